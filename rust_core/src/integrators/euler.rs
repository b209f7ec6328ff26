//! Explicit (forward) Euler: x' = x + dt v, v' = v + dt a(x, v). First order, not symplectic;
//! energy grows for every dt on an oscillator. Included for contrast.
use super::{accel, bad, ensure_len, store, Integrator, IntegratorInfo, Particles};
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
                x[k] = store(x[k] + v[k] * dt, single);
                v[k] = store(v[k] + accel(f[i], im[i], g) * dt, single);
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
