// android.media.Image → RgbdFrame (needs android.jar; the work is done by CameraPlanes, tested on the JVM).

package tensorholo.android

import android.graphics.ImageFormat
import android.media.Image
import tensorholo.CropRect
import tensorholo.DepthFormat
import tensorholo.RgbdFrame
import tensorholo.Rotation

/** [RgbdFrame]s from the `android.media.Image`s that Camera2 and ARCore deliver. */
object RgbdFrames {
    /**
     * Builds a frame from a colour image and a depth image of the same moment: a Camera2 YUV stream + a
     * `DEPTH16` stream, or ARCore's `Frame.acquireCameraImage()` + `Frame.acquireDepthImage16Bits()` (for
     * ARCore prefer [fromArFrame], which also registers the two: ARCore's depth covers only a band of the
     * CPU image). The colour is converted to RGBA8 ([CameraPlanes.yuv420ToRgba], BT.601 full range) and the
     * depth rows copied ([CameraPlanes.depth16Packed]), so both images may be closed as soon as this returns
     * (do: ARCore limits the images held at once). Both are read in the sensor's orientation; `rotation`
     * turns them upright ([CameraPlanes.rotationFor]). The image crop rectangle (`Image.getCropRect()`) is
     * ignored (camera CPU images are uncropped).
     *
     * The depth samples are read as the depth image's format says ([CameraPlanes.depthFormatOf]):
     * `HardwareBuffer.D_16` (ARCore 16-bit depth) as millimetres, `ImageFormat.DEPTH16` (Camera2, ARCore's
     * deprecated 13-bit depth) as 13 bits of millimetres + 3 bits of confidence.
     *
     * Cost: one pass over the colour pixels (`width · height`), on the calling thread; for ARCore's 640 × 480
     * CPU image a few milliseconds. Call it where the images are acquired and hand the frame to a
     * `HologramStream` (`push` never blocks).
     *
     * @param color an open `ImageFormat.YUV_420_888` image (3 planes).
     * @param depth an open 16-bit depth image (1 plane, pixel stride 2), any resolution (ARCore's is lower
     *   than the colour's).
     * @param rotation clockwise rotation making both images upright.
     * @param rgbaOut optional `width · height · 4` byte array to convert the colour into (see
     *   [CameraPlanes.yuv420ToRgba]); the returned frame holds it, so reuse it only after that frame was
     *   rendered or pushed (the bindings copy the bytes during the call).
     * @param colorCrop the rectangle of the colour image (pixels, sensor orientation) that the depth covers,
     *   or null when both cover the same field of view.
     * @throws IllegalArgumentException when an image has another format, an unexpected plane layout or
     *   buffers shorter than its size needs, or `colorCrop` is empty or outside the colour image.
     * @throws IllegalStateException when an image was already closed (from `Image.getPlanes()`).
     */
    @JvmStatic
    @JvmOverloads
    fun fromImages(
        color: Image,
        depth: Image,
        rotation: Rotation,
        rgbaOut: ByteArray? = null,
        colorCrop: CropRect? = null,
    ): RgbdFrame = convert(color, depth, rotation, CameraPlanes.depthFormatOf(depth.format), rgbaOut, colorCrop)

    /**
     * As [fromImages] with the depth format given by the caller; it must be the one the depth image's
     * format implies ([CameraPlanes.depthFormatOf]), else this throws instead of reading the samples
     * wrongly (a D_16 image read as DEPTH16 wraps every depth past 8.191 m to a near value).
     *
     * @throws IllegalArgumentException as [fromImages], and when `depthFormat` differs from the format the
     *   image's `Image.getFormat()` implies.
     */
    @Deprecated(
        "the depth format is taken from Image.getFormat(); drop the depthFormat argument",
        ReplaceWith("RgbdFrames.fromImages(color, depth, rotation, rgbaOut)"),
    )
    @JvmStatic
    @JvmOverloads
    fun fromImages(
        color: Image,
        depth: Image,
        rotation: Rotation,
        depthFormat: DepthFormat,
        rgbaOut: ByteArray? = null,
    ): RgbdFrame {
        val implied = CameraPlanes.depthFormatOf(depth.format)
        require(depthFormat == implied) {
            "depthFormat $depthFormat does not match the depth image's format ${depth.format}, which holds " +
                "$implied samples: call fromImages without depthFormat"
        }
        return convert(color, depth, rotation, implied, rgbaOut, null)
    }

    private fun convert(
        color: Image,
        depth: Image,
        rotation: Rotation,
        depthFormat: DepthFormat,
        rgbaOut: ByteArray?,
        colorCrop: CropRect?,
    ): RgbdFrame {
        require(color.format == ImageFormat.YUV_420_888) {
            "colour image format is ${color.format}, expected YUV_420_888 (${ImageFormat.YUV_420_888})"
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
            rgba, color.width, color.height, d[0].buffer, depth.width, depth.height, d[0].rowStride, depthFormat,
            rotation, colorCrop,
        )
    }
}
