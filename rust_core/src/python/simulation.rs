//! The `_core.Simulation` class: a handle on one 2D or 3D `crate::World`.
use super::{convert::*, errors::*, watch::*, Inner};
use crate::alloc::{count, Need};
use crate::constraints;
use crate::error::{invalid, Error};
use crate::systems::bodies::{Bodies2, Bodies3, Group2, Group3};
use crate::systems::particles::ParticleSystem;
use crate::systems::BodiesOf;
use crate::terms::registry::Params;
#[cfg(feature = "gpu")]
use crate::terms::registry::Value;
use crate::terms::registry::{self, Context};
use crate::vector::{Real, Vector};
use crate::world::World;
use glam::{DVec2, DVec3};
use numpy::ndarray::Array1;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Low-level simulation handle. Use `physcore.Scene`, which validates inputs and keeps the
/// scene description needed for `save()`.
#[pyclass(module = "physcore._core", name = "Simulation")]
pub struct PySimulation {
    inner: Inner,
    /// The force terms' records as added (kind, name, parameters), in order: what a device
    /// system is built from (`move_to_device`).
    terms: Vec<(String, String, registry::Params)>,
    /// Whether the particles live on a device (`move_to_device`): the getters read them from there.
    on_device: bool,
    /// The grids as added (kind, name, and the parameters of kinds the device has: what a device
    /// grid is built from; others keep none, so a wave's mask is not held twice).
    grids: Vec<(String, String, Option<registry::Params>)>,
    /// The colliders' records as added (kind, parameters), in order: what the device's are.
    colliders: Vec<(String, registry::Params)>,
    /// A number that no simulation's term and collider records have had before, new at each
    /// change of `terms` or `colliders` (`fresh_stamp`).
    stamp: u64,
}

/// A world's positions (`velocities` false) or velocities, flat, and its dimension; None in
/// single precision.
fn rows_of<V: Vector>(w: &World<V>, velocities: bool) -> Option<(&[Real], usize)> {
    let p = w.particles();
    if p.single() {
        return None;
    }
    let st = p.state();
    Some((V::flat(if velocities { &st.v } else { &st.x }), V::DIM))
}

/// A stamp no records have had before (`PySimulation::stamp`): from one counter for the process.
fn fresh_stamp() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// The name of the device particle system (`systems::device`); without the GPU backend no
/// world has one, and the lookups by it find nothing.
const DEVICE: &str = "device particles";

/// Vectors as a flat run of their components.
#[cfg(feature = "gpu")]
fn flat_of<V: Vector>(a: &[V]) -> Vec<f64> {
    a.iter().flat_map(|x| (0..V::DIM).map(move |k| x.comp(k))).collect()
}

/// The device system's fields `names`, read back, if the world has one.
fn device_fields<V: Vector>(w: &World<V>, on: bool, names: &[&str]) -> Option<crate::error::Result<Vec<Vec<f64>>>> {
    #[cfg(feature = "gpu")]
    if on {
        return w.other(DEVICE).ok().map(|d| d.fields(names));
    }
    let _ = (w, on, names);
    None
}

impl PySimulation {
    /// The device's (N, dim) rows of the fields `names` (the first dim of them), if the
    /// particles are on a device.
    fn device_rows<'py>(&self, py: Python<'py>, names: [&str; 3]) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        let (on, dim) = (self.on_device, self.dim());
        let Some(f) = with_sim!(&self.inner, s => device_fields(s, on, &names[..dim])) else { return Ok(None) };
        let f = f.map_err(|e| to_py(py, e))?;
        let n = f[0].len();
        let mut flat = Vec::with_capacity(n * dim);
        for i in 0..n {
            flat.extend(f.iter().map(|c| c[i]));
        }
        let a = numpy::ndarray::Array2::from_shape_vec((n, dim), flat)
            .map_err(|e| err(invalid("positions", e.to_string())))?;
        Ok(Some(a.into_pyarray(py)))
    }

    /// Refuses a change of the particles once they live on a device.
    fn host_only(&self) -> PyResult<()> {
        if self.on_device {
            return Err(err(invalid("particles", "they are on the GPU: add and set them before the first step")));
        }
        Ok(())
    }

    /// The world it holds (the batch steps several at once).
    pub(super) fn inner_mut(&mut self) -> &mut Inner {
        &mut self.inner
    }

    /// Its records' stamp (`stamp`): a batch on a device compares it with the one it was built
    /// from, one integer a member where comparing the records took a microsecond.
    #[cfg(feature = "gpu")]
    pub(super) fn records_stamp(&self) -> u64 {
        self.stamp
    }

    /// Its particles' positions (`velocities` false) or velocities, flat row-major (N, dim),
    /// and its dimension; None where they live on a device (the getters read them from there)
    /// or are single precision (the facade gives those as float32).
    pub(super) fn rows(&self, velocities: bool) -> Option<(&[Real], usize)> {
        if self.on_device {
            return None;
        }
        with_sim!(&self.inner, s => rows_of(s, velocities))
    }

    /// Whether `device_records` would give its records (not on a device, no grids).
    #[cfg(feature = "gpu")]
    pub(super) fn device_records_ready(&self) -> bool {
        !self.on_device && self.grids.is_empty()
    }

    /// Its term and collider records, what a batch on a device is built from; `InvalidInput`
    /// naming `sims` (entry `k`) if its particles are on a device already or it has grids.
    #[cfg(feature = "gpu")]
    pub(super) fn device_records(&self, k: usize) -> crate::error::Result<crate::systems::device_batch::Records> {
        if self.on_device {
            return Err(invalid(
                "sims",
                format!("entry {k} is on a device already (a GPU batch moves its members itself)"),
            ));
        }
        if let Some((_, name, _)) = self.grids.first() {
            return Err(invalid("sims", format!("entry {k} has the grid {name:?}: a GPU batch holds particles only")));
        }
        let terms = self
            .terms
            .iter()
            .map(|(k, n, p)| Ok((k.clone(), n.clone(), p.try_clone("step")?)))
            .collect::<crate::error::Result<Vec<_>>>()?;
        let cols = self
            .colliders
            .iter()
            .map(|(k, p)| Ok((k.clone(), p.try_clone("step")?)))
            .collect::<crate::error::Result<Vec<_>>>()?;
        Ok((terms, cols))
    }
}

