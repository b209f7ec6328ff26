//! Stam's stable fluid resident on the device: the CPU's `grids::fluid` step stage for stage
//! (its advection, sources, forces, incremental projection, implicit viscosity and energy
//! books), with the pressure solved by MGPCG and viscosity by diagonally preconditioned CG on
//! the device (the CPU's `grids::poisson`, whose stencils and coarse levels the host builds and
//! hands over as [`Operator`]s).
//!
//! What differs from the CPU: the reductions (kinetic energy, smoke, the solvers' dot products)
//! add in another fixed order (a tree per workgroup, then one workgroup over the partials), so
//! f64 runs agree with the CPU to round-off and the solvers' tolerances rather than bit for bit;
//! tracers are not here (the caller refuses them). Runs repeat bit for bit on one adapter.
//!
//! Submissions: a step is recorded as one stream of dispatches up to each solve; a solve is
//! recorded as a budget of iterations (its last count and two more) whose dispatches are
//! indirect, so that the iterations after convergence (decided on the device) run empty; the
//! host then reads the solve's few ints, records more iterations if it had not ended, and goes
//! on. So a step without viscosity waits for the device once.
use crate::{Gpu, GpuError, Precision, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A 5-point operator on padded arrays (the CPU's `poisson::Stencil`): `nx × ny` unknowns at
/// (i + 1) + (nx + 2)(j + 1); east and north link weights, the identity part and the neighbour
/// count, each padded. Its diagonal is d0 + s·count for the scale s.
#[derive(Clone, Debug, PartialEq)]
pub struct Operator {
    pub nx: usize,
    pub ny: usize,
    pub we: Vec<f64>,
    pub wn: Vec<f64>,
    pub d0: Vec<f64>,
    pub count: Vec<f64>,
}

impl Operator {
    fn len(&self) -> usize {
        (self.nx + 2) * (self.ny + 2)
    }
    /// The scaled diagonal and its inverse, as the CPU's `set_scale` makes them (asked of the
    /// allocator: they are the grid's size).
    fn diagonal(&self, s: f64) -> Result<(Vec<f64>, Vec<f64>)> {
        let n = self.d0.len();
        let mut d = Vec::new();
        let mut inv = Vec::new();
        d.try_reserve_exact(n).and_then(|_| inv.try_reserve_exact(n)).map_err(|_| GpuError::OutOfMemory {
            what: "the fluid solver's diagonal (host)".into(),
            bytes: 16 * n as u64,
        })?;
        d.extend(self.d0.iter().zip(&self.count).map(|(d0, c)| d0 + s * c));
        inv.extend(d.iter().map(|d| 1.0 / d));
        Ok((d, inv))
    }
}

/// An inflow of smoke and velocity (the CPU's `fluid::Source`).
#[derive(Clone, Debug, PartialEq)]
pub struct Source {
    /// (cell i + nx·j, weight in [0, 1]), in the CPU's order.
    pub cells: Vec<(usize, f64)>,
    pub density: f64,
    pub temperature: f64,
    pub velocity: [f64; 2],
}

/// The fixed configuration of a fluid.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    pub nx: usize,
    pub ny: usize,
    /// Cell size, m.
    pub dx: f64,
    pub no_slip: bool,
    /// The top wall's speed (0 without a lid).
    pub lid: f64,
    /// The inflow face's u per row (empty: a closed box).
    pub inflow: Vec<f64>,
    pub buoyancy_alpha: f64,
    pub buoyancy_beta: f64,
    pub ambient_temperature: f64,
    pub vorticity: f64,
    pub maccormack: bool,
    /// The share of the last pressure applied before advection (0 Chorin, ½ incremental).
    pub share: f64,
    pub viscosity: f64,
    pub tolerance: f64,
    pub max_iterations: usize,
    /// 1/0 masks: open u faces ((nx+1)(ny+2)), open v faces ((nx+2)(ny+1)), fluid cells.
    pub u_open: Vec<f64>,
    pub v_open: Vec<f64>,
    /// With viscosity: the no-slip walls along each u and v face (0, 1 or 2; the core's
    /// `u_walls`, `v_walls`), in the layouts of `u_open` and `v_open`; empty without.
    pub u_walls: Vec<f64>,
    pub v_walls: Vec<f64>,
    pub fluid: Vec<f64>,
    /// The pressure operator and its coarse levels (scale 1).
    pub pressure: Vec<Operator>,
    /// The viscous operators of u and v (scaled by ν dt / dx² each step), with viscosity.
    pub viscous: Option<[Operator; 2]>,
    pub sources: Vec<Source>,
    /// Passive tracers (moved by RK2 through the velocity each step).
    pub n_tracers: usize,
    /// The cells where a tracer that leaves re-enters: the first source's, in its order (empty:
    /// any fluid cell).
    pub seeds: Vec<u32>,
}

/// Everything a step changes, as the CPU keeps it.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    pub u: Vec<f64>,
    pub v: Vec<f64>,
    pub density: Vec<f64>,
    pub temperature: Vec<f64>,
    /// Padded, (nx+2)(ny+2).
    pub pressure: Vec<f64>,
    /// Injected smoke, the smoke advection's change, then the stages' losses (forces, sources,
    /// advection, viscosity, projection).
    pub books: [f64; 7],
    /// x0, y0, x1, … (m).
    pub tracers: Vec<f64>,
    /// Steps taken (the tracers' re-seeding hashes it).
    pub steps: u64,
}

/// Which of the state's arrays a read brings back (the books and the step count always come).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Parts {
    /// u and v.
    pub velocity: bool,
    /// Density and temperature.
    pub smoke: bool,
    pub pressure: bool,
    pub tracers: bool,
}

impl Parts {
    pub const ALL: Parts = Parts { velocity: true, smoke: true, pressure: true, tracers: true };
    pub const NONE: Parts = Parts { velocity: false, smoke: false, pressure: false, tracers: false };
}

/// What the last solves did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Solves {
    pub pressure_iterations: usize,
    pub pressure_residual: f64,
    pub pressure_converged: bool,
    pub viscosity_iterations: usize,
}

/// Why `step` stopped early.
#[derive(Debug, Clone, PartialEq)]
pub enum Halt {
    Stopped,
    /// A value stopped being finite: the node of u (0), v (1), density (2) or temperature (3)
    /// by its index in that layout.
    Diverged {
        field: usize,
        index: usize,
    },
    Failed(GpuError),
}

// Slabs of U and V: the field, the advected one, MacCormack's first pass, the half-kicked one,
// the open mask, the no-slip walls along each face.
const F: u64 = 0;
const F2: u64 = 1;
const HAT: u64 = 2;
const KICK: u64 = 3;
const OPEN: u64 = 4;
const WALLS: u64 = 5;
// Slabs of C.
const DEN: u64 = 0;
const TEM: u64 = 1;
const DEN2: u64 = 2;
const TEM2: u64 = 3;
const DENH: u64 = 4;
const TEMH: u64 = 5;
const WZ: u64 = 6;
const FX: u64 = 7;
const FY: u64 = 8;
const FLUID: u64 = 9;
const INFLOW: u64 = 10;
// The ints buffer: solver s's ints at 16 s (s = 0 pressure, 1 viscous u, 2 viscous v), the
// finiteness flags at FLAGS; INTS in all. (The indirect counts have a buffer of their own.)
const FLAGS: u64 = 48;
/// The step counter (low, high).
const STEP: u64 = 52;
const INTS: u64 = 64;
// The scalars: the books (0..9), solver s's from 16 + 16 s.
const SOLVER_SC: u32 = 16;

const WG: u32 = 64;

/// One parameter block (the shaders' `Params`).
#[derive(Clone, Copy, Debug, Default)]
struct Block {
    ints: [u32; 16],
    reals: [f64; 8],
}

fn block(nx: usize, ny: usize) -> Block {
    let mut b = Block::default();
    b.ints[0] = nx as u32;
    b.ints[1] = ny as u32;
    b
}

// The ints' names in a block.
const LW: usize = 2;
const LNX: usize = 3;
const LNY: usize = 4;
const O: usize = 5;
const FLAGS_I: usize = 13;
const GX: usize = 14;
const ID: usize = 15;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Module {
    Fluid,
    /// The solvers' kernels over arrays (dispatched indirect).
    Vector,
    /// The solvers' one-workgroup kernels (and `zero_x`), which write the indirect counts.
    Control,
}

