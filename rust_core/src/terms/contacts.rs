//! Contacts between grains: the discrete element method (DEM) for discs (2D) and spheres (3D).
//!
//! Grains are the scene's particles with a `radius` attribute > 0; pinned particles are fixed
//! obstacles (pegs). Walls are half-spaces `{x : (x − p)·n ≥ 0}`.
//!
//! Pair (i, j) touches when d = |x_j − x_i| < r_i + r_j: normal n = (x_j − x_i)/d, overlap
//! δ = r_i + r_j − d, effective mass m* = 1/(1/m_i + 1/m_j), levers a_i = r_i − δ/2 (both
//! grains push at the same point, so the pair conserves angular momentum), contact-point
//! relative velocity v_c = v_i − v_j + (a_i ω_i + a_j ω_j) × n, v_n = v_c·n (> 0 approaching).
//! - Normal force (spring–dashpot, never attractive): linear f_n = k_n δ + γ_n v_n with
//!   γ_n = 2ζ√(k_n m*); or Hertz f_n = k_n δ^{3/2} + γ_n v_n with γ_n = 2ζ√(k_n m*) δ^{1/4}
//!   (Tsuji, Tanaka & Ishida, Powder Technol. 71 (1992) 239, eq. 9: the restitution then does
//!   not depend on the impact speed). f_n < 0 is set to 0.
//! - The damping ratio ζ is chosen so that a head-on collision returns exactly the restitution e
//!   of the model as simulated, with the force clamped at 0 (the grains separate when the force
//!   vanishes, before the overlap does): for the linear law the closed form of
//!   Schwager & Pöschel, Phys. Rev. E 78 (2008) 051304, derived again in [`restitution_linear`];
//!   for Hertz the dimensionless collision integrated numerically ([`restitution_hertz`]);
//!   both inverted by bisection.
//! - Tangential force: Cundall & Strack, Géotechnique 29 (1979) 47, a tangential spring ξ per
//!   contact (zero when the contact forms, rotated into the current tangent plane each step)
//!   with f_t = −k_t ξ − γ_t v_t, capped by Coulomb's law |f_t| ≤ μ f_n (the spring then slips to
//!   the cap). k_t = ratio·k_n (2/7 by default: equal normal and tangential periods for spheres,
//!   Silbert et al., Phys. Rev. E 64 (2001) 051302); for Hertz k_t = ratio·(3/2)k_n√δ, the
//!   normal contact stiffness (Mindlin's no-slip tangential stiffness in the same ratio).
//! - Rolling: the tangential force turns each grain, τ_i = a_i n × f_t, on an angular velocity
//!   per particle with moment of inertia I = β m r² (disc β = ½, sphere β = ⅖).
//!
//! Stepping: semi-implicit Euler over the whole state (the usual DEM scheme). The forces and
//! torques are taken at the step's start from (x, v, ω, ξ); the integrator updates v then x;
//! `end_step` updates ω then each contact's spring with the NEW velocities,
//! ξ ← ξ_capped + dt·v_t(new): the spring follows the contact point as the positions do, so a
//! resting contact does not pump energy. The step is chosen by `max_dt`: a 50th of the contact
//! duration (the measured restitution then agrees with e to well under 1 %).
//!
//! Determinism and conservation: each particle gathers its own contacts (found through a cell
//! list of side 2 r_max, sorted by partner, summed in that order), so results are bit-identical
//! for any thread count; both sides of a pair compute exactly negated forces (x_i − x_j is
//! exactly −(x_j − x_i) in IEEE arithmetic, and every other step is symmetric), so momentum is
//! conserved to round-off. Each side keeps its own copy of the pair's spring (exact negatives).
//!
//! Energy books: kinetic energy includes rotation (½Iω²); potential: the springs' energy,
//! ½k_n δ² (Hertz ⅖k_n δ^{5/2}) + ½k_t|ξ|²; dissipated: "normal damping" and "friction". Each
//! is booked per contact and step as the work its force drew from the motion, the mean of its
//! power at the step's two ends (semi-implicit Euler changes the kinetic energy by exactly
//! F·(v + v')/2 dt), less what its spring gained; so the dashpots, the clamp letting go of an
//! overlap, slipping, and a tangential spring dropped when its contact ends are all in the
//! books, which balance to the scheme's first-order error.
use super::registry::{Context, Params};
use super::{Term, Write};
use crate::error::{invalid, Result};
use crate::neighbors::CellList;
use crate::par::{self, CHUNK};
use crate::state::Model;
use crate::vector::{Real, Vector};

/// Steps per contact duration (`max_dt`).
const STEPS_PER_CONTACT: Real = 50.0;

/// The normal force law.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    Linear,
    Hertz,
}

/// A half-space wall with its own contact coefficients.
#[derive(Clone, Copy, Debug)]
pub struct Wall<V> {
    pub point: V,
    /// Unit normal into the allowed side.
    pub normal: V,
    pub zeta: Real,
    pub friction: Real,
}

/// One side's record of a contact: the partner (a particle index, or n + wall index), the
/// tangential spring ξ (m) and the energy it stores (J); while a step is in progress also the
/// tangential force the step applies (N), for the books.
#[derive(Clone, Copy, Debug, Default)]
struct Entry<V> {
    partner: u32,
    xi: V,
    u: Real,
    ft: V,
    /// The normal force of the step (N), the normal spring's energy at its start (J), and the
    /// power both forces drew from the motion at the step's start (W).
    fn_: Real,
    un: Real,
    wn0: Real,
    wt0: Real,
}

/// The contacts of one chunk of `CHUNK` particles: particle s + k owns
/// `entries[start[k]..start[k + 1]]`, sorted by partner.
#[derive(Clone, Debug, Default)]
struct Chunk<V> {
    start: Vec<u32>,
    entries: Vec<Entry<V>>,
}

/// What one chunk's evaluation sums: the energy of tangential springs whose contact ended
/// (J), the largest overlap (m) and the contacts counted once (pairs halved, walls whole).
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    broken: Real,
    max_overlap: Real,
    half_pairs: u64,
    walls: u64,
}

