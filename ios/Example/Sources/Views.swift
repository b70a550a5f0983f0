import SwiftUI

/// The phone's screen: the simulated view of the hologram (what an eye focused at `focus` sees), a focus slider
/// from near to far, and the state of the pipeline and of the external display.
struct ContentView: View {
    @ObservedObject var model: HologramModel

    var body: some View {
        VStack(spacing: 16) {
            Group {
                if let image = model.previewImage {
                    // A touch on the preview is the gaze where the device has no face tracking
                    // (docs/FOVEATION.md): the hologram's 3D CNN runs around it.
                    GeometryReader { geometry in
                        Image(decorative: image, scale: 1)
                            .resizable()
                            .aspectRatio(contentMode: .fit)
                            .frame(width: geometry.size.width, height: geometry.size.height)
                            .gesture(DragGesture(minimumDistance: 0).onChanged { touch in
                                model.setTouchGaze(
                                    x: touch.location.x / max(geometry.size.width, 1),
                                    y: touch.location.y / max(geometry.size.height, 1))
                            })
                    }
                } else {
                    ProgressView()
                }
            }
            .frame(maxWidth: .infinity, maxHeight: .infinity)
            Slider(value: $model.focus, in: 0...1) {
                Text("Focus")
            } minimumValueLabel: {
                Text("near")
            } maximumValueLabel: {
                Text("far")
            }
            PrescriptionView(model: model)
            Text(model.externalDisplayConnected
                ? "SLM pattern on the external display (\(model.slmSize.width)×\(model.slmSize.height))"
                : "Connect the SLM (USB-C DisplayPort / HDMI) to show the pattern")
                .font(.footnote)
            Text(model.status)
                .font(.caption.monospacedDigit())
                .foregroundColor(.secondary)
            HStack {
                if let progress = model.photoProgress {
                    ProgressView(value: progress) { Text("Best quality…") }
                    Button("Cancel") { model.cancelPhoto() }
                } else if model.holdingPhoto {
                    Button("Live") { model.goLive() }
                } else {
                    Button("Best quality") { model.captureBestQuality() }
                }
            }
            Button("Benchmark this device") { model.runBenchmark() }
            if let text = model.benchmarkText {
                Text(text)
                    .font(.caption.monospacedDigit())
            }
        }
        .padding()
        .onAppear { model.start() }
    }
}

/// The viewer's spectacle prescription: on or off, sphere and cylinder in 0.25 D steps, the axis in 5° steps.
/// Applied when a stepper is released (the generator is remade with it: a moment).
struct PrescriptionView: View {
    @ObservedObject var model: HologramModel
    @State private var enabled = false
    @State private var sphere = 0.0
    @State private var cylinder = 0.0
    @State private var axis = 90.0

    var body: some View {
        VStack(alignment: .leading, spacing: 4) {
            Toggle("Correct my eyes", isOn: $enabled)
            if enabled {
                Stepper("Sphere \(sphere, specifier: "%+.2f") D", value: $sphere, in: -20...20, step: 0.25)
                Stepper("Cylinder \(cylinder, specifier: "%+.2f") D", value: $cylinder, in: -10...10, step: 0.25)
                Stepper("Axis \(Int(axis))°", value: $axis, in: 0...180, step: 5)
            }
        }
        .font(.footnote)
        .onChange(of: enabled) { _ in apply() }
        .onChange(of: sphere) { _ in apply() }
        .onChange(of: cylinder) { _ in apply() }
        .onChange(of: axis) { _ in apply() }
    }

    private func apply() {
        model.prescription = enabled
            ? Prescription(sphereD: sphere, cylinderD: cylinder, axisDeg: cylinder == 0 ? nil : axis)
            : nil
    }
}

/// The external display's content: the SLM's HDMI frame, black around it, drawn from the top-left corner at one
/// image pixel per display pixel (`scale` = the screen's) and never interpolated, so that each code reaches the
/// SLM unchanged (with `overscanCompensation = .none` on the screen, set by `ExternalDisplaySceneDelegate`).
struct SlmDisplayView: View {
    @ObservedObject var model: HologramModel
    /// The external screen's points-to-pixels scale (`UIScreen.scale`, usually 1).
    let displayScale: CGFloat

    var body: some View {
        ZStack(alignment: .topLeading) {
            Color.black
            if let image = model.slmImage {
                Image(decorative: image, scale: displayScale)
                    .interpolation(.none)
            }
        }
        .ignoresSafeArea()
    }
}
