#if canImport(ARKit) && os(iOS)
import ARKit
import CoreImage
import CoreVideo
import ImageIO

extension RgbdFrame {
    /// One frame of an ARKit session with LiDAR depth: `frame.capturedImage` converted to RGBA8 and
    /// `frame.sceneDepth.depthMap` (f32 metres, 256 × 192 on current devices) copied with its row stride.
    ///
    /// `capturedImage` is YpCbCr 4:2:0 (`kCVPixelFormatType_420YpCbCr8BiPlanarFullRange`), which the library does
    /// not read: Core Image converts it to 8-bit sRGB with the colour matrix attached to the buffer, rendering
    /// straight into the frame's colour bytes (one GPU pass and no intermediate pixel buffer; the colour data is
    /// `width · height · 4` bytes).
    ///
    /// - Parameters:
    ///   - frame: an `ARFrame` of a session whose configuration has `frameSemantics` containing `.sceneDepth`
    ///     (or `.smoothedSceneDepth` with `smoothedDepth: true`), which needs a LiDAR device.
    ///   - orientation: the EXIF orientation of ARKit's landscape buffers relative to the upright scene
    ///     (`Rotation(orientation:)`): `.right` in a portrait UI.
    ///   - smoothedDepth: read `frame.smoothedSceneDepth` (temporally smoothed) instead of `frame.sceneDepth`.
    ///   - context: the Core Image context that converts the colour; pass one kept for the session (a context
    ///     is costly to create), or `nil` for one shared by every call.
    /// - Throws: `TensorholoError.Unsupported` if the frame has no (smoothed) scene depth or the orientation is
    ///   mirrored; `TensorholoError.InvalidInput` for an empty image or an unexpected depth format.
    public init(
        frame: ARFrame,
        orientation: CGImagePropertyOrientation,
        smoothedDepth: Bool = false,
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
        let color = try RgbdFrame.renderRGBA(
            CIImage(cvPixelBuffer: frame.capturedImage),
            width: colorWidth,
            height: colorHeight,
            context: context ?? RgbdFrame.sharedCIContext
        )
        let depthFormat = try DepthFormat(pixelFormat: CVPixelBufferGetPixelFormatType(depthMap))
        let depth = try PixelBufferCopy(depthMap, bytesPerPixel: depthFormat.bytesPerSample, name: "depth")
        self.init(
            color: color,
            colorFormat: .rgba8,
            colorWidth: UInt32(colorWidth),
            colorHeight: UInt32(colorHeight),
            depth: depth.data,
            depthFormat: depthFormat,
            depthWidth: depth.width,
            depthHeight: depth.height,
            colorRowStride: 0,
            depthRowStride: depth.rowStride,
            rotation: rotation
        )
    }

    /// The Core Image context of `init(frame:orientation:smoothedDepth:context:)` when none is given.
    static let sharedCIContext = CIContext(options: [.cacheIntermediates: false])

    /// Renders `image` (its extent is `width × height` pixels at the origin) into packed 8-bit sRGB RGBA bytes,
    /// row 0 at the top. Throws `TensorholoError.InvalidInput` for an empty or oversized image.
    static func renderRGBA(_ image: CIImage, width: Int, height: Int, context: CIContext) throws -> Data {
        let (rowBytes, rowOverflow) = width.multipliedReportingOverflow(by: 4)
        let (count, countOverflow) = rowBytes.multipliedReportingOverflow(by: height)
        guard width > 0, height > 0, !rowOverflow, !countOverflow,
              UInt32(exactly: width) != nil, UInt32(exactly: height) != nil
        else {
            throw TensorholoError.InvalidInput(message: "ARFrame.capturedImage has size \(width) x \(height)")
        }
        var rgba = Data(count: count)
        let sRGB = CGColorSpace(name: CGColorSpace.sRGB)
        rgba.withUnsafeMutableBytes { bytes in
            if let base = bytes.baseAddress {
                context.render(
                    image,
                    toBitmap: base,
                    rowBytes: rowBytes,
                    bounds: CGRect(x: 0, y: 0, width: width, height: height),
                    format: .RGBA8,
                    colorSpace: sRGB
                )
            }
        }
        return rgba
    }
}
#endif
