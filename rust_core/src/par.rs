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

/// Runs `body(c)` for every `c` in `0..n` on the pool of the call in progress (rayon splits the
/// indices as it splits a slice's chunks); false, and nothing run, without a pool.
///
/// Where the crate's loops meet rayon. Its machinery (jobs, join, the bridge of producers and
/// consumers) is generic over the closure it runs, and was compiled once per loop, about 610 of
/// them: 1.4 million of the crate's 4.2 million lines of LLVM IR (800,000 for the helpers below
/// alone), and its build 137 s instead of 75 s on 2 cores (issue 67). Behind a `dyn` it is
/// compiled once; the cost is one indirect call per chunk of `CHUNK` items.
#[inline(never)]
pub fn for_each_index(n: usize, body: &(dyn Fn(usize) + Sync)) -> bool {
    for_each_index_min(n, 1, body)
}

/// `for_each_index` with at least `min_len` indices a task (rayon's `with_min_len`).
#[inline(never)]
pub fn for_each_index_min(n: usize, min_len: usize, body: &(dyn Fn(usize) + Sync)) -> bool {
    fork(|| (0..n).into_par_iter().with_min_len(min_len).for_each(body)).is_some()
}

/// `f(c)` for every `c` in `0..n`: in parallel (`for_each_index_min`, at least `min_len` indices
/// a task) when `parallel` and a pool is there, else in index order on the calling thread. With
/// `Shared` for the slices each index writes, this is every chunked loop of the crate.
#[inline]
pub fn each(parallel: bool, n: usize, min_len: usize, f: impl Fn(usize) + Sync + Send) {
    if !(parallel && for_each_index_min(n, min_len, &f)) {
        (0..n).for_each(f);
    }
}

/// `f(c)` for every `c` in `0..n`, in parallel (`for_each_index`), collected in index order;
/// `None` (nothing run) without a pool.
#[inline]
pub fn map_index<T: Send>(n: usize, f: impl Fn(usize) -> T + Sync) -> Option<Vec<T>> {
    let mut out: Vec<T> = Vec::with_capacity(n);
    let p = SyncPtr(out.as_mut_ptr());
    // Each index writes its own slot once. If `f` panics, rayon re-raises it here after every
    // task has ended, and `out` (length 0) frees its buffer without dropping what was written.
    if !for_each_index(n, &|c| unsafe { p.get().add(c).write(f(c)) }) {
        return None;
    }
    // SAFETY: every slot in 0..n was written (for_each_index ran every index, none panicked).
    unsafe { out.set_len(n) };
    Some(out)
}

/// `f(c)` for `c` in `0..chunks`, in index order: in parallel (`map_index`) when the loop covers
/// `n >= PAR_MIN` items and a pool is there, else serially. The same values either way.
#[inline]
pub fn map_chunks<T: Send>(n: usize, chunks: usize, f: impl Fn(usize) -> T + Sync + Send) -> Vec<T> {
    if n >= PAR_MIN {
        if let Some(v) = map_index(chunks, &f) {
            return v;
        }
    }
    (0..chunks).map(f).collect()
}

/// `f(c, item)` for each item of `items` (`c` its index), in index order: in parallel when the
/// loop covers `n >= PAR_MIN` items and a pool is there, else serially. The items are typically
/// a chunk's disjoint slices of several arrays, zipped.
#[inline]
pub fn map_vec<T: Send, R: Send>(n: usize, items: Vec<T>, f: impl Fn(usize, T) -> R + Sync + Send) -> Vec<R> {
    if n >= PAR_MIN {
        let len = items.len();
        let mut items = std::mem::ManuallyDrop::new(items);
        let src = SyncPtr(items.as_mut_ptr());
        // SAFETY: each index moves its own item out once; the buffer is then freed without
        // dropping them (and leaked, with what was not moved, if `f` panics).
        if let Some(out) = map_index(len, |c| f(c, unsafe { src.get().add(c).read() })) {
            unsafe { drop(Vec::from_raw_parts(items.as_mut_ptr(), 0, items.capacity())) };
            return out;
        }
        // No pool: nothing was moved out.
        return std::mem::ManuallyDrop::into_inner(items).into_iter().enumerate().map(|(c, t)| f(c, t)).collect();
    }
    items.into_iter().enumerate().map(|(c, t)| f(c, t)).collect()
}

/// `f(start, chunk)` on consecutive chunks of `a`.
#[inline]
pub fn chunks1<A: Send>(a: &mut [A], f: impl Fn(usize, &mut [A]) + Sync + Send) {
    let parallel = a.len() >= PAR_MIN;
    let a = Shared::new(a);
    // SAFETY (here and below): chunk `c` of each slice goes to index `c` alone.
    each(parallel, a.pieces(CHUNK), 1, |c| f(c * CHUNK, unsafe { a.piece(CHUNK, c) }));
}