impl Sums {
    fn add(self, o: Sums) -> Sums {
        Sums {
            broken: self.broken + o.broken,
            max_overlap: self.max_overlap.max(o.max_overlap),
            half_pairs: self.half_pairs + o.half_pairs,
            walls: self.walls + o.walls,
        }
    }
}

/// The material of the grains.
#[derive(Clone, Copy, Debug)]
pub struct Material {
    pub law: Law,
    /// k_n: N/m (linear) or N/m^{3/2} (Hertz).
    pub stiffness: Real,
    /// k_t / k_n (linear), or k_t over the normal contact stiffness (Hertz).
    pub tangential_ratio: Real,
    pub restitution: Real,
    pub zeta: Real,
    pub friction: Real,
    /// β in I = β m r².
    pub inertia_factor: Real,
}

/// Everything one pair evaluation returns (from side i).
struct PairOut<V> {
    force: V,
    ft: V,
    xi: V,
    fn_: Real,
    /// Power the normal and tangential forces draw from the relative motion now (W).
    wn0: Real,
    wt0: Real,
}

impl Material {
    /// Normal force magnitude (clamped at 0) and its elastic part, at overlap `d` and approach
    /// speed `vn`, for effective mass `m` and damping ratio `zeta`.
    ///
    /// The dashpot takes the approach speed at the middle of the step, v_n − ½dt·f/m*, with f
    /// this contact's force (solved in closed form, Crank–Nicolson for the pair): semi-implicit
    /// Euler's velocities lag half a step behind its positions, and a dashpot fed the lagged
    /// speed damps too much to first order (e = 0.1 came out 5.7 % low at a 50th of the
    /// contact; now 0.2 %).
    #[inline(always)]
    fn normal(&self, d: Real, vn: Real, m: Real, zeta: Real, sqrt_km: Real, dt: Real) -> (Real, Real) {
        let (el, g) = match self.law {
            Law::Linear => (self.stiffness * d, 2.0 * zeta * sqrt_km),
            Law::Hertz => {
                let sd = d.sqrt();
                (self.stiffness * d * sd, 2.0 * zeta * sqrt_km * sd.sqrt())
            }
        };
        let h = 0.5 * dt / m;
        let v_mid = (vn - h * el) / (1.0 + h * g);
        ((el + g * v_mid).max(0.0), el)
    }

    /// Tangential spring stiffness k_t at overlap `d`.
    #[inline(always)]
    fn kt(&self, d: Real) -> Real {
        match self.law {
            Law::Linear => self.tangential_ratio * self.stiffness,
            Law::Hertz => self.tangential_ratio * 1.5 * self.stiffness * d.sqrt(),
        }
    }

    /// Elastic potential of the normal spring at overlap `d`, J.
    fn normal_energy(&self, d: Real) -> Real {
        match self.law {
            Law::Linear => 0.5 * self.stiffness * d * d,
            Law::Hertz => 0.4 * self.stiffness * d * d * d.sqrt(),
        }
    }

    /// One contact seen from side i: normal `n` (towards the partner), overlap `d`,
    /// contact-point relative velocity `vc`, effective mass `m` (`sqrt_km` = √(k_n m)), the
    /// spring `xi` as stored;
    /// `dt`: the step; `new`: whether the contact formed during the last step.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn pair<V: Vector>(
        &self,
        n: V,
        d: Real,
        vc: V,
        m: Real,
        sqrt_km: Real,
        xi: V,
        zeta: Real,
        mu: Real,
        dt: Real,
        new: bool,
    ) -> PairOut<V> {
        let vn = vc.dot(n);
        let (mut fn_, _) = self.normal(d, vn, m, zeta, sqrt_km, dt);
        let onset = if new { dt } else { 0.0 };
        if onset > 0.0 && vn > 0.0 && d <= 1.5 * vn * onset {
            // A contact that began τ = δ/v_n before this step. Semi-implicit Euler is leapfrog:
            // this step's kick f(x)·dt stands for the force over [t − dt/2, t + dt/2], but the
            // contact pushed over [t − τ, t + dt/2]. Add the difference, exact for the force
            // law along δ = v_n u (u: time in contact), so that where in a step grains first
            // touch no longer matters: uncorrected, e = 0.1 came out 2–3 % off at random.
            let tau = (d / vn).min(onset);
            let t = tau + 0.5 * onset;
            let c = 2.0 * zeta * sqrt_km;
            let k = self.stiffness;
            let (el_j, damp_j) = match self.law {
                // ∫₀ᵀ (k v u + c v) du − (k v τ + c v) dt
                Law::Linear => (k * vn * (0.5 * t * t - tau * onset), c * vn * (t - onset)),
                // ∫₀ᵀ (k (v u)^{3/2} + c (v u)^{1/4} v) du − f(τ) dt
                Law::Hertz => {
                    let v15 = vn * vn.sqrt();
                    let v125 = vn * vn.sqrt().sqrt();
                    (
                        k * v15 * (t * t * t.sqrt() / 2.5 - tau * tau.sqrt() * onset),
                        c * v125 * (t * t.sqrt().sqrt() / 1.25 - tau.sqrt().sqrt() * onset),
                    )
                }
            };
            fn_ = (fn_ + (el_j + damp_j) / onset).max(0.0);
        }
        let vt = vc - n * vn;
        let kt = self.kt(d);
        let mut xi_p = xi;
        let xn = xi.dot(n);
        if xn != 0.0 {
            // Rotate the spring into the tangent plane, keeping its length.
            xi_p = xi - n * xn;
            let (l0, l1) = (xi.length_squared(), xi_p.length_squared());
            if l1 > 0.0 {
                xi_p = xi_p * (l0 / l1).sqrt();
            }
        }
        // γ_t = 2ζ√(k_t m*), from √(k_n m*).
        let gt = 2.0
            * zeta
            * sqrt_km
            * match self.law {
                Law::Linear => self.tangential_ratio.sqrt(),
                Law::Hertz => (1.5 * self.tangential_ratio).sqrt() * d.sqrt().sqrt(),
            };
        let mut ft = xi_p * (-kt) - vt * gt;
        let cap = mu * fn_;
        let f2 = ft.length_squared();
        let mut xi_c = xi_p;
        if f2 > cap * cap {
            ft = ft * (cap / f2.sqrt());
            xi_c = if kt > 0.0 { (ft + vt * gt) * (-1.0 / kt) } else { V::ZERO };
        }
        PairOut { force: ft - n * fn_, ft, xi: xi_c, fn_, wn0: fn_ * vn, wt0: -ft.dot(vt) }
    }
}

