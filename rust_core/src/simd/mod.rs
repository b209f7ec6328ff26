//! One portable SIMD layer for every hot kernel. A kernel is written once, generic over a token
//! `S: Simd` and a precision `F: Float`, and [`dispatch`] runs it compiled for the level picked at
//! run time: scalar, AVX2 + FMA (x86-64-v3), AVX-512 (x86-64-v4) or NEON (aarch64).
//!
//! Built on `pulp` (the layer under faer and gemm). Why pulp: its tokens can only be made when the
//! CPU has the features, so kernel bodies hold no `unsafe` and name no intrinsics; one generic
//! source is compiled per level inside a `#[target_feature]` wrapper (runtime dispatch, no
//! `target-cpu=native`); it covers every level we ship for, and it is maintained as faer's base.
//! Considered and not taken: `multiversion` clones whole functions but has no rsqrt, masks or
//! selects; `wide` fixes the level at compile time; `std::simd` is nightly-only; a layer of our
//! own would be more unsafe code to keep.
//!
//! What physics kernels need beyond pulp lives here: [`Simd::rsqrt_f64s`] / [`Simd::rsqrt_f32s`],
//! 1/√x from the hardware estimate refined by Newton steps — one primitive with a fast
//! implementation per level and a portable default (a square root and a division) — and
//! [`Float`] / [`P`], which let one kernel source serve f32 and f64 with arithmetic operators.
//!
//! The level is chosen once per process (one probe for the whole core): the best the CPU has, or
//! the one named by `PHYSCORE_SIMD=scalar|avx2|avx512|neon|auto`. A level the CPU lacks, or an
//! unknown name, is an error (`check`), never a crash. Tests can switch levels (`set_level`).
//!
//! Layout: this file holds the levels, their detection and dispatch, and the `Simd` trait;
//! `float` the `Float` trait (f32 and f64 with their vectors); `pack` the `P` and `Mask`
//! wrappers kernels are written with; `x86` and `aarch64` the levels' own code; `tests` the tests.
use crate::error::{invalid, Result};
use std::fmt::Debug;
use std::ops::{Add, Div, Mul, Neg, Sub};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::OnceLock;

mod float;
mod pack;
pub use float::Float;
pub use pack::{Mask, P};

#[cfg(target_arch = "aarch64")]
mod aarch64;
#[cfg(target_arch = "x86_64")]
mod x86;

/// An instruction-set level of the kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Level {
    /// Portable code for the baseline target (one lane per operation).
    Scalar,
    /// x86-64-v3: AVX2 + FMA, 4 f64 / 8 f32 lanes.
    Avx2,
    /// x86-64-v4: AVX-512 F/BW/CD/DQ/VL, 8 f64 / 16 f32 lanes.
    Avx512,
    /// aarch64 NEON (Advanced SIMD), 2 f64 / 4 f32 lanes.
    Neon,
}

impl Level {
    pub const ALL: [Level; 4] = [Level::Scalar, Level::Avx2, Level::Avx512, Level::Neon];

    /// The stable lower-case name (`PHYSCORE_SIMD` takes these).
    pub fn name(self) -> &'static str {
        match self {
            Level::Scalar => "scalar",
            Level::Avx2 => "avx2",
            Level::Avx512 => "avx512",
            Level::Neon => "neon",
        }
    }

    pub fn by_name(s: &str) -> Option<Level> {
        Level::ALL.into_iter().find(|l| l.name() == s)
    }

    /// Whether this CPU (and this build's architecture) can run the level.
    pub fn supported(self) -> bool {
        match self {
            Level::Scalar => true,
            #[cfg(target_arch = "x86_64")]
            Level::Avx2 => pulp::x86::V3::try_new().is_some(),
            #[cfg(target_arch = "x86_64")]
            Level::Avx512 => pulp::x86::V4::try_new().is_some(),
            #[cfg(target_arch = "aarch64")]
            Level::Neon => pulp::aarch64::Neon::try_new().is_some(),
            #[allow(unreachable_patterns)]
            _ => false,
        }
    }

    /// The levels this CPU supports, slowest first (scalar is always there).
    pub fn available() -> Vec<Level> {
        Level::ALL.into_iter().filter(|l| l.supported()).collect()
    }

    /// The fastest supported level.
    pub fn best() -> Level {
        *Level::available().last().expect("scalar is always available")
    }
}

