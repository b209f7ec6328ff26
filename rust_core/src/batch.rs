//! Many small worlds stepped together: the fused kernel of a batch (the `Batch` of the facade).
//!
//! A batch of three-body problems spends almost all of its time in what a general step does
//! around the physics (dispatch over terms, the SIMD sum's padding to 16 sources, the books'
//! bookkeeping, the parallel loops' set-up): ~0.45 µs a step for ~100 floating-point operations.
//! Members that are plain small N-body problems (`World::fused_shape`: float64, at most
//! `pairwise_small::SMALL` bodies, gravity or Coulomb by the small pairwise sum plus uniform
//! fields, velocity Verlet or Yoshida's fourth order, nothing else) are instead stepped here,
//! one member per SIMD lane (MuJoCo's `rollout` and JAX's `vmap` over a batch are the model):
//! a chunk of 2, 4, 8 or 16 members (two vectors of the level's float64 lanes, two dependency
//! chains in flight) runs all its steps in registers.
//!
//! Every member keeps the bits it has alone, for any thread count and chunking: the kernel runs
//! the very operations of `VelocityVerlet::step` (`accel`, the kick, the drift) and of the force
//! evaluation (`pairwise_small::small_sum`, written once over a `Lane` for both), each an IEEE
//! `+ − × ÷ √` done lane by lane, never fused, so a lane computes what the scalar code computes.
//! The rest of a step (the clock, advanced by dt a step in the lanes too; the force cache; the
//! count of force evaluations) is written back as the general step leaves it. A member that
//! ends non-finite (a non-finite position or velocity stays non-finite: no operation of the
//! step makes it finite again) is stepped again alone from the call's start by the general
//! step, which reports its divergence and rolls it back as it would alone. The stop flag is
//! read every `POLL` steps; once set, the chunk stops (`Error::Interrupted`).
//!
//! Nothing is written to a fused member until the caller keeps the call (`Call::end`): the
//! kernel works on the chunk's pack, so a fused member needs no checkpoint, and a call undone
//! after it ran (a Ctrl-C as it finished) just drops the packs. Around the kernel a member then
//! costs a few hundred nanoseconds (its checks, its gather and its write-back), which at 1,000
//! steps is a few per cent of its kernel time.
use crate::error::{Error, Result};
use crate::integrators::yoshida::{W0, W1};
use crate::simd::{self, Kernel, Level, Simd, P};
use crate::systems::particles::{Scheme, Shape};
use crate::terms::pairwise_small::{small_sum, Lane, SMALL};
use crate::vector::{Real, Vector};
use crate::world::{Checkpoint, World};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Worlds with their index in the call.
type Members<'a, V> = Vec<(usize, &'a mut World<V>)>;

/// Steps between two reads of the stop flag.
const POLL: u64 = 256;

/// What one world's part of a call came to.
enum Outcome {
    /// Its general step ran: the checkpoint at the call's start.
    Stepped(Checkpoint),
    /// The fused kernel stepped it in lane `lane` of `Call::packs[pack]`; nothing of it has
    /// been written to the world yet (`Call::end`).
    Fused { pack: usize, lane: usize },
    /// It failed as it would alone, and is back where the call started (or was never changed).
    Failed(Error),
    /// `Call::end` has run for it.
    Ended,
}

/// A call of `step_worlds`, not yet ended: each world's part is ended with `Call::end`, kept
/// (a fused member written back, a checkpoint released) or undone (back where the call
/// started). So a fused member needs no checkpoint: it is not touched until it is kept, and a
/// call undone after the kernel ran (a signal arriving as it finished) just drops its packs.
pub struct Call {
    outcomes: Vec<Outcome>,
    packs: Vec<Pack>,
    n: u64,
}

impl Call {
    /// A call whose worlds all took their general step (`World::step_checkpointed`).
    pub fn general(outcomes: Vec<Result<Checkpoint>>, n: u64) -> Call {
        let outcomes = outcomes.into_iter().map(|o| o.map_or_else(Outcome::Failed, Outcome::Stepped)).collect();
        Call { outcomes, packs: Vec::new(), n }
    }

    /// The number of worlds in the call.
    pub fn len(&self) -> usize {
        self.outcomes.len()
    }

    /// Whether the call has no world.
    pub fn is_empty(&self) -> bool {
        self.outcomes.is_empty()
    }

    /// The first world that failed for want of memory, and its error (a copy): the caller rolls
    /// every world back then, since the others stepped and the refusal says nothing changed.
    pub fn out_of_memory(&self) -> Option<(usize, Error)> {
        self.outcomes.iter().enumerate().find_map(|(k, o)| match o {
            Outcome::Failed(e @ Error::OutOfMemory { .. }) => Some((k, e.clone())),
            _ => None,
        })
    }

