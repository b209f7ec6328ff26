//! Fields on uniform grids, as systems of a [`World`](crate::world::World): the wave equation
//! ([`wave`]), Gray–Scott reaction–diffusion ([`gray_scott`]) and an incompressible grid fluid
//! ([`fluid`], Stam's stable fluids).
//!
//! Every grid here is **cell-centred**: cell (i, j, k) has its centre at ((i+½)dx, (j+½)dx,
//! (k+½)dx) and the domain is [0, nx·dx] × [0, ny·dx] (× [0, nz·dx]). Arrays are row-major with
//! x fastest: cell (i, j, k) is at `i + nx·(j + ny·k)`. A 2D grid has nz = 1.
//!
//! Boundaries are ghost cells one cell outside each face, written as a rule, not stored:
//! `Fixed` (u = 0 on the face: the ghost is −u of the cell inside, odd reflection), `Free`
//! (∂u/∂n = 0 on the face: the ghost equals the cell inside, even reflection) and `Periodic`
//! (the ghost is the cell on the opposite side). With these rules the discrete Laplacian is
//! symmetric, so the books of the schemes built on it balance to round-off.
//!
//! Parallel loops run over rows (fixed j, k) in fixed blocks; reductions add per-row partials
//! in row order, so results are bit-identical for any thread count.
pub mod build;
pub mod fluid;
pub mod gray_scott;
pub mod poisson;
pub mod wave;
mod wave_fused;

use crate::error::{invalid, Result};
use crate::par;
use crate::vector::Real;

/// What lies beyond a face of the grid (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Edge {
    /// u = 0 on the face (odd reflection).
    Fixed,
    /// ∂u/∂n = 0 on the face (even reflection).
    Free,
    /// The opposite face (both faces of an axis must say so).
    Periodic,
}

impl Edge {
    pub fn by_name(s: &str) -> Option<Edge> {
        match s {
            "fixed" => Some(Edge::Fixed),
            "free" => Some(Edge::Free),
            "periodic" => Some(Edge::Periodic),
            _ => None,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Edge::Fixed => "fixed",
            Edge::Free => "free",
            Edge::Periodic => "periodic",
        }
    }
}

/// A uniform cell-centred grid: cell counts, spacing and the rule at each face.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    /// Cells along x, y, z (z = 1 in 2D).
    pub n: [usize; 3],
    /// 2 or 3.
    pub dim: usize,
    /// Cell size, m.
    pub dx: Real,
    /// Faces: [x−, x+, y−, y+, z−, z+] (z ignored in 2D).
    pub edges: [Edge; 6],
}

impl Grid {
    /// `shape`: 2 or 3 cell counts (x first), each ≥ 3; `dx` > 0 and finite; `edges`: 2·dim faces.
    pub fn new(shape: &[usize], dx: Real, edges: &[Edge]) -> Result<Self> {
        let dim = shape.len();
        if !(2..=3).contains(&dim) {
            return Err(invalid("shape", format!("must have 2 or 3 cell counts, got {}", shape.len())));
        }
        if let Some(&n) = shape.iter().find(|&&n| n < 3) {
            return Err(invalid("shape", format!("every cell count must be >= 3, got {n}")));
        }
        let cells = shape.iter().try_fold(1usize, |a, &n| a.checked_mul(n));
        if cells.is_none_or(|c| c > (1usize << 40)) {
            return Err(invalid("shape", format!("{shape:?} has too many cells")));
        }
        if !(dx.is_finite() && dx > 0.0) {
            return Err(invalid("spacing", format!("{dx} must be finite and > 0 (m)")));
        }
        if edges.len() != 2 * dim {
            return Err(invalid(
                "edges",
                format!("needs {} faces (x-, x+, y-, y+[, z-, z+]), got {}", 2 * dim, edges.len()),
            ));
        }
        for a in 0..dim {
            if (edges[2 * a] == Edge::Periodic) != (edges[2 * a + 1] == Edge::Periodic) {
                return Err(invalid("edges", format!("axis {a}: periodic must be on both faces or neither")));
            }
        }
        let mut n = [1; 3];
        n[..dim].copy_from_slice(shape);
        let mut e = [Edge::Fixed; 6];
        e[..2 * dim].copy_from_slice(edges);
        Ok(Self { n, dim, dx, edges: e })
    }

