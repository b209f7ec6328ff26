//! Points advected by a first-order autonomous flow dx/dt = u(x): strange attractors painted by
//! a cloud of points. Each flow is an [`OdeSystem`] over the points' coordinates, stored by
//! axis (all x, then all y, then all z) so that the right-hand side runs over contiguous
//! columns, in parallel chunks of points: bit-identical for any thread count.
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
use super::ode::{OdeSystem, Rhs};
use super::System;
use crate::error::{invalid, Result};
use crate::par;
use crate::terms::registry::Params;
use crate::vector::Real;

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
fn velocity(flow: Flow, c: &[Real], p: [Real; 3]) -> [Real; 3] {
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

/// The right-hand side over a state stored by axis: `y` = [x₀…x_{n−1}, y₀…, (z₀…)].
fn rhs(kind: &'static FlowKind, c: Vec<Real>) -> Rhs {
    // One loop per flow (the match outside it), so that each is compiled with its formula
    // inlined and vectorises where its arithmetic allows.
    macro_rules! flow {
        ($f:expr) => {
            Box::new(move |y: &[Real], dy: &mut [Real]| sweep(kind.dim, y, dy, |p| velocity($f, &c, p)))
        };
    }
    match kind.flow {
        Flow::Lorenz => flow!(Flow::Lorenz),
        Flow::Rossler => flow!(Flow::Rossler),
        Flow::Thomas => flow!(Flow::Thomas),
        Flow::Aizawa => flow!(Flow::Aizawa),
        Flow::Halvorsen => flow!(Flow::Halvorsen),
        Flow::VanDerPol => flow!(Flow::VanDerPol),
    }
}

/// dy = u(y) over points stored by axis, in parallel chunks of points.
#[inline(always)]
fn sweep(d: usize, y: &[Real], dy: &mut [Real], u: impl Fn([Real; 3]) -> [Real; 3] + Sync + Send) {
    let n = y.len() / d;
    let (dx, rest) = dy.split_at_mut(n);
    let (dyy, dz) = rest.split_at_mut(n);
    let (xs, ys) = (&y[..n], &y[n..2 * n]);
    if d == 3 {
        let zs = &y[2 * n..];
        par::chunks3(dx, dyy, dz, |s, a, b, e| {
            let (xs, ys, zs) = (&xs[s..s + a.len()], &ys[s..s + a.len()], &zs[s..s + a.len()]);
            for k in 0..a.len() {
                let v = u([xs[k], ys[k], zs[k]]);
                (a[k], b[k], e[k]) = (v[0], v[1], v[2]);
            }
        });
    } else {
        par::chunks2(dx, dyy, |s, a, b| {
            let (xs, ys) = (&xs[s..s + a.len()], &ys[s..s + a.len()]);
            for k in 0..a.len() {
                let v = u([xs[k], ys[k], 0.0]);
                (a[k], b[k]) = (v[0], v[1]);
            }
        });
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
    let mut c = Vec::with_capacity(kind.params.len());
    for (key, default) in kind.params {
        c.push(if p.has(key) { p.number(key)? } else { *default });
    }
    let max_dt = if p.has("max_dt") { p.number("max_dt")? } else { kind.max_dt };
    let method = if p.has("method") { p.text("method")?.to_string() } else { "rk4".to_string() };
    Ok(Box::new(OdeSystem::new(name, points, &method, rhs(kind, c), Some(max_dt))?))
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
        let y = &s.fields(&["y"])[0];
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
