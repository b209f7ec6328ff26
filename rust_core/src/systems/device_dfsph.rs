//! A DFSPH fluid stepped on a GPU (`physcore_gpu::dfsph`) as a system of the world: what a
//! scene of one DFSPH fluid (`Fluid(method="dfsph")`), a uniform gravity and a box becomes at
//! `device="gpu"` (issue "GPU fluids, grains and batches"). As `device_sph` does for WCSPH, it
//! stands in for the particle system under its name ("device particles").
//!
//! What it holds: one DFSPH fluid of equal-mass particles (every particle of the scene), its
//! static boundary particles (Akinci et al. 2012) if any, at most one `gravity` term, exactly
//! one `box` collider, semi-implicit Euler (the CPU's DFSPH scheme); its surface tension and
//! adhesion (Akinci et al. 2013) with the CPU's coefficients (`sph::surface::Surface`). Not on
//! the device (refused by name before anything moves): several fluids, other terms.
//!
//! The state on the device is the positions, the velocities and the solvers' warm starts with
//! the last step's pressure (the CPU term's own state, `OwnState::history`: 3 values a
//! particle). The warm starts travel as the CPU's term history (`term_history`), so a scene file
//! written on the device continues on the CPU and the other way round; the device rows of the
//! file (`save`: positions, velocities, the books so far) continue bit for bit on the device.
use super::device_sph::{floats, fluid_records};
use super::{saved, Arrays, EnergyReport, Halt, HeldTerms, Snapshot, System};
use crate::error::{invalid, Result};
use crate::sph::dfsph::{relaxation, smoothing};
use crate::sph::surface::Surface;
use crate::sph::KernelKind;
use crate::terms::registry::Params;
use crate::vector::Real;
use physcore_gpu::dfsph::{Dfsph, DfsphParams};
use physcore_gpu::sph::Kernel;
use physcore_gpu::{Gpu, Precision};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

/// The names the books go under: the fluid term's and the gravity term's (as on the CPU).
struct Names {
    fluid: String,
    gravity: Option<String>,
    /// Whether gravity's potential comes before the fluid's (the terms' order on the CPU).
    gravity_first: bool,
}

/// What the solver counted before the fluid now on the device was uploaded (a restore or a
/// load makes a new upload, whose counters start from zero): kept here and added.
#[derive(Clone, Copy, Default)]
struct Base {
    /// The fluid's dissipated energy (both solves and the viscosity) and the box's, J.
    books: [Real; 2],
    steps: u64,
    density_iterations: u64,
    divergence_iterations: u64,
    unconverged: u64,
    /// The largest final mean errors of the solves (density, divergence).
    error_max: [Real; 2],
}

/// A checkpoint: the state, the warm starts and the books read back.
struct Saved {
    x: Vec<Real>,
    v: Vec<Real>,
    history: Vec<Real>,
    base: Base,
}

pub struct DeviceDfsph {
    name: String,
    gpu: Arc<Gpu>,
    precision: Precision,
    params: DfsphParams,
    /// The CPU term's CFL number λ (its step limit; the device does not use it).
    cfl: Real,
    /// The capillary step limit (`Surface::max_dt`), s; infinite without surface forces.
    capillary: Real,
    walls: Vec<Real>,
    psi: Vec<Real>,
    names: Names,
    g: Mutex<Dfsph>,
    base: Base,
}

