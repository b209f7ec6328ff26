//! Integrator numerics: convergence orders, stability, energy behaviour.

use super::common::oscillator;
use physcore_core::integrators::{by_name, NAMES};
use physcore_core::ParticleSystem;

fn error_at(integrator: &str, dt: f64, t_end: f64) -> f64 {
    let mut s = oscillator(integrator, dt);
    let n = (t_end / dt).round() as u64;
    s.step(n).unwrap();
    let t = s.time();
    let (x, v) = (s.particles().state().x[1], s.particles().state().v[1]);
    ((x.x - t.cos()).powi(2) + (v.x + t.sin()).powi(2) + x.y.powi(2) + v.y.powi(2)).sqrt()
}

fn observed_order(integrator: &str, dt0: f64) -> f64 {
    let e1 = error_at(integrator, dt0, 2.0);
    let e2 = error_at(integrator, dt0 / 2.0, 2.0);
    let e3 = error_at(integrator, dt0 / 4.0, 2.0);
    0.5 * ((e1 / e2).log2() + (e2 / e3).log2())
}

#[test]
fn convergence_orders_match_reported_order() {
    for (name, dt0) in [
        ("euler", 1e-3),
        ("semi_implicit_euler", 1e-3),
        ("verlet", 1e-2),
        ("yoshida4", 5e-2),
        ("rk4", 5e-2),
        ("boris", 1e-2),
        ("implicit_euler", 1e-3),
    ] {
        let p = observed_order(name, dt0);
        let reported = by_name::<glam::DVec2>(name).unwrap().info().order as f64;
        assert!((p - reported).abs() < 0.1, "{name}: observed order {p:.3}, reported {reported}");
    }
}

#[test]
fn integrator_table() {
    let infos: Vec<_> = NAMES.iter().map(|n| by_name::<glam::DVec3>(n).unwrap().info()).collect();
    let got: Vec<_> = infos.iter().map(|i| (i.name, i.order, i.symplectic, i.force_evals_per_step)).collect();
    assert_eq!(
        got,
        vec![
            ("euler", 1, false, 1),
            ("semi_implicit_euler", 1, true, 1),
            ("verlet", 2, true, 1),
            ("yoshida4", 4, true, 3),
            ("rk4", 4, false, 4),
            ("dopri5", 5, false, 6),
            ("wisdom_holman", 2, true, 1),
            ("boris", 2, false, 1),
            ("xpbd", 1, false, 10),
            ("implicit_euler", 1, false, 1),
        ]
    );
    assert!(by_name::<glam::DVec2>("leapfrogg").is_err());
}

/// Amplitude growth factor after `steps` steps at ω·dt = w (ω = 1).
fn growth(integrator: &str, w: f64, steps: u64) -> f64 {
    let mut s = oscillator(integrator, w);
    match s.step(steps) {
        Ok(()) => {
            let e = s.energy().total();
            (e / 0.5).sqrt()
        }
        Err(_) => f64::INFINITY,
    }
}

#[test]
fn stability_limits_match_theory() {
    // Semi-implicit Euler and Verlet: stable for ω·dt < 2; RK4: up to 2√2; explicit Euler: never.
    for name in ["semi_implicit_euler", "verlet"] {
        assert!(growth(name, 1.95, 2000) < 100.0, "{name} should be stable at 1.95");
        assert!(growth(name, 2.05, 2000) > 1e6, "{name} should be unstable at 2.05");
    }
    assert!(growth("rk4", 2.8, 2000) < 2.0, "rk4 stable (damped) just below 2√2");
    assert!(growth("rk4", 2.86, 2000) > 10.0, "rk4 unstable above 2√2");
    assert!(growth("euler", 0.01, 20_000) > 2.0, "explicit Euler grows even at small dt");
}

#[test]
fn symplectic_methods_have_no_secular_energy_drift() {
    for name in ["semi_implicit_euler", "verlet"] {
        let mut s = oscillator(name, 0.1);
        let e0 = s.energy().total();
        let mut first = 0.0f64;
        let mut last = 0.0f64;
        for k in 0..40_000 {
            s.step(1).unwrap();
            let de = ((s.energy().total() - e0) / e0).abs();
            if k < 10_000 {
                first = first.max(de);
            } else if k >= 30_000 {
                last = last.max(de);
            }
        }
        assert!(last < 1.5 * first, "{name}: error grew from {first:e} to {last:e}");
        assert!(first < 0.06, "{name}: error {first:e} too large at ω·dt = 0.1");
    }
}

