//! Divergence-free SPH (DFSPH) resident on the device: one fluid of equal-mass particles with
//! static wall particles in a box, 2D or 3D, f32 or f64, the whole step on the device. The
//! method is the CPU's term "dfsph" (`rust_core/src/sph/dfsph`: Bender & Koschier, "Divergence-
//! free SPH for incompressible and viscous fluids", IEEE TVCG 23 (2017) 1193–1206, Algorithms
//! 1–3), stage for stage, written in `dfsph.wgsl`. Per step of dt at the step's positions x:
//!
//! 1. the cell list (`cells.wgsl`), the state gathered into cell order, and per particle the
//!    density ρ_i = σ_d [Σ_j m w_ij + Σ_b Ψ_b w_ib] (walls: Akinci et al. 2012, eq. 4–5) and the
//!    factor 1/D_i, D_i = (s_i + 2 gw_i)·(s_i + gw_i) + Σ_j |m ∇W_ij|² (taken no smaller than its
//!    last term), s_i = Σ_j m ∇W_ij, gw_i = Σ_b Ψ_b ∇W_ib (paper eq. 9, α_i = ρ_i/D_i; the walls'
//!    own push doubled because they mirror the pressure);
//! 2. the divergence solve (Algorithm 3): e_i = (Dρ_i/Dt)₊ with Dρ_i/Dt = Σ_j m v_ij·∇W_ij +
//!    Σ_b Ψ_b v_i·∇W_ib, kept only where the neighbourhood (fluid and walls within 2h) holds at
//!    least 57 % of a full one's particles, κ^v_i/ρ_i = e_i/(dt D_i);
//! 3. Monaghan (1992) viscosity a_i = −Σ_j m Π_ij ∇W_ij (Π_ij = −α c0 h min(v_ij·x_ij, 0) /
//!    ((r² + 0.01h²) ρ̄_ij)) at the divergence-free velocities, with surface tension and
//!    adhesion if asked (below), and the kick v* = v + dt (a + g);
//! 4. the walls' hydrostatic pressure once, v* += dt Σ_b Ψ_b (g·(x_i − x_b)/ρ_i) ∇W_ib (Adami, Hu
//!    & Adams 2012, eq. 27: the CPU's `hydrostatic_walls`), then the density solve (Algorithm 2):
//!    e_i = (ρ_i + dt Dρ_i/Dt(v*) − ρ0)₊, κ_i/ρ_i = e_i/(dt² D_i);
//! 5. the drift x += dt v*, then the box's faces (as `sph`: projection, restitution, friction).
//!
//! Both solves update every velocity at once (Jacobi), v_i −= dt [Σ_j m (κ_i/ρ_i + κ_j/ρ_j)
//! ∇W_ij + 2 (κ_i/ρ_i) Σ_b Ψ_b ∇W_ib] (paper eq. 10–11, a wall sample mirroring its particle's
//! pressure), and stop when the mean error is within the tolerance, mean(e)/ρ0 ≤ `density_tol`
//! and mean(e)·dt/ρ0 ≤ `divergence_tol`, after at least 2 density and 1 divergence iterations, or
//! at `max_iterations`. Warm starts (paper §4.4, as the CPU): the density solve first pushes each
//! compressing particle with 0.4 × its last step's Σκ/ρ; the divergence solve's first iteration
//! takes the larger of its Jacobi κ^v/ρ and 0.5 × the last Σκ^v/ρ (where it compresses). The
//! sums are kept per particle (caller's order) with the step's pressure p = ρ²(Σκ/ρ + Σκ^v/ρ).
//!
//! On the device (issue "GPU fluids, grains and batches"): each solve is recorded as a budget
//! of iterations whose particle passes are dispatched indirectly; the mean error is reduced on
//! the device (a tree per workgroup, then one workgroup over the partial sums in a fixed order,
//! `check`), which stops the solve by emptying the dispatch counts of the passes recorded after
//! it. Nothing is read back within a step: the iteration counts and the finiteness flag come
//! back once per submission (of up to ~0.1 s of steps). The budget is twice the most
//! iterations of the last submission and two more (at most `max_iterations`), so that few
//! empty passes are recorded (each still costs a dispatch and its barrier); a solve
//! that outruns it is marked on the device (`seal`), and the submission is then run again from
//! a copy of its start (positions, velocities, warm starts, books, counters; taken on the
//! device at each submission's start) with the whole `max_iterations` recorded. The passes after
//! a solve's convergence change nothing, so the budget never changes a result. Every sum is a
//! gather in a fixed order (no float atomics): a run repeats bit for bit on one adapter.
//! The pair gradients m ∇W_ij are recomputed by each pass rather than stored (the CPU stores
//! them). Which pairs to visit is stored: `build`, which reads the cell list's 3^d cells
//! anyway, lists each particle's fluid neighbours within 2h (`list_cap` of them at most, about
//! 1.3 full neighbourhoods), and the solves' passes, the viscosity and the surface tension (its
//! normals and pairs) read that list instead of the cells: in 3D at h = 1.3 Δx some 80 pairs
//! in place of the 27 cells' ~475 candidates, ten passes or more a step. A particle with more
//! neighbours than the list holds reads the cells; both visit the same pairs in the same order
//! with the same expressions, so the lists change no bit of a result (tested with the lists
//! off).
//!
//! Surface tension and adhesion (optional; the CPU's `sph::surface`, `Solver::surface_acceleration`):
//! Akinci, Akinci & Teschner, "Versatile surface tension and adhesion for SPH fluids", ACM TOG
//! 32(6) 182 (2013), with H = 2h,
//! a_i += −γ Σ_j K_ij [m C(r_ij) x̂_ij + c (n_i − n_j)] − β Σ_b Ψ_b A(r_ib) x̂_ib
//! (paper eq. 1, 2, 6 and 7; K_ij = 2ρ0/(ρ_i + ρ_j)), the normals n_i = H Σ_j m/ρ_j ∇W_ij
//! (eq. 4) gathered by a pass of their own (`normals`) after the build. γ, C's normalisation,
//! c and β come from the core (`DfsphParams`); the pressure p_i gains the virial of the fluid
//! pairs' surface forces, −γ ρ_i/(2d) Σ_j x_ij·K_ij[…], as on the CPU. Their work is booked with
//! the viscosity's (the same kick).
//!
//! Energy books (the CPU's `books_step`): an incompressible fluid stores no internal energy;
//! every velocity change of the step (the two solves', the viscosity's kick) is booked as
//! dissipation by its work over the step's mean velocity, −Σ m Δv·(v0 + v1)/2, per particle by
//! the thread that owns it. Kinetic + gravity's potential + dissipated then moves by
//! −½ dt Σ m g·(v1 − v0) a step: zero at rest, first order in dt.
//!
//! Not here (the CPU has them): several fluids in one solve, per-particle masses and pinned
//! particles, moving boundaries (rigid bodies), the time step limit (the core's
//! `systems::device_dfsph` takes the CPU's, capillary limit included), checkpoints of the warm
//! starts.
use crate::cells::spread;
use crate::maxima::Maxima;
use crate::particles::Halt;
use crate::sph::{invalid, positive, Kernel};
use crate::tank::{Region, Tank};
use crate::{Bind, Chunk, Gpu, Precision, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// The divergence solve's warm-start share of the last step's Σκ^v/ρ (the CPU's `WARM_START`).
pub const WARM_START: f64 = 0.5;
/// The density solve's share (the CPU's `WARM_START_DENSITY`).
pub const WARM_START_DENSITY: f64 = 0.4;

/// The fluid, its walls' box and the solver settings, SI units. Vectors have three components;
/// z is ignored in 2D.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DfsphParams {
    /// 2 or 3.
    pub dim: usize,
    /// Smoothing length h, m (support 2h).
    pub h: f64,
    /// Mass of each particle, kg.
    pub mass: f64,
    /// Rest density ρ0, kg/m^dim.
    pub rho0: f64,
    /// Monaghan viscosity α (≥ 0) ...
    pub alpha: f64,
    /// ... and the speed c0 (m/s) it is scaled with (a pair's coefficient is α c0 h).
    pub c0: f64,
    pub kernel: Kernel,
    /// Density solve tolerance: mean relative compression (0.001 = 0.1 %).
    pub density_tol: f64,
    /// Divergence solve tolerance: mean (Dρ/Dt)₊ dt / ρ0.
    pub divergence_tol: f64,
    /// Most iterations of each solve (each is recorded: keep it modest, ≤ 1000).
    pub max_iterations: u32,
    /// Uniform gravitational acceleration, m/s².
    pub gravity: [f64; 3],
    /// The box's lower corner, m.
    pub lower: [f64; 3],
    /// The box's upper corner, m (> lower on each axis).
    pub upper: [f64; 3],
    /// Restitution e of the box's faces, in [0, 1].
    pub restitution: f64,
    /// Coulomb friction μ of the box's faces, ≥ 0.
    pub friction: f64,
    /// Akinci et al. (2013) cohesion γ of eq. 1 (and of the curvature term, eq. 6),
    /// m^(d+1)/(kg s²), ≥ 0; 0: no surface tension (no normals pass). The core maps a surface
    /// tension σ to it (`sph::surface::Surface::new`).
    pub cohesion: f64,
    /// The normalisation of the cohesion spline C(r) = k · shape(r) (eq. 2), 1/m^(d+6): 32/(π H⁹)
    /// in 3D, the core's 2D one in 2D (H = 2h), ≥ 0.
    pub cohesion_norm: f64,
    /// The curvature term's weight c (eq. 6 scaled by ρ0/(1000 kg/m^d), the core's
    /// `CURVATURE_RHO`), dimensionless, ≥ 0.
    pub curvature: f64,
    /// Adhesion β of eq. 7 to the wall particles, m⁴/(kg s²), ≥ 0; 0: none.
    pub adhesion: f64,
    /// The solves' Jacobi relaxation ω in (0, 1], folded into each factor (ω/D_k): the core's
    /// `sph::dfsph::relaxation` (1 in 2D at h = 1.3 Δx; 0.585 in 3D).
    pub relaxation: f64,
}

