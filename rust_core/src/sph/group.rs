//! Fluids that share one neighbour search: a `Group` of up to `MAX_FLUIDS` fluids with the same
//! smoothing length, kernel and pass precision (each an `Sph` term of its own, with its own
//! equation of state, viscosity, walls and energy books).
//!
//! One evaluation of the group builds one cell list over the particles of all its fluids,
//! gathers them into cell order, and runs the density pass then the force pass over all of them
//! (`passes`, whose several-fluid path gives each particle its own fluid's equation of state and
//! walls): each fluid's density counts the other fluids' particles and their pressures push on
//! each other, with the symmetric pair force, so momentum is conserved across fluids and the
//! internal energy of each fluid plus the viscous dissipation still balance the books.
//!
//! Who evaluates: the system evaluates its terms in the order they were added, so the group's
//! first fluid is always called first in a force evaluation. It evaluates the group and marks
//! the result fresh for the others, which then only copy their share; a member that finds no
//! fresh result (it is never called before the first, but a test may call it alone) evaluates
//! the group itself.
//!
//! A group of one fluid is today's single fluid: the passes take their one-fluid path and the
//! evaluation reads the scene's arrays in place, with no copy into the group's order.
use super::buffers::{cross3, BufSet, Bufs, MovingWalls, PassFloat, Walls, PAD};
use super::kernels::{CubicSpline, Float, WendlandC2};
use super::params::KernelKind;
use super::params::{Precision, SphParams};
use super::passes::{self, FluidView, Sums, MAX_FLUIDS};
use crate::alloc::{count, Need};
use crate::error::Result;
use crate::neighbors::CellList;
use crate::simd::Level;
use crate::stop::Stop;
use crate::terms::BodyMotion;
use crate::terms::Write;
use crate::vector::{Real, Vector};
use std::ops::Range;
use std::sync::atomic::Ordering;

/// One fluid of a group.
pub(super) struct Member {
    /// Its particles in the scene.
    pub(super) range: Range<usize>,
    /// Where they start in the group's order (the members' particles, member after member).
    offset: usize,
    pub(super) p: SphParams,
    pub(super) walls: Walls,
}

pub(super) struct Group<V: Vector> {
    pub(super) members: Vec<Member>,
    /// Each particle's fluid, in the group's order (several fluids only).
    fluid_of: Vec<u8>,
    grid: CellList,
    bufs: BufSet,
    /// Several fluids: the members' positions, velocities, masses and forces in the group's
    /// order.
    x: Vec<V>,
    v: Vec<V>,
    m: Vec<Real>,
    forces: Vec<V>,
    /// One fluid: the other terms' forces, kept while the passes write the fluid's.
    prev: Vec<V>,
    /// Per member: dissipated power and max |a|² of the last evaluation.
    pub(super) sums: Sums,
    /// Per member: whether the last evaluation's forces are still to be copied by it.
    fresh: [bool; MAX_FLUIDS],
    /// Wall time spent so far in (cell list + gather, density pass, force pass), s.
    pub(super) clock: [f64; 3],
    /// The rigid bodies' boundary particles (`terms::MovingBoundary`), once a coupling has set
    /// them: counted in the density like the walls (Akinci et al. 2012, eq. 4–5), pushing with
    /// −m_i Ψ_b (p_i/ρ_i²) ∇W_ib (eq. 10) and pushed back (eq. 11); `impulse` sums the forces
    /// on each body over the evaluations since (`evals` of them).
    moving: Option<MovingWalls<V>>,
    evals: u32,
}

impl<V: Vector> Group<V> {
    /// A group of the one fluid over particles `range`.
    pub(super) fn new(range: Range<usize>, p: SphParams, walls: Walls) -> Result<Self> {
        Ok(Self {
            members: vec![Member { range, offset: 0, p, walls }],
            fluid_of: Vec::new(),
            grid: CellList::new(2.0 * p.h, V::DIM)?,
            bufs: BufSet::default(),
            x: Vec::new(),
            v: Vec::new(),
            m: Vec::new(),
            forces: Vec::new(),
            prev: Vec::new(),
            sums: Sums::default(),
            fresh: [false; MAX_FLUIDS],
            clock: [0.0; 3],
            moving: None,
            evals: 0,
        })
    }

    /// The key under which groups register (`neighbors::Shared`): fluids share passes when
    /// their support, kernel and pass precision agree.
    pub(super) fn key(p: &SphParams) -> String {
        format!("sph h={:#x} {:?} {:?}", p.h.to_bits(), p.kernel, p.precision)
    }

