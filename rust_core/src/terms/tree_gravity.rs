//! Newtonian gravity with Plummer softening by a Barnes–Hut tree (Barnes & Hut, Nature 324
//! (1986) 446–449): an octree in 3D, a quadtree in 2D, rebuilt every evaluation, monopoles (the
//! centre of mass and total mass of each node).
//!
//! a_i ≈ G Σ_j m_j (x_j − x_i) / (|x_j − x_i|² + ε²)^{3/2}        (the force law of `pairwise_gravity`)
//!
//! where the sum runs over single particles near i and over whole nodes (as a point of the node's
//! mass at its centre of mass) far from it. θ = 0 opens every node: the direct sum, up to
//! round-off (the order of summation differs).
//!
//! **Build** (deterministic and parallel): the bounding cube of the positions; Morton (Z-order)
//! keys of the positions quantised in it (21 bits per axis in 3D, 32 in 2D); a parallel sort of
//! (key, index) pairs, which are distinct, so the order is unique whatever the thread count (the
//! previous step's order is the starting point: nearly sorted, so the sort is fast). The tree is
//! built from the sorted keys level by level: a node of more than `LEAF` particles splits at the
//! highest key bit in which its first and last keys differ (Karras 2012: chains of one-child
//! nodes are skipped), into its non-empty children; a node whose keys are all equal (coincident
//! or nearly coincident particles, or every particle at one point) stays a leaf whatever its size,
//! so the build never recurses forever. Every level is processed in parallel, child slots from a
//! prefix sum; moments are then summed bottom-up, level by level, children in order.
//!
//! **Opening criterion**: a node of tight bounding box side l (its longest side), centre of mass
//! c and offset δ = |c − box centre| is accepted as a point mass for a group of receivers when
//! the distance d from c to the group's bounding box exceeds r_crit = max(l/θ, l·√D/2) + δ. The
//! l/θ + δ part is the default criterion of Barnes' `treecode` (its `setrcrit`): the offset
//! term guards against the failure of the plain l/d < θ test shown by Salmon & Warren (J. Comput.
//! Phys. 111 (1994) 136–155), a receiver near one side of a cell whose mass sits at the other.
//! The l·√D/2 + δ floor is the radius of the sphere about c that holds the whole box: a node
//! containing a receiver (or any part of its group's box) is therefore always opened, for any θ.
//!
//! **Walk** (Barnes 1990, J. Comput. Phys. 87, 161–170): receivers are taken in groups of up to
//! `GROUP` consecutive particles in Morton order (the tree's nodes of at most `GROUP` particles
//! whose parent has more). One stackless walk per group (each node links to its first child and
//! to the node after its subtree) lists the accepted nodes and the particles of opened leaves;
//! every receiver of the group then sums over that list, one SIMD vector of sources at a time
//! (`crate::simd`, receivers in tiles that share the loads). The list is flushed every `LIST`
//! entries, so its memory is fixed and stays in cache. A group's test holds for each of its
//! receivers, so the error is at most that of the per-particle walk at the same θ. Groups run in
//! parallel, each written by one task, in an order of summation fixed by the tree: results are
//! bit-identical for any thread count (SIMD levels differ by a few ulp, as for the direct sum).
//!
//! The potential for the energy books is the tree's approximation of
//! U = −G Σ_{i<j} m_i m_j / (|x_j − x_i|² + ε²)^{1/2}: ½ Σ_i m_i φ_i with φ_i summed over the
//! same lists (approximate, to the accuracy of the forces; exact at θ = 0).
//!
//! The sums run in float64 whatever the state's precision (no `set_single` path).
//!
//! Tree forces are not exactly antisymmetric (i may see j's node while j sees i alone), so the
//! total momentum is conserved only to the accuracy of the forces (see the tests).
use super::pairwise_gravity::encounter_time;
use super::registry::{Context, Params};
use super::{Scratch, Setting, Term, Traits, Write};
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::par::{self, SyncPtr};
use crate::simd::{self, Kernel, Level, Simd, P};
use crate::state::Model;
use crate::stop::Stop;
use crate::vector::{Real, Vector};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// A node of at most this many particles is a leaf.
const LEAF: usize = 16;
/// Receivers walk the tree together in groups of at most this many (Morton-consecutive).
const GROUP: usize = 128;
/// Interaction-list entries summed at a time (the list is flushed when full).
const LIST: usize = 1024;
/// List padding: the widest vector of f64 lanes.
const PAD: usize = 8;
/// No node (the end of the walk, or no child).
const END: u32 = u32::MAX;

/// One node of the tree: 64 bytes, the fields the walk reads.
#[derive(Clone, Copy, Debug)]
struct Node {
    /// Centre of mass (z = 0 in 2D).
    c: [Real; 3],
    /// Total mass.
    m: Real,
    /// Squared opening radius r_crit²: accepted when the group's box is farther from `c`.
    r2: Real,
    /// The node after this one's subtree (`END`: none).
    next: u32,
    /// First child (`END` for a leaf); the children are consecutive.
    child: u32,
    /// The node's particles: `first .. first + count` in sorted order.
    first: u32,
    count: u32,
    nchild: u32,
}

impl Default for Node {
    fn default() -> Self {
        Node { c: [0.0; 3], m: 0.0, r2: 0.0, next: END, child: END, first: 0, count: 0, nchild: 0 }
    }
}

/// A tight axis-aligned bounding box: [lo, hi].
type Bounds = [[Real; 3]; 2];

const EMPTY: Bounds = [[Real::INFINITY; 3], [Real::NEG_INFINITY; 3]];

#[inline(always)]
fn union(a: Bounds, b: Bounds) -> Bounds {
    let mut o = a;
    for k in 0..3 {
        o[0][k] = o[0][k].min(b[0][k]);
        o[1][k] = o[1][k].max(b[1][k]);
    }
    o
}

