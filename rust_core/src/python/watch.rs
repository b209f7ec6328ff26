//! Ctrl-C while the core works: the call runs on a pool thread with the GIL released while
//! the calling thread runs Python's signal handlers, and an interrupted call is rolled back.
use super::errors::*;
use crate::error::Error;
use crate::vector::Vector;
use crate::world::{Checkpoint, World};
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// How often the calling thread runs Python's signal handlers while a step runs.
pub(super) const SIGNAL_POLL: Duration = Duration::from_millis(20);

/// Calls of at most this many element-steps (`World::elements`: particles, grid cells, flow
/// points) with a fixed-step integrator run on the calling thread, unwatched: even pairwise
/// gravity (N² per step) keeps them to milliseconds, and the hand-off to a pool thread (~20 µs)
/// would cost more than a small scene's step. A signal that
/// came during such a call is handled right after it, and the call is undone as if it had been
/// interrupted (`undo_if_signalled`).
pub(super) const SHORT_CALL: u64 = 4096;

/// Runs Python's signal handlers after a finished call; if one raises (Ctrl-C), the call is
/// undone (`rollback` to `cp`) and the handler's exception raised, so an interrupted call never
/// stands, however close to its end the signal came. Returns the call's result otherwise.
pub(super) fn undo_if_signalled<V: Vector, T>(
    py: Python<'_>,
    sim: &mut World<V>,
    (v, cp): (T, Checkpoint),
) -> PyResult<T> {
    match py.check_signals() {
        Ok(()) => {
            sim.release(cp);
            Ok(v)
        }
        Err(e) => {
            sim.rollback(cp);
            Err(e)
        }
    }
}

/// Runs `f` with the GIL released as a task on the simulation's pool (`run_watched`), while the
/// calling thread wakes every `SIGNAL_POLL` to run Python's signal handlers (`check_signals`;
/// Python runs them on the main thread only, so the stepping code, on a pool thread, cannot).
/// If a handler raises (Ctrl-C: KeyboardInterrupt), the stop flag is set and the handler's
/// exception is returned beside `f`'s result.
pub(super) fn watched<V: Vector, T: Send>(
    py: Python<'_>,
    sim: &mut World<V>,
    f: impl FnOnce(&mut World<V>, &Arc<AtomicBool>) -> Result<T, Error> + Send,
) -> (Result<T, Error>, Option<PyErr>) {
    let stop = Arc::new(AtomicBool::new(false));
    let mut pending: Option<PyErr> = None;
    let result = py.detach(|| {
        sim.run_watched(
            |s| f(s, &stop),
            |wait| {
                while !wait(SIGNAL_POLL) {
                    if let Err(e) = Python::attach(|py| py.check_signals()) {
                        pending = Some(e);
                        stop.store(true, Ordering::Relaxed);
                        return;
                    }
                }
            },
        )
    });
    (result, pending)
}

/// `f` under `watched`: once a handler raises, `f` rolls back and returns `Error::Interrupted`,
/// and the handler's exception is raised. If `f` finished before it saw the flag, the handlers
/// run once more and, if one raises, `f`'s work is undone with the checkpoint it returned: an
/// interrupted call never stands.
pub(super) fn interruptible<V: Vector, T: Send>(
    py: Python<'_>,
    sim: &mut World<V>,
    f: impl FnOnce(&mut World<V>, &Arc<AtomicBool>) -> Result<(T, Checkpoint), Error> + Send,
) -> PyResult<T> {
    match watched(py, sim, f) {
        (Ok(done), None) => undo_if_signalled(py, sim, done),
        (Ok((_, cp)), Some(e)) => {
            sim.rollback(cp);
            Err(e)
        }
        (Err(_), Some(e)) => Err(e),
        (Err(Error::Interrupted { .. }), None) => Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(())),
        (Err(e), None) => Err(to_py(py, e)),
    }
}

/// `f` under `watched`, for a call that changes nothing (the energy books): a handler's
/// exception stops it and is raised; there is nothing to roll back.
pub(super) fn interruptible_read<V: Vector, T: Send>(
    py: Python<'_>,
    sim: &mut World<V>,
    f: impl FnOnce(&mut World<V>, &Arc<AtomicBool>) -> Result<T, Error> + Send,
) -> PyResult<T> {
    match watched(py, sim, f) {
        (_, Some(e)) => Err(e),
        (Ok(v), None) => Ok(v),
        (Err(Error::Interrupted { .. }), None) => Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(())),
        (Err(e), None) => Err(to_py(py, e)),
    }
}
