//! Any one shape of this layer, chosen at run time: what the grains' walls hold
//! (`terms::contacts::Wall`), each answered by a `match` that the compiler inlines into the
//! contact loops (no virtual call per grain and wall; a plane wall runs its own arithmetic).
use super::{Aabb, Ball, Capsule, HalfSpace, OrientedBox, Projection, Shape, Surface};
use crate::vector::Vector;

#[derive(Clone, Debug, PartialEq)]
pub enum AnyShape<V: Vector> {
    HalfSpace(HalfSpace<V>),
    Ball(Ball<V>),
    Capsule(Capsule<V>),
    Aabb(Aabb<V>),
    OrientedBox(OrientedBox<V>),
}

/// `$body` with `$s` bound to the shape inside, whichever it is.
macro_rules! each {
    ($self:expr, $s:ident => $body:expr) => {
        match $self {
            AnyShape::HalfSpace($s) => $body,
            AnyShape::Ball($s) => $body,
            AnyShape::Capsule($s) => $body,
            AnyShape::Aabb($s) => $body,
            AnyShape::OrientedBox($s) => $body,
        }
    };
}

impl<V: Vector> Shape<V> for AnyShape<V> {
    #[inline(always)]
    fn project(&self, x: V, v: &V) -> Option<Projection<V>> {
        each!(self, s => s.project(x, v))
    }

    fn bounds(&self) -> (V, V) {
        each!(self, s => s.bounds())
    }

    #[inline(always)]
    fn closest(&self, x: V) -> Surface<V> {
        each!(self, s => s.closest(x))
    }
}

impl<V: Vector> From<HalfSpace<V>> for AnyShape<V> {
    fn from(s: HalfSpace<V>) -> Self {
        Self::HalfSpace(s)
    }
}
impl<V: Vector> From<Ball<V>> for AnyShape<V> {
    fn from(s: Ball<V>) -> Self {
        Self::Ball(s)
    }
}
impl<V: Vector> From<Capsule<V>> for AnyShape<V> {
    fn from(s: Capsule<V>) -> Self {
        Self::Capsule(s)
    }
}
impl<V: Vector> From<Aabb<V>> for AnyShape<V> {
    fn from(s: Aabb<V>) -> Self {
        Self::Aabb(s)
    }
}
impl<V: Vector> From<OrientedBox<V>> for AnyShape<V> {
    fn from(s: OrientedBox<V>) -> Self {
        Self::OrientedBox(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};
    use std::f64::consts::FRAC_PI_6;

    /// A small deterministic generator of points in [-2, 2]^DIM.
    fn points<V: Vector>(n: usize) -> Vec<V> {
        let mut state = 12345u64;
        let mut rnd = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
        };
        (0..n).map(|_| V::from_slice(&[rnd(), rnd(), rnd()][..V::DIM])).collect()
    }

    fn shapes<V: Vector>(rotation: V::Axial) -> Vec<AnyShape<V>> {
        let p = |a: [f64; 3]| V::from_slice(&a[..V::DIM]);
        vec![
            HalfSpace::new(p([0.1, -0.2, 0.3]), p([1.0, 2.0, -0.5])).unwrap().into(),
            Ball::new(p([0.2, 0.1, -0.1]), 0.7, false).unwrap().into(),
            Ball::new(p([0.2, 0.1, -0.1]), 1.3, true).unwrap().into(),
            Capsule::new(p([-0.5, 0.0, 0.2]), p([0.6, 0.3, -0.2]), 0.4).unwrap().into(),
            Aabb::new(p([-1.0, -0.5, -0.8]), p([0.9, 1.1, 0.7])).unwrap().into(),
            OrientedBox::new(p([0.1, 0.2, -0.1]), p([0.8, 0.3, 0.5]), rotation).unwrap().into(),
        ]
    }

