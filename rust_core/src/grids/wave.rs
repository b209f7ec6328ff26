//! The damped wave equation u_tt = c²∇²u − γ u_t + f(x, t) on a cell-centred grid (water
//! ripples, a drum, interference behind slits), stepped by the standard explicit leapfrog scheme
//! (central differences in time and space, second order in both; Langtangen & Linge, "Finite
//! Difference Computing with PDEs", 2017, §2.1):
//!
//! ```text
//!   u⁺ = (2u − (1 − a) u⁻ + dt² (c² L u + f)) / (1 + a),   a = γ dt / 2,
//! ```
//! with L the 5-point (7-point in 3D) Laplacian of `grids`. Stable for c·dt/dx ≤ 1/√dim (the CFL
//! condition); `auto_dt` keeps `cfl` (default 0.9) of that limit.
//!
//! **State.** u at the current time and u⁻ one step earlier (the increment u − u⁻ is dt times the
//! velocity at the half step), so a step reads two arrays and writes one in place: the scheme's
//! whole memory traffic. A change of dt rescales the increment, keeping the velocity.
//!
//! **Books.** The discrete energy (per unit areal density, J/(kg/m²) in 2D)
//! `E = ½ Σ ((u − u⁻)/dt)² dA − ½ c² Σ u⁻ (L u) dA` (kinetic at the half step, plus the
//! potential ½c²|∇u|² written as the symmetric cross term between the two time levels) is
//! conserved by leapfrog to round-off when γ = 0 and f = 0, because L is symmetric for every edge
//! rule (summation by parts). Damping books dt Σ γ v̄² dA as dissipated, v̄ = (u⁺ − u⁻)/(2 dt),
//! and sources book their work dt Σ f v̄ dA (a drop: the energy it adds), so
//! `kinetic + potential + dissipated − work` stays constant to round-off. The potential's cross
//! term depends on dt: a change of dt moves it (u⁻ rescaled, the velocity kept), and the
//! `dt changes` book holds what each change moved, so the total holds across it too.
//!
//! **Absorbing faces** are damping layers ("sponges") of `layer` cells whose γ rises as the
//! square of the depth into the layer to `layer_strength`·c/dx at the outer face (fixed): the
//! ramp is gentle enough that little reflects from it, and what crosses it is damped twice.
//! **Obstacles**: masked cells are held at u = 0 (a rigid wall at their centres).
use super::{first_non_finite, rows_each, sum_rows, wave_fused, Grid};
use crate::alloc::{count, Need};
use crate::error::{invalid, Failure, Result};
use crate::simd;
use crate::systems::{array, Arrays, EnergyReport, Halt, Snapshot, System};
use crate::vector::Real;
use std::f64::consts::PI;
use std::sync::atomic::AtomicBool;

/// A displacement dropped onto the surface at time `t`: u −= amplitude · profile, with no change
/// of velocity (a stone's dent; the profile is usually a Gaussian).
#[derive(Clone, Debug, PartialEq)]
pub struct Drop {
    /// When, s.
    pub t: Real,
    /// Depth at the profile's peak, m (positive: a dent).
    pub amplitude: Real,
    /// (cell, weight) pairs, weights usually in [0, 1].
    pub profile: Vec<(usize, Real)>,
}

/// A driven source: f(x, t) = amplitude · sin(2π·frequency·t + phase) · profile(x), an
/// acceleration (m/s²).
#[derive(Clone, Debug, PartialEq)]
pub struct Oscillator {
    pub amplitude: Real,
    /// Hz.
    pub frequency: Real,
    /// Radians.
    pub phase: Real,
    pub profile: Vec<(usize, Real)>,
}

/// Everything that defines a wave system (defaults: `WaveConfig::new`).
#[derive(Clone, Debug, PartialEq)]
pub struct WaveConfig {
    pub name: String,
    pub grid: Grid,
    /// Wave speed, m/s (> 0).
    pub c: Real,
    /// Damping rate γ, 1/s (≥ 0). Default 0.
    pub gamma: Real,
    /// Faces with a damping layer, [x−, x+, y−, y+, z−, z+] (an absorbing face must not be
    /// periodic; its ghost rule applies beyond the layer). Default none.
    pub absorbing: [bool; 6],
    /// Cells in each damping layer. Default 24.
    pub layer: usize,
    /// γ at a layer's outer face, in units of c/dx. Default 0.5.
    pub layer_strength: Real,
    /// Obstacle cells (held at u = 0), one per cell; `None`: no obstacle.
    pub mask: Option<Vec<bool>>,
    pub drops: Vec<Drop>,
    pub oscillators: Vec<Oscillator>,
    /// The step `auto_dt` proposes, as a fraction of the CFL limit dx/(c√dim). Default 0.9.
    pub cfl: Real,
}

impl WaveConfig {
    /// The CFL limit dx/(c√dim), s: the leapfrog scheme is stable for c·dt/dx ≤ 1/√dim
    /// (Langtangen & Linge 2017, §2.1).
    pub fn cfl_limit(&self) -> Real {
        self.grid.dx / (self.c * (self.grid.dim as Real).sqrt())
    }

    pub fn new(name: &str, grid: Grid, c: Real) -> Self {
        Self {
            name: name.to_string(),
            grid,
            c,
            gamma: 0.0,
            absorbing: [false; 6],
            layer: 24,
            layer_strength: 0.5,
            mask: None,
            drops: Vec::new(),
            oscillators: Vec::new(),
            cfl: 0.9,
        }
    }