/// The level named by `PHYSCORE_SIMD` (or the best one), decided once per process.
fn probe() -> &'static std::result::Result<Level, String> {
    static PROBE: OnceLock<std::result::Result<Level, String>> = OnceLock::new();
    PROBE.get_or_init(|| {
        let Some(raw) = std::env::var_os("PHYSCORE_SIMD") else {
            return Ok(Level::best());
        };
        let s = raw.to_string_lossy().trim().to_ascii_lowercase();
        if s.is_empty() || s == "auto" {
            return Ok(Level::best());
        }
        let names = || Level::available().iter().map(|l| l.name()).collect::<Vec<_>>().join(", ");
        match Level::by_name(&s) {
            None => Err(format!(
                "{s:?} is not a SIMD level; valid: scalar, avx2, avx512, neon, auto (this CPU has {})",
                names()
            )),
            Some(l) if !l.supported() => Err(format!("this CPU cannot run {s}; it has {} (or use auto)", names())),
            Some(l) => Ok(l),
        }
    })
}

/// 0: no override; 1 + index into `Level::ALL` otherwise.
static FORCED: AtomicU8 = AtomicU8::new(0);

/// The level the kernels run at, or the reason `PHYSCORE_SIMD` cannot be honoured.
pub fn check() -> Result<Level> {
    match FORCED.load(Ordering::Relaxed) {
        0 => probe().clone().map_err(|e| invalid("PHYSCORE_SIMD", e)),
        k => Ok(Level::ALL[k as usize - 1]),
    }
}

/// The level the kernels run at (scalar if `PHYSCORE_SIMD` is invalid; scenes refuse to be built
/// then, see `check`).
#[inline]
pub fn level() -> Level {
    check().unwrap_or(Level::Scalar)
}

/// Forces a level for this process (`None`: back to `PHYSCORE_SIMD` or the best). Results at
/// different levels agree to a few ulp, not bit for bit. Errors if the CPU lacks the level.
pub fn set_level(l: Option<Level>) -> Result<()> {
    match l {
        None => FORCED.store(0, Ordering::Relaxed),
        Some(l) if !l.supported() => {
            let have = Level::available().iter().map(|l| l.name()).collect::<Vec<_>>().join(", ");
            return Err(invalid("level", format!("this CPU cannot run {}; it supports {have}", l.name())));
        }
        Some(l) => FORCED.store(1 + Level::ALL.iter().position(|&x| x == l).expect("listed") as u8, Ordering::Relaxed),
    }
    Ok(())
}

/// Whether the hardware row gather beats loading lane by lane on this CPU. It moves data only, so
/// the choice never changes a result: it is the one place tuned to a microarchitecture. AMD Zen 4
/// (family 19h) runs AVX-512 gathers slowly: the 128² cloth at the avx512 level measured 29.2
/// against 33.9 M particle-steps/s lane by lane (256²: 28.7 against 35.0; medians of 6 alternating
/// runs), while on Zen 5 the gather doubled it (54 against 26–31 M). Decided once per process.
pub fn hardware_gather_pays() -> bool {
    static PAYS: OnceLock<bool> = OnceLock::new();
    *PAYS.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: CPUID leaves 0 and 1 exist on every x86-64 CPU (`__cpuid` is a safe function
            // from Rust 1.87 on, an unsafe one before).
            #[allow(unused_unsafe)]
            let (v, f) = unsafe { (std::arch::x86_64::__cpuid(0), std::arch::x86_64::__cpuid(1)) };
            let amd = (v.ebx, v.edx, v.ecx) == (0x6874_7541, 0x6974_6e65, 0x444d_4163); // "AuthenticAMD"
            let base = (f.eax >> 8) & 0xf;
            let family = if base == 0xf { base + ((f.eax >> 20) & 0xff) } else { base };
            !(amd && family == 0x19)
        }
        #[cfg(not(target_arch = "x86_64"))]
        true
    })
}

