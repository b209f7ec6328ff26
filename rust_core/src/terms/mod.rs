//! Force terms. A scene holds only the terms it names; each is evaluated only if present.
pub mod contacts;
pub mod coulomb;
pub mod drag;
pub mod electric_field;
pub mod gravity;
pub mod grid_fields;
pub mod magnetic_field;
pub mod pairwise_gravity;
pub mod pairwise_small;
pub mod potentials;
pub mod registry;
pub mod roles;
pub mod springs;
pub mod tree_gravity;
pub mod xpbd;

use crate::error::Result;
use crate::neighbors::Shared;
use crate::par;
use crate::state::Model;
use crate::stop::Stop;
use crate::vector::{Real, Vector};
use std::ops::Range;

pub use drag::Drag;
pub use gravity::UniformGravity;
pub use magnetic_field::UniformMagneticField;
pub use pairwise_gravity::{Pairwise, PairwiseGravity};
pub use roles::{
    BodyMotion, Constraints, FusedForce, Jacobian, Magnetic, MovingBoundary, OwnState, Spins, VelocityProjection,
};
pub use springs::Springs;
pub use tree_gravity::TreeGravity;

/// How a term stores its forces in the buffer of an evaluation: the first term overwrites what
/// the buffer holds (the previous evaluation's forces), which saves a zeroing pass; the others
/// add to it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Write {
    Overwrite,
    Add,
}

/// The stage of a step at which a `VelocityProjection` runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Projection {
    /// The step's start, before the forces: the velocities are made divergence free.
    Divergence,
    /// After the kick, before the drift: the predicted velocities are made to keep the density.
    Density,
}

impl Write {
    /// Stores force `f` into `slot` (`=` or `+=`).
    #[inline(always)]
    pub fn put<V: Vector>(self, slot: &mut V, f: V) {
        *slot = match self {
            Write::Overwrite => f,
            Write::Add => *slot + f,
        };
    }
}

/// What a term is, read when it joins a force set (`ForceSet::push`, `replace`) and fixed for
/// its life: a term whose parameters change is replaced, not told. Build one from
/// `Traits::conservative()` or `Traits::dissipative()` and change the fields that differ.
#[derive(Clone, Copy, Debug)]
pub struct Traits<V> {
    /// Whether the term can dissipate energy (drag, dashpots): its `add_forces` then returns
    /// the power it dissipates, which the integrators book.
    pub dissipative: bool,
    /// Whether the forces depend on the velocities: integrators that evaluate forces at
    /// predicted states (velocity Verlet) then predict the velocities too. Dissipative terms
    /// usually do; the magnetic force q v × B does too, though it does no work.
    pub velocity_dependent: bool,
    /// Whether `potential` costs little next to a step (a pass over the particles or the
    /// springs): what a coupling that moves particles evaluates around its moves to book what
    /// they change (`systems::bodies::BodyContacts`). Terms whose potential needs a neighbour
    /// search or a pair sum (SPH, DEM contacts, N-body gravity) say no, and the coupling leaves
    /// their share to the books' drift rather than pay two searches a step.
    pub cheap_potential: bool,
    /// Whether the term has a softening length (so that a divergence's advice may name it).
    pub softened: bool,
    /// Largest particle index the term refers to, plus one (0 if none).
    pub min_particles: usize,
    /// The integrators the term can be stepped by (`None`: any).
    pub integrators: Option<&'static [&'static str]>,
    /// `Some(g)` for a uniform acceleration field (world gravity, m/s²): integrators then add
    /// `g` to every free particle's acceleration directly and `add_forces` is never called.
    pub uniform: Option<V>,
}

