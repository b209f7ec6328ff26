//! The rigid bodies of a 2D world (`rapier2d-f64`): what differs from 3D, then the system
//! itself (`common.rs`, shared with `dim3`).
use super::{built, finite_all, pack, particle_kinetic, resolvable, take_len, unpack};
use crate::alloc::{count, Need};
use crate::error::{invalid, Failure, Result};
use crate::systems::{array, Arrays, Coupling, EnergyReport, Halt, Snapshot, System};
use crate::terms::registry::Params;
use crate::terms::BodyMotion;
use crate::vector::{Real, Vector as PVector};
use physcore_bodies_io::dim2 as io;
use rapier2d_f64::geometry::{
    ContactData, ContactManifold, ContactPair, SolverContact, TrackedContact, NEW_CONTACT_BIT,
};
use rapier2d_f64::parry::bounding_volume::{BoundingSphere, BoundingVolume};
use rapier2d_f64::prelude::*;
use std::sync::atomic::AtomicBool;

const D: usize = 2;

/// These bodies as the coupling's role hands them out, and back (`None`: the other dimension's).
fn as_bodies_of(b: &mut Bodies) -> crate::systems::BodiesOf<'_> {
    crate::systems::BodiesOf::Two(b)
}
fn of_this_dim(b: crate::systems::BodiesOf<'_>) -> Option<&mut Bodies> {
    match b {
        crate::systems::BodiesOf::Two(b) => Some(b),
        _ => None,
    }
}
/// Values per body of the orientation (an angle) and of the angular velocity (about z).
const ROT: usize = 1;
const ANG: usize = 1;
const ROTATION_KEY: &str = "angles";
/// The shape kinds of a group, as Python names them ("polyline": fixed bodies only).
pub const SHAPES: [&str; 5] = ["ball", "box", "capsule", "polygon", "polyline"];
pub const JOINTS: [&str; 4] = ["revolute", "fixed", "prismatic", "rope"];
/// A prismatic joint's axis when none is given.
const DEFAULT_AXIS: [Real; 2] = [1.0, 0.0];
const FIELDS: [&str; 8] = ["x", "y", "angle", "vx", "vy", "omega", "mass", "inertia"];
const READABLE: [&str; 8] = FIELDS;
/// The first SETTABLE fields can be set.
const SETTABLE: usize = 6;

fn settable_width(name: &str) -> Option<usize> {
    FIELDS[..SETTABLE].contains(&name).then_some(1)
}

fn vector(s: &[Real]) -> Vector {
    Vector::new(s[0], s[1])
}

fn rotation(s: &[Real]) -> Result<Rotation> {
    Ok(Rotation::new(s[0]))
}

fn ang_vector(s: &[Real]) -> AngVector {
    s[0]
}

fn rotation_finite(r: &Rotation) -> bool {
    r.angle().is_finite()
}

fn size_len(shape: &str) -> usize {
    match shape {
        "ball" => 1,
        "polygon" | "polyline" => 0,
        _ => 2,
    }
}

fn sized_shape(shape: &str, s: &[Real]) -> ColliderBuilder {
    match shape {
        "ball" => ColliderBuilder::ball(s[0]),
        "box" => ColliderBuilder::cuboid(s[0], s[1]),
        _ => ColliderBuilder::capsule_x(s[0], s[1]),
    }
}

