// Sample app: ARCore Depth API camera frames → tensorholo HologramStream → SLM patterns full-screen on a
// second display (Presentation) and a focusable preview on the phone. See ../README.md ("Sample").
import org.jetbrains.kotlin.gradle.dsl.JvmTarget

plugins {
    id("com.android.application")
    id("org.jetbrains.kotlin.android")
}

android {
    namespace = "org.tensorholo.sample"
    compileSdk = 35

    defaultConfig {
        applicationId = "org.tensorholo.sample"
        minSdk = 26
        targetSdk = 35
        versionCode = 1
        versionName = "1.0"
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
