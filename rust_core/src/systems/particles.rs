//! The particle system: particles (state + model) under force terms, advanced by a particle
//! integrator, then projected by the constraint stage. Everything physcore simulated before
//! the `World` existed is this one system.
use super::{array, Arrays, EnergyReport, Halt, Snapshot, System, WorldSetting};
use crate::alloc::{count, Need};
use crate::constraints::{Constraint, Constraints};
use crate::error::{invalid, Failure, Result};
use crate::integrators::{self, Cache, Integrator, IntegratorInfo, IntegratorOptions, Particles, SolverStats};
use crate::par;
use crate::state::{Model, State};
use crate::terms::{ForceSet, Scratch, Setting, Term};
use crate::vector::{Real, Vector};
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};

/// The integrators the batch's fused kernel (`crate::batch`) runs. These types live with
/// the particles, which decide whether they fit it (`fused_shape`); the batch sits above the
/// world and reads them from here, so no module below it imports the batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Scheme {
    /// Velocity Verlet (`integrators::VelocityVerlet`).
    Verlet,
    /// Yoshida's fourth order: three velocity Verlet substeps (`integrators::Yoshida4`).
    Yoshida4,
}

impl Scheme {
    pub(crate) fn evals_per_step(self) -> u64 {
        match self {
            Scheme::Verlet => 1,
            Scheme::Yoshida4 => 3,
        }
    }
}

/// What members of one fused chunk share: particle count, dimension and integrator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Shape {
    pub n: usize,
    pub dim: usize,
    pub scheme: Scheme,
}

pub struct ParticleSystem<V: Vector> {
    sys: Particles<V>,
    integrator: Box<dyn Integrator<V>>,
    constraints: Constraints<V>,
    /// The integrators' options (`IntegratorOptions`), kept when switching integrators.
    options: IntegratorOptions,
    /// The last checkpoint's snapshot, handed back unused (`System::recycle`), of a system of at
    /// most `SPARE_MAX` particles: the next snapshot copies into its buffers instead of
    /// allocating ~7 (a batch of small members takes one per general member per call).
    spare: std::sync::Mutex<Option<Box<ParticleSnapshot<V>>>>,
    /// The integrator's `settle` left a position or velocity not finite (`settled_fault`).
    settled_non_finite: bool,
}

/// What `ParticleSystem::restore` returns to (see `System::snapshot`).
struct ParticleSnapshot<V: Vector> {
    state: State<V>,
    dissipated: Vec<Real>,
    collisions: Real,
    cache: Option<Cache<V>>,
    /// dopri5's (accepted, rejected, next h): the counts are restored too.
    adaptive: Option<(u64, u64, Real)>,
    /// The terms' own states (`OwnState::history`), in term order.
    histories: Vec<Option<Vec<Real>>>,
}

/// The most particles a system keeps a spare snapshot for (`System::recycle`).
const SPARE_MAX: usize = 4096;

/// `dst` becomes a copy of `src`, in `dst`'s buffer where it is large enough; a refused
/// allocation is an error.
fn copy_into<T: Clone>(dst: &mut Vec<T>, src: &[T]) -> std::result::Result<(), std::collections::TryReserveError> {
    dst.clear();
    dst.try_reserve(src.len())?;
    dst.extend_from_slice(src);
    Ok(())
}

impl<V: Vector> ParticleSystem<V> {
    /// An empty system stepped by the integrator named `integrator` (`integrators::NAMES`).
    pub fn new(integrator: &str) -> Result<Self> {
        Ok(Self {
            sys: Particles {
                state: State::default(),
                model: Model::default(),
                forces: ForceSet::default(),
                single: false,
            },
            integrator: {
                let mut it = integrators::by_name(integrator)?;
                it.configure(&IntegratorOptions::default());
                it
            },
            constraints: Constraints::default(),
            options: IntegratorOptions::default(),
            spare: std::sync::Mutex::new(None),
            settled_non_finite: false,
        })
    }

    /// Positions (m) and velocities (m/s).
    pub fn state(&self) -> &State<V> {
        &self.sys.state
    }
    /// Positions and velocities to change, with the masses and attributes beside them (a
    /// coupling's exchange with another system, run between steps).
    pub fn state_model_mut(&mut self) -> (&mut State<V>, &Model) {
        (&mut self.sys.state, &self.sys.model)
    }
    /// `state_model_mut` with the spins a term gives the particles (`OwnState::spins`, the
    /// first term that gives them): a coupling that pushes particles at their surface turns
    /// them too.
    pub fn state_model_spins_mut(&mut self) -> (&mut State<V>, &Model, Option<crate::terms::Spins<'_, V>>) {
        let spins = self.sys.forces.terms.iter_mut().find_map(|t| t.as_own_state_mut().and_then(|o| o.spins()));
        (&mut self.sys.state, &self.sys.model, spins)
    }
    /// Say that a coupling moved particles or changed their velocities between steps: the
    /// integrator's cached forces (velocity Verlet's force at the step's end, kept for the
    /// next step's first kick) were evaluated at the old state and are dropped, as the
    /// constraint stage drops them (`Constraints::apply`).
    pub fn state_changed(&mut self) {
        self.integrator.reset();
    }
    /// The potential energy at the positions now (J) of the terms whose potential is cheap to
    /// evaluate (`Traits::cheap_potential`: gravity, springs, fields; not SPH, DEM contacts or
    /// N-body gravity): what a coupling that moves particles books of what its moves change.
    pub fn cheap_potential_energy(&self) -> Real {
        let (x, m) = (&self.sys.state.x, &self.sys.model);
        self.sys.forces.terms.iter().filter(|t| t.traits().cheap_potential).filter_map(|t| t.potential(x, m)).sum()
    }
    /// The fluids that take moving boundary particles from rigid bodies (`MovingBoundary`), with
    /// the masses and attributes.
    pub fn moving_boundaries(&mut self) -> (Vec<&mut dyn crate::terms::MovingBoundary<V>>, &Model) {
        let hosts = self.sys.forces.terms.iter_mut().filter_map(|t| t.as_moving_boundary()).collect();
        (hosts, &self.sys.model)
    }
    /// Masses and optional attributes.
    pub fn model(&self) -> &Model {
        &self.sys.model
    }
    /// The force terms and their dissipation ledger.
    pub fn forces(&self) -> &ForceSet<V> {
        &self.sys.forces
    }
    /// Energy removed by the constraint stage so far, J.
    /// The energy each force term has dissipated so far (J), in term order.
    pub fn dissipated_by_term(&self) -> &[Real] {
        &self.sys.forces.dissipated
    }
    pub fn constraints_dissipated(&self) -> Real {
        self.constraints.dissipated
    }
    pub fn n_constraints(&self) -> usize {
        self.constraints.len()
    }

