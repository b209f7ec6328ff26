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
use crate::error::{invalid, Result};
use std::fmt::Debug;
use std::ops::{Add, Div, Mul, Neg, Sub};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::OnceLock;

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
        let idx: [u32; 8] = std::array::from_fn(|k| (first + k) as u32);
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

/// The precision of a kernel: f32 or f64, with its SIMD vectors for token `S`.
pub trait Float:
    Copy
    + Send
    + Sync
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Debug
    + pulp::bytemuck::Pod
    + 'static
{
    const ZERO: Self;
    const ONE: Self;
    fn of(x: f64) -> Self;
    fn f64(self) -> f64;
    fn sqrt(self) -> Self;
    /// `a` if `c` else `b`, by masking the bits: no branch, even where one side is a division
    /// (LLVM turns a select of an expensive value into a branch, which mispredicts when the
    /// condition is random: the cubic spline's q < 1 over a particle's neighbours).
    fn pick(c: bool, a: Self, b: Self) -> Self;
    /// Plain compare (not IEEE maxNum): vectorises to one instruction.
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        if self > o {
            self
        } else {
            o
        }
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        if self < o {
            self
        } else {
            o
        }
    }

    type V<S: Simd>: Copy + pulp::bytemuck::Pod;
    type M<S: Simd>: Copy;
    fn lanes<S: Simd>() -> usize;
    fn splat<S: Simd>(s: S, x: Self) -> Self::V<S>;
    /// The first `lanes` entries of `a` (panics if `a` is shorter).
    fn load<S: Simd>(s: S, a: &[Self]) -> Self::V<S>;
    fn vadd<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vsub<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vmul<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vdiv<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    /// a·b + c (fused where the level has FMA; the scalar level has none and must not call libm's
    /// software fma).
    fn mul_add<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>, c: Self::V<S>) -> Self::V<S>;
    /// c − a·b.
    fn neg_mul_add<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>, c: Self::V<S>) -> Self::V<S>;
    fn vmax<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vmin<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    fn vlt<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::M<S>;
    fn vgt<S: Simd>(s: S, a: Self::V<S>, b: Self::V<S>) -> Self::M<S>;
    /// `m ? a : b` lane by lane.
    fn select<S: Simd>(s: S, m: Self::M<S>, a: Self::V<S>, b: Self::V<S>) -> Self::V<S>;
    /// Lanes set in both masks.
    fn mand<S: Simd>(s: S, a: Self::M<S>, b: Self::M<S>) -> Self::M<S>;
    /// Whether any lane of the mask is set.
    fn many<S: Simd>(s: S, m: Self::M<S>) -> bool;
    /// The mask as bits, lane l at bit l.
    fn mbits<S: Simd>(s: S, m: Self::M<S>) -> u64;
    fn rsqrt<S: Simd>(s: S, x: Self::V<S>) -> Self::V<S>;
    /// The correctly rounded square root.
    fn vsqrt<S: Simd>(s: S, x: Self::V<S>) -> Self::V<S>;
    /// Sum of the lanes (a fixed pairwise order per level).
    fn sum<S: Simd>(s: S, a: Self::V<S>) -> Self;
}

