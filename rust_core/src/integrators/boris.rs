//! The Boris push (Boris 1970, Proc. 4th Conf. Num. Sim. Plasmas, p. 3; in the form of Qin et al.
//! 2013, Phys. Plasmas 20, 084503, eqs. 2–6): for charged particles in a magnetic field. Each step
//! kicks the velocity by half the non-magnetic acceleration a = F/m (electric fields, Coulomb,
//! gravity, springs: every term but the magnetic ones, one evaluation per step), turns it about
//! B by the exact rotation of the Cayley form, and kicks by the other half:
//!
//!   v⁻ = v_{n−½} + a_n dt/2;   t = (q B/m) dt/2;   s = 2t/(1 + t²)
//!   v' = v⁻ + v⁻ × t;   v⁺ = v⁻ + v' × s;   v_{n+½} = v⁺ + a_n dt/2;   x_{n+1} = x_n + v_{n+½} dt
//!
//! The rotation turns v⁻ by θ = 2 arctan(ω_c dt/2) (ω_c = |q|B/m) and keeps |v| to round-off for
//! any step, so in a pure magnetic field the kinetic energy never drifts; a gyration then has the
//! radius r_L √(1 + (ω_c dt/2)²) and the E×B drift is exact (for uniform fields). Second order,
//! time-reversible and volume-preserving; not symplectic (Qin et al.), hence `symplectic: false`.
//!
//! **Staggering.** The push is a leapfrog: positions at whole steps, velocities at half steps.
//! The state holds both at whole steps, as every other integrator's does: v_n is v⁻ turned by
//! half of θ (about B at x_n), the middle of the rotation, and each step starts by turning v_n
//! by the other half. The positions are exactly Boris's; the two half-turns compose to its
//! rotation (to round-off); and |v_n| = |v⁻|, so a pure magnetic field keeps |v_n| to round-off
//! too. The energy books read (x_n, v_n). Without magnetic terms the turns are the identity and
//! the method is velocity Verlet to the bit.
//!
//! Like Verlet it keeps the forces at x_{n+1} (and B there) for the next step. Velocity-dependent
//! forces other than the magnetic one (drag) are evaluated at x_{n+1} with the velocity predicted
//! by the step's own kicks and turn with the old a and B (error O(dt²), keeping second order).
use super::{accel, bad, ensure_len, store, Carry, Integrator, IntegratorInfo, Particles};
use crate::par;
use crate::vector::{Real, Vector};

pub struct Boris<V: Vector> {
    /// Non-magnetic forces at the current state, and the term powers there.
    f: Vec<V>,
    p: Vec<Real>,
    /// Predicted end-of-step velocities (only with non-magnetic velocity-dependent forces).
    vp: Vec<V>,
    /// The magnetic field at the current positions (T; 2D: B_z).
    b: Vec<V::Axial>,
    valid: bool,
    b_valid: bool,
}

impl<V: Vector> Default for Boris<V> {
    fn default() -> Self {
        Self { f: Vec::new(), p: Vec::new(), vp: Vec::new(), b: Vec::new(), valid: false, b_valid: false }
    }
}

/// `v` turned about `t` by half of the Boris rotation with parameter `t` (angle 2 arctan|t|):
/// the Boris rotation with t / (1 + √(1 + |t|²)), whose tangent of the half angle is
/// tan(arctan|t| / 2). Two of them compose to the full rotation.
#[inline(always)]
pub(crate) fn half_turn<V: Vector>(v: V, t: V::Axial) -> V {
    let th = t * (1.0 / (1.0 + (1.0 + V::axial_length_squared(t)).sqrt()));
    let s = th * (2.0 / (1.0 + V::axial_length_squared(th)));
    let w = v + v.cross_axial(th);
    v + w.cross_axial(s)
}

