//! Points advected by a first-order autonomous flow dx/dt = u(x): strange attractors painted by
//! a cloud of points. The points are stored by axis (all x, then all y, then all z) and stepped
//! by an explicit Butcher tableau of the ODE layer (`crate::ode`), one point at a time in
//! parallel chunks: bit-identical for any thread count.
//!
//! The flows and their customary parameters:
//! - `lorenz` (3D): σ(y − x), x(ρ − z) − y, xy − βz; σ = 10, ρ = 28, β = 8/3 (Lorenz, J.
//!   Atmos. Sci. 20 (1963) 130, eqs. 25–27).
//! - `rossler` (3D): −y − z, x + ay, b + z(x − c); a = b = 0.2, c = 5.7 (Rössler, Phys. Lett.
//!   A 57 (1976) 397).
//! - `thomas` (3D): sin y − bx, sin z − by, sin x − bz; b = 0.208186 (Thomas, Int. J.
//!   Bifurcation Chaos 9 (1999) 1889).
//! - `aizawa` (3D): (z − b)x − dy, dx + (z − b)y, c + az − z³/3 − (x² + y²)(1 + ez) + fzx³;
//!   a = 0.95, b = 0.7, c = 0.6, d = 3.5, e = 0.25, f = 0.1 (Langford's torus attractor as
//!   popularised by Aizawa; see Sprott, "Elegant Chaos", 2010).
//! - `halvorsen` (3D): −ax − 4y − 4z − y² and its two cyclic permutations; a = 1.89 (Sprott,
//!   "Chaos and Time-Series Analysis", 2003, Table A.3).
//! - `van_der_pol` (2D): y, μ(1 − x²)y − x; μ = 1 (van der Pol, Phil. Mag. 2 (1926) 978): a
//!   limit cycle every start is drawn to.
use super::{load_flat, snapshot_flat, Arrays, EnergyReport, Halt, Snapshot, System};
use crate::alloc::Need;
use crate::error::{invalid, Failure, Result};
use crate::ode::{self, Tableau, MAX_STAGES};
use crate::par;
use crate::simd;
use crate::terms::registry::Params;
use crate::vector::Real;
use std::sync::atomic::AtomicBool;

/// One flow: its name, dimension, parameter names with their defaults, and the largest step
/// `World::advance` takes by default (s: well inside RK4's stability region on the attractor).
pub struct FlowKind {
    pub name: &'static str,
    flow: Flow,
    pub dim: usize,
    pub params: &'static [(&'static str, Real)],
    pub max_dt: Real,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Flow {
    Lorenz,
    Rossler,
    Thomas,
    Aizawa,
    Halvorsen,
    VanDerPol,
}

pub const KINDS: [FlowKind; 6] = [
    FlowKind {
        name: "lorenz",
        flow: Flow::Lorenz,
        dim: 3,
        params: &[("sigma", 10.0), ("rho", 28.0), ("beta", 8.0 / 3.0)],
        max_dt: 0.005,
    },
    FlowKind {
        name: "rossler",
        flow: Flow::Rossler,
        dim: 3,
        params: &[("a", 0.2), ("b", 0.2), ("c", 5.7)],
        max_dt: 0.02,
    },
    FlowKind { name: "thomas", flow: Flow::Thomas, dim: 3, params: &[("b", 0.208186)], max_dt: 0.05 },
    FlowKind {
        name: "aizawa",
        flow: Flow::Aizawa,
        dim: 3,
        params: &[("a", 0.95), ("b", 0.7), ("c", 0.6), ("d", 3.5), ("e", 0.25), ("f", 0.1)],
        max_dt: 0.01,
    },
    FlowKind { name: "halvorsen", flow: Flow::Halvorsen, dim: 3, params: &[("a", 1.89)], max_dt: 0.005 },
    FlowKind { name: "van_der_pol", flow: Flow::VanDerPol, dim: 2, params: &[("mu", 1.0)], max_dt: 0.01 },
];

