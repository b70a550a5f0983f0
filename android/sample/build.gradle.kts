// Sample app: ARCore Depth API camera frames → tensorholo HologramStream → SLM patterns full-screen on a
// second display (Presentation) and a focusable preview on the phone. See ../README.md ("Sample").
import org.jetbrains.kotlin.gradle.dsl.JvmTarget

plugins {
    id("com.android.application")
    id("org.jetbrains.kotlin.android")
}

android {
    namespace = "org.tensorholo.sample"
    // 36: ARCore 1.57's compileSdk (Google's ARCore samples use 36 since 1.50); Display.isInternal is API 36.
    compileSdk = 36

    defaultConfig {
        applicationId = "org.tensorholo.sample"
        minSdk = 26
        targetSdk = 35
        versionCode = 1
        versionName = "1.0"
        // libtensorholo_ffi.so exists for these ABIs only (../build-aar.sh): without the filter the APK would
        // also carry JNA's 32-bit libjnidispatch.so and install on 32-bit devices, then fail to load the
        // library at run time. With it, Play serves the app to 64-bit devices (and x86_64 emulators) only.
        ndk {
            abiFilters += listOf("arm64-v8a", "x86_64")
        }
    }

    buildTypes {
        release {
            isMinifyEnabled = true
            proguardFiles(getDefaultProguardFile("proguard-android-optimize.txt"))
            // Installable for trying out; sign with your own key to distribute.
            signingConfig = signingConfigs.getByName("debug")
        }
    }

    compileOptions {
        sourceCompatibility = JavaVersion.VERSION_17
        targetCompatibility = JavaVersion.VERSION_17
    }
}

kotlin {
    compilerOptions {
        jvmTarget.set(JvmTarget.JVM_17)
    }
}

dependencies {
    implementation(project(":tensorholo"))
    // ARCore (Google Play Services for AR): the Depth API lives in the app, not in the library.
    implementation("com.google.ar:core:1.57.0")
}
