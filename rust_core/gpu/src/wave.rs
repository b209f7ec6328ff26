//! The damped wave equation resident on the device: the CPU's `grids::wave` leapfrog step
//! (Langtangen & Linge, "Finite Difference Computing with PDEs", 2017, §2.1) cell for cell in
//! the same order of operations, with fixed, free and periodic faces, damping layers (γ per
//! cell), obstacles and driven sources (oscillators).
//!
//! Layout: u and u⁻ as flat arrays in the grid's layout (x fastest); a step writes u⁺ over u⁻
//! and the roles swap (two bind groups). The oscillators' forcing f(t) = A sin(2π ν t + φ) is
//! computed on the host for every step of a submission (the CPU's `sin`, so the device adds the
//! same values) and uploaded with it. The books: per workgroup, the damping's Σ γ v̄² (reduced
//! in a fixed tree order in the workgroup), and the sources' damping and work, accumulated by
//! the one thread that applies them; summed on the host in f64 in slot order.
use crate::grid::{self, WG};
use crate::{Chunk, Gpu, GpuError, Precision, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// A face's rule (the CPU's `grids::Edge`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Face {
    Fixed,
    Free,
    Periodic,
}

/// An oscillator: f(t) = amplitude · sin(2π·frequency·t + phase) on its cells, times each
/// cell's weight.
#[derive(Clone, Debug, PartialEq)]
pub struct Oscillator {
    pub amplitude: f64,
    pub frequency: f64,
    pub phase: f64,
    pub profile: Vec<(usize, f64)>,
}

/// The fixed coefficients of a wave system.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// Cells along x, y, z (z = 1 in 2D).
    pub n: [usize; 3],
    pub dim: usize,
    /// Cell size, m.
    pub dx: f64,
    /// Faces x−, x+, y−, y+, z−, z+.
    pub faces: [Face; 6],
    /// Wave speed, m/s, and the uniform damping rate γ, 1/s.
    pub c: f64,
    pub gamma: f64,
    /// γ per cell where the grid has damping layers (the uniform γ plus the layer's), else empty.
    pub gamma_cells: Vec<f64>,
    /// 1 on free cells, 0 on obstacles; empty without obstacles.
    pub keep: Vec<f64>,
    pub oscillators: Vec<Oscillator>,
}

/// Why `step` stopped early.
#[derive(Debug, Clone, PartialEq)]
pub enum Halt {
    Stopped,
    /// A cell's u stopped being finite within the last submission.
    Diverged {
        cell: usize,
    },
    Failed(GpuError),
}

/// What a checkpoint holds on the device.
struct Saved {
    u: wgpu::Buffer,
    up: wgpu::Buffer,
    diss: wgpu::Buffer,
    src_books: wgpu::Buffer,
}

/// A wave system on one device.
pub struct Wave {
    gpu: Arc<Gpu>,
    precision: Precision,
    model: Model,
    cells: usize,
    entries: usize,
    /// u and u⁻: `bufs[cur]` is u.
    bufs: [wgpu::Buffer; 2],
    cur: usize,
    diss: wgpu::Buffer,
    flag: wgpu::Buffer,
    ints: wgpu::Buffer,
    src: wgpu::Buffer,
    params: wgpu::Buffer,
    staging: wgpu::Buffer,
    saved: Option<Saved>,
    saved_cur: usize,
    /// binds[k]: u is bufs[k], u⁻ (written with u⁺) bufs[1 − k].
    binds: [wgpu::BindGroup; 2],
    step_pipe: wgpu::ComputePipeline,
    gather_pipe: wgpu::ComputePipeline,
    sources_pipe: wgpu::ComputePipeline,
    check_pipe: wgpu::ComputePipeline,
    groups: (u32, u32, u32),
    chunk: Chunk,
}

/// Steps in one submission at most (with oscillators, their forcing of every step travels with it).
const MAX_CHUNK: u64 = 8192;

