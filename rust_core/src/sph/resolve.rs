//! A fluid's resolution from its record, before any particle joins a scene: the smoothing
//! kernel's values, the particle mass, the wall particles' Ψ_b, the sound speed estimate and the
//! step limits at rest. The Python facade shows these values and messages; it computes none of
//! them (one formula, one language).
//!
//! - Particle mass m = ρ0 / Σ_j W(x_i − x_j) over an infinite cubic lattice of the particle
//!   spacing: a lattice at rest sits exactly at the rest density (summation density).
//! - Wall particles, Ψ_b = ρ0 V_b (Akinci et al. 2012, "Versatile rigid-fluid coupling for
//!   incompressible SPH", eq. 4–5): V_b = 1/Σ_k W_bk over the wall particles (`Sampled`), the fluid
//!   particle's volume m/ρ0 (`Lattice`), or given.
//! - Sound speed c0 = 10 v_max (Monaghan 1994, §3: Mach 0.1 keeps density within about 1 %),
//!   v_max the largest of the free-fall speed √(2 g H) over the fluid's height H along gravity,
//!   the initial speeds and, with surface tension, the capillary speed √(σ/(ρ0 h)).
//! - Step limits at rest: WCSPH's CFL condition 0.25 h / (c0 (1 + 0.6 α)) (Monaghan 1992, §5);
//!   DFSPH's viscous limit 0.125 h²/ν with ν = α c0 h/(2(d + 2)) (Monaghan 2005, §4.3) and the
//!   capillary limit (`Surface::max_dt`).
//!
//! Bit for bit: the kernel here is σ_d = (1/h^d)·c_d with powers by `pow`, and the lattice sum is
//! summed pairwise in NumPy's order (`pairwise_sum`), which is how the facade computed the mass
//! before the core owned it: fluids made before and after have the same masses, so their scene
//! files and GIFs are unchanged. The solver's kernels (`kernels`) keep their own σ_d form; the
//! two agree to round-off (a Rust test checks it).
use super::params::KernelKind;
use super::surface::Surface;
use crate::error::{invalid, Result};
use crate::vector::Real;
use std::f64::consts::PI;

/// 1/h^dim, or the error naming `h` where h^dim or its inverse leaves float64.
pub fn inv_h_dim(h: Real, dim: usize) -> Result<Real> {
    if !(h.is_finite() && h > 0.0) {
        return Err(invalid("h", format!("{h} must be finite and > 0 (m)")));
    }
    let inv = 1.0 / h.powf(dim as Real);
    if !(inv.is_finite() && inv > 0.0) {
        return Err(invalid("h", format!("{h} m has no h^{dim} and 1/h^{dim} inside float64")));
    }
    Ok(inv)
}

/// W at q = r/h (q ≥ 0, finite), given `inv` = 1/h^dim (`inv_h_dim`), 1/m^dim.
///
/// Cubic spline (Monaghan & Lattanzio 1985, eq. 21): σ (¼(2−q)₊³ − (1−q)₊³), σ₂ = 10/(7π h²),
/// σ₃ = 1/(π h³). Wendland C2 (Wendland 1995; Dehnen & Aly 2012, table 1): σ (1 − q/2)₊⁴ (2q + 1),
/// σ₂ = 7/(4π h²), σ₃ = 21/(16π h³).
pub fn kernel_value(q: Real, inv: Real, dim: usize, kernel: KernelKind) -> Real {
    match kernel {
        KernelKind::CubicSpline => {
            let s = inv * if dim == 2 { 10.0 / (7.0 * PI) } else { 1.0 / PI };
            let a = (2.0 - q).max(0.0);
            let b = (1.0 - q).max(0.0);
            s * (0.25 * a.powf(3.0) - b.powf(3.0))
        }
        KernelKind::WendlandC2 => {
            let s = inv * if dim == 2 { 7.0 / (4.0 * PI) } else { 21.0 / (16.0 * PI) };
            let t = (1.0 - 0.5 * q).max(0.0);
            // t = 0 beyond q = 2: the clamp keeps inf · 0 out of it.
            s * t.powf(4.0) * (2.0 * q.min(2.0) + 1.0)
        }
    }
}

