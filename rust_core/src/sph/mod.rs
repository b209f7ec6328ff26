//! Weakly compressible SPH (WCSPH) as one force term.
//!
//! Density by summation, ρ_i = Σ_j m_j W_ij + Σ_b Ψ_b W_ib (self included; b runs over static wall
//! particles of "mass" Ψ_b = ρ0 V_b, Akinci et al. 2012, eq. 4–5). Tait equation of state,
//! p = B[(ρ/ρ0)^γ − 1], B = ρ0 c0²/γ (Monaghan 1994; Becker & Teschner 2007, eq. 6), optionally
//! clamped to p ≥ 0. Symmetric, momentum-conserving pressure force with Monaghan (1992) artificial
//! viscosity:
//!
//!   dv_i/dt = −Σ_j m_j (p_i/ρ_i² + p_j/ρ_j² + Π_ij) ∇_i W_ij − Σ_b Ψ_b (p_i/ρ_i²) ∇_i W_ib,
//!   Π_ij = −α c0 μ_ij / ρ̄_ij,  μ_ij = h v_ij·r_ij / (r_ij² + 0.01 h²) if v_ij·r_ij < 0, else 0.
//!
//! The wall term is Akinci et al. (2012), eq. 10 (free slip: no wall viscosity, so fluid cannot
//! stick). With summation density the pressure part is exactly the gradient of the internal
//! energy U = Σ_i m_i u(ρ_i), u' = p/ρ² (the SPH Lagrangian, Price 2012, §3.2), so `potential`
//! books U and the energy books balance: the viscosity dissipates
//! P = ½ Σ_ij m_i m_j Π_ij v_ij·∇_i W_ij ≥ 0 (Monaghan 1992, §4).
//!
//! Each evaluation counting-sorts the fluid into cells (`crate::neighbors`), gathers positions and
//! velocities into cell order (structure of arrays, f32 or f64), and runs two passes, density then
//! forces, over contiguous candidate runs, 8 or 16 pairs at a time (SIMD lanes). Forces are
//! gathered per particle: no atomics, bit-identical for any thread count.
//!
//! Several fluids of one system with the same h, kernel and precision share that evaluation (a
//! group, found through `neighbors::Shared`): one cell list and one pass pair over all their
//! particles, so they push on each other, each particle with its own fluid's equation of state,
//! viscosity and walls. Mixing: summation density over all fluids (smeared across a density
//! jump); pair viscosity with the mean of the two fluids' α c0.
//!
//! Layout, one concept a file:
//! - `params`: `SphParams` (and `KernelKind`, `Precision`): validation, the Tait equation of
//!   state p(ρ) and the internal energy u(ρ).
//! - `kernels`: the smoothing kernels W and their gradients, scalar and on SIMD vectors.
//! - `buffers`: the static walls sorted into cells, and the padded structure-of-arrays buffers
//!   the passes read (the gather into cell order, reservation), one set per precision.
//! - `passes`: the density and force passes (SIMD, parallel over chunks of sorted particles).
//! - `group`: `Group`, the fluids that share one search, and one evaluation of them (cell list,
//!   gather, passes), written once for both pass precisions.
//! - `dfsph`: `Dfsph`, the divergence-free (incompressible) fluid, registered as "dfsph": its
//!   pressure comes from two velocity projections per step, not from an equation of state.
//! - `surface`: Akinci et al. (2013) surface tension and adhesion (kernels, σ → coefficients),
//!   used by `dfsph`.
//! - `fluid`: `Sph`, the force term itself (one fluid): construction, joining a group, the
//!   `Term` implementation (its share of the forces, its own books and fields), and its
//!   registration as "sph".
pub mod kernels;

mod buffers;
pub(crate) mod dfsph;
mod fluid;
mod group;
mod params;
mod passes;
pub mod resolve;
pub mod surface;

pub use dfsph::{Dfsph, DfsphParams};
pub use fluid::Sph;
pub use params::{KernelKind, Precision, SphParams};
#[cfg(all(test, feature = "gpu"))]
mod device_tests;
#[cfg(all(test, feature = "gpu"))]
mod dfsph_device_tests;
