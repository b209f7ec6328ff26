//! Colliders applied after each step. Their energy loss goes into the dissipation ledger.
pub mod aabb;
pub mod plane;
pub use aabb::Aabb;
pub use plane::Plane;

use crate::state::Model;
use crate::vector::{Real, Vector};

/// Any collider.
#[derive(Clone, Debug)]
pub enum Collider<V: Vector> {
    Plane(Plane<V>),
    Box(Aabb<V>),
}

impl<V: Vector> Collider<V> {
    /// Resolves contacts; returns (energy dissipated J, whether any particle was touched).
    pub fn apply(&self, x: &mut [V], v: &mut [V], model: &Model, f_last: &[V], g: V) -> (Real, bool) {
        match self {
            Collider::Plane(p) => p.apply(x, v, model, f_last, g),
            Collider::Box(b) => b.apply(x, v, model, f_last, g),
        }
    }
}