/// 21 bits spread to every third bit of 63.
#[inline(always)]
fn spread3(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// 32 bits spread to every second bit of 64.
#[inline(always)]
fn spread2(x: u64) -> u64 {
    let mut x = x & 0xffff_ffff;
    x = (x | x << 16) & 0x0000_ffff_0000_ffff;
    x = (x | x << 8) & 0x00ff_00ff_00ff_00ff;
    x = (x | x << 4) & 0x0f0f_0f0f_0f0f_0f0f;
    x = (x | x << 2) & 0x3333_3333_3333_3333;
    x = (x | x << 1) & 0x5555_5555_5555_5555;
    x
}

/// The scratch of one evaluation: the sorted particles and the tree over them.
#[derive(Default)]
struct Tree {
    /// (Morton key, particle index), sorted; kept as the next build's starting order.
    order: Vec<(u64, u32)>,
    /// The sorted keys.
    keys: Vec<u64>,
    /// The sorted particles: x, y, z (0 in 2D), m.
    pos: Vec<[Real; 4]>,
    /// Nodes level by level (root first); `levels` holds each level's range.
    nodes: Vec<Node>,
    boxes: Vec<Bounds>,
    levels: Vec<(usize, usize)>,
    /// Per level: children before each parent (prefix sums).
    off: Vec<u32>,
    /// The receiver groups (node indices) in Morton order.
    groups: Vec<u32>,
}

impl Tree {
    /// Bytes of scratch for `n` particles (nodes: at most 2n, every internal node having two
    /// children or more).
    fn bytes(n: usize) -> u128 {
        let m = 2 * n.max(1);
        Need::bytes_of::<(u64, u32)>(n)
            + Need::bytes_of::<u64>(n)
            + Need::bytes_of::<[Real; 4]>(n)
            + Need::bytes_of::<Node>(m)
            + Need::bytes_of::<Bounds>(m)
            + Need::bytes_of::<u32>(2 * n + 2)
    }

    fn reserve(&mut self, n: usize, need: &Need) -> Result<()> {
        let m = 2 * n.max(1);
        need.reserve(&mut self.order, n)?;
        need.reserve(&mut self.keys, n)?;
        need.reserve(&mut self.pos, n)?;
        need.reserve(&mut self.nodes, m)?;
        need.reserve(&mut self.boxes, m)?;
        need.reserve(&mut self.off, n + 1)?;
        need.reserve(&mut self.groups, n.max(1))?;
        Ok(())
    }

    /// Builds the tree over `x` with masses `mass` and opening angle `theta`.
    fn build<V: Vector>(&mut self, x: &[V], mass: &[Real], theta: Real) {
        let n = x.len();
        debug_assert!(n > 0 && n <= u32::MAX as usize);
        self.sort(x);
        // The sorted particles and keys.
        self.pos.clear();
        self.pos.resize(n, [0.0; 4]);
        self.keys.clear();
        self.keys.resize(n, 0);
        let order = &self.order;
        par::chunks2(&mut self.pos, &mut self.keys, |s, p, k| {
            for (j, (p, k)) in p.iter_mut().zip(k.iter_mut()).enumerate() {
                let (key, i) = order[s + j];
                let (xi, i) = (x[i as usize], i as usize);
                *p = [xi.comp(0), xi.comp(1), if V::DIM == 3 { xi.comp(2) } else { 0.0 }, mass[i]];
                *k = key;
            }
        });
        self.link::<V>();
        self.moments::<V>(theta);
        self.find_groups();
    }

    /// Morton keys in the bounding cube and the sort of (key, index).
    fn sort<V: Vector>(&mut self, x: &[V]) {
        let n = x.len();
        let bounds = par::reduce(n, EMPTY, union, |r| {
            let mut b = EMPTY;
            for p in &x[r] {
                for k in 0..V::DIM {
                    b[0][k] = b[0][k].min(p.comp(k));
                    b[1][k] = b[1][k].max(p.comp(k));
                }
            }
            b
        });
        let lo = bounds[0];
        let size = (0..V::DIM).map(|k| bounds[1][k] - bounds[0][k]).fold(0.0, Real::max);
        let bits: u32 = if V::DIM == 3 { 21 } else { 32 };
        let top = ((1u64 << bits) - 1) as Real;
        // Every particle at one point (or a non-finite extent): one key, one leaf.
        let inv = (1u64 << bits) as Real / size;
        let inv = if size > 0.0 && inv.is_finite() { inv } else { 0.0 };
        let q = |v: Real, k: usize| ((v - lo[k]) * inv).clamp(0.0, top) as u64; // NaN → 0
                                                                                // Last step's order as the starting point (nearly sorted); a fresh one if n changed.
        if self.order.len() != n {
            self.order.clear();
            self.order.extend((0..n as u32).map(|i| (0, i)));
        }
        par::chunks1(&mut self.order, |_, o| {
            for e in o {
                let p = x[e.1 as usize];
                e.0 = if V::DIM == 3 {
                    spread3(q(p.comp(0), 0)) | spread3(q(p.comp(1), 1)) << 1 | spread3(q(p.comp(2), 2)) << 2
                } else {
                    spread2(q(p.comp(0), 0)) | spread2(q(p.comp(1), 1)) << 1
                };
            }
        });
        // Distinct pairs: one sorted order, whatever the algorithm and the thread count.
        let order = &mut self.order;
        if par::fork_if(n, || order.par_sort_unstable()).is_none() {
            order.sort_unstable();
        }
    }

    /// The children of the node over sorted particles `first .. first + count`, as
    /// (first, count) pairs into `out`; returns how many (0: a leaf).
    #[inline(always)]
    fn split<V: Vector>(keys: &[u64], first: usize, count: usize, out: &mut [(u32, u32); 8]) -> usize {
        if count <= LEAF {
            return 0;
        }
        let k = &keys[first..first + count];
        let diff = k[0] ^ k[count - 1];
        if diff == 0 {
            return 0; // every key equal: a leaf of any size
        }
        let hb = 63 - diff.leading_zeros();
        let shift = hb - hb % V::DIM as u32;
        let mask = (1u64 << V::DIM) - 1;
        let digit = |key: u64| (key >> shift) & mask;
        let mut nc = 0;
        let mut start = 0;
        let (d0, d1) = (digit(k[0]), digit(k[count - 1]));
        for d in d0..=d1 {
            let end = if d == d1 { count } else { start + k[start..].partition_point(|&key| digit(key) <= d) };
            if end > start {
                out[nc] = ((first + start) as u32, (end - start) as u32);
                nc += 1;
            }
            start = end;
        }
        nc
    }

    /// The tree's links, level by level: children slots from a prefix sum of the children
    /// counts, each level's parents in parallel.
    fn link<V: Vector>(&mut self) {
        let n = self.pos.len();
        self.nodes.clear();
        self.nodes.push(Node { count: n as u32, ..Node::default() });
        self.levels.clear();
        let (mut ls, mut le) = (0, 1);
        loop {
            self.levels.push((ls, le));
            let np = le - ls;
            self.off.clear();
            self.off.resize(np + 1, 0);
            let keys = &self.keys;
            {
                let parents = &self.nodes[ls..le];
                par::chunks1(&mut self.off[1..], |s, o| {
                    let mut tmp = [(0, 0); 8];
                    for (k, o) in o.iter_mut().enumerate() {
                        let p = &parents[s + k];
                        *o = Self::split::<V>(keys, p.first as usize, p.count as usize, &mut tmp) as u32;
                    }
                });
            }
            for k in 0..np {
                self.off[k + 1] += self.off[k];
            }
            let total = self.off[np] as usize;
            if total == 0 {
                break;
            }
            self.nodes.resize(le + total, Node::default());
            let (head, kids) = self.nodes.split_at_mut(le);
            let kids = SyncPtr(kids.as_mut_ptr());
            let off = &self.off;
            par::chunks1(&mut head[ls..le], |s, ps| {
                let mut tmp = [(0, 0); 8];
                for (k, p) in ps.iter_mut().enumerate() {
                    let (a, b) = (off[s + k] as usize, off[s + k + 1] as usize);
                    if a == b {
                        continue;
                    }
                    let nc = Self::split::<V>(keys, p.first as usize, p.count as usize, &mut tmp);
                    debug_assert_eq!(nc, b - a);
                    p.child = (le + a) as u32;
                    p.nchild = nc as u32;
                    for (j, &(first, count)) in tmp[..nc].iter().enumerate() {
                        let next = if j + 1 < nc { (le + a + j + 1) as u32 } else { p.next };
                        // SAFETY: slots a..b of this level's children belong to parent k alone
                        // (prefix sums of the counts) and lie within `kids` (resized above).
                        unsafe { *kids.get().add(a + j) = Node { first, count, next, ..Node::default() } };
                    }
                }
            });
            (ls, le) = (le, le + total);
        }
    }

    /// Mass, centre of mass, bounding box and opening radius of every node, bottom-up.
    fn moments<V: Vector>(&mut self, theta: Real) {
        let half_diag = (V::DIM as Real).sqrt() / 2.0;
        let pos = &self.pos;
        self.boxes.clear();
        self.boxes.resize(self.nodes.len(), EMPTY);
        for &(ls, le) in self.levels.iter().rev() {
            let (head, below) = self.nodes.split_at_mut(le);
            let (bhead, bbelow) = self.boxes.split_at_mut(le);
            par::chunks2(&mut head[ls..le], &mut bhead[ls..le], |_, nodes, boxes| {
                for (node, bx) in nodes.iter_mut().zip(boxes.iter_mut()) {
                    let (mut m, mut s, mut b) = (0.0, [0.0; 3], EMPTY);
                    if node.child == END {
                        for p in &pos[node.first as usize..(node.first + node.count) as usize] {
                            m += p[3];
                            for k in 0..3 {
                                s[k] += p[3] * p[k];
                                b[0][k] = b[0][k].min(p[k]);
                                b[1][k] = b[1][k].max(p[k]);
                            }
                        }
                    } else {
                        let c0 = node.child as usize - le;
                        for (ch, cb) in below[c0..c0 + node.nchild as usize].iter().zip(&bbelow[c0..]) {
                            m += ch.m;
                            for k in 0..3 {
                                s[k] += ch.m * ch.c[k];
                            }
                            b = union(b, *cb);
                        }
                    }
                    let mid = [0, 1, 2].map(|k| 0.5 * (b[0][k] + b[1][k]));
                    let c = if m > 0.0 { s.map(|v| v / m) } else { mid };
                    let l = (0..3).map(|k| b[1][k] - b[0][k]).fold(0.0, Real::max);
                    let delta = (0..3).map(|k| (c[k] - mid[k]).powi(2)).sum::<Real>().sqrt();
                    let rc = if theta > 0.0 { (l / theta).max(l * half_diag) + delta } else { Real::INFINITY };
                    (node.m, node.c, node.r2) = (m, c, rc * rc);
                    *bx = b;
                }
            });
        }
    }

    /// The receiver groups: nodes of at most `GROUP` particles (or leaves) whose parent has
    /// more, in Morton order.
    fn find_groups(&mut self) {
        self.groups.clear();
        let root = &self.nodes[0];
        if root.child == END || root.count as usize <= GROUP {
            self.groups.push(0);
            return;
        }
        for p in &self.nodes {
            if p.child != END && p.count as usize > GROUP {
                for c in p.child..p.child + p.nchild {
                    let ch = &self.nodes[c as usize];
                    if ch.child == END || ch.count as usize <= GROUP {
                        self.groups.push(c);
                    }
                }
            }
        }
        let nodes = &self.nodes;
        self.groups.sort_unstable_by_key(|&g| nodes[g as usize].first);
    }
}

/// An interaction list, structure of arrays: sources (particles or nodes) x, y, z, m and the
/// sorted index of a particle (−1 for a node), padded to whole vectors.
struct List {
    x: Vec<Real>,
    y: Vec<Real>,
    z: Vec<Real>,
    m: Vec<Real>,
    id: Vec<Real>,
    len: usize,
}

impl List {
    fn new() -> Self {
        let v = || vec![0.0; LIST + PAD];
        List { x: v(), y: v(), z: v(), m: v(), id: v(), len: 0 }
    }

    #[inline(always)]
    fn push(&mut self, p: [Real; 4], id: Real) {
        let k = self.len;
        (self.x[k], self.y[k], self.z[k], self.m[k], self.id[k]) = (p[0], p[1], p[2], p[3], id);
        self.len = k + 1;
    }

    /// Pads the list with massless points to whole vectors of `l` lanes; returns the padded length.
    #[inline(always)]
    fn padded(&mut self, l: usize) -> usize {
        let np = self.len.div_ceil(l) * l;
        for k in self.len..np {
            (self.x[k], self.y[k], self.z[k], self.m[k], self.id[k]) = (0.0, 0.0, 0.0, 0.0, -1.0);
        }
        np
    }
}

/// What a walk sums for its receivers.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Sum {
    /// Accelerations / G: Σ m_j d_j (|d_j|² + ε²)^{-3/2}.
    Force,
    /// Potentials / (−G): Σ_{j≠i} m_j (|d_j|² + ε²)^{-1/2}.
    Potential,
}

