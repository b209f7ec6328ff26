//! Gray–Scott reaction–diffusion (Turing patterns): two species u, v on a grid,
//!
//! ```text
//!   u_t = D_u ∇²u − u v² + F (1 − u),     v_t = D_v ∇²v + u v² − (F + k) v
//! ```
//! (Pearson, "Complex patterns in a simple system", Science 261 (1993) 189–192, eq. 1–2),
//! stepped by forward Euler with the 5-point (7-point in 3D) Laplacian, the scheme Pearson used.
//! Explicit diffusion is stable for dt ≤ dx²/(2·dim·D) (dx²/(4D) in 2D). The reactions bound the
//! step too: `auto_dt` keeps `cfl` (default 0.8) of `stability_limit`, which includes both (see
//! there). The diffusion limit alone grows as dx² and, on coarse grids (16–64 cells a side at
//! Pearson's domain), stepped straight over the reactions' time scale (~1) and diverged. An
//! implicit or spectral step was not added: at Pearson's parameters the two limits are of the
//! same order as the step the reactions' accuracy asks for (~1), so it would buy little.
//!
//! **Books** (`System::books`): the amounts Σu dA and Σv dA and what the reactions made of each
//! so far (dt Σ (−uv² + F(1 − u)) dA per step for u, dt Σ (uv² − (F + k)v) dA for v). Diffusion
//! moves, never makes: with periodic or free (no-flux) edges Σ ∇²u = 0, so amount − made stays
//! at its start value to round-off. Fixed edges (u = 0 on the face) would leak, so they are
//! refused.
use super::{first_non_finite, rows2_each, Edge, Grid};
use crate::alloc::{count, Need};
use crate::error::{invalid, Failure, Result};
use crate::simd::{self, Kernel, Simd, P};
use crate::systems::{array, Arrays, EnergyReport, Halt, Snapshot, System};
use crate::vector::Real;
use std::sync::atomic::AtomicBool;

mod fused;

/// Everything that defines a Gray–Scott system.
#[derive(Clone, Debug, PartialEq)]
pub struct GrayScottConfig {
    pub name: String,
    /// Periodic or free edges only.
    pub grid: Grid,
    /// Diffusion coefficients, m²/s (≥ 0, not both 0).
    pub du: Real,
    pub dv: Real,
    /// Feed rate F and kill rate k, 1/s (≥ 0).
    pub feed: Real,
    pub kill: Real,
    /// The step `auto_dt` proposes, as a fraction of `stability_limit` (diffusion and
    /// reactions). Default 0.8.
    pub cfl: Real,
}

impl GrayScottConfig {
    /// The diffusion limit dx²/(2·dim·max(D_u, D_v)), s: forward Euler on the 5- (7-) point
    /// Laplacian is stable for diffusion alone below it (von Neumann analysis).
    pub fn diffusion_limit(&self) -> Real {
        let g = &self.grid;
        g.dx * g.dx / (2.0 * g.dim as Real * self.du.max(self.dv))
    }

    /// `GrayScottSystem::reaction_rate` of the fields `u`, `v`.
    pub fn reaction_rate(&self, u: &[Real], v: &[Real]) -> Real {
        let m = u.iter().zip(v).fold(0.0, |m: Real, (u, v)| m.max(v.abs() * (v.abs() + 2.0 * u.abs())));
        self.feed + self.kill + m.max(1.0)
    }

    /// `GrayScottSystem::stability_limit` of the fields `u`, `v`.
    pub fn stability_limit(&self, u: &[Real], v: &[Real]) -> Real {
        let t_d = self.diffusion_limit();
        t_d / (1.0 + 0.5 * self.reaction_rate(u, v) * t_d)
    }

    pub fn new(name: &str, grid: Grid, du: Real, dv: Real, feed: Real, kill: Real) -> Self {
        Self { name: name.to_string(), grid, du, dv, feed, kill, cfl: 0.8 }
    }

