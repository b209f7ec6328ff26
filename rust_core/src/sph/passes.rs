//! The density and force passes, written once over the portable SIMD layer (`crate::simd`) for
//! f32 and f64, 2D and 3D, both kernels and every instruction set.
//!
//! Each particle (in cell order; in the density pass, two particles of a cell together) visits
//! the contiguous candidate runs of its 3^dim neighbour cells one SIMD vector of candidates at a
//! time; lanes past a run's end read padding and are masked; a vector with no live candidate
//! within the support is skipped (its terms are 0). r and 1/r come from `P::sqrt_in_loop` /
//! `P::sqrt_and_rsqrt_in_loop`: the divider at avx2 (these loops leave it idle), the fast
//! reciprocal square root elsewhere. Forces are gathered per particle: no atomics, bit-identical
//! for any thread count; levels differ by a few ulp.
//!
//! The particles may belong to several fluids that share the passes (one cell list over all of
//! them, so they push on each other; see `group`): each particle then takes its own fluid's
//! equation of state and walls, and a pair's viscosity coefficient is the mean of the two
//! fluids' α c0 (Monaghan 1992, eq. 4.2 with the pair's mean sound speed c̄_ij; symmetric in
//! i, j, so momentum is still conserved and the dissipation is still ≥ 0). That path is a
//! compile-time parameter (`SEVERAL`), so one fluid runs the single-fluid loop; one fluid split
//! into several gives the same bits on both paths (½(a + a) = a exactly, and the pair sums run
//! in the same order).
//!
//! `density` and `forces` are the entry points: they pick the kernel, dimension and path
//! (compile-time parameters of the passes), cut the sorted particles into chunks (`par::CHUNK`)
//! run in parallel, and hand each chunk to the SIMD level in use. The force pass sums its
//! chunks' dissipated power in chunk order.
use super::buffers::{Bufs, WallArrays};
use super::kernels::{CubicSpline, Float, Kernel, WendlandC2};
use super::params::{KernelKind, SphParams};
use crate::neighbors::{CellList, Ranges, MAX_RANGES};
use crate::par::{self, SyncPtr};
use crate::simd::{self, Kernel as SimdKernel, Level, Simd, P};
use crate::vector::Vector;
use std::marker::PhantomData;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};

/// Most fluids that can share the passes (a group; see `group`).
pub(super) const MAX_FLUIDS: usize = 8;

/// One fluid as the passes see it: its Tait equation of state in the pass precision and its
/// static walls.
pub(super) struct FluidView<'a, F: Float> {
    /// Tait stiffness B, Pa.
    b: F,
    /// 1/ρ0, m^dim/kg.
    inv_rho0: F,
    gamma: i32,
    clamp: bool,
    walls: &'a CellList,
    w: &'a WallArrays<F>,
}

impl<'a, F: Float> FluidView<'a, F> {
    pub(super) fn new(p: &SphParams, walls: &'a CellList, w: &'a WallArrays<F>) -> Self {
        Self { b: F::of(p.b()), inv_rho0: F::of(1.0 / p.rho0), gamma: p.gamma, clamp: p.clamp, walls, w }
    }
}

/// Per fluid of the pass: the power its particles' viscosity dissipates (W; ½ of each pair's
/// to each side) and their largest |dv/dt|² (m²/s⁴).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Sums {
    pub(super) power: [f64; MAX_FLUIDS],
    pub(super) amax: [f64; MAX_FLUIDS],
}

impl Sums {
    fn fold(mut self, o: Sums) -> Sums {
        for k in 0..MAX_FLUIDS {
            self.power[k] += o.power[k];
            self.amax[k] = self.amax[k].max(o.amax[k]);
        }
        self
    }
}

/// Runs the local macro `$go!(Kernel, D)` for the kernel of `$p` and the dimension of `$v`
/// (compile-time parameters of the passes).
macro_rules! by_kernel_and_dim {
    ($p:expr, $v:ty, $go:ident) => {
        match ($p.kernel, <$v>::DIM) {
            (KernelKind::CubicSpline, 2) => $go!(CubicSpline, 2),
            (KernelKind::CubicSpline, _) => $go!(CubicSpline, 3),
            (KernelKind::WendlandC2, 2) => $go!(WendlandC2, 2),
            (KernelKind::WendlandC2, _) => $go!(WendlandC2, 3),
        }
    };
}

