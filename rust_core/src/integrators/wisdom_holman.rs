//! The Wisdom–Holman map for planetary systems (Wisdom & Holman, AJ 102 (1991) 1528), in Jacobi
//! coordinates (theirs, as in REBOUND's WHFast: Rein & Tamayo, MNRAS 452 (2015) 376) or in the
//! democratic heliocentric coordinates of Duncan, Levison & Lee (AJ 116 (1998) 2067, eqs. 2–4
//! and 14, as in SyMBA and REBOUND's WHDS).
//!
//! One body dominates (the heaviest particle; of equals, a pinned one, then the first: the
//! "Sun"). Either way H = H_Kepler + H_interaction (+ H_Sun), H_Kepler being a Kepler orbit per
//! body, followed exactly, and H_interaction, a function of the positions alone, a kick. Each
//! factor is the exact flow of its part, so the map is symplectic and second order, with an
//! error of order (m_planet / m_0) dt²: the Kepler drift follows each orbit exactly, where
//! velocity Verlet must resolve it.
//!
//! Jacobi (`Coordinates::Jacobi`, the default): with the bodies taken in the order centre, then
//! the others by index (list the planets from the inside out), q_k is body k's position relative
//! to the centre of mass of bodies 0..k, with η_k = m_0 + … + m_k; the kinetic energy is then
//! ½ M V_cm² + Σ_k ½ m'_k q̇_k², m'_k = m_k η_{k−1}/η_k (Wisdom & Holman 1991, §3), so there is
//! no H_Sun. H_Kepler = Σ_k (½ m'_k q̇_k² − G m'_k η_k / |q_k|) is body k's Kepler orbit of
//! μ = G η_k (the mass within it, as in WHFast), and H_interaction = Φ(x) + Σ_k G m'_k η_k / |q_k|
//! (Φ: every conservative term of the scene). A step of dt is WHFast's
//!   Kepler(½dt) ∘ kick(dt) ∘ Kepler(½dt)
//! (the centre of mass drifts uniformly beside it), one force evaluation mid-step, nothing
//! carried from one step to the next. With the Kepler flow outermost the leading error term,
//! of first order in the planets' masses, has half the coefficient it has with the kick
//! outermost (Strang splitting's `[A, [A, B]]` term: 1/24 for the outer flow A, 1/12 for the
//! inner). Measured on the outer Solar System at P_Jupiter/20 over 10⁴ years: 2.31e-6 of the
//! energy, WHFast's to three digits, where the kick-first order gave 4.54e-6 in Jacobi and
//! 4.74e-6 in heliocentric coordinates. The coordinates matter more the wider apart the orbits:
//! in heliocentric coordinates each planet's kick holds the Sun's reflex to the others' pull,
//! in Jacobi ones an outer planet orbits the mass within it (tests: a = 1 and 4, 0.065 of the
//! heliocentric error). A body listed after a planet but passing inside its orbit loses that.
//!
//! The Jacobi kick is the scene's full force less each body's Jacobi Kepler acceleration
//! −G η_k q_k/|q_k|³, taken back to the bodies (`from_jacobi`): a subtraction, not the exact split
//! of the heliocentric map, since q_k is relative to a centre of mass and no pair of the sum is
//! the Kepler term alone. It rounds at ε of the Sun's pull, as the Kepler drift's own update of
//! the same velocity does; the cost is the momentum, kept to rounding of the Sun's momentum a
//! step rather than exactly (tests/integrators/test_wisdom_holman.py).
//!
//! Democratic heliocentric (`Coordinates::DemocraticHeliocentric`): with heliocentric positions
//! Q_i = x_i − x_0 and barycentric velocities V_i = v_i − v_cm, H = H_Kepler + H_interaction +
//! H_Sun, where H_Kepler = Σ_i (½ m_i V_i² − G m_0 m_i / |Q_i|) is each body's Kepler orbit about
//! a fixed centre of G m_0, H_interaction holds everything else (the bodies' pull on one another
//! and any other conservative term of the scene), and H_Sun = |Σ_i m_i V_i|² / 2m_0 is the Sun's
//! reflex motion. A step of dt is
//!   kick(½dt) ∘ jump(½dt) ∘ Kepler(dt) ∘ jump(½dt) ∘ kick(½dt).
//! Its kick is the scene's gravity told to leave out every pair with the Sun
//! (`Setting::KeplerCentre`), so the Kepler part is split off exactly, not subtracted.
//!
//! Its kick takes every force the scene's terms give (one evaluation a step, kept for the next
//! step's first kick). The scene needs exactly one `PairwiseGravity` without softening
//! (`check_step`), no velocity-dependent force (the kick would no longer be a Hamiltonian flow),
//! and no pinned particle but the Sun: a pinned Sun is a fixed centre (no jump, inertial
//! velocities, the Kepler orbits of G m_0 about it), where both coordinate sets are the same map.
//!
//! Symplectic correctors (Jacobi only; `IntegratorOptions::wh_corrector`, off by default):
//! the map W is conjugate, to first order in the planets' masses, to the exact flow of H
//! through a near-identity map C, W ≈ C⁻¹ ∘ exp(dt H) ∘ C (Wisdom, Holman & Touma, Fields Inst.
//! Commun. 10 (1996) 217). The map's error of first order in the masses is then a coordinate
//! change, not a drift: stepping C(x) and handing back C⁻¹ of the result removes it, through
//! dt^(order+1), leaving the error of second order in the masses. As REBOUND's WHFast (Rein &
//! Tamayo 2015, §4), C is a product of stages Z(a, b) = K(a) ∘ I(−b) ∘ K(−2a) ∘ I(b) ∘ K(a)
//! (K a Kepler drift, I a kick of the interaction, each for the time given), at drifts
//! a_j = j √(7/40) dt and kicks ±β_j dt, the stages Z(−a_k, −β_k) … Z(−a_1, −β_1), Z(a_1, β_1)
//! … Z(a_k, β_k): to first order in the masses their generator is Σ_j 4 β_j sinh(a_j L_A) of
//! the interaction (L_A the Kepler part's Lie operator, times dt), which must equal
//! 1/w − 1/(2 sinh(w/2)) at w = L_A dt through w^(2k−1) (the conjugacy of the map
//! exp(½dt A) exp(dt B) exp(½dt A), whose generator to that order is A + (w/2)/sinh(w/2) B).
//! The β_j solve those k linear equations (`corrector_b`, computed at 60 digits; they are
//! WHT96's and WHFast's for orders 3, 5, 7 and 11). Negating every β gives the exact inverse.
//! C is applied at the first step of a run; each call's end (`settle`) hands back C⁻¹ of the
//! corrected state and keeps that state (`Carry`: a checkpoint, `Scene.state` and a saved file
//! hold it), from which the next call goes on, as WHFast does with `keep_unsynchronized`. So
//! outputs do not perturb the run: `step(n)` and n calls of `step(1)` give the same bits, and a
//! call costs 2(order − 1) force evaluations for its output, not a step. Anything that changes
//! the scene between calls (its state, terms, precision, dt, the corrector's order) resets the
//! integrator, and the next call applies C afresh to the state it is given.
//! Being private, the corrected state is also left between a step's kick and its second half
//! drift, which is joined with the next step's first into one Kepler drift of dt (as WHFast does
//! without `safe_mode`): one drift a step instead of two. Nothing may change the state between
//! the steps of such a call: a scene with colliders is refused (`ParticleSystem::check_dt`).
//!
//! The Kepler drift solves the universal Kepler equation for the universal anomaly s,
//!   dt = r_0 G_1(s) + η_0 G_2(s) + μ G_3(s),   η_0 = r_0·v_0,   β = 2μ/r_0 − v_0²,
//! with the G-functions G_k(s) = s^k c_k(βs²) of Stumpff's c_k (Danby, *Fundamentals of Celestial
//! Mechanics*, 2nd ed. 1992, §6.9, eqs. 6.9.11–6.9.26; Wisdom & Hernandez, MNRAS 453 (2015)
//! 3015), by Halley's method kept inside a bracket of the root (the left side rises in s, at the
//! rate r > 0), then moves by Gauss's f and g functions. Elliptic, parabolic and hyperbolic orbits
//! alike.
use super::{accel, bad, ensure_len, store, Carry, Integrator, IntegratorInfo, Particles};
use crate::error::{invalid, Result};
use crate::par;
use crate::terms::Setting;
use crate::vector::{Real, Vector};

