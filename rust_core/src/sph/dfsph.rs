//! DFSPH: divergence-free SPH, Bender & Koschier, "Divergence-free SPH for incompressible and
//! viscous fluids", IEEE TVCG 23 (2017) 1193–1206 (Algorithms 1–3), as the term "dfsph": a fluid
//! whose pressure is not an equation of state but the solution of two velocity projections per
//! step, so its step follows the flow's CFL condition instead of the speed of sound.
//!
//! Per step of dt, at the step's positions x (`integrators/semi_implicit_euler.rs` runs them):
//! 1. neighbour search; ρ_i = Σ_j m_j W_ij + Σ_b Ψ_b W_ib (walls as in WCSPH, Akinci et al. 2012,
//!    eq. 4–5) and the DFSPH factor, here as 1/D_i with
//!    D_i = |Σ_j m_j ∇W_ij + Σ_b Ψ_b ∇W_ib|² + Σ_j |m_j ∇W_ij|² (paper eq. 9: α_i = ρ_i / D_i);
//! 2. divergence solve (Algorithm 3): Dρ_i/Dt = Σ_j m_j v_ij·∇W_ij + Σ_b Ψ_b v_i·∇W_ib, kept
//!    only where it compresses (> 0) and the neighbourhood is at least ~57 % full (a free-surface
//!    particle's divergence is not a compression); κ^v_i/ρ_i = (Dρ_i/Dt)/(dt D_i);
//! 3. non-pressure forces (the term's viscosity, gravity and other terms), kick v* = v + dt a;
//! 4. density solve (Algorithm 2): ρ*_i = ρ_i + dt Dρ_i/Dt(v*), error max(ρ*_i − ρ0, 0) (no
//!    tension at the free surface), κ_i/ρ_i = (ρ*_i − ρ0)/(dt² D_i);
//! 5. drift x += dt v*.
//!
//! Both solvers update all velocities at once (Jacobi) with
//! v_i −= dt [Σ_j m_j (κ_i/ρ_i + κ_j/ρ_j) ∇W_ij + (κ_i/ρ_i) Σ_b Ψ_b ∇W_ib]
//! (paper eq. 10–11, walls as Akinci 2012 eq. 10), and iterate until the mean error over the
//! fluid's particles is below the tolerance: mean(ρ* − ρ0)₊/ρ0 ≤ `density_tol` (paper: 0.01–0.1 %),
//! mean (Dρ/Dt)₊·dt/ρ0 ≤ `divergence_tol`. Warm starts (paper §4.4): each solve starts from
//! half the previous step's summed κ/ρ (`WARM_START`; κ/ρ = p/ρ² does not scale with dt) on
//! the particles that compress at the solve's start, and adds it to this step's sum: the
//! density solve applies it before its iterations, the divergence solve takes the larger of it
//! and the Jacobi κ/ρ in its first iteration (`WarmStart`: two passes fewer). Those sums
//! are the term's own state (`history`), so a restart or a rollback continues bit for bit.
//! (Only where it compresses: the solves are one-sided, so a push where nothing compresses any
//! more would expand the fluid and never be taken back: energy put in.)
//!
//! Non-pressure force: Monaghan (1992) artificial viscosity with the fluid's α and c0 (the same
//! term and coefficient as WCSPH, eq. in `sph/mod.rs`), which dissipates
//! ½ Σ_ij m_i m_j Π_ij v_ij·∇W_ij ≥ 0 at the velocities v.
//!
//! Surface tension and adhesion (optional): Akinci, Akinci & Teschner (2013), `sph::surface`,
//! from the stored pairs and the step's normals; their work on the fluid (surface energy
//! released, or stored when negative) is booked with the dissipation, so the books balance.
//! The term books its forces' work over the kick, −Σ_i F_i·(v_i + dt a_i/2) with a_i its own
//! acceleration: the kick's change of kinetic energy by these forces, which the density solve's
//! books then see (exact but for the cross terms m dt² a_i·a_other with the kick's other
//! forces, which vanish for pair forces under uniform gravity).
//!
//! Energy books: an incompressible fluid stores no internal energy (`potential` is 0). The
//! projections remove kinetic energy (they are inelastic: the velocity components that would
//! compress are taken out); what each removes is measured (the change of Σ ½ m |v|² across it)
//! and booked as the term's dissipation, with the viscosity's.
//!
//! Neighbours are stored per step, unlike the WCSPH passes: the solvers visit the same pairs
//! 2 × (iterations) times a step, so each pair's m_j ∇W_ij is computed once (with the density
//! and the factor) and kept with j, chunk by chunk of the sorted particles (`par::CHUNK`), so
//! every pass is a gather over stored pairs: no atomics, bit-identical for any thread count.
//! The build runs on the SIMD layer (`BuildChunk`) with the scalar operations lane by lane, and
//! the passes are scalar, so the results are also the same bits at every SIMD level.
use super::buffers::{PassFloat, WallArrays, Walls, PAD};
use super::kernels::{CubicSpline, Kernel, WendlandC2};
use super::params::{positive, KernelKind};
use super::surface::Surface;
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::neighbors::CellList;
use crate::par::{self, SyncPtr, CHUNK};
use crate::simd::{self, Kernel as SimdKernel, Simd, P};
use crate::state::Model;
use crate::stop::Stop;
use crate::terms::registry::{Context, Params};
use crate::terms::{OwnState, Projection, Term, VelocityProjection, Write};
use crate::vector::{Real, Vector};
use rayon::prelude::*;
use std::marker::PhantomData;
use std::ops::Range;
use std::time::Instant;

/// The share of the last step's summed κ/ρ each solve starts from (module doc). On the Martin &
/// Moyce dam break (20 particles across, T = 0..3) the whole sum made the density solve put in
/// 25 J that the divergence solve then took out (front 8 % fast); a half sum keeps both solves
/// dissipative and cut the density iterations from 3.3 to 2.3 a step against no warm start.
const WARM_START: Real = 0.5;

/// Where a solve applies its warm start (`Dfsph::solve`).
///
/// `Before` (paper, Algorithms 2 and 3): an error pass finds the particles that compress, a
/// velocity pass pushes them with w, then the iterations start: two passes over the pairs.
/// `FirstIteration`: the first iteration pushes each compressing particle with the larger of
/// its Jacobi κ/ρ and w (not their sum, which overshoots: the Jacobi κ/ρ is computed before the
/// warm push), and saves those two passes. Measured on the 41k dam break to T* = 4 (Zen 4,
/// 2 threads, runs alternated, medians of 3): folded into the divergence solve, 4.16 → 4.33
/// iterations a step in both solves but 14.3 → 12.7 passes over the pairs; solver 6.8 → 6.0 ms
/// a step and wall 22.7 → 21.2 s in one comparison, 7.6 → 7.3 ms and 24.4 → 24.2 s in a noisier
/// one; fronts within 0.4 %. Folded into the density solve too, 10.4 against 13.5 ms a step,
/// but a resting layer's jitter rose 0.40 → 0.62 J and a drop held by adhesion no longer
/// spread: the density solve keeps the paper's form.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum WarmStart {
    Before,
    FirstIteration,
}

