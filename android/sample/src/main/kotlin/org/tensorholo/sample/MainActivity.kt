package org.tensorholo.sample

import android.Manifest
import android.app.Activity
import android.content.pm.PackageManager
import android.hardware.display.DisplayManager
import android.opengl.GLSurfaceView
import android.os.Build
import android.os.Bundle
import android.util.Log
import android.view.Display
import android.view.WindowManager
import android.widget.Button
import android.widget.Switch
import android.widget.ImageView
import android.widget.SeekBar
import android.widget.TextView
import com.google.ar.core.ArCoreApk
import com.google.ar.core.Config
import com.google.ar.core.Session
import com.google.ar.core.exceptions.CameraNotAvailableException
import com.google.ar.core.exceptions.UnavailableException
import java.io.IOException

/**
 * ARCore depth camera → hologram. The phone shows a simulated view of the hologram (focus slider: 0 = near,
 * 100 = far); a second display of category `DISPLAY_CATEGORY_PRESENTATION` (the SLM, over HDMI or USB-C
 * DisplayPort; wired displays preferred, see [slmDisplay]) shows the SLM frames full-screen, unscaled, at its
 * own resolution. Without one, holograms are computed at
 * [PREVIEW_ONLY_SIZE] for the preview alone.
 *
 * Threads: UI (this activity), GL ([ArFrameSource]: ARCore + conversion), the stream's thread (rendering)
 * and one worker ([HologramPipeline]: generator start-up, previews). Nothing heavy runs on UI or GL.
 */
class MainActivity : Activity(), DisplayManager.DisplayListener {
    private lateinit var surface: GLSurfaceView
    private lateinit var previewView: ImageView
    private lateinit var status: TextView
    private lateinit var focusBar: SeekBar
    private lateinit var sphereBar: SeekBar
    private lateinit var sphereLabel: TextView
    private val displays by lazy { getSystemService(DisplayManager::class.java) }

    /** The SLM's display profile, `assets/display.json` (docs/DISPLAYS.md), or null when the app ships none. */
    private val displayProfileJson: String? by lazy {
        try {
            assets.open(DISPLAY_PROFILE).bufferedReader().use { it.readText() }
        } catch (e: IOException) {
            null
        }
    }

    @Volatile private var session: Session? = null
    @Volatile private var pipeline: HologramPipeline? = null
    private var pipelineSize: Pair<Int, Int>? = null
    private var presentation: SlmPresentation? = null
    private var installRequested = false
    private lateinit var rawDepthSwitch: Switch

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        setContentView(R.layout.activity_main)
        surface = findViewById(R.id.surface)
        previewView = findViewById(R.id.preview)
        status = findViewById(R.id.status)
        focusBar = findViewById(R.id.focus)
        findViewById<Button>(R.id.benchmark).setOnClickListener { pipeline?.benchmark() }
        findViewById<Button>(R.id.best_quality).setOnClickListener { pipeline?.bestQuality() }
        findViewById<Button>(R.id.cancel_photo).setOnClickListener { pipeline?.cancelPhoto() }
        findViewById<Button>(R.id.live).setOnClickListener { pipeline?.live() }
        rawDepthSwitch = findViewById(R.id.raw_depth)
        // A touch on the preview is the viewer's gaze (docs/FOVEATION.md): frames are then foveated on it.
        previewView.setOnTouchListener { view, event ->
            if (view.width > 0 && view.height > 0) {
                pipeline?.gaze = event.x / view.width to event.y / view.height
            }
            view.performClick()
            true
        }
        focusBar.setOnSeekBarChangeListener(object : SeekBar.OnSeekBarChangeListener {
            override fun onProgressChanged(bar: SeekBar, progress: Int, fromUser: Boolean) {
                pipeline?.focus = progress / 100f
            }

            override fun onStartTrackingTouch(bar: SeekBar) = Unit

            override fun onStopTrackingTouch(bar: SeekBar) = Unit
        })
        sphereBar = findViewById(R.id.sphere)
        sphereLabel = findViewById(R.id.sphere_label)
        sphereBar.setOnSeekBarChangeListener(object : SeekBar.OnSeekBarChangeListener {
            override fun onProgressChanged(bar: SeekBar, progress: Int, fromUser: Boolean) {
                val sphere = sphereDioptres(progress)
                sphereLabel.text = if (sphere == null) "Correct my eyes: off" else "Correct my eyes: sphere %+.2f D".format(sphere)
            }

            override fun onStartTrackingTouch(bar: SeekBar) = Unit

            // Remake the pipeline with the new prescription (a moment: the generator is made again).
            override fun onStopTrackingTouch(bar: SeekBar) {
                pipelineSize = null
                updateOutput()
            }
        })
        window.addFlags(WindowManager.LayoutParams.FLAG_KEEP_SCREEN_ON)

