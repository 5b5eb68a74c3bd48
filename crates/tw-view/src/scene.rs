//! The scene of the viewer: the store and its [`tw_frame::Walkthrough`] (streamer + renderer on
//! the window's device), and the one place where a frame is selected and drawn
//! ([`Scene::frame`]). The viewer draws frames the way `terawalk bench` does:
//!
//! - **Streaming**: [`Walkthrough::draw_frame`] selects from the resident pages and never
//!   waits for the disk (missing pages are requested by priority, coarser resident ancestors
//!   drawn meanwhile). [`Scene::wants_redraw`] stays true while the cut still asks for pages or
//!   pages are in flight, so the app keeps drawing and the picture refines as data arrives.
//!   [`Scene::set_memory_budget`] rebuilds the streamer with the new budget. The HUD's figures
//!   come from the frame's [`StreamStats`] (pages pending + in flight, bytes read, resident
//!   bytes) and the renderer's [`tw_gpu::PoolStats`] (GPU memory under [`Settings::gpu_budget`]).
//! - **Occlusion**: the settings' [`tw_frame::Occlusion`], as `bench` runs it; the
//!   two-pass strategies need the renderer's *own* targets (depth read-back, queries against
//!   the own depth), so the frame is drawn into the own target and its colour is then copied
//!   into the scene's colour texture (`Rgba8UnormSrgb`, alpha 0 where nothing was drawn),
//!   which egui samples as a native texture behind the UI. Nothing is read back except for
//!   `hzb`'s depth, the query results and screenshots ([`Scene::read_image`]).
//! - **Debug view** (culling camera ≠ drawing camera) and **LOD freeze**: the cut is selected
//!   and occlusion-culled from the culling camera (into the own target), then the clusters it
//!   drew are drawn again from the drawing camera straight into the scene texture;
//!   [`Scene::visible_node_boxes`] / [`Scene::occluded_node_boxes`] give the nodes the debug
//!   view outlines (pink / yellow).
//! - **Hidden objects and the highlight** ([`Scene::set_filter`], [`Scene::set_highlight`]):
//!   with objects hidden or one isolated, the cut is selected without occlusion culling (a hidden
//!   object must not occlude what is behind it, and the renderer's occlusion tests know nothing
//!   of objects) and drawn again into the scene texture with a triangle mask per cluster (the
//!   debug view's path, [`tw_gpu::Renderer::draw_masked`]): a cluster mixes objects, so the
//!   filter works per triangle, and costs nothing while every object is shown. The picked
//!   object is tinted by the renderer in every colour mode ([`tw_gpu::Renderer::set_highlight`]).
//! - **Shadows** ([`Settings::shadows`], [`crate::settings::ShadowControls`]): each frame's
//!   `FrameSettings::shadows` is built from the controls — the sun's azimuth and elevation
//!   around the scene's up axis (the store's or `--up`'s) turned into a scene-space direction the
//!   way `--light sun:AZ,EL` is, a point light as it is — and tw-frame draws the shadow maps of
//!   the light-view sets before the eye's pass. The light is not part of what the cut is
//!   selected from: moving it draws the frame again without resetting the occlusion history or
//!   asking for a settling frame. With the LOD cut frozen the maps of the last selected frame
//!   stay. Ray traced, the same light goes to the tracer's shadow rays.
//! - **Ray tracing** ([`Settings::renderer`] `Rt`): [`crate::traced::TracedScene`] selects,
//!   streams and traces the frame on the CPU and keeps the running mean of its samples while
//!   the camera stands still; the mean is written into the scene texture
//!   (`Queue::write_texture`), so egui, screenshots and picking see it as they see a drawn
//!   frame. One renderer is kept at a time: switching drops the other's streamer (and GPU pool).

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use tw_frame::{FrameSettings, OcclusionStats, Walkthrough};
use tw_gpu::{Image, PoolStats, Renderer, Target};
use tw_runtime::{Camera, ClusterRef, ResidentPage, SelectStats, Selection, StreamOptions, StreamStats};
use tw_store::{Header, Store};

use crate::controller::SceneFrame;
use crate::error::ViewError;
use crate::pick::{pick_triangle, Ray, TriangleHit};
use crate::review::ObjectFilter;
use crate::settings::{RendererKind, Settings};
use crate::traced::TracedScene;

