//! The rigid bodies of a 3D world (`rapier3d-f64`): what differs from 2D, then the system
//! itself (`common.rs`, shared with `dim2`). Orientations are unit quaternions stored scalar
//! last, (x, y, z, w), as scipy's `Rotation.from_quat` reads them.
use super::{built, finite_all, pack, particle_kinetic, resolvable, take_len, unpack};
use crate::alloc::{count, Need};
use crate::error::{invalid, Failure, Result};
use crate::systems::{array, Arrays, Coupling, EnergyReport, Halt, Snapshot, System};
use crate::terms::registry::Params;
use crate::terms::BodyMotion;
use crate::vector::{Real, Vector as PVector};
use physcore_bodies_io::dim3 as io;
use rapier3d_f64::geometry::{
    ContactData, ContactManifold, ContactPair, SolverContact, TrackedContact, NEW_CONTACT_BIT,
};
use rapier3d_f64::parry::bounding_volume::{BoundingSphere, BoundingVolume};
use rapier3d_f64::prelude::*;
use std::sync::atomic::AtomicBool;

const D: usize = 3;

/// These bodies as the coupling's role hands them out, and back (`None`: the other dimension's).
fn as_bodies_of(b: &mut Bodies) -> crate::systems::BodiesOf<'_> {
    crate::systems::BodiesOf::Three(b)
}
fn of_this_dim(b: crate::systems::BodiesOf<'_>) -> Option<&mut Bodies> {
    match b {
        crate::systems::BodiesOf::Three(b) => Some(b),
        _ => None,
    }
}
/// Values per body of the orientation (a unit quaternion) and of the angular velocity.
const ROT: usize = 4;
const ANG: usize = 3;
const ROTATION_KEY: &str = "orientations";
/// The shape kinds of a group, as Python names them ("mesh": fixed bodies only).
pub const SHAPES: [&str; 5] = ["ball", "box", "capsule", "hull", "mesh"];
pub const JOINTS: [&str; 5] = ["revolute", "fixed", "prismatic", "spherical", "rope"];
/// A revolute or prismatic joint's axis when none is given: z, as in the plane.
const DEFAULT_AXIS: [Real; 3] = [0.0, 0.0, 1.0];
/// "q" sets the orientation, four values (x, y, z, w) a body; read it as qx, qy, qz, qw.
const FIELDS: [&str; 18] =
    ["x", "y", "z", "q", "vx", "vy", "vz", "wx", "wy", "wz", "qx", "qy", "qz", "qw", "mass", "ix", "iy", "iz"];
const READABLE: [&str; 17] =
    ["x", "y", "z", "vx", "vy", "vz", "wx", "wy", "wz", "qx", "qy", "qz", "qw", "mass", "ix", "iy", "iz"];
const SETTABLE: usize = 10;

fn settable_width(name: &str) -> Option<usize> {
    match name {
        "q" => Some(4),
        _ => FIELDS[..SETTABLE].contains(&name).then_some(1),
    }
}

fn vector(s: &[Real]) -> Vector {
    Vector::new(s[0], s[1], s[2])
}

/// A unit quaternion from (x, y, z, w), normalised; refused if its norm is 0 (no rotation).
fn rotation(s: &[Real]) -> Result<Rotation> {
    let q = Rotation::from_xyzw(s[0], s[1], s[2], s[3]);
    let norm = q.length();
    if !(norm > 1e-12 && norm.is_finite()) {
        return Err(invalid(
            ROTATION_KEY,
            format!("({}, {}, {}, {}) is not a rotation (norm {norm})", s[0], s[1], s[2], s[3]),
        ));
    }
    Ok(q / norm)
}

fn ang_vector(s: &[Real]) -> AngVector {
    Vector::new(s[0], s[1], s[2])
}

fn rotation_finite(r: &Rotation) -> bool {
    r.is_finite()
}

fn size_len(shape: &str) -> usize {
    match shape {
        "ball" => 1,
        "box" => 3,
        "capsule" => 2,
        _ => 0,
    }
}

fn sized_shape(shape: &str, s: &[Real]) -> ColliderBuilder {
    match shape {
        "ball" => ColliderBuilder::ball(s[0]),
        "box" => ColliderBuilder::cuboid(s[0], s[1], s[2]),
        _ => ColliderBuilder::capsule_x(s[0], s[1]),
    }
}