/// A short description of the CPU (model name where the OS tells it, else the architecture).
pub fn cpu_name() -> String {
    #[cfg(target_os = "linux")]
    if let Ok(s) = std::fs::read_to_string("/proc/cpuinfo") {
        if let Some(l) = s.lines().find(|l| l.starts_with("model name") || l.starts_with("Model")) {
            if let Some((_, v)) = l.split_once(':') {
                return v.trim().to_string();
            }
        }
    }
    std::env::consts::ARCH.to_string()
}

/// pulp's SIMD operations plus the fast approximate reciprocal square root, per level.
///
/// `rsqrt_*` returns 1/√x to about 1 ulp (f64: a few ulp; f32: ≤ 3 ulp) for every positive
/// finite x, and is unspecified (inf or NaN) for x = 0: kernels mask those lanes.
pub trait Simd: pulp::Simd {
    /// Vector registers of the level (16 on AVX2, 32 on AVX-512 and NEON): kernels that keep
    /// several receivers in registers size their tiles by it.
    const REGISTERS: usize = 16;
    /// 0, or k: kernels that compute many f64 1/√x route one receiver in k through the divider
    /// (`P::rsqrt_exact`) while the rest take the estimate (`P::rsqrt`), so that both the FMA
    /// units and the divider work (AVX2: k = 2, see `x86.rs`). The choice is fixed per receiver
    /// index, so results do not depend on the thread count or the tiling.
    const SPLIT_RSQRT: usize = 0;
    /// Whether loops that do much else per 1/√ or √ (and so leave the divider idle) take them
    /// from the divider (`P::rsqrt_in_loop` and its twins) instead of the estimate. AVX2: its
    /// f64 estimate goes through float32 (~17 instructions against a square root and a
    /// division), its f32 one needs a Newton step and a special-value select (6 against 1–2);
    /// measured on Zen 3, cloth 128² 39 → 48 M particle-steps/s, SPH-2D 160k +7 % (both with
    /// their other changes in place). Other levels keep the estimate (not measured here).
    const DIVIDER_IN_LOOPS: bool = false;
    /// Whether `gather_rows_f64s_hw` is the level's hardware gather (AVX-512), not the default.
    const HW_GATHER: bool = false;

    /// Rows `idx[..F64_LANES]` of two row-major `(n, dim)` arrays `a` and `b` (positions and
    /// velocities, dim 2 or 3), one vector per component (component 2 is zero in 2D), lane by
    /// lane. Panics if an index is out of bounds.
    #[inline(always)]
    fn gather_rows_f64s(self, a: &[f64], b: &[f64], dim: usize, idx: &[u32]) -> ([Self::f64s; 3], [Self::f64s; 3]) {
        let l = Self::F64_LANES;
        let idx = &idx[..l];
        let zero = self.splat_f64s(0.0);
        let (mut ra, mut rb) = ([zero; 3], [zero; 3]);
        for c in 0..dim {
            let (mut ba, mut bb) = ([0.0f64; 8], [0.0f64; 8]);
            for k in 0..l {
                let r = idx[k] as usize * dim + c;
                ba[k] = a[r];
                bb[k] = b[r];
            }
            ra[c] = pulp::bytemuck::pod_read_unaligned(pulp::bytemuck::cast_slice(&ba[..l]));
            rb[c] = pulp::bytemuck::pod_read_unaligned(pulp::bytemuck::cast_slice(&bb[..l]));
        }
        (ra, rb)
    }

