//! Weakly compressible SPH (WCSPH) as one force term.
//!
//! Density by summation, ρ_i = Σ_j m_j W_ij + Σ_b Ψ_b W_ib (self included; b runs over static wall
//! particles of "mass" Ψ_b = ρ0 V_b, Akinci et al. 2012, eq. 4–5). Tait equation of state,
//! p = B[(ρ/ρ0)^γ − 1], B = ρ0 c0²/γ (Monaghan 1994; Becker & Teschner 2007, eq. 6), optionally
//! clamped to p ≥ 0. Symmetric, momentum-conserving pressure force with Monaghan (1992) artificial
//! viscosity:
//!
//!   dv_i/dt = −Σ_j m_j (p_i/ρ_i² + p_j/ρ_j² + Π_ij) ∇_i W_ij − Σ_b Ψ_b (p_i/ρ_i²) ∇_i W_ib,
//!   Π_ij = −α c0 μ_ij / ρ̄_ij,  μ_ij = h v_ij·r_ij / (r_ij² + 0.01 h²) if v_ij·r_ij < 0, else 0.
//!
//! The wall term is Akinci et al. (2012), eq. 10 (free slip: no wall viscosity, so fluid cannot
//! stick). With summation density the pressure part is exactly the gradient of the internal
//! energy U = Σ_i m_i u(ρ_i), u' = p/ρ² (the SPH Lagrangian, Price 2012, §3.2), so `potential`
//! books U and the energy books balance: the viscosity dissipates
//! P = ½ Σ_ij m_i m_j Π_ij v_ij·∇_i W_ij ≥ 0 (Monaghan 1992, §4).
//!
//! Each evaluation counting-sorts the fluid into cells (`grid`), gathers positions and velocities
//! into cell order (structure of arrays, f32 or f64), and runs two passes, density then forces,
//! over contiguous candidate runs, 8 or 16 pairs at a time (SIMD lanes). Forces are gathered per
//! particle: no atomics, bit-identical for any thread count.
pub mod kernels;
mod passes;

use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::grid::CellList;
use crate::par::{self, SyncPtr};
use crate::simd::{self, Level};
use crate::state::Model;
use crate::stop::Stop;
use crate::terms::registry::{Context, Params};
use crate::terms::{Term, Write};
use crate::vector::{Real, Vector};
use kernels::{CubicSpline, Float, Kernel, WendlandC2};
use rayon::prelude::*;
use std::marker::PhantomData;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KernelKind {
    CubicSpline,
    WendlandC2,
}

impl KernelKind {
    pub fn by_name(s: &str) -> Result<Self> {
        match s {
            "cubic_spline" => Ok(Self::CubicSpline),
            "wendland_c2" => Ok(Self::WendlandC2),
            o => Err(invalid("kernel", format!("unknown kernel {o:?}; valid: cubic_spline, wendland_c2"))),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    F32,
    F64,
}

impl Precision {
    pub fn by_name(s: &str) -> Result<Self> {
        match s {
            "f32" | "float32" => Ok(Self::F32),
            "f64" | "float64" => Ok(Self::F64),
            o => Err(invalid("precision", format!("unknown precision {o:?}; valid: f32, f64"))),
        }
    }
}

/// Fluid parameters, SI units.
#[derive(Clone, Copy, Debug)]
pub struct SphParams {
    /// Smoothing length h, m (support 2h).
    pub h: Real,
    /// Rest density ρ0, kg/m^dim.
    pub rho0: Real,
    /// Speed of sound c0, m/s.
    pub c0: Real,
    /// Tait exponent γ (integer, 1..=15; water: 7).
    pub gamma: i32,
    /// Monaghan artificial viscosity α (≥ 0).
    pub alpha: Real,
    /// Clamp the pressure to p ≥ 0 (no tension at the free surface).
    pub clamp: bool,
    pub kernel: KernelKind,
    pub precision: Precision,
}

impl SphParams {
    pub fn validate(&self) -> Result<()> {
        let pos = |v: Real, a: &'static str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(invalid(a, format!("{v} must be finite and > 0")))
            }
        };
        pos(self.h, "h")?;
        pos(self.rho0, "density")?;
        pos(self.c0, "sound_speed")?;
        if !(1..=15).contains(&self.gamma) {
            return Err(invalid("gamma", format!("{} must be an integer in 1..=15", self.gamma)));
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(invalid("viscosity", format!("{} must be finite and >= 0", self.alpha)));
        }
        Ok(())
    }
    /// Tait stiffness B = ρ0 c0² / γ, Pa.
    pub fn b(&self) -> Real {
        self.rho0 * self.c0 * self.c0 / self.gamma as Real
    }
    /// Pressure (Pa) at density `rho`.
    pub fn pressure(&self, rho: Real) -> Real {
        let p = self.b() * ((rho / self.rho0).powi(self.gamma) - 1.0);
        if self.clamp {
            p.max(0.0)
        } else {
            p
        }
    }
    /// Specific internal energy u(ρ) = ∫_{ρ0}^{ρ} p/ρ'² dρ', J/kg (zero at rest density, ≥ 0).
    pub fn internal_energy(&self, rho: Real) -> Real {
        let s = rho / self.rho0;
        if self.clamp && s <= 1.0 {
            return 0.0;
        }
        let g = self.gamma as Real;
        let b = self.b() / self.rho0;
        if self.gamma == 1 {
            b * (s.ln() + 1.0 / s - 1.0)
        } else {
            b * (s.powi(self.gamma - 1) / (g - 1.0) + 1.0 / s - g / (g - 1.0))
        }
    }
}

