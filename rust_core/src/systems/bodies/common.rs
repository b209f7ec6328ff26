// The rigid-body system written once for both dimensions: `include!`d by `dim2.rs` (rapier2d-f64)
// and `dim3.rs` (rapier3d-f64), each of which first brings its rapier into scope and defines the
// few things that differ (vectors from slices, rotations, shapes, fields, the angular term of an
// effective mass). rapier's 2D and 3D crates are separate crates with separate types, so a
// generic would need a trait over all of rapier; the two inclusions are what parry and rapier
// themselves do (one source, built per dimension). Formatted with `rustfmt` on this file.

/// Everything rapier keeps between steps: what a snapshot copies and a save writes (through
/// `io`, the crate physcore-bodies-io, in this order).
#[derive(Clone)]
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

impl Rapier {
    fn empty() -> Self {
        Rapier {
            islands: IslandManager::new(),
            broad_phase: BroadPhaseBvh::new(),
            narrow_phase: NarrowPhase::new(),
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints: MultibodyJointSet::new(),
            soft_bodies: SoftBodySet::new(),
        }
    }
}

/// What rapier's step reads and changes, apart from the bodies' other fields, so that it can run
/// on a thread of its own (`Bodies::rapier_step`).
struct Stepper {
    r: Rapier,
    pipeline: PhysicsPipeline,
    ccd: CCDSolver,
    impacts: Impacts,
}

fn rapier_step_on(
    r: &mut Rapier,
    pipeline: &mut PhysicsPipeline,
    ccd: &mut CCDSolver,
    impacts: &Impacts,
    gravity: Vector,
    params: &IntegrationParameters,
) {
    pipeline.step(
        gravity,
        params,
        &mut r.islands,
        &mut r.broad_phase,
        &mut r.narrow_phase,
        &mut r.bodies,
        &mut r.colliders,
        &mut r.impulse_joints,
        &mut r.multibody_joints,
        &mut r.soft_bodies,
        ccd,
        impacts,
        &(),
    );
}

/// Gives body `h` what its collider `c`'s shape lacks in parry's mass properties
/// (`added_mass`), as its additional mass properties, and its own recomputed from them. Only a
/// body whose additional ones differ is taken mutably: rapier lists every body so taken as
/// modified, and the list is saved (a loaded state taken again stays bit for bit).
fn exact_mass(r: &mut Rapier, h: RigidBodyHandle, c: ColliderHandle) {
    let Some(add) = r.colliders.get(c).and_then(added_mass) else {
        return;
    };
    let added = Some(Box::new(RigidBodyAdditionalMassProps::MassProps(add)));
    if r.bodies.get(h).is_some_and(|b| b.mass_properties().additional_local_mprops != added) {
        let body = &mut r.bodies[h];
        body.set_additional_mass_properties(add, false);
        body.recompute_mass_properties_from_colliders(&r.colliders);
    }
}

/// A rapier step that took this long runs the next on a watched thread (`Bodies::rapier_step`):
/// starting the thread costs about 30 µs, under 0.3 % of such a step.
const WATCHED_STEP: std::time::Duration = std::time::Duration::from_millis(10);

/// What `step` changes: rapier's state and the books (saved through `io`, in this order).
#[derive(Clone)]
struct Dynamic {
    r: Rapier,
    /// Energy the contacts and joints took out (J; the residual of each step, see the module).
    contacts: Real,
    /// Energy the particle coupling took out of bodies and particles together (J).
    coupling: Real,
    /// Parts (groups and joint sets) added when this was saved: a load waits for as many.
    parts: usize,
    /// Particles pinned to bodies: (particle, body, the point in the body's frame).
    pins: Vec<(usize, usize, Vector)>,
}

impl Dynamic {
    /// The fields lent to `io` for a save.
    fn saving(&self) -> io::Saving<'_> {
        let r = &self.r;
        io::Saving {
            islands: &r.islands,
            broad_phase: &r.broad_phase,
            narrow_phase: &r.narrow_phase,
            bodies: &r.bodies,
            colliders: &r.colliders,
            impulse_joints: &r.impulse_joints,
            multibody_joints: &r.multibody_joints,
            soft_bodies: &r.soft_bodies,
            contacts: self.contacts,
            coupling: self.coupling,
            parts: self.parts,
            pins: &self.pins,
        }
    }

    /// The state `io` read.
    fn loaded(l: io::Loaded) -> Self {
        Dynamic {
            r: Rapier {
                islands: l.islands,
                broad_phase: l.broad_phase,
                narrow_phase: l.narrow_phase,
                bodies: l.bodies,
                colliders: l.colliders,
                impulse_joints: l.impulse_joints,
                multibody_joints: l.multibody_joints,
                soft_bodies: l.soft_bodies,
            },
            contacts: l.contacts,
            coupling: l.coupling,
            parts: l.parts,
            pins: l.pins,
        }
    }
}

/// The memory that adding `n` bodies to a system that then holds `total` needs (`group_bytes`),
/// checked to be there now (`Error::OutOfMemory` otherwise).
fn group_need(total: usize, n: usize) -> Result<Need> {
    let bytes = group_bytes(total, n);
    let need = Need::new("add_bodies", bytes, format!("{} rigid bodies in rapier's sets", count(n as u128)));
    need.room(bytes)?;
    Ok(need)
}

impl Group {
    /// Checks that the group fits in memory beside `existing` bodies, before any system is made
    /// for it (`Bodies::insert_group` checks again, and reserves).
    pub fn room(&self, existing: usize) -> Result<()> {
        group_need(existing + self.n, self.n).map(drop)
    }
}

/// A group of bodies checked and its shape built (`Bodies::build_group`).
pub struct Group {
    n: usize,
    shape: String,
    kind: String,
    x: Vec<Real>,
    rot: Vec<Rotation>,
    v: Vec<Real>,
    omega: Vec<Real>,
    size: Vec<Real>,
    density: Real,
    friction: Real,
    restitution: Real,
    rolling: Real,
    /// The one shape of a group given by its vertices.
    listed: Option<ColliderBuilder>,
}

/// The rigid bodies of a world.
pub struct Bodies {
    name: String,
    d: Dynamic,
    gravity: Vector,
    params: IntegrationParameters,
    pipeline: PhysicsPipeline,
    ccd: CCDSolver,
    /// The impacts of the step, found as rapier meets its contacts (see `Impacts`).
    impacts: Impacts,
    /// Each body's handle and its one collider, by body number.
    handles: Vec<RigidBodyHandle>,
    colliders: Vec<ColliderHandle>,
    /// The fixed body, without a collider, that joins to "the world" use.
    anchor: Option<RigidBodyHandle>,
    /// Each collider's coefficient of rolling friction μ_r (dimensionless), by the index of its
    /// handle (its group's `rolling_friction`; given again when a saved scene adds its groups).
    rolling: Vec<Real>,
    /// A saved state waiting for the parts it holds to be added again (scene file reader).
    pending: Option<Dynamic>,
    /// How long the last rapier step took (`None` before the first after a change of bodies or
    /// a rollback): it picks where the next runs (`rapier_step`), never what it computes.
    last_step: Option<std::time::Duration>,
    /// Bodies were moved by hand (`set_field`) since rapier's last step: the next step's
    /// memory is counted from their boxes, as after a change of bodies (`step_bytes`).
    moved: bool,
}

