// Checks of the generated Kotlin bindings (package tensorholo) on the JVM, run by check.sh:
// `java -Djna.library.path=<dir of libtensorholo_ffi.so> -cp check.jar:jna.jar MainKt <workspace version>`.
// Plain `fun main` with checks that throw (no JUnit). The demo items (Echo, Bytes8Demo, DemoListener,
// demoPanic) are placeholders proving the FFI paths; replace these checks together with them.

import java.util.Collections
import tensorholo.Bytes8Demo
import tensorholo.DemoListener
import tensorholo.Echo
import tensorholo.TensorholoException
import tensorholo.demoPanic
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

class Recorder : DemoListener {
    val indices: MutableList<ULong> = Collections.synchronizedList(mutableListOf())
    val values: MutableList<Bytes8Demo> = Collections.synchronizedList(mutableListOf())
    val threads: MutableSet<Long> = Collections.synchronizedSet(mutableSetOf())
    val errors: MutableList<TensorholoException> = Collections.synchronizedList(mutableListOf())
    var failAt: ULong? = null

    override fun onValue(index: ULong, value: Bytes8Demo) {
        threads.add(Thread.currentThread().id)
        indices.add(index)
        values.add(value)
        if (index == failAt) throw IllegalStateException("listener broke at $index")
    }

    override fun onError(error: TensorholoException) {
        errors.add(error)
    }
}

fun littleEndian(i: ULong): ByteArray = ByteArray(8) { k -> (i shr (8 * k)).toByte() }

fun main(args: Array<String>) {
    val expectedVersion = args.getOrNull(0) ?: throw IllegalArgumentException("usage: MainKt <workspace version>")
    check(version() == expectedVersion) { "version() = ${version()}, workspace says $expectedVersion" }

    Echo(1000uL).use { echo ->
        // Byte round trip: random bytes come back as their negative, and twice as themselves.
        val rnd = java.util.Random(7)
        val data = ByteArray(35).also { rnd.nextBytes(it) }
        val out = echo.invert(Bytes8Demo(7u, 5u, data))
        check(out.width == 7u && out.height == 5u) { "size ${out.width} x ${out.height}" }
        for (i in data.indices) {
            val a = data[i].toInt() and 0xff
            val b = out.data[i].toInt() and 0xff
            check(a + b == 255) { "byte $i: $a and $b do not add up to 255" }
        }
        check(echo.invert(out).data.contentEquals(data)) { "inverting twice is not the identity" }
        // Every byte value crosses unchanged (signed Kotlin bytes included).
        val all = ByteArray(256) { it.toByte() }
        val inv = echo.invert(Bytes8Demo(16u, 16u, all)).data
        check(inv.contentEquals(ByteArray(256) { (255 - it).toByte() })) { "0..255 not inverted" }

        // Errors arrive as the typed exception with the Rust message.
        val e = expectThrows<TensorholoException.InvalidInput> { echo.invert(Bytes8Demo(3u, 2u, ByteArray(5))) }
        check(e.reason.contains("5 bytes")) { "reason: ${e.reason}" }
        // Caught as the sealed base class: the variant is still the specific one.
        val big = expectThrows<TensorholoException> { echo.invert(Bytes8Demo(40u, 30u, ByteArray(1200))) }
        check(big is TensorholoException.InvalidInput && big.reason.contains("at most 1000")) { "unexpected $big" }
    }
    val ctor = expectThrows<TensorholoException.InvalidInput> { Echo(0uL) }
    check(ctor.reason.contains("max_pixels")) { "reason: ${ctor.reason}" }

    // A Rust panic comes back as Internal, and the library stays usable.
    val panic = expectThrows<TensorholoException.Internal> { demoPanic("boom") }
    check(panic.reason.contains("panicked: boom")) { "reason: ${panic.reason}" }
    check(version() == expectedVersion) { "library unusable after a panic" }

    // A listener implemented in Kotlin, called from a Rust thread, in order.
    Echo(1uL).use { echo ->
        val n = 500
        val rec = Recorder()
        echo.stream(rec, n.toULong(), true)
        check(rec.indices == (0 until n).map { it.toULong() }) { "indices ${rec.indices.take(10)}…" }
        for ((i, v) in rec.values.withIndex()) {
            check(v.width == 8u && v.height == 1u && v.data.contentEquals(littleEndian(i.toULong()))) {
                "value $i: $v"
            }
        }
        // JNA attaches the Rust thread to the JVM anew for each call, so the Java thread ids differ from call to
        // call; what matters is that none is the caller's.
        check(rec.threads.isNotEmpty() && Thread.currentThread().id !in rec.threads) {
            "called from threads ${rec.threads.take(5)}…, caller is ${Thread.currentThread().id}"
        }
        check(rec.errors.size == 1) { "errors ${rec.errors}" }
        val err = rec.errors[0]
        check(err is TensorholoException.InvalidInput && err.reason.contains("after $n values")) { "error $err" }

        val quiet = Recorder()
        echo.stream(quiet, 0uL, false)
        check(quiet.indices.isEmpty() && quiet.errors.isEmpty()) { "calls without values" }

        // An exception thrown by the listener stops the stream and comes back as Internal.
        val failing = Recorder().apply { failAt = 2uL }
        expectThrows<TensorholoException.Internal> { echo.stream(failing, 10uL, true) }
        check(failing.indices == listOf(0uL, 1uL, 2uL) && failing.errors.isEmpty()) {
            "after a listener exception: ${failing.indices}, ${failing.errors}"
        }
    }

    println("kotlin bindings: $checks checks passed")
}