/// What a collider's shape lacks in parry's mass properties (see the 2D one): nothing in 3D,
/// where a capsule's caps are hemispheres, their centroids 3r/8 from the flat side as parry has.
fn added_mass(_c: &Collider) -> Option<MassProperties> {
    None
}

/// A hull or mesh group's one shape: the convex hull of its `vertices` (K·3 values,
/// `n_vertices`), or the triangle mesh of `vertices` and `triangles` (T·3 indices,
/// `n_triangles`), for fixed bodies only (a mesh has no volume, so no mass).
/// What building a shape of `k` vertices and `t` triangles needs, checked to be there (parry
/// allocates infallibly): the points, and a hull's working lists or a mesh's tree, taken as
/// 2 kB a vertex and triangle (a hull of 50,000 vertices on a sphere peaked at 1.3 kB a vertex).
fn shape_need(k: usize, t: usize) -> Need {
    let of = format!("a shape of {} vertices and {} triangles", count(k as u128), count(t as u128));
    Need::new("add_bodies", (k + t) as u128 * 2048, of)
}

fn listed_shape(shape: &str, kind: &str, p: &mut Params) -> Result<Option<ColliderBuilder>> {
    if shape != "hull" && shape != "mesh" {
        return Ok(None);
    }
    let k = p.count("n_vertices", 1 << 20)?;
    let v = take_len(p, "vertices", 3 * k)?;
    let points = shape_need(k, 0).collect(v.chunks_exact(3).map(vector))?;
    if shape == "hull" {
        if points.len() < 4 {
            return Err(invalid("vertices", "a hull needs at least 4 vertices"));
        }
        resolvable(&v, 3)?;
        shape_need(k, 0).room(k as u128 * 2048)?;
        return built("vertices", || {
            ColliderBuilder::convex_hull(&points)
                .ok_or_else(|| "their convex hull is degenerate (all on one plane)".into())
        })
        .map(Some);
    }
    if kind != "fixed" {
        return Err(invalid("kind", "a triangle mesh has no volume and so no mass: make it kind=\"fixed\""));
    }
    let t = p.count("n_triangles", 1 << 22)?;
    let idx = take_len(p, "triangles", 3 * t)?;
    if t == 0 {
        return Err(invalid("triangles", "a mesh needs at least one triangle"));
    }
    if let Some(j) = idx.iter().position(|&i| i.fract() != 0.0 || i < 0.0 || i >= k as Real) {
        return Err(invalid("triangles", format!("entry {j} ({}) is not a vertex index (0..{k})", idx[j])));
    }
    let tris = shape_need(k, t).collect(idx.chunks_exact(3).map(|c| [c[0] as u32, c[1] as u32, c[2] as u32]))?;
    resolvable(&v, 3)?;
    shape_need(k, t).room((k + t) as u128 * 2048)?;
    built("triangles", || ColliderBuilder::trimesh(points, tris).map_err(|e| format!("do not make a mesh: {e}")))
        .map(Some)
}

/// A hinge about the axis given (in each body's frame).
fn revolute(axis1: Vector, axis2: Vector) -> RevoluteJointBuilder {
    let mut b = RevoluteJointBuilder::new(axis1);
    b.0.data.set_local_axis2(axis2);
    b
}

/// A ball-and-socket joint: the anchors together, turning free about every axis.
fn spherical(la: Vector, lb: Vector) -> GenericJoint {
    SphericalJointBuilder::new().local_anchor1(la).local_anchor2(lb).contacts_enabled(false).build().into()
}

/// The turning term (r×t)·I⁻¹(r×t) of a body's effective mass along t (r: from its centre of
/// mass; I⁻¹ in the world frame).
fn turning(body: &RigidBody, rc: Vector, t: Vector) -> Real {
    let r = rc.cross(t);
    r.dot(body.mass_properties().effective_world_inv_inertia * r)
}

/// "ix", "iy", "iz": the diagonal of the inertia tensor about the centre of mass in the body's
/// own axes (kg·m²). parry's principal moments come in its own frame (a capsule's axis, the
/// body's x, turned onto y; a hull's eigenvectors in any order), so they are turned back; for
/// a box and a capsule these are the principal moments, for a hull its products of inertia
/// (off the diagonal) are left out.
fn get_one(b: &RigidBody, name: &str) -> Real {
    let (t, q, v, w) = (b.translation(), b.rotation(), b.linvel(), b.angvel());
    let m = b.mass_properties().local_mprops.reconstruct_inertia_matrix();
    let i = Vector::new(m.x_axis.x, m.y_axis.y, m.z_axis.z);
    match name {
        "x" => t.x,
        "y" => t.y,
        "z" => t.z,
        "qx" => q.x,
        "qy" => q.y,
        "qz" => q.z,
        "qw" => q.w,
        "vx" => v.x,
        "vy" => v.y,
        "vz" => v.z,
        "wx" => w.x,
        "wy" => w.y,
        "wz" => w.z,
        "mass" => b.mass(),
        "ix" => i.x,
        "iy" => i.y,
        _ => i.z,
    }
}