impl Bodies {
    pub fn new(name: &str) -> Self {
        // No speed cap: rapier holds bodies under 400 length units a second by default (and, per
        // body, under 45° a step: `allow_fast_rotation` below) to keep its CCD reliable; a cap
        // is a silent clamp that falsifies the motion and the books (a 300 rad/s flywheel ran
        // at 188.5 rad/s after one step, the loss booked as contact dissipation).
        let params = IntegrationParameters { normalized_max_linear_velocity: Real::MAX, ..Default::default() };
        let mut b = Self {
            name: name.to_string(),
            d: Dynamic {
                r: Rapier::empty(),
                contacts: 0.0,
                coupling: 0.0,
                parts: 0,
                pins: Vec::new(),
            },
            gravity: Vector::ZERO,
            params,
            pipeline: PhysicsPipeline::new(),
            ccd: CCDSolver::new(),
            impacts: Impacts::default(),
            handles: Vec::new(),
            colliders: Vec::new(),
            anchor: None,
            rolling: Vec::new(),
            pending: None,
            last_step: None,
            moved: false,
        };
        b.scale_time();
        b
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
    pub fn add_group(&mut self, p: Params) -> Result<usize> {
        self.insert_group(Self::build_group(p, &AtomicBool::new(false))?)
    }

    /// A group checked whole and its shape built, in no system yet (`insert_group`): the long
    /// part of an add (parry's convex hull of 200,000 vertices takes seconds) changes nothing,
    /// so Ctrl-C (`stop`) can stop it, answered within 10 ms (`super::off_thread`).
    pub fn build_group(mut p: Params, stop: &AtomicBool) -> Result<Group> {
        let shape = p.text("shape")?.to_string();
        if !SHAPES.contains(&shape.as_str()) {
            return Err(invalid("shape", format!("unknown shape {shape:?}; valid: {}", SHAPES.join(", "))));
        }
        let kind = p.text("kind")?.to_string();
        if !["dynamic", "fixed", "kinematic"].contains(&kind.as_str()) {
            return Err(invalid("kind", format!("unknown body kind {kind:?}; valid: dynamic, fixed, kinematic")));
        }
        let n = p.count("n", 1 << 24)?;
        if n == 0 {
            return Err(invalid("n", "a group needs at least one body"));
        }
        let x = take_len(&mut p, "positions", D * n)?;
        let rotations = take_len(&mut p, ROTATION_KEY, ROT * n)?;
        let mut rot = Vec::new();
        Need::new("add_bodies", Need::bytes_of::<Rotation>(n), format!("{} rotations", count(n as u128)))
            .reserve(&mut rot, n)?;
        for r in rotations.chunks_exact(ROT) {
            rot.push(rotation(r)?);
        }
        let v = take_len(&mut p, "velocities", D * n)?;
        let omega = take_len(&mut p, "angular_velocities", ANG * n)?;
        let per = size_len(&shape);
        let size = take_len(&mut p, "size", per * n)?;
        if size.iter().any(|&s| s <= 0.0) {
            return Err(invalid("size", "every size must be > 0"));
        }
        let density = p.number("density")?;
        let friction = p.number("friction")?;
        let restitution = p.number("restitution")?;
        if density <= 0.0 {
            return Err(invalid("density", format!("must be > 0 (kg/m^{D}), got {density}")));
        }
        if friction < 0.0 {
            return Err(invalid("friction", format!("must be >= 0, got {friction}")));
        }
        if !(0.0..=1.0).contains(&restitution) {
            return Err(invalid("restitution", format!("must be in [0, 1], got {restitution}")));
        }
        // Absent (files and callers from before it): no rolling resistance.
        let rolling = if p.has("rolling_friction") { p.number("rolling_friction")? } else { 0.0 };
        if rolling < 0.0 {
            return Err(invalid("rolling_friction", format!("must be >= 0 (dimensionless), got {rolling}")));
        }
        // The group's one shape given by vertices (a convex polygon or hull, a triangle mesh).
        let listed = if p.has("vertices") {
            let (shape, kind) = (shape.clone(), kind.clone());
            super::off_thread(stop, move || listed_shape(&shape, &kind, &mut p))??
        } else {
            listed_shape(&shape, &kind, &mut p)?
        };
        let g = Group { n, shape, kind, x, rot, v, omega, size, density, friction, restitution, rolling, listed };
        Ok(g)
    }

    /// Puts a group `build_group` made into rapier; returns the number of its first body.
    pub fn insert_group(&mut self, g: Group) -> Result<usize> {
        let Group { n, shape, kind, x, rot, v, omega, size, density, friction, restitution, rolling, listed } = g;
        let per = size_len(&shape);
        let builder = |i: usize| -> RigidBodyBuilder {
            let b = match kind.as_str() {
                "fixed" => RigidBodyBuilder::fixed(),
                "kinematic" => RigidBodyBuilder::kinematic_velocity_based(),
                _ => RigidBodyBuilder::dynamic(),
            };
            own_gyroscopic(b)
                .pose(Pose::from_parts(vector(&x[D * i..D * (i + 1)]), rot[i]))
                .linvel(vector(&v[D * i..D * (i + 1)]))
                .angvel(ang_vector(&omega[ANG * i..ANG * (i + 1)]))
                // Sleeping freezes a body bit for bit at rest: deterministic, and a pile at rest
                // costs nothing, but a body asleep is not woken by particles (see BodyContacts).
                .can_sleep(false)
                .allow_fast_rotation(true)
        };
        let first = self.handles.len();
        self.room_for(n)?;
        for i in 0..n {
            let c = match &listed {
                Some(c) => c.clone(),
                None => sized_shape(&shape, &size[per * i..per * (i + 1)]),
            };
            // A contact bounces with the larger of its two bodies' e (rapier's default is their
            // mean, which bounced a ball of e = 0.9 off the default ground, e = 0.1, at 0.5).
            let c = c
                .density(density)
                .friction(friction)
                .restitution(restitution)
                .restitution_combine_rule(CoefficientCombineRule::Max);
            let h = self.d.r.bodies.insert(builder(i));
            let ch = self.d.r.colliders.insert_with_parent(c, h, &mut self.d.r.bodies);
            exact_mass(&mut self.d.r, h, ch);
            self.handles.push(h);
            self.colliders.push(ch);
            let at = ch.into_raw_parts().0 as usize;
            if self.rolling.len() <= at {
                self.rolling.resize(at + 1, 0.0);
            }
            self.rolling[at] = rolling;
        }
        self.part_added()?;
        Ok(first)
    }

    /// Adds `m` joints of one kind between bodies `a[k]` and `b[k]` (body numbers; −1: the
    /// world), at world points `anchor` (`anchor_b` for the second body of a rope; `axis` for a
    /// prismatic joint, and in 3D for a revolute one; `limits` in rad or m; `length`: a rope's
    /// longest length, m).
    pub fn add_joints(&mut self, mut p: Params) -> Result<()> {
        let kind = p.text("kind")?.to_string();
        if !JOINTS.contains(&kind.as_str()) {
            return Err(invalid("kind", format!("unknown joint {kind:?}; valid: {}", JOINTS.join(", "))));
        }
        let m = p.count("m", 1 << 24)?;
        let a = take_len(&mut p, "a", m)?;
        let b = take_len(&mut p, "b", m)?;
        let anchor = take_len(&mut p, "anchor", D * m)?;
        let anchor_b = if p.has("anchor_b") { take_len(&mut p, "anchor_b", D * m)? } else { anchor.clone() };
        let axis = if p.has("axis") { take_len(&mut p, "axis", D * m)? } else { DEFAULT_AXIS.repeat(m) };
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
        if let Some(k) = (0..m).find(|&k| vector(&axis[D * k..D * (k + 1)]).length() == 0.0) {
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
            let pa = vector(&anchor[D * k..D * (k + 1)]);
            let pb = vector(&anchor_b[D * k..D * (k + 1)]);
            let (posa, posb) = (*self.d.r.bodies[ha].position(), *self.d.r.bodies[hb].position());
            let la = posa.inverse_transform_point(pa);
            let lb = posb.inverse_transform_point(pb);
            // The axis in each body's frame (the two may be turned differently now).
            let ax = vector(&axis[D * k..D * (k + 1)]).normalize();
            let (axa, axb) = (posa.rotation.inverse() * ax, posb.rotation.inverse() * ax);
            let range = limits.as_ref().map(|l| [l[2 * k], l[2 * k + 1]]);
            // Joined bodies do not collide with each other (a chain's links overlap at their
            // hinges); a rope's ends still do.
            let joint: GenericJoint = match kind.as_str() {
                "revolute" => {
                    let mut j = revolute(axa, axb).local_anchor1(la).local_anchor2(lb).contacts_enabled(false);
                    if let Some(r) = range {
                        j = j.limits(r);
                    }
                    j.build().into()
                }
                "fixed" => FixedJointBuilder::new()
                    .local_frame1(posa.inverse() * posb)
                    .local_frame2(Pose::IDENTITY)
                    .contacts_enabled(false)
                    .build()
                    .into(),
                "prismatic" => {
                    let mut j =
                        PrismaticJointBuilder::new(axa).local_anchor1(la).local_anchor2(lb).contacts_enabled(false);
                    if let Some(r) = range {
                        j = j.limits(r);
                    }
                    let mut g: GenericJoint = j.build().into();
                    g.set_local_axis2(axb);
                    g
                }
                "spherical" => spherical(la, lb),
                _ => {
                    let len = length.as_ref().map(|l| l[k]).unwrap_or((pa - pb).length());
                    RopeJointBuilder::new(len).local_anchor1(la).local_anchor2(lb).build().into()
                }
            };
            self.d.r.impulse_joints.insert(ha, hb, joint, true);
            joined_gyroscopic(&mut self.d.r.bodies, ha);
            joined_gyroscopic(&mut self.d.r.bodies, hb);
        }
        self.part_added()?;
        Ok(())
    }

    /// Pins particle `particles[k]` to body `body[k]` at the world point `points[k]` (where the
    /// particle is now): from now on the particle moves with that point of the body, and what
    /// holds it there pushes the body back (see `BodyContacts`).
    pub fn add_pins(&mut self, mut p: Params) -> Result<()> {
        let m = p.count("m", 1 << 24)?;
        let particles = take_len(&mut p, "particles", m)?;
        let body = take_len(&mut p, "body", m)?;
        let points = take_len(&mut p, "points", D * m)?;
        if let Some(k) = particles.iter().position(|&i| i.fract() != 0.0 || i < 0.0) {
            return Err(invalid("particles", format!("entry {k} ({}) is not a particle index", particles[k])));
        }
        let n = self.handles.len() as Real;
        if let Some(k) = body.iter().position(|&i| i.fract() != 0.0 || i < 0.0 || i >= n) {
            return Err(invalid("body", format!("entry {k} ({}) is not a body of the scene (0..{n})", body[k])));
        }
        for k in 0..m {
            let h = self.handles[body[k] as usize];
            let local = self.d.r.bodies[h].position().inverse_transform_point(vector(&points[D * k..D * (k + 1)]));
            self.d.pins.push((particles[k] as usize, body[k] as usize, local));
        }
        self.part_added()?;
        Ok(())
    }

    /// Checks, before rapier is touched, that `n` more bodies fit in memory, and reserves this
    /// system's own lists for them: rapier's sets grow infallibly (a refused allocation aborted
    /// the process), so its need is estimated (`group_bytes`) and asked of the allocator first.
    fn room_for(&mut self, n: usize) -> Result<()> {
        let total = self.handles.len() + n;
        let need = group_need(total, n)?;
        need.reserve(&mut self.handles, total)?;
        need.reserve(&mut self.colliders, total)?;
        // A collider's handle index is at most the number of colliders (none is removed).
        need.reserve(&mut self.rolling, total + 1)
    }

    /// Counts a part added; a loaded state waiting for this part (`pending`) is checked against
    /// the bodies the parts built, and taken (a refusal drops it: the load fails).
    fn part_added(&mut self) -> Result<()> {
        self.d.parts += 1;
        self.last_step = None;
        if self.pending.as_ref().is_some_and(|p| p.parts == self.d.parts) {
            let d = self.pending.take().expect("checked");
            self.take_state(d)?;
        }
        self.params.length_unit = self.length_unit(&self.d.r);
        self.scale_time();
        Ok(())
    }

    /// Takes a loaded state for these bodies, after checking that it holds them: the same
    /// bodies and colliders, each collider of the same shape, density and material as the
    /// scene's records built (a state of another scene with as many bodies is refused), and
    /// every body finite.
    fn take_state(&mut self, mut d: Dynamic) -> Result<()> {
        let same = d.r.colliders.len() == self.colliders.len()
            && self.handles.iter().all(|&h| d.r.bodies.contains(h))
            && self.colliders.iter().all(|&h| {
                let (Some(a), Some(b)) = (d.r.colliders.get(h), self.d.r.colliders.get(h)) else {
                    return false;
                };
                a.parent() == b.parent()
                    && a.density().to_bits() == b.density().to_bits()
                    && a.friction().to_bits() == b.friction().to_bits()
                    && a.restitution().to_bits() == b.restitution().to_bits()
                    && io::shape_bytes(a.shared_shape()) == io::shape_bytes(b.shared_shape())
            });
        if !same {
            return Err(invalid("state", "holds other bodies than the scene's"));
        }
        // The exact mass properties whatever the file holds (states saved before 2D capsules
        // had them carry parry's); none of the bodies changes unless its own are amiss.
        for (&h, &c) in self.handles.iter().zip(&self.colliders) {
            exact_mass(&mut d.r, h, c);
        }
        // The trial steps with the tolerances the state's own steps will have (its length unit).
        let kept = self.params;
        self.params.length_unit = self.length_unit(&d.r);
        self.scale_time();
        if let Err(e) = self.trial_step(&d) {
            self.params = kept;
            return Err(e);
        }
        let old = std::mem::replace(&mut self.d, d);
        if let Some((i, q)) = self.fault() {
            self.d = old;
            return Err(invalid("state", format!("body {i}'s {q:?} is not finite")));
        }
        // The scene's rules whatever the file holds (states saved before contacts took the
        // larger e carry rapier's mean). Only where they differ: `get_mut` marks a collider
        // modified, which the next save would write.
        let rules = (CoefficientCombineRule::Average, CoefficientCombineRule::Max);
        for &c in &self.colliders {
            let held = self.d.r.colliders.get(c).map(|c| (c.friction_combine_rule(), c.restitution_combine_rule()));
            if held.is_some_and(|h| h != rules) {
                let col = &mut self.d.r.colliders[c];
                col.set_friction_combine_rule(rules.0);
                col.set_restitution_combine_rule(rules.1);
            }
        }
        Ok(())
    }

    /// Steps a copy of a loaded state, on a fresh pipeline, and refuses the state if rapier
    /// fails on it. The digest (`super::seal`) refuses damage, but a file crafted to pass it
    /// (its digest recomputed) can hold indices and links that rapier's step trips over. Of the
    /// 44,728 single-bit flips of a small scene's state, each sealed again, about 100 killed the
    /// process in a step (aborts: 8.8 TB asked for by the island manager, 4 GB by a broad-phase
    /// traversal run in a circle; crashes: a tree refit recursing until the stack overflowed;
    /// steps that never ended), some only at the third or the nineteenth step, and others
    /// panicked. No Rust code survives an abort or a stack overflow, so on Unix the copy is
    /// stepped in a child process (`super::apart`), its memory held to twice what a step is
    /// estimated to need plus 256 MiB: a state it dies or panics on, or that does not end in its
    /// time, is refused, this process untouched. It takes 2 steps, then more while they last
    /// under `TRIAL_TIME`, up to 64 (64 of a small scene, about 10 of 3,000 balls, 2 of 1,000
    /// balls in one place): a state crafted to fail later than that still fails in the user's
    /// step. Elsewhere (or where no process can be made) the copy is stepped here, where a
    /// panic is refused alike and an abort still ends the process. The step's memory is asked
    /// of the allocator first (as a checkpoint's).
    fn trial_step(&self, d: &Dynamic) -> Result<()> {
        const TRIAL_STEPS: [usize; 2] = [2, 64];
        const TRIAL_TIME: std::time::Duration = std::time::Duration::from_millis(25);
        let copy = state_bytes(&d.r);
        let bytes = copy + step_bytes(&d.r, copy, Some(self.params.prediction_distance()));
        let of = format!("a trial step of the loaded state of {} rigid bodies", count(self.handles.len() as u128));
        // No machine holds 2⁴⁸ bytes (256 TiB): a state whose counts ask that (41 of the flips
        // above asked up to 18 EB) is not short of memory but not a scene's.
        if bytes >= 1 << 48 {
            return Err(invalid("state", format!("is inconsistent: its counts ask {} for a step", crate::error::human(u64::try_from(bytes).unwrap_or(u64::MAX)))));
        }
        Need::new("load", bytes, of).room(bytes)?;
        // The step is the scene's (`hint_dt`; rapier's 1/60 s without one: bit 4,656 above passed
        // 64 steps at 1/60 and tripped rapier at the first of the scene's 1 ms). The world's
        // gravity is given at each call, not known here: a body scene's usual one.
        let mut gravity = Vector::ZERO;
        gravity[D - 1] = -9.81;
        let params = self.params;
        let trial = |r: &mut Rapier| {
            let (mut pipeline, mut ccd, impacts) = (PhysicsPipeline::new(), CCDSolver::new(), Impacts::default());
            let start = std::time::Instant::now();
            for k in 0..TRIAL_STEPS[1] {
                if k >= TRIAL_STEPS[0] && start.elapsed() >= TRIAL_TIME {
                    break;
                }
                rapier_step_on(r, &mut pipeline, &mut ccd, &impacts, gravity, &params);
            }
        };
        let refused = |why: &str| invalid("state", format!("is inconsistent: rapier's step fails on it ({why})"));
        // rapier's messages (and backtraces) of a refused state are not the user's to read: the
        // panic hook is silenced for the trial (process-wide, so a panic on another thread in
        // these microseconds would go unprinted; it still unwinds as before).
        let hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        // Its time: 5 s, and a second for each 10 MB a step is estimated to need (two steps of
        // 1,000 balls in one place took 28 s and are asked 4.45 GB: 450 s), so that a state
        // that loops for ever is refused in seconds at a small scene.
        let wall = std::time::Duration::from_secs_f64(5.0 + bytes as f64 / 1e7) + TRIAL_TIME;
        let outcome = match super::apart(2 * bytes + (256 << 20), wall, || trial(&mut d.r.clone())) {
            super::Apart::Ended => Ok(()),
            super::Apart::Panicked => Err(refused("a panic")),
            super::Apart::Died(why) => Err(refused(&why)),
            super::Apart::Interrupted => Err(crate::error::Error::Interrupted { rolled_back_to: 0 }),
            super::Apart::Unavailable => {
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| trial(&mut d.r.clone()))).map_err(|e| {
                    let why = e
                        .downcast_ref::<&str>()
                        .map(|s| s.to_string())
                        .or_else(|| e.downcast_ref::<String>().cloned())
                        .unwrap_or_else(|| "a panic".into());
                    refused(&why)
                })
            }
        };
        std::panic::set_hook(hook);
        outcome
    }

    /// rapier's rates scaled with its length unit L: its defaults are tuned for bodies of about
    /// a metre (contacts a spring of 30 Hz, 60 Hz against fixed bodies, penetration pushed out
    /// at up to 3 L a second); here the second is √(L / 1 m) s, the time scale √(L/g) of bodies
    /// of size L under gravity, relative to a metre's, so that a scene scaled in size (its step
    /// scaled with √L) steps the same in its own units, and a metre-sized scene as rapier tunes it.
    fn scale_time(&mut self) {
        let second = self.params.length_unit.sqrt();
        let d = IntegrationParameters::default();
        let (p, [soft, fixed]) = (&mut self.params, [d.contact_softness, d.static_contact_softness]);
        p.contact_softness.natural_frequency = soft.natural_frequency / second;
        p.static_contact_softness.natural_frequency = fixed.natural_frequency / second;
        p.normalized_max_corrective_velocity = d.normalized_max_corrective_velocity / second;
    }

    /// The length rapier's tolerances are measured in (its `length_unit`, m): the diameter of
    /// the smallest dynamic body's bounding sphere (1 m if there is none). rapier's contact
    /// slop (0.005), prediction distance (0.02) and corrective speed (3 /s) are multiples of it,
    /// so a scene scaled in size keeps its dimensionless answers: at the default 1 m, a row of
    /// 1 cm dominoes toppled 17 % slower in units of √(g h) than the same row at 1 m, as the
    /// 5 mm slop is half a domino's thickness there. From the bodies alone, so a loaded scene
    /// (its groups added again) steps with the same unit.
    fn length_unit(&self, state: &Rapier) -> Real {
        let mut unit = Real::INFINITY;
        for (&h, &c) in self.handles.iter().zip(&self.colliders) {
            if state.bodies[h].is_dynamic() {
                let r = state.colliders[c].shape().compute_local_bounding_sphere().radius();
                if r > 0.0 && r.is_finite() {
                    unit = unit.min(2.0 * r);
                }
            }
        }
        if unit.is_finite() {
            unit
        } else {
            1.0
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
            if !(b.translation().is_finite() && rotation_finite(b.rotation())) {
                Some((i, Failure::Position))
            } else if !(b.linvel().is_finite() && b.angvel().is_finite()) {
                Some((i, Failure::Velocity))
            } else {
                None
            }
        })
    }
}