    pub fn cells(&self) -> usize {
        self.n[0] * self.n[1] * self.n[2]
    }
    /// Rows along x: ny·nz.
    pub fn rows(&self) -> usize {
        self.n[1] * self.n[2]
    }
    /// Cell area (2D) or volume (3D), m² or m³.
    pub fn cell_measure(&self) -> Real {
        self.dx.powi(self.dim as i32)
    }

    /// The row across face `side` (0: −, 1: +) of axis `axis` (1: y, 2: z) from row `r`: the
    /// neighbouring row and the factor its values enter with (−1 for a `Fixed` ghost, which
    /// is the row itself reflected oddly; 1 otherwise).
    #[inline]
    pub fn neighbour_row(&self, r: usize, axis: usize, side: usize) -> (usize, Real) {
        let (j, k) = (r % self.n[1], r / self.n[1]);
        let (c, n, stride) = if axis == 1 { (j, self.n[1], 1) } else { (k, self.n[2], self.n[1]) };
        let inside = if side == 0 { c > 0 } else { c + 1 < n };
        if inside {
            return (if side == 0 { r - stride } else { r + stride }, 1.0);
        }
        match self.edges[2 * axis + side] {
            Edge::Fixed => (r, -1.0),
            Edge::Free => (r, 1.0),
            Edge::Periodic => (if side == 0 { r + (n - 1) * stride } else { r - (n - 1) * stride }, 1.0),
        }
    }

    /// The ghost value beyond x− (side 0) or x+ (side 1) of `row` (one row's cells).
    #[inline]
    pub fn ghost_x(&self, row: &[Real], side: usize) -> Real {
        let n = row.len();
        let (inside, opposite) = if side == 0 { (row[0], row[n - 1]) } else { (row[n - 1], row[0]) };
        match self.edges[side] {
            Edge::Fixed => -inside,
            Edge::Free => inside,
            Edge::Periodic => opposite,
        }
    }

    /// The 5-point (2D) or 7-point (3D) Laplacian of `u` at every cell of row `r`, times
    /// `scale`, into `out` (one row): (Σ_neighbours u − 2·dim·u) · scale. `scale` is usually
    /// 1/dx² times a coefficient.
    #[inline]
    pub fn laplacian_row(&self, u: &[Real], r: usize, scale: Real, out: &mut [Real]) {
        let nx = self.n[0];
        let row = &u[r * nx..(r + 1) * nx];
        let centre = -((2 * self.dim) as Real);
        let (s, fs) = self.neighbour_row(r, 1, 0);
        let (nn, fn_) = self.neighbour_row(r, 1, 1);
        let south = &u[s * nx..(s + 1) * nx];
        let north = &u[nn * nx..(nn + 1) * nx];
        let out = &mut out[..nx];
        if self.dim == 2 {
            for i in 1..nx - 1 {
                out[i] = (row[i - 1] + row[i + 1] + fs * south[i] + fn_ * north[i] + centre * row[i]) * scale;
            }
        } else {
            let (d, fd) = self.neighbour_row(r, 2, 0);
            let (up, fu) = self.neighbour_row(r, 2, 1);
            let down = &u[d * nx..(d + 1) * nx];
            let up = &u[up * nx..(up + 1) * nx];
            for i in 1..nx - 1 {
                out[i] = (row[i - 1]
                    + row[i + 1]
                    + fs * south[i]
                    + fn_ * north[i]
                    + fd * down[i]
                    + fu * up[i]
                    + centre * row[i])
                    * scale;
            }
        }
        let (g0, g1) = (self.ghost_x(row, 0), self.ghost_x(row, 1));
        for (i, left, right) in [(0, g0, row[1]), (nx - 1, row[nx - 2], g1)] {
            let mut s = left + right + fs * south[i] + fn_ * north[i] + centre * row[i];
            if self.dim == 3 {
                let (d, fd) = self.neighbour_row(r, 2, 0);
                let (up, fu) = self.neighbour_row(r, 2, 1);
                s += fd * u[d * nx + i] + fu * u[up * nx + i];
            }
            out[i] = s * scale;
        }
    }
}

