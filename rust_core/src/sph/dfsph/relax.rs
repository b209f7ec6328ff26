//! The solves' Jacobi relaxation ω (`DfsphParams::relaxation`): how much of each particle's
//! own correction κ_i/ρ_i = e_i/(dt^p D_i) an iteration applies.
//!
//! Both solves update every particle at once (Jacobi). On a particle lattice of spacing Δx at
//! rest, a plane wave κ_k = exp(i θ·x_k/Δx) of corrections changes the predicted density by
//! λ(θ) κ with λ(θ) ∝ |Σ_p g_p sin(θ·p)|², where g_p = g(|p|/s) p is the kernel gradient
//! towards the neighbour at lattice offset p (s = h/Δx, `Kernel::g`), while the iteration
//! divides by the diagonal D ∝ Σ_p |g_p|² (module doc's D_i; λ's mean over θ). A Jacobi
//! iteration with relaxation ω multiplies a wave's error by 1 − ω λ(θ)/D, so it grows once
//! ω max λ/D > 2. That ratio grows with the neighbourhood: 2.87 in 2D at the default h = 1.3 Δx
//! with the cubic spline, 4.91 in 3D, 6.7 and 17.6 at h = 2 Δx, 2.82 in 3D at h = 1.0 Δx (3D
//! DFSPH's default since 2026-12-01: unrelaxed, as the DFSPH paper) (`ratio`). The one-sided
//! solves (only compressing particles push) tolerate 2D's 2.87 (tuned, tested against
//! Martin & Moyce with ω = 1), but not 3D's: a 3D dam break 40 particles across at h = 1.3 Δx
//! grew a jitter in its fourth layer above the floor by ×1.8 a step whatever dt or warm start,
//! and blew up (2.5 km/s) by step 9, the density solve content with its 2 iterations because
//! the mean error hid it; at h = 2 Δx a 2D column blew up (10⁶¹ m/s) within 4 steps. So
//! ω = min(1, R/ratio) with R the ratio of the 2D cubic spline at h = 1.3 Δx: exactly 1 there
//! and wherever the neighbourhood is as narrow (2D scenes at the defaults kept their bits; 3D at
//! h = 1.0 Δx), 0.585 in 3D at h = 1.3 Δx, 0.43 at h = 2 Δx in 2D. The same rule as IISPH's
//! relaxed Jacobi (Ihmsen et al., IEEE TVCG 20 (2014) 426, eq. 14, ω = 0.5), with ω chosen
//! from the kernel instead of fixed.
use super::super::kernels::{CubicSpline, Kernel, WendlandC2};
use super::super::params::KernelKind;
use crate::vector::Real;

/// The smoothing h/Δx of the reference (`relaxation` is 1 up to its ratio).
const REFERENCE_SMOOTHING: Real = 1.3;

/// Wave numbers sampled per axis over [0, π] (λ is even in each component of θ up to the
/// lattice's symmetry, so the half-range holds the maximum): 17 points find it within 0.5 %.
const SAMPLES: usize = 16;

/// max_θ λ(θ)/D on the lattice Z^dim with h/Δx = `smoothing` (module doc).
pub fn ratio(dim: usize, kernel: KernelKind, smoothing: Real) -> Real {
    match kernel {
        KernelKind::CubicSpline => ratio_of::<CubicSpline>(dim, smoothing),
        KernelKind::WendlandC2 => ratio_of::<WendlandC2>(dim, smoothing),
    }
}

fn ratio_of<K: Kernel>(dim: usize, s: Real) -> Real {
    // The offsets p ≠ 0 within the support (|p| < 2s) and their g_p.
    let r = (2.0 * s).ceil() as i64;
    let z = if dim == 3 { r } else { 0 };
    let mut g: Vec<([Real; 3], [Real; 3])> = Vec::new();
    for c in -z..=z {
        for b in -r..=r {
            for a in -r..=r {
                let p = [a as Real, b as Real, c as Real];
                let q = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() / s;
                if q > 0.0 && q < 2.0 {
                    let k = K::g(q);
                    g.push((p, [k * p[0], k * p[1], k * p[2]]));
                }
            }
        }
    }
    let diagonal: Real = g.iter().map(|(_, v)| v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sum();
    if diagonal <= 0.0 {
        return 0.0;
    }
    let step = std::f64::consts::PI / SAMPLES as Real;
    let (ny, nz) = (SAMPLES + 1, if dim == 3 { SAMPLES + 1 } else { 1 });
    let mut most: Real = 0.0;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..=SAMPLES {
                let t = [i as Real * step, j as Real * step, k as Real * step];
                let mut w = [0.0; 3];
                for (p, v) in &g {
                    let sn = (t[0] * p[0] + t[1] * p[1] + t[2] * p[2]).sin();
                    for a in 0..3 {
                        w[a] += v[a] * sn;
                    }
                }
                most = most.max(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
            }
        }
    }
    most / diagonal
}

/// ω for a fluid of dimension `dim`, `kernel` and h/Δx = `smoothing` (module doc): in (0, 1],
/// exactly 1 for the 2D cubic spline at h = 1.3 Δx and any narrower neighbourhood.
pub fn relaxation(dim: usize, kernel: KernelKind, smoothing: Real) -> Real {
    let reference = ratio(2, KernelKind::CubicSpline, REFERENCE_SMOOTHING);
    let own = ratio(dim, kernel, smoothing);
    if own <= reference {
        1.0
    } else {
        reference / own
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ratios of the module doc (an independent numpy scan of 65 points an axis gave 2.880,
    /// 4.906, 6.703, 17.61 for the cubic spline; 2.603, 4.201 for Wendland C2), and ω.
    #[test]
    fn the_lattice_ratio_and_the_relaxation() {
        let c = KernelKind::CubicSpline;
        for (dim, s, want) in [(2, 1.3, 2.880), (3, 1.3, 4.906), (2, 2.0, 6.703), (3, 2.0, 17.61)] {
            let r = ratio(dim, c, s);
            assert!((r / want - 1.0).abs() < 6e-3, "{dim}D s = {s}: {r} against {want}");
        }
        for (dim, want) in [(2, 2.603), (3, 4.201)] {
            let r = ratio(dim, KernelKind::WendlandC2, 1.3);
            assert!((r / want - 1.0).abs() < 6e-3, "Wendland {dim}D: {r} against {want}");
        }
        assert_eq!(relaxation(2, c, 1.3), 1.0);
        assert_eq!(relaxation(2, c, 1.0), 1.0);
        // 3D's default h = 1.0 Δx: a ratio under the reference (numpy: 2.815), so unrelaxed.
        assert!((ratio(3, c, 1.0) / 2.815 - 1.0).abs() < 6e-3, "3D s = 1.0: {}", ratio(3, c, 1.0));
        assert_eq!(relaxation(3, c, 1.0), 1.0);
        assert_eq!(relaxation(2, KernelKind::WendlandC2, 1.3), 1.0);
        let w3 = relaxation(3, c, 1.3);
        assert!((0.57..0.60).contains(&w3), "3D at 1.3: {w3}");
        // Wider neighbourhoods relax more, and ω ratio never exceeds the reference's.
        let mut last = 1.0;
        for s in [1.3, 1.5, 1.75, 2.0, 3.0] {
            let w = relaxation(3, c, s);
            assert!(w < last && w > 0.0, "s = {s}: {w} after {last}");
            assert!(w * ratio(3, c, s) <= ratio(2, c, 1.3) * (1.0 + 1e-12));
            last = w;
        }
    }
}
