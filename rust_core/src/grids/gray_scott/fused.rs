//! Several forward Euler steps in one sweep over memory (temporal blocking), 2D. One step reads
//! u, v and writes u⁺, v⁺ at ~48 bytes per cell for ~25 flops, so a single step runs at the
//! memory's speed; a sweep that makes `K` steps moves the same bytes once for `K` steps.
//!
//! The rows are split into bands, run in parallel. A band [a, b) makes step `j` (1..=K) of the
//! rows within `K − j` of it (overlapped tiling: the halo rows are made again by each band that
//! needs them, a (K − 1)/(b − a) overhead), in a wavefront: at time `e` it makes step j of row
//! e − (j − 1), whose inputs, step j − 1 of rows e − j..e − j + 2, were just made. So each
//! intermediate step needs a ring of only 3 rows of u and v, which stays in the core's cache;
//! step 0 is read from `u`, `v` and step K written to `u2`, `v2`.
//!
//! Every cell of every step is made by `advance`, the single step's own arithmetic, from the
//! same inputs, so K fused steps give the bits of K single steps, for any split into bands and
//! any thread count; the books are reduced per step in row order, as a single step does.
use super::{advance, GrayScottSystem, Rates};
use crate::grids::Edge;
use crate::par;
use crate::vector::Real;
use rayon::prelude::*;

/// Steps per sweep. A band's rings hold 3 rows of u and v for each of the K − 1 steps between:
/// (K − 1)·6·nx values, 240 KiB at nx = 1024 — inside a core's L2 (512 KiB or more on the CPUs
/// we measure), above which the rings would spill and each step would cost memory traffic again.
pub(super) const FUSE: usize = 6;

/// Scratch of the fused sweep, kept between calls so that a sweep allocates nothing.
#[derive(Default)]
pub(super) struct Scratch {
    rings: Vec<Real>,
    partials: Vec<[Real; 3]>,
}

impl GrayScottSystem {
    /// Whether `sweep` applies: a 2D grid whose y edges are both periodic or both free.
    pub(super) fn fusable(&self) -> bool {
        let g = &self.cfg.grid;
        g.dim == 2 && g.edges[2] == g.edges[3] && g.n[0] >= 2
    }