/// A bouncy contact point rapier met in the step: the contact `id` of the solver manifold
/// tagged `tag` of the pair (`c1`, `c2`), its restitution e, how much normal speed its bodies'
/// gravity gave it while it was held at the surface (`held`, m/s: the part of the step's
/// impulse that held them there) and, if it approached at the start of the step (an impact),
/// the energy its normal motion is to leave with (e² of what it came with, per unit effective
/// mass, J/kg).
struct Impact {
    c1: ColliderHandle,
    c2: ColliderHandle,
    tag: u32,
    id: usize,
    e: Real,
    accel: Real,
    held: Real,
    energy: Option<Real>,
}

/// rapier's contact hook (on the colliders `hook_fast` picks) that takes restitution out of its
/// step and notes each bouncy contact for `restitution`. rapier (0.36) bounces a contact once,
/// after its substeps, to e times the normal velocity from before the step; but the contact
/// holds the body at the surface for the rest of the step it arrives in, so a body falling
/// onto a floor lost what gravity gave it on the way there and bounced short by O(g dt / v)
/// (a ball of e = 0.8 rebounded with 0.95 e to 0.996 e at dt = 1/240; 12 elastic balls lost
/// 1–10 % of their energy in 10 s), and a box landing flat bounced spinning, its two contacts
/// taken one after the other.
#[derive(Default)]
struct Impacts {
    gravity: Vector,
    /// rapier's step and substep (s): its step is substeps of semi-implicit Euler.
    dt: Real,
    substep: Real,
    found: std::sync::Mutex<Vec<Impact>>,
    /// The bodies' orientations before the step, by handle index (`restitution`'s levers,
    /// `contact_points`); filled only where a collider is bouncy, its buffer kept between steps.
    before: Vec<Option<Rotation>>,
}

/// The normal motion's energy per unit effective mass that semi-implicit Euler of step `h` keeps
/// exactly in free flight, at gap `d` and parting speed `v` under the acceleration `a` towards
/// the surface: v²/2 + a d − a h v/2 (the discrete flight's invariant; v²/2 + a d as h → 0).
/// Read at the apex it is the height's energy, so matching it across a bounce keeps the apexes
/// at e² of each other at any step (with v²/2 + a d the step's own asymmetry took 2 a h / v of
/// the energy at each bounce).
fn flight_energy(v: Real, d: Real, a: Real, h: Real) -> Real {
    0.5 * v * v + a * d - 0.5 * a * h * v
}

/// How far ahead of a fast body rapier looks for contacts (its soft CCD), in the body's
/// reach (the radius of its bounding sphere): see `hook_fast`.
const PREDICTION_REACH: Real = 2.0;

/// Hooks the colliders whose bodies move faster than `fast` (a point of the body, its speed
/// plus its spin times its reach), for the step about to be taken, and unhooks the others. A
/// hooked pair loses rapier's reuse of its contacts from the last step (its contact
/// recycling): hooking every bouncy collider made a settling pile of 1,000 boxes (e = 0.1)
/// step 2.9 times slower. A contact between two slower bodies (a resting one) bounces as
/// rapier does, from the velocity before the step; its error is under e times their speed.
///
/// The same fast bodies look for contacts up to `PREDICTION_REACH` reaches along their path
/// (rapier's soft CCD: a contact found before the bodies touch, its gap closed within the step),
/// so a body meets a surface where it is, not a step deep in it. Without it a ball of 5 cm
/// falling 1 m at dt = 1/240 found the floor only up to 15.6 mm inside it, and its first apex
/// read 0.965–1.000 e² h₀ by where the impact fell within the step (1.000–1.068 at 1/60,
/// where rapier's own sweep against fixed colliders caught it); with it 0.999–1.000 at both,
/// no depth. Only the fast ones: predicting for every body made a settling pile of 1,000
/// (3,000) boxes step 22 % (32 %) slower. Returns whether any collider is bouncy.
fn hook_fast(r: &mut Rapier, handles: &[RigidBodyHandle], colliders: &[ColliderHandle], fast: Real) -> bool {
    // A contact takes the larger e of its two colliders, so a body of e = 0 bounces off a
    // bouncy one: where any collider has e > 0, every fast body is hooked.
    let bouncy = colliders.iter().any(|&c| r.colliders.get(c).is_some_and(|c| c.restitution() > 0.0));
    for (&h, &c) in handles.iter().zip(colliders) {
        let (Some(b), Some(col)) = (r.bodies.get(h), r.colliders.get(c)) else {
            continue;
        };
        let reach = col.shape().compute_local_bounding_sphere().radius();
        let quick = !b.is_fixed() && {
            let (v, w) = (b.linvel().length(), ang_norm(b.angvel()));
            v > fast || (w > 0.0 && v + w * reach > fast)
        };
        let hooks = if quick && bouncy { ActiveHooks::MODIFY_SOLVER_CONTACTS } else { ActiveHooks::empty() };
        if col.active_hooks() != hooks {
            r.colliders[c].set_active_hooks(hooks);
        }
        let ahead = if quick && b.is_dynamic() { PREDICTION_REACH * reach } else { 0.0 };
        if b.soft_ccd_prediction() != ahead {
            r.bodies[h].set_soft_ccd_prediction(ahead);
        }
    }
    bouncy
}

impl PhysicsHooks for Impacts {
    /// Before the step: each contact point rapier takes as bouncy (new, or e ≥ 1, its rule),
    /// from its normal velocity u (approaching: u > 0) and gap d at the start of the step and
    /// the normal acceleration a its bodies' gravity gives it towards the surface: the time
    /// it meets the surface (d = u t + a t²/2), and if it approaches, the energy of its normal
    /// motion (`flight_energy`).
    fn modify_solver_contacts(&self, ctx: &mut ContactModificationContext) {
        let (bodies, c1, c2, b1, b2) = (ctx.bodies, ctx.collider1, ctx.collider2, ctx.rigid_body1, ctx.rigid_body2);
        let Some(m) = ctx.rigid_mut() else {
            return;
        };
        *m.user_data = 0;
        let e = *m.restitution;
        if !(e > 0.0) {
            return;
        }
        *m.restitution = 0.0;
        let n = *m.normal;
        let motion = |h: Option<RigidBodyHandle>, p: Vector| match h.and_then(|h| bodies.get(h)) {
            Some(b) if b.is_dynamic() => (b.velocity_at_point(p), self.gravity * b.gravity_scale()),
            Some(b) => (b.velocity_at_point(p), Vector::ZERO),
            None => (Vector::ZERO, Vector::ZERO),
        };
        let mut found = self.found.lock().unwrap_or_else(|p| p.into_inner());
        let tag = found.len() as u32 + 1;
        for sc in m.solver_contacts.iter() {
            let id = (sc.contact_id[0] & !NEW_CONTACT_BIT) as usize;
            let Some(point) = m.manifold.points.get(id) else {
                continue;
            };
            if !(point.data.impulse == 0.0 || e >= 1.0) {
                continue;
            }
            // In the hook the anchors are world points.
            let ((v1, a1), (v2, a2)) = (motion(b1, sc.anchor1), motion(b2, sc.anchor2));
            let (u, a, d) = ((v1 - v2).dot(n), (a1 - a2).dot(n), sc.dist.max(0.0));
            let (energy, meets) = if u > 0.0 {
                let arrival = (u * u + 2.0 * a * d).max(0.0).sqrt();
                (Some(e * e * flight_energy(-u, d, a, self.substep)), 2.0 * d / (u + arrival))
            } else {
                (None, 0.0)
            };
            let held = a.max(0.0) * (self.dt - meets).max(0.0);
            found.push(Impact { c1, c2, tag, id, e, accel: a, held, energy });
        }
        if found.len() as u32 >= tag {
            *m.user_data = tag;
        }
    }
}

/// Bytes that adding `n` bodies (each with its collider) to a system that then holds `total`
/// takes at its peak: each of rapier's arenas and lists of bodies and colliders (a body's and a
/// collider's struct, an arena slot's tag, a handle in each list of changes) may double its
/// capacity while the old buffer is still held, up to 2 `total` entries more; and each new body
/// allocates its own shape and list of colliders (under 256 bytes).
fn group_bytes(total: usize, n: usize) -> u128 {
    use std::mem::size_of;
    let slot = (size_of::<RigidBody>() + size_of::<Collider>() + 4 * 16) as u128;
    2 * total as u128 * slot + n as u128 * 256
}

/// Bytes a copy of rapier's state (a checkpoint) takes, from what it holds: each body and
/// collider (a hull shared by a group is shared by the copy too), contact pair, manifold and
/// contact point, and joint; twice that, for what counts do not see (the broad phase's tree,
/// the islands, hash tables' spare room, the allocator's overhead).
fn state_bytes(r: &Rapier) -> u128 {
    use std::mem::size_of;
    let mut pairs = 0usize;
    for p in r.narrow_phase.contact_pairs() {
        pairs += size_of::<ContactPair>();
        for m in p.manifolds() {
            pairs += size_of::<ContactManifold>()
                + m.points.len() * size_of::<TrackedContact<ContactData>>()
                + m.data.solver_contacts.len() * size_of::<SolverContact>();
        }
    }
    let bodies = r.bodies.len() * (size_of::<RigidBody>() + 64);
    let colliders = r.colliders.len() * (size_of::<Collider>() + 128);
    let joints = r.impulse_joints.len() * 2 * size_of::<ImpulseJoint>();
    2 * (bodies + colliders + pairs + joints) as u128
}

