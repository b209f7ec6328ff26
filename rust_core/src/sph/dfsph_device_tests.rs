//! The device's DFSPH (`physcore_gpu::dfsph`) against this crate's, the CPU path: a block of
//! water thrown at the wall of a tank of wall particles (Akinci et al. 2012) under gravity, and
//! a column collapsing in it, stepped by a CPU world (the "dfsph" term, gravity, the "box"
//! collider, semi-implicit Euler) and by the device (issue "GPU fluids, grains and batches");
//! and with Akinci et al. (2013) surface tension and adhesion, drops and a column in a tank,
//! the device built from the same records (`DeviceDfsph`: the core's coefficients), state,
//! books and step limit compared.
//! Skipped where no adapter is found, unless PHYSCORE_GPU_REQUIRED=1 (CI runs it on lavapipe
//! with PHYSCORE_GPU_ALLOW_CPU=1).
use super::device_tests::tank_walls;
use crate::constraints::aabb::Aabb;
use crate::sph::dfsph::relaxation;
use crate::sph::resolve::lattice_density_sum;
use crate::sph::surface::Surface;
use crate::sph::KernelKind;
use crate::systems::device_dfsph::DeviceDfsph;
use crate::systems::device_fluid::tests::gpu;
use crate::systems::particles::ParticleSystem;
use crate::systems::{EnergyReport, System};
use crate::terms::registry::{self, Context, Params, Value};
use crate::vector::{Real, Vector};
use crate::world::World;
use glam::{DVec2, DVec3};
use physcore_gpu::dfsph::{Dfsph, DfsphParams};
use physcore_gpu::sph::Kernel;
use physcore_gpu::Precision;
use std::sync::atomic::AtomicBool;

/// A column `cols` × `rows` (× `cols` in 3D) of particles `dx` apart in the corner of the tank,
/// with a small deterministic jitter (no sum symmetric by accident), at rest or thrown at +x.
fn column(dim: usize, cols: usize, rows: usize, dx: Real, vx: Real) -> (Vec<Real>, Vec<Real>) {
    let count = if dim == 2 { cols * rows } else { cols * cols * rows };
    let mut x = Vec::with_capacity(dim * count);
    for k in 0..count {
        let p = if dim == 2 { [k % cols, k / cols, 0] } else { [k % cols, (k / cols) % cols, k / (cols * cols)] };
        for a in 0..dim {
            x.push((p[a] as Real + 0.5) * dx + 1e-4 * (((k * 7 + a * 13) % 11) as Real - 5.0) * dx / 5.0);
        }
    }
    let v = (0..dim * count).map(|i| if i % dim == 0 { vx } else { 0.0 }).collect();
    (x, v)
}

/// The term records of the device's fluid (kind, name, record): the "dfsph" fluid of `n`
/// particles with surface tension and adhesion `surface` (σ, adhesion), and gravity.
fn term_records(
    p: &DfsphParams,
    n: usize,
    surface: [Real; 2],
    walls: &[Real],
    psi: &[Real],
) -> Vec<(String, String, Params)> {
    let d = p.dim;
    let f = Params::new()
        .with("first", Value::Number(0.0))
        .with("n", Value::Number(n as Real))
        .with("h", Value::Number(p.h))
        .with("density", Value::Number(p.rho0))
        .with("sound_speed", Value::Number(p.c0))
        .with("viscosity", Value::Number(p.alpha))
        .with("kernel", Value::Text(p.kernel.name().into()))
        .with("density_error", Value::Number(p.density_tol))
        .with("divergence_error", Value::Number(p.divergence_tol))
        .with("max_iterations", Value::Number(p.max_iterations as Real))
        .with("cfl", Value::Number(0.4))
        .with("surface_tension", Value::Number(surface[0]))
        .with("adhesion", Value::Number(surface[1]))
        .with("walls", Value::Floats(walls.to_vec()))
        .with("wall_psi", Value::Floats(psi.to_vec()));
    let g = Params::new().with("g", Value::Floats(p.gravity[..d].to_vec()));
    vec![("dfsph".into(), "water".into(), f), ("gravity".into(), "gravity".into(), g)]
}