impl Default for DfsphParams {
    /// Water, particles 1 cm apart in 2D (h = 1.3 cm, m = ρ0 (1 cm)²), α = 0.05 with c0 = 20
    /// m/s, the cubic spline, tolerances 0.1 %, 100 iterations at most, g = 9.81 m/s² down y, a
    /// 1 m box without bounce or friction (the CPU tests' settings); no surface tension or
    /// adhesion.
    fn default() -> Self {
        Self {
            dim: 2,
            h: 0.013,
            mass: 0.1,
            rho0: 1000.0,
            alpha: 0.05,
            c0: 20.0,
            kernel: Kernel::CubicSpline,
            density_tol: 1e-3,
            divergence_tol: 1e-3,
            max_iterations: 100,
            gravity: [0.0, -9.81, 0.0],
            lower: [0.0; 3],
            upper: [1.0; 3],
            restitution: 0.0,
            friction: 0.0,
            cohesion: 0.0,
            cohesion_norm: 0.0,
            curvature: 0.0,
            adhesion: 0.0,
            relaxation: 1.0,
        }
    }
}

impl DfsphParams {
    /// `Unsupported` naming the first field out of range.
    pub fn validate(&self) -> Result<()> {
        if !(self.dim == 2 || self.dim == 3) {
            return Err(invalid("dim", format_args!("{} must be 2 or 3", self.dim)));
        }
        positive(self.h, "h")?;
        positive(self.mass, "mass")?;
        positive(self.rho0, "rho0")?;
        positive(self.c0, "c0")?;
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(invalid("alpha", format_args!("{} must be finite and >= 0", self.alpha)));
        }
        for (v, a) in [(self.density_tol, "density_tol"), (self.divergence_tol, "divergence_tol")] {
            if !(v.is_finite() && v > 0.0 && v < 1.0) {
                return Err(invalid(a, format_args!("{v} must be in (0, 1) (a relative error; 0.001 = 0.1 %)")));
            }
        }
        if !(1..=1000).contains(&self.max_iterations) {
            return Err(invalid("max_iterations", format_args!("{} must be in 1..=1000", self.max_iterations)));
        }
        if !self.gravity.iter().all(|g| g.is_finite()) {
            return Err(invalid("gravity", "must be finite"));
        }
        for a in 0..self.dim {
            let (lo, hi) = (self.lower[a], self.upper[a]);
            if !(lo.is_finite() && hi.is_finite() && hi > lo) {
                return Err(invalid("upper", format_args!("axis {a}: [{lo}, {hi}] must be finite with upper > lower")));
            }
        }
        if !(0.0..=1.0).contains(&self.restitution) {
            return Err(invalid("restitution", format_args!("{} is outside [0, 1]", self.restitution)));
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err(invalid("friction", format_args!("{} must be finite and >= 0", self.friction)));
        }
        for (v, a) in [
            (self.cohesion, "cohesion"),
            (self.cohesion_norm, "cohesion_norm"),
            (self.curvature, "curvature"),
            (self.adhesion, "adhesion"),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(a, format_args!("{v} must be finite and >= 0")));
            }
        }
        if !(self.relaxation > 0.0 && self.relaxation <= 1.0) {
            return Err(invalid("relaxation", format_args!("{} must be in (0, 1]", self.relaxation)));
        }
        Ok(())
    }

    /// Cells of the box along x, y, z (z = 1 in 2D), each 2h wide (as `SphParams::cells`).
    pub fn cells(&self) -> Result<[usize; 3]> {
        crate::tank::box_cells(self.dim, self.h, &self.lower, &self.upper)
    }

    /// The box and resolution of the fluid's `Tank`.
    fn region(&self) -> Region {
        Region { dim: self.dim, h: self.h, lower: self.lower, upper: self.upper, number_density: self.rho0 / self.mass }
    }

    /// Neighbours (fluid and walls within 2h) below which the divergence solve leaves a
    /// particle out: 57 % of a full neighbourhood's ω_d (2h)^d ρ0/m, rounded (the CPU's
    /// `n_min`: 12 in 2D at h = 1.3 Δx).
    pub fn n_min(&self) -> u32 {
        use std::f64::consts::PI;
        let h = self.h;
        let ball = if self.dim == 2 { PI * 4.0 * h * h } else { 4.0 / 3.0 * PI * 8.0 * h * h * h };
        (0.57 * ball * self.rho0 / self.mass).round() as u32
    }
}

