//! Symmetric 5-point systems on a 2D grid of unknowns, solved by preconditioned conjugate
//! gradients: the pressure Poisson equation of [`super::fluid`] (preconditioned by one
//! geometric multigrid V-cycle, MGPCG: McAdams, Sifakis & Teran, "A parallel multigrid Poisson
//! solver for fluids simulation on large grids", SCA 2010) and its implicit viscosity
//! (preconditioned by the diagonal).
//!
//! Unknowns live on an `nx × ny` grid stored **padded** by one ghost ring of zeros:
//! unknown (i, j) is at `(i + 1) + (nx + 2)·(j + 1)`. The operator is
//!
//! (A x)_c = (d0_c + s·count_c)·x_c − s·Σ_nb w_{c,nb}·x_nb
//!
//! with link weights w (0 or 1 on the fine level: a link to a closed neighbour or a wall is
//! 0), `count_c` the diagonal of the graph Laplacian plus what Dirichlet neighbours and ghost
//! rules add, `d0` an identity part (1 for viscosity, pins and solid cells for pressure) and
//! `s` a scale. A is symmetric; it is positive definite once every connected component of the
//! pressure graph is pinned (see [`Stencil::pin`]).
//!
//! Determinism: every reduction (dot product) is summed per row, then over rows in row order
//! (`grids::rows_sum`, `grids::sum_rows`), so results are bit-identical for any thread count.
use super::{rows2_sum, rows_sum, sum_rows};
use crate::alloc::{count, Need};
use crate::error::Result;
use crate::par::Shared;
use crate::simd;
use crate::vector::Real;
use std::sync::atomic::{AtomicBool, Ordering};

/// Damped-Jacobi weight of the multigrid smoother (4/5 is the optimal smoothing weight of the
/// 2D 5-point Laplacian).
const OMEGA: Real = 0.8;
/// Smoothing sweeps before and after the coarse correction (even: sweeps alternate buffers).
const SWEEPS: usize = 2;
/// Sweeps on the coarsest level (even).
const COARSE_SWEEPS: usize = 32;
/// The coarse operator is this times the Galerkin one, P^T A P. With piecewise-constant P,
/// P^T A P is twice the Laplacian rediscretised on the coarse grid, so the Galerkin coarse
/// correction of a smooth error is half of it; ½ restores it (the correction term stays
/// positive semi-definite, so the V-cycle is still a valid CG preconditioner).
const COARSE_SCALE: Real = 0.5;
/// Iterations without the residual norm falling by 10 % after which a solve gives up.
const STALLED: usize = 100;
/// Coarsening stops once a side has at most this many cells.
const COARSEST: usize = 4;

/// A 5-point operator on padded arrays (see the module docs).
#[derive(Clone, Debug)]
pub struct Stencil {
    pub nx: usize,
    pub ny: usize,
    /// Padded row length, nx + 2.
    pub w: usize,
    /// Whether each unknown is free (false: a fixed row, x = b).
    pub open: Vec<bool>,
    /// Link weight to the east and north neighbour (unscaled).
    we: Vec<Real>,
    wn: Vec<Real>,
    /// Unscaled diagonal of the neighbour part, and the identity part.
    count: Vec<Real>,
    d0: Vec<Real>,
    /// Scaled: d0 + s·count, and its inverse (the links are scaled in the kernels).
    diag: Vec<Real>,
    inv_diag: Vec<Real>,
    scale: Real,
}

fn padded_len(nx: usize, ny: usize) -> usize {
    (nx + 2) * (ny + 2)
}

