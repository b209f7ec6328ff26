// One source for both dimensions (`include!`d by `dim2` and `dim3`, each with its rapier in scope).
// The fields, in this order, are the file format: rapier's sets, then the books, the parts and
// the pins, as the core's `Dynamic { r: Rapier { .. }, .. }` wrote them.

/// The state lent for a save.
#[derive(serde::Serialize)]
pub struct Saving<'a> {
    pub islands: &'a IslandManager,
    pub broad_phase: &'a BroadPhaseBvh,
    pub narrow_phase: &'a NarrowPhase,
    pub bodies: &'a RigidBodySet,
    pub colliders: &'a ColliderSet,
    pub impulse_joints: &'a ImpulseJointSet,
    pub multibody_joints: &'a MultibodyJointSet,
    pub soft_bodies: &'a SoftBodySet,
    pub contacts: f64,
    pub coupling: f64,
    pub parts: usize,
    pub pins: &'a [(usize, usize, Vector)],
}

/// The state a load read.
#[derive(serde::Deserialize)]
pub struct Loaded {
    pub islands: IslandManager,
    pub broad_phase: BroadPhaseBvh,
    pub narrow_phase: NarrowPhase,
    pub bodies: RigidBodySet,
    pub colliders: ColliderSet,
    pub impulse_joints: ImpulseJointSet,
    pub multibody_joints: MultibodyJointSet,
    pub soft_bodies: SoftBodySet,
    pub contacts: f64,
    pub coupling: f64,
    pub parts: usize,
    pub pins: Vec<(usize, usize, Vector)>,
}

/// The bytes `write` appends (nothing is allocated to count them).
pub fn size(s: &Saving) -> Result<u64, String> {
    bincode::serialized_size(s).map_err(|e| e.to_string())
}

/// Appends the state's bytes to `bytes` (reserve `size` first: the writes then allocate nothing).
pub fn write(bytes: &mut Vec<u8>, s: &Saving) -> Result<(), String> {
    bincode::serialize_into(bytes, s).map_err(|e| e.to_string())
}

/// The state from `write`'s bytes.
pub fn read(bytes: &[u8]) -> Result<Loaded, String> {
    bincode::deserialize(bytes).map_err(|e| e.to_string())
}

/// A shape's bytes (to compare two shapes field for field), or `None` if it cannot be written.
pub fn shape_bytes(shape: &SharedShape) -> Option<Vec<u8>> {
    bincode::serialize(shape).ok()
}
