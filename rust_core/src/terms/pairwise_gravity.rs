//! Pairwise Newtonian gravity with Plummer softening, by direct summation (O(N²), parallel over
//! the receiving particle).
//!
//! a_i = G Σ_j m_j (x_j − x_i) / (|x_j − x_i|² + ε²)^{3/2}        (Plummer 1911; Aarseth 2003, eq. 2.4)
//! U   = −G Σ_{i<j} m_i m_j / (|x_j − x_i|² + ε²)^{1/2}
//!
//! The kernel is the softened inverse-square sum S_i = Σ_j w_j (x_j − x_i) / (|x_j − x_i|² + ε²)^{3/2}
//! of source weights w_j, scaled per receiver: gravity takes w = m and F_i = G m_i S_i; the
//! Coulomb force (`super::coulomb`) takes w = q and F_i = −k q_i S_i (a `Law` says which). The
//! weights only change what is packed: the loops are the same for both.
//!
//! The inner loop runs over a structure-of-arrays copy of the sources, one SIMD vector of sources
//! at a time, written once over the portable SIMD layer (`crate::simd`) for f32 and f64 and every
//! instruction set: 1/r comes from the layer's fast reciprocal square root (hardware estimate plus
//! Newton steps), not a square root and a division, which would bound the loop at several cycles
//! per pair. Results never depend on the thread count; levels differ by a few ulp.
//!
//! Up to `pairwise_small::SMALL` bodies in float64 the sum is `pairwise_small`'s instead: each
//! pair once, in plain IEEE operations, the same bits on every SIMD level (and the same bits as
//! a batch's fused kernel, `crate::batch`).
//!
//! With a single-precision state the sum runs in float32 (twice the lanes per instruction). The
//! positions are then float32 values already, so differences lose nothing more.
//!
//! One evaluation at N = 10⁵ is seconds of work, so the kernels read the stop flag of the call
//! (`crate::stop`) before every block of 16 receivers (direct sum) or every tile of 2–4 receivers
//! (symmetric sum, whose blocks are N/32), i.e. every ~N·16 pairs at most, and skip the rest once
//! it is set.
use super::pairwise_small::{small_sum, SMALL};
use super::registry::{Context, Params};
use super::{FusedForce, Scratch, Setting, Term, Traits, Write};
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::par;
use crate::simd::{self, Float, Kernel, Level, Simd, P};
use crate::state::Model;
use crate::stop::Stop;
use crate::vector::{Real, Vector};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// Sources are padded with massless points to a multiple of the widest vector (16 f32 lanes).
const PAD: usize = 16;

/// Structure-of-arrays copy of the sources, padded with massless points.
#[derive(Default)]
struct Soa<T> {
    xs: Vec<T>,
    ys: Vec<T>,
    zs: Vec<T>,
    ms: Vec<T>,
}

impl<T: Float> Soa<T> {
    /// The sources of `r` (whole vectors of `l` lanes: `r` starts on a lane boundary and the
    /// padding completes the last one) as (x, y, z, m) slices of `l` values each.
    #[inline(always)]
    fn vectors(&self, r: std::ops::Range<usize>, l: usize) -> impl Iterator<Item = (&[T], &[T], &[T], &[T])> {
        let (x, y, z, m) = (&self.xs[r.clone()], &self.ys[r.clone()], &self.zs[r.clone()], &self.ms[r]);
        x.chunks_exact(l)
            .zip(y.chunks_exact(l))
            .zip(z.chunks_exact(l))
            .zip(m.chunks_exact(l))
            .map(|(((x, y), z), m)| (x, y, z, m))
    }

    /// Room for `n` sources.
    fn reserve(&mut self, n: usize, need: &Need) -> Result<()> {
        let np = n.div_ceil(PAD) * PAD;
        for a in [&mut self.xs, &mut self.ys, &mut self.zs, &mut self.ms] {
            need.reserve(a, np)?;
        }
        Ok(())
    }

    /// The sources `x` with weights `w` (masses for gravity, charges for Coulomb).
    fn pack<V: Vector>(&mut self, x: &[V], w: &[Real]) {
        let np = x.len().div_ceil(PAD) * PAD;
        for a in [&mut self.xs, &mut self.ys, &mut self.zs, &mut self.ms] {
            a.clear();
            a.resize(np, T::ZERO);
        }
        for (i, p) in x.iter().enumerate() {
            self.xs[i] = T::of(p.comp(0));
            self.ys[i] = T::of(p.comp(1));
            if V::DIM == 3 {
                self.zs[i] = T::of(p.comp(2));
            }
            self.ms[i] = T::of(w[i]);
        }
    }
}

/// The inverse-square law a `Pairwise` term sums.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Law {
    /// Newtonian gravity with constant G (m³/(kg·s²)): sources weighted by mass, attractive.
    Gravity(Real),
    /// Coulomb's law with constant k (N·m²/C²): sources weighted by the `charge` attribute;
    /// like charges repel. Without the attribute there is no force.
    Coulomb(Real),
}

/// Softened inverse-square forces between every pair of particles (gravity or Coulomb).
pub struct Pairwise {
    pub name: String,
    pub law: Law,
    /// Plummer softening length ε, m.
    pub softening: Real,
    src: Soa<Real>,
    /// Single-precision state: the sources in float32 and the float32 kernel.
    single: bool,
    src32: Soa<f32>,
    /// Scratch: accelerations / G of the last evaluation, and the symmetric sum's column sums.
    acc: Vec<[Real; 3]>,
    sym: SymScratch<Real>,
    sym32: SymScratch<f32>,
    /// The stop flag of the call in progress.
    stop: Stop,
    /// Gravity only: the body whose pairs the forces leave out (`Setting::KeplerCentre`).
    kepler_centre: Option<usize>,
    /// The potential's sources (the energy books are read through `&self`), reserved by
    /// `reserve_potential` so that reading them allocates nothing sized by N.
    pot: std::sync::Mutex<Soa<Real>>,
}

