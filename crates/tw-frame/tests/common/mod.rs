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

/// A built store; the directory lives as long as the store is used.
pub struct Built {
    _dir: tempfile::TempDir,
    pub store: Arc<Store>,
}

/// Generates a plant of `triangles` with `seed` and builds it.
pub fn build_plant(triangles: u64, seed: u64) -> Built {
    let params = tw_io::generate::PlantParams { triangles, seed };
    let source = tw_io::generate::PlantSource::new(params).unwrap();
    build(Box::new(source), "")
}

/// Generates a CAD assembly (millimetres) of `triangles` with `seed` as one object, as
/// `terawalk generate assembly --one-object` writes it (thousands of small closed parts with
/// no ids), and builds it.
#[allow(dead_code)] // Each test binary compiles this module; not every one builds an assembly.
pub fn build_assembly(triangles: u64, seed: u64) -> Built {
    use tw_io::generate::{AssemblyObjects, AssemblyParams, AssemblySource};
    let params = AssemblyParams { triangles, seed, objects: AssemblyObjects::One };
    let source = AssemblySource::new(params).unwrap();
    build(Box::new(source), "mm")
}

/// Builds `source` (in `units`, empty when unknown) into a store in a temporary directory.
fn build(source: Box<dyn tw_io::TriangleSource>, units: &str) -> Built {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.tw");
    let scene = tw_io::Scene::from_sources(vec![source]);
    let options =
        tw_build::BuildOptions { memory: 256 << 20, units: units.to_string(), ..Default::default() };
    tw_build::build(scene, &path, &options, &mut tw_build::NoProgress).unwrap();
    Built { store: Arc::new(Store::open(&path).unwrap()), _dir: dir }
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
