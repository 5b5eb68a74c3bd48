//! The light's view of a shadow-map layer (Govindaraju's thesis ch. 4, "LOD consistency":
//! always the eye's LOD): the eye's LOD cut culled by the layer's frustum, over stores built
//! with tw-build, in both residency modes.

mod common;
use common::{plant_path, spheres_path};

use std::collections::HashSet;
use std::path::Path;
use std::sync::Arc;

use glam::{Mat4, Vec3, Vec4};
use tw_runtime::camera::look_at_rh;
use tw_runtime::frustum::grid_box;
use tw_runtime::{
    Availability, Camera, Containment, Frustum, PageCache, Requests, SelectOptions, Selection, Selector,
    StreamOptions, Streamer,
};
use tw_store::Store;

fn open(path: &Path) -> Store {
    Store::open(path).unwrap()
}

fn scene_sphere(store: &Store) -> (Vec3, f32) {
    let h = store.header();
    let lo = Vec3::from_array([0, 1, 2].map(|a| (h.bounds_min[a] - h.grid_origin[a]) as f32));
    let hi = Vec3::from_array([0, 1, 2].map(|a| (h.bounds_max[a] - h.grid_origin[a]) as f32));
    ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
}

fn camera(eye: Vec3, target: Vec3) -> Camera {
    Camera::new(eye, target, Vec3::Z, 60f32.to_radians(), 0.01, 1e5).unwrap()
}

fn opts(tau: f32) -> SelectOptions {
    SelectOptions { tau, viewport: [1280, 720], frustum_culling: true, ..Default::default() }
}

/// The eye's own view-projection as the selection computes it.
fn eye_view_proj(eye: &Camera, options: &SelectOptions) -> Mat4 {
    let [w, h] = options.viewport.map(|v| v as f32);
    eye.view_projection(w / h)
}

/// A sun's orthographic layer over a square of half-width `half` around `at`, looking along
/// `−towards`, deep enough for the whole scene.
fn sun_layer(at: Vec3, towards: Vec3, half: f32, radius: f32) -> Mat4 {
    let up = if towards.z.abs() < 0.9 { Vec3::Z } else { Vec3::X };
    let view = look_at_rh(at + towards * 2.0 * radius, at, up);
    // Right-handed orthographic projection to depth 0..1: x, y in ±half, view z 0 → 0, −4r → 1.
    let depth = 4.0 * radius;
    let proj = Mat4::from_cols(
        Vec4::new(1.0 / half, 0.0, 0.0, 0.0),
        Vec4::new(0.0, 1.0 / half, 0.0, 0.0),
        Vec4::new(0.0, 0.0, -1.0 / depth, 0.0),
        Vec4::W,
    );
    proj * view
}

fn keys(sel: &Selection) -> HashSet<(u32, u32)> {
    sel.clusters.iter().map(|c| (c.page, c.index_in_page)).collect()
}

/// Eyes and layers over a store: eyes around and in the scene, layers beside and behind them.
fn views(store: &Store) -> Vec<(Camera, Mat4)> {
    let (c, r) = scene_sphere(store);
    let eyes = [
        camera(c + Vec3::new(1.0, 0.3, 0.2) * 3.0 * r, c),
        camera(c + Vec3::new(-0.5, 1.0, 0.7) * 1.2 * r, c),
        camera(c + Vec3::new(0.1, 0.05, 0.0) * r, c + Vec3::new(1.0, 0.5, 0.1) * r),
    ];
    let layers = [
        sun_layer(c, Vec3::new(0.2, 0.3, 1.0).normalize(), r, r),
        sun_layer(c + Vec3::new(0.5, -0.3, 0.0) * r, Vec3::new(-0.6, 0.1, 0.5).normalize(), 0.4 * r, r),
        sun_layer(c - Vec3::new(0.4, 0.2, 0.0) * r, Vec3::Z, 0.25 * r, r),
    ];
    eyes.iter().flat_map(|e| layers.iter().map(move |l| (*e, *l))).collect()
}

#[test]
fn the_eyes_own_frustum_gives_exactly_the_eye_selection() {
    for path in [spheres_path(), plant_path()] {
        let store = open(path);
        let cache = PageCache::new(&store, u64::MAX);
        cache.load_root_pages(&store);
        let selector = Selector::new(&store);
        for (eye, _) in views(&store) {
            for tau in [0.5, 2.0, 20.0] {
                let o = opts(tau);
                let own = selector.select_light(&store, &cache, &eye, &eye_view_proj(&eye, &o), &o);
                assert_eq!(own, selector.select(&store, &cache, &eye, &o), "{path:?} blocking, tau {tau}");
                // Streaming, with only the root pages resident: the same cut over one snapshot
                // (the second selection of a frame), and the same requests from snapshots of
                // their own (a frame requests each missing page once, for the first view that
                // meets it).
                let fresh = PageCache::new(&store, u64::MAX);
                fresh.load_root_pages(&store);
                let vp = eye_view_proj(&eye, &o);
                let (mut a, mut b, mut c) =
                    (Selection::default(), Selection::default(), Selection::default());
                let (mut ra, mut rb, mut rc) =
                    (Requests::default(), Requests::default(), Requests::default());
                let mut shared = Availability::default();
                shared.begin(&store);
                selector.select_available(&store, &fresh, &mut shared, &mut ra, &eye, &o, &mut a);
                selector.select_light_available(&store, &fresh, &mut shared, &mut rb, &eye, &vp, &o, &mut b);
                assert_eq!(a, b, "{path:?} streaming, tau {tau}");
                let mut own = Availability::default();
                own.begin(&store);
                selector.select_light_available(&store, &fresh, &mut own, &mut rc, &eye, &vp, &o, &mut c);
                assert_eq!(a, c, "{path:?} streaming, tau {tau}");
                assert_eq!(ra, rc, "{path:?} streaming requests, tau {tau}");
            }
        }
    }
}

