//! Hookean springs with dashpot damping along the spring axis.
//!
//! Force on i from spring (i, j): f = [k (L − L0) + c (v_j − v_i)·n] n, n = (x_j − x_i)/L,
//! and −f on j. Potential ½ k (L − L0)²; the dashpot dissipates c ((v_j − v_i)·n)².
//!
//! Each particle gathers the forces of its own springs (parallel over particles, no scatter, no
//! atomics, a fixed summation order: bit-identical results for any thread count). A spring is
//! thus evaluated once from each end; the two evaluations are exact negatives of each other
//! (x_j − x_i = −(x_i − x_j) exactly in IEEE arithmetic), so momentum is conserved to round-off.
//! Evaluating twice costs arithmetic but saves a per-spring force buffer and a second pass; the
//! kernel is bound by memory traffic, not arithmetic.
//!
//! The incidence lists are stored as sliced ELLPACK with slices of 8 particles (SELL-8, the
//! layout of sparse matrix–vector products on SIMD hardware: Kreutzer et al. 2014, SIAM J. Sci.
//! Comput. 36, C401): slot s of the 8 particles of a slice is 8 consecutive entries, so the
//! AVX-512 kernel handles 8 particles per instruction with contiguous loads of the spring data.
use super::Term;
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

pub struct Springs<V: Vector> {
    pub name: String,
    /// Spring endpoints in canonical order (i < j, sorted by (i, j)).
    pub i: Vec<u32>,
    pub j: Vec<u32>,
    /// Stiffness k, N/m.
    pub k: Vec<Real>,
    /// Dashpot coefficient c, N·s/m.
    pub c: Vec<Real>,
    /// Rest length L0, m.
    pub rest: Vec<Real>,
    /// SELL-8 incidence: slice g (particles 8g..8g+8) owns entries `start[g]..start[g+1]`, slot
    /// `s`, lane `l` at `start[g] + 8 s + l`; padding entries point at the particle itself (a
    /// zero-length spring exerts no force).
    start: Vec<u32>,
    other: Vec<u32>,
    e_rest: Vec<Real>,
    /// Per-entry k and c (empty when `uniform`).
    e_k: Vec<Real>,
    e_c: Vec<Real>,
    /// Particles covered (the particle count when the springs were added).
    n_cov: usize,
    any_damping: bool,
    /// `Some((k, c))` when every spring has the same stiffness and damping (a cloth, a chain):
    /// the kernels then stream no per-spring k and c.
    uniform: Option<(Real, Real)>,
    _v: std::marker::PhantomData<V>,
}

const SLICE: usize = 8;

