//! The device WCSPH (`physcore_gpu::sph`) against an f64 reference on the host written from the
//! same formulas (brute-force neighbours, each sum in increasing particle index): jittered blocks
//! thrown at the box's corner under gravity, 2D and 3D, both kernels, γ = 7 (the shader's fixed
//! chain) and 3 and 1 (its loop), clamped and unclamped pressure, walls with restitution and
//! friction, and static wall particles (Akinci et al. 2012) under the floor and beside the
//! block; f64 and f32; two runs repeat bit for bit; the summed density of a lattice at rest
//! is its kernel's lattice sum; a divergence halts naming a particle; bad input is refused. The
//! energy books (`Sph::books`) against the reference's, and exactly 0 viscous and wall books
//! for a fluid without viscosity that touches no wall.
//! Skips without an adapter unless `PHYSCORE_GPU_REQUIRED=1` (CI, on lavapipe).
use physcore_gpu::particles::Halt;
use physcore_gpu::sph::{Kernel, Sph, SphBooks, SphParams};
use physcore_gpu::{Gpu, GpuError, Precision};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

mod common;
use common::gpu;

/// A deterministic value in [0, 1).
fn unit(k: u64) -> f64 {
    let mut z = k.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// w(q) and g(q) = w'(q)/q as `sph.wgsl` (and the CPU's scalar kernels) write them.
fn w(k: Kernel, q: f64) -> f64 {
    match k {
        Kernel::CubicSpline => {
            let a = (2.0 - q).max(0.0);
            let b = (1.0 - q).max(0.0);
            0.25 * a * a * a - b * b * b
        }
        Kernel::WendlandC2 => {
            let t = (1.0 - 0.5 * q).max(0.0);
            let t2 = t * t;
            t2 * t2 * (2.0 * q + 1.0)
        }
    }
}

fn g(k: Kernel, q: f64) -> f64 {
    match k {
        Kernel::CubicSpline => {
            let a = (2.0 - q).max(0.0);
            if q < 1.0 {
                -3.0 + 2.25 * q
            } else {
                -0.75 * a * a / q.max(1.0)
            }
        }
        Kernel::WendlandC2 => {
            let t = (1.0 - 0.5 * q).max(0.0);
            -5.0 * t * t * t
        }
    }
}

fn powi(s: f64, gamma: u32) -> f64 {
    if gamma == 7 {
        let s2 = s * s;
        let s4 = s2 * s2;
        return s4 * s2 * s;
    }
    let mut r = s;
    for _ in 1..gamma {
        r *= s;
    }
    r
}

const TINY: f64 = 1e-300;

/// x_i − x_j (z = 0 in 2D), |x_i − x_j|² summed as the shader does.
fn pair(x: &[f64], d: usize, i: usize, j: usize) -> ([f64; 3], f64) {
    let mut e = [0.0; 3];
    for a in 0..d {
        e[a] = x[d * i + a] - x[d * j + a];
    }
    let mut r2 = e[0] * e[0] + e[1] * e[1];
    if d == 3 {
        r2 += e[2] * e[2];
    }
    (e, r2)
}

/// Static wall particles: positions (flat, dim each) and Ψ_b (kg), one each.
#[derive(Clone, Default)]
struct Walls {
    x: Vec<f64>,
    psi: Vec<f64>,
}

/// x_i − x_b for particle i and wall particle b (z = 0 in 2D), |x_i − x_b|² as the shader sums it.
fn wall_pair(x: &[f64], walls: &Walls, d: usize, i: usize, b: usize) -> ([f64; 3], f64) {
    let mut e = [0.0; 3];
    for a in 0..d {
        e[a] = x[d * i + a] - walls.x[d * b + a];
    }
    let mut r2 = e[0] * e[0] + e[1] * e[1];
    if d == 3 {
        r2 += e[2] * e[2];
    }
    (e, r2)
}

/// Summation densities, brute force, j in increasing order, then the walls' Σ_b Ψ_b w in
/// increasing order into the same sum (Akinci et al. 2012, eq. 4–5).
fn densities(p: &SphParams, x: &[f64], walls: &Walls) -> Vec<f64> {
    let (d, h) = (p.dim, p.h);
    let n = x.len() / d;
    let (inv_h, sigma, reach) = (1.0 / h, p.kernel.sigma(h, d), 4.0001 * h * h);
    (0..n)
        .map(|i| {
            let mut acc = 0.0;
            for j in 0..n {
                let (_, r2) = pair(x, d, i, j);
                if r2 < reach {
                    acc += w(p.kernel, r2.max(TINY).sqrt() * inv_h) * p.mass;
                }
            }
            for b in 0..walls.psi.len() {
                let (_, r2) = wall_pair(x, walls, d, i, b);
                if r2 < reach {
                    acc += w(p.kernel, r2.max(TINY).sqrt() * inv_h) * walls.psi[b];
                }
            }
            sigma * acc
        })
        .collect()
}

/// One step of the host reference; returns how many coordinates the box's faces projected and
/// the largest |dv/dt| of the pressure, viscosity and wall-particle forces (m/s²). Books into
/// `books` the viscous dissipation (the power at the step's start times dt) and what the box's
/// faces removed (ΔKE plus the work of the step's force over the projection, less ½dt m g·Δv), as the CPU's
/// WCSPH and box collider do. The wall particles push with p_i/ρ_i² Σ_b Ψ_b g(q) (x_i − x_b)
/// (Akinci et al. 2012, eq. 10; no viscosity), as passes.rs `Forces`.
fn step(p: &SphParams, x: &mut [f64], v: &mut [f64], walls: &Walls, dt: f64, books: &mut [f64; 2]) -> (usize, f64) {
    let (d, h, m) = (p.dim, p.h, p.mass);
    let n = x.len() / d;
    let rho = densities(p, x, walls);
    let (b, inv_rho0) = (p.b(), 1.0 / p.rho0);
    let pr: Vec<f64> = rho
        .iter()
        .map(|&r| {
            let mut q = b * (powi(r * inv_rho0, p.gamma) - 1.0);
            if p.clamp {
                q = q.max(0.0);
            }
            q / (r * r)
        })
        .collect();
    let sigma = p.kernel.sigma(h, d);
    let (inv_h, scale, visc) = (1.0 / h, -sigma / (h * h), 2.0 * p.alpha * p.c0 * h);
    let (eps_h2, reach, inv_m) = (0.01 * h * h, 4.0001 * h * h, 1.0 / m);
    let (x0, v0) = (x.to_vec(), v.to_vec());
    let (mut hits, mut amax) = (0, 0.0f64);
    for i in 0..n {
        let mut acc = [0.0; 3];
        let mut pw = 0.0;
        for j in 0..n {
            let (e, r2) = pair(&x0, d, i, j);
            let (u, _) = pair(&v0, d, i, j);
            let mut vr = u[0] * e[0] + u[1] * e[1];
            if d == 3 {
                vr += u[2] * e[2];
            }
            if r2 >= reach {
                continue;
            }
            let gq = g(p.kernel, r2.max(TINY).sqrt() * inv_h);
            let approach = (0.0 - vr).max(0.0);
            let pi = visc * approach / ((r2 + eps_h2) * (rho[i] + rho[j]));
            let cf = m * gq * (pr[i] + pr[j] + pi);
            for a in 0..d {
                acc[a] += cf * e[a];
            }
            pw += m * gq * pi * vr;
        }
        let mut wacc = [0.0; 3];
        for b in 0..walls.psi.len() {
            let (e, r2) = wall_pair(&x0, walls, d, i, b);
            if r2 >= reach {
                continue;
            }
            let cf = walls.psi[b] * g(p.kernel, r2.max(TINY).sqrt() * inv_h);
            for a in 0..d {
                wacc[a] += cf * e[a];
            }
        }
        books[0] += 0.5 * m * (-scale) * pw * dt;
        let (mut xn, mut vn, mut f) = ([0.0; 3], [0.0; 3], [0.0; 3]);
        let acc: [f64; 3] = std::array::from_fn(|a| acc[a] + pr[i] * wacc[a]);
        amax = amax.max((0..d).map(|a| (scale * acc[a]).powi(2)).sum::<f64>().sqrt());
        for a in 0..d {
            f[a] = m * (scale * acc[a]);
            vn[a] = v0[d * i + a] + (f[a] * inv_m + p.gravity[a]) * dt;
            xn[a] = x0[d * i + a] + vn[a] * dt;
        }
        let (xb, vb) = (xn, vn);
        // The box (constraints/aabb.rs).
        let (e, mu) = (p.restitution, p.friction);
        for a in 0..d {
            let out = if xn[a] < p.lower[a] {
                xn[a] = p.lower[a];
                -1.0
            } else if xn[a] > p.upper[a] {
                xn[a] = p.upper[a];
                1.0
            } else {
                continue;
            };
            hits += 1;
            let un = vn[a] * out;
            if un > 0.0 {
                let dvn = (1.0 + e) * un;
                vn[a] *= -e;
                if mu > 0.0 {
                    let vt2: f64 = (0..d).filter(|&b| b != a).map(|b| vn[b] * vn[b]).sum();
                    if vt2 > 0.0 {
                        let vt = vt2.sqrt();
                        let s = (vt - mu * dvn).max(0.0) / vt;
                        for b in (0..d).filter(|&b| b != a) {
                            vn[b] *= s;
                        }
                    }
                }
            }
        }
        if xn != xb || vn != vb {
            let ke = |u: &[f64; 3]| 0.5 * m * (0..d).map(|a| u[a] * u[a]).sum::<f64>();
            let work: f64 = (0..d).map(|a| (f[a] + p.gravity[a] * m) * (xn[a] - xb[a])).sum();
            // Semi-implicit Euler's share of the velocity change in gravity's field (the CPU's
            // `IntegratorInfo::projection_kick`).
            let kicked: f64 = (0..d).map(|a| p.gravity[a] * m * (vn[a] - vb[a])).sum();
            books[1] += ke(&vb) - ke(&vn) + work - 0.5 * dt * kicked;
        }
        x[d * i..d * i + d].copy_from_slice(&xn[..d]);
        v[d * i..d * i + d].copy_from_slice(&vn[..d]);
    }
    (hits, amax)
}

/// The books of the reference's state `x`, `v` with its accumulated `books` (`SphBooks`' sums).
fn host_books(p: &SphParams, x: &[f64], v: &[f64], walls: &Walls, books: [f64; 2]) -> SphBooks {
    let (d, m) = (p.dim, p.mass);
    let rho = densities(p, x, walls);
    SphBooks {
        kinetic: 0.5 * v.iter().map(|u| m * u * u).sum::<f64>(),
        internal: rho.iter().map(|&r| m * p.internal_energy(r)).sum(),
        gravity: -x.chunks_exact(d).map(|xi| m * (0..d).map(|a| p.gravity[a] * xi[a]).sum::<f64>()).sum::<f64>(),
        viscous: books[0],
        collisions: books[1],
    }
}

/// The books' entries, for comparing.
fn entries(b: &SphBooks) -> [f64; 5] {
    [b.kinetic, b.internal, b.gravity, b.viscous, b.collisions]
}

/// A jittered block of `side`^dim particles `dx` apart, 0.3 dx from the box's lower faces, thrown
/// at the lower corner (−1, −1.5, −1 m/s, ± 0.5 m/s each).
fn block(dim: usize, side: usize, dx: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let base = [-1.0, -1.5, -1.0];
    let (mut x, mut v) = (Vec::new(), Vec::new());
    for i in 0..side.pow(dim as u32) {
        let mut idx = i;
        for (a, b) in base.iter().enumerate().take(dim) {
            let k = 7 * (seed + i as u64) + a as u64;
            x.push(((idx % side) as f64 + 0.3 + 0.2 * unit(k)) * dx);
            v.push(b + unit(k + 3) - 0.5);
            idx /= side;
        }
    }
    (x, v)
}

/// The largest |a − b| over `scale`.
fn worst(a: &[f64], b: &[f64], scale: f64) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0, f64::max) / scale
}

