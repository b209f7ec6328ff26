//! Particles on the device: uniform gravity, linear drag and direct pairwise gravity (Plummer
//! softening), stepped by semi-implicit Euler or velocity Verlet, with the energy books.
//!
//! Layout (one `vec4` per particle, f32 or f64): position and mass, velocity and 1/mass (0:
//! pinned), acceleration, and the drag's books. Forces per unit mass as on the CPU path
//! (`terms::gravity`, `terms::drag`, `terms::pairwise_gravity`):
//!   a_i = g − (b/m_i) v_i + G Σ_j m_j (x_j − x_i) / (|x_j − x_i|² + ε²)^{3/2}
//! for free particles, 0 for pinned ones (which still pull). Velocity Verlet evaluates the drag
//! at the predicted velocity v + dt a and books dissipation by the trapezoidal rule, as the CPU's
//! `integrators::verlet` does, so both paths are the same method.
pub use crate::shape::Shape;
use crate::{Chunk, Gpu, GpuError, Precision, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// The integrators the device runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scheme {
    /// v += dt a(x, v); x += dt v.
    SemiImplicitEuler,
    /// Kick–drift–kick (Swope et al. 1982).
    VelocityVerlet,
    /// Yoshida's fourth-order "triple jump": velocity Verlet substeps of w₁dt, w₀dt, w₁dt
    /// (Yoshida, Phys. Lett. A 150 (1990) 262, eqs. 4.12–4.14), as the CPU's `yoshida4`.
    Yoshida4,
}

/// Yoshida's weights: w₁ = 1/(2 − 2^{1/3}), w₀ = 1 − 2w₁ (the CPU's `integrators::yoshida`).
pub const YOSHIDA_W1: f64 = 1.351_207_191_959_657_8;
pub const YOSHIDA_W0: f64 = -1.702_414_383_919_315_3;

/// The forces of a device particle system (all optional; several uniform fields are summed).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Forces {
    /// Uniform gravitational acceleration, m/s² (z = 0 in 2D).
    pub g: [f64; 3],
    /// Linear drag coefficient b, kg/s (F = −b v).
    pub drag: f64,
    /// Direct pairwise gravity: (G, Plummer softening ε in m).
    pub pairwise: Option<(f64, f64)>,
    /// Direct Coulomb forces between the charges (`Particles::set_charges`): (k in N·m²/C²,
    /// Plummer softening ε in m).
    pub coulomb: Option<(f64, f64)>,
}

/// Hookean springs with dashpots between particle pairs (one entry per spring), as the CPU's
/// `terms::springs`: f = [k (L − L0) + c (v_j − v_i)·n] n on i, −f on j.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Springs {
    pub i: Vec<u32>,
    pub j: Vec<u32>,
    /// Stiffness k, N/m.
    pub k: Vec<f64>,
    /// Dashpot coefficient c, N·s/m.
    pub c: Vec<f64>,
    /// Rest length L0, m.
    pub rest: Vec<f64>,
}

impl Springs {
    /// Per particle, its springs in spring order (CSR): start offsets (n + 1), the other ends,
    /// and (k, c, L0, 0) rows.
    fn gathered(&self, n: usize) -> (Vec<u32>, Vec<u32>, Vec<f64>) {
        let mut count = vec![0u32; n + 1];
        for (&a, &b) in self.i.iter().zip(&self.j) {
            count[a as usize + 1] += 1;
            count[b as usize + 1] += 1;
        }
        for p in 0..n {
            count[p + 1] += count[p];
        }
        let start = count.clone();
        let mut fill = count;
        let m = 2 * self.i.len();
        let (mut other, mut rows) = (vec![0u32; m], vec![0.0; 4 * m]);
        for s in 0..self.i.len() {
            for (a, b) in [(self.i[s], self.j[s]), (self.j[s], self.i[s])] {
                let e = fill[a as usize] as usize;
                fill[a as usize] += 1;
                other[e] = b;
                rows[4 * e..4 * e + 3].copy_from_slice(&[self.k[s], self.c[s], self.rest[s]]);
            }
        }
        (start, other, rows)
    }

    /// The gathered springs in slices of `SLICE` particles (sliced ELLPACK): particle i's q-th
    /// entry at `base[i] + q · SLICE`, a slice's entries interleaved lane by lane and padded
    /// to its largest degree, so that a warp's threads read consecutive entries together
    /// (CSR made each thread read its own run: the 1024² cloth ran ~4× off the H100's memory
    /// bandwidth). Entries keep their spring order per particle: the same sums, the same bits.
    /// Returns (offsets: CSR starts (n + 1) then base (n), other ends, rows, slice width);
    /// where padding would more than double the entries (a particle with far more springs
    /// than its slice-mates), the CSR layout itself (base = start, width 1).
    fn sliced(&self, n: usize) -> (Vec<u32>, Vec<u32>, Vec<f64>, u32) {
        let (start, other, rows) = self.gathered(n);
        let deg = |i: usize| (start[i + 1] - start[i]) as usize;
        let slices = n.div_ceil(SLICE);
        let mut base_of_slice = Vec::with_capacity(slices + 1);
        let mut total = 0usize;
        for s in 0..slices {
            base_of_slice.push(total);
            let most = (s * SLICE..((s + 1) * SLICE).min(n)).map(deg).max().unwrap_or(0);
            total += most * SLICE;
        }
        let mut offsets = start.clone();
        if total > 2 * other.len() + SLICE || u32::try_from(total).is_err() {
            offsets.extend_from_slice(&start[..n]);
            return (offsets, other, rows, 1);
        }
        // Padding entries (never read: a particle reads its own degree's) are marked `PAD`, so
        // that `kinds` gives them no kind of their own.
        let (mut o, mut r) = (vec![PAD; total], vec![0.0; 4 * total]);
        for i in 0..n {
            let b = base_of_slice[i / SLICE] + i % SLICE;
            offsets.push(b as u32);
            for q in 0..deg(i) {
                let (from, to) = (start[i] as usize + q, b + q * SLICE);
                o[to] = other[from];
                r[4 * to..4 * to + 4].copy_from_slice(&rows[4 * from..4 * from + 4]);
            }
        }
        (offsets, o, r, SLICE as u32)
    }

