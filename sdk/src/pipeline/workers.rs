//! [`ColourWorkers`]: three persistent threads, one per colour, that run a [`Task`] on each colour's state
//! without allocating (the offset stage; the encoding stage runs on the session's optics pool,
//! `pipeline/pool.rs`). Knows no optics: it moves [`ColourState`]s and results.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;
use std::thread::JoinHandle;

use super::colour::{ColourState, Task};
use crate::error::{invalid, HoloError, Result};

/// What a worker hands back: the colour's state and the task's result.
type Reply = (Box<ColourState>, Result<()>);

/// The mailboxes shared by a session and its colour workers, guarded by one mutex.
#[derive(Debug, Default)]
struct Mailboxes {
    /// The task and state waiting for worker `c`.
    tasks: [Option<(Task, Box<ColourState>)>; 3],
    /// What worker `c` handed back.
    replies: [Option<Reply>; 3],
    /// Set when the session drops its workers: the worker loops end.
    closed: bool,
}

#[derive(Debug, Default)]
struct Shared {
    boxes: std::sync::Mutex<Mailboxes>,
    /// Signalled when a task is posted or the workers are closed.
    task_posted: std::sync::Condvar,
    /// Signalled when a reply is posted.
    reply_posted: std::sync::Condvar,
}

impl Shared {
    /// Locks the mailboxes. No code panics while holding the lock (tasks run outside it, under
    /// `catch_unwind`), so a poisoned lock still holds consistent mailboxes.
    fn lock(&self) -> std::sync::MutexGuard<'_, Mailboxes> {
        self.boxes.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Three persistent threads, one per colour. A task moves a colour's state to its worker and back through
/// fixed mailboxes under a mutex and two condition variables (futex-based: waiting allocates nothing). Neither
/// a rayon pool (whose injector queue allocates a block every 63 jobs submitted from outside the pool) nor
/// `std::sync::mpsc` (whose waker lists allocate the first time a given thread blocks on a channel, so
/// whether the warm-up frame allocates them depends on timing) would keep a frame allocation-free.
#[derive(Debug)]
pub(super) struct ColourWorkers {
    shared: Arc<Shared>,
    handles: Vec<JoinHandle<()>>,
}

impl ColourWorkers {
    pub(super) fn start() -> Result<Self> {
        let shared = Arc::new(Shared::default());
        let mut workers = Self {
            shared: shared.clone(),
            handles: Vec::new(),
        };
        for c in 0..3 {
            let shared = shared.clone();
            let handle = std::thread::Builder::new()
                .name(format!("tensorholo-colour-{c}"))
                .spawn(move || Self::worker_loop(c, &shared))
                // Dropping `workers` closes the mailboxes and joins the workers already started.
                .map_err(|e| invalid("threads", format!("cannot start a colour worker: {e}")))?;
            workers.handles.push(handle);
        }
        Ok(workers)
    }

    fn worker_loop(c: usize, shared: &Shared) {
        loop {
            let (task, mut state) = {
                let mut boxes = shared.lock();
                loop {
                    if let Some(job) = boxes.tasks[c].take() {
                        break job;
                    }
                    if boxes.closed {
                        return;
                    }
                    boxes = shared
                        .task_posted
                        .wait(boxes)
                        .unwrap_or_else(|e| e.into_inner());
                }
            };
            let result = catch_unwind(AssertUnwindSafe(|| state.run(task))).unwrap_or_else(|_| {
                Err(HoloError::Internal(format!("colour worker {c} panicked")))
            });
            shared.lock().replies[c] = Some((state, result));
            shared.reply_posted.notify_all();
        }
    }

    /// Runs `task(c)` on each colour's state in parallel; the states come back in colour order. Returns the
    /// first error (in colour order) after all three have come back.
    pub(super) fn run(
        &self,
        states: &mut [Option<Box<ColourState>>; 3],
        task: impl Fn(usize) -> Task,
    ) -> Result<()> {
        {
            let mut boxes = self.shared.lock();
            if boxes.closed || self.handles.len() != 3 || states.iter().any(Option::is_none) {
                return Err(lost_state());
            }
            for (c, slot) in states.iter_mut().enumerate() {
                let state = slot.take().ok_or_else(lost_state)?;
                boxes.tasks[c] = Some((task(c), state));
            }
        }
        self.shared.task_posted.notify_all();
        let mut boxes = self.shared.lock();
        while boxes.replies.iter().any(Option::is_none) {
            if self.handles.iter().any(|h| h.is_finished()) {
                return Err(lost_state());
            }
            boxes = self
                .shared
                .reply_posted
                .wait(boxes)
                .unwrap_or_else(|e| e.into_inner());
        }
        let mut first_err = None;
        for (slot, reply) in states.iter_mut().zip(boxes.replies.iter_mut()) {
            let (state, result) = reply.take().ok_or_else(lost_state)?;
            *slot = Some(state);
            if let (Err(e), None) = (result, &first_err) {
                first_err = Some(e);
            }
        }
        first_err.map_or(Ok(()), Err)
    }
}

pub(super) fn lost_state() -> HoloError {
    HoloError::Internal("a colour worker of this session has stopped; create a new session".into())
}

impl Drop for ColourWorkers {
    fn drop(&mut self) {
        self.shared.lock().closed = true;
        self.shared.task_posted.notify_all();
        for h in self.handles.drain(..) {
            let _ = h.join();
        }
    }
}
