//! Electric and magnetic fields given as vectors on a regular grid (a field map), sampled at each
//! particle by multilinear interpolation: bilinear in 2D, trilinear in 3D, as nested linear
//! interpolations a + f (b − a) along x, then y, then z, so a uniform field is reproduced
//! exactly and a linear one to round-off. Outside the grid's box (beyond its first or last node
//! on any axis) the field is zero: a field map describes a region, and nothing is assumed about
//! the space around it.
//!
//! Parameters: `origin` (m, the node with index 0), `spacing` (m per axis, > 0), `shape`
//! (nodes per axis, ≥ 2 each) and `values`, the field at the nodes as a C-order array of shape
//! (nx, ny[, nz], components) flattened: E has the scene's dimension of components; B has 3 in
//! 3D and 1 in 2D (B_z, out of the plane).
//!
//! `grid_electric_field`: F = q E(x) on free particles. The field is not assumed to have a
//! potential (it need not be curl-free), so the term holds none, and its work is in no energy
//! book. `grid_magnetic_field`: F = q v × B(x), handed to the Boris integrator as a field like
//! `uniform_magnetic_field`. q is the `charge` attribute (C); without it neither acts.
use super::magnetic_field::{gyration_time, lorentz_forces};
use super::registry::{Context, Params};
use super::{Magnetic, Term, Traits, Write};
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::vector::{Real, Vector};

/// Values on a regular grid of nodes, sampled by multilinear interpolation (zero outside).
#[derive(Debug, Clone, PartialEq)]
pub struct GridSampler {
    origin: [Real; 3],
    spacing: [Real; 3],
    /// The last node, origin + (shape − 1) spacing: the box [origin, far] is the grid's.
    far: [Real; 3],
    /// Nodes per axis; 1 along z in 2D.
    shape: [usize; 3],
    /// Components per node (at most 3).
    comps: usize,
    /// Node values, C order (x slowest, the components fastest).
    values: Vec<Real>,
}

impl GridSampler {
    /// Reads and checks `origin`, `spacing`, `shape` and `values` (`comps` per node) of a grid
    /// in `dim` dimensions, naming the parameter at fault.
    pub fn from_params(p: &mut Params, dim: usize, comps: usize) -> Result<Self> {
        let axes = |key: &str, p: &mut Params| -> Result<Vec<Real>> {
            let v = p.take_floats(key)?;
            if v.len() != dim {
                return Err(invalid(key, format!("expected {dim} numbers (one per axis), got {}", v.len())));
            }
            Ok(v)
        };
        let origin = axes("origin", p)?;
        if origin.iter().any(|o| !o.is_finite()) {
            return Err(invalid("origin", format!("must be finite, got {origin:?}")));
        }
        let spacing = axes("spacing", p)?;
        if spacing.iter().any(|h| !(h.is_finite() && *h > 0.0)) {
            return Err(invalid("spacing", format!("must be finite and > 0 on every axis, got {spacing:?}")));
        }
        let shape = axes("shape", p)?;
        if shape.iter().any(|n| !(n.fract() == 0.0 && *n >= 2.0 && *n <= 1e15)) {
            return Err(invalid("shape", format!("expected whole numbers >= 2 (nodes per axis), got {shape:?}")));
        }
        let values = p.take_floats("values")?;
        let nodes = shape.iter().try_fold(1usize, |a, &n| a.checked_mul(n as usize));
        if nodes.and_then(|n| n.checked_mul(comps)) != Some(values.len()) {
            let want = shape.iter().product::<Real>() * comps as Real;
            return Err(invalid(
                "values",
                format!(
                    "has {} numbers, a grid of shape {shape:?} with {comps} components per node needs {want}",
                    values.len()
                ),
            ));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(invalid("values", format!("entry {i} (flat index) is {} (must be finite)", values[i])));
        }
        // The grid's far corner origin + (n − 1) spacing must be finite too.
        if (0..dim).any(|a| !(origin[a] + (shape[a] - 1.0) * spacing[a]).is_finite()) {
            return Err(invalid("spacing", "the grid's far corner origin + (shape − 1)·spacing overflows float64"));
        }
        let mut s = Self { origin: [0.0; 3], spacing: [1.0; 3], far: [0.0; 3], shape: [1; 3], comps, values };
        for a in 0..dim {
            s.origin[a] = origin[a];
            s.spacing[a] = spacing[a];
            s.far[a] = origin[a] + (shape[a] - 1.0) * spacing[a];
            s.shape[a] = shape[a] as usize;
        }
        Ok(s)
    }