/// What [`Scene::frame`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameInfo {
    /// Whether the cut was selected again (not frozen).
    pub selected: bool,
    pub select_ms: f32,
    /// Occlusion tests with their read-backs / queries.
    pub cull_ms: f32,
    pub render_ms: f32,
    /// Triangles and clusters drawn (after occlusion culling).
    pub triangles: u64,
    pub clusters: u64,
    pub stats: SelectStats,
    pub stream: StreamStats,
    pub occlusion: OcclusionStats,
    /// The GPU cluster pool after the frame.
    pub gpu: PoolStats,
    /// Ray traced: samples per pixel in the image shown (0 when rasterized).
    pub samples: u32,
    /// The shadow stage (all zero without shadows, and when ray traced: shadow rays are part
    /// of `render_ms`); its time is not in the other stages' times.
    pub shadow: tw_frame::ShadowInfo,
}

/// What the current selection was made from.
#[derive(Clone, Debug, PartialEq)]
struct SelectKey {
    camera: Camera,
    tau: f32,
    frustum: bool,
    viewport: [u32; 2],
    occlusion: tw_frame::Occlusion,
    /// Selected with objects hidden (without occlusion culling).
    filtered: bool,
    /// The section it was culled by.
    section: tw_runtime::Section,
}

/// Format of the scene's colour texture. The renderer's own target is `Rgba8Unorm` holding the
/// same sRGB-encoded bytes; wgpu copies between formats that differ only in sRGB-ness.
pub const SCENE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// The scene's colour texture.
struct SceneTarget {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    size: [u32; 2],
}

/// The window's device, and what the scene made on it.
struct SceneGfx {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    /// What the adapter supports beyond the baseline (compute on GL, for `gpu-hzb`).
    downlevel: wgpu::DownlevelCapabilities,
    target: Option<SceneTarget>,
    /// Bumped whenever the target texture is made again (egui must be told).
    generation: u64,
}

impl SceneGfx {
    /// The colour texture, made again when the size changes.
    fn ensure_target(&mut self, size: [u32; 2]) {
        if self.target.as_ref().is_none_or(|t| t.size != size) {
            let texture = self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("scene colour"),
                size: wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: SCENE_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC
                    | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            });
            let view = texture.create_view(&Default::default());
            self.target = Some(SceneTarget { texture, view, size });
            self.generation += 1;
        }
    }

    fn renderer(&self, size: [u32; 2], gpu_budget: u64) -> Result<Renderer, ViewError> {
        let mut r = Renderer::from_device(
            self.device.clone(),
            self.queue.clone(),
            self.info.clone(),
            size[0],
            size[1],
        )?;
        r.set_gpu_budget(gpu_budget.max(tw_gpu::MIN_BUDGET));
        // Tells the renderer about compute on GL (gpu-hzb); the viewer keeps its draw mode.
        let mode = r.draw_mode();
        r.set_downlevel(&self.downlevel);
        r.set_draw_mode(mode);
        Ok(r)
    }
}

/// The store and everything a frame needs from it.
pub struct Scene {
    store: Arc<Store>,
    memory_budget: u64,
    /// Raise τ while the cut's pages would not fit the budget (`tw_runtime::fit`).
    fit_memory: bool,
    gfx: Option<SceneGfx>,
    /// Made at the first frame (its own target has the frame's size).
    walk: Option<Walkthrough>,
    /// The ray-traced mode's walkthrough and samples, made at its first frame.
    traced: Option<TracedScene>,
    /// The clusters the last selected frame drew, and those it found occluded.
    drawn: Vec<ClusterRef>,
    occluded: Vec<ClusterRef>,
    key: Option<SelectKey>,
    /// Encoded bytes read from the store so far (sum of the frames' `bytes_read`).
    bytes_read: u64,
    /// One more frame wanted (occlusion history after a change).
    settle: bool,
    /// The cut of the last selected frame (to see whether it changed).
    prev_cut: Vec<ClusterRef>,
    /// The GPU budget last asked for (the pool may clamp it to the device's limits).
    gpu_request: u64,
    last: FrameInfo,
    /// The up axis the camera follows: the store's, or `view --up`'s override.
    up_axis: u8,
    /// The objects drawn and picked.
    filter: ObjectFilter,
    /// The object to tint, and the one the renderer's colour table tints now (a new renderer
    /// starts with the store's colours).
    highlight: Option<u32>,
    /// Where named viewpoints are saved (default: next to the store).
    views_file: std::path::PathBuf,
    /// The section of the last selected frame: the pick looks through what it removes.
    section: tw_runtime::Section,
}

