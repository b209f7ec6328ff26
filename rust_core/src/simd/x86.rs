//! The fast reciprocal square root and gathers on x86-64 (the only ISA-specific code of the
//! kernels).
use super::{newton_rsqrt_f32, rsqrt_specials_f32, rsqrt_specials_f64, Simd};
use pulp::x86::{V3, V4};
use pulp::{cast, Simd as _};
use std::arch::x86_64::{__m256d, __m512d};

type F64s3 = <V3 as pulp::Simd>::f64s;
type F32s3 = <V3 as pulp::Simd>::f32s;
type F64s4 = <V4 as pulp::Simd>::f64s;
type F32s4 = <V4 as pulp::Simd>::f32s;

/// Checks that rows `idx` of `(n, dim)` arrays `a` and `b` exist, so the gathers below read in
/// bounds.
#[inline(always)]
fn check_rows(a: &[f64], b: &[f64], dim: usize, idx: &[u32]) {
    let max = idx.iter().copied().fold(0, u32::max) as usize;
    assert!((max + 1) * dim <= a.len().min(b.len()), "gather: row {max} out of bounds");
}

/// AVX2 keeps the portable lane-by-lane row gather: `vgatherdpd` measured slower here (cloth 128²,
/// Zen 5 at the AVX2 level: 35–38 M particle-steps/s with it, 42–52 M without).
///
/// AVX2 has an estimate only for f32 (`vrsqrtps`, relative error ≤ 1.5·2⁻¹²). f64 takes it through
/// float32, one Newton step there and one third-order step in f64 (see `rsqrt_f64s`); a vector
/// with a lane outside float32's normal range takes the exact square root and division (a branch
/// per vector, not taken for physical distances).
impl Simd for V3 {
    /// Four consecutive rows as whole vectors, de-interleaved in registers. Cloth 128² (Zen 3,
    /// avx2), where most of a spring slice's runs are consecutive: see `Springs`.
    #[inline(always)]
    fn load_rows_f64s(self, a: &[f64], b: &[f64], dim: usize, first: usize) -> ([F64s3; 3], [F64s3; 3]) {
        let zero = self.splat_f64s(0.0);
        let (mut ra, mut rb) = ([zero; 3], [zero; 3]);
        for (src, out) in [(a, &mut ra), (b, &mut rb)] {
            // Rows first..first+4 are src[dim·first .. dim·(first+4)] (bounds checked here).
            let w = &src[dim * first..dim * (first + 4)];
            let ld = |k: usize| -> __m256d {
                cast(pulp::bytemuck::pod_read_unaligned::<F64s3>(pulp::bytemuck::cast_slice(&w[4 * k..4 * k + 4])))
            };
            let av = self.avx;
            if dim == 3 {
                // [x0 y0 z0 x1] [y1 z1 x2 y2] [z2 x3 y3 z3] → halves → x, y, z.
                let (p, q, r) = (ld(0), ld(1), ld(2));
                let m0 = av._mm256_permute2f128_pd::<0x30>(p, q); // x0 y0 x2 y2
                let m1 = av._mm256_permute2f128_pd::<0x21>(p, r); // z0 x1 z2 x3
                let m2 = av._mm256_permute2f128_pd::<0x30>(q, r); // y1 z1 y3 z3
                out[0] = cast(av._mm256_shuffle_pd::<0b1010>(m0, m1));
                out[1] = cast(av._mm256_shuffle_pd::<0b0101>(m0, m2));
                out[2] = cast(av._mm256_shuffle_pd::<0b1010>(m1, m2));
            } else {
                // [x0 y0 x1 y1] [x2 y2 x3 y3] → [x0 y0 x2 y2] [x1 y1 x3 y3] → x, y.
                let (p, q) = (ld(0), ld(1));
                let m0 = av._mm256_permute2f128_pd::<0x20>(p, q);
                let m1 = av._mm256_permute2f128_pd::<0x31>(p, q);
                out[0] = cast(av._mm256_unpacklo_pd(m0, m1));
                out[1] = cast(av._mm256_unpackhi_pd(m0, m1));
            }
        }
        (ra, rb)
    }

