//! [`OpticsPool`]: a rayon pool of all the cores for the encoding stage (each colour's rows split over its
//! threads, the three colours side by side), so that three colours on two cores leave no core idle or
//! time-sliced, as one thread per colour does.

use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::error::{invalid, HoloError, Result};

/// A rayon pool of one thread per core (`std::thread::available_parallelism`), kept by a session. A frame
/// enters it from outside twice (rayon's injector queue allocates a block every 63 such calls: see
/// `sdk/tests/pipeline_alloc.rs`); the work inside it allocates nothing.
#[derive(Debug)]
pub(super) struct OpticsPool {
    pool: rayon::ThreadPool,
}

impl OpticsPool {
    /// Starts the threads. Errors: [`HoloError::InvalidParameter`] (`threads`) if the OS will not.
    pub(super) fn start() -> Result<Self> {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("tensorholo-optics-{i}"))
            .build()
            .map_err(|e| invalid("threads", format!("cannot start the optics threads: {e}")))?;
        Ok(Self { pool })
    }

    /// Runs `work` on the pool (its parallel iterators spread over the pool's threads). Errors: `work`'s, and
    /// [`HoloError::Internal`] if it panicked (the session stays usable: the buffers are only data).
    pub(super) fn run<R: Send>(&self, work: impl FnOnce() -> Result<R> + Send) -> Result<R> {
        catch_unwind(AssertUnwindSafe(|| self.pool.install(work)))
            .unwrap_or_else(|_| Err(HoloError::Internal("an optics thread panicked".into())))
    }
}
