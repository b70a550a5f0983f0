// JVM tests of CameraPlanes (YUV_420_888 → RGBA8, 16-bit depth planes → RgbdFrame, rotation), run by
// android/check.sh and Gradle. Only depth16FrameRendersLikeTheMillimetreFrame needs the native library
// (-Djna.library.path).

package tensorholo.android

import java.math.BigDecimal
import java.math.RoundingMode
import java.nio.ByteBuffer
import java.util.Random
import org.junit.AfterClass
import org.junit.Assert.assertArrayEquals
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertThrows
import org.junit.Assert.assertTrue
import org.junit.Test
import tensorholo.ColorFormat
import tensorholo.DepthFormat
import tensorholo.GeneratorConfig
import tensorholo.HologramGenerator
import tensorholo.Rotation

class CameraPlanesTest {
    /** The planes of one YUV_420_888 image as an `android.media.Image` exposes them. */
    class Yuv(
        val width: Int,
        val height: Int,
        val y: ByteBuffer,
        val yRowStride: Int,
        val u: ByteBuffer,
        val v: ByteBuffer,
        val uvRowStride: Int,
        val uvPixelStride: Int,
    ) {
        fun toRgba(out: ByteArray? = null) =
            CameraPlanes.yuv420ToRgba(width, height, y, yRowStride, u, v, uvRowStride, uvPixelStride, out)
    }

