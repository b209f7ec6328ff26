//! Linearised implicit (backward) Euler for stiff springs (Baraff & Witkin 1998, "Large steps
//! in cloth simulation", SIGGRAPH, §3 and §5):
//!
//!   (M − h ∂f/∂v − h² ∂f/∂x) Δv = h (f0 + h (∂f/∂x) v0),   v' = v0 + Δv,   x' = x0 + h v',
//!
//! one Newton iteration of backward Euler, with f0 and the Jacobians at the step's start. The
//! system is solved matrix-free by the conjugate gradient method with a Jacobi (diagonal)
//! preconditioner; the terms supply the products (∂f/∂x)·w and (∂f/∂v)·w (the `Jacobian`
//! role), gathered per particle, and the dot products are summed over fixed chunks
//! in chunk order (`par`), so results are bit-identical for any thread count. Pinned particles
//! (inverse mass 0) are filtered out of the system as in B&W's modified PCG (§5.3): their rows
//! of the residual, the search directions and Δv are held at zero, so they never move.
//!
//! Which terms are implicit: springs (with the definiteness fix for compressed springs, see
//! `terms::springs`) and linear drag (∂f/∂v = −b I) have Jacobians. Uniform fields (gravity) are
//! constant and thus exact. Every other term (pairwise gravity, SPH, charges, magnetic fields)
//! has no Jacobian and is taken explicitly at the step's start: its own explicit stability limit
//! still applies (`auto_dt` keeps it).
//!
//! Stability and cost: for springs and drag the method is unconditionally stable (an undamped
//! oscillator of frequency ω shrinks by 1/√(1 + ω²h²) per step), so stiff cloth may take steps
//! 10–100× the explicit limit; each step costs one force evaluation (the count reported) plus
//! one Jacobian product per CG iteration (counted in `solver_stats`), and the iteration count
//! grows with ω_max h.
//!
//! Numerical damping: backward Euler dissipates energy that no term books, so the energy books
//! (kinetic + potential + dissipated by the terms, the dashpots' and drag's power booked at the
//! step's start) do not balance: that residual IS the integrator's damping, and it is large at
//! large steps (the fast modes are damped within a few steps). It is first order, not
//! symplectic: use it where stiffness, not accuracy, would set the explicit step.
//!
//! CG stops at a relative residual `tol` (‖r‖ ≤ tol ‖rhs‖, Euclidean norm, default 1e-8) or
//! after `max_iter` iterations (default 200). A solve that stops unconverged keeps its last
//! iterate (a finite, first-order-consistent but less accurate step) and is counted in
//! `solver_stats().unconverged`, with the worst relative residual seen: read them after a run
//! (Python: `Scene.integrator_stats`). The stop flag (Ctrl-C) is polled at every CG iteration.
use super::{bad, ensure_len, store, Integrator, IntegratorInfo, Particles, SolverStats, Stopped};
use crate::par;
use crate::vector::{Real, Vector};
use std::sync::atomic::{AtomicBool, Ordering};

/// Default relative residual of the CG solve.
pub const DEFAULT_TOL: Real = 1e-8;
/// Default iteration limit of the CG solve.
pub const DEFAULT_MAX_ITER: u32 = 200;

pub struct ImplicitEuler<V: Vector> {
    /// Forces at the step's start (N).
    f: Vec<V>,
    /// Δv (m/s), the unknown.
    dv: Vec<V>,
    /// Residual r = rhs − A Δv (N·s).
    r: Vec<V>,
    /// Search direction p and q = A p.
    p: Vec<V>,
    q: Vec<V>,
    /// Inverse of A's diagonal (0 on pinned particles: the filter).
    pinv: Vec<V>,
    tol: Real,
    max_iter: u32,
    stats: SolverStats,
}

impl<V: Vector> Default for ImplicitEuler<V> {
    fn default() -> Self {
        Self {
            f: Vec::new(),
            dv: Vec::new(),
            r: Vec::new(),
            p: Vec::new(),
            q: Vec::new(),
            pinv: Vec::new(),
            tol: DEFAULT_TOL,
            max_iter: DEFAULT_MAX_ITER,
            stats: SolverStats::default(),
        }
    }
}