#[pymethods]
impl PySimulation {
    #[new]
    #[pyo3(signature = (dim, integrator, dt, threads=None))]
    fn new(py: Python<'_>, dim: usize, integrator: &str, dt: f64, threads: Option<usize>) -> PyResult<Self> {
        let inner = match dim {
            2 => Inner::D2(
                ParticleSystem::new(integrator).and_then(|p| World::new(p, dt, threads)).map_err(|e| to_py(py, e))?,
            ),
            3 => Inner::D3(
                ParticleSystem::new(integrator).and_then(|p| World::new(p, dt, threads)).map_err(|e| to_py(py, e))?,
            ),
            _ => return Err(err(invalid("dim", format!("must be 2 or 3, got {dim}")))),
        };
        Ok(Self {
            inner,
            terms: Vec::new(),
            on_device: false,
            grids: Vec::new(),
            colliders: Vec::new(),
            stamp: fresh_stamp(),
        })
    }

    /// Moves the particles and the force terms to a device (`"gpu"`, `"gpu:NAME"`) at
    /// `precision` (`"f32"`, `"f64"`): a `systems::device::DeviceParticles` joins the world and
    /// the CPU particle system is left empty. Refuses (naming it) a term the device has no kernel
    /// for, an integrator it lacks, attributes, colliders; nothing changes then.
    fn move_to_device(&mut self, py: Python<'_>, device: &str, precision: &str) -> PyResult<()> {
        #[cfg(feature = "gpu")]
        {
            if self.on_device {
                return Err(err(invalid("device", "the particles are on the device already")));
            }
            use crate::systems::device::{DeviceGrayScott, DeviceParticles, DeviceWave};
            use crate::systems::device_fluid::DeviceFluid;
            use crate::systems::System;
            let (terms, grids, colliders) = (&self.terms, &self.grids, &self.colliders);
            let dim = self.dim();
            with_sim!(&mut self.inner, s => {
                let p = s.particles();
                // Charges are the Coulomb term's weights, radii the contacts term's grains;
                // other attributes have no kernel.
                let grains = terms.iter().any(|t| t.0 == "contacts");
                if let Some(a) = p.model().attributes.keys().find(|a| **a != "charge" && !(grains && **a == "radius")) {
                    return Err(err(invalid("device", format!("the GPU path has no per-particle {a:?} yet"))));
                }
                // The host copies made on the way (state, masses, pins, charges; a grid's two
                // fields) and as much again for the uploads' staging, asked for first: under a
                // memory cap they aborted the process (3,000,000 particles at +900 MB). And the
                // springs' lists, 256 bytes a spring at most: the record's copy (32), the lists
                // gathered per particle (72) and their sliced layout with its padding (144).
                let n = p.n_particles() as u128;
                let cells: u128 = grids.iter().filter_map(|(_, name, _)| s.other(name).ok()).map(|g| g.size() as u128).sum();
                let springs: u128 = terms.iter().filter(|t| t.0 == "springs").map(|t| t.2.len_of("i") as u128).sum();
                let bytes = 2 * (n * (2 * dim as u128 + 3) * 8 + cells * 2 * 8) + springs * 256;
                let of = format!(
                    "{} particles', {} springs' and {} grid cells' copies for the device",
                    count(n),
                    count(springs),
                    count(cells)
                );
                Need::new("step", bytes, of).room(bytes).map_err(|e| to_py(py, e))?;
                let charge = p.model().attribute("charge").map(|q| q.to_vec());
                if p.n_constraints() != colliders.len() {
                    return Err(err(invalid("device", "the GPU path has no constraints but its colliders yet")));
                }
                // Every device system is built before any is swapped in: a refusal changes nothing.
                let gpu = py.detach(|| physcore_gpu::Gpu::open(device)).map_err(|e| to_py(py, e.into()))?;
                let mut moved: Vec<Box<dyn System>> = Vec::new();
                for (kind, name, params) in grids {
                    let Some(params) = params.as_ref().filter(|_| matches!(kind.as_str(), "gray_scott" | "wave" | "stable_fluid")) else {
                        return Err(err(invalid(name, format!("the GPU path has no {kind:?} grid yet (it has \"gray_scott\", \"wave\" and \"stable_fluid\")"))));
                    };
                    let cpu = s.other(name).map_err(|e| to_py(py, e))?;
                    let g = gpu.clone();
                    if kind == "stable_fluid" {
                        // The obstacles left out of the record, from the CPU system (1 on solids).
                        let mut params = params.try_clone("step").map_err(|e| to_py(py, e))?;
                        let solid = cpu.fields(&["solid"]).map_err(|e| to_py(py, e))?.remove(0);
                        if solid.iter().any(|&m| m != 0.0) {
                            params.insert("obstacles", Value::Floats(solid));
                        }
                        let cfg = crate::grids::build::fluid_config(name, dim, params).map_err(|e| to_py(py, e))?;
                        let saved = cpu.save().map_err(|e| to_py(py, e))?;
                        let d = py.detach(|| DeviceFluid::on(g, precision, cfg, &saved)).map_err(|e| to_py(py, e))?;
                        moved.push(Box::new(d));
                        continue;
                    }
                    if kind == "wave" {
                        // The mask left out of the record, from the CPU system (1 on obstacles).
                        let mut params = params.try_clone("step").map_err(|e| to_py(py, e))?;
                        let mask = cpu.fields(&["mask"]).map_err(|e| to_py(py, e))?.remove(0);
                        if mask.iter().any(|&m| m != 0.0) {
                            params.insert("mask", Value::Floats(mask));
                        }
                        let cfg = crate::grids::build::wave_config(name, dim, params).map_err(|e| to_py(py, e))?;
                        let saved = cpu.save().map_err(|e| to_py(py, e))?;
                        let d = py.detach(|| DeviceWave::on(g, precision, cfg, &saved)).map_err(|e| to_py(py, e))?;
                        moved.push(Box::new(d));
                        continue;
                    }
                    let cfg = crate::grids::build::gray_scott_config(name, dim, params.clone()).map_err(|e| to_py(py, e))?;
                    let f = cpu.fields(&["u", "v"]).map_err(|e| to_py(py, e))?;
                    let made: Vec<f64> = cpu.books().into_iter().filter(|b| b.0.ends_with("_made")).map(|b| b.1).collect();
                    let made = [made[0], made[1]];
                    let d = py.detach(|| DeviceGrayScott::on(g, precision, cfg, &f[0], &f[1], made)).map_err(|e| to_py(py, e))?;
                    moved.push(Box::new(d));
                }
                let particles = p.n_particles() > 0 || !terms.is_empty() || !colliders.is_empty();
                let d: Option<Box<dyn System>> = if particles {
                    let (x, v) = (flat_of(&p.state().x), flat_of(&p.state().v));
                    let m = p.model().mass.clone();
                    let pinned: Vec<bool> = p.model().inv_mass.iter().map(|&im| im == 0.0).collect();
                    let integrator = p.integrator_info().name;
                    let g = gpu.clone();
                    if let Some((_, cname, _)) = terms.iter().find(|t| t.0 == "contacts") {
                        // DEM grains: their own device system, under the particles' name, taking
                        // the CPU term's spins and springs with them.
                        use crate::systems::device_dem::DeviceDem;
                        let history = p.term_history(cname).map_err(|e| to_py(py, e))?;
                        let radius = p.model().attribute("radius").map(|r| r.to_vec());
                        Some(Box::new(
                            py.detach(|| {
                                DeviceDem::from_records(
                                    g,
                                    precision,
                                    DEVICE,
                                    dim,
                                    integrator,
                                    &x,
                                    &v,
                                    &m,
                                    &pinned,
                                    radius.as_deref(),
                                    history.as_deref(),
                                    terms,
                                    colliders,
                                )
                            })
                            .map_err(|e| to_py(py, e))?,
                        ))
                    } else if let Some((_, fname, _)) = terms.iter().find(|t| t.0 == "dfsph") {
                        // A DFSPH fluid: its own device system, under the particles' name, taking
                        // the CPU term's warm starts with it.
                        use crate::systems::device_dfsph::DeviceDfsph;
                        let history = p.term_history(fname).map_err(|e| to_py(py, e))?;
                        Some(Box::new(
                            py.detach(|| {
                                DeviceDfsph::from_records(
                                    g, precision, DEVICE, dim, integrator, &x, &v, &m, &pinned, history.as_deref(), terms, colliders,
                                )
                            })
                            .map_err(|e| to_py(py, e))?,
                        ))
                    } else if terms.iter().any(|t| t.0 == "sph") {
                        // A WCSPH fluid: its own device system, under the particles' name.
                        use crate::systems::device_sph::DeviceSph;
                        Some(Box::new(
                            py.detach(|| DeviceSph::from_records(g, precision, DEVICE, dim, integrator, &x, &v, &m, &pinned, terms, colliders))
                                .map_err(|e| to_py(py, e))?,
                        ))
                    } else {
                        Some(Box::new(
                            py.detach(|| DeviceParticles::on(g, precision, dim, integrator, &x, &v, &m, &pinned, charge.as_deref(), terms, colliders))
                                .map_err(|e| to_py(py, e))?,
                        ))
                    }
                } else {
                    None
                };
                let integrator = p.integrator_info().name;
                for g in moved {
                    s.replace_system(g).map_err(|e| to_py(py, e))?;
                }
                if let Some(d) = d {
                    let empty = ParticleSystem::new(integrator).map_err(|e| to_py(py, e))?;
                    s.add_system(d).map_err(|e| to_py(py, e))?;
                    *s.particles_mut() = empty;
                }
                Ok::<(), PyErr>(())
            })?;
            self.on_device = true;
            Ok(())
        }
        #[cfg(not(feature = "gpu"))]
        {
            let _ = (device, precision);
            Err(to_py(py, invalid("device", "this build of physcore has no GPU backend")))
        }
    }