    /// Rows `first .. first + F64_LANES` of two row-major `(n, dim)` arrays: `gather_rows_f64s` of
    /// consecutive indices, the same values. Levels that can read whole vectors and de-interleave
    /// them in registers do so (AVX2: 2–3 loads and 4–6 shuffles per array instead of a load and
    /// an insert per lane and component); the default gathers. Panics if a row is out of bounds.
    #[inline(always)]
    fn load_rows_f64s(self, a: &[f64], b: &[f64], dim: usize, first: usize) -> ([Self::f64s; 3], [Self::f64s; 3]) {
        let mut idx = [0u32; 8];
        for (k, i) in idx.iter_mut().enumerate() {
            *i = (first + k) as u32;
        }
        self.gather_rows_f64s(a, b, dim, &idx)
    }

    /// `gather_rows_f64s` with the level's hardware gather where it has one (AVX-512), the same
    /// values. Kernels call it only where [`hardware_gather_pays`] (AVX2's gather measured slower
    /// than lane by lane, so AVX2 keeps this default).
    #[inline(always)]
    fn gather_rows_f64s_hw(self, a: &[f64], b: &[f64], dim: usize, idx: &[u32]) -> ([Self::f64s; 3], [Self::f64s; 3]) {
        self.gather_rows_f64s(a, b, dim, idx)
    }

    /// Bit l set where lane l of the f64 mask `m` is set (`mask_to_bits`).
    #[inline(always)]
    fn mask_bits_m64s(self, m: Self::m64s) -> u64 {
        mask_to_bits::<_, Self::u64s, u64>(m)
    }
    /// The float32 twin of `mask_bits_m64s`.
    #[inline(always)]
    fn mask_bits_m32s(self, m: Self::m32s) -> u64 {
        mask_to_bits::<_, Self::u32s, u32>(m)
    }

    #[inline(always)]
    fn rsqrt_f64s(self, x: Self::f64s) -> Self::f64s {
        self.div_f64s(self.splat_f64s(1.0), self.sqrt_f64s(x))
    }
    #[inline(always)]
    fn rsqrt_f32s(self, x: Self::f32s) -> Self::f32s {
        self.div_f32s(self.splat_f32s(1.0), self.sqrt_f32s(x))
    }
}

/// A mask `m` as bits, lane l at bit l: its lanes (all ones or zero) read as the unsigned
/// vector `U` of lanes `E` where it has that size (AVX2, NEON), or the bits themselves where the
/// level's mask is already a bit field (AVX-512's `b8`/`b16`, the scalar level's `bool`).
#[inline(always)]
fn mask_to_bits<M: pulp::bytemuck::NoUninit, U: pulp::bytemuck::Pod, E: pulp::bytemuck::Pod + Default + PartialEq>(
    m: M,
) -> u64 {
    use std::mem::size_of;
    if const { size_of::<M>() == size_of::<U>() } {
        let lanes: U = pulp::bytemuck::cast(m);
        let lanes = pulp::bytemuck::cast_slice::<U, E>(std::slice::from_ref(&lanes));
        lanes.iter().enumerate().fold(0, |b, (l, x)| b | (((*x != E::default()) as u64) << l))
    } else if const { size_of::<M>() == 1 } {
        pulp::bytemuck::cast::<M, u8>(m) as u64
    } else if const { size_of::<M>() == 2 } {
        pulp::bytemuck::cast::<M, u16>(m) as u64
    } else {
        unreachable!("no SIMD level has such a mask")
    }
}

impl Simd for pulp::Scalar {}

/// One Newton–Raphson step for y ≈ 1/√x, with h = x/2: y (3/2 − (h y) y). Written (h·y)·y, not
/// h·(y·y): y² overflows for x below 1e-308^(1/2)·… (springs decayed to 1e-155 m turned NaN).
/// The error e becomes ≈ 1.5 e² per step.
#[cfg(target_arch = "aarch64")]
#[inline(always)]
pub(crate) fn newton_rsqrt_f64<S: pulp::Simd>(s: S, h: S::f64s, y: S::f64s) -> S::f64s {
    s.mul_f64s(y, s.negate_mul_add_f64s(s.mul_f64s(h, y), y, s.splat_f64s(1.5)))
}
#[inline(always)]
pub(crate) fn newton_rsqrt_f32<S: pulp::Simd>(s: S, h: S::f32s, y: S::f32s) -> S::f32s {
    s.mul_f32s(y, s.negate_mul_add_f32s(s.mul_f32s(h, y), y, s.splat_f32s(1.5)))
}