macro_rules! float_impl {
    ($t:ty, $v:ident, $m:ident, $lanes:ident, $($op:ident = $f:ident),*) => {
        impl Float for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            #[inline(always)]
            fn of(x: f64) -> Self {
                x as $t
            }
            #[inline(always)]
            fn f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn pick(c: bool, a: Self, b: Self) -> Self {
                let m = opaque((c as u64).wrapping_neg());
                <$t>::from_bits((((a.to_bits() as u64) & m) | ((b.to_bits() as u64) & !m)) as _)
            }
            type V<S: Simd> = S::$v;
            type M<S: Simd> = S::$m;
            #[inline(always)]
            fn lanes<S: Simd>() -> usize {
                S::$lanes
            }
            #[inline(always)]
            fn load<S: Simd>(_: S, a: &[Self]) -> S::$v {
                pulp::bytemuck::pod_read_unaligned(pulp::bytemuck::cast_slice(&a[..S::$lanes]))
            }
            float_impl!(@ops $t, $v, $m, $($op = $f),*);
        }
    };
    (@ops $t:ty, $v:ident, $m:ident, splat = $splat:ident, add = $add:ident, sub = $sub:ident, mul = $mul:ident,
     div = $div:ident, fma = $fma:ident, fnma = $fnma:ident, max = $max:ident, min = $min:ident, lt = $lt:ident,
     gt = $gt:ident, select = $sel:ident, and = $and:ident, first = $first:ident, bits = $bits:ident, rsqrt = $rsqrt:ident, sqrt = $sqrt:ident, sum = $sum:ident) => {
        #[inline(always)]
        fn splat<S: Simd>(s: S, x: Self) -> S::$v {
            s.$splat(x)
        }
        #[inline(always)]
        fn vadd<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$add(a, b)
        }
        #[inline(always)]
        fn vsub<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$sub(a, b)
        }
        #[inline(always)]
        fn vmul<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$mul(a, b)
        }
        #[inline(always)]
        fn vdiv<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$div(a, b)
        }
        #[inline(always)]
        fn mul_add<S: Simd>(s: S, a: S::$v, b: S::$v, c: S::$v) -> S::$v {
            s.$fma(a, b, c)
        }
        #[inline(always)]
        fn neg_mul_add<S: Simd>(s: S, a: S::$v, b: S::$v, c: S::$v) -> S::$v {
            s.$fnma(a, b, c)
        }
        #[inline(always)]
        fn vmax<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$max(a, b)
        }
        #[inline(always)]
        fn vmin<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$v {
            s.$min(a, b)
        }
        #[inline(always)]
        fn vlt<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$m {
            s.$lt(a, b)
        }
        #[inline(always)]
        fn vgt<S: Simd>(s: S, a: S::$v, b: S::$v) -> S::$m {
            s.$gt(a, b)
        }
        #[inline(always)]
        fn select<S: Simd>(s: S, m: S::$m, a: S::$v, b: S::$v) -> S::$v {
            s.$sel(m, a, b)
        }
        #[inline(always)]
        fn mand<S: Simd>(s: S, a: S::$m, b: S::$m) -> S::$m {
            s.$and(a, b)
        }
        #[inline(always)]
        fn mbits<S: Simd>(s: S, m: S::$m) -> u64 {
            s.$bits(m)
        }
        #[inline(always)]
        fn many<S: Simd>(s: S, m: S::$m) -> bool {
            // pulp's first-true index is the lane count exactly when no lane is set (every level).
            s.$first(m) < <Self as Float>::lanes::<S>()
        }
        #[inline(always)]
        fn rsqrt<S: Simd>(s: S, x: S::$v) -> S::$v {
            s.$rsqrt(x)
        }
        #[inline(always)]
        fn vsqrt<S: Simd>(s: S, x: S::$v) -> S::$v {
            s.$sqrt(x)
        }
        #[inline(always)]
        fn sum<S: Simd>(s: S, a: S::$v) -> Self {
            s.$sum(a)
        }
    };
}

float_impl!(
    f64,
    f64s,
    m64s,
    F64_LANES,
    splat = splat_f64s,
    add = add_f64s,
    sub = sub_f64s,
    mul = mul_f64s,
    div = div_f64s,
    fma = mul_add_e_f64s,
    fnma = negate_mul_add_e_f64s,
    max = max_f64s,
    min = min_f64s,
    lt = less_than_f64s,
    gt = greater_than_f64s,
    select = select_f64s,
    and = and_m64s,
    first = first_true_m64s,
    bits = mask_bits_m64s,
    rsqrt = rsqrt_f64s,
    sqrt = sqrt_f64s,
    sum = reduce_sum_f64s
);
float_impl!(
    f32,
    f32s,
    m32s,
    F32_LANES,
    splat = splat_f32s,
    add = add_f32s,
    sub = sub_f32s,
    mul = mul_f32s,
    div = div_f32s,
    fma = mul_add_e_f32s,
    fnma = negate_mul_add_e_f32s,
    max = max_f32s,
    min = min_f32s,
    lt = less_than_f32s,
    gt = greater_than_f32s,
    select = select_f32s,
    and = and_m32s,
    first = first_true_m32s,
    bits = mask_bits_m32s,
    rsqrt = rsqrt_f32s,
    sqrt = sqrt_f32s,
    sum = reduce_sum_f32s
);

