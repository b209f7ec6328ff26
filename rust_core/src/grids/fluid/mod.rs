//! An incompressible fluid on a 2D staggered (MAC) grid: Stam's "stable fluids" (J. Stam,
//! "Stable Fluids", SIGGRAPH 1999) with the smoke model of Fedkiw, Stam & Jensen, "Visual
//! simulation of smoke", SIGGRAPH 2001 (buoyancy eq. 8, vorticity confinement eq. 9–11).
//! Density-free units: ρ_fluid = 1, so pressure is in m²/s² and energies in m⁴/s² per unit
//! depth and density.
//!
//! Layout (`nx × ny` cells of size dx, domain [0, nx·dx] × [0, ny·dx]):
//! - u on the x-faces, at (i·dx, (j+½)dx), i in 0..=nx, j in 0..ny; stored with a ghost row
//!   below and above: index `i + (nx+1)·(j+1)`.
//! - v on the y-faces, at ((i+½)dx, j·dx); stored with a ghost column left and right: index
//!   `(i+1) + (nx+2)·j`.
//! - density, temperature at the cell centres, `i + nx·j` (as in [`crate::grids`]).
//!
//! A step of dt:
//! 1. smoke density and temperature are advected by the (divergence-free) velocity;
//! 2. sources blend density, temperature and velocity towards their values (weight w per cell);
//! 3. forces: buoyancy f_y = −α·ρ_smoke + β·(T − T_amb) and vorticity confinement
//!    f = ε·dx·(N × ω), N = ∇|ω|/|∇|ω||;
//! 4. the velocity is advected by itself (with the incremental projection, the default: the
//!    field advected is u − ½dt·∇p, p the last step's pressure, while the paths are traced
//!    through u; see [`Projection`]);
//! 5. viscosity (ν > 0): backward Euler (I − ν·dt·∇²)u = u*, per component, by CG with a
//!    diagonal preconditioner (unconditionally stable); a wall that holds the tangential
//!    velocity (no slip, the inflow's v = 0, an obstacle's face) gives u* the value
//!    (1 − share)·dt·∂p/∂τ that the projection then takes back (Kim & Moin 1985;
//!    `slip_scale`), so the wall holds after it;
//! 6. projection: ∇²p = ∇·u*/dt with Neumann conditions at walls and obstacles, by CG
//!    preconditioned with one multigrid V-cycle (MGPCG, [`super::poisson`]), warm-started
//!    from the last pressure; u −= dt·∇p (incremental: the solve is for π = p_new − ½p, started
//!    at ½p, and p_new = ½p + π is kept);
//! 7. tracers are moved by RK2 through the new velocity.
//!
//! Advection is semi-Lagrangian (RK2 backtrace, bilinear interpolation) or MacCormack (Selle,
//! Fedkiw, Kim, Liu & Rossignac, "An unconditionally stable MacCormack method", J. Sci.
//! Comput. 35 (2008)), clamped to the min/max of the interpolation neighbourhood.
//!
//! Boundaries: the walls are solid (normal velocity 0); `no_slip` sets the tangential velocity
//! on them to 0 (ghost = −inside) instead of free slip (ghost = inside), and `lid` moves the
//! top wall at speed U (ghost = 2U − inside). Obstacles are solid cells: the faces touching
//! them carry no velocity and smoke does not enter them; their walls are no-slip, at the
//! cells' edges (the viscous solve's ghost −inside, as the domain's walls).
//!
//! Open boundaries (`inflow` = U): the x− face is an inflow, u = U and v = 0 on it (v's ghost
//! = −inside), held through every stage (its faces are not unknowns of the viscous or pressure
//! solves; the viscous solve of the next face sees U as a Dirichlet value); the x+ face is an
//! outflow where the pressure is 0 one half-cell beyond the last face (Dirichlet: the
//! pressure stencil's east side counts 1, so no pin is needed and the net flux through the
//! box is free), its normal velocity is advected (from upstream: a convective outflow) and
//! projected like an interior face, and v and u have zero normal gradient there (ghost =
//! inside; Neumann in the viscous solve); smoke leaves with zero gradient (the backtrace is
//! clamped to the domain). The y walls are unchanged.
//!
//! Energy books: kinetic energy is ½Σ|u|²·dx² over the faces (ρ = 1). The numerical scheme
//! does not conserve it and is not meant to, so each stage's measured change is booked as what
//! it dissipated (energy before the stage minus after; negative for work done, e.g. by
//! buoyancy, sources or the lid through the viscous stage): "forces", "sources", "advection",
//! "viscosity", "projection". The books balance by construction; what they tell is where the
//! energy went (with the incremental projection, "advection" includes the work of the half
//! pressure gradient applied before it, which "projection" then largely returns). Smoke: semi-Lagrangian advection does not conserve the amount either; its
//! measured change is booked as "smoke_advection_change", so amount = injected + that change.
//!
//! Tracers start at hashed points of the first source (of the fluid if there is none) and
//! are re-seeded there, at a point hashed from their index and the step count, when they
//! leave the domain or enter a solid. The buffers a step works in are allocated (fallibly) by
//! `StableFluid::new`; a step itself allocates only per-row partial sums (one value per row),
//! and a checkpoint reuses the buffers of the last one (`System::recycle`).
//!
//! Determinism: every pass runs over rows (or fixed chunks of tracers) and every reduction adds
//! per-row partials in row order, so runs are bit-identical for any thread count.
//!
//! Layout, one stage a file: this file holds the configuration, the state and the `System`
//! impl; `stages` the step's stages; `lanes` the SIMD lanes of the advection; `tests` the tests.
mod lanes;

use super::poisson::{Pcg, Solve, Stencil};
use super::{rows_sum, sum_rows};
use crate::alloc::{count, Need};
use crate::error::{invalid, Failure, Result};
use crate::par;
use crate::systems::{array, Arrays, EnergyReport, Halt, Snapshot, System};
use crate::vector::Real;
use std::sync::atomic::{AtomicBool, Ordering};
mod stages;

/// `NAMES`, `by_name` (an unknown name is an error naming `arg`) and `name` for a unit enum
/// whose variants the user picks by name.
macro_rules! named {
    ($ty:ident, $arg:literal, $($v:ident => $n:literal),+) => {
        impl $ty {
            pub const NAMES: &'static [&'static str] = &[$($n),+];
            pub fn by_name(s: &str) -> Result<Self> {
                match s {
                    $($n => Ok(Self::$v),)+
                    _ => Err(invalid($arg, format!("unknown scheme {s:?}; valid names: {}", Self::NAMES.join(", ")))),
                }
            }
            pub fn name(self) -> &'static str {
                match self {
                    $(Self::$v => $n,)+
                }
            }
        }
    };
}

