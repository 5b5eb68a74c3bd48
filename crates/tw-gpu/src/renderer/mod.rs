//! The [`Renderer`]: its state, its settings and small accessors. The rest of it lives by
//! concern: [`device`] (opening it), [`targets`] (its colour, depth, item and multisampled
//! targets and their readback), [`passes`] (drawing a frame's clusters in batches),
//! [`classified`] (the draws of a cluster whose triangles have shadow classes), and the GPU
//! occlusion cull in [`crate::gpu_cull`].

mod classified;
mod device;
mod passes;
mod targets;

pub(crate) use passes::Eye;
pub use passes::MAX_RUNS;

use std::time::Duration;

use tw_store::Store;

use crate::draw::{IndirectArgs, Pipelines};
use crate::pool::ClusterPool;
use crate::readback::Readback;
use crate::{
    color, depth, gpu_cull, msaa, query, ClusterKey, ColorMode, DrawMode, PoolStats, DEFAULT_COLOR,
    GL_DEPTH_ROUNDING,
};
use device::adapter_summary;

/// What the current frame (since [`Renderer::begin_frame`]) drew and how long it took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameStats {
    pub clusters: u64,
    /// Triangles the draws hold: with masks, the masked triangles plus the gaps between runs
    /// that [`MAX_RUNS`] bridges.
    pub triangles: u64,
    /// Of `triangles`, those whose mask bit is set (all of an unmasked cluster's): what the
    /// draws would hold if every run were drawn on its own.
    pub masked_triangles: u64,
    /// Draw calls issued (one per cluster with [`DrawMode::Direct`], one per batch indirect).
    pub draw_calls: u64,
    /// Making clusters resident: building and uploading the ones not yet on the GPU (CPU time).
    pub upload: Duration,
    /// Encoding, submitting and, for the headless calls, waiting and reading back.
    pub render: Duration,
    /// The cluster pool: uploads, evictions, resident bytes, batches (the shadow-map passes'
    /// too: they share the pool).
    pub pool: PoolStats,
    /// Clusters drawn into the shadow map ([`Renderer::draw_shadow_map`]). The shadow-map
    /// passes count apart from the figures above, which are the eye's; their uploads count in
    /// `upload` and `pool` (the GPU copy of a cluster serves both).
    pub shadow_clusters: u64,
    /// Triangles drawn into the shadow map.
    pub shadow_triangles: u64,
    /// Draw calls of the shadow-map passes.
    pub shadow_draw_calls: u64,
    /// Encoding and submitting the shadow-map passes, and reading layers back.
    pub shadow_render: Duration,
}

/// Where a [`Renderer::draw`] goes.
#[derive(Clone, Copy, Debug)]
pub enum Target<'a> {
    /// The renderer's own colour and depth targets (read back with [`Renderer::read_color`]
    /// and [`Renderer::read_depth`]).
    Own,
    /// A caller's colour view of `format` and `size`; depth is the renderer's (one per size).
    View { view: &'a wgpu::TextureView, format: wgpu::TextureFormat, size: (u32, u32) },
}

#[derive(Clone, Copy)]
pub(crate) enum Pass<'a> {
    /// A shaded pass into `view`; `own` when that is the renderer's own colour target, whose
    /// multisampled colour is resolved only when it is read ([`Renderer::resolve_color`]).
    Shade {
        view: &'a wgpu::TextureView,
        format: wgpu::TextureFormat,
        own: bool,
    },
    Items,
    /// A depth-only pass of the eye into the own depth target (its colour is left as it was).
    EyeDepth,
    /// A depth-only pass into layer `layer` of the shadow map ([`crate::shadow`]).
    ShadowMap {
        layer: u32,
    },
}

/// The views one pass draws into: `color` (none for a shadow map; multisampled when `resolve`
/// is set: resolved into it at the end of each render pass) and `depth`, at `samples` per pixel.
#[derive(Clone)]
pub(crate) struct Attachments {
    pub(crate) color: Option<wgpu::TextureView>,
    pub(crate) resolve: Option<wgpu::TextureView>,
    pub(crate) depth: wgpu::TextureView,
    pub(crate) samples: u32,
}