/// The resident pages of the `drawn` clusters, sorted by page number (pages no longer in
/// `cache` left out): a frame redrawn from another camera draws what it can of them.
fn resident_pages(drawn: &[ClusterRef], cache: &tw_runtime::PageCache) -> Vec<(u32, Arc<ResidentPage>)> {
    let mut pages: Vec<(u32, Arc<ResidentPage>)> = Vec::new();
    for c in drawn {
        if pages.last().is_none_or(|(p, _)| *p != c.page) {
            if let Some(p) = cache.try_get(c.page) {
                pages.push((c.page, p));
            }
        }
    }
    pages.sort_by_key(|(p, _)| *p);
    pages.dedup_by_key(|(p, _)| *p);
    pages
}

impl Scene {
    /// A scene over an opened store whose decoded pages stay within `memory_budget` bytes
    /// (the streamer starts with the first frame).
    pub fn new(store: Store, memory_budget: u64) -> Scene {
        let up_axis = store.header().up_axis.min(2);
        let views_file = crate::viewpoints::views_file(store.path());
        Scene {
            store: Arc::new(store),
            memory_budget,
            fit_memory: true,
            gfx: None,
            walk: None,
            traced: None,
            drawn: Vec::new(),
            occluded: Vec::new(),
            key: None,
            bytes_read: 0,
            settle: false,
            gpu_request: 0,
            prev_cut: Vec::new(),
            last: FrameInfo::default(),
            up_axis,
            filter: ObjectFilter::default(),
            highlight: None,
            views_file,
            section: Default::default(),
        }
    }

    /// The named viewpoints' file: `STORE.views.json` next to the store unless set here (a
    /// model opened through a build cache keeps its viewpoints next to the model instead).
    pub fn views_file(&self) -> &std::path::Path {
        &self.views_file
    }

    pub fn set_views_file(&mut self, file: std::path::PathBuf) {
        self.views_file = file;
    }

    /// The objects to draw (and pick) from the next frame on.
    pub fn set_filter(&mut self, filter: &ObjectFilter) {
        if *filter != self.filter {
            self.filter = filter.clone();
            self.key = None;
        }
    }

    pub fn filter(&self) -> &ObjectFilter {
        &self.filter
    }

    /// The object to tint from the next frame on (every colour mode).
    pub fn set_highlight(&mut self, object: Option<u32>) {
        self.highlight = object;
    }

    /// Overrides the store's up axis (0 x, 1 y, 2 z) for the camera and walk mode's gravity
    /// (`view --up`): the store is not changed.
    pub fn set_up_axis(&mut self, axis: u8) {
        self.up_axis = axis.min(2);
    }

    pub fn store(&self) -> &Store {
        &self.store
    }

    pub fn header(&self) -> &Header {
        self.store.header()
    }