/// Buffers of snapshots that were not needed (`System::recycle`), reused by the next snapshot:
/// a checkpoint per call then copies into memory already mapped instead of faulting in fresh
/// pages (measured: 22 % of a 2048² wave's time at 20 steps per call).
#[derive(Default)]
pub struct Spare(std::sync::Mutex<Vec<Vec<Real>>>);

impl Spare {
    /// A copy of `src`, in the smallest spare buffer that is large enough (so that arrays of
    /// different sizes each find theirs).
    pub fn copy(&self, src: &[Real], need: &crate::alloc::Need) -> Result<Vec<Real>> {
        if src.is_empty() {
            return Ok(Vec::new());
        }
        let spare = {
            let mut pool = self.0.lock().unwrap_or_else(|e| e.into_inner());
            let fits = pool.iter().enumerate().filter(|(_, b)| b.capacity() >= src.len());
            fits.min_by_key(|(_, b)| b.capacity()).map(|(i, _)| i).map(|i| pool.swap_remove(i))
        };
        match spare {
            Some(mut b) => {
                b.clear();
                b.extend_from_slice(src);
                Ok(b)
            }
            None => need.copy(src),
        }
    }
    /// A snapshot of two arrays and the small state `extra`, copied into spare buffers.
    pub fn snapshot2<T: Send + 'static>(&self, a: &[Real], b: &[Real], extra: T) -> Result<crate::systems::Snapshot> {
        let n = a.len() + b.len();
        let need = crate::alloc::Need::new(
            "step",
            crate::alloc::Need::bytes_of::<Real>(n),
            format!("a copy of {} values", crate::alloc::count(n as u128)),
        );
        Ok(Box::new((self.copy(a, &need)?, self.copy(b, &need)?, extra)))
    }
    /// Takes back the buffers of a `snapshot2` snapshot (anything else is dropped).
    pub fn recycle2<T: 'static>(&self, snapshot: crate::systems::Snapshot) {
        if let Ok(s) = snapshot.downcast::<(Vec<Real>, Vec<Real>, T)>() {
            let (a, b, _) = *s;
            self.keep(a);
            self.keep(b);
        }
    }
    /// Keeps `b` for a later `copy` (at most eight buffers are kept: a fluid's checkpoint has
    /// six).
    pub fn keep(&self, b: Vec<Real>) {
        let mut pool = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if b.capacity() > 0 && pool.len() < 8 {
            pool.push(b);
        }
    }
}

/// Grows `v` to at least `n` values, fallibly (the fused sweeps' scratch: a step allocates
/// nothing that could abort the process).
pub(super) fn grow<T: Clone + Default>(v: &mut Vec<T>, n: usize) -> bool {
    if v.len() < n {
        if v.try_reserve_exact(n - v.len()).is_err() {
            return false;
        }
        v.resize(n, T::default());
    }
    true
}

/// The bands of a fused sweep over `rows` rows: (rows per band, bands). About 4 bands per
/// thread, none shorter than 64 rows (the overlapped halo costs (K − 1)/rows of a band's work).
pub(super) fn fused_bands(rows: usize) -> (usize, usize) {
    let bands = (4 * par::threads()).min(rows / 64).max(1);
    let band = rows.div_ceil(bands);
    (band, rows.div_ceil(band))
}

/// What a fused sweep's wavefront makes at time `e` of a band: step j (1..=k) of row
/// e − (j − 1), for the rows step j makes (`range(j)` = [lo, hi)). In that order, step j's
/// inputs — step j − 1 of the rows around — were made before it.
pub(super) fn wavefront(
    k: isize,
    e: isize,
    range: impl Fn(isize) -> (isize, isize),
) -> impl Iterator<Item = (isize, isize)> {
    (1..=k).map(move |j| (j, e - (j - 1))).filter(move |&(j, s)| {
        let (lo, hi) = range(j);
        (lo..hi).contains(&s)
    })
}

/// Rows a parallel task takes at least (a 2048-cell row is ~16 kB per array).
const MIN_ROWS: usize = 4;

/// Rows per task for `rows` rows: a few long runs of consecutive rows per thread, so that each
/// thread streams through memory (the hardware prefetchers follow long runs; stencils here are
/// bandwidth-bound), with enough tasks left to balance a noisy machine.
fn task_rows(rows: usize) -> usize {
    (rows / (4 * par::threads())).max(MIN_ROWS)
}

