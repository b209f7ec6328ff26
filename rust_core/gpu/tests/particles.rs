//! The device particle kernels against an f64 reference on the host. Run on any adapter; CI runs
//! them on lavapipe with `PHYSCORE_GPU_ALLOW_CPU=1 PHYSCORE_GPU_REQUIRED=1` (no adapter is then
//! a failure, not a skip).
use physcore_gpu::particles::{Forces, Halt, Particles, Scheme, Springs};
use physcore_gpu::{Gpu, Precision};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

mod common;
use common::gpu;

/// A deterministic cloud: xorshift positions in the unit cube, small velocities.
fn cloud(n: usize, dim: usize, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut s = seed | 1;
    let mut r = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let x: Vec<f64> = (0..n * dim).map(|_| r() - 0.5).collect();
    let v: Vec<f64> = (0..n * dim).map(|_| 0.1 * (r() - 0.5)).collect();
    let m: Vec<f64> = (0..n).map(|_| 0.5 + r()).collect();
    (x, v, m)
}

/// Host f64 accelerations (the formula in particles.rs).
fn accel(x: &[f64], v: &[f64], m: &[f64], im: &[f64], dim: usize, f: &Forces) -> Vec<f64> {
    let n = m.len();
    let mut a = vec![0.0; n * dim];
    for i in 0..n {
        if im[i] == 0.0 {
            continue;
        }
        for k in 0..dim {
            a[i * dim + k] = f.g[k] - f.drag * im[i] * v[i * dim + k];
        }
        if let Some((g, eps)) = f.pairwise {
            for j in 0..n {
                let d: Vec<f64> = (0..dim).map(|k| x[j * dim + k] - x[i * dim + k]).collect();
                let r2: f64 = d.iter().map(|c| c * c).sum::<f64>() + eps * eps;
                if r2 == 0.0 {
                    continue;
                }
                let s = g * m[j] / (r2 * r2.sqrt());
                for k in 0..dim {
                    a[i * dim + k] += s * d[k];
                }
            }
        }
    }
    a
}

fn semi_implicit_euler(x: &mut [f64], v: &mut [f64], m: &[f64], im: &[f64], dim: usize, f: &Forces, dt: f64) {
    let a = accel(x, v, m, im, dim, f);
    for i in 0..m.len() {
        if im[i] == 0.0 {
            continue;
        }
        for k in 0..dim {
            v[i * dim + k] += dt * a[i * dim + k];
            x[i * dim + k] += dt * v[i * dim + k];
        }
    }
}

fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |s, x| s.max(x.abs()));
    a.iter().zip(b).fold(0.0f64, |e, (p, q)| e.max((p - q).abs() / scale))
}

#[allow(clippy::too_many_arguments)]
fn run(
    gpu: &Arc<Gpu>,
    p: Precision,
    dim: usize,
    scheme: Scheme,
    f: Forces,
    n: usize,
    steps: u64,
    dt: f64,
) -> Particles {
    let (x, v, m) = cloud(n, dim, 7);
    let im: Vec<f64> = m.iter().map(|m| 1.0 / m).collect();
    let mut ps = Particles::new(gpu.clone(), p, dim, scheme, f, &x, &v, &m, &im, None).unwrap();
    ps.step(steps, dt, &AtomicBool::new(false)).unwrap();
    ps
}

#[test]
fn steps_agree_with_the_f64_host_path() {
    let Some(gpu) = gpu() else { return };
    let f = Forces { g: [0.0, -9.81, 0.0], drag: 0.05, pairwise: Some((1e-3, 0.05)), ..Default::default() };
    for dim in [2, 3] {
        let n = 600; // more than two tiles, not a multiple of one
        let (mut x, mut v, m) = cloud(n, dim, 7);
        let im: Vec<f64> = m.iter().map(|m| 1.0 / m).collect();
        let ps = run(&gpu, Precision::F32, dim, Scheme::SemiImplicitEuler, f, n, 20, 1e-3);
        for _ in 0..20 {
            semi_implicit_euler(&mut x, &mut v, &m, &im, dim, &f, 1e-3);
        }
        let (gx, gv) = ps.read().unwrap();
        let (ex, ev) = (max_rel(&gx, &x), max_rel(&gv, &v));
        eprintln!("dim {dim}: f32 vs f64 after 20 steps: positions {ex:.2e}, velocities {ev:.2e}");
        assert!(ex < 1e-6 && ev < 1e-5, "dim {dim}: positions {ex:e}, velocities {ev:e}");
        if gpu.adapter().f64 {
            let ps = run(&gpu, Precision::F64, dim, Scheme::SemiImplicitEuler, f, n, 20, 1e-3);
            let (gx, gv) = ps.read().unwrap();
            let (ex, ev) = (max_rel(&gx, &x), max_rel(&gv, &v));
            eprintln!("dim {dim}: f64 vs f64 after 20 steps: positions {ex:.2e}, velocities {ev:.2e}");
            assert!(ex < 1e-13 && ev < 1e-12, "dim {dim}: positions {ex:e}, velocities {ev:e}");
        }
    }
}