pub fn kind(name: &str) -> Result<&'static FlowKind> {
    KINDS.iter().find(|k| k.name == name).ok_or_else(|| {
        let names: Vec<_> = KINDS.iter().map(|k| k.name).collect();
        invalid("kind", format!("unknown flow {name:?}; valid names: {}", names.join(", ")))
    })
}

/// The velocity u(p) of flow `name` with parameters `c` (in `FlowKind::params` order) at one
/// point `p` (its first `dim` entries).
#[inline(always)]
fn velocity(flow: Flow, c: &[Real; 6], p: [Real; 3]) -> [Real; 3] {
    let [x, y, z] = p;
    match flow {
        Flow::Lorenz => [c[0] * (y - x), x * (c[1] - z) - y, x * y - c[2] * z],
        Flow::Rossler => [-y - z, x + c[0] * y, c[1] + z * (x - c[2])],
        Flow::Thomas => [y.sin() - c[0] * x, z.sin() - c[0] * y, x.sin() - c[0] * z],
        Flow::Aizawa => {
            let (a, b, cc, d, e, f) = (c[0], c[1], c[2], c[3], c[4], c[5]);
            [
                (z - b) * x - d * y,
                d * x + (z - b) * y,
                cc + a * z - z * z * z / 3.0 - (x * x + y * y) * (1.0 + e * z) + f * z * x * x * x,
            ]
        }
        Flow::Halvorsen => {
            let a = c[0];
            [-a * x - 4.0 * y - 4.0 * z - y * y, -a * y - 4.0 * z - 4.0 * x - z * z, -a * z - 4.0 * x - 4.0 * y - x * x]
        }
        Flow::VanDerPol => [y, c[0] * (1.0 - x * x) * y - x, 0.0],
    }
}

/// Points under flow `u`, stored by axis, stepped one point at a time: each point's whole
/// Runge–Kutta step (every stage) runs in registers, so a step reads and writes each
/// coordinate once. The stage sums are the ODE layer's (`crate::ode::explicit_step`):
/// y + h Σ_j a_ij k_j, summed in j order.
pub struct FlowSystem<F> {
    name: String,
    dim: usize,
    y: Vec<Real>,
    tableau: &'static Tableau,
    u: F,
    max_dt: Real,
}

/// One explicit RK step of size `h` from `p` under `u`, for a tableau of `S` stages: with `S`
/// a constant the stage loops unroll and every k stays in registers. Zero coefficients are
/// not skipped (adding 0·k leaves a finite sum unchanged), so there are no branches.
#[inline(always)]
fn rk_point<const S: usize>(t: &Tableau, h: Real, p: [Real; 3], u: &impl Fn([Real; 3]) -> [Real; 3]) -> [Real; 3] {
    let mut k = [[0.0; 3]; S];
    let combine = |w: &[Real; MAX_STAGES], k: &[[Real; 3]; S], upto: usize| {
        let mut acc = [0.0; 3];
        for j in 0..upto {
            for c in 0..3 {
                acc[c] += w[j] * k[j][c];
            }
        }
        [p[0] + h * acc[0], p[1] + h * acc[1], p[2] + h * acc[2]]
    };
    k[0] = u(p);
    for i in 1..S {
        k[i] = u(combine(&t.a[i], &k, i));
    }
    combine(&t.b, &k, S)
}

/// `rk_point` with the tableau's stage count made a constant.
#[inline(always)]
fn sweep<const S: usize>(t: &Tableau, h: Real, d: usize, y: &mut [Real], u: &(impl Fn([Real; 3]) -> [Real; 3] + Sync)) {
    let n = y.len() / d;
    let (xs, rest) = y.split_at_mut(n);
    let (ys, zs) = rest.split_at_mut(n);
    // Compiled per SIMD level (the loop over points vectorises: 4 or 8 points per instruction).
    // No fused multiply-adds are formed, so every level gives the same bits.
    let level = simd::level();
    if d == 3 {
        par::chunks3(xs, ys, zs, |_, xs, ys, zs| {
            simd::vectorized(
                level,
                #[inline(always)]
                || {
                    for k in 0..xs.len() {
                        let q = rk_point::<S>(t, h, [xs[k], ys[k], zs[k]], u);
                        (xs[k], ys[k], zs[k]) = (q[0], q[1], q[2]);
                    }
                },
            )
        });
    } else {
        par::chunks2(xs, ys, |_, xs, ys| {
            simd::vectorized(
                level,
                #[inline(always)]
                || {
                    for k in 0..xs.len() {
                        let q = rk_point::<S>(t, h, [xs[k], ys[k], 0.0], u);
                        (xs[k], ys[k]) = (q[0], q[1]);
                    }
                },
            )
        });
    }
}

