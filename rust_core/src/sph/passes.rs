//! The density and force passes, written once over the portable SIMD layer (`crate::simd`) for
//! f32 and f64, 2D and 3D, both kernels and every instruction set.
//!
//! Each particle (in cell order) visits the contiguous candidate runs of its 3^dim neighbour
//! cells one SIMD vector of candidates at a time; lanes past a run's end read padding and are
//! masked. r and 1/r come from the layer's fast reciprocal square root (the passes would
//! otherwise spend most of their time in the divider). Forces are gathered per particle: no
//! atomics, bit-identical for any thread count; levels differ by a few ulp.
//!
//! `density` and `forces` are the entry points: they pick the kernel and dimension (compile-time
//! parameters of the passes), cut the sorted particles into chunks (`par::CHUNK`) run in
//! parallel, and hand each chunk to the SIMD level in use. The force pass sums its chunks'
//! dissipated power in chunk order.
use super::buffers::Bufs;
use super::kernels::{CubicSpline, Float, Kernel, WendlandC2};
use super::params::{KernelKind, SphParams};
use crate::neighbors::{CellList, Ranges, MAX_RANGES};
use crate::par::{self, SyncPtr};
use crate::simd::{self, Kernel as SimdKernel, Level, Simd, P};
use crate::vector::Vector;
use rayon::prelude::*;
use std::marker::PhantomData;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};

/// The density pass for the kernel of `p` and the dimension of `V`: ρ and p/ρ² of the particles
/// in `grid` into `b.rho`, `b.pr` (cell order).
pub(super) fn density<V: Vector, F: Float>(
    level: Level,
    p: &SphParams,
    grid: &CellList,
    walls: &CellList,
    b: &mut Bufs<F>,
    stop: &AtomicBool,
) {
    match (p.kernel, V::DIM) {
        (KernelKind::CubicSpline, 2) => density_pass::<F, CubicSpline, 2>(level, p, grid, walls, b, stop),
        (KernelKind::CubicSpline, _) => density_pass::<F, CubicSpline, 3>(level, p, grid, walls, b, stop),
        (KernelKind::WendlandC2, 2) => density_pass::<F, WendlandC2, 2>(level, p, grid, walls, b, stop),
        (KernelKind::WendlandC2, _) => density_pass::<F, WendlandC2, 3>(level, p, grid, walls, b, stop),
    }
}

/// The force pass for the kernel of `p` and the dimension of `V`: the forces of the particles
/// in `grid` into `out` (particle order); returns (dissipated power W, max |a|²).
#[allow(clippy::too_many_arguments)]
pub(super) fn forces<V: Vector, F: Float>(
    level: Level,
    p: &SphParams,
    grid: &CellList,
    walls: &CellList,
    b: &Bufs<F>,
    out: &mut [V],
    want_power: bool,
    stop: &AtomicBool,
) -> (f64, f64) {
    match (p.kernel, V::DIM) {
        (KernelKind::CubicSpline, 2) => {
            force_pass::<V, F, CubicSpline, 2>(level, p, grid, walls, b, out, want_power, stop)
        }
        (KernelKind::CubicSpline, _) => {
            force_pass::<V, F, CubicSpline, 3>(level, p, grid, walls, b, out, want_power, stop)
        }
        (KernelKind::WendlandC2, 2) => {
            force_pass::<V, F, WendlandC2, 2>(level, p, grid, walls, b, out, want_power, stop)
        }
        (KernelKind::WendlandC2, _) => {
            force_pass::<V, F, WendlandC2, 3>(level, p, grid, walls, b, out, want_power, stop)
        }
    }
}

fn density_pass<F: Float, K: Kernel, const D: usize>(
    level: Level,
    p: &SphParams,
    grid: &CellList,
    walls: &CellList,
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
            simd::dispatch(level, Density::<F, K, D> { p, grid, walls, b, ks, rho, pr, _k: PhantomData });
        });
    }
    b.rho = rho;
    b.pr = pr;
}

#[allow(clippy::too_many_arguments)]
fn force_pass<V: Vector, F: Float, K: Kernel, const D: usize>(
    level: Level,
    p: &SphParams,
    grid: &CellList,
    walls: &CellList,
    b: &Bufs<F>,
    out: &mut [V],
    want_power: bool,
    stop: &AtomicBool,
) -> (f64, f64) {
    let n = grid.len();
    let out = SyncPtr(out.as_mut_ptr());
    let chunk = |c: usize| {
        if stop.load(Ordering::Relaxed) {
            return (0.0, 0.0);
        }
        let ks = c * par::CHUNK..((c + 1) * par::CHUNK).min(n);
        if want_power {
            simd::dispatch(level, Forces::<V, F, K, D, true> { p, grid, walls, b, ks, out, _k: PhantomData })
        } else {
            simd::dispatch(level, Forces::<V, F, K, D, false> { p, grid, walls, b, ks, out, _k: PhantomData })
        }
    };
    let nc = n.div_ceil(par::CHUNK);
    let parts: Vec<(f64, f64)> = match par::fork_if(n, || (0..nc).into_par_iter().map(chunk).collect()) {
        Some(p) => p,
        None => (0..nc).map(chunk).collect(),
    };
    // Fixed chunk order: the same sum for any thread count.
    parts.into_iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1.max(b.1)))
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