/// How quantities are carried by the flow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Advection {
    /// RK2 backtrace, bilinear interpolation (first order, diffusive, unconditionally stable).
    SemiLagrangian,
    /// Forward and backward semi-Lagrangian steps correct the error, clamped to the
    /// neighbourhood's min/max (second order where smooth).
    MacCormack,
}

named!(Advection, "advection", SemiLagrangian => "semi_lagrangian", MacCormack => "maccormack");

/// How the pressure enters a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Projection {
    /// Chorin's projection (A. J. Chorin, "Numerical solution of the Navier–Stokes equations",
    /// Math. Comp. 22 (1968) 745–762): the velocity is advected without the pressure, which
    /// the projection then adds. The gradient part the projection removes is O(dt) a step, so
    /// the kinetic energy falls by O(dt²) a step more than it should: first order in time.
    Chorin,
    /// Incremental pressure correction (J. van Kan, "A second-order accurate pressure-correction
    /// scheme for viscous incompressible flow", SIAM J. Sci. Stat. Comput. 7 (1986) 870–891;
    /// the family reviewed by Guermond, Minev & Shen, Comput. Methods Appl. Mech. Engrg. 195
    /// (2006) 6011–6045), in semi-Lagrangian form: the last step's pressure p acts along the
    /// characteristic by the trapezoid rule, half (−½dt·∇p) at the departure point (applied
    /// to the field before it is advected) and half at the arrival point (left to the
    /// projection, which then solves for π = p_new − ½p and keeps p_new = ½p + π). The
    /// gradient the projection removes is then O(dt²): second order in time where the flow
    /// is smooth; the first step (p = 0) is Chorin's.
    Incremental,
}

named!(Projection, "projection", Chorin => "chorin", Incremental => "incremental");

/// An inflow: each step, each of its cells c with weight w (0..=1) has density, temperature and
/// the velocity of its four faces blended towards the source's values: q += w·(q_source − q).
#[derive(Clone, Debug, PartialEq)]
pub struct Source {
    /// (cell index i + nx·j, weight in [0, 1]).
    pub cells: Vec<(usize, Real)>,
    /// Smoke density (dimensionless concentration).
    pub density: Real,
    /// Temperature (K, or any unit consistent with `ambient_temperature` and β).
    pub temperature: Real,
    /// Inflow velocity [vx, vy] (m/s).
    pub velocity: [Real; 2],
}

impl Source {
    /// Cells i0..i1 × j0..j1 (weight 1) of a grid `nx` cells wide.
    pub fn rectangle(nx: usize, i: [usize; 2], j: [usize; 2]) -> Vec<(usize, Real)> {
        (j[0]..j[1]).flat_map(|j| (i[0]..i[1]).map(move |i| (i + nx * j, 1.0))).collect()
    }
    /// Cells whose centre lies within `radius` (m) of `centre` (m), weight 1.
    pub fn circle(shape: [usize; 2], dx: Real, centre: [Real; 2], radius: Real) -> Vec<(usize, Real)> {
        let mut out = Vec::new();
        for j in 0..shape[1] {
            for i in 0..shape[0] {
                let (x, y) = ((i as Real + 0.5) * dx - centre[0], (j as Real + 0.5) * dx - centre[1]);
                if x * x + y * y <= radius * radius {
                    out.push((i + shape[0] * j, 1.0));
                }
            }
        }
        out
    }
    /// The cells of a weight array (one weight per cell; zeros are left out).
    pub fn from_weights(weights: &[Real]) -> Vec<(usize, Real)> {
        weights.iter().enumerate().filter(|(_, w)| **w != 0.0).map(|(c, w)| (c, *w)).collect()
    }
}

/// Parameters of a [`StableFluid`]. Units: SI, ρ_fluid = 1.
#[derive(Clone, Debug, PartialEq)]
pub struct FluidConfig {
    /// The system's name in the world's books.
    pub name: String,
    /// Cells along x and y (each ≥ 3).
    pub shape: [usize; 2],
    /// Cell size (m).
    pub dx: Real,
    /// Kinematic viscosity ν (m²/s), ≥ 0; 0 skips the viscous stage.
    pub viscosity: Real,
    /// Buoyancy α: downward acceleration per unit smoke density (m/s²).
    pub buoyancy_alpha: Real,
    /// Buoyancy β: upward acceleration per unit temperature excess (m/s² per K).
    pub buoyancy_beta: Real,
    /// T_ambient (K).
    pub ambient_temperature: Real,
    /// Vorticity confinement strength ε (dimensionless), ≥ 0.
    pub vorticity: Real,
    pub advection: Advection,
    /// How the pressure enters a step (see [`Projection`]).
    pub projection: Projection,
    /// Relative residual |b − Ap|/|b| at which the pressure (and viscosity) solves stop.
    pub tolerance: Real,
    /// Most CG iterations per solve.
    pub max_iterations: usize,
    /// Walls are no-slip (tangential velocity 0) instead of free-slip.
    pub no_slip: bool,
    /// Tangential speed (m/s, +x) of the top wall (a lid-driven cavity); needs `no_slip`.
    pub lid: Option<Real>,
    /// Speed U (m/s, +x, > 0) of a uniform inflow through the x− face; the x+ face is then an
    /// open outflow (see the module docs). `None`: all four walls are solid.
    pub inflow: Option<Real>,
    /// Solid cells (nx·ny entries, or empty for none).
    pub obstacles: Vec<bool>,
    pub sources: Vec<Source>,
    /// Passive tracers carried by the flow (re-seeded in the first source when they leave).
    pub n_tracers: usize,
    /// Advection CFL number: `auto_dt` = cfl·dx / max|u|.
    pub cfl: Real,
}

impl Default for FluidConfig {
    fn default() -> Self {
        Self {
            name: "fluid".to_string(),
            shape: [64, 64],
            dx: 1.0 / 64.0,
            viscosity: 0.0,
            buoyancy_alpha: 0.0,
            buoyancy_beta: 0.0,
            ambient_temperature: 0.0,
            vorticity: 0.0,
            advection: Advection::SemiLagrangian,
            projection: Projection::Incremental,
            tolerance: 1e-10,
            max_iterations: 500,
            no_slip: false,
            lid: None,
            inflow: None,
            obstacles: Vec::new(),
            sources: Vec::new(),
            n_tracers: 0,
            cfl: 1.0,
        }
    }
}

