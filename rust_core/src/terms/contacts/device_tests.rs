//! The device's DEM (`physcore_gpu::dem`) against this crate's, the CPU path: grains thrown at
//! each other and at a floor (a plane wall) under gravity, with friction, stepped by a CPU world
//! (the "contacts" term, gravity, semi-implicit Euler) and by the device, for both laws, in 2D
//! and 3D (issue "GPU fluids, grains and batches"); and a grain bouncing obliquely off a pinned
//! grain (a peg). The damping ratios come from the CPU's own map of the restitution
//! (`damping_ratio`). Skipped where no adapter is found, unless
//! PHYSCORE_GPU_REQUIRED=1 (CI runs it on lavapipe with PHYSCORE_GPU_ALLOW_CPU=1).
use super::{damping_ratio, Law};
use crate::systems::device_fluid::tests::gpu;
use crate::systems::particles::ParticleSystem;
use crate::terms::registry::{self, Context, Params, Value};
use crate::vector::{Real, Vector};
use crate::world::World;
use glam::{DVec2, DVec3};
use physcore_gpu::dem::{self as dd, Dem, DemParams, Wall};
use physcore_gpu::Precision;
use std::sync::atomic::AtomicBool;

/// Six grains of unequal radii and masses: a pair thrown at each other, one falling onto the
/// floor with spin-free sliding, a stack, and a fast one thrown obliquely at the floor.
fn grains(dim: usize) -> (Vec<Real>, Vec<Real>, Vec<Real>, Vec<Real>) {
    let p: [[Real; 3]; 6] = [
        [-0.12, 0.3, 0.05],
        [0.12, 0.32, 0.0],
        [1.0, 0.12, 0.0],
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
        let (a, b) = if dim == 2 { (p[k], u[k]) } else { ([p[k][0], p[k][2], p[k][1]], [u[k][0], u[k][2], u[k][1]]) };
        x.extend_from_slice(&a[..dim]);
        v.extend_from_slice(&b[..dim]);
    }
    let m: Vec<Real> = r.iter().map(|ri: &Real| 1000.0 * ri.powi(dim as i32)).collect();
    (x, v, r.to_vec(), m)
}

struct Material {
    law: Law,
    stiffness: Real,
    restitution: Real,
    friction: Real,
    ratio: Real,
}

impl Material {
    /// The device's parameters of this material under gravity along −(last axis), cells over
    /// the box `[lower, upper]`.
    fn device_params(&self, dim: usize, lower: [Real; 3], upper: [Real; 3]) -> DemParams {
        let mut g = [0.0; 3];
        g[dim - 1] = -9.81;
        DemParams {
            law: if self.law == Law::Linear { dd::Law::Linear } else { dd::Law::Hertz },
            stiffness: self.stiffness,
            zeta: damping_ratio(self.law, self.restitution),
            friction: self.friction,
            tangential_ratio: self.ratio,
            gravity: g,
            lower,
            upper,
            ..DemParams::default()
        }
    }
}

/// The contacts term's walls as its record takes them: kinds ("plane,sphere,…") and every
/// wall's numbers in order, each wall with the material's restitution and friction.
struct Walls {
    kinds: String,
    params: Vec<Real>,
}

impl Walls {
    /// A floor through the origin, its normal up (the last axis).
    fn floor(dim: usize) -> Self {
        let mut up = vec![0.0; 2 * dim];
        up[2 * dim - 1] = 1.0;
        Self { kinds: "plane".into(), params: up }
    }
}

#[allow(clippy::too_many_arguments)]
fn cpu_run<V: Vector>(
    mat: &Material,
    walls: &Walls,
    x: &[Real],
    v: &[Real],
    r: &[Real],
    m: &[Real],
    pinned: &[bool],
    dt: Real,
    steps: u64,
) -> (Vec<Real>, Vec<Real>) {
    let d = V::DIM;
    let n = m.len();
    let vec = |s: &[Real]| V::from_slice(s);
    let mut sys = ParticleSystem::<V>::new("semi_implicit_euler").unwrap();
    sys.add_particles(x.chunks(d).map(vec).collect(), v.chunks(d).map(vec).collect(), m.to_vec(), pinned.to_vec())
        .unwrap();
    sys.set_attribute("radius", r.to_vec()).unwrap();
    let ctx = Context { n_particles: n };
    let nw = walls.kinds.split(',').count();
    let c = Params::new()
        .with("law", Value::Text(if mat.law == Law::Linear { "linear" } else { "hertz" }.into()))
        .with("stiffness", Value::Number(mat.stiffness))
        .with("tangential_ratio", Value::Number(mat.ratio))
        .with("restitution", Value::Number(mat.restitution))
        .with("friction", Value::Number(mat.friction))
        .with("wall_kinds", Value::Text(walls.kinds.clone()))
        .with("wall_params", Value::Floats(walls.params.clone()))
        .with("wall_restitution", Value::Floats(vec![mat.restitution; nw]))
        .with("wall_friction", Value::Floats(vec![mat.friction; nw]));
    let mut g = vec![0.0; d];
    g[d - 1] = -9.81;
    let g = Params::new().with("g", Value::Floats(g));
    for (kind, name, params) in [("contacts", "contacts", c), ("gravity", "gravity", g)] {
        sys.add_term(registry::lookup(kind).unwrap().build::<V>(name.into(), params, &ctx).unwrap()).unwrap();
    }
    let mut w = World::new(sys, dt, Some(1)).unwrap();
    w.step(steps).unwrap();
    let s = w.particles().state();
    (V::flat(&s.x).to_vec(), V::flat(&s.v).to_vec())
}

