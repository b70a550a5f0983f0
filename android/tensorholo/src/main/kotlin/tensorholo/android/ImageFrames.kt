// android.media.Image → RgbdFrame (needs android.jar; the work is done by CameraPlanes, tested on the JVM).

package tensorholo.android

import android.graphics.ImageFormat
import android.media.Image
import tensorholo.DepthFormat
import tensorholo.RgbdFrame
import tensorholo.Rotation

/** [RgbdFrame]s from the `android.media.Image`s that Camera2 and ARCore deliver. */
object RgbdFrames {
    /** `HardwareBuffer.D_16` (API 28; the value, so minSdk 26 needs no API check). */
    private const val HARDWARE_BUFFER_D_16 = 0x30

    /**
     * Builds a frame from a colour image and a depth image of the same moment and field of view: ARCore
     * `Frame.acquireCameraImage()` + `Frame.acquireDepthImage16Bits()`, or a Camera2 YUV stream + a
     * `DEPTH16` stream. The colour is converted to RGBA8 ([CameraPlanes.yuv420ToRgba], BT.601 full range)
     * and the depth rows copied ([CameraPlanes.depth16Packed]), so both images may be closed as soon as this
     * returns (do: ARCore limits the images held at once). Both are read in the sensor's orientation;
     * `rotation` turns them upright ([CameraPlanes.rotationFor]). The image crop rectangle is ignored
     * (camera CPU images are uncropped).
     *
     * Cost: one pass over the colour pixels (`width · height`), on the calling thread; for ARCore's 640 × 480
     * CPU image a few milliseconds. Call it where the images are acquired and hand the frame to a
     * `HologramStream` (`push` never blocks).
     *
     * @param color an open `ImageFormat.YUV_420_888` image (3 planes).
     * @param depth an open 16-bit depth image (1 plane, pixel stride 2): `ImageFormat.DEPTH16` (Camera2) or
     *   `HardwareBuffer.D_16` (ARCore 16-bit depth), any resolution (ARCore's is lower than the colour's).
     * @param rotation clockwise rotation making both images upright.
     * @param depthFormat how to read the depth samples: [DepthFormat.MILLIMETRES_U16] for ARCore
     *   `acquireDepthImage16Bits` (all 16 bits are millimetres), [DepthFormat.DEPTH16] for Camera2 `DEPTH16`
     *   (13 bits of millimetres + 3 bits of confidence). The image format alone cannot tell: ARCore's
     *   deprecated `acquireDepthImage` also reports `DEPTH16`.
     * @param rgbaOut optional `width · height · 4` byte array to convert the colour into (see
     *   [CameraPlanes.yuv420ToRgba]); the returned frame holds it, so reuse it only after that frame was
     *   rendered or pushed (the bindings copy the bytes during the call).
     * @throws IllegalArgumentException when an image has another format, an unexpected plane layout or
     *   buffers shorter than its size needs, or `depthFormat` is not a 16-bit format.
     * @throws IllegalStateException when an image was already closed (from `Image.getPlanes()`).
     */
    @JvmStatic
    @JvmOverloads
    fun fromImages(
        color: Image,
        depth: Image,
        rotation: Rotation,
        depthFormat: DepthFormat,
        rgbaOut: ByteArray? = null,
    ): RgbdFrame {
        require(color.format == ImageFormat.YUV_420_888) {
            "colour image format is ${color.format}, expected YUV_420_888 (${ImageFormat.YUV_420_888})"
        }
        require(depth.format == ImageFormat.DEPTH16 || depth.format == HARDWARE_BUFFER_D_16) {
            "depth image format is ${depth.format}, expected DEPTH16 (${ImageFormat.DEPTH16}) or " +
                "HardwareBuffer.D_16 ($HARDWARE_BUFFER_D_16)"
        }
        val planes = color.planes
        require(planes.size == 3) { "a YUV_420_888 image has 3 planes, this one ${planes.size}" }
        val (y, u, v) = planes
        require(y.pixelStride == 1) { "Y pixel stride is ${y.pixelStride}, expected 1" }
        require(u.rowStride == v.rowStride && u.pixelStride == v.pixelStride) {
            "U and V planes differ: row strides ${u.rowStride}/${v.rowStride}, pixel strides " +
                "${u.pixelStride}/${v.pixelStride}"
        }
        val rgba = CameraPlanes.yuv420ToRgba(
            color.width, color.height, y.buffer, y.rowStride, u.buffer, v.buffer, u.rowStride, u.pixelStride, rgbaOut,
        )
        val d = depth.planes
        require(d.size == 1 && d[0].pixelStride == 2) {
            "a 16-bit depth image has 1 plane of pixel stride 2, this one ${d.size} planes" +
                (d.firstOrNull()?.let { ", pixel stride ${it.pixelStride}" } ?: "")
        }
        return CameraPlanes.rgbdFrame(
            rgba, color.width, color.height, d[0].buffer, depth.width, depth.height, d[0].rowStride, depthFormat, rotation,
        )
    }
}
