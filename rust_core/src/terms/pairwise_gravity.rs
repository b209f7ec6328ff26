//! Pairwise Newtonian gravity with Plummer softening, by direct summation (O(N²), parallel over
//! the receiving particle).
//!
//! a_i = G Σ_j m_j (x_j − x_i) / (|x_j − x_i|² + ε²)^{3/2}        (Plummer 1911; Aarseth 2003, eq. 2.4)
//! U   = −G Σ_{i<j} m_i m_j / (|x_j − x_i|² + ε²)^{1/2}
//!
//! The inner loop runs over a structure-of-arrays copy of the sources in blocks of `LANES`
//! independent accumulators, so it vectorises. The best kernel is picked at run time (no
//! `target-cpu=native` in the build): hand-written AVX-512 (rsqrt + Newton), else the portable
//! loop compiled for AVX2, else SSE2. Results never depend on the thread count; the AVX-512 path
//! differs from the others by a few ulp. `PHYSCORE_NO_SIMD=1` forces the portable kernel.
//!
//! With a single-precision state the sum runs in float32 (16 lanes, 1/r from `vrsqrt14ps` plus
//! one Newton step, relative error ~1e-8 < float32's 6e-8): twice the pairs per instruction.
//! The positions are then float32 values already, so differences lose nothing more.
use super::Term;
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};
use rayon::prelude::*;

use crate::sph::kernels::Float;

const LANES: usize = 8;
const LANES32: usize = 16;

/// Structure-of-arrays copy of the sources, padded with massless points to a multiple of the
/// kernel's lane count.
#[derive(Default)]
struct Soa<T> {
    xs: Vec<T>,
    ys: Vec<T>,
    zs: Vec<T>,
    ms: Vec<T>,
}

impl<T: Float> Soa<T> {
    fn pack<V: Vector>(&mut self, x: &[V], model: &Model, lanes: usize) {
        let np = x.len().div_ceil(lanes) * lanes;
        for a in [&mut self.xs, &mut self.ys, &mut self.zs, &mut self.ms] {
            a.clear();
            a.resize(np, T::ZERO);
        }
        for (i, p) in x.iter().enumerate() {
            self.xs[i] = T::of(p.comp(0));
            self.ys[i] = T::of(p.comp(1));
            if V::DIM == 3 {
                self.zs[i] = T::of(p.comp(2));
            }
            self.ms[i] = T::of(model.mass[i]);
        }
    }
}

pub struct PairwiseGravity {
    pub name: String,
    /// Gravitational constant G, m³/(kg·s²).
    pub g: Real,
    /// Plummer softening length ε, m.
    pub softening: Real,
    src: Soa<Real>,
    /// Single-precision state: the sources in float32 and the float32 kernels.
    single: bool,
    src32: Soa<f32>,
}

impl PairwiseGravity {
    pub fn new(name: String, g: Real, softening: Real) -> Self {
        Self { name, g, softening, src: Soa::default(), single: false, src32: Soa::default() }
    }
}

/// Σ_j m_j d_j / (|d_j|² + ε²)^{3/2} for a receiver at (xi, yi, zi) in `L` independent lanes
/// (so the loop vectorises), summed lane-pairwise at the end; returns (ax, ay, az) / G.
#[inline(always)]
fn accel_portable<T: Float, const L: usize>(xi: T, yi: T, zi: T, xs: &[T], ys: &[T], zs: &[T], ms: &[T], eps2: T) -> [Real; 3] {
    let mut ax = [T::ZERO; L];
    let mut ay = [T::ZERO; L];
    let mut az = [T::ZERO; L];
    for (((bx, by), bz), bm) in xs.chunks_exact(L).zip(ys.chunks_exact(L)).zip(zs.chunks_exact(L)).zip(ms.chunks_exact(L)) {
        for l in 0..L {
            let dx = bx[l] - xi;
            let dy = by[l] - yi;
            let dz = bz[l] - zi;
            let r2 = dx * dx + dy * dy + dz * dz + eps2;
            let s = bm[l] / (r2 * r2.sqrt());
            // r2 == 0 only for the self term (or coincident points without softening): no force.
            let s = if r2 > T::ZERO { s } else { T::ZERO };
            ax[l] = ax[l] + s * dx;
            ay[l] = ay[l] + s * dy;
            az[l] = az[l] + s * dz;
        }
    }
    let red = |mut a: [T; L]| {
        let mut w = L;
        while w > 1 {
            w /= 2;
            for l in 0..w {
                a[l] = a[l] + a[l + w];
            }
        }
        a[0].f64()
    };
    [red(ax), red(ay), red(az)]
}