/// One dispatch: a pipeline, its block, and its workgroups (or, indirect, where their counts are
/// in the ints buffer).
#[derive(Clone, Copy, Debug)]
struct Go {
    module: Module,
    pipe: usize,
    block: u32,
    groups: Groups,
}

#[derive(Clone, Copy, Debug)]
enum Groups {
    Direct(u32, u32),
    Indirect(u64),
}

/// A stage of a step: dispatches, or a solve.
#[derive(Clone, Debug)]
enum Op {
    Go(Go),
    Solve { solver: usize, start: Vec<Go>, iteration: Vec<Go> },
}

// Pipelines by name, per module.
const FLUID_KERNELS: [&str; 20] = [
    "smoke",
    "faces_u",
    "faces_v",
    "inflow",
    "ghosts",
    "copy",
    "sources",
    "vorticity",
    "confine",
    "force_u",
    "force_v",
    "kick_u",
    "kick_v",
    "divergence",
    "pressure",
    "gradient_u",
    "gradient_v",
    "visc_u",
    "visc_v",
    "sums",
];
const BOOK: usize = 20;
const CHECK: usize = 21;
const TRACERS: usize = 22;
const COUNT_STEP: usize = 23;
const MAXIMA: usize = 24;
const FASTEST: usize = 25;
const VECTOR_KERNELS: [&str; 10] = [
    "apply",
    "residual",
    "norm",
    "jacobi",
    "restrict_residual",
    "prolong",
    "update",
    "diagonal",
    "direction",
    "coarsest",
];
/// Sweeps on the coarsest level (the CPU's `COARSE_SWEEPS`).
const COARSE_SWEEPS: u32 = 32;
/// The most unknowns of a coarsest level swept by one workgroup (`coarsest`); past it (a grid
/// far longer than wide), a dispatch per sweep.
const COARSE_MOST: usize = 4096;
const CONTROL_KERNELS: [&str; 8] = ["zero_x", "arm", "c_norm", "c_start", "c_rz", "c_alpha", "c_rr", "c_beta"];

fn fk(name: &str) -> usize {
    match name {
        "book" => BOOK,
        "check" => CHECK,
        "tracers" => TRACERS,
        "count_step" => COUNT_STEP,
        "maxima" => MAXIMA,
        "fastest" => FASTEST,
        _ => FLUID_KERNELS.iter().position(|k| *k == name).expect("a fluid kernel"),
    }
}

/// A solver kernel's module and pipeline.
fn pk(name: &str) -> (Module, usize) {
    match VECTOR_KERNELS.iter().position(|k| *k == name) {
        Some(i) => (Module::Vector, i),
        None => (Module::Control, CONTROL_KERNELS.iter().position(|k| *k == name).expect("a solver kernel")),
    }
}

/// Where a level of a solver lives in S.
#[derive(Clone, Copy, Debug)]
struct LevelAt {
    nx: usize,
    ny: usize,
    we: u64,
    wn: u64,
    diag: u64,
    inv: u64,
    x: u64,
    b: u64,
    tmp: u64,
}

/// A solver's arrays in S: its levels (level 0's x and b are the solve's unknown and
/// right-hand side) and the CG vectors.
#[derive(Clone, Debug)]
struct SolverAt {
    levels: Vec<LevelAt>,
    r: u64,
    z: u64,
    p: u64,
    ap: u64,
    /// Where its live indirect counts start in the ints buffer (3 per level) and their templates.
    live: u64,
    template: u64,
}

/// The planned step for one dt: its blocks and ops.
struct Plan {
    dt: f64,
    ops: Vec<Op>,
}

/// A fluid on one device.
pub struct Fluid {
    gpu: Arc<Gpu>,
    precision: Precision,
    /// Shared, so that a plan (made again at every change of dt) reads it without copying its
    /// grid-sized masks and stencils.
    model: Arc<Model>,
    lu: u64,
    lv: u64,
    cells: u64,
    np: u64,
    u_buf: wgpu::Buffer,
    v_buf: wgpu::Buffer,
    c_buf: wgpu::Buffer,
    s_buf: wgpu::Buffer,
    sc: wgpu::Buffer,
    ints: wgpu::Buffer,
    params: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// The indirect dispatches' counts.
    ind: wgpu::Buffer,
    fluid_bind: wgpu::BindGroup,
    vector_bind: wgpu::BindGroup,
    control_bind: wgpu::BindGroup,
    fluid_pipes: Vec<wgpu::ComputePipeline>,
    vector_pipes: Vec<wgpu::ComputePipeline>,
    control_pipes: Vec<wgpu::ComputePipeline>,
    slot: u64,
    blocks: Vec<Block>,
    /// Where the pressure lives in S and the solvers' arrays.
    pressure_at: u64,
    rhs_at: u64,
    solvers: Vec<SolverAt>,
    plan: Option<Plan>,
    /// Iterations of each solver's last solve (the next budget's start).
    last: [usize; 3],
    solves: Solves,
    /// Per source: its first group and its counts of cell, u-face and v-face groups.
    source_groups: Vec<(u32, [u32; 3])>,
    tr_buf: wgpu::Buffer,
    /// Kept alive with the bind groups: the partial sums, the sources' groups, the seeds.
    _keep: [wgpu::Buffer; 4],
    /// The checkpoint: copies of the state's regions (buffer, offset, copy), and the solves then.
    saved: Option<Vec<wgpu::Buffer>>,
    saved_solves: Solves,
}

/// A region of a slab for partial sums (`sums`, `maxima`): the buffer (0 U, 1 V, 2 C), the
/// slab's first element, its row length, nodes `cols` of rows `rows` (ranges).
#[derive(Clone, Copy, Debug)]
struct Region {
    buffer: u32,
    slab: u64,
    lw: usize,
    cols: (usize, usize),
    rows: (usize, usize),
}

impl Region {
    /// u's faces in the interior rows (the kinetic energy's and `auto_dt`'s).
    fn u(nx: usize, ny: usize) -> Self {
        Region { buffer: 0, slab: 0, lw: nx + 1, cols: (0, nx + 1), rows: (1, ny + 1) }
    }
    /// v's faces without its ghost columns (the kinetic energy's).
    fn v(nx: usize, ny: usize) -> Self {
        Region { buffer: 1, slab: 0, lw: nx + 2, cols: (1, nx + 1), rows: (0, ny + 1) }
    }
}

/// Workgroups along x and rows for a region `w` wide, `h` high.
fn groups(w: usize, h: usize) -> (u32, u32) {
    ((w as u32).div_ceil(WG), h as u32)
}

