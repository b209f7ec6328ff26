//! XPBD constraints: position-based constraints with compliance, projected by the "xpbd"
//! integrator (`integrators/xpbd.rs`).
//!
//! Macklin, Müller & Chentanez, "XPBD: position-based simulation of compliant constrained
//! dynamics", MIG 2016, eqs. 17–18: for a constraint C(x) with compliance α (the inverse of
//! its stiffness), per substep of length h, α̃ = α/h² and
//!
//! ```text
//! Δλ = (−C − α̃ λ) / (Σ_k w_k |∇_k C|² + α̃),   x_k += w_k ∇_k C Δλ,   λ += Δλ
//! ```
//!
//! with w = 1/m (0 for pinned particles). λ accumulates over the iterations of one substep and
//! returns to 0 at the start of the next (`xpbd_begin`): resetting it every iteration would make
//! the stiffness depend on the iteration count. The potential is Σ C²/(2α) over the compliant
//! constraints (α = 0, infinitely stiff, stores none).
//!
//! Kinds, projected in this order, each constraint with its own compliance:
//! - distance (i, j): C = |x_i − x_j| − L0; α in m/N.
//! - bending, 2D (i, j, k): the signed angle at j from x_i − x_j to x_k − x_j, C = θ − θ0
//!   (wrapped into (−π, π]); α in rad²/J = 1/(N·m). 3D (a, b, c, d): the dihedral angle of
//!   triangles (a, b, c) and (b, a, d) across edge a–b, 0 when flat, C = θ − θ0 (the dihedral
//!   bending constraint of Müller, Heidelberger, Hennix & Ratcliff, "Position based dynamics",
//!   JVCIR 2007, §4.2, with the exact gradient of the angle of Bridson, Marino & Fedkiw,
//!   "Simulation of clothing with folds and wrinkles", SCA 2003, §4); α in rad²/J.
//! - pins (i → p): C = |x_i − p| (a zero-length spring to a fixed point when α > 0); α in m/N.
//! - area, 2D triangles (i, j, k): C = A − A0 with the signed area A = ½ (x_j − x_i) × (x_k − x_i);
//!   α in m⁴/J = m³/N.
//! - volume, 3D tetrahedra (i, j, k, l): C = V − V0 with the signed volume
//!   V = ⅙ (x_j − x_i)·((x_k − x_i) × (x_l − x_i)); α in m⁶/J = m⁵/N.
//! - shapes (shape matching; Müller, Heidelberger, Teschner & Gross, "Meshless deformations
//!   based on shape matching", SIGGRAPH 2005, eqs. 5–7): a cluster of particles with rest
//!   positions x⁰; A_pq = Σ m_i p_i q_iᵀ (p = x − x_cm, q = x⁰ − x⁰_cm), R its rotational part,
//!   goals g_i = R q_i + x_cm, and x_i += s (g_i − x_i) with stiffness s in (0, 1] (1: rigid).
//!   In 2D R is exact (the angle atan2(A₁₀ − A₀₁, A₀₀ + A₁₁)); in 3D it is found by the
//!   iteration of Müller, Bender, Chentanez & Macklin, "A robust method to extract the rotational
//!   part of deformations", MIG 2016, warm-started from the shape's previous rotation, so it
//!   also holds for flat and straight clusters, where A_pq is singular and eq. 7's S⁻¹ fails.
//!   A cluster with pinned particles turns about their mean (the mass-weighted centre of a
//!   cluster holding an infinite mass), and its rotation is the pins' wherever they fix it (the
//!   same limit): two pins in 2D, or three not on a line in 3D, hold it rigidly (R fitted to the
//!   pins alone); pins on a line in 3D leave only the turn about that line, fitted to the free
//!   particles; one pin leaves every turn to them. Shape matching is not compliant: no potential, and s is
//!   a fraction per iteration, not a material constant.
//!
//! Parallel and deterministic: Gauss–Seidel by graph colouring. Each kind's constraints are
//! coloured once, greedily in input order (a constraint takes the smallest colour none of its
//! particles has yet), so constraints of one colour touch disjoint particles; colours run in a
//! fixed order, the constraints of one colour in parallel, each reading and writing only its own
//! particles and its own λ. The result is therefore the same, bit for bit, for any thread count.
//! Jacobi with averaging (Macklin et al. 2014) parallelises without colouring, but averaging
//! scales each correction by the number of constraints at a particle, which changes the
//! effective stiffness (the point of XPBD is a stiffness that does not depend on the solver)
//! and converges more slowly per iteration; with one iteration per substep ("Small steps",
//! Macklin et al. 2019) Gauss–Seidel's faster propagation matters most.
use super::registry::{Context, Params};
use super::{Constraints, Term, Traits, Write};
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::par::{self, SyncPtr};
use crate::state::Model;
use crate::vector::{Real, Vector};
use glam::{DMat3, DQuat, DVec3};
use std::f64::consts::PI;

/// A kind of scalar constraint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Distance,
    Bending2,
    Bending3,
    Pin,
    Area,
    Volume,
}

