use super::*;
use glam::DVec2;

/// A jittered square of `side²` particles `dx` apart (spacing × `squeeze`) on a floor of 3 wall
/// rows, with small random velocities.
fn scene(side: usize, dx: f64, squeeze: f64) -> (Vec<DVec2>, Vec<DVec2>, Vec<DVec2>) {
    let mut s = 7u64;
    let mut rnd = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let (mut x, mut v, mut w) = (vec![], vec![], vec![]);
    for k in 0..side * side {
        let (i, j) = ((k % side) as f64, (k / side) as f64);
        x.push(DVec2::new((i + 0.5 + 0.2 * rnd()) * dx * squeeze, (j + 0.5 + 0.2 * rnd()) * dx * squeeze));
        v.push(DVec2::new(0.1 * rnd(), 0.1 * rnd()));
    }
    for i in 0..side + 6 {
        for layer in 0..3 {
            w.push(DVec2::new((i as f64 - 2.5) * dx, -(layer as f64 + 0.5) * dx));
        }
    }
    (x, v, w)
}

fn params(dx: f64) -> DfsphParams {
    DfsphParams {
        h: 1.3 * dx,
        rho0: 1000.0,
        alpha: 0.05,
        c0: 20.0,
        kernel: KernelKind::CubicSpline,
        density_tol: 1e-3,
        divergence_tol: 1e-3,
        max_iterations: 100,
        cfl: 0.4,
        surface_tension: 0.0,
        adhesion: 0.0,
        relaxation: 1.0,
        smoothing: 1.3,
    }
}

/// The particle mass of spacing dx, the model of n such particles and a fresh solve of one
/// fluid over them with walls `w` of the same mass.
fn term(n: usize, w: &[DVec2], dx: f64) -> (f64, Model, Solver<DVec2>) {
    let m = 1000.0 * dx * dx;
    let model = Model { mass: vec![m; n], inv_mass: vec![1.0 / m; n], ..Default::default() };
    (m, model, Solver::new(0, n, params(dx), w.to_vec(), vec![m; w.len()]).unwrap())
}

/// ∇W and W of the cubic spline at smoothing length h, for the brute-force sums.
fn kernel(h: f64) -> (impl Fn(DVec2) -> DVec2, impl Fn(DVec2) -> f64) {
    let sigma = CubicSpline::sigma(h, 2);
    (
        move |d: DVec2| d * (sigma / (h * h) * CubicSpline::g(d.length() / h)),
        move |d: DVec2| sigma * CubicSpline::w(d.length() / h),
    )
}

/// Density, D_i and the wall gradient sums of the stored pairs against an O(N²) sum.
#[test]
fn the_build_matches_a_brute_force_sum() {
    let dx = 0.01;
    let (x, _, w) = scene(30, dx, 0.97);
    let n = x.len();
    let (m, model, mut t) = term(n, &w, dx);
    t.build(&x, &model);
    let (grad, wk) = kernel(t.p.h);
    for (k, &i) in t.grid.order.iter().enumerate() {
        let i = i as usize;
        let (mut rho, mut sum, mut sq, mut gw) = (0.0, DVec2::ZERO, 0.0, DVec2::ZERO);
        for j in 0..n {
            rho += m * wk(x[i] - x[j]);
            if j != i {
                let g = grad(x[i] - x[j]) * m;
                sum += g;
                sq += g.length_squared();
            }
        }
        for b in &w {
            rho += m * wk(x[i] - *b);
            gw += grad(x[i] - *b) * m;
        }
        let d = ((sum + gw * 2.0).dot(sum + gw) + sq).max(sq);
        let site = t.sites[k];
        assert!((t.rho[k] - rho).abs() <= 1e-12 * rho, "rho {} vs {rho}", t.rho[k]);
        assert!((site.gs - sum).length() <= 1e-9 * (sum.length() + 1e-3), "gs");
        assert!((site.gw - gw).length() <= 1e-9 * (gw.length() + sum.length() + 1e-3), "gw");
        assert!((site.dinv * d - 1.0).abs() <= 1e-9, "1/D {} vs {}", site.dinv, 1.0 / d);
    }
}

/// The stored pairs, densities and factors of one build at `level`, as bits.
fn build_bits<V: Vector>(t: &mut Solver<V>, x: &[V], model: &Model, level: simd::Level) -> Vec<u64> {
    t.build_at(x, model, level);
    let mut out = vec![];
    for p in &t.pairs {
        let end = *p.start.last().unwrap() as usize;
        out.extend(p.start.iter().map(|&s| s as u64));
        out.extend(p.j[..end].iter().map(|&j| j as u64));
        out.extend(p.g[..end].iter().flat_map(|g| (0..V::DIM).map(|c| g.comp(c).to_bits())));
    }
    for (s, r) in t.sites.iter().zip(&t.rho) {
        out.extend([s.dinv.to_bits(), r.to_bits(), s.inner as u64]);
        out.extend((0..V::DIM).flat_map(|c| [s.gw.comp(c).to_bits(), s.gs.comp(c).to_bits()]));
    }
    out
}