struct Case {
    name: &'static str,
    p: SphParams,
    x: Vec<f64>,
    v: Vec<f64>,
    walls: Walls,
}

/// `layers` layers of wall particles `dx` apart under the floor (y < 0) and beside the −x face
/// (x < 0) of a box `width` wide (x, and z in 3D) from the origin, on the lattice (k + ½) dx;
/// Ψ_b = `psi` each.
fn floor_and_side(dim: usize, width: f64, dx: f64, layers: usize, psi: f64) -> Walls {
    let (l, k) = (layers as i64, (width / dx).round() as i64);
    let zs: Vec<i64> = if dim == 3 { (-l..k + l).collect() } else { vec![0] };
    let mut x = Vec::new();
    for &kz in &zs {
        for ky in -l..k {
            for kx in -l..k + l {
                if ky >= 0 && kx >= 0 {
                    continue;
                }
                let c = [kx, ky, kz];
                x.extend((0..dim).map(|a| (c[a] as f64 + 0.5) * dx));
            }
        }
    }
    let psi = vec![psi; x.len() / dim];
    Walls { x, psi }
}

fn cases() -> Vec<Case> {
    let dx = 0.01;
    let water = |dim: usize, kernel: Kernel, gamma: u32, clamp: bool, upper: [f64; 3]| SphParams {
        dim,
        h: 1.3 * dx,
        mass: 1000.0 * dx.powi(dim as i32),
        rho0: 1000.0,
        c0: 15.0,
        gamma,
        alpha: 0.2,
        clamp,
        kernel,
        gravity: [0.0, -9.81, 0.0],
        lower: [0.0; 3],
        upper,
        restitution: 0.5,
        friction: 0.2,
    };
    let (x2, v2) = block(2, 20, dx, 1);
    let (x3, v3) = block(3, 8, dx, 2);
    let none = Walls::default;
    // Three layers of wall particles under the floor and beside the −x face, and (3D) one layer
    // under the floor only, reaching past the grid on +x and z (those farther than 2h dropped).
    let walls2 = floor_and_side(2, 0.4, dx, 3, 1000.0 * dx * dx);
    let mut walls3 = floor_and_side(3, 0.2, dx, 1, 1000.0 * dx.powi(3));
    walls3.x.extend([0.05, -0.005, 0.3, 0.5, -0.005, 0.05]);
    walls3.psi.extend([0.5e-3, 2e-3]);
    vec![
        Case {
            name: "2D cubic spline, gamma 7, clamped",
            p: water(2, Kernel::CubicSpline, 7, true, [0.4, 0.3, 0.0]),
            x: x2.clone(),
            v: v2.clone(),
            walls: none(),
        },
        Case {
            name: "2D Wendland C2, gamma 3, unclamped",
            p: water(2, Kernel::WendlandC2, 3, false, [0.4, 0.3, 0.0]),
            x: x2.clone(),
            v: v2.clone(),
            walls: none(),
        },
        Case {
            name: "2D cubic spline, gamma 7, clamped, 3 layers of wall particles",
            p: water(2, Kernel::CubicSpline, 7, true, [0.4, 0.3, 0.0]),
            x: x2,
            v: v2,
            walls: walls2,
        },
        Case {
            name: "3D Wendland C2, gamma 7, unclamped",
            p: water(3, Kernel::WendlandC2, 7, false, [0.2, 0.15, 0.12]),
            x: x3.clone(),
            v: v3.clone(),
            walls: none(),
        },
        Case {
            name: "3D cubic spline, gamma 1, clamped",
            p: water(3, Kernel::CubicSpline, 1, true, [0.2, 0.15, 0.12]),
            x: x3.clone(),
            v: v3.clone(),
            walls: none(),
        },
        Case {
            name: "3D Wendland C2, gamma 7, clamped, a layer of wall particles",
            p: water(3, Kernel::WendlandC2, 7, true, [0.2, 0.15, 0.12]),
            x: x3,
            v: v3,
            walls: walls3,
        },
    ]
}

