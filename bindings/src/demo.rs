//! Placeholder surface (to be deleted once the real API is exported): proves, in every generated
//! language, that byte buffers, records, objects, errors and callbacks from a Rust thread cross the FFI
//! (`bindings/tests/`).

use std::sync::Arc;

use crate::{guard, panic_message, TensorholoError};

/// Most values [`Echo::stream`] sends in one call (it runs on the caller's time).
const MAX_STREAM_COUNT: u64 = 1 << 20;

/// An 8-bit single-channel image, row-major: pixel `(x, y)` is `data[y * width + x]`, `data.len() ==
/// width * height`. Crosses as Python `bytes`, Kotlin `ByteArray`, Swift `Data`.
#[derive(Debug, Clone, PartialEq, Eq, uniffi::Record)]
pub struct Bytes8Demo {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The pixels, row-major, `width * height` bytes.
    pub data: Vec<u8>,
}

impl Bytes8Demo {
    /// Pixel count `width * height` after checking that `data` holds exactly that many bytes.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] if the product overflows or `data.len()` differs.
    fn checked_len(&self) -> Result<usize, TensorholoError> {
        let pixels = usize::try_from(self.width)
            .ok()
            .zip(usize::try_from(self.height).ok())
            .and_then(|(w, h)| w.checked_mul(h))
            .ok_or_else(|| TensorholoError::InvalidInput {
                message: format!(
                    "image size {} x {} overflows the address space",
                    self.width, self.height
                ),
            })?;
        if self.data.len() != pixels {
            return Err(TensorholoError::InvalidInput {
                message: format!(
                    "image data has {} bytes, expected width * height = {} * {} = {pixels}",
                    self.data.len(),
                    self.width,
                    self.height
                ),
            });
        }
        Ok(pixels)
    }
}

/// Receives the values of [`Echo::stream`], implemented in the foreign language. Its methods are called
/// from a Rust thread that is not the caller's, one call at a time, in order.
#[uniffi::export(with_foreign)]
pub trait DemoListener: Send + Sync {
    /// The `index`-th value (0-based): an 8 x 1 image whose bytes are `index` in little-endian order.
    fn on_value(&self, index: u64, value: Bytes8Demo);
    /// Called once after the values when the stream was asked to end with an error.
    fn on_error(&self, error: TensorholoError);
}

/// A stateless demo object with a fallible constructor and a size limit.
#[derive(Debug, uniffi::Object)]
pub struct Echo {
    /// Largest image [`Echo::invert`] accepts, in pixels (> 0).
    max_pixels: u64,
}

#[uniffi::export]
impl Echo {
    /// An echo accepting images of at most `max_pixels` pixels.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] if `max_pixels` is 0.
    #[uniffi::constructor]
    pub fn new(max_pixels: u64) -> Result<Arc<Self>, TensorholoError> {
        guard(|| {
            if max_pixels == 0 {
                return Err(TensorholoError::InvalidInput {
                    message: "max_pixels must be > 0".into(),
                });
            }
            Ok(Arc::new(Self { max_pixels }))
        })
    }

    /// The photographic negative of `image`: every byte `v` becomes `255 - v`, same size.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] if `data.len() != width * height` or the image has more
    /// than `max_pixels` pixels.
    pub fn invert(&self, image: Bytes8Demo) -> Result<Bytes8Demo, TensorholoError> {
        guard(|| {
            let pixels = image.checked_len()?;
            if u64::try_from(pixels).map_or(true, |p| p > self.max_pixels) {
                return Err(TensorholoError::InvalidInput {
                    message: format!(
                        "image has {pixels} pixels, this Echo accepts at most {}",
                        self.max_pixels
                    ),
                });
            }
            Ok(Bytes8Demo {
                data: image.data.iter().map(|v| 255 - v).collect(),
                ..image
            })
        })
    }

    /// Sends `count` values to `listener` from a newly spawned Rust thread, in order (`on_value(i, …)` for
    /// `i = 0..count`), then `on_error(InvalidInput)` once if `then_error`; returns when that thread is done.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] if `count` > 2^20; [`TensorholoError::Internal`] if the
    /// thread cannot be started or a listener call failed (raised an exception: uniffi turns it into a panic
    /// of that thread).
    pub fn stream(
        &self,
        listener: Arc<dyn DemoListener>,
        count: u64,
        then_error: bool,
    ) -> Result<(), TensorholoError> {
        guard(|| {
            if count > MAX_STREAM_COUNT {
                return Err(TensorholoError::InvalidInput {
                    message: format!("count {count} exceeds {MAX_STREAM_COUNT}"),
                });
            }
            let worker = std::thread::Builder::new()
                .name("tensorholo-demo-stream".into())
                .spawn(move || {
                    for index in 0..count {
                        listener.on_value(
                            index,
                            Bytes8Demo {
                                width: 8,
                                height: 1,
                                data: index.to_le_bytes().to_vec(),
                            },
                        );
                    }
                    if then_error {
                        listener.on_error(TensorholoError::InvalidInput {
                            message: format!("demo error after {count} values"),
                        });
                    }
                })
                .map_err(|e| TensorholoError::Internal {
                    message: format!("cannot start the stream thread: {e}"),
                })?;
            worker.join().map_err(|payload| TensorholoError::Internal {
                message: format!(
                    "the stream thread stopped: {}",
                    panic_message(payload.as_ref())
                ),
            })
        })
    }
}