/// The energy books of the fluid (J).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DfsphBooks {
    /// ½ Σ m |v|².
    pub kinetic: f64,
    /// Gravity's potential −Σ m g·x (zero at the origin).
    pub gravity: f64,
    /// Energy each solve removed so far (its velocity changes' work over the steps' mean
    /// velocities; the density solve's may be negative: it may push, as a spreading column's
    /// pressure does).
    pub divergence: f64,
    pub density: f64,
    /// Energy the viscosity removed so far, with the surface forces' work (the surface energy
    /// they released, negative where they stored it), as the CPU books them.
    pub viscous: f64,
    /// Energy the box's faces removed so far.
    pub collisions: f64,
}

impl DfsphBooks {
    /// Kinetic + potential + dissipated: constant up to −½ dt Σ m g·(v1 − v0) a step.
    pub fn total(&self) -> f64 {
        self.kinetic + self.gravity + (self.divergence + self.density + self.viscous + self.collisions)
    }
}

/// The solves' iteration counts, as read back after the last submission.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DfsphIterations {
    /// The last step's divergence and density iterations (velocity updates).
    pub divergence: u32,
    pub density: u32,
    /// Their totals over every step since `new`, and the steps.
    pub total_divergence: u64,
    pub total_density: u64,
    pub steps: u64,
    /// Solves that stopped at `max_iterations` above their tolerance.
    pub unconverged: u64,
}

