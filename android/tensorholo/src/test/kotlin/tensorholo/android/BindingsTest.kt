// JVM tests of the generated Kotlin bindings (package tensorholo, JNA) against the host library, on real
// phone frames compared with `holo render`. Run by android/check.sh (kotlinc + JUnitCore, Linux CI) and by
// Gradle (`gradle :tensorholo:testDebugUnitTest`).
//
// System properties:
//   jna.library.path    directory of libtensorholo_ffi.so (the host build)
//   tensorholo.cases    directory written by `python3 bindings/tests/frames.py DIR`: per real frame the phone
//                       buffers (color.raw, depth.raw), their layout (case.json) and holo render's SLM codes
//                       of the same scene (holo/phase_{r,g,b}.png). Absent: the real-frame tests are skipped.
//   tensorholo.version  the workspace version (Cargo.toml) that version() must return. Absent: skipped.

package tensorholo.android

import java.io.File
import java.nio.ByteBuffer
import java.nio.ByteOrder
import java.util.Collections
import javax.imageio.ImageIO
import org.junit.AfterClass
import org.junit.Assert.assertArrayEquals
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertNull
import org.junit.Assert.assertThrows
import org.junit.Assert.assertTrue
import org.junit.Assume.assumeTrue
import org.junit.Test
import tensorholo.CnnEngine
import tensorholo.ColorFormat
import tensorholo.DepthFormat
import tensorholo.DisplayProfile
import tensorholo.Foveation
import tensorholo.Gaze
import tensorholo.GeneratorConfig
import tensorholo.HologramGenerator
import tensorholo.PatternsListener
import tensorholo.RgbdFrame
import tensorholo.Rotation
import tensorholo.SlmPatterns
import tensorholo.TensorholoException
import tensorholo.checkDisplay
import tensorholo.displayProfileFromJson
import tensorholo.generatorConfigForDisplay
import tensorholo.packRgba
import tensorholo.version

class BindingsTest {
    /** One real frame of frames.py: its buffers as the phone delivers them and holo's codes of the scene. */
    class Case(val dir: File) {
        val name: String = dir.name
        private val json: Map<String, String> = readCase(File(dir, "case.json"))
        val width = json.getValue("out_width").toInt()
        val height = json.getValue("out_height").toInt()
        val frame = RgbdFrame(
            color = File(dir, "color.raw").readBytes(),
            colorFormat = ColorFormat.valueOf(json.getValue("color_format")),
            colorWidth = json.getValue("color_width").toUInt(),
            colorHeight = json.getValue("color_height").toUInt(),
            depth = File(dir, "depth.raw").readBytes(),
            depthFormat = DepthFormat.valueOf(json.getValue("depth_format")),
            depthWidth = json.getValue("depth_width").toUInt(),
            depthHeight = json.getValue("depth_height").toUInt(),
            colorRowStride = json.getValue("color_row_stride").toUInt(),
            depthRowStride = json.getValue("depth_row_stride").toUInt(),
            rotation = Rotation.valueOf(json.getValue("rotation")),
        )

        /** The case's generator at the hologram size, made once for all tests (autotuning takes seconds). */
        val generator: HologramGenerator by lazy {
            HologramGenerator(GeneratorConfig(width = width.toUInt(), height = height.toUInt())).also { opened += it }
        }

        /** The bindings' patterns of the frame, rendered once. */
        val patterns: SlmPatterns by lazy { generator.render(frame) }

        /** holo render's code plane of one laser (`r`, `g`, `b`), row-major (`folder`: holo_calibrated for the
         * patterns through panel.holocal). */
        fun holoCodes(laser: String, folder: String = "holo"): ByteArray {
            val img = ImageIO.read(File(dir, "$folder/phase_$laser.png"))
            assertEquals("$name: holo's image size", width to height, img.width to img.height)
            return ByteArray(width * height) { i -> img.raster.getSample(i % width, i / width, 0).toByte() }
        }
    }