    /// Whether the particles live on a device (`move_to_device`).
    #[getter]
    fn on_device(&self) -> bool {
        self.on_device
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
        let on = self.on_device;
        with_sim!(&self.inner, s => match device_fields(s, on, &["mass"]) {
            Some(Ok(f)) => f[0].len(),
            _ => s.n_particles(),
        })
    }

    #[getter]
    fn time(&self) -> f64 {
        with_sim!(&self.inner, s => s.time())
    }

    #[getter]
    fn step_count(&self) -> u64 {
        with_sim!(&self.inner, s => s.steps())
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
        with_sim!(&self.inner, s => s.particles().integrator_info().name)
    }

    #[setter]
    fn set_integrator(&mut self, py: Python<'_>, name: &str) -> PyResult<()> {
        with_sim!(&mut self.inner, s => s.particles_mut().set_integrator(name)).map_err(|e| to_py(py, e))
    }

    /// (rtol, atol) of the adaptive integrator.
    #[getter]
    fn tolerances(&self) -> (f64, f64) {
        with_sim!(&self.inner, s => s.particles().tolerances())
    }

    fn set_tolerances(&mut self, py: Python<'_>, rtol: f64, atol: f64) -> PyResult<()> {
        with_sim!(&mut self.inner, s => s.particles_mut().set_tolerances(rtol, atol)).map_err(|e| to_py(py, e))
    }

    /// (substeps per step, iterations per substep) of "xpbd".
    #[getter]
    fn substeps(&self) -> (u32, u32) {
        with_sim!(&self.inner, s => s.particles().substeps())
    }

    fn set_substeps(&mut self, py: Python<'_>, substeps: u32, iterations: u32) -> PyResult<()> {
        with_sim!(&mut self.inner, s => s.particles_mut().set_substeps(substeps, iterations)).map_err(|e| to_py(py, e))
    }

