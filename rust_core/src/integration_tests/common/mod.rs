#![allow(dead_code)]
use glam::{DVec2, DVec3};
use physcore_core::terms::{PairwiseGravity, Springs, UniformGravity};
use physcore_core::{ParticleSystem, World};

/// Unit-mass particle on a unit spring to a pinned anchor at the origin: x(t) = cos t.
pub fn oscillator(integrator: &str, dt: f64) -> World<DVec2> {
    let mut s = World::new(ParticleSystem::new(integrator).unwrap(), dt, Some(1)).unwrap();
    s.particles_mut()
        .add_particles(vec![DVec2::ZERO, DVec2::new(1.0, 0.0)], vec![DVec2::ZERO; 2], vec![1.0, 1.0], vec![true, false])
        .unwrap();
    s.particles_mut()
        .add_term(Box::new(
            Springs::new("springs".into(), vec![0], vec![1], vec![1.0], vec![0.0], vec![0.0], 2).unwrap(),
        ))
        .unwrap();
    s
}

/// A small deterministic pseudo-random generator (splitmix64), so tests need no crates.
pub struct Rng(pub u64);
impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        z ^ (z >> 31)
    }
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// n×n cloth in the z = 0 plane, first row pinned, structural + shear springs, gravity.
pub fn cloth(n: usize, integrator: &str, threads: usize, damping: f64) -> World<DVec3> {
    let s_ = 1.0 / (n - 1) as f64;
    let mut x = Vec::new();
    let mut pinned = Vec::new();
    for j in 0..n {
        for i in 0..n {
            x.push(DVec3::new(i as f64 * s_, j as f64 * s_, 0.0));
            pinned.push(j == 0);
        }
    }
    let np = n * n;
    let mut sim = World::new(ParticleSystem::new(integrator).unwrap(), 1e-4, Some(threads)).unwrap();
    sim.particles_mut().add_particles(x.clone(), vec![DVec3::ZERO; np], vec![1.0 / np as f64; np], pinned).unwrap();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for j in 0..n {
        for i in 0..n {
            let p = (j * n + i) as u32;
            if i + 1 < n {
                a.push(p);
                b.push(p + 1);
            }
            if j + 1 < n {
                a.push(p);
                b.push(p + n as u32);
            }
            if i + 1 < n && j + 1 < n {
                a.push(p);
                b.push(p + n as u32 + 1);
                a.push(p + 1);
                b.push(p + n as u32);
            }
        }
    }
    let m = a.len();
    let rest: Vec<f64> = a.iter().zip(&b).map(|(&i, &j)| (x[j as usize] - x[i as usize]).length()).collect();
    sim.particles_mut()
        .add_term(Box::new(Springs::new("springs".into(), a, b, vec![100.0; m], vec![damping; m], rest, np).unwrap()))
        .unwrap();
    sim.particles_mut()
        .add_term(Box::new(UniformGravity { name: "gravity".into(), g: DVec3::new(0.0, 0.0, -9.81) }))
        .unwrap();
    sim
}

/// Cloud of n bodies in the unit cube with small random velocities, under pairwise gravity.
pub fn cloud(n: usize, threads: usize, softening: f64) -> World<DVec3> {
    let mut r = Rng(7);
    let x: Vec<DVec3> = (0..n).map(|_| DVec3::new(r.uniform(), r.uniform(), r.uniform())).collect();
    let v: Vec<DVec3> =
        (0..n).map(|_| DVec3::new(r.uniform() - 0.5, r.uniform() - 0.5, r.uniform() - 0.5) * 0.1).collect();
    let mut sim = World::new(ParticleSystem::new("verlet").unwrap(), 1e-3, Some(threads)).unwrap();
    sim.particles_mut().add_particles(x, v, vec![1.0 / n as f64; n], vec![false; n]).unwrap();
    sim.particles_mut().add_term(Box::new(PairwiseGravity::new("pairwise_gravity".into(), 1.0, softening))).unwrap();
    sim
}

/// A star (mass 1) and `n` light planets (1e-4 each) on circular orbits at radii 1, 1.3, 1.6, …
/// (G = 1), stepped by `integrator` at a twentieth of the inner period: a scene every integrator
/// steps, "wisdom_holman" included.
pub fn planets(n: usize, integrator: &str, threads: usize) -> World<DVec3> {
    let mut x = vec![DVec3::ZERO];
    let mut v = vec![DVec3::ZERO];
    for k in 0..n {
        let (r, a) = (1.0 + 0.3 * k as f64, 2.0 * k as f64);
        x.push(DVec3::new(r * a.cos(), r * a.sin(), 0.01 * k as f64));
        v.push(DVec3::new(-a.sin(), a.cos(), 0.0) / r.sqrt());
    }
    let dt = 2.0 * std::f64::consts::PI / 20.0;
    let mut sim = World::new(ParticleSystem::new(integrator).unwrap(), dt, Some(threads)).unwrap();
    let mut m = vec![1e-4; n + 1];
    m[0] = 1.0;
    sim.particles_mut().add_particles(x, v, m, vec![false; n + 1]).unwrap();
    sim.particles_mut().add_term(Box::new(PairwiseGravity::new("pairwise_gravity".into(), 1.0, 0.0))).unwrap();
    sim
}
