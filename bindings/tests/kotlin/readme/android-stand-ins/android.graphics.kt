// Stand-ins for the Android and ARCore classes that the library's Android-only helpers (ImageFrames.kt,
// ArCoreFrames.kt, SlmBitmaps.kt) and android/README.md's example use, so that kotlinc compiles them on a plain
// JVM (bindings/tests/kotlin/check.sh). Only the members used, with the platform's names and types; bodies throw.
// They make the helpers' and the bindings' names checkable; the Android APIs themselves are not checked here
// (Gradle compiles against android.jar and ARCore: android/README.md).
package android.graphics

import java.nio.Buffer

class Bitmap private constructor() {
    enum class Config { ARGB_8888 }

    val isMutable: Boolean get() = TODO("stand-in")
    val isRecycled: Boolean get() = TODO("stand-in")
    val width: Int get() = TODO("stand-in")
    val height: Int get() = TODO("stand-in")
    val config: Config get() = TODO("stand-in")

    fun copyPixelsFromBuffer(src: Buffer): Unit = TODO("stand-in")

    companion object {
        @JvmStatic
        fun createBitmap(width: Int, height: Int, config: Config): Bitmap = TODO("stand-in")
    }
}

object ImageFormat {
    const val YUV_420_888 = 0x23
    const val DEPTH16 = 0x44363159
}