impl Wave {
    /// Uploads u and u⁻ (one value per cell, the grid's layout).
    ///
    /// Errors: `Unsupported` for f64 on an adapter without it or buffers over its limits,
    /// `OutOfMemory` naming the buffer.
    pub fn new(gpu: Arc<Gpu>, precision: Precision, model: Model, u: &[f64], up: &[f64]) -> Result<Self> {
        assert!(model.dim == 2 || model.dim == 3, "dim must be 2 or 3");
        let cells = model.n.iter().product::<usize>();
        assert!(u.len() == cells && up.len() == cells, "fields must have one value per cell");
        assert!(model.gamma_cells.is_empty() || model.gamma_cells.len() == cells, "γ per cell or none");
        assert!(model.keep.is_empty() || model.keep.len() == cells, "a mask value per cell or none");
        gpu.check_precision(precision)?;
        let entries: usize = model.oscillators.iter().map(|o| o.profile.len()).sum();
        if entries as u64 > u32::MAX as u64 / 4 {
            return Err(GpuError::Unsupported(format!("{entries} source cells: at most 2^30")));
        }
        let grid::Layout { groups: (gx, gy, gz), rows } = grid::layout(model.n)?;
        let slots = gx as u64 * gy as u64 * gz as u64;
        let rb = precision.bytes();
        let size = cells as u64 * rb;
        use wgpu::BufferUsages as U;
        let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let bufs = [gpu.buffer("u (0)", size, st)?, gpu.buffer("u (1)", size, st)?];
        let gam = gpu.buffer("γ per cell", model.gamma_cells.len() as u64 * rb, st)?;
        let keep = gpu.buffer("obstacle mask", model.keep.len() as u64 * rb, st)?;
        let diss = gpu.buffer("damping books", slots * rb, st)?;
        let flag = gpu.buffer("finiteness flag", 16, st)?;
        let ints = gpu.buffer("source cells", (1 + 2 * entries as u64) * 4, st)?;
        let nosc = model.oscillators.len() as u64;
        let src = gpu.buffer("sources", (2 + 2 * entries as u64 + MAX_CHUNK * nosc) * rb, st)?;
        let params = gpu.buffer("parameters", 48 + 8 * rb, U::UNIFORM | U::COPY_DST)?;
        let staging = gpu.buffer("read-back staging", size.max(slots * rb).max(16), U::MAP_READ | U::COPY_DST)?;
        let (layout, mut pipes) = {
            use crate::Bind::{Read as R, ReadWrite as W, Uniform};
            let binds = [Uniform { dynamic: false }, R, W, R, R, W, W, W, W];
            gpu.kernels(
                "wave.wgsl",
                precision,
                &grid::with_rows(include_str!("wave.wgsl"), rows),
                &binds,
                &["step", "gather", "sources", "check"],
            )
        };
        let check_pipe = pipes.pop().expect("four kernels");
        let sources_pipe = pipes.pop().expect("four kernels");
        let gather_pipe = pipes.pop().expect("four kernels");
        let step_pipe = pipes.pop().expect("four kernels");
        let bind = |a: &wgpu::Buffer, b: &wgpu::Buffer| {
            grid::bind_group(&gpu, "wave", &layout, &[&params, a, b, &gam, &keep, &diss, &flag, &ints, &src])
        };
        let binds = [bind(&bufs[0], &bufs[1]), bind(&bufs[1], &bufs[0])];
        if !model.gamma_cells.is_empty() {
            gpu.upload(precision, &gam, &model.gamma_cells);
        }
        if !model.keep.is_empty() {
            gpu.upload(precision, &keep, &model.keep);
        }
        // The entries' cells and oscillators, then their weights (after the books and u⁻ slots).
        let mut cells_of = vec![0u32];
        let mut weights = Vec::with_capacity(entries);
        for (o, osc) in model.oscillators.iter().enumerate() {
            for &(c, w) in &osc.profile {
                assert!(c < cells, "a source cell inside the grid");
                cells_of.extend([c as u32, o as u32]);
                weights.push(w);
            }
        }
        gpu.queue.write_buffer(&ints, 0, bytemuck::cast_slice(&cells_of));
        let mut head = vec![0.0; 2 + 2 * entries];
        head[2 + entries..].copy_from_slice(&weights);
        gpu.upload(precision, &src, &head);
        let w = Self {
            gpu,
            precision,
            model,
            cells,
            entries,
            bufs,
            cur: 0,
            diss,
            flag,
            ints,
            src,
            params,
            staging,
            saved: None,
            saved_cur: 0,
            binds,
            step_pipe,
            gather_pipe,
            sources_pipe,
            check_pipe,
            groups: (gx, gy, gz),
            chunk: Chunk::new(MAX_CHUNK),
        };
        w.set_fields(u, up)?;
        w.clear_books()?;
        Ok(w)
    }

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