/// Every SIMD level this CPU has finds the same pairs and stores the same bits (2D with
/// walls, both kernels; 3D), as the scalar level does: DFSPH's results do not depend on the
/// machine's level.
#[test]
fn the_build_is_the_same_at_every_level() {
    let dx = 0.01;
    let (x, _, w) = scene(30, dx, 0.97);
    let (_, model, mut t) = term(x.len(), &w, dx);
    for kernel in [KernelKind::CubicSpline, KernelKind::WendlandC2] {
        t.p.kernel = kernel;
        let want = build_bits(&mut t, &x, &model, simd::Level::Scalar);
        for level in simd::Level::available() {
            assert!(build_bits(&mut t, &x, &model, level) == want, "{level:?} {kernel:?}");
        }
    }
    let mut s = 5u64;
    let mut rnd = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let x3: Vec<glam::DVec3> = (0..12 * 12 * 12)
        .map(|k| glam::DVec3::new((k % 12) as f64, (k / 12 % 12) as f64, (k / 144) as f64) * dx)
        .map(|p| p + glam::DVec3::new(rnd(), rnd(), rnd()) * 0.3 * dx)
        .collect();
    let m = 1000.0 * dx * dx * dx;
    let model3 = Model { mass: vec![m; x3.len()], inv_mass: vec![1.0 / m; x3.len()], ..Default::default() };
    let mut t3 = Solver::new(0, x3.len(), params(dx), vec![], vec![]).unwrap();
    let want = build_bits(&mut t3, &x3, &model3, simd::Level::Scalar);
    for level in simd::Level::available() {
        assert!(build_bits(&mut t3, &x3, &model3, level) == want, "3D {level:?}");
    }
}

/// One density solve on a compressed, moving block: the predicted density error of the
/// velocities it leaves (summed by brute force) is within the tolerance, the kinetic energy
/// it reports removed is the change of Σ ½ m |v|², and a second solve from the same state
/// gives the same bits.
#[test]
fn a_density_solve_reaches_its_tolerance() {
    let dx = 0.01;
    let (x, v0, w) = scene(24, dx, 0.985);
    let (n, p) = (x.len(), params(dx));
    let dt = 1e-3;
    let mut runs = vec![];
    for _ in 0..2 {
        let (m, model, mut t) = term(n, &w, dx);
        let mut v = v0.clone();
        t.build(&x, &model);
        let removed = t.project(Projection::Density, &x, &mut v, &model, dt, DVec2::ZERO);
        let ke = |v: &[DVec2]| v.iter().map(|u| 0.5 * m * u.length_squared()).sum::<f64>();
        assert!((removed - (ke(&v0) - ke(&v))).abs() <= 1e-9 * ke(&v0).max(1e-9));
        assert!(t.books.density_iterations >= 2 && t.books.unconverged == 0);
        // The predicted density by brute force at the new velocities.
        let (grad, wk) = kernel(p.h);
        let mut err = 0.0;
        for i in 0..n {
            let mut rho = w.iter().map(|b| m * wk(x[i] - *b)).sum::<f64>();
            let mut div = w.iter().map(|b| v[i].dot(grad(x[i] - *b) * m)).sum::<f64>();
            for j in 0..n {
                rho += m * wk(x[i] - x[j]);
                div += (v[i] - v[j]).dot(grad(x[i] - x[j]) * m);
            }
            err += (rho + dt * div - p.rho0).max(0.0);
        }
        let err = err / (n as f64 * p.rho0);
        assert!(err <= p.density_tol * (1.0 + 1e-9), "predicted error {err}");
        assert!((err - t.books.density_error).abs() <= 1e-9, "{err} vs {}", t.books.density_error);
        runs.push(v);
    }
    assert_eq!(runs[0], runs[1]);
}

