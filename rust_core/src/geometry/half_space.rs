//! The half-space {x : (x − p)·n ≥ 0}: a floor, a wall, a ramp of any tilt.
use super::{unbounded, Projection, Shape, Surface};
use crate::error::{invalid, Result};
use crate::vector::{Real, Vector};

#[derive(Clone, Debug, PartialEq)]
pub struct HalfSpace<V: Vector> {
    /// A point on the plane, m.
    pub point: V,
    /// Unit normal into the allowed side.
    pub normal: V,
}

impl<V: Vector> HalfSpace<V> {
    /// The half-space bounded by the plane through `point` (m) with `normal` (any length > 0:
    /// it is normalised) pointing into the allowed side; `InvalidInput` naming the argument if
    /// one is not finite or the normal is zero.
    pub fn new(point: V, normal: V) -> Result<Self> {
        if !point.is_finite() {
            return Err(invalid("point", "must be finite"));
        }
        let l2 = normal.length_squared();
        if !(l2.is_finite() && l2 > 0.0) {
            return Err(invalid("normal", "must be finite and non-zero"));
        }
        Ok(Self { point, normal: normal / l2.sqrt() })
    }
}

impl<V: Vector> Shape<V> for HalfSpace<V> {
    /// Moved along the normal by the depth: x + n·(−(x − p)·n). A NaN depth is not refused
    /// here (it moves to NaN, as it always has): the divergence check reports it.
    #[inline(always)]
    fn project(&self, x: V, _v: &V) -> Option<Projection<V>> {
        let n = self.normal;
        let depth = (x - self.point).dot(n);
        if depth >= 0.0 {
            return None;
        }
        let dx = n * (-depth);
        let mut moved = x;
        moved += dx;
        Some(Projection { x: moved, dx, normal: n })
    }

    /// Bounded on one axis only when the normal is that axis (a level floor: hi_z = p_z).
    fn bounds(&self) -> (V, V) {
        let axis = (0..V::DIM).find(|&k| self.normal.comp(k).abs() == 1.0);
        let Some(k) = axis else { return unbounded() };
        let (mut lo, mut hi) = ([Real::NEG_INFINITY; 3], [Real::INFINITY; 3]);
        if self.normal.comp(k) > 0.0 {
            hi[k] = self.point.comp(k);
        } else {
            lo[k] = self.point.comp(k);
        }
        (V::from_slice(&lo[..V::DIM]), V::from_slice(&hi[..V::DIM]))
    }

    /// Distance (x − p)·n, normal n, point x − n·distance. The grains' plane walls take the
    /// distance and the normal as they always computed them (the same operations, the same bits).
    #[inline(always)]
    fn closest(&self, x: V) -> Surface<V> {
        let n = self.normal;
        let distance = (x - self.point).dot(n);
        Surface { point: x - n * distance, normal: n, distance }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    #[test]
    fn a_point_below_moves_along_the_normal_onto_the_plane() {
        let h = HalfSpace::new(DVec2::new(0.0, 1.0), DVec2::new(0.0, 2.0)).unwrap();
        assert_eq!(h.normal, DVec2::Y, "normalised");
        let p = h.project(DVec2::new(0.3, 0.75), &DVec2::ZERO).unwrap();
        assert_eq!(p, Projection { x: DVec2::new(0.3, 1.0), dx: DVec2::new(0.0, 0.25), normal: DVec2::Y });
        assert_eq!(h.project(DVec2::new(5.0, 1.0), &DVec2::ZERO), None, "on the plane: allowed");
        assert_eq!(h.project(DVec2::new(5.0, 1.5), &DVec2::ZERO), None);
        // Tilted: the projection is the nearest point of the plane.
        let n = DVec3::new(1.0, 1.0, 1.0) / 3f64.sqrt();
        let h = HalfSpace::new(DVec3::ZERO, n).unwrap();
        let p = h.project(DVec3::new(-1.0, 0.0, 0.0), &DVec3::ZERO).unwrap();
        assert!((p.x.dot(n)).abs() < 1e-15 && (p.x - DVec3::new(-2.0, 1.0, 1.0) / 3.0).length() < 1e-15);
    }

    #[test]
    fn bounds_are_finite_only_across_a_level_plane() {
        let h = HalfSpace::new(DVec3::new(0.0, 0.0, 0.5), DVec3::Z).unwrap();
        assert_eq!(h.bounds(), (DVec3::NEG_INFINITY, DVec3::new(f64::INFINITY, f64::INFINITY, 0.5)));
        let h = HalfSpace::new(DVec2::new(2.0, 0.0), -DVec2::X).unwrap();
        assert_eq!(h.bounds(), (DVec2::new(2.0, f64::NEG_INFINITY), DVec2::INFINITY));
        let h = HalfSpace::new(DVec2::ZERO, DVec2::new(1.0, 1.0)).unwrap();
        assert_eq!(h.bounds(), (DVec2::NEG_INFINITY, DVec2::INFINITY));
    }

    #[test]
    fn bad_input_is_named() {
        let arg = |r: Result<HalfSpace<DVec2>>| match r {
            Err(crate::Error::InvalidInput { arg, .. }) => arg,
            other => panic!("expected InvalidInput, got {other:?}"),
        };
        assert_eq!(arg(HalfSpace::new(DVec2::new(f64::NAN, 0.0), DVec2::Y)), "point");
        assert_eq!(arg(HalfSpace::new(DVec2::ZERO, DVec2::ZERO)), "normal");
        assert_eq!(arg(HalfSpace::new(DVec2::ZERO, DVec2::new(1e200, 0.0))), "normal");
    }
}