/// Component-wise product.
#[inline(always)]
fn mul<V: Vector>(a: V, b: V) -> V {
    let mut c = [0.0; 3];
    for (k, ck) in c.iter_mut().enumerate().take(V::DIM) {
        *ck = a.comp(k) * b.comp(k);
    }
    V::from_slice(&c[..V::DIM])
}

/// Deterministic Σ a_i·b_i (fixed chunks, chunk order).
fn dot<V: Vector>(a: &[V], b: &[V]) -> Real {
    par::sum(a.len(), 0.0, |r| {
        let mut s = 0.0;
        for i in r {
            s += a[i].dot(b[i]);
        }
        s
    })
}

impl<V: Vector> ImplicitEuler<V> {
    /// `out = M w + Σ_terms (cx ∂f/∂x + cv ∂f/∂v) w` (pinned rows included; callers filter).
    fn apply(sys: &Particles<V>, c: (Real, Real), w: &[V], out: &mut [V]) {
        let m = &sys.model.mass;
        par::chunks1(out, |s, o| {
            for (k, ok) in o.iter_mut().enumerate() {
                *ok = w[s + k] * m[s + k];
            }
        });
        for j in sys.forces.terms.iter().filter_map(|t| t.as_jacobian()) {
            j.product(&sys.state.x, &sys.state.v, &sys.model, c, w, out);
        }
    }
}

