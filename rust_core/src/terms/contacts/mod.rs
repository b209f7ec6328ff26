//! Contacts between grains: the discrete element method (DEM) for discs (2D) and spheres (3D).
//!
//! Grains are the scene's particles with a `radius` attribute > 0; pinned particles are fixed
//! obstacles (pegs). Walls are shapes of the geometry layer (`geometry::AnyShape`: a half-space
//! `{x : (x − p)·n ≥ 0}`, a ball or a bowl, a capsule, an oriented box), each with its own
//! restitution and friction. A grain i touches wall w when the signed distance of its centre
//! from the surface (`Shape::closest`: distance s, unit normal u into the allowed side) is
//! below r_i: overlap δ = r_i − s, normal n = −u (from the grain to the wall), lever
//! a_i = r_i − δ/2, and the pair laws below with m* = m_i, R* = r_i and a wall that neither
//! moves nor turns. A plane's distance and normal are the arithmetic this term always had for
//! it, so plane walls keep their bits.
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
//!   the cap: linear, −k_t ξ − γ_t v_t = the capped force; Hertz, −k_t ξ alone, see
//!   `Material::pair`). k_t = ratio·k_n, ratio > 0 (the facade's default β/(1 + β): equal normal and
//!   tangential periods, 2/7 for spheres, Silbert et al., Phys. Rev. E 64 (2001) 051302, and 1/3
//!   for discs); for Hertz k_t = ratio·(3/2)k_n√δ, the normal contact stiffness (Mindlin's
//!   no-slip tangential stiffness in the same ratio).
//! - Rolling: the tangential force turns each grain, τ_i = a_i n × f_t, on an angular velocity
//!   per particle with moment of inertia I = β m r² (disc β = ½, sphere β = ⅖).
//! - Rolling resistance (μ_r > 0 only; off, nothing of it runs and the bits are those without
//!   it): Ai, Chen, Rotter & Ooi, Powder Technol. 206 (2011) 269, model C (their
//!   elastic–plastic spring–dashpot; model A, a constant torque against ω_r, chatters about
//!   ω_r = 0 and holds nothing at rest). Per contact a rolling spring θ_r (axial) follows the
//!   relative rolling velocity ω_r = (ω_i − ω_j) less its twist about n (3D; ω_j = 0 for a
//!   wall), committed like ξ; torque −k_r θ_r with k_r = 2.25 k_c μ_r² R*² (k_c the normal
//!   contact stiffness, R* = r_i r_j/(r_i + r_j), r_i for a wall), capped at μ_r R* f_n, where
//!   the spring slips and the dashpot is off (their f = 0); below it a dashpot
//!   −η_r 2√(I_r k_r) ω_r with I_r = 1/(1/(I_i + m_i r_i²) + 1/(I_j + m_j r_j²)), the sum capped
//!   at μ_r R* f_n again. +M on i and −M on j: a couple, so momentum and angular momentum stay
//!   conserved. Its state sits beside the links (`Roll`), its pass after the pair and grain
//!   passes (`roll_pass`), its books in "friction".
//!
//! Stepping: semi-implicit Euler over the whole state (the usual DEM scheme). The forces and
//! torques are taken at the step's start from (x, v, ω, ξ); the integrator updates v then x;
//! `end_step` updates ω; then each contact's spring follows the contact point with the NEW
//! velocities, ξ ← ξ_capped + dt·v_t(new), so a resting contact does not pump energy. That
//! update needs the contact's geometry at the new positions, which the next evaluation computes
//! anyway: it is deferred to it (the numba peer does the same) and done there first, with the
//! same arithmetic, or by `settle` when a call of steps ends. The step is chosen by `max_dt`: a
//! 50th of the contact duration (the measured restitution then agrees with e to well under 1 %).
//! Under "xpbd" all of this happens in each substep (the contacts are its external forces; the
//! projections then move the grains, and the springs follow the velocities a substep ends with).
//!
//! Contact search: Verlet lists (Verlet, Phys. Rev. 159 (1967) 98; Allen & Tildesley,
//! *Computer Simulation of Liquids*, §5.3). Candidates are the pairs i < j closer than
//! r_i + r_j + s (skin s = `SKIN`·r_max), found through a cell list of side 2 r_max + s, and the
//! grain–wall pairs closer than r_i + s (by the signed distance, which changes by no more than
//! the grain moves); they are rebuilt once a grain has moved s/2 since the last build (no
//! contact can then form unseen), or the radii change. Each candidate carries its contact's
//! state (`Link`), carried over by partner when the lists are rebuilt.
//!
//! Determinism and conservation: each pair is evaluated once, from its lower index, into its
//! own slot; each particle then gathers its pairs' forces in a fixed order (its pairs as the
//! first grain, then as the second, then its walls), so results are bit-identical for any
//! thread count, and the two grains get exactly negated forces, so momentum is conserved to
//! round-off. The pair pass of the semi-implicit steps runs several pairs per SIMD vector
//! (`contacts/lanes.rs`), with the scalar loop's operations in its order: the same bits at
//! every level.
//!
//! Energy books: kinetic energy includes rotation (½Iω²); potential: the springs' energy,
//! ½k_n δ² (Hertz ⅖k_n δ^{5/2}) + ½k_t|ξ|² (+ ½k_r|θ_r|²); dissipated: "normal damping" and
//! "friction" (sliding and rolling). Each
//! is booked per contact and step as the work its force drew from the motion, the mean of its
//! power at the step's two ends (semi-implicit Euler changes the kinetic energy by exactly
//! F·(v + v')/2 dt), less what its spring gained; so the dashpots, the clamp letting go of an
//! overlap, slipping, and a tangential spring dropped when its contact ends are all in the
//! books. Each force's and torque's power at the step's end is that of the force as applied,
//! through the normal and levers it was evaluated with (`Material::commit`; a wall contact
//! keeps its lever for this), and a contact that formed during a step books the energy its
//! normal spring holds at the step's end as negative dissipation at that step's commit (the
//! scheme made it: the grains drifted into the overlap with no force doing work), so for
//! semi-implicit Euler the books balance the kinetic and potential energy to rounding,
//! friction and rolling resistance included, as the device's do (`physcore_gpu::dem`).
//! Overlaps present when the books begin are in the potential from the start, not booked.
//! With constraints (a `Box`), the particle system settles the step before their projections
//! move the grains, so the books close at the velocities the forces did their work with.
//!
//! Layout, one stage a file: this file holds the contact laws (`Material`), the term, its
//! registration and its roles (`Term`, `OwnState`); `verlet` the Verlet lists (when they are
//! stale, and their rebuild); `passes` the pair, grain and rolling passes and the commit of a
//! step; `lanes` the SIMD lanes of the pair pass; `tests` the tests.
use super::registry::{Context, Params};
use super::{Diagnostics, OwnState, Scratch, Term, Traits, Write};
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::geometry::{AnyShape, Ball, Capsule, HalfSpace, OrientedBox, Shape, Surface};
use crate::neighbors::CellList;
use crate::par::{self, CHUNK};
use crate::simd;
use crate::state::Model;
use crate::vector::{Real, Vector};

mod lanes;
mod passes;
mod verlet;

/// Steps per contact duration (`max_dt`).
const STEPS_PER_CONTACT: Real = 50.0;

/// Verlet skin over the largest radius. Larger means rarer rebuilds and more candidates; at 0.2
/// a packing of equal discs (neighbours 2r apart, the next ones 2√2 r) has no extra candidates.
const SKIN: Real = 0.2;

/// The normal force law.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    Linear,
    Hertz,
}

/// A wall: a shape of the geometry layer with its own contact coefficients.
#[derive(Clone, Debug)]
pub struct Wall<V: Vector> {
    pub shape: AnyShape<V>,
    /// The damping ratio of its restitution (`damping_ratio`).
    pub zeta: Real,
    pub friction: Real,
}

impl<V: Vector> Wall<V> {
    /// The wall's surface seen from `x` (grain centre): the overlap of a grain of radius `r` is
    /// r − distance, its normal (grain to wall) −normal. A plane inline; the other shapes
    /// through one call (`rounded`), so that their code stays out of the passes' loops. (Scenes
    /// whose walls are all planes do not come here: the passes take a loop of their own for
    /// them, `Contacts::planes`.)
    #[inline(always)]
    fn closest(&self, x: V) -> Surface<V> {
        match &self.shape {
            AnyShape::HalfSpace(h) => h.closest(x),
            shape => rounded(shape, x),
        }
    }
}