    pub fn validate(&self) -> Result<()> {
        for (arg, v, unit) in
            [("du", self.du, "m²/s"), ("dv", self.dv, "m²/s"), ("feed", self.feed, "1/s"), ("kill", self.kill, "1/s")]
        {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(arg, format!("{v} must be finite and >= 0 ({unit})")));
            }
        }
        if self.du == 0.0 && self.dv == 0.0 {
            return Err(invalid("du", "du and dv are both 0: nothing diffuses"));
        }
        if !(self.cfl.is_finite() && self.cfl > 0.0 && self.cfl <= 1.0) {
            return Err(invalid("cfl", format!("{} must be in (0, 1] (a fraction of the diffusion limit)", self.cfl)));
        }
        let g = &self.grid;
        if let Some(f) = (0..2 * g.dim).find(|&f| g.edges[f] == Edge::Fixed) {
            return Err(invalid(
                "edges",
                format!("face {f} is fixed: Gray–Scott takes periodic or free (no-flux) edges"),
            ));
        }
        Ok(())
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Books {
    made_u: Real,
    made_v: Real,
}

pub struct GrayScottSystem {
    cfg: GrayScottConfig,
    u: Vec<Real>,
    v: Vec<Real>,
    /// The next step's u and v (swapped in after each step).
    u2: Vec<Real>,
    v2: Vec<Real>,
    books: Books,
    /// Per row: (Σ reaction of u, Σ reaction of v, Σ u⁺ + v⁺ for the finiteness check).
    partials: Vec<[Real; 3]>,
    /// Buffers of checkpoints that were not needed (see `grids::Spare`).
    spare: super::Spare,
    /// Scratch of the fused steps (`fused`).
    fused: fused::Scratch,
}

impl GrayScottSystem {
    /// Starts at the homogeneous state u = 1, v = 0 (set another with `set_state`).
    pub fn new(cfg: GrayScottConfig) -> Result<Self> {
        cfg.validate()?;
        let n = cfg.grid.cells();
        let need =
            Need::new("add_gray_scott", Need::bytes_of::<Real>(4 * n), format!("{} grid cells", count(n as u128)));
        need.check()?;
        Ok(Self {
            u: need.filled(n, 1.0)?,
            v: need.filled(n, 0.0)?,
            u2: need.filled(n, 0.0)?,
            v2: need.filled(n, 0.0)?,
            books: Books { made_u: 0.0, made_v: 0.0 },
            partials: vec![[0.0; 3]; cfg.grid.rows()],
            spare: super::Spare::default(),
            fused: fused::Scratch::default(),
            cfg,
        })
    }

    pub fn config(&self) -> &GrayScottConfig {
        &self.cfg
    }
    pub fn u(&self) -> &[Real] {
        &self.u
    }
    pub fn v(&self) -> &[Real] {
        &self.v
    }

    /// The diffusion limit dx²/(2·dim·max(D_u, D_v)), s (`GrayScottConfig::diffusion_limit`).
    pub fn diffusion_limit(&self) -> Real {
        self.cfg.diffusion_limit()
    }

    /// A bound ρ_R (1/s) on the spectral radius of the reactions' Jacobian
    /// [[−v² − F, −2uv], [v², 2uv − (F + k)]] over the cells, by Gershgorin's theorem (each row's
    /// |diagonal| + |off-diagonal|): ρ_R ≤ max_cells v(v + 2u) + F + k. In the region the
    /// reactions keep (u, v ≥ 0, u + v ≤ 1: on u + v = 1 they change u + v by −kv ≤ 0)
    /// v(v + 2u) ≤ v(2 − v) ≤ 1; the bound takes at least that 1, so a pattern that grows within
    /// one `advance` (seeds start at v ≈ 0.25) stays inside the limit taken at its start.
    pub fn reaction_rate(&self) -> Real {
        self.cfg.reaction_rate(&self.u, &self.v)
    }

    /// The step (s) within forward Euler's stability region for diffusion and reactions
    /// together: |1 + dt λ| ≤ 1 holds for real λ ∈ [−2/dt, 0] (Hairer & Wanner, "Solving
    /// Ordinary Differential Equations II", §IV.2), and by Gershgorin the linearised step's
    /// eigenvalues have |λ| ≤ 4·dim·D/dx² + ρ_R (the Laplacian's rows: 2·dim/dx² on and off the
    /// diagonal). So dt ≤ 2 / (4·dim·D/dx² + ρ_R) = t_D / (1 + ρ_R t_D / 2), with t_D the
    /// diffusion limit and ρ_R `reaction_rate`. At Pearson's grid (t_D = 1.19) it is 0.72.
    pub fn stability_limit(&self) -> Real {
        self.cfg.stability_limit(&self.u, &self.v)
    }

