//! End-to-end tests of streaming over stores built with tw-build: the budget under teleports,
//! complete and crack-free cuts while pages are missing (the availability rule of
//! docs/FORMAT.md), convergence to the blocking cut, corrupt pages, prefetch, shutdown.

mod common;
use common::{plant_path, small_pages_plant_path, spheres_path};

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;
use tw_runtime::{
    Camera, PrefetchOptions, ResidentPage, SelectOptions, Selection, StreamOptions, StreamStats, Streamer,
};
use tw_store::Store;

fn open(path: &Path) -> Arc<Store> {
    Arc::new(Store::open(path).unwrap())
}

fn camera(eye: Vec3, target: Vec3) -> Camera {
    Camera::new(eye, target, Vec3::Z, 60f32.to_radians(), 0.01, 1e5).unwrap()
}

fn scene_sphere(store: &Store) -> (Vec3, f32) {
    let h = store.header();
    let lo = Vec3::from_array([0, 1, 2].map(|a| (h.bounds_min[a] - h.grid_origin[a]) as f32));
    let hi = Vec3::from_array([0, 1, 2].map(|a| (h.bounds_max[a] - h.grid_origin[a]) as f32));
    ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
}

fn opts(tau: f32, frustum: bool) -> SelectOptions {
    SelectOptions { tau, viewport: [1280, 720], frustum_culling: frustum, ..Default::default() }
}

/// No loader threads, and τ kept as asked (the fit is tested on its own).
fn manual(budget: u64) -> StreamOptions {
    StreamOptions {
        budget_bytes: budget,
        loader_threads: 0,
        prefetch: PrefetchOptions::default(),
        fit_budget: false,
    }
}

#[allow(dead_code)]
fn sorted(sel: &Selection) -> Vec<(u32, u32)> {
    let mut v: Vec<(u32, u32)> = sel.clusters.iter().map(|c| (c.page, c.index_in_page)).collect();
    v.sort();
    v
}

fn page_sizes(store: &Store) -> Vec<u64> {
    (0..store.pages().len() as u32)
        .map(|p| ResidentPage::new(store.page(p).unwrap()).bytes() as u64)
        .collect()
}