fn build<V: Vector>(name: String, p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    let (g, softening) = (p.number("G")?, p.number("softening")?);
    if g <= 0.0 {
        return Err(invalid("G", format!("{g} must be finite and > 0")));
    }
    if softening < 0.0 {
        return Err(invalid("softening", format!("{softening} must be finite and >= 0")));
    }
    Ok(Box::new(PairwiseGravity::new(name, g, softening)))
}
crate::register_term!("pairwise_gravity", build);

/// Pairwise gravity is the `Gravity` law of `Pairwise`.
pub type PairwiseGravity = Pairwise;

impl Pairwise {
    /// Gravity with constant `g` and Plummer softening `softening`.
    pub fn new(name: String, g: Real, softening: Real) -> Self {
        Self::with_law(name, Law::Gravity(g), softening)
    }

    /// The Coulomb force with constant `k` and Plummer softening `softening`.
    pub fn coulomb(name: String, k: Real, softening: Real) -> Self {
        Self::with_law(name, Law::Coulomb(k), softening)
    }

    fn with_law(name: String, law: Law, softening: Real) -> Self {
        Self {
            name,
            law,
            softening,
            src: Soa::default(),
            single: false,
            src32: Soa::default(),
            acc: Vec::new(),
            sym: SymScratch::default(),
            sym32: SymScratch::default(),
            stop: Stop::default(),
            kepler_centre: None,
            pot: std::sync::Mutex::new(Soa::default()),
        }
    }
}

/// Accelerations / G of receivers `rows` (indices into the sources) into `out` (one `[ax, ay, az]`
/// per row): Σ_j m_j d_j (|d_j|² + ε²)^{-3/2}, one SIMD vector of sources at a time, lanes summed
/// at the end.
struct Accel<'a, F: Float> {
    src: &'a Soa<F>,
    eps2: F,
    rows: std::ops::Range<usize>,
    out: &'a mut [[Real; 3]],
}

impl<F: Float> Kernel for Accel<'_, F> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        let all = 0..self.src.xs.len();
        for (i, out) in self.rows.zip(self.out.iter_mut()) {
            *out = direct(s, self.src, all.clone(), i, self.eps2);
        }
    }
}

/// Σ_j m_j d_j (|d_j|² + ε²)^{-3/2} over the sources `js` (whole vectors) for receiver `i`, one
/// SIMD vector of sources at a time, lanes summed at the end; returns (ax, ay, az) / G.
#[inline(always)]
fn direct<S: Simd, F: Float>(s: S, src: &Soa<F>, js: std::ops::Range<usize>, i: usize, eps2: F) -> [Real; 3] {
    let Soa { xs, ys, zs, .. } = src;
    let l = P::<S, F>::lanes();
    let (zero, eps2) = (P::<S, F>::zero(s), P::splat(s, eps2));
    let (xi, yi, zi) = (P::splat(s, xs[i]), P::splat(s, ys[i]), P::splat(s, zs[i]));
    let (mut ax, mut ay, mut az) = (zero, zero, zero);
    for (bx, by, bz, bm) in src.vectors(js, l) {
        let dx = P::load(s, bx) - xi;
        let dy = P::load(s, by) - yi;
        let dz = P::load(s, bz) - zi;
        let r2 = dx.mul_add(dx, dy.mul_add(dy, dz.mul_add(dz, eps2)));
        let y = r2.rsqrt();
        // r² = 0 only for the self term (or coincident points without softening): no force.
        let w = r2.gt(zero).select(P::load(s, bm) * (y * y * y), zero);
        ax = w.mul_add(dx, ax);
        ay = w.mul_add(dy, ay);
        az = w.mul_add(dz, az);
    }
    [ax.sum().f64(), ay.sum().f64(), az.sum().f64()]
}

/// Receivers per parallel task: O(N) work each, so small tasks balance well.
const ROWS: usize = 16;

/// Accelerations / G of every source (one `[ax, ay, az]` each), in parallel over fixed blocks of
/// receivers (the same result for any thread count). Once `stop` is set the remaining blocks
/// are skipped (their rows are left as they were).
fn accelerations<F: Float>(src: &Soa<F>, n: usize, eps2: F, level: Level, stop: &AtomicBool, out: &mut Vec<[Real; 3]>) {
    out.clear();
    out.resize(n, [0.0; 3]);
    let block = |(c, out): (usize, &mut [[Real; 3]])| {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        let r = c * ROWS..c * ROWS + out.len();
        simd::dispatch(level, Accel { src, eps2, rows: r, out });
    };
    // O(N) work per item: parallel from a few dozen particles on.
    if n < 64 || par::fork(|| out.par_chunks_mut(ROWS).enumerate().for_each(block)).is_none() {
        out.chunks_mut(ROWS).enumerate().for_each(block);
    }
}

/// Σ_{i ∈ rows} m_i Σ_{j>i} m_j (|x_j − x_i|² + ε²)^{-1/2}, the pairs' potential / (−G): the
/// sources before the first lane boundary past i one by one, then whole SIMD vectors (the
/// padding is massless). Pairs at r = 0 (coincident, unsoftened) contribute nothing.
struct Potential<'a> {
    src: &'a Soa<Real>,
    eps2: Real,
    rows: std::ops::Range<usize>,
    stop: &'a AtomicBool,
}

impl Kernel for Potential<'_> {
    type Output = Real;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> Real {
        let Soa { xs, ys, zs, ms } = self.src;
        let l = P::<S, Real>::lanes();
        let (zero, eps2) = (P::<S, Real>::zero(s), P::splat(s, self.eps2));
        let mut u = 0.0;
        for i in self.rows {
            if self.stop.load(Ordering::Relaxed) {
                break;
            }
            let head = (i + 1).div_ceil(l) * l;
            let mut row = 0.0;
            for j in i + 1..head {
                let (dx, dy, dz) = (xs[j] - xs[i], ys[j] - ys[i], zs[j] - zs[i]);
                let r2 = dx.mul_add(dx, dy.mul_add(dy, dz.mul_add(dz, self.eps2)));
                if r2 > 0.0 {
                    row += ms[j] / r2.sqrt();
                }
            }
            let (xi, yi, zi) = (P::splat(s, xs[i]), P::splat(s, ys[i]), P::splat(s, zs[i]));
            let mut acc = zero;
            for (bx, by, bz, bm) in self.src.vectors(head..xs.len(), l) {
                let dx = P::load(s, bx) - xi;
                let dy = P::load(s, by) - yi;
                let dz = P::load(s, bz) - zi;
                let r2 = dx.mul_add(dx, dy.mul_add(dy, dz.mul_add(dz, eps2)));
                acc = acc + r2.gt(zero).select(P::load(s, bm) * r2.rsqrt(), zero);
            }
            u += ms[i] * (row + acc.sum());
        }
        u
    }
}