/// Bytes a step of rapier allocates as it goes (its solver's bodies and constraints, the contact
/// pairs its broad phase finds, each with its manifolds, graph edge and hash entries): a state's
/// worth (`state_bytes`); three times a touching pair's structs for each pair touching now, or 4
/// a body where fewer touch; twice a pair's struct for the others. (The first step of 40,000
/// touching balls, 520,000 pairs in the broad phase of which 120,000 touch, took 1.07 GB; this
/// asks 1.48 GB, counting its pairs from the boxes as below.) Before the first step after
/// bodies were added, loaded, moved by hand or rolled back (`cold`), rapier has not met their
/// pairs: they are counted from the bodies' boxes (`box_pairs`), so that bodies added
/// overlapping many others (1,000 balls in one place, 500,000 pairs) are asked for, not met
/// inside rapier's step (an abort under a memory cap).
fn step_bytes(r: &Rapier, state: u128, cold: Option<Real>) -> u128 {
    use std::mem::size_of;
    let pair =
        size_of::<ContactPair>() + 2 * size_of::<ContactManifold>() + 8 * size_of::<TrackedContact<ContactData>>();
    let (mut all, mut touching) =
        r.narrow_phase.contact_pairs().fold((0, 0), |(a, t), p| (a + 1, t + p.has_any_active_contact() as usize));
    let mut heavy = 3 * touching.max(4 * r.bodies.len());
    if let Some(margin) = cold {
        // A pair met for the first time costs more than one carried over (its graph edge, hash
        // entry and first manifolds): 4 a touching pair's structs (1,000 balls in one place took
        // 3.78 GB in their first step; this asks 4.45 GB). Counting stops where the step could
        // not fit in any memory (2^40 bytes).
        let (a, t) = box_pairs(r, margin, (1usize << 40) / (4 * pair));
        heavy = heavy.max(4 * t);
        (all, touching) = (all.max(a), touching.max(t));
    }
    state + (heavy * pair + all.saturating_sub(touching) * 2 * size_of::<ContactPair>()) as u128
}

/// The pairs of colliders rapier's broad phase will find at the next step, counted from their
/// boxes grown by `margin` (its prediction distance): (all, touching), where a pair touches if
/// the colliders' bounding spheres meet (exact for balls). Pairs within one body or of two
/// fixed bodies' colliders are left out, as rapier leaves them out. A sweep along x over the
/// boxes sorted by their low ends, stopping at `limit` pairs; too little memory for the boxes
/// counts as `limit` (the step would not fit either).
fn box_pairs(r: &Rapier, margin: Real, limit: usize) -> (usize, usize) {
    let mut boxes: Vec<(Aabb, BoundingSphere, Option<RigidBodyHandle>, bool)> = Vec::new();
    if boxes.try_reserve_exact(r.colliders.len()).is_err() {
        return (limit, limit);
    }
    for (_, c) in r.colliders.iter() {
        let parent = c.parent();
        let body = parent.and_then(|h| r.bodies.get(h));
        let fixed = body.is_none_or(|b| b.is_fixed());
        // Where the body is now: a collider's own pose follows its body's only in rapier's step,
        // and bodies moved by hand (`set_field`) have not stepped since.
        let pose = match (body, c.position_wrt_parent()) {
            (Some(b), Some(rel)) => *b.position() * *rel,
            _ => *c.position(),
        };
        let (aabb, sphere) = (c.shape().compute_aabb(&pose), c.shape().compute_bounding_sphere(&pose));
        boxes.push((aabb.loosened(margin), sphere, parent, fixed));
    }
    boxes.sort_unstable_by(|a, b| a.0.mins.x.total_cmp(&b.0.mins.x));
    let (mut all, mut touching) = (0, 0);
    for (i, (a, sa, pa, fa)) in boxes.iter().enumerate() {
        for (b, sb, pb, fb) in &boxes[i + 1..] {
            if b.mins.x > a.maxs.x {
                break;
            }
            if (*fa && *fb) || (pa.is_some() && pa == pb) || !a.intersects(b) {
                continue;
            }
            all += 1;
            touching += (sa.center.distance(sb.center) <= sa.radius + sb.radius) as usize;
            if all >= limit {
                return (all, touching);
            }
        }
    }
    (all, touching)
}

/// A contact point of `restitution`: its bodies (dynamic ones), where it acts on each, its
/// normal (from body 1 to 2), its inverse effective mass, the speed it is to part at (an
/// impact), the impulse Newton's pass has given and the least it may give (less the step's
/// normal impulse and Poisson's part: the point's total stays ≥ 0).
struct Bounce {
    b: [Option<RigidBodyHandle>; 2],
    p: [Vector; 2],
    n: Vector,
    k: Real,
    speed: Option<Real>,
    given: Real,
    least: Real,
}

impl Bounce {
    fn push(&self, r: &mut Rapier, dj: Real) {
        for (i, s) in [(0, -1.0), (1, 1.0)] {
            if let Some(h) = self.b[i] {
                r.bodies[h].apply_impulse_at_point(self.n * (dj * s), self.p[i], true);
            }
        }
    }
}

/// Restitution after rapier's step, at the bouncy contact points `found` (`Impacts`) that took
/// a normal impulse J in it, in two passes.
///
/// First Poisson's law: each point gets e times its compression impulse, J less what held its
/// bodies at the surface against gravity after they met it (`Impact::held` over the point's
/// inverse effective mass k). rapier's step is an inelastic impact of all of them together,
/// so this is energy-consistent (e = 1 keeps the kinetic energy exactly: the inelastic
/// velocities are orthogonal in the mass metric to its impulses), and passes an impact on
/// along a chain (a ball struck from above while on the floor: without it rapier's inelastic
/// step gave the strike to the floor, and 12 elastic balls lost 3.5 % in one such strike).
/// A point that did not approach takes part only when it shares a body with one that did
/// (else a resting pile of e ≥ 1 would be kicked by the weight it holds); one still
/// approaching at the end of rapier's step by more than half of what J took out met the
/// surface only as the step ended (rapier's speculative contact slowed it to arrive then):
/// its impact is the next step's, and J is taken back (else a ball falling onto one that
/// bounced from the floor in the same step lost its speed: 5 % of 12 balls' energy).
///
/// Then Newton's law at the impacts: sequential impulses (each point's total normal impulse
/// kept ≥ 0), swept until the velocities settle, until each parts at the speed that leaves e²
/// of the energy of its normal motion (e times its arrival speed as h → 0: what rapier's step
/// lost to the contact on the way in put back), all together, as Box2D's relax iterations (and
/// Newton's per manifold) do: a box landing flat parts from the floor at both corners at once
/// (rapier's step may share the landing's impulse between them unevenly) and leaves without
/// spin. Where Poisson's pass already gave that, as at a lone impact, it changes nothing.
///
/// The bodies' positions are where rapier's step left them, at the surface: a bounce is late
/// by at most a step, never short.
fn restitution(r: &mut Rapier, found: &[Impact], h: Real, before: &[Option<Rotation>]) {
    let mut points: Vec<Bounce> = Vec::with_capacity(found.len());
    let mut kicks: Vec<Real> = Vec::with_capacity(found.len());
    for f in found {
        let Some(pair) = r.narrow_phase.contact_pair(f.c1, f.c2) else {
            continue;
        };
        let Some(m) = pair.solver_manifolds().iter().find(|m| m.data.user_data == f.tag) else {
            continue;
        };
        let Some(sc) = m.data.solver_contacts.iter().find(|sc| (sc.contact_id[0] & !NEW_CONTACT_BIT) as usize == f.id)
        else {
            continue;
        };
        let j = m.points.get(f.id).map_or(0.0, |p| p.data.impulse);
        if !(j > 0.0) {
            continue;
        }
        let (p1, p2) = contact_points(m, sc, &r.bodies, before);
        let n = m.data.normal;
        // The parting speed v with flight_energy(v, gap, a, h) = the impact's energy: the gap
        // where rapier's step left it (held at ≥ 0: a deeper body is pushed out later).
        let (a, gap) = (f.accel, (p2 - p1).dot(n).max(0.0));
        let q = 0.5 * a * h;
        let speed = f.energy.map(|energy| q + (q * q + 2.0 * (energy - a * gap)).max(0.0).sqrt());
        let dynamic = |h: Option<RigidBodyHandle>| h.filter(|&h| r.bodies.get(h).is_some_and(|b| b.is_dynamic()));
        let b = [dynamic(m.data.rigid_body1), dynamic(m.data.rigid_body2)];
        let mut k = 0.0;
        for (h, p) in b.iter().zip([p1, p2]) {
            if let Some(body) = h.map(|h| &r.bodies[h]) {
                let mp = body.mass_properties();
                let rn = moment(p - body.center_of_mass(), n);
                k += n.dot(n * mp.effective_inv_mass) + ang_dot(rn, mp.effective_world_inv_inertia * rn);
            }
        }
        if k > 0.0 && k.is_finite() {
            let at = |i: usize, p: Vector| b[i].map_or(Vector::ZERO, |h| r.bodies[h].velocity_at_point(p));
            let parting = (at(1, p2) - at(0, p1)).dot(n);
            let kick = if parting < -0.5 * j * k { -j } else { f.e * (j - f.held / k).max(0.0) };
            points.push(Bounce { b, p: [p1, p2], n, k, speed, given: 0.0, least: -(j + kick) });
            kicks.push(kick);
        }
    }
    let key = |h: &RigidBodyHandle| h.into_raw_parts();
    let mut struck: Vec<(u32, u32)> =
        points.iter().filter(|q| q.speed.is_some()).flat_map(|q| q.b.iter().flatten().map(key)).collect();
    struck.sort_unstable();
    for (q, &kick) in points.iter().zip(&kicks) {
        if q.speed.is_some() || q.b.iter().flatten().any(|h| struck.binary_search(&key(h)).is_ok()) {
            q.push(r, kick);
        }
    }
    points.retain(|q| q.speed.is_some());
    let scale = points.iter().fold(0.0, |s: Real, q| s.max(q.speed.unwrap_or(0.0)));
    for _ in 0..100 {
        let mut moved: Real = 0.0;
        for q in points.iter_mut() {
            let at = |i: usize| q.b[i].map_or(Vector::ZERO, |h| r.bodies[h].velocity_at_point(q.p[i]));
            let parting = (at(1) - at(0)).dot(q.n);
            let given = (q.given + (q.speed.unwrap_or(0.0) - parting) / q.k).max(q.least);
            let dj = given - q.given;
            q.given = given;
            q.push(r, dj);
            moved = moved.max((dj * q.k).abs());
        }
        if !(moved > 1e-12 * scale) {
            break;
        }
    }
}

/// The world points of a solver contact on each body, at the levers the narrow phase found
/// before the step: rapier's `solver_contact_world_points` resolves a body's anchor through its
/// pose after the step, which turns the lever with the body by ω dt. For a spinning ball the
/// lever then leaves the normal: the bounce's impulse along n exerted a torque and its parting
/// speed read ω × r (a frictionless elastic ball dropped with 15 rad/s rose to 68 % of its
/// height at dt = 1/60 and left spinning at 72 rad/s; a rolling ball with e > 0 slowed by 3 % in
/// 5 s). Each lever p − c is turned back by the step's rotation, R_before R_after⁻¹; a side
/// rapier attaches to the world (dominance) keeps its world point, as rapier resolves it.
fn contact_points(
    m: &ContactManifold,
    sc: &SolverContact,
    bodies: &RigidBodySet,
    before: &[Option<Rotation>],
) -> (Vector, Vector) {
    let (p1, p2) = m.data.solver_contact_world_points(sc, bodies);
    let back = |p: Vector, h: Option<RigidBodyHandle>, world_attached: bool| {
        let turned = h.filter(|_| !world_attached).and_then(|h| {
            let r0 = before.get(h.into_raw_parts().0 as usize).copied().flatten()?;
            Some((bodies.get(h)?, r0))
        });
        match turned {
            Some((b, r0)) => {
                let c = b.center_of_mass();
                c + r0 * (b.rotation().inverse() * (p - c))
            }
            None => p,
        }
    };
    let dominance = m.data.relative_dominance;
    (back(p1, m.data.rigid_body1, dominance > 0), back(p2, m.data.rigid_body2, dominance < 0))
}