fn accel_generic(xi: Real, yi: Real, zi: Real, xs: &[Real], ys: &[Real], zs: &[Real], ms: &[Real], eps2: Real) -> [Real; 3] {
    accel_portable::<Real, LANES>(xi, yi, zi, xs, ys, zs, ms, eps2)
}

fn accel32_generic(xi: f32, yi: f32, zi: f32, xs: &[f32], ys: &[f32], zs: &[f32], ms: &[f32], eps2: f32) -> [Real; 3] {
    accel_portable::<f32, LANES32>(xi, yi, zi, xs, ys, zs, ms, eps2)
}

/// AVX-512 path: 1/r from the hardware estimate `vrsqrt14pd` (relative error < 2⁻¹⁴) refined by
/// two Newton–Raphson steps y ← y (3/2 − r² y²/2) (error ≈ 1.5 e² per step, so ~2⁻⁵² after two),
/// instead of a square root and a division, which would bound the loop at ~4 cycles per pair.
/// Results agree with the portable kernel to a few ulp, not bit for bit; they are still
/// identical for any thread count.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn accel_avx512(xi: Real, yi: Real, zi: Real, xs: &[Real], ys: &[Real], zs: &[Real], ms: &[Real], eps2: Real) -> [Real; 3] {
    use std::arch::x86_64::*;
    debug_assert!(xs.len() % 8 == 0 && ys.len() == xs.len() && zs.len() == xs.len() && ms.len() == xs.len());
    let (pxi, pyi, pzi) = (_mm512_set1_pd(xi), _mm512_set1_pd(yi), _mm512_set1_pd(zi));
    let (eps, half, three_halves, zero) = (_mm512_set1_pd(eps2), _mm512_set1_pd(0.5), _mm512_set1_pd(1.5), _mm512_setzero_pd());
    let (mut ax, mut ay, mut az) = (zero, zero, zero);
    let mut b = 0;
    while b < xs.len() {
        // SAFETY: b + 8 <= len, all four slices have the same length (padded to LANES).
        let dx = _mm512_sub_pd(_mm512_loadu_pd(xs.as_ptr().add(b)), pxi);
        let dy = _mm512_sub_pd(_mm512_loadu_pd(ys.as_ptr().add(b)), pyi);
        let dz = _mm512_sub_pd(_mm512_loadu_pd(zs.as_ptr().add(b)), pzi);
        let m = _mm512_loadu_pd(ms.as_ptr().add(b));
        let r2 = _mm512_fmadd_pd(dx, dx, _mm512_fmadd_pd(dy, dy, _mm512_fmadd_pd(dz, dz, eps)));
        let h = _mm512_mul_pd(r2, half);
        let mut y = _mm512_rsqrt14_pd(r2);
        // (h·y)·y: y² alone would overflow for r < 1e-154.
        y = _mm512_mul_pd(y, _mm512_fnmadd_pd(_mm512_mul_pd(h, y), y, three_halves));
        y = _mm512_mul_pd(y, _mm512_fnmadd_pd(_mm512_mul_pd(h, y), y, three_halves));
        let s = _mm512_mul_pd(m, _mm512_mul_pd(y, _mm512_mul_pd(y, y)));
        // r² = 0 (self term, or coincident points without softening): no force.
        let s = _mm512_maskz_mov_pd(_mm512_cmp_pd_mask::<_CMP_GT_OQ>(r2, zero), s);
        ax = _mm512_fmadd_pd(s, dx, ax);
        ay = _mm512_fmadd_pd(s, dy, ay);
        az = _mm512_fmadd_pd(s, dz, az);
        b += 8;
    }
    [_mm512_reduce_add_pd(ax), _mm512_reduce_add_pd(ay), _mm512_reduce_add_pd(az)]
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn accel_avx2(xi: Real, yi: Real, zi: Real, xs: &[Real], ys: &[Real], zs: &[Real], ms: &[Real], eps2: Real) -> [Real; 3] {
    accel_generic(xi, yi, zi, xs, ys, zs, ms, eps2)
}