impl Kind {
    fn arity(self) -> usize {
        match self {
            Kind::Pin => 1,
            Kind::Distance => 2,
            Kind::Bending2 | Kind::Area => 3,
            Kind::Bending3 | Kind::Volume => 4,
        }
    }
}

/// Constraints of one kind, with their colouring.
struct Set {
    kind: Kind,
    /// `arity` particle indices per constraint.
    idx: Vec<u32>,
    /// Rest value (length m, angle rad, area m², volume m³; pins: unused).
    rest: Vec<Real>,
    /// Compliance α per constraint (unit: see the module doc).
    alpha: Vec<Real>,
    /// Pins: the fixed points (m).
    target: Vec<DVec3>,
    /// Accumulated Lagrange multipliers of the substep in progress.
    lambda: Vec<Real>,
    /// Constraints by colour: colour c is `order[start[c]..start[c + 1]]`.
    order: Vec<u32>,
    start: Vec<usize>,
}

/// Shape-matching clusters, with their colouring.
struct Shapes {
    /// Cluster s is `members[first[s]..first[s + 1]]`, rest positions `rest` alike.
    first: Vec<usize>,
    members: Vec<u32>,
    rest: Vec<DVec3>,
    stiffness: Vec<Real>,
    /// 3D: each cluster's rotation at its last projection (the warm start).
    rot: Vec<DQuat>,
    order: Vec<u32>,
    start: Vec<usize>,
}

pub struct XpbdConstraints<V: Vector> {
    pub name: String,
    sets: Vec<Set>,
    shapes: Shapes,
    n_cov: usize,
    _v: std::marker::PhantomData<V>,
}

#[inline(always)]
fn to3<V: Vector>(v: V) -> DVec3 {
    DVec3::new(v.comp(0), v.comp(1), if V::DIM == 3 { v.comp(2) } else { 0.0 })
}

#[inline(always)]
fn from3<V: Vector>(p: DVec3) -> V {
    V::from_slice(&p.to_array())
}

/// `a` wrapped into (−π, π].
#[inline]
fn wrap(a: Real) -> Real {
    let b = a.rem_euclid(2.0 * PI);
    if b > PI {
        b - 2.0 * PI
    } else {
        b
    }
}

/// C and its gradient per member at positions `p`, or `None` where the gradient is undefined
/// (coincident points, a degenerate triangle).
#[inline]
fn eval(kind: Kind, p: &[DVec3; 4], rest: Real, target: DVec3) -> Option<(Real, [DVec3; 4])> {
    let z = DVec3::ZERO;
    match kind {
        Kind::Distance => {
            let d = p[0] - p[1];
            let l = d.length();
            if !(l > 0.0) {
                return None;
            }
            let n = d / l;
            Some((l - rest, [n, -n, z, z]))
        }
        Kind::Pin => {
            let d = p[0] - target;
            let l = d.length();
            if !(l > 0.0) {
                return None;
            }
            Some((l, [d / l, z, z, z]))
        }
        Kind::Bending2 => {
            let (u, w) = (p[0] - p[1], p[2] - p[1]);
            let (uu, ww) = (u.length_squared(), w.length_squared());
            if !(uu > 0.0 && ww > 0.0) {
                return None;
            }
            let theta = (u.x * w.y - u.y * w.x).atan2(u.x * w.x + u.y * w.y);
            let gi = DVec3::new(u.y, -u.x, 0.0) / uu;
            let gk = DVec3::new(-w.y, w.x, 0.0) / ww;
            Some((wrap(theta - rest), [gi, -(gi + gk), gk, z]))
        }
        Kind::Bending3 => {
            // Edge a–b (p0, p1), wings c (p2) and d (p3). Bridson et al. 2003, §4.
            let e = p[1] - p[0];
            let el = e.length();
            let n1 = (p[2] - p[0]).cross(p[2] - p[1]);
            let n2 = (p[3] - p[1]).cross(p[3] - p[0]);
            let (q1, q2) = (n1.length_squared(), n2.length_squared());
            if !(el > 0.0 && q1 > 0.0 && q2 > 0.0) {
                return None;
            }
            let (a1, a2) = (n1 / q1, n2 / q2);
            let theta = (n1.cross(n2).dot(e) / el).atan2(n1.dot(n2));
            let ee = e / el;
            let u_c = a1 * el;
            let u_d = a2 * el;
            let u_a = a1 * (p[2] - p[1]).dot(ee) + a2 * (p[3] - p[1]).dot(ee);
            let u_b = -(a1 * (p[2] - p[0]).dot(ee)) - a2 * (p[3] - p[0]).dot(ee);
            // θ as defined above decreases along Bridson's bending modes.
            Some((wrap(theta - rest), [-u_a, -u_b, -u_c, -u_d]))
        }
        Kind::Area => {
            let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
            let a = 0.5 * (e1.x * e2.y - e1.y * e2.x);
            let g1 = DVec3::new(e2.y, -e2.x, 0.0) * 0.5;
            let g2 = DVec3::new(-e1.y, e1.x, 0.0) * 0.5;
            Some((a - rest, [-(g1 + g2), g1, g2, z]))
        }
        Kind::Volume => {
            let (e1, e2, e3) = (p[1] - p[0], p[2] - p[0], p[3] - p[0]);
            let v = e1.dot(e2.cross(e3)) / 6.0;
            let (g1, g2, g3) = (e2.cross(e3) / 6.0, e3.cross(e1) / 6.0, e1.cross(e2) / 6.0);
            Some((v - rest, [-(g1 + g2 + g3), g1, g2, g3]))
        }
    }
}

