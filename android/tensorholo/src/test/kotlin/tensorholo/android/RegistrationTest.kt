// JVM tests of the ARCore depth–colour registration (CameraPlanes.cropForTexture + the library's colour crop)
// and of the depth format chosen from Image.getFormat() (CameraPlanes.depthFormatOf), run by
// bindings/tests/kotlin/check.sh and Gradle. The end-to-end tests need the native library
// (-Djna.library.path): they read the converted frame back with convertFrame.

package tensorholo.android

import java.nio.ByteBuffer
import java.nio.ByteOrder
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertThrows
import org.junit.Assert.assertTrue
import org.junit.Test
import tensorholo.ConvertedFrame
import tensorholo.CropRect
import tensorholo.DepthFormat
import tensorholo.Fit
import tensorholo.RgbdFrame
import tensorholo.Rotation
import tensorholo.TensorholoException
import tensorholo.convertFrame

class RegistrationTest {
    companion object {
        /**
         * What `Frame.transformCoordinates2d(TEXTURE_NORMALIZED, textureCorners(), IMAGE_PIXELS, out)` writes
         * for a 16:9 texture on a 640 × 480 CPU image: the texture's corners (0,0), (0,1), (1,0), (1,1) land on
         * x = 0 / 640 and y = 60 / 420 (the texture sees the middle 360 rows), with float noise.
         */
        val CORNERS_16_9 = floatArrayOf(0f, 59.9996f, 0.0002f, 420.0003f, 639.9998f, 60.0001f, 640f, 419.9999f)

        /** `HardwareBuffer.D_16` samples (ARCore 16-bit depth), little-endian, `w × h` with a padded row. */
        fun depthD16(w: Int, h: Int, rowStride: Int, mm: (Int, Int) -> Int): ByteBuffer {
            val b = ByteBuffer.allocate(rowStride * (h - 1) + 2 * w).order(ByteOrder.LITTLE_ENDIAN)
            for (y in 0 until h) for (x in 0 until w) b.putShort(y * rowStride + 2 * x, mm(x, y).toShort())
            return b
        }

        /**
         * The ARCore scene of the test, by hand: a horizontal edge at 37 % of the depth's (the texture's) field
         * of view. In the 640 × 480 CPU image it lies at row 60 + 0.37 · 360 = 193.2: rows 0..192 bright (luma
         * 230), the rest dark (20). In the 160 × 90 depth (its rows span CPU rows 60..420) at row 0.37 · 90 =
         * 33.3: rows 0..32 at 0.5 m, the rest at 2 m. Converted with `crop` in portrait (`DEG90`), stretched to
         * the rotated crop's size, where the edge becomes vertical.
         */
        fun arcoreFrame(crop: CropRect?): Pair<RgbdFrame, ConvertedFrame> {
            val (w, h) = 640 to 480
            val y = ByteBuffer.wrap(ByteArray(w * h) { i -> (if (i / w <= 192) 230 else 20).toByte() })
            val chroma = ByteBuffer.wrap(ByteArray((w / 2) * (h / 2)) { 128.toByte() })
            val rgba = CameraPlanes.yuv420ToRgba(w, h, y, w, chroma, chroma.duplicate(), w / 2, 1)
            val depth = depthD16(160, 90, 2 * 160 + 16) { _, row -> if (row <= 32) 500 else 2000 }
            val format = CameraPlanes.depthFormatOf(CameraPlanes.HARDWARE_BUFFER_D_16)
            val frame = CameraPlanes.rgbdFrame(rgba, w, h, depth, 160, 90, 2 * 160 + 16, format, Rotation.DEG90, crop)
            val (outW, outH) = if (crop == null) h to w else crop.height.toInt() to crop.width.toInt()
            return frame to convertFrame(frame, outW.toUInt(), outH.toUInt(), Fit.STRETCH)
        }

        /** Last column of row `y` for which `dark` holds; the row must be `dark` up to it and not after. */
        fun lastColumn(width: Int, dark: (Int) -> Boolean): Int {
            val n = (0 until width).takeWhile(dark).count()
            assertTrue("one edge only", (n until width).none(dark))
            return n - 1
        }

        fun edges(f: ConvertedFrame, row: Int): Pair<Int, Int> {
            val (w, h) = f.width.toInt() to f.height.toInt()
            val green = w * h // plane 1 of [R, G, B]
            val dark = lastColumn(w) { x -> f.amplitude[green + row * w + x] < 0.5f }
            val far = lastColumn(w) { x -> f.depth[row * w + x] > 0.5f }
            return dark to far
        }
    }

