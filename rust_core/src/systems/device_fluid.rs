//! The stable fluid on a GPU (`physcore_gpu::fluid`): the CPU system's step (`grids::fluid`)
//! stage for stage, with its MGPCG pressure solve, implicit viscosity, open boundaries, sources,
//! buoyancy, vorticity confinement and energy books, the fields resident on the device. A CPU
//! copy of the system (`Tended::host`) keeps the configuration, builds the solvers' stencils
//! and does what happens seldom on the fields read back: the energies, reading and setting
//! fields, save and load, the next step's size (it holds the state on the host too).
//!
//! Measured against the CPU path (`a_device_fluid_steps_as_the_cpu_one`, lavapipe): see its
//! figures in docs/guide/gpu.md.
use super::device::precision_of;
use super::{Arrays, EnergyReport, Halt, Snapshot, System};
use crate::error::{invalid, Failure, Result};
use crate::grids::fluid::{FluidConfig, StableFluid};
use crate::grids::poisson::{Pcg, Solve, Stencil};
use crate::vector::Real;
use physcore_gpu::fluid::{self as df, Fluid, Parts};
use physcore_gpu::{Gpu, Precision};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

pub struct DeviceFluid {
    name: String,
    cells: usize,
    t: Mutex<Tended>,
}

struct Tended {
    host: StableFluid,
    dev: Fluid,
}

fn operator(st: &Stencil) -> Result<df::Operator> {
    let [we, wn, d0, count] = st.coefficients();
    let need = crate::alloc::Need::new("step", 32 * we.len() as u128, "a copy of the fluid's stencils for the device");
    Ok(df::Operator {
        nx: st.nx,
        ny: st.ny,
        we: need.copy(we)?,
        wn: need.copy(wn)?,
        d0: need.copy(d0)?,
        count: need.copy(count)?,
    })
}

fn operators(p: &Pcg) -> Result<Vec<df::Operator>> {
    p.stencils().map(operator).collect()
}

/// A copy of the host's state for the device (asked of the allocator: the copies are the grid's
/// size), refusing by name a value past f32's range on an f32 device (it would turn inf there
/// silently, or read as a divergence).
fn state_of(host: &mut StableFluid, precision: Precision) -> Result<df::State> {
    let (books, ..) = host.book_values();
    let steps = StableFluid::steps(host);
    let [u, v, d, t, p, tr] = host.state_arrays();
    let named = [("u", &*u), ("v", &*v), ("density", &*d), ("temperature", &*t), ("pressure", &*p), ("tracers", &*tr)];
    if precision == Precision::F32 {
        for (name, a) in named {
            if let Some(i) = a.iter().position(|x| x.abs() > f32::MAX as Real) {
                return Err(invalid(
                    name,
                    format!("entry {i} is past f32's range (precision=\"f32\" on the device; use \"f64\")"),
                ));
            }
        }
    }
    let n: usize = named.iter().map(|(_, a)| a.len()).sum();
    let need = crate::alloc::Need::new("step", 8 * n as u128, "a copy of the fluid's state for the device");
    Ok(df::State {
        u: need.copy(u)?,
        v: need.copy(v)?,
        density: need.copy(d)?,
        temperature: need.copy(t)?,
        pressure: need.copy(p)?,
        books,
        tracers: need.copy(tr)?,
        steps,
    })
}

impl Tended {
    /// The device's state and books made the host's.
    fn pull(&mut self) -> Result<()> {
        self.pull_parts(Parts::ALL)
    }

    /// `pull` of the books and the arrays of `parts` only (the host's others left as they were:
    /// for what reads only those, e.g. a frame's smoke).
    fn pull_parts(&mut self, parts: Parts) -> Result<()> {
        let s = self.dev.read_parts(parts)?;
        let [u, v, d, t, p, tr] = self.host.state_arrays();
        if parts.velocity {
            (*u, *v) = (s.u, s.v);
        }
        if parts.smoke {
            (*d, *t) = (s.density, s.temperature);
        }
        if parts.pressure {
            *p = s.pressure;
        }
        if parts.tracers {
            *tr = s.tracers;
        }
        let so = self.dev.solves();
        let pressure = Solve {
            iterations: so.pressure_iterations,
            residual: so.pressure_residual,
            converged: so.pressure_converged,
        };
        self.host.set_book_values(s.books, pressure, so.viscosity_iterations);
        Ok(())
    }