/// `Shape::closest` of a wall that is not a plane (see `Wall::closest`).
#[inline(never)]
fn rounded<V: Vector>(shape: &AnyShape<V>, x: V) -> Surface<V> {
    shape.closest(x)
}

/// A candidate contact (a pair i < j, or a grain and a wall) and the state of its contact,
/// seen from the first grain. Kept to 56 bytes in 2D: streaming these is a good part of a step.
#[derive(Clone, Copy, Debug)]
struct Link<V> {
    /// Tangential spring ξ (m): committed after a step, capped after an evaluation.
    xi: V,
    /// The tangential force on the first grain at the last evaluation (N), for the books.
    ft: V,
    /// The normal force at the last evaluation (N, ≥ 0); negative when not in contact (no
    /// spring: the link is `live` only while its grains touch).
    fn_: Real,
    /// The tangential book: once a step is committed (or loaded), the energy the spring stores
    /// (J); after an evaluation, ½dt·(the power the tangential force draws from the motion)
    /// plus that energy.
    bt: Real,
    /// The normal book after an evaluation: ½dt·(the power the normal force draws) plus the
    /// energy the normal spring stores (J).
    bn: Real,
}

impl<V: Vector> Link<V> {
    const NONE: Self = Self { xi: V::ZERO, ft: V::ZERO, fn_: -1.0, bt: 0.0, bn: 0.0 };

    /// A contact carried over with spring `xi` storing `u`.
    fn carried(xi: V, u: Real) -> Self {
        Self { xi, ft: V::ZERO, fn_: 0.0, bt: u, bn: 0.0 }
    }

    #[inline(always)]
    fn live(&self) -> bool {
        self.fn_ >= 0.0
    }
}

/// A contact's rolling spring (Ai, Chen, Rotter & Ooi, Powder Technol. 206 (2011) 269, model C),
/// seen from the first grain; kept beside the links, and only when μ_r > 0.
#[derive(Clone, Copy, Debug)]
struct Roll<V: Vector> {
    /// Rolling spring θ_r (rad, axial): its torque on the first grain is −k_r θ_r. Committed
    /// after a step, capped after an evaluation (as `Link::xi`).
    theta: V::Axial,
    /// The rolling torque on the first grain at the last evaluation (N·m), for the books.
    m: V::Axial,
    /// The book, as `Link::bt`: the energy the spring stores (J), after an evaluation plus
    /// ½dt·(the power the torque draws from the relative rotation).
    b: Real,
    live: bool,
}

impl<V: Vector> Roll<V> {
    const NONE: Self = Self { theta: V::AXIAL_ZERO, m: V::AXIAL_ZERO, b: 0.0, live: false };
}

/// What a pair's evaluation hands the gather: the force on the first grain (the second gets
/// its negative) and the torques on both.
#[derive(Clone, Copy, Debug)]
struct PairForce<V: Vector> {
    f: V,
    ti: V::Axial,
    tj: V::Axial,
}

impl<V: Vector> PairForce<V> {
    const ZERO: Self = Self { f: V::ZERO, ti: V::AXIAL_ZERO, tj: V::AXIAL_ZERO };
}

/// A contact carried from one set of lists to the next (or loaded): first grain, partner (a
/// grain > i, or a wall index if `wall`), spring and its energy.
#[derive(Clone, Copy, Debug)]
struct Carry<V: Vector> {
    i: u32,
    j: u32,
    wall: bool,
    xi: V,
    u: Real,
    /// The rolling spring and its energy (0 without rolling resistance).
    theta: V::Axial,
    ur: Real,
}

/// The candidate lists: pairs (i, pj[p]) for p in pstart[i]..pstart[i + 1], partners sorted;
/// the same pairs by second grain (rpair[rstart[j]..rstart[j + 1]], pair indices ascending);
/// the walls near grain i, wall[wstart[i]..wstart[i + 1]].
#[derive(Clone, Debug, Default)]
struct Lists<V: Vector> {
    /// The first grain of each pair: derivable from `pstart`, kept (4 bytes a pair, filled at a
    /// build) so that each lane of the lane-wise pass reads its grain instead of searching.
    pi: Vec<u32>,
    pj: Vec<u32>,
    pstart: Vec<u32>,
    rpair: Vec<u32>,
    rstart: Vec<u32>,
    wall: Vec<u32>,
    wstart: Vec<u32>,
    links: Vec<Link<V>>,
    wlinks: Vec<Link<V>>,
    /// Beside `wlinks`: the wall's normal into the allowed side at the contact's last
    /// evaluation (its force was f_t + normal·f_n; the commits read it; not kept for planes,
    /// whose normal is fixed), and the lever r − δ/2 of that evaluation (its torque was
    /// (n₀ × f_t)·lever, for friction's books).
    wnormal: Vec<V>,
    wlever: Vec<Real>,
    forces: Vec<PairForce<V>>,
    /// The rolling springs beside `links` and `wlinks`, and each pair's rolling torque on its
    /// first grain (N·m; the second gets its negative); empty without rolling resistance.
    roll: Vec<Roll<V>>,
    wroll: Vec<Roll<V>>,
    rt: Vec<V::Axial>,
    /// Positions and radii at the build.
    x: Vec<V>,
    r: Vec<Real>,
    skin: Real,
    /// (`crate::alloc`) The counting sort's cursors, kept so that their room (`reserve`) is reused.
    fill: Vec<u32>,
}

/// What a pass sums: the energies dissipated by the tangential and normal forces in the step
/// being committed and the energy of tangential springs whose contact ended (J), the largest
/// overlap (m) and the contacts (pairs and grain–wall).
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    lost_t: Real,
    lost_n: Real,
    broken: Real,
    max_overlap: Real,
    pairs: u64,
    walls: u64,
}

