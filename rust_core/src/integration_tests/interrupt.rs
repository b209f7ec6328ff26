//! The stop flag of `step_interruptible`: read between steps and between dopri5's internal step
//! attempts, it rolls everything back, and reading it never changes a result; `run_watched`
//! leaves the calling thread free to set it.

use super::common::{cloth, planets};
use glam::DVec3;
use physcore_core::error::Error;
use physcore_core::integrators::NAMES;
use physcore_core::state::Model;
use physcore_core::terms::{Springs, Term, Traits, UniformGravity, Write};
use physcore_core::ParticleSystem;
use physcore_core::World;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A force-free term that sets `flag` during its `at`-th evaluation (counting from 1), so an
/// interrupt lands at a chosen point inside a step, the same on every run.
struct Tripwire {
    flag: Arc<AtomicBool>,
    at: u64,
    calls: u64,
}

impl Term<DVec3> for Tripwire {
    fn name(&self) -> &str {
        "tripwire"
    }
    fn add_forces(&mut self, _x: &[DVec3], _v: &[DVec3], _m: &Model, f: &mut [DVec3], write: Write) -> f64 {
        if write == Write::Overwrite {
            f.fill(DVec3::ZERO);
        }
        self.calls += 1;
        if self.calls == self.at {
            self.flag.store(true, Ordering::Relaxed);
        }
        0.0
    }
    fn potential(&self, _x: &[DVec3], _m: &Model) -> Option<f64> {
        None
    }
    fn traits(&self) -> Traits<DVec3> {
        Traits::conservative()
    }
}

type Snapshot = (Vec<DVec3>, Vec<DVec3>, f64, u64, Vec<f64>, f64, Option<(Vec<DVec3>, Vec<f64>)>);

fn snapshot(s: &World<DVec3>) -> Snapshot {
    let st = s.particles().state();
    (
        st.x.clone(),
        st.v.clone(),
        s.time(),
        s.steps(),
        s.particles().forces().dissipated.clone(),
        s.particles().constraints_dissipated(),
        s.particles().integrator_cache(),
    )
}

/// A damped 8×8 cloth (dissipation books in play) with a tripwire; dopri5 gets one long output
/// step of many internal steps. The Wisdom–Holman map steps planetary systems only: it gets a
/// star and five planets.
fn scene(integrator: &str, threads: usize, flag: &Arc<AtomicBool>, at: u64) -> World<DVec3> {
    let mut s = if integrator == "wisdom_holman" {
        planets(5, integrator, threads)
    } else {
        cloth(8, integrator, threads, 0.05)
    };
    s.particles_mut().add_term(Box::new(Tripwire { flag: flag.clone(), at, calls: 0 })).unwrap();
    if integrator == "dopri5" {
        s.set_dt(0.5).unwrap();
        s.particles_mut().set_tolerances(1e-9, 1e-12).unwrap();
    }
    s
}

#[test]
fn flag_set_before_the_call_stops_it_before_the_first_step() {
    for name in NAMES {
        let unused = Arc::new(AtomicBool::new(false));
        let mut s = scene(name, 1, &unused, 0);
        s.step(2).unwrap();
        let before = snapshot(&s);
        let evals = s.force_evaluations();
        let stop = Arc::new(AtomicBool::new(true));
        assert_eq!(s.step_interruptible(5, &stop), Err(Error::Interrupted { rolled_back_to: 2 }), "{name}");
        assert_eq!(s.force_evaluations(), evals, "{name}: no work after a set flag");
        assert!(snapshot(&s) == before, "{name}: state changed");
        let dt = s.dt;
        assert_eq!(
            s.advance_interruptible(1.0, Some(3), &stop),
            Err(Error::Interrupted { rolled_back_to: 2 }),
            "{name}"
        );
        assert_eq!(s.dt, dt, "{name}: advance restores dt");
        assert!(snapshot(&s) == before, "{name}: state changed by advance");
    }
}

#[test]
fn interrupt_inside_a_call_rolls_back_and_the_retry_is_bit_identical() {
    for name in NAMES {
        for threads in [1, 2] {
            // Where the flag goes up: mid-call, and for dopri5 inside its single output step.
            let (warmup, n) = if name == "dopri5" { (1, 1) } else { (2, 20) };
            let mut reference = scene(name, threads, &Arc::new(AtomicBool::new(false)), 0);
            reference.step(warmup).unwrap();
            let e0 = reference.force_evaluations();
            reference.step(n).unwrap();
            let call_evals = reference.force_evaluations() - e0;
            let at = e0 + call_evals / 2;

            let flag = Arc::new(AtomicBool::new(false));
            let mut s = scene(name, threads, &flag, at);
            s.step(warmup).unwrap();
            let before = snapshot(&s);
            let r = s.step_interruptible(n, &flag);
            assert_eq!(r, Err(Error::Interrupted { rolled_back_to: warmup }), "{name}, {threads} threads");
            assert!(snapshot(&s) == before, "{name}, {threads} threads: not rolled back");
            // The flag is read before every step / internal attempt: at most one more attempt.
            let after = s.force_evaluations() - at;
            let bound = if name == "dopri5" { 6 } else { 4 };
            assert!(after <= bound, "{name}: {after} force evaluations after the flag went up (call: {call_evals})");
            if name == "dopri5" {
                assert!(call_evals > 100, "the dopri5 output step should be long; it took {call_evals} evaluations");
            }

            flag.store(false, Ordering::Relaxed);
            s.step(n).unwrap();
            assert!(
                snapshot(&s) == snapshot(&reference),
                "{name}, {threads} threads: retry differs from the uninterrupted run"
            );
        }
    }
}