/// The solves' mean errors (relative, as the tolerances measure them).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DfsphErrors {
    /// The last step's final errors.
    pub divergence: f64,
    pub density: f64,
    /// The largest final errors of all steps.
    pub divergence_max: f64,
    pub density_max: f64,
}

/// Words of the control buffer (`dfsph.wgsl`'s `ctl`): the finiteness flag, the most
/// iterations of each solve in the submission, and whether one outran its budget.
const CTL_WORDS: usize = 12;
const FLAG: u64 = 8;
const MOST: usize = 9;
const TRUNCATED: usize = 11;
/// The smallest budget of iterations recorded per solve.
const LEAST_BUDGET: u32 = 4;
/// Steps in one submission at most (each holds 4 `max_iterations` dispatches and some).
const MAX_CHUNK: u64 = 256;

/// The particle kernels of `dfsph.wgsl`, in this order.
const PARTICLE_KERNELS: [&str; 11] = [
    "gather",
    "build",
    "div_err0",
    "div_err",
    "div_apply",
    "forces",
    "den_warm",
    "den_err",
    "den_apply",
    "drift",
    "normals",
];
const GATHER: usize = 0;
const BUILD: usize = 1;
const DIV_ERR0: usize = 2;
const DIV_ERR: usize = 3;
const DIV_APPLY: usize = 4;
const FORCES: usize = 5;
const DEN_WARM: usize = 6;
const DEN_ERR: usize = 7;
const DEN_APPLY: usize = 8;
const DRIFT: usize = 9;
const NORMALS: usize = 10;
/// Its control kernels, in this order.
const CONTROL_KERNELS: [&str; 5] = ["init_div", "check_div", "init_den", "check_den", "seal"];
const SEAL: usize = 4;

/// The DFSPH fluid on one device: the state in the caller's order, the cell list and the
/// cell-ordered scratch the passes read.
pub struct Dfsph {
    gpu: Arc<Gpu>,
    precision: Precision,
    p: DfsphParams,
    /// The state, the cell list, the walls and the neighbour lists.
    tank: Tank,
    /// Workgroups of a particle dispatch along x and y (`spread`).
    groups: (u32, u32),
    rho: wgpu::Buffer,
    /// Σκ/ρ, Σκ^v/ρ and the pressure of the last step, caller's order (3n).
    hist: wgpu::Buffer,
    /// Per particle: the divergence, density, viscous and box books (4n, J).
    books: wgpu::Buffer,
    ctl: wgpu::Buffer,
    errs: wgpu::Buffer,
    args: wgpu::Buffer,
    params: wgpu::Buffer,
    staging: wgpu::Buffer,
    bind: wgpu::BindGroup,
    control_bind: wgpu::BindGroup,
    pipes: Vec<wgpu::ComputePipeline>,
    control_pipes: Vec<wgpu::ComputePipeline>,
    chunk: Chunk,
    iterations: DfsphIterations,
    /// The iterations recorded per solve (divergence, density) in the next submission.
    budget: [u32; 2],
    /// Record `max_iterations` always (`record_every_iteration`).
    full: bool,
    /// The copies of a submission's start: (buffer, its copy) pairs.
    backup: Vec<(wgpu::Buffer, wgpu::Buffer)>,
    /// The step limit's largest speed, over `vel`.
    maxima: Maxima,
    /// Bound only: the sorted scratch, the partial sums.
    _keep: Vec<wgpu::Buffer>,
}

impl Dfsph {
    /// Uploads `n` particles: `positions` and `velocities` flat (n·dim; m, m/s), every position
    /// in the box. No wall particles: `with_walls` with none.
    pub fn new(
        gpu: Arc<Gpu>,
        precision: Precision,
        params: DfsphParams,
        positions: &[f64],
        velocities: &[f64],
    ) -> Result<Self> {
        Self::with_walls(gpu, precision, params, positions, velocities, &[], &[])
    }

