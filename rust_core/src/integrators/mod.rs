//! Time integrators behind one trait. Each reports its name, order, whether it is symplectic and
//! its force evaluations per step, so the speed/accuracy trade can be tabulated honestly.
pub mod boris;
pub mod dopri5;
pub mod euler;
pub mod implicit_euler;
pub mod rk4;
pub mod semi_implicit_euler;
pub mod verlet;
pub mod wisdom_holman;
pub mod xpbd;
pub mod yoshida;

use crate::error::{invalid, Result};
use crate::state::{Model, State};
use crate::terms::ForceSet;
use crate::vector::{Real, Vector};
use std::collections::TryReserveError;
use std::sync::atomic::AtomicBool;

pub use boris::Boris;
pub use dopri5::Dopri5;
pub use euler::ExplicitEuler;
pub use implicit_euler::ImplicitEuler;
pub use rk4::Rk4;
pub use semi_implicit_euler::SemiImplicitEuler;
pub use verlet::VelocityVerlet;
pub use wisdom_holman::WisdomHolman;
pub use xpbd::Xpbd;
pub use yoshida::Yoshida4;

/// What a particle system hands its integrator: state, constants and the force terms.
pub struct Particles<V: Vector> {
    pub state: State<V>,
    pub model: Model,
    pub forces: ForceSet<V>,
    /// Single-precision state: integrators round every stored position and velocity to the
    /// nearest float32 (`store`), so forces are always evaluated at representable states.
    pub single: bool,
}

/// What an integrator carries between steps (`Integrator::cache`): forces and term powers.
pub type Cache<V> = (Vec<V>, Vec<Real>);

/// `Integrator::step_interruptible` saw its stop flag set and abandoned the step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stopped;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IntegratorInfo {
    /// Stable lower-case name used to pick it.
    pub name: &'static str,
    /// Global order of accuracy.
    pub order: u32,
    pub symplectic: bool,
    /// Force evaluations per step (in steady state).
    pub force_evals_per_step: u32,
}

impl IntegratorInfo {
    /// The constraint stage's share of the integrator's energy error, s: a projection that
    /// changes a velocity from v to v′ books `projection_kick(dt)`·F·(v′ − v) with the uniform
    /// field's force F = m g (`Constraint::project`). Semi-implicit Euler's books balance to ½dt F·(v₀ − v)
    /// over a step of constant force F, which telescopes over steps to the bounded ½dt F·(v₀ −
    /// v_N), unless a projection resets v between steps: a particle resting on a plane then
    /// booked −½ m g² dt² a step, without bound (energy_drift −1.0 after a second at dt = 1e-3).
    /// −dt/2 for the kick-then-drift schemes, +dt/2 for explicit Euler (drift then kick), 0 for
    /// the schemes exact under a constant force (velocity Verlet, Yoshida, RK4, ...). Here, by
    /// name, rather than a method of `Integrator` (whose size is capped: `trait_sizes`).
    pub fn projection_kick(&self, dt: Real) -> Real {
        match self.name {
            "semi_implicit_euler" | "implicit_euler" => -0.5 * dt,
            "euler" => 0.5 * dt,
            _ => 0.0,
        }
    }
}

/// The integrators' options: one struct, its defaults and its validation. The system keeps one
/// (kept when the scene switches integrators) and hands it to its integrator
/// (`Integrator::configure`), which reads the fields it uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntegratorOptions {
    /// "dopri5": relative tolerance of the error estimate, in [1e-14, 1). Default 1e-6.
    pub rtol: Real,
    /// "dopri5": absolute tolerance (m for positions, m/s for velocities), ≥ 0. Default 1e-9.
    pub atol: Real,
    /// "implicit_euler": relative residual at which CG stops, in [1e-14, 1). Default 1e-8.
    pub cg_tol: Real,
    /// "implicit_euler": CG iteration limit, 1..=1000000. Default 200.
    pub cg_max_iter: u32,
    /// "xpbd": substeps per step, 1..=100000. Default 10.
    pub xpbd_substeps: u32,
    /// "xpbd": constraint iterations per substep, 1..=10000. Default 1.
    pub xpbd_iterations: u32,
    /// "wisdom_holman": the coordinates of the split. Default Jacobi.
    pub wh_coordinates: wisdom_holman::Coordinates,
    /// "wisdom_holman": the order of the symplectic corrector applied at both ends of a call
    /// (`wisdom_holman::CORRECTOR_ORDERS`; Jacobi coordinates only), 0 for none. Default 0.
    pub wh_corrector: u32,
}

