//! The device Gray–Scott step against an f64 reference on the host (periodic and free faces, 2D
//! and 3D, a grid of more than one workgroup row, blocks of 4, 8 and 16 rows that cross planes). Skips without an adapter unless
//! `PHYSCORE_GPU_REQUIRED=1` (CI, on lavapipe).
use physcore_gpu::gray_scott::{GrayScott, Halt, Model};
use physcore_gpu::Precision;
use std::sync::atomic::AtomicBool;

mod common;
use common::gpu;

/// One forward Euler step on the host (Pearson's scheme), returning Σ reaction of u and v.
fn host_step(m: &Model, u: &mut Vec<f64>, v: &mut Vec<f64>, dt: f64) -> [f64; 2] {
    let [nx, ny, nz] = m.n;
    let at = |i: isize, n: usize, lo: usize| -> usize {
        if i < 0 {
            if m.free[lo] {
                0
            } else {
                n - 1
            }
        } else if i as usize >= n {
            if m.free[lo + 1] {
                n - 1
            } else {
                0
            }
        } else {
            i as usize
        }
    };
    let (mut un, mut vn) = (u.clone(), v.clone());
    let mut sums = [0.0; 2];
    let (du, dv) = (dt * m.du / (m.dx * m.dx), dt * m.dv / (m.dx * m.dx));
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let c = i + nx * (j + ny * k);
                let idx = |a: usize, b: usize, d: usize| a + nx * (b + ny * d);
                let (ii, jj, kk) = (i as isize, j as isize, k as isize);
                let nb = [
                    idx(at(ii - 1, nx, 0), j, k),
                    idx(at(ii + 1, nx, 0), j, k),
                    idx(i, at(jj - 1, ny, 2), k),
                    idx(i, at(jj + 1, ny, 2), k),
                ];
                let centre = 2.0 * m.dim as f64;
                let mut lu = u[nb[0]] + u[nb[1]] + u[nb[2]] + u[nb[3]] - centre * u[c];
                let mut lv = v[nb[0]] + v[nb[1]] + v[nb[2]] + v[nb[3]] - centre * v[c];
                if m.dim == 3 {
                    let (d, t) = (idx(i, j, at(kk - 1, nz, 4)), idx(i, j, at(kk + 1, nz, 4)));
                    lu += u[d] + u[t];
                    lv += v[d] + v[t];
                }
                let uvv = u[c] * v[c] * v[c];
                let ru = m.feed * (1.0 - u[c]) - uvv;
                let rv = uvv - (m.feed + m.kill) * v[c];
                un[c] = u[c] + du * lu + dt * ru;
                vn[c] = v[c] + dv * lv + dt * rv;
                sums[0] += ru;
                sums[1] += rv;
            }
        }
    }
    *u = un;
    *v = vn;
    sums
}

fn seeded(m: &Model) -> (Vec<f64>, Vec<f64>) {
    let cells: usize = m.n.iter().product();
    let mut s = 0x9e3779b97f4a7c15u64;
    let mut r = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let u = (0..cells).map(|_| 0.5 + 0.5 * r()).collect();
    let v = (0..cells).map(|_| 0.25 * r()).collect();
    (u, v)
}

