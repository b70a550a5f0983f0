package org.tensorholo.sample

import android.app.Presentation
import android.content.Context
import android.graphics.Bitmap
import android.graphics.Canvas
import android.graphics.Color
import android.graphics.Point
import android.os.Build
import android.os.Bundle
import android.view.Display
import android.view.View
import android.view.WindowInsets
import android.view.WindowManager

/**
 * The SLM's display (a second screen over a cable: HDMI, USB-C DisplayPort): shows each packed SLM frame
 * full-screen, one bitmap pixel per display pixel. The patterns are computed at the display's logical size
 * ([width] × [height], what the app draws into); any scaling or filtering of a phase pattern destroys the
 * hologram, so:
 * - the frame is drawn by [SlmView] at the window's origin with `Canvas.drawBitmap(bitmap, 0, 0, null)`: no
 *   scaling, no filtering (a null paint), no density scaling (the bitmap's density is `DENSITY_NONE`);
 * - the window is full-screen with the system bars hidden, so that it starts at the display's origin;
 * - [pixelExactProblem] says when the display itself scales: a logical size that differs from the current
 *   mode's physical size (the compositor then resamples every frame), or a window smaller than the display.
 */
class SlmPresentation(
    outer: Context,
    display: Display,
    private val onProblem: (String) -> Unit,
) : Presentation(outer, display) {
    private var view: SlmView? = null

    /** The display's logical width in pixels (what the app draws; `Display.getRealSize`). */
    val width: Int

    /** The display's logical height in pixels. */
    val height: Int

    /** Why this display is not pixel-exact, or null when its logical size is its mode's physical size. */
    val pixelExactProblem: String?

    init {
        val size = Point()
        @Suppress("DEPRECATION") // the display's logical size; WindowMetrics needs a window context
        display.getRealSize(size)
        width = size.x
        height = size.y
        val mode = display.mode
        val physical = setOf(mode.physicalWidth to mode.physicalHeight, mode.physicalHeight to mode.physicalWidth)
        pixelExactProblem = if ((width to height) in physical) {
            null
        } else {
            "the SLM display draws ${width}x$height but its mode is ${mode.physicalWidth}x${mode.physicalHeight}: " +
                "the compositor scales every pattern (set the display's resolution to its native mode)"
        }
    }

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        val v = SlmView(context) { w, h ->
            if (w != width || h != height) {
                onProblem("the SLM window is ${w}x$h, not the display's ${width}x$height: patterns would be cut")
            }
        }
        view = v
        setContentView(v)
        window?.apply {
            addFlags(WindowManager.LayoutParams.FLAG_KEEP_SCREEN_ON or WindowManager.LayoutParams.FLAG_FULLSCREEN)
            setLayout(WindowManager.LayoutParams.MATCH_PARENT, WindowManager.LayoutParams.MATCH_PARENT)
            if (Build.VERSION.SDK_INT >= 30) {
                setDecorFitsSystemWindows(false)
                insetsController?.hide(WindowInsets.Type.systemBars())
            }
        }
        pixelExactProblem?.let(onProblem)
    }

    /** Shows one SLM frame (`width × height`, from `SlmPatterns.toBitmap()`); call on the UI thread. */
    fun showPattern(bitmap: Bitmap) {
        if (bitmap.width != width || bitmap.height != height) {
            onProblem("pattern ${bitmap.width}x${bitmap.height} does not match the SLM display's ${width}x$height")
        }
        bitmap.density = Bitmap.DENSITY_NONE
        view?.bitmap = bitmap
    }

    /** Draws the bitmap unscaled and unfiltered at the view's origin (the window's, full-screen), black around. */
    private class SlmView(context: Context, private val onSize: (Int, Int) -> Unit) : View(context) {
        var bitmap: Bitmap? = null
            set(value) {
                field = value
                invalidate()
            }

        override fun onSizeChanged(w: Int, h: Int, oldw: Int, oldh: Int) = onSize(w, h)

        override fun onDraw(canvas: Canvas) {
            canvas.drawColor(Color.BLACK)
            bitmap?.let { canvas.drawBitmap(it, 0f, 0f, null) }
        }
    }
}