    /// The host's state and books made the device's. Refuses a value an f32 device cannot hold.
    fn push(&mut self) -> Result<()> {
        let state = state_of(&mut self.host, self.dev.precision())?;
        Ok(self.dev.set_state(&state)?)
    }
}

impl DeviceFluid {
    /// The fluid `cfg` with the state `saved` (what the CPU system's `save` wrote), on `gpu` at
    /// `precision` ("f32", "f64").
    ///
    /// Errors: `InvalidInput` naming `precision` or `device`
    /// (f64 on an adapter without it, a grid over its limits) or a saved array; `OutOfMemory`
    /// for host or device buffers.
    pub fn on(gpu: Arc<Gpu>, precision: &str, cfg: FluidConfig, saved: &Arrays) -> Result<Self> {
        let precision = precision_of(precision)?;
        let [nx, ny] = cfg.shape;
        if nx > 65_532 || ny > 65_532 {
            return Err(invalid("shape", format!("{nx} × {ny} cells: the GPU path takes at most 65,532 a side")));
        }
        let name = cfg.name.clone();
        let mut host = StableFluid::new(cfg)?;
        host.load(saved)?;
        let model = {
            let (c, [u_open, v_open, fluid, inflow, u_walls, v_walls], pressure, visc) = host.parts();
            let need = crate::alloc::Need::new(
                "step",
                8 * (u_open.len() + v_open.len() + fluid.len() + u_walls.len() + v_walls.len()) as u128,
                "a copy of the fluid's masks for the device",
            );
            df::Model {
                nx,
                ny,
                dx: c.dx,
                no_slip: c.no_slip,
                lid: c.lid.unwrap_or(0.0),
                inflow: inflow.to_vec(),
                buoyancy_alpha: c.buoyancy_alpha,
                buoyancy_beta: c.buoyancy_beta,
                ambient_temperature: c.ambient_temperature,
                vorticity: c.vorticity,
                maccormack: c.advection == crate::grids::fluid::Advection::MacCormack,
                share: match c.projection {
                    crate::grids::fluid::Projection::Chorin => 0.0,
                    crate::grids::fluid::Projection::Incremental => 0.5,
                },
                viscosity: c.viscosity,
                tolerance: c.tolerance,
                max_iterations: c.max_iterations,
                u_open: need.copy(u_open)?,
                v_open: need.copy(v_open)?,
                u_walls: need.copy(u_walls)?,
                v_walls: need.copy(v_walls)?,
                fluid: need.copy(fluid)?,
                pressure: operators(pressure)?,
                viscous: match visc {
                    Some([a, b]) => Some([operator(a.stencil())?, operator(b.stencil())?]),
                    None => None,
                },
                sources: c
                    .sources
                    .iter()
                    .map(|s| df::Source {
                        cells: s.cells.clone(),
                        density: s.density,
                        temperature: s.temperature,
                        velocity: s.velocity,
                    })
                    .collect(),
                n_tracers: c.n_tracers,
                seeds: match c.sources.first().filter(|s| !s.cells.is_empty()) {
                    Some(s) => s.cells.iter().map(|&(c, _)| c as u32).collect(),
                    None => Vec::new(),
                },
            }
        };
        let state = state_of(&mut host, precision)?;
        let dev = Fluid::new(gpu, precision, model, &state)?;
        Ok(Self { name, cells: nx * ny, t: Mutex::new(Tended { host, dev }) })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Tended> {
        self.t.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The CPU system's cell index of a device node that is not finite (as `non_finite_cell`).
    fn cell_of(&self, field: usize, index: usize, nx: usize, ny: usize) -> usize {
        match field {
            0 => (index % (nx + 1)).min(nx - 1) + nx * (index / (nx + 1)).saturating_sub(1).min(ny - 1),
            1 => (index % (nx + 2)).saturating_sub(1).min(nx - 1) + nx * (index / (nx + 2)).min(ny - 1),
            _ => index,
        }
    }
}

/// The host's step count at a checkpoint (the fields stay on the device).
struct FluidMark(u64);

impl System for DeviceFluid {
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
    fn steps(&mut self, n: u64, dt: Real, stop: &AtomicBool) -> std::result::Result<(), (u64, Halt)> {
        let mut g = self.lock();
        let (nx, ny) = (g.dev.model().nx, g.dev.model().ny);
        let r = g.dev.step(n, dt, stop);
        let done = match &r {
            Ok(k) => *k,
            Err((k, _)) => *k,
        };
        // The host's count of steps (the fields come on the next pull).
        let steps = g.host.steps() + done;
        g.host.set_steps(steps);
        drop(g);
        r.map(|_| ()).map_err(|(i, h)| {
            (
                i,
                match h {
                    df::Halt::Stopped => Halt::Stopped,
                    df::Halt::Diverged { field, index } => {
                        Halt::Diverged { index: self.cell_of(field, index, nx, ny), quantity: Failure::Cell }
                    }
                    // A failed device reads as a divergence: the world rolls back (see DeviceParticles).
                    df::Halt::Failed(_) => Halt::Diverged { index: 0, quantity: Failure::Cell },
                },
            )
        })
    }
    /// The CPU system's limit from the fastest face, found on the device (one value read back).
    fn auto_dt(&self) -> Option<Real> {
        let mut g = self.lock();
        let umax = g.dev.fastest().ok()?;
        g.host.limit_at(umax)
    }
    fn suggest_dt(&self) -> Option<Real> {
        self.auto_dt().map(|dt| 0.5 * dt)
    }
    /// The CPU system's books from the velocity read back (NaN if the device cannot be read).
    fn energy(&self) -> EnergyReport {
        let mut g = self.lock();
        match g.pull_parts(Parts { velocity: true, ..Parts::NONE }) {
            Ok(()) => g.host.energy(),
            Err(_) => EnergyReport { kinetic: Real::NAN, ..Default::default() },
        }
    }
    fn books(&self) -> Vec<(String, Real)> {
        let mut g = self.lock();
        match g.pull_parts(Parts { smoke: true, ..Parts::NONE }) {
            Ok(()) => g.host.books(),
            Err(_) => Vec::new(),
        }
    }
    fn set_field(&mut self, name: &str, values: &[Real]) -> Result<()> {
        let mut g = self.lock();
        g.pull()?;
        g.host.set_field(name, values)?;
        g.push()
    }
    /// The fields from the arrays they need, read back (a frame of smoke reads the smoke).
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let has = |set: &[&str]| names.iter().any(|n| set.contains(n));
        let parts = Parts {
            velocity: has(&["u", "v", "speed", "vorticity", "divergence"]),
            smoke: has(&["density", "temperature"]),
            pressure: has(&["pressure"]),
            tracers: has(&["tracers"]),
        };
        let mut g = self.lock();
        g.pull_parts(parts)?;
        g.host.fields(names)
    }
    fn snapshot(&self) -> Result<Snapshot> {
        let mut g = self.lock();
        g.dev.snapshot()?;
        Ok(Box::new(FluidMark(g.host.steps())))
    }
    fn restore(&mut self, snapshot: Snapshot) {
        let mut g = self.lock();
        let _ = g.dev.restore();
        if let Ok(m) = snapshot.downcast::<FluidMark>() {
            // Back to the checkpoint's count (the books come from the device on the next pull).
            g.host.set_steps(m.0);
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
        // Checked on a copy first: a refused load changes nothing.
        let before = g.host.save()?;
        g.host.load(arrays)?;
        if let Err(e) = g.push() {
            g.host.load(&before)?;
            return Err(e);
        }
        Ok(())
    }
}

#[cfg(test)]
pub(crate) mod tests {
    //! The device fluid against the CPU system (skipped where no adapter is found, unless
    //! PHYSCORE_GPU_REQUIRED=1; CI runs them on lavapipe with PHYSCORE_GPU_ALLOW_CPU=1).
    use super::*;
    use crate::grids::fluid::tests::disc;
    use crate::grids::fluid::{Advection, Projection, Source};

    /// The adapter the core's device tests run on (shared with `sph::device_tests`): a device of
    /// the test's own (`Gpu::open_own`), so that on lavapipe the tests' queues run in parallel.
    pub(crate) fn gpu() -> Option<Arc<Gpu>> {
        let w = if physcore_gpu::cpu_allowed_by_env() { "gpu" } else { "gpu:lavapipe" };
        match Gpu::open_own(w) {
            Ok(g) => Some(g),
            Err(e) if std::env::var("PHYSCORE_GPU_REQUIRED").as_deref() == Ok("1") => panic!("no adapter: {e}"),
            Err(e) => {
                eprintln!("skipped: {e}");
                None
            }
        }
    }

    /// A plume: a hot, dense source, buoyancy, confinement and an obstacle (the CPU tests' own).
    fn plume(shape: [usize; 2]) -> FluidConfig {
        let [nx, ny] = shape;
        let dx = 1.0 / nx as Real;
        FluidConfig {
            shape,
            dx,
            buoyancy_alpha: 0.1,
            buoyancy_beta: 2.0,
            vorticity: 0.3,
            advection: Advection::MacCormack,
            projection: Projection::Incremental,
            tolerance: 1e-12,
            n_tracers: 400,
            obstacles: disc(shape, [nx as Real * 0.6, ny as Real * 0.6], nx as Real * 0.12),
            sources: vec![Source {
                cells: Source::circle(shape, dx, [0.5, 0.15], 0.12),
                density: 1.0,
                temperature: 1.0,
                velocity: [0.1, 0.3],
            }],
            ..FluidConfig::default()
        }
    }

    /// `steps` steps of `dt` on the CPU and on the device at `precision`: the largest difference
    /// of each field (u, v, density, temperature, pressure, tracers) over its largest value, and
    /// of each book over the largest of them.
    fn compare(cfg: FluidConfig, precision: &str, steps: u64, dt: Real) -> Option<([Real; 6], Real, (Solve, Solve))> {
        let g = gpu()?;
        let stop = AtomicBool::new(false);
        let mut cpu = StableFluid::new(cfg.clone()).unwrap();
        let saved = cpu.save().unwrap();
        let mut dev = DeviceFluid::on(g, precision, cfg, &saved).unwrap();
        for _ in 0..steps {
            cpu.step(dt, &stop).unwrap();
        }
        dev.steps(steps, dt, &stop).unwrap();
        // The step's limit from the fastest face found on the device.
        let (ta, tb) = (cpu.auto_dt().unwrap(), dev.auto_dt().unwrap());
        let tol = if precision == "f64" { 1e-12 } else { 1e-5 };
        assert!((ta - tb).abs() <= tol * ta, "auto_dt {ta} on the CPU, {tb} on the device");
        let names = ["u", "v", "density", "temperature", "pressure", "tracers"];
        let (a, b) = (cpu.fields(&names).unwrap(), dev.fields(&names).unwrap());
        let mut errs = [0.0; 6];
        for k in 0..6 {
            let scale = a[k].iter().fold(0.0, |m: Real, x| m.max(x.abs())).max(1e-300);
            errs[k] = a[k].iter().zip(&b[k]).fold(0.0, |m: Real, (x, y)| m.max((x - y).abs())) / scale;
        }
        let (ea, eb) = (cpu.energy(), dev.energy());
        let mut books: Vec<(Real, Real)> = ea.dissipated.iter().zip(&eb.dissipated).map(|(x, y)| (x.1, y.1)).collect();
        books.push((ea.kinetic, eb.kinetic));
        let big = books.iter().fold(0.0, |m: Real, (x, _)| m.max(x.abs()));
        let book_err = books.iter().fold(0.0, |m: Real, (x, y)| m.max((x - y).abs())) / big;
        let (ca, da) = (cpu.book_values(), dev.lock().host.book_values());
        assert_eq!(dev.lock().host.steps(), steps, "the host counts the device's steps");
        Some((errs, book_err, (ca.1, da.1)))
    }

    #[test]
    fn a_device_fluid_steps_as_the_cpu_one() {
        // MacCormack, incremental, sources, buoyancy, confinement, an obstacle, tracers (some
        // leave and are re-seeded in the source by the CPU's hash); f64 and f32.
        let Some((e, b, (cs, ds))) = compare(plume([40, 48]), "f64", 30, 0.01) else { return };
        println!("f64 plume 40 × 48, 30 steps: fields {e:?}, books {b:e}, solves {cs:?} / {ds:?}");
        assert!(e.iter().all(|&x| x < 1e-9), "{e:?}");
        assert!(b < 1e-9, "{b}");
        assert!(ds.converged && (cs.iterations as i64 - ds.iterations as i64).abs() <= 1, "{cs:?} {ds:?}");
        let mut c = plume([40, 48]);
        c.tolerance = 1e-5;
        let (e, b, _) = compare(c, "f32", 30, 0.01).unwrap();
        println!("f32 plume 40 × 48, 30 steps: fields {e:?}, books {b:e}");
        assert!(e.iter().all(|&x| x < 1e-3), "{e:?}");
        assert!(b < 1e-3, "{b}");
    }

    #[test]
    fn a_device_fluid_with_viscosity_a_lid_and_an_inflow() {
        // The lid-driven cavity (no slip, viscosity), semi-Lagrangian and Chorin's projection.
        let cavity = FluidConfig {
            shape: [24, 24],
            dx: 1.0 / 24.0,
            viscosity: 0.01,
            no_slip: true,
            lid: Some(1.0),
            advection: Advection::SemiLagrangian,
            projection: Projection::Chorin,
            tolerance: 1e-12,
            ..FluidConfig::default()
        };
        let Some((e, b, _)) = compare(cavity, "f64", 40, 0.01) else { return };
        println!("f64 cavity 24², 40 steps: fields {e:?}, books {b:e}");
        assert!(e.iter().all(|&x| x < 1e-9), "{e:?}");
        assert!(b < 1e-9, "{b}");
        // An open channel past a disc (inflow, outflow), MacCormack, incremental.
        let channel = FluidConfig {
            shape: [48, 20],
            dx: 1.0 / 20.0,
            viscosity: 1e-3,
            inflow: Some(1.0),
            obstacles: disc([48, 20], [12.0, 10.0], 3.0),
            advection: Advection::MacCormack,
            tolerance: 1e-12,
            n_tracers: 300,
            ..FluidConfig::default()
        };
        // Tracers leave through the outflow and re-enter anywhere (no source): the CPU's do.
        let mut cpu = StableFluid::new(channel.clone()).unwrap();
        let x0: Vec<Real> = cpu.fields(&["tracers"]).unwrap()[0].iter().step_by(2).copied().collect();
        let stop = AtomicBool::new(false);
        for _ in 0..40 {
            cpu.step(0.02, &stop).unwrap();
        }
        let x1 = cpu.fields(&["tracers"]).unwrap().remove(0);
        let back = x0.iter().zip(x1.iter().step_by(2)).filter(|(a, b)| **b < **a - 0.1).count();
        assert!(back > 10, "only {back} tracers re-seeded");
        let (e, b, _) = compare(channel, "f64", 40, 0.02).unwrap();
        println!("f64 channel 48 × 20, 40 steps: fields {e:?}, books {b:e}");
        assert!(e.iter().all(|&x| x < 1e-9), "{e:?}");
        assert!(b < 1e-9, "{b}");
    }
}