    /// Ends world `k`'s part (`world` is the call's world `k`). `keep`: its `n` steps stay
    /// (a fused member is written back as its general step would have left it) and this is
    /// `Ok`, or the error it failed with (it is back where the call started). Not `keep`: it is
    /// back where the call started, and this is `Ok`. A second end of the same world does
    /// nothing.
    pub fn end<V: Vector>(&mut self, k: usize, world: &mut World<V>, keep: bool) -> Result<()> {
        match std::mem::replace(&mut self.outcomes[k], Outcome::Ended) {
            Outcome::Stepped(cp) if keep => world.release(cp),
            Outcome::Stepped(cp) => {
                world.rollback(cp);
            }
            Outcome::Fused { pack, lane } if keep => self.packs[pack].scatter(lane, world, self.n),
            Outcome::Failed(e) if keep => return Err(e),
            Outcome::Fused { .. } | Outcome::Failed(_) | Outcome::Ended => {}
        }
        Ok(())
    }

    /// Ends every world's part, keeping it (`end`): per world, `Ok` or its error.
    pub fn keep_all<V: Vector>(mut self, worlds: Vec<&mut World<V>>) -> Vec<Result<()>> {
        worlds.into_iter().enumerate().map(|(k, w)| self.end(k, w, true)).collect()
    }
}