impl<V: Vector> Integrator<V> for Boris<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "boris", order: 2, symplectic: false, force_evals_per_step: 1 }
    }
    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let n = sys.state.x.len();
        if !self.valid || self.f.len() != n {
            ensure_len(&mut self.f, n);
            sys.forces.eval_apart(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
            self.p = sys.forces.last_power().to_vec();
            self.valid = true;
        }
        // The field at x_n: kept from the previous step's end, or computed here.
        let magnetic = sys.forces.magnetic() && sys.model.attribute("charge").is_some();
        if magnetic && (!self.b_valid || self.b.len() != n) {
            sys.forces.magnetic_field(&sys.state.x, &sys.model, &mut self.b);
            self.b_valid = true;
        }
        // Dissipation by the trapezoidal rule: ½dt (P_start + P_end).
        sys.forces.set_last_power(&self.p);
        sys.forces.book_power(0.5 * dt);
        let half = 0.5 * dt;
        let (im, g, single) = (&sys.model.inv_mass, sys.forces.g, sys.single);
        let q = sys.model.attribute("charge").unwrap_or(&[]);
        // The rotation parameter t = (q B / m) dt/2 of particle i (pinned: 0).
        let t = |b: &[V::Axial], i: usize| b[i] * (q[i] * im[i] * half);
        let predict = sys.forces.velocity_dependent_apart();
        let (f, b) = (&self.f, &self.b);
        // Half a turn, a half kick, the drift; returns v_{n+½}, x_{n+1} and the predicted end
        // velocity (the other half kick and turn, with a_n and B at x_n).
        let first = |i: usize, x: V, v: V| -> (V, V, V) {
            let a = accel(f[i], im[i], g);
            let ti = if magnetic { t(b, i) } else { V::AXIAL_ZERO };
            let w = if magnetic { half_turn(v, ti) } else { v };
            let vh = store(w + a * half, single);
            let xn = store(x + vh * dt, single);
            let p = vh + a * half;
            (vh, xn, if magnetic { half_turn(p, ti) } else { p })
        };
        if predict {
            ensure_len(&mut self.vp, n);
            par::chunks3(&mut sys.state.x, &mut sys.state.v, &mut self.vp, |s, x, v, vp| {
                for k in 0..x.len() {
                    let (vh, xn, p) = first(s + k, x[k], v[k]);
                    (v[k], x[k], vp[k]) = (vh, xn, store(p, single));
                }
            });
        } else {
            par::chunks2(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
                for k in 0..x.len() {
                    let (vh, xn, _) = first(s + k, x[k], v[k]);
                    (v[k], x[k]) = (vh, xn);
                }
            });
        }
        // B and the forces at x_{n+1}.
        if magnetic {
            sys.forces.magnetic_field(&sys.state.x, &sys.model, &mut self.b);
        }
        let vel = if predict { &self.vp } else { &sys.state.v };
        sys.forces.eval_apart(&sys.state.x, vel, &sys.model, &mut self.f);
        sys.forces.book_power(0.5 * dt);
        self.p.clear();
        self.p.extend_from_slice(sys.forces.last_power());
        let (f, b) = (&self.f, &self.b);
        par::chunks2_any(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
            let mut bad_any = false;
            for k in 0..v.len() {
                let i = s + k;
                let w = v[k] + accel(f[i], im[i], g) * half;
                v[k] = store(if magnetic { half_turn(w, t(b, i)) } else { w }, single);
                bad_any |= bad(x[k], v[k]);
            }
            bad_any
        })
    }
    /// The non-magnetic forces (the magnetic force acts through the turn, not as a force).
    fn last_forces(&self) -> &[V] {
        &self.f
    }
    fn scratch(&mut self, velocity_dependent: bool) -> Vec<&mut Vec<V>> {
        if velocity_dependent {
            vec![&mut self.f, &mut self.vp]
        } else {
            vec![&mut self.f]
        }
    }
    fn axial_scratch(&mut self) -> Vec<&mut Vec<V::Axial>> {
        vec![&mut self.b]
    }
    fn reset(&mut self) {
        self.valid = false;
        self.b_valid = false;
    }
    fn as_carry(&self) -> Option<&dyn Carry<V>> {
        Some(self)
    }
    fn as_carry_mut(&mut self) -> Option<&mut dyn Carry<V>> {
        Some(self)
    }
}