/// The device against the CPU world: (positions over the scene's size, velocities over the
/// fastest), f64 and f32 (NaN where the adapter has no f64).
fn agree(dim: usize, mat: &Material, steps: u64) -> [(Real, Real); 2] {
    let Some(gpu) = gpu() else { return [(0.0, 0.0); 2] };
    let (x, v, r, m) = grains(dim);
    // A 50th of the shortest contact at the fastest impact (the CPU's `max_dt` rule).
    let dt = 2e-5;
    let free = vec![false; m.len()];
    let (cx, cv) = if dim == 2 {
        cpu_run::<DVec2>(mat, &Walls::floor(2), &x, &v, &r, &m, &free, dt, steps)
    } else {
        cpu_run::<DVec3>(mat, &Walls::floor(3), &x, &v, &r, &m, &free, dt, steps)
    };
    // Every kind of contact happened: the pair bounced apart, the fast grain off the floor.
    let up = |k: usize| cv[dim * k + dim - 1];
    assert!(cv[0] < 0.0 && cv[dim] > 0.0, "the pair collided: {cv:?}");
    assert!(up(5) > 0.0, "the oblique grain bounced: {cv:?}");
    let params = mat.device_params(dim, [-1.0, -1.0, -1.0], [4.0, 2.0, 2.0]);
    let zeta = params.zeta;
    let mut up = [0.0; 3];
    up[dim - 1] = 1.0;
    let floor = Wall::plane([0.0; 3], up, zeta, mat.friction);
    let what = format!("{:?} e {} μ {}", mat.law, mat.restitution, mat.friction);
    device_errors(&gpu, dim, params, (&x, &v, &r, &m), &[floor], (dt, steps), (&cx, &cv), &what)
}

/// The device's grains (`x`, `v`, `r`, `m`; `walls`) stepped `steps` of `dt` against the CPU
/// world's end state (`cx`, `cv`): (positions over the scene's size of 3, velocities over the
/// fastest), f64 and f32 (NaN where the adapter has no f64).
#[allow(clippy::too_many_arguments)]
fn device_errors(
    gpu: &std::sync::Arc<physcore_gpu::Gpu>,
    dim: usize,
    params: DemParams,
    (x, v, r, m): (&[Real], &[Real], &[Real], &[Real]),
    walls: &[Wall],
    (dt, steps): (Real, u64),
    (cx, cv): (&[Real], &[Real]),
    what: &str,
) -> [(Real, Real); 2] {
    let mut out = [(Real::NAN, Real::NAN); 2];
    for (k, precision) in [Precision::F64, Precision::F32].into_iter().enumerate() {
        let mut dev = match Dem::new(gpu.clone(), precision, dim, params, x, v, r, m, walls) {
            Ok(d) => d,
            Err(e) if precision == Precision::F64 => {
                eprintln!("f64 skipped: {e}");
                continue;
            }
            Err(e) => panic!("{e}"),
        };
        dev.step(steps, dt, &AtomicBool::new(false)).unwrap();
        let (dx, dv, _) = dev.read().unwrap();
        let vmax = cv.iter().map(|u| u.abs()).fold(0.0, Real::max);
        let ex = cx.iter().zip(&dx).map(|(a, b)| (a - b).abs()).fold(0.0, Real::max) / 3.0;
        let ev = cv.iter().zip(&dv).map(|(a, b)| (a - b).abs()).fold(0.0, Real::max) / vmax;
        eprintln!(
            "DEM {dim}D {what} {precision:?}, {steps} steps: positions {ex:.2e} of the scene, velocities {ev:.2e} of the fastest"
        );
        out[k] = (ex, ev);
    }
    out
}

