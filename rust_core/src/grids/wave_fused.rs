//! Several leapfrog steps in one sweep over memory (temporal blocking) for the plain 2D wave (no
//! damping, layers, obstacles or oscillators; y faces fixed or free). A single step reads u, u⁻
//! and writes u⁺ over u⁻, ~24 bytes per cell for ~9 flops: it runs at the memory's speed. A
//! sweep that makes `K` steps moves those bytes once for all K.
//!
//! Buffers: A = uⁿ (level 0), B = uⁿ⁻¹ (level −1). The rows are split into bands, run in
//! parallel. Band [a, b) makes level j (1..=K) of the rows within K − j of it (overlapped
//! tiling: halo rows are made again by each band that needs them), in a wavefront: at time `e`
//! it makes level j of row e − (j − 1), whose inputs — level j − 1 of the rows around it and
//! level j − 2 of the row itself — were just made. Levels 1..K − 1 live in rings of 3 rows
//! (in cache). Level K of row s is written over B's row s, and level K − 1 over A's row s two
//! times later, once level 1 and 2 no longer read it; the caller then swaps A and B. Rows of
//! other bands are read from copies taken before the sweep (their owners overwrite them).
//!
//! Every cell of every level is the single step's undamped expression, in the same order, from
//! the same inputs, so K fused steps give the bits of K single steps, for any split into bands.
use super::Grid;
use crate::simd::{Kernel, Simd, P};
use crate::vector::Real;

/// Steps per sweep. A band's rings hold 3 rows per level between: (K − 1)·3·nx values, 240 KiB
/// at nx = 2048 — inside a core's L2.
pub(super) const FUSE: usize = 6;

/// uⁿ⁺¹ of one row into `out` from uⁿ's rows `c`, `s`, `n` (south and north, with their
/// edge factors) and uⁿ⁻¹'s row `um`: 2c − um + k·(l + r + fs·s + fn·n − 4c), the single
/// step's undamped expression in the same order, in lanes (no fused multiply–adds: the same
/// bits at every level). Returns whether the row came out finite: Σ (x − x), made in the loop,
/// is 0 unless some x is not (a plain Σ x could overflow where no x does).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn leap<S: Simd>(
    sd: S,
    g: &Grid,
    c: &[Real],
    s: &[Real],
    fs: Real,
    n: &[Real],
    fn_: Real,
    um: &[Real],
    out: &mut [Real],
    k: Real,
) -> bool {
    let nx = c.len();
    let (g0, g1) = (g.ghost_x(c, 0), g.ghost_x(c, 1));
    let cell = |i: usize, left: Real, right: Real| -> Real {
        let lap = left + right + fs * s[i] + fn_ * n[i] - 4.0 * c[i];
        2.0 * c[i] - um[i] + k * lap
    };
    out[0] = cell(0, g0, c[1]);
    out[nx - 1] = cell(nx - 1, c[nx - 2], g1);
    let mut fine = out[0].is_finite() && out[nx - 1].is_finite();
    let l = P::<S, Real>::lanes();
    let sp = |x: Real| P::<S, Real>::splat(sd, x);
    let (p2, p4, pk, pfs, pfn) = (sp(2.0), sp(4.0), sp(k), sp(fs), sp(fn_));
    let mut acc = P::<S, Real>::zero(sd);
    let m = nx - 2;
    let blocks = m / l;
    for b in 0..blocks {
        let j = b * l;
        let cw = &c[j..j + l + 2];
        let ld = |a: &[Real], o: usize| P::<S, Real>::load(sd, &a[o..]);
        let one = |a: &[Real]| P::<S, Real>::load(sd, &a[j + 1..j + 1 + l]);
        let cc = ld(cw, 1);
        let lap = ld(cw, 0) + ld(cw, 2) + pfs * one(s) + pfn * one(n) - p4 * cc;
        let o = p2 * cc - one(um) + pk * lap;
        o.store(&mut out[j + 1..j + 1 + l]);
        acc = acc + nan_unless_finite(o);
    }
    for i in blocks * l + 1..nx - 1 {
        out[i] = cell(i, c[i - 1], c[i + 1]);
        fine &= out[i].is_finite();
    }
    fine && acc.sum() == 0.0
}