impl Stencil {
    /// A stencil on `nx × ny` unknowns. `open(i, j)`: whether unknown (i, j) is free.
    /// `wall`: what the count of an open unknown gains for a side beyond the grid, per side
    /// [east (x+), west (x−), north (y+), south (y−)] (0: Neumann / free slip / zero gradient;
    /// 1: Dirichlet 0 one cell beyond, e.g. an open boundary's pressure; 2: a no-slip ghost
    /// −u). `closed_counts`: whether a closed neighbour (held at 0) adds 1 to the count
    /// (Dirichlet) or nothing (Neumann). `d0_open`: the identity part of open unknowns (closed
    /// ones get 1).
    pub fn build(
        nx: usize,
        ny: usize,
        open: &dyn Fn(usize, usize) -> bool,
        wall: [Real; 4],
        closed_counts: bool,
        d0_open: Real,
    ) -> Result<Self> {
        let w = nx + 2;
        let n = padded_len(nx, ny);
        let need =
            Need::new("fluid", Need::bytes_of::<Real>(7 * n), format!("a solver of {} unknowns", count(n as u128)));
        need.check()?;
        let mut s = Self {
            nx,
            ny,
            w,
            open: need.filled(n, false)?,
            we: need.filled(n, 0.0)?,
            wn: need.filled(n, 0.0)?,
            count: need.filled(n, 0.0)?,
            d0: need.filled(n, 1.0)?,
            diag: need.filled(n, 1.0)?,
            inv_diag: need.filled(n, 1.0)?,
            scale: 1.0,
        };
        for j in 0..ny {
            for i in 0..nx {
                s.open[(i + 1) + w * (j + 1)] = open(i, j);
            }
        }
        for j in 0..ny {
            for i in 0..nx {
                let c = (i + 1) + w * (j + 1);
                if !s.open[c] {
                    continue;
                }
                let mut k = 0.0;
                let sides = [(c + 1, i + 1 < nx), (c - 1, i > 0), (c + w, j + 1 < ny), (c - w, j > 0)];
                for ((nb, inside), beyond) in sides.into_iter().zip(wall) {
                    if !inside {
                        k += beyond;
                    } else if s.open[nb] || closed_counts {
                        // An open neighbour, or a closed one held at 0 (Dirichlet).
                        k += 1.0;
                    }
                }
                s.count[c] = k;
                s.d0[c] = d0_open;
                if i + 1 < nx && s.open[c + 1] {
                    s.we[c] = 1.0;
                }
                if j + 1 < ny && s.open[c + w] {
                    s.wn[c] = 1.0;
                }
            }
        }
        s.set_scale(1.0);
        Ok(s)
    }

    /// The part of unknown c's count that no link carries: what Dirichlet sides (an open
    /// boundary, a counted closed neighbour) add to the diagonal. 0 for a pure-Neumann row.
    fn held(&self, c: usize) -> Real {
        let w = self.w;
        self.count[c] - (self.we[c] + self.we[c - 1] + self.wn[c] + self.wn[c - w])
    }

    /// Pins one unknown of every connected component of open unknowns that has neither an
    /// identity part nor a Dirichlet side (adds 1 to its d0), making a pure-Neumann operator
    /// definite. If the right-hand side sums to zero over the component (a compatible Poisson
    /// problem), the solution is unchanged: summing the rows of the component gives x_pin = 0.
    ///
    /// `Error::OutOfMemory` (naming "fluid") if its flood fill's buffers cannot be had: they
    /// are sized by the grid (a flag per unknown; the stack, up to one entry per unknown).
    pub fn pin(&mut self) -> Result<()> {
        let w = self.w;
        let n = self.open.len();
        let need = Need::new(
            "fluid",
            Need::bytes_of::<bool>(n) + Need::bytes_of::<usize>(n),
            format!("a solver of {} unknowns", count(n as u128)),
        );
        let mut seen = need.filled(n, false)?;
        let mut stack: Vec<usize> = Vec::new();
        need.reserve(&mut stack, n.min(64))?;
        for c0 in 0..n {
            if !self.open[c0] || seen[c0] {
                continue;
            }
            let mut definite = false;
            seen[c0] = true;
            stack.push(c0); // room: the stack is empty here, and keeps the capacity it grew to
            while let Some(c) = stack.pop() {
                definite |= self.d0[c] > 0.0 || self.held(c) > 0.0;
                let links =
                    [(c + 1, self.we[c]), (c - 1, self.we[c - 1]), (c + w, self.wn[c]), (c - w, self.wn[c - w])];
                for (nb, wt) in links {
                    if wt > 0.0 && !seen[nb] {
                        seen[nb] = true;
                        // Grown fallibly, doubling (at most n entries: each unknown is pushed once).
                        if stack.len() == stack.capacity() {
                            let grown = (2 * stack.capacity()).min(n);
                            need.reserve(&mut stack, grown)?;
                        }
                        stack.push(nb);
                    }
                }
            }
            if !definite {
                self.d0[c0] += 1.0;
            }
        }
        self.set_scale(self.scale);
        Ok(())
    }

    /// Sets s (e.g. ν·dt/dx² for viscosity) and the scaled coefficients.
    pub fn set_scale(&mut self, s: Real) {
        self.scale = s;
        let (d0, count) = (&self.d0, &self.count);
        crate::par::chunks2(&mut self.diag, &mut self.inv_diag, |at, dg, inv| {
            for k in 0..dg.len() {
                dg[k] = d0[at + k] + s * count[at + k];
                inv[k] = 1.0 / dg[k];
            }
        });
    }

