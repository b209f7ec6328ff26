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

impl<V: Vector> Term<V> for Springs<V> {
    fn name(&self) -> &str {
        &self.name
    }

    fn add_forces(&mut self, x: &[V], v: &[V], _model: &Model, f: &mut [V], want: bool) -> Real {
        let want = want && self.any_damping;
        let mut fs = std::mem::take(&mut self.fs);
        let this = &*self;
        let power = if want {
            par::chunks1_sum(&mut fs, |s0, out| {
                let mut p = 0.0;
                for (k, o) in out.iter_mut().enumerate() {
                    let (fv, pw) = this.spring_force(s0 + k, x, v, true);
                    *o = fv;
                    p += pw;
                }
                p
            })
        } else {
            par::chunks1(&mut fs, |s0, out| {
                for (k, o) in out.iter_mut().enumerate() {
                    *o = this.spring_force(s0 + k, x, v, false).0;
                }
            });
            0.0
        };
        // Gather: particles added after the springs have no incidences.
        let n_cov = self.off.len() - 1;
        let (off, mid, inc, fsr) = (&self.off, &self.mid, &self.inc, &fs);
        par::chunks1(&mut f[..n_cov], |p0, f| {
            for (k, fp) in f.iter_mut().enumerate() {
                let p = p0 + k;
                let mut acc = V::ZERO;
                for &s in &inc[off[p] as usize..mid[p] as usize] {
                    acc += fsr[s as usize];
                }
                for &s in &inc[mid[p] as usize..off[p + 1] as usize] {
                    acc -= fsr[s as usize];
                }
                *fp += acc;
            }
        });
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
