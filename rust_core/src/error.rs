//! The one error enum of the core. The Python bindings map `InvalidInput` to a `ValueError`
//! subclass and `Diverged` to `physcore.SimulationDiverged`.
use thiserror::Error;

#[derive(Debug, Error, Clone, PartialEq)]
pub enum Error {
    /// A user-supplied argument is invalid. Raised before any state changes.
    #[error("{arg}: {msg}")]
    InvalidInput { arg: String, msg: String },

    /// A user-supplied argument has the wrong type (Python: `InvalidTypeError`, a `TypeError`).
    #[error("{arg}: {msg}")]
    InvalidType { arg: String, msg: String },

    /// NaN or infinity appeared while stepping. The state is rolled back to where the failing
    /// `step(n)` call started.
    #[error(
        "simulation diverged at step {step} (t = {time}): {what}. The state was rolled back to step {rolled_back_to}. \
         {advice}",
        time = seconds(*t),
        what = describe(quantity, *particle),
        advice = advise(quantity, *step, *dt, *suggested_dt, *explicit_euler, *remedies)
    )]
    Diverged {
        step: u64,
        t: f64,
        particle: usize,
        quantity: Failure,
        rolled_back_to: u64,
        dt: f64,
        suggested_dt: f64,
        /// The particles were stepped by explicit Euler, which no smaller dt makes stable for an
        /// undamped oscillation.
        explicit_euler: bool,
        /// What else the scene offers to try (the advice names only these).
        remedies: Remedies,
    },

    /// `step_interruptible` was asked to stop (Ctrl-C); the state was rolled back.
    #[error("interrupted; the state was rolled back to step {rolled_back_to}")]
    Interrupted { rolled_back_to: u64 },

    /// A pool of `threads` threads could not be started (the process's limit on threads).
    #[error(
        "threads: could not start {threads} threads ({reason}); the process has probably hit its \
         limit on threads (ulimit -u, RLIMIT_NPROC). Ask for fewer threads, or pass threads=None \
         to use what can be started (the calling thread alone if no thread can)"
    )]
    Threads { threads: usize, reason: String },

    /// A buffer sized by the input could not be allocated; nothing was changed.
    #[error(
        "{what}: needs {size} for {of}, more than can be allocated now (nothing was changed). \
         Free memory, or make the input smaller",
        size = human(*bytes)
    )]
    OutOfMemory { what: String, bytes: u64, of: String },

    /// The GPU failed (a lost device, a driver error): the state is as of the last step that
    /// completed.
    #[error("the GPU device failed: {msg}")]
    Device { msg: String },
}

/// The remedies for a divergence that exist for the scene's terms and integrator, so that the
/// advice never names one the scene does not have (softening in a spring scene).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Remedies {
    /// A term has a softening length (pairwise or tree gravity, Coulomb, point masses).
    pub softening: bool,
    /// A term has a Jacobian (springs, drag) and the integrator does not yet take it
    /// implicitly: integrator='implicit_euler' would.
    pub implicit: bool,
}

/// A time for a message: four significant digits, plain from 1 ms to 1e5 s ("1.027 s",
/// "0.3 s", "484.8 s"), scientific outside ("2.500e-7 s"), as people read them.
pub fn seconds(t: f64) -> String {
    let a = t.abs();
    if t == 0.0 || !a.is_finite() {
        return format!("{t} s");
    }
    if !(1e-3..1e5).contains(&a) {
        return format!("{t:.3e} s");
    }
    let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
    let s = format!("{t:.decimals$}");
    let s = if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.') } else { &s };
    format!("{s} s")
}

