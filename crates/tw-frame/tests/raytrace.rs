//! The ray tracer against the rasterizer (docs/DESIGN.md D8): on the same LOD cut, tw-rt's
//! primary rays must see what tw-gpu's item buffer sees — the same object in ≥ 99.5 % of the
//! pixels, the same depth within the rasterizer's precision where both hit the same triangle,
//! and an image shaded the same way — on a walk through a generated plant and on the approach
//! to a generated CAD assembly (thousands of small parts). Streaming: a traced frame uses only
//! resident pages (coarser resident levels stand in for missing ones, so the first frame after
//! a cold start already shows the model), the page cache keeps its budget, and the cluster BVHs
//! of evicted pages are dropped. Vulkan (lavapipe) for the rasterizer; without an adapter the
//! tests are skipped unless `TERAWALK_REQUIRE_GPU=1` (CI), where they fail.

use std::sync::Arc;

use tw_frame::traced::TracedWalkthrough;
use tw_frame::FrameSettings;
use tw_gpu::wgpu;
use tw_rt::scene::{StoreTracer, TraceSettings};
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::{Camera, Projection, SelectOptions, SelectionPages, StreamOptions};
use tw_store::Store;

mod common;

use common::{gpu_lock, H, W};

fn plant() -> Arc<Store> {
    common::plant(200_000, 3)
}

fn assembly() -> Arc<Store> {
    common::assembly(300_000, 1)
}

fn path_cameras(store: &Store, part: PathPart, frames: usize, step: usize) -> Vec<Camera> {
    let options = PathOptions { frames, part, seed: 2, ..Default::default() };
    let path = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path;
    path.frames.iter().step_by(step).map(|f| f.to_scene(store.header()).unwrap()).collect()
}

/// How two renderers agreed over a list of frames.
#[derive(Default, Debug)]
struct Agreement {
    pixels: u64,
    /// Pixels where at least one renderer shows geometry.
    covered: u64,
    /// Of `covered`, those where both show the same object.
    same_object: u64,
    /// Pixels where both show the same triangle of the same cluster, and of those the ones
    /// whose depths differ by more than the tolerance.
    same_triangle: u64,
    depth_outliers: u64,
    worst_psnr: f64,
}

/// Traces and rasterizes the cut of every camera at τ = 1 (pages loaded on the spot) and
/// counts where they agree.
fn agreement(store: Arc<Store>, cameras: &[Camera], what: &str) -> Option<Agreement> {
    let _lock = gpu_lock();
    let mut walk = common::walkthrough(store.clone(), wgpu::Backends::VULKAN, what, 256 << 20)?;
    let mut tracer = StoreTracer::new(&store, 256 << 20);
    let options = SelectOptions { tau: 1.0, viewport: [W, H], frustum_culling: true, ..Default::default() };
    let mut a = Agreement { worst_psnr: f64::INFINITY, ..Default::default() };
    for (i, camera) in cameras.iter().enumerate() {
        let selection = walk.streamer().select_blocking(camera, &options);
        let cache = walk.streamer().cache().clone();
        let pages = SelectionPages::resolve(&store, &cache, &selection.clusters);
        let renderer = walk.renderer_mut();
        let raster = renderer.render_selection(&store, &cache, camera, &selection).unwrap();
        let depth = renderer.read_depth().unwrap();
        let items = renderer.item_buffer(camera, store.header().grid_step, &pages.clusters()).unwrap();
        let traced = tracer.trace(&pages, camera, (W, H), &TraceSettings::default());
        assert!(traced.stats.clusters > 0, "{what}: frame {i} traced nothing");

        let view = camera.view();
        let proj = camera.projection_reverse_z(W as f32 / H as f32);
        for y in 0..H {
            for x in 0..W {
                let p = (y * W + x) as usize;
                a.pixels += 1;
                let item = items.item(x, y);
                let rt_object = (traced.objects[p] != u32::MAX).then_some(traced.objects[p]);
                if item.is_none() && rt_object.is_none() {
                    continue;
                }
                a.covered += 1;
                if item.map(|i| i.object) == rt_object {
                    a.same_object += 1;
                }
                // Depth where both see the same triangle: the hit point projected as the
                // rasterizer projects vertices, against the depth buffer.
                let Some(item) = item else { continue };
                let rt_cluster = traced.clusters[p];
                let Some(triangle) = item.triangle else { continue };
                if rt_cluster != item.cluster || traced_triangle(&traced, p) != Some(triangle) {
                    continue;
                }
                a.same_triangle += 1;
                let ray = tw_rt::Camera::for_view(camera, W as f32 / H as f32).pixel_ray(x, y, W, H);
                let hit = ray.at(traced.distance[p]);
                let clip = proj * view * hit.extend(1.0);
                let rt_depth = clip.z / clip.w;
                let raster_depth = depth.depth[p];
                // Compare view depths, relatively: the rasterizer interpolates z/w in f32 across
                // the triangle.
                let to_view = |d: f32| camera.view_depth_reverse_z(d);
                let rel = (to_view(rt_depth) - to_view(raster_depth)).abs() / to_view(raster_depth);
                if rel > 1e-3 {
                    a.depth_outliers += 1;
                }
            }
        }
        let image = tw_gpu::Image { width: W, height: H, rgba: traced.rgba };
        let psnr = image.to_opaque().psnr(&raster.to_opaque()).unwrap();
        a.worst_psnr = a.worst_psnr.min(psnr);
    }
    eprintln!("{what}: {a:?}");
    Some(a)
}

