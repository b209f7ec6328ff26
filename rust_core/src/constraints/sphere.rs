//! Sphere collider (a disc in 2D) with restitution and Coulomb friction: a ball that particles
//! land on and slide off, or with `inside` a bowl that keeps them in.
//!
//! The same rule as `Plane`, with the normal taken at the nearest point of the surface: a
//! particle found on the wrong side of the surface after a step (|x − c| < r; with `inside`,
//! |x − c| > r) is projected onto it along the radius; if it moves into the sphere, its normal
//! velocity is reversed and scaled by the restitution e (v_n ← −e v_n), and its tangential
//! velocity is reduced by μ·(1 + e)|v_n| (Coulomb friction on the collision impulse), never past
//! zero. The energy this removes is booked as dissipated: the change in kinetic energy plus the
//! work −F·Δx of the last evaluated force F (with gravity) over the projection Δx (exact for
//! uniform gravity, first order otherwise).
//!
//! The shape is `geometry::Ball`; the loop, the bounce and the books are `Collider`'s
//! (`collider.rs`).
use super::collider::{Collide, Collider};
use super::{Constraint, Contact};
use crate::error::Result;
use crate::geometry::Ball;
use crate::vector::{Real, Vector};

/// The sphere collider: a [`Ball`] (or bowl) with its [`Contact`].
pub type Sphere<V> = Collider<V, Ball<V>>;

impl<V: Vector> Collide<V> for Ball<V> {}

impl<V: Vector> Sphere<V> {
    /// The sphere of `radius` (m) about `center` (m), keeping particles outside it (a ball) or,
    /// with `inside`, in it (a bowl); `InvalidInput` naming the argument if one is out of range.
    pub fn new(center: V, radius: Real, inside: bool, restitution: Real, friction: Real) -> Result<Self> {
        let shape = Ball::new(center, radius, inside)?;
        Ok(Self::with_shape(shape, Contact::new(restitution, friction)?))
    }
}