const STEPS: u64 = 20;
const DT: f64 = 2e-4;

fn run(g: &Arc<Gpu>, precision: Precision, c: &Case) -> (Vec<f64>, Vec<f64>, Vec<f64>, SphBooks) {
    run_listing(g, precision, c, None)
}

/// `run` with the neighbour lists `cap` entries long (None: as `with_walls` chose them).
fn run_listing(
    g: &Arc<Gpu>,
    precision: Precision,
    c: &Case,
    cap: Option<u32>,
) -> (Vec<f64>, Vec<f64>, Vec<f64>, SphBooks) {
    let mut s = Sph::with_walls(g.clone(), precision, c.p, &c.x, &c.v, &c.walls.x, &c.walls.psi).unwrap();
    assert_eq!(s.list_cap(), if c.p.dim == 2 { 28 } else { 96 }, "{}: the lists' length", c.name);
    if let Some(cap) = cap {
        s.set_list_cap(cap);
    }
    // Two calls: the second starts from the state the first left.
    assert_eq!(s.step(STEPS / 2, DT, &AtomicBool::new(false)).unwrap(), STEPS / 2);
    assert_eq!(s.step(STEPS - STEPS / 2, DT, &AtomicBool::new(false)).unwrap(), STEPS - STEPS / 2);
    let (x, v, rho) = s.read().unwrap();
    (x, v, rho, s.books().unwrap())
}

