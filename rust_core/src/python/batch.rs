//! Many scenes stepped in one call (the `Batch` of the facade): every member's `step(n)` as it
//! would run alone, members in parallel on one pool with the GIL released, Ctrl-C rolling back
//! the whole call, and a member that diverges rolled back alone while the others go on.
//!
//! Each member is its own `World`: nothing is shared between members, and a world's results do
//! not depend on the thread that steps it or on its pool's size (`par`), so each member is
//! bit-identical to stepping it alone, for any thread count. A member's own parallel loops fork
//! onto its own pool (`World::with_stop` installs it on the stepping thread), which only the
//! large members reach (`par::PAR_MIN`). Small N-body members are stepped by the core's fused
//! kernel instead, one member per SIMD lane (`crate::batch`), with the same bits.
use super::errors::*;
use super::simulation::PySimulation;
use super::watch::{SHORT_CALL, SIGNAL_POLL};
use super::Inner;
use crate::batch::Call;
use crate::error::{invalid, Error};
use crate::par::SyncPtr;
use pyo3::prelude::*;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Every simulation of `sims` borrowed mutably for the call; `InvalidInputError` naming `sims`
/// (its entry) if one is in use (given twice, or being stepped by another thread).
fn borrow_all<'py>(py: Python<'py>, sims: &[Bound<'py, PySimulation>]) -> PyResult<Vec<PyRefMut<'py, PySimulation>>> {
    sims.iter()
        .enumerate()
        .map(|(k, s)| {
            s.try_borrow_mut().map_err(|_| {
                to_py(
                    py,
                    invalid("sims", format!("entry {k} is in use (given twice, or being stepped by another thread)")),
                )
            })
        })
        .collect()
}

/// The pool a batch call runs on: `threads` threads, or the default pool (`None`). A pool of
/// `threads` threads is kept for the next call (the last few sizes asked for): built anew each
/// call, its thread's start was most of a short call's time.
fn batch_pool(py: Python<'_>, threads: Option<usize>) -> PyResult<Arc<rayon::ThreadPool>> {
    use std::sync::Mutex;
    static POOLS: Mutex<Vec<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(Vec::new());
    const KEPT: usize = 4;
    let err = |threads: usize, reason: String| to_py(py, Error::Threads { threads, reason });
    let Some(t) = threads else {
        return crate::par::default_pool().map_err(|e| err(0, e));
    };
    let t = t.max(1);
    let mut pools = POOLS.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, p)) = pools.iter().find(|(k, _)| *k == t) {
        return Ok(p.clone());
    }
    let p = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(t).build().map_err(|e| err(t, e.to_string()))?);
    if pools.len() == KEPT {
        pools.remove(0); // its threads end once no call holds it
    }
    pools.push((t, p.clone()));
    Ok(p)
}

/// Steps every member `n` steps on the current pool: through `crate::batch::step_worlds` (its
/// fused kernel for small N-body members) where all have one dimension, else one by one.
fn step_members(inners: Vec<&mut Inner>, n: u64, stop: &Arc<AtomicBool>) -> Call {
    let d2 = inners.iter().all(|i| matches!(i, Inner::D2(_)));
    let d3 = inners.iter().all(|i| matches!(i, Inner::D3(_)));
    if d2 {
        let worlds = inners.into_iter().filter_map(|i| if let Inner::D2(w) = i { Some(w) } else { None }).collect();
        crate::batch::step_worlds(worlds, n, stop, crate::simd::level())
    } else if d3 {
        let worlds = inners.into_iter().filter_map(|i| if let Inner::D3(w) = i { Some(w) } else { None }).collect();
        crate::batch::step_worlds(worlds, n, stop, crate::simd::level())
    } else {
        Call::general(
            inners.into_par_iter().map(|inner| with_sim!(inner, s => s.step_checkpointed(n, stop))).collect(),
            n,
        )
    }
}

