//! Pairwise Newtonian gravity with Plummer softening, by direct summation (O(N²), parallel over
//! the receiving particle).
//!
//! a_i = G Σ_j m_j (x_j − x_i) / (|x_j − x_i|² + ε²)^{3/2}        (Plummer 1911; Aarseth 2003, eq. 2.4)
//! U   = −G Σ_{i<j} m_i m_j / (|x_j − x_i|² + ε²)^{1/2}
//!
//! The inner loop runs over a structure-of-arrays copy of the sources in blocks of `LANES`
//! independent accumulators, so it vectorises; the hot function is compiled for AVX-512 and AVX2
//! as well and the best one is picked at run time (no `target-cpu=native` in the build). The
//! operations and their order are the same on every path, so results do not depend on the CPU
//! path or the thread count.
use super::Term;
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};
use rayon::prelude::*;

const LANES: usize = 8;

pub struct PairwiseGravity {
    pub name: String,
    /// Gravitational constant G, m³/(kg·s²).
    pub g: Real,
    /// Plummer softening length ε, m.
    pub softening: Real,
    // Structure-of-arrays copy of the sources, padded with massless points to a multiple of LANES.
    xs: Vec<Real>,
    ys: Vec<Real>,
    zs: Vec<Real>,
    ms: Vec<Real>,
}

impl PairwiseGravity {
    pub fn new(name: String, g: Real, softening: Real) -> Self {
        Self { name, g, softening, xs: vec![], ys: vec![], zs: vec![], ms: vec![] }
    }

    fn pack<V: Vector>(&mut self, x: &[V], model: &Model) {
        let n = x.len();
        let np = n.div_ceil(LANES) * LANES;
        for a in [&mut self.xs, &mut self.ys, &mut self.zs, &mut self.ms] {
            a.clear();
            a.resize(np, 0.0);
        }
        for (i, p) in x.iter().enumerate() {
            self.xs[i] = p.comp(0);
            self.ys[i] = p.comp(1);
            if V::DIM == 3 {
                self.zs[i] = p.comp(2);
            }
            self.ms[i] = model.mass[i];
        }
    }
}

/// Σ_j m_j d_j / (|d_j|² + ε²)^{3/2} for a receiver at (xi, yi, zi); returns (ax, ay, az) / G.
#[inline(always)]
fn accel_generic(xi: Real, yi: Real, zi: Real, xs: &[Real], ys: &[Real], zs: &[Real], ms: &[Real], eps2: Real) -> [Real; 3] {
    let mut ax = [0.0; LANES];
    let mut ay = [0.0; LANES];
    let mut az = [0.0; LANES];
    for (((bx, by), bz), bm) in xs
        .chunks_exact(LANES)
        .zip(ys.chunks_exact(LANES))
        .zip(zs.chunks_exact(LANES))
        .zip(ms.chunks_exact(LANES))
    {
        for l in 0..LANES {
            let dx = bx[l] - xi;
            let dy = by[l] - yi;
            let dz = bz[l] - zi;
            let r2 = dx * dx + dy * dy + dz * dz + eps2;
            let s = bm[l] / (r2 * r2.sqrt());
            // r2 == 0 only for the self term (or coincident points without softening): no force.
            let s = if r2 > 0.0 { s } else { 0.0 };
            ax[l] += s * dx;
            ay[l] += s * dy;
            az[l] += s * dz;
        }
    }
    let red = |a: [Real; LANES]| ((a[0] + a[4]) + (a[1] + a[5])) + ((a[2] + a[6]) + (a[3] + a[7]));
    [red(ax), red(ay), red(az)]
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2,fma")]
unsafe fn accel_avx512(xi: Real, yi: Real, zi: Real, xs: &[Real], ys: &[Real], zs: &[Real], ms: &[Real], eps2: Real) -> [Real; 3] {
    accel_generic(xi, yi, zi, xs, ys, zs, ms, eps2)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn accel_avx2(xi: Real, yi: Real, zi: Real, xs: &[Real], ys: &[Real], zs: &[Real], ms: &[Real], eps2: Real) -> [Real; 3] {
    accel_generic(xi, yi, zi, xs, ys, zs, ms, eps2)
}

type AccelFn = fn(Real, Real, Real, &[Real], &[Real], &[Real], &[Real], Real) -> [Real; 3];

fn pick_kernel() -> AccelFn {
    #[cfg(target_arch = "x86_64")]
    {
        if std::env::var_os("PHYSCORE_NO_SIMD").is_none() {
            if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512dq") && is_x86_feature_detected!("avx512vl") {
                // SAFETY: the features were detected at run time.
                return |a, b, c, d, e, f, g, h| unsafe { accel_avx512(a, b, c, d, e, f, g, h) };
            }
            if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
                // SAFETY: the features were detected at run time.
                return |a, b, c, d, e, f, g, h| unsafe { accel_avx2(a, b, c, d, e, f, g, h) };
            }
        }
    }
    accel_generic
}

impl<V: Vector> Term<V> for PairwiseGravity {
    fn name(&self) -> &str {
        &self.name
    }

    fn add_forces(&mut self, x: &[V], _v: &[V], model: &Model, f: &mut [V], _want: bool) -> Real {
        self.pack(x, model);
        let kernel = pick_kernel();
        let (xs, ys, zs, ms) = (&self.xs, &self.ys, &self.zs, &self.ms);
        let eps2 = self.softening * self.softening;
        let g = self.g;
        let body = |i: usize, fi: &mut V| {
            if model.inv_mass[i] == 0.0 {
                return; // pinned: its force is never used
            }
            let a = kernel(xs[i], ys[i], zs[i], xs, ys, zs, ms, eps2);
            let gm = g * model.mass[i];
            let mut buf = [0.0; 3];
            for k in 0..V::DIM {
                buf[k] = a[k] * gm;
            }
            *fi += V::from_slice(&buf);
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
