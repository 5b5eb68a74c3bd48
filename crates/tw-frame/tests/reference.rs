//! The frame pipeline against the reference (full detail, no culling) on a small plant, on GL
//! and Vulkan: frustum culling alone (τ = 0) gives the reference image exactly; the LOD cut at
//! 1 px stays close to it (PSNR); the exact visible set from the item buffer is consistent with
//! what a frame draws; the reference drawn in chunks under a small memory budget equals the one
//! drawn under a large budget.

use std::sync::Arc;

use tw_frame::{FrameSettings, Occlusion};
use tw_gpu::wgpu;
use tw_runtime::pathgen::{generate_path, PathOptions};
use tw_runtime::Camera;
use tw_store::Store;

mod common;

use common::gpu_lock;

fn store() -> Arc<Store> {
    common::plant(100_000, 5)
}

/// A few cameras of the default path (walk and fly-over).
fn cameras(store: &Store) -> Vec<Camera> {
    let path = generate_path(store, &PathOptions { frames: 60, ..Default::default() }, &mut |_, _, _| {})
        .unwrap()
        .path;
    path.frames.iter().step_by(12).map(|f| f.to_scene(store.header()).unwrap()).collect()
}

fn against_the_reference(backends: wgpu::Backends, what: &str) {
    let _lock = gpu_lock();
    let Some(mut w) = common::walkthrough(store(), backends, what, 256 << 20) else { return };
    let total_triangles = store().header().input_triangles;
    for (i, camera) in cameras(&store()).iter().enumerate() {
        let (reference, rinfo) = w.reference(camera).unwrap();
        assert_eq!(rinfo.triangles, total_triangles, "{what}: the reference draws every input triangle");
        assert!(reference.covered_pixels() > 0, "{what}: camera {i} sees nothing");

        let full = FrameSettings {
            tau: 0.0,
            occlusion: Occlusion::None,
            wait_for_pages: true,
            ..Default::default()
        };
        let (image, info) = w.frame(camera, &full).unwrap();
        assert_eq!(
            image.differing_pixels(&reference).unwrap(),
            0,
            "{what}: camera {i}: frustum culling at full detail changed the image"
        );
        assert!(info.triangles <= total_triangles);

        let lod = FrameSettings { tau: 1.0, ..full };
        let (image, lod_info) = w.frame(camera, &lod).unwrap();
        let psnr = image.psnr(&reference).unwrap();
        eprintln!(
            "{what}: camera {i}: τ=1 draws {} of {} triangles, PSNR {psnr:.1} dB, {:.2} % pixels differ",
            lod_info.triangles,
            total_triangles,
            100.0 * image.differing_share(&reference).unwrap()
        );
        assert!(psnr >= 30.0, "{what}: camera {i}: PSNR {psnr:.1} dB at 1 px error");

        let exact = w.exact_visibility(camera).unwrap();
        assert!(exact.triangles > 0 && exact.objects > 0, "{what}: camera {i}: nothing visible");
        assert!(exact.triangles <= total_triangles);
        assert_eq!(exact.covered_pixels as usize, reference.covered_pixels(), "{what}: item buffer coverage");
        assert!(
            info.triangles >= exact.triangles,
            "{what}: camera {i}: the full-detail frame drew {} triangles but {} are visible",
            info.triangles,
            exact.triangles
        );
    }
}

fn reference_in_chunks(backends: wgpu::Backends, what: &str) {
    let _lock = gpu_lock();
    let cams = cameras(&store());
    let Some(mut large) = common::walkthrough(store(), backends, what, 256 << 20) else { return };
    let big: Vec<_> = cams.iter().map(|c| large.reference(c).unwrap().0).collect();
    drop(large);
    // A budget of a few pages: the reference is drawn in many chunks.
    let Some(mut small) = common::walkthrough(store(), backends, what, 1 << 20) else { return };
    for (i, c) in cams.iter().enumerate() {
        let (image, _) = small.reference(c).unwrap();
        assert_eq!(
            image.differing_pixels(&big[i]).unwrap(),
            0,
            "{what}: camera {i}: chunked reference differs"
        );
    }
}

#[test]
fn frames_match_the_reference_vulkan() {
    against_the_reference(wgpu::Backends::VULKAN, "vulkan");
}

#[test]
fn frames_match_the_reference_gl() {
    against_the_reference(wgpu::Backends::GL, "gl");
}

#[test]
fn reference_in_chunks_is_the_same_image_vulkan() {
    reference_in_chunks(wgpu::Backends::VULKAN, "vulkan");
}

#[test]
fn reference_in_chunks_is_the_same_image_gl() {
    reference_in_chunks(wgpu::Backends::GL, "gl");
}
