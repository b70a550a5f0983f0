// Given to the ```kotlin examples of android/README.md (bindings/tests/kotlin/readme_examples.py prepends it):
// what the example takes from the app around it. Log, Bitmap, Frame and NotYetAvailableException are the
// stand-ins of android-stand-ins/ (no android.jar or ARCore on the JVM here).
import android.graphics.Bitmap
import android.util.Log
import com.google.ar.core.Frame
import com.google.ar.core.exceptions.NotYetAvailableException

lateinit var frame: Frame                // the ARCore frame Session.update() returned
val sensorOrientationDegrees = 90        // CameraCharacteristics.SENSOR_ORIENTATION
val displayRotationDegrees = 0           // the display's rotation in degrees
fun showOnSlm(bitmap: Bitmap) {}         // the app's Presentation on the SLM's display