    /// The coordinates of "wisdom_holman" ("jacobi" or "democratic_heliocentric").
    #[getter]
    fn wh_coordinates(&self) -> &'static str {
        with_sim!(&self.inner, s => s.particles().wh_coordinates())
    }

    fn set_wh_coordinates(&mut self, py: Python<'_>, name: &str) -> PyResult<()> {
        with_sim!(&mut self.inner, s => s.particles_mut().set_wh_coordinates(name)).map_err(|e| to_py(py, e))
    }

    /// The order of "wisdom_holman"'s symplectic corrector (0: none).
    #[getter]
    fn wh_corrector(&self) -> u32 {
        with_sim!(&self.inner, s => s.particles().wh_corrector())
    }

    fn set_wh_corrector(&mut self, py: Python<'_>, order: u32) -> PyResult<()> {
        with_sim!(&mut self.inner, s => s.particles_mut().set_wh_corrector(order)).map_err(|e| to_py(py, e))
    }

    /// (accepted, rejected, next internal step s) for "dopri5", else None.
    fn adaptive_stats(&self) -> Option<(u64, u64, f64)> {
        with_sim!(&self.inner, s => s.particles().adaptive_stats())
    }

    /// (cg_tol, cg_max_iter) of the implicit integrator's linear solve.
    #[getter]
    fn solver_options(&self) -> (f64, u32) {
        with_sim!(&self.inner, s => s.particles().solver_options())
    }

    fn set_solver_options(&mut self, py: Python<'_>, tol: f64, max_iter: u32) -> PyResult<()> {
        with_sim!(&mut self.inner, s => s.particles_mut().set_solver_options(tol, max_iter)).map_err(|e| to_py(py, e))
    }

    /// (solves, iterations, most iterations in one solve, unconverged solves, worst relative
    /// residual) of the implicit integrator's linear solves, else None.
    fn solver_stats(&self) -> Option<(u64, u64, u32, u64, f64)> {
        with_sim!(&self.inner, s => s.particles().solver_stats().map(|t| (t.solves, t.iterations, t.max_iterations, t.unconverged, t.worst_residual)))
    }

    /// Whether the state is kept in single precision.
    #[getter]
    fn single(&self) -> bool {
        with_sim!(&self.inner, s => s.particles().single())
    }

    #[setter]
    fn set_single(&mut self, single: bool) {
        with_sim!(&mut self.inner, s => s.particles_mut().set_single(single))
    }

    /// The substep advance() would take now, or None (O(N²) with gravity: GIL released, and
    /// Ctrl-C interrupts it).
    fn auto_dt(&mut self, py: Python<'_>) -> PyResult<Option<f64>> {
        with_sim!(&mut self.inner, s => interruptible_read(py, s, |s, stop| s.query_interruptible(stop, |s| s.auto_dt())))
    }

    fn integrator_info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        info_dict(py, with_sim!(&self.inner, s => s.particles().integrator_info()))
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
        self.host_only()?;
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
            vectors(x, &need).and_then(|x| Ok((x, vectors(v, &need)?))).and_then(|(x, v)| s.particles_mut().add_particles(x, v, m, p))
        })
        .map_err(|e| to_py(py, e))
    }

    /// Positions, m: a new (N, dim) float64 array (a copy; writing to it changes nothing).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        if let Some(a) = self.device_rows(py, ["x", "y", "z"])? {
            return Ok(a);
        }
        with_sim!(&self.inner, s => to_array2(py, &s.particles().state().x, "positions"))
    }

    /// Velocities, m/s: a new (N, dim) float64 array (a copy).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        if let Some(a) = self.device_rows(py, ["vx", "vy", "vz"])? {
            return Ok(a);
        }
        with_sim!(&self.inner, s => to_array2(py, &s.particles().state().v, "velocities"))
    }

    /// Masses, kg: a new (N,) float64 array (a copy).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let on = self.on_device;
        if let Some(f) = with_sim!(&self.inner, s => device_fields(s, on, &["mass"])) {
            let mut f = f.map_err(|e| to_py(py, e))?;
            return Ok(Array1::from_vec(f.swap_remove(0)).into_pyarray(py));
        }
        let m = with_sim!(&self.inner, s => copy_of(&s.particles().model().mass, "masses", "masses"));
        Ok(Array1::from_vec(m.map_err(|e| to_py(py, e))?).into_pyarray(py))
    }

    /// Which particles are pinned: a new (N,) bool array.
    #[getter]
    fn pinned<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let on = self.on_device;
        if let Some(f) = with_sim!(&self.inner, s => device_fields(s, on, &["pinned"])) {
            let f = f.map_err(|e| to_py(py, e))?;
            return Ok(Array1::from_vec(f[0].iter().map(|&p| p != 0.0).collect::<Vec<bool>>()).into_pyarray(py));
        }
        let p = with_sim!(&self.inner, s => {
            let im = &s.particles().model().inv_mass;
            Need::new("pinned", Need::bytes_of::<bool>(im.len()), format!("{} particles", count(im.len() as u128)))
                .collect(im.iter().map(|&im| im == 0.0))
        });
        Ok(Array1::from_vec(p.map_err(|e| to_py(py, e))?).into_pyarray(py))
    }

    #[pyo3(signature = (positions=None, velocities=None))]
    fn set_state(
        &mut self,
        py: Python<'_>,
        positions: Option<PyReadonlyArray2<'_, f64>>,
        velocities: Option<PyReadonlyArray2<'_, f64>>,
    ) -> PyResult<()> {
        self.host_only()?;
        let dim = self.dim();
        let x = positions.as_ref().map(|a| flat2(a, dim, "positions")).transpose()?;
        let v = velocities.as_ref().map(|a| flat2(a, dim, "velocities")).transpose()?;
        with_sim!(&mut self.inner, s => {
            let x = x.map(|x| try_from_flat(x, "set_state", "positions")).transpose();
            let v = v.map(|v| try_from_flat(v, "set_state", "velocities")).transpose();
            x.and_then(|x| Ok((x, v?))).and_then(|(x, v)| s.particles_mut().set_state(x, v))
        })
        .map_err(|e| to_py(py, e))
    }

    /// Sets the optional per-particle attribute `name` (`state::ATTRIBUTES`), (N,) float64.
    fn set_attribute(&mut self, py: Python<'_>, name: &str, values: PyReadonlyArray1<'_, f64>) -> PyResult<()> {
        self.host_only()?;
        let v = slice1(&values, name)?;
        let need = Need::new("set_attribute", Need::bytes_of::<f64>(v.len()), format!("a copy of {name}"));
        let v = need.copy(v).map_err(|e| to_py(py, e))?;
        with_sim!(&mut self.inner, s => s.particles_mut().set_attribute(name, v)).map_err(|e| to_py(py, e))
    }

    /// The attributes set so far: name -> (N,) float64 copy.
    fn attributes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        with_sim!(&self.inner, s => {
            for (k, a) in &s.particles().model().attributes {
                d.set_item(*k, copy_of(a, "attributes", k).map_err(|e| to_py(py, e))?.into_pyarray(py))?;
            }
        });
        Ok(d)
    }

    /// Adds a force term of registered type `kind` (see `terms::registry`) named `name`, built
    /// from `params`: numbers, bools, strings, and 1-D or 2-D arrays (float64: numbers; uint32:
    /// particle indices), copied fallibly.
    fn add_term(&mut self, py: Python<'_>, kind: &str, name: String, params: &Bound<'_, PyDict>) -> PyResult<()> {
        if self.on_device {
            return Err(err(invalid("item", "the particles are on the GPU: add every part before the first step")));
        }
        let ty = registry::lookup(kind).map_err(|e| to_py(py, e))?;
        let p = params_of(py, ty.kind, params)?;
        let record = (kind.to_string(), name.clone(), p.try_clone(ty.kind).map_err(|e| to_py(py, e))?);
        match &mut self.inner {
            Inner::D2(s) => {
                let ctx = Context { n_particles: s.n_particles() };
                ty.build::<DVec2>(name, p, &ctx).and_then(|t| s.particles_mut().add_term(t))
            }
            Inner::D3(s) => {
                let ctx = Context { n_particles: s.n_particles() };
                ty.build::<DVec3>(name, p, &ctx).and_then(|t| s.particles_mut().add_term(t))
            }
        }
        .map_err(|e| to_py(py, e))?;
        self.terms.push(record);
        self.stamp = fresh_stamp();
        Ok(())
    }

    /// Replaces the force term `name` by one of registered type `kind` built from `params`
    /// (`ParticleSystem::replace_term`): same place, books kept, state untouched; nothing changes
    /// on error. What the viewer's parameter keys use.
    fn replace_term(&mut self, py: Python<'_>, kind: &str, name: String, params: &Bound<'_, PyDict>) -> PyResult<()> {
        if self.on_device {
            return Err(err(invalid("item", "the particles are on the GPU: its terms cannot be replaced yet")));
        }
        let ty = registry::lookup(kind).map_err(|e| to_py(py, e))?;
        let p = params_of(py, ty.kind, params)?;
        let record = (kind.to_string(), name.clone(), p.try_clone(ty.kind).map_err(|e| to_py(py, e))?);
        let key = name.clone();
        match &mut self.inner {
            Inner::D2(s) => {
                let ctx = Context { n_particles: s.n_particles() };
                ty.build::<DVec2>(name, p, &ctx).and_then(|t| s.particles_mut().replace_term(t))
            }
            Inner::D3(s) => {
                let ctx = Context { n_particles: s.n_particles() };
                ty.build::<DVec3>(name, p, &ctx).and_then(|t| s.particles_mut().replace_term(t))
            }
        }
        .map_err(|e| to_py(py, e))?;
        // The record only once the term is in: a refused one (bad parameters, an integrator
        // that cannot take it) left the record of the term it did not replace (the move to a
        // device builds the device's terms from these records).
        if let Some(r) = self.terms.iter_mut().find(|r| r.1 == key) {
            *r = record;
            self.stamp = fresh_stamp();
        }
        Ok(())
    }

    /// Adds a grid system (`crate::grids::build`) of `kind` named `name`, built from `params`.
    fn add_grid(&mut self, py: Python<'_>, kind: &str, name: &str, params: &Bound<'_, PyDict>) -> PyResult<()> {
        let p = params_of(py, "add_grid", params)?;
        let dim = self.dim();
        // What a move to a device rebuilds the grid from. A wave's mask and a fluid's obstacles (a
        // value per cell) stay out: the device's copy reads them back from the CPU system ("mask",
        // "solid"), and a copy here aborted the process under a memory cap (it is the grid's size).
        let record = match kind {
            "gray_scott" => Some(p.try_clone("add_grid").map_err(|e| to_py(py, e))?),
            "wave" => Some(p.try_clone_except("add_wave", &["mask"]).map_err(|e| to_py(py, e))?),
            "stable_fluid" => Some(p.try_clone_except("add_fluid", &["obstacles"]).map_err(|e| to_py(py, e))?),
            _ => None,
        };
        let sys = crate::grids::build::build(kind, name, dim, p).map_err(|e| to_py(py, e))?;
        with_sim!(&mut self.inner, s => s.add_system(sys)).map_err(|e| to_py(py, e))?;
        self.grids.push((kind.to_string(), name.to_string(), record));
        Ok(())
    }

    /// Adds points advected by a flow (`crate::systems::flows::build`) of `kind` named `name`,
    /// built from `params`.
    fn add_flow(&mut self, py: Python<'_>, kind: &str, name: &str, params: &Bound<'_, PyDict>) -> PyResult<()> {
        let p = params_of(py, "add_flow", params)?;
        let dim = self.dim();
        let sys = crate::systems::flows::build(kind, name, dim, p).map_err(|e| to_py(py, e))?;
        with_sim!(&mut self.inner, s => s.add_system(sys)).map(drop).map_err(|e| to_py(py, e))
    }

    /// Adds a group of rigid bodies (`systems::bodies`) to the system "bodies" (made, with its
    /// coupling to the particles, at the first group); returns the number of its first body.
    /// Ctrl-C while its shape is built stops the call within `SIGNAL_POLL` (`add_group`).
    fn add_bodies(&mut self, py: Python<'_>, params: &Bound<'_, PyDict>) -> PyResult<usize> {
        let p = params_of(py, "add_bodies", params)?;
        match &mut self.inner {
            Inner::D2(s) => add_group::<_, Bodies2>(py, s, p),
            Inner::D3(s) => add_group::<_, Bodies3>(py, s, p),
        }
    }

    /// Adds joints between rigid bodies (`systems::bodies::Bodies2::add_joints`).
    fn add_joints(&mut self, py: Python<'_>, params: &Bound<'_, PyDict>) -> PyResult<()> {
        let p = params_of(py, "add_joints", params)?;
        with_bodies!(self, false, b => b.add_joints(p)).map_err(|e| to_py(py, e))
    }

    /// Pins particles to rigid bodies (`systems::bodies::Bodies2::add_pins`).
    fn add_pins(&mut self, py: Python<'_>, params: &Bound<'_, PyDict>) -> PyResult<()> {
        let p = params_of(py, "add_pins", params)?;
        with_bodies!(self, false, b => b.add_pins(p)).map_err(|e| to_py(py, e))
    }

    /// Body `i`'s shape as triangles in its own frame (3D bodies only): vertices (V, 3) float64
    /// m and corner indices (T, 3) uint32 (`systems::bodies::Bodies3::body_mesh`).
    #[allow(clippy::type_complexity)]
    fn body_mesh<'py>(
        &mut self,
        py: Python<'py>,
        i: usize,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<u32>>)> {
        let (v, t) = with_bodies!(self, false, b => b.body_mesh(i)).map_err(|e| to_py(py, e))?;
        let (nv, nt) = (v.len() / 3, t.len() / 3);
        let v = numpy::PyArray1::from_vec(py, v).reshape([nv, 3])?;
        let t = numpy::PyArray1::from_vec(py, t).reshape([nt, 3])?;
        Ok((v, t))
    }

    /// The fields `names` of system `name`, each a flat float64 array (the grid's layout).
    fn system_fields<'py>(
        &self,
        py: Python<'py>,
        name: &str,
        names: Vec<String>,
    ) -> PyResult<Vec<Bound<'py, PyArray1<f64>>>> {
        let names: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
        let inner = &self.inner;
        let f = py.detach(|| with_sim!(inner, s => s.other(name).and_then(|o| s.run(|| o.fields(&names)))));
        Ok(f.map_err(|e| to_py(py, e))?.into_iter().map(|v| Array1::from(v).into_pyarray(py)).collect())
    }

    /// Sets field `field` of system `name` (checked; nothing changes on error).
    fn set_system_field(
        &mut self,
        py: Python<'_>,
        name: &str,
        field: &str,
        values: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<()> {
        let v = slice1(&values, field)?;
        with_sim!(&mut self.inner, s => s.other_mut(name).and_then(|o| o.set_field(field, v))).map_err(|e| to_py(py, e))
    }

    /// The books of system `name` that are not energies, as (name, value) pairs.
    fn system_books(&self, py: Python<'_>, name: &str) -> PyResult<Vec<(String, f64)>> {
        let inner = &self.inner;
        py.detach(|| with_sim!(inner, s => s.other(name).map(|o| s.run(|| o.books())))).map_err(|e| to_py(py, e))
    }

    /// Everything a restart of system `name` needs, as (name, flat float64 array) pairs.
    /// The names of the world's systems besides the particles (rigid bodies, grids, flows,
    /// the particles on a device), in the order they joined.
    fn system_names(&self) -> Vec<String> {
        with_sim!(&self.inner, s => s.other_names())
    }

    /// What parts have registered here, counted: (particles, terms, colliders, the systems'
    /// names). The facade compares it before and after a part joins: a Ctrl-C raised as one of
    /// the part's calls returned leaves the core holding what the scene has not recorded.
    fn structure(&self) -> (usize, usize, usize, Vec<String>) {
        (self.n_particles(), self.terms.len(), self.colliders.len(), with_sim!(&self.inner, s => s.other_names()))
    }

    fn system_save<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Vec<(String, Bound<'py, PyArray1<f64>>)>> {
        let a = with_sim!(&self.inner, s => s.other(name).and_then(|o| o.save())).map_err(|e| to_py(py, e))?;
        Ok(a.into_iter().map(|(k, v)| (k, Array1::from(v).into_pyarray(py))).collect())
    }

    /// Loads what `system_save` wrote (every array checked first).
    fn system_load(
        &mut self,
        py: Python<'_>,
        name: &str,
        arrays: Vec<(String, PyReadonlyArray1<'_, f64>)>,
    ) -> PyResult<()> {
        let mut a = Vec::with_capacity(arrays.len());
        for (k, v) in &arrays {
            let s = slice1(v, k)?;
            let need = Need::new(
                "load",
                Need::bytes_of::<f64>(s.len()),
                format!("a copy of {name}'s {k} ({} values)", count(s.len() as u128)),
            );
            a.push((k.clone(), need.copy(s).map_err(|e| to_py(py, e))?));
        }
        with_sim!(&mut self.inner, s => s.other_mut(name).and_then(|o| o.load(&a))).map_err(|e| to_py(py, e))
    }

    /// Appends a collider of registered type `kind` (`constraints::registry`: "plane", "box",
    /// "sphere", "capsule") built from `params` to the projection stage (checked; nothing changes
    /// on error).
    fn add_collider(&mut self, py: Python<'_>, kind: &str, params: &Bound<'_, PyDict>) -> PyResult<()> {
        let ty = constraints::registry::lookup(kind).map_err(|e| to_py(py, e))?;
        let p = params_of(py, ty.kind, params)?;
        with_sim!(&mut self.inner, s => ty.build(&p).map(|c| s.particles_mut().add_constraint(c)))
            .map_err(|e| to_py(py, e))?;
        self.colliders.push((ty.kind.to_string(), p));
        self.stamp = fresh_stamp();
        Ok(())
    }

    /// Runs n steps in Rust with the GIL released. Ctrl-C is noticed within about
    /// `SIGNAL_POLL` plus a fraction of a millisecond of kernel work (see `interruptible`): the
    /// state is rolled back to where the call started and KeyboardInterrupt is raised.
    fn step(&mut self, py: Python<'_>, n: u64) -> PyResult<()> {
        with_sim!(&mut self.inner, s => {
            if s.particles().adaptive_stats().is_none() && n.saturating_mul(s.elements() as u64) <= SHORT_CALL {
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
        let (c, b) = with_sim!(&self.inner, s => s.particles().fluid_profile());
        ((c[0], c[1], c[2]), b)
    }

    /// (density, pressure) of every particle, (N,) float64 each; 0 outside fluids.
    fn fluid_fields<'py>(&self, py: Python<'py>) -> PyResult<Columns<'py>> {
        let (inner, on) = (&self.inner, self.on_device);
        // On a device the fluid's fields are its system's (the host's particles are gone).
        let (r, p) = py
            .detach(|| {
                with_sim!(inner, s => match device_fields(s, on, &["density", "pressure"]) {
                    Some(f) => f.map(|mut f| (std::mem::take(&mut f[0]), std::mem::take(&mut f[1]))),
                    None => s.fluid_fields(),
                })
            })
            .map_err(|e| to_py(py, e))?;
        Ok((Array1::from(r).into_pyarray(py), Array1::from(p).into_pyarray(py)))
    }

    /// The energy books; O(N²) with pairwise gravity, so Ctrl-C interrupts it (nothing changes).
    fn energy<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        with_sim!(&mut self.inner, s => s.prepare_energy()).map_err(|e| to_py(py, e))?;
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

    /// The per-particle output fields `names` of the terms (`Term::fields`), (N,) float64 each;
    /// 0 where a field is not defined.
    fn particle_fields<'py>(&self, py: Python<'py>, names: Vec<String>) -> PyResult<Vec<Bound<'py, PyArray1<f64>>>> {
        let names: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
        let (inner, on) = (&self.inner, self.on_device);
        // On a device the fields are its system's (a device fluid's density and pressure).
        let f = py
            .detach(|| with_sim!(inner, s => device_fields(s, on, &names).unwrap_or_else(|| s.fields(&names))))
            .map_err(|e| to_py(py, e))?;
        Ok(f.into_iter().map(|v| Array1::from(v).into_pyarray(py)).collect())
    }

    /// Each term's real-valued statistics (`Term::stats`): (term name, statistic, value).
    fn term_stats(&self) -> Vec<(String, &'static str, f64)> {
        let on = self.on_device;
        with_sim!(&self.inner, s => {
            let mut out = s.particles().term_stats();
            if on {
                // The device system stands in for the terms it took (`System::term_stats`).
                out.extend(s.other(DEVICE).ok().and_then(|d| d.as_held_terms()).map(|h| h.term_stats()).unwrap_or_default());
            }
            out
        })
    }

    /// Each term's counters (`Term::counts`): (term name, counter, value).
    fn term_counts(&self) -> Vec<(String, &'static str, u64)> {
        let on = self.on_device;
        with_sim!(&self.inner, s => {
            let mut out = s.particles().term_counts();
            if on {
                // The device system stands in for the terms it took (`System::term_counts`).
                out.extend(s.other(DEVICE).ok().and_then(|d| d.as_held_terms()).map(|h| h.term_counts()).unwrap_or_default());
            }
            out
        })
    }

    /// The own state of term `name` (contacts: spins and springs) as a flat float64 array, or
    /// None if it keeps none.
    fn term_history<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        // The device system answers for the terms it took (a DFSPH fluid's warm starts, in
        // the CPU term's layout; None for those that keep nothing): the host's particle system
        // is empty then.
        if self.on_device && self.terms.iter().any(|(_, n, _)| n == name) {
            let h = with_sim!(&self.inner, s => match s.other(DEVICE) {
                Ok(d) => d.as_held_terms().map_or(Ok(None), |h| h.term_history(name)),
                Err(_) => Ok(None),
            })
            .map_err(|e| to_py(py, e))?;
            return Ok(h.map(|h| Array1::from(h).into_pyarray(py)));
        }
        let h = with_sim!(&self.inner, s => s.particles().term_history(name)).map_err(|e| to_py(py, e))?;
        Ok(h.map(|h| Array1::from(h).into_pyarray(py)))
    }

    /// Restores what `term_history` returned (checked; nothing changes on error).
    fn set_term_history(&mut self, py: Python<'_>, name: &str, history: PyReadonlyArray1<'_, f64>) -> PyResult<()> {
        let h = slice1(&history, "history")?;
        if self.on_device && self.terms.iter().any(|(_, n, _)| n == name) {
            return with_sim!(&mut self.inner, s => s.other_mut(DEVICE).and_then(|d| match d.as_held_terms_mut() {
                Some(held) => held.set_term_history(name, h),
                None => Err(invalid(name, "the device holds no term of this name with a history")),
            }))
            .map_err(|e| to_py(py, e));
        }
        with_sim!(&mut self.inner, s => s.particles_mut().set_term_history(name, h)).map_err(|e| to_py(py, e))
    }

    /// (per-term dissipated energy in term order, collisions), J.
    fn ledger(&self) -> (Vec<f64>, f64) {
        with_sim!(&self.inner, s => (s.particles().forces().dissipated.clone(), s.particles().constraints_dissipated()))
    }

    /// Cached forces (N, dim) and term powers carried between steps, or None.
    fn integrator_cache<'py>(&self, py: Python<'py>) -> PyResult<Option<CacheArrays<'py>>> {
        with_sim!(&self.inner, s => {
            let cache = s.particles().try_integrator_cache("integrator_cache").map_err(|e| to_py(py, e))?;
            cache.map(|(f, p)| Ok((to_array2(py, &f, "integrator_cache")?, p))).transpose()
        })
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