impl<V: Vector> Springs<V> {
    /// Builds the term; `n_particles` is the current particle count (indices must be below it).
    pub fn new(
        name: String,
        i: Vec<u32>,
        j: Vec<u32>,
        k: Vec<Real>,
        c: Vec<Real>,
        rest: Vec<Real>,
        n_particles: usize,
    ) -> Result<Self> {
        let m = i.len();
        if j.len() != m {
            return Err(invalid("j", format!("has {} entries but i has {m}", j.len())));
        }
        for (arg, a) in [("stiffness", &k), ("damping", &c), ("rest_length", &rest)] {
            if a.len() != m {
                return Err(invalid(arg, format!("has {} entries, expected {m} (one per spring)", a.len())));
            }
            if let Some(p) = a.iter().position(|x| !x.is_finite() || *x < 0.0) {
                return Err(invalid(arg, format!("entry {p} is {} (must be finite and >= 0)", a[p])));
            }
        }
        for s in 0..m {
            let (a, b) = (i[s] as usize, j[s] as usize);
            if a >= n_particles || b >= n_particles {
                return Err(invalid("i/j", format!("spring {s} joins {a} and {b}, but the scene has {n_particles} particles")));
            }
            if a == b {
                return Err(invalid("i/j", format!("spring {s} joins particle {a} to itself")));
            }
        }
        // Canonical order: i < j, sorted by (i, j), so each particle's springs are listed in a
        // fixed order whatever order the caller gave.
        let (i, j, k, c, rest) = {
            let mut order: Vec<usize> = (0..m).collect();
            let key = |s: usize| (i[s].min(j[s]), i[s].max(j[s]));
            order.sort_by_key(|&s| key(s));
            (
                order.iter().map(|&s| i[s].min(j[s])).collect::<Vec<u32>>(),
                order.iter().map(|&s| i[s].max(j[s])).collect::<Vec<u32>>(),
                order.iter().map(|&s| k[s]).collect::<Vec<Real>>(),
                order.iter().map(|&s| c[s]).collect::<Vec<Real>>(),
                order.iter().map(|&s| rest[s]).collect::<Vec<Real>>(),
            )
        };
        let any_damping = c.iter().any(|&c| c > 0.0);
        let uniform = match (k.first(), c.first()) {
            (Some(&k0), Some(&c0)) if k.iter().all(|&x| x == k0) && c.iter().all(|&x| x == c0) => Some((k0, c0)),
            _ => None,
        };
        // Per-particle incidence lists (CSR, by counting sort), then SELL-8 slices.
        let n = n_particles;
        let mut off = vec![0u32; n + 1];
        for s in 0..m {
            off[i[s] as usize + 1] += 1;
            off[j[s] as usize + 1] += 1;
        }
        for p in 0..n {
            off[p + 1] += off[p];
        }
        let mut fill = off.clone();
        let mut inc = vec![(0u32, 0u32); 2 * m]; // (other endpoint, spring)
        for s in 0..m {
            let (a, b) = (i[s] as usize, j[s] as usize);
            inc[fill[a] as usize] = (j[s], s as u32);
            fill[a] += 1;
            inc[fill[b] as usize] = (i[s], s as u32);
            fill[b] += 1;
        }
        let n_slices = n.div_ceil(SLICE);
        let mut start = vec![0u32; n_slices + 1];
        for g in 0..n_slices {
            let w = (g * SLICE..((g + 1) * SLICE).min(n)).map(|p| off[p + 1] - off[p]).max().unwrap_or(0);
            start[g + 1] = start[g] + SLICE as u32 * w;
        }
        let entries = start[n_slices] as usize;
        let mut other = vec![0u32; entries];
        let mut e_rest = vec![0.0; entries];
        let (mut e_k, mut e_c) = if uniform.is_some() { (vec![], vec![]) } else { (vec![0.0; entries], vec![0.0; entries]) };
        for g in 0..n_slices {
            let w = (start[g + 1] - start[g]) as usize / SLICE;
            for slot in 0..w {
                for lane in 0..SLICE {
                    let p = g * SLICE + lane;
                    let e = start[g] as usize + SLICE * slot + lane;
                    // Padding: the particle itself (or, past the last particle, the last one).
                    other[e] = p.min(n - 1) as u32;
                    if p < n && slot < (off[p + 1] - off[p]) as usize {
                        let (o, s) = inc[off[p] as usize + slot];
                        other[e] = o;
                        e_rest[e] = rest[s as usize];
                        if uniform.is_none() {
                            e_k[e] = k[s as usize];
                            e_c[e] = c[s as usize];
                        }
                    }
                }
            }
        }
        Ok(Self {
            name,
            i,
            j,
            k,
            c,
            rest,
            start,
            other,
            e_rest,
            e_k,
            e_c,
            n_cov: n,
            any_damping,
            uniform,
            _v: std::marker::PhantomData,
        })
    }

    pub fn len(&self) -> usize {
        self.i.len()
    }
    pub fn is_empty(&self) -> bool {
        self.i.is_empty()
    }

    #[inline(always)]
    fn kc(&self, e: usize) -> (Real, Real) {
        match self.uniform {
            Some(kc) => kc,
            None => (self.e_k[e], self.e_c[e]),
        }
    }

    /// Total spring force on particle `p` (N) and half the dashpot power of its springs (W).
    #[inline(always)]
    fn particle_force(&self, p: usize, x: &[V], v: &[V], want_power: bool) -> (V, Real) {
        let g = p / SLICE;
        let w = (self.start[g + 1] - self.start[g]) as usize / SLICE;
        let base = self.start[g] as usize + p % SLICE;
        let (xp, vp) = (x[p], v[p]);
        let mut acc = V::ZERO;
        let mut pw = 0.0;
        for slot in 0..w {
            let e = base + SLICE * slot;
            let o = self.other[e] as usize;
            let d = x[o] - xp;
            let l2 = d.length_squared();
            if l2 <= 0.0 {
                // Padding, or coincident endpoints: the axis is undefined, no force.
                continue;
            }
            let l = l2.sqrt();
            let n = d * (1.0 / l); // one division, not one per component
            let vn = (v[o] - vp).dot(n);
            let (k, c) = self.kc(e);
            acc += n * (k * (l - self.e_rest[e]) + c * vn);
            if want_power {
                pw += c * vn * vn;
            }
        }
        (acc, 0.5 * pw)
    }
}