/// DFSPH parameters, SI units.
#[derive(Clone, Copy, Debug)]
pub struct DfsphParams {
    /// Smoothing length h, m (support 2h).
    pub h: Real,
    /// Rest density ρ0, kg/m^dim.
    pub rho0: Real,
    /// Monaghan viscosity α (≥ 0) ...
    pub alpha: Real,
    /// ... and the speed c0 (m/s) it is scaled with (a pair's coefficient is α c0 h).
    pub c0: Real,
    pub kernel: KernelKind,
    /// Density solver tolerance: mean relative compression (0.001 = 0.1 %).
    pub density_tol: Real,
    /// Divergence solver tolerance: mean (Dρ/Dt)₊ dt / ρ0.
    pub divergence_tol: Real,
    /// Most iterations of each solve.
    pub max_iterations: u32,
    /// CFL number λ of the step limit λ h / |v|max.
    pub cfl: Real,
    /// Surface tension σ, N/m (N in 2D), ≥ 0 (Akinci et al. 2013, `sph::surface`).
    pub surface_tension: Real,
    /// Adhesion to the walls, half the work of adhesion, σ's units, ≥ 0.
    pub adhesion: Real,
}

impl DfsphParams {
    pub fn validate(&self) -> Result<()> {
        let pos = positive;
        pos(self.h, "h")?;
        pos(self.rho0, "density")?;
        pos(self.c0, "sound_speed")?;
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(invalid("viscosity", format!("{} must be finite and >= 0", self.alpha)));
        }
        for (v, a) in [(self.density_tol, "density_error"), (self.divergence_tol, "divergence_error")] {
            if !(v.is_finite() && v > 0.0 && v < 1.0) {
                return Err(invalid(a, format!("{v} must be in (0, 1) (a relative error; 0.001 = 0.1 %)")));
            }
        }
        if !(1..=100_000).contains(&self.max_iterations) {
            return Err(invalid("max_iterations", format!("{} must be in 1..=100000", self.max_iterations)));
        }
        if !(self.cfl.is_finite() && self.cfl > 0.0 && self.cfl <= 1.0) {
            return Err(invalid("cfl", format!("{} must be in (0, 1]", self.cfl)));
        }
        for (v, a) in [(self.surface_tension, "surface_tension"), (self.adhesion, "adhesion")] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(a, format!("{v} must be finite and >= 0")));
            }
        }
        Ok(())
    }
}

/// One sorted particle's own quantities of the step (its density is in `Dfsph::rho`, which the
/// pair passes read for neighbours too).
#[derive(Clone, Copy, Debug, Default)]
struct Site<V: Vector> {
    /// 1/D_i (0 for a particle without neighbours).
    dinv: Real,
    /// Σ_b Ψ_b ∇W_ib, kg/m^(dim+1).
    gw: V,
    /// Σ_j m_j ∇W_ij over the fluid pairs, kg/m^(dim+1): the passes split each pair's
    /// (v_i − v_j)·∇W and (κ_i + κ_j)∇W so that only the neighbour's part is summed per pair.
    gs: V,
    /// Whether its neighbourhood is full enough for the divergence solve.
    inner: bool,
}

/// The stored pairs of one chunk of sorted particles: particle `s + k`'s are
/// `j[start[k]..start[k + 1]]` with `g` = m_j ∇W_ij (`j` and `g` may run past the chunk's
/// last pair: the build keeps their length, `start` bounds them).
///
/// Tried and not kept for the solver passes (SPH-2D 41k, 2 threads): `g` in f32 (Zen 3: no
/// faster, 8.3–11.1 against 8.0–8.5 ms a step); on Zen 4 at avx512: one factor s_ij with
/// g = (x_i − x_j) s_ij (12 bytes a pair, not 20) and four partial sums, the same time; the
/// passes on the SIMD layer, the neighbours' v and κ gathered lane by lane or built in
/// registers (2–13 % slower: a gathered lane costs a load and an insert, what the scalar loop
/// spends on the whole pair). What did pay in the passes is fewer operations a pair
/// (`pair_sum`). The build is on the SIMD layer (`BuildChunk`).
#[derive(Clone, Debug, Default)]
struct Pairs<V: Vector> {
    start: Vec<u32>,
    j: Vec<u32>,
    g: Vec<V>,
}

impl<V: Vector> Pairs<V> {
    fn bytes(&self) -> usize {
        self.start.capacity() * 4 + self.j.capacity() * 4 + self.g.capacity() * std::mem::size_of::<V>()
    }
}

/// Totals of the solvers, over every step since the term was made (rolled-back steps
/// included).
#[derive(Clone, Copy, Debug, Default)]
struct Books {
    steps: u64,
    density_iterations: u64,
    divergence_iterations: u64,
    /// Solves that stopped at `max_iterations` above their tolerance.
    unconverged: u64,
    /// Final mean errors of the last solves, and the largest of all steps.
    density_error: Real,
    density_error_max: Real,
    divergence_error: Real,
    divergence_error_max: Real,
    /// Mean compression (ρ − ρ0)₊/ρ0 measured by summation at the start of the last step, and
    /// its largest value.
    measured: Real,
    measured_max: Real,
    /// Kinetic energy removed by each solver, J.
    dissipated_density: Real,
    dissipated_divergence: Real,
}

/// The DFSPH fluid over particles `first .. first + n` of a scene.
pub struct Dfsph<V: Vector> {
    name: String,
    first: usize,
    n: usize,
    p: DfsphParams,
    walls: Walls,
    grid: CellList,
    /// Sorted order: positions, masses, per-particle quantities, velocities, κ/ρ of the
    /// iteration and its sum over the solve.
    xs: Vec<V>,
    /// The sorted positions by component (the pair build's candidate test loads them a vector
    /// at a time), each with `PAD` entries of slack past the last particle.
    xc: [Vec<Real>; 3],
    m: Vec<Real>,
    /// Whether the particle is free (pinned ones, inverse mass 0, keep their velocity: the
    /// solves push on them as on a wall that moves).
    free: Vec<bool>,
    sites: Vec<Site<V>>,
    /// Densities, kg/m^dim.
    rho: Vec<Real>,
    vs: Vec<V>,
    k: Vec<Real>,
    ksum: Vec<Real>,
    pairs: Vec<Pairs<V>>,
    /// Whether the sorted data are those of the current step's positions (set by the
    /// divergence stage, cleared by the density stage).
    built: bool,
    /// Warm starts, particle order: Σκ/ρ of the last density solve and Σκ^v/ρ of the last
    /// divergence solve (m^(dim+2)/(kg s²), dt-free).
    kappa: Vec<Real>,
    kappa_v: Vec<Real>,
    /// Pressure p_i = ρ_i² (Σκ_i + Σκ^v_i) of the last step's solves, plus with surface tension
    /// the surface forces' virial (`surface_acceleration`), Pa, particle order.
    pressure: Vec<Real>,
    /// Neighbours per particle below which the divergence solve leaves it out.
    n_min: u32,
    /// Surface tension and adhesion (Akinci 2013), the normals n_i of the step and the virial
    /// pressure of the surface forces (Pa, added to `pressure`), sorted.
    surface: Surface,
    normals: Vec<V>,
    surface_p: Vec<Real>,
    /// The step of the kick that follows the divergence solve (set by it), s.
    kick_dt: Real,
    books: Books,
    /// Wall time (neighbours + pairs, solver iterations, the rest), s.
    clock: [f64; 3],
    stop: Stop,
}

