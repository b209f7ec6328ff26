//! Explicit (forward) Euler: x' = x + dt v, v' = v + dt a(x, v). First order, not symplectic;
//! energy grows for every dt on an oscillator. Included for contrast.
use super::{accel, ensure_len, Integrator, IntegratorInfo, System};
use crate::par;
use crate::vector::{Real, Vector};

#[derive(Default)]
pub struct ExplicitEuler<V: Vector> {
    f: Vec<V>,
}

impl<V: Vector> Integrator<V> for ExplicitEuler<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "euler", order: 1, symplectic: false, force_evals_per_step: 1 }
    }
    fn step(&mut self, sys: &mut System<V>, dt: Real) {
        let n = sys.state.x.len();
        ensure_len(&mut self.f, n);
        sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
        sys.forces.book_power(dt);
        let (f, im) = (&self.f, &sys.model.inv_mass);
        par::chunks2(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
            for k in 0..x.len() {
                let i = s + k;
                x[k] += v[k] * dt;
                v[k] += accel(f[i], im[i]) * dt;
            }
        });
    }
    fn last_forces(&self) -> &[V] {
        &self.f
    }
}