/// A SIMD vector of `F` with its token, so kernels read like scalar code (`a * b + c`). The token
/// is zero-sized: a `P` is just the register.
pub struct P<S: Simd, F: Float> {
    pub s: S,
    pub v: F::V<S>,
}

/// A lane mask of `P`.
pub struct Mask<S: Simd, F: Float>(pub F::M<S>);

impl<S: Simd, F: Float> Clone for P<S, F> {
    #[inline(always)]
    fn clone(&self) -> Self {
        *self
    }
}
impl<S: Simd, F: Float> Copy for P<S, F> {}
impl<S: Simd, F: Float> Clone for Mask<S, F> {
    #[inline(always)]
    fn clone(&self) -> Self {
        *self
    }
}
impl<S: Simd, F: Float> Copy for Mask<S, F> {}

impl<S: Simd, F: Float> P<S, F> {
    #[inline(always)]
    pub fn lanes() -> usize {
        F::lanes::<S>()
    }
    #[inline(always)]
    pub fn splat(s: S, x: F) -> Self {
        P { s, v: F::splat(s, x) }
    }
    #[inline(always)]
    pub fn zero(s: S) -> Self {
        Self::splat(s, F::ZERO)
    }
    /// `a[..lanes]` (panics if shorter).
    #[inline(always)]
    pub fn load(s: S, a: &[F]) -> Self {
        P { s, v: F::load(s, a) }
    }
    /// Lane l = f(l), for l < lanes (lane indices, odd gathers; see `Simd::gather_rows_f64s`).
    #[inline(always)]
    pub fn from_fn(s: S, mut f: impl FnMut(usize) -> F) -> Self {
        let mut buf = [F::ZERO; 16];
        for (l, b) in buf.iter_mut().enumerate().take(Self::lanes()) {
            *b = f(l);
        }
        Self::load(s, &buf)
    }
    /// Writes the lanes over `dst[..lanes]` (panics if shorter).
    #[inline(always)]
    pub fn store(self, dst: &mut [F]) {
        let n = Self::lanes();
        let bytes: &mut [u8] = pulp::bytemuck::cast_slice_mut(&mut dst[..n]);
        bytes.copy_from_slice(pulp::bytemuck::bytes_of(&self.v));
    }
    /// Lanes as an array (first `lanes` entries used).
    #[inline(always)]
    pub fn to_array(self) -> [F; 16] {
        let mut buf = [F::ZERO; 16];
        let n = Self::lanes();
        let bytes: &mut [u8] = pulp::bytemuck::cast_slice_mut(&mut buf[..n]);
        bytes.copy_from_slice(pulp::bytemuck::bytes_of(&self.v));
        buf
    }
    /// self·b + c.
    #[inline(always)]
    pub fn mul_add(self, b: Self, c: Self) -> Self {
        P { s: self.s, v: F::mul_add(self.s, self.v, b.v, c.v) }
    }
    /// c − self·b.
    #[inline(always)]
    pub fn neg_mul_add(self, b: Self, c: Self) -> Self {
        P { s: self.s, v: F::neg_mul_add(self.s, self.v, b.v, c.v) }
    }
    #[inline(always)]
    pub fn max(self, o: Self) -> Self {
        P { s: self.s, v: F::vmax(self.s, self.v, o.v) }
    }
    #[inline(always)]
    pub fn min(self, o: Self) -> Self {
        P { s: self.s, v: F::vmin(self.s, self.v, o.v) }
    }
    #[inline(always)]
    pub fn lt(self, o: Self) -> Mask<S, F> {
        Mask(F::vlt(self.s, self.v, o.v))
    }
    #[inline(always)]
    pub fn gt(self, o: Self) -> Mask<S, F> {
        Mask(F::vgt(self.s, self.v, o.v))
    }
    /// 1/√self (see `Simd::rsqrt_f64s`; unspecified at 0).
    #[inline(always)]
    pub fn rsqrt(self) -> Self {
        P { s: self.s, v: F::rsqrt(self.s, self.v) }
    }
    /// 1/√self for a loop that does much else per value and leaves the divider idle (spring
    /// forces: gathers, projections, dashpots): the square root and division where the level
    /// asks for it (`Simd::DIVIDER_IN_LOOPS`), else the estimate. Cloth 128² on Zen 3 at avx2:
    /// 39 → 48 M particle-steps/s (3 alternating runs each); the divider's ~13 cycles per vector
    /// stay under the ~40 the rest of a spring slot takes.
    #[inline(always)]
    pub fn rsqrt_in_loop(self) -> Self {
        if S::DIVIDER_IN_LOOPS {
            self.rsqrt_exact()
        } else {
            self.rsqrt()
        }
    }
    /// √self in such a loop: the square root where the level asks for it, else self · 1/√self.
    #[inline(always)]
    pub fn sqrt_in_loop(self) -> Self {
        if S::DIVIDER_IN_LOOPS {
            self.sqrt()
        } else {
            self * self.rsqrt()
        }
    }
    /// (√self, 1/√self) in such a loop: a square root and a division where the level asks for
    /// it, else the estimate y and (self · y, y).
    #[inline(always)]
    pub fn sqrt_and_rsqrt_in_loop(self) -> (Self, Self) {
        if S::DIVIDER_IN_LOOPS {
            let r = self.sqrt();
            (r, Self::splat(self.s, F::ONE) / r)
        } else {
            let y = self.rsqrt();
            (self * y, y)
        }
    }
    /// The correctly rounded square root.
    #[inline(always)]
    pub fn sqrt(self) -> Self {
        P { s: self.s, v: F::vsqrt(self.s, self.v) }
    }
    /// 1/√self as a correctly rounded square root and a division: the divider, not the FMA
    /// units (see `Simd::SPLIT_RSQRT`).
    #[inline(always)]
    pub fn rsqrt_exact(self) -> Self {
        Self::splat(self.s, F::ONE) / self.sqrt()
    }
    #[inline(always)]
    pub fn sum(self) -> F {
        F::sum(self.s, self.v)
    }
}