/// The density pass for the kernel of `p` (its h and kernel; the equations of state are the
/// fluids') and the dimension of `V`: ρ and p/ρ² of the particles in `grid` into `b.rho`,
/// `b.pr` (cell order). Several `fluids` take the path that reads `b.fluid`.
pub(super) fn density<V: Vector, F: Float>(
    level: Level,
    p: &SphParams,
    grid: &CellList,
    fluids: &[FluidView<F>],
    b: &mut Bufs<F>,
    stop: &AtomicBool,
) {
    macro_rules! go {
        ($k:ty, $d:literal) => {
            if fluids.len() > 1 {
                density_pass::<F, $k, $d, true>(level, p, grid, fluids, b, stop)
            } else {
                density_pass::<F, $k, $d, false>(level, p, grid, fluids, b, stop)
            }
        };
    }
    by_kernel_and_dim!(p, V, go)
}

/// The force pass for the kernel of `p` (its h and kernel; with one fluid also its α and c0)
/// and the dimension of `V`: the forces of the particles in `grid` into `out` (particle order);
/// returns per fluid the dissipated power (W, summed only if `want_power`) and max |a|².
#[allow(clippy::too_many_arguments)]
pub(super) fn forces<V: Vector, F: Float>(
    level: Level,
    p: &SphParams,
    grid: &CellList,
    fluids: &[FluidView<F>],
    b: &Bufs<F>,
    out: &mut [V],
    want_power: bool,
    stop: &AtomicBool,
) -> Sums {
    macro_rules! go {
        ($k:ty, $d:literal) => {
            match (fluids.len() > 1, want_power) {
                (true, true) => force_pass::<V, F, $k, $d, true, true>(level, p, grid, fluids, b, out, stop),
                (true, false) => force_pass::<V, F, $k, $d, true, false>(level, p, grid, fluids, b, out, stop),
                (false, true) => force_pass::<V, F, $k, $d, false, true>(level, p, grid, fluids, b, out, stop),
                (false, false) => force_pass::<V, F, $k, $d, false, false>(level, p, grid, fluids, b, out, stop),
            }
        };
    }
    by_kernel_and_dim!(p, V, go)
}

fn density_pass<F: Float, K: Kernel, const D: usize, const SEVERAL: bool>(
    level: Level,
    p: &SphParams,
    grid: &CellList,
    fluids: &[FluidView<F>],
    b: &mut Bufs<F>,
    stop: &AtomicBool,
) {
    let n = grid.len();
    let mut rho = std::mem::take(&mut b.rho);
    let mut pr = std::mem::take(&mut b.pr);
    {
        let b: &Bufs<F> = b;
        par::chunks2(&mut rho[..n], &mut pr[..n], |s, rho, pr| {
            if stop.load(Ordering::Relaxed) {
                return;
            }
            let ks = s..s + rho.len();
            simd::dispatch(level, Density::<F, K, D, SEVERAL> { p, grid, fluids, b, ks, rho, pr, _k: PhantomData });
        });
    }
    b.rho = rho;
    b.pr = pr;
}

#[allow(clippy::too_many_arguments)]
fn force_pass<V: Vector, F: Float, K: Kernel, const D: usize, const SEVERAL: bool, const POWER: bool>(
    level: Level,
    p: &SphParams,
    grid: &CellList,
    fluids: &[FluidView<F>],
    b: &Bufs<F>,
    out: &mut [V],
    stop: &AtomicBool,
) -> Sums {
    let n = grid.len();
    let out = SyncPtr(out.as_mut_ptr());
    let chunk = |c: usize| {
        if stop.load(Ordering::Relaxed) {
            return Sums::default();
        }
        let ks = c * par::CHUNK..((c + 1) * par::CHUNK).min(n);
        simd::dispatch(level, Forces::<V, F, K, D, SEVERAL, POWER> { p, grid, fluids, b, ks, out, _k: PhantomData })
    };
    let nc = n.div_ceil(par::CHUNK);
    let parts: Vec<Sums> = par::map_chunks(n, nc, chunk);
    // Fixed chunk order: the same sum for any thread count.
    parts.into_iter().fold(Sums::default(), Sums::fold)
}

/// s^γ: a fixed multiplication chain for water's γ = 7 (this runs once per particle per step).
#[inline(always)]
fn powi<F: Float>(s: F, gamma: i32) -> F {
    if gamma == 7 {
        let s2 = s * s;
        let s4 = s2 * s2;
        return s4 * s2 * s;
    }
    let mut r = s;
    for _ in 1..gamma {
        r = r * s;
    }
    r
}