/// Two (N,) float64 arrays (density and pressure).
type Columns<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// A fallible copy of the (N,) array `a`, for the getter `what` (`of`: which array).
fn copy_of(a: &[f64], what: &'static str, of: &str) -> crate::error::Result<Vec<f64>> {
    Need::new(what, Need::bytes_of::<f64>(a.len()), format!("a copy of {of} ({} values)", count(a.len() as u128)))
        .copy(a)
}

/// `$body` with `$b` the world's rigid-body system (`bodies_of`, as the `RigidBodies` role;
/// made first, of the scene's dimension, if `$make`).
macro_rules! with_bodies {
    ($self:expr, $make:expr, $b:ident => $body:expr) => {
        match &mut $self.inner {
            Inner::D2(s) => bodies_of::<_, Bodies2>(s, $make).and_then(|$b| $body),
            Inner::D3(s) => bodies_of::<_, Bodies3>(s, $make).and_then(|$b| $body),
        }
    };
}
use with_bodies;

/// The world's "bodies" system, as its `RigidBodies` role; made (a `B`: `Bodies2` or
/// `Bodies3`), with its particle coupling, if missing and `make` (else refused: joints need
/// bodies first).
fn bodies_of<V: Vector, B: BodiesKind<V>>(
    s: &mut World<V>,
    make: bool,
) -> crate::error::Result<&mut dyn crate::systems::RigidBodies> {
    if !s.others().iter().any(|o| o.name() == "bodies") {
        if !make {
            return Err(invalid("a", "the scene has no rigid bodies yet: add Bodies before their joints"));
        }
        let k = s.add_system(Box::new(B::make("bodies")))?;
        s.add_coupling(B::coupling(k));
    }
    s.other_mut("bodies")?
        .as_rigid_bodies()
        .ok_or_else(|| invalid("a", "the scene's system \"bodies\" is not rigid bodies"))
}

