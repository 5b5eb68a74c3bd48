//! terawalk's GPU renderer (wgpu 30): draws the clusters a [`tw_runtime::Selector`] chose for a
//! frame (DESIGN "Data flow": camera → select → occlude → stream → draw; decision 5), headless
//! into its own offscreen target (for `terawalk render`, `bench`, tests) or into a caller's
//! texture view (the viewer's surface or egui texture), with the measurements of DESIGN
//! "Measuring" (item buffer, image comparison) and the GPU side of the occlusion strategies of
//! decision 6 (two-pass drawing with depth readback for `hzb`).
//!
//! Modules, one concern each:
//! - [`pool`]: clusters resident on the GPU in one pooled, indexed buffer under a byte budget,
//!   LRU eviction; only clusters not yet resident are uploaded each frame.
//! - [`draw`]: pipelines and batched draws (`multi_draw_indexed_indirect` or a `draw_indexed`
//!   loop, [`DrawMode`]); shading in draw.wgsl (headlight + fixed sun, [`ColorMode`]).
//! - [`ids`]: the item buffer and the exact visible sets.
//! - [`depth`]: reverse-Z depth readback for the CPU HZB.
//! - [`query`]: hardware occlusion queries of boxes against the frame's depth.
//! - [`gpu_cull`]: the GPU hierarchical Z-buffer built in compute shaders, the cull of
//!   candidate boxes against it feeding indirect draws in the same frame (`gpu-hzb`).
//! - [`msaa`]: 4× multisampling of the shaded passes, with the farthest-sample depth resolve
//!   the occlusion strategies read.
//! - [`image`]: RGBA images, PNG, PSNR and pixel differences.
//! - `readback`, [`color`], [`error`].
//!
//! A frame: [`Renderer::begin_frame`], then one or more [`Renderer::draw`] calls (the first
//! clears, later ones draw on top — the two passes of an occlusion-culled frame), then
//! [`Renderer::read_color`] / [`Renderer::read_depth`]. [`Renderer::render_clusters`] and
//! [`Renderer::render_selection`] do the whole single-pass frame and return an [`Image`];
//! [`Renderer::render_to_view`] draws into a caller's view and does not wait.
//!
//! Depth is reverse-Z ([`tw_runtime::Camera::projection_reverse_z`], `Greater`, clear 0).
//! Images: RGBA8 sRGB, rows from the top; alpha 255 where geometry was drawn, 0 elsewhere.
//!
//! What each backend gives (Mesa 22.3.6, tested by tests/frame.rs):
//!
//! | | Vulkan (lavapipe) | GL (llvmpipe) |
//! |---|---|---|
//! | batched draws | `multi_draw_indexed_indirect` | the same (wgpu loops over `glDrawElementsIndirect`); [`Renderer::from_device`] on GL needs [`Renderer::set_downlevel`] to use it |
//! | triangle ids in the item buffer | yes (`PRIMITIVE_INDEX`) | yes |
//! | depth readback | compute copy | compute copy |
//! | occlusion queries | sample counts | 0/1 |
//! | GPU HZB cull ([`gpu_cull`]) | compacted, `multi_draw_indexed_indirect_count` | in place (culled draws get 0 instances); needs GL 4.3 compute, known after [`Renderer::set_downlevel`] |
//! | 4× multisampling ([`Renderer::set_samples`]) | yes | refused (llvmpipe resolved to nothing) |
//! | reuse of evicted pool ranges | ordered by wgpu | the renderer waits for earlier GPU work first (see `draw_pass`) |

pub mod color;
pub mod depth;
pub mod draw;
pub mod error;
pub mod gpu_cull;
pub mod headless;
pub mod ids;
pub mod image;
pub mod msaa;
pub mod pool;
pub mod query;
mod readback;

use std::time::{Duration, Instant};

pub use wgpu;

use glam::Vec3;
use tw_runtime::{full_mask, Camera, ClusterRef, PageCache, Selection, TriangleMask};
use tw_store::{PageCluster, Store};

pub use color::{hash_color, level_color, ColorMode, BACKGROUND, DEFAULT_COLOR};
pub use depth::DepthImage;
pub use draw::DrawMode;
pub use error::GpuError;
pub use gpu_cull::GpuCullResult;
pub use ids::{ClusterVisibility, Item, ItemBuffer, VisibleSet};
pub use image::Image;
pub use msaa::SUPPORTED_SAMPLES;
pub use pool::{PoolStats, MIN_BUDGET};

use draw::{IndirectArgs, Pipelines, Uniforms, DEPTH_FORMAT, ITEM_FORMAT};
use pool::{ClusterPool, DrawArgs, Ensure, PoolKey};
use readback::Readback;

/// Identifies a cluster: its page, index in the page and group (as selected). The pool keys
/// clusters by (page, index in page).
pub type ClusterKey = ClusterRef;

/// The largest image side accepted.
pub const MAX_SIDE: u32 = 16384;

/// The default GPU-memory budget for resident cluster geometry (bytes).
pub const DEFAULT_GPU_BUDGET: u64 = 512 << 20;

/// The own colour target's format. Its bytes are sRGB-encoded, but by the vertex stage
/// (`srgb_encode` in draw.wgsl: colours are flat per triangle) rather than by the rasterizer on
/// every fragment write, which on llvmpipe cost a quarter of an interior frame (10^8 walk,
/// `stage_times`: 47.5 → 35.7 ms). Copies into an `Rgba8UnormSrgb` texture keep the meaning.
const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// Absolute rounding of a depth written on GL: wgpu's GL backend maps clip z to GL's −1..1
/// range in the vertex shader (z' = 2z − w) and the window transform maps it back, which leaves
/// a few ulps of 1.0 on every depth. (The identical-image test on llvmpipe failed by 4 pixels
/// when the triangle tests left it out.)
pub const GL_DEPTH_ROUNDING: f32 = 4.0 * f32::EPSILON;

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
    /// The cluster pool: uploads, evictions, resident bytes, batches.
    pub pool: PoolStats,
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

enum Pass<'a> {
    /// A shaded pass into `view`; `own` when that is the renderer's own colour target, whose
    /// multisampled colour is resolved only when it is read ([`Renderer::resolve_color`]).
    Shade {
        view: &'a wgpu::TextureView,
        format: wgpu::TextureFormat,
        own: bool,
    },
    Items,
}

/// The views one pass draws into: `color` (multisampled when `resolve` is set: resolved into
/// it at the end of each render pass) and `depth`, at `samples` per pixel.
#[derive(Clone)]
struct Attachments {
    color: wgpu::TextureView,
    resolve: Option<wgpu::TextureView>,
    depth: wgpu::TextureView,
    samples: u32,
}

