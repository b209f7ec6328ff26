//! What the kernels of cell-centred grids share (`gray_scott.wgsl`, `wave.wgsl`): their
//! workgroups' layout and their bind groups.
use crate::{Gpu, GpuError, Result};

/// A workgroup's cells: `WG` of a row (its threads) in each of `ROWS` rows (the shaders' `WG`,
/// `CPT`).
pub(crate) const WG: u32 = 64;
pub(crate) const ROWS: u64 = 4;

/// Workgroups along x, y and z for a grid of `n` cells (x, y, z; z = 1 in 2D): one workgroup per
/// `WG` cells of a row and `ROWS` rows (a block, the blocks folded into y and z), so that a
/// thread divides once to find its cell's j and k. At most 65,535 workgroups along each axis
/// (`Unsupported` beyond).
pub(crate) fn layout(n: [usize; 3]) -> Result<(u32, u32, u32)> {
    let gx = (n[0] as u64).div_ceil(WG as u64);
    let blocks = ((n[1] * n[2]) as u64).div_ceil(ROWS);
    let gy = blocks.min(65_535);
    let gz = blocks.div_ceil(gy);
    if gx > 65_535 || gz > 65_535 {
        return Err(GpuError::Unsupported(format!(
            "a grid of {} × {} × {} cells: the GPU path dispatches at most 65,535 × 64 cells along x and \
             65,535² × 4 rows",
            n[0], n[1], n[2]
        )));
    }
    Ok((gx as u32, gy as u32, gz as u32))
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
