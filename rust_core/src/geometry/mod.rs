//! Shapes for the particle colliders and the grains' walls: the geometry alone, with no
//! velocity rule and no energy book. A [`Shape`] answers two questions for a point x:
//! - `project`, for the colliders (points): is x on the forbidden side, and if so, where on the
//!   surface does it go and which way is out (the unit normal into the allowed side). The
//!   collision rule (restitution, Coulomb friction, the "collisions" book) is written once, in
//!   `constraints::collider`, for every shape.
//! - `closest`, for the walls of the grains (`terms::contacts`, a grain of radius r): the
//!   nearest point of the surface, the unit normal there into the allowed side and the signed
//!   distance of x ([`Surface`]); the grain touches when the distance is below r, with overlap
//!   r − distance, pushed along the normal.
//!
//! Each shape hands back both the new position and the displacement, each computed the way that
//! shape computes it (a plane adds n·depth to x; a sphere puts x at c + r·radial and takes the
//! difference), so a collider keeps the float operations, and the bits, it always had.
//!
//! Shapes: [`HalfSpace`] (the plane), [`Ball`] (a ball, or with `inside` a bowl), [`Capsule`],
//! [`Aabb`] (an axis-aligned box kept inside: a tank) and [`OrientedBox`] (a rotated block kept
//! outside: a ramp, an obstacle). [`AnyShape`] is any one of them, answered by a `match` (the
//! grains' walls hold one each).
pub mod aabb;
pub mod any_shape;
pub mod ball;
pub mod capsule;
pub mod half_space;
pub mod oriented_box;
pub use aabb::Aabb;
pub use any_shape::AnyShape;
pub use ball::Ball;
pub use capsule::Capsule;
pub use half_space::HalfSpace;
pub use oriented_box::OrientedBox;

use crate::vector::{Real, Vector};

/// Where a point found on the forbidden side of a shape goes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projection<V> {
    /// The point on the surface it moves to, m.
    pub x: V,
    /// The displacement, m: `x` minus the point given, as the shape's own arithmetic gives it
    /// (the work of the forces over the projection is booked with it).
    pub dx: V,
    /// Unit normal into the allowed side at `x`.
    pub normal: V,
}

/// The surface of a shape as seen from a point x (`Shape::closest`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface<V> {
    /// The point of the surface nearest to x, m.
    pub point: V,
    /// Unit normal into the allowed side at `point`: where x is off the surface,
    /// (x − point)/distance, so x = point + distance·normal (to round-off).
    pub normal: V,
    /// Signed distance of x from the surface, m: > 0 on the allowed side, < 0 on the forbidden
    /// side (minus the depth), 0 on the surface.
    pub distance: Real,
}

/// The geometry of a collider or a grains' wall.
pub trait Shape<V: Vector>: Send + Sync {
    /// `None` if `x` is on the allowed side (its surface included); else where it goes. `v` (the
    /// point's velocity, m/s) is read only where the geometry gives no direction: a point at a
    /// sphere's centre goes back the way it came.
    fn project(&self, x: V, v: &V) -> Option<Projection<V>>;

    /// The box (lo, hi), m, that holds the forbidden side: a point outside it is never moved.
    /// Infinite where the forbidden side is unbounded (a tilted plane; the outside of a bowl).
    fn bounds(&self) -> (V, V);

    /// The nearest surface point to `x`, the normal there and the signed distance (each shape's
    /// doc gives its formula). Where the nearest point is not unique (the centre of a ball, the
    /// middle of a box) one is chosen, as that shape's doc says. A NaN `x` gives a NaN distance,
    /// which compares false: never in contact.
    fn closest(&self, x: V) -> Surface<V>;
}

/// `V` with every component `c`.
#[inline(always)]
pub(crate) fn splat<V: Vector>(c: Real) -> V {
    V::from_slice(&[c; 3][..V::DIM])
}

/// Componentwise `f(a_k, b_k)`.
#[inline(always)]
pub(crate) fn zip<V: Vector>(a: V, b: V, f: impl Fn(Real, Real) -> Real) -> V {
    let mut out = [0.0; 3];
    for k in 0..V::DIM {
        out[k] = f(a.comp(k), b.comp(k));
    }
    V::from_slice(&out[..V::DIM])
}

/// A unit vector along the last axis (z in 3D, y in 2D): the direction chosen where the
/// geometry gives none (a point at a ball's centre).
#[inline(always)]
pub(crate) fn up<V: Vector>() -> V {
    let mut a = [0.0; 3];
    a[V::DIM - 1] = 1.0;
    V::from_slice(&a[..V::DIM])
}

/// Both bounds infinite: the forbidden side is unbounded.
pub(crate) fn unbounded<V: Vector>() -> (V, V) {
    (splat(Real::NEG_INFINITY), splat(Real::INFINITY))
}