/// Sets field `name` of body `b` to `row` (its values); `dry`: only checks.
fn set_one(b: &mut RigidBody, name: &str, row: &[Real], dry: bool) -> std::result::Result<(), String> {
    if name == "q" {
        let q = rotation(row).map_err(|e| e.to_string())?;
        if !dry {
            b.set_rotation(q, true);
        }
        return Ok(());
    }
    if dry {
        return Ok(());
    }
    let (mut t, mut v, mut w, val) = (b.translation(), b.linvel(), b.angvel(), row[0]);
    match name {
        "x" | "y" | "z" => {
            t[(name.as_bytes()[0] - b'x') as usize] = val;
            b.set_translation(t, true)
        }
        "vx" | "vy" | "vz" => {
            v[(name.as_bytes()[1] - b'x') as usize] = val;
            b.set_linvel(v, true)
        }
        _ => {
            w[(name.as_bytes()[1] - b'x') as usize] = val;
            b.set_angvel(w, true)
        }
    }
    Ok(())
}

/// Points on the surface of `shape` (its own frame) about `spacing` apart: a body's boundary
/// particles for a fluid (Akinci et al. 2012 sample the surface at the fluid's spacing). Each
/// triangle of the shape's mesh (`shape_mesh`) is covered by a lattice no coarser than
/// `spacing`, and a point is kept unless one kept already lies within 0.75 `spacing` (so the
/// edges shared by two triangles are sampled once). Empty for a shape without a mesh.
fn surface_samples(
    shape: &dyn Shape,
    spacing: Real,
    inset: Real,
    room: &dyn Fn(usize) -> Result<()>,
    stop: &AtomicBool,
) -> Result<Vec<Vector>> {
    // Half a spacing inside (see the 2D `surface_samples`): balls, boxes and capsules shrunk,
    // a hull's or mesh's points moved in along their triangle's normal; at most half the
    // shape's smallest half-extent.
    let he = shape.compute_local_aabb().half_extents();
    let d = inset.min(0.5 * he.x.min(he.y).min(he.z));
    let mesh = if let Some(b) = shape.as_ball() {
        shape_mesh(&Ball::new(b.radius - d)).map(|m| (m, 0.0))
    } else if let Some(c) = shape.as_cuboid() {
        shape_mesh(&Cuboid::new(c.half_extents - Vector::splat(d))).map(|m| (m, 0.0))
    } else if let Some(c) = shape.as_capsule() {
        shape_mesh(&Capsule::new(c.segment.a, c.segment.b, c.radius - d)).map(|m| (m, 0.0))
    } else {
        shape_mesh(shape).map(|m| (m, d))
    };
    let Some(((v, t), along)) = mesh else {
        return Ok(Vec::new());
    };
    // Points kept at least 0.75 spacing apart cover at most 1/(π 0.375²) ≈ 2.3 a spacing²
    // of surface, plus those along the edges: asked for before any is made.
    let (area, edges) = t.iter().fold((0.0, 0.0), |(a, e), tri| {
        let [p, q, r] = tri.map(|i| v[i as usize]);
        (a + 0.5 * (q - p).cross(r - p).length(), e + (q - p).length() + (r - q).length() + (p - r).length())
    });
    room((2.5 * area / (spacing * spacing) + edges / spacing).ceil().min(usize::MAX as Real) as usize)?;
    let mut out: Vec<Vector> = Vec::new();
    let mut cells: std::collections::HashMap<[i64; 3], Vec<usize>> = std::collections::HashMap::new();
    let cell =
        |p: Vector| [(p.x / spacing).floor() as i64, (p.y / spacing).floor() as i64, (p.z / spacing).floor() as i64];
    let min2 = (0.75 * spacing) * (0.75 * spacing);
    for tri in &t {
        let [a, b, c] = tri.map(|i| v[i as usize]);
        let shift = (b - a).cross(c - a).normalize_or_zero() * along;
        let [a, b, c] = [a - shift, b - shift, c - shift];
        let longest = (b - a).length().max((c - b).length()).max((a - c).length());
        let n = ((longest / spacing).ceil() as usize).max(1);
        for i in 0..=n {
            // A large body's surface takes seconds (a box 20 m wide at 5 cm: 8 s): Ctrl-C is
            // seen between rows of a triangle's lattice.
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Err(crate::error::Error::Interrupted { rolled_back_to: 0 });
            }
            for j in 0..=n - i {
                let p = a + (b - a) * (i as Real / n as Real) + (c - a) * (j as Real / n as Real);
                let k = cell(p);
                let near = (-1..=1).any(|dx| {
                    (-1..=1).any(|dy| {
                        (-1..=1).any(|dz| {
                            cells
                                .get(&[k[0] + dx, k[1] + dy, k[2] + dz])
                                .is_some_and(|l| l.iter().any(|&q| (out[q] - p).length_squared() < min2))
                        })
                    })
                });
                if !near {
                    cells.entry(k).or_default().push(out.len());
                    out.push(p);
                }
            }
        }
    }
    Ok(out)
}