impl Fluid {
    /// Uploads the model and the state.
    ///
    /// Errors: `Unsupported` for f64 on an adapter without it, a grid over the dispatch limits
    /// or buffers over the adapter's; `OutOfMemory` naming the buffer.
    pub fn new(gpu: Arc<Gpu>, precision: Precision, model: Model, state: &State) -> Result<Self> {
        gpu.check_precision(precision)?;
        let (nx, ny) = (model.nx, model.ny);
        assert!(nx >= 3 && ny >= 3, "a grid of at least 3 × 3 cells");
        if nx + 3 > 65_535 * WG as usize || ny + 3 > 65_535 {
            return Err(GpuError::Unsupported(format!(
                "a fluid of {nx} × {ny} cells: the GPU path takes at most 4,194,000 cells along x and 65,532 along y"
            )));
        }
        let (lu, lv, cells, np) = (
            ((nx + 1) * (ny + 2)) as u64,
            ((nx + 2) * (ny + 1)) as u64,
            (nx * ny) as u64,
            ((nx + 2) * (ny + 2)) as u64,
        );
        assert_eq!(model.u_open.len() as u64, lu, "an open flag per u face");
        assert_eq!(model.v_open.len() as u64, lv, "an open flag per v face");
        assert_eq!(model.fluid.len() as u64, cells, "a fluid flag per cell");
        if model.viscous.is_some() {
            assert_eq!(model.u_walls.len() as u64, lu, "a wall count per u face");
            assert_eq!(model.v_walls.len() as u64, lv, "a wall count per v face");
        }
        assert!(!model.pressure.is_empty() && model.pressure[0].nx == nx && model.pressure[0].ny == ny);
        let rb = precision.bytes();
        use wgpu::BufferUsages as Us;
        let st = Us::STORAGE | Us::COPY_SRC | Us::COPY_DST;
        // The WALLS slab only with viscosity (an inviscid fluid's faces keep five).
        let slabs = WALLS + model.viscous.is_some() as u64;
        let u_buf = gpu.buffer("fluid u faces", slabs * lu * rb, st)?;
        let v_buf = gpu.buffer("fluid v faces", slabs * lv * rb, st)?;
        let c_buf = gpu.buffer("fluid cells", 11 * cells * rb, st)?;
        // S: the pressure, its right-hand side, then each solver's arrays.
        let mut at = 0u64;
        let mut take = |n: u64| {
            let a = at;
            at += n;
            a
        };
        let pressure_at = take(np);
        let rhs_at = take(np);
        let mut solvers = Vec::new();
        let mut ops_len = 0;
        let nsolvers = 1 + 2 * model.viscous.is_some() as usize;
        let total_levels: u64 = model.pressure.len() as u64 + 2 * model.viscous.is_some() as u64;
        let mut template_at = 3 * total_levels;
        for s in 0..nsolvers {
            let ops: Vec<&Operator> = if s == 0 {
                model.pressure.iter().collect()
            } else {
                vec![&model.viscous.as_ref().expect("viscous operators")[s - 1]]
            };
            let n0 = ops[0].len() as u64;
            let (r, z, p, ap) = (take(n0), take(n0), take(n0), take(n0));
            let mut levels = Vec::new();
            for (l, op) in ops.iter().enumerate() {
                let n = op.len() as u64;
                let (we, wn, diag, inv) = (take(n), take(n), take(n), take(n));
                let (x, b) = if l == 0 {
                    if s == 0 {
                        // The pressure solve's unknown q and right-hand side; the viscous ones below.
                        (u64::MAX, rhs_at)
                    } else {
                        (take(n), take(n))
                    }
                } else {
                    (take(n), take(n))
                };
                let tmp = if s == 0 { take(n) } else { 0 };
                levels.push(LevelAt { nx: op.nx, ny: op.ny, we, wn, diag, inv, x, b, tmp });
            }
            solvers.push(SolverAt { levels, r, z, p, ap, live: ops_len, template: template_at });
            ops_len += 3 * ops.len() as u64;
            template_at += 3 * ops.len() as u64;
        }
        // The pressure's unknown q.
        let q_at = take(np);
        solvers[0].levels[0].x = q_at;
        let s_len = at;
        let s_buf = gpu.buffer("fluid solver arrays", s_len * rb, st)?;
        let sc = gpu.buffer("fluid books and scalars", 64 * rb, st)?;
        let ints = gpu.buffer("fluid solver ints", INTS * 4, st)?;
        let ind = gpu.buffer("fluid indirect counts", template_at * 4, st | Us::INDIRECT)?;
        if s_len >= u32::MAX as u64 {
            return Err(GpuError::Unsupported(format!(
                "a fluid of {nx} × {ny} cells: its solver arrays pass 2^32 values"
            )));
        }
        // Partial sums: the widest region's workgroups, twice (the diagonal CG's second sums),
        // and a slot per cell of the largest source.
        let most_groups = ((nx as u64 + 3).div_ceil(WG as u64)) * (ny as u64 + 3);
        let most_source = model.sources.iter().map(|s| s.cells.len() as u64).max().unwrap_or(0);
        let part = gpu.buffer("fluid partial sums", (2 * most_groups + most_source + 64) * rb, st)?;
        // The sources' groups: per source, cells, then u faces, then v faces, each a location and
        // its weights in the CPU's order.
        let (mut ops_u, mut ops_w) = (Vec::<u32>::new(), Vec::<f64>::new());
        let mut source_groups = Vec::new();
        for s in &model.sources {
            let mut counts = [0u32; 3];
            let first = (ops_u.len() / 3) as u32;
            for (kind, count) in counts.iter_mut().enumerate() {
                let mut by_loc: Vec<(u64, Vec<f64>)> = Vec::new();
                let mut index = std::collections::HashMap::new();
                for &(c, w) in &s.cells {
                    if model.fluid[c] == 0.0 {
                        continue;
                    }
                    let (i, j) = ((c % nx) as u64, (c / nx) as u64);
                    let locs: Vec<u64> = match kind {
                        0 => vec![c as u64],
                        1 => vec![i + (nx as u64 + 1) * (j + 1), i + 1 + (nx as u64 + 1) * (j + 1)],
                        _ => vec![(i + 1) + (nx as u64 + 2) * j, (i + 1) + (nx as u64 + 2) * (j + 1)],
                    };
                    for loc in locs {
                        let k = *index.entry(loc).or_insert_with(|| {
                            by_loc.push((loc, Vec::new()));
                            by_loc.len() - 1
                        });
                        by_loc[k].1.push(w);
                    }
                }
                for (loc, ws) in by_loc {
                    ops_u.extend([loc as u32, ops_w.len() as u32, ws.len() as u32]);
                    ops_w.extend(ws);
                    *count += 1;
                }
            }
            source_groups.push((first, counts));
        }
        if ops_w.len() as u64 >= u32::MAX as u64 / 4 {
            return Err(GpuError::Unsupported("the sources' cells: at most 2^30 entries".into()));
        }
        assert!(model.seeds.iter().all(|&c| (c as u64) < cells), "seed cells inside the grid");
        let tr_buf = gpu.buffer("fluid tracers", (2 * model.n_tracers as u64).max(1) * rb, st)?;
        let seeds_buf = gpu.buffer("fluid tracers' seed cells", (model.seeds.len() as u64).max(1) * 4, st)?;
        gpu.queue.write_buffer(&seeds_buf, 0, bytemuck::cast_slice(&model.seeds));
        let ops_buf = gpu.buffer("fluid source groups", (ops_u.len() as u64).max(4) * 4, st)?;
        let opw_buf = gpu.buffer("fluid source weights", (ops_w.len() as u64).max(1) * rb, st)?;
        gpu.queue.write_buffer(&ops_buf, 0, bytemuck::cast_slice(&ops_u));
        if !ops_w.is_empty() {
            gpu.upload(precision, &opw_buf, &ops_w);
        }
        let align = gpu.device.limits().min_uniform_buffer_offset_alignment as u64;
        let slot = (16 * 4 + 8 * rb).div_ceil(align) * align;
        // Blocks: bounded by the plan (below); 4096 is far more than a plan of 16 levels uses.
        let params = gpu.buffer("fluid parameters", 4096 * slot, Us::UNIFORM | Us::COPY_DST)?;
        let staging = gpu.buffer(
            "fluid read-back staging",
            (2 * lu.max(lv).max(np) * rb).max(INTS * 4).max(64 * rb),
            Us::MAP_READ | Us::COPY_DST,
        )?;
        let header = format!(
            "{}\nconst TINY: real = {};\n",
            include_str!("fluid_common.wgsl"),
            if precision == Precision::F64 { "1e-300" } else { "1e-30" }
        );
        use crate::Bind::{Read as R, ReadWrite as W, Uniform};
        let (fl, fluid_pipes) = gpu.kernels(
            "fluid.wgsl",
            precision,
            &format!("{header}{}", include_str!("fluid.wgsl")),
            &[Uniform { dynamic: true }, W, W, W, W, W, W, R, R, W, W, R],
            &[FLUID_KERNELS.as_slice(), &["book", "check", "tracers", "count_step", "maxima", "fastest"]].concat(),
        );
        let poisson = format!("{header}{}", include_str!("poisson.wgsl"));
        let (vl, vector_pipes) =
            gpu.kernels("poisson.wgsl", precision, &poisson, &[Uniform { dynamic: true }, W, W, W], &VECTOR_KERNELS);
        let (cl, control_pipes) = gpu.kernels(
            "poisson.wgsl",
            precision,
            &poisson,
            &[Uniform { dynamic: true }, W, W, W, W, W],
            &CONTROL_KERNELS,
        );
        let block = 16 * 4 + 8 * rb;
        let bind = |layout: &wgpu::BindGroupLayout, bufs: &[&wgpu::Buffer], label: &str| {
            gpu.bind_with_params(label, layout, bufs, block)
        };
        let fluid_bind = bind(
            &fl,
            &[&params, &sc, &part, &u_buf, &v_buf, &c_buf, &s_buf, &ops_buf, &opw_buf, &ints, &tr_buf, &seeds_buf],
            "fluid",
        );
        let vector_bind = bind(&vl, &[&params, &sc, &part, &s_buf], "fluid solves");
        let control_bind = bind(&cl, &[&params, &sc, &part, &s_buf, &ints, &ind], "fluid solves' control");
        // Fixed arrays: masks, the inflow column, the solvers' coefficients, the indirect templates.
        gpu.upload_at(precision, &u_buf, OPEN * lu * rb, &model.u_open);
        gpu.upload_at(precision, &v_buf, OPEN * lv * rb, &model.v_open);
        if model.viscous.is_some() {
            gpu.upload_at(precision, &u_buf, WALLS * lu * rb, &model.u_walls);
            gpu.upload_at(precision, &v_buf, WALLS * lv * rb, &model.v_walls);
        }
        gpu.upload_at(precision, &c_buf, FLUID * cells * rb, &model.fluid);
        if !model.inflow.is_empty() {
            gpu.upload_at(precision, &c_buf, INFLOW * cells * rb, &model.inflow);
        }
        let mut ints_init = vec![0u32; INTS as usize];
        for f in 0..4 {
            ints_init[FLAGS as usize + f] = u32::MAX;
        }
        gpu.queue.write_buffer(&ints, 0, bytemuck::cast_slice(&ints_init));
        let mut ind_init = vec![0u32; template_at as usize];
        for s in &solvers {
            for (l, lv) in s.levels.iter().enumerate() {
                let (gx, gy) = groups(lv.nx, lv.ny);
                let t = s.template as usize + 3 * l;
                ind_init[t..t + 3].copy_from_slice(&[gx, gy, 1]);
            }
        }
        gpu.queue.write_buffer(&ind, 0, bytemuck::cast_slice(&ind_init));
        for (l, op) in model.pressure.iter().enumerate() {
            let a = solvers[0].levels[l];
            let (d, inv) = op.diagonal(1.0)?;
            for (off, data) in [(a.we, &op.we), (a.wn, &op.wn), (a.diag, &d), (a.inv, &inv)] {
                gpu.upload_at(precision, &s_buf, off * rb, data);
            }
        }
        if let Some(vis) = &model.viscous {
            for (k, op) in vis.iter().enumerate() {
                let a = solvers[k + 1].levels[0];
                gpu.upload_at(precision, &s_buf, a.we * rb, &op.we);
                gpu.upload_at(precision, &s_buf, a.wn * rb, &op.wn);
            }
        }
        let mut f = Self {
            gpu,
            precision,
            model: Arc::new(model),
            lu,
            lv,
            cells,
            np,
            u_buf,
            v_buf,
            c_buf,
            s_buf,
            sc,
            ints,
            params,
            staging,
            ind,
            fluid_bind,
            vector_bind,
            control_bind,
            fluid_pipes,
            vector_pipes,
            control_pipes,
            slot,
            blocks: Vec::new(),
            pressure_at,
            rhs_at,
            solvers,
            plan: None,
            last: [0; 3],
            solves: Solves::default(),
            source_groups,
            tr_buf,
            _keep: [part, ops_buf, opw_buf, seeds_buf],
            saved: None,
            saved_solves: Solves::default(),
        };
        f.set_state(state)?;
        Ok(f)
    }
}

