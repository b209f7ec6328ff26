//! Weakly compressible SPH (WCSPH) resident on the device: one fluid of equal-mass particles in a
//! box, 2D or 3D, f32 or f64, a whole step on the device (issue "GPU fluids, grains and
//! batches"). The formulas are the CPU's (`rust_core/src/sph`), written expression by expression
//! in `sph.wgsl`:
//!
//! - Density by summation, ρ_i = σ_d [Σ_j m W(|x_i − x_j|/h) + Σ_b Ψ_b W(|x_i − x_b|/h)], self
//!   included, b over the static wall particles (Akinci et al. 2012, eq. 4–5; Ψ_b = ρ0 V_b, kg).
//! - Tait equation of state p = B[(ρ/ρ0)^γ − 1], B = ρ0 c0²/γ (Monaghan 1994; Becker & Teschner
//!   2007, eq. 6), optionally clamped to p ≥ 0.
//! - The symmetric pressure force with Monaghan (1992) artificial viscosity:
//!   dv_i/dt = −Σ_j m (p_i/ρ_i² + p_j/ρ_j² + Π_ij) ∇_i W_ij − (p_i/ρ_i²) Σ_b Ψ_b ∇_i W_ib + g,
//!   Π_ij = −α c0 μ_ij / ρ̄_ij, μ_ij = h v_ij·x_ij / (r² + 0.01h²) if v_ij·x_ij < 0, else 0;
//!   the walls push with the particle's own pressure mirrored (Akinci et al. 2012, eq. 10) and
//!   no viscosity, as the CPU's `sph::passes::Forces`.
//! - Kernels with support 2h: the cubic spline (Monaghan & Lattanzio 1985) and Wendland C2
//!   (Wendland 1995, in the form of Dehnen & Aly 2012), as `sph::kernels` normalises them.
//! - Semi-implicit Euler, v' = v + dt (f/m + g), x' = x + dt v' (the CPU's
//!   `semi_implicit_euler`), then the box's walls as the CPU's "box" collider
//!   (`constraints::Aabb`: projection onto the face, restitution e, Coulomb friction μ).
//!
//! A step is recorded as dispatches, with no read-back: the cell list (`cells.wgsl`'s kernels:
//! a counting sort, each cell's particles then put in index order), the state copied into cell
//! order, the density pass (which also sums the walls' pressure push, so a step walks the walls'
//! cells once), then one pass of forces, update and walls that reads the cell-ordered
//! copies and writes the state back in the caller's order. The wall particles are static: sorted
//! once on the host by (cell, index) over the same cells (those within one cell outside the grid
//! clamped into its outer cells, those farther dropped: no point of the box is within 2h of
//! them), with a start per cell, uploaded once. Every sum is gathered over the 3^d cells around
//! a particle in a fixed order (the fluid's, then the walls'): no float atomics, and a run
//! repeats bit for bit on one adapter. The density pass also lists each particle's fluid
//! neighbours within 2h, itself included (`list_cap` of them at most), and the forces' pass
//! reads that list instead of the cells (in 3D at h = 1.3 Δx some 80 pairs in place of ~475
//! candidates); a particle with more neighbours reads the cells, and both visit the same pairs
//! in the same order with the same expressions, so the lists change no bit (tested with them
//! off). Against the CPU, f64 agrees to round-off, not bit for bit: the CPU's SIMD passes
//! fuse some products (`mul_add`) and add their lanes in another order.
//!
//! The energy books (`Sph::books`) are the CPU's (`ParticleSystem::energy`): the state functions
//! (kinetic energy, the fluid's internal energy Σ m u(ρ), gravity's potential −Σ m g·x) from a
//! read-back, and the two accumulated books (viscous dissipation, what the box's faces removed)
//! kept on the device per particle by the thread that owns it during `integrate`, summed on the
//! host in the caller's order when read: no float atomics, nothing read back during a step. The
//! wall particles book nothing of their own, as on the CPU: they enter the densities, so the
//! internal energy, and their force is that energy's gradient.
//!
//! Not here (the CPU has them): moving wall particles (rigid bodies' boundary samples), several
//! fluids sharing one search, per-particle masses, the time step limit, checkpoints.
use crate::cells::spread;
use crate::maxima::Maxima;
use crate::particles::Halt;
use crate::tank::{Region, Tank};
use crate::{Bind, Chunk, Gpu, GpuError, Precision, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// The smoothing kernel (support 2h).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// Cubic spline (M4), Monaghan & Lattanzio (1985): σ₂ = 10/(7π h²), σ₃ = 1/(π h³).
    CubicSpline,
    /// Wendland C2, support-2h form of Dehnen & Aly (2012): σ₂ = 7/(4π h²), σ₃ = 21/(16π h³).
    WendlandC2,
}