impl<V: Vector> Carry<V> for Boris<V> {
    fn borrow(&self) -> Option<(&[V], &[Real])> {
        self.valid.then_some((&self.f[..], &self.p[..]))
    }
    /// The forces and powers; B is not part of the cache (it depends on the positions alone and
    /// is recomputed, to the same bits, at the next step).
    fn set(&mut self, f: Vec<V>, p: Vec<Real>, v: &[V], n_terms: usize) -> bool {
        let set = super::set_carried((&mut self.f, &mut self.p, &mut self.valid), f, p, v, n_terms);
        if set {
            self.b_valid = false;
        }
        set
    }
}

#[cfg(test)]
mod tests {
    use super::super::VelocityVerlet;
    use super::*;
    use crate::state::{Model, State};
    use crate::terms::electric_field::UniformElectricField;
    use crate::terms::{ForceSet, Pairwise, UniformMagneticField};
    use glam::{DVec2, DVec3};

    fn particles<V: Vector>(x: Vec<V>, v: Vec<V>, q: Vec<f64>, m: Vec<f64>) -> Particles<V> {
        let mut model = Model { inv_mass: m.iter().map(|m| 1.0 / m).collect(), mass: m, ..Default::default() };
        model.attributes.insert("charge", q);
        Particles { state: State { x, v }, model, forces: ForceSet::default(), single: false }
    }

    /// The full Boris rotation (Qin et al. eqs. 3–5) of `v` with parameter `t`.
    fn boris_rotation(v: DVec3, t: DVec3) -> DVec3 {
        let s = t * (2.0 / (1.0 + t.length_squared()));
        let w = v + v.cross(t);
        v + w.cross(s)
    }

    #[test]
    fn two_half_turns_are_the_boris_rotation() {
        let v = DVec3::new(0.3, -1.2, 0.7);
        for t in [DVec3::new(0.0, 0.0, 0.01), DVec3::new(0.4, -0.2, 0.9), DVec3::new(-3.0, 2.0, 5.0)] {
            let two = half_turn(half_turn(v, t), t);
            let one = boris_rotation(v, t);
            assert!((two - one).length() < 4e-16 * v.length(), "{two} vs {one}");
            // The angle between the components across t is 2 arctan|t|.
            let (n, vp) = (t.normalize(), |w: DVec3| w - t.normalize() * w.dot(t.normalize()));
            let (a, b) = (vp(v), vp(one));
            let angle = a.cross(b).dot(n).atan2(a.dot(b));
            assert!((angle.abs() - 2.0 * t.length().atan()).abs() < 1e-15, "{angle}");
        }
    }

    /// A charge in a uniform B (3D, B oblique, v with a parallel part): the speed and the
    /// parallel velocity keep to round-off, and the velocity turns by 2 arctan(ω_c dt/2) a step,
    /// clockwise about B for q > 0.
    #[test]
    fn a_pure_magnetic_field_turns_the_velocity_exactly() {
        let b = DVec3::new(0.3, -0.4, 1.2);
        let (q, m) = (2.0, 0.5);
        let wc = q * b.length() / m;
        for dt in [0.01 / wc, 0.7 / wc, 10.0 / wc] {
            let v0 = DVec3::new(1.0, 0.5, -0.25);
            let mut sys = particles(vec![DVec3::ZERO], vec![v0], vec![q], vec![m]);
            sys.forces.push(Box::new(UniformMagneticField::<DVec3> { name: "b".into(), b })).unwrap();
            let mut boris = Boris::default();
            let bh = b.normalize();
            let perp = |w: DVec3| w - bh * w.dot(bh);
            let want = 2.0 * (0.5 * wc * dt).atan();
            for _ in 0..500 {
                let before = sys.state.v[0];
                assert!(!boris.step(&mut sys, dt));
                let after = sys.state.v[0];
                let (a, c) = (perp(before), perp(after));
                let angle = a.cross(c).dot(bh).atan2(a.dot(c));
                assert!((angle + want).abs() < 1e-13, "dt {dt}: {angle} vs -{want}");
            }
            let v = sys.state.v[0];
            assert!((v.length_squared() / v0.length_squared() - 1.0).abs() < 1e-13, "dt {dt}");
            assert!((v.dot(bh) - v0.dot(bh)).abs() < 1e-14, "dt {dt}");
            assert_eq!(sys.forces.evaluations, 501);
        }
    }