/// What went wrong with the particle of a diverged step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    /// Its position is not finite.
    Position,
    /// Its velocity is not finite.
    Velocity,
    /// An adaptive integrator could not bring its local error within the tolerances at any
    /// step size (the state is still finite).
    Error,
    /// A cell of a grid field is not finite (the index is the cell's, see `crate::grids`).
    Cell,
    /// The flow sped up until its step limit (CFL) fell a millionfold within one `advance`:
    /// a runaway with finite values (the index is the fastest particle's).
    Speed,
    /// State a force term keeps for a particle is not finite: a grain's spin or rotation
    /// angle, or the tangential spring of one of its contacts (`Term::non_finite`).
    Spin,
    /// The energy books overflowed: a dissipated energy is not finite while the state still is
    /// (the index is the fastest particle's).
    Books,
    /// The rigid bodies' solver (rapier) failed on their state (it panicked): a state loaded
    /// from a damaged or crafted file that passed the load's checks, or a bug (the index is 0).
    Solver,
    /// A grid's energy books overflowed while its cells are still finite (a drop of 1e300 m):
    /// the index is the cell of the largest magnitude.
    GridBooks,
    /// A term could not have the memory for lists its step sizes by the state (the contacts of
    /// crowded grains): the world reports the term's `Error::OutOfMemory`
    /// (`terms::OwnState::refused`), not a divergence (the index is 0).
    Memory,
}

impl Failure {
    /// The name Python sees (`SimulationDiverged.quantity`).
    pub fn as_str(self) -> &'static str {
        match self {
            Failure::Position => "position",
            Failure::Velocity => "velocity",
            Failure::Error => "error",
            Failure::Cell => "cell",
            Failure::Speed => "speed",
            Failure::Spin => "spin",
            Failure::Books => "books",
            Failure::Solver => "solver",
            Failure::GridBooks => "books",
            Failure::Memory => "memory",
        }
    }
}

fn describe(quantity: &Failure, index: usize) -> String {
    match quantity {
        Failure::Cell => format!("grid cell {index} has a non-finite value"),
        Failure::Error => format!(
            "particle {index} has a local error that dopri5 (Dormand–Prince) cannot bring within rtol/atol at any \
             step size (its forces are not finite or not smooth there)"
        ),
        Failure::Speed => format!(
            "the flow ran away: its step limit fell over a millionfold within one advance or since \
             the last step (particle {index} is the fastest)"
        ),
        Failure::Spin => format!("particle {index} has a non-finite spin, rotation or contact spring"),
        Failure::Books => {
            format!("the dissipated energy overflowed the energy books (particle {index} is the fastest)")
        }
        Failure::Solver => "the rigid bodies' solver (rapier) failed on their state".to_string(),
        Failure::GridBooks => format!("the energy books overflowed (grid cell {index} holds the largest value)"),
        Failure::Memory => "a step's lists could not be allocated".to_string(),
        q => format!("particle {index} has a non-finite {}", q.as_str()),
    }
}

