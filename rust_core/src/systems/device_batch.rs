//! A batch of small particle worlds on one device (`Batch(..., device="gpu")` in the facade):
//! every member's particles in one `physcore_gpu::particles::Particles`, the pairwise sums kept
//! inside each member (`Particles::set_worlds`), so each stage of a step is one dispatch for the
//! whole batch (MuJoCo Warp's worlds per launch are the model). The members stay the CPU worlds
//! they are: a call uploads their states, steps all of them on the device, reads the positions,
//! velocities and books back once, and writes each member's state, clock and books into its
//! world, as if it had stepped alone (in the device's precision).
//!
//! What a device batch holds: members of one dimension and particle count, with the terms of
//! the device's particles (uniform gravity, drag, one pairwise gravity, one Coulomb, one springs
//! term) and its colliders, the same integrator and the same dt; the fields' parameters (g,
//! drag, G, k, softening) and the colliders the same in every member, as one dispatch runs them
//! (masses, charges, springs and states may differ). Anything else is refused by name.
//!
//! A member that diverges is retired (the call's error for it; nothing written to it) and the
//! call runs again from its start for the others, with the retired member's particles held still
//! (pinned) on the device: the others' results do not depend on it, as each world pulls only on
//! its own particles. A stop (Ctrl-C) or a device failure writes nothing to any member.
use super::device::{colliders_of, forces_of, precision_of, scheme_of};
use crate::alloc::{count, Need};
use crate::error::{invalid, Error, Failure, Result};
use crate::terms::registry::Params;
use crate::vector::{Real, Vector};
use crate::world::{World, MAX_STEPS};
use physcore_gpu::particles::{self as dp, Particles, Springs};
use physcore_gpu::{Gpu, Precision};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// A member's term records (kind, name, parameters) and collider records (kind, parameters), as
/// the facade added them (`Simulation.move_to_device` builds from the same).
pub type Records = (Vec<(String, String, Params)>, Vec<(String, Params)>);

/// Every member of a batch on one device.
pub struct DeviceBatch {
    dim: usize,
    /// Particles per member, and members.
    n: usize,
    m: usize,
    integrator: String,
    /// Each member's records at the build: a later call checks its members against them.
    records: Vec<Records>,
    /// Each drag term's index among the terms and its coefficient (b > 0): the device sums the
    /// drags into one b, and its dissipation is shared out in proportion.
    drag: Vec<(usize, Real)>,
    /// The springs term's index, if it has dashpots (the CPU books their dissipation then).
    dashpots: Option<usize>,
    p: Particles,
}

/// The first member whose `what` differs from member 0's, as an error naming `key`.
fn differs(key: &str, k: usize, what: &str) -> Error {
    invalid(
        key,
        format!(
            "member {k}'s {what} differs from member 0's: a GPU batch steps its members in one dispatch, \
             so they share it (run the batch with device=\"cpu\" to vary it)"
        ),
    )
}