impl Fluid {
    pub fn precision(&self) -> Precision {
        self.precision
    }
    pub fn model(&self) -> &Model {
        &self.model
    }
    /// The last solves (the pressure's residual as of the last `read_state`).
    pub fn solves(&self) -> Solves {
        self.solves
    }

    fn rb(&self) -> u64 {
        self.precision.bytes()
    }

    /// Replaces the state and the books (the finiteness flags cleared).
    pub fn set_state(&mut self, s: &State) -> Result<()> {
        let (p, rb) = (self.precision, self.rb());
        assert!(s.u.len() as u64 == self.lu && s.v.len() as u64 == self.lv, "u and v in their layouts");
        assert!(s.density.len() as u64 == self.cells && s.temperature.len() as u64 == self.cells);
        assert!(s.pressure.len() as u64 == self.np, "a padded pressure");
        assert!(s.tracers.len() == 2 * self.model.n_tracers, "two coordinates per tracer");
        let g = &self.gpu;
        g.upload_at(p, &self.u_buf, 0, &s.u);
        g.upload_at(p, &self.v_buf, 0, &s.v);
        g.upload_at(p, &self.c_buf, DEN * self.cells * rb, &s.density);
        g.upload_at(p, &self.c_buf, TEM * self.cells * rb, &s.temperature);
        g.upload_at(p, &self.s_buf, self.pressure_at * rb, &s.pressure);
        let b = &s.books;
        g.upload_at(p, &self.sc, 0, &[b[2], b[3], b[4], b[5], b[6], b[0], b[1]]);
        if !s.tracers.is_empty() {
            g.upload_at(p, &self.tr_buf, 0, &s.tracers);
        }
        let steps = [s.steps as u32, (s.steps >> 32) as u32];
        g.queue.write_buffer(&self.ints, STEP * 4, bytemuck::cast_slice(&steps));
        self.clear_flags();
        g.wait()
    }

    fn clear_flags(&self) {
        self.gpu.queue.write_buffer(&self.ints, FLAGS * 4, bytemuck::cast_slice(&[u32::MAX; 4]));
    }

    /// `count` reals from element `at` of `b`.
    fn read(&self, b: &wgpu::Buffer, at: u64, count: u64) -> Result<Vec<f64>> {
        self.gpu.read_reals_at(self.precision, b, at * self.rb(), &self.staging, count as usize)
    }

    /// The state and books read back (and the last pressure solve's residual kept).
    pub fn read_state(&mut self) -> Result<State> {
        self.read_parts(Parts::ALL)
    }

    /// The books, the step count and the arrays of `parts` read back (the others empty).
    pub fn read_parts(&mut self, parts: Parts) -> Result<State> {
        let sc = self.read(&self.sc, 0, 32)?;
        self.solves.pressure_residual = sc[SOLVER_SC as usize + 6];
        let get = |on: bool, b: &wgpu::Buffer, at: u64, n: u64| if on { self.read(b, at, n) } else { Ok(Vec::new()) };
        Ok(State {
            u: get(parts.velocity, &self.u_buf, 0, self.lu)?,
            v: get(parts.velocity, &self.v_buf, 0, self.lv)?,
            density: get(parts.smoke, &self.c_buf, DEN * self.cells, self.cells)?,
            temperature: get(parts.smoke, &self.c_buf, TEM * self.cells, self.cells)?,
            pressure: get(parts.pressure, &self.s_buf, self.pressure_at, self.np)?,
            books: [sc[5], sc[6], sc[0], sc[1], sc[2], sc[3], sc[4]],
            tracers: get(parts.tracers && self.model.n_tracers > 0, &self.tr_buf, 0, 2 * self.model.n_tracers as u64)?,
            steps: {
                let st = self.status()?;
                st[STEP as usize] as u64 | (st[STEP as usize + 1] as u64) << 32
            },
        })
    }

    /// The regions a checkpoint copies: (buffer, first byte, bytes).
    fn regions(&self) -> [(&wgpu::Buffer, u64, u64); 7] {
        let rb = self.rb();
        [
            (&self.u_buf, 0, self.lu * rb),
            (&self.v_buf, 0, self.lv * rb),
            (&self.c_buf, 0, 2 * self.cells * rb),
            (&self.s_buf, self.pressure_at * rb, self.np * rb),
            (&self.sc, 0, 64 * rb),
            (&self.tr_buf, 0, self.tr_buf.size()),
            (&self.ints, STEP * 4, 8),
        ]
    }