    /// Adds `extra` to the count of unknown (i, j) (a Dirichlet side's share that no link
    /// carries); call `set_scale` after.
    pub fn add_held(&mut self, i: usize, j: usize, extra: Real) {
        let c = (i + 1) + self.w * (j + 1);
        self.count[c] += extra;
    }

    pub fn len(&self) -> usize {
        self.open.len()
    }

    /// The unscaled coefficients, padded: east and north links, the identity part and the
    /// neighbour count (the diagonal is d0 + s·count): what the device's solver is given.
    pub fn coefficients(&self) -> [&[Real]; 4] {
        [&self.we, &self.wn, &self.d0, &self.count]
    }
    pub fn is_empty(&self) -> bool {
        self.open.is_empty()
    }

    /// The coarse operator of piecewise-constant interpolation, `COARSE_SCALE`·P^T A P: a
    /// coarse cell is open if any child is; the weight of a coarse link is the sum of the fine
    /// links crossing it, and its identity part the sum of its children's identity and
    /// Dirichlet parts (`held`), times the scale.
    fn coarsen(&self) -> Result<Self> {
        let (nx, ny) = (self.nx.div_ceil(2), self.ny.div_ceil(2));
        let (w, fw) = (nx + 2, self.w);
        let f = |i: usize, j: usize| (i + 1) + fw * (j + 1);
        let fluid = |i: usize, j: usize| {
            let mut any = false;
            for b in 2 * j..(2 * j + 2).min(self.ny) {
                for a in 2 * i..(2 * i + 2).min(self.nx) {
                    any |= self.open[f(a, b)];
                }
            }
            any
        };
        let mut s = Self::build(nx, ny, &fluid, [0.0; 4], false, 0.0)?;
        for j in 0..ny {
            for i in 0..nx {
                let c = (i + 1) + w * (j + 1);
                let (mut we, mut wn, mut d0) = (0.0, 0.0, 0.0);
                let (ie, jn) = ((2 * i + 1).min(self.nx - 1), (2 * j + 1).min(self.ny - 1));
                for b in 2 * j..(2 * j + 2).min(self.ny) {
                    we += self.we[f(ie, b)];
                }
                for a in 2 * i..(2 * i + 2).min(self.nx) {
                    wn += self.wn[f(a, jn)];
                }
                for b in 2 * j..(2 * j + 2).min(self.ny) {
                    for a in 2 * i..(2 * i + 2).min(self.nx) {
                        if self.open[f(a, b)] {
                            d0 += self.d0[f(a, b)] + self.held(f(a, b));
                        }
                    }
                }
                s.we[c] = COARSE_SCALE * we;
                s.wn[c] = COARSE_SCALE * wn;
                s.d0[c] = if s.open[c] { COARSE_SCALE * d0 } else { 1.0 };
            }
        }
        for j in 0..ny {
            for i in 0..nx {
                let c = (i + 1) + w * (j + 1);
                s.count[c] = s.we[c] + s.we[c - 1] + s.wn[c] + s.wn[c - w];
            }
        }
        s.set_scale(1.0);
        Ok(s)
    }
}

/// Σ a·b with 8 independent partial sums (vectorises; fixed order: deterministic).
#[inline]
pub fn dot(a: &[Real], b: &[Real]) -> Real {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            acc[k] += x[k] * y[k];
        }
    }
    let mut tail = 0.0;
    for (x, y) in ra.iter().zip(rb) {
        tail += x * y;
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7])) + tail
}

/// The interior rows of a padded array.
#[inline]
fn rows_of(a: &mut [Real], w: usize, ny: usize) -> &mut [Real] {
    &mut a[w..w * (ny + 1)]
}

/// (A x) into the interior of `o`'s row j (o is one padded row), returning nothing.
#[inline(always)]
fn apply_row(st: &Stencil, x: &[Real], j: usize, o: &mut [Real]) {
    let w = st.w;
    let x = &x[j * w..(j + 3) * w];
    apply_rows(st, &x[..w], &x[w..2 * w], &x[2 * w..], j, o);
}

