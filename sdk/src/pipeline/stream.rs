//! Streams: [`HologramSession::render_stream`] and [`HologramSession::render_stream_each`] overlap the
//! hologram CNN of frame `n + 1` (on a second thread, with its own [`crate::cnn::CnnPlan::spawn`]) with the
//! optics of frame `n`; on an accelerator, whole frames run one after another.

use std::sync::mpsc::sync_channel;
use std::time::Instant;

use super::frame::{Heads, SlmFrame};
use super::session::HologramSession;
use crate::error::Result;
use crate::scene::RgbdFrame;

impl HologramSession {
    /// Renders a sequence, overlapping the hologram CNN of frame `n + 1` (on a second thread) with the optics
    /// of frame `n`. `sink(index, frame)` receives each result in order; an error from a frame, the source or
    /// the sink stops the stream and is returned. Outputs equal [`HologramSession::render`]'s bit for bit;
    /// `timings.total_s` is the frame period (time since the previous frame was delivered).
    ///
    /// Errors: the first error of the source, a frame (as [`HologramSession::render`]) or the sink.
    pub fn render_stream<I, F>(&mut self, frames: I, mut sink: F) -> Result<usize>
    where
        I: IntoIterator<Item = Result<RgbdFrame>>,
        I::IntoIter: Send,
        F: FnMut(usize, &SlmFrame) -> Result<()>,
    {
        let tagged = frames.into_iter().enumerate();
        self.render_stream_each(tagged, |i, out| sink(i, out?))
    }

    /// As [`HologramSession::render_stream`], but a failed frame does not stop the stream: each item of
    /// `frames` is `(tag, frame or error)`, and `sink(tag, result)` receives every item in order, with the
    /// frame's SLM patterns or its error (a conversion error from the source, a CNN or encoding error). Only
    /// an error returned by `sink` stops the stream. The session stays usable after a failed frame.
    ///
    /// Returns the number of items delivered. Errors: the first error `sink` returns.
    pub fn render_stream_each<T, I, F>(&mut self, frames: I, sink: F) -> Result<usize>
    where
        T: Send,
        I: IntoIterator<Item = (T, Result<RgbdFrame>)>,
        I::IntoIter: Send,
        F: FnMut(T, Result<&SlmFrame>) -> Result<()>,
    {
        let frames = frames.into_iter();
        if self.accelerator.is_some() {
            // The GPU runs whole frames; the CPU only packs inputs, so frames go one after another.
            return self.deliver_each(frames, |s, f| s.render(&f).map(drop), sink);
        }
        let mut cnn = self.cnn.spawn();
        std::thread::scope(|scope| {
            // A rendezvous: the CNN thread hands frame n + 1's heads over when the optics of frame n are
            // done, and only then starts frame n + 2, so two frames' heads are alive at most (a queue of
            // one would hold a third: 50 MB at 1080p, for no faster a stream while the CNN is the slower
            // stage).
            let (tx, rx) = sync_channel::<(T, Result<(Heads, f64)>)>(0);
            scope.spawn(move || {
                for (tag, frame) in frames {
                    let out = frame.and_then(|f| cnn.run_frame(&f));
                    if tx.send((tag, out)).is_err() {
                        break;
                    }
                }
            });
            self.deliver_each(
                rx,
                |s, (heads, cnn_s)| s.encode_heads(heads, cnn_s).map(drop),
                sink,
            )
        })
    }

    /// The delivery loop of a stream: `step` turns each item's input into [`HologramSession::output`] (a whole
    /// frame, or the rest of one whose CNN ran elsewhere), and `sink(tag, result)` receives every item in
    /// order, the output's `timings.total_s` set to the frame period (from the previous frame's end). An
    /// item's error goes to `sink`; only `sink`'s own error stops the loop. Returns the number of items.
    pub(crate) fn deliver_each<T, X, F>(
        &mut self,
        items: impl IntoIterator<Item = (T, Result<X>)>,
        mut step: impl FnMut(&mut Self, X) -> Result<()>,
        mut sink: F,
    ) -> Result<usize>
    where
        F: FnMut(T, Result<&SlmFrame>) -> Result<()>,
    {
        let mut count = 0;
        let mut last = Instant::now();
        for (tag, item) in items {
            count += 1;
            match item.and_then(|x| step(self, x)) {
                Ok(()) => {
                    let now = Instant::now();
                    self.output.timings.total_s = (now - last).as_secs_f64();
                    last = now;
                    sink(tag, Ok(&self.output))?;
                }
                Err(e) => sink(tag, Err(e))?,
            }
        }
        Ok(count)
    }
}