/// Adds a group of bodies to `s`: checked and its shape built first, with the GIL released while
/// this thread runs Python's signal handlers (`watched`): a convex hull of 200,000 vertices
/// takes seconds, and Ctrl-C then stops the build at once with nothing added (it left the core
/// holding a body the scene did not know of). Then the system "bodies" is made if missing (a
/// refused group leaves none) and the group put in it, unwatched: a Ctrl-C during that insertion
/// (1.4 ms for 1,000 balls, 0.4 s for 100,000) is raised once the call returns, with the group
/// in the core; the scene then records it too (`Scene._add`, `Bodies._taken_despite`).
fn add_group<V: Vector, B: BodiesKind<V>>(py: Python<'_>, s: &mut World<V>, p: Params) -> PyResult<usize> {
    let group = match watched(py, s, |_, stop| B::build(p, stop)) {
        (Ok(g), None) => g,
        (_, Some(e)) => return Err(e),
        (Err(Error::Interrupted { .. }), None) => return Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(())),
        (Err(e), None) => return Err(to_py(py, e)),
    };
    // A signal that came as the build ended: still nothing added.
    py.check_signals()?;
    // Memory too is checked before the system is made, so that a refused group leaves none.
    let existing = s.others().iter().find(|o| o.name() == "bodies").map_or(0, |o| o.size());
    B::room(&group, existing).map_err(|e| to_py(py, e))?;
    let dt = s.dt();
    bodies_of::<V, B>(s, true)
        .and_then(|b| {
            b.hint_dt(dt);
            B::insert(b, group)
        })
        .map_err(|e| to_py(py, e))
}