    /// The model's bounds in scene space.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        tw_frame::shadow::scene_box(self.header())
    }

    /// The up axis as a unit vector: the store's, unless overridden ([`Scene::set_up_axis`]).
    pub fn up(&self) -> Vec3 {
        match self.up_axis {
            0 => Vec3::X,
            1 => Vec3::Y,
            _ => Vec3::Z,
        }
    }

    /// A scene-space point in input coordinates (the store's grid origin added back, in f64).
    pub fn input_position(&self, p: Vec3) -> [f64; 3] {
        let o = self.header().grid_origin;
        [o[0] + p.x as f64, o[1] + p.y as f64, o[2] + p.z as f64]
    }

    /// The store's units string (empty when it records none).
    pub fn units(&self) -> &str {
        self.store.units()
    }

    /// What the camera controllers need: bounds, up axis and metres per unit (the store's
    /// units; metres when it records none or ones [`tw_store::units`] does not know, as
    /// `terawalk path` assumes).
    pub fn scene_frame(&self) -> SceneFrame {
        SceneFrame {
            bounds: self.bounds(),
            up: self.up(),
            metres_per_unit: self.store.metres_per_unit().unwrap_or(1.0) as f32,
        }
    }

    /// The last frame's streaming statistics.
    pub fn stream_stats(&self) -> StreamStats {
        self.last.stream
    }

    /// Encoded bytes read from the store so far (for the HUD's disk rate).
    pub fn bytes_read(&self) -> u64 {
        self.bytes_read
    }

    pub fn memory_budget(&self) -> u64 {
        self.memory_budget
    }

    /// The renderer's GPU memory budget (0 before the first frame).
    pub fn gpu_budget(&self) -> u64 {
        self.walk.as_ref().map_or(0, |w| w.renderer().gpu_budget())
    }

    /// Pages asked for but not resident yet: pending in the loaders' queues + being loaded.
    pub fn pages_loading(&self) -> u64 {
        self.last.stream.pending + self.last.stream.in_flight
    }

    /// Whether the last frame is not final yet: its cut asked for pages, pages were being
    /// loaded, or the occlusion history is settling after a change. The app keeps redrawing
    /// meanwhile (the picture refines as the pages arrive).
    /// Ray traced, it also stays true while the still image gathers samples.
    pub fn wants_redraw(&self) -> bool {
        let streaming = self.last.stream.pages_requested > 0 || self.last.stream.in_flight > 0;
        if let Some(t) = &self.traced {
            return streaming || t.refining();
        }
        self.last.selected && (streaming || self.settle)
    }

    /// A new streamer with `bytes` of budget (the resident pages are dropped and reloaded as
    /// needed).
    pub fn set_memory_budget(&mut self, bytes: u64) -> Result<(), ViewError> {
        if bytes != self.memory_budget {
            self.memory_budget = bytes;
            self.restream(|o| StreamOptions { budget_bytes: bytes, ..o })?;
            // The ray tracer splits the budget between pages and BVHs: made again at its next frame.
            self.traced = None;
        }
        Ok(())
    }

    /// Whether τ is raised while the cut's pages would not fit the budget (`tw_runtime::fit`;
    /// on by default): off keeps the asked-for τ whatever the cache holds.
    pub fn set_fit_memory(&mut self, on: bool) -> Result<(), ViewError> {
        if on != self.fit_memory {
            self.fit_memory = on;
            self.restream(|o| StreamOptions { fit_budget: on, ..o })?;
        }
        Ok(())
    }

    pub fn fit_memory(&self) -> bool {
        self.fit_memory
    }

    /// A new streamer with the walkthrough's options changed by `change` (none is made before
    /// the first frame), and the next frame drawn anew.
    fn restream(&mut self, change: impl FnOnce(StreamOptions) -> StreamOptions) -> Result<(), ViewError> {
        if let Some(w) = self.walk.as_mut() {
            w.set_stream_options(change(*w.streamer().options()))?;
        }
        self.key = None;
        Ok(())
    }

    /// The last selected cut (before occlusion culling).
    pub fn selection(&self) -> Option<&Selection> {
        match (&self.walk, &self.traced) {
            (Some(w), _) => Some(w.selection()),
            (None, Some(t)) => Some(t.selection()),
            (None, None) => None,
        }
    }

    pub fn last_frame(&self) -> FrameInfo {
        self.last
    }

    /// Draws on the window's device (before this, [`frame`](Self::frame) fails); `downlevel`
    /// is its adapter's (`Adapter::get_downlevel_capabilities`).
    pub fn attach(
        &mut self,
        device: wgpu::Device,
        queue: wgpu::Queue,
        info: wgpu::AdapterInfo,
        downlevel: wgpu::DownlevelCapabilities,
    ) -> Result<(), ViewError> {
        self.gfx = Some(SceneGfx { device, queue, info, downlevel, target: None, generation: 0 });
        self.walk = None;
        Ok(())
    }

    /// The fastest conservative occlusion strategy on the window's device
    /// ([`tw_frame::Occlusion::fastest_conservative`]); `None` before [`attach`](Self::attach).
    pub fn fastest_occlusion(&self) -> Option<tw_frame::Occlusion> {
        let g = self.gfx.as_ref()?;
        let gpu_cull = Renderer::gpu_cull_possible(&g.downlevel);
        Some(tw_frame::Occlusion::fastest_conservative(g.info.device_type, gpu_cull))
    }

    pub fn adapter(&self) -> String {
        self.walk.as_ref().map(|w| w.renderer().adapter_summary()).unwrap_or_default()
    }

    /// The scene's colour texture, its size and generation (changes when it is made again).
    pub fn target(&self) -> Option<(&wgpu::TextureView, [u32; 2], u64)> {
        let g = self.gfx.as_ref()?;
        g.target.as_ref().map(|t| (&t.view, t.size, g.generation))
    }

    /// Reads the last frame back (for screenshots): waits for the GPU.
    pub fn read_image(&self) -> Result<Image, ViewError> {
        let g = self.gfx.as_ref().ok_or_else(|| ViewError::NoFrame("no renderer".into()))?;
        let t = g.target.as_ref().ok_or_else(|| ViewError::NoFrame("nothing drawn yet".into()))?;
        crate::readback::read_texture(&g.device, &g.queue, &t.texture, t.size)
    }

    /// Bytes of cluster geometry resident on the GPU after the last frame.
    pub fn gpu_bytes(&self) -> u64 {
        self.last.gpu.resident_bytes
    }

    /// Selects the cut from `cull` (unless the LOD cut is frozen), culls it with the settings'
    /// occlusion strategy, and shows it from `draw` at `size` pixels in the scene texture.
    pub fn frame(
        &mut self,
        cull: &Camera,
        draw: &Camera,
        settings: &Settings,
        size: [u32; 2],
    ) -> Result<FrameInfo, ViewError> {
        let size = [size[0].clamp(1, tw_gpu::MAX_SIDE), size[1].clamp(1, tw_gpu::MAX_SIDE)];
        if settings.renderer == RendererKind::Rt {
            return self.frame_traced(draw, settings, size);
        }
        self.traced = None;
        self.prepare_walk(settings, size)?;
        let filtered = !self.filter.is_all();
        // Hidden objects must not occlude: no occlusion culling while any is hidden.
        let occlusion = if filtered { tw_frame::Occlusion::None } else { settings.occlusion };
        let frozen = settings.lod_freeze && self.key.is_some();
        let mut info = if frozen {
            FrameInfo { selected: false, ..self.last }
        } else {
            self.select_and_draw(cull, settings, size, occlusion, filtered)?
        };
        self.gfx_mut()?.ensure_target(size);
        if frozen || cull != draw || filtered {
            self.redraw_drawn(draw, size, frozen, filtered, &mut info)?;
        } else {
            self.copy_own_target(size)?;
        }
        self.last = info;
        Ok(info)
    }

    /// The GPU context, or an error before a renderer is attached.
    fn gfx_mut(&mut self) -> Result<&mut SceneGfx, ViewError> {
        self.gfx.as_mut().ok_or_else(|| ViewError::Gpu("no renderer attached".into()))
    }

    /// Makes the walkthrough ready for a frame at `size`: made on the first frame, its renderer
    /// made again at a new size, the highlight, GPU budget and colour mode brought up to date.
    fn prepare_walk(&mut self, settings: &Settings, size: [u32; 2]) -> Result<(), ViewError> {
        let g = self.gfx.as_mut().ok_or_else(|| ViewError::Gpu("no renderer attached".into()))?;
        // The walkthrough, its own target at the frame's size.
        if self.walk.is_none() {
            let renderer = g.renderer(size, settings.gpu_budget)?;
            let options = StreamOptions {
                budget_bytes: self.memory_budget,
                fit_budget: self.fit_memory,
                ..Default::default()
            };
            self.walk = Some(Walkthrough::new(self.store.clone(), renderer, options)?);
            self.gpu_request = settings.gpu_budget;
            self.key = None;
        }
        let walk = self.walk.as_mut().expect("made above");
        let (ow, oh) = walk.renderer().size();
        if [ow, oh] != size {
            walk.replace_renderer(g.renderer(size, settings.gpu_budget)?);
            self.gpu_request = settings.gpu_budget;
            self.key = None;
        }
        walk.renderer_mut().set_highlight(self.highlight);
        if self.gpu_request != settings.gpu_budget {
            walk.renderer_mut().set_gpu_budget(settings.gpu_budget.max(tw_gpu::MIN_BUDGET));
            self.gpu_request = settings.gpu_budget;
        }
        walk.set_color_mode(settings.coloring.to_gpu());
        Ok(())
    }

    /// Selects the cut from `cull`, culls and draws it into the walkthrough's own target, and
    /// keeps what was drawn and occluded; notes whether one more frame is needed for the
    /// occlusion counts to settle. Returns the frame's figures.
    fn select_and_draw(
        &mut self,
        cull: &Camera,
        settings: &Settings,
        size: [u32; 2],
        occlusion: tw_frame::Occlusion,
        filtered: bool,
    ) -> Result<FrameInfo, ViewError> {
        let key = SelectKey {
            camera: *cull,
            tau: settings.pixel_error,
            frustum: settings.frustum_culling,
            viewport: size,
            occlusion,
            filtered,
            section: settings.section.section(),
        };
        self.section = key.section;
        let shadows = settings.shadows.frame_settings(self.store.header(), self.up_axis, cull);
        let walk = self.walk.as_mut().ok_or_else(|| ViewError::Gpu("no walkthrough".into()))?;
        let fs = FrameSettings {
            tau: settings.pixel_error,
            frustum_culling: settings.frustum_culling,
            occlusion,
            wait_for_pages: false,
            shadows,
            section: key.section,
            transition: settings.transition,
            ..Default::default()
        };
        let d = walk.draw_frame(cull, &fs)?;
        let t = &d.info.times;
        // The shadow stage is in the total only: drawing is what the other stages leave.
        let other_stages = t.select + t.cull + d.info.shadow.total;
        let info = FrameInfo {
            selected: true,
            select_ms: t.select.as_secs_f32() * 1e3,
            cull_ms: t.cull.as_secs_f32() * 1e3,
            render_ms: t.total.saturating_sub(other_stages).as_secs_f32() * 1e3,
            triangles: d.info.triangles,
            clusters: d.info.clusters,
            stats: d.info.select,
            stream: d.info.stream,
            occlusion: d.info.occlusion,
            gpu: d.info.gpu,
            samples: 0,
            shadow: d.info.shadow,
        };
        self.bytes_read += d.info.stream.bytes_read;
        self.drawn = d.drawn;
        self.occluded = d.occluded;
        // Occlusion culling tests what was not visible last frame: after a change of the camera
        // or of the cut (pages arrived), one more frame gives the settled counts.
        let cut = &walk.selection().clusters;
        let cut_changed = *cut != self.prev_cut;
        if cut_changed {
            self.prev_cut.clone_from(cut);
        }
        // A cross-fade in progress (`--transition dither`) goes on with the camera still.
        self.settle = walk.fading()
            || occlusion != tw_frame::Occlusion::None && (self.key.as_ref() != Some(&key) || cut_changed);
        self.key = Some(key);
        Ok(info)
    }

    /// Draws the clusters the culling camera drew, seen from the drawing camera `draw`, without
    /// the hidden objects' triangles, into the scene texture; `info` takes the draw's time and
    /// (for a frozen cut or hidden objects) its counts.
    fn redraw_drawn(
        &mut self,
        draw: &Camera,
        size: [u32; 2],
        frozen: bool,
        filtered: bool,
        info: &mut FrameInfo,
    ) -> Result<(), ViewError> {
        let t = Instant::now();
        let g = self.gfx.as_ref().ok_or_else(|| ViewError::Gpu("no renderer attached".into()))?;
        let target = g.target.as_ref().expect("made by ensure_target");
        let walk = self.walk.as_mut().ok_or_else(|| ViewError::Gpu("no walkthrough".into()))?;
        let pages = resident_pages(&self.drawn, walk.streamer().cache());
        let filter = &self.filter;
        let (clusters, masks): (Vec<_>, Vec<_>) = self
            .drawn
            .iter()
            .filter_map(|c| {
                let i = pages.binary_search_by_key(&c.page, |(p, _)| *p).ok()?;
                let pc = pages[i].1.clusters.get(c.index_in_page as usize)?;
                let mask = if filtered { filter.mask(&pc.objects) } else { u128::MAX };
                (mask != 0).then_some(((*c, pc), mask))
            })
            .unzip();
        let grid_step = self.store.header().grid_step;
        let r = walk.renderer_mut();
        r.begin_frame();
        let view = Target::View { view: &target.view, format: SCENE_FORMAT, size: (size[0], size[1]) };
        r.draw_masked(view, draw, grid_step, &clusters, filtered.then_some(&masks[..]), true)?;
        let ms = t.elapsed().as_secs_f32() * 1e3;
        info.render_ms = if frozen { ms } else { info.render_ms + ms };
        info.gpu = r.stats().pool;
        if frozen || filtered {
            info.triangles = r.stats().triangles;
            info.clusters = r.stats().clusters;
        }
        Ok(())
    }

    /// The walkthrough's own target's colour into the scene texture (no wait).
    fn copy_own_target(&mut self, size: [u32; 2]) -> Result<(), ViewError> {
        let g = self.gfx.as_ref().ok_or_else(|| ViewError::Gpu("no renderer attached".into()))?;
        let target = g.target.as_ref().expect("made by ensure_target");
        let walk = self.walk.as_mut().ok_or_else(|| ViewError::Gpu("no walkthrough".into()))?;
        let own = walk.renderer_mut().color_texture();
        let mut encoder =
            g.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("scene copy") });
        encoder.copy_texture_to_texture(
            own.as_image_copy(),
            target.texture.as_image_copy(),
            wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: 1 },
        );
        g.queue.submit([encoder.finish()]);
        Ok(())
    }

    /// Ray traces the frame from `draw` (the cut selected from it too) and shows the mean of
    /// its samples so far in the scene texture.
    fn frame_traced(
        &mut self,
        draw: &Camera,
        settings: &Settings,
        size: [u32; 2],
    ) -> Result<FrameInfo, ViewError> {
        let g = self.gfx.as_mut().ok_or_else(|| ViewError::Gpu("no renderer attached".into()))?;
        if self.traced.is_none() {
            // One renderer at a time: the rasterizer's streamer and GPU pool go.
            self.walk = None;
            self.key = None;
            self.traced = Some(TracedScene::new(self.store.clone(), size, self.memory_budget)?);
        }
        let light = settings.shadows.frame_settings(self.store.header(), self.up_axis, draw).map(|s| s.light);
        let traced = self.traced.as_mut().expect("made above");
        let out = traced.frame(draw, settings, light, size, self.highlight)?;
        let t = &out.info.times;
        let info = FrameInfo {
            selected: true,
            select_ms: t.select.as_secs_f32() * 1e3,
            render_ms: (t.upload + t.render).as_secs_f32() * 1e3,
            triangles: out.info.triangles,
            clusters: out.info.clusters,
            stats: out.info.select,
            stream: out.info.stream,
            samples: out.samples,
            ..Default::default()
        };
        tracing::debug!(
            "traced frame {}x{}: select {:.1} ms, BVHs {:.1} ms, trace and shade {:.1} ms, mean {:.1} ms, \
             total {:.1} ms; {} samples per pixel",
            size[0],
            size[1],
            info.select_ms,
            t.upload.as_secs_f32() * 1e3,
            t.render.as_secs_f32() * 1e3,
            out.mean_ms,
            t.total.as_secs_f32() * 1e3 + out.mean_ms,
            out.samples
        );
        self.bytes_read += info.stream.bytes_read;
        self.drawn.clone_from(&traced.selection().clusters);
        self.occluded.clear();
        g.ensure_target(size);
        if out.changed {
            let target = g.target.as_ref().expect("made above");
            g.queue.write_texture(
                target.texture.as_image_copy(),
                traced.image(),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(size[0] * 4),
                    rows_per_image: Some(size[1]),
                },
                wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: 1 },
            );
        }
        self.last = info;
        Ok(info)
    }

    /// Decoded clusters of `list` with their resident pages (nothing is loaded).
    fn resident<'a>(&self, list: &'a [ClusterRef]) -> Vec<(&'a ClusterRef, Arc<ResidentPage>)> {
        let cache = match (&self.walk, &self.traced) {
            (Some(w), _) => w.streamer().cache(),
            (None, Some(t)) => t.streamer().cache(),
            (None, None) => return Vec::new(),
        };
        let mut last: Option<(u32, Arc<ResidentPage>)> = None;
        let mut out = Vec::with_capacity(list.len());
        for r in list {
            if last.as_ref().is_none_or(|(p, _)| *p != r.page) {
                last = cache.try_get(r.page).map(|p| (r.page, p));
            }
            if let Some((p, page)) = &last {
                if *p == r.page {
                    out.push((r, page.clone()));
                }
            }
        }
        out
    }

    /// The triangles within `query` that walk mode collides with, into `out`: the full-detail
    /// clusters there and the last cut's (resident pages only; nothing is loaded, so nothing
    /// waits).
    pub fn gather_nearby(&self, query: &tw_collide::Aabb, out: &mut tw_collide::nearby::Nearby) {
        let cache = match (&self.walk, &self.traced) {
            (Some(w), _) => w.streamer().cache(),
            (None, Some(t)) => t.streamer().cache(),
            (None, None) => return out.gather(&self.store, query, &[], |_| None),
        };
        let cut = self.selection().map_or(&[][..], |s| &s.clusters[..]);
        out.gather(&self.store, query, cut, |p| cache.try_get(p));
    }

    /// Distance along `ray` to the nearest triangle drawn by the last frame (resident pages
    /// only; nothing is loaded; hidden objects are not hit).
    pub fn pick(&self, ray: &Ray, max_t: f32) -> Option<f32> {
        self.pick_triangle(ray, max_t).map(|h| h.t)
    }

    /// The nearest triangle of a shown object along `ray` among those the last frame drew, with
    /// its object id and corners (resident pages only).
    pub fn pick_triangle(&self, ray: &Ray, max_t: f32) -> Option<TriangleHit> {
        let step = self.header().grid_step;
        let resident = self.resident(&self.drawn);
        let items = resident.iter().filter_map(|(r, page)| {
            let c = page.clusters.get(r.index_in_page as usize)?;
            let (lo, hi) = page.bounds.get(r.index_in_page as usize)?;
            Some((tw_runtime::frustum::grid_box(*lo, *hi, step), c))
        });
        // With a section, the ray starts where it enters the kept part and ends where it
        // leaves it: hits on a removed side are not seen, as the renderer does not draw them.
        let (t0, t1) = self.section.ray_interval(ray.origin, ray.dir);
        let (t0, t1) = (t0.max(0.0), t1.min(max_t));
        if t0 > t1 {
            return None;
        }
        let kept = Ray { origin: ray.at(t0), dir: ray.dir };
        let hit = pick_triangle(&kept, items.collect::<Vec<_>>(), step, t1 - t0, |o| self.filter.shows(o))?;
        Some(TriangleHit { t: hit.t + t0, ..hit })
    }

    /// The scene-space box of object `id`'s triangles in the current cut's resident clusters
    /// (the store keeps no per-object bounds; this is the object as loaded at the current level
    /// of detail, within the view frustum when frustum culling is on), `None` when none is.
    pub fn object_box(&self, id: u32) -> Option<(Vec3, Vec3)> {
        let cut = &self.selection()?.clusters;
        let step = self.header().grid_step;
        let mut bounds: Option<(Vec3, Vec3)> = None;
        for (r, page) in self.resident(cut) {
            let Some(c) = page.clusters.get(r.index_in_page as usize) else { continue };
            for (tri, _) in c.indices.chunks_exact(3).zip(&c.objects).filter(|(_, &o)| o == id) {
                for &v in tri {
                    let Some(p) = c.positions.get(v as usize) else { continue };
                    let p = Vec3::from_array(p.map(|g| (g as f64 * step) as f32));
                    bounds = Some(bounds.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p))));
                }
            }
        }
        bounds
    }

    /// Scene-space boxes of the nodes that own a cluster the last frame drew (the visible
    /// nodes of the debug view, pink), at most `max`.
    pub fn visible_node_boxes(&self, max: usize) -> Vec<(Vec3, Vec3)> {
        self.node_boxes(&self.node_ids(&self.drawn), max)
    }

    /// Scene-space boxes of the nodes of the cut whose clusters were all found occluded (the
    /// debug view's yellow boxes), at most `max`.
    pub fn occluded_node_boxes(&self, max: usize) -> Vec<(Vec3, Vec3)> {
        let visible = self.node_ids(&self.drawn);
        let ids: Vec<u32> =
            self.node_ids(&self.occluded).into_iter().filter(|n| visible.binary_search(n).is_err()).collect();
        self.node_boxes(&ids, max)
    }

    /// The nodes owning `clusters`' groups, sorted, without repeats.
    fn node_ids(&self, clusters: &[ClusterRef]) -> Vec<u32> {
        let groups = self.store.groups();
        let mut ids: Vec<u32> =
            clusters.iter().filter_map(|c| groups.get(c.group as usize).map(|g| g.node)).collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    fn node_boxes(&self, ids: &[u32], max: usize) -> Vec<(Vec3, Vec3)> {
        let nodes = self.store.nodes();
        let step = self.header().grid_step;
        ids.iter()
            .filter_map(|&n| nodes.get(n as usize))
            .take(max)
            .map(|n| tw_runtime::frustum::grid_box(n.min, n.max, step))
            .collect()
    }
}