impl Sums {
    fn add(self, o: Sums) -> Sums {
        Sums {
            lost_t: self.lost_t + o.lost_t,
            lost_n: self.lost_n + o.lost_n,
            broken: self.broken + o.broken,
            max_overlap: self.max_overlap.max(o.max_overlap),
            pairs: self.pairs + o.pairs,
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
    /// γ_t / (2ζ√(k_n m*)): √ratio (linear), or √(1.5 ratio) to be times δ^{1/4} (Hertz).
    pub tangential_damping: Real,
    /// Coefficient of rolling friction μ_r (dimensionless; 0: no rolling resistance).
    pub rolling_friction: Real,
    /// η_r: the rolling dashpot over its critical value 2√(I_r k_r) (dimensionless).
    pub rolling_damping: Real,
}

/// How a pass treats the live contacts of the last step (or substep).
#[derive(Clone, Copy, Debug)]
enum Commit {
    /// The springs follow the contact points and the books close (a step of dt, s).
    Full(Real),
    /// "xpbd", after a substep's predict (of h, s), before the projections move the grains:
    /// the books close at the predicted state, each force's work as semi-implicit Euler did
    /// it; the springs stay. (The projections' own work on the grains is the constraints' to
    /// book: closing here keeps the two apart, where closing after them mixed them, a
    /// first-order error of 2 % of the energy in 2 s of tumbling boxes.) The normal book
    /// then holds ½h f·(v_i − v_j) at the predicted velocities (see `Springs`).
    Books(Real),
    /// Then, after the projections: the springs follow the contact points as the grains
    /// moved; what a spring stores more than it did at the predicted state is friction's.
    Springs(Real),
}

/// The coefficients of one kind of contact for one step (`Material::coef`).
#[derive(Clone, Copy, Debug)]
struct Coef {
    /// ½dt/m* (s/kg).
    h: Real,
    /// The normal and tangential dashpots 2ζ√(k m*) (kg/s; Hertz: to be times δ^{1/4}).
    gn: Real,
    gt: Real,
    /// 1/(1 + h·gn) (the linear law's mid-step speed) and 1/k_t (0 if k_t = 0), linear law.
    inv_den: Real,
    inv_kt: Real,
    /// Friction coefficient.
    mu: Real,
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
    /// The coefficients of a contact between masses with 1/m* = `inv_m` (`sqrt_km` = √(k_n m*))
    /// with damping ratio `zeta` and friction `mu`, for steps of `dt`.
    fn coef(&self, inv_m: Real, sqrt_km: Real, zeta: Real, mu: Real, dt: Real) -> Coef {
        let gn = 2.0 * zeta * sqrt_km;
        let h = 0.5 * dt * inv_m;
        let kt = self.tangential_ratio * self.stiffness;
        let inv_kt = if kt > 0.0 { 1.0 / kt } else { 0.0 };
        Coef { h, gn, gt: gn * self.tangential_damping, inv_den: 1.0 / (1.0 + h * gn), inv_kt, mu }
    }

    /// Normal force magnitude (clamped at 0) and its elastic part, at overlap `d` and approach
    /// speed `vn`.
    ///
    /// The dashpot takes the approach speed at the middle of the step, v_n − ½dt·f/m*, with f
    /// this contact's force (solved in closed form, Crank–Nicolson for the pair): semi-implicit
    /// Euler's velocities lag half a step behind its positions, and a dashpot fed the lagged
    /// speed damps too much to first order (e = 0.1 came out 5.7 % low at a 50th of the
    /// contact; now 0.2 %).
    #[inline(always)]
    fn normal(&self, d: Real, vn: Real, c: &Coef) -> (Real, Real) {
        let (el, g, v_mid) = match self.law {
            Law::Linear => {
                let el = self.stiffness * d;
                (el, c.gn, (vn - c.h * el) * c.inv_den)
            }
            Law::Hertz => {
                let sd = d.sqrt();
                let (el, g) = (self.stiffness * d * sd, c.gn * sd.sqrt());
                (el, g, (vn - c.h * el) / (1.0 + c.h * g))
            }
        };
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
    /// contact-point relative velocity `vc`, coefficients `c`, the
    /// spring `xi` as stored;
    /// `dt`: the step; `new`: whether the contact formed during the last step.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn pair<V: Vector>(&self, n: V, d: Real, vc: V, c: &Coef, xi: V, dt: Real, new: bool) -> PairOut<V> {
        let vn = vc.dot(n);
        let (mut fn_, _) = self.normal(d, vn, c);
        let onset = if new { dt } else { 0.0 };
        if onset > 0.0 && vn > 0.0 && d <= 1.5 * vn * onset {
            fn_ = self.onset(fn_, d, vn, c.gn, onset);
        }
        let vt = vc - n * vn;
        let kt = self.kt(d);
        // Rotate the spring into the tangent plane, keeping its length.
        let mut xi_p = xi;
        let xn = xi.dot(n);
        if V::DIM == 2 {
            // The tangent line is along t = n × ẑ: ξ' = ±|ξ| t, with no division.
            let t = n.cross_axial(V::axial_from_slice(&[1.0]));
            let s = xi.dot(t);
            if xn != 0.0 {
                xi_p = if s != 0.0 { t * xi.length_squared().sqrt().copysign(s) } else { V::ZERO };
            }
        } else if xn != 0.0 {
            xi_p = xi - n * xn;
            let (l0, l1) = (xi.length_squared(), xi_p.length_squared());
            if l1 > 0.0 {
                xi_p = xi_p * (l0 / l1).sqrt();
            }
        }
        // γ_t = 2ζ√(k_t m*).
        let gt = match self.law {
            Law::Linear => c.gt,
            Law::Hertz => c.gt * d.sqrt().sqrt(),
        };
        let mut ft = xi_p * (-kt) - vt * gt;
        let cap = c.mu * fn_;
        let f2 = ft.length_squared();
        let mut xi_c = xi_p;
        if f2 > cap * cap {
            ft = ft * (cap / f2.sqrt());
            xi_c = match self.law {
                // The spring takes the capped force less the dashpot's share, so that the
                // next step, at the same k_t and γ_t, continues the slip where it was.
                Law::Linear => (ft + vt * c.gt) * (-c.inv_kt),
                // Hertz: the spring alone holds the capped force. With the dashpot's share
                // folded in as for the linear law, the next step's k_t (∝ √δ) scaled that
                // share up faster than its γ_t (∝ δ^¼) grew: while the overlap grew, a slipping
                // contact of strong damping (e ≲ 0.3) pushed along the slip, and at e = 0.1 a
                // grain sliding onto a floor left faster than it came (a physics audit).
                Law::Hertz => {
                    if kt > 0.0 {
                        ft * (-1.0 / kt)
                    } else {
                        V::ZERO
                    }
                }
            };
        }
        PairOut { force: ft - n * fn_, ft, xi: xi_c, fn_, wn0: fn_ * vn, wt0: -ft.dot(vt) }
    }

    /// The normal force `fn_` of a contact that began during the last step (of `onset`, s), at
    /// overlap `d` approaching at `vn` > 0 with d ≤ 1.5 vn·onset (dashpot coefficient `gn`),
    /// corrected for when it began. The scalar and the lane-wise pair passes share it.
    #[inline(never)]
    fn onset(&self, fn_: Real, d: Real, vn: Real, gn: Real, onset: Real) -> Real {
        // A contact that began τ = δ/v_n before this step. Semi-implicit Euler is leapfrog:
        // this step's kick f(x)·dt stands for the force over [t − dt/2, t + dt/2], but the
        // contact pushed over [t − τ, t + dt/2]. Add the difference, exact for the force
        // law along δ = v_n u (u: time in contact), so that where in a step grains first
        // touch no longer matters: uncorrected, e = 0.1 came out 2–3 % off at random.
        let tau = (d / vn).min(onset);
        let t = tau + 0.5 * onset;
        let (c, k) = (gn, self.stiffness);
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
        (fn_ + (el_j + damp_j) / onset).max(0.0)
    }

    /// Commits a live contact's step with the state at the step's end (normal `n`, overlap
    /// `d`, contact-point velocity `vc`) as `c` says: the spring follows the contact point,
    /// ξ ← ξ + dt·v_t (frictionless contacts hold none: it could never push), and the books take
    /// what each force drew over the step (the mean of its power at the two ends) less what its
    /// spring now stores more. Adds the dissipated energies to `s`. `fp`, `vr`: the force the
    /// last evaluation put on the first grain and the grains' relative velocity now (a wall's
    /// grain: its velocity).
    ///
    /// The normal force's power at the step's end is that of the force as applied, n₀ f_n =
    /// f_t − `fp` along the evaluation's normal n₀, at the velocities now: exactly what
    /// semi-implicit Euler took from the kinetic energy. (Through the new normal n, as this
    /// did before, it is the same to first order, but the error has one sign: n turns towards
    /// the sliding direction, so a glancing contact booked −½f_n v_t² dt²/r a step. An elastic
    /// gas of 1,600 discs booked −21 % of its energy as dissipated in 18 collision times while
    /// it kept its energy to 0.4 %.)
    ///
    /// The tangential force's power at the step's end, `pt`, is likewise that of the force and
    /// torques as applied: f_t·v_r + τ_i·ω_i + τ_j·ω_j (a wall's: f_t·v + τ·ω), the torques those
    /// of the evaluation's normal and levers, at the velocities now. (Through the new normal and
    /// levers it is again the same to first order: 1.1e-4 of the energy in 800 steps of a
    /// frictional gas, halving with dt.)
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn commit<V: Vector>(
        &self,
        l: &mut Link<V>,
        n: V,
        d: Real,
        vc: V,
        mu: Real,
        c: Commit,
        fp: V,
        vr: V,
        pt: Real,
        s: &mut Sums,
    ) {
        let vn = vc.dot(n);
        let vt = vc - n * vn;
        let d = d.max(0.0);
        let cap = mu * l.fn_;
        match c {
            Commit::Full(dt) => {
                l.xi = if mu > 0.0 { l.xi + vt * dt } else { V::ZERO };
                let u = self.spring_energy(d, l.xi, cap);
                s.lost_t += l.bt - 0.5 * dt * pt - u;
                l.bt = u;
                s.lost_n += l.bn + 0.5 * dt * (l.ft - fp).dot(vr) - self.normal_energy(d);
            }
            Commit::Books(h) => {
                let xi = if mu > 0.0 { l.xi + vt * h } else { V::ZERO };
                let u = self.spring_energy(d, xi, cap);
                s.lost_t += l.bt - 0.5 * h * pt - u;
                l.bt = u;
                s.lost_n += l.bn + 0.5 * h * (l.ft - fp).dot(vr) - self.normal_energy(d);
                l.bn = 0.5 * h * fp.dot(vr);
            }
            Commit::Springs(dt) => {
                l.xi = if mu > 0.0 { l.xi + vt * dt } else { V::ZERO };
                let u = self.spring_energy(d, l.xi, cap);
                s.lost_t += l.bt - u;
                l.bt = u;
                // "xpbd" books what the projections did as the change of Σ ½m u² + U + ½ f·Δx
                // (integrators/xpbd.rs), whose last sum holds this force's ½h f·(v − v_pred):
                // not work this contact did, so it is taken back here.
                s.lost_n += 0.5 * dt * fp.dot(vr) - l.bn;
            }
        }
    }

    /// The energy a tangential spring ξ holds at overlap `d` (J): ½k_t|ξ|², but at most that of
    /// the force it can hold, `cap` = μ f_n of the last evaluation, ½cap²/k_t. A slipping
    /// linear-law spring takes the dashpot's share too (Luding 2008: the next step continues
    /// the slip), so that |k_t ξ| = μ f_n + γ_t|v_t|: as ½k_t|ξ|², a disc sliding on a floor at
    /// e = 0.1 showed a contact potential 4.8 times its kinetic energy and a friction book of
    /// −0.02 J (a physics audit). The books balance with either: it is their state's energy.
    #[inline(always)]
    fn spring_energy<V: Vector>(&self, d: Real, xi: V, cap: Real) -> Real {
        let kt = self.kt(d);
        let x2 = xi.length_squared();
        if kt * kt * x2 <= cap * cap {
            0.5 * kt * x2
        } else {
            0.5 * cap * cap / kt
        }
    }

    /// Evaluates a contact at the step's start into its link (spring capped, book terms set);
    /// returns the force on the first grain and the tangential force.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn evaluate<V: Vector>(&self, l: &mut Link<V>, n: V, d: Real, vc: V, c: &Coef, dt: Real) -> (V, V) {
        let o = self.pair(n, d, vc, c, l.xi, dt, !l.live());
        l.xi = o.xi;
        l.ft = o.ft;
        l.fn_ = o.fn_;
        l.bt += 0.5 * dt * o.wt0;
        l.bn = 0.5 * dt * o.wn0 + self.normal_energy(d);
        (o.force, o.ft)
    }

    /// Rolling stiffness k_r = 2.25 k_c μ_r² R*² at overlap `d` for rolling radius `reff`
    /// (Ai et al. 2011, model C, after Iwashita & Oda 1998), k_c the normal contact stiffness:
    /// k_n (linear), (3/2)k_n√δ (Hertz).
    #[inline(always)]
    fn kr(&self, d: Real, reff: Real) -> Real {
        let kc = match self.law {
            Law::Linear => self.stiffness,
            Law::Hertz => 1.5 * self.stiffness * d.sqrt(),
        };
        2.25 * kc * self.rolling_friction * self.rolling_friction * reff * reff
    }

    /// Evaluates a contact's rolling resistance (Ai et al. 2011, model C) at the step's start
    /// into `rl`: normal `n`, overlap `d`, relative rolling velocity `wr` (rad/s, tangential),
    /// normal force `fn_`, rolling radius `reff`, 1/I_r = `inv_ir`; returns the torque on the
    /// first grain. The spring −k_r θ_r is capped at μ_r R* f_n (full mobilisation: it slips,
    /// and the dashpot is off, Ai's f = 0); below the cap the dashpot −η_r·2√(I_r k_r) ω_r is
    /// added, the sum again capped at μ_r R* f_n (so a contact never resists rolling with more
    /// than the limiting torque).
    #[allow(clippy::too_many_arguments)]
    fn roll_evaluate<V: Vector>(
        &self,
        rl: &mut Roll<V>,
        n: V,
        d: Real,
        wr: V::Axial,
        fn_: Real,
        reff: Real,
        inv_ir: Real,
        dt: Real,
    ) -> V::Axial {
        let kr = self.kr(d, reff);
        let theta = tangent_spring::<V>(rl.theta, n);
        let ms = theta * (-kr);
        let cap = self.rolling_friction * reff * fn_;
        let m2 = V::axial_length_squared(ms);
        let (theta, m) = if m2 > cap * cap {
            let k = cap / m2.sqrt();
            (theta * k, ms * k)
        } else {
            let cr = 2.0 * self.rolling_damping * (kr / inv_ir).sqrt();
            let m = ms + wr * (-cr);
            let t2 = V::axial_length_squared(m);
            (theta, if t2 > cap * cap { m * (cap / t2.sqrt()) } else { m })
        };
        rl.theta = theta;
        rl.m = m;
        rl.b -= 0.5 * dt * axial_dot::<V>(m, wr);
        m
    }

    /// Commits a live rolling spring's step (of `dt`) at the step's end (overlap `d`, relative
    /// rolling velocity `wr`): θ_r ← θ_r + dt·ω_r, and the books take what the torque drew
    /// over the step (the mean of its power at the two ends) less what the spring now stores
    /// more, into `s.lost_t`. The power at the end is the torque's as applied, M·(ω_i − ω_j) for
    /// `w` = ω_i − ω_j (a wall's grain: ω_i), not through the new normal's rolling part (the
    /// same to first order only).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn roll_commit<V: Vector>(
        &self,
        rl: &mut Roll<V>,
        d: Real,
        reff: Real,
        wr: V::Axial,
        w: V::Axial,
        dt: Real,
        s: &mut Sums,
    ) {
        rl.theta = rl.theta + wr * dt;
        let u = 0.5 * self.kr(d.max(0.0), reff) * V::axial_length_squared(rl.theta);
        s.lost_t += rl.b - 0.5 * dt * axial_dot::<V>(rl.m, w) - u;
        rl.b = u;
    }
}