type AccelFn = fn(Real, Real, Real, &[Real], &[Real], &[Real], &[Real], Real) -> [Real; 3];

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn accel32_avx512(xi: f32, yi: f32, zi: f32, xs: &[f32], ys: &[f32], zs: &[f32], ms: &[f32], eps2: f32) -> [Real; 3] {
    use std::arch::x86_64::*;
    debug_assert!(xs.len() % 16 == 0 && ys.len() == xs.len() && zs.len() == xs.len() && ms.len() == xs.len());
    let (pxi, pyi, pzi) = (_mm512_set1_ps(xi), _mm512_set1_ps(yi), _mm512_set1_ps(zi));
    let (eps, half, three_halves, zero) = (_mm512_set1_ps(eps2), _mm512_set1_ps(0.5), _mm512_set1_ps(1.5), _mm512_setzero_ps());
    let (mut ax, mut ay, mut az) = (zero, zero, zero);
    let mut b = 0;
    while b < xs.len() {
        // SAFETY: b + 16 <= len, all four slices have the same length (padded to LANES32).
        let dx = _mm512_sub_ps(_mm512_loadu_ps(xs.as_ptr().add(b)), pxi);
        let dy = _mm512_sub_ps(_mm512_loadu_ps(ys.as_ptr().add(b)), pyi);
        let dz = _mm512_sub_ps(_mm512_loadu_ps(zs.as_ptr().add(b)), pzi);
        let m = _mm512_loadu_ps(ms.as_ptr().add(b));
        let r2 = _mm512_fmadd_ps(dx, dx, _mm512_fmadd_ps(dy, dy, _mm512_fmadd_ps(dz, dz, eps)));
        let mut y = _mm512_rsqrt14_ps(r2);
        y = _mm512_mul_ps(y, _mm512_fnmadd_ps(_mm512_mul_ps(_mm512_mul_ps(r2, half), y), y, three_halves));
        let s = _mm512_mul_ps(m, _mm512_mul_ps(y, _mm512_mul_ps(y, y)));
        let s = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(r2, zero), s);
        ax = _mm512_fmadd_ps(s, dx, ax);
        ay = _mm512_fmadd_ps(s, dy, ay);
        az = _mm512_fmadd_ps(s, dz, az);
        b += 16;
    }
    [_mm512_reduce_add_ps(ax) as Real, _mm512_reduce_add_ps(ay) as Real, _mm512_reduce_add_ps(az) as Real]
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn accel32_avx2(xi: f32, yi: f32, zi: f32, xs: &[f32], ys: &[f32], zs: &[f32], ms: &[f32], eps2: f32) -> [Real; 3] {
    accel32_generic(xi, yi, zi, xs, ys, zs, ms, eps2)
}

type Accel32Fn = fn(f32, f32, f32, &[f32], &[f32], &[f32], &[f32], f32) -> [Real; 3];

/// The instruction set the kernels use on this CPU, decided once per process.
#[derive(Clone, Copy, PartialEq)]
enum Simd {
    Avx512,
    Avx2,
    Portable,
}

