//! A potential φ sampled on a regular grid, interpolated bilinearly (2D) or trilinearly (3D),
//! acting on the particles' mass (φ in J/kg) or on their `charge` attribute (φ in V):
//!   U = Σ_i c_i φ̃(x_i),   F_i = −c_i ∇φ̃(x_i)
//! with c_i the particle's mass or charge and φ̃ the interpolant.
//!
//! **Layout.** `phi` holds n_0 × n_1 (× n_2) node values in C order (the last axis fastest, as
//! numpy stores an array of that shape); node (i, j, k) sits at origin + (i h_0, j h_1, k h_2).
//! Each n_a ≥ 2: the grid covers the box [origin, origin + (n − 1) h].
//!
//! **Force.** The force is minus the exact gradient of the same interpolant the energy books
//! evaluate, so the field is conservative with respect to the potential in the books. Within a
//! cell ∂φ̃/∂x_a is linear in the other coordinates and constant along x_a; across cell faces it
//! jumps (φ̃ is continuous, its gradient is not), by O(h |∂²φ/∂x_a²|) for a smooth φ. A
//! symplectic integrator therefore keeps no exact shadow energy over cell crossings: each crossing
//! costs an energy error of order |jump|·|v|·dt, of either sign (measured in
//! `tests/forces/test_potentials.py` and `docs/potentials.md`).
//!
//! **Outside the grid** φ̃ is continued by its value at the nearest point of the box (each
//! coordinate clamped to the box): φ̃(x) = φ̃(clamp(x)). This continuation is continuous, and the
//! force is its exact gradient: zero along every axis on which the particle is outside the box,
//! the interpolant's gradient at the clamped point along the others. The energy books therefore
//! stay balanced for particles that leave and come back (no force pushes them back, unless they
//! are inside the box along the axes that matter); a particle far outside feels only the
//! tangential force of the nearest face.
use super::{coupled_forces, coupled_potential, Coupling};
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::terms::registry::{Context, Params};
use crate::terms::{Term, Traits, Write};
use crate::vector::{Real, Vector};
use std::sync::OnceLock;

pub struct GridPotential<V: Vector> {
    pub name: String,
    /// Node values in C order, J/kg or V.
    phi: Vec<Real>,
    /// Nodes per axis (≥ 2; the unused third axis of a 2D grid is 1).
    n: [usize; 3],
    /// Node spacing per axis (m) and its reciprocal.
    h: [Real; 3],
    inv_h: [Real; 3],
    /// Position of node 0, m.
    origin: [Real; 3],
    pub coupling: Coupling,
    /// Bounds on the interpolant's curvature (1/s² per unit coupling over mass) and on its
    /// slope |∇φ̃| (m/s² per unit coupling over mass), computed on first use.
    bounds: OnceLock<(Real, Real)>,
    _v: std::marker::PhantomData<V>,
}

fn build<V: Vector>(name: String, mut p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    let coupling = Coupling::from_params(&p)?;
    let (spacing, origin) = (p.vector::<V>("spacing")?, p.vector::<V>("origin")?);
    let shape = p.take_floats("shape")?;
    let phi = p.take_floats("phi")?;
    Ok(Box::new(GridPotential::new(name, phi, &shape, spacing, origin, coupling)?))
}
crate::register_term!("grid_potential", build);

/// Where coordinate `x` falls on axis `a`: the cell (lower node index), the fraction in it
/// (0..=1) and whether `x` is inside the box along `a` (else it is clamped to the nearest face).
/// A NaN coordinate gives cell 0 and fraction NaN (no out-of-bounds read).
#[inline(always)]
fn locate(x: Real, origin: Real, inv_h: Real, n: usize) -> (usize, Real, bool) {
    let s = (x - origin) * inv_h;
    let top = (n - 1) as Real;
    let inside = (0.0..=top).contains(&s);
    let s = s.clamp(0.0, top);
    let c = (s as usize).min(n - 2);
    (c, s - c as Real, inside)
}

