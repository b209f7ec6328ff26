//! The pair query: every pair i < j of a point set closer than a radius, as two index arrays
//! (what `physcore.neighbors` returns), read off a cell list (`super::cell_list`). Rows are counted
//! first, so that the memory for the pairs is asked once, then filled block by block (in parallel)
//! in row order: the result does not depend on the thread count.
use super::cell_list::CellList;
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::vector::{Real, Vector};

impl CellList {
    /// All pairs (i, j), i < j (original indices), with squared distance < radius² evaluated in
    /// f64 as Σ_k (x_i,k − x_j,k)², sorted by i then j, as int64 (what numpy indexes with).
    /// The pairs are counted first, so memory for them is asked once, in full, and a refusal is
    /// `Error::OutOfMemory` naming the pair count. `radius` ≤ the cell size.
    pub fn pairs<V: Vector>(&self, x: &[V], radius: Real) -> Result<(Vec<i64>, Vec<i64>)> {
        let n = x.len();
        assert_eq!(n, self.order.len(), "cell list built for other points");
        assert!(radius <= self.cell_size());
        let r2 = radius * radius;
        let need = Need::new("neighbors", Need::bytes_of::<u32>(n), format!("{} points", count(n as u128)));
        // Sorted slot of each original index, to find a point's cell.
        let mut slot = need.filled(n, 0u32)?;
        for (k, &i) in self.order.iter().enumerate() {
            slot[i as usize] = k as u32;
        }
        // Row i: its neighbours j > i, sorted, into `row` (room for every candidate reserved).
        let neighbours = |i: usize, row: &mut Vec<u32>| -> Result<()> {
            let xi = x[i];
            let ranges = self.query(self.cells[slot[i] as usize]);
            row.clear();
            need.reserve(row, ranges.iter().map(|r| r.len()).sum())?;
            for rg in ranges.iter() {
                for &j in &self.order[rg] {
                    let j = j as usize;
                    if j > i {
                        let mut d2 = 0.0;
                        for k in 0..V::DIM {
                            let d = xi.comp(k) - x[j].comp(k);
                            d2 += d * d;
                        }
                        if d2 < r2 {
                            row.push(j as u32);
                        }
                    }
                }
            }
            Ok(())
        };
        let chunk = crate::par::CHUNK;
        let blocks = n.div_ceil(chunk);
        let rows = |b: usize| b * chunk..((b + 1) * chunk).min(n);
        // 1. Pairs per block of rows.
        let count_block = |b: usize| -> Result<usize> {
            let mut row = Vec::new();
            let mut c = 0;
            for i in rows(b) {
                neighbours(i, &mut row)?;
                c += row.len();
            }
            Ok(c)
        };
        // Every block counted, then the first error in block order (the same for any thread count).
        let counts: Vec<usize> = crate::par::map_chunks(n, blocks, count_block).into_iter().collect::<Result<_>>()?;
        let total: usize = counts.iter().sum();
        let need = Need::new("neighbors", 2 * Need::bytes_of::<i64>(total), format!("{} pairs", count(total as u128)));
        need.check()?;
        let mut i_out = need.filled(total, 0i64)?;
        let mut j_out = need.filled(total, 0i64)?;
        // 2. Each block fills its own slices, in row order.
        let mut parts = Vec::with_capacity(blocks);
        let (mut is, mut js) = (&mut i_out[..], &mut j_out[..]);
        for (b, &c) in counts.iter().enumerate() {
            let (a, rest_i) = std::mem::take(&mut is).split_at_mut(c);
            let (bb, rest_j) = std::mem::take(&mut js).split_at_mut(c);
            parts.push((b, a, bb));
            is = rest_i;
            js = rest_j;
        }
        let fill = |(b, pi, pj): (usize, &mut [i64], &mut [i64])| -> Result<()> {
            let mut row = Vec::new();
            let mut k = 0;
            for i in rows(b) {
                neighbours(i, &mut row)?;
                row.sort_unstable();
                for &j in &row {
                    pi[k] = i as i64;
                    pj[k] = j as i64;
                    k += 1;
                }
            }
            Ok(())
        };
        crate::par::map_vec(n, parts, |_, part| fill(part)).into_iter().collect::<Result<()>>()?;
        Ok((i_out, j_out))
    }
}

/// All pairs i < j of `x` closer than `radius` (see [`CellList::pairs`]).
pub fn neighbor_pairs<V: Vector>(x: &[V], radius: Real) -> Result<(Vec<i64>, Vec<i64>)> {
    if let Some(i) = x.iter().position(|p| !p.is_finite()) {
        return Err(invalid("points", format!("row {i} is not finite")));
    }
    if x.len() >= u32::MAX as usize {
        return Err(invalid("points", "too many points"));
    }
    if !(radius.is_finite() && radius > 0.0) {
        return Err(invalid("radius", format!("{radius} must be finite and > 0")));
    }
    // floor(x/cell) is rounded: two points just under `radius` apart could land two cells apart.
    // A cell slightly larger than the radius, by more than the rounding of x/cell (relative
    // 2⁻⁵³ of the largest |x|/radius), makes that impossible; it only adds candidates.
    let amax = x.iter().map(|p| (0..V::DIM).map(|k| p.comp(k).abs()).fold(0.0, f64::max)).fold(0.0, f64::max);
    let margin = (8.0 * f64::EPSILON * (amax / radius + 1.0)).max(1e-12);
    let cell = radius * (1.0 + margin);
    let mut g = CellList::new(if cell.is_finite() { cell } else { f64::MAX }, V::DIM)?;
    g.reserve(x.len(), "neighbors")?;
    g.build(x);
    g.pairs(x, radius)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::neighbors::cell_list::tests::lcg;
    use glam::{DVec2, DVec3};

    fn brute<V: Vector>(x: &[V], r: Real) -> (Vec<i64>, Vec<i64>) {
        let (mut a, mut b) = (vec![], vec![]);
        for i in 0..x.len() {
            for j in i + 1..x.len() {
                let mut d2 = 0.0;
                for k in 0..V::DIM {
                    let d = x[i].comp(k) - x[j].comp(k);
                    d2 += d * d;
                }
                if d2 < r * r {
                    a.push(i as i64);
                    b.push(j as i64);
                }
            }
        }
        (a, b)
    }

    #[test]
    fn matches_brute_force_dense_and_hashed() {
        let mut s = 7;
        for &(n, span, far) in &[(500usize, 5.0, false), (5000, 20.0, false), (300, 5.0, true), (6000, 30.0, true)] {
            let mut x: Vec<DVec2> =
                (0..n).map(|_| DVec2::new(lcg(&mut s) * span - span / 2.0, lcg(&mut s) * span)).collect();
            if far {
                x.push(DVec2::new(1e12, -3e11)); // forces hashing
            }
            let got = neighbor_pairs(&x, 0.7).unwrap();
            assert_eq!(got, brute(&x, 0.7));
            let mut g = CellList::new(0.7, 2).unwrap();
            g.build(&x);
            assert_eq!(g.is_dense(), !far);
        }
        let x: Vec<DVec3> =
            (0..3000).map(|_| DVec3::new(lcg(&mut s) * 6.0, lcg(&mut s) * 6.0, lcg(&mut s) * 6.0)).collect();
        assert_eq!(neighbor_pairs(&x, 0.8).unwrap(), brute(&x, 0.8));
    }
}