/// The contact term (see the module docs).
pub struct Contacts<V: Vector> {
    name: String,
    pub material: Material,
    pub walls: Vec<Wall<V>>,
    /// Angular velocity of each particle, rad/s (2D: about z).
    omega: Vec<V::Axial>,
    /// Rotation angle of each particle (2D only, rad; 0 in 3D).
    angle: Vec<Real>,
    /// Torques of the last evaluation, N·m.
    torque: Vec<V::Axial>,
    /// The springs as committed at the end of the last step, and those the last evaluation
    /// produced (capped, not yet advanced).
    hist: Vec<Chunk<V>>,
    pend: Vec<Chunk<V>>,
    /// The last evaluation's sums (booked by `end_step`).
    last: Sums,
    /// Energy dissipated so far by normal damping and by friction, J.
    dissipated: [Real; 2],
    cells: Option<CellList>,
    /// The step in progress (s), told by `begin_step`.
    dt: Real,
    /// Whether forces were evaluated since the last step ended (only then may `end_step` commit).
    evaluated: bool,
}

fn build<V: Vector>(name: String, mut p: Params, ctx: &Context) -> Result<Box<dyn Term<V>>> {
    let law = match p.text("law")? {
        "linear" => Law::Linear,
        "hertz" => Law::Hertz,
        other => return Err(invalid("law", format!("unknown law {other:?}; valid: linear, hertz"))),
    };
    let positive = |key: &str, v: Real| -> Result<Real> {
        if v > 0.0 {
            Ok(v)
        } else {
            Err(invalid(key, format!("{v} must be > 0")))
        }
    };
    let stiffness = positive("stiffness", p.number("stiffness")?)?;
    let tangential_ratio = p.number("tangential_ratio")?;
    if tangential_ratio < 0.0 {
        return Err(invalid("tangential_ratio", format!("{tangential_ratio} must be >= 0")));
    }
    let restitution = restitution_arg("restitution", p.number("restitution")?)?;
    let friction = friction_arg("friction", p.number("friction")?)?;
    let default_beta = if V::DIM == 2 { 0.5 } else { 0.4 };
    let inertia_factor = if p.has("inertia_factor") { p.number("inertia_factor")? } else { default_beta };
    let inertia_factor = positive("inertia_factor", inertia_factor)?;
    let zeta = damping_ratio(law, restitution);
    let material = Material { law, stiffness, tangential_ratio, restitution, zeta, friction, inertia_factor };
    let points: Vec<V> = p.take_vectors("wall_points")?;
    let normals: Vec<V> = p.take_vectors("wall_normals")?;
    let e = p.take_floats("wall_restitution")?;
    let mu = p.take_floats("wall_friction")?;
    let w = points.len();
    if normals.len() != w || e.len() != w || mu.len() != w {
        return Err(invalid("walls", "points, normals, restitution and friction must have one entry per wall"));
    }
    let mut walls = Vec::with_capacity(w);
    for k in 0..w {
        let l2 = normals[k].length_squared();
        if !(l2.is_finite() && l2 > 0.0 && points[k].is_finite()) {
            return Err(invalid("walls", format!("wall {k}: the point must be finite and the normal non-zero")));
        }
        let e = restitution_arg("walls", e[k])?;
        walls.push(Wall {
            point: points[k],
            normal: normals[k] / l2.sqrt(),
            zeta: damping_ratio(law, e),
            friction: friction_arg("walls", mu[k])?,
        });
    }
    if u32::try_from(ctx.n_particles + w).is_err() {
        return Err(invalid("walls", "too many particles and walls for 32-bit contact indices"));
    }
    Ok(Box::new(Contacts::new(name, material, walls)))
}
crate::register_term!("contacts", build);

fn restitution_arg(key: &str, e: Real) -> Result<Real> {
    if !(e > 0.0 && e <= 1.0) {
        return Err(invalid(
            key,
            format!("restitution {e} must be in (0, 1] (a dashpot that never pulls cannot stop a grain dead; use e.g. 0.05)"),
        ));
    }
    Ok(e)
}

fn friction_arg(key: &str, mu: Real) -> Result<Real> {
    if !(mu.is_finite() && mu >= 0.0) {
        return Err(invalid(key, format!("friction {mu} must be finite and >= 0")));
    }
    Ok(mu)
}

/// Restitution of a head-on collision under the linear spring–dashpot with damping ratio ζ
/// whose force is clamped at 0. The overlap obeys δ'' + 2ζω₀δ' + ω₀²δ = 0 from δ = 0,
/// δ' = v₀; the grains separate when the force kδ + γδ' (∝ −δ'') first vanishes, at
/// ωt = atan2(2ζw, ζ² − w²) with w = √(1 − ζ²) (hyperbolic for ζ > 1), and e = |δ'|/v₀ there
/// (Schwager & Pöschel, Phys. Rev. E 78 (2008) 051304, eqs. 12–14).
pub fn restitution_linear(zeta: Real) -> Real {
    if zeta <= 0.0 {
        return 1.0;
    }
    if (zeta - 1.0).abs() < 1e-9 {
        return (-2.0f64).exp();
    }
    if zeta < 1.0 {
        let w = (1.0 - zeta * zeta).sqrt();
        let phi = (2.0 * zeta * w).atan2(zeta * zeta - w * w);
        (-zeta * phi / w).exp() * (phi.cos() - zeta / w * phi.sin()).abs()
    } else {
        let k = (zeta * zeta - 1.0).sqrt();
        let psi = (2.0 * zeta * k / (zeta * zeta + k * k)).atanh();
        (-zeta * psi / k).exp() * (psi.cosh() - zeta / k * psi.sinh()).abs()
    }
}