impl<V: Vector> Integrator<V> for ImplicitEuler<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "implicit_euler", order: 1, symplectic: false, force_evals_per_step: 1 }
    }

    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let never = AtomicBool::new(false);
        self.step_interruptible(sys, dt, &never).unwrap_or(true)
    }

    fn step_interruptible(
        &mut self,
        sys: &mut Particles<V>,
        h: Real,
        stop: &AtomicBool,
    ) -> std::result::Result<bool, Stopped> {
        let n = sys.state.x.len();
        for b in [&mut self.f, &mut self.dv, &mut self.r, &mut self.p, &mut self.q, &mut self.pinv] {
            ensure_len(b, n);
        }
        // f0, and the dissipation books at the step's start (as semi-implicit Euler books them).
        sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
        sys.forces.book_power(h);
        if stop.load(Ordering::Relaxed) {
            return Err(Stopped);
        }
        for j in sys.forces.terms.iter_mut().filter_map(|t| t.as_jacobian_mut()) {
            j.prepare(&sys.state.x, &sys.state.v, &sys.model);
        }
        let (im, g) = (&sys.model.inv_mass, sys.forces.g);
        // rhs = h (f0 + m g) + h² (∂f/∂x) v0, filtered (0 on pinned particles); into r.
        Self::apply(sys, (h * h, 0.0), &sys.state.v, &mut self.q);
        {
            let (f, q, m, v) = (&self.f, &self.q, &sys.model.mass, &sys.state.v);
            par::chunks1(&mut self.r, |s, r| {
                for (k, rk) in r.iter_mut().enumerate() {
                    let i = s + k;
                    // q = M v0 + h² J_x v0.
                    *rk = if im[i] == 0.0 { V::ZERO } else { (f[i] + g * m[i]) * h + (q[i] - v[i] * m[i]) };
                }
            });
        }
        // Jacobi preconditioner: 1 / diag(M − h ∂f/∂v − h² ∂f/∂x), 0 on pinned particles.
        let c = (-h * h, -h);
        {
            let m = &sys.model.mass;
            par::chunks1(&mut self.pinv, |s, d| {
                for (k, dk) in d.iter_mut().enumerate() {
                    *dk = V::from_slice(&[m[s + k]; 3][..V::DIM]);
                }
            });
        }
        for j in sys.forces.terms.iter().filter_map(|t| t.as_jacobian()) {
            j.diagonal(&sys.state.x, &sys.state.v, &sys.model, c, &mut self.pinv);
        }
        par::chunks1(&mut self.pinv, |s, d| {
            for (k, dk) in d.iter_mut().enumerate() {
                let mut inv = [0.0; 3];
                if im[s + k] != 0.0 {
                    for (q, iq) in inv.iter_mut().enumerate().take(V::DIM) {
                        // The diagonal is ≥ m > 0 (the Jacobians' diagonals are ≤ 0); a NaN from
                        // a non-finite state is caught by the final check.
                        *iq = 1.0 / dk.comp(q);
                    }
                }
                *dk = V::from_slice(&inv[..V::DIM]);
            }
        });
        // Preconditioned CG from Δv = 0: r = rhs, p = P r.
        par::chunks1(&mut self.dv, |_, d| d.fill(V::ZERO));
        {
            let (r, pinv) = (&self.r, &self.pinv);
            par::chunks1(&mut self.p, |s, p| {
                for (k, pk) in p.iter_mut().enumerate() {
                    *pk = mul(pinv[s + k], r[s + k]);
                }
            });
        }
        let bnorm = dot(&self.r, &self.r).sqrt();
        let mut rz = dot(&self.r, &self.p);
        let mut rnorm = bnorm;
        let target = self.tol * bnorm;
        let mut iters = 0u32;
        while rnorm > target && iters < self.max_iter {
            if stop.load(Ordering::Relaxed) {
                return Err(Stopped);
            }
            Self::apply(sys, c, &self.p, &mut self.q);
            let pq = dot(&self.p, &self.q);
            if !(pq > 0.0 && rz > 0.0) {
                break; // breakdown (a non-finite or non-positive curvature): keep the iterate
            }
            let alpha = rz / pq;
            let (p, q, pinv) = (&self.p, &self.q, &self.pinv);
            let (rr, rz_new) = par::chunks2_fold(
                &mut self.dv,
                &mut self.r,
                (0.0, 0.0),
                |a, b| (a.0 + b.0, a.1 + b.1),
                |s, dv, r| {
                    let (mut rr, mut rz) = (0.0, 0.0);
                    for k in 0..dv.len() {
                        let i = s + k;
                        if im[i] != 0.0 {
                            dv[k] += p[i] * alpha;
                            r[k] -= q[i] * alpha;
                            rr += r[k].length_squared();
                            rz += r[k].dot(mul(pinv[i], r[k]));
                        }
                    }
                    (rr, rz)
                },
            );
            let beta = rz_new / rz;
            rz = rz_new;
            rnorm = rr.sqrt();
            let r = &self.r;
            par::chunks1(&mut self.p, |s, p| {
                for (k, pk) in p.iter_mut().enumerate() {
                    *pk = mul(pinv[s + k], r[s + k]) + *pk * beta;
                }
            });
            iters += 1;
        }
        let rel = if bnorm > 0.0 { rnorm / bnorm } else { 0.0 };
        self.stats.record(iters, rnorm <= target, rel);
        // v' = v0 + Δv, x' = x0 + h v' (pinned: Δv = 0 and v0 = 0).
        let (dv, single) = (&self.dv, sys.single);
        Ok(par::chunks2_any(&mut sys.state.x, &mut sys.state.v, |s, x, v| {
            let mut b = false;
            for k in 0..x.len() {
                let i = s + k;
                if im[i] != 0.0 {
                    v[k] = store(v[k] + dv[i], single);
                    x[k] = store(x[k] + v[k] * h, single);
                }
                b |= bad(x[k], v[k]);
            }
            b
        }))
    }

    fn last_forces(&self) -> &[V] {
        &self.f
    }
    fn scratch(&mut self, _velocity_dependent: bool) -> Vec<&mut Vec<V>> {
        vec![&mut self.f, &mut self.dv, &mut self.r, &mut self.p, &mut self.q, &mut self.pinv]
    }
    fn implicit(&self) -> bool {
        true
    }
    /// The solve scales the Jacobians by h². Where h² overflows (h ≥ √MAX ≈ 1.34e154 s) every
    /// diagonal of A is infinite, the preconditioner 0 and the right-hand side NaN (∞·0 for a
    /// body at rest), so CG stops at once with Δv = 0: the step silently did nothing. Where h²
    /// falls below the normal range (h < √MIN_POSITIVE ≈ 1.49e-154 s) the Jacobians vanish
    /// from A and the step is no longer implicit. Both are refused.
    fn check_step(&self, _sys: &Particles<V>, h: Real) -> crate::error::Result<()> {
        use crate::error::{invalid, seconds};
        let (big, small) = (seconds(Real::MAX.sqrt()), seconds(Real::MIN_POSITIVE.sqrt()));
        if !(h * h).is_finite() {
            let msg =
                format!("{} is too large for implicit_euler: dt² overflows float64 (take dt < {big})", seconds(h));
            return Err(invalid("dt", msg));
        }
        if h * h < Real::MIN_POSITIVE {
            let msg =
                format!("{} is too small for implicit_euler: dt² underflows float64 (take dt ≥ {small})", seconds(h));
            return Err(invalid("dt", msg));
        }
        Ok(())
    }
    fn configure(&mut self, o: &super::IntegratorOptions) {
        self.tol = o.cg_tol;
        self.max_iter = o.cg_max_iter;
    }
    fn solver_stats(&self) -> Option<SolverStats> {
        Some(self.stats)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::{Model, State};
    use crate::terms::{Drag, ForceSet, Springs, UniformGravity};
    use glam::{DVec2, DVec3};

    /// A particle of mass `m` tied to a pinned one at the origin by a spring of rest length 0
    /// (force exactly −k x, so the linearised step is the exact backward Euler step).
    fn oscillator(k: f64, m: f64, x0: DVec2, v0: DVec2) -> Particles<DVec2> {
        let mut forces = ForceSet::default();
        let sp = Springs::<DVec2>::new("s".into(), vec![0], vec![1], vec![k], vec![0.0], vec![0.0], 2).unwrap();
        forces.push(Box::new(sp)).unwrap();
        Particles {
            state: State { x: vec![DVec2::ZERO, x0], v: vec![DVec2::ZERO, v0] },
            model: Model { mass: vec![1.0, m], inv_mass: vec![0.0, 1.0 / m], ..Default::default() },
            forces,
            single: false,
        }
    }

    /// An n×n sheet in the z = 0 plane, first row pinned, structural and shear springs, gravity
    /// and drag.
    fn cloth(n: usize, k: f64) -> Particles<DVec3> {
        let s = 1.0 / (n - 1) as f64;
        let idx = |r: usize, c: usize| (r * n + c) as u32;
        let (mut i, mut j) = (vec![], vec![]);
        for r in 0..n {
            for c in 0..n {
                for (dr, dc) in [(0, 1), (1, 0), (1, 1)] {
                    if r + dr < n && c + dc < n {
                        i.push(idx(r, c));
                        j.push(idx(r + dr, c + dc));
                    }
                }
                if r + 1 < n && c >= 1 {
                    i.push(idx(r, c));
                    j.push(idx(r + 1, c - 1));
                }
            }
        }
        let x: Vec<DVec3> = (0..n * n).map(|p| DVec3::new((p % n) as f64 * s, (p / n) as f64 * s, 0.0)).collect();
        let rest: Vec<f64> = i.iter().zip(&j).map(|(&a, &b)| (x[a as usize] - x[b as usize]).length()).collect();
        let ms = 1.0 / (n * n) as f64;
        let inv: Vec<f64> = (0..n * n).map(|p| if p < n { 0.0 } else { 1.0 / ms }).collect();
        let mut forces = ForceSet::default();
        let m = i.len();
        forces
            .push(Box::new(Springs::<DVec3>::new("s".into(), i, j, vec![k; m], vec![0.1; m], rest, n * n).unwrap()))
            .unwrap();
        forces.push(Box::new(UniformGravity { name: "g".into(), g: DVec3::new(0.0, 0.0, -9.81) })).unwrap();
        forces.push(Box::new(Drag { name: "d".into(), b: 0.5 * ms })).unwrap();
        Particles {
            state: State { v: vec![DVec3::ZERO; n * n], x },
            model: Model { mass: vec![ms; n * n], inv_mass: inv, ..Default::default() },
            forces,
            single: false,
        }
    }

    /// ‖(ω x, v)‖ of the oscillator, which backward Euler shrinks by exactly 1/√(1 + ω²h²) a step
    /// (its step matrix is a scaled rotation in these coordinates).
    fn amplitude(p: &Particles<DVec2>, w: f64) -> f64 {
        ((p.state.x[1] * w).length_squared() + p.state.v[1].length_squared()).sqrt()
    }

    #[test]
    fn oscillator_amplitude_shrinks_by_the_backward_euler_factor() {
        let (k, m): (f64, f64) = (400.0, 0.25);
        let w = (k / m).sqrt();
        // ω h from well inside the explicit limit (2) to 50× it.
        for wh in [0.1f64, 1.0, 10.0, 100.0] {
            let mut p = oscillator(k, m, DVec2::new(0.3, -0.1), DVec2::new(2.0, 5.0));
            let mut it = ImplicitEuler::default();
            let theory = 1.0 / (1.0 + wh * wh).sqrt();
            for _ in 0..3 {
                let a0 = amplitude(&p, w);
                assert!(!it.step(&mut p, wh / w));
                let ratio = amplitude(&p, w) / a0;
                // Round-off: x' = x + h v' cancels all but 1/(1 + ω²h²) of x.
                let tol = 50.0 * f64::EPSILON * (1.0 + wh * wh);
                assert!((ratio / theory - 1.0).abs() < tol, "ωh {wh}: ratio {ratio} vs {theory}");
            }
            // One particle: the Jacobi preconditioner is the inverse, CG converges at once.
            assert_eq!(it.solver_stats().unwrap().unconverged, 0);
            assert_eq!(p.state.x[0], DVec2::ZERO);
        }
    }

    #[test]
    fn stiff_cloth_at_large_steps_stays_finite_with_pins_fixed() {
        let mut p = cloth(12, 2.0e4);
        let x0 = p.state.x.clone();
        let tau = p.forces.terms[0].time_scale(&p.state.x, &p.model).unwrap();
        let mut it = ImplicitEuler::default();
        for _ in 0..200 {
            assert!(!it.step(&mut p, 25.0 * tau)); // ω_max h = 25
        }
        for q in 0..12 {
            assert_eq!(p.state.x[q], x0[q]);
            assert_eq!(p.state.v[q], DVec3::ZERO);
        }
        assert!(p.state.x.iter().all(|x| x.is_finite() && x.length() < 3.0));
        let st = it.solver_stats().unwrap();
        assert_eq!((st.solves, st.unconverged), (200, 0), "{st:?}");
        assert!(st.worst_residual <= 1e-8);
        assert_eq!(p.forces.evaluations, 200);
    }

    #[test]
    fn an_iteration_limit_too_low_is_counted_not_hidden() {
        let mut p = cloth(8, 2.0e4);
        let tau = p.forces.terms[0].time_scale(&p.state.x, &p.model).unwrap();
        let mut it = ImplicitEuler::default();
        // The first step from the flat sheet at rest is trivial (gravity is normal to every
        // spring, which has no transverse stiffness at its rest length: CG converges at once).
        assert!(!it.step(&mut p, 25.0 * tau));
        assert_eq!(it.solver_stats().unwrap().iterations, 1);
        it.configure(&crate::integrators::IntegratorOptions { cg_tol: 1e-10, cg_max_iter: 2, ..Default::default() });
        assert!(!it.step(&mut p, 25.0 * tau));
        let st = it.solver_stats().unwrap();
        assert_eq!((st.solves, st.iterations, st.max_iterations, st.unconverged), (2, 3, 2, 1));
        assert!(st.worst_residual > 1e-10 && st.worst_residual < 1.0, "{st:?}");
    }

    #[test]
    fn a_set_stop_flag_abandons_the_step() {
        let mut p = cloth(8, 2.0e4);
        let mut it = ImplicitEuler::default();
        let stop = AtomicBool::new(true);
        assert_eq!(it.step_interruptible(&mut p, 1e-3, &stop), Err(Stopped));
        assert_eq!(it.solver_stats().unwrap().solves, 0);
    }

    /// The static equilibrium is the fixed point of the step (Δv = 0 ⇔ f(x) + m g = 0 at v = 0):
    /// a hanging chain settles where the forces balance, as with any explicit integrator.
    #[test]
    fn settles_to_the_static_equilibrium() {
        // A vertical chain of 5 masses under the pinned top one: spring s carries the weight of
        // the masses below it, so it stretches by (5 − s) m g / k.
        let (n, k, m, l0, g) = (6usize, 1.0e4, 0.1, 0.2, 9.81);
        let mut forces = ForceSet::default();
        let (i, j): (Vec<u32>, Vec<u32>) = (0..n as u32 - 1).map(|a| (a, a + 1)).unzip();
        forces
            .push(Box::new(
                Springs::<DVec2>::new("s".into(), i, j, vec![k; n - 1], vec![0.0; n - 1], vec![l0; n - 1], n).unwrap(),
            ))
            .unwrap();
        forces.push(Box::new(UniformGravity { name: "g".into(), g: DVec2::new(0.0, -g) })).unwrap();
        let mut p = Particles {
            state: State { x: (0..n).map(|q| DVec2::new(0.0, -l0 * q as f64)).collect(), v: vec![DVec2::ZERO; n] },
            model: Model {
                mass: vec![m; n],
                inv_mass: (0..n).map(|q| if q == 0 { 0.0 } else { 1.0 / m }).collect(),
                ..Default::default()
            },
            forces,
            single: false,
        };
        let mut it = ImplicitEuler::default();
        for _ in 0..400 {
            it.step(&mut p, 0.01); // ω_max h ≈ 6
        }
        let mut y = 0.0;
        for s in 1..n {
            y -= l0 + (n - s) as f64 * m * g / k;
            assert!((p.state.x[s].y - y).abs() < 1e-9, "mass {s}: {} vs {y}", p.state.x[s].y);
        }
    }

    #[test]
    fn a_step_whose_square_overflows_did_nothing_and_is_refused() {
        // What `check_step` refuses: at h = 1e155 (h² = inf) a body at rest, pulled by a spring,
        // did not move and no error was raised (issue 44); at 1e150 it moves.
        let ie = ImplicitEuler::<DVec2>::default();
        for h in [1e155, 1e300] {
            let (mut sys, mut ie) = (oscillator(4.0, 1.0, DVec2::new(1.0, 0.0), DVec2::ZERO), ImplicitEuler::default());
            assert!(!ie.step(&mut sys, h), "no non-finite value: the failure was silent");
            assert_eq!(sys.state.x[1], DVec2::new(1.0, 0.0), "h = {h:e}: a no-op");
        }
        let (mut sys, mut ok) = (oscillator(4.0, 1.0, DVec2::new(1.0, 0.0), DVec2::ZERO), ImplicitEuler::default());
        assert!(!ok.step(&mut sys, 1e150) && sys.state.x[1].length() < 1e-6, "{:?}", sys.state.x[1]);
        let sys = oscillator(4.0, 1.0, DVec2::new(1.0, 0.0), DVec2::ZERO);
        assert!(ie.check_step(&sys, 1e150).is_ok() && ie.check_step(&sys, 1e-150).is_ok());
        for h in [1e155, 1e300, 1e-155] {
            assert!(
                matches!(ie.check_step(&sys, h), Err(crate::Error::InvalidInput { arg, .. }) if arg == "dt"),
                "{h:e}"
            );
        }
    }
}
