//! `P`, a SIMD vector of a `Float` with its token, and `Mask`, a lane mask: kernels on them
//! read like scalar code.
use super::*;

/// A SIMD vector of `F` with its token, so kernels read like scalar code (`a * b + c`). The token
/// is zero-sized: a `P` is just the register.
pub struct P<S: Simd, F: Float> {
    pub s: S,
    pub v: F::V<S>,
}

/// A lane mask of `P`.
pub struct Mask<S: Simd, F: Float>(pub F::M<S>);

impl<S: Simd, F: Float> Clone for P<S, F> {
    #[inline(always)]
    fn clone(&self) -> Self {
        *self
    }
}
impl<S: Simd, F: Float> Copy for P<S, F> {}
impl<S: Simd, F: Float> Clone for Mask<S, F> {
    #[inline(always)]
    fn clone(&self) -> Self {
        *self
    }
}
impl<S: Simd, F: Float> Copy for Mask<S, F> {}

impl<S: Simd, F: Float> P<S, F> {
    #[inline(always)]
    pub fn lanes() -> usize {
        F::lanes::<S>()
    }
    #[inline(always)]
    pub fn splat(s: S, x: F) -> Self {
        P { s, v: F::splat(s, x) }
    }
    #[inline(always)]
    pub fn zero(s: S) -> Self {
        Self::splat(s, F::ZERO)
    }
    /// `a[..lanes]` (panics if shorter).
    #[inline(always)]
    pub fn load(s: S, a: &[F]) -> Self {
        P { s, v: F::load(s, a) }
    }
    /// Lane l = f(l), for l < lanes (lane indices, odd gathers; see `Simd::gather_rows_f64s`).
    #[inline(always)]
    pub fn from_fn(s: S, mut f: impl FnMut(usize) -> F) -> Self {
        let mut buf = [F::ZERO; 16];
        for (l, b) in buf.iter_mut().enumerate().take(Self::lanes()) {
            *b = f(l);
        }
        Self::load(s, &buf)
    }
    /// Writes the lanes over `dst[..lanes]` (panics if shorter).
    #[inline(always)]
    pub fn store(self, dst: &mut [F]) {
        let n = Self::lanes();
        let bytes: &mut [u8] = pulp::bytemuck::cast_slice_mut(&mut dst[..n]);
        bytes.copy_from_slice(pulp::bytemuck::bytes_of(&self.v));
    }
    /// Lanes as an array (first `lanes` entries used).
    #[inline(always)]
    pub fn to_array(self) -> [F; 16] {
        let mut buf = [F::ZERO; 16];
        let n = Self::lanes();
        let bytes: &mut [u8] = pulp::bytemuck::cast_slice_mut(&mut buf[..n]);
        bytes.copy_from_slice(pulp::bytemuck::bytes_of(&self.v));
        buf
    }
    /// self·b + c.
    #[inline(always)]
    pub fn mul_add(self, b: Self, c: Self) -> Self {
        P { s: self.s, v: F::mul_add(self.s, self.v, b.v, c.v) }
    }
    /// c − self·b.
    #[inline(always)]
    pub fn neg_mul_add(self, b: Self, c: Self) -> Self {
        P { s: self.s, v: F::neg_mul_add(self.s, self.v, b.v, c.v) }
    }
    #[inline(always)]
    pub fn max(self, o: Self) -> Self {
        P { s: self.s, v: F::vmax(self.s, self.v, o.v) }
    }
    #[inline(always)]
    pub fn min(self, o: Self) -> Self {
        P { s: self.s, v: F::vmin(self.s, self.v, o.v) }
    }
    #[inline(always)]
    pub fn lt(self, o: Self) -> Mask<S, F> {
        Mask(F::vlt(self.s, self.v, o.v))
    }
    #[inline(always)]
    pub fn gt(self, o: Self) -> Mask<S, F> {
        Mask(F::vgt(self.s, self.v, o.v))
    }
    /// 1/√self (see `Simd::rsqrt_f64s`; unspecified at 0).
    #[inline(always)]
    pub fn rsqrt(self) -> Self {
        P { s: self.s, v: F::rsqrt(self.s, self.v) }
    }
    /// 1/√self for a loop that does much else per value and leaves the divider idle (spring
    /// forces: gathers, projections, dashpots): the square root and division where the level
    /// asks for it (`Simd::DIVIDER_IN_LOOPS`), else the estimate. Cloth 128² on Zen 3 at avx2:
    /// 39 → 48 M particle-steps/s (3 alternating runs each); the divider's ~13 cycles per vector
    /// stay under the ~40 the rest of a spring slot takes.
    #[inline(always)]
    pub fn rsqrt_in_loop(self) -> Self {
        if S::DIVIDER_IN_LOOPS {
            self.rsqrt_exact()
        } else {
            self.rsqrt()
        }
    }
    /// √self in such a loop: the square root where the level asks for it, else self · 1/√self.
    #[inline(always)]
    pub fn sqrt_in_loop(self) -> Self {
        if S::DIVIDER_IN_LOOPS {
            self.sqrt()
        } else {
            self * self.rsqrt()
        }
    }
    /// (√self, 1/√self) in such a loop: a square root and a division where the level asks for
    /// it, else the estimate y and (self · y, y).
    #[inline(always)]
    pub fn sqrt_and_rsqrt_in_loop(self) -> (Self, Self) {
        if S::DIVIDER_IN_LOOPS {
            let r = self.sqrt();
            (r, Self::splat(self.s, F::ONE) / r)
        } else {
            let y = self.rsqrt();
            (self * y, y)
        }
    }
    /// `a` in the lanes where `self > 0`, `b` elsewhere (NaN lanes too).
    #[inline(always)]
    pub fn if_positive(self, a: Self, b: Self) -> Self {
        self.gt(Self::zero(self.s)).select(a, b)
    }
    /// The correctly rounded square root.
    #[inline(always)]
    pub fn sqrt(self) -> Self {
        P { s: self.s, v: F::vsqrt(self.s, self.v) }
    }
    /// 1/√self as a correctly rounded square root and a division: the divider, not the FMA
    /// units (see `Simd::SPLIT_RSQRT`).
    #[inline(always)]
    pub fn rsqrt_exact(self) -> Self {
        Self::splat(self.s, F::ONE) / self.sqrt()
    }
    #[inline(always)]
    pub fn sum(self) -> F {
        F::sum(self.s, self.v)
    }
}

