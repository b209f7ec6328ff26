//! Rigid bodies in 2D (balls, boxes, capsules, convex polygons; revolute, fixed, prismatic and
//! rope joints), solved by rapier (Crozet, dimforge: rapier2d-f64). Contact and joint solving
//! is a field of its own with a well-kept library: physcore adds what it does not have, the
//! coupling with particles ([`BodyContacts`]), the energy books, rollback and bit-identical
//! restarts, and the rendering.
//!
//! Why rapier: deterministic (its `enhanced-determinism` feature: libm's functions, the same
//! bits on every platform), double precision, serialisable state (serde), and no threads of its
//! own here (no `parallel` feature), so results never depend on the thread count.
//!
//! Bodies are numbered in the order they were added, across groups (the Python `Bodies` parts):
//! the fields (`x`, `y`, `angle`, `vx`, `vy`, `omega`, `mass`) hold one value per body in that
//! order. A group is one shape kind; joints join two bodies (or a body and a fixed point).
//!
//! The books: kinetic energy (translation and rotation) and the potential of uniform gravity
//! of the dynamic bodies; what rapier's contacts, friction, restitution and joints (and its
//! integrator's error) change is booked as one residual, "bodies: contacts and joints", since
//! rapier does not report them apart; what the particle coupling exchanges, as "bodies ⇄
//! particles". So the total balances by construction and the residual is what to read.
use super::{array, Arrays, Coupling, EnergyReport, Halt, Snapshot, System};
use crate::error::{invalid, Failure, Result};
use crate::terms::registry::Params;
use crate::vector::{Real, Vector as PVector};
use rapier2d_f64::parry::bounding_volume::BoundingVolume;
use rapier2d_f64::prelude::*;
use std::sync::atomic::AtomicBool;

/// Everything rapier keeps between steps: what a snapshot copies and a save writes.
#[derive(Clone, serde::Serialize, serde::Deserialize)]
struct Rapier {
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft_bodies: SoftBodySet,
}

/// What `step` changes: rapier's state and the books.
#[derive(Clone, serde::Serialize, serde::Deserialize)]
struct Dynamic {
    r: Rapier,
    /// Energy the contacts and joints took out (J; the residual of each step, see the module).
    contacts: Real,
    /// Energy the particle coupling took out of bodies and particles together (J).
    coupling: Real,
    /// Parts (groups and joint sets) added when this was saved: a load waits for as many.
    parts: usize,
}

/// The rigid bodies of a world (2D).
pub struct Bodies2 {
    name: String,
    d: Dynamic,
    gravity: Vector,
    params: IntegrationParameters,
    pipeline: PhysicsPipeline,
    ccd: CCDSolver,
    /// Each body's handle and its one collider, by body number.
    handles: Vec<RigidBodyHandle>,
    colliders: Vec<ColliderHandle>,
    /// The fixed body, without a collider, that joins to "the world" use.
    anchor: Option<RigidBodyHandle>,
    /// A saved state waiting for the parts it holds to be added again (scene file reader).
    pending: Option<Dynamic>,
}

/// The shape kinds of a group, as Python names them.
pub const SHAPES: [&str; 4] = ["ball", "box", "capsule", "polygon"];
pub const JOINTS: [&str; 4] = ["revolute", "fixed", "prismatic", "rope"];

fn finite_all(key: &str, v: &[Real]) -> Result<()> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(i) => Err(invalid(key, format!("entry {i} is not finite: {}", v[i]))),
        None => Ok(()),
    }
}

fn take_len(p: &mut Params, key: &str, len: usize) -> Result<Vec<Real>> {
    let v = p.take_floats(key)?;
    if v.len() != len {
        return Err(invalid(key, format!("has {} values, expected {len}", v.len())));
    }
    finite_all(key, &v)?;
    Ok(v)
}

impl Bodies2 {
    pub fn new(name: &str) -> Self {
        let params = IntegrationParameters::default();
        Self {
            name: name.to_string(),
            d: Dynamic {
                r: Rapier {
                    islands: IslandManager::new(),
                    broad_phase: BroadPhaseBvh::new(),
                    narrow_phase: NarrowPhase::new(),
                    bodies: RigidBodySet::new(),
                    colliders: ColliderSet::new(),
                    impulse_joints: ImpulseJointSet::new(),
                    multibody_joints: MultibodyJointSet::new(),
                    soft_bodies: SoftBodySet::new(),
                },
                contacts: 0.0,
                coupling: 0.0,
                parts: 0,
            },
            gravity: Vector::ZERO,
            params,
            pipeline: PhysicsPipeline::new(),
            ccd: CCDSolver::new(),
            handles: Vec::new(),
            colliders: Vec::new(),
            anchor: None,
            pending: None,
        }
    }