/// A shape as triangles in its own frame: vertices and corner indices (a ball and a capsule as
/// 16 × 32 facets); `None` for a shape of no kind here.
fn shape_mesh(shape: &dyn Shape) -> Option<(Vec<Vector>, Vec<[u32; 3]>)> {
    Some(if let Some(s) = shape.as_ball() {
        s.to_trimesh(16, 32)
    } else if let Some(s) = shape.as_cuboid() {
        s.to_trimesh()
    } else if let Some(s) = shape.as_capsule() {
        s.to_trimesh(16, 32)
    } else if let Some(s) = shape.as_convex_polyhedron() {
        s.to_trimesh()
    } else if let Some(s) = shape.as_trimesh() {
        (s.vertices().to_vec(), s.indices().to_vec())
    } else {
        return None;
    })
}

impl Bodies {
    /// Body `i`'s shape as triangles in its own frame (m): vertices (V·3) and corner indices
    /// (T·3), what the renderer draws; a ball and a capsule as 16 × 32 facets.
    pub fn body_mesh(&self, i: usize) -> Result<(Vec<Real>, Vec<u32>)> {
        if i >= self.handles.len() {
            return Err(invalid("body", format!("{i} is not a body of the scene (0..{})", self.handles.len())));
        }
        let shape = self.d.r.colliders[self.colliders[i]].shape();
        let Some((v, t)) = shape_mesh(shape) else {
            return Err(invalid("body", format!("{i}'s shape cannot be drawn")));
        };
        Ok((v.iter().flat_map(|p| [p.x, p.y, p.z]).collect(), t.into_iter().flatten().collect()))
    }
}

/// A body's world inverse inertia as (m11, m12, m13, m22, m23, m33).
fn inv_inertia6(body: &RigidBody) -> [Real; 6] {
    let m = body.mass_properties().effective_world_inv_inertia;
    [m.m11, m.m12, m.m13, m.m22, m.m23, m.m33]
}

/// An angular velocity as three components.
fn ang3(w: AngVector) -> [Real; 3] {
    [w.x, w.y, w.z]
}

/// Three components of an angular impulse as the dimension's.
fn ang_of(l: [Real; 3]) -> AngVector {
    Vector::new(l[0], l[1], l[2])
}

/// ω × r.
fn ang_cross(w: AngVector, r: Vector) -> Vector {
    w.cross(r)
}

/// The moment r × j.
fn moment(r: Vector, j: Vector) -> AngVector {
    r.cross(j)
}

/// The rolling part of a relative angular velocity `w` at a contact of normal `n`: w less its
/// twist about n, which rolls nothing (as the grains' rolling resistance takes it).
fn rolling_part(w: AngVector, n: Vector) -> AngVector {
    w - n * w.dot(n)
}

fn ang_norm(w: AngVector) -> Real {
    w.length()
}

fn ang_dot(a: AngVector, b: AngVector) -> Real {
    a.dot(b)
}

const ANG_ZERO: AngVector = Vector::ZERO;

/// Two orthonormal tangents of a contact of normal `n`.
const TANGENTS: usize = 2;
fn tangents(n: Vector) -> [Vector; 2] {
    let (a, b) = n.any_orthonormal_pair();
    [a, b]
}

/// 3D bodies turn without rapier's gyroscopic pass (`gyroscopic_step` replaces it).
fn own_gyroscopic(b: RigidBodyBuilder) -> RigidBodyBuilder {
    b.gyroscopic_forces_enabled(false)
}

