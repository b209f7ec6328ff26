//! A simulation: state, model, force terms, integrator, colliders and the energy books.
use crate::alloc::{count, Need};
use crate::boundary::{Aabb, Collider, Plane};
use crate::error::{invalid, Error, Failure, Result};
use crate::integrators::{self, Integrator, IntegratorInfo, System};
use crate::par;
use crate::state::{Model, State};
use crate::stop::Stop;
use crate::terms::{ForceSet, Term};
use crate::vector::{Real, Vector};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::Arc;

/// The largest step count: files store it as an int64, and it must never wrap.
pub const MAX_STEPS: u64 = i64::MAX as u64;
use std::time::Duration;

/// Energy books at one instant (J). `total()` = kinetic + Σ potential + Σ dissipated is conserved
/// by the exact dynamics; its change is the integrator's error.
#[derive(Clone, Debug, PartialEq)]
pub struct EnergyReport {
    pub kinetic: Real,
    /// Potential energy of each conservative term, by term name.
    pub potential: Vec<(String, Real)>,
    /// Energy dissipated so far by each dissipative term and by the colliders ("collisions").
    pub dissipated: Vec<(String, Real)>,
}

impl EnergyReport {
    pub fn total(&self) -> Real {
        self.kinetic
            + self.potential.iter().map(|p| p.1).sum::<Real>()
            + self.dissipated.iter().map(|p| p.1).sum::<Real>()
    }
}

/// What `Simulation::rollback` restores (see `Simulation::checkpoint`).
pub struct Checkpoint<V: Vector> {
    state: State<V>,
    dissipated: Vec<Real>,
    collisions: Real,
    cache: Option<(Vec<V>, Vec<Real>)>,
    /// rk45's (accepted, rejected, next h): the counts are restored too.
    adaptive: Option<(u64, u64, Real)>,
    dt: Real,
}

pub struct Simulation<V: Vector> {
    pub sys: System<V>,
    integrator: Box<dyn Integrator<V>>,
    pub colliders: Vec<Collider<V>>,
    /// Energy removed by the colliders so far, J.
    pub collision_dissipated: Real,
    /// Time step, s.
    pub dt: Real,
    /// Tolerances of the adaptive integrator ("rk45"); kept when switching integrators.
    rtol: Real,
    atol: Real,
    /// The pool the stepping runs on; `None`: the calling thread only (see `sequential`).
    pool: Option<Arc<rayon::ThreadPool>>,
    /// Why there is no pool: the default one could not start its threads.
    sequential: Option<String>,
}

impl<V: Vector> Simulation<V> {
    /// `threads`: `None` shares `par::default_pool` (all cores, or `RAYON_NUM_THREADS`), or, if
    /// its threads cannot be started (a thread limit), runs on the calling thread only
    /// (`sequential()` says why); `Some(n)`: a pool of its own, `Error::Threads` if the n
    /// threads cannot be started.
    pub fn new(integrator: &str, dt: Real, threads: Option<usize>) -> Result<Self> {
        check_dt(dt)?;
        // A PHYSCORE_SIMD the CPU cannot honour is refused here, before any state exists.
        crate::simd::check()?;
        let integrator = integrators::by_name(integrator)?;
        let (pool, sequential) = match threads {
            None => match par::default_pool() {
                Ok(p) => (Some(p), None),
                Err(reason) => (None, Some(reason)),
            },
            Some(0) => return Err(invalid("threads", "must be >= 1 (or None for all cores)")),
            Some(n) => match rayon::ThreadPoolBuilder::new().num_threads(n).build() {
                Ok(p) => (Some(Arc::new(p)), None),
                Err(e) => return Err(Error::Threads { threads: n, reason: e.to_string() }),
            },
        };
        Ok(Self {
            sys: System {
                state: State::default(),
                model: Model::default(),
                forces: ForceSet::default(),
                single: false,
            },
            integrator,
            colliders: Vec::new(),
            collision_dissipated: 0.0,
            dt,
            rtol: 1e-6,
            atol: 1e-9,
            pool,
            sequential,
        })
    }

