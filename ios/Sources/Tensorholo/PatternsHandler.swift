import Foundation

/// A `PatternsListener` made of two closures, for `HologramGenerator.stream(listener:)` without a class of
/// the app's own.
///
/// The stream calls both on its background thread, one call at a time, in frame order: hop to the main actor
/// (`DispatchQueue.main.async`, `Task { @MainActor in … }`) before touching the UI.
public final class PatternsHandler: PatternsListener {
    private let handlePatterns: @Sendable (UInt64, SlmPatterns) -> Void
    private let handleError: @Sendable (TensorholoError) -> Void

    /// - Parameters:
    ///   - onPatterns: called with the index `HologramStream.push(frame:)` returned for a frame and its patterns.
    ///   - onError: called when a frame fails (`TensorholoError`, message starting with `frame <index>:`);
    ///     the stream goes on. Default: ignore.
    public init(
        onPatterns: @escaping @Sendable (UInt64, SlmPatterns) -> Void,
        onError: @escaping @Sendable (TensorholoError) -> Void = { _ in }
    ) {
        handlePatterns = onPatterns
        handleError = onError
    }

    /// `PatternsListener`: forwards to `onPatterns`.
    public func onPatterns(index: UInt64, patterns: SlmPatterns) {
        handlePatterns(index, patterns)
    }

    /// `PatternsListener`: forwards to `onError`.
    public func onError(error: TensorholoError) {
        handleError(error)
    }
}
