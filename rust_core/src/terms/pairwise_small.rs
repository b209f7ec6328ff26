//! The pairwise sum of few bodies (N ≤ [`SMALL`], float64): written once over a [`Lane`], so
//! that one scene's force evaluation (a `Lane` of one `f64`) and the batch's fused kernel
//! (`crate::batch`: one SIMD lane per member) run the very same IEEE operations.
//!
//! S_i = Σ_{j≠i} w_j d_ij / (|d_ij|² + ε²)^{3/2},   d_ij = x_j − x_i
//! (the kernel of `super::pairwise_gravity`: Plummer-softened inverse square, Aarseth 2003,
//! eq. 2.4), each unordered pair once: 1/(r²√r²) is computed for i < j and used by both
//! receivers; each receiver still adds its sources in ascending order.
//!
//! Why not the SIMD direct sum there: below a vector's worth of sources it pads to 16 and sums
//! lanes in a level-dependent order, and its 1/√ is a level's estimate. Here every operation is
//! `+ − × ÷ √`, correctly rounded on every SIMD level and CPU, and none is fused: a few bodies
//! give the same bits at every level (docs/reproducibility.md), and a batch of many small
//! problems can put one member in each SIMD lane and still give each member its bits alone.
use std::ops::{Add, Div, Mul, Sub};

/// Bodies up to which `Pairwise` sums this way (float64 state).
pub const SMALL: usize = 16;

/// A float64, or a SIMD vector of float64 lanes (one member per lane): the operations of the
/// small sum, each correctly rounded lane by lane.
pub trait Lane: Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> {
    /// The correctly rounded square root.
    fn sqrt(self) -> Self;
    /// `a` where `self > 0`, else `b` (NaN: `b`).
    fn if_positive(self, a: Self, b: Self) -> Self;
}

impl Lane for f64 {
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn if_positive(self, a: Self, b: Self) -> Self {
        if self > 0.0 {
            a
        } else {
            b
        }
    }
}

impl<S: crate::simd::Simd> Lane for crate::simd::P<S, f64> {
    #[inline(always)]
    fn sqrt(self) -> Self {
        crate::simd::P::sqrt(self)
    }
    #[inline(always)]
    fn if_positive(self, a: Self, b: Self) -> Self {
        crate::simd::P::if_positive(self, a, b)
    }
}

/// `out[i] = S_i` (module docs) for the `x.len()` bodies at `x` (components `dim`, 2 or 3; a
/// 2D body's third component is ignored) with source weights `w`, ε² = `eps2`; `zero` and
/// `one` are 0 and 1 as `L`. Coincident points without softening (r² = 0) exert nothing.
#[inline(always)]
pub fn small_sum<L: Lane>(x: &[[L; 3]], w: &[L], eps2: L, dim: usize, zero: L, one: L, out: &mut [[L; 3]]) {
    let n = x.len();
    for o in out.iter_mut() {
        *o = [zero; 3];
    }
    for i in 0..n {
        for j in i + 1..n {
            let mut d = [zero; 3];
            let mut r2 = zero;
            for c in 0..dim {
                d[c] = x[j][c] - x[i][c];
                r2 = if c == 0 { d[c] * d[c] } else { r2 + d[c] * d[c] };
            }
            r2 = r2 + eps2;
            // 1/(r² √r²): one square root and one division for both receivers.
            let inv3 = r2.if_positive(one / (r2 * r2.sqrt()), zero);
            let (wi, wj) = (w[j] * inv3, w[i] * inv3);
            // Receiver j's term w_i (x_i − x_j)/r³ is −w_i d/r³: subtracted (x − y ≡ x + (−y)).
            for c in 0..dim {
                out[i][c] = out[i][c] + wi * d[c];
                out[j][c] = out[j][c] - wj * d[c];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the textbook sum (per receiver over all sources, exact to round-off), 2D and 3D,
    /// with and without softening, a coincident pair exerting nothing.
    #[test]
    fn matches_the_naive_sum() {
        let x: Vec<[f64; 3]> =
            (0..7).map(|k| [(k as f64 * 1.3).sin(), (k as f64 * 0.7).cos(), 0.1 * k as f64]).collect();
        let w: Vec<f64> = (0..7).map(|k| 1.0 + 0.25 * k as f64).collect();
        for (dim, eps2) in [(2, 0.0), (3, 0.0), (3, 1e-2)] {
            let mut out = vec![[0.0; 3]; 7];
            small_sum(&x, &w, eps2, dim, 0.0, 1.0, &mut out);
            for i in 0..7 {
                let mut s = [0.0; 3];
                for j in (0..7).filter(|&j| j != i) {
                    let d: Vec<f64> = (0..dim).map(|c| x[j][c] - x[i][c]).collect();
                    let r2: f64 = d.iter().map(|a| a * a).sum::<f64>() + eps2;
                    for c in 0..dim {
                        s[c] += w[j] * d[c] / r2.powf(1.5);
                    }
                }
                for c in 0..dim {
                    assert!((out[i][c] - s[c]).abs() <= 1e-14 * s[c].abs().max(1.0), "{dim} {i} {c}");
                }
                if dim == 2 {
                    assert_eq!(out[i][2], 0.0);
                }
            }
        }
        let mut out = vec![[0.0; 3]; 2];
        small_sum(&[[1.0, 2.0, 0.0], [1.0, 2.0, 0.0]], &[1.0, 1.0], 0.0, 2, 0.0, 1.0, &mut out);
        assert_eq!(out, vec![[0.0; 3]; 2]);
    }

    /// Newton's third law holds exactly for equal weights: each pair's two terms are negatives.
    #[test]
    fn equal_and_opposite_for_two_bodies() {
        let mut out = vec![[0.0; 3]; 2];
        small_sum(&[[0.3, -1.1, 0.2], [-0.7, 0.4, 2.0]], &[2.0, 2.0], 1e-3, 3, 0.0, 1.0, &mut out);
        for c in 0..3 {
            assert_eq!(out[0][c], -out[1][c]);
        }
    }
}
