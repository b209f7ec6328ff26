//! A WCSPH fluid stepped on a GPU (`physcore_gpu::sph`) as a system of the world: what a scene
//! of one WCSPH fluid, a uniform gravity and a box becomes at `device="gpu"` (issue "GPU fluids,
//! grains and batches"). It stands in for the particle system under its name ("device
//! particles"), so the scene reads positions, velocities, densities and the books from it.
//!
//! What it holds: one fluid of equal-mass particles (every particle of the scene), its static
//! boundary particles (Akinci et al. 2012) if any, at most one `gravity` term, exactly one `box` collider (its walls
//! and the cells' extent), semi-implicit Euler (the CPU's WCSPH scheme). Anything else is refused
//! by name before anything moves (`from_records`).
//!
//! The state on the device is the positions and velocities alone (the cell list and the
//! densities are made afresh each step), so a checkpoint, a save and a load are those two read
//! back and sent again: a restart continues bit for bit. The dissipated books kept on the device
//! start from zero on a new upload; what was booked before is kept here (`base`) and added.
use super::{saved, Arrays, EnergyReport, Halt, Snapshot, System};
use crate::error::{invalid, Result};
use crate::terms::registry::Params;
use crate::vector::Real;
use physcore_gpu::sph::{Kernel, Sph, SphBooks, SphParams};
use physcore_gpu::{Gpu, Precision};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

/// The names the books go under: the fluid term's and the gravity term's (as on the CPU).
struct Names {
    fluid: String,
    gravity: Option<String>,
    /// Whether gravity's potential comes before the fluid's (the terms' order on the CPU).
    gravity_first: bool,
    /// Whether the fluid books a dissipation (α > 0, as the CPU's `Traits`).
    viscous: bool,
}

/// A checkpoint: the state read back and the books so far.
struct Saved {
    x: Vec<Real>,
    v: Vec<Real>,
    base: [Real; 2],
}

pub struct DeviceSph {
    name: String,
    gpu: Arc<Gpu>,
    precision: Precision,
    params: SphParams,
    walls: Vec<Real>,
    psi: Vec<Real>,
    names: Names,
    g: Mutex<Sph>,
    /// The viscous and collision books booked before the fluid now on the device was uploaded.
    base: [Real; 2],
}

/// The floats under `key` (a copy: the records stay as they are).
pub(super) fn floats(p: &Params, key: &str) -> Result<Vec<Real>> {
    p.try_clone("step")?.take_floats(key)
}

/// What a particle fluid on the device (WCSPH here, DFSPH in `device_dfsph`) takes from a
/// scene's records, checked alike for both.
pub(super) struct FluidRecords<'a> {
    /// The fluid term's name and record.
    pub fluid: (String, &'a Params),
    /// The gravity term's name, if any, and whether it comes before the fluid's.
    pub gravity: Option<String>,
    pub gravity_first: bool,
    /// Gravity (m/s², zero without the term), the particles' one mass (kg).
    pub g: [Real; 3],
    pub mass: Real,
    /// The Box collider's corners (m, z zero in 2D), restitution and friction.
    pub lower: [Real; 3],
    pub upper: [Real; 3],
    pub restitution: Real,
    pub friction: Real,
}

/// Checks that the records are one fluid of term `kind` ("sph", "dfsph"; `method` names it in
/// messages) holding every particle, of one mass, none pinned, at most one gravity term,
/// exactly one Box collider and semi-implicit Euler, and returns what the device takes.
/// Errors: `InvalidInput` naming what the device cannot hold.
pub(super) fn fluid_records<'a>(
    (method, kind): (&str, &str),
    dim: usize,
    integrator: &str,
    mass: &[Real],
    pinned: &[bool],
    terms: &'a [(String, String, Params)],
    colliders: &'a [(String, Params)],
) -> Result<FluidRecords<'a>> {
    let n = mass.len();
    let mut fluid = None;
    let mut gravity = None;
    let mut gravity_first = false;
    for (k, tname, p) in terms {
        if k == kind && fluid.is_none() {
            fluid = Some((tname.clone(), p));
        } else if k == "gravity" && gravity.is_none() {
            gravity_first = fluid.is_none();
            gravity = Some((tname.clone(), p));
        } else if k == kind || k == "gravity" {
            return Err(invalid(
                tname,
                format!("the GPU path's {method} holds one fluid and one gravity term; {tname:?} is a second {k:?}"),
            ));
        } else {
            return Err(invalid(
                tname,
                format!("the GPU path's {method} runs with a uniform gravity alone; it has no kernel for {k:?} beside a fluid"),
            ));
        }
    }
    let Some((fname, fp)) = fluid else {
        return Err(invalid("terms", format!("no {method} fluid to move")));
    };
    if integrator != "semi_implicit_euler" {
        return Err(invalid(
            "integrator",
            format!(
                "the GPU path's {method} steps by semi-implicit Euler (the CPU's scheme for it), not {integrator:?}"
            ),
        ));
    }
    let boxes: Vec<&Params> = colliders.iter().filter(|c| c.0 == "box").map(|c| &c.1).collect();
    if boxes.len() != 1 || colliders.len() != 1 {
        return Err(invalid(
            "colliders",
            format!(
                "the GPU path's {method} needs exactly one Box collider (its walls and the cells' extent) and no other"
            ),
        ));
    }
    let (first, count) = (fp.number("first")?, fp.number("n")?);
    if first != 0.0 || count as usize != n {
        return Err(invalid("particles", format!("the GPU path's {method} holds the fluid's particles alone")));
    }
    if pinned.iter().any(|&p| p) {
        return Err(invalid("pinned", format!("the GPU path's {method} has no pinned particles")));
    }
    let m = mass.first().copied().unwrap_or(1.0);
    if mass.iter().any(|&mi| mi != m) {
        return Err(invalid("masses", format!("the GPU path's {method} takes particles of one mass (the fluid's)")));
    }
    let three = |s: &[Real]| {
        let mut a = [0.0; 3];
        a[..dim].copy_from_slice(&s[..dim]);
        a
    };
    let g = match &gravity {
        Some((_, p)) => three(&floats(p, "g")?),
        None => [0.0; 3],
    };
    let b = boxes[0];
    Ok(FluidRecords {
        fluid: (fname, fp),
        gravity: gravity.map(|g| g.0),
        gravity_first,
        g,
        mass: m,
        lower: three(&floats(b, "lower")?),
        upper: three(&floats(b, "upper")?),
        restitution: b.number("restitution")?,
        friction: b.number("friction")?,
    })
}