/// `a·b` for axial vectors.
#[inline(always)]
fn axial_dot<V: Vector>(a: V::Axial, b: V::Axial) -> Real {
    let (a, b) = (axial_components::<V>(a), axial_components::<V>(b));
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The rolling part of a relative angular velocity `w` at a contact of normal `n`: `w` in 2D
/// (about z, which is perpendicular to every normal in the plane), `w − (w·n)n` in 3D (the
/// twist about the normal, which rolls nothing, removed).
#[inline(always)]
fn rolling_part<V: Vector>(w: V::Axial, n: V) -> V::Axial {
    if V::AXIAL_DIM == 1 {
        return w;
    }
    let c = axial_components::<V>(w);
    let k = c[0] * n.comp(0) + c[1] * n.comp(1) + c[2] * n.comp(2);
    V::axial_from_slice(&[c[0] - k * n.comp(0), c[1] - k * n.comp(1), c[2] - k * n.comp(2)])
}

/// A rolling spring turned into the tangent plane of normal `n`, keeping its length (3D; in 2D
/// it is always there).
#[inline(always)]
fn tangent_spring<V: Vector>(theta: V::Axial, n: V) -> V::Axial {
    if V::AXIAL_DIM == 1 {
        return theta;
    }
    let p = rolling_part::<V>(theta, n);
    let (l0, l1) = (V::axial_length_squared(theta), V::axial_length_squared(p));
    if l1 > 0.0 && l1 != l0 {
        p * (l0 / l1).sqrt()
    } else {
        p
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
    /// The candidate lists and the contacts' states; `None` until built (and after a change
    /// that invalidates them).
    lists: Option<Lists<V>>,
    /// (`crate::alloc`) Empty lists with room for the next build's per-grain arrays, made fallibly by
    /// `reserve` while `lists` is `None` (whose presence means "built").
    room: Option<Lists<V>>,
    /// (`crate::alloc`) The energy books' cell list (`potential` takes `&self`), with room
    /// made fallibly by `reserve_potential`.
    books: std::sync::Mutex<Option<CellList>>,
    /// Contacts loaded by `set_history`, waiting for the next build.
    seed: Option<Vec<Carry<V>>>,
    /// The last evaluation's sums.
    last: Sums,
    /// Energy dissipated so far by normal damping and by friction, J.
    dissipated: [Real; 2],
    cells: Option<CellList>,
    /// The step in progress (s), told by `begin_step`.
    dt: Real,
    /// Whether forces were evaluated since the last step ended (only then may `end_step` commit).
    evaluated: bool,
    /// The step (s) whose springs and books await their commit (see the module docs).
    pending: Option<Real>,
    /// Whether the books of the pending step were closed after "xpbd"'s predict.
    prebooked: bool,
    /// `uniform_mass` of the evaluation in progress.
    uniform: Option<(Real, Real)>,
    /// How pair passes run: tests force a path to compare them.
    path: PairPath,
    /// The unwritten force buffer of `commit_pass`.
    scratch: Vec<V>,
    /// The memory the last build could not have (`room_for_lists`): its step is refused.
    refused: Option<crate::error::Error>,
}

/// The code a pair pass runs (see `lanes`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum PairPath {
    /// The lanes at the process's level for the semi-implicit steps, else the loop.
    Auto,
    /// The branchy scalar loop always.
    Loop,
    /// As `Auto`, at this level.
    #[cfg_attr(not(test), allow(dead_code))]
    Lanes(simd::Level),
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
    if !(tangential_ratio > 0.0) {
        return Err(invalid(
            "tangential_ratio",
            format!("{tangential_ratio} must be > 0 (a tangential spring of stiffness 0 holds nothing: to turn friction off, set friction=0)"),
        ));
    }
    // Absent: no rolling resistance (the facade always passes both).
    let rolling_friction = if p.has("rolling_friction") { p.number("rolling_friction")? } else { 0.0 };
    let rolling_friction = non_negative("rolling_friction", rolling_friction)?;
    let rolling_damping = if p.has("rolling_damping") { p.number("rolling_damping")? } else { 0.0 };
    let rolling_damping = non_negative("rolling_damping", rolling_damping)?;
    let restitution = restitution_arg("restitution", p.number("restitution")?)?;
    let friction = friction_arg("friction", p.number("friction")?)?;
    let default_beta = if V::DIM == 2 { 0.5 } else { 0.4 };
    let inertia_factor = if p.has("inertia_factor") { p.number("inertia_factor")? } else { default_beta };
    let inertia_factor = positive("inertia_factor", inertia_factor)?;
    let zeta = damping_ratio(law, restitution);
    let tangential_damping = match law {
        Law::Linear => tangential_ratio.sqrt(),
        Law::Hertz => (1.5 * tangential_ratio).sqrt(),
    };
    let material = Material {
        law,
        stiffness,
        tangential_ratio,
        restitution,
        zeta,
        friction,
        inertia_factor,
        tangential_damping,
        rolling_friction,
        rolling_damping,
    };
    let walls = walls::<V>(&mut p, law)?;
    let w = walls.len();
    if u32::try_from(ctx.n_particles + w).is_err() {
        return Err(invalid("walls", "too many particles and walls for 32-bit contact indices"));
    }
    Ok(Box::new(Contacts::new(name, material, walls)))
}
// "xpbd" is semi-implicit Euler per substep under the force terms (then projections).
crate::register_term!("contacts", build, (&["semi_implicit_euler", "xpbd"], "integrator", "Contacts need"));

/// The walls from `wall_kinds` (their collider keys, comma-separated: "plane", "sphere",
/// "capsule", "oriented_box"), `wall_params` (each wall's numbers, in order: a plane its point
/// and normal (any length > 0); a sphere its centre, radius and inside (1) or not (0); a capsule
/// its ends a, b and radius; an oriented box its centre, half extents and rotation (1 number in
/// 2D, 3 in 3D)), `wall_restitution` and `wall_friction`; `InvalidInput` naming "walls" and the
/// wall if one is out of range.
pub(crate) fn walls<V: Vector>(p: &mut Params, law: Law) -> Result<Vec<Wall<V>>> {
    let kinds = if p.has("wall_kinds") { p.text("wall_kinds")?.to_string() } else { String::new() };
    let kinds: Vec<&str> = if kinds.is_empty() { Vec::new() } else { kinds.split(',').collect() };
    let params = p.take_floats("wall_params")?;
    let e = p.take_floats("wall_restitution")?;
    let mu = p.take_floats("wall_friction")?;
    let w = kinds.len();
    if e.len() != w || mu.len() != w {
        return Err(invalid("walls", "kinds, restitution and friction must have one entry per wall"));
    }
    let (d, a) = (V::DIM, V::AXIAL_DIM);
    let mut at = 0;
    let mut walls = Vec::with_capacity(w);
    for (k, &kind) in kinds.iter().enumerate() {
        let len = match kind {
            "plane" => 2 * d,
            "sphere" => d + 2,
            "capsule" => 2 * d + 1,
            "oriented_box" => 2 * d + a,
            other => {
                return Err(invalid(
                    "walls",
                    format!("wall {k}: unknown shape {other:?}; valid: plane, sphere, capsule, oriented_box"),
                ))
            }
        };
        let Some(q) = params.get(at..at + len) else {
            return Err(invalid("walls", format!("wall {k} ({kind}): too few parameters")));
        };
        at += len;
        let named = |e: crate::Error| invalid("walls", format!("wall {k} ({kind}): {e}"));
        if !q.iter().all(|c| c.is_finite()) {
            return Err(invalid("walls", format!("wall {k} ({kind}): its parameters must be finite")));
        }
        let vec = |i: usize| V::from_slice(&q[i * d..(i + 1) * d]);
        let shape: AnyShape<V> = match kind {
            "plane" => HalfSpace::new(vec(0), vec(1)).map_err(named)?.into(),
            "sphere" => {
                let inside = q[d + 1];
                if inside != 0.0 && inside != 1.0 {
                    return Err(invalid("walls", format!("wall {k} (sphere): inside must be 0 or 1, got {inside}")));
                }
                let inside = inside == 1.0;
                Ball::new(vec(0), q[d], inside).map_err(named)?.into()
            }
            "capsule" => Capsule::new(vec(0), vec(1), q[2 * d]).map_err(named)?.into(),
            _ => OrientedBox::new(vec(0), vec(1), V::axial_from_slice(&q[2 * d..2 * d + a])).map_err(named)?.into(),
        };
        let e = restitution_arg("walls", e[k])?;
        walls.push(Wall { shape, zeta: damping_ratio(law, e), friction: friction_arg("walls", mu[k])? });
    }
    if at != params.len() {
        return Err(invalid("walls", format!("{} parameters for walls that take {at}", params.len())));
    }
    Ok(walls)
}

fn restitution_arg(key: &str, e: Real) -> Result<Real> {
    if !(e > 0.0 && e <= 1.0) {
        return Err(invalid(
            key,
            format!("restitution {e} must be in (0, 1] (a dashpot that never pulls cannot stop a grain dead; use e.g. 0.05)"),
        ));
    }
    Ok(e)
}

fn non_negative(key: &str, v: Real) -> Result<Real> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(invalid(key, format!("{v} must be finite and >= 0")));
    }
    Ok(v)
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
            lists: None,
            room: None,
            books: std::sync::Mutex::new(None),
            seed: None,
            last: Sums::default(),
            dissipated: [0.0; 2],
            cells: None,
            dt: 0.0,
            evaluated: false,
            pending: None,
            prebooked: false,
            uniform: None,
            path: PairPath::Auto,
            scratch: Vec::new(),
            refused: None,
        }
    }

    /// `set_history`; `checked`: refuse non-finite values (what a file or a caller gives), else
    /// take them as they are (the term's own snapshot, see `restore_history`).
    fn load_history(&mut self, h: &[Real], n_particles: usize, checked: bool) -> Result<()> {
        let name = self.name.clone(); // `bad` borrows it, not self: the spins' room is reserved below
        let bad = |why: &str| invalid("history", format!("contact term {name:?}: {why}"));
        if h.is_empty() || (checked && h.iter().any(|v| !v.is_finite())) {
            return Err(bad("must be a non-empty array of finite numbers"));
        }
        let n = h[0] as usize;
        // Before its first step the term holds no per-particle state: its history is for 0
        // particles whatever the scene's count, and is restored as such (`fit` sizes it).
        if h[0] != n as Real || (n != n_particles && n != 0) {
            return Err(bad(&format!("is for {} particles, the scene has {n_particles}", h[0])));
        }
        let a = V::AXIAL_DIM;
        let head = 1 + n * (a + 1) + 2;
        let width = self.record_width();
        if h.len() < head || !(h.len() - head).is_multiple_of(width) {
            return Err(bad("has the wrong length"));
        }
        // The spins and angles are written in place at the end, in room reserved now (nothing
        // changes if it cannot be had): a rollback restores a snapshot into buffers already of
        // its size, so it allocates none of them (new ones, 8 MB for 10⁶ grains in 2D, aborted
        // the process in the rollback of a step refused memory).
        self.reserve_spins("load", n)?;
        let dissipated = [h[head - 2], h[head - 1]];
        let nw = self.walls.len();
        // (record, whether it was given from the higher index)
        let mut seed: Vec<(Carry<V>, bool)> = Vec::new();
        for rec in h[head..].chunks_exact(width) {
            let (i, j) = (rec[0], rec[1]);
            if i < 0.0 || i.fract() != 0.0 || i as usize >= n || j < 0.0 || j.fract() != 0.0 || j as usize >= n + nw {
                return Err(bad("names a particle or wall that does not exist"));
            }
            let (i, j) = (i as usize, j as usize);
            let (xi, u) = (V::from_slice(&rec[2..2 + V::DIM]), rec[2 + V::DIM]);
            let (theta, ur) = if width > 3 + V::DIM {
                let at = 3 + V::DIM;
                (V::axial_from_slice(&rec[at..at + a]), rec[at + a])
            } else {
                (V::AXIAL_ZERO, 0.0)
            };
            if j >= n {
                seed.push((Carry { i: i as u32, j: (j - n) as u32, wall: true, xi, u, theta, ur }, false));
            } else if i < j {
                seed.push((Carry { i: i as u32, j: j as u32, wall: false, xi, u, theta, ur }, false));
            } else if i > j {
                let theta = theta * -1.0;
                seed.push((Carry { i: j as u32, j: i as u32, wall: false, xi: -xi, u, theta, ur }, true));
            } else {
                return Err(bad("has a self contact"));
            }
        }
        seed.sort_by_key(|(k, swapped)| (k.i, k.wall, k.j, *swapped));
        let mut kept: Vec<Carry<V>> = Vec::with_capacity(seed.len());
        let mut last: Option<(u32, bool, u32, bool)> = None;
        for (k, swapped) in seed {
            let key = (k.i, k.wall, k.j, swapped);
            if let Some(p) = last {
                if (p.0, p.1, p.2) == (key.0, key.1, key.2) {
                    if p.3 == key.3 {
                        return Err(bad("has a repeated contact"));
                    }
                    continue;
                }
            }
            last = Some(key);
            kept.push(k);
        }
        self.omega.clear();
        self.omega.extend((0..n).map(|i| V::axial_from_slice(&h[1 + i * a..1 + (i + 1) * a])));
        self.angle.clear();
        self.angle.extend_from_slice(&h[1 + n * a..1 + n * (a + 1)]);
        self.torque.resize(n, V::AXIAL_ZERO);
        self.dissipated = dissipated;
        self.seed = Some(kept);
        self.lists = None;
        self.pending = None;
        self.prebooked = false;
        self.evaluated = false;
        Ok(())
    }

    /// Room for `n` grains' spins, angles and torques (their contents unchanged); a refusal is
    /// `Error::OutOfMemory` naming `what`.
    fn reserve_spins(&mut self, what: &'static str, n: usize) -> Result<()> {
        let bytes = Need::bytes_of::<V::Axial>(2 * n) + Need::bytes_of::<Real>(n);
        let need = Need::new(what, bytes, format!("the spins of {} grains", count(n as u128)));
        need.reserve(&mut self.omega, n)?;
        need.reserve(&mut self.angle, n)?;
        need.reserve(&mut self.torque, n)
    }

    /// Sizes the per-particle state for `n` particles (new particles at rest); the contacts
    /// among the particles that remain are carried over.
    fn fit(&mut self, n: usize) {
        if self.omega.len() != n {
            let mut carry = self.carry();
            carry.retain(|k| (k.i as usize) < n && (k.wall || (k.j as usize) < n));
            self.seed = Some(carry);
            self.lists = None;
            self.omega.resize(n, V::AXIAL_ZERO);
            self.angle.resize(n, 0.0);
            self.torque.resize(n, V::AXIAL_ZERO);
        }
    }

    /// Contacts counted once at the last evaluation (pairs + wall contacts).
    pub fn count(&self) -> u64 {
        self.last.pairs + self.last.walls
    }

    fn inertia(&self, m: Real, r: Real) -> Real {
        self.material.inertia_factor * m * r * r
    }

    /// The live contacts, sorted by first grain, then pairs before walls, then partner.
    fn carry(&self) -> Vec<Carry<V>> {
        if let Some(s) = &self.seed {
            return s.clone();
        }
        let Some(l) = &self.lists else { return Vec::new() };
        let mut out = Vec::new();
        let rolled = |rolls: &[Roll<V>], p: usize| {
            rolls.get(p).filter(|r| r.live).map_or((V::AXIAL_ZERO, 0.0), |r| (r.theta, r.b))
        };
        for i in 0..l.pstart.len().saturating_sub(1) {
            let live = |j: u32, k: &Link<V>, wall: bool, (theta, ur): (V::Axial, Real)| Carry {
                i: i as u32,
                j,
                wall,
                xi: k.xi,
                u: k.bt,
                theta,
                ur,
            };
            let (a, b) = (l.pstart[i] as usize, l.pstart[i + 1] as usize);
            out.extend(
                (a..b).filter(|&p| l.links[p].live()).map(|p| live(l.pj[p], &l.links[p], false, rolled(&l.roll, p))),
            );
            let (a, b) = (l.wstart[i] as usize, l.wstart[i + 1] as usize);
            out.extend(
                (a..b)
                    .filter(|&q| l.wlinks[q].live())
                    .map(|q| live(l.wall[q], &l.wlinks[q], true, rolled(&l.wroll, q))),
            );
        }
        out
    }
}