fn finite(arg: &str, x: Real) -> Result<()> {
    if x.is_finite() {
        Ok(())
    } else {
        Err(invalid(arg, format!("{x} must be finite")))
    }
}

impl FluidConfig {
    pub fn validate(&self) -> Result<()> {
        let [nx, ny] = self.shape;
        if nx < 3 || ny < 3 {
            return Err(invalid("shape", format!("every cell count must be >= 3, got {:?}", self.shape)));
        }
        if nx >= (1 << 30) || ny >= (1 << 30) || nx.checked_mul(ny).is_none_or(|c| c > (1usize << 34)) {
            return Err(invalid("shape", format!("{:?} has too many cells", self.shape)));
        }
        if !(self.dx.is_finite() && self.dx > 0.0) {
            return Err(invalid("spacing", format!("{} must be finite and > 0 (m)", self.dx)));
        }
        if !(self.viscosity.is_finite() && self.viscosity >= 0.0) {
            return Err(invalid("nu", format!("{} must be finite and >= 0 (m^2/s)", self.viscosity)));
        }
        finite("buoyancy_alpha", self.buoyancy_alpha)?;
        finite("buoyancy_beta", self.buoyancy_beta)?;
        finite("ambient_temperature", self.ambient_temperature)?;
        if !(self.vorticity.is_finite() && self.vorticity >= 0.0) {
            return Err(invalid("vorticity", format!("{} must be finite and >= 0", self.vorticity)));
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(invalid("tolerance", format!("{} must be in (0, 1) (relative residual)", self.tolerance)));
        }
        if self.max_iterations == 0 {
            return Err(invalid("max_iterations", "must be >= 1"));
        }
        if let Some(u) = self.lid {
            finite("lid", u)?;
            if !self.no_slip {
                return Err(invalid("lid", "a moving lid needs no_slip = true (free-slip walls do not feel it)"));
            }
        }
        if let Some(u) = self.inflow {
            if !(u.is_finite() && u > 0.0) {
                return Err(invalid("inflow", format!("{u} must be finite and > 0 (m/s, +x)")));
            }
        }
        if !self.obstacles.is_empty() && self.obstacles.len() != nx * ny {
            return Err(invalid(
                "obstacles",
                format!("has {} cells, expected nx*ny = {} (or none)", self.obstacles.len(), nx * ny),
            ));
        }
        if !self.obstacles.is_empty() && self.obstacles.iter().all(|&s| s) {
            return Err(invalid("obstacles", "every cell is solid"));
        }
        for (k, s) in self.sources.iter().enumerate() {
            let arg = format!("sources[{k}]");
            for &(c, w) in &s.cells {
                if c >= nx * ny {
                    return Err(invalid(&arg, format!("cell {c} is outside the grid of {} cells", nx * ny)));
                }
                if !(0.0..=1.0).contains(&w) {
                    return Err(invalid(&arg, format!("weight {w} of cell {c} must be in [0, 1]")));
                }
            }
            for x in [s.density, s.temperature, s.velocity[0], s.velocity[1]] {
                finite(&arg, x)?;
            }
        }
        if !(self.cfl.is_finite() && self.cfl > 0.0) {
            return Err(invalid("cfl", format!("{} must be finite and > 0", self.cfl)));
        }
        if self.n_tracers > (1 << 32) {
            return Err(invalid("n_tracers", format!("{} is too many", self.n_tracers)));
        }
        Ok(())
    }
}

/// What `step` changes besides the fields.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Books {
    /// Σ of what sources added to the smoke amount (Σ Δρ·dA).
    injected: Real,
    /// Measured change of the smoke amount by advection (and by obstacles refusing smoke).
    smoke_advection: Real,
    /// Energy lost (negative: gained) by stage: forces, sources, advection, viscosity, projection.
    losses: [Real; 5],
    pressure: Solve,
    viscosity_iterations: usize,
}

const STAGES: [&str; 5] = ["forces", "sources", "advection", "viscosity", "projection"];

/// Everything `step` changes: what a snapshot copies and `save` writes.
#[derive(Clone, Debug, PartialEq)]
struct State {
    u: Vec<Real>,
    v: Vec<Real>,
    density: Vec<Real>,
    temperature: Vec<Real>,
    /// Pressure (m²/s², ρ = 1), padded like the solver's arrays: the warm start.
    pressure: Vec<Real>,
    tracers: Vec<Real>,
    steps: u64,
    books: Books,
}

/// How array index (a, b) maps to space: ((a + ox)·dx, (b + oy)·dx), `w × h` values.
#[derive(Clone, Copy, Debug)]
struct Lay {
    w: usize,
    h: usize,
    ox: Real,
    oy: Real,
}

/// A grid index as a real. Through u32: u64 → f64 has no single x86 instruction (grid sides
/// are far below 2³²; `validate` says so).
#[inline(always)]
fn re(n: usize) -> Real {
    n as u32 as Real
}

impl Lay {
    /// Bilinear interpolation at (x, y) (m, inside the domain), with the four values' min and max.
    #[inline(always)]
    fn sample(&self, a: &[Real], x: Real, y: Real, inv_dx: Real) -> (Real, Real, Real) {
        // Conversions through i32 (one instruction each way); sides < 2³¹.
        let (wm, hm) = (self.w as i32 - 1, self.h as i32 - 1);
        let fx = (x * inv_dx - self.ox).clamp(0.0, wm as Real);
        let fy = (y * inv_dx - self.oy).clamp(0.0, hm as Real);
        let i = (fx as i32).min(wm - 1);
        let j = (fy as i32).min(hm - 1);
        let (tx, ty) = (fx - i as Real, fy - j as Real);
        let k = i as usize + self.w * j as usize;
        // One bounds check for the four values (the slice's length proves the other three).
        let q = &a[k..k + self.w + 2];
        let (a00, a10, a01, a11) = (q[0], q[1], q[self.w], q[self.w + 1]);
        let v = (1.0 - ty) * ((1.0 - tx) * a00 + tx * a10) + ty * ((1.0 - tx) * a01 + tx * a11);
        // Plain compares, not IEEE min/max: the lanes make the same choice between ±0 at every
        // level (`lanes::bounds`).
        let (min, max) = (|a: Real, b: Real| if a < b { a } else { b }, |a: Real, b: Real| if a > b { a } else { b });
        (v, min(min(a00, a10), min(a01, a11)), max(max(a00, a10), max(a01, a11)))
    }
}

