//! The SPH force term: `Sph<V>`, the fluid (particles `first .. first + n` of a scene) and its
//! static walls, as a `Term` (forces, internal energy, density and pressure fields, time step
//! limit, buffer reservation), and its registration under the key "sph". One evaluation
//! (`Sph::eval`, written once for both pass precisions) builds the cell list, gathers into cell
//! order (`buffers`), then runs the density and force passes (`passes`).
use super::buffers::{BufSet, Bufs, PassFloat, Walls, PAD};
use super::params::{KernelKind, Precision, SphParams};
use super::passes;
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::neighbors::CellList;
use crate::par;
use crate::simd::{self, Level};
use crate::state::Model;
use crate::stop::Stop;
use crate::terms::registry::{Context, Params};
use crate::terms::{Term, Write};
use crate::vector::{Real, Vector};
use std::marker::PhantomData;
use std::ops::Range;
use std::sync::atomic::Ordering;

/// The SPH force term over particles `first .. first + n` of a scene.
pub struct Sph<V: Vector> {
    name: String,
    first: usize,
    n: usize,
    p: SphParams,
    grid: CellList,
    walls: Walls,
    bufs: BufSet,
    /// Largest |dv/dt| of the last evaluation (without uniform fields), m/s².
    amax: Real,
    /// Wall time spent so far in (cell list + gather, density pass, force pass), s.
    pub clock: [f64; 3],
    /// The stop flag of the call in progress: read between the phases of an evaluation and
    /// before every chunk of its passes (an evaluation at N = 10⁶ takes ~0.3 s).
    stop: Stop,
    /// Scratch: the forces of other terms, kept while the passes write the fluid's.
    prev: Vec<V>,
    _v: PhantomData<V>,
}

/// The registered builder: the fluid's particles `first..first + n` must already be in the
/// scene; parameters as in `SphParams` under the Python API's names.
fn build<V: Vector>(name: String, mut p: Params, ctx: &Context) -> Result<Box<dyn Term<V>>> {
    let (first, n) = (p.count("first", ctx.n_particles)?, p.count("n", ctx.n_particles)?);
    if first + n > ctx.n_particles {
        return Err(invalid(
            "n",
            format!("particles {first}..{} are not all in the scene ({})", first + n, ctx.n_particles),
        ));
    }
    let gamma = p.number("gamma")?;
    if gamma.fract() != 0.0 || gamma.abs() > 1e3 {
        return Err(invalid("gamma", format!("expected a whole number, got {gamma}")));
    }
    let params = SphParams {
        h: p.number("h")?,
        rho0: p.number("density")?,
        c0: p.number("sound_speed")?,
        gamma: gamma as i32,
        alpha: p.number("viscosity")?,
        clamp: p.flag("clamp_pressure")?,
        kernel: KernelKind::by_name(p.text("kernel")?)?,
        precision: Precision::by_name(p.text("precision")?)?,
    };
    let walls = p.take_vectors::<V>("walls")?;
    let psi = p.take_floats("wall_psi")?;
    Ok(Box::new(Sph::new(&name, first, n, params, walls, psi)?))
}
crate::register_term!("sph", build);

impl<V: Vector> Sph<V> {
    /// `walls`: static wall particle positions; `psi`: their Ψ_b = ρ0 V_b (kg), one each.
    pub fn new(name: &str, first: usize, n: usize, p: SphParams, walls: Vec<V>, psi: Vec<Real>) -> Result<Self> {
        p.validate()?;
        if walls.len() != psi.len() {
            return Err(invalid("wall_volume", format!("has {} entries, walls has {}", psi.len(), walls.len())));
        }
        if let Some(i) = walls.iter().position(|w| !w.is_finite()) {
            return Err(invalid("walls", format!("row {i} is not finite")));
        }
        if let Some(i) = psi.iter().position(|w| !(w.is_finite() && *w > 0.0)) {
            return Err(invalid("wall_volume", format!("entry {i} is {} (must be finite and > 0)", psi[i])));
        }
        let support = 2.0 * p.h;
        let (walls, bufs) = BufSet::with_walls(&walls, &psi, support)?;
        Ok(Self {
            name: name.to_string(),
            first,
            n,
            p,
            grid: CellList::new(support, V::DIM)?,
            walls,
            bufs,
            amax: 0.0,
            clock: [0.0; 3],
            stop: Stop::default(),
            prev: Vec::new(),
            _v: PhantomData,
        })
    }

    pub fn params(&self) -> &SphParams {
        &self.p
    }
    pub fn range(&self) -> Range<usize> {
        self.first..self.first + self.n
    }
    pub fn n_walls(&self) -> usize {
        self.walls.grid.len()
    }
    /// Heap bytes of the grid and pass buffers (memory-per-particle figures).
    pub fn bytes(&self) -> usize {
        self.grid.bytes() + self.bufs.bytes() + self.walls.grid.bytes()
    }