/// What a collider's shape lacks in parry's mass properties, as mass properties of no mass to
/// add to its body (`None`: nothing). parry2d gives a capsule (a stadium) the caps of its 3D
/// namesake: each half-disc's centre of mass 3r/8 from its flat side (a hemisphere's) instead
/// of 4r/(3π), so its moment of inertia came 1.9 % low for l = 2r. The exact one about the
/// centre, for half-length l, radius r and density ρ, by the parallel-axis theorem (a half-disc
/// of mass m_d/2 has (m_d/2) r²/2 about the middle of its flat side, its centroid 4r/(3π) from
/// it, and its centroid l + 4r/(3π) from the centre):
/// I = m_rect ((2l)² + (2r)²)/12 + m_d (r²/2 + l² + 2l · 4r/(3π)), m_rect = 4ρlr, m_d = ρπr².
/// The difference from parry's own (so a parry that gets it right adds nothing).
fn added_mass(c: &Collider) -> Option<MassProperties> {
    let cap = c.shape().as_capsule()?;
    let (l, r, rho) = (0.5 * cap.segment.length(), cap.radius, c.density());
    let (m_rect, m_disc) = (4.0 * rho * l * r, rho * std::f64::consts::PI * r * r);
    let centroid = 4.0 * r / (3.0 * std::f64::consts::PI);
    let exact = m_rect * (4.0 * l * l + 4.0 * r * r) / 12.0 + m_disc * (0.5 * r * r + l * l + 2.0 * l * centroid);
    let missing = exact - c.shape().mass_properties(rho).principal_inertia();
    (missing.abs() > 1e-12 * exact).then(|| MassProperties::new(Vector::ZERO, 0.0, missing))
}

/// A polygon group's one shape: the convex hull of its `vertices` (K·2 values, `n_vertices`);
/// a polyline group's: the chain of segments through them, for fixed bodies only (a chain of
/// segments has no area, so no mass: ground profiles, ramps, a bowl's section).
/// What building a shape of `k` vertices needs, checked to be there (parry allocates
/// infallibly): the points, and a hull's or a polyline's working lists, taken as 256 bytes a
/// vertex.
fn shape_need(k: usize) -> Need {
    Need::new("add_bodies", k as u128 * 256, format!("a shape of {} vertices", count(k as u128)))
}

fn listed_shape(shape: &str, kind: &str, p: &mut Params) -> Result<Option<ColliderBuilder>> {
    if shape != "polygon" && shape != "polyline" {
        return Ok(None);
    }
    let k = p.count("n_vertices", 1 << 20)?;
    let v = take_len(p, "vertices", 2 * k)?;
    let hull = shape_need(k).collect(v.chunks_exact(2).map(vector))?;
    if shape == "polyline" {
        if kind != "fixed" {
            return Err(invalid("kind", "a polyline has no area and so no mass: make it kind=\"fixed\""));
        }
        if hull.len() < 2 {
            return Err(invalid("vertices", "a polyline needs at least 2 vertices"));
        }
        if let Some(j) = (1..hull.len()).find(|&j| hull[j] == hull[j - 1]) {
            return Err(invalid("vertices", format!("vertices {} and {j} coincide (a segment of no length)", j - 1)));
        }
        resolvable(&v, 2)?;
        shape_need(k).room(k as u128 * 256)?;
        return built("vertices", || Ok(ColliderBuilder::polyline(hull, None))).map(Some);
    }
    if hull.len() < 3 {
        return Err(invalid("vertices", "a polygon needs at least 3 vertices"));
    }
    resolvable(&v, 2)?;
    shape_need(k).room(k as u128 * 256)?;
    built("vertices", || {
        ColliderBuilder::convex_hull(&hull).ok_or_else(|| "their convex hull is degenerate (all on one line)".into())
    })
    .map(Some)
}

/// A hinge in the plane: it turns about z, whatever the axis.
fn revolute(_axis1: Vector, _axis2: Vector) -> RevoluteJointBuilder {
    RevoluteJointBuilder::new()
}

fn spherical(_la: Vector, _lb: Vector) -> GenericJoint {
    unreachable!("not a joint of the plane: refused with the kind")
}

/// The turning term (r×t)²/I of a body's effective mass along t (r: from its centre of mass).
fn turning(body: &RigidBody, rc: Vector, t: Vector) -> Real {
    let r = rc.perp_dot(t);
    r * r * body.mass_properties().effective_world_inv_inertia
}

