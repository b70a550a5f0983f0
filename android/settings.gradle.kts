// The Android library (:tensorholo, an .aar of the uniffi Kotlin bindings + libtensorholo_ffi.so per ABI +
// the camera/bitmap helpers) and an ARCore sample app (:sample). See README.md.
pluginManagement {
    repositories {
        google()
        mavenCentral()
        gradlePluginPortal()
    }
}

dependencyResolutionManagement {
    repositoriesMode.set(RepositoriesMode.FAIL_ON_PROJECT_REPOS)
    repositories {
        google()
        mavenCentral()
    }
}

rootProject.name = "tensorholo-android"
include(":tensorholo", ":sample")