/// The wgpu renderer; see the crate documentation.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    width: u32,
    height: u32,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth: wgpu::Texture,
    depth_view: wgpu::TextureView,
    /// Depth targets for caller views of other sizes than the own target: (size, view).
    extra_depth: Option<((u32, u32), wgpu::TextureView)>,
    items: Option<(wgpu::Texture, wgpu::TextureView)>,
    /// Number of the first cluster of the current [`Renderer::draw_items`] call.
    item_base: u32,
    readback: Readback,
    pipelines: Pipelines,
    uniforms: wgpu::Buffer,
    object_colors: wgpu::Buffer,
    object_color_count: u32,
    bind_group: wgpu::BindGroup,
    bind_generation: u64,
    pool: ClusterPool,
    indirect: IndirectArgs,
    draw_mode: DrawMode,
    indirect_supported: bool,
    depth_copy: Option<depth::DepthCopy>,
    box_queries: Option<query::BoxQueries>,
    gpu_cull: Option<gpu_cull::GpuCull>,
    /// Compute shaders (`DownlevelFlags::COMPUTE_SHADERS`; on GL known after set_downlevel).
    compute_supported: bool,
    mode: ColorMode,
    stats: FrameStats,
    /// Whether the last draw went to the own target (so read_color / read_depth make sense).
    last_own: bool,
    /// The last batch submitted by [`Renderer::flush`], not yet known to be finished: the next
    /// flush waits for it (see there).
    in_flight: Option<wgpu::SubmissionIndex>,
    /// Samples per pixel of the shaded passes ([`msaa`]).
    samples: u32,
    /// Multisampled targets: the own target's, and one for a caller view's size and format.
    msaa_own: Option<msaa::MsaaTarget>,
    msaa_view: Option<msaa::MsaaTarget>,
    depth_resolve: Option<msaa::DepthResolve>,
    /// Whether the own single-sample depth lags behind the multisampled one (a shaded pass
    /// drew since the last resolve).
    depth_stale: bool,
    /// Whether the own colour target lags behind the multisampled colour. Passes into the own
    /// target do not resolve: a frame of two passes (occluders, then the rest) or of several
    /// batches would resolve every pass, and on lavapipe one resolve of 1280×720 at 4 samples
    /// costs ~6 ms. It is resolved once, when read ([`Renderer::read_color`],
    /// [`Renderer::color_texture`]) or before another target reuses the multisampled one.
    color_stale: bool,
}

/// A batch is submitted (and waited for before the next is prepared) once it has uploaded a
/// `1 / UPLOADS_PER_BATCH` part of the GPU budget. Each upload is staged in host memory until
/// its submission has run, so without this a frame drawn in chunks (a reference frame) staged
/// up to a whole pool's worth per batch, with the previous batch's still held: on the 10^8
/// plant with `--memory 512M --gpu-memory 512M` the peak RSS was 2.63 GB, against 1.73 GB for
/// the cache, pool, skeleton and fixed parts. Ordinary frames upload far less and are not split.
const UPLOADS_PER_BATCH: u64 = 4;

/// Storage buffers the draw shaders' vertex stage binds (common.wgsl: the slot table and the
/// object colours).
const VERTEX_STORAGE_BUFFERS: u32 = 2;

impl Renderer {
    /// A renderer of `width` × `height` pixels on the first adapter of the backends in
    /// `WGPU_BACKEND` (e.g. `vulkan`, `gl`; default all).
    pub fn new_headless(width: u32, height: u32) -> Result<Renderer, GpuError> {
        Renderer::new_headless_with(width, height, wgpu::Backends::all().with_env())
    }

