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
//! 4. the velocity is advected by itself;
//! 5. viscosity (ν > 0): backward Euler (I − ν·dt·∇²)u = u*, per component, by CG with a
//!    diagonal preconditioner (unconditionally stable);
//! 6. projection: ∇²p = ∇·u*/dt with Neumann conditions at walls and obstacles, by CG
//!    preconditioned with one multigrid V-cycle (MGPCG, [`super::poisson`]), warm-started
//!    from the last pressure; u −= dt·∇p;
//! 7. tracers are moved by RK2 through the new velocity.
//!
//! Advection is semi-Lagrangian (RK2 backtrace, bilinear interpolation) or MacCormack (Selle,
//! Fedkiw, Kim, Liu & Rossignac, "An unconditionally stable MacCormack method", J. Sci.
//! Comput. 35 (2008)), clamped to the min/max of the interpolation neighbourhood.
//!
//! Boundaries: the walls are solid (normal velocity 0); `no_slip` sets the tangential velocity
//! on them to 0 (ghost = −inside) instead of free slip (ghost = inside), and `lid` moves the
//! top wall at speed U (ghost = 2U − inside). Obstacles are solid cells: the faces touching
//! them carry no velocity and smoke does not enter them.
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
//! energy went. Smoke: semi-Lagrangian advection does not conserve the amount either; its
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
mod lanes;

use super::poisson::{Pcg, Solve, Stencil};
use super::{rows_sum, sum_rows};
use crate::alloc::{count, Need};
use crate::error::{invalid, Failure, Result};
use crate::par;
use crate::systems::{array, Arrays, EnergyReport, Halt, Snapshot, System};
use crate::vector::Real;
use std::sync::atomic::{AtomicBool, Ordering};

/// How quantities are carried by the flow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Advection {
    /// RK2 backtrace, bilinear interpolation (first order, diffusive, unconditionally stable).
    SemiLagrangian,
    /// Forward and backward semi-Lagrangian steps correct the error, clamped to the
    /// neighbourhood's min/max (second order where smooth).
    MacCormack,
}