/// The velocity field for tracing paths.
#[derive(Clone, Copy)]
struct Vel<'a> {
    u: &'a [Real],
    v: &'a [Real],
    lu: Lay,
    lv: Lay,
    inv_dx: Real,
    xmax: Real,
    ymax: Real,
}

impl Vel<'_> {
    #[inline(always)]
    fn clamp(&self, x: Real, y: Real) -> (Real, Real) {
        (x.clamp(0.0, self.xmax), y.clamp(0.0, self.ymax))
    }
    #[inline(always)]
    fn at(&self, x: Real, y: Real) -> (Real, Real) {
        (self.lu.sample(self.u, x, y, self.inv_dx).0, self.lv.sample(self.v, x, y, self.inv_dx).0)
    }
}

/// What the nodes of a layout are.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Node {
    Cell,
    U,
    V,
}

/// Which nodes of a layout are advected: columns a0..a1 of rows b0..b1; `mask` (1/0, same
/// layout) selects the free ones, the others get `fill`.
#[derive(Clone, Copy)]
struct Active<'a> {
    lay: Lay,
    kind: Node,
    a0: usize,
    a1: usize,
    b0: usize,
    b1: usize,
    mask: &'a [Real],
    fill: Real,
}

/// out = src carried back along the flow: semi-Lagrangian (`hat` = None) or MacCormack (`hat`
/// = the semi-Lagrangian result with ghosts filled: out = hat + ½(src − back-and-forth),
/// clamped to the min/max of the values of `src` the backtrace interpolated between). Rows
/// b0..b1, columns a0..a1 of `out` are written; in lanes, see [`lanes`].
fn advect_faces(vel: &Vel, dx: Real, act: &Active, src: &[Real], hat: Option<&[Real]>, dt: Real, out: &mut [Real]) {
    let lay = act.lay;
    each_row(&mut out[..lay.w * lay.h], lay.w, |b, row| {
        if b >= act.b0 && b < act.b1 {
            lanes::run(lanes::FaceRow { vel, dx, act, src, hat, dt, b, row });
        }
    });
}

/// `f(b, row)` for every row of `out` (rows of `w` values), in parallel.
fn each_row(out: &mut [Real], w: usize, f: impl Fn(usize, &mut [Real]) + Sync + Send) {
    // Zero-sized partials: no allocation.
    let mut none = vec![(); out.len() / w];
    super::rows_each(out, w, &mut none, f);
}

/// `each_row` over the matching rows of two arrays.
fn each_row2(a: &mut [Real], b: &mut [Real], w: usize, f: impl Fn(usize, &mut [Real], &mut [Real]) + Sync + Send) {
    let mut none = vec![(); a.len() / w];
    super::rows2_each(a, b, w, &mut none, f);
}

/// What the ghost fills need to know of the boundaries.
#[derive(Clone, Copy)]
struct Bounds<'a> {
    no_slip: bool,
    lid: Real,
    /// The inflow face's u, one per row (U, 0 beside a solid cell); None: a closed box.
    inflow: Option<&'a [Real]>,
}

impl<'a> Bounds<'a> {
    fn of(cfg: &FluidConfig, inflow_u: &'a [Real]) -> Self {
        Bounds { no_slip: cfg.no_slip, lid: cfg.lid.unwrap_or(0.0), inflow: (!inflow_u.is_empty()).then_some(inflow_u) }
    }
}

/// The inflow column of u (held at its values), then the ghost rows of u (below y = 0, above
/// y = ny·dx): free slip copies the row inside, no slip reflects it oddly about the wall's
/// speed (0, or the lid's).
fn fill_u_ghosts(u: &mut [Real], nx: usize, ny: usize, b: Bounds) {
    let (w, no_slip, lid) = (nx + 1, b.no_slip, b.lid);
    if let Some(col) = b.inflow {
        for (j, &uj) in col.iter().enumerate().take(ny) {
            u[w * (j + 1)] = uj;
        }
    }
    for i in 0..w {
        let (bottom, top) = (u[i + w], u[i + w * ny]);
        if no_slip {
            u[i] = -bottom;
            u[i + w * (ny + 1)] = 2.0 * lid - top;
        } else {
            u[i] = bottom;
            u[i + w * (ny + 1)] = top;
        }
    }
}

/// Ghost columns of v (left of x = 0, right of x = nx·dx): a wall's rule, or v = 0 on an
/// inflow face (ghost = −inside) and zero gradient on an outflow face (ghost = inside).
fn fill_v_ghosts(v: &mut [Real], nx: usize, ny: usize, b: Bounds) {
    let w = nx + 2;
    let f = if b.no_slip { -1.0 } else { 1.0 };
    let (fw, fe) = if b.inflow.is_some() { (-1.0, 1.0) } else { (f, f) };
    for j in 0..=ny {
        v[w * j] = fw * v[1 + w * j];
        v[nx + 1 + w * j] = fe * v[nx + w * j];
    }
}

