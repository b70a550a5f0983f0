//! [`HologramStream`]: video, its results reaching the app's [`PatternsListener`] in frame order.

use std::sync::Arc;

use tensorholo::generator as core;

use crate::error::{guard, Result, TensorholoError};
use crate::foveation::Gaze;
use crate::frames::{RgbdFrame, SlmPatterns};

/// Receives a [`HologramStream`]'s results, implemented by the app (Kotlin/Swift/Python). Called on the
/// stream's background thread, in frame order.
#[uniffi::export(with_foreign)]
pub trait PatternsListener: Send + Sync {
    /// The patterns of frame `index` (the number [`HologramStream::push`] returned for it).
    fn on_patterns(&self, index: u64, patterns: SlmPatterns);
    /// A frame failed (its message starts with `frame <index>:`); the stream goes on.
    fn on_error(&self, error: TensorholoError);
}

struct ListenerBridge(Arc<dyn PatternsListener>);

impl core::StreamListener for ListenerBridge {
    fn on_patterns(&mut self, index: u64, patterns: core::SlmPatterns) {
        self.0.on_patterns(index, patterns.into());
    }
    fn on_error(&mut self, index: u64, error: tensorholo::HoloError) {
        let mut e = TensorholoError::from(error);
        match &mut e {
            TensorholoError::InvalidInput { message }
            | TensorholoError::InvalidModel { message }
            | TensorholoError::Unsupported { message }
            | TensorholoError::Cancelled { message }
            | TensorholoError::Internal { message } => {
                *message = format!("frame {index}: {message}")
            }
        }
        self.0.on_error(e);
    }
}

/// A video stream ([`HologramGenerator::stream`](crate::HologramGenerator::stream)).
#[derive(Debug, uniffi::Object)]
pub struct HologramStream {
    inner: core::HologramStream,
}

impl HologramStream {
    /// Starts `generator`'s stream, its results going to `listener` ([`HologramGenerator::stream`](crate::HologramGenerator::stream)).
    pub(crate) fn start(
        generator: &core::HologramGenerator,
        listener: Arc<dyn PatternsListener>,
    ) -> Result<Self> {
        let inner = generator.stream(
            Box::new(ListenerBridge(listener)),
            core::DEFAULT_STREAM_CAPACITY,
        )?;
        Ok(Self { inner })
    }
}

#[uniffi::export]
impl HologramStream {
    /// Queues a frame without waiting for the hologram and returns its index (0, 1, 2… in push order); when
    /// the queue is full the oldest waiting frame is dropped.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] after [`HologramStream::close`].
    pub fn push(&self, frame: RgbdFrame) -> Result<u64> {
        guard(|| Ok(self.inner.push(frame.into_core())?))
    }

    /// Queues a frame to be rendered foveated on `gaze` (this frame's eye-tracker, face-tracking or touch
    /// point, in hologram pixels; [`HologramGenerator::render_foveated`](crate::HologramGenerator::render_foveated)),
    /// as [`HologramStream::push`] does.
    ///
    /// Errors: [`TensorholoError::InvalidInput`] for a generator made without
    /// [`GeneratorConfig::foveation`](crate::GeneratorConfig::foveation), a gaze outside the hologram or not
    /// finite (naming it), or after [`HologramStream::close`].
    pub fn push_foveated(&self, frame: RgbdFrame, gaze: Gaze) -> Result<u64> {
        guard(|| Ok(self.inner.push_foveated(frame.into_core(), gaze.into())?))
    }

    /// Frames dropped so far because the queue was full.
    pub fn dropped_frames(&self) -> u64 {
        self.inner.dropped_frames()
    }

    /// Stops accepting frames, finishes the queued ones and waits: afterwards the listener is called no
    /// more. Calling it again does nothing.
    pub fn close(&self) {
        self.inner.close()
    }
}