    @Test
    fun cropForTextureIsTheTexturesBandOfTheCpuImage() {
        assertEquals(CropRect(0u, 60u, 640u, 360u), CameraPlanes.cropForTexture(CORNERS_16_9, 640, 480))
        assertEquals(listOf(0f, 0f, 0f, 1f, 1f, 0f, 1f, 1f), CameraPlanes.textureCorners().toList())
        // The corners in another order (texture axes swapped against the image's): the same bounding box.
        val swapped = floatArrayOf(640f, 420f, 0f, 420f, 640f, 60f, 0f, 60f)
        assertEquals(CropRect(0u, 60u, 640u, 360u), CameraPlanes.cropForTexture(swapped, 640, 480))
        // A 4:3 texture on a 16:9 CPU image crops columns: 1920 × 1080 → x 240..1680.
        val pillar = floatArrayOf(240.4f, 0f, 240.4f, 1080f, 1679.6f, 0f, 1679.6f, 1080f)
        assertEquals(CropRect(240u, 0u, 1440u, 1080u), CameraPlanes.cropForTexture(pillar, 1920, 1080))
        // Edges round to the nearest pixel boundary: 59.5 → 60, 59.49 → 59.
        val half = floatArrayOf(0f, 59.5f, 0f, 420.49f, 640f, 59.5f, 640f, 420.49f)
        assertEquals(CropRect(0u, 60u, 640u, 360u), CameraPlanes.cropForTexture(half, 640, 480))
    }

    @Test
    fun cropForTextureRejectsWhatCroppingCannotRegister() {
        fun rejected(why: String, corners: FloatArray, w: Int = 640, h: Int = 480) {
            val e = assertThrows(IllegalArgumentException::class.java) { CameraPlanes.cropForTexture(corners, w, h) }
            assertTrue("${e.message} should mention '$why'", e.message!!.contains(why))
        }
        // The texture sees more than the CPU image (y −8 .. 488): the depth would cover pixels with no colour.
        rejected("reaches outside", floatArrayOf(0f, -8f, 0f, 488f, 640f, -8f, 640f, 488f))
        rejected("reaches outside", floatArrayOf(0f, 60f, 0f, 420f, 641f, 60f, 641f, 420f))
        rejected("non-finite", floatArrayOf(0f, Float.NaN, 0f, 420f, 640f, 60f, 640f, 420f))
        rejected("expected 8", CORNERS_16_9.copyOf(6))
        rejected("is empty", floatArrayOf(5f, 60f, 5f, 420f, 5.2f, 60f, 5.2f, 420f))
        rejected("must be positive", CORNERS_16_9, w = 0)
        // A crop given by hand is checked before the frame is built, too.
        val e = assertThrows(IllegalArgumentException::class.java) {
            CameraPlanes.rgbdFrame(
                ByteArray(4 * 4 * 4), 4, 4, depthD16(2, 2, 4) { _, _ -> 1000 }, 2, 2, 4,
                DepthFormat.MILLIMETRES_U16, Rotation.DEG0, CropRect(2u, 0u, 3u, 4u),
            )
        }
        assertTrue(e.message!!, e.message!!.contains("not inside the 4x4"))
    }

    /** The acceptance case: after registration a vertical edge lies on the same pixel, ±1, in colour and depth. */
    @Test
    fun arcoreRegistrationPutsColourAndDepthEdgesOnTheSamePixel() {
        val crop = CameraPlanes.cropForTexture(CORNERS_16_9, 640, 480)
        val (frame, registered) = arcoreFrame(crop)
        assertEquals(crop, frame.colorCrop)
        assertEquals(360u to 640u, registered.width to registered.height)
        // By hand: cropped colour rows 133.. are dark → portrait columns 0..226 (column = 359 − row); depth
        // 90 → 360 rows by nearest (row o reads ⌊(o + ½)/4⌋ ≥ 33 from o = 132) → columns 0..227 far.
        for (row in listOf(0, 321, 639)) {
            val (dark, far) = edges(registered, row)
            assertEquals("row $row", 226 to 227, dark to far)
            assertTrue("row $row: colour edge $dark, depth edge $far", Math.abs(dark - far) <= 1)
        }
        // Without registration the depth is stretched over all 480 rows: 17 pixels apart (286 vs 303), the
        // defect of issue 22.
        val (_, stretched) = arcoreFrame(null)
        val (dark, far) = edges(stretched, 0)
        assertEquals(286 to 303, dark to far)
        // The depth range is the scene's either way.
        assertEquals(0.5, registered.zNearM!!, 1e-3)
        assertEquals(2.0, registered.zFarM!!, 1e-3)
    }