/// Column sums of one task of the symmetric sum: −Σ_i m_i d_ij (|d_ij|² + ε²)^{-3/2} for every
/// source j (structure of arrays, one entry per padded source).
#[derive(Default)]
struct Cols<F> {
    x: Vec<F>,
    y: Vec<F>,
    z: Vec<F>,
}

/// Scratch of the symmetric sum, per precision.
#[derive(Default)]
struct SymScratch<F> {
    cols: Vec<Cols<F>>,
}

/// Receivers `block` (starting on a lane boundary) of the symmetric sum: their own block by
/// direct summation, and every source past `beyond` (the block's end, on a lane boundary) once
/// per pair, adding the pair's reaction on the source into `cols` (Newton's third law: each
/// pair's 1/r³ is computed once, not twice). `MASK`: guard r² = 0 (only without softening).
struct Sym<'a, F: Float, const MASK: bool> {
    src: &'a Soa<F>,
    /// Read before every tile of receivers: the rest of the block is skipped once it is set.
    stop: &'a AtomicBool,
    eps2: F,
    block: std::ops::Range<usize>,
    beyond: usize,
    out: &'a mut [[Real; 3]],
    cols: &'a mut Cols<F>,
}

impl<F: Float, const MASK: bool> Kernel for Sym<'_, F, MASK> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        // Receivers in tiles of R: each source vector and its column sums are loaded once per
        // tile, not once per receiver, and the tile's reactions are added to the column sums in
        // registers (in receiver order: the same bits as one receiver at a time). R = 4 fills 32
        // registers (AVX-512, NEON), R = 2 sixteen (AVX2, scalar).
        if S::REGISTERS >= 32 {
            self.tiles::<S, 4>(s);
        } else {
            self.tiles::<S, 2>(s);
        }
    }
}

impl<F: Float, const MASK: bool> Sym<'_, F, MASK> {
    #[inline(always)]
    fn tiles<S: Simd, const R: usize>(self, s: S) {
        let l = P::<S, F>::lanes();
        let own = self.block.start..self.block.start + self.block.len().div_ceil(l) * l;
        let far = self.beyond..self.src.xs.len();
        let Sym { src, stop, eps2, block, out, cols, .. } = self;
        let mut rows = block.clone().zip(out.iter_mut());
        loop {
            // Read before every tile (at most R receivers, each O(N) work).
            if stop.load(Ordering::Relaxed) {
                return;
            }
            let tile: [Option<(usize, &mut [Real; 3])>; R] = std::array::from_fn(|_| rows.next());
            match tile {
                _ if tile.iter().all(Option::is_some) => {
                    let i0 = tile[0].as_ref().map_or(0, |t| t.0);
                    let far_sums = far_tile::<S, F, R, MASK>(s, src, far.clone(), i0, eps2, cols);
                    for (t, a) in tile.into_iter().zip(far_sums) {
                        let (i, o) = t.expect("whole tile");
                        let near = direct(s, src, own.clone(), i, eps2);
                        *o = [near[0] + a[0], near[1] + a[1], near[2] + a[2]];
                    }
                }
                _ => {
                    // The block's last receivers, one at a time.
                    for (i, o) in tile.into_iter().flatten() {
                        let a = far_tile::<S, F, 1, MASK>(s, src, far.clone(), i, eps2, cols)[0];
                        let near = direct(s, src, own.clone(), i, eps2);
                        *o = [near[0] + a[0], near[1] + a[1], near[2] + a[2]];
                    }
                    return;
                }
            }
        }
    }
}

/// Receivers `i0 .. i0 + R` against the sources `far` (whole vectors, all past the receivers):
/// returns each receiver's row sum Σ_j m_j d_ij (|d_ij|² + ε²)^{-3/2} and adds each pair's
/// reaction −m_i d_ij (…)^{-3/2} to the column sums `cols`, receivers in order.
#[inline(always)]
fn far_tile<S: Simd, F: Float, const R: usize, const MASK: bool>(
    s: S,
    src: &Soa<F>,
    far: std::ops::Range<usize>,
    i0: usize,
    eps2: F,
    cols: &mut Cols<F>,
) -> [[Real; 3]; R] {
    let Soa { xs, ys, zs, ms } = src;
    let l = P::<S, F>::lanes();
    let (zero, eps2) = (P::<S, F>::zero(s), P::splat(s, eps2));
    // Plain loops, not `std::array::from_fn` / `map` (here and at the end): their closures run
    // behind core's generic `try_from_fn` / `try_map`, which in a build of several codegen units
    // stayed out of line, compiled without the level's features, so every splat and lane sum
    // became a call (N-body 2048: 1.11x the time in 16 units; see Cargo.toml).
    let mut xi = [[zero; 3]; R];
    // −m_i hoisted: the reaction is one FMA per component (negation is exact).
    let mut nmi = [zero; R];
    // One receiver in `S::SPLIT_RSQRT` takes f64 1/√ through the divider where the level asks
    // for it (a fixed choice per receiver index: the same bits for any tiling and thread count).
    let k = S::SPLIT_RSQRT;
    let mut exact = [false; R];
    for r in 0..R {
        xi[r] = [P::splat(s, xs[i0 + r]), P::splat(s, ys[i0 + r]), P::splat(s, zs[i0 + r])];
        nmi[r] = P::splat(s, -ms[i0 + r]);
        exact[r] = std::mem::size_of::<F>() == 8 && k > 0 && (i0 + r) % k == k - 1;
    }
    let mut acc = [[zero; 3]; R];
    let Cols { x: cx, y: cy, z: cz } = cols;
    let col = cx[far.clone()]
        .chunks_exact_mut(l)
        .zip(cy[far.clone()].chunks_exact_mut(l))
        .zip(cz[far.clone()].chunks_exact_mut(l));
    for ((bx, by, bz, bm), ((ox, oy), oz)) in src.vectors(far, l).zip(col) {
        let (x, y, z, m) = (P::load(s, bx), P::load(s, by), P::load(s, bz), P::load(s, bm));
        let (mut sx, mut sy, mut sz) = (P::load(s, ox), P::load(s, oy), P::load(s, oz));
        for r in 0..R {
            let dx = x - xi[r][0];
            let dy = y - xi[r][1];
            let dz = z - xi[r][2];
            let r2 = dx.mul_add(dx, dy.mul_add(dy, dz.mul_add(dz, eps2)));
            let rinv = if exact[r] { r2.rsqrt_exact() } else { r2.rsqrt() };
            let mut y3 = rinv * rinv * rinv;
            if MASK {
                y3 = r2.gt(zero).select(y3, zero);
            }
            let w = m * y3;
            acc[r][0] = w.mul_add(dx, acc[r][0]);
            acc[r][1] = w.mul_add(dy, acc[r][1]);
            acc[r][2] = w.mul_add(dz, acc[r][2]);
            let wj = nmi[r] * y3;
            sx = wj.mul_add(dx, sx);
            sy = wj.mul_add(dy, sy);
            sz = wj.mul_add(dz, sz);
        }
        sx.store(ox);
        sy.store(oy);
        sz.store(oz);
    }
    let mut sums = [[0.0; 3]; R];
    for r in 0..R {
        sums[r] = [acc[r][0].sum().f64(), acc[r][1].sum().f64(), acc[r][2].sum().f64()];
    }
    sums
}

