//! Semi-implicit (symplectic) Euler, kick then drift: v' = v + dt a(x, v); x' = x + dt v'.
//! First order, symplectic: bounded energy error on conservative systems for ω·dt < 2.
//! Velocity-dependent forces are taken at the step's start (v in a(x, v) is the old one); a
//! magnetic force q v × B then grows |v|² by (ω_c dt)² a step (use "boris").
use super::{accel, bad, ensure_len, store, Integrator, IntegratorInfo, Particles};
use crate::par;
use crate::vector::{Real, Vector};

#[derive(Default)]
pub struct SemiImplicitEuler<V: Vector> {
    f: Vec<V>,
}

impl<V: Vector> Integrator<V> for SemiImplicitEuler<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "semi_implicit_euler", order: 1, symplectic: true, force_evals_per_step: 1 }
    }
    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let n = sys.state.x.len();
        ensure_len(&mut self.f, n);
        sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
        sys.forces.book_power(dt);
        let (f, im, g, single) = (&self.f, &sys.model.inv_mass, sys.forces.g, sys.single);
        par::chunks2_any(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
            let mut b = false;
            for k in 0..x.len() {
                let i = s + k;
                v[k] = store(v[k] + accel(f[i], im[i], g) * dt, single);
                x[k] = store(x[k] + v[k] * dt, single);
                b |= bad(x[k], v[k]);
            }
            b
        })
    }
    fn last_forces(&self) -> &[V] {
        &self.f
    }
    fn scratch(&mut self, _velocity_dependent: bool) -> Vec<&mut Vec<V>> {
        vec![&mut self.f]
    }
}