    companion object {
        private var generator: HologramGenerator? = null

        /** A small generator for the rendering comparison, made on first use. */
        fun generator(): HologramGenerator =
            generator ?: HologramGenerator(GeneratorConfig(width = 64u, height = 48u)).also { generator = it }

        @AfterClass
        @JvmStatic
        fun close() {
            generator?.close()
            generator = null
        }

        /**
         * A random YUV_420_888 image whose planes are laid out as Android does: rows `padding` bytes longer
         * than needed (random bytes in the padding), the last row of each plane unpadded, each buffer starting
         * at position `offset` of a larger array (bytes before it random too). `uvPixelStride` 2: the U and V
         * buffers are views of one interleaved block, V first (NV21) or U first (NV12) per `vFirst`.
         * `chroma(cx, cy)`, when given, sets the (Cb, Cr) codes of each chroma sample instead of random ones.
         */
        fun yuvImage(
            rnd: Random,
            width: Int,
            height: Int,
            uvPixelStride: Int,
            padding: Int,
            offset: Int,
            vFirst: Boolean = true,
            chroma: ((Int, Int) -> Pair<Int, Int>)? = null,
        ): Yuv {
            val cw = (width + 1) / 2
            val ch = (height + 1) / 2
            val yRowStride = width + padding
            val uvRowStride = (cw - 1) * uvPixelStride + 1 + padding + (if (uvPixelStride == 2) 1 else 0)
            fun randomBytes(n: Int) = ByteArray(n).also { rnd.nextBytes(it) }
            fun view(bytes: ByteArray, start: Int, size: Int): ByteBuffer =
                ByteBuffer.wrap(bytes).position(start).limit(start + size) as ByteBuffer

            val ySize = yRowStride * (height - 1) + width
            val y = view(randomBytes(offset + ySize + 7), offset, ySize)
            val cSize = uvRowStride * (ch - 1) + (cw - 1) * uvPixelStride + 1
            val u: ByteBuffer
            val v: ByteBuffer
            val uBytes: ByteArray
            val vBytes: ByteArray
            val uStart: Int
            val vStart: Int
            if (uvPixelStride == 1) {
                uBytes = randomBytes(offset + cSize + 3)
                vBytes = randomBytes(offset + cSize + 5)
                uStart = offset
                vStart = offset
                u = view(uBytes, uStart, cSize)
                v = view(vBytes, vStart, cSize)
            } else {
                // One block: V U V U … (NV21) or U V U V … (NV12); each buffer ends at its own last sample.
                val block = randomBytes(offset + cSize + 1)
                uBytes = block
                vBytes = block
                vStart = if (vFirst) offset else offset + 1
                uStart = if (vFirst) offset + 1 else offset
                u = view(block, uStart, cSize)
                v = view(block, vStart, cSize)
            }
            if (chroma != null) {
                for (cy in 0 until ch) for (cx in 0 until cw) {
                    val (cb, cr) = chroma(cx, cy)
                    uBytes[uStart + cy * uvRowStride + cx * uvPixelStride] = cb.toByte()
                    vBytes[vStart + cy * uvRowStride + cx * uvPixelStride] = cr.toByte()
                }
            }
            return Yuv(width, height, y, yRowStride, u, v, uvRowStride, uvPixelStride)
        }

        /**
         * The naive reference: each pixel read with absolute indices from the plane layout of the Android
         * docs, the BT.601 full-range formula in exact decimal arithmetic, rounded to nearest (ties up),
         * clamped.
         */
        fun referenceRgba(img: Yuv): ByteArray {
            val out = ByteArray(img.width * img.height * 4)
            for (py in 0 until img.height) for (px in 0 until img.width) {
                val l = img.y.get(img.y.position() + py * img.yRowStride + px).toInt() and 0xFF
                val c = (py / 2) * img.uvRowStride + (px / 2) * img.uvPixelStride
                val cb = (img.u.get(img.u.position() + c).toInt() and 0xFF) - 128
                val cr = (img.v.get(img.v.position() + c).toInt() and 0xFF) - 128
                fun channel(k1: String, c1: Int, k2: String, c2: Int): Byte {
                    val x = BigDecimal(l) + BigDecimal(k1) * BigDecimal(c1) + BigDecimal(k2) * BigDecimal(c2)
                    val r = (x + BigDecimal("0.5")).setScale(0, RoundingMode.FLOOR).toInt()
                    return r.coerceIn(0, 255).toByte()
                }
                val o = (py * img.width + px) * 4
                out[o] = channel("1.402", cr, "0", 0)
                out[o + 1] = channel("-0.344136", cb, "-0.714136", cr)
                out[o + 2] = channel("1.772", cb, "0", 0)
                out[o + 3] = 255.toByte()
            }
            return out
        }

        /** JFIF (BT.601 full range) forward transform of an RGB colour: (Y, Cb, Cr) rounded and clamped. */
        fun jfif(r: Int, g: Int, b: Int): Triple<Int, Int, Int> {
            fun q(x: Double) = Math.round(x).toInt().coerceIn(0, 255)
            return Triple(
                q(0.299 * r + 0.587 * g + 0.114 * b),
                q(128 - 0.168736 * r - 0.331264 * g + 0.5 * b),
                q(128 + 0.5 * r - 0.418688 * g - 0.081312 * b),
            )
        }

        fun pixel(rgba: ByteArray, width: Int, x: Int, y: Int): List<Int> =
            (0 until 4).map { rgba[(y * width + x) * 4 + it].toInt() and 0xFF }
    }

    @Test
    fun yuvMatchesTheNaiveReferenceOnRandomPlanes() {
        val rnd = Random(601)
        var images = 0
        for ((w, h) in listOf(1 to 1, 2 to 2, 3 to 5, 37 to 23, 64 to 48)) {
            for (ps in listOf(1, 2)) for (padding in listOf(0, 13)) for (vFirst in listOf(true, false)) {
                if (ps == 1 && !vFirst) continue
                val img = yuvImage(rnd, w, h, ps, padding, offset = 5, vFirst = vFirst)
                assertArrayEquals("${w}x$h pixel stride $ps padding $padding vFirst $vFirst", referenceRgba(img), img.toRgba())
                images++
            }
        }
        assertEquals(30, images)
    }