impl<S: Simd, F: Float> Mask<S, F> {
    /// Lanes set in both.
    #[inline(always)]
    pub fn and(self, s: S, o: Self) -> Self {
        Mask(F::mand(s, self.0, o.0))
    }
    /// Whether any lane is set.
    #[inline(always)]
    pub fn any(self, s: S) -> bool {
        F::many(s, self.0)
    }
    /// The lanes as bits: lane l at bit l.
    #[inline(always)]
    pub fn bits(self, s: S) -> u64 {
        F::mbits(s, self.0)
    }
    /// `self ? a : b`.
    #[inline(always)]
    pub fn select(self, a: P<S, F>, b: P<S, F>) -> P<S, F> {
        P { s: a.s, v: F::select(a.s, self.0, a.v, b.v) }
    }
}

macro_rules! binop {
    ($tr:ident, $m:ident, $f:ident) => {
        impl<S: Simd, F: Float> $tr for P<S, F> {
            type Output = Self;
            #[inline(always)]
            fn $m(self, o: Self) -> Self {
                P { s: self.s, v: F::$f(self.s, self.v, o.v) }
            }
        }
    };
}
binop!(Add, add, vadd);
binop!(Sub, sub, vsub);
binop!(Mul, mul, vmul);
binop!(Div, div, vdiv);