/// The triangle (index in its cluster) a traced pixel shows, recovered from its cluster's hit.
fn traced_triangle(traced: &tw_rt::scene::TracedFrame, p: usize) -> Option<u32> {
    traced.triangles.get(p).copied().filter(|&t| t != u32::MAX)
}

fn check(a: &Agreement, what: &str) {
    assert!(
        a.covered > a.pixels / 20,
        "{what}: the frames show almost nothing ({} of {} pixels)",
        a.covered,
        a.pixels
    );
    let share = a.same_object as f64 / a.covered as f64;
    assert!(share >= 0.995, "{what}: the same object in only {:.3} % of the covered pixels", share * 100.0);
    assert!(
        a.same_triangle > a.covered / 2,
        "{what}: the same triangle in only {} of {} pixels",
        a.same_triangle,
        a.covered
    );
    let outliers = a.depth_outliers as f64 / a.same_triangle as f64;
    assert!(
        outliers <= 0.001,
        "{what}: depth differs beyond 0.1 % in {:.3} % of the pixels",
        outliers * 100.0
    );
    assert!(a.worst_psnr >= 40.0, "{what}: a traced frame is {:.1} dB from the rasterized one", a.worst_psnr);
}

#[test]
fn rays_see_what_the_item_buffer_sees_on_a_plant_walk() {
    let cameras = path_cameras(&plant(), PathPart::Walk, 48, 6);
    if let Some(a) = agreement(plant(), &cameras, "plant walk") {
        check(&a, "plant walk");
    }
}

#[test]
fn rays_see_what_the_item_buffer_sees_on_an_assembly_approach() {
    let cameras = path_cameras(&assembly(), PathPart::Approach, 16, 2);
    if let Some(a) = agreement(assembly(), &cameras, "assembly approach") {
        check(&a, "assembly approach");
    }
}

/// The same comparison through orthographic cameras: each approach camera with a view as high as
/// its perspective view is at the target, so the model keeps its size on screen.
#[test]
fn rays_see_what_the_item_buffer_sees_in_orthographic_views() {
    let store = assembly();
    let cameras: Vec<Camera> = path_cameras(&store, PathPart::Approach, 16, 4)
        .into_iter()
        .map(|c| {
            let height = c.view_height_at((c.target - c.eye).length() as f64) as f32;
            Camera::with_projection(c.eye, c.target, c.up, Projection::Orthographic { height }, c.near, c.far)
                .unwrap()
        })
        .collect();
    if let Some(a) = agreement(store, &cameras, "assembly orthographic") {
        check(&a, "assembly orthographic");
    }
}