#[test]
fn runs_repeat_bit_for_bit() {
    let Some(gpu) = gpu() else { return };
    let f = Forces { g: [0.0, 0.0, -1.0], drag: 0.1, pairwise: Some((1e-2, 0.01)), ..Default::default() };
    let a = run(&gpu, Precision::F32, 3, Scheme::VelocityVerlet, f, 700, 50, 1e-3).read().unwrap();
    let b = run(&gpu, Precision::F32, 3, Scheme::VelocityVerlet, f, 700, 50, 1e-3).read().unwrap();
    assert_eq!(a, b);
    // And the same steps taken in other submissions (1 + 49, 25 + 25) give the same bits.
    let (x, v, m) = cloud(700, 3, 7);
    let im: Vec<f64> = m.iter().map(|m| 1.0 / m).collect();
    let mut c =
        Particles::new(gpu.clone(), Precision::F32, 3, Scheme::VelocityVerlet, f, &x, &v, &m, &im, None).unwrap();
    let no = AtomicBool::new(false);
    c.step(1, 1e-3, &no).unwrap();
    c.step(24, 1e-3, &no).unwrap();
    c.step(25, 1e-3, &no).unwrap();
    assert_eq!(c.read().unwrap(), a);
}

/// Two equal bodies on a circular orbit: velocity Verlet keeps the energy to O(dt²) and the
/// books balance; the orbit closes after one period.
#[test]
fn a_kepler_orbit_keeps_its_energy() {
    let Some(gpu) = gpu() else { return };
    let (g, m, r) = (1.0, 0.5, 0.5); // separation 2r = 1, total mass 1: period 2π
    let w = (g * 2.0 * m / 1.0f64).sqrt() / 1.0; // ω² = G M / a³ with a = 1
    let vt = w * r;
    let x = [-r, 0.0, 0.0, r, 0.0, 0.0];
    let v = [0.0, -vt, 0.0, 0.0, vt, 0.0];
    let f = Forces { pairwise: Some((g, 0.0)), ..Default::default() };
    for p in [Precision::F32, Precision::F64] {
        if p == Precision::F64 && !gpu.adapter().f64 {
            continue;
        }
        let mut ps =
            Particles::new(gpu.clone(), p, 3, Scheme::VelocityVerlet, f, &x, &v, &[m, m], &[1.0 / m, 1.0 / m], None)
                .unwrap();
        let e0 = ps.books().unwrap();
        let exact = -g * m * m / 1.0 + 2.0 * 0.5 * m * vt * vt;
        assert!((e0.kinetic + e0.pairwise - exact).abs() < 1e-6, "{e0:?} vs {exact}");
        let steps = 2000u64;
        let dt = 2.0 * std::f64::consts::PI / steps as f64;
        let mut worst: f64 = 0.0;
        for _ in 0..20 {
            ps.step(steps / 20, dt, &AtomicBool::new(false)).unwrap();
            let e = ps.books().unwrap();
            worst = worst.max(((e.kinetic + e.pairwise) - exact).abs() / exact.abs());
        }
        let (xe, _) = ps.read().unwrap();
        let closure = ((xe[3] - r).powi(2) + xe[4].powi(2)).sqrt();
        eprintln!("{}: energy error {worst:.2e} over one period, orbit closes to {closure:.2e}", p.name());
        // Verlet at 2000 steps per orbit: energy O((ω dt)²) ~ 1e-5 and f32 rounding ~1e-6 a step.
        let (de, dc) = if p == Precision::F32 { (5e-5, 5e-4) } else { (1e-5, 1e-4) };
        assert!(worst < de && closure < dc, "{}: energy {worst:e}, closure {closure:e}", p.name());
    }
}