impl<F: Fn([Real; 3]) -> [Real; 3] + Send + Sync> FlowSystem<F> {
    fn new(name: &str, dim: usize, y: Vec<Real>, method: &str, u: F, max_dt: Real) -> Result<Self> {
        let tableau = ode::by_name(method).ok_or_else(|| {
            let names: Vec<_> = ode::TABLEAUX.iter().map(|t| t.name).collect();
            invalid("method", format!("unknown tableau {method:?}; valid names: {}", names.join(", ")))
        })?;
        if let Some(i) = y.iter().position(|v| !v.is_finite()) {
            return Err(invalid("points", format!("coordinate {i} is not finite: {}", y[i])));
        }
        if !(max_dt.is_finite() && max_dt > 0.0) {
            return Err(invalid("max_dt", format!("{max_dt} must be finite and > 0 (seconds)")));
        }
        Ok(Self { name: name.to_string(), dim, y, tableau, u, max_dt })
    }

    /// The velocity at every point, stored by axis like the points.
    fn rate(&self, need: &Need) -> Result<Vec<Real>> {
        let n = self.y.len() / self.dim;
        let mut out = need.filled(self.y.len(), 0.0)?;
        for i in 0..n {
            let v = (self.u)(self.point(i));
            for c in 0..self.dim {
                out[c * n + i] = v[c];
            }
        }
        Ok(out)
    }

    fn point(&self, i: usize) -> [Real; 3] {
        let n = self.y.len() / self.dim;
        [self.y[i], self.y[n + i], if self.dim == 3 { self.y[2 * n + i] } else { 0.0 }]
    }
}

impl<F: Fn([Real; 3]) -> [Real; 3] + Send + Sync + 'static> System for FlowSystem<F> {
    fn name(&self) -> &str {
        &self.name
    }
    fn is_empty(&self) -> bool {
        self.y.is_empty()
    }
    /// The points (a step's work is a few velocity evaluations per point).
    fn size(&self) -> usize {
        self.y.len() / self.dim
    }
    fn step(&mut self, dt: Real, _stop: &AtomicBool) -> std::result::Result<(), Halt> {
        let (t, d, u) = (self.tableau, self.dim, &self.u);
        match t.stages {
            1 => sweep::<1>(t, dt, d, &mut self.y, u),
            2 => sweep::<2>(t, dt, d, &mut self.y, u),
            4 => sweep::<4>(t, dt, d, &mut self.y, u),
            7 => sweep::<7>(t, dt, d, &mut self.y, u),
            s => unreachable!("no tableau of {s} stages in crate::ode"),
        }
        match self.y.iter().position(|v| !v.is_finite()) {
            None => Ok(()),
            Some(index) => Err(Halt::Diverged { index, quantity: Failure::Position }),
        }
    }
    fn auto_dt(&self) -> Option<Real> {
        Some(self.max_dt)
    }
    fn suggest_dt(&self) -> Option<Real> {
        Some(0.5 * self.max_dt)
    }
    /// A flow is not a mechanical system: no energy.
    fn energy(&self) -> EnergyReport {
        EnergyReport::default()
    }
    /// "y": the points (by axis); "rate": the velocity u there.
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let need = Need::fields(names, self.y.len(), "values (points by axis)");
        names
            .iter()
            .map(|n| match *n {
                "y" => need.copy(&self.y),
                "rate" => self.rate(&need),
                _ => need.filled(self.y.len(), 0.0),
            })
            .collect()
    }
    fn snapshot(&self) -> Result<Snapshot> {
        snapshot_flat(&self.y)
    }
    fn restore(&mut self, snapshot: Snapshot) {
        self.y = *snapshot.downcast::<Vec<Real>>().expect("a snapshot of this flow");
    }
    fn save(&self) -> Result<Arrays> {
        super::saved("the flow's points", &[("y", &self.y)])
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        load_flat(&mut self.y, arrays)
    }
}

