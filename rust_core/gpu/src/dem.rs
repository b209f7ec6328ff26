//! DEM grains resident on the device: discs (2D) and spheres (3D) with the contact laws of the
//! CPU's "contacts" term (`rust_core/src/terms/contacts`, whose module docs derive them), a
//! whole step on the device, f32 or f64 (issue "GPU fluids, grains and batches"):
//!
//! - Pair (i, j) touches when d = |x_j − x_i| < r_i + r_j: normal n = (x_j − x_i)/d, overlap
//!   δ = r_i + r_j − d, m* = 1/(1/m_i + 1/m_j), levers a_i = r_i − δ/2 (both grains push at the
//!   same point: angular momentum is conserved), contact-point relative velocity
//!   v_c = v_i − v_j + (a_i ω_i + a_j ω_j) × n, v_n = v_c·n (> 0 approaching).
//! - Normal force, never attractive: linear f_n = k_n δ + γ_n v_n, γ_n = 2ζ√(k_n m*); Hertz
//!   f_n = k_n δ^{3/2} + γ_n v_n with γ_n = 2ζ√(k_n m*) δ^{1/4} (Tsuji, Tanaka & Ishida, Powder
//!   Technol. 71 (1992) 239, eq. 9). The dashpot reads the mid-step approach speed, and a
//!   contact's first step is corrected for when in the step it began (the CPU's
//!   `Material::normal` and `onset`). ζ is the host's: the core turns a restitution into ζ
//!   (`contacts::damping_ratio`).
//! - Tangential force: Cundall & Strack, Géotechnique 29 (1979) 47: a spring ξ per contact
//!   (zero when it forms, turned into the current tangent plane keeping its length),
//!   f_t = −k_t ξ − γ_t v_t capped at μ f_n (the spring then slips to the cap: linear, with the
//!   dashpot's share; Hertz, −k_t ξ alone, as the CPU's `Material::pair`); k_t = ratio·k_n
//!   (Hertz: ratio·(3/2)k_n√δ), γ_t = γ_n √ratio (Hertz √(1.5 ratio)).
//! - Rotation: τ_i = a_i n × f_t on ω (2D a scalar about z, 3D a vector), I = β m r² (disc ½,
//!   sphere ⅖ by default).
//! - Rolling resistance (μ_r > 0 only): Ai, Chen, Rotter & Ooi, Powder Technol. 206 (2011) 269,
//!   model C, as the CPU has it: a rolling spring θ_r per contact following the relative rolling
//!   velocity ω_r = ω_i − ω_j less its twist about n (3D; a wall's ω is 0), torque −k_r θ_r with
//!   k_r = 2.25 k_c μ_r² R*² (k_c the normal contact stiffness, R* = r_i r_j/(r_i + r_j), r_i
//!   for a wall) capped at μ_r R* f_n (the spring slips, the dashpot off); below the cap a dashpot
//!   −η_r 2√(I_r k_r) ω_r, I_r = 1/(1/(I_i + m_i r_i²) + 1/(I_j + m_j r_j²)), the sum capped
//!   again. +M on i, −M on j: a couple. Its books go to "friction".
//! - Walls ([`Shape`]) are the CPU's: planes {x : (x − p)·n ≥ 0}, balls and bowls, capsules
//!   and oriented boxes, each with its own ζ and μ. A grain touches a wall when the signed
//!   distance s of its centre from the surface (unit normal u into the allowed side, the CPU's
//!   `Shape::closest` expression by expression) is below r: overlap r − s, normal −u, m* = m,
//!   lever r − δ/2; a wall neither moves nor turns. A plane's s = (x − p)·n, u = n; a ball's
//!   s = |x − c| − r along the radius (a bowl's r − |x − c|, u towards the centre; at the
//!   centre itself u is up); a capsule is the ball about the axis point nearest to x (Ericson,
//!   *Real-Time Collision Detection*, 2005, §5.1.2); an oriented box's s is the depth under
//!   its least-deep face (inside), the distance across one face, or to the nearest edge or
//!   corner point (Ericson 2005, §5.1.4), so a grain rolls round an edge as round a rod.
//! - Pinned grains (`set_pinned`) are fixed obstacles, pegs, as the CPU term holds them
//!   (`inv_mass` 0): 1/m* = 1/m_i + 1/m_j with 1/m = 0 for the pinned one (so m* = m_free), its
//!   1/(I + m r²) 0 in the rolling dashpot's I_r; a pinned grain never moves or turns, two
//!   pinned grains never meet, and a pinned grain touches no wall. A pair with a free grain is
//!   an ordinary pair otherwise (held in both histories, its books to its first grain, pinned
//!   or not).
//! - Linear drag (`DemParams::drag`, the CPU's "drag" term): F = −b v on each free grain at
//!   the step's start, added to the contacts' force before the kick.
//! - Semi-implicit Euler, v' = v + dt (f/m + g), x' = x + dt v', ω' = ω + dt τ/I (in 2D also
//!   the rotation angle, θ' = θ + dt ω', as the CPU's `end_step`); then each
//!   contact's spring follows the contact point at the new state, ξ ← ξ_capped + dt·v_t(new).
//!   The CPU defers that update to its next evaluation; here it runs at the end of the step
//!   (`commit`), the same arithmetic on the same state, so the history is whole between calls.
//!
//! Neighbours: a cell list built on the device every step (`cells.wgsl`'s counting sort, each
//! cell's grains then in index order) over the box `[lower, upper]` of [`DemParams`], cells at
//! least 2 r_max wide (touching grains sit in neighbouring cells). Grains outside the box fall
//! into its edge cells: still found, only slower.
//!
//! Determinism and conservation (the CPU's promises): no float atomics. The thread of grain i
//! sums only grain i's force and torque, over its neighbours in cell order then index order,
//! then its walls; each pair is evaluated with its lower index as the first grain by the same
//! code at both ends, and the second takes the exact negative: Σ F = 0 and Σ (x × F + τ) = 0 up
//! to the rounding of each grain's own sum. Runs repeat bit for bit on one adapter.
//!
//! Tangential history by pair key: each grain keeps up to `capacity` contacts (partner index,
//! or n + w for wall w) with ξ as seen from the pair's first grain, so both ends hold the same
//! ξ bit for bit. A contact found again takes its ξ, a new one starts at 0, a lost one is
//! dropped (its spring's energy booked as dissipated). More contacts on one grain than the
//! capacity halts the run ([`Halt::Failed`], naming the grain), never silently.
//!
//! Energy books ([`DemBooks`]), as the CPU keeps them: kinetic (translation + rotation), the
//! contact potential (½k_n δ² or ⅖k_n δ^{5/2} over the overlaps now, + ½k_t|ξ|² of the stored
//! springs, at most ½(μ f_n)²/k_t: the CPU's `Material::spring_energy`), gravity's potential −Σ m g·x (kinetic and gravity over the free grains only), the
//! energy drag dissipated (dt·b Σ|v|² a step, the power at the step's start: the CPU's
//! `book_power`, so the drag book is the CPU's to rounding), and the dissipated energy of the
//! normal dashpots and of friction, booked per contact and step as the work its force drew from the motion
//! (the mean of its power at the step's two ends: semi-implicit Euler changes the kinetic
//! energy by exactly F·(v + v')/2 dt) less what its spring gained. A pair's books go to its
//! first grain, kept per grain on the device, summed on the host in index order. The totals
//! balance to rounding (but for gravity's ½dt Σ m g·(v₀ − v), the integrator's own and
//! bounded): the power at the step's end is taken through the geometry the force was evaluated
//! with (as the CPU does; the rolling torque's as M·(ω_i − ω_j)),
//! and a contact's first evaluation does not book the energy its normal spring already holds
//! (the overlap formed within a step with no force doing work on it), which the books thus
//! take as negative dissipation (the CPU books the same energy at the commit of the step that
//! made it). The first step after `new` books those it finds, as the CPU does: they were in
//! the books from the start.
//!
//! Against the CPU the arithmetic is the same expression by expression but not bit for bit
//! (fused multiply-adds where the driver makes them, and the rolling torques summed with each
//! contact rather than in a pass of their own).
//!
//! Memory per grain: the state, and per history entry 4·dim + 3 reals (+ 3·axial + 1 with
//! rolling resistance) and two keys: 2D f32 at the default capacity 8, about 500 bytes a grain
//! (a million discs: 0.5 GB; the contact history alone is 352 MB, one binding).
//!
//! Not here (the CPU has them): Verlet lists (the cell list is rebuilt
//! every step), "xpbd"; of the other force terms only a uniform gravity and linear drag.
use crate::cells::{spread, write_cell_params, CellBuild};
use crate::particles::Halt;
pub use crate::shape::Shape;
use crate::shape::ROW;
use crate::sph::{invalid, positive};
use crate::{Bind, Chunk, Gpu, Precision, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// The normal force law.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    /// f_n = k_n δ + γ_n v_n (k_n in N/m).
    Linear,
    /// f_n = k_n δ^{3/2} + γ_n v_n (k_n in N/m^{3/2}).
    Hertz,
}

