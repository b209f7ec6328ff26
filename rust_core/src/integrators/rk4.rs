//! Classic fourth-order Runge–Kutta on (x, v) (Kutta 1901; Hairer, Nørsett & Wanner, Solving
//! ODEs I, Table 1.2). Fourth order, not symplectic, four force evaluations per step.
use super::{accel, bad, ensure_len, store, Integrator, IntegratorInfo, Particles};
use crate::par;
use crate::vector::{Real, Vector};

#[derive(Default)]
pub struct Rk4<V: Vector> {
    f: Vec<V>,
    xs: Vec<V>,
    vs: Vec<V>,
    ax: Vec<V>,
    av: Vec<V>,
}

impl<V: Vector> Integrator<V> for Rk4<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "rk4", order: 4, symplectic: false, force_evals_per_step: 4 }
    }
    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let n = sys.state.x.len();
        for b in [&mut self.f, &mut self.xs, &mut self.vs, &mut self.ax, &mut self.av] {
            ensure_len(b, n);
        }
        let (im, g) = (&sys.model.inv_mass, sys.forces.g);
        let (x0, v0) = (&sys.state.x, &sys.state.v);

        // Stage 1 at (x, v).
        sys.forces.eval(x0, v0, &sys.model, &mut self.f);
        sys.forces.book_power(dt / 6.0);
        let f = &self.f;
        par::chunks4(&mut self.xs, &mut self.vs, &mut self.ax, &mut self.av, |s, xs, vs, ax, av| {
            for k in 0..xs.len() {
                let i = s + k;
                let a = accel(f[i], im[i], g);
                ax[k] = v0[i];
                av[k] = a;
                xs[k] = x0[i] + v0[i] * (0.5 * dt);
                vs[k] = v0[i] + a * (0.5 * dt);
            }
        });
        // Stages 2 and 3 at the midpoints; weights 2/6.
        for stage_dt in [0.5 * dt, dt] {
            sys.forces.eval(&self.xs, &self.vs, &sys.model, &mut self.f);
            sys.forces.book_power(dt / 3.0);
            let f = &self.f;
            par::chunks4(&mut self.xs, &mut self.vs, &mut self.ax, &mut self.av, |s, xs, vs, ax, av| {
                for k in 0..xs.len() {
                    let i = s + k;
                    let a = accel(f[i], im[i], g);
                    ax[k] += vs[k] * 2.0;
                    av[k] += a * 2.0;
                    xs[k] = x0[i] + vs[k] * stage_dt;
                    vs[k] = v0[i] + a * stage_dt;
                }
            });
        }
        // Stage 4 at the end point, then the weighted update.
        sys.forces.eval(&self.xs, &self.vs, &sys.model, &mut self.f);
        sys.forces.book_power(dt / 6.0);
        let (f, vs, ax, av) = (&self.f, &self.vs, &self.ax, &self.av);
        let w = dt / 6.0;
        let single = sys.single;
        par::chunks2_any(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
            let mut b = false;
            for k in 0..x.len() {
                let i = s + k;
                x[k] = store(x[k] + (ax[i] + vs[i]) * w, single);
                v[k] = store(v[k] + (av[i] + accel(f[i], im[i], g)) * w, single);
                b |= bad(x[k], v[k]);
            }
            b
        })
    }
    fn last_forces(&self) -> &[V] {
        &self.f
    }
    fn scratch(&mut self, _velocity_dependent: bool) -> Vec<&mut Vec<V>> {
        vec![&mut self.f, &mut self.xs, &mut self.vs, &mut self.ax, &mut self.av]
    }
}
