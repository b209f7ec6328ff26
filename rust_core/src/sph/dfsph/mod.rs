//! DFSPH: divergence-free SPH, Bender & Koschier, "Divergence-free SPH for incompressible and
//! viscous fluids", IEEE TVCG 23 (2017) 1193–1206 (Algorithms 1–3), as the term "dfsph": a fluid
//! whose pressure is not an equation of state but the solution of two velocity projections per
//! step, so its step follows the flow's CFL condition instead of the speed of sound.
//!
//! Per step of dt, at the step's positions x (`integrators/semi_implicit_euler.rs` runs them):
//! 1. neighbour search; ρ_i = Σ_j m_j W_ij + Σ_b Ψ_b W_ib (walls as in WCSPH, Akinci et al. 2012,
//!    eq. 4–5) and the DFSPH factor, here as 1/D_i with
//!    D_i = |Σ_j m_j ∇W_ij + Σ_b Ψ_b ∇W_ib|² + Σ_j |m_j ∇W_ij|² (paper eq. 9: α_i = ρ_i / D_i);
//! 2. divergence solve (Algorithm 3): Dρ_i/Dt = Σ_j m_j v_ij·∇W_ij + Σ_b Ψ_b v_i·∇W_ib, kept
//!    only where it compresses (> 0) and the neighbourhood is at least ~57 % full (a free-surface
//!    particle's divergence is not a compression); κ^v_i/ρ_i = (Dρ_i/Dt)/(dt D_i);
//! 3. non-pressure forces (the term's viscosity, gravity and other terms), kick v* = v + dt a;
//! 4. density solve (Algorithm 2): ρ*_i = ρ_i + dt Dρ_i/Dt(v*), error max(ρ*_i − ρ0, 0) (no
//!    tension at the free surface), κ_i/ρ_i = (ρ*_i − ρ0)/(dt² D_i);
//! 5. drift x += dt v*.
//!
//! Both solvers update all velocities at once (Jacobi) with
//! v_i −= dt [Σ_j m_j (κ_i/ρ_i + κ_j/ρ_j) ∇W_ij + 2 (κ_i/ρ_i) Σ_b Ψ_b ∇W_ib]
//! (paper eq. 10–11; a wall sample mirrors its particle's pressure, p_b = p_i, `Solver::apply`,
//! plus, once a step before the density solve, its hydrostatic part ρ_i g·(x_b − x_i), Adami,
//! Hu & Adams 2012, eq. 27: `hydrostatic_walls`, `hydrostatic_boundary`), and iterate until the mean error over the
//! fluid's particles is below the tolerance: mean(ρ* − ρ0)₊/ρ0 ≤ `density_tol` (paper: 0.01–0.1 %),
//! mean (Dρ/Dt)₊·dt/ρ0 ≤ `divergence_tol`. Warm starts (paper §4.4): each solve starts from
//! a share of the previous step's summed κ/ρ (`WARM_START`, `WARM_START_DENSITY`; κ/ρ = p/ρ²
//! does not scale with dt) on
//! the particles that compress at the solve's start, and adds it to this step's sum: the
//! density solve applies it before its iterations, the divergence solve takes the larger of it
//! and the Jacobi κ/ρ in its first iteration (`WarmStart`: two passes fewer). Those sums
//! are the term's own state (`history`), so a restart or a rollback continues bit for bit.
//! (Only where it compresses: the solves are one-sided, so a push where nothing compresses any
//! more would expand the fluid and never be taken back: energy put in.)
//!
//! Non-pressure force: Monaghan (1992) artificial viscosity with the fluid's α and c0 (the same
//! term and coefficient as WCSPH, eq. in `sph/mod.rs`), which dissipates
//! ½ Σ_ij m_i m_j Π_ij v_ij·∇W_ij ≥ 0 at the velocities v.
//!
//! Surface tension and adhesion (optional): Akinci, Akinci & Teschner (2013), `sph::surface`,
//! from the stored pairs and the step's normals; their work on the fluid (surface energy
//! released, or stored when negative) is booked with the dissipation, so the books balance.
//!
//! Energy books: an incompressible fluid stores no internal energy (`potential` is 0). Every
//! velocity change the term makes in a step (the two solves' and its own forces' kick) is
//! booked as dissipation by its work over the step's mean velocity, −Σ_i m_i Δv_i·(v₀ + v₁)/2
//! (`Solver::books_step`). With the drift x₁ = x₀ + dt v₁ the books then move by exactly
//! semi-implicit Euler's own error, −½ dt Σ_i m_i g·(v₁ − v₀) a step: zero at rest, first order
//! in dt. (Their change of ½ m|v|² instead counted the ½ m (g dt)² the kick gives a resting
//! particle, which the density solve takes out, as dissipation: M g² dt/2 a second.) Together
//! the projections remove energy (they are inelastic); the density solve alone may do positive
//! work, as the pressure that spreads a collapsing column does.
//!
//! Neighbours are stored per step, unlike the WCSPH passes: the solvers visit the same pairs
//! 2 × (iterations) times a step, so each pair's m_j ∇W_ij is computed once (with the density
//! and the factor) and kept with j, chunk by chunk of the sorted particles (`par::CHUNK`), so
//! every pass is a gather over stored pairs: no atomics, bit-identical for any thread count.
//! The build runs on the SIMD layer (`BuildChunk`) with the scalar operations lane by lane, and
//! the passes are scalar, so the results are also the same bits at every SIMD level.
//!
//! Several fluids: DFSPH fluids of one system whose smoothing length, kernel, rest density and
//! solver settings agree are one `Solver` (they find each other through `neighbors::Shared`, as
//! WCSPH fluids do): their particles are gathered into one order (member after member), sorted
//! into one cell list, and solved together, so they push on each other as one incompressible
//! fluid. Each particle sees the walls of every member (the union, a position given twice
//! counted once: a tank given to a pool and a drop is one tank); a pair's viscosity takes the
//! mean of the two fluids' α c0 (symmetric, so momentum is kept); each fluid limits the step by
//! its own CFL number, α c0 and surface tension. The solve's first fluid (the first added, so
//! the first the system evaluates) runs the build, forces and projections for all of them and
//! books their work; the others add nothing, and report the solve's `stats`. One fluid alone
//! reads the scene's arrays in place (no gather), and a column split into several fluids over
//! the same particles steps bit for bit as one.
//!
//! Layout, one stage a file: this file holds the parameters, the term and its roles (`Term`,
//! `VelocityProjection`, `OwnState`); `pairs` the pair build (step 1, on the SIMD layer);
//! `solve` the two solves and the surface forces (steps 2–4); `tests` the tests.
use super::buffers::{cross3, MovingWalls, PassFloat, WallArrays, Walls, PAD};
use super::kernels::{CubicSpline, Kernel, WendlandC2};
use super::params::{positive, KernelKind};
use super::surface::Surface;
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::neighbors::CellList;
use crate::neighbors::Shared;
use crate::par::{self, SyncPtr, CHUNK};
use crate::simd::{self, Kernel as SimdKernel, Simd, P};
use crate::state::Model;
use crate::stop::Stop;
use crate::terms::registry::{Context, Params};
use crate::terms::{
    BodyMotion, Diagnostics, MovingBoundary, OwnState, Projection, Scratch, Setting, Term, Traits, VelocityProjection,
    Write,
};
use crate::vector::{Real, Vector};
use std::marker::PhantomData;
use std::ops::Range;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

