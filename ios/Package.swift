// swift-tools-version:5.9
// The Swift package of tensorholo for iOS apps (see README.md beside this file).
//
// Before the first build, run `ios/build-xcframework.sh` on a Mac: it builds the Rust library for the device and
// the simulators into `TensorholoFFI.xcframework` (the C module `TensorholoFFI`) and copies the generated
// bindings (`bindings/generated/swift/Tensorholo.swift`) into `Sources/Tensorholo/Generated/`. Both are
// git-ignored build products.
import PackageDescription

let package = Package(
    name: "Tensorholo",
    platforms: [
        .iOS(.v15),
        // Only with a macOS slice in the XCFramework (`TENSORHOLO_MACOS=1 ios/build-xcframework.sh`).
        .macOS(.v12),
    ],
    products: [
        .library(name: "Tensorholo", targets: ["Tensorholo"]),
    ],
    targets: [
        // The Rust static library `libtensorholo_ffi.a` per platform, with `TensorholoFFI.h` and its
        // `module.modulemap` (module `TensorholoFFI`, imported by the generated Swift).
        // To ship a prebuilt one instead: `.binaryTarget(name: "TensorholoFFI", url: "https://…/TensorholoFFI.xcframework.zip",
        // checksum: "<swift package compute-checksum TensorholoFFI.xcframework.zip>")`.
        .binaryTarget(name: "TensorholoFFI", path: "TensorholoFFI.xcframework"),
        // The generated bindings (Generated/Tensorholo.swift) and the hand-written Swift layer beside them.
        // linkerSettings: the system frameworks the static Rust library calls. wgpu's Metal back end (the GPU
        // path, cargo feature `gpu`, on by default) uses Metal and QuartzCore (CAMetalLayer); a static library
        // carries no link commands of its own, so without these an app fails to link with undefined Metal / CA
        // symbols. The rest of the library needs libSystem only (`cargo rustc … --print native-static-libs`).
        .target(
            name: "Tensorholo",
            dependencies: ["TensorholoFFI"],
            path: "Sources/Tensorholo",
            linkerSettings: [
                .linkedFramework("Metal"),
                .linkedFramework("QuartzCore"),
                .linkedFramework("CoreGraphics"),
                .linkedFramework("Foundation"),
            ]
        ),
        .testTarget(
            name: "TensorholoTests",
            dependencies: ["Tensorholo"],
            path: "Tests/TensorholoTests"
        ),
    ]
)
