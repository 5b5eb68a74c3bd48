//! Occlusion culling is conservative (DESIGN "Measuring"): with the same LOD cut, every strategy
//! gives the image of `--occlusion none`, pixel for pixel, on a walk through a generated plant's
//! interior (smooth camera motion) and on camera teleports (the two-pass scheme draws the newly
//! visible clusters in the same frame). Each strategy must also cull something on the walk, so
//! the comparison is not trivially true. On GL (llvmpipe) and Vulkan (lavapipe); without an
//! adapter the tests are skipped unless `TERAWALK_REQUIRE_GPU=1` (CI), where they fail.

use std::sync::{Arc, OnceLock};

use tw_frame::{FrameSettings, Occlusion};
use tw_gpu::wgpu;
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::Camera;
use tw_store::Store;

mod common;

use common::{gpu_lock, Built};

fn store() -> Arc<Store> {
    static STORE: OnceLock<Built> = OnceLock::new();
    STORE.get_or_init(|| common::build_plant(200_000, 3)).store.clone()
}

/// A walk at eye height inside the plant (smooth), every third frame of 72.
fn walk_cameras(store: &Store) -> Vec<Camera> {
    let options = PathOptions { frames: 72, part: PathPart::Walk, seed: 2, ..Default::default() };
    let path = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path;
    path.frames.iter().step_by(3).map(|f| f.to_scene(store.header()).unwrap()).collect()
}

/// Renders `cameras` with each strategy (the same cut: pages loaded before drawing) and checks
/// every image against `none`. Returns the clusters each strategy culled in all.
fn compare(backends: wgpu::Backends, what: &str, cameras: &[Camera]) -> Option<Vec<(Occlusion, u64)>> {
    let _lock = gpu_lock();
    let mut baseline = Vec::new();
    let mut w = common::walkthrough(store(), backends, what, 256 << 20)?;
    for c in cameras {
        let s = FrameSettings {
            tau: 1.0,
            occlusion: Occlusion::None,
            wait_for_pages: true,
            ..Default::default()
        };
        baseline.push(w.frame(c, &s).unwrap().0);
    }
    let mut culled = Vec::new();
    for strategy in [Occlusion::Hzb, Occlusion::Queries, Occlusion::GpuHzb] {
        w.reset();
        let mut total = 0;
        for (i, c) in cameras.iter().enumerate() {
            let s =
                FrameSettings { tau: 1.0, occlusion: strategy, wait_for_pages: true, ..Default::default() };
            let (image, info) = w.frame(c, &s).unwrap();
            let differing = image.differing_pixels(&baseline[i]).unwrap();
            assert_eq!(
                differing,
                0,
                "{what}, {}: frame {i} differs from --occlusion none in {differing} pixels",
                strategy.name()
            );
            assert!(image.covered_pixels() > 0, "{what}: frame {i} is empty");
            total += info.occlusion.culled;
        }
        culled.push((strategy, total));
    }
    Some(culled)
}

fn conservative_on_a_walk(backends: wgpu::Backends, what: &str) {
    let cameras = walk_cameras(&store());
    let Some(culled) = compare(backends, what, &cameras) else { return };
    for (strategy, n) in culled {
        eprintln!("{what}, {}: {n} clusters culled over {} frames", strategy.name(), cameras.len());
        assert!(n > 0, "{what}, {}: culled nothing inside the plant", strategy.name());
    }
}

fn conservative_on_teleports(backends: wgpu::Backends, what: &str) {
    // Jumps between far-apart walk cameras: last frame's visible set is useless as occluders.
    let walk = walk_cameras(&store());
    let cameras: Vec<Camera> = (0..8).map(|i| walk[(i * 7) % walk.len()]).collect();
    compare(backends, what, &cameras);
}

#[test]
fn occlusion_is_conservative_on_a_walk_vulkan() {
    conservative_on_a_walk(wgpu::Backends::VULKAN, "vulkan");
}

#[test]
fn occlusion_is_conservative_on_a_walk_gl() {
    conservative_on_a_walk(wgpu::Backends::GL, "gl");
}

#[test]
fn occlusion_is_conservative_on_teleports_vulkan() {
    conservative_on_teleports(wgpu::Backends::VULKAN, "vulkan");
}

#[test]
fn occlusion_is_conservative_on_teleports_gl() {
    conservative_on_teleports(wgpu::Backends::GL, "gl");
}