/// `apply_row` with x's padded rows j − 1, j, j + 1 (interior numbering) given apart.
#[inline(always)]
fn apply_rows(st: &Stencil, below: &[Real], mid: &[Real], above: &[Real], j: usize, o: &mut [Real]) {
    let (n, w) = (st.nx, st.w);
    let b = (j + 1) * w + 1;
    let xc = &mid[1..1 + n];
    let xw = &mid[..n];
    let xe = &mid[2..2 + n];
    let xs = &below[1..1 + n];
    let xn = &above[1..1 + n];
    let ce = &st.we[b..b + n];
    let cw = &st.we[b - 1..b - 1 + n];
    let cn = &st.wn[b..b + n];
    let cs = &st.wn[b - w..b - w + n];
    let dg = &st.diag[b..b + n];
    let s = st.scale;
    let o = &mut o[1..1 + n];
    for i in 0..n {
        o[i] = dg[i] * xc[i] - s * (ce[i] * xe[i] + cw[i] * xw[i] + cn[i] * xn[i] + cs[i] * xs[i]);
    }
}

/// out = A x; returns x·Ax.
pub fn apply(st: &Stencil, x: &[Real], out: &mut [Real]) -> Real {
    let (w, n) = (st.w, st.nx);
    rows_sum(rows_of(out, w, st.ny), w, |j, o| {
        simd::vectorized(
            simd::level(),
            #[inline(always)]
            || {
                apply_row(st, x, j, o);
                let b = (j + 1) * w + 1;
                dot(&o[1..1 + n], &x[b..b + n])
            },
        )
    })
}

/// res = b − A x; returns |res|².
pub fn residual(st: &Stencil, x: &[Real], b: &[Real], res: &mut [Real]) -> Real {
    let (w, n) = (st.w, st.nx);
    rows_sum(rows_of(res, w, st.ny), w, |j, o| {
        simd::vectorized(
            simd::level(),
            #[inline(always)]
            || {
                apply_row(st, x, j, o);
                let c = (j + 1) * w + 1;
                let (o, b) = (&mut o[1..1 + n], &b[c..c + n]);
                for i in 0..n {
                    o[i] = b[i] - o[i];
                }
                dot(o, o)
            },
        )
    })
}

/// Rows a task of `jacobi2` takes (fixed, so the work split never depends on the threads).
const BLOCK: usize = 16;

/// The scratch `jacobi2` needs on a grid of `ny` rows of `w`: three rows per block.
fn scratch_len(w: usize, ny: usize) -> usize {
    ny.div_ceil(BLOCK) * 3 * w
}

/// Two damped-Jacobi sweeps from `x` into `out` in one pass (out ≠ x): each block of rows
/// keeps the first sweep's rows it needs (its own and one either side, recomputed) in three
/// rolling rows of `scratch`, so the intermediate never goes through memory. `zero`: x = 0.
/// Per value the arithmetic is that of two separate sweeps. Returns out·b.
fn jacobi2(st: &Stencil, x: &[Real], b: &[Real], out: &mut [Real], scratch: &mut [Real], zero: bool) -> Real {
    let (w, n, ny) = (st.w, st.nx, st.ny);
    let level = simd::level();
    let run = |k: usize, o: &mut [Real], sc: &mut [Real], part: &mut Real| {
        *part = simd::vectorized(
            level,
            #[inline(always)]
            || {
                let (r0, r1) = (k * BLOCK, (k * BLOCK + BLOCK).min(ny));
                // First-sweep row of interior row jj (a ghost row when outside) into slot jj+1 mod 3.
                let first = |jj: usize, sc: &mut [Real]| {
                    let t = &mut sc[(jj % 3) * w..(jj % 3 + 1) * w];
                    if jj == 0 || jj == ny + 1 {
                        t.fill(0.0);
                        return;
                    }
                    let j = jj - 1;
                    let c = (j + 1) * w + 1;
                    let (bb, id) = (&b[c..c + n], &st.inv_diag[c..c + n]);
                    if zero {
                        let t = &mut t[1..1 + n];
                        for i in 0..n {
                            t[i] = OMEGA * id[i] * bb[i];
                        }
                    } else {
                        apply_row(st, x, j, t);
                        let (t, xc) = (&mut t[1..1 + n], &x[c..c + n]);
                        for i in 0..n {
                            t[i] = xc[i] + OMEGA * id[i] * (bb[i] - t[i]);
                        }
                    }
                };
                first(r0, sc);
                first(r0 + 1, sc);
                let mut sum = 0.0;
                for j in r0..r1 {
                    first(j + 2, sc);
                    let (s0, s1, s2) = (j % 3, (j + 1) % 3, (j + 2) % 3);
                    let o = &mut o[(j - r0) * w..(j - r0 + 1) * w];
                    apply_rows(
                        st,
                        &sc[s0 * w..(s0 + 1) * w],
                        &sc[s1 * w..(s1 + 1) * w],
                        &sc[s2 * w..(s2 + 1) * w],
                        j,
                        o,
                    );
                    let c = (j + 1) * w + 1;
                    let (bb, id, tc) = (&b[c..c + n], &st.inv_diag[c..c + n], &sc[s1 * w + 1..s1 * w + 1 + n]);
                    let o = &mut o[1..1 + n];
                    for i in 0..n {
                        o[i] = tc[i] + OMEGA * id[i] * (bb[i] - o[i]);
                    }
                    sum += dot(o, bb);
                }
                sum
            },
        );
    };
    let blocks = ny.div_ceil(BLOCK);
    let mut partials = vec![0.0; blocks];
    let rows = rows_of(out, w, ny);
    let scratch = &mut scratch[..blocks * 3 * w];
    let parallel = rows.len() >= crate::par::PAR_MIN;
    let n = partials.len().min(rows.len().div_ceil(BLOCK * w)).min(scratch.len().div_ceil(3 * w));
    let (o, sc, p) = (Shared::new(rows), Shared::new(scratch), Shared::new(&mut partials));
    // SAFETY: block k's rows, scratch and partial go to index k alone.
    crate::par::each(parallel, n, 1, |k| unsafe { run(k, o.piece(BLOCK * w, k), sc.piece(3 * w, k), p.at(k)) });
    partials.iter().sum()
}

