//! The popping measurement (`bench --popping`, tw-frame's `popping` module): a still camera's cut
//! does not change, so neither does its image; along a fly-over the cut does change, and the
//! measurement sees it. Vulkan (lavapipe); skipped without an adapter unless
//! `TERAWALK_REQUIRE_GPU=1`.

use std::sync::Arc;

use tw_frame::FrameSettings;
use tw_gpu::wgpu;
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};

mod common;

use common::gpu_lock;

#[test]
fn popping_is_zero_for_a_still_camera_and_seen_along_a_path() {
    let store: Arc<tw_store::Store> = common::plant(150_000, 7);
    let _lock = gpu_lock();
    let Some(mut walk) = common::walkthrough(store.clone(), wgpu::Backends::VULKAN, "popping", 256 << 20)
    else {
        return;
    };
    let options = PathOptions { frames: 60, part: PathPart::Fly, seed: 4, ..Default::default() };
    let path = generate_path(&store, &options, &mut |_, _, _| {}).unwrap().path;
    let cameras: Vec<_> = path.frames.iter().map(|f| f.to_scene(store.header()).unwrap()).collect();
    let settings = FrameSettings { wait_for_pages: true, ..Default::default() };

    walk.frame(&cameras[0], &settings).unwrap();
    let previous = walk.drawn_state();
    walk.frame(&cameras[0], &settings).unwrap();
    let still = walk.lod_change(&cameras[0], &previous).unwrap();
    assert_eq!(still.changed_pixels, 0.0, "{still:?}");
    assert_eq!(still.psnr_db, None);

    let mut changed_frames = 0;
    for pair in cameras.windows(2) {
        walk.frame(&pair[0], &settings).unwrap();
        let previous = walk.drawn_state();
        walk.frame(&pair[1], &settings).unwrap();
        let change = walk.lod_change(&pair[1], &previous).unwrap();
        assert!((0.0..=1.0).contains(&change.changed_pixels));
        if walk.selection().clusters != previous.clusters {
            changed_frames += 1;
        } else {
            assert_eq!(change.changed_pixels, 0.0, "the same cut drew a different image");
        }
    }
    assert!(changed_frames > 0, "the cut never changed along a fly-over");
}