mod pairs;
mod relax;
mod solve;

pub use relax::relaxation;

use pairs::*;

/// The share of the last step's summed κ/ρ each solve starts from (module doc). On the Martin &
/// Moyce dam break (20 particles across, T = 0..3) the whole sum made the density solve put in
/// 25 J that the divergence solve then took out (front 8 % fast); a half sum keeps both solves
/// dissipative and cut the density iterations from 3.3 to 2.3 a step against no warm start.
const WARM_START: Real = 0.5;

/// The density solve's share, below `WARM_START`: the one-sided solve cannot take back a warm
/// push that overshoots, and on a resting pool (0.5 × 0.5 m, 24 × 24, α = 0.05, 8 s, three
/// perturbed starts) a larger share set off a jitter near the floor that the solve then fed:
/// late rms speed 0.045–0.049 m/s at 0.5 against 0.017 at 0.4 and 0.014 at 0.35, with 12.8,
/// 17.5 and 20.5 density iterations a step (the threshold lies between 0.4 and 0.5).
const WARM_START_DENSITY: Real = 0.4;

/// The force criterion's share of the CFL number: dt ≤ (`FORCE_CFL` λ) √(h/|g|), 0.15 √(h/|g|)
/// at the default λ = 0.4 (Monaghan's 0.25 let the same pool's floor rows jitter at 0.04–0.08
/// m/s; 0.15: 0.017), and scaled with λ so that the CFL number alone sets how fine the steps
/// are, on a resting fluid as on a fast one (the drift of a dam break then converges with it).
const FORCE_CFL: Real = 0.375;

/// Where a solve applies its warm start (`Dfsph::solve`).
///
/// `Before` (paper, Algorithms 2 and 3): an error pass finds the particles that compress, a
/// velocity pass pushes them with w, then the iterations start: two passes over the pairs.
/// `FirstIteration`: the first iteration pushes each compressing particle with the larger of
/// its Jacobi κ/ρ and w (not their sum, which overshoots: the Jacobi κ/ρ is computed before the
/// warm push), and saves those two passes. Measured on the 41k dam break to T* = 4 (Zen 4,
/// 2 threads, runs alternated, medians of 3): folded into the divergence solve, 4.16 → 4.33
/// iterations a step in both solves but 14.3 → 12.7 passes over the pairs; solver 6.8 → 6.0 ms
/// a step and wall 22.7 → 21.2 s in one comparison, 7.6 → 7.3 ms and 24.4 → 24.2 s in a noisier
/// one; fronts within 0.4 %. Folded into the density solve too, 10.4 against 13.5 ms a step,
/// but a resting layer's jitter rose 0.40 → 0.62 J and a drop held by adhesion no longer
/// spread: the density solve keeps the paper's form.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum WarmStart {
    Before,
    FirstIteration,
}

/// DFSPH parameters, SI units.
#[derive(Clone, Copy, Debug)]
pub struct DfsphParams {
    /// Smoothing length h, m (support 2h).
    pub h: Real,
    /// Rest density ρ0, kg/m^dim.
    pub rho0: Real,
    /// Monaghan viscosity α (≥ 0) ...
    pub alpha: Real,
    /// ... and the speed c0 (m/s) it is scaled with (a pair's coefficient is α c0 h).
    pub c0: Real,
    pub kernel: KernelKind,
    /// Density solver tolerance: mean relative compression (0.001 = 0.1 %).
    pub density_tol: Real,
    /// Divergence solver tolerance: mean (Dρ/Dt)₊ dt / ρ0.
    pub divergence_tol: Real,
    /// Most iterations of each solve.
    pub max_iterations: u32,
    /// CFL number λ of the step limit λ h / |v|max.
    pub cfl: Real,
    /// Surface tension σ, N/m (N in 2D), ≥ 0 (Akinci et al. 2013, `sph::surface`).
    pub surface_tension: Real,
    /// Adhesion to the walls, half the work of adhesion, σ's units, ≥ 0.
    pub adhesion: Real,
    /// The solves' Jacobi relaxation ω in (0, 1]: each iteration applies ω times a particle's
    /// own correction (`relaxation`, from the dimension, kernel and h/Δx; 1 at the defaults,
    /// h = 1.3 Δx in 2D and 1.0 Δx in 3D).
    pub relaxation: Real,
    /// h/Δx, the smoothing the surface tension's calibration was measured at
    /// (`sph::surface::laplace_factor`).
    pub smoothing: Real,
}

