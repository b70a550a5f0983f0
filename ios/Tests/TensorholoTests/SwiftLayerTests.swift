import CoreGraphics
import CoreVideo
import Foundation
import ImageIO
import Tensorholo
import XCTest

/// The hand-written Swift layer: pixel formats, row strides, orientations and images, each checked against
/// what the library computes from the hand-built reference frame.
final class SwiftLayerTests: XCTestCase {
    /// EXIF orientation → clockwise rotation, both ways; mirrored orientations are refused.
    func testOrientationMapping() throws {
        let expected: [(CGImagePropertyOrientation, Rotation, Int)] = [
            (.up, .deg0, 0), (.right, .deg90, 90), (.down, .deg180, 180), (.left, .deg270, 270),
        ]
        for (orientation, rotation, degrees) in expected {
            XCTAssertEqual(try Rotation(orientation: orientation), rotation, "EXIF \(orientation.rawValue)")
            XCTAssertEqual(rotation.orientation, orientation)
            XCTAssertEqual(rotation.degrees, degrees)
        }
        let mirroredOrientations: [CGImagePropertyOrientation] = [.upMirrored, .downMirrored, .leftMirrored, .rightMirrored]
        for mirrored in mirroredOrientations {
            XCTAssertThrowsError(try Rotation(orientation: mirrored)) { error in
                guard let error = error as? TensorholoError, case .Unsupported = error else {
                    return XCTFail("expected Unsupported, got \(error)")
                }
            }
        }
    }

    /// The rotation means "clockwise to make upright": the scene stored turned 90° counter-clockwise (as the
    /// back camera's buffers are in a portrait UI) with orientation `.right` renders exactly like the upright
    /// scene; with `.left` (the opposite turn) it does not.
    func testRotatedBuffersRenderLikeUprightOnes() throws {
        let gen = try TestScene.generator()
        let upright = try gen.render(frame: TestScene.referenceFrame())
        let n = TestScene.size
        // Stored pixel (x, y) of the image turned 90° counter-clockwise is upright pixel (n − 1 − y, x).
        let color = try makePixelBuffer(width: n, height: n, format: kCVPixelFormatType_32BGRA, bytesPerPixel: 4) { x, y in
            let c = TestScene.rgba(x: n - 1 - y, y: x)
            return [c[2], c[1], c[0], c[3]]
        }
        let depth = try makePixelBuffer(width: n, height: n, format: kCVPixelFormatType_DepthFloat32, bytesPerPixel: 4) { x, y in
            TestScene.bytes(TestScene.metres(x: n - 1 - y, y: x))
        }
        let turned = try RgbdFrame(colorBuffer: color, depthBuffer: depth, rotation: Rotation(orientation: .right))
        XCTAssertEqual(turned.rotation, .deg90)
        assertSameCodes(try gen.render(frame: turned), upright, "buffers turned 90° CCW with orientation .right")

        var wrong = turned
        wrong.rotation = try Rotation(orientation: .left)
        XCTAssertNotEqual(try gen.render(frame: wrong).red, upright.red, "the opposite rotation must not match")
    }

    /// A BGRA buffer whose rows are padded: the frame keeps `CVPixelBufferGetBytesPerRow` as its stride, holds
    /// every row but the last row's padding, has each pixel where the stride says, and renders exactly like the
    /// packed RGBA reference frame.
    func testBGRAStrideHandling() throws {
        let padding = 20
        let stride = TestScene.size * 4 + padding
        let buffer = try sceneBGRABuffer(padding: padding)
        XCTAssertEqual(CVPixelBufferGetBytesPerRow(buffer), stride)

        let frame = try RgbdFrame(colorBuffer: buffer, depthBuffer: sceneDepthBuffer(padding: 12))
        XCTAssertEqual(frame.colorFormat, .bgra8)
        XCTAssertEqual(frame.colorWidth, 64)
        XCTAssertEqual(frame.colorHeight, 64)
        XCTAssertEqual(frame.colorRowStride, UInt32(stride))
        XCTAssertEqual(frame.color.count, stride * 63 + 64 * 4)
        XCTAssertEqual(frame.depthFormat, .metresF32)
        XCTAssertEqual(frame.depthRowStride, UInt32(64 * 4 + 12))
        XCTAssertEqual(frame.rotation, .deg0)
        let bytes = [UInt8](frame.color)
        for (x, y) in [(0, 0), (63, 0), (5, 17), (63, 63)] {
            let c = TestScene.rgba(x: x, y: y)
            XCTAssertEqual(Array(bytes[(y * stride + 4 * x)..<(y * stride + 4 * x + 4)]), [c[2], c[1], c[0], c[3]], "pixel (\(x), \(y))")
        }
        XCTAssertEqual(bytes[64 * 4], 0xEE, "row padding is copied as it is, not packed away")

        let gen = try TestScene.generator()
        assertSameCodes(try gen.render(frame: frame), try gen.render(frame: TestScene.referenceFrame()), "padded BGRA vs packed RGBA")
    }