    /// Whether a fluid over `range` can join: room left, and no particle in two fluids.
    pub(super) fn admits(&self, range: &Range<usize>) -> bool {
        !self.full() && self.members.iter().all(|m| m.range.end <= range.start || range.end <= m.range.start)
    }

    pub(super) fn full(&self) -> bool {
        self.members.len() == MAX_FLUIDS
    }

    /// Adds `m` as the last member; returns its index.
    pub(super) fn join(&mut self, m: Member) -> usize {
        self.members.push(m);
        let mut offset = 0;
        self.fluid_of.clear();
        for (f, m) in self.members.iter_mut().enumerate() {
            m.offset = offset;
            offset += m.range.len();
            self.fluid_of.extend(std::iter::repeat_n(f as u8, m.range.len()));
        }
        self.fresh = [false; MAX_FLUIDS];
        self.members.len() - 1
    }

    /// Takes the only member out (to join another group).
    pub(super) fn into_member(self) -> Member {
        self.members.into_iter().next().expect("a group has a member")
    }

    pub(super) fn len(&self) -> usize {
        self.members.iter().map(|m| m.range.len()).sum()
    }

    fn several(&self) -> bool {
        self.members.len() > 1
    }

    /// Whether any pair of the group dissipates (a pair's viscosity is the mean of its fluids').
    pub(super) fn dissipative(&self) -> bool {
        self.members.iter().any(|m| m.p.alpha > 0.0)
    }

    /// Heap bytes of the shared grid and buffers (memory-per-particle figures).
    pub(super) fn bytes(&self) -> usize {
        let v = std::mem::size_of::<V>();
        self.grid.bytes()
            + self.bufs.bytes()
            + self.members.iter().map(|m| m.walls.bytes()).sum::<usize>()
            + (self.x.capacity() + self.v.capacity() + self.forces.capacity() + self.prev.capacity()) * v
            + self.m.capacity() * 8
            + self.fluid_of.capacity()
    }

    /// Reserves, fallibly, everything an evaluation of the group allocates.
    pub(super) fn reserve(&mut self) -> Result<()> {
        let n = self.len();
        let precision = self.members[0].p.precision;
        let (f, arrays) = (
            match precision {
                Precision::F32 => 4,
                Precision::F64 => 8,
            },
            2 * V::DIM + 3 + if self.several() { 1 } else { 0 },
        );
        let copies = if self.several() { 3 } else { 1 };
        let bytes = (arrays * (n + PAD) * f) as u128 + copies * Need::bytes_of::<V>(n) + (n as u128) * 9;
        let need = Need::new("step", bytes, format!("the SPH buffers of {} particles", count(n as u128)));
        need.check()?;
        let several = self.several();
        match precision {
            Precision::F32 => self.bufs.b32.reserve::<V>(n, several, &need)?,
            Precision::F64 => self.bufs.b64.reserve::<V>(n, several, &need)?,
        }
        if several {
            for a in [&mut self.x, &mut self.v, &mut self.forces] {
                need.reserve(a, n)?;
            }
            need.reserve(&mut self.m, n)?;
        } else {
            need.reserve(&mut self.prev, n)?;
        }
        self.grid.reserve(n, "step")
    }

    /// Stores member `who`'s SPH forces (N) in `f[its range]` as `write` says, evaluating the
    /// group first unless a fresh result waits for this member (see the module docs); `sums`
    /// then holds each member's dissipated power (W; 0 unless the group is dissipative) and
    /// max |a|².
    #[allow(clippy::too_many_arguments)]
    pub(super) fn forces(
        &mut self,
        who: usize,
        level: Level,
        x: &[V],
        v: &[V],
        mass: &[Real],
        f: &mut [V],
        write: Write,
        stop: &Stop,
    ) {
        let r = self.members[who].range.clone();
        if !self.several() {
            // In place: the pass writes the fluid's forces over `f`; to add, keep what was there.
            let mut prev = std::mem::take(&mut self.prev);
            prev.clear();
            if write == Write::Add {
                prev.extend_from_slice(&f[r.clone()]);
            }
            let (xs, vs, ms) = (&x[r.clone()], &v[r.clone()], &mass[r.clone()]);
            self.sums = self.eval_in(level, xs, vs, ms, &mut f[r.clone()], stop);
            if write == Write::Add {
                for (fi, pi) in f[r].iter_mut().zip(&prev) {
                    *fi += *pi;
                }
            }
            self.prev = prev;
            return;
        }
        if who == 0 || !self.fresh[who] {
            let (mut gx, mut gv, mut gm, mut out) = (
                std::mem::take(&mut self.x),
                std::mem::take(&mut self.v),
                std::mem::take(&mut self.m),
                std::mem::take(&mut self.forces),
            );
            gx.clear();
            gv.clear();
            gm.clear();
            for m in &self.members {
                gx.extend_from_slice(&x[m.range.clone()]);
                gv.extend_from_slice(&v[m.range.clone()]);
                gm.extend_from_slice(&mass[m.range.clone()]);
            }
            out.resize(gx.len(), V::ZERO);
            self.sums = self.eval_in(level, &gx, &gv, &gm, &mut out, stop);
            (self.x, self.v, self.m, self.forces) = (gx, gv, gm, out);
            self.fresh = [true; MAX_FLUIDS];
        }
        self.fresh[who] = false;
        let o = self.members[who].offset;
        for (fi, gi) in f[r.clone()].iter_mut().zip(&self.forces[o..o + r.len()]) {
            write.put(fi, *gi);
        }
    }