impl<V: Vector> GridPotential<V> {
    pub fn new(
        name: String,
        phi: Vec<Real>,
        shape: &[Real],
        spacing: V,
        origin: V,
        coupling: Coupling,
    ) -> Result<Self> {
        if shape.len() != V::DIM {
            let msg = format!("a {}D grid cannot act in a {}D scene", shape.len(), V::DIM);
            return Err(invalid("phi", msg));
        }
        let mut n = [1usize; 3];
        for (a, &s) in shape.iter().enumerate() {
            if !(s.fract() == 0.0 && (2.0..=(u32::MAX as Real)).contains(&s)) {
                return Err(invalid("phi", format!("axis {a} has {s} nodes (each axis needs a whole number >= 2)")));
            }
            n[a] = s as usize;
        }
        let total = n.iter().try_fold(1usize, |p, &k| p.checked_mul(k));
        if total != Some(phi.len()) {
            return Err(invalid(
                "phi",
                format!("holds {} values, its shape {:?} needs {total:?}", phi.len(), &n[..V::DIM]),
            ));
        }
        if let Some(i) = phi.iter().position(|p| !p.is_finite()) {
            return Err(invalid("phi", format!("value {i} (C order) is {} (must be finite)", phi[i])));
        }
        let (mut h, mut inv_h, mut o) = ([1.0; 3], [1.0; 3], [0.0; 3]);
        for a in 0..V::DIM {
            h[a] = spacing.comp(a);
            o[a] = origin.comp(a);
            if !(h[a] > 0.0 && h[a].is_finite() && (1.0 / h[a]).is_finite()) {
                return Err(invalid("spacing", format!("component {a} is {} (must be finite and > 0)", h[a])));
            }
            inv_h[a] = 1.0 / h[a];
            let end = o[a] + (n[a] - 1) as Real * h[a];
            if !end.is_finite() {
                return Err(invalid("spacing", format!("axis {a}: the grid's far end {end} is beyond float64")));
            }
        }
        Ok(Self { name, phi, n, h, inv_h, origin: o, coupling, bounds: OnceLock::new(), _v: std::marker::PhantomData })
    }

    /// φ̃(x) and ∇φ̃(x) (J/kg/m or V/m), the gradient zero along axes on which x is outside.
    #[inline]
    pub fn sample(&self, x: V) -> (Real, V) {
        let (n, o, ih, p) = (self.n, self.origin, self.inv_h, &self.phi);
        let (i, tx, in_x) = locate(x.comp(0), o[0], ih[0], n[0]);
        let (j, ty, in_y) = locate(x.comp(1), o[1], ih[1], n[1]);
        let gate = |inside: bool, d: Real, a: usize| if inside { d * ih[a] } else { 0.0 };
        if V::DIM == 2 {
            let r = i * n[1] + j;
            let (f00, f01, f10, f11) = (p[r], p[r + 1], p[r + n[1]], p[r + n[1] + 1]);
            let (dx0, dx1) = (f10 - f00, f11 - f01); // along x at y = 0 and y = 1
            let a = f00 + tx * dx0;
            let b = f01 + tx * dx1;
            let phi = a + ty * (b - a);
            let g = [gate(in_x, dx0 + ty * (dx1 - dx0), 0), gate(in_y, b - a, 1), 0.0];
            (phi, V::from_slice(&g))
        } else {
            let (k, tz, in_z) = locate(x.comp(2), o[2], ih[2], n[2]);
            let (sy, sx) = (n[2], n[1] * n[2]); // strides of j and i
            let r = (i * n[1] + j) * n[2] + k;
            let c = |di: usize, dj: usize, dk: usize| p[r + di * sx + dj * sy + dk];
            // Differences along x on the four x-edges of the cell, named by (y, z).
            let (d00, d10, d01, d11) =
                (c(1, 0, 0) - c(0, 0, 0), c(1, 1, 0) - c(0, 1, 0), c(1, 0, 1) - c(0, 0, 1), c(1, 1, 1) - c(0, 1, 1));
            let e00 = c(0, 0, 0) + tx * d00;
            let e10 = c(0, 1, 0) + tx * d10;
            let e01 = c(0, 0, 1) + tx * d01;
            let e11 = c(0, 1, 1) + tx * d11;
            let g0 = e00 + ty * (e10 - e00);
            let g1 = e01 + ty * (e11 - e01);
            let phi = g0 + tz * (g1 - g0);
            let dx0 = d00 + ty * (d10 - d00);
            let dx1 = d01 + ty * (d11 - d01);
            let dy = (e10 - e00) + tz * ((e11 - e01) - (e10 - e00));
            let g = [gate(in_x, dx0 + tz * (dx1 - dx0), 0), gate(in_y, dy, 1), gate(in_z, g1 - g0, 2)];
            (phi, V::from_slice(&g))
        }
    }