/// One group's walk and sums: `out` holds one `[ax, ay, az]` (or `[φ, 0, 0]`) per receiver.
struct Walk<'a> {
    tree: &'a Tree,
    group: u32,
    eps2: Real,
    sum: Sum,
    list: &'a mut List,
    out: &'a mut [[Real; 3]],
}

impl Kernel for Walk<'_> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        let Walk { tree, group, eps2, sum, list, out } = self;
        let g = &tree.nodes[group as usize];
        let gb = tree.boxes[group as usize];
        let (first, count) = (g.first as usize, g.count as usize);
        let recv = &tree.pos[first..first + count];
        out.fill([0.0; 3]);
        list.len = 0;
        // A macro, not a closure: closures are compiled outside the level's target features.
        macro_rules! flush {
            () => {{
                flush::<S>(s, list, recv, first, eps2, sum, out);
                list.len = 0;
            }};
        }
        let mut i = 0u32;
        while i != END {
            let node = &tree.nodes[i as usize];
            let mut d2 = 0.0;
            for k in 0..3 {
                let d = (gb[0][k] - node.c[k]).max(node.c[k] - gb[1][k]).max(0.0);
                d2 += d * d;
            }
            if d2 > node.r2 {
                if list.len == LIST {
                    flush!();
                }
                list.push([node.c[0], node.c[1], node.c[2], node.m], -1.0);
                i = node.next;
            } else if node.child == END {
                for j in node.first as usize..(node.first + node.count) as usize {
                    if list.len == LIST {
                        flush!();
                    }
                    list.push(tree.pos[j], j as Real);
                }
                i = node.next;
            } else {
                i = node.child;
            }
        }
        if list.len > 0 {
            flush!();
        }
    }
}