impl DfsphParams {
    pub fn validate(&self) -> Result<()> {
        let pos = positive;
        pos(self.h, "h")?;
        pos(self.rho0, "density")?;
        pos(self.c0, "sound_speed")?;
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(invalid("viscosity", format!("{} must be finite and >= 0", self.alpha)));
        }
        for (v, a) in [(self.density_tol, "density_error"), (self.divergence_tol, "divergence_error")] {
            if !(v.is_finite() && v > 0.0 && v < 1.0) {
                return Err(invalid(a, format!("{v} must be in (0, 1) (a relative error; 0.001 = 0.1 %)")));
            }
        }
        if !(1..=100_000).contains(&self.max_iterations) {
            return Err(invalid("max_iterations", format!("{} must be in 1..=100000", self.max_iterations)));
        }
        if !(self.cfl.is_finite() && self.cfl > 0.0 && self.cfl <= 1.0) {
            return Err(invalid("cfl", format!("{} must be in (0, 1]", self.cfl)));
        }
        for (v, a) in [(self.surface_tension, "surface_tension"), (self.adhesion, "adhesion")] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(a, format!("{v} must be finite and >= 0")));
            }
        }
        if !(self.relaxation > 0.0 && self.relaxation <= 1.0) {
            return Err(invalid("relaxation", format!("{} must be in (0, 1]", self.relaxation)));
        }
        Ok(())
    }
}

/// One sorted particle's own quantities of the step (its density is in `Dfsph::rho`, which the
/// pair passes read for neighbours too).
#[derive(Clone, Copy, Debug, Default)]
struct Site<V: Vector> {
    /// 1/D_i (0 for a particle without neighbours).
    dinv: Real,
    /// Σ_b Ψ_b ∇W_ib, kg/m^(dim+1).
    gw: V,
    /// Σ_j m_j ∇W_ij over the fluid pairs, kg/m^(dim+1): the passes split each pair's
    /// (v_i − v_j)·∇W and (κ_i + κ_j)∇W so that only the neighbour's part is summed per pair.
    gs: V,
    /// Whether its neighbourhood is full enough for the divergence solve.
    inner: bool,
    /// Σ_b Ψ_b (g·(x_i − x_b)) ∇W_ib over the static walls, kg/s² (m^(1−dim)): the hydrostatic
    /// part of their mirrored pressure (`Solver::hydrostatic_walls`).
    hw: V,
    /// Σ_b Ψ_b v_b·∇W_ib over the moving walls (the bodies' boundary), kg/(m^dim s): their
    /// share of Dρ_i/Dt is Σ_b Ψ_b (v_i − v_b)·∇W_ib = v_i·(their part of gw) − wv.
    wv: Real,
}

/// The stored pairs of one chunk of sorted particles: particle `s + k`'s are
/// `j[start[k]..start[k + 1]]` with `g` = m_j ∇W_ij (`j` and `g` may run past the chunk's
/// last pair: the build keeps their length, `start` bounds them).
///
/// Tried and not kept for the solver passes (SPH-2D 41k, 2 threads): `g` in f32 (Zen 3: no
/// faster, 8.3–11.1 against 8.0–8.5 ms a step); on Zen 4 at avx512: one factor s_ij with
/// g = (x_i − x_j) s_ij (12 bytes a pair, not 20) and four partial sums, the same time; the
/// passes on the SIMD layer, the neighbours' v and κ gathered lane by lane or built in
/// registers (2–13 % slower: a gathered lane costs a load and an insert, what the scalar loop
/// spends on the whole pair). What did pay in the passes is fewer operations a pair
/// (`pair_sum`). The build is on the SIMD layer (`BuildChunk`).
#[derive(Clone, Debug, Default)]
struct Pairs<V: Vector> {
    start: Vec<u32>,
    j: Vec<u32>,
    g: Vec<V>,
}

impl<V: Vector> Pairs<V> {
    fn bytes(&self) -> usize {
        self.start.capacity() * 4 + self.j.capacity() * 4 + self.g.capacity() * std::mem::size_of::<V>()
    }
}

/// Totals of the solvers, over every step since the term was made (rolled-back steps
/// included).
#[derive(Clone, Copy, Debug, Default)]
struct Books {
    steps: u64,
    density_iterations: u64,
    divergence_iterations: u64,
    /// Solves that stopped at `max_iterations` above their tolerance.
    unconverged: u64,
    /// Final mean errors of the last solves, and the largest of all steps.
    density_error: Real,
    density_error_max: Real,
    divergence_error: Real,
    divergence_error_max: Real,
    /// Mean compression (ρ − ρ0)₊/ρ0 measured by summation at the start of the last step, and
    /// its largest value.
    measured: Real,
    measured_max: Real,
    /// Kinetic energy removed by each solver, J.
    dissipated_density: Real,
    dissipated_divergence: Real,
}

/// One fluid of a solve: its particles in the scene, where they start in the solve's order
/// (the members' particles, member after member), its walls as given and its α c0.
struct Member<V: Vector> {
    range: Range<usize>,
    offset: usize,
    walls: Vec<V>,
    psi: Vec<Real>,
    visc: Real,
}