    /// Replaces u and u⁻ (one value per cell each).
    pub fn set_fields(&self, u: &[f64], up: &[f64]) -> Result<()> {
        assert!(u.len() == self.cells && up.len() == self.cells, "one value per cell");
        self.gpu.upload(self.precision, &self.bufs[self.cur], u);
        self.gpu.upload(self.precision, &self.bufs[1 - self.cur], up);
        self.gpu.wait()
    }

    /// Sets the books (the damping's and the sources' damping and work) to zero.
    pub fn clear_books(&self) -> Result<()> {
        self.gpu.upload(self.precision, &self.diss, &vec![0.0; self.slots()]);
        self.gpu.upload(self.precision, &self.src, &[0.0, 0.0]);
        self.gpu.wait()
    }

    fn write_params(&self, dt: f64) {
        let m = &self.model;
        let code = |f: Face| match f {
            Face::Fixed => 0u32,
            Face::Free => 1,
            Face::Periodic => 2,
        };
        let edges = m.faces.iter().enumerate().fold(0u32, |acc, (f, &e)| acc | (code(e) << (2 * f)));
        let damped = m.gamma != 0.0 || !m.gamma_cells.is_empty();
        let flags = (!m.gamma_cells.is_empty()) as u32 | ((!m.keep.is_empty() as u32) << 1) | ((damped as u32) << 2);
        let (g, dim3) = (self.groups, (m.dim == 3) as u32);
        let ints = [
            m.n[0] as u32,
            m.n[1] as u32,
            m.n[2] as u32,
            edges,
            g.0,
            dim3,
            g.1,
            flags,
            self.entries as u32,
            m.oscillators.len() as u32,
            0,
            0,
        ];
        // The CPU's k, dt/2, 1/(1 + a) and 1 − a for the uniform γ (grids::wave: `step`, `span`).
        let (k, half) = ((m.c * dt / m.dx).powi(2), 0.5 * dt);
        let a0 = m.gamma * half;
        let reals = [k, (2 * m.dim) as f64, half, m.gamma, dt, 0.25 / dt, 1.0 / (1.0 + a0), 1.0 - a0];
        self.gpu.write_params(self.precision, &self.params, &ints, &reals);
    }