fn build<V: Vector>(name: String, mut p: Params, ctx: &Context) -> Result<Box<dyn Term<V>>> {
    let (first, n) = super::fluid::particles(&p, ctx)?;
    let iters = p.number("max_iterations")?;
    if iters.fract() != 0.0 || !(1.0..=100_000.0).contains(&iters) {
        return Err(invalid("max_iterations", format!("expected a whole number in 1..=100000, got {iters}")));
    }
    let params = DfsphParams {
        h: p.number("h")?,
        rho0: p.number("density")?,
        alpha: p.number("viscosity")?,
        c0: p.number("sound_speed")?,
        kernel: KernelKind::by_name(p.text("kernel")?)?,
        density_tol: p.number("density_error")?,
        divergence_tol: p.number("divergence_error")?,
        max_iterations: iters as u32,
        cfl: p.number("cfl")?,
        surface_tension: p.number("surface_tension")?,
        adhesion: p.number("adhesion")?,
    };
    let walls = p.take_vectors::<V>("walls")?;
    let psi = p.take_floats("wall_psi")?;
    Ok(Box::new(Dfsph::new(&name, first, n, params, walls, psi)?))
}
crate::register_term!("dfsph", build);

/// Wall particle `b`'s position (the wall arrays are by component).
#[inline(always)]
fn wall_at<V: Vector>(w: &WallArrays<f64>, b: usize) -> V {
    let mut c = [0.0; 3];
    for (d, cd) in c.iter_mut().enumerate().take(V::DIM) {
        *cd = w.pos[d][b];
    }
    V::from_slice(&c[..V::DIM])
}

/// Σ_q f(j_q, g_q) over sorted particle `kk`'s stored pairs (`kk` within the chunk of `p`), in
/// two sums of alternate pairs added at the end: two independent chains of additions, so a pass
/// is not bound by one chain's latency. The order is fixed (the same bits for any thread count).
#[inline(always)]
fn pair_sum<V: Vector>(p: &Pairs<V>, kk: usize, f: impl Fn(usize, V) -> V) -> V {
    let (a, b) = (p.start[kk] as usize, p.start[kk + 1] as usize);
    let (js, gs) = (&p.j[a..b], &p.g[a..b]);
    let (mut s0, mut s1) = (V::ZERO, V::ZERO);
    let (jc, gc) = (js.chunks_exact(2), gs.chunks_exact(2));
    let (jr, gr) = (jc.remainder(), gc.remainder());
    for (j, g) in jc.zip(gc) {
        s0 += f(j[0] as usize, g[0]);
        s1 += f(j[1] as usize, g[1]);
    }
    if let (Some(&j), Some(&g)) = (jr.first(), gr.first()) {
        s0 += f(j as usize, g);
    }
    s0 + s1
}

/// `out[order[k]] = f(k)` for every sorted slot k, in parallel (`order` is a permutation of
/// `0..out.len()`).
fn unsort(order: &[u32], out: &mut [Real], f: impl Fn(usize) -> Real + Sync) {
    assert_eq!(order.len(), out.len());
    let ptr = SyncPtr(out.as_mut_ptr());
    par::reduce(
        order.len(),
        (),
        |_, _| (),
        |ks| {
            for k in ks {
                debug_assert!((order[k] as usize) < order.len());
                // SAFETY: `order` is a permutation of the indices of `out` (checked length):
                // each slot is written once, by its one sorted k.
                unsafe { *ptr.get().add(order[k] as usize) = f(k) };
            }
        },
    );
}

/// x + y (+ z).
#[inline(always)]
fn components_sum<V: Vector>(v: V) -> Real {
    (1..V::DIM).fold(v.comp(0), |s, c| s + v.comp(c))
}

/// One chunk of sorted particles of the pair build (`Dfsph::build`), compiled per SIMD level:
/// each particle's candidates are tested a vector at a time from the sorted positions by
/// component (`Dfsph::xc`) and the passing ones compacted into `pairs.j` from the mask's bits
/// (`Mask::bits`); then the kernel is evaluated on those pairs a vector at a time
/// (`Kernel::wg_exact`), and the density, Σ ∇W and Σ|∇W|² are summed in pair order. Every lane
/// does the scalar operations in the scalar order (no FMA), so every level finds the same pairs
/// and stores the same bits (`tests::the_build_is_the_same_at_every_level`).
///
/// Measured on the state of the 41k dam break at T* = 2 (Zen 4, 2 threads unless said, min of
/// 31 builds, binaries alternated): the scalar build with its cubic-spline branch (LLVM turned
/// the select of q < 1 into a branch around the division, which mispredicts on a disordered
/// flow) 16.0 ms at 1 thread, 13.9 with the branch taken out (`Float::pick`); at 2 threads the
/// scalar build 7.9–8.0 ms, the SIMD kernel 5.4, with the SIMD candidate test, the walls' dense
/// cell list and no zeroing of the pair buffers 5.2–5.3 (against 6.4–7.5 for the one before in
/// that noisier hour).
struct BuildChunk<'a, V: Vector, K> {
    grid: &'a CellList,
    walls: &'a Walls,
    xs: &'a [V],
    xc: &'a [Vec<Real>; 3],
    m: &'a [Real],
    h: Real,
    n_min: u32,
    /// The chunk's first sorted particle.
    s: usize,
    pairs: &'a mut Pairs<V>,
    sites: &'a mut [Site<V>],
    rho: &'a mut [Real],
    _k: PhantomData<K>,
}