/// Edges used by exactly one selected triangle (by grid position), and the selected area.
fn boundary_and_area(store: &Store, sel: &Selection) -> (usize, f64) {
    let step = store.header().grid_step;
    let mut edges: HashMap<([u32; 3], [u32; 3]), u32> = HashMap::new();
    let mut area = 0.0;
    let mut pages: HashMap<u32, Vec<tw_store::PageCluster>> = HashMap::new();
    for c in &sel.clusters {
        let page = pages.entry(c.page).or_insert_with(|| store.page(c.page).unwrap());
        let cl = &page[c.index_in_page as usize];
        for t in cl.indices.chunks(3) {
            let p = [0, 1, 2].map(|i| cl.positions[t[i] as usize]);
            for e in 0..3 {
                let (a, b) = (p[e], p[(e + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
            let v = p.map(|q| glam::DVec3::new(q[0] as f64, q[1] as f64, q[2] as f64) * step);
            area += 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length();
        }
    }
    (edges.values().filter(|&&n| n == 1).count(), area)
}

/// Eyes around and inside the spheres scene.
fn sphere_eyes(store: &Store) -> Vec<Vec3> {
    let (c, r) = scene_sphere(store);
    vec![
        Vec3::new(0.0, 0.0, 10.5),
        Vec3::new(0.0, -11.0, 0.0),
        Vec3::new(20.0, 2.0, 0.5),
        c + Vec3::new(0.3, -1.0, 0.2) * (3.0 * r),
        c + Vec3::new(-1.0, 0.1, 0.5) * (30.0 * r),
    ]
}

/// THE property of the availability rule: starting with only the root pages and loading a
/// few pages per frame, every streamed cut of a closed input is closed (no crack) and has no
/// overlap; once nothing is missing it is exactly the blocking cut.
#[test]
fn streamed_cuts_are_crack_free_while_pages_are_missing_and_converge_to_the_blocking_cut() {
    let store = open(spheres_path());
    let (c, _) = scene_sphere(&store);
    let full = {
        let s = Streamer::new(store.clone(), manual(u64::MAX)).unwrap();
        s.select_blocking(&camera(Vec3::new(0.0, 0.0, 200.0), c), &opts(0.0, false))
    };
    let (open_edges, input_area) = boundary_and_area(&store, &full);
    assert_eq!(open_edges, 0, "the input is closed");
    let (mut partial_frames, mut min_ratio, mut stalls) = (0, f64::MAX, 0);
    for eye in sphere_eyes(&store) {
        for tau in [0.5, 3.0, 50.0] {
            let cam = camera(eye, c);
            let o = opts(tau, false);
            let mut streamer = Streamer::new(store.clone(), manual(u64::MAX)).unwrap();
            let mut frames = 0;
            loop {
                let f = streamer.frame(&cam, &o);
                let (open_edges, area) = boundary_and_area(&store, &f.selection);
                assert_eq!(
                    open_edges, 0,
                    "eye {eye} tau {tau} frame {frames}: cracks while streaming ({:?})",
                    f.stats
                );
                assert!(
                    area <= input_area * 1.001,
                    "eye {eye} tau {tau} frame {frames}: overlap, area {area}"
                );
                min_ratio = f64::min(min_ratio, area / input_area);
                assert!(f.selection.clusters.iter().all(|k| f.page(k.page).is_some()), "pages held");
                if f.stats.pages_requested == 0 {
                    assert_eq!(f.stats.stalls_avoided, 0);
                    assert_eq!(f.stats.clusters_fallback, 0);
                    break;
                }
                partial_frames += 1;
                stalls += f.stats.stalls_avoided;
                // Two pages a frame: slow loaders.
                assert!(streamer.load_queued(2) > 0, "requested pages get loaded");
                frames += 1;
                assert!(frames < 10_000);
            }
            let f = streamer.frame(&cam, &o);
            assert_eq!(f.selection, streamer.select_blocking(&cam, &o), "eye {eye} tau {tau}: converged");
        }
    }
    eprintln!(
        "spheres: {partial_frames} frames drawn with pages missing, all closed; {stalls} stalls avoided; \
         smallest area {min_ratio:.3} of the input"
    );
    assert!(partial_frames > 15, "the test saw frames with pages missing");
    assert!(min_ratio > 0.5, "the root cut covers the scene: {min_ratio}");
}

/// The same with the frustum on and real loader threads, paused and resumed: crack-free
/// within what is drawn is not checkable with culling, so this checks convergence to the
/// blocking cut (plant and spheres) and that stalls are counted while paused.
#[test]
fn with_loader_threads_the_streamed_cut_converges_to_the_blocking_cut() {
    for path in [plant_path(), spheres_path()] {
        let store = open(path);
        let (c, r) = scene_sphere(&store);
        let streamer_opts = StreamOptions { budget_bytes: u64::MAX, ..Default::default() };
        for (i, eye) in [Vec3::new(0.6, -0.7, 0.4), Vec3::new(-0.2, 0.1, 0.05)].into_iter().enumerate() {
            let mut streamer = Streamer::new(store.clone(), streamer_opts).unwrap();
            assert_eq!(streamer.loader_threads(), 2);
            let cam = camera(c + eye.normalize() * r * (1.5 - i as f32), c + Vec3::new(0.1, 0.2, 0.0) * r);
            let o = opts(1.0, true);
            streamer.set_paused(true);
            let first = streamer.frame(&cam, &o);
            assert!(first.stats.pages_requested > 0 && first.stats.stalls_avoided > 0, "{:?}", first.stats);
            assert!(first.stats.pending > 0);
            streamer.set_paused(false);
            let mut frames = 0;
            loop {
                assert!(streamer.wait_idle(Duration::from_secs(60)));
                let f = streamer.frame(&cam, &o);
                if f.stats.pages_requested == 0 {
                    assert_eq!(f.selection, streamer.select_blocking(&cam, &o), "{path:?} view {i}");
                    break;
                }
                frames += 1;
                assert!(frames < 1000);
            }
        }
    }
}

#[test]
fn random_teleports_keep_resident_bytes_within_the_budget() {
    let store = open(plant_path());
    let sizes = page_sizes(&store);
    let roots: Vec<u32> = (0..sizes.len() as u32).filter(|&p| store.pages()[p as usize].is_root()).collect();
    let pinned: u64 = roots.iter().map(|&p| sizes[p as usize]).sum();
    let total: u64 = sizes.iter().sum();
    let budget = pinned + (total - pinned) / 6;
    let largest = *sizes.iter().max().unwrap();
    let bound = budget.max(pinned) + largest;
    let mut streamer =
        Streamer::new(store.clone(), StreamOptions { budget_bytes: budget, ..Default::default() }).unwrap();
    let (c, r) = scene_sphere(&store);
    let mut rng = tw_core::Rng::new(11);
    let mut v = || rng.f64() as f32 * 2.0 - 1.0;
    let mut all = StreamStats::default();
    for i in 0..40 {
        let eye = c + Vec3::new(v(), v(), v()) * r * 1.2;
        let target = c + Vec3::new(v(), v(), v()) * r * 0.5;
        if eye.distance(target) < 1e-3 {
            continue;
        }
        let cam = camera(eye, target);
        streamer.reset_history();
        for k in 0..4 {
            let f = streamer.frame(&cam, &opts([0.5, 1.0, 4.0][i % 3], true));
            let s = f.stats;
            assert!(s.resident_bytes <= bound, "teleport {i} frame {k}: {s:?}, bound {bound}");
            assert!(roots.iter().all(|&p| streamer.cache().contains(p)), "teleport {i}: a root page went");
            assert_eq!(s.failed_pages, 0);
            all.pages_loaded += s.pages_loaded;
            all.pages_evicted += s.pages_evicted;
            all.stalls_avoided += s.stalls_avoided;
            all.bytes_read += s.bytes_read;
            // Watch the cache while the loaders work.
            for _ in 0..5 {
                std::thread::sleep(Duration::from_millis(1));
                let cs = streamer.cache().stats();
                assert!(cs.resident_bytes <= bound, "teleport {i}: {cs:?}, bound {bound}");
            }
        }
    }
    eprintln!(
        "teleports: budget {budget} of {total} decoded bytes (pinned {pinned}, largest page {largest}): {} pages \
         loaded, {} evicted, {} bytes read, {} stalls avoided",
        all.pages_loaded, all.pages_evicted, all.bytes_read, all.stalls_avoided
    );
    assert!(all.pages_evicted > 0, "the budget was tight enough to evict");
}

/// A corrupt page met while streaming: logged, marked failed, its groups drawn from their
/// ancestors — on a closed input the cut stays closed.
#[test]
fn corrupt_page_while_streaming_falls_back_to_ancestors() {
    let clean = Store::open(spheres_path()).unwrap();
    let victim = (0..clean.pages().len())
        .find(|&p| !clean.pages()[p].is_root() && clean.pages()[p].level_min == 0)
        .expect("a level-0 page") as u32;
    let entry = clean.pages()[victim as usize];
    let mut bytes = std::fs::read(spheres_path()).unwrap();
    bytes[entry.offset as usize + entry.compressed_len as usize / 2] ^= 0x10;
    let store = Arc::new(Store::from_bytes(bytes).unwrap());
    let (c, _) = scene_sphere(&store);
    let cam = camera(Vec3::new(0.0, -30.0, 5.0), c);
    let o = opts(0.0, false);
    let mut streamer =
        Streamer::new(store.clone(), StreamOptions { budget_bytes: u64::MAX, ..Default::default() }).unwrap();
    let mut last = None;
    for _ in 0..1000 {
        let f = streamer.frame(&cam, &o);
        let done = f.stats.pages_requested == 0;
        last = Some(f);
        if done {
            break;
        }
        assert!(streamer.wait_idle(Duration::from_secs(60)));
    }
    let f = last.unwrap();
    let s = f.stats;
    assert_eq!(s.pages_requested, 0, "converged: {s:?}");
    assert_eq!(s.failed_pages, 1, "{s:?}");
    assert!(s.groups_failed > 0 && s.clusters_fallback > 0, "fallback drawn: {s:?}");
    assert!(f.selection.clusters.iter().all(|k| k.page != victim));
    let (open_edges, _) = boundary_and_area(&store, &f.selection);
    assert_eq!(open_edges, 0, "the fallback closes the hole: {s:?}");
    // The blocking cut draws the same ancestors: no hole either, the same clusters.
    let blocking = streamer.select_blocking(&cam, &o);
    assert_eq!(boundary_and_area(&store, &blocking).0, 0);
    assert_eq!(blocking.clusters, f.selection.clusters);
    // Asked again, the failed page is not read again.
    let again = streamer.frame(&cam, &o);
    assert_eq!((again.stats.pages_loaded, again.stats.bytes_read), (0, 0));
    eprintln!("corrupt page {victim}: {s:?}");
}

/// Stalls over a smooth path with a slow loader (a few pages per frame, loaded on the test's
/// thread so the figures are deterministic), with and without prefetch.
fn smooth_path_stalls(
    prefetch: PrefetchOptions,
    pages_per_frame: usize,
    budget_share: f64,
) -> (u64, u64, u64, u64) {
    let store = open(small_pages_plant_path());
    let sizes = page_sizes(&store);
    let budget = (sizes.iter().sum::<u64>() as f64 * budget_share) as u64;
    let mut streamer = Streamer::new(store.clone(), manual(budget)).unwrap();
    streamer.set_prefetch(prefetch);
    let (c, r) = scene_sphere(&store);
    // Towards the centre while circling: 1.6 r to 0.5 r in 100 frames, a quarter turn.
    let at = |i: usize| {
        let t = i as f32 / 100.0;
        let a = t * 1.5;
        let eye = c + Vec3::new(a.cos(), a.sin(), 0.3).normalize() * r * (1.6 - 1.1 * t);
        camera(eye, c + Vec3::new(0.0, 0.0, 0.1 * r))
    };
    // Warm start: the first view is loaded before the walk starts (as far as the budget allows).
    for _ in 0..50 {
        let f = streamer.frame(&at(0), &opts(1.0, true));
        if f.stats.pages_requested == 0 {
            break;
        }
        streamer.load_queued(usize::MAX);
    }
    let (mut stalls, mut loaded, mut prefetched, mut dropped) = (0, 0, 0, 0);
    for i in 0..100 {
        let cam = at(i);
        let f = streamer.frame(&cam, &opts(1.0, true));
        stalls += f.stats.stalls_avoided;
        loaded += f.stats.pages_loaded;
        prefetched += f.stats.prefetch_loaded;
        dropped += f.stats.prefetch_dropped;
        streamer.load_queued(pages_per_frame);
    }
    (stalls, loaded, prefetched, dropped)
}

#[test]
fn prefetch_reduces_stalls_on_a_smooth_path() {
    let store = open(small_pages_plant_path());
    let roots = store.pages().iter().filter(|p| p.is_root()).count();
    eprintln!("small-pages plant: {} pages, {roots} root pages", store.pages().len());
    let off = PrefetchOptions { enabled: false, ..Default::default() };
    for (k, share) in [(1, 2.0), (2, 2.0), (4, 2.0), (2, 0.3)] {
        let (without, lw, _, _) = smooth_path_stalls(off, k, share);
        let (with, l, p, d) = smooth_path_stalls(PrefetchOptions::default(), k, share);
        for (name, variant) in [
            ("always", PrefetchOptions { idle_below: usize::MAX, ..Default::default() }),
            ("8 frames ahead", PrefetchOptions { frames_ahead: 8.0, ..Default::default() }),
            ("no tau/2", PrefetchOptions { tau_scale: 1.0, ..Default::default() }),
            ("selected every frame", PrefetchOptions { every: 1, ..Default::default() }),
        ] {
            let (st, l, p, d) = smooth_path_stalls(variant, k, share);
            eprintln!("  variant {name}: {st} stalls ({l} loaded, {p} prefetched, {d} dropped)");
        }
        eprintln!(
            "smooth path, {k} pages/frame, budget {share} of the pages: stalls avoided {without} without prefetch \
             ({lw} pages loaded), {with} with ({l} loaded, {p} of them prefetched, {d} prefetched pages dropped)"
        );
        assert!(with <= without, "{k} pages/frame: {with} > {without}");
    }
}

#[test]
fn drop_joins_the_loader_threads() {
    let store = open(plant_path());
    let (c, r) = scene_sphere(&store);
    let mut streamer = Streamer::new(store.clone(), StreamOptions::default()).unwrap();
    // Leave work queued and in flight.
    let f = streamer.frame(&camera(c + Vec3::new(0.1, 0.2, 0.05) * r, c + Vec3::X * r), &opts(0.0, false));
    assert!(f.stats.pages_requested > 0);
    drop(f);
    assert!(Arc::strong_count(&store) > 1, "the loaders hold the store");
    drop(streamer);
    assert_eq!(Arc::strong_count(&store), 1, "every loader thread ended and released the store");
}

/// `bench --wait`: a blocking frame reports the pages it read and holds, as a streamed frame
/// does (it reported zero memory and disk for every frame).
#[test]
fn a_blocking_frame_reports_what_it_read_and_holds() {
    let store = open(spheres_path());
    let (c, _) = scene_sphere(&store);
    let mut streamer = Streamer::new(store.clone(), manual(u64::MAX)).unwrap();
    let cam = camera(Vec3::new(0.0, 0.0, 200.0), c);
    let (selection, first) = streamer.frame_blocking(&cam, &opts(0.0, false));
    assert_eq!(selection, streamer.select_blocking(&cam, &opts(0.0, false)));
    assert!(first.pages_loaded > 0 && first.bytes_read > 0, "{first:?}");
    assert!(first.resident_bytes > 0 && first.resident_pages > 0, "{first:?}");
    assert_eq!(first.triangles, selection.triangles);
    // The same view again: everything resident, nothing read, the same memory held.
    let (_, again) = streamer.frame_blocking(&cam, &opts(0.0, false));
    assert_eq!((again.pages_loaded, again.bytes_read), (0, 0), "{again:?}");
    assert_eq!(again.resident_bytes, first.resident_bytes);
    assert_eq!(again.frame, first.frame + 1);
}

/// A cut whose pages do not fit the cache: without the fit of τ it thrashes (every frame asks
/// for pages and evicts others, for ever); with it the streamed cut settles at a raised τ, where
/// it asks for no page, loads none but prefetched ones, stays within the budget, and is exactly
/// the render rule's blocking cut at that τ (`tw_runtime::fit`). On the closed spheres the
/// settled cut is closed too.
#[test]
fn a_cut_too_big_for_the_cache_settles_at_a_raised_tau_instead_of_thrashing() {
    let spheres = open(spheres_path());
    let (c, _) = scene_sphere(&spheres);
    fit_settles(&spheres, camera(Vec3::new(0.0, 0.0, 10.5), c), 0.1, true);
    let plant = open(small_pages_plant_path());
    let (c, r) = scene_sphere(&plant);
    fit_settles(&plant, camera(c + Vec3::new(0.6, -0.7, 0.3) * r * 0.8, c), 0.1, false);
}

fn fit_settles(store: &Arc<Store>, cam: Camera, tau: f32, closed: bool) {
    let sizes = page_sizes(store);
    let pinned: u64 = (0..sizes.len()).filter(|&p| store.pages()[p].is_root()).map(|p| sizes[p]).sum();
    let o = opts(tau, false);
    let exact = Streamer::new(store.clone(), manual(u64::MAX)).unwrap().select_blocking(&cam, &o);
    let mut exact_pages: Vec<u32> = exact.clusters.iter().map(|k| k.page).collect();
    exact_pages.sort();
    exact_pages.dedup();
    let exact_bytes: u64 = exact_pages.iter().map(|&p| sizes[p as usize]).sum();
    // The root pages, and half of what the exact cut needs beyond them.
    let beyond: u64 = exact_pages
        .iter()
        .filter(|&&p| !store.pages()[p as usize].is_root())
        .map(|&p| sizes[p as usize])
        .sum();
    let budget = pinned + beyond / 2;
    assert!(beyond > pinned / 2, "the exact cut needs more than the root pages: {beyond} beyond {pinned}");
    let run = |fit: bool| {
        let mut streamer =
            Streamer::new(store.clone(), StreamOptions { fit_budget: fit, ..manual(budget) }).unwrap();
        let mut frames = Vec::new();
        for _ in 0..80 {
            let f = streamer.frame(&cam, &o);
            frames.push((f.stats, f.selection));
            streamer.load_queued(usize::MAX);
        }
        (streamer, frames)
    };
    let (_, thrashing) = run(false);
    let unsettled =
        thrashing[60..].iter().filter(|(s, _)| s.pages_requested > 0 && s.pages_evicted > 0).count();
    assert!(unsettled >= 15, "without the fit the cut thrashes: {:?}", thrashing.last().map(|f| f.0));
    let (streamer, fitted) = run(true);
    let (last, selection) = fitted.last().unwrap();
    for (s, sel) in &fitted[60..] {
        assert_eq!(s.pages_requested, 0, "settled: {s:?}");
        assert_eq!(s.pages_loaded, s.prefetch_loaded, "only prefetched pages load: {s:?}");
        assert!(
            s.resident_bytes <= budget && s.cut_bytes as f64 <= tw_runtime::fit::HIGH * budget as f64,
            "{s:?}"
        );
        assert_eq!((s.tau_scale, sel), (last.tau_scale, selection));
    }
    assert!(last.tau_scale > 1.0, "{last:?}");
    if closed {
        let (open_edges, _) = boundary_and_area(store, selection);
        assert_eq!(open_edges, 0, "the fitted cut is closed");
    }
    let at = opts(tau * last.tau_scale, false);
    assert_eq!(selection, &streamer.select_blocking(&cam, &at), "the render rule's cut at the raised τ");
    eprintln!(
        "fit: budget {budget} of the exact cut's {exact_bytes} bytes: τ × {:.2}, cut {} bytes, {} triangles \
         (exact {}); without the fit {unsettled} of the last 20 frames still loading",
        last.tau_scale, last.cut_bytes, last.triangles, exact.triangles
    );
}
