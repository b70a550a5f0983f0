// Camera buffers → the bindings' RgbdFrame, in plain Kotlin/JVM (java.nio only, no android.jar), so that the
// same code runs in the app and in the JVM tests on Linux CI (android/check.sh).

package tensorholo.android

import java.nio.ByteBuffer
import tensorholo.ColorFormat
import tensorholo.CropRect
import tensorholo.DepthFormat
import tensorholo.RgbdFrame
import tensorholo.Rotation

/**
 * Conversions from Android camera buffers (`android.media.Image` planes, as Camera2 and ARCore hand them to
 * the CPU) to the bindings' [RgbdFrame], written against `java.nio` only so they need no Android runtime.
 * [RgbdFrames.fromImages] (`ImageFrames.kt`) reads the planes of an `Image` and calls these.
 *
 * Every function validates its sizes first and throws [IllegalArgumentException], with a message naming the
 * buffer and giving the expected and actual byte counts, before anything is read: a buffer is never read
 * past its limit and a short buffer never yields a silently wrong frame. Sizes are checked with `Long`
 * arithmetic, so no size product overflows. Buffers are read from their current `position()` without
 * changing it (reads go through `duplicate()`), whatever their `order()` (bytes are taken as they lie in
 * memory).
 */
object CameraPlanes {
    /**
     * Converts a `YUV_420_888` image (Camera2 `ImageFormat.YUV_420_888`, ARCore `Frame.acquireCameraImage()`)
     * to packed RGBA8: `width · height · 4` bytes, row-major, R, G, B, A per pixel (alpha 255) — the layout of
     * [ColorFormat.RGBA8] and of Android's `Bitmap.Config.ARGB_8888` memory.
     *
     * Layout (the `Image.Plane`s, as `android.media.Image` documents YUV_420_888): luma `y` has `width ×
     * height` samples, one byte each, rows `yRowStride` bytes apart (pixel stride 1); chroma `u` (Cb) and
     * `v` (Cr) have `ceil(width/2) × ceil(height/2)` samples (4:2:0: one chroma sample per 2×2 pixels),
     * rows `uvRowStride` bytes apart, samples `uvPixelStride` bytes apart: 1 for planar (I420/YV12)
     * layouts, 2 for semi-planar (NV12/NV21, where the `u` and `v` buffers interleave in one memory block).
     * The last row of each plane may lack its padding, as Android's buffers do.
     *
     * Colour: BT.601 full range (JFIF: Y, Cb, Cr in 0..255, no 16..235 foot-room), the encoding of camera
     * YUV_420_888 CPU images:
     * `R = Y + 1.402 (Cr − 128)`, `G = Y − 0.344136 (Cb − 128) − 0.714136 (Cr − 128)`,
     * `B = Y + 1.772 (Cb − 128)`, each rounded to the nearest integer (ties upward) and clamped to 0..255,
     * exactly (tabulated in integer arithmetic). The values are the camera's 8-bit sRGB-encoded codes, which is what
     * the SDK expects for [ColorFormat.RGBA8].
     *
     * @param width image width in pixels (`Image.getWidth()`), ≥ 1.
     * @param height image height in pixels, ≥ 1.
     * @param y plane 0 buffer; needs `yRowStride · (height − 1) + width` bytes from its position.
     * @param yRowStride plane 0 `rowStride` in bytes, ≥ `width`.
     * @param u plane 1 (Cb) buffer; needs `uvRowStride · (ch − 1) + uvPixelStride · (cw − 1) + 1` bytes, with
     *   `cw = ceil(width/2)`, `ch = ceil(height/2)`.
     * @param v plane 2 (Cr) buffer; same size rule as `u`.
     * @param uvRowStride `rowStride` of planes 1 and 2 in bytes (Android gives both the same).
     * @param uvPixelStride `pixelStride` of planes 1 and 2: 1 or 2.
     * @param out optional destination of exactly `width · height · 4` bytes, reused across frames to spare
     *   an allocation; a new array when null.
     * @return the RGBA8 bytes (`out` when given).
     * @throws IllegalArgumentException on a size ≤ 0, a stride too small for one row, a pixel stride other
     *   than 1 or 2, a buffer shorter than its layout needs, or an `out` of the wrong size.
     */
    @JvmStatic
    @JvmOverloads
    fun yuv420ToRgba(
        width: Int,
        height: Int,
        y: ByteBuffer,
        yRowStride: Int,
        u: ByteBuffer,
        v: ByteBuffer,
        uvRowStride: Int,
        uvPixelStride: Int,
        out: ByteArray? = null,
    ): ByteArray {
        require(width > 0 && height > 0) { "YUV image size must be positive, got ${width}x$height" }
        require(uvPixelStride == 1 || uvPixelStride == 2) {
            "chroma pixel stride must be 1 (planar) or 2 (semi-planar), got $uvPixelStride"
        }
        val cw = (width + 1) / 2
        val ch = (height + 1) / 2
        require(yRowStride >= width) { "Y row stride $yRowStride is shorter than the width $width" }
        val uvRow = (cw - 1).toLong() * uvPixelStride + 1
        require(uvRowStride >= uvRow) {
            "U/V row stride $uvRowStride is shorter than one chroma row ($cw samples, pixel stride " +
                "$uvPixelStride = $uvRow bytes)"
        }
        val ySize = checkPlane("Y", y, yRowStride, height, width.toLong())
        val uSize = checkPlane("U", u, uvRowStride, ch, uvRow)
        val vSize = checkPlane("V", v, uvRowStride, ch, uvRow)
        val pixels = width.toLong() * height * 4
        require(pixels <= Int.MAX_VALUE - 8) { "RGBA output of ${width}x$height pixels exceeds a ByteArray" }
        val rgba = out ?: ByteArray(pixels.toInt())
        require(rgba.size.toLong() == pixels) { "out has ${rgba.size} bytes, ${width}x$height RGBA needs $pixels" }

        // One bulk copy per plane (a memcpy for the direct buffers of an Image), then array indexing.
        val yb = copyOf(y, ySize)
        val ub = copyOf(u, uSize)
        val vb = copyOf(v, vSize)
        var o = 0
        for (row in 0 until height) {
            val yBase = row * yRowStride
            val cBase = (row shr 1) * uvRowStride
            for (col in 0 until width) {
                val l = yb[yBase + col].toInt() and 0xFF
                val c = cBase + (col shr 1) * uvPixelStride
                val cb = ub[c].toInt() and 0xFF
                val cr = vb[c].toInt() and 0xFF
                rgba[o] = clamp(l + R_OF_CR[cr])
                rgba[o + 1] = clamp(l + G_OF_CB_CR[(cb shl 8) or cr])
                rgba[o + 2] = clamp(l + B_OF_CB[cb])
                rgba[o + 3] = -1 // 255
                o += 4
            }
        }
        return rgba
    }

