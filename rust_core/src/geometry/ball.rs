//! The ball {x : |x − c| < r} (a disc in 2D), kept outside; with `inside`, a bowl: the outside
//! {|x − c| > r} is forbidden. Also the round rule the capsule shares (`onto_round`).
use super::{splat, unbounded, up, Projection, Shape, Surface};
use crate::error::{invalid, Result};
use crate::vector::{Real, Vector};

#[derive(Clone, Debug, PartialEq)]
pub struct Ball<V: Vector> {
    /// Centre, m.
    pub center: V,
    /// Radius, m (> 0, with a finite square).
    pub radius: Real,
    /// Keep points inside (a bowl) instead of outside (a ball).
    pub inside: bool,
}

impl<V: Vector> Ball<V> {
    /// The ball of `radius` (m) about `center` (m), or with `inside` the bowl; `InvalidInput`
    /// naming the argument if one is out of range.
    pub fn new(center: V, radius: Real, inside: bool) -> Result<Self> {
        if !center.is_finite() {
            return Err(invalid("center", "must be finite"));
        }
        // r² must be finite too: the test compares squared distances.
        if !(radius > 0.0 && (radius * radius).is_finite()) {
            return Err(invalid("radius", format!("{radius} must be > 0 with a finite square")));
        }
        Ok(Self { center, radius, inside })
    }
}

/// The round rule, shared by the ball and the capsule: the surface at distance `r` from `c`
/// (the ball's centre; the capsule's nearest axis point), `x` forbidden when nearer (with
/// `inside`, farther); it moves radially to c + r·radial. A point at `c` goes back the way it
/// came (along −v), or up at rest. NaN positions compare false and are left alone.
#[inline(always)]
pub(crate) fn onto_round<V: Vector>(x: V, v: &V, c: V, r: Real, inside: bool) -> Option<Projection<V>> {
    let r2 = r * r;
    let rel = x - c;
    let l2 = rel.length_squared();
    let wrong = if inside { l2 > r2 } else { l2 < r2 };
    if !wrong {
        return None;
    }
    let l = l2.sqrt();
    let radial = if l > 0.0 {
        rel / l
    } else if v.length_squared() > 0.0 {
        -*v / v.length_squared().sqrt()
    } else {
        up::<V>()
    };
    let moved = c + radial * r;
    Some(Projection { x: moved, dx: moved - x, normal: if inside { -radial } else { radial } })
}

/// The round surface at distance `r` from `c` seen from `x` (the ball and the capsule's
/// `closest`): with l = |x − c| and the radial direction u = (x − c)/l (up where l = 0), the
/// point c + r·u; outside kept (a ball) distance l − r and normal u; inside kept (a bowl)
/// distance r − l and normal −u.
#[inline(always)]
pub(crate) fn round_surface<V: Vector>(x: V, c: V, r: Real, inside: bool) -> Surface<V> {
    let rel = x - c;
    let l = rel.length_squared().sqrt();
    let u = if l > 0.0 { rel / l } else { up::<V>() };
    let point = c + u * r;
    if inside {
        Surface { point, normal: -u, distance: r - l }
    } else {
        Surface { point, normal: u, distance: l - r }
    }
}

impl<V: Vector> Shape<V> for Ball<V> {
    #[inline(always)]
    fn project(&self, x: V, v: &V) -> Option<Projection<V>> {
        onto_round(x, v, self.center, self.radius, self.inside)
    }

    /// c ± r for a ball; a bowl's forbidden side (its outside) is unbounded.
    fn bounds(&self) -> (V, V) {
        if self.inside {
            return unbounded();
        }
        let r = splat::<V>(self.radius);
        (self.center - r, self.center + r)
    }

    /// `round_surface` about the centre: distance |x − c| − r (a bowl: r − |x − c|), the
    /// normal radial (a bowl: towards the centre); at the centre itself, up.
    #[inline(always)]
    fn closest(&self, x: V) -> Surface<V> {
        round_surface(x, self.center, self.radius, self.inside)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    #[test]
    fn a_point_inside_the_ball_moves_out_along_the_radius() {
        let b = Ball::new(DVec3::new(1.0, 2.0, 3.0), 0.5, false).unwrap();
        let n = DVec3::new(1.0, 2.0, 2.0) / 3.0;
        let p = b.project(b.center + n * 0.2, &DVec3::ZERO).unwrap();
        assert!((p.x - (b.center + n * 0.5)).length() < 1e-15);
        assert!((p.normal - n).length() < 1e-15 && (p.dx - n * 0.3).length() < 1e-15);
        assert_eq!(b.project(b.center + n * 0.5, &DVec3::ZERO), None, "on the surface: allowed");
        assert_eq!(b.project(b.center + n * 0.7, &DVec3::ZERO), None);
        assert_eq!(b.bounds(), (DVec3::new(0.5, 1.5, 2.5), DVec3::new(1.5, 2.5, 3.5)));
    }

    #[test]
    fn a_bowl_pulls_points_in_with_the_normal_pointing_to_the_centre() {
        let b = Ball::new(DVec2::new(0.0, 1.0), 1.0, true).unwrap();
        let p = b.project(DVec2::new(0.0, -0.5), &DVec2::ZERO).unwrap();
        assert_eq!((p.x, p.normal, p.dx), (DVec2::ZERO, DVec2::Y, DVec2::new(0.0, 0.5)));
        assert_eq!(b.project(DVec2::new(0.0, 0.5), &DVec2::ZERO), None);
        assert_eq!(b.bounds(), (DVec2::NEG_INFINITY, DVec2::INFINITY));
    }

    #[test]
    fn the_centre_goes_back_along_the_velocity_or_up() {
        let b = Ball::new(DVec2::ZERO, 2.0, false).unwrap();
        assert_eq!(b.project(DVec2::ZERO, &DVec2::new(3.0, 0.0)).unwrap().x, DVec2::new(-2.0, 0.0));
        assert_eq!(b.project(DVec2::ZERO, &DVec2::ZERO).unwrap().x, DVec2::new(0.0, 2.0));
        assert_eq!(b.project(DVec2::new(f64::NAN, 0.0), &DVec2::ZERO), None, "NaN left alone");
    }
}
