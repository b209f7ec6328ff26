//! The spatial hash (cell list): particles counting-sorted by cell, rebuilt each step in parallel.
//!
//! Cell size = the interaction radius, so every neighbour of a particle lies in its own cell or
//! one of the 3^dim − 1 around it. The domain is unbounded: when the cells spanned by the
//! particles' bounding box are few (≤ 4N + 4096) they are numbered densely, row by row, so the
//! three cells of a row are one contiguous run of sorted particles; otherwise (a particle far away,
//! huge or negative coordinates) cell coordinates are hashed into 2N..4N buckets. Either way a
//! query yields a few contiguous ranges of the sorted order ("candidates") that contain every
//! particle closer than the radius; the caller filters by distance. Neighbours are visited cell by
//! cell, never stored per particle.
//!
//! Hash collisions only add candidates: a particle in a bucket but not in one of the query's
//! neighbour cells is at least one cell width, i.e. ≥ radius, away on some axis. Buckets shared by
//! two neighbour cells are visited once.
//!
//! The sort is stable (by cell, then original index), so its result does not depend on the
//! thread count.
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::par::SyncPtr;
use crate::vector::{Real, Vector};
use std::ops::Range;

/// Maximum candidate ranges a query returns (3D, hashed: 27 cells).
pub const MAX_RANGES: usize = 27;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Mode {
    /// Cells numbered densely over the bounding box `lo .. lo + n` (cell coordinates).
    Dense { lo: [i64; 3], n: [i64; 3] },
    /// Cell coordinates hashed into `mask + 1` buckets.
    Hash { mask: u64 },
}

/// A cell list over a set of points (see the module docs).
#[derive(Clone, Debug)]
pub struct CellList {
    cell: Real,
    inv_cell: Real,
    dim: usize,
    mode: Mode,
    /// `order[k]`: the original index of the k-th particle in sorted order.
    pub order: Vec<u32>,
    /// Cell coordinates of each particle in sorted order.
    pub cells: Vec<[i64; 3]>,
    /// Bucket b holds sorted particles `start[b] .. start[b + 1]`.
    start: Vec<u32>,
    keys: Vec<u32>,
    hist: Vec<u32>,
    /// Cells a dense numbering may always take (besides 4 per point), `DENSE_FLOOR` unless set.
    dense_floor: usize,
}

/// The dense numbering's allowance besides 4 cells per point.
const DENSE_FLOOR: usize = 4096;

/// Candidate ranges of one query (into the sorted order).
#[derive(Clone, Copy, Debug)]
pub struct Ranges {
    pub r: [(u32, u32); MAX_RANGES],
    pub len: usize,
}

impl Ranges {
    #[inline]
    pub fn iter(&self) -> impl Iterator<Item = Range<usize>> + '_ {
        self.r[..self.len].iter().map(|&(a, b)| a as usize..b as usize)
    }
}

#[inline(always)]
fn cell_coord(x: Real, inv: Real) -> i64 {
    // `as` truncates and saturates (NaN → 0, which callers have rejected): a monotone map, so
    // points within one cell width stay in the same or adjacent cells and nothing is missed.
    // floor by hand: the baseline x86-64 target has no rounding instruction and `floor` is a call.
    // Saturating: below i64::MIN (a huge negative coordinate, or the empty set's bounding box
    // of ±inf) the truncation is already i64::MIN, and 1 less would wrap to the top.
    let t = x * inv;
    let c = t as i64;
    c.saturating_sub(((c as f64) > t) as i64)
}

/// Cell coordinates of `p` for cells of side 1/`inv` (unused axes 0).
#[inline(always)]
fn cell_coords<V: Vector>(p: V, inv: Real) -> [i64; 3] {
    let mut c = [0i64; 3];
    for (k, ck) in c.iter_mut().enumerate().take(V::DIM) {
        *ck = cell_coord(p.comp(k), inv);
    }
    c
}

