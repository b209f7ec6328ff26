//! The core's tests through its public API only (`physcore_core::...`, as a user crate sees it).
//! They were an integration-test binary (`tests/core`), and before that one binary per file, each
//! compiling the generic core again. Compiled into the library's own test harness instead, the
//! test build no longer compiles the whole crate a second time as a plain library beside it
//! (issue 67: on CI's 2 cores the two builds of the crate were 5.5 of the test build's 7.7 min,
//! each on one core).
mod common;
mod integrators;
mod interrupt;
mod physics;
mod world;