    /// The entries' constants as a table of kinds, where there are few: with at most `KINDS`
    /// distinct (k, c, L0) rows (a cloth has three: structure, shear, bend) and fewer than 2²⁴
    /// particles, each entry's other end gets its kind in its top 8 bits and the table replaces
    /// the rows (`Some(table)`); else `None` and nothing changes. The same constants, bit for
    /// bit: only where they are read from changes.
    fn kinds(other: &mut [u32], rows: &[f64], n: usize) -> Option<Vec<f64>> {
        if n >= 1 << 24 {
            return None;
        }
        let mut index: std::collections::HashMap<[u64; 3], u32> = std::collections::HashMap::new();
        let mut table = Vec::new();
        for (e, r) in rows.chunks_exact(4).enumerate() {
            if other[e] == PAD {
                continue;
            }
            let key = [r[0].to_bits(), r[1].to_bits(), r[2].to_bits()];
            let next = index.len() as u32;
            let k = *index.entry(key).or_insert(next);
            if k as usize >= KINDS {
                // Too many kinds: the ends as they were (each below 2²⁴; padding untouched).
                other[..e].iter_mut().filter(|o| **o != PAD).for_each(|o| *o &= 0xff_ffff);
                return None;
            }
            if k == next {
                table.extend_from_slice(&[r[0], r[1], r[2], 0.0]);
            }
            other[e] |= k << 24;
        }
        Some(table)
    }
}

/// The most kinds of spring constants `Springs::kinds` packs (8 bits of an entry).
const KINDS: usize = 256;

/// The other end of a padding entry of the sliced layout (no particle: at most 2²⁴ − 1 of them
/// are packed, and a layout's ends are below 2³²−1).
const PAD: u32 = u32::MAX;

/// Particles per slice of the springs' sliced layout: a warp on NVIDIA (32 threads).
const SLICE: usize = 32;

/// A collider of the projection stage, applied after every step in the order given (the CPU's
/// `constraints` colliders with `Contact::bounce`; restitution e in [0, 1], friction μ ≥ 0):
/// a plane, a box particles are kept in (its faces, `constraints::Aabb`), a sphere or bowl, a
/// capsule, an oriented box ([`Shape`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Collider {
    pub shape: Shape,
    pub restitution: f64,
    pub friction: f64,
}

/// Energy books summed on the host, in f64, in particle order (deterministic).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Books {
    pub kinetic: f64,
    /// −Σ m g·x over free particles.
    pub uniform: f64,
    /// −Σ_{i<j} G m_i m_j / √(r² + ε²).
    pub pairwise: f64,
    /// Energy taken out by drag so far.
    pub dissipated: f64,
    /// Σ ½ k (L − L0)² over the springs.
    pub springs: f64,
    /// Energy taken out by the springs' dashpots so far.
    pub dashpots: f64,
    /// Energy taken out by the colliders so far.
    pub collisions: f64,
    /// k Σ_{i<j} q_i q_j / √(r² + ε²).
    pub coulomb: f64,
}

/// Why `step` stopped early.
#[derive(Debug, Clone, PartialEq)]
pub enum Halt {
    /// The stop flag was raised (Ctrl-C): the steps before it completed.
    Stopped,
    /// A particle's position or velocity stopped being finite within the last submission.
    Diverged {
        particle: usize,
    },
    Failed(GpuError),
}

struct Bufs {
    pos: wgpu::Buffer,
    vel: wgpu::Buffer,
    acc: wgpu::Buffer,
    aux: wgpu::Buffer,
    /// The colliders' books (one real per particle).
    hits: wgpu::Buffer,
    /// The flags (the touched flag is state: a projection makes the carried force stale).
    flag: wgpu::Buffer,
}

/// Particles resident on one device.
pub struct Particles {
    gpu: Arc<Gpu>,
    precision: Precision,
    dim: usize,
    n: usize,
    scheme: Scheme,
    forces: Forces,
    live: Bufs,
    saved: Option<Bufs>,
    saved_acc_valid: bool,
    books: wgpu::Buffer,
    /// The charges (one real per particle; zero until `set_charges`).
    charges: wgpu::Buffer,
    /// The colliders (three rows each) and how many.
    colliders: wgpu::Buffer,
    ncol: u32,
    /// The predicted velocities and the springs' gathered lists (kept alive for the bind group).
    _vp: wgpu::Buffer,
    _springs: [wgpu::Buffer; 3],
    /// The shader's `springs`: 0 none, 1 constants per entry, 2 a table of kinds (`Springs::kinds`).
    springs_mode: u32,
    /// The springs' slice width (32, or 1: the CSR layout; see `Springs::sliced`).
    slice: u32,
    velocity_dependent: bool,
    /// Parameter blocks, one per substep of a composition (bound at dynamic offsets of `slot`).
    params: wgpu::Buffer,
    slot: u64,
    staging: wgpu::Buffer,
    bind: wgpu::BindGroup,
    pipes: Pipes,
    acc_valid: bool,
    /// Particle ranges (start, count) whose state `set_rows` replaced while the accelerations
    /// were carried: theirs are evaluated anew at the next step, every other particle's kept.
    refresh: Vec<(usize, usize)>,
    saved_refresh: Vec<(usize, usize)>,
    /// Copies of the accelerations and drag books while a refresh evaluates the forces.
    scratch: Option<[wgpu::Buffer; 2]>,
    /// 0, or the size of the worlds the pairwise sums keep to (`set_worlds`).
    world: u32,
    /// The fused kernel's scheme (0 Euler, 1 Verlet, 2 Yoshida 4) and substep lengths.
    fused_scheme: u32,
    fused_h: [f64; 2],
    /// Steps per submission (`Chunk`: about 0.1 s each).
    chunk: Chunk,
}

struct Pipes {
    forces: wgpu::ComputePipeline,
    forces_if_touched: wgpu::ComputePipeline,
    clear_touched: wgpu::ComputePipeline,
    project: wgpu::ComputePipeline,
    kick_drift: wgpu::ComputePipeline,
    kick: wgpu::ComputePipeline,
    check: wgpu::ComputePipeline,
    energy: wgpu::ComputePipeline,
    /// The fused small worlds' kernel (worlds.wgsl), built for one world size by `set_worlds`.
    worlds: Option<wgpu::ComputePipeline>,
}

