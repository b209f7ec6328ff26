//! Two leapfrog steps in one sweep over memory (temporal blocking) for the plain 2D wave (no
//! damping, layers, obstacles or oscillators): the stencil is bandwidth-bound, and a sweep that
//! makes two steps reads and writes each array once instead of twice.
//!
//! Buffers: A = uⁿ, B = uⁿ⁻¹. Step 1 writes uⁿ⁺¹ over B row by row (a cell reads only its own
//! old B value); step 2 writes uⁿ⁺² over A, row r as soon as step 1 has made rows r−1..r+1, so
//! a wavefront of two rows travels down each block of rows. Row r of A is overwritten only after
//! step 1 no longer needs it.
//!
//! Blocks run in parallel. A block's step 2 at its first and last rows needs step 1 one row
//! beyond (the halo row, in the neighbouring block): it computes that row itself, into a private
//! buffer, from copies of the neighbour's edge rows of A and B taken before the sweep (the
//! neighbour overwrites them). Every cell's arithmetic is the single step's, in the same order,
//! so two fused steps give the same bits as two single steps, for any split into blocks.
use super::Grid;
use crate::vector::Real;

/// uⁿ⁺¹ for one row into `out`, which holds uⁿ⁻¹ on entry: 2c − out + k·(l + r + fs·s + fn·n − 4c),
/// the same expression, in the same order, as the single step's undamped path.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn leap(g: &Grid, c: &[Real], s: &[Real], fs: Real, n: &[Real], fn_: Real, out: &mut [Real], k: Real) -> bool {
    let nx = c.len();
    let (g0, g1) = (g.ghost_x(c, 0), g.ghost_x(c, 1));
    let end = |i: usize, left: Real, right: Real, um: Real| -> Real {
        let lap = left + right + fs * s[i] + fn_ * n[i] - 4.0 * c[i];
        (2.0 * c[i] - (1.0 - 0.0) * um + k * lap) * 1.0
    };
    let first = end(0, g0, c[1], out[0]);
    let last = end(nx - 1, c[nx - 2], g1, out[nx - 1]);
    let m = nx - 2;
    let (l, cc, r, ss, nn) = (&c[..m], &c[1..][..m], &c[2..][..m], &s[1..][..m], &n[1..][..m]);
    let o = &mut out[1..][..m];
    for i in 0..m {
        let lap = l[i] + r[i] + fs * ss[i] + fn_ * nn[i] - 4.0 * cc[i];
        o[i] = 2.0 * cc[i] - o[i] + k * lap;
    }
    out[0] = first;
    out[nx - 1] = last;
    super::lanes_sum(out).is_finite()
}

/// Where a row's values are during the sweep of one block.
struct Rows<'a> {
    nx: usize,
    /// This block's rows [r0, r1).
    r0: usize,
    r1: usize,
    /// Copies, taken before the sweep, of the edge rows of every block: for block b, A rows
    /// (first, second, second-to-last, last) and B rows (first, last), `6·nx` values each.
    saved: &'a [Real],
    /// Block index of every row, and the first row of every block.
    starts: &'a [usize],
}

impl Rows<'_> {
    fn block_of(&self, r: usize) -> usize {
        self.starts.partition_point(|&s| s <= r) - 1
    }
    /// A copy of row `r` (outside this block) of A (`b = false`) or B (`b = true`).
    fn saved(&self, r: usize, b: bool) -> &[Real] {
        let k = self.block_of(r);
        let (s0, s1) = (self.starts[k], self.starts[k + 1]);
        let slot = match (b, r) {
            (false, r) if r == s0 => 0,
            (false, r) if r == s0 + 1 => 1,
            (false, r) if r + 2 == s1 => 2,
            (false, r) if r + 1 == s1 => 3,
            (true, r) if r == s0 => 4,
            (true, r) if r + 1 == s1 => 5,
            _ => unreachable!("row {r} is not an edge row of block {k}"),
        };
        &self.saved[(6 * k + slot) * self.nx..][..self.nx]
    }
    fn inside(&self, r: usize) -> bool {
        (self.r0..self.r1).contains(&r)
    }
}

