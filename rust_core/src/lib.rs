//! physcore's Rust core: particle state, force terms, integrators, colliders and energy books,
//! written once for 2D and 3D over glam's `DVec2`/`DVec3`. Plain Rust; the Python bindings live
//! in `python/` behind the `python` feature.

// Two lints the numerics disagree with, allowed for the whole crate on purpose:
// - `!(x > 0.0)` is the NaN-catching test (a NaN fails every comparison); `partial_cmp` would
//   hide that intent rather than show it.
// - Tableaux and kernels index several arrays by one loop index (`c[k]`, `a[i][k]`, `b[k]`), as
//   the papers write them; an iterator over one of them would make the others look different.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]
pub mod alloc;
pub mod boundary;
pub mod error;
pub mod integrators;
pub mod neighbors;
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