    /**
     * Builds an [RgbdFrame] from a packed RGBA8 colour image and a 16-bit depth buffer (an `Image` plane 0:
     * ARCore `Frame.acquireDepthImage16Bits()`, Camera2 `ImageFormat.DEPTH16`). The depth rows are copied
     * packed (row padding dropped), so the frame owns its bytes and the `Image` may be closed at once.
     *
     * Depth samples are 16-bit little-endian (Android's byte order), taken as they lie in memory:
     * [DepthFormat.MILLIMETRES_U16] = millimetres, 0 invalid (ARCore); [DepthFormat.DEPTH16] = low 13 bits
     * millimetres, high 3 bits confidence (code 1 = 0 % confidence = invalid), Camera2 depth cameras. The
     * SDK decodes them and never reads an invalid pixel as near. The depth covers the field of view of the
     * colour, or of `colorCrop` when given; it may have a lower resolution. ARCore's depth covers its GPU
     * texture's field of view, a band of the CPU image: pass [cropForTexture]'s rectangle (as
     * `RgbdFrames.fromArFrame` does).
     *
     *
     * @param rgba `width · height · 4` bytes, R, G, B, A, row-major (e.g. from [yuv420ToRgba]); not copied:
     *   the frame holds this array (the bindings copy it when the frame is rendered or pushed).
     * @param width colour width in pixels, ≥ 1.
     * @param height colour height in pixels, ≥ 1.
     * @param depth depth buffer; needs `depthRowStride · (depthHeight − 1) + 2 · depthWidth` bytes from its
     *   position.
     * @param depthWidth depth width in samples, ≥ 1.
     * @param depthHeight depth height in rows, ≥ 1.
     * @param depthRowStride bytes from one depth row to the next (`Image.Plane.getRowStride()`), ≥
     *   `2 · depthWidth`.
     * @param depthFormat [DepthFormat.MILLIMETRES_U16] or [DepthFormat.DEPTH16] (the 16-bit formats).
     * @param rotation clockwise rotation making both buffers upright (see [rotationFor]).
     * @param colorCrop the rectangle of the colour image (pixels, before the rotation) that the depth
     *   covers, or null for the whole image; the library crops the colour to it before rotating.
     * @return the frame: colour [ColorFormat.RGBA8] packed, depth packed, `colorCrop` as given.
     * @throws IllegalArgumentException on a size ≤ 0, `rgba` of the wrong size, a non-16-bit `depthFormat`,
     *   a stride shorter than one row, a depth buffer shorter than its layout needs, or a `colorCrop` that
     *   is empty or not inside the colour image.
     */
    @JvmStatic
    @JvmOverloads
    fun rgbdFrame(
        rgba: ByteArray,
        width: Int,
        height: Int,
        depth: ByteBuffer,
        depthWidth: Int,
        depthHeight: Int,
        depthRowStride: Int,
        depthFormat: DepthFormat,
        rotation: Rotation,
        colorCrop: CropRect? = null,
        confidence: ByteArray? = null,
        minConfidence: Int = 1,
    ): RgbdFrame {
        require(width > 0 && height > 0) { "colour size must be positive, got ${width}x$height" }
        require(minConfidence in 0..255) { "minConfidence is 0 to 255, got $minConfidence" }
        require(rgba.size.toLong() == width.toLong() * height * 4) {
            "rgba has ${rgba.size} bytes, a packed ${width}x$height RGBA8 image has ${width.toLong() * height * 4}"
        }
        if (colorCrop != null) checkCrop(colorCrop, width, height)
        val packed = depth16Packed(depth, depthWidth, depthHeight, depthRowStride, depthFormat)
        return RgbdFrame(
            color = rgba,
            colorFormat = ColorFormat.RGBA8,
            colorWidth = width.toUInt(),
            colorHeight = height.toUInt(),
            depth = packed,
            depthFormat = depthFormat,
            depthWidth = depthWidth.toUInt(),
            depthHeight = depthHeight.toUInt(),
            rotation = rotation,
            colorCrop = colorCrop,
            confidence = confidence,
            minConfidence = minConfidence.toUByte(),
        )
    }