    /// Keeps a copy of the state and books on the device (the world's checkpoint).
    pub fn snapshot(&mut self) -> Result<()> {
        if self.saved.is_none() {
            use wgpu::BufferUsages as Us;
            let mut v = Vec::new();
            for (_, _, n) in self.regions() {
                v.push(self.gpu.buffer("fluid checkpoint", n, Us::STORAGE | Us::COPY_SRC | Us::COPY_DST)?);
            }
            self.saved = Some(v);
        }
        let saved = self.saved.as_ref().expect("made above");
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        for ((b, at, n), s) in self.regions().into_iter().zip(saved) {
            enc.copy_buffer_to_buffer(b, at, s, 0, n);
        }
        self.gpu.queue.submit([enc.finish()]);
        self.saved_solves = self.solves;
        Ok(())
    }

    /// Returns to the last snapshot (nothing happens without one); the flags cleared.
    pub fn restore(&mut self) -> Result<()> {
        if let Some(saved) = &self.saved {
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            for ((b, at, n), s) in self.regions().into_iter().zip(saved) {
                enc.copy_buffer_to_buffer(s, 0, b, at, n);
            }
            self.gpu.queue.submit([enc.finish()]);
            self.solves = self.saved_solves;
        }
        self.clear_flags();
        self.gpu.wait()
    }

    /// The largest |u| over the faces of the interior rows and |v| over all v faces (the
    /// CPU's `auto_dt`), reduced on the device: one value read back. Uses the parameter
    /// blocks past the step's (the plan is kept).
    pub fn fastest(&mut self) -> Result<f64> {
        let (nx, ny) = (self.model.nx, self.model.ny);
        let keep = self.blocks.len();
        let (gu, cu) = self.sums(Region::u(nx, ny), false, 0);
        let (gv, cv) = self.sums(Region { cols: (0, nx + 2), ..Region::v(nx, ny) }, false, cu);
        let mut b = block(nx, ny);
        b.ints[O] = 0;
        b.ints[O + 1] = cu + cv;
        let f = self.go(FASTEST, b, (1, 1));
        for (k, b) in self.blocks.iter().enumerate().skip(keep) {
            self.gpu.write_params_at(self.precision, &self.params, k as u64 * self.slot, &b.ints, &b.reals);
        }
        let gos = [Go { pipe: MAXIMA, ..gu }, Go { pipe: MAXIMA, ..gv }, f];
        self.blocks.truncate(keep);
        self.submit(&gos.iter().collect::<Vec<_>>());
        Ok(self.read(&self.sc, 9, 1)?[0])
    }

    // ---- the plan of a step

    fn push(&mut self, b: Block) -> u32 {
        self.blocks.push(b);
        (self.blocks.len() - 1) as u32
    }

    fn go(&mut self, pipe: usize, b: Block, (x, y): (u32, u32)) -> Go {
        Go { module: Module::Fluid, pipe, block: self.push(b), groups: Groups::Direct(x, y) }
    }

    /// A fluid block with the advection's reals (dt, dx, 1/dx, ambient, extent).
    fn adv_block(&self, dt: f64) -> Block {
        let m = &self.model;
        let mut b = block(m.nx, m.ny);
        b.reals[..6].copy_from_slice(&[
            dt,
            m.dx,
            1.0 / m.dx,
            m.ambient_temperature,
            m.nx as u32 as f64 * m.dx,
            m.ny as u32 as f64 * m.dx,
        ]);
        b
    }

    /// Ghost fills of the u slab `us` and v slab `vs` (either may be None); with an inflow, its
    /// column first.
    fn ghosts(&mut self, us: Option<u64>, vs: Option<u64>) -> Vec<Go> {
        let m = &self.model;
        let (nx, ny) = (m.nx, m.ny);
        let mut b = block(nx, ny);
        b.ints[O] = us.map_or(0, |s| (s * self.lu) as u32);
        b.ints[O + 1] = vs.map_or(0, |s| (s * self.lv) as u32);
        b.ints[O + 2] = (INFLOW * self.cells) as u32;
        b.ints[FLAGS_I] = us.is_some() as u32
            | (vs.is_some() as u32) << 1
            | (m.no_slip as u32) << 2
            | (!m.inflow.is_empty() as u32) << 3;
        b.reals[0] = m.lid;
        let mut out = Vec::new();
        if us.is_some() && !m.inflow.is_empty() {
            out.push(self.go(fk("inflow"), b, groups(ny, 1)));
        }
        out.push(self.go(fk("ghosts"), b, groups(nx.max(ny) + 1, 1)));
        out
    }

    /// The partial sums of region `r` (of squares if `squared`) into part[at ..]: the dispatch
    /// and the count.
    fn sums(&mut self, r: Region, squared: bool, at: u32) -> (Go, u32) {
        let Region { buffer, slab, lw, cols, rows } = r;
        let m = &self.model;
        let mut b = block(m.nx, m.ny);
        let (gx, gy) = groups(cols.1 - cols.0, rows.1 - rows.0);
        b.ints[LW] = lw as u32;
        b.ints[LNY] = (rows.1 - rows.0) as u32;
        b.ints[O..O + 5].copy_from_slice(&[slab as u32, cols.0 as u32, cols.1 as u32, rows.0 as u32, at]);
        b.ints[FLAGS_I] = buffer | (squared as u32) << 2;
        b.ints[GX] = gx;
        (self.go(fk("sums"), b, (gx, gy)), gx * gy)
    }

    /// The kinetic energy's sums and the book `mode` (0: the start; 1: stage `id`'s loss).
    fn energy(&mut self, mode: u32, id: u32) -> Vec<Go> {
        let (nx, ny) = (self.model.nx, self.model.ny);
        let (gu, cu) = self.sums(Region::u(nx, ny), true, 0);
        let (gv, cv) = self.sums(Region::v(nx, ny), true, cu);
        let mut b = block(nx, ny);
        b.ints[O..O + 4].copy_from_slice(&[0, cu, cu, cv]);
        b.ints[FLAGS_I] = mode;
        b.ints[ID] = id;
        b.reals[1] = self.model.dx;
        vec![gu, gv, self.go(BOOK, b, (1, 1))]
    }

    /// The smoke's amount and book `mode` (2 before advection, 3 after).
    fn smoke_amount(&mut self, mode: u32) -> Vec<Go> {
        let (nx, ny) = (self.model.nx, self.model.ny);
        let cells = Region { buffer: 2, slab: DEN * self.cells, lw: nx, cols: (0, nx), rows: (0, ny) };
        let (g, c) = self.sums(cells, false, 0);
        let mut b = block(nx, ny);
        b.ints[O..O + 4].copy_from_slice(&[0, c, 0, 0]);
        b.ints[FLAGS_I] = mode;
        b.reals[1] = self.model.dx;
        vec![g, self.go(BOOK, b, (1, 1))]
    }

    /// A copy of `w` × `h` values from slab `from` to slab `to` of buffer `which` (slab size `len`).
    fn copy(&mut self, which: u32, len: u64, from: u64, to: u64, w: usize, h: usize) -> Go {
        let mut b = block(self.model.nx, self.model.ny);
        b.ints[LW] = w as u32;
        b.ints[LNX] = w as u32;
        b.ints[LNY] = h as u32;
        b.ints[O] = (from * len) as u32;
        b.ints[O + 1] = (to * len) as u32;
        b.ints[FLAGS_I] = which;
        self.go(fk("copy"), b, groups(w, h))
    }

    /// A solver block for level `l` of solver `s`: its shape and coefficients.
    fn level_block(&self, s: usize, l: usize) -> Block {
        let a = self.solvers[s].levels[l];
        let mut b = block(a.nx, a.ny);
        b.ints[LW] = (a.nx + 2) as u32;
        b.ints[LNX] = a.nx as u32;
        b.ints[LNY] = a.ny as u32;
        b.ints[O..O + 4].copy_from_slice(&[a.we as u32, a.wn as u32, a.diag as u32, a.inv as u32]);
        b.ints[GX] = groups(a.nx, a.ny).0;
        b.ints[ID] = s as u32;
        b
    }

    fn poisson(&mut self, pipe: &str, b: Block, groups: Groups) -> Go {
        let (module, pipe) = pk(pipe);
        Go { module, pipe, block: self.push(b), groups }
    }

    fn indirect(&self, s: usize, l: usize) -> Groups {
        Groups::Indirect(self.solvers[s].live + 3 * l as u64)
    }

