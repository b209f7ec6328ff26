//! Gray–Scott reaction–diffusion resident on the device: the CPU's `grids::gray_scott` step
//! (Pearson, Science 261 (1993) 189, eq. 1–2; forward Euler on the 5- or 7-point Laplacian),
//! cell for cell in the same order of operations, on periodic or free (no-flux) faces.
//!
//! Layout: u and v as flat arrays in the grid's layout (x fastest), twice (the step reads one
//! pair and writes the other; the host swaps bind groups). The books: per workgroup, what the
//! reactions made of u and of v (dt Σ reaction, reduced in a fixed tree order in the workgroup),
//! summed on the host in f64 in workgroup order.
use crate::grid;
use crate::{Chunk, Gpu, GpuError, Precision, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// The fixed coefficients of a Gray–Scott system.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Model {
    /// Cells along x, y, z (z = 1 in 2D).
    pub n: [usize; 3],
    pub dim: usize,
    /// Cell size, m.
    pub dx: f64,
    /// Faces x−, x+, y−, y+, z−, z+: true = free (∂u/∂n = 0), false = periodic.
    pub free: [bool; 6],
    /// Diffusion coefficients (m²/s), feed and kill rates (1/s).
    pub du: f64,
    pub dv: f64,
    pub feed: f64,
    pub kill: f64,
}

/// Why `step` stopped early.
#[derive(Debug, Clone, PartialEq)]
pub enum Halt {
    Stopped,
    /// A cell's u or v stopped being finite within the last submission.
    Diverged {
        cell: usize,
    },
    Failed(GpuError),
}

struct Pair {
    u: wgpu::Buffer,
    v: wgpu::Buffer,
}

/// A Gray–Scott system on one device.
pub struct GrayScott {
    gpu: Arc<Gpu>,
    precision: Precision,
    model: Model,
    cells: usize,
    /// The two buffer pairs; `cur` holds the state.
    bufs: [Pair; 2],
    cur: usize,
    made: wgpu::Buffer,
    saved: Option<(Pair, wgpu::Buffer)>,
    saved_cur: usize,
    flag: wgpu::Buffer,
    params: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// binds[k]: reads pair k, writes pair 1 − k.
    binds: [wgpu::BindGroup; 2],
    step_pipe: wgpu::ComputePipeline,
    check_pipe: wgpu::ComputePipeline,
    /// Workgroups along x (a row's segments of WG cells), and along y and z (the blocks of
    /// `grid::rows_for` rows, folded into y ≤ 65,535 and z).
    groups: (u32, u32, u32),
    chunk: Chunk,
}

/// Steps in one submission at most.
const MAX_CHUNK: u64 = 8192;

impl GrayScott {
    /// Uploads the fields `u`, `v` (one value per cell, the grid's layout) and what the
    /// reactions made so far (`made`: u's, v's).
    ///
    /// Errors: `Unsupported` for f64 on an adapter without it or buffers over its limits,
    /// `OutOfMemory` naming the buffer.
    pub fn new(
        gpu: Arc<Gpu>,
        precision: Precision,
        model: Model,
        u: &[f64],
        v: &[f64],
        made: [f64; 2],
    ) -> Result<Self> {
        assert!(model.dim == 2 || model.dim == 3, "dim must be 2 or 3");
        let cells = model.n.iter().product::<usize>();
        assert!(u.len() == cells && v.len() == cells, "fields must have one value per cell");
        gpu.check_precision(precision)?;
        let grid::Layout { groups: (gx, gy, gz), rows } = grid::layout(model.n)?;
        let slots = gx as u64 * gy as u64 * gz as u64;
        let size = cells as u64 * precision.bytes();
        use wgpu::BufferUsages as U;
        let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let pair = |k: usize| -> Result<Pair> {
            Ok(Pair { u: gpu.buffer(&format!("u ({k})"), size, st)?, v: gpu.buffer(&format!("v ({k})"), size, st)? })
        };
        let bufs = [pair(0)?, pair(1)?];
        let made_buf = gpu.buffer("reaction books", 2 * slots * precision.bytes(), st)?;
        let flag = gpu.buffer("finiteness flag", 16, st)?;
        let params = gpu.buffer("parameters", 32 + 8 * precision.bytes(), U::UNIFORM | U::COPY_DST)?;
        let staging =
            gpu.buffer("read-back staging", size.max(2 * slots * precision.bytes()), U::MAP_READ | U::COPY_DST)?;
        let (layout, step_pipe, check_pipe) = pipelines(&gpu, precision, rows);
        let bind = |a: &Pair, b: &Pair| {
            grid::bind_group(&gpu, "gray-scott", &layout, &[&params, &a.u, &a.v, &b.u, &b.v, &made_buf, &flag])
        };
        let binds = [bind(&bufs[0], &bufs[1]), bind(&bufs[1], &bufs[0])];
        let g = Self {
            gpu,
            precision,
            model,
            cells,
            bufs,
            cur: 0,
            made: made_buf,
            saved: None,
            saved_cur: 0,
            flag,
            params,
            staging,
            binds,
            step_pipe,
            check_pipe,
            groups: (gx, gy, gz),
            chunk: Chunk::new(MAX_CHUNK),
        };
        g.set_fields(Some(u), Some(v))?;
        g.set_made(made)?;
        Ok(g)
    }

