import Foundation

extension TensorholoError: CustomStringConvertible {
    /// The human-readable text of the error, naming the offending input (the core's message), whatever the case.
    public var message: String {
        switch self {
        case let .InvalidInput(message), let .InvalidModel(message), let .Unsupported(message),
             let .Cancelled(message), let .Internal(message):
            return message
        }
    }

    /// `"invalid input: <message>"`, `"invalid model: …"`, `"unsupported: …"`, `"cancelled: …"` or
    /// `"internal error: …"`: the
    /// library's own wording (the Rust `Display` text). The generated `errorDescription` (and so
    /// `localizedDescription`) is `String(reflecting: self)`, which prints this.
    public var description: String {
        switch self {
        case let .InvalidInput(message):
            return "invalid input: \(message)"
        case let .InvalidModel(message):
            return "invalid model: \(message)"
        case let .Unsupported(message):
            return "unsupported: \(message)"
        case let .Cancelled(message):
            return "cancelled: \(message)"
        case let .Internal(message):
            return "internal error: \(message)"
        }
    }

    /// `LocalizedError.failureReason`: the message (see `message`).
    public var failureReason: String? {
        message
    }

    /// `LocalizedError.recoverySuggestion`: what the app can do about this case.
    public var recoverySuggestion: String? {
        switch self {
        case .InvalidInput:
            return "Fix the input named in the message (buffer size, stride, format or configuration value) and retry."
        case .InvalidModel:
            return "Use another model: this one cannot be loaded or breaks the library's contract."
        case .Unsupported:
            return "This build or device does not support the request; choose another option."
        case .Cancelled:
            return "The app cancelled the call (its progress callback returned false); nothing was produced."
        case .Internal:
            return "A failure inside the library (a bug): please report it with the message."
        }
    }
}
