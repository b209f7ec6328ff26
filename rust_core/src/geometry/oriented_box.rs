//! The oriented box: a rotated block kept outside (a tilted ramp, a wedge, a beam at an angle).
//! Its local axes u_j are the columns of the rotation R; a point x has local coordinates
//! q_j = (x − c)·u_j and is inside when |q_j| < h_j on every axis (Ericson, *Real-Time Collision
//! Detection*, 2005, §4.4 and §5.1.4). A point inside leaves through the nearest face, the axis
//! j of least depth h_j − |q_j| (the first on a tie), along ±u_j: near an edge or a corner it
//! goes out through the face it is least deep under, as a plane there would push it.
//!
//! The rotation is an axial vector (`Vector::Axial`): in 2D the angle θ (rad, counterclockwise),
//! R = [[cos θ, −sin θ], [sin θ, cos θ]]; in 3D the rotation vector θk (axis k, angle θ, rad),
//! R from Rodrigues' formula (Murray, Li & Sastry, *A Mathematical Introduction to Robotic
//! Manipulation*, 1994, §2.2), computed through glam's quaternion.
use super::{Projection, Shape, Surface};
use crate::error::{invalid, Result};
use crate::vector::{Real, Vector};
use glam::{DMat3, DQuat, DVec3};

#[derive(Clone, Debug, PartialEq)]
pub struct OrientedBox<V: Vector> {
    /// Centre, m.
    pub center: V,
    /// Half the side along each local axis, m (> 0, finite).
    pub half: [Real; 3],
    /// The local axes in world coordinates (unit, orthogonal); the first `DIM` are used.
    pub axes: [V; 3],
}

/// The columns of the rotation `rotation` (module doc).
fn axes<V: Vector>(rotation: V::Axial) -> [V; 3] {
    let r = V::axial_flat(std::slice::from_ref(&rotation));
    let cols = if V::DIM == 2 {
        let (s, c) = r[0].sin_cos();
        [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]
    } else {
        let m = DMat3::from_quat(DQuat::from_scaled_axis(DVec3::new(r[0], r[1], r[2])));
        [m.x_axis.to_array(), m.y_axis.to_array(), m.z_axis.to_array()]
    };
    cols.map(|c| V::from_slice(&c[..V::DIM]))
}

impl<V: Vector> OrientedBox<V> {
    /// The box about `center` (m) with `half_extents` (m, > 0 on every axis) along its local
    /// axes, turned by `rotation` (module doc); `InvalidInput` naming the argument if one is not
    /// finite or a half extent is not > 0.
    pub fn new(center: V, half_extents: V, rotation: V::Axial) -> Result<Self> {
        if !center.is_finite() {
            return Err(invalid("center", "must be finite"));
        }
        if !(half_extents.is_finite() && (0..V::DIM).all(|k| half_extents.comp(k) > 0.0)) {
            return Err(invalid("half_extents", "must be finite and > 0 on every axis"));
        }
        if !V::axial_flat(std::slice::from_ref(&rotation)).iter().all(|r| r.is_finite()) {
            return Err(invalid("rotation", "must be finite"));
        }
        let mut half = [0.0; 3];
        for k in 0..V::DIM {
            half[k] = half_extents.comp(k);
        }
        Ok(Self { center, half, axes: axes::<V>(rotation) })
    }
}

impl<V: Vector> Shape<V> for OrientedBox<V> {
    #[inline(always)]
    fn project(&self, x: V, _v: &V) -> Option<Projection<V>> {
        let rel = x - self.center;
        let mut best = (Real::INFINITY, 0, 0.0);
        for j in 0..V::DIM {
            let q = rel.dot(self.axes[j]);
            let depth = self.half[j] - q.abs();
            // Not inside on this axis (NaN included: left alone).
            if !(depth > 0.0) {
                return None;
            }
            if depth < best.0 {
                best = (depth, j, q);
            }
        }
        let (depth, j, q) = best;
        let normal = if q < 0.0 { -self.axes[j] } else { self.axes[j] };
        let dx = normal * depth;
        let mut moved = x;
        moved += dx;
        Some(Projection { x: moved, dx, normal })
    }

