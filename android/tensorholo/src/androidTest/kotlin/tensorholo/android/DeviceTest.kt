// Instrumented tests (on a device or emulator: gradle :tensorholo:connectedDebugAndroidTest, after
// ../build-aar.sh filled src/main/jniLibs): the library loads through JNA from the APK, renders with the
// embedded CNNs, reports bad input as exceptions, streams, and makes bitmaps.

package tensorholo.android

import android.graphics.Bitmap
import android.graphics.Color
import androidx.test.ext.junit.runners.AndroidJUnit4
import java.util.Collections
import java.util.concurrent.TimeUnit
import java.util.concurrent.LinkedBlockingQueue
import org.junit.AfterClass
import org.junit.Assert.assertArrayEquals
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertNotNull
import org.junit.Assert.assertSame
import org.junit.Assert.assertThrows
import org.junit.Assert.assertTrue
import org.junit.BeforeClass
import org.junit.Test
import org.junit.runner.RunWith
import tensorholo.ColorFormat
import tensorholo.DepthFormat
import tensorholo.GeneratorConfig
import tensorholo.HologramGenerator
import tensorholo.PatternsListener
import tensorholo.RgbdFrame
import tensorholo.Rotation
import tensorholo.SlmPatterns
import tensorholo.TensorholoException

@RunWith(AndroidJUnit4::class)
class DeviceTest {
    companion object {
        private const val W = 64
        private const val H = 48
        private lateinit var gen: HologramGenerator

        @BeforeClass
        @JvmStatic
        fun open() {
            gen = HologramGenerator(GeneratorConfig(width = W.toUInt(), height = H.toUInt()))
        }

        @AfterClass
        @JvmStatic
        fun close() {
            gen.close()
        }

        /**
         * A 96 × 72 RGBA8 frame (colour gradients, a checkerboard in blue) with 48 × 36 ARCore millimetres
         * ramping from 500 mm at the left to 1500 mm at the right (`reversed`: right to left), as a landscape
         * sensor delivers it (no rotation).
         */
        fun syntheticFrame(reversed: Boolean = false): RgbdFrame {
            val (cw, ch, dw, dh) = listOf(96, 72, 48, 36)
            val rgba = ByteArray(cw * ch * 4) { i ->
                val (x, y) = (i / 4) % cw to (i / 4) / cw
                when (i % 4) {
                    0 -> (x * 255 / cw).toByte()
                    1 -> (y * 255 / ch).toByte()
                    2 -> (((x / 8 + y / 8) % 2) * 200).toByte()
                    else -> -1
                }
            }
            val depth = ByteArray(dw * dh * 2)
            for (y in 0 until dh) for (x in 0 until dw) {
                val t = if (reversed) dw - 1 - x else x
                val mm = 500 + 1000 * t / (dw - 1)
                depth[2 * (y * dw + x)] = (mm and 0xFF).toByte()
                depth[2 * (y * dw + x) + 1] = (mm ushr 8).toByte()
            }
            return RgbdFrame(
                color = rgba, colorFormat = ColorFormat.RGBA8, colorWidth = cw.toUInt(), colorHeight = ch.toUInt(),
                depth = depth, depthFormat = DepthFormat.MILLIMETRES_U16, depthWidth = dw.toUInt(),
                depthHeight = dh.toUInt(), rotation = Rotation.DEG0,
            )
        }
    }

    @Test
    fun rendersASyntheticFrameWithTheEmbeddedModel() {
        val frame = syntheticFrame()
        val p = gen.render(frame)
        assertEquals(W.toUInt() to H.toUInt(), p.width to p.height)
        for (plane in listOf(p.red, p.green, p.blue)) assertEquals(W * H, plane.size)
        // The automatic depth range is the 1st / 99th percentile of the frame's depths: 0.51 m and 1.49 m.
        assertEquals(0.51, p.zNearM!!, 0.02)
        assertEquals(1.49, p.zFarM!!, 0.02)
        // Deterministic, and the depth matters: the mirrored ramp gives another hologram.
        assertArrayEquals(p.green, gen.render(frame).green)
        assertFalse(p.green.contentEquals(gen.render(syntheticFrame(reversed = true)).green))
        // A phase hologram spreads over the phase circle.
        assertTrue(p.green.map { it.toInt() and 0xFF }.toSet().size > 64)
    }

    @Test
    fun badInputRaisesInvalidInput() {
        val frame = syntheticFrame()
        val e = assertThrows(TensorholoException.InvalidInput::class.java) {
            gen.render(frame.copy(depth = frame.depth.copyOf(frame.depth.size - 2)))
        }
        assertTrue(e.reason, e.reason.contains("depth"))
        assertThrows(TensorholoException.InvalidInput::class.java) { gen.preview(frame, 1.5f) }
        assertEquals(W.toUInt(), gen.render(frame).width) // still works
    }

    @Test
    fun streamCallsTheListenerInOrderOnAnotherThread() {
        val delivered = LinkedBlockingQueue<ULong>()
        val threads = Collections.synchronizedSet(mutableSetOf<Long>())
        val listener = object : PatternsListener {
            override fun onPatterns(index: ULong, patterns: SlmPatterns) {
                threads.add(Thread.currentThread().id)
                delivered.add(index)
            }

            override fun onError(error: TensorholoException) {
                delivered.add(ULong.MAX_VALUE)
            }
        }
        gen.stream(listener).use { stream ->
            for (i in 0 until 3) {
                assertEquals(i.toULong(), stream.push(syntheticFrame()))
                assertEquals(i.toULong(), delivered.poll(60, TimeUnit.SECONDS))
            }
            stream.finish()
        }
        assertFalse(Thread.currentThread().id in threads)
    }

    @Test
    fun toBitmapHoldsTheLaserCodes() {
        val p = gen.render(syntheticFrame())
        val bitmap = p.toBitmap()
        assertEquals(W to H, bitmap.width to bitmap.height)
        assertEquals(Bitmap.Config.ARGB_8888, bitmap.config)
        for (y in 0 until H) for (x in 0 until W) {
            val c = bitmap.getPixel(x, y)
            val i = y * W + x
            assertEquals(
                "pixel ($x, $y)",
                listOf(255, p.red[i].toInt() and 0xFF, p.green[i].toInt() and 0xFF, p.blue[i].toInt() and 0xFF),
                listOf(Color.alpha(c), Color.red(c), Color.green(c), Color.blue(c)),
            )
        }
        assertSame(bitmap, p.toBitmap(reuse = bitmap))
        val preview = gen.previewBitmap(syntheticFrame(), focus = 0.5f)
        assertNotNull(preview)
        assertEquals(W to H, preview.width to preview.height)
        assertEquals(255, Color.alpha(preview.getPixel(W / 2, H / 2)))
    }
}
