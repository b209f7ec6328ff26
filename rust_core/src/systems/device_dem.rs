//! DEM grains stepped on a GPU (`physcore_gpu::dem`) as a system of the world: what a scene of
//! grains under one "contacts" term (and a uniform gravity, a linear drag) becomes at
//! `device="gpu"` (issue "GPU fluids, grains and batches"). It stands in for the particle system
//! under its name, so the scene reads positions, spins, the books and the contact term's history
//! from it.
//!
//! What it holds: every particle of the scene as a grain (its `radius` attribute > 0), pinned
//! ones as fixed obstacles (pegs) as the CPU term holds them, exactly one `contacts` term with
//! its walls (planes, spheres and bowls, capsules, oriented boxes), at most one `gravity` and one `drag` term, in any order, semi-implicit
//! Euler (the CPU's scheme for contacts; not "xpbd"), no scene colliders. Anything else is
//! refused by name before anything moves (`from_records`).
//!
//! Books, history and step limit are the CPU term's (`terms::contacts`): the same energy names
//! and order, its `OwnState::history` layout both ways (`term_history`, `set_term_history`), so
//! a scene saved on either path continues on the other, and its `max_dt`. The device books
//! friction's dissipation per contact a little differently from the CPU (see
//! `physcore_gpu::dem`'s docs): the friction entries agree to the scheme's error, the normal
//! damping entries to the order of their sums.
//!
//! The cell list's box (which orders the force sums, so the bits, not the physics) is fitted to
//! the grains at `from_records` and kept in the saved rows: a load rebuilds it as it was, and
//! the run continues bit for bit.
use super::{saved, Arrays, EnergyReport, Halt, HeldTerms, Snapshot, System};
use crate::error::{invalid, Result};
use crate::geometry::AnyShape;
use crate::terms::contacts::{damping_ratio, Law as CpuLaw};
use crate::terms::registry::{self, Context, Params};
use crate::vector::{Real, Vector};
use glam::{DVec2, DVec3};
use physcore_gpu::dem::{Dem, DemBooks, DemParams, DemRaw, Law, Shape, Wall};
use physcore_gpu::{Gpu, Precision};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

/// Cells the fitted box may hold at most: beyond, the cells grow (still ≥ 2 r_max).
const MAX_CELLS: Real = 16_777_216.0;

/// The names the books go under, in the terms' order (as on the CPU).
struct Names {
    contacts: String,
    gravity: Option<String>,
    /// The drag term's, if its coefficient is > 0 (the CPU books a drag of 0 nowhere).
    drag: Option<String>,
    /// Whether gravity's potential comes before the contacts' (the terms' order).
    gravity_first: bool,
}

/// A checkpoint: the device keeps its own copy (`Dem::snapshot`); this marks it, with what the
/// host keeps.
struct Mark {
    evaluated: bool,
}

pub struct DeviceDem {
    name: String,
    gpu: Arc<Gpu>,
    precision: Precision,
    dim: usize,
    params: DemParams,
    walls: Vec<Wall>,
    radius: Vec<Real>,
    mass: Vec<Real>,
    /// The fixed grains (`Dem::set_pinned`).
    pinned: Vec<bool>,
    /// β of I = β m r² (the CPU term's, its default by dimension).
    beta: Real,
    /// The contacts term's record, to read histories through the CPU term's own loader.
    record: Params,
    names: Names,
    g: Mutex<Dem>,
    /// Whether a step ran since the state was last set: the Hertz step limit reads the last
    /// evaluation's deepest overlap (0 before, as on the CPU).
    evaluated: bool,
}

/// `key` of the record, or `default` where it is absent (the CPU builder's optional keys).
fn number_or(p: &Params, key: &str, default: Real) -> Result<Real> {
    if p.has(key) {
        p.number(key)
    } else {
        Ok(default)
    }
}

/// The floats under `key` (a copy: the records stay as they are).
/// The contacts term's walls as the device's: read and checked by the CPU term's own parser
/// (`contacts::walls`), so both paths hold the same shapes (an oriented box's axes as the CPU
/// computed them from its rotation).
fn walls_of<V: Vector>(cp: &Params, law: CpuLaw) -> Result<Vec<Wall>> {
    let flat = |v: &V| {
        let mut a = [0.0; 3];
        a[..V::DIM].copy_from_slice(V::flat(std::slice::from_ref(v)));
        a
    };
    let walls = crate::terms::contacts::walls::<V>(&mut cp.try_clone("add_term")?, law)?;
    walls
        .iter()
        .enumerate()
        .map(|(k, w)| {
            let shape = match &w.shape {
                AnyShape::HalfSpace(h) => Shape::Plane { point: flat(&h.point), normal: flat(&h.normal) },
                AnyShape::Ball(b) => Shape::Sphere { center: flat(&b.center), radius: b.radius, inside: b.inside },
                AnyShape::Capsule(c) => Shape::Capsule { a: flat(&c.a), b: flat(&c.b), radius: c.radius },
                AnyShape::OrientedBox(b) => {
                    Shape::OrientedBox { center: flat(&b.center), half: b.half, axes: b.axes.each_ref().map(flat) }
                }
                AnyShape::Aabb(_) => {
                    return Err(invalid("walls", format!("wall {k}: the GPU path's DEM has no axis-aligned box walls")))
                }
            };
            Ok(Wall { shape, zeta: w.zeta, friction: w.friction })
        })
        .collect()
}

/// `walls_of` in `dim` dimensions.
pub(crate) fn walls_of_record(dim: usize, cp: &Params, law: CpuLaw) -> Result<Vec<Wall>> {
    if dim == 2 {
        walls_of::<DVec2>(cp, law)
    } else {
        walls_of::<DVec3>(cp, law)
    }
}

fn floats(p: &Params, key: &str) -> Result<Vec<Real>> {
    p.try_clone("step")?.take_floats(key)
}

/// The CPU contacts term's history `h` as that term reads it back (checked by its loader,
/// pairs from their lower index, sorted, repeats dropped): what the device takes.
fn canonical<V: Vector>(record: &Params, name: &str, n: usize, h: &[Real]) -> Result<Vec<Real>> {
    let ctx = Context { n_particles: n };
    let mut t = registry::lookup("contacts")?.build::<V>(name.to_string(), record.try_clone("history")?, &ctx)?;
    let Some(s) = t.as_own_state_mut() else {
        return Err(invalid(name, "the contacts term keeps no history"));
    };
    s.set_history(h, n)?;
    s.history()
}

/// Axial components per grain: 1 in 2D (about z), 3 in 3D.
fn axial(dim: usize) -> usize {
    if dim == 2 {
        1
    } else {
        3
    }
}

/// The box of the cell list: the grains' bounding box grown by half its extent (at least 8
/// r_max) on every side, and the cell size (2 r_max, larger where the box would hold more than
/// `MAX_CELLS`).
fn fit_box(dim: usize, x: &[Real], rmax: Real) -> ([Real; 3], [Real; 3]) {
    let (mut lower, mut upper) = ([0.0; 3], [1.0; 3]);
    for a in 0..dim {
        let (lo, hi) =
            x.iter().skip(a).step_by(dim).fold((Real::INFINITY, Real::NEG_INFINITY), |(l, h), &c| (l.min(c), h.max(c)));
        let pad = (0.5 * (hi - lo)).max(8.0 * rmax);
        (lower[a], upper[a]) = (lo - pad, hi + pad);
    }
    (lower, upper)
}

/// The cell size for box `[lower, upper]` and grains up to `rmax`: 2 r_max, or larger so that
/// the box holds at most `MAX_CELLS` cells.
fn cell_of(dim: usize, lower: &[Real; 3], upper: &[Real; 3], rmax: Real) -> Real {
    let volume: Real = (0..dim).map(|a| upper[a] - lower[a]).product();
    let c = 2.0 * rmax;
    let cells = volume / c.powi(dim as i32);
    if cells > MAX_CELLS {
        (volume / MAX_CELLS).powf(1.0 / dim as Real).max(c)
    } else {
        c
    }
}