    pub fn validate(&self) -> Result<()> {
        let g = &self.grid;
        let cells = g.cells();
        if !(self.c.is_finite() && self.c > 0.0) {
            return Err(invalid("c", format!("{} must be finite and > 0 (m/s)", self.c)));
        }
        if !(self.gamma.is_finite() && self.gamma >= 0.0) {
            return Err(invalid("damping", format!("{} must be finite and >= 0 (1/s)", self.gamma)));
        }
        if !(self.cfl.is_finite() && self.cfl > 0.0 && self.cfl <= 1.0) {
            return Err(invalid("cfl", format!("{} must be in (0, 1] (a fraction of the CFL limit)", self.cfl)));
        }
        for f in 0..2 * g.dim {
            if self.absorbing[f] {
                if g.edges[f] == super::Edge::Periodic {
                    return Err(invalid("absorbing", format!("face {f} is periodic and cannot absorb")));
                }
                if self.layer == 0 || 2 * self.layer > g.n[f / 2] {
                    return Err(invalid(
                        "layer",
                        format!(
                            "{} cells: must be >= 1 and fit twice across axis {} ({} cells)",
                            self.layer,
                            f / 2,
                            g.n[f / 2]
                        ),
                    ));
                }
            }
        }
        if !(self.layer_strength.is_finite() && self.layer_strength > 0.0) {
            return Err(invalid(
                "layer_strength",
                format!("{} must be finite and > 0 (units of c/dx)", self.layer_strength),
            ));
        }
        if let Some(m) = &self.mask {
            if m.len() != cells {
                return Err(invalid("mask", format!("has {} cells, the grid has {cells}", m.len())));
            }
        }
        let profile = |arg: &str, p: &[(usize, Real)]| -> Result<()> {
            for &(c, w) in p {
                if c >= cells {
                    return Err(invalid(arg, format!("cell {c} is outside the grid ({cells} cells)")));
                }
                if !w.is_finite() {
                    return Err(invalid(arg, format!("weight {w} of cell {c} is not finite")));
                }
            }
            Ok(())
        };
        for (k, d) in self.drops.iter().enumerate() {
            if !(d.t.is_finite() && d.amplitude.is_finite()) {
                return Err(invalid("drops", format!("drop {k}: time and amplitude must be finite")));
            }
            profile("drops", &d.profile)?;
        }
        for (k, o) in self.oscillators.iter().enumerate() {
            if !(o.amplitude.is_finite() && o.frequency.is_finite() && o.frequency >= 0.0 && o.phase.is_finite()) {
                return Err(invalid(
                    "oscillators",
                    format!("oscillator {k}: amplitude and phase must be finite, frequency finite and >= 0"),
                ));
            }
            profile("oscillators", &o.profile)?;
        }
        Ok(())
    }
}

/// What a step changes besides the two arrays.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Clock {
    /// The system's time, s (drops and oscillators read it).
    t: Real,
    /// The dt that made u from u⁻.
    dt: Real,
    /// Energy dissipated by damping, J (per unit density).
    dissipated: Real,
    /// Work done by drops and oscillators, J.
    work: Real,
    /// Drops applied so far (they are sorted by time).
    next_drop: usize,
    /// Energy the changes of dt added, J (per unit density): the discrete energy's potential is
    /// a cross term of two time levels dt apart, so a new dt (the velocity kept) moves it.
    rescaled: Real,
}

pub struct WaveSystem {
    cfg: WaveConfig,
    u: Vec<Real>,
    u_prev: Vec<Real>,
    clock: Clock,
    /// γ per cell where damping layers are (else empty): the uniform γ plus the layer's.
    gamma_cells: Vec<Real>,
    /// Per row: the cell ranges [lo, hi) outside the x layers use the uniform γ; rows inside a
    /// y or z layer use `gamma_cells` throughout.
    row_in_layer: Vec<bool>,
    x_layer: (usize, usize),
    /// 1 for free cells, 0 for obstacles (empty without a mask); rows holding any obstacle.
    keep: Vec<Real>,
    row_masked: Vec<bool>,
    /// u⁻ at the oscillators' cells before a step, and the rows' partial sums (scratch).
    src_prev: Vec<Real>,
    partials: Vec<(Real, Real)>,
    /// Scratch of the fused steps (`wave_fused`).
    fused: wave_fused::Scratch,
    /// Buffers of checkpoints that were not needed (see `grids::Spare`).
    spare: super::Spare,
}

/// One row's update: the neighbour rows and what the leapfrog formula needs.
struct Row<'a> {
    u: &'a [Real],
    south: &'a [Real],
    north: &'a [Real],
    down: &'a [Real],
    up: &'a [Real],
    f: [Real; 4],
    ghost: [Real; 2],
}

impl WaveSystem {
    pub fn new(mut cfg: WaveConfig) -> Result<Self> {
        cfg.validate()?;
        cfg.drops.sort_by(|a, b| a.t.total_cmp(&b.t));
        let g = &cfg.grid;
        let n = g.cells();
        let need = Need::new("add_wave", Need::bytes_of::<Real>(4 * n), format!("{} grid cells", count(n as u128)));
        need.check()?;
        let u = need.filled(n, 0.0)?;
        let u_prev = need.filled(n, 0.0)?;
        let (nx, rows) = (g.n[0], g.rows());
        let mut gamma_cells = Vec::new();
        let mut row_in_layer = need.filled(rows, false)?;
        let mut x_layer = (0, nx);
        if cfg.absorbing.iter().any(|&a| a) {
            gamma_cells = need.filled(n, cfg.gamma)?;
            let (w, top) = (cfg.layer as Real, cfg.layer_strength * cfg.c / g.dx);
            // Depth into a layer, 1 at the outer cell, → 0 at its inner edge.
            let depth = |i: usize, n: usize, lo: bool, hi: bool| -> Real {
                let from_lo = if lo { (w - i as Real) / w } else { 0.0 };
                let from_hi = if hi { (w - (n - 1 - i) as Real) / w } else { 0.0 };
                from_lo.max(from_hi).max(0.0)
            };
            let a = cfg.absorbing;
            for c in 0..n {
                let (i, j, k) = (c % nx, (c / nx) % g.n[1], c / (nx * g.n[1]));
                let d = depth(i, nx, a[0], a[1]).max(depth(j, g.n[1], a[2], a[3])).max(if g.dim == 3 {
                    depth(k, g.n[2], a[4], a[5])
                } else {
                    0.0
                });
                gamma_cells[c] += top * d * d;
            }
            for (r, flag) in row_in_layer.iter_mut().enumerate() {
                let (j, k) = (r % g.n[1], r / g.n[1]);
                *flag = depth(j, g.n[1], a[2], a[3]) > 0.0 || (g.dim == 3 && depth(k, g.n[2], a[4], a[5]) > 0.0);
            }
            x_layer = (if a[0] { cfg.layer } else { 0 }, if a[1] { nx - cfg.layer } else { nx });
        }
        let (mut keep, mut row_masked) = (Vec::new(), need.filled(rows, false)?);
        if let Some(m) = &cfg.mask {
            // Fallible, as every buffer sized by the grid: an infallible collect here aborted
            // the process under a memory cap (issue 64 item 8).
            keep = need.collect(m.iter().map(|&b| if b { 0.0 } else { 1.0 }))?;
            for (r, flag) in row_masked.iter_mut().enumerate() {
                *flag = m[r * nx..(r + 1) * nx].iter().any(|&b| b);
            }
        }
        let src = cfg.oscillators.iter().map(|o| o.profile.len()).sum();
        let dt = cfg.cfl * g.dx / (cfg.c * (g.dim as Real).sqrt());
        Ok(Self {
            u,
            u_prev,
            clock: Clock { t: 0.0, dt, dissipated: 0.0, work: 0.0, next_drop: 0, rescaled: 0.0 },
            gamma_cells,
            row_in_layer,
            x_layer,
            keep,
            row_masked,
            src_prev: need.filled(src, 0.0)?,
            partials: need.filled(rows, (0.0, 0.0))?,
            spare: super::Spare::default(),
            fused: wave_fused::Scratch::default(),
            cfg,
        })
    }