impl<V: Vector, K: Kernel> SimdKernel for BuildChunk<'_, V, K> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, simd: S) {
        let BuildChunk { grid, walls, xs, xc, m, h, n_min, s, pairs, sites, rho: rho_out, .. } = self;
        let (sigma, reach) = (K::sigma(h, V::DIM), 4.0 * h * h);
        let gscale = sigma / (h * h);
        let (w, flat, lanes) = (f64::walls(walls), V::flat(xs), P::<S, f64>::lanes());
        let splat = |x: f64| P::<S, f64>::splat(simd, x);
        let (v_sigma, v_gscale, v_inv_h, v_reach) = (splat(sigma), splat(gscale), splat(1.0 / h), splat(reach));
        // `j` and `g` keep their length from step to step (no zeroing): the chunk's pairs are
        // `..top`, and `start` bounds every particle's.
        pairs.start.clear();
        let mut top = 0;
        let mut last = [i64::MIN; 3];
        let (mut fluid, mut wall) = (grid.query(last), walls.grid.query(last));
        for (kk, (site, rho_out)) in sites.iter_mut().zip(rho_out.iter_mut()).enumerate() {
            let k = s + kk;
            let cell = grid.cells[k];
            if cell != last {
                fluid = grid.query(cell);
                wall = walls.grid.query(cell);
                last = cell;
            }
            pairs.start.push(top as u32);
            let xk = xs[k];
            let (mut rho, mut sum, mut sq, mut count) = (m[k] * sigma * K::w(0.0), V::ZERO, 0.0, 0u32);
            // The candidates within reach, a vector of them at a time (|d|² lane by lane as
            // `Vector::dot` sums it: the same pairs at every level), compacted without a
            // branch (about a third of them pass, at random: a branch there mispredicts): each
            // candidate is written, and the count moves past it only if it passed.
            let base = top;
            let xkv: [P<S, f64>; 3] = std::array::from_fn(|c| splat(if c < V::DIM { xk.comp(c) } else { 0.0 }));
            for run in fluid.iter() {
                if pairs.j.len() < top + run.len() + lanes {
                    pairs.j.resize(top + run.len() + lanes, 0);
                }
                let (out, mut c) = (&mut pairs.j[top..], 0);
                let mut j = run.start;
                while j < run.end {
                    let d0 = xkv[0] - P::load(simd, &xc[0][j..]);
                    let mut r2 = d0 * d0;
                    for (xkc, xcc) in xkv.iter().zip(xc).take(V::DIM).skip(1) {
                        let dc = *xkc - P::load(simd, &xcc[j..]);
                        r2 = r2 + dc * dc;
                    }
                    let mut bits = r2.lt(v_reach).bits(simd);
                    if run.end - j < lanes {
                        bits &= (1 << (run.end - j)) - 1;
                    }
                    if (j..j + lanes).contains(&k) {
                        bits &= !(1 << (k - j));
                    }
                    for t in 0..lanes {
                        out[c] = (j + t) as u32;
                        c += ((bits >> t) & 1) as usize;
                    }
                    j += lanes;
                }
                top += c;
            }
            let end = top;
            if pairs.g.len() < end {
                pairs.g.resize(end, V::ZERO);
            }
            let mut q = base;
            while q < end {
                // A vector of pairs; lanes past the particle's last pair take j = k (d = 0:
                // finite, and dropped).
                let cnt = lanes.min(end - q);
                let idx: [usize; 16] = std::array::from_fn(|t| if t < cnt { pairs.j[q + t] as usize } else { k });
                let mut d = [P::zero(simd); 3];
                for c in 0..V::DIM {
                    d[c] = xkv[c] - P::from_fn(simd, |t| flat[idx[t] * V::DIM + c]);
                }
                // |d|² as `Vector::dot` sums it: ((x x + y y) + z z).
                let mut r2 = d[0] * d[0];
                for dc in &d[1..V::DIM] {
                    r2 = r2 + *dc * *dc;
                }
                let (wq, gq) = K::wg_exact(r2.sqrt() * v_inv_h);
                let mj = P::from_fn(simd, |t| m[idx[t]]);
                let (wr, f) = ((mj * v_sigma * wq).to_array(), mj * v_gscale * gq);
                let gc: [[f64; 16]; 3] = std::array::from_fn(|c| (d[c] * f).to_array());
                for t in 0..cnt {
                    let g = V::from_slice(&[gc[0][t], gc[1][t], gc[2][t]][..V::DIM]);
                    pairs.g[q + t] = g;
                    rho += wr[t];
                    sum += g;
                    sq += g.length_squared();
                }
                q += cnt;
            }
            count += (end - base) as u32;
            let mut gw = V::ZERO;
            for run in wall.iter() {
                for b in run {
                    let d = xk - wall_at::<V>(w, b);
                    let r2 = d.length_squared();
                    if r2 < reach {
                        let q = r2.sqrt() / h;
                        rho += w.psi[b] * sigma * K::w(q);
                        gw += d * (w.psi[b] * gscale * K::g(q));
                        count += 1;
                    }
                }
            }
            // Own push v_i −= dt κ_i/ρ_i (Σ_j m_j ∇W_ij + 2 Σ_b Ψ_b ∇W_ib) (walls mirror the
            // pressure), so Dρ_i/Dt changes by −dt κ_i/ρ_i D_i with this D_i (taken no
            // smaller than the neighbours' part, which is > 0, where a wall makes it so).
            let dd = ((sum + gw * 2.0).dot(sum + gw) + sq).max(sq);
            *site = Site { dinv: if dd > 0.0 { 1.0 / dd } else { 0.0 }, gw, gs: sum, inner: count >= n_min };
            *rho_out = rho;
        }
        pairs.start.push(top as u32);
    }
}

impl<V: Vector> Dfsph<V> {
    /// `walls`: static wall particle positions; `psi`: their Ψ_b = ρ0 V_b (kg), one each.
    pub fn new(name: &str, first: usize, n: usize, p: DfsphParams, walls: Vec<V>, psi: Vec<Real>) -> Result<Self> {
        p.validate()?;
        let walls = Walls::checked(&walls, &psi, 2.0 * p.h)?;
        Ok(Self {
            name: name.to_string(),
            first,
            n,
            p,
            walls,
            grid: CellList::new(2.0 * p.h, V::DIM)?,
            xs: Vec::new(),
            xc: Default::default(),
            m: Vec::new(),
            free: Vec::new(),
            sites: Vec::new(),
            rho: Vec::new(),
            vs: Vec::new(),
            k: Vec::new(),
            ksum: Vec::new(),
            pairs: Vec::new(),
            built: false,
            kappa: vec![0.0; n],
            kappa_v: vec![0.0; n],
            pressure: vec![0.0; n],
            n_min: 0,
            surface: Surface::new(p.surface_tension, p.adhesion, p.h, p.rho0, V::DIM),
            normals: Vec::new(),
            surface_p: Vec::new(),
            kick_dt: 0.0,
            books: Books::default(),
            clock: [0.0; 3],
            stop: Stop::default(),
        })
    }

    pub fn range(&self) -> Range<usize> {
        self.first..self.first + self.n
    }

    /// Sorts the fluid at `x` into cells and computes, per sorted particle, its density, factor,
    /// wall gradient sum and stored pairs (module doc, step 1).
    fn build(&mut self, x: &[V], model: &Model) {
        self.build_at(x, model, simd::level());
    }

    /// `build` at SIMD level `level` (every level gives the same bits).
    fn build_at(&mut self, x: &[V], model: &Model, level: simd::Level) {
        let t0 = Instant::now();
        match self.p.kernel {
            KernelKind::CubicSpline => self.build_with::<CubicSpline>(x, model, level),
            KernelKind::WendlandC2 => self.build_with::<WendlandC2>(x, model, level),
        }
        self.built = true;
        self.clock[0] += t0.elapsed().as_secs_f64();
    }

    fn build_with<K: Kernel>(&mut self, x: &[V], model: &Model, level: simd::Level) {
        let (n, r) = (self.n, self.range());
        let (xr, mr, im) = (&x[r.clone()], &model.mass[r.clone()], &model.inv_mass[r]);
        self.grid.build(xr);
        let order = &self.grid.order;
        self.xs.resize(n, V::ZERO);
        self.m.resize(n, 0.0);
        self.free.resize(n, true);
        par::chunks3(&mut self.xs, &mut self.m, &mut self.free, |s, xs, m, free| {
            for k in 0..xs.len() {
                let i = order[s + k] as usize;
                xs[k] = xr[i];
                m[k] = mr[i];
                free[k] = im[i] != 0.0;
            }
        });
        for (c, xc) in self.xc.iter_mut().enumerate().take(V::DIM) {
            xc.clear();
            xc.extend(self.xs.iter().map(|x| x.comp(c)));
            xc.resize(n + PAD, 0.0);
        }
        let h = self.p.h;
        // A full neighbourhood holds about ω_d (2h)^d ρ0/m particles; the divergence solve
        // takes those with at least 57 % of that (12 of 21 in 2D at h = 1.3 Δx).
        let mean_m = if n > 0 { self.m.iter().sum::<Real>() / n as Real } else { 1.0 };
        let ball = if V::DIM == 2 {
            std::f64::consts::PI * 4.0 * h * h
        } else {
            4.0 / 3.0 * std::f64::consts::PI * 8.0 * h * h * h
        };
        self.n_min = (0.57 * ball * self.p.rho0 / mean_m).round() as u32;
        let chunks = n.div_ceil(CHUNK);
        self.pairs.resize_with(chunks, Pairs::default);
        self.sites.resize(n, Site::default());
        self.rho.resize(n, 0.0);
        let (grid, xs, xc, m, walls) = (&self.grid, &self.xs, &self.xc, &self.m, &self.walls);
        let n_min = self.n_min;
        let chunk = |c: usize, pairs: &mut Pairs<V>, sites: &mut [Site<V>], rho: &mut [Real]| {
            let (s, _k) = (c * CHUNK, PhantomData::<K>);
            simd::dispatch(level, BuildChunk { grid, walls, xs, xc, m, h, n_min, s, pairs, sites, rho, _k });
        };
        let (pairs, sites, rho) = (&mut self.pairs, &mut self.sites, &mut self.rho);
        if par::fork_if(n, || {
            let parts = pairs.par_iter_mut().zip(sites.par_chunks_mut(CHUNK).zip(rho.par_chunks_mut(CHUNK)));
            parts.enumerate().for_each(|(c, (p, (s, r)))| chunk(c, p, s, r))
        })
        .is_none()
        {
            let parts = pairs.iter_mut().zip(sites.chunks_mut(CHUNK).zip(rho.chunks_mut(CHUNK)));
            parts.enumerate().for_each(|(c, (p, (s, r)))| chunk(c, p, s, r));
        }
        // The measured compression of this step's positions (the density solve's real result).
        let (rho0, rho) = (self.p.rho0, &self.rho);
        let e = par::sum(n, 0.0, |r| r.map(|k| (rho[k] - rho0).max(0.0)).sum::<Real>());
        let b = &mut self.books;
        b.measured = if n > 0 { e / (n as Real * rho0) } else { 0.0 };
        b.measured_max = b.measured_max.max(b.measured);
    }

