//! The core's integration tests, one binary: each test file was its own binary before, and each
//! compiled the generic core again at opt-level 3 (about a minute of CI's build per file).
mod common;
mod integrators;
mod interrupt;
mod physics;
mod world;