/// Streaming from a cold start: the first traced frame already covers the model with the root
/// pages' coarse levels; the page cache stays within its budget over a walk; the cluster BVHs of
/// pages the cache evicted are dropped.
#[test]
fn traced_frames_stream_within_the_budget() {
    let store = plant();
    let cameras = path_cameras(&store, PathPart::Walk, 48, 2);
    let root_bytes = {
        let cache = tw_runtime::PageCache::new(&store, u64::MAX);
        cache.load_root_pages(&store);
        cache.stats().resident_bytes
    };
    let budget = root_bytes + (2 << 20);
    let bvh_budget = StoreTracer::budget_split(budget).1 as usize;
    let stream = StreamOptions { budget_bytes: budget, ..Default::default() };
    let mut walk = TracedWalkthrough::new(store.clone(), (W, H), stream, TraceSettings::default()).unwrap();
    let streamed = FrameSettings { tau: 1.0, ..Default::default() };
    let complete = FrameSettings { wait_for_pages: true, ..streamed };

    let (first, ..) = walk.frame(&cameras[0], &streamed).unwrap();
    let mut full =
        TracedWalkthrough::new(store.clone(), (W, H), StreamOptions::default(), TraceSettings::default())
            .unwrap();
    let (reference, ..) = full.frame(&cameras[0], &complete).unwrap();
    let (a, b) = (first.covered_pixels(), reference.covered_pixels());
    assert!(a * 10 >= b * 9, "cold start: the first frame covers {a} pixels, the complete one {b}");

    let mut dropped = 0;
    for camera in &cameras {
        let (_, info, traced) = walk.frame(camera, &streamed).unwrap();
        let cache = walk.streamer().cache().stats();
        let pages = StoreTracer::budget_split(budget).0;
        assert!(
            cache.resident_bytes <= pages.max(cache.pinned_bytes),
            "{} resident over a budget of {pages}",
            cache.resident_bytes
        );
        assert_eq!(traced.stats.clusters as u64, info.clusters);
        let blas = traced.stats.blas;
        if traced.stats.tlas_rebuilt {
            assert!(
                blas.bytes <= bvh_budget.max(blas.frame_bytes),
                "cluster BVHs hold {} over a budget of {bvh_budget}",
                blas.bytes
            );
        }
        dropped += blas.dropped_pages + blas.evicted;
    }
    assert!(dropped > 0, "a walk under a tight budget dropped no cluster BVH");
}

/// `terawalk build --rt-bvh` (docs/DESIGN.md D8): the same plant built with the cluster BVHs'
/// shapes stored. Traced with the stored shapes (no SAH at run time), with the BVHs built as
/// pages load on the same store, and on the store built without them, every frame of a walk
/// gives the same pixels: colours, objects, clusters, triangles and distances, bit for bit.
#[test]
fn stored_cluster_bvhs_trace_the_same_frames() {
    let with_trees = {
        let mut o = tw_build::BuildOptions { memory: 256 << 20, ..Default::default() };
        o.pages.rt_bvh = Some(tw_rt::scene::stored::cluster_tree);
        tw_testkit::plant(200_000, 3, o).store()
    };
    let without = plant();
    assert!(with_trees.has_rt_trees() && !without.has_rt_trees());
    let cameras = path_cameras(&without, PathPart::Walk, 24, 3);
    let settings = FrameSettings { tau: 1.0, wait_for_pages: true, ..Default::default() };
    let walk = |store: &Arc<Store>, stored: bool| {
        let mut w =
            TracedWalkthrough::new(store.clone(), (W, H), StreamOptions::default(), TraceSettings::default())
                .unwrap();
        w.tracer_mut().use_stored_bvhs(stored);
        w
    };
    let mut walks = [walk(&with_trees, true), walk(&with_trees, false), walk(&without, true)];
    let (mut stored, mut built) = (0, 0);
    for (i, camera) in cameras.iter().enumerate() {
        let frames: Vec<_> = walks.iter_mut().map(|w| w.frame(camera, &settings).unwrap().2).collect();
        stored += frames[0].stats.blas.stored;
        built += frames[1].stats.blas.built + frames[2].stats.blas.built;
        assert_eq!(frames[0].stats.blas.stored, frames[0].stats.blas.built, "frame {i}: a BVH was built");
        assert_eq!(frames[1].stats.blas.stored + frames[2].stats.blas.stored, 0);
        for (k, f) in frames[1..].iter().enumerate() {
            let what = ["built on the same store", "the store without trees"][k];
            assert_eq!(f.stats.clusters, frames[0].stats.clusters, "frame {i}, {what}: another cut");
            assert!(f.rgba == frames[0].rgba, "frame {i}, {what}: other colours");
            assert!(f.objects == frames[0].objects, "frame {i}, {what}: other objects");
            assert!(f.clusters == frames[0].clusters, "frame {i}, {what}: other clusters");
            assert!(f.triangles == frames[0].triangles, "frame {i}, {what}: other triangles");
            let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert!(bits(&f.distance) == bits(&frames[0].distance), "frame {i}, {what}: other distances");
        }
    }
    assert!(stored > 0 && built == 2 * stored, "{stored} stored, {built} built");
}
