//! Deterministic parallel loops. Work is split into fixed chunks of `CHUNK` items whatever the
//! thread count, and reductions add chunk partials in chunk order, so 1 and many threads give
//! bit-identical results. Small problems run the same chunks serially (rayon's fork-join costs
//! microseconds, which dominates a 2-body orbit).
//!
//! Loops fork only onto one of physcore's own pools (a simulation's, or `default_pool`): the one
//! `install` names for the calling thread, or the pool whose thread runs them; without one they
//! run the same chunks in order on the calling thread. They never touch rayon's implicit global
//! pool: if that one cannot start its threads (a process or thread limit, RLIMIT_NPROC), rayon
//! panics on that use and on every later one. Our pools are built with the fallible `build()`.
use rayon::prelude::*;
use rayon::ThreadPool;
use std::cell::RefCell;
use std::ops::Range;
use std::sync::{Arc, Mutex};

pub const CHUNK: usize = 1024;
/// Below this many items a loop runs serially (same chunks, same order, same result).
pub const PAR_MIN: usize = 4 * CHUNK;

thread_local! {
    /// The pool the calling thread's loops fork onto (set by `install`).
    static POOL: RefCell<Option<Arc<ThreadPool>>> = const { RefCell::new(None) };
}

/// Runs `f` on the calling thread with `pool` as the pool its parallel loops fork onto (`None`:
/// they run serially). No hand-off to a pool thread for the call itself (~10-20 µs, the whole
/// cost of a small scene's step): only loops long enough to fork pay it.
pub fn install<R>(pool: Option<&Arc<ThreadPool>>, f: impl FnOnce() -> R) -> R {
    struct Restore(Option<Arc<ThreadPool>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            POOL.with(|p| *p.borrow_mut() = self.0.take());
        }
    }
    let _restore = Restore(POOL.with(|p| p.replace(pool.cloned())));
    f()
}

/// Runs `f`, which forks rayon work, on the pool of the call in progress: directly on one of
/// its threads, through `ThreadPool::install` from elsewhere. `None` (and `f` not run) if there
/// is no such pool: the caller then runs its loop serially.
#[inline]
pub fn fork<R: Send>(f: impl FnOnce() -> R + Send) -> Option<R> {
    if rayon::current_thread_index().is_some() {
        return Some(f());
    }
    let pool = POOL.with(|p| p.borrow().clone())?;
    Some(pool.install(f))
}

/// `fork` for a loop over `n` items: small ones never fork.
#[inline]
pub fn fork_if<R: Send>(n: usize, f: impl FnOnce() -> R + Send) -> Option<R> {
    if n >= PAR_MIN {
        fork(f)
    } else {
        None
    }
}

/// Threads the loops of the call in progress fork onto (1 without a pool).
pub fn threads() -> usize {
    if rayon::current_thread_index().is_some() {
        return rayon::current_num_threads();
    }
    POOL.with(|p| p.borrow().as_ref().map_or(1, |p| p.current_num_threads()))
}

/// The pool of every simulation built with `threads=None`: all cores, or `RAYON_NUM_THREADS`
/// threads, started on first use. If the threads cannot be started, returns why; the next call
/// tries again (the limit may have been lifted).
pub fn default_pool() -> Result<Arc<ThreadPool>, String> {
    static POOL: Mutex<Option<Arc<ThreadPool>>> = Mutex::new(None);
    let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(p) = &*pool {
        return Ok(p.clone());
    }
    let p = Arc::new(rayon::ThreadPoolBuilder::new().build().map_err(|e| e.to_string())?);
    *pool = Some(p.clone());
    Ok(p)
}

#[inline]
fn ranges(n: usize) -> impl Iterator<Item = Range<usize>> + Clone {
    (0..n.div_ceil(CHUNK)).map(move |c| c * CHUNK..((c + 1) * CHUNK).min(n))
}

/// `f(start, chunk)` on consecutive chunks of `a`.
#[inline]
pub fn chunks1<A: Send>(a: &mut [A], f: impl Fn(usize, &mut [A]) + Sync + Send) {
    if fork_if(a.len(), || a.par_chunks_mut(CHUNK).enumerate().for_each(|(c, a)| f(c * CHUNK, a))).is_none() {
        for (c, a) in a.chunks_mut(CHUNK).enumerate() {
            f(c * CHUNK, a);
        }
    }
}

/// `f(start, chunk_a, chunk_b)` on matching chunks of two equally long slices.
#[inline]
pub fn chunks2<A: Send, B: Send>(a: &mut [A], b: &mut [B], f: impl Fn(usize, &mut [A], &mut [B]) + Sync + Send) {
    debug_assert_eq!(a.len(), b.len());
    if fork_if(a.len(), || {
        a.par_chunks_mut(CHUNK).zip(b.par_chunks_mut(CHUNK)).enumerate().for_each(|(c, (a, b))| f(c * CHUNK, a, b))
    })
    .is_none()
    {
        for (c, (a, b)) in a.chunks_mut(CHUNK).zip(b.chunks_mut(CHUNK)).enumerate() {
            f(c * CHUNK, a, b);
        }
    }
}

/// `f(start, a, b, c)` on matching chunks of three equally long slices.
#[inline]
pub fn chunks3<A: Send, B: Send, C: Send>(
    a: &mut [A],
    b: &mut [B],
    c: &mut [C],
    f: impl Fn(usize, &mut [A], &mut [B], &mut [C]) + Sync + Send,
) {
    if fork_if(a.len(), || {
        a.par_chunks_mut(CHUNK)
            .zip(b.par_chunks_mut(CHUNK))
            .zip(c.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(k, ((a, b), c))| f(k * CHUNK, a, b, c))
    })
    .is_none()
    {
        for (k, ((a, b), c)) in a.chunks_mut(CHUNK).zip(b.chunks_mut(CHUNK)).zip(c.chunks_mut(CHUNK)).enumerate() {
            f(k * CHUNK, a, b, c);
        }
    }
}

