//! What the kernels of cell-centred grids share (`gray_scott.wgsl`, `wave.wgsl`): their
//! workgroups' layout and their bind groups.
use crate::{Gpu, GpuError, Result};

/// A workgroup's cells: `WG` of a row (its threads) in each of `rows` rows (the shaders' `WG`
/// and `CPT`; see [`rows_for`]).
pub(crate) const WG: u32 = 64;

/// How a grid's cells are dealt to workgroups: `groups` along x, y and z, each of `WG` cells of a
/// row in each of `rows` consecutive rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Layout {
    pub groups: (u32, u32, u32),
    pub rows: u32,
}

/// Rows per workgroup for a grid of `cells`: 16, 8 or 4, the most that still leaves 2^19 threads
/// (about two full waves of a large GPU: the H200's 132 SMs hold 270,336). A workgroup reduces
/// its books once (a tree of six barriers), so more rows make that rarer and read each row's
/// neighbours from the cache more often; fewer threads than the GPU holds leave it idle.
/// Measured on the H200 (Gray–Scott, f32, cell-steps/s, 2 × 2 alternating calls): at 4096²,
/// 4 rows 1.41–1.43e11, 8 rows 1.61–1.65e11, 16 rows 1.68–1.69e11 (its books left out
/// altogether: 1.96–1.98e11); at 1024², 4 rows 7.3–9.7e10, 16 rows 5.7–6.6e10.
pub(crate) fn rows_for(cells: u64) -> u32 {
    let threads = THREADS.with(|t| t.get());
    [16u32, 8].into_iter().find(|&r| cells / r as u64 >= threads).unwrap_or(4)
}

thread_local! {
    static THREADS: std::cell::Cell<u64> = const { std::cell::Cell::new(1 << 19) };
}

/// Tests only: grids built on this thread from now on take their rows as if 2^19 threads were
/// `threads` (1: 16 rows on any grid of 16 cells or more), so that small grids run the kernels'
/// 8- and 16-row blocks.
#[doc(hidden)]
pub fn set_threads_for_tests(threads: u64) {
    THREADS.with(|t| t.set(threads.max(1)));
}

/// Workgroups along x, y and z for a grid of `n` cells (x, y, z; z = 1 in 2D): one workgroup per
/// `WG` cells of a row and [`rows_for`] rows (a block, the blocks folded into y and z), so that a
/// thread divides once to find its cell's j and k. At most 65,535 workgroups along each axis
/// (`Unsupported` beyond).
pub(crate) fn layout(n: [usize; 3]) -> Result<Layout> {
    let rows = rows_for(n.iter().map(|&v| v as u64).product());
    let gx = (n[0] as u64).div_ceil(WG as u64);
    let blocks = ((n[1] * n[2]) as u64).div_ceil(rows as u64);
    let gy = blocks.min(65_535);
    let gz = blocks.div_ceil(gy);
    if gx > 65_535 || gz > 65_535 {
        return Err(GpuError::Unsupported(format!(
            "a grid of {} × {} × {} cells: the GPU path dispatches at most 65,535 × 64 cells along x and \
             65,535² × {rows} rows",
            n[0], n[1], n[2]
        )));
    }
    Ok(Layout { groups: (gx as u32, gy as u32, gz as u32), rows })
}

/// `wgsl` with its rows per workgroup (`const CPT: u32 = 4u;`, which it must hold once) set to
/// `rows`.
pub(crate) fn with_rows(wgsl: &str, rows: u32) -> String {
    const LINE: &str = "const CPT: u32 = 4u;";
    assert_eq!(wgsl.matches(LINE).count(), 1, "a grid kernel declares its rows once");
    wgsl.replace(LINE, &format!("const CPT: u32 = {rows}u;"))
}

/// A bind group of `layout` binding `buffers` whole, binding k the k-th.
pub(crate) fn bind_group(
    gpu: &Gpu,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    buffers: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
        .collect();
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_grow_with_the_grid_and_the_blocks_cover_it() {
        assert_eq!(rows_for(1024 * 1024), 4);
        assert_eq!(rows_for(2048 * 2048), 8);
        assert_eq!(rows_for(4096 * 4096), 16);
        assert_eq!(rows_for(1), 4);
        for n in [[1, 1, 1], [100, 37, 1], [4096, 4096, 1], [300, 200, 170], [64, 65_535 * 4 + 3, 1]] {
            let l = layout(n).unwrap();
            let blocks = l.groups.1 as u64 * l.groups.2 as u64;
            assert!(blocks * l.rows as u64 >= (n[1] * n[2]) as u64, "{n:?}");
            assert!(l.groups.0 as u64 * WG as u64 >= n[0] as u64, "{n:?}");
        }
        let w = with_rows("a\nconst CPT: u32 = 4u;\nb", 16);
        assert!(w.contains("const CPT: u32 = 16u;") && !w.contains("= 4u;"));
    }
}