    /// Density (kg/m^dim) and pressure (Pa) of each fluid particle, in particle order, computed
    /// now in f64.
    pub fn fields(&self, x: &[V], model: &Model) -> (Vec<Real>, Vec<Real>) {
        let mut grid = CellList::new(self.grid.cell_size(), V::DIM).expect("valid cell size");
        let mut b =
            Bufs::<f64> { wpos: self.bufs.b64.wpos.clone(), wpsi: self.bufs.b64.wpsi.clone(), ..Bufs::default() };
        let xs = &x[self.range()];
        grid.build(xs);
        b.gather(&grid, xs, None, &model.mass[self.range()]);
        passes::density::<V, f64>(simd::level(), &self.p, &grid, &self.walls.grid, &mut b, Stop::default().flag());
        let mut rho = vec![0.0; self.n];
        let mut p = vec![0.0; self.n];
        for (k, &i) in grid.order.iter().enumerate() {
            rho[i as usize] = b.rho[k];
            p[i as usize] = self.p.pressure(b.rho[k]);
        }
        (rho, p)
    }

    /// `add_forces` at a given SIMD level.
    fn forces_at(&mut self, level: Level, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let r = self.range();
        // The viscosity's power is summed only if it dissipates.
        let want_power = Term::<V>::dissipative(self);
        let assign = write == Write::Overwrite;
        if assign {
            // Particles outside the fluid get no SPH force.
            let (head, rest) = f.split_at_mut(r.start);
            head.fill(V::ZERO);
            rest[r.len()..].fill(V::ZERO);
        }
        if self.n == 0 {
            return 0.0;
        }
        // The pass writes the fluid's forces over `f`; to add instead, keep what was there.
        let mut prev = std::mem::take(&mut self.prev);
        prev.clear();
        if !assign {
            prev.extend_from_slice(&f[r.clone()]);
        }
        let (xs, vs, ms, out) = (&x[r.clone()], &v[r.clone()], &model.mass[r.clone()], &mut f[r.clone()]);
        let (power, amax) = match self.p.precision {
            Precision::F32 => self.eval::<f32>(level, xs, vs, ms, out, want_power),
            Precision::F64 => self.eval::<f64>(level, xs, vs, ms, out, want_power),
        };
        self.amax = amax;
        if !assign {
            for (fi, pi) in f[r].iter_mut().zip(&prev) {
                *fi += *pi;
            }
        }
        self.prev = prev;
        power
    }

    /// One evaluation in precision `F`: build the cell list, gather, density pass, force pass.
    /// Returns (dissipated power W, max |a|²). Once the stop flag is set the rest is skipped and
    /// `out` is left partly written.
    fn eval<F: PassFloat>(
        &mut self,
        level: Level,
        x: &[V],
        v: &[V],
        m: &[Real],
        out: &mut [V],
        want_power: bool,
    ) -> (Real, Real) {
        let Self { p, grid, walls, bufs, clock, stop, .. } = self;
        let (walls, b, stop) = (&walls.grid, F::bufs(bufs), stop.flag());
        let stopped = || stop.load(Ordering::Relaxed);
        let t0 = std::time::Instant::now();
        grid.build(x);
        if stopped() {
            return (0.0, 0.0);
        }
        b.gather(grid, x, Some(v), m);
        let t1 = std::time::Instant::now();
        passes::density::<V, F>(level, p, grid, walls, b, stop);
        let t2 = std::time::Instant::now();
        clock[0] += (t1 - t0).as_secs_f64();
        clock[1] += (t2 - t1).as_secs_f64();
        if stopped() {
            return (0.0, 0.0);
        }
        let r = passes::forces::<V, F>(level, p, grid, walls, b, out, want_power, stop);
        clock[2] += t2.elapsed().as_secs_f64();
        r
    }
}

impl<V: Vector> Term<V> for Sph<V> {
    fn name(&self) -> &str {
        &self.name
    }