    companion object {
        private val opened = mutableListOf<HologramGenerator>()

        /** The cases of `-Dtensorholo.cases`, or null when the property is absent. */
        private val cases: List<Case>? by lazy {
            System.getProperty("tensorholo.cases")?.let { root ->
                val dirs = File(root).listFiles { f -> File(f, "case.json").exists() }
                    ?: throw AssertionError("tensorholo.cases=$root is not a directory")
                assertTrue("no case.json under tensorholo.cases=$root", dirs.isNotEmpty())
                dirs.sortedBy { it.name }.map(::Case)
            }
        }

        /** The real frames; skips the calling test (with the reason) when no cases directory was given. */
        fun realCases(): List<Case> {
            val c = cases
            assumeTrue(
                "real-frame tests skipped: no -Dtensorholo.cases=DIR (python3 bindings/tests/frames.py DIR)",
                c != null,
            )
            return c!!
        }

        /** A flat JSON object of strings and numbers (frames.py's case.json), as a map of raw values. */
        fun readCase(file: File): Map<String, String> =
            Regex("\"(\\w+)\": *(\"[^\"]*\"|[0-9.eE+-]+)").findAll(file.readText())
                .associate { it.groupValues[1] to it.groupValues[2].trim('"') }

        /** Circular distance of two codes (255 and 0 are one code apart on the phase circle). */
        fun circularDiff(a: Byte, b: Byte): Int {
            val d = Math.abs((a.toInt() and 0xFF) - (b.toInt() and 0xFF))
            return minOf(d, 256 - d)
        }

        @AfterClass
        @JvmStatic
        fun closeGenerators() {
            opened.forEach { it.close() }
            opened.clear()
        }
    }

    /** Records what a stream delivers, and on which threads. */
    class Recorder : PatternsListener {
        val indices: MutableList<ULong> = Collections.synchronizedList(mutableListOf())
        val errors: MutableList<TensorholoException> = Collections.synchronizedList(mutableListOf())
        val threads: MutableSet<Long> = Collections.synchronizedSet(mutableSetOf())

        override fun onPatterns(index: ULong, patterns: SlmPatterns) {
            threads.add(Thread.currentThread().id)
            indices.add(index)
        }

        override fun onError(error: TensorholoException) {
            errors.add(error)
        }

        fun delivered() = indices.size + errors.size
    }

    @Test
    fun versionIsTheWorkspaceVersion() {
        val want = System.getProperty("tensorholo.version")
        assumeTrue("version test skipped: no -Dtensorholo.version", want != null)
        assertEquals(want, version())
    }

    /**
     * The bindings' SLM codes of each real frame (phone buffers: padded BGRA + f16 disparity at half
     * resolution; RGBA + ARCore millimetres turned 90°) agree with `holo render` on the same scene, with the
     * tolerance of frames.compare_codes: mean circular difference ≤ 0.02 codes and ≥ 99.9 % within ±1.
     */
    @Test
    fun realFramesMatchHoloRender() {
        for (case in realCases()) {
            val out = case.patterns
            assertEquals("${case.name}: size", case.width.toUInt() to case.height.toUInt(), out.width to out.height)
            for ((plane, laser) in listOf(out.red to "r", out.green to "g", out.blue to "b")) {
                val holo = case.holoCodes(laser)
                assertEquals(holo.size, plane.size)
                var sum = 0L
                var withinOne = 0
                for (i in plane.indices) {
                    val d = circularDiff(plane[i], holo[i])
                    sum += d
                    if (d <= 1) withinOne++
                }
                val mean = sum.toDouble() / plane.size
                val within = withinOne.toDouble() / plane.size
                println("${case.name} $laser: vs holo render mean circular difference $mean, within ±1: $within")
                assertTrue("${case.name} $laser: mean $mean > 0.02", mean <= 0.02)
                assertTrue("${case.name} $laser: within ±1 $within < 0.999", within >= 0.999)
            }
        }
    }