    pub fn n_bodies(&self) -> usize {
        self.handles.len()
    }

    /// Sets the solver's iterations per step (rapier's `num_solver_iterations`, default 4).
    pub fn set_iterations(&mut self, n: usize) -> Result<()> {
        if !(1..=1000).contains(&n) {
            return Err(invalid("iterations", format!("expected 1..=1000, got {n}")));
        }
        self.params.num_solver_iterations = n;
        Ok(())
    }

    /// Adds a group of `n` bodies of one shape (see the Python `Bodies` for the parameters);
    /// returns the number of its first body. Checked whole before anything changes.
    pub fn add_group(&mut self, mut p: Params) -> Result<usize> {
        let shape = p.text("shape")?.to_string();
        if !SHAPES.contains(&shape.as_str()) {
            return Err(invalid("shape", format!("unknown shape {shape:?}; valid: {}", SHAPES.join(", "))));
        }
        let kind = p.text("kind")?.to_string();
        let n = p.count("n", 1 << 24)?;
        if n == 0 {
            return Err(invalid("n", "a group needs at least one body"));
        }
        let x = take_len(&mut p, "positions", 2 * n)?;
        let angle = take_len(&mut p, "angles", n)?;
        let v = take_len(&mut p, "velocities", 2 * n)?;
        let omega = take_len(&mut p, "angular_velocities", n)?;
        let per = match shape.as_str() {
            "ball" => 1,
            "polygon" => 0,
            _ => 2,
        };
        let size = take_len(&mut p, "size", per * n)?;
        if size.iter().any(|&s| s <= 0.0) {
            return Err(invalid("size", "every size must be > 0"));
        }
        let vertices = if shape == "polygon" {
            let len = p_len(&p)?;
            take_len(&mut p, "vertices", len)?
        } else {
            Vec::new()
        };
        let density = p.number("density")?;
        let friction = p.number("friction")?;
        let restitution = p.number("restitution")?;
        if density <= 0.0 {
            return Err(invalid("density", format!("must be > 0 (kg/m²), got {density}")));
        }
        if friction < 0.0 {
            return Err(invalid("friction", format!("must be >= 0, got {friction}")));
        }
        if !(0.0..=1.0).contains(&restitution) {
            return Err(invalid("restitution", format!("must be in [0, 1], got {restitution}")));
        }
        let hull: Vec<Vector> = vertices.chunks_exact(2).map(|c| Vector::new(c[0], c[1])).collect();
        let polygon = if shape == "polygon" {
            if hull.len() < 3 {
                return Err(invalid("vertices", "a polygon needs at least 3 vertices"));
            }
            Some(
                ColliderBuilder::convex_hull(&hull)
                    .ok_or_else(|| invalid("vertices", "their convex hull is degenerate (all on one line)"))?,
            )
        } else {
            None
        };
        let builder = |i: usize| -> RigidBodyBuilder {
            let b = match kind.as_str() {
                "fixed" => RigidBodyBuilder::fixed(),
                "kinematic" => RigidBodyBuilder::kinematic_velocity_based(),
                _ => RigidBodyBuilder::dynamic(),
            };
            b.translation(Vector::new(x[2 * i], x[2 * i + 1]))
                .rotation(angle[i])
                .linvel(Vector::new(v[2 * i], v[2 * i + 1]))
                .angvel(omega[i])
                // Sleeping freezes a body bit for bit at rest: deterministic, and a pile at rest
                // costs nothing, but a body asleep is not woken by particles (see BodyContacts).
                .can_sleep(false)
        };
        if !["dynamic", "fixed", "kinematic"].contains(&kind.as_str()) {
            return Err(invalid("kind", format!("unknown body kind {kind:?}; valid: dynamic, fixed, kinematic")));
        }
        let first = self.handles.len();
        for i in 0..n {
            let c = match shape.as_str() {
                "ball" => ColliderBuilder::ball(size[i]),
                "box" => ColliderBuilder::cuboid(size[2 * i], size[2 * i + 1]),
                "capsule" => ColliderBuilder::capsule_x(size[2 * i], size[2 * i + 1]),
                _ => polygon.clone().expect("checked above"),
            };
            let c = c.density(density).friction(friction).restitution(restitution);
            let h = self.d.r.bodies.insert(builder(i));
            let ch = self.d.r.colliders.insert_with_parent(c, h, &mut self.d.r.bodies);
            self.handles.push(h);
            self.colliders.push(ch);
        }
        self.part_added();
        Ok(first)
    }