    /// For every shape and many points: x = point + distance·normal, |normal| = 1, the point on
    /// the surface (its own `closest` there is at distance 0), and the sign of the distance
    /// agreeing with `project` (forbidden side: negative; allowed: ≥ 0); a brute-force check
    /// that no sampled surface point is nearer than |distance|.
    fn closest_is_the_nearest_surface_point<V: Vector>(rotation: V::Axial) {
        let xs = points::<V>(4000);
        for (k, shape) in shapes::<V>(rotation).iter().enumerate() {
            let surface: Vec<V> = xs.iter().map(|&x| shape.closest(x).point).collect();
            for &x in &xs {
                let s = shape.closest(x);
                let what = format!("{}D shape {k} at {x:?}: {s:?}", V::DIM);
                assert!((s.normal.length_squared() - 1.0).abs() < 1e-12, "{what}: normal not unit");
                assert!((s.point + s.normal * s.distance - x).length_squared() < 1e-24, "{what}: x ≠ p + d n");
                assert!(shape.closest(s.point).distance.abs() < 1e-12, "{what}: point not on the surface");
                let forbidden = shape.project(x, &V::ZERO).is_some();
                assert!(if forbidden { s.distance < 0.0 } else { s.distance >= 0.0 }, "{what}: sign vs project");
                // No surface point (of those found for other x) is nearer.
                let nearest = surface.iter().map(|&p| (p - x).length_squared()).fold(f64::INFINITY, f64::min).sqrt();
                assert!(nearest >= s.distance.abs() - 1e-12, "{what}: a surface point at {nearest}");
            }
        }
    }

    #[test]
    fn closest_holds_for_every_shape() {
        closest_is_the_nearest_surface_point::<DVec2>(FRAC_PI_6);
        closest_is_the_nearest_surface_point::<DVec3>(DVec3::new(0.3, -0.5, 0.8));
    }

    /// The plane's distance is (x − p)·n computed as the grains' walls always did (their bits).
    #[test]
    fn the_plane_keeps_its_arithmetic_and_nan_is_never_near() {
        let h = HalfSpace::new(DVec3::new(0.1, 0.2, 0.3), DVec3::new(1.0, 2.0, 2.0)).unwrap();
        let x = DVec3::new(0.7, -0.3, 1.9);
        let s = AnyShape::from(h.clone()).closest(x);
        assert_eq!(s.distance.to_bits(), (x - h.point).dot(h.normal).to_bits());
        assert_eq!(s.normal, h.normal);
        let nan = DVec3::new(f64::NAN, 0.0, 0.0);
        for shape in shapes::<DVec3>(DVec3::ZERO) {
            assert!(shape.closest(nan).distance.is_nan(), "{shape:?}");
        }
    }

    /// Known answers: a ball's top, a bowl's bottom, a capsule's side, a box's face from inside,
    /// an oriented box's face, edge and inside.
    #[test]
    fn known_answers() {
        let ball = Ball::new(DVec2::new(0.0, 1.0), 0.5, false).unwrap();
        assert_eq!(
            ball.closest(DVec2::new(0.0, 2.0)),
            Surface { point: DVec2::new(0.0, 1.5), normal: DVec2::Y, distance: 0.5 }
        );
        let bowl = Ball::new(DVec2::new(0.0, 1.0), 0.5, true).unwrap();
        assert_eq!(
            bowl.closest(DVec2::new(0.0, 0.75)),
            Surface { point: DVec2::new(0.0, 0.5), normal: DVec2::Y, distance: 0.25 }
        );
        assert_eq!(bowl.closest(DVec2::new(0.0, 1.0)).distance, 0.5, "the centre: up, at r");
        let cap = Capsule::new(DVec2::new(-1.0, 0.0), DVec2::new(1.0, 0.0), 0.25).unwrap();
        assert_eq!(
            cap.closest(DVec2::new(0.5, 1.0)),
            Surface { point: DVec2::new(0.5, 0.25), normal: DVec2::Y, distance: 0.75 }
        );
        let tank = Aabb::new(DVec2::ZERO, DVec2::new(2.0, 1.0)).unwrap();
        assert_eq!(
            tank.closest(DVec2::new(1.5, 0.5)),
            Surface { point: DVec2::new(2.0, 0.5), normal: -DVec2::X, distance: 0.5 }
        );
        assert_eq!(tank.closest(DVec2::new(3.0, 0.5)).distance, -1.0);
        let block = OrientedBox::new(DVec2::ZERO, DVec2::new(1.0, 0.5), 0.0).unwrap();
        assert_eq!(
            block.closest(DVec2::new(0.3, 0.75)),
            Surface { point: DVec2::new(0.3, 0.5), normal: DVec2::Y, distance: 0.25 }
        );
        let edge = block.closest(DVec2::new(1.3, 0.9));
        assert_eq!(edge.point, DVec2::new(1.0, 0.5));
        assert!((edge.distance - 0.5).abs() < 1e-15 && (edge.normal - DVec2::new(0.6, 0.8)).length() < 1e-15);
        assert_eq!(
            block.closest(DVec2::new(0.8, -0.1)),
            Surface { point: DVec2::new(1.0, -0.1), normal: DVec2::X, distance: -0.19999999999999996 }
        );
    }
}
