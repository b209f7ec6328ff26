//! The data the passes read, in cell order: each fluid's static wall particles (`Walls`, sorted
//! once at construction, with their arrays in both pass precisions) and the per-evaluation
//! structure-of-arrays buffers (`Bufs`, one set per precision, `BufSet`): the gather of
//! positions, velocities and masses into cell order (and, when several fluids share the passes,
//! each particle's fluid and viscosity coefficient), and the reservation that makes a step
//! allocation-free.
use super::kernels::{Float, Kernel};
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::neighbors::CellList;
use crate::par::{self, SyncPtr};
use crate::terms::BodyMotion;
use crate::vector::{Real, Vector};

/// Wall particles in the precision of the passes, in the cell order of `Walls::grid`, padded.
#[derive(Clone, Debug, Default)]
pub(super) struct WallArrays<F: Float> {
    pub(super) pos: [Vec<F>; 3],
    /// Ψ_b = ρ0 V_b, kg.
    pub(super) psi: Vec<F>,
}

/// Static wall particles: positions and Ψ_b = ρ0 V_b (kg/m^dim · m^dim = kg), sorted into cells,
/// in both pass precisions.
#[derive(Clone, Debug)]
pub(super) struct Walls {
    pub(super) grid: CellList,
    w32: WallArrays<f32>,
    w64: WallArrays<f64>,
}

/// Sorted, padded structure-of-arrays buffers in the precision of the passes.
#[derive(Clone, Debug, Default)]
pub(super) struct Bufs<F: Float> {
    pub(super) pos: [Vec<F>; 3],
    pub(super) vel: [Vec<F>; 3],
    pub(super) m: Vec<F>,
    pub(super) rho: Vec<F>,
    /// p/ρ², m⁵/(kg s²) in 3D.
    pub(super) pr: Vec<F>,
    /// Several fluids only: each particle's fluid (index in its group) ...
    pub(super) fluid: Vec<u8>,
    /// ... and its α c0 h (m²/s), half of the pair's viscosity coefficient.
    pub(super) visc: Vec<F>,
}

/// Loads past the end of a run read up to `PAD` padding entries (masked out).
pub(super) const PAD: usize = 16;

/// The pass buffers of both precisions (the particle arrays of the one in use are filled by
/// each evaluation).
#[derive(Clone, Debug, Default)]
pub(super) struct BufSet {
    pub(super) b32: Bufs<f32>,
    pub(super) b64: Bufs<f64>,
}

/// A pass precision (f32 or f64): picks its buffers out of a `BufSet` and its arrays out of
/// `Walls`, so that an evaluation is written once, generic over the precision.
pub(super) trait PassFloat: Float {
    fn bufs(set: &mut BufSet) -> &mut Bufs<Self>;
    fn walls(w: &Walls) -> &WallArrays<Self>;
}

impl PassFloat for f32 {
    fn bufs(set: &mut BufSet) -> &mut Bufs<f32> {
        &mut set.b32
    }
    fn walls(w: &Walls) -> &WallArrays<f32> {
        &w.w32
    }
}

impl PassFloat for f64 {
    fn bufs(set: &mut BufSet) -> &mut Bufs<f64> {
        &mut set.b64
    }
    fn walls(w: &Walls) -> &WallArrays<f64> {
        &w.w64
    }
}

impl Walls {
    /// `new` after checking the arguments as a fluid term receives them (errors name
    /// `walls` and `wall_volume`, the Python API's arguments).
    pub(super) fn checked<V: Vector>(walls: &[V], psi: &[Real], support: Real) -> Result<Self> {
        if walls.len() != psi.len() {
            return Err(invalid("wall_volume", format!("has {} entries, walls has {}", psi.len(), walls.len())));
        }
        if let Some(i) = walls.iter().position(|w| !w.is_finite()) {
            return Err(invalid("walls", format!("row {i} is not finite")));
        }
        if let Some(i) = psi.iter().position(|w| !(w.is_finite() && *w > 0.0)) {
            return Err(invalid("wall_volume", format!("entry {i} is {} (must be finite and > 0)", psi[i])));
        }
        Self::new(walls, psi, support)
    }

    /// The wall particles `walls` (finite) with their Ψ (`psi`, one each) sorted into cells of
    /// side `support`, with their arrays in both precisions.
    pub(super) fn new<V: Vector>(walls: &[V], psi: &[Real], support: Real) -> Result<Self> {
        let nw = walls.len();
        let bytes = ((nw + PAD) * (V::DIM + 1) * (4 + 8)) as u128;
        let need = Need::new("add_fluid", bytes, format!("{} wall particles", count(nw as u128)));
        need.check()?;
        // Built once, queried for every particle's cell each step: dense up to 1M cells (4 MB
        // of cell starts kept; the build's scratch is freed).
        let mut grid = CellList::new(support, V::DIM)?.with_dense_floor(1 << 20);
        grid.reserve(nw, "add_fluid")?;
        grid.build(walls);
        grid.release_scratch();
        let w32 = WallArrays::sorted(&grid, walls, psi, &need)?;
        let w64 = WallArrays::sorted(&grid, walls, psi, &need)?;
        Ok(Self { grid, w32, w64 })
    }