fn advise(
    quantity: &Failure,
    step: u64,
    dt: f64,
    suggested_dt: f64,
    explicit_euler: bool,
    remedies: Remedies,
) -> String {
    let (now, then) = (seconds(dt), seconds(suggested_dt));
    let softening = if remedies.softening { ", a larger softening" } else { "" };
    // A usable step: a normal float64 (a subnormal or zero one would read "try dt = 0", and
    // Scene refuses it).
    let usable = suggested_dt >= f64::MIN_POSITIVE && suggested_dt.is_finite();
    // At the first steps, from the state as given: a value beyond what float64 holds for this
    // physics (a compliance or field of 1e308) fails at any dt, which the advice says too.
    let first = if step <= 2 {
        " If it fails at the first step whatever the dt, some value given is too large or too small \
         for float64 here (of some 1e150 or 1e-150): give values of a physical size."
    } else {
        ""
    };
    match quantity {
        // Grids step by their own explicit schemes: their limit is a CFL or diffusion number.
        Failure::Cell if !usable => format!(
            "No stable dt exists for this grid (its CFL or diffusion limit is {then}; dt now {now}): \
             its spacing, speed, diffusion or forcing is beyond float64's range: give values of a \
             physical size."
        ),
        Failure::Cell => format!(
            "Try a smaller dt (now {now}), e.g. {then}, within the grid's CFL or diffusion limit \
             (Scene.advance keeps to it).{first}"
        ),
        // |1 + iω dt| > 1 for every ω > 0: explicit Euler amplifies every undamped oscillation
        // (springs, orbits) by (1 + ω²dt²)^(1/2) a step, so a smaller dt only delays this.
        _ if explicit_euler => format!(
            "Explicit Euler amplifies every undamped oscillation (springs, orbits) at any dt: a \
             smaller dt (now {now}; the fastest time scale asks for {then}) only delays this. Use \
             semi_implicit_euler, verlet or rk4."
        ),
        // The step already follows the flow: a smaller one is what failed to keep up.
        Failure::Speed => format!(
            "The step follows the flow (last {now}), so a smaller dt does not help: try a \
             smaller cfl, more viscosity or a tighter density_error."
        ),
        // Energies past float64 with a finite state, some steps into the run and at a step
        // beyond the fastest time scale: most likely a run that blew up from a stable start (a
        // cloth at too long a step reached 1e45 J in 0.14 s), which a smaller step cures. At the
        // first steps the values were given so (a drop of 1e300 m).
        Failure::Books | Failure::GridBooks if step > 2 && suggested_dt >= f64::MIN_POSITIVE && suggested_dt < dt => {
            format!(
                "The run most likely blew up: the step (now {now}) is longer than the fastest time scale \
             asks ({then}): try a smaller dt, e.g. {then}. (Or some values given are of 1e150 or \
             more: give values of a physical size.)"
            )
        }
        // Energies past float64 with a finite state: the values given are beyond any step.
        Failure::Books | Failure::GridBooks => "The energies of this state are past float64's range (speeds, \
             amplitudes or masses of some 1e150 or more): give values of a physical size; a \
             smaller dt does not help."
            .to_string(),
        // Not a matter of the step: the state itself is inconsistent.
        Failure::Solver => "Its state is inconsistent (a damaged or crafted scene file that passed the load's \
             checks) or this is a bug: build the scene again or load it from a file you trust, and report \
             it if the scene was built, not loaded."
            .to_string(),
        // dopri5's dt is an output interval: a loose rtol may have led the trajectory astray.
        // (An atol below the state's round-off, 1e-308, cannot be met either.)
        Failure::Error => format!(
            "Try a tighter rtol (a loose one can let an orbit decay into a collision){softening}, \
             an atol above the state's round-off (about 1e-16 of its values) or a fixed-step integrator."
        ),
        // A suggestion that is not a usable step (0, subnormal, NaN) would read "try dt = 0":
        // the forces themselves are the problem (overflowing masses, coincident particles).
        _ if !usable => format!(
            "No stable dt exists for this state (the fastest time scale is {then}): check for \
             coincident particles, overflowing masses or stiffnesses{} (dt now {now}).",
            if remedies.softening { "; a larger softening helps with gravity" } else { "" }
        ),
        _ => {
            let implicit =
                if remedies.implicit { ", integrator='implicit_euler' (springs and drag implicitly)" } else { "" };
            format!("Try a smaller dt (now {now}), e.g. {then}{implicit}{softening}.{first}")
        }
    }
}

pub type Result<T> = std::result::Result<T, Error>;

pub fn invalid(arg: &str, msg: impl Into<String>) -> Error {
    Error::InvalidInput { arg: arg.to_string(), msg: msg.into() }
}

