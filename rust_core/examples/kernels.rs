//! Quick timing of the hot kernels at every SIMD level this CPU has (a development aid; the
//! benchmarks of record are under benches/). `cargo run --release --features examples --example kernels -- nbody`
use glam::DVec3;
use physcore_core::simd::{self, Level};
use physcore_core::terms::{PairwiseGravity, Springs, UniformGravity};
use physcore_core::{ParticleSystem, World};
use std::time::Instant;

fn nbody(n: usize, single: bool) -> World<DVec3> {
    let mut s = World::<DVec3>::new(ParticleSystem::<DVec3>::new("verlet").unwrap(), 1e-3, None).unwrap();
    let mut seed = 42u64;
    let mut rnd = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let x: Vec<DVec3> = (0..n).map(|_| DVec3::new(rnd(), rnd(), rnd())).collect();
    s.particles_mut().add_particles(x, vec![DVec3::ZERO; n], vec![1.0 / n as f64; n], vec![false; n]).unwrap();
    s.particles_mut().add_term(Box::new(PairwiseGravity::new("g".into(), 1.0, 0.01))).unwrap();
    s.particles_mut().set_single(single);
    s
}

/// WORKLOADS §2 cloth: g×g, structural + shear + bend springs, row 0 pinned, semi-implicit Euler.
fn cloth(g: usize) -> World<DVec3> {
    let n = g * g;
    let m = 1.0 / n as f64;
    let k = 100.0;
    let sp = 1.0 / (g - 1) as f64;
    let mut s =
        World::<DVec3>::new(ParticleSystem::<DVec3>::new("semi_implicit_euler").unwrap(), 0.25 * (m / k).sqrt(), None)
            .unwrap();
    let x: Vec<DVec3> = (0..n).map(|p| DVec3::new((p % g) as f64 * sp, (p / g) as f64 * sp, 0.0)).collect();
    let (mut i, mut j) = (vec![], vec![]);
    for y in 0..g {
        for xx in 0..g {
            let p = (y * g + xx) as u32;
            for (dx, dy) in [(1i64, 0i64), (0, 1), (1, 1), (-1, 1), (2, 0), (0, 2)] {
                let (qx, qy) = (xx as i64 + dx, y as i64 + dy);
                if qx >= 0 && qx < g as i64 && qy < g as i64 {
                    i.push(p);
                    j.push((qy * g as i64 + qx) as u32);
                }
            }
        }
    }
    let rest: Vec<f64> = i.iter().zip(&j).map(|(&a, &b)| (x[a as usize] - x[b as usize]).length()).collect();
    let ns = i.len();
    s.particles_mut().add_particles(x, vec![DVec3::ZERO; n], vec![m; n], (0..n).map(|p| p < g).collect()).unwrap();
    s.particles_mut()
        .add_term(Box::new(
            Springs::new("springs".into(), i, j, vec![k; ns], vec![0.1 * (k * m).sqrt(); ns], rest, n).unwrap(),
        ))
        .unwrap();
    s.particles_mut()
        .add_term(Box::new(UniformGravity { name: "gravity".into(), g: DVec3::new(0.0, 0.0, -9.81) }))
        .unwrap();
    s
}

fn time(s: &mut World<DVec3>, steps: u64) -> f64 {
    s.step(steps / 10).unwrap();
    let mut ts = vec![];
    for _ in 0..3 {
        let t0 = Instant::now();
        s.step(steps).unwrap();
        ts.push(t0.elapsed().as_secs_f64());
    }
    ts.sort_by(|a, b| a.partial_cmp(b).unwrap());
    ts[1]
}

fn main() {
    let what = std::env::args().nth(1).unwrap_or_else(|| "nbody".into());
    let only = std::env::args().nth(2);
    for level in Level::available() {
        if only.as_deref().is_some_and(|o| o != level.name()) {
            continue;
        }
        simd::set_level(Some(level)).unwrap();
        if what == "cloth" {
            for (g, steps) in [(128, 1000), (256, 250)] {
                let mut s = cloth(g);
                let t = time(&mut s, steps);
                println!(
                    "{:7} cloth {g} {:.1} M particle-steps/s",
                    level.name(),
                    (g * g) as f64 * steps as f64 / t / 1e6
                );
            }
        }
        if what == "nbody" {
            for single in [false, true] {
                let n = 4096;
                let mut s = nbody(n, single);
                s.step(3).unwrap();
                let mut ts = vec![];
                for _ in 0..3 {
                    let t0 = Instant::now();
                    s.step(20).unwrap();
                    ts.push(t0.elapsed().as_secs_f64());
                }
                ts.sort_by(|a, b| a.partial_cmp(b).unwrap());
                println!(
                    "{:7} nbody {} {:.2} G pairs/s",
                    level.name(),
                    if single { "f32" } else { "f64" },
                    (n * n * 20) as f64 / ts[1] / 1e9
                );
            }
        }
    }
}
