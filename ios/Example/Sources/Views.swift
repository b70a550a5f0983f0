import SwiftUI

/// The phone's screen: the simulated view of the hologram (what an eye focused at `focus` sees), a focus slider
/// from near to far, and the state of the pipeline and of the external display.
struct ContentView: View {
    @ObservedObject var model: HologramModel

    var body: some View {
        VStack(spacing: 16) {
            Group {
                if let image = model.previewImage {
                    Image(decorative: image, scale: 1)
                        .resizable()
                        .aspectRatio(contentMode: .fit)
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
            Text(model.externalDisplayConnected
                ? "SLM pattern on the external display (\(model.slmSize.width)×\(model.slmSize.height))"
                : "Connect the SLM (USB-C DisplayPort / HDMI) to show the pattern")
                .font(.footnote)
            Text(model.status)
                .font(.caption.monospacedDigit())
                .foregroundColor(.secondary)
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
