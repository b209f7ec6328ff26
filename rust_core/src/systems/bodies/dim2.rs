//! The rigid bodies of a 2D world (`rapier2d-f64`): what differs from 3D, then the system
//! itself (`common.rs`, shared with `dim3`).
use super::{finite_all, pack, particle_kinetic, take_len, unpack};
use crate::error::{invalid, Failure, Result};
use crate::systems::{array, Arrays, Coupling, EnergyReport, Halt, Snapshot, System};
use crate::terms::registry::Params;
use crate::vector::{Real, Vector as PVector};
use rapier2d_f64::parry::bounding_volume::BoundingVolume;
use rapier2d_f64::prelude::*;
use std::sync::atomic::AtomicBool;

const D: usize = 2;
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

/// A polygon group's one shape: the convex hull of its `vertices` (K·2 values, `n_vertices`);
/// a polyline group's: the chain of segments through them, for fixed bodies only (a chain of
/// segments has no area, so no mass: ground profiles, ramps, a bowl's section).
fn listed_shape(shape: &str, kind: &str, p: &mut Params) -> Result<Option<ColliderBuilder>> {
    if shape != "polygon" && shape != "polyline" {
        return Ok(None);
    }
    let k = p.count("n_vertices", 1 << 20)?;
    let v = take_len(p, "vertices", 2 * k)?;
    let hull: Vec<Vector> = v.chunks_exact(2).map(vector).collect();
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
        return Ok(Some(ColliderBuilder::polyline(hull, None)));
    }
    if hull.len() < 3 {
        return Err(invalid("vertices", "a polygon needs at least 3 vertices"));
    }
    ColliderBuilder::convex_hull(&hull)
        .map(Some)
        .ok_or_else(|| invalid("vertices", "their convex hull is degenerate (all on one line)"))
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

include!("common.rs");
