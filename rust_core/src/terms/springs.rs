//! Hookean springs with dashpot damping along the spring axis.
//!
//! Force on i from spring (i, j): f = [k (L − L0) + c (v_j − v_i)·n] n, n = (x_j − x_i)/L,
//! and −f on j. Potential ½ k (L − L0)²; the dashpot dissipates c ((v_j − v_i)·n)².
//!
//! Each spring is evaluated once into a per-spring buffer (parallel over springs); then each
//! particle gathers its own springs through a CSR incidence list (parallel over particles).
//! No atomics and a fixed summation order: bit-identical results for any thread count.
use super::Term;
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

pub struct Springs<V: Vector> {
    pub name: String,
    pub i: Vec<u32>,
    pub j: Vec<u32>,
    /// Stiffness k, N/m.
    pub k: Vec<Real>,
    /// Dashpot coefficient c, N·s/m.
    pub c: Vec<Real>,
    /// Rest length L0, m.
    pub rest: Vec<Real>,
    /// CSR incidence: particle p is endpoint i of springs `inc[off[p]..mid[p]]` (force +fs) and
    /// endpoint j of springs `inc[mid[p]..off[p+1]]` (force −fs). Split so the gather has no
    /// data-dependent branch.
    off: Vec<u32>,
    mid: Vec<u32>,
    inc: Vec<u32>,
    /// Scratch: force on endpoint i of each spring.
    fs: Vec<V>,
    any_damping: bool,
}

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
        // Canonical order: i < j, sorted by (i, j). Then each particle's "plus" springs are
        // contiguous in the force buffer and its "minus" springs were written shortly before, so
        // both passes walk memory nearly in order (the caller's spring order is not kept; no
        // result depends on it beyond round-off in sums).
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
        // CSR by counting sort of endpoints: per particle, its "i" springs then its "j" springs.
        let mut n_i = vec![0u32; n_particles];
        let mut n_j = vec![0u32; n_particles];
        for s in 0..m {
            n_i[i[s] as usize] += 1;
            n_j[j[s] as usize] += 1;
        }
        let mut off = vec![0u32; n_particles + 1];
        let mut mid = vec![0u32; n_particles];
        for p in 0..n_particles {
            mid[p] = off[p] + n_i[p];
            off[p + 1] = mid[p] + n_j[p];
        }
        let mut fill_i = off[..n_particles].to_vec();
        let mut fill_j = mid.clone();
        let mut inc = vec![0u32; 2 * m];
        for s in 0..m {
            let a = i[s] as usize;
            inc[fill_i[a] as usize] = s as u32;
            fill_i[a] += 1;
            let b = j[s] as usize;
            inc[fill_j[b] as usize] = s as u32;
            fill_j[b] += 1;
        }
        let any_damping = c.iter().any(|&c| c > 0.0);
        Ok(Self { name, i, j, k, c, rest, off, mid, inc, fs: vec![V::ZERO; m], any_damping })
    }

    pub fn len(&self) -> usize {
        self.i.len()
    }
    pub fn is_empty(&self) -> bool {
        self.i.is_empty()
    }

    #[inline(always)]
    fn spring_force(&self, s: usize, x: &[V], v: &[V], want_power: bool) -> (V, Real) {
        let (a, b) = (self.i[s] as usize, self.j[s] as usize);
        let d = x[b] - x[a];
        let l2 = d.length_squared();
        if l2 <= 0.0 {
            // Coincident endpoints: the axis is undefined, so the spring exerts no force.
            return (V::ZERO, 0.0);
        }
        let l = l2.sqrt();
        let n = d * (1.0 / l); // one division, not one per component
        let vn = (v[b] - v[a]).dot(n);
        let c = self.c[s];
        let mag = self.k[s] * (l - self.rest[s]) + c * vn;
        (n * mag, if want_power { c * vn * vn } else { 0.0 })
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
    /// Eight springs per iteration with AVX-512: endpoints fetched by gather, 1/L from
    /// `vrsqrt14pd` plus two Newton steps (a few ulp from the scalar path, whose sqrt and
    /// division would dominate). Writes `out[..done]` for springs `s0..s0 + done` (a multiple of
    /// 8); the caller finishes the rest with the scalar path. Returns (done, dissipated power).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn forces_avx512(&self, s0: usize, out: &mut [V], x: &[V], v: &[V], want: bool) -> (usize, Real) {
        use std::arch::x86_64::*;
        let dim = V::DIM;
        let xp = x.as_ptr() as *const f64;
        let vp = v.as_ptr() as *const f64;
        let n8 = out.len() / 8 * 8;
        let (zero, half, three_halves) = (_mm512_setzero_pd(), _mm512_set1_pd(0.5), _mm512_set1_pd(1.5));
        let mut power = zero;
        let stride = _mm256_set1_epi32(dim as i32);
        let mut k = 0;
        while k < n8 {
            let s = s0 + k;
            let ia = _mm256_mullo_epi32(_mm256_loadu_si256(self.i.as_ptr().add(s) as *const __m256i), stride);
            let ib = _mm256_mullo_epi32(_mm256_loadu_si256(self.j.as_ptr().add(s) as *const __m256i), stride);
            let mut d = [zero; 3];
            let mut dv = [zero; 3];
            let mut l2 = zero;
            for c in 0..dim {
                let xa = _mm512_i32gather_pd::<8>(ia, xp.add(c));
                let xb = _mm512_i32gather_pd::<8>(ib, xp.add(c));
                let va = _mm512_i32gather_pd::<8>(ia, vp.add(c));
                let vb = _mm512_i32gather_pd::<8>(ib, vp.add(c));
                d[c] = _mm512_sub_pd(xb, xa);
                dv[c] = _mm512_sub_pd(vb, va);
                l2 = _mm512_fmadd_pd(d[c], d[c], l2);
            }
            let h = _mm512_mul_pd(l2, half);
            let mut y = _mm512_rsqrt14_pd(l2);
            y = _mm512_mul_pd(y, _mm512_fnmadd_pd(h, _mm512_mul_pd(y, y), three_halves));
            y = _mm512_mul_pd(y, _mm512_fnmadd_pd(h, _mm512_mul_pd(y, y), three_halves));
            // Coincident endpoints (L = 0): no force, as in the scalar path.
            let y = _mm512_maskz_mov_pd(_mm512_cmp_pd_mask::<_CMP_GT_OQ>(l2, zero), y);
            let l = _mm512_mul_pd(l2, y);
            let mut vn = zero;
            for c in 0..dim {
                d[c] = _mm512_mul_pd(d[c], y); // unit axis n
                vn = _mm512_fmadd_pd(dv[c], d[c], vn);
            }
            let kk = _mm512_loadu_pd(self.k.as_ptr().add(s));
            let cc = _mm512_loadu_pd(self.c.as_ptr().add(s));
            let l0 = _mm512_loadu_pd(self.rest.as_ptr().add(s));
            let mag = _mm512_fmadd_pd(cc, vn, _mm512_mul_pd(kk, _mm512_sub_pd(l, l0)));
            if want {
                power = _mm512_fmadd_pd(_mm512_mul_pd(cc, vn), vn, power);
            }
            let mut lanes = [[0.0f64; 8]; 3];
            for c in 0..dim {
                _mm512_storeu_pd(lanes[c].as_mut_ptr(), _mm512_mul_pd(mag, d[c]));
            }
            for l in 0..8 {
                let comps = [lanes[0][l], lanes[1][l], lanes[2][l]];
                out[k + l] = V::from_slice(&comps[..dim]);
            }
            k += 8;
        }
        (n8, _mm512_reduce_add_pd(power))
    }
}

