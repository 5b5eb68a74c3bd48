//! The selection's frame-to-frame state (a [`Selector`] that has selected earlier frames keeps
//! each group's steps, read once from its page) never changes a cut: on random camera
//! sequences — smooth moves, teleports, τ changes, frustum culling on and off — with pages
//! arriving and being evicted under a small budget, a selector used for every frame gives the
//! same selection (clusters in the same order, triangles, statistics) and the same page
//! requests as a fresh selector traversing from the root, in both residency modes, and leaves
//! the page cache in the same state (same pages resident, so the same LRU order of use).

mod common;
use common::{small_pages_plant_path, spheres_path};

use glam::Vec3;
use tw_core::rng::Rng;
use tw_runtime::{
    Availability, Camera, PageCache, Requests, ResidentPage, SelectOptions, Selection, Selector,
};
use tw_store::Store;

fn scene_sphere(store: &Store) -> (Vec3, f32) {
    let h = store.header();
    let lo = Vec3::from_array([0, 1, 2].map(|a| (h.bounds_min[a] - h.grid_origin[a]) as f32));
    let hi = Vec3::from_array([0, 1, 2].map(|a| (h.bounds_max[a] - h.grid_origin[a]) as f32));
    ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
}

/// The draws the random sequences make, from the project's generator.
trait Draw {
    /// Uniform in [0, 1].
    fn unit(&mut self) -> f32;
    /// Uniform in the cube [-1, 1]³.
    fn vec(&mut self) -> Vec3;
}

impl Draw for Rng {
    fn unit(&mut self) -> f32 {
        self.f64() as f32
    }
    fn vec(&mut self) -> Vec3 {
        Vec3::from_array([(); 3].map(|_| self.range_f64(-1.0, 1.0) as f32))
    }
}

/// One frame's selections by `selector` over `cache` in streaming mode: the frame's cut and a
/// prefetch-like view (wider, τ/2, peek-only), as `Streamer::frame` does.
fn stream_frame(
    selector: &Selector,
    store: &Store,
    cache: &PageCache,
    availability: &mut Availability,
    camera: &Camera,
    options: &SelectOptions,
) -> (Selection, Requests, Selection, Requests) {
    availability.begin(store);
    let (mut demand, mut prefetch) = (Requests::default(), Requests::default());
    let (mut cut, mut view) = (Selection::default(), Selection::default());
    selector.select_available(store, cache, availability, &mut demand, camera, options, &mut cut);
    availability.set_peek_only(true);
    let wide = Camera { projection: camera.projection.widened(1.2), ..*camera };
    let half = SelectOptions { tau: options.tau * 0.5, ..*options };
    selector.select_available(store, cache, availability, &mut prefetch, &wide, &half, &mut view);
    availability.set_peek_only(false);
    (cut, demand, view, prefetch)
}

