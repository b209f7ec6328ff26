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
//! Comput. 36, C401): slot s of the 8 particles of a slice is 8 consecutive entries, so one SIMD
//! vector handles up to 8 particles with contiguous loads of the spring data (the kernel is
//! written once over `crate::simd`, for every instruction set).
//!
//! Jacobian (for implicit integrators, matrix-free, gathered per particle like the force):
//! ∂f_i/∂x_j = K = k n nᵀ + k (1 − L0/L)(I − n nᵀ), ∂f_i/∂x_i = −K; ∂f_i/∂v_j = c n nᵀ,
//! ∂f_i/∂v_i = −c n nᵀ (Baraff & Witkin 1998, §4.1–4.2). Two standard simplifications keep the
//! system matrix M − h ∂f/∂v − h² ∂f/∂x symmetric positive definite: the transverse term
//! k (1 − L0/L)(I − n nᵀ) is dropped for compressed springs (L < L0, where it is negative: the
//! definiteness fix of Choi & Ko 2002, "Stable but responsive cloth", §4), and the dashpot's
//! derivative with respect to positions (not symmetric) is left out. Both change only the
//! linearisation, not the force: the step stays consistent, first order.
use super::registry::{Context, Params};
use super::{Jacobian, Term, Traits, Write};
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::par;
use crate::simd::{self, Kernel, Simd, P};
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
    /// Per group of 8 entries (one slot of a slice): whether its 8 endpoints are consecutive
    /// particles (`other[8q + k] = other[8q] + k`), as in a lattice's interior, so the kernels
    /// read their rows as whole vectors (`Simd::load_rows_f64s`) instead of gathering them.
    consecutive: Vec<bool>,
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
    /// The Jacobian's state-dependent part per SELL-8 entry at the positions `jac_at` (their
    /// address and length) given to `jacobian_prepare`: the axis n and the transverse factor
    /// max(0, 1 − L0/L) (both 0 for padding and undefined axes; n = 0, factor 1 for a
    /// zero-length spring with coincident ends).
    jac_n: Vec<V>,
    jac_t: Vec<Real>,
    jac_at: Option<(usize, usize)>,
}

const SLICE: usize = 8;

