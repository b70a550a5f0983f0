//! [`HologramStream`]: video, through a bounded queue that drops the oldest frame and a worker thread that
//! hands results to a [`StreamListener`].

use std::collections::VecDeque;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Instant;

use crate::encoding::PhaseContinuity;
use crate::error::{invalid, HoloError, Result};
use crate::foveation::Gaze;
use crate::pipeline::HologramSession;
use crate::scene::CameraFrameBuf;

use super::config::GeneratorConfig;
use super::frames::SlmPatterns;

/// The default capacity of a [`HologramStream`]'s queue: one frame waiting while one is converted and one
/// runs through the CNN.
pub const DEFAULT_STREAM_CAPACITY: usize = 2;

/// Receives a [`HologramStream`]'s results, in frame order, on the stream's worker thread.
pub trait StreamListener: Send {
    /// The patterns of frame `index` (the value [`HologramStream::push`] returned for it).
    fn on_patterns(&mut self, index: u64, patterns: SlmPatterns);
    /// Frame `index` failed (bad buffers, all depth invalid, …); the stream goes on with the next frame.
    fn on_error(&mut self, index: u64, error: HoloError);
}

/// The queue between [`HologramStream::push`] and the worker.
#[derive(Debug, Default)]
struct Queue {
    frames: VecDeque<(u64, CameraFrameBuf, Option<Gaze>)>,
    next_index: u64,
    dropped: u64,
    closed: bool,
}

#[derive(Debug, Default)]
struct Shared {
    queue: Mutex<Queue>,
    ready: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        // The queue's critical sections cannot panic; recover it rather than propagate poison.
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The next frame, waiting for one; `None` once closed and drained.
    fn pop(&self) -> Option<(u64, CameraFrameBuf, Option<Gaze>)> {
        let mut q = self.lock();
        loop {
            if let Some(f) = q.frames.pop_front() {
                return Some(f);
            }
            if q.closed {
                return None;
            }
            q = self.ready.wait(q).unwrap_or_else(|p| p.into_inner());
        }
    }
}

/// A video stream of camera frames (see the [module docs](super)); made by [`HologramGenerator::stream`].
/// Dropping it closes it.
///
/// [`HologramGenerator::stream`]: super::HologramGenerator::stream
#[derive(Debug)]
pub struct HologramStream {
    shared: Arc<Shared>,
    capacity: usize,
    /// The hologram's `(height, width)` where the generator foveates ([`GeneratorConfig::foveation`]).
    foveated: Option<(usize, usize)>,
    worker: Mutex<Option<JoinHandle<()>>>,
}

impl HologramStream {
    pub(super) fn start(
        mut session: HologramSession,
        config: GeneratorConfig,
        mut temporal: PhaseContinuity,
        listener: Box<dyn StreamListener>,
        capacity: usize,
    ) -> Result<Self> {
        let shared = Arc::new(Shared::default());
        let source = Arc::clone(&shared);
        let foveated = config.foveation.is_some();
        let size = foveated.then_some((config.height, config.width));
        let worker = std::thread::Builder::new()
            .name("tensorholo-stream".into())
            .spawn(move || {
                let mut listener = listener;
                let mut options = config.frame_options();
                let run = catch_unwind(AssertUnwindSafe(|| {
                    // The CNN thread converts frames (the first auto range is locked for the rest); each
                    // frame's range and conversion time travel to the sink in its tag.
                    let frames = std::iter::from_fn(|| {
                        let (index, buf, gaze) = source.pop()?;
                        let t = Instant::now();
                        let converted = buf.view().to_rgbd(config.height, config.width, &options);
                        let convert_s = t.elapsed().as_secs_f64();
                        let range = converted.as_ref().ok().and_then(|(_, r)| r.range_used);
                        if options.range.is_none() {
                            options.range = range;
                        }
                        let frame = converted.map(|(frame, _)| (frame, gaze));
                        Some(((index, range, convert_s), frame))
                    });
                    // Each delivered pattern through the stream's temporal state (the churn from the
                    // previous one, the alignment where asked).
                    let sink = |(index, range, convert_s), result: Result<&_>| {
                        let patterns = result.and_then(|out| {
                            let mut p = SlmPatterns::from_frame(out, convert_s, range);
                            p.phase_churn = temporal.next(p.codes.view_mut())?.map(|s| s.churn);
                            Ok(p)
                        });
                        match patterns {
                            Ok(p) => listener.on_patterns(index, p),
                            Err(e) => listener.on_error(index, e),
                        }
                        Ok(())
                    };
                    if foveated {
                        // One frame after another, each on its own gaze (or the full frame without one).
                        session.deliver_each(
                            frames,
                            |s, (frame, gaze)| match gaze {
                                Some(g) => s.render_foveated(&frame, &g).map(drop),
                                None => s.render(&frame).map(drop),
                            },
                            sink,
                        )
                    } else {
                        let frames = frames.map(|(tag, f)| (tag, f.map(|(frame, _)| frame)));
                        session.render_stream_each(frames, sink)
                    }
                }));
                let failure = match run {
                    Ok(Ok(_)) => None,
                    Ok(Err(e)) => Some(e),
                    Err(_) => Some(HoloError::Internal("the stream's worker panicked".into())),
                };
                if let Some(e) = failure {
                    let index = source.lock().next_index;
                    listener.on_error(index, e);
                }
            })
            .map_err(|e| HoloError::Internal(format!("cannot start the stream's worker: {e}")))?;
        Ok(Self {
            shared,
            capacity,
            foveated: size,
            worker: Mutex::new(Some(worker)),
        })
    }

