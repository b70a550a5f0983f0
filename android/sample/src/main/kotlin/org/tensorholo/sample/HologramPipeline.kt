package org.tensorholo.sample

import android.graphics.Bitmap
import java.util.concurrent.Executors
import java.util.concurrent.RejectedExecutionException
import java.util.concurrent.atomic.AtomicBoolean
import java.util.concurrent.atomic.AtomicLong
import java.util.concurrent.atomic.AtomicReference
import tensorholo.Foveation
import tensorholo.Gaze
import tensorholo.GeneratorConfig
import tensorholo.HologramGenerator
import tensorholo.HologramStream
import tensorholo.PatternsListener
import tensorholo.Prescription
import tensorholo.RefineProgress
import tensorholo.RefineSettings
import tensorholo.RgbdFrame
import tensorholo.SlmPatterns
import tensorholo.TensorholoException
import tensorholo.android.previewBitmap
import tensorholo.android.toBitmap
import tensorholo.displayProfileFromJson
import tensorholo.generatorConfigForDisplay

/**
 * Camera frames → SLM patterns, off the UI and GL threads.
 *
 * A [HologramGenerator] of the SLM's `width × height` is made on a worker thread for the display that
 * `profileJson` describes and the viewer's sphere `sphereDioptres` ([generatorConfig]), then a [HologramStream]:
 * [push] hands it a frame without blocking, the stream's own thread renders and calls back [onSlm] with the
 * packed SLM bitmap. Every [PREVIEW_EVERY_MS] (and when [focus] changes) the worker renders a
 * [HologramGenerator.preview] of the latest frame for [onPreview]; the generator runs one call at a time, so
 * previews slow the stream a little. Callbacks arrive on background threads; the caller posts them to the UI
 * thread.
 *
 * Foveation (docs/FOVEATION.md): once [gaze] is set (the sample sets it from a touch on the preview), frames
 * are rendered foveated on it ([HologramStream.pushFoveated]): the 3D CNN around the gaze, a 2D hologram with
 * synthetic blur elsewhere, a fraction of a full frame's time at the SLM's resolution.
 */