#[test]
fn the_device_fluid_steps_as_the_host_reference_and_repeats_bit_for_bit() {
    let Some(g) = gpu() else { return };
    for c in cases() {
        let (mut x, mut v) = (c.x.clone(), c.v.clone());
        let (mut hits, mut amax, mut acc) = (0, 0.0f64, [0.0; 2]);
        for _ in 0..STEPS {
            let (k, a) = step(&c.p, &mut x, &mut v, &c.walls, DT, &mut acc);
            hits += k;
            amax = amax.max(a);
        }
        if !c.walls.psi.is_empty() {
            // The wall particles are within reach: they add to the densities.
            let (with, without) = (densities(&c.p, &c.x, &c.walls), densities(&c.p, &c.x, &Walls::default()));
            assert!(with.iter().zip(&without).any(|(a, b)| a > b), "{}: the walls touch nothing", c.name);
        }
        let rho = densities(&c.p, &x, &c.walls);
        let books = host_books(&c.p, &x, &v, &c.walls, acc);
        // Both accumulated books ran: the viscosity and the walls took energy.
        assert!(books.viscous > 0.0 && books.collisions > 0.0, "{}: {books:?}", c.name);
        let escale = entries(&books).iter().map(|e| e.abs()).sum::<f64>();
        // The walls' path ran: particles hit them, with restitution and friction.
        assert!(hits > 0, "{}: no particle reached a wall", c.name);
        // And the fluid's forces: the largest SPH acceleration, against g.
        assert!(amax > 10.0 * 9.81, "{}: SPH accelerations of at most {amax} m/s²", c.name);
        let box_size = (0..c.p.dim).map(|a| c.p.upper[a] - c.p.lower[a]).fold(0.0, f64::max);
        let vmax = v.iter().map(|u| u.abs()).fold(0.0, f64::max);
        for precision in [Precision::F64, Precision::F32] {
            if let Err(e) = g.check_precision(precision) {
                eprintln!("{}: {precision:?} not run: {e}", c.name);
                continue;
            }
            let (dx, dv, drho, db) = run(&g, precision, &c);
            // No particle lost (the mass, n m, kept): all there, finite and in the box.
            assert!(dx.len() == x.len() && dv.len() == v.len() && drho.len() == rho.len());
            let d = c.p.dim;
            assert!(dx.chunks_exact(d).all(|p| (0..d).all(|a| p[a] >= c.p.lower[a] && p[a] <= c.p.upper[a])));
            let err = [worst(&dx, &x, box_size), worst(&dv, &v, vmax), worst(&drho, &rho, c.p.rho0)];
            eprintln!(
                "{} {precision:?}: {hits} wall hits, SPH |a| up to {amax:.0} m/s²; max |Δx|/L = {:.2e}, |Δv|/vmax = {:.2e}, |Δρ|/ρ0 = {:.2e}",
                c.name, err[0], err[1], err[2]
            );
            let tol = if precision == Precision::F64 { 1e-10 } else { 1e-4 };
            assert!(err.iter().all(|&e| e <= tol), "{} {precision:?}: errors {err:?} over {tol:e}", c.name);
            // The books: each entry against the reference's, over the sum of their magnitudes.
            let eb = entries(&db).iter().zip(entries(&books)).map(|(a, b)| (a - b).abs() / escale).collect::<Vec<_>>();
            let ebs = eb.iter().map(|e| format!("{e:.2e}")).collect::<Vec<_>>().join(" ");
            eprintln!("  books {db:?}; |Δ|/Σ|E| (kinetic internal gravity viscous collisions) {ebs}");
            let btol = if precision == Precision::F64 { 1e-11 } else { 1e-4 };
            assert!(eb.iter().all(|&e| e <= btol), "{} {precision:?}: books off by {eb:?}", c.name);
            let again = run(&g, precision, &c);
            let bits = |a: &[f64]| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&again.0), bits(&dx), "{} {precision:?}: positions repeat", c.name);
            assert_eq!(bits(&again.1), bits(&dv), "{} {precision:?}: velocities repeat", c.name);
            assert_eq!(bits(&again.2), bits(&drho), "{} {precision:?}: densities repeat", c.name);
            assert_eq!(bits(&entries(&again.3)), bits(&entries(&db)), "{} {precision:?}: books repeat", c.name);
        }
    }
}