impl<V: Vector> Term<V> for Springs<V> {
    fn name(&self) -> &str {
        &self.name
    }

    fn add_forces(&mut self, x: &[V], v: &[V], _model: &Model, f: &mut [V], want: bool, assign: bool) -> Real {
        let want = want && self.any_damping;
        let mut fs = std::mem::take(&mut self.fs);
        let this = &*self;
        let simd = simd_available::<V>();
        let power = par::chunks1_sum(&mut fs, |s0, out| {
            let mut done = 0;
            let mut p = 0.0;
            #[cfg(target_arch = "x86_64")]
            if simd {
                // SAFETY: AVX-512F was detected at run time; indices were validated in `new`.
                let (d, pw) = unsafe { this.forces_avx512(s0, out, x, v, want) };
                done = d;
                p = pw;
            }
            for (k, o) in out.iter_mut().enumerate().skip(done) {
                let (fv, pw) = this.spring_force(s0 + k, x, v, want);
                *o = fv;
                p += pw;
            }
            p
        });
        let power = if want { power } else { 0.0 };
        // Gather: particles added after the springs have no incidences.
        let n_cov = self.off.len() - 1;
        let (off, mid, inc, fsr) = (&self.off, &self.mid, &self.inc, &fs);
        par::chunks1(&mut f[..n_cov], |p0, f| {
            for (k, fp) in f.iter_mut().enumerate() {
                let p = p0 + k;
                // Two accumulators: the sum is not one long chain of dependent additions.
                let (mut a, mut b) = (V::ZERO, V::ZERO);
                let plus = &inc[off[p] as usize..mid[p] as usize];
                let minus = &inc[mid[p] as usize..off[p + 1] as usize];
                for &s in plus {
                    a += fsr[s as usize];
                }
                for &s in minus {
                    b -= fsr[s as usize];
                }
                *fp = if assign { a + b } else { *fp + (a + b) };
            }
        });
        if assign {
            par::chunks1(&mut f[n_cov..], |_, f| f.fill(V::ZERO));
        }
        self.fs = fs;
        power
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
        self.off.len() - 1
    }

    fn time_scale(&self, _x: &[V], model: &Model) -> Option<Real> {
        // Gershgorin bound on the largest angular frequency of the linearised network:
        // ω_max² ≤ max_p 2 (1/m_p) Σ_{s ∋ p} k_s (equal masses; a safe estimate otherwise).
        let n = self.off.len() - 1;
        let mut w2: Real = 0.0;
        for p in 0..n {
            let ks: Real = self.inc[self.off[p] as usize..self.off[p + 1] as usize].iter().map(|&s| self.k[s as usize]).sum();
            w2 = w2.max(2.0 * model.inv_mass[p] * ks);
        }
        (w2 > 0.0).then(|| 1.0 / w2.sqrt())
    }
}