    /// c ± Σ_j h_j |u_j| per axis (Ericson 2005, §4.2.6).
    fn bounds(&self) -> (V, V) {
        let mut ext = [0.0; 3];
        for k in 0..V::DIM {
            ext[k] = (0..V::DIM).map(|j| self.half[j] * self.axes[j].comp(k).abs()).sum();
        }
        let e = V::from_slice(&ext[..V::DIM]);
        (self.center - e, self.center + e)
    }

    /// With the local coordinates q_j = (x − c)·u_j: inside or on the surface (|q_j| ≤ h_j on
    /// every axis), the face `project` leaves through (least depth h_j − |q_j|, the first on a
    /// tie), distance −(h_j − |q_j|), normal ±u_j (the sign of q_j), point x + normal·depth.
    /// Outside across one face only (|q_j| > h_j on one axis j), that face: distance
    /// |q_j| − h_j, normal ±u_j. Outside an edge or a corner, the clamped point
    /// p = c + Σ_j clamp(q_j, −h_j, h_j) u_j (Ericson 2005, §5.1.4), distance |x − p|, normal
    /// (x − p)/|x − p|: a grain rolls round an edge as round a rod.
    #[inline(always)]
    fn closest(&self, x: V) -> Surface<V> {
        let rel = x - self.center;
        let mut q = [0.0; 3];
        let (mut outside, mut across) = (0, 0);
        let mut least = (Real::INFINITY, 0);
        for j in 0..V::DIM {
            q[j] = rel.dot(self.axes[j]);
            let depth = self.half[j] - q[j].abs();
            // Outside on this axis (NaN included: its distance comes out NaN below).
            if !(depth >= 0.0) {
                outside += 1;
                across = j;
            }
            if depth < least.0 {
                least = (depth, j);
            }
        }
        let face = |j: usize| if q[j] < 0.0 { -self.axes[j] } else { self.axes[j] };
        if outside == 0 {
            let (depth, j) = least;
            let normal = face(j);
            return Surface { point: x + normal * depth, normal, distance: -depth };
        }
        if outside == 1 {
            let normal = face(across);
            let distance = q[across].abs() - self.half[across];
            return Surface { point: x - normal * distance, normal, distance };
        }
        let mut point = self.center;
        for j in 0..V::DIM {
            point += self.axes[j] * q[j].clamp(-self.half[j], self.half[j]);
        }
        let off = x - point;
        let distance = off.length_squared().sqrt();
        Surface { point, normal: off / distance, distance }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, FRAC_PI_6};

    fn local<V: Vector>(b: &OrientedBox<V>, q: [Real; 3]) -> V {
        (0..V::DIM).fold(b.center, |x, j| x + b.axes[j] * q[j])
    }

    /// Through each face along its own axis, in a rotated box: the new point is on the face
    /// (local coordinate ±h_j), the displacement the depth along the outward normal.
    #[test]
    fn a_point_inside_leaves_through_the_nearest_face() {
        let b = OrientedBox::new(DVec2::new(1.0, 2.0), DVec2::new(0.5, 0.25), FRAC_PI_6).unwrap();
        let (u, w) = (DVec2::new(3f64.sqrt() / 2.0, 0.5), DVec2::new(-0.5, 3f64.sqrt() / 2.0));
        assert!((b.axes[0] - u).length() < 1e-15 && (b.axes[1] - w).length() < 1e-15, "counterclockwise");
        for (q, n, depth) in
            [([0.4, 0.0], u, 0.1), ([-0.45, 0.1], -u, 0.05), ([0.0, -0.2], -w, 0.05), ([0.1, 0.2], w, 0.05)]
        {
            let x = local(&b, [q[0], q[1], 0.0]);
            let p = b.project(x, &DVec2::ZERO).unwrap();
            assert!((p.normal - n).length() < 1e-15, "{q:?}: normal {:?}", p.normal);
            assert!((p.dx - n * depth).length() < 1e-14, "{q:?}: dx {:?}", p.dx);
            let on = (p.x - b.center).dot(n);
            assert!((on - if n == u || n == -u { 0.5 } else { 0.25 }).abs() < 1e-14, "{q:?}: not on the face ({on})");
        }
    }