    fn run<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        par::install(self.pool.as_ref(), f)
    }

    /// Why this simulation runs on the calling thread only (its pool could not start its
    /// threads), if it does. Results are the same either way.
    pub fn sequential(&self) -> Option<&str> {
        self.sequential.as_deref()
    }

    pub fn n_particles(&self) -> usize {
        self.sys.state.x.len()
    }
    pub fn integrator_info(&self) -> IntegratorInfo {
        self.integrator.info()
    }
    pub fn set_integrator(&mut self, name: &str) -> Result<()> {
        let mut it = integrators::by_name(name)?;
        it.set_tolerances(self.rtol, self.atol);
        self.integrator = it;
        Ok(())
    }

    /// Relative and absolute (m, m/s) tolerances of the adaptive integrator; stored for any
    /// integrator, used by "rk45". rtol in [1e-14, 1), atol >= 0.
    pub fn set_tolerances(&mut self, rtol: Real, atol: Real) -> Result<()> {
        if !(rtol.is_finite() && (1e-14..1.0).contains(&rtol)) {
            return Err(invalid("rtol", format!("{rtol} must be in [1e-14, 1) (float64 cannot resolve less)")));
        }
        if !(atol.is_finite() && atol >= 0.0) {
            return Err(invalid("atol", format!("{atol} must be finite and >= 0 (m and m/s)")));
        }
        self.rtol = rtol;
        self.atol = atol;
        self.integrator.set_tolerances(rtol, atol);
        Ok(())
    }
    pub fn tolerances(&self) -> (Real, Real) {
        (self.rtol, self.atol)
    }
    /// (accepted, rejected internal steps, next internal step in s) for "rk45".
    pub fn adaptive_stats(&self) -> Option<(u64, u64, Real)> {
        self.integrator.adaptive_stats()
    }

    /// Single-precision state (`true`): positions and velocities are kept rounded to float32.
    /// Switching to it rounds the current state.
    pub fn set_single(&mut self, single: bool) {
        if single && !self.sys.single {
            for p in self.sys.state.x.iter_mut().chain(self.sys.state.v.iter_mut()) {
                *p = p.round_f32();
            }
            self.integrator.reset();
        }
        self.sys.single = single;
        for t in &mut self.sys.forces.terms {
            t.set_single(single);
        }
    }
    pub fn single(&self) -> bool {
        self.sys.single
    }

    /// With a single-precision state, values must fit float32 (|x| ≤ 3.4e38), or rounding
    /// would store infinities.
    fn check_single_range(&self, x: &[V], arg: &str) -> Result<()> {
        if self.sys.single {
            if let Some(i) = x.iter().position(|p| !p.round_f32().is_finite()) {
                return Err(invalid(arg, format!("row {i} does not fit float32 (precision=\"f32\"): {p:?}", p = x[i])));
            }
        }
        Ok(())
    }
    pub fn set_dt(&mut self, dt: Real) -> Result<()> {
        check_dt(dt)?;
        self.dt = dt;
        Ok(())
    }
    pub fn force_evaluations(&self) -> u64 {
        self.sys.forces.evaluations
    }

    /// Appends particles; returns the index of the first. Pinned particles get zero velocity.
    pub fn add_particles(&mut self, x: Vec<V>, mut v: Vec<V>, mass: Vec<Real>, pinned: Vec<bool>) -> Result<usize> {
        let n = x.len();
        if v.len() != n {
            return Err(invalid("velocities", format!("has {} rows, positions has {n}", v.len())));
        }
        if mass.len() != n {
            return Err(invalid("masses", format!("has {} entries, positions has {n}", mass.len())));
        }
        if pinned.len() != n {
            return Err(invalid("pinned", format!("has {} entries, positions has {n}", pinned.len())));
        }
        if let Some(i) = x.iter().position(|p| !p.is_finite()) {
            return Err(invalid("positions", format!("row {i} is not finite: {:?}", x[i])));
        }
        if let Some(i) = v.iter().position(|p| !p.is_finite()) {
            return Err(invalid("velocities", format!("row {i} is not finite: {:?}", v[i])));
        }
        if let Some(i) = mass.iter().position(|m| !(m.is_finite() && *m > 0.0)) {
            return Err(invalid("masses", format!("entry {i} is {} (must be finite and > 0)", mass[i])));
        }
        self.check_single_range(&x, "positions")?;
        self.check_single_range(&v, "velocities")?;
        let first = self.n_particles();
        let need = Need::new(
            "add_particles",
            Need::bytes_of::<V>(2 * n) + Need::bytes_of::<Real>(2 * n),
            format!("{} particles", count(n as u128)),
        );
        need.check()?;
        let total = first.checked_add(n).ok_or_else(|| need.error())?;
        need.reserve(&mut self.sys.state.x, total)?;
        need.reserve(&mut self.sys.state.v, total)?;
        need.reserve(&mut self.sys.model.mass, total)?;
        need.reserve(&mut self.sys.model.inv_mass, total)?;
        for (k, &p) in pinned.iter().enumerate() {
            if p {
                v[k] = V::ZERO;
            }
        }
        for a in self.sys.model.attributes.values_mut() {
            need.reserve(a, total)?;
        }
        self.sys.model.inv_mass.extend(mass.iter().zip(&pinned).map(|(m, &p)| if p { 0.0 } else { 1.0 / m }));
        self.sys.model.mass.extend(mass);
        for a in self.sys.model.attributes.values_mut() {
            a.resize(total, 0.0); // new particles hold 0 until set
        }
        let single = self.sys.single;
        self.sys.state.x.extend(x.into_iter().map(|p| integrators::store(p, single)));
        self.sys.state.v.extend(v.into_iter().map(|p| integrators::store(p, single)));
        self.integrator.reset();
        Ok(first)
    }

    /// Sets the optional per-particle attribute `name` (one of `state::ATTRIBUTES`) to `values`,
    /// one finite value per particle (radius: ≥ 0). Changes nothing on error.
    pub fn set_attribute(&mut self, name: &str, values: Vec<Real>) -> Result<()> {
        let Some(&(key, _)) = crate::state::ATTRIBUTES.iter().find(|(k, _)| *k == name) else {
            let known: Vec<_> = crate::state::ATTRIBUTES.iter().map(|(k, _)| *k).collect();
            return Err(invalid("name", format!("unknown attribute {name:?}; known: {}", known.join(", "))));
        };
        if values.len() != self.n_particles() {
            return Err(invalid(
                key,
                format!("has {} entries, the scene has {} particles", values.len(), self.n_particles()),
            ));
        }
        if let Some(i) = values.iter().position(|q| !q.is_finite() || (key == "radius" && *q < 0.0)) {
            let rule = if key == "radius" { "finite and >= 0" } else { "finite" };
            return Err(invalid(key, format!("entry {i} is {} (must be {rule})", values[i])));
        }
        self.sys.model.attributes.insert(key, values);
        self.integrator.reset();
        Ok(())
    }

    pub fn add_term(&mut self, t: Box<dyn Term<V>>) -> Result<()> {
        if self.sys.forces.terms.iter().any(|o| o.name() == t.name()) {
            return Err(invalid("name", format!("the scene already has a term named {:?}", t.name())));
        }
        if t.min_particles() > self.n_particles() {
            return Err(invalid(
                "term",
                format!("refers to {} particles, the scene has {}", t.min_particles(), self.n_particles()),
            ));
        }
        let mut t = t;
        t.set_single(self.sys.single);
        self.sys.forces.push(t);
        self.integrator.reset();
        Ok(())
    }

    pub fn add_plane(&mut self, p: Plane<V>) -> Result<()> {
        if !p.point.is_finite() {
            return Err(invalid("point", "must be finite"));
        }
        let l2 = p.normal.length_squared();
        if !(l2.is_finite() && l2 > 0.0) {
            return Err(invalid("normal", "must be finite and non-zero"));
        }
        if !(0.0..=1.0).contains(&p.restitution) {
            return Err(invalid("restitution", format!("{} is outside [0, 1]", p.restitution)));
        }
        if !(p.friction.is_finite() && p.friction >= 0.0) {
            return Err(invalid("friction", format!("{} must be finite and >= 0", p.friction)));
        }
        let normal = p.normal / l2.sqrt();
        self.colliders.push(Collider::Plane(Plane { normal, ..p }));
        Ok(())
    }

    pub fn add_box(&mut self, b: Aabb<V>) -> Result<()> {
        if !(b.lo.is_finite() && b.hi.is_finite()) {
            return Err(invalid("lower/upper", "must be finite"));
        }
        if (0..V::DIM).any(|k| !(b.hi.comp(k) > b.lo.comp(k))) {
            return Err(invalid("upper", "must be > lower on every axis"));
        }
        if !(0.0..=1.0).contains(&b.restitution) {
            return Err(invalid("restitution", format!("{} is outside [0, 1]", b.restitution)));
        }
        if !(b.friction.is_finite() && b.friction >= 0.0) {
            return Err(invalid("friction", format!("{} must be finite and >= 0", b.friction)));
        }
        self.colliders.push(Collider::Box(b));
        Ok(())
    }

    /// Replaces positions and/or velocities (same particle count), e.g. to restore a saved run.
    pub fn set_state(&mut self, x: Option<Vec<V>>, v: Option<Vec<V>>) -> Result<()> {
        let n = self.n_particles();
        if let Some(x) = &x {
            self.check_single_range(x, "positions")?;
            if x.len() != n {
                return Err(invalid("positions", format!("has {} rows, the scene has {n} particles", x.len())));
            }
            if let Some(i) = x.iter().position(|p| !p.is_finite()) {
                return Err(invalid("positions", format!("row {i} is not finite")));
            }
        }
        if let Some(v) = &v {
            self.check_single_range(v, "velocities")?;
            if v.len() != n {
                return Err(invalid("velocities", format!("has {} rows, the scene has {n} particles", v.len())));
            }
            if let Some(i) = v.iter().position(|p| !p.is_finite()) {
                return Err(invalid("velocities", format!("row {i} is not finite")));
            }
        }
        let single = self.sys.single;
        if let Some(mut x) = x {
            if single {
                x.iter_mut().for_each(|p| *p = p.round_f32());
            }
            self.sys.state.x = x;
        }
        if let Some(mut v) = v {
            for (i, vi) in v.iter_mut().enumerate() {
                if self.sys.model.is_pinned(i) {
                    *vi = V::ZERO;
                } else if single {
                    *vi = vi.round_f32();
                }
            }
            self.sys.state.v = v;
        }
        self.integrator.reset();
        Ok(())
    }

    /// Restores time, step count, the dissipation books and the integrator cache of a saved run.
    /// Restores what `save` wrote beside the state: time (s), step count, the energy books
    /// (J) and the integrator's cache. Every value is checked before anything changes.
    pub fn restore(
        &mut self,
        t: Real,
        step: u64,
        dissipated: &[Real],
        collisions: Real,
        cache: Option<(Vec<V>, Vec<Real>)>,
    ) -> Result<()> {
        if dissipated.len() != self.sys.forces.terms.len() {
            return Err(invalid("dissipated", "does not match the scene's terms"));
        }
        if !t.is_finite() {
            return Err(invalid("time", format!("must be finite, got {t}")));
        }
        if step > MAX_STEPS {
            return Err(invalid("step", format!("must be at most 2**63 - 1, got {step}")));
        }
        if let Some(d) = dissipated.iter().chain([&collisions]).find(|d| !d.is_finite()) {
            return Err(invalid("dissipated", format!("must be finite, got {d}")));
        }
        if let Some((f, p)) = &cache {
            if !(f.iter().all(|x| x.is_finite()) && p.iter().all(|x| x.is_finite())) {
                return Err(invalid("cache", "must be finite"));
            }
        }
        match cache {
            Some((f, p)) => {
                if !self.integrator.set_cache(f, p, &self.sys.state.v, dissipated.len()) {
                    return Err(invalid("cache", "does not match the scene or its integrator"));
                }
            }
            None => self.integrator.reset(),
        }
        self.sys.state.t = t;
        self.sys.state.step = step;
        self.sys.forces.dissipated.copy_from_slice(dissipated);
        self.collision_dissipated = collisions;
        Ok(())
    }

    pub fn integrator_cache(&self) -> Option<(Vec<V>, Vec<Real>)> {
        self.integrator.cache()
    }

    /// Runs `n` steps. On divergence (NaN/inf in a position or velocity) the state, books and
    /// caches are rolled back to where this call started and `Error::Diverged` names the step.
    pub fn step(&mut self, n: u64) -> Result<()> {
        self.step_interruptible(n, &Arc::new(AtomicBool::new(false)))
    }

    /// `step(n)` that stops once `stop` is set, from any thread (the Python binding sets it on
    /// Ctrl-C). The flag is read before and after every step, in "rk45" before every internal
    /// step attempt, and inside long force evaluations (pairwise gravity, see `crate::stop`).
    /// Reading it is a relaxed atomic load and changes no result. When it is seen set, the
    /// state is rolled back like on divergence and `Error::Interrupted` is returned; a flag set
    /// before the call stops it before the first step, and one set during the last step still
    /// rolls the call back.
    pub fn step_interruptible(&mut self, n: u64, stop: &Arc<AtomicBool>) -> Result<()> {
        self.step_checkpointed(n, stop).map(drop)
    }

    /// `step_interruptible` that, on success, returns the checkpoint taken at its start, so the
    /// caller can still undo the call (`rollback`): the Python binding does when a signal
    /// arrived while the call was finishing.
    pub fn step_checkpointed(&mut self, n: u64, stop: &Arc<AtomicBool>) -> Result<Checkpoint<V>> {
        if n > MAX_STEPS - self.sys.state.step {
            return Err(invalid(
                "n",
                format!("{n} more steps would take the step count past 2**63 - 1 (it is {})", self.sys.state.step),
            ));
        }
        self.prepare()?;
        let cp = self.checkpoint()?;
        if n == 0 || self.n_particles() == 0 {
            let t = self.sys.state.t + n as Real * self.dt;
            if !t.is_finite() {
                return Err(invalid("n", format!("{n} steps of {:e} s take the time past the largest float", self.dt)));
            }
            self.sys.state.t = t;
            self.sys.state.step += n;
            return Ok(cp);
        }
        match self.with_stop(stop, |s| s.step_inner(n, stop)) {
            Ok(()) => Ok(cp),
            Err(e) => Err(self.fail(cp, e)),
        }
    }

    /// Everything a `step` or `advance` call changes, to undo it with `rollback`: the state,
    /// the dissipation books, the integrator's cache and dt. A copy of the positions and
    /// velocities (and cached forces), allocated fallibly (`Error::OutOfMemory`).
    pub fn checkpoint(&self) -> Result<Checkpoint<V>> {
        let n = self.n_particles();
        let need = Need::new(
            "step",
            Need::bytes_of::<V>(3 * n),
            format!("a copy of the state of {} particles (to roll back to)", count(n as u128)),
        );
        let st = &self.sys.state;
        let state = State { x: need.copy(&st.x)?, v: need.copy(&st.v)?, t: st.t, step: st.step };
        Ok(Checkpoint {
            state,
            dissipated: self.sys.forces.dissipated.clone(),
            collisions: self.collision_dissipated,
            cache: self.integrator.try_cache().map_err(|_| need.error())?,
            adaptive: self.integrator.adaptive_stats(),
            dt: self.dt,
        })
    }

    /// Reserves, fallibly, the per-particle scratch of the integrator and the terms (sized on
    /// the first step and after particles are added), so that stepping allocates nothing that
    /// could abort the process; a refusal is `Error::OutOfMemory` and changes nothing.
    fn prepare(&mut self) -> Result<()> {
        let n = self.n_particles();
        let name = self.integrator.info().name;
        let bufs = self.integrator.scratch(self.sys.forces.velocity_dependent());
        let missing = bufs.iter().filter(|b| b.capacity() < n).count();
        let of = format!("the {name} integrator's scratch for {} particles", count(n as u128));
        let need = Need::new("step", Need::bytes_of::<V>(n) * missing as u128, of);
        for b in bufs {
            need.reserve(b, n)?;
        }
        let pool = self.pool.clone();
        let terms = &mut self.sys.forces.terms;
        // On the pool: the cell lists size their histograms by its thread count.
        par::install(pool.as_ref(), || terms.iter_mut().try_for_each(|t| t.reserve(n)))
    }

    /// Restores a checkpoint of this simulation; returns the step count it restored.
    pub fn rollback(&mut self, cp: Checkpoint<V>) -> u64 {
        let dt = cp.dt;
        let step = self.restore_state(cp);
        self.dt = dt;
        step
    }

    /// `rollback` but for dt (an error about the failed call still needs its dt).
    fn restore_state(&mut self, cp: Checkpoint<V>) -> u64 {
        let Checkpoint { state, dissipated, collisions, cache, adaptive, .. } = cp;
        if let Some((accepted, rejected, _)) = adaptive {
            self.integrator.set_adaptive_counts(accepted, rejected);
        }
        let rolled_back_to = state.step;
        self.sys.state = state;
        self.sys.forces.dissipated = dissipated;
        self.collision_dissipated = collisions;
        let n_terms = self.sys.forces.terms.len();
        let restored = match cache {
            Some((f, p)) => self.integrator.set_cache(f, p, &self.sys.state.v, n_terms),
            None => false,
        };
        if !restored {
            self.integrator.reset();
        }
        rolled_back_to
    }

    /// Rolls a failed call back to `cp` and completes its error (where it was rolled back to,
    /// the suggested dt of a divergence).
    fn fail(&mut self, cp: Checkpoint<V>, e: Error) -> Error {
        let dt = cp.dt;
        let rolled_back_to = self.restore_state(cp);
        let e = match e {
            Error::Diverged { step, particle, quantity, t, .. } => {
                // The dt that failed: `advance` ran substeps shorter than the saved dt.
                let suggested_dt = self.suggest_dt().min(0.5 * self.dt);
                Error::Diverged { step, t, particle, quantity, rolled_back_to, dt: self.dt, suggested_dt }
            }
            Error::Interrupted { .. } => Error::Interrupted { rolled_back_to },
            e => e,
        };
        self.dt = dt;
        e
    }

    /// Runs `f` on this simulation's pool with `stop` handed to the terms for its duration.
    fn with_stop<R: Send>(&mut self, stop: &Arc<AtomicBool>, f: impl FnOnce(&mut Self) -> R + Send) -> R {
        self.sys.forces.set_stop(&Stop::new(Some(stop.clone())));
        let pool = self.pool.clone();
        let r = par::install(pool.as_ref(), || f(self));
        self.sys.forces.set_stop(&Stop::default());
        r
    }

    /// Runs `job(self)` as a task on this simulation's pool while `watch` runs on the calling
    /// thread, and returns the job's result once it is done.
    /// `watch` gets `wait(timeout)`, true as soon as the job has finished (false on timeout), so
    /// the calling thread stays free, e.g. to set the stop flag of `step_interruptible`: the
    /// Python binding runs Python's signal handlers there (Python runs them on its main thread
    /// only). Costs one hand-off to a pool thread (~20 µs), not a thread start (~60 µs).
    /// Called from a thread of the pool the task would go to, the job runs on the calling
    /// thread (a task queued behind it could wait forever) and `wait` reports it done at once;
    /// so it does without a pool (`sequential()`): nothing can then watch while the job runs.
    pub fn run_watched<R: Send>(
        &mut self,
        job: impl FnOnce(&mut Self) -> R + Send,
        watch: impl FnOnce(&mut dyn FnMut(Duration) -> bool),
    ) -> R {
        let Some(pool) = self.pool.clone() else {
            let r = job(self);
            watch(&mut |_| true);
            return r;
        };
        if pool.current_thread_index().is_some() {
            let r = job(self);
            watch(&mut |_| true);
            return r;
        }
        let mut out = None;
        let slot = &mut out;
        let task = move || *slot = Some(job(self));
        pool.in_place_scope(|s| spawn_watched(s, task, watch));
        out.expect("the scope returns after its task")
    }

    /// Advances by `duration` seconds in `n` equal substeps, n = ⌈duration / auto_dt()⌉, so
    /// every substep is inside the stability region of the integrator at the start of the call
    /// (and the CFL limit for fluids).
    /// `substeps = Some(n)` fixes n instead. Sets `dt` to duration / n and returns n. On
    /// divergence or interrupt everything, dt included, is rolled back as in `step`.
    /// `stop` as in `step_interruptible`.
    pub fn advance_interruptible(
        &mut self,
        duration: Real,
        substeps: Option<u64>,
        stop: &Arc<AtomicBool>,
    ) -> Result<u64> {
        self.advance_checkpointed(duration, substeps, stop).map(|(n, _)| n)
    }

    /// `advance_interruptible` that also returns the checkpoint taken at its start (as
    /// `step_checkpointed`).
    pub fn advance_checkpointed(
        &mut self,
        duration: Real,
        substeps: Option<u64>,
        stop: &Arc<AtomicBool>,
    ) -> Result<(u64, Checkpoint<V>)> {
        if !(duration.is_finite() && duration > 0.0) {
            return Err(invalid("duration", format!("{duration} must be finite and > 0 (seconds)")));
        }
        if substeps == Some(0) {
            return Err(invalid("substeps", "must be >= 1"));
        }
        self.prepare()?;
        let cp = self.checkpoint()?;
        let r = self.with_stop(stop, |s| {
            let n = match substeps {
                Some(n) => n,
                None => {
                    // O(N²) for pairwise gravity below 20,000 bodies; the term polls `stop`.
                    let safe = s.auto_dt().unwrap_or(if s.integrator.info().name == "rk45" { duration } else { s.dt });
                    if stop.load(Ordering::Relaxed) {
                        return Err(Error::Interrupted { rolled_back_to: 0 });
                    }
                    let n = (duration / safe).ceil().max(1.0);
                    if n > 1e12 {
                        return Err(invalid(
                            "duration",
                            format!("{duration:.3e} s would take {n:.3e} substeps of {safe:.3e} s"),
                        ));
                    }
                    n as u64
                }
            };
            if n > MAX_STEPS - s.sys.state.step {
                let arg = if substeps.is_some() { "substeps" } else { "duration" };
                return Err(invalid(
                    arg,
                    format!("{n} more steps would take the step count past 2**63 - 1 (it is {})", s.sys.state.step),
                ));
            }
            // duration is finite and > 0: the quotient is never NaN, at worst 0 or subnormal,
            // a step with no finite reciprocal (rates, CFL numbers): refused.
            if duration / (n as Real) < Real::MIN_POSITIVE {
                return Err(invalid(
                    "substeps",
                    format!("{n} substeps of {duration:.3e} s would each be below float64's normal range"),
                ));
            }
            let old = s.dt;
            s.dt = duration / n as Real;
            // A cached force is still valid; a velocity predicted with the old dt is not (the
            // checkpoint keeps the cache for a rollback).
            if s.dt != old && s.sys.forces.velocity_dependent() {
                s.integrator.reset();
            }
            if s.n_particles() == 0 {
                let t = s.sys.state.t + n as Real * s.dt;
                if !t.is_finite() {
                    return Err(invalid("duration", format!("{duration} s take the time past the largest float")));
                }
                s.sys.state.t = t;
                s.sys.state.step += n;
                return Ok(n);
            }
            s.step_inner(n, stop).map(|()| n)
        });
        match r {
            Ok(n) => Ok((n, cp)),
            Err(e) => Err(self.fail(cp, e)),
        }
    }

    /// The named output fields of every term (see `Term::fields`), one value per particle (0
    /// for particles a field does not cover); `names` fixes which and in what order.
    pub fn fields(&self, names: &[&str]) -> Vec<Vec<Real>> {
        let n = self.n_particles();
        let mut out = vec![vec![0.0; n]; names.len()];
        self.run(|| {
            for t in &self.sys.forces.terms {
                for (name, range, values) in t.fields(&self.sys.state.x, &self.sys.model) {
                    if let Some(k) = names.iter().position(|m| *m == name) {
                        out[k][range].copy_from_slice(&values);
                    }
                }
            }
        });
        out
    }

    /// Density (kg/m^dim) and pressure (Pa) of every particle, from the fluid terms (0 for
    /// particles that are in no fluid).
    pub fn fluid_fields(&self) -> (Vec<Real>, Vec<Real>) {
        let mut f = self.fields(&["density", "pressure"]).into_iter();
        (f.next().expect("asked for two"), f.next().expect("asked for two"))
    }

    /// Wall time (s) the terms that keep such books have spent in their phases so far (SPH:
    /// cell list + gather, density, forces), and the heap bytes they hold.
    pub fn fluid_profile(&self) -> ([f64; 3], usize) {
        let mut c = [0.0; 3];
        let mut bytes = 0;
        for (clock, b) in self.sys.forces.terms.iter().filter_map(|t| t.profile()) {
            for k in 0..3 {
                c[k] += clock[k];
            }
            bytes += b;
        }
        (c, bytes)
    }

    fn step_inner(&mut self, n: u64, stop: &AtomicBool) -> Result<()> {
        let dt = self.dt;
        let interrupted = Err(Error::Interrupted { rolled_back_to: 0 });
        for _ in 0..n {
            if stop.load(Ordering::Relaxed) {
                return interrupted;
            }
            let Ok(non_finite) = self.integrator.step_interruptible(&mut self.sys, dt, stop) else {
                return interrupted;
            };
            // Set during the step: a term may have skipped part of its forces, so the step
            // (the last one too) must not stand.
            if stop.load(Ordering::Relaxed) {
                return interrupted;
            }
            self.sys.state.t += dt;
            self.sys.state.step += 1;
            if !self.colliders.is_empty() {
                let mut touched = false;
                let f = self.integrator.last_forces();
                let g = self.sys.forces.g;
                for c in &self.colliders {
                    let (d, t) = c.apply(&mut self.sys.state.x, &mut self.sys.state.v, &self.sys.model, f, g);
                    self.collision_dissipated += d;
                    touched |= t;
                }
                if touched {
                    if self.sys.single {
                        let (x, v) = (&mut self.sys.state.x, &mut self.sys.state.v);
                        par::chunks2(x, v, |_, x, v| {
                            x.iter_mut().chain(v.iter_mut()).for_each(|p| *p = p.round_f32());
                        });
                    }
                    self.integrator.reset();
                }
            }
            if non_finite {
                let (particle, quantity) =
                    self.first_non_finite().or(self.integrator.failure()).unwrap_or((0, Failure::Position));
                return Err(Error::Diverged {
                    step: self.sys.state.step,
                    t: self.sys.state.t,
                    particle,
                    quantity,
                    rolled_back_to: 0,
                    dt,
                    suggested_dt: 0.0,
                });
            }
        }
        Ok(())
    }

    /// The first particle (by index) with a non-finite position or velocity.
    fn first_non_finite(&self) -> Option<(usize, Failure)> {
        let (x, v) = (&self.sys.state.x, &self.sys.state.v);
        (0..x.len()).find_map(|i| {
            if !x[i].is_finite() {
                Some((i, Failure::Position))
            } else if !v[i].is_finite() {
                Some((i, Failure::Velocity))
            } else {
                None
            }
        })
    }

    /// A step size (s) safely inside the stability region of the stiffest term: half of its
    /// fastest time scale (springs: 1/ω_max by a Gershgorin bound; gravity: closest free-fall
    /// time; drag: m/b). Falls back to the current dt if no term has a time scale.
    pub fn suggest_dt(&self) -> Real {
        let (ts, limit) = self.time_scales();
        let dt = (0.5 * ts).min(limit);
        if dt.is_finite() {
            dt
        } else {
            self.dt
        }
    }

    /// (fastest time scale τ = 1/ω_max over the terms, smallest term step limit such as the
    /// SPH CFL), each infinite if no term has one.
    fn time_scales(&self) -> (Real, Real) {
        let ts = self
            .sys
            .forces
            .terms
            .iter()
            .filter_map(|t| t.time_scale(&self.sys.state.x, &self.sys.model))
            .fold(f64::INFINITY, f64::min);
        let g = self.sys.forces.g.length_squared().sqrt();
        let limit = self
            .sys
            .forces
            .terms
            .iter()
            .filter_map(|t| t.max_dt(&self.sys.state.x, &self.sys.state.v, &self.sys.model, g))
            .fold(f64::INFINITY, f64::min);
        (ts, limit)
    }

    /// The largest substep `advance` takes with the current integrator: ω_max·dt = 0.5 with
    /// ω_max = 1/τ bounded from above (Gershgorin), i.e. a quarter of the stability interval of
    /// semi-implicit Euler and Verlet (ω·dt < 2) and under a fifth of RK4's (2√2), and no more
    /// than a term's own limit (SPH CFL). RK4 is not given a longer step for its longer
    /// interval: it is dissipative, and on a stiff chain at ω·dt = 0.71 it lost 26 % of the
    /// energy in 200 stiff periods against 5.6 % at 0.5. Explicit Euler has no stability interval
    /// on undamped oscillations (it grows at every dt) and gets the same step. rk45 picks its
    /// own internal steps, so only the term limits apply to it. `None` if nothing in the scene
    /// sets a time scale.
    pub fn auto_dt(&self) -> Option<Real> {
        let (ts, limit) = self.time_scales();
        let factor = if self.integrator.info().name == "rk45" { f64::INFINITY } else { 0.5 };
        let dt = (factor * ts).min(limit);
        (dt.is_finite() && dt > 0.0).then_some(dt)
    }

    /// Runs a read-only query (`energy`, `suggest_dt`, `auto_dt`) with `stop` handed to the
    /// terms, whose O(N²) sums (gravity's potential and time scale) read it per row. Nothing
    /// changes either way; once `stop` is set the result is dropped and `Error::Interrupted`
    /// returned.
    pub fn query_interruptible<R: Send>(
        &mut self,
        stop: &Arc<AtomicBool>,
        f: impl FnOnce(&Self) -> R + Send,
    ) -> Result<R> {
        self.with_stop(stop, |s| {
            let r = f(s);
            if stop.load(Ordering::Relaxed) {
                return Err(Error::Interrupted { rolled_back_to: s.sys.state.step });
            }
            Ok(r)
        })
    }

    pub fn energy(&self) -> EnergyReport {
        self.run(|| {
            let (x, v, m) = (&self.sys.state.x, &self.sys.state.v, &self.sys.model);
            let kinetic = 0.5
                * par::sum(x.len(), 0.0, |r| {
                    let mut k = 0.0;
                    for i in r {
                        if m.inv_mass[i] != 0.0 {
                            k += m.mass[i] * v[i].length_squared();
                        }
                    }
                    k
                });
            let potential = self
                .sys
                .forces
                .terms
                .iter()
                .filter_map(|t| t.potential(x, m).map(|u| (t.name().to_string(), u)))
                .collect();
            let mut dissipated: Vec<(String, Real)> = self
                .sys
                .forces
                .terms
                .iter()
                .zip(&self.sys.forces.dissipated)
                .filter(|(t, _)| t.dissipative())
                .map(|(t, d)| (t.name().to_string(), *d))
                .collect();
            if !self.colliders.is_empty() {
                dissipated.push(("collisions".to_string(), self.collision_dissipated));
            }
            EnergyReport { kinetic, potential, dissipated }
        })
    }

    /// Σ m v over free particles, kg·m/s.
    pub fn momentum(&self) -> V {
        let (v, m) = (&self.sys.state.v, &self.sys.model);
        self.run(|| {
            par::sum(v.len(), V::ZERO, |r| {
                let mut p = V::ZERO;
                for i in r {
                    if m.inv_mass[i] != 0.0 {
                        p += v[i] * m.mass[i];
                    }
                }
                p
            })
        })
    }

    /// Σ m x × v about the origin over free particles, kg·m²/s (2D: only z is non-zero).
    pub fn angular_momentum(&self) -> [Real; 3] {
        let (x, v, m) = (&self.sys.state.x, &self.sys.state.v, &self.sys.model);
        let l = self.run(|| {
            par::sum(x.len(), glam::DVec3::ZERO, |r| {
                let mut l = glam::DVec3::ZERO;
                for i in r {
                    if m.inv_mass[i] != 0.0 {
                        let c = x[i].cross3(v[i]);
                        l += glam::DVec3::from_array(c) * m.mass[i];
                    }
                }
                l
            })
        });
        l.to_array()
    }
}

/// Spawns `task` in `s` and runs `watch` here with a `wait` that reports the task's end.
fn spawn_watched<'s>(
    s: &rayon::Scope<'s>,
    task: impl FnOnce() + Send + 's,
    watch: impl FnOnce(&mut dyn FnMut(Duration) -> bool),
) {
    let (tx, rx) = mpsc::channel::<()>();
    s.spawn(move |_| {
        let _done = tx; // dropped when the task ends, by a panic too
        task();
    });
    let mut done = false;
    watch(&mut |timeout| {
        done = done || !matches!(rx.recv_timeout(timeout), Err(RecvTimeoutError::Timeout));
        done
    });
}

fn check_dt(dt: Real) -> Result<()> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(invalid("dt", format!("{dt} must be finite and > 0 (seconds)")));
    }
    Ok(())
}