/// Damped oscillator m x'' = -k x - c x' (m = k = 1, c = 0.4): x(t) = e^{-ζt}(cos ω_d t + ζ/ω_d sin ω_d t).
fn damped_error(integrator: &str, dt: f64) -> f64 {
    use physcore_core::terms::Springs;
    let c = 0.4;
    let mut s = physcore_core::World::new(ParticleSystem::new(integrator).unwrap(), dt, Some(1)).unwrap();
    s.particles_mut()
        .add_particles(
            vec![glam::DVec2::ZERO, glam::DVec2::new(1.0, 0.0)],
            vec![glam::DVec2::ZERO; 2],
            vec![1.0, 1.0],
            vec![true, false],
        )
        .unwrap();
    // Rest length 0.5 keeps the spring axis along x for |x| > 0.5 with a 0.5 amplitude.
    s.particles_mut()
        .add_term(Box::new(Springs::new("s".into(), vec![0], vec![1], vec![1.0], vec![c], vec![0.5], 2).unwrap()))
        .unwrap();
    s.particles_mut().set_state(Some(vec![glam::DVec2::ZERO, glam::DVec2::new(1.0, 0.0)]), None).unwrap();
    let n = (2.0 / dt).round() as u64;
    s.step(n).unwrap();
    let t = s.time();
    let (z, wd) = (c / 2.0, (1.0f64 - c * c / 4.0).sqrt());
    let exact = 0.5 + 0.5 * (-z * t).exp() * ((wd * t).cos() + z / wd * (wd * t).sin());
    (s.particles().state().x[1].x - exact).abs()
}

#[test]
fn verlet_stays_second_order_with_velocity_dependent_forces() {
    for (name, want) in [("verlet", 2.0), ("rk4", 4.0), ("semi_implicit_euler", 1.0)] {
        let (e1, e2, e3) = (damped_error(name, 0.02), damped_error(name, 0.01), damped_error(name, 0.005));
        let p = 0.5 * ((e1 / e2).log2() + (e2 / e3).log2());
        assert!((p - want).abs() < 0.15, "{name}: observed order {p:.3} with damping, expected {want}");
    }
}

/// A strongly damped spring (2c/m = 200/s against ω = 1/s): the suggested dt must come from the
/// dashpot rate, and the explicit integrators must be stable there with balanced books.
#[test]
fn suggested_dt_accounts_for_dashpots() {
    use physcore_core::terms::Springs;
    for name in ["semi_implicit_euler", "verlet", "rk4"] {
        let mut s = physcore_core::World::new(ParticleSystem::new(name).unwrap(), 1.0, Some(1)).unwrap();
        s.particles_mut()
            .add_particles(
                vec![glam::DVec2::ZERO, glam::DVec2::new(1.0, 0.0)],
                vec![glam::DVec2::ZERO, glam::DVec2::new(0.0, 1.0)],
                vec![1.0, 1.0],
                vec![true, false],
            )
            .unwrap();
        s.particles_mut()
            .add_term(Box::new(
                Springs::new("s".into(), vec![0], vec![1], vec![1.0], vec![100.0], vec![0.5], 2).unwrap(),
            ))
            .unwrap();
        let dt = s.suggest_dt();
        assert!(dt <= 0.5 / 200.0 + 1e-15, "{name}: suggested {dt} ignores the dashpot rate 2c/m = 200/s");
        s.set_dt(dt).unwrap();
        s.step(2000).unwrap();
        let e = s.energy();
        let total = e.total();
        assert!((total - 0.5 - 0.125).abs() < 1e-2, "{name}: books {e:?}");
    }
}

/// dopri5 on the oscillator (ω = 1) over 10 periods, one output step per unit time: the global
/// error follows the tolerance (tolerance proportionality, Hairer, Nørsett & Wanner I, §II.4),
/// each call lands exactly on its output time, and the work grows like rtol^(-1/5).
#[test]
fn dopri5_error_follows_tolerance() {
    let t_end = 20.0 * std::f64::consts::PI;
    let mut errs = vec![];
    let mut evals = vec![];
    for rtol in [1e-4, 1e-6, 1e-8, 1e-10] {
        let mut s = oscillator("dopri5", 1.0);
        s.particles_mut().set_tolerances(rtol, rtol * 1e-3).unwrap();
        let n = t_end.round() as u64;
        s.step(n).unwrap();
        let t = s.time();
        assert_eq!(t, n as f64, "time is n·dt exactly");
        let (x, v) = (s.particles().state().x[1], s.particles().state().v[1]);
        let e = ((x.x - t.cos()).powi(2) + (v.x + t.sin()).powi(2)).sqrt();
        let (acc, rej, _) = s.particles().adaptive_stats().unwrap();
        assert!(acc > 0 && rej <= acc, "rtol {rtol}: {acc} accepted, {rej} rejected");
        errs.push(e);
        evals.push(s.force_evaluations() as f64);
    }
    for k in 0..errs.len() {
        let rtol = [1e-4, 1e-6, 1e-8, 1e-10][k];
        // ~60 steps' local errors of ≤ rtol each add up to at most a few hundred rtol.
        assert!(errs[k] < 300.0 * rtol && errs[k] > 1e-3 * rtol, "rtol {rtol}: global error {:e}", errs[k]);
    }
    for k in 1..errs.len() {
        let r = errs[k - 1] / errs[k];
        assert!((10.0..1e4).contains(&r), "100× smaller rtol gave {r:.1}× smaller error");
        // Order 5: 100× tighter costs 100^(1/5) ≈ 2.5× more evaluations.
        let w = evals[k] / evals[k - 1];
        assert!((1.8..3.5).contains(&w), "100× smaller rtol cost {w:.2}× the evaluations");
    }
}