    /** Every (Cb, Cr) pair of 8-bit codes once (a 512 × 512 image), random luma: exact against the formula. */
    @Test
    fun yuvIsExactForEveryChromaPair() {
        val img = yuvImage(Random(420), 512, 512, uvPixelStride = 2, padding = 0, offset = 0) { cx, cy -> cx to cy }
        val want = referenceRgba(img)
        val reused = ByteArray(512 * 512 * 4)
        val got = img.toRgba(reused)
        assertTrue("the out array is filled and returned", got === reused)
        assertArrayEquals(want, got)
    }

    /**
     * Greys (Cb = Cr = 128) come back unchanged, which a limited-range (16..235) conversion would not do; the
     * JFIF codes of red, green, blue, white and black come back within ±2 (8-bit quantisation of Y, Cb, Cr);
     * a 2×2 pixel block shares one chroma sample.
     */
    @Test
    fun yuvReproducesKnownColours() {
        for (g in listOf(0, 1, 16, 100, 128, 235, 255)) {
            val img = yuvImage(Random(1), 2, 2, 1, 0, 0) { _, _ -> 128 to 128 }
            (0 until 4).forEach { img.y.put(img.y.position() + it, g.toByte()) }
            assertEquals(List(4) { listOf(g, g, g, 255) }, (0 until 4).map { pixel(img.toRgba(), 2, it % 2, it / 2) })
        }
        val colours = listOf(
            listOf(255, 0, 0),
            listOf(0, 255, 0),
            listOf(0, 0, 255),
            listOf(255, 255, 255),
            listOf(0, 0, 0),
            listOf(200, 120, 40),
        )
        for (ps in listOf(1, 2)) for (c in colours) for (other in colours) {
            // 4 × 2 pixels: the left 2 × 2 block in colour c, the right one in `other`.
            val left = jfif(c[0], c[1], c[2])
            val right = jfif(other[0], other[1], other[2])
            val img = yuvImage(Random(2), 4, 2, ps, 3, 1) { cx, _ ->
                if (cx == 0) left.second to left.third else right.second to right.third
            }
            for (py in 0 until 2) for (px in 0 until 4) {
                img.y.put(img.y.position() + py * img.yRowStride + px, (if (px < 2) left.first else right.first).toByte())
            }
            val rgba = img.toRgba()
            for (py in 0 until 2) for (px in 0 until 4) {
                val want = if (px < 2) c else other
                val got = pixel(rgba, 4, px, py)
                for (k in 0 until 3) {
                    assertTrue("$want at ($px, $py), pixel stride $ps: got $got", Math.abs(got[k] - want[k]) <= 2)
                }
                assertEquals(255, got[3])
            }
        }
    }

    /** Buffers of exactly the size the layout needs convert; one byte less throws before anything is read. */
    @Test
    fun shortOrInconsistentYuvThrowsIllegalArgument() {
        for (ps in listOf(1, 2)) {
            val img = yuvImage(Random(3), 9, 7, ps, 4, 2)
            img.toRgba() // the minimal sizes are enough
            fun shorter(b: ByteBuffer) = b.duplicate().limit(b.limit() - 1) as ByteBuffer
            fun assertRejected(what: String, call: () -> Unit) {
                val e = assertThrows(IllegalArgumentException::class.java) { call() }
                assertTrue("message names $what: ${e.message}", e.message!!.contains(what))
            }
            with(img) {
                assertRejected("Y buffer too short") {
                    CameraPlanes.yuv420ToRgba(width, height, shorter(y), yRowStride, u, v, uvRowStride, uvPixelStride)
                }
                assertRejected("U buffer too short") {
                    CameraPlanes.yuv420ToRgba(width, height, y, yRowStride, shorter(u), v, uvRowStride, uvPixelStride)
                }
                assertRejected("V buffer too short") {
                    CameraPlanes.yuv420ToRgba(width, height, y, yRowStride, u, shorter(v), uvRowStride, uvPixelStride)
                }
                assertRejected("Y row stride") {
                    CameraPlanes.yuv420ToRgba(width, height, y, width - 1, u, v, uvRowStride, uvPixelStride)
                }
                assertRejected("U/V row stride") {
                    CameraPlanes.yuv420ToRgba(width, height, y, yRowStride, u, v, 4 * uvPixelStride, uvPixelStride)
                }
                assertRejected("pixel stride") {
                    CameraPlanes.yuv420ToRgba(width, height, y, yRowStride, u, v, uvRowStride, 3)
                }
                assertRejected("size must be positive") {
                    CameraPlanes.yuv420ToRgba(0, height, y, yRowStride, u, v, uvRowStride, uvPixelStride)
                }
                assertRejected("out has") { toRgba(ByteArray(width * height * 4 - 1)) }
                // A height one row taller needs more than the buffers hold.
                assertRejected("buffer too short") {
                    CameraPlanes.yuv420ToRgba(width, height + 2, y, yRowStride, u, v, uvRowStride, uvPixelStride)
                }
            }
            // Nothing moved the callers' buffers.
            assertEquals(2, img.y.position())
        }
    }

