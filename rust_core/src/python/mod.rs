//! Python bindings (the only module that knows pyo3). Arrays cross in bulk; the Python facade
//! (`physcore.Scene`) validates inputs first, and everything is validated again here so the
//! private module is safe to call directly. The GIL is released around stepping.
use crate::boundary::{Aabb, Plane};
use crate::error::Error;
use crate::integrators::{self, IntegratorInfo};
use crate::simulation::{EnergyReport, Simulation};
use crate::sph::{KernelKind, Precision, Sph, SphParams};
use crate::terms::{Drag, PairwiseGravity, Springs, UniformGravity};
use crate::vector::{from_flat, to_flat, Real, Vector};
use glam::{DVec2, DVec3};
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Maps the core's error enum onto the Python hierarchy defined in `physcore/_errors.py`.
fn to_py(py: Python<'_>, e: Error) -> PyErr {
    let msg = e.to_string();
    let build = || -> PyResult<PyErr> {
        let errors = py.import("physcore._errors")?;
        Ok(match e {
            Error::InvalidInput { .. } => PyErr::from_value(errors.getattr("InvalidInputError")?.call1((msg.clone(),))?),
            Error::Interrupted { .. } => pyo3::exceptions::PyKeyboardInterrupt::new_err(msg.clone()),
            Error::Diverged { step, t, particle, quantity, suggested_dt, rolled_back_to, .. } => {
                let exc = errors
                    .getattr("SimulationDiverged")?
                    .call1((msg.clone(), step, t, particle, quantity, suggested_dt, rolled_back_to))?;
                PyErr::from_value(exc)
            }
        })
    };
    build().unwrap_or_else(|_| PyValueError::new_err(msg))
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
        return Err(PyValueError::new_err(format!("{arg}: expected shape (N, {dim}), got ({}, {})", shape[0], shape[1])));
    }
    a.as_slice().map_err(|_| PyValueError::new_err(format!("{arg}: array must be C-contiguous")))
}

fn slice1<'a, T: numpy::Element>(a: &'a PyReadonlyArray1<'_, T>, arg: &str) -> PyResult<&'a [T]> {
    a.as_slice().map_err(|_| PyValueError::new_err(format!("{arg}: array must be contiguous")))
}

fn vec_of<V: Vector>(v: &[f64], arg: &str) -> PyResult<V> {
    if v.len() != V::DIM {
        return Err(PyValueError::new_err(format!("{arg}: expected {} components, got {}", V::DIM, v.len())));
    }
    Ok(V::from_slice(v))
}