/// Bytes in decimal units, three significant digits: "800 MB", "1.92 GB".
pub fn human(bytes: u64) -> String {
    let units = ["bytes", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut x = bytes as f64;
    let mut u = 0;
    while x >= 999.5 && u + 1 < units.len() {
        x /= 1000.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} bytes")
    } else if x >= 99.95 {
        format!("{x:.0} {}", units[u])
    } else if x >= 9.995 {
        format!("{x:.1} {}", units[u])
    } else {
        format!("{x:.2} {}", units[u])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn diverged(suggested_dt: f64) -> String {
        diverged_at(3, Failure::Position, suggested_dt)
    }

    fn diverged_at(step: u64, quantity: Failure, suggested_dt: f64) -> String {
        Error::Diverged {
            step,
            t: 0.1 * step as f64,
            particle: 1,
            quantity,
            rolled_back_to: 0,
            dt: 0.1,
            suggested_dt,
            explicit_euler: false,
            remedies: Remedies::default(),
        }
        .to_string()
    }

    #[test]
    fn a_grid_without_a_usable_step_is_told_to_give_values_of_a_physical_size() {
        // Gray–Scott at a spacing of 1e-308 advised "e.g. 0 s", the wave "e.g. 4.941e-324 s".
        for bad in [0.0, 4.941e-324, f64::NAN] {
            let m = diverged_at(3, Failure::Cell, bad);
            assert!(m.contains("No stable dt exists for this grid") && m.contains("physical size"), "{m}");
            assert!(!m.contains("e.g."), "{m}");
        }
        assert!(diverged_at(3, Failure::Cell, 1e-3).contains("e.g. 0.001 s"));
    }

    #[test]
    fn a_divergence_at_the_first_steps_also_names_values_out_of_range() {
        // An XPBD rest length or a field of 1e308 fails at any dt: from the state as given,
        // the advice says so beside the smaller dt; later in a run it does not.
        for q in [Failure::Position, Failure::Cell] {
            let first = diverged_at(1, q, 0.05);
            assert!(first.contains("e.g. 0.05 s") && first.contains("whatever the dt"), "{first}");
            assert!(!diverged_at(3, q, 0.05).contains("whatever the dt"));
        }
    }

    #[test]
    fn advice_never_suggests_an_unusable_dt() {
        assert!(diverged(1e-3).contains("e.g. 0.001 s"), "{}", diverged(1e-3));
        for bad in [0.0, 1e-310, f64::NAN, f64::INFINITY] {
            let m = diverged(bad);
            assert!(m.contains("No stable dt exists"), "{bad:e}: {m}");
            assert!(!m.contains("e.g."), "{bad:e}: {m}");
        }
    }

    #[test]
    fn explicit_euler_is_told_to_change_integrator_not_dt() {
        let e = Error::Diverged {
            step: 3,
            t: 0.3,
            particle: 1,
            quantity: Failure::Velocity,
            rolled_back_to: 0,
            dt: 0.1,
            suggested_dt: 1e-3,
            explicit_euler: true,
            remedies: Remedies::default(),
        };
        let m = e.to_string();
        assert!(m.contains("at any dt") && m.contains("verlet"), "{m}");
        assert!(!m.contains("e.g."), "{m}");
    }

    #[test]
    fn times_read_as_people_write_them() {
        let cases = [(1.026640, "1.027 s"), (0.3, "0.3 s"), (484.8485, "484.8 s"), (1555.556, "1556 s"), (0.0, "0 s")];
        for (t, want) in cases {
            assert_eq!(seconds(t), want);
        }
        assert_eq!(seconds(2.5e-7), "2.500e-7 s");
        assert_eq!(seconds(3.2e9), "3.200e9 s");
    }

    #[test]
    fn advice_names_only_the_remedies_the_scene_has() {
        let e = |remedies| {
            let (quantity, dt, t) = (Failure::Position, 0.1, 1.026640);
            let (particle, step, rolled_back_to, explicit_euler, suggested_dt) = (1, 3, 0, false, 1e-3);
            Error::Diverged { step, t, particle, quantity, rolled_back_to, dt, suggested_dt, explicit_euler, remedies }
                .to_string()
        };
        let springs = e(Remedies { softening: false, implicit: true });
        assert!(springs.contains("t = 1.027 s") && springs.contains("implicit_euler"), "{springs}");
        assert!(!springs.contains("softening") && !springs.contains("e0 s"), "{springs}");
        let gravity = e(Remedies { softening: true, implicit: false });
        assert!(gravity.contains("softening") && !gravity.contains("implicit_euler"), "{gravity}");
    }
}
