//! The scene of the viewer: the store, its page cache, the selector and the renderer, and the
//! one place where a frame is selected and drawn ([`Scene::frame`]).
//!
//! Integration points (each a single function, so the planned changes stay small):
//! - **Streaming**: [`Scene::select_cut`] calls the synchronous [`Selector::select_into`] over
//!   the [`PageCache`] (a miss loads the page on this thread, so a frame that needs new pages
//!   waits for them). The switch to tw-runtime's `Streamer` (branch helper-stream) is local to
//!   this module: the `cache`/`selector` fields become one `Streamer` (made from an
//!   `Arc<Store>` and `StreamOptions { budget_bytes, .. }`; [`Scene::set_memory_budget`] makes
//!   a new one), `select_cut` becomes `streamer.frame(camera, options)` keeping the
//!   `StreamFrame` (its `pages` feed [`upload_selection`] instead of `cache.get`),
//!   [`Scene::pages_loading`] returns `stats.pending + stats.in_flight`, the HUD's disk rate
//!   sums `stats.bytes_read`, and [`Scene::frame`] re-selects while pages are pending (the app
//!   already redraws while anything changes).
//! - **Rendering**: [`SceneRenderer`] wraps a `tw_gpu::Renderer` made with
//!   `Renderer::from_device` on the window's device ([`Scene::attach`]); each frame it uploads
//!   the cut and draws it with `render_to_view` into the scene's own colour texture
//!   (`Rgba8UnormSrgb`, alpha 0 where nothing was drawn), which egui samples as a native
//!   texture behind the UI. Nothing waits for the GPU and nothing is read back, except for a
//!   screenshot ([`Scene::read_image`]).
//! - **Occlusion**: [`crate::settings::OcclusionStrategy`]; only `None` is wired, the frustum-
//!   and LOD-culled cut is drawn as it is (occlusion-culled counts stay 0).

use std::time::Instant;

use glam::Vec3;
use tw_gpu::{Image, Renderer};
use tw_runtime::{CacheStats, Camera, PageCache, SelectOptions, SelectStats, Selection, Selector};
use tw_store::{Header, Store};

use crate::error::ViewError;
use crate::pick::{pick_clusters, Ray};
use crate::settings::Settings;

/// What [`Scene::frame`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameInfo {
    /// Whether the cut was selected again (not frozen, camera or settings changed).
    pub selected: bool,
    pub select_ms: f32,
    pub render_ms: f32,
    pub triangles: u64,
    pub clusters: u64,
    pub stats: SelectStats,
}

/// What the current selection was made from; the cut is re-selected when it changes.
#[derive(Clone, Debug, PartialEq)]
struct SelectKey {
    camera: Camera,
    tau: f32,
    frustum: bool,
    viewport: [u32; 2],
}

/// Format of the scene's colour texture.
pub const SCENE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// The scene's colour texture.
struct Target {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    size: [u32; 2],
}

/// The renderer behind the viewer (see the module documentation).
pub struct SceneRenderer {
    renderer: Renderer,
    device: wgpu::Device,
    queue: wgpu::Queue,
    target: Option<Target>,
    /// Bumped whenever the target texture is made again (egui must be told).
    generation: u64,
}

impl SceneRenderer {
    /// A renderer on the caller's device.
    pub fn new(
        device: wgpu::Device,
        queue: wgpu::Queue,
        info: wgpu::AdapterInfo,
        store: &Store,
    ) -> Result<SceneRenderer, ViewError> {
        // The renderer's own offscreen target is unused here (we draw into ours): keep it tiny.
        let mut renderer = Renderer::from_device(device.clone(), queue.clone(), info, 8, 8)?;
        renderer.set_store_colors(store);
        Ok(SceneRenderer { renderer, device, queue, target: None, generation: 0 })
    }

    /// The colour texture, made again when the size changes.
    fn ensure_target(&mut self, size: [u32; 2]) -> &Target {
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
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            let view = texture.create_view(&Default::default());
            self.target = Some(Target { texture, view, size });
            self.generation += 1;
        }
        self.target.as_ref().expect("made above")
    }

    pub fn adapter(&self) -> String {
        self.renderer.adapter_summary()
    }
}