/// Steps each of `sims` `n` steps (`Simulation.step`), in parallel over members on a pool of
/// `threads` threads (`None`: all cores). Returns `(index, exception)` for each member that
/// failed as it would have alone (a `SimulationDiverged`: that member is back where the call
/// started); the others stepped. Ctrl-C (any exception a signal handler raises) rolls every
/// member back and is raised. Before anything runs: `InvalidInputError` naming `sims` if one
/// simulation is given twice, naming `n` if it would take a member's step count past 2**63 - 1.
#[pyfunction]
#[pyo3(signature = (sims, n, threads=None))]
pub(super) fn step_batch(
    py: Python<'_>,
    sims: Vec<Bound<'_, PySimulation>>,
    n: u64,
    threads: Option<usize>,
) -> PyResult<Vec<(usize, Py<PyAny>)>> {
    let mut refs = borrow_all(py, &sims)?;
    if refs.iter_mut().any(|r| n > crate::world::MAX_STEPS - with_sim!(r.inner_mut(), s => s.steps())) {
        let e = invalid("n", format!("{n} more steps would take a member's step count past 2**63 - 1"));
        return Err(to_py(py, e));
    }
    let pool = batch_pool(py, threads)?;
    let ptrs: Vec<SyncPtr<Inner>> = refs.iter_mut().map(|r| SyncPtr(r.inner_mut() as *mut Inner)).collect();
    // A short call (at most SHORT_CALL steps × elements over all members, none adaptive) runs
    // unwatched, as a scene's short step does: the calling thread waits for the pool without a
    // watching thread, whose start was most of such a call's time. Signals are checked once it
    // ends (a signal then undoes the call, as below).
    let short = refs
        .iter_mut()
        .try_fold(0u64, |total, r| {
            with_sim!(r.inner_mut(), s => {
                let work = n.saturating_mul(s.elements() as u64);
                s.particles().adaptive_stats().is_none().then(|| total.saturating_add(work))
            })
        })
        .is_some_and(|total| total <= SHORT_CALL);
    let stop = Arc::new(AtomicBool::new(false));
    let run = || {
        pool.install(|| {
            // SAFETY: each pointer is a distinct simulation (each was borrowed mutably above,
            // and the borrows outlive this call), used by one task at a time.
            let inners: Vec<&mut Inner> = ptrs.iter().map(|p| unsafe { &mut *p.0 }).collect();
            step_members(inners, n, &stop)
        })
    };
    // A signal during the call, or right after it: every member goes back to where it started
    // (those that stopped on the flag, or diverged, already are; a fused member was never
    // written). Else each member's steps are kept: a fused member written back now.
    let (mut call, pending): (Call, _) = if short {
        let call = py.detach(run);
        (call, py.check_signals().err())
    } else {
        with_signals(py, &stop, run)
    };
    // A member refused memory: every member back where the call started, and the refusal
    // raised (it says nothing changed; the others had stepped).
    let oom = if pending.is_none() { call.out_of_memory() } else { None };
    let keep = pending.is_none() && oom.is_none();
    let mut failed = Vec::new();
    for (k, r) in refs.iter_mut().enumerate() {
        if let Err(e) = with_sim!(r.inner_mut(), s => call.end(k, s, keep)) {
            failed.push((k, to_py(py, e).into_value(py).into_any()));
        }
    }
    if let Some((_, e)) = oom {
        return Err(to_py(py, e));
    }
    match pending {
        Some(e) => Err(e),
        None => Ok(failed),
    }
}