impl Default for IntegratorOptions {
    fn default() -> Self {
        Self {
            rtol: 1e-6,
            atol: 1e-9,
            cg_tol: implicit_euler::DEFAULT_TOL,
            cg_max_iter: implicit_euler::DEFAULT_MAX_ITER,
            xpbd_substeps: 10,
            xpbd_iterations: 1,
            wh_coordinates: wisdom_holman::Coordinates::default(),
            wh_corrector: 0,
        }
    }
}

impl IntegratorOptions {
    /// `InvalidInput` naming the first field out of its range (see the fields).
    pub fn validate(&self) -> Result<()> {
        use crate::error::invalid;
        // A relative tolerance in [1e-14, 1), the message saying which end was missed.
        let tolerance = |name: &str, v: Real| -> Result<()> {
            if v.is_finite() && (1e-14..1.0).contains(&v) {
                return Ok(());
            }
            let why = if !(v > 0.0 && v.is_finite()) {
                "a tolerance is positive and finite"
            } else if v < 1e-14 {
                "float64 cannot resolve less"
            } else {
                "a relative error of 1 or more accepts any step"
            };
            let shown = if v != 0.0 && v.is_finite() && !(1e-3..1e5).contains(&v.abs()) {
                format!("{v:e}")
            } else {
                format!("{v}")
            };
            Err(invalid(name, format!("{shown} must be in [1e-14, 1) ({why})")))
        };
        tolerance("rtol", self.rtol)?;
        if !(self.atol.is_finite() && self.atol >= 0.0) {
            return Err(invalid("atol", format!("{} must be finite and >= 0 (m and m/s)", self.atol)));
        }
        tolerance("cg_tol", self.cg_tol)?;
        if !(1..=1_000_000).contains(&self.cg_max_iter) {
            return Err(invalid("cg_max_iter", format!("{} must be in 1..=1000000", self.cg_max_iter)));
        }
        if !(1..=100_000).contains(&self.xpbd_substeps) {
            return Err(invalid("substeps", format!("{} must be in 1..=100000", self.xpbd_substeps)));
        }
        if !(1..=10_000).contains(&self.xpbd_iterations) {
            return Err(invalid("iterations", format!("{} must be in 1..=10000", self.xpbd_iterations)));
        }
        if self.wh_corrector != 0 && !wisdom_holman::CORRECTOR_ORDERS.contains(&self.wh_corrector) {
            return Err(invalid(
                "wh_corrector",
                format!(
                    "{} is no corrector's order: 0 (none) or one of {:?}",
                    self.wh_corrector,
                    wisdom_holman::CORRECTOR_ORDERS
                ),
            ));
        }
        Ok(())
    }
}

pub trait Integrator<V: Vector>: Send + Sync {
    fn info(&self) -> IntegratorInfo;
    /// Advances `sys.state` by `dt` (x, v only; the caller advances time) and books the energy
    /// dissipated by the force terms during the step. Returns `true` if any position or
    /// velocity is not finite afterwards (checked in the final update pass, at no extra pass).
    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool;
    /// `step`, giving up part-way with `Err(Stopped)` once `stop` is seen set; the state and
    /// the integrator's cache are then partly advanced, and the caller must roll both back.
    /// By default `stop` is not read: a fixed-step method's step is a few force evaluations, and
    /// the caller polls between steps. An adaptive one polls before every internal attempt.
    fn step_interruptible(
        &mut self,
        sys: &mut Particles<V>,
        dt: Real,
        stop: &AtomicBool,
    ) -> std::result::Result<bool, Stopped> {
        let _ = stop;
        Ok(self.step(sys, dt))
    }
    /// Forces (N) of the most recent evaluation, one per particle.
    fn last_forces(&self) -> &[V];
    /// The per-particle scratch buffers `step` sizes to the particle count (with
    /// velocity-dependent forces or not), so the simulation can reserve them fallibly before
    /// stepping (a refused allocation is then an error, not an abort of the process).
    fn scratch(&mut self, velocity_dependent: bool) -> Vec<&mut Vec<V>>;
    /// Per-particle scratch of pseudo-vectors (`Vector::Axial`: the Boris integrator's
    /// magnetic field), reserved like `scratch`.
    fn axial_scratch(&mut self) -> Vec<&mut Vec<V::Axial>> {
        Vec::new()
    }
    /// Drop anything cached across steps (the state was changed from outside the integrator).
    fn reset(&mut self) {}
    /// What the integrator carries from one step to the next, as one value (`Carry`); `None`
    /// for an integrator that carries nothing.
    fn as_carry(&self) -> Option<&dyn Carry<V>> {
        None
    }
    /// `as_carry`, to restore or write in place.
    fn as_carry_mut(&mut self) -> Option<&mut dyn Carry<V>> {
        None
    }
    /// Takes the options it uses from `o` (validated by `IntegratorOptions::validate`); the
    /// others it leaves for the integrators that use them.
    fn configure(&mut self, _o: &IntegratorOptions) {}
    /// An adaptive integrator's step control (`Adaptive`); `None` for a fixed-step one.
    fn as_adaptive(&self) -> Option<&dyn Adaptive> {
        None
    }
    /// `as_adaptive`, to restore its counts.
    fn as_adaptive_mut(&mut self) -> Option<&mut dyn Adaptive> {
        None
    }
    /// Whether the terms with Jacobians (the `Jacobian` role) are taken implicitly, so that
    /// their time scales no longer limit the step for stability (`ParticleSystem::auto_dt`).
    fn implicit(&self) -> bool {
        false
    }
    /// Refuses, before a call steps, a step `dt` (s; already finite and > 0) this integrator
    /// cannot take (`InvalidInput` naming `dt`), or a scene `sys` it cannot step (naming
    /// `integrator`); every scene and step size is fine by default.
    fn check_step(&self, _sys: &Particles<V>, _dt: Real) -> Result<()> {
        Ok(())
    }
    /// The linear solver's books, for an integrator that has one.
    fn solver_stats(&self) -> Option<SolverStats> {
        None
    }
}

