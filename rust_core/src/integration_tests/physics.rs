//! Terms, colliders, energy books, conservation laws, determinism and error handling.

use super::common::{cloth, cloud, Rng};
use glam::{DVec2, DVec3};
use physcore_core::constraints::{Aabb, Plane, Sphere};
use physcore_core::terms::{Drag, Springs, UniformGravity};
use physcore_core::{Error, ParticleSystem, World};

#[test]
fn springs_and_gravity_conserve_momentum_to_round_off() {
    let mut s = cloud(200, 2, 0.05);
    let p0 = s.momentum();
    s.step(200).unwrap();
    assert!((s.momentum() - p0).length() < 1e-15, "pairwise gravity momentum drift {:e}", (s.momentum() - p0).length());

    let mut r = Rng(3);
    let n = 300;
    let x: Vec<DVec3> = (0..n).map(|_| DVec3::new(r.uniform(), r.uniform(), r.uniform())).collect();
    // Velocity Verlet conserves P and L of central forces exactly up to round-off (RK4 only P).
    let mut sim = World::new(ParticleSystem::new("verlet").unwrap(), 1e-3, Some(2)).unwrap();
    sim.particles_mut().add_particles(x, vec![DVec3::ZERO; n], vec![1.0; n], vec![false; n]).unwrap();
    let m = 1000;
    let i: Vec<u32> = (0..m).map(|_| (r.next_u64() % n as u64) as u32).collect();
    let j: Vec<u32> = i.iter().map(|&a| (a + 1 + (r.next_u64() % (n as u64 - 1)) as u32) % n as u32).collect();
    let rest: Vec<f64> = (0..m).map(|_| 0.5 * r.uniform()).collect();
    sim.particles_mut()
        .add_term(Box::new(Springs::new("s".into(), i, j, vec![50.0; m], vec![0.3; m], rest, n).unwrap()))
        .unwrap();
    let l0 = sim.angular_momentum();
    sim.step(500).unwrap();
    assert!(sim.momentum().length() < 1e-12, "spring momentum {:e}", sim.momentum().length());
    let l1 = sim.angular_momentum();
    let dl = ((l1[0] - l0[0]).powi(2) + (l1[1] - l0[1]).powi(2) + (l1[2] - l0[2]).powi(2)).sqrt();
    assert!(dl < 1e-11, "central spring forces changed L by {dl:e}");
}

#[test]
fn results_are_bit_identical_for_1_and_2_threads() {
    let mut a = cloth(80, "verlet", 1, 0.01);
    let mut b = cloth(80, "verlet", 2, 0.01);
    a.step(50).unwrap();
    b.step(50).unwrap();
    assert_eq!(a.particles().state().x, b.particles().state().x);
    assert_eq!(a.particles().state().v, b.particles().state().v);
    assert_eq!(a.energy(), b.energy());

    let mut a = cloud(300, 1, 0.01);
    let mut b = cloud(300, 2, 0.01);
    a.step(20).unwrap();
    b.step(20).unwrap();
    assert_eq!(a.particles().state().x, b.particles().state().x);
    assert_eq!(a.energy(), b.energy());
}

#[test]
fn damped_energy_books_balance() {
    // Dashpots and drag: total = kinetic + potential + dissipated stays put while mechanical
    // energy falls.
    let mut s = cloth(20, "rk4", 2, 0.05);
    s.particles_mut().add_term(Box::new(Drag { name: "drag".into(), b: 1e-3 })).unwrap();
    s.step(1).unwrap();
    let e0 = s.energy();
    s.step(3000).unwrap();
    let e1 = s.energy();
    let mech = |e: &physcore_core::EnergyReport| e.kinetic + e.potential.iter().map(|p| p.1).sum::<f64>();
    let dissipated: f64 = e1.dissipated.iter().map(|p| p.1).sum();
    assert!(dissipated > 1e-3 * mech(&e0).abs(), "something must be dissipated: {dissipated:e}");
    let scale = e1.kinetic + e1.potential.iter().map(|p| p.1.abs()).sum::<f64>();
    let residual = (e1.total() - e0.total()).abs() / scale;
    assert!(residual < 1e-6, "books off by {residual:e} of the energy scale");
}

