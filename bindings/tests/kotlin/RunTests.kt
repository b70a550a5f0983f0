// The JUnit 4 runner of check.sh (Gradle has its own): runs the given test classes with JUnitCore, prints one
// line per test (PASS / FAIL / SKIP with its reason, seconds) and the counts, and exits non-zero on a
// failure, or, with --strict (CI), on a skipped test too, so a missing system property cannot pass silently.
//
//   java -cp check.jar:jna.jar:junit4.jar:hamcrest.jar RunTestsKt [--strict] CLASS...

import kotlin.system.exitProcess
import org.junit.runner.Description
import org.junit.runner.JUnitCore
import org.junit.runner.notification.Failure
import org.junit.runner.notification.RunListener

private class LineListener : RunListener() {
    private var start = 0L
    private var outcome: String? = null

    override fun testStarted(description: Description) {
        start = System.nanoTime()
        outcome = null
    }

    override fun testFailure(failure: Failure) {
        outcome = "FAIL"
    }

    override fun testAssumptionFailure(failure: Failure) {
        outcome = "SKIP (${failure.message})"
    }

    override fun testFinished(description: Description) {
        val seconds = (System.nanoTime() - start) / 1e9
        val o = outcome ?: "PASS"
        val (tag, why) = if (o.startsWith("SKIP")) "SKIP" to "  " + o.removePrefix("SKIP ") else o to ""
        println("%-4s %s.%s  %.1f s%s".format(tag, description.testClass.simpleName, description.methodName, seconds, why))
    }
}

fun main(args: Array<String>) {
    val strict = args.firstOrNull() == "--strict"
    val names = if (strict) args.drop(1) else args.toList()
    if (names.isEmpty()) {
        System.err.println("usage: RunTestsKt [--strict] CLASS...")
        exitProcess(2)
    }
    val core = JUnitCore()
    core.addListener(LineListener())
    val result = core.run(*names.map { Class.forName(it) }.toTypedArray())
    for (f in result.failures) {
        println("\nFAILED ${f.testHeader}\n${f.trace}")
    }
    val skipped = result.assumptionFailureCount
    println(
        "kotlin tests: ${result.runCount} run, ${result.runCount - result.failureCount - skipped} passed, " +
            "${result.failureCount} failed, $skipped skipped (${names.size} classes, %.1f s)".format(result.runTime / 1e3),
    )
    if (result.failureCount > 0) exitProcess(1)
    if (strict && skipped > 0) {
        println("kotlin tests: --strict and $skipped tests skipped")
        exitProcess(1)
    }
}
