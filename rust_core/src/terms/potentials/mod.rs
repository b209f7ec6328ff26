//! Potential fields fixed in space: point sources (masses or charges), a harmonic trap, and a
//! potential sampled on a regular grid. Each is a conservative term with its potential in the
//! energy books, evaluated per particle in fixed chunks (bit-identical for any thread count).
//! Pinned particles feel nothing and hold no potential energy, as with the other fields.
pub mod grid_potential;
pub mod harmonic_trap;
pub mod point_sources;

use super::registry::Params;
use crate::error::{invalid, Result};
use crate::state::Model;
use crate::vector::Real;

pub use grid_potential::GridPotential;
pub use harmonic_trap::HarmonicTrap;
pub use point_sources::PointSources;

/// What a field acts on: the particle's mass (a gravitational potential, J/kg) or its `charge`
/// attribute (an electrostatic potential, V). A scene without charges feels nothing from a
/// field coupled to charge, like `UniformElectricField` (particles added before the attribute
/// is set, or after without a value, hold charge 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coupling {
    Mass,
    Charge,
}

impl Coupling {
    /// Parameter `coupling`: "mass" or "charge".
    pub fn from_params(p: &Params) -> Result<Self> {
        match p.text("coupling")? {
            "mass" => Ok(Coupling::Mass),
            "charge" => Ok(Coupling::Charge),
            other => Err(invalid("coupling", format!("expected \"mass\" or \"charge\", got {other:?}"))),
        }
    }

    /// Each particle's coupling (kg or C); `None` when coupled to charge in a scene without it.
    #[inline]
    pub fn of(self, model: &Model) -> Option<&[Real]> {
        match self {
            Coupling::Mass => Some(&model.mass),
            Coupling::Charge => model.attribute("charge"),
        }
    }

    /// The largest |coupling| / mass over free particles (1/kg·C, or 1 for mass): the factor from
    /// a field's curvature to a squared angular frequency. 0 without any.
    pub fn max_ratio(self, model: &Model) -> Real {
        let Some(c) = self.of(model) else { return 0.0 };
        let mut r: Real = 0.0;
        for i in 0..model.len() {
            if model.inv_mass[i] != 0.0 {
                r = r.max((c[i] * model.inv_mass[i]).abs());
            }
        }
        r
    }
}