fn build<V: Vector>(name: String, mut p: Params, ctx: &Context) -> Result<Box<dyn Term<V>>> {
    let (i, j) = (p.take_indices("i")?, p.take_indices("j")?);
    let (k, c, rest) = (p.take_floats("stiffness")?, p.take_floats("damping")?, p.take_floats("rest_length")?);
    Ok(Box::new(Springs::<V>::new(name, i, j, k, c, rest, ctx.n_particles)?))
}
crate::register_term!("springs", build);

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
                return Err(invalid(
                    "i/j",
                    format!("spring {s} joins {a} and {b}, but the scene has {n_particles} particles"),
                ));
            }
            if a == b {
                return Err(invalid("i/j", format!("spring {s} joins particle {a} to itself")));
            }
        }
        // Everything below but the SELL-8 arrays, whose size is known only later.
        let of = format!("{} springs on {} particles", count(m as u128), count(n_particles as u128));
        let bytes = m as u128 * (8 + 2 * 4 + 3 * 8 + 2 * 8) + 2 * Need::bytes_of::<u32>(n_particles + 1);
        let need = Need::new("springs", bytes, &of);
        need.check()?;
        // Canonical order: i < j, sorted by (i, j), so each particle's springs are listed in a
        // fixed order whatever order the caller gave (ties, duplicate springs, by given order:
        // an unstable sort on a unique key needs no buffer).
        let (i, j, k, c, rest) = {
            let mut order = need.collect(0..m)?;
            order.sort_unstable_by_key(|&s| (i[s].min(j[s]), i[s].max(j[s]), s));
            (
                need.collect(order.iter().map(|&s| i[s].min(j[s])))?,
                need.collect(order.iter().map(|&s| i[s].max(j[s])))?,
                need.collect(order.iter().map(|&s| k[s]))?,
                need.collect(order.iter().map(|&s| c[s]))?,
                need.collect(order.iter().map(|&s| rest[s]))?,
            )
        };
        let any_damping = c.iter().any(|&c| c > 0.0);
        let uniform = match (k.first(), c.first()) {
            (Some(&k0), Some(&c0)) if k.iter().all(|&x| x == k0) && c.iter().all(|&x| x == c0) => Some((k0, c0)),
            _ => None,
        };
        // Per-particle incidence lists (CSR, by counting sort), then SELL-8 slices.
        let n = n_particles;
        let mut off = need.filled(n + 1, 0u32)?;
        for s in 0..m {
            off[i[s] as usize + 1] += 1;
            off[j[s] as usize + 1] += 1;
        }
        for p in 0..n {
            off[p + 1] += off[p];
        }
        let mut fill = need.copy(&off)?;
        let mut inc = need.filled(2 * m, (0u32, 0u32))?; // (other endpoint, spring)
        for s in 0..m {
            let (a, b) = (i[s] as usize, j[s] as usize);
            inc[fill[a] as usize] = (j[s], s as u32);
            fill[a] += 1;
            inc[fill[b] as usize] = (i[s], s as u32);
            fill[b] += 1;
        }
        let n_slices = n.div_ceil(SLICE);
        let mut start = need.filled(n_slices + 1, 0u32)?;
        // Padded entries: up to 8× the largest degree per slice, which u32 offsets must hold.
        let mut entries: u64 = 0;
        for g in 0..n_slices {
            let w = (g * SLICE..((g + 1) * SLICE).min(n)).map(|p| off[p + 1] - off[p]).max().unwrap_or(0);
            entries += SLICE as u64 * w as u64;
            start[g + 1] = u32::try_from(entries)
                .map_err(|_| invalid("i/j", format!("{of}: too many padded incidence entries ({entries})")))?;
        }
        let entries = entries as usize;
        let per_entry = if uniform.is_some() { 4 + 8 } else { 4 + 3 * 8 };
        // Plus one flag per group of 8 entries (`consecutive`).
        let need = Need::new("springs", bytes + entries as u128 * per_entry + (entries / SLICE) as u128, &of);
        need.check()?;
        let mut other = need.filled(entries, 0u32)?;
        let mut e_rest = need.filled(entries, 0.0)?;
        let (mut e_k, mut e_c) =
            if uniform.is_some() { (vec![], vec![]) } else { (need.filled(entries, 0.0)?, need.filled(entries, 0.0)?) };
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
        let consecutive =
            need.collect(other.chunks_exact(SLICE).map(|o| o.iter().zip(o[0] as u64..).all(|(&a, b)| a as u64 == b)))?;
        Ok(Self {
            name,
            i,
            j,
            k,
            c,
            rest,
            start,
            other,
            consecutive,
            e_rest,
            e_k,
            e_c,
            n_cov: n,
            any_damping,
            uniform,
            jac_n: Vec::new(),
            jac_t: Vec::new(),
            jac_at: None,
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

    /// Total spring force on particle `p` (N) and half the dashpot power of its springs (W): the
    /// scalar reference the SIMD kernel is tested against.
    #[cfg(test)]
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

/// Spring forces of the slices `g0 .. g0 + out.len() / SLICE` (the last may be partial: `out` ends
/// at the last covered particle), written over or added to `out`; returns half the dashpot power.
/// One SIMD vector holds `lanes` particles of a slice (8/lanes vectors per slice); slot s of
/// those particles is one contiguous run of entries. 1/L comes from the layer's `rsqrt_in_loop`
/// (the divider at avx2, the estimate elsewhere: a few ulp from a square root and a division).
struct SliceForces<'a, V: Vector> {
    sp: &'a Springs<V>,
    x: &'a [V],
    v: &'a [V],
    g0: usize,
    out: &'a mut [V],
    /// Whether to sum the dashpots' power (only if any spring is damped).
    want: bool,
    write: Write,
}

impl<V: Vector> Kernel for SliceForces<'_, V> {
    type Output = Real;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> Real {
        // The gathers only move data: every way gives the same bits. Slots of consecutive rows
        // are read whole (`load_rows_f64s`); the others take the hardware gather where it pays
        // (Zen 5 at avx512: faster than lane by lane), else are gathered lane by lane. Zen 5,
        // avx512, cloth 128² on 2 threads: 36–40 → 72 M particle-steps/s once consecutive slots
        // were read whole rather than by the hardware gather (256²: 41 → 82–90 M).
        if S::HW_GATHER && simd::hardware_gather_pays() {
            self.slices::<S, true>(s)
        } else {
            self.slices::<S, false>(s)
        }
    }
}