/// Adds the list's sums into every receiver's `out`, receivers in tiles of R (4 where the level
/// has 32 registers, else 2) that share each source vector's loads.
#[inline(always)]
fn flush<S: Simd>(
    s: S,
    list: &mut List,
    recv: &[[Real; 4]],
    first: usize,
    eps2: Real,
    sum: Sum,
    out: &mut [[Real; 3]],
) {
    let nl = list.padded(P::<S, Real>::lanes());
    let list = &*list;
    let mask = eps2 <= 0.0;
    macro_rules! go {
        ($r:literal) => {
            match (sum, mask) {
                (Sum::Force, true) => tiles::<S, $r, true, false>(s, list, nl, recv, first, eps2, out),
                (Sum::Force, false) => tiles::<S, $r, false, false>(s, list, nl, recv, first, eps2, out),
                (Sum::Potential, true) => tiles::<S, $r, true, true>(s, list, nl, recv, first, eps2, out),
                (Sum::Potential, false) => tiles::<S, $r, false, true>(s, list, nl, recv, first, eps2, out),
            }
        };
    }
    if S::REGISTERS >= 32 {
        go!(4)
    } else {
        go!(2)
    }
}

#[inline(always)]
fn tiles<S: Simd, const R: usize, const MASK: bool, const POT: bool>(
    s: S,
    list: &List,
    nl: usize,
    recv: &[[Real; 4]],
    first: usize,
    eps2: Real,
    out: &mut [[Real; 3]],
) {
    let n = recv.len();
    let whole = n / R * R;
    for t in (0..whole).step_by(R) {
        let a = tile::<S, R, MASK, POT>(s, list, nl, &recv[t..t + R], first + t, eps2);
        for (o, a) in out[t..t + R].iter_mut().zip(a) {
            for k in 0..3 {
                o[k] += a[k];
            }
        }
    }
    for t in whole..n {
        let a = tile::<S, 1, MASK, POT>(s, list, nl, &recv[t..t + 1], first + t, eps2)[0];
        for k in 0..3 {
            out[t][k] += a[k];
        }
    }
}