/// Static wall particles: positions, Ψ_b = ρ0 V_b (kg/m^dim · m^dim = kg), sorted into cells.
#[derive(Clone, Debug)]
struct Walls {
    grid: CellList,
    pos: [Vec<f64>; 3],
    psi: Vec<f64>,
}

/// Sorted, padded structure-of-arrays buffers in the precision of the passes.
#[derive(Clone, Debug, Default)]
struct Bufs<F: Float> {
    pos: [Vec<F>; 3],
    vel: [Vec<F>; 3],
    m: Vec<F>,
    rho: Vec<F>,
    /// p/ρ², m⁵/(kg s²) in 3D.
    pr: Vec<F>,
    wpos: [Vec<F>; 3],
    wpsi: Vec<F>,
}

/// Loads past the end of a run read up to `PAD` padding entries (masked out).
const PAD: usize = 16;

/// The SPH force term over particles `first .. first + n` of a scene.
pub struct Sph<V: Vector> {
    name: String,
    first: usize,
    n: usize,
    p: SphParams,
    grid: CellList,
    walls: Walls,
    b32: Bufs<f32>,
    b64: Bufs<f64>,
    /// Largest |dv/dt| of the last evaluation (without uniform fields), m/s².
    amax: Real,
    /// Wall time spent so far in (cell list + gather, density pass, force pass), s.
    pub clock: [f64; 3],
    /// The stop flag of the call in progress: read between the phases of an evaluation and
    /// before every chunk of its passes (an evaluation at N = 10⁶ takes ~0.3 s).
    stop: Stop,
    /// Scratch: the forces of other terms, kept while the passes write the fluid's.
    prev: Vec<V>,
    _v: PhantomData<V>,
}

/// The registered builder: the fluid's particles `first..first + n` must already be in the
/// scene; parameters as in `SphParams` under the Python API's names.
fn build<V: Vector>(name: String, mut p: Params, ctx: &Context) -> Result<Box<dyn Term<V>>> {
    let (first, n) = (p.count("first", ctx.n_particles)?, p.count("n", ctx.n_particles)?);
    if first + n > ctx.n_particles {
        return Err(invalid(
            "n",
            format!("particles {first}..{} are not all in the scene ({})", first + n, ctx.n_particles),
        ));
    }
    let gamma = p.number("gamma")?;
    if gamma.fract() != 0.0 || gamma.abs() > 1e3 {
        return Err(invalid("gamma", format!("expected a whole number, got {gamma}")));
    }
    let params = SphParams {
        h: p.number("h")?,
        rho0: p.number("density")?,
        c0: p.number("sound_speed")?,
        gamma: gamma as i32,
        alpha: p.number("viscosity")?,
        clamp: p.flag("clamp_pressure")?,
        kernel: KernelKind::by_name(p.text("kernel")?)?,
        precision: Precision::by_name(p.text("precision")?)?,
    };
    let walls = p.take_vectors::<V>("walls")?;
    let psi = p.take_floats("wall_psi")?;
    Ok(Box::new(Sph::new(&name, first, n, params, walls, psi)?))
}
crate::register_term!("sph", build);