/// The rigid-body system of a dimension, its coupling to the particles, and its groups.
trait BodiesKind<V: Vector>: crate::systems::System + 'static {
    type Group: Send;
    fn make(name: &str) -> Self;
    fn coupling(k: usize) -> Box<dyn crate::systems::Coupling<V>>;
    fn build(p: Params, stop: &AtomicBool) -> crate::error::Result<Self::Group>;
    fn room(g: &Self::Group, existing: usize) -> crate::error::Result<()>;
    fn insert(b: &mut dyn crate::systems::RigidBodies, g: Self::Group) -> crate::error::Result<usize>;
}

impl BodiesKind<DVec2> for Bodies2 {
    type Group = Group2;
    fn make(name: &str) -> Self {
        Bodies2::new(name)
    }
    fn coupling(k: usize) -> Box<dyn crate::systems::Coupling<DVec2>> {
        Box::new(crate::systems::bodies::BodyContacts2::new(k))
    }
    fn build(p: Params, stop: &AtomicBool) -> crate::error::Result<Group2> {
        Bodies2::build_group(p, stop)
    }
    fn room(g: &Group2, existing: usize) -> crate::error::Result<()> {
        g.room(existing)
    }
    fn insert(b: &mut dyn crate::systems::RigidBodies, g: Group2) -> crate::error::Result<usize> {
        match b.bodies() {
            BodiesOf::Two(b) => b.insert_group(g),
            BodiesOf::Three(_) => Err(invalid("item", "these bodies are 2D and the scene's are 3D")),
        }
    }
}

impl BodiesKind<DVec3> for Bodies3 {
    type Group = Group3;
    fn make(name: &str) -> Self {
        Bodies3::new(name)
    }
    fn coupling(k: usize) -> Box<dyn crate::systems::Coupling<DVec3>> {
        Box::new(crate::systems::bodies::BodyContacts3::new(k))
    }
    fn build(p: Params, stop: &AtomicBool) -> crate::error::Result<Group3> {
        Bodies3::build_group(p, stop)
    }
    fn room(g: &Group3, existing: usize) -> crate::error::Result<()> {
        g.room(existing)
    }
    fn insert(b: &mut dyn crate::systems::RigidBodies, g: Group3) -> crate::error::Result<usize> {
        match b.bodies() {
            BodiesOf::Three(b) => b.insert_group(g),
            BodiesOf::Two(_) => Err(invalid("item", "these bodies are 3D and the scene's are 2D")),
        }
    }
}