/// Greedy colouring of `m` constraints whose particles are `members(c)`: each takes the smallest
/// colour not yet held by a constraint sharing a particle. Returns the constraints sorted by
/// colour (stable: input order within a colour) and each colour's start in that list. Sized by
/// the input, so allocated fallibly (`need`): a refusal is `Error::OutOfMemory`, not an abort.
fn colour<'a>(m: usize, n: usize, need: &Need, members: impl Fn(usize) -> &'a [u32]) -> Result<(Vec<u32>, Vec<usize>)> {
    let mut used: Vec<Vec<u32>> = need.filled(n, Vec::new())?;
    let mut seen: Vec<usize> = Vec::new(); // seen[k] = c + 1: colour k is taken around c
    let mut col = need.filled(m, 0u32)?;
    for c in 0..m {
        for &p in members(c) {
            for &k in &used[p as usize] {
                seen[k as usize] = c + 1;
            }
        }
        let k = (0..seen.len()).find(|&k| seen[k] != c + 1).unwrap_or(seen.len());
        if k == seen.len() {
            seen.push(0);
        }
        col[c] = k as u32;
        for &p in members(c) {
            let u = &mut used[p as usize];
            if u.try_reserve(1).is_err() {
                // Free the many small lists first: the error's own strings need room too.
                drop(used);
                return Err(need.error());
            }
            u.push(k as u32);
        }
    }
    let nc = seen.len();
    let mut start = vec![0usize; nc + 1];
    for &k in &col {
        start[k as usize + 1] += 1;
    }
    for k in 0..nc {
        start[k + 1] += start[k];
    }
    let mut fill = start.clone();
    drop(used);
    let mut order = need.filled(m, 0u32)?;
    for (c, &k) in col.iter().enumerate() {
        order[fill[k as usize]] = c as u32;
        fill[k as usize] += 1;
    }
    Ok((order, start))
}

/// Runs `f(id)` for every id of `ids`, in parallel over fixed chunks when there are many. The
/// callers' ids touch disjoint data, so the order does not change the result.
fn each(ids: &[u32], f: impl Fn(usize) + Sync + Send) {
    par::reduce(
        ids.len(),
        (),
        |_, _| (),
        |r| {
            for k in r {
                f(ids[k] as usize)
            }
        },
    );
}

/// The rotation of `a` (A_pq), from the warm start `q`: the fixed point of Müller et al. 2016's
/// iteration, R ← exp(ω) R with Σ_i r_i × a_i = 0 (r_i, a_i the columns of R and A; then RᵀA is
/// symmetric: R is the polar factor). Their step ω = Σ r_i × a_i / tr(R Aᵀ) converges only
/// linearly, slowly for elongated clusters (measured: 1.5e-8 rad left after 64 iterations);
/// here ω solves the Newton system (tr(M) I − M) ω = Σ r_i × a_i with M the symmetric part of
/// R Aᵀ (the derivative of the residual), which converges quadratically, and falls back to
/// their step where that matrix is not positive definite (far from the solution, or a straight
/// cluster whose turn about its own axis is undetermined).
fn rotation3(a: DMat3, mut q: DQuat) -> DQuat {
    for _ in 0..50 {
        let r = DMat3::from_quat(q);
        let num = r.x_axis.cross(a.x_axis) + r.y_axis.cross(a.y_axis) + r.z_axis.cross(a.z_axis);
        let m = r * a.transpose();
        let ms = (m + m.transpose()) * 0.5;
        let t = ms.x_axis.x + ms.y_axis.y + ms.z_axis.z;
        if !(t.abs() > 0.0) {
            break;
        }
        let b = DMat3::from_diagonal(DVec3::splat(t)) - ms;
        // Positive definite (Sylvester): leading minors > 0, relative to the scale t.
        let m1 = b.x_axis.x;
        let m2 = b.x_axis.x * b.y_axis.y - b.x_axis.y * b.y_axis.x;
        let newton = m1 > 1e-9 * t && m2 > 1e-9 * t * t && b.determinant() > 1e-9 * t * t * t;
        let omega = if newton { b.inverse() * num } else { num / t.abs() };
        let w = omega.length();
        if !(w > 1e-15) {
            break;
        }
        q = (DQuat::from_axis_angle(omega / w, w) * q).normalize();
    }
    q
}