/// `kernel_value` over many q; the error names `q` where one is negative or not finite.
pub fn kernel_values(q: &[Real], h: Real, dim: usize, kernel: KernelKind) -> Result<Vec<Real>> {
    if q.iter().any(|q| !(q.is_finite() && *q >= 0.0)) {
        return Err(invalid("q", "must be finite and >= 0 (r/h)"));
    }
    let inv = inv_h_dim(h, dim)?;
    Ok(q.iter().map(|&q| kernel_value(q, inv, dim, kernel)).collect())
}

/// NumPy's pairwise summation of a contiguous float64 array (`pairwise_sum` in its
/// `loops_utils.h`): blocks of at most 128 summed in 8 interleaved partial sums.
pub fn pairwise_sum(a: &[Real]) -> Real {
    let n = a.len();
    if n < 8 {
        let mut res = 0.0;
        for x in a {
            res += x;
        }
        res
    } else if n <= 128 {
        let mut r = [0.0; 8];
        r.copy_from_slice(&a[..8]);
        let mut i = 8;
        while i < n - n % 8 {
            for k in 0..8 {
                r[k] += a[i + k];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for x in &a[i..] {
            res += x;
        }
        res
    } else {
        let mut n2 = n / 2;
        n2 -= n2 % 8;
        pairwise_sum(&a[..n2]) + pairwise_sum(&a[n2..])
    }
}

/// Σ_j W(x_i − x_j) over an infinite cubic lattice of `spacing` (1/m^dim), the lattice points
/// within the kernel's support 2h (the box of half-width ⌈2h/spacing⌉ + 1 spacings).
pub fn lattice_density_sum(spacing: Real, h: Real, dim: usize, kernel: KernelKind) -> Result<Real> {
    if !(spacing.is_finite() && spacing > 0.0) {
        return Err(invalid("spacing", format!("{spacing} must be finite and > 0 (m)")));
    }
    let inv = inv_h_dim(h, dim)?;
    // The box holds (2k + 3)^dim points; a smoothing length of hundreds of spacings is a mistake.
    let k = (2.0 * h / spacing).ceil();
    if !(k <= 1000.0) {
        return Err(invalid("spacing", format!("{spacing} m is below 1/500 of the smoothing length {h} m")));
    }
    let k = k as i64 + 1;
    let ax: Vec<Real> = (-k..=k).map(|i| i as Real * spacing).collect();
    let q_of = |r2: Real| r2.sqrt() / h;
    let mut w = Vec::with_capacity(ax.len().pow(dim as u32));
    // C order (the first axis slowest), as the facade's meshgrid(indexing="ij") laid it out.
    if dim == 2 {
        for x in &ax {
            for y in &ax {
                w.push(kernel_value(q_of(x * x + y * y), inv, dim, kernel));
            }
        }
    } else {
        for x in &ax {
            for y in &ax {
                for z in &ax {
                    w.push(kernel_value(q_of(x * x + y * y + z * z), inv, dim, kernel));
                }
            }
        }
    }
    Ok(pairwise_sum(&w))
}

/// The fluid particle's mass ρ0 / Σ_j W(x_i − x_j) (`lattice_density_sum`), kg (2D: kg/m): a
/// lattice of the particle spacing at rest then has exactly the rest density.
pub fn particle_mass(density: Real, spacing: Real, h: Real, dim: usize, kernel: KernelKind) -> Result<Real> {
    Ok(density / lattice_density_sum(spacing, h, dim, kernel)?)
}

/// How the wall particles' volumes V_b are found.
pub enum WallVolume<'a> {
    /// V_b = 1 / Σ_k W(x_b − x_k), k over the wall particles, b included (Akinci et al. 2012, eq. 4).
    Sampled,
    /// The fluid particle's volume m/ρ0: Ψ_b = m (walls on the fluid's own lattice).
    Lattice,
    /// Given per wall particle, m^dim.
    Given(&'a [Real]),
}

/// Ψ_b = ρ0 V_b of each wall particle (kg); `walls` is (M, dim) flat, `mass` the fluid particle's.
/// The error names `wall_volume, density` where a Ψ_b is not a finite number > 0.
pub fn wall_psi(
    walls: &[Real],
    dim: usize,
    density: Real,
    h: Real,
    kernel: KernelKind,
    volume: WallVolume<'_>,
    mass: Real,
) -> Result<Vec<Real>> {
    let m = walls.len() / dim;
    let psi: Vec<Real> = match volume {
        _ if m == 0 => Vec::new(),
        WallVolume::Given(v) => {
            if v.len() != m {
                return Err(invalid(
                    "wall_volume",
                    format!("needs one volume per wall particle ({m}), got {}", v.len()),
                ));
            }
            v.iter().map(|v| density * v).collect()
        }
        WallVolume::Lattice => vec![mass; m],
        WallVolume::Sampled => {
            let (i, j) = pairs(walls, dim, 2.0 * h)?;
            let inv = inv_h_dim(h, dim)?;
            let row = |k: i64| &walls[k as usize * dim..(k as usize + 1) * dim];
            // Each pair's kernel, then the per-particle sums in pair order (bincount's order).
            let w: Vec<Real> = i
                .iter()
                .zip(&j)
                .map(|(&a, &b)| {
                    let r2 = row(a).iter().zip(row(b)).map(|(p, q)| (p - q) * (p - q)).fold(0.0, |s, d| s + d);
                    kernel_value(r2.sqrt() / h, inv, dim, kernel)
                })
                .collect();
            let (mut bi, mut bj) = (vec![0.0; m], vec![0.0; m]);
            for ((&a, &b), w) in i.iter().zip(&j).zip(&w) {
                bi[a as usize] += w;
                bj[b as usize] += w;
            }
            let own = kernel_value(0.0, inv, dim, kernel);
            bi.iter().zip(&bj).map(|(a, b)| density / (own + (a + b))).collect()
        }
    };
    if !psi.iter().all(|p| p.is_finite() && *p > 0.0) {
        return Err(invalid(
            "wall_volume, density",
            "density · wall volume is not a finite number > 0 (kg) for every wall particle",
        ));
    }
    Ok(psi)
}

fn pairs(x: &[Real], dim: usize, radius: Real) -> Result<(Vec<i64>, Vec<i64>)> {
    use crate::neighbors::neighbor_pairs;
    use glam::{DVec2, DVec3};
    if x.len() / dim < 2 {
        return Ok((Vec::new(), Vec::new()));
    }
    if dim == 3 {
        neighbor_pairs(&x.chunks_exact(3).map(|p| DVec3::new(p[0], p[1], p[2])).collect::<Vec<_>>(), radius)
    } else {
        neighbor_pairs(&x.chunks_exact(2).map(|p| DVec2::new(p[0], p[1])).collect::<Vec<_>>(), radius)
    }
}

/// The largest row norm of a finite (N, dim) flat array, scaled so that squaring cannot overflow
/// (inf only where the norm itself is beyond float64).
fn max_row_norm(a: &[Real], dim: usize) -> Real {
    let top = a.iter().fold(0.0, |m: Real, x| m.max(x.abs()));
    if top == 0.0 || a.is_empty() {
        return 0.0;
    }
    let m = a.chunks_exact(dim).map(|r| r.iter().fold(0.0, |s, x| s + (x / top) * (x / top))).fold(0.0, Real::max);
    top * m.sqrt()
}

/// What the sound speed estimate reads: the fluid's state and the scene's gravity.
pub struct AtRest<'a> {
    /// (N, dim) flat, m.
    pub positions: &'a [Real],
    /// (N, dim) flat, m/s; empty for a fluid at rest.
    pub velocities: &'a [Real],
    /// The scene's uniform gravity, summed over its gravity terms, m/s².
    pub gravity: &'a [Real],
    pub spacing: Real,
    pub density: Real,
    pub h: Real,
    /// max(surface tension σ, adhesion), N/m (2D: N).
    pub surface: Real,
}

/// The sound speed estimate c0 = 10 v_max, m/s (see the module's notes); the error names what
/// to give where it cannot be estimated or where ρ0 c0² overflows.
pub fn sound_speed(s: &AtRest<'_>) -> Result<Real> {
    let dim = s.gravity.len();
    let gn = max_row_norm(s.gravity, dim);
    let n = s.positions.len() / dim;
    let height = if gn > 0.0 && gn < Real::INFINITY && n > 0 {
        let u: Vec<Real> = s.gravity.iter().map(|g| g / gn).collect();
        let along = s.positions.chunks_exact(dim).map(|p| p.iter().zip(&u).fold(0.0, |a, (x, u)| a + x * u));
        let (lo, hi) = along.fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), y| (lo.min(y), hi.max(y)));
        (hi - lo) + s.spacing
    } else {
        0.0
    };
    let v0 = if n == 0 { 0.0 } else { max_row_norm(s.velocities, dim) };
    let fall = if gn < Real::INFINITY { (2.0 * gn * height).sqrt() } else { Real::INFINITY };
    let mut vmax = fall.max(v0);
    if s.surface > 0.0 {
        vmax = vmax.max((s.surface / (s.density * s.h)).sqrt());
    }
    if !(vmax > 0.0) {
        return Err(invalid(
            "sound_speed",
            "cannot be estimated for a fluid at rest (velocities) without gravity or without positions spread \
             along it; give sound_speed= (m/s)",
        ));
    }
    let c0 = 10.0 * vmax;
    if (c0 * c0 * 1e4).is_finite() && !(s.density * c0 * c0).is_finite() {
        // The estimate would do for any liquid's density (up to 1e4 kg/m³): the density given
        // makes the stiffness overflow (1e308 was refused as sound_speed's).
        return Err(invalid(
            "density",
            format!(
                "{:e} kg/m³ makes the Tait stiffness density · c0² overflow float64 (c0 = 10·v_max = \
                 {c0:.3e} m/s, estimated); give a density of a physical size",
                s.density
            ),
        ));
    }
    if !(c0.is_finite() && (s.density * c0 * c0).is_finite()) {
        let (args, capillary) =
            if s.surface > 0.0 { (", surface_tension, adhesion", " and the capillary speed") } else { ("", "") };
        return Err(invalid(
            &format!("sound_speed{args}"),
            format!(
                "the estimate 10·v_max = {c0:.3e} m/s, from gravity, the height of the positions, the velocities\
                 {capillary}, makes the Tait stiffness density · c0² overflow float64; give sound_speed= (m/s)"
            ),
        ));
    }
    Ok(c0)
}