/// The store and everything a frame needs from it.
pub struct Scene {
    store: Store,
    cache: PageCache,
    selector: Selector,
    selection: Selection,
    key: Option<SelectKey>,
    renderer: Option<SceneRenderer>,
    last: FrameInfo,
}

impl Scene {
    /// A scene over an opened store with a page cache of `memory_budget` bytes (root pages
    /// loaded now).
    pub fn new(store: Store, memory_budget: u64) -> Scene {
        let cache = PageCache::new(&store, memory_budget);
        cache.load_root_pages(&store);
        let selector = Selector::new(&store);
        Scene {
            store,
            cache,
            selector,
            selection: Selection::default(),
            key: None,
            renderer: None,
            last: FrameInfo::default(),
        }
    }

    pub fn store(&self) -> &Store {
        &self.store
    }

    pub fn header(&self) -> &Header {
        self.store.header()
    }

    /// The model's bounds in scene space.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let h = self.header();
        let o = glam::DVec3::from_array(h.grid_origin);
        (
            (glam::DVec3::from_array(h.bounds_min) - o).as_vec3(),
            (glam::DVec3::from_array(h.bounds_max) - o).as_vec3(),
        )
    }

    /// The store's up axis as a unit vector.
    pub fn up(&self) -> Vec3 {
        match self.header().up_axis {
            0 => Vec3::X,
            1 => Vec3::Y,
            _ => Vec3::Z,
        }
    }

    pub fn cache_stats(&self) -> CacheStats {
        self.cache.stats()
    }

    pub fn memory_budget(&self) -> u64 {
        self.cache.budget()
    }

    /// Pages asked for but not resident yet (0 with the synchronous cache).
    pub fn pages_loading(&self) -> u64 {
        self.cache.pending_requests() as u64
    }

    /// A new cache with `bytes` of budget (the resident pages are dropped and reloaded as
    /// needed).
    pub fn set_memory_budget(&mut self, bytes: u64) {
        if bytes != self.cache.budget() {
            self.cache = PageCache::new(&self.store, bytes);
            self.cache.load_root_pages(&self.store);
            self.key = None;
        }
    }

    pub fn selection(&self) -> &Selection {
        &self.selection
    }

    pub fn last_frame(&self) -> FrameInfo {
        self.last
    }

    /// Draws with a renderer on the window's device (before this, [`frame`](Self::frame)
    /// fails).
    pub fn attach(
        &mut self,
        device: wgpu::Device,
        queue: wgpu::Queue,
        info: wgpu::AdapterInfo,
    ) -> Result<(), ViewError> {
        self.renderer = Some(SceneRenderer::new(device, queue, info, &self.store)?);
        Ok(())
    }

    pub fn adapter(&self) -> String {
        self.renderer.as_ref().map(|r| r.adapter()).unwrap_or_default()
    }

    /// The scene's colour texture, its size and generation (changes when it is made again).
    pub fn target(&self) -> Option<(&wgpu::TextureView, [u32; 2], u64)> {
        let r = self.renderer.as_ref()?;
        r.target.as_ref().map(|t| (&t.view, t.size, r.generation))
    }

    /// Reads the last frame back (for screenshots): waits for the GPU.
    pub fn read_image(&self) -> Result<Image, ViewError> {
        let r = self.renderer.as_ref().ok_or_else(|| ViewError::NoFrame("no renderer".into()))?;
        let t = r.target.as_ref().ok_or_else(|| ViewError::NoFrame("nothing drawn yet".into()))?;
        crate::readback::read_texture(&r.device, &r.queue, &t.texture, t.size)
    }

    /// Bytes of vertex data the last frame uploaded (48 a triangle, see tw-gpu).
    pub fn gpu_bytes(&self) -> u64 {
        self.last.triangles * 48
    }

    /// THE selection call (streaming integration point, see the module documentation).
    fn select_cut(&mut self, camera: &Camera, options: &SelectOptions) {
        self.selector.select_into(&self.store, &self.cache, camera, options, &mut self.selection);
    }

    /// Selects the cut from `cull` (unless frozen or unchanged) and draws it from `draw` at
    /// `size` pixels.
    pub fn frame(
        &mut self,
        cull: &Camera,
        draw: &Camera,
        settings: &Settings,
        size: [u32; 2],
    ) -> Result<FrameInfo, ViewError> {
        let size = [size[0].clamp(1, tw_gpu::MAX_SIDE), size[1].clamp(1, tw_gpu::MAX_SIDE)];
        let key = SelectKey {
            camera: *cull,
            tau: settings.pixel_error,
            frustum: settings.frustum_culling,
            viewport: size,
        };
        let mut info = FrameInfo::default();
        let t = Instant::now();
        if self.key.is_none() || (!settings.lod_freeze && self.key.as_ref() != Some(&key)) {
            let options = SelectOptions {
                tau: settings.pixel_error,
                viewport: size,
                frustum_culling: settings.frustum_culling,
            };
            self.select_cut(cull, &options);
            self.key = Some(key);
            info.selected = true;
        }
        info.select_ms = t.elapsed().as_secs_f32() * 1e3;
        let t = Instant::now();
        let r = self.renderer.as_mut().ok_or_else(|| ViewError::Gpu("no renderer attached".into()))?;
        r.renderer.set_color_mode(settings.coloring.to_gpu());
        let pages = tw_gpu::SelectionPages::resolve(&self.store, &self.cache, &self.selection.clusters);
        r.ensure_target(size);
        let target = r.target.as_ref().expect("made above");
        let grid_step = self.store.header().grid_step;
        r.renderer.render_to_view(
            draw,
            grid_step,
            &pages.clusters(),
            &target.view,
            SCENE_FORMAT,
            (size[0], size[1]),
        )?;
        let rs = r.renderer.stats();
        info.render_ms = t.elapsed().as_secs_f32() * 1e3;
        info.triangles = rs.triangles;
        info.clusters = rs.clusters;
        info.stats = self.selection.stats;
        self.last = info;
        Ok(info)
    }

    /// Distance along `ray` to the nearest triangle of the current selection (resident pages
    /// only; nothing is loaded).
    pub fn pick(&self, ray: &Ray, max_t: f32) -> Option<f32> {
        let step = self.header().grid_step;
        let mut pages: Vec<(u32, std::sync::Arc<tw_runtime::ResidentPage>)> = Vec::new();
        for r in &self.selection.clusters {
            if pages.last().is_none_or(|(p, _)| *p != r.page) {
                if let Some(p) = self.cache.try_get(r.page) {
                    pages.push((r.page, p));
                }
            }
        }
        let items = self.selection.clusters.iter().filter_map(|r| {
            let (_, page) = pages.iter().rev().find(|(p, _)| *p == r.page)?;
            let c = page.clusters.get(r.index_in_page as usize)?;
            let (lo, hi) = page.bounds.get(r.index_in_page as usize)?;
            Some((tw_runtime::frustum::grid_box(*lo, *hi, step), c))
        });
        pick_clusters(ray, items.collect::<Vec<_>>(), step, max_t)
    }

    /// Scene-space boxes of the nodes that own a selected group (the visible nodes of the
    /// debug view), at most `max`.
    pub fn visible_node_boxes(&self, max: usize) -> Vec<(Vec3, Vec3)> {
        let groups = self.store.groups();
        let nodes = self.store.nodes();
        let step = self.header().grid_step;
        let mut ids: Vec<u32> = self
            .selection
            .clusters
            .iter()
            .filter_map(|c| groups.get(c.group as usize).map(|g| g.node))
            .collect();
        ids.sort_unstable();
        ids.dedup();
        ids.iter()
            .filter_map(|&n| nodes.get(n as usize))
            .take(max)
            .map(|n| tw_runtime::frustum::grid_box(n.min, n.max, step))
            .collect()
    }
}