/// A receiver block of the symmetric sum: its index and its rows of the output.
type Block<'a> = (usize, &'a mut [[Real; 3]]);

impl<F: Float> SymScratch<F> {
    /// Room for the column sums of `n` sources (see `accelerations_sym`).
    fn reserve(&mut self, n: usize, need: &Need) -> Result<()> {
        let np = n.div_ceil(PAD) * PAD;
        let t = n.div_ceil(BLOCKS).div_ceil(PAD) * PAD;
        let ntask = n.div_ceil(t.max(1)).div_ceil(2);
        self.cols.resize_with(ntask, Cols::default);
        for c in &mut self.cols {
            for a in [&mut c.x, &mut c.y, &mut c.z] {
                need.reserve(a, np)?;
            }
        }
        Ok(())
    }
}

/// Receiver blocks of the symmetric sum (a multiple of 16 sources each).
const BLOCKS: usize = 32;
/// Below this many bodies the direct sum is used (the symmetric one's blocks would be tiny).
const SYM_MIN: usize = 1024;

/// Accelerations / G of every source by the symmetric sum: `BLOCKS` receiver blocks; block b
/// interacts directly with itself and once per pair with every later block. Tasks pair block b
/// with block BLOCKS−1−b (equal work) and each owns its column sums; a body's acceleration is its
/// row sum plus the tasks' column sums in task order, so the result does not depend on the
/// thread count. Once `stop` is set the remaining receivers are skipped.
fn accelerations_sym<F: Float>(
    src: &Soa<F>,
    n: usize,
    eps2: F,
    level: Level,
    stop: &AtomicBool,
    scratch: &mut SymScratch<F>,
    out: &mut Vec<[Real; 3]>,
) {
    out.clear();
    out.resize(n, [0.0; 3]);
    let np = src.xs.len();
    let t = n.div_ceil(BLOCKS).div_ceil(PAD) * PAD;
    let nb = n.div_ceil(t);
    let ntask = nb.div_ceil(2);
    scratch.cols.resize_with(ntask, Cols::default);
    for c in &mut scratch.cols {
        for a in [&mut c.x, &mut c.y, &mut c.z] {
            a.clear();
            a.resize(np, F::ZERO);
        }
    }
    // Pair the blocks from both ends: (0, nb−1), (1, nb−2), ...
    let mut blocks: Vec<Option<Block>> = out.chunks_mut(t).enumerate().map(Some).collect();
    let mut tasks = Vec::with_capacity(ntask);
    for k in 0..ntask {
        let a = blocks[k].take().expect("each block once");
        let b = if nb - 1 - k != k { blocks[nb - 1 - k].take() } else { None };
        tasks.push((a, b));
    }
    let mask = eps2 <= F::ZERO;
    let run = |((a, b), cols): ((Block, Option<Block>), &mut Cols<F>)| {
        for (bi, out) in std::iter::once(a).chain(b) {
            let block = bi * t..bi * t + out.len();
            let beyond = (bi + 1) * t;
            let beyond = beyond.min(np);
            if mask {
                simd::dispatch(level, Sym::<F, true> { src, stop, eps2, block, beyond, out, cols });
            } else {
                simd::dispatch(level, Sym::<F, false> { src, stop, eps2, block, beyond, out, cols });
            }
        }
    };
    let cols = &mut scratch.cols;
    let mut tasks = Some(tasks);
    if par::fork(|| tasks.take().unwrap_or_default().into_par_iter().zip(cols.par_iter_mut()).for_each(run)).is_none() {
        tasks.unwrap_or_default().into_iter().zip(cols.iter_mut()).for_each(run);
    }
    let cols = &scratch.cols;
    par::chunks1(out, |s, out| {
        for (k, o) in out.iter_mut().enumerate() {
            let i = s + k;
            for c in cols {
                o[0] += c.x[i].f64();
                o[1] += c.y[i].f64();
                o[2] += c.z[i].f64();
            }
        }
    });
}

impl Pairwise {
    /// The source weights (masses or charges); `None`: no source (a Coulomb term in a scene
    /// without charges), so no force and no potential.
    /// F_i = c w_i S_i: c = G for gravity (w = m), −k for Coulomb (w = q).
    fn law_constant(&self) -> Real {
        match self.law {
            Law::Gravity(g) => g,
            Law::Coulomb(k) => -k,
        }
    }