/// The refined 1/√x where it is a number, else the hardware estimate `y0`: the refinement turns
/// x = 0 and x = +inf into NaN (0·inf), where the estimate is already exact (+inf and 0), as
/// 1/√x is on the scalar level. Without this a force at an overflowing distance (r² = inf) was 0
/// on the scalar and AVX2 f64 levels but NaN on AVX-512, and an ensemble member "diverged" only
/// on AVX-512 machines. Negative and NaN x stay NaN (the estimate is NaN there).
#[inline(always)]
pub(crate) fn rsqrt_specials_f64<S: pulp::Simd>(s: S, y0: S::f64s, y: S::f64s) -> S::f64s {
    s.select_f64s(s.equal_f64s(y, y), y, y0)
}
/// The float32 twin of `rsqrt_specials_f64`.
#[inline(always)]
pub(crate) fn rsqrt_specials_f32<S: pulp::Simd>(s: S, y0: S::f32s, y: S::f32s) -> S::f32s {
    s.select_f32s(s.equal_f32s(y, y), y, y0)
}

/// A kernel, generic over the SIMD token. `run` and everything it calls must be
/// `#[inline(always)]` so that it is compiled inside the level's `#[target_feature]` wrapper.
pub trait Kernel {
    type Output;
    fn run<S: Simd>(self, s: S) -> Self::Output;
}

/// Adapts a `Kernel` to pulp's `WithSimd`, handing it the concrete token (whose type implements
/// our `Simd`, which pulp's generic parameter cannot promise).
struct Run<K, S>(K, S);
impl<K: Kernel, T: Simd> pulp::WithSimd for Run<K, T> {
    type Output = K::Output;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> K::Output {
        self.0.run(self.1)
    }
}

/// Runs `k` compiled for `level` (scalar if this CPU cannot run `level`).
#[inline]
pub fn dispatch<K: Kernel>(level: Level, k: K) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    {
        if level == Level::Avx512 {
            if let Some(s) = pulp::x86::V4::try_new() {
                return pulp::Simd::vectorize(s, Run(k, s));
            }
        } else if level == Level::Avx2 {
            if let Some(s) = pulp::x86::V3::try_new() {
                return pulp::Simd::vectorize(s, Run(k, s));
            }
        }
    }
    #[cfg(target_arch = "aarch64")]
    if level == Level::Neon {
        if let Some(s) = pulp::aarch64::Neon::try_new() {
            return pulp::Simd::vectorize(s, Run(k, s));
        }
    }
    let _ = level;
    k.run(pulp::Scalar::new())
}

/// Runs `f` inside the `#[target_feature]` wrapper of `level`, so that plain loops over slices
/// in it (stencils) are auto-vectorised for that level. Mark the closure `#[inline(always)]`:
/// only code inlined into the wrapper gets the level's instructions.
#[inline]
pub fn vectorized<R>(level: Level, f: impl FnOnce() -> R) -> R {
    struct Closure<F>(F);
    impl<R, F: FnOnce() -> R> Kernel for Closure<F> {
        type Output = R;
        #[inline(always)]
        fn run<S: Simd>(self, _: S) -> R {
            (self.0)()
        }
    }
    dispatch(level, Closure(f))
}

/// `x`, hidden from the optimiser (no instruction is emitted), so that a bit mask stays a mask:
/// LLVM recognises `(a & m) | (b & !m)` as a select and turns a select of a division into a
/// branch.
#[inline(always)]
pub fn opaque(mut x: u64) -> u64 {
    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    // SAFETY: an empty asm block that only names a register: it reads and writes nothing.
    unsafe {
        core::arch::asm!("/* {0} */", inout(reg) x, options(pure, nomem, nostack, preserves_flags));
    }
    x
}

#[cfg(test)]
mod tests;