    /// A control kernel's block: solver s's scalars and indirect counts, `count` partials from
    /// `from`.
    fn control(&mut self, s: usize, pipe: &str, count: u32, from: u32) -> Go {
        let m = &self.model;
        let mut b = block(m.nx, m.ny);
        let sv = &self.solvers[s];
        b.ints[ID] = s as u32;
        b.ints[O] = SOLVER_SC + 16 * s as u32;
        b.ints[O + 1] = sv.live as u32;
        b.ints[O + 2] = 3 * sv.levels.len() as u32;
        b.ints[O + 3] = sv.template as u32;
        b.ints[LW] = count;
        b.ints[LNX] = from;
        self.poisson(pipe, b, Groups::Direct(1, 1))
    }

    /// A damped-Jacobi sweep at level l of the pressure's V-cycle from `x` into `out` (from
    /// zero if `zero`), its partial sums with b kept if `book`.
    fn sweep(&mut self, l: usize, x: u64, out: u64, zero: bool, book: bool) -> Go {
        let mut b = self.level_block(0, l);
        let a = self.cycle_level(l);
        b.ints[O + 4] = x as u32;
        b.ints[O + 5] = a.b as u32;
        b.ints[O + 6] = out as u32;
        b.ints[FLAGS_I] = zero as u32 | (book as u32) << 1;
        b.reals[0] = 1.0;
        let g = self.indirect(0, l);
        self.poisson("jacobi", b, g)
    }

    /// Level l of the pressure's V-cycle: level 0's x and b are the CG's z and r.
    fn cycle_level(&self, l: usize) -> LevelAt {
        let sv = &self.solvers[0];
        let mut a = sv.levels[l];
        if l == 0 {
            (a.x, a.b) = (sv.z, sv.r);
        }
        a
    }

    /// One V-cycle from level l down (x = 0 at the start; b at each level's b), its last sweep
    /// at level 0 booking z·r.
    fn vcycle(&mut self, l: usize, out: &mut Vec<Go>) {
        let levels: Vec<LevelAt> = (0..self.solvers[0].levels.len()).map(|k| self.cycle_level(k)).collect();
        let a = levels[l];
        let book = l == 0;
        if l + 1 == levels.len() && l > 0 && a.nx * a.ny <= COARSE_MOST {
            let mut b = self.level_block(0, l);
            b.ints[O + 4] = a.x as u32;
            b.ints[O + 5] = a.b as u32;
            b.ints[O + 6] = a.tmp as u32;
            b.ints[ID] = COARSE_SWEEPS;
            b.reals[0] = 1.0;
            // Direct: one workgroup, which reads nothing the stopping test has emptied (a done
            // solve's V-cycles still run this one dispatch, a few thousand values).
            let g = self.poisson("coarsest", b, Groups::Direct(1, 1));
            out.push(g);
            return;
        }
        if l + 1 == levels.len() {
            for k in 0..COARSE_SWEEPS {
                let (from, to) = if k % 2 == 0 { (a.x, a.tmp) } else { (a.tmp, a.x) };
                let g = self.sweep(l, from, to, k == 0, book && k == COARSE_SWEEPS - 1);
                out.push(g);
            }
            return;
        }
        let g = self.sweep(l, a.x, a.tmp, true, false);
        out.push(g);
        let g = self.sweep(l, a.tmp, a.x, false, false);
        out.push(g);
        let c = levels[l + 1];
        let mut b = self.level_block(0, l);
        b.ints[O + 4] = a.x as u32;
        b.ints[O + 5] = a.b as u32;
        b.ints[O + 6] = c.b as u32;
        b.ints[O + 7] = (c.nx + 2) as u32;
        b.ints[ID] = c.nx as u32 | (c.ny as u32) << 16;
        b.reals[0] = 1.0;
        let g = self.indirect(0, l + 1);
        let r = self.poisson("restrict_residual", b, g);
        out.push(r);
        self.vcycle(l + 1, out);
        let mut b = self.level_block(0, l);
        b.ints[O + 4] = a.x as u32;
        b.ints[O + 6] = c.x as u32;
        b.ints[O + 7] = (c.nx + 2) as u32;
        let g = self.indirect(0, l);
        let p = self.poisson("prolong", b, g);
        out.push(p);
        let g = self.sweep(l, a.x, a.tmp, false, false);
        out.push(g);
        let g = self.sweep(l, a.tmp, a.x, false, book);
        out.push(g);
    }

    /// z = M⁻¹ r and its partial sums of z·r (region 0).
    fn precondition(&mut self, s: usize, scale: f64, out: &mut Vec<Go>) {
        if s == 0 {
            self.vcycle(0, out);
        } else {
            let sv = self.solvers[s].clone();
            let mut b = self.level_block(s, 0);
            b.ints[O + 3] = sv.r as u32;
            b.ints[O + 5] = sv.z as u32;
            b.ints[O + 6] = sv.levels[0].inv as u32;
            b.reals[0] = scale;
            let g = self.indirect(s, 0);
            let d = self.poisson("diagonal", b, g);
            out.push(d);
        }
    }

    /// The ops of solve s at `scale`: its start and one iteration (the CPU's `Pcg::solve`).
    fn solve(&mut self, s: usize, scale: f64) -> Op {
        let sv = self.solvers[s].clone();
        let l0 = sv.levels[0];
        let count = {
            let (gx, gy) = groups(l0.nx, l0.ny);
            gx * gy
        };
        let tol = self.model.tolerance;
        let max = self.model.max_iterations.min(u32::MAX as usize) as u32;
        let mut start = Vec::new();
        let arm = self.control(s, "arm", 0, 0);
        let b = &mut self.blocks[arm.block as usize];
        b.ints[LNX] = max;
        b.reals[7] = tol;
        start.push(arm);
        let lb = |me: &Self| {
            let mut b = me.level_block(s, 0);
            b.reals[0] = scale;
            b
        };
        let g0 = self.indirect(s, 0);
        let mut b = lb(self);
        b.ints[O + 5] = l0.b as u32;
        start.push(self.poisson("norm", b, g0));
        start.push(self.control(s, "c_norm", count, 0));
        let mut b = lb(self);
        b.ints[O + 1] = l0.x as u32;
        start.push(self.poisson("zero_x", b, Groups::Direct(groups(l0.nx, l0.ny).0, l0.ny as u32)));
        let mut b = lb(self);
        b.ints[O + 4] = l0.x as u32;
        b.ints[O + 5] = l0.b as u32;
        b.ints[O + 6] = sv.r as u32;
        start.push(self.poisson("residual", b, g0));
        start.push(self.control(s, "c_start", count, 0));
        self.precondition(s, scale, &mut start);
        start.push(self.control(s, "c_rz", count, 0));
        let mut b = lb(self);
        b.ints[O] = SOLVER_SC + 16 * s as u32 + 4;
        b.ints[O + 2] = sv.p as u32;
        b.ints[O + 5] = sv.z as u32;
        b.ints[FLAGS_I] = 1;
        start.push(self.poisson("direction", b, g0));
        let mut it = Vec::new();
        let mut b = lb(self);
        b.ints[O + 4] = sv.p as u32;
        b.ints[O + 6] = sv.ap as u32;
        it.push(self.poisson("apply", b, g0));
        it.push(self.control(s, "c_alpha", count, 0));
        let mut b = lb(self);
        let diag = s != 0;
        b.ints[O..O + 8].copy_from_slice(&[
            SOLVER_SC + 16 * s as u32 + 3,
            l0.x as u32,
            sv.p as u32,
            sv.r as u32,
            sv.ap as u32,
            sv.z as u32,
            l0.inv as u32,
            count,
        ]);
        b.ints[FLAGS_I] = diag as u32;
        it.push(self.poisson("update", b, g0));
        it.push(self.control(s, "c_rr", count, 0));
        if diag {
            it.push(self.control(s, "c_beta", count, count));
        } else {
            self.precondition(s, scale, &mut it);
            it.push(self.control(s, "c_beta", count, 0));
        }
        let mut b = lb(self);
        b.ints[O] = SOLVER_SC + 16 * s as u32 + 4;
        b.ints[O + 2] = sv.p as u32;
        b.ints[O + 5] = sv.z as u32;
        it.push(self.poisson("direction", b, g0));
        Op::Solve { solver: s, start, iteration: it }
    }

