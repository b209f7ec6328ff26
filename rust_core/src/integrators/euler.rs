//! Explicit (forward) Euler: x' = x + dt v, v' = v + dt a(x, v). First order, not symplectic;
//! energy grows for every dt on an oscillator. Included for contrast.
use super::{accel, bad, ensure_len, Integrator, IntegratorInfo, System};
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
    fn step(&mut self, sys: &mut System<V>, dt: Real) -> bool {
        let n = sys.state.x.len();
        ensure_len(&mut self.f, n);
        sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
        sys.forces.book_power(dt);
        let (f, im, g) = (&self.f, &sys.model.inv_mass, sys.forces.g);
        par::chunks2_any(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
            let mut b = false;
            for k in 0..x.len() {
                let i = s + k;
                x[k] += v[k] * dt;
                v[k] += accel(f[i], im[i], g) * dt;
                b |= bad(x[k], v[k]);
            }
            b
        })
    }
    fn last_forces(&self) -> &[V] {
        &self.f
    }
}