/// The coarse right-hand side P^T (b − A x), the fine residual summed over each coarse
/// cell's children, in one pass (the fine residual is never stored).
fn restrict_residual(fine: &Stencil, x: &[Real], b: &[Real], coarse: &Stencil, out: &mut [Real]) {
    let (w, fw) = (coarse.w, fine.w);
    let (nx, fnx, fny) = (coarse.nx, fine.nx, fine.ny);
    rows_sum(rows_of(out, w, coarse.ny), w, |jc, o| {
        simd::vectorized(
            simd::level(),
            #[inline(always)]
            || {
                let o = &mut o[1..1 + nx];
                o.fill(0.0);
                for jf in 2 * jc..(2 * jc + 2).min(fny) {
                    let c = (jf + 1) * fw + 1;
                    let n = fnx;
                    let xc = &x[c..c + n];
                    let xw = &x[c - 1..c - 1 + n];
                    let xe = &x[c + 1..c + 1 + n];
                    let xs = &x[c - fw..c - fw + n];
                    let xn = &x[c + fw..c + fw + n];
                    let ce = &fine.we[c..c + n];
                    let cw = &fine.we[c - 1..c - 1 + n];
                    let cn = &fine.wn[c..c + n];
                    let cs = &fine.wn[c - fw..c - fw + n];
                    let sc = fine.scale;
                    let dg = &fine.diag[c..c + n];
                    let bb = &b[c..c + n];
                    // The residual in blocks of 64 on the stack (vectorised), then summed in pairs.
                    let mut buf = [0.0; 64];
                    for s0 in (0..n).step_by(64) {
                        let m = 64.min(n - s0);
                        for (k, r) in buf[..m].iter_mut().enumerate() {
                            let i = s0 + k;
                            *r = bb[i]
                                - (dg[i] * xc[i]
                                    - sc * (ce[i] * xe[i] + cw[i] * xw[i] + cn[i] * xn[i] + cs[i] * xs[i]));
                        }
                        for (p, v) in buf[..m].chunks(2).zip(&mut o[s0 / 2..]) {
                            *v += p.iter().sum::<Real>();
                        }
                    }
                }
                0.0
            },
        )
    });
}

/// x += P e (piecewise-constant interpolation of the coarse correction).
fn prolong_add(coarse: &Stencil, e: &[Real], fine: &Stencil, x: &mut [Real]) {
    let (w, cw) = (fine.w, coarse.w);
    let n = fine.nx;
    rows_sum(rows_of(x, w, fine.ny), w, |j, o| {
        simd::vectorized(
            simd::level(),
            #[inline(always)]
            || {
                let row = &e[(j / 2 + 1) * cw + 1..(j / 2 + 1) * cw + 1 + coarse.nx];
                let o = &mut o[1..1 + n];
                for (pair, e) in o.chunks_mut(2).zip(row) {
                    for v in pair {
                        *v += e;
                    }
                }
                0.0
            },
        )
    });
}

