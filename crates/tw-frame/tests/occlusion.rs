//! Occlusion culling is conservative (docs/DESIGN.md "Measuring"): with the same LOD cut, every
//! strategy gives the image of `--occlusion none`, pixel for pixel, on a walk through a generated
//! plant's interior (smooth camera motion), on camera teleports (the two-pass scheme draws the
//! newly visible clusters in the same frame) and on the approach to a generated CAD assembly in one
//! object (thousands of small closed parts in millimetres behind thin cabinet panels: other
//! occluders and other LOD than the plant's). Each strategy must also cull something on the walk
//! and on the approach, so the comparison is not trivially true. `hzb` runs with its hierarchical
//! tests (skeleton nodes, then groups, then clusters) in every frame and with the flat test: the
//! images are those of `none` and the triangles drawn the same, and its culling gives the same
//! clusters and images on one thread as on several. The same with 4× multisampling (tw_gpu::msaa:
//! the tests then treat a pixel as its four samples; Vulkan only, GL refuses it). Through
//! orthographic cameras (the same walk and approach, `terawalk path --ortho auto`'s views) `hzb`,
//! `gpu-hzb` and `queries` give `none`'s images and cull. On GL (llvmpipe)
//! and Vulkan (lavapipe); without an adapter the tests are skipped unless `TERAWALK_REQUIRE_GPU=1`
//! (CI), where they fail.

use std::sync::Arc;

use tw_frame::{FrameSettings, Occlusion};
use tw_gpu::wgpu;
use tw_runtime::occlusion::HierarchyOptions;
use tw_runtime::pathgen::{generate_path, OrthoHeight, PathOptions, PathPart};
use tw_runtime::{Camera, ClusterRef};
use tw_store::Store;

mod common;

use common::gpu_lock;

/// The plant of the walk and the teleports.
fn plant() -> Arc<Store> {
    common::plant(200_000, 3)
}

/// The assembly of the approach: 300 k triangles, a few boards in one cabinet, small enough for
/// a debug test build.
fn assembly() -> Arc<Store> {
    common::assembly(300_000, 1)
}

/// A walk at eye height inside the plant (smooth), every third frame of 72.
fn walk_cameras(store: &Store) -> Vec<Camera> {
    walk_cameras_with(store, None)
}

/// [`walk_cameras`] with the path's orthographic option.
fn walk_cameras_with(store: &Store, ortho: Option<OrthoHeight>) -> Vec<Camera> {
    let options = PathOptions { frames: 72, part: PathPart::Walk, seed: 2, ortho, ..Default::default() };
    let path = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path;
    path.frames.iter().step_by(3).map(|f| f.to_scene(store.header()).unwrap()).collect()
}

/// The approach to an assembly (crates/tw-runtime/src/pathgen/approach.rs): from the overview
/// of the whole model to a close oblique view, spiralling in, in 16 frames.
fn approach_cameras(store: &Store) -> Vec<Camera> {
    approach_cameras_with(store, None)
}

/// [`approach_cameras`] with the path's orthographic option.
fn approach_cameras_with(store: &Store, ortho: Option<OrthoHeight>) -> Vec<Camera> {
    let options = PathOptions { frames: 16, part: PathPart::Approach, ortho, ..Default::default() };
    let path = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path;
    path.frames.iter().map(|f| f.to_scene(store.header()).unwrap()).collect()
}

/// What one strategy did over a camera list.
struct Run {
    strategy: Occlusion,
    /// `hzb`: triangles of visible clusters tested too (the default; in every other frame for
    /// the run that switches).
    triangle_culling: bool,
    /// `hzb`: the boxes tested above the clusters (in every frame).
    hierarchy: HierarchyOptions,
    /// Clusters culled, skeleton node boxes tested and found hidden (Alg. 3.4.1's node tests),
    /// triangles drawn.
    culled: u64,
    node_tests: u64,
    nodes_hidden: u64,
    triangles: u64,
}