/// Steps each of `worlds` `n` steps, as `World::step_checkpointed` does, in parallel on the
/// current rayon pool: the members `World::fused_shape` admits through the fused kernel at
/// `level`, the others by their general step; the caller ends the call (`Call::end`). Results
/// do not depend on the pool's size. The level is an argument, read once by the caller: the
/// chunks' width, the packs and the kernel must agree on it, and the process-wide level may
/// be changed meanwhile (by another thread, or a test of another level running beside this one).
pub fn step_worlds<V: Vector>(worlds: Vec<&mut World<V>>, n: u64, stop: &Arc<AtomicBool>, level: Level) -> Call {
    let count = worlds.len();
    let mut general = Vec::new();
    let mut groups: BTreeMap<Shape, Members<'_, V>> = BTreeMap::new();
    for (k, w) in worlds.into_iter().enumerate() {
        // (No steps: nothing for the kernel; the general step's bookkeeping is all there is.)
        match w.fused_shape().filter(|_| n > 0) {
            Some(shape) => groups.entry(shape).or_default().push((k, w)),
            None => general.push((k, w)),
        }
    }
    let lanes = chunk_width(level);
    let mut chunks: Vec<(Shape, Members<'_, V>)> = Vec::new();
    for (shape, members) in groups {
        let mut it = members.into_iter().peekable();
        while it.peek().is_some() {
            chunks.push((shape, it.by_ref().take(lanes).collect()));
        }
    }
    let general_out: Vec<(usize, Result<Checkpoint>)> =
        general.into_par_iter().map(|(k, w)| (k, w.step_checkpointed(n, stop))).collect();
    let fused_out: Vec<Chunk> =
        chunks.into_par_iter().map(|(shape, members)| step_chunk(shape, members, n, stop, level)).collect();
    let mut outcomes: Vec<Outcome> = (0..count).map(|_| Outcome::Ended).collect();
    for (k, r) in general_out {
        outcomes[k] = r.map_or_else(Outcome::Failed, Outcome::Stepped);
    }
    let mut packs = Vec::with_capacity(fused_out.len());
    for chunk in fused_out {
        for (k, o) in chunk.outcomes {
            // A fused outcome's pack is this chunk's, numbered here.
            outcomes[k] = match o {
                Outcome::Fused { lane, .. } => Outcome::Fused { pack: packs.len(), lane },
                o => o,
            };
        }
        packs.extend(chunk.pack);
    }
    Call { outcomes, packs, n }
}

/// Members a chunk steps together: two vectors of the level's float64 lanes (`Two`).
fn chunk_width(level: Level) -> usize {
    2 * simd::dispatch(level, Lanes)
}

/// The float64 lanes of the level (1, 2, 4 or 8).
struct Lanes;
impl Kernel for Lanes {
    type Output = usize;
    #[inline(always)]
    fn run<S: Simd>(self, _s: S) -> usize {
        P::<S, f64>::lanes()
    }
}

/// One chunk's part of a call: each member's outcome (a fused one names its lane of `pack`).
struct Chunk {
    outcomes: Vec<(usize, Outcome)>,
    pack: Option<Pack>,
}

/// One chunk: each member checked (`World::begin_fused`), the fused kernel over those that run,
/// into a pack that `Call::end` writes back; a member that ended non-finite is stepped again
/// alone by its general step (which finds the step, and rolls it back, as alone).
fn step_chunk<V: Vector>(shape: Shape, members: Members<'_, V>, n: u64, stop: &Arc<AtomicBool>, level: Level) -> Chunk {
    let mut outcomes = Vec::with_capacity(members.len());
    let mut running: Vec<(usize, &mut World<V>)> = Vec::with_capacity(members.len());
    for (k, w) in members {
        match w.begin_fused(n) {
            Err(e) => outcomes.push((k, Outcome::Failed(e))),
            Ok(()) => running.push((k, w)),
        }
    }
    if running.is_empty() {
        return Chunk { outcomes, pack: None };
    }
    let mut pack = Pack::gather(shape, level, running.iter_mut().map(|(_, w)| &mut **w));
    if !simd::dispatch(level, Run { pack: &mut pack, steps: n, stop }) {
        // Stopped: nothing was written to the members.
        for (k, w) in running {
            outcomes.push((k, Outcome::Failed(Error::Interrupted { rolled_back_to: w.steps() })));
        }
        return Chunk { outcomes, pack: None };
    }
    for (lane, (k, w)) in running.into_iter().enumerate() {
        outcomes.push((
            k,
            if pack.finite(lane) {
                Outcome::Fused { pack: 0, lane }
            } else {
                w.step_checkpointed(n, stop).map_or_else(Outcome::Failed, Outcome::Stepped)
            },
        ));
    }
    Chunk { outcomes, pack: Some(pack) }
}

/// A chunk's members in structure-of-arrays form, member `l` in lane `l` of every row
/// (lanes past the members repeat member 0; nothing is read back from them). Vectors are
/// stored lane-minor: component c of particle i is `x[(3 i + c) L .. (3 i + c + 1) L]`.
struct Pack {
    shape: Shape,
    lanes: usize,
    x: Vec<f64>,
    v: Vec<f64>,
    /// The force at x (N): the integrator's cache where it had one.
    f: Vec<f64>,
    /// 1 where the member's cache holds f, 0 where the kernel evaluates it first.
    cached: Vec<f64>,
    /// Source weights (masses or charges), the receivers' c·w_i, inverse masses.
    w: Vec<f64>,
    cw: Vec<f64>,
    im: Vec<f64>,
    g: Vec<f64>,
    eps2: Vec<f64>,
    dt: Vec<f64>,
    /// Each member's clock, advanced by dt a step (the general step's `t += dt`).
    t: Vec<f64>,
    /// Force evaluations the kernel adds to each member's count.
    evals: Vec<u64>,
}

impl Pack {
    fn gather<'a, V: Vector + 'a>(shape: Shape, level: Level, worlds: impl Iterator<Item = &'a mut World<V>>) -> Pack {
        let lanes = chunk_width(level);
        let n = shape.n;
        let mut p = Pack {
            shape,
            lanes,
            x: vec![0.0; 3 * n * lanes],
            v: vec![0.0; 3 * n * lanes],
            f: vec![0.0; 3 * n * lanes],
            cached: vec![0.0; lanes],
            w: vec![0.0; n * lanes],
            cw: vec![0.0; n * lanes],
            im: vec![0.0; n * lanes],
            g: vec![0.0; 3 * lanes],
            eps2: vec![0.0; lanes],
            dt: vec![0.0; lanes],
            t: vec![0.0; lanes],
            evals: Vec::new(),
        };
        let mut members = 0;
        for (l, world) in worlds.enumerate() {
            let (dt, t) = (world.dt, world.time());
            let (sys, integrator) = world.particles_mut().fused_parts();
            let (c, eps2, w) = sys
                .forces
                .terms
                .iter()
                .find_map(|t| t.as_fused().and_then(|f| f.small_pairwise(&sys.model, n)))
                .expect("a fused member has its small pairwise sum");
            // The force cache, read in place (a fused member's integrator keeps one).
            let cache = integrator.as_carry().and_then(|c| c.borrow()).map(|(f, _)| f);
            for i in 0..n {
                for k in 0..V::DIM {
                    let at = (3 * i + k) * lanes + l;
                    p.x[at] = sys.state.x[i].comp(k);
                    p.v[at] = sys.state.v[i].comp(k);
                    if let Some(f) = cache {
                        p.f[at] = f[i].comp(k);
                    }
                }
                p.w[i * lanes + l] = w[i];
                p.cw[i * lanes + l] = c * w[i];
                p.im[i * lanes + l] = sys.model.inv_mass[i];
            }
            for k in 0..V::DIM {
                p.g[k * lanes + l] = sys.forces.g.comp(k);
            }
            p.cached[l] = if cache.is_some() { 1.0 } else { 0.0 };
            p.eps2[l] = eps2;
            p.dt[l] = dt;
            p.t[l] = t;
            p.evals.push(u64::from(cache.is_none()));
            members += 1;
        }
        // Idle lanes repeat member 0 (finite, so the kernel's arithmetic stays ordinary).
        for l in members..lanes {
            for a in [&mut p.x, &mut p.v, &mut p.f, &mut p.w, &mut p.cw, &mut p.im, &mut p.g] {
                for row in a.chunks_exact_mut(lanes) {
                    row[l] = row[0];
                }
            }
            p.cached[l] = p.cached[0];
            p.eps2[l] = p.eps2[0];
            p.dt[l] = p.dt[0];
            p.t[l] = p.t[0];
        }
        p
    }

    /// Whether lane `lane`'s positions and velocities are all finite.
    fn finite(&self, lane: usize) -> bool {
        let dim = self.shape.dim;
        (0..self.shape.n).all(|i| {
            (0..dim).all(|k| {
                let at = (3 * i + k) * self.lanes + lane;
                self.x[at].is_finite() && self.v[at].is_finite()
            })
        })
    }

    /// Writes lane `lane` back into its world, as `n` general steps leave it: state, the
    /// integrator's force cache (with the terms' last powers, which conservative terms leave
    /// as they were), the count of force evaluations, the clock.
    fn scatter<V: Vector>(&self, lane: usize, world: &mut World<V>, n: u64) {
        let (sys, integrator) = world.particles_mut().fused_parts();
        let at = |i: usize, k: usize| (3 * i + k) * self.lanes + lane;
        let comps = |a: &[f64], i: usize| -> V {
            let c: [f64; 3] = std::array::from_fn(|k| if k < V::DIM { a[at(i, k)] } else { 0.0 });
            V::from_slice(&c[..V::DIM])
        };
        for i in 0..self.shape.n {
            sys.state.x[i] = comps(&self.x, i);
            sys.state.v[i] = comps(&self.v, i);
        }
        // Into the integrator's own buffers: they allocate only the first time.
        let (f, p, valid) =
            integrator.as_carry_mut().and_then(|c| c.parts()).expect("a fused member's integrator keeps a force cache");
        f.clear();
        f.extend((0..self.shape.n).map(|i| comps(&self.f, i)));
        p.clear();
        p.extend_from_slice(sys.forces.last_power());
        *valid = true;
        sys.forces.evaluations += self.evals[lane] + n * self.shape.scheme.evals_per_step();
        world.end_fused(self.t[lane], n);
    }
}

/// The fused kernel over one chunk: `steps` steps of every lane, in registers; false if the
/// stop flag ended it (the pack is then partly stepped and must not be written back).
struct Run<'a> {
    pack: &'a mut Pack,
    steps: u64,
    stop: &'a AtomicBool,
}