/// Every member's positions (`velocities` false) or velocities as one new (M, N, dim) float64
/// array, member k's rows `[k]` (`Batch.positions`: one copy where a Python call a member and a
/// stack took 20-30 ms at 16,384 members); `None` where a member's particles live on a device
/// or are single precision, a member is in use, or the members' shapes differ (the caller
/// reads them one by one, and says so for a member in use). `OutOfMemoryError` for the array.
#[pyfunction]
pub(super) fn batch_rows<'py>(
    py: Python<'py>,
    sims: Vec<Bound<'py, PySimulation>>,
    velocities: bool,
) -> PyResult<Option<Bound<'py, numpy::PyArray3<f64>>>> {
    use numpy::IntoPyArray;
    // A member in use (another thread stepping it) is read alone by the caller, which says so.
    let Ok(refs) = sims.iter().map(|s| s.try_borrow()).collect::<Result<Vec<_>, _>>() else {
        return Ok(None);
    };
    let Some(Some((first, dim))) = refs.first().map(|r| r.rows(velocities)) else {
        return Ok(None);
    };
    let (m, len) = (refs.len(), first.len());
    let what = if velocities { "velocities" } else { "positions" };
    let need = crate::alloc::Need::new(
        what,
        crate::alloc::Need::bytes_of::<f64>(m) * len as u128,
        format!("{m} members' {what}"),
    );
    let mut flat = Vec::new();
    need.reserve(&mut flat, m * len).map_err(|e| to_py(py, e))?;
    for r in &refs {
        match r.rows(velocities) {
            Some((rows, d)) if d == dim && rows.len() == len => flat.extend_from_slice(rows),
            _ => return Ok(None),
        }
    }
    let shape = (m, len / dim.max(1), dim);
    Ok(Some(numpy::ndarray::Array3::from_shape_vec(shape, flat).expect("shape matches").into_pyarray(py)))
}

/// Each of `sims`' energy books reduced as `physcore.session.books` reduces them in Python
/// (the same additions in the same order, a repeated name counted once as a dict keeps it):
/// `(total, scale)` with total = (kinetic + Σ potential) + Σ dissipated and scale = (|kinetic|
/// + Σ |potential|) + Σ |dissipated|; `None` for a member whose books could not be prepared
/// (out of memory), which the caller then reads alone. In parallel on a pool of `threads`
/// threads with the GIL released: the batch's first step takes every member's reference at
/// once instead of one Python call each, and `Batch.energy_total` and `energy_drift` read every
/// member's books so. Not interruptible: the caller passes small members.
#[pyfunction]
#[pyo3(signature = (sims, threads=None))]
pub(super) fn reference_energies(
    py: Python<'_>,
    sims: Vec<Bound<'_, PySimulation>>,
    threads: Option<usize>,
) -> PyResult<Vec<Option<(f64, f64)>>> {
    let mut refs = borrow_all(py, &sims)?;
    let pool = batch_pool(py, threads)?;
    let ptrs: Vec<SyncPtr<Inner>> = refs.iter_mut().map(|r| SyncPtr(r.inner_mut() as *mut Inner)).collect();
    Ok(py.detach(|| {
        pool.install(|| {
            ptrs.par_iter()
                .map(|p| {
                    // SAFETY: distinct simulations, each borrowed mutably above for this call.
                    let inner = unsafe { &mut *p.0 };
                    with_sim!(inner, s => {
                        s.prepare_energy().ok()?;
                        let e = s.energy();
                        let (pot, dis) = (as_dict(&e.potential), as_dict(&e.dissipated));
                        let total = (e.kinetic + sum(pot.iter().copied())) + sum(dis.iter().copied());
                        let scale = (e.kinetic.abs() + sum(pot.iter().map(|u| u.abs()))) + sum(dis.iter().map(|d| d.abs()));
                        Some((total, scale))
                    })
                })
                .collect()
        })
    }))
}

/// The values of `(name, value)` pairs as a Python dict built from them holds them: in order of
/// first appearance, a repeated name keeping its last value.
fn as_dict(pairs: &[(String, f64)]) -> Vec<f64> {
    let mut names: Vec<&str> = Vec::with_capacity(pairs.len());
    let mut values: Vec<f64> = Vec::with_capacity(pairs.len());
    for (k, v) in pairs {
        match names.iter().position(|n| n == k) {
            Some(i) => values[i] = *v,
            None => {
                names.push(k);
                values.push(*v);
            }
        }
    }
    values
}

