import ARKit
import AVFoundation
import CoreGraphics
import CoreImage
import Foundation
import Tensorholo

/// The sample's engine: captures colour + depth, streams the frames through a `HologramGenerator` off the main
/// thread, and publishes the SLM pattern (for the external display) and a simulated preview at the chosen focus
/// (for the phone's screen). One instance, shared by both scenes.
///
/// The capture: on a LiDAR device an `ARSession` with scene depth (256 × 192 metres under the colour) and its
/// confidence map: `RgbdFrame(frame:orientation:minConfidence:)` keeps depth of medium and high confidence, the
/// rest is invalid and filled from its confident neighbours (docs/VIDEO.md). Elsewhere `AVCaptureSession` with
/// the dual camera's depth (filtered by AVFoundation; it has no confidence map).
///
/// Foveation (docs/FOVEATION.md): frames are rendered foveated on the viewer's gaze, the 3D CNN around it and a
/// 2D hologram with synthetic blur elsewhere. The gaze comes from ARKit's face tracking (the front camera's
/// `ARFaceAnchor.lookAtPoint`, while the back camera tracks the world) where the device has it, else from the
/// last touch on the preview; without either, full 3D frames.
final class HologramModel: NSObject, ObservableObject, AVCaptureDataOutputSynchronizerDelegate, ARSessionDelegate {
    /// The instance both scenes show.
    static let shared = HologramModel()

    /// Hologram size while no external display is connected (the preview alone), width × height in pixels.
    static let previewOnlySize = (width: UInt32(640), height: UInt32(360))

    /// What the viewer would see focused at `focus` (RGBA preview of the latest frame).
    @Published private(set) var previewImage: CGImage?
    /// The latest HDMI frame for the SLM (`SlmPatterns.cgImage()`: red/green/blue lasers' codes).
    @Published private(set) var slmImage: CGImage?
    /// One line for the user: starting, running at N fps, or what failed.
    @Published private(set) var status = "Starting…"
    /// Whether an external display (the SLM) is connected.
    @Published private(set) var externalDisplayConnected = false
    /// The hologram size in pixels: the external display's current mode when one is connected (its
    /// `UIScreen.currentMode.size`, whatever it is: 1920 × 1080, 3840 × 2160, …), else `previewOnlySize`.
    @Published private(set) var slmSize = HologramModel.previewOnlySize
    /// Whether the SLM shows a best-quality photo (`captureBestQuality`); the stream's frames wait until `goLive`.
    @Published private(set) var holdingPhoto = false
    /// The photo mode's progress in [0, 1] while it runs, else nil.
    @Published private(set) var photoProgress: Double?
    /// The last on-device benchmark (`HologramGenerator.benchmark`), or nil before the first.
    @Published private(set) var benchmarkText: String?
    /// The viewer's spectacle prescription, corrected in every frame (docs/ABERRATION.md): sphere and cylinder
    /// in dioptres (a myope's sphere is negative), axis in degrees counterclockwise as the viewer sees the
    /// image. nil: none. Changing it remakes the generator with the prescription in its configuration (it then
    /// runs on the CPU and encodes with AA-DPM, which holds for corrected fields).
    @Published var prescription: Prescription? = nil {
        didSet {
            lock.lock()
            currentPrescription = prescription
            lock.unlock()
            captureQueue.async {
                guard self.generator != nil else { return }
                do {
                    try self.makeGenerator(size: self.generatorSize)
                } catch {
                    self.publish(status: "Prescription not applied: \(error)")
                }
            }
        }
    }
    /// Focus of the preview as normalised depth, 0 = near, 1 = far.
    @Published var focus: Float = 0.5 {
        didSet {
            lock.lock()
            currentFocus = focus
            lock.unlock()
            requestPreview()
        }
    }