    pub fn config(&self) -> &WaveConfig {
        &self.cfg
    }
    pub fn u(&self) -> &[Real] {
        &self.u
    }
    /// The system's time, s.
    pub fn time(&self) -> Real {
        self.clock.t
    }

    /// The CFL limit dx/(c√dim), s (`WaveConfig::cfl_limit`).
    pub fn cfl_limit(&self) -> Real {
        self.cfg.cfl_limit()
    }

    /// Sets the displacement u (m) and the velocity u_t (m/s) at the half step before now
    /// (`None`: keep the current velocity). Obstacle cells must be 0.
    pub fn set_state(&mut self, u: &[Real], v: Option<&[Real]>) -> Result<()> {
        let n = self.u.len();
        for (arg, a) in [("u", Some(u)), ("velocity", v)] {
            let Some(a) = a else { continue };
            if a.len() != n {
                return Err(invalid(arg, format!("has {} values, the grid has {n} cells", a.len())));
            }
            if let Some(i) = first_non_finite(a) {
                return Err(invalid(arg, format!("cell {i} is not finite: {}", a[i])));
            }
            if let Some(i) = (0..n).find(|&i| !self.keep.is_empty() && self.keep[i] == 0.0 && a[i] != 0.0) {
                return Err(invalid(arg, format!("cell {i} is an obstacle and must be 0, got {}", a[i])));
            }
        }
        let dt = self.clock.dt;
        for i in 0..n {
            let vi = v.map_or((self.u[i] - self.u_prev[i]) / dt, |v| v[i]);
            self.u[i] = u[i];
            self.u_prev[i] = u[i] - dt * vi;
        }
        Ok(())
    }

    /// The velocity at the half step before now, m/s.
    pub fn velocity(&self, need: &Need) -> Result<Vec<Real>> {
        let dt = self.clock.dt;
        need.collect(self.u.iter().zip(&self.u_prev).map(|(a, b)| (a - b) / dt))
    }

    /// Kinetic and potential energy (per unit density) of the current pair of time levels.
    fn energies(&self) -> (Real, Real) {
        let g = &self.cfg.grid;
        let (nx, da) = (g.n[0], g.cell_measure());
        let inv_dt = 1.0 / self.clock.dt;
        let (u, up) = (&self.u, &self.u_prev);
        let kinetic = sum_rows(g.rows(), g.cells(), |r| {
            let s = r * nx..(r + 1) * nx;
            u[s.clone()].iter().zip(&up[s]).map(|(a, b)| ((a - b) * inv_dt).powi(2)).sum::<Real>()
        });
        let stencil = sum_rows(g.rows(), g.cells(), |r| {
            let mut lu = vec![0.0; nx];
            g.laplacian_row(u, r, 1.0, &mut lu);
            -up[r * nx..(r + 1) * nx].iter().zip(&lu).map(|(a, b)| a * b).sum::<Real>()
        });
        // (c/dx)² applied last: a flat surface has no potential even where (c/dx)² overflows.
        let potential = if stencil == 0.0 { 0.0 } else { stencil * (self.cfg.c / g.dx).powi(2) };
        (0.5 * kinetic * da, 0.5 * potential * da)
    }

    /// Steps of `dt` from now on: u⁻ is rescaled so that the velocity (u − u⁻)/dt is kept.
    ///
    /// The discrete energy's potential −½c² Σ u⁻ L u moves with it (by ½c² (dt' − dt) Σ v L u,
    /// v the velocity): the change is booked (`dt changes`), so that the books' total holds
    /// across it as across a step.
    pub(crate) fn change_dt(&mut self, dt: Real) {
        if dt != self.clock.dt {
            let (k0, p0) = self.energies();
            let ratio = dt / self.clock.dt;
            for (a, b) in self.u.iter().zip(self.u_prev.iter_mut()) {
                *b = a - ratio * (a - *b);
            }
            self.clock.dt = dt;
            let (k1, p1) = self.energies();
            self.clock.rescaled += (k1 + p1) - (k0 + p0);
        }
    }

    /// What a device's copy of this system needs beyond its configuration (`systems::device`):
    /// γ per cell where the grid has damping layers (else empty) and 1 (free) or 0 (obstacle)
    /// per cell where it has obstacles (else empty).
    #[cfg(feature = "gpu")]
    pub(crate) fn coefficients(&self) -> (&[Real], &[Real]) {
        (&self.gamma_cells, &self.keep)
    }

    /// u and u⁻, to read or replace (a device's copy keeps them between its read-backs).
    #[cfg(feature = "gpu")]
    pub(crate) fn levels_mut(&mut self) -> (&mut Vec<Real>, &mut Vec<Real>) {
        (&mut self.u, &mut self.u_prev)
    }

    /// The clock: t, dt, dissipated, work, drops applied (as `save` writes "clock"), then the
    /// energy the changes of dt added (`save`'s "dt_changes").
    #[cfg(feature = "gpu")]
    pub(crate) fn clock_values(&self) -> [Real; 6] {
        let c = &self.clock;
        [c.t, c.dt, c.dissipated, c.work, c.next_drop as Real, c.rescaled]
    }

    /// Sets the clock (`clock_values`' order; the values are the system's own, unchecked).
    #[cfg(feature = "gpu")]
    pub(crate) fn set_clock_values(&mut self, c: [Real; 6]) {
        self.clock =
            Clock { t: c[0], dt: c[1], dissipated: c[2], work: c[3], next_drop: c[4] as usize, rescaled: c[5] };
    }

    /// The time of the next drop not yet applied.
    #[cfg(feature = "gpu")]
    pub(crate) fn next_drop_time(&self) -> Option<Real> {
        self.cfg.drops.get(self.clock.next_drop).map(|d| d.t)
    }

    /// Applies the drops due before `t + dt` (a dent in u and u⁻ alike: no change of velocity)
    /// and books the energy each adds as work.
    pub(crate) fn drop_due(&mut self, dt: Real) {
        while let Some(d) = self.cfg.drops.get(self.clock.next_drop).filter(|d| d.t < self.clock.t + dt) {
            let (k0, u0) = self.energies();
            for &(c, w) in &d.profile {
                if self.keep.is_empty() || self.keep[c] != 0.0 {
                    self.u[c] -= d.amplitude * w;
                    self.u_prev[c] -= d.amplitude * w;
                }
            }
            let (k1, u1) = self.energies();
            self.clock.work += (k1 + u1) - (k0 + u0);
            self.clock.next_drop += 1;
        }
    }