impl<V> Traits<V> {
    /// A conservative term: no dissipation, no velocity dependence, a cheap potential.
    pub fn conservative() -> Self {
        Traits {
            dissipative: false,
            velocity_dependent: false,
            cheap_potential: true,
            softened: false,
            min_particles: 0,
            integrators: None,
            uniform: None,
        }
    }
    /// A term that dissipates, with forces that depend on the velocities.
    pub fn dissipative() -> Self {
        Traits { dissipative: true, velocity_dependent: true, ..Self::conservative() }
    }
    /// `conservative()` where `dissipative` is false, else `dissipative()`.
    pub fn dissipating(dissipative: bool) -> Self {
        if dissipative {
            Self::dissipative()
        } else {
            Self::conservative()
        }
    }
}

/// Which evaluation `Term::reserve` reserves scratch for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scratch {
    /// A step's force evaluations (`add_forces`).
    Step,
    /// The energy books (`potential`, which reads through `&self`).
    Potential,
}

/// What a term is told about the call or the system it is in (`Term::set`).
#[derive(Clone, Debug)]
pub enum Setting {
    /// The scene's state became single precision (`true`) or double: a term may then compute
    /// in float32 where that is faster (pairwise gravity does).
    Single(bool),
    /// The stop flag of the interruptible call in progress (`Stop::default()` between calls).
    /// A term whose one evaluation may take long polls it and skips the rest of its work once
    /// it is set (see `crate::stop`).
    Stop(Stop),
    /// The Wisdom–Holman integrator's central body during its force evaluation (`None` after
    /// it): Newtonian gravity leaves out every pair with that body, whose pull the integrator
    /// takes as Kepler orbits (`integrators::wisdom_holman`).
    KeplerCentre(Option<usize>),
}

