//! Python bindings (the only module that knows pyo3). Arrays cross in bulk; the Python facade
//! (`physcore.Scene`) validates inputs first, and everything is validated again here so the
//! private module is safe to call directly. The GIL is released around stepping.
use crate::alloc::{count, Need};
use crate::boundary::{Aabb, Plane};
use crate::error::{invalid, Error};
use crate::integrators::{self, IntegratorInfo};
use crate::simulation::{Checkpoint, EnergyReport, Simulation};
use crate::terms::registry::{self, Context, Params, Value};
use crate::vector::{Real, Vector};
use glam::{DVec2, DVec3};
use numpy::ndarray::{Array1, Array2};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyString};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Maps the core's error enum onto the Python hierarchy defined in `physcore/_errors.py`.
fn to_py(py: Python<'_>, e: Error) -> PyErr {
    let msg = e.to_string();
    let build = || -> PyResult<PyErr> {
        let errors = py.import("physcore._errors")?;
        Ok(match e {
            Error::InvalidInput { .. } => {
                PyErr::from_value(errors.getattr("InvalidInputError")?.call1((msg.clone(),))?)
            }
            Error::InvalidType { .. } => PyErr::from_value(errors.getattr("InvalidTypeError")?.call1((msg.clone(),))?),
            Error::Interrupted { .. } => pyo3::exceptions::PyKeyboardInterrupt::new_err(msg.clone()),
            Error::Threads { .. } => PyErr::from_value(errors.getattr("ThreadPoolError")?.call1((msg.clone(),))?),
            Error::OutOfMemory { bytes, .. } => {
                PyErr::from_value(errors.getattr("OutOfMemoryError")?.call1((msg.clone(), bytes))?)
            }
            Error::Diverged { step, t, particle, quantity, suggested_dt, rolled_back_to, .. } => {
                let exc = errors.getattr("SimulationDiverged")?.call1((
                    msg.clone(),
                    step,
                    t,
                    particle,
                    quantity,
                    suggested_dt,
                    rolled_back_to,
                ))?;
                PyErr::from_value(exc)
            }
        })
    };
    build().unwrap_or_else(|_| PyValueError::new_err(msg))
}

/// `to_py` where no `Python` token is at hand (the GIL is held: we are inside a call).
fn err(e: Error) -> PyErr {
    Python::attach(|py| to_py(py, e))
}

enum Inner {
    D2(Simulation<DVec2>),
    D3(Simulation<DVec3>),
}

macro_rules! with_sim {
    ($self:expr, $s:ident => $body:expr) => {
        match $self {
            Inner::D2($s) => $body,
            Inner::D3($s) => $body,
        }
    };
}

fn flat2<'a>(a: &'a PyReadonlyArray2<'_, f64>, dim: usize, arg: &str) -> PyResult<&'a [f64]> {
    let shape = a.shape();
    if shape[1] != dim {
        return Err(err(invalid(arg, format!("expected shape (N, {dim}), got ({}, {})", shape[0], shape[1]))));
    }
    a.as_slice().map_err(|_| err(invalid(arg, "array must be C-contiguous")))
}

fn slice1<'a, T: numpy::Element>(a: &'a PyReadonlyArray1<'_, T>, arg: &str) -> PyResult<&'a [T]> {
    a.as_slice().map_err(|_| err(invalid(arg, "array must be contiguous")))
}

fn vec_of<V: Vector>(v: &[f64], arg: &str) -> PyResult<V> {
    if v.len() != V::DIM {
        return Err(err(invalid(arg, format!("expected {} components, got {}", V::DIM, v.len()))));
    }
    Ok(V::from_slice(v))
}

/// Cached forces (N, dim) and term powers.
type CacheArrays<'py> = (Bound<'py, PyArray2<f64>>, Vec<f64>);
/// Neighbour pairs (i, j), (M,) int64 each.
type Pairs<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray1<i64>>);