    /// The divergence remedies the terms and the integrator offer (for the error's advice).
    pub fn remedies(&self) -> crate::error::Remedies {
        let terms = &self.sys.forces.terms;
        crate::error::Remedies {
            softening: terms.iter().any(|t| t.traits().softened),
            implicit: !self.integrator.implicit() && self.sys.forces.has_jacobian(),
        }
    }

    /// The memory a term's last evaluation could not have (`OwnState::refused`), if any.
    pub fn refusal(&self) -> Option<crate::error::Error> {
        self.sys.forces.terms.iter().filter_map(|t| t.as_own_state()).find_map(|s| s.refused())
    }

    /// Bytes the terms allocate on the fly in a step (`Term::transient_bytes`).
    pub fn transient_bytes(&self) -> u128 {
        let n = self.n_particles();
        self.sys.forces.terms.iter().map(|t| t.transient_bytes(n)).sum()
    }

    /// Refuses a step `dt`, or these particles and terms, where the integrator cannot step them
    /// (`Integrator::check_step`).
    pub fn check_dt(&self, dt: Real) -> Result<()> {
        if self.options.wh_corrector > 0
            && self.integrator.info().name == "wisdom_holman"
            && !self.constraints.is_empty()
        {
            // The corrected map keeps a private state between a call's steps (its joined
            // drifts), which a collision between them would not see.
            return Err(invalid(
                "wh_corrector",
                "the symplectic corrector steps a call's steps unobserved, and this scene has colliders (planes, boxes or spheres) that act between steps (set wh_corrector=0, or remove them)",
            ));
        }
        self.integrator.check_step(&self.sys, dt)
    }

    /// Reserves, fallibly, the scratch the terms' potentials need (`Scratch::Potential`).
    pub fn reserve_potential(&mut self) -> Result<()> {
        let n = self.n_particles();
        self.sys.forces.terms.iter_mut().try_for_each(|t| t.reserve(n, Scratch::Potential))
    }

    /// The shape of these particles for the batch's fused kernel (`crate::batch`), where it
    /// steps them with the same bits: float64, 1..=`pairwise_small::SMALL` particles, velocity
    /// Verlet or Yoshida's fourth order, no constraints or colliders, and terms that are
    /// uniform fields or one small pairwise sum (gravity or Coulomb), nothing else.
    pub(crate) fn fused_shape(&self) -> Option<Shape> {
        let (sys, n) = (&self.sys, self.sys.state.x.len());
        let scheme = match self.integrator.info().name {
            "verlet" => Scheme::Verlet,
            "yoshida4" => Scheme::Yoshida4,
            _ => return None,
        };
        if sys.single || n == 0 || !self.constraints.is_empty() || sys.forces.velocity_dependent() {
            return None;
        }
        let mut pairwise = 0;
        for t in &sys.forces.terms {
            if t.as_fused().and_then(|f| f.small_pairwise(&sys.model, n)).is_some() && t.as_own_state().is_none() {
                pairwise += 1;
            } else if t.traits().uniform.is_none() {
                return None;
            }
        }
        (pairwise == 1).then_some(Shape { n, dim: V::DIM, scheme })
    }

    /// What the fused kernel reads and writes (`crate::batch`): the particles and the
    /// integrator (its force cache).
    pub(crate) fn fused_parts(&mut self) -> (&mut Particles<V>, &mut dyn Integrator<V>) {
        (&mut self.sys, self.integrator.as_mut())
    }

    pub fn n_particles(&self) -> usize {
        self.sys.state.x.len()
    }
    pub fn integrator_info(&self) -> IntegratorInfo {
        self.integrator.info()
    }
    pub fn set_integrator(&mut self, name: &str) -> Result<()> {
        for t in &self.sys.forces.terms {
            check_integrator(t.as_ref(), name)?;
        }
        let mut it = integrators::by_name(name)?;
        it.configure(&self.options);
        self.integrator = it;
        Ok(())
    }

    /// Sets the integrators' options (validated; nothing changes on error).
    pub fn set_options(&mut self, o: IntegratorOptions) -> Result<()> {
        o.validate()?;
        self.options = o;
        self.integrator.configure(&o);
        Ok(())
    }
    /// The integrators' options.
    pub fn options(&self) -> IntegratorOptions {
        self.options
    }

    /// Substeps per step (1..=100000) and constraint iterations per substep (1..=10000) of the
    /// "xpbd" integrator; stored for any integrator. Defaults 10 and 1.
    pub fn set_substeps(&mut self, substeps: u32, iterations: u32) -> Result<()> {
        self.set_options(IntegratorOptions { xpbd_substeps: substeps, xpbd_iterations: iterations, ..self.options })
    }
    /// (substeps per step, iterations per substep) of "xpbd".
    pub fn substeps(&self) -> (u32, u32) {
        (self.options.xpbd_substeps, self.options.xpbd_iterations)
    }