    /// `new` with static wall particles (Akinci et al. 2012) as the CPU's "dfsph" term takes them
    /// (`walls` flat, M·dim, m; `psi` their Ψ_b = ρ0 V_b, kg, one each, finite and > 0). Those
    /// farther than 2h from the box never meet a particle and are not uploaded.
    ///
    /// Errors: `Unsupported` for parameters out of range (`DfsphParams::validate`), ragged or
    /// non-finite arrays, a position outside the box, more than 2^31 particles or cells, f64
    /// on an adapter without it, or buffers over its limits; `OutOfMemory` naming the buffer.
    pub fn with_walls(
        gpu: Arc<Gpu>,
        precision: Precision,
        params: DfsphParams,
        positions: &[f64],
        velocities: &[f64],
        walls: &[f64],
        psi: &[f64],
    ) -> Result<Self> {
        params.validate()?;
        gpu.check_precision(precision)?;
        let region = params.region();
        let tank = Tank::new(&gpu, precision, "DFSPH", &region, (positions, velocities), (walls, psi))?;
        let (n, d) = (tank.n, params.dim);
        let groups = spread(n.max(1));
        let ngroups = groups.0 as u64 * groups.1 as u64;
        let rb = precision.bytes();
        let (nn, dd) = (n as u64, d as u64);
        use wgpu::BufferUsages as U;
        let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let rho = gpu.buffer("DFSPH densities", nn * rb, st)?;
        let hist = gpu.buffer("DFSPH warm starts and pressure", 3 * nn * rb, st)?;
        let books = gpu.buffer("DFSPH energy books", 4 * nn * rb, st)?;
        // With cohesion, the normals and the surface forces' virial as one more field each.
        let surface = (params.cohesion > 0.0) as u64;
        let sv = gpu.buffer("DFSPH sorted vectors", (8 + surface) * nn * dd * rb, st)?;
        let ss = gpu.buffer("DFSPH sorted scalars", (6 + surface) * nn * rb, st)?;
        let partial = gpu.buffer("DFSPH partial sums", ngroups * rb, st)?;
        let ctl = gpu.buffer("DFSPH control", 4 * CTL_WORDS as u64, st)?;
        let errs = gpu.buffer("DFSPH solver errors", 4 * rb, st)?;
        let args = gpu.buffer("DFSPH indirect counts", 16, st | U::INDIRECT)?;
        let params_buf = gpu.buffer("DFSPH parameters", 48 + 40 * 8, U::UNIFORM | U::COPY_DST)?;
        let backup = vec![
            (tank.pos.clone(), gpu.buffer("DFSPH positions at the submission's start", nn * dd * rb, st)?),
            (tank.vel.clone(), gpu.buffer("DFSPH velocities at the submission's start", nn * dd * rb, st)?),
            (hist.clone(), gpu.buffer("DFSPH warm starts at the submission's start", 3 * nn * rb, st)?),
            (books.clone(), gpu.buffer("DFSPH books at the submission's start", 4 * nn * rb, st)?),
            (ctl.clone(), gpu.buffer("DFSPH control at the submission's start", 4 * CTL_WORDS as u64, st)?),
            (errs.clone(), gpu.buffer("DFSPH errors at the submission's start", 4 * rb, st)?),
        ];
        let staging = gpu.buffer("DFSPH read-back", (4 * nn).max(nn * dd).max(16) * rb, U::MAP_READ | U::COPY_DST)?;
        use Bind::{Read as R, ReadWrite as W, Uniform};
        let uniform = Uniform { dynamic: false };
        let src = concat!(include_str!("dfsph.wgsl"), include_str!("cell_walk.wgsl"), include_str!("box_faces.wgsl"));
        let particle_binds = [uniform, W, W, W, R, R, R, W, W, W, W, R, R, W, W, W, W];
        let t = &tank;
        let particle_bufs: [&wgpu::Buffer; 17] = [
            &params_buf,
            &t.pos,
            &t.vel,
            &rho,
            &t.cell_of,
            &t.start,
            &t.order,
            &sv,
            &ss,
            &hist,
            &books,
            &t.wall,
            &t.wall_start,
            &partial,
            &ctl,
            &t.nbr,
            &t.nlen,
        ];
        let (layout, pipes) = gpu.kernels("dfsph.wgsl", precision, src, &particle_binds, &PARTICLE_KERNELS);
        let bind = crate::grid::bind_group(&gpu, "DFSPH", &layout, &particle_bufs);
        // The control kernels' group: the particle kernels' and the errors and indirect counts
        // (which the particle passes, dispatched from those counts, must not bind).
        let mut control_binds = particle_binds.to_vec();
        control_binds.extend([W, W]);
        let (control_layout, control_pipes) =
            gpu.kernels("dfsph.wgsl control", precision, src, &control_binds, &CONTROL_KERNELS);
        let mut control_bufs = particle_bufs.to_vec();
        control_bufs.extend([&errs, &args]);
        let control_bind = crate::grid::bind_group(&gpu, "DFSPH control", &control_layout, &control_bufs);
        let maxima = Maxima::new(&gpu, precision, n, d, &tank.vel, None)?;
        let mut ctl0 = [0u32; CTL_WORDS];
        ctl0[FLAG as usize] = u32::MAX;
        gpu.queue.write_buffer(&ctl, 0, bytemuck::cast_slice(&ctl0));
        let s = Self {
            gpu,
            precision,
            p: params,
            tank,
            groups,
            rho,
            hist,
            books,
            ctl,
            errs,
            args,
            params: params_buf,
            staging,
            bind,
            control_bind,
            pipes,
            control_pipes,
            chunk: Chunk::new(MAX_CHUNK),
            iterations: DfsphIterations::default(),
            budget: [LEAST_BUDGET.min(params.max_iterations); 2],
            full: false,
            backup,
            maxima,
            _keep: vec![sv, ss, partial],
        };
        s.write_params(1.0);
        s.gpu.wait()?;
        Ok(s)
    }