/// Whether the AVX-512 spring kernel can run (and `V` is a plain array of `DIM` f64s).
#[inline]
fn simd_available<V: Vector>() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        use std::sync::OnceLock;
        static OK: OnceLock<bool> = OnceLock::new();
        std::mem::size_of::<V>() == V::DIM * 8
            && *OK.get_or_init(|| std::env::var_os("PHYSCORE_NO_SIMD").is_none() && is_x86_feature_detected!("avx512f"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

impl<V: Vector> Springs<V> {
    /// Spring forces on the 8 particles of slice `g` (all below `n_cov`) with AVX-512: other
    /// endpoints fetched by gather, 1/L from `vrsqrt14pd` plus two Newton steps (a few ulp from
    /// the scalar path's sqrt and division). Writes (assign) or adds the forces into `out[..8]`;
    /// returns half the dashpot power.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn slice_avx512(&self, g: usize, out: &mut [V], x: &[V], v: &[V], want: bool, assign: bool) -> Real {
        use std::arch::x86_64::*;
        let dim = V::DIM;
        let xptr = x.as_ptr() as *const f64;
        let vptr = v.as_ptr() as *const f64;
        let (zero, half, three_halves) = (_mm512_setzero_pd(), _mm512_set1_pd(0.5), _mm512_set1_pd(1.5));
        let stride = _mm256_set1_epi32(dim as i32);
        let lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let pidx = _mm256_mullo_epi32(_mm256_add_epi32(_mm256_set1_epi32((g * SLICE) as i32), lanes), stride);
        let mut xp = [zero; 3];
        let mut vp = [zero; 3];
        for c in 0..dim {
            xp[c] = _mm512_i32gather_pd::<8>(pidx, xptr.add(c));
            vp[c] = _mm512_i32gather_pd::<8>(pidx, vptr.add(c));
        }
        let mut acc = [zero; 3];
        let mut power = zero;
        let (s0, s1) = (self.start[g] as usize, self.start[g + 1] as usize);
        let mut e = s0;
        while e < s1 {
            // SAFETY: e + 8 <= s1 <= other.len(); indices < n_cov <= x.len() (checked in `new`).
            let oi = _mm256_mullo_epi32(_mm256_loadu_si256(self.other.as_ptr().add(e) as *const __m256i), stride);
            let mut d = [zero; 3];
            let mut dv = [zero; 3];
            let mut l2 = zero;
            for c in 0..dim {
                d[c] = _mm512_sub_pd(_mm512_i32gather_pd::<8>(oi, xptr.add(c)), xp[c]);
                dv[c] = _mm512_sub_pd(_mm512_i32gather_pd::<8>(oi, vptr.add(c)), vp[c]);
                l2 = _mm512_fmadd_pd(d[c], d[c], l2);
            }
            let h = _mm512_mul_pd(l2, half);
            let mut y = _mm512_rsqrt14_pd(l2);
            // (h·y)·y, not h·(y·y): y² = 1/L² overflows for L < 1e-154 (found by the stability
            // tests: springs that had decayed to 1e-155 m turned into NaN).
            y = _mm512_mul_pd(y, _mm512_fnmadd_pd(_mm512_mul_pd(h, y), y, three_halves));
            y = _mm512_mul_pd(y, _mm512_fnmadd_pd(_mm512_mul_pd(h, y), y, three_halves));
            // Padding and coincident endpoints (L = 0): no force, as in the scalar path.
            let y = _mm512_maskz_mov_pd(_mm512_cmp_pd_mask::<_CMP_GT_OQ>(l2, zero), y);
            let l = _mm512_mul_pd(l2, y);
            let mut vn = zero;
            for c in 0..dim {
                d[c] = _mm512_mul_pd(d[c], y); // unit axis n
                vn = _mm512_fmadd_pd(dv[c], d[c], vn);
            }
            let (kk, cc) = match self.uniform {
                Some((k, c)) => (_mm512_set1_pd(k), _mm512_set1_pd(c)),
                None => (_mm512_loadu_pd(self.e_k.as_ptr().add(e)), _mm512_loadu_pd(self.e_c.as_ptr().add(e))),
            };
            let l0 = _mm512_loadu_pd(self.e_rest.as_ptr().add(e));
            let mag = _mm512_fmadd_pd(cc, vn, _mm512_mul_pd(kk, _mm512_sub_pd(l, l0)));
            for c in 0..dim {
                acc[c] = _mm512_fmadd_pd(mag, d[c], acc[c]);
            }
            if want {
                power = _mm512_fmadd_pd(_mm512_mul_pd(cc, vn), vn, power);
            }
            e += SLICE;
        }
        let mut comps = [[0.0f64; 8]; 3];
        for c in 0..dim {
            _mm512_storeu_pd(comps[c].as_mut_ptr(), acc[c]);
        }
        for (l, o) in out.iter_mut().enumerate().take(SLICE) {
            let f = V::from_slice(&[comps[0][l], comps[1][l], comps[2][l]][..dim]);
            *o = if assign { f } else { *o + f };
        }
        0.5 * _mm512_reduce_add_pd(power)
    }
}

impl<V: Vector> Term<V> for Springs<V> {
    fn name(&self) -> &str {
        &self.name
    }

    fn add_forces(&mut self, x: &[V], v: &[V], _model: &Model, f: &mut [V], want: bool, assign: bool) -> Real {
        let want = want && self.any_damping;
        let n_cov = self.n_cov;
        let simd = simd_available::<V>();
        // Chunks start at multiples of par::CHUNK, itself a multiple of SLICE: slices never
        // straddle two chunks.
        let power = par::chunks1_sum(&mut f[..n_cov], |p0, f| {
            let mut pw = 0.0;
            let mut k = 0;
            #[cfg(target_arch = "x86_64")]
            if simd {
                while k + SLICE <= f.len() {
                    // SAFETY: AVX-512F detected at run time; the slice's 8 particles exist.
                    pw += unsafe { self.slice_avx512((p0 + k) / SLICE, &mut f[k..k + SLICE], x, v, want, assign) };
                    k += SLICE;
                }
            }
            for (q, fp) in f.iter_mut().enumerate().skip(k) {
                let (fv, p) = self.particle_force(p0 + q, x, v, want);
                *fp = if assign { fv } else { *fp + fv };
                pw += p;
            }
            pw
        });
        if assign {
            par::chunks1(&mut f[n_cov..], |_, f| f.fill(V::ZERO));
        }
        if want {
            power
        } else {
            0.0
        }
    }

    fn potential(&self, x: &[V], _m: &Model) -> Option<Real> {
        Some(par::sum(self.len(), 0.0, |r| {
            let mut u = 0.0;
            for s in r {
                let l = (x[self.j[s] as usize] - x[self.i[s] as usize]).length_squared().sqrt();
                let e = l - self.rest[s];
                u += 0.5 * self.k[s] * e * e;
            }
            u
        }))
    }

    fn dissipative(&self) -> bool {
        self.any_damping
    }

    fn min_particles(&self) -> usize {
        self.n_cov
    }

    fn time_scale(&self, _x: &[V], model: &Model) -> Option<Real> {
        // Gershgorin bounds on the linearised network: the largest angular frequency,
        // ω_max² ≤ max_p 2 (1/m_p) Σ_{s ∋ p} k_s, and the fastest dashpot rate,
        // λ_max ≤ max_p 2 (1/m_p) Σ_{s ∋ p} c_s (equal masses; safe estimates otherwise).
        // Explicit steps need dt below ~2/ω_max and ~2/λ_max; the time scale is the smaller of
        // 1/ω_max and 1/λ_max.
        let mut w2: Real = 0.0;
        let mut lam: Real = 0.0;
        for p in 0..self.n_cov {
            let g = p / SLICE;
            let w = (self.start[g + 1] - self.start[g]) as usize / SLICE;
            let (ks, cs) = (0..w)
                .map(|slot| self.start[g] as usize + SLICE * slot + p % SLICE)
                .filter(|&e| self.other[e] as usize != p)
                .map(|e| self.kc(e))
                .fold((0.0, 0.0), |(a, b), (k, c)| (a + k, b + c));
            w2 = w2.max(2.0 * model.inv_mass[p] * ks);
            lam = lam.max(2.0 * model.inv_mass[p] * cs);
        }
        let t = (1.0 / w2.sqrt()).min(1.0 / lam);
        t.is_finite().then_some(t)
    }
}
