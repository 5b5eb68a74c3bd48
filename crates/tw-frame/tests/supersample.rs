//! The supersampled reference (`bench --reference-samples`, tw-frame's `supersample` module) on a
//! small plant, Vulkan (lavapipe); skipped without an adapter unless `TERAWALK_REQUIRE_GPU=1`:
//! a 1 × 1 grid is the 1-sample reference itself; a 4 × 4 grid is a different, smoother image
//! that both the brute-force and the LOD frame can be measured against; the renderer's samples
//! per pixel survive it; a grid beyond the largest texture is a clear error.

use std::sync::Arc;

use tw_frame::{FrameSettings, Walkthrough};
use tw_gpu::{wgpu, Image, Renderer};
use tw_runtime::pathgen::{generate_path, PathOptions};
use tw_runtime::StreamOptions;

mod common;

use common::gpu_lock;

/// Pixels whose opaque colour differs from a neighbour's by more than 48 in some channel: the
/// hard edges aliasing leaves, which a supersampled image softens.
fn hard_edges(image: &Image) -> usize {
    let (w, h, px) = (image.width as usize, image.height as usize, image.opaque());
    let at = |x: usize, y: usize| &px[(y * w + x) * 4..(y * w + x) * 4 + 3];
    let far = |a: &[u8], b: &[u8]| a.iter().zip(b).any(|(p, q)| p.abs_diff(*q) > 48);
    (0..h - 1)
        .flat_map(|y| (0..w - 1).map(move |x| (x, y)))
        .filter(|&(x, y)| far(at(x, y), at(x + 1, y)) || far(at(x, y), at(x, y + 1)))
        .count()
}

#[test]
fn supersampled_reference_is_the_reference_at_one_sample_and_smoother_at_sixteen() {
    let store: Arc<tw_store::Store> = common::plant(100_000, 5);
    let _lock = gpu_lock();
    let Some(mut walk) = common::walkthrough(store.clone(), wgpu::Backends::VULKAN, "supersample", 256 << 20)
    else {
        return;
    };
    let path = generate_path(&store, &PathOptions { frames: 30, ..Default::default() }, &mut |_, _, _| {})
        .unwrap()
        .path;
    let camera = path.frames[10].to_scene(store.header()).unwrap();

    let (brute, _) = walk.reference(&camera).unwrap();
    assert!(brute.covered_pixels() > 0, "the camera sees nothing");
    let one = walk.reference_supersampled(&camera, 1).unwrap();
    assert_eq!(one, brute.to_opaque(), "a 1 × 1 grid is the 1-sample reference");

    let truth = walk.reference_supersampled(&camera, 16).unwrap();
    assert_eq!((truth.width, truth.height), (common::W, common::H));
    assert!(truth.rgba.chunks_exact(4).all(|p| p[3] == 255), "opaque");
    let brute_psnr = brute.psnr(&truth).unwrap();
    assert!(brute_psnr.is_finite() && brute_psnr > 15.0, "brute force against the truth: {brute_psnr} dB");
    let (hard_truth, hard_brute) = (hard_edges(&truth), hard_edges(&brute));
    assert!(hard_truth < hard_brute, "supersampling softens edges: {hard_truth} vs {hard_brute} hard pixels");

    let lod = FrameSettings { tau: 1.0, wait_for_pages: true, ..Default::default() };
    let (image, _) = walk.frame(&camera, &lod).unwrap();
    let lod_psnr = image.psnr(&truth).unwrap();
    eprintln!(
        "LOD {lod_psnr:.2} dB, brute force {brute_psnr:.2} dB against 16 samples; hard edges {hard_truth} vs {hard_brute}"
    );
    assert!(lod_psnr.is_finite() && lod_psnr > 15.0, "{lod_psnr}");

    // The renderer's own samples per pixel are back after the 1-sample grid draw.
    walk.renderer_mut().set_samples(4).unwrap();
    let truth4 = walk.reference_supersampled(&camera, 16).unwrap();
    assert_eq!(walk.renderer().samples(), 4);
    assert_eq!(truth4, truth, "drawn at one sample a sub-pixel whatever the run's samples");
    let (again, _) = walk.reference(&camera).unwrap();
    assert_ne!(again, brute, "the 4-sample reference is multisampled again");
}

#[test]
fn a_grid_beyond_the_largest_texture_is_a_clear_error() {
    let store = common::plant(20_000, 3);
    let _lock = gpu_lock();
    let renderer = match Renderer::new_headless_with(4096, 16, wgpu::Backends::VULKAN) {
        Ok(r) => r,
        Err(e) if std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1") => {
            eprintln!("SKIPPED: {e}");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    let max = renderer.device().0.limits().max_texture_dimension_2d;
    let mut walk = Walkthrough::new(store.clone(), renderer, StreamOptions::default()).unwrap();
    let camera = generate_path(&store, &PathOptions { frames: 2, ..Default::default() }, &mut |_, _, _| {})
        .unwrap()
        .path
        .frames[0]
        .to_scene(store.header())
        .unwrap();
    if 4096 * 8 <= max {
        eprintln!("SKIPPED: this device's largest texture is {max}");
        return;
    }
    let e = walk.reference_supersampled(&camera, 64).unwrap_err().to_string();
    assert!(e.contains("32768×128") && e.contains(&format!("{max}×{max}")), "{e}");
    let e = walk.reference_supersampled(&camera, 9).unwrap_err().to_string();
    assert!(e.contains("[1, 4, 16, 64]"), "{e}");
    assert_eq!(walk.renderer().samples(), 1);
}
