//! Systems: what a [`World`](crate::world::World) steps together. Each owns its state and
//! buffers and answers the world through one trait: advance by dt, energy books, the largest
//! stable dt, snapshot/restore (rollback, bit-identical restarts) and named output fields.
//!
//! - [`particles::ParticleSystem`]: particles under force terms (springs, gravity, SPH, …),
//!   stepped by a particle integrator, then projected by the constraint stage (walls).
//! - [`ode::OdeSystem`]: a first-order ODE y' = f(y) on a flat array, stepped by any explicit
//!   Butcher tableau of [`crate::ode`] (flows such as the Lorenz system; a field discretised in
//!   space, by the method of lines).
//!
//! - [`flows`]: points advected by a first-order flow (Lorenz, Rössler, …), an `OdeSystem`.
//!
//! Couplings between systems ([`Coupling`]) run after all systems have stepped.
pub mod bodies;
#[cfg(feature = "gpu")]
pub mod device;
#[cfg(feature = "gpu")]
pub mod device_batch;
#[cfg(feature = "gpu")]
pub mod device_dem;
#[cfg(feature = "gpu")]
pub mod device_dfsph;
#[cfg(feature = "gpu")]
pub mod device_fluid;
#[cfg(feature = "gpu")]
pub mod device_sph;
pub mod flows;
pub mod ode;
pub mod particles;

use crate::error::{Failure, Result};
use crate::stop::Stop;
use crate::vector::{Real, Vector};
use std::any::Any;
use std::sync::atomic::AtomicBool;

/// Energy books at one instant (J). `total()` = kinetic + Σ potential + Σ dissipated is conserved
/// by the exact dynamics; its change is the integrator's error.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct EnergyReport {
    pub kinetic: Real,
    /// Potential energy of each conservative term, by term name.
    pub potential: Vec<(String, Real)>,
    /// Energy dissipated so far by each dissipative term and by the constraints ("collisions").
    pub dissipated: Vec<(String, Real)>,
}

impl EnergyReport {
    pub fn total(&self) -> Real {
        self.kinetic
            + self.potential.iter().map(|p| p.1).sum::<Real>()
            + self.dissipated.iter().map(|p| p.1).sum::<Real>()
    }
    /// Adds another system's books to these (kinetic energies add; named entries append).
    pub fn merge(&mut self, other: EnergyReport) {
        self.kinetic += other.kinetic;
        self.potential.extend(other.potential);
        self.dissipated.extend(other.dissipated);
    }
}

/// Everything a system needs to return to an earlier instant, bit for bit. Opaque to the
/// world: only the system that made it reads it back (`System::restore`), so each system keeps
/// whatever it needs (a particle system: state, books, its integrator's cache) without the
/// world knowing its types.
pub type Snapshot = Box<dyn Any + Send>;

/// A system's state as named arrays of reals: what a scene file stores for it. `System::load`
/// reads it back bit for bit, so a run restarted from it continues exactly as the original.
pub type Arrays = Vec<(String, Vec<Real>)>;

/// What a `System::save` returns: `arrays` copied, each allocated fallibly, so that a save under
/// memory pressure is an `Error::OutOfMemory` named "save" (of `of`), not an abort.
pub fn saved(of: impl std::fmt::Display, arrays: &[(&str, &[Real])]) -> Result<Arrays> {
    let total: usize = arrays.iter().map(|(_, a)| a.len()).sum();
    let need = crate::alloc::Need::new("save", crate::alloc::Need::bytes_of::<Real>(total), of);
    arrays.iter().map(|(name, a)| Ok((name.to_string(), need.copy(a)?))).collect()
}

/// A snapshot of a flat state `y` (its copy, allocated fallibly): what systems whose whole state
/// is one array of reals (ODE systems, flows) return from `System::snapshot`.
pub fn snapshot_flat(y: &[Real]) -> Result<Snapshot> {
    let n = y.len();
    let need = crate::alloc::Need::new(
        "step",
        crate::alloc::Need::bytes_of::<Real>(n),
        format!("a copy of {} values", crate::alloc::count(n as u128)),
    );
    Ok(Box::new(need.copy(y)?))
}