/// The coordinates of the split (the module's docs). Default: Jacobi, the more accurate on a
/// hierarchical system (half the energy error on the outer Solar System at P_Jupiter/20).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Coordinates {
    #[default]
    Jacobi,
    DemocraticHeliocentric,
}

impl Coordinates {
    /// The names, as `by_name` takes them.
    pub const NAMES: [&'static str; 2] = ["jacobi", "democratic_heliocentric"];

    pub fn name(self) -> &'static str {
        match self {
            Self::Jacobi => Self::NAMES[0],
            Self::DemocraticHeliocentric => Self::NAMES[1],
        }
    }

    /// `InvalidInput` naming `wh_coordinates` for an unknown name.
    pub fn by_name(name: &str) -> Result<Self> {
        match name {
            "jacobi" => Ok(Self::Jacobi),
            "democratic_heliocentric" => Ok(Self::DemocraticHeliocentric),
            other => Err(invalid(
                "wh_coordinates",
                format!("unknown coordinates {other:?}; valid names: {}", Self::NAMES.join(", ")),
            )),
        }
    }
}

/// The symplectic correctors' orders (`IntegratorOptions::wh_corrector`; 0 is none).
pub const CORRECTOR_ORDERS: [u32; 5] = [3, 5, 7, 11, 17];

/// √(7/40): stage j of a corrector drifts ±j times this, times dt (Wisdom, Holman & Touma 1996).
const CORRECTOR_A: Real = 0.4183300132670378;

/// β_1 … β_k of the corrector of order 2k + 1 (the module's docs: Σ_j 4 β_j sinh(j a w) equals
/// 1/w − 1/(2 sinh(w/2)) through w^(2k−1); solved at 60 digits, rounded to float64).
fn corrector_b(order: u32) -> &'static [Real] {
    match order {
        3 => &[0.024900596027799867],
        5 => &[0.041500993379666444, -0.008300198675933288],
        7 => &[0.0539643990931275, -0.018270923246702132, 0.0024926811426922105],
        11 => &[
            0.07259339474884274,
            -0.03812161368128865,
            0.012309078592019946,
            -0.0023487215292295354,
            0.0002036157964785465,
        ],
        17 => &[
            0.09305610377142595,
            -0.0651928635763779,
            0.03242219886471358,
            -0.01207176082234229,
            0.0033132577069380654,
            -0.0006359998307581766,
            7.643635522793574e-05,
            -4.334741547337358e-06,
        ],
        _ => &[],
    }
}

#[derive(Default)]
pub struct WisdomHolman<V: Vector> {
    coords: Coordinates,
    /// The corrector's order (0: none).
    corrector: u32,
    /// The state is the corrected one (C(x)), to be handed back at `settle`: Some(the dt the
    /// corrector took).
    corrected: Option<Real>,
    /// While corrected: the last step's second half drift is owed (joined with the next step's
    /// first, or made at `settle`); the state is then the one after that step's kick.
    owed: bool,
    /// Forces of the last evaluation (all terms, N), kept for the next step's first kick.
    f: Vec<V>,
    /// Term powers at the cached force state.
    p: Vec<Real>,
    valid: bool,
    /// The drift's positions and velocities: heliocentric and barycentric, or Jacobi (in the
    /// order of `body`).
    q: Vec<V>,
    w: Vec<V>,
    /// Jacobi: the bodies' accelerations of the Kepler terms the kick adds back.
    d: Vec<V>,
    /// Jacobi: η_k, the mass of bodies 0..=k.
    eta: Vec<Real>,
    /// The corrected state the last call ended in (positions, then velocities: after that
    /// step's kick, its second half drift owed), from which the next call goes on; valid while
    /// `kept_p` is not empty.
    kept: Vec<V>,
    /// The term powers of that step, then its dt (`kept_dt`): the carried value's second part
    /// (`Carry`); empty while nothing is kept.
    kept_p: Vec<Real>,
}

/// The index of the central body (the heaviest; of equals, a pinned one, then the first) and
/// G of the scene's Newtonian gravity (0 without one: `check_step` refuses that scene). A pinned
/// star beside a test body of its own mass is the fixed centre, wherever it is.
fn centre<V: Vector>(sys: &Particles<V>) -> (usize, Real) {
    let g = sys.forces.terms.iter().find_map(|t| t.as_fused().and_then(|f| f.newtonian())).map_or(0.0, |t| t.0);
    let (m, im) = (&sys.model.mass, &sys.model.inv_mass);
    let heavier = |i: usize, c: usize| m[i] > m[c] || (m[i] == m[c] && im[i] == 0.0 && im[c] != 0.0);
    let c = (0..m.len()).fold(0, |c, i| if heavier(i, c) { i } else { c });
    (c, g)
}