/// A body held by a joint keeps rapier's gyroscopic pass (see `gyroscopic_step` for why).
fn joined_gyroscopic(bodies: &mut RigidBodySet, h: RigidBodyHandle) {
    if let Some(b) = bodies.get_mut(h) {
        if b.is_dynamic() && !b.gyroscopic_forces_enabled() {
            b.enable_gyroscopic_forces(true);
        }
    }
}

/// The gyroscopic term of every dynamic body not held by a joint over one step `dt`: Euler's
/// equations without torque, dL/dt = L × I⁻¹L for the angular momentum L in the principal
/// frame, by the implicit midpoint rule (solved by Newton's method) in each of rapier's
/// `substeps` substeps of h = dt/substeps. The rule keeps every quadratic invariant of the
/// flow exactly, here |L|² and the kinetic energy ½ L·I⁻¹L, so a spin about the largest or
/// smallest axis stays on its closed curve at any step (Hairer, Lubich and Wanner, *Geometric
/// Numerical Integration*, 2006, §IV.2 and §VII.5). rapier's own pass (one explicit Euler step
/// with |L| rescaled, after Jolt) spirals out of both: a box spun about its largest axis
/// wobbled +166 % in 40 s at dt = 1/60.
///
/// The body turns with it so that the world's L stays put. A substep is L₁ = Cay(−h Ŵ) L₀
/// with W = I⁻¹(L₀ + L₁)/2 and Cay(X) = (1 − X/2)⁻¹(1 + X/2) (a Cayley transform), so
/// principal axes A (principal frame to world) turned to A₁ = A₀ Cay(h Ŵ), a rotation about W
/// by 2 atan(|W| h/2), keep the world's L exactly: A₁ L₁ = A₀ L₀. The substeps' turns make one
/// rotation of the body, by θ about an axis u; rapier turns a body in each substep by the unit
/// quaternion along (ω h/2, 1), a rotation about ω by 2 atan(|ω| h/2) (its
/// `integrate_linearized`), and a body turning freely keeps its ω through them, so the body is
/// given ω = u (2/h) tan(θ/(2 substeps)) for rapier's step. (About a principal axis that is
/// rapier's own turn, ω unchanged. `substeps` must be rapier's: its `num_solver_iterations`,
/// plus a body's `additional_solver_iterations`, which physcore never sets.) Turned about the
/// end-of-step ω instead (as before), L turned at first order in dt: 0.013° in 5 s at
/// dt = 1e-3 for a tumbling brick. After rapier's step `end_turns` sets ω from L₀ and what
/// rapier's solver added (contacts).
///
/// Bodies held by joints keep rapier's pass, applied in each of its substeps: a joint solved
/// at first order drains energy, and this rule, once a step outside the substeps, let a top
/// started in steady precession sink 3× faster per precession period than rapier's (0.063
/// against 0.022 rad at dt = 1e-3). Heavy tops have their own step (`tops`). Saved files keep
/// each body's choice (older files: rapier's for every body), so a loaded scene steps on as it
/// was saved.
fn gyroscopic_step(bodies: &mut RigidBodySet, dt: Real, substeps: usize) -> Vec<Turn> {
    let mut turns = Vec::new();
    let n = substeps.max(1);
    let h = dt / n as Real;
    for (handle, b) in bodies.iter() {
        if !b.is_dynamic() || b.is_sleeping() || b.gyroscopic_forces_enabled() {
            continue;
        }
        let mp = &b.mass_properties().local_mprops;
        let inv = mp.inv_principal_inertia;
        // A locked or massless axis has no gyroscopic term to take.
        if !(inv.x > 0.0 && inv.y > 0.0 && inv.z > 0.0) || b.angvel() == Vector::ZERO {
            continue;
        }
        let axes = *b.rotation() * mp.principal_inertia_local_frame;
        let l0 = (axes.inverse() * b.angvel()) / inv;
        // The substeps' turns, composed in the principal frame at the start.
        let (mut l, mut turn) = (l0, Rotation::IDENTITY);
        for _ in 0..n {
            let l1 = Vector::from(midpoint_euler(l.into(), inv.into(), h));
            let half = (l + l1) * inv * (0.25 * h);
            turn = (turn * Rotation::from_xyzw(half.x, half.y, half.z, 1.0).normalize()).normalize();
            l = l1;
        }
        // θ/2 = atan2(|v|, w) for the quaternion (v, w), taken with w ≥ 0 (glam's axis and
        // angle round turns under 2e-8 rad to none).
        let sign = if turn.w < 0.0 { -1.0 } else { 1.0 };
        let (v, w) = (Vector::new(turn.x, turn.y, turn.z) * sign, turn.w * sign);
        let len = v.length();
        let rate = (2.0 / h) * (len.atan2(w) / n as Real).tan();
        let given = if len > 0.0 { axes * (v * (rate / len)) } else { Vector::ZERO };
        if given.is_finite() && l.is_finite() {
            turns.push(Turn { h: handle, given, l: axes * l0, axes, frame: mp.principal_inertia_local_frame, inv });
        }
    }
    for t in &turns {
        if let Some(b) = bodies.get_mut(t.h) {
            b.set_angvel(t.given, false);
        }
    }
    turns
}