impl<V: Vector> Sph<V> {
    /// `walls`: static wall particle positions; `psi`: their Ψ_b = ρ0 V_b (kg), one each.
    pub fn new(name: &str, first: usize, n: usize, p: SphParams, walls: Vec<V>, psi: Vec<Real>) -> Result<Self> {
        p.validate()?;
        if walls.len() != psi.len() {
            return Err(invalid("wall_volume", format!("has {} entries, walls has {}", psi.len(), walls.len())));
        }
        if let Some(i) = walls.iter().position(|w| !w.is_finite()) {
            return Err(invalid("walls", format!("row {i} is not finite")));
        }
        if let Some(i) = psi.iter().position(|w| !(w.is_finite() && *w > 0.0)) {
            return Err(invalid("wall_volume", format!("entry {i} is {} (must be finite and > 0)", psi[i])));
        }
        let support = 2.0 * p.h;
        let nw = walls.len();
        // Sorted copies in f64, f32 and f64 pass buffers (positions and Ψ).
        let bytes = ((nw + PAD) * (V::DIM + 1) * (8 + 4 + 8)) as u128;
        let need = Need::new("add_fluid", bytes, format!("{} wall particles", count(nw as u128)));
        need.check()?;
        let mut wg = CellList::new(support, V::DIM)?;
        wg.reserve(nw, "add_fluid")?;
        wg.build(&walls);
        let mut pos: [Vec<f64>; 3] = Default::default();
        for (d, pd) in pos.iter_mut().enumerate().take(V::DIM) {
            *pd = need.filled(nw + PAD, 0.0)?;
            for (o, &i) in pd.iter_mut().zip(&wg.order) {
                *o = walls[i as usize].comp(d);
            }
        }
        let mut spsi = need.filled(nw + PAD, 0.0)?;
        for (o, &i) in spsi.iter_mut().zip(&wg.order) {
            *o = psi[i as usize];
        }
        let walls = Walls { grid: wg, pos, psi: spsi };
        let mut s = Self {
            name: name.to_string(),
            first,
            n,
            p,
            grid: CellList::new(support, V::DIM)?,
            walls,
            b32: Bufs::default(),
            b64: Bufs::default(),
            amax: 0.0,
            clock: [0.0; 3],
            stop: Stop::default(),
            prev: Vec::new(),
            _v: PhantomData,
        };
        s.b32.set_walls(&s.walls, &need)?;
        s.b64.set_walls(&s.walls, &need)?;
        Ok(s)
    }

    pub fn params(&self) -> &SphParams {
        &self.p
    }
    pub fn range(&self) -> Range<usize> {
        self.first..self.first + self.n
    }
    pub fn n_walls(&self) -> usize {
        self.walls.grid.len()
    }
    /// Heap bytes of the grid and pass buffers (memory-per-particle figures).
    pub fn bytes(&self) -> usize {
        fn b<F: Float>(x: &Bufs<F>) -> usize {
            let s = std::mem::size_of::<F>();
            (x.pos.iter().chain(&x.vel).chain(&x.wpos).map(|v| v.capacity()).sum::<usize>()
                + x.m.capacity()
                + x.rho.capacity()
                + x.pr.capacity()
                + x.wpsi.capacity())
                * s
        }
        self.grid.bytes() + b(&self.b32) + b(&self.b64) + self.walls.grid.bytes()
    }

    /// Density (kg/m^dim) and pressure (Pa) of each fluid particle, in particle order, computed
    /// now in f64.
    pub fn fields(&self, x: &[V], model: &Model) -> (Vec<Real>, Vec<Real>) {
        let mut grid = CellList::new(self.grid.cell_size(), V::DIM).expect("valid cell size");
        let mut b = Bufs::<f64> { wpos: self.b64.wpos.clone(), wpsi: self.b64.wpsi.clone(), ..Bufs::default() };
        let xs = &x[self.range()];
        grid.build(xs);
        b.gather(&grid, xs, None, &model.mass[self.range()]);
        density::<V, f64>(simd::level(), &self.p, &grid, &self.walls.grid, &mut b, Stop::default().flag());
        let mut rho = vec![0.0; self.n];
        let mut p = vec![0.0; self.n];
        for (k, &i) in grid.order.iter().enumerate() {
            rho[i as usize] = b.rho[k];
            p[i as usize] = self.p.pressure(b.rho[k]);
        }
        (rho, p)
    }

