// ARCore Frame → registered RgbdFrame. ARCore is a compileOnly dependency of the library: this file's class
// (ArCoreFrames) is loaded only when an app calls fromArFrame, and such an app has ARCore itself. The maths
// (CameraPlanes.cropForTexture, depthFormatOf) is plain JVM code covered by the JVM tests.
@file:JvmName("ArCoreFrames")

package tensorholo.android

import com.google.ar.core.Coordinates2d
import com.google.ar.core.Frame
import tensorholo.RgbdFrame
import tensorholo.Rotation

/**
 * The registered RGB-D frame of an ARCore `Frame` (Depth API enabled: `Config.DepthMode.AUTOMATIC`):
 * `acquireCameraImage()` (the CPU image, `YUV_420_888`, e.g. 640 × 480) and `acquireDepthImage16Bits()`
 * (`HardwareBuffer.D_16` millimetres), both closed before this returns.
 *
 * Registration: ARCore's depth image covers the field of view of the GPU camera texture (usually 16:9), not
 * that of the CPU image (usually 4:3). The texture's corners are mapped into CPU image pixels with
 * `frame.transformCoordinates2d(TEXTURE_NORMALIZED → IMAGE_PIXELS)` and the bounding box becomes the frame's
 * `colorCrop` ([CameraPlanes.cropForTexture]; e.g. rows 60..420 of 640 × 480): the library crops the colour
 * to it before rotating, so that an edge falls on the same pixel in colour and depth. Without it, depth
 * would be stretched over the whole CPU image, up to ~12 % of the height off near the top and bottom.
 *
 * Call it on the thread that called `Session.update()` (ARCore's GL thread), after tracking started.
 * Kotlin: `RgbdFrames.fromArFrame(frame, rotation)`; Java: `ArCoreFrames.fromArFrame(RgbdFrames.INSTANCE,
 * frame, rotation)`.
 *
 * @param frame the frame `Session.update()` returned.
 * @param rotation clockwise rotation making the sensor-oriented images upright ([CameraPlanes.rotationFor]).
 * @param rgbaOut optional reusable colour array, as in [RgbdFrames.fromImages].
 * @param rawDepth read ARCore's raw depth (`acquireRawDepthImage16Bits`, unsmoothed, with holes) and its
 *   confidence (`acquireRawDepthConfidenceImage`, 0–255) instead of the smoothed depth: samples below
 *   `minConfidence` are invalid, filled from their confident neighbours (never read as near).
 * @param minConfidence with `rawDepth`: the lowest confidence kept, 0–255 (default 128).
 * @throws com.google.ar.core.exceptions.NotYetAvailableException when this frame has no camera image or no
 *   depth yet (common for the first frames): skip the frame.
 * @throws com.google.ar.core.exceptions.DeadlineExceededException when the frame is too old to acquire its
 *   images (called after the next `update()`): skip it.
 * @throws com.google.ar.core.exceptions.ResourceExhaustedException when the app holds too many ARCore images
 *   (it must close them): skip the frame and close what it holds.
 * @throws IllegalArgumentException when the images have unexpected formats or layouts, or the texture's field
 *   of view is not inside the CPU image (see [CameraPlanes.cropForTexture]).
 */
@JvmOverloads
fun RgbdFrames.fromArFrame(
    frame: Frame,
    rotation: Rotation,
    rgbaOut: ByteArray? = null,
    rawDepth: Boolean = false,
    minConfidence: Int = 128,
): RgbdFrame {
    require(minConfidence in 0..255) { "minConfidence is 0 to 255, got $minConfidence" }
    val imageCorners = FloatArray(8)
    frame.transformCoordinates2d(
        Coordinates2d.TEXTURE_NORMALIZED,
        CameraPlanes.textureCorners(),
        Coordinates2d.IMAGE_PIXELS,
        imageCorners,
    )
    return frame.acquireCameraImage().use { color ->
        val crop = CameraPlanes.cropForTexture(imageCorners, color.width, color.height)
        if (!rawDepth) {
            frame.acquireDepthImage16Bits().use { depth -> fromImages(color, depth, rotation, rgbaOut, crop) }
        } else {
            frame.acquireRawDepthImage16Bits().use { depth ->
                frame.acquireRawDepthConfidenceImage().use { confidence ->
                    val plane = confidence.planes.single()
                    require(confidence.width == depth.width && confidence.height == depth.height) {
                        "raw depth ${depth.width}x${depth.height} and its confidence " +
                            "${confidence.width}x${confidence.height} differ in size"
                    }
                    val bytes = CameraPlanes.bytes8Packed(
                        plane.buffer, confidence.width, confidence.height, plane.rowStride,
                    )
                    fromImages(color, depth, rotation, rgbaOut, crop).copy(
                        confidence = bytes,
                        minConfidence = minConfidence.toUByte(),
                    )
                }
            }
        }
    }
}
