//! Smoothing kernels with support 2h (scalar, and on SIMD vectors for the passes).
//!
//! With q = r/h: W(r) = σ_d w(q) and ∇_i W(r_ij) = (σ_d / h²) g(q) r_ij, r_ij = x_i − x_j, where
//! g(q) = w'(q)/q. Writing the gradient through g avoids dividing by r (finite at r = 0, where it
//! gives the zero vector).
pub use crate::simd::Float;
use crate::simd::{Simd, P};

pub trait Kernel: Copy + Send + Sync + Default + 'static {
    const NAME: &'static str;
    /// Wendland C2 (else cubic spline): selects the SIMD passes' formulas.
    const WENDLAND: bool;
    /// Normalisation σ_d for dimension `dim` (2 or 3) and smoothing length `h`.
    fn sigma(h: f64, dim: usize) -> f64;
    /// w(q), zero for q ≥ 2. The scalar forms `w`, `g` are the reference: the passes use `wv`,
    /// `gv`, tested against them lane by lane at every SIMD level.
    fn w<F: Float>(q: F) -> F;
    /// g(q) = w'(q)/q, zero for q ≥ 2 (and ≤ 0 everywhere: the kernel decreases).
    fn g<F: Float>(q: F) -> F;
    /// `w` on a SIMD vector of q.
    fn wv<S: Simd, F: Float>(q: P<S, F>) -> P<S, F>;
    /// `g` on a SIMD vector of q, given 1/q (finite: q is kept above a tiny floor).
    fn gv<S: Simd, F: Float>(q: P<S, F>, inv_q: P<S, F>) -> P<S, F>;
    /// (`w`, `g`) on a SIMD vector of q by the scalar forms' own operations in their order (no
    /// FMA, no reciprocal): bit for bit the scalar values at every level, so a pass that takes
    /// them (DFSPH's pair build) gives the same numbers on every CPU.
    fn wg_exact<S: Simd>(q: P<S, f64>) -> (P<S, f64>, P<S, f64>);
}

/// Cubic spline (M4), Monaghan & Lattanzio (1985), eq. 21:
/// w(q) = ¼(2−q)₊³ − (1−q)₊³; σ₂ = 10/(7π h²), σ₃ = 1/(π h³).
#[derive(Clone, Copy, Default, Debug)]
pub struct CubicSpline;

impl Kernel for CubicSpline {
    const NAME: &'static str = "cubic_spline";
    const WENDLAND: bool = false;
    fn sigma(h: f64, dim: usize) -> f64 {
        use std::f64::consts::PI;
        if dim == 2 {
            10.0 / (7.0 * PI * h * h)
        } else {
            1.0 / (PI * h * h * h)
        }
    }
    #[inline(always)]
    fn w<F: Float>(q: F) -> F {
        let a = (F::of(2.0) - q).max(F::ZERO);
        let b = (F::ONE - q).max(F::ZERO);
        F::of(0.25) * a * a * a - b * b * b
    }
    #[inline(always)]
    fn g<F: Float>(q: F) -> F {
        // q < 1: w'/q = −3 + 9/4 q exactly (no cancellation near 0); q ≥ 1: −¾(2−q)²/q.
        let a = (F::of(2.0) - q).max(F::ZERO);
        let inner = F::of(-3.0) + F::of(2.25) * q;
        let outer = F::of(-0.75) * a * a / q.max(F::ONE);
        F::pick(q < F::ONE, inner, outer)
    }
    #[inline(always)]
    fn wv<S: Simd, F: Float>(q: P<S, F>) -> P<S, F> {
        let (z, s) = (P::zero(q.s), q.s);
        let a = (P::splat(s, F::of(2.0)) - q).max(z);
        let b = (P::splat(s, F::ONE) - q).max(z);
        (b * b).neg_mul_add(b, P::splat(s, F::of(0.25)) * (a * a * a))
    }
    #[inline(always)]
    fn gv<S: Simd, F: Float>(q: P<S, F>, inv_q: P<S, F>) -> P<S, F> {
        let (z, s) = (P::zero(q.s), q.s);
        let a = (P::splat(s, F::of(2.0)) - q).max(z);
        let inner = P::splat(s, F::of(2.25)).mul_add(q, P::splat(s, F::of(-3.0)));
        let outer = P::splat(s, F::of(-0.75)) * (a * a) * inv_q;
        q.lt(P::splat(s, F::ONE)).select(inner, outer)
    }
    #[inline(always)]
    fn wg_exact<S: Simd>(q: P<S, f64>) -> (P<S, f64>, P<S, f64>) {
        let (z, s) = (P::zero(q.s), q.s);
        let c = |x: f64| P::splat(s, x);
        let a = (c(2.0) - q).max(z);
        let b = (c(1.0) - q).max(z);
        let w = c(0.25) * a * a * a - b * b * b;
        let inner = c(-3.0) + c(2.25) * q;
        let outer = c(-0.75) * a * a / q.max(c(1.0));
        (w, q.lt(c(1.0)).select(inner, outer))
    }
}