    /// The field at `p` (its first `comps` entries; zero outside the grid).
    #[inline]
    pub fn sample<V: Vector>(&self, p: V) -> [Real; 3] {
        let mut base = 0;
        let mut frac = [0.0; 3];
        let mut stride = [0usize; 3];
        // Strides in nodes: z fastest.
        let (ny, nz) = (self.shape[1], self.shape[2]);
        let node_stride = [ny * nz, nz, 1];
        for a in 0..V::DIM {
            let x = p.comp(a);
            // `!(..)` also sends NaN outside.
            if !(x >= self.origin[a] && x <= self.far[a]) {
                return [0.0; 3];
            }
            let u = ((x - self.origin[a]) / self.spacing[a]).min((self.shape[a] - 1) as Real);
            let i = (u.floor() as usize).min(self.shape[a] - 2);
            frac[a] = u - i as Real;
            base += i * node_stride[a];
            stride[a] = node_stride[a];
        }
        let mut out = [0.0; 3];
        let c = self.comps;
        for (k, o) in out.iter_mut().enumerate().take(c) {
            // The 2^DIM corners, bit a of the corner index = +1 along axis a.
            let mut v = [0.0; 8];
            for (corner, vc) in v.iter_mut().enumerate().take(1 << V::DIM) {
                let mut node = base;
                for (a, s) in stride.iter().enumerate().take(V::DIM) {
                    node += ((corner >> a) & 1) * s;
                }
                *vc = self.values[node * c + k];
            }
            // Along x, then y, then z: each pass halves the corners.
            let mut m = 1 << V::DIM;
            for f in frac.iter().take(V::DIM) {
                m /= 2;
                for j in 0..m {
                    v[j] = v[2 * j] + f * (v[2 * j + 1] - v[2 * j]);
                }
            }
            *o = v[0];
        }
        out
    }

    /// The largest magnitude of the node values (the field can be no larger anywhere).
    fn max_norm(&self) -> Real {
        self.values.chunks_exact(self.comps).map(|v| v.iter().map(|c| c * c).sum::<Real>().sqrt()).fold(0.0, Real::max)
    }
}

/// E(x) given on a grid: F = q E(x) (see the module docs).
pub struct GridElectricField {
    pub name: String,
    pub grid: GridSampler,
}

/// B(x) given on a grid: F = q v × B(x) (see the module docs).
pub struct GridMagneticField {
    pub name: String,
    pub grid: GridSampler,
}

fn build_electric<V: Vector>(name: String, mut p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    Ok(Box::new(GridElectricField { name, grid: GridSampler::from_params(&mut p, V::DIM, V::DIM)? }))
}
crate::register_term!("grid_electric_field", build_electric);

fn build_magnetic<V: Vector>(name: String, mut p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    Ok(Box::new(GridMagneticField { name, grid: GridSampler::from_params(&mut p, V::DIM, V::AXIAL_DIM)? }))
}
crate::register_term!("grid_magnetic_field", build_magnetic);

impl<V: Vector> Term<V> for GridElectricField {
    fn name(&self) -> &str {
        &self.name
    }
    fn add_forces(&mut self, x: &[V], _v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let q = model.attribute("charge");
        let grid = &self.grid;
        par::chunks1(f, |s, f| {
            for (k, fi) in f.iter_mut().enumerate() {
                let i = s + k;
                let fe = match q {
                    Some(q) if model.inv_mass[i] != 0.0 && q[i] != 0.0 => {
                        V::from_slice(&grid.sample(x[i])[..V::DIM]) * q[i]
                    }
                    _ => V::ZERO,
                };
                write.put(fi, fe);
            }
        });
        0.0
    }
    fn potential(&self, _x: &[V], _model: &Model) -> Option<Real> {
        None // a field given by its vectors need not have one
    }
    fn traits(&self) -> Traits<V> {
        Traits::conservative()
    }
}

impl<V: Vector> Term<V> for GridMagneticField {
    fn name(&self) -> &str {
        &self.name
    }
    fn add_forces(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let grid = &self.grid;
        lorentz_forces(v, model, f, write, |i| V::axial_from_slice(&grid.sample(x[i])));
        0.0
    }
    fn potential(&self, _x: &[V], _model: &Model) -> Option<Real> {
        None
    }
    /// The magnetic force depends on the velocities, though it does no work.
    fn traits(&self) -> Traits<V> {
        Traits { velocity_dependent: true, ..Traits::conservative() }
    }
    fn time_scale(&self, _x: &[V], model: &Model) -> Option<Real> {
        gyration_time(model, self.grid.max_norm())
    }
    fn as_magnetic(&self) -> Option<&dyn Magnetic<V>> {
        Some(self)
    }
}