/// Rolling resistance at the bodies' contacts over the step rapier just took (rapier has
/// none): each contact manifold whose colliders have rolling friction (μ_r, the larger of
/// the two) resists the relative rolling of its bodies, ω_r = ω_1 − ω_2 less its twist about
/// the normal n (3D), with a couple of angular impulse H along −ω_r on the first body and +ω_r
/// on the second, at most the limiting torque μ_r R f_n over the step, H ≤ μ_r R J_n (J_n the
/// manifold's normal impulse in the step, summed over its contacts): the grains' model at full
/// mobilisation (Ai, Chen, Rotter & Ooi, Powder Technol. 206 (2011) 269, model A, a constant
/// torque against ω_r; the grains' elastic spring of model C needs a state per contact that
/// rapier does not keep). R is the rolling radius, R = R_1 R_2/(R_1 + R_2) with R_k the
/// distance along n from body k's centre of mass to its contact point (at the centre of the
/// normal impulses): a ball's radius, a capsule's on its side; a fixed or kinematic body
/// counts as a wall (R_k = ∞).
///
/// A contact that sticks keeps sticking: the couple comes with the tangential impulse j at the
/// contact point that leaves its slip as rapier's friction left it (what that friction would
/// add in the next step, taken now), so the couple slows the rolling motion as a whole (a
/// ball's spin and its speed, v = ω R), whose inverse inertia k is the Schur complement
/// k = k_HH − k_Ht K_tt⁻¹ k_tH of the contact's response (1/(I + m R²) for a ball on the
/// ground); where friction could not supply j (|j| + rapier's friction impulse > μ J_n) the
/// couple acts alone, k = û·(I_1⁻¹ + I_2⁻¹)û. Either way H = min(μ_r R J_n, |ω_r|/k): it stops
/// the relative rolling at most, never reverses it, and only takes kinetic energy (by
/// H(|ω_r| − kH/2) at zero slip; the step books it with the contacts'). The bodies are then
/// moved by `lag` times the velocity this changed: as far as the change would have moved them
/// had it acted evenly through rapier's step (its n substeps of semi-implicit Euler: lag =
/// dt (n + 1)/(2n)). Without that a ball held on a slope by its rolling resistance crept down
/// at 2.4 mm/s (dt = 1/240), and with dt in place of the lag crept up at 0.9 mm/s. A couple plus an
/// equal and opposite pair of impulses at one point: momentum and angular momentum are kept.
/// On a flat floor a ball rolling at v decelerates at a = μ_r g /(1 + I/(m R²)) (the torque
/// μ_r R m g on the rolling constraint v = ω R).
fn rolling_resistance(r: &mut Rapier, mu_r: &[Real], lag: Real) {
    let mu_of = |c: ColliderHandle| mu_r.get(c.into_raw_parts().0 as usize).copied().unwrap_or(0.0);
    let Rapier { narrow_phase, bodies, colliders, .. } = r;
    for pair in narrow_phase.contact_pairs() {
        let mu = mu_of(pair.collider1).max(mu_of(pair.collider2));
        if !(mu > 0.0) {
            continue;
        }
        for m in pair.solver_manifolds() {
            let (Some(h1), Some(h2)) = (m.data.rigid_body1, m.data.rigid_body2) else {
                continue;
            };
            // The normal impulse of the step, where it acted on each surface, and the friction
            // impulse rapier spent (summed in magnitude: an upper bound of its total's).
            let (mut jn, mut jt, mut p1, mut p2) = (0.0, 0.0, Vector::ZERO, Vector::ZERO);
            for sc in &m.data.solver_contacts {
                let id = (sc.contact_id[0] & !NEW_CONTACT_BIT) as usize;
                let Some(point) = m.points.get(id) else {
                    continue;
                };
                let j = point.data.impulse;
                if j > 0.0 {
                    let (a, b) = m.data.solver_contact_world_points(sc, bodies);
                    jn += j;
                    p1 += a * j;
                    p2 += b * j;
                    jt += point.data.tangent_impulse.iter().map(|t| t * t).sum::<Real>().sqrt();
                }
            }
            if !(jn > 0.0) {
                continue;
            }
            let (n, friction) = (m.data.normal, m.data.friction);
            let (p1, p2) = (p1 / jn, p2 / jn);
            let (b1, b2) = (&bodies[h1], &bodies[h2]);
            let (r1, r2) = (p1 - b1.center_of_mass(), p2 - b2.center_of_mass());
            let arm = |b: &RigidBody, r: Vector| if b.is_dynamic() { r.dot(n).abs() } else { Real::INFINITY };
            let (a1, a2) = (arm(b1, r1), arm(b2, r2));
            let reff = if a1.is_infinite() {
                a2
            } else if a2.is_infinite() {
                a1
            } else {
                a1 * a2 / (a1 + a2)
            };
            let w = rolling_part(b1.angvel() - b2.angvel(), n);
            let speed = ang_norm(w);
            if !(reff.is_finite() && reff > 0.0 && speed > 0.0) {
                continue;
            }
            let u = w / speed;
            // The change of the contact's relative velocity (at p) and of ω_1 − ω_2 under an
            // impulse j on body 1 at its contact point (−j on body 2) and the couple h (−h û on
            // body 1, +h û on body 2).
            let response = |j: Vector, h: Real| -> (Vector, AngVector) {
                let (mut du, mut dw) = (Vector::ZERO, ANG_ZERO);
                for (b, r, s) in [(b1, r1, 1.0), (b2, r2, -1.0)] {
                    if b.is_dynamic() {
                        let mp = b.mass_properties();
                        let dwb = mp.effective_world_inv_inertia * (moment(r, j * s) + u * (-h * s));
                        du += (j * s * mp.effective_inv_mass + ang_cross(dwb, r)) * s;
                        dw += dwb * s;
                    }
                }
                (du, dw)
            };
            let t = tangents(n);
            let (du_h, dw_h) = response(Vector::ZERO, 1.0);
            let mut kt = [[0.0; 2]; 2];
            let mut rhs = [0.0; 2];
            for a in 0..TANGENTS {
                for b in 0..TANGENTS {
                    kt[a][b] = t[a].dot(response(t[b], 0.0).0);
                }
                rhs[a] = -t[a].dot(du_h);
            }
            // The impulse per unit couple that keeps the slip, and the rolling's inverse inertia.
            let held = solve2(kt, rhs, TANGENTS).map(|x| t[0] * x[0] + t[1] * x[1]);
            let rolling = held.map(|j| (j, -ang_dot(u, response(j, 1.0).1))).filter(|&(_, k)| k > 0.0);
            let alone = (Vector::ZERO, -ang_dot(u, dw_h));
            let (mut j_unit, mut k) = rolling.unwrap_or(alone);
            let mut h = (mu * reff * jn).min(speed / k);
            if (j_unit * h).length() + jt > friction * jn {
                (j_unit, k) = alone;
                h = (mu * reff * jn).min(speed / k);
            }
            if !(k > 0.0 && h > 0.0 && h.is_finite()) {
                continue;
            }
            let j = j_unit * h;
            for (hb, p, s) in [(h1, p1, 1.0), (h2, p2, -1.0)] {
                let body = &mut bodies[hb];
                if !body.is_dynamic() {
                    continue;
                }
                let (v0, w0) = (body.linvel(), body.angvel());
                body.apply_impulse_at_point(j * s, p, true);
                body.apply_torque_impulse(u * (-h * s), true);
                let dv = RigidBodyVelocity::<Real> { linvel: body.linvel() - v0, angvel: body.angvel() - w0 };
                let pose = dv.integrate(lag, body.position(), &body.mass_properties().local_mprops.local_com);
                body.set_position(pose, true);
                for &c in body.colliders() {
                    if let Some(rel) = colliders[c].position_wrt_parent().copied() {
                        colliders[c].set_position(pose * rel);
                    }
                }
            }
        }
    }
}

/// x with k x = b for the leading `dim` × `dim` block of `k` (dim 1 or 2); `None` if singular.
fn solve2(k: [[Real; 2]; 2], b: [Real; 2], dim: usize) -> Option<[Real; 2]> {
    let x = if dim == 1 {
        [b[0] / k[0][0], 0.0]
    } else {
        let det = k[0][0] * k[1][1] - k[0][1] * k[1][0];
        [(b[0] * k[1][1] - k[0][1] * b[1]) / det, (k[0][0] * b[1] - b[0] * k[1][0]) / det]
    };
    x.iter().all(|v| v.is_finite()).then_some(x)
}

impl Bodies {
    /// rapier's step. It has no stopping point inside (1,000 balls in one place: seconds a
    /// step), so a step that may be long (the first after a change or a rollback, or one after
    /// a step of `WATCHED_STEP` or more) runs on a thread of its own while this one watches
    /// `stop` (`super::watched`): once it is set, `Halt::Stopped` is returned within 10 ms and
    /// the step is left to finish unseen on its thread with the state it took (its result
    /// dropped; it runs on for the rest of its step, on one core). The bodies then hold an
    /// empty state until the caller rolls the call back (`restore`), as a stopped step must be.
    /// Where the step runs changes no bit of what it computes.
    fn rapier_step(&mut self, stop: &AtomicBool) -> std::result::Result<(), Halt> {
        let start = std::time::Instant::now();
        let (gravity, params) = (self.gravity, self.params);
        // A panic in rapier's step (an inconsistent state that passed the load's checks: see
        // `trial_step`) is a halt: the world rolls the bodies back to their checkpoint, and the
        // user gets an error naming the solver instead of a `PanicException` at every call.
        let failed = Err(Halt::Diverged { index: 0, quantity: Failure::Solver });
        if self.last_step.is_some_and(|t| t < WATCHED_STEP) {
            let step = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                rapier_step_on(&mut self.d.r, &mut self.pipeline, &mut self.ccd, &self.impacts, gravity, &params)
            }));
            if step.is_err() {
                self.last_step = None;
                return failed;
            }
        } else {
            let mut stepper = Stepper {
                r: std::mem::replace(&mut self.d.r, Rapier::empty()),
                pipeline: std::mem::replace(&mut self.pipeline, PhysicsPipeline::new()),
                ccd: std::mem::replace(&mut self.ccd, CCDSolver::new()),
                impacts: std::mem::take(&mut self.impacts),
            };
            stepper = match super::watched("physcore-bodies", stop, move || {
                let s = &mut stepper;
                rapier_step_on(&mut s.r, &mut s.pipeline, &mut s.ccd, &s.impacts, gravity, &params);
                stepper
            }) {
                Some(Ok(stepper)) => stepper,
                Some(Err(_)) => {
                    self.last_step = None;
                    return failed;
                }
                None => {
                    self.last_step = None;
                    return Err(Halt::Stopped);
                }
            };
            Stepper { r: self.d.r, pipeline: self.pipeline, ccd: self.ccd, impacts: self.impacts } = stepper;
        }
        self.last_step = Some(start.elapsed());
        self.moved = false;
        Ok(())
    }
}