fn simd() -> Simd {
    static LEVEL: std::sync::OnceLock<Simd> = std::sync::OnceLock::new();
    *LEVEL.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            if std::env::var_os("PHYSCORE_NO_SIMD").is_none() {
                if is_x86_feature_detected!("avx512f") {
                    return Simd::Avx512;
                }
                if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
                    return Simd::Avx2;
                }
            }
        }
        Simd::Portable
    })
}

fn pick_kernel() -> AccelFn {
    match simd() {
        // SAFETY (both): the features were detected at run time.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => |a, b, c, d, e, f, g, h| unsafe { accel_avx512(a, b, c, d, e, f, g, h) },
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => |a, b, c, d, e, f, g, h| unsafe { accel_avx2(a, b, c, d, e, f, g, h) },
        _ => accel_generic,
    }
}

fn pick_kernel32() -> Accel32Fn {
    match simd() {
        // SAFETY (both): the features were detected at run time.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => |a, b, c, d, e, f, g, h| unsafe { accel32_avx512(a, b, c, d, e, f, g, h) },
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => |a, b, c, d, e, f, g, h| unsafe { accel32_avx2(a, b, c, d, e, f, g, h) },
        _ => accel32_generic,
    }
}

impl<V: Vector> Term<V> for PairwiseGravity {
    fn name(&self) -> &str {
        &self.name
    }

    fn set_single(&mut self, single: bool) {
        self.single = single;
    }

    fn add_forces(&mut self, x: &[V], _v: &[V], model: &Model, f: &mut [V], _want: bool, assign: bool) -> Real {
        if self.single {
            self.src32.pack(x, model, LANES32);
        } else {
            self.src.pack(x, model, LANES);
        }
        let (kernel, kernel32) = (pick_kernel(), pick_kernel32());
        let Soa { xs, ys, zs, ms } = &self.src;
        let Soa { xs: xs32, ys: ys32, zs: zs32, ms: ms32 } = &self.src32;
        let eps2 = self.softening * self.softening;
        let eps2_32 = eps2 as f32;
        let single = self.single;
        let g = self.g;
        let body = |i: usize, fi: &mut V| {
            if model.inv_mass[i] == 0.0 {
                if assign {
                    *fi = V::ZERO;
                }
                return; // pinned: its force is never used
            }
            let a = if single {
                kernel32(xs32[i], ys32[i], zs32[i], xs32, ys32, zs32, ms32, eps2_32)
            } else {
                kernel(xs[i], ys[i], zs[i], xs, ys, zs, ms, eps2)
            };
            let gm = g * model.mass[i];
            let mut buf = [0.0; 3];
            for k in 0..V::DIM {
                buf[k] = a[k] * gm;
            }
            let fg = V::from_slice(&buf);
            *fi = if assign { fg } else { *fi + fg };
        };
        // O(N) work per item: parallel from a few dozen particles on, in fixed small chunks.
        if x.len() >= 64 {
            f.par_chunks_mut(16).enumerate().for_each(|(c, f)| {
                for (k, fi) in f.iter_mut().enumerate() {
                    body(c * 16 + k, fi);
                }
            });
        } else {
            for (i, fi) in f.iter_mut().enumerate() {
                body(i, fi);
            }
        }
        0.0
    }

    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        let eps2 = self.softening * self.softening;
        let n = x.len();
        // Σ_i Σ_{j>i}: each chunk of receivers sums its own rows in index order.
        let u = par::sum(n, 0.0, |r| {
            let mut u = 0.0;
            for i in r {
                let mut row = 0.0;
                for j in i + 1..n {
                    let r2 = (x[j] - x[i]).length_squared() + eps2;
                    if r2 > 0.0 {
                        row += model.mass[j] / r2.sqrt();
                    }
                }
                u += model.mass[i] * row;
            }
            u
        });
        Some(-self.g * u)
    }

    fn dissipative(&self) -> bool {
        false
    }

    fn time_scale(&self, x: &[V], model: &Model) -> Option<Real> {
        // O(N²): only asked for when suggesting a dt after a divergence.
        (x.len() <= 20_000).then(|| encounter_time(self.g, self.softening, x, model)).flatten()
    }
}

