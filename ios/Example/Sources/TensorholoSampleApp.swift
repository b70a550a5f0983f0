import SwiftUI
import UIKit

/// The sample app: the phone shows the simulated hologram with a focus slider; an external display (the SLM's
/// HDMI input, over USB-C DisplayPort) shows the SLM pattern full-screen in a scene of its own.
///
/// How the external display's scene arrives:
/// - iOS 16–26: iOS offers a scene of role `UIWindowSceneSessionRoleExternalDisplayNonInteractive` when a display
///   connects; `Info.plist` declares that role (`UISceneConfigurations`, configuration "SLM" →
///   `ExternalDisplaySceneDelegate`) with `UIApplicationSupportsMultipleScenes` on, and `AppDelegate` returns the
///   same configuration. Without the declaration iOS mirrors the phone's screen instead (`ios/check.sh` checks
///   the plist).
/// - iOS 27 and later: the app also registers a scene accessory, `UISceneAccessory.externalNonInteractive(
///   sceneConfiguration:)` on a view controller of the main window (`SceneAccessoryRegistrar`), so that the
///   system presents the same scene delegate when a display connects (a quoted Apple article says that from
///   iOS 27 the external-display scene arrives only then; both paths are kept).
@main
struct TensorholoSampleApp: App {
    @UIApplicationDelegateAdaptor(AppDelegate.self) private var appDelegate

    var body: some Scene {
        WindowGroup {
            ContentView(model: HologramModel.shared)
                .background(SceneAccessoryRegistrar().frame(width: 0, height: 0))
        }
    }
}

/// The name of the external display's scene configuration in `Info.plist`.
let slmSceneConfigurationName = "SLM"

/// Chooses the scene delegate per role: the external display gets `ExternalDisplaySceneDelegate` (the plist's
/// "SLM" configuration), every other scene SwiftUI's own (a configuration without a delegate class).
final class AppDelegate: NSObject, UIApplicationDelegate {
    func application(
        _ application: UIApplication,
        configurationForConnecting connectingSceneSession: UISceneSession,
        options: UIScene.ConnectionOptions
    ) -> UISceneConfiguration {
        if connectingSceneSession.role == .windowExternalDisplayNonInteractive {
            let configuration = UISceneConfiguration(name: slmSceneConfigurationName, sessionRole: connectingSceneSession.role)
            configuration.delegateClass = ExternalDisplaySceneDelegate.self
            return configuration
        }
        return UISceneConfiguration(name: nil, sessionRole: connectingSceneSession.role)
    }
}

/// Registers the external display's scene accessory (iOS 27 and later) from a view controller of the main
/// window; on earlier systems it does nothing (the plist's scene configuration is enough there).
struct SceneAccessoryRegistrar: UIViewControllerRepresentable {
    func makeUIViewController(context: Context) -> UIViewController {
        AccessoryViewController()
    }

    func updateUIViewController(_ uiViewController: UIViewController, context: Context) {}

    final class AccessoryViewController: UIViewController {
        /// The registration (a `UISceneAccessoryRegistration` on iOS 27+), kept while the view controller lives.
        private var registration: AnyObject?

        override func viewDidAppear(_ animated: Bool) {
            super.viewDidAppear(animated)
            guard registration == nil else { return }
            if #available(iOS 27, *) {
                let configuration = UISceneConfiguration(
                    name: slmSceneConfigurationName, sessionRole: .windowExternalDisplayNonInteractive
                )
                configuration.delegateClass = ExternalDisplaySceneDelegate.self
                registration = Self.registerExternalDisplayAccessory(on: self, configuration: configuration)
            }
        }

        /// `registerSceneAccessory(.externalNonInteractive(sceneConfiguration: configuration))` of the iOS 27 SDK
        /// (`UIViewController.registerSceneAccessory(_:)`, `UISceneAccessory.externalNonInteractive(
        /// sceneConfiguration:)`), called through the Objective-C runtime with the same selectors so that the
        /// sample still builds with older SDKs (CI's Xcode 15). With the iOS 27 SDK, write the typed call instead.
        /// Returns the `UISceneAccessoryRegistration`, or nil where the API is missing.
        static func registerExternalDisplayAccessory(on controller: UIViewController, configuration: UISceneConfiguration) -> AnyObject? {
            guard let accessoryType = NSClassFromString("UISceneAccessory") as? NSObject.Type else { return nil }
            let make = NSSelectorFromString("externalNonInteractiveSceneAccessoryWithConfiguration:")
            let register = NSSelectorFromString("registerSceneAccessory:")
            guard accessoryType.responds(to: make), controller.responds(to: register),
                  let accessory = accessoryType.perform(make, with: configuration)?.takeUnretainedValue()
            else { return nil }
            return controller.perform(register, with: accessory)?.takeUnretainedValue()
        }
    }
}

/// The external display's scene (role `.windowExternalDisplayNonInteractive`, iOS 16+): a window showing the
/// SLM pattern one image pixel per display pixel. Without this window iOS would mirror the phone's screen.
///
/// Pixel-exact output needs, besides the unscaled image (`SlmDisplayView`):
/// - the screen's `overscanCompensation` set to `.none`: the default `.scale` shrinks the whole frame on displays that report
///   overscan (TVs), resampling every phase code (`UIScreen.h`);
/// - holograms computed at the screen's current mode (`screen.currentMode.size`, pixels), not a fixed size.
final class ExternalDisplaySceneDelegate: UIResponder, UIWindowSceneDelegate {
    var window: UIWindow?

    func scene(_ scene: UIScene, willConnectTo session: UISceneSession, options connectionOptions: UIScene.ConnectionOptions) {
        guard let windowScene = scene as? UIWindowScene else { return }
        let screen = windowScene.screen
        screen.overscanCompensation = .none
        // The mode's size in pixels; nativeBounds (pixels) when no mode is reported.
        let size = screen.currentMode?.size ?? screen.nativeBounds.size
        let window = UIWindow(windowScene: windowScene)
        let view = SlmDisplayView(model: HologramModel.shared, displayScale: screen.scale)
        window.rootViewController = UIHostingController(rootView: view)
        window.isHidden = false
        self.window = window
        HologramModel.shared.setExternalDisplay(width: Int(size.width), height: Int(size.height))
    }

    func sceneDidDisconnect(_ scene: UIScene) {
        window?.isHidden = true
        window = nil
        HologramModel.shared.setExternalDisplay(width: nil, height: nil)
    }
}