/// dopri5 follows a Kepler orbit with e = 0.9 through 10 pericentre passages (a 1.9/0.1 = 19:1
/// range of distances): the step shrinks near pericentre instead of failing, energy holds.
#[test]
fn dopri5_kepler_high_eccentricity() {
    use glam::DVec2;
    use physcore_core::terms::PairwiseGravity;
    let e: f64 = 0.9;
    let mut s =
        physcore_core::World::<DVec2>::new(ParticleSystem::<DVec2>::new("dopri5").unwrap(), 0.5, Some(1)).unwrap();
    let rp = 1.0 - e;
    let vp = ((1.0 + e) / rp).sqrt();
    s.particles_mut()
        .add_particles(
            vec![DVec2::ZERO, DVec2::new(rp, 0.0)],
            vec![DVec2::ZERO, DVec2::new(0.0, vp)],
            vec![1.0, 1e-12],
            vec![true, false],
        )
        .unwrap();
    s.particles_mut().add_term(Box::new(PairwiseGravity::new("gravity".into(), 1.0, 0.0))).unwrap();
    s.particles_mut().set_tolerances(1e-10, 1e-13).unwrap();
    let e0 = s.energy().total();
    let period = 2.0 * std::f64::consts::PI;
    s.set_dt(period / 16.0).unwrap();
    s.step(160).unwrap();
    let de = ((s.energy().total() - e0) / e0).abs();
    let x = s.particles().state().x[1];
    assert!(de < 1e-7, "energy error {de:e}");
    assert!((x - DVec2::new(rp, 0.0)).length() < 1e-5, "back at pericentre after 10 orbits: {x:?}");
    let (acc, _, _) = s.particles().adaptive_stats().unwrap();
    assert!(acc > 160, "adaptive steps taken: {acc}");
}

/// Same scene, 1 and 2 threads, an dopri5 run larger than one parallel chunk: bit-identical.
#[test]
fn dopri5_is_deterministic_and_fails_cleanly() {
    use glam::DVec2;
    use physcore_core::terms::Springs;
    let run = |threads| {
        let n = 5000;
        let mut s =
            physcore_core::World::<DVec2>::new(ParticleSystem::<DVec2>::new("dopri5").unwrap(), 0.01, Some(threads))
                .unwrap();
        let x: Vec<DVec2> = (0..n).map(|i| DVec2::new(i as f64 * 0.01, ((i * 7919) % 13) as f64 * 1e-3)).collect();
        s.particles_mut()
            .add_particles(x, vec![DVec2::ZERO; n], vec![1e-3; n], (0..n).map(|i| i == 0).collect())
            .unwrap();
        let a: Vec<u32> = (0..n as u32 - 1).collect();
        let b: Vec<u32> = (1..n as u32).collect();
        s.particles_mut()
            .add_term(Box::new(
                Springs::new("s".into(), a, b, vec![50.0; n - 1], vec![0.0; n - 1], vec![0.009; n - 1], n).unwrap(),
            ))
            .unwrap();
        s.step(5).unwrap();
        (s.particles().state().x.clone(), s.particles().state().v.clone())
    };
    assert_eq!(run(1), run(2));

    // Forces that are infinite at the start: the controller gives up with the particle named,
    // and the state is rolled back.
    use physcore_core::terms::PairwiseGravity;
    let mut s =
        physcore_core::World::<DVec2>::new(ParticleSystem::<DVec2>::new("dopri5").unwrap(), 0.1, Some(1)).unwrap();
    s.particles_mut()
        .add_particles(
            vec![DVec2::ZERO, DVec2::new(1e-160, 0.0)],
            vec![DVec2::ZERO; 2],
            vec![1.0, 1.0],
            vec![false, false],
        )
        .unwrap();
    s.particles_mut().add_term(Box::new(PairwiseGravity::new("gravity".into(), 1.0, 0.0))).unwrap();
    let err = s.step(1).unwrap_err().to_string();
    assert!(err.contains("rtol/atol") && err.contains("particle"), "{err}");
    assert_eq!(s.steps(), 0);
    assert_eq!(s.particles().state().x[1], DVec2::new(1e-160, 0.0));
}
