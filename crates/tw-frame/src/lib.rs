//! terawalk's frame pipeline (docs/DESIGN.md "Data flow": camera → select → occlude → stream →
//! draw), shared by `terawalk bench`, `terawalk render` and the viewer, so that every front end
//! draws a frame the same way and measures it the same way (docs/DESIGN.md "Measuring": frame time
//! is from the camera update to the image complete, waiting for the GPU).
//!
//! [`Walkthrough`] owns a store's [`Streamer`] (page cache, loader threads, selector) and a
//! [`Renderer`]. One [`Walkthrough::frame`]:
//! 1. **select and stream** ([`Streamer::frame`]): the LOD cut by pixel error with frustum
//!    culling over the resident pages — missing pages are requested by priority and their
//!    groups drawn by their best resident ancestors (the availability rule of docs/FORMAT.md), so
//!    the frame never waits for the disk; with [`FrameSettings::wait_for_pages`] the complete
//!    cut is loaded on the spot instead (`render`, tests, images compared across strategies);
//! 2. **occlude and draw** ([`occlude::draw_culled`]): the [`Occlusion`] strategy decides which clusters
//!    of the cut are drawn, then the image is read back;
//! 3. statistics of every stage in a [`FrameInfo`].
//!
//! [`Walkthrough::reference`] draws the full-detail scene without any culling (τ = 0, no
//! frustum, no occlusion), in chunks of pages so that memory stays within the budget whatever
//! the scene size: the image every fidelity figure is measured against.
//! [`Walkthrough::reference_supersampled`] ([`supersample`]) draws it on an s × s grid of
//! samples per pixel: the ground truth that both a LOD frame and the 1-sample full-detail frame
//! are measured against (`bench --reference-samples`).
//! [`Walkthrough::exact_visibility`] draws the same into the item buffer: the exact visible
//! objects and triangles (docs/DESIGN.md "Measuring").

mod gpu_hzb;
pub mod mask;
pub mod occlude;
pub mod pipeline;
pub mod popping;
pub mod remote;
pub mod shadow;
pub mod supersample;
pub mod traced;
pub mod transition;

use std::sync::Arc;
use std::time::{Duration, Instant};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tw_gpu::{ColorMode, GpuError, Image, PoolStats, Renderer, Target};
use tw_runtime::{
    Camera, ClusterRef, PageCache, ResidentPage, RuntimeError, Section, SelectOptions, SelectStats,
    Selection, StreamOptions, StreamStats, Streamer,
};
use tw_store::{PageCluster, Store};

pub use occlude::{Occlusion, OcclusionStats};
pub use pipeline::{Pipe, Pipeline, PipelinedFrame};
pub use shadow::{ShadowInfo, ShadowLod, ShadowSettings};
pub use transition::{DrawnState, Transition};

/// What a frame draws, apart from the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSettings {
    /// Pixel error threshold τ (docs/DESIGN.md, D3).
    pub tau: f32,
    pub frustum_culling: bool,
    pub occlusion: Occlusion,
    /// Load every page of the cut before drawing (the frame may wait for the disk) instead of
    /// streaming.
    pub wait_for_pages: bool,
    /// `queries` only: a candidate counts as visible only when more than this many of its
    /// samples pass — the occlusion switch's visible-pixel cut-off (Govindaraju's thesis §3.4).
    /// 0, the default, is conservative; above 0 culling is approximate (measure it with
    /// `bench --compare`). Needs sample counts: ignored on GL, whose queries are booleans.
    pub visible_pixels: u32,
    /// `hzb` only: test each triangle of a visible cluster against the pyramid too, and draw
    /// only those that can show a pixel ([`tw_runtime::triangle_test`]; conservative, on by
    /// default). Off: whole clusters, as GigaWalk draws whole objects.
    pub triangle_culling: bool,
    /// Shadows of a light (`--light`; [`shadow`]): `None` draws the unshadowed shading.
    pub shadows: Option<ShadowSettings>,
    /// Section planes and box (scene space, [`tw_runtime::section`]): culled by every
    /// selection of the frame (the eye's, the prefetch views', the shadow layers') and clipped
    /// per fragment by every pass the renderer draws.
    pub section: Section,
    /// How LOD switches are drawn (`--transition`, [`transition`]): at once, or cross-faded
    /// over a few frames. Only [`Walkthrough::draw_frame`] (and so the serial pipeline) fades.
    pub transition: Transition,
}