impl<V: Vector> SliceForces<'_, V> {
    /// Whole rows for consecutive slots; the others by the level's hardware row gather
    /// (`Simd::gather_rows_f64s_hw`) if `HW`, else lane by lane.
    #[inline(always)]
    fn slices<S: Simd, const HW: bool>(self, s: S) -> Real {
        let SliceForces { sp, x, v, g0, out, want, write } = self;
        let (xf, vf) = (V::flat(x), V::flat(v));
        let l = P::<S, f64>::lanes();
        let dim = V::DIM;
        let last = sp.n_cov - 1;
        let zero = P::<S, f64>::zero(s);
        let uniform = sp.uniform.map(|(k, c)| (P::splat(s, k), P::splat(s, c)));
        let mut power = zero;
        for (gs, out) in out.chunks_mut(SLICE).enumerate() {
            let g = g0 + gs;
            let (s0, s1) = (sp.start[g] as usize, sp.start[g + 1] as usize);
            for (q, out) in out.chunks_mut(l).enumerate() {
                let p0 = g * SLICE + q * l;
                // Lanes past the last particle (a partial last slice) repeat it; never written.
                let own = |c: usize, a: &[V]| P::<S, f64>::from_fn(s, |k| a[(p0 + k).min(last)].comp(c));
                let (xp, vp) = (
                    [own(0, x), own(1, x), if dim == 3 { own(2, x) } else { zero }],
                    [own(0, v), own(1, v), if dim == 3 { own(2, v) } else { zero }],
                );
                let mut acc = [zero; 3];
                // Whole slots of the slice (8 entries each), zipped so that the loop carries no
                // index arithmetic or bounds checks per slot; this vector's lanes are `lo..lo + l`.
                let lo = q * l;
                let (ek, ec) = match uniform {
                    Some(_) => (&sp.e_rest[s0..s1], &sp.e_rest[s0..s1]), // unread
                    None => (&sp.e_k[s0..s1], &sp.e_c[s0..s1]),
                };
                let slots = sp.other[s0..s1]
                    .chunks_exact(SLICE)
                    .zip(sp.e_rest[s0..s1].chunks_exact(SLICE))
                    .zip(ek.chunks_exact(SLICE).zip(ec.chunks_exact(SLICE)))
                    .zip(&sp.consecutive[s0 / SLICE..s1 / SLICE]);
                for (((other, rest), (ek, ec)), &run) in slots {
                    let other = &other[lo..lo + l];
                    let (ox, ov) = if run {
                        s.load_rows_f64s(xf, vf, dim, other[0] as usize)
                    } else if HW {
                        s.gather_rows_f64s_hw(xf, vf, dim, other)
                    } else {
                        s.gather_rows_f64s(xf, vf, dim, other)
                    };
                    let mut d = [zero; 3];
                    let mut dv = [zero; 3];
                    let mut l2 = zero;
                    for c in 0..dim {
                        d[c] = P { s, v: ox[c] } - xp[c];
                        dv[c] = P { s, v: ov[c] } - vp[c];
                        l2 = d[c].mul_add(d[c], l2);
                    }
                    // Padding and coincident endpoints (L = 0): the axis is undefined, no force.
                    let y = l2.gt(zero).select(l2.rsqrt_in_loop(), zero);
                    let len = l2 * y;
                    let mut vn = zero;
                    for c in 0..dim {
                        d[c] = d[c] * y; // unit axis n
                        vn = dv[c].mul_add(d[c], vn);
                    }
                    let (kk, cc) = match uniform {
                        Some(kc) => kc,
                        None => (P::load(s, &ek[lo..]), P::load(s, &ec[lo..])),
                    };
                    let mag = cc.mul_add(vn, kk * (len - P::load(s, &rest[lo..])));
                    for c in 0..dim {
                        acc[c] = mag.mul_add(d[c], acc[c]);
                    }
                    if want {
                        power = (cc * vn).mul_add(vn, power);
                    }
                }
                let a = [acc[0].to_array(), acc[1].to_array(), acc[2].to_array()];
                for (k, o) in out.iter_mut().enumerate() {
                    let f = V::from_slice(&[a[0][k], a[1][k], a[2][k]][..dim]);
                    write.put(o, f);
                }
            }
        }
        0.5 * power.sum()
    }
}