const WG: u32 = 256;
/// Steps in one submission at most.
const MAX_CHUNK: u64 = 4096;
/// Worlds of at most this many particles are stepped by the fused kernel (worlds.wgsl).
pub const MAX_FUSED: u32 = 16;
/// Bytes of the parameter block's integers (`Params` in particles.wgsl: twelve u32).
const PARAM_INTS: u64 = 48;
/// Colliders a device particle system holds.
pub const MAX_COLLIDERS: usize = 64;

/// Rows (of 4 reals) per collider: its kind, restitution, friction and a radius; two points;
/// three axes (an oriented box's).
/// vec4s per collider (`Shape::row`).
const COLLIDER_ROWS: u64 = (crate::shape::ROW / 4) as u64;

impl Particles {
    /// Uploads `n` particles: `x`, `v` flat (n·dim, m and m/s), `mass` (kg, > 0), `inv_mass`
    /// (1/kg, 0 for pinned). The caller has validated the values (the core's scene checks).
    ///
    /// Errors: `Unsupported` for f64 on an adapter without it or buffers over its limits,
    /// `OutOfMemory` naming the buffer.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        gpu: Arc<Gpu>,
        precision: Precision,
        dim: usize,
        scheme: Scheme,
        forces: Forces,
        x: &[f64],
        v: &[f64],
        mass: &[f64],
        inv_mass: &[f64],
        springs: Option<&Springs>,
    ) -> Result<Self> {
        assert!(dim == 2 || dim == 3, "dim must be 2 or 3");
        let n = mass.len();
        assert!(x.len() == n * dim && v.len() == n * dim && inv_mass.len() == n, "ragged particle arrays");
        gpu.check_precision(precision)?;
        let row = 4 * precision.bytes();
        let size = (n as u64).max(1) * row;
        use wgpu::BufferUsages as U;
        let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let mk = |what: &str| gpu.buffer(what, size, st);
        let live = Bufs {
            pos: mk("positions")?,
            vel: mk("velocities")?,
            acc: mk("accelerations")?,
            aux: mk("drag books")?,
            hits: gpu.buffer("collision books", (n as u64).max(1) * precision.bytes(), st)?,
            flag: gpu.buffer("flags", 16, st)?,
        };
        let colliders =
            gpu.buffer("colliders", COLLIDER_ROWS * row * MAX_COLLIDERS as u64, U::STORAGE | U::COPY_DST)?;
        let charges = gpu.buffer("charges", (n as u64).max(1) * precision.bytes(), U::STORAGE | U::COPY_DST)?;
        let books = gpu.buffer("energy books", 2 * size, st)?;
        let vp = mk("predicted velocities")?;
        let empty = Springs::default();
        let sp = springs.unwrap_or(&empty);
        assert!(sp.i.iter().chain(&sp.j).all(|&p| (p as usize) < n), "spring index out of range");
        let (start, mut other, mut rows, slice) = sp.sliced(n);
        let springs_mode = if sp.i.is_empty() {
            0
        } else if let Some(table) = Springs::kinds(&mut other, &rows, n) {
            rows = table;
            2
        } else {
            1
        };
        let ro = U::STORAGE | U::COPY_DST;
        let entries_n = other.len().max(1) as u64;
        let sb = [
            gpu.buffer("spring offsets", 4 * (2 * n as u64 + 1), ro)?,
            gpu.buffer("spring ends", 4 * entries_n, ro)?,
            gpu.buffer("spring constants", (rows.len() as u64 / 4).max(1) * row, ro)?,
        ];
        gpu.queue.write_buffer(&sb[0], 0, bytemuck::cast_slice(&start));
        if !other.is_empty() {
            gpu.queue.write_buffer(&sb[1], 0, bytemuck::cast_slice(&other));
        }
        // Three parameter blocks (Yoshida's substeps), each at the device's uniform offset alignment.
        let align = gpu.device.limits().min_uniform_buffer_offset_alignment as u64;
        let slot = (16 * precision.bytes() + PARAM_INTS).div_ceil(align) * align;
        // A fourth: velocity Verlet's evaluation after a projection (books nothing).
        let params = gpu.buffer("parameters", 4 * slot, U::UNIFORM | U::COPY_DST)?;
        let staging = gpu.buffer("read-back staging", 2 * size, U::MAP_READ | U::COPY_DST)?;
        let (layout, pipes) = pipelines(&gpu, precision, forces.pairwise.is_some() || forces.coulomb.is_some(), 0);
        // The parameters: one block's worth, at the offset given when bound.
        let bind = gpu.bind_with_params(
            "particles",
            &layout,
            &[
                &params, &live.pos, &live.vel, &live.acc, &live.aux, &books, &live.flag, &vp, &sb[0], &sb[1], &sb[2],
                &colliders, &live.hits, &charges,
            ],
            16 * precision.bytes() + PARAM_INTS,
        );
        let mut p = Self {
            gpu,
            precision,
            dim,
            n,
            scheme,
            forces,
            live,
            saved: None,
            saved_acc_valid: false,
            refresh: Vec::new(),
            saved_refresh: Vec::new(),
            scratch: None,
            books,
            charges,
            colliders,
            ncol: 0,
            _vp: vp,
            _springs: sb,
            springs_mode,
            slice,
            velocity_dependent: forces.drag != 0.0 || sp.c.iter().any(|&c| c != 0.0),
            params,
            slot,
            staging,
            bind,
            pipes,
            acc_valid: false,
            world: 0,
            fused_scheme: match scheme {
                Scheme::SemiImplicitEuler => 0,
                Scheme::VelocityVerlet => 1,
                Scheme::Yoshida4 => 2,
            },
            fused_h: [0.0; 2],
            chunk: Chunk::new(MAX_CHUNK),
        };
        if !rows.is_empty() {
            p.upload(&p._springs[2], &rows);
        }
        p.write(x, v, mass, inv_mass);
        let zero = vec![0u8; size as usize];
        p.gpu.queue.write_buffer(&p._vp, 0, &zero);
        p.gpu.queue.write_buffer(&p.live.aux, 0, &zero);
        p.gpu.queue.write_buffer(&p.live.acc, 0, &zero);
        p.gpu.wait()?;
        Ok(p)
    }

    pub fn len(&self) -> usize {
        self.n
    }
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
    pub fn precision(&self) -> Precision {
        self.precision
    }
    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }
    pub fn forces(&self) -> Forces {
        self.forces
    }

    /// Writes positions and velocities (flat, n·dim) with the masses and 1/masses.
    fn write(&mut self, x: &[f64], v: &[f64], m: &[f64], im: &[f64]) {
        assert!(x.len() == self.n * self.dim && v.len() == self.n * self.dim, "ragged particle arrays");
        let pack = |a: &[f64], w: &[f64]| {
            let mut out = vec![0.0; 4 * self.n];
            for i in 0..self.n {
                out[4 * i..4 * i + self.dim].copy_from_slice(&a[self.dim * i..self.dim * (i + 1)]);
                out[4 * i + 3] = w[i];
            }
            out
        };
        self.upload(&self.live.pos, &pack(x, m));
        self.upload(&self.live.vel, &pack(v, im));
        self.acc_valid = false;
        self.refresh.clear();
    }

    /// Replaces the state of the `m.len()` particles from `start`: positions and velocities
    /// (flat, count·dim), masses and 1/masses (0: pinned), their books' accumulators (drag,
    /// dashpots, colliders) set to zero and their accelerations evaluated anew at the next
    /// step. Every other particle's state, acceleration and books stay as they are, bit for
    /// bit: a member of a batch written between calls changes no other member. The caller has
    /// validated the values.
    pub fn set_rows(&mut self, start: usize, x: &[f64], v: &[f64], m: &[f64], im: &[f64]) -> Result<()> {
        let (count, d) = (m.len(), self.dim);
        assert!(start + count <= self.n && im.len() == count, "rows out of range");
        assert!(x.len() == count * d && v.len() == count * d, "ragged particle arrays");
        if count == 0 {
            return Ok(());
        }
        let pack = |a: &[f64], w: &[f64]| {
            let mut out = vec![0.0; 4 * count];
            for i in 0..count {
                out[4 * i..4 * i + d].copy_from_slice(&a[d * i..d * (i + 1)]);
                out[4 * i + 3] = w[i];
            }
            out
        };
        let (row, real) = (4 * self.precision.bytes(), self.precision.bytes());
        let at = start as u64;
        let zero = vec![0.0; 4 * count];
        let g = &self.gpu;
        g.upload_at(self.precision, &self.live.pos, at * row, &pack(x, m));
        g.upload_at(self.precision, &self.live.vel, at * row, &pack(v, im));
        g.upload_at(self.precision, &self.live.aux, at * row, &zero);
        g.upload_at(self.precision, &self.live.hits, at * real, &zero[..count]);
        if self.acc_valid {
            self.refresh.push((start, count));
        }
        Ok(())
    }

    /// Evaluates the accelerations (and the drag books' last powers) of the particles in
    /// `refresh` anew, as the first evaluation of a step does (booking nothing), and keeps every
    /// other particle's: the whole pass runs, then the others' are copied back.
    fn refresh_rows(&mut self, dt: f64) -> Result<()> {
        let size = (self.n as u64).max(1) * 4 * self.precision.bytes();
        if self.scratch.is_none() {
            use wgpu::BufferUsages as U;
            let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
            self.scratch =
                Some([self.gpu.buffer("kept accelerations", size, st)?, self.gpu.buffer("kept drag books", size, st)?]);
        }
        let [sa, sx] = self.scratch.as_ref().expect("made above");
        let l = &self.live;
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&l.acc, 0, sa, 0, size);
        enc.copy_buffer_to_buffer(&l.aux, 0, sx, 0, size);
        self.gpu.queue.submit([enc.finish()]);
        self.write_params(dt, 0.0, 0.0, 0.0, 0.0, false);
        self.submit_one(&self.pipes.forces);
        // The particles outside the refreshed ranges get theirs back.
        let row = 4 * self.precision.bytes();
        let mut ranges = std::mem::take(&mut self.refresh);
        ranges.sort_unstable();
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        let mut from = 0usize;
        for &(start, count) in ranges.iter().chain(std::iter::once(&(self.n, 0))) {
            if start > from {
                let (o, len) = (from as u64 * row, (start - from) as u64 * row);
                enc.copy_buffer_to_buffer(sa, o, &l.acc, o, len);
                enc.copy_buffer_to_buffer(sx, o, &l.aux, o, len);
            }
            from = from.max(start + count);
        }
        self.gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    fn upload(&self, b: &wgpu::Buffer, data: &[f64]) {
        self.gpu.upload(self.precision, b, data)
    }

    fn write_params(&self, dt: f64, h1: f64, h2: f64, w_new: f64, w_old: f64, pred: bool) {
        self.write_params_at(0, dt, h1, h2, w_new, w_old, pred)
    }

    /// Writes parameter block `k` (substep k of a composition).
    #[allow(clippy::too_many_arguments)]
    fn write_params_at(&self, k: u64, dt: f64, h1: f64, h2: f64, w_new: f64, w_old: f64, pred: bool) {
        let f = &self.forces;
        let (gg, eps) = f.pairwise.unwrap_or((0.0, 0.0));
        let u = [
            self.n as u32,
            f.pairwise.is_some() as u32,
            pred as u32,
            self.springs_mode,
            self.dim as u32,
            self.ncol,
            f.coulomb.is_some() as u32,
            self.slice,
            self.world,
            0,
            self.fused_scheme,
            0,
        ];
        let (kc, epc) = f.coulomb.unwrap_or((0.0, 0.0));
        let [ha, hb] = self.fused_h;
        // The colliders' share of semi-implicit Euler's energy error (the CPU's
        // `IntegratorInfo::projection_kick`).
        let kick = if matches!(self.scheme, Scheme::SemiImplicitEuler) { -0.5 * dt } else { 0.0 };
        let r = [dt, h1, h2, w_new, w_old, gg, eps * eps, f.drag, f.g[0], f.g[1], f.g[2], ha, kc, epc * epc, hb, kick];
        self.gpu.write_params_at(self.precision, &self.params, k * self.slot, &u, &r);
    }

    fn groups(&self) -> u32 {
        (self.n as u32).div_ceil(WG).max(1)
    }

    fn velocity_dependent(&self) -> bool {
        self.velocity_dependent
    }

    /// Whether a step carries accelerations into the next that a fresh evaluation would not
    /// give bit for bit: velocity Verlet's and Yoshida 4's, taken at predicted velocities,
    /// where a force depends on the velocities (drag, dashpots). Where it does not, writing
    /// the state anew (which evaluates the forces again) changes no bit.
    pub fn carries_velocity_forces(&self) -> bool {
        matches!(self.scheme, Scheme::VelocityVerlet | Scheme::Yoshida4) && self.velocity_dependent()
    }

    /// Submits one dispatch of `pipe` over the particles.
    fn submit_one(&self, pipe: &wgpu::ComputePipeline) {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_bind_group(0, &self.bind, &[0]);
            pass.set_pipeline(pipe);
            pass.dispatch_workgroups(self.groups(), 1, 1);
        }
        self.gpu.queue.submit([enc.finish()]);
    }

    /// Records `steps` steps into one submission (the parameters already written).
    fn record(&self, steps: u64) -> wgpu::CommandBuffer {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_bind_group(0, &self.bind, &[0]);
            let g = self.groups();
            let colliders = self.ncol > 0;
            for _ in 0..steps {
                match self.scheme {
                    Scheme::SemiImplicitEuler => {
                        pass.set_pipeline(&self.pipes.forces);
                        pass.dispatch_workgroups(g, 1, 1);
                        pass.set_pipeline(&self.pipes.kick_drift);
                        pass.dispatch_workgroups(g, 1, 1);
                    }
                    Scheme::VelocityVerlet | Scheme::Yoshida4 => {
                        if colliders {
                            // The carried force is stale if the last step's projection moved a
                            // particle: evaluated again here, booking nothing (slot 3).
                            pass.set_bind_group(0, &self.bind, &[(3 * self.slot) as u32]);
                            pass.set_pipeline(&self.pipes.forces_if_touched);
                            pass.dispatch_workgroups(g, 1, 1);
                            pass.set_pipeline(&self.pipes.clear_touched);
                            pass.dispatch_workgroups(1, 1, 1);
                            pass.set_bind_group(0, &self.bind, &[0]);
                        }
                        let substeps = if self.scheme == Scheme::Yoshida4 { 3 } else { 1 };
                        for k in 0..substeps {
                            if substeps > 1 {
                                pass.set_bind_group(0, &self.bind, &[(k * self.slot) as u32]);
                            }
                            pass.set_pipeline(&self.pipes.kick_drift);
                            pass.dispatch_workgroups(g, 1, 1);
                            pass.set_pipeline(&self.pipes.forces);
                            pass.dispatch_workgroups(g, 1, 1);
                            pass.set_pipeline(&self.pipes.kick);
                            pass.dispatch_workgroups(g, 1, 1);
                        }
                        if substeps > 1 {
                            pass.set_bind_group(0, &self.bind, &[0]);
                        }
                    }
                }
                if colliders {
                    pass.set_pipeline(&self.pipes.project);
                    pass.dispatch_workgroups(g, 1, 1);
                }
            }
            pass.set_bind_group(0, &self.bind, &[0]);
            pass.set_pipeline(&self.pipes.check);
            pass.dispatch_workgroups(g, 1, 1);
        }
        enc.finish()
    }

    /// Runs `n` steps of `dt`. Steps are recorded into submissions of up to ~0.1 s each; the
    /// stop flag is read before each, and the finiteness flag after each (one u32 read back).
    /// Returns the steps completed; on a halt, those before the failing submission (the caller
    /// rolls back to its snapshot, as the world does for any system).
    pub fn step(&mut self, n: u64, dt: f64, stop: &AtomicBool) -> std::result::Result<u64, (u64, Halt)> {
        if self.n == 0 {
            return Ok(n);
        }
        let fail = |done: u64, e: GpuError| (done, Halt::Failed(e));
        let vv = matches!(self.scheme, Scheme::VelocityVerlet | Scheme::Yoshida4);
        let pred = vv && self.velocity_dependent();
        let fused = self.fused();
        // The fused kernel's substeps, computed as the general path's blocks compute them.
        self.fused_h = match self.scheme {
            Scheme::Yoshida4 => [YOSHIDA_W1 * dt, YOSHIDA_W0 * dt],
            _ => [dt, dt],
        };
        if vv && !self.acc_valid {
            // The first force evaluation of velocity Verlet: books nothing.
            self.write_params(dt, 0.0, 0.0, 0.0, 0.0, false);
            self.submit_one(&self.pipes.forces);
            self.acc_valid = true;
            self.refresh.clear();
        } else if vv && !self.refresh.is_empty() {
            self.refresh_rows(dt).map_err(|e| fail(0, e))?;
        }
        self.refresh.clear(); // (the other schemes carry no accelerations)
        match self.scheme {
            Scheme::SemiImplicitEuler => self.write_params(dt, dt, 0.0, dt, 0.0, false),
            Scheme::VelocityVerlet => {
                self.write_params(dt, 0.5 * dt, 0.5 * dt, 0.5 * dt, 0.5 * dt, pred);
                self.write_params_at(3, dt, 0.0, 0.0, 0.0, 0.0, false);
            }
            Scheme::Yoshida4 => {
                self.write_params_at(3, dt, 0.0, 0.0, 0.0, 0.0, false);
                // Each substep is a Verlet step of its own length (the CPU's `Yoshida4::step`).
                for (k, w) in [YOSHIDA_W1, YOSHIDA_W0, YOSHIDA_W1].into_iter().enumerate() {
                    let h = w * dt;
                    self.write_params_at(k as u64, h, 0.5 * h, 0.5 * h, 0.5 * h, 0.5 * h, pred);
                }
            }
        }
        let mut done = 0;
        while done < n {
            if stop.load(Ordering::Relaxed) {
                return Err((done, Halt::Stopped));
            }
            let k = self.chunk.next(n - done);
            // The first-bad-particle flag only: the touched flag carries over.
            self.gpu.queue.write_buffer(&self.live.flag, 0, bytemuck::cast_slice(&[u32::MAX]));
            let t0 = Instant::now();
            if fused {
                // The step count of this submission (`Params::steps`, block 0).
                self.gpu.queue.write_buffer(&self.params, 36, bytemuck::cast_slice(&[k as u32]));
                self.gpu.queue.submit([self.record_fused()]);
            } else {
                self.gpu.queue.submit([self.record(k)]);
            }
            let bad = self.read_flag().map_err(|e| fail(done, e))?;
            let took = t0.elapsed().as_secs_f64();
            if bad != u32::MAX {
                return Err((done, Halt::Diverged { particle: bad as usize }));
            }
            done += k;
            self.chunk.adapt(k, took);
        }
        Ok(done)
    }

    fn read_flag(&self) -> Result<u32> {
        self.gpu.read_u32(&self.live.flag, &self.staging)
    }

    fn read_reals(&self, b: &wgpu::Buffer) -> Result<Vec<f64>> {
        self.read_rows(b, self.n)
    }

    fn read_rows(&self, b: &wgpu::Buffer, rows: usize) -> Result<Vec<f64>> {
        self.gpu.read_reals(self.precision, b, &self.staging, 4 * rows.max(1))
    }

    /// Positions and velocities, flat (n·dim), as f64.
    pub fn read(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        Ok((self.read_one(false)?, self.read_one(true)?))
    }

    /// Positions (`vel` false) or velocities, flat (n·dim), as f64: one buffer read back.
    pub fn read_one(&self, vel: bool) -> Result<Vec<f64>> {
        let a = self.read_reals(if vel { &self.live.vel } else { &self.live.pos })?;
        let d = self.dim;
        let mut out = Vec::with_capacity(self.n * d);
        for row in a.chunks_exact(4).take(self.n) {
            out.extend_from_slice(&row[..d]);
        }
        Ok(out)
    }

    /// The energy books (reduced on the host in particle order).
    pub fn books(&self) -> Result<Books> {
        Ok(self.books_of(self.n.max(1))?.pop().unwrap_or_default())
    }

    /// The energy books of each world of `size` consecutive particles (`set_worlds`), each
    /// reduced on the host in particle order: one read-back for all.
    pub fn books_of_worlds(&self) -> Result<Vec<Books>> {
        self.books_of(if self.world > 0 { self.world as usize } else { self.n.max(1) })
    }

    fn books_of(&self, size: usize) -> Result<Vec<Books>> {
        if self.n == 0 {
            return Ok(Vec::new());
        }
        self.write_params(0.0, 0.0, 0.0, 0.0, 0.0, false);
        self.submit_one(&self.pipes.energy);
        let e = self.read_rows(&self.books, 2 * self.n)?;
        let hits = if self.ncol > 0 { self.read_hits()? } else { vec![0.0; self.n] };
        let mut out = Vec::with_capacity(self.n / size);
        for (rows, h) in e.chunks_exact(8 * size).zip(hits.chunks_exact(size)) {
            let mut b = Books::default();
            for r in rows.chunks_exact(8) {
                b.kinetic += r[0];
                b.uniform += r[1];
                b.pairwise += r[2];
                b.dissipated += r[3];
                b.springs += r[4];
                b.dashpots += r[5];
                b.coulomb += r[6];
            }
            b.collisions = h.iter().sum();
            out.push(b);
        }
        Ok(out)
    }

    /// Keeps the pairwise sums (gravity, Coulomb) inside worlds of `size` consecutive particles
    /// (0: all particles, the default): a batch of small worlds in one system, each world's
    /// particles pulling only on each other, in one dispatch per stage for all.
    ///
    /// Errors: `Unsupported` if `size` does not divide the particle count.
    pub fn set_worlds(&mut self, size: usize) -> Result<()> {
        if size > 0 && (!self.n.is_multiple_of(size) || size > u32::MAX as usize) {
            return Err(GpuError::Unsupported(format!(
                "worlds of {size} particles do not divide {} particles",
                self.n
            )));
        }
        self.world = size as u32;
        if (1..=MAX_FUSED as usize).contains(&size) {
            let far = self.forces.pairwise.is_some() || self.forces.coulomb.is_some();
            let (layout, pipes) = pipelines(&self.gpu, self.precision, far, self.world);
            self.bind = self.bind_all(&layout);
            self.pipes = pipes;
        }
        Ok(())
    }

    /// The bind group of every buffer, for `layout` (the kernels' bindings, in order).
    fn bind_all(&self, layout: &wgpu::BindGroupLayout) -> wgpu::BindGroup {
        let l = &self.live;
        let s = &self._springs;
        self.gpu.bind_with_params(
            "particles",
            layout,
            &[
                &self.params,
                &l.pos,
                &l.vel,
                &l.acc,
                &l.aux,
                &self.books,
                &l.flag,
                &self._vp,
                &s[0],
                &s[1],
                &s[2],
                &self.colliders,
                &l.hits,
                &self.charges,
            ],
            16 * self.precision.bytes() + PARAM_INTS,
        )
    }

    /// Whether a step runs as the fused worlds' kernel: worlds of at most `MAX_FUSED`, no
    /// drag, springs or colliders.
    fn fused(&self) -> bool {
        self.pipes.worlds.is_some()
            && self.ncol == 0
            && self.springs_mode == 0
            && self.forces.drag == 0.0
            && self.fused_groups() <= 65_535
    }

    /// Workgroups of the fused kernel: one thread a world, 64 a workgroup.
    fn fused_groups(&self) -> u32 {
        ((self.n / self.world.max(1) as usize) as u32).div_ceil(64).max(1)
    }

    /// Records `steps` steps of the fused worlds' kernel (its step count already written), then
    /// the finiteness check.
    fn record_fused(&self) -> wgpu::CommandBuffer {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_bind_group(0, &self.bind, &[0]);
            pass.set_pipeline(self.pipes.worlds.as_ref().expect("fused() checked it"));
            pass.dispatch_workgroups(self.fused_groups(), 1, 1);
            pass.set_pipeline(&self.pipes.check);
            pass.dispatch_workgroups(self.groups(), 1, 1);
        }
        enc.finish()
    }

    /// Replaces the state: positions and velocities (flat, n·dim), masses and 1/masses (0:
    /// pinned), with the books' accumulators (drag, dashpots, colliders) set to zero and the
    /// accelerations to be evaluated anew. The caller has validated the values.
    pub fn set_state(&mut self, x: &[f64], v: &[f64], m: &[f64], im: &[f64]) -> Result<()> {
        assert!(m.len() == self.n && im.len() == self.n, "one mass per particle");
        if self.n == 0 {
            return Ok(());
        }
        self.write(x, v, m, im);
        let zero = vec![0.0; 4 * self.n];
        self.upload(&self.live.aux, &zero);
        self.upload(&self.live.hits, &zero[..self.n]);
        self.gpu.queue.write_buffer(&self.live.flag, 0, bytemuck::cast_slice(&[u32::MAX, 0, 0, 0]));
        self.gpu.wait()
    }

    fn read_hits(&self) -> Result<Vec<f64>> {
        self.gpu.read_reals(self.precision, &self.live.hits, &self.staging, self.n)
    }

    /// Sets the charges (C, one per particle): the Coulomb term's source weights.
    pub fn set_charges(&mut self, q: &[f64]) -> Result<()> {
        assert_eq!(q.len(), self.n, "one charge per particle");
        if self.n > 0 {
            self.upload(&self.charges, q);
        }
        self.gpu.wait()
    }

    /// Sets the colliders (at most `MAX_COLLIDERS`), applied after every step in this order.
    ///
    /// Errors: `Unsupported` for more than `MAX_COLLIDERS`.
    pub fn set_colliders(&mut self, colliders: &[Collider]) -> Result<()> {
        if colliders.len() > MAX_COLLIDERS {
            return Err(GpuError::Unsupported(format!(
                "{} colliders: the GPU path holds at most {MAX_COLLIDERS}",
                colliders.len()
            )));
        }
        let rows: Vec<f64> = colliders.iter().flat_map(|c| c.shape.row([c.restitution, c.friction])).collect();
        if !rows.is_empty() {
            self.upload(&self.colliders, &rows);
        }
        self.ncol = colliders.len() as u32;
        self.gpu.wait()
    }

    /// The raw device rows (position·mass, velocity·1/mass, acceleration, drag books; 4n values
    /// each, as f64), the colliders' books (n values) and whether the accelerations are current
    /// (not after a projection moved a particle): what a restart needs.
    pub fn save_raw(&self) -> Result<([Vec<f64>; 4], Vec<f64>, bool)> {
        let l = &self.live;
        let touched = self.gpu.read_back(&l.flag, &self.staging, 8)?[4..8] != [0; 4];
        Ok((
            [self.read_reals(&l.pos)?, self.read_reals(&l.vel)?, self.read_reals(&l.acc)?, self.read_reals(&l.aux)?],
            self.read_hits()?,
            self.acc_valid && !touched,
        ))
    }

    /// Loads what `save_raw` gave (rounded to the device's precision).
    pub fn load_raw(&mut self, raw: &[Vec<f64>; 4], hits: &[f64], acc_valid: bool) -> Result<()> {
        assert!(raw.iter().all(|a| a.len() == 4 * self.n) && hits.len() == self.n, "ragged raw arrays");
        let l = &self.live;
        for (b, a) in [&l.pos, &l.vel, &l.acc, &l.aux].into_iter().zip(raw) {
            self.upload(b, a);
        }
        if self.n > 0 {
            self.upload(&l.hits, hits);
        }
        self.gpu.queue.write_buffer(&l.flag, 0, bytemuck::cast_slice(&[u32::MAX, 0, 0, 0]));
        self.acc_valid = acc_valid;
        self.refresh.clear();
        self.gpu.wait()
    }

    /// Keeps a copy of the state on the device (the world's checkpoint).
    pub fn snapshot(&mut self) -> Result<()> {
        if self.saved.is_none() {
            let size = (self.n as u64).max(1) * 4 * self.precision.bytes();
            use wgpu::BufferUsages as U;
            let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
            let mk = |what: &str| self.gpu.buffer(what, size, st);
            self.saved = Some(Bufs {
                pos: mk("checkpoint positions")?,
                vel: mk("checkpoint velocities")?,
                acc: mk("checkpoint accelerations")?,
                aux: mk("checkpoint drag books")?,
                hits: self.gpu.buffer(
                    "checkpoint collision books",
                    (self.n as u64).max(1) * self.precision.bytes(),
                    st,
                )?,
                flag: self.gpu.buffer("checkpoint flags", 16, st)?,
            });
        }
        let s = self.saved.as_ref().expect("made above");
        self.copy(&self.live, s);
        self.saved_acc_valid = self.acc_valid;
        self.saved_refresh.clone_from(&self.refresh);
        Ok(())
    }

    /// Returns to the last snapshot (nothing happens without one).
    pub fn restore(&mut self) -> Result<()> {
        if let Some(s) = &self.saved {
            self.copy(s, &self.live);
            self.acc_valid = self.saved_acc_valid;
            self.refresh.clone_from(&self.saved_refresh);
        }
        self.gpu.wait()
    }

    fn copy(&self, from: &Bufs, to: &Bufs) {
        let size = (self.n as u64).max(1) * 4 * self.precision.bytes();
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        for (a, b) in [(&from.pos, &to.pos), (&from.vel, &to.vel), (&from.acc, &to.acc), (&from.aux, &to.aux)] {
            enc.copy_buffer_to_buffer(a, 0, b, 0, size);
        }
        enc.copy_buffer_to_buffer(&from.hits, 0, &to.hits, 0, to.hits.size());
        enc.copy_buffer_to_buffer(&from.flag, 0, &to.flag, 0, 16);
        self.gpu.queue.submit([enc.finish()]);
    }
}