/// A free body's turn in a step (`gyroscopic_step`), finished after rapier's (`end_turns`).
struct Turn {
    h: RigidBodyHandle,
    /// The angular velocity rapier turns the body with (world frame, rad/s).
    given: Vector,
    /// The angular momentum about the centre of mass at the start (world frame, kg·m²/s).
    l: Vector,
    /// The principal axes at the start (principal frame to world), the principal frame in the
    /// body's, and the principal inverse inertia (1/(kg·m²)).
    axes: Rotation,
    frame: Rotation,
    inv: Vector,
}

/// Each free body's angular velocity after rapier's step, from its angular momentum: the one
/// it started with plus the angular impulse rapier's solver gave it (contacts), I₀ Δω for the
/// change Δω from the velocity it was given (its solver turns impulses into velocity with the
/// start's inverse inertia), so ω = I₁⁻¹ (L₀ + I₀ Δω) with I₁ at the new orientation. A body
/// that touched nothing (Δω = 0) keeps L₀, and its principal-frame L is the midpoint rule's
/// (to rounding): A₁ᵀ L₀ for A₁ = A₀ Cay(h Ŵ₁)… (`gyroscopic_step`). Turning the rule's L by
/// A₁ instead would carry the momentum round by the turn a contact gave too: a box landing on
/// a frictionless floor, whose pushes have no moment about the vertical, lost 22 % of its
/// vertical L that way in 3 s at dt = 1e-3; this way it keeps it to rounding.
fn end_turns(bodies: &mut RigidBodySet, turns: Vec<Turn>) {
    for t in turns {
        let Some(b) = bodies.get_mut(t.h) else {
            continue;
        };
        let dw = b.angvel() - t.given;
        let l = t.l + t.axes * ((t.axes.inverse() * dw) / t.inv);
        let axes = *b.rotation() * t.frame;
        let w = axes * ((axes.inverse() * l) * t.inv);
        if w.is_finite() {
            b.set_angvel(w, false);
        }
    }
}

