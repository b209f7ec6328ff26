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