/// The neighbour lists (made by the density pass for the forces' pass) are an index only: with
/// them, without them (the forces' pass reads the cells) and too short for most particles (those
/// read the cells, the others their list), every case gives the same bits.
#[test]
fn the_neighbour_lists_change_no_bit() {
    let Some(g) = gpu() else { return };
    for c in cases() {
        for precision in [Precision::F64, Precision::F32] {
            if g.check_precision(precision).is_err() {
                continue;
            }
            let bits = |r: &(Vec<f64>, Vec<f64>, Vec<f64>, SphBooks)| {
                let b = |a: &[f64]| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                (b(&r.0), b(&r.1), b(&r.2), b(&entries(&r.3)))
            };
            // 2D holds some 20 neighbours and 3D some 80: 12 and 40 leave most past the end.
            let short = if c.p.dim == 2 { 12 } else { 40 };
            let listed = bits(&run_listing(&g, precision, &c, None));
            assert!(
                listed == bits(&run_listing(&g, precision, &c, Some(0))),
                "{} {precision:?}: the lists changed the result",
                c.name
            );
            assert!(
                listed == bits(&run_listing(&g, precision, &c, Some(short))),
                "{} {precision:?}: lists too short changed the result",
                c.name
            );
        }
    }
}

/// ρ0 dx^d σ Σ w(|r|/h) over the lattice points r = dx·k (k ∈ Z^d) within the support: the summed
/// density of a particle deep inside a square lattice of spacing dx and mass ρ0 dx^d.
fn lattice_sum(p: &SphParams, dx: f64) -> f64 {
    let d = p.dim;
    let reach = (2.0 * p.h / dx).ceil() as i64;
    let mut acc = 0.0;
    let zs = if d == 3 { -reach..=reach } else { 0..=0 };
    for kz in zs {
        for ky in -reach..=reach {
            for kx in -reach..=reach {
                let r = dx * ((kx * kx + ky * ky + kz * kz) as f64).sqrt();
                acc += w(p.kernel, r / p.h);
            }
        }
    }
    p.rho0 * dx.powi(d as i32) * p.kernel.sigma(p.h, d) * acc
}