    private let captureSession = AVCaptureSession()
    private let arSession = ARSession()
    /// Converts ARKit's YpCbCr colour (kept for the session: a context is costly to create).
    private let ciContext = CIContext()
    /// The timestamp of the last ARKit frame converted (on `captureQueue`).
    private var lastARFrameTimestamp: TimeInterval = 0
    private let videoOutput = AVCaptureVideoDataOutput()
    private let depthOutput = AVCaptureDepthDataOutput()
    private var synchronizer: AVCaptureDataOutputSynchronizer?
    private let captureQueue = DispatchQueue(label: "tensorholo.capture")
    private let previewQueue = DispatchQueue(label: "tensorholo.preview", qos: .utility)

    // Touched on `captureQueue` (and `previewQueue` under `lock`).
    private let lock = NSLock()
    private var generator: HologramGenerator?
    private var stream: HologramStream?
    private var latestFrame: RgbdFrame?
    private var previewInFlight = false
    private var currentFocus: Float = 0.5
    private var currentPrescription: Prescription?
    private var started = false
    private var lastDelivery = Date()
    /// Whether the relative depth accuracy was reported (on `captureQueue`).
    private var relativeDepthReported = false
    /// The size the generator on `captureQueue` was made for.
    private var generatorSize = HologramModel.previewOnlySize
    /// Set by `cancelPhoto`, read by the photo mode's progress callback (under `lock`).
    private var photoCancelled = false
    /// Whether the stream's frames reach the SLM (false while a photo is held; under `lock`).
    private var showStream = true
    /// Where the viewer looks, as fractions of the hologram's width and height (0…1, top-left origin): the face
    /// tracker's or the last touch's; nil: none yet, full 3D frames (under `lock`).
    private var gaze: (x: Double, y: Double)?
    /// Whether the face tracker gives the gaze (then touches do not; under `lock`).
    private var faceGaze = false

    /// The gaze from a touch on the preview, as fractions of its width and height; ignored while the face
    /// tracker gives one.
    func setTouchGaze(x: Double, y: Double) {
        lock.lock()
        if !faceGaze {
            gaze = (min(max(x, 0), 1), min(max(y, 0), 1))
        }
        lock.unlock()
    }

    /// Asks for the camera, creates the generator (times the CNN plans: a few seconds) and starts capturing.
    /// Safe to call again: only the first call starts.
    func start() {
        lock.lock()
        let first = !started
        started = true
        lock.unlock()
        guard first else { return }
        AVCaptureDevice.requestAccess(for: .video) { granted in
            guard granted else {
                return self.publish(status: "Camera access denied: allow it in Settings")
            }
            self.captureQueue.async { self.setUp() }
        }
    }

    /// Called by the external display's scene: the display's mode in pixels when it connects, nil when it
    /// disconnects. The generator is remade at that size (a few seconds, off the main thread) when it changes.
    func setExternalDisplay(width: Int?, height: Int?) {
        let size: (width: UInt32, height: UInt32)
        if let width = width, let height = height, let w = UInt32(exactly: width), let h = UInt32(exactly: height), w > 0, h > 0 {
            size = (w, h)
        } else {
            size = Self.previewOnlySize
        }
        let connected = width != nil
        DispatchQueue.main.async {
            self.externalDisplayConnected = connected
            self.slmSize = size
        }
        captureQueue.async {
            guard self.generator != nil, size != self.generatorSize else { return }
            do {
                try self.makeGenerator(size: size)
            } catch {
                self.publish(status: "Cannot render at \(size.width)×\(size.height): \(error)")
            }
        }
    }

