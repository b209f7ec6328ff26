//! The fast reciprocal square root and gathers on x86-64 (the only ISA-specific code of the
//! kernels).
use super::{newton_rsqrt_f32, newton_rsqrt_f64, Simd};
use pulp::x86::{V3, V4};
use pulp::{cast, Simd as _};

type F64s3 = <V3 as pulp::Simd>::f64s;
type F32s3 = <V3 as pulp::Simd>::f32s;
type F64s4 = <V4 as pulp::Simd>::f64s;
type F32s4 = <V4 as pulp::Simd>::f32s;

/// AVX2 keeps the portable lane-by-lane row gather: `vgatherdpd` measured slower here (cloth 128²,
/// Zen 5 at the AVX2 level: 35–38 M particle-steps/s with it, 42–52 M without).
///
/// AVX2 has an estimate only for f32 (`vrsqrtps`, relative error ≤ 1.5·2⁻¹²). f64 takes it through
/// float32 and three Newton steps (error 3.7e-4 → 2e-7 → 6e-14 → round-off); lanes outside
/// float32's range, where the estimate would be 0 or inf, take the exact square root and division
/// (a branch per vector, never taken in practice).
/// Checks that rows `idx` of `(n, dim)` arrays `a` and `b` exist, so the gathers below read in
/// bounds.
#[inline(always)]
fn check_rows(a: &[f64], b: &[f64], dim: usize, idx: &[u32]) {
    let max = idx.iter().copied().fold(0, u32::max) as usize;
    assert!((max + 1) * dim <= a.len().min(b.len()), "gather: row {max} out of bounds");
}

impl Simd for V3 {
    #[inline(always)]
    fn rsqrt_f64s(self, x: F64s3) -> F64s3 {
        let zero = self.splat_f64s(0.0);
        let small = self.and_m64s(self.greater_than_f64s(x, zero), self.less_than_f64s(x, self.splat_f64s(1e-36)));
        let out = self.or_m64s(small, self.greater_than_f64s(x, self.splat_f64s(1e36)));
        if self.avx._mm256_movemask_pd(cast(out)) != 0 {
            return self.div_f64s(self.splat_f64s(1.0), self.sqrt_f64s(x));
        }
        let y = cast(self.avx._mm256_cvtps_pd(self.sse._mm_rsqrt_ps(self.avx._mm256_cvtpd_ps(cast(x)))));
        let h = self.mul_f64s(x, self.splat_f64s(0.5));
        let y = newton_rsqrt_f64(self, h, y);
        let y = newton_rsqrt_f64(self, h, y);
        newton_rsqrt_f64(self, h, y)
    }

    /// `vrsqrtps` plus one Newton step (error ≈ 2e-7, under 2 ulp of float32).
    #[inline(always)]
    fn rsqrt_f32s(self, x: F32s3) -> F32s3 {
        let y = self.approx_reciprocal_sqrt_f32x8(x);
        newton_rsqrt_f32(self, self.mul_f32s(x, self.splat_f32s(0.5)), y)
    }
}

/// AVX-512: the hardware row gather (cloth 128²: 54 M particle-steps/s against 26–31 M lane by
/// lane), and `vrsqrt14` (relative error < 2⁻¹⁴) over the whole range; two Newton steps for f64
/// (→ 5.6e-9 → round-off), one for f32 (→ 5.6e-9, below float32 rounding).
impl Simd for V4 {
    #[inline(always)]
    fn gather_rows_f64s(self, a: &[f64], b: &[f64], dim: usize, idx: &[u32]) -> ([F64s4; 3], [F64s4; 3]) {
        let idx: [u32; 8] = idx[..8].try_into().expect("8 lanes");
        check_rows(a, b, dim, &idx);
        let offs = self.avx2._mm256_mullo_epi32(cast(idx), self.avx._mm256_set1_epi32(dim as i32));
        let zero = self.splat_f64s(0.0);
        let (mut ra, mut rb) = ([zero; 3], [zero; 3]);
        for c in 0..dim {
            // SAFETY: every row index is < n (checked above) and c < dim.
            unsafe {
                ra[c] = cast(self.avx512f._mm512_i32gather_pd::<8>(offs, a.as_ptr().add(c)));
                rb[c] = cast(self.avx512f._mm512_i32gather_pd::<8>(offs, b.as_ptr().add(c)));
            }
        }
        (ra, rb)
    }

    #[inline(always)]
    fn rsqrt_f64s(self, x: F64s4) -> F64s4 {
        let y = cast(self.avx512f._mm512_rsqrt14_pd(cast(x)));
        let h = self.mul_f64s(x, self.splat_f64s(0.5));
        let y = newton_rsqrt_f64(self, h, y);
        newton_rsqrt_f64(self, h, y)
    }

    #[inline(always)]
    fn rsqrt_f32s(self, x: F32s4) -> F32s4 {
        let y = cast(self.avx512f._mm512_rsqrt14_ps(cast(x)));
        newton_rsqrt_f32(self, self.mul_f32s(x, self.splat_f32s(0.5)), y)
    }
}
