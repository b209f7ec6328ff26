//! The step limit's maxima reduced on the device (`maxima.wgsl`): the largest squared speed of
//! a particle state and, if asked, the largest of one more real per particle (WCSPH's squared
//! acceleration). The fluids' time step limits read these once per substep; reduced here, 16
//! bytes come back instead of every velocity.
//!
//! Each workgroup of 1024 particles (64 threads of 16) reduces its maxima in workgroup memory
//! and writes one pair; one workgroup then reduces those pairs. |v|² is computed in integer
//! arithmetic on the values' bits, in f64 whatever the state's precision, operation for
//! operation as the host computes it from a read-back (`u.iter().map(|c| c * c).sum::<f64>()`
//! over the widened components): the maxima equal the host's bit for bit on any driver
//! (whether it fuses multiply-adds or flushes subnormals), and a NaN counts as 0 as the host's
//! fold from 0 with `f64::max` counts it. That arithmetic costs some hundred integer operations,
//! so it is done only for the particles that rigorous bounds from f32 leave as candidates for
//! their workgroup's maximum. No float atomics; the result is the same on every run.
use crate::{Bind, Gpu, GpuError, Precision, Result};

/// Particles per workgroup of `partial` (the shader's `WG` threads of `PER` each).
const PER_GROUP: u32 = 64 * 16;
/// `extra_at` when there is no extra real.
const NONE: u32 = u32::MAX;

/// The reduction over one particle state, its buffers and kernels.
pub(crate) struct Maxima {
    n: usize,
    /// Workgroups of `partial` along x and y (folded into y past 65,535).
    groups: (u32, u32),
    result: wgpu::Buffer,
    bind: wgpu::BindGroup,
    /// `partial`, `total`.
    pipes: Vec<wgpu::ComputePipeline>,
    /// The parameters and the partial maxima (bound only).
    _keep: [wgpu::Buffer; 2],
}

impl Maxima {
    /// The reduction over `n` particles of `dim` reals each in `vel` (at `precision`), and, if
    /// given, over `n` reals of `extra` from its real `at`.
    pub(crate) fn new(
        gpu: &Gpu,
        precision: Precision,
        n: usize,
        dim: usize,
        vel: &wgpu::Buffer,
        extra: Option<(&wgpu::Buffer, u64)>,
    ) -> Result<Self> {
        let wgs = (n as u32).div_ceil(PER_GROUP).max(1);
        let groups = (wgs.min(65_535), wgs.div_ceil(65_535));
        let slots = groups.0 as u64 * groups.1 as u64;
        use wgpu::BufferUsages as U;
        let params = gpu.buffer("maxima parameters", 16, U::UNIFORM | U::COPY_DST)?;
        let part = gpu.buffer("maxima per workgroup", 16 * slots, U::STORAGE)?;
        let result = gpu.buffer("maxima", 16, U::STORAGE | U::COPY_SRC)?;
        // A real is one word in f32, two in f64.
        let words = precision.bytes() / 4;
        let extra_at = match extra {
            Some((_, at)) => u32::try_from(at * words).ok().filter(|&w| w != NONE).ok_or_else(|| {
                GpuError::Unsupported(format!("the step limit's maxima index 32-bit words; real {at} is past them"))
            })?,
            None => NONE,
        };
        let ints = [n as u32, dim as u32, extra_at, slots as u32];
        gpu.queue.write_buffer(&params, 0, bytemuck::cast_slice(&ints));
        use Bind::{Read as R, ReadWrite as W, Uniform};
        let src = format!("const F64: bool = {};\n{}", precision == Precision::F64, include_str!("maxima.wgsl"));
        let (layout, pipes) = gpu.kernels(
            "maxima.wgsl",
            precision,
            &src,
            &[Uniform { dynamic: false }, R, R, W, W],
            &["partial", "total"],
        );
        let extra = extra.map_or(vel, |e| e.0);
        let bind = crate::grid::bind_group(gpu, "maxima", &layout, &[&params, vel, extra, &part, &result]);
        Ok(Self { n, groups, result, bind, pipes, _keep: [params, part] })
    }