/// Renders `cameras` of `store` with each strategy (the same cut: pages loaded before drawing;
/// `hzb` with triangle tests, without, and switching between the two every frame) and checks
/// every image against `none`, at `samples` per pixel.
fn compare(
    store: Arc<Store>,
    cameras: &[Camera],
    backends: wgpu::Backends,
    what: &str,
    samples: u32,
) -> Option<Vec<Run>> {
    // The last but one hzb run turns its triangle tests on and off every frame, keeping the
    // history; the last one tests every candidate's box on its own.
    let hierarchical = HierarchyOptions::default();
    let strategies = [
        (Occlusion::Hzb, Some(true), hierarchical),
        (Occlusion::Hzb, Some(false), hierarchical),
        (Occlusion::Queries, Some(true), hierarchical),
        (Occlusion::GpuHzb, Some(true), hierarchical),
        (Occlusion::Hzb, None, hierarchical),
        (Occlusion::Hzb, Some(true), HierarchyOptions::FLAT),
    ];
    compare_with(store, cameras, backends, what, samples, &strategies)
}

/// [`compare`] with the runs `strategies` (strategy, triangle tests: `None` every other frame,
/// hierarchy).
fn compare_with(
    store: Arc<Store>,
    cameras: &[Camera],
    backends: wgpu::Backends,
    what: &str,
    samples: u32,
    strategies: &[(Occlusion, Option<bool>, HierarchyOptions)],
) -> Option<Vec<Run>> {
    let _lock = gpu_lock();
    let mut baseline = Vec::new();
    let mut w = common::walkthrough(store, backends, what, 256 << 20)?;
    w.renderer_mut().set_samples(samples).unwrap();
    for c in cameras {
        let s = FrameSettings {
            tau: 1.0,
            occlusion: Occlusion::None,
            wait_for_pages: true,
            ..Default::default()
        };
        baseline.push(w.frame(c, &s).unwrap().0);
    }
    let mut runs = Vec::new();
    for &(strategy, tests, hierarchy) in strategies {
        w.reset();
        w.set_hzb_hierarchy(hierarchy, true);
        let mut run = Run {
            strategy,
            triangle_culling: tests != Some(false),
            hierarchy,
            culled: 0,
            node_tests: 0,
            nodes_hidden: 0,
            triangles: 0,
        };
        for (i, c) in cameras.iter().enumerate() {
            let triangle_culling = tests.unwrap_or(i % 2 == 0);
            let s = FrameSettings {
                tau: 1.0,
                occlusion: strategy,
                wait_for_pages: true,
                triangle_culling,
                ..Default::default()
            };
            let (image, info) = w.frame(c, &s).unwrap();
            let differing = image.differing_pixels(&baseline[i]).unwrap();
            assert_eq!(
                differing,
                0,
                "{what}, {} (triangle tests {triangle_culling}): frame {i} differs from --occlusion none in \
                 {differing} pixels",
                strategy.name()
            );
            assert!(image.covered_pixels() > 0, "{what}: frame {i} is empty");
            run.culled += info.occlusion.culled;
            run.node_tests += info.occlusion.node_tests;
            run.nodes_hidden += info.occlusion.nodes_hidden;
            run.triangles += info.triangles;
        }
        runs.push(run);
    }
    Some(runs)
}

fn conservative_on_a_walk(backends: wgpu::Backends, what: &str, samples: u32) {
    let cameras = walk_cameras(&plant());
    let Some(runs) = compare(plant(), &cameras, backends, what, samples) else { return };
    check_culling(&runs, cameras.len(), what, "inside the plant");
    // The plant's halls and tanks hide whole cells of its spatial hierarchy from a walker, so
    // the node tests must have culled some: else the hierarchy went untested.
    for r in &runs {
        if matches!(r.strategy, Occlusion::Queries | Occlusion::Hzb) && r.hierarchy.nodes {
            assert!(r.nodes_hidden > 0, "{what}: no node test culled anything: the hierarchy went untested");
        }
    }
}

