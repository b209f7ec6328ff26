//! The axis-aligned box [lo, hi] with points kept inside (a tank, a room): its outside is the
//! forbidden side.
use super::{unbounded, zip, Projection, Shape, Surface};
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

    /// Outside: the clamped point c = clamp(x, lo, hi), distance −|x − c|, normal
    /// (c − x)/|x − c| (back in). Inside or on a face: the nearest face, the least of
    /// x_k − lo_k (normal +e_k) and hi_k − x_k (normal −e_k) over the axes (the first on a tie,
    /// lower before upper), that distance (≥ 0), and x with x_k set on that face. One face
    /// only: a grain in a corner touches two, so the grains' walls take a box as its faces.
    fn closest(&self, x: V) -> Surface<V> {
        let c = zip(zip(x, self.lo, Real::max), self.hi, Real::min);
        let l2 = (x - c).length_squared();
        // Outside, or NaN (which the clamp does not keep: its distance must be NaN).
        if l2 != 0.0 {
            let l = l2.sqrt();
            return Surface { point: c, normal: (c - x) / l, distance: -l };
        }
        let mut best = (Real::INFINITY, 0, 1.0);
        for k in 0..V::DIM {
            let (below, above) = (x.comp(k) - self.lo.comp(k), self.hi.comp(k) - x.comp(k));
            if below < best.0 {
                best = (below, k, 1.0);
            }
            if above < best.0 {
                best = (above, k, -1.0);
            }
        }
        let (distance, k, s) = best;
        let (mut n, mut p) = ([0.0; 3], [0.0; 3]);
        for j in 0..V::DIM {
            p[j] = x.comp(j);
        }
        n[k] = s;
        p[k] = if s > 0.0 { self.lo.comp(k) } else { self.hi.comp(k) };
        Surface { point: V::from_slice(&p[..V::DIM]), normal: V::from_slice(&n[..V::DIM]), distance }
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