/// The CPU world of the device's fluid.
fn cpu_world<V: Vector>(p: &DfsphParams, x: &[Real], v: &[Real], walls: &[Real], psi: &[Real], dt: Real) -> World<V> {
    surface_world(p, x, v, [0.0; 2], walls, psi, dt)
}

/// `cpu_world` with surface tension and adhesion `surface` (σ, adhesion).
fn surface_world<V: Vector>(
    p: &DfsphParams,
    x: &[Real],
    v: &[Real],
    surface: [Real; 2],
    walls: &[Real],
    psi: &[Real],
    dt: Real,
) -> World<V> {
    let d = p.dim;
    let n = x.len() / d;
    let vec = |s: &[Real]| V::from_slice(s);
    let mut sys = ParticleSystem::<V>::new("semi_implicit_euler").unwrap();
    sys.add_particles(x.chunks(d).map(vec).collect(), v.chunks(d).map(vec).collect(), vec![p.mass; n], vec![false; n])
        .unwrap();
    let ctx = Context { n_particles: n };
    for (kind, name, params) in term_records(p, n, surface, walls, psi) {
        sys.add_term(registry::lookup(&kind).unwrap().build::<V>(name, params, &ctx).unwrap()).unwrap();
    }
    let b = Aabb::new(vec(&p.lower[..d]), vec(&p.upper[..d]), p.restitution, p.friction).unwrap();
    sys.add_constraint(Box::new(b));
    World::new(sys, dt, Some(1)).unwrap()
}

fn cpu_run<V: Vector>(
    p: &DfsphParams,
    x: &[Real],
    v: &[Real],
    walls: &[Real],
    dt: Real,
    steps: u64,
) -> (Vec<Real>, Vec<Real>) {
    let psi = vec![p.mass; walls.len() / p.dim];
    let mut w = cpu_world::<V>(p, x, v, walls, &psi, dt);
    w.step(steps).unwrap();
    let s = w.particles().state();
    (V::flat(&s.x).to_vec(), V::flat(&s.v).to_vec())
}

/// What a run is compared by: the state, the leading edge (the mean x of the 10 particles
/// farthest along +x, m) and the mean density error of the fluid as the CPU's solve measures it
/// would need its pairs: the kinetic energy (J) stands in for the flow's vigour.
struct Out {
    x: Vec<Real>,
    v: Vec<Real>,
}

fn edge(x: &[Real], dim: usize) -> Real {
    let mut xs: Vec<Real> = x.chunks_exact(dim).map(|p| p[0]).collect();
    xs.sort_by(|a, b| b.total_cmp(a));
    xs[..10].iter().sum::<Real>() / 10.0
}

fn kinetic(v: &[Real], m: Real) -> Real {
    0.5 * m * v.iter().map(|c| c * c).sum::<Real>()
}

