//! The pair pass lane by lane: [`Contacts::pair_pass`](super::Contacts) for `F64_LANES` pairs at
//! once (4 on AVX2, 8 on AVX-512, 2 on NEON, 1 on the scalar level), for the semi-implicit steps
//! (commit `Full` or none). "xpbd"'s `Books` / `Springs` commits keep the branchy scalar loop.
//!
//! Why: the scalar loop branches on every candidate (touching or not, live or new, slipping or
//! not) in an order the branch predictor cannot learn, and its chain of square roots and
//! divisions runs one pair at a time. Here every lane takes every path and masks pick the
//! results, so there is nothing to mispredict and the divider works on whole vectors. Measured
//! on the 10^5-disc box (AMD Zen 3, 1 thread, ms/step, medians): AVX2 15.0 → 8.5; even the
//! one-lane scalar level gains (18.9 → 15.3), so it runs this kernel too.
//!
//! Same bits as the scalar loop: each lane does the scalar loop's operations in the same order
//! (no fused multiply–adds, same square roots and divisions, IEEE on every level), the rare
//! onset correction is the scalar function itself, and a tail group repeats its last pair in
//! the unused lanes, which are never written or summed. So a scene gives the same trajectory at
//! every level and for any thread count (tested: `lanes_match_the_scalar_pair_pass`).
//! The sums are added per lane and the lanes summed at the end of each chunk (a fixed order).

use super::{Coef, Law, Link, Material, PairForce, Sums};
use crate::simd::{Kernel, Mask, Simd, P};
use crate::vector::{Real, Vector};

/// The most lanes of any level (AVX-512: 8 f64).
const MAX_LANES: usize = 8;

/// One chunk's pairs (`pi[k]`, `pj[k]` with state `links[k]` and force slot `forces[k]`).
pub(super) struct Lanes<'a, V: Vector> {
    /// Flat `(n, DIM)` positions and velocities, flat `(n, AXIAL_DIM)` angular velocities.
    pub x: &'a [Real],
    pub v: &'a [Real],
    pub omega: &'a [Real],
    pub r: &'a [Real],
    pub im: &'a [Real],
    pub pi: &'a [u32],
    pub pj: &'a [u32],
    pub links: &'a mut [Link<V>],
    pub forces: &'a mut [PairForce<V>],
    pub mat: &'a Material,
    /// The free and the pinned pairs' coefficients when all free grains have one mass.
    pub uniform: Option<(Coef, Coef)>,
    pub dt: Real,
    /// `Commit::Full(dt)`'s dt, if the last step's live contacts are to be committed.
    pub commit: Option<Real>,
    pub eval: bool,
}

type F<S> = P<S, f64>;
type M<S> = Mask<S, f64>;

#[inline(always)]
fn and<S: Simd>(s: S, a: M<S>, b: M<S>) -> M<S> {
    Mask(s.and_m64s(a.0, b.0))
}
#[inline(always)]
fn or<S: Simd>(s: S, a: M<S>, b: M<S>) -> M<S> {
    Mask(s.or_m64s(a.0, b.0))
}
#[inline(always)]
fn andnot<S: Simd>(s: S, a: M<S>, b: M<S>) -> M<S> {
    // a ∧ ¬b
    Mask(s.and_m64s(a.0, s.xor_m64s(b.0, a.0)))
}
#[inline(always)]
fn ge<S: Simd>(a: F<S>, b: F<S>) -> M<S> {
    Mask(a.s.greater_than_or_equal_f64s(a.v, b.v))
}
#[inline(always)]
fn le<S: Simd>(a: F<S>, b: F<S>) -> M<S> {
    Mask(a.s.less_than_or_equal_f64s(a.v, b.v))
}
#[inline(always)]
fn ne<S: Simd>(a: F<S>, b: F<S>) -> M<S> {
    // a ≠ b as the scalar `!=` (true where either is NaN).
    let eq = a.s.equal_f64s(a.v, b.v);
    Mask(a.s.xor_m64s(eq, a.s.equal_f64s(a.s.splat_f64s(0.0), a.s.splat_f64s(0.0))))
}
/// −a exactly (signed zeros included, as the scalar `-a`).
#[inline(always)]
fn neg<S: Simd>(a: F<S>) -> F<S> {
    a * F::<S>::splat(a.s, -1.0)
}
#[inline(always)]
fn sqrt<S: Simd>(a: F<S>) -> F<S> {
    P { s: a.s, v: a.s.sqrt_f64s(a.v) }
}
/// Whether any lane of `m` is set.
#[inline(always)]
fn any<S: Simd>(s: S, m: M<S>) -> bool {
    s.first_true_m64s(m.0) < S::F64_LANES
}
/// `m ? a : b` for the first `k` components.
#[inline(always)]
fn sel3<S: Simd>(m: M<S>, a: [F<S>; 3], b: [F<S>; 3], k: usize) -> [F<S>; 3] {
    let mut o = b;
    for c in 0..k {
        o[c] = m.select(a[c], b[c]);
    }
    o
}