/// What a term reports besides its forces and energies (`Term::diagnostics`); empty by default.
#[derive(Clone, Debug, Default)]
pub struct Diagnostics {
    /// Wall time (s) spent so far in up to three phases of its evaluation (SPH: cell list and
    /// gather, density, forces) and the heap bytes it holds.
    pub profile: Option<([f64; 3], usize)>,
    /// Counters (contacts now), by name.
    pub counts: Vec<(&'static str, u64)>,
    /// Real-valued statistics (a solver's iterations and residuals), by name.
    pub stats: Vec<(&'static str, Real)>,
}

/// One force term: its forces, its potential and books, its scratch, and the roles it may play
/// besides (`roles`). The trait is kept small on purpose (a test caps it, `trait_sizes`): what
/// one or two terms need is a role they return, not a method every term carries.
pub trait Term<V: Vector>: Send + Sync {
    /// Stable name used as the key of the energy books (unique within a scene).
    fn name(&self) -> &str;
    /// What the term is (`Traits`), fixed for its life.
    fn traits(&self) -> Traits<V>;
    /// Stores this term's forces (N) at `(x, v)` in `f` as `write` says, one per particle (0 for
    /// particles it does not act on). Returns the power it dissipates at this state (W) if it
    /// is dissipative (`Traits`), else 0 (conservative terms skip that sum). Usually ≥ 0; a term
    /// whose non-conservative forces also release stored energy books that as negative
    /// dissipation (DFSPH with surface tension: the surface energy a drop releases as it rounds).
    fn add_forces(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real;
    /// Potential energy (J) if the term is conservative (or has a conservative part).
    fn potential(&self, x: &[V], model: &Model) -> Option<Real>;
    /// The fastest time scale the term introduces (s), used to suggest a dt on divergence.
    fn time_scale(&self, _x: &[V], _model: &Model) -> Option<Real> {
        None
    }
    /// The largest step (s) explicit integrators may take at this state, for terms whose limit
    /// is not a time scale (SPH: CFL and force criteria). `g`: magnitude of the uniform fields.
    fn max_dt(&self, _x: &[V], _v: &[V], _model: &Model, _g: Real) -> Option<Real> {
        None
    }
    /// Named per-particle output fields the term computes now (SPH: "density" in kg/m^dim,
    /// "pressure" in Pa), each over the particles it covers: `(name, particle range, values)`.
    fn fields(&self, _x: &[V], _model: &Model) -> Vec<(&'static str, Range<usize>, Vec<Real>)> {
        Vec::new()
    }
    /// What the term reports besides forces and energies (timings, counters, solver stats).
    fn diagnostics(&self) -> Diagnostics {
        Diagnostics::default()
    }
    /// Tells the term a setting of the call or the system it is in (`Setting`).
    fn set(&mut self, _setting: Setting) {}
    /// Called once when the term is added to a system, before it is evaluated: a term that
    /// needs neighbours joins a search that terms of its kind already share in this system, or
    /// registers its own (see `neighbors::Shared`). Terms without neighbours need not implement
    /// it.
    fn join(&mut self, _shared: &mut Shared) -> Result<()> {
        Ok(())
    }
    /// Reserves, fallibly, the scratch an evaluation over `n` particles needs (`Scratch`), so
    /// that it then allocates nothing sized by `n` (a refused allocation is
    /// `Error::OutOfMemory`, not an abort of the process). Terms without per-particle scratch
    /// need not implement it.
    fn reserve(&mut self, _n: usize, _for: Scratch) -> Result<()> {
        Ok(())
    }
    /// Bytes an evaluation over `n` particles allocates on the fly, where a refusal cannot be
    /// reported (inside parallel parts); the world checks they can be had before stepping.
    fn transient_bytes(&self, _n: usize) -> u128 {
        0
    }
    // ---- Roles besides giving forces (`roles`): each stage asks for the one it runs. ------
    /// The term as the batch's fused kernel can step it (`crate::batch`; `None`: it cannot).
    fn as_fused(&self) -> Option<&dyn FusedForce> {
        None
    }
    /// The term as a magnetic field, for the Boris push (`None`: not one).
    fn as_magnetic(&self) -> Option<&dyn Magnetic<V>> {
        None
    }
    /// The term as XPBD constraints, for the "xpbd" integrator (`None`: not one).
    fn as_constraints(&mut self) -> Option<&mut dyn Constraints<V>> {
        None
    }
    /// The term as a velocity projection (DFSPH's pressure solve), for "semi_implicit_euler".
    fn as_projection(&mut self) -> Option<&mut dyn VelocityProjection<V>> {
        None
    }
    /// The term as a fluid that takes moving boundary particles from rigid bodies (Akinci
    /// 2012), for the bodies' coupling (`None`: not one).
    fn as_moving_boundary(&mut self) -> Option<&mut dyn MovingBoundary<V>> {
        None
    }
    /// The term's Jacobians, for implicit integrators (`None`: taken explicitly).
    fn as_jacobian(&self) -> Option<&dyn Jacobian<V>> {
        None
    }
    /// `as_jacobian`, to prepare the products of a step.
    fn as_jacobian_mut(&mut self) -> Option<&mut dyn Jacobian<V>> {
        None
    }
    /// The term's own state (contacts' spins and springs, DFSPH's warm starts), `None` if it
    /// has none besides the particles'.
    fn as_own_state(&self) -> Option<&dyn OwnState<V>> {
        None
    }
    /// `as_own_state`, to step or restore it.
    fn as_own_state_mut(&mut self) -> Option<&mut dyn OwnState<V>> {
        None
    }
}

/// The terms of a scene plus their dissipation ledger.
pub struct ForceSet<V: Vector> {
    pub terms: Vec<Box<dyn Term<V>>>,
    /// Energy dissipated by each term so far (J), same order as `terms`.
    pub dissipated: Vec<Real>,
    power: Vec<Real>,
    /// Whether any term dissipates (else power is never asked for).
    any_dissipative: bool,
    /// Whether any term's force depends on velocity; and any besides the magnetic terms.
    any_velocity: bool,
    any_velocity_apart: bool,
    /// Whether any term is magnetic (`Term::as_magnetic`).
    any_magnetic: bool,
    /// Per term, whether `eval` skips it: a uniform field, which the integrators apply (`g`).
    uniform: Vec<bool>,
    /// Whether any term has Jacobians (`Term::as_jacobian`).
    any_jacobian: bool,
    /// The terms that hold XPBD constraints (`Term::as_constraints`), in term order.
    constraints: Vec<usize>,
    /// The terms that project velocities (`Term::as_projection`), in term order.
    projections: Vec<usize>,
    /// Force evaluations so far (for the work-precision books).
    pub evaluations: u64,
    /// Sum of the uniform acceleration fields (m/s²), applied by the integrators.
    pub g: V,
    /// The stop flag of the call in progress: once set, `eval` skips the remaining terms.
    stop: Stop,
    /// The neighbour searches the terms share (`Term::share`).
    shared: Shared,
}

impl<V: Vector> Default for ForceSet<V> {
    fn default() -> Self {
        Self {
            terms: Vec::new(),
            dissipated: Vec::new(),
            power: Vec::new(),
            any_dissipative: false,
            any_velocity: false,
            any_velocity_apart: false,
            any_magnetic: false,
            uniform: Vec::new(),
            any_jacobian: false,
            constraints: Vec::new(),
            projections: Vec::new(),
            evaluations: 0,
            g: V::ZERO,
            stop: Stop::default(),
            shared: Shared::default(),
        }
    }
}

impl<V: Vector> ForceSet<V> {
    /// Adds `t` after the others (it is evaluated after them), first letting it join the
    /// neighbour searches the terms share.
    pub fn push(&mut self, mut t: Box<dyn Term<V>>) -> Result<()> {
        t.join(&mut self.shared)?;
        self.terms.push(t);
        self.dissipated.push(0.0);
        self.power.push(0.0);
        self.refresh();
        Ok(())
    }

    /// The aggregates over the terms, summed again in term order: what adding them one by one
    /// gives (the uniform fields' sum included, bit for bit).
    fn refresh(&mut self) {
        let terms = &mut self.terms;
        let traits: Vec<Traits<V>> = terms.iter().map(|t| t.traits()).collect();
        self.any_dissipative = traits.iter().any(|t| t.dissipative);
        self.any_velocity = traits.iter().any(|t| t.velocity_dependent);
        self.any_velocity_apart =
            terms.iter().zip(&traits).any(|(t, tr)| tr.velocity_dependent && t.as_magnetic().is_none());
        self.any_magnetic = terms.iter().any(|t| t.as_magnetic().is_some());
        self.any_jacobian = terms.iter().any(|t| t.as_jacobian().is_some());
        self.uniform = traits.iter().map(|t| t.uniform.is_some()).collect();
        self.g = traits.iter().filter_map(|t| t.uniform).fold(V::ZERO, |g, a| g + a);
        self.constraints = (0..terms.len()).filter(|&k| terms[k].as_constraints().is_some()).collect();
        self.projections = (0..terms.len()).filter(|&k| terms[k].as_projection().is_some()).collect();
    }

    /// The terms that hold XPBD constraints, by index (what the "xpbd" integrator projects).
    pub fn constraint_terms(&self) -> &[usize] {
        &self.constraints
    }

    /// Whether term `k` holds XPBD constraints.
    pub fn is_constraint(&self, k: usize) -> bool {
        self.constraints.contains(&k)
    }

    /// Whether any term projects velocities (DFSPH).
    pub fn projects_velocities(&self) -> bool {
        !self.projections.is_empty()
    }

    /// Runs the velocity projections at `stage` (`VelocityProjection::project`), in term order,
    /// booking the kinetic energy each removes as its term's dissipation.
    pub fn project_velocities(&mut self, stage: Projection, x: &[V], v: &mut [V], model: &Model, dt: Real) {
        let g = self.g;
        for &k in &self.projections {
            if let Some(p) = self.terms[k].as_projection() {
                self.dissipated[k] += p.project(stage, x, v, model, dt, g);
            }
        }
    }

    /// Whether any term has Jacobians (an implicit integrator would take it implicitly).
    pub fn has_jacobian(&self) -> bool {
        self.any_jacobian
    }

    /// Puts `t` in place of term `at` (same place in the evaluation order), keeping the energy
    /// the old one dissipated in its books; the aggregates are summed again in term order, so
    /// they are what adding the terms afresh would give. A term that shares a neighbour search
    /// (a fluid) cannot be replaced: its search holds its particles.
    pub fn replace(&mut self, at: usize, mut t: Box<dyn Term<V>>) -> Result<()> {
        let mut probe = Shared::default();
        t.join(&mut probe)?;
        if !probe.is_empty() {
            return Err(crate::error::invalid(
                "item",
                format!("term {:?} shares a neighbour search and cannot be replaced", t.name()),
            ));
        }
        t.set(Setting::Stop(self.stop.clone()));
        self.terms[at] = t;
        self.refresh();
        self.power[at] = 0.0;
        Ok(())
    }

    /// Total force (N) at `(x, v)` into `f`, uniform fields excluded (see `g`). Remembers each
    /// term's dissipated power at this state for a following `book_power` call. Once the stop
    /// flag is set the remaining terms are skipped (the step will be rolled back).
    pub fn eval(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V]) {
        self.eval_terms(x, v, model, f, false);
    }

    /// `eval` without the magnetic terms (the Boris integrator turns the velocities through
    /// their field itself, `magnetic_field`).
    pub fn eval_apart(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V]) {
        self.eval_terms(x, v, model, f, true);
    }

    fn eval_terms(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], apart: bool) {
        self.evaluations += 1;
        let mut write = Write::Overwrite;
        for ((t, p), &uniform) in self.terms.iter_mut().zip(self.power.iter_mut()).zip(&self.uniform) {
            if uniform || (apart && t.as_magnetic().is_some()) {
                continue;
            }
            if self.stop.is_set() {
                break;
            }
            *p = t.add_forces(x, v, model, f, write);
            write = Write::Add;
        }
        if write == Write::Overwrite {
            par::chunks1(f, |_, f| f.fill(V::ZERO));
        }
    }

