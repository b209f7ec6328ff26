//! physcore's GPU backend: wgpu compute (WGSL) with the state resident on the device.
//!
//! This crate knows nothing of physcore's scenes: it holds a device ([`Gpu`]), lists the
//! adapters ([`adapters`]) and runs kernels on flat arrays ([`particles::Particles`]). The core
//! crate wraps it in a `System` (the device seam, docs/guide/architecture.md), so the world steps,
//! checkpoints and books a device system as any other.
//!
//! Promises kept from the CPU path:
//! - **Gather only.** Each thread writes its own element and sums over the others in a fixed
//!   order; no float atomics. A run repeats bit for bit on one adapter.
//! - **No silent CPU.** A CPU adapter (Mesa's lavapipe/llvmpipe, WARP, SwiftShader) is taken only
//!   when asked for by name (`"gpu:lavapipe"`) or with `PHYSCORE_GPU_ALLOW_CPU=1` (CI).
//! - **Clear failures.** No adapter, no f64 on the adapter, a buffer over the device's limits or
//!   out of device memory, a lost device: each is a [`GpuError`] saying which.
use std::fmt;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, OnceLock, Weak};

pub mod cells;
pub mod dem;
pub mod dfsph;
pub mod fluid;
pub mod gray_scott;
mod grid;
mod maxima;
pub mod particles;
pub mod shape;
pub mod sph;
mod tank;
#[doc(hidden)]
pub use grid::set_threads_for_tests as set_grid_threads_for_tests;
pub mod wave;

/// What can go wrong on the device.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GpuError {
    /// No adapter matches (none at all, or only CPU adapters that were not asked for).
    #[error("{0}")]
    NoAdapter(String),
    /// The adapter lacks something the scene needs (f64, a limit).
    #[error("{0}")]
    Unsupported(String),
    /// A device buffer could not be had.
    #[error("out of device memory: {what} ({bytes} bytes)")]
    OutOfMemory { what: String, bytes: u64 },
    /// The device was lost or reported an error; the state is as of the last completed step.
    #[error("the GPU device failed: {0}")]
    Device(String),
}

pub type Result<T> = std::result::Result<T, GpuError>;

/// Floating-point width of the device state and kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    F32,
    F64,
}

impl Precision {
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
    /// Bytes of one scalar.
    pub fn bytes(self) -> u64 {
        match self {
            Precision::F32 => 4,
            Precision::F64 => 8,
        }
    }
    /// The WGSL header that defines `real` and `bad` (non-finite) for this width.
    fn header(self) -> &'static str {
        match self {
            // The exponent bits all set: inf or NaN (comparisons may be folded by fast math).
            Precision::F32 => {
                "alias real = f32;\nfn bad(x: f32) -> bool { return (bitcast<u32>(x) & 0x7f800000u) == 0x7f800000u; }\n"
            }
            Precision::F64 => {
                "alias real = f64;\nfn bad(x: f64) -> bool { return !(abs(x) <= 1.7976931348623157e308); }\n"
            }
        }
    }
}

/// Steps per submission: grown (doubling, up to `most`) while a submission takes under half of
/// `SUBMIT_S` (0.1 s), halved when one takes over twice that. Short enough that the stop flag,
/// read between submissions, answers Ctrl-C within 0.5 s; long enough that the host's work per
/// submission (recording, the flag's read-back) is small beside the device's.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Chunk {
    steps: u64,
    most: u64,
}

const SUBMIT_S: f64 = 0.1;

impl Chunk {
    pub(crate) fn new(most: u64) -> Self {
        Self { steps: 1, most }
    }
    /// The steps of the next submission, with `left` to go.
    pub(crate) fn next(&self, left: u64) -> u64 {
        self.steps.min(left)
    }
    /// After a submission of `k` steps that took `took` seconds.
    pub(crate) fn adapt(&mut self, k: u64, took: f64) {
        if took < 0.5 * SUBMIT_S && k == self.steps {
            self.steps = (self.steps * 2).min(self.most);
        } else if took > 2.0 * SUBMIT_S && self.steps > 1 {
            self.steps /= 2;
        }
    }
}

/// How a kernel binds a buffer (`Gpu::kernels`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Bind {
    /// A uniform block, at a dynamic offset if `dynamic`.
    Uniform {
        dynamic: bool,
    },
    Read,
    ReadWrite,
}