/// The wgpu renderer; see the crate documentation.
pub struct Renderer {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) info: wgpu::AdapterInfo,
    pub(crate) width: u32,
    pub(crate) height: u32,
    color: wgpu::Texture,
    pub(crate) color_view: wgpu::TextureView,
    pub(crate) depth: wgpu::Texture,
    pub(crate) depth_view: wgpu::TextureView,
    /// Depth targets for caller views of other sizes than the own target: (size, view).
    extra_depth: Option<((u32, u32), wgpu::TextureView)>,
    items: Option<(wgpu::Texture, wgpu::TextureView)>,
    /// Number of the first cluster of the current [`Renderer::draw_items`] call.
    item_base: u32,
    pub(crate) readback: Readback,
    pub(crate) pipelines: Pipelines,
    pub(crate) uniforms: wgpu::Buffer,
    pub(crate) object_colors: wgpu::Buffer,
    object_color_count: u32,
    /// The object drawn tinted ([`Renderer::set_highlight`]).
    highlight: Option<u32>,
    /// The section every pass clips by ([`Renderer::set_section`]).
    pub(crate) section: tw_runtime::Section,
    /// The cross-fade words of the clusters that fade ([`Renderer::set_fades`]); every other
    /// cluster is drawn whole.
    pub(crate) fades: std::collections::HashMap<crate::pool::PoolKey, u32>,
    /// Whether the eye pipelines being chosen test the fade words (the passes' fading part,
    /// [`Renderer::set_fades`]).
    pub(crate) dither_pipelines: bool,
    pub(crate) bind_group: wgpu::BindGroup,
    pub(crate) bind_generation: u64,
    pub(crate) pool: ClusterPool,
    indirect: IndirectArgs,
    draw_mode: DrawMode,
    pub(crate) indirect_supported: bool,
    /// The device has `INDIRECT_FIRST_INSTANCE` (asked once: the shaded passes check it per
    /// partly shadowed cluster).
    pub(crate) first_instance_supported: bool,
    depth_copy: Option<depth::DepthCopy>,
    box_queries: Option<query::BoxQueries>,
    pub(crate) gpu_cull: Option<gpu_cull::GpuCull>,
    /// Compute shaders (`DownlevelFlags::COMPUTE_SHADERS`; on GL known after set_downlevel).
    pub(crate) compute_supported: bool,
    pub(crate) mode: ColorMode,
    pub(crate) stats: FrameStats,
    /// Whether the last draw went to the own target (so read_color / read_depth make sense).
    pub(crate) last_own: bool,
    /// The last batch submitted by [`Renderer::flush`], not yet known to be finished: the next
    /// flush waits for it (see there).
    in_flight: Option<wgpu::SubmissionIndex>,
    /// Samples per pixel of the shaded passes ([`msaa`]).
    pub(crate) samples: u32,
    /// Multisampled targets: the own target's, and one for a caller view's size and format.
    msaa_own: Option<msaa::MsaaTarget>,
    msaa_view: Option<msaa::MsaaTarget>,
    depth_resolve: Option<msaa::DepthResolve>,
    /// Whether the own single-sample depth lags behind the multisampled one (a shaded pass
    /// drew since the last resolve).
    pub(crate) depth_stale: bool,
    /// Whether the own colour target lags behind the multisampled colour. Passes into the own
    /// target do not resolve: a frame of two passes (occluders, then the rest) or of several
    /// batches would resolve every pass, and on lavapipe one resolve of 1280×720 at 4 samples
    /// costs ~6 ms. It is resolved once, when read ([`Renderer::read_color`],
    /// [`Renderer::color_texture`]) or before another target reuses the multisampled one.
    color_stale: bool,
    /// The shadow map, the shadows of the shaded passes and their per-slot classes.
    pub(crate) shadow: crate::shadow::ShadowState,
}

impl Renderer {
    /// Chooses how draws are issued; [`DrawMode::Indirect`] falls back to
    /// [`DrawMode::Direct`] where the device cannot execute indirect draws. Returns the mode in
    /// effect.
    pub fn set_draw_mode(&mut self, mode: DrawMode) -> DrawMode {
        self.draw_mode = if self.indirect_supported { mode } else { DrawMode::Direct };
        self.draw_mode
    }

    pub fn draw_mode(&self) -> DrawMode {
        self.draw_mode
    }

    /// Whether the shaded passes draw parts of a cluster by their own shadow class
    /// ([`Renderer::set_shadow_triangle_classes`]): they need indirect draws with a first
    /// instance (renderer/classified.rs). The GPU-culled pass draws clusters whole.
    pub fn refines_shadow_classes(&self) -> bool {
        self.draw_mode == DrawMode::Indirect && self.first_instance_supported
    }

    /// Whether the item buffer has triangle ids (`Features::PRIMITIVE_INDEX`).
    pub fn has_triangle_ids(&self) -> bool {
        self.pipelines.primitive_index
    }

    /// Sets the GPU-memory budget for resident cluster geometry (bytes; at least
    /// [`MIN_BUDGET`](crate::MIN_BUDGET)). Drops every resident cluster.
    pub fn set_gpu_budget(&mut self, bytes: u64) {
        self.pool = ClusterPool::new(&self.device, bytes, self.info.backend == wgpu::Backend::Gl);
        self.bind_generation = u64::MAX;
    }

    pub fn gpu_budget(&self) -> u64 {
        self.pool.budget()
    }

    /// The adapter in use.
    pub fn info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// "name (backend, device type)".
    pub fn adapter_summary(&self) -> String {
        adapter_summary(&self.info)
    }

    /// The device and queue in use (for callers that share them).
    pub fn device(&self) -> (&wgpu::Device, &wgpu::Queue) {
        (&self.device, &self.queue)
    }

    /// Size of the own target.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// What the current frame did so far.
    pub fn stats(&self) -> FrameStats {
        FrameStats { pool: self.pool.stats(), ..self.stats }
    }