    pub fn set_state(&mut self, u: Option<&[Real]>, v: Option<&[Real]>) -> Result<()> {
        let n = self.u.len();
        for (arg, a) in [("u", u), ("v", v)] {
            let Some(a) = a else { continue };
            if a.len() != n {
                return Err(invalid(arg, format!("has {} values, the grid has {n} cells", a.len())));
            }
            if let Some(i) = first_non_finite(a) {
                return Err(invalid(arg, format!("cell {i} is not finite: {}", a[i])));
            }
        }
        if let Some(u) = u {
            self.u.copy_from_slice(u);
        }
        if let Some(v) = v {
            self.v.copy_from_slice(v);
        }
        Ok(())
    }

    /// The coefficients of a step of `dt`.
    fn rates(&self, dt: Real) -> Rates {
        let g = &self.cfg.grid;
        let inv_dx2 = 1.0 / (g.dx * g.dx);
        Rates {
            du: dt * self.cfg.du * inv_dx2,
            dv: dt * self.cfg.dv * inv_dx2,
            dt,
            f: self.cfg.feed,
            fk: self.cfg.feed + self.cfg.kill,
        }
    }

    /// One row of the forward Euler step into `un`, `vn`.
    fn row(&self, r: usize, un: &mut [Real], vn: &mut [Real], k: Rates) -> [Real; 3] {
        let g = &self.cfg.grid;
        let nx = g.n[0];
        let nb = |q: usize| q * nx..(q + 1) * nx;
        let (s, _) = g.neighbour_row(r, 1, 0);
        let (n, _) = g.neighbour_row(r, 1, 1);
        // Periodic and free edges only: every neighbour enters with factor 1.
        let (d, t) = if g.dim == 3 { (g.neighbour_row(r, 2, 0).0, g.neighbour_row(r, 2, 1).0) } else { (r, r) };
        let rows = [nb(r), nb(s), nb(n), nb(d), nb(t)];
        advance(g, k, rows.clone().map(|q| &self.u[q]), rows.map(|q| &self.v[q]), un, vn)
    }
}

/// The coefficients of one step: dt·D/dx² for each species, dt, F and F + k.
#[derive(Clone, Copy)]
struct Rates {
    du: Real,
    dv: Real,
    dt: Real,
    f: Real,
    fk: Real,
}

/// One row of the forward Euler step into `un`, `vn`, from the rows [centre, south, north,
/// down, top] of u and v (down and top are read in 3D only). Returns (Σ reaction of u, Σ
/// reaction of v, Σ u⁺ + v⁺): the first two for the books, the last to catch non-finite values.
#[inline]
fn advance(g: &Grid, k: Rates, u: [&[Real]; 5], v: [&[Real]; 5], un: &mut [Real], vn: &mut [Real]) -> [Real; 3] {
    let row = Row { g, k, u, v, un, vn };
    if g.dim == 3 {
        simd::dispatch(simd::level(), Stencil::<true>(row))
    } else {
        simd::dispatch(simd::level(), Stencil::<false>(row))
    }
}

struct Row<'a> {
    g: &'a Grid,
    k: Rates,
    u: [&'a [Real]; 5],
    v: [&'a [Real]; 5],
    un: &'a mut [Real],
    vn: &'a mut [Real],
}

/// `advance` in lanes, 3D or not. The cells are the scalar expression's, operation for operation
/// (no fused multiply–adds), so u and v have the same bits at every SIMD level. The sums are
/// made in the stencil's loop, one per lane (a second pass over the row cost a third of the
/// time, and fixed 8-way sums spilled registers at AVX2): the books' last bits depend on the
/// lane count, never on the thread count.
struct Stencil<'a, const THREE: bool>(Row<'a>);

