import CoreVideo
import Foundation

extension ColorFormat {
    /// The colour format of a CoreVideo pixel format: `kCVPixelFormatType_32BGRA` → `.bgra8` (what
    /// `AVCaptureVideoDataOutput` delivers when asked for it), `kCVPixelFormatType_32RGBA` → `.rgba8`,
    /// `kCVPixelFormatType_24RGB` → `.rgb8`. Colour bytes are 8-bit sRGB.
    ///
    /// - Throws: `TensorholoError.InvalidInput` for any other format, e.g. the camera's default
    ///   `kCVPixelFormatType_420YpCbCr8BiPlanarFullRange` (`'420f'`): set the video output's `videoSettings` to
    ///   `[kCVPixelBufferPixelFormatTypeKey as String: kCVPixelFormatType_32BGRA]`, or for ARKit use
    ///   `RgbdFrame(frame:orientation:)`, which converts.
    public init(pixelFormat: OSType) throws {
        switch pixelFormat {
        case kCVPixelFormatType_32BGRA:
            self = .bgra8
        case kCVPixelFormatType_32RGBA:
            self = .rgba8
        case kCVPixelFormatType_24RGB:
            self = .rgb8
        default:
            throw TensorholoError.InvalidInput(
                message: "colour pixel format \(pixelFormatName(pixelFormat)) is not supported: use kCVPixelFormatType_32BGRA "
                    + "(AVCaptureVideoDataOutput.videoSettings = [kCVPixelBufferPixelFormatTypeKey: kCVPixelFormatType_32BGRA])"
            )
        }
    }

    /// Bytes of one pixel: 4 for `.bgra8` and `.rgba8`, 3 for `.rgb8`.
    public var bytesPerPixel: Int {
        switch self {
        case .bgra8, .rgba8:
            return 4
        case .rgb8:
            return 3
        }
    }
}

extension DepthFormat {
    /// The depth format of a CoreVideo pixel format, as `AVDepthData.depthDataMap` and ARKit's
    /// `ARDepthData.depthMap` use them: `kCVPixelFormatType_DepthFloat32` → `.metresF32`, `DepthFloat16` →
    /// `.metresF16`, `DisparityFloat32` → `.disparityF32` (1/m), `DisparityFloat16` → `.disparityF16`.
    ///
    /// - Throws: `TensorholoError.InvalidInput` for any other format (convert first with
    ///   `AVDepthData.converting(toDepthDataType:)`).
    public init(pixelFormat: OSType) throws {
        switch pixelFormat {
        case kCVPixelFormatType_DepthFloat32:
            self = .metresF32
        case kCVPixelFormatType_DepthFloat16:
            self = .metresF16
        case kCVPixelFormatType_DisparityFloat32:
            self = .disparityF32
        case kCVPixelFormatType_DisparityFloat16:
            self = .disparityF16
        default:
            throw TensorholoError.InvalidInput(
                message: "depth pixel format \(pixelFormatName(pixelFormat)) is not supported: use DepthFloat32/16 or "
                    + "DisparityFloat32/16 (AVDepthData.converting(toDepthDataType:))"
            )
        }
    }

    /// Bytes of one sample: 4 for the f32 formats, 2 for the f16 and 16-bit integer ones.
    public var bytesPerSample: Int {
        switch self {
        case .metresF32, .disparityF32:
            return 4
        case .metresF16, .disparityF16, .millimetresU16, .depth16:
            return 2
        }
    }
}

extension RgbdFrame {
    /// One camera frame from two CoreVideo buffers of the same field of view, each copied once with its own
    /// size and row stride (`CVPixelBufferGetBytesPerRow`; nothing is resampled here: the library resizes,
    /// rotates and fills the depth holes).
    ///
    /// - Parameters:
    ///   - colorBuffer: 8-bit sRGB colour, `kCVPixelFormatType_32BGRA` (or `32RGBA`, `24RGB`), non-planar.
    ///   - depthBuffer: depth in metres or disparity in 1/m, `kCVPixelFormatType_DepthFloat32`, `DepthFloat16`,
    ///     `DisparityFloat32` or `DisparityFloat16`, at any resolution (e.g. 640 × 480 beside 1920 × 1440
    ///     colour). Zero, NaN and infinite samples are invalid pixels (filled from the farthest neighbour).
    ///   - rotation: the clockwise rotation that makes both buffers upright (`Rotation(orientation:)`).
    /// - Throws: `TensorholoError.InvalidInput` for an unsupported pixel format (the message says which to use),
    ///   a planar or empty buffer; `TensorholoError.Internal` if a buffer cannot be locked.
    public init(colorBuffer: CVPixelBuffer, depthBuffer: CVPixelBuffer, rotation: Rotation = .deg0) throws {
        let colorFormat = try ColorFormat(pixelFormat: CVPixelBufferGetPixelFormatType(colorBuffer))
        let depthFormat = try DepthFormat(pixelFormat: CVPixelBufferGetPixelFormatType(depthBuffer))
        let color = try PixelBufferCopy(colorBuffer, bytesPerPixel: colorFormat.bytesPerPixel, name: "colour")
        let depth = try PixelBufferCopy(depthBuffer, bytesPerPixel: depthFormat.bytesPerSample, name: "depth")
        self.init(
            color: color.data,
            colorFormat: colorFormat,
            colorWidth: color.width,
            colorHeight: color.height,
            depth: depth.data,
            depthFormat: depthFormat,
            depthWidth: depth.width,
            depthHeight: depth.height,
            colorRowStride: color.rowStride,
            depthRowStride: depth.rowStride,
            rotation: rotation
        )
    }
}