    /**
     * The bytes of an 8-bit one-plane image (ARCore's raw depth confidence, `acquireRawDepthConfidenceImage`:
     * 0–255, 255 = most confident) without its row padding: `width × height` bytes, row by row.
     *
     * @throws IllegalArgumentException for a non-positive size, a row stride shorter than a row, or a buffer
     *   too short for its rows.
     */
    @JvmStatic
    fun bytes8Packed(buffer: ByteBuffer, width: Int, height: Int, rowStride: Int): ByteArray {
        require(width > 0 && height > 0) { "confidence size must be positive, got ${width}x$height" }
        require(rowStride >= width) { "confidence row stride $rowStride is shorter than one row ($width bytes)" }
        checkPlane("confidence", buffer, rowStride, height, width.toLong())
        val out = ByteArray(width * height)
        val src = buffer.duplicate()
        val base = buffer.position()
        for (r in 0 until height) {
            src.position(base + r * rowStride)
            src.get(out, r * width, width)
        }
        return out
    }

    /** `android.graphics.ImageFormat.DEPTH16`: Camera2 depth, and ARCore's deprecated `acquireDepthImage()`. */
    const val IMAGE_FORMAT_DEPTH16 = 0x44363159

    /** `android.hardware.HardwareBuffer.D_16` (API 28): ARCore's `acquireDepthImage16Bits()` since 1.31. */
    const val HARDWARE_BUFFER_D_16 = 0x30