/// A wall: its shape (any but `Shape::Box`: a box's walls are its faces, planes), with its
/// damping ratio ζ (of its restitution) and friction μ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wall {
    pub shape: Shape,
    pub zeta: f64,
    pub friction: f64,
}

impl Wall {
    /// The half-space {x : (x − point)·normal ≥ 0}.
    pub fn plane(point: [f64; 3], normal: [f64; 3], zeta: f64, friction: f64) -> Self {
        Self { shape: Shape::Plane { point, normal }, zeta, friction }
    }

    /// Checked and in the device's form (z zeroed in 2D, a plane's normal of unit length);
    /// `Unsupported` naming wall `w` if it is out of range.
    fn checked(&self, w: usize, dim: usize) -> Result<Self> {
        let bad = |what: &str| invalid("walls", format_args!("wall {w}: {what}"));
        let flat = |mut v: [f64; 3]| {
            if dim == 2 {
                v[2] = 0.0;
            }
            v
        };
        let finite = |v: &[f64]| v.iter().all(|c| c.is_finite());
        let round = |r: f64| r > 0.0 && (r * r).is_finite();
        let shape = match self.shape {
            Shape::Plane { point, normal } => {
                let (point, normal) = (flat(point), flat(normal));
                let len = normal.iter().map(|c| c * c).sum::<f64>().sqrt();
                if !(len.is_finite() && len > 0.0 && finite(&point)) {
                    return Err(bad("a plane needs a finite point and a non-zero normal"));
                }
                // A normal already of unit length (the CPU's, normalised there) keeps its bits.
                let unit = (len - 1.0).abs() <= 4.0 * f64::EPSILON;
                Shape::Plane { point, normal: if unit { normal } else { normal.map(|c| c / len) } }
            }
            Shape::Sphere { center, radius, inside } => {
                if !(finite(&center) && round(radius)) {
                    return Err(bad("a sphere needs a finite centre and a radius > 0 with a finite square"));
                }
                Shape::Sphere { center: flat(center), radius, inside }
            }
            Shape::Capsule { a, b, radius } => {
                let (a, b) = (flat(a), flat(b));
                let l2: f64 = (0..3).map(|k| (b[k] - a[k]) * (b[k] - a[k])).sum();
                if !(finite(&a) && finite(&b) && l2.is_finite() && round(radius)) {
                    return Err(bad("a capsule needs finite ends and a radius > 0 with a finite square"));
                }
                Shape::Capsule { a, b, radius }
            }
            Shape::Box { .. } => {
                return Err(bad("a box: give its faces as plane walls (the CPU's contacts term does)"));
            }
            Shape::OrientedBox { center, half, axes } => {
                let axes = axes.map(flat);
                let unit = (0..dim).all(|j| {
                    (0..dim).all(|k| {
                        let dot: f64 = (0..3).map(|c| axes[j][c] * axes[k][c]).sum();
                        (dot - if j == k { 1.0 } else { 0.0 }).abs() <= 1e-9
                    })
                });
                if !finite(&center) {
                    return Err(bad("an oriented box needs a finite centre"));
                }
                if !half[..dim].iter().all(|h| h.is_finite() && *h > 0.0) {
                    return Err(bad("an oriented box needs finite half extents > 0"));
                }
                if !unit {
                    return Err(bad("an oriented box needs unit, orthogonal axes"));
                }
                let (mut half, mut axes) = (half, axes);
                half[dim..].fill(0.0);
                axes[dim..].fill([0.0; 3]);
                Shape::OrientedBox { center: flat(center), half, axes }
            }
        };
        finite_nonneg(self.zeta, "walls' zeta")?;
        finite_nonneg(self.friction, "walls' friction")?;
        Ok(Self { shape, zeta: self.zeta, friction: self.friction })
    }
}