impl<V: Vector> Springs<V> {
    /// `add_forces` at a given SIMD level.
    fn forces(&self, level: simd::Level, x: &[V], v: &[V], f: &mut [V], write: Write) -> Real {
        let want = self.any_damping;
        let n_cov = self.n_cov;
        // Chunks start at multiples of par::CHUNK, itself a multiple of SLICE: slices never
        // straddle two chunks.
        let power = par::chunks1_sum(&mut f[..n_cov], |p0, out| {
            simd::dispatch(level, SliceForces { sp: self, x, v, g0: p0 / SLICE, out, want, write })
        });
        if write == Write::Overwrite {
            par::chunks1(&mut f[n_cov..], |_, f| f.fill(V::ZERO));
        }
        if want {
            power
        } else {
            0.0
        }
    }
}

impl<V: Vector> Springs<V> {
    /// The axis n and transverse factor t = max(0, 1 − L0/L) of entry `e` of particle `p`:
    /// (0, 0) for padding and for an undefined axis (coincident ends of a spring of positive rest
    /// length: no force, as in the force kernel); (0, 1) for coincident ends of a zero-length
    /// spring, whose K = k I whatever the axis (its dashpot's axis is undefined and its force 0).
    #[inline(always)]
    fn axis(&self, e: usize, p: usize, x: &[V]) -> (V, Real) {
        let o = self.other[e] as usize;
        if o == p {
            return (V::ZERO, 0.0); // padding (a real spring never joins a particle to itself)
        }
        let rest = self.e_rest[e];
        let d = x[o] - x[p];
        let l2 = d.length_squared();
        if l2 > 0.0 {
            let inv = 1.0 / l2.sqrt();
            (d * inv, (1.0 - rest * inv).max(0.0))
        } else if rest == 0.0 {
            (V::ZERO, 1.0)
        } else {
            (V::ZERO, 0.0)
        }
    }

    /// Whether `jacobian_prepare` kept the axes for these positions.
    fn prepared(&self, x: &[V]) -> bool {
        self.jac_at == Some((x.as_ptr() as usize, x.len())) && self.jac_t.len() == self.other.len()
    }