impl Kernel {
    /// The stable name ("cubic_spline", "wendland_c2").
    pub fn name(self) -> &'static str {
        match self {
            Kernel::CubicSpline => "cubic_spline",
            Kernel::WendlandC2 => "wendland_c2",
        }
    }

    /// By name; `Unsupported` listing the valid names for any other.
    pub fn by_name(s: &str) -> Result<Self> {
        match s {
            "cubic_spline" => Ok(Kernel::CubicSpline),
            "wendland_c2" => Ok(Kernel::WendlandC2),
            o => Err(GpuError::Unsupported(format!("unknown kernel {o:?}; valid: cubic_spline, wendland_c2"))),
        }
    }

    /// The normalisation σ_d (1/m^dim) for dimension `dim` (2 or 3) and smoothing length `h` (m):
    /// `sph::kernels`' `sigma`.
    pub fn sigma(self, h: f64, dim: usize) -> f64 {
        use std::f64::consts::PI;
        match (self, dim) {
            (Kernel::CubicSpline, 2) => 10.0 / (7.0 * PI * h * h),
            (Kernel::CubicSpline, _) => 1.0 / (PI * h * h * h),
            (Kernel::WendlandC2, 2) => 7.0 / (4.0 * PI * h * h),
            (Kernel::WendlandC2, _) => 21.0 / (16.0 * PI * h * h * h),
        }
    }
}

/// The fluid and its box, SI units. Vectors have three components; z is ignored in 2D.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphParams {
    /// 2 or 3.
    pub dim: usize,
    /// Smoothing length h, m (support 2h).
    pub h: f64,
    /// Mass of each particle, kg.
    pub mass: f64,
    /// Rest density ρ0, kg/m^dim.
    pub rho0: f64,
    /// Speed of sound c0, m/s (sets the Tait stiffness B = ρ0 c0²/γ).
    pub c0: f64,
    /// Tait exponent γ, 1..=15 (water: 7).
    pub gamma: u32,
    /// Monaghan artificial viscosity α (≥ 0).
    pub alpha: f64,
    /// Clamp the pressure to p ≥ 0 (no tension at the free surface).
    pub clamp: bool,
    pub kernel: Kernel,
    /// Uniform gravitational acceleration, m/s².
    pub gravity: [f64; 3],
    /// The box's lower corner, m.
    pub lower: [f64; 3],
    /// The box's upper corner, m (> lower on each axis).
    pub upper: [f64; 3],
    /// Restitution e of the box's walls, in [0, 1].
    pub restitution: f64,
    /// Coulomb friction μ of the box's walls, ≥ 0.
    pub friction: f64,
}

