// Stand-in (see android.graphics.kt): android.util.Log, as android/README.md's example uses it.
package android.util

object Log {
    @JvmStatic
    fun w(tag: String, msg: String): Int = TODO("stand-in")
}