#[test]
fn a_lattice_at_rest_has_its_kernels_lattice_sum_for_density() {
    let Some(g) = gpu() else { return };
    let dx = 0.01;
    for (dim, kernel, side) in [(2usize, Kernel::CubicSpline, 16usize), (3, Kernel::WendlandC2, 10)] {
        let p = SphParams {
            dim,
            h: 1.3 * dx,
            mass: 1000.0 * dx.powi(dim as i32),
            kernel,
            gravity: [0.0; 3],
            upper: [side as f64 * dx; 3],
            ..SphParams::default()
        };
        let n = side.pow(dim as u32);
        let (mut x, mut interior) = (Vec::new(), Vec::new());
        for i in 0..n {
            let (mut idx, mut inside) = (i, true);
            for _ in 0..dim {
                let k = idx % side;
                x.push((k as f64 + 0.5) * dx);
                // At least 2h (2.6 dx) from the block's edge: the whole support is lattice.
                inside &= (3..side - 3).contains(&k);
                idx /= side;
            }
            if inside {
                interior.push(i);
            }
        }
        let want = lattice_sum(&p, dx);
        // The lattice sum is near ρ0 (the kernels are normalised; the sum is a quadrature).
        assert!((want / p.rho0 - 1.0).abs() < 0.02, "{dim}D {kernel:?}: lattice sum {want}");
        let s = Sph::new(g.clone(), Precision::F64, p, &x, &vec![0.0; x.len()]).unwrap();
        let (xd, vd, rho) = s.read().unwrap();
        assert_eq!(xd, x, "reading gives the uploaded positions back");
        assert!(vd.iter().all(|&u| u == 0.0));
        let err = interior.iter().map(|&i| (rho[i] - want).abs() / want).fold(0.0, f64::max);
        eprintln!("{dim}D {kernel:?}: lattice sum ρ/ρ0 = {:.6}, worst interior |Δρ|/ρ = {err:.2e}", want / p.rho0);
        assert!(err <= 1e-12, "{dim}D {kernel:?}: interior densities off the lattice sum by {err:e}");
    }
}

