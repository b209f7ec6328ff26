//! Hand-written AVX-512 passes (16 f32 or 8 f64 pairs per instruction), chosen at run time.
//!
//! The portable passes spend most of their time in the divider: a square root and two divisions
//! per pair. Here 1/r comes from the hardware estimate `vrsqrt14` and 1/x from `vrcp14`
//! (relative error < 2⁻¹⁴), refined by Newton–Raphson steps (one for f32: error ~2⁻²⁸, below
//! f32 rounding; two for f64: ~2⁻⁵⁶). Results agree with the portable passes to a few ulp, not
//! bit for bit; for a given CPU they are still identical for any thread count.
#![cfg(target_arch = "x86_64")]

use super::{Bufs, SphParams};
use crate::par::SyncPtr;
use crate::grid::{CellList, Ranges, MAX_RANGES};
use crate::vector::Vector;
use std::arch::x86_64::*;
use std::ops::Range;

macro_rules! simd_passes {
    (
        $modname:ident, $F:ty, $V:ty, $M:ty, $L:expr, $newton:expr, $tiny:expr,
        set1 = $set1:ident, zero = $zero:ident, load = $load:ident, add = $add:ident, sub = $sub:ident,
        mul = $mul:ident, fmadd = $fmadd:ident, fnmadd = $fnmadd:ident, max = $max:ident,
        rsqrt = $rsqrt:ident, rcp = $rcp:ident, cmp = $cmp:ident, maskz = $maskz:ident,
        blend = $blend:ident, reduce = $reduce:ident
    ) => {
        pub mod $modname {
            use super::*;
            type F = $F;
            const L: usize = $L;

            #[inline(always)]
            fn mask(lim: usize) -> $M {
                if lim >= L {
                    <$M>::MAX
                } else {
                    ((1u32 << lim) - 1) as $M
                }
            }

            /// (r, 1/r) from r² via rsqrt estimate + Newton; r² = 0 gives r ≈ 0, 1/r large and finite.
            #[inline]
            #[target_feature(enable = "avx512f,avx512dq,avx512vl,fma")]
            fn r_and_inv(r2: $V) -> ($V, $V) {
                let x = $max(r2, $set1($tiny));
                let hx = $mul(x, $set1(0.5));
                let mut y = $rsqrt(x);
                for _ in 0..$newton {
                    y = $mul(y, $fnmadd(hx, $mul(y, y), $set1(1.5)));
                }
                ($mul(x, y), y)
            }

            #[inline]
            #[target_feature(enable = "avx512f,avx512dq,avx512vl,fma")]
            fn recip(x: $V) -> $V {
                let mut y = $rcp(x);
                for _ in 0..$newton {
                    y = $mul(y, $fnmadd(x, y, $set1(2.0)));
                }
                y
            }

            /// w(q) of the kernel (cubic spline unless `WEND`).
            #[inline]
            #[target_feature(enable = "avx512f,avx512dq,avx512vl,fma")]
            fn w<const WEND: bool>(q: $V) -> $V {
                let z = $zero();
                if WEND {
                    let t = $max($fnmadd($set1(0.5), q, $set1(1.0)), z);
                    let t2 = $mul(t, t);
                    $mul($mul(t2, t2), $fmadd($set1(2.0), q, $set1(1.0)))
                } else {
                    let a = $max($sub($set1(2.0), q), z);
                    let b = $max($sub($set1(1.0), q), z);
                    $fnmadd($mul(b, b), b, $mul($set1(0.25), $mul($mul(a, a), a)))
                }
            }

            /// g(q) = w'(q)/q; `inv_q` = 1/q.
            #[inline]
            #[target_feature(enable = "avx512f,avx512dq,avx512vl,fma")]
            fn g<const WEND: bool>(q: $V, inv_q: $V) -> $V {
                let z = $zero();
                if WEND {
                    let t = $max($fnmadd($set1(0.5), q, $set1(1.0)), z);
                    $mul($set1(-5.0), $mul($mul(t, t), t))
                } else {
                    let a = $max($sub($set1(2.0), q), z);
                    let inner = $fmadd($set1(2.25), q, $set1(-3.0));
                    let outer = $mul($set1(-0.75), $mul($mul(a, a), inv_q));
                    $blend($cmp::<_CMP_LT_OQ>(q, $set1(1.0)), outer, inner)
                }
            }

            #[target_feature(enable = "avx512f,avx512dq,avx512vl,fma")]
            pub fn density_chunk<const WEND: bool, const D: usize>(
                p: &SphParams,
                sigma: f64,
                grid: &CellList,
                walls: &CellList,
                b: &Bufs<F>,
                ks: Range<usize>,
                rho: &mut [F],
                pr: &mut [F],
            ) {
                let inv_h = $set1((1.0 / p.h) as F);
                let (sig, inv_rho0, bb) = (sigma as F, (1.0 / p.rho0) as F, p.b() as F);
                let mut last = [i64::MIN; 3];
                let mut rg = Ranges { r: [(0, 0); MAX_RANGES], len: 0 };
                let mut wr = rg;
                let base = ks.start;
                for k in ks {
                    let c = grid.cells[k];
                    if c != last {
                        rg = grid.query(c);
                        wr = walls.query(c);
                        last = c;
                    }
                    let xi: [$V; 3] = std::array::from_fn(|d| if d < D { $set1(b.pos[d][k]) } else { $zero() });
                    let mut acc = $zero();
                    for (pos, mass, ranges) in [(&b.pos, &b.m, &rg), (&b.wpos, &b.wpsi, &wr)] {
                        for r in ranges.iter() {
                            let mut j = r.start;
                            while j < r.end {
                                assert!(j + L <= mass.len());
                                // SAFETY: j + L ≤ len (padded buffers), checked above.
                                let mut r2 = $zero();
                                for d in 0..D {
                                    let dd = $sub(xi[d], unsafe { $load(pos[d].as_ptr().add(j)) });
                                    r2 = $fmadd(dd, dd, r2);
                                }
                                let (rr, _) = r_and_inv(r2);
                                let m = unsafe { $load(mass.as_ptr().add(j)) };
                                acc = $fmadd($maskz(mask(r.end - j), w::<WEND>($mul(rr, inv_h))), m, acc);
                                j += L;
                            }
                        }
                    }
                    let dsum = sig * $reduce(acc);
                    let s = dsum * inv_rho0;
                    let sg = crate::sph::powi(s, p.gamma);
                    let mut pk = bb * (sg - 1.0);
                    if p.clamp && pk < 0.0 {
                        pk = 0.0;
                    }
                    rho[k - base] = dsum;
                    pr[k - base] = pk / (dsum * dsum);
                }
            }

            #[target_feature(enable = "avx512f,avx512dq,avx512vl,fma")]
            pub fn force_chunk<V: Vector, const WEND: bool, const D: usize, const POWER: bool>(
                p: &SphParams,
                sigma: f64,
                grid: &CellList,
                walls: &CellList,
                b: &Bufs<F>,
                ks: Range<usize>,
                out: SyncPtr<V>,
            ) -> (f64, f64) {
                let h = $set1(p.h as F);
                let inv_h = $set1((1.0 / p.h) as F);
                let scale = -sigma / (p.h * p.h);
                let visc = $set1((2.0 * p.alpha * p.c0 * p.h) as F);
                let eps_h2 = $set1((0.01 * p.h * p.h) as F);
                let mut last = [i64::MIN; 3];
                let mut rg = Ranges { r: [(0, 0); MAX_RANGES], len: 0 };
                let mut wr = rg;
                let mut power = 0.0f64;
                let mut amax = 0.0f64;
                let n = b.m.len();
                for k in ks {
                    let c = grid.cells[k];
                    if c != last {
                        rg = grid.query(c);
                        wr = walls.query(c);
                        last = c;
                    }
                    let xi: [$V; 3] = std::array::from_fn(|d| if d < D { $set1(b.pos[d][k]) } else { $zero() });
                    let vi: [$V; 3] = std::array::from_fn(|d| if d < D { $set1(b.vel[d][k]) } else { $zero() });
                    let (rho_i, pr_i) = ($set1(b.rho[k]), $set1(b.pr[k]));
                    let mut acc = [$zero(); 3];
                    let mut pacc = $zero();
                    for r in rg.iter() {
                        let mut j = r.start;
                        while j < r.end {
                            assert!(j + L <= n);
                            let mm = mask(r.end - j);
                            let mut dx = [$zero(); 3];
                            let mut r2 = $zero();
                            let mut vr = $zero();
                            // SAFETY: j + L ≤ n (padded buffers), checked above.
                            unsafe {
                                for d in 0..D {
                                    dx[d] = $sub(xi[d], $load(b.pos[d].as_ptr().add(j)));
                                    r2 = $fmadd(dx[d], dx[d], r2);
                                    vr = $fmadd($sub(vi[d], $load(b.vel[d].as_ptr().add(j))), dx[d], vr);
                                }
                            }
                            let (rr, inv_r) = r_and_inv(r2);
                            let q = $mul(rr, inv_h);
                            let gq = g::<WEND>(q, $mul(h, inv_r));
                            let (mj, rho_j, pr_j) = unsafe {
                                ($load(b.m.as_ptr().add(j)), $load(b.rho.as_ptr().add(j)), $load(b.pr.as_ptr().add(j)))
                            };
                            // Π_ij = 2 α c0 h max(−v·r, 0) / ((r² + 0.01h²)(ρ_i + ρ_j)) ≥ 0.
                            let approach = $max($sub($zero(), vr), $zero());
                            let pi = $mul($mul(visc, approach), recip($mul($add(r2, eps_h2), $add(rho_i, rho_j))));
                            let mg = $maskz(mm, $mul(mj, gq));
                            let cf = $mul(mg, $add($add(pr_i, pr_j), pi));
                            for d in 0..D {
                                acc[d] = $fmadd(cf, dx[d], acc[d]);
                            }
                            if POWER {
                                pacc = $fmadd($mul(mg, pi), vr, pacc);
                            }
                            j += L;
                        }
                    }
                    let mut wacc = [$zero(); 3];
                    for r in wr.iter() {
                        let mut j = r.start;
                        while j < r.end {
                            assert!(j + L <= b.wpsi.len());
                            let mut dx = [$zero(); 3];
                            let mut r2 = $zero();
                            // SAFETY: j + L ≤ len (padded buffers), checked above.
                            unsafe {
                                for d in 0..D {
                                    dx[d] = $sub(xi[d], $load(b.wpos[d].as_ptr().add(j)));
                                    r2 = $fmadd(dx[d], dx[d], r2);
                                }
                            }
                            let (rr, inv_r) = r_and_inv(r2);
                            let gq = g::<WEND>($mul(rr, inv_h), $mul(h, inv_r));
                            let psi = unsafe { $load(b.wpsi.as_ptr().add(j)) };
                            let cf = $maskz(mask(r.end - j), $mul(psi, gq));
                            for d in 0..D {
                                wacc[d] = $fmadd(cf, dx[d], wacc[d]);
                            }
                            j += L;
                        }
                    }
                    let mi = b.m[k] as f64;
                    let pri = b.pr[k] as f64;
                    let mut a = [0.0f64; 3];
                    for d in 0..D {
                        a[d] = scale * ($reduce(acc[d]) as f64 + pri * $reduce(wacc[d]) as f64);
                    }
                    let a2 = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
                    if a2 > amax {
                        amax = a2;
                    }
                    if POWER {
                        power += 0.5 * mi * (-scale) * $reduce(pacc) as f64;
                    }
                    let fv = [mi * a[0], mi * a[1], mi * a[2]];
                    // SAFETY: `order` is a permutation; each particle is written by exactly one chunk.
                    unsafe { *out.get().add(grid.order[k] as usize) = V::from_slice(&fv[..D]) };
                }
                (power, amax)
            }
        }
    };
}