fn build<V: Vector>(name: String, mut p: Params, ctx: &Context) -> Result<Box<dyn Term<V>>> {
    let n = ctx.n_particles;
    // The colouring's scratch (a list per particle) and each set's arrays, per set of m rows.
    let need = |m: usize| {
        let bytes = Need::bytes_of::<Vec<u32>>(n) + Need::bytes_of::<u32>(6 * m) + Need::bytes_of::<DVec3>(m);
        Need::new(
            "xpbd_constraints",
            bytes,
            format!("{} constraints over {} particles", count(m as u128), count(n as u128)),
        )
    };
    let mut sets = Vec::new();
    let kinds: [(&str, Kind); 5] = [
        ("distance", Kind::Distance),
        ("bending", if V::DIM == 2 { Kind::Bending2 } else { Kind::Bending3 }),
        ("pins", Kind::Pin),
        ("area", Kind::Area),
        ("volume", Kind::Volume),
    ];
    for (key, kind) in kinds {
        if !p.has(key) {
            continue;
        }
        if kind == Kind::Area && V::DIM != 2 {
            return Err(invalid(key, "area constraints are for 2D scenes (use volume in 3D)"));
        }
        if kind == Kind::Volume && V::DIM != 3 {
            return Err(invalid(key, "volume constraints are for 3D scenes (use area in 2D)"));
        }
        let idx = p.take_indices(key)?;
        let a = kind.arity();
        if idx.len() % a != 0 {
            return Err(invalid(key, format!("expected rows of {a} particle indices, got {} indices", idx.len())));
        }
        let m = idx.len() / a;
        for (c, row) in idx.chunks_exact(a).enumerate() {
            if let Some(&i) = row.iter().find(|&&i| i as usize >= n) {
                return Err(invalid(key, format!("row {c} refers to particle {i}, but the scene has {n} particles")));
            }
            for s in 0..a {
                if row[s + 1..].contains(&row[s]) {
                    return Err(invalid(key, format!("row {c} names particle {} twice", row[s])));
                }
            }
        }
        let ckey = format!("{key}_compliance");
        let alpha = p.take_floats(&ckey)?;
        if alpha.len() != m {
            return Err(invalid(&ckey, format!("has {} entries, expected {m} (one per constraint)", alpha.len())));
        }
        if let Some(c) = alpha.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
            return Err(invalid(&ckey, format!("entry {c} is {} (must be finite and >= 0)", alpha[c])));
        }
        let (rest, target) = if kind == Kind::Pin {
            let t = p.take_vectors::<V>("pins_target")?;
            if t.len() != m {
                return Err(invalid("pins_target", format!("has {} rows, expected {m} (one per pin)", t.len())));
            }
            if let Some(c) = t.iter().position(|x| !x.is_finite()) {
                return Err(invalid("pins_target", format!("row {c} is not finite")));
            }
            (need(m).filled(m, 0.0)?, need(m).collect(t.into_iter().map(to3))?)
        } else {
            let rkey = format!("{key}_rest");
            let rest = p.take_floats(&rkey)?;
            if rest.len() != m {
                return Err(invalid(&rkey, format!("has {} entries, expected {m} (one per constraint)", rest.len())));
            }
            let bad = |r: Real| match kind {
                Kind::Distance => !(r.is_finite() && r >= 0.0),
                Kind::Bending2 | Kind::Bending3 => !(r.is_finite() && r.abs() <= PI),
                _ => !(r.is_finite() && r != 0.0),
            };
            if let Some(c) = rest.iter().position(|&r| bad(r)) {
                let rule = match kind {
                    Kind::Distance => "finite and >= 0 (m)",
                    Kind::Bending2 | Kind::Bending3 => "an angle in [-pi, pi] (rad)",
                    Kind::Area => "finite and non-zero (a degenerate rest triangle has no area to keep)",
                    _ => "finite and non-zero (a degenerate rest tetrahedron has no volume to keep)",
                };
                return Err(invalid(&rkey, format!("entry {c} is {} (must be {rule})", rest[c])));
            }
            (rest, Vec::new())
        };
        let (order, start) = colour(m, n, &need(m), |c| &idx[c * a..(c + 1) * a])?;
        let lambda = need(m).filled(m, 0.0)?;
        sets.push(Set { kind, idx, rest, alpha, target, lambda, order, start });
    }
    let mut shapes = Shapes {
        first: vec![0],
        members: vec![],
        rest: vec![],
        stiffness: vec![],
        rot: vec![],
        order: vec![],
        start: vec![0],
    };
    if p.has("shapes") {
        let members = p.take_indices("shapes")?;
        let sizes = p.take_indices("shapes_size")?;
        let rest = p.take_vectors::<V>("shapes_rest")?;
        let stiffness = p.take_floats("shapes_stiffness")?;
        let total: u64 = sizes.iter().map(|&s| s as u64).sum();
        if total != members.len() as u64 {
            return Err(invalid("shapes_size", format!("sums to {total}, but {} members were given", members.len())));
        }
        if rest.len() != members.len() {
            return Err(invalid(
                "shapes_rest",
                format!("has {} rows, expected {} (one per member)", rest.len(), members.len()),
            ));
        }
        if stiffness.len() != sizes.len() {
            return Err(invalid(
                "shapes_stiffness",
                format!("has {} entries, expected {} (one per shape)", stiffness.len(), sizes.len()),
            ));
        }
        if let Some(s) = stiffness.iter().position(|x| !(x.is_finite() && *x > 0.0 && *x <= 1.0)) {
            return Err(invalid("shapes_stiffness", format!("entry {s} is {} (must be in (0, 1])", stiffness[s])));
        }
        let mut first = vec![0usize];
        for (s, &k) in sizes.iter().enumerate() {
            let (a, b) = (*first.last().unwrap_or(&0), *first.last().unwrap_or(&0) + k as usize);
            let mem = &members[a..b];
            if k < 2 {
                return Err(invalid("shapes", format!("shape {s} has {k} particles (a shape needs at least 2)")));
            }
            if let Some(&i) = mem.iter().find(|&&i| i as usize >= n) {
                return Err(invalid(
                    "shapes",
                    format!("shape {s} refers to particle {i}, but the scene has {n} particles"),
                ));
            }
            let mut sorted = mem.to_vec();
            sorted.sort_unstable();
            if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
                return Err(invalid("shapes", format!("shape {s} names particle {} twice", w[0])));
            }
            if let Some(r) = rest[a..b].iter().position(|x| !x.is_finite()) {
                return Err(invalid("shapes_rest", format!("shape {s}'s row {r} is not finite")));
            }
            if rest[a..b].iter().all(|&x| x == rest[a]) {
                return Err(invalid(
                    "shapes_rest",
                    format!("shape {s}'s rest positions all coincide (a degenerate rest shape)"),
                ));
            }
            first.push(b);
        }
        let ns = sizes.len();
        let (order, start) = colour(ns, n, &need(ns), |s| &members[first[s]..first[s + 1]])?;
        shapes = Shapes {
            first,
            members,
            rest: rest.into_iter().map(to3).collect(),
            stiffness,
            rot: vec![DQuat::IDENTITY; ns],
            order,
            start,
        };
    }
    Ok(Box::new(XpbdConstraints::<V> { name, sets, shapes, n_cov: n, _v: std::marker::PhantomData }))
}
crate::register_term!("xpbd_constraints", build, (&["xpbd"], "integrator", "XpbdConstraints are projected by"));