/// The grains' material, gravity and search box, SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DemParams {
    pub law: Law,
    /// k_n: N/m (linear) or N/m^{3/2} (Hertz), > 0.
    pub stiffness: f64,
    /// Damping ratio ζ ≥ 0 of grain–grain contacts (0: elastic).
    pub zeta: f64,
    /// Coulomb friction μ ≥ 0 between grains.
    pub friction: f64,
    /// k_t over the normal contact stiffness, > 0 (the CPU's default β/(1 + β): 1/3 discs,
    /// 2/7 spheres).
    pub tangential_ratio: f64,
    /// β of I = β m r² (> 0; 0 here: the default, ½ in 2D, ⅖ in 3D).
    pub inertia_factor: f64,
    /// Uniform gravitational acceleration, m/s² (z ignored in 2D).
    pub gravity: [f64; 3],
    /// The box the cell list covers (grains outside it are still found, in its edge cells).
    pub lower: [f64; 3],
    pub upper: [f64; 3],
    /// Cell size, m (0: twice the largest radius; never less than that).
    pub cell: f64,
    /// Contacts one grain may hold at once (0: the default, 8 in 2D, 16 in 3D; at most 32).
    pub capacity: usize,
    /// Coefficient of rolling friction μ_r ≥ 0 (0: no rolling resistance, nothing of it runs).
    pub rolling_friction: f64,
    /// η_r ≥ 0: the rolling dashpot over its critical value 2√(I_r k_r).
    pub rolling_damping: f64,
    /// Linear drag b ≥ 0 (kg/s): F = −b v on every free grain, the CPU's "drag" term
    /// (0: none, nothing of it runs).
    pub drag: f64,
}

impl Default for DemParams {
    /// Linear law, k_n = 1e4 N/m, elastic, frictionless, ratio 2/7, β by dimension, no gravity,
    /// the unit box, no rolling resistance, no drag.
    fn default() -> Self {
        Self {
            law: Law::Linear,
            stiffness: 1e4,
            zeta: 0.0,
            friction: 0.0,
            tangential_ratio: 2.0 / 7.0,
            inertia_factor: 0.0,
            gravity: [0.0; 3],
            lower: [0.0; 3],
            upper: [1.0; 3],
            cell: 0.0,
            capacity: 0,
            rolling_friction: 0.0,
            rolling_damping: 0.0,
            drag: 0.0,
        }
    }
}

/// The energy books (J).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DemBooks {
    /// ½ Σ m |v|².
    pub kinetic: f64,
    /// ½ Σ I |ω|².
    pub rotational: f64,
    /// The contacts' springs now: normal (over the overlaps) and tangential (stored).
    pub potential: f64,
    /// Gravity's potential −Σ m g·x (zero at the origin).
    pub gravity: f64,
    /// Dissipated so far by the normal dashpots (and the clamp letting go of an overlap).
    pub damping: f64,
    /// Dissipated so far by friction (slipping, and the springs of contacts that ended).
    pub friction: f64,
    /// Dissipated so far by drag: Σ over steps of dt·b Σ|v|² at the step's start (the CPU's
    /// book of a term's power).
    pub drag: f64,
}

impl DemBooks {
    /// Everything: constant up to the scheme's error.
    pub fn total(&self) -> f64 {
        (self.kinetic + self.rotational) + (self.potential + self.gravity) + (self.damping + self.friction + self.drag)
    }
}

/// Everything a checkpoint needs (`save_raw`, `load_raw`), as f64 (rounded to the device's
/// precision when loaded).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DemRaw {
    /// Positions and velocities (n·dim), ω (n in 2D, 3n in 3D), as `read` gives them.
    pub x: Vec<f64>,
    pub v: Vec<f64>,
    pub omega: Vec<f64>,
    /// The rotation angles (rad): n in 2D, none in 3D.
    pub angle: Vec<f64>,
    /// The committed contact history: per grain, its count then `capacity` partners (a grain
    /// index, or n + w for wall w): n·(capacity + 1) values.
    pub keys: Vec<u32>,
    /// Per grain and entry, ξ (dim, as seen from the pair's first grain) and the energy it
    /// stores (J), then with rolling resistance θ_r (1 value in 2D, 3 in 3D) and its energy:
    /// n·capacity·(dim + 1) values, n·capacity·(dim + 2 + axial) with rolling resistance.
    pub springs: Vec<f64>,
    /// The dissipated books per grain: n of the normal dashpots, n of friction, then n of drag
    /// (J).
    pub books: Vec<f64>,
}

/// Values per grain in the ω buffer: ω and, in 2D, the angle (the n angles after the n spins).
fn spin_width(dim: usize) -> usize {
    if dim == 2 {
        2
    } else {
        3
    }
}

fn finite_nonneg(v: f64, what: &str) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(what, format_args!("{v} must be finite and >= 0")))
    }
}

/// Values per committed and per evaluated contact history entry (`dem.wgsl`'s `stride_in`,
/// `stride_out`): ξ, its energy (and θ_r, its energy); ξ capped, f_t, n, f_n, δ (and θ_r capped,
/// the rolling torque).
fn strides(dim: usize, roll: bool) -> (usize, usize) {
    let ad = if dim == 2 { 1 } else { 3 };
    let r = roll as usize;
    (dim + 1 + r * (ad + 1), 3 * dim + 2 + r * 2 * ad)
}

/// Steps in one submission at most.
const MAX_CHUNK: u64 = 1024;

/// Copies of the state a `restore` returns to.
struct Saved {
    bufs: Vec<wgpu::Buffer>,
    primed: bool,
}

