// Stand-in (see android.graphics.kt): the ARCore exception android/README.md's example catches.
package com.google.ar.core.exceptions

class NotYetAvailableException : RuntimeException()