/// Restitution of a head-on collision under the Hertz law with Tsuji's damping and damping
/// ratio ζ, force clamped at 0: the dimensionless collision u'' = −(u^{3/2} + 2ζ u^{1/4} u'),
/// u(0) = 0, u'(0) = 1 (the impact speed scales out), integrated by RK4 until the force
/// vanishes (interpolated linearly within the last step); e = |u'| then.
pub fn restitution_hertz(zeta: Real) -> Real {
    let acc = |u: Real, w: Real| -> Real {
        let u = u.max(0.0);
        -(u * u.sqrt() + 2.0 * zeta * u.sqrt().sqrt() * w)
    };
    let h = 2e-4;
    let (mut u, mut w) = (0.0, 1.0);
    let mut f_prev = 0.0;
    for step in 0..200_000 {
        let (k1u, k1w) = (w, acc(u, w));
        let (k2u, k2w) = (w + 0.5 * h * k1w, acc(u + 0.5 * h * k1u, w + 0.5 * h * k1w));
        let (k3u, k3w) = (w + 0.5 * h * k2w, acc(u + 0.5 * h * k2u, w + 0.5 * h * k2w));
        let (k4u, k4w) = (w + h * k3w, acc(u + h * k3u, w + h * k3w));
        let (u1, w1) =
            (u + h / 6.0 * (k1u + 2.0 * k2u + 2.0 * k3u + k4u), w + h / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w));
        let f1 = -acc(u1, w1);
        if step > 0 && (f1 <= 0.0 || u1 <= 0.0) {
            // Linear interpolation of the velocity to the force's zero.
            let s = if f1 < f_prev { (f_prev / (f_prev - f1)).clamp(0.0, 1.0) } else { 1.0 };
            return (w + s * (w1 - w)).abs().min(1.0);
        }
        (u, w, f_prev) = (u1, w1, f1);
    }
    w.abs().min(1.0)
}

