//! Semi-implicit (symplectic) Euler, kick then drift: v' = v + dt a(x, v); x' = x + dt v'.
//! First order, symplectic: bounded energy error on conservative systems for ω·dt < 2.
//! Velocity-dependent forces are taken at the step's start (v in a(x, v) is the old one); a
//! magnetic force q v × B then grows |v|² by (ω_c dt)² a step (use "boris").
//!
//! Terms that project velocities (the `VelocityProjection` role: DFSPH, Bender & Koschier 2017,
//! Algorithm 1) get the step in three parts, all at the step's start positions x:
//! v ← P_div(v) (divergence solve); v' = v + dt a(x, v); v' ← P_ρ(v') (density solve); x' = x + dt v'.
//! This is the paper's loop with its divergence solve moved from the end of one step to the
//! start of the next (the same positions, so one neighbour search serves a whole step). The
//! kinetic energy each projection removes is booked as the term's dissipation.
use super::{accel, bad, ensure_len, store, Integrator, IntegratorInfo, Particles};
use crate::par;
use crate::terms::Projection;
use crate::vector::{Real, Vector};

#[derive(Default)]
pub struct SemiImplicitEuler<V: Vector> {
    f: Vec<V>,
}

impl<V: Vector> SemiImplicitEuler<V> {
    /// The step with velocity projections (module doc).
    fn step_projected(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let project = |sys: &mut Particles<V>, stage: Projection| {
            let Particles { state, model, forces, .. } = sys;
            forces.project_velocities(stage, &state.x, &mut state.v, model, dt);
        };
        project(sys, Projection::Divergence);
        sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
        sys.forces.book_power(dt);
        let (f, im, g) = (&self.f, &sys.model.inv_mass, sys.forces.g);
        par::chunks1(&mut sys.state.v, |s, v| {
            for (k, vk) in v.iter_mut().enumerate() {
                *vk += accel(f[s + k], im[s + k], g) * dt;
            }
        });
        project(sys, Projection::Density);
        let single = sys.single;
        par::chunks2_any(&mut sys.state.x, &mut sys.state.v, |_, x, v| {
            let mut b = false;
            for k in 0..x.len() {
                v[k] = store(v[k], single);
                x[k] = store(x[k] + v[k] * dt, single);
                b |= bad(x[k], v[k]);
            }
            b
        })
    }
}

impl<V: Vector> Integrator<V> for SemiImplicitEuler<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "semi_implicit_euler", order: 1, symplectic: true, force_evals_per_step: 1 }
    }
    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let n = sys.state.x.len();
        ensure_len(&mut self.f, n);
        if sys.forces.projects_velocities() {
            return self.step_projected(sys, dt);
        }
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