    /// Sorted velocities from the scene's `v`, and their kinetic energy (J).
    fn gather_v(&mut self, v: &[V]) -> Real {
        let (order, vr, m, free) = (&self.grid.order, &v[self.range()], &self.m, &self.free);
        self.vs.resize(self.n, V::ZERO);
        par::chunks1_sum(&mut self.vs, |s, vs| {
            let mut e = 0.0;
            for (k, vk) in vs.iter_mut().enumerate() {
                *vk = vr[order[s + k] as usize];
                // Pinned particles carry no kinetic energy in the books (`ParticleSystem::energy`).
                if free[s + k] {
                    e += 0.5 * m[s + k] * vk.length_squared();
                }
            }
            e
        })
    }

    /// Writes the sorted velocities back into the scene's `v`; returns their kinetic energy.
    fn scatter_v(&self, v: &mut [V]) -> Real {
        let r = self.range();
        let out = SyncPtr(v[r].as_mut_ptr());
        let (order, vs, m, free) = (&self.grid.order, &self.vs, &self.m, &self.free);
        par::sum(self.n, 0.0, |ks| {
            let mut e = 0.0;
            for k in ks {
                // SAFETY: `order` is a permutation: each particle is written by one sorted slot.
                unsafe { *out.get().add(order[k] as usize) = vs[k] };
                if free[k] {
                    e += 0.5 * m[k] * vs[k].length_squared();
                }
            }
            e
        })
    }

    /// One error pass: per sorted particle the error e_i of `stage` at the sorted velocities
    /// (density: (ρ*_i − ρ0)₊, kg/m^dim; divergence: (Dρ_i/Dt)₊, kg/(m^dim s)), turned into
    /// κ_i/ρ_i = e_i / (dt^p D_i) in `k`; returns Σ e_i.
    fn errors(&mut self, stage: Projection, dt: Real) -> Real {
        let (pairs, sites, rho, vs, rho0) = (&self.pairs, &self.sites, &self.rho, &self.vs, self.p.rho0);
        let scale = match stage {
            Projection::Density => 1.0 / (dt * dt),
            Projection::Divergence => 1.0 / dt,
        };
        par::chunks1_sum(&mut self.k, |s, k| {
            let p = &pairs[s / CHUNK];
            let mut total = 0.0;
            for (kk, kout) in k.iter_mut().enumerate() {
                let i = s + kk;
                let (site, vi) = (&sites[i], vs[i]);
                // Σ_j (v_i − v_j)·g_ij = v_i·Σ_j g_ij − Σ_j v_j·g_ij: per pair only the
                // neighbour's part, in two independent sums (SPH-2D 41k, 2 threads: 0.62 →
                // 0.48 ms a pass beside the pairwise form in one process; between separate
                // binaries within noise; the whole run's solver share 11.7 → 8.0 ms a step).
                let acc = pair_sum(p, kk, |j, g| g * vs[j]);
                let div = vi.dot(site.gw + site.gs) - components_sum(acc);
                let e = match stage {
                    Projection::Density => (rho[i] + dt * div - rho0).max(0.0),
                    Projection::Divergence if site.inner => div.max(0.0),
                    Projection::Divergence => 0.0,
                };
                *kout = e * site.dinv * scale;
                total += e;
            }
            total
        })
    }

    /// One velocity update with κ/ρ in `k` (module doc), adding `k` into `ksum`.
    fn apply(&mut self, dt: Real) {
        let (pairs, sites, k, free) = (&self.pairs, &self.sites, &self.k, &self.free);
        par::chunks2(&mut self.vs, &mut self.ksum, |s, vs, ksum| {
            let p = &pairs[s / CHUNK];
            for kk in 0..vs.len() {
                let i = s + kk;
                let ki = k[i];
                // Walls mirror the particle's pressure (p_b = p_i: (κ_i + κ_i)/ρ_i), so a wall
                // layer balances the fluid's push; with κ_i alone (Akinci 2012, eq. 10, as in
                // WCSPH) the hydrostatic push drove the corner particles of a 2 m column through
                // the walls (144 particles across, T* = 0.15), their own pressure pushing
                // nothing where the fluid's and the walls' gradients cancel.
                // Σ_j (κ_i + κ_j) g_ij = κ_i Σ_j g_ij + Σ_j κ_j g_ij (as in `errors`).
                let a = (sites[i].gw * 2.0 + sites[i].gs) * ki + pair_sum(p, kk, |j, g| g * k[j]);
                if free[i] {
                    vs[kk] -= a * dt;
                }
                ksum[kk] += ki;
            }
        });
    }

    /// Turns the κ/ρ of an error pass in `k` into `pick(κ/ρ, w)` with w = `WARM_START` times
    /// the particle's last summed κ/ρ of `stage`, where it compresses (κ/ρ > 0), else 0.
    fn warm_start(&mut self, stage: Projection, pick: impl Fn(Real, Real) -> Real + Sync) {
        let (order, k) = (&self.grid.order, &mut self.k);
        let hist = match stage {
            Projection::Density => &self.kappa,
            Projection::Divergence => &self.kappa_v,
        };
        par::chunks1(k, |s, k| {
            for (kk, ko) in k.iter_mut().enumerate() {
                *ko = if *ko > 0.0 { pick(*ko, hist[order[s + kk] as usize] * WARM_START) } else { 0.0 };
            }
        });
    }