/// The particle at Jacobi index k: the centre first, then the others in index order.
#[inline]
fn body(k: usize, c: usize) -> usize {
    if k == 0 {
        c
    } else if k <= c {
        k - 1
    } else {
        k
    }
}

/// η_k = m_0 + … + m_k in Jacobi order (`body`), into `eta`.
fn masses_within(m: &[Real], c: usize, eta: &mut Vec<Real>) {
    eta.clear();
    let mut s = 0.0;
    for k in 0..m.len() {
        s += m[body(k, c)];
        eta.push(s);
    }
}

/// Jacobi coordinates of `x` (positions, velocities or accelerations alike: the map is linear)
/// in Jacobi order: `out[0]` the centre of mass, `out[k]` body k's relative to the centre of mass
/// of bodies 0..k (Wisdom & Holman 1991, §3). Sequential: the same sums at any thread count.
pub(crate) fn to_jacobi<V: Vector>(x: &[V], m: &[Real], c: usize, eta: &[Real], out: &mut [V]) {
    let n = x.len();
    let mut s = x[c] * m[c]; // η_{k−1} × the centre of mass of bodies 0..k
    for k in 1..n {
        let i = body(k, c);
        out[k] = x[i] - s * (1.0 / eta[k - 1]);
        s += x[i] * m[i];
    }
    out[0] = s * (1.0 / eta[n - 1]);
}

/// The inverse of `to_jacobi`, from the outermost body in: the centre of mass of bodies 0..k is
/// that of bodies 0..=k less (m_k / η_k) q_k. Each value rounded to float32 when `single`.
pub(crate) fn from_jacobi<V: Vector>(xj: &[V], m: &[Real], c: usize, eta: &[Real], out: &mut [V], single: bool) {
    let mut centre = xj[0]; // of bodies 0..=k
    for k in (1..xj.len()).rev() {
        let i = body(k, c);
        centre -= xj[k] * (m[i] / eta[k]);
        out[i] = store(centre + xj[k], single);
    }
    out[c] = store(centre, single);
}

impl<V: Vector> WisdomHolman<V> {
    /// The dt of the kept corrected state, if one is kept.
    fn kept_dt(&self) -> Option<Real> {
        self.kept_p.last().copied()
    }

    /// The forces at the state now: with `split`, gravity without the pairs of the central body
    /// `c` (democratic heliocentric); else all of them (Jacobi).
    fn eval(&mut self, sys: &mut Particles<V>, c: usize, split: bool) {
        if !split {
            sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
            return;
        }
        for t in sys.forces.terms.iter_mut() {
            t.set(Setting::KeplerCentre(Some(c)));
        }
        sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
        for t in sys.forces.terms.iter_mut() {
            t.set(Setting::KeplerCentre(None));
        }
    }

    /// Jacobi: v ← v + h (a − a_Kepler), a the full forces' accelerations (`eval`) and
    /// a_Kepler the bodies' accelerations of the Jacobi Kepler terms, −G η_k q_k/|q_k|³ in
    /// Jacobi coordinates (0 for the centre of mass), taken back by `from_jacobi`. `self.q` holds
    /// the Jacobi positions, `self.eta` the masses within.
    fn kick_jacobi(&mut self, sys: &mut Particles<V>, h: Real, gc: Real, c: usize) {
        let (q, eta, m) = (&self.q, &self.eta, &sys.model.mass);
        par::chunks1(&mut self.w, |s, w| {
            for (j, w) in w.iter_mut().enumerate() {
                let k = s + j;
                // A body on the centre of mass within it has no orbit: 0/0, a divergence.
                *w = if k == 0 {
                    V::ZERO
                } else {
                    let r2 = q[k].dot(q[k]);
                    q[k] * (gc * eta[k] / (r2 * r2.sqrt()))
                };
            }
        });
        from_jacobi(&self.w, m, c, eta, &mut self.d, false);
        let (f, d, im, g, single) = (&self.f, &self.d, &sys.model.inv_mass, sys.forces.g, sys.single);
        par::chunks1(&mut sys.state.v, |s, v| {
            for (j, v) in v.iter_mut().enumerate() {
                let i = s + j;
                *v = store(*v + (accel(f[i], im[i], g) + d[i]) * h, single);
            }
        });
    }

    /// Jacobi: the Kepler drift of dt about the masses within, and the centre of mass's uniform
    /// motion. `self.q` holds the Jacobi positions.
    fn drift_jacobi(&mut self, sys: &mut Particles<V>, dt: Real, gc: Real, c: usize, com: bool) {
        let (m, single) = (&sys.model.mass, sys.single);
        to_jacobi(&sys.state.v, m, c, &self.eta, &mut self.w);
        let eta = &self.eta;
        par::chunks2(&mut self.q, &mut self.w, |s, q, w| {
            for j in 0..q.len() {
                let k = s + j;
                if k > 0 {
                    (q[j], w[j]) = kepler(q[j], w[j], gc * eta[k], dt);
                }
            }
        });
        if com {
            self.q[0] += self.w[0] * dt;
        }
        from_jacobi(&self.q, m, c, eta, &mut sys.state.x, single);
        from_jacobi(&self.w, m, c, eta, &mut sys.state.v, single);
    }

    /// One corrector stage Z(a, b) = K(a) ∘ I(−b) ∘ K(−2a) ∘ I(b) ∘ K(a) (the module's docs),
    /// in Jacobi coordinates; the centre of mass does not move (its drifts sum to 0).
    fn corrector_stage(&mut self, sys: &mut Particles<V>, a: Real, b: Real, gc: Real, c: usize) {
        let m = &sys.model.mass;
        to_jacobi(&sys.state.x, m, c, &self.eta, &mut self.q);
        self.drift_jacobi(sys, a, gc, c, false);
        for (h, drift) in [(-b, -2.0 * a), (b, a)] {
            self.eval(sys, c, false);
            to_jacobi(&sys.state.x, &sys.model.mass, c, &self.eta, &mut self.q);
            self.kick_jacobi(sys, h, gc, c);
            self.drift_jacobi(sys, drift, gc, c, false);
        }
    }