    fn weights<'a>(&self, model: &'a Model) -> Option<&'a [Real]> {
        match self.law {
            Law::Gravity(_) => Some(&model.mass),
            Law::Coulomb(_) => model.attribute("charge"),
        }
    }
}

impl FusedForce for Pairwise {
    fn small_pairwise<'a>(&self, model: &'a Model, n: usize) -> Option<(Real, Real, &'a [Real])> {
        let w = self.weights(model)?;
        (!self.single && n <= SMALL).then_some((self.law_constant(), self.softening * self.softening, w))
    }
    fn newtonian(&self) -> Option<(Real, Real)> {
        match self.law {
            Law::Gravity(g) => Some((g, self.softening)),
            Law::Coulomb(_) => None,
        }
    }
}

impl<V: Vector> Term<V> for Pairwise {
    fn name(&self) -> &str {
        &self.name
    }
    fn traits(&self) -> Traits<V> {
        Traits { cheap_potential: false, softened: true, ..Traits::conservative() }
    }

    fn set(&mut self, setting: Setting) {
        match setting {
            Setting::Single(single) => self.single = single,
            Setting::Stop(stop) => self.stop = stop,
            Setting::KeplerCentre(c) => self.kepler_centre = c.filter(|_| matches!(self.law, Law::Gravity(_))),
        }
    }

    fn reserve(&mut self, n: usize, scratch: Scratch) -> Result<()> {
        if scratch == Scratch::Potential {
            let np = n.div_ceil(PAD) * PAD;
            let need = Need::new(
                "energy",
                4 * Need::bytes_of::<Real>(np),
                format!("the potential of {} bodies", count(n as u128)),
            );
            need.check()?;
            return self.pot.get_mut().unwrap_or_else(|e| e.into_inner()).reserve(n, &need);
        }
        if n <= SMALL && !self.single && self.acc.capacity() >= n {
            return Ok(()); // the small sum needs only `acc` (a batch prepares thousands of these per call)
        }
        let np = n.div_ceil(PAD) * PAD;
        let f = if self.single { 4 } else { 8 };
        let cols = if n >= SYM_MIN { 3 * (BLOCKS / 2) * np * f } else { 0 };
        let bytes = (4 * np * f + cols) as u128 + Need::bytes_of::<[Real; 3]>(n);
        let what = match self.law {
            Law::Gravity(_) => "pairwise gravity",
            Law::Coulomb(_) => "Coulomb forces",
        };
        let need = Need::new("step", bytes, format!("{what} between {} bodies", count(n as u128)));
        need.check()?;
        need.reserve(&mut self.acc, n)?;
        match (self.single, n >= SYM_MIN) {
            (true, sym) => {
                self.src32.reserve(n, &need)?;
                if sym {
                    self.sym32.reserve(n, &need)?;
                }
            }
            (false, sym) => {
                self.src.reserve(n, &need)?;
                if sym {
                    self.sym.reserve(n, &need)?;
                }
            }
        }
        Ok(())
    }

    fn add_forces(&mut self, x: &[V], _v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let Some(w) = self.weights(model) else {
            // Uncharged: no force.
            if write == Write::Overwrite {
                par::chunks1(f, |_, f| f.fill(V::ZERO));
            }
            return 0.0;
        };
        let eps2 = self.softening * self.softening;
        let level = simd::level();
        let mut acc = std::mem::take(&mut self.acc);
        let n = x.len();
        let stop = self.stop.flag();
        // Without the central body as a source, and with no force on it (Setting::KeplerCentre).
        let centre = self.kepler_centre.filter(|&c| c < n);
        match (self.single, n >= SYM_MIN) {
            (false, _) if n <= SMALL => {
                // Few bodies: the lane-by-lane IEEE sum (`pairwise_small`, module docs there).
                let mut xs = [[0.0; 3]; SMALL];
                for (xs, xi) in xs.iter_mut().zip(x) {
                    for (c, v) in xs.iter_mut().enumerate().take(V::DIM) {
                        *v = xi.comp(c);
                    }
                }
                acc.clear();
                acc.resize(n, [0.0; 3]);
                let mut ws = [0.0; SMALL];
                ws[..n].copy_from_slice(&w[..n]);
                if let Some(c) = centre {
                    ws[c] = 0.0;
                }
                small_sum(&xs[..n], &ws[..n], eps2, V::DIM, 0.0, 1.0, &mut acc);
            }
            (true, sym) => {
                self.src32.pack(x, w);
                if let Some(c) = centre {
                    self.src32.ms[c] = 0.0;
                }
                if sym {
                    accelerations_sym(&self.src32, n, eps2 as f32, level, stop, &mut self.sym32, &mut acc);
                } else {
                    accelerations(&self.src32, n, eps2 as f32, level, stop, &mut acc);
                }
            }
            (false, sym) => {
                self.src.pack(x, w);
                if let Some(c) = centre {
                    self.src.ms[c] = 0.0;
                }
                if sym {
                    accelerations_sym(&self.src, n, eps2, level, stop, &mut self.sym, &mut acc);
                } else {
                    accelerations(&self.src, n, eps2, level, stop, &mut acc);
                }
            }
        }
        let c = self.law_constant();
        par::chunks1(f, |s, f| {
            for (k, fi) in f.iter_mut().enumerate() {
                let i = s + k;
                if model.inv_mass[i] == 0.0 || centre == Some(i) {
                    // Pinned: its force is never used. The Kepler centre: left out.
                    if write == Write::Overwrite {
                        *fi = V::ZERO;
                    }
                    continue;
                }
                let (a, gm) = (acc[i], c * w[i]);
                let fg = V::from_slice(&[a[0] * gm, a[1] * gm, a[2] * gm][..V::DIM]);
                write.put(fi, fg);
            }
        });
        self.acc = acc;
        0.0
    }

    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        let Some(w) = self.weights(model) else {
            return Some(0.0); // uncharged
        };
        let mut src = self.pot.lock().unwrap_or_else(|e| e.into_inner());
        src.pack(x, w);
        let src = &*src;
        let (eps2, level, stop) = (self.softening * self.softening, simd::level(), self.stop.flag());
        // Σ_i m_i Σ_{j>i} m_j / r_ij, rows in fixed chunks summed in chunk order (any thread
        // count gives the same bits). O(N²): the stop flag is read per row and, once it is set,
        // the sum is abandoned (the caller discards it).
        let u = par::sum(x.len(), 0.0, |rows| simd::dispatch(level, Potential { src, eps2, rows, stop }));
        Some(match self.law {
            Law::Gravity(g) => -g * u,
            Law::Coulomb(k) => k * u,
        })
    }

    fn as_fused(&self) -> Option<&dyn FusedForce> {
        Some(self)
    }

    fn time_scale(&self, x: &[V], model: &Model) -> Option<Real> {
        // O(N²): left out above 2·10⁴ bodies (documented at Scene.suggest_dt).
        if x.len() > 20_000 {
            return None;
        }
        match self.law {
            Law::Gravity(g) => encounter_time(g, self.softening, x, model, self.stop.flag()),
            Law::Coulomb(k) => coulomb_time(k, self.softening, x, model, self.stop.flag()),
        }
    }
}