    /// A generator and its stream for `size` (on `captureQueue`); the previous stream finishes its frames first.
    private func makeGenerator(size: (width: UInt32, height: UInt32)) throws {
        publish(status: "Preparing the hologram CNN for \(size.width)×\(size.height)…")
        let generator = try HologramGenerator(config: generatorConfig(size: size))
        let handler = PatternsHandler(
            onPatterns: { [weak self] index, patterns in self?.deliver(index: index, patterns: patterns) },
            onError: { [weak self] error in self?.publish(status: error.description) }
        )
        let stream = try generator.stream(listener: handler)
        lock.lock()
        let old = self.stream
        self.generator = generator
        self.stream = stream
        generatorSize = size
        lock.unlock()
        old?.close()
        let info = try generator.info()
        publish(status: "Running: \(size.width)×\(size.height), \(info.layers) layers, CNN layout \(info.cnnLayout); \(info.displayMapping)")
    }

    /// The generator's configuration for a `size` SLM: the display profile bundled with the app (`display.json`:
    /// pitch, lasers, volume, offset; docs/DISPLAYS.md) where there is one, else the paper's 8 µm display, and the
    /// viewer's prescription where one is set (it replaces the profile's). The
    /// display's mode gives the size (it is what the SLM is sent). A profile the shipped CNNs cannot serve fails
    /// when the generator is made, naming the key (`volume_depth_m`, `wavelengths_m`…).
    private func generatorConfig(size: (width: UInt32, height: UInt32)) throws -> GeneratorConfig {
        var config: GeneratorConfig
        if let url = Bundle.main.url(forResource: "display", withExtension: "json") {
            let profile = try displayProfileFromJson(json: String(contentsOf: url, encoding: .utf8))
            config = try generatorConfigForDisplay(profile: profile)
            config.width = size.width
            config.height = size.height
        } else {
            config = GeneratorConfig(width: size.width, height: size.height)
        }
        lock.lock()
        let prescription = currentPrescription
        lock.unlock()
        if let prescription = prescription {
            config.prescription = prescription
        }
        // A 5° fovea behind the paper's 21 mm eyepiece (a display profile's own eyepiece would go here).
        config.foveation = Foveation()
        return config
    }

    private func setUp() {
        do {
            let size = DispatchQueue.main.sync { slmSize }
            try makeGenerator(size: size)
            if ARWorldTrackingConfiguration.supportsFrameSemantics(.sceneDepth) {
                startARSession()
            } else {
                try configureSession()
                captureSession.startRunning()
            }
        } catch {
            publish(status: "Cannot start: \(error)")
        }
    }

    /// LiDAR: ARKit's world tracking with scene depth, frames delivered on `captureQueue`.
    private func startARSession() {
        let configuration = ARWorldTrackingConfiguration()
        configuration.frameSemantics = [.sceneDepth]
        // The viewer's face through the front camera while the back camera tracks the world: the gaze.
        configuration.userFaceTrackingEnabled = ARWorldTrackingConfiguration.supportsUserFaceTracking
        arSession.delegate = self
        arSession.delegateQueue = captureQueue
        arSession.run(configuration)
    }

    /// `ARSessionDelegate`: one ARKit frame, on `captureQueue`. ARKit delivers 60 a second; at most 30 are
    /// converted (the stream drops the oldest waiting frame anyway). The depth below medium confidence is left out.
    func session(_ session: ARSession, didUpdate frame: ARFrame) {
        guard frame.timestamp - lastARFrameTimestamp >= 1.0 / 30 else { return }
        lastARFrameTimestamp = frame.timestamp
        if let face = frame.anchors.compactMap({ $0 as? ARFaceAnchor }).first, face.isTracked,
           let point = screenGaze(face: face, camera: frame.camera) {
            lock.lock()
            faceGaze = true
            gaze = point
            lock.unlock()
        }
        do {
            // Portrait UI: ARKit's buffers are the sensor's landscape, turned 90° counter-clockwise.
            try push(RgbdFrame(frame: frame, orientation: .right, minConfidence: .medium, context: ciContext))
        } catch {
            publish(status: error.localizedDescription)
        }
    }