    /// The corrector C (`sign` 1) or its inverse (−1) for steps of `dt`: the stages
    /// Z(−a_k, −sβ_k) … Z(−a_1, −sβ_1), Z(a_1, sβ_1) … Z(a_k, sβ_k). Returns `true` if any
    /// position or velocity is not finite afterwards.
    fn correct(&mut self, sys: &mut Particles<V>, dt: Real, sign: Real) -> bool {
        let (c, gc) = centre(sys);
        masses_within(&sys.model.mass, c, &mut self.eta);
        let b = corrector_b(self.corrector);
        for j in (1..=b.len()).rev().map(|j| -(j as Real)).chain((1..=b.len()).map(|j| j as Real)) {
            let beta = b[j.abs() as usize - 1] * j.signum();
            self.corrector_stage(sys, j * CORRECTOR_A * dt, sign * beta * dt, gc, c);
        }
        let (x, v) = (&sys.state.x, &sys.state.v);
        par::sum(x.len(), 0u32, |r| r.map(|i| bad(x[i], v[i]) as u32).sum()) > 0
    }

    /// v ← v + h a_interaction (the forces of `eval`).
    fn kick(&self, sys: &mut Particles<V>, h: Real) {
        let (f, im, g, single) = (&self.f, &sys.model.inv_mass, sys.forces.g, sys.single);
        par::chunks1(&mut sys.state.v, |s, v| {
            for (j, v) in v.iter_mut().enumerate() {
                *v = store(*v + accel(f[s + j], im[s + j], g) * h, single);
            }
        });
    }

    /// The jumps and the Kepler drift of dt, and the centre of mass's uniform motion.
    fn drift(&mut self, sys: &mut Particles<V>, dt: Real, mu: Real, c: usize) {
        let (m, im, single) = (&sys.model.mass, &sys.model.inv_mass, sys.single);
        let (x, v) = (&mut sys.state.x, &mut sys.state.v);
        let n = x.len();
        let free = |i: usize| i != c && im[i] != 0.0;
        let fixed = im[c] == 0.0;
        // The mobile bodies' centre of mass (the Sun's mass included).
        let (mut xcm, mut vcm, mut mt) = (V::ZERO, V::ZERO, 0.0);
        if !fixed {
            let mobile = |i: usize| im[i] != 0.0;
            mt = par::sum(n, 0.0, |r| r.filter(|&i| mobile(i)).map(|i| m[i]).sum());
            xcm = par::sum(n, V::ZERO, |r| r.filter(|&i| mobile(i)).fold(V::ZERO, |a, i| a + x[i] * m[i])) * (1.0 / mt);
            vcm = par::sum(n, V::ZERO, |r| r.filter(|&i| mobile(i)).fold(V::ZERO, |a, i| a + v[i] * m[i])) * (1.0 / mt);
        }
        let xc = x[c];
        {
            let (x, v) = (&*x, &*v);
            par::chunks2(&mut self.q, &mut self.w, |s, q, w| {
                for j in 0..q.len() {
                    let i = s + j;
                    (q[j], w[j]) = if free(i) { (x[i] - xc, v[i] - vcm) } else { (V::ZERO, V::ZERO) };
                    if free(i) && x[i] == xc {
                        // A body on the central one has no orbit: a divergence the step reports.
                        q[j] = q[j] * Real::NAN;
                    }
                }
            });
        }
        let momentum = |w: &[V]| par::sum(n, V::ZERO, |r| r.filter(|&i| free(i)).fold(V::ZERO, |a, i| a + w[i] * m[i]));
        let jump = |q: &mut [V], w: &[V]| {
            if fixed {
                return;
            }
            let d = momentum(w) * (0.5 * dt / m[c]);
            par::chunks1(q, |s, q| {
                for (j, q) in q.iter_mut().enumerate() {
                    if free(s + j) {
                        *q += d;
                    }
                }
            });
        };
        jump(&mut self.q, &self.w);
        par::chunks2(&mut self.q, &mut self.w, |s, q, w| {
            for j in 0..q.len() {
                if free(s + j) {
                    (q[j], w[j]) = kepler(q[j], w[j], mu, dt);
                }
            }
        });
        jump(&mut self.q, &self.w);
        let (q, w) = (&self.q, &self.w);
        if fixed {
            par::chunks2(x, v, |s, x, v| {
                for j in 0..x.len() {
                    if free(s + j) {
                        x[j] = store(xc + q[s + j], single);
                        v[j] = store(w[s + j], single);
                    }
                }
            });
            return;
        }
        let xcm = xcm + vcm * dt;
        let qm = par::sum(n, V::ZERO, |r| r.filter(|&i| free(i)).fold(V::ZERO, |a, i| a + q[i] * m[i]));
        let x0 = xcm - qm * (1.0 / mt);
        let v0 = vcm - momentum(w) * (1.0 / m[c]);
        par::chunks2(x, v, |s, x, v| {
            for j in 0..x.len() {
                let i = s + j;
                if free(i) {
                    x[j] = store(x0 + q[i], single);
                    v[j] = store(vcm + w[i], single);
                }
            }
        });
        x[c] = store(x0, single);
        v[c] = store(v0, single);
    }
}