/// The step a commit closes for the rolling springs: θ_r follows ω, which only `end_step`
/// changes, so "xpbd" commits them once, after the projections (`Springs`), not at its
/// predicted state (`Books`, before `end_step` turned the grains).
fn roll_step(c: Commit) -> Option<Real> {
    match c {
        Commit::Full(dt) | Commit::Springs(dt) => Some(dt),
        Commit::Books(_) => None,
    }
}

/// What one chunk's rebuild makes (see `Contacts::rebuild`).
struct Part<V: Vector> {
    pj: Vec<u32>,
    pcount: Vec<u32>,
    links: Vec<Link<V>>,
    roll: Vec<Roll<V>>,
    wall: Vec<u32>,
    wcount: Vec<u32>,
    wlinks: Vec<Link<V>>,
    wroll: Vec<Roll<V>>,
    dropped: Real,
}

impl<V: Vector> Default for Part<V> {
    fn default() -> Self {
        Self {
            pj: Vec::new(),
            pcount: Vec::new(),
            links: Vec::new(),
            roll: Vec::new(),
            wall: Vec::new(),
            wcount: Vec::new(),
            wlinks: Vec::new(),
            wroll: Vec::new(),
            dropped: 0.0,
        }
    }
}

/// A contact that ended: its spring's energy goes to the books, the link is cleared.
#[inline(always)]
fn end_contact<V: Vector>(l: &mut Link<V>, sums: &mut Sums) {
    if l.live() {
        sums.broken += l.bt;
        *l = Link::NONE;
    }
}