    /// Object colours (sRGB) by object id; `None` entries and ids beyond the list get
    /// [`DEFAULT_COLOR`]. Lists beyond the device's storage-binding limit (32 M objects at
    /// 128 MiB) are cut there; later objects get the default colour.
    pub fn set_object_colors(&mut self, colors: impl IntoIterator<Item = Option<[u8; 4]>>) {
        let max = (self.device.limits().max_storage_buffer_binding_size as usize / 4).max(1);
        let mut packed: Vec<u32> =
            colors.into_iter().take(max).map(|c| color::pack(c.unwrap_or(DEFAULT_COLOR))).collect();
        self.object_color_count = packed.len() as u32;
        if packed.is_empty() {
            packed.push(color::pack(DEFAULT_COLOR));
        }
        self.object_colors = colors_buffer(&self.device, &self.queue, &packed);
        self.bind_generation = u64::MAX;
    }

    /// The object drawn tinted from the next frame on, in every colour mode: its colour
    /// half-way to `tw_core::color::HIGHLIGHT` before shading ([`tw_core::color::highlight`]);
    /// `None` tints nothing. A viewer's picked object.
    pub fn set_highlight(&mut self, object: Option<u32>) {
        self.highlight = object.filter(|&o| o != u32::MAX);
    }

    /// Clips every later pass (colour, depth, item buffer, shadow map) by `section`: the
    /// fragments on a removed side are discarded, and the back faces the cut reveals are drawn
    /// in the flat `tw_core::color::SECTION` colour. An empty section (the default) clips
    /// nothing and draws with the pipelines that have no clip test. The selection culls by the
    /// same section (`tw_runtime::SelectOptions::section`); this makes the cut exact.
    pub fn set_section(&mut self, section: &tw_runtime::Section) {
        self.section = *section;
    }

    /// Whether the passes clip by a section.
    pub(crate) fn sectioned(&self) -> bool {
        !self.section.is_empty()
    }

    /// Cross-fades the clusters of `fades` in every later eye pass (shaded colour, with or
    /// without shadows, and depth only), each keeping the pixels its fade word gives
    /// ([`crate::dither`]); the others are drawn whole. The shadow map and the item buffer
    /// draw whole clusters. With no fades (the default) the passes use the pipelines without
    /// the dither test.
    pub fn set_fades(&mut self, fades: impl IntoIterator<Item = (ClusterKey, u32)>) {
        self.fades.clear();
        self.fades
            .extend(fades.into_iter().filter(|(_, w)| *w != 0).map(|(k, w)| ((k.page, k.index_in_page), w)));
    }

    /// Whether the eye passes cross-fade some clusters ([`Renderer::set_fades`]).
    pub(crate) fn dithered(&self) -> bool {
        !self.fades.is_empty()
    }

    /// Whether cluster `key` fades.
    pub(crate) fn fades(&self, key: &ClusterKey) -> bool {
        self.fades.contains_key(&(key.page, key.index_in_page))
    }

    /// [`set_object_colors`](Self::set_object_colors) from the store's object table.
    pub fn set_store_colors(&mut self, store: &Store) {
        self.set_object_colors(store.objects().iter().map(|o| o.color));
    }

    /// Colours the next passes by `mode`; each mode is a shaded pipeline of its own, made the
    /// first time it draws (draw.wgsl `COLOR_MODE`).
    pub fn set_color_mode(&mut self, mode: ColorMode) {
        self.mode = mode;
    }

    /// Absolute rounding of the depths this renderer writes, beyond what the projection's
    /// f32 arithmetic gives: [`GL_DEPTH_ROUNDING`] on GL, 0 elsewhere (Vulkan writes z/w as
    /// the vertex stage computed it). For tests that compare a primitive's computed depth
    /// with the depth buffer (`tw_runtime::triangle_test`).
    pub fn depth_rounding(&self) -> f32 {
        if self.info.backend == wgpu::Backend::Gl {
            GL_DEPTH_ROUNDING
        } else {
            0.0
        }
    }

    /// Whether [`query_boxes`](Self::query_boxes) returns pixel counts (else 0/1: GL).
    pub fn queries_count_samples(&self) -> bool {
        self.info.backend != wgpu::Backend::Gl
    }
}

/// A buffer of packed object colours (at least 16 bytes: a binding may not be empty).
pub(crate) fn colors_buffer(device: &wgpu::Device, queue: &wgpu::Queue, packed: &[u32]) -> wgpu::Buffer {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("object colours"),
        size: (packed.len() as u64 * 4).max(16),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    queue.write_buffer(&buffer, 0, bytemuck::cast_slice(packed));
    buffer
}

/// The draw shaders' bind group: uniforms, the pool's slot table and the object colours (common.wgsl).
pub(crate) fn bind_group(
    device: &wgpu::Device,
    pipelines: &Pipelines,
    uniforms: &wgpu::Buffer,
    pool: &ClusterPool,
    colors: &wgpu::Buffer,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("clusters"),
        layout: &pipelines.bind_layout,
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: uniforms.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: pool.slot_buffer().as_entire_binding() },
            wgpu::BindGroupEntry { binding: 2, resource: colors.as_entire_binding() },
        ],
    })
}