impl<V: Vector> Integrator<V> for WisdomHolman<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "wisdom_holman", order: 2, symplectic: true, force_evals_per_step: 1 }
    }
    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let n = sys.state.x.len();
        if n == 0 {
            return false;
        }
        let (c, gc) = centre(sys);
        // A fixed centre: both coordinate sets are the same map, the heliocentric one's.
        let jacobi = self.coords == Coordinates::Jacobi && sys.model.inv_mass[c] != 0.0;
        for b in [&mut self.q, &mut self.w, &mut self.d] {
            ensure_len(b, n);
        }
        let stale = !self.valid || self.f.len() != n;
        ensure_len(&mut self.f, n);
        if jacobi {
            // Kepler(½dt) ∘ kick(dt) ∘ Kepler(½dt): the one evaluation is mid-step, nothing is
            // carried in, and its dissipation is booked by the midpoint rule.
            let resume = self.corrector > 0 && self.corrected.is_none() && self.kept_dt() == Some(dt);
            if resume && self.kept.len() == 2 * n {
                // The last call's corrected state, its second half drift owed: the run goes on
                // from it as if that call had not ended.
                let (x, v) = self.kept.split_at(n);
                sys.state.x.copy_from_slice(x);
                sys.state.v.copy_from_slice(v);
                self.corrected = Some(dt);
                self.owed = true;
                masses_within(&sys.model.mass, c, &mut self.eta);
                to_jacobi(&sys.state.x, &sys.model.mass, c, &self.eta, &mut self.q);
            }
            let xc = sys.state.x[c];
            if let Some(i) = (0..n).find(|&i| i != c && sys.state.x[i] == xc) {
                // A body on the central one, as the heliocentric map sees it: a divergence.
                sys.state.v[i] = sys.state.v[i] * Real::NAN;
            }
            if self.corrector > 0 && self.corrected.is_none() {
                // The run's first step (or the first since a reset): from here on the state is
                // C(x), handed back at `settle`.
                self.corrected = Some(dt);
                if self.correct(sys, dt, 1.0) {
                    return true;
                }
            }
            masses_within(&sys.model.mass, c, &mut self.eta);
            if std::mem::take(&mut self.owed) {
                // The last step's second half drift and this one's first, joined (the state
                // between a corrected call's steps is private: WHFast's joined drifts). `self.q`
                // still holds the Jacobi positions of x: the kick moved no position.
                self.drift_jacobi(sys, dt, gc, c, true);
            } else {
                to_jacobi(&sys.state.x, &sys.model.mass, c, &self.eta, &mut self.q);
                self.drift_jacobi(sys, 0.5 * dt, gc, c, true);
            }
            self.eval(sys, c, false);
            self.p.clear();
            self.p.extend_from_slice(sys.forces.last_power());
            // Mid-step forces of the full gravity: nothing the heliocentric map may start from.
            self.valid = false;
            sys.forces.book_power(dt);
            to_jacobi(&sys.state.x, &sys.model.mass, c, &self.eta, &mut self.q);
            self.kick_jacobi(sys, dt, gc, c);
            if self.corrected.is_some() {
                // Owed to the next step, or to `settle`.
                self.owed = true;
            } else {
                self.drift_jacobi(sys, 0.5 * dt, gc, c, true);
            }
        } else {
            if stale {
                self.eval(sys, c, true);
                self.p = sys.forces.last_power().to_vec();
                self.valid = true;
            }
            // Dissipation by the trapezoidal rule, as velocity Verlet books it.
            sys.forces.set_last_power(&self.p);
            sys.forces.book_power(0.5 * dt);
            self.kick(sys, 0.5 * dt);
            self.drift(sys, dt, gc * sys.model.mass[c], c);
            self.eval(sys, c, true);
            sys.forces.book_power(0.5 * dt);
            self.p.clear();
            self.p.extend_from_slice(sys.forces.last_power());
            self.kick(sys, 0.5 * dt);
        }
        let (x, v) = (&sys.state.x, &sys.state.v);
        par::sum(n, 0u32, |r| r.map(|i| bad(x[i], v[i]) as u32).sum()) > 0
    }
    fn last_forces(&self) -> &[V] {
        &self.f
    }
    fn scratch(&mut self, _velocity_dependent: bool) -> Vec<&mut Vec<V>> {
        vec![&mut self.f, &mut self.q, &mut self.w, &mut self.d]
    }
    fn configure(&mut self, o: &super::IntegratorOptions) {
        // The carried forces are the other split's.
        if o.wh_coordinates != self.coords {
            self.coords = o.wh_coordinates;
            self.valid = false;
            self.kept_p.clear();
        }
        if o.wh_corrector != self.corrector {
            self.corrector = o.wh_corrector;
            self.kept_p.clear();
        }
    }
    fn reset(&mut self) {
        self.valid = false;
        self.kept_p.clear();
    }
    fn as_carry(&self) -> Option<&dyn Carry<V>> {
        Some(self)
    }
    fn as_carry_mut(&mut self) -> Option<&mut dyn Carry<V>> {
        Some(self)
    }
    fn check_step(&self, sys: &Particles<V>, _dt: Real) -> Result<()> {
        let why = |s: String| Err(invalid("integrator", format!("'wisdom_holman' {s}; use 'yoshida4' or 'verlet'")));
        let gravity: Vec<_> =
            sys.forces.terms.iter().filter_map(|t| t.as_fused().and_then(|f| f.newtonian())).collect();
        match gravity[..] {
            [] => return why("splits each body's Kepler orbit about the heaviest one off the scene's pairwise gravity, and this scene has none (add pc.PairwiseGravity; TreeGravity is not split)".into()),
            [(_, eps)] if eps > 0.0 => return why(format!("splits off unsoftened Kepler orbits, and the pairwise gravity's softening is {eps:e} m (set it to 0)")),
            [_] => {}
            _ => return why(format!("splits off one gravity term's Kepler orbits, and this scene has {}", gravity.len())),
        }
        if let Some(t) = sys.forces.terms.iter().find(|t| t.traits().velocity_dependent) {
            return why(format!("kicks with position-dependent forces, and term {:?} depends on velocity", t.name()));
        }
        let (c, _) = centre(sys);
        if self.corrector > 0 && (self.coords != Coordinates::Jacobi || sys.model.inv_mass[c] == 0.0) {
            let what = if self.coords != Coordinates::Jacobi {
                format!("these are {:?}", self.coords.name())
            } else {
                format!("the heaviest body (particle {c}) is pinned, a fixed centre, whose map is the heliocentric one")
            };
            return Err(invalid(
                "wh_corrector",
                format!("the symplectic corrector is derived for the map in Jacobi coordinates about a free centre, and {what} (set wh_corrector=0, or wh_coordinates='jacobi' and unpin it)"),
            ));
        }
        if let Some(k) = (0..sys.model.inv_mass.len()).find(|&k| k != c && sys.model.inv_mass[k] == 0.0) {
            return why(format!(
                "moves every body but the heaviest (particle {c}), which alone may be pinned (a fixed centre), and particle {k} is pinned"
            ));
        }
        Ok(())
    }
}

impl<V: Vector> Carry<V> for WisdomHolman<V> {
    fn settle(&mut self, sys: &mut Particles<V>) -> bool {
        let Some(dt) = self.corrected.take() else {
            return false;
        };
        self.kept_p.clear();
        if std::mem::take(&mut self.owed) {
            // Kept for the next call (a rollback restores the copy its checkpoint took).
            self.kept.clear();
            self.kept.extend_from_slice(&sys.state.x);
            self.kept.extend_from_slice(&sys.state.v);
            self.kept_p.extend_from_slice(&self.p);
            self.kept_p.push(dt);
            // The last step's second half drift (`self.q` and `self.eta` are that step's).
            let (c, gc) = centre(sys);
            self.drift_jacobi(sys, 0.5 * dt, gc, c, true);
        }
        self.correct(sys, dt, -1.0)
    }
    fn abandon(&mut self) {
        self.corrected = None;
        self.owed = false;
    }
    /// The forces of the heliocentric map's last evaluation (N) and the term powers there; or,
    /// in Jacobi coordinates with the corrector, the corrected state the next call goes on from
    /// (positions, then velocities: 2N) and the term powers, then that state's dt.
    fn borrow(&self) -> Option<(&[V], &[Real])> {
        if self.kept_dt().is_some() {
            return Some((&self.kept[..], &self.kept_p[..]));
        }
        self.valid.then_some((&self.f[..], &self.p[..]))
    }
    fn set(&mut self, f: Vec<V>, p: Vec<Real>, v: &[V], n_terms: usize) -> bool {
        let n = v.len();
        if n > 0 && f.len() == 2 * n && p.len() == n_terms + 1 {
            let dt = p[n_terms];
            if self.corrector == 0 || self.coords != Coordinates::Jacobi || !(dt.is_finite() && dt > 0.0) {
                return false;
            }
            (self.kept, self.kept_p, self.valid) = (f, p, false);
            return true;
        }
        self.kept_p.clear();
        super::set_carried((&mut self.f, &mut self.p, &mut self.valid), f, p, v, n_terms)
    }
}