    // f64 1/√ here costs ~10 FMA-unit operations (the estimate goes through float32) while the
    // divider idles: every second receiver of the N-body sum takes `vsqrtpd` + `vdivpd` instead.
    // Zen 4, N = 4096 f64 at avx2, medians of 6-8 alternating runs: 1.94 → 2.29 and 2.25 → 2.73 G
    // pairs/s; all receivers through the divider 2.57 (and slower on CPUs with slow dividers);
    // the same split of one receiver in 4 at AVX-512 gained nothing measurable (4.17 → 4.28).
    const SPLIT_RSQRT: usize = 2;
    const DIVIDER_IN_LOOPS: bool = true;
    #[inline(always)]
    fn rsqrt_f64s(self, x: F64s3) -> F64s3 {
        // Estimate and one Newton step in float32 on the narrow vector (four lanes in an xmm):
        // 3.7e-4 → ≈ 4e-7 (float32 rounding included).
        let xf = self.avx._mm256_cvtpd_ps(cast(x));
        let y0 = self.sse._mm_rsqrt_ps(xf);
        let hy = self.sse._mm_mul_ps(self.sse._mm_mul_ps(xf, self.sse._mm_set1_ps(0.5)), y0);
        let y1 = self.sse._mm_mul_ps(y0, self.fma._mm_fnmadd_ps(hy, y0, self.sse._mm_set1_ps(1.5)));
        // Lanes outside float32's normal range (and 0, negative or NaN) end the float32 step as
        // inf or NaN (y1 · 0 is NaN): take the exact square root and division for the vector.
        let z = self.sse._mm_mul_ps(y1, self.sse._mm_setzero_ps());
        if self.sse._mm_movemask_ps(self.sse._mm_cmpunord_ps(z, z)) != 0 {
            return self.div_f64s(self.splat_f64s(1.0), self.sqrt_f64s(x));
        }
        let y: F64s3 = cast(self.avx._mm256_cvtps_pd(y1));
        // One third-order (Householder) step in f64: with e = 1 − x y², 1/√x = y (1 − e)^{-1/2}
        // = y (1 + e/2 + 3e²/8 + …); error ≈ (5/16) e³ → round-off. Three Newton steps in f64
        // cost 12 operations; this and the float32 step 9, most on half-width vectors.
        let e = self.negate_mul_add_f64s(self.mul_f64s(x, y), y, self.splat_f64s(1.0));
        let p = self.mul_add_f64s(e, self.splat_f64s(0.375), self.splat_f64s(0.5));
        self.mul_add_f64s(self.mul_f64s(y, e), p, y)
    }

    /// `vrsqrtps` plus one Newton step (error ≈ 2e-7, under 2 ulp of float32).
    #[inline(always)]
    fn rsqrt_f32s(self, x: F32s3) -> F32s3 {
        let y = self.approx_reciprocal_sqrt_f32x8(x);
        rsqrt_specials_f32(self, y, newton_rsqrt_f32(self, self.mul_f32s(x, self.splat_f32s(0.5)), y))
    }
}

/// AVX-512: whole-row loads of consecutive rows, the hardware row gather for the others (Zen 5,
/// cloth 128²: 54 M particle-steps/s against 26–31 M lane by lane when it took every row; not
/// used on Zen 4, see `hardware_gather_pays`), and `vrsqrt14` (relative error
/// < 2⁻¹⁴) over the whole range; one fourth-order step for f64 (→ 4e-18, round-off), one Newton
/// step for f32 (→ 5.6e-9, below float32 rounding).
impl Simd for V4 {
    const REGISTERS: usize = 32;
    const HW_GATHER: bool = true;