impl DeviceDem {
    /// The scene's grains (`x`, `v`: flat, n·dim; `mass`, `pinned`, the `radius` attribute),
    /// its force terms and colliders (their records as added) as device grains on `gpu` at
    /// `precision` ("f32", "f64"), named `name`. `history`: the CPU contacts term's
    /// `OwnState::history` at the move (spins, angles, books, springs), or `None` (at rest,
    /// no contacts yet).
    ///
    /// Errors: `InvalidInput` naming what the device's DEM cannot hold (a term other than one
    /// "contacts", one "gravity" and one "drag", no contacts term,
    /// another integrator than "semi_implicit_euler", scene colliders, no radius attribute or
    /// a radius not > 0, pinned particles included, no grains), the contacts and drag terms' own
    /// checks of their records and of `history`, f64 on an adapter without it; `OutOfMemory` for
    /// device buffers.
    #[allow(clippy::too_many_arguments)]
    pub fn from_records(
        gpu: Arc<Gpu>,
        precision: &str,
        name: &str,
        dim: usize,
        integrator: &str,
        x: &[Real],
        v: &[Real],
        mass: &[Real],
        pinned: &[bool],
        radius: Option<&[Real]>,
        history: Option<&[Real]>,
        terms: &[(String, String, Params)],
        colliders: &[(String, Params)],
    ) -> Result<Self> {
        let precision = super::device::precision_of(precision)?;
        if !(dim == 2 || dim == 3) {
            return Err(invalid("dim", format!("{dim} must be 2 or 3")));
        }
        let n = mass.len();
        if x.len() != n * dim || v.len() != n * dim {
            return Err(invalid(
                "x",
                format!("{} positions and {} velocities for {n} particles in {dim}D", x.len(), v.len()),
            ));
        }
        let mut contacts = None;
        let mut gravity = None;
        let mut drag = None;
        let mut gravity_first = false;
        for (kind, tname, p) in terms {
            match kind.as_str() {
                "contacts" if contacts.is_none() => contacts = Some((tname.clone(), p)),
                "gravity" if gravity.is_none() => {
                    gravity_first = contacts.is_none();
                    gravity = Some((tname.clone(), p));
                }
                "drag" if drag.is_none() => drag = Some((tname.clone(), p)),
                "contacts" | "gravity" | "drag" => {
                    return Err(invalid(
                        tname,
                        format!(
                            "the GPU path's DEM holds one contacts, one gravity and one drag term; {tname:?} is a second {kind:?}"
                        ),
                    ))
                }
                _ => {
                    return Err(invalid(
                        tname,
                        format!(
                            "the GPU path's DEM holds grains under one \"contacts\" term, a uniform gravity and a linear drag; it has no kernel for {kind:?}"
                        ),
                    ))
                }
            }
        }
        let Some((cname, cp)) = contacts else {
            return Err(invalid("terms", "no contacts term: the GPU path's DEM moves grains under one"));
        };
        if integrator != "semi_implicit_euler" {
            return Err(invalid(
                "integrator",
                format!("the GPU path's DEM steps by semi-implicit Euler (the CPU's scheme for contacts), not {integrator:?}"),
            ));
        }
        if let Some((kind, _)) = colliders.first() {
            return Err(invalid(
                "colliders",
                format!(
                    "the GPU path's DEM has no scene colliders (a {kind:?} here); give the contacts term walls instead"
                ),
            ));
        }
        if pinned.len() != n {
            return Err(invalid("pinned", format!("{} flags for {n} particles", pinned.len())));
        }
        let Some(radius) = radius else {
            return Err(invalid("radius", "the GPU path's DEM needs the particles' \"radius\" attribute"));
        };
        if radius.len() != n {
            return Err(invalid("radius", format!("{} values for {n} particles", radius.len())));
        }
        if let Some(i) = radius.iter().position(|r| !(r.is_finite() && *r > 0.0)) {
            let what = if pinned[i] { "pinned particle" } else { "particle" };
            return Err(invalid(
                "radius",
                format!(
                    "{what} {i}: {} (the GPU path's DEM takes every particle as a grain, pinned ones too: radius > 0)",
                    radius[i]
                ),
            ));
        }
        if n == 0 {
            return Err(invalid("particles", "no grains to move"));
        }
        // The CPU term's own checks of its record (same errors on both paths).
        let ctx = Context { n_particles: n };
        let build = registry::lookup("contacts")?;
        if dim == 2 {
            build.build::<DVec2>(cname.clone(), cp.try_clone("add_term")?, &ctx)?;
        } else {
            build.build::<DVec3>(cname.clone(), cp.try_clone("add_term")?, &ctx)?;
        }
        // The drag term's own checks likewise; b = 0 is a term with no force and no book.
        let b = match &drag {
            Some((dname, p)) => {
                registry::lookup("drag")?.build::<DVec2>(dname.clone(), p.try_clone("add_term")?, &ctx)?;
                p.number("coefficient")?
            }
            None => 0.0,
        };
        let (law, cpu_law) = match cp.text("law")? {
            "hertz" => (Law::Hertz, CpuLaw::Hertz),
            _ => (Law::Linear, CpuLaw::Linear),
        };
        let beta = number_or(cp, "inertia_factor", if dim == 2 { 0.5 } else { 0.4 })?;
        let walls = walls_of_record(dim, cp, cpu_law)?;
        let mut g = [0.0; 3];
        if let Some((_, p)) = &gravity {
            let gv = floats(p, "g")?;
            g[..dim].copy_from_slice(&gv[..dim]);
        }
        let rmax = radius.iter().cloned().fold(0.0, Real::max);
        let (lower, upper) = fit_box(dim, x, rmax);
        let params = DemParams {
            law,
            stiffness: cp.number("stiffness")?,
            zeta: damping_ratio(cpu_law, cp.number("restitution")?),
            friction: cp.number("friction")?,
            tangential_ratio: cp.number("tangential_ratio")?,
            inertia_factor: beta,
            gravity: g,
            lower,
            upper,
            cell: cell_of(dim, &lower, &upper, rmax),
            capacity: if dim == 2 { 8 } else { 16 },
            rolling_friction: number_or(cp, "rolling_friction", 0.0)?,
            rolling_damping: number_or(cp, "rolling_damping", 0.0)?,
            drag: b,
        };
        let mut dem = Dem::new(gpu.clone(), precision, dim, params, x, v, radius, mass, &walls)?;
        dem.set_pinned(pinned)?;
        let drag = drag.filter(|_| b > 0.0).map(|d| d.0);
        let names = Names { contacts: cname, gravity: gravity.map(|g| g.0), drag, gravity_first };
        let mut s = Self {
            name: name.to_string(),
            gpu,
            precision,
            dim,
            params,
            walls,
            radius: radius.to_vec(),
            mass: mass.to_vec(),
            pinned: pinned.to_vec(),
            beta,
            record: cp.try_clone("add_term")?,
            names,
            g: Mutex::new(dem),
            evaluated: false,
        };
        if let Some(h) = history {
            let name = s.names.contacts.clone();
            s.set_term_history(&name, h)?;
            // Taken over from the CPU term: overlaps it has not met yet are booked at the first
            // step, as the CPU books them (grains placed overlapping).
            s.g.get_mut().unwrap_or_else(|p| p.into_inner()).book_found_contacts();
        }
        Ok(s)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Dem> {
        self.g.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A new device of `params` holding `raw` (a box or capacity changed).
    fn rebuild(&mut self, params: DemParams, raw: &DemRaw) -> Result<()> {
        let mut dem = Dem::new(
            self.gpu.clone(),
            self.precision,
            self.dim,
            params,
            &raw.x,
            &raw.v,
            &self.radius,
            &self.mass,
            &self.walls,
        )?;
        dem.set_pinned(&self.pinned)?;
        dem.load_raw(raw)?;
        *self.g.get_mut().unwrap_or_else(|p| p.into_inner()) = dem;
        self.params = params;
        Ok(())
    }

    /// The CPU layout of the history (see `term_history`) from the device's raw state.
    fn history_of(&self, raw: &DemRaw) -> Vec<Real> {
        let (d, n, k) = (self.dim, self.radius.len(), self.lock().capacity());
        let roll = self.params.rolling_friction > 0.0;
        let sv = raw.springs.len() / (n * k).max(1);
        let mut h = Vec::with_capacity(3 + n * (axial(d) + 1) + raw.springs.len());
        h.push(n as Real);
        h.extend_from_slice(&raw.omega);
        if d == 2 {
            h.extend_from_slice(&raw.angle);
        } else {
            h.extend(std::iter::repeat_n(0.0, n));
        }
        // Summed in grain order, as the device's books are (`Dem::books`).
        h.push(raw.books[..n].iter().fold(0.0, |a, b| a + b));
        h.push(raw.books[n..].iter().fold(0.0, |a, b| a + b));
        for i in 0..n {
            let row = &raw.keys[i * (k + 1)..(i + 1) * (k + 1)];
            // Each pair once, from its first grain (the lower index); walls after grains.
            let mut own: Vec<(u32, usize)> = (0..row[0] as usize)
                .map(|q| (row[1 + q], q))
                .filter(|&(j, _)| j as usize >= n || j as usize > i)
                .collect();
            own.sort_unstable();
            for (j, q) in own {
                let e = &raw.springs[(i * k + q) * sv..(i * k + q + 1) * sv];
                h.push(i as Real);
                h.push(j as Real);
                h.extend_from_slice(&e[..d + 1]);
                if roll {
                    h.extend_from_slice(&e[d + 1..]);
                }
            }
        }
        h
    }

    /// The device's raw state from a history in the CPU term's canonical layout (`canonical`),
    /// at positions and velocities `x`, `v`, for capacity `k`; the contacts' books so far go to
    /// grain 0, the drag's per grain are `drag` (not the contacts term's: kept as they are).
    fn raw_of(&self, c: &[Real], x: Vec<Real>, v: Vec<Real>, drag: &[Real], k: usize) -> DemRaw {
        let (d, n, a) = (self.dim, self.radius.len(), axial(self.dim));
        let roll = self.params.rolling_friction > 0.0;
        let sv = d + 1 + if roll { a + 1 } else { 0 };
        let h0 = c[0] as usize;
        let head = 1 + h0 * (a + 1) + 2;
        let (omega, angle) = if h0 == 0 {
            (vec![0.0; n * a], vec![0.0; n])
        } else {
            (c[1..1 + n * a].to_vec(), c[1 + n * a..1 + n * (a + 1)].to_vec())
        };
        let mut books = vec![0.0; 2 * n];
        books[0] = c[head - 2];
        books[n] = c[head - 1];
        books.extend_from_slice(drag);
        let mut keys = vec![0u32; n * (k + 1)];
        let mut springs = vec![0.0; n * k * sv];
        let mut put = |i: usize, j: usize, e: &[Real]| {
            let m = keys[i * (k + 1)] as usize;
            keys[i * (k + 1)] += 1;
            keys[i * (k + 1) + 1 + m] = j as u32;
            springs[(i * k + m) * sv..(i * k + m + 1) * sv].copy_from_slice(e);
        };
        for rec in c[head..].chunks_exact(2 + sv) {
            let (i, j) = (rec[0] as usize, rec[1] as usize);
            put(i, j, &rec[2..]);
            if j < n {
                put(j, i, &rec[2..]);
            }
        }
        let angle = if d == 2 { angle } else { Vec::new() };
        DemRaw { x, v, omega, angle, keys, springs, books }
    }

    /// Contacts the most-touched grain holds in canonical history `c`.
    fn most_contacts(&self, c: &[Real]) -> usize {
        let (n, a) = (self.radius.len(), axial(self.dim));
        let sv = self.dim + 1 + if self.params.rolling_friction > 0.0 { a + 1 } else { 0 };
        let head = 1 + c[0] as usize * (a + 1) + 2;
        let mut count = vec![0usize; n];
        for rec in c[head..].chunks_exact(2 + sv) {
            count[rec[0] as usize] += 1;
            if (rec[1] as usize) < n {
                count[rec[1] as usize] += 1;
            }
        }
        count.into_iter().max().unwrap_or(0)
    }

    /// The CPU scene's step limit (`ParticleSystem::auto_dt` of these terms): the contacts
    /// term's (`Contacts::max_dt`: a 50th of the contact duration of the lightest pair of free
    /// grains; linear: the stiffest of the normal, tangential and rolling modes; Hertz:
    /// Johnson's impact duration at twice the fastest free grain's speed or a fall through one
    /// radius, and the period at the last evaluation's deepest overlap), within half the drag's
    /// time scale m/b of the lightest free grain (`Drag::time_scale`); `None` with no free
    /// grain, as on the CPU.
    fn max_dt(&self) -> Result<Option<Real>> {
        let p = &self.params;
        let free = || (0..self.mass.len()).filter(|&i| !self.pinned[i]);
        let m_min = free().map(|i| self.mass[i]).fold(Real::INFINITY, Real::min);
        let r_min = free().map(|i| self.radius[i]).fold(Real::INFINITY, Real::min);
        if !m_min.is_finite() {
            return Ok(None);
        }
        let hertz = matches!(p.law, Law::Hertz);
        let (v_max2, deepest) = if hertz {
            let g = self.lock();
            let (_, v, _) = g.read()?;
            let d = self.dim;
            let v_max2 = free().map(|i| v[d * i..d * (i + 1)].iter().map(|u| u * u).sum::<Real>()).fold(0.0, Real::max);
            (v_max2, if self.evaluated { g.max_overlap()? } else { 0.0 })
        } else {
            (0.0, 0.0)
        };
        let gm = p.gravity.iter().map(|c| c * c).sum::<Real>().sqrt();
        let shape = (p.stiffness, p.tangential_ratio, self.beta, p.rolling_friction);
        let limit = crate::terms::contacts::step_limit(hertz, shape, m_min, r_min, v_max2, gm, deepest);
        let drag = if p.drag > 0.0 { 0.5 * (m_min / p.drag) } else { Real::INFINITY };
        let dt = drag.min(limit);
        Ok((dt.is_finite() && dt > 0.0).then_some(dt))
    }
}

impl System for DeviceDem {
    fn name(&self) -> &str {
        &self.name
    }
    fn as_held_terms(&self) -> Option<&dyn HeldTerms> {
        Some(self)
    }
    fn as_held_terms_mut(&mut self) -> Option<&mut dyn HeldTerms> {
        Some(self)
    }
    fn is_empty(&self) -> bool {
        self.radius.is_empty()
    }
    fn size(&self) -> usize {
        self.radius.len()
    }
    fn step(&mut self, dt: Real, stop: &AtomicBool) -> std::result::Result<(), Halt> {
        self.steps(1, dt, stop).map_err(|(_, h)| h)
    }
    fn steps(&mut self, n: u64, dt: Real, stop: &AtomicBool) -> std::result::Result<(), (u64, Halt)> {
        let r = self.g.get_mut().unwrap_or_else(|p| p.into_inner()).step(n, dt, stop);
        self.evaluated |= n > 0;
        r.map(|_| ()).map_err(super::device::halt_of)
    }
    /// The CPU contacts term's limit (see `max_dt`); a device that cannot be read gives none
    /// (its next step reports it).
    fn auto_dt(&self) -> Option<Real> {
        self.max_dt().ok().flatten()
    }
    fn suggest_dt(&self) -> Option<Real> {
        self.auto_dt()
    }
    /// The CPU scene's books under its names and order: kinetic with the spins (½Iω²; free
    /// grains), the potentials in the terms' order (the contacts' springs, gravity's −Σ m g·x
    /// over the free grains), then the dissipated: the drag term's (if b > 0; the CPU lists the
    /// dissipating terms first), the contacts term's own books, "NAME (normal damping)" and
    /// "NAME (friction)".
    fn energy(&self) -> EnergyReport {
        let nan = Real::NAN;
        let b = self.lock().books().unwrap_or(DemBooks {
            kinetic: nan,
            rotational: nan,
            potential: nan,
            gravity: nan,
            damping: nan,
            friction: nan,
            drag: nan,
        });
        let mut r = EnergyReport { kinetic: b.rotational + b.kinetic, ..Default::default() };
        let contacts = (self.names.contacts.clone(), b.potential);
        match &self.names.gravity {
            Some(g) if self.names.gravity_first => r.potential.extend([(g.clone(), b.gravity), contacts]),
            Some(g) => r.potential.extend([contacts, (g.clone(), b.gravity)]),
            None => r.potential.push(contacts),
        }
        if let Some(d) = &self.names.drag {
            r.dissipated.push((d.clone(), b.drag));
        }
        let c = &self.names.contacts;
        r.dissipated.push((format!("{c} (normal damping)"), b.damping));
        r.dissipated.push((format!("{c} (friction)"), b.friction));
        r
    }
    /// "x", "y", "z", "vx", "vy", "vz", "mass", "pinned", "radius", and the contacts term's
    /// fields: 2D "angular_velocity" and "angle", 3D "angular_velocity_x/y/z", "coordination"
    /// (contacts a grain holds); 0 for any other name.
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let (d, n) = (self.dim, self.radius.len());
        let g = self.lock();
        let (x, v, w) = g.read()?;
        let angle = if names.contains(&"angle") { g.angles()? } else { Vec::new() };
        let coordination = if names.contains(&"coordination") {
            let (raw, k) = (g.save_raw()?, g.capacity());
            (0..n).map(|i| raw.keys[i * (k + 1)] as Real).collect()
        } else {
            Vec::new()
        };
        let a = axial(d);
        let col = |s: &[Real], k: usize, w: usize| -> Vec<Real> { s.chunks_exact(w).map(|c| c[k]).collect() };
        Ok(names
            .iter()
            .map(|name| match *name {
                "x" => col(&x, 0, d),
                "y" => col(&x, 1, d),
                "z" if d == 3 => col(&x, 2, d),
                "vx" => col(&v, 0, d),
                "vy" => col(&v, 1, d),
                "vz" if d == 3 => col(&v, 2, d),
                "mass" => self.mass.clone(),
                "pinned" => self.pinned.iter().map(|&p| p as u8 as Real).collect(),
                "radius" => self.radius.clone(),
                "angular_velocity" if d == 2 => w.clone(),
                "angle" if d == 2 => angle.clone(),
                "angular_velocity_x" if d == 3 => col(&w, 0, a),
                "angular_velocity_y" if d == 3 => col(&w, 1, a),
                "angular_velocity_z" if d == 3 => col(&w, 2, a),
                "coordination" => coordination.clone(),
                _ => vec![0.0; n],
            })
            .collect())
    }
    fn snapshot(&self) -> Result<Snapshot> {
        self.lock().snapshot()?;
        Ok(Box::new(Mark { evaluated: self.evaluated }))
    }
    fn restore(&mut self, snapshot: Snapshot) {
        // A lost device cannot be restored: its next read reports the failure.
        let _ = self.g.get_mut().unwrap_or_else(|p| p.into_inner()).restore();
        if let Ok(m) = snapshot.downcast::<Mark>() {
            self.evaluated = m.evaluated;
        }
    }
    /// The grains' rows, as the scene file keeps the device's (`systems::device`): `pos` and
    /// `vel` (N × 4: position and mass as the device holds it, velocity and 1/mass), `aux` (ω:
    /// 1 value in 2D, 3 in 3D, from column 0; the 2D angle in column 3), `acc` (the grain's
    /// books, normal damping and friction, then for rows a < dim the cell list's box along
    /// axis a, lower and upper), `hits` (the grain's drag book), `acc_valid` 1. A pinned grain's
    /// 1/mass is 0 (the CPU's `inv_mass`). The contacts themselves travel in the contacts term's
    /// history (`term_history`).
    fn save(&self) -> Result<Arrays> {
        let raw = self.lock().save_raw()?;
        let (d, n, a) = (self.dim, self.radius.len(), axial(self.dim));
        let mut pos = vec![0.0; 4 * n];
        let mut vel = vec![0.0; 4 * n];
        let mut acc = vec![0.0; 4 * n];
        let mut aux = vec![0.0; 4 * n];
        for i in 0..n {
            let m = if self.precision == Precision::F32 { self.mass[i] as f32 as Real } else { self.mass[i] };
            pos[4 * i..4 * i + d].copy_from_slice(&raw.x[d * i..d * (i + 1)]);
            pos[4 * i + 3] = m;
            vel[4 * i..4 * i + d].copy_from_slice(&raw.v[d * i..d * (i + 1)]);
            vel[4 * i + 3] = if self.pinned[i] { 0.0 } else { 1.0 / m };
            aux[4 * i..4 * i + a].copy_from_slice(&raw.omega[a * i..a * (i + 1)]);
            if d == 2 {
                aux[4 * i + 3] = raw.angle[i];
            }
            acc[4 * i] = raw.books[i];
            acc[4 * i + 1] = raw.books[n + i];
            if i < d {
                acc[4 * i + 2] = self.params.lower[i];
                acc[4 * i + 3] = self.params.upper[i];
            }
        }
        let hits = raw.books[2 * n..].to_vec();
        saved(
            "the device grains",
            &[("pos", &pos), ("vel", &vel), ("acc", &acc), ("aux", &aux), ("hits", &hits), ("acc_valid", &[1.0])],
        )
    }
    /// Loads what `save` wrote: the state, spins, angles and books (the drag's from `hits`)
    /// from the rows, the contacts kept as they are (set them first through `set_term_history`), the cell list's box as
    /// saved (rebuilt if it differs, so the sums run in the saved order).
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let (d, n, a) = (self.dim, self.radius.len(), axial(self.dim));
        let mut rows = Vec::with_capacity(4);
        for key in ["pos", "vel", "acc", "aux"] {
            let r = super::array(arrays, key, Some(4 * n))?;
            if let Some(i) = r.iter().position(|c| !c.is_finite()) {
                return Err(invalid(key, format!("entry {i} is not finite")));
            }
            rows.push(r);
        }
        let (pos, vel, acc, aux) = (rows[0], rows[1], rows[2], rows[3]);
        let (mut lower, mut upper) = (self.params.lower, self.params.upper);
        if n >= d {
            for k in 0..d {
                (lower[k], upper[k]) = (acc[4 * k + 2], acc[4 * k + 3]);
                if !(upper[k] > lower[k]) {
                    return Err(invalid(
                        "acc",
                        format!("row {k}: the cell list's box [{}, {}] is empty", lower[k], upper[k]),
                    ));
                }
            }
        }
        let cols = |r: &[Real], w: usize| -> Vec<Real> { r.chunks_exact(4).flat_map(|c| c[..w].to_vec()).collect() };
        let mut raw = self.lock().save_raw()?;
        raw.x = cols(pos, d);
        raw.v = cols(vel, d);
        raw.omega = cols(aux, a);
        if d == 2 {
            raw.angle = aux.chunks_exact(4).map(|c| c[3]).collect();
        }
        let hits = super::array(arrays, "hits", Some(n))?;
        if let Some(i) = hits.iter().position(|c| !c.is_finite()) {
            return Err(invalid("hits", format!("entry {i} is not finite")));
        }
        raw.books =
            acc.chunks_exact(4).map(|c| c[0]).chain(acc.chunks_exact(4).map(|c| c[1])).chain(hits.to_vec()).collect();
        if (lower, upper) != (self.params.lower, self.params.upper) {
            let rmax = self.radius.iter().cloned().fold(0.0, Real::max);
            let cell = cell_of(d, &lower, &upper, rmax);
            let params = DemParams { lower, upper, cell, ..self.params };
            self.rebuild(params, &raw)?;
        } else {
            self.g.get_mut().unwrap_or_else(|p| p.into_inner()).load_raw(&raw)?;
        }
        self.evaluated = false;
        Ok(())
    }
}

