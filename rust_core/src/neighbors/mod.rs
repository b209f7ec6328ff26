//! The neighbour search of the core, shared by every part that needs "all points within r": a
//! cell list (Allen & Tildesley, *Computer Simulation of Liquids*, 1987, "cell structures and
//! linked lists"), with the linked lists replaced by a counting sort so that each cell's points
//! are one contiguous run.
//!
//! What it offers:
//! - [`CellList`] (`cell_list`): points counting-sorted into cells of side r (dense or hashed
//!   numbering, unbounded domain), rebuilt in parallel, with a stable order for any thread count;
//!   [`CellList::query`] gives the candidate [`Ranges`] (at most [`MAX_RANGES`] contiguous runs of
//!   the sorted order) around a cell, to be filtered by distance by the caller.
//! - [`neighbor_pairs`] (`pairs`): every pair i < j closer than r, as two sorted index arrays.
//! - [`Shared`] (`shared`): the registry through which the terms of one particle system that
//!   need neighbours within the same radius find each other and share one search.
//!
//! Who uses it: the SPH force terms (`crate::sph`): all fluids of a system with the same support,
//! kernel and precision share one cell list, rebuilt once per evaluation over all their particles
//! (so they push on each other), plus one cell list per fluid for its static wall particles, and
//! walk the candidate runs in their SIMD passes. The Python function `physcore.neighbors` is
//! [`neighbor_pairs`].
mod cell_list;
mod pairs;
mod shared;

pub use cell_list::{CellList, Ranges, MAX_RANGES};
pub use pairs::neighbor_pairs;
pub use shared::Shared;
