//! Half-space collider {x : (x − p)·n ≥ 0} with restitution and Coulomb friction.
//!
//! A particle found below the plane after a step is projected back onto it; if it moves into the
//! plane, its normal velocity is reversed and scaled by the restitution e (v_n ← −e v_n), and its
//! tangential velocity is reduced by μ·(1 + e)|v_n| (Coulomb friction on the collision impulse),
//! never past zero. The energy this removes is booked as dissipated: the change in kinetic energy
//! plus the work −F·Δx of the last evaluated force F (with gravity) over the projection Δx
//! (exact for uniform gravity, first order otherwise).
use super::{Constraint, Contact};
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

#[derive(Clone, Debug)]
pub struct Plane<V: Vector> {
    /// A point on the plane, m.
    pub(crate) point: V,
    /// Unit normal pointing into the allowed half-space.
    pub(crate) normal: V,
    pub(crate) contact: Contact,
}

impl<V: Vector> Plane<V> {
    /// The plane through `point` (m) with `normal` (any length > 0: it is normalised) pointing
    /// into the allowed side; `InvalidInput` naming the argument if one is out of range.
    pub fn new(point: V, normal: V, restitution: Real, friction: Real) -> Result<Self> {
        if !point.is_finite() {
            return Err(invalid("point", "must be finite"));
        }
        let l2 = normal.length_squared();
        if !(l2.is_finite() && l2 > 0.0) {
            return Err(invalid("normal", "must be finite and non-zero"));
        }
        let contact = Contact::new(restitution, friction)?;
        Ok(Self { point, normal: normal / l2.sqrt(), contact })
    }
}

impl<V: Vector> Constraint<V> for Plane<V> {
    fn project(&self, x: &mut [V], v: &mut [V], model: &Model, f_last: &[V], g: V) -> (Real, bool) {
        let (p, n, contact) = (self.point, self.normal, self.contact);
        par::chunks2_fold(
            x,
            v,
            (0.0, false),
            |a, b| (a.0 + b.0, a.1 | b.1),
            |s, x, v| {
                let mut d = 0.0;
                let mut touched = false;
                for k in 0..x.len() {
                    let i = s + k;
                    if model.inv_mass[i] == 0.0 {
                        continue;
                    }
                    let depth = (x[k] - p).dot(n);
                    if depth >= 0.0 {
                        continue;
                    }
                    touched = true;
                    let m = model.mass[i];
                    let ke0 = 0.5 * m * v[k].length_squared();
                    let dx = n * (-depth);
                    x[k] += dx;
                    v[k] = contact.bounce(v[k], n);
                    let ke1 = 0.5 * m * v[k].length_squared();
                    // Projection work: ΔU ≈ −F·Δx.
                    let f = if f_last.len() > i { f_last[i] } else { V::ZERO } + g * m;
                    let du = -f.dot(dx);
                    d += (ke0 - ke1) - du;
                }
                (d, touched)
            },
        )
    }
}

fn build<V: Vector>(p: &crate::terms::registry::Params) -> Result<Box<dyn Constraint<V>>> {
    let plane = Plane::new(p.vector("point")?, p.vector("normal")?, p.number("restitution")?, p.number("friction")?)?;
    Ok(Box::new(plane))
}
crate::register_collider!("plane", build);