#[test]
fn gray_scott_steps_as_the_host_reference() {
    let Some(g) = gpu() else { return };
    let no = AtomicBool::new(false);
    let cases = [
        // 2D periodic, a row longer than a workgroup.
        Model { n: [300, 7, 1], dim: 2, dx: 0.01, free: [false; 6], du: 2e-5, dv: 1e-5, feed: 0.035, kill: 0.065 },
        // 2D with free x faces, periodic y.
        Model {
            n: [17, 23, 1],
            dim: 2,
            dx: 0.01,
            free: [true, true, false, false, false, false],
            du: 2e-5,
            dv: 1e-5,
            feed: 0.03,
            kill: 0.06,
        },
        // 3D, free z only.
        Model {
            n: [9, 8, 7],
            dim: 3,
            dx: 0.01,
            free: [false, false, false, false, true, true],
            du: 2e-5,
            dv: 1e-5,
            feed: 0.035,
            kill: 0.065,
        },
        // 3D with 5 rows a plane: a workgroup's block of 4 rows crosses planes (free y, periodic
        // z), and a row longer than a workgroup.
        Model {
            n: [70, 5, 3],
            dim: 3,
            dx: 0.01,
            free: [false, false, true, true, false, false],
            du: 2e-5,
            dv: 1e-5,
            feed: 0.035,
            kill: 0.065,
        },
    ];
    for m in cases {
        let dt = 0.5;
        let (u0, v0) = seeded(&m);
        let (mut hu, mut hv) = (u0.clone(), v0.clone());
        let mut made = [0.0; 2];
        let steps = 25;
        for _ in 0..steps {
            let s = host_step(&m, &mut hu, &mut hv, dt);
            made[0] += dt * s[0];
            made[1] += dt * s[1];
        }
        let cells = m.n.iter().product::<usize>() as u64;
        // Blocks of 4 rows (these grids' own), 8 and 16 (a large grid's: grid::rows_for), each
        // against the same host run; the fields do not depend on the blocks, the books' sums
        // only in their order.
        for (p, threads) in
            [Precision::F32, Precision::F64].into_iter().flat_map(|p| [(p, 1 << 19), (p, cells / 8), (p, 1)])
        {
            if g.check_precision(p).is_err() {
                continue;
            }
            physcore_gpu::set_grid_threads_for_tests(threads);
            let mut d = GrayScott::new(g.clone(), p, m, &u0, &v0, [0.0, 0.0]).unwrap();
            // Odd counts: the buffers swap on odd submissions.
            d.step(3, dt, &no).unwrap();
            d.step(steps - 3, dt, &no).unwrap();
            let (du, dv) = d.read().unwrap();
            let err = du.iter().zip(&hu).chain(dv.iter().zip(&hv)).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            let dm = d.made().unwrap();
            let merr = (dm[0] - made[0]).abs().max((dm[1] - made[1]).abs()) / made[0].abs().max(made[1].abs());
            eprintln!("{:?} {} ({threads} threads' rows): fields {err:.1e}, books {merr:.1e}", m.n, p.name());
            let (tf, tm) = if p == Precision::F32 { (1e-5, 1e-5) } else { (1e-13, 1e-12) };
            assert!(err < tf, "{:?} {}: fields differ by {err}", m.n, p.name());
            assert!(merr < tm, "{:?} {}: books differ by {merr}", m.n, p.name());
            // Rollback to a snapshot and bit-identical repetition.
            d.snapshot().unwrap();
            d.step(5, dt, &no).unwrap();
            let once = d.read().unwrap();
            d.restore().unwrap();
            assert_eq!(d.read().unwrap(), (du.clone(), dv.clone()));
            d.step(5, dt, &no).unwrap();
            assert_eq!(d.read().unwrap(), once);
        }
    }
}

#[test]
fn a_diverging_grid_names_the_cell_and_a_stop_is_seen() {
    let Some(g) = gpu() else { return };
    let m = Model { n: [16, 16, 1], dim: 2, dx: 0.01, free: [false; 6], du: 2e-5, dv: 1e-5, feed: 0.035, kill: 0.065 };
    let (u, mut v) = seeded(&m);
    v[37] = 1e30;
    let mut d = GrayScott::new(g.clone(), Precision::F32, m, &u, &v, [0.0, 0.0]).unwrap();
    match d.step(50, 0.5, &AtomicBool::new(false)) {
        Err((_, Halt::Diverged { cell })) => assert!(cell < 256, "{cell}"),
        other => panic!("expected a divergence, got {other:?}"),
    }
    let mut d = GrayScott::new(g, Precision::F32, m, &u, &u, [0.0, 0.0]).unwrap();
    assert!(matches!(d.step(10, 0.5, &AtomicBool::new(true)), Err((0, Halt::Stopped))));
}