#[inline(always)]
fn hash(c: [i64; 3], mask: u64) -> usize {
    // Large odd multipliers then a xor-shift mix: neighbouring cells land far apart.
    let h = (c[0] as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (c[1] as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (c[2] as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    ((h ^ (h >> 29) ^ (h >> 47)) & mask) as usize
}

impl CellList {
    /// An empty cell list with cell size `cell` (> 0, finite), for points of dimension `dim`.
    pub fn new(cell: Real, dim: usize) -> Result<Self> {
        if !(cell.is_finite() && cell > 0.0) {
            return Err(invalid("radius", format!("{cell} must be finite and > 0")));
        }
        if !(dim == 2 || dim == 3) {
            return Err(invalid("dim", format!("{dim} must be 2 or 3")));
        }
        Ok(Self {
            cell,
            inv_cell: 1.0 / cell,
            dim,
            mode: Mode::Hash { mask: 0 },
            order: Vec::new(),
            cells: Vec::new(),
            start: vec![0, 0],
            keys: Vec::new(),
            hist: Vec::new(),
            dense_floor: DENSE_FLOOR,
        })
    }

    /// Changes the cell size (> 0, finite), keeping the buffers and the room `reserve` made, so
    /// that a list reserved before its size is known (the contacts' radii) builds without
    /// allocating.
    pub fn set_cell_size(&mut self, cell: Real) -> Result<()> {
        if !(cell.is_finite() && cell > 0.0) {
            return Err(invalid("radius", format!("{cell} must be finite and > 0")));
        }
        (self.cell, self.inv_cell) = (cell, 1.0 / cell);
        Ok(())
    }

    /// Lets a dense numbering take up to `cells` cells whatever the point count (4 bytes a cell
    /// kept, as much again while built: such a sparse numbering is counted in one histogram),
    /// for a list built once and queried every step: the walls of an SPH tank, whose 6,000
    /// points span 38,000 cells in the 41k dam break and so were hashed, and a hashed query
    /// costs 9 hashes where a dense one reads 3 row ranges.
    pub fn with_dense_floor(mut self, cells: usize) -> Self {
        self.dense_floor = cells.max(DENSE_FLOOR);
        self
    }

    pub fn cell_size(&self) -> Real {
        self.cell
    }

    pub fn len(&self) -> usize {
        self.order.len()
    }

    pub fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    /// Whether the last build numbered cells densely (else it hashed them).
    pub fn is_dense(&self) -> bool {
        matches!(self.mode, Mode::Dense { .. })
    }

    /// Cell coordinates of point `p` (unused axes 0).
    #[inline(always)]
    pub fn cell_of<V: Vector>(&self, p: V) -> [i64; 3] {
        cell_coords(p, self.inv_cell)
    }

    /// Sorts `x` (at most u32::MAX − 1 points) into cells. Parallel when `x` is large. Points
    /// should be finite; a NaN coordinate is sorted into some cell (never a panic), since a
    /// diverging step may build once before its finiteness check rolls it back.
    pub fn build<V: Vector>(&mut self, x: &[V]) {
        debug_assert_eq!(V::DIM, self.dim);
        let n = x.len();
        assert!(n < u32::MAX as usize, "cell list: too many points");
        let inv = self.inv_cell;

        let coord = |p: V| cell_coords(p, inv);

        // 1. The bounding box in cells: the cells of the points' coordinate-wise extremes (the
        //    floor is monotone). A point's cell coordinates are recomputed for its key and its
        //    sorted entry rather than stored: as fast (SPH-2D 160k), 24 bytes per point less.
        let bbox = |r: Range<usize>| {
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for p in &x[r] {
                for k in 0..V::DIM {
                    lo[k] = lo[k].min(p.comp(k));
                    hi[k] = hi[k].max(p.comp(k));
                }
            }
            (lo, hi)
        };
        let merge = |a: ([f64; 3], [f64; 3]), b: ([f64; 3], [f64; 3])| {
            let mut o = a;
            for k in 0..3 {
                o.0[k] = a.0[k].min(b.0[k]);
                o.1[k] = a.1[k].max(b.1[k]);
            }
            o
        };
        let (xlo, xhi) = crate::par::reduce(n, ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]), merge, bbox);
        let (mut lo, mut hi) = ([0i64; 3], [0i64; 3]);
        for k in 0..V::DIM {
            // An axis with every coordinate NaN (a diverging step) has an empty box (lo = +inf,
            // hi = −inf): one cell, not a span of −2⁶⁴ that made the dense numbering's clamp panic.
            if xlo[k] <= xhi[k] {
                lo[k] = cell_coord(xlo[k], inv);
                hi[k] = cell_coord(xhi[k], inv);
            }
        }
        let mut dims = [1i64; 3];
        let mut cells: i128 = 1;
        for k in 0..V::DIM {
            let span = if n == 0 { 1 } else { (hi[k] as i128 - lo[k] as i128) + 1 };
            // Saturates: three spans of up to 2⁶⁴ cells each overflow i128 (→ hashed mode).
            cells = cells.saturating_mul(span);
            dims[k] = span.min(i64::MAX as i128) as i64;
        }
        let limit = 4 * n as i128 + self.dense_floor as i128;
        self.mode = if n > 0 && cells <= limit {
            let mut l = [0i64; 3];
            l[..V::DIM].copy_from_slice(&lo[..V::DIM]);
            Mode::Dense { lo: l, n: dims }
        } else {
            let buckets = (2 * n).next_power_of_two().max(1024) as u64;
            Mode::Hash { mask: buckets - 1 }
        };
        let nb = match self.mode {
            Mode::Dense { n: d, .. } => (d[0] * d[1] * d[2]) as usize,
            Mode::Hash { mask } => mask as usize + 1,
        };

        // 2. Bucket of every point.
        self.keys.resize(n, 0);
        let mode = self.mode;
        crate::par::chunks1(&mut self.keys, |s, out| {
            for (k, o) in out.iter_mut().enumerate() {
                *o = bucket(mode, coord(x[s + k])) as u32;
            }
        });

        // 3. Stable counting sort: per-part histograms, exclusive scan over (bucket, part), scatter.
        // One histogram per part, unless the buckets far outnumber the points (a sparse dense
        // numbering, `with_dense_floor`): scanning parts × buckets would cost more than it saves.
        let parallel = n >= crate::par::PAR_MIN && nb <= 8 * n;
        let parts = if parallel { crate::par::threads().clamp(1, 16) } else { 1 };
        let per = n.div_ceil(parts).max(1);
        self.hist.clear();
        self.hist.resize(parts * nb, 0);
        let keys = &self.keys;
        {
            let h = &mut self.hist;
            let count = |(p, hp): (usize, &mut [u32])| {
                for &kk in &keys[(p * per).min(n)..((p + 1) * per).min(n)] {
                    hp[kk as usize] += 1;
                }
            };
            let hs = crate::par::Shared::new(h);
            // SAFETY: part p's histogram goes to index p alone.
            crate::par::each(parts > 1, hs.pieces(nb), 1, |p| count((p, unsafe { hs.piece(nb, p) })));
        }
        self.start.resize(nb + 1, 0);
        let mut acc = 0u32;
        for b in 0..nb {
            self.start[b] = acc;
            for p in 0..parts {
                let c = self.hist[p * nb + b];
                self.hist[p * nb + b] = acc;
                acc += c;
            }
        }
        self.start[nb] = acc;
        self.order.resize(n, 0);
        let out = SyncPtr(self.order.as_mut_ptr());
        let scatter = |(p, off): (usize, &mut [u32])| {
            // Consecutive points mostly share a bucket: keep its next slot in a register while
            // they do (a store and a reload of the counter per point had made this the slowest
            // stage of the build: 0.38 of 1.1 ms for SPH-2D 160k, 2 threads).
            let (a, e) = ((p * per).min(n), ((p + 1) * per).min(n));
            if a == e {
                return;
            }
            let mut b = keys[a] as usize;
            let mut slot = off[b];
            for i in a..e {
                let k = keys[i] as usize;
                if k != b {
                    off[b] = slot;
                    b = k;
                    slot = off[b];
                }
                // SAFETY: the scan gives every (part, bucket) a disjoint slot range within 0..n.
                unsafe { *out.get().add(slot as usize) = i as u32 };
                slot += 1;
            }
            off[b] = slot;
        };
        let h = &mut self.hist;
        let hs = crate::par::Shared::new(h);
        // SAFETY: part p's offsets go to index p alone.
        crate::par::each(parts > 1, hs.pieces(nb), 1, |p| scatter((p, unsafe { hs.piece(nb, p) })));

        // 4. Cell coordinates in sorted order (for queries). Dense: each slot's bucket is its
        //    cell, read off the scan's starts in one sequential pass (reading x again in sorted
        //    order, a random access per point, was 4 % of an SPH-2D 160k step; a finite point's
        //    cell decodes to its coordinates exactly). Hashed: a bucket may hold several cells.
        self.cells.resize(n, [0; 3]);
        let order = &self.order;
        match self.mode {
            Mode::Dense { lo, n: d } => {
                let start = &self.start;
                let decode = |b: usize| {
                    let b = b as i64;
                    [lo[0] + b % d[0], lo[1] + (b / d[0]) % d[1], lo[2] + b / (d[0] * d[1])]
                };
                crate::par::chunks1(&mut self.cells, |s, out| {
                    // The bucket holding slot s: the last whose start is <= s (start[0] = 0).
                    let mut b = start.partition_point(|&st| st as usize <= s) - 1;
                    let mut c = decode(b);
                    for (k, o) in out.iter_mut().enumerate() {
                        if start[b + 1] as usize <= s + k {
                            while start[b + 1] as usize <= s + k {
                                b += 1;
                            }
                            c = decode(b);
                        }
                        *o = c;
                    }
                });
            }
            Mode::Hash { .. } => crate::par::chunks1(&mut self.cells, |s, out| {
                for (k, o) in out.iter_mut().enumerate() {
                    *o = coord(x[order[s + k] as usize]);
                }
            }),
        }
    }

    /// Candidate ranges (into the sorted order) holding every point closer than the cell size to
    /// any point of cell `c`.
    #[inline]
    pub fn query(&self, c: [i64; 3]) -> Ranges {
        let mut out = Ranges { r: [(0, 0); MAX_RANGES], len: 0 };
        if self.order.is_empty() {
            return out;
        }
        let (dz_lo, dz_hi) = if self.dim == 3 { (-1i64, 1i64) } else { (0, 0) };
        match self.mode {
            Mode::Dense { lo, n } => {
                let x0 = c[0].saturating_sub(1).saturating_sub(lo[0]).max(0);
                let x1 = c[0].saturating_add(1).saturating_sub(lo[0]).min(n[0] - 1);
                if x0 > x1 {
                    return out;
                }
                for dz in dz_lo..=dz_hi {
                    let z = c[2].saturating_add(dz).saturating_sub(lo[2]);
                    if z < 0 || z >= n[2] {
                        continue;
                    }
                    for dy in -1i64..=1 {
                        let y = c[1].saturating_add(dy).saturating_sub(lo[1]);
                        if y < 0 || y >= n[1] {
                            continue;
                        }
                        let row = ((z * n[1] + y) * n[0]) as usize;
                        let a = self.start[row + x0 as usize];
                        let b = self.start[row + x1 as usize + 1];
                        if a < b {
                            out.r[out.len] = (a, b);
                            out.len += 1;
                        }
                    }
                }
            }
            Mode::Hash { mask } => {
                let mut seen = [usize::MAX; MAX_RANGES];
                let mut ns = 0;
                for dz in dz_lo..=dz_hi {
                    for dy in -1i64..=1 {
                        for dx in -1i64..=1 {
                            let b = hash([c[0].wrapping_add(dx), c[1].wrapping_add(dy), c[2].wrapping_add(dz)], mask);
                            if seen[..ns].contains(&b) {
                                continue;
                            }
                            seen[ns] = b;
                            ns += 1;
                            let (a, e) = (self.start[b], self.start[b + 1]);
                            if a < e {
                                out.r[out.len] = (a, e);
                                out.len += 1;
                            }
                        }
                    }
                }
            }
        }
        out
    }

    /// Room for a build over `n` points (every buffer at its largest), so that a build is then
    /// sure not to allocate. `what`: the call, for the error.
    pub fn reserve(&mut self, n: usize, what: &'static str) -> Result<()> {
        let parts = crate::par::threads().clamp(1, 16);
        // Buckets: dense ≤ 4n + the dense floor (4096 unless set) cells; hashed: a power of two
        // ≤ 4n (≥ 1024).
        let nb = (4 * n + self.dense_floor).max((2 * n).next_power_of_two().max(1024));
        let bytes = Need::bytes_of::<[i64; 3]>(n) + Need::bytes_of::<u32>(2 * n + (parts + 1) * nb + 1);
        let need = Need::new(what, bytes, format!("the cell list of {} points", count(n as u128)));
        need.check()?;
        need.reserve(&mut self.cells, n)?;
        need.reserve(&mut self.keys, n)?;
        need.reserve(&mut self.order, n)?;
        need.reserve(&mut self.hist, parts * nb)?;
        need.reserve(&mut self.start, nb + 1)
    }

    /// Frees the build's scratch (the keys and histograms), for a list built once.
    pub fn release_scratch(&mut self) {
        self.keys = Vec::new();
        self.hist = Vec::new();
    }

    /// Heap bytes held (for the memory-per-particle figures).
    pub fn bytes(&self) -> usize {
        self.order.capacity() * 4
            + self.cells.capacity() * 24
            + self.start.capacity() * 4
            + self.keys.capacity() * 4
            + self.hist.capacity() * 4
    }
}

#[inline(always)]
fn bucket(mode: Mode, c: [i64; 3]) -> usize {
    match mode {
        Mode::Dense { lo, n } => {
            // Clamped into the box: a no-op for finite points (the box holds them all), and a
            // valid bucket for a NaN coordinate (cell 0, which the NaN-skipping bounding box need
            // not contain) that a diverging step's drift can make before its check rolls it back.
            let at = |k: usize| c[k].clamp(lo[k], lo[k] + n[k] - 1) - lo[k];
            ((at(2) * n[1] + at(1)) * n[0] + at(0)) as usize
        }
        Mode::Hash { mask } => hash(c, mask),
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use glam::DVec3;

    /// Found by the hostile fuzz (`test_fuzz_add_fluid`): points whose every coordinate along an
    /// axis is NaN gave the dense numbering an empty box and its clamp panicked (min > max).
    #[test]
    fn points_all_nan_along_an_axis_build_without_a_panic() {
        let mut list = CellList::new(0.1, 3).unwrap();
        let x = vec![DVec3::new(0.0, f64::NAN, 0.0), DVec3::new(0.05, f64::NAN, 0.3)];
        list.build(&x);
        assert_eq!(list.len(), 2);
        let x = vec![DVec3::NAN; 3];
        list.build(&x);
        assert_eq!(list.len(), 3);
    }

    /// A reproducible uniform draw in [0, 1) (also used by the pair query's tests).
    pub(in crate::neighbors) fn lcg(s: &mut u64) -> f64 {
        *s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*s >> 11) as f64 / (1u64 << 53) as f64
    }

    /// The build is a stable counting sort: buckets ascending, original indices ascending within
    /// a bucket, every point once; in both numberings, for points that come in runs sharing a
    /// cell (the scatter's fast path) and for scattered ones.
    #[test]
    fn order_is_the_stable_sort_by_bucket() {
        for (runs, far) in [(true, false), (false, false), (true, true), (false, true)] {
            let mut s = 11;
            let mut x: Vec<DVec3> = (0..20000)
                .map(|i| {
                    let c = if runs { (i / 5) as f64 } else { i as f64 };
                    let base = DVec3::new((c * 0.37) % 1.0, (c * 0.61) % 1.0, (c * 0.13) % 1.0);
                    base + 0.001 * DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s))
                })
                .collect();
            if far {
                x.push(DVec3::splat(1e12));
            }
            let mut g = CellList::new(0.05, 3).unwrap();
            g.build(&x);
            assert_eq!(g.is_dense(), !far);
            let key = |i: u32| bucket(g.mode, g.cell_of(x[i as usize]));
            let mut seen = vec![false; x.len()];
            for w in g.order.windows(2) {
                assert!((key(w[0]), w[0]) < (key(w[1]), w[1]), "not a stable sort at {w:?}");
            }
            for &i in &g.order {
                assert!(!std::mem::replace(&mut seen[i as usize], true));
            }
            assert!(seen.iter().all(|&v| v));
        }
    }

    /// Cells at the ends of the i64 range: a point far below it saturates to i64::MIN (not past
    /// it to the top), so the map stays monotone; an empty set builds.
    #[test]
    fn cells_saturate_at_the_ends_of_the_range() {
        let mut g = CellList::new(1.0, 3).unwrap();
        assert_eq!(g.cell_of(DVec3::new(-1e300, 0.5, 1e300)), [i64::MIN, 0, i64::MAX]);
        assert_eq!(g.cell_of(DVec3::new(-1.5, -0.0, 2.5)), [-2, 0, 2]);
        g.build::<DVec3>(&[]);
        assert!(g.is_empty() && g.query([0; 3]).len == 0);
        let x = [DVec3::new(-1e300, 0.0, 0.0), DVec3::ZERO, DVec3::new(1e300, 0.0, 0.0)];
        g.build(&x);
        assert!(!g.is_dense());
        for (k, &i) in g.order.iter().enumerate() {
            assert_eq!(g.cells[k], g.cell_of(x[i as usize]));
        }
    }

    /// Each sorted slot's cell is its point's (read off the buckets in the dense numbering):
    /// 2D and 3D, negative coordinates, sparse points (empty buckets between runs), parallel
    /// chunks (1 and 3 threads), and the hashed numbering.
    #[test]
    fn cells_are_each_sorted_points_cell() {
        let mut s = 5;
        let check = |g: &CellList, at: &dyn Fn(usize) -> [i64; 3]| {
            for (k, &i) in g.order.iter().enumerate() {
                assert_eq!(g.cells[k], at(i as usize), "slot {k}");
            }
        };
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                for (spread, far) in [(1.0, false), (7.0, false), (1.0, true)] {
                    let mut x3: Vec<DVec3> = (0..30000)
                        .map(|_| DVec3::new(lcg(&mut s) - 0.5, lcg(&mut s) - 0.7, lcg(&mut s)) * spread)
                        .collect();
                    let mut x2: Vec<glam::DVec2> = x3.iter().map(|p| glam::DVec2::new(p.x, p.y - 3.0)).collect();
                    if far {
                        x3.push(DVec3::splat(1e12));
                        x2.push(glam::DVec2::splat(-1e12));
                    }
                    let mut g3 = CellList::new(0.05, 3).unwrap();
                    g3.build(&x3);
                    check(&g3, &|i| g3.cell_of(x3[i]));
                    let mut g2 = CellList::new(0.03, 2).unwrap();
                    g2.build(&x2);
                    // Spread 7: 3D's box of cells outnumbers 4 per point (hashed), 2D's does not.
                    assert_eq!((g2.is_dense(), g3.is_dense()), (!far, !far && spread == 1.0));
                    check(&g2, &|i| g2.cell_of(x2[i]));
                }
            });
        }
    }

    #[test]
    fn sort_is_independent_of_thread_count() {
        let mut s = 3;
        let x: Vec<DVec3> = (0..20000).map(|_| DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s))).collect();
        let build = |t| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap();
            pool.install(|| {
                let mut g = CellList::new(0.05, 3).unwrap();
                g.build(&x);
                g.order
            })
        };
        assert_eq!(build(1), build(3));
    }

    /// A NaN among finite points (a diverging drift before the step's check) is sorted into a
    /// cell, not out of bounds (the fuzz's dam of points at ±1e308 panicked here), and the finite
    /// points keep their order.
    #[test]
    fn a_nan_point_is_sorted_without_a_panic() {
        let mut x: Vec<DVec3> = (0..6).map(|i| DVec3::new(5.0 + 0.01 * i as f64, 5.0, 5.0)).collect();
        let mut list = CellList::new(1.0, 3).unwrap();
        list.build(&x);
        assert!(list.is_dense());
        let before = list.order.clone();
        x.push(DVec3::new(f64::NAN, 5.0, 5.0));
        list.build(&x);
        assert!(list.is_dense());
        assert_eq!(list.order.len(), 7);
        assert_eq!(&list.order.iter().copied().filter(|&i| i < 6).collect::<Vec<_>>(), &before);
    }
}
