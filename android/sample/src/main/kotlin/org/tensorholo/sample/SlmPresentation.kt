package org.tensorholo.sample

import android.app.Presentation
import android.content.Context
import android.graphics.Bitmap
import android.graphics.Color
import android.os.Bundle
import android.view.Display
import android.view.WindowManager
import android.widget.ImageView

/**
 * The SLM's display (a second screen: HDMI, USB-C DisplayPort): shows each packed SLM frame full-screen,
 * pixel for pixel. The patterns are computed at the display's own mode size ([width] × [height]), drawn
 * unscaled (no density scaling, no filtering): resampling a phase pattern destroys the hologram.
 */
class SlmPresentation(outer: Context, display: Display) : Presentation(outer, display) {
    private var image: ImageView? = null

    /** The display's width in pixels (its current mode, natural orientation). */
    val width: Int = display.mode.physicalWidth

    /** The display's height in pixels. */
    val height: Int = display.mode.physicalHeight

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        image = ImageView(context).apply {
            scaleType = ImageView.ScaleType.CENTER
            setBackgroundColor(Color.BLACK)
        }
        setContentView(image)
        window?.addFlags(WindowManager.LayoutParams.FLAG_KEEP_SCREEN_ON)
    }

    /** Shows one SLM frame (`width × height`, from `SlmPatterns.toBitmap()`); call on the UI thread. */
    fun showPattern(bitmap: Bitmap) {
        bitmap.density = Bitmap.DENSITY_NONE
        image?.setImageBitmap(bitmap)
    }
}
