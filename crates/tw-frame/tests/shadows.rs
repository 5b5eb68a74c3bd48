//! Shadows through the frame pipeline (docs/RUNTIME.md "Shadows"; Govindaraju's thesis ch. 4):
//! - cross-culling is conservative: classifying receivers as fully lit or fully shadowed, so
//!   that they are drawn without shadow lookups, gives the image of looking every receiver up,
//!   pixel for pixel, with and without occlusion culling, for a sun and a point light;
//! - LOD consistency: every cluster drawn into the shadow map belongs to the eye's own LOD cut
//!   (frustum aside), so no surface is shadowed by a coarser copy of itself;
//! - the rasterized shadow mask agrees with the ray tracer's shadow rays away from shadow edges.
//!
//! Vulkan (lavapipe); without an adapter the tests are skipped unless `TERAWALK_REQUIRE_GPU=1`.

use std::collections::HashSet;
use std::sync::Arc;

use tw_frame::shadow::{scene_box, ShadowOptions};
use tw_frame::{FrameSettings, Occlusion, ShadowLod, ShadowSettings};
use tw_gpu::{wgpu, ColorMode};
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::shadow::LightLod;
use tw_runtime::{Camera, Light, SelectOptions};
use tw_store::Store;

mod common;

use common::{gpu_lock, H, W};

fn plant() -> Arc<Store> {
    common::plant(200_000, 5)
}

fn cameras(store: &Store, part: PathPart, frames: usize, step: usize) -> Vec<Camera> {
    let options = PathOptions { frames, part, seed: 3, ..Default::default() };
    let path = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path;
    path.frames.iter().step_by(step).map(|f| f.to_scene(store.header()).unwrap()).collect()
}

/// A point light a few metres above the first camera's eye, along its up.
fn lamp(camera: &Camera) -> Light {
    Light::Point { position: camera.eye + camera.up.normalize() * 3.0 }
}

fn settings(light: Light, cross_culling: bool, occlusion: Occlusion) -> FrameSettings {
    let options = ShadowOptions { size: 1024, ..Default::default() };
    FrameSettings {
        occlusion,
        wait_for_pages: true,
        shadows: Some(ShadowSettings { light, options, cross_culling, lod: Default::default() }),
        ..Default::default()
    }
}

#[test]
fn cross_culling_does_not_change_the_image() {
    let store = plant();
    let _lock = gpu_lock();
    let Some(mut walk) = common::walkthrough(store.clone(), wgpu::Backends::VULKAN, "shadows", 256 << 20)
    else {
        return;
    };
    let mut views = cameras(&store, PathPart::Walk, 40, 10);
    views.extend(cameras(&store, PathPart::Fly, 40, 20));
    let (mut classified, mut light_culled, mut refined) = (0, 0, 0);
    for (i, camera) in views.iter().enumerate() {
        for light in [Light::default_sun(camera), lamp(&views[0])] {
            for (mode, occlusion) in
                [(ColorMode::Material, Occlusion::None), (ColorMode::Shadow, Occlusion::Hzb)]
            {
                walk.set_color_mode(mode);
                walk.reset();
                // A first frame fills the eye's occlusion history and the light's (which
                // cross-culling uses to draw the layers occlusion culled from the light); the
                // same camera then keeps both, so the two frames compared fit the same layers.
                walk.frame(camera, &settings(light, true, occlusion)).unwrap();
                let (all, info_all) = walk.frame(camera, &settings(light, false, occlusion)).unwrap();
                let (culled, info) = walk.frame(camera, &settings(light, true, occlusion)).unwrap();
                assert_eq!(
                    walk.last_shadows().map(|s| s.layers.len()),
                    Some(info_all.shadow.layers as usize)
                );
                assert!(info.shadow.layers > 0, "frame {i} {light:?}: no shadow layers");
                assert_eq!(info_all.shadow.sets.receivers_lit + info_all.shadow.sets.receivers_shadowed, 0);
                classified += info.shadow.sets.receivers_lit + info.shadow.sets.receivers_shadowed;
                refined += info.shadow.refined_lit_triangles + info.shadow.refined_shadowed_triangles;
                light_culled += info.shadow.light_triangles - info.shadow.light_drawn_triangles;
                let differing = all.rgba.iter().zip(&culled.rgba).filter(|(a, b)| a != b).count();
                assert_eq!(
                    differing, 0,
                    "frame {i}, {light:?}, {mode:?}, {occlusion:?}: cross-culling changed the image"
                );
            }
        }
    }
    // Not a vacuous pass: cross-culling decided something on these views, also for triangles of
    // partly shadowed receivers (drawn in parts, the finer classes), and the light's occlusion
    // culling left something out.
    assert!(classified > 0, "no receiver was classified fully lit or fully shadowed");
    assert!(refined > 0, "no triangle of a partly shadowed receiver was classified lit or shadowed");
    assert!(light_culled > 0, "occlusion culling from the light never culled anything");
}

