//! Yoshida's fourth-order symplectic integrator: the "triple jump" composition of velocity
//! Verlet (Yoshida, Phys. Lett. A 150 (1990) 262–268, eqs. 4.12–4.14; Hairer, Lubich &
//! Wanner, *Geometric Numerical Integration*, §II.4, eq. 4.4):
//!   Φ_dt = V(w₁dt) ∘ V(w₀dt) ∘ V(w₁dt),   w₁ = 1/(2 − 2^{1/3}),   w₀ = −2^{1/3}/(2 − 2^{1/3})
//! where V is one velocity Verlet step. A symmetric composition of a symmetric second-order
//! method with 2w₁ + w₀ = 1 and 2w₁³ + w₀³ = 0 is of order four, and symplectic because each
//! factor is. The middle substep runs backwards in time (w₀ ≈ −1.70); each Verlet substep
//! reuses the force at its start ("first same as last"), so a step costs three force
//! evaluations.
//!
//! With velocity-dependent forces (drag, dashpots) Verlet predicts the end velocity and is no
//! longer symmetric, so the composition keeps Verlet's second order there.
use super::{Carry, Integrator, IntegratorInfo, Particles, VelocityVerlet};
use crate::vector::{Real, Vector};

/// w₁ = 1/(2 − 2^{1/3}) (Yoshida 1990, eq. 4.14).
pub const W1: Real = 1.351_207_191_959_657_8;
/// w₀ = 1 − 2w₁ = −2^{1/3}/(2 − 2^{1/3}).
pub const W0: Real = -1.702_414_383_919_315_3;

#[derive(Default)]
pub struct Yoshida4<V: Vector> {
    verlet: VelocityVerlet<V>,
}

impl<V: Vector> Integrator<V> for Yoshida4<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "yoshida4", order: 4, symplectic: true, force_evals_per_step: 3 }
    }
    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let mut bad = false;
        for w in [W1, W0, W1] {
            bad |= self.verlet.step(sys, w * dt);
        }
        bad
    }
    fn last_forces(&self) -> &[V] {
        self.verlet.last_forces()
    }
    fn scratch(&mut self, velocity_dependent: bool) -> Vec<&mut Vec<V>> {
        self.verlet.scratch(velocity_dependent)
    }
    fn reset(&mut self) {
        self.verlet.reset()
    }
    fn as_carry(&self) -> Option<&dyn Carry<V>> {
        Some(&self.verlet)
    }
    fn as_carry_mut(&mut self) -> Option<&mut dyn Carry<V>> {
        Some(&mut self.verlet)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::{Model, State};
    use crate::terms::{ForceSet, Springs};
    use glam::DVec2;

    #[test]
    fn weights_satisfy_the_order_conditions() {
        assert!((2.0 * W1 + W0 - 1.0).abs() < 1e-15);
        assert!((2.0 * W1.powi(3) + W0.powi(3)).abs() < 1e-14);
        assert!((W1 - 1.0 / (2.0 - 2f64.cbrt())).abs() < 1e-15);
    }

    /// One particle on a pinned spring (ω = 1): the error at t = 1 falls 16× per halving of dt.
    #[test]
    fn fourth_order_on_a_harmonic_oscillator() {
        let run = |n: usize| {
            let mut forces = ForceSet::default();
            let springs = Springs::new("s".into(), vec![0], vec![1], vec![1.0], vec![0.0], vec![0.0], 2).unwrap();
            forces.push(Box::new(springs)).unwrap();
            let mut sys = Particles {
                state: State { x: vec![DVec2::ZERO, DVec2::X], v: vec![DVec2::ZERO; 2] },
                model: Model { mass: vec![1.0, 1.0], inv_mass: vec![0.0, 1.0], ..Default::default() },
                forces,
                single: false,
            };
            let mut it = Yoshida4::default();
            let dt = 1.0 / n as Real;
            for _ in 0..n {
                assert!(!it.step(&mut sys, dt));
            }
            (sys.state.x[1].x - 1f64.cos()).abs()
        };
        let (e1, e2, e3) = (run(10), run(20), run(40));
        for r in [e1 / e2, e2 / e3] {
            assert!((r.log2() - 4.0).abs() < 0.1, "observed order {}", r.log2());
        }
    }
}