/// What every run of smooth camera motion (`runs` over `frames` frames, `where_` for the
/// messages) must show besides identical images: each strategy culled clusters, the
/// hierarchical and flat tests drew the same triangles, and the triangle tests culled
/// triangles.
fn check_culling(runs: &[Run], frames: usize, what: &str, where_: &str) {
    for r in runs {
        eprintln!(
            "{what}, {} (triangle tests {}, {:?}): {} clusters culled over {} frames ({} of {} node boxes \
             hidden), {} triangles drawn",
            r.strategy.name(),
            r.triangle_culling,
            r.hierarchy,
            r.culled,
            frames,
            r.nodes_hidden,
            r.node_tests,
            r.triangles
        );
        assert!(r.culled > 0, "{what}, {}: culled nothing {where_}", r.strategy.name());
    }
    // The hierarchical tests cull what the flat test culls: the same triangles are drawn.
    let (hierarchical, flat) = (runs[0].triangles, runs[5].triangles);
    assert_eq!(
        hierarchical, flat,
        "{what}: hzb drew {hierarchical} triangles with node tests, {flat} without {where_}"
    );
    // The triangle tests must cull triangles, or the identical images above prove nothing
    // about them.
    let (with, without) = (runs[0].triangles, runs[1].triangles);
    assert!(
        with < without * 3 / 4,
        "{what}: hzb's triangle tests drew {with} triangles, whole clusters {without} {where_}"
    );
}

fn conservative_on_teleports(backends: wgpu::Backends, what: &str, samples: u32) {
    // Jumps between far-apart walk cameras: last frame's visible set is useless as occluders.
    let walk = walk_cameras(&plant());
    let cameras: Vec<Camera> = (0..8).map(|i| walk[(i * 7) % walk.len()]).collect();
    compare(plant(), &cameras, backends, what, samples);
}

/// Conservative on the approach to the assembly. No node box need be hidden there: the cells
/// of its card cage are slices of boards standing on edge, each box reaching from the board's
/// front panel, which the camera in front of the cabinet sees, to its rear connector; what
/// hzb culls are clusters behind the front panels (components, the backplane).
fn conservative_on_an_approach(backends: wgpu::Backends, what: &str, samples: u32) {
    let cameras = approach_cameras(&assembly());
    let Some(runs) = compare(assembly(), &cameras, backends, what, samples) else { return };
    check_culling(&runs, cameras.len(), what, "on the approach to the assembly");
}

fn conservative_on_assembly_teleports(backends: wgpu::Backends, what: &str) {
    // Jumps between the close view of the cabinet's roof and views of its front: last frame's
    // visible set hides nothing of the next.
    let approach = approach_cameras(&assembly());
    let cameras: Vec<Camera> = [15, 0, 12, 3, 9, 5, 14, 1].iter().map(|&i| approach[i]).collect();
    compare(assembly(), &cameras, backends, what, 1);
}

#[test]
fn occlusion_is_conservative_on_a_walk_vulkan() {
    conservative_on_a_walk(wgpu::Backends::VULKAN, "vulkan", 1);
}

#[test]
fn occlusion_is_conservative_on_a_walk_gl() {
    conservative_on_a_walk(wgpu::Backends::GL, "gl", 1);
}

#[test]
fn occlusion_is_conservative_on_teleports_vulkan() {
    conservative_on_teleports(wgpu::Backends::VULKAN, "vulkan", 1);
}

#[test]
fn occlusion_is_conservative_on_teleports_gl() {
    conservative_on_teleports(wgpu::Backends::GL, "gl", 1);
}

#[test]
fn occlusion_is_conservative_on_an_assembly_approach_vulkan() {
    conservative_on_an_approach(wgpu::Backends::VULKAN, "vulkan, assembly", 1);
}

#[test]
fn occlusion_is_conservative_on_an_assembly_approach_gl() {
    conservative_on_an_approach(wgpu::Backends::GL, "gl, assembly", 1);
}

#[test]
fn occlusion_is_conservative_on_assembly_teleports_vulkan() {
    conservative_on_assembly_teleports(wgpu::Backends::VULKAN, "vulkan, assembly");
}