/// Receivers `recv` (R of them, sorted indices `i0 ..`) against the list's `nl` sources: the
/// accelerations / G, or `[φ, 0, 0]` with POT. MASK: drop r² = 0 (only without softening: the
/// receiver itself and coincident particles, as the direct sum does).
#[inline(always)]
fn tile<S: Simd, const R: usize, const MASK: bool, const POT: bool>(
    s: S,
    list: &List,
    nl: usize,
    recv: &[[Real; 4]],
    i0: usize,
    eps2: Real,
) -> [[Real; 3]; R] {
    let l = P::<S, Real>::lanes();
    let (zero, e2) = (P::<S, Real>::zero(s), P::splat(s, eps2));
    // Plain loops, not `std::array::from_fn` / `map` (as in `pairwise_gravity::far_tile`: their
    // closures can stay out of line, without the level's features, in several codegen units).
    let (mut xi, mut idi) = ([[zero; 3]; R], [zero; R]);
    // One receiver in `S::SPLIT_RSQRT` takes 1/√ through the divider (see `Simd::SPLIT_RSQRT`);
    // fixed per sorted index, so the same bits for any tiling and thread count.
    let k = S::SPLIT_RSQRT;
    let mut exact = [false; R];
    for r in 0..R {
        xi[r] = [P::splat(s, recv[r][0]), P::splat(s, recv[r][1]), P::splat(s, recv[r][2])];
        idi[r] = P::splat(s, (i0 + r) as Real);
        exact[r] = k > 0 && (i0 + r) % k == k - 1;
    }
    let mut acc = [[zero; 3]; R];
    for j in (0..nl).step_by(l) {
        let x = P::load(s, &list.x[j..]);
        let y = P::load(s, &list.y[j..]);
        let z = P::load(s, &list.z[j..]);
        let m = P::load(s, &list.m[j..]);
        for r in 0..R {
            let dx = x - xi[r][0];
            let dy = y - xi[r][1];
            let dz = z - xi[r][2];
            let r2 = dx.mul_add(dx, dy.mul_add(dy, dz.mul_add(dz, e2)));
            let rinv = if exact[r] { r2.rsqrt_exact() } else { r2.rsqrt() };
            if POT {
                let mut w = m * rinv;
                if MASK {
                    w = r2.gt(zero).select(w, zero);
                }
                // The receiver itself (it is in its own leaf's list) contributes nothing.
                let id = P::load(s, &list.id[j..]);
                w = id.lt(idi[r]).select(w, id.gt(idi[r]).select(w, zero));
                acc[r][0] = acc[r][0] + w;
            } else {
                let mut y3 = rinv * rinv * rinv;
                if MASK {
                    y3 = r2.gt(zero).select(y3, zero);
                }
                let w = m * y3;
                acc[r][0] = w.mul_add(dx, acc[r][0]);
                acc[r][1] = w.mul_add(dy, acc[r][1]);
                acc[r][2] = w.mul_add(dz, acc[r][2]);
            }
        }
    }
    let mut sums = [[0.0; 3]; R];
    for r in 0..R {
        sums[r] = [acc[r][0].sum(), acc[r][1].sum(), acc[r][2].sum()];
    }
    sums
}

/// Runs `sum` for every group in parallel (each group by one task, into its own receivers'
/// rows of `out`, in sorted order). Once `stop` is set the remaining groups are skipped.
fn walk_all(tree: &Tree, eps2: Real, sum: Sum, level: Level, stop: &AtomicBool, out: &mut Vec<[Real; 3]>) {
    let n = tree.pos.len();
    out.clear();
    out.resize(n, [0.0; 3]);
    let ptr = SyncPtr(out.as_mut_ptr());
    let one = |list: &mut List, g: &u32| {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        let node = &tree.nodes[*g as usize];
        // SAFETY: the groups partition the sorted particles; each group's rows are written by
        // the one task that runs it, and lie within `out` (resized to n above).
        let rows = unsafe { std::slice::from_raw_parts_mut(ptr.get().add(node.first as usize), node.count as usize) };
        simd::dispatch(level, Walk { tree, group: *g, eps2, sum, list, out: rows });
    };
    let groups = &tree.groups;
    if n < 2 * GROUP || par::fork(|| groups.par_iter().for_each_init(List::new, one)).is_none() {
        let mut list = List::new();
        groups.iter().for_each(|g| one(&mut list, g));
    }
}

pub struct TreeGravity {
    pub name: String,
    /// Gravitational constant G, m³/(kg·s²).
    pub g: Real,
    /// Plummer softening length ε, m.
    pub softening: Real,
    /// Opening angle θ ≥ 0 (0: the direct sum).
    pub theta: Real,
    tree: Tree,
    /// Accelerations / G in sorted order.
    acc: Vec<[Real; 3]>,
    /// The energy books' own tree and potentials (`potential` takes `&self`), reserved by
    /// `reserve_potential` so that reading the books allocates nothing.
    books: Mutex<(Tree, Vec<[Real; 3]>)>,
    stop: Stop,
}

fn build<V: Vector>(name: String, p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    let (g, softening, theta) = (p.number("G")?, p.number("softening")?, p.number("theta")?);
    if g <= 0.0 {
        return Err(invalid("G", format!("{g} must be finite and > 0")));
    }
    if softening < 0.0 {
        return Err(invalid("softening", format!("{softening} must be finite and >= 0")));
    }
    // ε² enters every pair; an overflowing square would make the books NaN.
    if !(softening * softening).is_finite() {
        return Err(invalid("softening", format!("{softening} is too large: its square overflows float64")));
    }
    if theta < 0.0 {
        return Err(invalid("theta", format!("{theta} must be finite and >= 0")));
    }
    Ok(Box::new(TreeGravity::new(name, g, softening, theta)))
}
crate::register_term!("tree_gravity", build);

impl TreeGravity {
    pub fn new(name: String, g: Real, softening: Real, theta: Real) -> Self {
        let books = Mutex::new((Tree::default(), Vec::new()));
        Self { name, g, softening, theta, tree: Tree::default(), acc: Vec::new(), books, stop: Stop::default() }
    }

