import SwiftUI
import UIKit

/// The sample app: the phone shows the simulated hologram with a focus slider; an external display (the SLM's
/// HDMI input) shows the SLM pattern full-screen in a scene of its own.
@main
struct TensorholoSampleApp: App {
    @UIApplicationDelegateAdaptor(AppDelegate.self) private var appDelegate

    var body: some Scene {
        WindowGroup {
            ContentView(model: HologramModel.shared)
        }
    }
}

/// Chooses the scene delegate per role: the external display gets `ExternalDisplaySceneDelegate`, every other
/// scene SwiftUI's own (a configuration without a delegate class).
final class AppDelegate: NSObject, UIApplicationDelegate {
    func application(
        _ application: UIApplication,
        configurationForConnecting connectingSceneSession: UISceneSession,
        options: UIScene.ConnectionOptions
    ) -> UISceneConfiguration {
        let configuration = UISceneConfiguration(name: nil, sessionRole: connectingSceneSession.role)
        if connectingSceneSession.role == .windowExternalDisplayNonInteractive {
            configuration.delegateClass = ExternalDisplaySceneDelegate.self
        }
        return configuration
    }
}

/// The external display's scene (role `.windowExternalDisplayNonInteractive`, iOS 16+): a window showing the
/// SLM pattern one image pixel per display pixel. Without this window iOS would mirror the phone's screen.
final class ExternalDisplaySceneDelegate: UIResponder, UIWindowSceneDelegate {
    var window: UIWindow?

    func scene(_ scene: UIScene, willConnectTo session: UISceneSession, options connectionOptions: UIScene.ConnectionOptions) {
        guard let windowScene = scene as? UIWindowScene else { return }
        let window = UIWindow(windowScene: windowScene)
        let view = SlmDisplayView(model: HologramModel.shared, displayScale: windowScene.screen.scale)
        window.rootViewController = UIHostingController(rootView: view)
        window.isHidden = false
        self.window = window
        HologramModel.shared.setExternalDisplayConnected(true)
    }

    func sceneDidDisconnect(_ scene: UIScene) {
        window?.isHidden = true
        window = nil
        HologramModel.shared.setExternalDisplayConnected(false)
    }
}