impl<V: Vector> XpbdConstraints<V> {
    /// Number of constraints of each kind: distance, bending, pins, area, volume, shapes.
    pub fn counts(&self) -> [usize; 6] {
        let mut c = [0; 6];
        for s in &self.sets {
            let k = match s.kind {
                Kind::Distance => 0,
                Kind::Bending2 | Kind::Bending3 => 1,
                Kind::Pin => 2,
                Kind::Area => 3,
                Kind::Volume => 4,
            };
            c[k] = s.rest.len();
        }
        c[5] = self.shapes.stiffness.len();
        c
    }

    /// Colours of each kind (same order as `counts`).
    pub fn colours(&self) -> Vec<usize> {
        self.sets.iter().map(|s| s.start.len() - 1).chain([self.shapes.start.len() - 1]).collect()
    }

    fn project_set(set: &mut Set, x: &mut [V], w: &[Real], h: Real) {
        let a = set.kind.arity();
        let (xp, lp) = (SyncPtr(x.as_mut_ptr()), SyncPtr(set.lambda.as_mut_ptr()));
        let (idx, rest, alpha, target, kind) = (&set.idx, &set.rest, &set.alpha, &set.target, set.kind);
        for c in 0..set.start.len() - 1 {
            each(&set.order[set.start[c]..set.start[c + 1]], |c| {
                let m = &idx[c * a..(c + 1) * a];
                let mut p = [DVec3::ZERO; 4];
                // SAFETY: the constraints of one colour touch disjoint particles (`colour`), and
                // each writes only its own λ; indices were checked against the particle count.
                unsafe {
                    for k in 0..a {
                        p[k] = to3(*xp.get().add(m[k] as usize));
                    }
                }
                let t = if kind == Kind::Pin { target[c] } else { DVec3::ZERO };
                let Some((cv, g)) = eval(kind, &p, rest[c], t) else { return };
                let at = alpha[c] / (h * h);
                if at == Real::INFINITY {
                    // α/h² past float64 (a compliance of 1e308): infinitely soft, no correction
                    // (Δλ → 0 as α̃ → ∞), where the formula below would give ∞/∞.
                    return;
                }
                let mut den = at;
                for k in 0..a {
                    den += w[m[k] as usize] * g[k].length_squared();
                }
                if !(den > 0.0) {
                    return;
                }
                unsafe {
                    let l = lp.get().add(c);
                    let dl = (-cv - at * *l) / den;
                    *l += dl;
                    for k in 0..a {
                        let wi = w[m[k] as usize];
                        if wi != 0.0 {
                            *xp.get().add(m[k] as usize) = from3(p[k] + g[k] * (wi * dl));
                        }
                    }
                }
            });
        }
    }