    /// The ops of a step of `dt` (the CPU's `System::step` for a fluid, stage for stage), its
    /// blocks written to the device.
    fn make_plan(&mut self, dt: f64) -> Result<()> {
        self.blocks.clear();
        let m = self.model.clone();
        let (nx, ny, dx) = (m.nx, m.ny, m.dx);
        let (lu, lv, cells) = (self.lu, self.lv, self.cells);
        let mut ops: Vec<Op> = Vec::new();
        let add = |ops: &mut Vec<Op>, gs: Vec<Go>| ops.extend(gs.into_iter().map(Op::Go));
        // The ghosts, then the kinetic energy at the start.
        let g = self.ghosts(Some(F), Some(F));
        add(&mut ops, g);
        let g = self.energy(0, 0);
        add(&mut ops, g);
        // 1. The smoke, advected (its change booked).
        let g = self.smoke_amount(2);
        add(&mut ops, g);
        let mut b = self.adv_block(dt);
        b.ints[O + 6] = (FLUID * cells) as u32;
        let slab = |k: u64| (k * cells) as u32;
        let cg = groups(nx, ny);
        if m.maccormack {
            let mut first = b;
            first.ints[O..O + 6].copy_from_slice(&[slab(DEN), slab(TEM), 0, 0, slab(DENH), slab(TEMH)]);
            let g = self.go(fk("smoke"), first, cg);
            ops.push(Op::Go(g));
            b.ints[O..O + 6].copy_from_slice(&[slab(DEN), slab(TEM), slab(DENH), slab(TEMH), slab(DEN2), slab(TEM2)]);
            b.ints[FLAGS_I] = 1;
        } else {
            b.ints[O..O + 6].copy_from_slice(&[slab(DEN), slab(TEM), 0, 0, slab(DEN2), slab(TEM2)]);
        }
        let g = self.go(fk("smoke"), b, cg);
        ops.push(Op::Go(g));
        let g = self.copy(2, cells, DEN2, DEN, nx, ny);
        ops.push(Op::Go(g));
        let g = self.copy(2, cells, TEM2, TEM, nx, ny);
        ops.push(Op::Go(g));
        let g = self.smoke_amount(3);
        add(&mut ops, g);
        // 2. Sources.
        if !m.sources.is_empty() {
            for (k, src) in m.sources.iter().enumerate() {
                let (first, counts) = self.source_groups[k];
                let mut b = block(nx, ny);
                b.ints[O..O + 8].copy_from_slice(&[
                    first,
                    counts[0],
                    first + counts[0],
                    counts[1],
                    first + counts[0] + counts[1],
                    counts[2],
                    slab(DEN),
                    slab(TEM),
                ]);
                b.reals[..5].copy_from_slice(&[
                    src.density,
                    src.temperature,
                    src.velocity[0],
                    src.velocity[1],
                    dx * dx,
                ]);
                let n = counts.iter().sum::<u32>();
                let wgs = n.div_ceil(WG);
                let g = self.go(fk("sources"), b, (wgs.min(65_535), wgs.div_ceil(65_535)));
                ops.push(Op::Go(g));
                let mut bk = block(nx, ny);
                bk.ints[O..O + 4].copy_from_slice(&[0, counts[0], 0, 0]);
                bk.ints[FLAGS_I] = 4;
                let g = self.go(BOOK, bk, (1, 1));
                ops.push(Op::Go(g));
            }
            let g = self.energy(1, 1);
            add(&mut ops, g);
        }
        // 3. Forces.
        let confine = m.vorticity > 0.0;
        let buoyant = m.buoyancy_alpha != 0.0 || m.buoyancy_beta != 0.0;
        if confine || buoyant {
            let mut b = block(nx, ny);
            b.ints[O..O + 7].copy_from_slice(&[
                slab(WZ),
                slab(FX),
                slab(FY),
                slab(DEN),
                slab(TEM),
                (OPEN * lu) as u32,
                (OPEN * lv) as u32,
            ]);
            b.ints[FLAGS_I] = confine as u32;
            b.reals[..6].copy_from_slice(&[
                dt,
                dx,
                m.vorticity,
                m.buoyancy_alpha,
                m.buoyancy_beta,
                m.ambient_temperature,
            ]);
            if confine {
                for (name, shape) in [("vorticity", cg), ("confine", cg), ("force_u", groups(nx - 1, ny))] {
                    let g = self.go(fk(name), b, shape);
                    ops.push(Op::Go(g));
                }
            }
            let g = self.go(fk("force_v"), b, groups(nx, ny - 1));
            ops.push(Op::Go(g));
            let g = self.energy(1, 0);
            add(&mut ops, g);
        }
        // 4. The velocity, advected (the half kick first with the incremental projection).
        let src = if m.share > 0.0 {
            let mut b = block(nx, ny);
            b.ints[O..O + 7].copy_from_slice(&[
                self.pressure_at as u32,
                (KICK * lu) as u32,
                (KICK * lv) as u32,
                0,
                0,
                (OPEN * lu) as u32,
                (OPEN * lv) as u32,
            ]);
            b.reals[0] = m.share * dt / dx;
            let g = self.go(fk("kick_u"), b, groups(nx + 1, ny + 2));
            ops.push(Op::Go(g));
            let g = self.go(fk("kick_v"), b, groups(nx + 2, ny + 1));
            ops.push(Op::Go(g));
            let g = self.ghosts(Some(KICK), Some(KICK));
            add(&mut ops, g);
            KICK
        } else {
            F
        };
        for (kind, len, region) in [(0u32, lu, (0, nx + 1, 1, ny + 1)), (1, lv, (1, nx + 1, 0, ny + 1))] {
            let pipe = fk(if kind == 0 { "faces_u" } else { "faces_v" });
            let mut b = self.adv_block(dt);
            let shape = groups(region.1 - region.0, region.3 - region.2);
            b.ints[O..O + 8].copy_from_slice(&[
                (src * len) as u32,
                (HAT * len) as u32,
                (F2 * len) as u32,
                (OPEN * len) as u32,
                region.0 as u32,
                region.1 as u32,
                region.2 as u32,
                region.3 as u32,
            ]);
            if m.maccormack {
                let mut first = b;
                first.ints[O + 2] = (HAT * len) as u32;
                let g = self.go(pipe, first, shape);
                ops.push(Op::Go(g));
                let g = if kind == 0 { self.ghosts(Some(HAT), None) } else { self.ghosts(None, Some(HAT)) };
                add(&mut ops, g);
                b.ints[FLAGS_I] = 1;
            }
            let g = self.go(pipe, b, shape);
            ops.push(Op::Go(g));
        }
        let g = self.copy(0, lu, F2, F, nx + 1, ny + 2);
        ops.push(Op::Go(g));
        let g = self.copy(1, lv, F2, F, nx + 2, ny + 1);
        ops.push(Op::Go(g));
        let g = self.ghosts(Some(F), Some(F));
        add(&mut ops, g);
        let g = self.energy(1, 2);
        add(&mut ops, g);
        // 5. Viscosity (backward Euler, per component).
        if let Some(vis) = &m.viscous {
            let s = m.viscosity * dt / (dx * dx);
            let rb = self.rb();
            for (k, op) in vis.iter().enumerate() {
                let a = self.solvers[k + 1].levels[0];
                let (d, inv) = op.diagonal(s)?;
                self.gpu.upload_at(self.precision, &self.s_buf, a.diag * rb, &d);
                self.gpu.upload_at(self.precision, &self.s_buf, a.inv * rb, &inv);
            }
            let lid_term = if m.no_slip { 2.0 * s * m.lid } else { 0.0 };
            // The walls' slip term per wall and unit pressure difference (the core's `slip_scale`).
            let slip = 2.0 * s * (1.0 - m.share) * dt / dx;
            for k in 0..2 {
                let a = self.solvers[k + 1].levels[0];
                let mut b = block(nx, ny);
                let walls = if k == 0 { WALLS * lu } else { WALLS * lv };
                b.ints[O..O + 7].copy_from_slice(&[
                    a.x as u32,
                    a.b as u32,
                    self.pressure_at as u32,
                    0,
                    0,
                    (OPEN * lu) as u32,
                    walls as u32,
                ]);
                b.reals[..3].copy_from_slice(&[s, lid_term, slip]);
                b.ints[FLAGS_I] = !m.inflow.is_empty() as u32;
                let (name, shape) =
                    if k == 0 { ("visc_u", groups(nx + 1, ny)) } else { ("visc_v", groups(nx, ny + 1)) };
                let g = self.go(fk(name), b, shape);
                ops.push(Op::Go(g));
                ops.push(self.solve(k + 1, s));
                b.ints[FLAGS_I] = 2;
                let g = self.go(fk(name), b, shape);
                ops.push(Op::Go(g));
            }
            let g = self.ghosts(Some(F), Some(F));
            add(&mut ops, g);
            let g = self.energy(1, 3);
            add(&mut ops, g);
        }
        // 6. The projection: solves for π = p_new − share·p from (1 − share)·p; keeps share·p + π.
        let scale = dt / dx;
        let q = self.solvers[0].levels[0].x;
        let mut b = block(nx, ny);
        b.ints[O] = self.rhs_at as u32;
        b.ints[O + 6] = slab(FLUID);
        let g = self.go(fk("divergence"), b, cg);
        ops.push(Op::Go(g));
        let mut b = block(nx, ny);
        b.ints[LW] = (nx + 2) as u32;
        b.ints[LNY] = (ny + 2) as u32;
        b.ints[O] = self.pressure_at as u32;
        b.ints[O + 1] = q as u32;
        b.reals[0] = (1.0 - m.share) * scale;
        let g = self.go(fk("pressure"), b, groups(nx + 2, ny + 2));
        ops.push(Op::Go(g));
        ops.push(self.solve(0, 1.0));
        let mut b = block(nx, ny);
        b.ints[O + 1] = q as u32;
        b.ints[O + 5] = (OPEN * lu) as u32;
        b.ints[O + 6] = (OPEN * lv) as u32;
        let g = self.go(fk("gradient_u"), b, groups(nx + 1, ny));
        ops.push(Op::Go(g));
        let g = self.go(fk("gradient_v"), b, groups(nx, ny - 1));
        ops.push(Op::Go(g));
        let mut b = block(nx, ny);
        b.ints[LW] = (nx + 2) as u32;
        b.ints[LNY] = (ny + 2) as u32;
        b.ints[O] = self.pressure_at as u32;
        b.ints[O + 1] = q as u32;
        b.ints[FLAGS_I] = 1;
        b.reals[0] = 1.0 / scale;
        b.reals[1] = m.share;
        let g = self.go(fk("pressure"), b, groups(nx + 2, ny + 2));
        ops.push(Op::Go(g));
        let g = self.ghosts(Some(F), Some(F));
        add(&mut ops, g);
        let g = self.energy(1, 4);
        add(&mut ops, g);
        // 7. The tracers, then the step counted (the tracers' seeds hash it).
        if m.n_tracers > 0 {
            let mut b = self.adv_block(dt);
            b.ints[O] = m.seeds.len() as u32;
            b.ints[O + 1] = m.n_tracers as u32;
            b.ints[O + 6] = slab(FLUID);
            b.ints[O + 7] = STEP as u32;
            let wgs = (m.n_tracers as u32).div_ceil(WG);
            let g = self.go(TRACERS, b, (wgs.min(65_535), wgs.div_ceil(65_535)));
            ops.push(Op::Go(g));
        }
        let mut b = block(nx, ny);
        b.ints[O + 7] = STEP as u32;
        let g = self.go(COUNT_STEP, b, (1, 1));
        ops.push(Op::Go(g));
        // The finiteness check.
        let mut b = block(nx, ny);
        b.ints[O + 7] = FLAGS as u32;
        let g = self.go(fk("check"), b, groups(nx + 2, ny + 2));
        ops.push(Op::Go(g));
        if self.blocks.len() > 4096 - 3 {
            return Err(GpuError::Unsupported(format!("a fluid step of {} parameter blocks", self.blocks.len())));
        }
        for (k, b) in self.blocks.iter().enumerate() {
            self.gpu.write_params_at(self.precision, &self.params, k as u64 * self.slot, &b.ints, &b.reals);
        }
        self.plan = Some(Plan { dt, ops });
        Ok(())
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>, go: &Go) {
        let (pipes, bind) = match go.module {
            Module::Fluid => (&self.fluid_pipes, &self.fluid_bind),
            Module::Vector => (&self.vector_pipes, &self.vector_bind),
            Module::Control => (&self.control_pipes, &self.control_bind),
        };
        pass.set_pipeline(&pipes[go.pipe]);
        pass.set_bind_group(0, bind, &[(go.block as u64 * self.slot) as u32]);
        match go.groups {
            Groups::Direct(x, y) => {
                if x > 0 && y > 0 {
                    pass.dispatch_workgroups(x, y, 1)
                }
            }
            Groups::Indirect(at) => pass.dispatch_workgroups_indirect(&self.ind, at * 4),
        }
    }