/// Shortest pairwise free-fall time sqrt((r² + ε²)^{3/2} / (G (m_i + m_j))) (s), O(N²), in
/// parallel over fixed chunks of rows on the SIMD layer: the largest (m_i + m_j) / (r² + ε²)^{3/2}
/// (a maximum, exact in any order, so any thread count gives the same bits). Pairs at r = 0
/// (coincident, unsoftened) and massless pairs have no time scale. Once `stop` is set the
/// remaining rows are skipped (the result is then meaningless).
pub fn encounter_time<V: Vector>(g: Real, softening: Real, x: &[V], model: &Model, stop: &AtomicBool) -> Option<Real> {
    let mut src = Soa::<Real>::default();
    src.pack(x, &model.mass);
    let (eps2, level, n) = (softening * softening, simd::level(), x.len());
    let rate = par::reduce(n, 0.0, Real::max, |rows| {
        simd::dispatch(level, Encounter::<false> { src: &src, a: &[], n, eps2, rows, stop })
    });
    // G = 0 (or no pair with a time scale): none.
    (rate > 0.0).then(|| (1.0 / (g * rate)).sqrt()).filter(|t| t.is_finite())
}

/// Shortest pairwise Coulomb time sqrt((r² + ε²)^{3/2} / (k |q_i q_j| (1/m_i + 1/m_j))) (s) over
/// pairs with a free particle (a pinned one's 1/m is 0), the relative motion's time scale; O(N²)
/// on the SIMD layer like `encounter_time` (the largest |q_i||q_j| (1/m_i + 1/m_j) / (r² + ε²)^{3/2}
/// as a_i b_j + a_j b_i with a = |q|/m, b = |q|). None without charges.
fn coulomb_time<V: Vector>(k: Real, softening: Real, x: &[V], model: &Model, stop: &AtomicBool) -> Option<Real> {
    let q = model.attribute("charge")?;
    let b: Vec<Real> = q.iter().map(|q| q.abs()).collect();
    let mut src = Soa::<Real>::default();
    src.pack(x, &b);
    let mut a = vec![0.0; src.xs.len()];
    for (i, ai) in a.iter_mut().enumerate().take(x.len()) {
        *ai = b[i] * model.inv_mass[i];
    }
    let (eps2, level, n) = (softening * softening, simd::level(), x.len());
    let rate = par::reduce(n, 0.0, Real::max, |rows| {
        simd::dispatch(level, Encounter::<true> { src: &src, a: &a, n, eps2, rows, stop })
    });
    (rate > 0.0).then(|| (1.0 / (k * rate)).sqrt()).filter(|t| t.is_finite())
}

/// max over rows i and sources j > i of the pair's rate over (|x_j − x_i|² + ε²)^{3/2}: the
/// sources before the first lane boundary past i and past the last whole vector one by one (the
/// padding is not a body here: its zero mass would still pair with m_i), whole SIMD vectors
/// between. The rate is m_i + m_j (`PRODUCT` false, weights `ms` = masses), or
/// a_i b_j + a_j b_i (`PRODUCT`: b = `ms`, a = `a`, padded like the sources).
struct Encounter<'a, const PRODUCT: bool> {
    src: &'a Soa<Real>,
    a: &'a [Real],
    n: usize,
    eps2: Real,
    rows: std::ops::Range<usize>,
    stop: &'a AtomicBool,
}

