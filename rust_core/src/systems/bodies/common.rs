// The rigid-body system written once for both dimensions: `include!`d by `dim2.rs` (rapier2d-f64)
// and `dim3.rs` (rapier3d-f64), each of which first brings its rapier into scope and defines the
// few things that differ (vectors from slices, rotations, shapes, fields, the angular term of an
// effective mass). rapier's 2D and 3D crates are separate crates with separate types, so a
// generic would need a trait over all of rapier; the two inclusions are what parry and rapier
// themselves do (one source, built per dimension). Formatted with `rustfmt` on this file.

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
    /// Particles pinned to bodies: (particle, body, the point in the body's frame).
    pins: Vec<(usize, usize, Vector)>,
}

/// The rigid bodies of a world.
pub struct Bodies {
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

impl Bodies {
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
                pins: Vec::new(),
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
        if !["dynamic", "fixed", "kinematic"].contains(&kind.as_str()) {
            return Err(invalid("kind", format!("unknown body kind {kind:?}; valid: dynamic, fixed, kinematic")));
        }
        let n = p.count("n", 1 << 24)?;
        if n == 0 {
            return Err(invalid("n", "a group needs at least one body"));
        }
        let x = take_len(&mut p, "positions", D * n)?;
        let rotations = take_len(&mut p, ROTATION_KEY, ROT * n)?;
        let rot: Vec<Rotation> = rotations.chunks_exact(ROT).map(rotation).collect::<Result<_>>()?;
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
        // The group's one shape given by vertices (a convex polygon or hull, a triangle mesh).
        let listed = listed_shape(&shape, &kind, &mut p)?;
        let builder = |i: usize| -> RigidBodyBuilder {
            let b = match kind.as_str() {
                "fixed" => RigidBodyBuilder::fixed(),
                "kinematic" => RigidBodyBuilder::kinematic_velocity_based(),
                _ => RigidBodyBuilder::dynamic(),
            };
            b.pose(Pose::from_parts(vector(&x[D * i..D * (i + 1)]), rot[i]))
                .linvel(vector(&v[D * i..D * (i + 1)]))
                .angvel(ang_vector(&omega[ANG * i..ANG * (i + 1)]))
                // Sleeping freezes a body bit for bit at rest: deterministic, and a pile at rest
                // costs nothing, but a body asleep is not woken by particles (see BodyContacts).
                .can_sleep(false)
        };
        let first = self.handles.len();
        for i in 0..n {
            let c = match &listed {
                Some(c) => c.clone(),
                None => sized_shape(&shape, &size[per * i..per * (i + 1)]),
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
        }
        self.part_added();
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
    fn set_gravity(&mut self, g: [Real; 3]) {
        self.gravity = vector(&g[..D]);
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
                Ok((0..self.handles.len()).map(|i| get_one(self.body(i), name)).collect())
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
    fn as_any_bodies(&mut self) -> Option<&mut dyn std::any::Any> {
        Some(self)
    }
}

/// Particles against the bodies, both ways: a particle (its `radius` attribute, else a point)
/// inside or touching a body's shape is put back on its surface, and the impulse that stops
/// its approach (the body's restitution, Coulomb friction with the body's coefficient) is
/// applied to both, equal and opposite, at the contact point: grains push bodies, a body pushes
/// grains, cloth drapes over a body, fluid particles hold a body up. Particles are visited in
/// order (the bodies' velocities change as they go): deterministic. The energy this removes
/// (kinetic, and the particles' potential in gravity raised by the moves) is booked in the
/// bodies' "bodies ⇄ particles".
pub struct BodyContacts {
    system: usize,
    /// Working buffers kept between steps: each body's grown box, and every move of the step
    /// (the particle and, in turn, its position before and after: see `apply`).
    boxes: Vec<Aabb>,
    moved: Vec<(usize, [Real; 3])>,
}

impl BodyContacts {
    /// The coupling of the particles with the bodies system `others[system]` of the world.
    pub fn new(system: usize) -> Self {
        Self { system, boxes: Vec::new(), moved: Vec::new() }
    }
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

impl<V: PVector> Coupling<V> for BodyContacts {
    fn name(&self) -> &str {
        "bodies ⇄ particles"
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
        let Some(bodies) =
            others.get_mut(self.system).and_then(|s| s.as_any_bodies()).and_then(|a| a.downcast_mut::<Bodies>())
        else {
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
        let boxes = &mut self.boxes;
        boxes.clear();
        boxes.extend(bodies.colliders.iter().map(|&c| bodies.d.r.colliders[c].compute_aabb().loosened(r_max)));
        let e_before = particle_kinetic(&state.v, &model.mass, &model.inv_mass) + bodies.mechanical().0;
        // Every move: the particle and where it was (the potential energy the moves change
        // is booked with the exchange below).
        let moved = &mut self.moved;
        moved.clear();
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
                let vi = from_p(state.v[i]);
                let vb = body.velocity_at_point(c);
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
        let e_after = particle_kinetic(&state.v, &model.mass, &model.inv_mass) + bodies.mechanical().0;
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
        bodies.d.coupling += e_before - e_after - raised;
    }
}