/// Fails on llvmpipe GL, by draw order and not by culling: in frame 5 (approach frame 5,
/// after the close view of the roof) pixels (253, 260) and (256, 265) show, in `none`, a back
/// face of a 4.6 × 6 × 222 mm bar (x = 293.1 mm, page 69 cluster 63 triangle 21) and, in
/// `hzb` with triangle tests, the bar's top face (z = 416 mm, cluster 64 triangle 116), which
/// shares an edge with it. Both cover the pixel centres; the top face is nearer by 1.4·10⁻⁸ in
/// reverse-Z depth (6.131 against 6.117·10⁻⁶, about 4 mm at 1.8 m), far below GL's depth
/// rounding (`tw_gpu::GL_DEPTH_ROUNDING`, 4.8·10⁻⁷), so both are stored as 6.1186265·10⁻⁶ and
/// the `Greater` depth test keeps the first drawn. Drawing `none`'s clusters with only those
/// two swapped gives `hzb`'s image exactly. Vulkan stores the depths apart and passes.
#[test]
#[ignore = "GL depth rounding makes two faces of one small part tie; the winner is draw order"]
fn occlusion_is_conservative_on_assembly_teleports_gl() {
    conservative_on_assembly_teleports(wgpu::Backends::GL, "gl, assembly");
}

/// Through orthographic cameras: `gpu-hzb` (its HZB built and tested on the GPU), `hzb` and
/// `queries` give `none`'s images on the assembly approach and (`walk`) the plant walk made
/// orthographic as `terawalk path --ortho auto` makes them, and each culls something.
fn conservative_through_orthographic_cameras(backends: wgpu::Backends, what: &str, walk: bool) {
    let h = HierarchyOptions::default();
    let strategies = [
        (Occlusion::GpuHzb, Some(true), h),
        (Occlusion::Hzb, Some(true), h),
        (Occlusion::Queries, Some(true), h),
    ];
    let approach = approach_cameras_with(&assembly(), Some(OrthoHeight::Framed));
    let mut runs = vec![(assembly(), approach, "on an orthographic approach")];
    if walk {
        runs.push((
            plant(),
            walk_cameras_with(&plant(), Some(OrthoHeight::Framed)),
            "on an orthographic walk",
        ));
    }
    assert!(runs.iter().all(|r| r.1.iter().all(|c| c.is_orthographic())));
    for (store, cameras, where_) in runs {
        let Some(runs) = compare_with(store, &cameras, backends, what, 1, &strategies) else { return };
        for r in &runs {
            eprintln!(
                "{what}, {}: {} clusters culled {where_}, {} triangles drawn",
                r.strategy.name(),
                r.culled,
                r.triangles
            );
            assert!(r.culled > 0, "{what}, {}: culled nothing {where_}", r.strategy.name());
        }
    }
}

#[test]
fn occlusion_is_conservative_through_orthographic_cameras_vulkan() {
    conservative_through_orthographic_cameras(wgpu::Backends::VULKAN, "vulkan, orthographic", true);
}

/// GL on the approach only: on the orthographic walk, frame 5 differs from `none` in the same 3
/// pixels with every strategy (hzb with and without triangle tests, queries, gpu-hzb), so by
/// draw order and not by culling — the orthographic depth is linear over the whole plant, and
/// GL's depth rounding (`tw_gpu::GL_DEPTH_ROUNDING`) stores faces that close as equal, the
/// first drawn then winning the `Greater` test (as in the ignored assembly teleports on GL).
#[test]
fn occlusion_is_conservative_through_orthographic_cameras_gl() {
    conservative_through_orthographic_cameras(wgpu::Backends::GL, "gl, orthographic", false);
}

#[test]
fn occlusion_is_conservative_with_msaa_on_an_assembly_approach_vulkan() {
    conservative_on_an_approach(wgpu::Backends::VULKAN, "vulkan, 4 samples, assembly", 4);
}

#[test]
fn occlusion_is_conservative_with_msaa_on_a_walk_vulkan() {
    conservative_on_a_walk(wgpu::Backends::VULKAN, "vulkan, 4 samples", 4);
}

#[test]
fn occlusion_is_conservative_with_msaa_on_teleports_vulkan() {
    conservative_on_teleports(wgpu::Backends::VULKAN, "vulkan, 4 samples", 4);
}