/// x − x: 0 in every lane where x is finite, NaN where it is not.
#[inline(always)]
#[allow(clippy::eq_op)]
fn nan_unless_finite<S: Simd>(x: P<S, Real>) -> P<S, Real> {
    x - x
}

/// Where a sweep's bands are and their scratch.
#[derive(Default)]
pub(super) struct Scratch {
    /// Per band, copies of the rows of other bands it reads: A's K rows below and K above, then
    /// B's (4·K·nx values).
    saved: Vec<Real>,
    /// Per band, the rings of levels 1..K − 1 ((K − 1)·3·nx values).
    rings: Vec<Real>,
    /// Per band, whether each level's rows came out finite.
    oks: Vec<[bool; FUSE]>,
}

/// `k` steps (2 ≤ k ≤ `FUSE`) of A = uⁿ, B = uⁿ⁻¹ with coefficient `kc` = (c·dt/dx)²: on
/// return B holds uⁿ⁺ᵏ and A uⁿ⁺ᵏ⁻¹. Returns whether each level came out finite (`None` if
/// the scratch could not be allocated; nothing has changed then).
pub(super) fn sweep(
    g: &Grid,
    kc: Real,
    k: usize,
    a: &mut [Real],
    b: &mut [Real],
    scratch: &mut Scratch,
) -> Option<[bool; FUSE]> {
    use rayon::prelude::*;
    debug_assert!((2..=FUSE).contains(&k));
    let (nx, rows) = (g.n[0], g.rows());
    let (band, bands) = super::fused_bands(rows);
    let (saved_len, ring_len) = (4 * k * nx, (k - 1) * 3 * nx);
    if !(super::grow(&mut scratch.saved, bands * saved_len)
        && super::grow(&mut scratch.rings, bands * ring_len)
        && super::grow(&mut scratch.oks, bands))
    {
        return None;
    }
    let saved = &mut scratch.saved[..bands * saved_len];
    for (i, sv) in saved.chunks_mut(saved_len).enumerate() {
        let (r0, r1) = (i * band, ((i + 1) * band).min(rows));
        for (src, at) in [(&*a, 0), (&*b, 2 * k)] {
            for s in r0.saturating_sub(k)..r0 {
                sv[(at + s + k - r0) * nx..][..nx].copy_from_slice(&src[s * nx..][..nx]);
            }
            for s in r1..(r1 + k).min(rows) {
                sv[(at + k + s - r1) * nx..][..nx].copy_from_slice(&src[s * nx..][..nx]);
            }
        }
    }
    let saved = &*saved;
    let (rings, oks) = (&mut scratch.rings[..bands * ring_len], &mut scratch.oks[..bands]);
    let level = crate::simd::level();
    type Job<'x> = (usize, (((&'x mut [Real], &'x mut [Real]), &'x mut [Real]), &'x mut [bool; FUSE]));
    let job = |(i, (((own_a, own_b), ring), ok)): Job| {
        let saved = &saved[i * saved_len..][..saved_len];
        *ok = crate::simd::dispatch(level, Band { g, kc, k, r0: i * band, own_a, own_b, saved, ring });
    };
    let forked = crate::par::fork_if(a.len(), || {
        a.par_chunks_mut(band * nx)
            .zip(b.par_chunks_mut(band * nx))
            .zip(rings.par_chunks_mut(ring_len))
            .zip(oks.par_iter_mut())
            .enumerate()
            .for_each(job)
    });
    if forked.is_none() {
        a.chunks_mut(band * nx)
            .zip(b.chunks_mut(band * nx))
            .zip(rings.chunks_mut(ring_len))
            .zip(oks.iter_mut())
            .enumerate()
            .for_each(job);
    }
    let mut ok = [true; FUSE];
    for o in oks.iter() {
        for j in 0..FUSE {
            ok[j] &= o[j];
        }
    }
    Some(ok)
}