/// The solve of the DFSPH fluids of one system that share a neighbour search (module doc,
/// "Several fluids"): one fluid alone, or several whose particles are gathered into one order.
pub(super) struct Solver<V: Vector> {
    members: Vec<Member<V>>,
    /// The first member's first particle in the scene, and the particles of all members.
    first: usize,
    n: usize,
    /// The parameters the members share (each keeps its own CFL number, α and c0 for its
    /// step limit).
    p: DfsphParams,
    /// Several members: the scene index of each particle in the solve's order, the positions
    /// and masses gathered in that order, and each sorted particle's α c0 (empty for one).
    to_scene: Vec<u32>,
    xg: Vec<V>,
    mg: Vec<Real>,
    img: Vec<Real>,
    visc: Vec<Real>,
    /// Several members: each particle's α c0 in the solve's order (set when a member joins).
    visc_u: Vec<Real>,
    /// The walls of all members (each position once).
    walls: Walls,
    /// The rigid bodies' boundary particles (`MovingBoundary`), once a coupling has set them.
    moving: Option<MovingWalls<V>>,
    grid: CellList,
    /// Sorted order: positions, masses, per-particle quantities, velocities, κ/ρ of the
    /// iteration and its sum over the solve.
    xs: Vec<V>,
    /// The sorted positions by component (the pair build's candidate test loads them a vector
    /// at a time), each with `PAD` entries of slack past the last particle.
    xc: [Vec<Real>; 3],
    m: Vec<Real>,
    /// Whether the particle is free (pinned ones, inverse mass 0, keep their velocity: the
    /// solves push on them as on a wall that moves).
    free: Vec<bool>,
    sites: Vec<Site<V>>,
    /// Densities, kg/m^dim.
    rho: Vec<Real>,
    vs: Vec<V>,
    k: Vec<Real>,
    ksum: Vec<Real>,
    pairs: Vec<Pairs<V>>,
    /// Whether the sorted data are those of the current step's positions (set by the
    /// divergence stage, cleared by the density stage).
    built: bool,
    /// Warm starts, particle order: Σκ/ρ of the last density solve and Σκ^v/ρ of the last
    /// divergence solve (m^(dim+2)/(kg s²), dt-free).
    kappa: Vec<Real>,
    kappa_v: Vec<Real>,
    /// Pressure p_i = ρ_i² (Σκ_i + Σκ^v_i) of the last step's solves, plus with surface tension
    /// the surface forces' virial (`surface_acceleration`), Pa, particle order.
    pressure: Vec<Real>,
    /// Neighbours per particle below which the divergence solve leaves it out.
    n_min: u32,
    /// Surface tension and adhesion (Akinci 2013), the normals n_i of the step and the virial
    /// pressure of the surface forces (Pa, added to `pressure`), sorted.
    surface: Surface,
    normals: Vec<V>,
    surface_p: Vec<Real>,
    /// The step of the kick that follows the divergence solve (set by it), s.
    kick_dt: Real,
    /// The step's uniform acceleration (world gravity, m/s²), set by each projection.
    gravity: V,
    /// Sorted, for the step's books (`Solver::books_step`): the velocities at the step's
    /// start, the divergence solve's change of them, and the velocities after the kick; and
    /// whether a divergence stage opened the step.
    v_start: Vec<V>,
    dv_div: Vec<V>,
    v_kick: Vec<V>,
    /// The term's own acceleration (viscosity, surface forces) evaluated inside the step.
    a_forces: Vec<V>,
    open: bool,
    books: Books,
    /// Wall time (neighbours + pairs, solver iterations, the rest), s.
    clock: [f64; 3],
    stop: Stop,
}

/// The DFSPH fluid over particles `first .. first + n` of a scene: a member of a `Solver`,
/// alone in it by default, and when added to a system that already has a DFSPH fluid with the
/// same smoothing length, kernel, rest density and solver settings (`Term::share`), a member of
/// that fluid's solve.
pub struct Dfsph<V: Vector> {
    name: String,
    range: Range<usize>,
    /// Its own parameters (its step limit: CFL number, α, c0, surface tension).
    p: DfsphParams,
    /// Its index in the solve (0: the solve's first fluid, which runs it and keeps its books).
    who: usize,
    solver: Arc<Mutex<Solver<V>>>,
}

fn build<V: Vector>(name: String, mut p: Params, ctx: &Context) -> Result<Box<dyn Term<V>>> {
    let (first, n) = super::fluid::particles(&p, ctx)?;
    let iters = p.number("max_iterations")?;
    if iters.fract() != 0.0 || !(1.0..=100_000.0).contains(&iters) {
        return Err(invalid("max_iterations", format!("expected a whole number in 1..=100000, got {iters}")));
    }
    let params = DfsphParams {
        h: p.number("h")?,
        rho0: p.number("density")?,
        alpha: p.number("viscosity")?,
        c0: p.number("sound_speed")?,
        kernel: KernelKind::by_name(p.text("kernel")?)?,
        density_tol: p.number("density_error")?,
        divergence_tol: p.number("divergence_error")?,
        max_iterations: iters as u32,
        cfl: p.number("cfl")?,
        surface_tension: p.number("surface_tension")?,
        adhesion: p.number("adhesion")?,
        relaxation: relaxation(V::DIM, KernelKind::by_name(p.text("kernel")?)?, smoothing(&p)?),
        smoothing: smoothing(&p)?,
    };
    let walls = p.take_vectors::<V>("walls")?;
    let psi = p.take_floats("wall_psi")?;
    Ok(Box::new(Dfsph::new(&name, first, n, params, walls, psi)?))
}
/// The fluid's h/Δx (`Fluid.smoothing`): the key "smoothing", 1.3 (the Fluid's default) where a
/// caller gives none.
pub(crate) fn smoothing(p: &Params) -> Result<Real> {
    if !p.has("smoothing") {
        return Ok(1.3);
    }
    let s = p.number("smoothing")?;
    if !(s.is_finite() && (0.5..=4.0).contains(&s)) {
        return Err(invalid("smoothing", format!("h/spacing must be in [0.5, 4], got {s}")));
    }
    Ok(s)
}

// DFSPH's projections run inside semi-implicit Euler's step (velocity, then position).
crate::register_term!("dfsph", build, (&["semi_implicit_euler"], "method", "DFSPH steps with"));

impl<V: Vector> Dfsph<V> {
    /// `walls`: static wall particle positions; `psi`: their Ψ_b = ρ0 V_b (kg), one each.
    pub fn new(name: &str, first: usize, n: usize, p: DfsphParams, walls: Vec<V>, psi: Vec<Real>) -> Result<Self> {
        let solver = Solver::new(first, n, p, walls, psi)?;
        Ok(Self { name: name.to_string(), range: first..first + n, p, who: 0, solver: Arc::new(Mutex::new(solver)) })
    }

    pub fn range(&self) -> Range<usize> {
        self.range.clone()
    }

    /// The solve (a poisoned lock only means a panic elsewhere: the solver's scratch is rebuilt
    /// by the next build).
    fn solver(&self) -> MutexGuard<'_, Solver<V>> {
        self.solver.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The number of fluids in its solve.
    pub fn solve_size(&self) -> usize {
        self.solver().members.len()
    }

    /// The key under which solves register (`neighbors::Shared`): fluids share one solve when
    /// everything but their particles, walls, CFL number and α c0 agrees.
    fn key(p: &DfsphParams) -> String {
        let b = |x: Real| x.to_bits();
        format!(
            "dfsph h={:#x} {:?} rho0={:#x} tol={:#x},{:#x} it={} st={:#x} ad={:#x}",
            b(p.h),
            p.kernel,
            b(p.rho0),
            b(p.density_tol),
            b(p.divergence_tol),
            p.max_iterations,
            b(p.surface_tension),
            b(p.adhesion)
        )
    }
}

