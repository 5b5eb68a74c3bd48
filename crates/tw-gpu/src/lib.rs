//! terawalk's GPU renderer (wgpu 30): draws the clusters a [`tw_runtime::Selector`] chose for a
//! frame (DESIGN "Data flow": camera → select → … → draw), headless into an offscreen target
//! that is read back (for `terawalk render`, tests and measurements, DESIGN decision 5).
//!
//! - [`Renderer::new_headless`] opens an adapter without a surface (backends from
//!   `WGPU_BACKEND`, default all; on machines without a GPU, Mesa's lavapipe (Vulkan) or llvmpipe
//!   (GL) serve), with an `Rgba8UnormSrgb` colour target, a `Depth32Float` depth target and a
//!   readback buffer whose rows are padded to 256 bytes.
//! - Geometry: [`Renderer::upload_clusters`] builds this frame's vertex buffers from decoded
//!   store clusters ([`tw_store::PageCluster`], grid positions → f32 scene space `g × grid_step`,
//!   docs/FORMAT.md "Model"). Vertices are **not indexed**: three per triangle, each 16 bytes
//!   (position f32×3, colour sRGB u8×4), so a triangle's object colour needs no per-primitive
//!   lookup. That is 48 bytes a triangle, about 3× an indexed layout; acceptable for a CPU
//!   rasterizer whose limit is ~0.5 M visible triangles a frame, to be replaced by resident
//!   per-cluster index buffers when streaming moves to the GPU. The buffers are rebuilt each
//!   frame and their capacity reused; they are split into chunks of at most
//!   [`MAX_CHUNK_BYTES`].
//! - Shading: flat normals from screen-space derivatives (`cross(dpdx(p), dpdy(p))` in the
//!   fragment shader, supported by every naga backend including GLSL), turned towards the viewer
//!   (both sides are drawn), a headlight plus a fixed sun from above. Colours: the store's object
//!   colours (grey when an object has none) or a debug mode ([`ColorMode`]).
//! - Depth is reverse-Z ([`tw_runtime::Camera::projection_reverse_z`], `Greater`, clear 0).
//! - [`Renderer::render`] draws, waits for the GPU (`PollType::wait_indefinitely`) and returns an
//!   [`Image`]: RGBA8, rows from the top; alpha is 255 where geometry was drawn and 0 on the
//!   background, so coverage can be read from it. [`Image::save_png`] writes it opaque.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub use wgpu;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use tw_runtime::{Camera, ClusterRef, PageCache, Selection};
use tw_store::{PageCluster, Store};

/// Identifies a cluster: its page, index in the page and group (as selected).
pub type ClusterKey = ClusterRef;

/// The largest vertex buffer chunk (bytes). Well under every backend's `max_buffer_size`.
pub const MAX_CHUNK_BYTES: u64 = 256 << 20;

/// The largest image side accepted.
pub const MAX_SIDE: u32 = 16384;

/// Colour of objects without one in the store (sRGB).
pub const DEFAULT_COLOR: [u8; 4] = [180, 180, 180, 255];

/// Background (sRGB) that [`Image::save_png`] puts where nothing was drawn.
pub const BACKGROUND: [u8; 3] = [205, 218, 235];

const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Errors of this crate.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter for backends {backends}: {reason}; install mesa-vulkan-drivers or set \
         WGPU_BACKEND=gl"
    )]
    NoAdapter { backends: String, reason: String },
    #[error("cannot create a device on {adapter}: {source}")]
    Device {
        adapter: String,
        #[source]
        source: wgpu::RequestDeviceError,
    },
    #[error("image size {width}×{height} is invalid: each side must be 1 to {max} pixels")]
    Size { width: u32, height: u32, max: u32 },
    #[error("GPU error: {0}")]
    Gpu(String),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: PNG encoding failed: {source}", path.display())]
    Png {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
}

/// Where a triangle's colour comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ColorMode {
    /// The object's colour from the store's object table, [`DEFAULT_COLOR`] without one.
    #[default]
    Material,
    /// A colour from a hash of the object id.
    Object,
    /// A colour per LOD level (0 = full resolution).
    Level,
    /// A colour from a hash of the cluster (page, index in page).
    Cluster,
}