/// Level `lv` (−1 = B, 0 = A, ≥ 1 the rings, `rings` starting at level 1) of row `x` of the
/// band [a, b): its own rows of A and B, the saved copies of other bands' rows, or a ring.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn level_row<'x>(
    lv: isize,
    x: isize,
    (a, b): (isize, isize),
    kk: isize,
    nx: usize,
    own_a: &'x [Real],
    own_b: &'x [Real],
    saved: &'x [Real],
    rings: &'x [Real],
) -> &'x [Real] {
    if lv >= 1 {
        return &rings[(((lv - 1) * 3 + x.rem_euclid(3)) as usize) * nx..][..nx];
    }
    if (a..b).contains(&x) {
        let own = if lv == 0 { own_a } else { own_b };
        return &own[((x - a) as usize) * nx..][..nx];
    }
    let at = if lv < 0 { 2 * kk } else { 0 };
    let r = if x < a { at + x + kk - a } else { at + kk + x - b };
    &saved[(r as usize) * nx..][..nx]
}

/// Levels 1..=k of the band whose first row is `r0` and whose rows of A and B are `own_a`,
/// `own_b`; `saved` holds the other bands' rows it reads, `ring` its rings. Returns whether
/// each level's rows of this band came out finite.
struct Band<'a> {
    g: &'a Grid,
    kc: Real,
    k: usize,
    r0: usize,
    own_a: &'a mut [Real],
    own_b: &'a mut [Real],
    saved: &'a [Real],
    ring: &'a mut [Real],
}

impl Kernel for Band<'_> {
    type Output = [bool; FUSE];
    #[inline(always)]
    fn run<S: Simd>(self, sd: S) -> [bool; FUSE] {
        let Band { g, kc, k, r0, own_a, own_b, saved, ring } = self;
        run_band(sd, g, kc, k, r0, own_a, own_b, saved, ring)
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn run_band<S: Simd>(
    sd: S,
    g: &Grid,
    kc: Real,
    k: usize,
    r0: usize,
    own_a: &mut [Real],
    own_b: &mut [Real],
    saved: &[Real],
    ring: &mut [Real],
) -> [bool; FUSE] {
    let nx = g.n[0];
    let rows = g.rows() as isize;
    let ab @ (a, b) = (r0 as isize, (r0 + own_a.len() / nx) as isize);
    let kk = k as isize;
    let mut ok = [true; FUSE];
    // The rows level j makes (y faces are not periodic: clamped to the grid).
    let range = |j: isize| ((a - (kk - j)).max(0), (b + (kk - j)).min(rows));
    let last = |s: isize| ((((kk - 2) * 3 + s.rem_euclid(3)) as usize) * nx, ((s - a) as usize) * nx);
    for e in range(1).0..b + kk - 1 {
        for (j, s) in super::wavefront(kk, e, &range) {
            let (sr, fs) = g.neighbour_row(s as usize, 1, 0);
            let (nr, fn_) = g.neighbour_row(s as usize, 1, 1);
            let (lower, upper) = ring.split_at_mut(((j - 1) * 3) as usize * nx);
            // Level j − 1 of rows s, south and north, and level j − 2 of row s.
            let inputs = |oa, ob| {
                let get = |lv: isize, x: isize| level_row(lv, x, ab, kk, nx, oa, ob, saved, lower);
                (get(j - 1, s), get(j - 1, sr as isize), get(j - 1, nr as isize), get(j - 2, s))
            };
            let fine = if j < kk {
                let (c, sv, nv, um) = inputs(own_a, own_b);
                leap(sd, g, c, sv, fs, nv, fn_, um, &mut upper[(s.rem_euclid(3) as usize) * nx..][..nx], kc)
            } else {
                // Level k reads levels ≥ 0 only, never B.
                let (c, sv, nv, um) = inputs(own_a, &[]);
                leap(sd, g, c, sv, fs, nv, fn_, um, &mut own_b[((s - a) as usize) * nx..][..nx], kc)
            };
            if (a..b).contains(&s) {
                ok[(j - 1) as usize] &= fine;
            }
        }
        // Level k − 1 of row e − k over A: levels 1 and 2 have read A's row for the last time.
        let s = e - kk;
        if (a..b).contains(&s) {
            let (from, to) = last(s);
            own_a[to..][..nx].copy_from_slice(&ring[from..][..nx]);
        }
    }
    // The band's last row, whose time to be written comes after the loop.
    let (from, to) = last(b - 1);
    own_a[to..][..nx].copy_from_slice(&ring[from..][..nx]);
    ok
}
