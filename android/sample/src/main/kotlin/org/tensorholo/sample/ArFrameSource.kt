package org.tensorholo.sample

import android.content.Context
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CameraManager
import android.opengl.GLES11Ext
import android.opengl.GLES20
import android.opengl.GLSurfaceView
import android.util.Log
import com.google.ar.core.Session
import com.google.ar.core.TrackingState
import com.google.ar.core.exceptions.CameraNotAvailableException
import com.google.ar.core.exceptions.DeadlineExceededException
import com.google.ar.core.exceptions.NotYetAvailableException
import com.google.ar.core.exceptions.ResourceExhaustedException
import javax.microedition.khronos.egl.EGLConfig
import javax.microedition.khronos.opengles.GL10
import tensorholo.Rotation
import tensorholo.android.CameraPlanes
import tensorholo.android.RgbdFrames
import tensorholo.android.fromArFrame

/**
 * Runs the ARCore session on the GL thread (ARCore needs a GL context and a camera texture for
 * `Session.update()`; nothing is drawn, the hologram preview covers the surface) and feeds the pipeline:
 * for each frame the pipeline wants, `RgbdFrames.fromArFrame` turns the CPU camera image (`YUV_420_888`,
 * sensor orientation) and the Depth API image (`acquireDepthImage16Bits`: 16-bit millimetres covering the
 * GPU texture's field of view) into a registered [tensorholo.RgbdFrame] (the CPU image cropped to the depth's
 * field of view; a few ms of conversion), both images are closed at once, and the frame is pushed (never
 * blocks). With [rawDepth] on, the frame carries ARCore's raw depth (`acquireRawDepthImage16Bits`: unsmoothed,
 * with holes) and its confidence image (`acquireRawDepthConfidenceImage`, 0–255) instead: depth below
 * [MIN_CONFIDENCE] is invalid and filled from its confident neighbours by the library, never read as near.
 *
 * No exception escapes to the GL thread (one would kill the app): a frame without depth yet, a frame too old
 * or too many held images skip the frame; anything else is reported through [onError] once per message and
 * the next frame is tried.
 *
 * @param session the session once made (ARCore may need installing first), else null.
 * @param displayRotation the display's `Surface.ROTATION_*`.
 * @param rawDepth whether to take the raw depth and its confidence (read for every frame: a switch).
 * @param onError a problem for the user (called on the GL thread; post it to the UI thread).
 */
class ArFrameSource(
    private val context: Context,
    private val session: () -> Session?,
    private val displayRotation: () -> Int,
    private val pipeline: () -> HologramPipeline?,
    private val rawDepth: () -> Boolean = { false },
    private val onError: (String) -> Unit = {},
) : GLSurfaceView.Renderer {
    private var lastError: String? = null
    private var textureId = 0
    private var textureSession: Session? = null
    private var width = 0
    private var height = 0
    private var geometry = -1 // display rotation the session was told, -1 = not yet
    private var sensorOrientation = 90
    private var rotation = Rotation.DEG90

    override fun onSurfaceCreated(gl: GL10?, config: EGLConfig?) {
        GLES20.glClearColor(0f, 0f, 0f, 1f)
        val names = IntArray(1)
        GLES20.glGenTextures(1, names, 0)
        textureId = names[0]
        GLES20.glBindTexture(GLES11Ext.GL_TEXTURE_EXTERNAL_OES, textureId)
        GLES20.glTexParameteri(GLES11Ext.GL_TEXTURE_EXTERNAL_OES, GLES20.GL_TEXTURE_MIN_FILTER, GLES20.GL_LINEAR)
        GLES20.glTexParameteri(GLES11Ext.GL_TEXTURE_EXTERNAL_OES, GLES20.GL_TEXTURE_MAG_FILTER, GLES20.GL_LINEAR)
        textureSession = null // a new context: tell the session the new texture
    }

    override fun onSurfaceChanged(gl: GL10?, width: Int, height: Int) {
        GLES20.glViewport(0, 0, width, height)
        this.width = width
        this.height = height
        geometry = -1
    }

    override fun onDrawFrame(gl: GL10?) {
        try {
            drawFrame()
        } catch (e: Exception) {
            // ARCore's other exceptions (SessionPausedException, FatalException, …), a bad image layout
            // (IllegalArgumentException), a closed stream: reported, never thrown on the GL thread.
            val message = "${e.javaClass.simpleName}: ${e.message}"
            Log.w(TAG, "frame skipped", e)
            if (message != lastError) onError(message)
            lastError = message
        }
    }

    private fun drawFrame() {
        GLES20.glClear(GLES20.GL_COLOR_BUFFER_BIT)
        val s = session() ?: return
        if (textureSession !== s) {
            s.setCameraTextureNames(intArrayOf(textureId))
            val characteristics = context.getSystemService(CameraManager::class.java)
                .getCameraCharacteristics(s.cameraConfig.cameraId)
            sensorOrientation = characteristics.get(CameraCharacteristics.SENSOR_ORIENTATION) ?: 90
            textureSession = s
            geometry = -1
        }
        val r = displayRotation()
        if (r != geometry && width > 0) {
            s.setDisplayGeometry(r, width, height)
            rotation = CameraPlanes.rotationFor(sensorOrientation, r * 90, frontFacing = false)
            geometry = r
        }
        val frame = try {
            s.update()
        } catch (e: CameraNotAvailableException) {
            return
        }
        if (frame.camera.trackingState != TrackingState.TRACKING) return // depth needs tracking
        val p = pipeline() ?: return
        if (!p.wantsFrame()) return
        val rgbd = try {
            RgbdFrames.fromArFrame(frame, rotation, rawDepth = rawDepth(), minConfidence = MIN_CONFIDENCE)
        } catch (e: NotYetAvailableException) {
            return // no camera image or depth for this frame yet
        } catch (e: DeadlineExceededException) {
            return // the frame is already too old
        } catch (e: ResourceExhaustedException) {
            return // too many images held at once: ARCore frees them as they are closed
        }
        p.push(rgbd)
        lastError = null
    }

    private companion object {
        const val TAG = "tensorholo"

        /** The lowest raw-depth confidence kept (ARCore's 0–255 scale; about half of its range). */
        const val MIN_CONFIDENCE = 128
    }
}