    pub fn len(&self) -> usize {
        self.tank.n
    }
    pub fn is_empty(&self) -> bool {
        self.tank.n == 0
    }
    pub fn precision(&self) -> Precision {
        self.precision
    }
    pub fn params(&self) -> &DfsphParams {
        &self.p
    }
    /// Wall particles on the device: those of `with_walls` within reach (2h) of the box.
    pub fn n_walls(&self) -> usize {
        self.tank.walls
    }
    /// Cells of the cell list along x, y, z (each 2h wide).
    pub fn cells(&self) -> [usize; 3] {
        self.tank.cells
    }
    /// Entries of each particle's neighbour list (see `list_cap`; 0: the passes read the cells).
    pub fn list_cap(&self) -> u32 {
        self.tank.cap
    }
    /// Sets the neighbour lists' length (at most the one `with_walls` chose; 0: none), for
    /// tests: a particle with more neighbours reads the cells, and the result is the same.
    #[doc(hidden)]
    pub fn set_list_cap(&mut self, cap: u32) {
        self.tank.set_list_cap(cap);
    }

    /// Records every solve's `max_iterations` in every submission instead of the adaptive
    /// budget (for tests: the budget changes no result).
    #[doc(hidden)]
    pub fn record_every_iteration(&mut self, yes: bool) {
        self.full = yes;
    }

    /// The solves' iteration counts as of the last submission (read back with its flag).
    pub fn iterations(&self) -> DfsphIterations {
        self.iterations
    }

    /// The kernels' parameter block with time step `dt` (s); every constant derived on the
    /// host in f64.
    fn write_params(&self, dt: f64) {
        let p = &self.p;
        let h = p.h;
        let tiny = if self.precision == Precision::F32 { 1e-30 } else { 1e-300 };
        let sigma = p.kernel.sigma(h, p.dim);
        let big_h = 2.0 * h;
        let c = self.tank.cells;
        let ng = self.groups.0 * self.groups.1;
        let ints = [
            self.tank.n as u32,
            p.dim as u32,
            c[0] as u32,
            c[1] as u32,
            c[2] as u32,
            (p.kernel == Kernel::WendlandC2) as u32,
            p.n_min(),
            ng,
            p.max_iterations,
            self.groups.0,
            self.groups.1,
            self.tank.cap,
        ];
        let (g, lo, hi) = (p.gravity, p.lower, p.upper);
        let nr = (self.tank.n.max(1) as f64) * p.rho0;
        let reals = [
            1.0 / h,
            p.mass,
            sigma,
            sigma / (h * h),
            p.alpha * p.c0 * h,
            0.01 * h * h,
            4.0 * h * h,
            tiny,
            p.rho0,
            dt,
            1.0 / dt,
            1.0 / (dt * dt),
            g[0],
            g[1],
            g[2],
            lo[0],
            lo[1],
            lo[2],
            hi[0],
            hi[1],
            hi[2],
            p.restitution,
            p.friction,
            p.divergence_tol,
            p.density_tol,
            WARM_START,
            WARM_START_DENSITY,
            dt / nr,
            1.0 / nr,
            // Akinci 2013 (`dfsph.wgsl`'s `surface`): γ, β, c, H, C's norm, H⁶/64, A's 0.007/H^3.25.
            p.cohesion,
            p.adhesion,
            p.curvature,
            big_h,
            p.cohesion_norm,
            big_h.powi(6) / 64.0,
            0.007 / big_h.powf(3.25),
            p.relaxation,
        ];
        self.gpu.write_params(self.precision, &self.params, &ints, &reals);
    }

    /// Records the cell list, the gather and the build (densities, factors) at the positions.
    fn record_build(&self, pass: &mut wgpu::ComputePass) {
        self.tank.cell_build.record(pass, self.tank.n);
        let n = self.groups;
        pass.set_bind_group(0, &self.bind, &[]);
        for pipe in &self.pipes[GATHER..=BUILD] {
            pass.set_pipeline(pipe);
            pass.dispatch_workgroups(n.0, n.1, 1);
        }
    }

    /// A particle kernel over all particles.
    fn direct(&self, pass: &mut wgpu::ComputePass, k: usize) {
        pass.set_bind_group(0, &self.bind, &[]);
        pass.set_pipeline(&self.pipes[k]);
        pass.dispatch_workgroups(self.groups.0, self.groups.1, 1);
    }

    /// A particle kernel over all particles while the running solve goes on (none after).
    fn live(&self, pass: &mut wgpu::ComputePass, k: usize) {
        pass.set_bind_group(0, &self.bind, &[]);
        pass.set_pipeline(&self.pipes[k]);
        pass.dispatch_workgroups_indirect(&self.args, 0);
    }

    /// A control kernel (one workgroup).
    fn control(&self, pass: &mut wgpu::ComputePass, k: usize) {
        pass.set_bind_group(0, &self.control_bind, &[]);
        pass.set_pipeline(&self.control_pipes[k]);
        pass.dispatch_workgroups(1, 1, 1);
    }

    /// One solve with a budget of `budget` iterations: `budget` + 1 error passes, each followed
    /// by the stopping test, and `budget` velocity updates, all but the tests dispatched from
    /// the counts the tests empty once the solve stops; then, below `max_iterations`, the seal
    /// that marks a solve still running.
    fn record_solve(&self, pass: &mut wgpu::ComputePass, kernels: [usize; 4], budget: u32) {
        let [first, err, apply, check] = kernels;
        for it in 0..=budget {
            self.live(pass, if it == 0 { first } else { err });
            self.control(pass, check);
            if it < budget {
                self.live(pass, apply);
            }
        }
        if budget < self.p.max_iterations {
            self.control(pass, SEAL);
        }
    }

