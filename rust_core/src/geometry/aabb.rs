//! The axis-aligned box [lo, hi] with points kept inside (a tank, a room): its outside is the
//! forbidden side.
use super::{unbounded, zip, Projection, Shape};
use crate::error::{invalid, Result};
use crate::vector::{Real, Vector};

#[derive(Clone, Debug, PartialEq)]
pub struct Aabb<V: Vector> {
    /// Lower corner, m.
    pub lo: V,
    /// Upper corner, m (> lo on every axis).
    pub hi: V,
}

impl<V: Vector> Aabb<V> {
    /// The box [lo, hi] (m); `InvalidInput` naming the argument if one is out of range.
    pub fn new(lo: V, hi: V) -> Result<Self> {
        if !(lo.is_finite() && hi.is_finite()) {
            return Err(invalid("lower/upper", "must be finite"));
        }
        if (0..V::DIM).any(|k| !(hi.comp(k) > lo.comp(k))) {
            return Err(invalid("upper", "must be > lower on every axis"));
        }
        Ok(Self { lo, hi })
    }
}

impl<V: Vector> Shape<V> for Aabb<V> {
    /// Clamped into [lo, hi], the nearest point of the box (Ericson, *Real-Time Collision
    /// Detection*, 2005, §5.1.3); the normal points back in along the displacement (at a
    /// corner or an edge, the diagonal). The box collider does not use this answer: it bounces
    /// face by face (`constraints::aabb`).
    fn project(&self, x: V, _v: &V) -> Option<Projection<V>> {
        let outside = (0..V::DIM).any(|k| x.comp(k) < self.lo.comp(k) || x.comp(k) > self.hi.comp(k));
        if !outside {
            return None;
        }
        let moved = zip(zip(x, self.lo, Real::max), self.hi, Real::min);
        let dx = moved - x;
        Some(Projection { x: moved, dx, normal: dx / dx.length_squared().sqrt() })
    }

    /// The outside of a box is unbounded.
    fn bounds(&self) -> (V, V) {
        unbounded()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    #[test]
    fn a_point_outside_is_clamped_onto_the_nearest_face_edge_or_corner() {
        let b = Aabb::new(DVec2::ZERO, DVec2::new(2.0, 1.0)).unwrap();
        let face = b.project(DVec2::new(1.0, -0.5), &DVec2::ZERO).unwrap();
        assert_eq!((face.x, face.normal), (DVec2::new(1.0, 0.0), DVec2::Y));
        let corner = b.project(DVec2::new(3.0, 2.0), &DVec2::ZERO).unwrap();
        assert_eq!(corner.x, DVec2::new(2.0, 1.0));
        assert!((corner.normal - DVec2::new(-1.0, -1.0) / 2f64.sqrt()).length() < 1e-15);
        assert_eq!(b.project(DVec2::new(2.0, 0.5), &DVec2::ZERO), None, "on a face: allowed");
        assert!(Aabb::new(DVec2::ZERO, DVec2::new(1.0, 0.0)).is_err());
    }
}
