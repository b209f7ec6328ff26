//! The extension module `physcore._core`, linked from physcore-core's bindings (its `python`
//! feature, `src/python`). See this crate's Cargo.toml for why it is a crate of its own.

// Links the core: its `PyInit__core` (pyo3's `#[pymodule]`) is the module's entry point.
extern crate physcore_core;