/// `partials[r] = f(r, row)` for every row `r` of `out` (rows of `row_len` values), in parallel
/// on the pool of the call in progress. The caller reduces `partials` in row order, so results
/// are bit-identical for any thread count; `partials` is scratch the caller keeps, so a step
/// allocates nothing.
pub fn rows_each<T: Send>(
    out: &mut [Real],
    row_len: usize,
    partials: &mut [T],
    f: impl Fn(usize, &mut [Real]) -> T + Sync + Send,
) {
    debug_assert_eq!(out.len(), row_len * partials.len());
    let per_task = task_rows(partials.len());
    let rows = partials.len().min(out.len().div_ceil(row_len));
    let parallel = out.len() >= par::PAR_MIN;
    let (o, p) = (par::Shared::new(out), par::Shared::new(partials));
    // SAFETY: row r and partial r go to index r alone.
    par::each(parallel, rows, per_task, |r| unsafe { *p.at(r) = f(r, o.piece(row_len, r)) });
}

/// `rows_each`, returning Σ f in row order.
pub fn rows_sum_into(
    out: &mut [Real],
    row_len: usize,
    partials: &mut [Real],
    f: impl Fn(usize, &mut [Real]) -> Real + Sync + Send,
) -> Real {
    rows_each(out, row_len, partials, f);
    partials.iter().sum()
}

/// `rows_each` over the matching rows of two arrays.
pub fn rows2_each<T: Send>(
    a: &mut [Real],
    b: &mut [Real],
    row_len: usize,
    partials: &mut [T],
    f: impl Fn(usize, &mut [Real], &mut [Real]) -> T + Sync + Send,
) {
    debug_assert_eq!(a.len(), b.len());
    let per_task = task_rows(partials.len());
    let rows = partials.len().min(a.len().div_ceil(row_len)).min(b.len().div_ceil(row_len));
    let parallel = a.len() >= par::PAR_MIN;
    let (pa, pb, p) = (par::Shared::new(a), par::Shared::new(b), par::Shared::new(partials));
    // SAFETY: the rows and partial r go to index r alone.
    par::each(parallel, rows, per_task, |r| unsafe { *p.at(r) = f(r, pa.piece(row_len, r), pb.piece(row_len, r)) });
}

/// `rows2_each`, returning Σ f in row order.
pub fn rows2_sum_into(
    a: &mut [Real],
    b: &mut [Real],
    row_len: usize,
    partials: &mut [Real],
    f: impl Fn(usize, &mut [Real], &mut [Real]) -> Real + Sync + Send,
) -> Real {
    rows2_each(a, b, row_len, partials, f);
    partials.iter().sum()
}

/// `f(r, row)` for every row `r` of `out` (rows of `row_len` values), in parallel; returns Σ f
/// in row order (deterministic for any thread count). Allocates one value per row: steps use
/// `rows_sum_into`.
pub fn rows_sum(out: &mut [Real], row_len: usize, f: impl Fn(usize, &mut [Real]) -> Real + Sync + Send) -> Real {
    let mut partials = vec![0.0; out.len() / row_len];
    rows_sum_into(out, row_len, &mut partials, f)
}

/// `rows_sum` over two arrays' matching rows.
pub fn rows2_sum(
    a: &mut [Real],
    b: &mut [Real],
    row_len: usize,
    f: impl Fn(usize, &mut [Real], &mut [Real]) -> Real + Sync + Send,
) -> Real {
    let mut partials = vec![0.0; a.len() / row_len];
    rows2_sum_into(a, b, row_len, &mut partials, f)
}

/// Σ f(r) over `rows` rows, in row order, in parallel (read-only passes: energies, norms).
pub fn sum_rows(rows: usize, cells: usize, f: impl Fn(usize) -> Real + Sync + Send) -> Real {
    // The partials allocated fallibly: where they cannot be had (a memory cap: this runs in
    // the energy books, which report nothing), the serial sum below gives the same bits.
    let mut partials = Vec::new();
    if cells >= par::PAR_MIN && partials.try_reserve_exact(rows).is_ok() {
        partials.resize(rows, 0.0);
        let p = par::Shared::new(&mut partials);
        // SAFETY: partial r goes to index r alone.
        if par::for_each_index_min(rows, MIN_ROWS, &|r| unsafe { *p.at(r) = f(r) }) {
            return partials.into_iter().sum();
        }
    }
    // Serially (small grids, every solver iteration): the same sum, nothing allocated.
    (0..rows).map(f).sum()
}