/// One vertex: scene-space position and sRGB colour.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Vertex {
    position: [f32; 3],
    color: [u8; 4],
}

const VERTEX_SIZE: u64 = std::mem::size_of::<Vertex>() as u64;

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Uniforms {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    sun: [f32; 4],
}

/// An RGBA8 image read back from the GPU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// RGBA, 8 bits a channel (sRGB), rows from the top, `width × height × 4` bytes. Alpha is
    /// 255 where geometry was drawn, 0 elsewhere.
    pub rgba: Vec<u8>,
}

impl Image {
    /// Whether pixel `(x, y)` shows geometry.
    pub fn covered(&self, x: u32, y: u32) -> bool {
        let i = (y as usize * self.width as usize + x as usize) * 4 + 3;
        self.rgba.get(i).is_some_and(|&a| a != 0)
    }

    /// Pixels that show geometry.
    pub fn covered_pixels(&self) -> usize {
        self.rgba.chunks_exact(4).filter(|p| p[3] != 0).count()
    }

    /// The image with [`BACKGROUND`] where nothing was drawn, opaque.
    pub fn opaque(&self) -> Vec<u8> {
        let mut out = self.rgba.clone();
        for p in out.chunks_exact_mut(4) {
            if p[3] == 0 {
                p[..3].copy_from_slice(&BACKGROUND);
            }
            p[3] = 255;
        }
        out
    }

    /// Writes the image as an opaque 8-bit RGBA PNG (see [`Image::opaque`]), atomically (a
    /// temporary file beside `path`, renamed).
    pub fn save_png(&self, path: &Path) -> Result<(), GpuError> {
        let io = |source| GpuError::Io { path: path.to_path_buf(), source };
        let png_err = |source| GpuError::Png { path: path.to_path_buf(), source };
        let mut tmp_name = path.file_name().unwrap_or_default().to_os_string();
        tmp_name.push(".tmp");
        let tmp = path.with_file_name(tmp_name);
        let result = (|| {
            let file = std::fs::File::create(&tmp).map_err(io)?;
            let mut w = std::io::BufWriter::new(file);
            {
                let mut enc = png::Encoder::new(&mut w, self.width, self.height);
                enc.set_color(png::ColorType::Rgba);
                enc.set_depth(png::BitDepth::Eight);
                enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
                let mut pw = enc.write_header().map_err(png_err)?;
                pw.write_image_data(&self.opaque()).map_err(png_err)?;
                pw.finish().map_err(png_err)?;
            }
            let file = w.into_inner().map_err(|e| io(e.into_error()))?;
            file.sync_all().map_err(io)?;
            std::fs::rename(&tmp, path).map_err(io)
        })();
        if result.is_err() {
            let _ = std::fs::remove_file(&tmp);
        }
        result
    }
}

/// What the last frame drew and how long it took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameStats {
    pub clusters: u64,
    pub triangles: u64,
    /// Building and uploading the vertex buffers.
    pub upload: Duration,
    /// Encoding, GPU work and readback (wall clock, waiting for the GPU).
    pub render: Duration,
}

