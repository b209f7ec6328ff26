//! The fluid's parameters (`SphParams`: smoothing length, rest density, sound speed, Tait γ,
//! viscosity, pressure clamp, kernel, precision), their validation, and the quantities derived
//! from them: the Tait stiffness B, the equation of state p(ρ) and the specific internal energy
//! u(ρ) that `potential` books.
use crate::error::{invalid, Result};
use crate::vector::Real;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KernelKind {
    CubicSpline,
    WendlandC2,
}

impl KernelKind {
    pub fn by_name(s: &str) -> Result<Self> {
        match s {
            "cubic_spline" => Ok(Self::CubicSpline),
            "wendland_c2" => Ok(Self::WendlandC2),
            o => Err(invalid("kernel", format!("unknown kernel {o:?}; valid: cubic_spline, wendland_c2"))),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    F32,
    F64,
}

impl Precision {
    pub fn by_name(s: &str) -> Result<Self> {
        match s {
            "f32" | "float32" => Ok(Self::F32),
            "f64" | "float64" => Ok(Self::F64),
            o => Err(invalid("precision", format!("unknown precision {o:?}; valid: f32, f64"))),
        }
    }
}

/// Fluid parameters, SI units.
#[derive(Clone, Copy, Debug)]
pub struct SphParams {
    /// Smoothing length h, m (support 2h).
    pub h: Real,
    /// Rest density ρ0, kg/m^dim.
    pub rho0: Real,
    /// Speed of sound c0, m/s.
    pub c0: Real,
    /// Tait exponent γ (integer, 1..=15; water: 7).
    pub gamma: i32,
    /// Monaghan artificial viscosity α (≥ 0).
    pub alpha: Real,
    /// Clamp the pressure to p ≥ 0 (no tension at the free surface).
    pub clamp: bool,
    pub kernel: KernelKind,
    pub precision: Precision,
}

/// `Ok` if `v` is finite and > 0, else the error naming argument `arg`.
pub(super) fn positive(v: Real, arg: &'static str) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(arg, format!("{v} must be finite and > 0")))
    }
}

impl SphParams {
    pub fn validate(&self) -> Result<()> {
        let pos = positive;
        pos(self.h, "h")?;
        pos(self.rho0, "density")?;
        pos(self.c0, "sound_speed")?;
        if !(1..=15).contains(&self.gamma) {
            return Err(invalid("gamma", format!("{} must be an integer in 1..=15", self.gamma)));
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(invalid("viscosity", format!("{} must be finite and >= 0", self.alpha)));
        }
        Ok(())
    }
    /// Tait stiffness B = ρ0 c0² / γ, Pa.
    pub fn b(&self) -> Real {
        self.rho0 * self.c0 * self.c0 / self.gamma as Real
    }
    /// Pressure (Pa) at density `rho`.
    pub fn pressure(&self, rho: Real) -> Real {
        let p = self.b() * ((rho / self.rho0).powi(self.gamma) - 1.0);
        if self.clamp {
            p.max(0.0)
        } else {
            p
        }
    }
    /// Specific internal energy u(ρ) = ∫_{ρ0}^{ρ} p/ρ'² dρ', J/kg (zero at rest density, ≥ 0).
    pub fn internal_energy(&self, rho: Real) -> Real {
        let s = rho / self.rho0;
        if self.clamp && s <= 1.0 {
            return 0.0;
        }
        let g = self.gamma as Real;
        let b = self.b() / self.rho0;
        if self.gamma == 1 {
            b * (s.ln() + 1.0 / s - 1.0)
        } else {
            b * (s.powi(self.gamma - 1) / (g - 1.0) + 1.0 / s - g / (g - 1.0))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn internal_energy_is_the_integral_of_p_over_rho_squared() {
        let p = SphParams {
            h: 0.01,
            rho0: 1000.0,
            c0: 30.0,
            gamma: 7,
            alpha: 0.0,
            clamp: false,
            kernel: KernelKind::CubicSpline,
            precision: Precision::F64,
        };
        for &rho in &[950.0, 1000.0, 1013.0, 1100.0] {
            let e = 1e-3;
            let du = (p.internal_energy(rho + e) - p.internal_energy(rho - e)) / (2.0 * e);
            let want = p.pressure(rho) / (rho * rho);
            assert!((du - want).abs() <= 1e-6 * want.abs().max(1e-3), "u'({rho}) = {du}, p/rho^2 = {want}");
        }
        assert_eq!(p.internal_energy(1000.0), 0.0);
        assert!(p.internal_energy(990.0) > 0.0 && p.internal_energy(1010.0) > 0.0);
    }
}