/// Development timing (not a test of record): `cargo test --release -p physcore-core
/// dfsph::tests::time_the_passes -- --ignored --nocapture` times one build and one of each
/// pass (min and median of 31) on `scene(204, ..)`, or with `BENCH_DAM=DIR` on a saved state
/// of the 144-across dam break (spacing 1/144 m): `x.bin`, `v.bin`, `w.bin` in DIR, float64
/// (N, 2) row-major positions, velocities and wall points (numpy's `tofile` of
/// `scene.positions`, `scene.velocities`, `scene.boundary_points()`); `BENCH_THREADS` (2).
/// Prints a hash of the build's bits, to compare levels (`PHYSCORE_SIMD`) and binaries.
#[test]
#[ignore]
fn time_the_passes() {
    let read = |p: String| -> Vec<DVec2> {
        let b = std::fs::read(p).unwrap();
        b.chunks(16)
            .map(|c| {
                DVec2::new(
                    f64::from_le_bytes(c[..8].try_into().unwrap()),
                    f64::from_le_bytes(c[8..].try_into().unwrap()),
                )
            })
            .collect()
    };
    let ((x, v, w), dx) = match std::env::var("BENCH_DAM") {
        Ok(dir) => {
            ((read(format!("{dir}/x.bin")), read(format!("{dir}/v.bin")), read(format!("{dir}/w.bin"))), 1.0 / 144.0)
        }
        Err(_) => (scene(204, 0.01, 1.0), 0.01),
    };
    let n = x.len();
    let (_, model, mut t) = term(n, &w, dx);
    let threads = std::env::var("BENCH_THREADS").map_or(2, |s| s.parse().unwrap());
    let pool = std::sync::Arc::new(rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap());
    let mut f = vec![DVec2::ZERO; n];
    let reps = 31;
    let mut tm = vec![[0.0f64; 4]; reps];
    par::install(Some(&pool), || {
        for r in tm.iter_mut() {
            let c = Instant::now();
            t.build(&x, &model);
            r[0] = c.elapsed().as_secs_f64() * 1e3;
            t.gather_v(&v);
            t.k.resize(n, 0.0);
            t.ksum.resize(n, 0.0);
            let c = Instant::now();
            t.errors(Projection::Density, 1e-3);
            r[1] = c.elapsed().as_secs_f64() * 1e3;
            let c = Instant::now();
            t.apply(1e-3);
            r[2] = c.elapsed().as_secs_f64() * 1e3;
            let c = Instant::now();
            t.add_forces(&x, &v, &model, &mut f, Write::Overwrite);
            r[3] = c.elapsed().as_secs_f64() * 1e3;
        }
    });
    let pairs: usize = t.pairs.iter().map(|p| *p.start.last().unwrap() as usize).sum();
    let hash = build_bits(&mut t, &x, &model, simd::level()).iter().fold(0u64, |h, b| h.rotate_left(5) ^ b);
    let med = |k: usize| {
        let mut a: Vec<f64> = tm.iter().map(|r| r[k]).collect();
        a.sort_by(|a, b| a.partial_cmp(b).unwrap());
        (a[0], a[a.len() / 2])
    };
    println!("hash {hash:016x} level {:?}", simd::level());
    println!(
        "n {n} pairs {pairs}: build {:.3?} errors {:.3?} apply {:.3?} forces {:.3?} ms (min, median of {reps})",
        med(0),
        med(1),
        med(2),
        med(3)
    );
}

/// Fluids with the same settings join one solve through `Shared` (walls given to both counted
/// once); another rest density, or overlapping particles, stay apart; one step of the split
/// solve is the same bits as one fluid over the same particles.
#[test]
fn fluids_with_the_same_settings_join_one_solve() {
    let dx = 0.01;
    let (x, v0, w) = scene(16, dx, 0.985);
    let n = x.len();
    let (m, model, _) = term(n, &w, dx);
    let psi = vec![m; w.len()];
    let mut shared = Shared::default();
    let half = n / 2;
    let mut a = Dfsph::new("a", 0, half, params(dx), w.clone(), psi.clone()).unwrap();
    let mut b = Dfsph::new("b", half, n - half, params(dx), w.clone(), psi.clone()).unwrap();
    a.join(&mut shared).unwrap();
    b.join(&mut shared).unwrap();
    assert_eq!((a.solve_size(), b.who), (2, 1));
    assert_eq!(a.solver().walls.grid.len(), w.len(), "the same tank counted once");
    let mut other = Dfsph::<DVec2>::new("c", n, 10, DfsphParams { rho0: 999.0, ..params(dx) }, vec![], vec![]).unwrap();
    other.join(&mut shared).unwrap();
    assert_eq!(other.solve_size(), 1);
    let mut overlap = Dfsph::<DVec2>::new("d", half - 1, 2, params(dx), vec![], vec![]).unwrap();
    overlap.join(&mut shared).unwrap();
    assert_eq!((overlap.solve_size(), a.solve_size()), (1, 2));

    let mut one = Dfsph::new("one", 0, n, params(dx), w.clone(), psi).unwrap();
    let dt = 1e-3;
    let run = |terms: &mut [&mut Dfsph<DVec2>]| {
        let mut v = v0.clone();
        let mut f = vec![DVec2::ZERO; n];
        let mut e = 0.0;
        for t in terms.iter_mut() {
            e += VelocityProjection::project(*t, Projection::Divergence, &x, &mut v, &model, dt, DVec2::ZERO);
        }
        for (k, t) in terms.iter_mut().enumerate() {
            let write = if k == 0 { Write::Overwrite } else { Write::Add };
            e += t.add_forces(&x, &v, &model, &mut f, write);
        }
        for (vi, fi) in v.iter_mut().zip(&f) {
            *vi += *fi * (dt / m);
        }
        for t in terms.iter_mut() {
            e += VelocityProjection::project(*t, Projection::Density, &x, &mut v, &model, dt, DVec2::ZERO);
        }
        (v, f, e)
    };
    let split = run(&mut [&mut a, &mut b]);
    let whole = run(&mut [&mut one]);
    assert_eq!(split, whole);
}
