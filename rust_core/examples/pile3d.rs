//! physcore's overhead over the bare rapier3d-f64 pipeline, at one precision (f64) and the same
//! settings: N cubes falling into a 4 × 4 m container (benches/bodies/bench_pile3d.py's scene),
//! dt = 1/60 s, 4 solver iterations, no sleeping; median ms/step of 3 blocks of 60 steps after
//! 60 steps of fall, the two stepped alternately, block by block. What physcore adds per step:
//! its energy books (kinetic and potential energy before and after) and the divergence check.
//! `cargo run --release --features examples --example pile3d -- 1000 3000`
use physcore_core::systems::bodies::Bodies3;
use physcore_core::systems::System;
use physcore_core::terms::registry::{Params, Value};
use rapier3d_f64::prelude::*;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

const HALF: f64 = 0.1;
const WIDTH: f64 = 4.0;
const DT: f64 = 1.0 / 60.0;

fn walls() -> Vec<([f64; 3], [f64; 3])> {
    let w = WIDTH / 2.0;
    vec![
        ([0.0, 0.0, -0.1], [w, w, 0.1]),
        ([-(w + 0.1), 0.0, 2.0], [0.1, w, 2.0]),
        ([w + 0.1, 0.0, 2.0], [0.1, w, 2.0]),
        ([0.0, -(w + 0.1), 2.0], [w, 0.1, 2.0]),
        ([0.0, w + 0.1, 2.0], [w, 0.1, 2.0]),
    ]
}

fn grid(n: usize) -> Vec<[f64; 3]> {
    let cols = (WIDTH / (2.6 * HALF)) as usize - 1;
    (0..n)
        .map(|k| {
            [
                -WIDTH / 2.0 + 2.0 * HALF + (k % cols) as f64 * 2.6 * HALF,
                -WIDTH / 2.0 + 2.0 * HALF + ((k / cols) % cols) as f64 * 2.6 * HALF,
                0.5 + (k / (cols * cols)) as f64 * 2.6 * HALF,
            ]
        })
        .collect()
}

fn group(kind: &str, x: Vec<f64>, size: Vec<f64>, density: f64, e: f64) -> Params {
    let n = x.len() / 3;
    Params::new()
        .with("shape", Value::Text("box".into()))
        .with("kind", Value::Text(kind.into()))
        .with("n", Value::Number(n as f64))
        .with("positions", Value::Floats(x))
        .with("orientations", Value::Floats([0.0, 0.0, 0.0, 1.0].repeat(n)))
        .with("velocities", Value::Floats(vec![0.0; 3 * n]))
        .with("angular_velocities", Value::Floats(vec![0.0; 3 * n]))
        .with("size", Value::Floats(size))
        .with("density", Value::Number(density))
        .with("friction", Value::Number(0.5))
        .with("restitution", Value::Number(e))
}

fn physcore(n: usize) -> Bodies3 {
    let mut b = Bodies3::new("bodies");
    let w = walls();
    b.add_group(group(
        "fixed",
        w.iter().flat_map(|(c, _)| *c).collect(),
        w.iter().flat_map(|(_, h)| *h).collect(),
        1.0,
        0.0,
    ))
    .unwrap();
    b.add_group(group("dynamic", grid(n).concat(), [HALF; 3].repeat(n), 1.0, 0.1)).unwrap();
    b.set(&physcore_core::systems::WorldSetting::Gravity([0.0, 0.0, -9.81]));
    b
}

struct Bare {
    pipeline: PhysicsPipeline,
    params: IntegrationParameters,
    islands: IslandManager,
    broad: BroadPhaseBvh,
    narrow: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    joints: ImpulseJointSet,
    multibody: MultibodyJointSet,
    soft: SoftBodySet,
    ccd: CCDSolver,
}

impl Bare {
    fn new(n: usize) -> Self {
        let mut s = Self {
            pipeline: PhysicsPipeline::new(),
            params: IntegrationParameters { dt: DT, ..Default::default() },
            islands: IslandManager::new(),
            broad: BroadPhaseBvh::new(),
            narrow: NarrowPhase::new(),
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            joints: ImpulseJointSet::new(),
            multibody: MultibodyJointSet::new(),
            soft: SoftBodySet::new(),
            ccd: CCDSolver::new(),
        };
        for (c, h) in walls() {
            let b = s.bodies.insert(RigidBodyBuilder::fixed().translation(Vector::new(c[0], c[1], c[2])));
            let col = ColliderBuilder::cuboid(h[0], h[1], h[2]).density(1.0).friction(0.5).restitution(0.0);
            s.colliders.insert_with_parent(col, b, &mut s.bodies);
        }
        for x in grid(n) {
            let b = s
                .bodies
                .insert(RigidBodyBuilder::dynamic().translation(Vector::new(x[0], x[1], x[2])).can_sleep(false));
            let col = ColliderBuilder::cuboid(HALF, HALF, HALF).density(1.0).friction(0.5).restitution(0.1);
            s.colliders.insert_with_parent(col, b, &mut s.bodies);
        }
        s
    }
    fn step(&mut self) {
        self.pipeline.step(
            Vector::new(0.0, 0.0, -9.81),
            &self.params,
            &mut self.islands,
            &mut self.broad,
            &mut self.narrow,
            &mut self.bodies,
            &mut self.colliders,
            &mut self.joints,
            &mut self.multibody,
            &mut self.soft,
            &mut self.ccd,
            &(),
            &(),
        );
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn main() {
    let sizes: Vec<usize> = std::env::args().skip(1).map(|a| a.parse().expect("a box count")).collect();
    let sizes = if sizes.is_empty() { vec![1000, 3000] } else { sizes };
    let stop = AtomicBool::new(false);
    println!("| boxes | bare rapier3d-f64 (ms/step) | physcore Bodies3 (ms/step) | overhead |");
    println!("|---|---|---|---|");
    for n in sizes {
        let (mut p, mut b) = (physcore(n), Bare::new(n));
        for _ in 0..60 {
            p.step(DT, &stop).unwrap();
            b.step();
        }
        let (mut tp, mut tb) = (Vec::new(), Vec::new());
        for _ in 0..3 {
            let t = Instant::now();
            for _ in 0..60 {
                b.step();
            }
            tb.push(t.elapsed().as_secs_f64() / 60.0);
            let t = Instant::now();
            for _ in 0..60 {
                p.step(DT, &stop).unwrap();
            }
            tp.push(t.elapsed().as_secs_f64() / 60.0);
        }
        let (mp, mb) = (median(tp), median(tb));
        println!("| {n} | {:.2} | {:.2} | {:+.1} % |", 1e3 * mb, 1e3 * mp, 100.0 * (mp / mb - 1.0));
    }
}
