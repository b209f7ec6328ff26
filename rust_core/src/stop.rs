//! The stop flag of a call in progress (Ctrl-C), as the force terms see it.
//!
//! `World::step_interruptible` hands its flag to every term for the length of the call
//! (`Term::set(Setting::Stop)`). A term whose one evaluation is long (pairwise gravity: O(N²)) reads it
//! every fraction of a millisecond of work and, once it is set, skips the rest, leaving its
//! forces partly written: the simulation sees the flag after the evaluation and rolls the whole
//! call back, so such forces are never kept. Reading the flag is a relaxed atomic load and
//! changes no result. The flag belongs to one call of one simulation: other scenes' kernels
//! never see it.
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

/// Ctrl-C as code that holds the calling thread (outside a stepping call and its flag) can
/// poll it: the Python module installs `check` (Python's signal handlers, run on the main
/// thread); without it, never.
static SIGNALS: OnceLock<fn() -> bool> = OnceLock::new();

/// Installs the check `signalled` runs (the first one installed stays).
pub fn on_signals(check: fn() -> bool) {
    let _ = SIGNALS.set(check);
}

/// Whether a signal handler raised (Ctrl-C) since the last check: a waiting loop's way out.
pub fn signalled() -> bool {
    SIGNALS.get().is_some_and(|check| check())
}

/// A flag that is never set, for evaluations outside an interruptible call.
static NEVER: AtomicBool = AtomicBool::new(false);

/// A term's view of the stop flag: none between calls.
#[derive(Clone, Debug, Default)]
pub struct Stop(Option<Arc<AtomicBool>>);

impl Stop {
    pub fn new(flag: Option<Arc<AtomicBool>>) -> Self {
        Self(flag)
    }

    /// The flag to poll (a never-set one between calls).
    #[inline]
    pub fn flag(&self) -> &AtomicBool {
        self.0.as_deref().unwrap_or(&NEVER)
    }

    #[inline]
    pub fn is_set(&self) -> bool {
        self.flag().load(Ordering::Relaxed)
    }
}