    fn project_shapes(&mut self, x: &mut [V], model: &Model) {
        let sh = &mut self.shapes;
        let (xp, rp) = (SyncPtr(x.as_mut_ptr()), SyncPtr(sh.rot.as_mut_ptr()));
        let (first, members, rest, stiff) = (&sh.first, &sh.members, &sh.rest, &sh.stiffness);
        for c in 0..sh.start.len() - 1 {
            each(&sh.order[sh.start[c]..sh.start[c + 1]], |s| {
                let (a, b) = (first[s], first[s + 1]);
                let mem = &members[a..b];
                let q0 = &rest[a..b];
                // SAFETY: shapes of one colour share no particle (`colour`); each writes only its
                // own rotation.
                let xs: Vec<DVec3> = mem.iter().map(|&i| unsafe { to3(*xp.get().add(i as usize)) }).collect();
                let pinned = mem.iter().filter(|&&i| model.inv_mass[i as usize] == 0.0).count();
                let (mut cm, mut cm0, mut mt) = (DVec3::ZERO, DVec3::ZERO, 0.0);
                for (k, &i) in mem.iter().enumerate() {
                    let free = model.inv_mass[i as usize] != 0.0;
                    let wgt = if pinned > 0 { (!free) as u8 as Real } else { model.mass[i as usize] };
                    cm += xs[k] * wgt;
                    cm0 += q0[k] * wgt;
                    mt += wgt;
                }
                cm /= mt;
                cm0 /= mt;
                // A_pq split into the free particles' part (mass-weighted) and the pins' (unit
                // weights): the pins' infinite mass makes their part decide every turn it
                // determines, the free particles only the turns the pins leave open.
                let (mut am, mut ap) = (DMat3::ZERO, DMat3::ZERO);
                let (mut spread, mut far) = (0.0, (0.0, DVec3::ZERO, DVec3::ZERO));
                for (k, &i) in mem.iter().enumerate() {
                    let (pk, qk) = (xs[k] - cm, q0[k] - cm0);
                    spread += qk.length_squared();
                    if model.inv_mass[i as usize] == 0.0 {
                        ap += DMat3::from_cols(pk * qk.x, pk * qk.y, pk * qk.z);
                        if qk.length_squared() > far.0 {
                            far = (qk.length_squared(), qk, pk);
                        }
                        continue;
                    }
                    let pk = pk * model.mass[i as usize];
                    am += DMat3::from_cols(pk * qk.x, pk * qk.y, pk * qk.z);
                }
                // How many directions the pins fix: none (one pin, or pins at one point), their
                // axis (pins on a line; 2D: that fixes the turn), or all (3D, pins in a plane).
                let tiny = 1e-24 * spread;
                let rank = if !(far.0 > tiny) {
                    0
                } else if V::DIM == 2 {
                    2
                } else {
                    let a0 = far.1 / far.0.sqrt();
                    let off_axis = mem
                        .iter()
                        .enumerate()
                        .filter(|&(_, &i)| model.inv_mass[i as usize] == 0.0)
                        .map(|(k, _)| (q0[k] - cm0).cross(a0).length_squared())
                        .fold(0.0, Real::max);
                    if off_axis > tiny {
                        2
                    } else {
                        1
                    }
                };
                let r = if V::DIM == 2 {
                    let a = if rank == 0 { am } else { ap };
                    let th = (a.x_axis.y - a.y_axis.x).atan2(a.x_axis.x + a.y_axis.y);
                    DMat3::from_rotation_z(th)
                } else {
                    let q = match rank {
                        0 => unsafe { rotation3(am, *rp.get().add(s)) },
                        2 => unsafe { rotation3(ap, *rp.get().add(s)) },
                        _ => {
                            // Pins on a line: turn their rest axis onto the present one, then
                            // about it by the angle that best fits the free particles.
                            let (a0, a) = (far.1.normalize(), far.2.normalize_or_zero());
                            let align =
                                if a == DVec3::ZERO { DQuat::IDENTITY } else { DQuat::from_rotation_arc(a0, a) };
                            let (mut sn, mut cs) = (0.0, 0.0);
                            for (k, &i) in mem.iter().enumerate() {
                                if model.inv_mass[i as usize] == 0.0 {
                                    continue;
                                }
                                let q = align * (q0[k] - cm0);
                                let (q, p) = (q - a * a.dot(q), xs[k] - cm);
                                let p = p - a * a.dot(p);
                                let m = model.mass[i as usize];
                                sn += m * a.dot(q.cross(p));
                                cs += m * q.dot(p);
                            }
                            let twist = if a == DVec3::ZERO {
                                DQuat::IDENTITY
                            } else {
                                DQuat::from_axis_angle(a, sn.atan2(cs))
                            };
                            twist * align
                        }
                    };
                    unsafe { *rp.get().add(s) = q };
                    DMat3::from_quat(q)
                };
                let st = stiff[s];
                for (k, &i) in mem.iter().enumerate() {
                    if model.inv_mass[i as usize] == 0.0 {
                        continue;
                    }
                    let goal = r * (q0[k] - cm0) + cm;
                    let xn = if st == 1.0 { goal } else { xs[k] + (goal - xs[k]) * st };
                    unsafe { *xp.get().add(i as usize) = from3(xn) };
                }
            });
        }
    }
}

