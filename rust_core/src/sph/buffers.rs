//! The data the passes read, in cell order: the static wall particles (`Walls`, sorted once at
//! construction) and the per-evaluation structure-of-arrays buffers (`Bufs`, one set per
//! precision, `BufSet`): the gather of positions, velocities and masses into cell order, the
//! wall arrays in the pass precision, and the reservation that makes a step allocation-free.
use super::kernels::Float;
use crate::alloc::{count, Need};
use crate::error::Result;
use crate::neighbors::CellList;
use crate::par::{self, SyncPtr};
use crate::vector::{Real, Vector};

/// Static wall particles: positions, Ψ_b = ρ0 V_b (kg/m^dim · m^dim = kg), sorted into cells.
#[derive(Clone, Debug)]
pub(super) struct Walls {
    pub(super) grid: CellList,
    pos: [Vec<f64>; 3],
    psi: Vec<f64>,
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
    pub(super) wpos: [Vec<F>; 3],
    pub(super) wpsi: Vec<F>,
}

/// Loads past the end of a run read up to `PAD` padding entries (masked out).
pub(super) const PAD: usize = 16;

/// The pass buffers of both precisions (the wall arrays of both are set at construction; the
/// particle arrays of the one in use are filled by each evaluation).
#[derive(Clone, Debug, Default)]
pub(super) struct BufSet {
    pub(super) b32: Bufs<f32>,
    pub(super) b64: Bufs<f64>,
}

/// A pass precision (f32 or f64): picks its buffers out of a `BufSet`, so that an evaluation is
/// written once, generic over the precision.
pub(super) trait PassFloat: Float {
    fn bufs(set: &mut BufSet) -> &mut Bufs<Self>;
}

impl PassFloat for f32 {
    fn bufs(set: &mut BufSet) -> &mut Bufs<f32> {
        &mut set.b32
    }
}

impl PassFloat for f64 {
    fn bufs(set: &mut BufSet) -> &mut Bufs<f64> {
        &mut set.b64
    }
}

impl BufSet {
    /// The wall particles `walls` (finite) with their Ψ (`psi`, one each) sorted into cells of
    /// side `support`, and the buffers of both precisions holding them.
    pub(super) fn with_walls<V: Vector>(walls: &[V], psi: &[Real], support: Real) -> Result<(Walls, Self)> {
        let nw = walls.len();
        // Sorted copies in f64, f32 and f64 pass buffers (positions and Ψ).
        let bytes = ((nw + PAD) * (V::DIM + 1) * (8 + 4 + 8)) as u128;
        let need = Need::new("add_fluid", bytes, format!("{} wall particles", count(nw as u128)));
        need.check()?;
        let mut wg = CellList::new(support, V::DIM)?;
        wg.reserve(nw, "add_fluid")?;
        wg.build(walls);
        let mut pos: [Vec<f64>; 3] = Default::default();
        for (d, pd) in pos.iter_mut().enumerate().take(V::DIM) {
            *pd = need.filled(nw + PAD, 0.0)?;
            for (o, &i) in pd.iter_mut().zip(&wg.order) {
                *o = walls[i as usize].comp(d);
            }
        }
        let mut spsi = need.filled(nw + PAD, 0.0)?;
        for (o, &i) in spsi.iter_mut().zip(&wg.order) {
            *o = psi[i as usize];
        }
        let walls = Walls { grid: wg, pos, psi: spsi };
        let mut set = Self::default();
        set.b32.set_walls(&walls, &need)?;
        set.b64.set_walls(&walls, &need)?;
        Ok((walls, set))
    }

    /// Heap bytes of the pass buffers (memory-per-particle figures).
    pub(super) fn bytes(&self) -> usize {
        self.b32.bytes() + self.b64.bytes()
    }
}

impl<F: Float> Bufs<F> {
    /// Room for `gather` of `n` particles.
    pub(super) fn reserve<V: Vector>(&mut self, n: usize, need: &Need) -> Result<()> {
        for d in 0..V::DIM {
            need.reserve(&mut self.pos[d], n + PAD)?;
            need.reserve(&mut self.vel[d], n + PAD)?;
        }
        for a in [&mut self.m, &mut self.rho, &mut self.pr] {
            need.reserve(a, n + PAD)?;
        }
        Ok(())
    }

    fn set_walls(&mut self, w: &Walls, need: &Need) -> Result<()> {
        for d in 0..3 {
            self.wpos[d] = need.collect(w.pos[d].iter().map(|&a| F::of(a)))?;
        }
        self.wpsi = need.collect(w.psi.iter().map(|&a| F::of(a)))?;
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
        par::chunks1(&mut self.m[..n], |s, mm| {
            for (k, mk) in mm.iter_mut().enumerate() {
                let i = order[s + k] as usize;
                *mk = F::of(m[i]);
                for d in 0..V::DIM {
                    // SAFETY: each sorted slot s + k is written by exactly one chunk.
                    unsafe {
                        *ptr[d].get().add(s + k) = F::of(x[i].comp(d));
                        *vptr[d].get().add(s + k) = F::of(v.map_or(0.0, |v| v[i].comp(d)));
                    }
                }
            }
        });
    }

    /// Heap bytes held.
    fn bytes(&self) -> usize {
        let s = std::mem::size_of::<F>();
        (self.pos.iter().chain(&self.vel).chain(&self.wpos).map(|v| v.capacity()).sum::<usize>()
            + self.m.capacity()
            + self.rho.capacity()
            + self.pr.capacity()
            + self.wpsi.capacity())
            * s
    }
}