#[test]
fn shadow_maps_are_drawn_at_the_eyes_lod() {
    let store = plant();
    let _lock = gpu_lock();
    let Some(mut walk) = common::walkthrough(store.clone(), wgpu::Backends::VULKAN, "shadow lod", 256 << 20)
    else {
        return;
    };
    for camera in cameras(&store, PathPart::Walk, 30, 15) {
        let light = Light::default_sun(&camera);
        let options =
            SelectOptions { tau: 1.0, viewport: [W, H], frustum_culling: false, ..Default::default() };
        // The eye's cut without its frustum: every cluster the eye's LOD would draw anywhere.
        let eye: HashSet<_> =
            walk.streamer().select_blocking(&camera, &options).clusters.into_iter().collect();
        let (_, info) = walk.frame(&camera, &settings(light, true, Occlusion::None)).unwrap();
        assert!(info.shadow.sets.light_cut > 0);
        let shadows = walk.last_shadows().expect("the frame drew shadows").clone();
        for layer in &shadows.layers {
            let set = walk.streamer().select_light_blocking(
                &camera,
                &layer.view_proj,
                &SelectOptions { frustum_culling: true, ..options },
            );
            let foreign: Vec<_> = set.clusters.iter().filter(|c| !eye.contains(c)).collect();
            assert!(
                foreign.is_empty(),
                "{} clusters of a shadow layer are not in the eye's cut: {:?}",
                foreign.len(),
                &foreign[..foreign.len().min(5)]
            );
        }
    }
}

/// The policy "the finer of both" (Govindaraju's thesis §4.2.1, method 1): a light far from the
/// eye but near the geometry it lights refines that geometry beyond the eye's LOD, in both views
/// alike. With the light's metric of the frame's layers, every cluster a layer draws is in the
/// eye's cut of the same metric (frustum aside), and that cut has at least the eye-LOD cut's
/// triangles; the frames drawn under it select more triangles than under the eye's LOD.
#[test]
fn the_finer_of_both_lods_refines_for_the_light_in_both_views() {
    let store = plant();
    let _lock = gpu_lock();
    let Some(mut walk) = common::walkthrough(store.clone(), wgpu::Backends::VULKAN, "finer lod", 256 << 20)
    else {
        return;
    };
    let views = cameras(&store, PathPart::Walk, 30, 10);
    // The lamp above the walk's last eye; the eye at its first views, far from it.
    let light = lamp(views.last().expect("a walk"));
    let (mut eye_triangles, mut finer_triangles) = (0u64, 0u64);
    for camera in &views[..2] {
        let mut eye_lod = settings(light, true, Occlusion::None);
        walk.reset();
        let (_, eye_info) = walk.frame(camera, &eye_lod).unwrap();
        if let Some(s) = eye_lod.shadows.as_mut() {
            s.lod = ShadowLod::Finer;
        }
        let (_, finer_info) = walk.frame(camera, &eye_lod).unwrap();
        eye_triangles += eye_info.cut_triangles;
        finer_triangles += finer_info.cut_triangles;
        let shadows = walk.last_shadows().expect("the frame drew shadows").clone();
        let lod = LightLod::new(&shadows, camera, scene_box(store.header())).expect("layers");
        let options = SelectOptions {
            tau: 1.0,
            viewport: [W, H],
            frustum_culling: false,
            light_lod: Some(lod),
            ..Default::default()
        };
        let eye_only = SelectOptions { light_lod: None, ..options };
        let finer = walk.streamer().select_blocking(camera, &options);
        let coarser = walk.streamer().select_blocking(camera, &eye_only);
        assert!(finer.triangles >= coarser.triangles, "{} < {}", finer.triangles, coarser.triangles);
        let cut: HashSet<_> = finer.clusters.into_iter().collect();
        for layer in &shadows.layers {
            let set = walk.streamer().select_light_blocking(
                camera,
                &layer.view_proj,
                &SelectOptions { frustum_culling: true, ..options },
            );
            let foreign = set.clusters.iter().filter(|c| !cut.contains(c)).count();
            assert_eq!(foreign, 0, "clusters of a shadow layer not in the eye's cut of the same metric");
        }
    }
    eprintln!("cut triangles: eye LOD {eye_triangles}, finer of both {finer_triangles}");
    assert!(
        finer_triangles > eye_triangles,
        "the light near far geometry refines nothing: {finer_triangles} against {eye_triangles}"
    );
}