/// Σ a in a fixed order of 8 interleaved partial sums (vectorises at every SIMD level and gives
/// the same bits at all of them).
#[inline(always)]
pub fn lanes_sum(a: &[Real]) -> Real {
    let mut acc = [0.0; 8];
    let chunks = a.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for k in 0..8 {
            acc[k] += c[k];
        }
    }
    let mut s = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
    for x in rest {
        s += x;
    }
    s
}

/// The first index of a non-finite value of `a`, if any (the slow path after a row sum came out
/// non-finite).
pub fn first_non_finite(a: &[Real]) -> Option<usize> {
    a.iter().position(|v| !v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(edges: [Edge; 4], n: [usize; 2]) -> Grid {
        Grid::new(&n, 0.5, &edges).unwrap()
    }

    /// ⟨a, L b⟩ = ⟨L a, b⟩ for every boundary rule: the symmetry the energy books rest on.
    #[test]
    fn laplacian_is_symmetric_for_every_edge_rule() {
        use Edge::*;
        for edges in
            [[Fixed; 4], [Free; 4], [Periodic; 4], [Fixed, Free, Periodic, Periodic], [Free, Fixed, Fixed, Free]]
        {
            let g = grid(edges, [7, 5]);
            let n = g.cells();
            let a: Vec<Real> = (0..n).map(|i| ((i * 37 % 11) as Real).sin()).collect();
            let b: Vec<Real> = (0..n).map(|i| ((i * 13 % 7) as Real).cos()).collect();
            let (mut la, mut lb) = (vec![0.0; n], vec![0.0; n]);
            for r in 0..g.rows() {
                g.laplacian_row(&a, r, 1.0, &mut la[r * 7..]);
                g.laplacian_row(&b, r, 1.0, &mut lb[r * 7..]);
            }
            let ab: Real = a.iter().zip(&lb).map(|(x, y)| x * y).sum();
            let ba: Real = la.iter().zip(&b).map(|(x, y)| x * y).sum();
            assert!((ab - ba).abs() < 1e-12 * ab.abs().max(1.0), "{edges:?}: {ab} vs {ba}");
        }
    }

    /// sin(mπ(i+½)/n) is an eigenvector of the fixed-edge Laplacian with eigenvalue
    /// −4 sin²(mπ/2n) per axis: the boundary sits on the faces, L = n·dx.
    #[test]
    fn fixed_modes_are_eigenvectors() {
        let (nx, ny, m, k) = (9usize, 6usize, 2.0, 3.0);
        let g = grid([Edge::Fixed; 4], [nx, ny]);
        let pi = std::f64::consts::PI;
        let u: Vec<Real> = (0..nx * ny)
            .map(|c| {
                let (i, j) = ((c % nx) as Real, (c / nx) as Real);
                (m * pi * (i + 0.5) / nx as Real).sin() * (k * pi * (j + 0.5) / ny as Real).sin()
            })
            .collect();
        let lambda = -4.0 * ((m * pi / (2.0 * nx as Real)).sin().powi(2) + (k * pi / (2.0 * ny as Real)).sin().powi(2));
        let mut lu = vec![0.0; nx * ny];
        for r in 0..ny {
            g.laplacian_row(&u, r, 1.0, &mut lu[r * nx..]);
        }
        for c in 0..nx * ny {
            assert!((lu[c] - lambda * u[c]).abs() < 1e-13, "cell {c}");
        }
    }

    #[test]
    fn bad_grids_are_refused() {
        assert!(Grid::new(&[2, 5], 1.0, &[Edge::Fixed; 4]).is_err());
        assert!(Grid::new(&[4, 5], 0.0, &[Edge::Fixed; 4]).is_err());
        assert!(Grid::new(&[4, 5], 1.0, &[Edge::Periodic, Edge::Fixed, Edge::Free, Edge::Free]).is_err());
        assert!(Grid::new(&[4, 5, 6, 7], 1.0, &[Edge::Fixed; 8]).is_err());
    }
}
