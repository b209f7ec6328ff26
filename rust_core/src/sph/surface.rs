//! Surface tension and adhesion of Akinci, Akinci & Teschner, "Versatile surface tension and
//! adhesion for SPH fluids", ACM TOG 32(6) 182 (SIGGRAPH Asia 2013): the kernels and the map
//! from a physical surface tension σ to the model's coefficients.
//!
//! With H = 2h the support radius, the model's accelerations of fluid particle i are
//!
//!   a_i = −γ Σ_j K_ij [m_j C(r_ij) x̂_ij + c (n_i − n_j)]   (paper eq. 1, 2, 6: cohesion,
//!                                                            curvature, K_ij = 2ρ0/(ρ_i + ρ_j))
//!       − β Σ_b Ψ_b A(r_ib) x̂_ib                           (paper eq. 7: adhesion to walls)
//!
//! with n_i = H Σ_j m_j/ρ_j ∇W_ij (eq. 4), the cohesion spline C (eq. 2) and the adhesion spline
//! A (eq. 7).
//!
//! Three choices of ours, because the paper's γ and β have no fixed physical meaning:
//! - **σ sets γ** through the Kirkwood–Buff integral of the cohesion force, which for a flat
//!   interface of a fluid of uniform density ρ0 (pair force γ m m' C(r)) gives
//!   σ_c = (π/8) ρ0² γ ∫ C r⁴ dr in 3D and σ_c = (1/3) ρ0² γ ∫ C r³ dr in 2D (Kirkwood & Buff,
//!   J. Chem. Phys. 17, 1949; the 2D form by the same half-space integral), divided by the
//!   measured `laplace_factor` (below): the curvature term adds a surface tension of its own,
//!   which has no closed form. The `adhesion`, in σ's units, is half the work of adhesion W_a
//!   of a fluid half-space on a wall half-space of density ρ0 (Ψ_b / V_b = ρ0), by the same
//!   integral over A: `adhesion = surface_tension` is complete wetting in the continuum
//!   (Young–Dupré: cos θ = W_a/σ − 1 = 2 adhesion/σ − 1; contact angles not validated).
//! - **The curvature term is scaled by c = ρ0 / (1000 kg/m^d).** Eq. 6 adds an acceleration
//!   γ (n_i − n_j) (units of γ: m/s²) to eq. 1's γ m_j C (units of γ: m^(d+1)/(kg s²)): the paper
//!   is not dimensionally consistent, and its balance of the two terms is that of water in SI
//!   units. Scaling by ρ0 / 1000 keeps that balance in any unit system.
//!
//! - **The Laplace factor: 2.3 in 2D, 3.4 in 3D at h = 1.3 Δx, 2.9 in 3D at h = 1.0 Δx**
//!   (`laplace_factor`), measured: the mechanical pressure at the centre
//!   of droplets at rest (the solvers' pressure plus the surface forces' virial,
//!   `Dfsph::surface_acceleration`, averaged over every step from 4 to 10 capillary times), with
//!   γ from σ_c alone, read Δp R/σ ≈ 2.5–5.3 for 2D droplets of R = 3–12 H (H = 2h,
//!   h = 1.3 Δx). With 2.3 in both dimensions, at σ = 0.03 N, ρ0 = 800, Δx = 0.5 mm (the factor
//!   was first measured at σ = 0.072 N, ρ0 = 1000, Δx = 1 mm), 2D droplets started 1e-9 m apart
//!   read σ/R × 1.60 on average at R = 3.1 H (6 droplets), 1.18 at 4.6 H (16), 1.06 at 6.2 H
//!   (13, each 0.66–1.34) and 0.84–1.11 at 8.5 H (4): small droplets read high, large ones
//!   about right. 3D droplets read 2σ/R × 1.64 and 1.65 at R = 2.9 H, 1.50 at 3.7 H and 1.46
//!   at 5.6 H: not the 2D trend to 1, so 3D has its own factor, 2.3 × 1.46 ≈ 3.4. At
//!   h = 1.0 Δx (3D DFSPH's default since 2026-12-01) the same droplets read 2σ/R × 0.675 at
//!   R = 2.8 H, 0.737 and 0.664 at 3.8 H (two droplets), 0.859 at 5.5 H and 0.845 at 7.5 H with
//!   3.4, so 3D takes 3.4 × 0.85 ≈ 2.9 there, linear in h/Δx between the two. One
//!   droplet scatters because the reading is the small difference of the solvers' pressure and
//!   the virial, each 30 to 70 times σ/R (the cohesion's bulk tension), and each droplet
//!   freezes into its own packing (with the solves at 0.001 % the step-to-step noise falls to
//!   0.2 σ/R; the scatter stays). With the curvature term off, the cohesion alone read about 1
//!   on average, scattered from 0.1 to 2.1. The model is a visual one, not a tensiometer.
use crate::vector::Real;
use std::f64::consts::PI;

/// The reference density of the curvature term's scale c = ρ0 / `CURVATURE_RHO`, kg/m^d (module doc).
pub const CURVATURE_RHO: Real = 1000.0;