/// Loads the array "y" of `arrays` into `y` (same length, every value finite; nothing changes
/// on error): `System::load` of a system whose state is one flat array.
pub fn load_flat(y: &mut [Real], arrays: &Arrays) -> Result<()> {
    let a = array(arrays, "y", Some(y.len()))?;
    if let Some(i) = a.iter().position(|v| !v.is_finite()) {
        return Err(crate::error::invalid("y", format!("entry {i} is not finite: {}", a[i])));
    }
    y.copy_from_slice(a);
    Ok(())
}

/// The array `name` of `arrays`, which must hold `len` values (`None`: any length); an
/// `InvalidInput` naming it otherwise.
pub fn array<'a>(arrays: &'a Arrays, name: &str, len: Option<usize>) -> Result<&'a [Real]> {
    let Some((_, a)) = arrays.iter().find(|(n, _)| n == name) else {
        return Err(crate::error::invalid(name, "is missing"));
    };
    if let Some(len) = len.filter(|&l| l != a.len()) {
        return Err(crate::error::invalid(name, format!("has {} values, expected {len}", a.len())));
    }
    Ok(a)
}

/// Why a system's step did not stand.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Halt {
    /// The stop flag was seen set (the step may be partial).
    Stopped,
    /// A value became non-finite (or an adaptive step could not be controlled): the element
    /// (particle, grid cell, ODE component) and what went wrong.
    Diverged { index: usize, quantity: Failure },
}

/// What the world tells its systems at the start of a call (`System::set`), as a term is told
/// its settings (`terms::Setting`).
#[derive(Clone, Debug)]
pub enum WorldSetting {
    /// The world's gravity (m/s²; the particles' uniform fields, their `Gravity` terms,
    /// summed), given at the start of every call of steps and before the books are read:
    /// systems with mass under gravity (rigid bodies) fall under it and book its potential.
    Gravity([Real; 3]),
    /// The stop flag of the call in progress (`Stop::default()` after it), for evaluations long
    /// enough to poll it (see `crate::stop`).
    Stop(Stop),
}

/// Rigid bodies (`bodies::Bodies2`, `bodies::Bodies3`): the role through which the bindings
/// add bodies, joints and pins and read a body's mesh, the same calls in 2D and 3D.
pub trait RigidBodies {
    /// Adds a group of bodies of one shape (`Params` as the Python `Bodies` part gives them);
    /// returns the number of its first body.
    fn add_group(&mut self, p: crate::terms::registry::Params) -> Result<usize>;
    /// Adds joints between bodies (or a body and a fixed point).
    fn add_joints(&mut self, p: crate::terms::registry::Params) -> Result<()>;
    /// Pins particles to bodies.
    fn add_pins(&mut self, p: crate::terms::registry::Params) -> Result<()>;
    /// Body `i`'s shape as triangles in its own frame (m): vertices (V·3) and corner indices
    /// (T·3). 3D only: 2D bodies refuse naming `dim` (they have outlines).
    fn body_mesh(&self, i: usize) -> Result<(Vec<Real>, Vec<u32>)>;
    /// The scene's step (s), before any step is taken: what a loaded state's trial steps at
    /// (`systems::bodies`); each step then sets its own.
    fn hint_dt(&mut self, dt: crate::vector::Real);
    /// The bodies themselves, of their dimension: what the particles⇄bodies coupling written
    /// beside them (`BodyContacts`) steps with. A role, not a downcast: no system is `Any`.
    fn bodies(&mut self) -> BodiesOf<'_>;
}

