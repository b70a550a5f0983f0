import Foundation
import Tensorholo
import XCTest

/// Bad input → `TensorholoError.InvalidInput` naming what is wrong, never a crash; the generator stays usable.
final class ErrorTests: XCTestCase {
    /// Asserts that `body` throws `InvalidInput` whose message contains `expected`.
    private func assertInvalidInput<T>(
        _ body: @autoclosure () throws -> T,
        mentioning expected: String,
        file: StaticString = #filePath,
        line: UInt = #line
    ) {
        XCTAssertThrowsError(try body(), file: file, line: line) { error in
            guard let message = invalidInputMessage(error) else {
                return XCTFail("expected TensorholoError.InvalidInput, got \(error)", file: file, line: line)
            }
            XCTAssertTrue(message.contains(expected), "message \"\(message)\" does not mention \"\(expected)\"", file: file, line: line)
        }
    }

    /// A colour buffer one byte short of `height` rows of `width` RGBA pixels.
    func testShortColorBuffer() throws {
        let gen = try TestScene.generator()
        var frame = TestScene.referenceFrame()
        frame.color = frame.color.dropLast(1)
        assertInvalidInput(try gen.render(frame: frame), mentioning: "too short")
        // The generator still renders a good frame afterwards.
        XCTAssertEqual(try gen.render(frame: TestScene.referenceFrame()).width, 64)
    }

    /// A zero-width colour buffer.
    func testZeroSize() throws {
        let gen = try TestScene.generator()
        var frame = TestScene.referenceFrame()
        frame.colorWidth = 0
        assertInvalidInput(try gen.render(frame: frame), mentioning: "non-zero size")
    }

    /// A stride shorter than one row.
    func testStrideShorterThanARow() throws {
        let gen = try TestScene.generator()
        var frame = TestScene.referenceFrame()
        frame.colorRowStride = 64 * 4 - 1
        assertInvalidInput(try gen.render(frame: frame), mentioning: "shorter than one row")
    }

    /// A depth map without one valid pixel (all NaN).
    func testAllInvalidDepth() throws {
        let gen = try TestScene.generator()
        var frame = TestScene.referenceFrame()
        frame.depth = Data((0..<(64 * 64)).flatMap { _ in TestScene.bytes(.nan) })
        assertInvalidInput(try gen.render(frame: frame), mentioning: "invalid")
    }

    /// A display profile with a negative pitch (JSON) or a one-value resolution (a record built field by
    /// field) is refused naming the key.
    func testBadDisplayProfile() {
        let json = """
            {"pixel_pitch_m": -4e-6, "resolution": [64, 64], "wavelengths_m": [638e-9, 520e-9, 450e-9],
             "volume_depth_m": 1.5e-3, "offsets_m": [1.5e-3]}
            """
        assertInvalidInput(try displayProfileFromJson(json: json), mentioning: "pixel_pitch_m")
        let record = DisplayProfile(
            pixelPitchM: 4e-6, resolution: [64], wavelengthsM: [638e-9, 520e-9, 450e-9], volumeDepthM: 1.5e-3,
            offsetsM: [1.5e-3])
        assertInvalidInput(try generatorConfigForDisplay(profile: record), mentioning: "resolution")
    }

    /// A NaN SLM offset in the configuration.
    func testNaNOffset() {
        assertInvalidInput(
            try HologramGenerator(config: GeneratorConfig(width: 64, height: 64, offsetMm: .nan)),
            mentioning: "offset_m"
        )
    }

    /// A zero-sized hologram, and only one end of the depth range.
    func testBadConfigurations() {
        assertInvalidInput(try HologramGenerator(config: GeneratorConfig(width: 0, height: 64)), mentioning: "width")
        assertInvalidInput(
            try HologramGenerator(config: GeneratorConfig(width: 64, height: 64, zNearM: 0.3)),
            mentioning: "z_near_m and z_far_m"
        )
    }

    /// A focus outside [0, 1].
    func testFocusOutOfRange() throws {
        let gen = try TestScene.generator()
        assertInvalidInput(try gen.preview(frame: TestScene.referenceFrame(), focus: 1.5), mentioning: "focus")
    }

    /// Patterns whose planes do not hold `width · height` codes cannot be packed or drawn.
    func testPackRgbaShortPlane() throws {
        let patterns = try TestScene.generator().render(frame: TestScene.referenceFrame())
        var short = patterns
        short.blue = short.blue.dropLast(1)
        assertInvalidInput(try packRgba(patterns: short), mentioning: "blue")
        assertInvalidInput(try short.cgImage(), mentioning: "blue")
        assertInvalidInput(try short.cgImage(channel: .blue), mentioning: "blue plane")
        XCTAssertNoThrow(try short.cgImage(channel: .red))
    }

    /// The error's text: `message`, and the library's wording in `description` / `localizedDescription`.
    func testErrorText() {
        let error = TensorholoError.InvalidInput(message: "the colour buffer is too short")
        XCTAssertEqual(error.message, "the colour buffer is too short")
        XCTAssertEqual(error.description, "invalid input: the colour buffer is too short")
        XCTAssertEqual(error.localizedDescription, "invalid input: the colour buffer is too short")
        XCTAssertEqual(TensorholoError.Internal(message: "x").description, "internal error: x")
        XCTAssertNotNil(error.recoverySuggestion)
    }
}
