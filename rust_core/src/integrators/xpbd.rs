//! XPBD with substeps: Macklin, Müller & Chentanez, "XPBD: position-based simulation of
//! compliant constrained dynamics", MIG 2016 (Algorithm 1), stepped as in Macklin, Storey, Lu,
//! Terdiman, Chentanez, Jeschke & Müller, "Small steps in physics simulation", SCA 2019: a step
//! of `dt` is `substeps` substeps of h = dt/substeps, each
//!
//! ```text
//! v += h (f_ext/m + g);  x_prev = x;  x += h v       (predict: semi-implicit Euler)
//! λ = 0; repeat `iterations` times: project every constraint set (Gauss–Seidel)
//! v = (x − x_prev)/h
//! ```
//!
//! External forces come from the scene's force terms (gravity, drag, springs, contacts, ...),
//! evaluated once per substep (terms with a state of their own get `begin_step` / `end_step`
//! per substep, and the step limits of the force terms hold per substep); the constraints are the terms with `Term::xpbd_constraints` (terms/xpbd.rs).
//! The paper's choice is many substeps with one iteration each (the default here: 10 and 1).
//! Without constraints a substep is exactly semi-implicit Euler at h.
//!
//! Energy books. The projection is implicit Euler on the constraint potential and damps; the
//! energy it removes is measured, not assumed: the change, across each term's projection, of the
//! energy H̃ = Σ ½ m |u|² + Σ U(x) + ½ Σ f_ext·(x − x_prev), with u = (x − x_prev)/h the velocity
//! the substep will end with, U the potentials of every term (the constraints' own Σ C²/(2α)
//! included) and f_ext the external force of the substep (m g included), plus the change of the
//! term's own potential during the predict (which moves x without the constraint forces: the
//! projection applies them). The last sum of H̃ is symplectic Euler's first-order correction of
//! the energy (H̃ = H + (h/2) F·v, which its kick and drift keep exactly in a uniform field), so
//! the predict's own error (½ m |g|² h² a substep in free fall) is not booked as the
//! projection's: a mass hanging at rest books no dissipation.
//! What is booked (J) goes to the term's dissipated energy; it can be negative (a projection that
//! adds energy, e.g. when a large step meets a stiff constraint far from its rest state).
//! Cost: every substep evaluates the potentials of all terms 1 + iterations × (constraint terms)
//! times, and the constraint terms' twice more.
use super::{accel, bad, ensure_len, store, Integrator, IntegratorInfo, Particles};
use crate::par;
use crate::vector::{Real, Vector};

pub struct Xpbd<V: Vector> {
    f: Vec<V>,
    x_prev: Vec<V>,
    /// Substeps per step (≥ 1).
    pub substeps: u32,
    /// Gauss–Seidel iterations per substep (≥ 1).
    pub iterations: u32,
    /// Tests only: reset λ before every iteration (the bug the paper's λ accumulation avoids).
    #[cfg(test)]
    reset_each_iteration: bool,
}

impl<V: Vector> Default for Xpbd<V> {
    fn default() -> Self {
        Self {
            f: Vec::new(),
            x_prev: Vec::new(),
            substeps: 10,
            iterations: 1,
            #[cfg(test)]
            reset_each_iteration: false,
        }
    }
}

/// H̃ at positions `x` (see the module doc).
fn energy<V: Vector>(sys: &Particles<V>, x: &[V], x_prev: &[V], f: &[V], h: Real) -> Real {
    let (m, g) = (&sys.model, sys.forces.g);
    let kin = par::sum(x.len(), 0.0, |r| {
        let mut e = 0.0;
        for i in r {
            if m.inv_mass[i] != 0.0 {
                let d = x[i] - x_prev[i];
                e += 0.5 * m.mass[i] * (d / h).length_squared() + 0.5 * (f[i] + g * m.mass[i]).dot(d);
            }
        }
        e
    });
    let pot: Real = sys.forces.terms.iter().filter_map(|t| t.potential(x, m)).sum();
    kin + pot
}

