import CoreVideo
import Foundation
import Tensorholo
import XCTest

/// A real frame through the embedded CNNs: camera buffers → `RgbdFrame` → `HologramGenerator` → codes and
/// previews.
final class GeneratorTests: XCTestCase {
    /// A BGRA + DepthFloat32 pixel-buffer pair renders into three 64 × 64 planes of varying codes, mapped to the
    /// scene's depth range, the same codes on a second render, and different codes per laser.
    func testRenderPixelBufferFrame() throws {
        let gen = try TestScene.generator()
        let frame = try RgbdFrame(colorBuffer: sceneBGRABuffer(padding: 0), depthBuffer: sceneDepthBuffer())
        let patterns = try gen.render(frame: frame)

        XCTAssertEqual(patterns.width, 64)
        XCTAssertEqual(patterns.height, 64)
        for channel in SlmChannel.allCases {
            let codes = patterns.codes(channel)
            XCTAssertEqual(codes.count, 64 * 64, "\(channel)")
            XCTAssertGreaterThan(Set(codes).count, 16, "\(channel) codes are (nearly) constant")
        }
        XCTAssertNotEqual(patterns.red, patterns.green, "red and green lasers have different wavelengths")
        // Two depths only: the 1st/99th percentiles of the valid depths are exactly the two depths.
        XCTAssertEqual(try XCTUnwrap(patterns.zNearM), Double(TestScene.near), accuracy: 1e-6)
        XCTAssertEqual(try XCTUnwrap(patterns.zFarM), Double(TestScene.far), accuracy: 1e-6)
        XCTAssertGreaterThanOrEqual(patterns.timings.totalMs, 0)

        assertSameCodes(try gen.render(frame: frame), patterns, "a second render of the same frame")
    }

    /// Previews focused at the near (0) and far (1) ends of the volume are opaque images of the scene that
    /// differ from each other (the simulated focus moves).
    func testPreviewFocusNearAndFarDiffer() throws {
        let gen = try TestScene.generator()
        let frame = TestScene.referenceFrame()
        let near = try gen.preview(frame: frame, focus: 0)
        let far = try gen.preview(frame: frame, focus: 1)

        for preview in [near, far] {
            XCTAssertEqual(preview.width, 64)
            XCTAssertEqual(preview.height, 64)
            XCTAssertEqual(preview.rgba.count, 64 * 64 * 4)
            let alpha = stride(from: 3, to: preview.rgba.count, by: 4).map { preview.rgba[preview.rgba.startIndex + $0] }
            XCTAssertTrue(alpha.allSatisfy { $0 == 255 }, "preview alpha is 255")
            XCTAssertGreaterThan(Set(preview.rgba).count, 16, "the preview is an image, not a flat colour")
        }
        let differing = zip(near.rgba, far.rgba).filter { pair in pair.0 != pair.1 }.count
        // The Python bindings on this scene: mean |near − far| ≈ 17 levels; most bytes differ.
        XCTAssertGreaterThan(differing, near.rgba.count / 4, "focus near and far give the same preview")
    }

    /// What the generator runs: the configured size, 8 layers, a version, and the same facts as JSON.
    func testInfo() throws {
        let info = try TestScene.generator().info()
        XCTAssertEqual(info.width, 64)
        XCTAssertEqual(info.height, 64)
        XCTAssertEqual(info.layers, 8)
        XCTAssertEqual(info.cnnThreads, 1)
        XCTAssertEqual(info.version, version())
        let json = try XCTUnwrap(JSONSerialization.jsonObject(with: Data(info.json.utf8)) as? [String: Any])
        XCTAssertEqual(json["width"] as? Int, 64)
        XCTAssertEqual(json["layers"] as? Int, 8)
    }

    /// `benchmark` times the built-in scene: positive frames per second; 0 frames is an input error.
    func testBenchmark() throws {
        let gen = try TestScene.generator()
        let report = try gen.benchmark(frames: 1)
        XCTAssertEqual(report.frames, 1)
        XCTAssertGreaterThan(report.fps, 0)
        XCTAssertEqual(report.info.width, 64)
        XCTAssertThrowsError(try gen.benchmark(frames: 0)) { error in
            XCTAssertNotNil(invalidInputMessage(error), "expected InvalidInput, got \(error)")
        }
    }

    /// A 4 µm SLM's display profile (docs/DISPLAYS.md) → configuration → generator: the shipped 8 µm CNNs serve
    /// it at σ = 0.25 (a 1.5 mm volume, offsets of 1.5 and 3 mm).
    func testDisplayProfileOfA4umSlm() throws {
        let json = """
            {"pixel_pitch_m": 4e-6, "resolution": [64, 64], "wavelengths_m": [638e-9, 520e-9, 450e-9],
             "volume_depth_m": 1.5e-3, "offsets_m": [1.5e-3, 3e-3]}
            """
        let profile = try displayProfileFromJson(json: json)
        XCTAssertEqual(profile.resolution, [64, 64])
        var config = try generatorConfigForDisplay(profile: profile)
        XCTAssertEqual(config.pixelPitchM, 4e-6)
        XCTAssertEqual(config.offsetMm, 1.5, accuracy: 1e-12)
        config.threads = 1
        let gen = try HologramGenerator(config: config)
        XCTAssertEqual(try gen.render(frame: TestScene.referenceFrame()).width, 64)
        let mapping = try gen.info().displayMapping
        XCTAssertTrue(mapping.contains("σ = 0.25"), mapping)
    }
}