impl Default for FrameSettings {
    fn default() -> Self {
        FrameSettings {
            tau: 1.0,
            frustum_culling: true,
            occlusion: Occlusion::None,
            wait_for_pages: false,
            visible_pixels: 0,
            triangle_culling: true,
            shadows: None,
            section: Section::default(),
            transition: Transition::Pop,
        }
    }
}

/// Wall-clock time of each stage of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameTimes {
    /// Selection and streaming requests.
    pub select: Duration,
    /// Of which the frame's own cut (a streamed frame; with `wait_for_pages` all of `select`).
    #[serde(default)]
    pub select_cut: Duration,
    /// Of which the prefetch views' selections.
    #[serde(default)]
    pub select_prefetch: Duration,
    /// Occlusion culling: tests and the depth read-back or queries they need (drawing excluded).
    pub cull: Duration,
    /// Of `cull`, `hzb` only: the boxes' tests (nodes, groups, clusters), without the depth
    /// read-back, the pyramid and the triangle tests.
    #[serde(default)]
    pub cull_box_tests: Duration,
    /// Of `cull`, `hzb` only: the triangle tests.
    #[serde(default)]
    pub cull_triangle_tests: Duration,
    /// Of `cull`, `hzb` only: the depth read-back, which waits for the first pass to be drawn
    /// (so on a CPU driver it is rasterization, not culling).
    #[serde(default)]
    pub cull_readback: Duration,
    /// Making clusters resident on the GPU.
    pub upload: Duration,
    /// Drawing, waiting for the GPU, reading the image back.
    pub render: Duration,
    /// Camera update to image complete.
    pub total: Duration,
}

/// Everything one frame did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameInfo {
    pub times: FrameTimes,
    /// The LOD cut and frustum culling.
    pub select: SelectStats,
    /// Streaming: pages requested, loaded, evicted, bytes read, residency, stalls avoided.
    pub stream: StreamStats,
    /// Triangles of the LOD cut within the frustum (the clusters handed to occlusion culling;
    /// in a streamed frame, resident ancestors stand in for missing pages): what the LOD chose,
    /// before occlusion culling removes any.
    pub cut_triangles: u64,
    /// Triangles and clusters drawn (after occlusion culling).
    pub triangles: u64,
    /// Of `triangles`, those that passed the triangle tests (the rest are the gaps between
    /// runs that the draws bridge, [`tw_gpu::MAX_RUNS`]); equal to `triangles` without them.
    pub masked_triangles: u64,
    pub clusters: u64,
    pub draw_calls: u64,
    pub occlusion: OcclusionStats,
    /// The GPU cluster pool after the frame.
    pub gpu: PoolStats,
    /// The shadow stage (all zero without shadows); its time is part of `times.total`, not of
    /// the other stages.
    pub shadow: ShadowInfo,
}

impl FrameInfo {
    /// A culled frame's figures: `times`' selection parts, the cut's selection and streaming
    /// statistics and its triangles (`cut`), what occlusion culling did, what the renderer that
    /// drew it counted (`gpu`), and the frame's `total` time. No shadows.
    pub(crate) fn culled(
        times: FrameTimes,
        (select, stream, cut_triangles): (SelectStats, StreamStats, u64),
        culled: &Culled,
        gpu: &tw_gpu::FrameStats,
        total: Duration,
    ) -> FrameInfo {
        FrameInfo {
            times: FrameTimes {
                cull: culled.cull_time,
                cull_box_tests: culled.box_test_time,
                cull_triangle_tests: culled.triangle_test_time,
                cull_readback: culled.readback_time,
                upload: gpu.upload,
                render: gpu.render,
                total,
                ..times
            },
            select,
            stream,
            cut_triangles,
            triangles: gpu.triangles,
            masked_triangles: gpu.masked_triangles,
            clusters: gpu.clusters,
            draw_calls: gpu.draw_calls,
            occlusion: culled.stats,
            gpu: gpu.pool,
            shadow: ShadowInfo::default(),
        }
    }
}