/// The CPU world and the device (f64 where the adapter has it, and f32) from the same column
/// `steps` steps of 1 ms: (CPU, [f64, f32]) with None where f64 is missing.
fn runs(dim: usize, kernel: Kernel, vx: Real, steps: u64) -> Option<(DfsphParams, Out, [Option<Out>; 2])> {
    let gpu = gpu()?;
    let dx = 0.01;
    let h = 1.3 * dx;
    let (cols, rows) = if dim == 2 { (12, 20) } else { (6, 8) };
    let (x, v) = column(dim, cols, rows, dx, vx);
    let sum = lattice_density_sum(dx, h, dim, KernelKind::by_name(kernel.name()).unwrap()).unwrap();
    let up = if dim == 2 { [0.4, 0.4, 0.0] } else { [0.2, 0.2, 0.2] };
    let g = if dim == 2 { [0.0, -9.81, 0.0] } else { [0.0, 0.0, -9.81] };
    // The box a few spacings outside the walls (the device's cell list spans it).
    let p = DfsphParams {
        dim,
        h,
        mass: 1000.0 / sum,
        kernel,
        gravity: g,
        lower: [-0.04; 3],
        upper: [up[0] + 0.04, up[1] + 0.04, up[2] + 0.04],
        relaxation: relaxation(dim, KernelKind::by_name(kernel.name()).unwrap(), 1.3),
        ..DfsphParams::default()
    };
    let walls = tank_walls(dim, &up, dx, 3);
    let dt = 1e-3;
    let (cx, cv) = if dim == 2 {
        cpu_run::<DVec2>(&p, &x, &v, &walls, dt, steps)
    } else {
        cpu_run::<DVec3>(&p, &x, &v, &walls, dt, steps)
    };
    let psi = vec![p.mass; walls.len() / dim];
    let mut dev = [None, None];
    for (k, precision) in [Precision::F64, Precision::F32].into_iter().enumerate() {
        let mut d = match Dfsph::with_walls(gpu.clone(), precision, p, &x, &v, &walls, &psi) {
            Ok(d) => d,
            Err(e) if precision == Precision::F64 => {
                eprintln!("f64 skipped: {e}");
                continue;
            }
            Err(e) => panic!("{e}"),
        };
        d.step(steps, dt, &AtomicBool::new(false)).unwrap();
        let (x, v) = d.read_state().unwrap();
        dev[k] = Some(Out { x, v });
    }
    Some((p, Out { x: cx, v: cv }, dev))
}

/// Ten steps of 1 ms (some 20 pressure iterations each): the same arithmetic on the same
/// pairs, so the device in f64 agrees to f64's rounding. In f32 a solve's mean error crosses
/// its tolerance at another iteration from the first steps on, so the velocities part at the
/// solver's tolerance (5 % of the fastest, measured) while the positions keep within 1.3e-5 of
/// the box: f32 is held to its positions.
#[test]
fn device_dfsph_takes_the_cpus_steps() {
    for (dim, kernel, vx) in
        [(2, Kernel::CubicSpline, 0.0), (2, Kernel::WendlandC2, 0.5), (3, Kernel::CubicSpline, 0.0)]
    {
        let Some((p, cpu, dev)) = runs(dim, kernel, vx, 10) else { return };
        let width = p.upper[0] - p.lower[0];
        let vmax = cpu.v.iter().map(|u| u.abs()).fold(0.0, Real::max);
        assert!(vmax > 0.05, "the water moves ({vmax})");
        for (out, precision, (tx, tv)) in [(&dev[0], "f64", (1e-12, 1e-9)), (&dev[1], "f32", (1e-4, 1.0))] {
            let Some(o) = out else { continue };
            let ex = cpu.x.iter().zip(&o.x).map(|(a, b)| (a - b).abs()).fold(0.0, Real::max) / width;
            let ev = cpu.v.iter().zip(&o.v).map(|(a, b)| (a - b).abs()).fold(0.0, Real::max) / vmax;
            eprintln!("DFSPH {dim}D {} {precision}, 10 steps: positions {ex:.2e} of the box, velocities {ev:.2e} of the fastest", kernel.name());
            assert!(ex < tx && ev < tv, "{dim}D {precision}: {ex} {ev}");
        }
    }
}