impl<S: Simd, F: Float> Mask<S, F> {
    /// Lanes set in both.
    #[inline(always)]
    pub fn and(self, s: S, o: Self) -> Self {
        Mask(F::mand(s, self.0, o.0))
    }
    /// Whether any lane is set.
    #[inline(always)]
    pub fn any(self, s: S) -> bool {
        F::many(s, self.0)
    }
    /// The lanes as bits: lane l at bit l.
    #[inline(always)]
    pub fn bits(self, s: S) -> u64 {
        F::mbits(s, self.0)
    }
    /// `self ? a : b`.
    #[inline(always)]
    pub fn select(self, a: P<S, F>, b: P<S, F>) -> P<S, F> {
        P { s: a.s, v: F::select(a.s, self.0, a.v, b.v) }
    }
}

macro_rules! binop {
    ($tr:ident, $m:ident, $f:ident) => {
        impl<S: Simd, F: Float> $tr for P<S, F> {
            type Output = Self;
            #[inline(always)]
            fn $m(self, o: Self) -> Self {
                P { s: self.s, v: F::$f(self.s, self.v, o.v) }
            }
        }
    };
}
binop!(Add, add, vadd);
binop!(Sub, sub, vsub);
binop!(Mul, mul, vmul);
binop!(Div, div, vdiv);

#[cfg(test)]
mod tests {
    use super::*;