    /// The books' slots: one per workgroup.
    fn slots(&self) -> usize {
        self.groups.0 as usize * self.groups.1 as usize * self.groups.2 as usize
    }

    pub fn cells(&self) -> usize {
        self.cells
    }
    pub fn precision(&self) -> Precision {
        self.precision
    }
    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Replaces u and/or v (one value per cell).
    pub fn set_fields(&self, u: Option<&[f64]>, v: Option<&[f64]>) -> Result<()> {
        let p = &self.bufs[self.cur];
        for (b, a) in [(&p.u, u), (&p.v, v)] {
            if let Some(a) = a {
                assert_eq!(a.len(), self.cells, "one value per cell");
                self.gpu.upload(self.precision, b, a);
            }
        }
        self.gpu.wait()
    }

    /// Sets what the reactions made so far (u's, v's), kept in the first workgroup's slot.
    pub fn set_made(&self, made: [f64; 2]) -> Result<()> {
        let mut m = vec![0.0; 2 * self.slots()];
        m[..2].copy_from_slice(&made);
        self.gpu.upload(self.precision, &self.made, &m);
        self.gpu.wait()
    }

    fn write_params(&self, dt: f64) {
        let m = &self.model;
        let free = m.free.iter().enumerate().fold(0u32, |acc, (f, &b)| acc | ((b as u32) << f));
        let u =
            [m.n[0] as u32, m.n[1] as u32, m.n[2] as u32, free, self.groups.0, (m.dim == 3) as u32, self.groups.1, 0];
        let inv = 1.0 / (m.dx * m.dx);
        let r = [dt * m.du * inv, dt * m.dv * inv, dt, m.feed, m.feed + m.kill, 2.0 * m.dim as f64, 0.0, 0.0];
        self.gpu.write_params(self.precision, &self.params, &u, &r);
    }