struct Level {
    st: Stencil,
    x: Vec<Real>,
    b: Vec<Real>,
    tmp: Vec<Real>,
    scratch: Vec<Real>,
}

/// `sweeps` (even) damped-Jacobi sweeps on x (from 0 if `zero`), two per pass; `tmp` is the
/// other buffer (swapped with x). Returns x·b after the last.
fn smooth(
    st: &Stencil,
    b: &[Real],
    x: &mut Vec<Real>,
    tmp: &mut Vec<Real>,
    scratch: &mut [Real],
    sweeps: usize,
    zero: bool,
) -> Real {
    let mut xb = 0.0;
    for k in 0..sweeps / 2 {
        xb = jacobi2(st, x, b, tmp, scratch, zero && k == 0);
        std::mem::swap(x, tmp);
    }
    xb
}

/// One V-cycle for A x = b on `levels[0]`'s grid, from x = 0; returns x·b. Symmetric (same
/// smoother before and after, restriction = interpolationᵀ, scaled Galerkin coarse
/// operators), so it is a valid CG preconditioner.
fn vcycle(levels: &mut [Level], b: &[Real], x: &mut Vec<Real>) -> Real {
    let (this, rest) = levels.split_first_mut().expect("at least one level");
    if rest.is_empty() {
        return smooth(&this.st, b, x, &mut this.tmp, &mut this.scratch, COARSE_SWEEPS, true);
    }
    smooth(&this.st, b, x, &mut this.tmp, &mut this.scratch, SWEEPS, true);
    let next = &mut rest[0];
    let (mut cb, mut cx) = (std::mem::take(&mut next.b), std::mem::take(&mut next.x));
    restrict_residual(&this.st, x, b, &next.st, &mut cb);
    vcycle(rest, &cb, &mut cx);
    prolong_add(&rest[0].st, &cx, &this.st, x);
    rest[0].b = cb;
    rest[0].x = cx;
    smooth(&this.st, b, x, &mut this.tmp, &mut this.scratch, SWEEPS, false)
}

/// `f(j, x row, r row, z row)` over the interior rows of three padded arrays, in parallel;
/// returns the two partial sums of f added in row order (deterministic).
fn update_xrz(
    w: usize,
    ny: usize,
    x: &mut [Real],
    r: &mut [Real],
    z: &mut [Real],
    f: impl Fn(usize, &mut [Real], &mut [Real], &mut [Real]) -> (Real, Real) + Sync + Send,
) -> (Real, Real) {
    let mut partials = vec![(0.0, 0.0); ny];
    let (x, r, z) = (rows_of(x, w, ny), rows_of(r, w, ny), rows_of(z, w, ny));
    let level = simd::level();
    let g = |j: usize, a: &mut [Real], b: &mut [Real], c: &mut [Real]| {
        simd::vectorized(
            level,
            #[inline(always)]
            || f(j, a, b, c),
        )
    };
    let parallel = x.len() >= crate::par::PAR_MIN;
    let n = partials.len().min(x.len().div_ceil(w)).min(r.len().div_ceil(w)).min(z.len().div_ceil(w));
    let (a, b, c, p) = (Shared::new(x), Shared::new(r), Shared::new(z), Shared::new(&mut partials));
    // SAFETY: row j of each array and partial j go to index j alone.
    crate::par::each(parallel, n, 4, |j| unsafe { *p.at(j) = g(j, a.piece(w, j), b.piece(w, j), c.piece(w, j)) });
    partials.iter().fold((0.0, 0.0), |(s, t), &(a, b)| (s + a, t + b))
}

/// What a solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Solve {
    pub iterations: usize,
    /// |b − A x| / |b| at the end (0 if b = 0).
    pub residual: Real,
    pub converged: bool,
}

/// A preconditioned conjugate-gradient solver with its buffers (allocated once).
pub struct Pcg {
    levels: Vec<Level>,
    multigrid: bool,
    r: Vec<Real>,
    z: Vec<Real>,
    p: Vec<Real>,
    ap: Vec<Real>,
}