impl<const PRODUCT: bool> Kernel for Encounter<'_, PRODUCT> {
    type Output = Real;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> Real {
        let Soa { xs, ys, zs, ms } = self.src;
        let aw = self.a;
        let (l, n) = (P::<S, Real>::lanes(), self.n);
        let (zero, eps2) = (P::<S, Real>::zero(s), P::splat(s, self.eps2));
        let one = |i: usize, j: usize| {
            let (dx, dy, dz) = (xs[j] - xs[i], ys[j] - ys[i], zs[j] - zs[i]);
            let r2 = dx.mul_add(dx, dy.mul_add(dy, dz.mul_add(dz, self.eps2)));
            let w = if PRODUCT { aw[i] * ms[j] + aw[j] * ms[i] } else { ms[i] + ms[j] };
            if r2 > 0.0 {
                w / (r2 * r2.sqrt())
            } else {
                0.0
            }
        };
        let mut best: Real = 0.0;
        let body_end = n / l * l;
        for i in self.rows {
            if self.stop.load(Ordering::Relaxed) {
                break;
            }
            let head = ((i + 1).div_ceil(l) * l).min(n);
            for j in (i + 1..head).chain(head.max(body_end)..n) {
                best = best.max(one(i, j));
            }
            if head >= body_end {
                continue;
            }
            let (xi, yi, zi, mi) = (P::splat(s, xs[i]), P::splat(s, ys[i]), P::splat(s, zs[i]), P::splat(s, ms[i]));
            let ai = P::splat(s, if PRODUCT { aw[i] } else { 0.0 });
            let mut acc = zero;
            for (k, (bx, by, bz, bm)) in self.src.vectors(head..body_end, l).enumerate() {
                let dx = P::load(s, bx) - xi;
                let dy = P::load(s, by) - yi;
                let dz = P::load(s, bz) - zi;
                let r2 = dx.mul_add(dx, dy.mul_add(dy, dz.mul_add(dz, eps2)));
                let y = r2.rsqrt();
                let w = if PRODUCT {
                    let j = head + k * l;
                    ai.mul_add(P::load(s, bm), P::load(s, &aw[j..j + l]) * mi)
                } else {
                    P::load(s, bm) + mi
                };
                let rate = r2.gt(zero).select(w * (y * y * y), zero);
                acc = acc.max(rate);
            }
            best = best.max(acc.to_array().into_iter().take(l).fold(0.0, Real::max));
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sources of `x` in precision `T`, as the term packs them.
    fn packed<T: Float>(x: &[glam::DVec3], model: &Model) -> Soa<T> {
        let mut src = Soa::default();
        src.pack(x, &model.mass);
        src
    }

    fn cloud(n: usize, seed: u64, single: bool) -> (Vec<glam::DVec3>, Model) {
        let mut seed = seed;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let x = (0..n)
            .map(|_| glam::DVec3::new(rnd(), rnd(), rnd()))
            .map(|p| if single { p.round_f32() } else { p })
            .collect();
        let model = Model {
            mass: (0..n).map(|k| 1.0 + k as f64 / n as f64).collect(),
            inv_mass: vec![1.0; n],
            ..Default::default()
        };
        (x, model)
    }

    /// Every level this CPU has (the others cannot run here and are not claimed).
    #[test]
    fn every_level_matches_the_naive_sum_to_round_off() {
        let n = 203; // not a multiple of any lane count: exercises the massless padding
        let (x, model) = cloud(n, 12345, false);
        let src = packed::<f64>(&x, &model);
        for level in Level::available() {
            let mut acc = Vec::new();
            accelerations(&src, n, 0.0, level, &AtomicBool::new(false), &mut acc);
            for i in 0..n {
                let mut naive = glam::DVec3::ZERO;
                for j in 0..n {
                    if j != i {
                        let d = x[j] - x[i];
                        naive += d * (model.mass[j] / d.length().powi(3));
                    }
                }
                let got = glam::DVec3::from_array(acc[i]);
                assert!((got - naive).length() <= 1e-13 * naive.length().max(1.0), "{level:?}: {got} vs {naive}");
            }
        }
    }

    /// The potential Σ_{i<j} m_i m_j / r_ij at every level, with and without softening, a
    /// coincident unsoftened pair contributing nothing, rows cut at every lane offset.
    #[test]
    fn potential_matches_the_naive_sum_at_every_level() {
        let n = 203;
        let (mut x, model) = cloud(n, 777, false);
        x[7] = x[3];
        for eps in [0.0, 0.05] {
            let mut naive = 0.0;
            for i in 0..n {
                for j in i + 1..n {
                    let r2 = (x[j] - x[i]).length_squared() + eps * eps;
                    if r2 > 0.0 {
                        naive += model.mass[i] * model.mass[j] / r2.sqrt();
                    }
                }
            }
            let src = packed::<f64>(&x, &model);
            for level in Level::available() {
                let never = AtomicBool::new(false);
                // Rows in uneven pieces, as the parallel chunks cut them.
                let got: f64 = [0..1, 1..50, 50..97, 97..n]
                    .into_iter()
                    .map(|rows| simd::dispatch(level, Potential { src: &src, eps2: eps * eps, rows, stop: &never }))
                    .sum();
                assert!(
                    got.is_finite() && ((got - naive) / naive).abs() < 1e-13,
                    "{level:?} eps {eps}: {got} vs {naive}"
                );
            }
        }
    }

    /// The shortest free-fall time at every level against the pairwise definition, with and
    /// without softening, rows cut at every lane offset, a massless body and a coincident pair.
    #[test]
    fn encounter_time_matches_the_naive_minimum_at_every_level() {
        let n = 203;
        let (mut x, mut model) = cloud(n, 99, false);
        x[11] = x[5];
        model.mass[40] = 0.0;
        for eps in [0.0, 0.3] {
            let mut naive = f64::INFINITY;
            for i in 0..n {
                for j in i + 1..n {
                    let r2 = (x[j] - x[i]).length_squared() + eps * eps;
                    let t2 = r2 * r2.sqrt() / (2.0 * (model.mass[i] + model.mass[j]));
                    if t2 > 0.0 {
                        naive = naive.min(t2.sqrt());
                    }
                }
            }
            let src = packed::<f64>(&x, &model);
            for level in Level::available() {
                let never = AtomicBool::new(false);
                let rate = [0..1, 1..50, 50..200, 200..n]
                    .into_iter()
                    .map(|rows| {
                        simd::dispatch(
                            level,
                            Encounter::<false> { src: &src, a: &[], n, eps2: eps * eps, rows, stop: &never },
                        )
                    })
                    .fold(0.0, f64::max);
                let got = (1.0 / (2.0 * rate)).sqrt();
                assert!(((got - naive) / naive).abs() < 1e-14, "{level:?} eps {eps}: {got} vs {naive}");
            }
        }
        assert_eq!(encounter_time(0.0, 0.1, &x, &model, &AtomicBool::new(false)), None);
    }

    /// The symmetric (Newton's third law) sum at every level, with and without softening, for a
    /// body count that fills no block evenly.
    #[test]
    fn symmetric_sum_matches_the_naive_sum_at_every_level() {
        let n = 1107;
        let (x, model) = cloud(n, 99, false);
        let src = packed::<f64>(&x, &model);
        for eps2 in [0.0, 1e-4] {
            let naive: Vec<glam::DVec3> = (0..n)
                .map(|i| {
                    let mut a = glam::DVec3::ZERO;
                    for j in (0..n).filter(|&j| j != i) {
                        let d = x[j] - x[i];
                        a += d * (model.mass[j] / (d.length_squared() + eps2).powf(1.5));
                    }
                    a
                })
                .collect();
            for level in Level::available() {
                let (mut acc, mut scratch) = (Vec::new(), SymScratch::default());
                accelerations_sym(&src, n, eps2, level, &AtomicBool::new(false), &mut scratch, &mut acc);
                let mut momentum = glam::DVec3::ZERO;
                for i in 0..n {
                    let got = glam::DVec3::from_array(acc[i]);
                    assert!(
                        (got - naive[i]).length() <= 1e-12 * naive[i].length().max(1.0),
                        "{level:?} eps2={eps2} body {i}: {got} vs {}",
                        naive[i]
                    );
                    momentum += got * model.mass[i];
                }
                // Each pair's force is computed once and applied with both signs.
                let scale: f64 = (0..n).map(|i| glam::DVec3::from_array(acc[i]).length() * model.mass[i]).sum();
                assert!(momentum.length() <= 1e-14 * scale, "{level:?}: net force {momentum} of {scale}");
            }
        }
    }

    /// Receivers `i0..i0+R` for a tile of R, and one at a time.
    struct Tiles<'a, const R: usize>(&'a Soa<f64>, std::ops::Range<usize>, usize, f64, &'a mut Cols<f64>);
    impl<const R: usize> Kernel for Tiles<'_, R> {
        type Output = Vec<[Real; 3]>;
        #[inline(always)]
        fn run<S: Simd>(self, s: S) -> Vec<[Real; 3]> {
            let Tiles(src, far, i0, eps2, cols) = self;
            if R == 1 {
                (0..4).map(|k| far_tile::<S, f64, 1, false>(s, src, far.clone(), i0 + k, eps2, cols)[0]).collect()
            } else {
                far_tile::<S, f64, R, false>(s, src, far, i0, eps2, cols).to_vec()
            }
        }
    }

    /// A tile of receivers gives the same bits as the receivers one at a time, row sums and
    /// column sums both, at every level (the tiles only share loads; the order of every sum is
    /// kept).
    #[test]
    fn receiver_tiles_give_the_same_bits_as_one_receiver_at_a_time() {
        let n = 300;
        let (x, model) = cloud(n, 4242, false);
        let src = packed::<f64>(&x, &model);
        let far = 64..src.xs.len();
        let cols = || Cols { x: vec![0.25; src.xs.len()], y: vec![-0.5; src.xs.len()], z: vec![1.0; src.xs.len()] };
        for level in Level::available() {
            let (mut c1, mut c2, mut c4) = (cols(), cols(), cols());
            let one = simd::dispatch(level, Tiles::<1>(&src, far.clone(), 7, 1e-4, &mut c1));
            let mut two = simd::dispatch(level, Tiles::<2>(&src, far.clone(), 7, 1e-4, &mut c2));
            two.extend(simd::dispatch(level, Tiles::<2>(&src, far.clone(), 9, 1e-4, &mut c2)));
            let four = simd::dispatch(level, Tiles::<4>(&src, far.clone(), 7, 1e-4, &mut c4));
            for (name, rows, c) in [("2", &two, &c2), ("4", &four, &c4)] {
                assert_eq!(
                    rows.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    one.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    "{level:?} tile {name}: rows"
                );
                for (a, b) in [(&c.x, &c1.x), (&c.y, &c1.y), (&c.z, &c1.z)] {
                    assert!(
                        a.iter().zip(b.iter()).all(|(p, q)| p.to_bits() == q.to_bits()),
                        "{level:?} tile {name}: columns"
                    );
                }
            }
            assert!(c1.x[far.clone()].iter().any(|&v| v != 0.25), "the columns were updated");
        }
    }

    /// With the stop flag set the kernels compute nothing (every row keeps the zero it was
    /// cleared to); unset, the same call fills every row.
    #[test]
    fn a_set_stop_flag_skips_the_remaining_work() {
        let n = 1500; // above SYM_MIN: both sums apply
        let (x, model) = cloud(n, 5, false);
        let src = packed::<f64>(&x, &model);
        let level = simd::level();
        for stopped in [true, false] {
            let stop = AtomicBool::new(stopped);
            let (mut direct, mut sym, mut scratch) = (Vec::new(), Vec::new(), SymScratch::default());
            accelerations(&src, n, 1e-4, level, &stop, &mut direct);
            accelerations_sym(&src, n, 1e-4, level, &stop, &mut scratch, &mut sym);
            for (name, acc) in [("direct", &direct), ("symmetric", &sym)] {
                let computed = acc.iter().filter(|a| a[0] != 0.0).count();
                // Unset: the symmetric sum's column sums reach every row.
                let expected = if stopped { 0 } else { n };
                assert_eq!(computed, expected, "{name}, stop = {stopped}");
            }
        }
        let stop = AtomicBool::new(true);
        assert_eq!(encounter_time(1.0, 0.0, &x, &model, &stop), None);
        assert!(encounter_time(1.0, 0.0, &x, &model, &AtomicBool::new(false)).is_some());
    }

    #[test]
    fn float32_levels_match_the_naive_sum_to_single_precision() {
        let n = 517;
        let (x, model) = cloud(n, 777, true);
        let src = packed::<f32>(&x, &model);
        for level in Level::available() {
            let mut acc = Vec::new();
            accelerations(&src, n, 1e-4, level, &AtomicBool::new(false), &mut acc);
            for i in 0..n {
                let mut naive = glam::DVec3::ZERO;
                for j in 0..n {
                    let d = x[j] - x[i];
                    naive += d * ((model.mass[j] as f32) as f64 / (d.length_squared() + 1e-4).powf(1.5));
                }
                // Sum of n float32 terms: error ~ sqrt(n)·6e-8 of the term magnitudes.
                let scale: f64 = (0..n).map(|j| model.mass[j] / ((x[j] - x[i]).length_squared() + 1e-4)).sum();
                let got = glam::DVec3::from_array(acc[i]);
                assert!((got - naive).length() <= 2e-5 * scale, "{level:?}: {got} vs {naive}");
            }
        }
    }
}