/// A column collapsing for 0.2 s: past some 30 steps the two stop their solves at different
/// iterations now and then (each solve's mean error against its tolerance, a sum in another
/// order), so the states part at the solver's tolerance, not at rounding; the flow agrees:
/// the surge's leading edge within 2 % of the column's width and the kinetic energy within 5 %.
#[test]
fn device_dfsph_collapses_a_column_as_the_cpu_does() {
    for (dim, steps) in [(2, 200), (3, 120)] {
        let Some((p, cpu, dev)) = runs(dim, Kernel::CubicSpline, 0.0, steps) else { return };
        let width = if dim == 2 { 0.12 } else { 0.06 };
        let (e0, k0) = (edge(&cpu.x, dim), kinetic(&cpu.v, p.mass));
        assert!(e0 > 1.3 * width, "{dim}D: the column collapsed ({e0} m)");
        for (out, precision) in [(&dev[0], "f64"), (&dev[1], "f32")] {
            let Some(o) = out else { continue };
            let (e, k) = (edge(&o.x, dim), kinetic(&o.v, p.mass));
            eprintln!(
                "DFSPH {dim}D {precision}, {steps} steps: leading edge {e:.4} vs the CPU's {e0:.4} m ({:.2e} of the width), kinetic energy {:+.2e} relative",
                (e - e0).abs() / width,
                k / k0 - 1.0
            );
            assert!(
                (e - e0).abs() < 0.02 * width && (k / k0 - 1.0).abs() < 0.05,
                "{dim}D {precision}: {e} vs {e0}, {k} vs {k0}"
            );
        }
    }
}

/// The box collider's record (as the scene hands it to the device).
fn box_record(p: &DfsphParams) -> Vec<(String, Params)> {
    let d = p.dim;
    let b = Params::new()
        .with("lower", Value::Floats(p.lower[..d].to_vec()))
        .with("upper", Value::Floats(p.upper[..d].to_vec()))
        .with("restitution", Value::Number(p.restitution))
        .with("friction", Value::Number(p.friction));
    vec![("box".into(), b)]
}

/// The state by component from `System::fields` as flat n·dim.
fn flat_state(s: &dyn System, dim: usize) -> (Vec<Real>, Vec<Real>) {
    let names: &[&str] = if dim == 2 { &["x", "y", "vx", "vy"] } else { &["x", "y", "z", "vx", "vy", "vz"] };
    let f = s.fields(names).unwrap();
    let n = f[0].len();
    let pick = |o: usize| (0..n).flat_map(|i| (0..dim).map(move |a| (i, a))).map(|(i, a)| f[o + a][i]).collect();
    (pick(0), pick(dim))
}

/// The books as (entry, value): kinetic, then each potential and each dissipated by name.
fn book_entries(e: &EnergyReport) -> Vec<(String, Real)> {
    let mut out = vec![("kinetic".to_string(), e.kinetic)];
    out.extend(e.potential.iter().map(|(k, v)| (format!("potential {k}"), *v)));
    out.extend(e.dissipated.iter().map(|(k, v)| (format!("dissipated {k}"), *v)));
    out
}

/// A block `cols` × `rows` (× `cols` in 3D) of particles `dx` apart from `at`, with `column`'s
/// jitter, at rest.
fn block(dim: usize, cols: usize, rows: usize, dx: Real, at: Real) -> Vec<Real> {
    column(dim, cols, rows, dx, 0.0).0.iter().map(|c| c + at).collect()
}

/// The CPU world's step limit at the start, then its positions, velocities and books after
/// `steps` steps.
#[allow(clippy::too_many_arguments)]
fn cpu_surface<V: Vector>(
    p: &DfsphParams,
    x: &[Real],
    v: &[Real],
    surface: [Real; 2],
    walls: &[Real],
    psi: &[Real],
    dt: Real,
    steps: u64,
) -> (Option<Real>, Vec<Real>, Vec<Real>, EnergyReport) {
    let mut w = surface_world::<V>(p, x, v, surface, walls, psi, dt);
    let dt0 = w.auto_dt();
    w.step(steps).unwrap();
    w.prepare_energy().unwrap();
    let s = w.particles().state();
    (dt0, V::flat(&s.x).to_vec(), V::flat(&s.v).to_vec(), w.energy())
}