    /// Heap bytes held.
    pub(super) fn bytes(&self) -> usize {
        self.grid.bytes() + self.w32.bytes() + self.w64.bytes()
    }
}

/// Moving wall particles: the rigid bodies' boundary samples (Akinci et al. 2012; the role
/// `terms::MovingBoundary`), set before every step, sorted into cells of the fluid's support
/// like `Walls` (f64 only: the DFSPH build reads them), each with its body and its offset from
/// the body's centre of mass (sorted); the bodies' motion, which the pressure solve updates
/// iteration by iteration, and the impulse it gave each body over the step; and the step's
/// pairs of a fluid particle and a sample (`pair_up`).
#[derive(Clone, Debug)]
pub(super) struct MovingWalls<V: Vector> {
    pub(super) grid: CellList,
    pub(super) w: WallArrays<f64>,
    pub(super) body: Vec<u32>,
    pub(super) offset: Vec<V>,
    pub(super) bodies: Vec<BodyMotion<V>>,
    pub(super) impulse: Vec<(V, [Real; 3])>,
    /// The pairs (sorted fluid particle k, sorted sample b, g = Ψ_b ∇W_kb, Ψ_b W_kb) ordered by
    /// k, then b; and per fluid particle that has any, (k, its first pair, past its last).
    pub(super) pairs: Vec<(u32, u32, V, Real)>,
    pub(super) runs: Vec<(u32, u32, u32)>,
    /// Each body's push in one solver iteration (scratch, kept so an iteration allocates nothing).
    pub(super) push: Vec<(V, [Real; 3])>,
}

impl<V: Vector> MovingWalls<V> {
    pub(super) fn new(support: Real) -> Result<Self> {
        let grid = CellList::new(support, V::DIM)?;
        Ok(Self {
            grid,
            w: WallArrays::default(),
            body: Vec::new(),
            offset: Vec::new(),
            bodies: Vec::new(),
            impulse: Vec::new(),
            pairs: Vec::new(),
            runs: Vec::new(),
            push: Vec::new(),
        })
    }

    /// The boundary of the next step (`MovingBoundary::set_boundary`).
    pub(super) fn set(&mut self, x: &[V], psi: &[Real], body: &[u32], offset: &[V], bodies: &[BodyMotion<V>]) {
        self.grid.build(x);
        let order = &self.grid.order;
        for d in 0..V::DIM {
            self.w.pos[d].clear();
            self.w.pos[d].extend(order.iter().map(|&i| x[i as usize].comp(d)));
        }
        self.w.psi.clear();
        self.w.psi.extend(order.iter().map(|&i| psi[i as usize]));
        self.body.clear();
        self.body.extend(order.iter().map(|&i| body[i as usize]));
        self.offset.clear();
        self.offset.extend(order.iter().map(|&i| offset[i as usize]));
        self.bodies.clear();
        self.bodies.extend_from_slice(bodies);
        self.impulse.clear();
        self.impulse.resize(bodies.len(), (V::ZERO, [0.0; 3]));
        self.pairs.clear();
        self.runs.clear();
    }

    /// The step's pairs of a fluid particle k (sorted by `grid`, at `at(k)`) and a sample b
    /// within reach 2h, found from the samples' side (they are few) into `out`, ordered by k
    /// and then b (a stable sort): one thread, the same order for any count.
    pub(super) fn find_pairs<K: Kernel>(
        &self,
        grid: &CellList,
        at: impl Fn(usize) -> V,
        h: Real,
        out: &mut Vec<(u32, u32, V, Real)>,
    ) {
        let (sigma, reach) = (K::sigma(h, V::DIM), 4.0 * h * h);
        let gscale = sigma / (h * h);
        out.clear();
        for b in 0..self.grid.len() {
            let mut c = [0.0; 3];
            for (d, cd) in c.iter_mut().enumerate().take(V::DIM) {
                *cd = self.w.pos[d][b];
            }
            let xb = V::from_slice(&c[..V::DIM]);
            let psi = self.w.psi[b];
            for run in grid.query(grid.cell_of(xb)).iter() {
                for k in run {
                    let d = at(k) - xb;
                    let r2 = d.length_squared();
                    if r2 < reach {
                        let q = r2.sqrt() / h;
                        out.push((k as u32, b as u32, d * (psi * gscale * K::g(q)), psi * sigma * K::w(q)));
                    }
                }
            }
        }
        out.sort_by_key(|p| p.0);
    }