impl DeviceSph {
    /// The scene's particles (`x`, `v`: flat, n·dim; `mass`, `pinned`), force terms and
    /// colliders (their records as added) as a device fluid on `gpu` at `precision` ("f32",
    /// "f64"), named `name`.
    ///
    /// Errors: `InvalidInput` naming what the device's WCSPH cannot hold (another term, a
    /// second fluid or gravity, DFSPH, no box or another collider, another integrator, pinned
    /// particles, particles outside the fluid or of another mass, a position outside the box,
    /// f64 on an adapter without it); `OutOfMemory` for device buffers.
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
        terms: &[(String, String, Params)],
        colliders: &[(String, Params)],
    ) -> Result<Self> {
        let precision = super::device::precision_of(precision)?;
        let r = fluid_records(("WCSPH", "sph"), dim, integrator, mass, pinned, terms, colliders)?;
        let (fname, fp) = r.fluid;
        let params = SphParams {
            dim,
            h: fp.number("h")?,
            mass: r.mass,
            rho0: fp.number("density")?,
            c0: fp.number("sound_speed")?,
            gamma: fp.number("gamma")? as u32,
            alpha: fp.number("viscosity")?,
            clamp: fp.flag("clamp_pressure")?,
            kernel: Kernel::by_name(fp.text("kernel")?)?,
            gravity: r.g,
            lower: r.lower,
            upper: r.upper,
            restitution: r.restitution,
            friction: r.friction,
        };
        let walls = floats(fp, "walls")?;
        let psi = floats(fp, "wall_psi")?;
        let names =
            Names { fluid: fname, gravity: r.gravity, gravity_first: r.gravity_first, viscous: params.alpha > 0.0 };
        let sph = Sph::with_walls(gpu.clone(), precision, params, x, v, &walls, &psi)?;
        Ok(Self {
            name: name.to_string(),
            gpu,
            precision,
            params,
            walls,
            psi,
            names,
            g: Mutex::new(sph),
            base: [0.0; 2],
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Sph> {
        self.g.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn books(&self) -> Result<SphBooks> {
        let mut b = self.lock().books()?;
        b.viscous += self.base[0];
        b.collisions += self.base[1];
        Ok(b)
    }

    /// A new upload of `x`, `v` with the books so far `base` (checkpoint, load).
    fn upload(&mut self, x: &[Real], v: &[Real], base: [Real; 2]) -> Result<()> {
        let sph = Sph::with_walls(self.gpu.clone(), self.precision, self.params, x, v, &self.walls, &self.psi)?;
        *self.g.get_mut().unwrap_or_else(|p| p.into_inner()) = sph;
        self.base = base;
        Ok(())
    }

    fn state(&self) -> Result<Saved> {
        let g = self.lock();
        let (x, v) = g.read_state()?;
        let (viscous, collisions) = g.dissipated()?;
        Ok(Saved { x, v, base: [viscous + self.base[0], collisions + self.base[1]] })
    }
}

impl System for DeviceSph {
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
        self.lock().step(n, dt, stop).map(|_| ()).map_err(super::device::halt_of)
    }
    /// The CPU's WCSPH step limit (`sph::fluid`'s `max_dt`): the CFL condition at the largest
    /// speed now and the force criterion at the last step's largest pressure and viscous
    /// acceleration plus |g| (both maxima reduced on the device, 16 bytes read back; none
    /// before the first step's acceleration is known, as on the CPU). A device that cannot be
    /// read gives no limit (its next step reports it).
    fn auto_dt(&self) -> Option<Real> {
        let (vmax, a2) = self.lock().extremes().ok()?;
        let p = &self.params;
        let cfl = crate::sph::resolve::wcsph_cfl(p.h, p.c0, p.alpha, vmax);
        let a = a2.sqrt() + p.gravity.iter().map(|c| c * c).sum::<Real>().sqrt();
        let force = if a > 0.0 { 0.25 * (p.h / a).sqrt() } else { Real::INFINITY };
        Some(cfl.min(force))
    }
    fn suggest_dt(&self) -> Option<Real> {
        self.auto_dt()
    }
    /// The CPU's books under the CPU's names and order: the potentials in the terms' order,
    /// the fluid's dissipation (if α > 0), then the walls' "collisions".
    fn energy(&self) -> EnergyReport {
        let b = self.books().unwrap_or(SphBooks {
            kinetic: Real::NAN,
            internal: Real::NAN,
            gravity: Real::NAN,
            viscous: Real::NAN,
            collisions: Real::NAN,
        });
        let mut r = EnergyReport { kinetic: b.kinetic, ..Default::default() };
        let fluid = (self.names.fluid.clone(), b.internal);
        match &self.names.gravity {
            Some(g) if self.names.gravity_first => r.potential.extend([(g.clone(), b.gravity), fluid]),
            Some(g) => r.potential.extend([fluid, (g.clone(), b.gravity)]),
            None => r.potential.push(fluid),
        }
        if self.names.viscous {
            r.dissipated.push((self.names.fluid.clone(), b.viscous));
        }
        r.dissipated.push(("collisions".to_string(), b.collisions));
        r
    }
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        // The density pass and its read only when a density or a pressure is asked for.
        let (x, v, rho) = if names.iter().any(|n| matches!(*n, "density" | "pressure")) {
            self.lock().read()?
        } else {
            let (x, v) = self.lock().read_state()?;
            (x, v, Vec::new())
        };
        let (d, n) = (self.params.dim, x.len() / self.params.dim);
        Ok(names
            .iter()
            .map(|name| {
                let (a, k) = match *name {
                    "mass" => return vec![self.params.mass; n],
                    "pinned" => return vec![0.0; n],
                    "density" => return rho.clone(),
                    "pressure" => return rho.iter().map(|&r| self.params.pressure(r)).collect(),
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
        Ok(Box::new(self.state()?))
    }
    fn restore(&mut self, snapshot: Snapshot) {
        if let Ok(s) = snapshot.downcast::<Saved>() {
            // A device that cannot take it back reports the failure at its next read.
            let _ = self.upload(&s.x, &s.v, s.base);
        }
    }
    /// The device particles' rows, as the scene file keeps them (`systems::device`): `pos` and
    /// `vel` (N × 4: position and mass, velocity and 1/mass), `acc` zero (nothing carried
    /// between steps), `aux` zero but for row 0 (the viscous and collision books so far),
    /// `hits` zero, `acc_valid` 1.
    fn save(&self) -> Result<Arrays> {
        let s = self.state()?;
        let (d, n, m) = (self.params.dim, s.x.len() / self.params.dim, self.params.mass);
        let rows = |a: &[Real], w: Real| {
            let mut out = vec![0.0; 4 * n];
            for i in 0..n {
                out[4 * i..4 * i + d].copy_from_slice(&a[d * i..d * (i + 1)]);
                out[4 * i + 3] = w;
            }
            out
        };
        // The mass as the device holds it (the scene checks the column against its masses so).
        let m = if self.precision == Precision::F32 { m as f32 as Real } else { m };
        let (pos, vel) = (rows(&s.x, m), rows(&s.v, 1.0 / m));
        let zero = vec![0.0; 4 * n];
        let mut aux = zero.clone();
        if n > 0 {
            aux[..2].copy_from_slice(&s.base);
        }
        let hits = vec![0.0; n];
        saved(
            "the device fluid",
            &[("pos", &pos), ("vel", &vel), ("acc", &zero), ("aux", &aux), ("hits", &hits), ("acc_valid", &[1.0])],
        )
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let (d, n) = (self.params.dim, self.lock().len());
        let pos = super::array(arrays, "pos", Some(4 * n))?;
        let vel = super::array(arrays, "vel", Some(4 * n))?;
        let aux = super::array(arrays, "aux", Some(4 * n))?;
        for (name, a) in [("pos", pos), ("vel", vel), ("aux", aux)] {
            if let Some(i) = a.iter().position(|c| !c.is_finite()) {
                return Err(invalid(name, format!("entry {i} is not finite")));
            }
        }
        let cols = |a: &[Real]| -> Vec<Real> { a.chunks_exact(4).flat_map(|r| r[..d].to_vec()).collect() };
        let base = if n > 0 { [aux[0], aux[1]] } else { [0.0; 2] };
        self.upload(&cols(pos), &cols(vel), base)
    }
}