impl Advection {
    pub const NAMES: [&'static str; 2] = ["semi_lagrangian", "maccormack"];
    pub fn by_name(s: &str) -> Result<Self> {
        match s {
            "semi_lagrangian" => Ok(Self::SemiLagrangian),
            "maccormack" => Ok(Self::MacCormack),
            _ => Err(invalid("advection", format!("unknown scheme {s:?}; valid names: {}", Self::NAMES.join(", ")))),
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Self::SemiLagrangian => Self::NAMES[0],
            Self::MacCormack => Self::NAMES[1],
        }
    }
}

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
            return Err(invalid("dx", format!("{} must be finite and > 0 (m)", self.dx)));
        }
        if !(self.viscosity.is_finite() && self.viscosity >= 0.0) {
            return Err(invalid("viscosity", format!("{} must be finite and >= 0 (m^2/s)", self.viscosity)));
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
        st.pin();
        let pressure = Pcg::new(st, true)?;
        let wall = if config.no_slip { 2.0 } else { 0.0 };
        let (east, west) = if outflow { (0.0, 2.0) } else { (wall, wall) };
        let visc = if config.viscosity > 0.0 {
            let su = Stencil::build(nx + 1, ny, &u_open_at, [east, wall, wall, wall], true, 1.0)?;
            let sv = Stencil::build(nx, ny + 1, &v_open_at, [east, west, wall, wall], true, 1.0)?;
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
    /// The last pressure solve.
    pub fn pressure_solve(&self) -> Solve {
        self.s.books.pressure
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

    /// A position for tracer `k` at step `step`: a hash of both picks a cell of the first
    /// source (or, without sources or if `anywhere`, of the fluid) and a point in it.
    fn seed(&self, k: usize, step: u64, anywhere: bool) -> (Real, Real) {
        let (nx, dx) = (self.nx, self.dx);
        let mut h = hash((k as u64) ^ hash(step));
        let src = self.cfg.sources.first().filter(|s| !s.cells.is_empty() && !anywhere);
        let mut pick = (0.5 * dx, 0.5 * dx);
        for _ in 0..64 {
            let c = match src {
                Some(s) => s.cells[(h % s.cells.len() as u64) as usize].0,
                None => (h % (nx * self.ny) as u64) as usize,
            };
            let (h1, h2) = (hash(h ^ 1), hash(h ^ 2));
            pick = (((c % nx) as Real + unit(h1)) * dx, ((c / nx) as Real + unit(h2)) * dx);
            if self.fluid[c] > 0.0 {
                break;
            }
            h = hash(h);
        }
        pick
    }

    /// Advects density and temperature by the current velocity (one backtrace serves both).
    fn advect_scalars(&mut self, dt: Real) {
        let (_, _, lay) = self.lays();
        let (nx, dx) = (self.nx, self.dx);
        let ambient = self.cfg.ambient_temperature;
        let before = self.smoke_amount();
        let vel = self.vel(&self.s.u, &self.s.v);
        let src = [&self.s.density[..], &self.s.temperature[..]];
        let fluid = &self.fluid;
        let pass = |hat: Option<[&[Real]; 2]>, d: &mut [Real], t: &mut [Real]| {
            each_row2(d, t, nx, |j, d, t| {
                lanes::run(lanes::SmokeRow { vel: &vel, dx, lay, fluid, ambient, src, hat, dt, j, out: [d, t] })
            })
        };
        if self.cfg.advection == Advection::MacCormack {
            pass(None, &mut self.fx, &mut self.fy);
            pass(Some([&self.fx, &self.fy]), &mut self.c2, &mut self.wz);
        } else {
            pass(None, &mut self.c2, &mut self.wz);
        }
        std::mem::swap(&mut self.s.density, &mut self.c2);
        std::mem::swap(&mut self.s.temperature, &mut self.wz);
        self.s.books.smoke_advection += self.smoke_amount() - before;
    }

    /// Sources blend density, temperature and face velocities towards their values.
    fn apply_sources(&mut self) {
        let (nx, da) = (self.nx, self.dx * self.dx);
        let s = &mut self.s;
        for src in &self.cfg.sources {
            for &(c, w) in &src.cells {
                if self.fluid[c] == 0.0 {
                    continue;
                }
                let d = w * (src.density - s.density[c]);
                s.density[c] += d;
                s.books.injected += d * da;
                s.temperature[c] += w * (src.temperature - s.temperature[c]);
                let (i, j) = (c % nx, c / nx);
                for k in [i + (nx + 1) * (j + 1), i + 1 + (nx + 1) * (j + 1)] {
                    s.u[k] += self.u_open[k] * w * (src.velocity[0] - s.u[k]);
                }
                for k in [(i + 1) + (nx + 2) * j, (i + 1) + (nx + 2) * (j + 1)] {
                    s.v[k] += self.v_open[k] * w * (src.velocity[1] - s.v[k]);
                }
            }
        }
    }

    /// Buoyancy and vorticity confinement, over dt.
    fn apply_forces(&mut self, dt: Real) {
        let (nx, ny, dx) = (self.nx, self.ny, self.dx);
        let (alpha, beta, amb, eps) =
            (self.cfg.buoyancy_alpha, self.cfg.buoyancy_beta, self.cfg.ambient_temperature, self.cfg.vorticity);
        let confine = eps > 0.0;
        if confine {
            let (u, v) = (&self.s.u, &self.s.v);
            let uc = |i: usize, j: usize| 0.5 * (u[i + (nx + 1) * (j + 1)] + u[i + 1 + (nx + 1) * (j + 1)]);
            let vc = |i: usize, j: usize| 0.5 * (v[(i + 1) + (nx + 2) * j] + v[(i + 1) + (nx + 2) * (j + 1)]);
            // Centred differences inside, one-sided at the walls (nx, ny ≥ 3: `validate`);
            // reciprocals, not divisions (the divider bounded these loops).
            let (centred, one_sided) = (0.5 / dx, 1.0 / dx);
            let inv = |d: usize| if d == 2 { centred } else { one_sided };
            let last = nx - 1;
            each_row(&mut self.wz, nx, |j, row| {
                let (j0, j1) = (j.saturating_sub(1), (j + 1).min(ny - 1));
                let hy = inv(j1 - j0);
                let cell = |i: usize, i0: usize, i1: usize, hx: Real| {
                    (vc(i1, j) - vc(i0, j)) * hx - (uc(i, j1) - uc(i, j0)) * hy
                };
                row[0] = cell(0, 0, 1, one_sided);
                for i in 1..last {
                    row[i] = cell(i, i - 1, i + 1, centred);
                }
                row[last] = cell(last, last - 1, last, one_sided);
            });
            let wz = &self.wz;
            let fy = &mut self.fy;
            each_row2(&mut self.fx, fy, nx, |j, fx, fy| {
                let (j0, j1) = (j.saturating_sub(1), (j + 1).min(ny - 1));
                let hy = inv(j1 - j0);
                let (w0, wc, w1) =
                    (&wz[nx * j0..nx * (j0 + 1)], &wz[nx * j..nx * (j + 1)], &wz[nx * j1..nx * (j1 + 1)]);
                let force = |i: usize, i0: usize, i1: usize, hx: Real| {
                    let ex = (wc[i1].abs() - wc[i0].abs()) * hx;
                    let ey = (w1[i].abs() - w0[i].abs()) * hy;
                    let k = eps * dx * wc[i] / ((ex * ex + ey * ey).sqrt() + 1e-300);
                    (k * ey, -k * ex)
                };
                (fx[0], fy[0]) = force(0, 0, 1, one_sided);
                for i in 1..last {
                    (fx[i], fy[i]) = force(i, i - 1, i + 1, centred);
                }
                (fx[last], fy[last]) = force(last, last - 1, last, one_sided);
            });
            let (fx, open) = (&self.fx, &self.u_open);
            rows_sum(&mut self.s.u[nx + 1..(nx + 1) * (ny + 1)], nx + 1, |j, row| {
                let f = &fx[nx * j..nx * (j + 1)];
                let m = &open[(nx + 1) * (j + 1)..(nx + 1) * (j + 2)];
                for i in 1..nx {
                    row[i] += m[i] * dt * 0.5 * (f[i - 1] + f[i]);
                }
                0.0
            });
        }
        if confine || alpha != 0.0 || beta != 0.0 {
            let (fy, open, rho, t) = (&self.fy, &self.v_open, &self.s.density, &self.s.temperature);
            rows_sum(&mut self.s.v[..(nx + 2) * (ny + 1)], nx + 2, |j, row| {
                if j == 0 || j == ny {
                    return 0.0;
                }
                let m = &open[(nx + 2) * j + 1..(nx + 2) * j + 1 + nx];
                let (r0, r1) = (&rho[nx * (j - 1)..nx * j], &rho[nx * j..nx * (j + 1)]);
                let (t0, t1) = (&t[nx * (j - 1)..nx * j], &t[nx * j..nx * (j + 1)]);
                let row = &mut row[1..1 + nx];
                for i in 0..nx {
                    let b = -alpha * 0.5 * (r0[i] + r1[i]) + beta * (0.5 * (t0[i] + t1[i]) - amb);
                    row[i] += m[i] * dt * b;
                }
                if confine {
                    let (f0, f1) = (&fy[nx * (j - 1)..nx * j], &fy[nx * j..nx * (j + 1)]);
                    for i in 0..nx {
                        row[i] += m[i] * dt * 0.5 * (f0[i] + f1[i]);
                    }
                }
                0.0
            });
        }
    }

    /// Advects the velocity by itself.
    fn advect_velocity(&mut self, dt: Real) {
        let (lu, lv, _) = self.lays();
        let (nx, ny, dx) = (self.nx, self.ny, self.dx);
        let bounds = Bounds::of(&self.cfg, &self.inflow_u);
        let mc = self.cfg.advection == Advection::MacCormack;
        let au = Active { lay: lu, kind: Node::U, a0: 0, a1: nx + 1, b0: 1, b1: ny + 1, mask: &self.u_open, fill: 0.0 };
        let av = Active { lay: lv, kind: Node::V, a0: 1, a1: nx + 1, b0: 0, b1: ny + 1, mask: &self.v_open, fill: 0.0 };
        let vel = self.vel(&self.s.u, &self.s.v);
        if mc {
            let hat = &mut self.hat[..lu.w * lu.h];
            advect_faces(&vel, dx, &au, &self.s.u, None, dt, hat);
            fill_u_ghosts(hat, nx, ny, bounds);
            advect_faces(&vel, dx, &au, &self.s.u, Some(hat), dt, &mut self.u2);
            let hat = &mut self.hat[..lv.w * lv.h];
            advect_faces(&vel, dx, &av, &self.s.v, None, dt, hat);
            fill_v_ghosts(hat, nx, ny, bounds);
            advect_faces(&vel, dx, &av, &self.s.v, Some(hat), dt, &mut self.v2);
        } else {
            advect_faces(&vel, dx, &au, &self.s.u, None, dt, &mut self.u2);
            advect_faces(&vel, dx, &av, &self.s.v, None, dt, &mut self.v2);
        }
        std::mem::swap(&mut self.s.u, &mut self.u2);
        std::mem::swap(&mut self.s.v, &mut self.v2);
        self.fill_ghosts_uv();
    }

    /// Backward-Euler viscosity, per component. `None` if stopped.
    fn diffuse(&mut self, dt: Real, stop: &AtomicBool) -> Option<()> {
        let Some(visc) = self.visc.as_mut() else { return Some(()) };
        let (nx, ny) = (self.nx, self.ny);
        let s = self.cfg.viscosity * dt / (self.dx * self.dx);
        if s != self.visc_scale {
            visc[0].stencil_mut().set_scale(s);
            visc[1].stencil_mut().set_scale(s);
            self.visc_scale = s;
        }
        let (tol, maxit) = (self.cfg.tolerance, self.cfg.max_iterations);
        let lid = self.cfg.lid.unwrap_or(0.0);
        let mut iters = 0;
        // u: unknown (i, j), i in 0..=nx, j in 0..ny, at padded (i+1) + (nx+3)(j+1).
        {
            let (x, b, u, open) = (&mut self.vx[0], &mut self.vb[0], &mut self.s.u, &self.u_open);
            let (w, wu) = (nx + 3, nx + 1);
            let lid_term = if self.cfg.no_slip { 2.0 * s * lid } else { 0.0 };
            let inflow = !self.inflow_u.is_empty();
            super::rows2_sum(&mut x[w..w * (ny + 1)], &mut b[w..w * (ny + 1)], w, |j, x, b| {
                let src = &u[wu * (j + 1)..wu * (j + 2)];
                x[1..wu + 1].copy_from_slice(src);
                b[1..wu + 1].copy_from_slice(src);
                if inflow {
                    // The held inflow face is the next face's Dirichlet neighbour.
                    b[2] += open[wu * (j + 1) + 1] * s * src[0];
                }
                if j == ny - 1 {
                    let m = &open[wu * (j + 1)..wu * (j + 2)];
                    for i in 0..wu {
                        b[i + 1] += m[i] * lid_term;
                    }
                }
                0.0
            });
            iters += visc[0].solve(x, b, tol, maxit, stop)?.iterations;
            rows_sum(&mut u[wu..wu * (ny + 1)], wu, |j, row| {
                row.copy_from_slice(&x[w * (j + 1) + 1..w * (j + 1) + 1 + wu]);
                0.0
            });
        }
        // v: unknown (i, j), i in 0..nx, j in 0..=ny, at padded (i+1) + (nx+2)(j+1).
        {
            let (x, b, v) = (&mut self.vx[1], &mut self.vb[1], &mut self.s.v);
            let w = nx + 2;
            super::rows2_sum(&mut x[w..w * (ny + 2)], &mut b[w..w * (ny + 2)], w, |j, x, b| {
                let src = &v[w * j + 1..w * j + 1 + nx];
                x[1..nx + 1].copy_from_slice(src);
                b[1..nx + 1].copy_from_slice(src);
                0.0
            });
            iters += visc[1].solve(x, b, tol, maxit, stop)?.iterations;
            rows_sum(&mut v[..w * (ny + 1)], w, |j, row| {
                row[1..nx + 1].copy_from_slice(&x[w * (j + 1) + 1..w * (j + 1) + 1 + nx]);
                0.0
            });
        }
        self.s.books.viscosity_iterations = iters;
        self.fill_ghosts_uv();
        Some(())
    }

    /// Makes the velocity divergence-free: solves ∇²p = ∇·u/dt (Neumann at walls and
    /// obstacles), u −= dt·∇p. The pressure is kept as the next solve's start. `None` if stopped.
    pub fn project(&mut self, dt: Real, stop: &AtomicBool) -> Option<Solve> {
        let (nx, ny, dx) = (self.nx, self.ny, self.dx);
        let w = nx + 2;
        // rhs = −(unnormalised divergence); q = p·dt/dx (the solve's unknown).
        {
            let (u, v, fl) = (&self.s.u, &self.s.v, &self.fluid);
            rows_sum(&mut self.rhs[w..w * (ny + 1)], w, |j, row| {
                let ur = &u[(nx + 1) * (j + 1)..(nx + 1) * (j + 2)];
                let (vs, vn) = (&v[w * j + 1..w * j + 1 + nx], &v[w * (j + 1) + 1..w * (j + 1) + 1 + nx]);
                let f = &fl[nx * j..nx * (j + 1)];
                let row = &mut row[1..1 + nx];
                for i in 0..nx {
                    row[i] = -f[i] * ((ur[i + 1] - ur[i]) + (vn[i] - vs[i]));
                }
                0.0
            });
        }
        let scale = dt / dx;
        for (q, p) in self.q.iter_mut().zip(&self.s.pressure) {
            *q = p * scale;
        }
        let solve = self.pressure.solve(&mut self.q, &self.rhs, self.cfg.tolerance, self.cfg.max_iterations, stop)?;
        {
            let (q, open) = (&self.q, &self.u_open);
            rows_sum(&mut self.s.u[nx + 1..(nx + 1) * (ny + 1)], nx + 1, |j, row| {
                let qr = &q[w * (j + 1)..w * (j + 2)];
                let m = &open[(nx + 1) * (j + 1)..(nx + 1) * (j + 2)];
                for i in 0..=nx {
                    row[i] = m[i] * (row[i] - (qr[i + 1] - qr[i]));
                }
                0.0
            });
            let open = &self.v_open;
            rows_sum(&mut self.s.v[..w * (ny + 1)], w, |j, row| {
                if j == 0 || j == ny {
                    return 0.0;
                }
                let (qs, qn) = (&q[w * j..w * (j + 1)], &q[w * (j + 1)..w * (j + 2)]);
                let m = &open[w * j..w * (j + 1)];
                for i in 1..=nx {
                    row[i] = m[i] * (row[i] - (qn[i] - qs[i]));
                }
                0.0
            });
        }
        let inv = 1.0 / scale;
        for (p, q) in self.s.pressure.iter_mut().zip(&self.q) {
            *p = q * inv;
        }
        self.s.books.pressure = solve;
        self.fill_ghosts_uv();
        Some(solve)
    }

    /// Moves the tracers by RK2 through the velocity; re-seeds those that leave or hit a solid.
    fn move_tracers(&mut self, dt: Real) {
        if self.s.tracers.is_empty() {
            return;
        }
        let mut tr = std::mem::take(&mut self.s.tracers);
        let (nx, ny, inv) = (self.nx, self.ny, 1.0 / self.dx);
        let step = self.s.steps;
        {
            let vel = self.vel(&self.s.u, &self.s.v);
            let me = &*self;
            par::chunks1(&mut tr, |start, chunk| {
                for (k, p) in chunk.chunks_exact_mut(2).enumerate() {
                    let (x, y) = (p[0], p[1]);
                    let (a, b) = vel.at(x, y);
                    let (xm, ym) = vel.clamp(x + 0.5 * dt * a, y + 0.5 * dt * b);
                    let (a, b) = vel.at(xm, ym);
                    let (xn, yn) = (x + dt * a, y + dt * b);
                    let inside = xn >= 0.0 && yn >= 0.0 && xn < vel.xmax && yn < vel.ymax;
                    let ok = inside && {
                        let (i, j) = (((xn * inv) as usize).min(nx - 1), ((yn * inv) as usize).min(ny - 1));
                        me.fluid[i + nx * j] > 0.0
                    };
                    let (xn, yn) = if ok { (xn, yn) } else { me.seed(start / 2 + k, step, false) };
                    p[0] = xn;
                    p[1] = yn;
                }
            });
        }
        self.s.tracers = tr;
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
        if self.project(dt, stop).is_none() {
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
        let umax = amax(&self.s.u[nx + 1..(nx + 1) * (ny + 1)]).max(amax(&self.s.v));
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
    fn save(&self) -> Arrays {
        let s = &self.s;
        vec![
            ("u".into(), s.u.clone()),
            ("v".into(), s.v.clone()),
            ("density".into(), s.density.clone()),
            ("temperature".into(), s.temperature.clone()),
            ("pressure".into(), s.pressure.clone()),
            ("tracers".into(), s.tracers.clone()),
            // Exact as f64 below 2^53 steps.
            ("steps".into(), vec![s.steps as Real]),
            ("books".into(), self.books_array()),
        ]
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
mod tests {
    use super::*;
    use crate::error::Error;
    use std::f64::consts::PI;
    use std::sync::Arc;

    fn no_stop() -> AtomicBool {
        AtomicBool::new(false)
    }

    fn run(f: &mut StableFluid, steps: usize, dt: Real) {
        let stop = no_stop();
        for _ in 0..steps {
            f.step(dt, &stop).unwrap();
        }
    }

    /// A deterministic pseudo-random value in [−1, 1).
    fn noise(k: usize, salt: u64) -> Real {
        2.0 * unit(hash(k as u64 ^ hash(salt))) - 1.0
    }

    fn disc(shape: [usize; 2], centre: [Real; 2], r: Real) -> Vec<bool> {
        let (nx, ny) = (shape[0], shape[1]);
        (0..nx * ny)
            .map(|c| {
                let (x, y) = ((c % nx) as Real + 0.5 - centre[0], (c / nx) as Real + 0.5 - centre[1]);
                x * x + y * y <= r * r
            })
            .collect()
    }

    /// A smoke plume: a hot, dense source near the bottom, an obstacle above it.
    fn plume(shape: [usize; 2], advection: Advection) -> FluidConfig {
        let [nx, ny] = shape;
        let dx = 1.0 / nx as Real;
        FluidConfig {
            shape,
            dx,
            viscosity: 1e-4,
            buoyancy_alpha: 0.1,
            buoyancy_beta: 2.0,
            ambient_temperature: 0.0,
            vorticity: 0.3,
            advection,
            obstacles: disc(shape, [nx as Real * 0.6, ny as Real * 0.6], nx as Real * 0.08),
            sources: vec![Source {
                cells: Source::circle(shape, dx, [0.5, 0.12], 0.08),
                density: 1.0,
                temperature: 1.0,
                velocity: [0.0, 0.2],
            }],
            n_tracers: 3000,
            ..FluidConfig::default()
        }
    }

    /// The scalar expressions the lanes must reproduce bit for bit (the passes before they were
    /// written in lanes).
    impl Vel<'_> {
        /// The velocity at node (a, b) of a layout, read off the faces (what bilinear
        /// interpolation there gives, without the search).
        #[inline(always)]
        fn node(&self, kind: Node, a: usize, b: usize) -> (Real, Real) {
            let (wu, wv) = (self.lu.w, self.lv.w);
            let (u, v) = (self.u, self.v);
            match kind {
                // Cell (a, b): its four faces.
                Node::Cell => (
                    0.5 * (u[a + wu * (b + 1)] + u[a + 1 + wu * (b + 1)]),
                    0.5 * (v[(a + 1) + wv * b] + v[(a + 1) + wv * (b + 1)]),
                ),
                // u face at padded (a, b) = (i, j + 1): the four v around it.
                Node::U => (
                    u[a + wu * b],
                    0.25 * ((v[a + wv * (b - 1)] + v[a + 1 + wv * (b - 1)]) + (v[a + wv * b] + v[a + 1 + wv * b])),
                ),
                // v face at padded (a, b) = (i + 1, j): the four u around it.
                Node::V => (
                    0.25 * ((u[a - 1 + wu * b] + u[a + wu * b]) + (u[a - 1 + wu * (b + 1)] + u[a + wu * (b + 1)])),
                    v[a + wv * b],
                ),
            }
        }
        /// Where the point at (x, y), moving at (a, b) now, was dt ago (RK2, midpoint), clamped
        /// into the domain.
        #[inline(always)]
        fn trace_from(&self, x: Real, y: Real, (a, b): (Real, Real), dt: Real) -> (Real, Real) {
            let (xm, ym) = self.clamp(x - 0.5 * dt * a, y - 0.5 * dt * b);
            let (a, b) = self.at(xm, ym);
            self.clamp(x - dt * a, y - dt * b)
        }
    }

    /// One node of `advect_faces`, one value at a time.
    #[allow(clippy::too_many_arguments)]
    fn face_reference(
        vel: &Vel,
        dx: Real,
        act: &Active,
        src: &[Real],
        hat: Option<&[Real]>,
        dt: Real,
        a: usize,
        b: usize,
    ) -> Real {
        let lay = act.lay;
        let k = a + lay.w * b;
        if act.mask[k] <= 0.0 {
            return act.fill;
        }
        let (x, y) = ((re(a) + lay.ox) * dx, (re(b) + lay.oy) * dx);
        let v0 = vel.node(act.kind, a, b);
        let (xb, yb) = vel.trace_from(x, y, v0, dt);
        let (val, lo, hi) = lay.sample(src, xb, yb, vel.inv_dx);
        match hat {
            None => val,
            Some(hat) => {
                let (xf, yf) = vel.trace_from(x, y, v0, -dt);
                let back = lay.sample(hat, xf, yf, vel.inv_dx).0;
                (hat[k] + 0.5 * (src[k] - back)).clamp(lo, hi)
            }
        }
    }

    #[test]
    fn advection_in_lanes_has_the_bits_of_the_scalar_expressions() {
        use crate::simd::{dispatch, Level};
        // Odd sides (a tail group at every level, and one grid narrower than AVX-512's lanes),
        // an obstacle, and velocities that carry some feet out of the domain (clamped).
        for shape in [[37, 29], [6, 9]] {
            let mut f = StableFluid::new(plume(shape, Advection::MacCormack)).unwrap();
            let [nx, ny] = shape;
            let field =
                |len: usize, salt: u64, scale: Real| (0..len).map(|k| scale * noise(k, salt)).collect::<Vec<_>>();
            f.set_field("u", &field((nx + 1) * ny, 1, 3.0)).unwrap();
            f.set_field("v", &field(nx * (ny + 1), 2, 3.0)).unwrap();
            f.set_field("density", &field(nx * ny, 3, 1.0)).unwrap();
            f.set_field("temperature", &field(nx * ny, 4, 1.0)).unwrap();
            f.fill_ghosts_uv();
            let (lu, lv, lc) = f.lays();
            let (dx, dt) = (f.dx, 0.7 * f.dx);
            let vel = f.vel(&f.s.u, &f.s.v);
            let au =
                Active { lay: lu, kind: Node::U, a0: 0, a1: nx + 1, b0: 1, b1: ny + 1, mask: &f.u_open, fill: 0.0 };
            let av =
                Active { lay: lv, kind: Node::V, a0: 1, a1: nx + 1, b0: 0, b1: ny + 1, mask: &f.v_open, fill: 0.5 };
            let hat_u = field(lu.w * lu.h, 5, 1.0);
            let hat_v = field(lv.w * lv.h, 6, 1.0);
            let hats = [field(nx * ny, 7, 1.0), field(nx * ny, 8, 1.0)];
            for level in Level::available() {
                for (act, src, hat) in [(&au, &f.s.u, &hat_u), (&av, &f.s.v, &hat_v)] {
                    for hat in [None, Some(&hat[..])] {
                        let w = act.lay.w;
                        for b in act.b0..act.b1 {
                            let mut row = vec![Real::NAN; w];
                            dispatch(level, lanes::FaceRow { vel: &vel, dx, act, src, hat, dt, b, row: &mut row });
                            for a in act.a0..act.a1 {
                                let want = face_reference(&vel, dx, act, src, hat, dt, a, b);
                                assert_eq!(
                                    row[a].to_bits(),
                                    want.to_bits(),
                                    "{} {shape:?} node ({a}, {b})",
                                    level.name()
                                );
                            }
                        }
                    }
                }
                let src = [&f.s.density[..], &f.s.temperature[..]];
                let cells =
                    Active { lay: lc, kind: Node::Cell, a0: 0, a1: nx, b0: 0, b1: ny, mask: &f.fluid, fill: 0.0 };
                let amb = Active { fill: f.cfg.ambient_temperature, ..cells };
                for hat in [None, Some([&hats[0][..], &hats[1][..]])] {
                    for j in 0..ny {
                        let (mut d, mut t) = (vec![Real::NAN; nx], vec![Real::NAN; nx]);
                        let out = [&mut d[..], &mut t[..]];
                        let ambient = f.cfg.ambient_temperature;
                        let row =
                            lanes::SmokeRow { vel: &vel, dx, lay: lc, fluid: &f.fluid, ambient, src, hat, dt, j, out };
                        dispatch(level, row);
                        for i in 0..nx {
                            let want_d = face_reference(&vel, dx, &cells, src[0], hat.map(|h| h[0]), dt, i, j);
                            let want_t = face_reference(&vel, dx, &amb, src[1], hat.map(|h| h[1]), dt, i, j);
                            assert_eq!(
                                d[i].to_bits(),
                                want_d.to_bits(),
                                "{} {shape:?} density ({i}, {j})",
                                level.name()
                            );
                            assert_eq!(
                                t[i].to_bits(),
                                want_t.to_bits(),
                                "{} {shape:?} temperature ({i}, {j})",
                                level.name()
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn defaults_are_pinned() {
        let c = FluidConfig::default();
        assert_eq!((c.name.as_str(), c.shape, c.dx), ("fluid", [64, 64], 1.0 / 64.0));
        assert_eq!((c.viscosity, c.buoyancy_alpha, c.buoyancy_beta, c.vorticity), (0.0, 0.0, 0.0, 0.0));
        assert_eq!((c.advection, c.tolerance, c.max_iterations, c.cfl), (Advection::SemiLagrangian, 1e-10, 500, 1.0));
        assert_eq!((c.no_slip, c.lid, c.n_tracers), (false, None, 0));
        assert!(c.validate().is_ok());
        assert_eq!(Advection::by_name("maccormack").unwrap(), Advection::MacCormack);
        assert!(Advection::by_name("upwind").unwrap_err().to_string().contains("semi_lagrangian"));
    }

    #[test]
    fn bad_configs_are_refused_naming_the_argument() {
        let d = FluidConfig::default;
        let src = |cells| Source { cells, density: 1.0, temperature: 0.0, velocity: [0.0; 2] };
        let cases: Vec<(FluidConfig, &str)> = vec![
            (FluidConfig { shape: [2, 8], ..d() }, "shape"),
            (FluidConfig { dx: 0.0, ..d() }, "dx"),
            (FluidConfig { viscosity: -1.0, ..d() }, "viscosity"),
            (FluidConfig { buoyancy_beta: Real::NAN, ..d() }, "buoyancy_beta"),
            (FluidConfig { vorticity: -0.1, ..d() }, "vorticity"),
            (FluidConfig { tolerance: 0.0, ..d() }, "tolerance"),
            (FluidConfig { max_iterations: 0, ..d() }, "max_iterations"),
            (FluidConfig { lid: Some(1.0), ..d() }, "lid"),
            (FluidConfig { inflow: Some(0.0), ..d() }, "inflow"),
            (FluidConfig { inflow: Some(-1.0), ..d() }, "inflow"),
            (FluidConfig { inflow: Some(Real::NAN), ..d() }, "inflow"),
            (FluidConfig { obstacles: vec![false; 7], ..d() }, "obstacles"),
            (FluidConfig { sources: vec![src(vec![(64 * 64, 1.0)])], ..d() }, "sources[0]"),
            (FluidConfig { sources: vec![src(vec![(3, 1.5)])], ..d() }, "sources[0]"),
            (FluidConfig { cfl: 0.0, ..d() }, "cfl"),
        ];
        for (c, name) in cases {
            match StableFluid::new(c).err() {
                Some(Error::InvalidInput { arg, msg }) => assert_eq!(arg, name, "{msg}"),
                other => panic!("{name}: {other:?}"),
            }
        }
        let mut f = StableFluid::new(d()).unwrap();
        assert!(f.set_field("u", &[0.0; 3]).is_err());
        assert!(f.set_field("pressure", &[0.0; 64 * 64]).is_err());
    }

    /// A random velocity around an obstacle, projected: max |∇·u| < 1e-8 · U/dx.
    #[test]
    fn projection_leaves_no_divergence() {
        let shape = [96, 64];
        let (nx, ny) = (96, 64);
        let cfg = FluidConfig { shape, dx: 0.01, obstacles: disc(shape, [40.0, 30.0], 9.0), ..FluidConfig::default() };
        let mut f = StableFluid::new(cfg).unwrap();
        let u: Vec<Real> = (0..(nx + 1) * ny).map(|k| noise(k, 1)).collect();
        let v: Vec<Real> = (0..nx * (ny + 1)).map(|k| noise(k, 2)).collect();
        f.set_field("u", &u).unwrap();
        f.set_field("v", &v).unwrap();
        let before = f.fields(&["divergence"]).unwrap()[0].iter().fold(0.0, |m: Real, d| m.max(d.abs()));
        let s = f.project(0.01, &no_stop()).unwrap();
        let after = f.fields(&["divergence"]).unwrap()[0].iter().fold(0.0, |m: Real, d| m.max(d.abs()));
        let bound = 1e-8 * 1.0 / 0.01;
        println!("projection {nx}x{ny}: max|div| {before:.3e} -> {after:.3e} 1/s (bound {bound:.1e}); {s:?}");
        assert!(s.converged && after < bound, "{after:e} {s:?}");
        // Solid faces carry nothing.
        let solid = f.fields(&["solid", "speed"]).unwrap();
        assert!(solid[0].iter().zip(&solid[1]).all(|(s, v)| *s == 0.0 || *v == 0.0));
    }

    /// Σ u over the faces of column i (rows of fluid), m/s: the flux through x = i·dx per dx.
    fn column_flux(f: &StableFluid, i: usize) -> Real {
        let (nx, ny) = (f.nx, f.ny);
        (0..ny).map(|j| f.s.u[i + (nx + 1) * (j + 1)]).sum()
    }

    /// An open channel (inflow U at x−, outflow at x+, free-slip y walls) that starts at rest:
    /// the first projection makes it the potential flow, a uniform plug u = U, v = 0, and
    /// steps (advection, viscosity, projection) keep that exact Navier–Stokes solution.
    #[test]
    fn a_plug_flow_passes_through_an_open_channel_unchanged() {
        let (nx, ny, speed) = (48usize, 20usize, 0.3);
        for advection in [Advection::SemiLagrangian, Advection::MacCormack] {
            let cfg = FluidConfig {
                shape: [nx, ny],
                dx: 0.01,
                viscosity: 1e-3,
                advection,
                inflow: Some(speed),
                ..FluidConfig::default()
            };
            let mut f = StableFluid::new(cfg).unwrap();
            let dt = f.auto_dt().unwrap();
            assert!((dt - 0.01 / speed).abs() < 1e-15, "the inflow drives a still fluid: dt {dt}");
            run(&mut f, 40, dt);
            let uv = f.fields(&["u", "v", "divergence"]).unwrap();
            let du = uv[0].iter().fold(0.0, |m: Real, u| m.max((u - speed).abs()));
            let v = uv[1].iter().fold(0.0, |m: Real, v| m.max(v.abs()));
            let div = uv[2].iter().fold(0.0, |m: Real, d| m.max(d.abs()));
            println!("plug flow {advection:?}: max|u − U| {du:.2e}, max|v| {v:.2e}, max|div| {div:.2e} 1/s");
            assert!(du < 1e-7 * speed && v < 1e-7 * speed, "{du:e} {v:e}");
            assert!(div < 1e-7 * speed / 0.01, "{div:e}");
            // Every face column carries the inflow's flux.
            for i in [0, nx / 2, nx] {
                assert!((column_flux(&f, i) - speed * ny as Real).abs() < 1e-7 * speed * ny as Real);
            }
        }
    }

    /// The projection with the outflow's Dirichlet pressure: a random velocity around an
    /// obstacle in an open channel comes out divergence-free, with the outflow carrying the
    /// inflow's flux (mass conservation) and the inflow face still at U.
    #[test]
    fn projection_with_an_outflow_leaves_no_divergence_and_conserves_mass() {
        let shape = [96, 40];
        let (nx, ny, speed) = (96, 40, 1.0);
        let cfg = FluidConfig {
            shape,
            dx: 0.01,
            obstacles: disc(shape, [30.0, 21.0], 6.0),
            inflow: Some(speed),
            ..FluidConfig::default()
        };
        let mut f = StableFluid::new(cfg).unwrap();
        let u: Vec<Real> = (0..(nx + 1) * ny).map(|k| noise(k, 3)).collect();
        let v: Vec<Real> = (0..nx * (ny + 1)).map(|k| noise(k, 4)).collect();
        f.set_field("u", &u).unwrap();
        f.set_field("v", &v).unwrap();
        let before = f.fields(&["divergence"]).unwrap()[0].iter().fold(0.0, |m: Real, d| m.max(d.abs()));
        let s = f.project(0.01, &no_stop()).unwrap();
        let after = f.fields(&["divergence"]).unwrap()[0].iter().fold(0.0, |m: Real, d| m.max(d.abs()));
        let bound = 1e-8 * speed / 0.01;
        let (fin, fout) = (column_flux(&f, 0), column_flux(&f, nx));
        println!("open projection: max|div| {before:.3e} -> {after:.3e} (bound {bound:.1e}); flux in {fin}, out {fout}; {s:?}");
        assert!(s.converged && after < bound, "{after:e} {s:?}");
        assert_eq!(fin, speed * ny as Real, "the inflow face is held at U");
        assert!((fout - fin).abs() < 1e-8 * fin, "in {fin} out {fout}");
        // Solid faces carry nothing.
        let solid = f.fields(&["solid", "speed"]).unwrap();
        assert!(solid[0].iter().zip(&solid[1]).all(|(s, v)| *s == 0.0 || *v == 0.0));
    }

    /// An open channel with a cylinder, run for a while: the outflow keeps carrying what comes
    /// in, and save / load continues bit-identically.
    #[test]
    fn an_open_channel_with_a_cylinder_conserves_mass_and_reloads_bit_identically() {
        let shape = [80, 32];
        let (nx, speed) = (80, 0.5);
        let cfg = FluidConfig {
            shape,
            dx: 0.01,
            viscosity: 4e-5,
            advection: Advection::MacCormack,
            tolerance: 1e-10,
            obstacles: disc(shape, [20.0, 16.5], 4.0),
            inflow: Some(speed),
            sources: vec![Source {
                cells: Source::rectangle(nx, [0, 2], [12, 20]),
                density: 1.0,
                temperature: 0.0,
                velocity: [speed, 0.0],
            }],
            ..FluidConfig::default()
        };
        let mut f = StableFluid::new(cfg.clone()).unwrap();
        let dt = 0.02;
        run(&mut f, 60, dt);
        let (fin, fout) = (column_flux(&f, 0), column_flux(&f, nx));
        println!("cylinder channel: flux in {fin}, out {fout}");
        assert!((fout - fin).abs() < 1e-8 * fin, "in {fin} out {fout}");
        assert!(f.smoke_amount() > 0.0 && f.s.density.iter().all(|d| d.is_finite()));
        let saved = f.save();
        run(&mut f, 10, dt);
        let a = f.save();
        let mut g = StableFluid::new(cfg).unwrap();
        g.load(&saved).unwrap();
        run(&mut g, 10, dt);
        assert!(g.save() == a, "load");
    }

    /// Taylor–Green vortex in the free-slip box [0, π]²: u = sin x cos y, v = −cos x sin y has
    /// zero normal velocity and zero shear on the walls, so it is an exact Navier–Stokes
    /// solution there, decaying as exp(−2νt) (kinetic energy exp(−4νt)).
    fn taylor_green(n: usize, advection: Advection, nu: Real, t_end: Real, cfl: Real) -> Real {
        let dx = PI / n as Real;
        let cfg = FluidConfig { shape: [n, n], dx, viscosity: nu, advection, ..FluidConfig::default() };
        let mut f = StableFluid::new(cfg).unwrap();
        let u: Vec<Real> = (0..(n + 1) * n)
            .map(|k| {
                let (x, y) = ((k % (n + 1)) as Real * dx, ((k / (n + 1)) as Real + 0.5) * dx);
                x.sin() * y.cos()
            })
            .collect();
        let v: Vec<Real> = (0..n * (n + 1))
            .map(|k| {
                let (x, y) = (((k % n) as Real + 0.5) * dx, (k / n) as Real * dx);
                -x.cos() * y.sin()
            })
            .collect();
        f.set_field("u", &u).unwrap();
        f.set_field("v", &v).unwrap();
        let e0 = f.kinetic_energy();
        let steps = (t_end / (cfl * dx)).ceil() as usize; // the peak speed is 1
        run(&mut f, steps, t_end / steps as Real);
        let ratio = f.kinetic_energy() / e0;
        let exact = (-4.0 * nu * t_end).exp();
        let total = f.energy().total();
        assert!((total - e0).abs() < 1e-12 * e0, "books: {total} vs {e0}");
        (ratio - exact).abs() / exact
    }

    #[test]
    fn taylor_green_decays_at_the_viscous_rate_and_converges() {
        // The error is first order: the splitting of advection and projection loses O(dt²)
        // energy a step (the scheme's own dissipation); refining dx and dt together at a fixed
        // CFL number halves it.
        let (nu, t, cfl) = (0.05, 1.0, 0.25);
        let mut errors = Vec::new();
        println!("Taylor-Green, free-slip box [0,pi]^2, nu = {nu}, t = {t}, cfl {cfl}: relative error of KE(t)/KE(0) vs exp(-4 nu t)");
        println!("{:>6} {:>14} {:>14}", "n", "maccormack", "semi_lagr.");
        for n in [16, 32, 64] {
            let mc = taylor_green(n, Advection::MacCormack, nu, t, cfl);
            let sl = taylor_green(n, Advection::SemiLagrangian, nu, t, cfl);
            println!("{n:>6} {mc:>14.3e} {sl:>14.3e}");
            errors.push((mc, sl));
        }
        assert!(errors[2].0 < 0.01, "64^2 MacCormack: {:e}", errors[2].0);
        assert!(errors[0].0 > errors[1].0 && errors[1].0 > errors[2].0, "{errors:?}");
        let sl = taylor_green(64, Advection::SemiLagrangian, nu, t, 1.0);
        println!("semi-Lagrangian, 64^2, cfl 1: {sl:.3e}");
    }

    /// Ghia, Ghia & Shin, "High-Re solutions for incompressible flow using the Navier-Stokes
    /// equations and a multigrid method", J. Comput. Phys. 48 (1982) 387-411, Table I, Re = 100:
    /// u along the vertical centreline x = 0.5 of the unit lid-driven cavity (lid speed 1).
    const GHIA_RE100: [(Real, Real); 17] = [
        (1.0000, 1.00000),
        (0.9766, 0.84123),
        (0.9688, 0.78871),
        (0.9609, 0.73722),
        (0.9531, 0.68717),
        (0.8516, 0.23151),
        (0.7344, 0.00332),
        (0.6172, -0.13641),
        (0.5000, -0.20581),
        (0.4531, -0.21090),
        (0.2813, -0.15662),
        (0.1719, -0.10150),
        (0.1016, -0.06434),
        (0.0703, -0.04775),
        (0.0625, -0.04192),
        (0.0547, -0.03717),
        (0.0000, 0.00000),
    ];

    #[test]
    fn lid_driven_cavity_re100_matches_ghia() {
        // 48² cells, CFL 1, run to t = 12 lid-crossing times (steady to better than 1e-3).
        for (n, cfl, t_end) in [(48usize, 1.0, 12.0)] {
            let dx = 1.0 / n as Real;
            let cfg = FluidConfig {
                shape: [n, n],
                dx,
                viscosity: 0.01,
                no_slip: true,
                lid: Some(1.0),
                advection: Advection::MacCormack,
                cfl,
                ..FluidConfig::default()
            };
            let mut f = StableFluid::new(cfg).unwrap();
            let stop = no_stop();
            let (mut t, mut steps) = (0.0, 0);
            let start = std::time::Instant::now();
            let mut its = 0;
            while t < t_end {
                let dt = f.auto_dt().unwrap().min(t_end - t);
                f.step(dt, &stop).unwrap();
                its += f.pressure_solve().iterations;
                t += dt;
                steps += 1;
            }
            let lu = f.lays().0;
            let mut worst: Real = 0.0;
            for (y, u) in GHIA_RE100 {
                let got = lu.sample(&f.s.u, 0.5, y, 1.0 / dx).0;
                worst = worst.max((got - u).abs());
                println!("  y {y:.4}: ghia {u:+.5} here {got:+.5}");
            }
            println!(
                "cavity Re=100 {n}^2 cfl {cfl}: {steps} steps to t = {t_end} in {:.2?}, {:.1} pressure iterations/step, max |u - ghia| = {worst:.4}",
                start.elapsed(),
                its as Real / steps as Real
            );
            assert!(worst < 0.03, "{worst}");
        }
    }

    /// The same run on 1 and 2 threads: bit-identical state.
    #[test]
    fn runs_are_bit_identical_for_any_thread_count() {
        let mut saved = Vec::new();
        for threads in [1, 2] {
            let pool = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap());
            let out = crate::par::install(Some(&pool), || {
                let mut f = StableFluid::new(plume([64, 80], Advection::MacCormack)).unwrap();
                run(&mut f, 15, 0.01);
                (f.save(), f.fields(&["vorticity", "speed", "pressure"]).unwrap())
            });
            saved.push(out);
        }
        assert!(saved[0] == saved[1]);
    }

    #[test]
    fn snapshot_restore_and_save_load_continue_bit_identically() {
        let cfg = plume([48, 64], Advection::MacCormack);
        let mut f = StableFluid::new(cfg.clone()).unwrap();
        run(&mut f, 8, 0.01);
        let snap = f.snapshot().unwrap();
        let saved = f.save();
        run(&mut f, 8, 0.01);
        let a = f.save();
        f.restore(snap);
        run(&mut f, 8, 0.01);
        assert!(f.save() == a, "restore");
        let mut g = StableFluid::new(cfg).unwrap();
        g.load(&saved).unwrap();
        run(&mut g, 8, 0.01);
        assert!(g.save() == a, "load");
        let mut bad = saved.clone();
        bad[0].1[5] = Real::NAN;
        assert!(g.load(&bad).is_err());
    }

    /// Semi-Lagrangian advection, implicit viscosity and the projection are unconditionally
    /// stable: a step a thousand times the CFL step stays finite.
    #[test]
    fn a_huge_step_stays_finite() {
        for adv in [Advection::SemiLagrangian, Advection::MacCormack] {
            let mut f = StableFluid::new(plume([32, 40], adv)).unwrap();
            let dt = 1000.0 * f.auto_dt().unwrap();
            run(&mut f, 3, dt);
            for field in f.fields(&["u", "v", "density", "temperature", "pressure"]).unwrap() {
                assert!(field.iter().all(|x| x.is_finite()));
            }
        }
    }

    /// An overflowing force makes the state non-finite: the step reports the cell, and a
    /// restore returns the state from before it bit for bit; a set stop flag halts.
    #[test]
    fn an_overflow_is_reported_as_a_diverged_cell() {
        let mut cfg = plume([32, 40], Advection::SemiLagrangian);
        cfg.buoyancy_beta = 1e300;
        cfg.sources[0].temperature = 1e300;
        let mut f = StableFluid::new(cfg).unwrap();
        let before = f.save();
        let snap = f.snapshot().unwrap();
        match f.step(0.01, &no_stop()) {
            Err(Halt::Diverged { index, quantity: Failure::Cell }) => assert!(index < 32 * 40),
            other => panic!("{other:?}"),
        }
        f.restore(snap);
        assert!(f.save() == before);
        assert_eq!(f.step(0.01, &AtomicBool::new(true)), Err(Halt::Stopped));
    }

    /// A checkpoint made in the buffers of recycled ones (`grids::Spare`) holds what it saved,
    /// whatever the fluid does after.
    #[test]
    fn recycled_checkpoints_restore_what_they_saved() {
        let mut f = StableFluid::new(plume([24, 32], Advection::MacCormack)).unwrap();
        let stop = no_stop();
        for _ in 0..3 {
            let snap = f.snapshot().unwrap();
            f.step(0.01, &stop).unwrap();
            f.recycle(snap);
        }
        assert!(f.spare.0.lock().unwrap().len() >= 6, "the recycled buffers are kept");
        let before = f.save();
        let snap = f.snapshot().unwrap();
        assert!(f.spare.0.lock().unwrap().is_empty(), "the checkpoint reused them");
        f.step(0.01, &stop).unwrap();
        f.step(0.01, &stop).unwrap();
        assert!(f.save() != before);
        f.restore(snap);
        assert!(f.save() == before);
    }

    /// Hot smoke rises; the smoke books balance: amount = injected + advection change.
    #[test]
    fn smoke_plume_rises_and_its_books_balance() {
        let mut f = StableFluid::new(plume([48, 64], Advection::SemiLagrangian)).unwrap();
        let stop = no_stop();
        let centre = |f: &StableFluid| {
            let d = &f.fields(&["density"]).unwrap()[0];
            let (m, my) = d.iter().enumerate().fold((0.0, 0.0), |(m, my), (c, r)| (m + r, my + r * (c / 48) as Real));
            (my / m + 0.5) * f.dx
        };
        let mut ys = Vec::new();
        for k in 0..60 {
            let dt = f.auto_dt().unwrap();
            f.step(dt, &stop).unwrap();
            if k % 20 == 19 {
                ys.push(centre(&f));
            }
        }
        let books: std::collections::HashMap<String, Real> = f.books().into_iter().collect();
        let (amount, injected, change) =
            (books["smoke_amount"], books["smoke_injected"], books["smoke_advection_change"]);
        println!("plume: centre of smoke y {ys:?}; amount {amount:.6}, injected {injected:.6}, advection change {change:.3e}; books {books:?}");
        assert!(ys[0] > 0.12 && ys[1] > ys[0] && ys[2] > ys[1], "{ys:?}");
        assert!((amount - (injected + change)).abs() < 1e-12 * injected);
        let e = f.energy();
        println!("energy {e:?}");
        assert!(e.dissipated.iter().find(|d| d.0 == "forces").unwrap().1 < 0.0, "buoyancy does work");
        let tr = &f.fields(&["tracers"]).unwrap()[0];
        assert_eq!(tr.len(), 6000);
        assert!(tr.iter().all(|x| (0.0..=1.0).contains(x) || (0.0..=64.0 / 48.0).contains(x)));
    }

    /// Per-pass timings at 512², serial (run with --ignored).
    #[test]
    #[ignore]
    fn bench_parts() {
        let mut cfg = plume([512, 512], Advection::SemiLagrangian);
        cfg.n_tracers = 0;
        let mut f = StableFluid::new(cfg).unwrap();
        let stop = no_stop();
        for _ in 0..3 {
            f.step(f.auto_dt().unwrap(), &stop).unwrap();
        }
        let dt = f.auto_dt().unwrap();
        let time = |name: &str, n: usize, f: &mut dyn FnMut()| {
            let s = std::time::Instant::now();
            for _ in 0..n {
                f();
            }
            println!("{name}: {:.3} ms", s.elapsed().as_secs_f64() * 1e3 / n as Real);
        };
        time("advect_scalars", 10, &mut || f.advect_scalars(dt));
        time("advect_velocity", 10, &mut || f.advect_velocity(dt));
        let st = f.pressure.stencil().clone();
        let (x, mut out) = (f.q.clone(), vec![0.0; f.q.len()]);
        time("apply", 50, &mut || {
            super::super::poisson::apply(&st, &x, &mut out);
        });
        time("project", 10, &mut || {
            f.s.pressure.fill(0.0);
            f.project(dt, &stop);
        });
        println!("iterations from zero: {:?}", f.pressure_solve());
    }

    /// 512² plume: time per step and pressure iterations (run with --ignored).
    #[test]
    #[ignore]
    fn bench_512() {
        let threads = std::env::var("FLUID_THREADS").ok().and_then(|s| s.parse().ok()).unwrap_or(2);
        let pool = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap());
        crate::par::install(Some(&pool), || {
            for adv in [Advection::SemiLagrangian, Advection::MacCormack] {
                let mut cfg = plume([512, 512], adv);
                cfg.n_tracers = 0;
                let mut f = StableFluid::new(cfg).unwrap();
                let stop = no_stop();
                for _ in 0..5 {
                    f.step(f.auto_dt().unwrap(), &stop).unwrap();
                }
                let mut t = [0.0; 7];
                for _ in 0..5 {
                    let dt = f.auto_dt().unwrap();
                    let mut c = std::time::Instant::now();
                    let mut lap = |k: usize| {
                        t[k] += c.elapsed().as_secs_f64() * 1e3 / 5.0;
                        c = std::time::Instant::now();
                    };
                    f.advect_scalars(dt);
                    lap(0);
                    f.apply_sources();
                    lap(1);
                    f.apply_forces(dt);
                    lap(2);
                    f.advect_velocity(dt);
                    lap(3);
                    f.diffuse(dt, &stop);
                    lap(4);
                    f.project(dt, &stop);
                    lap(5);
                    f.kinetic_energy();
                    lap(6);
                }
                println!("ms: scalars {:.1} sources {:.1} forces {:.1} velocity {:.1} viscosity {:.1} projection {:.1} ke {:.1}", t[0], t[1], t[2], t[3], t[4], t[5], t[6]);
                let start = std::time::Instant::now();
                let (n, mut its) = (20, 0);
                for _ in 0..n {
                    f.step(f.auto_dt().unwrap(), &stop).unwrap();
                    its += f.pressure_solve().iterations;
                }
                println!(
                    "512^2 {} on {threads} threads: {:.2} ms/step, {:.1} pressure iterations/step",
                    adv.name(),
                    start.elapsed().as_secs_f64() * 1e3 / n as Real,
                    its as Real / n as Real
                );
            }
        });
    }
}