/// The light's cut has the eye's LOD: every cluster of it is a cluster of the eye's whole
/// (unculled) cut, so a cluster seen from both is the same cluster at the same level; none lies
/// outside the layer's frustum; and every cluster of the eye's cut inside the layer's frustum is
/// in it, wherever the eye looks.
#[test]
fn the_light_cut_is_the_eyes_cut_culled_by_the_layer() {
    for path in [spheres_path(), plant_path()] {
        let store = open(path);
        let step = store.header().grid_step;
        let cache = PageCache::new(&store, u64::MAX);
        cache.load_root_pages(&store);
        let selector = Selector::new(&store);
        let (mut inside, mut outside_eye) = (0usize, 0usize);
        for (eye, layer) in views(&store) {
            for tau in [0.5, 4.0] {
                let o = opts(tau);
                let light = selector.select_light(&store, &cache, &eye, &layer, &o);
                let whole =
                    selector.select(&store, &cache, &eye, &SelectOptions { frustum_culling: false, ..o });
                let seen = keys(&selector.select(&store, &cache, &eye, &o));
                let (lk, wk) = (keys(&light), keys(&whole));
                assert!(lk.is_subset(&wk), "{path:?} tau {tau}: a light cluster not in the eye's cut");
                assert_eq!(light.triangles, {
                    let mut t = 0u64;
                    for c in &light.clusters {
                        t += cache.get(&store, c.page).unwrap().info()[c.index_in_page as usize].triangles
                            as u64;
                    }
                    t
                });
                let frustum = Frustum::from_view_projection(&layer);
                for c in &whole.clusters {
                    let page = cache.get(&store, c.page).unwrap();
                    let (lo, hi) = page.bounds[c.index_in_page as usize];
                    let (lo, hi) = grid_box(lo, hi, step);
                    let key = (c.page, c.index_in_page);
                    match frustum.test_aabb(lo, hi) {
                        Containment::Outside => {
                            assert!(!lk.contains(&key), "{path:?}: {key:?} outside the layer")
                        }
                        Containment::Inside => {
                            assert!(lk.contains(&key), "{path:?}: {key:?} inside the layer but not selected");
                            inside += 1;
                            outside_eye += !seen.contains(&key) as usize;
                        }
                        Containment::Intersecting => {}
                    }
                }
            }
        }
        assert!(inside > 50, "{path:?}: {inside} clusters inside the layers");
        assert!(outside_eye > 10, "{path:?}: {outside_eye}: the layers hardly reach beyond the eye's view");
    }
}

/// Streaming: after a frame, the light's view selects over the frame's snapshot, holds its pages,
/// requests what it misses along with the frame's requests and converges to the blocking light
/// cut as pages arrive; the eye's own frustum gives the frame's cut.
#[test]
fn streamed_light_views_request_their_pages_and_converge() {
    let store = Arc::new(open(spheres_path()));
    let (c, r) = scene_sphere(&store);
    let options = StreamOptions { budget_bytes: u64::MAX, loader_threads: 0, ..Default::default() };
    // The eye looks away from the region the layer covers.
    let eye = camera(c + Vec3::new(0.3, 0.0, 0.1) * r, c + Vec3::new(2.0, 0.0, 0.1) * r);
    let layer = sun_layer(c - Vec3::new(0.5, 0.0, 0.0) * r, Vec3::new(0.1, 0.2, 1.0).normalize(), 0.5 * r, r);
    let o = opts(1.0);
    let mut streamer = Streamer::new(store.clone(), options).unwrap();
    let blocking = {
        let reference = Streamer::new(store.clone(), options).unwrap();
        reference.select_light_blocking(&eye, &layer, &o)
    };
    assert!(!blocking.clusters.is_empty());
    let mut converged = None;
    for frame in 0..400 {
        let f = streamer.frame(&eye, &o);
        let (own, _) = streamer.select_light(&eye, &eye_view_proj(&eye, &o), &o);
        assert_eq!(own, f.selection, "frame {frame}: the eye's own frustum");
        let (light, pages) = streamer.select_light(&eye, &layer, &o);
        for cl in &light.clusters {
            assert!(
                pages.binary_search_by_key(&cl.page, |(p, _)| *p).is_ok(),
                "frame {frame}: page {} not held",
                cl.page
            );
        }
        if light == blocking && streamer.pending() == (0, 0) {
            converged = Some(frame);
            break;
        }
        streamer.load_queued(2);
    }
    let frame = converged.expect("the light's cut never converged: its pages were not requested");
    assert!(frame > 0, "the layer's pages were resident from the start: the test proves nothing");
}

#[test]
fn light_selection_before_any_frame_uses_the_root_pages() {
    let store = Arc::new(open(spheres_path()));
    let (c, r) = scene_sphere(&store);
    let options = StreamOptions { budget_bytes: u64::MAX, loader_threads: 0, ..Default::default() };
    let mut streamer = Streamer::new(store, options).unwrap();
    let eye = camera(c + Vec3::new(3.0 * r, 0.0, 0.0), c);
    let (sel, pages) = streamer.select_light(&eye, &sun_layer(c, Vec3::Z, r, r), &opts(1.0));
    assert!(!sel.clusters.is_empty());
    assert!(pages.iter().all(|(p, _)| streamer.cache().is_pinned(*p)));
}