/// A headless wgpu renderer; see the crate documentation.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    width: u32,
    height: u32,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    padded_row: u32,
    /// The cluster pipeline per colour target format (the own target's first).
    pipelines: Vec<(wgpu::TextureFormat, wgpu::RenderPipeline)>,
    pipeline_layout: wgpu::PipelineLayout,
    shader: wgpu::ShaderModule,
    /// A depth target for caller-supplied views of another size than the own target.
    extra_depth: Option<(u32, u32, wgpu::TextureView)>,
    uniforms: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// Vertex buffer chunks with their capacity in vertices; `draws` says how many vertices of
    /// each the current frame uses.
    chunks: Vec<(wgpu::Buffer, u64)>,
    draws: Vec<u32>,
    scratch: Vec<Vertex>,
    object_colors: Vec<[u8; 4]>,
    mode: ColorMode,
    stats: FrameStats,
}

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
        let limits = wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits());
        if width > limits.max_texture_dimension_2d || height > limits.max_texture_dimension_2d {
            return Err(GpuError::Size { width, height, max: limits.max_texture_dimension_2d });
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("terawalk"),
            required_features: wgpu::Features::empty(),
            required_limits: limits,
            ..Default::default()
        }))
        .map_err(|source| GpuError::Device { adapter: adapter_summary(&info), source })?;
        tracing::info!("GPU adapter: {}", adapter_summary(&info));
        Renderer::from_device(device, queue, info, width, height)
    }

    /// A renderer on a device the caller already has (a viewer's winit surface or egui-wgpu
    /// device). `width` × `height` is the size of the renderer's own offscreen target, used by
    /// [`render`](Self::render); [`render_to_view`](Self::render_to_view) draws into any
    /// caller-supplied view instead. wgpu devices and queues are reference-counted handles:
    /// pass clones.
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
        let extent = wgpu::Extent3d { width, height, depth_or_array_layers: 1 };
        let color = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("colour target"),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: COLOR_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let depth = depth_texture(&device, width, height);
        let padded_row =
            (width * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: padded_row as u64 * height as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("uniforms"),
            size: std::mem::size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("uniforms"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("uniforms"),
            layout: &bind_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: uniforms.as_entire_binding() }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("clusters"),
            bind_group_layouts: &[Some(&bind_layout)],
            immediate_size: 0,
        });
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("clusters"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shader.wgsl").into()),
        });
        let pipeline = cluster_pipeline(&device, &layout, &shader, COLOR_FORMAT);
        let color_view = color.create_view(&Default::default());
        let depth_view = depth.create_view(&Default::default());
        Ok(Renderer {
            device,
            queue,
            info,
            width,
            height,
            color,
            color_view,
            depth_view,
            readback,
            padded_row,
            pipelines: vec![(COLOR_FORMAT, pipeline)],
            pipeline_layout: layout,
            shader,
            extra_depth: None,
            uniforms,
            bind_group,
            chunks: Vec::new(),
            draws: Vec::new(),
            scratch: Vec::new(),
            object_colors: Vec::new(),
            mode: ColorMode::default(),
            stats: FrameStats::default(),
        })
    }

    /// The adapter in use.
    pub fn info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// "name (backend, device type)".
    pub fn adapter_summary(&self) -> String {
        adapter_summary(&self.info)
    }

    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// What the last [`upload_clusters`](Self::upload_clusters) / [`render`](Self::render) did.
    pub fn stats(&self) -> FrameStats {
        self.stats
    }

    /// Object colours (sRGB) by object id; `None` entries and ids beyond the list get
    /// [`DEFAULT_COLOR`].
    pub fn set_object_colors(&mut self, colors: impl IntoIterator<Item = Option<[u8; 4]>>) {
        self.object_colors = colors.into_iter().map(|c| c.unwrap_or(DEFAULT_COLOR)).collect();
    }

    /// [`set_object_colors`](Self::set_object_colors) from the store's object table.
    pub fn set_store_colors(&mut self, store: &Store) {
        self.set_object_colors(store.objects().iter().map(|o| o.color));
    }

    pub fn set_color_mode(&mut self, mode: ColorMode) {
        self.mode = mode;
    }

    /// Builds this frame's geometry from `clusters` (replacing the previous frame's): positions
    /// are grid coordinates × `grid_step` (scene space). Malformed clusters (an index beyond the
    /// vertices) have the bad triangles skipped.
    pub fn upload_clusters(&mut self, grid_step: f64, clusters: &[(ClusterKey, &PageCluster)]) {
        let start = Instant::now();
        let max_chunk_vertices = (MAX_CHUNK_BYTES / VERTEX_SIZE)
            .min(self.device.limits().max_buffer_size / VERTEX_SIZE)
            .min(u32::MAX as u64 / 3 * 3)
            / 3
            * 3;
        self.draws.clear();
        self.scratch.clear();
        let mut chunk = 0usize;
        let mut triangles = 0u64;
        for (key, c) in clusters {
            let cluster_color = hash_color(key.page.wrapping_mul(0x9e37_79b9) ^ key.index_in_page);
            let level_color = level_color(c.level);
            for (t, tri) in c.indices.chunks_exact(3).enumerate() {
                let (Some(a), Some(b), Some(d)) = (
                    c.positions.get(tri[0] as usize),
                    c.positions.get(tri[1] as usize),
                    c.positions.get(tri[2] as usize),
                ) else {
                    continue;
                };
                let object = c.objects.get(t).copied().unwrap_or(0);
                let color = match self.mode {
                    ColorMode::Material => {
                        self.object_colors.get(object as usize).copied().unwrap_or(DEFAULT_COLOR)
                    }
                    ColorMode::Object => hash_color(object),
                    ColorMode::Level => level_color,
                    ColorMode::Cluster => cluster_color,
                };
                for p in [a, b, d] {
                    let position = p.map(|g| (g as f64 * grid_step) as f32);
                    self.scratch.push(Vertex { position, color });
                }
                triangles += 1;
                if self.scratch.len() as u64 >= max_chunk_vertices {
                    self.flush_chunk(chunk);
                    chunk += 1;
                }
            }
        }
        if !self.scratch.is_empty() {
            self.flush_chunk(chunk);
        }
        self.stats = FrameStats {
            clusters: clusters.len() as u64,
            triangles,
            upload: start.elapsed(),
            ..Default::default()
        };
    }

    /// Writes the scratch vertices into chunk `chunk` (growing it as needed) and records a draw.
    fn flush_chunk(&mut self, chunk: usize) {
        let n = self.scratch.len() as u64;
        let needed = n.max(1024);
        if chunk >= self.chunks.len() || self.chunks[chunk].1 < n {
            let capacity = needed.next_power_of_two().min(MAX_CHUNK_BYTES / VERTEX_SIZE).max(n);
            let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("cluster vertices"),
                size: capacity * VERTEX_SIZE,
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            if chunk < self.chunks.len() {
                self.chunks[chunk] = (buffer, capacity);
            } else {
                self.chunks.push((buffer, capacity));
            }
        }
        self.queue.write_buffer(&self.chunks[chunk].0, 0, bytemuck::cast_slice(&self.scratch));
        self.draws.push(n as u32);
        self.scratch.clear();
    }

    /// Writes the uniforms for `camera` drawing into a target of `width` × `height` pixels and
    /// `format` (formats without sRGB encoding get it in the shader).
    fn write_uniforms(&self, camera: &Camera, width: u32, height: u32, format: wgpu::TextureFormat) {
        let aspect = width as f32 / height as f32;
        let view_proj = camera.projection_reverse_z(aspect) * camera.view();
        // The sun: from above (the camera's up), tilted towards a fixed scene direction.
        let up = camera.up.normalize_or(Vec3::Z);
        let tilt = if up.dot(Vec3::X).abs() < 0.9 { Vec3::X } else { Vec3::Y };
        let sun = (up * 0.8 + (tilt - up * tilt.dot(up)).normalize_or_zero() * 0.35).normalize_or(up);
        let encode = if format.is_srgb() { 0.0 } else { 1.0 };
        let u = Uniforms {
            view_proj: view_proj.to_cols_array_2d(),
            eye: camera.eye.extend(1.0).to_array(),
            sun: sun.extend(encode).to_array(),
        };
        self.queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
    }

    /// The cluster pipeline for `format`, created on first use.
    fn pipeline_for(&mut self, format: wgpu::TextureFormat) -> usize {
        if let Some(i) = self.pipelines.iter().position(|(f, _)| *f == format) {
            return i;
        }
        let p = cluster_pipeline(&self.device, &self.pipeline_layout, &self.shader, format);
        self.pipelines.push((format, p));
        self.pipelines.len() - 1
    }

    /// Records the frame's draws into `encoder`, into the caller's colour `view` (`format`,
    /// `width` × `height`, cleared to transparent black) with a depth target of the renderer's
    /// own (kept between calls while the size stays). Nothing is submitted: for callers that
    /// own the encoder (e.g. an egui-wgpu paint callback or a surface frame loop). The camera's
    /// uniforms are written through the queue, so they take effect at the next submit.
    pub fn encode_to_view(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        camera: &Camera,
        view: &wgpu::TextureView,
        format: wgpu::TextureFormat,
        (width, height): (u32, u32),
    ) -> Result<(), GpuError> {
        let max = self.device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > max || height > max {
            return Err(GpuError::Size { width, height, max });
        }
        self.write_uniforms(camera, width, height, format);
        let pipeline = self.pipeline_for(format);
        if (width, height) != (self.width, self.height)
            && !matches!(&self.extra_depth, Some((w, h, _)) if (*w, *h) == (width, height))
        {
            let tex = depth_texture(&self.device, width, height);
            self.extra_depth = Some((width, height, tex.create_view(&Default::default())));
        }
        let depth_view = match &self.extra_depth {
            Some((w, h, v)) if (*w, *h) == (width, height) => v,
            _ => &self.depth_view,
        };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("clusters"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color { r: 0.0, g: 0.0, b: 0.0, a: 0.0 }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(0.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipelines[pipeline].1);
        pass.set_bind_group(0, &self.bind_group, &[]);
        for (&n, (buffer, _)) in self.draws.iter().zip(&self.chunks) {
            pass.set_vertex_buffer(0, buffer.slice(..n as u64 * VERTEX_SIZE));
            pass.draw(0..n, 0..1);
        }
        Ok(())
    }

    /// Draws the uploaded geometry from `camera` into the caller's colour `view` (see
    /// [`encode_to_view`](Self::encode_to_view)) and submits, without waiting and without
    /// readback: the caller presents the surface texture or shows the egui texture.
    pub fn render_to_view(
        &mut self,
        camera: &Camera,
        view: &wgpu::TextureView,
        format: wgpu::TextureFormat,
        size: (u32, u32),
    ) -> Result<(), GpuError> {
        let start = Instant::now();
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        self.encode_to_view(&mut encoder, camera, view, format, size)?;
        self.queue.submit([encoder.finish()]);
        self.stats.render = start.elapsed();
        Ok(())
    }

    /// The device and queue in use (for callers that share them).
    pub fn device(&self) -> (&wgpu::Device, &wgpu::Queue) {
        (&self.device, &self.queue)
    }

    /// Draws the uploaded geometry from `camera`, waits for the GPU and reads the image back.
    pub fn render(&mut self, camera: &Camera) -> Result<Image, GpuError> {
        let start = Instant::now();
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        let view = self.color_view.clone();
        self.encode_to_view(&mut encoder, camera, &view, COLOR_FORMAT, (self.width, self.height))?;
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.color,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.padded_row),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 },
        );
        self.queue.submit([encoder.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        self.readback.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Gpu(format!("waiting for the frame: {e}")))?;
        rx.recv()
            .map_err(|_| GpuError::Gpu("the readback was never mapped".into()))?
            .map_err(|e| GpuError::Gpu(format!("mapping the readback buffer: {e}")))?;
        let row = self.width as usize * 4;
        let mut rgba = Vec::with_capacity(row * self.height as usize);
        {
            let view = self
                .readback
                .get_mapped_range(..)
                .map_err(|e| GpuError::Gpu(format!("reading the readback buffer: {e}")))?;
            for r in view.chunks(self.padded_row as usize).take(self.height as usize) {
                rgba.extend_from_slice(&r[..row]);
            }
        }
        self.readback.unmap();
        self.stats.render = start.elapsed();
        Ok(Image { width: self.width, height: self.height, rgba })
    }

    /// Uploads `clusters` and renders them (see [`upload_clusters`](Self::upload_clusters) and
    /// [`render`](Self::render)).
    pub fn render_clusters(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
    ) -> Result<Image, GpuError> {
        self.upload_clusters(grid_step, clusters);
        self.render(camera)
    }

    /// Renders a [`Selection`] over `store`, taking the decoded pages from `cache` (clusters
    /// whose page cannot be loaded are skipped and logged).
    pub fn render_selection(
        &mut self,
        store: &Store,
        cache: &PageCache,
        camera: &Camera,
        selection: &Selection,
    ) -> Result<Image, GpuError> {
        let mut pages = Vec::new();
        let mut last: Option<(u32, usize)> = None;
        let mut refs: Vec<(ClusterKey, usize, u32)> = Vec::with_capacity(selection.clusters.len());
        for r in &selection.clusters {
            let slot = match last {
                Some((p, slot)) if p == r.page => slot,
                _ => match cache.get(store, r.page) {
                    Ok(page) => {
                        pages.push(page);
                        last = Some((r.page, pages.len() - 1));
                        pages.len() - 1
                    }
                    Err(e) => {
                        tracing::error!("cluster {r:?} skipped: {e}");
                        continue;
                    }
                },
            };
            refs.push((*r, slot, r.index_in_page));
        }
        let clusters: Vec<(ClusterKey, &PageCluster)> = refs
            .iter()
            .filter_map(|&(k, slot, i)| pages[slot].clusters.get(i as usize).map(|c| (k, c)))
            .collect();
        self.render_clusters(camera, store.header().grid_step, &clusters)
    }
}

