//! The one precision alias and the small `Vector` trait that lets every kernel be written once
//! for 2D (`DVec2`) and 3D (`DVec3`). glam's unpadded f64 vectors are used (not `Vec3A`) so a
//! buffer maps onto an `(N, dim)` float64 array.
use glam::{DVec2, DVec3};
use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

/// Scalar type of the whole core.
pub type Real = f64;

pub trait Vector:
    Copy
    + Send
    + Sync
    + Default
    + PartialEq
    + Debug
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Real, Output = Self>
    + Mul<Self, Output = Self>
    + Div<Real, Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + 'static
{
    const DIM: usize;
    const ZERO: Self;
    /// A pseudo-vector of this dimension (a magnetic field, a rotation axis times an angle): in
    /// 3D a vector, in 2D its one component out of the plane (z), the only one that turns
    /// motion within the plane.
    type Axial: Copy
        + Send
        + Sync
        + Default
        + PartialEq
        + Debug
        + Add<Output = Self::Axial>
        + Mul<Real, Output = Self::Axial>
        + 'static;
    /// Components of an `Axial`: 1 in 2D (z), 3 in 3D.
    const AXIAL_DIM: usize;
    const AXIAL_ZERO: Self::Axial;
    /// An `Axial` from the first `AXIAL_DIM` entries of `s`.
    fn axial_from_slice(s: &[Real]) -> Self::Axial;
    /// |b|².
    fn axial_length_squared(b: Self::Axial) -> Real;
    /// `self × b` (in 2D, `b` is along z, so the product lies in the plane).
    fn cross_axial(self, b: Self::Axial) -> Self;
    fn dot(self, other: Self) -> Real;
    #[inline(always)]
    fn length_squared(self) -> Real {
        self.dot(self)
    }
    fn is_finite(self) -> bool;
    /// Component `k` (0 = x, 1 = y, 2 = z); `k < DIM`.
    fn comp(self, k: usize) -> Real;
    /// Build from the first `DIM` entries of `s`.
    fn from_slice(s: &[Real]) -> Self;
    /// `self × other` as a 3-vector (in 2D only the z component is non-zero).
    fn cross3(self, other: Self) -> [Real; 3];
    /// Each component rounded to the nearest float32 (the single-precision state).
    fn round_f32(self) -> Self;
    /// The vectors as a flat row-major `(N, DIM)` slice of reals (no copy).
    fn flat(v: &[Self]) -> &[Real];
    /// A flat row-major `(N, DIM)` slice of reals as vectors (no copy): `flat`'s inverse; the
    /// slice's length is a multiple of `DIM`.
    fn rows(flat: &[Real]) -> &[Self];
    /// Axial vectors as a flat row-major `(N, AXIAL_DIM)` slice of reals (no copy).
    fn axial_flat(b: &[Self::Axial]) -> &[Real];
}

impl Vector for DVec2 {
    #[inline(always)]
    fn flat(v: &[Self]) -> &[Real] {
        bytemuck::cast_slice(v)
    }
    #[inline(always)]
    fn rows(flat: &[Real]) -> &[Self] {
        bytemuck::cast_slice(flat)
    }
    #[inline(always)]
    fn axial_flat(b: &[Real]) -> &[Real] {
        b
    }
    const DIM: usize = 2;
    const ZERO: Self = DVec2::ZERO;
    type Axial = Real;
    const AXIAL_DIM: usize = 1;
    const AXIAL_ZERO: Real = 0.0;
    #[inline(always)]
    fn axial_from_slice(s: &[Real]) -> Real {
        s[0]
    }
    #[inline(always)]
    fn axial_length_squared(b: Real) -> Real {
        b * b
    }
    #[inline(always)]
    fn cross_axial(self, b: Real) -> Self {
        // (x, y, 0) × (0, 0, b) = (y b, −x b, 0)
        DVec2::new(self.y * b, -self.x * b)
    }
    #[inline(always)]
    fn dot(self, o: Self) -> Real {
        self.x * o.x + self.y * o.y
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
    #[inline(always)]
    fn comp(self, k: usize) -> Real {
        self[k]
    }
    #[inline(always)]
    fn from_slice(s: &[Real]) -> Self {
        DVec2::new(s[0], s[1])
    }
    #[inline(always)]
    fn cross3(self, o: Self) -> [Real; 3] {
        [0.0, 0.0, self.x * o.y - self.y * o.x]
    }
    #[inline(always)]
    fn round_f32(self) -> Self {
        DVec2::new(self.x as f32 as f64, self.y as f32 as f64)
    }
}

impl Vector for DVec3 {
    #[inline(always)]
    fn flat(v: &[Self]) -> &[Real] {
        bytemuck::cast_slice(v)
    }
    #[inline(always)]
    fn rows(flat: &[Real]) -> &[Self] {
        bytemuck::cast_slice(flat)
    }
    #[inline(always)]
    fn axial_flat(b: &[DVec3]) -> &[Real] {
        bytemuck::cast_slice(b)
    }
    const DIM: usize = 3;
    const ZERO: Self = DVec3::ZERO;
    type Axial = DVec3;
    const AXIAL_DIM: usize = 3;
    const AXIAL_ZERO: DVec3 = DVec3::ZERO;
    #[inline(always)]
    fn axial_from_slice(s: &[Real]) -> DVec3 {
        DVec3::new(s[0], s[1], s[2])
    }
    #[inline(always)]
    fn axial_length_squared(b: DVec3) -> Real {
        b.dot(b)
    }
    #[inline(always)]
    fn cross_axial(self, b: DVec3) -> Self {
        self.cross(b)
    }
    #[inline(always)]
    fn dot(self, o: Self) -> Real {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
    #[inline(always)]
    fn comp(self, k: usize) -> Real {
        self[k]
    }
    #[inline(always)]
    fn from_slice(s: &[Real]) -> Self {
        DVec3::new(s[0], s[1], s[2])
    }
    #[inline(always)]
    fn cross3(self, o: Self) -> [Real; 3] {
        let c = self.cross(o);
        [c.x, c.y, c.z]
    }
    #[inline(always)]
    fn round_f32(self) -> Self {
        DVec3::new(self.x as f32 as f64, self.y as f32 as f64, self.z as f32 as f64)
    }
}

/// Flat `[x0, y0, (z0,) x1, ...]` → vectors. `flat.len()` must be a multiple of `V::DIM`.
pub fn from_flat<V: Vector>(flat: &[Real]) -> Vec<V> {
    flat.chunks_exact(V::DIM).map(V::from_slice).collect()
}

/// Vectors → flat row-major `(N, DIM)` buffer.
pub fn to_flat<V: Vector>(v: &[V]) -> Vec<Real> {
    let mut out = Vec::with_capacity(v.len() * V::DIM);
    for p in v {
        for k in 0..V::DIM {
            out.push(p.comp(k));
        }
    }
    out
}