    /// Queues a frame and returns its index (0, 1, 2… in push order). Never blocks on the hologram: when
    /// the queue is full, the oldest waiting frame is dropped ([`HologramStream::dropped_frames`] counts
    /// them) and its index is never delivered.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`stream`) after [`HologramStream::close`].
    pub fn push(&self, frame: CameraFrameBuf) -> Result<u64> {
        self.enqueue(frame, None)
    }

    /// Queues a frame to be rendered foveated on `gaze` (`docs/FOVEATION.md`,
    /// [`HologramGenerator::render_foveated`]: the gaze in pixels of the hologram), as
    /// [`HologramStream::push`] does. A foveating generator's stream renders its frames one after another
    /// (the tile's CNN is short), frames pushed without a gaze as full frames.
    ///
    /// Errors: [`HoloError::InvalidParameter`] naming `foveation` for a generator made without
    /// [`GeneratorConfig::foveation`], `gaze` or `gaze_depth_m` for a gaze outside the hologram or not finite
    /// ([`Gaze::check`]), `stream` after [`HologramStream::close`].
    ///
    /// [`HologramGenerator::render_foveated`]: super::HologramGenerator::render_foveated
    pub fn push_foveated(&self, frame: CameraFrameBuf, gaze: Gaze) -> Result<u64> {
        let Some((height, width)) = self.foveated else {
            return Err(invalid(
                "foveation",
                "this stream's generator was made without foveation (GeneratorConfig::foveation)",
            ));
        };
        gaze.check(height, width)?;
        self.enqueue(frame, Some(gaze))
    }

    fn enqueue(&self, frame: CameraFrameBuf, gaze: Option<Gaze>) -> Result<u64> {
        let mut q = self.shared.lock();
        if q.closed {
            return Err(invalid("stream", "this stream is closed; start a new one"));
        }
        let index = q.next_index;
        q.next_index += 1;
        q.frames.push_back((index, frame, gaze));
        while q.frames.len() > self.capacity {
            q.frames.pop_front();
            q.dropped += 1;
        }
        drop(q);
        self.shared.ready.notify_one();
        Ok(index)
    }

    /// Frames dropped so far because the queue was full.
    pub fn dropped_frames(&self) -> u64 {
        self.shared.lock().dropped
    }

    /// Frames pushed so far.
    pub fn pushed_frames(&self) -> u64 {
        self.shared.lock().next_index
    }

    /// Stops accepting frames, lets the worker finish the frames already queued, and waits for it: after
    /// `close` returns, the listener is called no more. Calling it again does nothing.
    pub fn close(&self) {
        self.shared.lock().closed = true;
        self.shared.ready.notify_all();
        let handle = self.worker.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(h) = handle {
            // The worker catches its own panics; a join error cannot carry anything more.
            let _ = h.join();
        }
    }

    /// Whether [`HologramStream::close`] was called.
    pub fn is_closed(&self) -> bool {
        self.shared.lock().closed
    }
}

impl Drop for HologramStream {
    fn drop(&mut self) {
        self.close();
    }
}
