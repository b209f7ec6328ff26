//! physcore's Rust core, written once for 2D and 3D over glam's `DVec2`/`DVec3`. Plain Rust; the
//! Python bindings live in `python/` behind the `python` feature.
//!
//! A [`World`] steps one or more systems (`systems`) with one clock, thread pool and rollback.
//! The particle system holds the particle state and model (`state`), force terms (`terms`,
//! `sph`), an integrator (`integrators`, with tableaux from `ode`) and the projection stage
//! (`constraints`: colliders over the shapes of `geometry`). Fields on grids (`grids`: waves,
//! reaction–diffusion, a grid fluid) are further systems. Shared services: the neighbour search (`neighbors`), the SIMD layer
//! (`simd`), deterministic parallel loops (`par`), fallible allocation (`alloc`), the stop flag
//! (`stop`) and typed errors (`error`). Outside the physics, `raster` draws the renderer's
//! shaded triangle meshes (per pixel, per frame: too slow in numpy).

// Two lints the numerics disagree with, allowed for the whole crate on purpose:
// - `!(x > 0.0)` is the NaN-catching test (a NaN fails every comparison); `partial_cmp` would
//   hide that intent rather than show it.
// - Tableaux and kernels index several arrays by one loop index (`c[k]`, `a[i][k]`, `b[k]`), as
//   the papers write them; an iterator over one of them would make the others look different.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]
pub mod alloc;
pub mod batch;
pub mod constraints;
pub mod error;
pub mod geometry;
pub mod grids;
pub mod integrators;
pub mod neighbors;
pub mod ode;
pub mod par;
pub mod raster;
pub mod simd;
pub mod sph;
pub mod state;
pub mod stop;
pub mod systems;
pub mod terms;
#[cfg(test)]
mod trait_sizes;
// The public-API tests (src/integration_tests) name the crate as a user does.
#[cfg(test)]
extern crate self as physcore_core;
#[cfg(test)]
mod integration_tests;
pub mod vector;
pub mod world;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, Result};
pub use systems::particles::ParticleSystem;
pub use systems::EnergyReport;
pub use world::{Checkpoint, World};