/// A rigid-body system as the particles⇄bodies coupling of its dimension sees it.
pub enum BodiesOf<'a> {
    Two(&'a mut bodies::Bodies2),
    Three(&'a mut bodies::Bodies3),
}

/// The role of a system that stands in for terms of the scene (a device system that took a
/// DFSPH fluid or grains' contacts): their own state, statistics and counters, in the CPU
/// terms' layouts, so that a scene file and `state()` continue on either path.
pub trait HeldTerms {
    /// The own state of the term named `name`, in the CPU term's `OwnState::history` layout (a
    /// DFSPH fluid's warm starts, contacts' spins and springs); `None` where it holds no such
    /// term or the term keeps none.
    fn term_history(&self, name: &str) -> Result<Option<Vec<Real>>>;
    /// Loads what `term_history` gave (the CPU term's layout; checked, nothing changes on
    /// error); refuses, naming it, a term it does not hold.
    fn set_term_history(&mut self, name: &str, history: &[Real]) -> Result<()>;
    /// The statistics of the terms it holds, as `Term::stats` gives them on the CPU: (term
    /// name, statistic, value). Empty by default.
    fn term_stats(&self) -> Vec<(String, &'static str, Real)> {
        Vec::new()
    }
    /// The counters of the terms it holds, as `Term::counts` gives them on the CPU. Empty by
    /// default.
    fn term_counts(&self) -> Vec<(String, &'static str, u64)> {
        Vec::new()
    }
}

/// One system of a world. Methods that run kernels are called on the world's thread pool.
///
/// Nothing looks inside a system: the bindings, the world and the couplings go through this
/// trait and its roles (`as_rigid_bodies`; the bodies' `BodyContacts` finds its bodies by
/// `RigidBodies::bodies`).
pub trait System: Send + Sync {
    /// Short name, e.g. "particles" (the books of several systems are told apart by it).
    fn name(&self) -> &str;
    /// Whether there is nothing to step (the world then only advances time).
    fn is_empty(&self) -> bool;
    /// Elements stepped (particles, grid cells): how long a step takes, roughly. Default 0.
    fn size(&self) -> usize {
        0
    }
    /// Reserves, fallibly, what stepping will need (`Error::OutOfMemory` and no change if it
    /// cannot), so that a step allocates nothing that could abort the process.
    fn prepare(&mut self) -> Result<()> {
        Ok(())
    }
    /// The system as rigid bodies (`RigidBodies`), for the bindings (`None`: not bodies).
    fn as_rigid_bodies(&mut self) -> Option<&mut dyn RigidBodies> {
        None
    }
    /// The system as one that stands in for terms of the scene (`HeldTerms`: a device system
    /// holding a DFSPH fluid or grains' contacts), for the bindings (`None`: it holds none).
    fn as_held_terms(&self) -> Option<&dyn HeldTerms> {
        None
    }
    /// `as_held_terms`, to load a term's history.
    fn as_held_terms_mut(&mut self) -> Option<&mut dyn HeldTerms> {
        None
    }
    /// Tells the system a property of the world for the call in progress (`WorldSetting`: the
    /// world's gravity, the stop flag). Default: ignored.
    fn set(&mut self, _setting: &WorldSetting) {}
    /// Advances by `dt` seconds. On `Err` the world rolls every system back.
    fn step(&mut self, dt: Real, stop: &AtomicBool) -> std::result::Result<(), Halt>;
    /// `n` steps of `dt`, when this is the world's only system with anything to step and no
    /// coupling runs between steps (a system may then fuse steps). On a halt, the steps taken
    /// before it: the world's clock counts those, plus the halted one if it diverged. Reads
    /// `stop` before every step, as the world does.
    fn steps(&mut self, n: u64, dt: Real, stop: &AtomicBool) -> std::result::Result<(), (u64, Halt)> {
        for i in 0..n {
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Err((i, Halt::Stopped));
            }
            self.step(dt, stop).map_err(|h| (i, h))?;
        }
        Ok(())
    }
    /// Completes what the last steps deferred (see `Term::settle`): the world calls it when a
    /// call of steps ends and before couplings run, so that nothing outside a step sees a
    /// state half-committed. Default: nothing deferred.
    fn settle(&mut self) {}
    /// After `settle`: the first non-finite value the steps could not see (what a commit that
    /// `settle` completed produced: a term's own state, the energy books), as a divergence.
    fn settled_fault(&self) -> Option<(usize, Failure)> {
        None
    }
    /// Told that the world's dt changed between calls: drop anything predicted with the old one.
    fn dt_changed(&mut self) {}
    /// Whether the system picks its own internal steps (an adaptive integrator): with no stable
    /// dt anywhere, `World::advance` then takes the whole duration as one step.
    fn adaptive(&self) -> bool {
        false
    }
    /// Whether `auto_dt` follows the flow so closely (a DFSPH fluid's CFL limit, with no speed
    /// of sound under it) that `World::advance` must take it again before every substep.
    fn limit_follows_flow(&self) -> bool {
        false
    }
    /// The largest step (s) `World::advance` should take now, `None` if the system sets none.
    fn auto_dt(&self) -> Option<Real>;
    /// A step (s) safely inside the stability region, to suggest after a divergence; `None` if
    /// the system has no time scale.
    fn suggest_dt(&self) -> Option<Real>;
    /// The energy books now.
    fn energy(&self) -> EnergyReport;
    /// Sets the named state field `name` (one value per element; checked, nothing changes on
    /// error). Systems without settable fields refuse every name.
    fn set_field(&mut self, name: &str, _values: &[Real]) -> Result<()> {
        Err(crate::error::invalid("field", format!("{name:?} cannot be set on system {:?}", self.name())))
    }
    /// Further books that are not energies, by name (a reaction–diffusion system's amounts of
    /// each species and what its reactions made of them); empty by default.
    fn books(&self) -> Vec<(String, Real)> {
        Vec::new()
    }
    /// The named output fields `names`, one value per element (0 where a field is not defined;
    /// all zeros if the system has no field of that name), allocated fallibly: a field read
    /// of a large grid must not abort the process (see `crate::alloc`).
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>>;
    /// A copy of everything `step` changes, allocated fallibly.
    fn snapshot(&self) -> Result<Snapshot>;
    /// Everything a restart needs (state, books, caches), as named arrays; `Error::OutOfMemory`
    /// where a system counts its arrays first (the rigid bodies' solver state).
    fn save(&self) -> Result<Arrays>;
    /// Loads what `save` wrote for a system built the same way; every array is checked (names,
    /// lengths, finite values) before anything changes.
    fn load(&mut self, arrays: &Arrays) -> Result<()>;
    /// Returns to `snapshot`, which this system made.
    fn restore(&mut self, snapshot: Snapshot);
    /// Takes back a snapshot this system made that was not needed (the call succeeded), so its
    /// buffers can serve the next `snapshot`. Default: dropped.
    fn recycle(&mut self, _snapshot: Snapshot) {}
}