#[test]
fn drag_books_balance_and_pinned_particles_stay() {
    let Some(gpu) = gpu() else { return };
    let f = Forces { g: [0.0, -9.81, 0.0], drag: 0.3, ..Default::default() };
    for scheme in [Scheme::SemiImplicitEuler, Scheme::VelocityVerlet] {
        let (x, v, m) = cloud(300, 2, 3);
        let mut im: Vec<f64> = m.iter().map(|m| 1.0 / m).collect();
        im[5] = 0.0;
        let mut v = v;
        v[10] = 0.0;
        v[11] = 0.0;
        let mut ps = Particles::new(gpu.clone(), Precision::F32, 2, scheme, f, &x, &v, &m, &im, None).unwrap();
        let b0 = ps.books().unwrap();
        ps.step(2000, 1e-3, &AtomicBool::new(false)).unwrap();
        let b = ps.books().unwrap();
        let (e0, e) = (b0.kinetic + b0.uniform, b.kinetic + b.uniform + b.dissipated);
        let lost = b.dissipated;
        eprintln!("{scheme:?}: dissipated {lost:.4} J, books off by {:.2e} of it", (e - e0).abs() / lost);
        assert!(lost > 1.0);
        // First order (semi-implicit Euler) misses O(dt) of the work; Verlet O(dt²).
        let tol = if scheme == Scheme::SemiImplicitEuler { 5e-3 } else { 1e-5 };
        assert!((e - e0).abs() < tol * lost, "{scheme:?}: {e0} vs {e}");
        let (xe, _) = ps.read().unwrap();
        assert_eq!([xe[10], xe[11]], [(x[10] as f32) as f64, (x[11] as f32) as f64]);
    }
}

#[test]
fn stop_divergence_and_rollback() {
    let Some(gpu) = gpu() else { return };
    let f = Forces { g: [0.0, -9.81, 0.0], ..Default::default() };
    let (x, v, m) = cloud(100, 3, 1);
    let im: Vec<f64> = m.iter().map(|m| 1.0 / m).collect();
    let mut ps =
        Particles::new(gpu.clone(), Precision::F32, 3, Scheme::SemiImplicitEuler, f, &x, &v, &m, &im, None).unwrap();
    // A raised flag stops before any step.
    assert_eq!(ps.step(10, 1e-3, &AtomicBool::new(true)), Err((0, Halt::Stopped)));
    ps.snapshot().unwrap();
    let before = ps.read().unwrap();
    // A step of 1e30 s overflows f32: found, named, and the snapshot brings the state back.
    match ps.step(3, 1e30, &AtomicBool::new(false)) {
        Err((0, Halt::Diverged { particle })) => assert!(particle < 100),
        other => panic!("expected a divergence, got {other:?}"),
    }
    ps.restore().unwrap();
    assert_eq!(ps.read().unwrap(), before);
}

#[test]
fn what_the_adapter_lacks_is_refused_by_name() {
    let Some(gpu) = gpu() else { return };
    if !gpu.adapter().f64 {
        let e = Particles::new(
            gpu.clone(),
            Precision::F64,
            2,
            Scheme::SemiImplicitEuler,
            Forces::default(),
            &[0.0; 2],
            &[0.0; 2],
            &[1.0],
            &[1.0],
            None,
        );
        assert!(format!("{}", e.err().unwrap()).contains("f64"));
    }
    assert!(Gpu::open("gpu:no-such-adapter").unwrap_err().to_string().contains("no-such-adapter"));
    assert!(Gpu::open("tpu").unwrap_err().to_string().contains("\"gpu\""));
}