impl Default for SphParams {
    /// Water in a 1 m box, particles 1 cm apart in 2D (h = 1.3 cm, m = ρ0 (1 cm)²), sound at
    /// 20 m/s, γ = 7, α = 0.1, clamped pressure, the cubic spline, g = 9.81 m/s² down y, walls
    /// without bounce or friction.
    fn default() -> Self {
        Self {
            dim: 2,
            h: 0.013,
            mass: 0.1,
            rho0: 1000.0,
            c0: 20.0,
            gamma: 7,
            alpha: 0.1,
            clamp: true,
            kernel: Kernel::CubicSpline,
            gravity: [0.0, -9.81, 0.0],
            lower: [0.0; 3],
            upper: [1.0; 3],
            restitution: 0.0,
            friction: 0.0,
        }
    }
}

/// The error for argument `what` (the particle kernels' checks share it: sph, dfsph, dem).
pub(crate) fn invalid(what: &str, why: impl std::fmt::Display) -> GpuError {
    GpuError::Unsupported(format!("{what}: {why}"))
}

pub(crate) fn positive(v: f64, what: &str) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(what, format_args!("{v} must be finite and > 0")))
    }
}

impl SphParams {
    /// `Unsupported` naming the first field out of range.
    pub fn validate(&self) -> Result<()> {
        if !(self.dim == 2 || self.dim == 3) {
            return Err(invalid("dim", format_args!("{} must be 2 or 3", self.dim)));
        }
        positive(self.h, "h")?;
        positive(self.mass, "mass")?;
        positive(self.rho0, "rho0")?;
        positive(self.c0, "c0")?;
        if !(1..=15).contains(&self.gamma) {
            return Err(invalid("gamma", format_args!("{} must be in 1..=15", self.gamma)));
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(invalid("alpha", format_args!("{} must be finite and >= 0", self.alpha)));
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
        Ok(())
    }

    /// Tait stiffness B = ρ0 c0²/γ, Pa.
    pub fn b(&self) -> f64 {
        self.rho0 * self.c0 * self.c0 / self.gamma as f64
    }

    /// Pressure (Pa) at density `rho` (kg/m^dim): B[(ρ/ρ0)^γ − 1], clamped to ≥ 0 if asked.
    pub fn pressure(&self, rho: f64) -> f64 {
        let p = self.b() * ((rho / self.rho0).powi(self.gamma as i32) - 1.0);
        if self.clamp {
            p.max(0.0)
        } else {
            p
        }
    }

    /// Specific internal energy u(ρ) = ∫_{ρ0}^{ρ} p/ρ'² dρ' (J/kg; zero at ρ0, ≥ 0): the CPU's
    /// `sph::SphParams::internal_energy`, expression by expression.
    pub fn internal_energy(&self, rho: f64) -> f64 {
        let s = rho / self.rho0;
        if self.clamp && s <= 1.0 {
            return 0.0;
        }
        let g = self.gamma as f64;
        let b = self.b() / self.rho0;
        if self.gamma == 1 {
            b * (s.ln() + 1.0 / s - 1.0)
        } else {
            b * (s.powi(self.gamma as i32 - 1) / (g - 1.0) + 1.0 / s - g / (g - 1.0))
        }
    }

    /// Cells of the box along x, y, z (z = 1 in 2D), each 2h wide (the support): the cell list
    /// covers [lower, lower + cells · 2h] ⊇ the box. `Unsupported` past 2^31 cells.
    pub fn cells(&self) -> Result<[usize; 3]> {
        crate::tank::box_cells(self.dim, self.h, &self.lower, &self.upper)
    }

    /// The box and resolution of the fluid's `Tank`.
    pub(crate) fn region(&self) -> Region {
        Region { dim: self.dim, h: self.h, lower: self.lower, upper: self.upper, number_density: self.rho0 / self.mass }
    }
}

/// The energy books of the fluid (J), as the CPU's `ParticleSystem::energy` reports them for a
/// world of the "sph" term, a "gravity" term and the "box" collider.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SphBooks {
    /// ½ Σ m |v|².
    pub kinetic: f64,
    /// The fluid's internal energy Σ m u(ρ), densities summed at the current positions (the sph
    /// term's potential).
    pub internal: f64,
    /// Gravity's potential −Σ m g·x (zero at the origin, as the CPU's gravity term).
    pub gravity: f64,
    /// Energy the artificial viscosity dissipated so far (the sph term's dissipated book).
    pub viscous: f64,
    /// Energy the box's walls removed so far (the "collisions" book).
    pub collisions: f64,
}