/// WCSPH's CFL step 0.25 h / (c0 (1 + 0.6 α) + |v|max) (Monaghan 1992, §5, with the viscous
/// term), s.
pub fn wcsph_cfl(h: Real, c0: Real, alpha: Real, vmax: Real) -> Real {
    0.25 * h / (c0 * (1.0 + 0.6 * alpha) + vmax)
}

/// DFSPH's viscous step limit 0.125 h²/ν with Monaghan's ν = α c0 h/(2(d + 2)) (Monaghan 2005,
/// §4.3), s; infinite without viscosity.
pub fn dfsph_viscous(h: Real, dim: usize, alpha: Real, c0: Real) -> Real {
    let visc = alpha * c0;
    if visc > 0.0 {
        0.125 * 2.0 * (dim as Real + 2.0) * h / visc
    } else {
        Real::INFINITY
    }
}

/// The fluid's step limit at rest, s: WCSPH's CFL step; DFSPH's viscous and capillary limits
/// (infinite without either: the flow's speed sets it).
#[allow(clippy::too_many_arguments)]
pub fn max_dt_at_rest(
    dfsph: bool,
    dim: usize,
    h: Real,
    c0: Real,
    alpha: Real,
    density: Real,
    surface_tension: Real,
    adhesion: Real,
) -> Real {
    if dfsph {
        dfsph_viscous(h, dim, alpha, c0).min(Surface::max_dt(surface_tension, adhesion, density, h))
    } else {
        wcsph_cfl(h, c0, alpha, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sph::kernels::{CubicSpline, Kernel, WendlandC2};

    #[test]
    fn pairwise_sum_is_the_sum_to_round_off_at_every_length() {
        for n in [0usize, 1, 7, 8, 9, 127, 128, 129, 1000, 4097] {
            let a: Vec<Real> = (0..n).map(|i| 1.0 / (1.0 + i as Real)).collect();
            let exact: Real = a.iter().rev().sum();
            assert!((pairwise_sum(&a) - exact).abs() <= 1e-14 * exact.max(1.0), "n = {n}");
        }
    }

    #[test]
    fn the_resolution_kernel_is_the_solvers_kernel_to_round_off() {
        for dim in [2, 3] {
            for k in [KernelKind::CubicSpline, KernelKind::WendlandC2] {
                let h = 0.013;
                let inv = inv_h_dim(h, dim).unwrap();
                for i in 0..=40 {
                    let q = i as Real * 0.05;
                    let solver = match k {
                        KernelKind::CubicSpline => CubicSpline::sigma(h, dim) * CubicSpline::w(q),
                        KernelKind::WendlandC2 => WendlandC2::sigma(h, dim) * WendlandC2::w(q),
                    };
                    let here = kernel_value(q, inv, dim, k);
                    assert!((here - solver).abs() <= 1e-13 * solver.abs().max(1.0 / (h * h)), "{dim}D {k:?} q={q}");
                }
            }
        }
    }

    #[test]
    fn a_lattice_at_the_particle_mass_has_the_rest_density() {
        // Away from the edges a lattice of particles of mass ρ0/Σ sums to ρ0 by construction;
        // check the sum against a direct one over a wide box.
        for dim in [2, 3] {
            let (dx, h) = (0.01, 0.013);
            let s = lattice_density_sum(dx, h, dim, KernelKind::CubicSpline).unwrap();
            let inv = inv_h_dim(h, dim).unwrap();
            let mut direct = 0.0;
            let k = 6i64;
            let it = || -k..=k;
            for x in it() {
                for y in it() {
                    for z in if dim == 3 { it() } else { 0..=0 } {
                        let r = ((x * x + y * y + z * z) as Real).sqrt() * dx;
                        direct += kernel_value(r / h, inv, dim, KernelKind::CubicSpline);
                    }
                }
            }
            assert!((s - direct).abs() <= 1e-12 * s, "{dim}D: {s} vs {direct}");
        }
    }

    #[test]
    fn bad_inputs_are_refused_by_name() {
        let e = |r: Result<Real>| r.unwrap_err().to_string();
        assert!(e(lattice_density_sum(0.0, 0.01, 2, KernelKind::CubicSpline)).contains("spacing"));
        assert!(e(lattice_density_sum(1e-9, 0.01, 2, KernelKind::CubicSpline)).contains("spacing"));
        assert!(e(inv_h_dim(1e-200, 2)).contains("h"));
        let still = AtRest {
            positions: &[0.0, 0.0],
            velocities: &[],
            gravity: &[0.0, 0.0],
            spacing: 0.01,
            density: 1000.0,
            h: 0.013,
            surface: 0.0,
        };
        assert!(e(sound_speed(&still)).contains("sound_speed"));
        let psi = wall_psi(&[0.0, 0.0], 2, -1.0, 0.01, KernelKind::CubicSpline, WallVolume::Sampled, 1.0);
        assert!(psi.unwrap_err().to_string().contains("wall_volume"));
    }
}
