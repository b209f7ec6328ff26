//! Linear (Stokes) drag: F_i = −b v_i, dissipating P = b Σ |v_i|². Jacobian: ∂f/∂v = −b I,
//! ∂f/∂x = 0 (for implicit integrators).
use super::registry::{Context, Params};
use super::{Jacobian, Term, Traits, Write};
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

fn build<V: Vector>(name: String, p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    let b = p.number("coefficient")?;
    if b < 0.0 {
        return Err(invalid("coefficient", format!("{b} must be finite and >= 0")));
    }
    Ok(Box::new(Drag { name, b }))
}
crate::register_term!("drag", build);

pub struct Drag {
    pub name: String,
    /// Drag coefficient b, kg/s (N·s/m), ≥ 0.
    pub b: Real,
}

impl<V: Vector> Term<V> for Drag {
    fn name(&self) -> &str {
        &self.name
    }
    fn add_forces(&mut self, _x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let b = self.b;
        let body = |s: usize, f: &mut [V]| {
            let mut p = 0.0;
            for (k, fi) in f.iter_mut().enumerate() {
                let i = s + k;
                let fd = if model.inv_mass[i] != 0.0 { v[i] * (-b) } else { V::ZERO };
                write.put(fi, fd);
                p += b * v[i].length_squared();
            }
            p
        };
        if b > 0.0 {
            par::chunks1_sum(f, body)
        } else {
            par::chunks1(f, |s, f| {
                body(s, f);
            });
            0.0
        }
    }
    fn potential(&self, _x: &[V], _m: &Model) -> Option<Real> {
        None
    }
    fn traits(&self) -> Traits<V> {
        Traits::dissipating(self.b > 0.0)
    }
    fn time_scale(&self, _x: &[V], model: &Model) -> Option<Real> {
        // Velocity relaxation time m/b of the lightest free particle.
        let m = model
            .mass
            .iter()
            .zip(&model.inv_mass)
            .filter(|(_, &im)| im != 0.0)
            .map(|(m, _)| *m)
            .fold(f64::INFINITY, f64::min);
        (self.b > 0.0 && m.is_finite()).then(|| m / self.b)
    }

    fn as_jacobian(&self) -> Option<&dyn Jacobian<V>> {
        Some(self)
    }
    fn as_jacobian_mut(&mut self) -> Option<&mut dyn Jacobian<V>> {
        Some(self)
    }
}

impl<V: Vector> Jacobian<V> for Drag {
    /// Adds cv (−b) w_i on free particles (∂f/∂v = −b I; ∂f/∂x = 0).
    fn product(&self, _x: &[V], _v: &[V], model: &Model, c: (Real, Real), w: &[V], out: &mut [V]) {
        let s = -self.b * c.1;
        par::chunks1(out, |p0, out| {
            for (k, o) in out.iter_mut().enumerate() {
                if model.inv_mass[p0 + k] != 0.0 {
                    *o += w[p0 + k] * s;
                }
            }
        });
    }
    fn diagonal(&self, _x: &[V], _v: &[V], model: &Model, c: (Real, Real), out: &mut [V]) {
        let s = -self.b * c.1;
        let d = V::from_slice(&[s; 3][..V::DIM]);
        par::chunks1(out, |p0, out| {
            for (k, o) in out.iter_mut().enumerate() {
                if model.inv_mass[p0 + k] != 0.0 {
                    *o += d;
                }
            }
        });
    }
}
