#if canImport(ARKit) && os(iOS)
import ARKit
import CoreImage
import CoreVideo
import ImageIO

extension RgbdFrame {
    /// One frame of an ARKit session with LiDAR depth: `frame.capturedImage` converted to BGRA8 and
    /// `frame.sceneDepth.depthMap` (f32 metres, 256 × 192 on current devices) copied with its row stride.
    ///
    /// `capturedImage` is YpCbCr 4:2:0 (`kCVPixelFormatType_420YpCbCr8BiPlanarFullRange`), which the library does
    /// not read: Core Image converts it to 8-bit sRGB with the colour matrix attached to the buffer, rendering into
    /// a BGRA `CVPixelBuffer` of the same size (`CIContext.render(_:to:bounds:colorSpace:)`, as Apple's AVCamFilter
    /// sample does), whose rows are then copied once. Rendering pixel buffer to pixel buffer keeps CoreVideo's row
    /// order (row 0 = the buffer's top row) whatever Core Image's bottom-left working origin; `SwiftLayerTests`
    /// checks it (a bright top half gives a bright row 0).
    ///
    /// Registration: ARKit's `sceneDepth` is aligned with `capturedImage` and covers the same field of view, at a
    /// lower resolution with the same aspect ratio (1920 × 1440 and 256 × 192 are both 4:3). This initialiser
    /// checks that promise (`checkSameFieldOfView`) instead of trusting it: depth with another aspect ratio
    /// would be stretched onto the colour.
    ///
    /// - Parameters:
    ///   - frame: an `ARFrame` of a session whose configuration has `frameSemantics` containing `.sceneDepth`
    ///     (or `.smoothedSceneDepth` with `smoothedDepth: true`), which needs a LiDAR device.
    ///   - orientation: the EXIF orientation of ARKit's landscape buffers relative to the upright scene
    ///     (`Rotation(orientation:)`): `.right` in a portrait UI.
    ///   - smoothedDepth: read `frame.smoothedSceneDepth` (temporally smoothed) instead of `frame.sceneDepth`.
    ///   - minConfidence: the lowest `ARConfidenceLevel` of `confidenceMap` whose depth is kept (default
    ///     `.medium`): depth of lower confidence is invalid, filled from its confident neighbours and never
    ///     read as near (docs/VIDEO.md); `nil` takes every depth sample and leaves the confidence map out.
    ///   - context: the Core Image context that converts the colour; pass one kept for the session (a context
    ///     is costly to create), or `nil` for one shared by every call.
    /// - Throws: `TensorholoError.Unsupported` if the frame has no (smoothed) scene depth, the orientation is
    ///   mirrored, or depth and colour differ in aspect ratio (not one field of view); `TensorholoError.InvalidInput`
    ///   for an empty image or an unexpected depth format; `TensorholoError.Internal` if CoreVideo cannot make the
    ///   colour buffer.
    public init(
        frame: ARFrame,
        orientation: CGImagePropertyOrientation,
        smoothedDepth: Bool = false,
        minConfidence: ARConfidenceLevel? = .medium,
        context: CIContext? = nil
    ) throws {
        let sceneDepth = smoothedDepth ? frame.smoothedSceneDepth : frame.sceneDepth
        guard let depthMap = sceneDepth?.depthMap else {
            throw TensorholoError.Unsupported(
                message: "the ARFrame has no \(smoothedDepth ? "smoothedSceneDepth" : "sceneDepth"): run ARWorldTrackingConfiguration "
                    + "with frameSemantics containing .\(smoothedDepth ? "smoothedSceneDepth" : "sceneDepth") on a device with LiDAR"
            )
        }
        let rotation = try Rotation(orientation: orientation)
        let colorWidth = CVPixelBufferGetWidth(frame.capturedImage)
        let colorHeight = CVPixelBufferGetHeight(frame.capturedImage)
        try RgbdFrame.checkSameFieldOfView(
            colorWidth: colorWidth,
            colorHeight: colorHeight,
            depthWidth: CVPixelBufferGetWidth(depthMap),
            depthHeight: CVPixelBufferGetHeight(depthMap)
        )
        let bgra = try RgbdFrame.renderBGRA(
            CIImage(cvPixelBuffer: frame.capturedImage),
            width: colorWidth,
            height: colorHeight,
            context: context ?? RgbdFrame.sharedCIContext
        )
        let color = try PixelBufferCopy(bgra, bytesPerPixel: 4, name: "colour")
        let depthFormat = try DepthFormat(pixelFormat: CVPixelBufferGetPixelFormatType(depthMap))
        let depth = try PixelBufferCopy(depthMap, bytesPerPixel: depthFormat.bytesPerSample, name: "depth")
        // ARKit's confidence map: one UInt8 ARConfidenceLevel per depth sample (OneComponent8).
        let confidence = try minConfidence.flatMap { _ in sceneDepth?.confidenceMap }.map {
            try PixelBufferCopy($0, bytesPerPixel: 1, name: "confidence")
        }
        self.init(
            color: color.data,
            colorFormat: .bgra8,
            colorWidth: color.width,
            colorHeight: color.height,
            depth: depth.data,
            depthFormat: depthFormat,
            depthWidth: depth.width,
            depthHeight: depth.height,
            colorRowStride: color.rowStride,
            depthRowStride: depth.rowStride,
            rotation: rotation,
            confidence: confidence?.data,
            confidenceRowStride: confidence?.rowStride ?? 0,
            minConfidence: UInt8(clamping: minConfidence?.rawValue ?? 0)
        )
    }
}
#endif