    /// The coordinates of the "wisdom_holman" split by name ("jacobi", "democratic_heliocentric";
    /// `InvalidInput` naming `wh_coordinates` for another); stored for any integrator.
    pub fn set_wh_coordinates(&mut self, name: &str) -> Result<()> {
        let wh_coordinates = integrators::wisdom_holman::Coordinates::by_name(name)?;
        self.set_options(IntegratorOptions { wh_coordinates, ..self.options })
    }
    /// The name of the "wisdom_holman" coordinates.
    pub fn wh_coordinates(&self) -> &'static str {
        self.options.wh_coordinates.name()
    }
    /// The order of the "wisdom_holman" symplectic corrector (0: none, or one of
    /// `wisdom_holman::CORRECTOR_ORDERS`; `InvalidInput` naming `wh_corrector` for another);
    /// stored for any integrator.
    pub fn set_wh_corrector(&mut self, order: u32) -> Result<()> {
        self.set_options(IntegratorOptions { wh_corrector: order, ..self.options })
    }
    /// The order of the "wisdom_holman" corrector (0: none).
    pub fn wh_corrector(&self) -> u32 {
        self.options.wh_corrector
    }

    /// Relative and absolute (m, m/s) tolerances of the adaptive integrator; stored for any
    /// integrator, used by "dopri5". rtol in [1e-14, 1), atol >= 0.
    pub fn set_tolerances(&mut self, rtol: Real, atol: Real) -> Result<()> {
        self.set_options(IntegratorOptions { rtol, atol, ..self.options })
    }
    pub fn tolerances(&self) -> (Real, Real) {
        (self.options.rtol, self.options.atol)
    }
    /// Relative residual (in [1e-14, 1)) and iteration limit (in 1..=1e6) of the linear solve of
    /// an implicit integrator ("implicit_euler"); stored for any integrator.
    pub fn set_solver_options(&mut self, tol: Real, max_iter: u32) -> Result<()> {
        self.set_options(IntegratorOptions { cg_tol: tol, cg_max_iter: max_iter, ..self.options })
    }
    pub fn solver_options(&self) -> (Real, u32) {
        (self.options.cg_tol, self.options.cg_max_iter)
    }
    /// The linear solver's books of an implicit integrator (see `SolverStats`).
    pub fn solver_stats(&self) -> Option<SolverStats> {
        self.integrator.solver_stats()
    }
    /// (accepted, rejected internal steps, next internal step in s) for "dopri5".
    pub fn adaptive_stats(&self) -> Option<(u64, u64, Real)> {
        self.integrator.as_adaptive().map(|a| a.stats())
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
            t.set(Setting::Single(single));
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
        let t = self.admit(t)?;
        self.sys.forces.push(t)?;
        self.integrator.reset();
        Ok(())
    }

    /// The checks a term joining the system passes, new or replacing one (its particles exist,
    /// the integrator can step it), and the scene's precision handed to it.
    fn admit(&self, mut t: Box<dyn Term<V>>) -> Result<Box<dyn Term<V>>> {
        let min = t.traits().min_particles;
        if min > self.n_particles() {
            return Err(invalid("term", format!("refers to {min} particles, the scene has {}", self.n_particles())));
        }
        check_integrator(t.as_ref(), self.integrator.info().name)?;
        t.set(Setting::Single(self.sys.single));
        Ok(t)
    }

    /// Replaces the term named as `t` is by `t` (`ForceSet::replace`), checked as `add_term`
    /// checks a new one; nothing changes on error. The integrator's cached forces are dropped.
    pub fn replace_term(&mut self, t: Box<dyn Term<V>>) -> Result<()> {
        let Some(at) = self.sys.forces.terms.iter().position(|o| o.name() == t.name()) else {
            return Err(invalid("name", format!("the scene has no term named {:?}", t.name())));
        };
        let t = self.admit(t)?;
        self.sys.forces.replace(at, t)?;
        self.integrator.reset();
        Ok(())
    }

    /// Appends a constraint to the projection stage (walls: `constraints::{Plane, Aabb, Sphere}`, built
    /// validated by their `new`).
    pub fn add_constraint(&mut self, c: Box<dyn Constraint<V>>) {
        self.constraints.push(c);
    }

    /// Replaces positions and/or velocities (same particle count), e.g. to restore a saved run.
    pub fn set_state(&mut self, x: Option<Vec<V>>, v: Option<Vec<V>>) -> Result<()> {
        self.check_state(x.as_deref(), v.as_deref())?;
        if let Some(x) = x {
            self.sys.state.x = x;
            self.settle_positions();
        }
        if let Some(v) = v {
            self.sys.state.v = v;
            self.settle_velocities();
        }
        self.integrator.reset();
        Ok(())
    }

    /// `set_state` of both from slices, copied into the arrays it has (no allocation: a device
    /// batch writes thousands of small members back each call); the same checks, the same bits.
    pub fn set_state_from(&mut self, x: &[V], v: &[V]) -> Result<()> {
        self.check_state(Some(x), Some(v))?;
        self.sys.state.x.copy_from_slice(x);
        self.settle_positions();
        self.sys.state.v.copy_from_slice(v);
        self.settle_velocities();
        self.integrator.reset();
        Ok(())
    }

    /// `InvalidInput` naming "positions" / "velocities" for rows that are not finite, do not fit
    /// float32 in a single-precision system, or are not one a particle.
    fn check_state(&self, x: Option<&[V]>, v: Option<&[V]>) -> Result<()> {
        let n = self.n_particles();
        for (rows, arg) in [(x, "positions"), (v, "velocities")] {
            let Some(rows) = rows else { continue };
            self.check_single_range(rows, arg)?;
            if rows.len() != n {
                return Err(invalid(arg, format!("has {} rows, the scene has {n} particles", rows.len())));
            }
            if let Some(i) = rows.iter().position(|p| !p.is_finite()) {
                return Err(invalid(arg, format!("row {i} is not finite")));
            }
        }
        Ok(())
    }

    /// The positions just set: rounded to float32 in a single-precision system.
    fn settle_positions(&mut self) {
        if self.sys.single {
            self.sys.state.x.iter_mut().for_each(|p| *p = p.round_f32());
        }
    }

    /// The velocities just set: a pinned particle's zero, the others rounded to float32 in a
    /// single-precision system.
    fn settle_velocities(&mut self) {
        let single = self.sys.single;
        let (model, v) = (&self.sys.model, &mut self.sys.state.v);
        for (i, vi) in v.iter_mut().enumerate() {
            if model.is_pinned(i) {
                *vi = V::ZERO;
            } else if single {
                *vi = vi.round_f32();
            }
        }
    }

    /// Checks the books of a saved run (per-term dissipated energy and the constraints', J; the
    /// integrator's cache) against this system; nothing changes. `restore_books` then cannot fail.
    pub fn check_books(&self, dissipated: &[Real], collisions: Real, cache: &Option<Cache<V>>) -> Result<()> {
        if dissipated.len() != self.sys.forces.terms.len() {
            return Err(invalid("dissipated", "does not match the scene's terms"));
        }
        if let Some(d) = dissipated.iter().chain([&collisions]).find(|d| !d.is_finite()) {
            return Err(invalid("dissipated", format!("must be finite, got {d}")));
        }
        if let Some((f, p)) = cache {
            if !(f.iter().all(|x| x.is_finite()) && p.iter().all(|x| x.is_finite())) {
                return Err(invalid("cache", "must be finite"));
            }
        }
        Ok(())
    }

    /// Restores the books `check_books` accepted; `InvalidInput` (and no change) if the cache
    /// does not fit the integrator.
    pub fn restore_books(&mut self, dissipated: &[Real], collisions: Real, cache: Option<Cache<V>>) -> Result<()> {
        self.check_books(dissipated, collisions, &cache)?;
        match cache {
            Some((f, p)) => {
                if !self.integrator.as_carry_mut().is_some_and(|c| c.set(f, p, &self.sys.state.v, dissipated.len())) {
                    return Err(invalid("cache", "does not match the scene or its integrator"));
                }
            }
            None => self.integrator.reset(),
        }
        self.sys.forces.dissipated.copy_from_slice(dissipated);
        self.constraints.dissipated = collisions;
        Ok(())
    }

    pub fn integrator_cache(&self) -> Option<Cache<V>> {
        self.integrator.as_carry().and_then(|c| c.get())
    }

    /// `integrator_cache` with its copy of the forces allocated fallibly: `Error::OutOfMemory`
    /// naming `what` (a scene's `state()` and save read it: 72 MB for 3·10⁶ particles in 3D,
    /// and an infallible copy aborted the process under a memory cap).
    pub fn try_integrator_cache(&self, what: &'static str) -> Result<Option<Cache<V>>> {
        let Some(c) = self.integrator.as_carry() else { return Ok(None) };
        c.try_get().map_err(|_| {
            let n = self.n_particles();
            Need::new(
                what,
                Need::bytes_of::<V>(n),
                format!("the integrator's cached forces of {} particles", count(n as u128)),
            )
            .error()
        })
    }

    /// Wall time (s) the terms that keep such books have spent in their phases so far (SPH:
    /// cell list + gather, density, forces), and the heap bytes they hold.
    pub fn fluid_profile(&self) -> ([f64; 3], usize) {
        let mut c = [0.0; 3];
        let mut bytes = 0;
        for (clock, b) in self.sys.forces.terms.iter().filter_map(|t| t.diagnostics().profile) {
            for k in 0..3 {
                c[k] += clock[k];
            }
            bytes += b;
        }
        (c, bytes)
    }

    /// Each term's real-valued statistics (`Diagnostics::stats`): (term name, statistic, value).
    pub fn term_stats(&self) -> Vec<(String, &'static str, Real)> {
        let mut out = Vec::new();
        for t in &self.sys.forces.terms {
            out.extend(t.diagnostics().stats.into_iter().map(|(k, c)| (t.name().to_string(), k, c)));
        }
        out
    }

    /// Each term's counters (`Diagnostics::counts`): (term name, counter, value).
    pub fn term_counts(&self) -> Vec<(String, &'static str, u64)> {
        let mut out = Vec::new();
        for t in &self.sys.forces.terms {
            out.extend(t.diagnostics().counts.into_iter().map(|(k, c)| (t.name().to_string(), k, c)));
        }
        out
    }

    /// The own state (`OwnState::history`) of the term named `name`, `None` if it keeps none.
    pub fn term_history(&self, name: &str) -> Result<Option<Vec<Real>>> {
        self.term_named(name)?.as_own_state().map(|s| s.history()).transpose()
    }

    /// Restores a term's own state (checked; nothing changes on error).
    pub fn set_term_history(&mut self, name: &str, h: &[Real]) -> Result<()> {
        let n = self.n_particles();
        let k = self
            .sys
            .forces
            .terms
            .iter()
            .position(|t| t.name() == name)
            .ok_or_else(|| invalid("name", format!("no term named {name:?}")))?;
        match self.sys.forces.terms[k].as_own_state_mut() {
            Some(s) => s.set_history(h, n),
            None => Err(invalid("history", format!("term {name:?} keeps no state of its own"))),
        }
    }

    fn term_named(&self, name: &str) -> Result<&dyn Term<V>> {
        self.sys
            .forces
            .terms
            .iter()
            .find(|t| t.name() == name)
            .map(|t| t.as_ref())
            .ok_or_else(|| invalid("name", format!("no term named {name:?}")))
    }

    /// Whether every dissipated energy (the force terms', the colliders', the terms' own) is
    /// finite.
    fn books_finite(&self) -> bool {
        let f = &self.sys.forces;
        f.dissipated.iter().chain([&self.constraints.dissipated]).all(|d| d.is_finite())
            && f.terms.iter().filter_map(|t| t.as_own_state()).all(|s| s.books_finite())
    }

    /// The fastest particle (the first of equals; 0 if none is).
    fn fastest(&self) -> usize {
        let speeds = self.sys.state.v.iter().map(|u| u.length_squared());
        speeds.enumerate().fold((0, -1.0), |(i, m), (k, s)| if s > m { (k, s) } else { (i, m) }).0
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

    /// (fastest time scale τ = 1/ω_max over the terms, smallest term step limit such as the
    /// SPH CFL), each infinite if no term has one. `implicit`: leave out the terms an implicit
    /// integrator takes implicitly (the `Jacobian` role), returning their τ apart, as a third.
    /// Under "xpbd" the XPBD constraints are in that third too (projected like implicit Euler
    /// steps a spring); under other integrators they are inert and set no time scale.
    fn time_scales_split(&self, implicit: bool) -> (Real, Real, Real) {
        let (x, v, m) = (&self.sys.state.x, &self.sys.state.v, &self.sys.model);
        let terms = &self.sys.forces.terms;
        let xpbd = self.integrator.info().name == "xpbd";
        let scale = |implicitly: bool| {
            let forces = &self.sys.forces;
            terms
                .iter()
                .enumerate()
                .filter(|&(k, _)| xpbd || !forces.is_constraint(k))
                .filter(|&(k, t)| ((implicit && t.as_jacobian().is_some()) || forces.is_constraint(k)) == implicitly)
                .filter_map(|(_, t)| t.time_scale(x, m))
                .fold(f64::INFINITY, f64::min)
        };
        let g = self.sys.forces.g.length_squared().sqrt();
        let limit = terms.iter().filter_map(|t| t.max_dt(x, v, m, g)).fold(f64::INFINITY, f64::min);
        // "xpbd" steps the force terms in substeps of semi-implicit Euler: their limits are
        // the substep's, and a step may be `substeps` times longer.
        let sub = if self.integrator.info().name == "xpbd" { self.options.xpbd_substeps as Real } else { 1.0 };
        (sub * scale(false), sub * limit, sub * scale(true))
    }

    /// `time_scales_split(false)` without the third.
    fn time_scales(&self) -> (Real, Real) {
        let (ts, limit, _) = self.time_scales_split(false);
        (ts, limit)
    }

    /// Σ m v over free particles, kg·m/s.
    pub fn momentum(&self) -> V {
        let (v, m) = (&self.sys.state.v, &self.sys.model);
        par::sum(v.len(), V::ZERO, |r| {
            let mut p = V::ZERO;
            for i in r {
                if m.inv_mass[i] != 0.0 {
                    p += v[i] * m.mass[i];
                }
            }
            p
        })
    }

    /// Σ m x × v about the origin over free particles, plus the spins terms carry (contacts:
    /// Σ Iω), kg·m²/s (2D: only z is non-zero).
    pub fn angular_momentum(&self) -> [Real; 3] {
        let (x, v, m) = (&self.sys.state.x, &self.sys.state.v, &self.sys.model);
        let l = par::sum(x.len(), glam::DVec3::ZERO, |r: Range<usize>| {
            let mut l = glam::DVec3::ZERO;
            for i in r {
                if m.inv_mass[i] != 0.0 {
                    let c = x[i].cross3(v[i]);
                    l += glam::DVec3::from_array(c) * m.mass[i];
                }
            }
            l
        });
        let mut l = l.to_array();
        for t in self.sys.forces.terms.iter().filter_map(|t| t.as_own_state()) {
            let s = t.angular_momentum(m);
            for k in 0..3 {
                l[k] += s[k];
            }
        }
        l
    }
}