    /// Row `p` of `(cx ∂f/∂x + cv ∂f/∂v)·w` (`with_w`) or of its diagonal (not `with_w`): the
    /// springs of `p` in their fixed slot order. Per spring, the block applied to u = w_o − w_p
    /// is a n nᵀ + b (I − n nᵀ) with a = cx k + cv c and b = cx k max(0, 1 − L0/L). The axes come
    /// from `jacobian_prepare` when `prepared` (the same values, computed once a step).
    #[inline]
    fn jacobian_row(&self, p: usize, x: &[V], c: (Real, Real), w: &[V], with_w: bool, prepared: bool) -> V {
        let (cx, cv) = c;
        let g = p / SLICE;
        let slots = (self.start[g + 1] - self.start[g]) as usize / SLICE;
        let base = self.start[g] as usize + p % SLICE;
        let mut acc = V::ZERO;
        for slot in 0..slots {
            let e = base + SLICE * slot;
            let o = self.other[e] as usize;
            let (n, t) = if prepared { (self.jac_n[e], self.jac_t[e]) } else { self.axis(e, p, x) };
            if t == 0.0 && n == V::ZERO {
                continue; // padding, or no axis
            }
            let (k, damp) = self.kc(e);
            let (a, b) = (cx * k + cv * damp, cx * k * t);
            if with_w {
                let u = w[o] - w[p];
                acc += n * ((a - b) * u.dot(n)) + u * b;
            } else {
                let mut diag = [0.0; 3];
                for (q, dq) in diag.iter_mut().enumerate().take(V::DIM) {
                    let nq = n.comp(q);
                    *dq = -(a * nq * nq + b * (1.0 - nq * nq));
                }
                acc += V::from_slice(&diag[..V::DIM]);
            }
        }
        acc
    }
}

impl<V: Vector> Term<V> for Springs<V> {
    fn name(&self) -> &str {
        &self.name
    }

