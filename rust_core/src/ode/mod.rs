//! The ODE layer: Butcher tableaux of explicit Runge–Kutta methods and one explicit RK step over
//! a flat array, shared by every system. The particle integrators (`crate::integrators`) read
//! their coefficients from here and fuse the stages with the force evaluation for speed; other
//! systems (`systems::ode`, grid fields by the method of lines) step with [`explicit_step`].
//!
//! A tableau (Hairer, Nørsett & Wanner, Solving ODEs I, §II.1, eq. 1.8): for y' = f(y),
//!   k_i = f(y0 + h Σ_{j<i} a_ij k_j),   y1 = y0 + h Σ_i b_i k_i,
//! with c_i = Σ_j a_ij the stage times; `e` = b − b̂ gives an embedded error estimate.
use crate::par;
use crate::vector::Real;

/// The most stages a tableau here has (Dormand–Prince: 7).
pub const MAX_STAGES: usize = 7;

/// An explicit Runge–Kutta method. Rows and weights past `stages` are zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tableau {
    pub name: &'static str,
    /// Order of accuracy of `b`.
    pub order: u32,
    pub stages: usize,
    /// Strictly lower triangular: `a[i][j] = 0` for j ≥ i.
    pub a: [[Real; MAX_STAGES]; MAX_STAGES],
    pub b: [Real; MAX_STAGES],
    pub c: [Real; MAX_STAGES],
    /// b − b̂ (the embedded lower-order weights) for error control, if the method has them.
    pub e: Option<[Real; MAX_STAGES]>,
}

const Z: [Real; MAX_STAGES] = [0.0; MAX_STAGES];

/// Explicit (forward) Euler: first order, one stage.
pub const EULER: Tableau = Tableau {
    name: "euler",
    order: 1,
    stages: 1,
    a: [Z; MAX_STAGES],
    b: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    c: Z,
    e: None,
};

/// Heun's method (explicit trapezoid): second order, with Euler embedded (b̂ = (1, 0)).
pub const HEUN: Tableau = Tableau {
    name: "heun",
    order: 2,
    stages: 2,
    a: [Z, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], Z, Z, Z, Z, Z],
    b: [0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0],
    c: [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    e: Some([-0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0]),
};

/// The classic fourth-order method (Kutta 1901; Hairer, Nørsett & Wanner, Table 1.2).
pub const RK4: Tableau = Tableau {
    name: "rk4",
    order: 4,
    stages: 4,
    a: [
        Z,
        [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        Z,
        Z,
        Z,
    ],
    b: [1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0, 0.0, 0.0, 0.0],
    c: [0.0, 0.5, 0.5, 1.0, 0.0, 0.0, 0.0],
    e: None,
};

/// Dormand–Prince RK5(4) (Dormand & Prince 1980, J. Comput. Appl. Math. 6, 19, Table 2): fifth
/// order with fourth embedded; the last row of `a` equals `b` ("first same as last": stage 7 is
/// the derivative at y1).
pub const DOPRI5: Tableau = Tableau {
    name: "dopri5",
    order: 5,
    stages: 7,
    a: [
        Z,
        [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0, 0.0],
        [19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0, 0.0, 0.0, 0.0],
        [9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0, 0.0, 0.0],
        [35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0, 0.0],
    ],
    b: [35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0, 0.0],
    c: [0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0],
    e: Some([71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0]),
};

/// Every tableau here, for tables and tests.
pub const TABLEAUX: [&Tableau; 4] = [&EULER, &HEUN, &RK4, &DOPRI5];

/// Looks a tableau up by name.
pub fn by_name(name: &str) -> Option<&'static Tableau> {
    TABLEAUX.iter().copied().find(|t| t.name == name)
}

/// The scratch of [`explicit_step`]: one derivative per stage and the stage state.
#[derive(Default, Clone)]
pub struct Stages {
    k: Vec<Vec<Real>>,
    ys: Vec<Real>,
}

impl Stages {
    /// Reserves, fallibly, the scratch of a `stages`-stage step over `n` values.
    pub fn reserve(&mut self, stages: usize, n: usize) -> Result<(), std::collections::TryReserveError> {
        self.k.resize_with(stages.max(self.k.len()), Vec::new);
        for k in self.k.iter_mut().chain([&mut self.ys]) {
            k.try_reserve_exact(n.saturating_sub(k.len()))?;
            k.resize(n, 0.0);
        }
        Ok(())
    }
}