/// The kernels; `far`: the scene has pairwise sums (gravity, Coulomb), else the force kernels are
/// `forces_local` (the tiles' code compiled out: no workgroup memory, fewer registers).
/// The kernels; with `world` in 1..=`MAX_FUSED`, also the fused kernel for worlds of that size
/// (worlds.wgsl appended, its size a constant: its loops unrolled, its state in registers).
fn pipelines(gpu: &Gpu, p: Precision, far: bool, world: u32) -> (wgpu::BindGroupLayout, Pipes) {
    use crate::Bind::{Read as R, ReadWrite as W, Uniform};
    // The parameters are bound at a dynamic offset: one block per substep of a composition.
    let binds = [Uniform { dynamic: true }, W, W, W, W, W, W, W, R, R, R, R, W, R];
    let (f, ft) = if far { ("forces", "forces_if_touched") } else { ("forces_local", "forces_local_if_touched") };
    let mut names = vec![f, ft, "clear_touched", "project", "kick_drift", "kick", "check", "energy"];
    let fused = (1..=MAX_FUSED).contains(&world);
    let src = if fused {
        names.push("worlds");
        format!("{}\nconst W: u32 = {world}u;\n{}", include_str!("particles.wgsl"), include_str!("worlds.wgsl"))
    } else {
        include_str!("particles.wgsl").to_string()
    };
    let (layout, pipes) = gpu.kernels("particles.wgsl", p, &src, &binds, &names);
    let mut pipes = pipes.into_iter();
    let mut next = || pipes.next().unwrap_or_else(|| unreachable!("a kernel per name"));
    let [forces, forces_if_touched, clear_touched, project, kick_drift, kick, check, energy] =
        std::array::from_fn(|_| next());
    let worlds = fused.then(next);
    (layout, Pipes { forces, forces_if_touched, clear_touched, project, kick_drift, kick, check, energy, worlds })
}