impl<V: Vector> Kernel for Lanes<'_, V> {
    type Output = Sums;

    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> Sums {
        let l = S::F64_LANES;
        let (dim, ad) = (V::DIM, V::AXIAL_DIM);
        let Lanes { x, v, omega, r, im, pi, pj, links, forces, mat, uniform, dt, commit, eval } = self;
        let n_pairs = pi.len();
        let splat = |a: Real| F::<S>::splat(s, a);
        let (zero, half) = (splat(0.0), splat(0.5));
        let kn = mat.stiffness;
        let mu = mat.friction;
        let yes = Mask(s.equal_f64s(s.splat_f64s(0.0), s.splat_f64s(0.0)));
        let no = Mask(s.less_than_f64s(s.splat_f64s(0.0), s.splat_f64s(0.0)));
        let (m_commit, m_eval) = (if commit.is_some() { yes } else { no }, if eval { yes } else { no });
        let dtc = commit.unwrap_or(0.0);
        // Per-lane max overlap and pair count. The books (lost_t, lost_n, broken) are added
        // lane by lane in pair order, as the scalar loop adds them: a per-lane sum would depend
        // on which candidates share a block with a contact, and a restart rebuilds the Verlet
        // lists with other candidates (its books then differed in the last bit at avx2).
        let (mut s_mo, mut s_np) = (zero, zero);
        let (mut b_lt, mut b_ln, mut b_br): (Real, Real, Real) = (0.0, 0.0, 0.0);
        // Branch-free: a lane outside the mask adds +0.0, which leaves any sum but −0.0 as it
        // is, and a book that starts at +0.0 cannot tell (a per-lane branch cost 10 % of a dense
        // pile's step).
        let in_order = |acc: &mut Real, m: M<S>, v: F<S>, cnt: usize| {
            let val = m.select(v, zero).to_array();
            for x in &val[..cnt] {
                *acc += *x;
            }
        };

        let mut p = 0;
        while p < n_pairs {
            let cnt = (n_pairs - p).min(l);
            let mut ii = [0usize; MAX_LANES];
            let mut jj = [0usize; MAX_LANES];
            for k in 0..l {
                let q = p + k.min(cnt - 1);
                ii[k] = pi[q] as usize;
                jj[k] = pj[q] as usize;
            }
            let valid = F::<S>::from_fn(s, |k| if k < cnt { 1.0 } else { 0.0 }).gt(half);
            let g =
                |a: &[Real], idx: &[usize; MAX_LANES], w: usize, c: usize| F::<S>::from_fn(s, |k| a[idx[k] * w + c]);
            let (mut xi, mut xj, mut vi, mut vj) = ([zero; 3], [zero; 3], [zero; 3], [zero; 3]);
            for c in 0..dim {
                xi[c] = g(x, &ii, dim, c);
                xj[c] = g(x, &jj, dim, c);
            }
            let (ri, rj, imi, imj) = (g(r, &ii, 1, 0), g(r, &jj, 1, 0), g(im, &ii, 1, 0), g(im, &jj, 1, 0));
            let lk = |k: usize| &links[p + k.min(cnt - 1)];
            let lfn = F::<S>::from_fn(s, |k| lk(k).fn_);

            // Geometry, as the scalar loop.
            let mut dx = [zero; 3];
            let mut d2 = zero;
            for c in 0..dim {
                dx[c] = xj[c] - xi[c];
                d2 = if c == 0 { dx[c] * dx[c] } else { d2 + dx[c] * dx[c] };
            }
            let sr = ri + rj;
            let overlap = and(s, and(s, d2.lt(sr * sr), and(s, d2.gt(zero), ne(imi + imj, zero))), valid);
            let touching = and(s, m_eval, overlap);
            let live = ge(lfn, zero);
            // Contacts that formed in the step being committed (the scalar loop's `formed`).
            let formed = andnot(s, and(s, m_commit, overlap), live);
            if !any(s, and(s, valid, or(s, or(s, touching, live), formed))) {
                // Candidates apart and without a contact (most of them in a sparse scene).
                if eval {
                    forces[p..p + cnt].iter_mut().for_each(|f| *f = PairForce::ZERO);
                }
                p += l;
                continue;
            }
            let committing = and(s, m_commit, live);
            let active = and(s, or(s, or(s, touching, committing), formed), ne(d2, zero));
            let active = and(s, active, valid);
            for c in 0..dim {
                vi[c] = g(v, &ii, dim, c);
                vj[c] = g(v, &jj, dim, c);
            }
            let (mut wi, mut wj) = ([zero; 3], [zero; 3]);
            for a in 0..ad {
                wi[a] = g(omega, &ii, ad, a);
                wj[a] = g(omega, &jj, ad, a);
            }
            let (mut lxi, mut lft) = ([zero; 3], [zero; 3]);
            for c in 0..dim {
                lxi[c] = F::<S>::from_fn(s, |k| lk(k).xi.comp(c));
                lft[c] = F::<S>::from_fn(s, |k| lk(k).ft.comp(c));
            }
            let mut lbt = F::<S>::from_fn(s, |k| lk(k).bt);
            let lbn = F::<S>::from_fn(s, |k| lk(k).bn);
            let dist = sqrt(d2);
            let inv = splat(1.0) / dist;
            let mut nrm = [zero; 3];
            for c in 0..dim {
                nrm[c] = dx[c] * inv;
            }
            let d = sr - dist;
            let (ai, aj) = (ri - half * d, rj - half * d);
            let mut w = [zero; 3];
            for a in 0..ad {
                w[a] = wi[a] * ai + wj[a] * aj;
            }
            // spin = −n × ω.
            let spin: [F<S>; 3] = if dim == 2 {
                [neg(nrm[1] * w[0]), neg(neg(nrm[0]) * w[0]), zero]
            } else {
                [
                    neg(nrm[1] * w[2] - nrm[2] * w[1]),
                    neg(nrm[2] * w[0] - nrm[0] * w[2]),
                    neg(nrm[0] * w[1] - nrm[1] * w[0]),
                ]
            };
            let mut vc = [zero; 3];
            for c in 0..dim {
                vc[c] = vi[c] - vj[c] + spin[c];
            }
            let dot = |a: &[F<S>; 3], b: &[F<S>; 3]| {
                let mut t = a[0] * b[0];
                for c in 1..dim {
                    t = t + a[c] * b[c];
                }
                t
            };
            let vn = dot(&vc, &nrm);
            let mut vt = [zero; 3];
            for c in 0..dim {
                vt[c] = vc[c] - nrm[c] * vn;
            }

            // Commit (Material::commit, Commit::Full), and the contacts that formed.
            let cm = and(s, active, committing);
            let fm = and(s, active, formed);
            if any(s, or(s, cm, fm)) {
                let dcl = d.max(zero);
                let mut xn = [zero; 3];
                if mu > 0.0 {
                    for c in 0..dim {
                        xn[c] = lxi[c] + vt[c] * splat(dtc);
                    }
                }
                // `Material::spring_energy`, at the cap μ f_n of the last evaluation.
                let (ktv, x2) = (kt(mat, dcl), dot(&xn, &xn));
                let cap = splat(mu) * lfn;
                let held = le(ktv * ktv * x2, cap * cap);
                let ktd = held.select(splat(1.0), ktv);
                let u = held.select(half * ktv * x2, half * cap * cap / ktd);
                // The normal force as applied, f_t − f (f: the last evaluation's force on the
                // first grain), at the relative velocity now.
                let mut fnv = [zero; 3];
                let mut vr = [zero; 3];
                for c in 0..dim {
                    fnv[c] = lft[c] - F::<S>::from_fn(s, |k| forces[p + k.min(cnt - 1)].f.comp(c));
                    vr[c] = vi[c] - vj[c];
                }
                // The tangential force's power as applied: f_t·v_r + τ_i·ω_i + τ_j·ω_j.
                // Summed as the scalar loop's `axial_dot`s, for the same bits.
                let (mut pi_, mut pj_) = (zero, zero);
                for a in 0..ad {
                    let pf = |k: usize| &forces[p + k.min(cnt - 1)];
                    let (ti, tj) = (
                        F::<S>::from_fn(s, |k| V::axial_flat(std::slice::from_ref(&pf(k).ti))[a]),
                        F::<S>::from_fn(s, |k| V::axial_flat(std::slice::from_ref(&pf(k).tj))[a]),
                    );
                    (pi_, pj_) = if a == 0 { (ti * wi[a], tj * wj[a]) } else { (pi_ + ti * wi[a], pj_ + tj * wj[a]) };
                }
                let pt = dot(&lft, &vr) + pi_ + pj_;
                let lost_t = lbt - splat(0.5 * dtc) * pt - u;
                let un = normal_energy(mat, dcl);
                let lost_n = cm.select(lbn + splat(0.5 * dtc) * dot(&fnv, &vr) - un, neg(un));
                in_order(&mut b_lt, cm, lost_t, cnt);
                in_order(&mut b_ln, or(s, cm, fm), lost_n, cnt);
                lxi = sel3(cm, xn, lxi, dim);
                lbt = cm.select(u, lbt);
            }

            // Evaluate (Material::evaluate / pair).
            let ev = and(s, active, touching);
            let en = andnot(s, and(s, m_eval, valid), ev);
            let mut out_xi = lxi;
            let mut out_ft = lft;
            let mut out_fn = lfn;
            let mut out_bt = lbt;
            let mut out_bn = lbn;
            let (mut pf_f, mut pf_ti, mut pf_tj) = ([zero; 3], [zero; 3], [zero; 3]);
            if any(s, ev) {
                let c = coef(s, mat, uniform, imi, imj, dt);
                let (el, gd, v_mid);
                let mut sd = zero;
                match mat.law {
                    Law::Linear => {
                        el = splat(kn) * d;
                        gd = c.gn;
                        v_mid = (vn - c.h * el) * c.inv_den;
                    }
                    Law::Hertz => {
                        sd = sqrt(d);
                        el = splat(kn) * d * sd;
                        gd = c.gn * sqrt(sd);
                        v_mid = (vn - c.h * el) / (splat(1.0) + c.h * gd);
                    }
                }
                let mut fnv = (el + gd * v_mid).max(zero);
                if dt > 0.0 {
                    // A contact that formed during the last step (rare): the scalar correction.
                    let new = andnot(s, ev, live);
                    let on = and(s, and(s, new, vn.gt(zero)), le(d, splat(1.5) * vn * splat(dt)));
                    if any(s, on) {
                        let (onv, fa, da, va, ga) = (
                            on.select(splat(1.0), zero).to_array(),
                            fnv.to_array(),
                            d.to_array(),
                            vn.to_array(),
                            c.gn.to_array(),
                        );
                        let mut fb = fa;
                        for k in 0..l {
                            if onv[k] != 0.0 {
                                fb[k] = mat.onset(fa[k], da[k], va[k], ga[k], dt);
                            }
                        }
                        fnv = F::<S>::load(s, &fb[..l]);
                    }
                }
                let ktv = kt(mat, d);
                // Rotate the spring into the tangent plane, keeping its length.
                let xnrm = dot(&lxi, &nrm);
                let xn_nz = ne(xnrm, zero);
                let xi_p = if dim == 2 {
                    let t = [nrm[1], neg(nrm[0]), zero];
                    let st = dot(&lxi, &t);
                    let len = sqrt(dot(&lxi, &lxi));
                    let signed = st.lt(zero).select(neg(len), len);
                    let s_nz = ne(st, zero);
                    let mut rot = [zero; 3];
                    for c in 0..2 {
                        rot[c] = s_nz.select(t[c] * signed, zero);
                    }
                    sel3(xn_nz, rot, lxi, 2)
                } else {
                    let mut xp = [zero; 3];
                    for c in 0..3 {
                        xp[c] = lxi[c] - nrm[c] * xnrm;
                    }
                    let (l0, l1) = (dot(&lxi, &lxi), dot(&xp, &xp));
                    let scale = sqrt(l0 / l1);
                    let pos = l1.gt(zero);
                    let mut scaled = xp;
                    for c in 0..3 {
                        scaled[c] = pos.select(xp[c] * scale, xp[c]);
                    }
                    sel3(xn_nz, scaled, lxi, 3)
                };
                let gt = match mat.law {
                    Law::Linear => c.gt,
                    Law::Hertz => c.gt * sqrt(sd),
                };
                let mut ft = [zero; 3];
                for c in 0..dim {
                    ft[c] = xi_p[c] * neg(ktv) - vt[c] * gt;
                }
                let cap = splat(mu) * fnv;
                let f2 = dot(&ft, &ft);
                let slip = and(s, f2.gt(cap * cap), ev);
                let mut xi_c = xi_p;
                if any(s, slip) {
                    let scale = cap / sqrt(f2);
                    // As the scalar pair (`Material::pair`): the linear law's spring takes the
                    // capped force less the dashpot's share, the Hertz law's the capped force.
                    let (inv_kt, damp) = match mat.law {
                        Law::Linear => (c.inv_kt, gt),
                        Law::Hertz => (ktv.gt(zero).select(splat(1.0) / ktv, zero), zero),
                    };
                    let mut fs = [zero; 3];
                    let mut xs = [zero; 3];
                    for c in 0..dim {
                        fs[c] = ft[c] * scale;
                        xs[c] = (fs[c] + vt[c] * damp) * neg(inv_kt);
                    }
                    ft = sel3(slip, fs, ft, dim);
                    xi_c = sel3(slip, xs, xi_p, dim);
                }
                let mut force = [zero; 3];
                for c in 0..dim {
                    force[c] = ft[c] - nrm[c] * fnv;
                }
                let wn0 = fnv * vn;
                let wt0 = neg(dot(&ft, &vt));
                out_xi = sel3(ev, xi_c, out_xi, dim);
                out_ft = sel3(ev, ft, out_ft, dim);
                out_fn = ev.select(fnv, out_fn);
                out_bt = ev.select(lbt + splat(0.5 * dt) * wt0, out_bt);
                out_bn = ev.select(splat(0.5 * dt) * wn0 + normal_energy(mat, d), out_bn);
                // moment(n, f_t) = n × f_t; each grain's torque is it times its lever.
                let t: [F<S>; 3] = if dim == 2 {
                    [nrm[0] * ft[1] - nrm[1] * ft[0], zero, zero]
                } else {
                    [nrm[1] * ft[2] - nrm[2] * ft[1], nrm[2] * ft[0] - nrm[0] * ft[2], nrm[0] * ft[1] - nrm[1] * ft[0]]
                };
                for c in 0..dim {
                    pf_f[c] = ev.select(force[c], zero);
                }
                for a in 0..ad {
                    pf_ti[a] = ev.select(t[a] * ai, zero);
                    pf_tj[a] = ev.select(t[a] * aj, zero);
                }
                s_np = s_np + ev.select(splat(1.0), zero);
                s_mo = s_mo.max(ev.select(d, zero));
            }
            // Contacts that ended: the spring's energy to the books, the link cleared.
            let gone = and(s, en, live);
            if any(s, gone) {
                in_order(&mut b_br, gone, lbt, cnt);
                out_xi = sel3(gone, [zero; 3], out_xi, dim);
                out_ft = sel3(gone, [zero; 3], out_ft, dim);
                out_fn = gone.select(splat(Link::<V>::NONE.fn_), out_fn);
                out_bt = gone.select(zero, out_bt);
                out_bn = gone.select(zero, out_bn);
            }

            // Write the lanes back.
            // `to_array` by hand, not `[_; 3]::map`: its closures can stay out of line in a build
            // of several codegen units.
            let arr = |q: [F<S>; 3]| [q[0].to_array(), q[1].to_array(), q[2].to_array()];
            let (a_xi, a_ft) = (arr(out_xi), arr(out_ft));
            let (a_fn, a_bt, a_bn) = (out_fn.to_array(), out_bt.to_array(), out_bn.to_array());
            let mut buf = [0.0; 3];
            for k in 0..cnt {
                let lkm = &mut links[p + k];
                for c in 0..dim {
                    buf[c] = a_xi[c][k];
                }
                lkm.xi = V::from_slice(&buf);
                for c in 0..dim {
                    buf[c] = a_ft[c][k];
                }
                lkm.ft = V::from_slice(&buf);
                lkm.fn_ = a_fn[k];
                lkm.bt = a_bt[k];
                lkm.bn = a_bn[k];
            }
            if eval {
                let (a_f, a_ti, a_tj) = (arr(pf_f), arr(pf_ti), arr(pf_tj));
                for k in 0..cnt {
                    for c in 0..dim {
                        buf[c] = a_f[c][k];
                    }
                    let f = V::from_slice(&buf);
                    for a in 0..ad {
                        buf[a] = a_ti[a][k];
                    }
                    let ti = V::axial_from_slice(&buf);
                    for a in 0..ad {
                        buf[a] = a_tj[a][k];
                    }
                    let tj = V::axial_from_slice(&buf);
                    forces[p + k] = PairForce { f, ti, tj };
                }
            }
            p += l;
        }
        let (mo, np) = (s_mo.to_array(), s_np.to_array());
        let mut out = Sums { lost_t: b_lt, lost_n: b_ln, broken: b_br, ..Sums::default() };
        for k in 0..l {
            out.max_overlap = out.max_overlap.max(mo[k]);
            out.pairs += np[k] as u64;
        }
        out
    }
}