    /// One solve (module doc, steps 2 and 4) on the scene's velocities `v`; returns the kinetic
    /// energy it removed (J).
    fn solve(&mut self, stage: Projection, v: &mut [V], dt: Real) -> Real {
        let t0 = Instant::now();
        let n = self.n;
        let e0 = self.gather_v(v);
        // Warm start: half the last step's sum (module doc; κ/ρ does not scale with dt), only
        // where the state compresses now (a push where it no longer does would expand it,
        // which the one-sided solve never takes back: energy put in). The density solve
        // applies it before its iterations (paper, Algorithm 2); the divergence solve folds it
        // into its first iteration (`WarmStart`).
        let warm = match stage {
            Projection::Density => WarmStart::Before,
            Projection::Divergence => WarmStart::FirstIteration,
        };
        self.k.resize(n, 0.0);
        self.ksum.clear();
        self.ksum.resize(n, 0.0);
        if warm == WarmStart::Before {
            self.errors(stage, dt);
            self.warm_start(stage, |_, w| w);
            self.apply(dt);
        }
        let rho0 = self.p.rho0;
        let tol = match stage {
            Projection::Density => self.p.density_tol,
            Projection::Divergence => self.p.divergence_tol,
        };
        let norm = match stage {
            Projection::Density => 1.0 / (n.max(1) as Real * rho0),
            Projection::Divergence => dt / (n.max(1) as Real * rho0),
        };
        // At least 2 density iterations and 1 divergence iteration a step (paper, Algorithms 2
        // and 3): a mean below the tolerance can hide a deep layer's growing compression (a 2 m
        // column, 144 particles across, blew up at step 13 when the solve first had to act).
        let least = match stage {
            Projection::Density => 2,
            Projection::Divergence => 1,
        };
        let mut iterations = 0u32;
        let err = loop {
            let err = self.errors(stage, dt) * norm;
            let done = err <= tol && iterations >= least.min(self.p.max_iterations);
            if done || iterations >= self.p.max_iterations || self.stop.is_set() {
                break err;
            }
            if iterations == 0 && warm == WarmStart::FirstIteration {
                self.warm_start(stage, Real::max);
            }
            self.apply(dt);
            iterations += 1;
        };
        // Keep the sum for the next step's warm start (particle order). κ/ρ = p/ρ² does not
        // scale with dt: a steady flow needs the same pressure whatever the step.
        let (order, ksum) = (&self.grid.order, &self.ksum);
        let out = match stage {
            Projection::Density => &mut self.kappa,
            Projection::Divergence => &mut self.kappa_v,
        };
        unsort(order, out, |k| ksum[k]);
        if stage == Projection::Density {
            // Both solves push with the same form: the step's pressure is their sum.
            // With surface tension, plus the surface forces' virial (`surface_acceleration`):
            // the mechanical pressure.
            let (sp, rho, kappa, kappa_v) = (&self.surface_p, &self.rho, &self.kappa, &self.kappa_v);
            unsort(order, &mut self.pressure, |k| {
                let i = order[k] as usize;
                (kappa[i] + kappa_v[i]) * rho[k] * rho[k] + sp.get(k).copied().unwrap_or(0.0)
            });
        }
        let e1 = self.scatter_v(v);
        let b = &mut self.books;
        b.unconverged += (err > tol) as u64;
        match stage {
            Projection::Density => {
                b.steps += 1;
                b.density_iterations += iterations as u64;
                b.density_error = err;
                b.density_error_max = b.density_error_max.max(err);
                b.dissipated_density += e0 - e1;
            }
            Projection::Divergence => {
                b.divergence_iterations += iterations as u64;
                b.divergence_error = err;
                b.divergence_error_max = b.divergence_error_max.max(err);
                b.dissipated_divergence += e0 - e1;
            }
        }
        self.clock[1] += t0.elapsed().as_secs_f64();
        e0 - e1
    }

    /// The step's surface normals n_i = H Σ_j m_j/ρ_j ∇W_ij (Akinci 2013, eq. 4; fluid
    /// neighbours only), sorted order, from the stored pairs (g = m_j ∇W_ij).
    fn compute_normals(&mut self) {
        let (pairs, rho, big_h) = (&self.pairs, &self.rho, self.surface.big_h);
        self.normals.resize(self.n, V::ZERO);
        par::chunks1(&mut self.normals, |s, out| {
            let p = &pairs[s / CHUNK];
            for (kk, n) in out.iter_mut().enumerate() {
                let mut sum = V::ZERO;
                for q in p.start[kk] as usize..p.start[kk + 1] as usize {
                    sum += p.g[q] * (1.0 / rho[p.j[q] as usize]);
                }
                *n = sum * big_h;
            }
        });
    }

    /// Sorted particle i's acceleration by surface tension and adhesion (`sph::surface`):
    /// −γ Σ_j K_ij [m_j C(r) x̂_ij + c (n_i − n_j)] − β Σ_b Ψ_b A(r) x̂_ib, m/s²; and the virial
    /// pressure of its fluid pairs' surface forces, ρ_i/(2d) Σ_j x_ij·a_ij, Pa (Irving &
    /// Kirkwood 1950: each pair's x_ij·F_ij shared half and half, over the particle's volume
    /// m_i/ρ_i). The cohesion holds the fluid together with a bulk tension of its own (about
    /// −(π/2)ρ0²γ∫C r² dr in 2D, tens of times σ/R): the solvers' pressure carries it, and only
    /// the sum of the two, the mechanical pressure, shows a droplet's Laplace pressure.
    #[inline(always)]
    fn surface_acceleration(&self, i: usize, xi: V, ri: Real) -> (V, Real) {
        let (surf, normals, rho0) = (&self.surface, &self.normals, self.p.rho0);
        let (p, kk) = (&self.pairs[i / CHUNK], i % CHUNK);
        let (mut a, mut virial) = (V::ZERO, 0.0);
        if surf.tension() {
            let (xs, m, rho) = (&self.xs, &self.m, &self.rho);
            let ni = normals[i];
            let (mut st, mut vir) = (V::ZERO, 0.0);
            for q in p.start[kk] as usize..p.start[kk + 1] as usize {
                let j = p.j[q] as usize;
                let d = xi - xs[j];
                let r = d.length_squared().sqrt();
                let k_ij = 2.0 * rho0 / (ri + rho[j]);
                // Coincident particles have no direction: no cohesion (the curvature term stays).
                let coh = if r > 0.0 { d * (m[j] * surf.cohesion(r) / r) } else { V::ZERO };
                let pair = (coh + (ni - normals[j]) * surf.c) * k_ij;
                st += pair;
                vir += d.dot(pair);
            }
            a -= st * surf.gamma;
            virial = -surf.gamma * vir * ri / (2.0 * V::DIM as Real);
        }
        if surf.adhesion() {
            let mut ad = V::ZERO;
            let w = f64::walls(&self.walls);
            for run in self.walls.grid.query(self.grid.cells[i]).iter() {
                for b in run {
                    let d = xi - wall_at::<V>(w, b);
                    let r = d.length_squared().sqrt();
                    let k = super::surface::adhesion_kernel(r, surf.big_h);
                    if k > 0.0 {
                        ad += d * (w.psi[b] * k / r);
                    }
                }
            }
            a -= ad * surf.beta;
        }
        (a, virial)
    }

    /// Density (kg/m^dim) of each particle of the fluid at `x`, particle order, computed now
    /// (scratch of its own).
    pub fn densities(&self, x: &[V], model: &Model) -> Vec<Real> {
        match self.p.kernel {
            KernelKind::CubicSpline => self.densities_with::<CubicSpline>(x, model),
            KernelKind::WendlandC2 => self.densities_with::<WendlandC2>(x, model),
        }
    }