    /// Advances `k` steps of `dt` (2 ≤ k ≤ `FUSE`) in one sweep. Returns false, with nothing
    /// changed, if a value of any of the k steps is not finite (the caller then takes them one
    /// by one, which finds the step that diverged) or if the scratch cannot be allocated.
    pub(super) fn sweep(&mut self, dt: Real, k: usize) -> bool {
        debug_assert!((2..=FUSE).contains(&k) && self.fusable());
        let g = &self.cfg.grid;
        let (nx, ny) = (g.n[0], g.n[1]);
        let (band, bands) = crate::grids::fused_bands(ny);
        let ring = (k - 1) * 6 * nx;
        let mut scratch = std::mem::take(&mut self.fused);
        if !(crate::grids::grow(&mut scratch.rings, bands * ring) && crate::grids::grow(&mut scratch.partials, ny * k))
        {
            self.fused = scratch;
            return false;
        }
        let (mut u2, mut v2) = (std::mem::take(&mut self.u2), std::mem::take(&mut self.v2));
        let rates = self.rates(dt);
        let periodic = g.edges[2] == Edge::Periodic;
        let this = &*self;
        {
            let (rings, partials) = (&mut scratch.rings[..bands * ring], &mut scratch.partials[..ny * k]);
            type Job<'x> = (usize, (((&'x mut [Real], &'x mut [Real]), &'x mut [[Real; 3]]), &'x mut [Real]));
            let job =
                |(i, (((ou, ov), parts), ring)): Job| this.band(rates, k, i * band, periodic, ring, ou, ov, parts);
            let forked = par::fork_if(nx * ny, || {
                u2.par_chunks_mut(band * nx)
                    .zip(v2.par_chunks_mut(band * nx))
                    .zip(partials.par_chunks_mut(band * k))
                    .zip(rings.par_chunks_mut(ring))
                    .enumerate()
                    .with_max_len(1)
                    .for_each(job)
            });
            if forked.is_none() {
                u2.chunks_mut(band * nx)
                    .zip(v2.chunks_mut(band * nx))
                    .zip(partials.chunks_mut(band * k))
                    .zip(rings.chunks_mut(ring))
                    .enumerate()
                    .for_each(job);
            }
        }
        // Per step, in row order: what one step reduces.
        let mut sums = [[0.0; 3]; FUSE];
        for r in 0..ny {
            for (s, p) in sums.iter_mut().zip(&scratch.partials[r * k..(r + 1) * k]) {
                for q in 0..3 {
                    s[q] += p[q];
                }
            }
        }
        self.fused = scratch;
        if !sums[..k].iter().all(|s| s[2].is_finite()) {
            (self.u2, self.v2) = (u2, v2);
            return false;
        }
        let da = self.cfg.grid.cell_measure();
        for s in &sums[..k] {
            self.books.made_u += dt * s[0] * da;
            self.books.made_v += dt * s[1] * da;
        }
        self.u2 = std::mem::replace(&mut self.u, u2);
        self.v2 = std::mem::replace(&mut self.v, v2);
        true
    }

    /// Steps 1..=k of the rows of the band starting at row `a` that `ou` holds, into `ou`,
    /// `ov`; `parts[(r − a)·k + j − 1]` gets row r's partial sums of step j. Rows are counted
    /// without wrapping (periodic: −k..ny + k, taken mod ny when read from u, v; free: clamped).
    #[allow(clippy::too_many_arguments)]
    fn band(
        &self,
        rates: Rates,
        k: usize,
        a: usize,
        periodic: bool,
        ring: &mut [Real],
        ou: &mut [Real],
        ov: &mut [Real],
        parts: &mut [[Real; 3]],
    ) {
        let g = &self.cfg.grid;
        let nx = g.n[0];
        let ny = g.n[1] as isize;
        let (a, b) = (a as isize, (a + ou.len() / nx) as isize);
        let kk = k as isize;
        // The rows that step j makes.
        let range = |j: isize| {
            let h = kk - j;
            if periodic {
                (a - h, b + h)
            } else {
                ((a - h).max(0), (b + h).min(ny))
            }
        };
        // A row's south and north neighbours; a free edge is its own neighbour.
        let around = |s: isize| {
            let south = if !periodic && s == 0 { s } else { s - 1 };
            let north = if !periodic && s == ny - 1 { s } else { s + 1 };
            (south, north)
        };
        let slot = |level: isize, s: isize| (((level - 1) * 3 + s.rem_euclid(3)) as usize) * 2 * nx;
        let main = |s: isize| {
            let o = s.rem_euclid(ny) as usize * nx;
            (&self.u[o..o + nx], &self.v[o..o + nx])
        };
        for e in range(1).0..b + kk - 1 {
            for (j, s) in crate::grids::wavefront(kk, e, &range) {
                let (south, north) = around(s);
                // Step j − 1 of rows south, s, north, and where step j of row s goes.
                let (done, next) = ring.split_at_mut(((j - 1) * 6) as usize * nx);
                let get = |s: isize| {
                    if j == 1 {
                        main(s)
                    } else {
                        let o = slot(j - 1, s);
                        (&done[o..o + nx], &done[o + nx..o + 2 * nx])
                    }
                };
                let ((uc, vc), (us, vs), (un, vn)) = (get(s), get(south), get(north));
                let (out_u, out_v) = if j == kk {
                    let o = (s - a) as usize * nx;
                    (&mut ou[o..o + nx], &mut ov[o..o + nx])
                } else {
                    // `next` starts at step j's ring.
                    let o = slot(1, s);
                    next[o..o + 2 * nx].split_at_mut(nx)
                };
                let p = advance(g, rates, [uc, us, un, uc, uc], [vc, vs, vn, vc, vc], out_u, out_v);
                if (a..b).contains(&s) {
                    parts[(s - a) as usize * k + (j - 1) as usize] = p;
                }
            }
        }
    }
}
