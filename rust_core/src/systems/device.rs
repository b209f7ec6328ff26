//! The device seam's first system: particles resident on a GPU (`physcore_gpu::particles`),
//! built from the same part records as the CPU's `ParticleSystem` (registry keys and `Params`)
//! and stepped, checkpointed and booked by the world as any system (docs/guide/architecture.md,
//! "How to add a backend").
//!
//! Also Gray–Scott and wave grids on the device (`DeviceGrayScott`, `DeviceWave`, from the CPU
//! system's configuration and state).
//!
//! What it holds: particles (positions, velocities, masses, pinned) under the terms `gravity`
//! (summed), `drag` (summed), one `pairwise_gravity` and one `springs` (cloth, chains: gathered
//! per particle, no atomics), with `semi_implicit_euler` or `verlet`.
//! Any other term kind or integrator is refused by name: nothing runs silently on the CPU.
use super::{Arrays, EnergyReport, Halt, Snapshot, System};
use crate::alloc::Need;
use crate::error::{invalid, Error, Failure, Result};
use crate::grids::gray_scott::GrayScottConfig;
use crate::grids::wave::{WaveConfig, WaveSystem};
use crate::grids::Edge;
use crate::terms::registry::Params;
use crate::vector::Real;
use physcore_gpu::gray_scott::{self as dg, GrayScott};
use physcore_gpu::particles::{self as dp, Collider, Forces, Particles, Scheme, Shape, Springs};
use physcore_gpu::wave::{self as dw, Wave};
use physcore_gpu::{Gpu, GpuError, Precision};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

impl From<GpuError> for Error {
    fn from(e: GpuError) -> Self {
        match e {
            GpuError::NoAdapter(m) => invalid("device", m),
            GpuError::Unsupported(m) => invalid("device", m),
            GpuError::OutOfMemory { what, bytes } => {
                Error::OutOfMemory { what: "device".into(), bytes, of: format!("the GPU buffer of {what}") }
            }
            GpuError::Device(m) => Error::Device { msg: m },
        }
    }
}

/// Names of the terms the books are kept under.
#[derive(Clone, Debug, Default)]
pub(crate) struct Names {
    gravity: Vec<String>,
    drag: Vec<String>,
    pairwise: Option<String>,
    coulomb: Option<String>,
    springs: Option<String>,
    /// Whether the springs have dashpots (the CPU books their dissipation only then).
    damped: bool,
    /// Whether there are colliders (their book is "collisions", as on the CPU).
    collisions: bool,
}

/// Particles on a GPU: a `System` whose state lives on the device.
pub struct DeviceParticles {
    name: String,
    dim: usize,
    names: Names,
    /// The masses as given (float64) and which particles are pinned: fixed, so kept here too
    /// (an f32 device holds rounded masses).
    mass: Vec<Real>,
    pinned: Vec<bool>,
    p: Mutex<Particles>,
}

/// The integrators the device has, by the core's names.
pub fn scheme_of(integrator: &str) -> Result<Scheme> {
    match integrator {
        "semi_implicit_euler" => Ok(Scheme::SemiImplicitEuler),
        "verlet" => Ok(Scheme::VelocityVerlet),
        "yoshida4" => Ok(Scheme::Yoshida4),
        other => Err(invalid(
            "integrator",
            format!("the GPU path has {other:?} not yet (it has \"semi_implicit_euler\", \"verlet\" and \"yoshida4\")"),
        )),
    }
}

/// The precision by name (`"f32"`, `"f64"`).
pub fn precision_of(name: &str) -> Result<Precision> {
    match name {
        "f32" => Ok(Precision::F32),
        "f64" => Ok(Precision::F64),
        other => Err(invalid("precision", format!("must be \"f32\" or \"f64\", got {other:?}"))),
    }
}

