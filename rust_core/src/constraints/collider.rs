//! One collider for every shape: [`Collider`] holds a `geometry::Shape` and a [`Contact`] and
//! runs the projection loop once for all of them. Per particle, per step: skip the pinned
//! (inverse mass 0); ask the shape where a particle on its forbidden side goes; move it there,
//! bounce its velocity (restitution e on the normal part, Coulomb friction μ(1 + e)|v_n| off the
//! tangential part, `Contact::bounce`); book the energy removed: the change in kinetic energy
//! plus the work −F·Δx of the last evaluated force F (with gravity) over the projection Δx
//! (exact for uniform gravity, first order otherwise).
//!
//! How the velocity is corrected is [`Collide::resolve`], which by default is the one bounce
//! off the shape's normal; a shape with another rule overrides it.
//!
//! The axis-aligned box (`aabb.rs`) keeps a loop of its own: it bounces face by face, once per
//! axis it is outside of (a particle past a corner gets two or three bounces, each off its own
//! face: one off the diagonal would change the bits), and through this loop, with that rule as
//! its `resolve`, it ran 25–35 % slower (200,000 particles in a box under gravity, 2 cores,
//! AVX-512: 0.86–0.92 ms a step alone, 1.09–1.27 ms through here; the plane and the sphere
//! kept their speed). `geometry::Aabb` is its shape for every other use.
use super::{Constraint, Contact};
use crate::geometry::Shape;
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

/// A resolved contact: the new position and velocity, and the displacement the work is booked
/// over.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Resolved<V> {
    /// New position, m.
    pub x: V,
    /// Displacement, m (as the shape computed it).
    pub dx: V,
    /// New velocity, m/s.
    pub v: V,
}

/// How a shape resolves a contact. The default, one bounce off the shape's normal, is what
/// every shape but the axis-aligned box uses (`impl Collide<V> for MyShape<V> {}`).
pub trait Collide<V: Vector>: Shape<V> {
    /// `None` if `x` is allowed; else the particle moved onto the surface and its velocity
    /// corrected by `contact`.
    #[inline(always)]
    fn resolve(&self, x: V, v: &V, contact: Contact) -> Option<Resolved<V>> {
        let p = self.project(x, v)?;
        Some(Resolved { x: p.x, dx: p.dx, v: contact.bounce(*v, p.normal) })
    }
}

/// A shape with contact coefficients: the constraint of the projection stage (module doc).
#[derive(Clone, Debug)]
pub struct Collider<V: Vector, S: Collide<V>> {
    pub shape: S,
    pub contact: Contact,
    _v: std::marker::PhantomData<V>,
}

impl<V: Vector, S: Collide<V>> Collider<V, S> {
    /// `shape` with `contact` (both checked by their own constructors).
    pub fn with_shape(shape: S, contact: Contact) -> Self {
        Self { shape, contact, _v: std::marker::PhantomData }
    }
}

impl<V: Vector, S: Collide<V> + Clone> Constraint<V> for Collider<V, S> {
    fn project(&self, x: &mut [V], v: &mut [V], model: &Model, f_last: &[V], g: V, kick: Real) -> (Real, bool) {
        let (shape, contact) = (&self.shape, self.contact);
        par::chunks2_fold(
            x,
            v,
            (0.0, false),
            |a, b| (a.0 + b.0, a.1 | b.1),
            |s, x, v| {
                // A copy of the shape on this chunk's stack: its parameters then stay in registers
                // through the loop (read through the shared reference, they were loaded again per
                // particle: the box ran 35 % slower).
                let shape = shape.clone();
                let mut d = 0.0;
                let mut touched = false;
                for k in 0..x.len() {
                    // The geometry first, from the position alone: a particle on the allowed
                    // side (nearly all of them) costs one load of x, not of v and its mass too
                    // (this order kept the old box and sphere loops' speed; resolving is pure,
                    // so a pinned particle's answer is just dropped).
                    let Some(r) = shape.resolve(x[k], &v[k], contact) else { continue };
                    let i = s + k;
                    if model.inv_mass[i] == 0.0 {
                        continue;
                    }
                    touched = true;
                    let m = model.mass[i];
                    let (ke0, v0) = (0.5 * m * v[k].length_squared(), v[k]);
                    x[k] = r.x;
                    v[k] = r.v;
                    let ke1 = 0.5 * m * v[k].length_squared();
                    // Projection work: ΔU ≈ −F·Δx; and the integrator's error term (`kick`).
                    let f = if f_last.len() > i { f_last[i] } else { V::ZERO } + g * m;
                    let du = -f.dot(r.dx);
                    d += (ke0 - ke1) - du + kick * (g * m).dot(r.v - v0);
                }
                (d, touched)
            },
        )
    }
}
