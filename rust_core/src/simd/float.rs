//! The precision of a kernel (`Float`: f32 or f64) with its SIMD vectors and operations for
//! each token.
use super::*;

/// The precision of a kernel: f32 or f64, with its SIMD vectors for token `S`.
pub trait Float:
    Copy
    + Send
    + Sync
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Debug
    + pulp::bytemuck::Pod
    + 'static
{
    const ZERO: Self;
    const ONE: Self;
    fn of(x: f64) -> Self;
    fn f64(self) -> f64;
    fn sqrt(self) -> Self;
    /// `a` if `c` else `b`, by masking the bits: no branch, even where one side is a division
    /// (LLVM turns a select of an expensive value into a branch, which mispredicts when the
    /// condition is random: the cubic spline's q < 1 over a particle's neighbours).
    fn pick(c: bool, a: Self, b: Self) -> Self;
    /// Plain compare (not IEEE maxNum): vectorises to one instruction.
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        if self > o {
            self
        } else {
            o
        }
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        if self < o {
            self
        } else {
            o
        }
    }

    type V<S: Simd>: Copy + pulp::bytemuck::Pod;
    type M<S: Simd>: Copy;
    fn lanes<S: Simd>() -> usize;
    fn splat<S: Simd>(s: S, x: Self) -> Self::V<S>;
    /// The first `lanes` entries of `a` (panics if `a` is shorter).
    fn load<S: Simd>(s: S, a: &[Self]) -> Self::V<S>;
    fn vadd<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vsub<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vmul<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vdiv<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    /// a·b + c (fused where the level has FMA; the scalar level has none and must not call libm's
    /// software fma).
    fn mul_add<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>, c: Self::V<S>) -> Self::V<S>;
    /// c − a·b.
    fn neg_mul_add<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>, c: Self::V<S>) -> Self::V<S>;
    fn vmax<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vmin<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vlt<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::M<S>;
    fn vgt<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::M<S>;
    /// `m ? a : b` lane by lane.
    fn select<S: Simd>(s: S, m: Self::M<S>, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    /// Lanes set in both masks.
    fn mand<S: Simd>(s: S, a: Self::M<S>, b: Self::M<S>) -> Self::M<S>;
    /// Whether any lane of the mask is set.
    fn many<S: Simd>(s: S, m: Self::M<S>) -> bool;
    /// The mask as bits, lane l at bit l.
    fn mbits<S: Simd>(s: S, m: Self::M<S>) -> u64;
    fn rsqrt<S: Simd>(s: S, x: Self::V<S>) -> Self::V<S>;
    /// The correctly rounded square root.
    fn vsqrt<S: Simd>(s: S, x: Self::V<S>) -> Self::V<S>;
    /// Sum of the lanes (a fixed pairwise order per level).
    fn sum<S: Simd>(s: S, a: Self::V<S>) -> Self;
}