    fn densities_with<K: Kernel>(&self, x: &[V], model: &Model) -> Vec<Real> {
        let r = self.range();
        let (xr, mr) = (&x[r.clone()], &model.mass[r]);
        let mut grid = CellList::new(self.grid.cell_size(), V::DIM).expect("valid cell size");
        grid.build(xr);
        let (h, w) = (self.p.h, f64::walls(&self.walls));
        let (sigma, reach) = (K::sigma(h, V::DIM), 4.0 * h * h);
        let mut rho = vec![0.0; self.n];
        let out = SyncPtr(rho.as_mut_ptr());
        let grid = &grid;
        par::reduce(
            self.n,
            (),
            |_, _| (),
            |ks| {
                for k in ks {
                    let i = grid.order[k] as usize;
                    let c = grid.cells[k];
                    let mut s = 0.0;
                    for run in grid.query(c).iter() {
                        for j in run {
                            let jj = grid.order[j] as usize;
                            let r2 = (xr[i] - xr[jj]).length_squared();
                            if r2 < reach {
                                s += mr[jj] * sigma * K::w(r2.sqrt() / h);
                            }
                        }
                    }
                    for run in self.walls.grid.query(c).iter() {
                        for b in run {
                            let r2 = (xr[i] - wall_at::<V>(w, b)).length_squared();
                            if r2 < reach {
                                s += w.psi[b] * sigma * K::w(r2.sqrt() / h);
                            }
                        }
                    }
                    // SAFETY: each particle i is written by its one sorted slot k.
                    unsafe { *out.get().add(i) = s };
                }
            },
        );
        rho
    }
}

impl<V: Vector> Term<V> for Dfsph<V> {
    fn name(&self) -> &str {
        &self.name
    }

    /// (`crate::alloc`) The build grows its pair lists inside parallel kernels, where a refusal
    /// cannot be reported; the world checks this much room is left once the step's checkpoint
    /// is taken. After a build: what it held again (a list that must grow reallocates beside
    /// the old one). Before the first: 64 neighbours a particle in 2D, 160 in 3D (a full
    /// neighbourhood is about 21 and 74 at h = 1.3 Δx; the rest covers a longer h), and the
    /// per-particle arrays.
    fn transient_bytes(&self, _n: usize) -> u128 {
        let held: u128 = self.pairs.iter().map(|p| p.bytes() as u128).sum();
        if held > 0 {
            return held;
        }
        let per_pair = Need::bytes_of::<u32>(1) + Need::bytes_of::<V>(1);
        let neighbours: u128 = if V::DIM == 2 { 64 } else { 160 };
        let n = self.n as u128;
        n * neighbours * per_pair
            + n * (Need::bytes_of::<Site<V>>(1) + Need::bytes_of::<V>(2) + Need::bytes_of::<Real>(4))
    }

    /// The viscous forces at (x, v) (module doc); pressure is the projections'.
    fn add_forces(&mut self, x: &[V], v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let r = self.range();
        if write == Write::Overwrite {
            let (head, rest) = f.split_at_mut(r.start);
            head.fill(V::ZERO);
            rest[r.len()..].fill(V::ZERO);
        }
        if self.n == 0 {
            return 0.0;
        }
        if !self.built {
            self.build(x, model);
            // Only a step's divergence stage keeps the build for the stages after it.
            self.built = false;
        }
        let t0 = Instant::now();
        self.gather_v(v);
        let visc = self.p.alpha * self.p.c0;
        let surf = self.surface;
        if surf.tension() {
            self.compute_normals();
        }
        self.surface_p.clear();
        if surf.tension() || surf.adhesion() {
            self.surface_p.resize(self.n, 0.0);
        }
        // Written below only where the surface forces are on (then it holds n values).
        let sp = SyncPtr(self.surface_p.as_mut_ptr());
        let power = if visc == 0.0 && !surf.tension() && !surf.adhesion() {
            if write == Write::Overwrite {
                f[r].fill(V::ZERO);
            }
            0.0
        } else {
            let (pairs, rho, xs, vs, m, h) = (&self.pairs, &self.rho, &self.xs, &self.vs, &self.m, self.p.h);
            let (order, out) = (&self.grid.order, SyncPtr(f[r].as_mut_ptr()));
            let eps = 0.01 * h * h;
            let kick_dt = self.kick_dt;
            par::sum(self.n, 0.0, |ks| {
                let mut power = 0.0;
                for i in ks {
                    let p = &pairs[i / CHUNK];
                    let kk = i % CHUNK;
                    let (xi, vi, ri) = (xs[i], vs[i], rho[i]);
                    let mut a = V::ZERO;
                    for q in p.start[kk] as usize..p.start[kk + 1] as usize {
                        let j = p.j[q] as usize;
                        let (d, vij) = (xi - xs[j], vi - vs[j]);
                        // Π_ij = −α c0 μ_ij / ρ̄_ij, μ_ij = h v_ij·r_ij / (r² + 0.01 h²) for
                        // approaching pairs, else 0 (without a branch: half the pairs approach).
                        let vr = vij.dot(d).min(0.0);
                        let pi = -visc * h * vr / ((d.length_squared() + eps) * 0.5 * (ri + rho[j]));
                        a -= p.g[q] * pi;
                    }
                    if surf.tension() || surf.adhesion() {
                        let (s, virial) = self.surface_acceleration(i, xi, ri);
                        // SAFETY: each sorted slot i is written by this one iteration.
                        unsafe { *sp.get().add(i) = virial };
                        a += s;
                    }
                    // The work of the term's forces over the kick that follows, F·(v + dt a/2)
                    // (their share of the kick's change of ½ m|v|²), booked as dissipation when taken
                    // out: the viscosity's, and the surface's, which releases energy (< 0) or
                    // stores it. (The viscosity alone, at v, is ½ Σ_ij m_i m_j Π_ij v_ij·∇W_ij;
                    // at v alone the kick's ½ m dt² |a|², which the density solve then takes
                    // out and books, went unbooked: a drop held by its surface tension drifted
                    // its books by 1.5 % per ms, 2D, 2 400 particles.)
                    if self.free[i] {
                        power -= m[i] * a.dot(vi + a * (0.5 * kick_dt));
                    }
                    // SAFETY: `order` is a permutation: each particle is written by one slot.
                    unsafe { write.put(&mut *out.get().add(order[i] as usize), a * m[i]) };
                }
                power
            })
        };
        self.clock[2] += t0.elapsed().as_secs_f64();
        power
    }

    fn potential(&self, _x: &[V], _model: &Model) -> Option<Real> {
        // Incompressible: no internal energy (module doc).
        Some(0.0)
    }

    fn dissipative(&self) -> bool {
        true
    }

    fn velocity_dependent(&self) -> bool {
        true
    }

    fn min_particles(&self) -> usize {
        self.first + self.n
    }

    fn max_dt(&self, _x: &[V], v: &[V], _model: &Model, g: Real) -> Option<Real> {
        if self.n == 0 {
            return None;
        }
        let vmax = v[self.range()].iter().map(|u| u.length_squared()).fold(0.0, f64::max).sqrt();
        // The flow's CFL condition λ h/|v|max, the explicit viscosity's limit 0.125 h²/ν with
        // Monaghan's ν = α c0 h/(2(d + 2)) (Monaghan 2005, §4.3), and the force criterion of the
        // uniform fields (a fluid falling from rest has no speed yet), and with surface tension
        // the capillary limit (`Surface::max_dt`). (WCSPH's form
        // λ h/(|v|max + 0.6 α c0) took 2199 steps to T* = 4 on the 41k dam break.)
        let h = self.p.h;
        let cfl = if vmax > 0.0 { self.p.cfl * h / vmax } else { f64::INFINITY };
        let viscous = super::resolve::dfsph_viscous(h, V::DIM, self.p.alpha, self.p.c0);
        let force = if g > 0.0 { 0.25 * (h / g).sqrt() } else { f64::INFINITY };
        let capillary = Surface::max_dt(self.p.surface_tension, self.p.adhesion, self.p.rho0, h);
        let dt = cfl.min(viscous).min(force).min(capillary);
        dt.is_finite().then_some(dt)
    }