    /**
     * A display calibration file (frames.py's panel.holocal, `holo calibrate global`) gives the codes of `holo
     * render --calibration` through it; bytes that are not such a file raise InvalidInput; null returns to
     * the ideal panel.
     */
    @Test
    fun aCalibrationFileGivesTheCodesOfHoloRenderThroughIt() {
        for (case in realCases()) {
            val gen = case.generator
            assertThrows(TensorholoException.InvalidInput::class.java) {
                gen.setCalibration("HOLOCAL but not one".toByteArray())
            }
            gen.setCalibration(File(case.dir, "panel.holocal").readBytes())
            try {
                assertTrue("${case.name}: info", gen.info().calibration!!.contains("global"))
                val out = gen.render(case.frame)
                for ((plane, laser) in listOf(out.red to "r", out.green to "g", out.blue to "b")) {
                    val holo = case.holoCodes(laser, "holo_calibrated")
                    val mean = plane.indices.sumOf { circularDiff(plane[it], holo[it]) }.toDouble() / plane.size
                    println("${case.name} $laser: calibrated vs holo render --calibration mean difference $mean")
                    assertTrue("${case.name} $laser: mean $mean > 0.02", mean <= 0.02)
                }
            } finally {
                gen.setCalibration(null)
            }
            assertEquals(null, gen.info().calibration)
        }
    }

    /** packRgba puts red, green, blue codes in bytes 0, 1, 2 of every pixel and alpha 255 in byte 3. */
    @Test
    fun packRgbaInterleavesTheLasers() {
        for (case in realCases()) {
            val out = case.patterns
            val rgba = packRgba(out)
            val n = case.width * case.height
            assertEquals(n * 4, rgba.size)
            assertArrayEquals(out.red, ByteArray(n) { rgba[4 * it] })
            assertArrayEquals(out.green, ByteArray(n) { rgba[4 * it + 1] })
            assertArrayEquals(out.blue, ByteArray(n) { rgba[4 * it + 2] })
            assertTrue(ByteArray(n) { rgba[4 * it + 3] }.all { it == 255.toByte() })
            // The three lasers differ (different wavelengths): a mix-up of planes would show.
            assertFalse(out.red.contentEquals(out.green) || out.green.contentEquals(out.blue))
            assertEquals(8u, case.generator.info().layers)
        }
    }

    /** Bad frames raise InvalidInput (naming the buffer where it is one), and the generator goes on. */
    @Test
    fun badFramesRaiseInvalidInputAndTheGeneratorGoesOn() {
        for (case in realCases()) {
            val gen = case.generator
            val frame = case.frame
            val short = assertThrows(TensorholoException.InvalidInput::class.java) {
                gen.render(frame.copy(depth = frame.depth.copyOf(frame.depth.size - 2)))
            }
            assertTrue("message names the buffer: ${short.reason}", short.reason.contains("depth"))
            assertThrows(TensorholoException.InvalidInput::class.java) { gen.render(frame.copy(colorWidth = 0u)) }
            // Every depth sample invalid (0 in every format here): no depth range, an error, not a flat scene.
            assertThrows(TensorholoException.InvalidInput::class.java) {
                gen.render(frame.copy(depth = ByteArray(frame.depth.size)))
            }
            assertArrayEquals("${case.name}: generator after errors", case.patterns.green, gen.render(frame).green)
        }
    }

    /** A listener written in Kotlin gets every frame, in order, on the stream's thread; push after finish fails. */
    @Test
    fun streamDeliversInOrderOnABackgroundThread() {
        for (case in realCases()) {
            val rec = Recorder()
            case.generator.stream(rec).use { stream ->
                for (i in 0 until 3) {
                    assertEquals(i.toULong(), stream.push(case.frame))
                    // One at a time, so the 2-frame queue never drops one.
                    val deadline = System.nanoTime() + 120_000_000_000L
                    while (rec.delivered() <= i) {
                        assertTrue("${case.name}: frame $i not delivered within 120 s", System.nanoTime() < deadline)
                        Thread.sleep(10)
                    }
                }
                stream.finish()
                assertEquals(listOf(0uL, 1uL, 2uL), rec.indices.toList())
                assertEquals(emptyList<TensorholoException>(), rec.errors.toList())
                assertFalse("listener ran on the caller's thread", Thread.currentThread().id in rec.threads)
                assertEquals(0uL, stream.droppedFrames())
                assertThrows(TensorholoException.InvalidInput::class.java) { stream.push(case.frame) }
            }
        }
    }