/// Smallest r² the passes take a square root of (r = 0 is the self pair): keeps 1/r finite.
#[inline(always)]
fn tiny<F: Float>() -> F {
    if std::mem::size_of::<F>() == 4 {
        F::of(1e-30)
    } else {
        F::of(1e-300)
    }
}

/// The candidate runs around sorted particle `k`: fluid runs of its cell, and wall runs of its
/// cell in its fluid's walls, cached while consecutive particles share both (they mostly do:
/// the order is by cell).
struct Neighbours<'a, F: Float> {
    grid: &'a CellList,
    fluids: &'a [FluidView<'a, F>],
    last: ([i64; 3], usize),
    fluid: Ranges,
    wall: Ranges,
}

impl<'a, F: Float> Neighbours<'a, F> {
    fn new(grid: &'a CellList, fluids: &'a [FluidView<'a, F>]) -> Self {
        let empty = Ranges { r: [(0, 0); MAX_RANGES], len: 0 };
        Self { grid, fluids, last: ([i64::MIN; 3], 0), fluid: empty, wall: empty }
    }
    /// Particle `k` of fluid `f` (always 0 unless `SEVERAL`: the one-fluid path then keys the
    /// cache by the cell alone).
    #[inline(always)]
    fn at<const SEVERAL: bool>(&mut self, k: usize, f: usize) {
        let c = self.grid.cells[k];
        if !SEVERAL {
            if c != self.last.0 {
                self.fluid = self.grid.query(c);
                self.wall = self.fluids[0].walls.query(c);
                self.last.0 = c;
            }
        } else if (c, f) != self.last {
            if c != self.last.0 {
                self.fluid = self.grid.query(c);
            }
            self.wall = self.fluids[f].walls.query(c);
            self.last = (c, f);
        }
    }
}

/// `a[r.start ..]` cut to whole vectors covering `r` (the buffers are padded), so the loops
/// below walk it with `chunks_exact` and no per-load bounds check.
#[inline(always)]
fn run<'a, F>(a: &'a [F], r: &Range<usize>, l: usize) -> &'a [F] {
    &a[r.start..r.start + (r.end - r.start).div_ceil(l) * l]
}

/// 0, 1, 2, … per lane (for the run-end masks).
#[inline(always)]
fn iota<S: Simd, F: Float>(s: S) -> P<S, F> {
    P::from_fn(s, |k| F::of(k as f64))
}

/// The fluid of sorted particle `k` (0 on the one-fluid path, which has no `b.fluid`).
#[inline(always)]
fn fluid_of<F: Float, const SEVERAL: bool>(b: &Bufs<F>, k: usize) -> usize {
    if SEVERAL {
        b.fluid[k] as usize
    } else {
        0
    }
}

/// Summation density and Tait pressure (as p/ρ²) of sorted particles `ks`.
pub(super) struct Density<'a, F: Float, K: Kernel, const D: usize, const SEVERAL: bool> {
    pub p: &'a SphParams,
    pub grid: &'a CellList,
    pub fluids: &'a [FluidView<'a, F>],
    pub b: &'a Bufs<F>,
    pub ks: Range<usize>,
    pub rho: &'a mut [F],
    pub pr: &'a mut [F],
    pub _k: PhantomData<K>,
}