impl<V: Vector> Integrator<V> for Xpbd<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "xpbd", order: 1, symplectic: false, force_evals_per_step: self.substeps }
    }
    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let n = sys.state.x.len();
        ensure_len(&mut self.f, n);
        ensure_len(&mut self.x_prev, n);
        let h = dt / self.substeps as Real;
        let projecting: Vec<usize> = sys.forces.constraint_terms().to_vec();
        let mut any_bad = false;
        let mut u_start = vec![0.0; projecting.len()];
        for _ in 0..self.substeps {
            // The constraints' potential before the predict moves x without their forces.
            for (u, &k) in u_start.iter_mut().zip(&projecting) {
                *u = sys.forces.terms[k].potential(&sys.state.x, &sys.model).unwrap_or(0.0);
            }
            // Terms with a state of their own (contacts) step with the substeps.
            for s in sys.forces.terms.iter_mut().filter_map(|t| t.as_own_state_mut()) {
                s.begin_step(h);
            }
            sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
            sys.forces.book_power(h);
            let (f, im, g, single) = (&self.f, &sys.model.inv_mass, sys.forces.g, sys.single);
            par::chunks3(&mut sys.state.x, &mut sys.state.v, &mut self.x_prev, |s, x, v, xp| {
                xp.copy_from_slice(x);
                for k in 0..x.len() {
                    let i = s + k;
                    v[k] += accel(f[i], im[i], g) * h;
                    x[k] += v[k] * h;
                }
            });
            if !projecting.is_empty() {
                for s in sys.forces.terms.iter_mut().filter_map(|t| t.as_own_state_mut()) {
                    s.after_predict(&sys.state.x, &sys.state.v, &sys.model, h);
                }
                for &k in &projecting {
                    if let Some(c) = sys.forces.terms[k].as_constraints() {
                        c.begin();
                    }
                }
                let mut e = energy(sys, &sys.state.x, &self.x_prev, &self.f, h);
                // The predict changed the constraints' potential with no constraint force acting:
                // that change is the projection's to answer for (it applies those forces).
                for (u, &k) in u_start.iter().zip(&projecting) {
                    let u_pred = sys.forces.terms[k].potential(&sys.state.x, &sys.model).unwrap_or(0.0);
                    sys.forces.dissipated[k] += u - u_pred;
                }
                for _it in 0..self.iterations {
                    for &k in &projecting {
                        let Some(c) = sys.forces.terms[k].as_constraints() else { continue };
                        #[cfg(test)]
                        if self.reset_each_iteration && _it > 0 {
                            c.begin();
                        }
                        c.project(&mut sys.state.x, &sys.model, h);
                        let e2 = energy(sys, &sys.state.x, &self.x_prev, &self.f, h);
                        sys.forces.dissipated[k] += e - e2;
                        e = e2;
                    }
                }
            }
            // Without constraints the predicted velocity stands (recomputing it from the
            // positions would only add round-off): the substep is semi-implicit Euler.
            let (xp, moved) = (&self.x_prev, !projecting.is_empty());
            any_bad |= par::chunks2_any(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
                let mut b = false;
                for k in 0..x.len() {
                    let i = s + k;
                    if moved && im[i] != 0.0 {
                        v[k] = (x[k] - xp[i]) / h;
                    }
                    v[k] = store(v[k], single);
                    x[k] = store(x[k], single);
                    b |= bad(x[k], v[k]);
                }
                b
            });
            for s in sys.forces.terms.iter_mut().filter_map(|t| t.as_own_state_mut()) {
                s.end_step(&sys.state.x, &sys.state.v, &sys.model, h);
            }
        }
        any_bad
    }
    fn last_forces(&self) -> &[V] {
        &self.f
    }
    fn scratch(&mut self, _velocity_dependent: bool) -> Vec<&mut Vec<V>> {
        vec![&mut self.f, &mut self.x_prev]
    }
    fn configure(&mut self, o: &super::IntegratorOptions) {
        self.substeps = o.xpbd_substeps.max(1);
        self.iterations = o.xpbd_iterations.max(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::{Model, State};
    use crate::terms::registry::{lookup, Context, Params, Value};
    use crate::terms::{ForceSet, UniformGravity};
    use glam::{DVec2, DVec3};

    /// A particle of mass m hanging from a pinned one on a distance constraint of rest length 1
    /// and compliance α, settled: the stretch is m g α (Hooke's law with k = 1/α).
    fn hang(alpha: Real, substeps: u32, iterations: u32, dt: Real) -> Real {
        hang_with(alpha, substeps, iterations, dt, false)
    }

    fn hang_with(alpha: Real, substeps: u32, iterations: u32, dt: Real, reset: bool) -> Real {
        let (m, g) = (0.5, 9.81);
        let mut sys = Particles::<DVec2> {
            state: State { x: vec![DVec2::ZERO, DVec2::new(0.0, -1.0)], v: vec![DVec2::ZERO; 2] },
            model: Model { mass: vec![1.0, m], inv_mass: vec![0.0, 1.0 / m], attributes: Default::default() },
            forces: ForceSet::default(),
            single: false,
        };
        sys.forces.push(Box::new(UniformGravity { name: "g".into(), g: DVec2::new(0.0, -g) })).unwrap();
        let p = Params::new()
            .with("distance", Value::Indices(vec![0, 1]))
            .with("distance_rest", Value::Floats(vec![1.0]))
            .with("distance_compliance", Value::Floats(vec![alpha]));
        let t = lookup("xpbd_constraints").unwrap().build::<DVec2>("c".into(), p, &Context { n_particles: 2 }).unwrap();
        sys.forces.push(t).unwrap();
        let mut it = Xpbd::default();
        it.configure(&crate::integrators::IntegratorOptions {
            xpbd_substeps: substeps,
            xpbd_iterations: iterations,
            ..Default::default()
        });
        it.reset_each_iteration = reset;
        // A damped settle: XPBD's own damping brings the bob to rest.
        for _ in 0..(60.0 / dt) as usize {
            assert!(!it.step(&mut sys, dt));
        }
        let stretch = -sys.state.x[1].y - 1.0;
        stretch / (m * g * alpha)
    }

    #[test]
    fn xpbd_stretch_is_m_g_alpha_whatever_the_solver() {
        for (substeps, iterations, dt) in [(1, 1, 1e-2), (1, 20, 1e-2), (10, 1, 1e-2), (4, 5, 5e-3), (1, 1, 1e-3)] {
            let r = hang(1e-3, substeps, iterations, dt);
            assert!((r - 1.0).abs() < 1e-6, "substeps {substeps}, iterations {iterations}, dt {dt}: stretch/mgα = {r}");
        }
    }

    #[test]
    fn xpbd_books_balance_and_a_mass_at_rest_books_nothing() {
        let (m, g, alpha) = (0.5, 9.81, 1e-3);
        let mut sys = Particles::<DVec2> {
            state: State { x: vec![DVec2::ZERO, DVec2::new(0.0, -1.0 - m * g * alpha)], v: vec![DVec2::ZERO; 2] },
            model: Model { mass: vec![1.0, m], inv_mass: vec![0.0, 1.0 / m], attributes: Default::default() },
            forces: ForceSet::default(),
            single: false,
        };
        sys.forces.push(Box::new(UniformGravity { name: "g".into(), g: DVec2::new(0.0, -g) })).unwrap();
        let p = Params::new()
            .with("distance", Value::Indices(vec![0, 1]))
            .with("distance_rest", Value::Floats(vec![1.0]))
            .with("distance_compliance", Value::Floats(vec![alpha]));
        let t = lookup("xpbd_constraints").unwrap().build::<DVec2>("c".into(), p, &Context { n_particles: 2 }).unwrap();
        sys.forces.push(t).unwrap();
        let mut it = Xpbd::default();
        let books = |sys: &Particles<DVec2>| {
            let k = 0.5 * m * sys.state.v[1].length_squared();
            let u: Real = sys.forces.terms.iter().filter_map(|t| t.potential(&sys.state.x, &sys.model)).sum();
            (k + u + sys.forces.dissipated[1], sys.forces.dissipated[1])
        };
        for _ in 0..1000 {
            it.step(&mut sys, 1e-2);
        }
        assert!(books(&sys).1.abs() < 1e-12, "at rest: {}", books(&sys).1);
        // Swinging (kinetic energy 1 J): the books balance to the bounded difference between the
        // energy and its symplectic-Euler form, ½ m g |v| h ≈ 5e-3 J, while the projection
        // dissipates more than that.
        sys.state.v[1] = DVec2::new(2.0, 0.0);
        let (e0, d0) = books(&sys);
        for _ in 0..1000 {
            it.step(&mut sys, 1e-2);
            let (e, _) = books(&sys);
            assert!((e - e0).abs() < 1e-2, "total {e} vs {e0}");
        }
        assert!(books(&sys).1 - d0 > 1e-2, "dissipated {}", books(&sys).1 - d0);
    }

    #[test]
    fn xpbd_resetting_lambda_each_iteration_changes_the_stiffness() {
        // The failure the stretch test must be able to catch: with λ reset every iteration, 20
        // iterations make the constraint about 20 times stiffer than 1 iteration does.
        let one = hang_with(1e-3, 1, 1, 1e-2, true);
        let twenty = hang_with(1e-3, 1, 20, 1e-2, true);
        assert!((one - 1.0).abs() < 1e-6, "{one}");
        assert!(twenty < 0.2, "stretch/mgα with 20 reset iterations: {twenty}");
    }

    #[test]
    fn xpbd_rigid_pendulum_keeps_its_length_3d() {
        let mut sys = Particles::<DVec3> {
            state: State { x: vec![DVec3::ZERO, DVec3::new(1.0, 0.0, 0.0)], v: vec![DVec3::ZERO; 2] },
            model: Model { mass: vec![1.0, 1.0], inv_mass: vec![0.0, 1.0], attributes: Default::default() },
            forces: ForceSet::default(),
            single: false,
        };
        sys.forces.push(Box::new(UniformGravity { name: "g".into(), g: DVec3::new(0.0, 0.0, -9.81) })).unwrap();
        let p = Params::new()
            .with("distance", Value::Indices(vec![0, 1]))
            .with("distance_rest", Value::Floats(vec![1.0]))
            .with("distance_compliance", Value::Floats(vec![0.0]));
        let t = lookup("xpbd_constraints").unwrap().build::<DVec3>("c".into(), p, &Context { n_particles: 2 }).unwrap();
        sys.forces.push(t).unwrap();
        let mut it = Xpbd::default();
        for _ in 0..1000 {
            it.step(&mut sys, 1e-3);
            assert!((sys.state.x[1].length() - 1.0).abs() < 1e-12);
        }
    }
}