    /// The largest |v|² (m²/s², as the host sums it in f64) and the largest extra real (0
    /// without one; widened to f64) now: the two passes, then 16 bytes read back through
    /// `staging`. (0, 0) for no particles.
    pub(crate) fn read(&self, gpu: &Gpu, precision: Precision, staging: &wgpu::Buffer) -> Result<(f64, f64)> {
        if self.n == 0 {
            return Ok((0.0, 0.0));
        }
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_bind_group(0, &self.bind, &[]);
            pass.set_pipeline(&self.pipes[0]);
            pass.dispatch_workgroups(self.groups.0, self.groups.1, 1);
            pass.set_pipeline(&self.pipes[1]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        gpu.queue.submit([enc.finish()]);
        let raw = gpu.read_back(&self.result, staging, 16)?;
        let w: Vec<u32> = raw.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
        let v2 = f64::from_bits((w[0] as u64) << 32 | w[1] as u64);
        let extra = match precision {
            Precision::F64 => f64::from_bits((w[2] as u64) << 32 | w[3] as u64),
            Precision::F32 => f64::from(f32::from_bits(w[3])),
        };
        Ok((v2, extra))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// A kernel appended to `maxima.wgsl` for this test: each particle's |v|² and extra value,
    /// unreduced, into `part`.
    const EACH: &str = "
@compute @workgroup_size(64)
fn each(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x < P.n) {
        part[gid.x] = vec4<u32>(speed2(gid.x), extra_of(gid.x));
    }
}
";

    fn gpu() -> Option<Arc<Gpu>> {
        let which = if crate::cpu_allowed_by_env() { "gpu" } else { "gpu:lavapipe" };
        match Gpu::open(which) {
            Ok(g) => Some(g),
            Err(e) if std::env::var("PHYSCORE_GPU_REQUIRED").as_deref() == Ok("1") => panic!("no adapter: {e}"),
            Err(e) => {
                eprintln!("skipped: {e}");
                None
            }
        }
    }

    /// A deterministic 64-bit value.
    fn mix(k: u64) -> u64 {
        let mut z = k.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Components that reach every branch of the arithmetic: ±∞, ±0, NaN, the extremes, any
    /// bit pattern (squares past the largest f64), values whose squares are about the smallest
    /// f64s (f64: 2^−1106 to 2^−986; f32: its subnormals), and values of a few significant bits
    /// in a narrow band of exponents, whose sums hit exact ties and sticky bits at the rounding
    /// position (exponents up to 60 apart). As bits of the precision.
    fn components(precision: Precision, count: usize) -> Vec<u64> {
        let special = [f64::INFINITY, -f64::INFINITY, 0.0, -0.0, f64::NAN, f64::MAX, f64::MIN_POSITIVE, 5e-324];
        (0..count as u64)
            .map(|k| {
                let r = mix(k);
                let s = mix(r);
                match (precision, k % 4) {
                    (Precision::F64, _) if k % 101 == 7 => special[(r % 8) as usize].to_bits(),
                    (Precision::F32, _) if k % 101 == 7 => {
                        let special = [f32::INFINITY, -f32::INFINITY, 0.0, -0.0, f32::NAN, f32::MAX, 1e-45, 1e-38];
                        special[(r % 8) as usize].to_bits() as u64
                    }
                    (Precision::F64, 0) => r,
                    (Precision::F32, 0) => r & 0xffff_ffff,
                    (Precision::F64, 1) => (r & 0x800f_ffff_ffff_ffff) | ((470 + s % 60) << 52),
                    (Precision::F32, 1) => (r & 0x807f_ffff) | ((s % 12) << 23),
                    (p, _) => {
                        // 1 to 27 leading significand bits, an exponent within 30 of 2^0.
                        let kept = 1 + s % 27;
                        let frac = (r >> (64 - kept)) << (52 - kept + 1);
                        let x = f64::from_bits(((1023 + (s >> 8) % 61 - 30) << 52) | (frac & ((1 << 52) - 1)));
                        match p {
                            Precision::F64 => x.to_bits(),
                            Precision::F32 => (x as f32).to_bits() as u64,
                        }
                    }
                }
            })
            .collect()
    }

    fn widen(precision: Precision, b: u64) -> f64 {
        match precision {
            Precision::F64 => f64::from_bits(b),
            Precision::F32 => f64::from(f32::from_bits(b as u32)),
        }
    }

    /// Each particle's |v|² from the device's integer arithmetic against the host's f64
    /// (`u.iter().map(|c| c * c).sum::<f64>()`), bit for bit, in 2D and 3D, f32 and f64; and
    /// the extra values passed through as the host's fold takes them (NaN and negative as 0).
    #[test]
    fn each_squared_speed_is_the_hosts_bit_for_bit() {
        let Some(gpu) = gpu() else { return };
        for precision in [Precision::F32, Precision::F64] {
            if gpu.check_precision(precision).is_err() {
                eprintln!("skipped {}: the adapter has no f64", precision.name());
                continue;
            }
            for dim in [2usize, 3] {
                let n = 40_000;
                let bits = components(precision, n * dim);
                let extra = components(precision, n);
                let words = |b: &[u64]| -> Vec<u8> {
                    match precision {
                        Precision::F64 => bytemuck::cast_slice(b).to_vec(),
                        Precision::F32 => b.iter().flat_map(|&w| (w as u32).to_le_bytes()).collect(),
                    }
                };
                use wgpu::BufferUsages as U;
                let st = U::STORAGE | U::COPY_DST | U::COPY_SRC;
                let rb = precision.bytes();
                let params = gpu.buffer("test parameters", 16, U::UNIFORM | U::COPY_DST).unwrap();
                let vel = gpu.buffer("test velocities", (n * dim) as u64 * rb, st).unwrap();
                let ext = gpu.buffer("test extra", n as u64 * rb, st).unwrap();
                let part = gpu.buffer("test per particle", 16 * n as u64, st).unwrap();
                let result = gpu.buffer("test result", 16, st).unwrap();
                let staging = gpu.buffer("test read-back", 16 * n as u64, U::MAP_READ | U::COPY_DST).unwrap();
                gpu.queue.write_buffer(&params, 0, bytemuck::cast_slice(&[n as u32, dim as u32, 0, 1]));
                gpu.queue.write_buffer(&vel, 0, &words(&bits));
                gpu.queue.write_buffer(&ext, 0, &words(&extra));
                let src = format!(
                    "const F64: bool = {};\n{}{EACH}",
                    precision == Precision::F64,
                    include_str!("maxima.wgsl")
                );
                use Bind::{Read as R, ReadWrite as W, Uniform};
                let (layout, pipes) =
                    gpu.kernels("maxima test", precision, &src, &[Uniform { dynamic: false }, R, R, W, W], &["each"]);
                let bind =
                    crate::grid::bind_group(&gpu, "maxima test", &layout, &[&params, &vel, &ext, &part, &result]);
                let mut enc = gpu.device.create_command_encoder(&Default::default());
                {
                    let mut pass = enc.begin_compute_pass(&Default::default());
                    pass.set_bind_group(0, &bind, &[]);
                    pass.set_pipeline(&pipes[0]);
                    pass.dispatch_workgroups((n as u32).div_ceil(64), 1, 1);
                }
                gpu.queue.submit([enc.finish()]);
                let raw = gpu.read_back(&part, &staging, 16 * n as u64).unwrap();
                let w: Vec<u32> = raw.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
                let (mut nan, mut inf, mut sub) = (0, 0, 0);
                for i in 0..n {
                    let u: Vec<f64> = bits[dim * i..dim * (i + 1)].iter().map(|&b| widen(precision, b)).collect();
                    let host = u.iter().map(|c| c * c).sum::<f64>();
                    let dev = f64::from_bits((w[4 * i] as u64) << 32 | w[4 * i + 1] as u64);
                    let same = if host.is_nan() { dev.is_nan() } else { dev.to_bits() == host.to_bits() };
                    assert!(
                        same,
                        "{} {dim}D particle {i}: v = {u:?}: host |v|² = {host:e} ({:#x}), device {dev:e} ({:#x})",
                        precision.name(),
                        host.to_bits(),
                        dev.to_bits()
                    );
                    nan += host.is_nan() as usize;
                    inf += host.is_infinite() as usize;
                    sub += host.is_subnormal() as usize;
                    let e = widen(precision, extra[i]);
                    let want = if e.is_nan() || e.is_sign_negative() { 0.0 } else { e };
                    let got = match precision {
                        Precision::F64 => f64::from_bits((w[4 * i + 2] as u64) << 32 | w[4 * i + 3] as u64),
                        Precision::F32 => f64::from(f32::from_bits(w[4 * i + 3])),
                    };
                    assert_eq!(got.to_bits(), want.to_bits(), "extra {i}: {e:e}");
                }
                // The cases were reached.
                assert!(nan > 0 && inf > 0, "{} {dim}D: {nan} NaN, {inf} infinite", precision.name());
                if precision == Precision::F64 {
                    assert!(sub > 0, "{dim}D: no subnormal |v|²");
                }
            }
        }
    }

    /// Upload of components given as f64 at `precision` (f32: rounded) into a buffer.
    fn upload(gpu: &Gpu, precision: Precision, v: &[f64]) -> wgpu::Buffer {
        use wgpu::BufferUsages as U;
        let b = gpu.buffer("test velocities", v.len() as u64 * precision.bytes(), U::STORAGE | U::COPY_DST).unwrap();
        gpu.upload(precision, &b, v);
        b
    }

    /// The whole reduction (the f32 bounds that spare the exact |v|², then the maxima) against
    /// the host's fold over every particle, where the bounds cannot tell the particles apart:
    /// 3D speeds equal but for the rounding of their sums (the components permuted and their
    /// signs flipped, in every workgroup), a fast particle among them, speeds below 2^−60 m/s
    /// alone, a NaN component beside a large one (its |v|² counts as 0, its other component
    /// must not hide the true maximum), components from 2^63 up, all at rest; 1000 particles
    /// and 1.
    #[test]
    fn the_reduced_maxima_are_the_hosts_where_the_bounds_cannot_tell() {
        let Some(gpu) = gpu() else { return };
        let perms = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
        for precision in [Precision::F32, Precision::F64] {
            if gpu.check_precision(precision).is_err() {
                continue;
            }
            let wide = |x: f64| match precision {
                Precision::F64 => x,
                Precision::F32 => x as f32 as f64,
            };
            // Three workgroups, the last in part.
            let n = 2500;
            let mut cases: Vec<(&str, Vec<f64>)> = Vec::new();
            // Components whose sums of squares round apart in some orders (magnitudes 2^−3
            // and 2^−4 below the first: the first sum may need more than 53 bits).
            let sums = |c: &[f64; 3]| -> std::collections::BTreeSet<u64> {
                perms.iter().map(|p| p.iter().map(|&a| c[a] * c[a]).sum::<f64>().to_bits()).collect()
            };
            let scale = [1.0, 1.0 / 8.0, 1.0 / 16.0];
            let triples = (0u64..)
                .map(|seed| {
                    [0, 1, 2].map(|a| {
                        wide(scale[a] * f64::from_bits(0x3ff0_0000_0000_0000 | mix(3 * seed + a as u64) >> 12))
                    })
                })
                .filter(|c| sums(c).len() > 1)
                .take(6);
            for (seed, c) in triples.enumerate() {
                let seed = seed as u64;
                let near: Vec<f64> = (0..n)
                    .flat_map(|i| {
                        let p = perms[(mix(100 + i as u64) % 6) as usize];
                        (0..3).map(
                            move |a| if mix(7 * i as u64 + a as u64).is_multiple_of(2) { c[p[a]] } else { -c[p[a]] },
                        )
                    })
                    .collect();
                cases.push(("near ties", near.clone()));
                let mut fast = near;
                fast[3 * (mix(seed) % n as u64) as usize] *= 1.0 + 1e-6;
                cases.push(("near ties and a faster one", fast));
            }
            // Pairs whose f32 sums of squares (fused or not) order against their exact |v|²: the
            // bounds' margin must keep the larger.
            let inversions = (0u64..)
                .filter_map(|k| {
                    let bits = |j: u64| 0x3f00_0000 | (mix(j) as u32 & 0x7f_ffff);
                    let a = [f32::from_bits(bits(2 * k)), f32::from_bits(bits(2 * k + 1))];
                    let b = [f32::from_bits(a[0].to_bits() + 1), f32::from_bits(a[1].to_bits() - 1)];
                    let exact = |v: [f32; 2]| v.iter().map(|&c| f64::from(c) * f64::from(c)).sum::<f64>();
                    let (lo, hi) = if exact(a) < exact(b) { (a, b) } else { (b, a) };
                    let plain = |v: [f32; 2]| v[0] * v[0] + v[1] * v[1];
                    let fused = |v: [f32; 2]| v[1].mul_add(v[1], v[0] * v[0]);
                    let inverted = exact(lo) < exact(hi) && plain(hi) < plain(lo) && fused(hi) < fused(lo);
                    inverted.then_some((lo, hi))
                })
                .take(3);
            for (lo, hi) in inversions {
                let mut v: Vec<f64> = (0..3 * n as u64)
                    .map(|k| 0.1 * (f64::from_bits(mix(k) >> 12 | 0x3ff0_0000_0000_0000) - 1.5))
                    .collect();
                v[30..33].copy_from_slice(&[f64::from(lo[0]), f64::from(lo[1]), 0.0]);
                v[600..603].copy_from_slice(&[f64::from(hi[0]), -f64::from(hi[1]), 0.0]);
                cases.push(("an f32 sum ordered against the exact", v));
            }
            let tiny: Vec<f64> = (0..3 * n as u64)
                .map(|k| wide((f64::from_bits(mix(k) >> 12 | 0x3ff0_0000_0000_0000) - 1.5) * 2e-19))
                .collect();
            cases.push(("below 2^-60", tiny));
            let mut nan: Vec<f64> =
                (0..3 * n as u64).map(|k| wide(f64::from_bits(mix(k) >> 12 | 0x3ff0_0000_0000_0000) - 1.5)).collect();
            nan[3 * 300..3 * 301].copy_from_slice(&[f64::NAN, 4.0, 0.0]);
            cases.push(("a NaN beside a large component", nan.clone()));
            let mut big = nan;
            big[3 * 700 + 1] = wide(1.5e19);
            big[3 * 999 + 2] = f64::INFINITY;
            cases.push(("components from 2^63 up", big.clone()));
            big[3 * 999 + 2] = 0.0;
            cases.push(("components from 2^63 up, finite", big));
            cases.push(("at rest", vec![0.0; 3 * n]));
            cases.push(("one particle", vec![wide(0.3), wide(-0.4), wide(1e-30)]));
            for (what, v) in cases {
                let buf = upload(&gpu, precision, &v);
                let n = v.len() / 3;
                let m = Maxima::new(&gpu, precision, n, 3, &buf, None).unwrap();
                use wgpu::BufferUsages as U;
                let staging = gpu.buffer("test read-back", 16, U::MAP_READ | U::COPY_DST).unwrap();
                let (v2, extra) = m.read(&gpu, precision, &staging).unwrap();
                let host =
                    v.chunks_exact(3).map(|u| u.iter().map(|c| wide(*c) * wide(*c)).sum::<f64>()).fold(0.0, f64::max);
                assert_eq!(v2.to_bits(), host.to_bits(), "{} {what}: device {v2:e}, host {host:e}", precision.name());
                assert_eq!(extra, 0.0);
                if what.starts_with("near ties") {
                    // The permutations' sums round apart: the test can tell a wrong pick.
                    let sums: std::collections::BTreeSet<u64> = v
                        .chunks_exact(3)
                        .map(|u| u.iter().map(|c| wide(*c) * wide(*c)).sum::<f64>().to_bits())
                        .collect();
                    assert!(sums.len() > 1, "{} {what}: {} distinct sums", precision.name(), sums.len());
                }
            }
        }
    }
}