/// What an integrator carries from one step to the next ("first same as last" forces, the
/// term powers there, an adaptive controller's memory): needed to continue a saved run, or to
/// retry a rolled-back one, bit for bit. One value behind `Integrator::as_carry`, so that the
/// central trait does not hold five ways to reach it. It may also carry, within one call of
/// steps, a state of its own that the call's end hands back (`settle`: the Wisdom–Holman
/// corrector's coordinates) and a rollback forgets (`abandon`).
pub trait Carry<V: Vector> {
    /// The call of steps ended (`System::settle`): completes what the steps left for its end
    /// (the Wisdom–Holman corrector's output transformation). Returns `true` if any position or
    /// velocity is not finite afterwards. Default: nothing left.
    fn settle(&mut self, _sys: &mut Particles<V>) -> bool {
        false
    }
    /// The call of steps was rolled back (to a checkpoint taken before it): forget what was
    /// left for its end. Default: nothing left.
    fn abandon(&mut self) {}
    /// A copy (forces, N, one per particle; powers, W, one per term, then any controller
    /// memory), or `None` while nothing valid is carried.
    fn get(&self) -> Option<Cache<V>> {
        self.borrow().map(|(f, p)| (f.to_vec(), p.to_vec()))
    }
    /// `get`, with its copy of the per-particle forces allocated fallibly.
    fn try_get(&self) -> std::result::Result<Option<Cache<V>>, TryReserveError> {
        self.borrow().map(|(f, p)| Ok((try_copy(f)?, p.to_vec()))).transpose()
    }
    /// Borrowed, where it can be lent (`None` also while nothing valid is carried): a checkpoint
    /// copies it into buffers it already has instead of allocating two. `get` and `try_get`
    /// copy it, unless the carried value is not held as two slices (dopri5).
    fn borrow(&self) -> Option<(&[V], &[Real])> {
        None
    }
    /// In place, for a caller that steps the particles itself with the same bits (the batch's
    /// fused kernel): the forces, the terms' powers there, and whether they are valid (the
    /// caller sets the three together). `None` if it cannot be written in place.
    fn parts(&mut self) -> Option<(&mut Vec<V>, &mut Vec<Real>, &mut bool)> {
        None
    }
    /// Restores `get()`'s output at the state whose velocities are `v`, for a scene with
    /// `n_terms` terms; returns false (and changes nothing) if it does not fit.
    fn set(&mut self, f: Vec<V>, p: Vec<Real>, v: &[V], n_terms: usize) -> bool;
}

/// An adaptive integrator's step control, behind `Integrator::as_adaptive`.
pub trait Adaptive {
    /// (accepted, rejected internal steps, next internal step in s).
    fn stats(&self) -> (u64, u64, Real);
    /// Sets the accepted and rejected counts (a rolled-back call leaves them as they were).
    fn set_counts(&mut self, accepted: u64, rejected: u64);
    /// Why the last `step` failed with a finite state (step control gave up): the particle and
    /// what was wrong.
    fn failure(&self) -> Option<(usize, crate::error::Failure)>;
}