/// The device against a CPU world of the same records (contacts with a floor, gravity),
/// both laws, 2D and 3D, f64 and f32; the history both ways, save and load, snapshot and
/// restore, and the refusals. Skipped where no adapter is found, unless PHYSCORE_GPU_REQUIRED=1
/// (CI runs it on lavapipe with PHYSCORE_GPU_ALLOW_CPU=1).
impl HeldTerms for DeviceDem {
    /// [n, ω (n·axial), angle (n; zeros in 3D), dissipated (normal damping, friction), then per
    /// live contact, sorted by first grain then partner (grains before walls): first grain,
    /// partner (grain, or n + wall index), ξ (dim) seen from the first grain, its spring's
    /// energy, and with rolling resistance θ_r (axial) and its energy]: the CPU contacts
    /// term's `OwnState::history`, for the contacts term's name; `None` for any other.
    fn term_history(&self, name: &str) -> Result<Option<Vec<Real>>> {
        if name != self.names.contacts {
            return Ok(None);
        }
        let raw = self.lock().save_raw()?;
        Ok(Some(self.history_of(&raw)))
    }
    /// Takes the CPU term's history (checked by that term's loader, which also takes a pair
    /// given from its higher index, or a history of 0 particles: at rest, no contacts). The
    /// books so far go to grain 0 of the device's per-grain books; more contacts on one grain
    /// than the device holds (32) is refused naming "history".
    fn set_term_history(&mut self, name: &str, history: &[Real]) -> Result<()> {
        if name != self.names.contacts {
            return Err(invalid(name, format!("system {:?} keeps no history of a term {name:?}", self.name)));
        }
        let n = self.radius.len();
        let c = if self.dim == 2 {
            canonical::<DVec2>(&self.record, name, n, history)?
        } else {
            canonical::<DVec3>(&self.record, name, n, history)?
        };
        let most = self.most_contacts(&c);
        if most > 32 {
            return Err(invalid(
                "history",
                format!("a grain holds {most} contacts: the GPU path's DEM holds 32 at most"),
            ));
        }
        let state = self.lock().save_raw()?;
        let k = self.lock().capacity();
        if most > k {
            let params = DemParams { capacity: most, ..self.params };
            let raw = self.raw_of(&c, state.x, state.v, &state.books[2 * n..], most);
            self.rebuild(params, &raw)?;
        } else {
            let raw = self.raw_of(&c, state.x, state.v, &state.books[2 * n..], k);
            self.g.get_mut().unwrap_or_else(|p| p.into_inner()).load_raw(&raw)?;
        }
        self.evaluated = false;
        Ok(())
    }
    /// The contacts term's counter "contacts", as the CPU's: grain pairs counted once and
    /// grain–wall contacts, from the committed history (the contacts of the last evaluation),
    /// counted on the device.
    fn term_counts(&self) -> Vec<(String, &'static str, u64)> {
        let Ok(count) = self.lock().contacts_once() else { return Vec::new() };
        vec![(self.names.contacts.clone(), "contacts", count)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use crate::systems::device_fluid::tests::gpu;
    use crate::systems::particles::ParticleSystem;
    use crate::terms::registry::Value;
    use crate::world::World;

    fn go() -> AtomicBool {
        AtomicBool::new(false)
    }

    /// Six grains of unequal radii and masses (density 1000): a pair thrown at each other, one
    /// sliding on the floor (in contact from the start: it stays so), a stack falling onto the
    /// floor, a fast one thrown obliquely at it.
    fn grains(dim: usize) -> (Vec<Real>, Vec<Real>, Vec<Real>, Vec<Real>) {
        let p: [[Real; 3]; 6] = [
            [-0.12, 0.3, 0.05],
            [0.12, 0.32, 0.0],
            [1.0, 0.0995, 0.0],
            [1.6, 0.12, 0.02],
            [1.63, 0.35, 0.0],
            [2.4, 0.2, -0.03],
        ];
        let u: [[Real; 3]; 6] =
            [[1.2, 0.0, 0.1], [-1.0, 0.05, 0.0], [0.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, -0.5, 0.0], [1.5, -2.0, 0.4]];
        let r = [0.1, 0.12, 0.1, 0.11, 0.1, 0.09];
        let (mut x, mut v) = (Vec::new(), Vec::new());
        for k in 0..6 {
            // In 3D the last axis is up: y and z swapped.
            let (a, b) =
                if dim == 2 { (p[k], u[k]) } else { ([p[k][0], p[k][2], p[k][1]], [u[k][0], u[k][2], u[k][1]]) };
            x.extend_from_slice(&a[..dim]);
            v.extend_from_slice(&b[..dim]);
        }
        let m = r.iter().map(|ri: &Real| 1000.0 * ri.powi(dim as i32)).collect();
        (x, v, r.to_vec(), m)
    }

    /// The records of "grains" (contacts, a floor through the origin) and "earth" (gravity).
    fn records(dim: usize, hertz: bool) -> Vec<(String, String, Params)> {
        let mut up = vec![0.0; 2 * dim];
        up[2 * dim - 1] = 1.0;
        let stiffness = match (hertz, dim) {
            (false, 2) => 1e5,
            (false, _) => 1e4,
            (true, 2) => 1e7,
            (true, _) => 1e6,
        };
        let mut c = Params::new()
            .with("law", Value::Text(if hertz { "hertz" } else { "linear" }.into()))
            .with("stiffness", Value::Number(stiffness))
            .with("tangential_ratio", Value::Number(if dim == 2 { 1.0 / 3.0 } else { 2.0 / 7.0 }))
            .with("restitution", Value::Number(0.6))
            .with("friction", Value::Number(0.4))
            .with("wall_kinds", Value::Text("plane".into()))
            .with("wall_params", Value::Floats(up))
            .with("wall_restitution", Value::Floats(vec![0.5]))
            .with("wall_friction", Value::Floats(vec![0.3]));
        if hertz {
            // Rolling resistance with the Hertz law: its springs travel in the history too.
            c.insert("rolling_friction", Value::Number(0.05));
            c.insert("rolling_damping", Value::Number(0.3));
        }
        let mut g = vec![0.0; dim];
        g[dim - 1] = -9.81;
        let g = Params::new().with("g", Value::Floats(g));
        vec![("contacts".into(), "grains".into(), c), ("gravity".into(), "earth".into(), g)]
    }

    fn cpu_world<V: Vector>(
        x: &[Real],
        v: &[Real],
        r: &[Real],
        m: &[Real],
        rec: &[(String, String, Params)],
        dt: Real,
    ) -> World<V> {
        cpu_world_pinned(x, v, r, m, &vec![false; m.len()], rec, dt)
    }

    fn cpu_world_pinned<V: Vector>(
        x: &[Real],
        v: &[Real],
        r: &[Real],
        m: &[Real],
        pinned: &[bool],
        rec: &[(String, String, Params)],
        dt: Real,
    ) -> World<V> {
        let (d, n) = (V::DIM, m.len());
        let vec = |s: &[Real]| V::from_slice(s);
        let mut sys = ParticleSystem::<V>::new("semi_implicit_euler").unwrap();
        sys.add_particles(x.chunks(d).map(vec).collect(), v.chunks(d).map(vec).collect(), m.to_vec(), pinned.to_vec())
            .unwrap();
        sys.set_attribute("radius", r.to_vec()).unwrap();
        let ctx = Context { n_particles: n };
        for (kind, name, p) in rec {
            let t =
                registry::lookup(kind).unwrap().build::<V>(name.clone(), p.try_clone("test").unwrap(), &ctx).unwrap();
            sys.add_term(t).unwrap();
        }
        World::new(sys, dt, Some(1)).unwrap()
    }

    fn device(
        gpu: &Arc<Gpu>,
        p: Precision,
        dim: usize,
        state: (&[Real], &[Real], &[Real], &[Real]),
        history: Option<&[Real]>,
        rec: &[(String, String, Params)],
    ) -> Result<DeviceDem> {
        device_pinned(gpu, p, dim, state, &vec![false; state.3.len()], history, rec)
    }

    fn device_pinned(
        gpu: &Arc<Gpu>,
        p: Precision,
        dim: usize,
        state: (&[Real], &[Real], &[Real], &[Real]),
        pinned: &[bool],
        history: Option<&[Real]>,
        rec: &[(String, String, Params)],
    ) -> Result<DeviceDem> {
        let (x, v, r, m) = state;
        let p = if p == Precision::F64 { "f64" } else { "f32" };
        DeviceDem::from_records(
            gpu.clone(),
            p,
            "device particles",
            dim,
            "semi_implicit_euler",
            x,
            v,
            m,
            pinned,
            Some(r),
            history,
            rec,
            &[],
        )
    }

    fn positions<V: Vector>(w: &World<V>) -> (Vec<Real>, Vec<Real>) {
        let s = w.particles().state();
        (V::flat(&s.x).to_vec(), V::flat(&s.v).to_vec())
    }

    fn dev_state(d: &DeviceDem) -> (Vec<Real>, Vec<Real>) {
        let (x, v, _) = d.lock().read().unwrap();
        (x, v)
    }

    fn max_diff(a: &[Real], b: &[Real]) -> Real {
        assert_eq!(a.len(), b.len());
        a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0, Real::max)
    }

    /// The history's head (n, ω, angle), its books and its records (i, j, then the values).
    type Parts = (Vec<Real>, [Real; 2], Vec<(usize, usize, Vec<Real>)>);
    fn parts(h: &[Real], dim: usize, roll: bool) -> Parts {
        let (n, a) = (h[0] as usize, axial(dim));
        let head = 1 + n * (a + 1) + 2;
        let w = 3 + dim + if roll { a + 1 } else { 0 };
        let recs = h[head..].chunks_exact(w).map(|r| (r[0] as usize, r[1] as usize, r[2..].to_vec())).collect();
        (h[..head - 2].to_vec(), [h[head - 2], h[head - 1]], recs)
    }

    /// Device and CPU histories: the same contacts; the largest difference of spins and
    /// angles, of the springs (ξ, θ_r and energies), and of the books.
    fn compare_histories(a: &[Real], b: &[Real], dim: usize, roll: bool) -> (usize, Real, Real, Real) {
        let (ha, da, ra) = parts(a, dim, roll);
        let (hb, db, rb) = parts(b, dim, roll);
        let pairs = |r: &[(usize, usize, Vec<Real>)]| r.iter().map(|c| (c.0, c.1)).collect::<Vec<_>>();
        assert_eq!(pairs(&ra), pairs(&rb), "the same contacts, in the same order");
        let springs = ra.iter().zip(&rb).map(|(p, q)| max_diff(&p.2, &q.2)).fold(0.0, Real::max);
        let books = (da[0] - db[0]).abs().max((da[1] - db[1]).abs());
        (ra.len(), max_diff(&ha, &hb), springs, books)
    }

    fn entries(e: &[(String, Real)]) -> Vec<&str> {
        e.iter().map(|p| p.0.as_str()).collect()
    }

    /// The energy reports: the same names in the same order; the largest difference of the
    /// state's parts (kinetic, potentials) and of the dissipated entries, over the total's scale.
    fn compare_energy(a: &EnergyReport, b: &EnergyReport) -> (Real, Real) {
        assert_eq!(entries(&a.potential), entries(&b.potential));
        assert_eq!(entries(&a.dissipated), entries(&b.dissipated));
        let scale = a.kinetic.abs() + a.potential.iter().chain(&a.dissipated).map(|p| p.1.abs()).sum::<Real>();
        let state = a
            .potential
            .iter()
            .zip(&b.potential)
            .map(|(p, q)| (p.1 - q.1).abs())
            .fold((a.kinetic - b.kinetic).abs(), Real::max);
        let lost = a.dissipated.iter().zip(&b.dissipated).map(|(p, q)| (p.1 - q.1).abs()).fold(0.0, Real::max);
        (state / scale, lost / scale)
    }

    fn follow<V: Vector>(gpu: &Arc<Gpu>, hertz: bool) {
        let dim = V::DIM;
        let (x, v, r, m) = grains(dim);
        let rec = records(dim, hertz);
        let mut w = cpu_world::<V>(&x, &v, &r, &m, &rec, 1.0);
        let dt = w.particles().auto_dt().unwrap();
        w.set_dt(dt).unwrap();
        let steps = 500;
        let limit = dt;
        w.step(steps).unwrap();
        for p in [Precision::F64, Precision::F32] {
            let mut dev = match device(gpu, p, dim, (&x, &v, &r, &m), None, &rec) {
                Ok(d) => d,
                Err(e) if p == Precision::F64 => {
                    eprintln!("f64 skipped: {e}");
                    continue;
                }
                Err(e) => panic!("{e}"),
            };
            // At the start (f32: of the rounded velocities).
            let (a, b) = (dev.auto_dt().unwrap(), limit);
            let tol = if p == Precision::F64 { 1e-12 } else { 1e-6 };
            assert!((a - b).abs() <= tol * b, "{dim}D step limits: device {a}, CPU {b}");
            dev.steps(steps, dt, &go()).unwrap();
            let (cx, cv) = positions(&w);
            let (dx, dv) = dev_state(&dev);
            let vmax = cv.iter().map(|u| u.abs()).fold(0.0, Real::max);
            let (ex, ev) = (max_diff(&cx, &dx) / 3.0, max_diff(&cv, &dv) / vmax);
            let (es, el) = compare_energy(&w.energy(), &dev.energy());
            let roll = hertz;
            let hd = dev.term_history("grains").unwrap().unwrap();
            let hc = w.particles().term_history("grains").unwrap().unwrap();
            let (contacts, spins, springs, books) = compare_histories(&hd, &hc, dim, roll);
            let (a, b) = (dev.auto_dt().unwrap(), w.particles().auto_dt().unwrap());
            eprintln!(
                "{dim}D {} {p:?}, {steps} steps of {dt:.2e} s: positions {ex:.1e} of the scene, velocities {ev:.1e}; \
                 energy: state {es:.1e}, dissipated {el:.1e} of the total; history: {contacts} contacts, spins {spins:.1e}, \
                 springs {springs:.1e}, books {books:.1e}; step limit {:.1e}",
                if hertz { "Hertz, rolling resistance" } else { "linear" },
                (a - b).abs() / b
            );
            assert!(contacts > 0 && cv[0] < 0.0 && cv[dim] > 0.0, "{dim}D: the grains collide");
            if p == Precision::F64 {
                assert!(ex < 1e-12 && ev < 1e-10, "{dim}D f64: {ex:e} {ev:e}");
                assert!(es < 1e-10 && spins < 1e-9 && springs < 1e-9, "{dim}D f64: {es:e} {spins:e} {springs:e}");
                assert!(el < 1e-2 && (a - b).abs() <= 1e-6 * b, "{dim}D f64: {el:e} {a} {b}");
            } else {
                assert!(ex < 1e-3 && ev < 1e-2 && es < 1e-2, "{dim}D f32: {ex:e} {ev:e} {es:e}");
            }
        }
    }

    #[test]
    fn device_dem_follows_the_cpu_scene() {
        let Some(gpu) = gpu() else { return };
        for hertz in [false, true] {
            follow::<DVec2>(&gpu, hertz);
            follow::<DVec3>(&gpu, hertz);
        }
    }

    /// The device's history loaded on the CPU and the CPU's on the device: both continue as
    /// the other would.
    fn cross<V: Vector>(gpu: &Arc<Gpu>) {
        let dim = V::DIM;
        let (x, v, r, m) = grains(dim);
        let rec = records(dim, true);
        let mut w = cpu_world::<V>(&x, &v, &r, &m, &rec, 1.0);
        let dt = w.particles().auto_dt().unwrap();
        w.set_dt(dt).unwrap();
        let Ok(mut dev) = device(gpu, Precision::F64, dim, (&x, &v, &r, &m), None, &rec) else {
            eprintln!("f64 skipped");
            return;
        };
        // Mid-collision of the pair (it touches from about step 70 on in 2D, 96 in 3D, for about
        // 70 steps), the sliding grain on the floor.
        let at = if dim == 2 { 90 } else { 130 };
        dev.steps(at, dt, &go()).unwrap();
        w.step(at).unwrap();
        // Device → CPU: a CPU world at the device's state and history.
        let (dx, dv) = dev_state(&dev);
        let hd = dev.term_history("grains").unwrap().unwrap();
        let mut w2 = cpu_world::<V>(&x, &v, &r, &m, &rec, dt);
        let vecs = |s: &[Real]| s.chunks(dim).map(V::from_slice).collect::<Vec<_>>();
        w2.particles_mut().set_state(Some(vecs(&dx)), Some(vecs(&dv))).unwrap();
        w2.particles_mut().set_term_history("grains", &hd).unwrap();
        assert_eq!(w2.particles().term_history("grains").unwrap().unwrap(), hd, "the CPU holds what the device gave");
        dev.steps(200, dt, &go()).unwrap();
        w2.step(200).unwrap();
        let (cx, _) = positions(&w2);
        let e1 = max_diff(&cx, &dev_state(&dev).0) / 3.0;
        // CPU → device: a new device from the CPU world's state and history.
        let (cx, cv) = positions(&w);
        let hc = w.particles().term_history("grains").unwrap().unwrap();
        let mut dev2 = device(gpu, Precision::F64, dim, (&cx, &cv, &r, &m), Some(&hc), &rec).unwrap();
        let back = dev2.term_history("grains").unwrap().unwrap();
        let (_, spins, springs, books) = compare_histories(&back, &hc, dim, true);
        assert!(spins == 0.0 && springs == 0.0 && books == 0.0, "the device holds what the CPU gave");
        dev2.steps(200, dt, &go()).unwrap();
        w.step(200).unwrap();
        let e2 = max_diff(&positions(&w).0, &dev_state(&dev2).0) / 3.0;
        let (n, ..) = compare_histories(&hc, &hd, dim, true);
        let pairs = parts(&hd, dim, true).2.iter().filter(|c| c.1 < m.len()).count();
        eprintln!(
            "{dim}D histories ({n} contacts, {pairs} between grains) crossed, 200 steps on: device → CPU {e1:.1e}, \
             CPU → device {e2:.1e} of the scene"
        );
        assert!(pairs > 0 && n > pairs && e1 < 1e-12 && e2 < 1e-12, "{dim}D: {n} {pairs} {e1:e} {e2:e}");
    }

    #[test]
    fn device_dem_history_crosses_to_the_cpu_and_back() {
        let Some(gpu) = gpu() else { return };
        cross::<DVec2>(&gpu);
        cross::<DVec3>(&gpu);
    }

    /// The contacts counter (`term_counts`, counted on the device) against the CPU term's,
    /// mid-collision (the pair and the grain on the floor) and once the pair has parted.
    fn counts<V: Vector>(gpu: &Arc<Gpu>) {
        let dim = V::DIM;
        let (x, v, r, m) = grains(dim);
        let rec = records(dim, false);
        let mut w = cpu_world::<V>(&x, &v, &r, &m, &rec, 1.0);
        let dt = w.particles().auto_dt().unwrap();
        w.set_dt(dt).unwrap();
        let Ok(mut dev) = device(gpu, Precision::F64, dim, (&x, &v, &r, &m), None, &rec) else {
            eprintln!("f64 skipped");
            return;
        };
        let mut done = 0;
        for at in [if dim == 2 { 90 } else { 130 }, 400] {
            dev.steps(at - done, dt, &go()).unwrap();
            w.step(at - done).unwrap();
            done = at;
            let cpu: Vec<_> = w.particles().term_counts().into_iter().filter(|c| c.1 == "contacts").collect();
            assert!(cpu.len() == 1 && cpu[0].2 > 0, "{dim}D after {at} steps: {cpu:?}");
            assert_eq!(dev.term_counts(), cpu, "{dim}D after {at} steps");
        }
    }

    #[test]
    fn device_dem_counts_its_contacts_as_the_cpu() {
        let Some(gpu) = gpu() else { return };
        counts::<DVec2>(&gpu);
        counts::<DVec3>(&gpu);
    }

    /// Everything the device keeps: its rows, the contacts' history, the energy report.
    fn all(d: &DeviceDem) -> (Arrays, Vec<Real>, Vec<Real>) {
        let e = d.energy();
        let books = [e.kinetic].into_iter().chain(e.potential.iter().chain(&e.dissipated).map(|p| p.1)).collect();
        (d.save().unwrap(), d.term_history("grains").unwrap().unwrap(), books)
    }

    #[test]
    fn device_dem_saves_loads_and_restores_bit_for_bit() {
        let Some(gpu) = gpu() else { return };
        for (dim, p) in [(2, Precision::F64), (3, Precision::F64), (2, Precision::F32)] {
            let (x, v, r, m) = grains(dim);
            let rec = records(dim, dim == 3);
            let Ok(mut dev) = device(&gpu, p, dim, (&x, &v, &r, &m), None, &rec) else {
                eprintln!("{p:?} skipped");
                continue;
            };
            let dt = dev.auto_dt().unwrap();
            dev.steps(250, dt, &go()).unwrap();
            // A load as the scene file's: a device built at the saved state (so another box)
            // and history, then given the rows.
            let (rows, h, _) = all(&dev);
            let (sx, sv) = dev_state(&dev);
            let mut other = device(&gpu, p, dim, (&sx, &sv, &r, &m), Some(&h), &rec).unwrap();
            assert!(other.params.lower != dev.params.lower, "the test loads into another box");
            other.load(&rows).unwrap();
            assert!(all(&other) == all(&dev), "{dim}D {p:?}: a load holds what was saved");
            dev.steps(150, dt, &go()).unwrap();
            other.steps(150, dt, &go()).unwrap();
            assert!(all(&other) == all(&dev), "{dim}D {p:?}: a loaded run continues bit for bit");
            // Snapshot and restore.
            let snap = dev.snapshot().unwrap();
            dev.steps(100, dt, &go()).unwrap();
            let a = all(&dev);
            dev.restore(snap);
            dev.steps(100, dt, &go()).unwrap();
            assert!(all(&dev) == a, "{dim}D {p:?}: restore then the same steps repeat the bits");
            // Rows of another length or not finite are refused, and nothing changes.
            let mut bad = rows.clone();
            bad[0].1[1] = Real::NAN;
            assert!(matches!(dev.load(&bad), Err(Error::InvalidInput { ref arg, .. }) if arg == "pos"));
            bad[0].1.pop();
            assert!(dev.load(&bad).is_err());
            assert!(all(&dev) == a);
            let contacts = parts(&h, dim, dim == 3).2.len();
            eprintln!("{dim}D {p:?}: saved with {contacts} contacts, loaded into another box, continued and restored bit for bit");
        }
    }

    /// Positions, velocities, radii, masses.
    type Grains = (Vec<Real>, Vec<Real>, Vec<Real>, Vec<Real>);

    /// `grains` with pegs: pinned grains under the colliding pair and in the oblique grain's
    /// way, one overlapping the floor and two overlapping each other (none of them may push);
    /// the flags.
    fn pegged(dim: usize) -> (Grains, Vec<bool>) {
        let (mut x, mut v, mut r, mut m) = grains(dim);
        let pegs: [([Real; 3], Real); 5] = [
            ([0.0, 0.15, 0.02], 0.07),
            ([2.62, 0.1, -0.02], 0.04),
            ([2.0, 0.03, 0.0], 0.05),
            ([3.0, 0.5, 0.0], 0.04),
            ([3.05, 0.5, 0.0], 0.04),
        ];
        for (p, q) in pegs {
            let p = if dim == 2 { p } else { [p[0], p[2], p[1]] };
            x.extend_from_slice(&p[..dim]);
            v.extend(std::iter::repeat_n(0.0, dim));
            r.push(q);
            m.push(1000.0 * q.powi(dim as i32));
        }
        let pinned = (0..m.len()).map(|i| i >= 6).collect();
        ((x, v, r, m), pinned)
    }

    /// A scene of grains with pegs (pinned grains) and a linear drag, its terms in two orders:
    /// the device follows the CPU world (positions, spins and springs, books under the same
    /// names in the same order, the step limit), the pegs never move, the contacts with them are
    /// in the history as the CPU's (pairs from their lower index), and a save and load continue
    /// bit for bit.
    fn pegs_and_drag<V: Vector>(gpu: &Arc<Gpu>, drag_first: bool) {
        let dim = V::DIM;
        let ((x, v, r, m), pinned) = pegged(dim);
        let mut rec = records(dim, dim == 3);
        let drag = ("drag".to_string(), "liquid".to_string(), Params::new().with("coefficient", Value::Number(2.0)));
        if drag_first {
            rec.insert(0, drag);
            rec.swap(1, 2); // drag, gravity, contacts
        } else {
            rec.push(drag); // contacts, gravity, drag
        }
        let roll = dim == 3;
        let mut w = cpu_world_pinned::<V>(&x, &v, &r, &m, &pinned, &rec, 1.0);
        let dt = w.particles().auto_dt().unwrap();
        w.set_dt(dt).unwrap();
        let steps = 700;
        // Some contacts with pegs, seen in the CPU's history along the way.
        let mut peg_contacts = 0;
        for _ in 0..7 {
            w.step(steps / 7).unwrap();
            let h = w.particles().term_history("grains").unwrap().unwrap();
            peg_contacts +=
                parts(&h, dim, roll).2.iter().filter(|c| c.1 < m.len() && (pinned[c.0] || pinned[c.1])).count();
        }
        let ce = w.energy();
        for p in [Precision::F64, Precision::F32] {
            let mut dev = match device_pinned(gpu, p, dim, (&x, &v, &r, &m), &pinned, None, &rec) {
                Ok(d) => d,
                Err(e) if p == Precision::F64 => {
                    eprintln!("f64 skipped: {e}");
                    continue;
                }
                Err(e) => panic!("{e}"),
            };
            let (a, b) = (dev.auto_dt().unwrap(), dt);
            assert!((a - b).abs() <= 1e-6 * b, "{dim}D step limits: device {a}, CPU {b}");
            let (x0, _) = dev_state(&dev);
            dev.steps(steps, dt, &go()).unwrap();
            let (cx, cv) = positions(&w);
            let (dx, dv) = dev_state(&dev);
            let de = dev.energy();
            let (es, el) = compare_energy(&ce, &de);
            let lost = |e: &EnergyReport| e.dissipated.iter().find(|q| q.0 == "liquid").unwrap().1;
            let ed = (lost(&ce) - lost(&de)).abs() / lost(&ce);
            let vmax = cv.iter().map(|u| u.abs()).fold(0.0, Real::max);
            let (ex, ev) = (max_diff(&cx, &dx) / 3.0, max_diff(&cv, &dv) / vmax);
            let hd = dev.term_history("grains").unwrap().unwrap();
            let hc = w.particles().term_history("grains").unwrap().unwrap();
            let (contacts, spins, springs, _) = compare_histories(&hd, &hc, dim, roll);
            let still = (0..m.len()).filter(|&i| pinned[i]).all(|i| {
                (0..dim).all(|a| dx[dim * i + a].to_bits() == x0[dim * i + a].to_bits() && dv[dim * i + a] == 0.0)
            });
            eprintln!(
                "{dim}D pegs and drag ({}) {p:?}, {steps} steps of {dt:.2e} s: positions {ex:.1e} of the scene, velocities \
                 {ev:.1e}; energy: state {es:.1e}, dissipated {el:.1e} of the total, drag's book {ed:.1e}; {contacts} contacts \
                 now, {peg_contacts} with pegs seen; spins {spins:.1e}, springs {springs:.1e}",
                if drag_first { "drag, gravity, contacts" } else { "contacts, gravity, drag" }
            );
            assert!(still, "{dim}D {p:?}: a peg moved");
            assert!(peg_contacts > 0 && lost(&ce) > 0.0, "{dim}D: grains met the pegs, drag dissipated");
            assert_eq!(entries(&de.dissipated)[0], "liquid", "the dissipating terms first, as on the CPU");
            if p == Precision::F64 {
                assert!(ex < 1e-12 && ev < 1e-10, "{dim}D f64: {ex:e} {ev:e}");
                assert!(es < 1e-10 && spins < 1e-9 && springs < 1e-9, "{dim}D f64: {es:e} {spins:e} {springs:e}");
                assert!(el < 1e-2 && ed < 1e-10, "{dim}D f64: {el:e} {ed:e}");
            } else {
                assert!(ex < 1e-3 && ev < 1e-2 && es < 1e-2, "{dim}D f32: {ex:e} {ev:e} {es:e}");
            }
            // A load as the scene file's continues bit for bit (the pegs' flags, the drag's
            // books in `hits`).
            let (rows, h, _) = all(&dev);
            let (sx, sv) = dev_state(&dev);
            let mut other = device_pinned(gpu, p, dim, (&sx, &sv, &r, &m), &pinned, Some(&h), &rec).unwrap();
            other.load(&rows).unwrap();
            assert!(all(&other) == all(&dev), "{dim}D {p:?}: a load holds what was saved");
            dev.steps(100, dt, &go()).unwrap();
            other.steps(100, dt, &go()).unwrap();
            assert!(all(&other) == all(&dev), "{dim}D {p:?}: a loaded run continues bit for bit");
        }
    }

    #[test]
    fn device_dem_holds_pegs_and_drag_as_the_cpu() {
        let Some(gpu) = gpu() else { return };
        for drag_first in [false, true] {
            pegs_and_drag::<DVec2>(&gpu, drag_first);
            pegs_and_drag::<DVec3>(&gpu, drag_first);
        }
    }

    #[test]
    fn device_dem_refuses_what_it_cannot_hold() {
        let Some(gpu) = gpu() else { return };
        let (x, v, r, m) = grains(2);
        let rec = records(2, false);
        let pinned = vec![false; 6];
        let arg_of = |e: Result<DeviceDem>| match e {
            Err(Error::InvalidInput { arg, msg }) => {
                eprintln!("refused: {arg}: {msg}");
                arg
            }
            Err(e) => panic!("another error: {e}"),
            Ok(_) => panic!("accepted"),
        };
        let with = |rec: &[(String, String, Params)],
                    integrator: &str,
                    pinned: &[bool],
                    radius: Option<&[Real]>,
                    colliders: &[(String, Params)]| {
            DeviceDem::from_records(
                gpu.clone(),
                "f32",
                "p",
                2,
                integrator,
                &x,
                &v,
                &m,
                pinned,
                radius,
                None,
                rec,
                colliders,
            )
        };
        let ok = Some(&r[..]);
        let mut twice = rec.clone();
        twice.push(("contacts".into(), "more".into(), rec[0].2.clone()));
        assert_eq!(arg_of(with(&twice, "semi_implicit_euler", &pinned, ok, &[])), "more");
        let mut springs = rec.clone();
        springs.push(("springs".into(), "links".into(), Params::new()));
        assert_eq!(arg_of(with(&springs, "semi_implicit_euler", &pinned, ok, &[])), "links");
        assert_eq!(arg_of(with(&rec[1..], "semi_implicit_euler", &pinned, ok, &[])), "terms");
        assert_eq!(arg_of(with(&rec, "xpbd", &pinned, ok, &[])), "integrator");
        // Pinned grains are held (`device_dem_holds_pegs_and_drag_as_the_cpu`); one flag each, and
        // a radius > 0 for them too.
        let mut pin = pinned.clone();
        pin[3] = true;
        assert!(with(&rec, "semi_implicit_euler", &pin, ok, &[]).is_ok());
        assert_eq!(arg_of(with(&rec, "semi_implicit_euler", &pin[1..], ok, &[])), "pinned");
        let mut r3 = r.clone();
        r3[3] = 0.0;
        assert_eq!(arg_of(with(&rec, "semi_implicit_euler", &pin, Some(&r3), &[])), "radius");
        // One drag term, of the drag term's own checks.
        let drag = |name: &str, b: Real| {
            ("drag".to_string(), name.to_string(), Params::new().with("coefficient", Value::Number(b)))
        };
        let mut dragged = rec.clone();
        dragged.insert(0, drag("liquid", 0.5));
        assert!(with(&dragged, "semi_implicit_euler", &pin, ok, &[]).is_ok());
        dragged.push(drag("more liquid", 0.5));
        assert_eq!(arg_of(with(&dragged, "semi_implicit_euler", &pinned, ok, &[])), "more liquid");
        let mut negative = rec.clone();
        negative.push(drag("liquid", -0.5));
        assert_eq!(arg_of(with(&negative, "semi_implicit_euler", &pinned, ok, &[])), "coefficient");
        assert_eq!(arg_of(with(&rec, "semi_implicit_euler", &pinned, None, &[])), "radius");
        let mut r0 = r.clone();
        r0[2] = 0.0;
        assert_eq!(arg_of(with(&rec, "semi_implicit_euler", &pinned, Some(&r0), &[])), "radius");
        let boxed = [("box".to_string(), Params::new())];
        assert_eq!(arg_of(with(&rec, "semi_implicit_euler", &pinned, ok, &boxed)), "colliders");
        let mut ball = rec.clone();
        ball[0].2.insert("wall_kinds", Value::Text("plane,sphere".into()));
        ball[0].2.insert("wall_params", Value::Floats(vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 5.0, 1.0]));
        ball[0].2.insert("wall_restitution", Value::Floats(vec![0.5, 0.5]));
        ball[0].2.insert("wall_friction", Value::Floats(vec![0.3, 0.3]));
        // Walls of every shape are held (`contacts::device_tests`); the CPU term's parser
        // refuses what it would refuse (an unknown shape, a bowl's radius of 0).
        assert!(with(&ball, "semi_implicit_euler", &pinned, ok, &[]).is_ok());
        let mut cone = ball.clone();
        cone[0].2.insert("wall_kinds", Value::Text("plane,cone".into()));
        assert_eq!(arg_of(with(&cone, "semi_implicit_euler", &pinned, ok, &[])), "walls");
        ball[0].2.insert("wall_params", Value::Floats(vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]));
        assert_eq!(arg_of(with(&ball, "semi_implicit_euler", &pinned, ok, &[])), "walls");
        // The contacts term's own checks, as on the CPU.
        let mut soft = rec.clone();
        soft[0].2.insert("stiffness", Value::Number(-1.0));
        assert_eq!(arg_of(with(&soft, "semi_implicit_euler", &pinned, ok, &[])), "stiffness");
        // Histories: of another term, or one that does not fit.
        let mut dev = with(&rec, "semi_implicit_euler", &pinned, ok, &[]).unwrap();
        let h = dev.term_history("grains").unwrap().unwrap();
        assert!(dev.term_history("earth").unwrap().is_none());
        assert!(
            matches!(dev.set_term_history("earth", &h), Err(Error::InvalidInput { ref arg, .. }) if arg == "earth")
        );
        let mut bad = h.clone();
        bad.extend_from_slice(&[0.0, 9.0, 0.0, 0.0, 0.0]);
        assert!(
            matches!(dev.set_term_history("grains", &bad), Err(Error::InvalidInput { ref arg, .. }) if arg == "history")
        );
        assert_eq!(dev.term_history("grains").unwrap().unwrap(), h, "nothing changed");
    }
}