/// How many times the explicit auto step (ω_max·dt = 0.5) an implicit integrator takes on the
/// terms it treats implicitly: ω_max·dt = 10. Stability no longer bounds it, accuracy does:
/// backward Euler shrinks a mode of frequency ω by 1/√(1 + ω²dt²) a step, i.e. by
/// (1 + ω²dt²)^(−π/(ω dt)) a period. The fastest (stretch) modes, which the large step is meant
/// to skip, are damped to 10 % within one step; a mode at ω_max/1000 (the swing of a stiff
/// cloth) keeps 97 % of its amplitude per period, one at ω_max/100 73 %. A larger factor buys
/// speed with more numerical damping of the slow motion (at 50×: 92 % and 47 % per period).
pub const IMPLICIT_DT_FACTOR: Real = 20.0;

impl<V: Vector> System for ParticleSystem<V> {
    fn name(&self) -> &str {
        "particles"
    }
    fn is_empty(&self) -> bool {
        self.n_particles() == 0
    }

    /// Reserves, fallibly, the per-particle scratch of the integrator and the terms (sized on
    /// the first step and after particles are added).
    fn prepare(&mut self) -> Result<()> {
        let n = self.n_particles();
        let name = self.integrator.info().name;
        let bufs = self.integrator.scratch(self.sys.forces.velocity_dependent());
        let missing = bufs.iter().filter(|b| b.capacity() < n).count();
        let of = || format!("the {name} integrator's scratch for {} particles", count(n as u128));
        // (Described only when something is missing: a batch prepares thousands of small
        // members per call.)
        if missing > 0 {
            let need = Need::new("step", Need::bytes_of::<V>(n) * missing as u128, of());
            for b in bufs {
                need.reserve(b, n)?;
            }
        }
        let axial = self.integrator.axial_scratch();
        let missing = axial.iter().filter(|b| b.capacity() < n).count();
        if missing > 0 {
            let need = Need::new("step", Need::bytes_of::<V::Axial>(n) * missing as u128, of());
            for b in axial {
                need.reserve(b, n)?;
            }
        }
        // On the world's pool: the cell lists size their histograms by its thread count.
        self.sys.forces.terms.iter_mut().try_for_each(|t| t.reserve(n, Scratch::Step))
    }

