// Stand-in (see android.graphics.kt): android.media.Image, the members the helpers use.
package android.media

import java.nio.ByteBuffer

abstract class Image : AutoCloseable {
    abstract class Plane {
        abstract val buffer: ByteBuffer
        abstract val pixelStride: Int
        abstract val rowStride: Int
    }

    abstract val format: Int
    abstract val width: Int
    abstract val height: Int
    abstract val planes: Array<Plane>
}