/// Books of an implicit integrator's linear solves (CG), over every solve run since the
/// integrator was made, including those of steps later rolled back (divergence, Ctrl-C).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SolverStats {
    /// Linear solves (one per step).
    pub solves: u64,
    /// CG iterations over all solves (one Jacobian product each).
    pub iterations: u64,
    /// Most iterations one solve took.
    pub max_iterations: u32,
    /// Solves that stopped at the iteration limit (or broke down) above the tolerance.
    pub unconverged: u64,
    /// Largest relative residual ‖r‖/‖rhs‖ a solve ended with.
    pub worst_residual: Real,
}

impl SolverStats {
    pub fn record(&mut self, iterations: u32, converged: bool, residual: Real) {
        self.solves += 1;
        self.iterations += iterations as u64;
        self.max_iterations = self.max_iterations.max(iterations);
        self.unconverged += !converged as u64;
        // NaN (a non-finite state) counts as worst.
        if !(residual <= self.worst_residual) {
            self.worst_residual = residual;
        }
    }
}

/// All integrator names, in the order of the documentation table.
pub const NAMES: [&str; 10] = [
    "euler",
    "semi_implicit_euler",
    "verlet",
    "yoshida4",
    "rk4",
    "dopri5",
    "wisdom_holman",
    "boris",
    "xpbd",
    "implicit_euler",
];

pub fn by_name<V: Vector>(name: &str) -> Result<Box<dyn Integrator<V>>> {
    Ok(match name {
        "euler" => Box::new(ExplicitEuler::default()),
        "semi_implicit_euler" => Box::new(SemiImplicitEuler::default()),
        "verlet" => Box::new(VelocityVerlet::default()),
        "yoshida4" => Box::new(Yoshida4::default()),
        "rk4" => Box::new(Rk4::default()),
        "dopri5" => Box::new(Dopri5::default()),
        "wisdom_holman" => Box::new(WisdomHolman::default()),
        "boris" => Box::new(Boris::default()),
        "xpbd" => Box::new(Xpbd::default()),
        "implicit_euler" => Box::new(ImplicitEuler::default()),
        other => {
            return Err(invalid(
                "integrator",
                format!("unknown integrator {other:?}; valid names: {}", NAMES.join(", ")),
            ))
        }
    })
}

/// `Carry::set` for an integrator that carries the forces (N) and term powers (W) of the state it
/// ended at, "first same as last" (verlet, boris, wisdom_holman): the `slots` take `f` and `p`
/// and become valid, unless `f` is not one force per velocity of `v` or `p` one power per term
/// of `n_terms` (then nothing changes and it is false).
pub(crate) fn set_carried<V: Vector>(
    slots: (&mut Vec<V>, &mut Vec<Real>, &mut bool),
    f: Vec<V>,
    p: Vec<Real>,
    v: &[V],
    n_terms: usize,
) -> bool {
    if f.len() != v.len() || p.len() != n_terms {
        return false;
    }
    (*slots.0, *slots.1, *slots.2) = (f, p, true);
    true
}

/// A copy of `s`, allocated fallibly.
pub(crate) fn try_copy<T: Clone>(s: &[T]) -> std::result::Result<Vec<T>, TryReserveError> {
    let mut v = Vec::new();
    v.try_reserve_exact(s.len())?;
    v.extend_from_slice(s);
    Ok(v)
}

#[inline]
pub(crate) fn ensure_len<V: Vector>(buf: &mut Vec<V>, n: usize) {
    if buf.len() != n {
        buf.resize(n, V::ZERO);
    }
}

/// Acceleration f/m + g (g: the uniform fields), exactly zero for pinned particles (inverse
/// mass 0) even when f is not finite.
#[inline(always)]
pub(crate) fn accel<V: Vector>(f: V, inv_mass: Real, g: V) -> V {
    if inv_mass == 0.0 {
        V::ZERO
    } else {
        f * inv_mass + g
    }
}

/// A position or velocity as the state stores it (rounded to float32 in single precision).
#[inline(always)]
pub(crate) fn store<V: Vector>(x: V, single: bool) -> V {
    if single {
        x.round_f32()
    } else {
        x
    }
}

/// Whether a position or velocity has a NaN or infinite component (branch-free, vectorisable).
#[inline(always)]
pub(crate) fn bad<V: Vector>(x: V, v: V) -> bool {
    let mut b = false;
    for k in 0..V::DIM {
        b |= !x.comp(k).is_finite() | !v.comp(k).is_finite();
    }
    b
}