/// Two vectors of lanes stepped side by side: two independent dependency chains (a step is a
/// chain of square roots and divisions ~70 cycles long per substep; with two in flight the
/// core overlaps them). Every operation applies to both halves alike, lane by lane.
#[derive(Clone, Copy)]
struct Two<L>(L, L);

macro_rules! two_op {
    ($tr:ident, $m:ident) => {
        impl<L: Lane> std::ops::$tr for Two<L> {
            type Output = Self;
            #[inline(always)]
            fn $m(self, o: Self) -> Self {
                Two(self.0.$m(o.0), self.1.$m(o.1))
            }
        }
    };
}
two_op!(Add, add);
two_op!(Sub, sub);
two_op!(Mul, mul);
two_op!(Div, div);

impl<L: Lane> Lane for Two<L> {
    #[inline(always)]
    fn sqrt(self) -> Self {
        Two(self.0.sqrt(), self.1.sqrt())
    }
    #[inline(always)]
    fn if_positive(self, a: Self, b: Self) -> Self {
        Two(self.0.if_positive(a.0, b.0), self.1.if_positive(a.1, b.1))
    }
}

/// What stays fixed through a chunk's steps, as vectors. `N`: the particle count where it is
/// known at compile time (2, 3, 4: the loops unroll and the state stays in registers), else 0
/// (then `n`).
struct Fixed<L, const D: usize, const N: usize> {
    n: usize,
    w: [L; SMALL],
    cw: [L; SMALL],
    im: [L; SMALL],
    g: [L; 3],
    eps2: L,
    zero: L,
    one: L,
}