impl System for Bodies {
    fn name(&self) -> &str {
        &self.name
    }
    fn is_empty(&self) -> bool {
        self.handles.is_empty()
    }
    fn size(&self) -> usize {
        self.handles.len()
    }
    fn set(&mut self, setting: &crate::systems::WorldSetting) {
        if let crate::systems::WorldSetting::Gravity(g) = setting {
            self.gravity = vector(&g[..D]);
        }
    }
    fn step(&mut self, dt: Real, stop: &AtomicBool) -> std::result::Result<(), Halt> {
        let (k0, u0) = self.mechanical();
        self.params.dt = dt;
        let r = &mut self.d.r;
        let turns = gyroscopic_step(&mut r.bodies, dt, self.params.num_solver_iterations);
        let tops = tops(r, self.gravity, dt);
        let substep = dt / self.params.num_solver_iterations as Real;
        (self.impacts.gravity, self.impacts.dt, self.impacts.substep) = (self.gravity, dt, substep);
        // Faster than gravity gives in two steps: a body resting on another stays below it.
        let bouncy = hook_fast(r, &self.handles, &self.colliders, 2.0 * self.gravity.length() * dt);
        // The orientations the narrow phase sees, by handle index: `restitution`'s levers.
        let before = &mut self.impacts.before;
        before.clear();
        if bouncy {
            for (h, b) in r.bodies.iter() {
                let i = h.into_raw_parts().0 as usize;
                if before.len() <= i {
                    before.resize(i + 1, None);
                }
                before[i] = Some(*b.rotation());
            }
        }
        self.rapier_step(stop)?;
        let r = &mut self.d.r;
        end_turns(&mut r.bodies, turns);
        place_tops(r, tops);
        // The list is emptied in place: its buffer serves every step's impacts.
        let found = self.impacts.found.get_mut().unwrap_or_else(|p| p.into_inner());
        restitution(r, found, substep, &self.impacts.before);
        found.clear();
        if self.rolling.iter().any(|&m| m > 0.0) {
            // rapier's step is n substeps of semi-implicit Euler: a velocity change spread evenly
            // over them moves a body by (n + 1)/(2n) of it times dt.
            let n = self.params.num_solver_iterations as Real;
            rolling_resistance(&mut self.d.r, &self.rolling, dt * (n + 1.0) / (2.0 * n));
        }
        if let Some((index, quantity)) = self.fault() {
            return Err(Halt::Diverged { index, quantity });
        }
        let (k1, u1) = self.mechanical();
        // Speeds whose energy float64 cannot hold (a body set moving at 1e200 m/s): the books
        // overflow while the state is finite, and the call could not be saved with them; a
        // halt, as the particles' books.
        if !((k0 + u0) - (k1 + u1)).is_finite() {
            let speed = |i: usize| self.body(i).linvel().length();
            let fastest = (0..self.handles.len()).fold(0, |f, i| if speed(i) > speed(f) { i } else { f });
            return Err(Halt::Diverged { index: fastest, quantity: Failure::Books });
        }
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
        let Some(width) = settable_width(name) else {
            return Err(invalid(
                "field",
                format!("{name:?} cannot be set on the bodies (settable: {})", FIELDS[..SETTABLE].join(", ")),
            ));
        };
        if values.len() != width * n {
            return Err(invalid(name, format!("has {} values, expected {}", values.len(), width * n)));
        }
        finite_all(name, values)?;
        let rows: Vec<&[Real]> = values.chunks_exact(width).collect();
        // Every row checked before the first is written (a zero quaternion has no rotation).
        for (i, row) in rows.iter().enumerate() {
            set_one(&mut self.d.r.bodies[self.handles[i]], name, row, true)
                .map_err(|e| invalid(name, format!("entry {i}: {e}")))?;
        }
        for (i, row) in rows.iter().enumerate() {
            set_one(&mut self.d.r.bodies[self.handles[i]], name, row, false).expect("checked above");
        }
        // Bodies moved by hand may overlap others rapier has not paired: the next step's memory
        // is counted from their boxes (`step_bytes`).
        self.moved = true;
        Ok(())
    }
    fn fields(&self, names: &[&str]) -> Result<Vec<Vec<Real>>> {
        names
            .iter()
            .map(|&name| {
                if !FIELDS.contains(&name) || settable_width(name).is_some_and(|w| w > 1) {
                    return Err(invalid(
                        "field",
                        format!("the bodies have no field {name:?} to read (valid: {})", READABLE.join(", ")),
                    ));
                }
                let n = self.handles.len();
                Need::fields(&[name], n, "rigid bodies").collect((0..n).map(|i| get_one(self.body(i), name)))
            })
            .collect()
    }
    /// A copy of rapier's state. Its clone allocates infallibly (a refusal aborted the process),
    /// so the copy and the step it guards are first asked of the allocator (`state_bytes`,
    /// `step_bytes`): too little memory is an `Error::OutOfMemory` named "step".
    fn snapshot(&self) -> Result<Snapshot> {
        let copy = state_bytes(&self.d.r);
        let cold = (self.last_step.is_none() || self.moved).then(|| self.params.prediction_distance());
        let bytes = copy + step_bytes(&self.d.r, copy, cold);
        let of = format!("a checkpoint of {} rigid bodies and their step", count(self.handles.len() as u128));
        Need::new("step", bytes, of).room(bytes)?;
        Ok(Box::new(self.d.clone()))
    }
    /// The state as bincode bytes, sealed (`super::seal`) and packed 6 to a real: its size is
    /// counted first (`serialized_size`, which allocates nothing) and each buffer reserved
    /// fallibly, so too little memory is an `Error::OutOfMemory` named "save", not an abort.
    fn save(&self) -> Result<Arrays> {
        // Serialising rapier's types allocates temporaries of its own, infallibly (20 MB aborted
        // a save of 100,000 touching balls under a cap): a quarter of the state's copy is asked
        // for them first.
        let temporaries = state_bytes(&self.d.r) / 4;
        let of = format!("the solver state of {} rigid bodies", count(self.handles.len() as u128));
        Need::new("save", temporaries, &of).room(temporaries)?;
        let saving = self.d.saving();
        let size = io::size(&saving).map_err(|e| invalid("state", format!("cannot be saved: {e}")))?;
        let len = super::SEALED + size as usize;
        let bytes = len as u128 * 7 / 3 + temporaries;
        let need = Need::new("save", bytes, format!("{of} ({} bytes, packed)", count(len as u128)));
        need.room(bytes)?;
        let mut bytes = Vec::new();
        need.reserve(&mut bytes, len)?;
        bytes.resize(super::SEALED, 0);
        io::write(&mut bytes, &saving).map_err(|e| invalid("state", format!("cannot be saved: {e}")))?;
        super::seal(&mut bytes);
        let packed = pack(&bytes, &need)?;
        Ok(vec![("state".to_string(), packed), ("bytes".to_string(), vec![bytes.len() as Real])])
    }
    /// Reads a saved state: the packed bytes, then rapier's state from them, each asked of the
    /// allocator first (the state in memory is taken as three times its bytes: what bincode's
    /// growing lists may hold at their peak); too little memory is an `Error::OutOfMemory`
    /// named "load", and nothing changes.
    fn load(&mut self, arrays: &Arrays) -> Result<()> {
        let len = array(arrays, "bytes", Some(1))?[0];
        let packed = array(arrays, "state", None)?;
        let total = 4 * packed.len() as u128 * 6;
        let need = Need::new(
            "load",
            total,
            format!("the rigid bodies' solver state ({} bytes)", count(packed.len() as u128 * 6)),
        );
        need.room(total)?;
        let bytes = unpack(packed, len, &need)?.ok_or_else(|| invalid("state", "is not a packed bodies state"))?;
        let d = Dynamic::loaded(
            io::read(super::unsealed(&bytes)?).map_err(|e| invalid("state", format!("cannot be read: {e}")))?,
        );
        if d.parts < self.d.parts {
            return Err(invalid("state", format!("holds {} parts, the scene has {}", d.parts, self.d.parts)));
        }
        if d.parts == self.d.parts {
            self.take_state(d)?;
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
        self.last_step = None;
    }
    fn as_rigid_bodies(&mut self) -> Option<&mut dyn crate::systems::RigidBodies> {
        Some(self)
    }
}

impl crate::systems::RigidBodies for Bodies {
    fn bodies(&mut self) -> crate::systems::BodiesOf<'_> {
        as_bodies_of(self)
    }
    fn hint_dt(&mut self, dt: Real) {
        if dt.is_finite() && dt > 0.0 {
            self.params.dt = dt;
        }
    }
    fn add_group(&mut self, p: Params) -> Result<usize> {
        Bodies::add_group(self, p)
    }
    fn add_joints(&mut self, p: Params) -> Result<()> {
        Bodies::add_joints(self, p)
    }
    fn add_pins(&mut self, p: Params) -> Result<()> {
        Bodies::add_pins(self, p)
    }
    fn body_mesh(&self, i: usize) -> Result<(Vec<Real>, Vec<u32>)> {
        Bodies::body_mesh(self, i)
    }
}

/// Particles against the bodies, both ways: a particle (its `radius` attribute, else a point)
/// inside or touching a body's shape is put back on its surface, and the impulse that stops
/// its approach (the body's restitution, Coulomb friction with the body's coefficient) is
/// applied to both, equal and opposite, at the contact point: grains push bodies, a body pushes
/// grains, cloth drapes over a body, fluid particles hold a body up. A grain that turns (a
/// radius and a spin from a term's `OwnState::spins`: DEM contacts) is pushed at its surface
/// point, its friction against the contact point's velocity with its rotational inertia in the
/// effective mass, and the moment turns it (`grain_contact`); other particles are pushed at
/// their centres, as they were before grains turned here. A particle with a radius held
/// between a moving body and a fixed one (`backing`: a cloth under a plate on the table) bears
/// the moving body's weight instead: the body is lifted off it and the contacts of each such
/// body are solved together (`Held`), with Coulomb friction between the particle and the body.
/// Particles are visited in
/// order (the bodies' velocities change as they go): deterministic. The energy this removes
/// (kinetic, the grains' spin included, and the particles' potential in gravity raised by the
/// moves) is booked in the bodies' "bodies ⇄ particles".
///
/// Fluids that take moving boundary particles (`terms::MovingBoundary`: DFSPH and WCSPH) meet
/// the moving (dynamic and kinematic) bodies through them as well (Akinci et al. 2012): each
/// such body's surface is sampled once at the fluid's spacing, half a spacing inside
/// (`surface_samples`), each sample weighed by Ψ_b = ρ0/Σ_k W_bk over its body's samples
/// (`sph::resolve::wall_psi`, paper eq. 4–5) times `layer_scale`; before each step (`prepare`)
/// the samples are posed and the fluid given their bodies' motion; after the particles' step
/// and before the bodies' (`between`), each body takes the impulse the fluid gave it. So the
/// fluid holds a body up by its pressure, as it does its walls. (DFSPH books the fluid's share
/// of the exchange as what its projections remove, the coupling the bodies'; a WCSPH fluid's
/// internal energy pays for both.)
pub struct BodyContacts {
    system: usize,
    /// Working buffers kept between steps: each body's grown box, and every move of the step
    /// (the particle and, in turn, its position before and after: see `apply`).
    boxes: Vec<Aabb>,
    moved: Vec<(usize, [Real; 3])>,
    /// The boundary particles of each fluid that takes them, in the particle system's order.
    fluids: Vec<Boundary>,
    /// The impulses a fluid reports, by body (linear, angular), kept between steps.
    impulses: Vec<([Real; 3], [Real; 3])>,
    /// Each body's lift off the particles that hold it up against a fixed body (`backing`):
    /// how far, and along which normal, kept between steps.
    lifts: Vec<(Real, Vector)>,
    /// The step's contacts of particles held between a moving body and a fixed one, kept
    /// between steps.
    held: Vec<Held>,
}

/// A particle `i` held between the moving body `k` and a fixed body (`backing`): the contact
/// point on the body `c`, the fixed body's outward normal `nf`, the body's friction
/// coefficient, and the normal impulse found for it (N·s).
struct Held {
    i: usize,
    k: usize,
    c: Vector,
    nf: Vector,
    mu: Real,
    jn: Real,
}

/// Projected Gauss-Seidel sweeps over the contacts of the bodies particles hold up, a step:
/// enough for a plate on a few dozen particles to rest (see `apply`).
const HELD_SWEEPS: usize = 16;

/// The lightest moving body a fluid takes, as a fraction of its rest density. Measured on a
/// ball (radius 2.5 and 1.5 spacings, 2D and 3D) dropped 1 cm onto DFSPH water at rest, its
/// speed after 1 s at the suggested dt: at 0.1, 0.016 m/s (2D) and 0.05 (3D); at 0.05, 0.10
/// and 0.14; at 0.02 (3D) 1.7 m/s, at 0.005 (2D) 2.3; at 1e-6 it leaves at 3e8 m/s with a
/// particle at 1e5 m/s (and nothing said so before this limit).
const LIGHTEST: Real = 0.1;

/// One fluid's boundary particles on the moving bodies, in their bodies' frames.
#[derive(Default)]
struct Boundary {
    /// What the samples were made for: bodies, and the bits of h, ρ0, the spacing and the kernel.
    key: Option<(usize, [u64; 3], crate::sph::KernelKind)>,
    /// The bodies sampled (body numbers), each sample's index among them and its point (body
    /// frame), and its Ψ_b (kg).
    movers: Vec<usize>,
    body: Vec<u32>,
    local: Vec<Vector>,
    psi: Vec<Real>,
}

impl Boundary {
    /// Samples every dynamic and kinematic body's surface (fixed ones are the fluid's walls to
    /// give; they keep fluid out by the impulse exchange).
    ///
    /// A body whose surface needs more samples than memory holds (each with its kernel pairs)
    /// is refused as `Error::OutOfMemory` before any is made, and Ctrl-C (`stop`) is seen
    /// between bodies and between a 3D surface's triangles (`Error::Interrupted`): a body
    /// a kilometre wide in a fluid of centimetre spacing is billions of samples.
    fn sample(
        &mut self,
        bodies: &Bodies,
        h: Real,
        rho0: Real,
        kernel: crate::sph::KernelKind,
        spacing: Real,
        stop: &AtomicBool,
    ) -> Result<()> {
        use crate::sph::resolve::{wall_psi, WallVolume};
        // The spacing is the fluid's m/ρ0 to the 1/D: a mass far from ρ0 Δx^D (a hostile file)
        // gave 2h/spacing in the billions, and layer_scale's rows a 22 GB allocation.
        let reach = 2.0 * h / spacing;
        if !(1e-3..=64.0).contains(&reach) {
            return Err(invalid(
                "mass",
                format!(
                    "the fluid's particle mass gives a spacing (m/ρ0)^(1/{D}) = {spacing:.3e} m, and its kernel \
                     support 2h = {:.3e} m is {reach:.3e} of those: a mass so far from ρ0 Δx^{D} cannot \
                     sample a body's surface",
                    2.0 * h
                ),
            ));
        }
        let scale = layer_scale(h, spacing, kernel);
        self.key = None;
        self.movers.clear();
        self.body.clear();
        self.local.clear();
        self.psi.clear();
        // A sample's bytes: its point here and in the fluid (position, offset), Ψ, its body,
        // and the kernel pairs Ψ is summed over (two indices and a value each, about
        // π (2h/spacing)^(D-1) pairs a sample on a surface).
        let pairs = if D == 2 { 2.0 * reach + 1.0 } else { std::f64::consts::PI * reach * reach + 1.0 };
        let per = (3 * std::mem::size_of::<Vector>() + 12) as Real + 24.0 * pairs;
        for (k, (&hd, &c)) in bodies.handles.iter().zip(&bodies.colliders).enumerate() {
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Err(crate::error::Error::Interrupted { rolled_back_to: 0 });
            }
            if bodies.d.r.bodies[hd].is_fixed() {
                continue;
            }
            let col = &bodies.d.r.colliders[c];
            if bodies.d.r.bodies[hd].is_dynamic() && col.density() < LIGHTEST * rho0 {
                return Err(invalid(
                    "density",
                    format!(
                        "body {k} has density {:e} in a fluid of rest density {rho0:e}: a body lighter \
                         than {LIGHTEST} times the fluid's is flung out by the pressure it takes (the \
                         fluid's pushes are explicit in the body's motion); make it at least {:e}",
                        col.density(),
                        LIGHTEST * rho0
                    ),
                ));
            }
            let room = |n: usize| {
                let bytes = (n as Real * per).min(u128::MAX as Real) as u128;
                crate::alloc::Need::new(
                    "boundary samples",
                    bytes,
                    format!("body {k}'s surface at the fluid's spacing {spacing:.3e} m (about {n} samples)"),
                )
                .room(bytes)
            };
            let mut pts = surface_samples(col.shape(), spacing, 0.5 * spacing, &room, stop)?;
            if let Some(rel) = col.position_wrt_parent() {
                pts.iter_mut().for_each(|p| *p = rel.transform_point(*p));
            }
            let flat: Vec<Real> = pts.iter().flat_map(|p| p.to_array()[..D].to_vec()).collect();
            // Finite and > 0 for any sampled surface (each sample counts itself).
            let Ok(mut psi) = wall_psi(&flat, D, rho0, h, kernel, WallVolume::Sampled, 0.0) else {
                continue;
            };
            psi.iter_mut().for_each(|p| *p *= scale);
            if pts.is_empty() {
                continue;
            }
            self.body.extend(std::iter::repeat_n(self.movers.len() as u32, pts.len()));
            self.movers.push(k);
            self.local.extend(pts);
            self.psi.extend(psi);
        }
        Ok(())
    }
}