impl<V: Vector> Solver<V> {
    fn new(first: usize, n: usize, p: DfsphParams, walls: Vec<V>, psi: Vec<Real>) -> Result<Self> {
        p.validate()?;
        let checked = Walls::checked(&walls, &psi, 2.0 * p.h)?;
        let visc = p.alpha * p.c0;
        Ok(Self {
            members: vec![Member { range: first..first + n, offset: 0, walls, psi, visc }],
            first,
            n,
            p,
            to_scene: Vec::new(),
            xg: Vec::new(),
            mg: Vec::new(),
            img: Vec::new(),
            visc: Vec::new(),
            visc_u: Vec::new(),
            walls: checked,
            moving: None,
            grid: CellList::new(2.0 * p.h, V::DIM)?,
            xs: Vec::new(),
            xc: Default::default(),
            m: Vec::new(),
            free: Vec::new(),
            sites: Vec::new(),
            rho: Vec::new(),
            vs: Vec::new(),
            k: Vec::new(),
            ksum: Vec::new(),
            pairs: Vec::new(),
            built: false,
            kappa: vec![0.0; n],
            kappa_v: vec![0.0; n],
            pressure: vec![0.0; n],
            n_min: 0,
            surface: Surface::new(p.surface_tension, p.adhesion, p.h, p.rho0, V::DIM, p.smoothing),
            normals: Vec::new(),
            surface_p: Vec::new(),
            kick_dt: 0.0,
            gravity: V::ZERO,
            v_start: Vec::new(),
            dv_div: Vec::new(),
            v_kick: Vec::new(),
            a_forces: Vec::new(),
            open: false,
            books: Books::default(),
            clock: [0.0; 3],
            stop: Stop::default(),
        })
    }

    /// Whether a fluid over `range` can join: no particle in two fluids, and every particle
    /// addressable by the `u32` of the sorted order.
    fn admits(&self, range: &Range<usize>) -> bool {
        self.members.iter().all(|m| m.range.end <= range.start || range.end <= m.range.start)
            && (self.n + range.len()) < u32::MAX as usize
    }

    /// Adds the only member of `other` as the last member; returns its index. The walls become
    /// the union of the members' (a position given twice, the same tank, counted once).
    fn join(&mut self, other: Solver<V>) -> Result<usize> {
        let m = other.members.into_iter().next().expect("a solve has a member");
        let mut seen: std::collections::HashSet<Vec<u64>> = std::collections::HashSet::new();
        let (mut walls, mut psi) = (Vec::new(), Vec::new());
        for mm in self.members.iter().chain(std::iter::once(&m)) {
            for (w, &p) in mm.walls.iter().zip(&mm.psi) {
                if seen.insert((0..V::DIM).map(|c| w.comp(c).to_bits()).collect()) {
                    walls.push(*w);
                    psi.push(p);
                }
            }
        }
        self.walls = Walls::checked(&walls, &psi, 2.0 * self.p.h)?;
        // The solve relaxes as its widest neighbourhood needs (the same h, so the finer
        // spacing: the smaller ω).
        self.p.relaxation = self.p.relaxation.min(other.p.relaxation);
        self.members.push(Member { offset: self.n, ..m });
        self.n += self.members.last().map_or(0, |m| m.range.len());
        self.to_scene = self.members.iter().flat_map(|m| m.range.clone().map(|i| i as u32)).collect();
        self.visc_u = self.members.iter().flat_map(|m| std::iter::repeat_n(m.visc, m.range.len())).collect();
        // The warm starts and pressures, particle order, member after member.
        for a in [&mut self.kappa, &mut self.kappa_v, &mut self.pressure] {
            a.resize(self.n, 0.0);
        }
        self.built = false;
        Ok(self.members.len() - 1)
    }

    /// The scene index of particle `u` of the solve's order.
    #[inline(always)]
    fn at(first: usize, to_scene: &[u32], u: usize) -> usize {
        if to_scene.is_empty() {
            first + u
        } else {
            to_scene[u] as usize
        }
    }
}