    /**
     * How to read a 16-bit depth `Image`'s samples, from its `Image.getFormat()`:
     * - `HardwareBuffer.D_16` ([HARDWARE_BUFFER_D_16]) → [DepthFormat.MILLIMETRES_U16]: all 16 bits are
     *   millimetres (ARCore `acquireDepthImage16Bits()` / `acquireRawDepthImage16Bits()`, up to 65.535 m);
     * - `ImageFormat.DEPTH16` ([IMAGE_FORMAT_DEPTH16]) → [DepthFormat.DEPTH16]: 13 bits of millimetres and 3
     *   bits of confidence (Camera2 depth cameras; ARCore's deprecated `acquireDepthImage()` clears the top 3
     *   bits, i.e. full confidence, and caps the range at 8.191 m, so it reads correctly too).
     *
     * Reading a D_16 image as DEPTH16 would wrap every depth past 8.191 m to a near value, and a DEPTH16
     * image as millimetres would read its confidence bits as metres: the format decides, never the caller.
     *
     * @throws IllegalArgumentException for any other format, naming it.
     */
    @JvmStatic
    fun depthFormatOf(imageFormat: Int): DepthFormat = when (imageFormat) {
        HARDWARE_BUFFER_D_16 -> DepthFormat.MILLIMETRES_U16
        IMAGE_FORMAT_DEPTH16 -> DepthFormat.DEPTH16
        else -> throw IllegalArgumentException(
            "depth image format is $imageFormat (0x${Integer.toHexString(imageFormat)}), expected " +
                "HardwareBuffer.D_16 ($HARDWARE_BUFFER_D_16) or ImageFormat.DEPTH16 ($IMAGE_FORMAT_DEPTH16)",
        )
    }

    /**
     * The four corners of the GPU camera texture in ARCore's `Coordinates2d.TEXTURE_NORMALIZED`, as
     * `(x, y)` pairs: (0, 0), (0, 1), (1, 0), (1, 1). Transform them with `Frame.transformCoordinates2d(
     * TEXTURE_NORMALIZED, textureCorners(), IMAGE_PIXELS, out)` and pass `out` to [cropForTexture]. A new
     * array on each call (ARCore only reads it).
     */
    @JvmStatic
    fun textureCorners(): FloatArray = floatArrayOf(0f, 0f, 0f, 1f, 1f, 0f, 1f, 1f)