fn get_one(b: &RigidBody, name: &str) -> Real {
    match name {
        "x" => b.translation().x,
        "y" => b.translation().y,
        "angle" => b.rotation().angle(),
        "vx" => b.linvel().x,
        "vy" => b.linvel().y,
        "omega" => b.angvel(),
        "mass" => b.mass(),
        _ => b.mass_properties().local_mprops.principal_inertia(),
    }
}

/// Sets field `name` of body `b` to `row` (its values); `dry`: only checks.
fn set_one(b: &mut RigidBody, name: &str, row: &[Real], dry: bool) -> std::result::Result<(), String> {
    if dry {
        return Ok(());
    }
    let (t, v, val) = (b.translation(), b.linvel(), row[0]);
    match name {
        "x" => b.set_translation(Vector::new(val, t.y), true),
        "y" => b.set_translation(Vector::new(t.x, val), true),
        "angle" => b.set_rotation(Rotation::new(val), true),
        "vx" => b.set_linvel(Vector::new(val, v.y), true),
        "vy" => b.set_linvel(Vector::new(v.x, val), true),
        _ => b.set_angvel(val, true),
    }
    Ok(())
}

/// Points on the outline of `shape` (its own frame) set `inset` inside it, about `spacing` apart,
/// every corner among them: a body's boundary particles for a fluid (Akinci et al. 2012 sample
/// the surface at the fluid's spacing; half a spacing inside, the fluid's edge, half a spacing
/// beyond its last particle, meets the surface, as at a wall of lattice particles). Balls and
/// capsules are walked along a fine polygon (256 and 128 sides a cap); a polygon's outline is
/// moved in by its edges' normals (exact for a convex one). The inset is at most half the
/// shape's smallest half-extent. Empty for a shape with no inside (a polyline).
fn surface_samples(
    shape: &dyn Shape,
    spacing: Real,
    inset: Real,
    room: &dyn Fn(usize) -> Result<()>,
    _stop: &AtomicBool,
) -> Result<Vec<Vector>> {
    // (A ring of millions of points is walked in a fraction of a second: no stop to watch.)
    let he = shape.compute_local_aabb().half_extents();
    let d = inset.min(0.5 * he.x.min(he.y));
    let ring: Vec<Vector> = if let Some(b) = shape.as_ball() {
        Ball::new(b.radius - d).to_polyline(256)
    } else if let Some(c) = shape.as_cuboid() {
        Cuboid::new(c.half_extents - Vector::splat(d)).to_polyline()
    } else if let Some(c) = shape.as_capsule() {
        Capsule::new(c.segment.a, c.segment.b, c.radius - d).to_polyline(128)
    } else if let Some(p) = shape.as_convex_polygon() {
        let (pts, nrm) = (p.points(), p.normals());
        let n = pts.len();
        // Vertex i joins edges i − 1 and i: moved so that both edges move in by d.
        (0..n)
            .map(|i| {
                let (a, b) = (nrm[(i + n - 1) % n], nrm[i]);
                pts[i] - (a + b) * (d / (1.0 + a.dot(b)).max(0.1))
            })
            .collect()
    } else {
        return Ok(Vec::new());
    };
    // About one point a spacing, and every corner: asked for before any is made.
    let perimeter: Real = (0..ring.len()).map(|i| (ring[(i + 1) % ring.len()] - ring[i]).length()).sum();
    room(((perimeter / spacing).ceil() as usize).saturating_add(2 * ring.len()))?;
    Ok(walk_ring(&ring, spacing))
}