fn cross(a: [Real; 3], b: [Real; 3]) -> [Real; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// L₁ = L₀ + dt · m × (I⁻¹ m), m = (L₀ + L₁)/2: the implicit midpoint step of Euler's
/// torque-free equations in the principal frame (`inv`: the principal inverse inertia). Newton's
/// method from L₀; it converges in a few iterations for dt·|ω| up to about 1 (a turn of a
/// radian a step), and stops at the float64 floor or after 50.
fn midpoint_euler(l0: [Real; 3], inv: [Real; 3], dt: Real) -> [Real; 3] {
    let scale = l0.iter().fold(0.0, |a: Real, x| a.max(x.abs()));
    let mut l1 = l0;
    for _ in 0..50 {
        let m = [0.5 * (l0[0] + l1[0]), 0.5 * (l0[1] + l1[1]), 0.5 * (l0[2] + l1[2])];
        let w = [inv[0] * m[0], inv[1] * m[1], inv[2] * m[2]];
        let g = cross(m, w);
        let f = [l1[0] - l0[0] - dt * g[0], l1[1] - l0[1] - dt * g[1], l1[2] - l0[2] - dt * g[2]];
        // J = 1 − (dt/2)(−[w]× + [m]× diag(inv)): d(m × I⁻¹m)/dm, and dm/dL₁ = 1/2.
        let h = 0.5 * dt;
        let j = [
            [1.0, h * (-w[2] + m[2] * inv[1]), h * (w[1] - m[1] * inv[2])],
            [h * (w[2] - m[2] * inv[0]), 1.0, h * (-w[0] + m[0] * inv[2])],
            [h * (-w[1] + m[1] * inv[0]), h * (w[0] - m[0] * inv[1]), 1.0],
        ];
        let Some(d) = solve3(j, [-f[0], -f[1], -f[2]]) else {
            break;
        };
        l1 = [l1[0] + d[0], l1[1] + d[1], l1[2] + d[2]];
        if d.iter().all(|x| x.abs() <= 1e-15 * scale) {
            break;
        }
    }
    l1
}

/// x with a x = b (Cramer's rule; `None` if a is singular).
fn solve3(a: [[Real; 3]; 3], b: [Real; 3]) -> Option<[Real; 3]> {
    let det = |m: [[Real; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    if !(d.is_finite() && d != 0.0) {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        *xk = det(m) / d;
    }
    Some(x)
}

/// A heavy top's next state, computed before rapier's step and put in place of rapier's after it
/// (`place_tops`) where nothing touched the body in that step.
struct Top {
    h: RigidBodyHandle,
    pose: Pose,
    v: Vector,
    w: Vector,
}

/// Every dynamic body held at one point by a free spherical joint (no limit, no motor) to a
/// fixed body, and by nothing else: a heavy top. rapier's joint is solved at first order and its
/// gyroscopic term is explicit, so such a top started in steady precession sank by 0.022 rad a
/// precession period at dt = 1e-3 (0.46 rad at 1/60) while gaining energy, and more substeps
/// traded the sinking for more energy. Here its step is the top's own: the body turns about the
/// pivot with the inertia there (parallel axes), by the symplectic splitting of Dullweber,
/// Leimkuhler and McLachlan (J. Chem. Phys. 107 (1997) 5840, §III): half a kick of gravity's
/// torque about the pivot, the free rotation as five exact turns about the principal axes
/// (x, y by half a step, z by a whole one, y, x), half a kick. It is second order, keeps |L|
/// in the free flight, and its energy error stays bounded (no drift), so the top precesses level.
///
/// The angular momentum about the pivot is taken from the body's velocities as they are, linear
/// and angular: an impulse given to the body before the step (grains, pins) keeps it, as the
/// pivot's reaction would. Bodies with damping, user forces, locked axes, or asleep stay
/// rapier's, as does any top that touched anything in the step (`place_tops`).
fn tops(r: &Rapier, gravity: Vector, dt: Real) -> Vec<Top> {
    let mut found = Vec::new();
    for (_, j) in r.impulse_joints.iter() {
        let d = &j.data;
        if d.locked_axes != JointAxesMask::LOCKED_SPHERICAL_AXES
            || !d.limit_axes.is_empty()
            || !d.motor_axes.is_empty()
            || !d.coupled_axes.is_empty()
        {
            continue;
        }
        let (b1, b2) = (&r.bodies[j.body1()], &r.bodies[j.body2()]);
        let (h, body, anchor, pivot) = match (b1.is_fixed(), b2.is_fixed()) {
            (true, false) => (j.body2(), b2, d.local_anchor2(), *b1.position() * d.local_anchor1()),
            (false, true) => (j.body1(), b1, d.local_anchor1(), *b2.position() * d.local_anchor2()),
            _ => continue,
        };
        if !body.is_dynamic()
            || body.is_sleeping()
            || r.impulse_joints.attached_joints(h).count() != 1
            || body.linear_damping() != 0.0
            || body.angular_damping() != 0.0
            || !body.locked_axes().is_empty()
            || body.user_force() != Vector::ZERO
            || body.user_torque() != ANG_ZERO
        {
            continue;
        }
        if let Some(top) = top_step(h, body, anchor, pivot, gravity * body.gravity_scale(), dt) {
            found.push(top);
        }
    }
    found
}

/// One step of the splitting above for the body `h` held at its local point `anchor` at the
/// world point `pivot`. `None` (rapier steps it) if its mass or an inertia is zero, if its
/// anchor has drifted from the pivot by more than 1e-6 of its reach, or if anything is not
/// finite.
fn top_step(h: RigidBodyHandle, body: &RigidBody, anchor: Vector, pivot: Vector, g: Vector, dt: Real) -> Option<Top> {
    let mp = &body.mass_properties().local_mprops;
    let m = mp.mass();
    let inv = mp.inv_principal_inertia;
    if !(m > 0.0 && inv.x > 0.0 && inv.y > 0.0 && inv.z > 0.0) {
        return None;
    }
    let q = *body.rotation();
    let c = mp.local_com - anchor; // the centre of mass from the pivot, body frame
    let drift = (*body.position() * anchor - pivot).length();
    if !(drift <= 1e-6 * c.length()) {
        return None;
    }
    // The inertia about the pivot in the body frame: I_cm + m(|c|²1 − c cᵀ).
    let pf = Matrix::from_quat(mp.principal_inertia_local_frame);
    let icm = pf * Matrix::from_diagonal(Vector::new(1.0 / inv.x, 1.0 / inv.y, 1.0 / inv.z)) * pf.transpose();
    let ip = icm + (Matrix::IDENTITY * c.length_squared() - outer(c, c)) * m;
    let (axes, jp) = eigen3(ip)?;
    let rp = Rotation::from_mat3(&axes);
    // L about the pivot, world frame, from the velocities as they are.
    let r = q * c;
    let mut l = q * (icm * (q.inverse() * body.angvel())) + r.cross(body.linvel()) * m;
    let mut a = q * rp; // principal frame of the pivot's inertia → world
    let kick = |l: Vector, a: Rotation| l + (a * (rp.inverse() * c)).cross(g * m) * (0.5 * dt);
    l = kick(l, a);
    let mut p = a.inverse() * l;
    for (k, t) in [(0, 0.5), (1, 0.5), (2, 1.0), (1, 0.5), (0, 0.5)] {
        let e = Vector::AXES[k];
        let turn = Rotation::from_axis_angle(e, t * dt * p[k] / jp[k]);
        p = turn.inverse() * p;
        a = (a * turn).normalize();
    }
    l = kick(a * p, a);
    let rot = (a * rp.inverse()).normalize();
    let w = a * ((a.inverse() * l) / jp);
    let r1 = rot * c;
    let pose = Pose::from_parts(pivot - rot * anchor, rot);
    let top = Top { h, pose, v: w.cross(r1), w };
    (top.v.is_finite() && top.w.is_finite() && top.pose.translation.is_finite()).then_some(top)
}

/// Puts each top's own step in place of rapier's, unless the top touched something in it (any
/// collider of it with a contact in the solver, speculative ones included): then rapier's
/// solve, which saw the contact, stands.
fn place_tops(r: &mut Rapier, tops: Vec<Top>) {
    for t in tops {
        let touched = r.bodies[t.h].colliders().iter().any(|&c| {
            r.narrow_phase
                .contact_pairs_with(c)
                .any(|p| p.manifolds().iter().any(|m| !m.data.solver_contacts.is_empty()))
        });
        if touched {
            continue;
        }
        let body = &mut r.bodies[t.h];
        body.set_position(t.pose, false);
        body.set_linvel(t.v, false);
        body.set_angvel(t.w, false);
        for &c in body.colliders() {
            if let Some(rel) = r.colliders[c].position_wrt_parent().copied() {
                r.colliders[c].set_position(t.pose * rel);
            }
        }
    }
}

fn outer(a: Vector, b: Vector) -> Matrix {
    Matrix::from_cols(a * b.x, a * b.y, a * b.z)
}

/// The eigenvectors (columns, a right-handed frame) and eigenvalues of a symmetric 3 × 3
/// matrix, by cyclic Jacobi rotations (Golub and Van Loan, *Matrix Computations*, §8.5); `None`
/// if it does not converge or an eigenvalue is not positive.
fn eigen3(m: Matrix) -> Option<(Matrix, Vector)> {
    let mut a = [[0.0; 3]; 3];
    for (i, row) in a.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = m.col(j)[i];
        }
    }
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = (0..3).map(|i| a[i][i].abs()).fold(0.0, Real::max);
    let mut done = false;
    for _ in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-17 * scale {
            done = true;
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let cs = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * cs;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = cs * akp - sn * akq;
                a[k][q] = sn * akp + cs * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = cs * apk - sn * aqk;
                a[q][k] = sn * apk + cs * aqk;
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = cs * vp - sn * vq;
                row[q] = sn * vp + cs * vq;
            }
        }
    }
    let vals = Vector::new(a[0][0], a[1][1], a[2][2]);
    let col = |k: usize| Vector::new(v[0][k], v[1][k], v[2][k]);
    let (c0, c1) = (col(0), col(1));
    // A right-handed frame: the third axis from the first two.
    let axes = Matrix::from_cols(c0, c1, c0.cross(c1));
    (done && vals.min_element() > 0.0 && vals.is_finite()).then_some((axes, vals))
}

include!("common.rs");