impl<V: Vector> Magnetic<V> for GridMagneticField {
    fn add_field(&self, x: &[V], _model: &Model, b: &mut [V::Axial]) {
        let grid = &self.grid;
        par::chunks1(b, |s, b| {
            for (k, bi) in b.iter_mut().enumerate() {
                *bi = *bi + V::axial_from_slice(&grid.sample(x[s + k]));
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::super::registry::Value;
    use super::*;
    use glam::{DVec2, DVec3};

    fn params(origin: &[f64], spacing: &[f64], shape: &[usize], values: Vec<f64>) -> Params {
        Params::new()
            .with("origin", Value::Floats(origin.to_vec()))
            .with("spacing", Value::Floats(spacing.to_vec()))
            .with("shape", Value::Floats(shape.iter().map(|&n| n as f64).collect()))
            .with("values", Value::Floats(values))
    }

    /// A linear field E(x) = A x + c on a 3D grid: trilinear interpolation reproduces it to
    /// round-off inside, and it is zero outside.
    #[test]
    fn a_linear_field_is_reproduced_inside_and_zero_outside() {
        let (o, h, n) = ([-1.0, 0.5, 2.0], [0.25, 0.5, 0.125], [5usize, 4, 6]);
        let a = [[1.0, -2.0, 0.5], [0.25, 3.0, -1.0], [2.0, 0.0, 1.5]];
        let c = [0.3, -0.7, 1.1];
        let e =
            |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|r| c[r] + (0..3).map(|k| a[r][k] * p[k]).sum::<f64>()) };
        let mut values = Vec::new();
        for i in 0..n[0] {
            for j in 0..n[1] {
                for k in 0..n[2] {
                    values.extend(e([o[0] + i as f64 * h[0], o[1] + j as f64 * h[1], o[2] + k as f64 * h[2]]));
                }
            }
        }
        let g = GridSampler::from_params(&mut params(&o, &h, &n, values), 3, 3).unwrap();
        let far = [o[0] + 4.0 * h[0], o[1] + 3.0 * h[1], o[2] + 5.0 * h[2]];
        for t in 0..=200 {
            let s = t as f64 / 200.0;
            let p = [
                o[0] + s * (far[0] - o[0]),
                o[1] + (1.0 - s) * (far[1] - o[1]),
                o[2] + (s * 7.0).fract() * (far[2] - o[2]),
            ];
            let got = g.sample(DVec3::from_array(p));
            let want = e(p);
            for r in 0..3 {
                assert!((got[r] - want[r]).abs() <= 1e-14 * 10.0, "{p:?}: {got:?} vs {want:?}");
            }
        }
        // The corners are nodes: exact.
        assert_eq!(g.sample(DVec3::from_array(o)), e(o));
        for p in [[o[0] - 1e-9, 1.0, 2.2], [far[0] + 1e-9, 1.0, 2.2], [0.0, 1.0, far[2] + 1e-12], [f64::NAN, 1.0, 2.2]]
        {
            assert_eq!(g.sample(DVec3::from_array(p)), [0.0; 3], "{p:?}");
        }
    }

    #[test]
    fn a_uniform_field_is_reproduced_exactly_in_2d() {
        let values: Vec<f64> = (0..3 * 4).flat_map(|_| [0.1, -7.3]).collect();
        let g = GridSampler::from_params(&mut params(&[0.0, 0.0], &[0.3, 0.7], &[3, 4], values), 2, 2).unwrap();
        for t in 0..100 {
            let p = DVec2::new(2.0 * 0.3 * (t as f64 / 99.0), 3.0 * 0.7 * ((t * 37 % 100) as f64 / 99.0));
            assert_eq!(g.sample(p), [0.1, -7.3, 0.0], "{p}");
        }
    }

    #[test]
    fn bad_grids_are_refused_by_name() {
        let ok = || params(&[0.0, 0.0], &[1.0, 1.0], &[2, 3], vec![0.0; 6]);
        assert!(GridSampler::from_params(&mut ok(), 2, 1).is_ok());
        let cases: Vec<(Params, &str)> = vec![
            (ok().with("origin", Value::Floats(vec![0.0])), "origin: expected 2 numbers"),
            (ok().with("origin", Value::Floats(vec![0.0, f64::NAN])), "origin: must be finite"),
            (ok().with("spacing", Value::Floats(vec![1.0, 0.0])), "spacing: must be finite and > 0"),
            (ok().with("spacing", Value::Floats(vec![-1.0, 1.0])), "spacing: must be finite and > 0"),
            (ok().with("shape", Value::Floats(vec![1.0, 3.0])), "shape: expected whole numbers >= 2"),
            (ok().with("shape", Value::Floats(vec![2.5, 3.0])), "shape: expected whole numbers >= 2"),
            (ok().with("values", Value::Floats(vec![0.0; 5])), "values: has 5 numbers"),
            (ok().with("values", Value::Floats(vec![0.0, 1.0, f64::INFINITY, 0.0, 0.0, 0.0])), "values: entry 2"),
            (
                ok().with("spacing", Value::Floats(vec![1e308, 1.0])).with("origin", Value::Floats(vec![1e308, 0.0])),
                "spacing: the grid's far corner",
            ),
        ];
        for (mut p, want) in cases {
            let e = GridSampler::from_params(&mut p, 2, 1).unwrap_err().to_string();
            assert!(e.starts_with(want), "{e} (wanted {want})");
        }
    }
}
