//! Cross-faded LOD switches (`--transition dither`, tw-frame's `transition` module, tw-gpu's
//! `dither`): the two halves of a switch are complementary (the same geometry as old and new
//! gives the plain image at every t); once a fade is over the frame is its cut's image exactly;
//! a still camera changes nothing; every occlusion strategy draws, pixel for pixel, what `none`
//! draws under the same fades; and along a fly-over the LOD-only change per frame
//! (`bench --popping`) is smaller than with `pop`. Vulkan (lavapipe); skipped without an
//! adapter unless `TERAWALK_REQUIRE_GPU=1`.

use std::sync::Arc;

use tw_frame::{FrameSettings, Occlusion, Transition, Walkthrough};
use tw_gpu::dither::{fade_word, Fade};
use tw_gpu::{wgpu, Image, Target};
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::{Camera, ClusterRef, SelectionPages};
use tw_store::Store;

mod common;

use common::gpu_lock;

fn plant() -> Arc<Store> {
    common::plant(150_000, 7)
}

fn fly(store: &Store, frames: usize) -> Vec<Camera> {
    let options = PathOptions { frames, part: PathPart::Fly, seed: 4, ..Default::default() };
    let path = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path;
    path.frames.iter().map(|f| f.to_scene(store.header()).unwrap()).collect()
}

fn settings(occlusion: Occlusion, transition: Transition) -> FrameSettings {
    FrameSettings { tau: 1.0, occlusion, wait_for_pages: true, transition, ..Default::default() }
}

fn walk(store: &Arc<Store>, what: &str) -> Option<Walkthrough> {
    common::walkthrough(store.clone(), wgpu::Backends::VULKAN, what, 256 << 20)
}

/// The same clusters drawn as a leaving copy and an entering copy (the copies' keys moved to
/// pages past the store's, so the pool holds each twice with its own fade word) give the image
/// of the clusters drawn once, whole, at every t.
#[test]
fn the_halves_of_a_switch_are_complementary() {
    let store = plant();
    let _lock = gpu_lock();
    let Some(mut w) = walk(&store, "complementary halves") else { return };
    let camera = fly(&store, 30)[10];
    w.frame(&camera, &settings(Occlusion::None, Transition::Pop)).unwrap();
    let cut = w.selection().clusters.clone();
    let cache = w.streamer().cache().clone();
    let pages = SelectionPages::resolve(&store, &cache, &cut);
    let clusters = pages.clusters();
    let grid_step = store.header().grid_step;
    let r = w.renderer_mut();
    let plain = r.render_clusters(&camera, grid_step, &clusters).unwrap();
    assert!(plain.covered_pixels() > 1000, "the view shows little of the plant");
    let shift = store.header().page_count + 1;
    let copy = |c: &ClusterRef| ClusterRef { page: c.page + shift, ..*c };
    let mut both = clusters.clone();
    both.extend(clusters.iter().map(|(k, c)| (copy(k), *c)));
    for k in 0..=9 {
        let t = k as f32 / 9.0;
        let words = clusters.iter().flat_map(|(key, _)| {
            [(*key, fade_word(Fade::Leaving, t)), (copy(key), fade_word(Fade::Entering, t))]
        });
        r.set_fades(words.collect::<Vec<_>>());
        r.begin_frame();
        r.draw(Target::Own, &camera, grid_step, &both, true).unwrap();
        let image = r.read_color().unwrap();
        r.set_fades([]);
        let differing = image.differing_share(&plain).unwrap();
        assert_eq!(differing, 0.0, "t = {t}: the two halves differ from the plain image");
    }
    // One half alone at 0 < t < 1 leaves holes: the masks do discard.
    let half = clusters.iter().map(|(key, _)| (*key, fade_word(Fade::Leaving, 0.5)));
    r.set_fades(half.collect::<Vec<_>>());
    let holed = r.render_clusters(&camera, grid_step, &clusters).unwrap();
    r.set_fades([]);
    assert!(holed.covered_pixels() < plain.covered_pixels() * 3 / 4, "a half-faded cut covered as much");
}