impl Pcg {
    /// `multigrid`: precondition with one V-cycle (else with the diagonal).
    pub fn new(st: Stencil, multigrid: bool) -> Result<Self> {
        let n = st.len();
        let need = Need::new(
            "fluid",
            Need::bytes_of::<Real>(8 * n),
            format!("solver buffers of {} unknowns", count(n as u128)),
        );
        let mut levels = Vec::new();
        let mut st = st;
        loop {
            let m = st.len();
            let next = if multigrid && st.nx > COARSEST && st.ny > COARSEST { Some(st.coarsen()?) } else { None };
            let level_zero = levels.is_empty();
            levels.push(Level {
                x: if level_zero { Vec::new() } else { need.filled(m, 0.0)? },
                b: if level_zero { Vec::new() } else { need.filled(m, 0.0)? },
                tmp: if multigrid { need.filled(m, 0.0)? } else { Vec::new() },
                scratch: if multigrid { need.filled(scratch_len(st.w, st.ny), 0.0)? } else { Vec::new() },
                st,
            });
            match next {
                Some(s) => st = s,
                None => break,
            }
        }
        Ok(Self {
            levels,
            multigrid,
            r: need.filled(n, 0.0)?,
            z: need.filled(n, 0.0)?,
            p: need.filled(n, 0.0)?,
            ap: need.filled(n, 0.0)?,
        })
    }

    pub fn stencil(&self) -> &Stencil {
        &self.levels[0].st
    }
    pub fn stencil_mut(&mut self) -> &mut Stencil {
        &mut self.levels[0].st
    }
    pub fn levels(&self) -> usize {
        self.levels.len()
    }
    /// The stencil of each level, finest first (one without multigrid).
    pub fn stencils(&self) -> impl Iterator<Item = &Stencil> {
        self.levels.iter().map(|l| &l.st)
    }

    /// z = M⁻¹ r; returns r·z.
    fn precondition(&mut self) -> Real {
        let (w, n, ny) = (self.levels[0].st.w, self.levels[0].st.nx, self.levels[0].st.ny);
        if self.multigrid {
            vcycle(&mut self.levels, &self.r, &mut self.z)
        } else {
            let (r, st) = (&self.r, &self.levels[0].st);
            rows_sum(rows_of(&mut self.z, w, ny), w, |j, o| {
                simd::vectorized(
                    simd::level(),
                    #[inline(always)]
                    || {
                        let c = (j + 1) * w + 1;
                        let (o, r, id) = (&mut o[1..1 + n], &r[c..c + n], &st.inv_diag[c..c + n]);
                        for i in 0..n {
                            o[i] = id[i] * r[i];
                        }
                        dot(o, r)
                    },
                )
            })
        }
    }