    /// Where the face's gaze meets the phone's screen, as fractions of the portrait screen's width and height, or
    /// nil when it looks away from the screen. The gaze ray runs from between the eyes towards
    /// `ARFaceAnchor.lookAtPoint` (face coordinates, metres); the screen is approximated by the camera's plane,
    /// `screenHalfSize` metres either side of the camera's axis (a 6.1" phone; an app would read the device's).
    private func screenGaze(face: ARFaceAnchor, camera: ARCamera) -> (x: Double, y: Double)? {
        let screenHalfSize = SIMD2<Float>(0.032, 0.070)
        let toCamera = camera.transform.inverse * face.transform
        let eyes = (face.leftEyeTransform.columns.3 + face.rightEyeTransform.columns.3) / 2
        let origin = toCamera * SIMD4<Float>(eyes.x, eyes.y, eyes.z, 1)
        let target = toCamera * SIMD4<Float>(face.lookAtPoint, 1)
        let direction = target - origin
        // The camera's plane is z = 0 in its own coordinates; the face is at z > 0 (in front of the screen).
        guard abs(direction.z) > 1e-6 else { return nil }
        let t = -origin.z / direction.z
        guard t > 0 else { return nil }
        let hit = origin + t * direction
        // ARKit's camera axes are the sensor's landscape ones: x along the long side. Portrait: x ↔ y.
        let u = 0.5 + Double(hit.y / screenHalfSize.x) / 2
        let v = 0.5 + Double(hit.x / screenHalfSize.y) / 2
        guard (0...1).contains(u), (0...1).contains(v) else { return nil }
        return (u, v)
    }

    /// `ARSessionDelegate`: the session stopped (camera denied, sensor failure).
    func session(_ session: ARSession, didFailWithError error: Error) {
        publish(status: "ARKit: \(error.localizedDescription)")
    }

    /// Colour (BGRA) + depth from the best depth camera, synchronised.
    private func configureSession() throws {
        guard let device = AVCaptureDevice.default(.builtInLiDARDepthCamera, for: .video, position: .back)
            ?? AVCaptureDevice.default(.builtInDualWideCamera, for: .video, position: .back)
            ?? AVCaptureDevice.default(.builtInDualCamera, for: .video, position: .back)
        else {
            throw TensorholoError.Unsupported(message: "this device has no back depth camera (LiDAR or dual camera)")
        }
        captureSession.beginConfiguration()
        defer { captureSession.commitConfiguration() }
        captureSession.sessionPreset = .photo
        let input = try AVCaptureDeviceInput(device: device)
        guard captureSession.canAddInput(input) else {
            throw TensorholoError.Unsupported(message: "cannot use the camera as a capture input")
        }
        captureSession.addInput(input)

        // The library reads BGRA, not the camera's default YpCbCr 4:2:0.
        videoOutput.videoSettings = [kCVPixelBufferPixelFormatTypeKey as String: kCVPixelFormatType_32BGRA]
        videoOutput.alwaysDiscardsLateVideoFrames = true
        depthOutput.isFilteringEnabled = true
        depthOutput.alwaysDiscardsLateDepthData = true
        guard captureSession.canAddOutput(videoOutput), captureSession.canAddOutput(depthOutput) else {
            throw TensorholoError.Unsupported(message: "cannot capture video and depth together")
        }
        captureSession.addOutput(videoOutput)
        captureSession.addOutput(depthOutput)
        depthOutput.connection(with: .depthData)?.isEnabled = true

        // A video format with depth (the `.photo` preset's may have none, e.g. on the LiDAR camera), then its
        // largest depth format in metres (the library also takes disparity).
        try device.lockForConfiguration()
        defer { device.unlockForConfiguration() }
        if device.activeFormat.supportedDepthDataFormats.isEmpty,
           let format = device.formats.last(where: { !$0.supportedDepthDataFormats.isEmpty }) {
            device.activeFormat = format
        }
        let depthFormats = device.activeFormat.supportedDepthDataFormats.filter {
            let type = CMFormatDescriptionGetMediaSubType($0.formatDescription)
            return type == kCVPixelFormatType_DepthFloat32 || type == kCVPixelFormatType_DepthFloat16
        }
        let width = { (format: AVCaptureDevice.Format) in CMVideoFormatDescriptionGetDimensions(format.formatDescription).width }
        if let largest = depthFormats.max(by: { width($0) < width($1) }) {
            device.activeDepthDataFormat = largest
        }

        let synchronizer = AVCaptureDataOutputSynchronizer(dataOutputs: [videoOutput, depthOutput])
        synchronizer.setDelegate(self, queue: captureQueue)
        self.synchronizer = synchronizer
    }