    /// [`Renderer::new_headless`] on the given backends (the environment is not consulted).
    pub fn new_headless_with(
        width: u32,
        height: u32,
        backends: wgpu::Backends,
    ) -> Result<Renderer, GpuError> {
        if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
            return Err(GpuError::Size { width, height, max: MAX_SIDE });
        }
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = backends;
        desc.flags = wgpu::InstanceFlags::default().with_env();
        let instance = wgpu::Instance::new(desc);
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter { backends: format!("{backends:?}"), reason: e.to_string() })?;
        let info = adapter.get_info();
        Renderer::check_adapter(&adapter)?;
        let limits = Renderer::device_limits(&adapter);
        if width > limits.max_texture_dimension_2d || height > limits.max_texture_dimension_2d {
            return Err(GpuError::Size { width, height, max: limits.max_texture_dimension_2d });
        }
        let features = adapter.features() & Renderer::optional_features();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("terawalk"),
            required_features: features,
            required_limits: limits,
            memory_hints: Renderer::memory_hints(),
            ..Default::default()
        }))
        .map_err(|source| GpuError::Device { adapter: adapter_summary(&info), source })?;
        tracing::info!("GPU adapter: {}", adapter_summary(&info));
        let mut r = Renderer::from_device(device, queue, info, width, height)?;
        r.set_downlevel(&adapter.get_downlevel_capabilities());
        Ok(r)
    }

    /// Refuses an adapter that cannot run the draw shaders: their vertex stage reads the slot
    /// table and the object colours from storage buffers (common.wgsl). wgpu's GL backend on
    /// NVIDIA's EGL driver offered a GLSL version without them (BENCHMARKS.md, "On a real
    /// GPU"), and its shader translation then panicked at the first pipeline; this turns that
    /// into a clear error before a device is opened.
    pub fn check_adapter(adapter: &wgpu::Adapter) -> Result<(), GpuError> {
        let info = adapter.get_info();
        let caps = adapter.get_downlevel_capabilities();
        let limits = adapter.limits();
        let missing = if !caps.flags.contains(wgpu::DownlevelFlags::VERTEX_STORAGE) {
            Some(
                "storage buffers in vertex shaders (GL 4.3 / GLES 3.1 with vertex storage blocks)"
                    .to_string(),
            )
        } else if limits.max_storage_buffers_per_shader_stage < VERTEX_STORAGE_BUFFERS {
            Some(format!(
                "{VERTEX_STORAGE_BUFFERS} storage buffers per shader stage (it has {})",
                limits.max_storage_buffers_per_shader_stage
            ))
        } else {
            None
        };
        match missing {
            Some(missing) => Err(GpuError::Unusable { adapter: adapter_summary(&info), missing }),
            None => Ok(()),
        }
    }

    /// The limits to open a device with (also for [`Renderer::from_device`]): wgpu's downlevel
    /// defaults raised to the adapter's texture size and buffer sizes. The downlevel default
    /// `max_buffer_size` (256 MiB) would silently cap the cluster pool, whose arena is one
    /// buffer, below a larger GPU budget.
    pub fn device_limits(adapter: &wgpu::Adapter) -> wgpu::Limits {
        let have = adapter.limits();
        wgpu::Limits {
            max_buffer_size: have.max_buffer_size,
            max_storage_buffer_binding_size: have.max_storage_buffer_binding_size,
            ..wgpu::Limits::downlevel_defaults().using_resolution(have)
        }
    }

    /// The memory hints to open a device with (also for [`Renderer::from_device`]): small
    /// device-memory blocks. wgpu's default (`Performance`) sub-allocates from 128–256 MiB blocks
    /// and keeps an emptied block for reuse; with the cluster pool's doubling arena that held
    /// 512 MiB of memory for a 256 MiB budget (measured with heaptrack on lavapipe, where device
    /// memory is process memory), so GPU memory would not stay within its budget.
    pub fn memory_hints() -> wgpu::MemoryHints {
        wgpu::MemoryHints::MemoryUsage
    }

    /// Features the renderer uses when the device has them (request them when opening a device
    /// for [`Renderer::from_device`]): `PRIMITIVE_INDEX` (triangle ids in the item buffer),
    /// `MULTI_DRAW_INDIRECT_COUNT` (compacted GPU-culled draws) and `TIMESTAMP_QUERY` (the GPU
    /// cull's compute time).
    pub fn optional_features() -> wgpu::Features {
        wgpu::Features::PRIMITIVE_INDEX
            | wgpu::Features::MULTI_DRAW_INDIRECT_COUNT
            | wgpu::Features::TIMESTAMP_QUERY
    }

    /// A renderer on a device the caller already has (a viewer's winit surface or egui-wgpu
    /// device; wgpu devices and queues are reference-counted handles: pass clones).
    /// `width` × `height` is the size of the renderer's own offscreen target, used by
    /// [`render_clusters`](Self::render_clusters) and [`Target::Own`];
    /// [`render_to_view`](Self::render_to_view) draws into any caller view instead.
    /// Indirect draws are used on all backends but GL, where the adapter must be asked:
    /// call [`set_downlevel`](Self::set_downlevel) with the adapter's capabilities.
    pub fn from_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        info: wgpu::AdapterInfo,
        width: u32,
        height: u32,
    ) -> Result<Renderer, GpuError> {
        let max = device.limits().max_texture_dimension_2d.min(MAX_SIDE);
        if width == 0 || height == 0 || width > max || height > max {
            return Err(GpuError::Size { width, height, max });
        }
        let color = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("colour target"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: COLOR_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let depth = depth_texture(&device, width, height);
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("uniforms"),
            size: std::mem::size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let object_colors = colors_buffer(&device, &queue, &[color::pack(DEFAULT_COLOR)]);
        let pipelines = Pipelines::new(&device);
        let pool = ClusterPool::new(&device, DEFAULT_GPU_BUDGET, info.backend == wgpu::Backend::Gl);
        let bind_group = bind_group(&device, &pipelines, &uniforms, &pool, &object_colors);
        let indirect_supported = info.backend != wgpu::Backend::Gl;
        Ok(Renderer {
            color_view: color.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            color,
            depth,
            extra_depth: None,
            items: None,
            item_base: 0,
            readback: Readback::default(),
            pipelines,
            uniforms,
            object_colors,
            object_color_count: 0,
            bind_group,
            bind_generation: pool.generation,
            pool,
            indirect: IndirectArgs::default(),
            draw_mode: if indirect_supported { DrawMode::Indirect } else { DrawMode::Direct },
            indirect_supported,
            depth_copy: None,
            box_queries: None,
            gpu_cull: None,
            compute_supported: indirect_supported,
            mode: ColorMode::default(),
            stats: FrameStats::default(),
            last_own: false,
            in_flight: None,
            samples: 1,
            msaa_own: None,
            msaa_view: None,
            depth_resolve: None,
            depth_stale: false,
            color_stale: false,
            device,
            queue,
            info,
            width,
            height,
        })
    }

    /// Tells the renderer what the adapter supports (indirect execution and compute shaders on
    /// GL), and picks [`DrawMode::Indirect`] when it does.
    /// Whether a device with `caps` can run [`Renderer::draw_gpu_culled`] (compute shaders and
    /// indirect draws): [`Renderer::gpu_cull_supported`] before a renderer exists.
    pub fn gpu_cull_possible(caps: &wgpu::DownlevelCapabilities) -> bool {
        caps.flags.contains(wgpu::DownlevelFlags::INDIRECT_EXECUTION | wgpu::DownlevelFlags::COMPUTE_SHADERS)
    }

    pub fn set_downlevel(&mut self, caps: &wgpu::DownlevelCapabilities) {
        self.indirect_supported = caps.flags.contains(wgpu::DownlevelFlags::INDIRECT_EXECUTION);
        self.compute_supported = caps.flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS);
        self.draw_mode = if self.indirect_supported { DrawMode::Indirect } else { DrawMode::Direct };
    }

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

    /// Whether the item buffer has triangle ids (`Features::PRIMITIVE_INDEX`).
    pub fn has_triangle_ids(&self) -> bool {
        self.pipelines.primitive_index
    }

    /// Sets the samples per pixel of the shaded passes: 1, or 4 for 4× multisampling
    /// ([`msaa`]; its targets take 8 bytes × samples a pixel more GPU memory). The item buffer
    /// stays single-sample. Call between frames. Not on GL: wgpu's GL backend on llvmpipe
    /// resolved multisampled frames to nothing or to one sample (tests/frame.rs `msaa_gl`).
    pub fn set_samples(&mut self, samples: u32) -> Result<(), GpuError> {
        if !SUPPORTED_SAMPLES.contains(&samples) {
            return Err(GpuError::Gpu(format!(
                "{samples} samples per pixel are not supported (use one of {SUPPORTED_SAMPLES:?})"
            )));
        }
        if samples > 1 && !self.multisampling_supported() {
            return Err(GpuError::Gpu(format!(
                "multisampling is not supported on the {:?} backend (use Vulkan: WGPU_BACKEND=vulkan)",
                self.info.backend
            )));
        }
        if samples != self.samples {
            self.samples = samples;
            self.msaa_own = None;
            self.msaa_view = None;
            self.depth_resolve = None;
            self.box_queries = None;
            self.depth_stale = false;
            self.color_stale = false;
        }
        Ok(())
    }

    /// Whether [`Renderer::set_samples`] accepts more than one sample (every backend but GL).
    pub fn multisampling_supported(&self) -> bool {
        self.info.backend != wgpu::Backend::Gl
    }

    /// The samples per pixel `--samples auto` picks: 4 on a real GPU that can multisample (the
    /// fidelity goal's setting; it cost 17–26 % of the frame on an NVIDIA H200 against 2–3× on
    /// lavapipe, BENCHMARKS.md "On a real GPU"), 1 on CPU drivers and on GL.
    pub fn default_samples(&self) -> u32 {
        if self.multisampling_supported() && self.info.device_type != wgpu::DeviceType::Cpu {
            4
        } else {
            1
        }
    }

    /// Samples per pixel of the shaded passes ([`Renderer::set_samples`]).
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Where those samples lie in a pixel (x, y from its top-left corner): what the CPU
    /// occlusion tests take ([`tw_runtime::hzb::Hzb::with_samples`]) to stay conservative.
    pub fn sample_positions(&self) -> &'static [[f32; 2]] {
        tw_runtime::hzb::sample_positions(self.samples).expect("set_samples accepts only these")
    }

    /// Sets the GPU-memory budget for resident cluster geometry (bytes; at least
    /// [`MIN_BUDGET`]). Drops every resident cluster.
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

    /// The own colour target (`Rgba8Unorm` holding sRGB-encoded bytes, usage
    /// `RENDER_ATTACHMENT | COPY_SRC`): a viewer copies it into the (`Rgba8UnormSrgb`) texture
    /// it shows after drawing to [`Target::Own`] (no readback, no wait). With multisampling the
    /// frame's colour is resolved into it first (submitted, not waited for).
    pub fn color_texture(&mut self) -> &wgpu::Texture {
        self.resolve_color();
        &self.color
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

    /// [`set_object_colors`](Self::set_object_colors) from the store's object table.
    pub fn set_store_colors(&mut self, store: &Store) {
        self.set_object_colors(store.objects().iter().map(|o| o.color));
    }

    /// Colours the next passes by `mode`; each mode is a shaded pipeline of its own, made the
    /// first time it draws (draw.wgsl `COLOR_MODE`).
    pub fn set_color_mode(&mut self, mode: ColorMode) {
        self.mode = mode;
    }

    /// Starts a frame: resets the stats; clusters drawn from now on are this frame's (the pool
    /// evicts only clusters not drawn in the current frame).
    pub fn begin_frame(&mut self) {
        self.pool.begin_frame();
        self.stats = FrameStats::default();
    }

    /// Draws `clusters` from `camera` into `target`: clusters not resident are uploaded first
    /// (positions are grid coordinates × `grid_step`, scene space). With `clear` the colour and
    /// depth targets are cleared first (colour to transparent black, depth to 0); without, the
    /// clusters are drawn on top of what the frame drew before (depth-tested against it). When
    /// the selection exceeds the GPU budget it is drawn in several batches (see [`pool`]).
    /// Submits without waiting. Malformed triangles (an index beyond the vertices) are skipped.
    pub fn draw(
        &mut self,
        target: Target<'_>,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        clear: bool,
    ) -> Result<(), GpuError> {
        self.draw_masked(target, camera, grid_step, clusters, None, clear)
    }

    /// [`draw`](Self::draw) of only some triangles: with `masks`, cluster `i` draws the
    /// triangles whose bits are set in `masks[i]` (bit `t` = triangle `t`; `u128::MAX` = all;
    /// see [`tw_runtime::triangle_test`]). A partial cluster is drawn as runs of consecutive
    /// triangles straight from its pooled index range (no copy), gaps of up to [`RUN_GAP`]
    /// triangles bridged to save draws; the frame's triangle count counts what was drawn.
    pub fn draw_masked(
        &mut self,
        target: Target<'_>,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        masks: Option<&[TriangleMask]>,
        clear: bool,
    ) -> Result<(), GpuError> {
        match target {
            Target::Own => {
                let view = self.color_view.clone();
                self.last_own = true;
                let size = (self.width, self.height);
                let pass = Pass::Shade { view: &view, format: COLOR_FORMAT, own: true };
                self.depth_stale = self.samples > 1;
                self.draw_pass(None, pass, size, camera, grid_step, clusters, masks, clear)
            }
            Target::View { view, format, size } => {
                self.last_own = false;
                self.draw_pass(
                    None,
                    Pass::Shade { view, format, own: false },
                    size,
                    camera,
                    grid_step,
                    clusters,
                    masks,
                    clear,
                )
            }
        }
    }

    /// Reads the own colour target back (after [`draw`](Self::draw) to [`Target::Own`]);
    /// waits for the GPU.
    pub fn read_color(&mut self) -> Result<Image, GpuError> {
        if !self.last_own {
            return Err(GpuError::NotOwnTarget { what: "read_color" });
        }
        self.resolve_color();
        let color = self.color.clone();
        let rgba = self.read_texture(&color, 4)?;
        Ok(Image { width: self.width, height: self.height, rgba })
    }

    /// Copies an own-size `texture` of `bytes_per_pixel` to the CPU (rows from the top, no
    /// padding); waits for the GPU. The time counts as rendering.
    fn read_texture(&mut self, texture: &wgpu::Texture, bytes_per_pixel: u32) -> Result<Vec<u8>, GpuError> {
        let start = Instant::now();
        let mut encoder = self.device.create_command_encoder(&Default::default());
        self.readback.copy_texture(&self.device, &mut encoder, texture, bytes_per_pixel);
        let pitch = readback::padded_row(self.width, bytes_per_pixel) as usize;
        let bytes = self.readback.finish(
            &self.device,
            &self.queue,
            encoder,
            pitch,
            self.width as usize * bytes_per_pixel as usize,
            self.height as usize,
        )?;
        self.stats.render += start.elapsed();
        Ok(bytes)
    }

    /// Reads the own depth target back as reverse-Z f32 (see [`depth`]); waits for the GPU.
    pub fn read_depth(&mut self) -> Result<DepthImage, GpuError> {
        if !self.last_own {
            return Err(GpuError::NotOwnTarget { what: "read_depth" });
        }
        let start = Instant::now();
        self.resolve_depth();
        let d = if self.info.backend == wgpu::Backend::Gl {
            let copy = self.depth_copy.get_or_insert_with(|| depth::DepthCopy::new(&self.device));
            copy.read(&self.device, &self.queue, &mut self.readback, &self.depth)?
        } else {
            depth::read_direct(&self.device, &self.queue, &mut self.readback, &self.depth)?
        };
        self.stats.render += start.elapsed();
        Ok(d)
    }

    /// Hardware occlusion queries of `boxes` (scene-space min, max) against the own depth
    /// target as the frame's draws left it, from `camera` (the camera of those draws): per box
    /// the samples that passed on Vulkan, 0 or 1 on GL ([`Renderer::queries_count_samples`]),
    /// [`query::EYE_INSIDE`] for a box around the eye; > 0 means visible. Waits for the GPU.
    pub fn query_boxes(&mut self, camera: &Camera, boxes: &[(Vec3, Vec3)]) -> Result<Vec<u64>, GpuError> {
        if !self.last_own {
            return Err(GpuError::NotOwnTarget { what: "query_boxes" });
        }
        let start = Instant::now();
        let aspect = self.width as f32 / self.height as f32;
        let view_proj = camera.projection_reverse_z(aspect) * camera.view();
        // With multisampling the boxes are rasterized at the same samples against the
        // multisampled depth itself (no resolve); counts are given back in pixels (rounded up).
        let samples = self.samples;
        let depth_view = match &self.msaa_own {
            Some(t) if samples > 1 => t.depth.clone(),
            _ => self.depth_view.clone(),
        };
        let q = self
            .box_queries
            .get_or_insert_with(|| query::BoxQueries::new(&self.device, &self.queue, DEPTH_FORMAT, samples));
        let mut r = q.run(
            &self.device,
            &self.queue,
            &mut self.readback,
            &depth_view,
            view_proj,
            camera.eye,
            camera.near,
            boxes,
        )?;
        if samples > 1 && self.queries_count_samples() {
            for c in r.iter_mut().filter(|c| **c != query::EYE_INSIDE) {
                *c = c.div_ceil(samples as u64);
            }
        }
        self.stats.render += start.elapsed();
        Ok(r)
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

    /// A whole single-pass frame into the own target: [`begin_frame`](Self::begin_frame),
    /// [`draw`](Self::draw) (clearing), [`read_color`](Self::read_color).
    pub fn render_clusters(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
    ) -> Result<Image, GpuError> {
        self.begin_frame();
        self.draw(Target::Own, camera, grid_step, clusters, true)?;
        self.read_color()
    }

    /// A whole frame into the caller's colour `view` (`format`, `size`): begins a frame,
    /// draws (clearing) and submits, without waiting and without readback — the caller
    /// presents the surface texture or shows the egui texture. Formats without sRGB encoding
    /// (e.g. `Bgra8Unorm` surfaces) get it in the shader.
    pub fn render_to_view(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        view: &wgpu::TextureView,
        format: wgpu::TextureFormat,
        size: (u32, u32),
    ) -> Result<(), GpuError> {
        self.begin_frame();
        self.draw(Target::View { view, format, size }, camera, grid_step, clusters, true)
    }

    /// Like [`render_to_view`](Self::render_to_view), but records the frame's one render pass
    /// into the caller's `encoder` (submitted by the caller; uploads go through the queue and
    /// land before that submit). The frame must fit the GPU budget in one batch, else
    /// [`GpuError::OverBudget`] (and nothing is recorded; use `render_to_view` or a larger
    /// budget).
    #[allow(clippy::too_many_arguments)]
    pub fn encode_to_view(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        view: &wgpu::TextureView,
        format: wgpu::TextureFormat,
        size: (u32, u32),
    ) -> Result<(), GpuError> {
        self.begin_frame();
        self.last_own = false;
        self.draw_pass(
            Some(encoder),
            Pass::Shade { view, format, own: false },
            size,
            camera,
            grid_step,
            clusters,
            None,
            true,
        )
    }

    /// Renders a [`Selection`] over `store` into the own target, taking the decoded pages from
    /// `cache` (clusters whose page cannot be loaded are skipped and logged).
    pub fn render_selection(
        &mut self,
        store: &Store,
        cache: &PageCache,
        camera: &Camera,
        selection: &Selection,
    ) -> Result<Image, GpuError> {
        let pages = SelectionPages::resolve(store, cache, &selection.clusters);
        self.render_clusters(camera, store.header().grid_step, &pages.clusters())
    }

    /// Draws `clusters` with depth test into the item buffer (own size, cleared) and reads it
    /// back: per pixel the object, the cluster (its position in `clusters`) and the triangle
    /// (see [`ids`]). Begins a frame of its own.
    pub fn item_buffer(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
    ) -> Result<ItemBuffer, GpuError> {
        self.begin_frame();
        self.draw_items(camera, grid_step, clusters, 0, true)?;
        let keys: Vec<ClusterKey> = clusters.iter().map(|c| c.0).collect();
        self.read_items(&keys)
    }

    /// Draws `clusters` into the item buffer (own size), the first of them numbered
    /// `first_number` (cluster ids in the buffer are positions in the whole list the caller
    /// later passes to [`read_items`](Self::read_items)); with `clear` the buffer and depth
    /// are cleared first, else the clusters are depth-tested against what the frame drew
    /// before — so a large set can be drawn in chunks.
    pub fn draw_items(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        first_number: u32,
        clear: bool,
    ) -> Result<(), GpuError> {
        let size = (self.width, self.height);
        self.item_base = first_number;
        self.depth_stale = false;
        self.draw_pass(None, Pass::Items, size, camera, grid_step, clusters, None, clear)
    }

    /// Reads the item buffer back after [`draw_items`](Self::draw_items); `clusters` are the
    /// keys of every cluster drawn into it, in the numbering of those calls. Waits for the GPU.
    pub fn read_items(&mut self, clusters: &[ClusterKey]) -> Result<ItemBuffer, GpuError> {
        let Some((texture, _)) = &self.items else { return Err(GpuError::Gpu("no item target".into())) };
        let texture = texture.clone();
        let bytes = self.read_texture(&texture, 16)?;
        let raw = bytes
            .chunks_exact(16)
            .map(|p| {
                let w = |i: usize| u32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
                [w(0), w(4), w(8), w(12)]
            })
            .collect();
        Ok(ItemBuffer { width: self.width, height: self.height, raw, clusters: clusters.to_vec() })
    }

    /// [`item_buffer`](Self::item_buffer) of a [`Selection`] (pages from `cache`).
    pub fn item_buffer_selection(
        &mut self,
        store: &Store,
        cache: &PageCache,
        camera: &Camera,
        selection: &Selection,
    ) -> Result<ItemBuffer, GpuError> {
        let pages = SelectionPages::resolve(store, cache, &selection.clusters);
        self.item_buffer(camera, store.header().grid_step, &pages.clusters())
    }

    /// The draw shaders' uniforms for `camera` on a target of `size`. Nothing a shader branches
    /// on alone goes here (draw.wgsl: the colour mode and the sRGB encoding are pipeline
    /// constants, [`draw::Pipelines::shaded`]).
    fn write_uniforms(&self, camera: &Camera, (width, height): (u32, u32)) {
        let aspect = width as f32 / height as f32;
        let view_proj = camera.projection_reverse_z(aspect) * camera.view();
        // The sun: from above (the camera's up), tilted towards a fixed scene direction.
        let up = camera.up.normalize_or(Vec3::Z);
        let tilt = if up.dot(Vec3::X).abs() < 0.9 { Vec3::X } else { Vec3::Y };
        let sun = (up * 0.8 + (tilt - up * tilt.dot(up)).normalize_or_zero() * 0.35).normalize_or(up);
        let u = Uniforms {
            view_proj: view_proj.to_cols_array_2d(),
            eye: camera.eye.extend(1.0).to_array(),
            sun: sun.extend(0.0).to_array(),
            params: [0, self.object_color_count, color::pack(DEFAULT_COLOR), 0],
            headlight: (camera.eye - camera.target).normalize_or(Vec3::Z).extend(0.0).to_array(),
        };
        self.queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
    }

    /// The attachments of `pass` into a target of `size` whose single-sample depth is
    /// `depth_view`: with multisampling, a shaded pass draws into the multisampled targets of
    /// that size and format (made on first use) and resolves into the pass's view.
    fn attachments(
        &mut self,
        pass: &Pass<'_>,
        size: (u32, u32),
        depth_view: wgpu::TextureView,
    ) -> Attachments {
        match *pass {
            Pass::Items => Attachments {
                color: self.items.as_ref().expect("made before").1.clone(),
                resolve: None,
                depth: depth_view,
                samples: 1,
            },
            Pass::Shade { view, .. } if self.samples == 1 => {
                Attachments { color: view.clone(), resolve: None, depth: depth_view, samples: 1 }
            }
            Pass::Shade { view, format, own } => {
                let own_size = size == (self.width, self.height) && format == COLOR_FORMAT;
                if own_size && !own {
                    // The caller's view reuses the own multisampled target: keep its frame.
                    self.resolve_color();
                }
                let (device, samples) = (&self.device, self.samples);
                let slot = if own_size { &mut self.msaa_own } else { &mut self.msaa_view };
                if slot.as_ref().is_none_or(|t| t.size != size || t.format != format) {
                    *slot = Some(msaa::MsaaTarget::new(device, size, format, samples));
                }
                let t = slot.as_ref().expect("made above");
                let att = Attachments {
                    color: t.color.clone(),
                    resolve: (!own).then(|| view.clone()),
                    depth: t.depth.clone(),
                    samples,
                };
                self.color_stale |= own;
                att
            }
        }
    }

    /// Brings the own single-sample depth up to date with the multisampled one (the farthest
    /// sample of each pixel, [`msaa`]) when a shaded pass drew since; submits without waiting.
    fn resolve_depth(&mut self) {
        if !self.depth_stale {
            return;
        }
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("depth resolve") });
        self.encode_depth_resolve(&mut encoder);
        self.queue.submit([encoder.finish()]);
    }

    /// Resolves the own multisampled colour into the own colour target when a pass drew into
    /// it since the last resolve (see `color_stale`); submits without waiting.
    fn resolve_color(&mut self) {
        if !self.color_stale {
            return;
        }
        self.color_stale = false;
        let Some(target) = self.msaa_own.as_ref() else { return };
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("colour resolve") });
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("colour resolve"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &target.color,
                depth_slice: None,
                resolve_target: Some(&self.color_view),
                ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        self.queue.submit([encoder.finish()]);
    }

    /// Records [`resolve_depth`](Self::resolve_depth)'s pass into `encoder` (when needed).
    fn encode_depth_resolve(&mut self, encoder: &mut wgpu::CommandEncoder) {
        let Some(target) = self.msaa_own.as_ref().filter(|_| self.depth_stale) else { return };
        if self.depth_resolve.as_ref().is_none_or(|r| r.samples() != self.samples) {
            self.depth_resolve = Some(msaa::DepthResolve::new(&self.device, self.samples));
        }
        let resolve = self.depth_resolve.as_ref().expect("made above");
        resolve.encode(&self.device, encoder, &target.depth_only, &self.depth_view);
        self.depth_stale = false;
    }

    /// The depth view for a target of `size`.
    fn depth_view_for(&mut self, size: (u32, u32)) -> wgpu::TextureView {
        if size == (self.width, self.height) {
            return self.depth_view.clone();
        }
        match &self.extra_depth {
            Some((s, v)) if *s == size => v.clone(),
            _ => {
                let v = depth_texture(&self.device, size.0, size.1).create_view(&Default::default());
                self.extra_depth = Some((size, v.clone()));
                v
            }
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn draw_pass(
        &mut self,
        mut external: Option<&mut wgpu::CommandEncoder>,
        pass: Pass<'_>,
        size: (u32, u32),
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        masks: Option<&[TriangleMask]>,
        clear: bool,
    ) -> Result<(), GpuError> {
        let max = self.device.limits().max_texture_dimension_2d;
        if size.0 == 0 || size.1 == 0 || size.0 > max || size.1 > max {
            return Err(GpuError::Size { width: size.0, height: size.1, max });
        }
        let items = matches!(pass, Pass::Items);
        self.write_uniforms(camera, size);
        let depth_view = self.depth_view_for(size);
        if items && self.items.is_none() {
            let t = self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("item buffer"),
                size: wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: ITEM_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            let v = t.create_view(&Default::default());
            self.items = Some((t, v));
        }
        let att = self.attachments(&pass, size, depth_view);
        let format = match pass {
            Pass::Shade { format, .. } => Some(format),
            Pass::Items => None,
        };
        // GL (llvmpipe) hazard, seen in tests: a queued write into an arena range that an
        // earlier, still running submission draws from is not always ordered after it. On GL,
        // wait for earlier work before any eviction can happen (the arena is full) and after
        // each batch; other backends order it themselves.
        let gl = self.info.backend == wgpu::Backend::Gl;
        if gl && self.pool.stats().arena_bytes >= self.pool.budget() {
            self.wait_idle()?;
        }
        let mut batch: Vec<DrawArgs> = Vec::new();
        let mut keys: Vec<PoolKey> = Vec::new();
        let mut first = true;
        let mut upload = Duration::ZERO;
        let mut batch_uploads_from = self.pool.stats().uploaded_bytes;
        for (i, (key, cluster)) in clusters.iter().enumerate() {
            let pk = (key.page, key.index_in_page);
            let mut retried = false;
            loop {
                let t = Instant::now();
                let r = self.pool.ensure(&self.device, &self.queue, pk, grid_step, cluster);
                upload += t.elapsed();
                match r {
                    Ensure::Ready { args, slot } => {
                        if items {
                            self.pool.set_item(&self.queue, slot, self.item_base + i as u32 + 1);
                        }
                        let before = batch.len();
                        let mask = masks.and_then(|m| m.get(i).copied()).unwrap_or(u128::MAX);
                        let (drawn, masked) = push_runs(&mut batch, args, cluster, mask);
                        if batch.len() > before {
                            self.stats.clusters += 1;
                        }
                        self.stats.triangles += drawn;
                        self.stats.masked_triangles += masked;
                        keys.push(pk);
                        // Bound the staging memory of one batch (see `UPLOADS_PER_BATCH`).
                        let uploaded = self.pool.stats().uploaded_bytes - batch_uploads_from;
                        // Multisampled, a batch is `samples` times smaller: lavapipe's binned
                        // scene of a batch grows with the samples (a 10^7 reference frame at 64
                        // MiB peaked 63 MB higher at 4 samples with the single-sample cap).
                        let cap = self.pool.budget() / (UPLOADS_PER_BATCH * self.samples as u64);
                        if external.is_none() && uploaded >= cap {
                            let clear = clear && first;
                            batch_uploads_from =
                                self.flush_part(&att, format, &mut batch, &mut keys, clear)?;
                            first = false;
                        }
                        break;
                    }
                    Ensure::Empty => break,
                    Ensure::Full if external.is_some() => {
                        return Err(GpuError::OverBudget { budget: self.pool.budget() });
                    }
                    Ensure::Full if !retried && !batch.is_empty() => {
                        let clear = clear && first;
                        batch_uploads_from = self.flush_part(&att, format, &mut batch, &mut keys, clear)?;
                        first = false;
                        retried = true;
                    }
                    Ensure::Full => {
                        return Err(GpuError::Gpu(format!(
                            "cluster {key:?} does not fit the GPU budget of {} bytes",
                            self.pool.budget()
                        )))
                    }
                }
            }
        }
        self.flush(external.take(), &att, format, &batch, clear && first)?;
        // Submitted: a later draw of the same frame (the second pass of occlusion culling, the
        // next chunk of a reference frame) may evict these if it needs the room.
        self.pool.release_batch(&keys);
        self.stats.upload += upload;
        Ok(())
    }

    /// Submits a part of a frame drawn in several batches and waits for it before the next is
    /// prepared, on every backend (staging, see [`UPLOADS_PER_BATCH`]; on GL also the hazard
    /// noted in `draw`); its clusters may then be evicted. Returns the pool's uploaded bytes, from
    /// which the next batch's uploads are counted.
    fn flush_part(
        &mut self,
        att: &Attachments,
        format: Option<wgpu::TextureFormat>,
        batch: &mut Vec<DrawArgs>,
        keys: &mut Vec<PoolKey>,
        clear: bool,
    ) -> Result<u64, GpuError> {
        self.flush(None, att, format, batch, clear)?;
        self.wait_idle()?;
        self.pool.release_batch(keys);
        batch.clear();
        keys.clear();
        Ok(self.pool.stats().uploaded_bytes)
    }

    fn wait_idle(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Gpu(format!("waiting for the GPU: {e}")))
    }

    /// Encodes and submits one batch. `format` is `None` for the item buffer.
    fn flush(
        &mut self,
        external: Option<&mut wgpu::CommandEncoder>,
        att: &Attachments,
        format: Option<wgpu::TextureFormat>,
        batch: &[DrawArgs],
        clear: bool,
    ) -> Result<(), GpuError> {
        let start = Instant::now();
        if self.bind_generation != self.pool.generation {
            self.bind_group =
                bind_group(&self.device, &self.pipelines, &self.uniforms, &self.pool, &self.object_colors);
            self.bind_generation = self.pool.generation;
        }
        let indirect = match self.draw_mode {
            DrawMode::Indirect if !batch.is_empty() => {
                Some(self.indirect.write(&self.device, &self.queue, batch).clone())
            }
            _ => None,
        };
        let pipeline = match format {
            Some(f) => self.pipelines.shaded(&self.device, f, att.samples, self.mode).clone(),
            None => self.pipelines.item(&self.device).clone(),
        };
        let mut own = None;
        let encoder = match external {
            Some(e) => e,
            None => own.insert(
                self.device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("clusters") }),
            ),
        };
        {
            let load_color =
                if clear { wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT) } else { wgpu::LoadOp::Load };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("clusters"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &att.color,
                    depth_slice: None,
                    resolve_target: att.resolve.as_ref(),
                    ops: wgpu::Operations { load: load_color, store: wgpu::StoreOp::Store },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &att.depth,
                    depth_ops: Some(wgpu::Operations {
                        load: if clear { wgpu::LoadOp::Clear(0.0) } else { wgpu::LoadOp::Load },
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            if let Some(arena) = self.pool.arena() {
                draw::encode_batch(&mut pass, arena, batch, indirect.as_ref());
            }
        }
        if let Some(e) = own {
            // At most two batches in flight: a CPU driver runs a submission long after it is
            // made, and each holds the staging copies of its uploads (up to a quarter of the
            // GPU budget, `UPLOADS_PER_BATCH`), so without this wait they piled up over
            // frames. Waiting for the previous batch, not this one, keeps the CPU preparing
            // the next batch while the GPU draws.
            let index = self.queue.submit([e.finish()]);
            if let Some(previous) = self.in_flight.replace(index) {
                self.device
                    .poll(wgpu::PollType::Wait { submission_index: Some(previous), timeout: None })
                    .map_err(|e| GpuError::Gpu(format!("waiting for the GPU: {e}")))?;
            }
        }
        self.pool.note_batch();
        self.stats.draw_calls += match (self.draw_mode, batch.is_empty()) {
            (_, true) => 0,
            (DrawMode::Indirect, false) => 1,
            (DrawMode::Direct, false) => batch.len() as u64,
        };
        self.stats.render += start.elapsed();
        Ok(())
    }
}

