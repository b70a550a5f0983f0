// The tensorholo Android library (.aar): the uniffi Kotlin bindings (package `tensorholo`, generated into
// bindings/generated/kotlin, compiled from there), libtensorholo_ffi.so per ABI (src/main/jniLibs, filled
// by ../build-aar.sh), JNA, and the helpers of package `tensorholo.android`.
import org.jetbrains.kotlin.gradle.dsl.JvmTarget

plugins {
    id("com.android.library")
    id("org.jetbrains.kotlin.android")
}

val repoRoot: File = rootDir.parentFile

/** The workspace version ([workspace.package] in Cargo.toml): what the library's `version()` returns. */
val workspaceVersion: String =
    Regex("""(?ms)^\[workspace\.package\].*?^version\s*=\s*"([^"]+)"""")
        .find(repoRoot.resolve("Cargo.toml").readText())?.groupValues?.get(1)
        ?: error("no version in [workspace.package] of ${repoRoot.resolve("Cargo.toml")}")

// JNA: 5.17.0 was the first release whose libjnidispatch.so is 16 KB-page aligned on Android (Android 15+
// devices with 16 KB pages; Google Play requires it for apps targeting SDK 35+); 5.18.1 keeps that and fixes
// a deadlock (#1681) and a race (#1686) reported from multi-threaded use such as uniffi's (a stream's
// thread calling back into Kotlin while the app calls the generator). Linux CI runs the same JVM tests with
// Debian's JNA (bindings/tests/kotlin/check.sh); uniffi's bindings use no API newer than 5.x.
val jnaVersion = "5.18.1"

// ARCore: only for RgbdFrames.fromArFrame (ArCoreFrames.kt), compileOnly: an app that calls it has ARCore
// itself; the others never load that class. The version the sample uses.
val arcoreVersion = "1.57.0"

android {
    namespace = "org.tensorholo"
    // 36: ARCore 1.57's own compileSdk (Google's ARCore samples build with 36 since 1.50) and the API 36
    // names the sample uses behind version checks. minSdk stays 26.
    compileSdk = 36

    defaultConfig {
        minSdk = 26
        testInstrumentationRunner = "androidx.test.runner.AndroidJUnitRunner"
        consumerProguardFiles("consumer-rules.pro")
    }

    buildTypes {
        release {
            // A library is shrunk by the app that uses it (consumer-rules.pro keeps what JNA needs).
            isMinifyEnabled = false
        }
    }

    compileOptions {
        sourceCompatibility = JavaVersion.VERSION_17
        targetCompatibility = JavaVersion.VERSION_17
    }

    sourceSets["main"].apply {
        // The committed generated bindings, compiled in place (no copy in this module).
        kotlin.srcDir(repoRoot.resolve("bindings/generated/kotlin"))
        // libtensorholo_ffi.so per ABI (git-ignored; ../build-aar.sh runs cargo ndk into it).
        jniLibs.srcDir("src/main/jniLibs")
    }

    testOptions {
        // JVM unit tests (src/test): the host build of the library through JNA, and the real frames of
        // bindings/tests/frames.py when given: gradle :tensorholo:testDebugUnitTest
        //   -Ptensorholo.hostLibDir=<dir of libtensorholo_ffi.so> (default <repo>/target/debug)
        //   -Ptensorholo.cases=<dir written by python3 bindings/tests/frames.py DIR> (else those tests skip)
        unitTests.all { test ->
            test.systemProperty(
                "jna.library.path",
                providers.gradleProperty("tensorholo.hostLibDir").getOrElse(repoRoot.resolve("target/debug").path),
            )
            providers.gradleProperty("tensorholo.cases").orNull?.let { test.systemProperty("tensorholo.cases", it) }
            test.systemProperty("tensorholo.version", workspaceVersion)
        }
    }
}

kotlin {
    compilerOptions {
        jvmTarget.set(JvmTarget.JVM_17)
    }
}

dependencies {
    // The @aar carries libjnidispatch.so for every Android ABI.
    implementation("net.java.dev.jna:jna:$jnaVersion@aar")
    compileOnly("com.google.ar:core:$arcoreVersion")

    // JVM unit tests: the plain jar (with the desktop libjnidispatch) instead of the aar's natives.
    testImplementation("junit:junit:4.13.2")
    testImplementation("net.java.dev.jna:jna:$jnaVersion")

    androidTestImplementation("androidx.test:runner:1.6.2")
    androidTestImplementation("androidx.test.ext:junit:1.2.1")
}