    /**
     * A generator with a fovea renders a gaze's frame: the full frame's codes nowhere near the gaze, the same
     * codes for the same gaze, and a gaze outside the hologram or a generator without a fovea refused by name.
     */
    @Test
    fun aGazeRendersAFoveatedFrame() {
        val frame = smallFrame(96, 64)
        HologramGenerator(
            GeneratorConfig(width = 96u, height = 64u, threads = 1u, foveation = Foveation(radiusPx = 10.0)),
        ).use { gen ->
            val full = gen.render(frame)
            val gaze = Gaze(x = 30.0, y = 20.0)
            val fov = gen.renderFoveated(frame, gaze)
            assertArrayEquals("same gaze, same codes", fov.green, gen.renderFoveated(frame, gaze).green)
            // The far corner (beyond the fovea, its band and the CNN's margin) holds the periphery's codes.
            var differ = 0
            for (y in 40 until 64) for (x in 70 until 96) if (fov.green[y * 96 + x] != full.green[y * 96 + x]) differ++
            assertTrue("periphery differs from the full frame at $differ of ${24 * 26} pixels", differ > 24 * 26 / 2)
            val outside = assertThrows(TensorholoException.InvalidInput::class.java) {
                gen.renderFoveated(frame, Gaze(x = 500.0, y = 20.0))
            }
            assertTrue(outside.reason, outside.reason.contains("gaze"))
        }
        HologramGenerator(GeneratorConfig(width = 96u, height = 64u, threads = 1u)).use { gen ->
            val none = assertThrows(TensorholoException.InvalidInput::class.java) {
                gen.renderFoveated(frame, Gaze(x = 30.0, y = 20.0))
            }
            assertTrue(none.reason, none.reason.contains("foveation"))
        }
    }

    /** Configurations the contract rejects raise InvalidInput at construction. */
    @Test
    fun badConfigurationsRaiseInvalidInput() {
        assertThrows(TensorholoException.InvalidInput::class.java) {
            HologramGenerator(GeneratorConfig(width = 64u, height = 64u, layers = 9u))
        }
        assertThrows(TensorholoException.InvalidInput::class.java) {
            HologramGenerator(GeneratorConfig(width = 64u, height = 64u, offsetMm = Double.NaN))
        }
        assertThrows(TensorholoException.InvalidInput::class.java) {
            HologramGenerator(GeneratorConfig(width = 0u, height = 64u))
        }
    }

    /**
     * A 4 µm SLM at the paper's lasers (docs/DISPLAYS.md): σ = (4/8)² = 0.25, so the shipped 8 µm / 6 mm CNNs
     * serve a 1.5 mm volume at offsets of 1.5 and 3 mm. Small, so that a frame renders quickly.
     */
    private val profile4um = DisplayProfile(
        pixelPitchM = 4e-6,
        resolution = listOf(48u, 64u),
        wavelengthsM = listOf(638e-9, 520e-9, 450e-9),
        volumeDepthM = 1.5e-3,
        offsetsM = listOf(1.5e-3, 3e-3),
        name = "4 µm SLM",
    )

    /** [profile4um] as a profile file's JSON, with `key` set to the raw JSON `value` where one is given. */
    private fun profileJson(key: String? = null, value: String? = null): String {
        val keys = linkedMapOf(
            "name" to "\"4 µm SLM\"",
            "pixel_pitch_m" to "4e-6",
            "resolution" to "[48, 64]",
            "wavelengths_m" to "[638e-9, 520e-9, 450e-9]",
            "volume_depth_m" to "1.5e-3",
            "offsets_m" to "[1.5e-3, 3e-3]",
        )
        if (key != null && value != null) keys[key] = value
        return keys.entries.joinToString(",\n  ", "{\n  ", "\n}") { (k, v) -> "\"$k\": $v" }
    }

    /** A 64×48 RGB8 texture with metric depth (a ramp from 0.5 m to 1.5 m across the width). */
    private fun smallFrame(width: Int = 64, height: Int = 48): RgbdFrame {
        val color = ByteArray(width * height * 3)
        val depth = ByteBuffer.allocate(width * height * 4).order(ByteOrder.LITTLE_ENDIAN)
        for (y in 0 until height) {
            for (x in 0 until width) {
                val i = (y * width + x) * 3
                color[i] = (x * 4).toByte()
                color[i + 1] = (y * 5).toByte()
                color[i + 2] = ((x xor y) * 7).toByte()
                depth.putFloat(0.5f + x.toFloat() / width)
            }
        }
        return RgbdFrame(
            color = color, colorFormat = ColorFormat.RGB8, colorWidth = width.toUInt(), colorHeight = height.toUInt(),
            depth = depth.array(), depthFormat = DepthFormat.METRES_F32, depthWidth = width.toUInt(),
            depthHeight = height.toUInt(),
        )
    }

