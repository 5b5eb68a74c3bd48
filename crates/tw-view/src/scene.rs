//! The scene of the viewer: the store, its page cache, the selector and the renderer, and the
//! one place where a frame is selected and drawn ([`Scene::frame`]).
//!
//! Integration points (each a single function, so the planned changes stay small):
//! - **Streaming**: [`Scene::select_cut`] calls the synchronous [`Selector::select_into`] over
//!   the [`PageCache`] (a miss loads the page on this thread). The asynchronous `Streamer`
//!   (background loaders, non-blocking select that draws the best resident ancestor) replaces
//!   that call and the cache field; the HUD's "pages loading" then reads its queue.
//! - **Rendering**: [`SceneRenderer`] wraps `tw_gpu::Renderer`. Stopgap until
//!   `Renderer::from_device` lands: a headless renderer on its own device renders and reads
//!   back an [`Image`], which the UI shows as an egui texture. With `from_device` the renderer
//!   shares the window's device and draws into a texture egui samples directly.
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

/// The renderer behind the viewer (see the module documentation).
pub struct SceneRenderer {
    renderer: Option<Renderer>,
    image: Option<Image>,
}

impl SceneRenderer {
    fn new() -> SceneRenderer {
        SceneRenderer { renderer: None, image: None }
    }

    /// A renderer of `size` pixels (made again when the size changes).
    fn ensure(&mut self, size: [u32; 2], store: &Store) -> Result<&mut Renderer, ViewError> {
        let ok = self.renderer.as_ref().is_some_and(|r| r.size() == (size[0], size[1]));
        if !ok {
            self.renderer = None;
            let mut r = Renderer::new_headless(size[0], size[1])?;
            r.set_store_colors(store);
            self.renderer = Some(r);
        }
        Ok(self.renderer.as_mut().expect("made above"))
    }

    pub fn adapter(&self) -> String {
        self.renderer.as_ref().map(|r| r.adapter_summary()).unwrap_or_default()
    }
}

/// The store and everything a frame needs from it.
pub struct Scene {
    store: Store,
    cache: PageCache,
    selector: Selector,
    selection: Selection,
    key: Option<SelectKey>,
    renderer: SceneRenderer,
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
            renderer: SceneRenderer::new(),
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

    pub fn adapter(&self) -> String {
        self.renderer.adapter()
    }

    /// The last rendered image.
    pub fn image(&self) -> Option<&Image> {
        self.renderer.image.as_ref()
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
        let renderer = self.renderer.ensure(size, &self.store)?;
        renderer.set_color_mode(settings.coloring.to_gpu());
        let image = renderer.render_selection(&self.store, &self.cache, draw, &self.selection)?;
        let rs = renderer.stats();
        self.renderer.image = Some(image);
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