    /// Records `steps` steps from pair `cur` and the finiteness check of the result.
    fn record(&self, steps: u64) -> wgpu::CommandBuffer {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.step_pipe);
            let mut c = self.cur;
            for _ in 0..steps {
                pass.set_bind_group(0, &self.binds[c], &[]);
                pass.dispatch_workgroups(self.groups.0, self.groups.1, self.groups.2);
                c = 1 - c;
            }
            pass.set_pipeline(&self.check_pipe);
            pass.set_bind_group(0, &self.binds[c], &[]);
            pass.dispatch_workgroups(self.groups.0, self.groups.1, self.groups.2);
        }
        enc.finish()
    }

    /// Runs `n` steps of `dt`, in submissions of up to ~0.1 s (the stop flag read before each,
    /// the finiteness flag after each). Returns the steps completed; on a halt, those before the
    /// failing submission (the caller rolls back to its snapshot).
    pub fn step(&mut self, n: u64, dt: f64, stop: &AtomicBool) -> std::result::Result<u64, (u64, Halt)> {
        self.write_params(dt);
        let mut done = 0;
        while done < n {
            if stop.load(Ordering::Relaxed) {
                return Err((done, Halt::Stopped));
            }
            let k = self.chunk.next(n - done);
            self.gpu.queue.write_buffer(&self.flag, 0, bytemuck::cast_slice(&[u32::MAX; 4]));
            let t0 = Instant::now();
            self.gpu.queue.submit([self.record(k)]);
            let bad = self.gpu.read_u32(&self.flag, &self.staging).map_err(|e| (done, Halt::Failed(e)))?;
            let took = t0.elapsed().as_secs_f64();
            if k % 2 == 1 {
                self.cur = 1 - self.cur;
            }
            if bad != u32::MAX {
                return Err((done, Halt::Diverged { cell: bad as usize }));
            }
            done += k;
            self.chunk.adapt(k, took);
        }
        Ok(done)
    }

    /// u and v read back, as f64.
    pub fn read(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        let p = &self.bufs[self.cur];
        Ok((
            self.gpu.read_reals(self.precision, &p.u, &self.staging, self.cells)?,
            self.gpu.read_reals(self.precision, &p.v, &self.staging, self.cells)?,
        ))
    }

    /// What the reactions made of u and of v so far, per unit cell measure (summed on the host
    /// in f64, in workgroup order).
    pub fn made(&self) -> Result<[f64; 2]> {
        let slots = self.slots();
        let m = self.gpu.read_reals(self.precision, &self.made, &self.staging, 2 * slots)?;
        let mut out = [0.0; 2];
        for s in m.chunks_exact(2) {
            out[0] += s[0];
            out[1] += s[1];
        }
        Ok(out)
    }

    /// Keeps a copy of the state and books on the device (the world's checkpoint).
    pub fn snapshot(&mut self) -> Result<()> {
        if self.saved.is_none() {
            use wgpu::BufferUsages as U;
            let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
            let size = self.cells as u64 * self.precision.bytes();
            self.saved = Some((
                Pair { u: self.gpu.buffer("checkpoint u", size, st)?, v: self.gpu.buffer("checkpoint v", size, st)? },
                self.gpu.buffer("checkpoint reaction books", self.made.size(), st)?,
            ));
        }
        let (p, m) = self.saved.as_ref().expect("made above");
        let live = &self.bufs[self.cur];
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&live.u, 0, &p.u, 0, p.u.size());
        enc.copy_buffer_to_buffer(&live.v, 0, &p.v, 0, p.v.size());
        enc.copy_buffer_to_buffer(&self.made, 0, m, 0, m.size());
        self.gpu.queue.submit([enc.finish()]);
        self.saved_cur = self.cur;
        Ok(())
    }

    /// Returns to the last snapshot (nothing happens without one).
    pub fn restore(&mut self) -> Result<()> {
        if let Some((p, m)) = &self.saved {
            let live = &self.bufs[self.saved_cur];
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(&p.u, 0, &live.u, 0, p.u.size());
            enc.copy_buffer_to_buffer(&p.v, 0, &live.v, 0, p.v.size());
            enc.copy_buffer_to_buffer(m, 0, &self.made, 0, m.size());
            self.gpu.queue.submit([enc.finish()]);
            self.cur = self.saved_cur;
        }
        self.gpu.wait()
    }
}

fn pipelines(
    gpu: &Gpu,
    p: Precision,
    rows: u32,
) -> (wgpu::BindGroupLayout, wgpu::ComputePipeline, wgpu::ComputePipeline) {
    use crate::Bind::{Read as R, ReadWrite as W, Uniform};
    let binds = [Uniform { dynamic: false }, R, R, W, W, W, W];
    let (layout, mut pipes) = gpu.kernels(
        "gray_scott.wgsl",
        p,
        &grid::with_rows(include_str!("gray_scott.wgsl"), rows),
        &binds,
        &["step", "check"],
    );
    let c = pipes.pop().expect("two kernels");
    let s = pipes.pop().expect("two kernels");
    (layout, s, c)
}
