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
use super::{Constraint, Contact};
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

#[derive(Clone, Debug)]
pub struct Sphere<V: Vector> {
    /// Centre, m.
    pub(crate) center: V,
    /// Radius, m (> 0 and finite).
    pub(crate) radius: Real,
    /// Keep particles inside (a bowl) instead of outside (a ball).
    pub(crate) inside: bool,
    pub(crate) contact: Contact,
}

impl<V: Vector> Sphere<V> {
    /// The sphere of `radius` (m) about `center` (m), keeping particles outside it (a ball) or,
    /// with `inside`, in it (a bowl); `InvalidInput` naming the argument if one is out of range.
    pub fn new(center: V, radius: Real, inside: bool, restitution: Real, friction: Real) -> Result<Self> {
        if !center.is_finite() {
            return Err(invalid("center", "must be finite"));
        }
        // r² must be finite too: the test below compares squared distances.
        if !(radius > 0.0 && (radius * radius).is_finite()) {
            return Err(invalid("radius", format!("{radius} must be > 0 with a finite square")));
        }
        let contact = Contact::new(restitution, friction)?;
        Ok(Self { center, radius, inside, contact })
    }
}

/// A unit vector along the last axis (z in 3D, y in 2D): the direction out of a particle found
/// exactly at the centre and at rest.
fn up<V: Vector>() -> V {
    let mut a = [0.0; 3];
    a[V::DIM - 1] = 1.0;
    V::from_slice(&a[..V::DIM])
}

impl<V: Vector> Constraint<V> for Sphere<V> {
    fn project(&self, x: &mut [V], v: &mut [V], model: &Model, f_last: &[V], g: V) -> (Real, bool) {
        let c = self.center;
        project_round(x, v, model, f_last, g, self.radius, self.inside, self.contact, |_| c)
    }
}

/// The rule of a round surface (module doc), shared by the sphere and the capsule: the surface
/// is at distance `r` from `centre_of(x)` (the sphere's centre; the nearest point of a capsule's
/// axis), particles kept outside (or with `inside`, within). Returns (energy removed, J;
/// whether any particle was moved).
#[allow(clippy::too_many_arguments)]
pub(super) fn project_round<V: Vector>(
    x: &mut [V],
    v: &mut [V],
    model: &Model,
    f_last: &[V],
    g: V,
    r: Real,
    inside: bool,
    contact: Contact,
    centre_of: impl Fn(V) -> V + Sync,
) -> (Real, bool) {
    let r2 = r * r;
    par::chunks2_fold(
        x,
        v,
        (0.0, false),
        |a, b| (a.0 + b.0, a.1 | b.1),
        |s, x, v| {
            let mut d = 0.0;
            let mut touched = false;
            for k in 0..x.len() {
                let c = centre_of(x[k]);
                let rel = x[k] - c;
                let l2 = rel.length_squared();
                // NaN positions compare false and are left alone, as the plane leaves them.
                let wrong = if inside { l2 > r2 } else { l2 < r2 };
                if !wrong {
                    continue;
                }
                let i = s + k;
                if model.inv_mass[i] == 0.0 {
                    continue;
                }
                touched = true;
                let m = model.mass[i];
                let ke0 = 0.5 * m * v[k].length_squared();
                // Outward radial unit vector; a particle exactly at the centre goes back the
                // way it came (or up, at rest).
                let l = l2.sqrt();
                let radial = if l > 0.0 {
                    rel / l
                } else if v[k].length_squared() > 0.0 {
                    -v[k] / v[k].length_squared().sqrt()
                } else {
                    up::<V>()
                };
                // Unit normal into the allowed side.
                let n = if inside { -radial } else { radial };
                let x0 = x[k];
                x[k] = c + radial * r;
                v[k] = contact.bounce(v[k], n);
                let ke1 = 0.5 * m * v[k].length_squared();
                // Projection work: ΔU ≈ −F·Δx.
                let f = if f_last.len() > i { f_last[i] } else { V::ZERO } + g * m;
                let du = -f.dot(x[k] - x0);
                d += (ke0 - ke1) - du;
            }
            (d, touched)
        },
    )
}

fn build<V: Vector>(p: &crate::terms::registry::Params) -> Result<Box<dyn Constraint<V>>> {
    let (r, e, mu) = (p.number("radius")?, p.number("restitution")?, p.number("friction")?);
    Ok(Box::new(Sphere::new(p.vector("center")?, r, p.flag("inside")?, e, mu)?))
}
crate::register_collider!("sphere", build);

#[cfg(test)]
mod tests {
    use super::*;
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
        let mut x = vec![s.center + n * 0.4];
        let mut v = vec![n * -3.0 + t * 1.5];
        let (d, touched) = s.project(&mut x, &mut v, &model(&[m]), &[], DVec3::ZERO);
        assert!(touched);
        assert!(((x[0] - s.center).length() - 0.5).abs() < 1e-15, "not on the surface: {:?}", x[0]);
        assert!((x[0] - (s.center + n * 0.5)).length() < 1e-15, "not projected along the radius");
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
        let _ = s.project(&mut x, &mut v, &m, &[], DVec2::ZERO);
        assert!((v[0] - DVec2::new(0.4, 1.0)).length() < 1e-14, "{:?}", v[0]);
        let mut x = vec![DVec2::new(0.0, 0.9), DVec2::new(0.0, 0.9)];
        let mut v = vec![DVec2::new(0.5, -2.0), DVec2::new(0.3, -4.0)];
        let _ = s.project(&mut x, &mut v, &m, &[], DVec2::ZERO);
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
        let (d, touched) = s.project(&mut x, &mut v, &model(&[3.0, 1.0]), &[], g);
        assert!(touched);
        assert!((d + 3.0 * 9.81 * 0.01).abs() < 1e-12, "booked {d}");
        assert_eq!(x[1], DVec3::new(0.0, 0.0, 1.5), "outside: not moved");
        assert_eq!(v[1], DVec3::new(0.0, 0.0, -1.0));
        // A particle at the centre at rest goes up; one moving goes back the way it came.
        let mut x = vec![DVec3::ZERO, DVec3::ZERO];
        let mut v = vec![DVec3::ZERO, DVec3::new(1.0, 0.0, 0.0)];
        let _ = s.project(&mut x, &mut v, &model(&[1.0, 1.0]), &[], DVec3::ZERO);
        assert_eq!(x, vec![DVec3::Z, -DVec3::X]);
        assert_eq!(v[1], DVec3::new(-1.0, 0.0, 0.0), "e = 1 reverses it");
    }

    #[test]
    fn sphere_inside_keeps_particles_in_a_bowl() {
        let s = Sphere::new(DVec2::new(0.0, 1.0), 1.0, true, 0.0, 0.0).unwrap();
        let mut x = vec![DVec2::new(0.0, -0.1), DVec2::new(0.0, 0.5)];
        let mut v = vec![DVec2::new(1.0, -1.0), DVec2::new(0.0, -1.0)];
        let (d, _) = s.project(&mut x, &mut v, &model(&[1.0, 1.0]), &[], DVec2::ZERO);
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
        assert_eq!(s.project(&mut x, &mut v, &m, &[], DVec2::ZERO), (0.0, false));
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