    struct Rsqrt<'a, F: Float>(&'a [F], &'a mut [F]);
    impl<F: Float> Kernel for Rsqrt<'_, F> {
        type Output = ();
        #[inline(always)]
        fn run<S: Simd>(self, s: S) {
            let l = P::<S, F>::lanes();
            for (x, y) in self.0.chunks_exact(l).zip(self.1.chunks_exact_mut(l)) {
                let r = P::<S, F>::load(s, x).rsqrt().to_array();
                y.copy_from_slice(&r[..l]);
            }
        }
    }

    /// x over 600 decades (f64) / 70 (f32), including the f32 range limits that the AVX2 f64 path
    /// must route around.
    fn inputs<F: Float>(lo: i32, hi: i32) -> Vec<F> {
        let mut v = Vec::new();
        let mut e = lo as f64;
        while e < hi as f64 {
            for m in [1.0, 1.37, 2.0, 3.99, 7.1] {
                v.push(F::of(m * 10f64.powf(e)));
            }
            e += 0.37;
        }
        v.resize(v.len().div_ceil(16) * 16, F::ONE);
        v
    }

    #[test]
    fn rsqrt_is_accurate_on_every_available_level() {
        for level in Level::available() {
            // 1/√0 = inf and 1/√inf = 0 at every level, as on the scalar one (forces at overflowing
            // distances are then 0 everywhere, not NaN on some levels).
            // (The other lanes are finite: the accuracy checks below cover them.)
            let mut x = vec![0.0, f64::INFINITY];
            x.resize(16, 4.0);
            let mut y = vec![1.0; x.len()];
            dispatch(level, Rsqrt(&x, &mut y));
            assert_eq!(y[..2], [f64::INFINITY, 0.0], "{level:?} f64 special values");
            let mut x = vec![0.0f32, f32::INFINITY];
            x.resize(16, 4.0);
            let mut y = vec![1.0f32; x.len()];
            dispatch(level, Rsqrt(&x, &mut y));
            assert_eq!(y[..2], [f32::INFINITY, 0.0], "{level:?} f32 special values");
            let x = inputs::<f64>(-300, 300);
            let mut y = vec![0.0; x.len()];
            dispatch(level, Rsqrt(&x, &mut y));
            for (a, b) in x.iter().zip(&y) {
                let exact = 1.0 / a.sqrt();
                assert!(
                    ((b - exact) / exact).abs() < 4.0 * f64::EPSILON,
                    "{level:?} f64 rsqrt({a:e}) = {b:e}, want {exact:e}"
                );
            }
            let x = inputs::<f32>(-36, 37);
            let mut y = vec![0.0f32; x.len()];
            dispatch(level, Rsqrt(&x, &mut y));
            for (a, b) in x.iter().zip(&y) {
                let exact = 1.0 / (*a as f64).sqrt();
                assert!(
                    ((*b as f64 - exact) / exact).abs() < 4.0 * f32::EPSILON as f64,
                    "{level:?} f32 rsqrt({a:e}) = {b:e}"
                );
            }
        }
    }

    /// Rows `idx` by the hardware gather (`Some(true)`), lane by lane (`Some(false)`) or as the
    /// consecutive rows from `idx[0]` (`None`, `load_rows_f64s`).
    struct Gather<'a>(&'a [f64], &'a [f64], usize, &'a [u32], Option<bool>);
    impl Kernel for Gather<'_> {
        type Output = Vec<f64>;
        #[inline(always)]
        fn run<S: Simd>(self, s: S) -> Vec<f64> {
            let Gather(a, b, dim, idx, hw) = self;
            let (ra, rb) = match hw {
                Some(true) => s.gather_rows_f64s_hw(a, b, dim, idx),
                Some(false) => s.gather_rows_f64s(a, b, dim, idx),
                None => s.load_rows_f64s(a, b, dim, idx[0] as usize),
            };
            let l = S::F64_LANES;
            ra.iter().chain(&rb).flat_map(|v| P::<S, f64> { s, v: *v }.to_array()[..l].to_vec()).collect()
        }
    }

    const S_MAX_LANES: usize = 8;

    /// Both row gathers and the consecutive row load give the rows asked for, at every level (the
    /// hardware gather is used only where it pays, so it must be exact everywhere).
    #[test]
    fn hardware_and_lane_gathers_agree_at_every_level() {
        for dim in [2, 3] {
            let n = 37;
            let a: Vec<f64> = (0..n * dim).map(|k| k as f64 * 1.5 + 0.25).collect();
            let b: Vec<f64> = (0..n * dim).map(|k| -(k as f64) * 0.75).collect();
            let idx: Vec<u32> = (0..8).map(|k| (k * 13 % n) as u32).collect();
            for level in Level::available() {
                let hw = dispatch(level, Gather(&a, &b, dim, &idx, Some(true)));
                let lanes = dispatch(level, Gather(&a, &b, dim, &idx, Some(false)));
                assert_eq!(hw, lanes, "{level:?} dim {dim}");
                // Consecutive rows, read whole where the level can, up to the arrays' last row.
                for first in [0, 5, n - S_MAX_LANES] {
                    let run: Vec<u32> = (first..first + S_MAX_LANES).map(|k| k as u32).collect();
                    let whole = dispatch(level, Gather(&a, &b, dim, &run, None));
                    assert_eq!(whole, dispatch(level, Gather(&a, &b, dim, &run, Some(false))), "{level:?} dim {dim}");
                }
                let l = hw.len() / 6;
                for (k, &i) in idx[..l].iter().enumerate() {
                    for c in 0..dim {
                        assert_eq!(hw[c * l + k], a[i as usize * dim + c]);
                        assert_eq!(hw[(3 + c) * l + k], b[i as usize * dim + c]);
                    }
                }
            }
        }
    }

    /// `Mask::bits` of `a < b` lane by lane, for f32 and f64.
    struct Bits<'a, F: Float>(&'a [F], &'a [F]);
    impl<F: Float> Kernel for Bits<'_, F> {
        type Output = Vec<u64>;
        #[inline(always)]
        fn run<S: Simd>(self, s: S) -> Vec<u64> {
            let l = P::<S, F>::lanes();
            let chunks = self.0.chunks_exact(l).zip(self.1.chunks_exact(l));
            chunks.map(|(a, b)| P::<S, F>::load(s, a).lt(P::load(s, b)).bits(s)).collect()
        }
    }

    /// Every level's mask bits are the lanes' comparisons, lane l at bit l, and no bit past the
    /// last lane is set (f64 and f32, random and all-set and none-set vectors).
    #[test]
    fn mask_bits_are_the_lanes_at_every_level() {
        fn check<F: Float>() {
            let mut seed = 11u64;
            let mut rnd = || {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                F::of((seed >> 11) as f64 / (1u64 << 53) as f64)
            };
            let mut a: Vec<F> = (0..16 * 40).map(|_| rnd()).collect();
            let mut b: Vec<F> = (0..16 * 40).map(|_| rnd()).collect();
            a[..16].fill(F::ZERO); // all set
            b[..16].fill(F::ONE);
            a[16..32].fill(F::ONE); // none set
            b[16..32].fill(F::ZERO);
            for level in Level::available() {
                let bits = dispatch(level, Bits(&a, &b));
                let l = a.len() / bits.len();
                for (v, &m) in bits.iter().enumerate() {
                    let want = (0..l).fold(0u64, |w, t| w | (((a[v * l + t] < b[v * l + t]) as u64) << t));
                    assert_eq!(m, want, "{level:?} vector {v} ({l} lanes)");
                }
            }
        }
        check::<f64>();
        check::<f32>();
    }

    #[test]
    fn level_names_round_trip_and_unsupported_levels_are_refused() {
        for l in Level::ALL {
            assert_eq!(Level::by_name(l.name()), Some(l));
        }
        assert!(Level::Scalar.supported());
        assert!(Level::available().contains(&Level::best()));
        #[cfg(target_arch = "x86_64")]
        assert!(set_level(Some(Level::Neon)).is_err());
        #[cfg(target_arch = "aarch64")]
        {
            assert!(set_level(Some(Level::Avx2)).is_err());
            // Every aarch64 CPU has NEON: the agreement tests do run the neon level there.
            assert_eq!(Level::best(), Level::Neon);
        }
    }
}
