// SLM patterns and previews → android.graphics.Bitmap (needs android.jar).
@file:JvmName("SlmBitmaps")

package tensorholo.android

import android.graphics.Bitmap
import java.nio.ByteBuffer
import tensorholo.HologramGenerator
import tensorholo.Preview
import tensorholo.RgbdFrame
import tensorholo.SlmPatterns
import tensorholo.packRgba

/**
 * The frame a colour-sequential SLM driver takes over HDMI ([packRgba]) as an `ARGB_8888` bitmap of
 * `width × height` pixels: pixel (x, y) has red = the red laser's code, green = the green laser's, blue =
 * the blue laser's (code c displays phase 2πc/256), alpha 255. Show it unscaled, full-screen on the SLM's
 * display (an `android.app.Presentation`); any resampling destroys the hologram.
 *
 * `ARGB_8888` pixels lie in memory as the bytes R, G, B, A, exactly [packRgba]'s layout, so the bytes are
 * copied as they are (`copyPixelsFromBuffer`); with alpha 255 premultiplication changes nothing.
 *
 * @param reuse a mutable `ARGB_8888` bitmap of the same size to fill instead of allocating one (per-frame
 *   display; not while a view may still draw it); ignored when it does not fit.
 * @return `reuse`, or a new bitmap.
 * @throws tensorholo.TensorholoException.InvalidInput when a plane's length is not `width · height` (from
 *   [packRgba]).
 */
@JvmOverloads
fun SlmPatterns.toBitmap(reuse: Bitmap? = null): Bitmap =
    rgbaBitmap(packRgba(this), width.toInt(), height.toInt(), reuse)

/**
 * The simulated view of a [Preview] (`width · height` sRGB RGBA8 bytes) as an `ARGB_8888` bitmap for the
 * phone's screen; `reuse` as in [SlmPatterns.toBitmap].
 *
 * @throws IllegalArgumentException when `rgba` is not `width · height · 4` bytes.
 */
@JvmOverloads
fun Preview.toBitmap(reuse: Bitmap? = null): Bitmap = rgbaBitmap(rgba, width.toInt(), height.toInt(), reuse)

/**
 * [HologramGenerator.preview] as a bitmap: what a viewer of the hologram of `frame` sees with the eye
 * focused at normalised depth `focus` ∈ [0, 1] (0 = near), at the generator's resolution. Runs the
 * generator (a full hologram computation plus the simulation): call it off the UI thread.
 *
 * @throws tensorholo.TensorholoException as [HologramGenerator.preview] (InvalidInput for a bad frame or a
 *   focus outside [0, 1]).
 */
@JvmOverloads
fun HologramGenerator.previewBitmap(frame: RgbdFrame, focus: Float, reuse: Bitmap? = null): Bitmap =
    preview(frame, focus).toBitmap(reuse)

private fun rgbaBitmap(rgba: ByteArray, width: Int, height: Int, reuse: Bitmap?): Bitmap {
    require(width > 0 && height > 0 && rgba.size.toLong() == width.toLong() * height * 4) {
        "RGBA of ${rgba.size} bytes does not fill a ${width}x$height bitmap (${width.toLong() * height * 4} bytes)"
    }
    val bitmap = reuse?.takeIf {
        it.isMutable && !it.isRecycled && it.width == width && it.height == height && it.config == Bitmap.Config.ARGB_8888
    } ?: Bitmap.createBitmap(width, height, Bitmap.Config.ARGB_8888)
    bitmap.copyPixelsFromBuffer(ByteBuffer.wrap(rgba))
    return bitmap
}
