//! Deterministic parallel loops. Work is split into fixed chunks of `CHUNK` items whatever the
//! thread count, and reductions add chunk partials in chunk order, so 1 and many threads give
//! bit-identical results. Small problems run the same chunks serially (rayon's fork-join costs
//! microseconds, which dominates a 2-body orbit).
use rayon::prelude::*;
use std::ops::Range;

pub const CHUNK: usize = 1024;
/// Below this many items a loop runs serially (same chunks, same order, same result).
pub const PAR_MIN: usize = 4 * CHUNK;

#[inline]
fn ranges(n: usize) -> impl Iterator<Item = Range<usize>> + Clone {
    (0..n.div_ceil(CHUNK)).map(move |c| c * CHUNK..((c + 1) * CHUNK).min(n))
}

/// `f(start, chunk)` on consecutive chunks of `a`.
pub fn chunks1<A: Send>(a: &mut [A], f: impl Fn(usize, &mut [A]) + Sync + Send) {
    if a.len() >= PAR_MIN {
        a.par_chunks_mut(CHUNK).enumerate().for_each(|(c, a)| f(c * CHUNK, a));
    } else {
        a.chunks_mut(CHUNK).enumerate().for_each(|(c, a)| f(c * CHUNK, a));
    }
}

/// `f(start, chunk_a, chunk_b)` on matching chunks of two equally long slices.
pub fn chunks2<A: Send, B: Send>(
    a: &mut [A],
    b: &mut [B],
    f: impl Fn(usize, &mut [A], &mut [B]) + Sync + Send,
) {
    debug_assert_eq!(a.len(), b.len());
    if a.len() >= PAR_MIN {
        a.par_chunks_mut(CHUNK)
            .zip(b.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (a, b))| f(c * CHUNK, a, b));
    } else {
        a.chunks_mut(CHUNK)
            .zip(b.chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (a, b))| f(c * CHUNK, a, b));
    }
}

/// `f(start, a, b, c)` on matching chunks of three equally long slices.
pub fn chunks3<A: Send, B: Send, C: Send>(
    a: &mut [A],
    b: &mut [B],
    c: &mut [C],
    f: impl Fn(usize, &mut [A], &mut [B], &mut [C]) + Sync + Send,
) {
    if a.len() >= PAR_MIN {
        a.par_chunks_mut(CHUNK)
            .zip(b.par_chunks_mut(CHUNK))
            .zip(c.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(k, ((a, b), c))| f(k * CHUNK, a, b, c));
    } else {
        a.chunks_mut(CHUNK)
            .zip(b.chunks_mut(CHUNK))
            .zip(c.chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(k, ((a, b), c))| f(k * CHUNK, a, b, c));
    }
}

/// `f(start, a, b, c, d)` on matching chunks of four equally long slices.
pub fn chunks4<A: Send, B: Send, C: Send, D: Send>(
    a: &mut [A],
    b: &mut [B],
    c: &mut [C],
    d: &mut [D],
    f: impl Fn(usize, &mut [A], &mut [B], &mut [C], &mut [D]) + Sync + Send,
) {
    if a.len() >= PAR_MIN {
        a.par_chunks_mut(CHUNK)
            .zip(b.par_chunks_mut(CHUNK))
            .zip(c.par_chunks_mut(CHUNK))
            .zip(d.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(k, (((a, b), c), d))| f(k * CHUNK, a, b, c, d));
    } else {
        a.chunks_mut(CHUNK)
            .zip(b.chunks_mut(CHUNK))
            .zip(c.chunks_mut(CHUNK))
            .zip(d.chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(k, (((a, b), c), d))| f(k * CHUNK, a, b, c, d));
    }
}

/// Deterministic sum of `f(range)` over fixed chunks of `0..n`.
pub fn sum<T>(n: usize, zero: T, f: impl Fn(Range<usize>) -> T + Sync + Send) -> T
where
    T: Send + Copy + std::ops::Add<Output = T>,
{
    reduce(n, zero, |a, b| a + b, f)
}

/// Deterministic sum where each chunk also writes into its own slice of `out` (fused pass).
pub fn chunks1_sum<A: Send>(
    a: &mut [A],
    f: impl Fn(usize, &mut [A]) -> f64 + Sync + Send,
) -> f64 {
    chunks1_fold(a, 0.0, |a, b| a + b, f)
}

/// Like `chunks2`, with each chunk returning a value; the values are folded in chunk order
/// (deterministic for any thread count).
pub fn chunks2_fold<A: Send, B: Send, T: Send>(
    a: &mut [A],
    b: &mut [B],
    zero: T,
    fold: impl Fn(T, T) -> T,
    f: impl Fn(usize, &mut [A], &mut [B]) -> T + Sync + Send,
) -> T {
    let partials: Vec<T> = if a.len() >= PAR_MIN {
        a.par_chunks_mut(CHUNK).zip(b.par_chunks_mut(CHUNK)).enumerate().map(|(c, (a, b))| f(c * CHUNK, a, b)).collect()
    } else {
        a.chunks_mut(CHUNK).zip(b.chunks_mut(CHUNK)).enumerate().map(|(c, (a, b))| f(c * CHUNK, a, b)).collect()
    };
    partials.into_iter().fold(zero, fold)
}

/// Like `chunks1`, with each chunk returning a value folded in chunk order (deterministic).
pub fn chunks1_fold<A: Send, T: Send>(
    a: &mut [A],
    zero: T,
    fold: impl Fn(T, T) -> T,
    f: impl Fn(usize, &mut [A]) -> T + Sync + Send,
) -> T {
    let partials: Vec<T> = if a.len() >= PAR_MIN {
        a.par_chunks_mut(CHUNK).enumerate().map(|(c, a)| f(c * CHUNK, a)).collect()
    } else {
        a.chunks_mut(CHUNK).enumerate().map(|(c, a)| f(c * CHUNK, a)).collect()
    };
    partials.into_iter().fold(zero, fold)
}

/// Deterministic fold of `f(range)` over fixed chunks of `0..n` (e.g. a maximum).
pub fn reduce<T: Send>(n: usize, zero: T, fold: impl Fn(T, T) -> T, f: impl Fn(Range<usize>) -> T + Sync + Send) -> T {
    let partials: Vec<T> = if n >= PAR_MIN {
        ranges(n).collect::<Vec<_>>().into_par_iter().map(&f).collect()
    } else {
        ranges(n).map(&f).collect()
    };
    partials.into_iter().fold(zero, fold)
}

/// `chunks2` whose chunks raise a flag; returns whether any did.
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