simd_passes!(
    f32x16, f32, __m512, __mmask16, 16, 1, 1e-30,
    set1 = _mm512_set1_ps, zero = _mm512_setzero_ps, load = _mm512_loadu_ps, add = _mm512_add_ps,
    sub = _mm512_sub_ps, mul = _mm512_mul_ps, fmadd = _mm512_fmadd_ps, fnmadd = _mm512_fnmadd_ps,
    max = _mm512_max_ps, rsqrt = _mm512_rsqrt14_ps, rcp = _mm512_rcp14_ps, cmp = _mm512_cmp_ps_mask,
    maskz = _mm512_maskz_mov_ps, blend = _mm512_mask_blend_ps, reduce = _mm512_reduce_add_ps
);

simd_passes!(
    f64x8, f64, __m512d, __mmask8, 8, 2, 1e-300,
    set1 = _mm512_set1_pd, zero = _mm512_setzero_pd, load = _mm512_loadu_pd, add = _mm512_add_pd,
    sub = _mm512_sub_pd, mul = _mm512_mul_pd, fmadd = _mm512_fmadd_pd, fnmadd = _mm512_fnmadd_pd,
    max = _mm512_max_pd, rsqrt = _mm512_rsqrt14_pd, rcp = _mm512_rcp14_pd, cmp = _mm512_cmp_pd_mask,
    maskz = _mm512_maskz_mov_pd, blend = _mm512_mask_blend_pd, reduce = _mm512_reduce_add_pd
);
