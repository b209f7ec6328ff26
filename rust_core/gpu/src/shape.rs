//! The shapes the device's particles collide with (`particles::Collider`) and its grains touch
//! (`dem::Wall`): the CPU's geometry layer (`rust_core/src/geometry`), m, z ignored in 2D, and
//! the one row both kernels read them from (`Shape::row`).

/// A shape of the CPU's geometry layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// The half-space (x − point)·normal ≥ 0 (a collider's `normal` of unit length; a DEM
    /// wall's of any length > 0, normalised by `Dem::new`).
    Plane { point: [f64; 3], normal: [f64; 3] },
    /// Points kept inside [lower, upper] (z ignored in 2D); a collider only.
    Box { lower: [f64; 3], upper: [f64; 3] },
    /// Points kept outside the sphere (a disc in 2D) of `radius` about `center`, or with
    /// `inside` in it (a bowl): the CPU's `geometry::Ball`.
    Sphere { center: [f64; 3], radius: f64, inside: bool },
    /// Points kept outside the capsule of `radius` about the segment from `a` to `b`.
    Capsule { a: [f64; 3], b: [f64; 3], radius: f64 },
    /// Points kept outside the box of `half` extents along the unit, orthogonal `axes` about
    /// `center` (2D: the first two axes and half extents, z = 0), the axes as the CPU computes
    /// them from its rotation.
    OrientedBox { center: [f64; 3], half: [f64; 3], axes: [[f64; 3]; 3] },
}

/// Reals per shape on the device (`Shape::row`).
pub(crate) const ROW: usize = 24;

impl Shape {
    /// The device's row of the shape with its two coefficients `c` (restitution or damping
    /// ratio, and friction), six groups of 4 (particles.wgsl reads them as vec4s): kind (0
    /// plane, 1 box, 2 sphere, 3 capsule, 4 oriented box), c[0], c[1], a capsule's radius; a
    /// point (a plane's, a box's lower corner, a sphere's or box's centre, a capsule's first
    /// end); a second (a plane's normal, a box's upper corner, a sphere's radius and `inside`,
    /// a capsule's second end, an oriented box's half extents); an oriented box's three axes.
    pub(crate) fn row(&self, c: [f64; 2]) -> [f64; ROW] {
        const NO_AXES: [[f64; 3]; 3] = [[0.0; 3]; 3];
        let (kind, a, b, w, axes) = match *self {
            Shape::Plane { point, normal } => (0.0, point, normal, 0.0, NO_AXES),
            Shape::Box { lower, upper } => (1.0, lower, upper, 0.0, NO_AXES),
            Shape::Sphere { center, radius, inside } => {
                (2.0, center, [radius, if inside { 1.0 } else { 0.0 }, 0.0], 0.0, NO_AXES)
            }
            Shape::Capsule { a, b, radius } => (3.0, a, b, radius, NO_AXES),
            Shape::OrientedBox { center, half, axes } => (4.0, center, half, 0.0, axes),
        };
        let mut row = [0.0; ROW];
        row[..4].copy_from_slice(&[kind, c[0], c[1], w]);
        for (k, v) in [a, b, axes[0], axes[1], axes[2]].iter().enumerate() {
            row[4 + 4 * k..7 + 4 * k].copy_from_slice(v);
        }
        row
    }
}