    /// (curvature, slope): max over axes a of (max |Δ²_a φ| / h_a² + Σ_{b≠a} max |Δ_a Δ_b φ| /
    /// (h_a h_b)), a Gershgorin bound on the curvature of a smooth potential the grid samples, and
    /// (Σ_a (max |Δ_a φ| / h_a)²)^{1/2} ≥ |∇φ̃| everywhere. O(nodes), once.
    fn bounds(&self) -> (Real, Real) {
        *self.bounds.get_or_init(|| {
            let (n, p) = (self.n, &self.phi);
            let stride = [n[1] * n[2], n[2], 1];
            let mut first = [0.0 as Real; 3];
            let mut second = [0.0 as Real; 3];
            let mut mixed = [[0.0 as Real; 3]; 3];
            for i in 0..n[0] {
                for j in 0..n[1] {
                    for k in 0..n[2] {
                        let at = [i, j, k];
                        let r = (i * n[1] + j) * n[2] + k;
                        for a in 0..V::DIM {
                            if at[a] + 1 < n[a] {
                                first[a] = first[a].max((p[r + stride[a]] - p[r]).abs());
                            }
                            if at[a] >= 1 && at[a] + 1 < n[a] {
                                let d = p[r + stride[a]] - 2.0 * p[r] + p[r - stride[a]];
                                second[a] = second[a].max(d.abs());
                            }
                            for b in a + 1..V::DIM {
                                if at[a] + 1 < n[a] && at[b] + 1 < n[b] {
                                    let (sa, sb) = (stride[a], stride[b]);
                                    let d = p[r + sa + sb] - p[r + sa] - p[r + sb] + p[r];
                                    mixed[a][b] = mixed[a][b].max(d.abs());
                                }
                            }
                        }
                    }
                }
            }
            let h = self.h;
            let curvature = (0..V::DIM)
                .map(|a| {
                    let off: Real =
                        (0..V::DIM).filter(|&b| b != a).map(|b| mixed[a.min(b)][a.max(b)] / (h[a] * h[b])).sum();
                    second[a] / (h[a] * h[a]) + off
                })
                .fold(0.0, Real::max);
            let slope = (0..V::DIM).map(|a| (first[a] / h[a]).powi(2)).sum::<Real>().sqrt();
            (curvature, slope)
        })
    }
}

