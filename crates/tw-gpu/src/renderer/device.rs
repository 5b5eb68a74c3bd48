//! Opening the renderer: the adapter and device a headless renderer asks for (or the checks,
//! limits, memory hints and features a caller opening its own device passes), and
//! [`Renderer::from_device`], which makes the renderer's own targets, buffers and pipelines.

use super::targets::depth_texture;
use super::{bind_group, colors_buffer, FrameStats, Renderer};
use crate::draw::{IndirectArgs, Pipelines, Uniforms};
use crate::pool::ClusterPool;
use crate::readback::Readback;
use crate::{
    color, ColorMode, DrawMode, GpuError, COLOR_FORMAT, DEFAULT_COLOR, DEFAULT_GPU_BUDGET, MAX_SIDE,
};

/// Storage buffers the draw shaders' vertex stage binds (common.wgsl: the slot table and the
/// object colours).
const VERTEX_STORAGE_BUFFERS: u32 = 2;

impl Renderer {
    /// A renderer of `width` × `height` pixels on the first adapter of the backends in
    /// `WGPU_BACKEND` (e.g. `vulkan`, `gl`; default all).
    pub fn new_headless(width: u32, height: u32) -> Result<Renderer, GpuError> {
        Renderer::new_headless_with(width, height, wgpu::Backends::all().with_env())
    }

    /// The first high-performance adapter of `backends`, without a display (headless
    /// rendering, and the collision passes of [`crate::visibility`]).
    pub(crate) fn headless_adapter(backends: wgpu::Backends) -> Result<wgpu::Adapter, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = backends;
        desc.flags = wgpu::InstanceFlags::default().with_env();
        let instance = wgpu::Instance::new(desc);
        pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter { backends: format!("{backends:?}"), reason: e.to_string() })
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
        let adapter = Renderer::headless_adapter(backends)?;
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

    /// Another headless renderer like this one, on a device of its own: the same backend,
    /// size, samples per pixel, GPU budget, draw mode and colour mode (object colours are the
    /// caller's: [`Renderer::set_store_colors`]). The occlusion contexts of
    /// the parallel frame pipelines (tw-frame's `pipeline`) draw on such devices; on Mesa's CPU
    /// drivers each device has its own rasterizer threads, so two of them draw at once. Fails
    /// when the backend's first adapter is not this renderer's (the occlusion tests must see
    /// the depth this renderer's device would draw).
    pub fn sibling(&self) -> Result<Renderer, GpuError> {
        let mut r =
            Renderer::new_headless_with(self.width, self.height, wgpu::Backends::from(self.info.backend))?;
        if (r.info.name.as_str(), r.info.device_type) != (self.info.name.as_str(), self.info.device_type) {
            return Err(GpuError::Gpu(format!(
                "a second device of {} opened {} instead",
                adapter_summary(&self.info),
                adapter_summary(&r.info)
            )));
        }
        r.set_samples(self.samples)?;
        r.set_gpu_budget(self.gpu_budget());
        r.set_draw_mode(self.draw_mode);
        r.mode = self.mode;
        Ok(r)
    }

    /// Refuses an adapter that cannot run the draw shaders: their vertex stage reads the slot
    /// table and the object colours from storage buffers (common.wgsl). wgpu's GL backend on
    /// NVIDIA's EGL driver offered a GLSL version without them (docs/benchmarks-log.md, "On a real
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
    /// `MULTI_DRAW_INDIRECT_COUNT` (compacted GPU-culled draws), `TIMESTAMP_QUERY` (the GPU
    /// cull's compute time) and `INDIRECT_FIRST_INSTANCE` (a part of a cluster drawn with its own
    /// shadow class, renderer/classified.rs).
    pub fn optional_features() -> wgpu::Features {
        wgpu::Features::PRIMITIVE_INDEX
            | wgpu::Features::MULTI_DRAW_INDIRECT_COUNT
            | wgpu::Features::TIMESTAMP_QUERY
            | wgpu::Features::INDIRECT_FIRST_INSTANCE
    }

    /// A renderer on a device the caller already has (a viewer's winit surface or egui-wgpu
    /// device; wgpu devices and queues are reference-counted handles: pass clones).
    /// `width` × `height` is the size of the renderer's own offscreen target, used by
    /// [`render_clusters`](Self::render_clusters) and [`Target::Own`](crate::Target::Own);
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
            highlight: None,
            section: Default::default(),
            fades: Default::default(),
            dither_pipelines: false,
            bind_group,
            bind_generation: pool.generation,
            pool,
            indirect: IndirectArgs::default(),
            draw_mode: if indirect_supported { DrawMode::Indirect } else { DrawMode::Direct },
            indirect_supported,
            first_instance_supported: device.features().contains(wgpu::Features::INDIRECT_FIRST_INSTANCE),
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
            shadow: crate::shadow::ShadowState::new(&device),
            device,
            queue,
            info,
            width,
            height,
        })
    }

    /// Whether a device with `caps` can run [`Renderer::draw_gpu_culled`] (compute shaders and
    /// indirect draws): [`Renderer::gpu_cull_supported`] before a renderer exists.
    pub fn gpu_cull_possible(caps: &wgpu::DownlevelCapabilities) -> bool {
        caps.flags.contains(wgpu::DownlevelFlags::INDIRECT_EXECUTION | wgpu::DownlevelFlags::COMPUTE_SHADERS)
    }

    /// Tells the renderer what the adapter supports (indirect execution and compute shaders on
    /// GL), and picks [`DrawMode::Indirect`] when it does.
    pub fn set_downlevel(&mut self, caps: &wgpu::DownlevelCapabilities) {
        self.indirect_supported = caps.flags.contains(wgpu::DownlevelFlags::INDIRECT_EXECUTION);
        self.compute_supported = caps.flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS);
        self.draw_mode = if self.indirect_supported { DrawMode::Indirect } else { DrawMode::Direct };
    }
}

/// "name (backend, device type)".
pub(super) fn adapter_summary(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

#[cfg(test)]
mod tests {
    use crate::{GpuError, Renderer, MAX_SIDE};

    #[test]
    fn bad_sizes_are_rejected_before_touching_the_gpu() {
        assert!(matches!(Renderer::new_headless(0, 10), Err(GpuError::Size { .. })));
        assert!(matches!(Renderer::new_headless(10, MAX_SIDE + 1), Err(GpuError::Size { .. })));
    }
}