    fn fields(&self, x: &[V], model: &Model) -> Vec<(&'static str, Range<usize>, Vec<Real>)> {
        vec![("density", self.range(), self.densities(x, model)), ("pressure", self.range(), self.pressure.clone())]
    }

    fn profile(&self) -> Option<([f64; 3], usize)> {
        let bytes = self.grid.bytes()
            + self.walls.bytes()
            + self.pairs.iter().map(Pairs::bytes).sum::<usize>()
            + (self.xs.capacity() + self.vs.capacity() + self.normals.capacity()) * std::mem::size_of::<V>()
            + self.sites.capacity() * std::mem::size_of::<Site<V>>()
            + (self.m.capacity() + self.k.capacity() + self.ksum.capacity() + self.surface_p.capacity()) * 8
            + (self.rho.capacity() + self.xc.iter().map(Vec::capacity).sum::<usize>()) * 8
            + (self.kappa.capacity() + self.kappa_v.capacity() + self.pressure.capacity()) * 8;
        Some((self.clock, bytes))
    }

    fn set_stop(&mut self, stop: Stop) {
        self.stop = stop;
    }

    fn reserve(&mut self, _n_particles: usize) -> Result<()> {
        let n = self.n;
        let vb = std::mem::size_of::<V>();
        let per = 2 * vb + std::mem::size_of::<Site<V>>() + (4 + V::DIM) * 8;
        let bytes = (n as u128) * per as u128 + (V::DIM * PAD * 8) as u128;
        let need = Need::new("step", bytes, format!("the DFSPH buffers of {} particles", count(n as u128)));
        need.check()?;
        need.reserve(&mut self.xs, n)?;
        need.reserve(&mut self.vs, n)?;
        need.reserve(&mut self.sites, n)?;
        for a in [&mut self.m, &mut self.k, &mut self.ksum, &mut self.rho] {
            need.reserve(a, n)?;
        }
        for xc in self.xc.iter_mut().take(V::DIM) {
            need.reserve(xc, n + PAD)?;
        }
        self.grid.reserve(n, "step")?;
        // The step's checkpoint copies the state (fallibly) and then this term's history, which
        // `Term::history` cannot refuse: check now that both still fit (3 reals and 3 vectors a
        // particle), so that a refusal is an error here rather than an abort there.
        let snapshot = Need::bytes_of::<Real>(3 * n) + Need::bytes_of::<V>(3 * n);
        Need::new("step", snapshot, format!("a copy of the DFSPH state of {} particles", count(n as u128)))
            .room(snapshot)
    }

    fn integrators(&self) -> Option<&'static [&'static str]> {
        crate::terms::registry::integrator_rule("dfsph").map(|r| r.0)
    }

    fn stats(&self) -> Vec<(&'static str, Real)> {
        let b = &self.books;
        vec![
            ("steps", b.steps as Real),
            ("density_iterations", b.density_iterations as Real),
            ("divergence_iterations", b.divergence_iterations as Real),
            ("unconverged", b.unconverged as Real),
            ("density_error", b.density_error),
            ("density_error_max", b.density_error_max),
            ("divergence_error", b.divergence_error),
            ("divergence_error_max", b.divergence_error_max),
            ("measured_density_error", b.measured),
            ("measured_density_error_max", b.measured_max),
            ("dissipated_density_solver", b.dissipated_density),
            ("dissipated_divergence_solver", b.dissipated_divergence),
        ]
    }

    fn as_projection(&mut self) -> Option<&mut dyn VelocityProjection<V>> {
        Some(self)
    }
    fn as_own_state(&self) -> Option<&dyn OwnState<V>> {
        Some(self)
    }
    fn as_own_state_mut(&mut self) -> Option<&mut dyn OwnState<V>> {
        Some(self)
    }
}

impl<V: Vector> OwnState<V> for Dfsph<V> {
    /// The warm starts and the last step's pressure: 3 values per particle.
    fn history(&self) -> Vec<Real> {
        let mut h = Vec::with_capacity(3 * self.n);
        h.extend_from_slice(&self.kappa);
        h.extend_from_slice(&self.kappa_v);
        h.extend_from_slice(&self.pressure);
        h
    }
    fn set_history(&mut self, h: &[Real], _n_particles: usize) -> Result<()> {
        let n = self.n;
        if h.len() != 3 * n {
            return Err(invalid("history", format!("expected {} values (3 per particle), got {}", 3 * n, h.len())));
        }
        if let Some(i) = h.iter().position(|x| !x.is_finite()) {
            return Err(invalid("history", format!("entry {i} is not finite")));
        }
        self.kappa.copy_from_slice(&h[..n]);
        self.kappa_v.copy_from_slice(&h[n..2 * n]);
        self.pressure.copy_from_slice(&h[2 * n..]);
        self.built = false;
        Ok(())
    }
    /// A snapshot of this term, non-finite values (a rollback of a diverged call) included.
    fn restore_history(&mut self, h: &[Real], _n_particles: usize) {
        let n = self.n;
        assert_eq!(h.len(), 3 * n, "a DFSPH term's own history restores");
        self.kappa.copy_from_slice(&h[..n]);
        self.kappa_v.copy_from_slice(&h[n..2 * n]);
        self.pressure.copy_from_slice(&h[2 * n..]);
        self.built = false;
    }
}

impl<V: Vector> VelocityProjection<V> for Dfsph<V> {
    fn project(&mut self, stage: Projection, x: &[V], v: &mut [V], model: &Model, dt: Real) -> Real {
        if self.n == 0 || self.stop.is_set() {
            return 0.0;
        }
        if stage == Projection::Divergence || !self.built {
            self.build(x, model);
        }
        if stage == Projection::Divergence {
            self.kick_dt = dt;
        }
        let e = self.solve(stage, v, dt);
        if stage == Projection::Density {
            self.built = false;
        }
        e
    }
}

#[cfg(test)]
mod tests {
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
        }
    }

    /// The particle mass of spacing dx, the model of n such particles and a fresh term over
    /// them with walls `w` of the same mass.
    fn term(n: usize, w: &[DVec2], dx: f64) -> (f64, Model, Dfsph<DVec2>) {
        let m = 1000.0 * dx * dx;
        let model = Model { mass: vec![m; n], inv_mass: vec![1.0 / m; n], ..Default::default() };
        (m, model, Dfsph::new("f", 0, n, params(dx), w.to_vec(), vec![m; w.len()]).unwrap())
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
    fn build_bits<V: Vector>(t: &mut Dfsph<V>, x: &[V], model: &Model, level: simd::Level) -> Vec<u64> {
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
        let mut t3 = Dfsph::new("f", 0, x3.len(), params(dx), vec![], vec![]).unwrap();
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
            let removed = VelocityProjection::project(&mut t, Projection::Density, &x, &mut v, &model, dt);
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
            Ok(dir) => (
                (read(format!("{dir}/x.bin")), read(format!("{dir}/v.bin")), read(format!("{dir}/w.bin"))),
                1.0 / 144.0,
            ),
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
}
