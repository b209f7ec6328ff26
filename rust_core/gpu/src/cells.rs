//! A cell list on the device: the neighbour search the particle fluids and grains on a GPU will
//! gather over (issue "GPU fluids, grains and batches"). Particles are binned into the cells of a
//! box by a counting sort (u32 atomics for the counts, a prefix scan in three dispatches, an
//! atomic scatter) and each cell's particles are then put in index order, so the order is the same on
//! every run (the atomics decide only the order before that sort) and any sum gathered over it
//! repeats bit for bit. Particles outside the box fall into its edge cells.
//!
//! Not yet used by a scene: `neighbours` (each particle's count of neighbours within the radius,
//! over the 3^d cells around its own) is the gather's check against a brute-force count.
use crate::{Bind, Gpu, GpuError, Precision, Result};
use std::sync::Arc;

const WG: u32 = 64;

/// Cells a workgroup of the scan covers (`cells.wgsl`'s BLOCK: 256 threads of 4 cells).
const SCAN_BLOCK: usize = 1024;

/// cells.wgsl's build kernels, in dispatch order (`CellBuild::record`).
const BUILD: [&str; 7] = ["clear", "bin", "scan_blocks", "scan_tops", "scan_apply", "scatter", "sort_cells"];

/// The scan's block dispatch over `cells` cells, folded into y past 65,535 (`block_of`).
fn scan_groups(cells: usize) -> (u32, u32) {
    let b = cells.div_ceil(SCAN_BLOCK) as u32;
    (b.clamp(1, 65_535), b.div_ceil(65_535).max(1))
}

/// Writes cells.wgsl's parameter block to `buf`: `n` particles in `dim` dimensions over `cells`
/// cells (z = 1 in 2D) of side `cell` m from the corner `lo` (m).
pub(crate) fn write_cell_params(
    gpu: &Gpu,
    precision: Precision,
    buf: &wgpu::Buffer,
    (n, dim): (usize, usize),
    cells: [usize; 3],
    (lo, cell): ([f64; 3], f64),
) {
    let ints = [n as u32, dim as u32, cells[0] as u32, cells[1] as u32, cells[2] as u32, 0, 0, 0];
    gpu.write_params(precision, buf, &ints, &[lo[0], lo[1], lo[2], cell, cell]);
}

/// cells.wgsl's build for a particle pass (WCSPH, DFSPH, DEM, the tests' `Cells`): its
/// pipelines, their bind group and the scan's block totals, over a grid of `cells` cells.
pub(crate) struct CellBuild {
    pipes: Vec<wgpu::ComputePipeline>,
    bind: wgpu::BindGroup,
    cells: usize,
    _blocks: wgpu::Buffer,
}

impl CellBuild {
    /// `bufs`: cells.wgsl's bindings 0–6 (the parameters, positions, each particle's cell, the
    /// counts, the starts, the order, the neighbour counts); `extra`: entry points after the
    /// build's (the tests' "neighbours").
    pub(crate) fn new(
        gpu: &Gpu,
        precision: Precision,
        label: &str,
        bufs: [&wgpu::Buffer; 7],
        cells: usize,
        extra: &[&str],
    ) -> Result<Self> {
        use wgpu::BufferUsages as U;
        let blocks =
            gpu.buffer(&format!("{label}: scan blocks"), (cells.div_ceil(SCAN_BLOCK) as u64 * 4).max(16), U::STORAGE)?;
        use Bind::{Read as R, ReadWrite as W, Uniform};
        let names: Vec<&str> = BUILD.iter().chain(extra).copied().collect();
        let binds = [Uniform { dynamic: false }, R, W, W, W, W, W, W];
        let (layout, pipes) = gpu.kernels("cells.wgsl", precision, include_str!("cells.wgsl"), &binds, &names);
        let mut all = bufs.to_vec();
        all.push(&blocks);
        let bind = crate::grid::bind_group(gpu, label, &layout, &all);
        Ok(Self { pipes, bind, cells, _blocks: blocks })
    }

    /// Records the build of `n` particles' cell list (the bind group stays set).
    pub(crate) fn record(&self, pass: &mut wgpu::ComputePass, n: usize) {
        let (p, m, b) = (spread(n), spread(self.cells), scan_groups(self.cells));
        pass.set_bind_group(0, &self.bind, &[]);
        for (pipe, (x, y)) in self.pipes.iter().zip([m, p, b, (1, 1), b, p, m]) {
            pass.set_pipeline(pipe);
            pass.dispatch_workgroups(x, y, 1);
        }
    }
}

/// The box and its cells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub dim: usize,
    /// The lower corner (m; z ignored in 2D).
    pub lo: [f64; 3],
    /// The cell size (m), at least the interaction radius.
    pub cell: f64,
    /// Cells along x, y, z (z = 1 in 2D).
    pub n: [usize; 3],
    /// The interaction radius (m).
    pub radius: f64,
}