/// At most this many draws per partially drawn cluster: beyond, the smallest gaps between its
/// runs of visible triangles are drawn too. Each draw has a fixed cost on Mesa's CPU drivers
/// that outweighs a few triangles' (BENCHMARKS.md, "Triangle-level HZB culling").
pub const MAX_RUNS: usize = 4;

/// Appends the draws of `mask`'s triangles of a resident cluster drawn whole by `args` and
/// returns how many triangles they draw and how many of those are in the mask. A cluster with
/// a malformed triangle (which the pool skipped, shifting the others) is drawn whole.
fn push_runs(
    batch: &mut Vec<DrawArgs>,
    args: DrawArgs,
    cluster: &PageCluster,
    mask: TriangleMask,
) -> (u64, u64) {
    let triangles = args.index_count / 3;
    let full = full_mask(triangles as usize);
    let well_formed = || cluster.indices.iter().all(|&v| (v as usize) < cluster.positions.len());
    if mask & full == full || triangles > 128 || !well_formed() {
        batch.push(args);
        return (triangles as u64, triangles as u64);
    }
    let mut runs = triangle_runs(mask & full);
    while runs.len() > MAX_RUNS {
        let i = (1..runs.len()).min_by_key(|&i| runs[i].0 - runs[i - 1].1).expect("two runs or more");
        runs[i - 1].1 = runs[i].1;
        runs.remove(i);
    }
    let mut drawn = 0u64;
    for (start, end) in runs {
        batch.push(DrawArgs {
            index_count: 3 * (end - start),
            first_index: args.first_index + 3 * start,
            ..args
        });
        drawn += (end - start) as u64;
    }
    (drawn, (mask & full).count_ones() as u64)
}

