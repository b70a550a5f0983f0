import Foundation
import Tensorholo
import XCTest

/// A `PatternsListener` written in Swift: records what the stream delivers (from its background thread) and
/// fulfils an expectation per frame or when a given frame arrives.
final class CollectingListener: PatternsListener, @unchecked Sendable {
    private let lock = NSLock()
    private var deliveredIndices: [UInt64] = []
    private var errorMessages: [String] = []
    private var sawMainThread = false
    private var sizes: [UInt32] = []
    private var waiters: [UInt64: XCTestExpectation] = [:]

    /// Fulfils `expectation` when the patterns (or the error) of frame `index` arrive.
    func expect(frame index: UInt64, _ expectation: XCTestExpectation) {
        lock.lock()
        waiters[index] = expectation
        lock.unlock()
    }

    /// `PatternsListener`: records the frame.
    func onPatterns(index: UInt64, patterns: SlmPatterns) {
        lock.lock()
        deliveredIndices.append(index)
        sizes.append(patterns.width)
        sawMainThread = sawMainThread || Thread.isMainThread
        let waiter = waiters.removeValue(forKey: index)
        lock.unlock()
        waiter?.fulfill()
    }

    /// `PatternsListener`: records the error; its message starts with `frame <index>:`.
    func onError(error: TensorholoError) {
        lock.lock()
        errorMessages.append(error.message)
        sawMainThread = sawMainThread || Thread.isMainThread
        let index = error.message.split(separator: ":").first.flatMap { UInt64($0.dropFirst("frame ".count)) }
        let waiter = index.flatMap { waiters.removeValue(forKey: $0) }
        lock.unlock()
        waiter?.fulfill()
    }

    /// The indices delivered so far, in delivery order.
    var indices: [UInt64] {
        lock.lock()
        defer { lock.unlock() }
        return deliveredIndices
    }

    /// The error messages so far.
    var errors: [String] {
        lock.lock()
        defer { lock.unlock() }
        return errorMessages
    }

    /// Whether any callback ran on the main thread.
    var calledOnMainThread: Bool {
        lock.lock()
        defer { lock.unlock() }
        return sawMainThread
    }

    /// The widths of the delivered patterns.
    var widths: [UInt32] {
        lock.lock()
        defer { lock.unlock() }
        return sizes
    }
}

/// `HologramGenerator.stream`: frames in order on a background thread, the drop-oldest queue, errors in place.
final class StreamTests: XCTestCase {
    /// Three frames pushed one at a time, each awaited: indices 0, 1, 2 delivered in order, none dropped.
    func testFramesPushedOneAtATimeArriveInOrder() throws {
        let listener = CollectingListener()
        let stream = try TestScene.generator().stream(listener: listener)
        for i in UInt64(0)..<3 {
            let delivered = expectation(description: "frame \(i) delivered")
            listener.expect(frame: i, delivered)
            XCTAssertEqual(try stream.push(frame: TestScene.referenceFrame()), i)
            wait(for: [delivered], timeout: 120)
        }
        stream.close()
        XCTAssertEqual(listener.indices, [0, 1, 2])
        XCTAssertEqual(listener.widths, [64, 64, 64])
        XCTAssertEqual(stream.droppedFrames(), 0)
        XCTAssertEqual(listener.errors, [])
        XCTAssertFalse(listener.calledOnMainThread, "the listener runs on the stream's background thread")
    }

    /// Three frames pushed at once: the last one always arrives; every frame is either delivered (in order) or
    /// counted as dropped, and the 2-frame queue drops at most one of three.
    func testBurstDeliversOrDropsEveryFrame() throws {
        let listener = CollectingListener()
        let stream = try TestScene.generator().stream(listener: listener)
        let last = expectation(description: "the last frame is delivered")
        listener.expect(frame: 2, last)
        for i in UInt64(0)..<3 {
            XCTAssertEqual(try stream.push(frame: TestScene.referenceFrame()), i)
        }
        wait(for: [last], timeout: 120)
        stream.close()

        let indices = listener.indices
        XCTAssertEqual(indices.last, 2)
        XCTAssertEqual(indices, indices.sorted(), "frames arrive in push order")
        XCTAssertEqual(Set(indices).count, indices.count, "no frame arrives twice")
        XCTAssertEqual(UInt64(indices.count) + stream.droppedFrames(), 3, "pushed = delivered + dropped")
        XCTAssertLessThanOrEqual(stream.droppedFrames(), 1)
        XCTAssertEqual(listener.errors, [])
    }

    /// A bad frame in a stream reaches `onError` as `frame <index>: …`; the frames around it still render.
    func testBadFrameReportedInPlace() throws {
        let listener = CollectingListener()
        let stream = try TestScene.generator().stream(listener: listener)
        var bad = TestScene.referenceFrame()
        bad.color = bad.color.dropLast(1)
        for (i, frame) in [TestScene.referenceFrame(), bad, TestScene.referenceFrame()].enumerated() {
            let done = expectation(description: "frame \(i) handled")
            listener.expect(frame: UInt64(i), done)
            XCTAssertEqual(try stream.push(frame: frame), UInt64(i))
            wait(for: [done], timeout: 120)
        }
        stream.close()
        XCTAssertEqual(listener.indices, [0, 2])
        XCTAssertEqual(listener.errors.count, 1)
        XCTAssertTrue(listener.errors.first?.hasPrefix("frame 1: ") ?? false, "\(listener.errors)")
    }

    /// After `close()` a push is an input error, and a second `close()` does nothing.
    func testPushAfterClose() throws {
        let listener = CollectingListener()
        let stream = try TestScene.generator().stream(listener: listener)
        stream.close()
        XCTAssertThrowsError(try stream.push(frame: TestScene.referenceFrame())) { error in
            XCTAssertNotNil(invalidInputMessage(error), "expected InvalidInput, got \(error)")
        }
        stream.close()
        XCTAssertEqual(listener.indices, [])
    }

    /// `PatternsHandler` forwards to its closures.
    func testPatternsHandlerClosures() throws {
        let delivered = expectation(description: "patterns delivered to the closure")
        let handler = PatternsHandler(onPatterns: { index, patterns in
            XCTAssertEqual(index, 0)
            XCTAssertEqual(patterns.height, 64)
            delivered.fulfill()
        })
        let stream = try TestScene.generator().stream(listener: handler)
        XCTAssertEqual(try stream.push(frame: TestScene.referenceFrame()), 0)
        wait(for: [delivered], timeout: 120)
        stream.close()
    }
}
