//! Half-space collider {x : (x − p)·n ≥ 0} with restitution and Coulomb friction.
//!
//! A particle found below the plane after a step is projected back onto it; if it moves into the
//! plane, its normal velocity is reversed and scaled by the restitution e (v_n ← −e v_n), and its
//! tangential velocity is reduced by μ·(1 + e)|v_n| (Coulomb friction on the collision impulse),
//! never past zero. The energy this removes is booked as dissipated: the change in kinetic energy
//! plus the work −F·Δx of the last evaluated force F (with gravity) over the projection Δx
//! (exact for uniform gravity, first order otherwise).
//!
//! The shape is `geometry::HalfSpace`; the loop, the bounce and the books are `Collider`'s
//! (`collider.rs`).
use super::collider::{Collide, Collider};
use super::{Constraint, Contact};
use crate::error::Result;
use crate::geometry::HalfSpace;
use crate::vector::{Real, Vector};

/// The plane collider: a [`HalfSpace`] with its [`Contact`].
pub type Plane<V> = Collider<V, HalfSpace<V>>;

impl<V: Vector> Collide<V> for HalfSpace<V> {}

impl<V: Vector> Plane<V> {
    /// The plane through `point` (m) with `normal` (any length > 0: it is normalised) pointing
    /// into the allowed side; `InvalidInput` naming the argument if one is out of range.
    pub fn new(point: V, normal: V, restitution: Real, friction: Real) -> Result<Self> {
        let shape = HalfSpace::new(point, normal)?;
        Ok(Self::with_shape(shape, Contact::new(restitution, friction)?))
    }
}

fn build<V: Vector>(p: &crate::terms::registry::Params) -> Result<Box<dyn Constraint<V>>> {
    let plane = Plane::new(p.vector("point")?, p.vector("normal")?, p.number("restitution")?, p.number("friction")?)?;
    Ok(Box::new(plane))
}
crate::register_collider!("plane", build);