    /// Adds `m` joints of one kind between bodies `a[k]` and `b[k]` (body numbers; −1: the
    /// world), at world points `anchor` (`anchor_b` for the second body of a rope; `axis` for a
    /// prismatic joint; `limits` in rad or m; `length`: a rope's longest length, m).
    pub fn add_joints(&mut self, mut p: Params) -> Result<()> {
        let kind = p.text("kind")?.to_string();
        if !JOINTS.contains(&kind.as_str()) {
            return Err(invalid("kind", format!("unknown joint {kind:?}; valid: {}", JOINTS.join(", "))));
        }
        let m = p.count("m", 1 << 24)?;
        let a = take_len(&mut p, "a", m)?;
        let b = take_len(&mut p, "b", m)?;
        let anchor = take_len(&mut p, "anchor", 2 * m)?;
        let anchor_b = if p.has("anchor_b") { take_len(&mut p, "anchor_b", 2 * m)? } else { anchor.clone() };
        let axis = if p.has("axis") { take_len(&mut p, "axis", 2 * m)? } else { [1.0, 0.0].repeat(m) };
        let limits = if p.has("limits") { Some(take_len(&mut p, "limits", 2 * m)?) } else { None };
        let length = if p.has("length") { Some(take_len(&mut p, "length", m)?) } else { None };
        let n = self.handles.len() as Real;
        for (key, ids) in [("a", &a), ("b", &b)] {
            if let Some(k) = ids.iter().position(|&i| i.fract() != 0.0 || i < -1.0 || i >= n) {
                return Err(invalid(key, format!("entry {k} ({}) is not a body of the scene (0..{n}) or -1", ids[k])));
            }
        }
        if let Some(k) = (0..m).find(|&k| a[k] == b[k]) {
            return Err(invalid("b", format!("joint {k} joins body {} to itself", a[k])));
        }
        if let Some(k) = (0..m).find(|&k| a[k] < 0.0 && b[k] < 0.0) {
            return Err(invalid("a", format!("joint {k} joins the world to the world")));
        }
        if let Some(k) = (0..m).find(|&k| axis[2 * k].hypot(axis[2 * k + 1]) == 0.0) {
            return Err(invalid("axis", format!("joint {k}'s axis is zero")));
        }
        if let Some(l) = &limits {
            if let Some(k) = (0..m).find(|&k| l[2 * k] > l[2 * k + 1]) {
                return Err(invalid("limits", format!("joint {k}: lower {} > upper {}", l[2 * k], l[2 * k + 1])));
            }
        }
        if let Some(l) = &length {
            if let Some(k) = l.iter().position(|&v| v < 0.0) {
                return Err(invalid("length", format!("entry {k} is negative")));
            }
        }
        let anchor_body = if a.iter().chain(&b).any(|&i| i < 0.0) {
            Some(match self.anchor {
                Some(h) => h,
                None => self.d.r.bodies.insert(RigidBodyBuilder::fixed()),
            })
        } else {
            None
        };
        self.anchor = self.anchor.or(anchor_body);
        for k in 0..m {
            let h = |i: Real| if i < 0.0 { anchor_body.expect("set above") } else { self.handles[i as usize] };
            let (ha, hb) = (h(a[k]), h(b[k]));
            let pa = Vector::new(anchor[2 * k], anchor[2 * k + 1]);
            let pb = Vector::new(anchor_b[2 * k], anchor_b[2 * k + 1]);
            let la = self.d.r.bodies[ha].position().inverse_transform_point(pa);
            let lb = self.d.r.bodies[hb].position().inverse_transform_point(pb);
            // Joined bodies do not collide with each other (a chain's links overlap at their
            // hinges); a rope's ends still do.
            let joint: GenericJoint = match kind.as_str() {
                "revolute" => {
                    let mut j = RevoluteJointBuilder::new().local_anchor1(la).local_anchor2(lb).contacts_enabled(false);
                    if let Some(l) = &limits {
                        j = j.limits([l[2 * k], l[2 * k + 1]]);
                    }
                    j.build().into()
                }
                "fixed" => {
                    let rel = self.d.r.bodies[ha].position().inverse() * *self.d.r.bodies[hb].position();
                    FixedJointBuilder::new()
                        .local_frame1(rel)
                        .local_frame2(Pose::IDENTITY)
                        .contacts_enabled(false)
                        .build()
                        .into()
                }
                "prismatic" => {
                    let ax = Vector::new(axis[2 * k], axis[2 * k + 1]).normalize();
                    let lax = self.d.r.bodies[ha].rotation().inverse_transform_vector(ax);
                    let mut j =
                        PrismaticJointBuilder::new(lax).local_anchor1(la).local_anchor2(lb).contacts_enabled(false);
                    if let Some(l) = &limits {
                        j = j.limits([l[2 * k], l[2 * k + 1]]);
                    }
                    j.build().into()
                }
                _ => {
                    let len = length.as_ref().map(|l| l[k]).unwrap_or((pa - pb).length());
                    RopeJointBuilder::new(len).local_anchor1(la).local_anchor2(lb).build().into()
                }
            };
            self.d.r.impulse_joints.insert(ha, hb, joint, true);
        }
        self.part_added();
        Ok(())
    }