    /// `find_pairs` into `pairs`, and their `runs`.
    pub(super) fn pair_up<K: Kernel>(&mut self, grid: &CellList, at: impl Fn(usize) -> V, h: Real) {
        let mut pairs = std::mem::take(&mut self.pairs);
        self.find_pairs::<K>(grid, at, h, &mut pairs);
        self.runs.clear();
        let mut a = 0;
        while a < pairs.len() {
            let k = pairs[a].0;
            let e = a + pairs[a..].iter().take_while(|p| p.0 == k).count();
            self.runs.push((k, a as u32, e as u32));
            a = e;
        }
        self.pairs = pairs;
    }

    /// Gives each pushed body its impulse in `dp` (linear, angular about its centre of mass):
    /// its velocity and spin change, and the step's impulse grows; `dp` is kept as `push`.
    pub(super) fn give(&mut self, dp: Vec<(V, [Real; 3])>) {
        for ((body, imp), &(p, l)) in self.bodies.iter_mut().zip(self.impulse.iter_mut()).zip(&dp) {
            if body.inv_mass == 0.0 {
                continue;
            }
            body.v += p * body.inv_mass;
            let [a11, a12, a13, a22, a23, a33] = body.inv_inertia;
            body.w[0] += a11 * l[0] + a12 * l[1] + a13 * l[2];
            body.w[1] += a12 * l[0] + a22 * l[1] + a23 * l[2];
            body.w[2] += a13 * l[0] + a23 * l[1] + a33 * l[2];
            imp.0 += p;
            for c in 0..3 {
                imp.1[c] += l[c];
            }
        }
        self.push = dp;
    }

    /// The velocity of sample `b` now: v + ω × r.
    #[inline(always)]
    pub(super) fn velocity(&self, b: usize) -> V {
        let m = &self.bodies[self.body[b] as usize];
        m.v + omega_cross(m.w, self.offset[b])
    }

    pub(super) fn bytes(&self) -> usize {
        let vb = std::mem::size_of::<V>();
        self.grid.bytes()
            + self.w.bytes()
            + self.body.capacity() * 4
            + self.offset.capacity() * vb
            + self.pairs.capacity() * (8 + vb)
            + self.runs.capacity() * 12
    }
}

/// A fluid's particle spacing (m̄/ρ0)^(1/dim), m̄ the mean of `mass` over the fluids' `ranges`:
/// what the bodies' boundary is sampled at (`MovingBoundary::boundary_sampling`).
pub(super) fn spacing(
    mass: &[Real],
    ranges: impl Iterator<Item = std::ops::Range<usize>>,
    rho0: Real,
    dim: usize,
) -> Real {
    let (mut sum, mut n) = (0.0, 0usize);
    for r in ranges {
        n += r.len();
        sum += mass[r].iter().sum::<Real>();
    }
    let mean = if n > 0 { sum / n as Real } else { 0.0 };
    (mean / rho0).powf(1.0 / dim as Real)
}

/// ω × r for ω = (wx, wy, wz) (2D: only wz) and r of the vector's dimension.
#[inline(always)]
pub(super) fn omega_cross<V: Vector>(w: [Real; 3], r: V) -> V {
    let (x, y) = (r.comp(0), r.comp(1));
    if V::DIM == 2 {
        V::from_slice(&[-w[2] * y, w[2] * x])
    } else {
        let z = r.comp(2);
        V::from_slice(&[w[1] * z - w[2] * y, w[2] * x - w[0] * z, w[0] * y - w[1] * x])
    }
}

/// r × f as three components (2D: (0, 0, r_x f_y − r_y f_x)).
#[inline(always)]
pub(super) fn cross3<V: Vector>(r: V, f: V) -> [Real; 3] {
    let (rx, ry, fx, fy) = (r.comp(0), r.comp(1), f.comp(0), f.comp(1));
    if V::DIM == 2 {
        [0.0, 0.0, rx * fy - ry * fx]
    } else {
        let (rz, fz) = (r.comp(2), f.comp(2));
        [ry * fz - rz * fy, rz * fx - rx * fz, rx * fy - ry * fx]
    }
}

impl<F: Float> WallArrays<F> {
    fn sorted<V: Vector>(grid: &CellList, walls: &[V], psi: &[Real], need: &Need) -> Result<Self> {
        let n = walls.len();
        let mut w = Self::default();
        for d in 0..V::DIM {
            w.pos[d] = need.filled(n + PAD, F::ZERO)?;
            for (o, &i) in w.pos[d].iter_mut().zip(&grid.order) {
                *o = F::of(walls[i as usize].comp(d));
            }
        }
        w.psi = need.filled(n + PAD, F::ZERO)?;
        for (o, &i) in w.psi.iter_mut().zip(&grid.order) {
            *o = F::of(psi[i as usize]);
        }
        Ok(w)
    }