/// A chunk's state: positions, velocities, the force at x.
#[derive(Clone, Copy)]
struct Moving<L> {
    x: [[L; 3]; SMALL],
    v: [[L; 3]; SMALL],
    f: [[L; 3]; SMALL],
}

impl<L: Lane, const D: usize, const N: usize> Fixed<L, D, N> {
    #[inline(always)]
    fn n(&self) -> usize {
        if N > 0 {
            N
        } else {
            self.n
        }
    }

    /// `ForceSet::eval` of the fused terms into `f`: `Pairwise::add_forces`'s small sum,
    /// overwriting (F_i = c w_i S_i; 0 for a pinned particle).
    #[inline(always)]
    fn forces(&self, x: &[[L; 3]; SMALL], f: &mut [[L; 3]; SMALL]) {
        let n = self.n();
        small_sum(&x[..n], &self.w[..n], self.eps2, D, self.zero, self.one, &mut f[..n]);
        for i in 0..n {
            for k in 0..D {
                f[i][k] = self.im[i].if_positive(f[i][k] * self.cw[i], self.zero);
            }
        }
    }

    /// `integrators::accel`: f/m + g, 0 for a pinned particle. `G0`: every lane's g is zero,
    /// and then f/m + g is already 0 for a pinned particle (its f is +0, its 1/m 0: +0·0 + 0 =
    /// +0), so the select is skipped with the same bits.
    #[inline(always)]
    fn accel<const G0: bool>(&self, f: L, i: usize, k: usize) -> L {
        let a = f * self.im[i] + self.g[k];
        if G0 {
            a
        } else {
            self.im[i].if_positive(a, self.zero)
        }
    }

    /// `VelocityVerlet::step` of `dt` (`half` = 0.5 dt) without velocity-dependent forces.
    #[inline(always)]
    fn verlet<const G0: bool>(&self, m: &mut Moving<L>, dt: L, half: L) {
        for i in 0..self.n() {
            for k in 0..D {
                m.v[i][k] = m.v[i][k] + self.accel::<G0>(m.f[i][k], i, k) * half;
                m.x[i][k] = m.x[i][k] + m.v[i][k] * dt;
            }
        }
        self.forces(&m.x, &mut m.f);
        for i in 0..self.n() {
            for k in 0..D {
                m.v[i][k] = m.v[i][k] + self.accel::<G0>(m.f[i][k], i, k) * half;
            }
        }
    }

    /// `steps` steps of `scheme` (`subs`: each velocity Verlet substep's dt and 0.5 dt), reading
    /// `stop` every `POLL` steps; false if it was set.
    #[inline(always)]
    fn run<const G0: bool>(
        &self,
        m: &mut Moving<L>,
        clock: &mut (L, L),
        subs: &[(L, L)],
        steps: u64,
        stop: &AtomicBool,
    ) -> bool {
        let mut done = 0;
        while done < steps {
            if stop.load(Ordering::Relaxed) {
                return false;
            }
            let run = POLL.min(steps - done);
            for _ in 0..run {
                for &(dt, half) in subs {
                    self.verlet::<G0>(m, dt, half);
                }
                clock.0 = clock.0 + clock.1;
            }
            done += run;
        }
        !stop.load(Ordering::Relaxed)
    }
}

impl Kernel for Run<'_> {
    type Output = bool;
    #[inline(always)]
    fn run<S: Simd>(self, s: S) -> bool {
        match self.pack.shape.dim {
            2 => self.run_dim::<S, 2>(s),
            _ => self.run_dim::<S, 3>(s),
        }
    }
}