/// The copies `Rows::saved` reads, for blocks starting at `starts` (ending with the row count).
pub(super) fn save_edges(a: &[Real], b: &[Real], nx: usize, starts: &[usize], saved: &mut [Real]) {
    for k in 0..starts.len() - 1 {
        let (s0, s1) = (starts[k], starts[k + 1]);
        for (slot, (src, r)) in
            [(a, s0), (a, s0 + 1), (a, s1 - 2), (a, s1 - 1), (b, s0), (b, s1 - 1)].into_iter().enumerate()
        {
            saved[(6 * k + slot) * nx..][..nx].copy_from_slice(&src[r * nx..][..nx]);
        }
    }
}

/// Two steps over block [r0, r1) of A (`a`, this block's rows only) and B (`b`, likewise).
/// `scratch`: 2 rows. Returns whether step 1's and step 2's rows came out finite.
#[allow(clippy::too_many_arguments)]
pub(super) fn block_pair(
    g: &Grid,
    r0: usize,
    a: &mut [Real],
    b: &mut [Real],
    saved: &[Real],
    starts: &[usize],
    k: Real,
    scratch: &mut [Real],
) -> (bool, bool) {
    let nx = g.n[0];
    let r1 = r0 + a.len() / nx;
    let rows = Rows { nx, r0, r1, saved, starts };
    let (h_lo, h_hi) = scratch[..2 * nx].split_at_mut(nx);
    let (mut ok1, mut ok2) = (true, true);
    // The rows across this block's faces (a neighbour block's edge, a periodic wrap, or the row
    // itself for fixed/free faces, which needs no halo).
    let (below, _) = g.neighbour_row(r0, 1, 0);
    let (above, _) = g.neighbour_row(r1 - 1, 1, 1);
    // Halo rows first, before this block's A rows change: step 1 of `below` and `above` from
    // the saved copies (and this block's own edge rows of A, still uⁿ).
    for (x, dst) in [(below, &mut *h_lo), (above, &mut *h_hi)] {
        if rows.inside(x) {
            continue;
        }
        let (s, fs) = g.neighbour_row(x, 1, 0);
        let (n, fn_) = g.neighbour_row(x, 1, 1);
        let a_row = |r: usize| -> &[Real] {
            if rows.inside(r) {
                &a[(r - r0) * nx..][..nx]
            } else {
                rows.saved(r, false)
            }
        };
        dst.copy_from_slice(rows.saved(x, true));
        ok1 &= leap(g, a_row(x), a_row(s), fs, a_row(n), fn_, dst, k);
    }
    // The wavefront: step 1 of row j, then step 2 of row j − 1.
    for j in r0..=r1 {
        if j < r1 {
            let (s, fs) = g.neighbour_row(j, 1, 0);
            let (n, fn_) = g.neighbour_row(j, 1, 1);
            let sv: &[Real] = if rows.inside(s) { &a[(s - r0) * nx..][..nx] } else { rows.saved(s, false) };
            let nv: &[Real] = if rows.inside(n) { &a[(n - r0) * nx..][..nx] } else { rows.saved(n, false) };
            let cv = &a[(j - r0) * nx..][..nx];
            ok1 &= leap(g, cv, sv, fs, nv, fn_, &mut b[(j - r0) * nx..][..nx], k);
        }
        if j > r0 {
            let r = j - 1;
            let (s, fs) = g.neighbour_row(r, 1, 0);
            let (n, fn_) = g.neighbour_row(r, 1, 1);
            let b1 = |x: usize| -> &[Real] {
                if rows.inside(x) {
                    &b[(x - r0) * nx..][..nx]
                } else if x == below {
                    h_lo
                } else {
                    h_hi
                }
            };
            let (sv, cv, nv) = (b1(s), b1(r), b1(n));
            ok2 &= leap(g, cv, sv, fs, nv, fn_, &mut a[(r - r0) * nx..][..nx], k);
        }
    }
    (ok1, ok2)
}