/// The factor on Akinci's Ψ_b = ρ0/Σ_k W_bk for one layer of samples `spacing` apart (a
/// body's boundary), so that a fluid particle one spacing from a flat layer finds the density
/// the missing rows of a lattice would give it (what a wall of lattice layers gives): with
/// f(r) the kernel summed over a flat layer at distance r and m = ρ0/Σ_j f(j s) the fluid
/// particle's mass, Ψ f(s) = m Σ_{j≥1} f(j s). Akinci's Ψ alone gives that particle ρ0 f(s)/f(0),
/// about twice as much at h = 1.3 spacings, and holds the fluid off: a box of half the water's
/// density floated 1.4 spacings too high (2D).
fn layer_scale(h: Real, spacing: Real, kernel: crate::sph::KernelKind) -> Real {
    let Ok(inv) = crate::sph::resolve::inv_h_dim(h, D) else {
        return 1.0;
    };
    let reach = (2.0 * h / spacing).ceil() as i64 + 1;
    let w = |r2: Real| crate::sph::resolve::kernel_value(r2.sqrt() / h, inv, D, kernel);
    let layer = |r: Real| {
        let mut t = 0.0;
        for i in -reach..=reach {
            let a = (i as Real * spacing).powi(2) + r * r;
            if D == 2 {
                t += w(a);
            } else {
                for j in -reach..=reach {
                    t += w(a + (j as Real * spacing).powi(2));
                }
            }
        }
        t
    };
    let rows: Vec<Real> = (0..=reach).map(|j| layer(j as Real * spacing)).collect();
    let beyond: Real = rows[1..].iter().sum();
    let total = rows[0] + 2.0 * beyond;
    if rows[1] > 0.0 && total > 0.0 {
        rows[0] * beyond / (total * rows[1])
    } else {
        1.0
    }
}

impl BodyContacts {
    /// The coupling of the particles with the bodies system `others[system]` of the world.
    pub fn new(system: usize) -> Self {
        Self { system, boxes: Vec::new(), moved: Vec::new(), fluids: Vec::new(), impulses: Vec::new(), lifts: Vec::new(), held: Vec::new() }
    }
}

/// The bodies system `others[system]` of this dimension, if it is one (through its role).
fn bodies_in(others: &mut [Box<dyn System>], system: usize) -> Option<&mut Bodies> {
    of_this_dim(others.get_mut(system)?.as_rigid_bodies()?.bodies())
}

/// A vector of the bodies' dimension as the particles' (`V::DIM == D`).
fn to_particle<V: PVector>(x: Vector) -> V {
    let mut s = [0.0; 3];
    s[..D].copy_from_slice(&x.to_array()[..D]);
    V::from_slice(&s[..V::DIM])
}

/// How far (at most, over its radius) a particle may sit from a fixed body's surface and still
/// rest on it, as a fraction of its radius: one step of gravity takes a particle resting at its
/// radius a little into the surface, and a sheet pressed between two bodies a little out.
const RESTING: Real = 1.25;

/// The projection of `p` onto the shape of `col`, and `p` minus the projected point. A point at
/// a ball's centre has no nearest surface point (parry's is NaN, and the particle's state
/// became NaN with it): it is projected from 1e-9 of the shape's size above it (+y), so it is
/// pushed out upward.
fn project(col: &Collider, p: Vector) -> (PointProjection, Vector) {
    let proj = col.shape().project_point(col.position(), p, false);
    let d = p - proj.point;
    if d.is_finite() {
        return (proj, d);
    }
    let size = col.shape().compute_local_bounding_sphere().radius();
    let q = p + Vector::Y * (1e-9 * if size > 0.0 && size.is_finite() { size } else { 1.0 });
    let proj = col.shape().project_point(col.position(), q, false);
    let d = q - proj.point;
    (proj, d)
}

/// The outward normal of the fixed body that the particle at `p` (radius `ri` > 0: particles
/// of no size, an SPH fluid's, are pushed out as before) rests on, if one
/// lies on the far side of it from a moving body touching it with the normal `normal` (from
/// that body to the particle; the two normals more than 90° apart: the body touches the
/// particle on the half away from the fixed one): the particle is then held between them, a
/// cloth between a plate and the table. (A sheet of particles is a surface: a plate's edge that
/// dips between two of them as the sheet slides under it is held up by it, not rammed.)
fn backing(bodies: &Bodies, p: Vector, ri: Real, normal: Vector) -> Option<Vector> {
    for (&h, &c) in bodies.handles.iter().zip(&bodies.colliders) {
        if !bodies.d.r.bodies[h].is_fixed() {
            continue;
        }
        let col = &bodies.d.r.colliders[c];
        let (proj, d) = project(col, p);
        let dist = d.length();
        if !(dist > 0.0) || (!proj.is_inside && dist > RESTING * ri) {
            continue;
        }
        let nf = if proj.is_inside { -d / dist } else { d / dist };
        if nf.dot(normal) < 0.0 {
            return Some(nf);
        }
    }
    None
}

/// The inverse effective mass of a particle (inverse mass `im`) and a body pushed apart at `c`
/// along the unit `t`: im + 1/m + (r×t)·I⁻¹(r×t), r from the body's centre of mass; the body's
/// share is 0 if it is fixed or kinematic.
fn pair_inv_mass(im: Real, body: &RigidBody, c: Vector, t: Vector) -> Real {
    if !body.is_dynamic() {
        return im;
    }
    im + body.mass_properties().effective_inv_mass.x + turning(body, c - body.center_of_mass(), t)
}

/// The rotational kinetic energy of the grains that turn, Σ ½ β m r² |ω|² (J; 0 without spins).
fn spin_kinetic<V: PVector>(
    spins: Option<&crate::terms::Spins<'_, V>>,
    model: &crate::state::Model,
    radius: Option<&[Real]>,
) -> Real {
    let (Some(sp), Some(r)) = (spins, radius) else {
        return 0.0;
    };
    let mut k = 0.0;
    for (i, w) in sp.omega.iter().enumerate() {
        if model.inv_mass[i] != 0.0 && r[i] > 0.0 {
            k += 0.5 * sp.inertia_factor * model.mass[i] * r[i] * r[i] * V::axial_length_squared(*w);
        }
    }
    k
}

/// A particle's spin (`V::AXIAL_DIM` components) as the bodies' angular vector.
fn axial_ang<V: PVector>(w: V::Axial) -> AngVector {
    let s = V::axial_flat(std::slice::from_ref(&w));
    let mut a = [0.0; 3];
    a[3 - s.len()..].copy_from_slice(s);
    ang_of(a)
}

/// The bodies' angular vector as a particle's spin.
fn ang_axial<V: PVector>(w: AngVector) -> V::Axial {
    V::axial_from_slice(&ang3(w)[3 - V::AXIAL_DIM..])
}

/// A grain that turns, as one contact with a body sees it: velocity (m/s), spin (rad/s),
/// inverse mass (1/kg), radius (m) and β in I = β m r².
struct Grain<V: PVector> {
    v: Vector,
    w: V::Axial,
    inv_mass: Real,
    radius: Real,
    beta: Real,
}

/// The impulse between a grain that turns and a body, the grain already put back on the
/// body's surface (its centre at c + r n, n the unit normal out of the body): the contact acts
/// at the grain's surface point c, r_c = −r n from its centre. The contact point's relative
/// velocity is u = v + ω × r_c − v_b(c); the normal impulse stops its approach with the
/// restitution e, J_n = −(1 + e) u_n / k_n; friction acts against the sliding u_t, J_t = −t ·
/// min(μ J_n, |u_t| / k_t), where 1/k_t, the effective mass along t, counts the grain's turning
/// as the body's: k_t = 1/m + |r_c × t|²/I + the body's share = (1 + 1/β)/m + the body's share
/// (|r_c × t| = r for t ⊥ n). (On the normal r_c × n = 0: k_n is the centre's.) The grain takes
/// J at its centre and the moment r_c × J_t on its spin, the body −J at c: momentum and angular
/// momentum are exchanged exactly. Rigid impact theory with Coulomb friction (Stronge, *Impact
/// Mechanics*, 2000, §4.2; the rough ball of Garwin, Am. J. Phys. 37 (1969) 88, at e_t = 0):
/// a disc (β = ½) meeting a fixed surface at u_t with μ(1 + e)u_n ≥ u_t β/(1 + β) leaves
/// rolling, v_t' = u_t/(1 + β) = ⅔ u_t. Returns the grain's new velocity and spin.
fn grain_contact<V: PVector>(
    body: &mut RigidBody,
    g: Grain<V>,
    c: Vector,
    normal: Vector,
    e: Real,
    mu: Real,
) -> (Vector, V::Axial) {
    let w = axial_ang::<V>(g.w);
    let rc = normal * -g.radius;
    let rel = g.v + ang_cross(w, rc) - body.velocity_at_point(c);
    let vn = rel.dot(normal);
    if vn >= 0.0 {
        return (g.v, g.w);
    }
    let k_n = pair_inv_mass(g.inv_mass, body, c, normal);
    let jn = -(1.0 + e) * vn / k_n;
    let vt_vec = rel - normal * vn;
    let vt = vt_vec.length();
    let mut jt = Vector::ZERO;
    if vt > 0.0 && mu > 0.0 {
        let t = vt_vec / vt;
        let k_t = pair_inv_mass(g.inv_mass, body, c, t) + g.inv_mass / g.beta;
        jt = t * -(mu * jn).min(vt / k_t);
    }
    let impulse = normal * jn + jt;
    if body.is_dynamic() {
        body.apply_impulse_at_point(-impulse, c, true);
    }
    let inv_inertia = g.inv_mass / (g.beta * g.radius * g.radius);
    (g.v + impulse * g.inv_mass, ang_axial::<V>(w + moment(rc, jt) * inv_inertia))
}

impl<V: PVector> Coupling<V> for BodyContacts {
    fn name(&self) -> &str {
        "bodies ⇄ particles"
    }
    fn prepare(
        &mut self,
        particles: &mut crate::systems::particles::ParticleSystem<V>,
        others: &mut [Box<dyn System>],
        stop: &AtomicBool,
    ) -> Result<()> {
        if V::DIM != D {
            return Ok(());
        }
        let Some(bodies) = bodies_in(others, self.system) else {
            return Ok(());
        };
        let (hosts, model) = particles.moving_boundaries();
        self.fluids.resize_with(hosts.len(), Boundary::default);
        for (host, bd) in hosts.into_iter().zip(&mut self.fluids) {
            let (h, rho0, kernel, spacing) = host.boundary_sampling(model);
            let key = (bodies.handles.len(), [h.to_bits(), rho0.to_bits(), spacing.to_bits()], kernel);
            if bd.key != Some(key) {
                if spacing.is_finite() && spacing > 0.0 {
                    bd.sample(bodies, h, rho0, kernel, spacing, stop)?;
                }
                bd.key = Some(key);
            }
            let motion: Vec<BodyMotion<V>> = bd
                .movers
                .iter()
                .map(|&k| {
                    let b = &bodies.d.r.bodies[bodies.handles[k]];
                    let pushed = b.is_dynamic();
                    BodyMotion {
                        v: to_particle(b.linvel()),
                        w: ang3(b.angvel()),
                        inv_mass: if pushed { b.mass_properties().effective_inv_mass.x } else { 0.0 },
                        inv_inertia: if pushed { inv_inertia6(b) } else { [0.0; 6] },
                        accel: if pushed { to_particle(bodies.gravity * b.gravity_scale()) } else { V::ZERO },
                        gravity: to_particle(bodies.gravity),
                    }
                })
                .collect();
            let mut x = Vec::with_capacity(bd.local.len());
            let mut offset = Vec::with_capacity(bd.local.len());
            for (&m, &local) in bd.body.iter().zip(&bd.local) {
                let body = &bodies.d.r.bodies[bodies.handles[bd.movers[m as usize]]];
                let p = body.position().transform_point(local);
                x.push(to_particle(p));
                offset.push(to_particle(p - body.center_of_mass()));
            }
            host.set_boundary(&x, &bd.psi, &bd.body, &offset, &motion);
        }
        Ok(())
    }