        // The renderer is set once, before the surface exists; it waits for the session.
        surface.preserveEGLContextOnPause = true
        surface.setEGLContextClientVersion(2)
        @Suppress("DEPRECATION")
        surface.setRenderer(
            ArFrameSource(
                this,
                { session },
                { windowManager.defaultDisplay.rotation },
                { pipeline },
                rawDepth = { rawDepthSwitch.isChecked },
            ) { message ->
                runOnUiThread { status.text = message }
            },
        )
        surface.renderMode = GLSurfaceView.RENDERMODE_CONTINUOUSLY
    }

    override fun onResume() {
        super.onResume()
        if (checkSelfPermission(Manifest.permission.CAMERA) != PackageManager.PERMISSION_GRANTED) {
            requestPermissions(arrayOf(Manifest.permission.CAMERA), CAMERA_REQUEST)
            return
        }
        val s = session ?: createSession() ?: return
        try {
            s.resume()
        } catch (e: CameraNotAvailableException) {
            status.text = "camera not available: ${e.message}"
            return
        }
        surface.onResume()
        displays.registerDisplayListener(this, null)
        updateOutput()
    }

    override fun onPause() {
        super.onPause()
        displays.unregisterDisplayListener(this)
        surface.onPause() // stops the GL thread before the session pauses
        session?.pause()
        presentation?.dismiss()
        presentation = null
    }

    override fun onDestroy() {
        pipeline?.close()
        pipeline = null
        session?.close()
        session = null
        super.onDestroy()
    }

    override fun onRequestPermissionsResult(requestCode: Int, permissions: Array<out String>, results: IntArray) {
        super.onRequestPermissionsResult(requestCode, permissions, results)
        if (requestCode == CAMERA_REQUEST && results.firstOrNull() != PackageManager.PERMISSION_GRANTED) {
            status.text = "the camera permission is needed for the depth camera"
        }
    }

    /** ARCore installed (or installing: null, resumed later) and a session with the Depth API, else null. */
    private fun createSession(): Session? {
        try {
            if (ArCoreApk.getInstance().requestInstall(this, !installRequested) == ArCoreApk.InstallStatus.INSTALL_REQUESTED) {
                installRequested = true
                return null
            }
            val s = Session(this)
            if (!s.isDepthModeSupported(Config.DepthMode.AUTOMATIC)) {
                status.text = "this device has no ARCore Depth API"
                s.close()
                return null
            }
            s.configure(Config(s).apply {
                depthMode = Config.DepthMode.AUTOMATIC
                focusMode = Config.FocusMode.AUTO
            })
            session = s
            return s
        } catch (e: UnavailableException) {
            status.text = "ARCore unavailable: $e"
            return null
        }
    }

    /**
     * The display for the SLM among the presentation displays, or null: never this activity's own display
     * nor a built-in one (Android 16 lets built-in displays carry `FLAG_PRESENTATION` too), never a private
     * one; among the rest, a display that reported an EDID over its cable (`Display.getDeviceProductInfo()`,
     * API 31: physical HDMI / DisplayPort displays have one, Wi-Fi displays (Miracast) and virtual or overlay
     * displays have none) before any other. A wireless display compresses the video, so it is used only when
     * nothing else is connected, with a warning (Android has no public "is wireless" test).
     */
    private fun slmDisplay(): Display? {
        @Suppress("DEPRECATION")
        val own = if (Build.VERSION.SDK_INT >= 30) display?.displayId else windowManager.defaultDisplay.displayId
        val candidates = displays.getDisplays(DisplayManager.DISPLAY_CATEGORY_PRESENTATION).filter { d ->
            d.displayId != own && d.displayId != Display.DEFAULT_DISPLAY && d.isValid &&
                (d.flags and Display.FLAG_PRIVATE) == 0 &&
                !(Build.VERSION.SDK_INT >= 36 && d.isInternal)
        }
        if (Build.VERSION.SDK_INT >= 31) {
            candidates.firstOrNull { it.deviceProductInfo != null }?.let { return it }
        }
        return candidates.firstOrNull()?.also {
            status.text = "warning: cannot tell whether display '${it.name}' is wired; a wireless display " +
                "compresses the pattern (use USB-C DisplayPort or HDMI)"
        }
    }

    /**
     * The SLM output for the displays present now: a presentation on [slmDisplay] and a pipeline at its size,
     * or a preview-only pipeline. A pipeline is remade only when the size changes.
     */
    private fun updateOutput() {
        val slm = slmDisplay()
        if (presentation?.display?.displayId != slm?.displayId) {
            presentation?.dismiss()
            presentation = slm?.let { showPresentation(it) }
        }
        val size = presentation?.let { it.width to it.height } ?: PREVIEW_ONLY_SIZE
        if (pipeline != null && pipelineSize == size) return
        pipeline?.close()
        pipelineSize = size
        pipeline = HologramPipeline(
            size.first,
            size.second,
            displayProfileJson,
            sphereDioptres(sphereBar.progress),
            onSlm = { bitmap -> runOnUiThread { presentation?.showPattern(bitmap) } },
            onPreview = { bitmap -> runOnUiThread { previewView.setImageBitmap(bitmap) } },
            onStatus = { message -> runOnUiThread { status.text = message } },
        ).also { it.focus = focusBar.progress / 100f }
    }

    /** The sphere the slider gives, dioptres in 0.25 D steps, or null in its middle (no correction). */
    private fun sphereDioptres(progress: Int): Double? =
        if (progress == SPHERE_OFF) null else (progress - SPHERE_OFF) * 0.25

    /** A shown presentation on `display`, or null when the display went away meanwhile (reported). */
    private fun showPresentation(display: Display): SlmPresentation? {
        val p = SlmPresentation(this, display) { problem -> runOnUiThread { status.text = problem } }
        return try {
            p.show()
            p
        } catch (e: WindowManager.InvalidDisplayException) {
            // The display was removed between the query and show(): onDisplayRemoved follows.
            Log.w("tensorholo", "SLM display ${display.displayId} is gone", e)
            status.text = "the SLM display disconnected: ${e.message}"
            null
        }
    }

    override fun onDisplayAdded(displayId: Int) = updateOutput()

    override fun onDisplayRemoved(displayId: Int) = updateOutput()

    override fun onDisplayChanged(displayId: Int) = updateOutput()

    private companion object {
        const val CAMERA_REQUEST = 1

        /** The SLM's display profile in the app's assets: pitch, lasers, volume, offsets (docs/DISPLAYS.md). */
        const val DISPLAY_PROFILE = "display.json"

        /** Hologram size when no SLM display is connected (preview only). */
        val PREVIEW_ONLY_SIZE = 640 to 360

        /** The sphere slider's middle: no correction. */
        const val SPHERE_OFF = 48
    }
}