    /// `Term::reserve` for the energy books.
    fn reserve_potential(&mut self, n: usize) -> Result<()> {
        let bytes = Tree::bytes(n) + Need::bytes_of::<[Real; 3]>(n);
        let need = Need::new("energy", bytes, format!("tree gravity's potential of {} bodies", count(n as u128)));
        need.check()?;
        if n > u32::MAX as usize {
            return Err(need.error());
        }
        let (tree, phi) = self.books.get_mut().unwrap_or_else(|e| e.into_inner());
        tree.reserve(n, &need)?;
        need.reserve(phi, n)
    }
}

impl<V: Vector> Term<V> for TreeGravity {
    fn name(&self) -> &str {
        &self.name
    }
    fn traits(&self) -> Traits<V> {
        Traits { cheap_potential: false, softened: true, ..Traits::conservative() }
    }

    fn set(&mut self, setting: Setting) {
        if let Setting::Stop(stop) = setting {
            self.stop = stop;
        }
    }

    fn reserve(&mut self, n: usize, scratch: Scratch) -> Result<()> {
        if scratch == Scratch::Potential {
            return self.reserve_potential(n);
        }
        let bytes = Tree::bytes(n) + Need::bytes_of::<[Real; 3]>(n);
        let need = Need::new("step", bytes, format!("tree gravity over {} bodies", count(n as u128)));
        need.check()?;
        if n > u32::MAX as usize {
            return Err(need.error());
        }
        self.tree.reserve(n, &need)?;
        need.reserve(&mut self.acc, n)
    }