/// `physcore.session.left_sum`: from 0.0, left to right.
fn sum(values: impl Iterator<Item = f64>) -> f64 {
    values.fold(0.0, |s, v| s + v)
}

/// Runs `f` with the GIL released on a thread of its own while the calling thread runs Python's
/// signal handlers every `SIGNAL_POLL` (as `watch::watched` does for one world); a handler's
/// exception (Ctrl-C) sets `stop` and is returned beside `f`'s result, as is one raised by the
/// handlers run once more right after `f` ends.
fn with_signals<T: Send>(py: Python<'_>, stop: &AtomicBool, f: impl FnOnce() -> T + Send) -> (T, Option<PyErr>) {
    let mut pending: Option<PyErr> = None;
    let out = py.detach(|| {
        // A channel, not park/unpark and `is_finished`: the job's unpark could come before it
        // counted as finished, and the caller then slept a whole `SIGNAL_POLL` (20 ms) after a
        // short call. The sender dropped (the job returned or panicked) ends the wait.
        let (done, wait) = std::sync::mpsc::channel::<()>();
        std::thread::scope(|scope| {
            let job = scope.spawn(move || {
                let _done = done;
                f()
            });
            while let Err(std::sync::mpsc::RecvTimeoutError::Timeout) = wait.recv_timeout(SIGNAL_POLL) {
                if pending.is_none() {
                    if let Err(e) = Python::attach(|py| py.check_signals()) {
                        pending = Some(e);
                        stop.store(true, Ordering::Relaxed);
                    }
                }
            }
            job.join().unwrap_or_else(|p| std::panic::resume_unwind(p))
        })
    });
    if pending.is_none() {
        pending = py.check_signals().err();
    }
    (out, pending)
}

/// The worlds of `refs`, all of one dimension: `(Some(2D), None)` or `(None, Some(3D))`;
/// `InvalidInput` naming `sims` for a mix.
#[cfg(feature = "gpu")]
#[allow(clippy::type_complexity)]
fn worlds_of<'a>(
    refs: &'a mut [PyRefMut<'_, PySimulation>],
) -> crate::error::Result<(Vec<&'a mut crate::world::World<glam::DVec2>>, Vec<&'a mut crate::world::World<glam::DVec3>>)>
{
    let (mut d2, mut d3) = (Vec::new(), Vec::new());
    for r in refs.iter_mut() {
        match r.inner_mut() {
            Inner::D2(w) => d2.push(w),
            Inner::D3(w) => d3.push(w),
        }
    }
    if !d2.is_empty() && !d3.is_empty() {
        return Err(invalid("sims", "the members of a batch have one dimension"));
    }
    Ok((d2, d3))
}

/// Every member of a batch on one device (`Batch(..., device="gpu")`): see
/// `systems::device_batch`. Built from the members' simulations (which stay CPU simulations);
/// `step` runs them on the device in one dispatch per stage, keeping their state there and in
/// a mirror on the host, and `settle` writes a member back from the mirror when it is read
/// (the facade's `Session.checked` asks for it).
#[cfg(feature = "gpu")]
#[pyclass(module = "physcore._core", name = "DeviceBatch")]
pub(super) struct PyDeviceBatch {
    inner: crate::systems::device_batch::DeviceBatch,
    /// The members' records stamps at the build (`PySimulation::records_stamp`).
    stamps: Vec<u64>,
    /// The members' simulations, in order: a call names the members it reads by index.
    sims: Vec<Py<PySimulation>>,
}