/// `hzb`'s culling gives the same clusters drawn and hidden, and the same images, in a rayon
/// pool of one thread as in one of several (its tests, look-ups and history run in parallel).
fn parallel_equals_serial(store: Arc<Store>, cameras: &[Camera], backends: wgpu::Backends, what: &str) {
    let _lock = gpu_lock();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut w = common::walkthrough(store.clone(), backends, what, 256 << 20)?;
            w.set_hzb_hierarchy(HierarchyOptions::default(), true);
            let s = FrameSettings { occlusion: Occlusion::Hzb, wait_for_pages: true, ..Default::default() };
            let frames: Vec<(Vec<ClusterRef>, Vec<ClusterRef>, tw_gpu::Image)> = cameras
                .iter()
                .map(|c| {
                    let drawn = w.draw_frame(c, &s).unwrap();
                    (drawn.drawn, drawn.occluded, w.renderer_mut().read_color().unwrap())
                })
                .collect();
            Some(frames)
        })
    };
    let Some(serial) = run(1) else { return };
    let parallel = run(4).unwrap();
    assert!(serial.iter().any(|f| !f.1.is_empty()), "{what}: nothing culled");
    for (i, (s, p)) in serial.iter().zip(&parallel).enumerate() {
        assert_eq!((&s.0, &s.1), (&p.0, &p.1), "{what}: frame {i}: other clusters on 4 threads");
        assert_eq!(s.2.differing_pixels(&p.2).unwrap(), 0, "{what}: frame {i}: another image on 4 threads");
    }
}

#[test]
fn hzb_culling_on_one_thread_equals_several_vulkan() {
    parallel_equals_serial(plant(), &walk_cameras(&plant()), wgpu::Backends::VULKAN, "vulkan");
}

#[test]
fn hzb_culling_on_one_thread_equals_several_on_an_assembly_vulkan() {
    let cameras = approach_cameras(&assembly());
    parallel_equals_serial(assembly(), &cameras, wgpu::Backends::VULKAN, "vulkan, assembly");
}

/// The queries' visible-pixel cut-off: with sample counts (Vulkan) a cut-off culls at least
/// what 0 culls and changes few pixels (it is approximate: clusters showing ≤ N samples go);
/// with booleans (GL) it is ignored, so the images stay those of the conservative run.
fn visible_pixel_cutoff(backends: wgpu::Backends, what: &str, counts_samples: bool) {
    let _lock = gpu_lock();
    let cameras = walk_cameras(&plant());
    let Some(mut w) = common::walkthrough(plant(), backends, what, 256 << 20) else { return };
    let mut run = |cutoff: u32| {
        w.reset();
        let s = FrameSettings {
            occlusion: Occlusion::Queries,
            wait_for_pages: true,
            visible_pixels: cutoff,
            ..Default::default()
        };
        let frames: Vec<_> = cameras.iter().map(|c| w.frame(c, &s).unwrap()).collect();
        let culled: u64 = frames.iter().map(|(_, i)| i.occlusion.culled).sum();
        (frames.into_iter().map(|(img, _)| img).collect::<Vec<_>>(), culled)
    };
    let (exact, culled0) = run(0);
    let (approx, culled16) = run(16);
    let differing: usize = exact.iter().zip(&approx).map(|(a, b)| a.differing_pixels(b).unwrap()).sum();
    let pixels: usize = exact.iter().map(|i| (i.width * i.height) as usize).sum();
    eprintln!(
        "{what}: cut-off 16 samples: {culled16} culled (0: {culled0}), {differing} of {pixels} pixels differ"
    );
    if counts_samples {
        assert!(culled16 >= culled0, "{what}: a cut-off culled less ({culled16} < {culled0})");
        assert!(differing * 100 <= pixels, "{what}: {differing} of {pixels} pixels differ");
    } else {
        assert_eq!((culled16, differing), (culled0, 0), "{what}: GL has no sample counts");
    }
}

#[test]
fn visible_pixel_cutoff_vulkan() {
    visible_pixel_cutoff(wgpu::Backends::VULKAN, "vulkan", true);
}

#[test]
fn visible_pixel_cutoff_gl() {
    visible_pixel_cutoff(wgpu::Backends::GL, "gl", false);
}
