//! The SPH force term: `Sph<V>`, one fluid (particles `first .. first + n` of a scene, its
//! parameters and static walls) as a `Term` (forces, internal energy, density and pressure
//! fields, time step limit, buffer reservation), and its registration under the key "sph".
//!
//! A fluid is a member of a `Group` (`group`): alone in one by default, and when added to a
//! system that already has a fluid with the same support, kernel and precision
//! (`Term::share`), a member of that fluid's group, so the two push on each other. The group
//! evaluates; the term hands it the scene's arrays and keeps its own books.
use super::buffers::Walls;
use super::group::Group;
use super::params::{KernelKind, Precision, SphParams};
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::neighbors::Shared;
use crate::par;
use crate::simd::{self, Level};
use crate::state::Model;
use crate::stop::Stop;
use crate::terms::registry::{Context, Params};
use crate::terms::{BodyMotion, Diagnostics, MovingBoundary, Scratch, Setting, Term, Traits, Write};
use crate::vector::{Real, Vector};
use std::ops::Range;
use std::sync::{Arc, Mutex, MutexGuard};

/// The SPH force term over particles `first .. first + n` of a scene.
pub struct Sph<V: Vector> {
    name: String,
    first: usize,
    n: usize,
    p: SphParams,
    /// The group it evaluates in, and its index there.
    group: Arc<Mutex<Group<V>>>,
    who: usize,
    /// The stop flag of the call in progress: read between the phases of an evaluation and
    /// before every chunk of its passes (an evaluation at N = 10⁶ takes ~0.3 s).
    stop: Stop,
}

/// A fluid term's particles `first .. first + n` from its parameters, all in the scene (shared
/// by the "sph" and "dfsph" builders).
pub(super) fn particles(p: &Params, ctx: &Context) -> Result<(usize, usize)> {
    let (first, n) = (p.count("first", ctx.n_particles)?, p.count("n", ctx.n_particles)?);
    if first + n > ctx.n_particles {
        return Err(invalid(
            "n",
            format!("particles {first}..{} are not all in the scene ({})", first + n, ctx.n_particles),
        ));
    }
    Ok((first, n))
}

/// The registered builder: the fluid's particles `first..first + n` must already be in the
/// scene; parameters as in `SphParams` under the Python API's names.
fn build<V: Vector>(name: String, mut p: Params, ctx: &Context) -> Result<Box<dyn Term<V>>> {
    let (first, n) = particles(&p, ctx)?;
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
        let walls = Walls::checked(&walls, &psi, 2.0 * p.h)?;
        let group = Group::new(first..first + n, p, walls)?;
        Ok(Self {
            name: name.to_string(),
            first,
            n,
            p,
            group: Arc::new(Mutex::new(group)),
            who: 0,
            stop: Stop::default(),
        })
    }

    pub fn params(&self) -> &SphParams {
        &self.p
    }
    pub fn range(&self) -> Range<usize> {
        self.first..self.first + self.n
    }
    pub fn n_walls(&self) -> usize {
        self.group().members[self.who].walls.grid.len()
    }
    /// How many fluids evaluate together with this one, itself included.
    pub fn group_size(&self) -> usize {
        self.group().members.len()
    }

    /// The group (a poisoned lock only means a panic elsewhere; the group holds no invariant a
    /// panic can break between evaluations).
    fn group(&self) -> MutexGuard<'_, Group<V>> {
        self.group.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Density (kg/m^dim) and pressure (Pa) of each particle of this fluid, in particle order,
    /// computed now in f64 (with the other fluids of its group in the sums).
    pub fn fields(&self, x: &[V], model: &Model) -> (Vec<Real>, Vec<Real>) {
        let g = self.group();
        let all = g.densities(x, &model.mass);
        let rho = g.share_of(self.who, &all).to_vec();
        let p = rho.iter().map(|&r| self.p.pressure(r)).collect();
        (rho, p)
    }

    /// `add_forces` at a given SIMD level.
    fn forces_at(&mut self, level: Level, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let r = self.range();
        if write == Write::Overwrite {
            // Particles outside the fluid get no SPH force.
            let (head, rest) = f.split_at_mut(r.start);
            head.fill(V::ZERO);
            rest[r.len()..].fill(V::ZERO);
        }
        let mut g = self.group.lock().unwrap_or_else(|e| e.into_inner());
        if g.len() == 0 {
            return 0.0;
        }
        g.forces(self.who, level, x, v, &model.mass, f, write, &self.stop);
        g.sums.power[self.who]
    }
}