    /// u⁺ for row `r`, in place over u⁻ (`up`); returns (Σ u⁺ for the finiteness check, the
    /// row's Σ γ (u⁺ − u⁻)²).
    fn update_row(&self, r: usize, up: &mut [Real], k: Real, dt: Real) -> (Real, Real) {
        let g = &self.cfg.grid;
        let nx = g.n[0];
        let u = &self.u;
        let (s, fs) = g.neighbour_row(r, 1, 0);
        let (nn, fn_) = g.neighbour_row(r, 1, 1);
        let (d, fd, t, ft) = if g.dim == 3 {
            let (d, fd) = g.neighbour_row(r, 2, 0);
            let (t, ft) = g.neighbour_row(r, 2, 1);
            (d, fd, t, ft)
        } else {
            (r, 0.0, r, 0.0)
        };
        let rows = |q: usize| &u[q * nx..(q + 1) * nx];
        let row = rows(r);
        let w = Row {
            u: row,
            south: rows(s),
            north: rows(nn),
            down: rows(d),
            up: rows(t),
            f: [fs, fn_, fd, ft],
            ghost: [g.ghost_x(row, 0), g.ghost_x(row, 1)],
        };
        let keep = (!self.keep.is_empty() && self.row_masked[r]).then(|| &self.keep[r * nx..(r + 1) * nx]);
        let centre = (2 * g.dim) as Real;
        let gamma = self.cfg.gamma;
        let half = 0.5 * dt;
        let level = simd::level();
        let three = g.dim == 3;
        let mut acc = (0.0, 0.0);
        let mut run = |lo: usize, hi: usize, gam: Option<&[Real]>| {
            let (a, b) = simd::vectorized(
                level,
                #[inline(always)]
                || match (three, gam, keep) {
                    (false, None, None) => {
                        span::<false, false, false>(&w, up, lo, hi, k, centre, half, gamma, &[], &[])
                    }
                    (true, None, None) => span::<true, false, false>(&w, up, lo, hi, k, centre, half, gamma, &[], &[]),
                    (false, Some(gc), None) => {
                        span::<false, true, false>(&w, up, lo, hi, k, centre, half, gamma, gc, &[])
                    }
                    (true, Some(gc), None) => {
                        span::<true, true, false>(&w, up, lo, hi, k, centre, half, gamma, gc, &[])
                    }
                    (false, None, Some(m)) => {
                        span::<false, false, true>(&w, up, lo, hi, k, centre, half, gamma, &[], m)
                    }
                    (true, None, Some(m)) => span::<true, false, true>(&w, up, lo, hi, k, centre, half, gamma, &[], m),
                    (false, Some(gc), Some(m)) => {
                        span::<false, true, true>(&w, up, lo, hi, k, centre, half, gamma, gc, m)
                    }
                    (true, Some(gc), Some(m)) => {
                        span::<true, true, true>(&w, up, lo, hi, k, centre, half, gamma, gc, m)
                    }
                },
            );
            acc.0 += a;
            acc.1 += b;
        };
        if self.gamma_cells.is_empty() {
            run(0, nx, None);
        } else {
            let gc = &self.gamma_cells[r * nx..(r + 1) * nx];
            if self.row_in_layer[r] {
                run(0, nx, Some(gc));
            } else {
                let (lo, hi) = self.x_layer;
                run(0, lo, Some(gc));
                run(lo, hi, None);
                run(hi, nx, Some(gc));
            }
        }
        acc
    }
}

impl WaveSystem {
    /// Whether steps can be fused (`wave_fused`): 2D, undamped, no layers, obstacles or
    /// oscillators, y faces not periodic, at least 8 rows.
    fn fusable(&self) -> bool {
        let g = &self.cfg.grid;
        g.dim == 2
            && self.cfg.gamma == 0.0
            && self.gamma_cells.is_empty()
            && self.keep.is_empty()
            && self.cfg.oscillators.is_empty()
            && g.edges[2] != super::Edge::Periodic
            && g.rows() >= 8
    }

    /// The clock's books (damping, the sources' work, dt changes) overflowed while every cell is
    /// finite (a drop of 1e300 m): a halt, as a cell that is not finite is, so that the call is
    /// rolled back (a clock that is not finite could not be saved).
    fn books_halt(&self) -> Option<Halt> {
        let c = &self.clock;
        if c.dissipated.is_finite() && c.work.is_finite() && c.rescaled.is_finite() {
            return None;
        }
        let index = self
            .u
            .iter()
            .enumerate()
            .fold((0, -1.0), |(k, m), (i, v)| if v.abs() > m { (i, v.abs()) } else { (k, m) })
            .0;
        Some(Halt::Diverged { index, quantity: Failure::GridBooks })
    }

    /// `k` steps of `dt` in one sweep (`wave_fused`); `Err(j, halt)` names the step that
    /// diverged, j from 0. `Ok(false)`, with nothing changed, if the scratch cannot be had.
    fn step_fused(&mut self, dt: Real, k: usize) -> std::result::Result<bool, (u64, Halt)> {
        let kc = (self.cfg.c * dt / self.cfg.grid.dx).powi(2);
        let Some(ok) = wave_fused::sweep(&self.cfg.grid, kc, k, &mut self.u, &mut self.u_prev, &mut self.fused) else {
            return Ok(false);
        };
        // u_prev holds uⁿ⁺ᵏ and u uⁿ⁺ᵏ⁻¹.
        std::mem::swap(&mut self.u, &mut self.u_prev);
        for (j, fine) in ok[..k].iter().enumerate() {
            self.clock.t += dt;
            if !fine {
                let index = first_non_finite(&self.u).or_else(|| first_non_finite(&self.u_prev)).unwrap_or(0);
                return Err((j as u64, Halt::Diverged { index, quantity: Failure::Cell }));
            }
        }
        Ok(true)
    }
}