/// A new (N, dim) array of `v` (`what`: the getter, for a MemoryError).
fn to_array2<'py, V: Vector>(py: Python<'py>, v: &[V], what: &'static str) -> PyResult<Bound<'py, PyArray2<f64>>> {
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
fn vectors<V: Vector>(flat: &[f64], need: &Need) -> Result<Vec<V>, Error> {
    need.collect(flat.chunks_exact(V::DIM).map(V::from_slice))
}

/// `from_flat` that reports a refused allocation as `Error::OutOfMemory` of call `what`.
fn try_from_flat<V: Vector>(flat: &[f64], what: &'static str, of: &str) -> Result<Vec<V>, Error> {
    let n = flat.len() / V::DIM;
    vectors(flat, &Need::new(what, Need::bytes_of::<V>(n), format!("{} {of}", count(n as u128))))
}

/// A term's parameters from a Python dict (see `Simulation2::add_term`); a refused copy is an
/// `OutOfMemoryError` of `kind` naming the parameter and its length.
fn params_of(py: Python<'_>, kind: &'static str, d: &Bound<'_, PyDict>) -> PyResult<Params> {
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

fn info_dict<'py>(py: Python<'py>, i: IntegratorInfo) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", i.name)?;
    d.set_item("order", i.order)?;
    d.set_item("symplectic", i.symplectic)?;
    d.set_item("force_evals_per_step", i.force_evals_per_step)?;
    Ok(d)
}

fn energy_dict<'py>(py: Python<'py>, e: EnergyReport) -> PyResult<Bound<'py, PyDict>> {
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

/// Low-level simulation handle. Use `physcore.Scene`, which validates inputs and keeps the
/// scene description needed for `save()`.
#[pyclass(module = "physcore._core")]
pub struct Simulation2 {
    inner: Inner,
}

#[pymethods]
impl Simulation2 {
    #[new]
    #[pyo3(signature = (dim, integrator, dt, threads=None))]
    fn new(py: Python<'_>, dim: usize, integrator: &str, dt: f64, threads: Option<usize>) -> PyResult<Self> {
        let inner = match dim {
            2 => Inner::D2(Simulation::new(integrator, dt, threads).map_err(|e| to_py(py, e))?),
            3 => Inner::D3(Simulation::new(integrator, dt, threads).map_err(|e| to_py(py, e))?),
            _ => return Err(err(invalid("dim", format!("must be 2 or 3, got {dim}")))),
        };
        Ok(Self { inner })
    }

    #[getter]
    fn dim(&self) -> usize {
        match self.inner {
            Inner::D2(_) => 2,
            Inner::D3(_) => 3,
        }
    }

    #[getter]
    fn n_particles(&self) -> usize {
        with_sim!(&self.inner, s => s.n_particles())
    }

    #[getter]
    fn time(&self) -> f64 {
        with_sim!(&self.inner, s => s.sys.state.t)
    }

    #[getter]
    fn step_count(&self) -> u64 {
        with_sim!(&self.inner, s => s.sys.state.step)
    }

    /// Why this simulation runs on the calling thread alone (its threads could not be
    /// started), or None.
    #[getter]
    fn sequential(&self) -> Option<String> {
        with_sim!(&self.inner, s => s.sequential().map(str::to_string))
    }

    #[getter]
    fn dt(&self) -> f64 {
        with_sim!(&self.inner, s => s.dt)
    }

    #[setter]
    fn set_dt(&mut self, py: Python<'_>, dt: f64) -> PyResult<()> {
        with_sim!(&mut self.inner, s => s.set_dt(dt)).map_err(|e| to_py(py, e))
    }