    /// Solves A x = b from the `x` given (warm start) until |b − A x| ≤ tol·|b| or
    /// `max_iterations`. `x`, `b`: padded arrays (ghosts 0). `None` if `stop` was seen set.
    pub fn solve(
        &mut self,
        x: &mut [Real],
        b: &[Real],
        tol: Real,
        max_iterations: usize,
        stop: &AtomicBool,
    ) -> Option<Solve> {
        let (w, n, ny) = (self.levels[0].st.w, self.levels[0].st.nx, self.levels[0].st.ny);
        let cells = self.levels[0].st.len();
        let bb = sum_rows(ny, cells, |j| {
            let c = (j + 1) * w + 1;
            dot(&b[c..c + n], &b[c..c + n])
        });
        if bb == 0.0 {
            x.fill(0.0);
            return Some(Solve { iterations: 0, residual: 0.0, converged: true });
        }
        let bnorm = bb.sqrt();
        let mut rr = residual(&self.levels[0].st, x, b, &mut self.r);
        if rr.sqrt() <= tol * bnorm {
            return Some(Solve { iterations: 0, residual: rr.sqrt() / bnorm, converged: true });
        }
        let mut rz = self.precondition();
        self.p.copy_from_slice(&self.z);
        // Stagnation guard: a tolerance below what round-off allows (a warm start far larger
        // than b) would otherwise run to max_iterations every solve.
        let (mut best, mut since_best) = (rr, 0);
        for k in 1..=max_iterations {
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            let pap = apply(&self.levels[0].st, &self.p, &mut self.ap);
            if !(pap.is_finite() && pap > 0.0 && rz.is_finite()) {
                return Some(Solve { iterations: k, residual: rr.sqrt() / bnorm, converged: false });
            }
            let alpha = rz / pap;
            let (p, ap) = (&self.p, &self.ap);
            let mut rz_fused = 0.0;
            if self.multigrid {
                rr = rows2_sum(rows_of(x, w, ny), rows_of(&mut self.r, w, ny), w, |j, xr, rr| {
                    simd::vectorized(
                        simd::level(),
                        #[inline(always)]
                        || {
                            let c = (j + 1) * w + 1;
                            let (p, ap) = (&p[c..c + n], &ap[c..c + n]);
                            let (xr, rr) = (&mut xr[1..1 + n], &mut rr[1..1 + n]);
                            for i in 0..n {
                                xr[i] += alpha * p[i];
                                rr[i] -= alpha * ap[i];
                            }
                            dot(rr, rr)
                        },
                    )
                });
            } else {
                // The diagonal preconditioner is row-local: z = D⁻¹ r in the same pass.
                let id = &self.levels[0].st.inv_diag;
                (rr, rz_fused) = update_xrz(w, ny, x, &mut self.r, &mut self.z, |j, xr, rr, zr| {
                    let c = (j + 1) * w + 1;
                    let (p, ap, id) = (&p[c..c + n], &ap[c..c + n], &id[c..c + n]);
                    let (xr, rr, zr) = (&mut xr[1..1 + n], &mut rr[1..1 + n], &mut zr[1..1 + n]);
                    for i in 0..n {
                        xr[i] += alpha * p[i];
                        rr[i] -= alpha * ap[i];
                        zr[i] = id[i] * rr[i];
                    }
                    (dot(rr, rr), dot(zr, rr))
                });
            }
            if rr < 0.81 * best {
                (best, since_best) = (rr, 0);
            } else {
                since_best += 1;
            }
            if rr.sqrt() <= tol * bnorm || k == max_iterations || !rr.is_finite() || since_best >= STALLED {
                let r = rr.sqrt() / bnorm;
                return Some(Solve { iterations: k, residual: r, converged: r <= tol });
            }
            let rz_new = if self.multigrid { self.precondition() } else { rz_fused };
            let beta = rz_new / rz;
            rz = rz_new;
            let z = &self.z;
            rows_sum(rows_of(&mut self.p, w, ny), w, |j, o| {
                simd::vectorized(
                    simd::level(),
                    #[inline(always)]
                    || {
                        let c = (j + 1) * w + 1;
                        let (o, z) = (&mut o[1..1 + n], &z[c..c + n]);
                        for i in 0..n {
                            o[i] = z[i] + beta * o[i];
                        }
                        0.0
                    },
                )
            });
        }
        Some(Solve { iterations: max_iterations, residual: rr.sqrt() / bnorm, converged: false })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poisson(nx: usize, ny: usize, solid: impl Fn(usize, usize) -> bool) -> Stencil {
        let mut s = Stencil::build(nx, ny, &|i, j| !solid(i, j), [0.0; 4], false, 0.0).unwrap();
        s.pin().unwrap();
        s
    }

    /// A compatible right-hand side (zero sum over the fluid), padded.
    fn rhs(st: &Stencil) -> Vec<Real> {
        let mut b = vec![0.0; st.len()];
        let mut sum = 0.0;
        let mut n = 0.0;
        for c in 0..st.len() {
            if st.open[c] {
                b[c] = ((c * 7919 % 1013) as Real / 1013.0 - 0.5).sin();
                sum += b[c];
                n += 1.0;
            }
        }
        for c in 0..st.len() {
            if st.open[c] {
                b[c] -= sum / n;
            }
        }
        b
    }

    #[test]
    fn mgpcg_and_jacobi_pcg_solve_a_neumann_problem_with_an_obstacle() {
        let (nx, ny) = (37, 29);
        let solid = |i: usize, j: usize| (10..20).contains(&i) && (8..14).contains(&j);
        let st = poisson(nx, ny, solid);
        let b = rhs(&st);
        let stop = AtomicBool::new(false);
        let mut its = Vec::new();
        for mg in [true, false] {
            let mut pcg = Pcg::new(st.clone(), mg).unwrap();
            let mut x = vec![0.0; st.len()];
            let s = pcg.solve(&mut x, &b, 1e-12, 2000, &stop).unwrap();
            assert!(s.converged, "mg {mg}: {s:?}");
            let mut r = vec![0.0; st.len()];
            let rr = residual(&st, &x, &b, &mut r);
            assert!(rr.sqrt() < 1e-10 * dot(&b, &b).sqrt(), "mg {mg}");
            its.push(s.iterations);
        }
        println!("{nx}x{ny} with an obstacle, tolerance 1e-12: iterations (MGPCG, Jacobi-PCG) {its:?}");
        assert!(its[0] * 3 < its[1], "multigrid should need far fewer iterations: {its:?}");
    }
}