/// Splits `a` at `bounds` (ascending, first 0, last `a.len()`).
fn split_at<'a, T>(mut a: &'a mut [T], bounds: &[usize]) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(bounds.len().saturating_sub(1));
    for w in bounds.windows(2) {
        let (head, tail) = std::mem::take(&mut a).split_at_mut(w[1] - w[0]);
        out.push(head);
        a = tail;
    }
    out
}

/// The mass and inverse mass every free grain has, if they are all equal (the usual case).
fn uniform_mass(model: &Model, r: &[Real]) -> Option<(Real, Real)> {
    // The lightest and heaviest free grain (parallel: it runs every step).
    let (lo, hi) = par::reduce(
        r.len(),
        (Real::INFINITY, Real::NEG_INFINITY),
        |a, b| (a.0.min(b.0), a.1.max(b.1)),
        |range| {
            range
                .into_iter()
                .filter(|&i| model.inv_mass[i] != 0.0 && r[i] > 0.0)
                .fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), i| {
                    (lo.min(model.mass[i]), hi.max(model.mass[i]))
                })
        },
    );
    let i0 = (0..r.len()).find(|&i| model.inv_mass[i] != 0.0 && r[i] > 0.0 && model.mass[i] == lo)?;
    (lo == hi).then_some((lo, model.inv_mass[i0]))
}