    fn add_forces(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        self.forces_at(simd::level(), x, v, model, f, write)
    }

    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        if self.n == 0 {
            return Some(0.0);
        }
        let (rho, _) = self.fields(x, model);
        let m = &model.mass[self.range()];
        Some(par::sum(self.n, 0.0, |r| r.map(|i| m[i] * self.p.internal_energy(rho[i])).sum::<Real>()))
    }

    fn dissipative(&self) -> bool {
        self.p.alpha > 0.0
    }

    fn fields(&self, x: &[V], model: &Model) -> Vec<(&'static str, Range<usize>, Vec<Real>)> {
        let (rho, p) = Sph::fields(self, x, model);
        vec![("density", self.range(), rho), ("pressure", self.range(), p)]
    }

    fn profile(&self) -> Option<([f64; 3], usize)> {
        Some((self.clock, self.bytes()))
    }

    fn set_stop(&mut self, stop: Stop) {
        self.stop = stop;
    }

    fn reserve(&mut self, _n_particles: usize) -> Result<()> {
        let n = self.n;
        let (f, arrays) = (
            match self.p.precision {
                Precision::F32 => 4,
                Precision::F64 => 8,
            },
            2 * V::DIM + 3,
        );
        let bytes = (arrays * (n + PAD) * f) as u128 + Need::bytes_of::<V>(n);
        let need = Need::new("step", bytes, format!("the SPH buffers of {} particles", count(n as u128)));
        need.check()?;
        match self.p.precision {
            Precision::F32 => self.bufs.b32.reserve::<V>(n, &need)?,
            Precision::F64 => self.bufs.b64.reserve::<V>(n, &need)?,
        }
        need.reserve(&mut self.prev, n)?;
        self.grid.reserve(n, "step")
    }

    fn min_particles(&self) -> usize {
        self.first + self.n
    }

    fn max_dt(&self, _x: &[V], v: &[V], _model: &Model, g: Real) -> Option<Real> {
        if self.n == 0 {
            return None;
        }
        let vs = &v[self.range()];
        let vmax = vs.iter().map(|u| u.length_squared()).fold(0.0, f64::max).sqrt();
        // CFL (Monaghan 1992, §5, with the viscous term) and force criterion.
        let cfl = 0.25 * self.p.h / (self.p.c0 * (1.0 + 0.6 * self.p.alpha) + vmax);
        let a = self.amax.sqrt() + g;
        let force = if a > 0.0 { 0.25 * (self.p.h / a).sqrt() } else { f64::INFINITY };
        Some(cfl.min(force))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sph::kernels::{CubicSpline, Kernel, WendlandC2};
    use glam::{DVec2, DVec3};
    use std::sync::atomic::AtomicBool;

    fn lcg(s: &mut u64) -> f64 {
        *s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*s >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A jittered lattice blob (moving) plus a floor of wall particles under it.
    fn blob<V: Vector>(n: usize, dx: f64, seed: u64) -> (Vec<V>, Vec<V>, Vec<V>) {
        let mut s = seed;
        let side = (n as f64).powf(1.0 / V::DIM as f64).ceil() as usize;
        let (mut x, mut v, mut w) = (vec![], vec![], vec![]);
        for k in 0..n {
            let mut c = [0.0; 3];
            let mut u = [0.0; 3];
            let mut idx = k;
            for d in 0..V::DIM {
                c[d] = ((idx % side) as f64 + 0.5 + 0.3 * (lcg(&mut s) - 0.5)) * dx;
                u[d] = lcg(&mut s) - 0.5;
                idx /= side;
            }
            x.push(V::from_slice(&c[..V::DIM]));
            v.push(V::from_slice(&u[..V::DIM]));
        }
        for k in 0..side * side {
            for layer in 0..3 {
                let mut c = [0.0; 3];
                c[0] = ((k % side) as f64 + 0.5) * dx;
                if V::DIM == 3 {
                    c[1] = ((k / side) as f64 + 0.5) * dx;
                } else if k >= side {
                    continue;
                }
                c[V::DIM - 1] = -(layer as f64 + 0.5) * dx;
                w.push(V::from_slice(&c[..V::DIM]));
            }
        }
        (x, v, w)
    }

    fn forces<V: Vector>(p: SphParams, x: &[V], v: &[V], w: &[V], m: f64, level: Level) -> (Vec<V>, f64) {
        let n = x.len();
        let model = Model { mass: vec![m; n], inv_mass: vec![1.0 / m; n], ..Default::default() };
        let mut t = Sph::new("fluid", 0, n, p, w.to_vec(), vec![m; w.len()]).unwrap();
        let mut f = vec![V::ZERO; n];
        let pw = t.forces_at(level, x, v, &model, &mut f, Write::Overwrite);
        (f, pw)
    }

    /// With the call's stop flag set an evaluation writes no fluid force; without it, it does.
    #[test]
    fn a_set_stop_flag_skips_the_evaluation() {
        let (x, v, w) = blob::<DVec2>(900, 0.1, 3);
        let n = x.len();
        let model = Model { mass: vec![10.0; n], inv_mass: vec![0.1; n], ..Default::default() };
        let p = SphParams {
            h: 0.13,
            rho0: 1000.0,
            c0: 20.0,
            gamma: 7,
            alpha: 0.1,
            clamp: true,
            kernel: KernelKind::CubicSpline,
            precision: Precision::F64,
        };
        let mut t = Sph::new("fluid", 0, n, p, w.clone(), vec![10.0; w.len()]).unwrap();
        for stopped in [true, false] {
            t.set_stop(Stop::new(Some(std::sync::Arc::new(AtomicBool::new(stopped)))));
            let sentinel = DVec2::splat(123.0);
            let mut f = vec![sentinel; n];
            t.forces_at(simd::level(), &x, &v, &model, &mut f, Write::Overwrite);
            let untouched = f.iter().filter(|&&fi| fi == sentinel).count();
            assert_eq!(untouched, if stopped { n } else { 0 }, "stop = {stopped}");
        }
    }

    /// The WCSPH forces and viscous power by brute force over all pairs, in f64, from the scalar
    /// kernel formulas: the oracle of the passes.
    fn brute<V: Vector, K: Kernel>(p: &SphParams, x: &[V], v: &[V], w: &[V], m: f64) -> (Vec<V>, f64) {
        let (n, d) = (x.len(), V::DIM);
        let sigma = K::sigma(p.h, d);
        let wk = |r2: f64| sigma * K::w(r2.sqrt() / p.h);
        let rho: Vec<f64> = (0..n)
            .map(|i| {
                (0..n).map(|j| m * wk((x[i] - x[j]).length_squared())).sum::<f64>()
                    + w.iter().map(|b| m * wk((x[i] - *b).length_squared())).sum::<f64>()
            })
            .collect();
        let pp: Vec<f64> = rho.iter().map(|&r| p.pressure(r) / (r * r)).collect();
        let grad = |r: V| r * (sigma / (p.h * p.h) * K::g(r.length_squared().sqrt() / p.h));
        let mut power = 0.0;
        let f = (0..n)
            .map(|i| {
                let mut a = V::ZERO;
                for j in 0..n {
                    let r = x[i] - x[j];
                    let vr = (v[i] - v[j]).dot(r);
                    let pi = 2.0 * p.alpha * p.c0 * p.h * (-vr).max(0.0)
                        / ((r.length_squared() + 0.01 * p.h * p.h) * (rho[i] + rho[j]));
                    a -= grad(r) * (m * (pp[i] + pp[j] + pi));
                    power += 0.5 * m * m * pi * grad(r).dot(v[i] - v[j]);
                }
                for b in w {
                    a -= grad(x[i] - *b) * (m * pp[i]);
                }
                a * m
            })
            .collect();
        (f, power)
    }

    fn check<V: Vector>() {
        let dx = 0.01;
        for kernel in [KernelKind::CubicSpline, KernelKind::WendlandC2] {
            // Compressed 5 % so that the pressure term is active everywhere.
            let p64 = SphParams {
                h: 1.3 * dx,
                rho0: 1000.0,
                c0: 20.0,
                gamma: 7,
                alpha: 0.1,
                clamp: true,
                kernel,
                precision: Precision::F64,
            };
            let (x, v, w) = blob::<V>(1500, dx * 0.95, 11);
            let m = 1000.0 * dx.powi(V::DIM as i32);
            let (fb, pb) = match kernel {
                KernelKind::CubicSpline => brute::<V, CubicSpline>(&p64, &x, &v, &w, m),
                KernelKind::WendlandC2 => brute::<V, WendlandC2>(&p64, &x, &v, &w, m),
            };
            let scale = fb.iter().map(|f| f.length_squared()).fold(0.0, f64::max).sqrt();
            assert!(scale > 0.0 && pb > 0.0);
            // f32: float32 positions (spacing ~1e-2, |x| ~ 0.2) and sums of ~30 terms.
            for (precision, tol) in [(Precision::F32, 2e-4), (Precision::F64, 1e-11)] {
                let p = SphParams { precision, ..p64 };
                for level in Level::available() {
                    let (fs, ps) = forces(p, &x, &v, &w, m, level);
                    let diff = fs.iter().zip(&fb).map(|(a, b)| (*a - *b).length_squared()).fold(0.0, f64::max).sqrt();
                    assert!(
                        diff <= tol * scale,
                        "{kernel:?} {precision:?} {}D {level:?}: vs brute force {diff:e} of {scale:e}",
                        V::DIM
                    );
                    assert!((ps - pb).abs() <= 10.0 * tol * pb, "{level:?} power {ps} vs {pb}");
                    // Without walls, the pair forces are antisymmetric: Σ f = 0 to round-off.
                    let (f0, _) = forces(p, &x, &v, &[], m, level);
                    let total = f0.iter().fold(V::ZERO, |a, b| a + *b);
                    let abs: f64 = f0.iter().map(|f| f.length_squared().sqrt()).sum();
                    assert!(
                        total.length_squared().sqrt() <= tol * abs,
                        "{kernel:?} {precision:?} {level:?}: net force {total:?} of {abs:e}"
                    );
                }
            }
        }
    }

    #[test]
    fn every_level_matches_brute_force_and_conserves_momentum() {
        check::<DVec2>();
        check::<DVec3>();
    }
}