#[cfg(feature = "gpu")]
fn records_of(
    py: Python<'_>,
    refs: &[PyRefMut<'_, PySimulation>],
) -> PyResult<Vec<crate::systems::device_batch::Records>> {
    refs.iter().enumerate().map(|(k, r)| r.device_records(k).map_err(|e| to_py(py, e))).collect()
}

#[cfg(feature = "gpu")]
impl PyDeviceBatch {
    /// InvalidInputError unless the worlds `worlds_of` split into `n2` of 2D and `n3` of 3D are
    /// all of the batch's dimension.
    fn one_dim(&self, py: Python<'_>, n2: usize, n3: usize) -> PyResult<()> {
        if (if self.inner.dim() == 2 { n3 } else { n2 }) > 0 {
            return Err(to_py(py, invalid("sims", "the members of a batch have one dimension")));
        }
        Ok(())
    }

    /// The simulations of the members `ks`; `InvalidInputError` naming `members` for an index
    /// past them.
    fn members<'py>(&self, py: Python<'py>, ks: &[usize]) -> PyResult<Vec<Bound<'py, PySimulation>>> {
        ks.iter()
            .map(|&k| {
                self.sims.get(k).map(|s| s.bind(py).clone()).ok_or_else(|| {
                    to_py(py, invalid("members", format!("{k} is past the batch's {} members", self.sims.len())))
                })
            })
            .collect()
    }
}

#[cfg(feature = "gpu")]
#[pymethods]
impl PyDeviceBatch {
    /// The members `sims` on the device `device` ("gpu", "gpu:NAME") at `precision` ("f32",
    /// "f64"). InvalidInputError naming what a device batch cannot hold (nothing changes).
    #[new]
    fn new(py: Python<'_>, sims: Vec<Bound<'_, PySimulation>>, device: &str, precision: &str) -> PyResult<Self> {
        use crate::systems::device_batch::DeviceBatch;
        let mut refs = borrow_all(py, &sims)?;
        let records = records_of(py, &refs)?;
        let gpu = py.detach(|| physcore_gpu::Gpu::open(device)).map_err(|e| to_py(py, e.into()))?;
        let (d2, d3) = worlds_of(&mut refs).map_err(|e| to_py(py, e))?;
        let inner = py
            .detach(|| {
                if d3.is_empty() {
                    let w: Vec<&_> = d2.iter().map(|w| &**w).collect();
                    DeviceBatch::new(gpu, precision, &w, records)
                } else {
                    let w: Vec<&_> = d3.iter().map(|w| &**w).collect();
                    DeviceBatch::new(gpu, precision, &w, records)
                }
            })
            .map_err(|e| to_py(py, e))?;
        let stamps = refs.iter().map(|r| r.records_stamp()).collect();
        drop(refs);
        Ok(Self { inner, stamps, sims: sims.into_iter().map(|s| s.unbind()).collect() })
    }

    /// The adapter and precision, e.g. "NVIDIA H100 (vulkan, f32)".
    #[getter]
    fn device(&self) -> String {
        self.inner.describe()
    }