/// Surface tension of the whole model over its cohesion's σ_c, measured (module doc): 2D at
/// h = 1.3 Δx.
pub const LAPLACE_FACTOR_2D: Real = 2.3;

/// The same in 3D, measured at two smoothings (h/Δx, factor): 1.0 (3D DFSPH's default) and 1.3.
pub const LAPLACE_FACTOR_3D: [(Real, Real); 2] = [(1.0, 2.9), (1.3, 3.4)];

/// The `LAPLACE_FACTOR` of a dimension (2 or 3) and smoothing h/Δx: in 3D linear between the two
/// measured smoothings and held at the nearer one outside them; in 2D the one measured value.
pub fn laplace_factor(dim: usize, smoothing: Real) -> Real {
    if dim != 3 {
        return LAPLACE_FACTOR_2D;
    }
    let [(s0, f0), (s1, f1)] = LAPLACE_FACTOR_3D;
    let t = ((smoothing - s0) / (s1 - s0)).clamp(0.0, 1.0);
    f0 + t * (f1 - f0)
}

/// Akinci's cohesion spline without its normalisation: (H − r)³ r³ for H/2 < r ≤ H,
/// 2 (H − r)³ r³ − H⁶/64 for 0 < r ≤ H/2, 0 beyond H. Negative at short range (repulsion).
#[inline(always)]
fn cohesion_shape(r: Real, big_h: Real) -> Real {
    let a = (big_h - r).max(0.0);
    let b = a * a * a * r * r * r;
    if 2.0 * r > big_h {
        b
    } else {
        2.0 * b - big_h.powi(6) / 64.0
    }
}

/// Normalisation of C: 32/(π H⁹) in 3D (paper eq. 2); in 2D k₂/H⁸ with k₂ chosen so that ∫ C dA
/// equals the 3D ∫ C dV = 79/336 (k₂ = 79·35840/(336·209 π): ∫ shape dA = 209π/35840 at H = 1).
fn cohesion_norm(big_h: Real, dim: usize) -> Real {
    if dim == 3 {
        32.0 / (PI * big_h.powi(9))
    } else {
        79.0 * 35840.0 / (336.0 * 209.0 * PI) / big_h.powi(8)
    }
}

/// The paper's adhesion spline A(r) = 0.007/H^3.25 (−4r²/H + 6r − 2H)^¼ for H/2 < r ≤ H, else 0.
#[inline(always)]
pub fn adhesion_kernel(r: Real, big_h: Real) -> Real {
    if 2.0 * r > big_h && r <= big_h {
        let s = (-4.0 * r * r / big_h + 6.0 * r - 2.0 * big_h).max(0.0);
        0.007 / big_h.powf(3.25) * s.sqrt().sqrt()
    } else {
        0.0
    }
}

/// ∫₀^H f(r) r^p dr by the midpoint rule, 4096 panels each side of H/2 (the splines' joint):
/// relative error below 1e-7 for the cohesion's polynomials, 7e-6 for the adhesion spline (its
/// quarter root at the ends).
fn moment(f: impl Fn(Real) -> Real, big_h: Real, p: i32) -> Real {
    let n = 4096;
    let half = 0.5 * big_h;
    let dr = half / n as Real;
    (0..2 * n).map(|k| (k as Real + 0.5) * dr).map(|r| f(r) * r.powi(p)).sum::<Real>() * dr
}

/// The Kirkwood–Buff factor: σ per unit pair-force coefficient and ρ0², from the force spline f.
fn kirkwood_buff(f: impl Fn(Real) -> Real, big_h: Real, dim: usize) -> Real {
    if dim == 3 {
        PI / 8.0 * moment(f, big_h, 4)
    } else {
        moment(f, big_h, 3) / 3.0
    }
}

/// The model of one fluid: coefficients and kernels (module doc).
#[derive(Clone, Copy, Debug, Default)]
pub struct Surface {
    /// Support radius H = 2h, m.
    pub big_h: Real,
    /// Cohesion normalisation (C = norm · shape); the device's DFSPH takes it as a parameter.
    pub(crate) norm: Real,
    /// γ, m^(d+1)/(kg s²) (0: no surface tension).
    pub gamma: Real,
    /// c = ρ0 / `CURVATURE_RHO`: the curvature term's weight against the cohesion's.
    pub c: Real,
    /// β, m⁴/(kg s²) in 2D and 3D (A is 1/m³ in both) (0: no adhesion).
    pub beta: Real,
}

