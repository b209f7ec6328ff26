//! Oriented box collider: a rotated block particles are kept out of (a tilted ramp, a wedge, a
//! beam at an angle), added through the shape layer alone: the geometry is
//! `geometry::OrientedBox` (a particle inside leaves through the nearest face), the loop,
//! bounce and books are `Collider`'s (`collider.rs`).
use super::collider::{Collide, Collider};
use super::{Constraint, Contact};
use crate::error::Result;
use crate::geometry;
use crate::terms::registry::Params;
use crate::vector::{Real, Vector};

/// The oriented box collider: a [`geometry::OrientedBox`] with its [`Contact`].
pub type OrientedBox<V> = Collider<V, geometry::OrientedBox<V>>;

impl<V: Vector> Collide<V> for geometry::OrientedBox<V> {}

impl<V: Vector> OrientedBox<V> {
    /// The box about `center` (m) with `half_extents` (m) turned by `rotation` (rad: an angle
    /// in 2D, a rotation vector in 3D; `geometry::oriented_box`); `InvalidInput` naming the
    /// argument if one is out of range.
    pub fn new(center: V, half_extents: V, rotation: V::Axial, restitution: Real, friction: Real) -> Result<Self> {
        let shape = geometry::OrientedBox::new(center, half_extents, rotation)?;
        Ok(Self::with_shape(shape, Contact::new(restitution, friction)?))
    }
}

fn build<V: Vector>(p: &Params) -> Result<Box<dyn Constraint<V>>> {
    let (e, mu) = (p.number("restitution")?, p.number("friction")?);
    Ok(Box::new(OrientedBox::new(p.vector("center")?, p.vector("half_extents")?, p.axial::<V>("rotation")?, e, mu)?))
}
crate::register_collider!("oriented_box", build);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::Model;
    use glam::{DVec2, DVec3};
    use std::collections::BTreeMap;

    fn model(n: usize, m: Real) -> Model {
        Model { mass: vec![m; n], inv_mass: vec![1.0 / m; n], attributes: BTreeMap::new() }
    }

    /// A ramp tilted by 30°: a particle that fell 1 cm into its top face while moving straight
    /// down lands on the face; with e = 1 its normal velocity reverses, with e = 0 it is gone,
    /// the tangential part kept (no friction); the energy booked is the kinetic energy lost
    /// minus the potential energy the lift gave it, −(work of gravity) = −m g·Δx.
    #[test]
    fn a_particle_falling_onto_a_tilted_ramp_bounces_with_the_restitution_and_books_it() {
        let (m, g) = (0.5, DVec2::new(0.0, -9.81));
        let theta = std::f64::consts::FRAC_PI_6;
        let n = DVec2::new(-theta.sin(), theta.cos()); // the top face's outward normal
        for e in [1.0, 0.0] {
            let ramp = OrientedBox::new(DVec2::new(0.0, -1.0), DVec2::new(2.0, 1.0), theta, e, 0.0).unwrap();
            let x0 = ramp.shape.center + n * 0.99;
            let v0 = DVec2::new(0.0, -2.0);
            let (mut x, mut v) = (vec![x0], vec![v0]);
            let (d, touched) = ramp.project(&mut x, &mut v, &model(1, m), &[], g, 0.0);
            assert!(touched);
            assert!(((x[0] - ramp.shape.center).dot(n) - 1.0).abs() < 1e-14, "on the top face: {:?}", x[0]);
            let (vn0, vt0) = (v0.dot(n), v0 - n * v0.dot(n));
            assert!((v[0].dot(n) + e * vn0).abs() < 1e-14, "e = {e}: normal speed {}", v[0].dot(n));
            assert!((v[0] - n * v[0].dot(n) - vt0).length() < 1e-14, "tangential kept");
            let lost = 0.5 * m * (v0.length_squared() - v[0].length_squared());
            let work = (g * m).dot(x[0] - x0); // gravity's work over the lift (< 0)
            assert!(work < -1e-3, "lifted against gravity: {work}");
            assert!((d - (lost + work)).abs() < 1e-13, "e = {e}: booked {d}, expected {}", lost + work);
            assert!(
                if e == 1.0 { lost.abs() < 1e-13 } else { lost > 0.5 * m * vn0 * vn0 * 0.99 },
                "e = {e}: lost {lost}"
            );
        }
    }

    /// Pinned particles stay put, particles outside are left alone, and only a 3D rotation
    /// vector is read in 3D.
    #[test]
    fn pinned_and_outside_particles_are_untouched() {
        let b = OrientedBox::new(DVec3::ZERO, DVec3::ONE, DVec3::new(0.0, 0.3, 0.0), 0.5, 0.2).unwrap();
        let mut m = model(2, 1.0);
        m.inv_mass[0] = 0.0;
        let mut x = vec![DVec3::new(0.1, 0.0, 0.0), DVec3::new(0.0, 0.0, 2.0)];
        let mut v = vec![DVec3::new(0.0, 0.0, -1.0), DVec3::new(0.0, 0.0, -1.0)];
        let (x0, v0) = (x.clone(), v.clone());
        assert_eq!(b.project(&mut x, &mut v, &m, &[], DVec3::new(0.0, 0.0, -9.81), 0.0), (0.0, false));
        assert_eq!((x, v), (x0, v0));
    }

    #[test]
    fn the_registry_builds_it_and_names_a_bad_rotation() {
        use crate::terms::registry::Value;
        let p = |rot: Vec<Real>| {
            Params::new()
                .with("center", Value::Floats(vec![0.0, 0.0]))
                .with("half_extents", Value::Floats(vec![1.0, 0.5]))
                .with("rotation", Value::Floats(rot))
                .with("restitution", Value::Number(0.5))
                .with("friction", Value::Number(0.0))
        };
        let ty = super::super::registry::lookup("oriented_box").unwrap();
        assert!(ty.build::<DVec2>(&p(vec![0.3])).is_ok());
        assert!(ty.build::<DVec2>(&p(vec![0.0, 0.0, 0.3])).err().unwrap().to_string().contains("rotation"));
    }
}