/// 1/k! for k = 0..=18.
const INV_FACTORIAL: [Real; 19] = {
    let mut t = [1.0; 19];
    let mut k = 1;
    while k < 19 {
        t[k] = t[k - 1] / k as Real;
        k += 1;
    }
    t
};

/// Stumpff's c_0 … c_3 at z (Danby 1992, eq. 6.9.2; c_k(z) = Σ_j (−z)^j / (2j + k)!): z is
/// quartered until |z| ≤ 0.1, where eight terms of the series are exact to rounding, and the
/// doubling formulas c_0(4z) = 2c_0² − 1, c_1(4z) = c_0 c_1, c_2(4z) = c_1²/2,
/// c_3(4z) = (c_2 + c_0 c_3)/4 bring it back (Danby, eq. 6.9.26).
#[inline(always)]
fn stumpff(z: Real) -> [Real; 4] {
    let (mut z, mut quarters) = (z, 0);
    while z.abs() > 0.1 && quarters < 64 {
        z *= 0.25;
        quarters += 1;
    }
    // Σ_{j<8} (−z)^j / (2j + k)! by Estrin's scheme: three dependent multiply-adds, not eight
    // (Horner's), on the Kepler solver's critical path (the same terms, rounded alike to an ulp).
    let (y, f) = (-z, &INV_FACTORIAL);
    let (y2, y4) = (y * y, (y * y) * (y * y));
    let series = |k: usize| {
        let pair = |j: usize| f[2 * j + k] + y * f[2 * j + 2 + k];
        (pair(0) + y2 * pair(2)) + y4 * (pair(4) + y2 * pair(6))
    };
    let (mut c2, mut c3) = (series(2), series(3));
    let (mut c0, mut c1) = (1.0 - z * c2, 1.0 - z * c3);
    for _ in 0..quarters {
        c3 = 0.25 * (c2 + c0 * c3);
        c2 = 0.5 * c1 * c1;
        c1 *= c0;
        c0 = 2.0 * c0 * c0 - 1.0;
    }
    [c0, c1, c2, c3]
}

/// The G-functions G_0 … G_3 at the universal anomaly s for β (G_k = s^k c_k(βs²)).
#[inline]
fn g_functions(s: Real, beta: Real) -> [Real; 4] {
    let [c0, c1, c2, c3] = stumpff(beta * s * s);
    [c0, s * c1, s * s * c2, s * s * s * c3]
}

