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

// JNA: 5.17.0 is the first release whose libjnidispatch.so is 16 KB-page aligned on Android (Android 15+
// devices with 16 KB pages; Google Play requires it for apps targeting SDK 35+). Linux CI runs the same
// JVM tests with Debian's JNA 5.13 (bindings/tests/kotlin/check.sh); uniffi's bindings use no API newer.
val jnaVersion = "5.17.0"

android {
    namespace = "org.tensorholo"
    compileSdk = 35

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

    // JVM unit tests: the plain jar (with the desktop libjnidispatch) instead of the aar's natives.
    testImplementation("junit:junit:4.13.2")
    testImplementation("net.java.dev.jna:jna:$jnaVersion")

    androidTestImplementation("androidx.test:runner:1.6.2")
    androidTestImplementation("androidx.test.ext:junit:1.2.1")
}