    /// `add_forces` at a given SIMD level.
    #[allow(clippy::too_many_arguments)]
    fn forces_at(
        &mut self,
        level: Level,
        x: &[V],
        v: &[V],
        model: &Model,
        f: &mut [V],
        want_power: bool,
        assign: bool,
    ) -> Real {
        let r = self.range();
        if assign {
            // Particles outside the fluid get no SPH force.
            let (head, rest) = f.split_at_mut(r.start);
            head.fill(V::ZERO);
            rest[r.len()..].fill(V::ZERO);
        }
        if self.n == 0 {
            return 0.0;
        }
        // The pass writes the fluid's forces over `f`; to add instead, keep what was there.
        let mut prev = std::mem::take(&mut self.prev);
        prev.clear();
        if !assign {
            prev.extend_from_slice(&f[r.clone()]);
        }
        let (xs, vs, ms, out) = (&x[r.clone()], &v[r.clone()], &model.mass[r.clone()], &mut f[r.clone()]);
        let stop = self.stop.flag();
        let (power, amax) = match self.p.precision {
            Precision::F32 => eval::<V, f32>(
                level,
                &self.p,
                &mut self.grid,
                &self.walls.grid,
                &mut self.b32,
                xs,
                vs,
                ms,
                out,
                want_power,
                &mut self.clock,
                stop,
            ),
            Precision::F64 => eval::<V, f64>(
                level,
                &self.p,
                &mut self.grid,
                &self.walls.grid,
                &mut self.b64,
                xs,
                vs,
                ms,
                out,
                want_power,
                &mut self.clock,
                stop,
            ),
        };
        self.amax = amax;
        if !assign {
            for (fi, pi) in f[r].iter_mut().zip(&prev) {
                *fi += *pi;
            }
        }
        self.prev = prev;
        power
    }
}

/// One evaluation in precision `F`: build the cell list, gather, density pass, force pass.
/// Returns (dissipated power W, max |a|²). Once `stop` is set the rest is skipped and `out` is
/// left partly written.
#[allow(clippy::too_many_arguments)]
fn eval<V: Vector, F: Float>(
    level: Level,
    p: &SphParams,
    grid: &mut CellList,
    walls: &CellList,
    b: &mut Bufs<F>,
    x: &[V],
    v: &[V],
    m: &[Real],
    out: &mut [V],
    want_power: bool,
    clock: &mut [f64; 3],
    stop: &AtomicBool,
) -> (Real, Real) {
    let stopped = || stop.load(Ordering::Relaxed);
    let t0 = std::time::Instant::now();
    grid.build(x);
    if stopped() {
        return (0.0, 0.0);
    }
    b.gather(grid, x, Some(v), m);
    let t1 = std::time::Instant::now();
    density::<V, F>(level, p, grid, walls, b, stop);
    let t2 = std::time::Instant::now();
    clock[0] += (t1 - t0).as_secs_f64();
    clock[1] += (t2 - t1).as_secs_f64();
    if stopped() {
        return (0.0, 0.0);
    }
    let r = match (p.kernel, V::DIM) {
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
    };
    clock[2] += t2.elapsed().as_secs_f64();
    r
}

