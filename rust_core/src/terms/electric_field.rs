//! Uniform electric field on charged particles: F_i = q_i E, U = −Σ q_i E·x_i over free
//! particles (Griffiths, *Introduction to Electrodynamics*, 4th ed., eqs. 2.21 and 4.14 for a
//! point charge). q is the `charge` attribute (C); a scene without it feels no force.
use super::registry::{Context, Params};
use super::{Term, Traits, Write};
use crate::error::Result;
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

pub struct UniformElectricField<V: Vector> {
    pub name: String,
    /// Field strength E, V/m (N/C).
    pub e: V,
}

fn build<V: Vector>(name: String, p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    Ok(Box::new(UniformElectricField { name, e: p.vector("E")? }))
}
crate::register_term!("uniform_electric_field", build);

impl<V: Vector> Term<V> for UniformElectricField<V> {
    fn name(&self) -> &str {
        &self.name
    }
    fn add_forces(&mut self, _x: &[V], _v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let (e, q) = (self.e, model.attribute("charge"));
        par::chunks1(f, |s, f| {
            for (k, fi) in f.iter_mut().enumerate() {
                let i = s + k;
                let fe = match q {
                    Some(q) if model.inv_mass[i] != 0.0 => e * q[i],
                    _ => V::ZERO,
                };
                write.put(fi, fe);
            }
        });
        0.0
    }
    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        let Some(q) = model.attribute("charge") else {
            return Some(0.0); // uncharged
        };
        let e = self.e;
        Some(par::sum(x.len(), 0.0, |r| {
            let mut u = 0.0;
            for i in r {
                if model.inv_mass[i] != 0.0 {
                    u -= q[i] * e.dot(x[i]);
                }
            }
            u
        }))
    }
    fn traits(&self) -> Traits<V> {
        Traits::conservative()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    #[test]
    fn force_is_charge_times_field_on_free_particles_only() {
        let mut model = Model { mass: vec![1.0; 3], inv_mass: vec![1.0, 0.0, 1.0], ..Default::default() };
        let x = [DVec2::new(1.0, 2.0); 3];
        let mut t = UniformElectricField { name: "e".into(), e: DVec2::new(3.0, -1.0) };
        let mut f = [DVec2::ONE; 3];
        t.add_forces(&x, &x, &model, &mut f, Write::Overwrite);
        assert_eq!(f, [DVec2::ZERO; 3]); // no charge attribute: no force
        assert_eq!(t.potential(&x, &model), Some(0.0));
        model.attributes.insert("charge", vec![2.0, 5.0, -1.0]);
        t.add_forces(&x, &x, &model, &mut f, Write::Add);
        assert_eq!(f, [DVec2::new(6.0, -2.0), DVec2::ZERO, DVec2::new(-3.0, 1.0)]);
        // U = -(2 + (-1)) (3·1 - 1·2): the pinned particle's charge does not count.
        assert_eq!(t.potential(&x, &model), Some(-1.0));
    }
}
