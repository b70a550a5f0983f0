import CoreVideo
import Foundation

/// The bytes of one plane of a non-planar `CVPixelBuffer`, as `RgbdFrame` takes them: `height` rows of `width`
/// pixels, row `y` starting at byte `y · rowStride` (the buffer's `CVPixelBufferGetBytesPerRow`, padding kept).
///
/// Internal to the Swift layer; built by `PixelBufferCopy.init(_:bytesPerPixel:name:)`.
struct PixelBufferCopy {
    /// `rowStride · (height − 1) + width · bytesPerPixel` bytes: every row with its padding except the last
    /// row's padding, which a buffer need not have (the length rule of `RgbdFrame`).
    let data: Data
    /// Pixels per row.
    let width: UInt32
    /// Rows.
    let height: UInt32
    /// Bytes from the start of one row to the next (`CVPixelBufferGetBytesPerRow`).
    let rowStride: UInt32

    /// Copies the pixels of `buffer` (locked read-only for the copy, unlocked after it) in one block, keeping
    /// its row stride.
    ///
    /// - Parameters:
    ///   - buffer: a non-planar pixel buffer of `bytesPerPixel` bytes a pixel.
    ///   - bytesPerPixel: bytes of one pixel of the buffer's pixel format (4 for BGRA8, 4 for f32 depth…).
    ///   - name: what the buffer is (`"colour"`, `"depth"`), for the error messages.
    /// - Throws: `TensorholoError.InvalidInput` for a planar buffer, a zero size, a row stride shorter than a
    ///   row, or sizes that overflow `UInt32`/`Int`; `TensorholoError.Internal` if CoreVideo cannot lock the
    ///   buffer or gives no base address.
    init(_ buffer: CVPixelBuffer, bytesPerPixel: Int, name: String) throws {
        let format = CVPixelBufferGetPixelFormatType(buffer)
        guard !CVPixelBufferIsPlanar(buffer) else {
            throw TensorholoError.InvalidInput(
                message: "\(name) pixel buffer: planar format \(pixelFormatName(format)) is not supported"
            )
        }
        let width = CVPixelBufferGetWidth(buffer)
        let height = CVPixelBufferGetHeight(buffer)
        let bytesPerRow = CVPixelBufferGetBytesPerRow(buffer)
        guard width > 0, height > 0 else {
            throw TensorholoError.InvalidInput(
                message: "\(name) pixel buffer has size \(width) x \(height); it must not be empty"
            )
        }
        let (row, rowOverflow) = width.multipliedReportingOverflow(by: bytesPerPixel)
        guard !rowOverflow, bytesPerRow >= row else {
            throw TensorholoError.InvalidInput(
                message: "\(name) pixel buffer: \(bytesPerRow) bytes per row is shorter than \(width) pixels x \(bytesPerPixel) bytes"
            )
        }
        let (rows, rowsOverflow) = bytesPerRow.multipliedReportingOverflow(by: height - 1)
        let (count, countOverflow) = rows.addingReportingOverflow(row)
        guard !rowsOverflow, !countOverflow,
              let width32 = UInt32(exactly: width),
              let height32 = UInt32(exactly: height),
              let stride32 = UInt32(exactly: bytesPerRow)
        else {
            throw TensorholoError.InvalidInput(
                message: "\(name) pixel buffer of \(width) x \(height) pixels, \(bytesPerRow) bytes per row, is too large"
            )
        }

        let locked = CVPixelBufferLockBaseAddress(buffer, .readOnly)
        guard locked == kCVReturnSuccess else {
            throw TensorholoError.Internal(
                message: "\(name) pixel buffer: CVPixelBufferLockBaseAddress failed (CVReturn \(locked))"
            )
        }
        defer { CVPixelBufferUnlockBaseAddress(buffer, .readOnly) }
        guard let base = CVPixelBufferGetBaseAddress(buffer) else {
            throw TensorholoError.Internal(message: "\(name) pixel buffer has no base address")
        }
        data = Data(bytes: base, count: count)
        self.width = width32
        self.height = height32
        rowStride = stride32
    }
}

/// A CoreVideo pixel format as text: its four-character code (`'BGRA'`, `'420f'`, `'fdep'`) when printable,
/// else hexadecimal (`0x00000018`).
func pixelFormatName(_ format: OSType) -> String {
    let bytes: [UInt8] = [24, 16, 8, 0].map { UInt8(truncatingIfNeeded: format >> $0) }
    if bytes.allSatisfy({ $0 >= 0x20 && $0 < 0x7F }) {
        return "'" + String(decoding: bytes, as: UTF8.self) + "'"
    }
    return String(format: "0x%08x", format)
}
