//! Wald's proxies over a real store (a generated plant): every group a missing page can leave
//! uncovered has one, a frame with every non-root page withheld still shows the warm frame's
//! surface from the proxies, never behind it, and with every page resident the proxies change
//! nothing.

use std::sync::Arc;

use tw_core::color::ColorMode;
use tw_rt::scene::proxies::{missing_groups, GroupProxies, ProxyPixels};
use tw_rt::scene::{StoreTracer, TraceSettings, TracedFrame};
use tw_runtime::{
    generate_path, Camera, PageCache, PathOptions, SelectOptions, SelectionPages, StreamOptions, Streamer,
};
use tw_store::Store;

const SIZE: (u32, u32) = (160, 120);
const RAYS: u32 = 2_000;

fn store() -> Arc<Store> {
    tw_testkit::plant(60_000, 1, Default::default()).store()
}

/// The first camera of each part (walk, fly-over) of the generated path.
fn cameras(store: &Store) -> Vec<Camera> {
    let options = PathOptions { frames: 40, ..Default::default() };
    let frames = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path.frames;
    let mut out = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        if i == 0 || frames[i - 1].segment != f.segment {
            out.push(f.to_scene(store.header()).unwrap());
        }
    }
    out
}

fn settings() -> TraceSettings {
    TraceSettings { coloring: ColorMode::Material, ..Default::default() }
}

/// The warm cut of `camera` (every page loadable) and its traced frame.
fn warm(store: &Arc<Store>, camera: &Camera) -> (Vec<tw_runtime::ClusterRef>, TracedFrame) {
    let options = StreamOptions { loader_threads: 0, ..Default::default() };
    let mut streamer = Streamer::new(store.clone(), options).unwrap();
    let select =
        SelectOptions { tau: 1.0, viewport: [SIZE.0, SIZE.1], frustum_culling: true, ..Default::default() };
    let (selection, _) = streamer.frame_blocking(camera, &select);
    let held = SelectionPages::resolve(store, streamer.cache(), &selection.clusters);
    let frame = StoreTracer::new(store, u64::MAX).trace(&held, camera, SIZE, &settings());
    (selection.clusters, frame)
}

fn covered(frame: &TracedFrame) -> usize {
    frame.rgba.chunks_exact(4).filter(|p| p[3] != 0).count()
}

#[test]
fn every_group_off_the_root_pages_has_a_proxy() {
    let store = store();
    let proxies = GroupProxies::build(&store, RAYS, |_| true).unwrap();
    let mut off_root = 0;
    for (g, group) in store.groups().iter().enumerate() {
        let root = store.pages()[group.page as usize].is_root();
        let proxy = proxies.get(g as u32);
        assert_eq!(proxy.is_some(), !root, "group {g} (root page: {root})");
        if let Some((p, bounds)) = proxy {
            off_root += 1;
            assert_eq!(p.id, g as u32);
            assert!((0..18).any(|k| p.direction(k).is_some()), "group {g} saw nothing");
            let [x, y, z, r] = group.sphere;
            let centre = glam::Vec3::new(x, y, z);
            assert!(
                bounds.min.distance(centre) <= r * 1.8 + 1e-3
                    && bounds.max.distance(centre) <= r * 1.8 + 1e-3
            );
        }
    }
    assert!(off_root > 10, "the plant pages its groups: {off_root}");
    assert_eq!(proxies.len(), off_root);
    assert_eq!(proxies.bytes(), off_root * 104);
}

#[test]
fn withheld_pages_are_shaded_from_proxies_in_front_of_their_surface() {
    let store = store();
    let proxies = GroupProxies::build(&store, RAYS, |_| true).unwrap();
    for camera in cameras(&store) {
        let (cut, warm) = warm(&store, &camera);
        assert!(
            cut.iter().any(|c| !store.pages()[c.page as usize].is_root()),
            "the cut needs non-root pages"
        );

        // Root pages only: the missing groups' boxes cover what the warm frame shows.
        let cache = PageCache::new(&store, 1 << 30);
        cache.load_root_pages(&store);
        let mut tracer = StoreTracer::new(&store, u64::MAX);
        let (cold, shaded) = tracer.trace_with_proxies(&cache, &cut, &proxies, &camera, SIZE, &settings());
        assert!(shaded > 0);
        let (a, b) = (covered(&cold), covered(&warm));
        assert!(a * 100 >= b * 95, "proxies cover {a} pixels, the warm frame {b}");
        // A proxy's box holds its group's surface: the ray stops at or before the warm hit.
        let (mut behind, mut both) = (0, 0);
        for (c, w) in cold.distance.iter().zip(&warm.distance) {
            if w.is_finite() {
                both += 1;
                behind += (*c > *w * 1.001) as usize;
            }
        }
        assert!(behind * 100 <= both, "{behind} of {both} pixels see past the missing geometry");

        // The hybrid shades only the pixels a frame left empty: on the warm frame with every
        // group of the cut as missing, nothing it drew changes.
        let all: Vec<u32> = cut.iter().map(|c| c.group).collect();
        let mut hybrid = warm.clone();
        let filled = tracer.shade_missing(&mut hybrid, &proxies, all.clone(), &camera, ProxyPixels::Holes);
        for (i, d) in warm.distance.iter().enumerate() {
            if d.is_finite() {
                assert_eq!(hybrid.rgba[i * 4..i * 4 + 4], warm.rgba[i * 4..i * 4 + 4], "pixel {i}");
            }
        }
        assert!(filled <= warm.distance.iter().filter(|d| !d.is_finite()).count());
        let mut before = warm.clone();
        assert!(tracer.shade_missing(&mut before, &proxies, all, &camera, ProxyPixels::BeforeHits) > filled);
        assert!(!missing_groups(&cut, &cache).is_empty());

        // Every page of the cut resident: no proxy, the warm frame exactly.
        for c in &cut {
            cache.get(&store, c.page).unwrap();
        }
        let (full, shaded) = tracer.trace_with_proxies(&cache, &cut, &proxies, &camera, SIZE, &settings());
        assert_eq!(shaded, 0);
        assert!(
            full.rgba == warm.rgba && full.objects == warm.objects,
            "the complete frame differs from the warm one"
        );
    }
}