    /// One evaluation over the group's particles `x, v, m` (in the group's order) into `out`, in
    /// the pass precision.
    fn eval_in(&mut self, level: Level, x: &[V], v: &[V], m: &[Real], out: &mut [V], stop: &Stop) -> Sums {
        match self.members[0].p.precision {
            Precision::F32 => self.eval::<f32>(level, x, v, m, out, stop),
            Precision::F64 => self.eval::<f64>(level, x, v, m, out, stop),
        }
    }

    /// One evaluation in precision `F`: build the cell list, gather, density pass, force pass.
    /// Once the stop flag is set the rest is skipped and `out` is left partly written.
    fn eval<F: PassFloat>(&mut self, level: Level, x: &[V], v: &[V], m: &[Real], out: &mut [V], stop: &Stop) -> Sums {
        let want_power = self.dissipative();
        let Self { members, fluid_of, grid, bufs, clock, moving, evals, .. } = self;
        let (b, stop) = (F::bufs(bufs), stop.flag());
        let stopped = || stop.load(Ordering::Relaxed);
        let t0 = std::time::Instant::now();
        grid.build(x);
        if stopped() {
            return Sums::default();
        }
        b.gather(grid, x, Some(v), m);
        if members.len() > 1 {
            let mut visc = [0.0; MAX_FLUIDS];
            for (c, m) in visc.iter_mut().zip(members.iter()) {
                *c = m.p.alpha * m.p.c0 * m.p.h;
            }
            b.gather_fluids(grid, fluid_of, &visc);
        }
        let views = views::<F>(members);
        let p = &members[0].p;
        let t1 = std::time::Instant::now();
        passes::density::<V, F>(level, p, grid, &views[..members.len()], b, stop);
        if let Some(mw) = moving.as_mut() {
            match p.kernel {
                KernelKind::CubicSpline => mw.pair_up::<CubicSpline>(grid, |k| x[grid.order[k] as usize], p.h),
                KernelKind::WendlandC2 => mw.pair_up::<WendlandC2>(grid, |k| x[grid.order[k] as usize], p.h),
            }
            boundary_density(mw, members, b);
        }
        let t2 = std::time::Instant::now();
        clock[0] += (t1 - t0).as_secs_f64();
        clock[1] += (t2 - t1).as_secs_f64();
        if stopped() {
            return Sums::default();
        }
        let sums = passes::forces::<V, F>(level, p, grid, &views[..members.len()], b, out, want_power, stop);
        if let Some(mw) = moving.as_mut() {
            boundary_forces(mw, grid, b, out);
            *evals += 1;
        }
        clock[2] += t2.elapsed().as_secs_f64();
        sums
    }

    /// Density (kg/m^dim) of every particle of the group, in the group's order, computed now in
    /// f64 (scratch of its own: the evaluation buffers are left as they are).
    pub(super) fn densities(&self, x: &[V], mass: &[Real]) -> Vec<Real> {
        let (mut gx, mut gm) = (Vec::with_capacity(self.len()), Vec::with_capacity(self.len()));
        for m in &self.members {
            gx.extend_from_slice(&x[m.range.clone()]);
            gm.extend_from_slice(&mass[m.range.clone()]);
        }
        let mut grid = CellList::new(self.grid.cell_size(), V::DIM).expect("valid cell size");
        let mut b = Bufs::<f64>::default();
        grid.build(&gx);
        b.gather(&grid, &gx, None, &gm);
        if self.several() {
            b.gather_fluids(&grid, &self.fluid_of, &[0.0; MAX_FLUIDS]);
        }
        let views = views::<f64>(&self.members);
        let never = Stop::default();
        let views = &views[..self.members.len()];
        let p = &self.members[0].p;
        passes::density::<V, f64>(crate::simd::level(), p, &grid, views, &mut b, never.flag());
        if let Some(mw) = &self.moving {
            let mut pairs = Vec::new();
            match p.kernel {
                KernelKind::CubicSpline => {
                    mw.find_pairs::<CubicSpline>(&grid, |k| gx[grid.order[k] as usize], p.h, &mut pairs)
                }
                KernelKind::WendlandC2 => {
                    mw.find_pairs::<WendlandC2>(&grid, |k| gx[grid.order[k] as usize], p.h, &mut pairs)
                }
            }
            for &(k, _, _, w) in &pairs {
                b.rho[k as usize] += w;
            }
        }
        let mut rho = vec![0.0; gx.len()];
        for (k, &i) in grid.order.iter().enumerate() {
            rho[i as usize] = b.rho[k];
        }
        rho
    }