/// One explicit RK step of size `h` of y' = f(y) in place: `f(y, dy)` writes the derivative at
/// `y` into `dy`. The combinations are elementwise (no reductions), run in parallel chunks, so
/// the result is bit-identical for any thread count. Returns the first index whose new value
/// is not finite, if any.
pub fn explicit_step(
    tableau: &Tableau,
    y: &mut [Real],
    h: Real,
    mut f: impl FnMut(&[Real], &mut [Real]),
    st: &mut Stages,
) -> Option<usize> {
    let n = y.len();
    let s = tableau.stages;
    if st.k.len() < s || st.ys.len() != n || st.k[..s].iter().any(|k| k.len() != n) {
        st.reserve(s, n).expect("explicit_step scratch: reserve with Stages::reserve first");
    }
    for i in 0..s {
        let (done, rest) = st.k.split_at_mut(i);
        if i == 0 {
            f(y, &mut rest[0]);
            continue;
        }
        let a = &tableau.a[i];
        let y0: &[Real] = y;
        par::chunks1(&mut st.ys, |start, ys| {
            let len = ys.len();
            let acc = weighted(a, done, start, len);
            for ((out, y0), acc) in ys.iter_mut().zip(&y0[start..]).zip(&acc[..len]) {
                *out = y0 + h * acc;
            }
        });
        f(&st.ys, &mut rest[0]);
    }
    let (b, k) = (&tableau.b, &st.k[..s]);
    par::chunks1(y, |start, ys| {
        let len = ys.len();
        let acc = weighted(b, k, start, len);
        for (out, acc) in ys.iter_mut().zip(&acc[..len]) {
            *out += h * acc;
        }
    });
    y.iter().position(|v| !v.is_finite())
}

/// Σ_j w_j k_j[start..start + len] (len ≤ `par::CHUNK`), summed in j order for each element as
/// a scalar loop would, but one stage at a time over the chunk, so that it vectorises.
#[inline(always)]
fn weighted(w: &[Real; MAX_STAGES], k: &[Vec<Real>], start: usize, len: usize) -> [Real; par::CHUNK] {
    let mut acc = [0.0; par::CHUNK];
    for (j, k) in k.iter().enumerate() {
        if w[j] != 0.0 {
            for (a, k) in acc[..len].iter_mut().zip(&k[start..start + len]) {
                *a += w[j] * k;
            }
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The order conditions up to order 4 (Hairer, Nørsett & Wanner, Table 2.2), and c = row
    /// sums of a: a tableau whose coefficient is mistyped fails here.
    #[test]
    fn tableaux_satisfy_their_order_conditions() {
        for t in TABLEAUX {
            let (a, b, c, s) = (&t.a, &t.b, &t.c, t.stages);
            for i in 0..s {
                let row: Real = a[i][..i].iter().sum();
                assert!((row - c[i]).abs() < 1e-14, "{}: c[{i}]", t.name);
                assert!(a[i][i..].iter().all(|&x| x == 0.0), "{}: row {i} not strictly lower", t.name);
            }
            let sum = |f: &dyn Fn(usize) -> Real| (0..s).map(f).sum::<Real>();
            let ac = |i: usize| (0..s).map(|j| a[i][j] * c[j]).sum::<Real>();
            let conditions: [(u32, Real, Real); 8] = [
                (1, sum(&|i| b[i]), 1.0),
                (2, sum(&|i| b[i] * c[i]), 0.5),
                (3, sum(&|i| b[i] * c[i] * c[i]), 1.0 / 3.0),
                (3, sum(&|i| b[i] * ac(i)), 1.0 / 6.0),
                (4, sum(&|i| b[i] * c[i].powi(3)), 0.25),
                (4, sum(&|i| b[i] * c[i] * ac(i)), 0.125),
                (4, sum(&|i| b[i] * (0..s).map(|j| a[i][j] * c[j] * c[j]).sum::<Real>()), 1.0 / 12.0),
                (4, sum(&|i| b[i] * (0..s).map(|j| a[i][j] * ac(j)).sum::<Real>()), 1.0 / 24.0),
            ];
            for (order, got, want) in conditions {
                if order <= t.order {
                    assert!((got - want).abs() < 1e-14, "{}: order-{order} condition {got} != {want}", t.name);
                }
            }
            // Every embedded estimate is of a consistent method: Σ b̂ = 1, i.e. Σ e = 0.
            if let Some(e) = t.e {
                assert!(e.iter().sum::<Real>().abs() < 1e-15, "{}: Σ e", t.name);
            }
        }
    }

    /// y' = −y from 1 to t = 1: the global error falls as h^order.
    #[test]
    fn explicit_step_converges_at_the_order_of_each_tableau() {
        for t in TABLEAUX {
            let err = |n: usize| {
                let mut y = vec![1.0, 2.0];
                let mut st = Stages::default();
                st.reserve(t.stages, 2).unwrap();
                for _ in 0..n {
                    let bad = explicit_step(
                        t,
                        &mut y,
                        1.0 / n as Real,
                        |y, dy| dy.iter_mut().zip(y).for_each(|(d, y)| *d = -y),
                        &mut st,
                    );
                    assert_eq!(bad, None);
                }
                (y[0] - (-1.0 as Real).exp()).abs()
            };
            let (coarse, fine) = (err(8), err(16));
            let observed = (coarse / fine).log2();
            assert!((observed - t.order as Real).abs() < 0.3, "{}: observed order {observed:.2}", t.name);
        }
    }

    #[test]
    fn a_non_finite_value_is_reported_by_index() {
        let mut y = vec![1.0, 1.0, 1.0];
        let mut st = Stages::default();
        let bad =
            explicit_step(&RK4, &mut y, 1.0, |y, dy| dy.iter_mut().zip(y).for_each(|(d, y)| *d = 1e300 * y), &mut st);
        assert_eq!(bad, Some(0));
    }
}
