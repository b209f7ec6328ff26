//! The world: several systems stepped together with one clock, atomic rollback across all of
//! them, couplings after every step, and the ODE layer's tableaux shared with the particle
//! integrators.

use super::common::oscillator;
use glam::DVec2;
use physcore_core::error::Error;
use physcore_core::systems::ode::OdeSystem;
use physcore_core::systems::particles::ParticleSystem;
use physcore_core::systems::{Arrays, Coupling, System};
use physcore_core::World;
use std::sync::{Arc, Mutex};

/// q' = p, p' = −q: the particle oscillator of `common::oscillator` as a first-order ODE.
fn harmonic(method: &str, max_dt: Option<f64>) -> OdeSystem {
    let rhs = Box::new(|y: &[f64], dy: &mut [f64]| {
        dy[0] = y[1];
        dy[1] = -y[0];
    });
    OdeSystem::new("harmonic", vec![1.0, 0.0], method, rhs, max_dt)
        .unwrap()
        .with_energy(Box::new(|y: &[f64]| 0.5 * (y[0] * y[0] + y[1] * y[1])))
}

#[test]
fn a_second_system_steps_with_the_particles_on_one_clock_and_the_tableau_matches_rk4() {
    let mut w = oscillator("rk4", 0.01);
    w.add_system(Box::new(harmonic("rk4", None))).unwrap();
    w.step(700).unwrap();
    assert_eq!(w.steps(), 700);
    assert!((w.time() - 7.0).abs() < 1e-12);
    let q = w.others()[0].fields(&["y"]).unwrap()[0].clone();
    let x = w.particles().state().x[1].x;
    // The same problem by the fused particle RK4 and by the generic tableau step: equal up to
    // the rounding of differently ordered sums, and both at RK4's accuracy.
    assert!((q[0] - x).abs() < 1e-13, "tableau rk4 {} vs particle rk4 {x}", q[0]);
    assert!((q[0] - 7.0f64.cos()).abs() < 1e-8);
    // The books of both systems, in one report: each conserves its energy to RK4's error.
    let e = w.energy();
    assert!(e.potential.iter().any(|(n, _)| n == "harmonic"), "{e:?}");
    assert!((e.total() - 1.0).abs() < 1e-8, "0.5 (particle) + 0.5 (ODE), got {}", e.total());
}

#[test]
fn a_divergence_in_any_system_rolls_every_system_back() {
    let mut w = oscillator("verlet", 0.01);
    // y' = y², y(0) = 1 blows up at t = 1.
    let blowup = Box::new(|y: &[f64], dy: &mut [f64]| dy[0] = y[0] * y[0]);
    w.add_system(Box::new(OdeSystem::new("blowup", vec![1.0], "euler", blowup, None).unwrap())).unwrap();
    w.step(10).unwrap();
    let (x, y, t) = (w.particles().state().clone(), w.others()[0].fields(&["y"]).unwrap(), w.time());
    match w.step(100_000) {
        Err(Error::Diverged { step, rolled_back_to, particle, .. }) => {
            assert!(step > 10 && step < 100_000);
            assert_eq!(rolled_back_to, 10);
            assert_eq!(particle, 0, "the ODE component that blew up");
        }
        other => panic!("expected a divergence, got {other:?}"),
    }
    assert!(w.particles().state() == &x, "the particles were not rolled back with the ODE");
    assert_eq!(w.others()[0].fields(&["y"]).unwrap(), y);
    assert_eq!((w.time(), w.steps()), (t, 10));
}

#[test]
fn advance_keeps_to_the_smallest_stable_step_of_all_systems() {
    let mut w = oscillator("verlet", 0.1);
    let particles_dt: f64 = w.auto_dt().unwrap();
    w.add_system(Box::new(harmonic("rk4", Some(particles_dt / 3.0)))).unwrap();
    assert_eq!(w.auto_dt(), Some(particles_dt / 3.0));
    let n = w.advance_interruptible(1.0, None, &Arc::default()).unwrap();
    assert_eq!(n, (1.0 / (particles_dt / 3.0)).ceil() as u64);
}

/// Records the ODE's state it sees after every step.
struct Probe(Arc<Mutex<Vec<f64>>>);

impl Coupling<DVec2> for Probe {
    fn name(&self) -> &str {
        "probe"
    }
    fn apply(&mut self, _particles: &mut ParticleSystem<DVec2>, others: &mut [Box<dyn System>], _dt: f64) {
        self.0.lock().unwrap().push(others[0].fields(&["y"]).unwrap()[0][0]);
    }
}

#[test]
fn couplings_run_after_every_step_and_see_the_stepped_systems() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut w = World::<DVec2>::new(ParticleSystem::<DVec2>::new("verlet").unwrap(), 0.1, Some(1)).unwrap();
    w.add_system(Box::new(harmonic("heun", None))).unwrap();
    w.add_coupling(Box::new(Probe(seen.clone())));
    let mut alone = harmonic("heun", None);
    let mut expected = Vec::new();
    for _ in 0..5 {
        alone.step(0.1, &Default::default()).unwrap();
        expected.push(alone.y()[0]);
    }
    w.step(5).unwrap();
    assert_eq!(*seen.lock().unwrap(), expected);
}