    fn set(&mut self, setting: &WorldSetting) {
        if let WorldSetting::Stop(stop) = setting {
            self.sys.forces.set_stop(stop);
        }
    }

    /// One integrator step, then the constraint stage. A stop flag seen set during the step
    /// (a term may have skipped part of its forces) halts it: the step must not stand.
    fn step(&mut self, dt: Real, stop: &AtomicBool) -> std::result::Result<(), Halt> {
        if self.is_empty() {
            return Ok(());
        }
        for s in self.sys.forces.terms.iter_mut().filter_map(|t| t.as_own_state_mut()) {
            s.begin_step(dt);
        }
        let Ok(non_finite) = self.integrator.step_interruptible(&mut self.sys, dt, stop) else {
            return Err(Halt::Stopped);
        };
        if stop.load(Ordering::Relaxed) {
            return Err(Halt::Stopped);
        }
        // A term refused its lists: its forces were left out, so the step must not stand.
        if self.refusal().is_some() {
            return Err(Halt::Diverged { index: 0, quantity: Failure::Memory });
        }
        if !non_finite {
            let sys = &mut self.sys;
            for s in sys.forces.terms.iter_mut().filter_map(|t| t.as_own_state_mut()) {
                s.end_step(&sys.state.x, &sys.state.v, &sys.model, dt);
            }
        }
        if !self.constraints.is_empty() {
            // The own states close the step at the state the integrator made, before the
            // projections move it: a contact's books take its force's work at the velocities it
            // did that work with (closed after a reflection, at the reflected velocity, an
            // elastic gas in a box drifted +2.2e-3 of its energy in 40 collision times).
            if !non_finite {
                let sys = &mut self.sys;
                for s in sys.forces.terms.iter_mut().filter_map(|t| t.as_own_state_mut()) {
                    s.settle(&sys.state.x, &sys.state.v, &sys.model);
                }
            }
            let (f, g, kick) =
                (self.integrator.last_forces(), self.sys.forces.g, self.integrator.info().projection_kick(dt));
            if self.constraints.apply(&mut self.sys.state, &self.sys.model, f, g, kick, self.sys.single) {
                self.integrator.reset();
            }
        }
        if non_finite {
            let (index, quantity) = self
                .first_non_finite()
                .or(self.integrator.as_adaptive().and_then(|a| a.failure()))
                .unwrap_or((0, Failure::Position));
            return Err(Halt::Diverged { index, quantity });
        }
        // What the integrator does not see: the state terms keep (a grain's spin) and the
        // books, which overflow while the state is still finite (a call that started then
        // could not be saved, nor loaded back).
        match self.settled_fault() {
            Some((index, quantity)) => Err(Halt::Diverged { index, quantity }),
            None => Ok(()),
        }
    }