#[test]
fn device_dem_agrees_with_the_cpu_contacts() {
    for dim in [2, 3] {
        for (law, stiffness) in [(Law::Linear, 1e5), (Law::Hertz, 1e7)] {
            let ratio = if dim == 2 { 1.0 / 3.0 } else { 2.0 / 7.0 };
            let mat = Material { law, stiffness, restitution: 0.6, friction: 0.4, ratio };
            let [(x64, v64), (x32, v32)] = agree(dim, &mat, 5000);
            if x64.is_finite() {
                assert!(x64 < 1e-10 && v64 < 1e-8, "{dim}D {law:?} f64: {x64} {v64}");
            }
            assert!(x32 < 1e-3 && v32 < 1e-2, "{dim}D {law:?} f32: {x32} {v32}");
        }
    }
}

/// A grain (radius 0.1, 10 kg in 2D, 1 kg in 3D: density 1000) dropped a little off-centre onto
/// a pinned grain (radius 0.08, on no floor: the peg alone holds it up for a moment), with
/// friction: the device against the CPU world, the grain's state after it bounced and the peg
/// unmoved; the rebound speed over the impact speed (normal to the contact) is the CPU's.
#[test]
fn a_grain_bounces_off_a_pinned_grain_as_on_the_cpu() {
    let Some(gpu) = gpu() else { return };
    for dim in [2, 3] {
        for (law, stiffness) in [(Law::Linear, 1e5), (Law::Hertz, 1e7)] {
            let ratio = if dim == 2 { 1.0 / 3.0 } else { 2.0 / 7.0 };
            let mat = Material { law, stiffness, restitution: 0.6, friction: 0.4, ratio };
            // Up is the last axis; the grain 0.03 m off the peg's axis, 0.01 m above it.
            let (mut x, mut v) = (vec![0.0; 2 * dim], vec![0.0; 2 * dim]);
            x[0] = 0.03;
            x[dim - 1] = 0.19;
            v[dim - 1] = -1.0;
            let (r, m) = ([0.1, 0.08], [1000.0 * 0.1f64.powi(dim as i32), 1000.0 * 0.08f64.powi(dim as i32)]);
            let pinned = [false, true];
            let (dt, steps) = (2e-5, 2500);
            let (cx, cv) = if dim == 2 {
                cpu_run::<DVec2>(&mat, &Walls::floor(2), &x, &v, &r, &m, &pinned, dt, steps)
            } else {
                cpu_run::<DVec3>(&mat, &Walls::floor(3), &x, &v, &r, &m, &pinned, dt, steps)
            };
            // It hit (about step 500) and left: up and sideways, the peg where it was.
            assert!(cv[dim - 1] > 0.0 && cv[0] > 0.0, "{dim}D {law:?}: bounced off the peg: {cv:?}");
            assert!(cx[dim..] == x[dim..] && cv[dim..].iter().all(|&c| c == 0.0));
            let params = mat.device_params(dim, [-1.0; 3], [1.0; 3]);
            for precision in [Precision::F64, Precision::F32] {
                let mut dev = match Dem::new(gpu.clone(), precision, dim, params, &x, &v, &r, &m, &[]) {
                    Ok(d) => d,
                    Err(e) if precision == Precision::F64 => {
                        eprintln!("f64 skipped: {e}");
                        continue;
                    }
                    Err(e) => panic!("{e}"),
                };
                dev.set_pinned(&pinned).unwrap();
                dev.step(steps, dt, &AtomicBool::new(false)).unwrap();
                let (dx, dv, _) = dev.read().unwrap();
                let ex = (0..dim).map(|a| (cx[a] - dx[a]).abs()).fold(0.0, Real::max) / x[dim - 1];
                let ev = (0..dim).map(|a| (cv[a] - dv[a]).abs()).fold(0.0, Real::max);
                let speed = |u: &[Real]| u[..dim].iter().map(|c| c * c).sum::<Real>().sqrt();
                eprintln!(
                    "DEM {dim}D {law:?} off a peg {precision:?}, {steps} steps: rebound {:.6} m/s (CPU {:.6}); positions {ex:.1e} \
                     of the drop, velocities {ev:.1e} m/s",
                    speed(&dv),
                    speed(&cv)
                );
                assert!(dx[dim..] == x[dim..] && dv[dim..].iter().all(|&c| c == 0.0), "the peg moved on the device");
                if precision == Precision::F64 {
                    assert!(ex < 1e-10 && ev < 1e-8, "{dim}D {law:?} f64: {ex:e} {ev:e}");
                } else {
                    assert!(ex < 1e-3 && ev < 1e-2, "{dim}D {law:?} f32: {ex:e} {ev:e}");
                }
            }
        }
    }
}