/// Grains on one device: state in the caller's order, the cell list, the contact history.
pub struct Dem {
    gpu: Arc<Gpu>,
    precision: Precision,
    dim: usize,
    p: DemParams,
    n: usize,
    cap: usize,
    beta: f64,
    cells: [usize; 3],
    radius: Vec<f64>,
    mass: Vec<f64>,
    /// Fixed obstacles (`set_pinned`).
    pinned: Vec<bool>,
    walls: Vec<Wall>,
    pos: wgpu::Buffer,
    vel: wgpu::Buffer,
    omega: wgpu::Buffer,
    /// Per grain: radius, mass, 1 free or 0 pinned.
    props: wgpu::Buffer,
    keys: wgpu::Buffer,
    vals: wgpu::Buffer,
    flag: wgpu::Buffer,
    books: wgpu::Buffer,
    params: wgpu::Buffer,
    staging: wgpu::Buffer,
    bind: wgpu::BindGroup,
    /// cells.wgsl's build (`CellBuild`).
    cell_build: CellBuild,
    /// dem.wgsl's contacts, integrate, commit, energy, tally.
    pipes: Vec<wgpu::ComputePipeline>,
    chunk: Chunk,
    saved: Option<Saved>,
    /// Whether a step ran since `new` (see `dem.wgsl`'s `primed`).
    primed: bool,
    _keep: Vec<wgpu::Buffer>,
}

