import CoreGraphics
import Foundation

/// One laser's plane of `SlmPatterns` (field-sequential colour: red, green, blue).
public enum SlmChannel: CaseIterable, Sendable {
    /// The red laser's pattern (`SlmPatterns.red`).
    case red
    /// The green laser's pattern (`SlmPatterns.green`).
    case green
    /// The blue laser's pattern (`SlmPatterns.blue`).
    case blue
}

extension SlmPatterns {
    /// The frame a colour-sequential SLM driver takes over HDMI / an external display, as an image of
    /// `width × height` pixels: the red laser's codes in R, green in G, blue in B (`packRgba(patterns:)`),
    /// 8 bits a component, 32 bits a pixel, alpha ignored (`CGImageAlphaInfo.noneSkipLast`), device RGB.
    ///
    /// Show it at one image pixel per display pixel, without interpolation (`.interpolation(.none)` in SwiftUI,
    /// `magnificationFilter = .nearest` on a layer): code `c` displays phase `2π·c/256`, and any resampling or
    /// colour conversion changes the phase.
    ///
    /// - Throws: `TensorholoError.InvalidInput` if a plane does not hold `width · height` codes.
    public func cgImage() throws -> CGImage {
        let rgba = try packRgba(patterns: self)
        return try makeCGImage(bytes: rgba, width: width, height: height, bytesPerPixel: 4, space: CGColorSpaceCreateDeviceRGB(), name: "SLM frame")
    }

    /// One laser's codes (`red`, `green` or `blue`): `width · height` bytes, row-major.
    public func codes(_ channel: SlmChannel) -> Data {
        switch channel {
        case .red:
            return red
        case .green:
            return green
        case .blue:
            return blue
        }
    }

    /// One laser's pattern as an 8-bit grayscale image of `width × height` pixels (device gray, no alpha), for a
    /// monochrome SLM or to inspect a plane.
    ///
    /// - Throws: `TensorholoError.InvalidInput` if the plane does not hold `width · height` codes.
    public func cgImage(channel: SlmChannel) throws -> CGImage {
        try makeCGImage(
            bytes: codes(channel),
            width: width,
            height: height,
            bytesPerPixel: 1,
            space: CGColorSpaceCreateDeviceGray(),
            name: "\(channel) plane"
        )
    }
}

extension Preview {
    /// The simulated view as an image of `width × height` pixels: the `rgba` bytes, 8-bit sRGB, alpha ignored
    /// (it is 255).
    ///
    /// - Throws: `TensorholoError.InvalidInput` if `rgba` does not hold `width · height · 4` bytes.
    public func cgImage() throws -> CGImage {
        let sRGB = CGColorSpace(name: CGColorSpace.sRGB) ?? CGColorSpaceCreateDeviceRGB()
        return try makeCGImage(bytes: rgba, width: width, height: height, bytesPerPixel: 4, space: sRGB, name: "preview")
    }
}

/// An image over `bytes`: `height` packed rows of `width` pixels of `bytesPerPixel` 8-bit components (4: RGBX,
/// alpha ignored; 1: gray). Throws `TensorholoError.InvalidInput` when the byte count does not match or the size
/// is zero or overflows, `TensorholoError.Internal` if Core Graphics refuses the image.
func makeCGImage(bytes: Data, width: UInt32, height: UInt32, bytesPerPixel: Int, space: CGColorSpace, name: String) throws -> CGImage {
    let w = Int(width)
    let h = Int(height)
    let (rowBytes, rowOverflow) = w.multipliedReportingOverflow(by: bytesPerPixel)
    let (count, countOverflow) = rowBytes.multipliedReportingOverflow(by: h)
    guard w > 0, h > 0, !rowOverflow, !countOverflow, bytes.count == count else {
        throw TensorholoError.InvalidInput(
            message: "\(name) holds \(bytes.count) bytes, expected \(width) x \(height) pixels x \(bytesPerPixel) bytes"
        )
    }
    let alpha: CGImageAlphaInfo = bytesPerPixel == 4 ? .noneSkipLast : .none
    guard let provider = CGDataProvider(data: bytes as CFData),
          let image = CGImage(
              width: w,
              height: h,
              bitsPerComponent: 8,
              bitsPerPixel: 8 * bytesPerPixel,
              bytesPerRow: rowBytes,
              space: space,
              bitmapInfo: CGBitmapInfo(rawValue: alpha.rawValue),
              provider: provider,
              decode: nil,
              shouldInterpolate: false,
              intent: .defaultIntent
          )
    else {
        throw TensorholoError.Internal(message: "Core Graphics cannot make a \(w) x \(h) image of the \(name)")
    }
    return image
}