    fn part_added(&mut self) {
        self.d.parts += 1;
        if self.pending.as_ref().is_some_and(|p| p.parts == self.d.parts) {
            self.d = self.pending.take().expect("checked");
        }
    }

    /// Kinetic energy and the potential of gravity of the dynamic bodies (J).
    fn mechanical(&self) -> (Real, Real) {
        let (mut k, mut u) = (0.0, 0.0);
        for &h in &self.handles {
            let b = &self.d.r.bodies[h];
            if b.is_dynamic() {
                k += b.kinetic_energy();
                u -= b.mass() * self.gravity.dot(b.center_of_mass());
            }
        }
        (k, u)
    }

    fn body(&self, i: usize) -> &RigidBody {
        &self.d.r.bodies[self.handles[i]]
    }

    /// The first body whose pose or velocity is not finite.
    fn fault(&self) -> Option<(usize, Failure)> {
        (0..self.handles.len()).find_map(|i| {
            let b = self.body(i);
            if !(b.translation().is_finite() && b.rotation().angle().is_finite()) {
                Some((i, Failure::Position))
            } else if !(b.linvel().is_finite() && b.angvel().is_finite()) {
                Some((i, Failure::Velocity))
            } else {
                None
            }
        })
    }
}

fn p_len(p: &Params) -> Result<usize> {
    let k = p.count("n_vertices", 1 << 16)?;
    Ok(2 * k)
}

const FIELDS: [&str; 8] = ["x", "y", "angle", "vx", "vy", "omega", "mass", "inertia"];