    /// Records `steps` whole steps into one command buffer with `budget` iterations per solve,
    /// after the copy of the submission's start (`backup`).
    fn record(&self, steps: u64, budget: [u32; 2]) -> wgpu::CommandBuffer {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        for (b, copy) in &self.backup {
            enc.copy_buffer_to_buffer(b, 0, copy, 0, b.size());
        }
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            for _ in 0..steps {
                self.record_build(&mut pass);
                self.control(&mut pass, 0);
                self.record_solve(&mut pass, [DIV_ERR0, DIV_ERR, DIV_APPLY, 1], budget[0]);
                if self.p.cohesion > 0.0 {
                    self.direct(&mut pass, NORMALS);
                }
                self.direct(&mut pass, FORCES);
                self.control(&mut pass, 2);
                // The density solve's warm start, before its iterations (the CPU's `Before`).
                self.direct(&mut pass, DEN_WARM);
                self.direct(&mut pass, DEN_APPLY);
                self.record_solve(&mut pass, [DEN_ERR, DEN_ERR, DEN_APPLY, 3], budget[1]);
                self.direct(&mut pass, DRIFT);
            }
        }
        enc.finish()
    }

    /// Runs `steps` steps of `dt` (s), in submissions of up to ~0.1 s each (nothing read back
    /// between the steps of one); the stop flag is read before each, and the control words (the
    /// finiteness flag, the iteration counts) after each. Returns the steps completed; on a
    /// halt, those before the failing submission, with `Halt::Diverged` naming the first
    /// particle (the caller's index) that stopped being finite, or `Halt::Failed`.
    pub fn step(&mut self, steps: u64, dt: f64, stop: &AtomicBool) -> std::result::Result<u64, (u64, Halt)> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err((0, Halt::Failed(invalid("dt", format_args!("{dt} must be finite and > 0")))));
        }
        if self.tank.n == 0 {
            return Ok(steps);
        }
        self.write_params(dt);
        let mut done = 0;
        while done < steps {
            if stop.load(Ordering::Relaxed) {
                return Err((done, Halt::Stopped));
            }
            let k = self.chunk.next(steps - done);
            // The flag, the submission's most iterations and the truncation mark, cleared.
            self.gpu.queue.write_buffer(&self.ctl, FLAG * 4, bytemuck::cast_slice(&[u32::MAX, 0, 0, 0]));
            let t0 = Instant::now();
            let read = |me: &Self| -> Result<Vec<u32>> {
                let raw = me.gpu.read_back(&me.ctl, &me.staging, 4 * CTL_WORDS as u64)?;
                Ok(raw.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
            };
            let budget = if self.full { [self.p.max_iterations; 2] } else { self.budget };
            self.gpu.queue.submit([self.record(k, budget)]);
            let mut w = read(self).map_err(|e| (done, Halt::Failed(e)))?;
            if w[TRUNCATED] != 0 {
                // A solve outran its budget: the submission again from its start, with every
                // iteration recorded (the copies also reset the counters and marks).
                let mut enc = self.gpu.device.create_command_encoder(&Default::default());
                for (b, copy) in &self.backup {
                    enc.copy_buffer_to_buffer(copy, 0, b, 0, b.size());
                }
                let max = self.p.max_iterations;
                self.gpu.queue.submit([enc.finish(), self.record(k, [max; 2])]);
                w = read(self).map_err(|e| (done, Halt::Failed(e)))?;
                debug_assert_eq!(w[TRUNCATED], 0);
            }
            for s in 0..2 {
                self.budget[s] = (2 * w[MOST + s] + 2).max(LEAST_BUDGET).min(self.p.max_iterations);
            }
            let it = &mut self.iterations;
            it.divergence = w[2];
            it.density = w[3];
            // The device's totals are u32: widen them, counting each submission's increments.
            let wide = |old: u64, now: u32| old + (now.wrapping_sub(old as u32)) as u64;
            it.total_divergence = wide(it.total_divergence, w[4]);
            it.total_density = wide(it.total_density, w[5]);
            it.unconverged = wide(it.unconverged, w[6]);
            it.steps = wide(it.steps, w[7]);
            if w[FLAG as usize] != u32::MAX {
                return Err((done, Halt::Diverged { particle: w[FLAG as usize] as usize }));
            }
            done += k;
            self.chunk.adapt(k, t0.elapsed().as_secs_f64());
        }
        Ok(done)
    }

    /// The solves' mean errors (read back now).
    pub fn errors(&self) -> Result<DfsphErrors> {
        let e = self.gpu.read_reals(self.precision, &self.errs, &self.staging, 4)?;
        Ok(DfsphErrors { divergence: e[0], density: e[1], divergence_max: e[2], density_max: e[3] })
    }

    /// Positions (m) and velocities (m/s), flat (n·dim), and densities (kg/m^dim, summed now at
    /// these positions), in the caller's particle order, as f64.
    pub fn read(&self) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        if self.tank.n == 0 {
            return Ok((Vec::new(), Vec::new(), Vec::new()));
        }
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            self.record_build(&mut pass);
        }
        self.gpu.queue.submit([enc.finish()]);
        let (x, v) = self.read_state()?;
        Ok((x, v, self.gpu.read_reals(self.precision, &self.rho, &self.staging, self.tank.n)?))
    }

    /// Positions and velocities alone (as `read`), without the density pass.
    pub fn read_state(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        if self.tank.n == 0 {
            return Ok((Vec::new(), Vec::new()));
        }
        let (p, s, nd) = (self.precision, &self.staging, self.tank.n * self.p.dim);
        Ok((self.gpu.read_reals(p, &self.tank.pos, s, nd)?, self.gpu.read_reals(p, &self.tank.vel, s, nd)?))
    }

    /// The largest speed now (m/s), what the step limit's CFL condition takes: reduced on the
    /// device (`maxima`), 16 bytes read back; the same bits as the largest speed the host
    /// finds in `read_state`'s velocities (|v|² summed in f64, its square root).
    pub fn max_speed(&self) -> Result<f64> {
        Ok(self.maxima.read(&self.gpu, self.precision, &self.staging)?.0.sqrt())
    }

    /// The last step's pressure p_i = ρ_i² (Σκ_i/ρ_i + Σκ^v_i/ρ_i), plus with cohesion the
    /// surface forces' virial (the CPU's mechanical pressure), Pa, caller's order (zero before
    /// the first step).
    pub fn pressure(&self) -> Result<Vec<f64>> {
        self.history_part(2)
    }

    /// The warm starts: the last step's Σκ/ρ of the density solve and Σκ^v/ρ of the
    /// divergence solve (m^(dim+2)/(kg s²)), caller's order.
    pub fn warm_starts(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        Ok((self.history_part(0)?, self.history_part(1)?))
    }

    /// Puts back the warm starts and the last step's pressure (`warm_starts` then `pressure`:
    /// 3n values, caller's order; the CPU term's `history` layout), so that a restart or a file
    /// continues as the run it came from. Errors: `Unsupported` for another length or a
    /// non-finite value (nothing changes).
    pub fn set_history(&mut self, history: &[f64]) -> Result<()> {
        if history.len() != 3 * self.tank.n {
            return Err(invalid(
                "history",
                format_args!("expected {} values (3 per particle), got {}", 3 * self.tank.n, history.len()),
            ));
        }
        if let Some(i) = history.iter().position(|h| !h.is_finite()) {
            return Err(invalid("history", format_args!("entry {i} is not finite")));
        }
        if self.tank.n > 0 {
            self.gpu.upload(self.precision, &self.hist, history);
            self.gpu.wait()?;
        }
        Ok(())
    }

    fn history_part(&self, k: u64) -> Result<Vec<f64>> {
        if self.tank.n == 0 {
            return Ok(Vec::new());
        }
        let off = k * self.tank.n as u64 * self.precision.bytes();
        self.gpu.read_reals_at(self.precision, &self.hist, off, &self.staging, self.tank.n)
    }

    /// The energy books now (J; see `DfsphBooks`): the state functions from a read-back, each
    /// sum in f64 in the caller's order, and the dissipated books kept per particle on the
    /// device, summed here in the same order (deterministic).
    pub fn books(&self) -> Result<DfsphBooks> {
        if self.tank.n == 0 {
            return Ok(DfsphBooks::default());
        }
        let (x, v) = self.read_state()?;
        let per = self.gpu.read_reals(self.precision, &self.books, &self.staging, 4 * self.tank.n)?;
        let (p, d, m, n) = (&self.p, self.p.dim, self.p.mass, self.tank.n);
        let (mut kinetic, mut gravity) = (0.0, 0.0);
        for i in 0..n {
            let (xi, vi) = (&x[d * i..d * i + d], &v[d * i..d * i + d]);
            kinetic += m * vi.iter().map(|u| u * u).sum::<f64>();
            gravity -= m * (0..d).map(|a| p.gravity[a] * xi[a]).sum::<f64>();
        }
        let sum = |k: usize| per[k * n..(k + 1) * n].iter().sum::<f64>();
        Ok(DfsphBooks {
            kinetic: 0.5 * kinetic,
            gravity,
            divergence: sum(0),
            density: sum(1),
            viscous: sum(2),
            collisions: sum(3),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_valid_and_the_neighbour_floor_is_the_cpus() {
        let p = DfsphParams::default();
        p.validate().unwrap();
        assert_eq!(p.n_min(), 12);
        assert_eq!(p.cells().unwrap(), [39, 39, 1]);
        let bad = DfsphParams { max_iterations: 0, ..p };
        assert!(bad.validate().unwrap_err().to_string().contains("max_iterations"));
        let bad = DfsphParams { density_tol: 1.5, ..p };
        assert!(bad.validate().unwrap_err().to_string().contains("density_tol"));
        // Surface tension and adhesion: off by default, finite and >= 0.
        assert_eq!((p.cohesion, p.adhesion), (0.0, 0.0));
        let bad = DfsphParams { cohesion: -1.0, ..p };
        assert!(bad.validate().unwrap_err().to_string().contains("cohesion"));
        let bad = DfsphParams { adhesion: f64::NAN, ..p };
        assert!(bad.validate().unwrap_err().to_string().contains("adhesion"));
    }
}