/// Reusing layers (docs/RUNTIME.md "Shadows", "Reusing layers"): along a walk of small steps most
/// layers serve again, and the shadow mask drawn with them agrees with the one of layers fitted
/// and drawn afresh for every frame, away from shadow edges (a reused layer's texels are up to
/// √2 wider, so edges may move by a texel). With a still camera every layer is reused and the
/// image is the fresh frame's, pixel for pixel.
#[test]
fn reused_layers_give_the_shadows_of_fresh_ones() {
    let store = plant();
    let _lock = gpu_lock();
    let new = |what| common::walkthrough(store.clone(), wgpu::Backends::VULKAN, what, 256 << 20);
    let (Some(mut reusing), Some(mut fresh)) = (new("reused layers"), new("fresh layers")) else {
        return;
    };
    reusing.set_color_mode(ColorMode::Shadow);
    fresh.set_color_mode(ColorMode::Shadow);
    let views = cameras(&store, PathPart::Walk, 24, 1);
    let light = Light::default_sun(&views[0]);
    let settings = settings(light, true, Occlusion::Hzb);
    let (mut reused, mut layers, mut compared, mut agree) = (0, 0, 0, 0);
    for (i, camera) in views.iter().enumerate() {
        let (image, info) = reusing.frame(camera, &settings).unwrap();
        fresh.reset();
        let (reference, _) = fresh.frame(camera, &settings).unwrap();
        reused += info.shadow.layers_reused;
        layers += info.shadow.layers;
        let a = tw_frame::mask::compare_shadow_images(&reference, &image, 2).unwrap();
        assert!(a.ratio() >= 0.98, "frame {i}: {:.2} % of the mask agrees", 100.0 * a.ratio());
        compared += a.compared;
        agree += a.agree;
    }
    assert!(reused > 0 && reused < layers, "{reused} of {layers} layers reused: nothing was tested");
    assert!(agree as f64 >= 0.995 * compared as f64, "{agree} of {compared} mask pixels agree");
    // A still camera: the second frame reuses every layer and draws the first frame's image.
    reusing.reset();
    let (first, _) = reusing.frame(&views[5], &settings).unwrap();
    let (again, info) = reusing.frame(&views[5], &settings).unwrap();
    assert_eq!(info.shadow.layers_reused, info.shadow.layers);
    assert!(first.rgba == again.rgba, "a still camera's image changed with reused layers");
    // Another cap on the cascades sets the map up anew: nothing in it can be reused.
    let mut more = settings;
    if let Some(s) = more.shadows.as_mut() {
        s.options.cascades = 4;
    }
    let (_, info) = reusing.frame(&views[5], &more).unwrap();
    assert_eq!(info.shadow.layers_reused, 0, "layers reused from a map set up anew");
}