    /// The impulse each fluid's pressure solve gave the bodies over the particles' step,
    /// applied before the bodies step (so they move with it); the energy it gives them is
    /// booked with the exchange.
    fn between(
        &mut self,
        particles: &mut crate::systems::particles::ParticleSystem<V>,
        others: &mut [Box<dyn System>],
        dt: Real,
    ) {
        if V::DIM != D || self.fluids.is_empty() {
            return;
        }
        let Some(bodies) = bodies_in(others, self.system) else {
            return;
        };
        let (hosts, _) = particles.moving_boundaries();
        let mut out: Vec<(V, [Real; 3])> = Vec::new();
        for (host, bd) in hosts.into_iter().zip(&self.fluids) {
            let before = bodies.mechanical().0;
            host.boundary_impulses(dt, &mut out);
            if out.len() != bd.movers.len() {
                continue;
            }
            self.impulses.clear();
            self.impulses.extend(out.iter().map(|(p, l)| {
                let mut s = [0.0; 3];
                for (c, v) in s.iter_mut().enumerate().take(D) {
                    *v = p.comp(c);
                }
                (s, *l)
            }));
            for (&k, (p, l)) in bd.movers.iter().zip(&self.impulses) {
                let body = &mut bodies.d.r.bodies[bodies.handles[k]];
                if body.is_dynamic() {
                    body.apply_impulse(vector(&p[..D]), true);
                    body.apply_torque_impulse(ang_of(*l), true);
                }
            }
            // DFSPH's projections book the fluid's share of the exchange; a WCSPH fluid's
            // internal energy counts the boundary, so it pays the bodies' gain itself.
            if host.books_exchange() {
                bodies.d.coupling += before - bodies.mechanical().0;
            }
        }
    }

    fn apply(
        &mut self,
        particles: &mut crate::systems::particles::ParticleSystem<V>,
        others: &mut [Box<dyn System>],
        _dt: Real,
    ) {
        if V::DIM != D {
            return;
        }
        let Some(bodies) = bodies_in(others, self.system) else {
            return;
        };
        let (state, model, mut spins) = particles.state_model_spins_mut();
        let n = state.x.len();
        if n == 0 || bodies.handles.is_empty() {
            return;
        }
        let radius = model.attribute("radius");
        // Spins once their term has sized them to the particles (after its first step).
        if spins.as_ref().is_some_and(|s| s.omega.len() != n || radius.is_none()) {
            spins = None;
        }
        let r_max = radius.map(|r| r.iter().cloned().fold(0.0, Real::max)).unwrap_or(0.0);
        // Each body's box, grown by the largest radius: the broad test.
        let boxes = &mut self.boxes;
        boxes.clear();
        boxes.extend(bodies.colliders.iter().map(|&c| bodies.d.r.colliders[c].compute_aabb().loosened(r_max)));
        let e_before = particle_kinetic(&state.v, &model.mass, &model.inv_mass)
            + bodies.mechanical().0
            + spin_kinetic(spins.as_ref(), model, radius);
        // Every move: the particle and where it was (the potential energy the moves change
        // is booked with the exchange below).
        let moved = &mut self.moved;
        moved.clear();
        self.lifts.clear();
        self.held.clear();
        self.lifts.resize(bodies.handles.len(), (0.0, Vector::ZERO));
        let slot = |x: V| {
            let mut s = [0.0; 3];
            for (c, v) in s.iter_mut().enumerate().take(D) {
                *v = x.comp(c);
            }
            s
        };
        let from_p = |x: V| vector(&slot(x)[..D]);
        let to_p = |x: Vector| {
            let mut s = [0.0; 3];
            s[..D].copy_from_slice(&x.to_array()[..D]);
            V::from_slice(&s)
        };
        for i in 0..n {
            let im = model.inv_mass[i];
            if im == 0.0 {
                continue;
            }
            let ri = radius.map(|r| r[i]).unwrap_or(0.0);
            let p = from_p(state.x[i]);
            for (k, bb) in boxes.iter().enumerate() {
                if !bb.contains_local_point(p) {
                    continue;
                }
                let col = &bodies.d.r.colliders[bodies.colliders[k]];
                let (proj, d) = project(col, p);
                let (e, mu) = (col.restitution(), col.friction());
                let dist = d.length();
                let (normal, depth) = if proj.is_inside {
                    if !(dist > 0.0) {
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
                let vi = from_p(state.v[i]);
                let vb = body.velocity_at_point(c);
                // A grain that turns is pushed at its surface point (see `grain_contact`).
                if let Some(sp) = spins.as_mut().filter(|_| ri > 0.0) {
                    moved.push((i, slot(state.x[i])));
                    state.x[i] = to_p(p + normal * depth);
                    let (v, w) = grain_contact::<V>(
                        body,
                        Grain { v: vi, w: sp.omega[i], inv_mass: im, radius: ri, beta: sp.inertia_factor },
                        c,
                        normal,
                        e,
                        mu,
                    );
                    state.v[i] = to_p(v);
                    sp.omega[i] = w;
                    continue;
                }
                // A particle held between a moving body and a fixed one (a cloth under a plate on
                // the table) bears the body's weight: the body, not the particle, is put back (lifted
                // along the fixed body's normal after the sweep, `lifts`), and the contact is solved
                // after the sweep with the body's others (`Held`).
                if body.is_dynamic() && ri > 0.0 {
                    let nf = {
                        let b: &Bodies = bodies;
                        backing(b, p, ri, normal)
                    };
                    if let Some(nf) = nf {
                        let q = c - p;
                        let (qn, qt) = (q.dot(nf), (q - nf * q.dot(nf)).length());
                        if qt < ri {
                            let lift = (ri * ri - qt * qt).sqrt() - qn;
                            if lift > self.lifts[k].0 {
                                self.lifts[k] = (lift, nf);
                            }
                        }
                        self.held.push(Held { i, k, c, nf, mu, jn: 0.0 });
                        continue;
                    }
                }
                let body = &mut bodies.d.r.bodies[h];
                let vn = (vi - vb).dot(normal);
                // The particle goes back to the surface (plus its radius) along the normal.
                moved.push((i, slot(state.x[i])));
                state.x[i] = to_p(p + normal * depth);
                if vn >= 0.0 {
                    continue;
                }
                // Effective mass of the pair along a direction t: 1/(1/m_i + the body's share).
                let k_n = pair_inv_mass(im, body, c, normal);
                let jn = -(1.0 + e) * vn / k_n;
                let vt_vec = (vi - vb) - normal * vn;
                let vt = vt_vec.length();
                let mut impulse = normal * jn;
                if vt > 0.0 && mu > 0.0 {
                    let t = vt_vec / vt;
                    let k_t = pair_inv_mass(im, body, c, t);
                    impulse -= t * (mu * jn).min(vt / k_t);
                }
                state.v[i] = to_p(vi + impulse * im);
                if body.is_dynamic() {
                    body.apply_impulse_at_point(-impulse, c, true);
                }
            }
        }
        // The bodies held up by particles: the normal impulses of each one's contacts (the fixed
        // body bears them through the particle, whose share of the effective mass is 0) found
        // together, by projected Gauss-Seidel sweeps (each contact's total kept ≥ 0), so that
        // no point of the body approaches the fixed one: a plate lying on a sheet rests (one
        // contact at a time, each stopping its own point, set it rocking, and the impulses
        // grew to 40 times its weight). Then Coulomb friction at each, with its normal impulse
        // J_n, between the particle and the body: the body slides on the sheet, dragged by
        // μ J_n each step while they slip, and carried along where the limit allows it.
        let held = &mut self.held;
        for _ in 0..HELD_SWEEPS {
            for hc in held.iter_mut() {
                let body = &mut bodies.d.r.bodies[bodies.handles[hc.k]];
                let u = -body.velocity_at_point(hc.c).dot(hc.nf);
                let next = (hc.jn + u / pair_inv_mass(0.0, body, hc.c, hc.nf)).max(0.0);
                if next != hc.jn {
                    body.apply_impulse_at_point(hc.nf * (next - hc.jn), hc.c, true);
                    hc.jn = next;
                }
            }
        }
        for hc in held.iter() {
            if hc.jn <= 0.0 || hc.mu <= 0.0 {
                continue;
            }
            let body = &mut bodies.d.r.bodies[bodies.handles[hc.k]];
            let im = model.inv_mass[hc.i];
            let vi = from_p(state.v[hc.i]);
            let rel = vi - body.velocity_at_point(hc.c);
            let vt_vec = rel - hc.nf * rel.dot(hc.nf);
            let vt = vt_vec.length();
            if vt > 0.0 {
                let t = vt_vec / vt;
                let jt = t * -(hc.mu * hc.jn).min(vt / pair_inv_mass(im, body, hc.c, t));
                state.v[hc.i] = to_p(vi + jt * im);
                body.apply_impulse_at_point(-jt, hc.c, true);
            }
        }
        // The bodies held up by particles, lifted off them (the most any of them asks) along the
        // fixed body's normal: the potential of gravity this raises is booked with the exchange.
        let mut lifted = 0.0;
        for (k, &(lift, nf)) in self.lifts.iter().enumerate() {
            if lift > 0.0 {
                let body = &mut bodies.d.r.bodies[bodies.handles[k]];
                lifted -= body.mass() * bodies.gravity.dot(nf * lift);
                body.set_translation(body.translation() + nf * lift, true);
            }
        }
        // Pinned particles: put on their point of the body, their velocity made the point's by
        // an impulse along the difference, applied to the body the other way.
        let Dynamic { r, pins, .. } = &mut bodies.d;
        for &(i, k, local) in pins.iter() {
            if i >= n || model.inv_mass[i] == 0.0 {
                continue;
            }
            let im = model.inv_mass[i];
            let body = &mut r.bodies[bodies.handles[k]];
            let c = body.position().transform_point(local);
            moved.push((i, slot(state.x[i])));
            state.x[i] = to_p(c);
            let vi = from_p(state.v[i]);
            let dv = body.velocity_at_point(c) - vi;
            let len = dv.length();
            if len == 0.0 {
                continue;
            }
            let u = dv / len;
            if body.is_dynamic() {
                let j = u * (len / pair_inv_mass(im, body, c, u));
                state.v[i] = to_p(vi + j * im);
                body.apply_impulse_at_point(-j, c, true);
            } else {
                state.v[i] = to_p(vi + dv);
            }
        }
        let e_after = particle_kinetic(&state.v, &model.mass, &model.inv_mass)
            + bodies.mechanical().0
            + spin_kinetic(spins.as_ref(), model, radius);
        // The potential the moves changed: evaluated after them, and before them with the old
        // positions put back for the moment (only when something moved); of the terms whose
        // potential is cheap to evaluate (gravity, springs, fields): an SPH fluid's or DEM
        // contacts' share would cost two neighbour searches a step, and is left to the drift.
        // Undone and redone by swaps: backwards, each record takes the position its move made
        // and gives back the one before; forwards, the reverse.
        let mut raised = 0.0;
        if !moved.is_empty() {
            let u_after = particles.cheap_potential_energy();
            let swap = |x: &mut V, rec: &mut [Real; 3]| {
                let here = slot(*x);
                *x = V::from_slice(rec);
                *rec = here;
            };
            let (state, _) = particles.state_model_mut();
            for (i, rec) in moved.iter_mut().rev() {
                swap(&mut state.x[*i], rec);
            }
            let u_before = particles.cheap_potential_energy();
            let (state, _) = particles.state_model_mut();
            for (i, rec) in moved.iter_mut() {
                swap(&mut state.x[*i], rec);
            }
            raised = u_after - u_before;
        }
        bodies.d.coupling += e_before - e_after - raised - lifted;
        if !moved.is_empty() {
            particles.state_changed();
        }
    }
}