/// Builds flow `kind` named `name` in a world of dimension `dim` from `p`: `points` (n·dim
/// coordinates stored by axis), `method` (a tableau of `crate::ode`), `max_dt` (s) and the
/// flow's parameters by name (missing ones take the defaults of [`KINDS`]).
pub fn build(kind_name: &str, name: &str, dim: usize, mut p: Params) -> Result<Box<dyn System>> {
    let kind = kind(kind_name)?;
    if kind.dim != dim {
        return Err(invalid("kind", format!("the {} flow is {}D; the scene is {dim}D", kind.name, kind.dim)));
    }
    let points = p.take_floats("points")?;
    if points.is_empty() || points.len() % dim != 0 {
        return Err(invalid("points", format!("expected n·{dim} > 0 coordinates, got {}", points.len())));
    }
    // A fixed array, not a Vec: no bounds checks in the loop, so it can vectorise.
    let mut c = [0.0; 6];
    for (slot, (key, default)) in c.iter_mut().zip(kind.params) {
        *slot = if p.has(key) { p.number(key)? } else { *default };
    }
    let max_dt = if p.has("max_dt") { p.number("max_dt")? } else { kind.max_dt };
    let method = if p.has("method") { p.text("method")?.to_string() } else { "rk4".to_string() };
    // One system type per flow, so each step loop is compiled with its formula inlined.
    macro_rules! flow {
        ($f:expr) => {
            Box::new(FlowSystem::new(name, dim, points, &method, move |q| velocity($f, &c, q), max_dt)?)
        };
    }
    Ok(match kind.flow {
        Flow::Lorenz => flow!(Flow::Lorenz),
        Flow::Rossler => flow!(Flow::Rossler),
        Flow::Thomas => flow!(Flow::Thomas),
        Flow::Aizawa => flow!(Flow::Aizawa),
        Flow::Halvorsen => flow!(Flow::Halvorsen),
        Flow::VanDerPol => flow!(Flow::VanDerPol),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terms::registry::Value;
    use std::sync::atomic::AtomicBool;

    fn lorenz(points: Vec<Real>) -> Box<dyn System> {
        let p = Params::new().with("points", Value::Floats(points)).with("method", Value::Text("rk4".into()));
        build("lorenz", "l", 3, p).unwrap()
    }

    #[test]
    fn fixed_points_of_lorenz_stay_put() {
        // C± = (±√(β(ρ−1)), ±√(β(ρ−1)), ρ − 1) and the origin are equilibria.
        let q = (8.0 / 3.0 * 27.0_f64).sqrt();
        let mut s = lorenz(vec![q, -q, 0.0, q, -q, 0.0, 27.0, 27.0, 0.0]);
        let stop = AtomicBool::new(false);
        for _ in 0..100 {
            s.step(0.005, &stop).unwrap();
        }
        let y = &s.fields(&["y"]).unwrap()[0];
        let want = [q, -q, 0.0, q, -q, 0.0, 27.0, 27.0, 0.0];
        for (a, b) in y.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn every_kind_builds_and_checks_its_input() {
        for k in &KINDS {
            let pts = vec![0.1; 2 * k.dim];
            let p = Params::new().with("points", Value::Floats(pts));
            assert!(build(k.name, "f", k.dim, p).is_ok(), "{}", k.name);
        }
        let p = Params::new().with("points", Value::Floats(vec![0.1; 4]));
        assert!(build("lorenz", "f", 3, p.clone()).is_err()); // not n·3 values
        assert!(build("lorenz", "f", 2, p.clone()).is_err()); // a 3D flow in 2D
        assert!(build("nope", "f", 2, p).is_err());
    }
}