/// The maximal runs `[start, end)` of set bits of `mask`, in order.
fn triangle_runs(mut mask: TriangleMask) -> Vec<(u32, u32)> {
    let mut runs = Vec::new();
    let mut base = 0u32;
    while mask != 0 {
        let skip = mask.trailing_zeros();
        mask >>= skip;
        let len = mask.trailing_ones();
        runs.push((base + skip, base + skip + len));
        base += skip + len;
        mask = if len >= 128 { 0 } else { mask >> len };
    }
    runs
}

/// The decoded pages of a selection's clusters, held while the frame is drawn.
pub struct SelectionPages {
    pages: Vec<std::sync::Arc<tw_runtime::ResidentPage>>,
    refs: Vec<(ClusterKey, usize)>,
}

impl SelectionPages {
    /// Looks the pages of `clusters` up in `cache` (loading them if needed); clusters whose page
    /// fails are skipped and logged.
    pub fn resolve(store: &Store, cache: &PageCache, clusters: &[ClusterRef]) -> SelectionPages {
        let mut pages = Vec::new();
        let mut slot_of: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
        let mut refs = Vec::with_capacity(clusters.len());
        for r in clusters {
            let slot = match slot_of.get(&r.page) {
                Some(&s) => s,
                None => match cache.get(store, r.page) {
                    Ok(page) => {
                        pages.push(page);
                        slot_of.insert(r.page, pages.len() - 1);
                        pages.len() - 1
                    }
                    Err(e) => {
                        tracing::error!("cluster {r:?} skipped: {e}");
                        continue;
                    }
                },
            };
            refs.push((*r, slot));
        }
        SelectionPages { pages, refs }
    }