/// A cell list of `n` particles on one device.
pub struct Cells {
    gpu: Arc<Gpu>,
    precision: Precision,
    grid: Grid,
    n: usize,
    pos: wgpu::Buffer,
    start: wgpu::Buffer,
    order: wgpu::Buffer,
    found: wgpu::Buffer,
    staging: wgpu::Buffer,
    build: CellBuild,
    _keep: [wgpu::Buffer; 3],
}

/// A 1D dispatch of `n` threads, folded into y past 65,535 workgroups (the shader's `index`).
pub(crate) fn spread(n: usize) -> (u32, u32) {
    let wgs = (n as u32).div_ceil(WG);
    (wgs.min(65_535), wgs.div_ceil(65_535).max(1))
}

impl Cells {
    /// Uploads the positions (`dim` per particle, m).
    ///
    /// Errors: `Unsupported` for f64 on an adapter without it, a cell smaller than the radius,
    /// or more cells than u32 indexes; `OutOfMemory` naming the buffer.
    pub fn new(gpu: Arc<Gpu>, precision: Precision, grid: Grid, positions: &[f64]) -> Result<Self> {
        gpu.check_precision(precision)?;
        let d = grid.dim;
        assert!((d == 2 || d == 3) && positions.len().is_multiple_of(d), "dim values per particle");
        if !(grid.cell >= grid.radius && grid.radius > 0.0) {
            return Err(GpuError::Unsupported(format!("cells of {} m for a radius of {} m", grid.cell, grid.radius)));
        }
        let n = positions.len() / d;
        let cells = grid.n.iter().map(|&v| v as u64).product::<u64>();
        if cells == 0 || cells >= u32::MAX as u64 / 2 || n as u64 >= u32::MAX as u64 / 2 {
            return Err(GpuError::Unsupported(format!("{cells} cells and {n} particles: at most 2^31 of each")));
        }
        let rb = precision.bytes();
        use wgpu::BufferUsages as U;
        let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let pos = gpu.buffer("cell list positions", positions.len() as u64 * rb, st)?;
        let cell_of = gpu.buffer("cell list cells", n as u64 * 4, st)?;
        let counts = gpu.buffer("cell list counts", cells * 4, st)?;
        let start = gpu.buffer("cell list starts", (cells + 1) * 4, st)?;
        let order = gpu.buffer("cell list order", n as u64 * 4, st)?;
        let found = gpu.buffer("cell list neighbours", n as u64 * 4, st)?;
        let staging = gpu.buffer("cell list read-back", ((cells + 1).max(n as u64)) * 4, U::MAP_READ | U::COPY_DST)?;
        let params = gpu.buffer("cell list parameters", 32 + 8 * rb, U::UNIFORM | U::COPY_DST)?;
        let bufs = [&params, &pos, &cell_of, &counts, &start, &order, &found];
        let build = CellBuild::new(&gpu, precision, "cells", bufs, cells as usize, &["neighbours"])?;
        gpu.upload(precision, &pos, positions);
        let ints = [n as u32, d as u32, grid.n[0] as u32, grid.n[1] as u32, grid.n[2] as u32, 0, 0, 0];
        gpu.write_params(precision, &params, &ints, &[grid.lo[0], grid.lo[1], grid.lo[2], grid.cell, grid.radius]);
        Ok(Self { gpu, precision, grid, n, pos, start, order, found, staging, build, _keep: [cell_of, counts, params] })
    }

    /// Replaces the positions (as many as before).
    pub fn set_positions(&self, positions: &[f64]) {
        assert_eq!(positions.len(), self.n * self.grid.dim, "dim values per particle");
        self.gpu.upload(self.precision, &self.pos, positions);
    }

    /// Bins the particles and counts each one's neighbours (one submission).
    pub fn build(&self) -> Result<()> {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            self.build.record(&mut pass, self.n);
            let (x, y) = spread(self.n);
            pass.set_pipeline(&self.build.pipes[BUILD.len()]);
            pass.dispatch_workgroups(x, y, 1);
        }
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait()
    }

    fn read_u32(&self, b: &wgpu::Buffer, count: usize) -> Result<Vec<u32>> {
        let raw = self.gpu.read_back(b, &self.staging, (count as u64).max(1) * 4)?;
        Ok(raw.chunks_exact(4).take(count).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }

    /// The particles by cell (each cell's in index order), each cell's first slot in that order
    /// (one more: the particle count), and each particle's neighbours within the radius.
    pub fn read(&self) -> Result<(Vec<u32>, Vec<u32>, Vec<u32>)> {
        let cells = self.grid.n.iter().product::<usize>();
        Ok((
            self.read_u32(&self.order, self.n)?,
            self.read_u32(&self.start, cells + 1)?,
            self.read_u32(&self.found, self.n)?,
        ))
    }
}