/// Drives a warm selector and fresh ones through `frames` random frames (see the module
/// documentation) over two caches of `budget` bytes that receive the same loads.
fn check_sequence(store: &Store, budget: u64, frames: usize, seed: u64) {
    let (centre, radius) = scene_sphere(store);
    let warm = Selector::new(store);
    let (cache_w, cache_c) = (PageCache::new(store, budget), PageCache::new(store, budget));
    cache_w.load_root_pages(store);
    cache_c.load_root_pages(store);
    let mut availability = Availability::default();
    let mut rng = Rng::new(seed);
    let mut eye = centre + Vec3::new(0.3, -0.2, 0.1) * radius;
    let mut dir = Vec3::new(1.0, 0.4, -0.1).normalize();
    let taus = [0.25f32, 0.5, 1.0, 2.0, 8.0];
    let (mut tau, mut frustum) = (1.0f32, true);
    let (mut teleports, mut evictions, mut drawn) = (0, 0u64, 0usize);
    for frame in 0..frames {
        let r = rng.unit();
        if r < 0.12 {
            // Teleport: anywhere within twice the scene's radius, looking anywhere.
            eye = centre + rng.vec() * 2.0 * radius;
            dir = rng.vec().normalize_or(Vec3::X);
            teleports += 1;
        } else {
            eye += dir * 0.02 * radius + rng.vec() * 0.005 * radius;
            dir = (dir + rng.vec() * 0.1).normalize_or(Vec3::X);
        }
        if rng.unit() < 0.1 {
            tau = *rng.pick(&taus);
        }
        if rng.unit() < 0.1 {
            frustum = !frustum;
        }
        let Ok(camera) = Camera::new(eye, eye + dir, Vec3::Z, 60f32.to_radians(), 0.01, 1e5) else {
            continue;
        };
        let options =
            SelectOptions { tau, viewport: [1280, 720], frustum_culling: frustum, ..Default::default() };
        let what = format!("frame {frame}: eye {eye}, dir {dir}, tau {tau}, frustum {frustum}");
        if frame % 10 == 9 {
            // The blocking mode (loads what it needs into both caches alike).
            let a = warm.select(store, &cache_w, &camera, &options);
            let b = Selector::new(store).select(store, &cache_c, &camera, &options);
            assert_eq!(a, b, "blocking, {what}");
        } else {
            let a = stream_frame(&warm, store, &cache_w, &mut availability, &camera, &options);
            let b = stream_frame(
                &Selector::new(store),
                store,
                &cache_c,
                &mut Availability::default(),
                &camera,
                &options,
            );
            assert_eq!(a.0, b.0, "cut, {what}");
            assert_eq!(a.1, b.1, "requests, {what}");
            assert_eq!(a.2, b.2, "prefetch view, {what}");
            assert_eq!(a.3, b.3, "prefetch requests, {what}");
            drawn += a.0.clusters.len();
            // Some of the requested pages arrive, highest priority first (frame pages, then a
            // few prefetched ones), in both caches alike.
            let n = rng.range_u32(0, 12) as usize;
            let pages: Vec<u32> =
                a.1.sorted().into_iter().chain(a.3.sorted()).map(|(p, _)| p).take(n).collect();
            drop((a, b));
            for p in pages {
                let (x, y) = (cache_w.get(store, p).is_ok(), cache_c.get(store, p).is_ok());
                assert_eq!(x, y, "load of page {p}, {what}");
            }
        }
        let (sw, sc) = (cache_w.stats(), cache_c.stats());
        assert_eq!(sw.resident_pages, sc.resident_pages, "{what}");
        assert_eq!(sw.evictions, sc.evictions, "{what}");
        for p in 0..store.pages().len() as u32 {
            assert_eq!(cache_w.contains(p), cache_c.contains(p), "page {p} resident, {what}");
        }
        evictions = sw.evictions;
    }
    assert!(teleports > 5, "{teleports} teleports");
    assert!(evictions > 0, "the budget never forced an eviction");
    assert!(drawn > 0);
    eprintln!(
        "{frames} frames: {teleports} teleports, {evictions} evictions, {drawn} clusters drawn, {} groups \
         selected from their kept steps",
        warm.groups_from_steps()
    );
    assert!(
        warm.groups_from_steps() > frames as u64,
        "{} groups selected from their kept steps: the shortcut was hardly exercised",
        warm.groups_from_steps()
    );
}

fn total_page_bytes(store: &Store) -> u64 {
    (0..store.pages().len() as u32).map(|p| ResidentPage::new(store.page(p).unwrap()).bytes() as u64).sum()
}

#[test]
fn warm_selector_selects_what_a_fresh_one_selects_on_random_sequences_of_the_plant() {
    let store = Store::open(small_pages_plant_path()).unwrap();
    let budget = total_page_bytes(&store) / 4;
    check_sequence(&store, budget, 300, 0x5eed_0001);
}

#[test]
fn warm_selector_selects_what_a_fresh_one_selects_on_random_sequences_of_spheres() {
    let store = Store::open(spheres_path()).unwrap();
    let budget = total_page_bytes(&store) / 3;
    check_sequence(&store, budget, 200, 0x5eed_0002);
}
