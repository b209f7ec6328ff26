//! Colliders applied after each step. Their energy loss goes into the dissipation ledger.
pub mod plane;
pub use plane::Plane;