impl<V: Vector> Term<V> for XpbdConstraints<V> {
    fn name(&self) -> &str {
        &self.name
    }
    /// No force: the constraints act through the projection.
    fn add_forces(&mut self, _x: &[V], _v: &[V], _model: &Model, f: &mut [V], write: Write) -> Real {
        if write == Write::Overwrite {
            par::chunks1(f, |_, f| f.fill(V::ZERO));
        }
        0.0
    }
    /// Σ C²/(2α) over the compliant constraints (J); α = 0 stores none.
    fn potential(&self, x: &[V], _model: &Model) -> Option<Real> {
        let mut u = 0.0;
        for set in &self.sets {
            let a = set.kind.arity();
            let m = set.rest.len();
            u += par::sum(m, 0.0, |r| {
                let mut u = 0.0;
                for c in r {
                    if set.alpha[c] == 0.0 {
                        continue;
                    }
                    let mut p = [DVec3::ZERO; 4];
                    for k in 0..a {
                        p[k] = to3(x[set.idx[c * a + k] as usize]);
                    }
                    let t = if set.kind == Kind::Pin { set.target[c] } else { DVec3::ZERO };
                    let cv = match eval(set.kind, &p, set.rest[c], t) {
                        Some((cv, _)) => cv,
                        None if set.kind == Kind::Pin => 0.0,
                        None => (p[0] - p[1]).length() - set.rest[c], // distance of coincident points
                    };
                    u += cv * cv / (2.0 * set.alpha[c]);
                }
                u
            });
        }
        Some(u)
    }
    /// The projection damps (the energy it removes is booked by the integrator); its forces
    /// do not depend on the velocities.
    fn traits(&self) -> Traits<V> {
        let min_particles = self.n_cov.min(
            self.sets
                .iter()
                .flat_map(|s| s.idx.iter())
                .chain(self.shapes.members.iter())
                .map(|&i| i as usize + 1)
                .max()
                .unwrap_or(0),
        );
        // Another integrator would step the particles as if the constraints were not there
        // (they add no force): refused by name, as Contacts are.
        let integrators = crate::terms::registry::integrator_rule("xpbd_constraints").map(|r| r.0);
        Traits { velocity_dependent: false, min_particles, integrators, ..Traits::dissipative() }
    }

    /// 1/ω_max of the compliant distance and pin constraints, ω_max² ≤ max_p (2/m_p) Σ_{c ∋ p}
    /// 1/α_c (Gershgorin, as for springs: compliance α is a spring of stiffness 1/α). Stiff
    /// constraints (α = 0, no oscillation to resolve), bending, area, volume and shapes set
    /// none. The "xpbd" integrator's `auto_dt` takes it as implicit Euler takes its springs
    /// (ω_max h = 10 per substep): XPBD damps such a mode exactly as implicit Euler does.
    fn time_scale(&self, _x: &[V], model: &Model) -> Option<Real> {
        let n = model.inv_mass.len();
        // A query must not abort under a memory cap: no time scale is the safe answer.
        let mut k: Vec<Real> = Vec::new();
        k.try_reserve_exact(n).ok()?;
        k.resize(n, 0.0);
        for s in self.sets.iter().filter(|s| matches!(s.kind, Kind::Distance | Kind::Pin)) {
            let a = s.kind.arity();
            for (c, &alpha) in s.alpha.iter().enumerate() {
                if alpha > 0.0 {
                    for &p in &s.idx[c * a..(c + 1) * a] {
                        k[p as usize] += 1.0 / alpha;
                    }
                }
            }
        }
        let w2 = k.iter().zip(&model.inv_mass).map(|(k, im)| 2.0 * im * k).fold(0.0, Real::max);
        let t = 1.0 / w2.sqrt();
        (t.is_finite() && t > 0.0).then_some(t)
    }
    fn as_constraints(&mut self) -> Option<&mut dyn Constraints<V>> {
        Some(self)
    }
}