impl<V: Vector> Term<V> for GridPotential<V> {
    fn name(&self) -> &str {
        &self.name
    }
    fn add_forces(&mut self, x: &[V], _v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let this = &*self;
        coupled_forces(self.coupling, x, model, f, write, |p| -this.sample(p).1);
        0.0
    }
    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        Some(coupled_potential(self.coupling, x, model, |p| self.sample(p).0))
    }
    fn traits(&self) -> Traits<V> {
        Traits::conservative()
    }
    fn time_scale(&self, _x: &[V], model: &Model) -> Option<Real> {
        let w2 = self.bounds().0 * self.coupling.max_ratio(model);
        let t = 1.0 / w2.sqrt();
        (t.is_finite() && t > 0.0).then_some(t)
    }
    fn max_dt(&self, _x: &[V], v: &[V], model: &Model, g: Real) -> Option<Real> {
        // The interpolant's force is piecewise smooth cell by cell: `advance` keeps every particle
        // it moves to at most one cell per substep, |v| dt + ½ a dt² ≤ h_min, with a bounded by
        // the grid's steepest slope (plus the uniform fields).
        let c = self.coupling.of(model)?;
        let vmax = par::reduce(v.len(), 0.0, Real::max, |r| {
            r.filter(|&i| model.inv_mass[i] != 0.0 && c[i] != 0.0).map(|i| v[i].length_squared()).fold(0.0, Real::max)
        })
        .sqrt();
        let a = self.bounds().1 * self.coupling.max_ratio(model) + g;
        let h = self.h[..V::DIM].iter().copied().fold(Real::INFINITY, Real::min);
        // The positive root of ½ a t² + vmax t − h, written without cancellation.
        let dt = 2.0 * h / (vmax + (vmax * vmax + 2.0 * a * h).sqrt());
        (dt.is_finite() && dt > 0.0).then_some(dt)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    fn lcg(s: &mut u64) -> f64 {
        *s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*s >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A grid of `shape` sampling `f` at its nodes.
    fn sampled<V: Vector>(shape: &[usize], h: V, o: V, mut f: impl FnMut(&[Real]) -> Real) -> GridPotential<V> {
        let mut phi = Vec::new();
        let n3 = [shape[0], shape[1], shape.get(2).copied().unwrap_or(1)];
        for i in 0..n3[0] {
            for j in 0..n3[1] {
                for k in 0..n3[2] {
                    let at = [i, j, k];
                    let x: Vec<Real> = (0..V::DIM).map(|a| o.comp(a) + at[a] as Real * h.comp(a)).collect();
                    phi.push(f(&x));
                }
            }
        }
        let s: Vec<Real> = shape.iter().map(|&n| n as Real).collect();
        GridPotential::new("g".into(), phi, &s, h, o, Coupling::Mass).unwrap()
    }

    fn linear(x: &[Real]) -> Real {
        [2.0, -3.0, 0.5].iter().zip(x).map(|(a, b)| a * b).sum::<Real>() + 1.0
    }

    fn check_linear_is_exact<V: Vector>(shape: &[usize]) {
        let h = V::from_slice(&[0.3, 0.2, 0.5]);
        let o = V::from_slice(&[-1.0, 0.5, 2.0]);
        let g = sampled(shape, h, o, linear);
        let want = V::from_slice(&[2.0, -3.0, 0.5]);
        let mut s = 1;
        for _ in 0..1000 {
            let x = V::from_slice(&[-1.0 + 2.0 * lcg(&mut s), 0.5 + 1.5 * lcg(&mut s), 2.0 + 3.0 * lcg(&mut s)]);
            let (phi, grad) = g.sample(x);
            let xs: Vec<Real> = (0..V::DIM).map(|a| x.comp(a)).collect();
            assert!((phi - linear(&xs)).abs() < 1e-13, "{phi} vs {}", linear(&xs));
            assert!((grad - want).length_squared().sqrt() < 1e-12, "{grad:?}");
        }
    }

    #[test]
    fn a_linear_potential_is_reproduced_exactly_with_its_uniform_gradient() {
        check_linear_is_exact::<DVec2>(&[8, 9]);
        check_linear_is_exact::<DVec3>(&[8, 9, 7]);
    }

    fn check_gradient_is_the_interpolants<V: Vector>(shape: &[usize]) {
        // A rough random field: inside a cell the gradient matches central differences of φ̃.
        let mut s = 9;
        let g = sampled(shape, V::from_slice(&[0.5, 0.25, 1.0]), V::ZERO, |_| lcg(&mut s));
        let mut s = 3;
        let h = 1e-7;
        for _ in 0..500 {
            let x = V::from_slice(&[
                0.05 + 0.9 * lcg(&mut s) * 3.0,
                0.05 + 0.9 * lcg(&mut s) * 1.5,
                0.05 + 0.9 * lcg(&mut s) * 6.0,
            ]);
            let (_, grad) = g.sample(x);
            for a in 0..V::DIM {
                let mut e = [0.0; 3];
                e[a] = h;
                let d = V::from_slice(&e);
                let fd = (g.sample(x + d).0 - g.sample(x - d).0) / (2.0 * h);
                assert!((grad.comp(a) - fd).abs() < 1e-6, "axis {a} at {x:?}: {} vs {fd}", grad.comp(a));
            }
        }
    }

    #[test]
    fn the_gradient_is_the_interpolants_own() {
        check_gradient_is_the_interpolants::<DVec2>(&[7, 7]);
        check_gradient_is_the_interpolants::<DVec3>(&[7, 7, 7]);
    }

    #[test]
    fn outside_the_box_the_value_is_clamped_and_the_normal_force_vanishes() {
        // φ = x² + y² on [0, 1]²: beyond x = 1 the value is φ̃(1, y), ∂/∂x = 0, ∂/∂y unchanged.
        let g = sampled(&[11, 11], DVec2::splat(0.1), DVec2::ZERO, |x| x[0] * x[0] + x[1] * x[1]);
        let (inside, gi) = g.sample(DVec2::new(1.0, 0.35));
        let (outside, go) = g.sample(DVec2::new(7.0, 0.35));
        assert_eq!(inside, outside);
        assert_eq!(go.x, 0.0);
        assert_eq!(go.y, gi.y);
        let (corner, gc) = g.sample(DVec2::new(-3.0, 9.0));
        assert_eq!((corner, gc), (1.0, DVec2::ZERO));
        let (nan, _) = g.sample(DVec2::new(f64::NAN, 0.5));
        assert!(nan.is_nan());
    }

    #[test]
    fn forces_and_potential_follow_the_coupling() {
        let g = |c| {
            let phi = vec![0.0, 1.0, 2.0, 3.0]; // φ = 2x + y on the unit square
            GridPotential::<DVec2>::new("g".into(), phi, &[2.0, 2.0], DVec2::ONE, DVec2::ZERO, c).unwrap()
        };
        let mut model = Model { mass: vec![2.0; 3], inv_mass: vec![0.5, 0.5, 0.0], ..Default::default() };
        let x = [DVec2::new(0.5, 0.5); 3];
        let mut f = [DVec2::ONE; 3];
        let mut t = g(Coupling::Mass);
        t.add_forces(&x, &x, &model, &mut f, Write::Overwrite);
        assert_eq!(f, [DVec2::new(-4.0, -2.0), DVec2::new(-4.0, -2.0), DVec2::ZERO]);
        assert_eq!(t.potential(&x, &model), Some(2.0 * 2.0 * 1.5));
        let mut t = g(Coupling::Charge);
        t.add_forces(&x, &x, &model, &mut f, Write::Overwrite);
        assert_eq!(f, [DVec2::ZERO; 3]); // no charges
        assert_eq!(t.potential(&x, &model), Some(0.0));
        model.attributes.insert("charge", vec![-1.0, 0.0, 5.0]);
        t.add_forces(&x, &x, &model, &mut f, Write::Overwrite);
        assert_eq!(f, [DVec2::new(2.0, 1.0), DVec2::ZERO, DVec2::ZERO]);
        assert_eq!(t.potential(&x, &model), Some(-1.5));
    }

    #[test]
    fn the_curvature_bound_gives_the_trap_frequency_of_a_sampled_parabola() {
        // φ = ½ ω² |x|² with ω² = 9: the bound is exactly ω² (no mixed terms).
        let g = sampled(&[21, 21, 21], DVec3::splat(0.1), DVec3::splat(-1.0), |x| {
            4.5 * (x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
        });
        let model = Model { mass: vec![3.0], inv_mass: vec![1.0 / 3.0], ..Default::default() };
        let t = g.time_scale(&[DVec3::ZERO], &model).unwrap();
        assert!((t - 1.0 / 3.0).abs() < 1e-9, "{t}");
    }

    #[test]
    fn a_step_may_cross_at_most_one_cell() {
        // φ = 3x + 4y (slope 5) on cells 0.1 m wide: |v| dt + ½·5·dt² = 0.1.
        let g = sampled(&[11, 11], DVec2::splat(0.1), DVec2::ZERO, |x| 3.0 * x[0] + 4.0 * x[1]);
        let model = Model { mass: vec![2.0; 2], inv_mass: vec![0.5, 0.0], ..Default::default() };
        let v = [DVec2::new(0.0, 2.0), DVec2::new(0.0, 1e9)]; // the pinned particle does not count
        let dt = g.max_dt(&v, &v, &model, 0.0).unwrap();
        assert!((2.0 * dt + 2.5 * dt * dt - 0.1).abs() < 1e-15, "{dt}");
        let at_rest = g.max_dt(&v, &[DVec2::ZERO; 2], &model, 0.0).unwrap();
        assert!((at_rest - (0.2f64 / 5.0).sqrt()).abs() < 1e-15, "{at_rest}");
        // A flat grid on particles at rest has no limit.
        let flat = sampled(&[3, 3], DVec2::ONE, DVec2::ZERO, |_| 1.0);
        assert_eq!(flat.max_dt(&v, &[DVec2::ZERO; 2], &model, 0.0), None);
    }

    #[test]
    fn bad_grids_are_refused_by_name() {
        let e = |phi: Vec<Real>, shape: &[Real], h: Real| {
            GridPotential::<DVec2>::new("g".into(), phi, shape, DVec2::splat(h), DVec2::ZERO, Coupling::Mass)
                .err()
                .unwrap()
                .to_string()
        };
        assert!(e(vec![0.0; 4], &[2.0, 2.0, 1.0], 1.0).starts_with("phi: a 3D grid"));
        assert!(e(vec![0.0; 4], &[1.0, 4.0], 1.0).starts_with("phi: axis 0 has 1 nodes"));
        assert!(e(vec![0.0; 4], &[2.0, 2.5], 1.0).starts_with("phi: axis 1"));
        assert!(e(vec![0.0; 5], &[2.0, 2.0], 1.0).starts_with("phi: holds 5 values"));
        assert!(e(vec![0.0, f64::NAN, 0.0, 0.0], &[2.0, 2.0], 1.0).starts_with("phi: value 1"));
        assert!(e(vec![0.0; 4], &[2.0, 2.0], 0.0).starts_with("spacing"));
        assert!(e(vec![0.0; 4], &[2.0, 2.0], -1.0).starts_with("spacing"));
        assert!(e(vec![0.0; 4], &[2.0, 2.0], 1e-320).starts_with("spacing"));
        assert!(e(vec![0.0; 6], &[3.0, 2.0], 1e308).starts_with("spacing: axis 0"));
        let p = Params::new().with("coupling", crate::terms::registry::Value::Text("spin".into()));
        assert!(Coupling::from_params(&p).err().unwrap().to_string().starts_with("coupling"));
    }
}