/// One adapter as `physcore info` lists it.
#[derive(Clone, Debug, PartialEq)]
pub struct AdapterSummary {
    pub name: String,
    /// "vulkan", "metal", "dx12", ...
    pub backend: String,
    /// "discrete", "integrated", "virtual", "cpu" or "other".
    pub kind: String,
    pub driver: String,
    /// Whether the adapter runs f64 in shaders (`precision="f64"`).
    pub f64: bool,
    /// Largest storage buffer binding, bytes.
    pub max_storage_binding: u64,
    /// Largest buffer, bytes.
    pub max_buffer: u64,
}

impl AdapterSummary {
    fn of(a: &wgpu::Adapter) -> Self {
        let info = a.get_info();
        let limits = a.limits();
        Self {
            name: info.name.clone(),
            backend: info.backend.to_str().to_string(),
            kind: kind_name(info.device_type).to_string(),
            driver: format!("{} {}", info.driver, info.driver_info).trim().to_string(),
            f64: a.features().contains(wgpu::Features::SHADER_F64),
            max_storage_binding: limits.max_storage_buffer_binding_size,
            max_buffer: limits.max_buffer_size,
        }
    }
    /// Whether this is a CPU implementation (never taken silently).
    pub fn is_cpu(&self) -> bool {
        self.kind == "cpu"
    }
}

fn kind_name(t: wgpu::DeviceType) -> &'static str {
    match t {
        wgpu::DeviceType::DiscreteGpu => "discrete",
        wgpu::DeviceType::IntegratedGpu => "integrated",
        wgpu::DeviceType::VirtualGpu => "virtual",
        wgpu::DeviceType::Cpu => "cpu",
        wgpu::DeviceType::Other => "other",
    }
}

/// The process's one wgpu instance (made at first use; None where making it panicked, as a
/// missing Vulkan loader makes some drivers' probing do). One instance for the process: each
/// open device keeps its instance alive, and the NVIDIA driver stopped listing adapters
/// ("no adapter at all") after a test module had opened a few dozen of each.
fn instance() -> Option<&'static wgpu::Instance> {
    static INSTANCE: OnceLock<Option<wgpu::Instance>> = OnceLock::new();
    INSTANCE
        .get_or_init(|| {
            std::panic::catch_unwind(|| {
                // Vulkan, Metal and DX12 only: the GL backend has no f64 and weaker compute.
                let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
                desc.backends = wgpu::Backends::VULKAN | wgpu::Backends::METAL | wgpu::Backends::DX12;
                // Validation layers are for development; wgpu's own validation stays on.
                desc.flags = wgpu::InstanceFlags::empty();
                wgpu::Instance::new(desc)
            })
            .ok()
        })
        .as_ref()
}

fn enumerate() -> Vec<wgpu::Adapter> {
    // A missing Vulkan loader panics in some drivers' probing: treat it as "no adapter".
    let Some(inst) = instance() else { return Vec::new() };
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        pollster::block_on(inst.enumerate_adapters(wgpu::Backends::all()))
    }))
    .unwrap_or_default()
}

/// Each open device by its adapter's key, held weakly.
type OpenDevices = Mutex<Vec<(String, Weak<Gpu>)>>;

/// The devices open in this process, by adapter: scenes on one adapter share its device (and
/// queue) while any of them lives, as a process shares one CUDA context per GPU. Each scene's
/// work is submitted and waited for within its own calls, so sharing changes no result.
fn open_devices() -> &'static OpenDevices {
    static OPEN: OnceLock<OpenDevices> = OnceLock::new();
    OPEN.get_or_init(|| Mutex::new(Vec::new()))
}

/// Every adapter wgpu sees (Vulkan, Metal, DX12), CPU ones included, in the order found.
pub fn adapters() -> Vec<AdapterSummary> {
    enumerate().iter().map(AdapterSummary::of).collect()
}

/// Whether CPU adapters may be taken without being named (`PHYSCORE_GPU_ALLOW_CPU=1`: CI's
/// lavapipe).
pub fn cpu_allowed_by_env() -> bool {
    std::env::var("PHYSCORE_GPU_ALLOW_CPU").map(|v| v == "1").unwrap_or(false)
}