impl<V: Vector> Constraints<V> for XpbdConstraints<V> {
    fn begin(&mut self) {
        for s in &mut self.sets {
            s.lambda.iter_mut().for_each(|l| *l = 0.0);
        }
    }
    fn project(&mut self, x: &mut [V], model: &Model, h: Real) {
        for s in &mut self.sets {
            Self::project_set(s, x, &model.inv_mass, h);
        }
        self.project_shapes(x, model);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terms::registry::{lookup, Value};
    use glam::{DVec2, DVec3};

    fn grad_check(kind: Kind, p: [DVec3; 4], rest: Real) {
        let (c0, g) = eval(kind, &p, rest, DVec3::ZERO).unwrap();
        let eps = 1e-6;
        for k in 0..kind.arity() {
            for d in 0..3 {
                if matches!(kind, Kind::Bending2 | Kind::Area) && d == 2 {
                    continue;
                }
                let mut q = p;
                q[k][d] += eps;
                let (c1, _) = eval(kind, &q, rest, DVec3::ZERO).unwrap();
                let num = (c1 - c0) / eps;
                assert!(
                    (num - g[k][d]).abs() < 1e-5 * (1.0 + num.abs()),
                    "{kind:?} ∂C/∂x{k}[{d}]: {num} vs {}",
                    g[k][d]
                );
            }
        }
    }

    #[test]
    fn xpbd_gradients_match_finite_differences() {
        let p = [
            DVec3::new(0.1, 0.2, 0.3),
            DVec3::new(1.1, -0.2, 0.1),
            DVec3::new(0.4, 0.9, -0.2),
            DVec3::new(0.5, -0.8, 0.6),
        ];
        let flat = |q: [DVec3; 4]| q.map(|v| DVec3::new(v.x, v.y, 0.0));
        grad_check(Kind::Distance, p, 0.5);
        grad_check(Kind::Bending2, flat(p), 0.3);
        grad_check(Kind::Bending3, p, 0.2);
        grad_check(Kind::Area, flat(p), 0.1);
        grad_check(Kind::Volume, p, 0.1);
        // A flat pair of triangles across the edge has dihedral angle 0.
        let flat_pair = [DVec3::ZERO, DVec3::X, DVec3::new(0.5, 1.0, 0.0), DVec3::new(0.5, -1.0, 0.0)];
        assert!(eval(Kind::Bending3, &flat_pair, 0.0, DVec3::ZERO).unwrap().0.abs() < 1e-15);
    }

    #[test]
    fn xpbd_rotation_is_the_polar_factor_for_elongated_and_flat_clusters() {
        let r0 = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        for s in [DVec3::new(0.25, 0.09, 0.04), DVec3::new(3.0, 1.0, 0.05), DVec3::new(1.0, 0.5, 0.0)] {
            let sym = DMat3::from_quat(DQuat::from_rotation_x(0.4)) * DMat3::from_diagonal(s);
            let sym = sym * DMat3::from_quat(DQuat::from_rotation_x(0.4)).transpose();
            let a = DMat3::from_quat(r0) * sym;
            let q = rotation3(a, DQuat::from_axis_angle(DVec3::new(0.3, -0.2, 0.9).normalize(), 0.9));
            let err =
                (DMat3::from_quat(q) - DMat3::from_quat(r0)).to_cols_array().iter().fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(err < 1e-13, "S = {s:?}: |R − R0| = {err:e}");
        }
    }

    #[test]
    fn xpbd_colouring_gives_disjoint_colours() {
        // A chain 0-1-2-3-4 and a triangle fan: no colour holds two constraints sharing a particle.
        let idx: Vec<u32> = vec![0, 1, 1, 2, 2, 3, 3, 4, 0, 2, 1, 3];
        let (order, start) = colour(6, 5, &Need::new("test", 0, ""), |c| &idx[2 * c..2 * c + 2]).unwrap();
        assert_eq!(order.len(), 6);
        for c in 0..start.len() - 1 {
            let mut seen = std::collections::HashSet::new();
            for &k in &order[start[c]..start[c + 1]] {
                for &p in &idx[2 * k as usize..2 * k as usize + 2] {
                    assert!(seen.insert(p), "colour {c} touches {p} twice");
                }
            }
        }
    }

    #[test]
    fn xpbd_bad_input_names_the_argument() {
        let ctx = Context { n_particles: 3 };
        let t = lookup("xpbd_constraints").unwrap();
        let base = || {
            Params::new()
                .with("distance", Value::Indices(vec![0, 1, 1, 2]))
                .with("distance_rest", Value::Floats(vec![1.0, 1.0]))
                .with("distance_compliance", Value::Floats(vec![0.0, 1e-3]))
        };
        assert!(t.build::<DVec2>("x".into(), base(), &ctx).is_ok());
        let e = t.build::<DVec2>("x".into(), base().with("distance_compliance", Value::Floats(vec![0.0, -1.0])), &ctx);
        assert!(e.err().unwrap().to_string().starts_with("distance_compliance: entry 1 is -1"));
        let e = t.build::<DVec2>("x".into(), base().with("distance", Value::Indices(vec![0, 1, 1, 3])), &ctx);
        assert!(e.err().unwrap().to_string().starts_with("distance: row 1 refers to particle 3"));
        let e = t.build::<DVec3>(
            "x".into(),
            Params::new()
                .with("volume", Value::Indices(vec![0, 1, 2, 0]))
                .with("volume_rest", Value::Floats(vec![1.0]))
                .with("volume_compliance", Value::Floats(vec![0.0])),
            &ctx,
        );
        assert!(e.err().unwrap().to_string().starts_with("volume: row 0 names particle 0 twice"));
        let e = t.build::<DVec2>(
            "x".into(),
            Params::new()
                .with("area", Value::Indices(vec![0, 1, 2]))
                .with("area_rest", Value::Floats(vec![0.0]))
                .with("area_compliance", Value::Floats(vec![0.0])),
            &ctx,
        );
        assert!(e.err().unwrap().to_string().starts_with("area_rest: entry 0 is 0"));
    }
}