    fn add_forces(&mut self, x: &[V], v: &[V], _model: &Model, f: &mut [V], write: Write) -> Real {
        self.forces(simd::level(), x, v, f, write)
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

    fn traits(&self) -> Traits<V> {
        Traits { min_particles: self.n_cov, ..Traits::dissipating(self.any_damping) }
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

    fn as_jacobian(&self) -> Option<&dyn Jacobian<V>> {
        Some(self)
    }
    fn as_jacobian_mut(&mut self) -> Option<&mut dyn Jacobian<V>> {
        Some(self)
    }
}

impl<V: Vector> Jacobian<V> for Springs<V> {
    fn prepare(&mut self, x: &[V], _v: &[V], _model: &Model) -> bool {
        let m = self.other.len();
        if self.jac_t.len() != m {
            // Fallible: without room the products compute their axes themselves.
            let (mut n, mut t) = (Vec::new(), Vec::new());
            if n.try_reserve_exact(m).is_err() || t.try_reserve_exact(m).is_err() {
                self.jac_at = None;
                return false;
            }
            n.resize(m, V::ZERO);
            t.resize(m, 0.0);
            (self.jac_n, self.jac_t) = (n, t);
        }
        let (mut jn, mut jt) = (std::mem::take(&mut self.jac_n), std::mem::take(&mut self.jac_t));
        let start = &self.start;
        // One chunk of entries per slice range: entries of slices g0.. are start[g0]..; computed
        // per entry, so any split gives the same values.
        par::chunks2(&mut jn, &mut jt, |e0, n, t| {
            // The slice of entry e0 (start is sorted; a chunk may begin mid-slice).
            let mut g = start.partition_point(|&s| (s as usize) <= e0) - 1;
            for k in 0..n.len() {
                let e = e0 + k;
                while start[g + 1] as usize <= e {
                    g += 1;
                }
                let p = g * SLICE + (e - start[g] as usize) % SLICE;
                (n[k], t[k]) = if p < self.n_cov { self.axis(e, p, x) } else { (V::ZERO, 0.0) };
            }
        });
        (self.jac_n, self.jac_t) = (jn, jt);
        self.jac_at = Some((x.as_ptr() as usize, x.len()));
        true
    }
    fn product(&self, x: &[V], _v: &[V], _model: &Model, c: (Real, Real), w: &[V], out: &mut [V]) {
        let prepared = self.prepared(x);
        par::chunks1(&mut out[..self.n_cov], |p0, out| {
            for (k, o) in out.iter_mut().enumerate() {
                *o += self.jacobian_row(p0 + k, x, c, w, true, prepared);
            }
        });
    }
    fn diagonal(&self, x: &[V], _v: &[V], _model: &Model, c: (Real, Real), out: &mut [V]) {
        let prepared = self.prepared(x);
        par::chunks1(&mut out[..self.n_cov], |p0, out| {
            for (k, o) in out.iter_mut().enumerate() {
                *o += self.jacobian_row(p0 + k, x, c, x, false, prepared);
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simd::Level;
    use glam::{DVec2, DVec3};

    fn lcg(s: &mut u64) -> f64 {
        *s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*s >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A random network over 203 particles (a partial last slice, uneven degrees, one spring of
    /// zero length) at every level this CPU has, against the scalar per-particle reference.
    fn check<V: Vector>(uniform: bool) {
        let n = 203;
        let mut s = 5;
        let mut x: Vec<V> = (0..n).map(|_| V::from_slice(&[lcg(&mut s), lcg(&mut s), lcg(&mut s)][..V::DIM])).collect();
        x[7] = x[3];
        let v: Vec<V> = (0..n)
            .map(|_| V::from_slice(&[lcg(&mut s) - 0.5, lcg(&mut s) - 0.5, lcg(&mut s) - 0.5][..V::DIM]))
            .collect();
        let (mut i, mut j) = (vec![3u32], vec![7u32]);
        for a in 0..n as u32 {
            for _ in 0..(a % 5) {
                let b = (lcg(&mut s) * n as f64) as u32;
                if b != a && !(i.contains(&a.min(b)) && j.contains(&a.max(b))) {
                    i.push(a);
                    j.push(b);
                }
            }
        }
        compare(&x, &v, i, j, uniform, &mut s);
    }

    /// The SIMD kernel at every level this CPU has against the scalar per-particle reference, for
    /// springs `(i, j)` on particles `x` with velocities `v`; returns the springs.
    fn compare<V: Vector>(x: &[V], v: &[V], i: Vec<u32>, j: Vec<u32>, uniform: bool, s: &mut u64) -> Springs<V> {
        let n = x.len();
        let m = i.len();
        let k: Vec<f64> = (0..m).map(|q| if uniform { 50.0 } else { 10.0 + q as f64 }).collect();
        let c: Vec<f64> = (0..m).map(|q| if uniform { 0.3 } else { 0.01 * q as f64 }).collect();
        let rest: Vec<f64> = (0..m).map(|_| 0.2 * lcg(s)).collect();
        let sp = Springs::<V>::new("s".into(), i, j, k, c, rest, n).unwrap();
        let (want, pw): (Vec<V>, f64) = {
            let r: Vec<(V, f64)> = (0..n).map(|p| sp.particle_force(p, x, v, true)).collect();
            (r.iter().map(|a| a.0).collect(), r.iter().map(|a| a.1).sum())
        };
        let scale = want.iter().map(|f| f.length_squared()).fold(0.0, f64::max).sqrt();
        for level in Level::available() {
            let mut f = vec![V::ZERO; n];
            let p = sp.forces(level, x, v, &mut f, Write::Overwrite);
            for q in 0..n {
                assert!(
                    (f[q] - want[q]).length_squared().sqrt() <= 1e-13 * scale,
                    "{level:?} particle {q}: {:?} vs {:?}",
                    f[q],
                    want[q]
                );
            }
            assert!((p - pw).abs() <= 1e-12 * pw, "{level:?} power {p} vs {pw}");
        }
        sp
    }

    /// A 21×13 lattice (structural, shear and bend springs, as a cloth), slightly shaken: most
    /// slots of its slices join consecutive particles and are read as whole rows
    /// (`load_rows_f64s`), the slices at the lattice's edges are gathered.
    fn check_lattice<V: Vector>(uniform: bool) {
        let (gx, gy) = (21usize, 13usize);
        let mut s = 11;
        let x: Vec<V> = (0..gx * gy)
            .map(|p| {
                let jit = [0.01 * lcg(&mut s), 0.01 * lcg(&mut s), 0.01 * lcg(&mut s)];
                V::from_slice(&[(p % gx) as f64 * 0.1 + jit[0], (p / gx) as f64 * 0.1 + jit[1], jit[2]][..V::DIM])
            })
            .collect();
        let v: Vec<V> =
            (0..x.len()).map(|_| V::from_slice(&[lcg(&mut s) - 0.5, lcg(&mut s) - 0.5, 0.1][..V::DIM])).collect();
        let (mut i, mut j) = (vec![], vec![]);
        for p in 0..gx * gy {
            let (px, py) = ((p % gx) as i64, (p / gx) as i64);
            for (dx, dy) in [(1i64, 0i64), (0, 1), (1, 1), (-1, 1), (2, 0), (0, 2)] {
                let (qx, qy) = (px + dx, py + dy);
                if (0..gx as i64).contains(&qx) && qy < gy as i64 {
                    i.push(p as u32);
                    j.push((qy * gx as i64 + qx) as u32);
                }
            }
        }
        let sp = compare(&x, &v, i, j, uniform, &mut s);
        let runs = sp.consecutive.iter().filter(|&&r| r).count();
        assert!(runs > sp.consecutive.len() / 2 && runs < sp.consecutive.len(), "{runs} of {}", sp.consecutive.len());
    }

    /// The Jacobian products against central differences of the force, on a random stretched
    /// network (every spring longer than its rest length: no definiteness fix applies) without
    /// dashpots for ∂f/∂x (their positional derivative is left out by design) and with them for
    /// ∂f/∂v (the force is linear in v: the difference is exact up to round-off).
    fn check_jacobian<V: Vector>() {
        let n = 37;
        let mut s = 11;
        let x: Vec<V> = (0..n).map(|_| V::from_slice(&[lcg(&mut s), lcg(&mut s), lcg(&mut s)][..V::DIM])).collect();
        let v: Vec<V> = (0..n).map(|_| V::from_slice(&[lcg(&mut s), lcg(&mut s), lcg(&mut s)][..V::DIM])).collect();
        let w: Vec<V> = (0..n).map(|_| V::from_slice(&[lcg(&mut s), lcg(&mut s), lcg(&mut s)][..V::DIM])).collect();
        let (mut i, mut j) = (vec![], vec![]);
        for a in 0..n as u32 {
            for b in [(a + 1) % n as u32, (a + 5) % n as u32] {
                i.push(a);
                j.push(b);
            }
        }
        let m = i.len();
        let rest: Vec<f64> =
            (0..m).map(|q| 0.5 * (x[i[q] as usize] - x[j[q] as usize]).length_squared().sqrt()).collect();
        let k: Vec<f64> = (0..m).map(|q| 10.0 + q as f64).collect();
        let model = Model { mass: vec![1.0; n], inv_mass: vec![1.0; n], ..Default::default() };
        for (damping, c, h) in [(0.0, (1.0, 0.0), 1e-6), (0.7, (0.0, 1.0), 1.0)] {
            let sp = Springs::<V>::new("s".into(), i.clone(), j.clone(), k.clone(), vec![damping; m], rest.clone(), n)
                .unwrap();
            let shifted = |sign: f64| {
                let (mut xs, mut vs) = (x.clone(), v.clone());
                let z = if c.0 != 0.0 { &mut xs } else { &mut vs };
                for (a, b) in z.iter_mut().zip(&w) {
                    *a += *b * (sign * h);
                }
                let mut f = vec![V::ZERO; n];
                for p in 0..n {
                    f[p] = sp.particle_force(p, &xs, &vs, false).0;
                }
                f
            };
            let (fp, fm) = (shifted(1.0), shifted(-1.0));
            let mut jw = vec![V::ZERO; n];
            Jacobian::product(&sp, &x, &v, &model, c, &w, &mut jw);
            // The axes kept by jacobian_prepare give the same bits.
            let mut sp2 =
                Springs::<V>::new("s".into(), i.clone(), j.clone(), k.clone(), vec![damping; m], rest.clone(), n)
                    .unwrap();
            assert!(Jacobian::prepare(&mut sp2, &x, &v, &model));
            assert!(sp2.prepared(&x));
            let mut jw2 = vec![V::ZERO; n];
            Jacobian::product(&sp2, &x, &v, &model, c, &w, &mut jw2);
            assert_eq!(jw, jw2);
            let scale = jw.iter().map(|f| f.length_squared()).fold(0.0, f64::max).sqrt();
            for p in 0..n {
                let fd = (fp[p] - fm[p]) * (0.5 / h);
                assert!(
                    (fd - jw[p]).length_squared().sqrt() <= 1e-7 * scale,
                    "{c:?} particle {p}: {fd:?} vs {:?}",
                    jw[p]
                );
            }
            // The diagonal: row (p, q) of the product with unit vectors on component q of
            // particle p alone.
            let mut diag = vec![V::ZERO; n];
            Jacobian::diagonal(&sp, &x, &v, &model, c, &mut diag);
            for p in [0, 7, n - 1] {
                for q in 0..V::DIM {
                    let mut e = vec![V::ZERO; n];
                    let mut unit = [0.0; 3];
                    unit[q] = 1.0;
                    e[p] = V::from_slice(&unit[..V::DIM]);
                    let mut col = vec![V::ZERO; n];
                    Jacobian::product(&sp, &x, &v, &model, c, &e, &mut col);
                    let (a, b) = (col[p].comp(q), diag[p].comp(q));
                    assert!((a - b).abs() <= 1e-12 * a.abs(), "diagonal ({p}, {q}): {b} vs {a}");
                }
            }
        }
    }

    #[test]
    fn jacobian_products_match_finite_differences() {
        check_jacobian::<DVec2>();
        check_jacobian::<DVec3>();
    }

    /// Compressed springs lose their transverse stiffness (Choi & Ko's fix), so −∂f/∂x stays
    /// positive semi-definite: wᵀ(−J)w ≥ 0 for random w on a network squeezed to half its
    /// rest lengths.
    #[test]
    fn compressed_springs_keep_the_jacobian_semidefinite() {
        let n = 20;
        let mut s = 3;
        let x: Vec<DVec3> = (0..n).map(|_| DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s))).collect();
        let (i, j): (Vec<u32>, Vec<u32>) = (0..n as u32).map(|a| (a, (a + 3) % n as u32)).unzip();
        let rest: Vec<f64> = i.iter().zip(&j).map(|(&a, &b)| 2.0 * (x[a as usize] - x[b as usize]).length()).collect();
        let sp = Springs::<DVec3>::new("s".into(), i, j, vec![100.0; n], vec![0.0; n], rest, n).unwrap();
        let model = Model { mass: vec![1.0; n], inv_mass: vec![1.0; n], ..Default::default() };
        for _ in 0..50 {
            let w: Vec<DVec3> = (0..n).map(|_| DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) - 0.5).collect();
            let mut jw = vec![DVec3::ZERO; n];
            Jacobian::product(&sp, &x, &x, &model, (1.0, 0.0), &w, &mut jw);
            let q: f64 = w.iter().zip(&jw).map(|(a, b)| a.dot(*b)).sum();
            assert!(q <= 1e-12, "wᵀJw = {q} > 0");
        }
    }

    #[test]
    fn every_level_matches_the_scalar_reference() {
        check::<DVec2>(true);
        check::<DVec3>(true);
        check::<DVec2>(false);
        check::<DVec3>(false);
        check_lattice::<DVec2>(true);
        check_lattice::<DVec3>(true);
        check_lattice::<DVec3>(false);
    }
}
