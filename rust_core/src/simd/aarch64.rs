//! The fast reciprocal square root on aarch64 NEON.
use super::{newton_rsqrt_f32, newton_rsqrt_f64, rsqrt_specials_f32, rsqrt_specials_f64, Simd};
use pulp::aarch64::Neon;
use pulp::Simd as _;
use std::arch::aarch64::{float32x4_t, float64x2_t, vrsqrteq_f32, vrsqrteq_f64};

type F64s = <Neon as pulp::Simd>::f64s;
type F32s = <Neon as pulp::Simd>::f32s;

/// `frsqrte` (an 8-bit estimate, relative error ≤ 2⁻⁸) over the whole range; three Newton steps
/// for f64 (→ 2.3e-5 → 8e-10 → round-off), two for f32.
impl Simd for Neon {
    const REGISTERS: usize = 32;

    #[inline(always)]
    fn rsqrt_f64s(self, x: F64s) -> F64s {
        // SAFETY: NEON is part of every aarch64 target this builds for (and the token proves it);
        // f64x2 and float64x2_t are both two plain f64s.
        let y: F64s = unsafe { std::mem::transmute(vrsqrteq_f64(std::mem::transmute::<F64s, float64x2_t>(x))) };
        let h = self.mul_f64s(x, self.splat_f64s(0.5));
        let y1 = newton_rsqrt_f64(self, h, y);
        let y1 = newton_rsqrt_f64(self, h, y1);
        rsqrt_specials_f64(self, y, newton_rsqrt_f64(self, h, y1))
    }

    #[inline(always)]
    fn rsqrt_f32s(self, x: F32s) -> F32s {
        // SAFETY: as above; four plain f32s.
        let y: F32s = unsafe { std::mem::transmute(vrsqrteq_f32(std::mem::transmute::<F32s, float32x4_t>(x))) };
        let h = self.mul_f32s(x, self.splat_f32s(0.5));
        let y1 = newton_rsqrt_f32(self, h, y);
        rsqrt_specials_f32(self, y, newton_rsqrt_f32(self, h, y1))
    }
}