    @Test
    fun depthRowsArePackedFromThePlaneLayout() {
        val rnd = Random(16)
        val (w, h, stride, offset) = listOf(5, 3, 14, 6)
        val bytes = ByteArray(offset + stride * (h - 1) + 2 * w).also { rnd.nextBytes(it) }
        val plane = ByteBuffer.wrap(bytes).position(offset) as ByteBuffer
        val want = ByteArray(2 * w * h) { i -> bytes[offset + (i / (2 * w)) * stride + i % (2 * w)] }
        assertArrayEquals(want, CameraPlanes.depth16Packed(plane, w, h, stride, DepthFormat.MILLIMETRES_U16))
        assertEquals(offset, plane.position())
        // Packed rows (stride = 2·width) take the bulk path.
        val packed = ByteBuffer.wrap(want)
        assertArrayEquals(want, CameraPlanes.depth16Packed(packed, w, h, 2 * w, DepthFormat.DEPTH16))

        val rgba = ByteArray(8 * 6 * 4)
        val frame = CameraPlanes.rgbdFrame(rgba, 8, 6, plane, w, h, stride, DepthFormat.DEPTH16, Rotation.DEG270)
        assertTrue(frame.color === rgba)
        assertEquals(ColorFormat.RGBA8, frame.colorFormat)
        assertEquals(listOf(8u, 6u, 5u, 3u, 0u, 0u), listOf(frame.colorWidth, frame.colorHeight, frame.depthWidth, frame.depthHeight, frame.colorRowStride, frame.depthRowStride))
        assertEquals(DepthFormat.DEPTH16, frame.depthFormat)
        assertEquals(Rotation.DEG270, frame.rotation)
        assertArrayEquals(want, frame.depth)

        val tooShort = ByteBuffer.wrap(bytes, 0, bytes.size - 1).position(offset) as ByteBuffer
        for (call in listOf<() -> Any>(
            { CameraPlanes.depth16Packed(tooShort, w, h, stride, DepthFormat.MILLIMETRES_U16) },
            { CameraPlanes.depth16Packed(plane, w, h, 2 * w - 1, DepthFormat.MILLIMETRES_U16) },
            { CameraPlanes.depth16Packed(plane, w, h, stride, DepthFormat.METRES_F32) },
            { CameraPlanes.depth16Packed(plane, w, 0, stride, DepthFormat.DEPTH16) },
            { CameraPlanes.rgbdFrame(ByteArray(8 * 6 * 4 - 1), 8, 6, plane, w, h, stride, DepthFormat.DEPTH16, Rotation.DEG0) },
        )) {
            assertThrows(IllegalArgumentException::class.java) { call() }
        }
    }