/// One agreement case of surface tension and adhesion: the CPU world and the device built from
/// the same records (`DeviceDfsph::from_records`: the core's coefficients, `Surface::new`), in
/// f64 and f32, `steps` steps of `dt`; the step limits compared at the start, the positions
/// (of the box), the velocities (of the fastest) and the books (of the largest entry) after.
/// Returns the errors [f64, f32] (None where the adapter lacks f64).
#[allow(clippy::too_many_arguments)]
fn surface_case(
    what: &str,
    p: &DfsphParams,
    x: &[Real],
    surface: [Real; 2],
    walls: &[Real],
    dt: Real,
    steps: u64,
) -> Option<[Option<[Real; 3]>; 2]> {
    let gpu = gpu()?;
    let (d, n) = (p.dim, x.len() / p.dim);
    let v = vec![0.0; x.len()];
    let psi = vec![p.mass; walls.len() / d];
    let (cpu_dt0, cx, cv, cbooks) = if d == 2 {
        cpu_surface::<DVec2>(p, x, &v, surface, walls, &psi, dt, steps)
    } else {
        cpu_surface::<DVec3>(p, x, &v, surface, walls, &psi, dt, steps)
    };
    let capillary = Surface::max_dt(surface[0], surface[1], p.rho0, p.h);
    assert!(cpu_dt0.is_some_and(|t| t <= capillary), "{what}: {cpu_dt0:?} within the capillary limit {capillary}");
    let terms = term_records(p, n, surface, walls, &psi);
    let colliders = box_record(p);
    let width = p.upper[0] - p.lower[0];
    let vmax = cv.iter().map(|u| u.abs()).fold(0.0, Real::max);
    assert!(vmax > 0.0, "{what}: the fluid moves");
    let cb = book_entries(&cbooks);
    let bmax = cb.iter().map(|e| e.1.abs()).fold(0.0, Real::max);
    let mut out = [None, None];
    for (k, precision) in ["f64", "f32"].into_iter().enumerate() {
        let mass = vec![p.mass; n];
        let made = DeviceDfsph::from_records(
            gpu.clone(),
            precision,
            "device particles",
            d,
            "semi_implicit_euler",
            x,
            &v,
            &mass,
            &vec![false; n],
            None,
            &terms,
            &colliders,
        );
        let mut dev = match made {
            Ok(s) => s,
            Err(e) if precision == "f64" => {
                eprintln!("f64 skipped: {e}");
                continue;
            }
            Err(e) => panic!("{e}"),
        };
        // At rest: the capillary limit (the drops') or gravity's, by the same formulas.
        assert_eq!(dev.auto_dt(), cpu_dt0, "{what} {precision}: the step limits");
        dev.steps(steps, dt, &AtomicBool::new(false)).unwrap();
        let (gx, gv) = flat_state(&dev, d);
        let ex = cx.iter().zip(&gx).map(|(a, b)| (a - b).abs()).fold(0.0, Real::max) / width;
        let ev = cv.iter().zip(&gv).map(|(a, b)| (a - b).abs()).fold(0.0, Real::max) / vmax;
        let gb = book_entries(&dev.energy());
        assert_eq!(cb.iter().map(|e| &e.0).collect::<Vec<_>>(), gb.iter().map(|e| &e.0).collect::<Vec<_>>());
        let eb = cb.iter().zip(&gb).map(|(a, b)| (a.1 - b.1).abs()).fold(0.0, Real::max) / bmax;
        eprintln!(
            "DFSPH surface, {what}, {precision}, {steps} steps: positions {ex:.2e} of the box, velocities {ev:.2e} of the fastest ({vmax:.2e} m/s), books {eb:.2e} of the largest entry ({bmax:.2e} J)"
        );
        for ((name, a), (_, b)) in cb.iter().zip(&gb) {
            eprintln!("    {name}: CPU {a:+.6e}, device {b:+.6e}");
        }
        out[k] = Some([ex, ev, eb]);
    }
    Some(out)
}