    fn bytes(&self) -> usize {
        (self.pos.iter().map(|v| v.capacity()).sum::<usize>() + self.psi.capacity()) * std::mem::size_of::<F>()
    }
}

impl BufSet {
    /// Heap bytes of the pass buffers (memory-per-particle figures).
    pub(super) fn bytes(&self) -> usize {
        self.b32.bytes() + self.b64.bytes()
    }
}

impl<F: Float> Bufs<F> {
    /// Room for `gather` of `n` particles (and, for several fluids, `gather_fluids`).
    pub(super) fn reserve<V: Vector>(&mut self, n: usize, several: bool, need: &Need) -> Result<()> {
        for d in 0..V::DIM {
            need.reserve(&mut self.pos[d], n + PAD)?;
            need.reserve(&mut self.vel[d], n + PAD)?;
        }
        for a in [&mut self.m, &mut self.rho, &mut self.pr] {
            need.reserve(a, n + PAD)?;
        }
        if several {
            need.reserve(&mut self.fluid, n + PAD)?;
            need.reserve(&mut self.visc, n + PAD)?;
        }
        Ok(())
    }

    /// Positions, velocities and masses into cell order (padded by `PAD`).
    pub(super) fn gather<V: Vector>(&mut self, grid: &CellList, x: &[V], v: Option<&[V]>, m: &[Real]) {
        let n = x.len();
        let order = &grid.order;
        for d in 0..V::DIM {
            self.pos[d].resize(n + PAD, F::ZERO);
            self.vel[d].resize(n + PAD, F::ZERO);
        }
        self.m.resize(n + PAD, F::ZERO);
        self.rho.resize(n + PAD, F::ONE);
        self.pr.resize(n + PAD, F::ZERO);
        let [p0, p1, p2] = &mut self.pos;
        let [v0, v1, v2] = &mut self.vel;
        let ptr = [SyncPtr(p0.as_mut_ptr()), SyncPtr(p1.as_mut_ptr()), SyncPtr(p2.as_mut_ptr())];
        let vptr = [SyncPtr(v0.as_mut_ptr()), SyncPtr(v1.as_mut_ptr()), SyncPtr(v2.as_mut_ptr())];
        // Two loops, so that the one with velocities does not test for them per component (the
        // gather of SPH-2D 160k took 0.28 ms with the test, 0.22 without; Zen 3, 2 threads).
        par::chunks1(&mut self.m[..n], |s, mm| {
            let ord = &order[s..s + mm.len()];
            let put = |k: usize, p: [SyncPtr<F>; 3], a: V| {
                for (d, pd) in p.iter().enumerate().take(V::DIM) {
                    // SAFETY: each sorted slot s + k is written by exactly one chunk.
                    unsafe { *pd.get().add(s + k) = F::of(a.comp(d)) };
                }
            };
            match v {
                Some(v) => {
                    for (k, (mk, &i)) in mm.iter_mut().zip(ord).enumerate() {
                        let i = i as usize;
                        *mk = F::of(m[i]);
                        put(k, ptr, x[i]);
                        put(k, vptr, v[i]);
                    }
                }
                None => {
                    for (k, (mk, &i)) in mm.iter_mut().zip(ord).enumerate() {
                        let i = i as usize;
                        *mk = F::of(m[i]);
                        put(k, ptr, x[i]);
                        put(k, vptr, V::ZERO);
                    }
                }
            }
        });
    }

    /// Several fluids: each particle's fluid (`fluid`, by particle) and α c0 h (`visc`, by
    /// fluid) into cell order.
    pub(super) fn gather_fluids(&mut self, grid: &CellList, fluid: &[u8], visc: &[Real]) {
        let n = fluid.len();
        self.fluid.resize(n + PAD, 0);
        self.visc.resize(n + PAD, F::ZERO);
        let vp = SyncPtr(self.visc.as_mut_ptr());
        par::chunks1(&mut self.fluid[..n], |s, out| {
            for (k, o) in out.iter_mut().enumerate() {
                let f = fluid[grid.order[s + k] as usize];
                *o = f;
                // SAFETY: each sorted slot s + k is written by exactly one chunk.
                unsafe { *vp.get().add(s + k) = F::of(visc[f as usize]) };
            }
        });
    }

    /// Heap bytes held.
    fn bytes(&self) -> usize {
        let s = std::mem::size_of::<F>();
        (self.pos.iter().chain(&self.vel).map(|v| v.capacity()).sum::<usize>()
            + self.m.capacity()
            + self.rho.capacity()
            + self.pr.capacity()
            + self.visc.capacity())
            * s
            + self.fluid.capacity()
    }
}