impl<V: Vector> Solver<V> {
    /// The viscous and surface forces at (x, v) on every member's particles (module doc).
    fn add_forces(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        if write == Write::Overwrite {
            if self.to_scene.is_empty() {
                let (head, rest) = f.split_at_mut(self.first);
                head.fill(V::ZERO);
                rest[self.n..].fill(V::ZERO);
            } else {
                // Every particle is zeroed, and each member's then overwritten.
                f.fill(V::ZERO);
            }
        }
        if self.n == 0 {
            return 0.0;
        }
        if !self.built {
            self.build(x, model);
            // Only a step's divergence stage keeps the build for the stages after it.
            self.built = false;
        }
        let t0 = Instant::now();
        self.gather_v(v);
        let visc = self.p.alpha * self.p.c0;
        let surf = self.surface;
        if surf.tension() {
            self.compute_normals();
        }
        self.surface_p.clear();
        if surf.tension() || surf.adhesion() {
            self.surface_p.resize(self.n, 0.0);
        }
        // Written below only where the surface forces are on (then it holds n values).
        let sp = SyncPtr(self.surface_p.as_mut_ptr());
        if self.open {
            self.a_forces.clear();
            self.a_forces.resize(self.n, V::ZERO);
        }
        let power = if visc == 0.0 && !surf.tension() && !surf.adhesion() {
            if write == Write::Overwrite {
                for m in &self.members {
                    f[m.range.clone()].fill(V::ZERO);
                }
            }
            0.0
        } else {
            let (pairs, rho, xs, vs, m, h) = (&self.pairs, &self.rho, &self.xs, &self.vs, &self.m, self.p.h);
            let (order, out) = (&self.grid.order, SyncPtr(f.as_mut_ptr()));
            let (first, to_scene, vc) = (self.first, &self.to_scene, &self.visc);
            let eps = 0.01 * h * h;
            let kick_dt = self.kick_dt;
            let open = self.open;
            let av = SyncPtr(self.a_forces.as_mut_ptr());
            par::sum(self.n, 0.0, |ks| {
                let mut power = 0.0;
                for i in ks {
                    let p = &pairs[i / CHUNK];
                    let kk = i % CHUNK;
                    let (xi, vi, ri) = (xs[i], vs[i], rho[i]);
                    let mut a = V::ZERO;
                    for q in p.start[kk] as usize..p.start[kk + 1] as usize {
                        let j = p.j[q] as usize;
                        let (d, vij) = (xi - xs[j], vi - vs[j]);
                        // Π_ij = −α c0 μ_ij / ρ̄_ij, μ_ij = h v_ij·r_ij / (r² + 0.01 h²) for
                        // approaching pairs, else 0 (without a branch: half the pairs approach).
                        let vr = vij.dot(d).min(0.0);
                        // Several fluids: the pair's mean α c0 (symmetric: momentum is kept).
                        let c = if vc.is_empty() { visc } else { 0.5 * (vc[i] + vc[j]) };
                        let pi = -c * h * vr / ((d.length_squared() + eps) * 0.5 * (ri + rho[j]));
                        a -= p.g[q] * pi;
                    }
                    if surf.tension() || surf.adhesion() {
                        let (s, virial) = self.surface_acceleration(i, xi, ri);
                        // SAFETY: each sorted slot i is written by this one iteration.
                        unsafe { *sp.get().add(i) = virial };
                        a += s;
                    }
                    // The work of the term's forces over the kick that follows, F·(v + dt a/2)
                    // (their share of the kick's change of ½ m|v|²), booked as dissipation when taken
                    // out: the viscosity's, and the surface's, which releases energy (< 0) or
                    // stores it. (The viscosity alone, at v, is ½ Σ_ij m_i m_j Π_ij v_ij·∇W_ij;
                    // at v alone the kick's ½ m dt² |a|², which the density solve then takes
                    // out and books, went unbooked: a drop held by its surface tension drifted
                    // its books by 1.5 % per ms, 2D, 2 400 particles.)
                    if open {
                        // Booked with the solves over the step's mean velocity (`books_step`).
                        // SAFETY: each sorted slot i is written by this one iteration.
                        unsafe { *av.get().add(i) = a };
                    } else if self.free[i] {
                        power -= m[i] * a.dot(vi + a * (0.5 * kick_dt));
                    }
                    // SAFETY: `order` is a permutation: each particle is written by one slot.
                    let at = Self::at(first, to_scene, order[i] as usize);
                    unsafe { write.put(&mut *out.get().add(at), a * m[i]) };
                }
                power
            })
        };
        self.clock[2] += t0.elapsed().as_secs_f64();
        power
    }

    /// Density (kg/m^dim) of each particle of member `who`, particle order, computed now.
    fn member_densities(&self, who: usize, x: &[V], model: &Model) -> Vec<Real> {
        let all = self.densities(x, model);
        let m = &self.members[who];
        all[m.offset..m.offset + m.range.len()].to_vec()
    }

    fn bytes(&self) -> usize {
        self.grid.bytes()
            + self.walls.bytes()
            + self.moving.as_ref().map_or(0, MovingWalls::bytes)
            + self.pairs.iter().map(Pairs::bytes).sum::<usize>()
            + (self.xs.capacity() + self.vs.capacity() + self.normals.capacity() + self.xg.capacity())
                * std::mem::size_of::<V>()
            + (self.v_start.capacity() + self.dv_div.capacity() + self.v_kick.capacity() + self.a_forces.capacity())
                * std::mem::size_of::<V>()
            + self.sites.capacity() * std::mem::size_of::<Site<V>>()
            + (self.m.capacity() + self.k.capacity() + self.ksum.capacity() + self.surface_p.capacity()) * 8
            + (self.rho.capacity() + self.xc.iter().map(Vec::capacity).sum::<usize>()) * 8
            + (self.kappa.capacity() + self.kappa_v.capacity() + self.pressure.capacity()) * 8
            + (self.mg.capacity() + self.img.capacity() + self.visc.capacity() + self.visc_u.capacity()) * 8
            + self.to_scene.capacity() * 4
    }

    fn reserve(&mut self) -> Result<()> {
        let n = self.n;
        let vb = std::mem::size_of::<V>();
        let several = !self.to_scene.is_empty();
        // Several members: the gathered positions, masses and α c0 too.
        let per = 6 * vb + std::mem::size_of::<Site<V>>() + (4 + V::DIM) * 8 + if several { vb + 24 } else { 0 };
        let bytes = (n as u128) * per as u128 + (V::DIM * PAD * 8) as u128;
        let need = Need::new("step", bytes, format!("the DFSPH buffers of {} particles", count(n as u128)));
        need.check()?;
        need.reserve(&mut self.xs, n)?;
        need.reserve(&mut self.vs, n)?;
        for a in [&mut self.v_start, &mut self.dv_div, &mut self.v_kick, &mut self.a_forces] {
            need.reserve(a, n)?;
        }
        need.reserve(&mut self.sites, n)?;
        for a in [&mut self.m, &mut self.k, &mut self.ksum, &mut self.rho] {
            need.reserve(a, n)?;
        }
        if several {
            need.reserve(&mut self.xg, n)?;
            for a in [&mut self.mg, &mut self.img, &mut self.visc] {
                need.reserve(a, n)?;
            }
        }
        for xc in self.xc.iter_mut().take(V::DIM) {
            need.reserve(xc, n + PAD)?;
        }
        self.grid.reserve(n, "step")?;
        // The step's checkpoint copies the state (fallibly) and then the terms' histories, which
        // `Term::history` cannot refuse: check now that both still fit (3 reals and 3 vectors a
        // particle), so that a refusal is an error here rather than an abort there.
        let snapshot = Need::bytes_of::<Real>(3 * n) + Need::bytes_of::<V>(3 * n);
        Need::new("step", snapshot, format!("a copy of the DFSPH state of {} particles", count(n as u128)))
            .room(snapshot)
    }