    /// Steps every member not retired `n` steps on the device (GIL released), the members'
    /// state kept there and in its mirror between calls: `touched` names the members whose
    /// simulations may differ from the mirror (settled since the last call), checked and, if
    /// they changed, written to the device again; the others are not read at all. Returns the
    /// members that diverged, retired (`settle` writes them back, `diverged` gives their
    /// errors).
    /// Ctrl-C commits nothing (the mirror stays where the call started) and is raised. `None`,
    /// with nothing stepped, if a touched member is no longer what the batch was built from
    /// (its terms or colliders changed: their records' stamps differ): the caller builds it
    /// again.
    fn step(&mut self, py: Python<'_>, touched: Vec<usize>, n: u64) -> PyResult<Option<Vec<usize>>> {
        let sims = self.members(py, &touched)?;
        let mut refs = borrow_all(py, &sims)?;
        for (&k, r) in touched.iter().zip(&refs) {
            if self.stamps.get(k) != Some(&r.records_stamp()) || !r.device_records_ready() {
                return Ok(None);
            }
        }
        let (d2, d3) = worlds_of(&mut refs).map_err(|e| to_py(py, e))?;
        self.one_dim(py, d2.len(), d3.len())?;
        let idx = touched;
        let stop = AtomicBool::new(false);
        let inner = &mut self.inner;
        let (ran, pending) = with_signals(py, &stop, || {
            if inner.dim() == 2 {
                let t: Vec<_> = idx.iter().zip(&d2).map(|(&k, w)| (k, &**w)).collect();
                inner.run(&t, n, &stop)
            } else {
                let t: Vec<_> = idx.iter().zip(&d3).map(|(&k, w)| (k, &**w)).collect();
                inner.run(&t, n, &stop)
            }
        });
        if let Some(e) = pending {
            return Err(e); // nothing was committed
        }
        match ran {
            Ok(r) => Ok(Some(self.inner.commit(r))),
            Err(Error::Interrupted { .. }) => Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(())),
            Err(e) => Err(to_py(py, e)),
        }
    }

    /// Writes each of the members `members` from the mirror: its state, clock and books as if
    /// it had taken its steps alone (in parallel, the GIL released).
    fn settle(&self, py: Python<'_>, members: Vec<usize>) -> PyResult<()> {
        let sims = self.members(py, &members)?;
        let mut refs = borrow_all(py, &sims)?;
        let (mut d2, mut d3) = worlds_of(&mut refs).map_err(|e| to_py(py, e))?;
        self.one_dim(py, d2.len(), d3.len())?;
        let idx = members;
        let pool = batch_pool(py, None)?;
        let inner = &self.inner;
        py.detach(|| {
            pool.install(|| {
                if inner.dim() == 2 {
                    let mut t: Vec<_> = idx.iter().zip(d2.iter_mut()).map(|(&k, w)| (k, &mut **w)).collect();
                    inner.settle_all(&mut t)
                } else {
                    let mut t: Vec<_> = idx.iter().zip(d3.iter_mut()).map(|(&k, w)| (k, &mut **w)).collect();
                    inner.settle_all(&mut t)
                }
            })
        })
        .map_err(|e| to_py(py, e))
    }

    /// The exception the retired member `k` (settled) would have raised alone; None if it did
    /// not diverge.
    fn diverged(&self, py: Python<'_>, k: usize) -> PyResult<Option<Py<PyAny>>> {
        let sims = self.members(py, &[k])?;
        let mut r = borrow_all(py, &sims)?.pop().expect("one member");
        let e = match r.inner_mut() {
            Inner::D2(w) => self.inner.diverged(k, w),
            Inner::D3(w) => self.inner.diverged(k, w),
        };
        Ok(e.map(|e| to_py(py, e).into_value(py).into_any()))
    }

    /// Every member's positions (`velocities` false) or velocities, (m, n, dim) float64, with
    /// each member's time (m,) and step count (m,), as the mirror holds them (a retired member
    /// where its last call started).
    #[allow(clippy::type_complexity)]
    fn mirror<'py>(
        &self,
        py: Python<'py>,
        velocities: bool,
    ) -> PyResult<(Bound<'py, numpy::PyArray3<f64>>, Bound<'py, numpy::PyArray1<f64>>, Bound<'py, numpy::PyArray1<u64>>)>
    {
        use numpy::{IntoPyArray, PyArray1};
        let (rows, t, steps) = self.inner.mirror(velocities);
        let (m, dim) = (t.len(), self.inner.dim());
        let what = if velocities { "velocities" } else { "positions" };
        let need = crate::alloc::Need::new(
            what,
            crate::alloc::Need::bytes_of::<f64>(rows.len()),
            format!("{m} members' {what}"),
        );
        let mut flat = Vec::new();
        need.reserve(&mut flat, rows.len()).map_err(|e| to_py(py, e))?;
        flat.extend_from_slice(rows);
        let shape = (m, rows.len() / (m * dim).max(1), dim);
        let a = numpy::ndarray::Array3::from_shape_vec(shape, flat).expect("shape matches").into_pyarray(py);
        Ok((a, PyArray1::from_slice(py, t), PyArray1::from_slice(py, steps)))
    }
}