    /**
     * The rectangle of an ARCore CPU image (`acquireCameraImage()`, e.g. 640 × 480) that the GPU camera
     * texture sees, which is the field of view of ARCore's depth image (`acquireDepthImage16Bits()` covers
     * the texture's field of view, usually 16:9, not the 4:3 CPU image's): the bounding box of the texture's
     * corners in CPU image pixels, its edges rounded to the nearest pixel boundary. Pass it as the frame's
     * `colorCrop` so that colour and depth are registered (Google's raw-depth sample crops the same way).
     *
     * Example: a 16:9 texture on a 640 × 480 image maps its corners to y = 60 and y = 420 → `CropRect(x = 0,
     * y = 60, width = 640, height = 360)`.
     *
     * @param imageCorners the 8 floats `Frame.transformCoordinates2d(TEXTURE_NORMALIZED, textureCorners(),
     *   IMAGE_PIXELS, imageCorners)` wrote: `(x, y)` in CPU image pixels for each corner of [textureCorners],
     *   pixel edges (0 = the image's left/top edge, `imageWidth` its right edge).
     * @param imageWidth CPU image width in pixels (`Image.getWidth()`), ≥ 1.
     * @param imageHeight CPU image height in pixels, ≥ 1.
     * @throws IllegalArgumentException when `imageCorners` does not hold 8 finite values, the sizes are not
     *   positive, the rectangle is empty, or it reaches more than half a pixel outside the image (the depth
     *   would then see more than the colour: cropping the colour cannot register them).
     */
    @JvmStatic
    fun cropForTexture(imageCorners: FloatArray, imageWidth: Int, imageHeight: Int): CropRect {
        require(imageWidth > 0 && imageHeight > 0) { "image size must be positive, got ${imageWidth}x$imageHeight" }
        require(imageCorners.size == 8) { "imageCorners holds ${imageCorners.size} floats, expected 8 (4 corners x, y)" }
        require(imageCorners.all { it.isFinite() }) {
            "imageCorners holds a non-finite value: ${imageCorners.joinToString()}"
        }
        val xs = (0 until 4).map { imageCorners[2 * it].toDouble() }
        val ys = (0 until 4).map { imageCorners[2 * it + 1].toDouble() }
        fun edge(v: Double) = Math.floor(v + 0.5).toLong()
        val x0 = edge(xs.min())
        val x1 = edge(xs.max())
        val y0 = edge(ys.min())
        val y1 = edge(ys.max())
        require(x0 >= 0 && y0 >= 0 && x1 <= imageWidth && y1 <= imageHeight) {
            "the texture's field of view (x ${xs.min()}..${xs.max()}, y ${ys.min()}..${ys.max()} CPU image pixels) " +
                "reaches outside the ${imageWidth}x$imageHeight CPU image: the depth sees more than the colour"
        }
        require(x1 > x0 && y1 > y0) {
            "the texture's field of view (x ${xs.min()}..${xs.max()}, y ${ys.min()}..${ys.max()}) is empty in pixels"
        }
        return CropRect(x = x0.toUInt(), y = y0.toUInt(), width = (x1 - x0).toUInt(), height = (y1 - y0).toUInt())
    }

    /** Checks that `crop` is non-empty and inside a `width × height` image (as the library does). */
    private fun checkCrop(crop: CropRect, width: Int, height: Int) {
        require(
            crop.width > 0u && crop.height > 0u &&
                crop.x.toLong() + crop.width.toLong() <= width && crop.y.toLong() + crop.height.toLong() <= height,
        ) {
            "colour crop x ${crop.x}, y ${crop.y}, width ${crop.width}, height ${crop.height} is empty or not " +
                "inside the ${width}x$height colour image"
        }
    }

    /**
     * Copies a 16-bit depth plane into packed bytes: `depthWidth · depthHeight · 2` bytes, row-major, each
     * sample's two bytes as they lie in memory (little-endian on Android), row padding dropped.
     *
     * @param depth buffer read from its position (not moved); needs `rowStride · (depthHeight − 1) +
     *   2 · depthWidth` bytes.
     * @param depthWidth samples per row, ≥ 1.
     * @param depthHeight rows, ≥ 1.
     * @param rowStride bytes from one row to the next, ≥ `2 · depthWidth`.
     * @param depthFormat must be [DepthFormat.MILLIMETRES_U16] or [DepthFormat.DEPTH16].
     * @throws IllegalArgumentException as [rgbdFrame] does for the depth buffer.
     */
    @JvmStatic
    fun depth16Packed(
        depth: ByteBuffer,
        depthWidth: Int,
        depthHeight: Int,
        rowStride: Int,
        depthFormat: DepthFormat,
    ): ByteArray {
        require(depthFormat == DepthFormat.MILLIMETRES_U16 || depthFormat == DepthFormat.DEPTH16) {
            "a 16-bit depth image is MILLIMETRES_U16 or DEPTH16, not $depthFormat"
        }
        require(depthWidth > 0 && depthHeight > 0) { "depth size must be positive, got ${depthWidth}x$depthHeight" }
        val row = depthWidth.toLong() * 2
        require(rowStride >= row) { "depth row stride $rowStride is shorter than one row ($depthWidth x 2 = $row bytes)" }
        checkPlane("depth", depth, rowStride, depthHeight, row)
        val total = row * depthHeight
        require(total <= Int.MAX_VALUE - 8) { "depth of ${depthWidth}x$depthHeight exceeds a ByteArray" }
        val out = ByteArray(total.toInt())
        val src = depth.duplicate()
        val base = depth.position()
        val rowBytes = row.toInt()
        if (rowStride.toLong() == row) {
            src.get(out)
        } else {
            for (r in 0 until depthHeight) {
                src.position(base + r * rowStride)
                src.get(out, r * rowBytes, rowBytes)
            }
        }
        return out
    }