    fn stats(&self) -> Vec<(&'static str, Real)> {
        let b = &self.books;
        vec![
            ("steps", b.steps as Real),
            ("density_iterations", b.density_iterations as Real),
            ("divergence_iterations", b.divergence_iterations as Real),
            ("unconverged", b.unconverged as Real),
            ("density_error", b.density_error),
            ("density_error_max", b.density_error_max),
            ("divergence_error", b.divergence_error),
            ("divergence_error_max", b.divergence_error_max),
            ("measured_density_error", b.measured),
            ("measured_density_error_max", b.measured_max),
            ("dissipated_density_solver", b.dissipated_density),
            ("dissipated_divergence_solver", b.dissipated_divergence),
        ]
    }

    /// Member `who`'s slices of the warm starts and pressures.
    fn history_of(&self, who: usize) -> Result<Vec<Real>> {
        let m = &self.members[who];
        let r = m.offset..m.offset + m.range.len();
        let mut h = Vec::new();
        Need::new(
            "save",
            Need::bytes_of::<Real>(3 * r.len()),
            format!("a DFSPH fluid's warm starts of {} particles", r.len()),
        )
        .reserve(&mut h, 3 * r.len())?;
        h.extend_from_slice(&self.kappa[r.clone()]);
        h.extend_from_slice(&self.kappa_v[r.clone()]);
        h.extend_from_slice(&self.pressure[r]);
        Ok(h)
    }

    fn set_history_of(&mut self, who: usize, h: &[Real]) {
        let m = &self.members[who];
        let (o, n) = (m.offset, m.range.len());
        self.kappa[o..o + n].copy_from_slice(&h[..n]);
        self.kappa_v[o..o + n].copy_from_slice(&h[n..2 * n]);
        self.pressure[o..o + n].copy_from_slice(&h[2 * n..]);
        self.built = false;
    }

    fn project(&mut self, stage: Projection, x: &[V], v: &mut [V], model: &Model, dt: Real, g: V) -> Real {
        if self.n == 0 || self.stop.is_set() {
            return 0.0;
        }
        if (0..V::DIM).any(|c| g.comp(c).to_bits() != self.gravity.comp(c).to_bits()) {
            self.gravity = g;
            self.built = false;
        }
        if stage == Projection::Divergence || !self.built {
            self.build(x, model);
        }
        if stage == Projection::Divergence {
            self.kick_dt = dt;
        }
        let e = self.solve(stage, v, dt);
        if stage == Projection::Density {
            self.built = false;
        }
        e
    }
}

/// A DFSPH fluid's step limit without surface forces (`Dfsph::max_dt`, which the device's
/// fluid also takes): the flow's CFL condition λ h/|v|max, the explicit viscosity's limit and
/// the force criterion of a uniform field of strength `g` (m/s²); `None` where none applies.
pub fn max_dt(cfl: Real, h: Real, dim: usize, alpha: Real, c0: Real, vmax: Real, g: Real) -> Option<Real> {
    let flow = if vmax > 0.0 { cfl * h / vmax } else { f64::INFINITY };
    let viscous = super::resolve::dfsph_viscous(h, dim, alpha, c0);
    let force = if g > 0.0 { FORCE_CFL * cfl * (h / g).sqrt() } else { f64::INFINITY };
    let dt = flow.min(viscous).min(force);
    dt.is_finite().then_some(dt)
}

impl<V: Vector> Term<V> for Dfsph<V> {
    fn name(&self) -> &str {
        &self.name
    }

    fn traits(&self) -> Traits<V> {
        Traits {
            min_particles: self.range.end,
            integrators: crate::terms::registry::integrator_rule("dfsph").map(|r| r.0),
            ..Traits::dissipative()
        }
    }

    /// (`crate::alloc`) The build grows its pair lists inside parallel kernels, where a refusal
    /// cannot be reported; the world checks this much room is left once the step's checkpoint
    /// is taken. After a build: what it held again (a list that must grow reallocates beside
    /// the old one). Before the first: 64 neighbours a particle in 2D, 160 in 3D (a full
    /// neighbourhood is about 21 and 74 at h = 1.3 Δx; the rest covers a longer h), and the
    /// per-particle arrays. The solve's first fluid answers for all of it.
    fn transient_bytes(&self, _n: usize) -> u128 {
        if self.who != 0 {
            return 0;
        }
        let s = self.solver();
        let held: u128 = s.pairs.iter().map(|p| p.bytes() as u128).sum();
        if held > 0 {
            return held;
        }
        let per_pair = Need::bytes_of::<u32>(1) + Need::bytes_of::<V>(1);
        let neighbours: u128 = if V::DIM == 2 { 64 } else { 160 };
        let n = s.n as u128;
        n * neighbours * per_pair
            + n * (Need::bytes_of::<Site<V>>(1) + Need::bytes_of::<V>(2) + Need::bytes_of::<Real>(4))
    }

    /// The viscous and surface forces at (x, v) (module doc); pressure is the projections'.
    /// The solve's first fluid adds them for every fluid of the solve, and books their work.
    fn add_forces(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        if self.who != 0 {
            // The first fluid is always evaluated before (the system evaluates terms in the
            // order they were added) and wrote this fluid's forces.
            if write == Write::Overwrite {
                f.fill(V::ZERO);
            }
            return 0.0;
        }
        self.solver().add_forces(x, v, model, f, write)
    }

    fn potential(&self, _x: &[V], _model: &Model) -> Option<Real> {
        // Incompressible: no internal energy (module doc).
        Some(0.0)
    }

    fn max_dt(&self, _x: &[V], v: &[V], _model: &Model, g: Real) -> Option<Real> {
        if self.range.is_empty() {
            return None;
        }
        let vmax = v[self.range()].iter().map(|u| u.length_squared()).fold(0.0, f64::max).sqrt();
        // The flow's CFL condition λ h/|v|max, the explicit viscosity's limit 0.125 h²/ν with
        // Monaghan's ν = α c0 h/(2(d + 2)) (Monaghan 2005, §4.3), and the force criterion of the
        // uniform fields (a fluid falling from rest has no speed yet), and with surface tension
        // the capillary limit (`Surface::max_dt`). (WCSPH's form
        // λ h/(|v|max + 0.6 α c0) took 2199 steps to T* = 4 on the 41k dam break.) Each fluid
        // of a solve limits the step by its own: a pair's α c0, their mean, is within them.
        let h = self.p.h;
        let capillary = Surface::max_dt(self.p.surface_tension, self.p.adhesion, self.p.rho0, h);
        let dt =
            max_dt(self.p.cfl, h, V::DIM, self.p.alpha, self.p.c0, vmax, g).unwrap_or(f64::INFINITY).min(capillary);
        dt.is_finite().then_some(dt)
    }