impl<V: Vector> Term<V> for Sph<V> {
    fn name(&self) -> &str {
        &self.name
    }

    /// Its pairs with another fluid of the group dissipate if either fluid is viscous.
    fn traits(&self) -> Traits<V> {
        Traits {
            cheap_potential: false,
            min_particles: self.first + self.n,
            ..Traits::dissipating(self.group().dissipative())
        }
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

    fn fields(&self, x: &[V], model: &Model) -> Vec<(&'static str, Range<usize>, Vec<Real>)> {
        let (rho, p) = Sph::fields(self, x, model);
        vec![("density", self.range(), rho), ("pressure", self.range(), p)]
    }

    /// The group's clock and buffers are booked once, by its first fluid.
    fn diagnostics(&self) -> Diagnostics {
        let g = self.group();
        let profile = Some(if self.who == 0 { (g.clock, g.bytes()) } else { ([0.0; 3], 0) });
        Diagnostics { profile, ..Diagnostics::default() }
    }

    fn set(&mut self, setting: Setting) {
        if let Setting::Stop(stop) = setting {
            self.stop = stop;
        }
    }

    fn join(&mut self, shared: &mut Shared) -> Result<()> {
        let key = Group::<V>::key(&self.p);
        if let Some(other) = shared.find::<Mutex<Group<V>>>(&key) {
            if Arc::ptr_eq(&other, &self.group) {
                return Ok(());
            }
            let mut g = other.lock().unwrap_or_else(|e| e.into_inner());
            if g.admits(&self.range()) {
                // Move this fluid (alone in its group until now) into the other group.
                let mine = std::mem::replace(&mut self.group, other.clone());
                match Arc::try_unwrap(mine) {
                    Ok(m) => self.who = g.join(m.into_inner().unwrap_or_else(|e| e.into_inner()).into_member()),
                    Err(mine) => self.group = mine, // shared already (not before it is added): stay alone
                }
                return Ok(());
            }
            if !g.full() {
                // Its particles overlap a member's: it stays alone, and the group stays registered.
                return Ok(());
            }
        }
        shared.register(key, self.group.clone());
        Ok(())
    }

    /// For the books: their densities are computed afresh by `potential` (the group's points
    /// copied and sorted into a new cell list, a density pass, copies out: under 256 bytes a
    /// particle), which cannot report a refused allocation: check that much room is there.
    fn reserve(&mut self, n: usize, scratch: Scratch) -> Result<()> {
        match scratch {
            Scratch::Step => self.group().reserve(),
            Scratch::Potential => {
                let bytes = 256 * n as u128;
                Need::new("energy", bytes, format!("the SPH densities of {} particles", count(n as u128))).room(bytes)
            }
        }
    }

    /// The group's first fluid takes the bodies' boundary for all its fluids.
    fn as_moving_boundary(&mut self) -> Option<&mut dyn MovingBoundary<V>> {
        if self.who == 0 {
            Some(self)
        } else {
            None
        }
    }

    fn max_dt(&self, _x: &[V], v: &[V], _model: &Model, g: Real) -> Option<Real> {
        if self.n == 0 {
            return None;
        }
        let vs = &v[self.range()];
        let vmax = vs.iter().map(|u| u.length_squared()).fold(0.0, f64::max).sqrt();
        // CFL (Monaghan 1992, §5, with the viscous term) and force criterion.
        let cfl = super::resolve::wcsph_cfl(self.p.h, self.p.c0, self.p.alpha, vmax);
        let a = self.group().sums.amax[self.who].sqrt() + g;
        let force = if a > 0.0 { 0.25 * (self.p.h / a).sqrt() } else { f64::INFINITY };
        Some(cfl.min(force))
    }
}

impl<V: Vector> MovingBoundary<V> for Sph<V> {
    fn boundary_sampling(&self, model: &Model) -> (Real, Real, KernelKind, Real) {
        let g = self.group();
        let spacing =
            super::buffers::spacing(&model.mass, g.members.iter().map(|m| m.range.clone()), self.p.rho0, V::DIM);
        (self.p.h, self.p.rho0, self.p.kernel, spacing)
    }

