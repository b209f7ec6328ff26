//! The rigid bodies' state as bytes (bincode 1 over rapier's serde), one module per dimension.
//!
//! The core keeps the state in its own structs; to save, it lends their fields as a [`dim3::Saving`]
//! (references: nothing is copied), and a load gives back a [`dim3::Loaded`] (owned) to move into
//! them. bincode writes a struct as its fields in order, so the bytes are those the core's own
//! nested structs wrote before this crate existed: files saved then load unchanged.

pub mod dim2 {
    use rapier2d_f64::prelude::*;
    include!("common.rs");
}

pub mod dim3 {
    use rapier3d_f64::prelude::*;
    include!("common.rs");
}