/// A 12×12 cloth pinned at two corners under gravity with dashpots, velocity Verlet: against a
/// host f64 Verlet of the same springs (predicted velocities for the dashpots, as on the CPU
/// path), and its books balance.
#[test]
fn a_cloth_hangs_as_on_the_host() {
    let Some(gpu) = gpu() else { return };
    let (w, h) = (12usize, 12usize);
    let d = 0.1;
    let mut x = Vec::new();
    for r in 0..h {
        for c in 0..w {
            x.extend_from_slice(&[c as f64 * d, 0.0, -(r as f64) * d]);
        }
    }
    let n = w * h;
    let mut sp = Springs::default();
    for r in 0..h {
        for c in 0..w {
            let p = (r * w + c) as u32;
            if c + 1 < w {
                sp.i.push(p);
                sp.j.push(p + 1);
            }
            if r + 1 < h {
                sp.i.push(p);
                sp.j.push(p + w as u32);
            }
        }
    }
    let ns = sp.i.len();
    // Once with one kind of spring (the device packs the constants as a table of kinds) and once
    // with every spring's stiffness its own (264 kinds, past the table's 256: per entry).
    let pairs = sp;
    for distinct in [false, true] {
        let mut sp = pairs.clone();
        sp.k = (0..ns).map(|s| if distinct { 400.0 + 0.01 * s as f64 } else { 400.0 }).collect();
        sp.c = vec![0.05; ns];
        sp.rest = vec![d; ns];
        let m = vec![0.01; n];
        let mut im: Vec<f64> = m.iter().map(|m| 1.0 / m).collect();
        im[0] = 0.0;
        im[w - 1] = 0.0;
        let f = Forces { g: [0.0, 0.0, -9.81], ..Default::default() };
        let v0 = vec![0.0; 3 * n];
        // Host reference: Verlet with the dashpots at the predicted velocity.
        let acc = |x: &[f64], v: &[f64]| {
            let mut a = vec![0.0; 3 * n];
            for p in 0..n {
                if im[p] != 0.0 {
                    a[3 * p + 2] = -9.81;
                }
            }
            for s in 0..ns {
                let (i, j) = (sp.i[s] as usize, sp.j[s] as usize);
                let dx: Vec<f64> = (0..3).map(|k| x[3 * j + k] - x[3 * i + k]).collect();
                let l = dx.iter().map(|c| c * c).sum::<f64>().sqrt();
                let nn: Vec<f64> = dx.iter().map(|c| c / l).collect();
                let wv: f64 = (0..3).map(|k| (v[3 * j + k] - v[3 * i + k]) * nn[k]).sum();
                let fm = sp.k[s] * (l - sp.rest[s]) + sp.c[s] * wv;
                for k in 0..3 {
                    a[3 * i + k] += fm * nn[k] * im[i];
                    a[3 * j + k] -= fm * nn[k] * im[j];
                }
            }
            a
        };
        let dt = 5e-4;
        let steps = 400;
        let (mut hx, mut hv) = (x.clone(), v0.clone());
        let mut a = acc(&hx, &hv);
        for _ in 0..steps {
            let mut vp = hv.clone();
            for q in 0..3 * n {
                if im[q / 3] != 0.0 {
                    vp[q] = hv[q] + dt * a[q];
                    hv[q] += 0.5 * dt * a[q];
                    hx[q] += dt * hv[q];
                }
            }
            a = acc(&hx, &vp);
            for q in 0..3 * n {
                if im[q / 3] != 0.0 {
                    hv[q] += 0.5 * dt * a[q];
                }
            }
        }
        for p in [Precision::F32, Precision::F64] {
            if p == Precision::F64 && !gpu.adapter().f64 {
                continue;
            }
            let mut ps =
                Particles::new(gpu.clone(), p, 3, Scheme::VelocityVerlet, f, &x, &v0, &m, &im, Some(&sp)).unwrap();
            let b0 = ps.books().unwrap();
            ps.step(steps, dt, &AtomicBool::new(false)).unwrap();
            let b = ps.books().unwrap();
            let (gx, _) = ps.read().unwrap();
            let err = gx.iter().zip(&hx).fold(0.0f64, |e, (a, b)| e.max((a - b).abs()));
            let e0 = b0.kinetic + b0.uniform + b0.springs;
            let e1 = b.kinetic + b.uniform + b.springs + b.dashpots;
            eprintln!(
            "{} (distinct {distinct}): cloth after {steps} steps: largest position difference {err:.2e} m; far corner stretched {:.4} m; books off by {:.2e} J of {:.3e} J dissipated",
            p.name(),
            -gx[3 * (n - 1) + 2] - (h - 1) as f64 * d,
            e1 - e0,
            b.dashpots
        );
            let tol = if p == Precision::F32 { 1e-4 } else { 1e-11 };
            assert!(err < tol, "{}: {err}", p.name());
            assert!(b.dashpots > 0.0 && b.springs > 0.0);
            assert!((e1 - e0).abs() < 0.05 * b.dashpots.max(1e-3), "{}: books {e0} -> {e1}", p.name());
        }
    }
}