impl System for Bodies2 {
    fn name(&self) -> &str {
        &self.name
    }
    fn is_empty(&self) -> bool {
        self.handles.is_empty()
    }
    fn size(&self) -> usize {
        self.handles.len()
    }
    fn set_gravity(&mut self, g: [Real; 3]) {
        self.gravity = Vector::new(g[0], g[1]);
    }
    fn as_bodies(&mut self) -> Option<&mut Bodies2> {
        Some(self)
    }
    fn step(&mut self, dt: Real, _stop: &AtomicBool) -> std::result::Result<(), Halt> {
        let (k0, u0) = self.mechanical();
        self.params.dt = dt;
        let r = &mut self.d.r;
        self.pipeline.step(
            self.gravity,
            &self.params,
            &mut r.islands,
            &mut r.broad_phase,
            &mut r.narrow_phase,
            &mut r.bodies,
            &mut r.colliders,
            &mut r.impulse_joints,
            &mut r.multibody_joints,
            &mut r.soft_bodies,
            &mut self.ccd,
            &(),
            &(),
        );
        if let Some((index, quantity)) = self.fault() {
            return Err(Halt::Diverged { index, quantity });
        }
        let (k1, u1) = self.mechanical();
        self.d.contacts += (k0 + u0) - (k1 + u1);
        Ok(())
    }
    fn auto_dt(&self) -> Option<Real> {
        None
    }
    fn suggest_dt(&self) -> Option<Real> {
        Some(1.0 / 240.0)
    }
    fn energy(&self) -> EnergyReport {
        let (k, u) = self.mechanical();
        EnergyReport {
            kinetic: k,
            potential: vec![("bodies: gravity".to_string(), u)],
            dissipated: vec![
                ("bodies: contacts and joints".to_string(), self.d.contacts),
                ("bodies ⇄ particles".to_string(), self.d.coupling),
            ],
        }
    }
    fn set_field(&mut self, name: &str, values: &[Real]) -> Result<()> {
        let n = self.handles.len();
        if !FIELDS[..6].contains(&name) {
            return Err(invalid(
                "field",
                format!("{name:?} cannot be set on the bodies (settable: x, y, angle, vx, vy, omega)"),
            ));
        }
        if values.len() != n {
            return Err(invalid(name, format!("has {} values, expected {n}", values.len())));
        }
        finite_all(name, values)?;
        for (i, &val) in values.iter().enumerate() {
            let b = &mut self.d.r.bodies[self.handles[i]];
            let (t, v) = (b.translation(), b.linvel());
            match name {
                "x" => b.set_translation(Vector::new(val, t.y), true),
                "y" => b.set_translation(Vector::new(t.x, val), true),
                "angle" => b.set_rotation(Rotation::new(val), true),
                "vx" => b.set_linvel(Vector::new(val, v.y), true),
                "vy" => b.set_linvel(Vector::new(v.x, val), true),
                _ => b.set_angvel(val, true),
            }
        }
        Ok(())
    }
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        names
            .iter()
            .map(|&name| {
                if !FIELDS.contains(&name) {
                    return Err(invalid(
                        "field",
                        format!("the bodies have no field {name:?} (valid: {})", FIELDS.join(", ")),
                    ));
                }
                Ok((0..self.handles.len())
                    .map(|i| {
                        let b = self.body(i);
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
                    })
                    .collect())
            })
            .collect()
    }
    fn snapshot(&self) -> Result<Snapshot> {
        Ok(Box::new(self.d.clone()))
    }
    fn save(&self) -> Arrays {
        let bytes = bincode::serialize(&self.d).expect("rapier's state serialises");
        vec![("state".to_string(), pack(&bytes)), ("bytes".to_string(), vec![bytes.len() as Real])]
    }
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let len = array(arrays, "bytes", Some(1))?[0];
        let packed = array(arrays, "state", None)?;
        let bytes = unpack(packed, len).ok_or_else(|| invalid("state", "is not a packed bodies state"))?;
        let d: Dynamic = bincode::deserialize(&bytes).map_err(|e| invalid("state", format!("cannot be read: {e}")))?;
        let check = |d: &Dynamic| -> Result<()> {
            let ok = d.r.colliders.len() == self.colliders.len()
                && self.handles.iter().all(|&h| d.r.bodies.contains(h))
                && self.colliders.iter().all(|&h| d.r.colliders.contains(h));
            if ok {
                Ok(())
            } else {
                Err(invalid("state", "holds other bodies than the scene's"))
            }
        };
        if d.parts < self.d.parts {
            return Err(invalid("state", format!("holds {} parts, the scene has {}", d.parts, self.d.parts)));
        }
        if d.parts == self.d.parts {
            check(&d)?;
            let old = std::mem::replace(&mut self.d, d);
            if let Some((i, q)) = self.fault() {
                self.d = old;
                return Err(invalid("state", format!("body {i}'s {q:?} is not finite")));
            }
        } else {
            self.pending = Some(d);
        }
        Ok(())
    }
    fn restore(&mut self, snapshot: Snapshot) {
        self.d = *snapshot.downcast::<Dynamic>().expect("a snapshot of the bodies");
        // rapier's pipeline and CCD solver keep working buffers from the steps undone; fresh ones
        // step on exactly as after a load (where they are fresh too, and a restart continues bit
        // for bit), so a rolled-back run matches one never interrupted.
        self.pipeline = PhysicsPipeline::new();
        self.ccd = CCDSolver::new();
    }
}

/// Bytes packed 6 to a real (each an integer below 2⁴⁸, exact and finite), so that rapier's
/// serialised state travels in the scene file's arrays of reals.
fn pack(bytes: &[u8]) -> Vec<Real> {
    bytes
        .chunks(6)
        .map(|c| {
            let mut w = [0u8; 8];
            w[..c.len()].copy_from_slice(c);
            u64::from_le_bytes(w) as Real
        })
        .collect()
}