    #[getter]
    fn integrator(&self) -> &'static str {
        with_sim!(&self.inner, s => s.integrator_info().name)
    }

    #[setter]
    fn set_integrator(&mut self, py: Python<'_>, name: &str) -> PyResult<()> {
        with_sim!(&mut self.inner, s => s.set_integrator(name)).map_err(|e| to_py(py, e))
    }

    /// (rtol, atol) of the adaptive integrator.
    #[getter]
    fn tolerances(&self) -> (f64, f64) {
        with_sim!(&self.inner, s => s.tolerances())
    }

    fn set_tolerances(&mut self, py: Python<'_>, rtol: f64, atol: f64) -> PyResult<()> {
        with_sim!(&mut self.inner, s => s.set_tolerances(rtol, atol)).map_err(|e| to_py(py, e))
    }

    /// (accepted, rejected, next internal step s) for "rk45", else None.
    fn adaptive_stats(&self) -> Option<(u64, u64, f64)> {
        with_sim!(&self.inner, s => s.adaptive_stats())
    }

    /// Whether the state is kept in single precision.
    #[getter]
    fn single(&self) -> bool {
        with_sim!(&self.inner, s => s.single())
    }

    #[setter]
    fn set_single(&mut self, single: bool) {
        with_sim!(&mut self.inner, s => s.set_single(single))
    }

    /// The substep advance() would take now, or None (O(N²) with gravity: GIL released, and
    /// Ctrl-C interrupts it).
    fn auto_dt(&mut self, py: Python<'_>) -> PyResult<Option<f64>> {
        with_sim!(&mut self.inner, s => interruptible_read(py, s, |s, stop| s.query_interruptible(stop, |s| s.auto_dt())))
    }

    fn integrator_info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        info_dict(py, with_sim!(&self.inner, s => s.integrator_info()))
    }

    #[getter]
    fn force_evaluations(&self) -> u64 {
        with_sim!(&self.inner, s => s.force_evaluations())
    }

    /// Appends particles; returns the index of the first.
    fn add_particles(
        &mut self,
        py: Python<'_>,
        positions: PyReadonlyArray2<'_, f64>,
        velocities: PyReadonlyArray2<'_, f64>,
        masses: PyReadonlyArray1<'_, f64>,
        pinned: PyReadonlyArray1<'_, bool>,
    ) -> PyResult<usize> {
        let dim = self.dim();
        let x = flat2(&positions, dim, "positions")?;
        let v = flat2(&velocities, dim, "velocities")?;
        let (m, p) = (slice1(&masses, "masses")?, slice1(&pinned, "pinned")?);
        // The copies made here plus what the scene grows by (state and masses).
        let n = x.len() / dim;
        let bytes = n as u128 * (2 * 2 * 8 * dim as u128 + 2 * 8 + 8 + 1);
        let need = Need::new("add_particles", bytes, format!("{} particles", count(n as u128)));
        let copies = || -> Result<_, Error> {
            need.check()?;
            Ok((need.copy(m)?, need.copy(p)?))
        };
        let (m, p) = copies().map_err(|e| to_py(py, e))?;
        with_sim!(&mut self.inner, s => {
            vectors(x, &need).and_then(|x| Ok((x, vectors(v, &need)?))).and_then(|(x, v)| s.add_particles(x, v, m, p))
        })
        .map_err(|e| to_py(py, e))
    }

    /// Positions, m: a new (N, dim) float64 array (a copy; writing to it changes nothing).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        with_sim!(&self.inner, s => to_array2(py, &s.sys.state.x, "positions"))
    }

    /// Velocities, m/s: a new (N, dim) float64 array (a copy).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        with_sim!(&self.inner, s => to_array2(py, &s.sys.state.v, "velocities"))
    }

    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        with_sim!(&self.inner, s => Array1::from_vec(s.sys.model.mass.clone()).into_pyarray(py))
    }

    #[getter]
    fn pinned<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        with_sim!(&self.inner, s => Array1::from_vec(s.sys.model.inv_mass.iter().map(|&im| im == 0.0).collect()).into_pyarray(py))
    }

    #[pyo3(signature = (positions=None, velocities=None))]
    fn set_state(
        &mut self,
        py: Python<'_>,
        positions: Option<PyReadonlyArray2<'_, f64>>,
        velocities: Option<PyReadonlyArray2<'_, f64>>,
    ) -> PyResult<()> {
        let dim = self.dim();
        let x = positions.as_ref().map(|a| flat2(a, dim, "positions")).transpose()?;
        let v = velocities.as_ref().map(|a| flat2(a, dim, "velocities")).transpose()?;
        with_sim!(&mut self.inner, s => {
            let x = x.map(|x| try_from_flat(x, "set_state", "positions")).transpose();
            let v = v.map(|v| try_from_flat(v, "set_state", "velocities")).transpose();
            x.and_then(|x| Ok((x, v?))).and_then(|(x, v)| s.set_state(x, v))
        })
        .map_err(|e| to_py(py, e))
    }

    /// Sets the optional per-particle attribute `name` (`state::ATTRIBUTES`), (N,) float64.
    fn set_attribute(&mut self, py: Python<'_>, name: &str, values: PyReadonlyArray1<'_, f64>) -> PyResult<()> {
        let v = slice1(&values, name)?;
        let need = Need::new("set_attribute", Need::bytes_of::<f64>(v.len()), format!("a copy of {name}"));
        let v = need.copy(v).map_err(|e| to_py(py, e))?;
        with_sim!(&mut self.inner, s => s.set_attribute(name, v)).map_err(|e| to_py(py, e))
    }

    /// The attributes set so far: name -> (N,) float64 copy.
    fn attributes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        with_sim!(&self.inner, s => {
            for (k, a) in &s.sys.model.attributes {
                d.set_item(*k, a.clone().into_pyarray(py))?;
            }
        });
        Ok(d)
    }

    /// Adds a force term of registered type `kind` (see `terms::registry`) named `name`, built
    /// from `params`: numbers, bools, strings, and 1-D or 2-D arrays (float64: numbers; uint32:
    /// particle indices), copied fallibly.
    fn add_term(&mut self, py: Python<'_>, kind: &str, name: String, params: &Bound<'_, PyDict>) -> PyResult<()> {
        let ty = registry::lookup(kind).map_err(|e| to_py(py, e))?;
        let p = params_of(py, ty.kind, params)?;
        match &mut self.inner {
            Inner::D2(s) => {
                let ctx = Context { n_particles: s.n_particles() };
                ty.build::<DVec2>(name, p, &ctx).and_then(|t| s.add_term(t))
            }
            Inner::D3(s) => {
                let ctx = Context { n_particles: s.n_particles() };
                ty.build::<DVec3>(name, p, &ctx).and_then(|t| s.add_term(t))
            }
        }
        .map_err(|e| to_py(py, e))
    }

    fn add_plane(
        &mut self,
        py: Python<'_>,
        point: Vec<f64>,
        normal: Vec<f64>,
        restitution: f64,
        friction: f64,
    ) -> PyResult<()> {
        with_sim!(&mut self.inner, s => {
            let p = Plane { point: vec_of(&point, "point")?, normal: vec_of(&normal, "normal")?, restitution, friction };
            s.add_plane(p)
        })
        .map_err(|e| to_py(py, e))
    }

    fn add_box(
        &mut self,
        py: Python<'_>,
        lower: Vec<f64>,
        upper: Vec<f64>,
        restitution: f64,
        friction: f64,
    ) -> PyResult<()> {
        with_sim!(&mut self.inner, s => {
            let b = Aabb { lo: vec_of(&lower, "lower")?, hi: vec_of(&upper, "upper")?, restitution, friction };
            s.add_box(b)
        })
        .map_err(|e| to_py(py, e))
    }

    /// Runs n steps in Rust with the GIL released. Ctrl-C is noticed within about
    /// `SIGNAL_POLL` plus a fraction of a millisecond of kernel work (see `interruptible`): the
    /// state is rolled back to where the call started and KeyboardInterrupt is raised.
    fn step(&mut self, py: Python<'_>, n: u64) -> PyResult<()> {
        with_sim!(&mut self.inner, s => {
            if s.adaptive_stats().is_none() && n.saturating_mul(s.n_particles() as u64) <= SHORT_CALL {
                let never = Arc::new(AtomicBool::new(false));
                let cp = py.detach(|| s.step_checkpointed(n, &never)).map_err(|e| to_py(py, e))?;
                return undo_if_signalled(py, s, ((), cp));
            }
            interruptible(py, s, |s, stop| s.step_checkpointed(n, stop).map(|cp| ((), cp)))
        })
    }

    /// Advances `duration` seconds in automatically chosen substeps; returns their number.
    #[pyo3(signature = (duration, substeps=None))]
    fn advance(&mut self, py: Python<'_>, duration: f64, substeps: Option<u64>) -> PyResult<u64> {
        with_sim!(&mut self.inner, s => interruptible(py, s, |s, stop| s.advance_checkpointed(duration, substeps, stop)))
    }

    /// ((grid_s, density_s, forces_s), heap bytes) of the SPH terms.
    fn fluid_profile(&self) -> ((f64, f64, f64), usize) {
        let (c, b) = with_sim!(&self.inner, s => s.fluid_profile());
        ((c[0], c[1], c[2]), b)
    }

    /// (density, pressure) of every particle, (N,) float64 each; 0 outside fluids.
    fn fluid_fields<'py>(&self, py: Python<'py>) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>) {
        let inner = &self.inner;
        let (r, p) = py.detach(|| with_sim!(inner, s => s.fluid_fields()));
        (Array1::from(r).into_pyarray(py), Array1::from(p).into_pyarray(py))
    }

    /// The energy books; O(N²) with pairwise gravity, so Ctrl-C interrupts it (nothing changes).
    fn energy<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let e = with_sim!(&mut self.inner, s => interruptible_read(py, s, |s, stop| s.query_interruptible(stop, |s| s.energy())))?;
        energy_dict(py, e)
    }

    fn momentum<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let p: Vec<Real> =
            with_sim!(&self.inner, s => { let p = s.momentum(); (0..p_dim(&p)).map(|k| p.comp(k)).collect() });
        Array1::from_vec(p).into_pyarray(py)
    }

    fn angular_momentum<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        Array1::from_vec(with_sim!(&self.inner, s => s.angular_momentum()).to_vec()).into_pyarray(py)
    }

    /// O(N²) with pairwise gravity: the GIL is released and Ctrl-C interrupts it.
    fn suggest_dt(&mut self, py: Python<'_>) -> PyResult<f64> {
        with_sim!(&mut self.inner, s => interruptible_read(py, s, |s, stop| s.query_interruptible(stop, |s| s.suggest_dt())))
    }

    /// (per-term dissipated energy in term order, collisions), J.
    fn ledger(&self) -> (Vec<f64>, f64) {
        with_sim!(&self.inner, s => (s.sys.forces.dissipated.clone(), s.collision_dissipated))
    }

    /// Cached forces (N, dim) and term powers carried between steps, or None.
    fn integrator_cache<'py>(&self, py: Python<'py>) -> PyResult<Option<CacheArrays<'py>>> {
        with_sim!(&self.inner, s => s.integrator_cache().map(|(f, p)| Ok((to_array2(py, &f, "integrator_cache")?, p))).transpose())
    }

    #[pyo3(signature = (t, step, dissipated, collisions, cache_forces=None, cache_power=None))]
    #[allow(clippy::too_many_arguments)]
    fn restore(
        &mut self,
        py: Python<'_>,
        t: f64,
        step: u64,
        dissipated: Vec<f64>,
        collisions: f64,
        cache_forces: Option<PyReadonlyArray2<'_, f64>>,
        cache_power: Option<Vec<f64>>,
    ) -> PyResult<()> {
        let dim = self.dim();
        let f = cache_forces.as_ref().map(|a| flat2(a, dim, "cache_forces")).transpose()?;
        with_sim!(&mut self.inner, s => {
            let cache = match (f, cache_power) {
                (Some(f), Some(p)) => try_from_flat(f, "restore", "cached forces").map(|f| Some((f, p))),
                _ => Ok(None),
            };
            cache.and_then(|cache| s.restore(t, step, &dissipated, collisions, cache))
        })
        .map_err(|e| to_py(py, e))
    }
}

