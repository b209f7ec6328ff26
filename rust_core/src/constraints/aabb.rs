//! Axis-aligned box collider: particles are kept inside [lo, hi] (a tank or a room), all faces in
//! one pass over the particles. Per face the same rule as `Plane`: a particle found outside is
//! projected onto the face; if it moves outward its normal velocity becomes −e·v_n and its
//! tangential velocity drops by μ(1 + e)|v_n| (never reversing). The energy removed (ΔKE plus the
//! work −F·Δx of the last force and gravity over the projection) is booked as dissipated.
//!
//! The shape is `geometry::Aabb`; the loop is the one of every collider (`collider.rs`). Only the
//! velocity rule is its own ([`Collide::resolve`] overridden): face by face, so past an edge or a
//! corner a particle gets one bounce per face it is outside of, each with its own friction, not
//! one bounce off the diagonal the shape's normal gives there.
use super::collider::{Collide, Collider, Resolved};
use super::{Constraint, Contact};
use crate::error::Result;
use crate::geometry;
use crate::vector::{Real, Vector};

/// The box collider: a [`geometry::Aabb`] with its [`Contact`].
pub type Aabb<V> = Collider<V, geometry::Aabb<V>>;

impl<V: Vector> Aabb<V> {
    /// The box [lo, hi] (m); `InvalidInput` naming the argument if one is out of range.
    pub fn new(lo: V, hi: V, restitution: Real, friction: Real) -> Result<Self> {
        let shape = geometry::Aabb::new(lo, hi)?;
        Ok(Self::with_shape(shape, Contact::new(restitution, friction)?))
    }
}

impl<V: Vector> Collide<V> for geometry::Aabb<V> {
    /// Clamped onto the box axis by axis, with a bounce off each face crossed (module doc).
    #[inline(always)]
    fn resolve(&self, x: V, v: V, contact: Contact) -> Option<Resolved<V>> {
        let Contact { restitution: e, friction: mu } = contact;
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for k in 0..V::DIM {
            lo[k] = self.lo.comp(k);
            hi[k] = self.hi.comp(k);
        }
        let mut outside = false;
        for a in 0..V::DIM {
            let c = x.comp(a);
            outside |= (c < lo[a]) | (c > hi[a]);
        }
        if !outside {
            return None;
        }
        let mut xa = [0.0; 3];
        let mut va = [0.0; 3];
        for a in 0..V::DIM {
            xa[a] = x.comp(a);
            va[a] = v.comp(a);
        }
        for a in 0..V::DIM {
            // Outward direction along axis a: −1 below lo, +1 above hi.
            let out = if xa[a] < lo[a] {
                xa[a] = lo[a];
                -1.0
            } else if xa[a] > hi[a] {
                xa[a] = hi[a];
                1.0
            } else {
                continue;
            };
            let vn = va[a] * out; // > 0: moving outward
            if vn > 0.0 {
                let dvn = (1.0 + e) * vn;
                va[a] *= -e;
                if mu > 0.0 {
                    let vt2: Real = (0..V::DIM).filter(|&b| b != a).map(|b| va[b] * va[b]).sum();
                    if vt2 > 0.0 {
                        let vt = vt2.sqrt();
                        let s = (vt - mu * dvn).max(0.0) / vt;
                        for b in (0..V::DIM).filter(|&b| b != a) {
                            va[b] *= s;
                        }
                    }
                }
            }
        }
        let moved = V::from_slice(&xa[..V::DIM]);
        Some(Resolved { x: moved, dx: moved - x, v: V::from_slice(&va[..V::DIM]) })
    }
}

fn build<V: Vector>(p: &crate::terms::registry::Params) -> Result<Box<dyn Constraint<V>>> {
    let b = Aabb::new(p.vector("lower")?, p.vector("upper")?, p.number("restitution")?, p.number("friction")?)?;
    Ok(Box::new(b))
}
crate::register_collider!("box", build);
