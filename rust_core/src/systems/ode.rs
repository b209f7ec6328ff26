//! A system for a first-order ODE y' = f(y) on a flat array of reals, stepped by an explicit
//! Butcher tableau of the ODE layer (`crate::ode`): a flow such as the Lorenz system (y holds
//! every tracer's coordinates), or a field discretised in space (method of lines).
use super::{load_flat, snapshot_flat, Arrays, EnergyReport, Halt, Snapshot, System};
use crate::alloc::{count, Need};
use crate::error::{invalid, Failure, Result};
use crate::ode::{self, Stages, Tableau};
use crate::vector::Real;
use std::sync::atomic::AtomicBool;

/// The right-hand side: writes f(y) into its second argument.
pub type Rhs = Box<dyn Fn(&[Real], &mut [Real]) + Send + Sync>;
/// An energy (J) of the state, booked as the system's potential.
pub type EnergyFn = Box<dyn Fn(&[Real]) -> Real + Send + Sync>;

pub struct OdeSystem {
    name: String,
    y: Vec<Real>,
    tableau: &'static Tableau,
    rhs: Rhs,
    energy: Option<EnergyFn>,
    /// The largest stable step (s), if the caller knows one (a CFL or diffusion limit).
    max_dt: Option<Real>,
    stages: Stages,
}

impl OdeSystem {
    /// `y0`: the initial state (finite); `method`: a tableau name of `crate::ode` ("euler",
    /// "heun", "rk4", "dopri5"); `max_dt`: the step limit `World::advance` keeps to.
    pub fn new(name: &str, y0: Vec<Real>, method: &str, rhs: Rhs, max_dt: Option<Real>) -> Result<Self> {
        let tableau = ode::by_name(method).ok_or_else(|| {
            let names: Vec<_> = ode::TABLEAUX.iter().map(|t| t.name).collect();
            invalid("method", format!("unknown tableau {method:?}; valid names: {}", names.join(", ")))
        })?;
        if let Some(i) = y0.iter().position(|v| !v.is_finite()) {
            return Err(invalid("y0", format!("entry {i} is not finite: {}", y0[i])));
        }
        if let Some(dt) = max_dt.filter(|dt| !(dt.is_finite() && *dt > 0.0)) {
            return Err(invalid("max_dt", format!("{dt} must be finite and > 0 (seconds)")));
        }
        Ok(Self { name: name.to_string(), y: y0, tableau, rhs, energy: None, max_dt, stages: Stages::default() })
    }

    /// Books `energy(y)` as this system's potential energy.
    pub fn with_energy(mut self, energy: EnergyFn) -> Self {
        self.energy = Some(energy);
        self
    }

    /// The state.
    pub fn y(&self) -> &[Real] {
        &self.y
    }
    pub fn tableau(&self) -> &Tableau {
        self.tableau
    }
}

impl System for OdeSystem {
    fn name(&self) -> &str {
        &self.name
    }
    fn is_empty(&self) -> bool {
        self.y.is_empty()
    }
    /// The state's values.
    fn size(&self) -> usize {
        self.y.len()
    }
    fn prepare(&mut self) -> Result<()> {
        let n = self.y.len();
        let s = self.tableau.stages;
        let need = Need::new(
            "step",
            Need::bytes_of::<Real>((s + 1) * n),
            format!("{s} stages of {} values", count(n as u128)),
        );
        self.stages.reserve(s, n).map_err(|_| need.error())
    }
    fn step(&mut self, dt: Real, _stop: &AtomicBool) -> std::result::Result<(), Halt> {
        let rhs = &self.rhs;
        match ode::explicit_step(self.tableau, &mut self.y, dt, |y, dy| rhs(y, dy), &mut self.stages) {
            None => Ok(()),
            Some(index) => Err(Halt::Diverged { index, quantity: Failure::Position }),
        }
    }
    fn auto_dt(&self) -> Option<Real> {
        self.max_dt
    }
    fn suggest_dt(&self) -> Option<Real> {
        self.max_dt.map(|dt| 0.5 * dt)
    }
    fn energy(&self) -> EnergyReport {
        let potential = self.energy.as_ref().map(|e| vec![(self.name.clone(), e(&self.y))]).unwrap_or_default();
        EnergyReport { kinetic: 0.0, potential, dissipated: Vec::new() }
    }
    /// "y": the state; "rate": f(y), its rate of change.
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let need = Need::fields(names, self.y.len(), "values");
        names
            .iter()
            .map(|n| match *n {
                "y" => need.copy(&self.y),
                "rate" => {
                    let mut dy = need.filled(self.y.len(), 0.0)?;
                    (self.rhs)(&self.y, &mut dy);
                    Ok(dy)
                }
                _ => need.filled(self.y.len(), 0.0),
            })
            .collect()
    }
    fn snapshot(&self) -> Result<Snapshot> {
        snapshot_flat(&self.y)
    }
    fn restore(&mut self, snapshot: Snapshot) {
        self.y = *snapshot.downcast::<Vec<Real>>().expect("a snapshot of this ODE system");
    }
    fn save(&self) -> Result<Arrays> {
        super::saved("the ODE system's state", &[("y", &self.y)])
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        load_flat(&mut self.y, arrays)
    }
}