    fn set_boundary(&mut self, x: &[V], psi: &[Real], body: &[u32], offset: &[V], bodies: &[BodyMotion<V>]) {
        self.group().set_boundary(x, psi, body, offset, bodies);
    }

    fn boundary_impulses(&self, dt: Real, out: &mut Vec<(V, [Real; 3])>) {
        self.group().boundary_impulses(dt, out);
    }

    fn books_exchange(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sph::kernels::{CubicSpline, Kernel, WendlandC2};
    use crate::sph::passes::MAX_FLUIDS;
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
            t.set(Setting::Stop(Stop::new(Some(std::sync::Arc::new(AtomicBool::new(stopped))))));
            let sentinel = DVec2::splat(123.0);
            let mut f = vec![sentinel; n];
            t.forces_at(simd::level(), &x, &v, &model, &mut f, Write::Overwrite);
            let untouched = f.iter().filter(|&&fi| fi == sentinel).count();
            assert_eq!(untouched, if stopped { n } else { 0 }, "stop = {stopped}");
        }
    }

    /// The WCSPH forces and viscous power by brute force over all pairs, in f64, from the scalar
    /// kernel formulas: the oracle of the passes. Particle i belongs to fluid `fl[i]` (parameters
    /// `ps[fl[i]]`, walls `ws[fl[i]]` of Ψ = `psi[fl[i]]`) and has mass `m[i]`; a pair's viscosity
    /// coefficient is the mean of its fluids' α c0.
    #[allow(clippy::too_many_arguments)]
    fn brute_several<V: Vector, K: Kernel>(
        ps: &[SphParams],
        fl: &[usize],
        x: &[V],
        v: &[V],
        m: &[f64],
        ws: &[Vec<V>],
        psi: &[f64],
    ) -> (Vec<V>, f64) {
        let (n, d, h) = (x.len(), V::DIM, ps[0].h);
        let sigma = K::sigma(h, d);
        let wk = |r2: f64| sigma * K::w(r2.sqrt() / h);
        let rho: Vec<f64> = (0..n)
            .map(|i| {
                (0..n).map(|j| m[j] * wk((x[i] - x[j]).length_squared())).sum::<f64>()
                    + ws[fl[i]].iter().map(|b| psi[fl[i]] * wk((x[i] - *b).length_squared())).sum::<f64>()
            })
            .collect();
        let pp: Vec<f64> = (0..n).map(|i| ps[fl[i]].pressure(rho[i]) / (rho[i] * rho[i])).collect();
        let ac: Vec<f64> = (0..n).map(|i| ps[fl[i]].alpha * ps[fl[i]].c0).collect();
        let grad = |r: V| r * (sigma / (h * h) * K::g(r.length_squared().sqrt() / h));
        let mut power = 0.0;
        let f = (0..n)
            .map(|i| {
                let mut a = V::ZERO;
                for j in 0..n {
                    let r = x[i] - x[j];
                    let vr = (v[i] - v[j]).dot(r);
                    let pi = (ac[i] + ac[j]) * h * (-vr).max(0.0)
                        / ((r.length_squared() + 0.01 * h * h) * (rho[i] + rho[j]));
                    a -= grad(r) * (m[j] * (pp[i] + pp[j] + pi));
                    power += 0.5 * m[i] * m[j] * pi * grad(r).dot(v[i] - v[j]);
                }
                for b in &ws[fl[i]] {
                    a -= grad(x[i] - *b) * (psi[fl[i]] * pp[i]);
                }
                a * m[i]
            })
            .collect();
        (f, power)
    }

    fn brute<V: Vector, K: Kernel>(p: &SphParams, x: &[V], v: &[V], w: &[V], m: f64) -> (Vec<V>, f64) {
        let n = x.len();
        brute_several::<V, K>(&[*p], &vec![0; n], x, v, &vec![m; n], &[w.to_vec()], &[m])
    }

