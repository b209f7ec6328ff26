//! Python bindings (the only module that knows pyo3). Arrays cross in bulk; the Python facade
//! (`physcore.Scene`) validates inputs first, and everything is validated again here so the
//! private module is safe to call directly. The GIL is released around stepping.
use crate::integrators;
use crate::world::World;
use glam::{DVec2, DVec3};
use numpy::{IntoPyArray, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

macro_rules! with_sim {
    ($self:expr, $s:ident => $body:expr) => {
        match $self {
            Inner::D2($s) => $body,
            Inner::D3($s) => $body,
        }
    };
}

mod convert;
mod errors;
mod simulation;
mod watch;

use convert::*;
use errors::*;
use simulation::PySimulation;

/// A simulation of either dimension (the core is generic over the vector type).
enum Inner {
    D2(World<DVec2>),
    D3(World<DVec3>),
}

/// All pairs i < j of `points` ((N, 2) or (N, 3) float64, C-contiguous) closer than `radius`:
/// two (M,) int64 arrays, sorted by i then j. OutOfMemoryError (a MemoryError) if the pairs do
/// not fit in memory: they are counted before any is stored.
#[pyfunction]
fn neighbors<'py>(py: Python<'py>, points: PyReadonlyArray2<'py, f64>, radius: f64) -> PyResult<Pairs<'py>> {
    let dim = if points.shape()[1] == 3 { 3 } else { 2 };
    let flat = flat2(&points, dim, "points")?;
    let pool = crate::par::default_pool().ok();
    let r = if dim == 3 {
        let x = try_from_flat::<DVec3>(flat, "neighbors", "points").map_err(|e| to_py(py, e))?;
        py.detach(|| crate::par::install(pool.as_ref(), || crate::neighbors::neighbor_pairs(&x, radius)))
    } else {
        let x = try_from_flat::<DVec2>(flat, "neighbors", "points").map_err(|e| to_py(py, e))?;
        py.detach(|| crate::par::install(pool.as_ref(), || crate::neighbors::neighbor_pairs(&x, radius)))
    };
    let (i, j) = r.map_err(|e| to_py(py, e))?;
    Ok((i.into_pyarray(py), j.into_pyarray(py)))
}

/// Name, order, symplectic flag and force evaluations per step of every integrator.
#[pyfunction]
fn integrator_table<'py>(py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
    integrators::NAMES.iter().map(|n| info_dict(py, integrators::by_name::<DVec2>(n).expect("listed").info())).collect()
}

/// Number of threads of the pool of scenes built with threads=None (1 if it cannot start).
#[pyfunction]
fn default_threads() -> usize {
    crate::par::default_pool().map_or(1, |p| p.current_num_threads())
}

/// The SIMD level the kernels run at ("scalar", "avx2", "avx512" or "neon"); InvalidInputError
/// if PHYSCORE_SIMD names a level that is unknown or that this CPU lacks.
#[pyfunction]
fn simd_level(py: Python<'_>) -> PyResult<&'static str> {
    crate::simd::check().map(|l| l.name()).map_err(|e| to_py(py, e))
}

/// The SIMD levels this CPU supports, slowest first.
#[pyfunction]
fn simd_levels() -> Vec<&'static str> {
    crate::simd::Level::available().into_iter().map(|l| l.name()).collect()
}

/// Forces the SIMD level for this process (None: back to PHYSCORE_SIMD, else the best).
#[pyfunction]
#[pyo3(signature = (level=None))]
fn set_simd_level(py: Python<'_>, level: Option<&str>) -> PyResult<()> {
    let l = match level {
        None => None,
        Some(name) => Some(crate::simd::Level::by_name(name).ok_or_else(|| {
            to_py(
                py,
                crate::error::invalid(
                    "level",
                    format!("unknown SIMD level {name:?}; valid: scalar, avx2, avx512, neon"),
                ),
            )
        })?),
    };
    crate::simd::set_level(l).map_err(|e| to_py(py, e))
}

/// A short description of this CPU.
#[pyfunction]
fn cpu_name() -> String {
    crate::simd::cpu_name()
}

/// The optional per-particle attributes a scene may carry: name -> SI unit.
#[pyfunction]
fn particle_attributes() -> Vec<(&'static str, &'static str)> {
    crate::state::ATTRIBUTES.to_vec()
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySimulation>()?;
    m.add_function(wrap_pyfunction!(integrator_table, m)?)?;
    m.add_function(wrap_pyfunction!(default_threads, m)?)?;
    m.add_function(wrap_pyfunction!(simd_level, m)?)?;
    m.add_function(wrap_pyfunction!(simd_levels, m)?)?;
    m.add_function(wrap_pyfunction!(set_simd_level, m)?)?;
    m.add_function(wrap_pyfunction!(cpu_name, m)?)?;
    m.add_function(wrap_pyfunction!(particle_attributes, m)?)?;
    m.add_function(wrap_pyfunction!(neighbors, m)?)?;
    m.add("build_profile", if cfg!(debug_assertions) { "debug" } else { "release" })?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
