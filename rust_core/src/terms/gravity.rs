//! Uniform gravity: F_i = m_i g on every free particle; U = −Σ m_i g·x_i.
use super::registry::{Context, Params};
use super::{Term, Traits, Write};
use crate::error::Result;
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

fn build<V: Vector>(name: String, p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    Ok(Box::new(UniformGravity { name, g: p.vector("g")? }))
}
crate::register_term!("gravity", build);

pub struct UniformGravity<V: Vector> {
    pub name: String,
    /// Gravitational acceleration, m/s².
    pub g: V,
}

impl<V: Vector> Term<V> for UniformGravity<V> {
    fn name(&self) -> &str {
        &self.name
    }
    fn add_forces(&mut self, _x: &[V], _v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let g = self.g;
        par::chunks1(f, |s, f| {
            for (k, fi) in f.iter_mut().enumerate() {
                let i = s + k;
                let fg = if model.inv_mass[i] != 0.0 { g * model.mass[i] } else { V::ZERO };
                write.put(fi, fg);
            }
        });
        0.0
    }
    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        let g = self.g;
        Some(par::sum(x.len(), 0.0, |r| {
            let mut u = 0.0;
            for i in r {
                if model.inv_mass[i] != 0.0 {
                    u -= model.mass[i] * g.dot(x[i]);
                }
            }
            u
        }))
    }
    fn traits(&self) -> Traits<V> {
        Traits { uniform: Some(self.g), ..Traits::conservative() }
    }
}