fn unpack(packed: &[Real], len: Real) -> Option<Vec<u8>> {
    if !(len >= 0.0 && len.fract() == 0.0 && len as usize <= packed.len() * 6 && len as usize + 6 > packed.len() * 6) {
        return None;
    }
    let mut out = Vec::with_capacity(packed.len() * 6);
    for &w in packed {
        if !(0.0..281_474_976_710_656.0).contains(&w) || w.fract() != 0.0 {
            return None;
        }
        out.extend_from_slice(&(w as u64).to_le_bytes()[..6]);
    }
    out.truncate(len as usize);
    Some(out)
}

/// Particles against the bodies, both ways: a particle (its `radius` attribute, else a point)
/// inside or touching a body's shape is put back on its surface, and the impulse that stops
/// its approach (the body's restitution, Coulomb friction with the body's coefficient) is applied to both,
/// equal and opposite, at the contact point: grains push bodies, a body pushes grains, cloth
/// drapes over a body, fluid particles hold a body up. Particles are visited in order (the
/// bodies' velocities change as they go): deterministic. The energy this removes (kinetic, and
/// the particles' potential in gravity raised by the moves) is booked in the bodies' "bodies ⇄
/// particles".
pub struct BodyContacts {
    system: usize,
}

impl BodyContacts {
    /// The coupling of the particles with the bodies system `others[system]` of the world.
    pub fn new(system: usize) -> Self {
        Self { system }
    }
}

impl<V: PVector> Coupling<V> for BodyContacts {
    fn name(&self) -> &str {
        "bodies ⇄ particles"
    }
    fn apply(
        &mut self,
        particles: &mut super::particles::ParticleSystem<V>,
        others: &mut [Box<dyn System>],
        _dt: Real,
    ) {
        if V::DIM != 2 {
            return;
        }
        let Some(bodies) = others.get_mut(self.system).and_then(|s| s.as_bodies()) else {
            return;
        };
        let (state, model) = particles.state_model_mut();
        let n = state.x.len();
        if n == 0 || bodies.handles.is_empty() {
            return;
        }
        let radius = model.attribute("radius");
        let r_max = radius.map(|r| r.iter().cloned().fold(0.0, Real::max)).unwrap_or(0.0);
        // Each body's box, grown by the largest radius: the broad test.
        let boxes: Vec<_> =
            bodies.colliders.iter().map(|&c| bodies.d.r.colliders[c].compute_aabb().loosened(r_max)).collect();
        let e_before = particle_kinetic(&state.v, &model.mass, &model.inv_mass) + bodies.mechanical().0;
        let gravity = bodies.gravity;
        let mut lifted = 0.0;
        for i in 0..n {
            let im = model.inv_mass[i];
            if im == 0.0 {
                continue;
            }
            let ri = radius.map(|r| r[i]).unwrap_or(0.0);
            let p = Vector::new(state.x[i].comp(0), state.x[i].comp(1));
            for (k, bb) in boxes.iter().enumerate() {
                if !bb.contains_local_point(p) {
                    continue;
                }
                let col = &bodies.d.r.colliders[bodies.colliders[k]];
                let proj = col.shape().project_point(col.position(), p, false);
                let (e, mu) = (col.restitution(), col.friction());
                let d = p - proj.point;
                let dist = d.length();
                let (normal, depth) = if proj.is_inside {
                    if dist == 0.0 {
                        continue;
                    }
                    (-d / dist, ri + dist)
                } else {
                    if dist >= ri || dist == 0.0 {
                        continue;
                    }
                    (d / dist, ri - dist)
                };
                let h = bodies.handles[k];
                let body = &mut bodies.d.r.bodies[h];
                let c = proj.point;
                let vi = Vector::new(state.v[i].comp(0), state.v[i].comp(1));
                let vb = body.velocity_at_point(c);
                let vn = (vi - vb).dot(normal);
                // The particle goes back to the surface (plus its radius) along the normal; the
                // work gravity does against that move, −m g·Δx, is booked with the exchange.
                let pn = p + normal * depth;
                state.x[i] = V::from_slice(&[pn.x, pn.y, 0.0]);
                lifted -= model.mass[i] * gravity.dot(normal * depth);
                if vn >= 0.0 {
                    continue;
                }
                // Effective mass of the pair along the normal: 1/(1/m_i + 1/m_b + (r×n)²/I_b).
                let dynamic = body.is_dynamic();
                let (ib_m, ib_i, rc) = if dynamic {
                    let mp = body.mass_properties();
                    let com = body.center_of_mass();
                    (mp.effective_inv_mass.x, mp.effective_world_inv_inertia, c - com)
                } else {
                    (0.0, 0.0, Vector::ZERO)
                };
                let rn = rc.perp_dot(normal);
                let k_n = im + ib_m + rn * rn * ib_i;
                let jn = -(1.0 + e) * vn / k_n;
                let vt_vec = (vi - vb) - normal * vn;
                let vt = vt_vec.length();
                let mut impulse = normal * jn;
                if vt > 0.0 && mu > 0.0 {
                    let t = vt_vec / vt;
                    let rt = rc.perp_dot(t);
                    let k_t = im + ib_m + rt * rt * ib_i;
                    impulse -= t * (mu * jn).min(vt / k_t);
                }
                let nv = vi + impulse * im;
                state.v[i] = V::from_slice(&[nv.x, nv.y, 0.0]);
                if dynamic {
                    body.apply_impulse_at_point(-impulse, c, true);
                }
            }
        }
        let e_after = particle_kinetic(&state.v, &model.mass, &model.inv_mass) + bodies.mechanical().0;
        bodies.d.coupling += e_before - e_after - lifted;
    }
}

