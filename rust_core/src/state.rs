//! Particle state (what changes during a run) and the model (what does not).
use crate::vector::{Real, Vector};

/// Positions, velocities and time: the part of a simulation that changes every step.
#[derive(Clone, Debug, Default)]
pub struct State<V: Vector> {
    /// Positions, m.
    pub x: Vec<V>,
    /// Velocities, m/s.
    pub v: Vec<V>,
    /// Simulated time, s.
    pub t: Real,
    /// Steps taken since the scene was built.
    pub step: u64,
}

/// Per-particle constants. `inv_mass == 0` marks a pinned particle: it never moves, but its
/// mass still takes part in pairwise gravity.
#[derive(Clone, Debug, Default)]
pub struct Model {
    /// Mass, kg (> 0 and finite).
    pub mass: Vec<Real>,
    /// 1 / mass for free particles, 0 for pinned ones, 1/kg.
    pub inv_mass: Vec<Real>,
}

impl Model {
    pub fn len(&self) -> usize {
        self.mass.len()
    }
    pub fn is_empty(&self) -> bool {
        self.mass.is_empty()
    }
    #[inline(always)]
    pub fn is_pinned(&self, i: usize) -> bool {
        self.inv_mass[i] == 0.0
    }
}