impl Run<'_> {
    #[inline(always)]
    fn run_dim<S: Simd, const D: usize>(self, s: S) -> bool {
        match self.pack.shape.n {
            2 => self.run_n::<S, D, 2>(s),
            3 => self.run_n::<S, D, 3>(s),
            4 => self.run_n::<S, D, 4>(s),
            _ => self.run_n::<S, D, 0>(s),
        }
    }

    #[inline(always)]
    fn run_n<S: Simd, const D: usize, const N: usize>(self, s: S) -> bool {
        let p = self.pack;
        let l = P::<S, f64>::lanes();
        debug_assert_eq!(2 * l, p.lanes);
        // Row `row` of a pack array: its first l lanes and its second l lanes.
        let ld = |a: &[f64], row: usize| {
            let r = &a[row * 2 * l..(row + 1) * 2 * l];
            Two(P::<S, f64>::load(s, &r[..l]), P::<S, f64>::load(s, &r[l..]))
        };
        let zero = Two(P::<S, f64>::zero(s), P::zero(s));
        let splat = |v: f64| Two(P::<S, f64>::splat(s, v), P::splat(s, v));
        let n = p.shape.n;
        let mut fixed = Fixed::<_, D, N> {
            n,
            w: [zero; SMALL],
            cw: [zero; SMALL],
            im: [zero; SMALL],
            g: [zero; 3],
            eps2: ld(&p.eps2, 0),
            zero,
            one: splat(1.0),
        };
        let mut m = Moving { x: [[zero; 3]; SMALL], v: [[zero; 3]; SMALL], f: [[zero; 3]; SMALL] };
        for i in 0..n {
            for k in 0..D {
                m.x[i][k] = ld(&p.x, 3 * i + k);
                m.v[i][k] = ld(&p.v, 3 * i + k);
                m.f[i][k] = ld(&p.f, 3 * i + k);
            }
            fixed.w[i] = ld(&p.w, i);
            fixed.cw[i] = ld(&p.cw, i);
            fixed.im[i] = ld(&p.im, i);
        }
        for k in 0..D {
            fixed.g[k] = ld(&p.g, k);
        }
        // The force at the start where a member had none cached (VelocityVerlet's first step).
        let cached = ld(&p.cached, 0);
        let mut f = m.f;
        fixed.forces(&m.x, &mut f);
        for i in 0..n {
            for k in 0..D {
                m.f[i][k] = cached.if_positive(m.f[i][k], f[i][k]);
            }
        }
        let (dt, half) = (ld(&p.dt, 0), splat(0.5));
        // Each velocity Verlet substep's dt and 0.5 dt: Yoshida's w dt, as `Yoshida4::step`
        // and `VelocityVerlet::step` compute them.
        let (d1, d0) = (splat(W1) * dt, splat(W0) * dt);
        let subs = match p.shape.scheme {
            Scheme::Verlet => vec![(dt, half * dt)],
            Scheme::Yoshida4 => vec![(d1, half * d1), (d0, half * d0), (d1, half * d1)],
        };
        let g_zero = p.g.iter().all(|&g| g == 0.0);
        let mut clock = (ld(&p.t, 0), dt);
        let finished = if g_zero {
            fixed.run::<true>(&mut m, &mut clock, &subs, self.steps, self.stop)
        } else {
            fixed.run::<false>(&mut m, &mut clock, &subs, self.steps, self.stop)
        };
        if !finished {
            return false;
        }
        let st = |a: &mut [f64], row: usize, v: Two<P<S, f64>>| {
            let r = &mut a[row * 2 * l..(row + 1) * 2 * l];
            v.0.store(&mut r[..l]);
            v.1.store(&mut r[l..]);
        };
        st(&mut p.t, 0, clock.0);
        for i in 0..n {
            for k in 0..D {
                st(&mut p.x, 3 * i + k, m.x[i][k]);
                st(&mut p.v, 3 * i + k, m.v[i][k]);
                st(&mut p.f, 3 * i + k, m.f[i][k]);
            }
        }
        true
    }
}