fn density<V: Vector, F: Float>(
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

impl<F: Float> Bufs<F> {
    /// Room for `gather` of `n` particles.
    fn reserve<V: Vector>(&mut self, n: usize, need: &Need) -> Result<()> {
        for d in 0..V::DIM {
            need.reserve(&mut self.pos[d], n + PAD)?;
            need.reserve(&mut self.vel[d], n + PAD)?;
        }
        for a in [&mut self.m, &mut self.rho, &mut self.pr] {
            need.reserve(a, n + PAD)?;
        }
        Ok(())
    }

    fn set_walls(&mut self, w: &Walls, need: &Need) -> Result<()> {
        for d in 0..3 {
            self.wpos[d] = need.collect(w.pos[d].iter().map(|&a| F::of(a)))?;
        }
        self.wpsi = need.collect(w.psi.iter().map(|&a| F::of(a)))?;
        Ok(())
    }

    /// Positions, velocities and masses into cell order (padded by `PAD`).
    fn gather<V: Vector>(&mut self, grid: &CellList, x: &[V], v: Option<&[V]>, m: &[Real]) {
        let n = x.len();
        let order = &grid.order;
        for d in 0..V::DIM {
            self.pos[d].resize(n + PAD, F::ZERO);
            self.vel[d].resize(n + PAD, F::ZERO);
        }
        self.m.resize(n + PAD, F::ZERO);
        self.rho.resize(n + PAD, F::ONE);
        self.pr.resize(n + PAD, F::ZERO);
        let [p0, p1, p2] = &mut self.pos;
        let [v0, v1, v2] = &mut self.vel;
        let ptr = [SyncPtr(p0.as_mut_ptr()), SyncPtr(p1.as_mut_ptr()), SyncPtr(p2.as_mut_ptr())];
        let vptr = [SyncPtr(v0.as_mut_ptr()), SyncPtr(v1.as_mut_ptr()), SyncPtr(v2.as_mut_ptr())];
        par::chunks1(&mut self.m[..n], |s, mm| {
            for (k, mk) in mm.iter_mut().enumerate() {
                let i = order[s + k] as usize;
                *mk = F::of(m[i]);
                for d in 0..V::DIM {
                    // SAFETY: each sorted slot s + k is written by exactly one chunk.
                    unsafe {
                        *ptr[d].get().add(s + k) = F::of(x[i].comp(d));
                        *vptr[d].get().add(s + k) = F::of(v.map_or(0.0, |v| v[i].comp(d)));
                    }
                }
            }
        });
    }
}

/// s^γ: a fixed multiplication chain for water's γ = 7 (this runs once per particle per step).
#[inline(always)]
pub(crate) fn powi<F: Float>(s: F, gamma: i32) -> F {
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
            simd::dispatch(level, passes::Density::<F, K, D> { p, grid, walls, b, ks, rho, pr, _k: PhantomData });
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
            simd::dispatch(level, passes::Forces::<V, F, K, D, true> { p, grid, walls, b, ks, out, _k: PhantomData })
        } else {
            simd::dispatch(level, passes::Forces::<V, F, K, D, false> { p, grid, walls, b, ks, out, _k: PhantomData })
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

impl<V: Vector> Term<V> for Sph<V> {
    fn name(&self) -> &str {
        &self.name
    }

    fn add_forces(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let want_power = Term::<V>::dissipative(self);
        self.forces_at(simd::level(), x, v, model, f, want_power, write == Write::Overwrite)
    }

    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        if self.n == 0 {
            return Some(0.0);
        }
        let (rho, _) = self.fields(x, model);
        let m = &model.mass[self.range()];
        Some(par::sum(self.n, 0.0, |r| r.map(|i| m[i] * self.p.internal_energy(rho[i])).sum::<Real>()))
    }

    fn dissipative(&self) -> bool {
        self.p.alpha > 0.0
    }

    fn fields(&self, x: &[V], model: &Model) -> Vec<(&'static str, Range<usize>, Vec<Real>)> {
        let (rho, p) = Sph::fields(self, x, model);
        vec![("density", self.range(), rho), ("pressure", self.range(), p)]
    }

    fn profile(&self) -> Option<([f64; 3], usize)> {
        Some((self.clock, self.bytes()))
    }

    fn set_stop(&mut self, stop: Stop) {
        self.stop = stop;
    }

    fn reserve(&mut self, _n_particles: usize) -> Result<()> {
        let n = self.n;
        let (f, arrays) = (
            match self.p.precision {
                Precision::F32 => 4,
                Precision::F64 => 8,
            },
            2 * V::DIM + 3,
        );
        let bytes = (arrays * (n + PAD) * f) as u128 + Need::bytes_of::<V>(n);
        let need = Need::new("step", bytes, format!("the SPH buffers of {} particles", count(n as u128)));
        need.check()?;
        match self.p.precision {
            Precision::F32 => self.b32.reserve::<V>(n, &need)?,
            Precision::F64 => self.b64.reserve::<V>(n, &need)?,
        }
        need.reserve(&mut self.prev, n)?;
        self.grid.reserve(n, "step")
    }

    fn min_particles(&self) -> usize {
        self.first + self.n
    }

    fn max_dt(&self, _x: &[V], v: &[V], _model: &Model, g: Real) -> Option<Real> {
        if self.n == 0 {
            return None;
        }
        let vs = &v[self.range()];
        let vmax = vs.iter().map(|u| u.length_squared()).fold(0.0, f64::max).sqrt();
        // CFL (Monaghan 1992, §5, with the viscous term) and force criterion.
        let cfl = 0.25 * self.p.h / (self.p.c0 * (1.0 + 0.6 * self.p.alpha) + vmax);
        let a = self.amax.sqrt() + g;
        let force = if a > 0.0 { 0.25 * (self.p.h / a).sqrt() } else { f64::INFINITY };
        Some(cfl.min(force))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    fn lcg(s: &mut u64) -> f64 {
        *s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*s >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A jittered lattice blob (moving) plus a floor of wall particles under it.
    fn blob<V: Vector>(n: usize, dx: f64, seed: u64) -> (Vec<V>, Vec<V>, Vec<V>) {
        let mut s = seed;
        let side = (n as f64).powf(1.0 / V::DIM as f64).ceil() as usize;
        let (mut x, mut v, mut w) = (vec![], vec![], vec![]);
        for k in 0..n {
            let mut c = [0.0; 3];
            let mut u = [0.0; 3];
            let mut idx = k;
            for d in 0..V::DIM {
                c[d] = ((idx % side) as f64 + 0.5 + 0.3 * (lcg(&mut s) - 0.5)) * dx;
                u[d] = lcg(&mut s) - 0.5;
                idx /= side;
            }
            x.push(V::from_slice(&c[..V::DIM]));
            v.push(V::from_slice(&u[..V::DIM]));
        }
        for k in 0..side * side {
            for layer in 0..3 {
                let mut c = [0.0; 3];
                c[0] = ((k % side) as f64 + 0.5) * dx;
                if V::DIM == 3 {
                    c[1] = ((k / side) as f64 + 0.5) * dx;
                } else if k >= side {
                    continue;
                }
                c[V::DIM - 1] = -(layer as f64 + 0.5) * dx;
                w.push(V::from_slice(&c[..V::DIM]));
            }
        }
        (x, v, w)
    }

    fn forces<V: Vector>(p: SphParams, x: &[V], v: &[V], w: &[V], m: f64, level: Level) -> (Vec<V>, f64) {
        let n = x.len();
        let model = Model { mass: vec![m; n], inv_mass: vec![1.0 / m; n], ..Default::default() };
        let mut t = Sph::new("fluid", 0, n, p, w.to_vec(), vec![m; w.len()]).unwrap();
        let mut f = vec![V::ZERO; n];
        let pw = t.forces_at(level, x, v, &model, &mut f, true, true);
        (f, pw)
    }

    /// With the call's stop flag set an evaluation writes no fluid force; without it, it does.
    #[test]
    fn a_set_stop_flag_skips_the_evaluation() {
        let (x, v, w) = blob::<DVec2>(900, 0.1, 3);
        let n = x.len();
        let model = Model { mass: vec![10.0; n], inv_mass: vec![0.1; n], ..Default::default() };
        let p = SphParams {
            h: 0.13,
            rho0: 1000.0,
            c0: 20.0,
            gamma: 7,
            alpha: 0.1,
            clamp: true,
            kernel: KernelKind::CubicSpline,
            precision: Precision::F64,
        };
        let mut t = Sph::new("fluid", 0, n, p, w.clone(), vec![10.0; w.len()]).unwrap();
        for stopped in [true, false] {
            t.set_stop(Stop::new(Some(std::sync::Arc::new(AtomicBool::new(stopped)))));
            let sentinel = DVec2::splat(123.0);
            let mut f = vec![sentinel; n];
            t.forces_at(simd::level(), &x, &v, &model, &mut f, true, true);
            let untouched = f.iter().filter(|&&fi| fi == sentinel).count();
            assert_eq!(untouched, if stopped { n } else { 0 }, "stop = {stopped}");
        }
    }

    /// The WCSPH forces and viscous power by brute force over all pairs, in f64, from the scalar
    /// kernel formulas: the oracle of the passes.
    fn brute<V: Vector, K: Kernel>(p: &SphParams, x: &[V], v: &[V], w: &[V], m: f64) -> (Vec<V>, f64) {
        let (n, d) = (x.len(), V::DIM);
        let sigma = K::sigma(p.h, d);
        let wk = |r2: f64| sigma * K::w(r2.sqrt() / p.h);
        let rho: Vec<f64> = (0..n)
            .map(|i| {
                (0..n).map(|j| m * wk((x[i] - x[j]).length_squared())).sum::<f64>()
                    + w.iter().map(|b| m * wk((x[i] - *b).length_squared())).sum::<f64>()
            })
            .collect();
        let pp: Vec<f64> = rho.iter().map(|&r| p.pressure(r) / (r * r)).collect();
        let grad = |r: V| r * (sigma / (p.h * p.h) * K::g(r.length_squared().sqrt() / p.h));
        let mut power = 0.0;
        let f = (0..n)
            .map(|i| {
                let mut a = V::ZERO;
                for j in 0..n {
                    let r = x[i] - x[j];
                    let vr = (v[i] - v[j]).dot(r);
                    let pi = 2.0 * p.alpha * p.c0 * p.h * (-vr).max(0.0)
                        / ((r.length_squared() + 0.01 * p.h * p.h) * (rho[i] + rho[j]));
                    a -= grad(r) * (m * (pp[i] + pp[j] + pi));
                    power += 0.5 * m * m * pi * grad(r).dot(v[i] - v[j]);
                }
                for b in w {
                    a -= grad(x[i] - *b) * (m * pp[i]);
                }
                a * m
            })
            .collect();
        (f, power)
    }

    fn check<V: Vector>() {
        let dx = 0.01;
        for kernel in [KernelKind::CubicSpline, KernelKind::WendlandC2] {
            // Compressed 5 % so that the pressure term is active everywhere.
            let p64 = SphParams {
                h: 1.3 * dx,
                rho0: 1000.0,
                c0: 20.0,
                gamma: 7,
                alpha: 0.1,
                clamp: true,
                kernel,
                precision: Precision::F64,
            };
            let (x, v, w) = blob::<V>(1500, dx * 0.95, 11);
            let m = 1000.0 * dx.powi(V::DIM as i32);
            let (fb, pb) = match kernel {
                KernelKind::CubicSpline => brute::<V, CubicSpline>(&p64, &x, &v, &w, m),
                KernelKind::WendlandC2 => brute::<V, WendlandC2>(&p64, &x, &v, &w, m),
            };
            let scale = fb.iter().map(|f| f.length_squared()).fold(0.0, f64::max).sqrt();
            assert!(scale > 0.0 && pb > 0.0);
            // f32: float32 positions (spacing ~1e-2, |x| ~ 0.2) and sums of ~30 terms.
            for (precision, tol) in [(Precision::F32, 2e-4), (Precision::F64, 1e-11)] {
                let p = SphParams { precision, ..p64 };
                for level in Level::available() {
                    let (fs, ps) = forces(p, &x, &v, &w, m, level);
                    let diff = fs.iter().zip(&fb).map(|(a, b)| (*a - *b).length_squared()).fold(0.0, f64::max).sqrt();
                    assert!(
                        diff <= tol * scale,
                        "{kernel:?} {precision:?} {}D {level:?}: vs brute force {diff:e} of {scale:e}",
                        V::DIM
                    );
                    assert!((ps - pb).abs() <= 10.0 * tol * pb, "{level:?} power {ps} vs {pb}");
                    // Without walls, the pair forces are antisymmetric: Σ f = 0 to round-off.
                    let (f0, _) = forces(p, &x, &v, &[], m, level);
                    let total = f0.iter().fold(V::ZERO, |a, b| a + *b);
                    let abs: f64 = f0.iter().map(|f| f.length_squared().sqrt()).sum();
                    assert!(
                        total.length_squared().sqrt() <= tol * abs,
                        "{kernel:?} {precision:?} {level:?}: net force {total:?} of {abs:e}"
                    );
                }
            }
        }
    }

    #[test]
    fn every_level_matches_brute_force_and_conserves_momentum() {
        check::<DVec2>();
        check::<DVec3>();
    }

    #[test]
    fn internal_energy_is_the_integral_of_p_over_rho_squared() {
        let p = SphParams {
            h: 0.01,
            rho0: 1000.0,
            c0: 30.0,
            gamma: 7,
            alpha: 0.0,
            clamp: false,
            kernel: KernelKind::CubicSpline,
            precision: Precision::F64,
        };
        for &rho in &[950.0, 1000.0, 1013.0, 1100.0] {
            let e = 1e-3;
            let du = (p.internal_energy(rho + e) - p.internal_energy(rho - e)) / (2.0 * e);
            let want = p.pressure(rho) / (rho * rho);
            assert!((du - want).abs() <= 1e-6 * want.abs().max(1e-3), "u'({rho}) = {du}, p/rho^2 = {want}");
        }
        assert_eq!(p.internal_energy(1000.0), 0.0);
        assert!(p.internal_energy(990.0) > 0.0 && p.internal_energy(1010.0) > 0.0);
    }
}
