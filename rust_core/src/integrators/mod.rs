//! Time integrators behind one trait. Each reports its name, order, whether it is symplectic and
//! its force evaluations per step, so the speed/accuracy trade can be tabulated honestly.
pub mod euler;
pub mod rk4;
pub mod semi_implicit_euler;
pub mod verlet;

use crate::error::{invalid, Result};
use crate::state::{Model, State};
use crate::terms::ForceSet;
use crate::vector::{Real, Vector};

pub use euler::ExplicitEuler;
pub use rk4::Rk4;
pub use semi_implicit_euler::SemiImplicitEuler;
pub use verlet::VelocityVerlet;

/// What a simulation hands an integrator: state, constants and the force terms.
pub struct System<V: Vector> {
    pub state: State<V>,
    pub model: Model,
    pub forces: ForceSet<V>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IntegratorInfo {
    /// Stable lower-case name used to pick it.
    pub name: &'static str,
    /// Global order of accuracy.
    pub order: u32,
    pub symplectic: bool,
    /// Force evaluations per step (in steady state).
    pub force_evals_per_step: u32,
}

pub trait Integrator<V: Vector>: Send + Sync {
    fn info(&self) -> IntegratorInfo;
    /// Advances `sys.state` by `dt` (x, v only; the caller advances time) and books the energy
    /// dissipated by the force terms during the step. Returns `true` if any position or
    /// velocity is not finite afterwards (checked in the final update pass, at no extra pass).
    fn step(&mut self, sys: &mut System<V>, dt: Real) -> bool;
    /// Forces (N) of the most recent evaluation, one per particle.
    fn last_forces(&self) -> &[V];
    /// Drop anything cached across steps (the state was changed from outside the integrator).
    fn reset(&mut self) {}
    /// Cached forces carried from one step to the next (velocity Verlet's "first same as last"),
    /// with the term powers at that state; needed to continue a saved run bit for bit.
    fn cache(&self) -> Option<(&[V], &[Real])> {
        None
    }
    fn set_cache(&mut self, _f: Vec<V>, _p: Vec<Real>) {}
}

/// All integrator names, in the order of the documentation table.
pub const NAMES: [&str; 4] = ["euler", "semi_implicit_euler", "verlet", "rk4"];

pub fn by_name<V: Vector>(name: &str) -> Result<Box<dyn Integrator<V>>> {
    Ok(match name {
        "euler" => Box::new(ExplicitEuler::default()),
        "semi_implicit_euler" => Box::new(SemiImplicitEuler::default()),
        "verlet" => Box::new(VelocityVerlet::default()),
        "rk4" => Box::new(Rk4::default()),
        other => {
            return Err(invalid("integrator", format!("unknown integrator {other:?}; valid names: {}", NAMES.join(", "))))
        }
    })
}

#[inline]
pub(crate) fn ensure_len<V: Vector>(buf: &mut Vec<V>, n: usize) {
    if buf.len() != n {
        buf.resize(n, V::ZERO);
    }
}

/// Acceleration f/m + g (g: the uniform fields), exactly zero for pinned particles (inverse
/// mass 0) even when f is not finite.
#[inline(always)]
pub(crate) fn accel<V: Vector>(f: V, inv_mass: Real, g: V) -> V {
    if inv_mass == 0.0 {
        V::ZERO
    } else {
        f * inv_mass + g
    }
}

/// Whether a position or velocity has a NaN or infinite component (branch-free, vectorisable).
#[inline(always)]
pub(crate) fn bad<V: Vector>(x: V, v: V) -> bool {
    let mut b = false;
    for k in 0..V::DIM {
        b |= !x.comp(k).is_finite() | !v.comp(k).is_finite();
    }
    b
}