fn p_dim<V: Vector>(_: &V) -> usize {
    V::DIM
}

/// How often the calling thread runs Python's signal handlers while a step runs.
const SIGNAL_POLL: Duration = Duration::from_millis(20);

/// Calls of at most this many particle-steps with a fixed-step integrator run on the calling
/// thread, unwatched: even pairwise gravity (N² per step) keeps them to milliseconds, and the
/// hand-off to a pool thread (~20 µs) would cost more than a small scene's step. A signal that
/// came during such a call is handled right after it, and the call is undone as if it had been
/// interrupted (`undo_if_signalled`).
const SHORT_CALL: u64 = 4096;

/// Runs Python's signal handlers after a finished call; if one raises (Ctrl-C), the call is
/// undone (`rollback` to `cp`) and the handler's exception raised, so an interrupted call never
/// stands, however close to its end the signal came. Returns the call's result otherwise.
fn undo_if_signalled<V: Vector, T>(
    py: Python<'_>,
    sim: &mut Simulation<V>,
    (v, cp): (T, Checkpoint<V>),
) -> PyResult<T> {
    match py.check_signals() {
        Ok(()) => Ok(v),
        Err(e) => {
            sim.rollback(cp);
            Err(e)
        }
    }
}

/// Runs `f` with the GIL released as a task on the simulation's pool (`run_watched`), while the
/// calling thread wakes every `SIGNAL_POLL` to run Python's signal handlers (`check_signals`;
/// Python runs them on the main thread only, so the stepping code, on a pool thread, cannot).
/// If a handler raises (Ctrl-C: KeyboardInterrupt), the stop flag is set and the handler's
/// exception is returned beside `f`'s result.
fn watched<V: Vector, T: Send>(
    py: Python<'_>,
    sim: &mut Simulation<V>,
    f: impl FnOnce(&mut Simulation<V>, &Arc<AtomicBool>) -> Result<T, Error> + Send,
) -> (Result<T, Error>, Option<PyErr>) {
    let stop = Arc::new(AtomicBool::new(false));
    let mut pending: Option<PyErr> = None;
    let result = py.detach(|| {
        sim.run_watched(
            |s| f(s, &stop),
            |wait| {
                while !wait(SIGNAL_POLL) {
                    if let Err(e) = Python::attach(|py| py.check_signals()) {
                        pending = Some(e);
                        stop.store(true, Ordering::Relaxed);
                        return;
                    }
                }
            },
        )
    });
    (result, pending)
}