/// Wendland C2, Wendland (1995); in the support-2h form of Dehnen & Aly (2012), Table 1:
/// w(q) = (1 − q/2)₊⁴ (2q + 1); σ₂ = 7/(4π h²), σ₃ = 21/(16π h³).
#[derive(Clone, Copy, Default, Debug)]
pub struct WendlandC2;

impl Kernel for WendlandC2 {
    const NAME: &'static str = "wendland_c2";
    const WENDLAND: bool = true;
    fn sigma(h: f64, dim: usize) -> f64 {
        use std::f64::consts::PI;
        if dim == 2 {
            7.0 / (4.0 * PI * h * h)
        } else {
            21.0 / (16.0 * PI * h * h * h)
        }
    }
    #[inline(always)]
    fn w<F: Float>(q: F) -> F {
        let t = (F::ONE - F::of(0.5) * q).max(F::ZERO);
        let t2 = t * t;
        t2 * t2 * (F::of(2.0) * q + F::ONE)
    }
    #[inline(always)]
    fn g<F: Float>(q: F) -> F {
        let t = (F::ONE - F::of(0.5) * q).max(F::ZERO);
        F::of(-5.0) * t * t * t
    }
    #[inline(always)]
    fn wv<S: Simd, F: Float>(q: P<S, F>) -> P<S, F> {
        let s = q.s;
        let t = P::splat(s, F::of(0.5)).neg_mul_add(q, P::splat(s, F::ONE)).max(P::zero(s));
        let t2 = t * t;
        (t2 * t2) * P::splat(s, F::of(2.0)).mul_add(q, P::splat(s, F::ONE))
    }
    #[inline(always)]
    fn gv<S: Simd, F: Float>(q: P<S, F>, _inv_q: P<S, F>) -> P<S, F> {
        let s = q.s;
        let t = P::splat(s, F::of(0.5)).neg_mul_add(q, P::splat(s, F::ONE)).max(P::zero(s));
        P::splat(s, F::of(-5.0)) * (t * t * t)
    }
    #[inline(always)]
    fn wg_exact<S: Simd>(q: P<S, f64>) -> (P<S, f64>, P<S, f64>) {
        let s = q.s;
        let c = |x: f64| P::splat(s, x);
        let t = (c(1.0) - c(0.5) * q).max(P::zero(s));
        let t2 = t * t;
        (t2 * t2 * (c(2.0) * q + c(1.0)), c(-5.0) * t * t * t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫ W dV = 1 (radial quadrature) and g = w'/q (finite differences), in 2D and 3D.
    fn check<K: Kernel>() {
        let h = 0.7;
        for dim in [2usize, 3] {
            let n = 200_000;
            let dr = 2.0 * h / n as f64;
            let mut total = 0.0;
            for k in 0..n {
                let r = (k as f64 + 0.5) * dr;
                let shell = if dim == 2 { 2.0 * std::f64::consts::PI * r } else { 4.0 * std::f64::consts::PI * r * r };
                total += K::sigma(h, dim) * K::w(r / h) * shell * dr;
            }
            assert!((total - 1.0).abs() < 1e-8, "{} {dim}D integrates to {total}", K::NAME);
        }
        for &q in &[0.05f64, 0.5, 0.99, 1.01, 1.5, 1.9] {
            let e = 1e-6;
            let d = (K::w(q + e) - K::w(q - e)) / (2.0 * e);
            assert!((d / q - K::g(q)).abs() < 1e-6, "{} g({q})", K::NAME);
        }
        assert_eq!(K::w(2.0f64), 0.0);
        assert_eq!(K::g(2.0f64), 0.0);
        assert_eq!(K::w(3.0f64), 0.0);
        assert!(K::g(0.0f64).is_finite());
    }

    /// `wv`/`gv` on SIMD vectors equal the scalar forms lane by lane (to rounding), at every level.
    struct Lanes<K>(std::marker::PhantomData<K>);
    impl<K: Kernel> crate::simd::Kernel for Lanes<K> {
        type Output = ();
        #[inline(always)]
        fn run<S: Simd>(self, s: S) {
            let qs: Vec<f64> = (0..=64).map(|k| 0.03125 * k as f64 + 1e-3).collect();
            let l = P::<S, f64>::lanes();
            for c in qs.chunks(l) {
                let q = P::<S, f64>::from_fn(s, |k| c.get(k).copied().unwrap_or(1.0));
                let (w, g) = (K::wv(q).to_array(), K::gv(q, P::splat(s, 1.0) / q).to_array());
                for (k, &qk) in c.iter().enumerate() {
                    assert!((w[k] - K::w(qk)).abs() <= 1e-15, "{} w({qk})", K::NAME);
                    assert!((g[k] - K::g(qk)).abs() <= 1e-13 * K::g(qk).abs().max(1.0), "{} g({qk})", K::NAME);
                }
            }
        }
    }

    /// `wg_exact` equals the scalar forms bit for bit at every level, over q in [0, 2.5] (the
    /// branch points 1 and 2 included) and at random q.
    struct Exact<K>(std::marker::PhantomData<K>);
    impl<K: Kernel> crate::simd::Kernel for Exact<K> {
        type Output = ();
        #[inline(always)]
        fn run<S: Simd>(self, s: S) {
            let mut seed = 3u64;
            let mut qs: Vec<f64> = (0..=640).map(|k| k as f64 / 256.0).collect();
            qs.extend((0..2000).map(|_| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                2.2 * (seed >> 11) as f64 / (1u64 << 53) as f64
            }));
            let l = P::<S, f64>::lanes();
            for c in qs.chunks(l) {
                let q = P::<S, f64>::from_fn(s, |k| c.get(k).copied().unwrap_or(1.0));
                let (w, g) = K::wg_exact(q);
                let (w, g) = (w.to_array(), g.to_array());
                for (k, &qk) in c.iter().enumerate() {
                    assert_eq!(w[k].to_bits(), K::w(qk).to_bits(), "{} w({qk})", K::NAME);
                    assert_eq!(g[k].to_bits(), K::g(qk).to_bits(), "{} g({qk})", K::NAME);
                }
            }
        }
    }

    #[test]
    fn exact_lane_forms_are_the_scalar_forms_bit_for_bit_at_every_level() {
        for level in crate::simd::Level::available() {
            crate::simd::dispatch(level, Exact::<CubicSpline>(std::marker::PhantomData));
            crate::simd::dispatch(level, Exact::<WendlandC2>(std::marker::PhantomData));
        }
    }

    #[test]
    fn simd_forms_match_the_scalar_reference_at_every_level() {
        for level in crate::simd::Level::available() {
            crate::simd::dispatch(level, Lanes::<CubicSpline>(std::marker::PhantomData));
            crate::simd::dispatch(level, Lanes::<WendlandC2>(std::marker::PhantomData));
        }
    }

    #[test]
    fn kernels_are_normalised_and_consistent() {
        check::<CubicSpline>();
        check::<WendlandC2>();
    }
}