/// Errors of a frame.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
    /// A parallel pipeline ([`pipeline`]) could not run, or stopped.
    #[error("pipeline: {0}")]
    Pipeline(String),
}

/// Exact visibility of one camera (full detail, no culling, item buffer).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExactVisibility {
    /// Distinct objects with at least one visible pixel.
    pub objects: u64,
    /// Distinct full-resolution triangles with at least one visible pixel.
    pub triangles: u64,
    /// Distinct clusters with at least one visible pixel.
    pub clusters: u64,
    pub covered_pixels: u64,
}

/// A store being walked through: the per-frame pipeline of the crate documentation.
pub struct Walkthrough {
    streamer: Streamer,
    renderer: Renderer,
    occlusion: occlude::OcclusionState,
    selection: Selection,
    /// The last frame's shadow layers (`None` without shadows).
    shadows: Option<tw_runtime::Shadows>,
    /// What the shadow stage keeps between frames: its layers and what they hold ([`shadow`]).
    shadow_cache: shadow::ShadowCache,
    /// The clusters fading in and out ([`transition`]).
    fades: transition::Fades,
    /// The last frame's fading-out clusters that it drew, and the fade words it drew with.
    faded: (Vec<ClusterRef>, Vec<(ClusterRef, u32)>),
    /// The view-projection of the last frame's camera (what it could show; [`transition`]).
    view: Option<glam::Mat4>,
}

impl Walkthrough {
    /// Prepares `store` for walking with `renderer`: decoded pages stay under
    /// `stream.budget_bytes` (root pages are loaded now and stay resident).
    pub fn new(
        store: Arc<Store>,
        mut renderer: Renderer,
        stream: StreamOptions,
    ) -> Result<Walkthrough, FrameError> {
        renderer.set_store_colors(&store);
        let streamer = Streamer::new(store, stream)?;
        Ok(Walkthrough {
            streamer,
            renderer,
            occlusion: occlude::OcclusionState::default(),
            selection: Selection::default(),
            shadows: None,
            shadow_cache: Default::default(),
            fades: Default::default(),
            faded: Default::default(),
            view: None,
        })
    }

    pub fn store(&self) -> &Arc<Store> {
        self.streamer.store()
    }

    pub fn streamer(&self) -> &Streamer {
        &self.streamer
    }

    pub fn streamer_mut(&mut self) -> &mut Streamer {
        &mut self.streamer
    }

    /// The shadow-map layers the last frame drew (`None` when it drew no shadows).
    pub fn last_shadows(&self) -> Option<&tw_runtime::Shadows> {
        self.shadows.as_ref()
    }

    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    pub fn renderer_mut(&mut self) -> &mut Renderer {
        &mut self.renderer
    }

    pub fn set_color_mode(&mut self, mode: ColorMode) {
        self.renderer.set_color_mode(mode);
    }

    /// Which boxes above the clusters `hzb` tests first (skeleton nodes and groups by default;
    /// [`HierarchyOptions::FLAT`](tw_runtime::occlusion::HierarchyOptions::FLAT) tests each
    /// candidate's own box), and whether in every frame (`forced`) or only while they pay (the
    /// default: measured as the queries' node tests, [`tw_runtime::NodeTestSwitch`]): to
    /// compare them; the image is the same.
    pub fn set_hzb_hierarchy(&mut self, options: tw_runtime::occlusion::HierarchyOptions, forced: bool) {
        self.occlusion.hierarchy = options;
        self.occlusion.hierarchy_forced = forced;
    }

    /// The clusters the last frame selected (its LOD cut within the frustum).
    pub fn selection(&self) -> &Selection {
        &self.selection
    }

