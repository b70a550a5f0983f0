import CoreVideo
import Foundation
import Tensorholo
import XCTest

/// The synthetic RGB-D scene of the tests, made in code (no data files): 64 × 64 pixels, a checkerboard of
/// 4-pixel squares in two colours, the left half (x < 32) at 0.5 m and the right half at 1.5 m.
///
/// Its depth has two values, so the automatic depth range is exactly [0.5 m, 1.5 m] (1st and 99th percentiles)
/// and every depth encoding of the scene (f32/f16 metres, f32 disparity, half resolution) gives the same
/// normalised depth, hence the same SLM codes (checked against the Python bindings on the same scene).
enum TestScene {
    /// Width and height in pixels.
    static let size = 64
    /// Depth of the left half, metres.
    static let near: Float = 0.5
    /// Depth of the right half, metres.
    static let far: Float = 1.5

    /// The colour of pixel (x, y) as R, G, B, A (alpha 255).
    static func rgba(x: Int, y: Int) -> [UInt8] {
        (x / 4 + y / 4) % 2 == 0 ? [230, 180, 40, 255] : [20, 50, 200, 255]
    }

    /// The depth of pixel (x, y) in metres.
    static func metres(x: Int, y: Int) -> Float {
        x < size / 2 ? near : far
    }

    /// Little-endian bytes of an f32.
    static func bytes(_ value: Float) -> [UInt8] {
        withUnsafeBytes(of: value.bitPattern.littleEndian) { Array($0) }
    }

    /// Little-endian f16 bytes of the scene's two depths (0.5 = 0x3800, 1.5 = 0x3E00; both exact in f16).
    static func halfBytes(_ value: Float) -> [UInt8] {
        let bits: UInt16 = value == near ? 0x3800 : 0x3E00
        precondition(value == near || value == far, "only the scene's depths have f16 constants here")
        return withUnsafeBytes(of: bits.littleEndian) { Array($0) }
    }

    /// The reference frame, built by hand from packed bytes: RGBA8 colour, f32 metres, no rotation.
    static func referenceFrame() -> RgbdFrame {
        var color = Data()
        var depth = Data()
        for y in 0..<size {
            for x in 0..<size {
                color.append(contentsOf: rgba(x: x, y: y))
                depth.append(contentsOf: bytes(metres(x: x, y: y)))
            }
        }
        return RgbdFrame(
            color: color,
            colorFormat: .rgba8,
            colorWidth: UInt32(size),
            colorHeight: UInt32(size),
            depth: depth,
            depthFormat: .metresF32,
            depthWidth: UInt32(size),
            depthHeight: UInt32(size)
        )
    }

    /// The generator every test shares (64 × 64, one CNN thread), created once: creation times the CNN plans.
    private static let sharedGenerator = Result { try HologramGenerator(config: GeneratorConfig(width: 64, height: 64, threads: 1)) }

    /// The shared generator; throws the error of its creation, if any (every test that needs it then fails).
    static func generator() throws -> HologramGenerator {
        try sharedGenerator.get()
    }
}

/// A pixel buffer over memory of its own with exactly `bytesPerRow = width · bytesPerPixel + padding` (the
/// padding bytes are 0xEE, so reading them would show), pixel (x, y) holding `pixel(x, y)`
/// (`bytesPerPixel` bytes). The memory is freed when CoreVideo releases the buffer.
func makePixelBuffer(
    width: Int,
    height: Int,
    format: OSType,
    bytesPerPixel: Int,
    padding: Int = 0,
    pixel: (Int, Int) -> [UInt8]
) throws -> CVPixelBuffer {
    let bytesPerRow = width * bytesPerPixel + padding
    let memory = UnsafeMutableRawPointer.allocate(byteCount: bytesPerRow * height, alignment: 64)
    memory.initializeMemory(as: UInt8.self, repeating: 0xEE, count: bytesPerRow * height)
    for y in 0..<height {
        for x in 0..<width {
            let value = pixel(x, y)
            precondition(value.count == bytesPerPixel)
            for (i, byte) in value.enumerated() {
                memory.storeBytes(of: byte, toByteOffset: y * bytesPerRow + x * bytesPerPixel + i, as: UInt8.self)
            }
        }
    }
    var buffer: CVPixelBuffer?
    let status = CVPixelBufferCreateWithBytes(
        kCFAllocatorDefault,
        width,
        height,
        format,
        memory,
        bytesPerRow,
        { _, baseAddress in
            if let base = baseAddress {
                UnsafeMutableRawPointer(mutating: base).deallocate()
            }
        },
        nil,
        nil,
        &buffer
    )
    guard status == kCVReturnSuccess, let created = buffer else {
        memory.deallocate()
        throw TestSetupError(message: "CVPixelBufferCreateWithBytes('\(pixelFormatText(format))') failed with CVReturn \(status)")
    }
    return created
}

/// A failure to build a test input (fails the test that throws it).
struct TestSetupError: Error {
    /// What failed.
    let message: String
}

/// A four-character code as text, for messages.
func pixelFormatText(_ format: OSType) -> String {
    String(decoding: [24, 16, 8, 0].map { UInt8(truncatingIfNeeded: format >> $0) }, as: UTF8.self)
}

/// The scene's colour as a BGRA pixel buffer with `padding` bytes after each row.
func sceneBGRABuffer(padding: Int) throws -> CVPixelBuffer {
    try makePixelBuffer(
        width: TestScene.size,
        height: TestScene.size,
        format: kCVPixelFormatType_32BGRA,
        bytesPerPixel: 4,
        padding: padding
    ) { x, y in
        let c = TestScene.rgba(x: x, y: y)
        return [c[2], c[1], c[0], c[3]]
    }
}

/// The scene's depth as an f32 metres (`DepthFloat32`) pixel buffer.
func sceneDepthBuffer(padding: Int = 0) throws -> CVPixelBuffer {
    try makePixelBuffer(
        width: TestScene.size,
        height: TestScene.size,
        format: kCVPixelFormatType_DepthFloat32,
        bytesPerPixel: 4,
        padding: padding
    ) { x, y in
        TestScene.bytes(TestScene.metres(x: x, y: y))
    }
}

/// Asserts that two renders gave the same SLM codes in every plane.
func assertSameCodes(_ a: SlmPatterns, _ b: SlmPatterns, _ what: String, file: StaticString = #filePath, line: UInt = #line) {
    XCTAssertEqual(a.width, b.width, what, file: file, line: line)
    XCTAssertEqual(a.height, b.height, what, file: file, line: line)
    XCTAssertTrue(a.red == b.red && a.green == b.green && a.blue == b.blue, "\(what): the codes differ", file: file, line: line)
}

/// The message of a `TensorholoError.InvalidInput`, or nil for any other error.
func invalidInputMessage(_ error: Error) -> String? {
    guard let error = error as? TensorholoError, case let .InvalidInput(message) = error else {
        return nil
    }
    return message
}