/// An exchange between systems (tracers carried by a grid's velocity, a fluid pushing a body),
/// run by the world after every system has stepped, in the order the couplings were added. It
/// keeps no state of its own (rollback restores the systems only); it reads other systems
/// through their named fields.
pub trait Coupling<V: Vector>: Send + Sync {
    fn name(&self) -> &str;
    /// Applies the exchange over a step of `dt` seconds.
    fn apply(&mut self, particles: &mut particles::ParticleSystem<V>, others: &mut [Box<dyn System>], dt: Real);
    /// Before every step, from the state alone (so that a restart or a rollback steps the same):
    /// what the systems' steps read of each other (the bodies' boundary particles a fluid counts).
    /// Refuses (`Error::OutOfMemory`) what it cannot hold and sees Ctrl-C (`stop`,
    /// `Error::Interrupted`); the call is then rolled back.
    fn prepare(
        &mut self,
        _particles: &mut particles::ParticleSystem<V>,
        _others: &mut [Box<dyn System>],
        _stop: &AtomicBool,
    ) -> Result<()> {
        Ok(())
    }
    /// After the particles' step and before the other systems' (what the particles' step gave
    /// them: the impulse a fluid's pressure solve gave the bodies, before they step with it).
    fn between(&mut self, _particles: &mut particles::ParticleSystem<V>, _others: &mut [Box<dyn System>], _dt: Real) {}
}