    /// The light's LOD of a frame under the policy "the finer of both" ([`ShadowLod::Finer`]):
    /// measured in the layers of the frame before (they change little from frame to frame, and
    /// the metric only chooses levels, never what is shadowed); the first frame fits layers to
    /// its eye-LOD cut first. `None` under the eye's LOD or without shadows.
    fn light_lod(
        &mut self,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Option<tw_runtime::shadow::LightLod> {
        let shadows = settings.shadows.as_ref().filter(|s| s.lod == ShadowLod::Finer)?;
        if self.shadows.is_none() {
            let size = self.renderer.size();
            let Streamed { pages, .. } =
                select_and_stream(&mut self.streamer, &mut self.selection, camera, settings, size);
            let clusters = lookup(&pages, &self.selection.clusters);
            let store = self.streamer.store().clone();
            let bounds = |c: &ClusterRef| page_bounds(&pages, c);
            let viewport = [size.0, size.1];
            self.shadows =
                Some(shadow::fit_to_cut(shadows, store.header(), camera, viewport, &clusters, bounds));
        }
        let scene = shadow::scene_box(self.streamer.store().header());
        tw_runtime::shadow::LightLod::new(self.shadows.as_ref()?, camera, scene)
    }

    /// Forgets frame-to-frame state (occlusion history, camera history for prefetching): after
    /// a teleport or a change of settings.
    pub fn reset(&mut self) {
        self.occlusion.reset();
        self.fades.reset();
        self.view = None;
        self.shadow_cache = Default::default();
        self.streamer.reset_history();
    }

    /// Draws one frame of `camera` and returns its image and statistics:
    /// [`draw_frame`](Self::draw_frame), then the image read back (the frame time includes the
    /// GPU finishing the frame).
    pub fn frame(
        &mut self,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<(Image, FrameInfo), FrameError> {
        let start = Instant::now();
        let mut drawn = self.draw_frame(camera, settings)?;
        let image = self.renderer.read_color()?;
        drawn.info.times.render = self.renderer.stats().render;
        drawn.info.times.total = start.elapsed();
        Ok((image, drawn.info))
    }

    /// The reference image of `camera`: every full-resolution cluster, without frustum, LOD or
    /// occlusion culling, drawn in chunks of pages (decoded pages stay within the budget).
    pub fn reference(&mut self, camera: &Camera) -> Result<(Image, FrameInfo), FrameError> {
        let start = Instant::now();
        let selection = self.full_detail(camera);
        let select = start.elapsed();
        let grid_step = self.streamer.store().header().grid_step;
        self.renderer.begin_frame();
        let mut first = true;
        self.for_each_chunk(&selection, |renderer, clusters| {
            renderer.draw(Target::Own, camera, grid_step, clusters, first)?;
            first = false;
            Ok(())
        })?;
        if first {
            self.renderer.draw(Target::Own, camera, grid_step, &[], true)?;
        }
        let image = self.renderer.read_color()?;
        let gpu = self.renderer.stats();
        let info = FrameInfo {
            times: FrameTimes {
                select,
                select_cut: select,
                select_prefetch: Duration::ZERO,
                cull: Duration::ZERO,
                cull_box_tests: Duration::ZERO,
                cull_triangle_tests: Duration::ZERO,
                cull_readback: Duration::ZERO,
                upload: gpu.upload,
                render: gpu.render,
                total: start.elapsed(),
            },
            select: selection.stats,
            stream: StreamStats::default(),
            cut_triangles: gpu.triangles,
            triangles: gpu.triangles,
            masked_triangles: gpu.masked_triangles,
            clusters: gpu.clusters,
            draw_calls: gpu.draw_calls,
            occlusion: OcclusionStats::default(),
            gpu: gpu.pool,
            shadow: ShadowInfo::default(),
        };
        Ok((image, info))
    }

    /// Exact visibility of `camera`: the full-detail scene without culling drawn into the item
    /// buffer (in chunks, like [`reference`](Self::reference)); the ids left in it are the
    /// visible objects, clusters and triangles.
    pub fn exact_visibility(&mut self, camera: &Camera) -> Result<ExactVisibility, FrameError> {
        let selection = self.full_detail(camera);
        self.visible_in(camera, &selection)
    }

    /// Exact visibility of `camera`'s own LOD cut at pixel error `tau` (frustum culling on,
    /// pages loaded as needed, no occlusion culling): what the occlusion culling of a frame
    /// with this cut could at best draw. Against [`exact_visibility`](Self::exact_visibility)
    /// it separates the culling's excess from the LOD's (a cut's triangle stands for several
    /// full-detail ones, and may show where they do not).
    pub fn exact_visibility_of_cut(
        &mut self,
        camera: &Camera,
        tau: f32,
    ) -> Result<ExactVisibility, FrameError> {
        let (w, h) = self.renderer.size();
        let options = SelectOptions { tau, viewport: [w, h], frustum_culling: true, ..Default::default() };
        let selection = self.streamer.select_blocking(camera, &options);
        self.visible_in(camera, &selection)
    }

    /// The objects, clusters and triangles of `selection` left in the item buffer when all of
    /// it is drawn (in chunks).
    fn visible_in(&mut self, camera: &Camera, selection: &Selection) -> Result<ExactVisibility, FrameError> {
        let grid_step = self.streamer.store().header().grid_step;
        self.renderer.begin_frame();
        let mut first = true;
        let mut offset = 0u32;
        self.for_each_chunk(selection, |renderer, clusters| {
            renderer.draw_items(camera, grid_step, clusters, offset, first)?;
            first = false;
            offset += clusters.len() as u32;
            Ok(())
        })?;
        if first {
            return Ok(ExactVisibility::default());
        }
        let items = self.renderer.read_items(&selection.clusters)?;
        let v = items.visible();
        Ok(ExactVisibility {
            objects: v.objects.len() as u64,
            triangles: v.triangles,
            clusters: v.clusters.len() as u64,
            covered_pixels: v.covered_pixels,
        })
    }

    /// The full-detail, unculled cut (τ = 0, frustum off), pages loaded as needed. The
    /// occlusion history is kept: it only chooses the next frame's occluders, and any choice
    /// gives a conservative result, so a compared frame does not make the frame after it start
    /// from nothing.
    fn full_detail(&mut self, camera: &Camera) -> Selection {
        let (w, h) = self.renderer.size();
        let options =
            SelectOptions { tau: 0.0, viewport: [w, h], frustum_culling: false, ..Default::default() };
        self.streamer.select_blocking(camera, &options)
    }

    /// Calls `draw` on consecutive chunks of `selection`'s clusters, each chunk's pages taking at
    /// most a quarter of the cache budget, so the pages held while drawing stay bounded.
    fn for_each_chunk(
        &mut self,
        selection: &Selection,
        mut draw: impl FnMut(&mut Renderer, &[(ClusterRef, &PageCluster)]) -> Result<(), GpuError>,
    ) -> Result<(), FrameError> {
        let limit = (self.streamer.options().budget_bytes / 4).max(1);
        let store = self.streamer.store().clone();
        let cache = self.streamer.cache().clone();
        let all = &selection.clusters[..];
        // Pages are read and decoded ahead on every core, a window at a time, into the cache;
        // the loop below then finds them there. One page at a time on this thread, a reference
        // frame of the 10^8 plant (whose decoded full detail is larger than the cache) took
        // over 20 s on a 16-core host (docs/benchmarks-log.md, "On a real GPU").
        let window = 4 * rayon::current_num_threads();
        let mut warm_end = 0;
        let mut rest = all;
        while !rest.is_empty() {
            let mut pages: Vec<(u32, Arc<ResidentPage>)> = Vec::new();
            let mut bytes = 0u64;
            let mut n = 0;
            let done = all.len() - rest.len();
            for c in rest {
                if pages.last().map(|(p, _)| *p) != Some(c.page) {
                    if bytes >= limit {
                        break;
                    }
                    if done + n >= warm_end {
                        warm_end = warm_pages(&cache, &store, all, done + n, window);
                    }
                    match cache.get(&store, c.page) {
                        Ok(p) => {
                            bytes += p.bytes() as u64;
                            pages.push((c.page, p));
                        }
                        Err(e) => tracing::error!("cluster {c:?} skipped: {e}"),
                    }
                }
                n += 1;
            }
            pages.sort_by_key(|(p, _)| *p);
            pages.dedup_by_key(|(p, _)| *p);
            let clusters = lookup(&pages, &rest[..n]);
            draw(&mut self.renderer, &clusters)?;
            rest = &rest[n..];
        }
        Ok(())
    }
}

/// The pages a frame's cut needs, held while it is drawn, and how streaming went.
struct Streamed {
    /// Sorted by page.
    pages: Vec<(u32, Arc<ResidentPage>)>,
    stats: StreamStats,
    /// `None` for a blocking frame (`wait_for_pages`).
    times: Option<tw_runtime::StreamTimes>,
}

/// A frame's first step, shared by both renderers: the LOD cut of `camera` into `selection`
/// and the pages it needs — streamed (missing pages requested, resident ancestors drawn in their
/// place) or, with `wait_for_pages`, loaded on the spot.
fn select_and_stream(
    streamer: &mut Streamer,
    selection: &mut Selection,
    camera: &Camera,
    settings: &FrameSettings,
    (w, h): (u32, u32),
) -> Streamed {
    select_and_stream_lod(streamer, selection, camera, settings, (w, h), None)
}

/// [`select_and_stream`] with a light's LOD as well ([`SelectOptions::light_lod`]: the shadow
/// policy "the finer of both").
fn select_and_stream_lod(
    streamer: &mut Streamer,
    selection: &mut Selection,
    camera: &Camera,
    settings: &FrameSettings,
    (w, h): (u32, u32),
    light_lod: Option<tw_runtime::shadow::LightLod>,
) -> Streamed {
    let options = select_options(settings, [w, h], light_lod);
    if settings.wait_for_pages {
        let stats;
        (*selection, stats) = streamer.frame_blocking(camera, &options);
        Streamed { pages: resident_pages(streamer, &selection.clusters), stats, times: None }
    } else {
        let frame = streamer.frame(camera, &options);
        *selection = frame.selection;
        Streamed { pages: frame.pages, stats: frame.stats, times: Some(frame.times) }
    }
}

/// The selection options of a frame: its τ, viewport, frustum culling and section, and a light's
/// LOD.
fn select_options(
    settings: &FrameSettings,
    viewport: [u32; 2],
    light_lod: Option<tw_runtime::shadow::LightLod>,
) -> SelectOptions {
    SelectOptions {
        tau: settings.tau,
        viewport,
        frustum_culling: settings.frustum_culling,
        section: settings.section,
        light_lod,
    }
}

/// Loads the pages of `clusters[from..]` into `cache` in parallel, up to `pages` distinct ones
/// (errors are left for the caller's own [`PageCache::get`], which reports them); returns the
/// end of the clusters whose pages were loaded.
fn warm_pages(cache: &PageCache, store: &Store, clusters: &[ClusterRef], from: usize, pages: usize) -> usize {
    let mut ids: Vec<u32> = Vec::with_capacity(pages);
    let mut end = from;
    while let Some(c) = clusters.get(end) {
        if ids.last() != Some(&c.page) {
            if ids.len() == pages {
                break;
            }
            ids.push(c.page);
        }
        end += 1;
    }
    ids.par_iter().for_each(|&page| {
        let _ = cache.get(store, page);
    });
    end
}

/// The resident pages of `clusters` (loaded through the cache where needed), sorted by page.
fn resident_pages(streamer: &Streamer, clusters: &[ClusterRef]) -> Vec<(u32, Arc<ResidentPage>)> {
    let (store, cache) = (streamer.store(), streamer.cache());
    let mut pages: Vec<(u32, Arc<ResidentPage>)> = Vec::new();
    for c in clusters {
        if pages.last().map(|(p, _)| *p) != Some(c.page) {
            match cache.get(store, c.page) {
                Ok(p) => pages.push((c.page, p)),
                Err(e) => tracing::error!("cluster {c:?} skipped: {e}"),
            }
        }
    }
    pages.sort_by_key(|(p, _)| *p);
    pages.dedup_by_key(|(p, _)| *p);
    pages
}

/// The grid box of cluster `c` from `pages` (sorted by page), `None` when its page is not there.
fn page_bounds(pages: &[(u32, Arc<ResidentPage>)], c: &ClusterRef) -> Option<([u32; 3], [u32; 3])> {
    let i = pages.binary_search_by_key(&c.page, |(p, _)| *p).ok()?;
    pages[i].1.bounds.get(c.index_in_page as usize).copied()
}

/// The decoded clusters of `clusters`, in order, from `pages` (sorted by page); clusters whose
/// page is not there (failed) are skipped.
fn lookup<'a>(
    pages: &'a [(u32, Arc<ResidentPage>)],
    clusters: &[ClusterRef],
) -> Vec<(ClusterRef, &'a PageCluster)> {
    clusters
        .iter()
        .filter_map(|c| {
            let i = pages.binary_search_by_key(&c.page, |(p, _)| *p).ok()?;
            pages[i].1.clusters.get(c.index_in_page as usize).map(|pc| (*c, pc))
        })
        .collect()
}

/// Triangles of decoded clusters.
pub(crate) fn triangles(clusters: &[(ClusterRef, &PageCluster)]) -> u64 {
    clusters.iter().map(|(_, c)| (c.indices.len() / 3) as u64).sum()
}

/// A frame's selection times: `select` in all, of which the cut and the prefetch views as the
/// streamer measured them (`None`, a blocking frame: all of it the cut).
pub(crate) fn selection_times(select: Duration, stream: Option<tw_runtime::StreamTimes>) -> FrameTimes {
    FrameTimes {
        select,
        select_cut: stream.map_or(select, |t| t.cut),
        select_prefetch: stream.map_or(Duration::ZERO, |t| t.prefetch),
        ..Default::default()
    }
}

pub use occlude::Culled;

/// One frame drawn by [`Walkthrough::draw_frame`]: its statistics and which clusters were
/// drawn and found occluded; the image is in the renderer's own colour target.
#[derive(Clone, Debug, Default)]
pub struct DrawnFrame {
    pub info: FrameInfo,
    /// Clusters drawn (the cut after occlusion culling).
    pub drawn: Vec<ClusterRef>,
    /// Clusters of the cut hidden by occlusion culling.
    pub occluded: Vec<ClusterRef>,
}

/// The culling side of a frame, for a cull server ([`remote`]; the occlusion switch's culling
/// GPU): what a frame of `camera` would draw, without drawing it.
impl Walkthrough {
    /// The cut of `camera` (streamed, or loaded with `wait_for_pages`) and, for `hzb` and
    /// `queries`, its occluders drawn **depth only** and the candidates tested: the clusters a
    /// frame would draw (`drawn`) and those found hidden, as [`draw_frame`](Self::draw_frame)
    /// returns them, without the second pass or any colour. `none` draws nothing at all;
    /// `gpu-hzb`, whose tests feed its own draws, draws its frame as `draw_frame` does. The
    /// occlusion history is kept as a frame keeps it. Shadows are not culled here.
    pub fn cull_frame(
        &mut self,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<DrawnFrame, FrameError> {
        self.renderer.set_section(&settings.section);
        if settings.occlusion == Occlusion::GpuHzb {
            return self.draw_frame(camera, &FrameSettings { shadows: None, ..*settings });
        }
        let start = Instant::now();
        let store = self.streamer.store().clone();
        let size = self.renderer.size();
        let Streamed { pages, stats: stream, times: stream_times } =
            select_and_stream(&mut self.streamer, &mut self.selection, camera, settings, size);
        let select = start.elapsed();
        let clusters = lookup(&pages, &self.selection.clusters);
        let cut_triangles = triangles(&clusters);
        let culled = if settings.occlusion == Occlusion::None {
            self.renderer.begin_frame();
            Culled { drawn: clusters.iter().map(|c| c.0).collect(), ..Default::default() }
        } else {
            self.occlusion.visible_pixels = settings.visible_pixels;
            self.occlusion.triangle_culling = settings.triangle_culling;
            self.renderer.begin_frame();
            let bounds = |c: &ClusterRef| page_bounds(&pages, c);
            let (_, mut outcome) = occlude::cull_on(
                settings.occlusion,
                &mut self.occlusion,
                &mut self.renderer,
                &store,
                camera,
                &clusters,
                &bounds,
                true,
            )?;
            self.occlusion.finish(&mut outcome);
            outcome.culled
        };
        let select_times = selection_times(select, stream_times);
        let figures = (self.selection.stats, stream, cut_triangles);
        let info = FrameInfo::culled(select_times, figures, &culled, &self.renderer.stats(), start.elapsed());
        Ok(DrawnFrame { info, drawn: culled.drawn, occluded: culled.occluded })
    }
}

/// For interactive front ends (the viewer): frames without readback, a new streamer or
/// renderer without a new walkthrough.
impl Walkthrough {
    /// Replaces the streamer by one with `stream`'s options (a new memory budget, say): the
    /// resident pages are dropped (root pages loaded again) and the frame-to-frame state is
    /// forgotten. The old streamer's loaders finish their current page and stop.
    pub fn set_stream_options(&mut self, stream: StreamOptions) -> Result<(), FrameError> {
        let store = self.streamer.store().clone();
        self.streamer = Streamer::new(store, stream)?;
        self.selection = Selection::default();
        self.occlusion.reset();
        self.fades.reset();
        Ok(())
    }