/// Position and velocity after `dt` on the Kepler orbit of `mu` = G M (m³/s²) about the origin,
/// from `r0`, `v0` (the module's docs).
pub(crate) fn kepler<V: Vector>(r0v: V, v0: V, mu: Real, dt: Real) -> (V, V) {
    if dt == 0.0 {
        return (r0v, v0);
    }
    let r0 = r0v.dot(r0v).sqrt();
    if r0 == 0.0 {
        // At the centre: no orbit, a divergence for the step to report.
        return (r0v * Real::NAN, v0 * Real::NAN);
    }
    // Products with 1/r0 and 1/r, not quotients: the divisions are the chain's slowest links.
    let ri = 1.0 / r0;
    let eta = r0v.dot(v0);
    let beta = 2.0 * mu * ri - v0.dot(v0);
    let zeta = mu - beta * r0;
    // f(s) = r0 G1 + η G2 + μ G3 − dt rises in s (f' = r > 0), with f(0) = −dt.
    // The first guess reverses dt = r0 s + a2 s² + a3 s³ + a4 s⁴ + O(s⁵) (a2 = η/2, a3 = ζ/6,
    // a4 = −βη/24, from the G-functions' series) to s = Σ b_k dt^k (series reversion:
    // Abramowitz & Stegun 3.6.25): good to some 1e-6 of s at an eighth of a period, where one
    // Halley step then ends it. For a step that is a large part of the orbit, where the series
    // does not converge, it falls back on s to second order; the bracket [lo, hi] of the root,
    // the half-line on dt's side of 0 at first, closes as the iterates fall on either side.
    let u = dt * ri;
    let s2 = u - 0.5 * eta * u * u * ri;
    let (a2, a3, a4) = (0.5 * eta, zeta / 6.0, -beta * eta / 24.0);
    let s4 = s2
        + (2.0 * a2 * a2 - r0 * a3) * u * u * u * (ri * ri)
        + (5.0 * r0 * a2 * a3 - r0 * r0 * a4 - 5.0 * a2 * a2 * a2) * u * u * u * u * (ri * ri * ri);
    // |β| s² < 1: within about a sixth of a period (z = βs² = (n dt)² on a circle).
    let short = (beta * s2 * s2).abs() < 1.0 && (s4 - s2).abs() <= 0.1 * s2.abs();
    let s0 = if short { s4 } else { s2 };
    let s0 = if s0 * dt > 0.0 { s0 } else { u };
    let (mut lo, mut hi) = if dt > 0.0 { (0.0, Real::INFINITY) } else { (Real::NEG_INFINITY, 0.0) };
    let mut s = s0;
    let mut g = g_functions(s, beta);
    for _ in 0..200 {
        let fs = r0 * g[1] + eta * g[2] + mu * g[3] - dt;
        if fs < 0.0 {
            lo = s;
        } else {
            hi = s;
        }
        let fp = r0 * g[0] + eta * g[1] + mu * g[2];
        let fpp = eta * g[0] + zeta * g[1];
        // Halley's step −f/(f′ − ½f″ f/f′) over one division, not two in a row (the chain's
        // slowest links); over two where f′² or f f′ leaves the float range (or f f′ falls
        // below it, which would read as a step of 0).
        let (num, den) = (fs * fp, fp * fp - 0.5 * fpp * fs);
        let ds = if (num.is_normal() || fs == 0.0) && den.is_normal() {
            -num / den
        } else {
            -fs / (fp + 0.5 * fpp * (-fs / fp))
        };
        if ds.abs() <= 4.0 * Real::EPSILON * s.abs() {
            // Converged: f is 0 at s to rounding. (Taken on, a step below half an ulp of s
            // leaves next = s, which the bracket test takes for a step out of the bracket: it
            // then bisected, or doubled s, away from the root and came back, at three times the
            // cost of the solve at the short steps of the outer planets, P/5000 and shorter.)
            break;
        }
        let mut next = s + ds;
        let halley = next > lo && next < hi;
        if !halley {
            // Halley left the bracket (or f was not finite): bisect it, or widen an open one.
            next = if lo.is_finite() && hi.is_finite() { 0.5 * (lo + hi) } else { 2.0 * s };
        }
        if next == s || (next - s).abs() <= 4.0 * Real::EPSILON * s.abs() {
            break;
        }
        s = next;
        g = g_functions(s, beta);
        // Halley converges cubically: a step below 1e-6 of s leaves an error of order 1e-18 of
        // it, so s is final (one evaluation of the G-functions fewer than a last, null step).
        if halley && ds.abs() <= 1e-6 * s.abs() {
            break;
        }
    }
    let rinv = 1.0 / (r0 * g[0] + eta * g[1] + mu * g[2]);
    // f − 1, g, ḟ and ġ − 1 (Danby, eq. 6.9.29), as increments to keep the rounding small.
    let fm1 = -mu * g[2] * ri;
    let gg = r0 * g[1] + eta * g[2];
    let fdot = -mu * g[1] * (ri * rinv);
    let gdotm1 = -mu * g[2] * rinv;
    (r0v + (r0v * fm1 + v0 * gg), v0 + (r0v * fdot + v0 * gdotm1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    #[test]
    fn stumpff_matches_the_closed_forms() {
        for z in [-400.0, -30.0, -2.0, -0.05, 0.0, 1e-9, 0.05, 0.3, 2.0, 9.0, 39.0, 400.0] {
            let [c0, c1, c2, c3] = stumpff(z);
            let (e0, e1, e2, e3): (Real, Real, Real, Real) = if z > 0.0 {
                let x = (z as Real).sqrt();
                (x.cos(), x.sin() / x, (1.0 - x.cos()) / z, (x - x.sin()) / (z * x))
            } else if z < 0.0 {
                let x = (-z as Real).sqrt();
                (x.cosh(), x.sinh() / x, (x.cosh() - 1.0) / -z, (x.sinh() - x) / (-z * x))
            } else {
                (1.0, 1.0, 0.5, 1.0 / 6.0)
            };
            // The closed forms of c2, c3 cancel near z = 0; the comparison is meaningful away from it.
            let tol = if z.abs() < 0.1 { 1e-7 } else { 1e-12 };
            for (a, b) in [(c0, e0), (c1, e1), (c2, e2), (c3, e3)] {
                assert!((a - b).abs() <= tol * b.abs().max(1.0), "z = {z}: {a} vs {b}");
            }
        }
    }

    /// A circular orbit returns to its start after one period, and a quarter period turns it
    /// by 90°, to rounding.
    #[test]
    fn kepler_drift_follows_a_circular_orbit() {
        let (mu, r) = (3.0, 2.0);
        let v = (mu / r as Real).sqrt();
        let period = 2.0 * std::f64::consts::PI * (r * r * r / mu as Real).sqrt();
        let (x, u) = kepler(DVec2::new(r, 0.0), DVec2::new(0.0, v), mu, 0.25 * period);
        assert!((x - DVec2::new(0.0, r)).length() < 1e-14 * r, "{x}");
        assert!((u - DVec2::new(-v, 0.0)).length() < 1e-14 * v, "{u}");
        let (x, u) = kepler(DVec2::new(r, 0.0), DVec2::new(0.0, v), mu, period);
        assert!(
            (x - DVec2::new(r, 0.0)).length() < 1e-14 * r && (u - DVec2::new(0.0, v)).length() < 1e-14 * v,
            "{x} {u} {:e} {:e}",
            (x - DVec2::new(r, 0.0)).length() / r,
            (u - DVec2::new(0.0, v)).length() / v
        );
    }

    /// Eccentric (e = 0.9), hyperbolic and radial-ish orbits keep their energy and angular
    /// momentum over a drift many periods long, and a drift there and back returns to the start.
    #[test]
    fn kepler_drift_scales_to_the_ends_of_the_float_range() {
        // Lengths × λ, times × λ^(3/2), velocities × λ^(−1/2) at the same μ: the same orbit. At
        // λ = 1e150 (r² near the top of the range) Halley's one-division form can overflow
        // (f f′ up to dt r ≈ 1e375), where its two-division form, or the bracket, takes over; at
        // 1e-150, 1/r0 and the quotients reach 1e150, and f f′ underflows (1e-375), which read
        // as a step of 0 would end the solve at its first guess.
        let (x0, v0, dt) = (DVec3::new(1.0, 0.2, 0.0), DVec3::new(0.1, 1.3, 0.05), 0.9);
        let (x1, v1) = kepler(x0, v0, 1.0, dt);
        for lambda in [1e150, 1e-150, 3.7] {
            let (sx, sv) = (lambda, (1.0 / lambda as Real).sqrt());
            let (x, v) = kepler(x0 * sx, v0 * sv, 1.0, dt * lambda * lambda.sqrt());
            let (x, v) = (x * (1.0 / sx), v * (1.0 / sv));
            assert!(
                (x - x1).length() < 1e-12 * x1.length() && (v - v1).length() < 1e-12 * v1.length(),
                "λ {lambda}: {x} {v} vs {x1} {v1}"
            );
        }
    }

    #[test]
    fn kepler_drift_keeps_the_integrals_and_reverses() {
        let mu = 1.0;
        for (x0, v0, dt) in [
            (DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.0, 1.378, 0.1), 1500.0), // e ≈ 0.9, ~6.6 periods
            (DVec3::new(1.0, 0.2, 0.0), DVec3::new(0.1, 1.6, 0.0), 0.7),      // bound, eccentric
            (DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.3, 2.0, 0.0), 40.0),     // hyperbolic, far out
            (DVec3::new(-2.0, 1.0, 0.5), DVec3::new(0.01, 0.0, 0.0), 3.0),    // nearly radial fall
        ] {
            let energy = |x: DVec3, v: DVec3| 0.5 * v.length_squared() - mu / x.length();
            let (x1, v1) = kepler(x0, v0, mu, dt);
            let (e0, e1) = (energy(x0, v0), energy(x1, v1));
            assert!((e1 - e0).abs() < 1e-12 * e0.abs().max(1.0), "energy {e0} -> {e1}");
            let (l0, l1) = (x0.cross(v0), x1.cross(v1));
            assert!((l1 - l0).length() < 1e-12 * l0.length().max(1.0), "L {l0} -> {l1}");
            let (x2, v2) = kepler(x1, v1, mu, -dt);
            assert!((x2 - x0).length() < 1e-9 * x0.length() && (v2 - v0).length() < 1e-9 * v0.length().max(1.0));
        }
    }

    /// Bodies of unequal masses, the centre (the heaviest) not first: (x, v, m, c).
    fn bodies() -> (Vec<DVec3>, Vec<DVec3>, Vec<Real>, usize) {
        let m = vec![3e-4, 1e-3, 1.0, 0.0, 5e-5, 2e-6];
        let x: Vec<DVec3> =
            (0..6).map(|i| DVec3::new(1.3 * i as Real - 2.0, (0.7 * i as Real).sin(), 0.1 * i as Real)).collect();
        let v: Vec<DVec3> = (0..6).map(|i| DVec3::new((1.1 * i as Real).cos(), 0.3, -0.2 * i as Real)).collect();
        (x, v, m, 2)
    }

    /// Jacobi coordinates and back give each position to rounding (a few ε of the largest).
    #[test]
    fn jacobi_coordinates_and_back_are_the_identity() {
        let (x, v, m, c) = bodies();
        let mut eta = Vec::new();
        masses_within(&m, c, &mut eta);
        assert_eq!(eta[0], m[c]);
        assert!((eta[5] - m.iter().sum::<Real>()).abs() <= 4.0 * Real::EPSILON);
        for a in [&x, &v] {
            let (mut j, mut back) = (vec![DVec3::ZERO; 6], vec![DVec3::ZERO; 6]);
            to_jacobi(a, &m, c, &eta, &mut j);
            from_jacobi(&j, &m, c, &eta, &mut back, false);
            let scale = a.iter().map(|p| p.length()).fold(0.0, Real::max);
            for (p, q) in a.iter().zip(&back) {
                assert!((*p - *q).length() <= 8.0 * Real::EPSILON * scale, "{p} -> {q}");
            }
        }
    }

    /// The transform is Jacobi's: q_0 is the centre of mass, q_1 the second body's position
    /// relative to the centre, and the kinetic energy is ½ M V² + Σ_k ½ m'_k q̇_k² with
    /// m'_k = m_k η_{k−1}/η_k (Wisdom & Holman 1991, §3), which holds only for the right transform.
    #[test]
    fn jacobi_coordinates_diagonalise_the_kinetic_energy() {
        let (x, v, m, c) = bodies();
        let mut eta = Vec::new();
        masses_within(&m, c, &mut eta);
        let (mut xj, mut vj) = (vec![DVec3::ZERO; 6], vec![DVec3::ZERO; 6]);
        to_jacobi(&x, &m, c, &eta, &mut xj);
        to_jacobi(&v, &m, c, &eta, &mut vj);
        let mt = eta[5];
        let com = x.iter().zip(&m).fold(DVec3::ZERO, |a, (p, &mi)| a + *p * mi) / mt;
        assert!((xj[0] - com).length() < 1e-15 * com.length().max(1.0));
        assert!((xj[1] - (x[0] - x[c])).length() < 1e-15);
        let t: Real = v.iter().zip(&m).map(|(u, &mi)| 0.5 * mi * u.length_squared()).sum();
        let tj: Real = 0.5 * mt * vj[0].length_squared()
            + (1..6).map(|k| 0.5 * m[body(k, c)] * eta[k - 1] / eta[k] * vj[k].length_squared()).sum::<Real>();
        assert!((t - tj).abs() < 1e-14 * t, "{t} vs {tj}");
    }

    #[test]
    fn coordinates_by_name_and_default() {
        assert_eq!(Coordinates::default(), Coordinates::Jacobi);
        for n in Coordinates::NAMES {
            assert_eq!(Coordinates::by_name(n).unwrap().name(), n);
        }
        let e = Coordinates::by_name("heliocentric").unwrap_err().to_string();
        assert!(e.contains("wh_coordinates") && e.contains("jacobi"), "{e}");
    }

    /// Each corrector's β_j solve its conditions: Σ_j 4 β_j (j a)^(2m+1)/(2m+1)! equals the
    /// coefficient of w^(2m+1) in 1/w − 1/(2 sinh(w/2)) for m < k (the module's docs), that
    /// coefficient being −½ · 2(1 − 2^(2n−1)) B_2n/(2n)! / 2^(2n−1), n = m + 1, from the series of
    /// 1/sinh z (Abramowitz & Stegun 4.5.63) with Bernoulli's B_2 … B_16.
    #[test]
    fn corrector_coefficients_meet_their_conditions() {
        let bernoulli =
            [1.0 / 6.0, -1.0 / 30.0, 1.0 / 42.0, -1.0 / 30.0, 5.0 / 66.0, -691.0 / 2730.0, 7.0 / 6.0, -3617.0 / 510.0];
        let factorial = |k: i32| (1..=k).map(|i| i as Real).product::<Real>();
        let target = |m: usize| {
            let n = m as i32 + 1;
            let c = 2.0 * (1.0 - (2.0 as Real).powi(2 * n - 1)) * bernoulli[m] / factorial(2 * n);
            -0.5 * c / (2.0 as Real).powi(2 * n - 1)
        };
        assert_eq!(target(0), 1.0 / 24.0);
        assert!((target(1) + 7.0 / 5760.0).abs() < 1e-18);
        for order in CORRECTOR_ORDERS {
            let b = corrector_b(order);
            assert_eq!(2 * b.len() + 1, order as usize);
            for m in 0..b.len() {
                let p = 2 * m as i32 + 1;
                let sum: Real = b
                    .iter()
                    .enumerate()
                    .map(|(j, bj)| 4.0 * bj * ((j + 1) as Real * CORRECTOR_A).powi(p) / factorial(p))
                    .sum();
                // The terms alternate in sign and cancel to a few hundredths of their largest at
                // order 17's highest powers: f64 evaluates the sum to about 1e-12 of itself.
                assert!((sum / target(m) - 1.0).abs() < 1e-10, "order {order}, w^{p}: {sum:e} against {:e}", target(m));
            }
        }
        assert!((CORRECTOR_A * CORRECTOR_A / (7.0 / 40.0) - 1.0).abs() < 4.0 * Real::EPSILON);
        assert!(corrector_b(4).is_empty());
    }
}