impl Surface {
    /// `sigma`: surface tension (N/m in 3D, N in 2D); `adhesion`: half the work of adhesion on
    /// the walls, same units; `h`: smoothing length; `rho0`: rest density; `smoothing`: h/Δx
    /// (`laplace_factor`).
    pub fn new(sigma: Real, adhesion: Real, h: Real, rho0: Real, dim: usize, smoothing: Real) -> Self {
        let big_h = 2.0 * h;
        let norm = cohesion_norm(big_h, dim);
        let unit_sigma = rho0 * rho0 * kirkwood_buff(|r| norm * cohesion_shape(r, big_h), big_h, dim);
        let unit_adhesion = rho0 * rho0 * kirkwood_buff(|r| adhesion_kernel(r, big_h), big_h, dim);
        let gamma = if sigma > 0.0 { sigma / (laplace_factor(dim, smoothing) * unit_sigma) } else { 0.0 };
        let beta = if adhesion > 0.0 { adhesion / unit_adhesion } else { 0.0 };
        Self { big_h, norm, gamma, c: rho0 / CURVATURE_RHO, beta }
    }

    pub fn tension(&self) -> bool {
        self.gamma > 0.0
    }

    pub fn adhesion(&self) -> bool {
        self.beta > 0.0
    }

    /// C(r), 1/m^d (paper eq. 2, with the 2D normalisation above).
    #[inline(always)]
    pub fn cohesion(&self, r: Real) -> Real {
        if r < self.big_h {
            self.norm * cohesion_shape(r, self.big_h)
        } else {
            0.0
        }
    }

    /// The capillary time step limit 0.25 √(ρ0 h³ / (2π σ)) (Brackbill, Kothe & Zemach,
    /// J. Comput. Phys. 100 (1992) 335, eq. 61; Morris, Int. J. Numer. Meth. Fluids 33 (2000),
    /// eq. 46), s; infinite without surface tension.
    pub fn max_dt(sigma: Real, adhesion: Real, rho0: Real, h: Real) -> Real {
        let s = sigma.max(adhesion);
        if s > 0.0 {
            // h³ by `pow`, as the facade computed the limit at rest before the core owned it.
            0.25 * (rho0 * h.powf(3.0) / (2.0 * PI * s)).sqrt()
        } else {
            Real::INFINITY
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_kirkwood_buff_maps_match_their_closed_forms() {
        // 3D: σ = (π/8) ρ0² γ (32/(π H⁹)) ∫ shape r⁴ dr = (π/8)(32/π)(21/28160) ρ0² γ H².
        let (h, rho0) = (0.37, 998.0);
        let s = Surface::new(0.072, 0.0, h, rho0, 3, 1.3);
        let big_h = 2.0 * h;
        let want = 0.072 / (4.0 * 21.0 / 28160.0 * rho0 * rho0 * big_h * big_h) / 3.4;
        assert!((s.gamma / want - 1.0).abs() < 1e-6, "{} {}", s.gamma, want);
        // 2D: σ = (1/3) ρ0² γ k₂ (33/28672) H².
        let s = Surface::new(0.072, 0.0, h, rho0, 2, 1.3);
        let k2 = 79.0 * 35840.0 / (336.0 * 209.0 * PI);
        let want = 0.072 / (k2 * 33.0 / 28672.0 / 3.0 * rho0 * rho0 * big_h * big_h) / 2.3;
        assert!((s.gamma / want - 1.0).abs() < 1e-6, "{} {}", s.gamma, want);
        assert_eq!(s.beta, 0.0);
    }

    #[test]
    fn the_laplace_factor_is_the_measured_one_at_each_measured_smoothing() {
        assert_eq!(laplace_factor(2, 1.3), 2.3);
        assert_eq!(laplace_factor(2, 1.0), 2.3);
        assert_eq!(laplace_factor(3, 1.3), 3.4);
        assert_eq!(laplace_factor(3, 1.0), 2.9);
        assert_eq!(laplace_factor(3, 0.5), 2.9);
        assert_eq!(laplace_factor(3, 2.0), 3.4);
        assert!((laplace_factor(3, 1.15) - 3.15).abs() < 1e-12);
        // γ scales as 1/factor: a 3D fluid at h = 1.0 Δx pulls 3.4/2.9 times harder than the
        // 1.3 factor would make it (module doc: its droplets read 0.85 of 2σ/R with 3.4).
        let (a, b) = (Surface::new(0.072, 0.0, 0.01, 1000.0, 3, 1.0), Surface::new(0.072, 0.0, 0.01, 1000.0, 3, 1.3));
        assert!((a.gamma / b.gamma - 3.4 / 2.9).abs() < 1e-12);
    }

    #[test]
    fn the_cohesion_spline_is_continuous_and_repels_at_short_range() {
        let s = Surface::new(1.0, 0.0, 0.5, 1.0, 3, 1.3);
        let hh = s.big_h;
        assert!(s.cohesion(0.01 * hh) < 0.0);
        assert!(s.cohesion(0.75 * hh) > 0.0);
        assert_eq!(s.cohesion(hh), 0.0);
        let (a, b) = (s.cohesion(0.5 * hh * (1.0 - 1e-9)), s.cohesion(0.5 * hh * (1.0 + 1e-9)));
        assert!((a - b).abs() < 1e-6 * b.abs(), "{a} {b}");
        assert_eq!(adhesion_kernel(0.4 * hh, hh), 0.0);
        assert!(adhesion_kernel(0.75 * hh, hh) > 0.0);
    }
}