#[test]
fn bad_input_is_refused() {
    let Some(g) = gpu() else { return };
    let p = SphParams::default();
    let x = vec![0.5, 0.5, 0.6, 0.5];
    let v = vec![0.0; 4];
    let refused = |p: SphParams, x: &[f64], v: &[f64], what: &str| match Sph::new(g.clone(), Precision::F32, p, x, v) {
        Err(GpuError::Unsupported(m)) => assert!(m.starts_with(what), "{what}: {m}"),
        Err(e) => panic!("{what}: wrong error {e}"),
        Ok(_) => panic!("{what}: accepted"),
    };
    refused(SphParams { h: 0.0, ..p }, &x, &v, "h");
    refused(SphParams { h: f64::NAN, ..p }, &x, &v, "h");
    refused(SphParams { mass: -1.0, ..p }, &x, &v, "mass");
    refused(SphParams { rho0: f64::INFINITY, ..p }, &x, &v, "rho0");
    refused(SphParams { c0: 0.0, ..p }, &x, &v, "c0");
    refused(SphParams { gamma: 0, ..p }, &x, &v, "gamma");
    refused(SphParams { alpha: -0.1, ..p }, &x, &v, "alpha");
    refused(SphParams { dim: 4, ..p }, &x, &v, "dim");
    refused(SphParams { gravity: [0.0, f64::NAN, 0.0], ..p }, &x, &v, "gravity");
    refused(SphParams { upper: [1.0, 0.0, 1.0], ..p }, &x, &v, "upper");
    refused(SphParams { restitution: 1.5, ..p }, &x, &v, "restitution");
    refused(SphParams { friction: f64::NAN, ..p }, &x, &v, "friction");
    refused(SphParams { h: 1e-12, ..p }, &x, &v, "h");
    refused(p, &[0.5, f64::NAN, 0.6, 0.5], &v, "positions");
    refused(p, &x, &[0.0, 0.0, f64::INFINITY, 0.0], "velocities");
    refused(p, &x, &v[..2], "positions");
    refused(p, &x[..3], &v[..3], "positions");
    refused(p, &[0.5, 0.5, 1.5, 0.5], &v, "positions");
    let walled =
        |w: &[f64], psi: &[f64], what: &str| match Sph::with_walls(g.clone(), Precision::F32, p, &x, &v, w, psi) {
            Err(GpuError::Unsupported(m)) => assert!(m.starts_with(what), "{what}: {m}"),
            Err(e) => panic!("{what}: wrong error {e}"),
            Ok(_) => panic!("{what}: accepted"),
        };
    walled(&[0.5, -0.005, 0.5], &[0.1], "walls");
    walled(&[0.5, f64::NAN], &[0.1], "walls");
    walled(&[0.5, -0.005], &[0.1, 0.1], "psi");
    walled(&[0.5, -0.005], &[0.0], "psi");
    walled(&[0.5, -0.005], &[f64::INFINITY], "psi");
    // Walls far outside the box are accepted and dropped; those within 2h kept.
    let s =
        Sph::with_walls(g.clone(), Precision::F32, p, &x, &v, &[0.5, -0.005, 0.5, -5.0, 1.01, 0.5], &[0.1; 3]).unwrap();
    assert_eq!(s.n_walls(), 2);
    let mut s = Sph::new(g.clone(), Precision::F32, p, &x, &v).unwrap();
    let stop = AtomicBool::new(false);
    for dt in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
        match s.step(1, dt, &stop) {
            Err((0, Halt::Failed(GpuError::Unsupported(m)))) => assert!(m.starts_with("dt"), "{m}"),
            other => panic!("dt = {dt}: {other:?}"),
        }
    }
    // A raised stop flag runs nothing; an empty fluid steps as a no-op.
    assert_eq!(s.step(5, 1e-4, &AtomicBool::new(true)), Err((0, Halt::Stopped)));
    let mut empty = Sph::new(g.clone(), Precision::F32, p, &[], &[]).unwrap();
    assert_eq!(empty.step(3, 1e-4, &stop), Ok(3));
    assert_eq!(empty.read().unwrap(), (vec![], vec![], vec![]));
}

#[test]
fn a_diverging_fluid_halts_naming_a_particle() {
    let Some(g) = gpu() else { return };
    // Gravity that overflows f32 within one step: every velocity becomes infinite.
    let p = SphParams { gravity: [0.0, -1e30, 0.0], ..SphParams::default() };
    let mut s = Sph::new(g.clone(), Precision::F32, p, &[0.5, 0.5, 0.6, 0.5], &[0.0; 4]).unwrap();
    assert_eq!(s.step(3, 1e10, &AtomicBool::new(false)), Err((0, Halt::Diverged { particle: 0 })));
}