impl<const THREE: bool> Kernel for Stencil<'_, THREE> {
    type Output = [Real; 3];
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> [Real; 3] {
        let Row { g, k, u, v, un, vn } = self.0;
        let nx = g.n[0];
        let Rates { du, dv, dt, f, fk } = k;
        let [uc, us, un_, ud, ut] = u;
        let [vc, vs, vn_, vd, vt] = v;
        let centre = (2 * g.dim) as Real;
        // One cell, scalar: the edges (ghosts from `ghost_x`) and the cells past the last full
        // vector.
        let cell = |i: usize, ul: Real, ur: Real, vl: Real, vr: Real| -> [Real; 4] {
            let mut lu = ul + ur + us[i] + un_[i] - centre * uc[i];
            let mut lv = vl + vr + vs[i] + vn_[i] - centre * vc[i];
            if THREE {
                lu += ud[i] + ut[i];
                lv += vd[i] + vt[i];
            }
            let uvv = uc[i] * vc[i] * vc[i];
            let ru = f * (1.0 - uc[i]) - uvv;
            let rv = uvv - fk * vc[i];
            [uc[i] + du * lu + dt * ru, vc[i] + dv * lv + dt * rv, ru, rv]
        };
        let l = P::<S, Real>::lanes();
        let sp = |x: Real| P::<S, Real>::splat(s, x);
        let (pdu, pdv, pdt, pf, pfk, one, pc) = (sp(du), sp(dv), sp(dt), sp(f), sp(fk), sp(1.0), sp(centre));
        let (mut acc_u, mut acc_v, mut acc_s) = (P::<S, Real>::zero(s), P::<S, Real>::zero(s), P::<S, Real>::zero(s));
        let m = nx - 2;
        let blocks = m / l;
        // Interior cell j + 1 for j in 0..m. Windows of l + 2 cells, so that the loads need no
        // bounds checks.
        fn window(a: &[Real], j: usize, l: usize) -> &[Real] {
            &a[j..j + l + 2]
        }
        for b in 0..blocks {
            let j = b * l;
            let w = |a| window(a, j, l);
            let (uw, vw, usw, unw, vsw, vnw) = (w(uc), w(vc), w(us), w(un_), w(vs), w(vn_));
            let ld = |a: &[Real], o: usize| P::<S, Real>::load(s, &a[o..]);
            let (ucc, vcc) = (ld(uw, 1), ld(vw, 1));
            let mut lu = ld(uw, 0) + ld(uw, 2) + ld(usw, 1) + ld(unw, 1) - pc * ucc;
            let mut lv = ld(vw, 0) + ld(vw, 2) + ld(vsw, 1) + ld(vnw, 1) - pc * vcc;
            if THREE {
                lu = lu + (ld(w(ud), 1) + ld(w(ut), 1));
                lv = lv + (ld(w(vd), 1) + ld(w(vt), 1));
            }
            let uvv = ucc * vcc * vcc;
            let ru = pf * (one - ucc) - uvv;
            let rv = uvv - pfk * vcc;
            let a = ucc + pdu * lu + pdt * ru;
            let c = vcc + pdv * lv + pdt * rv;
            a.store(&mut un[j + 1..j + 1 + l]);
            c.store(&mut vn[j + 1..j + 1 + l]);
            acc_u = acc_u + ru;
            acc_v = acc_v + rv;
            acc_s = acc_s + (a + c);
        }
        let mut sums = [acc_u.sum(), acc_v.sum(), acc_s.sum()];
        let mut add = |i: usize, c: [Real; 4], un: &mut [Real], vn: &mut [Real]| {
            un[i] = c[0];
            vn[i] = c[1];
            sums[0] += c[2];
            sums[1] += c[3];
            sums[2] += c[0] + c[1];
        };
        for i in blocks * l + 1..nx - 1 {
            add(i, cell(i, uc[i - 1], uc[i + 1], vc[i - 1], vc[i + 1]), un, vn);
        }
        let (gu, gv) = ([g.ghost_x(uc, 0), g.ghost_x(uc, 1)], [g.ghost_x(vc, 0), g.ghost_x(vc, 1)]);
        add(0, cell(0, gu[0], uc[1], gv[0], vc[1]), un, vn);
        add(nx - 1, cell(nx - 1, uc[nx - 2], gu[1], vc[nx - 2], gv[1]), un, vn);
        sums
    }
}