    /// Replaces the renderer (an own target of another size, on the same device, say) and
    /// returns the old one; the store's object colours are set on the new one and the
    /// occlusion history is forgotten.
    pub fn replace_renderer(&mut self, mut renderer: Renderer) -> Renderer {
        renderer.set_store_colors(self.streamer.store());
        self.occlusion.reset();
        std::mem::replace(&mut self.renderer, renderer)
    }

    /// [`frame`](Self::frame) without reading the image back: the frame is left in the
    /// renderer's own colour target ([`Renderer::color_texture`]) for the caller to show or
    /// copy. With streaming it never waits for the disk; it waits for the GPU only where the
    /// occlusion strategy does (depth read-back for `hzb`, query results for `queries`).
    /// `times.render` and `times.total` therefore do not include the GPU finishing the frame.
    pub fn draw_frame(
        &mut self,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<DrawnFrame, FrameError> {
        self.renderer.set_section(&settings.section);
        let start = Instant::now();
        let store = self.streamer.store().clone();
        let light_lod = self.light_lod(camera, settings);
        let Streamed { pages, stats: stream, times: stream_times } = select_and_stream_lod(
            &mut self.streamer,
            &mut self.selection,
            camera,
            settings,
            self.renderer.size(),
            light_lod,
        );
        let select = start.elapsed();
        let pages = self.fade(camera, settings.transition, pages);
        let mut clusters = lookup(&pages, &self.selection.clusters);
        let cut_triangles = triangles(&clusters);
        clusters.extend(lookup(&pages, &self.faded.0));
        let bounds = |c: &ClusterRef| page_bounds(&pages, c);
        let shadow = match &settings.shadows {
            Some(shadows) => {
                let (w, h) = self.renderer.size();
                let options = select_options(settings, [w, h], light_lod);
                let receivers = shadow::receivers(settings.occlusion, &self.occlusion, &clusters);
                let (info, layers) = shadow::prepare(
                    shadows,
                    &mut self.streamer,
                    &mut self.renderer,
                    camera,
                    &options,
                    settings.wait_for_pages,
                    &receivers,
                    bounds,
                    &mut self.shadow_cache,
                )?;
                self.shadows = Some(layers);
                info
            }
            None => {
                shadow::clear(&mut self.renderer);
                self.shadows = None;
                self.shadow_cache = Default::default();
                ShadowInfo::default()
            }
        };
        self.occlusion.visible_pixels = settings.visible_pixels;
        self.occlusion.triangle_culling = settings.triangle_culling;
        let culled = occlude::draw_culled(
            settings.occlusion,
            &mut self.occlusion,
            &mut self.renderer,
            &store,
            camera,
            &clusters,
            bounds,
        );
        // The fades are this frame's: the passes drawn later (a reference, the item buffer)
        // draw whole clusters.
        self.renderer.set_fades([]);
        let culled = culled?;
        let select_times = selection_times(select, stream_times);
        let mut info = FrameInfo::culled(
            select_times,
            (self.selection.stats, stream, cut_triangles),
            &culled,
            &self.renderer.stats(),
            start.elapsed(),
        );
        info.shadow = shadow;
        Ok(DrawnFrame { info, drawn: culled.drawn, occluded: culled.occluded })
    }
}