/// Panics with `message` inside [`guard`]: proves that a bug comes back as
/// [`TensorholoError::Internal`] in the foreign language, not as an untyped error or a crash.
///
/// Errors: always [`TensorholoError::Internal`].
#[uniffi::export]
pub fn demo_panic(message: String) -> Result<(), TensorholoError> {
    guard(|| panic!("{message}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    fn image(width: u32, height: u32, data: Vec<u8>) -> Bytes8Demo {
        Bytes8Demo {
            width,
            height,
            data,
        }
    }

    #[test]
    fn invert_is_the_negative_and_an_involution() {
        let echo = Echo::new(100).unwrap();
        let data: Vec<u8> = (0..12u8).map(|i| i.wrapping_mul(37)).collect();
        let inv = echo.invert(image(4, 3, data.clone())).unwrap();
        assert_eq!((inv.width, inv.height), (4, 3));
        for (a, b) in data.iter().zip(&inv.data) {
            assert_eq!(u16::from(*a) + u16::from(*b), 255);
        }
        assert_eq!(echo.invert(inv).unwrap().data, data);
    }

    #[test]
    fn invert_refuses_wrong_sizes() {
        let echo = Echo::new(10).unwrap();
        let short = echo.invert(image(3, 2, vec![0; 5]));
        assert!(
            matches!(&short, Err(TensorholoError::InvalidInput { message }) if message.contains("5 bytes")),
            "{short:?}"
        );
        let big = echo.invert(image(4, 3, vec![0; 12]));
        assert!(
            matches!(&big, Err(TensorholoError::InvalidInput { message }) if message.contains("at most 10")),
            "{big:?}"
        );
        // u32::MAX² does not fit a 32-bit usize; on 64-bit it is simply not the data length.
        let huge = echo.invert(image(u32::MAX, u32::MAX, vec![]));
        assert!(
            matches!(huge, Err(TensorholoError::InvalidInput { .. })),
            "{huge:?}"
        );
        assert!(matches!(
            Echo::new(0),
            Err(TensorholoError::InvalidInput { .. })
        ));
    }

    #[derive(Default)]
    struct Recorder {
        values: Mutex<Vec<(u64, Bytes8Demo, std::thread::ThreadId)>>,
        errors: Mutex<Vec<TensorholoError>>,
    }

    impl DemoListener for Recorder {
        fn on_value(&self, index: u64, value: Bytes8Demo) {
            let me = std::thread::current().id();
            self.values.lock().unwrap().push((index, value, me));
        }
        fn on_error(&self, error: TensorholoError) {
            self.errors.lock().unwrap().push(error);
        }
    }

    #[test]
    fn stream_calls_in_order_from_another_thread() {
        let echo = Echo::new(1).unwrap();
        let rec = Arc::new(Recorder::default());
        echo.stream(rec.clone(), 300, true).unwrap();
        let values = rec.values.lock().unwrap();
        assert_eq!(values.len(), 300);
        let caller = std::thread::current().id();
        for (i, (index, value, thread)) in values.iter().enumerate() {
            assert_eq!(*index, i as u64);
            assert_eq!(value.data, (i as u64).to_le_bytes());
            assert_ne!(*thread, caller);
        }
        let errors = rec.errors.lock().unwrap();
        assert_eq!(errors.len(), 1);
        assert!(
            matches!(&errors[0], TensorholoError::InvalidInput { message } if message.contains("after 300"))
        );

        let quiet = Arc::new(Recorder::default());
        echo.stream(quiet.clone(), 0, false).unwrap();
        assert!(quiet.values.lock().unwrap().is_empty());
        assert!(quiet.errors.lock().unwrap().is_empty());
        assert!(matches!(
            echo.stream(quiet, MAX_STREAM_COUNT + 1, false),
            Err(TensorholoError::InvalidInput { .. })
        ));
    }

    struct Failing;
    impl DemoListener for Failing {
        fn on_value(&self, index: u64, _: Bytes8Demo) {
            if index == 2 {
                panic!("listener failed at {index}");
            }
        }
        fn on_error(&self, _: TensorholoError) {}
    }

    #[test]
    fn a_failing_listener_is_an_internal_error() {
        let r = Echo::new(1).unwrap().stream(Arc::new(Failing), 5, false);
        assert!(
            matches!(&r, Err(TensorholoError::Internal { message }) if message.contains("listener failed at 2")),
            "{r:?}"
        );
    }

    #[test]
    fn demo_panic_is_internal() {
        let r = demo_panic("boom".into());
        assert!(
            matches!(&r, Err(TensorholoError::Internal { message }) if message.contains("panicked: boom")),
            "{r:?}"
        );
    }
}