    /// Records `steps` steps from buffer `cur` and the finiteness check of the result.
    fn record(&self, steps: u64) -> wgpu::CommandBuffer {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            let mut c = self.cur;
            let gather = (self.entries as u32).div_ceil(WG);
            for _ in 0..steps {
                pass.set_bind_group(0, &self.binds[c], &[]);
                if self.entries > 0 {
                    pass.set_pipeline(&self.gather_pipe);
                    pass.dispatch_workgroups(gather, 1, 1);
                }
                pass.set_pipeline(&self.step_pipe);
                pass.dispatch_workgroups(self.groups.0, self.groups.1, self.groups.2);
                if self.entries > 0 {
                    pass.set_pipeline(&self.sources_pipe);
                    pass.dispatch_workgroups(1, 1, 1);
                }
                c = 1 - c;
            }
            pass.set_pipeline(&self.check_pipe);
            pass.set_bind_group(0, &self.binds[c], &[]);
            pass.dispatch_workgroups(self.groups.0, self.groups.1, self.groups.2);
        }
        enc.finish()
    }

    /// Runs `n` steps of `dt` from time `t` (s; the oscillators' clock), in submissions of up to
    /// ~0.1 s (the stop flag read before each, the finiteness flag after each). Returns the steps
    /// completed; on a halt, those before the failing submission (the caller rolls back to its
    /// snapshot). The caller's clock advances by `dt` per step completed, added one at a time as
    /// here.
    pub fn step(&mut self, n: u64, dt: f64, t: f64, stop: &AtomicBool) -> std::result::Result<u64, (u64, Halt)> {
        self.write_params(dt);
        let mut done = 0;
        let mut t = t;
        let nosc = self.model.oscillators.len();
        while done < n {
            if stop.load(Ordering::Relaxed) {
                return Err((done, Halt::Stopped));
            }
            let k = self.chunk.next(n - done);
            let mut t_end = t;
            if nosc > 0 {
                // The forcing of each step of the submission, at the time the CPU's step sees.
                let mut f = Vec::with_capacity(k as usize * nosc);
                for _ in 0..k {
                    for o in &self.model.oscillators {
                        f.push(o.amplitude * (2.0 * std::f64::consts::PI * o.frequency * t_end + o.phase).sin());
                    }
                    t_end += dt;
                }
                let offset = (2 + 2 * self.entries as u64) * self.precision.bytes();
                self.gpu.upload_at(self.precision, &self.src, offset, &f);
                self.gpu.queue.write_buffer(&self.ints, 0, bytemuck::cast_slice(&[0u32]));
            } else {
                for _ in 0..k {
                    t_end += dt;
                }
            }
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
            t = t_end;
            self.chunk.adapt(k, took);
        }
        Ok(done)
    }

    /// u and u⁻ read back, as f64.
    pub fn read(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        Ok((
            self.gpu.read_reals(self.precision, &self.bufs[self.cur], &self.staging, self.cells)?,
            self.gpu.read_reals(self.precision, &self.bufs[1 - self.cur], &self.staging, self.cells)?,
        ))
    }

    /// The books since they were last cleared, per unit cell measure: the energy damping took
    /// out (the cells' and the sources' share together) and the work the sources did (summed on
    /// the host in f64, in slot order).
    pub fn books(&self) -> Result<[f64; 2]> {
        let d = self.gpu.read_reals(self.precision, &self.diss, &self.staging, self.slots())?;
        let s = self.gpu.read_reals(self.precision, &self.src, &self.staging, 2)?;
        Ok([d.iter().sum::<f64>() + s[0], s[1]])
    }

    /// Keeps a copy of the state and books on the device (the world's checkpoint).
    pub fn snapshot(&mut self) -> Result<()> {
        if self.saved.is_none() {
            use wgpu::BufferUsages as U;
            let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
            let size = self.cells as u64 * self.precision.bytes();
            self.saved = Some(Saved {
                u: self.gpu.buffer("checkpoint u", size, st)?,
                up: self.gpu.buffer("checkpoint u⁻", size, st)?,
                diss: self.gpu.buffer("checkpoint damping books", self.diss.size(), st)?,
                src_books: self.gpu.buffer("checkpoint source books", 16, st)?,
            });
        }
        let s = self.saved.as_ref().expect("made above");
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&self.bufs[self.cur], 0, &s.u, 0, s.u.size());
        enc.copy_buffer_to_buffer(&self.bufs[1 - self.cur], 0, &s.up, 0, s.up.size());
        enc.copy_buffer_to_buffer(&self.diss, 0, &s.diss, 0, s.diss.size());
        enc.copy_buffer_to_buffer(&self.src, 0, &s.src_books, 0, 2 * self.precision.bytes());
        self.gpu.queue.submit([enc.finish()]);
        self.saved_cur = self.cur;
        Ok(())
    }

    /// Returns to the last snapshot (nothing happens without one).
    pub fn restore(&mut self) -> Result<()> {
        if let Some(s) = &self.saved {
            let c = self.saved_cur;
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(&s.u, 0, &self.bufs[c], 0, s.u.size());
            enc.copy_buffer_to_buffer(&s.up, 0, &self.bufs[1 - c], 0, s.up.size());
            enc.copy_buffer_to_buffer(&s.diss, 0, &self.diss, 0, s.diss.size());
            enc.copy_buffer_to_buffer(&s.src_books, 0, &self.src, 0, 2 * self.precision.bytes());
            self.gpu.queue.submit([enc.finish()]);
            self.cur = c;
        }
        self.gpu.wait()
    }
}