/// Shortest pairwise free-fall time sqrt((r² + ε²)^{3/2} / (G (m_i + m_j))) (s), O(N²).
pub fn encounter_time<V: Vector>(g: Real, softening: Real, x: &[V], model: &Model) -> Option<Real> {
    let n = x.len();
    let eps2 = softening * softening;
    let mut best = f64::INFINITY;
    for i in 0..n {
        for j in i + 1..n {
            let r2 = (x[j] - x[i]).length_squared() + eps2;
            let t2 = (r2 * r2.sqrt()) / (g * (model.mass[i] + model.mass[j]));
            if t2 > 0.0 && t2 < best {
                best = t2;
            }
        }
    }
    best.is_finite().then(|| best.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simd_paths_match_the_naive_sum_to_round_off() {
        let n = 203; // not a multiple of LANES: exercises the massless padding
        let mut pg = PairwiseGravity::new("g".into(), 1.0, 0.0);
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let x: Vec<glam::DVec3> = (0..n).map(|_| glam::DVec3::new(rnd(), rnd(), rnd())).collect();
        let model = Model { mass: (0..n).map(|k| 1.0 + k as f64 / n as f64).collect(), inv_mass: vec![1.0; n] };
        pg.src.pack(&x, &model, LANES);
        let fast = pick_kernel();
        let Soa { xs, ys, zs, ms } = &pg.src;
        for i in 0..n {
            let a = accel_generic(xs[i], ys[i], zs[i], xs, ys, zs, ms, 0.0);
            let b = fast(xs[i], ys[i], zs[i], xs, ys, zs, ms, 0.0);
            let mut naive = glam::DVec3::ZERO;
            for j in 0..n {
                if j != i {
                    let d = x[j] - x[i];
                    naive += d * (model.mass[j] / d.length().powi(3));
                }
            }
            for got in [glam::DVec3::from_array(a), glam::DVec3::from_array(b)] {
                assert!((got - naive).length() <= 1e-13 * naive.length().max(1.0), "{got} vs {naive}");
            }
        }
    }

    #[test]
    fn float32_paths_match_the_naive_sum_to_single_precision() {
        let n = 517;
        let mut pg = PairwiseGravity::new("g".into(), 1.0, 0.01);
        let mut seed = 777u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let x: Vec<glam::DVec3> = (0..n).map(|_| glam::DVec3::new(rnd(), rnd(), rnd()).round_f32()).collect();
        let model = Model { mass: (0..n).map(|k| 1.0 + k as f64 / n as f64).collect(), inv_mass: vec![1.0; n] };
        pg.src32.pack(&x, &model, LANES32);
        let fast = pick_kernel32();
        let Soa { xs, ys, zs, ms } = &pg.src32;
        for i in 0..n {
            let (xi, yi, zi) = (xs[i], ys[i], zs[i]);
            let a = accel32_generic(xi, yi, zi, xs, ys, zs, ms, 1e-4);
            let b = fast(xi, yi, zi, xs, ys, zs, ms, 1e-4);
            let mut naive = glam::DVec3::ZERO;
            for j in 0..n {
                let d = x[j] - x[i];
                naive += d * ((model.mass[j] as f32) as f64 / (d.length_squared() + 1e-4).powf(1.5));
            }
            for got in [glam::DVec3::from_array(a), glam::DVec3::from_array(b)] {
                // Sum of n float32 terms: error ~ sqrt(n)·6e-8 of the term magnitudes.
                let scale: f64 = (0..n).map(|j| model.mass[j] / ((x[j] - x[i]).length_squared() + 1e-4)).sum();
                assert!((got - naive).length() <= 2e-5 * scale, "{got} vs {naive}");
            }
        }
    }
}