    /// The clusters, in the selection's order (clusters beyond their page are skipped).
    pub fn clusters(&self) -> Vec<(ClusterKey, &PageCluster)> {
        self.refs
            .iter()
            .filter_map(|&(k, slot)| self.pages[slot].clusters.get(k.index_in_page as usize).map(|c| (k, c)))
            .collect()
    }
}

fn depth_texture(device: &wgpu::Device, width: u32, height: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("depth target"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: DEPTH_FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

fn colors_buffer(device: &wgpu::Device, queue: &wgpu::Queue, packed: &[u32]) -> wgpu::Buffer {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("object colours"),
        size: (packed.len() as u64 * 4).max(16),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    queue.write_buffer(&buffer, 0, bytemuck::cast_slice(packed));
    buffer
}

fn bind_group(
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

fn adapter_summary(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_sizes_are_rejected_before_touching_the_gpu() {
        assert!(matches!(Renderer::new_headless(0, 10), Err(GpuError::Size { .. })));
        assert!(matches!(Renderer::new_headless(10, MAX_SIDE + 1), Err(GpuError::Size { .. })));
    }

    fn strip(triangles: u8) -> PageCluster {
        PageCluster {
            positions: (0..triangles as u32 + 2).map(|i| [i, i % 2, 0]).collect(),
            indices: (0..triangles).flat_map(|t| [t, t + 1, t + 2]).collect(),
            objects: vec![0; triangles as usize],
            ..Default::default()
        }
    }

    #[test]
    fn masked_clusters_draw_runs_of_their_pooled_index_range() {
        let c = strip(10);
        let args = DrawArgs {
            index_count: 30,
            instance_count: 1,
            first_index: 300,
            base_vertex: 40,
            first_instance: 0,
        };
        let ranges = |mask: TriangleMask| {
            let mut batch = Vec::new();
            let (drawn, masked) = push_runs(&mut batch, args, &c, mask);
            for a in &batch {
                assert_eq!((a.base_vertex, a.instance_count, a.first_instance), (40, 1, 0));
            }
            assert_eq!(masked, (mask & 0b11_1111_1111).count_ones() as u64);
            (drawn, batch.iter().map(|a| (a.first_index, a.index_count)).collect::<Vec<_>>())
        };
        // Everything (and bits beyond the cluster): the whole range, one draw.
        assert_eq!(ranges(u128::MAX), (10, vec![(300, 30)]));
        assert_eq!(ranges(0b11_1111_1111), (10, vec![(300, 30)]));
        assert_eq!(ranges(0), (0, vec![]));
        assert_eq!(MAX_RUNS, 4);
        // Triangles 0-2, 5, 9: three runs, three draws.
        assert_eq!(ranges(0b10_0010_0111), (5, vec![(300, 9), (315, 3), (327, 3)]));
        assert_eq!(ranges(0b10_0000_0000), (1, vec![(327, 3)]));
        // Triangles 0, 2, 4, 6, 9: five runs; the first of the smallest gaps (triangle 1) is
        // bridged.
        assert_eq!(ranges(0b10_0101_0101), (6, vec![(300, 9), (312, 3), (318, 3), (327, 3)]));
        assert_eq!(triangle_runs(u128::MAX), vec![(0, 128)]);
        assert_eq!(triangle_runs(1 << 127 | 0b110), vec![(1, 3), (127, 128)]);
        assert_eq!(triangle_runs(0), vec![]);
        // A malformed triangle shifts the pooled ones: the cluster is drawn whole.
        let mut bad = c.clone();
        bad.indices[4] = 200;
        let mut batch = Vec::new();
        assert_eq!(push_runs(&mut batch, args, &bad, 0b1), (10, 10));
        assert_eq!(batch.len(), 1);
    }
}