impl SphBooks {
    /// Kinetic + potentials + dissipated: constant up to the integrator's error.
    pub fn total(&self) -> f64 {
        self.kinetic + (self.internal + self.gravity) + (self.viscous + self.collisions)
    }
}

/// The WCSPH fluid on one device: positions, velocities and densities in the caller's particle
/// order, the cell list and the cell-ordered copies the passes read.
pub struct Sph {
    gpu: Arc<Gpu>,
    precision: Precision,
    p: SphParams,
    /// The state, the cell list, the walls and the neighbour lists.
    tank: Tank,
    rho: wgpu::Buffer,
    /// The first particle whose state stopped being finite (u32::MAX: none).
    flag: wgpu::Buffer,
    /// Per particle (caller's order): the viscous books, then the walls' (2n reals, J), then
    /// the squared pressure and viscous acceleration of the last step (n reals, m²/s⁴).
    books: wgpu::Buffer,
    /// The parameter block of the SPH kernels (its dt written by each `step`).
    params: wgpu::Buffer,
    staging: wgpu::Buffer,
    sph_bind: wgpu::BindGroup,
    /// sph.wgsl's gather, density, integrate.
    sph_pipes: Vec<wgpu::ComputePipeline>,
    /// The step limit's maxima over `vel` and the squared accelerations in `books`.
    maxima: Maxima,
    /// Steps per submission (about 0.1 s each).
    chunk: Chunk,
    /// The cell-ordered copies (bound only).
    _keep: Vec<wgpu::Buffer>,
}

/// Steps in one submission at most.
const MAX_CHUNK: u64 = 1024;

impl Sph {
    /// Uploads `n` particles: `positions` and `velocities` flat (n·dim; m, m/s), every position
    /// in the box. No wall particles: `with_walls` with none.
    ///
    /// Errors: `Unsupported` for parameters out of range (`SphParams::validate`), ragged or
    /// non-finite arrays, a position outside the box, more than 2^31 particles or cells, f64 on
    /// an adapter without it, or buffers over its limits; `OutOfMemory` naming the buffer.
    pub fn new(
        gpu: Arc<Gpu>,
        precision: Precision,
        params: SphParams,
        positions: &[f64],
        velocities: &[f64],
    ) -> Result<Self> {
        Self::with_walls(gpu, precision, params, positions, velocities, &[], &[])
    }

