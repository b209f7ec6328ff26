//! The capsule: the points within `radius` of the segment a–b (a stadium in 2D), kept outside.
//! The round rule of the ball (`ball::onto_round`) about the nearest point of the axis,
//! p = a + t (b − a), t = clamp((x − a)·(b − a)/|b − a|², 0, 1) (Ericson, *Real-Time Collision
//! Detection*, 2005, §5.1.2). With a = b it is a ball.
use super::ball::{onto_round, round_surface};
use super::{splat, zip, Projection, Shape, Surface};
use crate::error::{invalid, Result};
use crate::vector::{Real, Vector};

#[derive(Clone, Debug, PartialEq)]
pub struct Capsule<V: Vector> {
    /// The axis' ends, m.
    pub a: V,
    pub b: V,
    /// Radius, m (> 0, with a finite square).
    pub radius: Real,
}

impl<V: Vector> Capsule<V> {
    /// The capsule of `radius` (m) about the segment `a`–`b` (m); `InvalidInput` naming the
    /// argument if one is out of range.
    pub fn new(a: V, b: V, radius: Real) -> Result<Self> {
        for (p, arg) in [(a, "a"), (b, "b")] {
            if !p.is_finite() {
                return Err(invalid(arg, "must be finite"));
            }
        }
        if !(b - a).length_squared().is_finite() {
            return Err(invalid("b", "the axis' squared length must be finite"));
        }
        if !(radius > 0.0 && (radius * radius).is_finite()) {
            return Err(invalid("radius", format!("{radius} must be > 0 with a finite square")));
        }
        Ok(Self { a, b, radius })
    }

    /// The point of the axis nearest to `x`.
    #[inline(always)]
    pub fn nearest(&self, x: V) -> V {
        let ab = self.b - self.a;
        let l2 = ab.length_squared();
        let t = if l2 > 0.0 { ((x - self.a).dot(ab) / l2).clamp(0.0, 1.0) } else { 0.0 };
        self.a + ab * t
    }
}

impl<V: Vector> Shape<V> for Capsule<V> {
    #[inline(always)]
    fn project(&self, x: V, v: &V) -> Option<Projection<V>> {
        onto_round(x, v, self.nearest(x), self.radius, false)
    }

    /// The ends' box grown by the radius.
    fn bounds(&self) -> (V, V) {
        let r = splat::<V>(self.radius);
        (zip(self.a, self.b, Real::min) - r, zip(self.a, self.b, Real::max) + r)
    }

    /// The ball's rule about the nearest axis point p (module doc): distance |x − p| − r, the
    /// normal (x − p)/|x − p| (up on the axis itself).
    #[inline(always)]
    fn closest(&self, x: V) -> Surface<V> {
        round_surface(x, self.nearest(x), self.radius, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn the_side_pushes_out_perpendicular_and_the_cap_radially() {
        let c = Capsule::new(DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0), 0.5).unwrap();
        let side = c.project(DVec3::new(1.0, 0.3, 0.0), &DVec3::ZERO).unwrap();
        assert!((side.x - DVec3::new(1.0, 0.5, 0.0)).length() < 1e-15 && side.normal == DVec3::Y);
        let cap = c.project(DVec3::new(2.3, 0.0, 0.2), &DVec3::ZERO).unwrap();
        let n = DVec3::new(0.3, 0.0, 0.2).normalize();
        assert!((cap.x - (DVec3::new(2.0, 0.0, 0.0) + n * 0.5)).length() < 1e-15 && (cap.normal - n).length() < 1e-15);
        assert_eq!(c.project(DVec3::new(1.0, 0.0, 0.6), &DVec3::ZERO), None);
        assert_eq!(c.bounds(), (DVec3::new(-0.5, -0.5, -0.5), DVec3::new(2.5, 0.5, 0.5)));
    }
}