    fn settle(&mut self) {
        // The integrator first (the Wisdom–Holman corrector hands back the state the terms see).
        self.settled_non_finite = self.integrator.as_carry_mut().is_some_and(|c| c.settle(&mut self.sys));
        let sys = &mut self.sys;
        for s in sys.forces.terms.iter_mut().filter_map(|t| t.as_own_state_mut()) {
            s.settle(&sys.state.x, &sys.state.v, &sys.model);
        }
    }

    /// A term's own state (`Term::non_finite`), then the books. Also run after every step: a
    /// commit deferred to the next evaluation then shows there.
    fn settled_fault(&self) -> Option<(usize, Failure)> {
        if self.settled_non_finite {
            return Some(self.first_non_finite().unwrap_or((0, Failure::Position)));
        }
        if let Some(index) = self.sys.forces.terms.iter().filter_map(|t| t.as_own_state()).find_map(|s| s.non_finite())
        {
            return Some((index, Failure::Spin));
        }
        (!self.books_finite()).then(|| (self.fastest(), Failure::Books))
    }

    /// A cached force is still valid; a velocity predicted with the old dt is not.
    fn dt_changed(&mut self) {
        if self.sys.forces.velocity_dependent() {
            self.integrator.reset();
        }
    }

    fn adaptive(&self) -> bool {
        self.integrator.as_adaptive().map(|a| a.stats()).is_some()
    }

    fn limit_follows_flow(&self) -> bool {
        self.sys.forces.projects_velocities()
    }

    /// The largest substep with the current integrator: ω_max·dt = 0.5 with ω_max = 1/τ bounded
    /// from above (Gershgorin), i.e. a quarter of the stability interval of semi-implicit Euler
    /// and Verlet (ω·dt < 2) and under a fifth of RK4's (2√2), and no more than a term's own
    /// limit (SPH CFL). RK4 is not given a longer step for its longer interval: it is
    /// dissipative, and on a stiff chain at ω·dt = 0.71 it lost 26 % of the energy in 200 stiff
    /// periods against 5.6 % at 0.5. Explicit Euler has no stability interval on undamped
    /// oscillations (it grows at every dt) and gets the same step. dopri5 picks its own internal
    /// steps, so only the term limits apply to it.
    ///
    /// An implicit integrator ("implicit_euler") is unconditionally stable on the terms it takes
    /// implicitly (springs, drag), so their time scale τ_J sets its step through accuracy, not
    /// stability: dt = IMPLICIT_DT_FACTOR · 0.5 τ_J = 10/ω_max (see there), within 0.5 τ of the
    /// terms it takes explicitly and every term's own limit. "xpbd" takes its compliant
    /// constraints the same way, per substep (ω_max h = 10): without them a cloth's step was
    /// set by its drag alone (50 s for `xpbd_cloth`, one substep per `advance` call).
    fn auto_dt(&self) -> Option<Real> {
        let implicit = self.integrator.implicit();
        let (ts, limit, ts_implicit) = self.time_scales_split(implicit);
        let factor = if self.adaptive() { f64::INFINITY } else { 0.5 };
        let dt = (factor * ts).min(limit).min(IMPLICIT_DT_FACTOR * 0.5 * ts_implicit);
        (dt.is_finite() && dt > 0.0).then_some(dt)
    }

    /// Half of the fastest time scale of the terms (springs: 1/ω_max by a Gershgorin bound;
    /// gravity: closest free-fall time; drag: m/b), within every term's own limit.
    fn suggest_dt(&self) -> Option<Real> {
        let (ts, limit) = self.time_scales();
        let dt = (0.5 * ts).min(limit);
        dt.is_finite().then_some(dt)
    }

