//! Shared by tw-frame's tests: a store built from a generated plant or CAD assembly, one GPU
//! test at a time, and a walkthrough on a given backend (skipped without an adapter unless
//! `TERAWALK_REQUIRE_GPU=1`).

use std::sync::{Arc, Mutex};

use tw_frame::Walkthrough;
use tw_gpu::{wgpu, GpuError, Renderer};
use tw_runtime::StreamOptions;
use tw_store::Store;

pub const W: u32 = 480;
pub const H: u32 = 270;

/// How the stores of these tests are built, in `units` (empty when unknown).
fn options(units: &str) -> tw_build::BuildOptions {
    tw_build::BuildOptions { memory: 256 << 20, units: units.to_string(), ..Default::default() }
}

/// The generated plant of `triangles` with `seed`, built once per process (tw-testkit).
pub fn plant(triangles: u64, seed: u64) -> Arc<Store> {
    tw_testkit::plant(triangles, seed, options("")).store()
}

/// The generated CAD assembly (millimetres) of `triangles` with `seed` as one object, as
/// `terawalk generate assembly --one-object` writes it (thousands of small closed parts with
/// no ids), built once per process (tw-testkit).
#[allow(dead_code)] // Each test binary compiles this module; not every one builds an assembly.
pub fn assembly(triangles: u64, seed: u64) -> Arc<Store> {
    tw_testkit::assembly(triangles, seed, tw_io::generate::AssemblyObjects::One, options("mm")).store()
}

/// One GPU test at a time: software rasterizers use every core.
pub fn gpu_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// A `W`×`H` walkthrough of `store` on `backends` with a page budget, or `None` (skipped).
pub fn walkthrough(
    store: Arc<Store>,
    backends: wgpu::Backends,
    what: &str,
    budget: u64,
) -> Option<Walkthrough> {
    let renderer = match Renderer::new_headless_with(W, H, backends) {
        Ok(r) => r,
        Err(e @ GpuError::NoAdapter { .. })
            if std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1") =>
        {
            eprintln!("SKIPPED {what}: {e} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)");
            return None;
        }
        Err(e) => panic!("{what}: {e}"),
    };
    eprintln!("{what}: {}", renderer.adapter_summary());
    let stream = StreamOptions { budget_bytes: budget, ..Default::default() };
    Some(Walkthrough::new(store, renderer, stream).unwrap())
}