impl DeviceBatch {
    /// The members `worlds` (their `records`) on the device `gpu` at `precision` ("f32",
    /// "f64"). Errors: `InvalidInput` naming what a device batch cannot hold (see the module
    /// docs) or a value past f32's range; `OutOfMemory` for the host copies or device buffers.
    pub fn new<V: Vector>(gpu: Arc<Gpu>, precision: &str, worlds: &[&World<V>], records: Vec<Records>) -> Result<Self> {
        let (m, dim) = (worlds.len(), V::DIM);
        if m == 0 || records.len() != m {
            return Err(invalid("sims", "a batch needs at least one member, each with its records"));
        }
        let precision = precision_of(precision)?;
        let w0 = worlds[0];
        let n = w0.n_particles();
        let integrator = w0.particles().integrator_info().name.to_string();
        let scheme = scheme_of(&integrator)?;
        let total = n
            .checked_mul(m)
            .filter(|t| *t < u32::MAX as usize)
            .ok_or_else(|| invalid("sims", format!("{m} members of {n} particles are more than the device indexes")))?;
        // The host copies (state, masses, the springs gathered) and as much again for staging.
        let springs: usize =
            records.iter().flat_map(|r| &r.0).filter(|t| t.0 == "springs").map(|t| t.2.len_of("i")).sum();
        let bytes = 2 * (total as u128 * (2 * dim as u128 + 3) * 8) + springs as u128 * 256;
        Need::new("step", bytes, format!("{} particles' copies for the device", count(total as u128))).room(bytes)?;
        let (forces, _, _) = forces_of(dim, n, &records[0].0)?;
        let colliders = colliders_of(dim, &records[0].1)?;
        let (mut x, mut v, mut mass, mut im) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut charge: Option<Vec<Real>> = None;
        let mut all = Springs::default();
        for (k, (w, (terms, cols))) in worlds.iter().zip(&records).enumerate() {
            Self::check_member(w, k, n, &integrator, terms, cols, w0.dt())?;
            let (f, springs, _) = forces_of(dim, n, terms)?;
            if f != forces {
                return Err(differs("terms", k, "field parameters (g, drag, G, k, softening)"));
            }
            if cols != &records[0].1 {
                return Err(differs("colliders", k, "colliders"));
            }
            let p = w.particles();
            x.extend(V::flat(&p.state().x));
            v.extend(V::flat(&p.state().v));
            mass.extend_from_slice(&p.model().mass);
            im.extend_from_slice(&p.model().inv_mass);
            match (p.model().attribute("charge"), &mut charge) {
                (Some(q), Some(c)) => c.extend_from_slice(q),
                (Some(q), None) if k == 0 => charge = Some(q.to_vec()),
                (None, None) => {}
                _ => return Err(differs("charge", k, "charges (some members have none)")),
            }
            if let Some(s) = springs {
                let o = (k * n) as u32;
                all.i.extend(s.i.iter().map(|i| i + o));
                all.j.extend(s.j.iter().map(|j| j + o));
                all.k.extend(s.k);
                all.c.extend(s.c);
                all.rest.extend(s.rest);
            }
        }
        if precision == Precision::F32 {
            let over = |a: &[Real]| a.iter().position(|c| c.abs() > f32::MAX as Real);
            for (key, a) in
                [("positions", &x), ("velocities", &v), ("masses", &mass), ("charge", charge.as_ref().unwrap_or(&x))]
            {
                if let Some(i) = over(a) {
                    return Err(invalid(key, format!("value {i} of the batch ({:e}) is past f32's range (precision=\"f32\" on the device; use \"f64\")", a[i])));
                }
            }
        }
        let drag = records[0]
            .0
            .iter()
            .enumerate()
            .filter(|(_, t)| t.0 == "drag")
            .map(|(i, t)| Ok((i, t.2.number("coefficient")?)))
            .filter(|r: &Result<(usize, Real)>| r.as_ref().map_or(true, |(_, b)| *b > 0.0))
            .collect::<Result<Vec<_>>>()?;
        let dashpots = records[0].0.iter().position(|t| t.0 == "springs").filter(|_| all.c.iter().any(|&c| c > 0.0));
        let springs = (!all.i.is_empty()).then_some(&all);
        let mut p = Particles::new(gpu, precision, dim, scheme, forces, &x, &v, &mass, &im, springs)?;
        p.set_colliders(&colliders)?;
        if let Some(q) = &charge {
            p.set_charges(q)?;
        }
        p.set_worlds(n)?;
        Ok(Self { dim, n, m, integrator, records, drag, dashpots, p })
    }

    /// Refuses (naming it) what member `k` has that a device batch cannot hold.
    fn check_member<V: Vector>(
        w: &World<V>,
        k: usize,
        n: usize,
        integrator: &str,
        terms: &[(String, String, Params)],
        cols: &[(String, Params)],
        dt: Real,
    ) -> Result<()> {
        let p = w.particles();
        if let Some(s) = w.other_names().first() {
            return Err(invalid(
                "sims",
                format!("member {k} has the system {s:?} besides its particles: a GPU batch holds particles only"),
            ));
        }
        if p.n_particles() != n {
            return Err(differs("sims", k, "particle count"));
        }
        if p.integrator_info().name != integrator {
            return Err(differs("integrator", k, "integrator"));
        }
        if w.dt().to_bits() != dt.to_bits() {
            return Err(differs("dt", k, "dt"));
        }
        if let Some(a) = p.model().attributes.keys().find(|a| **a != "charge") {
            return Err(invalid("sims", format!("member {k}: the GPU path has no per-particle {a:?} yet")));
        }
        if p.n_constraints() != cols.len() {
            return Err(invalid("sims", format!("member {k}: the GPU path has no constraints but its colliders yet")));
        }
        if terms.len() != p.dissipated_by_term().len() {
            return Err(invalid("sims", format!("member {k}: its term records do not match its terms")));
        }
        Ok(())
    }

    /// The adapter it runs on and its precision, e.g. "NVIDIA H100 (vulkan, f32)".
    pub fn describe(&self) -> String {
        let a = self.p.gpu().adapter();
        format!("{} ({}, {})", a.name, a.backend, self.p.precision().name())
    }

