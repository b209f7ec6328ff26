//! Particle state (what changes during a run) and the model (what does not).
use crate::vector::{Real, Vector};
use std::collections::BTreeMap;

/// Positions and velocities: the part of a particle system that changes every step (time and
/// the step count belong to the `World`, which steps every system together).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct State<V: Vector> {
    /// Positions, m.
    pub x: Vec<V>,
    /// Velocities, m/s.
    pub v: Vec<V>,
}

/// Per-particle constants. `inv_mass == 0` marks a pinned particle: it never moves, but its
/// mass still takes part in pairwise gravity.
#[derive(Clone, Debug, Default)]
pub struct Model {
    /// Mass, kg (> 0 and finite).
    pub mass: Vec<Real>,
    /// 1 / mass for free particles, 0 for pinned ones, 1/kg.
    pub inv_mass: Vec<Real>,
    /// Optional per-particle attributes (see [`ATTRIBUTES`]), each one value per particle; a
    /// scene pays for an attribute only once it is set.
    pub attributes: BTreeMap<&'static str, Vec<Real>>,
}

/// The optional per-particle attributes a scene may carry, with their SI units. Particles
/// without a value (added before the attribute was set, or after without one) hold 0.
pub const ATTRIBUTES: &[(&str, &str)] = &[("charge", "C"), ("radius", "m")];

impl Model {
    /// The attribute `name`'s values (one per particle), if it has been set.
    pub fn attribute(&self, name: &str) -> Option<&[Real]> {
        self.attributes.get(name).map(|a| a.as_slice())
    }
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
