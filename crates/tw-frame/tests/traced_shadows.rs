//! Ray-traced shadows through [`TracedWalkthrough`]: shadow rays meet the casters outside the
//! eye's frustum. On a walk through a generated plant under a low sun, the frame's cut (the
//! eye's LOD over the store, cut down to the light's sweep of the view) gives the shadow mask of
//! the whole eye-LOD cut pixel for pixel, while the eye's frustum-culled cut alone misses shadows;
//! primary rays see the same in all three. No GPU needed.

use std::sync::Arc;

use tw_core::color::{ColorMode, SHADOW_BLOCKED, SHADOW_LIT};
use tw_frame::mask::compare_shadow_masks;
use tw_frame::traced::TracedWalkthrough;
use tw_frame::FrameSettings;
use tw_rt::scene::{StoreTracer, TraceSettings};
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::{Camera, InputLight, SelectOptions, SelectionPages, StreamOptions};
use tw_store::Store;

// Shared with the GPU tests, whose walkthrough helpers this one does not use.
#[allow(dead_code)]
mod common;

use common::{H, W};

fn plant() -> Arc<Store> {
    common::plant(200_000, 3)
}

fn walk_cameras(store: &Store) -> Vec<Camera> {
    let options = PathOptions { frames: 40, part: PathPart::Walk, seed: 2, ..Default::default() };
    let path = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path;
    path.frames.iter().step_by(8).map(|f| f.to_scene(store.header()).unwrap()).collect()
}

#[test]
fn shadow_rays_meet_casters_outside_the_view() {
    let store = plant();
    let cameras = walk_cameras(&store);
    let header = store.header();
    // Low suns from two sides: from one, roofs behind the eye shade the view; from the other,
    // the light's sweep leaves out much of the whole cut.
    let (mut missed, mut dropped, mut blocked) = (0, 0, 0);
    for azimuth_deg in [270.0, 180.0] {
        let input = InputLight::Sun { azimuth_deg, elevation_deg: 25.0 };
        let light = input.to_scene(header, header.up_axis, &cameras[0]);
        let settings =
            TraceSettings { coloring: ColorMode::Shadow, light: Some(light), ..Default::default() };
        let walk =
            || TracedWalkthrough::new(store.clone(), (W, H), StreamOptions::default(), settings).unwrap();
        let (mut casters, mut whole) = (walk(), walk());
        let mut eye_tracer = StoreTracer::new(&store, 256 << 20);
        for (i, camera) in cameras.iter().enumerate() {
            let culled = FrameSettings { wait_for_pages: true, ..Default::default() };
            let (image, _, traced) = casters.frame(camera, &culled).unwrap();
            let (reference, _, traced_whole) =
                whole.frame(camera, &FrameSettings { frustum_culling: false, ..culled }).unwrap();
            assert!(
                image.rgba == reference.rgba,
                "{input:?}, frame {i}: the casters' cut shadows otherwise than the whole cut"
            );
            assert_eq!((&traced.objects, &traced.distance), (&traced_whole.objects, &traced_whole.distance));
            dropped += whole.selection().clusters.len() - casters.selection().clusters.len();
            blocked += image.rgba.chunks_exact(4).filter(|p| *p == SHADOW_BLOCKED).count();

            // The eye's own cut: the same surfaces, no more shadows.
            let options =
                SelectOptions { tau: 1.0, viewport: [W, H], frustum_culling: true, ..Default::default() };
            let selection = casters.streamer().select_blocking(camera, &options);
            let pages = SelectionPages::resolve(&store, casters.streamer().cache(), &selection.clusters);
            let eye_only = eye_tracer.trace(&pages, camera, (W, H), &settings);
            assert_eq!(
                eye_only.objects, traced.objects,
                "{input:?}, frame {i}: the light's cut changed what the eye sees"
            );
            let a = compare_shadow_masks(&image.rgba, &eye_only.rgba, W, H, 0).unwrap();
            assert_eq!(a.lit_as_blocked, 0, "{input:?}, frame {i}: more casters cannot lighten a pixel");
            missed += a.blocked_as_lit;
            assert!(image.rgba.chunks_exact(4).any(|p| p == SHADOW_LIT), "{input:?}, frame {i}: nothing lit");
        }
    }
    assert!(blocked > 1000, "too few shadowed pixels ({blocked}) for the test to mean anything");
    assert!(
        missed > 1000,
        "the eye's cut alone missed {missed} shadowed pixels: casters outside the view are not exercised"
    );
    assert!(dropped > 0, "the light's sweep dropped no cluster of the whole cut");
}
