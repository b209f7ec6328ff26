//! WCSPH throughput on the device (issue "GPU fluids, grains and batches": WCSPH 2D at 4M
//! particles ≥ 1.2e9 particle-steps/s, 3D at 1M ≥ 2.5e8 on an H100). Not a test: `#[ignore]`d,
//! run by `benches/gpu/device_check.sh` (`sph_bench-tests --ignored --nocapture`) and by hand:
//!
//!     PHYSCORE_SPH_BENCH=2d:65536,3d:32768 PHYSCORE_GPU_ALLOW_CPU=1 \
//!       cargo test --release -p physcore-gpu --test sph_bench -- --ignored --nocapture
//!
//! A dam break: a block of water (spacing 0.01 m, h = 1.3 dx, ρ0 = 1000, c0 = 20 m/s, α = 0.05,
//! cubic spline, Tait γ = 7 clamped) in the corner of a box twice its width, gravity 9.81, dt =
//! 5e-5 s; `PHYSCORE_SPH_BENCH` lists dim:count pairs (default 2d:4194304,3d:1048576), the
//! precision is `PHYSCORE_SPH_PRECISION` (default f32). A full step is the cell list's rebuild
//! (counting sort), the reorder, the density and the force passes, the update and the walls.
//! Reported: the median of 3 timed blocks of 20 steps after 5 steps of warm-up, each block
//! ending with the step's read-back (the finiteness flag), so the time is the device's.
use physcore_gpu::sph::{Kernel, Sph, SphParams};
use physcore_gpu::Precision;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

mod common;

fn dam(dim: usize, count: usize) -> (SphParams, Vec<f64>, Vec<f64>) {
    let dx = 0.01;
    // A block `side` wide and `2 side` tall (2D) or `side × side × side` (3D), near `count`.
    let (nx, ny, nz) = if dim == 2 {
        let side = ((count as f64 / 2.0).sqrt().round() as usize).max(1);
        (side, 2 * side, 1)
    } else {
        let side = (count as f64).cbrt().round() as usize;
        (side, side, side)
    };
    let mut x = Vec::with_capacity(dim * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let p = [i, j, k];
                x.extend((0..dim).map(|a| (p[a] as f64 + 0.5) * dx));
            }
        }
    }
    let v = vec![0.0; x.len()];
    let w = |n: usize| 2.0 * n as f64 * dx;
    let upper = if dim == 2 { [w(nx), w(ny), 0.0] } else { [w(nx), w(ny), w(nz)] };
    let gravity = if dim == 2 { [0.0, -9.81, 0.0] } else { [0.0, 0.0, -9.81] };
    let h = 1.3 * dx;
    let mass = 1000.0 * dx.powi(dim as i32);
    let p = SphParams {
        dim,
        h,
        mass,
        rho0: 1000.0,
        c0: 20.0,
        gamma: 7,
        alpha: 0.05,
        clamp: true,
        kernel: Kernel::CubicSpline,
        gravity,
        lower: [0.0; 3],
        upper,
        restitution: 0.0,
        friction: 0.0,
    };
    (p, x, v)
}

#[test]
#[ignore = "a benchmark: run with --ignored"]
fn wcsph_throughput() {
    let Some(gpu) = common::gpu() else { return };
    let list = std::env::var("PHYSCORE_SPH_BENCH").unwrap_or_else(|_| "2d:4194304,3d:1048576".into());
    let precision = match std::env::var("PHYSCORE_SPH_PRECISION").as_deref() {
        Ok("f64") => Precision::F64,
        _ => Precision::F32,
    };
    let a = gpu.adapter();
    println!("adapter: {} ({}, {}, driver {})", a.name, a.backend, a.kind, a.driver);
    for item in list.split(',') {
        let (d, n) = item.split_once(':').expect("dim:count");
        let dim: usize = d.trim_end_matches('d').parse().expect("2d or 3d");
        let (p, x, v) = dam(dim, n.parse().expect("a count"));
        let count = x.len() / dim;
        let built = Instant::now();
        let mut fluid = match Sph::new(gpu.clone(), precision, p, &x, &v) {
            Ok(f) => f,
            Err(e) => {
                println!("WCSPH {dim}D {count} {precision:?}: not run: {e}");
                continue;
            }
        };
        let setup = built.elapsed().as_secs_f64();
        let no = AtomicBool::new(false);
        let dt = 5e-5;
        fluid.step(5, dt, &no).expect("warm-up");
        let mut times = Vec::new();
        for _ in 0..3 {
            let t = Instant::now();
            fluid.step(20, dt, &no).expect("steps");
            times.push(t.elapsed().as_secs_f64() / 20.0);
        }
        times.sort_by(f64::total_cmp);
        let per = times[1];
        println!(
            "WCSPH {dim}D {count} particles {precision:?} cells {:?}: {:.3} ms a step, {:.3e} particle-steps/s (setup {setup:.2} s)",
            fluid.cells(),
            per * 1e3,
            count as f64 / per
        );
    }
}

/// The step limit's maxima (`extremes`: reduced on the device, 16 bytes read back) against the
/// host's from a read-back of every velocity and squared acceleration
/// (`extremes_from_read_back`), on a dam of `PHYSCORE_SPH_MAXIMA_BENCH` particles (default
/// 100000) after 5 steps, 2D and 3D, f32 and f64 (where the adapter has it): the median of 15
/// calls of each, alternating, and their results compared bit for bit.
#[test]
#[ignore = "a benchmark: run with --ignored"]
fn step_limit_maxima() {
    let Some(gpu) = common::gpu() else { return };
    let count: usize = std::env::var("PHYSCORE_SPH_MAXIMA_BENCH").map_or(100_000, |c| c.parse().expect("a count"));
    let a = gpu.adapter();
    println!("adapter: {} ({}, {}, driver {})", a.name, a.backend, a.kind, a.driver);
    for precision in [Precision::F32, Precision::F64] {
        if gpu.check_precision(precision).is_err() {
            continue;
        }
        for dim in [2, 3] {
            let (p, x, v) = dam(dim, count);
            let mut fluid = Sph::new(gpu.clone(), precision, p, &x, &v).expect("upload");
            fluid.step(5, 5e-5, &AtomicBool::new(false)).expect("steps");
            let (mut device, mut host) = (Vec::new(), Vec::new());
            for _ in 0..15 {
                let t = Instant::now();
                let d = fluid.extremes().unwrap();
                device.push(t.elapsed().as_secs_f64());
                let t = Instant::now();
                let h = fluid.extremes_from_read_back().unwrap();
                host.push(t.elapsed().as_secs_f64());
                assert_eq!((d.0.to_bits(), d.1.to_bits()), (h.0.to_bits(), h.1.to_bits()));
            }
            device.sort_by(f64::total_cmp);
            host.sort_by(f64::total_cmp);
            println!(
                "WCSPH {dim}D {} particles {precision:?}: extremes {:.3} ms on the device, {:.3} ms from a read-back",
                fluid.len(),
                device[7] * 1e3,
                host[7] * 1e3
            );
        }
    }
}