/// The coefficients of each lane's pair (`Material::coef`, lane by lane).
struct LaneCoef<S: Simd> {
    h: F<S>,
    gn: F<S>,
    gt: F<S>,
    inv_den: F<S>,
    inv_kt: F<S>,
}

#[inline(always)]
fn coef<S: Simd>(s: S, mat: &Material, uniform: Option<(Coef, Coef)>, imi: F<S>, imj: F<S>, dt: Real) -> LaneCoef<S> {
    let splat = |a: Real| F::<S>::splat(s, a);
    let zero = splat(0.0);
    match uniform {
        Some((free, pinned)) => {
            let both = and(s, ne(imi, zero), ne(imj, zero));
            let pick = |a: Real, b: Real| both.select(splat(a), splat(b));
            LaneCoef {
                h: pick(free.h, pinned.h),
                gn: pick(free.gn, pinned.gn),
                gt: pick(free.gt, pinned.gt),
                inv_den: pick(free.inv_den, pinned.inv_den),
                inv_kt: pick(free.inv_kt, pinned.inv_kt),
            }
        }
        None => {
            let inv_m = imi + imj;
            let sqrt_km = sqrt(splat(mat.stiffness) / inv_m);
            let gn = splat(2.0 * mat.zeta) * sqrt_km;
            let h = splat(0.5 * dt) * inv_m;
            let kt = mat.tangential_ratio * mat.stiffness;
            let inv_kt = if kt > 0.0 { 1.0 / kt } else { 0.0 };
            LaneCoef {
                h,
                gn,
                gt: gn * splat(mat.tangential_damping),
                inv_den: splat(1.0) / (splat(1.0) + h * gn),
                inv_kt: splat(inv_kt),
            }
        }
    }
}

/// `Material::kt`, lane by lane.
#[inline(always)]
fn kt<S: Simd>(mat: &Material, d: F<S>) -> F<S> {
    match mat.law {
        Law::Linear => F::<S>::splat(d.s, mat.tangential_ratio * mat.stiffness),
        Law::Hertz => F::<S>::splat(d.s, mat.tangential_ratio * 1.5 * mat.stiffness) * sqrt(d),
    }
}

/// `Material::normal_energy`, lane by lane.
#[inline(always)]
fn normal_energy<S: Simd>(mat: &Material, d: F<S>) -> F<S> {
    let s = d.s;
    match mat.law {
        Law::Linear => F::<S>::splat(s, 0.5 * mat.stiffness) * d * d,
        Law::Hertz => F::<S>::splat(s, 0.4 * mat.stiffness) * d * d * sqrt(d),
    }
}
