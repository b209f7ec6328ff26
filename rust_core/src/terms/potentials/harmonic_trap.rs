//! A harmonic trap: every free particle is tied to the point c by a spring of stiffness k_a per
//! axis (N/m), F_a = −k_a (x_a − c_a), U = ½ Σ_i Σ_a k_a (x_ia − c_a)². An isotropic trap has all
//! k_a equal; a particle of mass m then oscillates at ω = √(k/m) on every axis.
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::terms::registry::{Context, Params};
use crate::terms::{Term, Traits, Write};
use crate::vector::{Real, Vector};

pub struct HarmonicTrap<V: Vector> {
    pub name: String,
    /// Stiffness per axis, N/m (each ≥ 0).
    pub k: V,
    /// Centre, m.
    pub center: V,
}

fn build<V: Vector>(name: String, p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    Ok(Box::new(HarmonicTrap::new(name, p.vector("k")?, p.vector("center")?)?))
}
crate::register_term!("harmonic_trap", build);

/// The component-wise product of `a` and `b`.
#[inline(always)]
fn times<V: Vector>(a: V, b: V) -> V {
    let mut c = [0.0; 3];
    for (k, o) in c.iter_mut().enumerate().take(V::DIM) {
        *o = a.comp(k) * b.comp(k);
    }
    V::from_slice(&c)
}

impl<V: Vector> HarmonicTrap<V> {
    pub fn new(name: String, k: V, center: V) -> Result<Self> {
        for a in 0..V::DIM {
            let ka = k.comp(a);
            if !(ka.is_finite() && ka >= 0.0) {
                return Err(invalid("k", format!("component {a} is {ka} (must be finite and >= 0)")));
            }
        }
        if !center.is_finite() {
            return Err(invalid("center", "must be finite"));
        }
        Ok(Self { name, k, center })
    }
}

impl<V: Vector> Term<V> for HarmonicTrap<V> {
    fn name(&self) -> &str {
        &self.name
    }
    fn add_forces(&mut self, x: &[V], _v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let (k, c) = (self.k, self.center);
        par::chunks1(f, |s, f| {
            for (j, fi) in f.iter_mut().enumerate() {
                let i = s + j;
                let fe = if model.inv_mass[i] != 0.0 { -times(k, x[i] - c) } else { V::ZERO };
                write.put(fi, fe);
            }
        });
        0.0
    }
    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        let (k, c) = (self.k, self.center);
        Some(par::sum(x.len(), 0.0, |r| {
            let mut u = 0.0;
            for i in r {
                if model.inv_mass[i] != 0.0 {
                    let d = x[i] - c;
                    u += 0.5 * times(k, d).dot(d);
                }
            }
            u
        }))
    }
    fn traits(&self) -> Traits<V> {
        Traits::conservative()
    }
    fn time_scale(&self, _x: &[V], model: &Model) -> Option<Real> {
        // 1/ω of the lightest free particle on the stiffest axis: √(m / k).
        let kmax = (0..V::DIM).map(|a| self.k.comp(a)).fold(0.0, Real::max);
        let w2 = model.inv_mass.iter().fold(0.0, |w: Real, &im| w.max(kmax * im));
        let t = 1.0 / w2.sqrt();
        (t.is_finite() && t > 0.0).then_some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    #[test]
    fn the_force_pulls_towards_the_centre_axis_by_axis() {
        let mut t = HarmonicTrap::new("t".into(), DVec3::new(1.0, 2.0, 0.0), DVec3::new(1.0, 1.0, 1.0)).unwrap();
        let model = Model { mass: vec![4.0; 2], inv_mass: vec![0.25, 0.0], ..Default::default() };
        let x = [DVec3::new(3.0, 0.0, 7.0); 2];
        let mut f = [DVec3::ONE; 2];
        t.add_forces(&x, &x, &model, &mut f, Write::Overwrite);
        assert_eq!(f, [DVec3::new(-2.0, 2.0, 0.0), DVec3::ZERO]);
        assert_eq!(t.potential(&x, &model), Some(0.5 * (4.0 + 2.0)));
        assert!((t.time_scale(&x, &model).unwrap() - 2.0f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn negative_or_infinite_stiffness_is_refused_by_name() {
        let e = HarmonicTrap::new("t".into(), DVec2::new(1.0, -1.0), DVec2::ZERO).err().unwrap().to_string();
        assert!(e.starts_with("k: component 1 is -1"), "{e}");
        let e = HarmonicTrap::new("t".into(), DVec2::ONE, DVec2::new(0.0, f64::INFINITY)).err().unwrap().to_string();
        assert!(e.starts_with("center"), "{e}");
        let free = HarmonicTrap::new("t".into(), DVec2::ZERO, DVec2::ZERO).unwrap();
        let model = Model { mass: vec![1.0], inv_mass: vec![1.0], ..Default::default() };
        assert_eq!(free.time_scale(&[DVec2::ZERO], &model), None);
    }
}