    /// `AVCaptureDataOutputSynchronizerDelegate`: one colour + depth pair, on `captureQueue`. Pushing never
    /// blocks: the stream drops the oldest waiting frame when the CNN falls behind the camera.
    func dataOutputSynchronizer(
        _ synchronizer: AVCaptureDataOutputSynchronizer,
        didOutput synchronizedDataCollection: AVCaptureSynchronizedDataCollection
    ) {
        guard let video = synchronizedDataCollection.synchronizedData(for: videoOutput) as? AVCaptureSynchronizedSampleBufferData,
              let depth = synchronizedDataCollection.synchronizedData(for: depthOutput) as? AVCaptureSynchronizedDepthData,
              !video.sampleBufferWasDropped, !depth.depthDataWasDropped
        else { return }
        do {
            // Portrait UI, back camera: the buffers are the sensor's landscape, turned 90° counter-clockwise.
            // Relative depth (not metres) is fine with the automatic depth range this sample uses; say so once.
            if depth.depthData.isRelativeDepth && !relativeDepthReported {
                relativeDepthReported = true
                publish(status: "Depth accuracy is relative (not metres): the automatic depth range still applies")
            }
            try push(RgbdFrame(sampleBuffer: video.sampleBuffer, depthData: depth.depthData, orientation: .right))
        } catch {
            publish(status: error.localizedDescription)
        }
    }

    /// Keeps `frame` for the preview and the photo mode and pushes it into the stream (never blocks).
    private func push(_ frame: RgbdFrame) throws {
        lock.lock()
        latestFrame = frame
        let stream = self.stream
        let gaze = self.gaze
        let size = generatorSize
        lock.unlock()
        if let gaze = gaze {
            // Fractions of the hologram to its pixels (0, 0 the top-left pixel's centre).
            let point = Gaze(x: gaze.x * Double(size.width - 1), y: gaze.y * Double(size.height - 1))
            _ = try stream?.pushFoveated(frame: frame, gaze: point)
        } else {
            _ = try stream?.push(frame: frame)
        }
    }

    /// The stream's result (its background thread): the SLM image for the external display, then a preview.
    private func deliver(index: UInt64, patterns: SlmPatterns) {
        let image = try? patterns.cgImage()
        let now = Date()
        lock.lock()
        let period = now.timeIntervalSince(lastDelivery)
        lastDelivery = now
        let show = showStream
        lock.unlock()
        guard show else { return }
        DispatchQueue.main.async {
            self.slmImage = image
            self.status = String(format: "Frame %llu: %.1f fps, CNN %.0f ms", index, 1 / max(period, 1e-3), patterns.timings.cnnMs)
        }
        requestPreview()
    }

    /// Renders a preview of the latest frame at the current focus on `previewQueue`, one at a time (requests
    /// while one runs are skipped: the next delivered frame asks again).
    private func requestPreview() {
        lock.lock()
        guard !previewInFlight, let generator = generator, let frame = latestFrame else {
            lock.unlock()
            return
        }
        previewInFlight = true
        let focus = currentFocus
        lock.unlock()
        previewQueue.async {
            let image = try? generator.preview(frame: frame, focus: focus).cgImage()
            self.lock.lock()
            self.previewInFlight = false
            self.lock.unlock()
            DispatchQueue.main.async { self.previewImage = image }
        }
    }