/// Yoshida's triple jump on the device is of fourth order: a circular Kepler orbit's position
/// error after one period falls ~16× per halving of dt (f64), against Verlet's 4×.
#[test]
fn yoshida4_converges_at_fourth_order() {
    let Some(gpu) = gpu() else { return };
    if !gpu.adapter().f64 {
        eprintln!("skipped: no f64 on {}", gpu.adapter().name);
        return;
    }
    let (g, m, r): (f64, f64, f64) = (1.0, 0.5, 0.5);
    let vt = (g * 2.0 * m).sqrt() * r;
    let x = [-r, 0.0, 0.0, r, 0.0, 0.0];
    let v = [0.0, -vt, 0.0, 0.0, vt, 0.0];
    let f = Forces { pairwise: Some((g, 0.0)), ..Default::default() };
    let err = |scheme: Scheme, steps: u64| {
        let mut ps =
            Particles::new(gpu.clone(), Precision::F64, 3, scheme, f, &x, &v, &[m, m], &[1.0 / m, 1.0 / m], None)
                .unwrap();
        ps.step(steps, 2.0 * std::f64::consts::PI / steps as f64, &AtomicBool::new(false)).unwrap();
        let (xe, _) = ps.read().unwrap();
        ((xe[3] - r).powi(2) + xe[4].powi(2)).sqrt()
    };
    for (scheme, order) in [(Scheme::Yoshida4, 4.0), (Scheme::VelocityVerlet, 2.0)] {
        let (e1, e2) = (err(scheme, 100), err(scheme, 200));
        let observed = (e1 / e2).log2();
        eprintln!("{scheme:?}: errors {e1:.2e}, {e2:.2e}: order {observed:.2}");
        assert!((observed - order).abs() < 0.25, "{scheme:?}: observed order {observed}");
    }
}