    #[inline(always)]
    fn gather_rows_f64s_hw(self, a: &[f64], b: &[f64], dim: usize, idx: &[u32]) -> ([F64s4; 3], [F64s4; 3]) {
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

    /// Eight consecutive rows as whole vectors (2–3 loads per array), de-interleaved by
    /// two-source permutes (`vpermt2pd`: 1 per component in 2D, 2 in 3D).
    #[inline(always)]
    fn load_rows_f64s(self, a: &[f64], b: &[f64], dim: usize, first: usize) -> ([F64s4; 3], [F64s4; 3]) {
        let zero = self.splat_f64s(0.0);
        let (mut ra, mut rb) = ([zero; 3], [zero; 3]);
        let f = self.avx512f;
        for (src, out) in [(a, &mut ra), (b, &mut rb)] {
            // Rows first..first+8 are src[dim·first .. dim·(first+8)] (bounds checked here).
            let w = &src[dim * first..dim * (first + 8)];
            let ld = |k: usize| -> __m512d {
                cast(pulp::bytemuck::pod_read_unaligned::<F64s4>(pulp::bytemuck::cast_slice(&w[8 * k..8 * k + 8])))
            };
            if dim == 3 {
                // Component c of row k is element 3k + c of p ‖ q ‖ r: the first five or six
                // from p ‖ q (indices 0–15), the rest from r (indices 8–15 of the second permute).
                let (p, q, r) = (ld(0), ld(1), ld(2));
                let x = f._mm512_permutex2var_pd(p, f._mm512_setr_epi64(0, 3, 6, 9, 12, 15, 0, 0), q);
                let y = f._mm512_permutex2var_pd(p, f._mm512_setr_epi64(1, 4, 7, 10, 13, 0, 0, 0), q);
                let z = f._mm512_permutex2var_pd(p, f._mm512_setr_epi64(2, 5, 8, 11, 14, 0, 0, 0), q);
                out[0] = cast(f._mm512_permutex2var_pd(x, f._mm512_setr_epi64(0, 1, 2, 3, 4, 5, 10, 13), r));
                out[1] = cast(f._mm512_permutex2var_pd(y, f._mm512_setr_epi64(0, 1, 2, 3, 4, 8, 11, 14), r));
                out[2] = cast(f._mm512_permutex2var_pd(z, f._mm512_setr_epi64(0, 1, 2, 3, 4, 9, 12, 15), r));
            } else {
                let (p, q) = (ld(0), ld(1));
                out[0] = cast(f._mm512_permutex2var_pd(p, f._mm512_setr_epi64(0, 2, 4, 6, 8, 10, 12, 14), q));
                out[1] = cast(f._mm512_permutex2var_pd(p, f._mm512_setr_epi64(1, 3, 5, 7, 9, 11, 13, 15), q));
            }
        }
        (ra, rb)
    }

    #[inline(always)]
    fn rsqrt_f64s(self, x: F64s4) -> F64s4 {
        let y: F64s4 = cast(self.avx512f._mm512_rsqrt14_pd(cast(x)));
        // One fourth-order step: with e = 1 − x y², y (1 + e/2 + 3e²/8 + 5e³/16); error
        // ≈ (35/128) e⁴ < 4e-18 from e < 2⁻¹⁴: 6 operations, against 7 for two Newton steps.
        let e = self.negate_mul_add_f64s(self.mul_f64s(x, y), y, self.splat_f64s(1.0));
        let p = self.mul_add_f64s(e, self.splat_f64s(0.3125), self.splat_f64s(0.375));
        let p = self.mul_add_f64s(e, p, self.splat_f64s(0.5));
        rsqrt_specials_f64(self, y, self.mul_add_f64s(self.mul_f64s(y, e), p, y))
    }

    #[inline(always)]
    fn rsqrt_f32s(self, x: F32s4) -> F32s4 {
        let y = cast(self.avx512f._mm512_rsqrt14_ps(cast(x)));
        rsqrt_specials_f32(self, y, newton_rsqrt_f32(self, self.mul_f32s(x, self.splat_f32s(0.5)), y))
    }
}