/// `Real` is float64 throughout this module.
const _: () = assert!(std::mem::size_of::<Real>() == 8);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::systems::particles::ParticleSystem;
    use crate::terms::{PairwiseGravity, UniformGravity};
    use glam::{DVec2, DVec3};

    /// A three-body world (figure-eight-like, perturbed by `eps`), optionally with uniform
    /// gravity and a pinned body.
    fn three<V: Vector>(integrator: &str, eps: f64, softening: f64, extra: bool) -> World<V> {
        let mut w = World::<V>::new(ParticleSystem::<V>::new(integrator).unwrap(), 1e-3 * (1.0 + eps), None).unwrap();
        let c = |a: [f64; 3]| V::from_slice(&a[..V::DIM]);
        let x = vec![c([0.97000436 + eps, -0.24308753, 0.1]), c([-0.97000436, 0.24308753, -0.1]), c([0.0, 0.0, 0.0])];
        let v = vec![
            c([0.466203685, 0.43236573, 0.0]),
            c([0.466203685, 0.43236573, 0.0]),
            c([-0.93240737, -0.86473146, 0.01]),
        ];
        let p = w.particles_mut();
        p.add_particles(x, v, vec![1.0, 1.0 + eps, 1.0], vec![false, false, extra]).unwrap();
        p.add_term(Box::new(PairwiseGravity::new("g".into(), 1.0, softening))).unwrap();
        if extra {
            p.add_term(Box::new(UniformGravity { name: "u".into(), g: c([0.0, -0.5, 0.25]) })).unwrap();
        }
        w
    }

    fn bits<V: Vector>(w: &World<V>) -> Vec<u64> {
        let s = w.particles().state();
        let mut b: Vec<u64> =
            s.x.iter().chain(&s.v).flat_map(|p| (0..V::DIM).map(move |k| p.comp(k).to_bits())).collect();
        b.push(w.time().to_bits());
        b.push(w.steps());
        b.push(w.force_evaluations());
        b
    }

    /// Every member of a fused batch ends with the bits it has stepped alone (state, clock,
    /// force evaluations), at every level this CPU has, 2D and 3D, both schemes, with and
    /// without softening, uniform gravity and a pinned body; and again after a second call
    /// (the written-back force cache).
    fn same_bits_as_alone<V: Vector>() {
        // Each level is passed to the call, never set process-wide: tests run side by side.
        for level in simd::Level::available() {
            for integrator in ["verlet", "yoshida4"] {
                for (softening, extra) in [(0.0, false), (0.05, true)] {
                    let make = |k: usize| three::<V>(integrator, 1e-3 * k as f64, softening, extra);
                    let mut alone: Vec<World<V>> = (0..7).map(make).collect();
                    let mut batch: Vec<World<V>> = (0..7).map(make).collect();
                    assert!(batch[0].fused_shape().is_some());
                    let stop = Arc::new(AtomicBool::new(false));
                    for n in [100, 37] {
                        for w in &mut alone {
                            w.step(n).unwrap();
                        }
                        let call = step_worlds(batch.iter_mut().collect(), n, &stop, level);
                        for r in call.keep_all(batch.iter_mut().collect()) {
                            r.unwrap();
                        }
                        for (k, (a, b)) in alone.iter().zip(&batch).enumerate() {
                            assert_eq!(bits(a), bits(b), "{level:?} {integrator} softening {softening} member {k}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn fused_members_have_their_bits_alone_2d() {
        same_bits_as_alone::<DVec2>();
    }

    #[test]
    fn fused_members_have_their_bits_alone_3d() {
        same_bits_as_alone::<DVec3>();
    }

    /// A member that diverges inside the kernel (a body flying past the largest float) is
    /// stepped again alone and rolled back with its error; the others are written back.
    #[test]
    fn a_diverging_member_fails_alone() {
        let make = |k: usize| {
            let mut w = three::<DVec2>("yoshida4", 1e-3 * k as f64, 0.0, false);
            if k == 3 {
                let state = w.particles_mut().state_model_mut().0;
                (state.x[0], state.v[0]) = (DVec2::new(1.79e308, 0.0), DVec2::new(1e308, 0.0));
                // overflows in ~8 steps
            }
            w
        };
        let mut ws: Vec<World<DVec2>> = (0..5).map(make).collect();
        let mut twin = make(3);
        let alone = twin.step(50);
        assert!(matches!(alone, Err(Error::Diverged { .. })));
        let stop = Arc::new(AtomicBool::new(false));
        let call = step_worlds(ws.iter_mut().collect(), 50, &stop, simd::level());
        for (k, o) in call.keep_all(ws.iter_mut().collect()).into_iter().enumerate() {
            if k == 3 {
                assert_eq!(format!("{:?}", o.err()), format!("{:?}", alone.as_ref().err()));
            } else {
                o.unwrap();
                assert_eq!(ws[k].steps(), 50);
            }
        }
        assert_eq!(bits(&ws[3]), bits(&twin));
    }

    /// A stop flag set before the call stops every fused member, unchanged, at every level.
    #[test]
    fn a_set_stop_flag_rolls_every_member_back() {
        for level in simd::Level::available() {
            let mut ws: Vec<World<DVec3>> = (0..3).map(|k| three("verlet", 1e-3 * k as f64, 0.0, false)).collect();
            let before: Vec<_> = ws.iter().map(bits).collect();
            let stop = Arc::new(AtomicBool::new(true));
            let call = step_worlds(ws.iter_mut().collect(), 1000, &stop, level);
            let out = call.keep_all(ws.iter_mut().collect());
            assert!(out.iter().all(|o| matches!(o, Err(Error::Interrupted { .. }))), "{level:?}");
            assert_eq!(ws.iter().map(bits).collect::<Vec<_>>(), before, "{level:?}");
        }
    }

    /// A call undone after it ran (a signal as it finished) leaves every member where it
    /// started, fused (never written) or general (rolled back to its checkpoint); the next
    /// call then gives the bits of stepping alone, force cache included. (The general step's
    /// count of force evaluations keeps the work of an undone call, as an interrupted
    /// `World::step` does; a fused member's, never written, stays its count alone.)
    #[test]
    fn an_undone_call_leaves_every_member_as_it_was() {
        let make = |k: usize| three::<DVec2>(if k == 2 { "rk4" } else { "yoshida4" }, 1e-3 * k as f64, 0.0, false);
        let mut ws: Vec<World<DVec2>> = (0..5).map(make).collect();
        let mut alone: Vec<World<DVec2>> = (0..5).map(make).collect();
        let stop = Arc::new(AtomicBool::new(false));
        for w in ws.iter_mut().chain(alone.iter_mut()) {
            w.step(10).unwrap(); // a force cache to keep
        }
        let before: Vec<_> = ws.iter().map(bits).collect();
        let mut call = step_worlds(ws.iter_mut().collect(), 100, &stop, simd::level());
        assert_eq!(call.len(), 5);
        for (k, w) in ws.iter_mut().enumerate() {
            call.end(k, w, false).unwrap();
            call.end(k, w, true).unwrap(); // a second end does nothing
        }
        let mut after: Vec<_> = ws.iter().map(bits).collect();
        assert_eq!(after[2].pop(), before[2].last().map(|e| e + 400)); // rk4: 4 evaluations a step
        after[2].push(before[2][before[2].len() - 1]);
        assert_eq!(after, before);
        for w in &mut alone {
            w.step(100).unwrap();
        }
        let call = step_worlds(ws.iter_mut().collect(), 100, &stop, simd::level());
        for r in call.keep_all(ws.iter_mut().collect()) {
            r.unwrap();
        }
        let (mut got, want): (Vec<_>, Vec<_>) = (ws.iter().map(bits).collect(), alone.iter().map(bits).collect());
        *got[2].last_mut().unwrap() -= 400;
        assert_eq!(got, want);
    }

    /// Where a call's time goes around the kernel, per member (10,000 three-body members):
    /// `cargo test --release -p physcore-core time_the_members -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn time_the_members() {
        use std::time::Instant;
        let m = 10_000;
        let mut ws: Vec<World<DVec2>> = (0..m).map(|k| three("yoshida4", 1e-7 * k as f64, 0.0, false)).collect();
        let stop = Arc::new(AtomicBool::new(false));
        let level = simd::level();
        let call = |ws: &mut Vec<World<DVec2>>, n: u64| {
            let t = Instant::now();
            let call = step_worlds(ws.iter_mut().collect(), n, &stop, level);
            let dt = t.elapsed().as_secs_f64();
            let t = Instant::now();
            for r in call.keep_all(ws.iter_mut().collect()) {
                r.unwrap();
            }
            (dt, t.elapsed().as_secs_f64())
        };
        call(&mut ws, 1);
        for n in [0, 1, 1, 100] {
            let (dt, keep) = call(&mut ws, n);
            println!(
                "step_worlds n = {n}: {:.2} us a member, keep_all {:.2} us",
                dt * 1e6 / m as f64,
                keep * 1e6 / m as f64
            );
        }
        let t = Instant::now();
        let shapes = ws.iter().filter(|w| w.fused_shape().is_some()).count();
        println!("fused_shape: {:.3} us ({shapes})", t.elapsed().as_secs_f64() * 1e6 / m as f64);
        let t = Instant::now();
        for w in ws.iter_mut() {
            let cp = w.checkpoint().unwrap();
            w.release(cp);
        }
        println!("checkpoint + release: {:.3} us", t.elapsed().as_secs_f64() * 1e6 / m as f64);
        let shape = ws[0].fused_shape().unwrap();
        let lanes = chunk_width(level);
        let t = Instant::now();
        for chunk in ws.chunks_mut(lanes) {
            let pack = Pack::gather(shape, level, chunk.iter_mut());
            for (l, w) in chunk.iter_mut().enumerate() {
                pack.scatter(l, w, 0);
            }
        }
        println!("gather + scatter: {:.3} us", t.elapsed().as_secs_f64() * 1e6 / m as f64);
    }

    /// What the kernel does not fuse: other integrators, drag, single precision, too many bodies.
    #[test]
    fn only_plain_small_nbody_worlds_are_fused() {
        assert!(three::<DVec2>("rk4", 0.0, 0.0, false).fused_shape().is_none());
        let mut big = World::<DVec2>::new(ParticleSystem::<DVec2>::new("verlet").unwrap(), 1e-3, Some(1)).unwrap();
        let x: Vec<DVec2> = (0..SMALL + 1).map(|k| DVec2::new(k as f64, 0.5 * k as f64)).collect();
        big.particles_mut()
            .add_particles(x, vec![DVec2::ZERO; SMALL + 1], vec![1.0; SMALL + 1], vec![false; SMALL + 1])
            .unwrap();
        big.particles_mut().add_term(Box::new(PairwiseGravity::new("g".into(), 1.0, 0.0))).unwrap();
        assert!(big.fused_shape().is_none());
    }
}
