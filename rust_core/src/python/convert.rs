//! Arrays and dicts across the boundary: checked views of numpy arrays, fallible copies into
//! the core's vectors, term parameters from a dict, and the dicts the bindings return.
use super::errors::*;
use crate::alloc::{count, Need};
use crate::error::{invalid, Error};
use crate::integrators::IntegratorInfo;
use crate::systems::EnergyReport;
use crate::terms::registry::{Params, Value};
use crate::vector::Vector;
use numpy::ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyString};

pub(super) fn flat2<'a>(a: &'a PyReadonlyArray2<'_, f64>, dim: usize, arg: &str) -> PyResult<&'a [f64]> {
    let shape = a.shape();
    if shape[1] != dim {
        return Err(err(invalid(arg, format!("expected shape (N, {dim}), got ({}, {})", shape[0], shape[1]))));
    }
    c_order(a, arg)
}

/// The data of a C-ordered 2D array, row after row. `as_slice` alone also takes a
/// Fortran-ordered array, whose rows it would read as columns.
pub(super) fn c_order<'a, T: numpy::Element>(a: &'a PyReadonlyArray2<'_, T>, arg: &str) -> PyResult<&'a [T]> {
    let refuse = || err(invalid(arg, "array must be C-contiguous"));
    if !a.is_c_contiguous() {
        return Err(refuse());
    }
    a.as_slice().map_err(|_| refuse())
}

pub(super) fn slice1<'a, T: numpy::Element>(a: &'a PyReadonlyArray1<'_, T>, arg: &str) -> PyResult<&'a [T]> {
    a.as_slice().map_err(|_| err(invalid(arg, "array must be contiguous")))
}

/// Cached forces (N, dim) and term powers.
pub(super) type CacheArrays<'py> = (Bound<'py, PyArray2<f64>>, Vec<f64>);
/// Neighbour pairs (i, j), (M,) int64 each.
pub(super) type Pairs<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray1<i64>>);

/// A new (N, dim) array of `v` (`what`: the getter, for a MemoryError).
pub(super) fn to_array2<'py, V: Vector>(
    py: Python<'py>,
    v: &[V],
    what: &'static str,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let need = Need::new(what, Need::bytes_of::<V>(v.len()), format!("a copy of {} rows", count(v.len() as u128)));
    let mut flat = need.filled(v.len() * V::DIM, 0.0).map_err(|e| to_py(py, e))?;
    for (row, p) in flat.chunks_exact_mut(V::DIM).zip(v) {
        for (k, o) in row.iter_mut().enumerate() {
            *o = p.comp(k);
        }
    }
    Ok(Array2::from_shape_vec((v.len(), V::DIM), flat).expect("shape matches").into_pyarray(py))
}

/// Copies of (N, dim) rows as vectors, allocated fallibly (`need`).
pub(super) fn vectors<V: Vector>(flat: &[f64], need: &Need) -> Result<Vec<V>, Error> {
    need.collect(flat.chunks_exact(V::DIM).map(V::from_slice))
}

/// `from_flat` that reports a refused allocation as `Error::OutOfMemory` of call `what`.
pub(super) fn try_from_flat<V: Vector>(flat: &[f64], what: &'static str, of: &str) -> Result<Vec<V>, Error> {
    let n = flat.len() / V::DIM;
    vectors(flat, &Need::new(what, Need::bytes_of::<V>(n), format!("{} {of}", count(n as u128))))
}

/// A term's parameters from a Python dict (see `PySimulation::add_term`); a refused copy is an
/// `OutOfMemoryError` of `kind` naming the parameter and its length.
pub(super) fn params_of(py: Python<'_>, kind: &'static str, d: &Bound<'_, PyDict>) -> PyResult<Params> {
    let copy_of = |key: &str, n: usize, bytes: u128| {
        Need::new(kind, bytes, format!("a copy of its {key} ({} entries)", count(n as u128)))
    };
    let mut p = Params::new();
    for (k, v) in d.iter() {
        let key: String = k.extract()?;
        let value = if let Ok(b) = v.cast::<PyBool>() {
            Value::Number(if b.is_true() { 1.0 } else { 0.0 })
        } else if let Ok(x) = v.cast::<PyFloat>() {
            Value::Number(x.value())
        } else if let Ok(x) = v.cast::<PyInt>() {
            Value::Number(x.extract::<f64>()?)
        } else if let Ok(s) = v.cast::<PyString>() {
            Value::Text(s.to_str()?.to_string())
        } else if let Ok(a) = v.extract::<PyReadonlyArrayDyn<'_, u32>>() {
            let s = a.as_slice().map_err(|_| to_py(py, invalid(&key, "array must be contiguous")))?;
            let need = copy_of(&key, s.len(), Need::bytes_of::<u32>(s.len()));
            Value::Indices(need.copy(s).map_err(|e| to_py(py, e))?)
        } else if let Ok(a) = v.extract::<PyReadonlyArrayDyn<'_, f64>>() {
            let s = a.as_slice().map_err(|_| to_py(py, invalid(&key, "array must be C-contiguous")))?;
            let need = copy_of(&key, s.len(), Need::bytes_of::<f64>(s.len()));
            Value::Floats(need.copy(s).map_err(|e| to_py(py, e))?)
        } else {
            let msg = format!("expected a number, bool, str or a float64/uint32 array, got {}", v.get_type().name()?);
            return Err(to_py(py, Error::InvalidType { arg: key, msg }));
        };
        p.insert(&key, value);
    }
    Ok(p)
}

pub(super) fn info_dict<'py>(py: Python<'py>, i: IntegratorInfo) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", i.name)?;
    d.set_item("order", i.order)?;
    d.set_item("symplectic", i.symplectic)?;
    d.set_item("force_evals_per_step", i.force_evals_per_step)?;
    Ok(d)
}

pub(super) fn energy_dict<'py>(py: Python<'py>, e: EnergyReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("kinetic", e.kinetic)?;
    let pot = PyDict::new(py);
    for (k, u) in &e.potential {
        pot.set_item(k, u)?;
    }
    let dis = PyDict::new(py);
    for (k, u) in &e.dissipated {
        dis.set_item(k, u)?;
    }
    d.set_item("potential", pot)?;
    d.set_item("dissipated", dis)?;
    Ok(d)
}
