// Plugin versions for both modules. AGP 8.13 (Gradle ≥ 8.13, JDK 17) is the first AGP whose D8/R8 read
// Kotlin 2.3 class files (developer.android.com/build/kotlin-support).
plugins {
    id("com.android.library") version "8.13.2" apply false
    id("com.android.application") version "8.13.2" apply false
    id("org.jetbrains.kotlin.android") version "2.3.0" apply false
}
