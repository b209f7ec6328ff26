//! A batch of small particle worlds on one device (`Batch(..., device="gpu")` in the facade):
//! every member's particles in one `physcore_gpu::particles::Particles`, the pairwise sums kept
//! inside each member (`Particles::set_worlds`), so each stage of a step is one dispatch for the
//! whole batch (MuJoCo Warp's worlds per launch are the model).
//!
//! The members stay on the device between calls. A call reads the positions and velocities
//! back once into the batch's mirror on the host (with each member's clock and books), and
//! writes nothing into the members' worlds: a member is written from the mirror (`settle`)
//! only when it is read or changed, as if it had stepped alone (in the device's precision).
//! A member settled since the last call is "touched": the next call compares its world with
//! the mirror and, if it was changed, gathers it and writes its rows alone to the device
//! (`Particles::set_rows`, no other member's bits moved); the others cost a call nothing on
//! the host. Writing every member back each call cost about 1.8 µs a member (16,384 members: 30
//! ms a call of one step on a 2-core EPYC, where the target is a call of 1,000 steps in 10
//! ms; docs/guide/gpu.md).
//!
//! What a device batch holds: members of one dimension and particle count, with the terms of
//! the device's particles (uniform gravity, drag, one pairwise gravity, one Coulomb, one springs
//! term) and its colliders, the same integrator and the same dt; the fields' parameters (g,
//! drag, G, k, softening) and the colliders the same in every member, as one dispatch runs them
//! (masses, charges, springs and states may differ). Anything else is refused by name.
//!
//! A member that diverges is retired (the mirror keeps it where the call started) and the call
//! runs again from its start for the others, with the retired member's particles held still
//! (pinned) on the device, as they stay: the others' results do not depend on it, bit for bit,
//! as each world pulls only on its own particles (where the forces depend on the velocities,
//! the run again starts from a copy of the call's start on the device, which keeps the
//! accelerations velocity Verlet carried into it). A stop (Ctrl-C) or a device failure commits nothing: the
//! mirror stays where the call started, and the next call writes the device from it.
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
    /// The members' time step (they share it).
    dt: Real,
    p: Particles,
    mirror: Mirror,
    /// Whether the device holds the mirror's state (false after a call stopped or failed part
    /// way, or diverged: the next call writes the whole mirror).
    current: bool,
    /// The members that diverged, held still on the device and not stepped again, with the
    /// steps their call had completed and the particle that failed.
    retired: Vec<bool>,
    diverged: HashMap<usize, (u64, usize)>,
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
        // The mirror kept on the host (state, masses, each member's clock and books), as much
        // again for staging, and the springs gathered.
        let springs: usize =
            records.iter().flat_map(|r| &r.0).filter(|t| t.0 == "springs").map(|t| t.2.len_of("i")).sum();
        let bytes = 2 * (total as u128 * (2 * dim as u128 + 3) * 8) + springs as u128 * 256 + m as u128 * 256;
        Need::new("step", bytes, format!("{} particles' copies for the device", count(total as u128))).room(bytes)?;
        let (forces, _, _) = forces_of(dim, n, &records[0].0)?;
        let colliders = colliders_of(dim, &records[0].1)?;
        let (mut x, mut v, mut mass, mut im) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let (mut t, mut steps, mut dis, mut collisions) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
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
            t.push(w.time());
            steps.push(w.steps());
            dis.push(p.dissipated_by_term().to_vec());
            collisions.push(p.constraints_dissipated());
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
        let (dis_at_upload, collisions_at_upload) = (dis.clone(), collisions.clone());
        let mirror = Mirror { x, v, mass, im, t, steps, dis, collisions, dis_at_upload, collisions_at_upload };
        Ok(Self {
            dim,
            n,
            m,
            integrator,
            records,
            drag,
            dashpots,
            dt: w0.dt(),
            p,
            mirror,
            current: true,
            retired: vec![false; m],
            diverged: HashMap::new(),
        })
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

    /// The members' dimension.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The adapter it runs on and its precision, e.g. "NVIDIA H100 (vulkan, f32)".
    pub fn describe(&self) -> String {
        let a = self.p.gpu().adapter();
        format!("{} ({}, {})", a.name, a.backend, self.p.precision().name())
    }

    /// Steps every member not retired `n` steps of the batch's dt on the device, writing
    /// nothing yet: `commit` takes the results into the mirror. The members stay on the device
    /// between calls: only the `touched` ones (index, world), whose worlds may differ from the
    /// mirror (settled, then read or changed, since), are checked and gathered again, and the
    /// device is written only if one was (or the last call did not commit). No world is
    /// written: `settle` does that, when a member is read. `Error::Interrupted` if `stop` was
    /// set, a device error if the device failed (the mirror is then where the call started).
    /// `InvalidInput`, before anything changes, for a touched member no longer of this batch's
    /// shape (count, integrator, dt, colliders) or `n` past a member's step limit.
    pub fn run<V: Vector>(&mut self, touched: &[(usize, &World<V>)], n: u64, stop: &AtomicBool) -> Result<Ran> {
        if V::DIM != self.dim {
            return Err(invalid("sims", format!("the batch on the device holds members of dimension {}", self.dim)));
        }
        let dt = self.dt;
        let mut now: Vec<Option<(Real, u64)>> = vec![None; self.m];
        for &(k, w) in touched {
            if k >= self.m || self.retired[k] {
                return Err(invalid("sims", format!("member {k} is not one the device steps")));
            }
            let (terms, cols) = &self.records[k];
            Self::check_member(w, k, self.n, &self.integrator, terms, cols, dt)?;
            now[k] = Some((w.time(), w.steps()));
        }
        // Every member's limits, from its touched world or the mirror (the others' truth).
        for k in (0..self.m).filter(|&k| !self.retired[k]) {
            let (t, steps) = now[k].unwrap_or((self.mirror.t[k], self.mirror.steps[k]));
            if n > MAX_STEPS - steps {
                return Err(invalid("n", format!("{n} more steps would take a member's step count past 2**63 - 1")));
            }
            if !(t + n as Real * dt).is_finite() {
                return Err(invalid("n", format!("{n} steps of {dt:e} s take the time past the largest float")));
            }
        }
        // A member only read since it was written back is as the mirror has it: nothing to do
        // (reading a member changes nothing, not even its carried accelerations).
        let mut changed = Vec::new();
        for &(k, w) in touched {
            if !self.holds(k, w) {
                self.gather(k, w);
                changed.push(k);
            }
        }
        let mut ran = Ran { n, x: Vec::new(), v: Vec::new(), books: Vec::new(), failed: Vec::new() };
        if n == 0 {
            return Ok(ran);
        }
        let books = !self.drag.is_empty() || self.dashpots.is_some() || !self.records[0].1.is_empty();
        let mut still: Vec<usize> = Vec::new();
        // Where the accelerations a step carries are not what a fresh evaluation gives (forces
        // of the velocities), a divergence's run again starts from a copy of the call's start
        // on the device, not from the mirror: the others then go on bit for bit as without it.
        let mut snapped = false;
        loop {
            // Until the results are committed, the device is apart from the mirror (also if a
            // write fails part way).
            let whole = !std::mem::replace(&mut self.current, false);
            if whole {
                self.upload(&still)?;
            } else if !changed.is_empty() {
                self.write_rows(&changed)?;
            }
            changed.clear();
            if !snapped && !whole && self.p.carries_velocity_forces() {
                self.p.snapshot()?;
                snapped = true;
            }
            match self.p.step(n, dt, stop) {
                Ok(_) => break,
                Err((_, dp::Halt::Stopped)) => return Err(Error::Interrupted { rolled_back_to: 0 }),
                Err((_, dp::Halt::Failed(e))) => return Err(e.into()),
                Err((done, dp::Halt::Diverged { particle })) => {
                    let k = particle / self.n;
                    if still.contains(&k) || self.retired[k] {
                        // A member held still cannot move: the device itself misbehaves.
                        return Err(Error::Device { msg: format!("member {k} diverged again while held still") });
                    }
                    // Held still from the call's start for the run again.
                    still.push(k);
                    ran.failed.push((k, done, particle % self.n));
                    if snapped {
                        self.p.restore()?;
                        self.hold_still(k)?;
                        self.current = true; // the call's start, `k` held still: no upload
                    }
                }
            }
        }
        (ran.x, ran.v) = self.p.read()?;
        // Kinetic and potential energy follow from the state; the device's books are read only
        // for what it accumulates (drag, dashpots, colliders).
        if books {
            ran.books = self.p.books_of_worlds()?;
        }
        Ok(ran)
    }

    /// Takes what `run` computed into the mirror (the live members' rows, books and clocks)
    /// and retires the members that diverged in it, held still on the device from now on: the
    /// mirror keeps them where the call started (`settle` writes that back, `diverged` gives
    /// their errors). Returns those members.
    pub fn commit(&mut self, ran: Ran) -> Vec<usize> {
        let Ran { n, x, v, books, failed } = ran;
        if n == 0 {
            return Vec::new();
        }
        let dt = self.dt;
        for &(k, done, particle) in &failed {
            self.retired[k] = true;
            self.diverged.insert(k, (done, particle));
        }
        let rows = self.n * self.dim;
        if self.retired.iter().any(|&r| r) {
            for k in (0..self.m).filter(|&k| !self.retired[k]) {
                let r = k * rows..(k + 1) * rows;
                self.mirror.x[r.clone()].copy_from_slice(&x[r.clone()]);
                self.mirror.v[r.clone()].copy_from_slice(&v[r]);
            }
        } else {
            (self.mirror.x, self.mirror.v) = (x, v);
        }
        if !books.is_empty() {
            // The device's books hold the losses since the last upload (they go on adding up
            // from call to call, as within one): added to the books at that upload.
            let btot: Real = self.drag.iter().map(|d| d.1).sum();
            let m = &mut self.mirror;
            for k in (0..self.m).filter(|&k| !self.retired[k]) {
                for &(i, coef) in &self.drag {
                    m.dis[k][i] = m.dis_at_upload[k][i] + books[k].dissipated * (coef / btot);
                }
                if let Some(i) = self.dashpots {
                    m.dis[k][i] = m.dis_at_upload[k][i] + books[k].dashpots;
                }
                m.collisions[k] = m.collisions_at_upload[k] + books[k].collisions;
            }
        }
        // The clock as a world's own steps count it (t += dt a step), once per start time.
        let mut last: Option<(u64, Real)> = None;
        for k in (0..self.m).filter(|&k| !self.retired[k]) {
            let t0 = self.mirror.t[k];
            let t = match last {
                Some((bits, t)) if bits == t0.to_bits() => t,
                _ => (0..n).fold(t0, |t, _| t + dt),
            };
            last = Some((t0.to_bits(), t));
            self.mirror.t[k] = t;
            self.mirror.steps[k] += n;
        }
        // The device holds the mirror now: the retired members' rows are held still there, as
        // an upload holds them.
        self.current = true;
        failed.into_iter().map(|f| f.0).collect()
    }

    /// Whether member `k`'s world is, bit for bit, what the mirror holds of it (state, masses,
    /// clock, books): written back and not changed since.
    fn holds<V: Vector>(&self, k: usize, w: &World<V>) -> bool {
        let same =
            |a: &[Real], b: &[Real]| a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        let (p, m) = (w.particles(), &self.mirror);
        let (rows, n) = (k * self.n * self.dim..(k + 1) * self.n * self.dim, k * self.n..(k + 1) * self.n);
        same(V::flat(&p.state().x), &m.x[rows.clone()])
            && same(V::flat(&p.state().v), &m.v[rows])
            && same(&p.model().mass, &m.mass[n.clone()])
            && same(&p.model().inv_mass, &m.im[n])
            && w.time().to_bits() == m.t[k].to_bits()
            && w.steps() == m.steps[k]
            && same(p.dissipated_by_term(), &m.dis[k])
            && p.constraints_dissipated().to_bits() == m.collisions[k].to_bits()
    }

    /// The rows of the members `changed` (gathered into the mirror) onto the device, a run of
    /// consecutive members in one write: their books start from zero there and their
    /// accelerations are evaluated anew, the other members' left as they are
    /// (`Particles::set_rows`).
    fn write_rows(&mut self, changed: &[usize]) -> Result<()> {
        let mut ks = changed.to_vec();
        ks.sort_unstable();
        let (n, d, m) = (self.n, self.dim, &mut self.mirror);
        let mut i = 0;
        while i < ks.len() {
            let mut j = i + 1;
            while j < ks.len() && ks[j] == ks[j - 1] + 1 {
                j += 1;
            }
            let (a, b) = (ks[i], ks[j - 1] + 1);
            self.p.set_rows(
                a * n,
                &m.x[a * n * d..b * n * d],
                &m.v[a * n * d..b * n * d],
                &m.mass[a * n..b * n],
                &m.im[a * n..b * n],
            )?;
            i = j;
        }
        for &k in &ks {
            m.dis_at_upload[k].clone_from(&m.dis[k]);
            m.collisions_at_upload[k] = m.collisions[k];
        }
        Ok(())
    }

    /// Member `k`'s particles held still on the device, where the mirror has them (no
    /// velocity, no inverse mass).
    fn hold_still(&mut self, k: usize) -> Result<()> {
        let (n, d, m) = (self.n, self.dim, &self.mirror);
        let zero = vec![0.0; n * d];
        self.p
            .set_rows(k * n, &m.x[k * n * d..(k + 1) * n * d], &zero, &m.mass[k * n..(k + 1) * n], &zero[..n])
            .map_err(Into::into)
    }

    /// Member `k`'s world into the mirror (state, masses, clock, books).
    fn gather<V: Vector>(&mut self, k: usize, w: &World<V>) {
        let p = w.particles();
        let (rows, n) = (k * self.n * self.dim..(k + 1) * self.n * self.dim, k * self.n..(k + 1) * self.n);
        let mirror = &mut self.mirror;
        mirror.x[rows.clone()].copy_from_slice(V::flat(&p.state().x));
        mirror.v[rows].copy_from_slice(V::flat(&p.state().v));
        mirror.mass[n.clone()].copy_from_slice(&p.model().mass);
        mirror.im[n].copy_from_slice(&p.model().inv_mass);
        mirror.t[k] = w.time();
        mirror.steps[k] = w.steps();
        mirror.dis[k] = p.dissipated_by_term().to_vec();
        mirror.collisions[k] = p.constraints_dissipated();
    }

    /// The mirror onto the device, the retired members and `failed` held still (no velocity,
    /// no inverse mass) so that they cannot move; the device's books start from zero there.
    fn upload(&mut self, failed: &[usize]) -> Result<()> {
        self.mirror.dis_at_upload.clone_from(&self.mirror.dis);
        self.mirror.collisions_at_upload.clone_from(&self.mirror.collisions);
        let still: Vec<usize> = (0..self.m).filter(|&k| self.retired[k] || failed.contains(&k)).collect();
        if still.is_empty() {
            self.p.set_state(&self.mirror.x, &self.mirror.v, &self.mirror.mass, &self.mirror.im)?;
        } else {
            let (mut v, mut im) = (self.mirror.v.clone(), self.mirror.im.clone());
            let rows = self.n * self.dim;
            for k in still {
                v[k * rows..(k + 1) * rows].iter_mut().for_each(|c| *c = 0.0);
                im[k * self.n..(k + 1) * self.n].iter_mut().for_each(|c| *c = 0.0);
            }
            self.p.set_state(&self.mirror.x, &v, &self.mirror.mass, &im)?;
        }
        Ok(())
    }

    /// Writes member `k`'s state, clock and books from the mirror into its world `w`, as if it
    /// had taken its steps alone.
    pub fn settle<V: Vector>(&self, k: usize, w: &mut World<V>) -> Result<()> {
        let rows = k * self.n * self.dim..(k + 1) * self.n * self.dim;
        let m = &self.mirror;
        w.particles_mut().set_state_from(V::rows(&m.x[rows.clone()]), V::rows(&m.v[rows]))?;
        w.restore(m.t[k], m.steps[k], &m.dis[k], m.collisions[k], None)
    }

    /// `settle` for each of `worlds` (index, world), in parallel on the current pool.
    pub fn settle_all<V: Vector>(&self, worlds: &mut [(usize, &mut World<V>)]) -> Result<()> {
        worlds.par_iter_mut().map(|(k, w)| self.settle(*k, w)).collect::<Vec<Result<()>>>().into_iter().collect()
    }

    /// The error a retired member `k` raised, for its world `w` settled where its call started:
    /// what the member stepped alone would have raised.
    pub fn diverged<V: Vector>(&self, k: usize, w: &World<V>) -> Option<Error> {
        let &(done, particle) = self.diverged.get(&k)?;
        let dt = self.dt;
        Some(Error::Diverged {
            step: w.steps() + done + 1,
            t: w.time() + (done + 1) as Real * dt,
            particle,
            quantity: Failure::Position,
            rolled_back_to: w.steps(),
            dt,
            suggested_dt: w.suggest_dt().min(0.5 * dt),
            explicit_euler: false,
            remedies: w.particles().remedies(),
        })
    }

    /// Every member's positions (`vel` false) or velocities as the mirror holds them, flat
    /// (m·n·dim), and each member's clock and step count.
    pub fn mirror(&self, vel: bool) -> (&[Real], &[Real], &[u64]) {
        (if vel { &self.mirror.v } else { &self.mirror.x }, &self.mirror.t, &self.mirror.steps)
    }
}

/// The host's copy of every member as the device has stepped it: what a member's world is
/// written from when it is read (`DeviceBatch::settle`), and what the device is written from
/// when a member was changed.
struct Mirror {
    /// Positions and velocities, flat (m·n·dim); masses and inverse masses (m·n).
    x: Vec<Real>,
    v: Vec<Real>,
    mass: Vec<Real>,
    im: Vec<Real>,
    /// Each member's clock and step count.
    t: Vec<Real>,
    steps: Vec<u64>,
    /// Each member's energy dissipated by each term, and by its colliders; and as they were
    /// at the last upload, where the device's books started from zero.
    dis: Vec<Vec<Real>>,
    collisions: Vec<Real>,
    dis_at_upload: Vec<Vec<Real>>,
    collisions_at_upload: Vec<Real>,
}

/// What `DeviceBatch::run` computed, not yet in the mirror.
pub struct Ran {
    n: u64,
    x: Vec<Real>,
    v: Vec<Real>,
    books: Vec<dp::Books>,
    /// The members that diverged: (member, steps done before, particle).
    failed: Vec<(usize, u64, usize)>,
}