macro_rules! float_impl {
    ($t:ty, $v:ident, $m:ident, $lanes:ident, $($op:ident = $f:ident),*) => {
        impl Float for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            #[inline(always)]
            fn of(x: f64) -> Self {
                x as $t
            }
            #[inline(always)]
            fn f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn pick(c: bool, a: Self, b: Self) -> Self {
                let m = opaque((c as u64).wrapping_neg());
                <$t>::from_bits((((a.to_bits() as u64) & m) | ((b.to_bits() as u64) & !m)) as _)
            }
            type V<S: Simd> = S::$v;
            type M<S: Simd> = S::$m;
            #[inline(always)]
            fn lanes<S: Simd>() -> usize {
                S::$lanes
            }
            #[inline(always)]
            fn load<S: Simd>(_: S, a: &[Self]) -> S::$v {
                pulp::bytemuck::pod_read_unaligned(pulp::bytemuck::cast_slice(&a[..S::$lanes]))
            }
            float_impl!(@ops $t, $v, $m, $($op = $f),*);
        }
    };
    (@ops $t:ty, $v:ident, $m:ident, splat = $splat:ident, add = $add:ident, sub = $sub:ident, mul = $mul:ident,
     div = $div:ident, fma = $fma:ident, fnma = $fnma:ident, max = $max:ident, min = $min:ident, lt = $lt:ident,
     gt = $gt:ident, select = $sel:ident, and = $and:ident, first = $first:ident, bits = $bits:ident, rsqrt = $rsqrt:ident, sqrt = $sqrt:ident, sum = $sum:ident) => {
        #[inline(always)]
        fn splat<S: Simd>(s: S, x: Self) -> S::$v {
            s.$splat(x)
        }
        #[inline(always)]
        fn vadd<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$add(a, b)
        }
        #[inline(always)]
        fn vsub<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$sub(a, b)
        }
        #[inline(always)]
        fn vmul<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$mul(a, b)
        }
        #[inline(always)]
        fn vdiv<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$div(a, b)
        }
        #[inline(always)]
        fn mul_add<S: Simd>(s: S, a: S::$v, b: S::$v, c: S::$v) -> S::$v {
            s.$fma(a, b, c)
        }
        #[inline(always)]
        fn neg_mul_add<S: Simd>(s: S, a: S::$v, b: S::$v, c: S::$v) -> S::$v {
            s.$fnma(a, b, c)
        }
        #[inline(always)]
        fn vmax<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$max(a, b)
        }
        #[inline(always)]
        fn vmin<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$min(a, b)
        }
        #[inline(always)]
        fn vlt<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$m {
            s.$lt(a, b)
        }
        #[inline(always)]
        fn vgt<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$m {
            s.$gt(a, b)
        }
        #[inline(always)]
        fn select<S: Simd>(s: S, m: S::$m, a: S::$v, b: S::$v) -> S::$v {
            s.$sel(m, a, b)
        }
        #[inline(always)]
        fn mand<S: Simd>(s: S, a: S::$m, b: S::$m) -> S::$m {
            s.$and(a, b)
        }
        #[inline(always)]
        fn mbits<S: Simd>(s: S, m: S::$m) -> u64 {
            s.$bits(m)
        }
        #[inline(always)]
        fn many<S: Simd>(s: S, m: S::$m) -> bool {
            // pulp's first-true index is the lane count exactly when no lane is set (every level).
            s.$first(m) < <Self as Float>::lanes::<S>()
        }
        #[inline(always)]
        fn rsqrt<S: Simd>(s: S, x: S::$v) -> S::$v {
            s.$rsqrt(x)
        }
        #[inline(always)]
        fn vsqrt<S: Simd>(s: S, x: S::$v) -> S::$v {
            s.$sqrt(x)
        }
        #[inline(always)]
        fn sum<S: Simd>(s: S, a: S::$v) -> Self {
            s.$sum(a)
        }
    };
}

float_impl!(
    f64,
    f64s,
    m64s,
    F64_LANES,
    splat = splat_f64s,
    add = add_f64s,
    sub = sub_f64s,
    mul = mul_f64s,
    div = div_f64s,
    fma = mul_add_e_f64s,
    fnma = negate_mul_add_e_f64s,
    max = max_f64s,
    min = min_f64s,
    lt = less_than_f64s,
    gt = greater_than_f64s,
    select = select_f64s,
    and = and_m64s,
    first = first_true_m64s,
    bits = mask_bits_m64s,
    rsqrt = rsqrt_f64s,
    sqrt = sqrt_f64s,
    sum = reduce_sum_f64s
);
float_impl!(
    f32,
    f32s,
    m32s,
    F32_LANES,
    splat = splat_f32s,
    add = add_f32s,
    sub = sub_f32s,
    mul = mul_f32s,
    div = div_f32s,
    fma = mul_add_e_f32s,
    fnma = negate_mul_add_e_f32s,
    max = max_f32s,
    min = min_f32s,
    lt = less_than_f32s,
    gt = greater_than_f32s,
    select = select_f32s,
    and = and_m32s,
    first = first_true_m32s,
    bits = mask_bits_m32s,
    rsqrt = rsqrt_f32s,
    sqrt = sqrt_f32s,
    sum = reduce_sum_f32s
);
