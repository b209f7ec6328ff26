//! A uniform magnetic field on charged particles: the Lorentz force F_i = q_i v_i × B on free
//! particles (Griffiths, *Introduction to Electrodynamics*, 4th ed., eq. 5.1). In 2D, B is its z
//! component (out of the plane): the only one that turns motion within the plane. q is the
//! `charge` attribute (C); a scene without it feels no force.
//!
//! The force does no work (F·v = 0), so the term has no potential and dissipates nothing, but it
//! depends on the velocities (`Term::velocity_dependent`). Its field is handed to the Boris
//! integrator (the `Magnetic` role), which turns each velocity through it exactly,
//! keeping |v| to round-off for any step; the other integrators take the force from `add_forces`.
use super::registry::{Context, Params};
use super::{Magnetic, Term, Traits, Write};
use crate::error::Result;
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

pub struct UniformMagneticField<V: Vector> {
    pub name: String,
    /// Field B, T (2D: B_z).
    pub b: V::Axial,
}

fn build<V: Vector>(name: String, p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    Ok(Box::new(UniformMagneticField::<V> { name, b: p.axial::<V>("B")? }))
}
crate::register_term!("uniform_magnetic_field", build);

/// q v × B(x_i) on every free particle of `model` (0 for pinned ones, and for all without the
/// `charge` attribute), stored as `write` says; `field(i)` is B at particle i.
pub(crate) fn lorentz_forces<V: Vector>(
    v: &[V],
    model: &Model,
    f: &mut [V],
    write: Write,
    field: impl Fn(usize) -> V::Axial + Sync + Send,
) {
    let q = model.attribute("charge");
    par::chunks1(f, |s, f| {
        for (k, fi) in f.iter_mut().enumerate() {
            let i = s + k;
            let fb = match q {
                Some(q) if model.inv_mass[i] != 0.0 => v[i].cross_axial(field(i)) * q[i],
                _ => V::ZERO,
            };
            write.put(fi, fb);
        }
    });
}

/// The gyration time scale 1/ω_c = m/(|q| B) (s) of the free particle that turns fastest in a
/// field of at most `b_max` (T); `None` without charges, field, or free charged particles.
pub(crate) fn gyration_time(model: &Model, b_max: Real) -> Option<Real> {
    let q = model.attribute("charge")?;
    let rate = par::reduce(q.len(), 0.0, Real::max, |r| r.map(|i| q[i].abs() * model.inv_mass[i]).fold(0.0, Real::max));
    let w = rate * b_max;
    (w > 0.0).then(|| 1.0 / w).filter(|t| t.is_finite())
}

impl<V: Vector> Term<V> for UniformMagneticField<V> {
    fn name(&self) -> &str {
        &self.name
    }
    fn add_forces(&mut self, _x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let b = self.b;
        lorentz_forces(v, model, f, write, |_| b);
        0.0 // no work: F·v = 0
    }
    fn potential(&self, _x: &[V], _model: &Model) -> Option<Real> {
        None // a velocity-dependent force that does no work has none
    }
    /// The magnetic force depends on the velocities, though it does no work.
    fn traits(&self) -> Traits<V> {
        Traits { velocity_dependent: true, ..Traits::conservative() }
    }
    fn time_scale(&self, _x: &[V], model: &Model) -> Option<Real> {
        gyration_time(model, V::axial_length_squared(self.b).sqrt())
    }
    fn as_magnetic(&self) -> Option<&dyn Magnetic<V>> {
        Some(self)
    }
}

impl<V: Vector> Magnetic<V> for UniformMagneticField<V> {
    fn add_field(&self, _x: &[V], _model: &Model, b: &mut [V::Axial]) {
        let field = self.b;
        par::chunks1(b, |_, b| {
            for bi in b {
                *bi = *bi + field;
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    #[test]
    fn force_is_q_v_cross_b_on_free_charged_particles_only() {
        let mut model = Model { mass: vec![1.0; 3], inv_mass: vec![1.0, 0.0, 0.5], ..Default::default() };
        let v = [DVec3::new(1.0, 2.0, 3.0), DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.0, -1.0, 2.0)];
        let mut t = UniformMagneticField::<DVec3> { name: "b".into(), b: DVec3::new(0.5, -1.0, 2.0) };
        let mut f = [DVec3::ONE; 3];
        assert_eq!(t.add_forces(&v, &v, &model, &mut f, Write::Overwrite), 0.0);
        assert_eq!(f, [DVec3::ZERO; 3]); // no charge attribute
        model.attributes.insert("charge", vec![2.0, 1.0, -3.0]);
        t.add_forces(&v, &v, &model, &mut f, Write::Overwrite);
        assert_eq!(f[0], v[0].cross(t.b) * 2.0);
        assert_eq!(f[1], DVec3::ZERO); // pinned
        assert_eq!(f[2], v[2].cross(t.b) * -3.0);
        assert_eq!(Term::<DVec3>::potential(&t, &v, &model), None);
        let traits = Term::<DVec3>::traits(&t);
        assert!(traits.velocity_dependent && !traits.dissipative);
        let mut b = vec![DVec3::X; 3];
        Magnetic::add_field(&t, &v, &model, &mut b);
        assert_eq!(b, vec![DVec3::X + t.b; 3]);
        // Fastest gyration: |q|/m = 2 (particle 0; 1 is pinned, 2 has 1.5), |B| = sqrt(5.25).
        let ts = Term::<DVec3>::time_scale(&t, &v, &model).unwrap();
        assert!((ts - 1.0 / (2.0 * 5.25f64.sqrt())).abs() < 1e-15, "{ts}");
    }

    #[test]
    fn in_2d_the_field_is_out_of_the_plane() {
        let mut model = Model { mass: vec![1.0], inv_mass: vec![1.0], ..Default::default() };
        model.attributes.insert("charge", vec![1.0]);
        let v = [DVec2::new(1.0, 0.0)];
        let mut t = UniformMagneticField::<DVec2> { name: "b".into(), b: 2.0 };
        let mut f = [DVec2::ZERO];
        t.add_forces(&v, &v, &model, &mut f, Write::Overwrite);
        // x̂ × 2ẑ = −2ŷ: a positive charge moving along +x in B_z > 0 turns clockwise.
        assert_eq!(f[0], DVec2::new(0.0, -2.0));
    }
}