    @Test
    fun aCropOutsideTheColourIsAnInvalidInputFromTheLibrary() {
        val (frame, _) = arcoreFrame(CropRect(0u, 60u, 640u, 360u))
        // Bypassing the Kotlin check (a frame built by hand): the library refuses it with a typed error.
        val bad = frame.copy(colorCrop = CropRect(0u, 121u, 640u, 360u))
        val e = assertThrows(TensorholoException.InvalidInput::class.java) {
            convertFrame(bad, 360u, 640u, Fit.STRETCH)
        }
        assertTrue(e.reason, e.reason.contains("color_crop") && e.reason.contains("640x480"))
    }

    @Test
    fun depthFormatFollowsTheImageFormat() {
        assertEquals(DepthFormat.MILLIMETRES_U16, CameraPlanes.depthFormatOf(0x30)) // HardwareBuffer.D_16
        assertEquals(DepthFormat.DEPTH16, CameraPlanes.depthFormatOf(0x44363159)) // ImageFormat.DEPTH16
        for (other in listOf(0x23 /* YUV_420_888 */, 0x20203859 /* Y8 */, 0)) {
            val e = assertThrows(IllegalArgumentException::class.java) { CameraPlanes.depthFormatOf(other) }
            assertTrue(e.message!!, e.message!!.contains("expected HardwareBuffer.D_16"))
        }
    }

    /**
     * Why the format matters, in numbers: a D_16 image (ARCore 16-bit) of 1 m and 42.768 m (0xA710). Read as
     * its format says (millimetres) the far value is 42.768 m; read as DEPTH16 its top 3 bits (5) would be
     * confidence and the range 0x0710 = 1.808 m, a near value.
     */
    @Test
    fun d16DepthReadAsItsFormatKeepsFarValuesFar() {
        val (w, h) = 8 to 2
        val rgba = ByteArray(w * h * 4) { 100 }
        val depth = depthD16(w, h, 2 * w) { x, _ -> if (x < 4) 1000 else 0xA710 }
        fun range(format: DepthFormat): Pair<Double, Double> {
            val frame = CameraPlanes.rgbdFrame(rgba, w, h, depth, w, h, 2 * w, format, Rotation.DEG0)
            val f = convertFrame(frame, w.toUInt(), h.toUInt(), Fit.STRETCH)
            return f.zNearM!! to f.zFarM!!
        }
        val right = range(CameraPlanes.depthFormatOf(CameraPlanes.HARDWARE_BUFFER_D_16))
        assertEquals(1.0, right.first, 1e-3)
        assertEquals(42.768, right.second, 1e-3)
        val wrong = range(DepthFormat.DEPTH16)
        assertEquals(1.0, wrong.first, 1e-3)
        assertEquals(1.808, wrong.second, 1e-3)
    }

    /**
     * ARCore's raw depth confidence (0–255): the test scene's top rows hold a wrong, nearer depth (300 mm) rated
     * 0, the rest 255, packed from a padded plane ([CameraPlanes.bytes8Packed]) and passed by
     * [CameraPlanes.rgbdFrame]: the converted frame equals the one whose depth holds 0 (invalid) there, and
     * differs from the one that takes the wrong depth.
     */
    @Test
    fun lowConfidenceRawDepthIsNeverReadAsNear() {
        val (w, h, stride) = listOf(160, 90, 176)
        val confidencePlane = ByteBuffer.wrap(ByteArray(stride * (h - 1) + w) { i ->
            (if (i / stride <= 16) 0 else 255).toByte()
        })
        val confidence = CameraPlanes.bytes8Packed(confidencePlane, w, h, stride)
        assertEquals(w * h, confidence.size)
        val rgba = arcoreFrame(null).first.color
        val format = CameraPlanes.depthFormatOf(CameraPlanes.HARDWARE_BUFFER_D_16)
        val depthStride = 2 * w + 16
        fun frame(top: Int, rated: ByteArray?) = CameraPlanes.rgbdFrame(
            rgba, 640, 480,
            depthD16(w, h, depthStride) { _, row -> if (row <= 16) top else if (row <= 32) 500 else 2000 },
            w, h, depthStride, format, Rotation.DEG90, null, rated, 128,
        )
        fun converted(f: RgbdFrame) = convertFrame(f, 480u, 640u, Fit.STRETCH).depth
        val rated = frame(300, confidence)
        assertEquals(128.toUByte(), rated.minConfidence)
        assertEquals(converted(frame(0, null)), converted(rated))
        assertFalse("the wrong depth is read without the confidence", converted(frame(300, null)) == converted(rated))
        assertThrows(IllegalArgumentException::class.java) {
            CameraPlanes.bytes8Packed(confidencePlane, w, h, w - 1)
        }
    }
}