    /// Steps every member of `worlds` (those it was built from, in order) `n` steps of their dt
    /// on the device, writing nothing to them yet: `Ran::keep` does. `Error::Interrupted` if
    /// `stop` was set, a device error if the device failed. `InvalidInput` before anything runs
    /// for a member no longer of this batch's shape (its count, integrator, dt) or `n` past the
    /// step limit.
    pub fn run<V: Vector>(&mut self, worlds: &[&mut World<V>], n: u64, stop: &AtomicBool) -> Result<Ran> {
        if worlds.len() != self.m || V::DIM != self.dim {
            return Err(invalid(
                "sims",
                format!("the batch on the device holds {} members of dimension {}", self.m, self.dim),
            ));
        }
        let dt = worlds[0].dt();
        for (k, w) in worlds.iter().enumerate() {
            let (terms, cols) = &self.records[k];
            Self::check_member(w, k, self.n, &self.integrator, terms, cols, dt)?;
            if n > MAX_STEPS - w.steps() {
                return Err(invalid("n", format!("{n} more steps would take a member's step count past 2**63 - 1")));
            }
            if !(w.time() + n as Real * dt).is_finite() {
                return Err(invalid("n", format!("{n} steps of {dt:e} s take the time past the largest float")));
            }
        }
        let mut ran = Ran { n, dt, x: Vec::new(), v: Vec::new(), books: Vec::new(), failed: Vec::new() };
        if n == 0 {
            return Ok(ran);
        }
        let d = self.dim;
        let (mut x, mut v, mut mass, mut im) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for w in worlds.iter() {
            let p = w.particles();
            x.extend(V::flat(&p.state().x));
            v.extend(V::flat(&p.state().v));
            mass.extend_from_slice(&p.model().mass);
            im.extend_from_slice(&p.model().inv_mass);
        }
        loop {
            self.p.set_state(&x, &v, &mass, &im)?;
            match self.p.step(n, dt, stop) {
                Ok(_) => break,
                Err((_, dp::Halt::Stopped)) => return Err(Error::Interrupted { rolled_back_to: 0 }),
                Err((_, dp::Halt::Failed(e))) => return Err(e.into()),
                Err((done, dp::Halt::Diverged { particle })) => {
                    let k = particle / self.n;
                    if ran.failed.iter().any(|f| f.0 == k) {
                        // A member held still cannot move: the device itself misbehaves.
                        return Err(Error::Device { msg: format!("member {k} diverged again while held still") });
                    }
                    let w = &worlds[k];
                    ran.failed.push((
                        k,
                        Error::Diverged {
                            step: w.steps() + done + 1,
                            t: w.time() + (done + 1) as Real * dt,
                            particle: particle % self.n,
                            quantity: Failure::Position,
                            rolled_back_to: w.steps(),
                            dt,
                            suggested_dt: w.suggest_dt().min(0.5 * dt),
                            explicit_euler: false,
                            remedies: w.particles().remedies(),
                        },
                    ));
                    // Held still from its start for the run again.
                    let r = k * self.n..(k + 1) * self.n;
                    v[r.start * d..r.end * d].iter_mut().for_each(|c| *c = 0.0);
                    im[r].iter_mut().for_each(|c| *c = 0.0);
                }
            }
        }
        (ran.x, ran.v) = self.p.read()?;
        // Kinetic and potential energy follow from the state; the device's books are read only
        // for what it accumulates (drag, dashpots, colliders).
        if !self.drag.is_empty() || self.dashpots.is_some() || !self.records[0].1.is_empty() {
            ran.books = self.p.books_of_worlds()?;
        }
        Ok(ran)
    }

    /// Writes what `run` computed into the members (state, clock, books), the failed ones left
    /// as they were; returns `(member, error)` for each of those.
    pub fn keep<V: Vector>(&self, worlds: &mut [&mut World<V>], ran: Ran) -> Result<Vec<(usize, Error)>> {
        let Ran { n, dt, x, v, books, failed } = ran;
        if n == 0 {
            return Ok(failed);
        }
        let d = self.dim;
        let btot: Real = self.drag.iter().map(|d| d.1).sum();
        // The clock as a world's own steps count it (t += dt a step), once per start time.
        let mut clocks: HashMap<u64, Real> = HashMap::new();
        for w in worlds.iter() {
            let t0 = w.time();
            clocks.entry(t0.to_bits()).or_insert_with(|| (0..n).fold(t0, |t, _| t + dt));
        }
        // Each member written on its own (they share nothing), in parallel, into the arrays it has.
        let none = dp::Books::default();
        let written: Vec<Result<()>> = worlds
            .par_iter_mut()
            .enumerate()
            .map(|(k, w)| {
                if failed.iter().any(|f| f.0 == k) {
                    return Ok(());
                }
                let t = clocks[&w.time().to_bits()];
                let r = k * self.n * d..(k + 1) * self.n * d;
                let b = books.get(k).unwrap_or(&none);
                let mut dis = w.particles().dissipated_by_term().to_vec();
                for &(i, coef) in &self.drag {
                    dis[i] += b.dissipated * (coef / btot);
                }
                if let Some(i) = self.dashpots {
                    dis[i] += b.dashpots;
                }
                let collisions = w.particles().constraints_dissipated() + b.collisions;
                let steps = w.steps() + n;
                w.particles_mut().set_state_from(V::rows(&x[r.clone()]), V::rows(&v[r]))?;
                w.restore(t, steps, &dis, collisions, None)
            })
            .collect();
        written.into_iter().collect::<Result<()>>()?;
        Ok(failed)
    }
}

/// What `DeviceBatch::run` computed, not yet written to the members.
pub struct Ran {
    n: u64,
    dt: Real,
    x: Vec<Real>,
    v: Vec<Real>,
    books: Vec<dp::Books>,
    failed: Vec<(usize, Error)>,
}
