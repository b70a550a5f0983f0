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
    /// - Throws: `TensorholoError.InvalidInput` for an unsupported pixel format or an empty buffer;
    ///   `TensorholoError.Unsupported` for a mirrored orientation; `TensorholoError.Internal` if a buffer cannot
    ///   be locked.
    public init(pixelBuffer: CVPixelBuffer, depthData: AVDepthData, orientation: CGImagePropertyOrientation = .up) throws {
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
    public init(sampleBuffer: CMSampleBuffer, depthData: AVDepthData, orientation: CGImagePropertyOrientation = .up) throws {
        guard let pixelBuffer = CMSampleBufferGetImageBuffer(sampleBuffer) else {
            throw TensorholoError.InvalidInput(message: "the colour sample buffer holds no image buffer")
        }
        try self.init(pixelBuffer: pixelBuffer, depthData: depthData, orientation: orientation)
    }
}
#endif
