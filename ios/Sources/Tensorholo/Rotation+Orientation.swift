import ImageIO

extension Rotation {
    /// The clockwise rotation that makes an image stored with EXIF orientation `orientation` upright:
    ///
    /// | `CGImagePropertyOrientation` | EXIF | stored image | `Rotation` |
    /// |---|---|---|---|
    /// | `.up` | 1 | upright | `.deg0` |
    /// | `.right` | 6 | turned 90° counter-clockwise (the back camera's buffers in a portrait UI) | `.deg90` |
    /// | `.down` | 3 | upside down | `.deg180` |
    /// | `.left` | 8 | turned 90° clockwise (portrait upside down) | `.deg270` |
    ///
    /// The camera delivers buffers in the sensor's landscape orientation whatever the device's orientation,
    /// so an app passes the orientation of its UI (for the back camera: portrait `.right`, landscape with the
    /// home button / USB port on the right `.up`, on the left `.down`, portrait upside down `.left`).
    ///
    /// - Throws: `TensorholoError.Unsupported` for the mirrored orientations (`.upMirrored`, `.downMirrored`,
    ///   `.leftMirrored`, `.rightMirrored`): a frame carries no flip; capture unmirrored buffers
    ///   (`AVCaptureConnection.isVideoMirrored = false`, the default of data outputs) or flip them first.
    public init(orientation: CGImagePropertyOrientation) throws {
        switch orientation {
        case .up:
            self = .deg0
        case .right:
            self = .deg90
        case .down:
            self = .deg180
        case .left:
            self = .deg270
        case .upMirrored, .downMirrored, .leftMirrored, .rightMirrored:
            throw TensorholoError.Unsupported(
                message: "mirrored orientation (EXIF \(orientation.rawValue)) is not supported: RgbdFrame rotates, it does not flip; capture unmirrored buffers"
            )
        }
    }

    /// The EXIF orientation of an image that this rotation makes upright (the inverse of
    /// `Rotation(orientation:)`): `.deg0` → `.up`, `.deg90` → `.right`, `.deg180` → `.down`, `.deg270` → `.left`.
    public var orientation: CGImagePropertyOrientation {
        switch self {
        case .deg0:
            return .up
        case .deg90:
            return .right
        case .deg180:
            return .down
        case .deg270:
            return .left
        }
    }

    /// The clockwise angle in degrees: 0, 90, 180 or 270.
    public var degrees: Int {
        switch self {
        case .deg0:
            return 0
        case .deg90:
            return 90
        case .deg180:
            return 180
        case .deg270:
            return 270
        }
    }
}