/// An open device and its queue, shared by the systems of a scene.
pub struct Gpu {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    summary: AdapterSummary,
    /// Set by the device-lost callback.
    lost: Arc<AtomicBool>,
}

impl fmt::Debug for Gpu {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Gpu({} via {})", self.summary.name, self.summary.backend)
    }
}

impl Gpu {
    /// Opens a device. `which`: `"gpu"` (the best non-CPU adapter: discrete, then integrated,
    /// then virtual), or `"gpu:NAME"` (the first adapter whose name, backend or kind contains
    /// NAME, case-insensitive; `"gpu:lavapipe"` takes Mesa's CPU Vulkan, whose name is
    /// "llvmpipe"). CPU adapters are taken under `"gpu"` only with `PHYSCORE_GPU_ALLOW_CPU=1`.
    ///
    /// Errors: [`GpuError::NoAdapter`] naming what was found instead.
    pub fn open(which: &str) -> Result<Arc<Gpu>> {
        Self::open_as(which, true)
    }

    /// Opens a device of its own on the adapter `which` names (as [`Gpu::open`]), shared with
    /// no other caller: its queue runs beside theirs. On a CPU adapter (lavapipe) each queue
    /// executes on a thread of its own, so the device tests, which open one each, run in
    /// parallel; through one shared queue they ran one after another, on one core.
    ///
    /// Errors: as [`Gpu::open`].
    pub fn open_own(which: &str) -> Result<Arc<Gpu>> {
        Self::open_as(which, false)
    }

