//! Axis-aligned box collider: particles are kept inside [lo, hi] (a tank or a room), all faces in
//! one pass over the particles. Per face the same rule as `Plane`: a particle found outside is
//! projected onto the face; if it moves outward its normal velocity becomes −e·v_n and its
//! tangential velocity drops by μ(1 + e)|v_n| (never reversing). The energy removed (ΔKE plus the
//! work −F·Δx of the last force and gravity over the projection) is booked as dissipated.
use super::{Constraint, Contact};
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

#[derive(Clone, Debug)]
pub struct Aabb<V: Vector> {
    /// Lower corner, m.
    pub(crate) lo: V,
    /// Upper corner, m (> lo on every axis).
    pub(crate) hi: V,
    pub(crate) contact: Contact,
}

impl<V: Vector> Aabb<V> {
    /// The box [lo, hi] (m); `InvalidInput` naming the argument if one is out of range.
    pub fn new(lo: V, hi: V, restitution: Real, friction: Real) -> Result<Self> {
        if !(lo.is_finite() && hi.is_finite()) {
            return Err(invalid("lower/upper", "must be finite"));
        }
        if (0..V::DIM).any(|k| !(hi.comp(k) > lo.comp(k))) {
            return Err(invalid("upper", "must be > lower on every axis"));
        }
        let contact = Contact::new(restitution, friction)?;
        Ok(Self { lo, hi, contact })
    }
}

impl<V: Vector> Constraint<V> for Aabb<V> {
    fn project(&self, x: &mut [V], v: &mut [V], model: &Model, f_last: &[V], g: V, kick: Real) -> (Real, bool) {
        let Contact { restitution: e, friction: mu } = self.contact;
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for k in 0..V::DIM {
            lo[k] = self.lo.comp(k);
            hi[k] = self.hi.comp(k);
        }
        par::chunks2_fold(
            x,
            v,
            (0.0, false),
            |a, b| (a.0 + b.0, a.1 | b.1),
            |s, x, v| {
                let mut d = 0.0;
                let mut touched = false;
                for k in 0..x.len() {
                    let mut outside = false;
                    for a in 0..V::DIM {
                        let c = x[k].comp(a);
                        outside |= (c < lo[a]) | (c > hi[a]);
                    }
                    if !outside {
                        continue;
                    }
                    let i = s + k;
                    if model.inv_mass[i] == 0.0 {
                        continue;
                    }
                    touched = true;
                    let m = model.mass[i];
                    let mut xa = [0.0; 3];
                    let mut va = [0.0; 3];
                    for a in 0..V::DIM {
                        xa[a] = x[k].comp(a);
                        va[a] = v[k].comp(a);
                    }
                    let ke0 = 0.5 * m * v[k].length_squared();
                    let (x0, v0) = (x[k], v[k]);
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
                    x[k] = V::from_slice(&xa[..V::DIM]);
                    v[k] = V::from_slice(&va[..V::DIM]);
                    let ke1 = 0.5 * m * v[k].length_squared();
                    let f = if f_last.len() > i { f_last[i] } else { V::ZERO } + g * m;
                    let du = -f.dot(x[k] - x0);
                    d += (ke0 - ke1) - du + kick * (g * m).dot(v[k] - v0);
                }
                (d, touched)
            },
        )
    }
}

fn build<V: Vector>(p: &crate::terms::registry::Params) -> Result<Box<dyn Constraint<V>>> {
    let b = Aabb::new(p.vector("lower")?, p.vector("upper")?, p.number("restitution")?, p.number("friction")?)?;
    Ok(Box::new(b))
}
crate::register_collider!("box", build);