/// `f(start, a, b, c, d)` on matching chunks of four equally long slices.
#[inline]
pub fn chunks4<A: Send, B: Send, C: Send, D: Send>(
    a: &mut [A],
    b: &mut [B],
    c: &mut [C],
    d: &mut [D],
    f: impl Fn(usize, &mut [A], &mut [B], &mut [C], &mut [D]) + Sync + Send,
) {
    if fork_if(a.len(), || {
        a.par_chunks_mut(CHUNK)
            .zip(b.par_chunks_mut(CHUNK))
            .zip(c.par_chunks_mut(CHUNK))
            .zip(d.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(k, (((a, b), c), d))| f(k * CHUNK, a, b, c, d))
    })
    .is_none()
    {
        let chunks = a.chunks_mut(CHUNK).zip(b.chunks_mut(CHUNK)).zip(c.chunks_mut(CHUNK)).zip(d.chunks_mut(CHUNK));
        for (k, (((a, b), c), d)) in chunks.enumerate() {
            f(k * CHUNK, a, b, c, d);
        }
    }
}

/// Deterministic sum of `f(range)` over fixed chunks of `0..n`.
#[inline]
pub fn sum<T>(n: usize, zero: T, f: impl Fn(Range<usize>) -> T + Sync + Send) -> T
where
    T: Send + Copy + std::ops::Add<Output = T>,
{
    reduce(n, zero, |a, b| a + b, f)
}

/// Deterministic sum where each chunk also writes into its own slice of `out` (fused pass).
#[inline]
pub fn chunks1_sum<A: Send>(a: &mut [A], f: impl Fn(usize, &mut [A]) -> f64 + Sync + Send) -> f64 {
    chunks1_fold(a, 0.0, |a, b| a + b, f)
}

/// Like `chunks2`, with each chunk returning a value; the values are folded in chunk order
/// (deterministic for any thread count).
#[inline]
pub fn chunks2_fold<A: Send, B: Send, T: Send>(
    a: &mut [A],
    b: &mut [B],
    zero: T,
    fold: impl Fn(T, T) -> T,
    f: impl Fn(usize, &mut [A], &mut [B]) -> T + Sync + Send,
) -> T {
    if let Some(p) = fork_if(a.len(), || {
        a.par_chunks_mut(CHUNK)
            .zip(b.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (a, b))| f(c * CHUNK, a, b))
            .collect::<Vec<T>>()
    }) {
        return p.into_iter().fold(zero, fold);
    }
    // Serially: the same partials folded in the same order, without the vector of partials.
    let mut acc = zero;
    for (c, (a, b)) in a.chunks_mut(CHUNK).zip(b.chunks_mut(CHUNK)).enumerate() {
        acc = fold(acc, f(c * CHUNK, a, b));
    }
    acc
}

/// Like `chunks1`, with each chunk returning a value folded in chunk order (deterministic).
#[inline]
pub fn chunks1_fold<A: Send, T: Send>(
    a: &mut [A],
    zero: T,
    fold: impl Fn(T, T) -> T,
    f: impl Fn(usize, &mut [A]) -> T + Sync + Send,
) -> T {
    if let Some(p) =
        fork_if(a.len(), || a.par_chunks_mut(CHUNK).enumerate().map(|(c, a)| f(c * CHUNK, a)).collect::<Vec<T>>())
    {
        return p.into_iter().fold(zero, fold);
    }
    // Serially: the same partials folded in the same order, without the vector of partials.
    let mut acc = zero;
    for (c, a) in a.chunks_mut(CHUNK).enumerate() {
        acc = fold(acc, f(c * CHUNK, a));
    }
    acc
}

/// Deterministic fold of `f(range)` over fixed chunks of `0..n` (e.g. a maximum).
#[inline]
pub fn reduce<T: Send>(n: usize, zero: T, fold: impl Fn(T, T) -> T, f: impl Fn(Range<usize>) -> T + Sync + Send) -> T {
    if let Some(p) = fork_if(n, || ranges(n).collect::<Vec<_>>().into_par_iter().map(&f).collect::<Vec<T>>()) {
        return p.into_iter().fold(zero, fold);
    }
    // Serially: the same partials folded in the same order, without the vector of partials.
    let mut acc = zero;
    for r in ranges(n) {
        acc = fold(acc, f(r));
    }
    acc
}

/// `chunks2` whose chunks raise a flag; returns whether any did.
#[inline]
pub fn chunks2_any<A: Send, B: Send>(
    a: &mut [A],
    b: &mut [B],
    f: impl Fn(usize, &mut [A], &mut [B]) -> bool + Sync + Send,
) -> bool {
    chunks2_fold(a, b, false, |x, y| x | y, f)
}

/// A raw pointer shared by the threads of a parallel pass in which each thread writes a disjoint
/// set of indices (a scatter through a permutation, the cell-list sort).
#[derive(Clone, Copy)]
pub struct SyncPtr<T>(pub *mut T);
unsafe impl<T> Send for SyncPtr<T> {}
unsafe impl<T> Sync for SyncPtr<T> {}
impl<T> SyncPtr<T> {
    #[inline(always)]
    pub fn get(self) -> *mut T {
        self.0
    }
}