#[test]
fn a_flag_set_during_the_last_step_rolls_the_call_back() {
    // The flag goes up in the first force evaluation of a one-step call: the step's forces may
    // be partial (a term skips its work), so the step must not stand.
    for name in NAMES {
        let mut probe = scene(name, 1, &Arc::new(AtomicBool::new(false)), 0);
        probe.step(2).unwrap();
        let at = probe.force_evaluations() + 1;
        let flag = Arc::new(AtomicBool::new(false));
        let mut s = scene(name, 1, &flag, at);
        s.step(2).unwrap();
        let before = snapshot(&s);
        assert_eq!(s.step_interruptible(1, &flag), Err(Error::Interrupted { rolled_back_to: 2 }), "{name}");
        assert!(snapshot(&s) == before, "{name}: the last step stood");
    }
}

/// Counts its evaluations (a force-free term).
struct Counter(Arc<AtomicU64>);

impl Term<DVec3> for Counter {
    fn name(&self) -> &str {
        "counter"
    }
    fn add_forces(&mut self, _x: &[DVec3], _v: &[DVec3], _m: &Model, _f: &mut [DVec3], _write: Write) -> f64 {
        self.0.fetch_add(1, Ordering::Relaxed);
        0.0
    }
    fn potential(&self, _x: &[DVec3], _m: &Model) -> Option<f64> {
        None
    }
    fn traits(&self) -> Traits<DVec3> {
        Traits::conservative()
    }
}

#[test]
fn once_the_flag_is_up_the_remaining_terms_of_an_evaluation_are_skipped() {
    for name in ["verlet", "rk4"] {
        let flag = Arc::new(AtomicBool::new(false));
        let at = 7;
        let mut s = scene(name, 1, &flag, at);
        let calls = Arc::new(AtomicU64::new(0));
        s.particles_mut().add_term(Box::new(Counter(calls.clone()))).unwrap();
        assert_eq!(s.step_interruptible(20, &flag), Err(Error::Interrupted { rolled_back_to: 0 }), "{name}");
        // The counter comes after the tripwire: it misses the evaluation in which the flag went up.
        assert_eq!(calls.load(Ordering::Relaxed), at - 1, "{name}");
        // Between calls the terms see no flag, even one left set.
        s.step(1).unwrap();
        assert!(calls.load(Ordering::Relaxed) > at - 1, "{name}");
    }
}

/// A stiff hanging chain under dopri5 whose one output step (dt = 10⁴ s) takes minutes.
fn long_dopri5_step(threads: Option<usize>) -> World<DVec3> {
    let n = 200;
    let mut s = World::new(ParticleSystem::new("dopri5").unwrap(), 1e4, threads).unwrap();
    let x = (0..n).map(|i| DVec3::new(i as f64 / n as f64, 0.0, 0.0)).collect();
    s.particles_mut()
        .add_particles(x, vec![DVec3::ZERO; n], vec![1.0 / n as f64; n], (0..n).map(|i| i == 0).collect())
        .unwrap();
    let (i, j): (Vec<u32>, Vec<u32>) = (0..n as u32 - 1).map(|i| (i, i + 1)).unzip();
    let m = i.len();
    s.particles_mut()
        .add_term(Box::new(
            Springs::new("springs".into(), i, j, vec![1e4; m], vec![0.0; m], vec![1.0 / n as f64; m], n).unwrap(),
        ))
        .unwrap();
    s.particles_mut()
        .add_term(Box::new(UniformGravity { name: "gravity".into(), g: DVec3::new(0.0, 0.0, -9.81) }))
        .unwrap();
    s.particles_mut().set_tolerances(1e-10, 1e-12).unwrap();
    s
}

#[test]
fn a_watcher_on_the_calling_thread_stops_a_step_running_on_the_pool() {
    for threads in [None, Some(1), Some(2)] {
        let mut s = long_dopri5_step(threads);
        let before = snapshot(&s);
        let stop = Arc::new(AtomicBool::new(false));
        let caller = std::thread::current().id();
        let mut timeouts = 0;
        let t0 = Instant::now();
        let r = s.run_watched(
            |s| {
                assert_ne!(std::thread::current().id(), caller, "the job runs on a pool thread");
                s.step_interruptible(1, &stop)
            },
            |wait| {
                while !wait(Duration::from_millis(20)) {
                    timeouts += 1;
                    if timeouts == 3 {
                        stop.store(true, Ordering::Relaxed);
                    }
                }
            },
        );
        assert_eq!(r, Err(Error::Interrupted { rolled_back_to: 0 }), "threads {threads:?}");
        assert!(timeouts >= 3, "threads {threads:?}");
        // Generous: the flag is read between internal attempts of ~1 ms here.
        assert!(t0.elapsed() < Duration::from_secs(10), "threads {threads:?}: took {:?}", t0.elapsed());
        assert!(snapshot(&s) == before, "threads {threads:?}: not rolled back");
        // A finished job is reported at once, and its result returned.
        let r = s.run_watched(|s| s.n_particles(), |wait| assert!(wait(Duration::from_secs(60))));
        assert_eq!(r, 200);
    }
}

#[test]
fn run_watched_from_a_pool_thread_runs_the_job_there() {
    // On the only thread of a pool, a task queued on that pool would never start.
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let mut s = long_dopri5_step(None);
    s.set_dt(1e-3).unwrap();
    let r = one.install(|| s.run_watched(|s| s.step(1), |wait| assert!(wait(Duration::from_secs(60)))));
    assert_eq!(r, Ok(()));
    assert_eq!(s.steps(), 1);
}