    /** Profile → configuration → generator, as an app does (one thread, the native engine: quick and fixed). */
    private fun generatorFor(profile: DisplayProfile): HologramGenerator =
        HologramGenerator(generatorConfigForDisplay(profile).copy(threads = 1u, engine = CnnEngine.NATIVE))

    /** The 4 µm profile from JSON is the record built field by field, and the shipped CNNs drive it at σ = 0.25. */
    @Test
    fun a4umDisplayProfileRendersWithTheShippedModels() {
        val profile = displayProfileFromJson(profileJson())
        assertEquals(profile4um, profile)
        val config = generatorConfigForDisplay(profile)
        assertEquals(64u to 48u, config.width to config.height)
        assertEquals(4e-6, config.pixelPitchM, 0.0)
        assertEquals(1.5e-3, config.volumeDepthM, 0.0)
        assertEquals(1.5, config.offsetMm, 1e-12)
        assertNull(config.wavelengthRatioTolerance) // the serving rule's
        val checks = checkDisplay(profile, null)
        val hologramChecks = checks.filter { it.kind == "hologram-cnn" }
        assertTrue(checks.toString(), hologramChecks.isNotEmpty() && hologramChecks.all { it.served })
        generatorFor(profile).use { gen ->
            val out = gen.render(smallFrame())
            assertEquals(64u to 48u, out.width to out.height)
            assertTrue("constant pattern", out.red.toSet().size > 1)
            val info = gen.info()
            println("4 µm display: ${info.displayMapping}")
            assertTrue(info.displayMapping, info.displayMapping.contains("σ = 0.25"))
            assertTrue(info.displayMapping, info.displayMapping.contains("serves 4 µm with a 1.5 mm volume"))
            assertTrue(info.prefilterReason, info.prefilterModel?.contains("6mm") == true)
        }
    }

    /**
     * Each bad display is an error naming the key, whether it comes as JSON or as a record built field by field:
     * a negative pitch and a resolution that is not [height, width] break the profile rules (InvalidInput); a
     * green laser 8 % off 520 nm (a spread that costs more than the serving rule allows) and a volume deeper than
     * σ·6 mm = 1.5 mm are displays the shipped CNNs do not serve (InvalidModel, when the generator checks its models).
     */
    @Test
    fun badDisplayProfilesAreErrorsNamingTheKey() {
        data class Bad(val key: String, val json: String, val record: DisplayProfile, val error: Class<out TensorholoException>)
        val bad = listOf(
            Bad("pixel_pitch_m", "-4e-6", profile4um.copy(pixelPitchM = -4e-6), TensorholoException.InvalidInput::class.java),
            Bad("resolution", "[48]", profile4um.copy(resolution = listOf(48u)), TensorholoException.InvalidInput::class.java),
            Bad(
                "wavelengths_m", "[638e-9, 561.6e-9, 450e-9]", profile4um.copy(wavelengthsM = listOf(638e-9, 561.6e-9, 450e-9)),
                TensorholoException.InvalidModel::class.java,
            ),
            Bad("volume_depth_m", "2e-3", profile4um.copy(volumeDepthM = 2e-3), TensorholoException.InvalidModel::class.java),
        )
        for (b in bad) {
            val fromJson = assertThrows(b.error) { generatorFor(displayProfileFromJson(profileJson(b.key, b.json))).close() }
            assertTrue("JSON ${b.key}: ${fromJson.message}", fromJson.message!!.contains(b.key))
            val fromRecord = assertThrows(b.error) { generatorFor(b.record).close() }
            assertTrue("record ${b.key}: ${fromRecord.message}", fromRecord.message!!.contains(b.key))
        }
        val typo = assertThrows(TensorholoException.InvalidInput::class.java) {
            displayProfileFromJson(profileJson().replace("pixel_pitch_m", "pixel_pich_m"))
        }
        assertTrue(typo.reason, typo.reason.contains("pixel_pich_m"))
    }
}
