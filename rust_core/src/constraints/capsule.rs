//! Capsule collider: the points within `radius` of the segment from `a` to `b` (a stadium in
//! 2D), which particles are kept out of: a rod, a rail, a rounded beam a cloth drapes over.
//!
//! The rule of the sphere (`sphere.rs`: projection onto the surface along the normal,
//! restitution and Coulomb friction on the impulse, the energy removed booked), with the centre
//! taken at the nearest point of the axis, p = a + t (b − a), t = clamp((x − a)·(b − a)/|b − a|²,
//! 0, 1) (Ericson, *Real-Time Collision Detection*, 2005, §5.1.2). With a = b it is a sphere.
//!
//! The shape is `geometry::Capsule`; the loop, the bounce and the books are `Collider`'s
//! (`collider.rs`).
use super::collider::{Collide, Collider};
use super::{Constraint, Contact};
use crate::error::Result;
use crate::geometry;
use crate::terms::registry::Params;
use crate::vector::{Real, Vector};

/// The capsule collider: a [`geometry::Capsule`] with its [`Contact`].
pub type Capsule<V> = Collider<V, geometry::Capsule<V>>;

impl<V: Vector> Collide<V> for geometry::Capsule<V> {}

impl<V: Vector> Capsule<V> {
    /// The capsule of `radius` (m) about the segment `a`–`b` (m); `InvalidInput` naming the
    /// argument if one is out of range.
    pub fn new(a: V, b: V, radius: Real, restitution: Real, friction: Real) -> Result<Self> {
        let shape = geometry::Capsule::new(a, b, radius)?;
        Ok(Self::with_shape(shape, Contact::new(restitution, friction)?))
    }
}

fn build<V: Vector>(p: &Params) -> Result<Box<dyn Constraint<V>>> {
    let (r, e, mu) = (p.number("radius")?, p.number("restitution")?, p.number("friction")?);
    Ok(Box::new(Capsule::new(p.vector("a")?, p.vector("b")?, r, e, mu)?))
}
crate::register_collider!("capsule", build);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::Model;
    use glam::{DVec2, DVec3};
    use std::collections::BTreeMap;

    fn model(n: usize, m: Real) -> Model {
        Model { mass: vec![m; n], inv_mass: vec![1.0 / m; n], attributes: BTreeMap::new() }
    }

    /// Along the side a particle is pushed out along the perpendicular; past an end, radially
    /// from the end (the cap); outside it is left alone.
    #[test]
    fn the_side_and_the_caps_push_out_along_their_normals() {
        let c = Capsule::new(DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0), 0.5, 1.0, 0.0).unwrap();
        let mut x = vec![DVec3::new(1.0, 0.3, 0.0), DVec3::new(2.3, 0.0, 0.2), DVec3::new(1.0, 0.0, 0.6)];
        let mut v = vec![DVec3::new(0.0, -1.0, 0.0), DVec3::ZERO, DVec3::new(0.0, 0.0, -1.0)];
        let (d, touched) = c.project(&mut x, &mut v, &model(3, 1.0), &[], DVec3::ZERO, 0.0);
        assert!(touched);
        assert!((x[0] - DVec3::new(1.0, 0.5, 0.0)).length() < 1e-15);
        assert_eq!(v[0], DVec3::new(0.0, 1.0, 0.0), "e = 1: the normal velocity reverses");
        let cap = DVec3::new(2.0, 0.0, 0.0) + DVec3::new(0.3, 0.0, 0.2).normalize() * 0.5;
        assert!((x[1] - cap).length() < 1e-15);
        assert_eq!((x[2], v[2]), (DVec3::new(1.0, 0.0, 0.6), DVec3::new(0.0, 0.0, -1.0)));
        assert!(d.abs() < 1e-15, "elastic and without forces: nothing dissipated ({d})");
    }

    /// A particle falling onto a flat capsule with e = 0 and friction loses all its normal
    /// speed; the energy booked is the kinetic energy lost plus the projection's work.
    #[test]
    fn an_inelastic_landing_books_the_energy_it_removes() {
        let c = Capsule::new(DVec2::new(-1.0, 0.0), DVec2::new(1.0, 0.0), 0.1, 0.0, 0.0).unwrap();
        let (m, g) = (2.0, DVec2::new(0.0, -9.81));
        let mut x = vec![DVec2::new(0.2, 0.09)];
        let mut v = vec![DVec2::new(0.5, -3.0)];
        let (d, _) = c.project(&mut x, &mut v, &model(1, m), &[], g, 0.0);
        // (The nearest axis point, −1 + 1.2 = 0.19999999999999996, tilts the normal by 5e-16.)
        assert!((v[0] - DVec2::new(0.5, 0.0)).length() < 1e-14, "{}", v[0]);
        let work = -(g * m).dot(x[0] - DVec2::new(0.2, 0.09));
        let lost = 0.5 * m * (DVec2::new(0.5, -3.0).length_squared() - v[0].length_squared());
        assert!((d - (lost - work)).abs() < 1e-12, "{d}");
        assert!((x[0].y - 0.1).abs() < 1e-15);
    }

    #[test]
    fn bad_parameters_are_named() {
        let o = DVec2::ZERO;
        let e = |r: Result<Capsule<DVec2>>| r.unwrap_err().to_string();
        assert!(e(Capsule::new(DVec2::new(f64::NAN, 0.0), o, 1.0, 0.5, 0.0)).contains("a"));
        assert!(e(Capsule::new(o, DVec2::new(1e200, 1e200), 1.0, 0.5, 0.0)).contains("b"));
        assert!(e(Capsule::new(o, o, 0.0, 0.5, 0.0)).contains("radius"));
        assert!(e(Capsule::new(o, o, 1.0, 1.5, 0.0)).contains("restitution"));
    }
}