/// The candidate runs of the cell of sorted particle `k`, cached while consecutive particles
/// share a cell (they do: the order is by cell).
struct Neighbours<'a> {
    grid: &'a CellList,
    walls: &'a CellList,
    last: [i64; 3],
    fluid: Ranges,
    wall: Ranges,
}

impl<'a> Neighbours<'a> {
    fn new(grid: &'a CellList, walls: &'a CellList) -> Self {
        let empty = Ranges { r: [(0, 0); MAX_RANGES], len: 0 };
        Self { grid, walls, last: [i64::MIN; 3], fluid: empty, wall: empty }
    }
    #[inline(always)]
    fn at(&mut self, k: usize) {
        let c = self.grid.cells[k];
        if c != self.last {
            self.fluid = self.grid.query(c);
            self.wall = self.walls.query(c);
            self.last = c;
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

/// Summation density and Tait pressure (as p/ρ²) of sorted particles `ks`.
pub(super) struct Density<'a, F: Float, K: Kernel, const D: usize> {
    pub p: &'a SphParams,
    pub grid: &'a CellList,
    pub walls: &'a CellList,
    pub b: &'a Bufs<F>,
    pub ks: Range<usize>,
    pub rho: &'a mut [F],
    pub pr: &'a mut [F],
    pub _k: PhantomData<K>,
}

impl<F: Float, K: Kernel, const D: usize> SimdKernel for Density<'_, F, K, D> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        let Density { p, grid, walls, b, ks, rho, pr, .. } = self;
        let l = P::<S, F>::lanes();
        let (zero, lanes, tiny) = (P::<S, F>::zero(s), iota::<S, F>(s), P::splat(s, tiny::<F>()));
        let inv_h = P::splat(s, F::of(1.0 / p.h));
        let (sigma, inv_rho0, bb) = (F::of(K::sigma(p.h, D)), F::of(1.0 / p.rho0), F::of(p.b()));
        let z = if D == 3 { 2 } else { 0 };
        let mut nb = Neighbours::new(grid, walls);
        let base = ks.start;
        for k in ks {
            nb.at(k);
            let xi: [P<S, F>; 3] = std::array::from_fn(|d| if d < D { P::splat(s, b.pos[d][k]) } else { zero });
            let mut acc = zero;
            for (pos, mass, ranges) in [(&b.pos, &b.m, &nb.fluid), (&b.wpos, &b.wpsi, &nb.wall)] {
                for r in ranges.iter() {
                    let cols = run(&pos[0], &r, l).chunks_exact(l).zip(run(&pos[1], &r, l).chunks_exact(l));
                    let cols = cols.zip(run(&pos[z], &r, l).chunks_exact(l)).zip(run(mass, &r, l).chunks_exact(l));
                    let mut left = P::splat(s, F::of((r.end - r.start) as f64));
                    for (((cx, cy), cz), cm) in cols {
                        let dx = xi[0] - P::load(s, cx);
                        let dy = xi[1] - P::load(s, cy);
                        let mut r2 = dx.mul_add(dx, dy * dy);
                        if D == 3 {
                            let dz = xi[2] - P::load(s, cz);
                            r2 = dz.mul_add(dz, r2);
                        }
                        let x = r2.max(tiny);
                        let q = x * x.rsqrt() * inv_h;
                        let w = K::wv(q) * P::load(s, cm);
                        acc = acc + lanes.lt(left).select(w, zero);
                        left = left - P::splat(s, F::of(l as f64));
                    }
                }
            }
            let d = sigma * acc.sum();
            let mut pk = bb * (powi(d * inv_rho0, p.gamma) - F::ONE);
            if p.clamp {
                pk = pk.max(F::ZERO);
            }
            rho[k - base] = d;
            pr[k - base] = pk / (d * d);
        }
    }
}