/// Grains against a wall of every other shape, the device against the CPU world (linear law,
/// friction, gravity along −up), in 2D and 3D: one falls onto a capsule (a rod) off its axis,
/// one onto a tilted oriented box (a ramp) and slides off round its lower edge, one onto a
/// ball off its top, and one onto the sloping side of a bowl that holds them all. Each grain
/// leaves its fall line (so its wall pushed it), and the device's state is the CPU's: to
/// rounding in f64, to f32's accuracy in f32. The shapes are read by the CPU term's own parser
/// on both sides (as `DeviceDem` does).
#[test]
fn walls_of_every_shape_push_grains_as_on_the_cpu() {
    let Some(gpu) = gpu() else { return };
    let mat = Material { law: Law::Linear, stiffness: 1e5, restitution: 0.6, friction: 0.4, ratio: 1.0 / 3.0 };
    // (x, up, depth) per grain, at rest: onto the rod's end cap, the ramp, the ball, the bowl.
    let p: [[Real; 3]; 4] = [[0.36, 0.85, 0.0], [1.35, 0.95, 0.02], [1.86, 1.2, -0.03], [1.3, 0.2, 0.05]];
    let (theta, dt, steps) = (0.5, 2e-4, 2500);
    for dim in [2, 3] {
        let at = |q: [Real; 3]| if dim == 2 { vec![q[0], q[1]] } else { vec![q[0], q[2], q[1]] };
        let x: Vec<Real> = p.iter().flat_map(|&q| at(q)).collect();
        let v = vec![0.0; 4 * dim];
        let r = vec![0.1; 4];
        let m: Vec<Real> = r.iter().map(|ri: &Real| 1000.0 * ri.powi(dim as i32)).collect();
        // A bowl of radius 1.5 about (1, 1), a rod from (−0.1, 0.6) to (0.3, 0.6) of radius 0.05,
        // a ramp 0.6 × 0.1 about (1.2, 0.5) turned up by θ, a ball of radius 0.15 at (1.8, 0.9).
        let mut params = Vec::new();
        params.extend(at([1.0, 1.0, 0.0]));
        params.extend([1.5, 1.0]);
        params.extend(at([-0.1, 0.6, 0.0]));
        params.extend(at([0.3, 0.6, 0.0]));
        params.push(0.05);
        params.extend(at([1.2, 0.5, 0.0]));
        params.extend(at([0.3, 0.05, 0.2]));
        // In 3D the up axis is z: the x axis turned towards up is a turn of −θ about y.
        params.extend(if dim == 2 { vec![theta] } else { vec![0.0, -theta, 0.0] });
        params.extend(at([1.8, 0.9, 0.0]));
        params.extend([0.15, 0.0]);
        let walls = Walls { kinds: "sphere,capsule,oriented_box,sphere".into(), params };
        let free = vec![false; 4];
        let (cx, cv) = if dim == 2 {
            cpu_run::<DVec2>(&mat, &walls, &x, &v, &r, &m, &free, dt, steps)
        } else {
            cpu_run::<DVec3>(&mat, &walls, &x, &v, &r, &m, &free, dt, steps)
        };
        // Each grain left its fall line: the rod's and the ball's to +x, the ramp's down it
        // (−x), the bowl's towards its centre (−x) and up again.
        let shift: Vec<Real> = (0..4).map(|k| cx[dim * k] - x[dim * k]).collect();
        assert!(shift[0] > 0.05 && shift[1] < -0.2 && shift[2] > 0.05 && shift[3] < -0.01, "{dim}D: {shift:?}");
        assert!(cv[dim * 3 + dim - 1] > 0.0, "{dim}D: the last grain bounced off the bowl: {cv:?}");
        let record = Params::new()
            .with("wall_kinds", Value::Text(walls.kinds.clone()))
            .with("wall_params", Value::Floats(walls.params.clone()))
            .with("wall_restitution", Value::Floats(vec![mat.restitution; 4]))
            .with("wall_friction", Value::Floats(vec![mat.friction; 4]));
        let dev_walls = crate::systems::device_dem::walls_of_record(dim, &record, mat.law).unwrap();
        let params = mat.device_params(dim, [-1.0; 3], [3.0; 3]);
        let what = "walls of every shape";
        let [(x64, v64), (x32, v32)] =
            device_errors(&gpu, dim, params, (&x, &v, &r, &m), &dev_walls, (dt, steps), (&cx, &cv), what);
        if x64.is_finite() {
            assert!(x64 < 1e-10 && v64 < 1e-8, "{dim}D f64: {x64:e} {v64:e}");
        }
        assert!(x32 < 1e-3 && v32 < 1e-2, "{dim}D f32: {x32:e} {v32:e}");
    }
}
