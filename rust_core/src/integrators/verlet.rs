//! Velocity Verlet (kick–drift–kick, Swope et al. 1982, J. Chem. Phys. 76, 637):
//!   v½ = v + ½dt a(x);  x' = x + dt v½;  v' = v½ + ½dt a(x')
//! Second order, symplectic, time-reversible. The force at x' is kept for the next step
//! ("first same as last"), so it costs one force evaluation per step.
//!
//! Velocity-dependent forces (drag, dashpots, the magnetic force q v × B) at x' are evaluated
//! with the predicted velocity v + dt a(x, v), whose O(dt²) error keeps the method second
//! order; evaluating them with v½ (a common shortcut) would drop it to first order. Without
//! such forces the prediction is skipped and the method is exactly the symplectic velocity
//! Verlet.
use super::{accel, bad, ensure_len, store, Carry, Integrator, IntegratorInfo, Particles};
use crate::par;
use crate::vector::{Real, Vector};

#[derive(Default)]
pub struct VelocityVerlet<V: Vector> {
    f: Vec<V>,
    /// Term powers at the cached force state (for trapezoidal dissipation books).
    p: Vec<Real>,
    /// Predicted end-of-step velocities (only with velocity-dependent forces).
    vp: Vec<V>,
    valid: bool,
}

impl<V: Vector> Integrator<V> for VelocityVerlet<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "verlet", order: 2, symplectic: true, force_evals_per_step: 1 }
    }
    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let n = sys.state.x.len();
        if !self.valid || self.f.len() != n {
            ensure_len(&mut self.f, n);
            sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
            self.p = sys.forces.last_power().to_vec();
            self.valid = true;
        }
        // Dissipation by the trapezoidal rule: ½dt (P_start + P_end).
        sys.forces.set_last_power(&self.p);
        sys.forces.book_power(0.5 * dt);
        let half = 0.5 * dt;
        let (f, im, g, single) = (&self.f, &sys.model.inv_mass, sys.forces.g, sys.single);
        if sys.forces.velocity_dependent() {
            ensure_len(&mut self.vp, n);
            par::chunks3(&mut sys.state.x, &mut sys.state.v, &mut self.vp, |s, x, v, vp| {
                for k in 0..x.len() {
                    let i = s + k;
                    let a = accel(f[i], im[i], g);
                    vp[k] = store(v[k] + a * dt, single);
                    v[k] = store(v[k] + a * half, single);
                    x[k] = store(x[k] + v[k] * dt, single);
                }
            });
            sys.forces.eval(&sys.state.x, &self.vp, &sys.model, &mut self.f);
        } else {
            par::chunks2(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
                for k in 0..x.len() {
                    let i = s + k;
                    v[k] = store(v[k] + accel(f[i], im[i], g) * half, single);
                    x[k] = store(x[k] + v[k] * dt, single);
                }
            });
            sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
        }
        sys.forces.book_power(0.5 * dt);
        self.p.clear();
        self.p.extend_from_slice(sys.forces.last_power());
        let f = &self.f;
        par::chunks2_any(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
            let mut b = false;
            for k in 0..v.len() {
                let i = s + k;
                v[k] = store(v[k] + accel(f[i], im[i], g) * half, single);
                b |= bad(x[k], v[k]);
            }
            b
        })
    }
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
    fn reset(&mut self) {
        self.valid = false;
    }
    fn as_carry(&self) -> Option<&dyn Carry<V>> {
        Some(self)
    }
    fn as_carry_mut(&mut self) -> Option<&mut dyn Carry<V>> {
        Some(self)
    }
}

impl<V: Vector> Carry<V> for VelocityVerlet<V> {
    fn borrow(&self) -> Option<(&[V], &[Real])> {
        self.valid.then_some((&self.f[..], &self.p[..]))
    }
    fn parts(&mut self) -> Option<(&mut Vec<V>, &mut Vec<Real>, &mut bool)> {
        Some((&mut self.f, &mut self.p, &mut self.valid))
    }
    fn set(&mut self, f: Vec<V>, p: Vec<Real>, v: &[V], n_terms: usize) -> bool {
        super::set_carried((&mut self.f, &mut self.p, &mut self.valid), f, p, v, n_terms)
    }
}
