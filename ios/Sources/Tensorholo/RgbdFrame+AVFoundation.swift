#if canImport(AVFoundation)
import AVFoundation
import CoreMedia
import CoreVideo
import ImageIO

extension RgbdFrame {
    /// One camera frame from `AVCaptureVideoDataOutput` and `AVCaptureDepthDataOutput` (e.g. the pair that
    /// `AVCaptureDataOutputSynchronizer` delivers): the colour buffer and `depthData.depthDataMap`, each copied
    /// once with its own size and row stride.
    ///
    /// - Parameters:
    ///   - pixelBuffer: the video frame, `kCVPixelFormatType_32BGRA` (set the output's `videoSettings` to
    ///     `[kCVPixelBufferPixelFormatTypeKey as String: kCVPixelFormatType_32BGRA]`; the camera's default
    ///     YpCbCr 4:2:0 is rejected with a message saying so) or `32RGBA`.
    ///   - depthData: depth in metres (`DepthFloat32/16`) or disparity in 1/m (`DisparityFloat32/16`, what the
    ///     dual and TrueDepth cameras deliver by default) in the same orientation as `pixelBuffer` (leave both
    ///     connections' orientations at their defaults, or set both alike); its resolution may be lower.
    ///   - orientation: the EXIF orientation of the buffers relative to the upright scene (`Rotation(orientation:)`;
    ///     for the back camera in a portrait UI, `.right`).
    ///   - requireAbsoluteDepth: refuse depth whose `depthDataAccuracy` is `.relative`. Relative depth (dual
    ///     cameras without calibration, some portrait-effect depth) orders near and far correctly but its values
    ///     are not metres: fine with the automatic depth range (the default: the 1st–99th percentiles, and the
    ///     diopter mapping does not change when every depth is scaled alike), wrong with a fixed `z_near_m` /
    ///     `z_far_m` in the generator's configuration: pass `true` there. `depthData.isRelativeDepth` tells.
    /// - Throws: `TensorholoError.InvalidInput` for an unsupported pixel format or an empty buffer;
    ///   `TensorholoError.Unsupported` for a mirrored orientation, or relative depth with `requireAbsoluteDepth`;
    ///   `TensorholoError.Internal` if a buffer cannot be locked.
    public init(
        pixelBuffer: CVPixelBuffer,
        depthData: AVDepthData,
        orientation: CGImagePropertyOrientation = .up,
        requireAbsoluteDepth: Bool = false
    ) throws {
        if requireAbsoluteDepth && depthData.isRelativeDepth {
            throw TensorholoError.Unsupported(
                message: "the depth data's accuracy is relative (AVDepthData.Accuracy.relative): its values are not metres, "
                    + "so a fixed z_near_m/z_far_m range does not apply; use the automatic range or a camera with absolute depth (LiDAR)"
            )
        }
        try self.init(
            colorBuffer: pixelBuffer,
            depthBuffer: depthData.depthDataMap,
            rotation: Rotation(orientation: orientation)
        )
    }

    /// As `init(pixelBuffer:depthData:orientation:)`, from the video output's sample buffer.
    ///
    /// - Throws: as `init(pixelBuffer:depthData:orientation:)`, and `TensorholoError.InvalidInput` for a sample
    ///   buffer without an image buffer.
    public init(
        sampleBuffer: CMSampleBuffer,
        depthData: AVDepthData,
        orientation: CGImagePropertyOrientation = .up,
        requireAbsoluteDepth: Bool = false
    ) throws {
        guard let pixelBuffer = CMSampleBufferGetImageBuffer(sampleBuffer) else {
            throw TensorholoError.InvalidInput(message: "the colour sample buffer holds no image buffer")
        }
        try self.init(
            pixelBuffer: pixelBuffer, depthData: depthData, orientation: orientation, requireAbsoluteDepth: requireAbsoluteDepth
        )
    }
}

extension AVDepthData {
    /// Whether the depth values are only relative (`depthDataAccuracy == .relative`): right in order, not in metres.
    /// See `RgbdFrame(pixelBuffer:depthData:orientation:requireAbsoluteDepth:)`.
    public var isRelativeDepth: Bool {
        depthDataAccuracy == .relative
    }
}
#endif