    /// `new` with static wall particles (Akinci et al. 2012), as the CPU's "sph" term takes them
    /// (`walls`, `wall_psi`): `walls` flat (M·dim, m), anywhere (usually just outside the box,
    /// e.g. three lattice layers lining it); `psi` their Ψ_b = ρ0 V_b (kg), one each, finite
    /// and positive (a wall sampled on the fluid's lattice: Ψ_b = the particle mass). They add
    /// Σ_b Ψ_b W_ib to each density and push with the particle's own pressure mirrored (see the
    /// module docs). Those farther than 2h from the box never meet a particle and are not
    /// uploaded.
    ///
    /// Errors: as `new`, and `Unsupported` naming `walls` (ragged, non-finite, 2^31 or more) or
    /// `psi` (not one per wall, not finite and > 0).
    pub fn with_walls(
        gpu: Arc<Gpu>,
        precision: Precision,
        params: SphParams,
        positions: &[f64],
        velocities: &[f64],
        walls: &[f64],
        psi: &[f64],
    ) -> Result<Self> {
        params.validate()?;
        gpu.check_precision(precision)?;
        let region = params.region();
        let tank = Tank::new(&gpu, precision, "SPH", &region, (positions, velocities), (walls, psi))?;
        let (n, d) = (tank.n, params.dim);
        let rb = precision.bytes();
        let nn = n as u64;
        use wgpu::BufferUsages as U;
        let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let rho = gpu.buffer("SPH densities", nn * rb, st)?;
        let flag = gpu.buffer("SPH divergence flag", 16, st)?;
        let books = gpu.buffer("SPH energy books", (3 * nn * rb).max(16), st)?;
        let spos = gpu.buffer("SPH sorted positions", nn * d as u64 * rb, st)?;
        let svel = gpu.buffer("SPH sorted velocities", nn * d as u64 * rb, st)?;
        let srho = gpu.buffer("SPH sorted densities", nn * rb, st)?;
        let spr = gpu.buffer("SPH sorted p/rho^2", nn * rb, st)?;
        let swall = gpu.buffer("SPH sorted wall pushes", nn * d as u64 * rb, st)?;
        let params_buf = gpu.buffer("SPH parameters", 48 + 24 * rb, U::UNIFORM | U::COPY_DST)?;
        let staging = gpu.buffer("SPH read-back", (nn * d as u64 * rb).max(16), U::MAP_READ | U::COPY_DST)?;
        use Bind::{Read as R, ReadWrite as W, Uniform};
        let uniform = Uniform { dynamic: false };
        let (layout, sph_pipes) = gpu.kernels(
            "sph.wgsl",
            precision,
            concat!(include_str!("sph.wgsl"), include_str!("cell_walk.wgsl"), include_str!("box_faces.wgsl")),
            &[uniform, W, W, W, R, R, R, W, W, W, W, W, W, R, R, W, W, W],
            &["gather", "density", "integrate"],
        );
        let t = &tank;
        let sph_bind = crate::grid::bind_group(
            &gpu,
            "SPH",
            &layout,
            &[
                &params_buf,
                &t.pos,
                &t.vel,
                &rho,
                &t.cell_of,
                &t.start,
                &t.order,
                &spos,
                &svel,
                &srho,
                &spr,
                &flag,
                &books,
                &t.wall,
                &t.wall_start,
                &t.nbr,
                &t.nlen,
                &swall,
            ],
        );
        let maxima = Maxima::new(&gpu, precision, n, d, &t.vel, Some((&books, 2 * nn)))?;
        let s = Self {
            gpu,
            precision,
            p: params,
            tank,
            maxima,
            rho,
            flag,
            books,
            params: params_buf,
            staging,
            sph_bind,
            sph_pipes,
            chunk: Chunk::new(MAX_CHUNK),
            _keep: vec![spos, svel, srho, spr, swall],
        };
        s.write_params(0.0);
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
    pub fn params(&self) -> &SphParams {
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
    /// Entries of each particle's neighbour list (see `list_cap`; 0: `integrate` reads the cells).
    pub fn list_cap(&self) -> u32 {
        self.tank.cap
    }
    /// Sets the neighbour lists' length (at most the one `with_walls` chose; 0: none), for
    /// tests: a particle with more neighbours reads the cells, and the result is the same.
    #[doc(hidden)]
    pub fn set_list_cap(&mut self, cap: u32) {
        self.tank.set_list_cap(cap);
    }

    /// The SPH kernels' parameter block, with time step `dt` (s); every constant derived from
    /// the parameters in f64 on the host, as the CPU derives them.
    fn write_params(&self, dt: f64) {
        let p = &self.p;
        let h = p.h;
        let tiny = if self.precision == Precision::F32 { 1e-30 } else { 1e-300 };
        let sigma = p.kernel.sigma(h, p.dim);
        let c = self.tank.cells;
        let ints = [
            self.tank.n as u32,
            p.dim as u32,
            c[0] as u32,
            c[1] as u32,
            c[2] as u32,
            (p.kernel == Kernel::WendlandC2) as u32,
            p.gamma,
            p.clamp as u32,
            self.tank.cap,
            0,
            0,
            0,
        ];
        let (g, lo, hi) = (p.gravity, p.lower, p.upper);
        let reals = [
            1.0 / h,
            p.mass,
            1.0 / p.mass,
            sigma,
            -sigma / (h * h),
            2.0 * p.alpha * p.c0 * h,
            0.01 * h * h,
            4.0001 * h * h,
            tiny,
            p.b(),
            1.0 / p.rho0,
            dt,
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
        ];
        self.gpu.write_params(self.precision, &self.params, &ints, &reals);
    }

    /// Records the cell list's build and the density pass at the current positions.
    fn record_density(&self, pass: &mut wgpu::ComputePass) {
        self.tank.cell_build.record(pass, self.tank.n);
        let n = spread(self.tank.n);
        pass.set_bind_group(0, &self.sph_bind, &[]);
        for pipe in &self.sph_pipes[..2] {
            pass.set_pipeline(pipe);
            pass.dispatch_workgroups(n.0, n.1, 1);
        }
    }

    /// Records `steps` whole steps into one command buffer.
    fn record(&self, steps: u64) -> wgpu::CommandBuffer {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            let n = spread(self.tank.n);
            for _ in 0..steps {
                self.record_density(&mut pass);
                pass.set_pipeline(&self.sph_pipes[2]);
                pass.dispatch_workgroups(n.0, n.1, 1);
            }
        }
        enc.finish()
    }

    /// Runs `steps` steps of `dt` (s). Steps are recorded into submissions of up to ~0.1 s each
    /// (nothing read back between the steps of one); the stop flag is read before each, and the
    /// finiteness flag (one u32) after each. Returns the steps completed; on a halt, those before
    /// the failing submission, with `Halt::Diverged` naming the first particle (the caller's
    /// index) that stopped being finite, or `Halt::Failed` (`Unsupported` for a `dt` that is
    /// not finite and > 0; a device error).
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
            self.gpu.queue.write_buffer(&self.flag, 0, bytemuck::cast_slice(&[u32::MAX]));
            let t0 = Instant::now();
            self.gpu.queue.submit([self.record(k)]);
            let bad = self.gpu.read_u32(&self.flag, &self.staging).map_err(|e| (done, Halt::Failed(e)))?;
            if bad != u32::MAX {
                return Err((done, Halt::Diverged { particle: bad as usize }));
            }
            done += k;
            self.chunk.adapt(k, t0.elapsed().as_secs_f64());
        }
        Ok(done)
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
            self.record_density(&mut pass);
        }
        self.gpu.queue.submit([enc.finish()]);
        let (x, v) = self.read_state()?;
        Ok((x, v, self.gpu.read_reals(self.precision, &self.rho, &self.staging, self.tank.n)?))
    }

    /// Positions and velocities alone (as `read`), without the density pass that `read` runs:
    /// what a frame or a checkpoint needs.
    pub fn read_state(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        if self.tank.n == 0 {
            return Ok((Vec::new(), Vec::new()));
        }
        let (p, s, nd) = (self.precision, &self.staging, self.tank.n * self.p.dim);
        Ok((self.gpu.read_reals(p, &self.tank.pos, s, nd)?, self.gpu.read_reals(p, &self.tank.vel, s, nd)?))
    }

    /// The step limit's inputs: the largest speed now (m/s) and the largest squared pressure
    /// and viscous acceleration of the last step (m²/s⁴; 0 before the first), as the CPU's
    /// WCSPH takes them (`sph::fluid`'s `max_dt`). Reduced on the device (`maxima`): 16 bytes
    /// read back, the same bits as `extremes_from_read_back`.
    pub fn extremes(&self) -> Result<(f64, f64)> {
        let (v2, a2) = self.maxima.read(&self.gpu, self.precision, &self.staging)?;
        Ok((v2.sqrt(), a2))
    }

    /// `extremes` from a read-back of every velocity and squared acceleration, the maxima taken
    /// on the host: the reference the device's reduction is tested and timed against.
    #[doc(hidden)]
    pub fn extremes_from_read_back(&self) -> Result<(f64, f64)> {
        if self.tank.n == 0 {
            return Ok((0.0, 0.0));
        }
        let d = self.p.dim;
        let v = self.gpu.read_reals(self.precision, &self.tank.vel, &self.staging, d * self.tank.n)?;
        let vmax = v.chunks_exact(d).map(|u| u.iter().map(|c| c * c).sum::<f64>()).fold(0.0, f64::max).sqrt();
        let at = 2 * self.tank.n as u64 * self.precision.bytes();
        let a2 = self.gpu.read_reals_at(self.precision, &self.books, at, &self.staging, self.tank.n)?;
        Ok((vmax, a2.into_iter().fold(0.0, f64::max)))
    }

    /// The dissipated books alone (viscous, collisions), J: the per-particle accumulators read
    /// back and summed in index order, as `books` sums them (a checkpoint needs no densities).
    pub fn dissipated(&self) -> Result<(f64, f64)> {
        if self.tank.n == 0 {
            return Ok((0.0, 0.0));
        }
        let per = self.gpu.read_reals(self.precision, &self.books, &self.staging, 2 * self.tank.n)?;
        let (viscous, walls) = per.split_at(self.tank.n);
        Ok((viscous.iter().sum(), walls.iter().sum()))
    }

    /// The energy books now (J; see `SphBooks`), as the CPU's `ParticleSystem::energy` defines
    /// them: the state functions from a read-back of the state (densities summed now), each sum
    /// in f64 in the caller's particle order; the viscous and wall books accumulated on the device
    /// since `new`, per particle, summed here in the same order. Deterministic: the same bits
    /// for the same run on one adapter.
    pub fn books(&self) -> Result<SphBooks> {
        if self.tank.n == 0 {
            return Ok(SphBooks::default());
        }
        let (x, v, rho) = self.read()?;
        let per = self.gpu.read_reals(self.precision, &self.books, &self.staging, 2 * self.tank.n)?;
        let (p, d, m) = (&self.p, self.p.dim, self.p.mass);
        let (mut kinetic, mut gravity, mut internal) = (0.0, 0.0, 0.0);
        for i in 0..self.tank.n {
            let (xi, vi) = (&x[d * i..d * i + d], &v[d * i..d * i + d]);
            kinetic += m * vi.iter().map(|u| u * u).sum::<f64>();
            gravity -= m * (0..d).map(|a| p.gravity[a] * xi[a]).sum::<f64>();
            internal += m * p.internal_energy(rho[i]);
        }
        let (viscous, walls) = per.split_at(self.tank.n);
        Ok(SphBooks {
            kinetic: 0.5 * kinetic,
            internal,
            gravity,
            viscous: viscous.iter().sum(),
            collisions: walls.iter().sum(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_pinned_and_valid() {
        let p = SphParams::default();
        assert_eq!((p.dim, p.h, p.mass, p.rho0, p.c0, p.gamma, p.alpha), (2, 0.013, 0.1, 1000.0, 20.0, 7, 0.1));
        assert!(p.clamp && p.kernel == Kernel::CubicSpline && p.gravity == [0.0, -9.81, 0.0]);
        assert_eq!((p.lower, p.upper, p.restitution, p.friction), ([0.0; 3], [1.0; 3], 0.0, 0.0));
        p.validate().unwrap();
        assert_eq!(p.cells().unwrap(), [39, 39, 1]);
        assert_eq!(Kernel::by_name("wendland_c2").unwrap(), Kernel::WendlandC2);
        assert!(Kernel::by_name("gauss").unwrap_err().to_string().contains("cubic_spline, wendland_c2"));
    }
}