/// Leapfrog over cells [lo, hi) of one row: `D3` adds the z neighbours, `G` reads γ per cell
/// (`gc`), `M` zeroes obstacle cells (`keep`). Returns (Σ u⁺, Σ γ (u⁺ − u⁻)²).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn span<const D3: bool, const G: bool, const M: bool>(
    w: &Row,
    up: &mut [Real],
    lo: usize,
    hi: usize,
    k: Real,
    centre: Real,
    half_dt: Real,
    gamma: Real,
    gc: &[Real],
    keep: &[Real],
) -> (Real, Real) {
    let nx = w.u.len();
    if lo >= hi {
        return (0.0, 0.0);
    }
    let (a0, inv0) = (gamma * half_dt, 1.0 / (1.0 + gamma * half_dt));
    let [fs, fn_, fd, fu] = w.f;
    let cell = |i: usize, left: Real, right: Real, um: Real| -> (Real, Real) {
        let mut lap = left + right + fs * w.south[i] + fn_ * w.north[i] - centre * w.u[i];
        if D3 {
            lap += fd * w.down[i] + fu * w.up[i];
        }
        let (a, inv, g) = if G { (gc[i] * half_dt, 1.0 / (1.0 + gc[i] * half_dt), gc[i]) } else { (a0, inv0, gamma) };
        let mut new = (2.0 * w.u[i] - (1.0 - a) * um + k * lap) * inv;
        if M {
            new *= keep[i];
        }
        (new, g * (new - um) * (new - um))
    };
    let (mut sum, mut diss) = (0.0, 0.0);
    // The row's ends read the ghost cells; the middle is one straight loop LLVM vectorises.
    let first = lo.max(1);
    let last = hi.min(nx - 1);
    for i in lo..first.min(hi) {
        let (n, d) = cell(i, w.ghost[0], if nx > 1 { w.u[1] } else { w.ghost[1] }, up[i]);
        up[i] = n;
        sum += n;
        diss += d;
    }
    if first < last && !G && gamma == 0.0 {
        // Undamped: a = 0, so (2u − (1 − a)u⁻ + k·L)/(1 + a) is 2u − u⁻ + k·L bit for bit; one
        // straight loop over slices that LLVM vectorises.
        let n = last - first;
        let (l, c, r) = (&w.u[first - 1..][..n], &w.u[first..][..n], &w.u[first + 1..][..n]);
        let (s, no) = (&w.south[first..][..n], &w.north[first..][..n]);
        let (d, t) = if D3 { (&w.down[first..][..n], &w.up[first..][..n]) } else { (s, s) };
        let km = if M { &keep[first..][..n] } else { c };
        let out = &mut up[first..][..n];
        for i in 0..n {
            let mut lap = l[i] + r[i] + fs * s[i] + fn_ * no[i] - centre * c[i];
            if D3 {
                lap += fd * d[i] + fu * t[i];
            }
            let mut new = 2.0 * c[i] - out[i] + k * lap;
            if M {
                new *= km[i];
            }
            out[i] = new;
        }
        sum += super::lanes_sum(out);
    } else if first < last {
        for i in first..last {
            let (n, d) = cell(i, w.u[i - 1], w.u[i + 1], up[i]);
            up[i] = n;
            sum += n;
            diss += d;
        }
    }
    for i in last.max(first)..hi {
        let (n, d) = cell(i, w.u[i - 1], w.ghost[1], up[i]);
        up[i] = n;
        sum += n;
        diss += d;
    }
    (sum, diss)
}

