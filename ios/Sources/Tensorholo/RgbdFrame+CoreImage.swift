#if canImport(CoreImage)
import CoreGraphics
import CoreImage
import CoreVideo
import Foundation

// The Core Image half of `RgbdFrame(frame:orientation:smoothedDepth:context:)` (ARKit), apart so that the XCTests
// run it on macOS too (`SwiftLayerTests`: row order, field-of-view check).
extension RgbdFrame {
    /// The Core Image context of `init(frame:orientation:smoothedDepth:context:)` when none is given.
    static let sharedCIContext = CIContext(options: [.cacheIntermediates: false])

    /// Checks that a `colorWidth × colorHeight` image and a `depthWidth × depthHeight` depth map can cover one
    /// field of view: the same aspect ratio within 1 % (`|cw·dh − ch·dw| ≤ 0.01 · cw·dh`). ARKit promises it for
    /// `capturedImage` and `sceneDepth`; a mismatch would stretch depth over colour, so it is refused.
    ///
    /// - Throws: `TensorholoError.Unsupported` naming both sizes when the ratios differ, or
    ///   `TensorholoError.InvalidInput` for an empty size.
    static func checkSameFieldOfView(colorWidth: Int, colorHeight: Int, depthWidth: Int, depthHeight: Int) throws {
        guard colorWidth > 0, colorHeight > 0, depthWidth > 0, depthHeight > 0 else {
            throw TensorholoError.InvalidInput(
                message: "ARFrame sizes must not be empty: colour \(colorWidth) x \(colorHeight), depth \(depthWidth) x \(depthHeight)"
            )
        }
        let a = Double(colorWidth) * Double(depthHeight)
        let b = Double(colorHeight) * Double(depthWidth)
        guard abs(a - b) <= 0.01 * a else {
            throw TensorholoError.Unsupported(
                message: "ARFrame capturedImage \(colorWidth) x \(colorHeight) and sceneDepth \(depthWidth) x \(depthHeight) differ in "
                    + "aspect ratio, so they do not cover one field of view; build the RgbdFrame with a colorCrop for the depth's field of view"
            )
        }
    }

    /// Renders `image` (its extent is `width × height` pixels at the origin) into a new BGRA8 `CVPixelBuffer`
    /// (IOSurface-backed, 8-bit sRGB) with `CIContext.render(_:to:bounds:colorSpace:)`: pixel buffer in, pixel
    /// buffer out, so the buffer's row 0 is the source buffer's row 0. Throws `TensorholoError.InvalidInput` for
    /// an empty or oversized image, `TensorholoError.Internal` if `CVPixelBufferCreate` fails.
    static func renderBGRA(_ image: CIImage, width: Int, height: Int, context: CIContext) throws -> CVPixelBuffer {
        let (rowBytes, rowOverflow) = width.multipliedReportingOverflow(by: 4)
        let (_, countOverflow) = rowBytes.multipliedReportingOverflow(by: height)
        guard width > 0, height > 0, !rowOverflow, !countOverflow,
              UInt32(exactly: width) != nil, UInt32(exactly: height) != nil
        else {
            throw TensorholoError.InvalidInput(message: "ARFrame.capturedImage has size \(width) x \(height)")
        }
        let attributes = [kCVPixelBufferIOSurfacePropertiesKey as String: [String: Any]()] as CFDictionary
        var output: CVPixelBuffer?
        let status = CVPixelBufferCreate(kCFAllocatorDefault, width, height, kCVPixelFormatType_32BGRA, attributes, &output)
        guard status == kCVReturnSuccess, let buffer = output else {
            throw TensorholoError.Internal(message: "CVPixelBufferCreate failed for \(width) x \(height) BGRA (CVReturn \(status))")
        }
        context.render(
            image,
            to: buffer,
            bounds: CGRect(x: 0, y: 0, width: width, height: height),
            colorSpace: CGColorSpace(name: CGColorSpace.sRGB)
        )
        return buffer
    }
}
#endif