/// `f` under `watched`: once a handler raises, `f` rolls back and returns `Error::Interrupted`,
/// and the handler's exception is raised. If `f` finished before it saw the flag, the handlers
/// run once more and, if one raises, `f`'s work is undone with the checkpoint it returned: an
/// interrupted call never stands.
fn interruptible<V: Vector, T: Send>(
    py: Python<'_>,
    sim: &mut Simulation<V>,
    f: impl FnOnce(&mut Simulation<V>, &Arc<AtomicBool>) -> Result<(T, Checkpoint<V>), Error> + Send,
) -> PyResult<T> {
    match watched(py, sim, f) {
        (Ok(done), None) => undo_if_signalled(py, sim, done),
        (Ok((_, cp)), Some(e)) => {
            sim.rollback(cp);
            Err(e)
        }
        (Err(_), Some(e)) => Err(e),
        (Err(Error::Interrupted { .. }), None) => Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(())),
        (Err(e), None) => Err(to_py(py, e)),
    }
}

/// `f` under `watched`, for a call that changes nothing (the energy books): a handler's
/// exception stops it and is raised; there is nothing to roll back.
fn interruptible_read<V: Vector, T: Send>(
    py: Python<'_>,
    sim: &mut Simulation<V>,
    f: impl FnOnce(&mut Simulation<V>, &Arc<AtomicBool>) -> Result<T, Error> + Send,
) -> PyResult<T> {
    match watched(py, sim, f) {
        (_, Some(e)) => Err(e),
        (Ok(v), None) => Ok(v),
        (Err(Error::Interrupted { .. }), None) => Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(())),
        (Err(e), None) => Err(to_py(py, e)),
    }
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
        py.detach(|| crate::par::install(pool.as_ref(), || crate::grid::neighbor_pairs(&x, radius)))
    } else {
        let x = try_from_flat::<DVec2>(flat, "neighbors", "points").map_err(|e| to_py(py, e))?;
        py.detach(|| crate::par::install(pool.as_ref(), || crate::grid::neighbor_pairs(&x, radius)))
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
    m.add_class::<Simulation2>()?;
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