/// Worlds of a few particles in one system (`set_worlds`): the fused kernel (worlds.wgsl, one
/// dispatch a chunk of steps) steps each world as the general path steps it alone, under every
/// scheme, pinned particles and Coulomb too; and a world of more than `MAX_FUSED` particles,
/// which takes the general path with its sums kept to the world, agrees as well.
#[test]
fn worlds_stepped_together_agree_with_each_world_alone() {
    let Some(gpu) = gpu() else { return };
    let p = if gpu.adapter().f64 { Precision::F64 } else { Precision::F32 };
    let tol = if p == Precision::F64 { 1e-12 } else { 1e-4 };
    for (scheme, w, dim, coulomb) in [
        (Scheme::Yoshida4, 3, 2, false),
        (Scheme::VelocityVerlet, 5, 3, true),
        (Scheme::SemiImplicitEuler, 4, 3, false),
        (Scheme::VelocityVerlet, 20, 2, false),
    ] {
        let m = 7;
        let (x, v, mass) = cloud(m * w, dim, 11 + w as u64);
        let mut im: Vec<f64> = mass.iter().map(|m| 1.0 / m).collect();
        im[2 * w + 1] = 0.0; // a pinned particle in world 2
        let mut v = v;
        v[(2 * w + 1) * dim..(2 * w + 2) * dim].iter_mut().for_each(|c| *c = 0.0);
        let q: Vec<f64> = (0..m * w).map(|i| if i % 2 == 0 { 1e-6 } else { -2e-6 }).collect();
        let forces = Forces {
            g: [0.0, -1.0, 0.0],
            pairwise: Some((0.05, 0.02)),
            coulomb: coulomb.then_some((8.99e9 * 1e-3, 0.02)),
            ..Default::default()
        };
        let stop = AtomicBool::new(false);
        let mut all = Particles::new(gpu.clone(), p, dim, scheme, forces, &x, &v, &mass, &im, None).unwrap();
        all.set_worlds(w).unwrap();
        if coulomb {
            all.set_charges(&q).unwrap();
        }
        all.step(150, 2e-3, &stop).unwrap();
        all.step(50, 2e-3, &stop).unwrap(); // a second call continues (the carried force)
        let (xa, va) = all.read().unwrap();
        let scale = xa.iter().fold(0.0f64, |s, c| s.max(c.abs()));
        for k in 0..m {
            let r = k * w * dim..(k + 1) * w * dim;
            let rw = k * w..(k + 1) * w;
            let mut one = Particles::new(
                gpu.clone(),
                p,
                dim,
                scheme,
                forces,
                &x[r.clone()],
                &v[r.clone()],
                &mass[rw.clone()],
                &im[rw.clone()],
                None,
            )
            .unwrap();
            if coulomb {
                one.set_charges(&q[rw]).unwrap();
            }
            one.step(200, 2e-3, &stop).unwrap();
            let (xo, vo) = one.read().unwrap();
            let dx = xo.iter().zip(&xa[r.clone()]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            let dv = vo.iter().zip(&va[r.clone()]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(dx < tol * scale && dv < tol * scale.max(1.0), "{scheme:?} w {w} world {k}: dx {dx:e} dv {dv:e}");
            if k == 0 {
                eprintln!(
                    "{scheme:?}, worlds of {w}, {p:?}: world 0 within {dx:.1e} (positions), {dv:.1e} (velocities)"
                );
            }
            if k == 2 {
                let pin = dim..2 * dim; // particle 1 of world 2
                assert_eq!(xa[r][pin.clone()], x[2 * w * dim..][pin], "the pinned particle stays");
            }
        }
        // The books per world sum to the whole.
        let per = all.books_of_worlds().unwrap();
        let whole = all.books().unwrap();
        assert_eq!(per.len(), m);
        let ke: f64 = per.iter().map(|b| b.kinetic).sum();
        assert!((ke - whole.kinetic).abs() <= 1e-12 * whole.kinetic.abs().max(1e-30));
    }
}

/// `set_rows` replaces one world's rows between calls: with drag (a force of the velocities,
/// whose carried accelerations velocity Verlet takes at predicted velocities), every other
/// world's state and books go on bit for bit as in a run where nothing was replaced, and the
/// replaced world steps bit for bit as a system of it alone, from the state written.
#[test]
fn set_rows_changes_its_rows_alone() {
    let Some(gpu) = gpu() else { return };
    let p = if gpu.adapter().f64 { Precision::F64 } else { Precision::F32 };
    let (w, m, dim, dt) = (4, 5, 2, 2e-3);
    let (x, v, mass) = cloud(m * w, dim, 5);
    let im: Vec<f64> = mass.iter().map(|m| 1.0 / m).collect();
    let forces = Forces { g: [0.0, -1.0, 0.0], drag: 0.3, pairwise: Some((0.05, 0.02)), ..Default::default() };
    let stop = AtomicBool::new(false);
    let make = |x: &[f64], v: &[f64], mass: &[f64], im: &[f64], worlds: bool| {
        let mut s = Particles::new(gpu.clone(), p, dim, Scheme::VelocityVerlet, forces, x, v, mass, im, None).unwrap();
        if worlds {
            s.set_worlds(w).unwrap();
        }
        s
    };
    let mut plain = make(&x, &v, &mass, &im, true);
    let mut changed = make(&x, &v, &mass, &im, true);
    for s in [&mut plain, &mut changed] {
        s.step(100, dt, &stop).unwrap();
    }
    // World 3's velocities halved, and its masses doubled, between the calls.
    let (xc, vc) = changed.read().unwrap();
    let r = 3 * w * dim..4 * w * dim;
    let rw = 3 * w..4 * w;
    let v3: Vec<f64> = vc[r.clone()].iter().map(|c| 0.5 * c).collect();
    let m3: Vec<f64> = mass[rw.clone()].iter().map(|m| 2.0 * m).collect();
    let im3: Vec<f64> = m3.iter().map(|m| 1.0 / m).collect();
    changed.set_rows(3 * w, &xc[r.clone()], &v3, &m3, &im3).unwrap();
    let mut alone = make(&xc[r.clone()], &v3, &m3, &im3, false);
    for s in [&mut plain, &mut changed, &mut alone] {
        s.step(100, dt, &stop).unwrap();
    }
    let ((xp, vp), (xc, vc), (xa, va)) = (plain.read().unwrap(), changed.read().unwrap(), alone.read().unwrap());
    let other = |a: &[f64]| [&a[..3 * w * dim], &a[4 * w * dim..]].concat();
    assert_eq!(other(&xc), other(&xp), "the other worlds' positions");
    assert_eq!(other(&vc), other(&vp), "the other worlds' velocities");
    assert_eq!(xc[r.clone()], xa[..], "the written world steps as alone");
    assert_eq!(vc[r], va[..]);
    assert_ne!(xc, xp, "the write changed world 3");
    let (bp, bc, ba) = (plain.books_of_worlds().unwrap(), changed.books_of_worlds().unwrap(), alone.books().unwrap());
    for k in [0, 1, 2, 4] {
        assert_eq!(bc[k].dissipated, bp[k].dissipated, "world {k}'s drag books");
    }
    assert_eq!(bc[3].dissipated, ba.dissipated, "the written world's drag books start from zero");
}