/// Reads the radius attribute (zeros if unset).
fn radii(model: &Model) -> Option<&[Real]> {
    model.attribute("radius")
}

/// The step limit of a contacts term (`Contacts::max_dt`, which the device's grains also take):
/// a `STEPS_PER_CONTACT`th of the contact duration of the lightest pair. `shape`: the normal
/// stiffness k, the tangential ratio, β of I = β m r² and μ_r; `m_min`, `r_min` the lightest
/// mass and smallest radius of the free grains, `v_max2` the largest squared speed, `g` the
/// uniform fields' strength (m/s²), `max_overlap` the deepest overlap at the last evaluation.
pub(crate) fn step_limit(
    hertz: bool,
    shape: (Real, Real, Real, Real),
    m_min: Real,
    r_min: Real,
    v_max2: Real,
    g: Real,
    max_overlap: Real,
) -> Real {
    let (stiffness, tangential_ratio, beta, rolling_friction) = shape;
    // Lightest pair: m* = m/2; the tangential mode also turns both grains:
    // 1/m*_t = 2/m + 2a²/I = (2/m)(1 + 1/β).
    let m_eff = 0.5 * m_min;
    let tangential = tangential_ratio * (2.0 / m_min) * (1.0 + 1.0 / beta);
    // The rolling spring's mode, k_r/I_r, fastest against a wall: 2.25 μ_r² k_c/((1 + β) m).
    let rolling = 2.25 * rolling_friction * rolling_friction / ((1.0 + beta) * m_min);
    let duration = if !hertz {
        let mut w2 = (stiffness / m_eff).max(tangential * stiffness);
        if rolling > 0.0 {
            w2 = w2.max(rolling * stiffness);
        }
        std::f64::consts::PI / w2.sqrt()
    } else {
        // Hertz contact duration 3.21 (m*/k)^{2/5} v^{-1/5} (Johnson, Contact Mechanics,
        // eq. 11.24, in terms of k), at twice the fastest grain's speed or the speed of a
        // fall through one radius; and the period at the deepest overlap seen.
        let vr = (2.0 * v_max2.sqrt()).max((2.0 * g * r_min).sqrt()).max(1e-12);
        let t_impact = 3.21 * (m_eff / stiffness).powf(0.4) * vr.powf(-0.2);
        let k_deep = 1.5 * stiffness * max_overlap.sqrt();
        let mut w2 = k_deep / m_eff * (1.0 + tangential_ratio * (1.0 + 1.0 / beta));
        if rolling > 0.0 {
            w2 = w2.max(rolling * k_deep);
        }
        if w2 > 0.0 {
            t_impact.min(std::f64::consts::PI / w2.sqrt())
        } else {
            t_impact
        }
    };
    duration / STEPS_PER_CONTACT
}

impl<V: Vector> Term<V> for Contacts<V> {
    fn name(&self) -> &str {
        &self.name
    }
    /// It books its own dissipation (two ledgers, `OwnState::books`), so it is not
    /// `dissipative` to the integrators; its forces depend on the velocities.
    fn traits(&self) -> Traits<V> {
        Traits {
            velocity_dependent: true,
            cheap_potential: false,
            integrators: crate::terms::registry::integrator_rule("contacts").map(|r| r.0),
            ..Traits::conservative()
        }
    }

    fn add_forces(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let n = x.len();
        self.fit(n);
        self.evaluated = true;
        let Some(r) = radii(model) else {
            par::chunks1(f, |_, f| f.iter_mut().for_each(|fi| write.put(fi, V::ZERO)));
            self.torque.iter_mut().for_each(|t| *t = V::AXIAL_ZERO);
            (self.lists, self.seed, self.pending, self.prebooked) = (None, None, None, false);
            self.last = Sums::default();
            return 0.0;
        };
        let mut commit = self.take_pending();
        let mut dropped = 0.0;
        if self.stale(x, r) {
            if let Some(c) = commit.take() {
                self.commit_pass(x, v, model, c);
            }
            dropped = self.rebuild(x, r);
        }
        self.uniform = uniform_mass(model, r);
        let s = self.pair_pass(x, v, model, r, commit, true);
        let mut s = s.add(self.grain_pass(x, v, model, r, commit, f, write, true));
        if self.material.rolling_friction > 0.0 {
            s = s.add(self.roll_pass(x, model, r, commit.and_then(roll_step), true));
        }
        s.broken += dropped;
        // In the order `settle_now` and the next evaluation would book them: the same bits
        // whether a call of steps ends here or not.
        self.dissipated[0] += s.lost_n;
        self.dissipated[1] += s.lost_t;
        self.dissipated[1] += s.broken;
        self.last = s;
        0.0
    }

    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        let Some(r) = radii(model) else { return Some(0.0) };
        let n = x.len();
        let mat = &self.material;
        let mut u = 0.0;
        // Normal springs at x (a fresh search: the lists may be stale for these positions).
        let r_max = r.iter().fold(0.0, |a: Real, &b| a.max(b));
        if r_max > 0.0 {
            // [alloc] The list `reserve_potential` made room in, at this size.
            let mut books = self.books.lock().unwrap_or_else(|e| e.into_inner());
            let cl = books.take().map_or_else(|| CellList::new(1.0, V::DIM), Ok);
            if let Ok(mut cl) = cl.and_then(|mut c| c.set_cell_size(2.0 * r_max).map(|()| c)) {
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
                *books = Some(cl);
            }
        }
        for i in 0..n {
            if r[i] <= 0.0 || model.inv_mass[i] == 0.0 {
                continue;
            }
            for wall in &self.walls {
                let d = r[i] - wall.closest(x[i]).distance;
                if d > 0.0 {
                    u += mat.normal_energy(d);
                }
            }
        }
        // Tangential (and rolling) springs as committed.
        Some(u + self.carry().iter().map(|k| k.u + k.ur).sum::<Real>())
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
        let hertz = matches!(mat.law, Law::Hertz);
        let shape = (mat.stiffness, mat.tangential_ratio, mat.inertia_factor, mat.rolling_friction);
        Some(step_limit(hertz, shape, m_min, r_min, v_max, g, self.last.max_overlap))
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
        let mut coordination = vec![0.0; n];
        for k in self.carry() {
            coordination[k.i as usize] += 1.0;
            if !k.wall {
                coordination[k.j as usize] += 1.0;
            }
        }
        out.push(("coordination", 0..n, coordination));
        out
    }

    fn reserve(&mut self, n: usize, scratch: Scratch) -> Result<()> {
        if scratch == Scratch::Potential {
            let books = self.books.get_mut().unwrap_or_else(|e| e.into_inner());
            if books.is_none() {
                *books = CellList::new(1.0, V::DIM).ok();
            }
            return books.as_mut().map_or(Ok(()), |c| c.reserve(n, "energy"));
        }
        // [alloc] Room for the spins (`fit`) and the cell list before the first step builds
        // them: their infallible growth aborted the process under memory pressure. The list's
        // size is set by the radii at its first build (`rebuild`); 1 m until then. Room only:
        // the sizing itself (`fit`, in `add_forces`) comes after the step's checkpoint, so
        // that a rolled-back first step leaves the term as it was, unsized (its history then
        // reads as before the call, byte for byte).
        self.reserve_spins("step", n)?;
        if self.lists.is_none() || self.omega.len() != n {
            let l = self.room.get_or_insert_with(Lists::default);
            let bytes = Need::bytes_of::<u32>(4 * n + 3) + Need::bytes_of::<V>(n) + Need::bytes_of::<Real>(n);
            let need = Need::new("step", bytes, format!("the contact lists of {} grains", count(n as u128)));
            for v in [&mut l.pstart, &mut l.wstart, &mut l.rstart] {
                need.reserve(v, n + 1)?;
            }
            need.reserve(&mut l.fill, n)?;
            need.reserve(&mut l.x, n)?;
            need.reserve(&mut l.r, n)?;
        }
        if self.cells.is_none() {
            self.cells = CellList::new(1.0, V::DIM).ok();
        }
        if let Some(c) = self.cells.as_mut() {
            c.reserve(n, "step")?;
        }
        Ok(())
    }

    /// (`crate::alloc`) The build's per-chunk parts (two counts a grain, the last build's pairs again)
    /// are allocated in parallel where a refusal cannot be reported; the world checks this much
    /// room is left once the step's checkpoint is taken.
    fn transient_bytes(&self, n: usize) -> u128 {
        let pairs = self.lists.as_ref().map_or(0, |l| l.pj.len() + l.wall.len());
        Need::bytes_of::<u32>(2 * n) + Need::bytes_of::<(u32, Link<V>)>(pairs)
    }

    fn diagnostics(&self) -> Diagnostics {
        Diagnostics { counts: vec![("contacts", self.count())], ..Diagnostics::default() }
    }

    fn as_own_state(&self) -> Option<&dyn OwnState<V>> {
        Some(self)
    }
    fn as_own_state_mut(&mut self) -> Option<&mut dyn OwnState<V>> {
        Some(self)
    }
}