fn particle_kinetic<V: PVector>(v: &[V], mass: &[Real], inv_mass: &[Real]) -> Real {
    let mut k = 0.0;
    for i in 0..v.len() {
        if inv_mass[i] != 0.0 {
            k += 0.5 * mass[i] * v[i].length_squared();
        }
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terms::registry::Value;

    fn group(shape: &str, x: &[Real], size: &[Real]) -> Params {
        let n = x.len() / 2;
        Params::new()
            .with("shape", Value::Text(shape.into()))
            .with("kind", Value::Text("dynamic".into()))
            .with("n", Value::Number(n as Real))
            .with("positions", Value::Floats(x.to_vec()))
            .with("angles", Value::Floats(vec![0.0; n]))
            .with("velocities", Value::Floats(vec![0.0; 2 * n]))
            .with("angular_velocities", Value::Floats(vec![0.0; n]))
            .with("size", Value::Floats(size.to_vec()))
            .with("density", Value::Number(1000.0))
            .with("friction", Value::Number(0.5))
            .with("restitution", Value::Number(0.1))
    }

    #[test]
    fn bytes_pack_into_reals_and_back() {
        let bytes: Vec<u8> = (0..=255u8).chain(0..7).collect();
        let packed = pack(&bytes);
        assert!(packed.iter().all(|w| w.is_finite() && w.fract() == 0.0));
        assert_eq!(unpack(&packed, bytes.len() as Real).unwrap(), bytes);
        assert!(unpack(&packed, (bytes.len() + 100) as Real).is_none());
        assert!(unpack(&[0.5], 1.0).is_none());
    }

    #[test]
    fn a_ball_falls_freely_and_a_restore_returns_bit_for_bit() {
        let mut b = Bodies2::new("bodies");
        b.add_group(group("ball", &[0.0, 10.0], &[0.1])).unwrap();
        b.set_gravity([0.0, -9.81, 0.0]);
        let stop = AtomicBool::new(false);
        let snap = b.snapshot().unwrap();
        let dt = 1e-3;
        for _ in 0..1000 {
            b.step(dt, &stop).unwrap();
        }
        let y = b.fields(&["y"]).unwrap()[0][0];
        // Free fall, y0 − g t²/2 at t = 1 s, to the first order in dt of rapier's integrator.
        assert!((y - (10.0 - 9.81 / 2.0)).abs() < 9.81 * dt, "{y}");
        // The books balance: kinetic + potential + residual as at the start.
        let e = b.energy();
        assert!((e.total() - 1000.0 * std::f64::consts::PI * 0.01 * 9.81 * 10.0).abs() < 1e-6, "{e:?}");
        b.restore(snap);
        assert_eq!(b.fields(&["y"]).unwrap()[0][0], 10.0);
    }

    #[test]
    fn bad_groups_are_refused_by_name() {
        let mut b = Bodies2::new("bodies");
        let e = b.add_group(group("blob", &[0.0, 0.0], &[0.1])).unwrap_err();
        assert!(e.to_string().contains("shape"), "{e}");
        let e = b.add_group(group("ball", &[0.0, 0.0], &[-1.0])).unwrap_err();
        assert!(e.to_string().contains("size"), "{e}");
        assert!(b.is_empty());
    }
}