/// splitmix64: a stateless hash for tracer re-seeding.
fn hash(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn unit(h: u64) -> Real {
    (h >> 11) as Real / (1u64 << 53) as Real
}

/// Stam's stable fluids on a MAC grid, with smoke, obstacles, sources and tracers (see the
/// module docs).
pub struct StableFluid {
    cfg: FluidConfig,
    nx: usize,
    ny: usize,
    dx: Real,
    s: State,
    // Fixed: open faces (1/0) in the u and v layouts, fluid cells (1/0).
    u_open: Vec<Real>,
    v_open: Vec<Real>,
    // With viscosity: the no-slip walls along each face (0, 1, 2), in the u and v layouts.
    u_walls: Vec<Real>,
    v_walls: Vec<Real>,
    fluid: Vec<Real>,
    /// The inflow face's u per row (U beside fluid, 0 beside solid); empty for a closed box.
    inflow_u: Vec<Real>,
    // Scratch.
    u2: Vec<Real>,
    v2: Vec<Real>,
    hat: Vec<Real>,
    c2: Vec<Real>,
    wz: Vec<Real>,
    fx: Vec<Real>,
    fy: Vec<Real>,
    q: Vec<Real>,
    rhs: Vec<Real>,
    pressure: Pcg,
    visc: Option<[Pcg; 2]>,
    vx: [Vec<Real>; 2],
    vb: [Vec<Real>; 2],
    visc_scale: Real,
    /// Buffers of checkpoints that were not needed (`System::recycle`).
    spare: super::Spare,
}

impl StableFluid {
    pub fn new(config: FluidConfig) -> Result<Self> {
        config.validate()?;
        let [nx, ny] = config.shape;
        let dx = config.dx;
        let cells = nx * ny;
        let (nu_len, nv_len, np) = ((nx + 1) * (ny + 2), (nx + 2) * (ny + 1), (nx + 2) * (ny + 2));
        let need = Need::new(
            "fluid",
            Need::bytes_of::<Real>(40 * np + 2 * config.n_tracers),
            format!("a fluid of {} cells", count(cells as u128)),
        );
        need.check()?;
        let solid = |i: usize, j: usize| !config.obstacles.is_empty() && config.obstacles[i + nx * j];
        let mut fluid = need.filled(cells, 0.0)?;
        for j in 0..ny {
            for i in 0..nx {
                fluid[i + nx * j] = if solid(i, j) { 0.0 } else { 1.0 };
            }
        }
        let outflow = config.inflow.is_some();
        // The x+ face of an open box is an unknown like an interior face; the x− face is held.
        let u_open_at = |i: usize, j: usize| i > 0 && !solid(i - 1, j) && if i < nx { !solid(i, j) } else { outflow };
        let v_open_at = |i: usize, j: usize| j > 0 && j < ny && !solid(i, j - 1) && !solid(i, j);
        let mut u_open = need.filled(nu_len, 0.0)?;
        let mut v_open = need.filled(nv_len, 0.0)?;
        for j in 0..ny {
            for i in 0..=nx {
                u_open[i + (nx + 1) * (j + 1)] = if u_open_at(i, j) { 1.0 } else { 0.0 };
            }
        }
        for j in 0..=ny {
            for i in 0..nx {
                v_open[(i + 1) + (nx + 2) * j] = if v_open_at(i, j) { 1.0 } else { 0.0 };
            }
        }
        // Sides [east, west, north, south]. Pressure: Neumann at walls, Dirichlet p = 0 beyond
        // an outflow. Viscosity: the wall rule; zero gradient at an outflow; v = 0 on an inflow.
        let mut st =
            Stencil::build(nx, ny, &|i, j| !solid(i, j), [if outflow { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0], false, 0.0)?;
        st.pin()?;
        let pressure = Pcg::new(st, true)?;
        let wall = if config.no_slip { 2.0 } else { 0.0 };
        let (east, west) = if outflow { (0.0, 2.0) } else { (wall, wall) };
        // The no-slip walls along each open face, 0–2 (`u_walls`, `v_walls`): the domain's walls
        // that hold the tangential velocity (the `wall` sides: no slip; v = 0 on the inflow) and
        // the faces of obstacles. An obstacle's tangential neighbour face that lies inside it
        // (both its cells solid) was a Dirichlet 0 one cell away, the wall taken half a cell
        // into the solid; it is now a ghost −u like the domain's walls (count 2, the wall at the
        // cell edge), and both get the slip term of `diffuse`.
        // (An outflow face beside a solid cell ends that obstacle at the boundary: inside it.)
        let inside_u = |i: usize, j: usize| i > 0 && solid(i - 1, j) && (i == nx || solid(i, j));
        let inside_v = |i: usize, j: usize| j > 0 && j < ny && solid(i, j - 1) && solid(i, j);
        let (mut u_walls, mut v_walls) = (Vec::new(), Vec::new());
        let visc = if config.viscosity > 0.0 {
            let mut su = Stencil::build(nx + 1, ny, &u_open_at, [east, wall, wall, wall], true, 1.0)?;
            let mut sv = Stencil::build(nx, ny + 1, &v_open_at, [east, west, wall, wall], true, 1.0)?;
            u_walls = need.filled(nu_len, 0.0)?;
            v_walls = need.filled(nv_len, 0.0)?;
            let side = |k: Real| if k == 2.0 { 1.0 } else { 0.0 };
            for j in 0..ny {
                for i in 0..=nx {
                    if u_open_at(i, j) {
                        let inside = (j + 1 < ny && inside_u(i, j + 1)) as u8 + (j > 0 && inside_u(i, j - 1)) as u8;
                        su.add_held(i, j, Real::from(inside));
                        let domain = if j + 1 == ny { side(wall) } else { 0.0 } + if j == 0 { side(wall) } else { 0.0 };
                        u_walls[i + (nx + 1) * (j + 1)] = domain + Real::from(inside);
                    }
                }
            }
            for j in 0..=ny {
                for i in 0..nx {
                    if v_open_at(i, j) {
                        let inside = (i + 1 < nx && inside_v(i + 1, j)) as u8 + (i > 0 && inside_v(i - 1, j)) as u8;
                        sv.add_held(i, j, Real::from(inside));
                        let domain = if i + 1 == nx { side(east) } else { 0.0 } + if i == 0 { side(west) } else { 0.0 };
                        v_walls[(i + 1) + (nx + 2) * j] = domain + Real::from(inside);
                    }
                }
            }
            su.set_scale(1.0);
            sv.set_scale(1.0);
            Some([Pcg::new(su, false)?, Pcg::new(sv, false)?])
        } else {
            None
        };
        let (lu, lv) = ((nx + 3) * (ny + 2), (nx + 2) * (ny + 3));
        let has_visc = visc.is_some();
        let vlen = |n: usize| if has_visc { n } else { 0 };
        let amb = config.ambient_temperature;
        let inflow_u = match config.inflow {
            Some(speed) => (0..ny).map(|j| if solid(0, j) { 0.0 } else { speed }).collect(),
            None => Vec::new(),
        };
        let mut me = Self {
            nx,
            ny,
            dx,
            s: State {
                u: need.filled(nu_len, 0.0)?,
                v: need.filled(nv_len, 0.0)?,
                density: need.filled(cells, 0.0)?,
                temperature: need.filled(cells, amb)?,
                pressure: need.filled(np, 0.0)?,
                tracers: need.filled(2 * config.n_tracers, 0.0)?,
                steps: 0,
                books: Books::default(),
            },
            u_open,
            v_open,
            u_walls,
            v_walls,
            fluid,
            inflow_u,
            u2: need.filled(nu_len, 0.0)?,
            v2: need.filled(nv_len, 0.0)?,
            hat: need.filled(nu_len.max(nv_len), 0.0)?,
            c2: need.filled(cells, 0.0)?,
            wz: need.filled(cells, 0.0)?,
            fx: need.filled(cells, 0.0)?,
            fy: need.filled(cells, 0.0)?,
            q: need.filled(np, 0.0)?,
            rhs: need.filled(np, 0.0)?,
            pressure,
            visc,
            vx: [need.filled(vlen(lu), 0.0)?, need.filled(vlen(lv), 0.0)?],
            vb: [need.filled(vlen(lu), 0.0)?, need.filled(vlen(lv), 0.0)?],
            visc_scale: Real::NAN,
            spare: super::Spare::default(),
            cfg: config,
        };
        for k in 0..me.cfg.n_tracers {
            let (x, y) = me.seed(k, u64::MAX, false);
            me.s.tracers[2 * k] = x;
            me.s.tracers[2 * k + 1] = y;
        }
        Ok(me)
    }

    pub fn config(&self) -> &FluidConfig {
        &self.cfg
    }
    pub fn shape(&self) -> [usize; 2] {
        [self.nx, self.ny]
    }
    /// Steps taken (the tracer re-seeding hash reads it).
    pub fn steps(&self) -> u64 {
        self.s.steps
    }
    /// For the device path: the step count (the device's steps counted, or a checkpoint's).
    #[cfg(feature = "gpu")]
    pub(crate) fn set_steps(&mut self, steps: u64) {
        self.s.steps = steps;
    }
    /// The last pressure solve.
    pub fn pressure_solve(&self) -> Solve {
        self.s.books.pressure
    }

    /// For the device path (`systems::device::DeviceFluid`): the configuration, the open masks
    /// of u and v faces and the fluid cells (1/0), the inflow column, the no-slip walls along
    /// u and v faces (empty without viscosity), and the pressure and viscous solvers (their
    /// stencils).
    #[allow(clippy::type_complexity)]
    #[cfg(feature = "gpu")]
    pub(crate) fn parts(&self) -> (&FluidConfig, [&[Real]; 6], &Pcg, Option<&[Pcg; 2]>) {
        let masks = [&self.u_open[..], &self.v_open, &self.fluid, &self.inflow_u, &self.u_walls, &self.v_walls];
        (&self.cfg, masks, &self.pressure, self.visc.as_ref())
    }

    /// For the device path: u, v, density, temperature, the padded pressure and the tracers.
    #[cfg(feature = "gpu")]
    pub(crate) fn state_arrays(&mut self) -> [&mut Vec<Real>; 6] {
        let s = &mut self.s;
        [&mut s.u, &mut s.v, &mut s.density, &mut s.temperature, &mut s.pressure, &mut s.tracers]
    }

    /// For the device path: the injected smoke, the smoke advection's change and the stages'
    /// losses; the last pressure solve; the viscous iterations of the last step.
    #[cfg(feature = "gpu")]
    pub(crate) fn book_values(&self) -> ([Real; 7], Solve, usize) {
        let b = &self.s.books;
        let l = b.losses;
        ([b.injected, b.smoke_advection, l[0], l[1], l[2], l[3], l[4]], b.pressure, b.viscosity_iterations)
    }

    /// The device path's books made the host's.
    #[cfg(feature = "gpu")]
    pub(crate) fn set_book_values(&mut self, v: [Real; 7], pressure: Solve, viscosity_iterations: usize) {
        let b = &mut self.s.books;
        b.injected = v[0];
        b.smoke_advection = v[1];
        b.losses.copy_from_slice(&v[2..]);
        b.pressure = pressure;
        b.viscosity_iterations = viscosity_iterations;
    }

    /// `auto_dt` for a largest face speed `umax` (m/s): cfl·dx / max(umax, the drive speed).
    /// The device path (`systems::device_fluid`) finds umax on the device.
    pub(crate) fn limit_at(&self, umax: Real) -> Option<Real> {
        let c = &self.cfg;
        let mut drive = c.lid.unwrap_or(0.0).abs().max(c.inflow.unwrap_or(0.0));
        for s in &c.sources {
            drive = drive.max(s.velocity[0].hypot(s.velocity[1]));
            let g = c.buoyancy_alpha.abs() * s.density.abs()
                + c.buoyancy_beta.abs() * (s.temperature - c.ambient_temperature).abs();
            drive = drive.max((g * self.ny as Real * self.dx).sqrt());
        }
        let speed = umax.max(drive);
        (speed > 0.0 && speed.is_finite()).then(|| c.cfl * self.dx / speed)
    }

    fn fill_ghosts_uv(&mut self) {
        let (nx, ny) = (self.nx, self.ny);
        let b = Bounds::of(&self.cfg, &self.inflow_u);
        fill_u_ghosts(&mut self.s.u, nx, ny, b);
        fill_v_ghosts(&mut self.s.v, nx, ny, b);
    }

    fn lays(&self) -> (Lay, Lay, Lay) {
        let (nx, ny) = (self.nx, self.ny);
        (
            Lay { w: nx + 1, h: ny + 2, ox: 0.0, oy: -0.5 },
            Lay { w: nx + 2, h: ny + 1, ox: -0.5, oy: 0.0 },
            Lay { w: nx, h: ny, ox: 0.5, oy: 0.5 },
        )
    }

    fn vel<'a>(&self, u: &'a [Real], v: &'a [Real]) -> Vel<'a> {
        let (lu, lv, _) = self.lays();
        Vel { u, v, lu, lv, inv_dx: 1.0 / self.dx, xmax: self.nx as Real * self.dx, ymax: self.ny as Real * self.dx }
    }

    /// Σu² over the u faces, Σv² over the v faces (ghosts left out).
    fn sums_sq(&self) -> (Real, Real) {
        let (nx, ny) = (self.nx, self.ny);
        let (u, v) = (&self.s.u, &self.s.v);
        let su = sum_rows(ny, u.len(), |j| {
            let r = &u[(nx + 1) * (j + 1)..(nx + 1) * (j + 2)];
            super::poisson::dot(r, r)
        });
        let sv = sum_rows(ny + 1, v.len(), |j| {
            let r = &v[(nx + 2) * j + 1..(nx + 2) * j + 1 + nx];
            super::poisson::dot(r, r)
        });
        (su, sv)
    }

    /// Kinetic energy ½Σ|u|²·dx² (ρ = 1).
    pub fn kinetic_energy(&self) -> Real {
        let (a, b) = self.sums_sq();
        0.5 * (a + b) * self.dx * self.dx
    }

    /// Σρ·dA.
    pub fn smoke_amount(&self) -> Real {
        let (nx, d) = (self.nx, &self.s.density);
        sum_rows(self.ny, d.len(), |j| d[nx * j..nx * (j + 1)].iter().sum::<Real>()) * self.dx * self.dx
    }

    /// The first non-finite value of the state, as a cell index.
    fn non_finite_cell(&self) -> Option<usize> {
        let (nx, ny) = (self.nx, self.ny);
        if let Some(k) = super::first_non_finite(&self.s.u) {
            let (i, j) = (k % (nx + 1), (k / (nx + 1)).saturating_sub(1).min(ny - 1));
            return Some(i.min(nx - 1) + nx * j);
        }
        if let Some(k) = super::first_non_finite(&self.s.v) {
            let (i, j) = ((k % (nx + 2)).saturating_sub(1).min(nx - 1), (k / (nx + 2)).min(ny - 1));
            return Some(i + nx * j);
        }
        super::first_non_finite(&self.s.density).or_else(|| super::first_non_finite(&self.s.temperature))
    }

    fn field_cells(&self, name: &str, need: &Need) -> Option<Result<Vec<Real>>> {
        let (nx, ny, dx) = (self.nx, self.ny, self.dx);
        let (u, v) = (&self.s.u, &self.s.v);
        let uc = |i: usize, j: usize| 0.5 * (u[i + (nx + 1) * (j + 1)] + u[i + 1 + (nx + 1) * (j + 1)]);
        let vc = |i: usize, j: usize| 0.5 * (v[(i + 1) + (nx + 2) * j] + v[(i + 1) + (nx + 2) * (j + 1)]);
        let cells = |f: &dyn Fn(usize, usize) -> Real| need.collect((0..nx * ny).map(|c| f(c % nx, c / nx)));
        Some(match name {
            "u" => cells(&uc),
            "v" => cells(&vc),
            "speed" => cells(&|i, j| uc(i, j).hypot(vc(i, j))),
            "vorticity" => cells(&|i, j| {
                let (i0, i1, j0, j1) =
                    (i.saturating_sub(1), (i + 1).min(nx - 1), j.saturating_sub(1), (j + 1).min(ny - 1));
                (vc(i1, j) - vc(i0, j)) / ((i1 - i0) as Real * dx) - (uc(i, j1) - uc(i, j0)) / ((j1 - j0) as Real * dx)
            }),
            "density" => need.copy(&self.s.density),
            "temperature" => need.copy(&self.s.temperature),
            "pressure" => cells(&|i, j| self.s.pressure[(i + 1) + (nx + 2) * (j + 1)]),
            "divergence" => cells(&|i, j| {
                self.fluid[i + nx * j]
                    * ((u[i + 1 + (nx + 1) * (j + 1)] - u[i + (nx + 1) * (j + 1)])
                        + (v[(i + 1) + (nx + 2) * (j + 1)] - v[(i + 1) + (nx + 2) * j]))
                    / dx
            }),
            "solid" => need.collect(self.fluid.iter().map(|f| 1.0 - f)),
            "tracers" => need.copy(&self.s.tracers),
            _ => return None,
        })
    }

    fn books_array(&self) -> Vec<Real> {
        let b = &self.s.books;
        let mut out = vec![b.injected, b.smoke_advection];
        out.extend_from_slice(&b.losses);
        out.extend([
            b.pressure.iterations as Real,
            b.pressure.residual,
            if b.pressure.converged { 1.0 } else { 0.0 },
            b.viscosity_iterations as Real,
        ]);
        out
    }
}

impl System for StableFluid {
    fn name(&self) -> &str {
        &self.cfg.name
    }
    fn is_empty(&self) -> bool {
        false
    }
    fn size(&self) -> usize {
        self.nx * self.ny
    }
    /// Everything is allocated (fallibly) by `new`.
    fn prepare(&mut self) -> Result<()> {
        Ok(())
    }
    fn step(&mut self, dt: Real, stop: &AtomicBool) -> std::result::Result<(), Halt> {
        if stop.load(Ordering::Relaxed) {
            return Err(Halt::Stopped);
        }
        self.fill_ghosts_uv();
        let mut ke = self.kinetic_energy();
        let book = |me: &mut Self, stage: usize, ke: &mut Real| {
            let now = me.kinetic_energy();
            me.s.books.losses[stage] += *ke - now;
            *ke = now;
        };
        self.advect_scalars(dt);
        self.apply_sources();
        book(self, 1, &mut ke);
        self.apply_forces(dt);
        book(self, 0, &mut ke);
        self.advect_velocity(dt);
        book(self, 2, &mut ke);
        if self.diffuse(dt, stop).is_none() {
            return Err(Halt::Stopped);
        }
        book(self, 3, &mut ke);
        if self.project_keeping(dt, self.departure_share(), stop).is_none() {
            return Err(Halt::Stopped);
        }
        book(self, 4, &mut ke);
        self.move_tracers(dt);
        self.s.steps += 1;
        let t = &self.s.temperature;
        let tsum = sum_rows(self.ny, t.len(), |j| t[self.nx * j..self.nx * (j + 1)].iter().sum::<Real>());
        if !(ke.is_finite() && self.smoke_amount().is_finite() && tsum.is_finite()) {
            let index = self.non_finite_cell().unwrap_or(0);
            return Err(Halt::Diverged { index, quantity: Failure::Cell });
        }
        Ok(())
    }
    /// cfl·dx / max(max|u|, drive speed), where the drive speed is the largest of the lid and inflow speeds,
    /// the sources' speeds and √(g'·H) (g' the largest buoyant acceleration the sources can
    /// cause, H the domain height), so that a still fluid that is being driven gets a finite
    /// step. `None` if nothing moves and nothing drives.
    fn auto_dt(&self) -> Option<Real> {
        let amax =
            |a: &[Real]| par::reduce(a.len(), 0.0, Real::max, |r| a[r].iter().fold(0.0, |m: Real, x| m.max(x.abs())));
        // Ghost rows of u left out: beside a lid they hold 2U − u.
        let (nx, ny) = (self.nx, self.ny);
        self.limit_at(amax(&self.s.u[nx + 1..(nx + 1) * (ny + 1)]).max(amax(&self.s.v)))
    }
    fn suggest_dt(&self) -> Option<Real> {
        self.auto_dt().map(|dt| 0.5 * dt)
    }
    fn energy(&self) -> EnergyReport {
        EnergyReport {
            kinetic: self.kinetic_energy(),
            potential: Vec::new(),
            dissipated: STAGES.iter().zip(&self.s.books.losses).map(|(n, l)| (n.to_string(), *l)).collect(),
        }
    }
    /// "smoke_amount" (Σρ·dA), "smoke_injected", "smoke_advection_change" (amount = injected +
    /// change), "pressure_iterations", "pressure_residual" (relative, last solve),
    /// "viscosity_iterations" (last step, both components).
    fn books(&self) -> Vec<(String, Real)> {
        let b = &self.s.books;
        vec![
            ("smoke_amount".into(), self.smoke_amount()),
            ("smoke_injected".into(), b.injected),
            ("smoke_advection_change".into(), b.smoke_advection),
            ("pressure_iterations".into(), b.pressure.iterations as Real),
            ("pressure_residual".into(), b.pressure.residual),
            ("viscosity_iterations".into(), b.viscosity_iterations as Real),
        ]
    }
    /// Cell-centred "u", "v" (face averages, m/s), "speed", "vorticity" (1/s), "density",
    /// "temperature", "pressure" (m²/s²), "divergence" (1/s), "solid" (1/0); and "tracers"
    /// (2·n_tracers: x0, y0, x1, … in m).
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let need = Need::fields(names, self.nx * self.ny, "grid cells");
        names
            .iter()
            .map(|n| self.field_cells(n, &need).unwrap_or_else(|| need.filled(self.nx * self.ny, 0.0)))
            .collect()
    }
    fn snapshot(&self) -> Result<Snapshot> {
        let s = &self.s;
        let n = s.u.len() + s.v.len() + 2 * s.density.len() + s.pressure.len() + s.tracers.len();
        let need = Need::new("step", Need::bytes_of::<Real>(n), format!("a copy of {} values", count(n as u128)));
        let copy = |a: &[Real]| self.spare.copy(a, &need);
        Ok(Box::new(State {
            u: copy(&s.u)?,
            v: copy(&s.v)?,
            density: copy(&s.density)?,
            temperature: copy(&s.temperature)?,
            pressure: copy(&s.pressure)?,
            tracers: copy(&s.tracers)?,
            steps: s.steps,
            books: s.books,
        }))
    }
    /// Sets a field: "u" ((nx+1)·ny face values, i fastest, m/s), "v" (nx·(ny+1)), "density",
    /// "temperature" (nx·ny), "tracers" (2·n_tracers, x and y in m). Closed faces are set to
    /// 0 and smoke in solid cells is dropped. The velocity is not projected (see `project`).
    /// A method of `System`, so the world reaches it (an inherent `set_field` left the world
    /// with the trait's default, which refused every field).
    fn set_field(&mut self, name: &str, values: &[Real]) -> Result<()> {
        let (nx, ny) = (self.nx, self.ny);
        let len = match name {
            "u" => (nx + 1) * ny,
            "v" => nx * (ny + 1),
            "density" | "temperature" => nx * ny,
            "tracers" => self.s.tracers.len(),
            _ => {
                return Err(invalid(
                    "name",
                    format!("unknown field {name:?}; valid: u, v, density, temperature, tracers"),
                ))
            }
        };
        if values.len() != len {
            return Err(invalid(name, format!("has {} values, expected {len}", values.len())));
        }
        if let Some(i) = values.iter().position(|x| !x.is_finite()) {
            return Err(invalid(name, format!("entry {i} is not finite: {}", values[i])));
        }
        match name {
            "u" => {
                for j in 0..ny {
                    for i in 0..=nx {
                        let k = i + (nx + 1) * (j + 1);
                        self.s.u[k] = self.u_open[k] * values[i + (nx + 1) * j];
                    }
                }
            }
            "v" => {
                for j in 0..=ny {
                    for i in 0..nx {
                        let k = (i + 1) + (nx + 2) * j;
                        self.s.v[k] = self.v_open[k] * values[i + nx * j];
                    }
                }
            }
            "density" => {
                for (c, d) in self.s.density.iter_mut().enumerate() {
                    *d = self.fluid[c] * values[c];
                }
            }
            "temperature" => self.s.temperature.copy_from_slice(values),
            _ => self.s.tracers.copy_from_slice(values),
        }
        self.fill_ghosts_uv();
        Ok(())
    }
    fn restore(&mut self, snapshot: Snapshot) {
        self.s = *snapshot.downcast::<State>().expect("a snapshot of this fluid");
    }
    fn recycle(&mut self, snapshot: Snapshot) {
        if let Ok(s) = snapshot.downcast::<State>() {
            let State { u, v, density, temperature, pressure, tracers, .. } = *s;
            for b in [u, v, density, temperature, pressure, tracers] {
                self.spare.keep(b);
            }
        }
    }
    fn save(&self) -> Result<Arrays> {
        let s = &self.s;
        // Exact as f64 below 2^53 steps.
        let (steps, books) = ([s.steps as Real], self.books_array());
        let of = format!("the fluid's fields of {} cells", count(s.density.len() as u128));
        crate::systems::saved(
            of,
            &[
                ("u", &s.u),
                ("v", &s.v),
                ("density", &s.density),
                ("temperature", &s.temperature),
                ("pressure", &s.pressure),
                ("tracers", &s.tracers),
                ("steps", &steps),
                ("books", &books),
            ],
        )
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let s = &self.s;
        let names = ["u", "v", "density", "temperature", "pressure", "tracers"];
        let lens = [s.u.len(), s.v.len(), s.density.len(), s.temperature.len(), s.pressure.len(), s.tracers.len()];
        let mut got = Vec::new();
        for (n, l) in names.iter().zip(lens) {
            let a = array(arrays, n, Some(l))?;
            if let Some(i) = a.iter().position(|v| !v.is_finite()) {
                return Err(invalid(n, format!("entry {i} is not finite: {}", a[i])));
            }
            got.push(a);
        }
        let steps = array(arrays, "steps", Some(1))?[0];
        if !(steps >= 0.0 && steps.fract() == 0.0 && steps < 9.0e15) {
            return Err(invalid("steps", format!("{steps} is not a step count")));
        }
        let b = array(arrays, "books", Some(self.books_array().len()))?;
        if let Some(i) = b.iter().position(|v| !v.is_finite()) {
            return Err(invalid("books", format!("entry {i} is not finite: {}", b[i])));
        }
        let s = &mut self.s;
        for (dst, src) in [&mut s.u, &mut s.v, &mut s.density, &mut s.temperature, &mut s.pressure, &mut s.tracers]
            .into_iter()
            .zip(got)
        {
            dst.copy_from_slice(src);
        }
        s.steps = steps as u64;
        s.books = Books {
            injected: b[0],
            smoke_advection: b[1],
            losses: [b[2], b[3], b[4], b[5], b[6]],
            pressure: Solve { iterations: b[7] as usize, residual: b[8], converged: b[9] != 0.0 },
            viscosity_iterations: b[10] as usize,
        };
        Ok(())
    }
}

#[cfg(test)]
pub(crate) mod tests;