/// The damping ratio ζ ≥ 0 whose clamped collision returns restitution `e` in (0, 1]
/// (bisection on the monotone map; e = 1 gives 0).
pub fn damping_ratio(law: Law, e: Real) -> Real {
    if e >= 1.0 {
        return 0.0;
    }
    let map = |z: Real| match law {
        Law::Linear => restitution_linear(z),
        Law::Hertz => restitution_hertz(z),
    };
    let (mut lo, mut hi) = (0.0, 1.0);
    while map(hi) > e && hi < 1e6 {
        (lo, hi) = (hi, 2.0 * hi);
    }
    let iters = if law == Law::Linear { 200 } else { 48 };
    for _ in 0..iters {
        let mid = 0.5 * (lo + hi);
        if map(mid) > e {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-15 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// Axial × vector: ω × n (in 2D ω is along z).
#[inline(always)]
fn spin<V: Vector>(w: V::Axial, n: V) -> V {
    -n.cross_axial(w)
}

/// The axial vector n × f.
#[inline(always)]
fn moment<V: Vector>(n: V, f: V) -> V::Axial {
    let c = n.cross3(f);
    V::axial_from_slice(&c[3 - V::AXIAL_DIM..])
}

impl<V: Vector> Contacts<V> {
    pub fn new(name: String, material: Material, walls: Vec<Wall<V>>) -> Self {
        Self {
            name,
            material,
            walls,
            omega: Vec::new(),
            angle: Vec::new(),
            torque: Vec::new(),
            hist: Vec::new(),
            pend: Vec::new(),
            last: Sums::default(),
            dissipated: [0.0; 2],
            cells: None,
            dt: 0.0,
            evaluated: false,
        }
    }

    /// Sizes the per-particle state for `n` particles (new particles at rest, no contacts).
    fn fit(&mut self, n: usize) {
        if self.omega.len() != n {
            self.omega.resize(n, V::AXIAL_ZERO);
            self.angle.resize(n, 0.0);
            self.torque.resize(n, V::AXIAL_ZERO);
        }
        let chunks = n.div_ceil(CHUNK);
        if self.hist.len() != chunks || self.hist.iter().enumerate().any(|(c, h)| h.start.len() != chunk_len(n, c) + 1)
        {
            self.hist =
                (0..chunks).map(|c| Chunk { start: vec![0; chunk_len(n, c) + 1], entries: Vec::new() }).collect();
            self.pend = self.hist.clone();
        }
    }

    /// The committed contacts of particle i.
    #[inline(always)]
    fn committed(&self, i: usize) -> &[Entry<V>] {
        let h = &self.hist[i / CHUNK];
        let k = i % CHUNK;
        &h.entries[h.start[k] as usize..h.start[k + 1] as usize]
    }

    /// Contacts counted once at the last evaluation (pairs + wall contacts).
    pub fn count(&self) -> u64 {
        self.last.half_pairs / 2 + self.last.walls
    }

    fn inertia(&self, m: Real, r: Real) -> Real {
        self.material.inertia_factor * m * r * r
    }
}

fn chunk_len(n: usize, c: usize) -> usize {
    CHUNK.min(n - c * CHUNK)
}

/// Reads the radius attribute (zeros if unset).
fn radii(model: &Model) -> Option<&[Real]> {
    model.attribute("radius")
}

impl<V: Vector> Term<V> for Contacts<V> {
    fn name(&self) -> &str {
        &self.name
    }

    fn add_forces(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let n = x.len();
        self.fit(n);
        self.evaluated = true;
        let Some(r) = radii(model) else {
            par::chunks1(f, |_, f| f.iter_mut().for_each(|fi| write.put(fi, V::ZERO)));
            self.torque.iter_mut().for_each(|t| *t = V::AXIAL_ZERO);
            self.pend.iter_mut().for_each(|c| {
                c.entries.clear();
                c.start.iter_mut().for_each(|s| *s = 0);
            });
            self.last = Sums::default();
            return 0.0;
        };
        let r_max = r.iter().fold(0.0, |a: Real, &b| a.max(b));
        let cell = 2.0 * r_max;
        if r_max > 0.0 && self.cells.as_ref().is_none_or(|c| c.cell_size() != cell) {
            self.cells = CellList::new(cell, V::DIM).ok();
        }
        if let Some(c) = self.cells.as_mut() {
            c.build(x);
        }
        let cells = self.cells.as_ref();
        let (mat, walls) = (&self.material, &self.walls);
        let (omega, hist, dt) = (&self.omega, &self.hist, self.dt);
        // Equal masses (the usual case): one √(k m*) for every pair and one for the walls.
        let m0 = (0..n).find(|&i| model.inv_mass[i] != 0.0 && r[i] > 0.0).map(|i| model.mass[i]);
        let uniform = m0.filter(|&m0| (0..n).all(|i| model.inv_mass[i] == 0.0 || r[i] <= 0.0 || model.mass[i] == m0));
        let kn = self.material.stiffness;
        let pair_root = uniform.map(|m0| ((kn * m0 * 0.5).sqrt(), (kn * m0).sqrt()));
        let nw = n as u32;
        // Each side books its share of a pair: half when both are free (the other side books
        // the rest), all of it against a pinned grain (which computes nothing) or a wall.
        let share = |j: u32| if j < nw && model.inv_mass[j as usize] != 0.0 { 0.5 } else { 1.0 };
        let mut pend = std::mem::take(&mut self.pend);
        let body = |c: usize, f: &mut [V], tq: &mut [V::Axial], out: &mut Chunk<V>| -> Sums {
            let s0 = c * CHUNK;
            let mut sums = Sums::default();
            out.entries.clear();
            out.start.clear();
            out.start.push(0);
            let mut found: Vec<(u32, V, Real)> = Vec::with_capacity(16);
            for (k, (fi, ti)) in f.iter_mut().zip(tq.iter_mut()).enumerate() {
                let i = s0 + k;
                let ri = r[i];
                if model.inv_mass[i] == 0.0 || ri <= 0.0 {
                    write.put(fi, V::ZERO);
                    *ti = V::AXIAL_ZERO;
                    out.start.push(out.entries.len() as u32);
                    continue;
                }
                found.clear();
                if let Some(cl) = cells {
                    for range in cl.query(cl.cell_of(x[i])).iter() {
                        for &j in &cl.order[range] {
                            let j = j as usize;
                            let rj = r[j];
                            if j == i || rj <= 0.0 {
                                continue;
                            }
                            let dx = x[j] - x[i];
                            let d2 = dx.length_squared();
                            let s = ri + rj;
                            if d2 < s * s && d2 > 0.0 {
                                let d = d2.sqrt();
                                found.push((j as u32, dx / d, s - d));
                            }
                        }
                    }
                }
                for (w, wall) in walls.iter().enumerate() {
                    let s = (x[i] - wall.point).dot(wall.normal);
                    if s < ri {
                        found.push((nw + w as u32, -wall.normal, ri - s));
                    }
                }
                found.sort_unstable_by_key(|e| e.0);
                let old = {
                    let h = &hist[c];
                    &h.entries[h.start[k] as usize..h.start[k + 1] as usize]
                };
                let mut o = 0;
                let mut force = V::ZERO;
                let mut torque = V::AXIAL_ZERO;
                let mi = model.mass[i];
                for &(j, nrm, d) in &found {
                    while o < old.len() && old[o].partner < j {
                        o += 1;
                    }
                    let known = o < old.len() && old[o].partner == j;
                    let (xi, u_old) = if known { (old[o].xi, old[o].u) } else { (V::ZERO, 0.0) };
                    if known {
                        sums.broken -= share(j) * u_old;
                    }
                    let ai = ri - 0.5 * d;
                    let (out_pair, half) = if j < nw {
                        let j = j as usize;
                        let aj = r[j] - 0.5 * d;
                        let m = 1.0 / (model.inv_mass[i] + model.inv_mass[j]);
                        let root = match pair_root {
                            Some((p, w)) => {
                                if model.inv_mass[j] != 0.0 {
                                    p
                                } else {
                                    w
                                }
                            }
                            None => (kn * m).sqrt(),
                        };
                        let vc = v[i] - v[j] + spin::<V>(omega[i] * ai + omega[j] * aj, nrm);
                        (mat.pair(nrm, d, vc, m, root, xi, mat.zeta, mat.friction, dt, !known), share(j as u32))
                    } else {
                        let wall = &walls[(j - nw) as usize];
                        let vc = v[i] + spin::<V>(omega[i] * ai, nrm);
                        let root = pair_root.map_or_else(|| (kn * mi).sqrt(), |(_, w)| w);
                        (mat.pair(nrm, d, vc, mi, root, xi, wall.zeta, wall.friction, dt, !known), 1.0)
                    };
                    force += out_pair.force;
                    torque = torque + moment(nrm, out_pair.ft) * ai;
                    sums.max_overlap = sums.max_overlap.max(d);
                    if j < nw {
                        // Half a pair from each free side; a pinned partner has no side.
                        sums.half_pairs += if half == 0.5 { 1 } else { 2 };
                    } else {
                        sums.walls += 1;
                    }
                    out.entries.push(Entry {
                        partner: j,
                        xi: out_pair.xi,
                        u: u_old,
                        ft: out_pair.ft,
                        fn_: out_pair.fn_,
                        un: mat.normal_energy(d),
                        wn0: out_pair.wn0,
                        wt0: out_pair.wt0,
                    });
                }
                // Springs of contacts that ended release their energy (the matched ones were
                // subtracted above).
                sums.broken += old.iter().map(|e| share(e.partner) * e.u).sum::<Real>();
                write.put(fi, force);
                *ti = torque;
                out.start.push(out.entries.len() as u32);
            }
            sums
        };
        let mut torque = std::mem::take(&mut self.torque);
        let sums = {
            use rayon::prelude::*;
            let run = || -> Vec<Sums> {
                f.par_chunks_mut(CHUNK)
                    .zip(torque.par_chunks_mut(CHUNK))
                    .zip(pend.par_iter_mut())
                    .enumerate()
                    .map(|(c, ((f, t), o))| body(c, f, t, o))
                    .collect()
            };
            match par::fork_if(n, run) {
                Some(s) => s,
                None => f
                    .chunks_mut(CHUNK)
                    .zip(torque.chunks_mut(CHUNK))
                    .zip(pend.iter_mut())
                    .enumerate()
                    .map(|(c, ((f, t), o))| body(c, f, t, o))
                    .collect(),
            }
        };
        self.torque = torque;
        self.pend = pend;
        self.last = sums.into_iter().fold(Sums::default(), Sums::add);
        0.0
    }

    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        let Some(r) = radii(model) else { return Some(0.0) };
        let n = x.len();
        let mat = &self.material;
        let mut u = 0.0;
        // Normal springs at x (a fresh search: the stored contacts are those of the step's start).
        let r_max = r.iter().fold(0.0, |a: Real, &b| a.max(b));
        if r_max > 0.0 {
            if let Ok(mut cl) = CellList::new(2.0 * r_max, V::DIM) {
                cl.build(x);
                for i in 0..n {
                    if r[i] <= 0.0 {
                        continue;
                    }
                    for range in cl.query(cl.cell_of(x[i])).iter() {
                        for &j in &cl.order[range] {
                            let j = j as usize;
                            if j <= i || r[j] <= 0.0 || (model.inv_mass[i] == 0.0 && model.inv_mass[j] == 0.0) {
                                continue;
                            }
                            let s = r[i] + r[j];
                            let d2 = (x[j] - x[i]).length_squared();
                            if d2 < s * s {
                                u += mat.normal_energy(s - d2.sqrt());
                            }
                        }
                    }
                }
            }
        }
        for i in 0..n {
            if r[i] <= 0.0 || model.inv_mass[i] == 0.0 {
                continue;
            }
            for wall in &self.walls {
                let d = r[i] - (x[i] - wall.point).dot(wall.normal);
                if d > 0.0 {
                    u += mat.normal_energy(d);
                }
            }
        }
        // Tangential springs as stored (each pair's spring is held by both sides: half each).
        if self.hist.len() == n.div_ceil(CHUNK) {
            for i in 0..n {
                u += self
                    .committed(i)
                    .iter()
                    .map(|e| if (e.partner as usize) < n && model.inv_mass[e.partner as usize] != 0.0 { 0.5 } else { 1.0 } * e.u)
                    .sum::<Real>();
            }
        }
        Some(u)
    }

    fn dissipative(&self) -> bool {
        // Books its own dissipation (two ledgers, at the step's end): see `own_books`.
        false
    }
    fn velocity_dependent(&self) -> bool {
        true
    }

    fn max_dt(&self, _x: &[V], v: &[V], model: &Model, g: Real) -> Option<Real> {
        let r = radii(model)?;
        let (mut m_min, mut r_min) = (Real::INFINITY, Real::INFINITY);
        let mut v_max: Real = 0.0;
        for i in 0..r.len() {
            if r[i] > 0.0 && model.inv_mass[i] != 0.0 {
                m_min = m_min.min(model.mass[i]);
                r_min = r_min.min(r[i]);
                v_max = v_max.max(v[i].length_squared());
            }
        }
        if !m_min.is_finite() {
            return None;
        }
        let mat = &self.material;
        // Lightest pair: m* = m/2; the tangential mode also turns both grains:
        // 1/m*_t = 2/m + 2a²/I = (2/m)(1 + 1/β).
        let m_eff = 0.5 * m_min;
        let tangential = mat.tangential_ratio * (2.0 / m_min) * (1.0 + 1.0 / mat.inertia_factor);
        let duration = match mat.law {
            Law::Linear => {
                let w2 = (mat.stiffness / m_eff).max(tangential * mat.stiffness);
                std::f64::consts::PI / w2.sqrt()
            }
            Law::Hertz => {
                // Hertz contact duration 3.21 (m*/k)^{2/5} v^{-1/5} (Johnson, Contact Mechanics,
                // eq. 11.24, in terms of k), at twice the fastest grain's speed or the speed of a
                // fall through one radius; and the period at the deepest overlap seen.
                let vr = (2.0 * v_max.sqrt()).max((2.0 * g * r_min).sqrt()).max(1e-12);
                let t_impact = 3.21 * (m_eff / mat.stiffness).powf(0.4) * vr.powf(-0.2);
                let k_deep = 1.5 * mat.stiffness * self.last.max_overlap.sqrt();
                let w2 = k_deep / m_eff * (1.0 + mat.tangential_ratio * (1.0 + 1.0 / mat.inertia_factor));
                if w2 > 0.0 {
                    t_impact.min(std::f64::consts::PI / w2.sqrt())
                } else {
                    t_impact
                }
            }
        };
        Some(duration / STEPS_PER_CONTACT)
    }

    fn fields(&self, _x: &[V], model: &Model) -> Vec<(&'static str, std::ops::Range<usize>, Vec<Real>)> {
        let n = self.omega.len().min(model.len());
        let mut out = Vec::new();
        if V::DIM == 2 {
            out.push(("angular_velocity", 0..n, self.omega[..n].iter().map(|w| axial_z::<V>(*w)).collect()));
            out.push(("angle", 0..n, self.angle[..n].to_vec()));
        } else {
            for (k, name) in ["angular_velocity_x", "angular_velocity_y", "angular_velocity_z"].into_iter().enumerate()
            {
                out.push((name, 0..n, self.omega[..n].iter().map(|w| axial_comp::<V>(*w, k)).collect()));
            }
        }
        if self.hist.len() == n.div_ceil(CHUNK) {
            let coordination = (0..n).map(|i| self.committed(i).len() as Real).collect();
            out.push(("coordination", 0..n, coordination));
        }
        out
    }

    fn reserve(&mut self, n: usize) -> Result<()> {
        self.fit(n);
        if let Some(c) = self.cells.as_mut() {
            c.reserve(n, "step")?;
        }
        Ok(())
    }

    fn begin_step(&mut self, dt: Real) {
        self.dt = dt;
    }

    fn end_step(&mut self, x: &[V], v: &[V], model: &Model, dt: Real) {
        if !self.evaluated {
            return;
        }
        self.evaluated = false;
        let n = x.len();
        let Some(r) = radii(model) else { return };
        let beta = self.material.inertia_factor;
        // ω ← ω + dt τ/I, then the angle with the new ω (semi-implicit, like v and x).
        let torque = &self.torque;
        par::chunks2(&mut self.omega, &mut self.angle, |s, w, a| {
            for k in 0..w.len() {
                let i = s + k;
                if model.inv_mass[i] == 0.0 || r[i] <= 0.0 {
                    continue;
                }
                let inv_i = 1.0 / (beta * model.mass[i] * r[i] * r[i]);
                w[k] = w[k] + torque[i] * (dt * inv_i);
                if V::DIM == 2 {
                    a[k] += dt * axial_z::<V>(w[k]);
                }
            }
        });
        // Each surviving spring follows the contact point with the new velocities, and the
        // books take what the tangential force did over the step (−f_t·v_t dt, the particles'
        // work against it) less what the spring now stores more: exactly the energy friction
        // removed, slipping and the tangential dashpot together.
        let (omega, walls, mat) = (&self.omega, &self.walls, &self.material);
        let nw = n as u32;
        let advance = |c: usize, out: &mut Chunk<V>| -> (Real, Real) {
            let s0 = c * CHUNK;
            let (mut lost, mut lost_n) = (0.0, 0.0);
            for k in 0..out.start.len().saturating_sub(1) {
                let i = s0 + k;
                let (a, b) = (out.start[k] as usize, out.start[k + 1] as usize);
                for e in &mut out.entries[a..b] {
                    let (nrm, d, vc, mu, half) = if e.partner < nw {
                        let j = e.partner as usize;
                        let dx = x[j] - x[i];
                        let dist = dx.length_squared().sqrt();
                        if dist == 0.0 {
                            continue;
                        }
                        let nrm = dx / dist;
                        let d = r[i] + r[j] - dist;
                        let w = omega[i] * (r[i] - 0.5 * d) + omega[j] * (r[j] - 0.5 * d);
                        let half = if model.inv_mass[j] != 0.0 { 0.5 } else { 1.0 };
                        (nrm, d, v[i] - v[j] + spin::<V>(w, nrm), mat.friction, half)
                    } else {
                        let wall = &walls[(e.partner - nw) as usize];
                        let d = r[i] - (x[i] - wall.point).dot(wall.normal);
                        let nrm = -wall.normal;
                        (nrm, d, v[i] + spin::<V>(omega[i] * (r[i] - 0.5 * d), nrm), wall.friction, 1.0)
                    };
                    let vt = vc - nrm * vc.dot(nrm);
                    // Frictionless contacts hold no spring (it could never push).
                    e.xi = if mu > 0.0 { e.xi + vt * dt } else { V::ZERO };
                    let u = 0.5 * mat.kt(d.max(0.0)) * e.xi.length_squared();
                    // Semi-implicit Euler changes the kinetic energy by exactly F·(v + v')/2 dt, so
                    // each force drew the mean of its power at the step's two ends; less what its
                    // spring now stores more, that is what it dissipated.
                    lost += half * (0.5 * (e.wt0 - e.ft.dot(vt)) * dt - (u - e.u));
                    let un = mat.normal_energy(d.max(0.0));
                    lost_n += half * (0.5 * (e.wn0 + e.fn_ * vc.dot(nrm)) * dt - (un - e.un));
                    e.u = u;
                    e.ft = V::ZERO;
                }
            }
            (lost, lost_n)
        };
        let (lost, lost_n): (Real, Real) = {
            use rayon::prelude::*;
            let pend = &mut self.pend;
            let parts: Vec<(Real, Real)> =
                match par::fork_if(n, || pend.par_iter_mut().enumerate().map(|(c, o)| advance(c, o)).collect()) {
                    Some(p) => p,
                    None => pend.iter_mut().enumerate().map(|(c, o)| advance(c, o)).collect(),
                };
            parts.into_iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
        };
        std::mem::swap(&mut self.hist, &mut self.pend);
        self.dissipated[0] += lost_n;
        self.dissipated[1] += lost + self.last.broken;
    }

    fn extra_kinetic(&self, model: &Model) -> Real {
        let Some(r) = radii(model) else { return 0.0 };
        let mut k = 0.0;
        for (i, w) in self.omega.iter().enumerate().take(model.len()) {
            if model.inv_mass[i] != 0.0 && r[i] > 0.0 {
                k += 0.5 * self.inertia(model.mass[i], r[i]) * V::axial_length_squared(*w);
            }
        }
        k
    }

    fn extra_angular_momentum(&self, model: &Model) -> [Real; 3] {
        let mut l = [0.0; 3];
        let Some(r) = radii(model) else { return l };
        let mut buf = Vec::with_capacity(3);
        for (i, w) in self.omega.iter().enumerate().take(model.len()) {
            if model.inv_mass[i] != 0.0 && r[i] > 0.0 {
                buf.clear();
                push_axial::<V>(&mut buf, *w);
                let inertia = self.inertia(model.mass[i], r[i]);
                for (k, c) in buf.iter().enumerate() {
                    l[3 - V::AXIAL_DIM + k] += inertia * c;
                }
            }
        }
        l
    }

    fn own_books(&self) -> Vec<(String, Real)> {
        vec![
            (format!("{} (normal damping)", self.name), self.dissipated[0]),
            (format!("{} (friction)", self.name), self.dissipated[1]),
        ]
    }

    fn integrators(&self) -> Option<&'static [&'static str]> {
        Some(&["semi_implicit_euler"])
    }

    fn counts(&self) -> Vec<(&'static str, u64)> {
        vec![("contacts", self.count())]
    }

    /// [n, ω (n·axial), angle (n), dissipated (2), then per spring: owner, partner, ξ (dim), energy].
    fn history(&self) -> Option<Vec<Real>> {
        let n = self.omega.len();
        let mut h = Vec::with_capacity(3 + n * (V::AXIAL_DIM + 1));
        h.push(n as Real);
        for w in &self.omega {
            push_axial::<V>(&mut h, *w);
        }
        h.extend_from_slice(&self.angle);
        h.extend_from_slice(&self.dissipated);
        if self.hist.len() == n.div_ceil(CHUNK) {
            for i in 0..n {
                for e in self.committed(i) {
                    h.push(i as Real);
                    h.push(e.partner as Real);
                    h.extend_from_slice(&V::flat(std::slice::from_ref(&e.xi))[..V::DIM]);
                    h.push(e.u);
                }
            }
        }
        Some(h)
    }

    fn set_history(&mut self, h: &[Real], n_particles: usize) -> Result<()> {
        let bad = |why: &str| invalid("history", format!("contact term {:?}: {why}", self.name));
        if h.is_empty() || h.iter().any(|v| !v.is_finite()) {
            return Err(bad("must be a non-empty array of finite numbers"));
        }
        let n = h[0] as usize;
        if h[0] != n as Real || n != n_particles {
            return Err(bad(&format!("is for {} particles, the scene has {n_particles}", h[0])));
        }
        let a = V::AXIAL_DIM;
        let head = 1 + n * (a + 1) + 2;
        if h.len() < head || !(h.len() - head).is_multiple_of(3 + V::DIM) {
            return Err(bad("has the wrong length"));
        }
        let omega: Vec<V::Axial> = (0..n).map(|i| V::axial_from_slice(&h[1 + i * a..1 + (i + 1) * a])).collect();
        let angle = h[1 + n * a..1 + n * (a + 1)].to_vec();
        let dissipated = [h[head - 2], h[head - 1]];
        let nw = self.walls.len();
        let mut per: Vec<Vec<Entry<V>>> = vec![Vec::new(); n];
        for rec in h[head..].chunks_exact(3 + V::DIM) {
            let (i, j) = (rec[0], rec[1]);
            if i < 0.0 || i.fract() != 0.0 || i as usize >= n || j < 0.0 || j.fract() != 0.0 || j as usize >= n + nw {
                return Err(bad("names a particle or wall that does not exist"));
            }
            per[i as usize].push(Entry {
                partner: j as u32,
                xi: V::from_slice(&rec[2..2 + V::DIM]),
                u: rec[2 + V::DIM],
                ft: V::ZERO,
                fn_: 0.0,
                un: 0.0,
                wn0: 0.0,
                wt0: 0.0,
            });
        }
        for (i, p) in per.iter_mut().enumerate() {
            p.sort_by_key(|e| e.partner);
            if p.windows(2).any(|w| w[0].partner == w[1].partner) || p.iter().any(|e| e.partner as usize == i) {
                return Err(bad("has a repeated or self contact"));
            }
        }
        self.fit(n);
        for (c, chunk) in self.hist.iter_mut().enumerate() {
            chunk.entries.clear();
            chunk.start.clear();
            chunk.start.push(0);
            for p in &per[c * CHUNK..c * CHUNK + chunk_len(n, c)] {
                chunk.entries.extend_from_slice(p);
                chunk.start.push(chunk.entries.len() as u32);
            }
        }
        self.omega = omega;
        self.angle = angle;
        self.dissipated = dissipated;
        self.evaluated = false;
        Ok(())
    }
}

/// Component k of an axial vector (2D: k = 0 is its z component); no allocation (it runs per
/// particle per step).
#[inline(always)]
fn axial_comp<V: Vector>(w: V::Axial, k: usize) -> Real {
    axial_components::<V>(w)[k]
}

#[inline(always)]
fn axial_z<V: Vector>(w: V::Axial) -> Real {
    axial_comp::<V>(w, V::AXIAL_DIM - 1)
}

/// Appends the components of an axial vector.
fn push_axial<V: Vector>(out: &mut Vec<Real>, w: V::Axial) {
    out.extend_from_slice(&axial_components::<V>(w)[..V::AXIAL_DIM]);
}

/// The components of an axial vector (the first `AXIAL_DIM` entries; the rest 0), recovered
/// through its action on the unit axes.
#[inline(always)]
fn axial_components<V: Vector>(w: V::Axial) -> [Real; 3] {
    if V::AXIAL_DIM == 1 {
        // 2D: w = (0, 0, wz): e_x × w = (0, −wz) → wz = −(e_x × w)_y.
        let ex = V::from_slice(&[1.0, 0.0, 0.0][..V::DIM]);
        [-ex.cross_axial(w).comp(1), 0.0, 0.0]
    } else {
        // 3D: e_y × w = (wz, 0, −wx), e_z × w = (−wy, wx, 0).
        let ey = V::from_slice(&[0.0, 1.0, 0.0]);
        let ez = V::from_slice(&[0.0, 0.0, 1.0]);
        let (a, b) = (ey.cross_axial(w), ez.cross_axial(w));
        [-a.comp(2), -b.comp(0), a.comp(0)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_restitution_map_inverts_for_both_laws() {
        for law in [Law::Linear, Law::Hertz] {
            for &e in &[0.05, 0.1, 0.3, 0.5, 0.8, 0.95, 1.0] {
                let z = damping_ratio(law, e);
                let back = match law {
                    Law::Linear => restitution_linear(z),
                    Law::Hertz => restitution_hertz(z),
                };
                assert!((back - e).abs() < 1e-9, "{law:?} e={e}: zeta={z} gives {back}");
            }
        }
        // Undamped: exactly elastic; the unclamped textbook map ζ = −ln e/√(π² + ln² e) is not
        // this model's (the clamp lets go early), so the two must differ at strong damping.
        assert_eq!(restitution_linear(0.0), 1.0);
        let e: Real = 0.3;
        let textbook = -e.ln() / (std::f64::consts::PI.powi(2) + e.ln().powi(2)).sqrt();
        assert!((damping_ratio(Law::Linear, e) - textbook).abs() > 1e-3);
    }

    #[test]
    fn axial_components_round_trip() {
        let mut b = Vec::new();
        push_axial::<glam::DVec2>(&mut b, 2.5);
        assert_eq!(b, vec![2.5]);
        b.clear();
        push_axial::<glam::DVec3>(&mut b, glam::DVec3::new(1.0, -2.0, 3.0));
        assert_eq!(b, vec![1.0, -2.0, 3.0]);
    }
}