#[test]
fn plane_bounce_follows_restitution() {
    let e = 0.8;
    let mut s = World::new(ParticleSystem::new("verlet").unwrap(), 1e-4, Some(1)).unwrap();
    s.particles_mut().add_particles(vec![DVec2::new(0.0, 1.0)], vec![DVec2::ZERO], vec![2.0], vec![false]).unwrap();
    s.particles_mut().add_term(Box::new(UniformGravity { name: "gravity".into(), g: DVec2::new(0.0, -9.81) })).unwrap();
    s.particles_mut().add_constraint(Box::new(Plane::new(DVec2::ZERO, DVec2::new(0.0, 3.0), e, 0.0).unwrap()));
    // Apex heights after the first and second bounce: 1·e², 1·e⁴.
    let mut apex = Vec::new();
    let mut prev_vy = 0.0;
    for _ in 0..40_000 {
        s.step(1).unwrap();
        let vy = s.particles().state().v[0].y;
        if prev_vy > 0.0 && vy <= 0.0 {
            apex.push(s.particles().state().x[0].y);
        }
        prev_vy = vy;
        assert!(s.particles().state().x[0].y >= 0.0);
    }
    assert!(apex.len() >= 2);
    assert!((apex[0] - e * e).abs() < 5e-3, "first apex {} vs {}", apex[0], e * e);
    assert!((apex[1] - e.powi(4)).abs() < 5e-3, "second apex {} vs {}", apex[1], e.powi(4));
    let en = s.energy();
    let coll = en.dissipated.iter().find(|p| p.0 == "collisions").unwrap().1;
    assert!(coll > 0.0);
    assert!((en.total() - 2.0 * 9.81).abs() < 2e-3 * 2.0 * 9.81, "books {:?}", en);
}

#[test]
fn sphere_bounce_follows_restitution_and_books_balance() {
    // A particle dropped from 1 m above the top of a sphere bounces straight up to e², then e⁴.
    let (e, r) = (0.8, 0.5);
    let mut s = World::new(ParticleSystem::new("verlet").unwrap(), 1e-4, Some(1)).unwrap();
    s.particles_mut()
        .add_particles(vec![DVec3::new(0.0, 0.0, r + 1.0)], vec![DVec3::ZERO], vec![2.0], vec![false])
        .unwrap();
    s.particles_mut()
        .add_term(Box::new(UniformGravity { name: "gravity".into(), g: DVec3::new(0.0, 0.0, -9.81) }))
        .unwrap();
    s.particles_mut().add_constraint(Box::new(Sphere::new(DVec3::ZERO, r, false, e, 0.0).unwrap()));
    let mut apex = Vec::new();
    let mut prev_vz = 0.0;
    for _ in 0..40_000 {
        s.step(1).unwrap();
        let (x, v) = (s.particles().state().x[0], s.particles().state().v[0]);
        if prev_vz > 0.0 && v.z <= 0.0 {
            apex.push(x.z - r);
        }
        prev_vz = v.z;
        assert!(x.length() >= r * (1.0 - 1e-15), "inside the sphere: {x:?}");
        assert!(x.x == 0.0 && x.y == 0.0, "a bounce on the top stays on the axis: {x:?}");
    }
    assert!(apex.len() >= 2);
    assert!((apex[0] - e * e).abs() < 5e-3, "first apex {} vs {}", apex[0], e * e);
    assert!((apex[1] - e.powi(4)).abs() < 5e-3, "second apex {} vs {}", apex[1], e.powi(4));
    let en = s.energy();
    let coll = en.dissipated.iter().find(|p| p.0 == "collisions").unwrap().1;
    assert!(coll > 0.5 * 2.0 * 9.81 * (1.0 - e.powi(4)), "collisions booked {coll}");
    assert!((en.total() - 2.0 * 9.81 * (r + 1.0)).abs() < 2e-3 * 2.0 * 9.81, "books {:?}", en);
}

#[test]
fn sphere_collider_is_bit_identical_for_1_and_2_threads() {
    let run = |threads| {
        let mut w = cloth(80, "verlet", threads, 0.01);
        w.particles_mut()
            .add_constraint(Box::new(Sphere::new(DVec3::new(0.5, 0.5, 0.1), 0.3, false, 0.3, 0.4).unwrap()));
        w.step(50).unwrap();
        w
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.particles().state().x, b.particles().state().x);
    assert_eq!(a.particles().state().v, b.particles().state().v);
    assert_eq!(a.energy(), b.energy());
    let c = DVec3::new(0.5, 0.5, 0.1);
    assert!(a.particles().state().x.iter().all(|x| (*x - c).length() >= 0.3 * (1.0 - 1e-12)));
}