    /// Near an edge or a corner it leaves through the face it is least deep under; on an exact
    /// tie, the first axis.
    #[test]
    fn near_an_edge_or_a_corner_the_least_deep_face_wins() {
        let b = OrientedBox::new(DVec3::new(1.0, -1.0, 0.5), DVec3::new(0.5, 0.25, 0.375), DVec3::ZERO).unwrap();
        let at = |q: [Real; 3]| b.project(b.center + DVec3::from_array(q), &DVec3::ZERO).unwrap();
        // Edge x–y: 0.0625 under x, 0.03125 under y: out through +y.
        let p = at([0.4375, 0.21875, 0.0]);
        assert_eq!((p.normal, p.x), (DVec3::Y, b.center + DVec3::new(0.4375, 0.25, 0.0)));
        // Corner (−, −, +), 0.0625 under every face: the tie goes to x.
        let p = at([-0.4375, -0.1875, 0.3125]);
        assert_eq!((p.normal, p.dx), (-DVec3::X, DVec3::new(-0.0625, 0.0, 0.0)));
    }

    /// Outside a face, an edge or a corner, and on the surface itself: left alone.
    #[test]
    fn points_outside_or_on_the_surface_are_allowed() {
        let b = OrientedBox::new(DVec3::ZERO, DVec3::new(0.5, 0.25, 0.375), DVec3::ZERO).unwrap();
        for q in [
            [0.6, 0.0, 0.0],
            [0.6, 0.3, 0.0],
            [-0.6, 0.3, -0.4],
            [0.5, 0.0, 0.0],
            [0.5, 0.25, 0.375],
            [f64::NAN, 0.0, 0.0],
        ] {
            assert_eq!(b.project(DVec3::from_array(q), &DVec3::ZERO), None, "{q:?}");
        }
    }

    /// A 3D rotation about z by θ is the 2D rotation by θ; its bounds are the turned corners'.
    #[test]
    fn rotation_vectors_agree_with_the_angle_and_bound_the_turned_box() {
        let b3 = OrientedBox::new(DVec3::ZERO, DVec3::new(0.5, 0.25, 1.0), DVec3::new(0.0, 0.0, FRAC_PI_2)).unwrap();
        let b2 = OrientedBox::new(DVec2::ZERO, DVec2::new(0.5, 0.25), FRAC_PI_2).unwrap();
        for j in 0..2 {
            assert!((b3.axes[j].truncate() - b2.axes[j]).length() < 1e-15 && b3.axes[j].z.abs() < 1e-15);
        }
        assert!((b3.axes[0] - DVec3::Y).length() < 1e-15 && (b3.axes[2] - DVec3::Z).length() < 1e-15);
        let b = OrientedBox::new(DVec2::new(1.0, 0.0), DVec2::new(0.5, 0.25), FRAC_PI_4).unwrap();
        let e = 0.75 / 2f64.sqrt();
        let (lo, hi) = b.bounds();
        assert!((lo - DVec2::new(1.0 - e, -e)).length() < 1e-15 && (hi - DVec2::new(1.0 + e, e)).length() < 1e-15);
    }

    #[test]
    fn bad_input_is_named() {
        let arg = |r: Result<OrientedBox<DVec2>>| match r {
            Err(crate::Error::InvalidInput { arg, .. }) => arg,
            other => panic!("expected InvalidInput, got {other:?}"),
        };
        let h = DVec2::new(0.5, 0.5);
        assert_eq!(arg(OrientedBox::new(DVec2::new(f64::NAN, 0.0), h, 0.0)), "center");
        for bad in [DVec2::new(0.0, 1.0), DVec2::new(1.0, -1.0), DVec2::new(f64::INFINITY, 1.0)] {
            assert_eq!(arg(OrientedBox::new(DVec2::ZERO, bad, 0.0)), "half_extents");
        }
        assert_eq!(arg(OrientedBox::new(DVec2::ZERO, h, f64::NAN)), "rotation");
    }
}