    fn submit(&self, gos: &[&Go]) {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            for g in gos {
                self.record(&mut pass, g);
            }
        }
        self.gpu.queue.submit([enc.finish()]);
    }

    /// The solvers' ints and the flags, read back (waits for the device).
    fn status(&self) -> Result<Vec<u32>> {
        let raw = self.gpu.read_back(&self.ints, &self.staging, INTS * 4)?;
        Ok(raw.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }

    fn diverged(st: &[u32]) -> Option<Halt> {
        (0..4)
            .find(|&f| st[FLAGS as usize + f] != u32::MAX)
            .map(|f| Halt::Diverged { field: f, index: st[FLAGS as usize + f] as usize })
    }

    /// Runs `n` steps of `dt`. Returns the steps completed; on a halt, the index of the step that
    /// failed (a divergence) or that was about to start (a stop), the state then mid-step (the
    /// caller rolls back to its snapshot). The stop flag is read before each step.
    pub fn step(&mut self, n: u64, dt: f64, stop: &AtomicBool) -> std::result::Result<u64, (u64, Halt)> {
        if self.plan.as_ref().map(|p| p.dt) != Some(dt) {
            self.make_plan(dt).map_err(|e| (0, Halt::Failed(e)))?;
        }
        let ops = std::mem::take(&mut self.plan.as_mut().expect("made above").ops);
        let r = self.run(&ops, n, stop);
        self.plan.as_mut().expect("made above").ops = ops;
        r
    }

    fn run(&mut self, ops: &[Op], n: u64, stop: &AtomicBool) -> std::result::Result<u64, (u64, Halt)> {
        let failed = |i: u64| move |e: GpuError| (i, Halt::Failed(e));
        for i in 0..n {
            if stop.load(Ordering::Relaxed) {
                return Err((i, Halt::Stopped));
            }
            let mut pending: Vec<&Go> = Vec::new();
            let mut visc = 0;
            for op in ops {
                match op {
                    Op::Go(g) => pending.push(g),
                    Op::Solve { solver, start, iteration } => {
                        let s = *solver;
                        pending.extend(start.iter());
                        let mut budget = (self.last[s] + 2).max(4);
                        loop {
                            for _ in 0..budget {
                                pending.extend(iteration.iter());
                            }
                            self.submit(&pending);
                            pending.clear();
                            let st = self.status().map_err(failed(i))?;
                            if let Some(h) = Self::diverged(&st) {
                                // The check of the step before found it (this step's comes at its end).
                                return Err((i.saturating_sub(1), h));
                            }
                            let b = 16 * s;
                            if st[b] != 0 {
                                let its = st[b + 1] as usize;
                                self.last[s] = its;
                                if s == 0 {
                                    self.solves.pressure_iterations = its;
                                    self.solves.pressure_converged = st[b + 3] != 0;
                                } else {
                                    visc += its;
                                }
                                break;
                            }
                            budget *= 2;
                        }
                    }
                }
            }
            if self.model.viscous.is_some() {
                self.solves.viscosity_iterations = visc;
            }
            self.submit(&pending);
        }
        let st = self.status().map_err(failed(n.saturating_sub(1)))?;
        if let Some(h) = Self::diverged(&st) {
            return Err((n.saturating_sub(1), h));
        }
        Ok(n)
    }
}
