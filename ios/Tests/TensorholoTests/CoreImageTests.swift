import CoreImage
import CoreVideo
import Foundation
@testable import Tensorholo
import XCTest

/// The Core Image path of `RgbdFrame(frame:orientation:smoothedDepth:context:)` (ARKit), which no other test
/// reaches: the row order of `RgbdFrame.renderBGRA` and the field-of-view check. `@testable`: both are internal.
final class CoreImageTests: XCTestCase {
    /// Core Image's working space has its origin at the bottom left; rendering a pixel buffer into a pixel buffer
    /// must still keep the source's row order. A bright top half (rows 0..<3 of 6) must come out as a bright row 0
    /// and a dark last row, pixel for pixel in all three channels.
    func testBrightTopHalfGivesBrightRowZero() throws {
        let (width, height) = (8, 6)
        let source = try makePixelBuffer(width: width, height: height, format: kCVPixelFormatType_32BGRA, bytesPerPixel: 4) { _, y in
            y < height / 2 ? [240, 240, 240, 255] : [10, 10, 10, 255]
        }
        let rendered = try RgbdFrame.renderBGRA(
            CIImage(cvPixelBuffer: source), width: width, height: height, context: RgbdFrame.sharedCIContext
        )
        XCTAssertEqual(CVPixelBufferGetPixelFormatType(rendered), kCVPixelFormatType_32BGRA)
        XCTAssertEqual(CVPixelBufferGetWidth(rendered), width)
        XCTAssertEqual(CVPixelBufferGetHeight(rendered), height)
        XCTAssertEqual(CVPixelBufferLockBaseAddress(rendered, .readOnly), kCVReturnSuccess)
        defer { CVPixelBufferUnlockBaseAddress(rendered, .readOnly) }
        let base = try XCTUnwrap(CVPixelBufferGetBaseAddress(rendered))
        let rowBytes = CVPixelBufferGetBytesPerRow(rendered)
        func byte(_ x: Int, _ y: Int, _ c: Int) -> UInt8 {
            base.load(fromByteOffset: y * rowBytes + x * 4 + c, as: UInt8.self)
        }
        for y in 0..<height {
            for x in 0..<width {
                for c in 0..<3 {
                    // sRGB in, sRGB out: 240 and 10 come back within a code or two of themselves.
                    let expected: Int = y < height / 2 ? 240 : 10
                    XCTAssertLessThanOrEqual(abs(Int(byte(x, y, c)) - expected), 3, "pixel (\(x), \(y)) channel \(c)")
                }
            }
        }
    }

    /// ARKit's colour and depth must share one aspect ratio (1 % tolerance); another ratio is `Unsupported`.
    func testFieldOfViewCheck() throws {
        XCTAssertNoThrow(try RgbdFrame.checkSameFieldOfView(colorWidth: 1920, colorHeight: 1440, depthWidth: 256, depthHeight: 192))
        XCTAssertNoThrow(try RgbdFrame.checkSameFieldOfView(colorWidth: 1920, colorHeight: 1440, depthWidth: 256, depthHeight: 193))
        XCTAssertThrowsError(try RgbdFrame.checkSameFieldOfView(colorWidth: 1920, colorHeight: 1080, depthWidth: 256, depthHeight: 192)) { error in
            guard let error = error as? TensorholoError, case let .Unsupported(message) = error else {
                return XCTFail("expected Unsupported, got \(error)")
            }
            XCTAssertTrue(message.contains("1920 x 1080") && message.contains("256 x 192"), message)
        }
        XCTAssertThrowsError(try RgbdFrame.checkSameFieldOfView(colorWidth: 0, colorHeight: 1440, depthWidth: 256, depthHeight: 192))
    }
}
