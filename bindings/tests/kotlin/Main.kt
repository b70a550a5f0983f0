// Checks of the generated Kotlin bindings (package tensorholo) on the JVM, run by check.sh:
// `java -Djna.library.path=<dir of libtensorholo_ffi.so> -cp check.jar:jna.jar MainKt <version> <cases dir>`.
// <cases dir> is written by `python3 bindings/tests/frames.py DIR`: per real frame, the phone buffers
// (color.raw, depth.raw), their layout (case.json) and holo render's SLM patterns of the same scene
// (holo/phase_{r,g,b}.png). Plain `fun main` with checks that throw (no JUnit).

import java.io.File
import java.util.Collections
import javax.imageio.ImageIO
import tensorholo.ColorFormat
import tensorholo.DepthFormat
import tensorholo.GeneratorConfig
import tensorholo.HologramGenerator
import tensorholo.PatternsListener
import tensorholo.RgbdFrame
import tensorholo.Rotation
import tensorholo.SlmPatterns
import tensorholo.TensorholoException
import tensorholo.packRgba
import tensorholo.version

var checks = 0

fun check(condition: Boolean, what: () -> String) {
    if (!condition) throw AssertionError(what())
    checks++
}

inline fun <reified E : Throwable> expectThrows(block: () -> Unit): E {
    try {
        block()
    } catch (e: Throwable) {
        if (e is E) {
            checks++
            return e
        }
        throw AssertionError("expected ${E::class.qualifiedName}, got $e", e)
    }
    throw AssertionError("expected ${E::class.qualifiedName}, nothing was thrown")
}

/** A flat JSON object of strings and numbers (frames.py's case.json), as a map of raw values. */
fun readCase(file: File): Map<String, String> =
    Regex("\"(\\w+)\": *(\"[^\"]*\"|[0-9.eE+-]+)").findAll(file.readText())
        .associate { it.groupValues[1] to it.groupValues[2].trim('"') }

fun frameOf(dir: File, case: Map<String, String>): RgbdFrame = RgbdFrame(
    color = File(dir, "color.raw").readBytes(),
    colorFormat = ColorFormat.valueOf(case.getValue("color_format")),
    colorWidth = case.getValue("color_width").toUInt(),
    colorHeight = case.getValue("color_height").toUInt(),
    depth = File(dir, "depth.raw").readBytes(),
    depthFormat = DepthFormat.valueOf(case.getValue("depth_format")),
    depthWidth = case.getValue("depth_width").toUInt(),
    depthHeight = case.getValue("depth_height").toUInt(),
    colorRowStride = case.getValue("color_row_stride").toUInt(),
    depthRowStride = case.getValue("depth_row_stride").toUInt(),
    rotation = Rotation.valueOf(case.getValue("rotation")),
)

/** Circular code differences (255 and 0 are one code apart) against holo's grey PNG of one laser. */
fun compare(name: String, got: ByteArray, png: File, w: Int, h: Int): Pair<Double, Double> {
    val img = ImageIO.read(png)
    check(img.width == w && img.height == h) { "$name: holo wrote ${img.width}x${img.height}, expected ${w}x$h" }
    var sum = 0L
    var withinOne = 0
    for (y in 0 until h) for (x in 0 until w) {
        val a = got[y * w + x].toInt() and 0xFF
        val b = img.raster.getSample(x, y, 0)
        val d = Math.abs(a - b).let { minOf(it, 256 - it) }
        sum += d
        if (d <= 1) withinOne++
    }
    return Pair(sum.toDouble() / (w * h), withinOne.toDouble() / (w * h))
}

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
}

fun main(args: Array<String>) {
    if (args.size != 2) throw IllegalArgumentException("usage: MainKt <workspace version> <cases dir>")
    check(version() == args[0]) { "version() = ${version()}, workspace says ${args[0]}" }
    val cases = File(args[1]).listFiles { f -> File(f, "case.json").exists() }!!.sortedBy { it.name }
    check(cases.isNotEmpty()) { "no case in ${args[1]}" }
    for (dir in cases) {
        val case = readCase(File(dir, "case.json"))
        val (w, h) = Pair(case.getValue("out_width").toInt(), case.getValue("out_height").toInt())
        val frame = frameOf(dir, case)
        HologramGenerator(GeneratorConfig(width = w.toUInt(), height = h.toUInt())).use { gen ->
            val out = gen.render(frame)
            check(out.width == w.toUInt() && out.height == h.toUInt()) { "${dir.name}: size ${out.width}x${out.height}" }
            for ((plane, laser) in listOf(out.red to "r", out.green to "g", out.blue to "b")) {
                val (mean, within) = compare(dir.name, plane, File(dir, "holo/phase_$laser.png"), w, h)
                println("${dir.name} $laser: vs holo render mean circular difference $mean, within ±1: $within")
                // The tolerance of frames.compare_codes.
                check(mean <= 0.02 && within >= 0.999) { "${dir.name} $laser: $mean, $within" }
            }
            val rgba = packRgba(out)
            check(rgba.size == w * h * 4 && rgba[3] == 255.toByte() && rgba[0] == out.red[0]) { "packRgba" }
            check(gen.info().layers == 8u) { "info: ${gen.info()}" }

            // Bad input: a typed exception, and the generator goes on.
            val short = expectThrows<TensorholoException.InvalidInput> {
                gen.render(frame.copy(depth = frame.depth.copyOf(frame.depth.size - 2)))
            }
            check(short.reason.contains("depth")) { "message names the buffer: ${short.reason}" }
            expectThrows<TensorholoException.InvalidInput> { gen.render(frame.copy(colorWidth = 0u)) }
            expectThrows<TensorholoException.InvalidInput> {
                gen.render(frame.copy(depth = ByteArray(frame.depth.size)))
            }
            check(gen.render(frame).green.contentEquals(out.green)) { "${dir.name}: generator after errors" }

            // A listener implemented in Kotlin, called from the stream's thread in frame order.
            val rec = Recorder()
            gen.stream(rec).use { stream ->
                for (i in 0 until 3) {
                    check(stream.push(frame) == i.toULong()) { "push index" }
                    while (rec.indices.size + rec.errors.size <= i) Thread.sleep(10)
                }
                stream.finish()
                check(rec.indices == listOf(0uL, 1uL, 2uL) && rec.errors.isEmpty()) { "stream: ${rec.indices} ${rec.errors}" }
                check(Thread.currentThread().id !in rec.threads) { "listener ran on the caller's thread" }
                expectThrows<TensorholoException.InvalidInput> { stream.push(frame) }
            }
        }
    }
    expectThrows<TensorholoException.InvalidInput> {
        HologramGenerator(GeneratorConfig(width = 64u, height = 64u, layers = 9u))
    }
    expectThrows<TensorholoException.InvalidInput> {
        HologramGenerator(GeneratorConfig(width = 64u, height = 64u, offsetMm = Double.NaN))
    }
    println("kotlin bindings: $checks checks passed on ${cases.size} real frames")
}