    fn fields(&self, x: &[V], model: &Model) -> Vec<(&'static str, Range<usize>, Vec<Real>)> {
        let s = self.solver();
        let m = &s.members[self.who];
        let pressure = s.pressure[m.offset..m.offset + m.range.len()].to_vec();
        vec![("density", self.range(), s.member_densities(self.who, x, model)), ("pressure", self.range(), pressure)]
    }

    /// The solve's clock and buffers are booked once, by its first fluid; its totals (a solve
    /// of several fluids: each reports the same).
    fn diagnostics(&self) -> Diagnostics {
        let s = self.solver();
        let profile = Some(if self.who == 0 { (s.clock, s.bytes()) } else { ([0.0; 3], 0) });
        Diagnostics { profile, stats: s.stats(), ..Diagnostics::default() }
    }

    fn set(&mut self, setting: Setting) {
        if let Setting::Stop(stop) = setting {
            self.solver().stop = stop;
        }
    }

    fn join(&mut self, shared: &mut Shared) -> Result<()> {
        let key = Self::key(&self.p);
        if let Some(other) = shared.find::<Mutex<Solver<V>>>(&key) {
            if Arc::ptr_eq(&other, &self.solver) {
                return Ok(());
            }
            let mut g = other.lock().unwrap_or_else(|e| e.into_inner());
            if g.admits(&self.range) {
                // Move this fluid (alone in its solve until now) into the other solve.
                let mine = std::mem::replace(&mut self.solver, other.clone());
                match Arc::try_unwrap(mine) {
                    Ok(m) => {
                        let stop = g.stop.clone();
                        self.who = g.join(m.into_inner().unwrap_or_else(|e| e.into_inner()))?;
                        g.stop = stop;
                    }
                    Err(mine) => self.solver = mine, // shared already: stay alone
                }
                return Ok(());
            }
            // Its particles overlap a member's: it stays alone, and the solve stays registered.
            return Ok(());
        }
        shared.register(key, self.solver.clone());
        Ok(())
    }

    /// The books need no scratch (the potential is 0).
    fn reserve(&mut self, _n_particles: usize, scratch: Scratch) -> Result<()> {
        match scratch {
            Scratch::Step => self.solver().reserve(),
            Scratch::Potential => Ok(()),
        }
    }

    fn as_projection(&mut self) -> Option<&mut dyn VelocityProjection<V>> {
        Some(self)
    }
    /// The solve's first fluid takes the bodies' boundary for all its fluids.
    fn as_moving_boundary(&mut self) -> Option<&mut dyn MovingBoundary<V>> {
        if self.who == 0 {
            Some(self)
        } else {
            None
        }
    }
    fn as_own_state(&self) -> Option<&dyn OwnState<V>> {
        Some(self)
    }
    fn as_own_state_mut(&mut self) -> Option<&mut dyn OwnState<V>> {
        Some(self)
    }
}

impl<V: Vector> OwnState<V> for Dfsph<V> {
    /// The warm starts and the last step's pressure: 3 values per particle.
    fn history(&self) -> Result<Vec<Real>> {
        self.solver().history_of(self.who)
    }
    fn set_history(&mut self, h: &[Real], _n_particles: usize) -> Result<()> {
        let n = self.range.len();
        if h.len() != 3 * n {
            return Err(invalid("history", format!("expected {} values (3 per particle), got {}", 3 * n, h.len())));
        }
        if let Some(i) = h.iter().position(|x| !x.is_finite()) {
            return Err(invalid("history", format!("entry {i} is not finite")));
        }
        self.solver().set_history_of(self.who, h);
        Ok(())
    }
    /// A snapshot of this term, non-finite values (a rollback of a diverged call) included.
    fn restore_history(&mut self, h: &[Real], _n_particles: usize) {
        assert_eq!(h.len(), 3 * self.range.len(), "a DFSPH term's own history restores");
        self.solver().set_history_of(self.who, h);
    }
}

impl<V: Vector> MovingBoundary<V> for Dfsph<V> {
    fn boundary_sampling(&self, model: &Model) -> (Real, Real, KernelKind, Real) {
        let s = self.solver();
        let spacing = super::buffers::spacing(&model.mass, s.members.iter().map(|m| m.range.clone()), s.p.rho0, V::DIM);
        (s.p.h, s.p.rho0, s.p.kernel, spacing)
    }

    fn set_boundary(&mut self, x: &[V], psi: &[Real], body: &[u32], offset: &[V], bodies: &[BodyMotion<V>]) {
        let mut s = self.solver();
        if x.is_empty() {
            s.moving = None;
        } else {
            let support = 2.0 * s.p.h;
            let mw = s.moving.get_or_insert_with(|| MovingWalls::new(support).expect("a valid support"));
            mw.set(x, psi, body, offset, bodies);
        }
        s.built = false;
    }

    fn books_exchange(&self) -> bool {
        true
    }

    fn boundary_impulses(&self, _dt: Real, out: &mut Vec<(V, [Real; 3])>) {
        out.clear();
        if let Some(mw) = &self.solver().moving {
            out.extend_from_slice(&mw.impulse);
        }
    }
}

impl<V: Vector> VelocityProjection<V> for Dfsph<V> {
    /// The solve's first fluid runs the solve for all its fluids, and books what it removes.
    fn project(&mut self, stage: Projection, x: &[V], v: &mut [V], model: &Model, dt: Real, g: V) -> Real {
        if self.who != 0 {
            return 0.0;
        }
        self.solver().project(stage, x, v, model, dt, g)
    }
}

#[cfg(test)]
mod tests;