/// Pressure, viscosity and wall forces (N) of sorted particles `ks`, written to `out` in particle
/// order; returns (dissipated power partial, max |a|²).
pub(super) struct Forces<'a, V: Vector, F: Float, K: Kernel, const D: usize, const POWER: bool> {
    pub p: &'a SphParams,
    pub grid: &'a CellList,
    pub walls: &'a CellList,
    pub b: &'a Bufs<F>,
    pub ks: Range<usize>,
    pub out: SyncPtr<V>,
    pub _k: PhantomData<K>,
}

impl<V: Vector, F: Float, K: Kernel, const D: usize, const POWER: bool> SimdKernel for Forces<'_, V, F, K, D, POWER> {
    type Output = (f64, f64);
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> (f64, f64) {
        let Forces { p, grid, walls, b, ks, out, .. } = self;
        let l = P::<S, F>::lanes();
        let (zero, lanes, tiny) = (P::<S, F>::zero(s), iota::<S, F>(s), P::splat(s, tiny::<F>()));
        let (h, inv_h) = (P::splat(s, F::of(p.h)), P::splat(s, F::of(1.0 / p.h)));
        let scale = -K::sigma(p.h, D) / (p.h * p.h);
        let visc = P::splat(s, F::of(2.0 * p.alpha * p.c0 * p.h));
        let eps_h2 = P::splat(s, F::of(0.01 * p.h * p.h));
        let step = P::splat(s, F::of(l as f64));
        let z = if D == 3 { 2 } else { 0 };
        let mut nb = Neighbours::new(grid, walls);
        let (mut power, mut amax) = (0.0f64, 0.0f64);
        for k in ks {
            nb.at(k);
            let xi: [P<S, F>; 3] = std::array::from_fn(|d| if d < D { P::splat(s, b.pos[d][k]) } else { zero });
            let vi: [P<S, F>; 3] = std::array::from_fn(|d| if d < D { P::splat(s, b.vel[d][k]) } else { zero });
            let (rho_i, pr_i) = (P::splat(s, b.rho[k]), P::splat(s, b.pr[k]));
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
                    let x = r2.max(tiny);
                    let inv_r = x.rsqrt();
                    let gq = K::gv(x * inv_r * inv_h, h * inv_r);
                    // Π_ij = 2 α c0 h max(−v·r, 0) / ((r² + 0.01h²)(ρ_i + ρ_j)) ≥ 0.
                    let approach = (zero - vr).max(zero);
                    let pi = visc * approach / ((r2 + eps_h2) * (rho_i + P::load(s, rho)));
                    let mg = lanes.lt(left).select(P::load(s, m) * gq, zero);
                    let cf = mg * (pr_i + P::load(s, pr) + pi);
                    for d in 0..D {
                        acc[d] = cf.mul_add(dx[d], acc[d]);
                    }
                    if POWER {
                        pacc = (mg * pi).mul_add(vr, pacc);
                    }
                    left = left - step;
                }
            }
            let mut wacc = [zero; 3];
            for r in nb.wall.iter() {
                let pos = run(&b.wpos[0], &r, l)
                    .chunks_exact(l)
                    .zip(run(&b.wpos[1], &r, l).chunks_exact(l))
                    .zip(run(&b.wpos[z], &r, l).chunks_exact(l));
                let mut left = P::splat(s, F::of((r.end - r.start) as f64));
                for (((px, py), pz), psi) in pos.zip(run(&b.wpsi, &r, l).chunks_exact(l)) {
                    let mut dx = [xi[0] - P::load(s, px), xi[1] - P::load(s, py), zero];
                    let mut r2 = dx[0].mul_add(dx[0], dx[1] * dx[1]);
                    if D == 3 {
                        dx[2] = xi[2] - P::load(s, pz);
                        r2 = dx[2].mul_add(dx[2], r2);
                    }
                    let x = r2.max(tiny);
                    let inv_r = x.rsqrt();
                    let gq = K::gv(x * inv_r * inv_h, h * inv_r);
                    let cf = lanes.lt(left).select(P::load(s, psi) * gq, zero);
                    for d in 0..D {
                        wacc[d] = cf.mul_add(dx[d], wacc[d]);
                    }
                    left = left - step;
                }
            }
            let mi = b.m[k].f64();
            let pri = b.pr[k].f64();
            let mut a = [0.0f64; 3];
            for d in 0..D {
                a[d] = scale * (acc[d].sum().f64() + pri * wacc[d].sum().f64());
            }
            amax = amax.max(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
            if POWER {
                power += 0.5 * mi * (-scale) * pacc.sum().f64();
            }
            let fv = [mi * a[0], mi * a[1], mi * a[2]];
            // SAFETY: `order` is a permutation; each particle is written by exactly one chunk.
            unsafe { *out.get().add(grid.order[k] as usize) = V::from_slice(&fv[..D]) };
        }
        (power, amax)
    }
}