    /**
     * The same scene as Camera2 DEPTH16 (millimetres + random confidence codes; invalid pixels as range 0 or
     * confidence code 1 = 0 %) and as ARCore millimetres (invalid = 0), built through CameraPlanes from padded
     * planes and rendered: identical SLM codes. Control: the DEPTH16 bytes read as plain millimetres give
     * other codes, so the comparison can tell the formats apart.
     */
    @Test
    fun depth16FrameRendersLikeTheMillimetreFrame() {
        val rnd = Random(13)
        val (cw, ch, dw, dh) = listOf(96, 72, 48, 36)
        val rgba = ByteArray(cw * ch * 4) { i ->
            val p = i / 4
            val (x, y) = p % cw to p / cw
            when (i % 4) {
                0 -> (x * 255 / cw).toByte()
                1 -> (y * 255 / ch).toByte()
                2 -> (((x / 8 + y / 8) % 2) * 200).toByte()
                else -> -1
            }
        }
        val stride = dw * 2 + 10
        val mm = ByteBuffer.allocate(stride * dh)
        val d16 = ByteBuffer.allocate(stride * dh)
        rnd.nextBytes(mm.array())
        rnd.nextBytes(d16.array())
        var invalid = 0
        for (y in 0 until dh) for (x in 0 until dw) {
            val range = 400 + 40 * x + 20 * y + (if ((x / 6 + y / 6) % 2 == 0) 600 else 0) // ≤ 3720 mm < 8192
            val hole = rnd.nextInt(10) == 0
            val confidence = if (hole) 1 else intArrayOf(0, 2, 3, 4, 5, 6, 7)[rnd.nextInt(7)]
            val sample16 = if (hole && rnd.nextBoolean()) (rnd.nextInt(8) shl 13) else (confidence shl 13) or range
            val sampleMm = if (hole) 0 else range
            if (hole) invalid++
            for ((buf, s) in listOf(mm to sampleMm, d16 to sample16)) {
                buf.put(y * stride + 2 * x, (s and 0xFF).toByte())
                buf.put(y * stride + 2 * x + 1, (s ushr 8).toByte())
            }
        }
        assertTrue("some invalid pixels", invalid > 50)
        fun render(buf: ByteBuffer, format: DepthFormat) = generator().render(
            CameraPlanes.rgbdFrame(rgba, cw, ch, buf, dw, dh, stride, format, Rotation.DEG90),
        )
        val a = render(mm, DepthFormat.MILLIMETRES_U16)
        val b = render(d16, DepthFormat.DEPTH16)
        assertArrayEquals(a.red, b.red)
        assertArrayEquals(a.green, b.green)
        assertArrayEquals(a.blue, b.blue)
        assertEquals(a.zNearM to a.zFarM, b.zNearM to b.zFarM)
        val wrong = render(d16, DepthFormat.MILLIMETRES_U16)
        assertFalse("confidence bits read as millimetres change the hologram", wrong.green.contentEquals(a.green))
    }

    @Test
    fun rotationFollowsSensorAndDisplay() {
        // Back camera: the usual sensor mounted at 90° needs a quarter turn clockwise on an upright phone.
        assertEquals(Rotation.DEG90, CameraPlanes.rotationFor(90, 0, frontFacing = false))
        assertEquals(Rotation.DEG0, CameraPlanes.rotationFor(90, 90, frontFacing = false))
        assertEquals(Rotation.DEG270, CameraPlanes.rotationFor(90, 180, frontFacing = false))
        assertEquals(Rotation.DEG180, CameraPlanes.rotationFor(90, 270, frontFacing = false))
        assertEquals(Rotation.DEG180, CameraPlanes.rotationFor(270, 90, frontFacing = false))
        // Front camera (mounted at 270°): the display rotation adds.
        assertEquals(Rotation.DEG270, CameraPlanes.rotationFor(270, 0, frontFacing = true))
        assertEquals(Rotation.DEG0, CameraPlanes.rotationFor(270, 90, frontFacing = true))
        assertThrows(IllegalArgumentException::class.java) { CameraPlanes.rotationFor(45, 0, frontFacing = false) }
    }
}