    /// The boundary of the next step (`MovingBoundary::set_boundary`).
    pub(super) fn set_boundary(&mut self, x: &[V], psi: &[Real], body: &[u32], offset: &[V], bodies: &[BodyMotion<V>]) {
        self.evals = 0;
        if x.is_empty() {
            self.moving = None;
            return;
        }
        let support = 2.0 * self.members[0].p.h;
        let mw = self.moving.get_or_insert_with(|| MovingWalls::new(support).expect("a valid support"));
        mw.set(x, psi, body, offset, bodies);
    }

    /// The impulse on each body over a step of `dt`: the mean force of the evaluations since
    /// the boundary was set (one a step for semi-implicit Euler and velocity Verlet) times dt.
    pub(super) fn boundary_impulses(&self, dt: Real, out: &mut Vec<(V, [Real; 3])>) {
        out.clear();
        if let Some(mw) = &self.moving {
            let s = if self.evals > 0 { dt / self.evals as Real } else { 0.0 };
            out.extend(mw.impulse.iter().map(|(f, l)| (*f * s, l.map(|c| c * s))));
        }
    }

    /// Member `who`'s share of a group-order array.
    pub(super) fn share_of<'a, T>(&self, who: usize, a: &'a [T]) -> &'a [T] {
        let m = &self.members[who];
        &a[m.offset..m.offset + m.range.len()]
    }
}

/// The members as the passes see them, on the stack (an evaluation allocates nothing); slots past
/// the last member repeat it and are not read: pass `&views[..members.len()]`.
fn views<F: PassFloat>(members: &[Member]) -> [FluidView<'_, F>; MAX_FLUIDS] {
    std::array::from_fn(|k| {
        let m = &members[k.min(members.len() - 1)];
        FluidView::new(&m.p, &m.walls.grid, F::walls(&m.walls))
    })
}

/// The boundary's density Σ_b Ψ_b W_kb added to each sorted particle's ρ that has any, and its
/// p/ρ² recomputed with its fluid's equation of state.
fn boundary_density<V: Vector, F: Float>(mw: &MovingWalls<V>, members: &[Member], b: &mut Bufs<F>) {
    for &(k, a, e) in &mw.runs {
        let k = k as usize;
        let extra: Real = mw.pairs[a as usize..e as usize].iter().map(|p| p.3).sum();
        let rho = b.rho[k].f64() + extra;
        let p = if members.len() > 1 { &members[b.fluid[k] as usize].p } else { &members[0].p };
        b.rho[k] = F::of(rho);
        b.pr[k] = F::of(p.pressure(rho) / (rho * rho));
    }
}

/// The boundary's pressure force on each particle near it, −m_k (p_k/ρ_k²) Ψ_b ∇W_kb (Akinci
/// 2012, eq. 10: free slip), added into `out` (the group's order), and its reaction on each
/// body at the sample (eq. 11) added to `mw.impulse` (force, torque about the centre of mass).
fn boundary_forces<V: Vector, F: Float>(mw: &mut MovingWalls<V>, grid: &CellList, b: &Bufs<F>, out: &mut [V]) {
    let MovingWalls { pairs, runs, body, offset, impulse, .. } = mw;
    for &(k, a, e) in runs.iter() {
        let k = k as usize;
        let s = b.m[k].f64() * b.pr[k].f64();
        let mut fk = V::ZERO;
        for &(_, sb, g, _) in &pairs[a as usize..e as usize] {
            let f = g * s;
            fk += f;
            let (imp, l) = (&mut impulse[body[sb as usize] as usize], cross3(offset[sb as usize], f));
            imp.0 += f;
            for c in 0..3 {
                imp.1[c] += l[c];
            }
        }
        out[grid.order[k] as usize] -= fk;
    }
}
