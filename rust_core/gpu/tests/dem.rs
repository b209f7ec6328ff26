//! The device DEM (`physcore_gpu::dem`): a Hertz head-on collision against the analytic
//! contact duration (elastic) and against a host f64 loop of the same model (damped); total
//! momentum and angular momentum of an exploding cloud with friction; a grain sliding on a floor
//! ends rolling at v0/(1 + β); a pile settles under gravity with its books balanced; runs repeat
//! bit for bit and f32 follows f64; capacity overflow, non-finite input and divergence halt with
//! an error; pinned grains (pegs) stay still to the bit while grains rain onto them, and a grain
//! bounces off one as off a wall (m* = m of the free grain); under linear drag a grain reaches
//! the terminal speed m g / b with its books balanced; walls out of range are refused by name.
//! 2D discs and 3D spheres throughout.
//! Skips without an adapter unless `PHYSCORE_GPU_REQUIRED=1` (CI, on lavapipe).
use physcore_gpu::dem::{Dem, DemParams, Law, Shape, Wall};
use physcore_gpu::particles::Halt;
use physcore_gpu::{Gpu, GpuError, Precision};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

mod common;
use common::gpu;

/// A deterministic value in [0, 1).
fn unit(k: u64) -> f64 {
    let mut z = k.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

fn go() -> AtomicBool {
    AtomicBool::new(false)
}

fn run(dem: &mut Dem, steps: u64, dt: f64) {
    let done = dem.step(steps, dt, &go()).unwrap_or_else(|(k, h)| panic!("halted after {k} steps: {h:?}"));
    assert_eq!(done, steps);
}

/// ∫₀¹ (1 − x^{5/2})^{−1/2} dx · 2: the Hertz contact duration is this times δ_max/v
/// (δ_max = (5 m* v²/(4 k_n))^{2/5}), i.e. 3.2145 (m*/k_n)^{2/5} v^{−1/5}.
const HERTZ_T: f64 = 2.943_28;

/// Two equal grains (radius 0.5, mass 1) along x, `gap` apart, closing at `v` (relative).
fn head_on(gpu: &Arc<Gpu>, p: Precision, dim: usize, params: DemParams, gap: f64, v: f64) -> Dem {
    let mut x = vec![0.0; 2 * dim];
    let mut u = vec![0.0; 2 * dim];
    x[0] = -0.5 - 0.5 * gap;
    x[dim] = 0.5 + 0.5 * gap;
    u[0] = 0.5 * v;
    u[dim] = -0.5 * v;
    let params = DemParams { lower: [-2.0; 3], upper: [2.0; 3], ..params };
    Dem::new(gpu.clone(), p, dim, params, &x, &u, &[0.5, 0.5], &[1.0, 1.0], &[]).unwrap()
}

#[test]
fn hertz_head_on_lasts_the_analytic_time_and_keeps_its_energy() {
    let Some(gpu) = gpu() else { return };
    let (kn, v, m_eff) = (1e5f64, 1.0f64, 0.5f64);
    let dmax = (5.0 * m_eff * v * v / (4.0 * kn)).powf(0.4);
    let tc = HERTZ_T * dmax / v;
    let dt = tc / 1234.5;
    for dim in [2, 3] {
        let params = DemParams { law: Law::Hertz, stiffness: kn, ..Default::default() };
        let mut dem = head_on(&gpu, Precision::F64, dim, params, 0.0015, v);
        let ke0 = dem.books().unwrap().kinetic;
        let (mut touching, mut seen, mut steps) = (0u64, false, 0);
        // One step at a time: a step whose evaluation found the contact leaves it in the history.
        while steps < 3000 {
            run(&mut dem, 1, dt);
            steps += 1;
            let c = dem.contacts().unwrap();
            if c > 0 {
                touching += 1;
                seen = true;
            } else if seen {
                break;
            }
        }
        let measured = touching as f64 * dt;
        let err = measured / tc - 1.0;
        let b = dem.books().unwrap();
        let de = (b.kinetic + b.rotational) / ke0 - 1.0;
        let (_, u, w) = dem.read().unwrap();
        eprintln!("{dim}D Hertz head-on: t_c {measured:.6e} s vs {tc:.6e} s ({err:+.2e}); ΔKE/KE {de:+.2e}");
        assert!(err.abs() < 0.01, "{dim}D contact time off by {err:e}");
        assert!(de.abs() < 1e-4, "{dim}D elastic collision changed the energy by {de:e}");
        assert!((u[0] + 0.5 * v).abs() < 1e-3 * v && (u[dim] - 0.5 * v).abs() < 1e-3 * v, "{u:?}");
        assert!(w.iter().all(|&w| w == 0.0), "a head-on collision turns nothing: {w:?}");
        assert_eq!(b.friction, 0.0, "frictionless: nothing booked as lost to friction");
        let balance = b.total() / ke0 - 1.0;
        eprintln!(
            "{dim}D elastic books: total off by {balance:+.1e}, the spring's integration error booked {:+.1e} J",
            b.damping
        );
        assert!(balance.abs() < 1e-12, "{dim}D books off by {balance:e}");
    }
}

/// The model's head-on collision on the host, f64, written from `dem.wgsl`'s expressions: two
/// grains of mass `m`, radius `r` along x, grain 0 the first; returns their velocities after
/// `steps` steps.
#[allow(clippy::too_many_arguments)]
fn reference_head_on(
    hertz: bool,
    kn: f64,
    zeta: f64,
    m: f64,
    r: f64,
    x: [f64; 2],
    v: [f64; 2],
    dt: f64,
    steps: usize,
) -> [f64; 2] {
    let (mut x, mut v) = (x, v);
    let mut live = false;
    for _ in 0..steps {
        let dx = x[1] - x[0];
        let d2 = dx * dx;
        let s = r + r;
        let touching = d2 < s * s && d2 > 0.0;
        let mut fa = 0.0;
        if touching {
            let dist = d2.sqrt();
            let n = dx * (1.0 / dist);
            let d = s - dist;
            let vn = (v[0] - v[1]) * n;
            let inv_m = 1.0 / m + 1.0 / m;
            let gn = 2.0 * zeta * (kn / inv_m).sqrt();
            let h = 0.5 * dt * inv_m;
            let mut f = if hertz {
                let sd = d.sqrt();
                let el = kn * d * sd;
                let g = gn * sd.sqrt();
                let vm = (vn - h * el) / (1.0 + h * g);
                (el + g * vm).max(0.0)
            } else {
                let el = kn * d;
                let vm = (vn - h * el) * (1.0 / (1.0 + h * gn));
                (el + gn * vm).max(0.0)
            };
            if !live && vn > 0.0 && d <= 1.5 * vn * dt {
                let tau = (d / vn).min(dt);
                let t = tau + 0.5 * dt;
                let (el_j, damp_j) = if hertz {
                    let v15 = vn * vn.sqrt();
                    let v125 = vn * vn.sqrt().sqrt();
                    (
                        kn * v15 * (t * t * t.sqrt() / 2.5 - tau * tau.sqrt() * dt),
                        gn * v125 * (t * t.sqrt().sqrt() / 1.25 - tau.sqrt().sqrt() * dt),
                    )
                } else {
                    (kn * vn * (0.5 * t * t - tau * dt), gn * vn * (t - dt))
                };
                f = (f + (el_j + damp_j) / dt).max(0.0);
            }
            fa = -(n * f);
        }
        live = touching;
        v[0] += fa * (1.0 / m) * dt;
        v[1] += -fa * (1.0 / m) * dt;
        x[0] += v[0] * dt;
        x[1] += v[1] * dt;
    }
    v
}

#[test]
fn damped_restitution_matches_a_host_loop_of_the_same_model() {
    let Some(gpu) = gpu() else { return };
    let (kn, v) = (1e5f64, 1.0f64);
    let dmax = (5.0 * 0.5 * v * v / (4.0 * kn)).powf(0.4);
    let dt = HERTZ_T * dmax / v / 50.0;
    for (law, hertz) in [(Law::Hertz, true), (Law::Linear, false)] {
        for dim in [2, 3] {
            let zeta = 0.3;
            let params = DemParams { law, stiffness: kn, zeta, ..Default::default() };
            let gap = 0.0123 * v * dt;
            let mut dem = head_on(&gpu, Precision::F64, dim, params, gap, v);
            let steps = 200;
            run(&mut dem, steps as u64, dt);
            let (_, u, _) = dem.read().unwrap();
            let e = (u[dim] - u[0]) / v;
            let r = reference_head_on(
                hertz,
                kn,
                zeta,
                1.0,
                0.5,
                [-0.5 - 0.5 * gap, 0.5 + 0.5 * gap],
                [0.5 * v, -0.5 * v],
                dt,
                steps,
            );
            let e_ref = (r[1] - r[0]) / v;
            let b = dem.books().unwrap();
            let ke = b.kinetic + b.rotational;
            let balance = (ke + b.damping) / (0.25 * v * v) - 1.0;
            eprintln!(
                "{dim}D {law:?} ζ = {zeta}: e = {e:.12} (host {e_ref:.12}, {:+.1e}); books {balance:+.1e}",
                e - e_ref
            );
            assert!((e - e_ref).abs() < 1e-10, "{dim}D {law:?}: device e = {e}, host e = {e_ref}");
            assert!(e > 0.1 && e < 0.9, "{e}");
            assert!(balance.abs() < 1e-12, "{dim}D {law:?}: kinetic + dissipated off by {balance:e}");
        }
    }
}

/// Positions, velocities, radii, masses, ω.
type Cloud = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

/// `n` grains in the unit box, radius `r` (± 20 %), random velocities and ω, overlapping.
fn cloud(dim: usize, n: usize, r: f64, seed: u64) -> Cloud {
    let mut k = seed * 1_000_003;
    let mut next = || {
        k += 1;
        unit(k)
    };
    let x: Vec<f64> = (0..n * dim).map(|_| next()).collect();
    let v: Vec<f64> = (0..n * dim).map(|_| next() - 0.5).collect();
    let rad: Vec<f64> = (0..n).map(|_| r * (0.8 + 0.4 * next())).collect();
    let m: Vec<f64> = rad.iter().map(|&q| (q / r).powi(dim as i32)).collect();
    let ad = if dim == 2 { 1 } else { 3 };
    let w: Vec<f64> = (0..n * ad).map(|_| 20.0 * (next() - 0.5)).collect();
    (x, v, rad, m, w)
}

/// Total momentum and angular momentum about the origin (Σ m x × v + I ω; 2D: the z part).
fn momenta(dim: usize, beta: f64, x: &[f64], v: &[f64], w: &[f64], r: &[f64], m: &[f64]) -> ([f64; 3], [f64; 3], f64) {
    let (mut p, mut l, mut scale) = ([0.0; 3], [0.0; 3], 0.0);
    for i in 0..m.len() {
        let mut xi = [0.0; 3];
        let mut vi = [0.0; 3];
        xi[..dim].copy_from_slice(&x[dim * i..dim * i + dim]);
        vi[..dim].copy_from_slice(&v[dim * i..dim * i + dim]);
        let c = [xi[1] * vi[2] - xi[2] * vi[1], xi[2] * vi[0] - xi[0] * vi[2], xi[0] * vi[1] - xi[1] * vi[0]];
        let inertia = beta * m[i] * r[i] * r[i];
        for a in 0..3 {
            p[a] += m[i] * vi[a];
            l[a] += m[i] * c[a];
        }
        if dim == 2 {
            l[2] += inertia * w[i];
        } else {
            for a in 0..3 {
                l[a] += inertia * w[3 * i + a];
            }
        }
        scale += m[i] * vi.iter().map(|q| q * q).sum::<f64>().sqrt();
    }
    (p, l, scale)
}

#[test]
fn an_exploding_cloud_keeps_its_momentum_and_angular_momentum() {
    let Some(gpu) = gpu() else { return };
    for (dim, r) in [(2, 0.0226), (3, 0.06)] {
        let n = 500;
        let (x, v, rad, m, w) = cloud(dim, n, r, dim as u64);
        let params = DemParams {
            stiffness: 1e4,
            zeta: 0.2,
            friction: 0.5,
            rolling_friction: 0.1,
            rolling_damping: 0.3,
            capacity: 24,
            lower: [0.0; 3],
            upper: [1.0; 3],
            ..Default::default()
        };
        let mut dem = Dem::new(gpu.clone(), Precision::F64, dim, params, &x, &v, &rad, &m, &[]).unwrap();
        dem.set_omega(&w).unwrap();
        let beta = dem.inertia_factor();
        let (p0, l0, scale) = momenta(dim, beta, &x, &v, &w, &rad, &m);
        run(&mut dem, 300, 1e-4);
        let touching = dem.contacts().unwrap();
        let (x1, v1, w1) = dem.read().unwrap();
        let (p1, l1, _) = momenta(dim, beta, &x1, &v1, &w1, &rad, &m);
        let dp = (0..3).map(|a| (p1[a] - p0[a]).abs()).fold(0.0, f64::max) / scale;
        let dl = (0..3).map(|a| (l1[a] - l0[a]).abs()).fold(0.0, f64::max) / scale;
        let moved = (0..n * dim).map(|k| (v1[k] - v[k]).abs()).fold(0.0, f64::max);
        let spun = (0..w.len()).map(|k| (w1[k] - w[k]).abs()).fold(0.0, f64::max);
        eprintln!(
            "{dim}D cloud of {n}: {touching} contact ends live; |ΔP|/Σm|v| {dp:.1e}, |ΔL|/Σm|v| {dl:.1e} (max |Δv| {moved:.2}, |Δω| {spun:.2})"
        );
        assert!(touching > 50 && moved > 0.5 && spun > 1.0, "the cloud must interact: {touching} {moved} {spun}");
        // Both ends of each pair hold the same spring, bit for bit.
        let raw = dem.save_raw().unwrap();
        let (k, sv) = (dem.capacity(), raw.springs.len() / (n * dem.capacity()));
        let entry = |i: usize, q: usize| &raw.springs[(i * k + q) * sv..(i * k + q + 1) * sv];
        let partners = |i: usize| &raw.keys[i * (k + 1) + 1..i * (k + 1) + 1 + raw.keys[i * (k + 1)] as usize];
        let mut pairs = 0;
        for i in 0..n {
            for (q, &j) in partners(i).iter().enumerate() {
                let j = j as usize;
                let back = partners(j).iter().position(|&b| b as usize == i).expect("the partner holds the contact");
                assert!(entry(i, q) == entry(j, back), "grains {i} and {j} hold different springs");
                pairs += (entry(i, q)[0] != 0.0) as usize;
            }
        }
        eprintln!("{dim}D cloud: both ends of {} contacts hold the same spring ({pairs} ends non-zero)", touching / 2);
        assert!(pairs > 50);
        assert!(dp < 1e-13, "{dim}D momentum drifted by {dp:e}");
        assert!(dl < 1e-13, "{dim}D angular momentum drifted by {dl:e}");
    }
}

#[test]
fn a_grain_sliding_on_a_floor_ends_rolling() {
    let Some(gpu) = gpu() else { return };
    let (r, m, kn, g, v0, mu) = (0.1, 1.0f64, 1e5f64, 9.81, 2.0, 0.3);
    let floor = Wall::plane([0.0; 3], [0.0, 1.0, 0.0], 0.5, mu);
    let dt = std::f64::consts::PI / (kn / m).sqrt() / 50.0;
    for dim in [2, 3] {
        let mut x = vec![0.0; dim];
        x[1] = r - m * g / kn;
        let mut v = vec![0.0; dim];
        v[0] = v0;
        let params = DemParams {
            stiffness: kn,
            friction: mu,
            gravity: [0.0, -g, 0.0],
            lower: [-1.0; 3],
            upper: [3.0; 3],
            ..Default::default()
        };
        let mut dem = Dem::new(gpu.clone(), Precision::F64, dim, params, &x, &v, &[r], &[m], &[floor]).unwrap();
        let beta = dem.inertia_factor();
        // Slides for v0 β/((1 + β) μ g) (0.23 s for a disc): run twice that.
        let t_roll = v0 * beta / ((1.0 + beta) * mu * g);
        run(&mut dem, (2.0 * t_roll / dt) as u64, dt);
        let (x1, v1, w1) = dem.read().unwrap();
        let wz = if dim == 2 { w1[0] } else { w1[2] };
        let ratio = v1[0] / v0;
        let expect = 1.0 / (1.0 + beta);
        let slip = (v1[0] + wz * r) / v1[0];
        let b = dem.books().unwrap();
        eprintln!(
            "{dim}D rolling: v/v0 = {ratio:.6} (no-slip {expect:.6}, {:+.1e}); (v + ω r)/v = {slip:+.1e}; y = {:.6}; friction lost {:.4} J",
            ratio / expect - 1.0,
            x1[1],
            b.friction
        );
        assert!((ratio / expect - 1.0).abs() < 2e-3, "{dim}D v/v0 = {ratio}, no-slip rolling {expect}");
        assert!(slip.abs() < 2e-3, "{dim}D still slipping: (v + ω r)/v = {slip}");
        assert!((x1[1] - (r - m * g / kn)).abs() < 1e-3 * r, "{dim}D left the floor: y = {}", x1[1]);
    }
}

#[test]
fn rolling_resistance_stops_a_rolling_grain_at_the_rate_of_its_torque() {
    let Some(gpu) = gpu() else { return };
    let (r, m, kn, g, v0, mu_r) = (0.1, 1.0f64, 1e5f64, 9.81, 0.5, 0.05);
    let floor = Wall::plane([0.0; 3], [0.0, 1.0, 0.0], 0.5, 0.5);
    let dt = std::f64::consts::PI / (kn / m).sqrt() / 50.0;
    for dim in [2, 3] {
        let mut x = vec![0.0; dim];
        x[1] = r - m * g / kn;
        let mut v = vec![0.0; dim];
        v[0] = v0;
        let params = DemParams {
            stiffness: kn,
            friction: 0.5,
            rolling_friction: mu_r,
            rolling_damping: 0.3,
            gravity: [0.0, -g, 0.0],
            lower: [-1.0; 3],
            upper: [3.0; 3],
            ..Default::default()
        };
        let mut dem = Dem::new(gpu.clone(), Precision::F64, dim, params, &x, &v, &[r], &[m], &[floor]).unwrap();
        // Rolling from the start: ω r = −v.
        let w = if dim == 2 { vec![-v0 / r] } else { vec![0.0, 0.0, -v0 / r] };
        dem.set_omega(&w).unwrap();
        let beta = dem.inertia_factor();
        let b0 = dem.books().unwrap();
        // M = μ_r r m g against (I + m r²) ω̇: a = μ_r g/(1 + β), at rest after v0 (1 + β)/(μ_r g).
        let a = mu_r * g / (1.0 + beta);
        let half = (0.5 * v0 / a / dt).round() as u64;
        run(&mut dem, half, dt);
        let (_, v1, _) = dem.read().unwrap();
        let expect = v0 - a * half as f64 * dt;
        run(&mut dem, 2 * half, dt);
        let (_, v2, w2) = dem.read().unwrap();
        let b = dem.books().unwrap();
        let lost = b.damping + b.friction;
        let balance = (b.total() - b0.total()) / lost;
        eprintln!(
            "{dim}D rolling resistance: v = {:.6} m/s halfway (torque's rate {expect:.6}, {:+.1e}); then v = {:.1e} m/s, \
             ω = {:.1e} rad/s; books {balance:+.1e} of the {lost:.4} J lost",
            v1[0],
            v1[0] / expect - 1.0,
            v2[0],
            w2.iter().fold(0.0f64, |s, w| s.max(w.abs()))
        );
        assert!((v1[0] / expect - 1.0).abs() < 0.01, "{dim}D halfway v = {}, expected {expect}", v1[0]);
        assert!(
            v2[0].abs() < 1e-3 * v0 && w2.iter().all(|w| w.abs() < 1e-2 * v0 / r),
            "{dim}D still rolling: {v2:?} {w2:?}"
        );
        assert!(balance.abs() < 1e-9, "{dim}D books off by {balance:e}");
    }
}

/// A pile: grains of radius 3–4 cm on a lattice above a floor between two walls, random
/// velocities, gravity down y.
fn pile(gpu: &Arc<Gpu>, p: Precision, dim: usize, across: usize, rows: usize, seed: u64) -> Dem {
    let per_row = if dim == 2 { across } else { across * across };
    let n = per_row * rows;
    let (mut x, mut v, mut rad, mut m) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for i in 0..n {
        let (row, k) = (i / per_row, i % per_row);
        let c = [0.05 + 0.09 * (k % across) as f64, 0.1 + 0.09 * row as f64, 0.05 + 0.09 * (k / across) as f64];
        let q = 0.03 + 0.01 * unit(seed * 7919 + i as u64);
        x.extend_from_slice(&[c[0], c[1], c[2]][..dim]);
        for a in 0..dim {
            v.push(unit(seed * 104_729 + (dim * i + a) as u64) - 0.5);
        }
        rad.push(q);
        m.push((q / 0.035).powi(dim as i32));
    }
    let w = 0.09 * across as f64;
    let wall = |point: [f64; 3], normal: [f64; 3]| Wall::plane(point, normal, 0.5, 0.5);
    let mut walls =
        vec![wall([0.0; 3], [0.0, 1.0, 0.0]), wall([0.0; 3], [1.0, 0.0, 0.0]), wall([w, 0.0, 0.0], [-1.0, 0.0, 0.0])];
    if dim == 3 {
        walls.push(wall([0.0; 3], [0.0, 0.0, 1.0]));
        walls.push(wall([0.0, 0.0, w], [0.0, 0.0, -1.0]));
    }
    let params = DemParams {
        stiffness: 1e5,
        zeta: 0.5,
        friction: 0.5,
        gravity: [0.0, -9.81, 0.0],
        lower: [0.0; 3],
        upper: [w, 0.1 + 0.09 * rows as f64, w],
        ..Default::default()
    };
    Dem::new(gpu.clone(), p, dim, params, &x, &v, &rad, &m, &walls).unwrap()
}

/// The pile's step: a 50th of the linear contact duration π/√(k_n/m*) (m* = ½ the largest mass).
fn pile_dt(dim: usize) -> f64 {
    let m_max = (0.04f64 / 0.035).powi(dim as i32);
    std::f64::consts::PI / (1e5 / (0.5 * m_max)).sqrt() / 50.0
}

#[test]
fn a_pile_settles_on_the_floor_with_its_books_balanced() {
    let Some(gpu) = gpu() else { return };
    for (dim, across, rows, seconds) in [(2, 8, 8, 4.0), (3, 4, 4, 3.0)] {
        let mut dem = pile(&gpu, Precision::F64, dim, across, rows, 1);
        let n = dem.len();
        // A 25th of the contact duration: the books balance to rounding at any stable step
        // (gravity's drift is taken out exactly below), and settling takes half the steps.
        let dt = 2.0 * pile_dt(dim);
        let b0 = dem.books().unwrap();
        let (_, v0, _) = dem.read().unwrap();
        let mass = dem.masses().to_vec();
        // Semi-implicit Euler's own error in gravity's work, ½dt Σ m g·(v₀ − v): the books are
        // checked with it taken out (and without it at rest, where it is ½dt Σ m g·v₀).
        let drift = |v: &[f64]| -> f64 {
            (0..n).map(|i| 0.5 * dt * mass[i] * -9.81 * (v0[dim * i + 1] - v[dim * i + 1])).sum()
        };
        let (mut ke_max, mut total_err, mut t) = (b0.kinetic, 0.0f64, 0.0);
        let chunk = 2000;
        let t0 = Instant::now();
        let mut last = b0;
        // Until at rest (a margin of 10 below the check) or `seconds`.
        while t < seconds && last.kinetic + last.rotational >= 1e-7 * ke_max {
            run(&mut dem, chunk, dt);
            t += chunk as f64 * dt;
            last = dem.books().unwrap();
            let (_, v, _) = dem.read().unwrap();
            ke_max = ke_max.max(last.kinetic + last.rotational);
            total_err = total_err.max((last.total() - b0.total() - drift(&v)).abs());
        }
        let raw = (last.total() - b0.total()).abs();
        let took = t0.elapsed().as_secs_f64();
        let (x, _, _) = dem.read().unwrap();
        let ke = last.kinetic + last.rotational;
        let lost = last.damping + last.friction;
        let lowest = (0..n).map(|i| x[dim * i + 1]).fold(f64::INFINITY, f64::min);
        eprintln!(
            "{dim}D pile of {n}: {:.0} steps in {took:.1} s; KE {ke:.2e} J (max {ke_max:.2e}, ratio {:.1e}); lost {lost:.4} J \
             (damping {:.4}, friction {:.4}); books off at rest by {raw:.2e} J ({:.1e} of the lost), gravity's drift taken out at most {total_err:.2e} J ({:.1e}); \
             lowest centre {lowest:.4}",
            t / dt,
            ke / ke_max,
            last.damping,
            last.friction,
            raw / lost,
            total_err / lost
        );
        assert!(ke < 1e-6 * ke_max, "{dim}D pile still moving: KE {ke:e} of {ke_max:e}");
        assert!(lowest > 0.0295, "{dim}D a grain sank through the floor: {lowest}");
        assert!(last.friction > 0.0 && last.damping > 0.0);
        assert!(total_err < 1e-9 * lost, "{dim}D books off by {total_err:e} J of {lost:e} J dissipated");
    }
}

/// Two grains (radius 0.5, mass 1) colliding off-centre with spin, and a third hitting the wall
/// x = 3 obliquely; μ = 0.5, ζ = 0.3.
fn oblique(gpu: &Arc<Gpu>, p: Precision, dim: usize) -> Dem {
    let pts = [[-0.48, 0.3, 0.1], [0.48, -0.2, 0.0], [2.45, 0.0, 0.0]];
    let vel = [[1.0, 0.0, 0.0], [-1.0, 0.1, 0.0], [1.5, 0.7, 0.2]];
    let (mut x, mut v) = (Vec::new(), Vec::new());
    for k in 0..3 {
        x.extend_from_slice(&pts[k][..dim]);
        v.extend_from_slice(&vel[k][..dim]);
    }
    let params =
        DemParams { stiffness: 1e5, zeta: 0.3, friction: 0.5, lower: [-3.0; 3], upper: [4.0; 3], ..Default::default() };
    let wall = Wall::plane([3.0, 0.0, 0.0], [-1.0, 0.0, 0.0], 0.3, 0.5);
    let mut dem = Dem::new(gpu.clone(), p, dim, params, &x, &v, &[0.5; 3], &[1.0; 3], &[wall]).unwrap();
    let w: Vec<f64> = if dim == 2 { vec![3.0, -2.0, 5.0] } else { vec![3.0, 1.0, -2.0, 0.0, 2.0, 1.0, 1.0, -1.0, 5.0] };
    dem.set_omega(&w).unwrap();
    dem
}

#[test]
fn runs_repeat_bit_for_bit_and_f32_follows_f64() {
    let Some(gpu) = gpu() else { return };
    for dim in [2, 3] {
        let (across, rows) = if dim == 2 { (10, 6) } else { (4, 4) };
        let dt = pile_dt(dim);
        let mut bits = Vec::new();
        for _ in 0..2 {
            let mut dem = pile(&gpu, Precision::F64, dim, across, rows, 2);
            // Long enough for the pile's contacts to form, slip and roll (lavapipe runs a
            // contact step in ~3 ms whatever the size: the suite's time is in these loops).
            run(&mut dem, 800, dt);
            assert!(dem.contacts().unwrap() > 0, "{dim}D: the grains touch");
            let (x, v, w) = dem.read().unwrap();
            let b = dem.books().unwrap();
            let all: Vec<u64> = x
                .iter()
                .chain(&v)
                .chain(&w)
                .chain(&[b.damping, b.friction, b.potential])
                .map(|q| q.to_bits())
                .collect();
            bits.push(all);
        }
        assert!(bits[0] == bits[1], "{dim}D: two runs differ");
        // f32 against f64: oblique collisions with friction and spin (a pair, a grain and a
        // wall), which amplify no rounding (a pile's collisions amplify it without bound).
        let mut out = Vec::new();
        for p in [Precision::F64, Precision::F32] {
            let mut dem = oblique(&gpu, p, dim);
            let dt = std::f64::consts::PI / (1e5f64 / 0.5).sqrt() / 50.0;
            let w0 = dem.read().unwrap().2;
            run(&mut dem, 600, dt);
            assert_eq!(dem.contacts().unwrap(), 0, "the collisions are over");
            let o = dem.read().unwrap();
            let ad = w0.len() / 3;
            let turned = (0..3).all(|i| (0..ad).map(|a| (o.2[ad * i + a] - w0[ad * i + a]).abs()).sum::<f64>() > 0.1);
            assert!(turned, "every grain collided: {w0:?} {:?}", o.2);
            out.push(o);
        }
        let diff = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        let (dx, dv, dw) = (diff(&out[0].0, &out[1].0), diff(&out[0].1, &out[1].1), diff(&out[0].2, &out[1].2));
        eprintln!("{dim}D: two runs bit-identical; f32 vs f64 after oblique collisions: |Δx| {dx:.1e} m, |Δv| {dv:.1e} m/s, |Δω| {dw:.1e} rad/s");
        assert!(dx < 1e-4 && dv < 1e-3 && dw < 2e-3, "{dim}D f32 off: {dx} {dv} {dw}");
    }
}

#[test]
fn snapshot_and_restore_repeat_the_steps() {
    let Some(gpu) = gpu() else { return };
    let mut dem = pile(&gpu, Precision::F64, 2, 6, 4, 4);
    let dt = pile_dt(2);
    run(&mut dem, 500, dt);
    dem.snapshot().unwrap();
    run(&mut dem, 700, dt);
    let (a, _, _) = dem.read().unwrap();
    let ba = dem.books().unwrap();
    dem.restore().unwrap();
    run(&mut dem, 700, dt);
    let (b, _, _) = dem.read().unwrap();
    assert!(a == b && ba == dem.books().unwrap(), "restore then the same steps must repeat the bits");
    // A checkpoint loaded into a new `Dem` continues with the same bits.
    let raw = dem.save_raw().unwrap();
    run(&mut dem, 300, dt);
    let mut other = pile(&gpu, Precision::F64, 2, 6, 4, 4);
    other.load_raw(&raw).unwrap();
    run(&mut other, 300, dt);
    assert!(
        dem.save_raw().unwrap() == other.save_raw().unwrap(),
        "a loaded checkpoint must continue with the same bits"
    );
    let mut bad = raw.clone();
    bad.keys[1] = 1000;
    bad.keys[0] = 1;
    assert!(other.load_raw(&bad).is_err());
}

/// The 2D rotation angle: θ' = θ + dt ω' each step (the CPU's `end_step`), for a disc spinning
/// free and one rolling on a floor; kept by checkpoints, snapshots and `load_raw`; none in 3D.
#[test]
fn the_2d_angle_follows_the_spin_and_is_kept() {
    let Some(gpu) = gpu() else { return };
    let floor = Wall::plane([0.0; 3], [0.0, 1.0, 0.0], 0.5, 0.3);
    let params = DemParams {
        stiffness: 1e5,
        friction: 0.3,
        gravity: [0.0, -9.81, 0.0],
        lower: [-1.0; 3],
        upper: [3.0; 3],
        ..Default::default()
    };
    let (x, v) = ([0.0, 2.0, 0.5, 0.1 - 9.81e-5], [0.0, 0.0, 2.0, 0.0]);
    let mut dem = Dem::new(gpu.clone(), Precision::F64, 2, params, &x, &v, &[0.1; 2], &[1.0; 2], &[floor]).unwrap();
    dem.set_omega(&[3.0, 0.0]).unwrap();
    let dt = 1e-4;
    let (mut want, mut steps) = ([0.0f64; 2], 0);
    for _ in 0..40 {
        run(&mut dem, 5, dt);
        steps += 5;
        // ω is constant between the reads only for the free disc: the rolling one is summed
        // from the ω the device reports at each read, as a check of the sign and the scale.
        let w = dem.read().unwrap().2;
        want[1] += 5.0 * dt * w[1];
    }
    want[0] = (0..steps).fold(0.0, |a, _| a + dt * 3.0);
    let a = dem.angles().unwrap();
    let (w, r) = (dem.read().unwrap().2, 0.1);
    eprintln!("2D angles after {steps} steps: {a:?} (free {:.6}, rolling ≈ {:.6}); ω {w:?}", want[0], want[1]);
    assert!((a[0] - want[0]).abs() < 1e-12, "free disc: {} vs {}", a[0], want[0]);
    // Rolling to +x turns the disc clockwise: θ < 0, near the ω-sum (which lags by ≤ 5 steps).
    assert!(a[1] < 0.0 && (a[1] - want[1]).abs() < 0.05 * want[1].abs(), "rolling disc: {} vs {}", a[1], want[1]);
    assert!(w[1] * r < 0.0);
    // Checkpoints carry the angle; a snapshot restores it.
    let raw = dem.save_raw().unwrap();
    assert_eq!(raw.angle, a);
    dem.snapshot().unwrap();
    run(&mut dem, 50, dt);
    let later = dem.angles().unwrap();
    assert!(later[0] > a[0]);
    dem.restore().unwrap();
    assert_eq!(dem.angles().unwrap(), a);
    let mut other = Dem::new(gpu.clone(), Precision::F64, 2, params, &x, &v, &[0.1; 2], &[1.0; 2], &[floor]).unwrap();
    other.load_raw(&raw).unwrap();
    run(&mut other, 50, dt);
    run(&mut dem, 50, dt);
    assert_eq!(other.angles().unwrap(), later);
    assert_eq!(dem.save_raw().unwrap(), other.save_raw().unwrap());
    let mut short = raw.clone();
    short.angle.pop();
    assert!(other.load_raw(&short).is_err(), "an angle missing is refused");
    // 3D keeps no angle.
    let x3 = [0.0, 0.0, 2.0];
    let mut d3 = Dem::new(gpu.clone(), Precision::F64, 3, params, &x3, &[0.0; 3], &[0.1], &[1.0], &[]).unwrap();
    d3.set_omega(&[1.0, 2.0, 3.0]).unwrap();
    run(&mut d3, 3, dt);
    assert_eq!(d3.angles().unwrap(), vec![0.0]);
    assert!(d3.save_raw().unwrap().angle.is_empty());
    assert!(d3.max_overlap().unwrap() == 0.0);
    // The largest overlap of the last evaluation: the rolling disc's on the floor.
    let o = dem.max_overlap().unwrap();
    assert!(o > 0.5 * 9.81e-5 && o < 2.0 * 9.81e-5, "max overlap {o}");
}

#[test]
fn overflow_and_non_finite_values_halt_with_an_error() {
    let Some(gpu) = gpu() else { return };
    let params = DemParams { capacity: 3, lower: [-1.0; 3], upper: [1.0; 3], ..Default::default() };
    // Five grains around a sixth, all overlapping it: six contacts on the centre grain.
    let mut x = vec![0.0, 0.0];
    for k in 0..5 {
        let a = k as f64 * 2.0 * std::f64::consts::PI / 5.0;
        x.extend_from_slice(&[0.15 * a.cos(), 0.15 * a.sin()]);
    }
    let v = vec![0.0; 12];
    let mut dem = Dem::new(gpu.clone(), Precision::F64, 2, params, &x, &v, &[0.1; 6], &[1.0; 6], &[]).unwrap();
    match dem.step(10, 1e-4, &go()) {
        Err((0, Halt::Failed(GpuError::Unsupported(m)))) => {
            eprintln!("overflow: {m}");
            assert!(m.contains("grain 0") && m.contains("more than 3"), "{m}");
        }
        o => panic!("expected a capacity halt, got {o:?}"),
    }
    // Non-finite input is refused by name.
    let mut bad = x.clone();
    bad[5] = f64::NAN;
    let e = Dem::new(gpu.clone(), Precision::F64, 2, params, &bad, &v, &[0.1; 6], &[1.0; 6], &[]).err().unwrap();
    assert!(e.to_string().contains("grain 2 has a non-finite value"), "{e}");
    let e = Dem::new(gpu.clone(), Precision::F64, 2, params, &x, &v, &[0.1; 6], &[1.0, 1.0, -1.0, 1.0, 1.0, 1.0], &[])
        .err();
    assert!(e.unwrap().to_string().contains("mass: grain 2"));
    assert!(matches!(dem.step(1, f64::NAN, &go()), Err((0, Halt::Failed(_)))));
    // A grain between two walls with a step far past stable grows until it is not finite.
    let walls =
        [Wall::plane([0.0; 3], [0.0, 1.0, 0.0], 0.0, 0.0), Wall::plane([0.0, 1.0, 0.0], [0.0, -1.0, 0.0], 0.0, 0.0)];
    for p in [Precision::F32, Precision::F64] {
        let params = DemParams { stiffness: 1e5, lower: [-1.0; 3], upper: [2.0; 3], ..Default::default() };
        let mut dem = Dem::new(gpu.clone(), p, 2, params, &[0.0, 0.4], &[0.0, 0.0], &[0.5], &[1.0], &walls).unwrap();
        match dem.step(10_000, 1.0, &go()) {
            Err((k, Halt::Diverged { particle: 0 })) => eprintln!("{p:?}: diverged, halted after {k} steps"),
            o => panic!("expected a divergence, got {o:?}"),
        }
    }
    // A raised stop flag stops before the first step.
    assert!(matches!(dem.step(5, 1e-4, &AtomicBool::new(true)), Err((0, Halt::Stopped))));
}

#[test]
#[ignore = "a benchmark: cargo test --release -p physcore-gpu --test dem -- --ignored --nocapture"]
fn bench_discs() {
    let Some(gpu) = gpu() else { return };
    for side in [100usize, 316, 1000] {
        let n = side * side;
        let (r, gap) = (0.5, 1.05);
        let (mut x, mut v) = (Vec::with_capacity(2 * n), Vec::with_capacity(2 * n));
        for i in 0..n {
            x.extend_from_slice(&[(i % side) as f64 * gap + 0.6, (i / side) as f64 * gap + 0.6]);
            v.extend_from_slice(&[unit(2 * i as u64) - 0.5, unit(2 * i as u64 + 1) - 0.5]);
        }
        let w = side as f64 * gap + 1.2;
        let wall = |point: [f64; 3], normal: [f64; 3]| Wall::plane(point, normal, 0.3, 0.5);
        let walls =
            [wall([0.0; 3], [0.0, 1.0, 0.0]), wall([0.0; 3], [1.0, 0.0, 0.0]), wall([w, 0.0, 0.0], [-1.0, 0.0, 0.0])];
        let params = DemParams {
            stiffness: 1e5,
            zeta: 0.3,
            friction: 0.5,
            gravity: [0.0, -9.81, 0.0],
            lower: [0.0; 3],
            upper: [w, w, 1.0],
            ..Default::default()
        };
        for p in [Precision::F32, Precision::F64] {
            if p == Precision::F64 && !gpu.adapter().f64 {
                continue;
            }
            let mut dem = match Dem::new(gpu.clone(), p, 2, params, &x, &v, &vec![r; n], &vec![1.0; n], &walls) {
                Ok(d) => d,
                Err(e) => {
                    eprintln!("{n} discs {p:?}: skipped ({e})");
                    continue;
                }
            };
            let dt = 1e-4;
            run(&mut dem, 5, dt);
            // Doubling calls until one second has passed.
            let (mut steps, mut k, t0) = (0u64, 5u64, Instant::now());
            while t0.elapsed().as_secs_f64() < 1.0 {
                run(&mut dem, k, dt);
                steps += k;
                k *= 2;
            }
            let s = t0.elapsed().as_secs_f64();
            eprintln!(
                "{n} discs {p:?}: {:.3e} particle-steps/s ({steps} steps in {s:.2} s)",
                (n as u64 * steps) as f64 / s
            );
        }
    }
}

/// `contacts_once` (counted on the device) against the count the host makes from the whole
/// committed history (`save_raw`): grain pairs once, grain–wall contacts once; a settling pile
/// with walls, 2D and 3D, f32 and f64; and none for no grains.
#[test]
fn the_device_counts_each_contact_once_as_the_host() {
    let Some(gpu) = gpu() else { return };
    for p in [Precision::F32, Precision::F64] {
        if gpu.check_precision(p).is_err() {
            continue;
        }
        for (dim, across, rows) in [(2, 10, 6), (3, 4, 4)] {
            let mut dem = pile(&gpu, p, dim, across, rows, 3);
            run(&mut dem, 300, pile_dt(dim));
            let raw = dem.save_raw().unwrap();
            let (n, k) = (dem.len(), dem.capacity());
            let (mut pairs, mut walls) = (0u64, 0u64);
            for i in 0..n {
                let row = &raw.keys[i * (k + 1)..(i + 1) * (k + 1)];
                for &q in &row[1..=row[0] as usize] {
                    pairs += ((q as usize) > i && (q as usize) < n) as u64;
                    walls += (q as usize >= n) as u64;
                }
            }
            assert!(pairs > 0 && walls > 0, "{p:?} {dim}D: {pairs} pairs and {walls} wall contacts");
            assert_eq!(dem.contacts_once().unwrap(), pairs + walls, "{p:?} {dim}D");
            assert_eq!(dem.contacts().unwrap() as u64, 2 * pairs + walls, "{p:?} {dim}D");
        }
    }
    let box1 = DemParams { cell: 0.1, lower: [0.0; 3], upper: [1.0; 3], ..Default::default() };
    let none = Dem::new(gpu.clone(), Precision::F32, 2, box1, &[], &[], &[], &[], &[]).unwrap();
    assert_eq!(none.contacts_once().unwrap(), 0);
}

/// Pegs: pinned grains on a staggered lattice (two of them overlapping each other and one
/// overlapping the floor: neither may push), with a rain of free grains falling onto them under
/// gravity, friction and rolling resistance; returns the system and the pinned flags.
fn pegboard(gpu: &Arc<Gpu>, p: Precision, dim: usize) -> (Dem, Vec<bool>) {
    let (mut x, mut v, mut rad, mut m, mut pinned) = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut put = |c: [f64; 3], u: [f64; 3], r: f64, pin: bool| {
        x.extend_from_slice(&c[..dim]);
        v.extend_from_slice(&u[..dim]);
        rad.push(r);
        m.push((r / 0.03).powi(dim as i32));
        pinned.push(pin);
    };
    // Free grains first, a queue above the pegs, a little off their axes.
    for k in 0..12 {
        let j = k as f64;
        let c =
            [0.25 + 0.07 * (k % 4) as f64 + 0.004 * unit(k), 0.66 + 0.07 * (k / 4) as f64, 0.25 + 0.01 * unit(99 + k)];
        put(c, [0.1 * (unit(7 * k) - 0.5), -0.5, 0.1 * (unit(11 * k) - 0.5)], 0.025 + 0.002 * (j % 3.0), false);
    }
    for row in 0..3 {
        for k in 0..5 {
            let c = [0.1 + 0.1 * k as f64 + 0.05 * (row % 2) as f64, 0.55 - 0.12 * row as f64, 0.25];
            // The pegs are given a velocity: pinning sets it to 0.
            put(c, [0.3, 0.2, 0.1], 0.02, true);
        }
    }
    put([0.62, 0.56, 0.25], [0.0; 3], 0.02, true); // overlaps the first row's last peg
    put([0.3, 0.01, 0.25], [0.0; 3], 0.02, true); // overlaps the floor
    let wall = |point: [f64; 3], normal: [f64; 3]| Wall::plane(point, normal, 0.4, 0.4);
    let walls =
        [wall([0.0; 3], [0.0, 1.0, 0.0]), wall([0.0; 3], [1.0, 0.0, 0.0]), wall([0.7, 0.0, 0.0], [-1.0, 0.0, 0.0])];
    let params = DemParams {
        stiffness: 1e5,
        zeta: 0.4,
        friction: 0.4,
        rolling_friction: 0.05,
        rolling_damping: 0.3,
        gravity: [0.0, -9.81, 0.0],
        lower: [0.0; 3],
        upper: [0.7, 1.1, 0.5],
        ..Default::default()
    };
    let mut dem = Dem::new(gpu.clone(), p, dim, params, &x, &v, &rad, &m, &walls).unwrap();
    dem.set_pinned(&pinned).unwrap();
    (dem, pinned)
}

/// Pinned grains are fixed obstacles: grains rain onto them for 0.12 s and they stay where they
/// were to the bit, at rest and unturned (f64 and f32, 2D and 3D), while the free grains touch
/// them; the books leave them out and balance as a board without them does.
#[test]
fn pinned_grains_stay_still_to_the_bit_while_grains_rain_onto_them() {
    let Some(gpu) = gpu() else { return };
    for dim in [2, 3] {
        for p in [Precision::F64, Precision::F32] {
            let (mut dem, pinned) = pegboard(&gpu, p, dim);
            let n = dem.len();
            // A 59th of the pegs' contact duration π√(m*/k_n).
            let dt = 1e-4;
            let (x0, v0, w0) = dem.read().unwrap();
            let a0 = dem.angles().unwrap();
            let mass = dem.masses().to_vec();
            let b0 = dem.books().unwrap();
            let pins: Vec<usize> = (0..n).filter(|&i| pinned[i]).collect();
            assert!(pins.iter().all(|&i| (0..dim).all(|a| v0[dim * i + a] == 0.0)), "pinning stops a grain");
            let (mut peg_contacts, mut most) = (0usize, 0usize);
            for _ in 0..12 {
                run(&mut dem, 100, dt);
                let raw = dem.save_raw().unwrap();
                let k = dem.capacity();
                let on_pegs: usize = pins.iter().map(|&i| raw.keys[i * (k + 1)] as usize).sum();
                peg_contacts += on_pegs;
                most = most.max(on_pegs);
                // No peg holds a contact with another peg or a wall.
                for &i in &pins {
                    let row = &raw.keys[i * (k + 1) + 1..i * (k + 1) + 1 + raw.keys[i * (k + 1)] as usize];
                    assert!(row.iter().all(|&j| (j as usize) < n && !pinned[j as usize]), "{dim}D peg {i}: {row:?}");
                }
            }
            let (x, v, w) = dem.read().unwrap();
            let a = dem.angles().unwrap();
            let b = dem.books().unwrap();
            for &i in &pins {
                for c in 0..dim {
                    assert_eq!(x[dim * i + c].to_bits(), x0[dim * i + c].to_bits(), "{dim}D {p:?} peg {i} moved");
                    assert_eq!(v[dim * i + c].to_bits(), 0f64.to_bits(), "{dim}D {p:?} peg {i} has a velocity");
                }
                let ad = if dim == 2 { 1 } else { 3 };
                assert!((0..ad).all(|c| w[ad * i + c] == w0[ad * i + c] && w[ad * i + c] == 0.0), "peg {i} turned");
                assert_eq!(a[i], a0[i]);
            }
            // The free grains fell onto the pegs and bounced off them.
            let fell = (0..n).filter(|&i| !pinned[i]).all(|i| x[dim * i + 1] < x0[dim * i + 1] - 0.05);
            // Gravity's work in semi-implicit Euler, ½dt Σ m g·(v₀ − v) (free grains; the pegs'
            // velocities are 0), taken out of the balance as in the pile's test.
            let drift: f64 = (0..n)
                .filter(|&i| !pinned[i])
                .map(|i| 0.5 * dt * mass[i] * -9.81 * (v0[dim * i + 1] - v[dim * i + 1]))
                .sum();
            let lost = b.damping + b.friction;
            let off = (b.total() - b0.total() - drift).abs();
            eprintln!(
                "{dim}D {p:?} pegboard, {} pegs: {peg_contacts} peg contacts seen ({most} at once), lost {lost:.3e} J, \
                 books off by {off:.1e} J ({:.1e} of it); pegs still to the bit",
                pins.len(),
                off / lost
            );
            assert!(fell && most > 0 && lost > 0.0, "{dim}D {p:?}: the grains met the pegs");
            if p == Precision::F64 {
                assert!(off < 1e-9 * lost, "{dim}D books off by {off:e} J of {lost:e} J");
            }
        }
    }
}

/// A grain falling head-on onto a pinned grain bounces as off a plane wall of the same ζ at the
/// same overlap: m* = m of the free grain, the pinned one unmoved (the same trajectory to
/// rounding, both laws); and the restitution is the model's.
#[test]
fn a_grain_bounces_off_a_pinned_grain_as_off_a_wall() {
    let Some(gpu) = gpu() else { return };
    let (kn, v, m, r) = (1e5f64, 1.0f64, 0.7f64, 0.5f64);
    let zeta = 0.3;
    for (law, hertz) in [(Law::Linear, false), (Law::Hertz, true)] {
        let dmax = (5.0 * m * v * v / (4.0 * kn)).powf(0.4);
        let dt = if hertz { HERTZ_T * dmax / v / 50.0 } else { std::f64::consts::PI / (kn / m).sqrt() / 50.0 };
        for dim in [2, 3] {
            let params =
                DemParams { law, stiffness: kn, zeta, lower: [-2.0; 3], upper: [2.0; 3], ..Default::default() };
            let gap = 0.0123 * v * dt;
            // The free grain at y = 1 + gap above a pinned one at the origin, falling at v.
            let (mut x, mut u) = (vec![0.0; 2 * dim], vec![0.0; 2 * dim]);
            x[1] = 2.0 * r + gap;
            u[1] = -v;
            let mut peg = Dem::new(gpu.clone(), Precision::F64, dim, params, &x, &u, &[r, r], &[m, 3.0], &[]).unwrap();
            peg.set_pinned(&[false, true]).unwrap();
            // The same grain over a floor at y = r (the peg's top).
            let floor = Wall::plane([0.0, r, 0.0], [0.0, 1.0, 0.0], zeta, 0.0);
            let mut wall =
                Dem::new(gpu.clone(), Precision::F64, dim, params, &x[..dim], &u[..dim], &[r], &[m], &[floor]).unwrap();
            let steps = 120;
            for _ in 0..steps {
                run(&mut peg, 1, dt);
                run(&mut wall, 1, dt);
            }
            let (xp, vp, _) = peg.read().unwrap();
            let (xw, vw, _) = wall.read().unwrap();
            let e = vp[1] / v;
            let dx = (xp[1] - xw[1]).abs().max((vp[1] - vw[1]).abs() * dt);
            let b = peg.books().unwrap();
            let balance = (b.kinetic + b.damping) / (0.5 * m * v * v) - 1.0;
            eprintln!(
                "{dim}D {law:?}: off a pinned grain e = {e:.12}, off a wall {:.12}; trajectories {dx:.1e} m apart; books {balance:+.1e}",
                vw[1] / v
            );
            assert!(e > 0.1 && e < 0.9 && peg.contacts().unwrap() == 0, "{dim}D {law:?}: bounced off: {e}");
            assert!((xp[1] - xw[1]).abs() < 1e-12 && (vp[1] - vw[1]).abs() < 1e-10, "{dim}D {law:?}: {xp:?} {xw:?}");
            assert!(xp[dim..].iter().zip(&x[dim..]).all(|(a, b)| a.to_bits() == b.to_bits()), "the peg moved");
            assert!(vp[dim..].iter().all(|&c| c == 0.0));
            assert!(balance.abs() < 1e-12, "{dim}D {law:?}: books off by {balance:e}");
        }
    }
}

/// Linear drag under gravity: each grain tends to the terminal speed m g / b (the fixed point
/// of v' = v + dt (g − b v/m) too), from above and from below; the drag book is the sum of
/// dt·b|v|² over the steps (a host loop of the same expressions), the pinned grain none; the
/// books balance: with gravity's ½dt Σ m g·(v₀ − v) taken out (as in the pile's test), what is
/// left is the left-point rule's, ½dt Σ b v·(v − v'), bounded by ½dt b max|v| Σ|v_N − v₀|.
#[test]
fn drag_brings_a_grain_to_its_terminal_speed_with_its_books_balanced() {
    let Some(gpu) = gpu() else { return };
    let (b, g) = (0.05f64, 9.81f64);
    for dim in [2, 3] {
        for p in [Precision::F64, Precision::F32] {
            // Three grains far apart (no contacts), masses 0.01, 0.02, 0.03 kg, the first
            // thrown up, the second thrown down faster than terminal; a fourth pinned.
            let n = 4;
            let masses = [0.01, 0.02, 0.03, 0.05];
            let (mut x, mut u) = (vec![0.0; n * dim], vec![0.0; n * dim]);
            for i in 0..n {
                x[dim * i] = i as f64;
            }
            u[1] = 2.0;
            u[dim + 1] = -8.0;
            u[2 * dim] = 0.5;
            let params =
                DemParams { gravity: [0.0, -g, 0.0], drag: b, lower: [-1.0; 3], upper: [5.0; 3], ..Default::default() };
            let mut dem = Dem::new(gpu.clone(), p, dim, params, &x, &u, &[0.1; 4], &masses, &[]).unwrap();
            dem.set_pinned(&[false, false, false, true]).unwrap();
            // m/b = 0.2–0.6 s: a step of a 40th of the shortest (the fixed point m g / b does
            // not depend on dt), so 2,400 lavapipe steps a case rather than 12,000.
            let dt = 5e-3;
            // 20 relaxation times of the heaviest free grain, m/b = 0.6 s.
            let steps = (20.0 * 0.03 / b / dt).round() as u64;
            let b0 = dem.books().unwrap();
            let (_, v0, _) = dem.read().unwrap();
            run(&mut dem, steps, dt);
            let (_, v, _) = dem.read().unwrap();
            let books = dem.books().unwrap();
            // The host loop: the kernel's expressions in f64.
            let mut want = 0.0;
            let mut bound = 0.0;
            let mut drift = 0.0;
            for i in 0..3 {
                let mut w: Vec<f64> = v0[dim * i..dim * (i + 1)].to_vec();
                let mut vmax: f64 = 0.0;
                for _ in 0..steps {
                    let v2: f64 = w.iter().map(|c| c * c).sum();
                    want += dt * (b * v2);
                    vmax = vmax.max(v2.sqrt());
                    for (a, c) in w.iter_mut().enumerate() {
                        let ga = if a == 1 { -g } else { 0.0 };
                        *c += (*c * -b * (1.0 / masses[i]) + ga) * dt;
                    }
                }
                // Each component moves monotonically to its terminal value: Σ|v − v'| = |v_N − v₀|.
                bound += 0.5 * dt * b * vmax * (0..dim).map(|c| (v[dim * i + c] - v0[dim * i + c]).abs()).sum::<f64>();
                drift += 0.5 * dt * masses[i] * -g * (v0[dim * i + 1] - v[dim * i + 1]);
            }
            let terminal = (0..3).map(|i| (v[dim * i + 1] + masses[i] * g / b).abs() / (masses[i] * g / b));
            let terminal = terminal.fold(0.0, f64::max);
            let sideways = (0..3).map(|i| v[dim * i].abs()).fold(0.0, f64::max);
            let off = (books.total() - b0.total() - drift).abs();
            let err = (books.drag - want).abs() / want;
            eprintln!(
                "{dim}D {p:?} drag b = {b}: {steps} steps, speeds within {terminal:.1e} of m g / b; drag book {:.6e} J \
                 (host loop {err:.1e} off); books off by {off:.2e} J (bound {bound:.2e} J, of {:.3e} J dissipated)",
                books.drag, books.drag
            );
            let (x1, _, _) = dem.read().unwrap();
            assert_eq!(&x1[3 * dim..], &x[3 * dim..], "the pinned grain stayed");
            assert!(books.damping == 0.0 && books.friction == 0.0 && books.potential == 0.0);
            if p == Precision::F64 {
                assert!(terminal < 1e-8 && sideways < 1e-8, "{dim}D: {v:?}");
                assert!(err < 1e-12, "{dim}D: drag book {} vs {want}", books.drag);
                assert!(
                    off <= bound * 1.0001 + 1e-12 * books.drag && off > 0.0,
                    "{dim}D books off by {off:e} (bound {bound:e})"
                );
            } else {
                // f32: the kick stalls once dt (g − b v/m) is below half an ulp of v (≈ 3e-5 of
                // m g / b); each grain's book is a sum of `steps` f32 terms (n ε = 7e-4).
                assert!(terminal < 1e-4 && err < 1e-3, "{dim}D f32: {terminal:e} {err:e}");
            }
        }
    }
}

/// Each kind of wall out of range, and a box (its faces are planes), is refused with the wall's index and what is wrong (the
/// shapes' own checks, as the CPU's constructors make them); a 2D box reads only its first two
/// axes and half extents, so a third axis of any value is no error there.
#[test]
fn walls_out_of_range_are_refused_by_name() {
    let Some(gpu) = gpu() else { return };
    let params = DemParams { stiffness: 1e4, lower: [-1.0; 3], upper: [1.0; 3], ..DemParams::default() };
    let floor = Wall::plane([0.0, -1.0, 0.0], [0.0, 1.0, 0.0], 0.5, 0.5);
    let eye = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let nan = f64::NAN;
    let boxed = |half: [f64; 3], axes: [[f64; 3]; 3]| Shape::OrientedBox { center: [0.0; 3], half, axes };
    let bad = [
        (Shape::Plane { point: [0.0; 3], normal: [0.0; 3] }, "non-zero normal"),
        (Shape::Plane { point: [nan, 0.0, 0.0], normal: [0.0, 1.0, 0.0] }, "finite point"),
        (Shape::Sphere { center: [0.0; 3], radius: 0.0, inside: true }, "radius > 0"),
        (Shape::Sphere { center: [0.0; 3], radius: 1e200, inside: false }, "finite square"),
        (Shape::Capsule { a: [0.0; 3], b: [f64::INFINITY, 0.0, 0.0], radius: 0.1 }, "finite ends"),
        (boxed([0.5, 0.0, 0.5], eye), "half extents > 0"),
        (Shape::OrientedBox { center: [nan; 3], half: [0.5; 3], axes: eye }, "finite centre"),
        (Shape::Box { lower: [-1.0; 3], upper: [1.0; 3] }, "faces as plane walls"),
        (boxed([0.5; 3], [[1.0, 0.0, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]]), "orthogonal axes"),
        (boxed([0.5; 3], [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), "unit"),
    ];
    let (x, v) = ([0.0, 0.5, 0.0], [0.0; 3]);
    for dim in [2, 3] {
        for (shape, what) in bad {
            let walls = [floor, Wall { shape, zeta: 0.5, friction: 0.5 }];
            match Dem::new(gpu.clone(), Precision::F32, dim, params, &x[..dim], &v[..dim], &[0.1], &[1.0], &walls) {
                Err(GpuError::Unsupported(m)) => {
                    assert!(m.contains("wall 1") && m.contains(what), "{dim}D {shape:?}: {m}")
                }
                Err(e) => panic!("{dim}D {shape:?}: {e}"),
                Ok(_) => panic!("{dim}D {shape:?} was taken"),
            }
        }
        let skew = Wall {
            shape: boxed([0.5, 0.5, nan], [[1.0, 0.0, 9.0], [0.0, 1.0, 0.0], [nan; 3]]),
            zeta: 0.5,
            friction: 0.5,
        };
        let got = Dem::new(gpu.clone(), Precision::F32, dim, params, &x[..dim], &v[..dim], &[0.1], &[1.0], &[skew]);
        assert_eq!(got.is_ok(), dim == 2, "{dim}D: {:?}", got.err());
        let wrong = Wall { friction: -0.1, ..floor };
        assert!(
            Dem::new(gpu.clone(), Precision::F32, dim, params, &x[..dim], &v[..dim], &[0.1], &[1.0], &[wrong]).is_err()
        );
    }
}