    /// Books `weight` × (power at the last `eval`) into the dissipation ledger. Integrators call
    /// this with their quadrature weight (e.g. dt/6 for RK4's first stage).
    #[inline]
    pub fn book_power(&mut self, weight: Real) {
        if self.any_dissipative {
            for (d, p) in self.dissipated.iter_mut().zip(&self.power) {
                *d += weight * p;
            }
        }
    }

    /// Hands every term the stop flag of the call in progress (see `crate::stop`).
    pub fn set_stop(&mut self, stop: &Stop) {
        for t in &mut self.terms {
            t.set(Setting::Stop(stop.clone()));
        }
        self.stop = stop.clone();
    }

    /// Whether any term depends on velocity (drag, dashpots, the magnetic force).
    pub fn velocity_dependent(&self) -> bool {
        self.any_velocity
    }

    /// Whether any term besides the magnetic ones depends on velocity (what `eval_apart` sums).
    pub fn velocity_dependent_apart(&self) -> bool {
        self.any_velocity_apart
    }

    /// Whether any term is magnetic.
    pub fn magnetic(&self) -> bool {
        self.any_magnetic
    }

    /// The total magnetic field (T) of the magnetic terms at each position of `x` into `b`
    /// (resized to `x.len()`); false, leaving `b` as it was, if the scene has none.
    pub fn magnetic_field(&self, x: &[V], model: &Model, b: &mut Vec<V::Axial>) -> bool {
        if !self.any_magnetic {
            return false;
        }
        b.clear();
        b.resize(x.len(), V::AXIAL_ZERO);
        for m in self.terms.iter().filter_map(|t| t.as_magnetic()) {
            m.add_field(x, model, b);
        }
        true
    }

    /// Power at the last `eval`, per term (W).
    pub fn last_power(&self) -> &[Real] {
        &self.power
    }
    pub fn set_last_power(&mut self, p: &[Real]) {
        self.power.copy_from_slice(p);
    }
}
