//! physcore's Rust core: particle state, force terms, integrators, colliders and energy books,
//! written once for 2D and 3D over glam's `DVec2`/`DVec3`. Plain Rust; the Python bindings live
//! in `python/` behind the `python` feature.
pub mod alloc;
pub mod boundary;
pub mod error;
pub mod grid;
pub mod integrators;
pub mod par;
pub mod simd;
pub mod simulation;
pub mod sph;
pub mod state;
pub mod stop;
pub mod terms;
pub mod vector;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, Result};
pub use simulation::{Checkpoint, EnergyReport, Simulation};