    fn add_forces(&mut self, x: &[V], _v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let n = x.len();
        if n == 0 {
            return 0.0;
        }
        let stop = self.stop.flag();
        self.tree.build(x, &model.mass, self.theta);
        let eps2 = self.softening * self.softening;
        walk_all(&self.tree, eps2, Sum::Force, simd::level(), stop, &mut self.acc);
        let (g, acc, order) = (self.g, &self.acc, &self.tree.order);
        let fp = SyncPtr(f.as_mut_ptr());
        par::reduce(
            n,
            (),
            |_, _| (),
            |r| {
                for k in r {
                    let i = order[k].1 as usize;
                    // SAFETY: `order` is a permutation of 0..n: each force is written once.
                    let fi = unsafe { &mut *fp.get().add(i) };
                    if model.inv_mass[i] == 0.0 {
                        // Pinned: its force is never used.
                        if write == Write::Overwrite {
                            *fi = V::ZERO;
                        }
                        continue;
                    }
                    let (a, gm) = (acc[k], g * model.mass[i]);
                    write.put(fi, V::from_slice(&[a[0] * gm, a[1] * gm, a[2] * gm][..V::DIM]));
                }
            },
        );
        0.0
    }

    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        let n = x.len();
        if n == 0 {
            return Some(0.0);
        }
        let mut books = self.books.lock().unwrap_or_else(|e| e.into_inner());
        let (tree, phi) = &mut *books;
        tree.build(x, &model.mass, self.theta);
        let eps2 = self.softening * self.softening;
        walk_all(tree, eps2, Sum::Potential, simd::level(), self.stop.flag(), phi);
        // ½ Σ_i m_i φ_i in fixed chunks of the sorted order (any thread count: the same bits).
        let u = par::sum(n, 0.0, |r| r.map(|k| tree.pos[k][3] * phi[k][0]).sum::<Real>());
        Some(-0.5 * self.g * u)
    }

    fn time_scale(&self, x: &[V], model: &Model) -> Option<Real> {
        // The closest pair's free-fall time, as pairwise gravity: O(N²), so left out above
        // 2·10⁴ bodies.
        (x.len() <= 20_000).then(|| encounter_time(self.g, self.softening, x, model, self.stop.flag())).flatten()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};
    use std::sync::Arc;

    fn rng(seed: u64) -> impl FnMut() -> f64 {
        let mut seed = seed;
        move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
    }

    /// A Plummer sphere (scale radius 1, cut at 30) of `n` equal masses summing to 1; in 2D its
    /// projection on the xy plane.
    fn plummer<V: Vector>(n: usize, seed: u64) -> (Vec<V>, Model) {
        let mut rnd = rng(seed);
        let x = (0..n)
            .map(|_| {
                let r = (1.0 / (rnd().powf(-2.0 / 3.0) - 1.0).sqrt()).min(30.0);
                let (u, ph) = (2.0 * rnd() - 1.0, 2.0 * std::f64::consts::PI * rnd());
                let s = (1.0 - u * u).sqrt();
                V::from_slice(&[r * s * ph.cos(), r * s * ph.sin(), r * u])
            })
            .collect();
        let mut model = Model { mass: vec![1.0 / n as f64; n], inv_mass: vec![n as f64; n], ..Default::default() };
        // Unequal masses exercise the centres of mass.
        for (k, m) in model.mass.iter_mut().enumerate() {
            *m *= 0.5 + (k % 7) as f64 / 6.0;
        }
        (x, model)
    }

    /// The direct sum a_i / G and φ_i / (−G) (r = 0 pairs skipped, as both terms do).
    fn naive<V: Vector>(x: &[V], model: &Model, eps2: f64) -> (Vec<[f64; 3]>, Vec<f64>) {
        let n = x.len();
        (0..n)
            .map(|i| {
                let (mut a, mut phi) = ([0.0; 3], 0.0);
                for j in (0..n).filter(|&j| j != i) {
                    let d = x[j] - x[i];
                    let r2 = d.length_squared() + eps2;
                    if r2 > 0.0 {
                        let w = model.mass[j] / (r2 * r2.sqrt());
                        for k in 0..V::DIM {
                            a[k] += w * d.comp(k);
                        }
                        phi += model.mass[j] / r2.sqrt();
                    }
                }
                (a, phi)
            })
            .unzip()
    }

    /// The term's accelerations / G, by particle (not sorted), and the potential.
    fn tree_accel<V: Vector>(x: &[V], model: &Model, eps: f64, theta: f64) -> (Vec<[f64; 3]>, f64) {
        let mut t = TreeGravity::new("t".into(), 1.0, eps, theta);
        Term::<V>::reserve(&mut t, x.len(), crate::terms::Scratch::Step).unwrap();
        let mut f = vec![V::ZERO; x.len()];
        Term::<V>::add_forces(&mut t, x, &[], model, &mut f, Write::Overwrite);
        let a = f
            .iter()
            .zip(&model.mass)
            .map(|(f, m)| {
                let mut a = [0.0; 3];
                for k in 0..V::DIM {
                    a[k] = f.comp(k) / m;
                }
                a
            })
            .collect();
        (a, Term::<V>::potential(&t, x, model).unwrap())
    }

    fn norm(a: [f64; 3]) -> f64 {
        (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
    }

    fn relative_errors(got: &[[f64; 3]], want: &[[f64; 3]]) -> Vec<f64> {
        let mut e: Vec<f64> =
            got.iter().zip(want).map(|(g, w)| norm([g[0] - w[0], g[1] - w[1], g[2] - w[2]]) / norm(*w)).collect();
        e.sort_by(f64::total_cmp);
        e
    }

    /// Accelerations / G by particle and the potential / G at `level` (the tree's own sums,
    /// without the global level switch, which would race with other tests).
    fn at_level<V: Vector>(x: &[V], model: &Model, eps: f64, theta: f64, level: Level) -> (Vec<[f64; 3]>, f64) {
        let mut t = Tree::default();
        t.build(x, &model.mass, theta);
        let (mut acc, mut phi) = (Vec::new(), Vec::new());
        let never = AtomicBool::new(false);
        walk_all(&t, eps * eps, Sum::Force, level, &never, &mut acc);
        walk_all(&t, eps * eps, Sum::Potential, level, &never, &mut phi);
        let mut a = vec![[0.0; 3]; x.len()];
        for (k, &(_, i)) in t.order.iter().enumerate() {
            a[i as usize] = acc[k];
        }
        (a, -0.5 * (0..x.len()).map(|k| t.pos[k][3] * phi[k][0]).sum::<f64>())
    }

    fn check_theta_zero<V: Vector>() {
        let n = 1500; // several levels and groups
        let (x, model) = plummer::<V>(n, 7);
        for eps in [0.0, 0.01] {
            let (want, phi) = naive(&x, &model, eps * eps);
            let u: f64 = -0.5 * phi.iter().zip(&model.mass).map(|(p, m)| p * m).sum::<f64>();
            for level in Level::available() {
                let (got, pot) = at_level(&x, &model, eps, 0.0, level);
                let e = relative_errors(&got, &want);
                assert!(e[n - 1] < 1e-12, "{}D {level:?} eps {eps}: worst relative error {:e}", V::DIM, e[n - 1]);
                assert!(((pot - u) / u).abs() < 1e-12, "{}D {level:?} eps {eps}: potential {pot} vs {u}", V::DIM);
            }
            // Through the term: forces G m a, the same potential.
            let (got, pot) = tree_accel(&x, &model, eps, 0.0);
            assert!(relative_errors(&got, &want)[n - 1] < 1e-12 && ((pot - u) / u).abs() < 1e-12);
        }
    }

    #[test]
    fn theta_zero_is_the_direct_sum_in_2d_and_3d() {
        check_theta_zero::<DVec3>();
        check_theta_zero::<DVec2>();
    }

    /// Median and 99th-percentile relative force errors on a Plummer sphere: below the bounds
    /// measured for this criterion (with margin), and falling with θ.
    #[test]
    fn force_error_is_bounded_and_falls_with_theta() {
        let n = 4000;
        let (x, model) = plummer::<DVec3>(n, 3);
        let eps = 0.01;
        let (want, phi) = naive(&x, &model, eps * eps);
        let u: f64 = -0.5 * phi.iter().zip(&model.mass).map(|(p, m)| p * m).sum::<f64>();
        let mut last = (0.0, 0.0);
        // (θ, median bound, 99th percentile bound)
        for (theta, med, p99) in [(0.2, 2e-4, 1.5e-3), (0.5, 1.5e-3, 1e-2), (1.0, 6e-3, 5e-2)] {
            let (got, pot) = tree_accel(&x, &model, eps, theta);
            let e = relative_errors(&got, &want);
            let (m, p) = (e[n / 2], e[n * 99 / 100]);
            assert!(m < med && p < p99, "theta {theta}: median {m:e}, 99% {p:e}");
            assert!(m > last.0 && p > last.1, "theta {theta}: errors should grow with theta");
            assert!(((pot - u) / u).abs() < 10.0 * med, "theta {theta}: potential {pot} vs {u}");
            last = (m, p);
        }
    }

    fn pool(threads: usize) -> Arc<rayon::ThreadPool> {
        Arc::new(rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap())
    }

    #[test]
    fn any_thread_count_gives_the_same_bits() {
        let n = 20_000; // above the parallel thresholds of every pass
        let (x, model) = plummer::<DVec3>(n, 11);
        let run = |threads: usize| {
            par::install(Some(&pool(threads)), || {
                let (a, u) = tree_accel(&x, &model, 0.01, 0.6);
                (a.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>(), u.to_bits())
            })
        };
        let one = run(1);
        assert_eq!(one, run(2));
        assert_eq!(one, run(3));
    }

    /// Every node's count is its children's, the groups partition the particles in order, and
    /// the links of a θ = 0 walk reach every particle once.
    #[test]
    fn the_tree_is_consistent() {
        for (n, seed) in [(1, 1), (2, 2), (17, 3), (129, 4), (5000, 5)] {
            let (x, model) = plummer::<DVec3>(n, seed);
            let mut t = Tree::default();
            t.build(&x, &model.mass, 0.0);
            for node in &t.nodes {
                if node.child != END {
                    let kids = &t.nodes[node.child as usize..(node.child + node.nchild) as usize];
                    assert!(kids.len() >= 2);
                    assert_eq!(kids.iter().map(|k| k.count).sum::<u32>(), node.count);
                    assert_eq!(kids[0].first, node.first);
                }
            }
            let mut next = 0;
            for &g in &t.groups {
                assert_eq!(t.nodes[g as usize].first, next);
                next += t.nodes[g as usize].count;
            }
            assert_eq!(next as usize, n);
            let (mut i, mut seen) = (0u32, 0);
            while i != END {
                let node = &t.nodes[i as usize];
                if node.child == END {
                    assert_eq!(node.first, seen);
                    seen += node.count;
                    i = node.next;
                } else {
                    i = node.child;
                }
            }
            assert_eq!(seen as usize, n);
            let m: f64 = model.mass.iter().sum();
            assert!((t.nodes[0].m - m).abs() < 1e-12 * m);
        }
    }

    /// Coincident particles and every particle at one point end in a leaf of any size (keys all
    /// equal), not an endless split; the forces stay finite (zero at one point).
    #[test]
    fn coincident_particles_do_not_recurse_forever() {
        let n = 1000;
        let same = vec![DVec3::new(0.25, -1.0, 3.0); n];
        let model = Model { mass: vec![1.0; n], inv_mass: vec![1.0; n], ..Default::default() };
        for eps in [0.0, 0.1] {
            let (a, u) = tree_accel(&same, &model, eps, 0.5);
            assert!(a.iter().flatten().all(|&v| v == 0.0));
            let pairs = (n * (n - 1) / 2) as f64;
            let want = if eps > 0.0 { -pairs / eps } else { 0.0 };
            assert!((u - want).abs() <= 1e-12 * want.abs(), "eps {eps}: {u} vs {want}");
        }
        // Half the particles on one point, the rest spread: the point is one deep leaf.
        let (mut x, model) = plummer::<DVec3>(n, 9);
        for p in x.iter_mut().step_by(2) {
            *p = DVec3::new(0.1, 0.2, 0.3);
        }
        let (want, _) = naive(&x, &model, 0.0);
        let (got, _) = tree_accel(&x, &model, 0.0, 0.0);
        let e = relative_errors(&got, &want);
        assert!(e[n - 1] < 1e-12, "{:e}", e[n - 1]);
    }

    #[test]
    fn pinned_particles_attract_but_feel_nothing() {
        let x = vec![DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0), DVec2::new(0.0, 2.0)];
        let model = Model { mass: vec![2.0, 1.0, 1.0], inv_mass: vec![0.0, 1.0, 1.0], ..Default::default() };
        let mut t = TreeGravity::new("t".into(), 1.0, 0.0, 0.5);
        let mut f = vec![DVec2::new(9.0, 9.0); 3];
        Term::<DVec2>::add_forces(&mut t, &x, &[], &model, &mut f, Write::Overwrite);
        assert_eq!(f[0], DVec2::ZERO);
        // Body 1: pulled by 2 (mass 2) at distance 1 and by 2 at distance √5.
        let d = DVec2::new(-1.0, 2.0);
        let want = DVec2::new(-2.0, 0.0) + d * (1.0 / d.length().powi(3));
        assert!((f[1] - want).length() < 1e-14, "{} vs {want}", f[1]);
        let mut g = vec![DVec2::new(9.0, 9.0); 3];
        Term::<DVec2>::add_forces(&mut t, &x, &[], &model, &mut g, Write::Add);
        assert_eq!(g[0], DVec2::new(9.0, 9.0));
        assert_eq!(g[1], DVec2::new(9.0, 9.0) + f[1]);
    }

    #[test]
    fn a_set_stop_flag_skips_the_walk() {
        let (x, model) = plummer::<DVec3>(3000, 1);
        let mut t = Tree::default();
        t.build(&x, &model.mass, 0.5);
        for stopped in [true, false] {
            let mut acc = Vec::new();
            walk_all(&t, 0.0, Sum::Force, simd::level(), &AtomicBool::new(stopped), &mut acc);
            let computed = acc.iter().filter(|a| a[0] != 0.0).count();
            assert_eq!(computed, if stopped { 0 } else { 3000 });
        }
    }

    #[test]
    fn bad_parameters_are_refused_by_name_and_huge_n_is_an_error() {
        let ctx = Context { n_particles: 0 };
        let params = |g: f64, eps: f64, theta: f64| {
            use crate::terms::registry::Value::Number;
            Params::new().with("G", Number(g)).with("softening", Number(eps)).with("theta", Number(theta))
        };
        let ty = crate::terms::registry::lookup("tree_gravity").unwrap();
        for (p, arg) in [
            (params(0.0, 0.0, 0.5), "G"),
            (params(1.0, -1.0, 0.5), "softening"),
            (params(1.0, 0.0, -0.1), "theta"),
            (params(1.0, 0.0, f64::NAN), "theta"),
            (params(1.0, f64::INFINITY, 0.5), "softening"),
        ] {
            let e = ty.build::<DVec3>("t".into(), p, &ctx).err().expect("refused").to_string();
            assert!(e.contains(arg), "{e}");
        }
        assert!(ty.build::<DVec2>("t".into(), params(1.0, 0.0, 0.0), &ctx).is_ok());
        let mut t = TreeGravity::new("t".into(), 1.0, 0.0, 0.5);
        let e = Term::<DVec3>::reserve(&mut t, usize::MAX / 64, crate::terms::Scratch::Step).unwrap_err().to_string();
        assert!(e.contains("tree gravity"), "{e}");
    }
}