    /// The four AVDepthData formats map to their `DepthFormat`, and the scene in each renders the same codes:
    /// f16 metres and f32 disparity (1/m) of the same depths, and depth at half the colour's resolution.
    func testDepthFormats() throws {
        let gen = try TestScene.generator()
        let reference = try gen.render(frame: TestScene.referenceFrame())
        let color = try sceneBGRABuffer(padding: 0)
        let n = TestScene.size
        let cases: [(String, CVPixelBuffer, DepthFormat)] = try [
            ("DepthFloat16", makePixelBuffer(width: n, height: n, format: kCVPixelFormatType_DepthFloat16, bytesPerPixel: 2) { x, y in
                TestScene.halfBytes(TestScene.metres(x: x, y: y))
            }, .metresF16),
            ("DisparityFloat32", makePixelBuffer(width: n, height: n, format: kCVPixelFormatType_DisparityFloat32, bytesPerPixel: 4) { x, y in
                TestScene.bytes(1 / TestScene.metres(x: x, y: y))
            }, .disparityF32),
            ("DepthFloat32 at half resolution", makePixelBuffer(width: n / 2, height: n / 2, format: kCVPixelFormatType_DepthFloat32, bytesPerPixel: 4) { x, y in
                TestScene.bytes(TestScene.metres(x: 2 * x, y: 2 * y))
            }, .metresF32),
        ]
        for (name, depth, format) in cases {
            let frame = try RgbdFrame(colorBuffer: color, depthBuffer: depth)
            XCTAssertEqual(frame.depthFormat, format, name)
            assertSameCodes(try gen.render(frame: frame), reference, name)
        }
        XCTAssertEqual(try DepthFormat(pixelFormat: kCVPixelFormatType_DisparityFloat16), .disparityF16)
        XCTAssertEqual(DepthFormat.metresF16.bytesPerSample, 2)
        XCTAssertEqual(DepthFormat.disparityF32.bytesPerSample, 4)
    }

    /// Colour formats: BGRA and RGBA map; the camera's default YpCbCr 4:2:0 is refused with a message that says
    /// what to set; so is a colour buffer given as depth.
    func testPixelFormats() throws {
        XCTAssertEqual(try ColorFormat(pixelFormat: kCVPixelFormatType_32BGRA), .bgra8)
        XCTAssertEqual(try ColorFormat(pixelFormat: kCVPixelFormatType_32RGBA), .rgba8)
        XCTAssertEqual(ColorFormat.rgb8.bytesPerPixel, 3)
        XCTAssertThrowsError(try ColorFormat(pixelFormat: kCVPixelFormatType_420YpCbCr8BiPlanarFullRange)) { error in
            let message = invalidInputMessage(error) ?? ""
            XCTAssertTrue(message.contains("'420f'"), message)
            XCTAssertTrue(message.contains("kCVPixelFormatType_32BGRA"), message)
        }
        let bgra = try sceneBGRABuffer(padding: 0)
        XCTAssertThrowsError(try RgbdFrame(colorBuffer: bgra, depthBuffer: bgra)) { error in
            XCTAssertTrue((invalidInputMessage(error) ?? "").contains("'BGRA'"), "\(error)")
        }
    }

    /// The SLM frame as a CGImage: the patterns' size, 32-bit RGBX without alpha, and pixel (x, y) holds the red,
    /// green and blue lasers' codes of that pixel; one channel as 8-bit gray holds that laser's codes.
    func testSlmCGImage() throws {
        let patterns = try TestScene.generator().render(frame: TestScene.referenceFrame())
        let image = try patterns.cgImage()
        XCTAssertEqual(image.width, 64)
        XCTAssertEqual(image.height, 64)
        XCTAssertEqual(image.bitsPerComponent, 8)
        XCTAssertEqual(image.bitsPerPixel, 32)
        XCTAssertEqual(image.alphaInfo, .noneSkipLast)
        let rgba = try XCTUnwrap(image.dataProvider?.data) as Data
        XCTAssertEqual(rgba, try packRgba(patterns: patterns))
        let red = [UInt8](patterns.red)
        let green = [UInt8](patterns.green)
        let blue = [UInt8](patterns.blue)
        let pixels = [UInt8](rgba)
        for i in [0, 1, 63, 64 * 31 + 17, 64 * 64 - 1] {
            XCTAssertEqual(Array(pixels[(4 * i)..<(4 * i + 4)]), [red[i], green[i], blue[i], 255], "pixel \(i)")
        }

        let gray = try patterns.cgImage(channel: .green)
        XCTAssertEqual(gray.width, 64)
        XCTAssertEqual(gray.height, 64)
        XCTAssertEqual(gray.bitsPerPixel, 8)
        XCTAssertEqual(gray.alphaInfo, CGImageAlphaInfo.none)
        XCTAssertEqual(try XCTUnwrap(gray.dataProvider?.data) as Data, patterns.green)
    }

    /// The preview as a CGImage: its size, opaque, its bytes.
    func testPreviewCGImage() throws {
        let preview = try TestScene.generator().preview(frame: TestScene.referenceFrame(), focus: 0.5)
        let image = try preview.cgImage()
        XCTAssertEqual(image.width, Int(preview.width))
        XCTAssertEqual(image.height, Int(preview.height))
        XCTAssertEqual(image.alphaInfo, .noneSkipLast)
        XCTAssertEqual(try XCTUnwrap(image.dataProvider?.data) as Data, preview.rgba)
    }
}