/// Points about `spacing` apart along the closed polygon `ring`: each run between corners (turns
/// of more than 15°; the whole ring if it has none) walked by arc length from its corner, so
/// every corner is a point and the points are evenly spaced between.
fn walk_ring(ring: &[Vector], spacing: Real) -> Vec<Vector> {
    let n = ring.len();
    if n < 2 {
        return ring.to_vec();
    }
    let dir = |i: usize| (ring[(i + 1) % n] - ring[i]).normalize_or_zero();
    let turn = (15.0 as Real).to_radians().cos();
    let mut starts: Vec<usize> = (0..n).filter(|&i| dir((i + n - 1) % n).dot(dir(i)) < turn).collect();
    if starts.is_empty() {
        starts.push(0);
    }
    let mut out = Vec::new();
    for (r, &s) in starts.iter().enumerate() {
        let e = starts[(r + 1) % starts.len()];
        let mut run = vec![ring[s]];
        let mut i = s;
        loop {
            i = (i + 1) % n;
            run.push(ring[i]);
            if i == e {
                break;
            }
        }
        let lens: Vec<Real> = run.windows(2).map(|w| (w[1] - w[0]).length()).collect();
        let total: Real = lens.iter().sum();
        let m = ((total / spacing).round() as usize).max(1);
        let (mut seg, mut done) = (0, 0.0);
        for k in 0..m {
            let at = k as Real * total / m as Real;
            while seg + 1 < lens.len() && done + lens[seg] < at {
                done += lens[seg];
                seg += 1;
            }
            let t = if lens[seg] > 0.0 { ((at - done) / lens[seg]).min(1.0) } else { 0.0 };
            out.push(run[seg] + (run[seg + 1] - run[seg]) * t);
        }
    }
    out
}

/// A body's world inverse inertia as (m11, m12, m13, m22, m23, m33): in the plane only m33.
fn inv_inertia6(body: &RigidBody) -> [Real; 6] {
    [0.0, 0.0, 0.0, 0.0, 0.0, body.mass_properties().effective_world_inv_inertia]
}

/// An angular velocity as three components, (0, 0, ω) in the plane.
fn ang3(w: AngVector) -> [Real; 3] {
    [0.0, 0.0, w]
}

/// Three components of an angular impulse as the dimension's (its z).
fn ang_of(l: [Real; 3]) -> AngVector {
    l[2]
}

/// ω × r for an angular velocity about z.
fn ang_cross(w: AngVector, r: Vector) -> Vector {
    Vector::new(-w * r.y, w * r.x)
}

/// The moment r × j (about z).
fn moment(r: Vector, j: Vector) -> AngVector {
    r.perp_dot(j)
}

/// The rolling part of a relative angular velocity at a contact of normal `n`: all of it in
/// the plane (a turn about z rolls every contact of the plane).
fn rolling_part(w: AngVector, _n: Vector) -> AngVector {
    w
}

fn ang_norm(w: AngVector) -> Real {
    w.abs()
}

fn ang_dot(a: AngVector, b: AngVector) -> Real {
    a * b
}

const ANG_ZERO: AngVector = 0.0;

/// The tangents of a contact of normal `n`: one in the plane (the second unused).
const TANGENTS: usize = 1;
fn tangents(n: Vector) -> [Vector; 2] {
    [n.perp(), Vector::ZERO]
}

impl Bodies {
    /// 2D bodies have outlines, not meshes (`RigidBodies::body_mesh`).
    pub fn body_mesh(&self, _i: usize) -> Result<(Vec<Real>, Vec<u32>)> {
        Err(invalid("dim", "body meshes are for 3D bodies (2D bodies have outlines)"))
    }
}

/// In the plane a body turns about its one axis: no gyroscopic term (rapier's pass is 3D only).
fn own_gyroscopic(b: RigidBodyBuilder) -> RigidBodyBuilder {
    b
}
fn joined_gyroscopic(_bodies: &mut RigidBodySet, _h: RigidBodyHandle) {}
struct Turn;
fn gyroscopic_step(_bodies: &mut RigidBodySet, _dt: Real, _substeps: usize) -> Vec<Turn> {
    Vec::new()
}
fn end_turns(_bodies: &mut RigidBodySet, _turns: Vec<Turn>) {}
/// No tops in the plane: a body on a joint turns about one axis, as rapier steps it.
struct Top;
fn tops(_r: &Rapier, _gravity: Vector, _dt: Real) -> Vec<Top> {
    Vec::new()
}
fn place_tops(_r: &mut Rapier, _tops: Vec<Top>) {}

include!("common.rs");