/// `f(start, chunk_a, chunk_b)` on matching chunks of two equally long slices.
#[inline]
pub fn chunks2<A: Send, B: Send>(a: &mut [A], b: &mut [B], f: impl Fn(usize, &mut [A], &mut [B]) + Sync + Send) {
    debug_assert_eq!(a.len(), b.len());
    let parallel = a.len() >= PAR_MIN;
    let (a, b) = (Shared::new(a), Shared::new(b));
    let chunks = a.pieces(CHUNK).min(b.pieces(CHUNK));
    each(parallel, chunks, 1, |c| unsafe { f(c * CHUNK, a.piece(CHUNK, c), b.piece(CHUNK, c)) });
}

/// `f(start, a, b, c)` on matching chunks of three equally long slices.
#[inline]
pub fn chunks3<A: Send, B: Send, C: Send>(
    a: &mut [A],
    b: &mut [B],
    c: &mut [C],
    f: impl Fn(usize, &mut [A], &mut [B], &mut [C]) + Sync + Send,
) {
    let parallel = a.len() >= PAR_MIN;
    let (a, b, c) = (Shared::new(a), Shared::new(b), Shared::new(c));
    let chunks = a.pieces(CHUNK).min(b.pieces(CHUNK)).min(c.pieces(CHUNK));
    each(parallel, chunks, 1, |k| unsafe { f(k * CHUNK, a.piece(CHUNK, k), b.piece(CHUNK, k), c.piece(CHUNK, k)) });
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
    let parallel = a.len() >= PAR_MIN;
    let (a, b, c, d) = (Shared::new(a), Shared::new(b), Shared::new(c), Shared::new(d));
    let chunks = a.pieces(CHUNK).min(b.pieces(CHUNK)).min(c.pieces(CHUNK)).min(d.pieces(CHUNK));
    each(parallel, chunks, 1, |k| unsafe {
        f(k * CHUNK, a.piece(CHUNK, k), b.piece(CHUNK, k), c.piece(CHUNK, k), d.piece(CHUNK, k))
    });
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
    if a.len() >= PAR_MIN {
        let (pa, pb) = (Shared::new(a), Shared::new(b));
        let chunks = pa.pieces(CHUNK).min(pb.pieces(CHUNK));
        if let Some(p) = map_index(chunks, |c| unsafe { f(c * CHUNK, pa.piece(CHUNK, c), pb.piece(CHUNK, c)) }) {
            return p.into_iter().fold(zero, fold);
        }
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
    if a.len() >= PAR_MIN {
        let pa = Shared::new(a);
        if let Some(p) = map_index(pa.pieces(CHUNK), |c| f(c * CHUNK, unsafe { pa.piece(CHUNK, c) })) {
            return p.into_iter().fold(zero, fold);
        }
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
    if n >= PAR_MIN {
        if let Some(p) = map_index(n.div_ceil(CHUNK), |c| f(c * CHUNK..((c + 1) * CHUNK).min(n))) {
            return p.into_iter().fold(zero, fold);
        }
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

/// A `&mut [T]` handed out in disjoint pieces to the tasks of a parallel pass (`each`): piece
/// `c` of `size` items to index `c`, as `chunks_mut(size)` would give them.
pub struct Shared<T> {
    p: SyncPtr<T>,
    len: usize,
}
impl<T> Clone for Shared<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for Shared<T> {}
impl<T> Shared<T> {
    #[inline(always)]
    pub fn new(s: &mut [T]) -> Self {
        Shared { p: SyncPtr(s.as_mut_ptr()), len: s.len() }
    }
    /// How many pieces of `size` items (the last one shorter).
    #[inline(always)]
    pub fn pieces(self, size: usize) -> usize {
        self.len.div_ceil(size)
    }
    /// Piece `c` of `size` items (empty past the end).
    ///
    /// # Safety
    /// The slice outlives the result, and no other live reference overlaps it.
    #[inline(always)]
    pub unsafe fn piece<'a>(self, size: usize, c: usize) -> &'a mut [T] {
        let (start, end) = ((c * size).min(self.len), ((c + 1) * size).min(self.len));
        std::slice::from_raw_parts_mut(self.p.get().add(start), end - start)
    }
    /// Item `i` (`i < len`).
    ///
    /// # Safety
    /// As `piece`.
    #[inline(always)]
    pub unsafe fn at<'a>(self, i: usize) -> &'a mut T {
        debug_assert!(i < self.len);
        &mut *self.p.get().add(i)
    }
}

/// A raw pointer shared by the threads of a parallel pass in which each thread writes a disjoint
/// set of indices (a scatter through a permutation, the cell-list sort).
pub struct SyncPtr<T>(pub *mut T);
// By hand: the derives would ask `T: Copy`, and a pointer copies whatever it points to.
impl<T> Clone for SyncPtr<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for SyncPtr<T> {}
unsafe impl<T> Send for SyncPtr<T> {}
unsafe impl<T> Sync for SyncPtr<T> {}
impl<T> SyncPtr<T> {
    #[inline(always)]
    pub fn get(self) -> *mut T {
        self.0
    }
}
