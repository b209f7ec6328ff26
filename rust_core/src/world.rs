//! The world: every system of a scene, stepped together on one thread pool, with one clock
//! (time, step count, dt), rollback, interrupts and the energy books of all systems.
//!
//! ```text
//!   World ── clock (t, step, dt), thread pool, stop flag, checkpoints
//!     ├── ParticleSystem  (systems/particles)   state + model
//!     │     ├── ForceSet: terms (springs, gravity, SPH, fields…; terms/, sph/)
//!     │     ├── Integrator (integrators/; tableaux from ode/)
//!     │     └── Constraints: projection after each step (constraints/: walls; XPBD next)
//!     ├── further systems behind `System` (systems/ode; grids next)
//!     └── Couplings between systems, after every step
//! ```
//!
//! One call (`step`, `advance`) is atomic: it takes a checkpoint of every system first, and a
//! divergence or an interrupt anywhere restores all of them.
use crate::alloc::Need;
use crate::error::{invalid, Error, Result};
use crate::par;
use crate::stop::Stop;
use crate::systems::particles::ParticleSystem;
use crate::systems::{Arrays, Coupling, EnergyReport, Halt, Snapshot, System, WorldSetting};
use crate::vector::{Real, Vector};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::Arc;
use std::time::Duration;

/// The largest step count: files store it as an int64, and it must never wrap.
pub const MAX_STEPS: u64 = i64::MAX as u64;

/// How `World::begin_steps` left a call.
enum Begun {
    /// Nothing to step: the call is done.
    Done(Checkpoint),
    /// Steps to run, from this checkpoint.
    Run(Checkpoint),
}

/// What `World::save` returns: the clock (t, step count, dt) and each system's arrays by name.
pub type Saved = ((Real, u64, Real), Vec<(String, Arrays)>);

/// What `World::rollback` restores (see `World::checkpoint`).
pub struct Checkpoint {
    snapshots: Vec<Snapshot>,
    t: Real,
    step: u64,
    dt: Real,
}

pub struct World<V: Vector> {
    /// The first system: every scene has particles (possibly none).
    particles: ParticleSystem<V>,
    /// Further systems, stepped after the particles in the order they were added.
    others: Vec<Box<dyn System>>,
    couplings: Vec<Box<dyn Coupling<V>>>,
    /// Simulated time, s.
    t: Real,
    /// Steps taken since the world was built.
    step: u64,
    /// Time step, s.
    pub dt: Real,
    /// The pool the stepping runs on; `None`: the calling thread only (see `sequential`).
    pool: Option<Arc<rayon::ThreadPool>>,
    /// Why there is no pool: the default one could not start its threads.
    sequential: Option<String>,
}

impl<V: Vector> World<V> {
    /// A world of `particles` (a `ParticleSystem`, made with its integrator: the world steps
    /// systems and knows no integrator). `threads`: `None` shares `par::default_pool` (all cores, or `RAYON_NUM_THREADS`), or, if
    /// its threads cannot be started (a thread limit), runs on the calling thread only
    /// (`sequential()` says why); `Some(n)`: a pool of its own, `Error::Threads` if the n
    /// threads cannot be started.
    pub fn new(particles: ParticleSystem<V>, dt: Real, threads: Option<usize>) -> Result<Self> {
        check_dt(dt)?;
        // A PHYSCORE_SIMD the CPU cannot honour is refused here, before any state steps.
        crate::simd::check()?;
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
        Ok(Self { particles, others: Vec::new(), couplings: Vec::new(), t: 0.0, step: 0, dt, pool, sequential })
    }