    fn energy(&self) -> EnergyReport {
        let (x, v, m) = (&self.sys.state.x, &self.sys.state.v, &self.sys.model);
        let spin: Real = self.sys.forces.terms.iter().filter_map(|t| t.as_own_state()).map(|s| s.kinetic(m)).sum();
        let kinetic = spin
            + 0.5
                * par::sum(x.len(), 0.0, |r| {
                    let mut k = 0.0;
                    for i in r {
                        if m.inv_mass[i] != 0.0 {
                            k += m.mass[i] * v[i].length_squared();
                        }
                    }
                    k
                });
        let terms = &self.sys.forces.terms;
        let potential = terms.iter().filter_map(|t| t.potential(x, m).map(|u| (t.name().to_string(), u))).collect();
        let mut dissipated: Vec<(String, Real)> = terms
            .iter()
            .zip(&self.sys.forces.dissipated)
            .filter(|(t, _)| t.traits().dissipative)
            .map(|(t, d)| (t.name().to_string(), *d))
            .collect();
        dissipated.extend(terms.iter().filter_map(|t| t.as_own_state()).flat_map(|s| s.books()));
        if !self.constraints.is_empty() {
            dissipated.push(("collisions".to_string(), self.constraints.dissipated));
        }
        EnergyReport { kinetic, potential, dissipated }
    }

    /// The named output fields of every term (see `Term::fields`), one value per particle (0
    /// for particles a field does not cover); `names` fixes which and in what order.
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let n = self.n_particles();
        let need = Need::new(
            "fields",
            Need::bytes_of::<Real>(n) * names.len() as u128,
            format!("{} of {} particles", names.join(" and "), count(n as u128)),
        );
        let mut out = names.iter().map(|_| need.filled(n, 0.0)).collect::<Result<Vec<_>>>()?;
        for t in &self.sys.forces.terms {
            for (name, range, values) in t.fields(&self.sys.state.x, &self.sys.model) {
                if let Some(k) = names.iter().position(|m| *m == name) {
                    out[k][range].copy_from_slice(&values);
                }
            }
        }
        Ok(out)
    }

    /// A copy of the positions and velocities (and cached forces), allocated fallibly.
    fn snapshot(&self) -> Result<Snapshot> {
        let n = self.n_particles();
        let need = || {
            Need::new(
                "step",
                Need::bytes_of::<V>(3 * n),
                format!("a copy of the state of {} particles (to roll back to)", count(n as u128)),
            )
        };
        let spare = self.spare.lock().ok().and_then(|mut s| s.take());
        let mut snap = spare.unwrap_or_else(|| {
            Box::new(ParticleSnapshot {
                state: State::default(),
                dissipated: Vec::new(),
                collisions: 0.0,
                cache: None,
                adaptive: None,
                histories: Vec::new(),
            })
        });
        let st = &self.sys.state;
        let copied = (|| {
            copy_into(&mut snap.state.x, &st.x)?;
            copy_into(&mut snap.state.v, &st.v)?;
            match self.integrator.as_carry().and_then(|c| c.borrow()) {
                Some((f, p)) => {
                    let (cf, cp) = snap.cache.get_or_insert_with(Default::default);
                    copy_into(cf, f)?;
                    copy_into(cp, p)
                }
                None => self.integrator.as_carry().map_or(Ok(None), |c| c.try_get()).map(|c| snap.cache = c),
            }
        })();
        copied.map_err(|_| need().error())?;
        copy_into(&mut snap.dissipated, &self.sys.forces.dissipated).map_err(|_| need().error())?;
        snap.collisions = self.constraints.dissipated;
        snap.adaptive = self.integrator.as_adaptive().map(|a| a.stats());
        snap.histories.clear();
        for t in &self.sys.forces.terms {
            let h = t.as_own_state().map(|s| s.history()).transpose().map_err(|_| need().error())?;
            snap.histories.push(h);
        }
        Ok(snap)
    }

    fn recycle(&mut self, snapshot: Snapshot) {
        // Kept for small systems only: there the allocations are a visible part of a call (a
        // batch's members), while a large system would hold a copy of its state between calls
        // for nothing (an allocation is nothing beside its step).
        if self.n_particles() > SPARE_MAX {
            return;
        }
        if let (Ok(snap), Ok(spare)) = (snapshot.downcast::<ParticleSnapshot<V>>(), self.spare.get_mut()) {
            *spare = Some(snap);
        }
    }

    /// "x", "v" (n × dim, row-major), "dissipated" (one per term), "collisions" (one) and, if the
    /// integrator carries them, "cache_forces" (n × dim) and "cache_power" (one per term).
    fn save(&self) -> Result<Arrays> {
        let st = &self.sys.state;
        let of = format!("the state of {} particles", count(st.x.len() as u128));
        let collisions = [self.constraints.dissipated];
        let mut out = crate::systems::saved(
            &of,
            &[
                ("x", V::flat(&st.x)),
                ("v", V::flat(&st.v)),
                ("dissipated", &self.sys.forces.dissipated),
                ("collisions", &collisions),
            ],
        )?;
        if let Some(c) = self.integrator.as_carry() {
            let carried =
                |f: &[V], p: &[Real]| crate::systems::saved(&of, &[("cache_forces", V::flat(f)), ("cache_power", p)]);
            match c.borrow() {
                Some((f, p)) => out.extend(carried(f, p)?),
                None => {
                    let need = Need::new("save", Need::bytes_of::<V>(st.x.len()), &of);
                    if let Some((f, p)) = c.try_get().map_err(|_| need.error())? {
                        out.extend(carried(&f, &p)?);
                    }
                }
            }
        }
        for t in &self.sys.forces.terms {
            if let Some(s) = t.as_own_state() {
                out.push((format!("history:{}", t.name()), s.history()?));
            }
        }
        if let Some((accepted, rejected, _)) = self.integrator.as_adaptive().map(|a| a.stats()) {
            // Counts below 2^53 are exact in a float64.
            out.push(("adaptive_counts".to_string(), vec![accepted as Real, rejected as Real]));
        }
        Ok(out)
    }

    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let (n, d, terms) = (self.n_particles(), V::DIM, self.sys.forces.terms.len());
        let vectors = |name: &str, len: Option<usize>| -> Result<Vec<V>> {
            let a = array(arrays, name, len)?;
            if a.len() % d != 0 {
                return Err(invalid(name, format!("has {} values, not rows of {d}", a.len())));
            }
            if let Some(i) = a.iter().position(|c| !c.is_finite()) {
                return Err(invalid(name, format!("value {i} is not finite: {}", a[i])));
            }
            Ok(a.chunks_exact(d).map(V::from_slice).collect())
        };
        let (x, v) = (vectors("x", Some(n * d))?, vectors("v", Some(n * d))?);
        let dissipated = array(arrays, "dissipated", Some(terms))?;
        let collisions = array(arrays, "collisions", Some(1))?[0];
        // The cache's shape is the integrator's own (dopri5 adds its controller's memory):
        // `restore_books` asks the integrator whether it fits.
        let cache = match arrays.iter().any(|(k, _)| k == "cache_forces") {
            true => Some((vectors("cache_forces", None)?, array(arrays, "cache_power", None)?.to_vec())),
            false => None,
        };
        let counts = match arrays.iter().any(|(k, _)| k == "adaptive_counts") {
            true => {
                let c = array(arrays, "adaptive_counts", Some(2))?;
                if c.iter().any(|k| !(k.is_finite() && *k >= 0.0 && k.fract() == 0.0 && *k < 2f64.powi(53))) {
                    return Err(invalid("adaptive_counts", "must be whole numbers in [0, 2**53)"));
                }
                Some((c[0] as u64, c[1] as u64))
            }
            false => None,
        };
        self.check_books(dissipated, collisions, &cache)?;
        let mut histories = Vec::new();
        for (k, t) in self.sys.forces.terms.iter().enumerate() {
            if t.as_own_state().is_some() {
                histories.push((k, array(arrays, &format!("history:{}", t.name()), None)?));
            }
        }
        // The cache can only be checked against the integrator once the state is in: on a
        // refusal everything returns to the snapshot.
        let before = self.snapshot()?;
        let r = self.set_state(Some(x), Some(v)).and_then(|()| self.restore_books(dissipated, collisions, cache));
        let r = r.and_then(|()| {
            histories.iter().try_for_each(|&(k, h)| match self.sys.forces.terms[k].as_own_state_mut() {
                Some(s) => s.set_history(h, n),
                None => Ok(()),
            })
        });
        if r.is_err() {
            self.restore(before);
        } else if let Some((accepted, rejected)) = counts {
            if let Some(a) = self.integrator.as_adaptive_mut() {
                a.set_counts(accepted, rejected);
            }
        }
        r
    }

    fn restore(&mut self, snapshot: Snapshot) {
        let ParticleSnapshot { state, dissipated, collisions, cache, adaptive, histories } =
            *snapshot.downcast::<ParticleSnapshot<V>>().expect("a snapshot of this particle system");
        if let Some((accepted, rejected, _)) = adaptive {
            if let Some(a) = self.integrator.as_adaptive_mut() {
                a.set_counts(accepted, rejected);
            }
        }
        let n = state.x.len();
        if let Some(c) = self.integrator.as_carry_mut() {
            c.abandon();
        }
        self.settled_non_finite = false;
        for (t, h) in self.sys.forces.terms.iter_mut().zip(&histories) {
            if let Some(h) = h {
                // A snapshot this system made: it fits, and may hold the non-finite values of
                // a state that had started to diverge.
                if let Some(s) = t.as_own_state_mut() {
                    s.restore_history(h, n);
                }
            }
        }
        self.sys.state = state;
        self.sys.forces.dissipated = dissipated;
        self.constraints.dissipated = collisions;
        let n_terms = self.sys.forces.terms.len();
        let restored = match cache {
            Some((f, p)) => self.integrator.as_carry_mut().is_some_and(|c| c.set(f, p, &self.sys.state.v, n_terms)),
            None => false,
        };
        if !restored {
            self.integrator.reset();
        }
    }
}

