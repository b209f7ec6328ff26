//! The device cell list against the host: the particles by cell, each cell's in index order (a
//! sort by (cell, index)), each cell's first slot, and each particle's neighbours within the
//! radius against a brute-force count; 2D and 3D, particles outside the box (clamped into its
//! edge cells), crowded cells, f32 and f64; two builds give the same order. Skips without an
//! adapter unless `PHYSCORE_GPU_REQUIRED=1` (CI, on lavapipe).
use physcore_gpu::cells::{Cells, Grid};
use physcore_gpu::{Gpu, Precision};
use std::sync::Arc;

mod common;
use common::gpu;

/// A deterministic value in [0, 1).
fn unit(k: u64) -> f64 {
    let mut z = k.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

fn check(g: &Arc<Gpu>, precision: Precision, grid: Grid, x: &[f64]) {
    let d = grid.dim;
    let n = x.len() / d;
    // The host's cells, by the shader's rule in the device's precision (rounded positions).
    let round = |v: f64| if precision == Precision::F32 { v as f32 as f64 } else { v };
    let axis = |v: f64, lo: f64, m: usize| {
        let f = (round(v) - round(lo)) / round(grid.cell);
        if f > 0.0 {
            (f as usize).min(m - 1)
        } else {
            0
        }
    };
    let cell = |i: usize| {
        let c: Vec<usize> = (0..3).map(|a| if a < d { axis(x[d * i + a], grid.lo[a], grid.n[a]) } else { 0 }).collect();
        c[0] + grid.n[0] * (c[1] + grid.n[1] * c[2])
    };
    let mut want: Vec<u32> = (0..n as u32).collect();
    want.sort_by_key(|&i| (cell(i as usize), i));
    let cells = grid.n.iter().product::<usize>();
    let mut starts = vec![0u32; cells + 1];
    for i in 0..n {
        starts[cell(i) + 1] += 1;
    }
    for c in 0..cells {
        starts[c + 1] += starts[c];
    }
    let r2 = grid.radius * grid.radius;
    let near: Vec<u32> = (0..n)
        .map(|i| {
            (0..n)
                .filter(|&j| {
                    j != i && (0..d).map(|a| (round(x[d * j + a]) - round(x[d * i + a])).powi(2)).sum::<f64>() < r2
                })
                .count() as u32
        })
        .collect();
    let c = Cells::new(g.clone(), precision, grid, x).unwrap();
    c.build().unwrap();
    let (order, start, found) = c.read().unwrap();
    assert_eq!(start, starts, "{precision:?} {grid:?}: starts");
    assert_eq!(order, want, "{precision:?} {grid:?}: order");
    assert_eq!(found, near, "{precision:?} {grid:?}: neighbours");
    c.build().unwrap();
    assert_eq!(c.read().unwrap().0, order, "a second build gives the same order");
}

#[test]
fn the_device_cell_list_sorts_by_cell_and_finds_the_neighbours() {
    let Some(g) = gpu() else { return };
    for precision in [Precision::F32, Precision::F64] {
        if g.check_precision(precision).is_err() {
            continue;
        }
        // The scan covers 1,024 cells a workgroup: one block, two (the second part-filled), and
        // 342 (350,000 cells, mostly empty: its block totals' scan takes two a thread).
        for (dim, n, cells) in [(2usize, 3000usize, [40usize, 25, 1]), (3, 2000, [12, 10, 9]), (2, 3000, [700, 500, 1])]
        {
            let radius = 0.05;
            let grid = Grid { dim, lo: [0.0, 0.0, 0.0], cell: 0.05, n: cells, radius };
            // Spread over the box and 10 % beyond it (clamped into the edge cells), and a crowd
            // of 200 in one corner cell.
            let mut x = Vec::new();
            for i in 0..n as u64 {
                for a in 0..dim as u64 {
                    let ext = cells[a as usize] as f64 * 0.05;
                    x.push(if i < 200 { 0.04 * unit(7 * i + a) } else { -0.1 * ext + 1.2 * ext * unit(7 * i + a) });
                }
            }
            check(&g, precision, grid, &x);
        }
    }
}

/// `Gpu::open` hands every caller on one adapter the same device (scenes share its queue);
/// `Gpu::open_own` a device of the caller's own, which later `open`s do not hand out.
#[test]
fn open_shares_the_adapters_device_and_open_own_does_not() {
    let Some(own) = gpu() else { return };
    let which = common::which();
    let a = Gpu::open(which).unwrap();
    let b = Gpu::open(which).unwrap();
    let c = Gpu::open_own(which).unwrap();
    assert!(Arc::ptr_eq(&a, &b), "two opens on one adapter share its device");
    assert!(!Arc::ptr_eq(&a, &c) && !Arc::ptr_eq(&own, &c) && !Arc::ptr_eq(&own, &a), "open_own shares nothing");
    assert_eq!(a.adapter(), c.adapter());
    drop(c);
    assert!(Arc::ptr_eq(&a, &Gpu::open(which).unwrap()), "the shared device outlives an own one");
}