impl DeviceParticles {
    /// Particles on the device `which` (`"gpu"`, `"gpu:NAME"`: see `physcore_gpu::Gpu::open`).
    /// `x`, `v`: flat (n·dim; pinned particles get zero velocity); `mass` > 0; `pinned`; `terms`: (kind, name, params) records.
    ///
    /// Errors: `InvalidInput` naming `device`, `precision`, `integrator` or the term that the
    /// device cannot run; `OutOfMemory` for device buffers.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        which: &str,
        precision: &str,
        dim: usize,
        integrator: &str,
        x: &[Real],
        v: &[Real],
        mass: &[Real],
        pinned: &[bool],
        terms: &[(String, String, Params)],
        colliders: &[(String, Params)],
    ) -> Result<Self> {
        let gpu = Gpu::open(which)?;
        Self::on(gpu, precision, dim, integrator, x, v, mass, pinned, None, terms, colliders)
    }

    /// As `new`, on a device already open (one device serves every system of a scene).
    #[allow(clippy::too_many_arguments)]
    pub fn on(
        gpu: Arc<Gpu>,
        precision: &str,
        dim: usize,
        integrator: &str,
        x: &[Real],
        v: &[Real],
        mass: &[Real],
        pinned: &[bool],
        charge: Option<&[Real]>,
        terms: &[(String, String, Params)],
        colliders: &[(String, Params)],
    ) -> Result<Self> {
        if dim != 2 && dim != 3 {
            return Err(invalid("dim", format!("must be 2 or 3, got {dim}")));
        }
        let n = mass.len();
        if x.len() != n * dim || v.len() != n * dim || pinned.len() != n {
            return Err(invalid(
                "positions",
                "positions, velocities, masses and pinned must describe the same particles",
            ));
        }
        if let Some(i) = mass.iter().position(|m| !(m.is_finite() && *m > 0.0)) {
            return Err(invalid("masses", format!("entry {i} must be finite and > 0, got {}", mass[i])));
        }
        if let Some(i) = x.iter().chain(v).position(|c| !c.is_finite()) {
            return Err(invalid("positions", format!("value {i} of the positions and velocities is not finite")));
        }
        let (scheme, precision) = (scheme_of(integrator)?, precision_of(precision)?);
        if precision == Precision::F32 {
            // A value past f32's range became inf on the device, silently (or a divergence
            // that blamed dt); a mass whose reciprocal is past it, likewise.
            let over = |a: &[Real]| a.iter().position(|c| c.abs() > f32::MAX as Real);
            for (key, what, a) in
                [("positions", "position", x), ("velocities", "velocity", v), ("masses", "mass", mass)]
            {
                if let Some(i) = over(a) {
                    return Err(invalid(key, format!("{what} value {i} ({:e}) is past f32's range (precision=\"f32\" on the device; use \"f64\")", a[i])));
                }
            }
            if let Some(i) = mass.iter().zip(pinned).position(|(m, &p)| !p && (1.0 / m).abs() > f32::MAX as Real) {
                return Err(invalid("masses", format!("entry {i} ({:e}): its reciprocal is past f32's range (precision=\"f32\" on the device; use \"f64\")", mass[i])));
            }
            if let Some(i) = charge.and_then(over) {
                return Err(invalid(
                    "charge",
                    format!("value {i} is past f32's range (precision=\"f32\" on the device; use \"f64\")"),
                ));
            }
        }
        let (forces, springs, mut names) = forces_of(dim, n, terms)?;
        let colliders = colliders_of(dim, colliders)?;
        names.collisions = !colliders.is_empty();
        let im: Vec<Real> = mass.iter().zip(pinned).map(|(m, &p)| if p { 0.0 } else { 1.0 / m }).collect();
        // Pinned particles get zero velocity, as on the CPU (`ParticleSystem::add_particles`).
        let v: Vec<Real> = v.iter().enumerate().map(|(k, &c)| if pinned[k / dim] { 0.0 } else { c }).collect();
        let mut p = Particles::new(gpu, precision, dim, scheme, forces, x, &v, mass, &im, springs.as_ref())?;
        p.set_colliders(&colliders)?;
        if let Some(q) = charge {
            if q.len() != n || q.iter().any(|c| !c.is_finite()) {
                return Err(invalid("charge", "must be finite, one value per particle"));
            }
            p.set_charges(q)?;
        }
        // Beside the world's (empty) CPU particle system, which is "particles".
        Ok(Self {
            name: "device particles".into(),
            dim,
            names,
            mass: mass.to_vec(),
            pinned: pinned.to_vec(),
            p: Mutex::new(p),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Particles> {
        self.p.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Positions and velocities, flat (n·dim), read back.
    pub fn read(&self) -> Result<(Vec<Real>, Vec<Real>)> {
        Ok(self.lock().read()?)
    }

    /// The adapter it runs on and its precision, e.g. "NVIDIA H100 (vulkan, f32)".
    pub fn describe(&self) -> String {
        let p = self.lock();
        let a = p.gpu().adapter();
        format!("{} ({}, {})", a.name, a.backend, p.precision().name())
    }
}

/// The device's colliders from their records (kind, parameters), checked as the CPU's
/// constructors check them; kinds other than planes, boxes, spheres, capsules and oriented boxes are refused by name.
pub(crate) fn colliders_of(dim: usize, records: &[(String, Params)]) -> Result<Vec<Collider>> {
    let vec3 = |p: &Params, name: &str| -> Result<[f64; 3]> {
        let v = if dim == 2 {
            let v = p.vector::<glam::DVec2>(name)?;
            [v.x, v.y, 0.0]
        } else {
            p.vector::<glam::DVec3>(name)?.to_array()
        };
        if v.iter().any(|c| !c.is_finite()) {
            return Err(invalid(name, "must be finite"));
        }
        Ok(v)
    };
    records
        .iter()
        .map(|(kind, p)| {
            let contact = crate::constraints::Contact::new(p.number("restitution")?, p.number("friction")?)?;
            let (restitution, friction) = (contact.restitution, contact.friction);
            match kind.as_str() {
                "plane" => {
                    let (point, n) = (vec3(p, "point")?, vec3(p, "normal")?);
                    let l2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
                    if !(l2.is_finite() && l2 > 0.0) {
                        return Err(invalid("normal", "must be finite and non-zero"));
                    }
                    let l = l2.sqrt();
                    Ok(Collider { shape: Shape::Plane { point, normal: [n[0] / l, n[1] / l, n[2] / l] }, restitution, friction })
                }
                "box" => {
                    let (lower, upper) = (vec3(p, "lower")?, vec3(p, "upper")?);
                    if (0..dim).any(|k| !(upper[k] > lower[k])) {
                        return Err(invalid("upper", "must be > lower on every axis"));
                    }
                    Ok(Collider { shape: Shape::Box { lower, upper }, restitution, friction })
                }
                // Spheres and capsules checked by the CPU's constructors (in 3D: a 2D shape's z is 0).
                "sphere" => {
                    let (center, radius, inside) = (vec3(p, "center")?, p.number("radius")?, p.flag("inside")?);
                    crate::geometry::Ball::new(glam::DVec3::from_array(center), radius, inside)?;
                    Ok(Collider { shape: Shape::Sphere { center, radius, inside }, restitution, friction })
                }
                "capsule" => {
                    let (a, b, radius) = (vec3(p, "a")?, vec3(p, "b")?, p.number("radius")?);
                    crate::geometry::Capsule::new(glam::DVec3::from_array(a), glam::DVec3::from_array(b), radius)?;
                    Ok(Collider { shape: Shape::Capsule { a, b, radius }, restitution, friction })
                }
                "oriented_box" => {
                    // Built as the CPU builds it (its checks, and its axes from the rotation).
                    let (center, half, axes) = if dim == 2 {
                        let b = crate::geometry::OrientedBox::<glam::DVec2>::new(
                            p.vector("center")?,
                            p.vector("half_extents")?,
                            p.axial::<glam::DVec2>("rotation")?,
                        )?;
                        let ax = b.axes.map(|u| [u.x, u.y, 0.0]);
                        ([b.center.x, b.center.y, 0.0], b.half, ax)
                    } else {
                        let b = crate::geometry::OrientedBox::<glam::DVec3>::new(
                            p.vector("center")?,
                            p.vector("half_extents")?,
                            p.axial::<glam::DVec3>("rotation")?,
                        )?;
                        (b.center.to_array(), b.half, b.axes.map(|u| u.to_array()))
                    };
                    Ok(Collider { shape: Shape::OrientedBox { center, half, axes }, restitution, friction })
                }
                other => Err(invalid(
                    other,
                    format!(
                        "the GPU path has no {other:?} collider yet (it has planes, boxes, spheres, capsules and oriented boxes); run this scene on the CPU"
                    ),
                )),
            }
        })
        .collect()
}

/// The device's forces from term records, refusing kinds it has no kernel for.
pub(crate) fn forces_of(
    dim: usize,
    n: usize,
    terms: &[(String, String, Params)],
) -> Result<(Forces, Option<Springs>, Names)> {
    let mut f = Forces::default();
    let mut springs = None;
    let mut names = Names::default();
    for (kind, name, p) in terms {
        match kind.as_str() {
            "gravity" => {
                let g = if dim == 2 {
                    let g = p.vector::<glam::DVec2>("g")?;
                    [g.x, g.y, 0.0]
                } else {
                    p.vector::<glam::DVec3>("g")?.to_array()
                };
                for (k, c) in g.iter().enumerate() {
                    f.g[k] += c;
                }
                names.gravity.push(name.clone());
            }
            "drag" => {
                let b = p.number("coefficient")?;
                if b < 0.0 {
                    return Err(invalid("coefficient", format!("{b} must be finite and >= 0")));
                }
                f.drag += b;
                // As on the CPU, a drag of 0 dissipates nothing and has no entry in the books.
                if b > 0.0 {
                    names.drag.push(name.clone());
                }
            }
            "pairwise_gravity" => {
                if names.pairwise.is_some() {
                    return Err(invalid(name, "the GPU path holds one pairwise_gravity term"));
                }
                let (g, eps) = (p.number("G")?, p.number("softening")?);
                if g <= 0.0 {
                    return Err(invalid("G", format!("{g} must be finite and > 0")));
                }
                if eps < 0.0 {
                    return Err(invalid("softening", format!("{eps} must be finite and >= 0")));
                }
                f.pairwise = Some((g, eps));
                names.pairwise = Some(name.clone());
            }
            "coulomb" => {
                if names.coulomb.is_some() {
                    return Err(invalid(name, "the GPU path holds one coulomb term"));
                }
                let (k, eps) = (p.number("k")?, p.number("softening")?);
                if k <= 0.0 {
                    return Err(invalid("k", format!("{k} must be finite and > 0")));
                }
                if eps < 0.0 {
                    return Err(invalid("softening", format!("{eps} must be finite and >= 0")));
                }
                f.coulomb = Some((k, eps));
                names.coulomb = Some(name.clone());
            }
            "springs" => {
                if names.springs.is_some() {
                    return Err(invalid(name, "the GPU path holds one springs term (join them into one)"));
                }
                let mut p = p.try_clone("step")?;
                let (i, j) = (p.take_indices("i")?, p.take_indices("j")?);
                let (k, c, rest) =
                    (p.take_floats("stiffness")?, p.take_floats("damping")?, p.take_floats("rest_length")?);
                let m = i.len();
                if j.len() != m || k.len() != m || c.len() != m || rest.len() != m {
                    return Err(invalid(
                        name,
                        "i, j, stiffness, damping and rest_length must have one entry per spring",
                    ));
                }
                if let Some(s) = (0..m).find(|&s| i[s] as usize >= n || j[s] as usize >= n || i[s] == j[s]) {
                    return Err(invalid(
                        "i",
                        format!("spring {s} joins {} and {} (particles 0..{n}, two different)", i[s], j[s]),
                    ));
                }
                if let Some(s) = (0..m)
                    .find(|&s| !(k[s] >= 0.0 && c[s] >= 0.0 && rest[s] >= 0.0 && (k[s] + c[s] + rest[s]).is_finite()))
                {
                    return Err(invalid(
                        name,
                        format!("spring {s}: stiffness, damping and rest_length must be finite and >= 0"),
                    ));
                }
                names.damped = c.iter().any(|&c| c > 0.0);
                springs = Some(Springs { i, j, k, c, rest });
                names.springs = Some(name.clone());
            }
            other => {
                return Err(invalid(
                    name,
                    format!(
                        "the GPU path has no kernel for {other:?} yet (it has gravity, drag, pairwise_gravity, \
                         coulomb and springs); run this scene on the CPU (device=\"cpu\")"
                    ),
                ))
            }
        }
    }
    Ok((f, springs, names))
}

/// The device's own checkpoint is kept on the device; the world's snapshot only marks it.
struct Mark;

/// A device's halt after `done` steps as the world's (the particles and the WCSPH fluid alike).
pub(crate) fn halt_of((done, h): (u64, dp::Halt)) -> (u64, Halt) {
    match h {
        dp::Halt::Stopped => (done, Halt::Stopped),
        dp::Halt::Diverged { particle } => (done, Halt::Diverged { index: particle, quantity: Failure::Position }),
        // A device failure reads as a divergence of particle 0: the world rolls back to its
        // checkpoint (kept on the device, or lost with it: see `restore`).
        dp::Halt::Failed(_) => (done, Halt::Diverged { index: 0, quantity: Failure::Position }),
    }
}

impl System for DeviceParticles {
    fn name(&self) -> &str {
        &self.name
    }
    fn is_empty(&self) -> bool {
        self.lock().is_empty()
    }
    fn size(&self) -> usize {
        self.lock().len()
    }
    fn step(&mut self, dt: Real, stop: &AtomicBool) -> std::result::Result<(), Halt> {
        self.steps(1, dt, stop).map_err(|(_, h)| h)
    }
    fn steps(&mut self, n: u64, dt: Real, stop: &AtomicBool) -> std::result::Result<(), (u64, Halt)> {
        self.lock().step(n, dt, stop).map(|_| ()).map_err(halt_of)
    }
    fn auto_dt(&self) -> Option<Real> {
        None
    }
    fn suggest_dt(&self) -> Option<Real> {
        None
    }
    fn energy(&self) -> EnergyReport {
        // A device that cannot be read gives NaN books (the world's checks see them).
        let b = self.lock().books().unwrap_or(dp::Books {
            kinetic: Real::NAN,
            uniform: Real::NAN,
            pairwise: Real::NAN,
            dissipated: Real::NAN,
            springs: Real::NAN,
            dashpots: Real::NAN,
            collisions: Real::NAN,
            coulomb: Real::NAN,
        });
        let mut r = EnergyReport { kinetic: b.kinetic, ..Default::default() };
        // The summed uniform field's potential is booked under the first gravity term's name.
        if let Some(g) = self.names.gravity.first() {
            r.potential.push((g.clone(), b.uniform));
        }
        if let Some(p) = &self.names.pairwise {
            r.potential.push((p.clone(), b.pairwise));
        }
        if let Some(s) = &self.names.springs {
            r.potential.push((s.clone(), b.springs));
        }
        if let Some(c) = &self.names.coulomb {
            r.potential.push((c.clone(), b.coulomb));
        }
        if let Some(d) = self.names.drag.first() {
            r.dissipated.push((d.clone(), b.dissipated));
        }
        if let (Some(s), true) = (&self.names.springs, self.names.damped) {
            r.dissipated.push((s.clone(), b.dashpots));
        }
        if self.names.collisions {
            r.dissipated.push(("collisions".to_string(), b.collisions));
        }
        r
    }
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        // Masses and pins are kept on the host: read the device back only for the state.
        // Each buffer only if asked for (a million particles' positions: one 16 MB read).
        let want_x = names.iter().any(|n| matches!(*n, "x" | "y" | "z"));
        let want_v = names.iter().any(|n| matches!(*n, "vx" | "vy" | "vz"));
        let x = if want_x { self.lock().read_one(false)? } else { Vec::new() };
        let v = if want_v { self.lock().read_one(true)? } else { Vec::new() };
        let (d, n) = (self.dim, self.mass.len());
        Ok(names
            .iter()
            .map(|name| {
                let (a, k) = match *name {
                    "mass" => return self.mass.clone(),
                    "pinned" => return self.pinned.iter().map(|&p| p as u8 as Real).collect(),
                    "x" => (&x, 0),
                    "y" => (&x, 1),
                    "z" if d == 3 => (&x, 2),
                    "vx" => (&v, 0),
                    "vy" => (&v, 1),
                    "vz" if d == 3 => (&v, 2),
                    _ => return vec![0.0; n],
                };
                a.chunks_exact(d).map(|c| c[k]).collect()
            })
            .collect())
    }
    fn snapshot(&self) -> Result<Snapshot> {
        self.lock().snapshot()?;
        Ok(Box::new(Mark))
    }
    fn restore(&mut self, _snapshot: Snapshot) {
        // A lost device cannot be restored: its next read reports the failure.
        let _ = self.lock().restore();
    }
    fn save(&self) -> Result<Arrays> {
        // Raw device rows (vec4: position and mass, velocity and 1/mass, acceleration, drag
        // books) and whether the accelerations are current: a restart repeats bit for bit.
        let ([pos, vel, acc, aux], hits, valid) = self.lock().save_raw()?;
        Ok(vec![
            ("pos".into(), pos),
            ("vel".into(), vel),
            ("acc".into(), acc),
            ("aux".into(), aux),
            ("hits".into(), hits),
            ("acc_valid".into(), vec![valid as u8 as Real]),
        ])
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let n = self.lock().len();
        let mut raw: [Vec<Real>; 4] = Default::default();
        for (k, name) in ["pos", "vel", "acc", "aux"].iter().enumerate() {
            let a = super::array(arrays, name, Some(4 * n))?;
            if let Some(i) = a.iter().position(|c| !c.is_finite()) {
                return Err(invalid(name, format!("entry {i} is not finite")));
            }
            raw[k] = a.to_vec();
        }
        if let Some(i) = (0..n).find(|&i| !(raw[0][4 * i + 3] > 0.0) || raw[1][4 * i + 3] < 0.0) {
            return Err(invalid("pos", format!("particle {i}: mass must be > 0 and 1/mass >= 0")));
        }
        let valid = super::array(arrays, "acc_valid", Some(1))?[0];
        if valid != 0.0 && valid != 1.0 {
            return Err(invalid("acc_valid", format!("must be 0 or 1, got {valid}")));
        }
        let hits = super::array(arrays, "hits", Some(n))?;
        if let Some(i) = hits.iter().position(|c| !c.is_finite()) {
            return Err(invalid("hits", format!("entry {i} is not finite")));
        }
        Ok(self.lock().load_raw(&raw, hits, valid == 1.0)?)
    }
}

/// Gray–Scott reaction–diffusion on a GPU (`physcore_gpu::gray_scott`): the CPU system's step
/// (`grids::gray_scott`) cell for cell, its books (amounts and what the reactions made) and its
/// fields, with the state on the device. Periodic and free faces, 2D and 3D.
///
/// Measured against the CPU path (tests, lavapipe): f64 bit-identical fields after 25 steps
/// (the same order of operations, no fused multiply–adds); f32 within 2e-7 of the fields (of
/// order 1) and 2e-7 relative in the books.
pub struct DeviceGrayScott {
    cfg: GrayScottConfig,
    /// `GrayScottConfig::stability_limit` of the fields as moved: the reactions' bound takes at
    /// least 1, which holds while u, v stay in [0, 1] as the reactions keep them (no read-back
    /// per call).
    limit: Real,
    g: Mutex<GrayScott>,
    /// What the reactions made before the fields came to the device (u's, v's; moved or
    /// loaded), kept on the host in f64: the device's per-workgroup slots start from zero and
    /// `made` adds them to it. One f32 slot holding a saved total lost its low bits, and the
    /// additions to it more.
    base: [Real; 2],
}

impl DeviceGrayScott {
    /// The system `cfg` with fields `u`, `v` (one value per cell) and what the reactions made so
    /// far (`made`: u's, v's, in the CPU's units), on `gpu` at `precision` ("f32", "f64").
    ///
    /// Errors: `InvalidInput` naming `precision` or `device` (f64 on an adapter without it,
    /// a grid over its limits); `OutOfMemory` for device buffers.
    pub fn on(
        gpu: Arc<Gpu>,
        precision: &str,
        cfg: GrayScottConfig,
        u: &[Real],
        v: &[Real],
        made: [Real; 2],
    ) -> Result<Self> {
        cfg.validate()?;
        let g = &cfg.grid;
        let cells = g.cells();
        if u.len() != cells || v.len() != cells {
            return Err(invalid("u", format!("u and v must have one value per cell ({cells})")));
        }
        if cells > u32::MAX as usize / 2 {
            return Err(invalid("shape", format!("{cells} cells: the GPU path indexes at most 2^31 cells")));
        }
        let mut free = [false; 6];
        for (f, e) in g.edges.iter().enumerate().take(2 * g.dim) {
            free[f] = *e == Edge::Free;
        }
        let model =
            dg::Model { n: g.n, dim: g.dim, dx: g.dx, free, du: cfg.du, dv: cfg.dv, feed: cfg.feed, kill: cfg.kill };
        let limit = cfg.stability_limit(u, v);
        let dev = GrayScott::new(gpu, precision_of(precision)?, model, u, v, [0.0; 2])?;
        Ok(Self { cfg, limit, g: Mutex::new(dev), base: made })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, GrayScott> {
        self.g.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// u and v read back.
    pub fn read(&self) -> Result<(Vec<Real>, Vec<Real>)> {
        Ok(self.lock().read()?)
    }

    fn made(&self) -> Result<[Real; 2]> {
        let m = self.lock().made()?;
        let da = self.cfg.grid.cell_measure();
        Ok([self.base[0] + m[0] * da, self.base[1] + m[1] * da])
    }
}

impl System for DeviceGrayScott {
    fn name(&self) -> &str {
        &self.cfg.name
    }
    fn is_empty(&self) -> bool {
        false
    }
    fn size(&self) -> usize {
        self.cfg.grid.cells()
    }
    fn step(&mut self, dt: Real, stop: &AtomicBool) -> std::result::Result<(), Halt> {
        self.steps(1, dt, stop).map_err(|(_, h)| h)
    }
    fn steps(&mut self, n: u64, dt: Real, stop: &AtomicBool) -> std::result::Result<(), (u64, Halt)> {
        let mut g = self.lock();
        g.step(n, dt, stop).map(|_| ()).map_err(|(done, h)| match h {
            dg::Halt::Stopped => (done, Halt::Stopped),
            dg::Halt::Diverged { cell } => (done, Halt::Diverged { index: cell, quantity: Failure::Cell }),
            // A failed device reads as a divergence: the world rolls back (see DeviceParticles).
            dg::Halt::Failed(_) => (done, Halt::Diverged { index: 0, quantity: Failure::Cell }),
        })
    }
    fn auto_dt(&self) -> Option<Real> {
        Some(self.cfg.cfl * self.limit)
    }
    fn suggest_dt(&self) -> Option<Real> {
        Some(self.cfg.cfl * self.limit)
    }
    fn energy(&self) -> EnergyReport {
        EnergyReport::default()
    }
    /// As the CPU system's: amounts Σu dA, Σv dA (summed on the host in f64, row by row) and
    /// what the reactions made. NaN if the device cannot be read.
    fn books(&self) -> Vec<(String, Real)> {
        let da = self.cfg.grid.cell_measure();
        let nx = self.cfg.grid.n[0];
        let sum = |a: &[Real]| a.chunks(nx).map(|r| r.iter().sum::<Real>()).sum::<Real>() * da;
        let (amounts, made) = match (self.read(), self.made()) {
            (Ok((u, v)), Ok(m)) => ([sum(&u), sum(&v)], m),
            _ => ([Real::NAN; 2], [Real::NAN; 2]),
        };
        vec![
            ("u".to_string(), amounts[0]),
            ("v".to_string(), amounts[1]),
            ("u_made".to_string(), made[0]),
            ("v_made".to_string(), made[1]),
        ]
    }
    fn set_field(&mut self, name: &str, values: &[Real]) -> Result<()> {
        let n = self.size();
        if !matches!(name, "u" | "v") {
            return Err(invalid("field", format!("{name:?}: Gray–Scott's settable fields are \"u\" and \"v\"")));
        }
        if values.len() != n {
            return Err(invalid(name, format!("has {} values, the grid has {n} cells", values.len())));
        }
        if let Some(i) = crate::grids::first_non_finite(values) {
            return Err(invalid(name, format!("cell {i} is not finite: {}", values[i])));
        }
        let g = self.lock();
        Ok(if name == "u" { g.set_fields(Some(values), None) } else { g.set_fields(None, Some(values)) }?)
    }
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let (u, v) = self.read()?;
        Ok(names
            .iter()
            .map(|n| match *n {
                "u" => u.clone(),
                "v" => v.clone(),
                _ => vec![0.0; u.len()],
            })
            .collect())
    }
    fn snapshot(&self) -> Result<Snapshot> {
        self.lock().snapshot()?;
        Ok(Box::new(Mark))
    }
    fn restore(&mut self, _snapshot: Snapshot) {
        let _ = self.lock().restore();
    }
    /// The CPU system's arrays (u, v, made): a file saved from the device loads on the CPU.
    fn save(&self) -> Result<Arrays> {
        let (u, v) = self.read()?;
        let m = self.made()?;
        Ok(vec![("u".to_string(), u), ("v".to_string(), v), ("made".to_string(), m.to_vec())])
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let n = self.size();
        let (u, v, m) = (
            super::array(arrays, "u", Some(n))?,
            super::array(arrays, "v", Some(n))?,
            super::array(arrays, "made", Some(2))?,
        );
        for (name, a) in [("u", u), ("v", v), ("made", m)] {
            if let Some(i) = crate::grids::first_non_finite(a) {
                return Err(invalid(name, format!("value {i} is not finite: {}", a[i])));
            }
        }
        let g = self.lock();
        g.set_fields(Some(u), Some(v))?;
        g.set_made([0.0; 2])?;
        drop(g);
        self.base = [m[0], m[1]];
        Ok(())
    }
}

/// The damped wave equation on a GPU (`physcore_gpu::wave`): the CPU system's leapfrog step
/// (`grids::wave`) cell for cell, with its faces, damping layers, obstacles and oscillators, the
/// fields resident on the device. A CPU copy of the system (`Tended::host`) keeps the
/// configuration and the clock and does what happens seldom, on the fields read back and sent
/// again: a drop, a change of dt, the energies, reading and setting fields, save and load (it
/// holds u and u⁻ on the host too: 16 bytes a cell).
///
/// Measured against the CPU path (`a_device_wave_steps_and_books_as_the_cpu_one`, lavapipe,
/// 325 steps from a noisy start, a change of dt among them): f64 bit-identical fields (the same
/// order of operations, no fused multiply–adds) with every face rule, a damping layer, a wall,
/// an oscillator and drops, in 2D and 3D, and the books within 2e-15 relative (other summation
/// orders); f32 within 2e-5 (u) and 4e-5 (velocity) of each field's largest value, the energy
/// books within 1e-5 relative.
pub struct DeviceWave {
    name: String,
    cells: usize,
    /// `WaveSystem::auto_dt` (the CFL limit's fraction: fixed by the configuration).
    auto: Option<Real>,
    t: Mutex<Tended>,
}

struct Tended {
    host: WaveSystem,
    /// The damping's and the sources' books (J per unit density) when the host's fields were
    /// last sent to the device: the device's books count from there.
    base: [Real; 2],
    dev: Wave,
}

impl Tended {
    /// The host's fields and books made the device's (read back).
    fn pull(&mut self) -> Result<()> {
        let (u, up) = self.dev.read()?;
        let books = self.dev.books()?;
        let da = self.host.config().grid.cell_measure();
        let (hu, hup) = self.host.levels_mut();
        (*hu, *hup) = (u, up);
        let mut c = self.host.clock_values();
        c[2] = self.base[0] + books[0] * da;
        c[3] = self.base[1] + books[1] * da;
        self.host.set_clock_values(c);
        Ok(())
    }

    /// The device's fields made the host's, its books counting from the host's (after `pull`
    /// and a change on the host). Refuses a value an f32 device cannot hold (`within_range`);
    /// nothing is sent then.
    fn push(&mut self) -> Result<()> {
        let c = self.host.clock_values();
        let (u, up) = self.host.levels_mut();
        within_range(self.dev.precision(), u, up)?;
        self.dev.set_fields(u, up)?;
        self.dev.clear_books()?;
        self.base = [c[2], c[3]];
        Ok(())
    }
}

impl DeviceWave {
    /// The wave system `cfg` with the state `saved` (what the CPU system's `save` wrote), on
    /// `gpu` at `precision` ("f32", "f64").
    ///
    /// Errors: `InvalidInput` naming `precision` or `device` (f64 on an adapter without it, a
    /// grid over its limits) or a saved array; `OutOfMemory` for host or device buffers.
    pub fn on(gpu: Arc<Gpu>, precision: &str, cfg: WaveConfig, saved: &Arrays) -> Result<Self> {
        let precision = precision_of(precision)?;
        let g = &cfg.grid;
        let cells = g.cells();
        if cells > u32::MAX as usize / 2 {
            return Err(invalid("shape", format!("{cells} cells: the GPU path indexes at most 2^31 cells")));
        }
        let face = |e: Edge| match e {
            Edge::Fixed => dw::Face::Fixed,
            Edge::Free => dw::Face::Free,
            Edge::Periodic => dw::Face::Periodic,
        };
        let mut faces = [dw::Face::Free; 6];
        for (f, e) in g.edges.iter().enumerate().take(2 * g.dim) {
            faces[f] = face(*e);
        }
        let oscillators = cfg
            .oscillators
            .iter()
            .map(|o| dw::Oscillator {
                amplitude: o.amplitude,
                frequency: o.frequency,
                phase: o.phase,
                profile: o.profile.clone(),
            })
            .collect();
        let (name, n, dim, dx, c, gamma) = (cfg.name.clone(), g.n, g.dim, g.dx, cfg.c, cfg.gamma);
        let mut host = WaveSystem::new(cfg)?;
        host.load(saved)?;
        let (gamma_cells, keep) = host.coefficients();
        // Copies for the upload, asked of the allocator (a grid's arrays abort the process where
        // an infallible copy is refused under a memory cap).
        let need =
            Need::new("step", Need::bytes_of::<Real>(gamma_cells.len() + keep.len()), "a wave grid's layers and wall");
        let model = dw::Model {
            n,
            dim,
            dx,
            faces,
            c,
            gamma,
            gamma_cells: need.copy(gamma_cells)?,
            keep: need.copy(keep)?,
            oscillators,
        };
        let clock = host.clock_values();
        let (u, up) = host.levels_mut();
        within_range(precision, u, up)?;
        let dev = Wave::new(gpu, precision, model, u, up)?;
        let auto = host.auto_dt();
        Ok(Self { name, cells, auto, t: Mutex::new(Tended { host, base: [clock[2], clock[3]], dev }) })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Tended> {
        self.t.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Refuses, naming "u", a wave's value an f32 device cannot hold (it would turn inf there
/// silently, or read as a divergence).
fn within_range(precision: Precision, u: &[Real], up: &[Real]) -> Result<()> {
    if precision == Precision::F32 {
        let over = |a: &[Real]| a.iter().position(|x| x.abs() > f32::MAX as Real);
        if let Some(i) = over(u).or_else(|| over(up)) {
            return Err(invalid(
                "u",
                format!("cell {i} holds a value past f32's range (precision=\"f32\" on the device; use \"f64\")"),
            ));
        }
    }
    Ok(())
}

/// The clock and the books' base of a `DeviceWave` at a checkpoint (its fields stay on the device).
struct WaveMark([Real; 6], [Real; 2]);

impl System for DeviceWave {
    fn name(&self) -> &str {
        &self.name
    }
    fn is_empty(&self) -> bool {
        false
    }
    fn size(&self) -> usize {
        self.cells
    }
    fn step(&mut self, dt: Real, stop: &AtomicBool) -> std::result::Result<(), Halt> {
        self.steps(1, dt, stop).map_err(|(_, h)| h)
    }
    /// As the CPU system's `steps`: a change of dt and each drop as it falls due are done on the
    /// host (the fields read back and sent again); the steps between run on the device.
    fn steps(&mut self, n: u64, dt: Real, stop: &AtomicBool) -> std::result::Result<(), (u64, Halt)> {
        let failed = |i: u64| move |_| (i, Halt::Diverged { index: 0, quantity: Failure::Cell });
        let mut g = self.lock();
        let w = &mut *g;
        if dt != w.host.clock_values()[1] {
            w.pull().map_err(failed(0))?;
            w.host.change_dt(dt);
            w.push().map_err(failed(0))?;
        }
        let mut i = 0;
        while i < n {
            let t = w.host.clock_values()[0];
            if w.host.next_drop_time().is_some_and(|d| d < t + dt) {
                w.pull().map_err(failed(i))?;
                w.host.drop_due(dt);
                w.push().map_err(failed(i))?;
            }
            // The steps before the next drop falls due, as the CPU's `drop_due` sees each
            // (the clock added up one step at a time); at most 2^20 at once.
            let mut k = (n - i).min(1 << 20);
            if let Some(d) = w.host.next_drop_time() {
                let (mut j, mut tj) = (1, t);
                while j < k {
                    tj += dt;
                    if d < tj + dt {
                        break;
                    }
                    j += 1;
                }
                k = j;
            }
            let result = w.dev.step(k, dt, t, stop);
            let done = match &result {
                Ok(done) => *done,
                Err((done, _)) => *done,
            };
            let mut c = w.host.clock_values();
            for _ in 0..done {
                c[0] += dt;
            }
            w.host.set_clock_values(c);
            if let Err((done, h)) = result {
                return Err((
                    i + done,
                    match h {
                        dw::Halt::Stopped => Halt::Stopped,
                        dw::Halt::Diverged { cell } => Halt::Diverged { index: cell, quantity: Failure::Cell },
                        // A failed device reads as a divergence: the world rolls back (see DeviceParticles).
                        dw::Halt::Failed(_) => Halt::Diverged { index: 0, quantity: Failure::Cell },
                    },
                ));
            }
            i += done;
        }
        Ok(())
    }
    fn auto_dt(&self) -> Option<Real> {
        self.auto
    }
    fn suggest_dt(&self) -> Option<Real> {
        self.auto
    }
    /// The CPU system's books from the fields read back (NaN if the device cannot be read).
    fn energy(&self) -> EnergyReport {
        let mut g = self.lock();
        match g.pull() {
            Ok(()) => g.host.energy(),
            Err(_) => EnergyReport { kinetic: Real::NAN, ..Default::default() },
        }
    }
    fn set_field(&mut self, name: &str, values: &[Real]) -> Result<()> {
        let mut g = self.lock();
        g.pull()?;
        g.host.set_field(name, values)?;
        g.push()
    }
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let mut g = self.lock();
        g.pull()?;
        g.host.fields(names)
    }
    fn snapshot(&self) -> Result<Snapshot> {
        let mut g = self.lock();
        g.dev.snapshot()?;
        Ok(Box::new(WaveMark(g.host.clock_values(), g.base)))
    }
    fn restore(&mut self, snapshot: Snapshot) {
        let mut g = self.lock();
        let _ = g.dev.restore();
        if let Ok(m) = snapshot.downcast::<WaveMark>() {
            g.host.set_clock_values(m.0);
            g.base = m.1;
        }
    }
    /// The CPU system's arrays: a file saved from the device loads on the CPU.
    fn save(&self) -> Result<Arrays> {
        let mut g = self.lock();
        g.pull()?;
        g.host.save()
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let mut g = self.lock();
        // The range first: a refused load changes nothing (the host's clock included).
        let n = self.cells;
        within_range(g.dev.precision(), super::array(arrays, "u", Some(n))?, super::array(arrays, "u_prev", Some(n))?)?;
        g.host.load(arrays)?;
        g.push()
    }
}

#[cfg(test)]
mod tests {
    //! The device system inside a world against the CPU path (skipped where no adapter is found,
    //! unless PHYSCORE_GPU_REQUIRED=1; CI runs them on lavapipe with PHYSCORE_GPU_ALLOW_CPU=1).
    use super::*;
    use crate::systems::particles::ParticleSystem;
    use crate::terms::registry::{self, Context, Value};
    use crate::world::World;
    use glam::DVec3;

    fn which() -> Option<&'static str> {
        let w = if physcore_gpu::cpu_allowed_by_env() { "gpu" } else { "gpu:lavapipe" };
        match Gpu::open(w) {
            Ok(_) => Some(w),
            Err(e) if std::env::var("PHYSCORE_GPU_REQUIRED").as_deref() == Ok("1") => panic!("no adapter: {e}"),
            Err(e) => {
                eprintln!("skipped: {e}");
                None
            }
        }
    }

    fn terms() -> Vec<(String, String, Params)> {
        vec![
            ("gravity".into(), "gravity".into(), Params::new().with("g", Value::Floats(vec![0.0, 0.0, -9.81]))),
            ("drag".into(), "drag".into(), Params::new().with("coefficient", Value::Number(0.2))),
            (
                "pairwise_gravity".into(),
                "nbody".into(),
                Params::new().with("G", Value::Number(1e-3)).with("softening", Value::Number(0.05)),
            ),
        ]
    }

    fn cloud(n: usize) -> (Vec<Real>, Vec<Real>, Vec<Real>, Vec<bool>) {
        let x = (0..3 * n).map(|i| ((i * 7919) % 1000) as Real / 1000.0 - 0.5).collect();
        let v = (0..3 * n).map(|i| ((i * 104729) % 1000) as Real / 1e4 - 0.05).collect();
        let m = (0..n).map(|i| 0.5 + (i % 7) as Real / 7.0).collect();
        let p = (0..n).map(|i| i % 50 == 0).collect();
        (x, v, m, p)
    }

    #[test]
    fn a_device_world_steps_as_the_cpu_world() {
        for integrator in ["verlet", "yoshida4"] {
            world_against_cpu(integrator);
        }
    }

    fn world_against_cpu(integrator: &str) {
        let Some(w) = which() else { return };
        let n = 400;
        let (x, v, m, pinned) = cloud(n);
        let mut cpu = ParticleSystem::<DVec3>::new(integrator).unwrap();
        let xs: Vec<DVec3> = x.chunks(3).map(DVec3::from_slice).collect();
        let vs: Vec<DVec3> = v.chunks(3).map(DVec3::from_slice).collect();
        cpu.add_particles(xs, vs, m.clone(), pinned.clone()).unwrap();
        let ctx = Context { n_particles: n };
        for (kind, name, p) in terms() {
            cpu.add_term(registry::lookup(&kind).unwrap().build::<DVec3>(name, p, &ctx).unwrap()).unwrap();
        }
        let mut cw = World::new(cpu, 1e-3, Some(1)).unwrap();
        let e0 = cw.energy();
        cw.step(100).unwrap();
        let (cx, e1) = (cw.particles().state().x.clone(), cw.energy());
        let drift = |a: &EnergyReport, b: &EnergyReport| (b.total() - a.total()).abs();
        for precision in ["f32", "f64"] {
            let d = match DeviceParticles::new(w, precision, 3, integrator, &x, &v, &m, &pinned, &terms(), &[]) {
                Ok(d) => d,
                Err(e) if precision == "f64" => {
                    eprintln!("f64 skipped: {e}");
                    continue;
                }
                Err(e) => panic!("{e}"),
            };
            let mut dw = World::new(ParticleSystem::<DVec3>::new(integrator).unwrap(), 1e-3, Some(1)).unwrap();
            dw.add_system(Box::new(d)).unwrap();
            let d0 = dw.energy();
            dw.step(100).unwrap();
            let d1 = dw.energy();
            let f = dw.other("device particles").unwrap().fields(&["x", "y", "z"]).unwrap();
            let err = (0..n).map(|i| (DVec3::new(f[0][i], f[1][i], f[2][i]) - cx[i]).length()).fold(0.0, Real::max);
            let dev = drift(&d0, &d1);
            eprintln!(
                "{integrator} {precision}: device vs CPU after 100 steps: positions {err:.2e} m; books' drift: CPU {:.2e} J, device {dev:.2e} J (of {:.3} J)",
                drift(&e0, &e1),
                e0.total()
            );
            let (tol_x, tol_e) = if precision == "f32" { (1e-5, 1e-5) } else { (1e-12, 1e-9) };
            assert!(err < tol_x, "{precision}: {err}");
            // The books keep the CPU's names, and the device's total drifts no more than f32 allows.
            let names = |e: &EnergyReport| {
                (
                    e.potential.iter().map(|p| p.0.clone()).collect::<Vec<_>>(),
                    e.dissipated.iter().map(|p| p.0.clone()).collect::<Vec<_>>(),
                )
            };
            assert_eq!(names(&e1), names(&d1));
            assert!(
                (d1.total() - e1.total()).abs() < tol_e * e0.total().abs().max(1.0),
                "{precision}: {d1:?} vs {e1:?}"
            );
            assert!(dev < drift(&e0, &e1) + tol_e * e0.total().abs().max(1.0), "{precision}: device drift {dev}");
        }
    }

    #[test]
    fn the_device_takes_the_cpu_yoshida_weights() {
        assert_eq!(physcore_gpu::particles::YOSHIDA_W1, crate::integrators::yoshida::W1);
        assert_eq!(physcore_gpu::particles::YOSHIDA_W0, crate::integrators::yoshida::W0);
    }

    #[test]
    fn a_restart_repeats_bit_for_bit_and_unknown_parts_are_refused() {
        let Some(w) = which() else { return };
        let (x, v, m, pinned) = cloud(300);
        let mut a = DeviceParticles::new(w, "f32", 3, "verlet", &x, &v, &m, &pinned, &terms(), &[]).unwrap();
        let no = AtomicBool::new(false);
        a.steps(10, 1e-3, &no).unwrap();
        let saved = a.save().unwrap();
        a.steps(10, 1e-3, &no).unwrap();
        let mut b = DeviceParticles::new(w, "f32", 3, "verlet", &x, &v, &m, &pinned, &terms(), &[]).unwrap();
        b.load(&saved).unwrap();
        b.steps(10, 1e-3, &no).unwrap();
        assert_eq!(a.read().unwrap(), b.read().unwrap());
        // Rollback through the world's snapshot.
        let snap = a.snapshot().unwrap();
        let before = a.read().unwrap();
        a.steps(5, 1e-3, &no).unwrap();
        a.restore(snap);
        assert_eq!(a.read().unwrap(), before);
        let tree = vec![("tree_gravity".to_string(), "tree".to_string(), Params::new())];
        let e = DeviceParticles::new(w, "f32", 3, "verlet", &x, &v, &m, &pinned, &tree, &[]).err().unwrap();
        assert!(e.to_string().starts_with("tree: the GPU path has no kernel for \"tree_gravity\""), "{e}");
        // Every registered collider has a kernel: a kind the device does not know is refused
        // by name, and a collider's own parameters are checked by name.
        let contact = Params::new().with("restitution", Value::Number(0.5)).with("friction", Value::Number(0.0));
        let torus = vec![("torus".to_string(), contact.clone())];
        let e = DeviceParticles::new(w, "f32", 3, "verlet", &x, &v, &m, &pinned, &terms(), &torus).err().unwrap();
        assert!(e.to_string().contains("no \"torus\" collider"), "{e}");
        let sphere = vec![("sphere".to_string(), contact)];
        let e = DeviceParticles::new(w, "f32", 3, "verlet", &x, &v, &m, &pinned, &terms(), &sphere).err().unwrap();
        assert!(e.to_string().starts_with("center:"), "{e}");
        let e = DeviceParticles::new(w, "f32", 3, "rk4", &x, &v, &m, &pinned, &terms(), &[]).err().unwrap();
        assert!(e.to_string().starts_with("integrator:"), "{e}");
    }

    #[test]
    fn a_device_gray_scott_grid_steps_and_books_as_the_cpu_one() {
        use crate::grids::build;
        use crate::grids::gray_scott::GrayScottSystem;
        let Some(w) = which() else { return };
        let gpu = Gpu::open(w).unwrap();
        for (shape, edges) in [
            (vec![96.0, 80.0], "periodic,periodic,free,free"),
            (vec![12.0, 10.0, 9.0], "free,free,periodic,periodic,free,free"),
        ] {
            let dim = shape.len();
            let params = Params::new()
                .with("shape", Value::Floats(shape.clone()))
                .with("spacing", Value::Number(0.01))
                .with("edges", Value::Text(edges.into()))
                .with("du", Value::Number(2e-5))
                .with("dv", Value::Number(1e-5))
                .with("feed", Value::Number(0.035))
                .with("kill", Value::Number(0.065))
                .with("cfl", Value::Number(0.8));
            let cfg = build::gray_scott_config("gs", dim, params).unwrap();
            let mut cpu = GrayScottSystem::new(cfg.clone()).unwrap();
            let n = cfg.grid.cells();
            let u: Vec<Real> = (0..n).map(|c| 1.0 - 0.5 * ((c * 7919) % 101) as Real / 101.0).collect();
            let v: Vec<Real> = (0..n).map(|c| 0.25 * ((c * 104729) % 97) as Real / 97.0).collect();
            cpu.set_state(Some(&u), Some(&v)).unwrap();
            let no = AtomicBool::new(false);
            let dt = cpu.auto_dt().unwrap();
            for precision in ["f32", "f64"] {
                let mut d = match DeviceGrayScott::on(gpu.clone(), precision, cfg.clone(), &u, &v, [0.0, 0.0]) {
                    Ok(d) => d,
                    Err(e) if precision == "f64" => {
                        eprintln!("f64 skipped: {e}");
                        continue;
                    }
                    Err(e) => panic!("{e}"),
                };
                assert_eq!(d.auto_dt(), cpu.auto_dt());
                let mut c = GrayScottSystem::new(cfg.clone()).unwrap();
                c.set_state(Some(&u), Some(&v)).unwrap();
                c.steps(40, dt, &no).unwrap();
                d.steps(40, dt, &no).unwrap();
                let (du, dv) = d.read().unwrap();
                let err =
                    du.iter().zip(c.u()).chain(dv.iter().zip(c.v())).map(|(a, b)| (a - b).abs()).fold(0.0, Real::max);
                let (cb, db) = (c.books(), d.books());
                eprintln!("{shape:?} {precision}: fields {err:.1e}; books CPU {cb:?} device {db:?}");
                let tol = if precision == "f32" { 1e-5 } else { 1e-13 };
                assert!(err < tol, "{precision}: fields differ by {err}");
                for ((name, a), (dname, b)) in cb.iter().zip(&db) {
                    assert_eq!(name, dname);
                    assert!((a - b).abs() <= tol * a.abs().max(1e-3), "{precision} {name}: {a} vs {b}");
                }
                // What the CPU saves, the device loads (and the other way), and steps on alike.
                let saved = c.save().unwrap();
                d.load(&saved).unwrap();
                let back = d.save().unwrap();
                assert_eq!(back[2].1.len(), 2);
                c.load(&back).unwrap();
            }
        }
    }

    /// A wave's parameters as the Python layer passes them: `shape`, `edges`, damping γ, the
    /// absorbing faces, a wall with a slit (`walled`), one oscillator, drops at `drops` s.
    fn wave_params(
        shape: &[Real],
        edges: &str,
        gamma: Real,
        absorbing: &[Real],
        walled: bool,
        drops: &[Real],
    ) -> Params {
        let n: usize = shape.iter().map(|&s| s as usize).product();
        let nx = shape[0] as usize;
        let mut p = Params::new()
            .with("shape", Value::Floats(shape.to_vec()))
            .with("spacing", Value::Number(0.02))
            .with("edges", Value::Text(edges.into()))
            .with("c", Value::Number(1.3))
            .with("damping", Value::Number(gamma))
            .with("cfl", Value::Number(0.9))
            .with("layer", Value::Number(6.0))
            .with("layer_strength", Value::Number(0.5))
            .with("absorbing", Value::Floats(absorbing.to_vec()));
        if walled {
            // A wall across x at a third of the way, with a slit of 4 cells.
            let mask = (0..n).map(|c| ((c % nx == nx / 3) && ((c / nx) % 10 > 3)) as u8 as Real).collect();
            p = p.with("mask", Value::Floats(mask));
        }
        let k = drops.len();
        let cells: Vec<u32> = (0..k).flat_map(|d| (0..9).map(move |j| ((37 + 13 * d + j * 5) % n) as u32)).collect();
        p = p
            .with("drop_t", Value::Floats(drops.to_vec()))
            .with("drop_amplitude", Value::Floats(vec![0.01; k]))
            .with("drop_counts", Value::Floats(vec![9.0; k]))
            .with("drop_weights", Value::Floats((0..9 * k).map(|j| 0.3 + 0.07 * j as Real).collect()))
            .with("drop_cells", Value::Indices(cells));
        // One oscillator on four cells, two of them the same (entries add in order).
        let osc = vec![(n / 2) as u32, (n / 2 + 1) as u32, (n / 2 + 1) as u32, (n / 3) as u32];
        p.with("osc_amplitude", Value::Floats(vec![40.0]))
            .with("osc_frequency", Value::Floats(vec![3.0]))
            .with("osc_phase", Value::Floats(vec![0.4]))
            .with("osc_counts", Value::Floats(vec![4.0]))
            .with("osc_weights", Value::Floats(vec![1.0, 0.5, 0.25, 0.8]))
            .with("osc_cells", Value::Indices(osc))
    }

    #[test]
    fn a_device_wave_steps_and_books_as_the_cpu_one() {
        use crate::grids::build;
        let Some(w) = which() else { return };
        let gpu = Gpu::open(w).unwrap();
        // On a CPU adapter (lavapipe) f64 runs the CPU's operations bit for bit.
        let exact = gpu.adapter().kind == "cpu";
        let no = AtomicBool::new(false);
        for (shape, edges, gamma, absorbing, walled, drops) in [
            // Damping, a layer, a wall with a slit, every face rule, an oscillator and drops.
            (vec![70.0, 50.0], "fixed,free,periodic,periodic", 0.3, vec![0.0, 1.0, 0.0, 0.0], true, vec![0.01, 0.2]),
            // Undamped, no layer or wall (the CPU fuses these steps; their bits are single steps').
            (vec![64.0, 40.0], "free,fixed,fixed,free", 0.0, vec![0.0; 4], false, vec![0.05]),
            (
                vec![14.0, 12.0, 10.0],
                "free,fixed,fixed,free,periodic,periodic",
                0.1,
                vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                false,
                vec![0.03],
            ),
        ] {
            let dim = shape.len();
            let params = wave_params(&shape, edges, gamma, &absorbing, walled, &drops);
            let cfg = build::wave_config("wave", dim, params).unwrap();
            let mut cpu = WaveSystem::new(cfg.clone()).unwrap();
            let n = cfg.grid.cells();
            let (_, keep) = cpu.coefficients();
            let keep = keep.to_vec();
            let u: Vec<Real> = (0..n)
                .map(|c| {
                    if keep.is_empty() || keep[c] != 0.0 {
                        0.01 * (((c * 7919) % 101) as Real / 101.0 - 0.5)
                    } else {
                        0.0
                    }
                })
                .collect();
            cpu.set_state(&u, None).unwrap();
            let dt = cpu.auto_dt().unwrap();
            let start = cpu.save().unwrap();
            // Each precision with the kernels' blocks of 4 rows (these grids' own) and of 16 (a
            // large grid's: the GPU crate's grid::rows_for).
            for (precision, threads) in [("f32", 1 << 19), ("f64", 1 << 19), ("f32", 1), ("f64", 1)] {
                physcore_gpu::set_grid_threads_for_tests(threads);
                let mut d = match DeviceWave::on(gpu.clone(), precision, cfg.clone(), &start) {
                    Ok(d) => d,
                    Err(e) if precision == "f64" => {
                        eprintln!("f64 skipped: {e}");
                        continue;
                    }
                    Err(e) => panic!("{e}"),
                };
                assert_eq!(d.auto_dt(), cpu.auto_dt());
                let mut c = WaveSystem::new(cfg.clone()).unwrap();
                c.load(&start).unwrap();
                // 300 steps in calls of 1, 7 and the rest (drops fall due inside them), then 25
                // at another dt.
                for (k, h) in [(1, dt), (7, dt), (292, dt), (25, 0.7 * dt)] {
                    c.steps(k, h, &no).unwrap();
                    d.steps(k, h, &no).unwrap();
                }
                let names = ["u", "velocity"];
                let (cf, df) = (c.fields(&names).unwrap(), d.fields(&names).unwrap());
                let max = |a: &[Real]| a.iter().fold(0.0, |m: Real, x| m.max(x.abs()));
                let diff = |a: &[Real], b: &[Real]| a.iter().zip(b).map(|(a, b)| (a - b).abs()).fold(0.0, Real::max);
                // Each field's largest difference relative to its largest value.
                let rel = [diff(&cf[0], &df[0]) / max(&cf[0]), diff(&cf[1], &df[1]) / max(&cf[1])];
                let scale = max(&cf[0]);
                let (ce, de) = (c.energy(), d.energy());
                eprintln!(
                    "{shape:?} {precision}: u, velocity {:.1e}, {:.1e} of their largest values; total CPU {} device {}; books {:?} / {:?}",
                    rel[0],
                    rel[1],
                    ce.total(),
                    de.total(),
                    ce.dissipated,
                    de.dissipated
                );
                assert!(scale > 1e-3, "the waves move");
                if precision == "f64" && exact {
                    assert!(rel == [0.0, 0.0], "f64: the fields differ by {rel:?}");
                } else if precision == "f64" {
                    // A GPU's compiler fuses a·b + c into one rounding (and may round a division
                    // otherwise): the last bits differ from the CPU's (the H200: 2.6e-16 of the
                    // largest u after 100 steps at 4096²).
                    assert!(rel[0] < 1e-12 && rel[1] < 1e-12, "f64: the fields differ by {rel:?}");
                } else {
                    assert!(rel[0] < 1e-4 && rel[1] < 1e-4, "f32: the fields differ by {rel:?}");
                }
                let tol = if precision == "f32" { 1e-4 } else { 1e-12 };
                assert!((ce.kinetic - de.kinetic).abs() <= tol * ce.kinetic.abs(), "{precision}: kinetic");
                for ((na, a), (nb, b)) in ce.dissipated.iter().zip(&de.dissipated) {
                    assert_eq!(na, nb);
                    assert!((a - b).abs() <= tol * a.abs().max(1e-9), "{precision} {na}: {a} vs {b}");
                }
                // A checkpoint and a rollback on the device, then the state the CPU saved loads and
                // steps on alike.
                let before = d.fields(&["u"]).unwrap();
                let mark = d.snapshot().unwrap();
                d.steps(5, dt, &no).unwrap();
                d.restore(mark);
                assert!(d.fields(&["u"]).unwrap() == before, "restore");
                let saved = c.save().unwrap();
                d.load(&saved).unwrap();
                c.steps(9, dt, &no).unwrap();
                d.steps(9, dt, &no).unwrap();
                let (cu, du) = (c.fields(&["u"]).unwrap(), d.fields(&["u"]).unwrap());
                let err = diff(&cu[0], &du[0]) / max(&cu[0]);
                let tol = if precision == "f32" {
                    1e-4
                } else if exact {
                    0.0
                } else {
                    1e-12
                };
                assert!(err <= tol, "{precision}: after load {err}");
                assert_eq!(d.save().unwrap().len(), saved.len());
            }
        }
    }
}