#[test]
fn system_names_are_unique_and_bad_ode_input_is_refused() {
    let mut w = oscillator("verlet", 0.1);
    w.add_system(Box::new(harmonic("rk4", None))).unwrap();
    assert!(matches!(w.add_system(Box::new(harmonic("rk4", None))), Err(Error::InvalidInput { .. })));
    let rhs = || Box::new(|_: &[f64], _: &mut [f64]| {});
    assert!(OdeSystem::new("x", vec![1.0], "rk5", rhs(), None).is_err());
    assert!(OdeSystem::new("x", vec![f64::NAN], "rk4", rhs(), None).is_err());
    assert!(OdeSystem::new("x", vec![1.0], "rk4", rhs(), Some(0.0)).is_err());
    assert_eq!(w.others().len(), 1);
}

#[test]
fn an_ode_system_is_bit_identical_for_1_and_2_threads() {
    let run = |threads| {
        let mut w = World::<DVec2>::new(ParticleSystem::<DVec2>::new("verlet").unwrap(), 1e-3, Some(threads)).unwrap();
        let n = 200_000;
        let y0: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        // A ring of coupled rates: every derivative reads its neighbours.
        let rhs = Box::new(move |y: &[f64], dy: &mut [f64]| {
            for i in 0..y.len() {
                dy[i] = y[(i + 1) % y.len()] - 2.0 * y[i] + y[(i + y.len() - 1) % y.len()] - y[i] * y[i] * y[i];
            }
        });
        w.add_system(Box::new(OdeSystem::new("ring", y0, "dopri5", rhs, None).unwrap())).unwrap();
        w.step(20).unwrap();
        w.others()[0].fields(&["y"]).unwrap().remove(0)
    };
    let (a, b) = (run(1), run(2));
    assert!(a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()));
}

/// A damped cloth falling onto a floor (constraint books), plus an ODE system.
fn restartable(integrator: &str) -> World<glam::DVec3> {
    use physcore_core::constraints::Plane;
    let mut w = super::common::cloth(6, integrator, 2, 0.05);
    let floor = Plane::new(glam::DVec3::new(0.0, 0.0, -0.05), glam::DVec3::Z, 0.5, 0.3).unwrap();
    w.particles_mut().add_constraint(Box::new(floor));
    w.add_system(Box::new(harmonic("dopri5", None))).unwrap();
    if integrator == "dopri5" {
        w.set_dt(0.01).unwrap();
    }
    w
}

#[test]
fn a_run_restarted_from_its_saved_arrays_continues_bit_for_bit() {
    // The Wisdom–Holman map steps planetary systems only (no floor, no pins): its restart is
    // tests/integrators/test_wisdom_holman.py's.
    for integrator in physcore_core::integrators::NAMES.into_iter().filter(|n| *n != "wisdom_holman") {
        let mut a = restartable(integrator);
        a.step(30).unwrap();
        let (clock, systems) = a.save().unwrap();
        let mut b = restartable(integrator);
        b.load(clock, &systems).unwrap();
        a.step(40).unwrap();
        b.step(40).unwrap();
        assert!(a.particles().state() == b.particles().state(), "{integrator}: particles differ after the restart");
        assert_eq!(a.others()[0].fields(&["y"]).unwrap(), b.others()[0].fields(&["y"]).unwrap(), "{integrator}");
        assert_eq!(a.energy(), b.energy(), "{integrator}: books differ");
        assert_eq!((a.time(), a.steps()), (b.time(), b.steps()));
        assert_eq!(a.particles().adaptive_stats(), b.particles().adaptive_stats(), "{integrator}");
    }
}

#[test]
fn a_bad_saved_state_is_refused_by_name_and_changes_nothing() {
    let mut a = restartable("verlet");
    a.step(5).unwrap();
    let (clock, good) = a.save().unwrap();
    let mut b = restartable("verlet");
    b.step(3).unwrap();
    let before = b.save().unwrap();
    let edit = |sys: usize, name: &str, f: &dyn Fn(&mut Vec<f64>)| {
        let mut s = good.clone();
        let (_, arrays) = &mut s[sys];
        f(&mut arrays.iter_mut().find(|(n, _)| n == name).unwrap().1);
        s
    };
    let cases: Vec<(&str, Vec<(String, Arrays)>)> = vec![
        ("x", edit(0, "x", &|x| x[4] = f64::NAN)),
        ("v", edit(0, "v", &|v| v.truncate(3))),
        ("dissipated", edit(0, "dissipated", &|d| d[0] = f64::INFINITY)),
        ("y", edit(1, "y", &|y| y.push(0.0))),
        ("systems", good[..1].to_vec()),
    ];
    for (arg, saved) in cases {
        match b.load(clock, &saved) {
            Err(Error::InvalidInput { arg: got, .. }) => assert_eq!(got, arg),
            other => panic!("{arg}: expected InvalidInput, got {other:?}"),
        }
        assert_eq!(b.save().unwrap(), before, "{arg}: a refused load changed the world");
    }
    assert!(b.load((f64::NAN, 0, 0.1), &good).is_err());
    assert!(b.load((0.0, 0, 0.0), &good).is_err());
    assert_eq!(b.save().unwrap(), before);
}
