//! Sections (tw_runtime::section) through the frame pipeline: with a section box keeping about
//! a quarter of a generated plant and a plane through it, every occlusion strategy gives the
//! image of `--occlusion none` with the same section, pixel for pixel but for depth ties between
//! a revealed back face and a coincident front face, whose winner is the draw order (the depth
//! the occlusion tests read holds only what is drawn: the renderer clips every pass), the
//! selection culls by
//! the section (counted), and the section changes the image (so the comparison is not
//! trivially true). On Vulkan (lavapipe); skipped without an adapter unless
//! `TERAWALK_REQUIRE_GPU=1`.

use std::sync::Arc;

use tw_frame::{FrameSettings, Occlusion};
use tw_gpu::wgpu;
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::{Camera, Section, SectionBox, SectionPlane};
use tw_store::Store;

mod common;

use common::gpu_lock;

/// The plant's fly-over, every fourth frame of 24: views of the whole scene and its parts.
fn fly_cameras(store: &Store) -> Vec<Camera> {
    let options = PathOptions { frames: 24, part: PathPart::Fly, seed: 2, ..Default::default() };
    let path = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path;
    path.frames.iter().step_by(4).map(|f| f.to_scene(store.header()).unwrap()).collect()
}

/// The lower-left half of the scene's box on x and y (all of z): about a quarter of it, and a
/// plane at 40% of the height keeping what is below it (in input coordinates).
fn quarter_section(store: &Store) -> Section {
    let h = store.header();
    let (lo, hi) = (h.bounds_min, h.bounds_max);
    let mid = |i: usize| lo[i] + 0.5 * (hi[i] - lo[i]);
    let boxed = SectionBox { min: lo, max: [mid(0), mid(1), hi[2]] };
    let z = lo[2] + 0.4 * (hi[2] - lo[2]);
    let plane = SectionPlane { normal: [0.0, 0.0, -1.0], offset: -z };
    Section::to_scene(&[plane], Some(boxed), h.grid_origin).unwrap()
}

/// tw_core::color::SECTION: the back faces a section reveals.
const SECTION_COLOR: [u8; 3] = [200, 30, 60];

fn settings(occlusion: Occlusion, section: Section) -> FrameSettings {
    FrameSettings { tau: 1.0, occlusion, wait_for_pages: true, section, ..Default::default() }
}

#[test]
fn every_occlusion_strategy_gives_nones_image_with_a_section() {
    let store: Arc<Store> = common::plant(200_000, 3);
    let cameras = fly_cameras(&store);
    let section = quarter_section(&store);
    let _lock = gpu_lock();
    let Some(mut w) = common::walkthrough(store.clone(), wgpu::Backends::VULKAN, "section", 256 << 20) else {
        return;
    };
    let (mut baseline, mut changed, mut culled) = (Vec::new(), 0, 0);
    for c in &cameras {
        let whole = w.frame(c, &settings(Occlusion::None, Section::default())).unwrap().0;
        let (image, info) = w.frame(c, &settings(Occlusion::None, section)).unwrap();
        changed += (image.rgba != whole.rgba) as usize;
        culled += info.select.nodes_culled_section
            + info.select.groups_culled_section
            + info.select.clusters_culled_section;
        baseline.push(image);
    }
    assert_eq!(changed, cameras.len(), "the section changes every view");
    assert!(culled > 0, "the selection culls by the section");
    for strategy in [Occlusion::Hzb, Occlusion::Queries, Occlusion::GpuHzb] {
        w.reset();
        let mut occluded = 0;
        for (i, c) in cameras.iter().enumerate() {
            let (image, info) = w.frame(c, &settings(strategy, section)).unwrap();
            occluded += info.occlusion.culled;
            let diff: Vec<(&[u8], &[u8])> =
                image.rgba.chunks(4).zip(baseline[i].rgba.chunks(4)).filter(|(a, b)| a != b).collect();
            // A revealed back face and another object's front face at the same depth: the
            // first drawn wins, and culling changes the order (without a section both show
            // one material colour). Every other pixel is none's.
            let tie = |p: &[u8]| p[..3] == SECTION_COLOR;
            let other = diff.iter().filter(|(a, b)| !tie(a) && !tie(b)).count();
            assert_eq!(other, 0, "{strategy:?}, frame {i}: pixels differ from none's: {diff:?}");
            assert!(diff.len() * 1000 < image.rgba.len() / 4, "{strategy:?}, frame {i}: {} ties", diff.len());
        }
        eprintln!("{strategy:?}: {occluded} clusters occluded over {} frames", cameras.len());
    }
}