/// The settings of the surface cases: particles `dx` apart (h = 1.3 dx, the lattice's rest
/// density), gravity `g` down the last axis, the box from `lower` to `upper` on every axis.
fn surface_params(dim: usize, dx: Real, g: Real, lower: Real, upper: Real) -> DfsphParams {
    let h = 1.3 * dx;
    let sum = lattice_density_sum(dx, h, dim, KernelKind::CubicSpline).unwrap();
    let mut gravity = [0.0; 3];
    gravity[dim - 1] = -g;
    let relaxation = relaxation(dim, KernelKind::CubicSpline, 1.3);
    DfsphParams {
        dim,
        h,
        mass: 1000.0 / sum,
        gravity,
        lower: [lower; 3],
        upper: [upper; 3],
        relaxation,
        ..DfsphParams::default()
    }
}

/// Holds a case's errors (positions of the box, velocities of the fastest, books of the
/// largest entry) at what was measured (lavapipe), with room. f64: positions 7.6e-16, books
/// 2e-13, velocities 3.7e-12: above rounding as in `device_dfsph_takes_the_cpus_steps`, the
/// density solve's error ρ + dt Dρ/Dt − ρ0 being a small difference of large terms, divided by
/// dt². f32: a solve's mean error crosses its tolerance at another iteration, so the velocities
/// part at the solver's tolerance (4.4e-2 of the fastest), the books by 9.6e-4, the positions
/// by 4.6e-6 of the box.
fn gate(what: &str, e: [Option<[Real; 3]>; 2]) {
    let (f64_tol, f32_tol) = ([1e-12, 1e-10, 1e-11], [5e-5, 0.2, 1e-2]);
    for (out, tol, precision) in [(e[0], f64_tol, "f64"), (e[1], f32_tol, "f32")] {
        let Some(o) = out else { continue };
        assert!((0..3).all(|k| o[k] < tol[k]), "{what} {precision}: positions, velocities, books {o:?} over {tol:?}");
    }
}

/// (a) A 2D square drop of water (σ = 0.0728 N, 12 × 12 particles 1 mm apart) free in zero
/// gravity: only its surface forces move it.
#[test]
fn device_dfsph_surface_tension_takes_the_cpus_steps_2d() {
    let p = surface_params(2, 1e-3, 0.0, 0.0, 0.032);
    let x = block(2, 12, 12, 1e-3, 0.01);
    let Some(e) = surface_case("2D drop, σ = 0.0728 N", &p, &x, [0.0728, 0.0], &[], 1e-4, 10) else { return };
    gate("2D drop", e);
}

/// (b) A 2D column (10 × 8 particles 1 mm apart) in the corner of a tank of wall particles
/// under gravity, held by adhesion to them (0.0728 N), alone and with σ = 0.0728 N.
#[test]
fn device_dfsph_adhesion_to_the_walls_takes_the_cpus_steps_2d() {
    let dx = 1e-3;
    let up = [0.03, 0.03, 0.0];
    let walls = tank_walls(2, &up, dx, 3);
    let p = surface_params(2, dx, 9.81, -0.004, 0.034);
    let x = column(2, 10, 8, dx, 0.0).0;
    for (what, surface) in [("2D tank, adhesion 0.0728 N", [0.0, 0.0728]), ("2D tank, σ and adhesion", [0.0728; 2])] {
        let Some(e) = surface_case(what, &p, &x, surface, &walls, 1e-4, 10) else { return };
        gate(what, e);
    }
}

/// (c) A 3D cube drop (σ = 0.0728 N/m, 6³ particles 1 mm apart) free in zero gravity.
#[test]
fn device_dfsph_surface_tension_takes_the_cpus_steps_3d() {
    let p = surface_params(3, 1e-3, 0.0, 0.0, 0.016);
    let x = block(3, 6, 6, 1e-3, 0.005);
    let Some(e) = surface_case("3D drop, σ = 0.0728 N/m", &p, &x, [0.0728, 0.0], &[], 1e-4, 10) else { return };
    gate("3D drop", e);
}