fn to_array2<'py, V: Vector>(py: Python<'py>, v: &[V]) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_vec((v.len(), V::DIM), to_flat(v)).expect("shape matches").into_pyarray(py)
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
            _ => return Err(PyValueError::new_err(format!("dim: must be 2 or 3, got {dim}"))),
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

    /// The substep advance() would take now, or None (GIL released: O(N²) with gravity).
    fn auto_dt(&self, py: Python<'_>) -> Option<f64> {
        let inner = &self.inner;
        py.detach(|| with_sim!(inner, s => s.auto_dt()))
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
        let m = slice1(&masses, "masses")?.to_vec();
        let p = slice1(&pinned, "pinned")?.to_vec();
        with_sim!(&mut self.inner, s => s.add_particles(from_flat(x), from_flat(v), m, p)).map_err(|e| to_py(py, e))
    }

    /// Positions, m: a new (N, dim) float64 array (a copy; writing to it changes nothing).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        with_sim!(&self.inner, s => to_array2(py, &s.sys.state.x))
    }

    /// Velocities, m/s: a new (N, dim) float64 array (a copy).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        with_sim!(&self.inner, s => to_array2(py, &s.sys.state.v))
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
    fn set_state(&mut self, py: Python<'_>, positions: Option<PyReadonlyArray2<'_, f64>>, velocities: Option<PyReadonlyArray2<'_, f64>>) -> PyResult<()> {
        let dim = self.dim();
        let x = positions.as_ref().map(|a| flat2(a, dim, "positions")).transpose()?;
        let v = velocities.as_ref().map(|a| flat2(a, dim, "velocities")).transpose()?;
        with_sim!(&mut self.inner, s => s.set_state(x.map(from_flat), v.map(from_flat))).map_err(|e| to_py(py, e))
    }

    fn add_gravity(&mut self, py: Python<'_>, name: String, g: Vec<f64>) -> PyResult<()> {
        if g.iter().any(|c| !c.is_finite()) {
            return Err(PyValueError::new_err("g: must be finite"));
        }
        with_sim!(&mut self.inner, s => {
            let t = UniformGravity { name, g: vec_of(&g, "g")? };
            s.add_term(Box::new(t))
        })
        .map_err(|e| to_py(py, e))
    }

    fn add_drag(&mut self, py: Python<'_>, name: String, coefficient: f64) -> PyResult<()> {
        if !(coefficient.is_finite() && coefficient >= 0.0) {
            return Err(PyValueError::new_err(format!("coefficient: {coefficient} must be finite and >= 0")));
        }
        with_sim!(&mut self.inner, s => s.add_term(Box::new(Drag { name, b: coefficient }))).map_err(|e| to_py(py, e))
    }

    #[allow(clippy::too_many_arguments)]
    fn add_springs(
        &mut self,
        py: Python<'_>,
        name: String,
        i: PyReadonlyArray1<'_, u32>,
        j: PyReadonlyArray1<'_, u32>,
        stiffness: PyReadonlyArray1<'_, f64>,
        damping: PyReadonlyArray1<'_, f64>,
        rest_length: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<()> {
        let (i, j) = (slice1(&i, "i")?.to_vec(), slice1(&j, "j")?.to_vec());
        let (k, c, r) = (slice1(&stiffness, "stiffness")?.to_vec(), slice1(&damping, "damping")?.to_vec(), slice1(&rest_length, "rest_length")?.to_vec());
        with_sim!(&mut self.inner, s => {
            let n = s.n_particles();
            Springs::new(name, i, j, k, c, r, n).and_then(|t| s.add_term(Box::new(t)))
        })
        .map_err(|e| to_py(py, e))
    }

    #[pyo3(name = "add_pairwise_gravity")]
    fn add_pairwise_gravity(&mut self, py: Python<'_>, name: String, g: f64, softening: f64) -> PyResult<()> {
        if !(g.is_finite() && g > 0.0) {
            return Err(PyValueError::new_err(format!("G: {g} must be finite and > 0")));
        }
        if !(softening.is_finite() && softening >= 0.0) {
            return Err(PyValueError::new_err(format!("softening: {softening} must be finite and >= 0")));
        }
        with_sim!(&mut self.inner, s => s.add_term(Box::new(PairwiseGravity::new(name, g, softening)))).map_err(|e| to_py(py, e))
    }

    fn add_plane(&mut self, py: Python<'_>, point: Vec<f64>, normal: Vec<f64>, restitution: f64, friction: f64) -> PyResult<()> {
        with_sim!(&mut self.inner, s => {
            let p = Plane { point: vec_of(&point, "point")?, normal: vec_of(&normal, "normal")?, restitution, friction };
            s.add_plane(p)
        })
        .map_err(|e| to_py(py, e))
    }

    fn add_box(&mut self, py: Python<'_>, lower: Vec<f64>, upper: Vec<f64>, restitution: f64, friction: f64) -> PyResult<()> {
        with_sim!(&mut self.inner, s => {
            let b = Aabb { lo: vec_of(&lower, "lower")?, hi: vec_of(&upper, "upper")?, restitution, friction };
            s.add_box(b)
        })
        .map_err(|e| to_py(py, e))
    }

    /// Runs n steps in Rust with the GIL released. Ctrl-C is noticed within about
    /// `SIGNAL_POLL` plus one force evaluation (see `interruptible`): the state is rolled back
    /// to where the call started and KeyboardInterrupt is raised.
    fn step(&mut self, py: Python<'_>, n: u64) -> PyResult<()> {
        with_sim!(&mut self.inner, s => {
            if s.adaptive_stats().is_none() && n.saturating_mul(s.n_particles() as u64) <= SHORT_CALL {
                return py.detach(|| s.step(n)).map_err(|e| to_py(py, e));
            }
            interruptible(py, s, |s, stop| s.step_interruptible(n, stop))
        })
    }

    /// Advances `duration` seconds in automatically chosen substeps; returns their number.
    #[pyo3(signature = (duration, substeps=None))]
    fn advance(&mut self, py: Python<'_>, duration: f64, substeps: Option<u64>) -> PyResult<u64> {
        with_sim!(&mut self.inner, s => interruptible(py, s, |s, stop| s.advance_interruptible(duration, substeps, stop)))
    }

    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (name, first, n, h, density, sound_speed, gamma, viscosity, clamp_pressure, kernel, precision, walls, wall_psi))]
    fn add_sph(
        &mut self,
        py: Python<'_>,
        name: String,
        first: usize,
        n: usize,
        h: f64,
        density: f64,
        sound_speed: f64,
        gamma: i32,
        viscosity: f64,
        clamp_pressure: bool,
        kernel: &str,
        precision: &str,
        walls: PyReadonlyArray2<'_, f64>,
        wall_psi: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<()> {
        let kernel = KernelKind::by_name(kernel).map_err(|e| to_py(py, e))?;
        let precision = Precision::by_name(precision).map_err(|e| to_py(py, e))?;
        let p = SphParams { h, rho0: density, c0: sound_speed, gamma, alpha: viscosity, clamp: clamp_pressure, kernel, precision };
        let psi = slice1(&wall_psi, "wall_psi")?.to_vec();
        with_sim!(&mut self.inner, s => {
            let w = from_flat(flat2(&walls, p_dim(&s.sys.state.x.first().copied().unwrap_or_default()), "walls")?);
            if first.checked_add(n).is_none_or(|e| e > s.n_particles()) {
                return Err(PyValueError::new_err(format!("n: particles {first}..{} are not all in the scene ({})", first.saturating_add(n), s.n_particles())));
            }
            Sph::new(&name, first, n, p, w, psi).and_then(|t| s.add_term(Box::new(t)))
        })
        .map_err(|e| to_py(py, e))
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

    fn energy<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let inner = &self.inner;
        let e = py.detach(|| with_sim!(inner, s => s.energy()));
        energy_dict(py, e)
    }

    fn momentum<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let p: Vec<Real> = with_sim!(&self.inner, s => { let p = s.momentum(); (0..p_dim(&p)).map(|k| p.comp(k)).collect() });
        Array1::from_vec(p).into_pyarray(py)
    }

    fn angular_momentum<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        Array1::from_vec(with_sim!(&self.inner, s => s.angular_momentum()).to_vec()).into_pyarray(py)
    }

    /// O(N²) with pairwise gravity: the GIL is released.
    fn suggest_dt(&self, py: Python<'_>) -> f64 {
        let inner = &self.inner;
        py.detach(|| with_sim!(inner, s => s.suggest_dt()))
    }

    /// (per-term dissipated energy in term order, collisions), J.
    fn ledger(&self) -> (Vec<f64>, f64) {
        with_sim!(&self.inner, s => (s.sys.forces.dissipated.clone(), s.collision_dissipated))
    }

    /// Cached forces (N, dim) and term powers carried between steps, or None.
    fn integrator_cache<'py>(&self, py: Python<'py>) -> Option<(Bound<'py, PyArray2<f64>>, Vec<f64>)> {
        with_sim!(&self.inner, s => s.integrator_cache().map(|(f, p)| (to_array2(py, &f), p)))
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
                (Some(f), Some(p)) => Some((from_flat(f), p)),
                _ => None,
            };
            s.restore(t, step, &dissipated, collisions, cache)
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
/// hand-off to a pool thread (~20 µs) would cost more than a small scene's step. Ctrl-C then
/// lands right after the call, as it would between calls.
const SHORT_CALL: u64 = 4096;