class HologramPipeline(
    width: Int,
    height: Int,
    private val profileJson: String?,
    private val sphereDioptres: Double?,
    private val onSlm: (Bitmap) -> Unit,
    private val onPreview: (Bitmap) -> Unit,
    private val onStatus: (String) -> Unit,
) : AutoCloseable {
    private val worker = Executors.newSingleThreadExecutor { Thread(it, "tensorholo-worker") }
    @Volatile private var generator: HologramGenerator? = null
    @Volatile private var stream: HologramStream? = null
    private val closed = AtomicBoolean(false)
    private val pushed = AtomicLong(0)
    private val delivered = AtomicLong(0)
    private val latest = AtomicReference<RgbdFrame?>(null)
    private val previewQueued = AtomicBoolean(false)
    @Volatile private var lastPreview = 0L
    /** While a best-quality photo is on the SLM, the stream's frames are not shown ([bestQuality], [live]). */
    private val holdingPhoto = AtomicBoolean(false)
    private val photoCancelled = AtomicBoolean(false)

    /**
     * Where the viewer looks, as fractions of the hologram's width and height (0..1, top-left origin), or null
     * (the default) for full 3D frames.
     */
    @Volatile var gaze: Pair<Float, Float>? = null

    private val size = width to height

    /** Focus of the preview's simulated eye, normalised depth in [0, 1] (0 = near). */
    @Volatile var focus = 0.5f
        set(value) {
            field = value.coerceIn(0f, 1f)
            requestPreview(force = true)
        }

    private val listener = object : PatternsListener {
        override fun onPatterns(index: ULong, patterns: SlmPatterns) {
            delivered.incrementAndGet()
            if (closed.get() || holdingPhoto.get()) return
            onSlm(patterns.toBitmap())
            requestPreview(force = false)
        }

        override fun onError(error: TensorholoException) {
            delivered.incrementAndGet()
            if (!closed.get()) onStatus("frame skipped: ${error.message}")
        }
    }

    init {
        worker.execute {
            try {
                onStatus("preparing the hologram CNN for ${width}x$height…")
                val gen = HologramGenerator(generatorConfig(width, height))
                generator = gen
                stream = gen.stream(listener)
                val info = gen.info()
                onStatus(
                    "${info.width}x${info.height}, ${info.layers} layers, ${info.cnnLayout} × ${info.cnnThreads} threads; " +
                        info.displayMapping,
                )
            } catch (e: TensorholoException) {
                onStatus("cannot start: ${e.message}")
            }
        }
    }

    /**
     * The generator's configuration for a `width × height` SLM: from the display profile (pitch, lasers, volume,
     * offset; docs/DISPLAYS.md) where the app ships one, else the paper's 8 µm display. The display's mode gives
     * the size (it is what the SLM is sent). A profile the shipped CNNs cannot serve fails when the generator is
     * made, naming the key (`volume_depth_m`, `wavelengths_m`…).
     */
    private fun generatorConfig(width: Int, height: Int): GeneratorConfig {
        val json = profileJson ?: return withPrescription(GeneratorConfig(width = width.toUInt(), height = height.toUInt()))
        return withPrescription(
            generatorConfigForDisplay(displayProfileFromJson(json))
                .copy(width = width.toUInt(), height = height.toUInt()),
        )
    }

    /**
     * `config` with the viewer's sphere from the slider (docs/ABERRATION.md, "A viewer's prescription"): the
     * profile's prescription (cylinder, axis, eyepiece) with that sphere, or a sphere alone; without a sphere the
     * profile's prescription as it is. A corrected generator runs on the CPU and encodes with AA-DPM.
     */
    private fun withPrescription(config: GeneratorConfig): GeneratorConfig {
        // A 5° fovea behind the paper's 21 mm eyepiece, used once a gaze is set.
        val sphere = sphereDioptres ?: return config.copy(foveation = Foveation())
        val rx = config.prescription?.copy(sphereD = sphere) ?: Prescription(sphereD = sphere)
        return config.copy(prescription = rx, foveation = Foveation())
    }

    /**
     * Whether a frame is worth converting now: the stream exists and holds fewer than 2 frames (pushed, not
     * yet delivered or dropped). Checked on the GL thread before the camera images are converted, so no
     * conversion is wasted on a frame the stream would drop.
     */
    fun wantsFrame(): Boolean {
        val s = stream ?: return false
        return try {
            pushed.get() - delivered.get() - s.droppedFrames().toLong() < 2
        } catch (e: IllegalStateException) {
            false // closed meanwhile by close()
        }
    }

    /** Queues a frame (never blocks; the stream drops its oldest frame when two are waiting). */
    fun push(frame: RgbdFrame) {
        if (closed.get()) return
        val s = stream ?: return
        latest.set(frame)
        try {
            val g = gaze
            if (g == null) {
                s.push(frame)
            } else {
                // Fractions to hologram pixels (0, 0 the top-left pixel's centre).
                val x = g.first.coerceIn(0f, 1f) * (size.first - 1)
                val y = g.second.coerceIn(0f, 1f) * (size.second - 1)
                s.pushFoveated(frame, Gaze(x = x.toDouble(), y = y.toDouble()))
            }
            pushed.incrementAndGet()
        } catch (e: TensorholoException) {
            onStatus("push: ${e.message}")
        } catch (e: IllegalStateException) {
            // The stream was closed by close() on the worker meanwhile.
        }
    }

    private fun requestPreview(force: Boolean) {
        val now = System.currentTimeMillis()
        if (closed.get() || (!force && now - lastPreview < PREVIEW_EVERY_MS)) return
        if (!previewQueued.compareAndSet(false, true)) return
        runOnWorker {
            previewQueued.set(false)
            val gen = generator ?: return@runOnWorker
            val frame = latest.get() ?: return@runOnWorker
            lastPreview = System.currentTimeMillis()
            try {
                val bitmap = gen.previewBitmap(frame, focus)
                if (!closed.get()) onPreview(bitmap)
            } catch (e: TensorholoException) {
                onStatus("preview: ${e.message}")
            }
        }
    }

    /**
     * Times [frames] renders of the library's built-in scene at the SLM's resolution on the worker
     * ([HologramGenerator.benchmark]; the stream waits meanwhile) and reports the median stage timings and the CNN
     * plan this phone chose through [onStatus].
     */
    fun benchmark(frames: UInt = 10u) = runOnWorker {
        val gen = generator ?: return@runOnWorker
        onStatus("benchmarking $frames frames…")
        try {
            val r = gen.benchmark(frames)
            val m = r.median
            onStatus(
                if (r.info.backend == "gpu") {
                    "%.1f fps on the GPU (%s): GPU %.0f ms, input %.0f ms".format(
                        r.fps, r.info.gpuAdapter ?: "?", m.gpuMs, m.cnnMs,
                    )
                } else {
                    "%.1f fps on the CPU: CNN %.0f ms, offset %.0f ms, pre-filter %.0f ms, encoding %.0f ms; %s × %d threads (%s)".format(
                        r.fps, m.cnnMs, m.offsetMs, m.prefilterMs, m.encodingMs, r.info.cnnLayout, r.info.cnnThreads.toInt(),
                        r.info.backendReason,
                    )
                },
            )
        } catch (e: TensorholoException) {
            onStatus("benchmark: ${e.message}")
        }
    }

    /**
     * The "best quality" photo: the latest frame refined on the worker ([HologramGenerator.renderRefined],
     * 10 iterations of focal-stack refinement from the CNN's codes against the frame's SM-LBM focal stack:
     * about +4 dB, seconds on a phone; docs/REFINE.md). Progress goes to [onStatus]; [cancelPhoto] stops it.
     * The refined pattern stays on the SLM until [live].
     */
    fun bestQuality(iterations: UInt = 10u) = runOnWorker {
        val gen = generator ?: return@runOnWorker
        val frame = latest.get() ?: return@runOnWorker
        photoCancelled.set(false)
        val progress = object : RefineProgress {
            override fun onIteration(iteration: UInt, iterations: UInt, psnrDb: Double): Boolean {
                onStatus("best quality: iteration $iteration of $iterations, %.1f dB".format(psnrDb))
                return !photoCancelled.get() && !closed.get()
            }
        }
        try {
            val patterns = gen.renderRefined(frame, RefineSettings(iterations = iterations), progress)
            holdingPhoto.set(true)
            if (!closed.get()) onSlm(patterns.toBitmap())
            onStatus("best quality photo on the SLM (tap Live to go back)")
        } catch (e: TensorholoException.Cancelled) {
            onStatus("best quality: cancelled")
        } catch (e: TensorholoException) {
            onStatus("best quality: ${e.message}")
        }
    }

    /** Stops a running [bestQuality] (it ends at its next iteration). */
    fun cancelPhoto() = photoCancelled.set(true)

    /** Back to the live stream after [bestQuality]. */
    fun live() = holdingPhoto.set(false)

    /** Stops the stream (delivering nothing more to the callbacks) and frees the generator, off the caller's thread. */
    override fun close() {
        if (!closed.compareAndSet(false, true)) return
        // On the worker, after the start-up task: the stream and generator exist by then (or never will).
        runOnWorker {
            val s = stream
            stream = null // wantsFrame() is false from now on
            s?.let {
                it.finish()
                it.close()
            }
            generator?.close()
            generator = null
        }
        worker.shutdown()
    }

    private fun runOnWorker(task: () -> Unit) {
        try {
            worker.execute(task)
        } catch (e: RejectedExecutionException) {
            // After close(): nothing more to do.
        }
    }

    private companion object {
        const val PREVIEW_EVERY_MS = 500L
    }
}