/// Along a fly-over with `dither:4`, then four frames at the last camera: the fade is over and
/// the image is that of the last cut drawn at once; a camera held still from the start never
/// changes its image.
#[test]
fn a_finished_fade_is_the_cut_and_a_still_camera_changes_nothing() {
    let store = plant();
    let _lock = gpu_lock();
    let Some(mut w) = walk(&store, "finished fade") else { return };
    let cameras = fly(&store, 40);
    let dither = settings(Occlusion::None, Transition::Dither { frames: 4 });
    let mut faded = false;
    for c in &cameras[..20] {
        w.frame(c, &dither).unwrap();
        faded |= w.fading();
    }
    assert!(faded, "nothing switched along the fly-over");
    let last = cameras[19];
    let mut image = None;
    for _ in 0..4 {
        image = Some(w.frame(&last, &dither).unwrap().0);
    }
    assert!(!w.fading(), "a fade lasted beyond its 4 frames");
    let faded_image = image.unwrap();
    w.reset();
    let popped = w.frame(&last, &settings(Occlusion::None, Transition::Pop)).unwrap().0;
    assert_eq!(faded_image.differing_share(&popped).unwrap(), 0.0, "the finished fade is not the cut");

    w.reset();
    let first = w.frame(&cameras[0], &dither).unwrap().0;
    for _ in 0..3 {
        let previous = w.drawn_state();
        let again = w.frame(&cameras[0], &dither).unwrap().0;
        assert!(!w.fading());
        assert_eq!(again.differing_share(&first).unwrap(), 0.0, "a still camera's image changed");
        let change = w.lod_change(&cameras[0], &previous).unwrap();
        assert_eq!(change.changed_pixels, 0.0, "{change:?}");
    }
}

/// Every occlusion strategy with `dither:4` draws, frame by frame along a fly-over, the image
/// of `none` with the same fades: a dithered depth stays a conservative occluder.
#[test]
fn occlusion_with_dither_equals_none_with_dither() {
    let store = plant();
    let _lock = gpu_lock();
    let Some(mut w) = walk(&store, "occlusion with dither") else { return };
    let cameras: Vec<Camera> = fly(&store, 48).into_iter().step_by(2).collect();
    let transition = Transition::Dither { frames: 4 };
    let run = |w: &mut Walkthrough, occlusion: Occlusion| -> (Vec<Image>, u64, bool) {
        w.reset();
        let mut culled = 0;
        let mut faded = false;
        let images = cameras
            .iter()
            .map(|c| {
                let (image, info) = w.frame(c, &settings(occlusion, transition)).unwrap();
                culled += info.occlusion.culled;
                faded |= w.fading();
                image
            })
            .collect();
        (images, culled, faded)
    };
    let (none, _, faded) = run(&mut w, Occlusion::None);
    assert!(faded, "nothing faded along the fly-over");
    for occlusion in [Occlusion::Hzb, Occlusion::Queries, Occlusion::GpuHzb] {
        let (images, culled, _) = run(&mut w, occlusion);
        for (i, (a, b)) in images.iter().zip(&none).enumerate() {
            let differing = a.differing_share(b).unwrap();
            assert_eq!(
                differing,
                0.0,
                "{}: frame {i} differs from none under the same fades",
                occlusion.name()
            );
        }
        eprintln!("{}: {culled} clusters culled", occlusion.name());
    }
}

/// The LOD-only change of each frame along a fly-over ([`Walkthrough::lod_change`] of the
/// previous frame's drawn state): the worst frame changes less than half as many pixels with
/// `dither:8` as with `pop` (a switch's change is spread over the fade's frames; the sum over
/// the path stays about the same, each pixel changing once per switch).
#[test]
fn dither_reduces_the_popping_along_a_fly_over() {
    let store = plant();
    let _lock = gpu_lock();
    let Some(mut w) = walk(&store, "popping with dither") else { return };
    let cameras = fly(&store, 60);
    let mut measure = |transition: Transition| -> (f64, f64) {
        w.reset();
        let s = settings(Occlusion::None, transition);
        w.frame(&cameras[0], &s).unwrap();
        let (mut worst, mut sum) = (0.0f64, 0.0f64);
        for c in &cameras[1..] {
            let previous = w.drawn_state();
            w.frame(c, &s).unwrap();
            let change = w.lod_change(c, &previous).unwrap().changed_pixels;
            worst = worst.max(change);
            sum += change;
        }
        (worst, sum)
    };
    let (pop_worst, pop_sum) = measure(Transition::Pop);
    let (dither_worst, dither_sum) = measure(Transition::Dither { frames: 8 });
    eprintln!(
        "pop: worst {pop_worst:.5}, sum {pop_sum:.5}; dither:8: worst {dither_worst:.5}, sum {dither_sum:.5}"
    );
    assert!(pop_worst > 0.0, "the cut never changed the image along the fly-over");
    assert!(dither_worst < pop_worst / 2.0, "worst frame: dither {dither_worst} against pop {pop_worst}");
}