#[cfg(test)]
mod tests {
    use super::{Springs, PAD, SLICE};

    fn springs(pairs: &[(u32, u32)]) -> Springs {
        let m = pairs.len();
        Springs {
            i: pairs.iter().map(|p| p.0).collect(),
            j: pairs.iter().map(|p| p.1).collect(),
            k: (0..m).map(|s| 1.0 + s as f64).collect(),
            c: vec![0.5; m],
            rest: (0..m).map(|s| 0.1 * s as f64).collect(),
        }
    }

    /// Particle i's entries (other end, row) in the order the kernel visits them.
    fn visits(off: &[u32], other: &[u32], rows: &[f64], w: u32, n: usize, i: usize) -> Vec<(u32, Vec<f64>)> {
        let deg = off[i + 1] - off[i];
        (0..deg)
            .map(|q| {
                let e = (off[n + 1 + i] + q * w) as usize;
                (other[e], rows[4 * e..4 * e + 4].to_vec())
            })
            .collect()
    }

    #[test]
    fn a_few_kinds_of_constants_pack_into_the_ends_and_many_leave_them_as_they_were() {
        // A 30 × 30 cloth, structural and shear springs: two kinds of rest length.
        let side = 30u32;
        let mut pairs = Vec::new();
        for r in 0..side - 1 {
            for c in 0..side - 1 {
                let p = r * side + c;
                pairs.extend_from_slice(&[(p, p + 1), (p, p + side), (p, p + side + 1)]);
            }
        }
        let n = (side * side) as usize;
        let mut s = springs(&pairs);
        s.k = vec![100.0; pairs.len()];
        s.rest = pairs.iter().map(|&(a, b)| if b == a + side + 1 { 0.1 * 2f64.sqrt() } else { 0.1 }).collect();
        let (off, o, r, w) = s.sliced(n);
        let mut packed = o.clone();
        let table = Springs::kinds(&mut packed, &r, n).expect("two kinds");
        assert_eq!(table.len(), 4 * 2, "structure and shear (the slices' padding takes no kind)");
        assert!(o.contains(&PAD), "the layout has padding");
        for i in 0..n {
            let deg = off[i + 1] - off[i];
            for q in 0..deg {
                let e = (off[n + 1 + i] + q * w) as usize;
                let k = (packed[e] >> 24) as usize;
                assert_eq!(packed[e] & 0xff_ffff, o[e]);
                assert_eq!(&table[4 * k..4 * k + 4], &r[4 * e..4 * e + 4]);
            }
        }
        // 300 kinds: past the 256 the top byte holds; the ends come back untouched.
        let many = springs(&pairs[..300]);
        let (_, o, r, _) = many.sliced(n);
        let mut same = o.clone();
        assert!(Springs::kinds(&mut same, &r, n).is_none());
        assert_eq!(same, o);
        // Exactly 256 kinds pack, padding and all.
        let mut full = springs(&pairs[..256]);
        full.k = (0..256).map(|k| 1.0 + k as f64).collect();
        let (_, o, r, _) = full.sliced(n);
        assert!(o.contains(&PAD));
        let mut packed = o.clone();
        assert_eq!(Springs::kinds(&mut packed, &r, n).map(|t| t.len()), Some(4 * 256));
    }