impl Dem {
    /// Uploads `n` grains: `x`, `v` flat (n·dim; m, m/s), `radius` (m, > 0) and `mass` (kg, > 0)
    /// one each; ω starts at 0 (`set_omega`). `walls`: at most 2^16.
    ///
    /// Errors: `Unsupported` naming the first thing out of range (parameters, ragged or
    /// non-finite arrays, a radius or mass not finite and > 0, a wall out of range (`Wall`), more
    /// than 2^31 cells or grains), f64 on an adapter without it, buffers over its limits;
    /// `OutOfMemory` naming the buffer.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        gpu: Arc<Gpu>,
        precision: Precision,
        dim: usize,
        params: DemParams,
        x: &[f64],
        v: &[f64],
        radius: &[f64],
        mass: &[f64],
        walls: &[Wall],
    ) -> Result<Self> {
        gpu.check_precision(precision)?;
        let p = params;
        if !(dim == 2 || dim == 3) {
            return Err(invalid("dim", format_args!("{dim} must be 2 or 3")));
        }
        positive(p.stiffness, "stiffness")?;
        finite_nonneg(p.zeta, "zeta")?;
        finite_nonneg(p.friction, "friction")?;
        positive(p.tangential_ratio, "tangential_ratio")?;
        finite_nonneg(p.inertia_factor, "inertia_factor")?;
        finite_nonneg(p.cell, "cell")?;
        finite_nonneg(p.rolling_friction, "rolling_friction")?;
        finite_nonneg(p.rolling_damping, "rolling_damping")?;
        finite_nonneg(p.drag, "drag")?;
        if !p.gravity.iter().all(|g| g.is_finite()) {
            return Err(invalid("gravity", "must be finite"));
        }
        for a in 0..dim {
            let (lo, hi) = (p.lower[a], p.upper[a]);
            if !(lo.is_finite() && hi.is_finite() && hi > lo) {
                return Err(invalid("upper", format_args!("axis {a}: [{lo}, {hi}] must be finite with upper > lower")));
            }
        }
        let cap = if p.capacity == 0 { [8, 16][dim - 2] } else { p.capacity };
        if cap > 32 {
            return Err(invalid("capacity", format_args!("{cap}: at most 32 contacts per grain")));
        }
        if !x.len().is_multiple_of(dim) || v.len() != x.len() {
            return Err(invalid(
                "x",
                format_args!(
                    "{} positions and {} velocities: both must hold dim = {dim} values per grain",
                    x.len(),
                    v.len()
                ),
            ));
        }
        let n = x.len() / dim;
        if radius.len() != n || mass.len() != n {
            return Err(invalid(
                "radius",
                format_args!("{} radii and {} masses for {n} grains: one each", radius.len(), mass.len()),
            ));
        }
        if n as u64 >= 1 << 31 {
            return Err(invalid("x", format_args!("{n} grains: at most 2^31")));
        }
        if let Some(k) = x.iter().chain(v).position(|u| !u.is_finite()) {
            let (what, k) = if k < x.len() { ("x", k) } else { ("v", k - x.len()) };
            return Err(invalid(what, format_args!("grain {} has a non-finite value", k / dim)));
        }
        for (what, a) in [("radius", radius), ("mass", mass)] {
            if let Some(i) = a.iter().position(|u| !(u.is_finite() && *u > 0.0)) {
                return Err(invalid(what, format_args!("grain {i}: {} must be finite and > 0", a[i])));
            }
        }
        if walls.len() > 1 << 16 {
            return Err(invalid("walls", format_args!("{}: at most 2^16", walls.len())));
        }
        let walls = walls.iter().enumerate().map(|(w, wall)| wall.checked(w, dim)).collect::<Result<Vec<_>>>()?;
        let beta = if p.inertia_factor > 0.0 { p.inertia_factor } else { [0.5, 0.4][dim - 2] };
        let rmax = radius.iter().cloned().fold(0.0, f64::max);
        let cell = p.cell.max(2.0 * rmax).max(f64::MIN_POSITIVE);
        let mut cells = [1usize; 3];
        let mut total = 1u64;
        for (a, ca) in cells.iter_mut().enumerate().take(dim) {
            let m = ((p.upper[a] - p.lower[a]) / cell).ceil().max(1.0);
            if m >= 2f64.powi(31) {
                return Err(invalid("cell", format_args!("{m} cells along axis {a}: at most 2^31")));
            }
            *ca = m as usize;
            total = total.saturating_mul(m as u64);
        }
        if total >= 1 << 31 {
            return Err(invalid("cell", format_args!("{total} cells in the box: at most 2^31")));
        }
        let rb = precision.bytes();
        let nn = n as u64;
        let (d, k) = (dim as u64, cap as u64);
        use wgpu::BufferUsages as U;
        let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let pos = gpu.buffer("DEM positions", nn * d * rb, st)?;
        let vel = gpu.buffer("DEM velocities", nn * d * rb, st)?;
        let omega = gpu.buffer("DEM angular velocities and angles", nn * spin_width(dim) as u64 * rb, st)?;
        let props = gpu.buffer("DEM radii, masses and pins", 3 * nn * rb, st)?;
        let wall_buf = gpu.buffer("DEM walls", (ROW as u64 * walls.len() as u64 * rb).max(16), st)?;
        let cell_of = gpu.buffer("DEM cells", nn * 4, st)?;
        let counts = gpu.buffer("DEM cell counts", total * 4, st)?;
        let start = gpu.buffer("DEM cell starts", (total + 1) * 4, st)?;
        let order = gpu.buffer("DEM cell order", nn * 4, st)?;
        let found = gpu.buffer("DEM unused neighbour counts", 16, st)?;
        let load = gpu.buffer("DEM forces and torques", 6 * nn * rb, st)?;
        let keys = gpu.buffer("DEM contact keys", 2 * nn * (k + 1) * 4, st)?;
        let (sv, sc) = strides(dim, p.rolling_friction > 0.0);
        let vals = gpu.buffer("DEM contact history", nn * k * (sv + sc) as u64 * rb, st)?;
        let flag = gpu.buffer("DEM halt flags", 16, st)?;
        let books = gpu.buffer("DEM energy books", 4 * nn * rb, st)?;
        let cell_params = gpu.buffer("DEM cell list parameters", 32 + 8 * rb, U::UNIFORM | U::COPY_DST)?;
        // STORAGE too: on a CPU adapter the kernels read it as storage (`Gpu::kernels_with`).
        let params_buf = gpu.buffer("DEM parameters", 64 + 16 * rb, U::UNIFORM | U::STORAGE | U::COPY_DST)?;
        let staging =
            gpu.buffer("DEM read-back", (4 * nn * rb).max(nn * (k + 1) * 4).max(16), U::MAP_READ | U::COPY_DST)?;
        use Bind::{Read as R, ReadWrite as W, Uniform};
        let uniform = Uniform { dynamic: false };
        let cell_bufs = [&cell_params, &pos, &cell_of, &counts, &start, &order, &found];
        let cell_build = CellBuild::new(&gpu, precision, "DEM cell list", cell_bufs, total as usize, &[])?;
        // Walls all planes: the other shapes' code compiled out (`dem.wgsl`'s `SHAPED`), so a
        // scene of planes runs the kernels it ran before the other shapes came.
        let mut wgsl = concat!(include_str!("dem.wgsl"), include_str!("cell_walk.wgsl")).to_string();
        if walls.iter().all(|w| matches!(w.shape, Shape::Plane { .. })) {
            wgsl = wgsl.replace("const SHAPED: bool = true;", "const SHAPED: bool = false;");
        }
        let (layout, pipes) = gpu.kernels_with(
            "dem.wgsl",
            precision,
            &wgsl,
            &[uniform, W, W, W, R, R, R, R, R, W, W, W, W, W],
            &["contacts", "integrate", "commit", "energy", "tally"],
            gpu.is_cpu(),
        );
        let bind = crate::grid::bind_group(
            &gpu,
            "DEM",
            &layout,
            &[
                &params_buf,
                &pos,
                &vel,
                &omega,
                &props,
                &wall_buf,
                &cell_of,
                &start,
                &order,
                &load,
                &keys,
                &vals,
                &flag,
                &books,
            ],
        );
        write_cell_params(&gpu, precision, &cell_params, (n, dim), cells, (p.lower, cell));
        if n > 0 {
            gpu.upload(precision, &pos, x);
            gpu.upload(precision, &vel, v);
            gpu.upload(precision, &omega, &vec![0.0; n * spin_width(dim)]);
            let pr: Vec<f64> = radius.iter().zip(mass).flat_map(|(&r, &m)| [r, m, 1.0]).collect();
            gpu.upload(precision, &props, &pr);
            gpu.queue.write_buffer(&keys, 0, &vec![0u8; (2 * nn * (k + 1) * 4) as usize]);
            gpu.upload(precision, &books, &vec![0.0; 4 * n]);
        }
        if !walls.is_empty() {
            let rows: Vec<f64> = walls.iter().flat_map(|w| w.shape.row([w.zeta, w.friction])).collect();
            gpu.upload(precision, &wall_buf, &rows);
        }
        let s = Self {
            gpu,
            precision,
            dim,
            p,
            n,
            cap,
            beta,
            cells,
            radius: radius.to_vec(),
            mass: mass.to_vec(),
            pinned: vec![false; n],
            walls,
            pos,
            vel,
            omega,
            props,
            keys,
            vals,
            flag,
            books,
            params: params_buf,
            staging,
            bind,
            cell_build,
            pipes,
            chunk: Chunk::new(MAX_CHUNK),
            saved: None,
            primed: false,
            _keep: vec![wall_buf, cell_of, counts, start, order, found, load, cell_params],
        };
        s.write_params(0.0);
        s.gpu.wait()?;
        Ok(s)
    }

    pub fn len(&self) -> usize {
        self.n
    }
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
    pub fn dim(&self) -> usize {
        self.dim
    }
    pub fn precision(&self) -> Precision {
        self.precision
    }
    pub fn params(&self) -> &DemParams {
        &self.p
    }
    /// The walls as the device holds them (planes' normals of unit length; z zeroed in 2D).
    pub fn walls(&self) -> &[Wall] {
        &self.walls
    }
    /// The grains' radii (m), as given.
    pub fn radii(&self) -> &[f64] {
        &self.radius
    }
    /// The grains' masses (kg), as given.
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }
    /// Which grains are pinned (`set_pinned`; none after `new`).
    pub fn pinned(&self) -> &[bool] {
        &self.pinned
    }

    /// Pins grains (`pinned`: one flag a grain): a pinned grain is a fixed obstacle, a peg,
    /// as the CPU's contacts term holds one (`inv_mass` 0). It never moves or turns (its
    /// velocity is set to 0 here, as the CPU's `add_particles` and `set_state` do; its spin is
    /// kept, and enters its contacts as the CPU's does); a pair with a free grain has
    /// m* = m_free, I_r = I_free + m r² of the free one, and is held in both grains' histories
    /// like any pair, its books going to its first grain; two pinned grains never meet; a
    /// pinned grain touches no wall; the books leave pinned grains out of the kinetic energy
    /// and of gravity's potential, as the CPU's do.
    ///
    /// Errors: `Unsupported` naming "pinned" for a length other than one flag a grain.
    pub fn set_pinned(&mut self, pinned: &[bool]) -> Result<()> {
        if pinned.len() != self.n {
            return Err(invalid("pinned", format_args!("{} flags for {} grains: one each", pinned.len(), self.n)));
        }
        self.pinned = pinned.to_vec();
        if self.n == 0 {
            return Ok(());
        }
        let pr: Vec<f64> =
            (0..self.n).flat_map(|i| [self.radius[i], self.mass[i], if pinned[i] { 0.0 } else { 1.0 }]).collect();
        self.gpu.upload(self.precision, &self.props, &pr);
        if pinned.iter().any(|&p| p) {
            let (_, mut v, _) = self.read()?;
            self.rest_pinned(&mut v);
            self.gpu.upload(self.precision, &self.vel, &v);
        }
        self.gpu.wait()
    }

    /// Zeroes the pinned grains' velocities in `v` (n·dim).
    fn rest_pinned(&self, v: &mut [f64]) {
        let d = self.dim;
        for (i, _) in self.pinned.iter().enumerate().filter(|p| *p.1) {
            v[d * i..d * (i + 1)].fill(0.0);
        }
    }
    /// Contacts one grain may hold at once.
    pub fn capacity(&self) -> usize {
        self.cap
    }
    /// β of I = β m r² in use.
    pub fn inertia_factor(&self) -> f64 {
        self.beta
    }
    /// Cells of the cell list along x, y, z.
    pub fn cells(&self) -> [usize; 3] {
        self.cells
    }

    fn write_params(&self, dt: f64) {
        let p = &self.p;
        let c = self.cells;
        let tdamp = match p.law {
            Law::Linear => p.tangential_ratio.sqrt(),
            Law::Hertz => (1.5 * p.tangential_ratio).sqrt(),
        };
        let ints = [
            self.n as u32,
            self.dim as u32,
            c[0] as u32,
            c[1] as u32,
            c[2] as u32,
            self.cap as u32,
            (p.law == Law::Hertz) as u32,
            self.walls.len() as u32,
            (p.rolling_friction > 0.0) as u32,
            if self.dim == 2 { 1 } else { 3 },
            self.primed as u32,
            0,
        ];
        let g = p.gravity;
        let reals = [
            p.stiffness,
            p.zeta,
            p.friction,
            p.tangential_ratio,
            tdamp,
            self.beta,
            dt,
            g[0],
            g[1],
            g[2],
            p.rolling_friction,
            p.rolling_damping,
            p.drag,
        ];
        self.gpu.write_params(self.precision, &self.params, &ints, &reals);
    }

    /// Records the cell list's build at the current positions.
    fn record_cells(&self, pass: &mut wgpu::ComputePass) {
        self.cell_build.record(pass, self.n);
    }

    /// Records `steps` whole steps into one command buffer.
    fn record(&self, steps: u64) -> wgpu::CommandBuffer {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            let n = spread(self.n);
            for _ in 0..steps {
                self.record_cells(&mut pass);
                pass.set_bind_group(0, &self.bind, &[]);
                for pipe in &self.pipes[..3] {
                    pass.set_pipeline(pipe);
                    pass.dispatch_workgroups(n.0, n.1, 1);
                }
            }
        }
        enc.finish()
    }

    /// Runs `steps` steps of `dt` (s), in submissions of about 0.1 s (nothing read back within
    /// one); the stop flag is read before each, the halt flags after each. Returns the steps
    /// completed; on a halt, those before the failing submission (the state is then that
    /// submission's end: the caller rolls back, e.g. to a `snapshot`), with `Halt::Diverged`
    /// naming the first grain whose state stopped being finite, or `Halt::Failed`: a `dt` that
    /// is not finite and > 0, a grain with more contacts than the capacity (`Unsupported`,
    /// naming it), a device error.
    pub fn step(&mut self, steps: u64, dt: f64, stop: &AtomicBool) -> std::result::Result<u64, (u64, Halt)> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err((0, Halt::Failed(invalid("dt", format_args!("{dt} must be finite and > 0")))));
        }
        if self.n == 0 {
            return Ok(steps);
        }
        self.write_params(dt);
        let mut done = 0;
        while done < steps {
            if stop.load(Ordering::Relaxed) {
                return Err((done, Halt::Stopped));
            }
            // The first step after `new` alone: the books treat its contacts apart.
            let k = if self.primed { self.chunk.next(steps - done) } else { 1 };
            self.gpu.queue.write_buffer(&self.flag, 0, bytemuck::cast_slice(&[u32::MAX, u32::MAX]));
            let t0 = Instant::now();
            self.gpu.queue.submit([self.record(k)]);
            let raw = self.gpu.read_back(&self.flag, &self.staging, 8).map_err(|e| (done, Halt::Failed(e)))?;
            let word = |o: usize| u32::from_le_bytes([raw[o], raw[o + 1], raw[o + 2], raw[o + 3]]);
            let (bad, full) = (word(0), word(4));
            if full != u32::MAX {
                return Err((
                    done,
                    Halt::Failed(invalid(
                        "capacity",
                        format_args!(
                            "grain {full} touched more than {} grains and walls at once (raise DemParams::capacity, \
                             at most 32, or look for grains packed too deep)",
                            self.cap
                        ),
                    )),
                ));
            }
            if bad != u32::MAX {
                return Err((done, Halt::Diverged { particle: bad as usize }));
            }
            done += k;
            if !self.primed {
                self.primed = true;
                self.write_params(dt);
            }
            self.chunk.adapt(k, t0.elapsed().as_secs_f64());
        }
        Ok(done)
    }

    /// Positions (m), velocities (m/s), both n·dim, and angular velocities (rad/s; n in 2D,
    /// 3n in 3D), in the caller's order, as f64.
    pub fn read(&self) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        if self.n == 0 {
            return Ok((Vec::new(), Vec::new(), Vec::new()));
        }
        let (p, s, nd) = (self.precision, &self.staging, self.n * self.dim);
        let ad = if self.dim == 2 { 1 } else { 3 };
        Ok((
            self.gpu.read_reals(p, &self.pos, s, nd)?,
            self.gpu.read_reals(p, &self.vel, s, nd)?,
            self.gpu.read_reals(p, &self.omega, s, self.n * ad)?,
        ))
    }

    /// Sets the angular velocities (n in 2D, 3n in 3D; finite).
    pub fn set_omega(&mut self, omega: &[f64]) -> Result<()> {
        let ad = if self.dim == 2 { 1 } else { 3 };
        if omega.len() != ad * self.n || !omega.iter().all(|w| w.is_finite()) {
            return Err(invalid("omega", format_args!("{} values: {} finite ones needed", omega.len(), ad * self.n)));
        }
        if self.n > 0 {
            self.gpu.upload(self.precision, &self.omega, omega);
        }
        self.gpu.wait()
    }

    /// The rotation angles (rad; 2D, n of them: θ' = θ + dt ω' each step, 0 at `new`; in 3D
    /// none are kept and this gives n zeros).
    pub fn angles(&self) -> Result<Vec<f64>> {
        if self.dim == 3 || self.n == 0 {
            return Ok(vec![0.0; self.n]);
        }
        let at = self.n as u64 * self.precision.bytes();
        self.gpu.read_reals_at(self.precision, &self.omega, at, &self.staging, self.n)
    }

    /// The largest overlap (m) among the contacts of the last step's evaluation (0 before the
    /// first step; after `load_raw`, that of the last step run here, if any): the CPU's
    /// `max_overlap`, which its Hertz step limit reads.
    pub fn max_overlap(&self) -> Result<f64> {
        if self.n == 0 {
            return Ok(0.0);
        }
        let (p, n, k, d) = (self.precision, self.n, self.cap, self.dim);
        let (sv, sc) = strides(d, self.p.rolling_friction > 0.0);
        let kb = (n * (k + 1) * 4) as u64;
        let mut counts = Vec::with_capacity(n);
        self.gpu.read_back_from(&self.keys, kb, &self.staging, kb, |raw| {
            counts.extend((0..n).map(|i| {
                let o = 4 * i * (k + 1);
                u32::from_le_bytes([raw[o], raw[o + 1], raw[o + 2], raw[o + 3]]) as usize
            }))
        })?;
        use wgpu::BufferUsages as U;
        let len = n * k * sc;
        let staging = self.gpu.buffer("DEM overlap read-back", len as u64 * p.bytes(), U::MAP_READ | U::COPY_DST)?;
        let vals = self.gpu.read_reals_at(p, &self.vals, (n * k * sv) as u64 * p.bytes(), &staging, len)?;
        let mut most: f64 = 0.0;
        for (i, &c) in counts.iter().enumerate() {
            for q in 0..c.min(k) {
                most = most.max(vals[(i * k + q) * sc + 3 * d + 1]);
            }
        }
        Ok(most)
    }

    /// The committed history's contacts counted once, as the CPU's contacts term counts them
    /// (a grain pair once, a grain–wall contact once): counted on the device, 4 bytes read
    /// back.
    pub fn contacts_once(&self) -> Result<u64> {
        if self.n == 0 {
            return Ok(0);
        }
        self.gpu.queue.write_buffer(&self.flag, 8, bytemuck::cast_slice(&[0u32]));
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_bind_group(0, &self.bind, &[]);
            pass.set_pipeline(&self.pipes[4]);
            let n = spread(self.n);
            pass.dispatch_workgroups(n.0, n.1, 1);
        }
        self.gpu.queue.submit([enc.finish()]);
        let mut count = 0;
        self.gpu.read_back_from(&self.flag, 8, &self.staging, 4, |raw| {
            count = u32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]) as u64
        })?;
        Ok(count)
    }

    /// Live contacts now (pairs counted at both grains, plus grain–wall contacts), from the
    /// committed history: for tests and diagnostics.
    pub fn contacts(&self) -> Result<usize> {
        if self.n == 0 {
            return Ok(0);
        }
        let raw = self.gpu.read_back(&self.keys, &self.staging, (self.n * (self.cap + 1) * 4) as u64)?;
        let words: Vec<u32> = raw.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
        Ok((0..self.n).map(|i| words[i * (self.cap + 1)] as usize).sum())
    }

    /// The energy books now (see [`DemBooks`] and the module docs): the state's parts from a
    /// read-back, the contact potential from a device pass at the current positions, the
    /// dissipated books accumulated per grain since `new`; every sum in f64 in grain order.
    pub fn books(&self) -> Result<DemBooks> {
        if self.n == 0 {
            return Ok(DemBooks::default());
        }
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            self.record_cells(&mut pass);
            pass.set_bind_group(0, &self.bind, &[]);
            pass.set_pipeline(&self.pipes[3]);
            let n = spread(self.n);
            pass.dispatch_workgroups(n.0, n.1, 1);
        }
        self.gpu.queue.submit([enc.finish()]);
        let (x, v, w) = self.read()?;
        let per = self.gpu.read_reals(self.precision, &self.books, &self.staging, 4 * self.n)?;
        let (d, n) = (self.dim, self.n);
        let ad = if d == 2 { 1 } else { 3 };
        let mut b = DemBooks::default();
        for i in 0..n {
            b.damping += per[i];
            b.friction += per[n + i];
            b.potential += per[2 * n + i];
            b.drag += per[3 * n + i];
            // A pinned grain holds no energy of motion or of gravity (the CPU's books).
            if self.pinned[i] {
                continue;
            }
            let (m, r) = (self.mass[i], self.radius[i]);
            b.kinetic += 0.5 * m * (0..d).map(|a| v[d * i + a] * v[d * i + a]).sum::<f64>();
            b.rotational += 0.5 * self.beta * m * r * r * (0..ad).map(|a| w[ad * i + a] * w[ad * i + a]).sum::<f64>();
            b.gravity -= m * (0..d).map(|a| self.p.gravity[a] * x[d * i + a]).sum::<f64>();
        }
        Ok(b)
    }

    /// The whole state as raw arrays ([`DemRaw`]): what a checkpoint needs.
    pub fn save_raw(&self) -> Result<DemRaw> {
        if self.n == 0 {
            return Ok(DemRaw::default());
        }
        let (x, v, omega) = self.read()?;
        let (p, n, k) = (self.precision, self.n, self.cap);
        let springs_len = n * k * strides(self.dim, self.p.rolling_friction > 0.0).0;
        use wgpu::BufferUsages as U;
        let bytes = (springs_len as u64 * p.bytes()).max((n * (k + 1) * 4) as u64);
        let staging = self.gpu.buffer("DEM checkpoint read-back", bytes, U::MAP_READ | U::COPY_DST)?;
        let raw = self.gpu.read_back(&self.keys, &staging, (n * (k + 1) * 4) as u64)?;
        let keys = raw.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
        let springs = self.gpu.read_reals(p, &self.vals, &staging, springs_len)?;
        let mut books = self.gpu.read_reals(p, &self.books, &self.staging, 2 * n)?;
        books.extend(self.gpu.read_reals_at(p, &self.books, (3 * n) as u64 * p.bytes(), &self.staging, n)?);
        let angle = if self.dim == 2 { self.angles()? } else { Vec::new() };
        Ok(DemRaw { x, v, omega, angle, keys, springs, books })
    }

    /// Loads what `save_raw` gave (of a `Dem` with the same grains, walls and capacity), as a
    /// run that continues (its books then go on as if it had never stopped).
    ///
    /// Errors: `Unsupported` for arrays of the wrong lengths, non-finite values, or a history
    /// entry naming no grain or wall.
    pub fn load_raw(&mut self, raw: &DemRaw) -> Result<()> {
        let (n, k, d) = (self.n, self.cap, self.dim);
        let ad = if d == 2 { 1 } else { 3 };
        let lens = [
            raw.x.len(),
            raw.v.len(),
            raw.omega.len(),
            raw.angle.len(),
            raw.keys.len(),
            raw.springs.len(),
            raw.books.len(),
        ];
        let sv = strides(d, self.p.rolling_friction > 0.0).0;
        let na = if d == 2 { n } else { 0 };
        if lens != [n * d, n * d, n * ad, na, n * (k + 1), n * k * sv, 3 * n] {
            return Err(invalid("raw", format_args!("array lengths {lens:?} do not fit {n} grains of capacity {k}")));
        }
        let reals =
            raw.x.iter().chain(&raw.v).chain(&raw.omega).chain(&raw.angle).chain(&raw.springs).chain(&raw.books);
        if !reals.into_iter().all(|u| u.is_finite()) {
            return Err(invalid("raw", "a non-finite value"));
        }
        let partners = (n + self.walls.len()) as u32;
        for i in 0..n {
            let c = raw.keys[i * (k + 1)] as usize;
            let row = &raw.keys[i * (k + 1) + 1..(i + 1) * (k + 1)];
            if c > k || row[..c].iter().any(|&j| j >= partners || j as usize == i) {
                return Err(invalid("raw", format_args!("grain {i}'s contact history names no grain or wall")));
            }
        }
        if n == 0 {
            return Ok(());
        }
        let p = self.precision;
        self.gpu.upload(p, &self.pos, &raw.x);
        let mut v = raw.v.clone();
        self.rest_pinned(&mut v);
        self.gpu.upload(p, &self.vel, &v);
        self.gpu.upload(p, &self.omega, &raw.omega);
        if d == 2 {
            self.gpu.upload_at(p, &self.omega, n as u64 * p.bytes(), &raw.angle);
        }
        self.gpu.queue.write_buffer(&self.keys, 0, bytemuck::cast_slice(&raw.keys));
        self.gpu.upload(p, &self.vals, &raw.springs);
        self.gpu.upload(p, &self.books, &raw.books[..2 * n]);
        self.gpu.upload_at(p, &self.books, (3 * n) as u64 * p.bytes(), &raw.books[2 * n..]);
        self.primed = true;
        self.gpu.wait()
    }

    /// Makes the next step book the contacts it finds that the history does not hold as a
    /// new system's first step does (`new`): their springs' energy was in the books already
    /// (the contact potential at these positions), as the CPU books them. For a state taken
    /// over from elsewhere (`load_raw` of the CPU's history at a scene's move to the device),
    /// not for a restart of this system's own run, whose next step must repeat it.
    pub fn book_found_contacts(&mut self) {
        self.primed = false;
    }

    /// The buffers a snapshot holds: the state, the contact history, the books.
    fn state_buffers(&self) -> [&wgpu::Buffer; 6] {
        [&self.pos, &self.vel, &self.omega, &self.keys, &self.vals, &self.books]
    }

    /// Keeps a copy of the whole state on the device (positions, velocities, ω and the 2D
    /// angles, the contact history and the books) for `restore`.
    pub fn snapshot(&mut self) -> Result<()> {
        if self.saved.is_none() {
            let mut bufs = Vec::new();
            for b in self.state_buffers() {
                bufs.push(self.gpu.buffer(
                    "DEM snapshot",
                    b.size(),
                    wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                )?);
            }
            self.saved = Some(Saved { bufs, primed: self.primed });
        }
        let primed = self.primed;
        self.saved.as_mut().unwrap().primed = primed;
        let saved = self.saved.as_ref().unwrap();
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        for (b, s) in self.state_buffers().into_iter().zip(&saved.bufs) {
            enc.copy_buffer_to_buffer(b, 0, s, 0, b.size());
        }
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait()
    }

    /// Returns to the last snapshot (nothing happens without one).
    pub fn restore(&mut self) -> Result<()> {
        let Some(saved) = self.saved.as_ref() else { return Ok(()) };
        self.primed = saved.primed;
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        for (b, s) in self.state_buffers().into_iter().zip(&saved.bufs) {
            enc.copy_buffer_to_buffer(s, 0, b, 0, b.size());
        }
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait()
    }
}