#[test]
fn without_viscosity_or_walls_the_dissipated_books_are_zero_and_the_total_holds() {
    let Some(g) = gpu() else { return };
    let dx = 0.01;
    // A block at rest in the middle of a large box, no viscosity: it falls and spreads, touching
    // no wall within the run.
    let p = SphParams {
        h: 1.3 * dx,
        mass: 1000.0 * dx * dx,
        c0: 15.0,
        alpha: 0.0,
        clamp: false,
        upper: [1.0, 1.0, 0.0],
        ..SphParams::default()
    };
    let (mut x, _) = block(2, 12, dx, 3);
    x.iter_mut().for_each(|c| *c += 0.4);
    let v = vec![0.0; x.len()];
    for precision in [Precision::F64, Precision::F32] {
        if g.check_precision(precision).is_err() {
            continue;
        }
        let mut s = Sph::new(g.clone(), precision, p, &x, &v).unwrap();
        let b0 = s.books().unwrap();
        assert_eq!((b0.kinetic, b0.viscous, b0.collisions), (0.0, 0.0, 0.0));
        s.step(200, 1e-4, &AtomicBool::new(false)).unwrap();
        let b = s.books().unwrap();
        let (xd, _, _) = s.read().unwrap();
        assert!(xd.iter().all(|&c| c > 0.2 && c < 0.8), "{precision:?}: a particle went near a wall");
        assert_eq!((b.viscous, b.collisions), (0.0, 0.0), "{precision:?}");
        let scale = entries(&b).iter().map(|e| e.abs()).sum::<f64>();
        let drift = (b.total() - b0.total()).abs() / scale;
        eprintln!("{precision:?}: books {b:?}, total drift {drift:.2e} of Σ|E|");
        assert!(b.kinetic > 0.0 && drift < 1e-2, "{precision:?}: {b:?} from {b0:?}");
    }
}

/// The step limit's maxima (`extremes`), reduced on the device, against those the host finds
/// in a read-back of every velocity and squared acceleration (`extremes_from_read_back`, and
/// the largest speed from `read_state`): the same bits, f32 and f64, 2D and 3D, for 2500 and
/// 2744 particles (three workgroups of the reduction's 1024, the last in part), one and none;
/// at the upload (no acceleration yet) and after steps. The speeds span four decades.
#[test]
fn the_device_reduced_maxima_are_the_hosts_bit_for_bit() {
    let Some(g) = gpu() else { return };
    let dx = 0.01;
    for precision in [Precision::F32, Precision::F64] {
        if g.check_precision(precision).is_err() {
            eprintln!("skipped {precision:?}: the adapter has no f64");
            continue;
        }
        for (dim, n) in [(2, 2500), (3, 2744), (2, 1), (3, 1), (2, 0)] {
            let side = if dim == 2 { 50 } else { 14 };
            let (mut x, mut v) = block(dim, side, dx, 11);
            x.iter_mut().for_each(|c| *c += 0.2);
            x.truncate(dim * n);
            v.truncate(dim * n);
            for (k, c) in v.iter_mut().enumerate() {
                *c *= 10f64.powf(-4.0 * unit(1000 + k as u64 / dim as u64));
            }
            let p = SphParams { dim, h: 1.3 * dx, mass: 1000.0 * dx.powi(dim as i32), ..SphParams::default() };
            let mut s = Sph::new(g.clone(), precision, p, &x, &v).unwrap();
            for steps in [0, 5] {
                s.step(steps, 1e-5, &AtomicBool::new(false)).unwrap();
                let (vmax, a2) = s.extremes().unwrap();
                let (host_v, host_a2) = s.extremes_from_read_back().unwrap();
                let (_, vd) = s.read_state().unwrap();
                let from_state =
                    vd.chunks_exact(dim).map(|u| u.iter().map(|c| c * c).sum::<f64>()).fold(0.0, f64::max).sqrt();
                let what = format!("{precision:?} {dim}D, {n} particles, {steps} steps");
                assert_eq!(vmax.to_bits(), host_v.to_bits(), "{what}: |v|max {vmax:e} against the host's {host_v:e}");
                assert_eq!(vmax.to_bits(), from_state.to_bits(), "{what}");
                assert_eq!(a2.to_bits(), host_a2.to_bits(), "{what}: |a|²max {a2:e} against the host's {host_a2:e}");
                assert_eq!(vmax > 0.0, n > 0, "{what}");
                assert_eq!(a2 > 0.0, n > 1 && steps > 0, "{what}: |a|²max {a2:e}");
            }
        }
    }
}