impl System for GrayScottSystem {
    fn name(&self) -> &str {
        &self.cfg.name
    }
    fn is_empty(&self) -> bool {
        false
    }
    fn size(&self) -> usize {
        self.u.len()
    }
    fn step(&mut self, dt: Real, _stop: &AtomicBool) -> std::result::Result<(), Halt> {
        let nx = self.cfg.grid.n[0];
        let (mut un, mut vn, mut partials) =
            (std::mem::take(&mut self.u2), std::mem::take(&mut self.v2), std::mem::take(&mut self.partials));
        let this = &*self;
        let k = this.rates(dt);
        rows2_each(&mut un, &mut vn, nx, &mut partials, |r, a, b| this.row(r, a, b, k));
        let (mut mu, mut mv, mut sum) = (0.0, 0.0, 0.0);
        for p in &partials {
            mu += p[0];
            mv += p[1];
            sum += p[2];
        }
        self.u2 = std::mem::replace(&mut self.u, un);
        self.v2 = std::mem::replace(&mut self.v, vn);
        self.partials = partials;
        let da = self.cfg.grid.cell_measure();
        self.books.made_u += dt * mu * da;
        self.books.made_v += dt * mv * da;
        if !sum.is_finite() {
            let index = first_non_finite(&self.u).or_else(|| first_non_finite(&self.v)).unwrap_or(0);
            return Err(Halt::Diverged { index, quantity: Failure::Cell });
        }
        Ok(())
    }
    /// Up to `fused::FUSE` steps per sweep over memory, with the bits of single steps; a sweep
    /// that meets a non-finite value is taken again step by step, which finds the step.
    fn steps(&mut self, n: u64, dt: Real, stop: &AtomicBool) -> std::result::Result<(), (u64, Halt)> {
        let mut i = 0;
        while i < n {
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Err((i, Halt::Stopped));
            }
            let k = (n - i).min(fused::FUSE as u64);
            if k >= 2 && self.fusable() && self.sweep(dt, k as usize) {
                i += k;
                continue;
            }
            for _ in 0..k {
                if stop.load(std::sync::atomic::Ordering::Relaxed) {
                    return Err((i, Halt::Stopped));
                }
                self.step(dt, stop).map_err(|h| (i, h))?;
                i += 1;
            }
        }
        Ok(())
    }
    fn auto_dt(&self) -> Option<Real> {
        Some(self.cfg.cfl * self.stability_limit())
    }
    fn suggest_dt(&self) -> Option<Real> {
        Some(self.cfg.cfl * self.stability_limit())
    }
    /// No energy: the books are amounts (`books`).
    fn energy(&self) -> EnergyReport {
        EnergyReport::default()
    }
    fn books(&self) -> Vec<(String, Real)> {
        let da = self.cfg.grid.cell_measure();
        let sum = |a: &[Real]| {
            super::sum_rows(self.cfg.grid.rows(), a.len(), |r| {
                let nx = self.cfg.grid.n[0];
                a[r * nx..(r + 1) * nx].iter().sum::<Real>()
            }) * da
        };
        vec![
            ("u".to_string(), sum(&self.u)),
            ("v".to_string(), sum(&self.v)),
            ("u_made".to_string(), self.books.made_u),
            ("v_made".to_string(), self.books.made_v),
        ]
    }
    fn set_field(&mut self, name: &str, values: &[Real]) -> Result<()> {
        match name {
            "u" => self.set_state(Some(values), None),
            "v" => self.set_state(None, Some(values)),
            _ => Err(invalid("field", format!("{name:?}: Gray–Scott's settable fields are \"u\" and \"v\""))),
        }
    }
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let need = Need::fields(names, self.u.len(), "grid cells");
        names
            .iter()
            .map(|n| match *n {
                "u" => need.copy(&self.u),
                "v" => need.copy(&self.v),
                _ => need.filled(self.u.len(), 0.0),
            })
            .collect()
    }
    fn snapshot(&self) -> Result<Snapshot> {
        self.spare.snapshot2(&self.u, &self.v, self.books)
    }
    fn restore(&mut self, snapshot: Snapshot) {
        let (u, v, b) =
            *snapshot.downcast::<(Vec<Real>, Vec<Real>, Books)>().expect("a snapshot of this Gray–Scott system");
        (self.u, self.v, self.books) = (u, v, b);
    }
    fn recycle(&mut self, snapshot: Snapshot) {
        self.spare.recycle2::<Books>(snapshot);
    }
    fn save(&self) -> Result<Arrays> {
        let made = [self.books.made_u, self.books.made_v];
        let of = format!("the Gray–Scott fields of {} cells", count(self.u.len() as u128));
        crate::systems::saved(of, &[("u", &self.u), ("v", &self.v), ("made", &made)])
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let n = self.u.len();
        let (u, v, m) = (array(arrays, "u", Some(n))?, array(arrays, "v", Some(n))?, array(arrays, "made", Some(2))?);
        for (name, a) in [("u", u), ("v", v), ("made", m)] {
            if let Some(i) = first_non_finite(a) {
                return Err(invalid(name, format!("value {i} is not finite: {}", a[i])));
            }
        }
        self.u.copy_from_slice(u);
        self.v.copy_from_slice(v);
        self.books = Books { made_u: m[0], made_v: m[1] };
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    fn pearson(n: usize) -> GrayScottSystem {
        let g = Grid::new(&[n, n], 2.5 / 256.0, &[Edge::Periodic; 4]).unwrap();
        let mut s = GrayScottSystem::new(GrayScottConfig::new("gs", g, 2e-5, 1e-5, 0.035, 0.065)).unwrap();
        let (mut u, mut v) = (vec![1.0; n * n], vec![0.0; n * n]);
        for c in 0..n * n {
            let (i, j) = (c % n, c / n);
            if (n / 2 - 5..n / 2 + 5).contains(&i) && (n / 2 - 5..n / 2 + 5).contains(&j) {
                u[c] = 0.5 + 0.01 * ((c * 7919 % 101) as Real / 101.0);
                v[c] = 0.25;
            }
        }
        s.set_state(Some(&u), Some(&v)).unwrap();
        s
    }

    fn run(s: &mut GrayScottSystem, n: usize) {
        let stop = AtomicBool::new(false);
        let dt = s.auto_dt().unwrap();
        for _ in 0..n {
            s.step(dt, &stop).unwrap();
        }
    }

    #[test]
    fn amounts_balance_what_the_reactions_made() {
        let mut s = pearson(64);
        let b0 = s.books();
        run(&mut s, 500);
        let b = s.books();
        let (u0, v0) = (b0[0].1, b0[1].1);
        assert!(b[2].1.abs() > 1e-3 && b[3].1.abs() > 1e-5, "the reactions ran: {b:?}");
        assert!(((b[0].1 - b[2].1) - u0).abs() < 1e-12 * u0, "{b:?}");
        assert!(((b[1].1 - b[3].1) - v0).abs() < 1e-10 * u0, "{b:?}");
    }

    #[test]
    fn bit_identical_for_any_thread_count() {
        let go = |t: usize| {
            let pool = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap());
            crate::par::install(Some(&pool), || {
                let mut s = pearson(96);
                run(&mut s, 50);
                (s.v.clone(), s.books())
            })
        };
        let (a, ba) = go(1);
        let (b, bb) = go(3);
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
        assert_eq!(ba, bb);
    }

    /// A seeded start on an nx × ny grid with the given y edges.
    fn seeded(nx: usize, ny: usize, y: Edge) -> GrayScottSystem {
        let g = Grid::new(&[nx, ny], 0.01, &[Edge::Free, Edge::Free, y, y]).unwrap();
        let mut s = GrayScottSystem::new(GrayScottConfig::new("gs", g, 2e-5, 1e-5, 0.035, 0.065)).unwrap();
        let n = nx * ny;
        let u: Vec<Real> = (0..n).map(|c| 0.5 + 0.5 * ((c * 7919 % 101) as Real / 101.0)).collect();
        let v: Vec<Real> = (0..n).map(|c| 0.3 * ((c * 104729 % 97) as Real / 97.0)).collect();
        s.set_state(Some(&u), Some(&v)).unwrap();
        s
    }

    #[test]
    fn fused_steps_give_the_bits_of_single_steps() {
        let stop = AtomicBool::new(false);
        for (nx, ny, y) in
            [(40, 300, Edge::Periodic), (33, 150, Edge::Free), (8, 5, Edge::Periodic), (9, 3, Edge::Free)]
        {
            for threads in [1, 3] {
                let pool = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap());
                crate::par::install(Some(&pool), || {
                    for n in [2, 5, 6, 17] {
                        let (mut one, mut many) = (seeded(nx, ny, y), seeded(nx, ny, y));
                        assert!(many.fusable());
                        let dt = one.auto_dt().unwrap();
                        for _ in 0..n {
                            one.step(dt, &stop).unwrap();
                        }
                        if n <= fused::FUSE as u64 {
                            assert!(many.sweep(dt, n as usize), "one sweep of {n} steps");
                        } else {
                            many.steps(n, dt, &stop).unwrap();
                        }
                        let same = |a: &[Real], b: &[Real]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
                        assert!(same(&one.u, &many.u) && same(&one.v, &many.v), "{nx}×{ny} {y:?} {n} steps");
                        assert_eq!(one.books(), many.books(), "{nx}×{ny} {y:?} {n} steps");
                    }
                });
            }
        }
    }

    #[test]
    fn fused_steps_find_the_step_that_diverged() {
        let stop = AtomicBool::new(false);
        let (mut one, mut many) = (seeded(40, 300, Edge::Periodic), seeded(40, 300, Edge::Periodic));
        let dt = 1.3 * one.diffusion_limit();
        let first = (0..5000u64).find(|_| one.step(dt, &stop).is_err()).expect("diverges");
        let (taken, halt) = many.steps(5000, dt, &stop).unwrap_err();
        assert_eq!(taken, first);
        assert!(matches!(halt, Halt::Diverged { quantity: Failure::Cell, .. }), "{halt:?}");
    }

    #[test]
    fn the_automatic_step_keeps_coarse_grids_within_the_reactions() {
        // Pearson's domain (2.5) on 16–64 cells a side: the diffusion limit alone is 15–240
        // time units, over the reactions' scale (~1), and its automatic step diverged within
        // 13 steps (issue 44). The reactions' bound keeps it below 2/ρ_R.
        let stop = AtomicBool::new(false);
        for n in [16, 32, 64] {
            let g = Grid::new(&[n, n], 2.5 / n as Real, &[Edge::Periodic; 4]).unwrap();
            let mut s = GrayScottSystem::new(GrayScottConfig::new("gs", g, 2e-5, 1e-5, 0.0545, 0.062)).unwrap();
            let (mut u, mut v) = (vec![1.0; n * n], vec![0.0; n * n]);
            for c in (0..n * n).filter(|c| (c % n).abs_diff(n / 2) < n / 8 && (c / n).abs_diff(n / 2) < n / 8) {
                (u[c], v[c]) = (0.5, 0.25);
            }
            s.set_state(Some(&u), Some(&v)).unwrap();
            let dt = s.auto_dt().unwrap();
            assert!(dt * s.reaction_rate() <= 2.0 * s.cfg.cfl, "n = {n}: dt {dt}");
            for k in 0..(2000.0 / dt) as usize {
                s.step(dt, &stop).unwrap_or_else(|h| panic!("n = {n}: step {k} of {dt}: {h:?}"));
            }
            assert!(s.v.iter().chain(&s.u).all(|x| (-1e-9..=1.0 + 1e-9).contains(x)), "n = {n}");
        }
        // Pearson's grid: t_D / (1 + ρ_R t_D / 2) with ρ_R = 1 + F + k (seeds have v(v + 2u) < 1).
        let s = pearson(256);
        let (t_d, rho) = (s.diffusion_limit(), 1.0 + 0.035 + 0.065);
        assert!((s.stability_limit() - t_d / (1.0 + 0.5 * rho * t_d)).abs() < 1e-15);
    }

    #[test]
    fn above_the_diffusion_limit_diverges() {
        let mut s = pearson(32);
        let stop = AtomicBool::new(false);
        let dt = 1.1 * s.diffusion_limit();
        let h = (0..5000).find_map(|_| s.step(dt, &stop).err());
        assert!(matches!(h, Some(Halt::Diverged { quantity: Failure::Cell, .. })), "{h:?}");
    }

    #[test]
    fn restore_and_load_continue_bit_identically() {
        let mut s = pearson(32);
        run(&mut s, 10);
        let (snap, saved) = (s.snapshot().unwrap(), s.save().unwrap());
        run(&mut s, 30);
        let a = s.v.clone();
        s.restore(snap);
        run(&mut s, 30);
        assert_eq!(a, s.v);
        let mut t = pearson(32);
        t.load(&saved).unwrap();
        run(&mut t, 30);
        assert_eq!(a, t.v);
    }

    #[test]
    fn fixed_edges_and_bad_rates_are_refused() {
        let g = Grid::new(&[8, 8], 1.0, &[Edge::Fixed; 4]).unwrap();
        let c = GrayScottConfig::new("gs", g.clone(), 0.2, 0.1, 0.03, 0.06);
        assert!(
            matches!(GrayScottSystem::new(c).err(), Some(crate::Error::InvalidInput { arg, .. }) if arg == "edges")
        );
        let g = Grid::new(&[8, 8], 1.0, &[Edge::Periodic; 4]).unwrap();
        let c = GrayScottConfig::new("gs", g, 0.2, 0.1, -0.03, 0.06);
        assert!(matches!(GrayScottSystem::new(c).err(), Some(crate::Error::InvalidInput { arg, .. }) if arg == "feed"));
    }
}