/// Runs `f` with the GIL released as a task on the simulation's pool (`run_watched`), while the
/// calling thread wakes every `SIGNAL_POLL` to run Python's signal handlers (`check_signals`;
/// Python runs them on the main thread only, so the stepping code, on a pool thread, cannot).
/// If a handler raises (Ctrl-C: KeyboardInterrupt), the stop flag is set, `f` rolls back and
/// returns `Error::Interrupted`, and the handler's exception is raised. If `f` finished before
/// it saw the flag, its work stands and the exception is raised as if the signal had come
/// right after the call.
fn interruptible<V: Vector, T: Send>(
    py: Python<'_>,
    sim: &mut Simulation<V>,
    f: impl FnOnce(&mut Simulation<V>, &AtomicBool) -> Result<T, Error> + Send,
) -> PyResult<T> {
    let stop = AtomicBool::new(false);
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
    match (result, pending) {
        (Ok(v), None) => Ok(v),
        (_, Some(e)) => Err(e),
        (Err(Error::Interrupted { .. }), None) => Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(())),
        (Err(e), None) => Err(to_py(py, e)),
    }
}

/// All pairs i < j of `points` ((N, 2) or (N, 3) float64, C-contiguous) closer than `radius`:
/// two (M,) int64 arrays, sorted by i then j.
#[pyfunction]
fn neighbors<'py>(py: Python<'py>, points: PyReadonlyArray2<'py, f64>, radius: f64) -> PyResult<(Bound<'py, PyArray1<i64>>, Bound<'py, PyArray1<i64>>)> {
    let dim = points.shape()[1];
    let flat = flat2(&points, if dim == 3 { 3 } else { 2 }, "points")?.to_vec();
    let r = py.detach(|| {
        if dim == 3 {
            crate::grid::neighbor_pairs::<DVec3>(&from_flat(&flat), radius)
        } else {
            crate::grid::neighbor_pairs::<DVec2>(&from_flat(&flat), radius)
        }
    });
    let (i, j) = r.map_err(|e| to_py(py, e))?;
    let cv = |a: Vec<u32>| Array1::from_iter(a.into_iter().map(i64::from)).into_pyarray(py);
    Ok((cv(i), cv(j)))
}

/// Name, order, symplectic flag and force evaluations per step of every integrator.
#[pyfunction]
fn integrator_table<'py>(py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
    integrators::NAMES
        .iter()
        .map(|n| info_dict(py, integrators::by_name::<DVec2>(n).expect("listed").info()))
        .collect()
}

/// Number of threads in rayon's global pool.
#[pyfunction]
fn default_threads() -> usize {
    rayon::current_num_threads()
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
            to_py(py, crate::error::invalid("level", format!("unknown SIMD level {name:?}; valid: scalar, avx2, avx512, neon")))
        })?),
    };
    crate::simd::set_level(l).map_err(|e| to_py(py, e))
}

/// A short description of this CPU.
#[pyfunction]
fn cpu_name() -> String {
    crate::simd::cpu_name()
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
    m.add_function(wrap_pyfunction!(neighbors, m)?)?;
    m.add("build_profile", if cfg!(debug_assertions) { "debug" } else { "release" })?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
