//! Potential fields fixed in space: point sources (masses or charges), a harmonic trap, and a
//! potential sampled on a regular grid. Each is a conservative term with its potential in the
//! energy books, evaluated per particle in fixed chunks (bit-identical for any thread count).
//! Pinned particles feel nothing and hold no potential energy, as with the other fields.
pub mod grid_potential;
pub mod harmonic_trap;
pub mod point_sources;

use super::registry::Params;
use super::Write;
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

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

/// Stores `coupling`'s force on every free particle with a nonzero coupling constant c_i (mass
/// or charge) in `f` as `write` says: c_i · `per_unit(x_i)`, the force per unit of c at x_i;
/// zero elsewhere. Shared by the fixed fields, which differ only in `per_unit`.
pub(crate) fn coupled_forces<V: Vector>(
    coupling: Coupling,
    x: &[V],
    model: &Model,
    f: &mut [V],
    write: Write,
    per_unit: impl Fn(V) -> V + Sync + Send,
) {
    let c = coupling.of(model);
    par::chunks1(f, |s, f| {
        for (k, fi) in f.iter_mut().enumerate() {
            let i = s + k;
            let fe = match c {
                Some(c) if model.inv_mass[i] != 0.0 && c[i] != 0.0 => per_unit(x[i]) * c[i],
                _ => V::ZERO,
            };
            write.put(fi, fe);
        }
    });
}

/// Σ c_i `phi(x_i)` over free particles with a nonzero coupling constant (J): the potential
/// energy of a fixed field whose potential per unit of c is `phi`. 0 when the scene lacks the
/// coupled attribute (a charge field in an uncharged scene).
pub(crate) fn coupled_potential<V: Vector>(
    coupling: Coupling,
    x: &[V],
    model: &Model,
    phi: impl Fn(V) -> Real + Sync + Send,
) -> Real {
    let Some(c) = coupling.of(model) else {
        return 0.0;
    };
    par::sum(x.len(), 0.0, |r| {
        let mut u = 0.0;
        for i in r {
            if model.inv_mass[i] != 0.0 && c[i] != 0.0 {
                u += c[i] * phi(x[i]);
            }
        }
        u
    })
}