impl<F: Float, K: Kernel, const D: usize, const SEVERAL: bool> SimdKernel for Density<'_, F, K, D, SEVERAL> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        let Density { p, grid, fluids, b, ks, rho, pr, .. } = self;
        let l = P::<S, F>::lanes();
        let (zero, lanes, tiny) = (P::<S, F>::zero(s), iota::<S, F>(s), P::splat(s, tiny::<F>()));
        let inv_h = P::splat(s, F::of(1.0 / p.h));
        // Vectors with no candidate within the support (q < 2 for both kernels) are skipped: their
        // terms are exactly 0 (the margin keeps rounding from dropping a q just under 2).
        let reach = P::splat(s, F::of(4.0001 * p.h * p.h));
        let sigma = F::of(K::sigma(p.h, D));
        let z = if D == 3 { 2 } else { 0 };
        let mut nb = Neighbours::new(grid, fluids);
        let base = ks.start;
        let first = &fluids[0];
        // Two particles of a cell at a time (they share its candidate runs): each candidate
        // vector is loaded and tested once for both, and the two sums are independent chains
        // (profiled one particle at a time, the loop's samples sat on the kernel's chain of
        // dependent multiplications after the square root).
        // Each particle adds the same terms in the same order as alone: a term out of its reach
        // is exactly 0. A cell's odd particle goes alone (as the pair (k, k), stored once).
        let mut k = ks.start;
        while k < ks.end {
            let f = fluid_of::<F, SEVERAL>(b, k);
            nb.at::<SEVERAL>(k, f);
            let fl = if SEVERAL { &fluids[f] } else { first };
            let pair = k + 1 < ks.end
                && grid.cells[k + 1] == grid.cells[k]
                && (!SEVERAL || fluid_of::<F, SEVERAL>(b, k + 1) == f);
            let k2 = if pair { k + 1 } else { k };
            // A loop, not `std::array::from_fn`: its closure can stay out of line (a call per
            // splat) in a build of several codegen units.
            let (mut xa, mut xb) = ([zero; 3], [zero; 3]);
            for d in 0..D {
                (xa[d], xb[d]) = (P::splat(s, b.pos[d][k]), P::splat(s, b.pos[d][k2]));
            }
            let (mut acc_a, mut acc_b) = (zero, zero);
            for r in nb.fluid.iter() {
                let cols = run(&b.pos[0], &r, l).chunks_exact(l).zip(run(&b.pos[1], &r, l).chunks_exact(l));
                let cols = cols.zip(run(&b.pos[z], &r, l).chunks_exact(l)).zip(run(&b.m, &r, l).chunks_exact(l));
                let mut left = P::splat(s, F::of((r.end - r.start) as f64));
                for (((cx, cy), cz), cm) in cols {
                    let (cx, cy) = (P::load(s, cx), P::load(s, cy));
                    let (dxa, dya) = (xa[0] - cx, xa[1] - cy);
                    let (dxb, dyb) = (xb[0] - cx, xb[1] - cy);
                    let mut r2a = dxa.mul_add(dxa, dya * dya);
                    let mut r2b = dxb.mul_add(dxb, dyb * dyb);
                    if D == 3 {
                        let cz = P::load(s, cz);
                        let (dza, dzb) = (xa[2] - cz, xb[2] - cz);
                        r2a = dza.mul_add(dza, r2a);
                        r2b = dzb.mul_add(dzb, r2b);
                    }
                    let live = lanes.lt(left);
                    left = left - P::splat(s, F::of(l as f64));
                    if !live.and(s, r2a.min(r2b).lt(reach)).any(s) {
                        continue;
                    }
                    let m = P::load(s, cm);
                    let wa = K::wv(r2a.max(tiny).sqrt_in_loop() * inv_h) * m;
                    let wb = K::wv(r2b.max(tiny).sqrt_in_loop() * inv_h) * m;
                    acc_a = acc_a + live.select(wa, zero);
                    acc_b = acc_b + live.select(wb, zero);
                }
            }
            let (pos, psi) = (&fl.w.pos, &fl.w.psi);
            for (xi, acc) in [(xa, &mut acc_a), (xb, &mut acc_b)].into_iter().take(1 + pair as usize) {
                for r in nb.wall.iter() {
                    let cols = run(&pos[0], &r, l).chunks_exact(l).zip(run(&pos[1], &r, l).chunks_exact(l));
                    let cols = cols.zip(run(&pos[z], &r, l).chunks_exact(l)).zip(run(psi, &r, l).chunks_exact(l));
                    let mut left = P::splat(s, F::of((r.end - r.start) as f64));
                    for (((cx, cy), cz), cm) in cols {
                        let dx = xi[0] - P::load(s, cx);
                        let dy = xi[1] - P::load(s, cy);
                        let mut r2 = dx.mul_add(dx, dy * dy);
                        if D == 3 {
                            let dz = xi[2] - P::load(s, cz);
                            r2 = dz.mul_add(dz, r2);
                        }
                        let live = lanes.lt(left);
                        left = left - P::splat(s, F::of(l as f64));
                        if !live.and(s, r2.lt(reach)).any(s) {
                            continue;
                        }
                        let x = r2.max(tiny);
                        let q = x.sqrt_in_loop() * inv_h;
                        let w = K::wv(q) * P::load(s, cm);
                        *acc = *acc + live.select(w, zero);
                    }
                }
            }
            rho[k - base] = sigma * acc_a.sum();
            if pair {
                rho[k2 - base] = sigma * acc_b.sum();
            }
            k = k2 + 1;
        }
        // The equation of state in a loop of its own: its chain of multiplications and a
        // division per particle, at the end of each neighbour loop, had held up the next
        // particle's (SPH-2D 160k at avx2: the density pass took 0.8 of its 4.9 ms without it).
        for (k, (&d, pr)) in (base..).zip(rho.iter().zip(pr.iter_mut())) {
            let fl = if SEVERAL { &fluids[fluid_of::<F, SEVERAL>(b, k)] } else { first };
            let mut pk = fl.b * (powi(d * fl.inv_rho0, fl.gamma) - F::ONE);
            if fl.clamp {
                pk = pk.max(F::ZERO);
            }
            *pr = pk / (d * d);
        }
    }
}

