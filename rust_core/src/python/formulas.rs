//! The core's formulas that the facade shows before a scene holds the part: a fluid's resolution
//! (`crate::sph::resolve`), a grid's step limits (`crate::grids::build::limits`) and the
//! part–integrator rules (`crate::terms::registry::check_integrator`). Python computes none of
//! these; it passes the record's numbers and shows the values and messages that come back.
use super::convert::*;
use super::errors::*;
use crate::error::invalid;
use crate::sph::resolve::{self, AtRest, WallVolume};
use crate::sph::KernelKind;
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn kernel_of(name: &str) -> PyResult<KernelKind> {
    KernelKind::by_name(name).map_err(err)
}

fn dim_of(dim: usize) -> PyResult<usize> {
    if (2..=3).contains(&dim) {
        Ok(dim)
    } else {
        Err(err(invalid("dim", format!("must be 2 or 3, got {dim}"))))
    }
}

/// The smoothing kernel W(q h) (1/m^dim) at each q = r/h of `q` ((N,) float64, finite, ≥ 0).
#[pyfunction]
pub(super) fn sph_kernel<'py>(
    py: Python<'py>,
    q: PyReadonlyArray1<'py, f64>,
    h: f64,
    dim: usize,
    kernel: &str,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let w = resolve::kernel_values(slice1(&q, "q")?, h, dim_of(dim)?, kernel_of(kernel)?).map_err(err)?;
    Ok(w.into_pyarray(py))
}

/// Σ_j W(x_i − x_j) over an infinite cubic lattice of `spacing` (1/m^dim).
#[pyfunction]
pub(super) fn sph_lattice_sum(spacing: f64, h: f64, dim: usize, kernel: &str) -> PyResult<f64> {
    resolve::lattice_density_sum(spacing, h, dim_of(dim)?, kernel_of(kernel)?).map_err(err)
}

/// The fluid particle's mass ρ0 / Σ_j W over its lattice (kg), `resolve::particle_mass`.
#[pyfunction]
pub(super) fn sph_particle_mass(density: f64, spacing: f64, h: f64, dim: usize, kernel: &str) -> PyResult<f64> {
    resolve::particle_mass(density, spacing, h, dim_of(dim)?, kernel_of(kernel)?).map_err(err)
}

/// Ψ_b = ρ0 V_b of each wall particle of `walls` ((M, dim) float64), kg: `volume` is
/// "akinci" (sampled), "lattice" (Ψ_b = `mass`) or "given" (V_b from `given`, (M,) m^dim).
#[pyfunction]
#[pyo3(signature = (walls, density, h, kernel, volume, mass, given=None))]
#[allow(clippy::too_many_arguments)]
pub(super) fn sph_wall_psi<'py>(
    py: Python<'py>,
    walls: PyReadonlyArray2<'py, f64>,
    density: f64,
    h: f64,
    kernel: &str,
    volume: &str,
    mass: f64,
    given: Option<PyReadonlyArray1<'py, f64>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let dim = dim_of(walls.shape()[1])?;
    let w = flat2(&walls, dim, "walls")?;
    let v = match (volume, &given) {
        ("akinci", _) => WallVolume::Sampled,
        ("lattice", _) => WallVolume::Lattice,
        ("given", Some(g)) => WallVolume::Given(slice1(g, "wall_volume")?),
        _ => return Err(err(invalid("wall_volume", format!("unknown rule {volume:?}; valid: akinci, lattice")))),
    };
    let k = kernel_of(kernel)?;
    let psi = py.detach(|| resolve::wall_psi(w, dim, density, h, k, v, mass)).map_err(err)?;
    Ok(psi.into_pyarray(py))
}

/// The sound speed estimate c0 = 10 v_max (m/s) of a fluid at `positions` ((N, dim)) moving at
/// `velocities` ((N, dim) or None) under the scene's summed `gravity` ((dim,), m/s²);
/// `surface` = max(σ, adhesion).
#[pyfunction]
#[pyo3(signature = (positions, velocities, gravity, spacing, density, h, surface))]
#[allow(clippy::too_many_arguments)]
pub(super) fn sph_sound_speed(
    positions: PyReadonlyArray2<'_, f64>,
    velocities: Option<PyReadonlyArray2<'_, f64>>,
    gravity: PyReadonlyArray1<'_, f64>,
    spacing: f64,
    density: f64,
    h: f64,
    surface: f64,
) -> PyResult<f64> {
    let g = slice1(&gravity, "gravity")?;
    let dim = dim_of(g.len())?;
    let v = match &velocities {
        Some(v) => flat2(v, dim, "velocities")?,
        None => &[],
    };
    let at = AtRest {
        positions: flat2(&positions, dim, "positions")?,
        velocities: v,
        gravity: g,
        spacing,
        density,
        h,
        surface,
    };
    resolve::sound_speed(&at).map_err(err)
}

/// The fluid's step limit at rest, s (`resolve::max_dt_at_rest`); `method` "wcsph" or "dfsph".
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub(super) fn sph_max_dt(
    method: &str,
    dim: usize,
    h: f64,
    sound_speed: f64,
    viscosity: f64,
    density: f64,
    surface_tension: f64,
    adhesion: f64,
) -> PyResult<f64> {
    let dfsph = match method {
        "dfsph" => true,
        "wcsph" => false,
        o => return Err(err(invalid("method", format!("unknown method {o:?}; valid: wcsph, dfsph")))),
    };
    Ok(resolve::max_dt_at_rest(dfsph, dim_of(dim)?, h, sound_speed, viscosity, density, surface_tension, adhesion))
}

/// The step limits of a grid of `kind` built from `params` (what `Simulation.add_grid` takes):
/// a dict name -> s (see `crate::grids::build::limits`).
#[pyfunction]
pub(super) fn grid_limits<'py>(
    py: Python<'py>,
    kind: &str,
    dim: usize,
    params: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let p = params_of(py, "grid_limits", params)?;
    let d = PyDict::new(py);
    for (k, v) in crate::grids::build::limits(kind, dim_of(dim)?, p).map_err(err)? {
        d.set_item(k, v)?;
    }
    Ok(d)
}

/// InvalidInputError (naming the argument) if a part of `kind` cannot be stepped by
/// `integrator`; the core's one table of these rules.
#[pyfunction]
pub(super) fn check_integrator(kind: &str, integrator: &str) -> PyResult<()> {
    crate::terms::registry::check_integrator(kind, integrator).map_err(err)
}