    /// In 2D with B_z the orbit is a circle of radius r_L √(1 + (ω_c dt/2)²) about a fixed
    /// centre, which the positions keep to round-off.
    #[test]
    fn in_2d_the_orbit_is_the_discrete_circle() {
        let (q, m, bz, v0): (f64, f64, f64, f64) = (-1.5, 2.0, 0.8, 3.0);
        let wc = q.abs() * bz / m;
        let dt = 0.9 / wc;
        let mut sys = particles(vec![DVec2::ZERO], vec![DVec2::new(v0, 0.0)], vec![q], vec![m]);
        sys.forces.push(Box::new(UniformMagneticField::<DVec2> { name: "b".into(), b: bz })).unwrap();
        let mut boris = Boris::default();
        let mut xs = Vec::new();
        for _ in 0..200 {
            boris.step(&mut sys, dt);
            xs.push(sys.state.x[0]);
        }
        // The centre: the circle through three positions.
        let (a, b, c) = (xs[0], xs[1], xs[2]);
        let d = 2.0 * (a.x * (b.y - c.y) + b.x * (c.y - a.y) + c.x * (a.y - b.y));
        let centre = DVec2::new(
            (a.length_squared() * (b.y - c.y) + b.length_squared() * (c.y - a.y) + c.length_squared() * (a.y - b.y))
                / d,
            (a.length_squared() * (c.x - b.x) + b.length_squared() * (a.x - c.x) + c.length_squared() * (b.x - a.x))
                / d,
        );
        let r = m * v0 / (q.abs() * bz) * (1.0 + (0.5 * wc * dt).powi(2)).sqrt();
        for x in &xs {
            assert!(((*x - centre).length() - r).abs() < 1e-13 * r, "{} vs {r}", (*x - centre).length());
        }
        // A negative charge turns counter-clockwise about +z: the centre is to the left of +x.
        assert!(centre.y > 0.0);
    }

    /// Without magnetic terms the turns are the identity: velocity Verlet, bit for bit.
    #[test]
    fn without_a_magnetic_field_it_is_velocity_verlet_to_the_bit() {
        let make = || {
            let x = vec![DVec3::new(0.0, 0.0, 0.0), DVec3::new(1.0, 0.2, 0.0), DVec3::new(0.3, 1.0, -0.4)];
            let v = vec![DVec3::new(0.1, 0.0, 0.0), DVec3::ZERO, DVec3::new(0.0, -0.2, 0.1)];
            let mut sys = particles(x, v, vec![1.0, -0.5, 0.7], vec![1.0, 2.0, 0.5]);
            sys.forces.push(Box::new(Pairwise::coulomb("c".into(), 1.0, 0.1))).unwrap();
            let e = UniformElectricField::<DVec3> { name: "e".into(), e: DVec3::new(0.5, 0.0, -0.2) };
            sys.forces.push(Box::new(e)).unwrap();
            sys
        };
        let (mut a, mut b) = (make(), make());
        let (mut boris, mut verlet) = (Boris::default(), VelocityVerlet::default());
        for _ in 0..300 {
            boris.step(&mut a, 0.01);
            verlet.step(&mut b, 0.01);
        }
        assert_eq!(a.state, b.state);
        assert_eq!(a.forces.evaluations, b.forces.evaluations);
    }
}