    /// Times `frames` renders of the library's built-in scene at the SLM's resolution on `previewQueue` (the
    /// generator runs one call at a time, so the stream pauses meanwhile) and shows the median stage timings
    /// and the CNN plan this device chose.
    func runBenchmark(frames: UInt32 = 10) {
        guard let generator = generator else { return }
        benchmarkText = "Benchmarking \(frames) frames…"
        previewQueue.async {
            let text: String
            do {
                let report = try generator.benchmark(frames: frames)
                let m = report.median
                if report.info.backend == "gpu" {
                    text = String(
                        format: "%.1f fps on the GPU (%@): GPU %.0f ms, input %.0f ms",
                        report.fps, report.info.gpuAdapter ?? "?", m.gpuMs, m.cnnMs)
                } else {
                    text = String(
                        format: "%.1f fps on the CPU: CNN %.0f ms, offset %.0f ms, pre-filter %.0f ms, encoding %.0f ms; %@, %u threads (%@)",
                        report.fps, m.cnnMs, m.offsetMs, m.prefilterMs, m.encodingMs,
                        report.info.cnnLayout, report.info.cnnThreads, report.info.backendReason)
                }
            } catch {
                text = "Benchmark failed: \(error)"
            }
            DispatchQueue.main.async { self.benchmarkText = text }
        }
    }

    /// The "best quality" photo: the latest frame refined on `previewQueue` (`HologramGenerator.renderRefined`:
    /// 10 iterations of focal-stack refinement from the CNN's codes against the frame's SM-LBM focal stack, about
    /// +4 dB, seconds on a phone; docs/REFINE.md). The refined pattern stays on the SLM until `goLive`.
    func captureBestQuality(iterations: UInt32 = 10) {
        lock.lock()
        guard let generator = generator, let frame = latestFrame else {
            lock.unlock()
            return
        }
        photoCancelled = false
        lock.unlock()
        photoProgress = 0
        let progress = PhotoProgress(model: self)
        previewQueue.async {
            do {
                let patterns = try generator.renderRefined(
                    frame: frame, settings: RefineSettings(iterations: iterations), progress: progress)
                let image = try patterns.cgImage()
                self.lock.lock()
                self.showStream = false
                self.lock.unlock()
                DispatchQueue.main.async {
                    self.slmImage = image
                    self.holdingPhoto = true
                    self.photoProgress = nil
                    self.status = "Best quality photo on the SLM"
                }
            } catch {
                DispatchQueue.main.async {
                    self.photoProgress = nil
                    self.status = "Best quality: \(error)"
                }
            }
        }
    }

    /// Stops a running `captureBestQuality` at its next iteration.
    func cancelPhoto() {
        lock.lock()
        photoCancelled = true
        lock.unlock()
    }

    /// Back to the live stream after `captureBestQuality`.
    func goLive() {
        lock.lock()
        showStream = true
        lock.unlock()
        holdingPhoto = false
    }

    /// The photo mode's progress callback (on `previewQueue`): publishes the fraction done, answers `cancelPhoto`.
    fileprivate func photoIteration(_ iteration: UInt32, of iterations: UInt32) -> Bool {
        DispatchQueue.main.async { self.photoProgress = Double(iteration) / Double(max(iterations, 1)) }
        lock.lock()
        defer { lock.unlock() }
        return !photoCancelled
    }

    private func publish(status: String) {
        DispatchQueue.main.async { self.status = status }
    }
}

/// Relays the photo mode's iterations to the model (uniffi's `RefineProgress` callback interface).
private final class PhotoProgress: RefineProgress, @unchecked Sendable {
    private weak var model: HologramModel?

    init(model: HologramModel) {
        self.model = model
    }

    func onIteration(iteration: UInt32, iterations: UInt32, psnrDb: Double) -> Bool {
        model?.photoIteration(iteration, of: iterations) ?? false
    }
}