    /**
     * The clockwise [Rotation] that makes a camera image upright on the screen, from the sensor's mounting
     * (`CameraCharacteristics.SENSOR_ORIENTATION`: 0, 90, 180 or 270 degrees clockwise) and the display's
     * rotation (`Display.getRotation()` as degrees: `Surface.ROTATION_90` = 90 …): back camera
     * `(sensor − display) mod 360`, front camera `(sensor + display) mod 360`, as Android's camera
     * orientation guide computes it. A front camera's image stays mirrored (as a selfie preview shows it).
     *
     * Example: a phone held upright (display 0) with the usual back sensor mounted at 90° → [Rotation.DEG90].
     *
     * @throws IllegalArgumentException when either angle is not a multiple of 90 degrees.
     */
    @JvmStatic
    fun rotationFor(sensorOrientationDegrees: Int, displayRotationDegrees: Int, frontFacing: Boolean): Rotation {
        require(sensorOrientationDegrees % 90 == 0 && displayRotationDegrees % 90 == 0) {
            "angles must be multiples of 90 degrees, got sensor $sensorOrientationDegrees, display $displayRotationDegrees"
        }
        val degrees = if (frontFacing) {
            sensorOrientationDegrees + displayRotationDegrees
        } else {
            sensorOrientationDegrees - displayRotationDegrees
        }
        return when (Math.floorMod(degrees, 360)) {
            0 -> Rotation.DEG0
            90 -> Rotation.DEG90
            180 -> Rotation.DEG180
            else -> Rotation.DEG270
        }
    }

    // BT.601 full-range offsets from Y, tabulated for every 8-bit chroma code (256 + 256 + 65536 Ints, about
    // 260 KiB): computed in exact integer arithmetic from the coefficients in millionths, rounded to the
    // nearest integer with ties upward (floor(x + 1/2)), so the conversion is the formula above exactly.
    private fun offset(micro: Long): Int = Math.floorDiv(micro + 500_000L, 1_000_000L).toInt()
    private val R_OF_CR = IntArray(256) { cr -> offset(1_402_000L * (cr - 128)) }
    private val B_OF_CB = IntArray(256) { cb -> offset(1_772_000L * (cb - 128)) }
    private val G_OF_CB_CR = IntArray(65536) { i ->
        offset(-344_136L * ((i shr 8) - 128) - 714_136L * ((i and 0xFF) - 128))
    }

    private fun clamp(x: Int): Byte = (if (x < 0) 0 else if (x > 255) 255 else x).toByte()

    /**
     * Checks that `buffer` holds `rows` rows of `rowBytes` bytes `rowStride` apart (the last row without
     * padding) from its position; returns the bytes needed.
     */
    private fun checkPlane(name: String, buffer: ByteBuffer, rowStride: Int, rows: Int, rowBytes: Long): Int {
        val needed = rowStride.toLong() * (rows - 1) + rowBytes
        require(needed <= buffer.remaining()) {
            "$name buffer too short: $rows rows of stride $rowStride bytes need $needed bytes, it has " +
                "${buffer.remaining()}"
        }
        return needed.toInt()
    }

    private fun copyOf(buffer: ByteBuffer, size: Int): ByteArray {
        val bytes = ByteArray(size)
        buffer.duplicate().get(bytes)
        return bytes
    }
}