/// `InvalidInput` naming the integrator if term `t` cannot be stepped by integrator `name`.
fn check_integrator<V: Vector>(t: &dyn Term<V>, name: &str) -> Result<()> {
    match t.traits().integrators {
        Some(ok) if !ok.contains(&name) => Err(invalid(
            "integrator",
            format!(
                "term {:?} needs integrator {} (this scene uses {name:?})",
                t.name(),
                ok.iter().map(|o| format!("{o:?}")).collect::<Vec<_>>().join(" or ")
            ),
        )),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::ParticleSystem;
    use crate::terms::PairwiseGravity;
    use crate::world::World;
    use glam::DVec2;

    fn bits(w: &World<DVec2>) -> Vec<u64> {
        let s = w.particles().state();
        s.x.iter().chain(&s.v).flat_map(|p| [p.x.to_bits(), p.y.to_bits()]).collect()
    }

    /// A checkpoint made in a recycled snapshot's buffers restores its own state, also after
    /// the particle count grew past what the buffers held, and past `SPARE_MAX`.
    #[test]
    fn a_recycled_snapshot_restores_the_state_it_was_taken_at() {
        let mut w = World::<DVec2>::new(ParticleSystem::<DVec2>::new("verlet").unwrap(), 1e-3, None).unwrap();
        let add = |w: &mut World<DVec2>, n: usize, at: f64| {
            let x = (0..n).map(|k| DVec2::new(at + k as f64, 0.5 * k as f64)).collect();
            w.particles_mut().add_particles(x, vec![DVec2::new(0.0, 0.1); n], vec![1.0; n], vec![false; n]).unwrap();
        };
        add(&mut w, 3, 0.0);
        w.particles_mut().add_term(Box::new(PairwiseGravity::new("g".into(), 1.0, 0.01))).unwrap();
        for more in [0, 2, super::SPARE_MAX] {
            let at = 10.0 + w.particles().state().x.len() as f64;
            add(&mut w, more, at);
            w.step(3).unwrap(); // its checkpoint is recycled
            let before = bits(&w);
            let cp = w.checkpoint().unwrap(); // made in the recycled buffers (if kept)
            w.step(4).unwrap();
            assert_ne!(bits(&w), before);
            w.rollback(cp);
            assert_eq!(bits(&w), before, "after adding {more}");
        }
    }
}
