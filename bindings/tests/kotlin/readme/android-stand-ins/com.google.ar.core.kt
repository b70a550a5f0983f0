// Stand-ins (see android.graphics.kt): ARCore's Frame and Coordinates2d, the members ArCoreFrames.kt uses.
package com.google.ar.core

import android.media.Image

enum class Coordinates2d { TEXTURE_NORMALIZED, IMAGE_PIXELS }

abstract class Frame {
    abstract fun transformCoordinates2d(
        inputCoordinates: Coordinates2d,
        inputVertices2d: FloatArray,
        outputCoordinates: Coordinates2d,
        outputVertices2d: FloatArray,
    )

    abstract fun acquireCameraImage(): Image
    abstract fun acquireDepthImage16Bits(): Image
    abstract fun acquireRawDepthImage16Bits(): Image
    abstract fun acquireRawDepthConfidenceImage(): Image
}
