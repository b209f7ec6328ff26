//! What the device tests share.
use physcore_gpu::Gpu;
use std::sync::Arc;

/// The adapter the tests run on: a GPU with `PHYSCORE_GPU_ALLOW_CPU=1` (which also admits
/// lavapipe), else lavapipe by name. None (a skip) where there is none, unless
/// `PHYSCORE_GPU_REQUIRED=1` (CI), which makes that a failure. Each test opens a device of its
/// own (`Gpu::open_own`): on lavapipe the tests' queues then run in parallel.
pub fn gpu() -> Option<Arc<Gpu>> {
    match Gpu::open_own(which()) {
        Ok(g) => Some(g),
        Err(e) => {
            if std::env::var("PHYSCORE_GPU_REQUIRED").as_deref() == Ok("1") {
                panic!("PHYSCORE_GPU_REQUIRED=1 but no adapter: {e}");
            }
            eprintln!("skipped: {e}");
            None
        }
    }
}

/// The adapter `gpu` opens, by name: "gpu" with `PHYSCORE_GPU_ALLOW_CPU=1`, else "gpu:lavapipe".
#[allow(dead_code)] // each test binary compiles this module; not every one names the adapter
pub fn which() -> &'static str {
    if physcore_gpu::cpu_allowed_by_env() {
        "gpu"
    } else {
        "gpu:lavapipe"
    }
}