#[test]
fn divergence_is_reported_and_rolled_back() {
    let mut s = World::new(ParticleSystem::new("euler").unwrap(), 1.0, Some(1)).unwrap();
    s.particles_mut()
        .add_particles(
            vec![DVec2::ZERO, DVec2::new(1.0, 0.0)],
            vec![DVec2::ZERO, DVec2::new(0.0, 1.0)],
            vec![1.0, 1.0],
            vec![true, false],
        )
        .unwrap();
    s.particles_mut()
        .add_term(Box::new(Springs::new("s".into(), vec![0], vec![1], vec![1e9], vec![0.0], vec![0.5], 2).unwrap()))
        .unwrap();
    s.step(2).unwrap_or(());
    let before = s.particles().state().clone();
    let before_step = s.steps();
    match s.step(10_000) {
        Err(Error::Diverged { step, particle, suggested_dt, rolled_back_to, .. }) => {
            assert!(step > before_step);
            assert_eq!(particle, 1);
            assert!(suggested_dt < 1e-4, "suggested {suggested_dt}");
            assert_eq!(rolled_back_to, before_step);
        }
        other => panic!("expected divergence, got {other:?}"),
    }
    assert_eq!(s.particles().state().x, before.x);
    assert_eq!(s.steps(), before_step);
    assert!(s.particles().state().x.iter().all(|p| p.is_finite()));
}

#[test]
fn bad_input_is_rejected_before_state_changes() {
    let mut s: World<DVec2> = World::new(ParticleSystem::new("verlet").unwrap(), 1e-3, None).unwrap();
    assert!(matches!(ParticleSystem::<DVec2>::new("leapfrogg"), Err(Error::InvalidInput { .. })));
    assert!(World::<DVec2>::new(ParticleSystem::<DVec2>::new("rk4").unwrap(), 0.0, None).is_err());
    assert!(World::<DVec2>::new(ParticleSystem::<DVec2>::new("rk4").unwrap(), f64::NAN, None).is_err());
    assert!(s
        .particles_mut()
        .add_particles(vec![DVec2::new(f64::NAN, 0.0)], vec![DVec2::ZERO], vec![1.0], vec![false])
        .is_err());
    assert!(s.particles_mut().add_particles(vec![DVec2::ZERO], vec![DVec2::ZERO], vec![0.0], vec![false]).is_err());
    assert!(s.particles_mut().add_particles(vec![DVec2::ZERO], vec![DVec2::ZERO; 2], vec![1.0], vec![false]).is_err());
    assert_eq!(s.n_particles(), 0);
    s.particles_mut()
        .add_particles(vec![DVec2::ZERO, DVec2::X], vec![DVec2::ZERO; 2], vec![1.0; 2], vec![false; 2])
        .unwrap();
    assert!(Springs::<DVec2>::new("s".into(), vec![0], vec![2], vec![1.0], vec![0.0], vec![1.0], 2).is_err());
    assert!(Springs::<DVec2>::new("s".into(), vec![1], vec![1], vec![1.0], vec![0.0], vec![1.0], 2).is_err());
    assert!(Springs::<DVec2>::new("s".into(), vec![0], vec![1], vec![-1.0], vec![0.0], vec![1.0], 2).is_err());
    assert!(Plane::new(DVec2::ZERO, DVec2::ZERO, 0.5, 0.0).is_err());
    assert!(Plane::new(DVec2::ZERO, DVec2::Y, 1.5, 0.0).is_err());
    assert!(Plane::new(DVec2::ZERO, DVec2::Y, 0.5, -1.0).is_err());
    assert!(Aabb::new(DVec2::ZERO, DVec2::new(1.0, 0.0), 0.5, 0.0).is_err());
    assert!(Aabb::new(DVec2::ZERO, DVec2::ONE, 0.5, f64::NAN).is_err());
    assert_eq!(s.particles().n_constraints(), 0);
}

#[test]
fn zero_length_spring_and_coincident_bodies_give_no_nan() {
    let mut s = World::new(ParticleSystem::new("rk4").unwrap(), 1e-3, Some(1)).unwrap();
    s.particles_mut().add_particles(vec![DVec3::ONE; 3], vec![DVec3::ZERO; 3], vec![1.0; 3], vec![false; 3]).unwrap();
    s.particles_mut()
        .add_term(Box::new(
            Springs::new("s".into(), vec![0, 1], vec![1, 2], vec![10.0; 2], vec![1.0; 2], vec![0.0, 1.0], 3).unwrap(),
        ))
        .unwrap();
    s.particles_mut().add_term(Box::new(physcore_core::terms::PairwiseGravity::new("g".into(), 1.0, 0.0))).unwrap();
    s.step(100).unwrap();
    assert!(s.particles().state().x.iter().all(|p| p.is_finite()));
    assert!(s.energy().total().is_finite());
}