    #[test]
    fn the_sliced_layout_visits_each_particles_springs_in_the_csr_order() {
        // A 40 × 40 cloth's structural springs (degrees 2 to 4, slices cut across rows).
        let side = 40u32;
        let mut pairs = Vec::new();
        for r in 0..side {
            for c in 0..side {
                let p = r * side + c;
                if c + 1 < side {
                    pairs.push((p, p + 1));
                }
                if r + 1 < side {
                    pairs.push((p, p + side));
                }
            }
        }
        let s = springs(&pairs);
        let n = (side * side) as usize;
        let (start, other, rows) = s.gathered(n);
        let (off, o, r, w) = s.sliced(n);
        assert_eq!(w as usize, SLICE);
        assert_eq!(&off[..=n], &start[..]);
        let mut csr = start.clone();
        csr.extend_from_slice(&start[..n]);
        for i in 0..n {
            assert_eq!(visits(&off, &o, &r, w, n, i), visits(&csr, &other, &rows, 1, n, i), "particle {i}");
        }
    }

    #[test]
    fn a_hub_keeps_the_csr_layout() {
        // One particle joined to 1,000 others: its slice padded to 1,000 would hold 32,000.
        let pairs: Vec<(u32, u32)> = (1..1001).map(|j| (0, j)).collect();
        let s = springs(&pairs);
        let (start, other, rows) = s.gathered(1001);
        let (off, o, r, w) = s.sliced(1001);
        assert_eq!(w, 1);
        assert_eq!((&off[..1002], &o, &r), (&start[..], &other, &rows));
        assert_eq!(&off[1002..], &start[..1001]);
    }
}