impl System for WaveSystem {
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
        self.change_dt(dt);
        self.drop_due(dt);
        let g = &self.cfg.grid;
        let nx = g.n[0];
        let k = (self.cfg.c * dt / g.dx).powi(2);
        // u⁻ at the driven cells, before the row pass overwrites it with u⁺.
        let mut at = 0;
        for o in &self.cfg.oscillators {
            for &(c, _) in &o.profile {
                self.src_prev[at] = self.u_prev[c];
                at += 1;
            }
        }
        let mut up = std::mem::take(&mut self.u_prev);
        let mut partials = std::mem::take(&mut self.partials);
        let this = &*self;
        rows_each(&mut up, nx, &mut partials, |r, row| this.update_row(r, row, k, dt));
        self.u_prev = up;
        // Row order: the same sums for any thread count.
        let (mut sum, mut diss) = (0.0, 0.0);
        for &(s, d) in &partials {
            sum += s;
            diss += d;
        }
        self.partials = partials;
        // Now u_prev holds u⁺: swap so that u is the new level and u_prev the old one.
        std::mem::swap(&mut self.u, &mut self.u_prev);
        let da = g.cell_measure();
        let inv4dt = 0.25 / dt;
        self.clock.dissipated += diss * inv4dt * da;
        // Sources, cell by cell in a fixed order: add dt² f/(1 + a) to u⁺, book their work and
        // correct the damping booked with the unforced u⁺.
        let t = self.clock.t;
        let mut at = 0;
        for o in &self.cfg.oscillators {
            let f = o.amplitude * (2.0 * PI * o.frequency * t + o.phase).sin();
            for &(c, wgt) in &o.profile {
                let um = self.src_prev[at];
                at += 1;
                if !self.keep.is_empty() && self.keep[c] == 0.0 {
                    continue;
                }
                let gam = if self.gamma_cells.is_empty() { self.cfg.gamma } else { self.gamma_cells[c] };
                let before = self.u[c];
                self.u[c] += dt * dt * f * wgt / (1.0 + 0.5 * gam * dt);
                let (vb0, vb1) = ((before - um) / (2.0 * dt), (self.u[c] - um) / (2.0 * dt));
                self.clock.dissipated += dt * gam * (vb1 * vb1 - vb0 * vb0) * da;
                self.clock.work += dt * f * wgt * vb1 * da;
                sum += self.u[c] - before;
            }
        }
        self.clock.t += dt;
        // Σ u⁺ can overflow where no cell does: a cell that is not finite halts, as in `steps`.
        if !sum.is_finite() {
            if let Some(index) = first_non_finite(&self.u) {
                return Err(Halt::Diverged { index, quantity: Failure::Cell });
            }
        }
        self.books_halt().map_or(Ok(()), Err)
    }
    /// Up to `wave_fused::FUSE` steps per sweep over memory where `fusable`, with the bits of
    /// single steps; a drop that falls due ends a sweep.
    fn steps(&mut self, n: u64, dt: Real, stop: &AtomicBool) -> std::result::Result<(), (u64, Halt)> {
        let mut i = 0;
        while i < n {
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Err((i, Halt::Stopped));
            }
            if i + 1 < n && dt == self.clock.dt && self.fusable() {
                self.drop_due(dt);
                // Steps before the next drop falls due (as `drop_due` would see it at each).
                let cap = (n - i).min(wave_fused::FUSE as u64) as usize;
                let next = self.cfg.drops.get(self.clock.next_drop).map(|d| d.t);
                let (mut k, mut t) = (1, self.clock.t);
                while k < cap {
                    t += dt;
                    if next.is_some_and(|d| d < t + dt) {
                        break;
                    }
                    k += 1;
                }
                if k >= 2 && self.step_fused(dt, k).map_err(|(j, h)| (i + j, h))? {
                    i += k as u64;
                    if let Some(h) = self.books_halt() {
                        return Err((i - 1, h));
                    }
                    continue;
                }
            }
            self.step(dt, stop).map_err(|h| (i, h))?;
            i += 1;
        }
        Ok(())
    }
    fn auto_dt(&self) -> Option<Real> {
        Some(self.cfg.cfl * self.cfl_limit())
    }
    fn suggest_dt(&self) -> Option<Real> {
        Some(self.cfg.cfl * self.cfl_limit())
    }
    fn energy(&self) -> EnergyReport {
        let (kinetic, potential) = self.energies();
        let mut dissipated = vec![(format!("{} damping", self.cfg.name), self.clock.dissipated)];
        if !(self.cfg.drops.is_empty() && self.cfg.oscillators.is_empty()) {
            dissipated.push((format!("{} sources", self.cfg.name), -self.clock.work));
        }
        dissipated.push((format!("{} dt changes", self.cfg.name), -self.clock.rescaled));
        EnergyReport { kinetic, potential: vec![(self.cfg.name.clone(), potential)], dissipated }
    }
    /// "u" (m; the velocity is kept) or "velocity" (m/s, at the half step before now).
    fn set_field(&mut self, name: &str, values: &[Real]) -> Result<()> {
        match name {
            "u" => self.set_state(values, None),
            "velocity" => {
                let u = self.u.clone();
                self.set_state(&u, Some(values))
            }
            _ => Err(invalid("field", format!("{name:?}: a wave's settable fields are \"u\" and \"velocity\""))),
        }
    }
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        let n = self.u.len();
        let need = Need::fields(names, n, "grid cells");
        names
            .iter()
            .map(|name| match *name {
                "u" => need.copy(&self.u),
                "velocity" => self.velocity(&need),
                // 1 on obstacle cells (`keep` is empty without a mask).
                "mask" if self.keep.is_empty() => need.filled(n, 0.0),
                "mask" => need.collect(self.keep.iter().map(|k| 1.0 - k)),
                _ => need.filled(n, 0.0),
            })
            .collect()
    }
    fn snapshot(&self) -> Result<Snapshot> {
        self.spare.snapshot2(&self.u, &self.u_prev, self.clock)
    }
    fn restore(&mut self, snapshot: Snapshot) {
        let (u, up, clock) =
            *snapshot.downcast::<(Vec<Real>, Vec<Real>, Clock)>().expect("a snapshot of this wave system");
        (self.u, self.u_prev, self.clock) = (u, up, clock);
    }
    fn recycle(&mut self, snapshot: Snapshot) {
        self.spare.recycle2::<Clock>(snapshot);
    }
    fn save(&self) -> Result<Arrays> {
        let c = &self.clock;
        let clock = [c.t, c.dt, c.dissipated, c.work, c.next_drop as Real];
        let of = format!("the wave's fields of {} cells", count(self.u.len() as u128));
        let arrays = [("u", &self.u[..]), ("u_prev", &self.u_prev), ("clock", &clock), ("dt_changes", &[c.rescaled])];
        crate::systems::saved(of, &arrays)
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let n = self.u.len();
        let u = array(arrays, "u", Some(n))?;
        let up = array(arrays, "u_prev", Some(n))?;
        let c = array(arrays, "clock", Some(5))?;
        // Absent from files written before the changes of dt were booked (none was, then).
        let changes = match arrays.iter().any(|(n, _)| n == "dt_changes") {
            true => array(arrays, "dt_changes", Some(1))?,
            false => &[0.0][..],
        };
        for (name, a) in [("u", u), ("u_prev", up), ("clock", c), ("dt_changes", changes)] {
            if let Some(i) = first_non_finite(a) {
                return Err(invalid(name, format!("value {i} is not finite: {}", a[i])));
            }
        }
        if !(c[1] > 0.0) {
            return Err(invalid("clock", format!("dt {} must be > 0", c[1])));
        }
        if !(c[4] >= 0.0 && c[4] <= self.cfg.drops.len() as Real && c[4].fract() == 0.0) {
            return Err(invalid(
                "clock",
                format!("drops applied {} must be a count in [0, {}]", c[4], self.cfg.drops.len()),
            ));
        }
        self.u.copy_from_slice(u);
        self.u_prev.copy_from_slice(up);
        let rescaled = changes[0];
        self.clock = Clock { t: c[0], dt: c[1], dissipated: c[2], work: c[3], next_drop: c[4] as usize, rescaled };
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grids::Edge;
    use std::sync::Arc;

    fn square(n: usize, l: Real, edges: Edge) -> WaveConfig {
        WaveConfig::new("wave", Grid::new(&[n, n], l / n as Real, &[edges; 4]).unwrap(), 1.0)
    }

    fn steps(w: &mut WaveSystem, n: usize, dt: Real) {
        let stop = AtomicBool::new(false);
        for _ in 0..n {
            w.step(dt, &stop).unwrap();
        }
    }

    /// The (m, k) mode of a fixed square membrane and its discrete angular frequency.
    fn mode(n: usize, m: Real, k: Real, c_num: Real) -> (Vec<Real>, Real) {
        let nf = n as Real;
        let u = (0..n * n)
            .map(|c| {
                let (i, j) = ((c % n) as Real + 0.5, (c / n) as Real + 0.5);
                (m * PI * i / nf).sin() * (k * PI * j / nf).sin()
            })
            .collect();
        let s = c_num * ((m * PI / (2.0 * nf)).sin().powi(2) + (k * PI / (2.0 * nf)).sin().powi(2)).sqrt();
        (u, 2.0 * s.asin())
    }

    /// Runs the (m, k) mode and measures ω dt from the recurrence a⁺ + a⁻ = 2 cos(ω dt) a.
    fn measured(n: usize, m: Real, k: Real, c_num: Real, n_steps: usize) -> (Real, Real) {
        let mut w = WaveSystem::new(square(n, 1.0, Edge::Fixed)).unwrap();
        let dt = c_num * w.cfg.grid.dx / w.cfg.c;
        w.clock.dt = dt;
        let (shape, wdt) = mode(n, m, k, c_num);
        let up: Vec<Real> = shape.iter().map(|s| s * wdt.cos()).collect();
        let v: Vec<Real> = shape.iter().zip(&up).map(|(a, b)| (a - b) / dt).collect();
        w.set_state(&shape, Some(&v)).unwrap();
        let norm: Real = shape.iter().map(|s| s * s).sum();
        let mut a = vec![1.0];
        for _ in 0..n_steps {
            steps(&mut w, 1, dt);
            a.push(w.u.iter().zip(&shape).map(|(x, s)| x * s).sum::<Real>() / norm);
        }
        let (mut num, mut den) = (0.0, 0.0);
        for i in 1..a.len() - 1 {
            num += a[i] * (a[i + 1] + a[i - 1]);
            den += 2.0 * a[i] * a[i];
        }
        ((num / den).acos() / dt, wdt / dt)
    }

    #[test]
    fn standing_mode_follows_the_discrete_dispersion_relation() {
        for (m, k) in [(1.0, 1.0), (2.0, 3.0)] {
            let (omega, discrete) = measured(32, m, k, 0.5, 400);
            assert!(((omega - discrete) / discrete).abs() < 1e-6, "({m},{k}): {omega} vs {discrete}");
        }
    }

    /// The discrete frequency converges to cπ√(m²+k²)/L at second order in dx (fixed c dt/dx).
    #[test]
    fn standing_mode_converges_at_second_order() {
        let exact = PI * (1.0f64 + 4.0).sqrt();
        let errs: Vec<Real> =
            [16, 32, 64].iter().map(|&n| (measured(n, 1.0, 2.0, 0.5, 200).0 - exact).abs() / exact).collect();
        for p in errs.windows(2) {
            let order = (p[0] / p[1]).log2();
            assert!((order - 2.0).abs() < 0.05, "observed order {order} ({errs:?})");
        }
    }

    fn bumpy(w: &mut WaveSystem) {
        let n = w.u.len();
        let nx = w.cfg.grid.n[0];
        let u: Vec<Real> = (0..n)
            .map(|c| {
                let (x, y) = ((c % nx) as Real / nx as Real - 0.4, (c / nx) as Real / nx as Real - 0.55);
                (-(x * x + y * y) / 0.005).exp()
            })
            .collect();
        w.set_state(&u, Some(&vec![0.0; n])).unwrap();
    }

    fn total(w: &WaveSystem) -> Real {
        w.energy().total()
    }

    #[test]
    fn energy_is_conserved_to_round_off_for_every_edge_rule() {
        for edge in [Edge::Fixed, Edge::Free, Edge::Periodic] {
            let mut w = WaveSystem::new(square(48, 1.0, edge)).unwrap();
            let dt = w.auto_dt().unwrap();
            bumpy(&mut w);
            let e0 = total(&w);
            let mut worst: Real = 0.0;
            for _ in 0..20 {
                steps(&mut w, 50, dt);
                worst = worst.max(((total(&w) - e0) / e0).abs());
            }
            assert!(worst < 1e-12, "{edge:?}: drift {worst:e}");
        }
    }

    /// A change of dt keeps the velocity and moves the discrete energy's potential; the books
    /// hold the move, so their total holds across changes as across steps (and a file keeps it).
    #[test]
    fn changes_of_dt_are_booked_and_the_total_holds() {
        let mut w = WaveSystem::new(square(48, 1.0, Edge::Free)).unwrap();
        let dt = w.auto_dt().unwrap();
        bumpy(&mut w);
        steps(&mut w, 30, dt);
        let e0 = total(&w);
        let book = |w: &WaveSystem| w.energy().dissipated.iter().find(|d| d.0 == "wave dt changes").unwrap().1;
        assert_eq!(book(&w), 0.0);
        let need = Need::new("test", 0, "velocity");
        for f in [0.6, 0.97, 0.31, 1.0, 0.5] {
            let v0 = w.velocity(&need).unwrap();
            w.change_dt(f * dt);
            let v1 = w.velocity(&need).unwrap();
            assert!(v0.iter().zip(&v1).all(|(a, b)| (a - b).abs() <= 1e-12 * (1.0 + a.abs())), "the velocity is kept");
            steps(&mut w, 7, f * dt);
            let drift = ((total(&w) - e0) / e0).abs();
            assert!(drift < 1e-12, "after steps at {f} dt: drift {drift:e}");
        }
        // The book holds something a plain total would have lost (not a vanishing correction).
        assert!(book(&w).abs() > 1e-4 * e0, "book {:e} of {e0:e}", book(&w));
        // Saved and loaded, the book comes back; a file without it (written before it) reads 0.
        let saved = w.save().unwrap();
        let mut back = WaveSystem::new(square(48, 1.0, Edge::Free)).unwrap();
        back.load(&saved).unwrap();
        assert_eq!(book(&back), book(&w));
        assert_eq!(total(&back), total(&w));
        let old: Arrays = saved.into_iter().filter(|(n, _)| n != "dt_changes").collect();
        back.load(&old).unwrap();
        assert_eq!(book(&back), 0.0);
        let bad: Arrays = w
            .save()
            .unwrap()
            .into_iter()
            .map(|(n, a)| if n == "dt_changes" { (n, vec![0.0, 1.0]) } else { (n, a) })
            .collect();
        assert!(back.load(&bad).unwrap_err().to_string().contains("dt_changes"));
    }

    #[test]
    fn damping_sources_and_obstacles_keep_the_books_balanced() {
        let mut cfg = square(40, 1.0, Edge::Free);
        cfg.gamma = 0.7;
        cfg.absorbing = [true, false, true, false, false, false];
        cfg.layer = 6;
        cfg.mask = Some((0..1600).map(|c| c % 40 == 20 && !(18..22).contains(&(c / 40))).collect());
        cfg.drops = vec![Drop { t: 0.05, amplitude: 0.3, profile: vec![(410, 1.0), (411, 0.5)] }];
        cfg.oscillators =
            vec![Oscillator { amplitude: 40.0, frequency: 3.0, phase: 0.2, profile: vec![(1205, 1.0), (1245, 0.7)] }];
        let mut w = WaveSystem::new(cfg).unwrap();
        let dt = w.auto_dt().unwrap();
        let e0 = total(&w);
        steps(&mut w, 400, dt);
        let e = w.energy();
        let scale = e.kinetic.abs() + e.dissipated.iter().map(|d| d.1.abs()).sum::<Real>();
        assert!(scale > 1e-3, "something happened: {e:?}");
        assert!(((e.total() - e0) / scale).abs() < 1e-12, "{e:?}");
        assert!(w.u.iter().enumerate().all(|(c, &u)| c % 40 != 20 || (18..22).contains(&(c / 40)) || u == 0.0));
    }

    #[test]
    fn just_above_the_cfl_limit_diverges_and_just_below_does_not() {
        let mut w = WaveSystem::new(square(32, 1.0, Edge::Fixed)).unwrap();
        bumpy(&mut w);
        let limit = w.cfl_limit();
        let stop = AtomicBool::new(false);
        let mut below = WaveSystem::new(square(32, 1.0, Edge::Fixed)).unwrap();
        bumpy(&mut below);
        let e0 = total(&below);
        steps(&mut below, 5000, 0.99 * limit);
        assert!((total(&below) - e0).abs() < 1e-9 * e0);
        let diverged = (0..20000).find_map(|_| w.step(1.01 * limit, &stop).err());
        assert!(matches!(diverged, Some(Halt::Diverged { quantity: Failure::Cell, .. })), "{diverged:?}");
    }

    fn run_threads(threads: usize) -> (Vec<Real>, Real) {
        let pool = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap());
        crate::par::install(Some(&pool), || {
            let mut cfg = square(160, 1.0, Edge::Fixed);
            cfg.gamma = 0.1;
            cfg.absorbing = [false, true, false, true, false, false];
            let mut w = WaveSystem::new(cfg).unwrap();
            bumpy(&mut w);
            let dt = w.auto_dt().unwrap();
            steps(&mut w, 30, dt);
            (w.u.clone(), w.energy().total())
        })
    }

    #[test]
    fn bit_identical_for_any_thread_count() {
        let (a, ea) = run_threads(1);
        let (b, eb) = run_threads(3);
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
        assert_eq!(ea.to_bits(), eb.to_bits());
    }

    #[test]
    fn restore_and_load_continue_bit_identically() {
        let mut cfg = square(24, 1.0, Edge::Free);
        cfg.drops = vec![Drop { t: 0.1, amplitude: 0.3, profile: vec![(100, 1.0)] }];
        let mut w = WaveSystem::new(cfg.clone()).unwrap();
        bumpy(&mut w);
        let dt = w.auto_dt().unwrap();
        steps(&mut w, 5, dt);
        let snap = w.snapshot().unwrap();
        let saved = w.save().unwrap();
        steps(&mut w, 40, dt);
        let a = w.u.clone();
        w.restore(snap);
        steps(&mut w, 40, dt);
        assert_eq!(a, w.u);
        let mut fresh = WaveSystem::new(cfg).unwrap();
        fresh.load(&saved).unwrap();
        steps(&mut fresh, 40, dt);
        assert_eq!(a, fresh.u);
    }

    /// Two equal systems of `cfg`, bumpy, and the automatic step they are set to.
    fn twins(cfg: WaveConfig) -> (WaveSystem, WaveSystem, Real) {
        let (mut one, mut two) = (WaveSystem::new(cfg.clone()).unwrap(), WaveSystem::new(cfg).unwrap());
        bumpy(&mut one);
        bumpy(&mut two);
        let dt = one.auto_dt().unwrap();
        one.clock.dt = dt;
        two.clock.dt = dt;
        (one, two, dt)
    }

    /// Fused steps give the bits of single steps, for every edge rule that fuses, any thread
    /// count (band split), step counts that are not a multiple of the fusion and drops falling
    /// between or inside sweeps.
    #[test]
    fn fused_steps_give_the_bits_of_single_steps() {
        let shapes = [[67, 45], [40, 300]]; // one band; four with 3 threads
        for (edges, shape) in
            [[Edge::Fixed; 4], [Edge::Free; 4], [Edge::Periodic, Edge::Periodic, Edge::Free, Edge::Fixed]]
                .into_iter()
                .flat_map(|e| shapes.map(|s| (e, s)))
        {
            for threads in [1, 2, 3] {
                let pool = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap());
                crate::par::install(Some(&pool), || {
                    let dx = 1.0 / shape[1] as Real;
                    let mut cfg = WaveConfig::new("w", Grid::new(&shape, dx, &edges).unwrap(), 1.0);
                    cfg.drops = (0..5)
                        .map(|d| Drop { t: 0.013 * d as Real, amplitude: 0.2, profile: vec![(100 + 300 * d, 1.0)] })
                        .collect();
                    let (mut one, mut two, dt) = twins(cfg);
                    assert!(two.fusable());
                    let stop = AtomicBool::new(false);
                    for _ in 0..41 {
                        one.step(dt, &stop).unwrap();
                    }
                    two.steps(41, dt, &stop).unwrap();
                    assert!(
                        one.u.iter().zip(&two.u).all(|(a, b)| a.to_bits() == b.to_bits()),
                        "{edges:?} {shape:?} {threads}"
                    );
                    assert!(one.u_prev.iter().zip(&two.u_prev).all(|(a, b)| a.to_bits() == b.to_bits()));
                    assert_eq!(one.clock, two.clock);
                });
            }
        }
    }

    /// Each sweep length on its own, over four bands.
    #[test]
    fn every_sweep_length_gives_the_bits_of_single_steps() {
        let pool = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap());
        crate::par::install(Some(&pool), || {
            for k in 2..=wave_fused::FUSE {
                let cfg = WaveConfig::new("w", Grid::new(&[50, 290], 1.0 / 290.0, &[Edge::Fixed; 4]).unwrap(), 1.0);
                let (mut one, mut two, dt) = twins(cfg);
                let stop = AtomicBool::new(false);
                for _ in 0..k {
                    one.step(dt, &stop).unwrap();
                }
                assert_eq!(two.step_fused(dt, k), Ok(true));
                let same = |a: &[Real], b: &[Real]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
                assert!(same(&one.u, &two.u) && same(&one.u_prev, &two.u_prev), "{k} steps");
                assert_eq!(one.clock, two.clock);
            }
        });
    }

    #[test]
    fn fused_steps_report_the_step_that_diverged() {
        let mut w = WaveSystem::new(square(32, 1.0, Edge::Fixed)).unwrap();
        bumpy(&mut w);
        let dt = 1.01 * w.cfl_limit();
        w.clock.dt = dt;
        let mut single = WaveSystem::new(square(32, 1.0, Edge::Fixed)).unwrap();
        bumpy(&mut single);
        single.clock.dt = dt;
        let stop = AtomicBool::new(false);
        let first = (0..20000u64).find(|_| single.step(dt, &stop).is_err()).unwrap();
        match w.steps(20000, dt, &stop) {
            Err((i, Halt::Diverged { quantity: Failure::Cell, .. })) => assert_eq!(i, first),
            other => panic!("{other:?}"),
        }
    }

    /// A 3D box: the same code, 7-point stencil, CFL 1/√3.
    #[test]
    fn three_dimensional_mode_and_energy() {
        let g = Grid::new(&[12, 10, 8], 0.1, &[Edge::Fixed; 6]).unwrap();
        let mut w = WaveSystem::new(WaveConfig::new("w3", g, 2.0)).unwrap();
        assert!((w.cfl_limit() - 0.1 / (2.0 * 3f64.sqrt())).abs() < 1e-15);
        let n = w.u.len();
        let u: Vec<Real> = (0..n).map(|c| ((c * 7 % 13) as Real * 0.1).sin()).collect();
        w.set_state(&u, None).unwrap();
        let e0 = total(&w);
        let dt = w.auto_dt().unwrap();
        steps(&mut w, 300, dt);
        assert!(((total(&w) - e0) / e0).abs() < 1e-12);
    }

    #[test]
    fn bad_configs_name_the_argument() {
        let mut c = square(8, 1.0, Edge::Fixed);
        c.c = -1.0;
        assert!(matches!(WaveSystem::new(c).err(), Some(crate::Error::InvalidInput { arg, .. }) if arg == "c"));
        let mut c = square(8, 1.0, Edge::Fixed);
        c.absorbing[0] = true;
        c.layer = 5;
        assert!(matches!(WaveSystem::new(c).err(), Some(crate::Error::InvalidInput { arg, .. }) if arg == "layer"));
        let mut c = square(8, 1.0, Edge::Fixed);
        c.oscillators.push(Oscillator { amplitude: 1.0, frequency: 1.0, phase: 0.0, profile: vec![(64, 1.0)] });
        assert!(
            matches!(WaveSystem::new(c).err(), Some(crate::Error::InvalidInput { arg, .. }) if arg == "oscillators")
        );
    }
}