    /// Fluids over consecutive ranges of `x` (`cuts`: their sizes), with parameters `ps`, walls
    /// `ws` (Ψ = `psi`), joined into one group as a system joins them; forces as the system
    /// evaluates them (in order, adding), and the total power.
    #[allow(clippy::too_many_arguments)]
    fn forces_several<V: Vector>(
        ps: &[SphParams],
        cuts: &[usize],
        x: &[V],
        v: &[V],
        m: &[f64],
        ws: &[Vec<V>],
        psi: &[f64],
        level: Level,
    ) -> (Vec<V>, f64, usize) {
        let n = x.len();
        let model = Model { mass: m.to_vec(), inv_mass: m.iter().map(|m| 1.0 / m).collect(), ..Default::default() };
        let mut shared = Shared::default();
        let mut terms = Vec::new();
        let mut first = 0;
        for (k, &c) in cuts.iter().enumerate() {
            let mut t = Sph::new(&format!("f{k}"), first, c, ps[k], ws[k].clone(), vec![psi[k]; ws[k].len()]).unwrap();
            t.join(&mut shared).unwrap();
            t.reserve(n, Scratch::Step).unwrap();
            terms.push(t);
            first += c;
        }
        let mut f = vec![V::from_slice(&[7.0; 3][..V::DIM]); n];
        let mut power = 0.0;
        for (k, t) in terms.iter_mut().enumerate() {
            let write = if k == 0 { Write::Overwrite } else { Write::Add };
            power += t.forces_at(level, x, v, &model, &mut f, write);
        }
        (f, power, terms[0].group_size())
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

    fn params(kernel: KernelKind, precision: Precision, h: f64) -> SphParams {
        SphParams { h, rho0: 1000.0, c0: 20.0, gamma: 7, alpha: 0.1, clamp: true, kernel, precision }
    }

    /// Two fluids of different rest density, sound speed, viscosity, γ, clamp and masses, each
    /// with its own walls, joined into one group: at every level the forces and power match the
    /// brute-force oracle of interacting fluids, and without walls the net force is zero.
    fn check_several<V: Vector>() {
        let dx = 0.01;
        let (x, v, w) = blob::<V>(1200, dx * 0.95, 5);
        let n = x.len();
        let cut = n / 3;
        let ma = 1000.0 * dx.powi(V::DIM as i32);
        let m: Vec<f64> = (0..n).map(|i| if i < cut { ma } else { 0.6 * ma }).collect();
        let half: Vec<V> = w.iter().copied().step_by(2).collect();
        let walls = [w.clone(), half];
        let psi = [ma, 0.6 * ma];
        for kernel in [KernelKind::CubicSpline, KernelKind::WendlandC2] {
            let a = params(kernel, Precision::F64, 1.3 * dx);
            let b = SphParams { rho0: 600.0, c0: 15.0, gamma: 3, alpha: 0.3, clamp: false, ..a };
            let fl: Vec<usize> = (0..n).map(|i| usize::from(i >= cut)).collect();
            let (fb, pb) = match kernel {
                KernelKind::CubicSpline => brute_several::<V, CubicSpline>(&[a, b], &fl, &x, &v, &m, &walls, &psi),
                KernelKind::WendlandC2 => brute_several::<V, WendlandC2>(&[a, b], &fl, &x, &v, &m, &walls, &psi),
            };
            let scale = fb.iter().map(|f| f.length_squared()).fold(0.0, f64::max).sqrt();
            assert!(scale > 0.0 && pb > 0.0);
            for (precision, tol) in [(Precision::F32, 2e-4), (Precision::F64, 1e-11)] {
                let ps = [SphParams { precision, ..a }, SphParams { precision, ..b }];
                for level in Level::available() {
                    let (fs, p, size) = forces_several(&ps, &[cut, n - cut], &x, &v, &m, &walls, &psi, level);
                    assert_eq!(size, 2, "the fluids joined one group");
                    let diff = fs.iter().zip(&fb).map(|(a, b)| (*a - *b).length_squared()).fold(0.0, f64::max).sqrt();
                    assert!(
                        diff <= tol * scale,
                        "{kernel:?} {precision:?} {}D {level:?}: {diff:e} of {scale:e}",
                        V::DIM
                    );
                    assert!((p - pb).abs() <= 10.0 * tol * pb, "{level:?} power {p} vs {pb}");
                    let none = [vec![], vec![]];
                    let (f0, _, _) = forces_several(&ps, &[cut, n - cut], &x, &v, &m, &none, &psi, level);
                    let total = f0.iter().fold(V::ZERO, |a, b| a + *b);
                    let abs: f64 = f0.iter().map(|f| f.length_squared().sqrt()).sum();
                    assert!(total.length_squared().sqrt() <= tol * abs, "{level:?}: net force {total:?} of {abs:e}");
                    // Fluid b alone, for contrast: its forces change when a is there (they interact).
                    let alone = forces_several(
                        &ps[1..],
                        &[n - cut],
                        &x[cut..],
                        &v[cut..],
                        &m[cut..],
                        &walls[1..],
                        &psi[1..],
                        level,
                    )
                    .0;
                    let changed = alone.iter().zip(&fs[cut..]).filter(|(p, q)| p != q).count();
                    assert!(changed > (n - cut) / 10, "{level:?}: only {changed} forces of b changed");
                }
            }
        }
    }

    #[test]
    fn several_fluids_match_brute_force_and_conserve_momentum_at_every_level() {
        check_several::<DVec2>();
        check_several::<DVec3>();
    }

    /// One fluid split into three identical fluids (same parameters and walls) gives the same
    /// bits as the one fluid, at every level and in both precisions: the several-fluid path is
    /// the one-fluid path when the fluids agree.
    #[test]
    fn one_fluid_split_in_three_gives_the_same_bits() {
        let dx = 0.01;
        let (x, v, w) = blob::<DVec2>(2000, dx * 0.95, 9);
        let n = x.len();
        let m = vec![0.1; n];
        for precision in [Precision::F32, Precision::F64] {
            let p = params(KernelKind::WendlandC2, precision, 1.3 * dx);
            for level in Level::available() {
                let (one, p1, s1) = forces_several(&[p], &[n], &x, &v, &m, std::slice::from_ref(&w), &[0.1], level);
                let cuts = [700, 1, n - 701];
                let (three, p3, s3) =
                    forces_several(&[p; 3], &cuts, &x, &v, &m, &[w.clone(), w.clone(), w.clone()], &[0.1; 3], level);
                assert_eq!((s1, s3), (1, 3));
                assert!(one == three, "{precision:?} {level:?}: forces differ");
                assert!((p1 - p3).abs() <= 1e-12 * p1, "{precision:?} {level:?}: power {p1} vs {p3}");
            }
        }
    }

    /// Fluids join only where they can share passes: another smoothing length, kernel or
    /// precision, or overlapping particles, make a group of their own.
    #[test]
    fn fluids_join_only_compatible_groups() {
        let p = params(KernelKind::CubicSpline, Precision::F64, 0.1);
        let mut shared = Shared::default();
        let mut make = |first: usize, n: usize, p: SphParams| {
            let mut t = Sph::<DVec2>::new("f", first, n, p, vec![], vec![]).unwrap();
            t.join(&mut shared).unwrap();
            t
        };
        let a = make(0, 10, p);
        let b = make(10, 10, SphParams { rho0: 500.0, alpha: 0.0, ..p });
        assert_eq!((a.group_size(), b.group_size()), (2, 2));
        assert!(Term::<DVec2>::traits(&b).dissipative, "pairs with the viscous fluid dissipate");
        for other in [
            SphParams { h: 0.11, ..p },
            SphParams { kernel: KernelKind::WendlandC2, ..p },
            SphParams { precision: Precision::F32, ..p },
        ] {
            assert_eq!(make(100, 5, other).group_size(), 1, "{other:?}");
        }
        assert_eq!(make(15, 10, p).group_size(), 1, "overlaps b");
        assert_eq!(a.group_size(), 2);
        for k in 0..MAX_FLUIDS - 2 {
            assert_eq!(make(200 + 10 * k, 10, p).group_size(), 3 + k);
        }
        assert_eq!(make(500, 10, p).group_size(), 1, "the group is full: a new one starts");
        assert_eq!(make(600, 10, p).group_size(), 2, "and later fluids join the new one");
    }
}