/// Pressure, viscosity and wall forces (N) of sorted particles `ks`, written to `out` in particle
/// order; returns this chunk's power and max |a|² per fluid.
pub(super) struct Forces<'a, V: Vector, F: Float, K: Kernel, const D: usize, const SEVERAL: bool, const POWER: bool> {
    pub p: &'a SphParams,
    pub grid: &'a CellList,
    pub fluids: &'a [FluidView<'a, F>],
    pub b: &'a Bufs<F>,
    pub ks: Range<usize>,
    pub out: SyncPtr<V>,
    pub _k: PhantomData<K>,
}

impl<V: Vector, F: Float, K: Kernel, const D: usize, const SEVERAL: bool, const POWER: bool> SimdKernel
    for Forces<'_, V, F, K, D, SEVERAL, POWER>
{
    type Output = Sums;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> Sums {
        let Forces { p, grid, fluids, b, ks, out, .. } = self;
        let l = P::<S, F>::lanes();
        let (zero, lanes, tiny) = (P::<S, F>::zero(s), iota::<S, F>(s), P::splat(s, tiny::<F>()));
        let (h, inv_h) = (P::splat(s, F::of(p.h)), P::splat(s, F::of(1.0 / p.h)));
        let scale = -K::sigma(p.h, D) / (p.h * p.h);
        // One fluid: 2 α c0 h for every pair. Several: (α c0 h)_i + (α c0 h)_j.
        let visc = P::splat(s, F::of(2.0 * p.alpha * p.c0 * p.h));
        let eps_h2 = P::splat(s, F::of(0.01 * p.h * p.h));
        // Vectors with no candidate within the support (q < 2 for both kernels) are skipped: their
        // terms are exactly 0 (the margin keeps rounding from dropping a q just under 2).
        let reach = P::splat(s, F::of(4.0001 * p.h * p.h));
        let step = P::splat(s, F::of(l as f64));
        let z = if D == 3 { 2 } else { 0 };
        let mut nb = Neighbours::new(grid, fluids);
        let mut sums = Sums::default();
        let first = &fluids[0];
        for k in ks {
            let f = fluid_of::<F, SEVERAL>(b, k);
            nb.at::<SEVERAL>(k, f);
            let fl = if SEVERAL { &fluids[f] } else { first };
            // A loop, not `std::array::from_fn` (see the density pass).
            let (mut xi, mut vi) = ([zero; 3], [zero; 3]);
            for d in 0..D {
                (xi[d], vi[d]) = (P::splat(s, b.pos[d][k]), P::splat(s, b.vel[d][k]));
            }
            let (rho_i, pr_i) = (P::splat(s, b.rho[k]), P::splat(s, b.pr[k]));
            let visc_i = if SEVERAL { P::splat(s, b.visc[k]) } else { zero };
            let mut acc = [zero; 3];
            let mut pacc = zero;
            for r in nb.fluid.iter() {
                let pos = run(&b.pos[0], &r, l)
                    .chunks_exact(l)
                    .zip(run(&b.pos[1], &r, l).chunks_exact(l))
                    .zip(run(&b.pos[z], &r, l).chunks_exact(l));
                let vel = run(&b.vel[0], &r, l)
                    .chunks_exact(l)
                    .zip(run(&b.vel[1], &r, l).chunks_exact(l))
                    .zip(run(&b.vel[z], &r, l).chunks_exact(l));
                let par = run(&b.m, &r, l)
                    .chunks_exact(l)
                    .zip(run(&b.rho, &r, l).chunks_exact(l))
                    .zip(run(&b.pr, &r, l).chunks_exact(l));
                // The candidates' α c0 h: a column of the several-fluid path only (the one-fluid
                // loop zips nothing more than it did before fluids could meet).
                let mut visc_j = if SEVERAL { run(&b.visc, &r, l).chunks_exact(l) } else { [].chunks_exact(l) };
                let mut left = P::splat(s, F::of((r.end - r.start) as f64));
                for ((((px, py), pz), ((ux, uy), uz)), ((m, rho), pr)) in pos.zip(vel).zip(par) {
                    let mut dx = [xi[0] - P::load(s, px), xi[1] - P::load(s, py), zero];
                    let mut r2 = dx[0].mul_add(dx[0], dx[1] * dx[1]);
                    let mut vr = (vi[0] - P::load(s, ux)).mul_add(dx[0], (vi[1] - P::load(s, uy)) * dx[1]);
                    if D == 3 {
                        dx[2] = xi[2] - P::load(s, pz);
                        r2 = dx[2].mul_add(dx[2], r2);
                        vr = (vi[2] - P::load(s, uz)).mul_add(dx[2], vr);
                    }
                    let live = lanes.lt(left);
                    left = left - step;
                    if !live.and(s, r2.lt(reach)).any(s) {
                        if SEVERAL {
                            visc_j.next();
                        }
                        continue;
                    }
                    let x = r2.max(tiny);
                    let (rr, inv_r) = x.sqrt_and_rsqrt_in_loop();
                    let gq = K::gv(rr * inv_h, h * inv_r);
                    // Π_ij = 2 (α c0)_ij h max(−v·r, 0) / ((r² + 0.01h²)(ρ_i + ρ_j)) ≥ 0.
                    let approach = (zero - vr).max(zero);
                    let vij = if SEVERAL {
                        // The column is as long as the run.
                        visc_j.next().map_or(visc, |vc| visc_i + P::load(s, vc))
                    } else {
                        visc
                    };
                    let pi = vij * approach / ((r2 + eps_h2) * (rho_i + P::load(s, rho)));
                    let mg = live.select(P::load(s, m) * gq, zero);
                    let cf = mg * (pr_i + P::load(s, pr) + pi);
                    for d in 0..D {
                        acc[d] = cf.mul_add(dx[d], acc[d]);
                    }
                    if POWER {
                        pacc = (mg * pi).mul_add(vr, pacc);
                    }
                }
            }
            let mut wacc = [zero; 3];
            for r in nb.wall.iter() {
                let pos = run(&fl.w.pos[0], &r, l)
                    .chunks_exact(l)
                    .zip(run(&fl.w.pos[1], &r, l).chunks_exact(l))
                    .zip(run(&fl.w.pos[z], &r, l).chunks_exact(l));
                let mut left = P::splat(s, F::of((r.end - r.start) as f64));
                for (((px, py), pz), psi) in pos.zip(run(&fl.w.psi, &r, l).chunks_exact(l)) {
                    let mut dx = [xi[0] - P::load(s, px), xi[1] - P::load(s, py), zero];
                    let mut r2 = dx[0].mul_add(dx[0], dx[1] * dx[1]);
                    if D == 3 {
                        dx[2] = xi[2] - P::load(s, pz);
                        r2 = dx[2].mul_add(dx[2], r2);
                    }
                    let live = lanes.lt(left);
                    left = left - step;
                    if !live.and(s, r2.lt(reach)).any(s) {
                        continue;
                    }
                    let x = r2.max(tiny);
                    let (rr, inv_r) = x.sqrt_and_rsqrt_in_loop();
                    let gq = K::gv(rr * inv_h, h * inv_r);
                    let cf = live.select(P::load(s, psi) * gq, zero);
                    for d in 0..D {
                        wacc[d] = cf.mul_add(dx[d], wacc[d]);
                    }
                }
            }
            let mi = b.m[k].f64();
            let pri = b.pr[k].f64();
            let mut a = [0.0f64; 3];
            for d in 0..D {
                a[d] = scale * (acc[d].sum().f64() + pri * wacc[d].sum().f64());
            }
            sums.amax[f] = sums.amax[f].max(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
            if POWER {
                sums.power[f] += 0.5 * mi * (-scale) * pacc.sum().f64();
            }
            let fv = [mi * a[0], mi * a[1], mi * a[2]];
            // SAFETY: `order` is a permutation; each particle is written by exactly one chunk.
            unsafe { *out.get().add(grid.order[k] as usize) = V::from_slice(&fv[..D]) };
        }
        sums
    }
}