    fn open_as(which: &str, share: bool) -> Result<Arc<Gpu>> {
        let found = enumerate();
        let named = which.strip_prefix("gpu:").map(|s| s.to_ascii_lowercase());
        let listed: Vec<String> =
            found.iter().map(AdapterSummary::of).map(|s| format!("{} ({}, {})", s.name, s.kind, s.backend)).collect();
        let seen = if listed.is_empty() {
            "no adapter at all (is a Vulkan driver installed?)".to_string()
        } else {
            listed.join("; ")
        };
        let pick = match (&named, which) {
            (Some(name), _) => {
                // lavapipe calls itself llvmpipe.
                let name = if name == "lavapipe" { "llvmpipe".to_string() } else { name.clone() };
                found.into_iter().find(|a| {
                    let s = AdapterSummary::of(a);
                    [s.name, s.backend, s.kind].iter().any(|f| f.to_ascii_lowercase().contains(&name))
                })
            }
            (None, "gpu") => {
                let allow_cpu = cpu_allowed_by_env();
                let rank = |a: &wgpu::Adapter| match a.get_info().device_type {
                    wgpu::DeviceType::DiscreteGpu => 0,
                    wgpu::DeviceType::IntegratedGpu => 1,
                    wgpu::DeviceType::VirtualGpu => 2,
                    wgpu::DeviceType::Other => 3,
                    wgpu::DeviceType::Cpu => 4,
                };
                let mut ok: Vec<_> = found
                    .into_iter()
                    .filter(|a| allow_cpu || a.get_info().device_type != wgpu::DeviceType::Cpu)
                    .collect();
                ok.sort_by_key(rank);
                ok.into_iter().next()
            }
            _ => {
                return Err(GpuError::NoAdapter(format!(
                    "device must be \"gpu\" or \"gpu:NAME\" (an adapter's name, backend or kind), got {which:?}"
                )))
            }
        };
        let adapter = pick.ok_or_else(|| {
            GpuError::NoAdapter(match &named {
                Some(n) => format!("no GPU adapter matches {n:?}; found: {seen}"),
                None => format!(
                    "no GPU adapter; found: {seen}. A CPU adapter (lavapipe) runs only when named \
                     (device=\"gpu:lavapipe\") or with PHYSCORE_GPU_ALLOW_CPU=1"
                ),
            })
        })?;
        let summary = AdapterSummary::of(&adapter);
        let info = adapter.get_info();
        let key = format!("{}|{:?}|{}|{}|{}", info.name, info.backend, info.vendor, info.device, info.driver_info);
        let mut open = open_devices().lock().unwrap_or_else(|e| e.into_inner());
        open.retain(|(_, w)| w.strong_count() > 0);
        if share {
            if let Some(gpu) = open.iter().find(|(k, _)| *k == key).and_then(|(_, w)| w.upgrade()) {
                if !gpu.lost.load(std::sync::atomic::Ordering::Relaxed) {
                    return Ok(gpu);
                }
            }
        }
        let limits = adapter.limits();
        let mut features = wgpu::Features::empty();
        if summary.f64 {
            features |= wgpu::Features::SHADER_F64;
        }
        let desc = wgpu::DeviceDescriptor {
            label: Some("physcore"),
            required_features: features,
            // The adapter's own limits: large scenes need more than WebGPU's defaults.
            required_limits: limits,
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&desc))
            .map_err(|e| GpuError::Device(format!("could not open {}: {e}", summary.name)))?;
        let gpu = Arc::new(Gpu { device, queue, summary, lost: Arc::new(AtomicBool::new(false)) });
        // A lost device is not handed to the next scene: it opens a new one.
        let lost = gpu.lost.clone();
        gpu.device.set_device_lost_callback(move |_, _| lost.store(true, std::sync::atomic::Ordering::Relaxed));
        if share {
            open.retain(|(k, _)| *k != key);
            open.push((key, Arc::downgrade(&gpu)));
        }
        Ok(gpu)
    }

    /// Whether the adapter is a CPU one (lavapipe): see `Gpu::kernels_with`.
    pub(crate) fn is_cpu(&self) -> bool {
        self.summary.kind == kind_name(wgpu::DeviceType::Cpu)
    }

    /// The adapter it runs on.
    pub fn adapter(&self) -> &AdapterSummary {
        &self.summary
    }

    /// Refuses a precision the adapter lacks, naming it.
    pub fn check_precision(&self, p: Precision) -> Result<()> {
        if p == Precision::F64 && !self.summary.f64 {
            return Err(GpuError::Unsupported(format!(
                "precision \"f64\": the adapter {} has no f64 in shaders (use \"f32\")",
                self.summary.name
            )));
        }
        Ok(())
    }

    /// Creates a buffer, refusing one over the device's limits and reporting out-of-memory as
    /// [`GpuError::OutOfMemory`] naming `what`.
    pub(crate) fn buffer(&self, what: &str, bytes: u64, usage: wgpu::BufferUsages) -> Result<wgpu::Buffer> {
        let lim = self.device.limits();
        let storage = usage.contains(wgpu::BufferUsages::STORAGE);
        if bytes > lim.max_buffer_size || (storage && bytes > lim.max_storage_buffer_binding_size) {
            let most = if storage { lim.max_storage_buffer_binding_size } else { lim.max_buffer_size };
            return Err(GpuError::Unsupported(format!(
                "{what} needs {bytes} bytes; the adapter {} binds at most {most}",
                self.summary.name
            )));
        }
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let b = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(what),
            size: bytes.max(16),
            usage,
            mapped_at_creation: false,
        });
        if pollster::block_on(scope.pop()).is_some() {
            return Err(GpuError::OutOfMemory { what: what.to_string(), bytes });
        }
        Ok(b)
    }

    /// Writes `data` (f64 on the host) into `b` at the device's precision.
    pub(crate) fn upload(&self, p: Precision, b: &wgpu::Buffer, data: &[f64]) {
        self.upload_at(p, b, 0, data)
    }

    /// `upload` from byte `offset` of `b`.
    pub(crate) fn upload_at(&self, p: Precision, b: &wgpu::Buffer, offset: u64, data: &[f64]) {
        match p {
            Precision::F64 => self.queue.write_buffer(b, offset, bytemuck::cast_slice(data)),
            Precision::F32 => {
                let d: Vec<f32> = data.iter().map(|&x| x as f32).collect();
                self.queue.write_buffer(b, offset, bytemuck::cast_slice(&d))
            }
        }
    }

    /// Writes a uniform block: `ints` (u32) then `reals` at the device's precision.
    pub(crate) fn write_params(&self, p: Precision, b: &wgpu::Buffer, ints: &[u32], reals: &[f64]) {
        self.write_params_at(p, b, 0, ints, reals)
    }

    /// `write_params` at byte `offset` of `b`.
    pub(crate) fn write_params_at(&self, p: Precision, b: &wgpu::Buffer, offset: u64, ints: &[u32], reals: &[f64]) {
        let mut bytes: Vec<u8> = bytemuck::cast_slice(ints).to_vec();
        match p {
            Precision::F64 => bytes.extend_from_slice(bytemuck::cast_slice(reals)),
            Precision::F32 => {
                let r: Vec<f32> = reals.iter().map(|&x| x as f32).collect();
                bytes.extend_from_slice(bytemuck::cast_slice(&r))
            }
        }
        self.queue.write_buffer(b, offset, &bytes);
    }

    /// Copies the first `bytes` of `b` to the host through `staging` (waits for the queue).
    pub(crate) fn read_back(&self, b: &wgpu::Buffer, staging: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        self.read_back_with(b, staging, bytes, |raw| out = raw.to_vec())?;
        Ok(out)
    }

    /// Copies the first `bytes` of `b` through `staging` and hands the mapped bytes to `f`.
    pub(crate) fn read_back_with(
        &self,
        b: &wgpu::Buffer,
        staging: &wgpu::Buffer,
        bytes: u64,
        f: impl FnOnce(&[u8]),
    ) -> Result<()> {
        self.read_back_from(b, 0, staging, bytes, f)
    }

    /// `read_back_with` from byte `offset` of `b`.
    pub(crate) fn read_back_from(
        &self,
        b: &wgpu::Buffer,
        offset: u64,
        staging: &wgpu::Buffer,
        bytes: u64,
        f: impl FnOnce(&[u8]),
    ) -> Result<()> {
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(b, offset, staging, 0, bytes);
        self.queue.submit([enc.finish()]);
        let slice = staging.slice(0..bytes);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv()
            .map_err(|e| GpuError::Device(e.to_string()))?
            .map_err(|e| GpuError::Device(format!("reading back: {e}")))?;
        {
            let view = slice.get_mapped_range().map_err(|e| GpuError::Device(e.to_string()))?;
            f(&view);
        }
        staging.unmap();
        Ok(())
    }

    /// The first u32 of `b` (a flag), read back.
    pub(crate) fn read_u32(&self, b: &wgpu::Buffer, staging: &wgpu::Buffer) -> Result<u32> {
        let bytes = self.read_back(b, staging, 4)?;
        Ok(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
    }

    /// The first `count` reals of `b`, read back as f64.
    pub(crate) fn read_reals(
        &self,
        p: Precision,
        b: &wgpu::Buffer,
        staging: &wgpu::Buffer,
        count: usize,
    ) -> Result<Vec<f64>> {
        self.read_reals_at(p, b, 0, staging, count)
    }

    /// `count` reals of `b` from byte `offset`, read back as f64.
    pub(crate) fn read_reals_at(
        &self,
        p: Precision,
        b: &wgpu::Buffer,
        offset: u64,
        staging: &wgpu::Buffer,
        count: usize,
    ) -> Result<Vec<f64>> {
        // Converted straight from the mapped range: one pass, no intermediate copies (a
        // million particles' rows took 150 ms through three copies).
        let bytes = (count as u64).max(1) * p.bytes();
        let mut v = Vec::new();
        v.try_reserve_exact(count)
            .map_err(|_| GpuError::OutOfMemory { what: "read-back".into(), bytes: 8 * count as u64 })?;
        self.read_back_from(b, offset, staging, bytes, |raw| match p {
            Precision::F64 => {
                v.extend(raw.chunks_exact(8).take(count).map(|c| f64::from_le_bytes(c.try_into().unwrap())))
            }
            Precision::F32 => {
                v.extend(raw.chunks_exact(4).take(count).map(|c| f64::from(f32::from_le_bytes(c.try_into().unwrap()))))
            }
        })?;
        Ok(v)
    }

    /// Compiles `wgsl` (after the precision header of `p`) and makes its bind group layout from
    /// `binds` (binding k: `binds[k]`, every one a buffer seen by compute) and one pipeline per
    /// entry point of `names`, in that order.
    pub(crate) fn kernels(
        &self,
        label: &str,
        p: Precision,
        wgsl: &str,
        binds: &[Bind],
        names: &[&str],
    ) -> (wgpu::BindGroupLayout, Vec<wgpu::ComputePipeline>) {
        self.kernels_with(label, p, wgsl, binds, names, false)
    }

    /// `kernels`, with the parameter block `P` (`var<uniform> P: Params;`, bound as
    /// `Bind::Uniform`) read from a read-only storage buffer instead if `params_in_storage`
    /// (its buffer then needs `STORAGE` usage too). The arithmetic, so every bit, is the same.
    ///
    /// Why (lavapipe only): lavapipe inlines the values of a uniform block that branch and loop
    /// conditions read, and when that shrinks a shader by half it compiles the shader with LLVM
    /// again at every dispatch (Mesa 22.3, `update_inline_shader_state`: no cache of those
    /// variants); otherwise it gives up inlining for good. Which way it goes depends on the
    /// values: a DEM step took 10 ms for 29 grains against 0.8 ms for 28 on CI's lavapipe, 63 %
    /// of it in the driver (perf). A storage buffer is never inlined, but on lavapipe its loads cost
    /// more than a uniform's: the SPH, DFSPH and particle kernels ran 1.2-1.4x slower with it,
    /// so only the DEM takes it there (`Dem::new`, on a CPU adapter).
    pub(crate) fn kernels_with(
        &self,
        label: &str,
        p: Precision,
        wgsl: &str,
        binds: &[Bind],
        names: &[&str],
        params_in_storage: bool,
    ) -> (wgpu::BindGroupLayout, Vec<wgpu::ComputePipeline>) {
        let d = &self.device;
        let mut src = format!("{}{}", p.header(), wgsl);
        if params_in_storage {
            src = src.replace("var<uniform> P: Params;", "var<storage, read> P: Params;");
        }
        // Every check wgpu offers stays on (bounds of every buffer access, integer division by
        // zero) except the loop counter naga adds to every loop in case it never ends
        // (`force_loop_bounding`): a register and a compare-and-branch in each N-body and spring
        // iteration. Safe here because every loop in physcore's WGSL runs a counter from 0 up
        // to a bound fixed before it starts (a uniform, a workgroup constant, a particle's
        // spring count) or halves a workgroup constant to 0; a shader that breaks this rule
        // must not come through here.
        let checks = wgpu::ShaderRuntimeChecks { force_loop_bounding: false, ..wgpu::ShaderRuntimeChecks::checked() };
        // SAFETY: the one check left out is the loop bound above; our loops end (see there).
        let module = unsafe {
            d.create_shader_module_trusted(
                wgpu::ShaderModuleDescriptor { label: Some(label), source: wgpu::ShaderSource::Wgsl(src.into()) },
                checks,
            )
        };
        let entries: Vec<wgpu::BindGroupLayoutEntry> = binds
            .iter()
            .enumerate()
            .map(|(k, b)| {
                let (ty, has_dynamic_offset) = match b {
                    Bind::Uniform { dynamic } if params_in_storage => {
                        (wgpu::BufferBindingType::Storage { read_only: true }, *dynamic)
                    }
                    Bind::Uniform { dynamic } => (wgpu::BufferBindingType::Uniform, *dynamic),
                    Bind::Read => (wgpu::BufferBindingType::Storage { read_only: true }, false),
                    Bind::ReadWrite => (wgpu::BufferBindingType::Storage { read_only: false }, false),
                };
                wgpu::BindGroupLayoutEntry {
                    binding: k as u32,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset, min_binding_size: None },
                    count: None,
                }
            })
            .collect();
        let layout =
            d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries });
        let pl = d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipes = names
            .iter()
            .map(|name| {
                d.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(name),
                    layout: Some(&pl),
                    module: &module,
                    entry_point: Some(name),
                    compilation_options: Default::default(),
                    cache: None,
                })
            })
            .collect();
        (layout, pipes)
    }

    /// A bind group of `layout` binding `buffers` whole, binding k the k-th, but for binding 0:
    /// a uniform block of `block` bytes at the dynamic offset given when it is bound.
    pub(crate) fn bind_with_params(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        buffers: &[&wgpu::Buffer],
        block: u64,
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: if i == 0 {
                    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: b,
                        offset: 0,
                        size: std::num::NonZeroU64::new(block),
                    })
                } else {
                    b.as_entire_binding()
                },
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
    }

    /// Waits for all submitted work.
    pub(crate) fn wait(&self) -> Result<()> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).map(|_| ()).map_err(|e| GpuError::Device(e.to_string()))
    }
}