impl<V: Vector> OwnState<V> for Contacts<V> {
    fn begin_step(&mut self, dt: Real) {
        self.dt = dt;
        self.refused = None;
    }
    fn end_step(&mut self, _x: &[V], _v: &[V], model: &Model, dt: Real) {
        if !self.evaluated {
            return;
        }
        self.evaluated = false;
        let Some(r) = radii(model) else { return };
        let beta = self.material.inertia_factor;
        // ω ← ω + dt τ/I, then the angle with the new ω (semi-implicit, like v and x).
        let torque = &self.torque;
        let level = simd::level();
        par::chunks2(&mut self.omega, &mut self.angle, |s, w, a| {
            // Selects, not branches, so that the divisions vectorise.
            simd::vectorized(
                level,
                #[inline(always)]
                || {
                    for k in 0..w.len() {
                        let i = s + k;
                        let turns = model.inv_mass[i] != 0.0 && r[i] > 0.0;
                        let inv_i = 1.0 / (beta * model.mass[i] * r[i] * r[i]);
                        let wk = w[k] + torque[i] * (dt * inv_i);
                        w[k] = if turns { wk } else { w[k] };
                        if V::DIM == 2 {
                            let ak = a[k] + dt * axial_z::<V>(w[k]);
                            a[k] = if turns { ak } else { a[k] };
                        }
                    }
                },
            )
        });
        // The springs follow the contact points with the new velocities: deferred to the next
        // evaluation, which computes each contact's geometry at these positions anyway, or to
        // `settle` (see the module docs).
        self.pending = Some(dt);
    }
    fn settle(&mut self, x: &[V], v: &[V], model: &Model) {
        self.settle_now(x, v, model);
    }
    fn after_predict(&mut self, x: &[V], v: &[V], model: &Model, h: Real) {
        if self.evaluated && !self.prebooked {
            self.commit_pass(x, v, model, Commit::Books(h));
            self.prebooked = true;
        }
    }
    fn kinetic(&self, model: &Model) -> Real {
        let Some(r) = radii(model) else { return 0.0 };
        let mut k = 0.0;
        for (i, w) in self.omega.iter().enumerate().take(model.len()) {
            if model.inv_mass[i] != 0.0 && r[i] > 0.0 {
                k += 0.5 * self.inertia(model.mass[i], r[i]) * V::axial_length_squared(*w);
            }
        }
        k
    }
    fn angular_momentum(&self, model: &Model) -> [Real; 3] {
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
    fn books(&self) -> Vec<(String, Real)> {
        vec![
            (format!("{} (normal damping)", self.name), self.dissipated[0]),
            (format!("{} (friction)", self.name), self.dissipated[1]),
        ]
    }
    fn books_finite(&self) -> bool {
        self.dissipated.iter().all(|d| d.is_finite())
    }
    /// [n, ω (n·axial), angle (n), dissipated (2), then per live contact: first grain, partner
    /// (a grain, or n + wall index), ξ (dim) seen from the first grain, spring energy, and with
    /// rolling resistance θ_r (axial) seen from the first grain and its energy].
    fn history(&self) -> Result<Vec<Real>> {
        let n = self.omega.len();
        let carry = self.carry();
        let per = 2 + V::DIM + 1 + if self.material.rolling_friction > 0.0 { V::AXIAL_DIM + 1 } else { 0 };
        let len = 1 + n * V::AXIAL_DIM + self.angle.len() + self.dissipated.len() + carry.len() * per;
        let mut h = Vec::new();
        Need::new("save", Need::bytes_of::<Real>(len), format!("the contacts' history of {} grains", count(n as u128)))
            .reserve(&mut h, len)?;
        h.push(n as Real);
        for w in &self.omega {
            push_axial::<V>(&mut h, *w);
        }
        h.extend_from_slice(&self.angle);
        h.extend_from_slice(&self.dissipated);
        for k in carry {
            h.push(k.i as Real);
            h.push(if k.wall { (n + k.j as usize) as Real } else { k.j as Real });
            h.extend_from_slice(&V::flat(std::slice::from_ref(&k.xi))[..V::DIM]);
            h.push(k.u);
            if self.material.rolling_friction > 0.0 {
                push_axial::<V>(&mut h, k.theta);
                h.push(k.ur);
            }
        }
        Ok(h)
    }
    /// Loads `history`. A pair may also be given from its higher index (ξ seen from that
    /// grain), or from both sides (files of physcore before the Verlet lists): the record from
    /// the lower index is kept. A history for 0 particles is that of a term that never stepped
    /// (it sizes itself to the scene at its first step), and fits any scene.
    fn set_history(&mut self, h: &[Real], n_particles: usize) -> Result<()> {
        self.load_history(h, n_particles, true)
    }
    /// A snapshot of this term: non-finite spins and springs (a rollback of a diverged call)
    /// are restored as they were.
    fn restore_history(&mut self, h: &[Real], n_particles: usize) {
        self.load_history(h, n_particles, false).expect("a contact term's own history restores");
    }
    /// The grains' spins and β: the rigid bodies' coupling pushes a grain at its surface point,
    /// so its friction turns the grain (and the moment is the body's too).
    fn spins(&mut self) -> Option<super::Spins<'_, V>> {
        Some(super::Spins { omega: &mut self.omega, inertia_factor: self.material.inertia_factor })
    }
    fn refused(&self) -> Option<crate::error::Error> {
        self.refused.clone()
    }
    /// Spins, angles and the springs of live contacts.
    fn non_finite(&self) -> Option<usize> {
        // It runs after every step: first one streaming, branch-free pass (0·x is 0 for a
        // finite x and NaN otherwise, and NaN survives a sum), in parallel; the search for the
        // first bad grain only when that pass finds something. (The search alone cost 23 % of a
        // 25k-disc pile's step.)
        if self.all_finite() {
            return None;
        }
        let grain = (0..self.omega.len()).find(|&i| {
            !axial_components::<V>(self.omega[i]).iter().all(|c| c.is_finite()) || !self.angle[i].is_finite()
        });
        let spring = |l: &Link<V>| l.live() && !(l.xi.is_finite() && l.bt.is_finite());
        let pair = self.lists.as_ref().and_then(|lists| {
            (0..lists.pstart.len().saturating_sub(1)).find(|&i| {
                let (a, b) = (lists.pstart[i] as usize, lists.pstart[i + 1] as usize);
                let (c, d) = (lists.wstart[i] as usize, lists.wstart[i + 1] as usize);
                lists.links[a..b].iter().any(spring) || lists.wlinks[c..d].iter().any(spring)
            })
        });
        grain.into_iter().chain(pair).min()
    }
}

impl<V: Vector> Contacts<V> {
    /// Whether every grain's spin and angle and every live contact's spring and book are
    /// finite (see `non_finite`).
    fn all_finite(&self) -> bool {
        let (omega, angle) = (&self.omega, &self.angle);
        let grains = par::sum(omega.len(), 0.0, |r| {
            r.map(|i| {
                let w = axial_components::<V>(omega[i]);
                (w[0] + w[1] + w[2] + angle[i]) * 0.0
            })
            .sum::<Real>()
        });
        let links = |ls: &[Link<V>]| {
            par::sum(ls.len(), 0.0, |r| {
                r.map(|k| {
                    let l = &ls[k];
                    let d = (l.xi.length_squared() + l.bt) * 0.0;
                    if l.live() {
                        d
                    } else {
                        0.0
                    }
                })
                .sum::<Real>()
            })
        };
        let pairs = self.lists.as_ref().map_or(0.0, |lists| links(&lists.links) + links(&lists.wlinks));
        (grains + pairs) == 0.0
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

#[cfg(all(test, feature = "gpu"))]
mod device_tests;
#[cfg(test)]
mod tests;