    /// Runs `f` on this world's pool (or the calling thread without one).
    pub fn run<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        par::install(self.pool.as_ref(), f)
    }

    /// Why this world runs on the calling thread only (its pool could not start its threads),
    /// if it does. Results are the same either way.
    pub fn sequential(&self) -> Option<&str> {
        self.sequential.as_deref()
    }

    pub fn particles(&self) -> &ParticleSystem<V> {
        &self.particles
    }
    pub fn particles_mut(&mut self) -> &mut ParticleSystem<V> {
        &mut self.particles
    }
    /// The systems after the particles.
    pub fn others(&self) -> &[Box<dyn System>] {
        &self.others
    }
    /// The system after the particles named `name`.
    /// The names of the systems besides the particles, in the order they joined.
    pub fn other_names(&self) -> Vec<String> {
        self.others.iter().map(|s| s.name().to_string()).collect()
    }
    pub fn other(&self, name: &str) -> Result<&dyn System> {
        match self.others.iter().find(|s| s.name() == name) {
            Some(s) => Ok(s.as_ref()),
            None => Err(invalid("name", format!("no system named {name:?}"))),
        }
    }
    pub fn other_mut(&mut self, name: &str) -> Result<&mut (dyn System + 'static)> {
        match self.others.iter_mut().find(|s| s.name() == name) {
            Some(s) => Ok(s.as_mut()),
            None => Err(invalid("name", format!("no system named {name:?}"))),
        }
    }
    /// Adds a system, stepped after those already there; returns its index in `others`.
    pub fn add_system(&mut self, s: Box<dyn System>) -> Result<usize> {
        if s.name() == self.particles.name() || self.others.iter().any(|o| o.name() == s.name()) {
            return Err(invalid("name", format!("the world already has a system named {:?}", s.name())));
        }
        self.others.push(s);
        Ok(self.others.len() - 1)
    }
    /// Puts `s` in the place of the system of the same name (a grid moved to a device keeps its
    /// place in the order of steps); returns the one it replaced.
    pub fn replace_system(&mut self, s: Box<dyn System>) -> Result<Box<dyn System>> {
        match self.others.iter_mut().find(|o| o.name() == s.name()) {
            Some(o) => Ok(std::mem::replace(o, s)),
            None => Err(invalid("name", format!("no system named {:?}", s.name()))),
        }
    }
    /// Adds a coupling, run after every step (after those already there).
    pub fn add_coupling(&mut self, c: Box<dyn Coupling<V>>) {
        self.couplings.push(c);
    }

    /// Every system, the particles first.
    fn systems(&self) -> impl Iterator<Item = &(dyn System + 'static)> {
        std::iter::once(&self.particles as &dyn System).chain(self.others.iter().map(|s| s.as_ref()))
    }
    fn systems_mut(&mut self) -> impl Iterator<Item = &mut (dyn System + 'static)> {
        let others = self.others.iter_mut().map(|s| s.as_mut());
        std::iter::once(&mut self.particles as &mut (dyn System + 'static)).chain(others)
    }

    pub fn n_particles(&self) -> usize {
        self.particles.n_particles()
    }
    /// Particles plus the elements of the other systems (grid cells, flow points, an ODE's
    /// values): the work of one step. A system that has something to step counts at least 1.
    /// A world with couplings counts as unbounded work: a coupling's first step may take
    /// seconds whatever the counts (sampling a large body's surface for a fluid), so its calls
    /// are always watched for Ctrl-C.
    pub fn elements(&self) -> usize {
        if !self.couplings.is_empty() {
            return usize::MAX;
        }
        let others = self.others.iter().filter(|s| !s.is_empty()).map(|s| s.size().max(1));
        self.particles.n_particles() + others.sum::<usize>()
    }
    /// Simulated time, s.
    pub fn time(&self) -> Real {
        self.t
    }
    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.step
    }
    /// The step a call takes when it is not given one.
    pub fn dt(&self) -> Real {
        self.dt
    }
    pub fn set_dt(&mut self, dt: Real) -> Result<()> {
        check_dt(dt)?;
        self.dt = dt;
        Ok(())
    }
    pub fn force_evaluations(&self) -> u64 {
        self.particles.force_evaluations()
    }

    /// Restores what `save` wrote beside the state: time (s), step count, the particle
    /// system's energy books (J) and its integrator's cache. Every value is checked before
    /// anything changes.
    pub fn restore(
        &mut self,
        t: Real,
        step: u64,
        dissipated: &[Real],
        collisions: Real,
        cache: Option<crate::integrators::Cache<V>>,
    ) -> Result<()> {
        self.particles.check_books(dissipated, collisions, &cache)?;
        if !t.is_finite() {
            return Err(invalid("time", format!("must be finite, got {t}")));
        }
        if step > MAX_STEPS {
            return Err(invalid("step", format!("must be at most 2**63 - 1, got {step}")));
        }
        self.particles.restore_books(dissipated, collisions, cache)?;
        self.t = t;
        self.step = step;
        Ok(())
    }

    /// Everything a restart needs: the clock (t, step count, dt) and each system's arrays
    /// (`System::save`), by system name, the particles first; `Error::OutOfMemory` if a system's
    /// arrays cannot be had.
    pub fn save(&self) -> Result<Saved> {
        let systems = self.systems().map(|s| Ok((s.name().to_string(), s.save()?))).collect::<Result<_>>()?;
        Ok(((self.t, self.step, self.dt), systems))
    }

    /// Loads what `save` wrote into a world built the same way (same systems, terms and
    /// particle counts): a run continued from it is bit-identical to the saved one. Every
    /// value is checked before anything changes.
    pub fn load(&mut self, clock: (Real, u64, Real), systems: &[(String, Arrays)]) -> Result<()> {
        let (t, step, dt) = clock;
        check_dt(dt)?;
        if !t.is_finite() {
            return Err(invalid("time", format!("must be finite, got {t}")));
        }
        if step > MAX_STEPS {
            return Err(invalid("step", format!("must be at most 2**63 - 1, got {step}")));
        }
        let names: Vec<String> = self.systems().map(|s| s.name().to_string()).collect();
        if systems.iter().map(|(n, _)| n).ne(names.iter()) {
            return Err(invalid("systems", format!("expected the systems {names:?}")));
        }
        let cp = self.checkpoint()?;
        let r = self.systems_mut().zip(systems).try_for_each(|(s, (_, a))| s.load(a));
        if let Err(e) = r {
            self.rollback(cp);
            return Err(e);
        }
        (self.t, self.step, self.dt) = (t, step, dt);
        Ok(())
    }

    /// Runs `n` steps. On divergence (NaN/inf anywhere) every system, the books and the caches
    /// are rolled back to where this call started and `Error::Diverged` names the step.
    pub fn step(&mut self, n: u64) -> Result<()> {
        self.step_interruptible(n, &Arc::new(AtomicBool::new(false)))
    }

    /// `step(n)` that stops once `stop` is set, from any thread (the Python binding sets it on
    /// Ctrl-C). The flag is read before and after every step, in "dopri5" before every internal
    /// step attempt, and inside long force evaluations (pairwise gravity, see `crate::stop`).
    /// Reading it is a relaxed atomic load and changes no result. When it is seen set, the
    /// state is rolled back like on divergence and `Error::Interrupted` is returned; a flag set
    /// before the call stops it before the first step, and one set during the last step still
    /// rolls the call back.
    pub fn step_interruptible(&mut self, n: u64, stop: &Arc<AtomicBool>) -> Result<()> {
        self.step_checkpointed(n, stop).map(|cp| self.release(cp))
    }

    /// `step_interruptible` that, on success, returns the checkpoint taken at its start, so the
    /// caller can still undo the call (`rollback`): the Python binding does when a signal
    /// arrived while the call was finishing.
    pub fn step_checkpointed(&mut self, n: u64, stop: &Arc<AtomicBool>) -> Result<Checkpoint> {
        match self.begin_steps(n)? {
            Begun::Done(cp) => Ok(cp),
            Begun::Run(cp) => match self.with_stop(stop, |s| s.step_inner(n, stop)) {
                Ok(()) => Ok(cp),
                Err(e) => Err(self.fail(cp, e)),
            },
        }
    }

    /// The start of `step_checkpointed(n)`: the call's checks, the reservations and the
    /// checkpoint. `Done` where nothing is left to step (n = 0, or nothing to step: the clock
    /// has advanced already), else `Run`: the caller steps `n` steps, and rolls back to the
    /// checkpoint (`fail`) on an error. (The batch's fused kernel allocates nothing per step
    /// and writes nothing before it keeps its result: it begins with `begin_fused` instead.)
    fn begin_steps(&mut self, n: u64) -> Result<Begun> {
        self.check_n(n)?;
        // Any scene, not only an empty one: a clock at inf stepped on silently (issue 64's
        // hostile pass: dt = 1e308, two steps).
        if !(self.t + n as Real * self.dt).is_finite() {
            return Err(invalid("n", format!("{n} steps of {:e} s take the time past the largest float", self.dt)));
        }
        self.prepare()?;
        let cp = self.checkpoint()?;
        if let Err(e) = self.room() {
            self.release(cp);
            return Err(e);
        }
        if n == 0 || self.is_empty() {
            let t = self.t + n as Real * self.dt;
            if !t.is_finite() {
                return Err(invalid("n", format!("{n} steps of {:e} s take the time past the largest float", self.dt)));
            }
            self.t = t;
            self.step += n;
            return Ok(Begun::Done(cp));
        }
        Ok(Begun::Run(cp))
    }

    /// The shape of this world for the batch's fused kernel (`crate::batch`): particles alone
    /// (no other system, no coupling) that the kernel can step with the same bits.
    pub(crate) fn fused_shape(&self) -> Option<crate::systems::particles::Shape> {
        (self.others.is_empty() && self.couplings.is_empty()).then(|| self.particles.fused_shape()).flatten()
    }

    /// The checks `step_checkpointed(n)` makes before its first step, for a caller that steps
    /// the particles itself and writes nothing to the world until it keeps the result
    /// (`crate::batch`): the step count, the particles' dt. No checkpoint: nothing changes here.
    pub(crate) fn begin_fused(&self, n: u64) -> Result<()> {
        self.check_n(n)?;
        self.particles.check_dt(self.dt)
    }

    /// `n` more steps keep the step count within 2**63 - 1.
    fn check_n(&self, n: u64) -> Result<()> {
        if n > MAX_STEPS - self.step {
            return Err(invalid(
                "n",
                format!("{n} more steps would take the step count past 2**63 - 1 (it is {})", self.step),
            ));
        }
        Ok(())
    }

    /// The end of a fused run of `n` steps (`crate::batch`): the clock `t`, which the kernel
    /// advanced by dt a step as `step_loop` does (the same bits), and the step count.
    pub(crate) fn end_fused(&mut self, t: Real, n: u64) {
        self.t = t;
        self.step += n;
    }

    /// Whether no system has anything to step.
    fn is_empty(&self) -> bool {
        self.systems().all(|s| s.is_empty())
    }

    /// Everything a `step` or `advance` call changes, to undo it with `rollback`: a snapshot of
    /// every system, the clock and dt. Allocated fallibly (`Error::OutOfMemory`).
    pub fn checkpoint(&self) -> Result<Checkpoint> {
        let snapshots = self.systems().map(|s| s.snapshot()).collect::<Result<Vec<_>>>()?;
        Ok(Checkpoint { snapshots, t: self.t, step: self.step, dt: self.dt })
    }

    /// Reserves, fallibly, what every system's stepping needs (on the pool: the cell lists size
    /// their histograms by its thread count); a refusal is `Error::OutOfMemory` and changes
    /// nothing.
    fn prepare(&mut self) -> Result<()> {
        let pool = self.pool.clone();
        par::install(pool.as_ref(), || self.systems_mut().try_for_each(|s| s.prepare()))
    }

    /// Checks, once the checkpoint is taken, that the step's small buffers allocated on the fly
    /// (the terms' `transient_bytes`, and 1 MB for per-chunk lists and the thread pool's jobs)
    /// can still be had: under memory pressure a refused one would abort the process, this
    /// check is an `Error::OutOfMemory` instead.
    fn room(&self) -> Result<()> {
        let bytes = self.particles.transient_bytes() + (1 << 20);
        Need::new("step", bytes, "the step's transient buffers").room(bytes)
    }

    /// Hands a checkpoint that is no longer needed back to the systems, whose buffers then serve
    /// the next one (`System::recycle`).
    pub fn release(&mut self, cp: Checkpoint) {
        for (s, snap) in self.systems_mut().zip(cp.snapshots) {
            s.recycle(snap);
        }
    }

    /// Restores a checkpoint of this world; returns the step count it restored.
    pub fn rollback(&mut self, cp: Checkpoint) -> u64 {
        let dt = cp.dt;
        let step = self.restore_state(cp);
        self.dt = dt;
        step
    }

    /// `rollback` but for dt (an error about the failed call still needs its dt).
    fn restore_state(&mut self, cp: Checkpoint) -> u64 {
        let Checkpoint { snapshots, t, step, .. } = cp;
        for (s, snap) in self.systems_mut().zip(snapshots) {
            s.restore(snap);
        }
        self.t = t;
        self.step = step;
        step
    }

    /// Rolls a failed call back to `cp` and completes its error (where it was rolled back to,
    /// the suggested dt of a divergence).
    fn fail(&mut self, cp: Checkpoint, e: Error) -> Error {
        let dt = cp.dt;
        let rolled_back_to = self.restore_state(cp);
        let e = match e {
            Error::Diverged { step, particle, quantity, t, .. } => {
                // The dt that failed: `advance` ran substeps shorter than the saved dt.
                let suggested_dt = self.suggest_dt().min(0.5 * self.dt);
                let explicit_euler = self.particles.integrator_info().name == "euler";
                let remedies = self.particles.remedies();
                Error::Diverged {
                    step,
                    t,
                    particle,
                    quantity,
                    rolled_back_to,
                    dt: self.dt,
                    suggested_dt,
                    explicit_euler,
                    remedies,
                }
            }
            Error::Interrupted { .. } => Error::Interrupted { rolled_back_to },
            e => e,
        };
        self.dt = dt;
        e
    }

    /// Runs `f` on this world's pool with `stop` handed to the systems for its duration.
    fn with_stop<R: Send>(&mut self, stop: &Arc<AtomicBool>, f: impl FnOnce(&mut Self) -> R + Send) -> R {
        let flag = WorldSetting::Stop(Stop::new(Some(stop.clone())));
        self.systems_mut().for_each(|s| s.set(&flag));
        let pool = self.pool.clone();
        let r = par::install(pool.as_ref(), || f(self));
        self.systems_mut().for_each(|s| s.set(&WorldSetting::Stop(Stop::default())));
        r
    }

    /// Runs `job(self)` as a task on this world's pool while `watch` runs on the calling
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
    /// every substep is inside the stability region of every system at the start of the call
    /// (and the CFL limit for fluids); with a system whose limit follows the flow (DFSPH) the
    /// substeps are unequal instead (`advance_following`).
    /// `substeps = Some(n)` fixes n instead. Sets `dt` to duration / n and returns n. On
    /// divergence or interrupt everything, dt included, is rolled back as in `step`.
    /// `stop` as in `step_interruptible`.
    pub fn advance_interruptible(
        &mut self,
        duration: Real,
        substeps: Option<u64>,
        stop: &Arc<AtomicBool>,
    ) -> Result<u64> {
        self.advance_checkpointed(duration, substeps, stop).map(|(n, cp)| {
            self.release(cp);
            n
        })
    }

    /// `advance_interruptible` that also returns the checkpoint taken at its start (as
    /// `step_checkpointed`).
    pub fn advance_checkpointed(
        &mut self,
        duration: Real,
        substeps: Option<u64>,
        stop: &Arc<AtomicBool>,
    ) -> Result<(u64, Checkpoint)> {
        if !(duration.is_finite() && duration > 0.0) {
            return Err(invalid("duration", format!("{duration} must be finite and > 0 (seconds)")));
        }
        if substeps == Some(0) {
            return Err(invalid("substeps", "must be >= 1"));
        }
        self.prepare()?;
        let cp = self.checkpoint()?;
        if let Err(e) = self.room() {
            self.release(cp);
            return Err(e);
        }
        if substeps.is_none() && self.systems().any(|s| s.limit_follows_flow()) {
            let r = self.with_stop(stop, |s| s.advance_following(duration, stop));
            return match r {
                Ok(n) => Ok((n, cp)),
                Err(e) => Err(self.fail(cp, e)),
            };
        }
        let r = self.with_stop(stop, |s| {
            let n = match substeps {
                Some(n) => n,
                None => {
                    // O(N²) for pairwise gravity below 20,000 bodies; the term polls `stop`.
                    // With no limit anywhere, systems that pick their own steps take the whole
                    // duration at once.
                    let fallback = if s.systems().all(|s| s.adaptive()) { duration } else { s.dt };
                    let safe = s.auto_dt().unwrap_or(fallback);
                    if stop.load(Ordering::Relaxed) {
                        return Err(Error::Interrupted { rolled_back_to: 0 });
                    }
                    if !(safe >= Real::MIN_POSITIVE) {
                        return Err(invalid(
                            "duration",
                            format!(
                                "the scene's fastest time scale asks for substeps of {safe:.3e} s, below \
                                 float64's normal range: no stable step exists; give values of a physical size"
                            ),
                        ));
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
            if n > MAX_STEPS - s.step {
                let arg = if substeps.is_some() { "substeps" } else { "duration" };
                return Err(invalid(
                    arg,
                    format!("{n} more steps would take the step count past 2**63 - 1 (it is {})", s.step),
                ));
            }
            // duration is finite and > 0: the quotient is never NaN, at worst 0 or subnormal,
            // a step with no finite reciprocal (rates, CFL numbers): refused.
            if duration / (n as Real) < Real::MIN_POSITIVE {
                let each = duration / n as Real;
                return Err(match substeps {
                    Some(_) => invalid(
                        "substeps",
                        format!("{n} substeps of {duration:.3e} s would each last {each:.3e} s, below float64's normal range"),
                    ),
                    // Automatic, of a usable step (checked above): a duration that is itself
                    // subnormal is refused by the facade; kept for the core's other callers.
                    None => invalid(
                        "duration",
                        format!("{duration:.3e} s in {n} substeps would each last {each:.3e} s, below float64's normal range"),
                    ),
                });
            }
            // Any scene, not only an empty one: a clock at inf stepped on silently (issue 64's
            // hostile pass: dt = 1e308, two steps).
            if !(s.t + duration).is_finite() {
                return Err(invalid("duration", format!("{duration} s take the time past the largest float")));
            }
            let old = s.dt;
            s.dt = duration / n as Real;
            if s.dt != old {
                s.systems_mut().for_each(|s| s.dt_changed());
            }
            if s.is_empty() {
                let t = s.t + n as Real * s.dt;
                if !t.is_finite() {
                    return Err(invalid("duration", format!("{duration} s take the time past the largest float")));
                }
                s.t = t;
                s.step += n;
                return Ok(n);
            }
            s.step_inner(n, stop).map(|()| n)
        });
        match r {
            Ok(n) => Ok((n, cp)),
            Err(e) => Err(self.fail(cp, e)),
        }
    }

    /// `advance` of `duration` for a world whose step limit follows the flow
    /// (`System::limit_follows_flow`): before each substep the limit is taken anew and the
    /// rest of the duration cut into equal parts within it (the last substep ends the duration
    /// exactly); returns the substeps taken. `dt` is left at the last substep.
    fn advance_following(&mut self, duration: Real, stop: &AtomicBool) -> Result<u64> {
        let (mut left, mut n) = (duration, 0u64);
        while left > 0.0 {
            let limit = self.auto_dt().unwrap_or(left);
            // As the equal-substep path: refuse what would never end. After steps of this call
            // (whose start passed this check), or at the start of a call with a limit a
            // millionfold below the last step taken, the flow itself sped up: a runaway with
            // finite velocities, which no other check catches, not a duration too long (an
            // advance after one that ended in a runaway named `duration`).
            if left / limit > 1e12 {
                if n > 0 || (self.step > 0 && limit < 1e-6 * self.dt) {
                    return Err(self.diverged(self.fastest(), crate::error::Failure::Speed));
                }
                return Err(invalid(
                    "duration",
                    format!("{left:.3e} s left would take over 1e12 substeps of {limit:.3e} s"),
                ));
            }
            // The rest in equal parts within the limit: steady where the limit is (the
            // solvers' pressure, Σκ/ρ a step, reads high after a step shorter than the last).
            let parts = (left / limit).ceil().max(1.0);
            let dt = if parts <= 1.0 { left } else { left / parts };
            if !(dt >= Real::MIN_POSITIVE) || n >= MAX_STEPS - self.step {
                return Err(invalid("duration", format!("{duration:.3e} s cannot be advanced in steps of {dt:.3e} s")));
            }
            if dt != self.dt {
                self.dt = dt;
                self.systems_mut().for_each(|s| s.dt_changed());
            }
            self.step_inner(1, stop)?;
            let rest = if dt == left { 0.0 } else { left - dt };
            if rest >= left {
                return Err(invalid("duration", format!("{duration:.3e} s: steps of {dt:.3e} s no longer shorten it")));
            }
            left = rest;
            n += 1;
        }
        Ok(n)
    }

    /// The particle system's named output fields (see `Term::fields`), one value per particle
    /// (0 for particles a field does not cover); `names` fixes which and in what order.
    pub fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        self.run(|| self.particles.fields(names))
    }

    /// Density (kg/m^dim) and pressure (Pa) of every particle, from the fluid terms (0 for
    /// particles that are in no fluid).
    pub fn fluid_fields(&self) -> Result<(Vec<Real>, Vec<Real>)> {
        let mut f = self.fields(&["density", "pressure"])?.into_iter();
        Ok((f.next().expect("asked for two"), f.next().expect("asked for two")))
    }

    /// `n` steps of every system, then the couplings; the clock advances after each.
    fn step_inner(&mut self, n: u64, stop: &AtomicBool) -> Result<()> {
        // (On an error the call is rolled back to a settled checkpoint.)
        if !self.particles.is_empty() {
            self.particles.check_dt(self.dt)?;
        }
        self.step_loop(n, stop)?;
        self.settle()
    }

    /// Completes what the last step deferred (`System::settle`); a non-finite value that this
    /// produced is a divergence at that step.
    fn settle(&mut self) -> Result<()> {
        self.systems_mut().for_each(|s| s.settle());
        match self.systems().find_map(|s| s.settled_fault()) {
            Some((index, quantity)) => Err(self.diverged(index, quantity)),
            None => Ok(()),
        }
    }

    /// Gives every other system the world's gravity (`WorldSetting::Gravity`): the
    /// rigid bodies fall under the scene's `Gravity` terms, and their books use the same g.
    fn sync_gravity(&mut self) {
        if !self.others.is_empty() {
            let g = self.particles.forces().g;
            let g = [g.comp(0), g.comp(1), if V::DIM == 3 { g.comp(2) } else { 0.0 }];
            self.others.iter_mut().for_each(|s| s.set(&WorldSetting::Gravity(g)));
        }
    }

    /// The steps of `step_inner`.
    fn step_loop(&mut self, n: u64, stop: &AtomicBool) -> Result<()> {
        let dt = self.dt;
        self.sync_gravity();
        let interrupted = Err(Error::Interrupted { rolled_back_to: 0 });
        // One system alone, nothing between its steps: it takes all n at once (and may fuse
        // them); the clock then counts them one by one, as below, for the same bits.
        if self.couplings.is_empty() && self.particles.is_empty() && self.others.len() == 1 {
            let r = self.others[0].steps(n, dt, stop);
            let done = match r {
                Ok(()) => n,
                Err((i, Halt::Stopped)) => i,
                Err((i, Halt::Diverged { .. })) => i + 1,
            };
            for _ in 0..done {
                self.t += dt;
                self.step += 1;
            }
            return match r {
                Ok(()) => Ok(()),
                Err((_, Halt::Stopped)) => interrupted,
                Err((_, Halt::Diverged { index, quantity })) => Err(self.diverged(index, quantity)),
            };
        }
        for _ in 0..n {
            if stop.load(Ordering::Relaxed) {
                return interrupted;
            }
            for c in &mut self.couplings {
                c.prepare(&mut self.particles, &mut self.others, stop)?;
            }
            let mut halt = self.particles.step(dt, stop).err();
            if halt.is_none() {
                for c in &mut self.couplings {
                    c.between(&mut self.particles, &mut self.others, dt);
                }
                halt = self.others.iter_mut().find_map(|s| s.step(dt, stop).err());
            }
            if halt == Some(Halt::Stopped) {
                return interrupted;
            }
            self.t += dt;
            self.step += 1;
            if let Some(Halt::Diverged { index, quantity }) = halt {
                return Err(self.diverged(index, quantity));
            }
            if !self.couplings.is_empty() {
                self.settle()?;
            }
            for c in &mut self.couplings {
                c.apply(&mut self.particles, &mut self.others, dt);
            }
        }
        Ok(())
    }

    /// The index of the fastest particle (the first of equals; 0 if there are none).
    fn fastest(&self) -> usize {
        let v = &self.particles.state().v;
        let speeds = v.iter().map(|u| u.length_squared());
        speeds.enumerate().fold((0, -1.0), |(i, m), (k, s)| if s > m { (k, s) } else { (i, m) }).0
    }

    /// The error of a divergence at the current step (`fail` completes it once rolled back).
    fn diverged(&self, index: usize, quantity: crate::error::Failure) -> Error {
        if quantity == crate::error::Failure::Memory {
            let generic = || Error::OutOfMemory { what: "step".into(), bytes: 0, of: "a term's lists".into() };
            return self.particles.refusal().unwrap_or_else(generic);
        }
        Error::Diverged {
            step: self.step,
            t: self.t,
            particle: index,
            quantity,
            rolled_back_to: 0,
            dt: self.dt,
            suggested_dt: 0.0,
            explicit_euler: false,
            remedies: Default::default(),
        }
    }

    /// A step size (s) safely inside the stability region of every system (the particles:
    /// half of the stiffest term's fastest time scale). Falls back to the current dt if no
    /// system has a time scale.
    pub fn suggest_dt(&self) -> Real {
        let dt = self.run(|| self.systems().filter_map(|s| s.suggest_dt()).fold(f64::INFINITY, f64::min));
        if dt.is_finite() {
            dt
        } else {
            self.dt
        }
    }

    /// The largest substep `advance` takes: the smallest of the systems' `auto_dt` (see
    /// `ParticleSystem`'s for the stability argument). `None` if nothing in the world sets a
    /// time scale.
    pub fn auto_dt(&self) -> Option<Real> {
        let dt = self.run(|| self.systems().filter_map(|s| s.auto_dt()).fold(f64::INFINITY, f64::min));
        (dt.is_finite() && dt > 0.0).then_some(dt)
    }

    /// Runs a read-only query (`energy`, `suggest_dt`, `auto_dt`) with `stop` handed to the
    /// systems, whose O(N²) sums (gravity's potential and time scale) read it per row. Nothing
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
                return Err(Error::Interrupted { rolled_back_to: s.step });
            }
            Ok(r)
        })
    }

    /// Reserves, fallibly, what reading the energy books needs (a refusal is
    /// `Error::OutOfMemory`, not an abort); `energy` then allocates nothing sized by the input.
    pub fn prepare_energy(&mut self) -> Result<()> {
        self.sync_gravity();
        let pool = self.pool.clone();
        par::install(pool.as_ref(), || self.particles.reserve_potential())
    }

    /// The energy books of every system, the particles' first.
    pub fn energy(&self) -> EnergyReport {
        self.run(|| {
            let mut e = self.particles.energy();
            for s in &self.others {
                e.merge(s.energy());
            }
            e
        })
    }

    /// Σ m v over free particles, kg·m/s.
    pub fn momentum(&self) -> V {
        self.run(|| self.particles.momentum())
    }

    /// Σ m x × v about the origin over free particles, kg·m²/s (2D: only z is non-zero).
    pub fn angular_momentum(&self) -> [Real; 3] {
        self.run(|| self.particles.angular_momentum())
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

/// The one rule for a step: finite and at least the smallest normal float64 (a subnormal step
/// has no usable reciprocal for rates and CFL ratios, and would never advance time). The facade
/// checks only that `dt` is a real number and shows this message.
pub fn check_dt(dt: Real) -> Result<()> {
    if !(dt.is_finite() && dt >= Real::MIN_POSITIVE) {
        return Err(invalid(
            "dt",
            format!(
                "must be > 0 and finite (at least {:.3e} s, the smallest normal float64), got {}",
                Real::MIN_POSITIVE,
                crate::error::seconds(dt)
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    /// A system whose flow limit falls a billionfold a step (what a runaway's CFL limit does).
    struct Runaway {
        limit: Real,
    }

    impl System for Runaway {
        fn name(&self) -> &str {
            "runaway"
        }
        fn is_empty(&self) -> bool {
            false
        }
        fn step(&mut self, _dt: Real, _stop: &AtomicBool) -> std::result::Result<(), Halt> {
            self.limit *= 1e-9;
            Ok(())
        }
        fn limit_follows_flow(&self) -> bool {
            true
        }
        fn auto_dt(&self) -> Option<Real> {
            Some(self.limit)
        }
        fn suggest_dt(&self) -> Option<Real> {
            Some(self.limit)
        }
        fn energy(&self) -> EnergyReport {
            EnergyReport::default()
        }
        fn fields(&self, _names: &[&str]) -> Result<Vec<Vec<Real>>> {
            Ok(vec![])
        }
        fn snapshot(&self) -> Result<Snapshot> {
            Ok(Box::new(self.limit))
        }
        fn save(&self) -> Result<Arrays> {
            Ok(vec![("limit".into(), vec![self.limit])])
        }
        fn load(&mut self, arrays: &Arrays) -> Result<()> {
            self.limit = arrays[0].1[0];
            Ok(())
        }
        fn restore(&mut self, snapshot: Snapshot) {
            self.limit = *snapshot.downcast::<Real>().unwrap();
        }
    }

    #[test]
    fn a_flow_limit_that_collapses_within_an_advance_is_a_divergence_not_bad_input() {
        let mut w =
            World::<DVec2>::new(ParticleSystem::<DVec2>::new("semi_implicit_euler").unwrap(), 1e-3, Some(1)).unwrap();
        w.add_system(Box::new(Runaway { limit: 1e-3 })).unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        // Two substeps (under limits of 1e-3 and 1e-12 s), then the limit is 1e-21 s with 9e-3 s left.
        match w.advance_interruptible(0.01, None, &stop) {
            Err(Error::Diverged { quantity: crate::error::Failure::Speed, step, rolled_back_to, .. }) => {
                assert_eq!((step, rolled_back_to), (2, 0));
            }
            r => panic!("{r:?}"),
        }
        // Rolled back to the call's start.
        assert_eq!(w.time(), 0.0);
        // A duration too long for the limit at the call's start stays the caller's error.
        let mut w =
            World::<DVec2>::new(ParticleSystem::<DVec2>::new("semi_implicit_euler").unwrap(), 1e-3, Some(1)).unwrap();
        w.add_system(Box::new(Runaway { limit: 1e-15 })).unwrap();
        match w.advance_interruptible(10.0, None, &stop) {
            Err(Error::InvalidInput { arg, .. }) => assert_eq!(arg, "duration"),
            r => panic!("{r:?}"),
        }
    }
}