impl DeviceDfsph {
    /// The scene's particles (`x`, `v`: flat, n·dim; `mass`, `pinned`), the CPU fluid term's
    /// history at the move (`history`: 3n values, `None` for zeros), its force terms and
    /// colliders (their records as added) as a device fluid on `gpu` at `precision` ("f32",
    /// "f64"), named `name`.
    ///
    /// Errors: `InvalidInput` naming what the device's DFSPH cannot hold (another term, a
    /// second fluid or gravity, no box or another collider, another
    /// integrator, pinned particles, particles outside the fluid or of another mass, a position
    /// outside the box, f64 on an adapter without it); `OutOfMemory` for device buffers.
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
        history: Option<&[Real]>,
        terms: &[(String, String, Params)],
        colliders: &[(String, Params)],
    ) -> Result<Self> {
        let precision = super::device::precision_of(precision)?;
        let r = fluid_records(("DFSPH", "dfsph"), dim, integrator, mass, pinned, terms, colliders)?;
        let (fname, fp) = r.fluid;
        let iterations = fp.number("max_iterations")?;
        if iterations.fract() != 0.0 || !(1.0..=100_000.0).contains(&iterations) {
            return Err(invalid("max_iterations", format!("expected a whole number in 1..=100000, got {iterations}")));
        }
        // The CPU's own coefficients of Akinci et al. (2013), from the fluid's σ and adhesion.
        let (h, rho0) = (fp.number("h")?, fp.number("density")?);
        let (sigma, adhesion) = (fp.number("surface_tension")?, fp.number("adhesion")?);
        let surface = Surface::new(sigma, adhesion, h, rho0, dim, smoothing(fp)?);
        let params = DfsphParams {
            dim,
            h,
            mass: r.mass,
            rho0,
            alpha: fp.number("viscosity")?,
            c0: fp.number("sound_speed")?,
            kernel: Kernel::by_name(fp.text("kernel")?)?,
            // The CPU term's own relaxation (`sph::dfsph::relaxation`), so both solve alike.
            relaxation: relaxation(dim, KernelKind::by_name(fp.text("kernel")?)?, smoothing(fp)?),
            density_tol: fp.number("density_error")?,
            divergence_tol: fp.number("divergence_error")?,
            max_iterations: iterations as u32,
            gravity: r.g,
            lower: r.lower,
            upper: r.upper,
            restitution: r.restitution,
            friction: r.friction,
            cohesion: surface.gamma,
            cohesion_norm: surface.norm,
            curvature: surface.c,
            adhesion: surface.beta,
        };
        let walls = floats(fp, "walls")?;
        let psi = floats(fp, "wall_psi")?;
        let names = Names { fluid: fname, gravity: r.gravity, gravity_first: r.gravity_first };
        let mut dfsph = Dfsph::with_walls(gpu.clone(), precision, params, x, v, &walls, &psi)?;
        if let Some(h) = history {
            dfsph.set_history(h)?;
        }
        Ok(Self {
            name: name.to_string(),
            gpu,
            precision,
            params,
            cfl: fp.number("cfl")?,
            capillary: Surface::max_dt(sigma, adhesion, rho0, h),
            walls,
            psi,
            names,
            g: Mutex::new(dfsph),
            base: Base::default(),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Dfsph> {
        self.g.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// What the solver counted so far: the device's since its upload plus `base`.
    fn counted(&self) -> Result<Base> {
        let g = self.lock();
        let b = g.books()?;
        let (it, e) = (g.iterations(), g.errors()?);
        let base = &self.base;
        Ok(Base {
            books: [b.divergence + b.density + b.viscous + base.books[0], b.collisions + base.books[1]],
            steps: base.steps + it.steps,
            density_iterations: base.density_iterations + it.total_density,
            divergence_iterations: base.divergence_iterations + it.total_divergence,
            unconverged: base.unconverged + it.unconverged,
            error_max: [base.error_max[0].max(e.density_max), base.error_max[1].max(e.divergence_max)],
        })
    }

    /// A new upload of `x`, `v` and the warm starts `history` with what was counted so far
    /// `base` (checkpoint, load).
    fn upload(&mut self, x: &[Real], v: &[Real], history: &[Real], base: Base) -> Result<()> {
        let mut d = Dfsph::with_walls(self.gpu.clone(), self.precision, self.params, x, v, &self.walls, &self.psi)?;
        d.set_history(history)?;
        *self.g.get_mut().unwrap_or_else(|p| p.into_inner()) = d;
        self.base = base;
        Ok(())
    }

    /// The warm starts and pressure, in the CPU term's layout (3n).
    fn history(&self) -> Result<Vec<Real>> {
        let g = self.lock();
        let (kappa, kappa_v) = g.warm_starts()?;
        let mut h = kappa;
        h.extend(kappa_v);
        h.extend(g.pressure()?);
        Ok(h)
    }

    fn state(&self) -> Result<Saved> {
        let (x, v) = self.lock().read_state()?;
        Ok(Saved { x, v, history: self.history()?, base: self.counted()? })
    }
}

impl System for DeviceDfsph {
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
    /// As the CPU's: the step limit follows the flow, so `advance` takes it before every substep.
    fn limit_follows_flow(&self) -> bool {
        true
    }
    /// The CPU term's step limit (`Dfsph::max_dt`): the flow's CFL condition λ h/|v|max at the
    /// speeds now (|v|max reduced on the device, 16 bytes read back), the explicit viscosity's
    /// limit, gravity's force criterion and the capillary limit. A device that cannot be read
    /// gives no limit (its next step reports it).
    fn auto_dt(&self) -> Option<Real> {
        let vmax = self.lock().max_speed().ok()?;
        let d = self.params.dim;
        let g = self.params.gravity.iter().map(|c| c * c).sum::<Real>().sqrt();
        let p = &self.params;
        let dt = crate::sph::dfsph::max_dt(self.cfl, p.h, d, p.alpha, p.c0, vmax, g)
            .unwrap_or(Real::INFINITY)
            .min(self.capillary);
        dt.is_finite().then_some(dt)
    }
    fn suggest_dt(&self) -> Option<Real> {
        self.auto_dt()
    }
    /// The CPU's books under the CPU's names and order: the potentials in the terms' order (the
    /// incompressible fluid's is 0), the fluid's dissipation (both solves and the viscosity),
    /// then the box's "collisions".
    fn energy(&self) -> EnergyReport {
        let (kinetic, gravity) = match self.lock().books() {
            Ok(b) => (b.kinetic, b.gravity),
            Err(_) => (Real::NAN, Real::NAN),
        };
        let books = self.counted().map(|b| b.books).unwrap_or([Real::NAN; 2]);
        let mut r = EnergyReport { kinetic, ..Default::default() };
        let fluid = (self.names.fluid.clone(), 0.0);
        match &self.names.gravity {
            Some(g) if self.names.gravity_first => r.potential.extend([(g.clone(), gravity), fluid]),
            Some(g) => r.potential.extend([fluid, (g.clone(), gravity)]),
            None => r.potential.push(fluid),
        }
        r.dissipated.push((self.names.fluid.clone(), books[0]));
        r.dissipated.push(("collisions".to_string(), books[1]));
        r
    }
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        // The density pass and its read only when a density is asked for.
        let (x, v, rho) = if names.contains(&"density") {
            self.lock().read()?
        } else {
            let (x, v) = self.lock().read_state()?;
            (x, v, Vec::new())
        };
        let pressure = if names.contains(&"pressure") { self.lock().pressure()? } else { Vec::new() };
        let (d, n) = (self.params.dim, x.len() / self.params.dim);
        Ok(names
            .iter()
            .map(|name| {
                let (a, k) = match *name {
                    "mass" => return vec![self.params.mass; n],
                    "pinned" => return vec![0.0; n],
                    "density" => return rho.clone(),
                    "pressure" => return pressure.clone(),
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
            // The books go back; the solver's counts keep the steps rolled back (as the CPU's).
            let mut base = s.base;
            if let Ok(now) = self.counted() {
                base = Base { books: base.books, ..now };
            }
            // A device that cannot take it back reports the failure at its next read.
            let _ = self.upload(&s.x, &s.v, &s.history, base);
        }
    }
    /// The device particles' rows, as the scene file keeps them (`systems::device`, as
    /// `device_sph`'s): `pos` and `vel` (N × 4: position and mass, velocity and 1/mass), `acc`
    /// zero, `aux` zero but for row 0 (the fluid's and the box's dissipated energy so far) and
    /// row 1 (the steps, the density and divergence iterations and the unconverged solves so
    /// far) and row 2 (the largest final errors), `hits` zero, `acc_valid` 1. The warm starts
    /// are the fluid term's history (`term_history`), saved with the term.
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
        let b = &s.base;
        let counts = [b.steps, b.density_iterations, b.divergence_iterations, b.unconverged].map(|c| c as Real);
        for (row, values) in [&b.books[..], &counts[..], &b.error_max[..]].into_iter().enumerate().take(n) {
            aux[4 * row..4 * row + values.len()].copy_from_slice(values);
        }
        let hits = vec![0.0; n];
        saved(
            "the device fluid",
            &[("pos", &pos), ("vel", &vel), ("acc", &zero), ("aux", &aux), ("hits", &hits), ("acc_valid", &[1.0])],
        )
    }
    /// Loads `save`'s rows; the warm starts now on the device stay (the scene sets them from
    /// the fluid term's history).
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
        let count = |k: usize| -> Result<u64> {
            let c = aux.get(k).copied().unwrap_or(0.0);
            if c < 0.0 || c.fract() != 0.0 || c > u64::MAX as Real {
                return Err(invalid("aux", format!("entry {k} ({c}) is not a count")));
            }
            Ok(c as u64)
        };
        let at = |k: usize| aux.get(k).copied().unwrap_or(0.0);
        let base = Base {
            books: [at(0), at(1)],
            steps: count(4)?,
            density_iterations: count(5)?,
            divergence_iterations: count(6)?,
            unconverged: count(7)?,
            error_max: [at(8), at(9)],
        };
        let cols = |a: &[Real]| -> Vec<Real> { a.chunks_exact(4).flat_map(|r| r[..d].to_vec()).collect() };
        let history = self.history()?;
        self.upload(&cols(pos), &cols(vel), &history, base)
    }
}

impl HeldTerms for DeviceDfsph {
    fn term_history(&self, name: &str) -> Result<Option<Vec<Real>>> {
        if name != self.names.fluid {
            return Ok(None);
        }
        self.history().map(Some)
    }
    fn set_term_history(&mut self, name: &str, history: &[Real]) -> Result<()> {
        if name != self.names.fluid {
            return Err(invalid(name, format!("the device's DFSPH holds no term {name:?} with a history")));
        }
        Ok(self.g.get_mut().unwrap_or_else(|p| p.into_inner()).set_history(history)?)
    }
    /// The CPU term's statistics that the device counts: the steps, both solves' iterations and
    /// unconverged solves (totals), the last solves' and the largest final mean errors.
    fn term_stats(&self) -> Vec<(String, &'static str, Real)> {
        let (Ok(c), Ok(e)) = (self.counted(), self.lock().errors()) else {
            return Vec::new();
        };
        let f = &self.names.fluid;
        [
            ("steps", c.steps as Real),
            ("density_iterations", c.density_iterations as Real),
            ("divergence_iterations", c.divergence_iterations as Real),
            ("unconverged", c.unconverged as Real),
            ("density_error", e.density),
            ("density_error_max", c.error_max[0]),
            ("divergence_error", e.divergence),
            ("divergence_error_max", c.error_max[1]),
        ]
        .into_iter()
        .map(|(k, v)| (f.clone(), k, v))
        .collect()
    }
}