/// The cluster pipeline drawing into `format` (depth `Depth32Float`, reverse-Z).
fn cluster_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    shader: &wgpu::ShaderModule,
    format: wgpu::TextureFormat,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("clusters"),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module: shader,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: VERTEX_SIZE,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Unorm8x4],
            })],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: shader,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

fn depth_texture(device: &wgpu::Device, width: u32, height: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("depth target"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: DEPTH_FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    })
}

fn adapter_summary(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

/// A distinct, fairly saturated sRGB colour for an id (MurmurHash3's finaliser; the same as
/// tw-preview's `hash_color`).
pub fn hash_color(id: u32) -> [u8; 4] {
    let mut h = id.wrapping_add(0x9e37_79b9);
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^= h >> 16;
    let hue = (h & 0xffff) as f64 / 65536.0 * 6.0;
    let sat = 0.45 + 0.35 * ((h >> 16) & 0xff) as f64 / 255.0;
    let val = 0.75 + 0.25 * (h >> 24) as f64 / 255.0;
    let f = hue.fract();
    let (p, q, t) = (val * (1.0 - sat), val * (1.0 - sat * f), val * (1.0 - sat * (1.0 - f)));
    let rgb = match hue as u32 {
        0 => [val, t, p],
        1 => [q, val, p],
        2 => [p, val, t],
        3 => [p, q, val],
        4 => [t, p, val],
        _ => [val, p, q],
    };
    let [r, g, b] = rgb.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
    [r, g, b, 255]
}

/// The colour of LOD level `level`: full resolution green, then yellow, orange, red, magenta,
/// blue, cyan, repeating.
pub fn level_color(level: u8) -> [u8; 4] {
    const PALETTE: [[u8; 4]; 8] = [
        [80, 200, 90, 255],
        [220, 210, 70, 255],
        [240, 150, 50, 255],
        [225, 70, 60, 255],
        [200, 80, 200, 255],
        [90, 110, 230, 255],
        [70, 200, 220, 255],
        [240, 240, 240, 255],
    ];
    PALETTE[level as usize % PALETTE.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hash_colors_differ_between_ids() {
        let colors: std::collections::HashSet<_> = (0..64).map(hash_color).collect();
        assert!(colors.len() > 50);
    }

    #[test]
    fn level_colors_cycle() {
        assert_ne!(level_color(0), level_color(1));
        assert_eq!(level_color(0), level_color(8));
    }

    #[test]
    fn opaque_fills_the_background() {
        let img = Image { width: 2, height: 1, rgba: vec![1, 2, 3, 0, 9, 9, 9, 255] };
        assert_eq!(img.opaque(), vec![205, 218, 235, 255, 9, 9, 9, 255]);
        assert!(!img.covered(0, 0));
        assert!(img.covered(1, 0));
        assert!(!img.covered(5, 5));
        assert_eq!(img.covered_pixels(), 1);
    }

    #[test]
    fn bad_sizes_are_rejected_before_touching_the_gpu() {
        assert!(matches!(Renderer::new_headless(0, 10), Err(GpuError::Size { .. })));
        assert!(matches!(Renderer::new_headless(10, MAX_SIDE + 1), Err(GpuError::Size { .. })));
    }
}