fn build<V: Vector>(p: &crate::terms::registry::Params) -> Result<Box<dyn Constraint<V>>> {
    let (r, e, mu) = (p.number("radius")?, p.number("restitution")?, p.number("friction")?);
    Ok(Box::new(Sphere::new(p.vector("center")?, r, p.flag("inside")?, e, mu)?))
}
crate::register_collider!("sphere", build);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::Model;
    use glam::{DVec2, DVec3};
    use std::collections::BTreeMap;

    fn model(m: &[Real]) -> Model {
        Model { mass: m.to_vec(), inv_mass: m.iter().map(|&m| 1.0 / m).collect(), attributes: BTreeMap::new() }
    }

    #[test]
    fn sphere_puts_a_particle_moving_in_on_its_surface_with_the_restitution_speed() {
        let (e, m) = (0.6, 2.0);
        let s = Sphere::new(DVec3::new(1.0, 2.0, 3.0), 0.5, false, e, 0.0).unwrap();
        // 0.1 m inside along (1, 2, 2)/3, moving in along the normal with a tangential part.
        let n = DVec3::new(1.0, 2.0, 2.0) / 3.0;
        let t = DVec3::new(2.0, -1.0, 0.0) / 5f64.sqrt(); // ⟂ n
        let mut x = vec![s.shape.center + n * 0.4];
        let mut v = vec![n * -3.0 + t * 1.5];
        let (d, touched) = s.project(&mut x, &mut v, &model(&[m]), &[], DVec3::ZERO, 0.0);
        assert!(touched);
        assert!(((x[0] - s.shape.center).length() - 0.5).abs() < 1e-15, "not on the surface: {:?}", x[0]);
        assert!((x[0] - (s.shape.center + n * 0.5)).length() < 1e-15, "not projected along the radius");
        assert!((v[0].dot(n) - e * 3.0).abs() < 1e-14, "normal speed {} vs e·3", v[0].dot(n));
        assert!((v[0] - n * v[0].dot(n) - t * 1.5).length() < 1e-14, "frictionless: tangential kept");
        // No forces: the energy booked is the kinetic energy lost, ½ m (1 − e²) v_n².
        let lost = 0.5 * m * (1.0 - e * e) * 9.0;
        assert!((d - lost).abs() < 1e-13 * lost, "booked {d} vs lost {lost}");
    }

    #[test]
    fn sphere_friction_slows_the_tangential_speed_and_never_reverses_it() {
        let s = Sphere::new(DVec2::ZERO, 1.0, false, 0.5, 0.2).unwrap();
        let m = model(&[1.0, 1.0]);
        // Normal speed 2 in: the impulse takes μ (1 + e)·2 = 0.6 m/s of tangential speed.
        let mut x = vec![DVec2::new(0.0, 0.9), DVec2::new(0.0, 0.9)];
        let mut v = vec![DVec2::new(1.0, -2.0), DVec2::new(0.5, -2.0)];
        let _ = s.project(&mut x, &mut v, &m, &[], DVec2::ZERO, 0.0);
        assert!((v[0] - DVec2::new(0.4, 1.0)).length() < 1e-14, "{:?}", v[0]);
        let mut x = vec![DVec2::new(0.0, 0.9), DVec2::new(0.0, 0.9)];
        let mut v = vec![DVec2::new(0.5, -2.0), DVec2::new(0.3, -4.0)];
        let _ = s.project(&mut x, &mut v, &m, &[], DVec2::ZERO, 0.0);
        assert_eq!(v[0].x, 0.0, "0.5 m/s stops, never reverses");
        assert_eq!(v[1].x, 0.0);
    }

    #[test]
    fn sphere_books_the_work_against_gravity_and_leaves_the_allowed_side_alone() {
        let g = DVec3::new(0.0, 0.0, -9.81);
        let s = Sphere::new(DVec3::ZERO, 1.0, false, 1.0, 0.0).unwrap();
        // At rest 1 cm under the top: lifted 1 cm against gravity, no kinetic change, so the
        // booked energy is −m g h (energy added, as the plane books its lift).
        let mut x = vec![DVec3::new(0.0, 0.0, 0.99), DVec3::new(0.0, 0.0, 1.5)];
        let mut v = vec![DVec3::ZERO, DVec3::new(0.0, 0.0, -1.0)];
        let (d, touched) = s.project(&mut x, &mut v, &model(&[3.0, 1.0]), &[], g, 0.0);
        assert!(touched);
        assert!((d + 3.0 * 9.81 * 0.01).abs() < 1e-12, "booked {d}");
        assert_eq!(x[1], DVec3::new(0.0, 0.0, 1.5), "outside: not moved");
        assert_eq!(v[1], DVec3::new(0.0, 0.0, -1.0));
        // A particle at the centre at rest goes up; one moving goes back the way it came.
        let mut x = vec![DVec3::ZERO, DVec3::ZERO];
        let mut v = vec![DVec3::ZERO, DVec3::new(1.0, 0.0, 0.0)];
        let _ = s.project(&mut x, &mut v, &model(&[1.0, 1.0]), &[], DVec3::ZERO, 0.0);
        assert_eq!(x, vec![DVec3::Z, -DVec3::X]);
        assert_eq!(v[1], DVec3::new(-1.0, 0.0, 0.0), "e = 1 reverses it");
    }

    #[test]
    fn sphere_inside_keeps_particles_in_a_bowl() {
        let s = Sphere::new(DVec2::new(0.0, 1.0), 1.0, true, 0.0, 0.0).unwrap();
        let mut x = vec![DVec2::new(0.0, -0.1), DVec2::new(0.0, 0.5)];
        let mut v = vec![DVec2::new(1.0, -1.0), DVec2::new(0.0, -1.0)];
        let (d, _) = s.project(&mut x, &mut v, &model(&[1.0, 1.0]), &[], DVec2::ZERO, 0.0);
        assert!((x[0] - DVec2::ZERO).length() < 1e-15);
        assert_eq!(v[0], DVec2::new(1.0, 0.0), "e = 0: the outward speed is removed");
        assert_eq!((x[1], v[1]), (DVec2::new(0.0, 0.5), DVec2::new(0.0, -1.0)), "inside: left alone");
        assert!((d - 0.5).abs() < 1e-15);
    }

    #[test]
    fn sphere_pinned_particles_stay_and_bad_input_is_refused() {
        let s = Sphere::new(DVec2::ZERO, 1.0, false, 0.5, 0.0).unwrap();
        let mut m = model(&[1.0]);
        m.inv_mass[0] = 0.0;
        let mut x = vec![DVec2::new(0.1, 0.0)];
        let mut v = vec![DVec2::new(-1.0, 0.0)];
        assert_eq!(s.project(&mut x, &mut v, &m, &[], DVec2::ZERO, 0.0), (0.0, false));
        assert_eq!(x[0], DVec2::new(0.1, 0.0));
        let err = |r: Result<Sphere<DVec2>>| match r {
            Err(crate::Error::InvalidInput { arg, .. }) => arg,
            other => panic!("expected InvalidInput, got {other:?}"),
        };
        assert_eq!(err(Sphere::new(DVec2::new(f64::NAN, 0.0), 1.0, false, 0.5, 0.0)), "center");
        for r in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e200] {
            assert_eq!(err(Sphere::new(DVec2::ZERO, r, false, 0.5, 0.0)), "radius");
        }
        assert_eq!(err(Sphere::new(DVec2::ZERO, 1.0, false, 1.5, 0.0)), "restitution");
        assert_eq!(err(Sphere::new(DVec2::ZERO, 1.0, false, 0.5, -0.1)), "friction");
    }
}
