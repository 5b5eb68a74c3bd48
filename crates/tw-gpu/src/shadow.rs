//! Shadow maps on the rasterizer (Govindaraju's thesis ch. 4, "single-GPU shadow-map mode": the
//! light's depth buffer, drawn from the light-view set, is the shadow map): the map itself (a
//! `Depth32Float` array of up to [`MAX_SHADOW_LAYERS`] square layers, sun cascades or a point
//! light's cube faces), its depth-only pass, its readback, and the shading with shadows that the
//! following shaded passes do.
//!
//! The shading (shadow.wgsl) follows the lookup rule of `tw_runtime::shadow`
//! ([`Shadows::lit`]) exactly: the first layer whose eye-depth split and clip space hold the
//! point, the texel by `floor`, an exact `textureLoad` (no filtering, no comparison sampler), lit
//! when `d ≤ map + bias`, lit outside every layer. The vertex stage shades each triangle twice,
//! with the light's term and without, so a fragment costs one lookup. Clusters the CPU's
//! cross-culling classified ([`ShadowClass`]) skip the lookup: the class is a per-slot value of
//! the cluster pool, kept in a CPU mirror and uploaded once per pass (only the changed range),
//! and a shaded pass draws the classified clusters with a pipeline without lookup code, the
//! others with the lookup (`draw::Shading`; the GPU-culled pass draws all with the lookup
//! pipeline, which honours the classes too).
//!
//! Everything that selects code paths (shadows on or off, the number of layers) is a pipeline
//! constant, not a uniform: lavapipe recompiles shaders that branch on uniforms alone at every
//! bind (draw.wgsl, `COLOR_MODE`). Without shadows ([`Renderer::set_shadows`]`(None)`) the
//! shaded passes use the unshadowed pipeline of draw.wgsl unchanged.
//!
//! GL (llvmpipe): wgpu's GL backend picks a texture's GL target from its layer count (one layer:
//! `TEXTURE_2D`; a multiple of six on a square: a cube map), while the shaders bind the map as a
//! 2D array; the map there gets one spare layer where needed (`allocated_layers`). A layer is
//! read back through a compute copy (shadow_read.wgsl), GL having no depth-to-buffer copy.

use std::collections::HashMap;
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::Mat4;
use tw_runtime::{Camera, Light, ShadowClass, Shadows, TriangleClasses};
use tw_store::PageCluster;

use crate::draw::{LookupLayers, Shading, DEPTH_FORMAT};
use crate::pool::PoolKey;
use crate::readback::{padded_row, Readback};
use crate::renderer::{Eye, Pass};
use crate::{ClusterKey, GpuError, Renderer};

/// The most layers a shadow map has (a point light's six cube faces).
pub const MAX_SHADOW_LAYERS: u32 = 6;

/// Storage buffers the vertex stage of the shading with shadows binds: the slot table, the
/// object colours and the slot classes (shadow.wgsl).
const SHADOWED_VERTEX_STORAGE_BUFFERS: u32 = 3;

/// Class codes of shadow.wgsl (`CLASS_*`); 0, the zeroed buffer's value, is `Partial`.
const CLASS_PARTIAL: u32 = 0;
const CLASS_LIT: u32 = 1;
const CLASS_SHADOWED: u32 = 2;

/// The lit and shadowed class codes, for the draws of a refined cluster's parts
/// (renderer/classified.rs).
pub(crate) const CLASSIFIED_CODES: (u32, u32) = (CLASS_LIT, CLASS_SHADOWED);

fn class_code(class: ShadowClass) -> u32 {
    match class {
        ShadowClass::Partial => CLASS_PARTIAL,
        ShadowClass::Lit => CLASS_LIT,
        ShadowClass::Shadowed => CLASS_SHADOWED,
    }
}

/// shadow.wgsl `ShadowLayer`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct LayerUniform {
    view_proj: [[f32; 4]; 4],
    /// x, y: the split; infinite ends as ±`f32::MAX` (the same comparisons for finite depths,
    /// without infinities in a shader).
    split: [f32; 4],
}

/// shadow.wgsl `ShadowUniforms`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct ShadowUniforms {
    light: [f32; 4],
    view_dir: [f32; 4],
    params: [f32; 4],
    layers: [LayerUniform; MAX_SHADOW_LAYERS as usize],
}

impl ShadowUniforms {
    fn new(shadows: &Shadows, eye: &Camera) -> ShadowUniforms {
        let mut layers = [LayerUniform::zeroed(); MAX_SHADOW_LAYERS as usize];
        for (u, layer) in layers.iter_mut().zip(&shadows.layers) {
            let finite = |x: f32| x.clamp(-f32::MAX, f32::MAX);
            u.view_proj = layer.view_proj.to_cols_array_2d();
            u.split = [finite(layer.split[0]), finite(layer.split[1]), 0.0, 0.0];
        }
        let light = match shadows.light {
            Light::Sun { towards } => towards.extend(0.0),
            Light::Point { position } => position.extend(1.0),
        };
        ShadowUniforms {
            light: light.to_array(),
            view_dir: eye.direction().extend(0.0).to_array(),
            params: [shadows.size as f32, shadows.bias, 0.0, 0.0],
            layers,
        }
    }
}

/// Group 1 of the shading with shadows (shadow.wgsl): uniforms, slot classes, the map.
pub(crate) fn bind_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("shadows"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 2,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2Array,
                    multisampled: false,
                },
                count: None,
            },
        ],
    })
}

/// The layers to allocate for a map of `layers`: on GL one more where wgpu's GL backend would
/// otherwise not make it a 2D array texture (see the module documentation).
pub(crate) fn allocated_layers(layers: u32, gl: bool) -> u32 {
    if gl && (layers == 1 || layers.is_multiple_of(6)) {
        layers + 1
    } else {
        layers
    }
}

/// The shadow-map texture and its views.
struct ShadowMap {
    texture: wgpu::Texture,
    /// All layers, for the shading (shadow.wgsl `shadow_map`) and the GL readback.
    array_view: wgpu::TextureView,
    /// One view per layer, for its depth pass.
    layer_views: Vec<wgpu::TextureView>,
    size: u32,
    layers: u32,
}

/// The renderer's shadow state: the map, the shadows of the shaded passes, the classes by
/// cluster and their per-slot mirror.
pub(crate) struct ShadowState {
    map: Option<ShadowMap>,
    shadows: Option<Shadows>,
    classes: HashMap<PoolKey, u32>,
    /// The triangle classes of partly shadowed clusters that cross-culling refined.
    triangles: HashMap<PoolKey, TriangleClasses>,
    /// Class code per pool slot, as the GPU's `slot_classes` should hold it.
    mirror: Vec<u32>,
    /// The slots `[from, to)` of `mirror` changed since the last upload.
    dirty: Option<(usize, usize)>,
    class_buffer: wgpu::Buffer,
    uniforms: wgpu::Buffer,
    /// Group 1, rebuilt when the map or the class buffer changes.
    bind: Option<wgpu::BindGroup>,
    layer_copy: Option<LayerCopy>,
}

fn class_buffer(device: &wgpu::Device, slots: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("slot classes"),
        size: slots as u64 * 4,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

impl ShadowState {
    pub(crate) fn new(device: &wgpu::Device) -> ShadowState {
        ShadowState {
            map: None,
            shadows: None,
            classes: HashMap::new(),
            triangles: HashMap::new(),
            mirror: Vec::new(),
            dirty: None,
            class_buffer: class_buffer(device, 1024),
            uniforms: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("shadow uniforms"),
                size: std::mem::size_of::<ShadowUniforms>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            bind: None,
            layer_copy: None,
        }
    }

    /// Records that the cluster `key` is drawn from pool slot `slot` in the current shaded pass:
    /// its class goes to the slot's mirror entry (uploaded by [`Renderer::shaded_pipeline`]).
    /// Returns whether the cluster needs lookups (it is `Partial`).
    pub(crate) fn note_slot(&mut self, key: PoolKey, slot: u32) -> bool {
        let code = self.classes.get(&key).copied().unwrap_or(CLASS_PARTIAL);
        let s = slot as usize;
        if s >= self.mirror.len() {
            self.mirror.resize(s + 1, CLASS_PARTIAL);
        } else if self.mirror[s] == code {
            return code == CLASS_PARTIAL;
        }
        self.mirror[s] = code;
        self.dirty = Some(match self.dirty {
            Some((from, to)) => (from.min(s), to.max(s + 1)),
            None => (s, s + 1),
        });
        code == CLASS_PARTIAL
    }

    /// The triangle classes of the partly shadowed cluster `key`, if cross-culling refined it.
    pub(crate) fn triangle_classes(&self, key: PoolKey) -> Option<TriangleClasses> {
        self.triangles.get(&key).copied()
    }

    /// The shadow uniforms of a shaded pass from `eye` (the shadows must be set).
    pub(crate) fn write_uniforms(&self, queue: &wgpu::Queue, eye: &Camera) {
        if let Some(shadows) = &self.shadows {
            let u = ShadowUniforms::new(shadows, eye);
            queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
        }
    }

    /// The depth view of `layer` for its depth pass.
    pub(crate) fn layer_view(&self, layer: u32) -> Result<wgpu::TextureView, GpuError> {
        let map = self.map.as_ref().ok_or_else(no_map)?;
        map.layer_views.get(layer as usize).cloned().ok_or_else(|| {
            GpuError::Shadow(format!(
                "layer {layer} does not exist: the shadow map has {} layers",
                map.layers
            ))
        })
    }

    /// Uploads the changed part of the class mirror (all of it into a new, larger buffer when
    /// the slots outgrew the buffer, which then needs a new bind group).
    fn upload_classes(&mut self, device: &wgpu::Device, queue: &wgpu::Queue) {
        let Some((from, to)) = self.dirty.take() else { return };
        let (from, to) = if self.mirror.len() as u64 * 4 > self.class_buffer.size() {
            self.class_buffer = class_buffer(device, self.mirror.len().next_power_of_two());
            self.bind = None;
            (0, self.mirror.len())
        } else {
            (from, to)
        };
        queue.write_buffer(&self.class_buffer, from as u64 * 4, bytemuck::cast_slice(&self.mirror[from..to]));
    }
}

fn no_map() -> GpuError {
    GpuError::Shadow("no shadow map: call Renderer::set_shadow_map first".into())
}

impl Renderer {
    /// Allocates the shadow map array: `layers` (1..=[`MAX_SHADOW_LAYERS`]) layers of
    /// `size`×`size` (1 to the device's texture limit), `Depth32Float`, cleared to 1.0 (standard
    /// depth, 0 nearest the light). Replaces the previous map, except that a map of the same size
    /// and layers is kept as it is, contents included: a caller may set the map every frame and
    /// keep drawn layers for later frames (tw-frame's shadow stage reuses them). Errors, never
    /// panics, on bad sizes and when the device cannot hold it.
    pub fn set_shadow_map(&mut self, size: u32, layers: u32) -> Result<(), GpuError> {
        if self.shadow.map.as_ref().is_some_and(|m| m.size == size && m.layers == layers) {
            return Ok(());
        }
        let limits = self.device.limits();
        let max = limits.max_texture_dimension_2d;
        if size == 0 || size > max {
            return Err(GpuError::Shadow(format!(
                "a shadow map of {size}×{size} texels: each side must be 1 to {max}"
            )));
        }
        let gl = self.info.backend == wgpu::Backend::Gl;
        let allocated = allocated_layers(layers, gl);
        if layers == 0 || layers > MAX_SHADOW_LAYERS || allocated > limits.max_texture_array_layers {
            return Err(GpuError::Shadow(format!(
                "a shadow map of {layers} layers: 1 to {} are possible",
                MAX_SHADOW_LAYERS.min(limits.max_texture_array_layers)
            )));
        }
        if limits.max_storage_buffers_per_shader_stage < SHADOWED_VERTEX_STORAGE_BUFFERS {
            return Err(GpuError::Unsupported {
                what: "shadows",
                missing: "3 storage buffers per shader stage",
                adapter: self.adapter_summary(),
            });
        }
        self.shadow.map = None;
        self.shadow.bind = None;
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let texture = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("shadow map"),
            size: wgpu::Extent3d { width: size, height: size, depth_or_array_layers: allocated },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let invalid = pollster::block_on(validation.pop());
        let oom = pollster::block_on(scope.pop());
        if let Some(e) = invalid.or(oom) {
            return Err(GpuError::Shadow(format!("cannot allocate a {size}² × {layers} shadow map: {e}")));
        }
        let array_view = texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some("shadow map layers"),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            aspect: wgpu::TextureAspect::DepthOnly,
            ..Default::default()
        });
        let layer_views = (0..layers)
            .map(|layer| {
                texture.create_view(&wgpu::TextureViewDescriptor {
                    label: Some("shadow map layer"),
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: layer,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        self.shadow.map = Some(ShadowMap { texture, array_view, layer_views, size, layers });
        self.clear_shadow_layers()
    }

    /// Clears every layer of the map to 1.0 (nothing blocks the light).
    fn clear_shadow_layers(&mut self) -> Result<(), GpuError> {
        let map = self.shadow.map.as_ref().ok_or_else(no_map)?;
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("shadow map clear") });
        for view in &map.layer_views {
            encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shadow map clear"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
        }
        self.queue.submit([encoder.finish()]);
        Ok(())
    }

    /// Depth-only draw of `clusters` into layer `layer` with `view_proj` (scene space → the
    /// light's clip space, depth 0..1 nearest the light first), positions being grid coordinates
    /// × `grid_step`: the pool, batching and budget of [`draw`](Self::draw) (clusters uploaded as
    /// needed), both faces, the depth bias of `draw::SHADOW_DEPTH_BIAS`. With `clear` the layer is
    /// cleared to 1.0 first. Counts into the frame's `shadow_*` stats. Submits without waiting.
    pub fn draw_shadow_map(
        &mut self,
        layer: u32,
        view_proj: &Mat4,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        clear: bool,
    ) -> Result<(), GpuError> {
        let size = self.shadow.map.as_ref().ok_or_else(no_map)?.size;
        self.shadow.layer_view(layer)?;
        let pass = Pass::ShadowMap { layer };
        self.draw_pass(None, pass, (size, size), Eye::Light(view_proj), grid_step, clusters, None, clear)
    }

    /// Reads layer `layer` back (waits for the GPU): `size × size` depths, row 0 at the top
    /// (clip y = +1), 1.0 where nothing was drawn. The time counts as `shadow_render`.
    pub fn read_shadow_map(&mut self, layer: u32) -> Result<Vec<f32>, GpuError> {
        let start = Instant::now();
        self.shadow.layer_view(layer)?;
        let gl = self.info.backend == wgpu::Backend::Gl;
        let map = self.shadow.map.as_ref().ok_or_else(no_map)?;
        let depths = if gl {
            let copy = self.shadow.layer_copy.get_or_insert_with(|| LayerCopy::new(&self.device));
            copy.read(&self.device, &self.queue, &mut self.readback, map, layer)?
        } else {
            read_layer_direct(&self.device, &self.queue, &mut self.readback, map, layer)?
        };
        self.stats.shadow_render += start.elapsed();
        Ok(depths)
    }

    /// Shadows for the following shaded passes (their layers' view-projections, splits, bias
    /// and the light, whose direction replaces the fixed sun's); the map must match (`size`, at
    /// most its layers), which the next shaded draw checks. `None`: today's unshadowed shading
    /// with the fixed sun, bit for bit; it also forgets the classes.
    pub fn set_shadows(&mut self, shadows: Option<&Shadows>) {
        self.shadow.shadows = shadows.cloned();
        if shadows.is_none() {
            self.shadow.classes.clear();
            self.shadow.triangles.clear();
        }
    }

    /// Per-cluster classes for the following shaded draws (replacing earlier ones); clusters
    /// not listed are [`ShadowClass::Partial`]. `Lit`: drawn without lookup, with the light's
    /// term; `Shadowed`: without lookup and without it; `Partial`: a lookup per fragment.
    /// Forgets the triangle classes ([`set_shadow_triangle_classes`](Self::set_shadow_triangle_classes)).
    pub fn set_shadow_classes(&mut self, classes: &[(ClusterKey, ShadowClass)]) {
        self.shadow.classes =
            classes.iter().map(|(k, c)| ((k.page, k.index_in_page), class_code(*c))).collect();
        self.shadow.triangles.clear();
    }

    /// Per-triangle classes of `Partial` clusters for the following shaded draws (replacing
    /// earlier ones; cross-culling's subobjects, `tw_runtime::shadow::subobjects`): their lit
    /// and shadowed triangles are drawn without lookups, the rest with them. Ignored where the
    /// renderer cannot draw a part of a cluster with a class of its own
    /// ([`refines_shadow_classes`](Self::refines_shadow_classes)).
    pub fn set_shadow_triangle_classes(&mut self, classes: &[(ClusterKey, TriangleClasses)]) {
        self.shadow.triangles = classes
            .iter()
            .filter(|(_, c)| c.refines())
            .map(|(k, c)| ((k.page, k.index_in_page), *c))
            .collect();
    }

    /// The layers the shaded passes shade with: `None` without shadows, else the shadows'
    /// layer count and whether their splits are disjoint, once the shadows are checked against
    /// the map.
    pub(crate) fn shadow_layers(&self) -> Result<Option<LookupLayers>, GpuError> {
        let Some(shadows) = &self.shadow.shadows else { return Ok(None) };
        let map = self.shadow.map.as_ref().ok_or_else(no_map)?;
        if shadows.size != map.size {
            return Err(GpuError::Shadow(format!(
                "the shadows are for {0}×{0} layers, the shadow map has {1}×{1}",
                shadows.size, map.size
            )));
        }
        if shadows.layers.len() > map.layers as usize {
            return Err(GpuError::Shadow(format!(
                "the shadows have {} layers, the shadow map {}",
                shadows.layers.len(),
                map.layers
            )));
        }
        let disjoint = shadows.layers.windows(2).all(|w| w[0].split[1] <= w[1].split[0]);
        let orthographic = shadows.layers.iter().all(|l| l.view_proj.row(3) == glam::Vec4::W);
        Ok(Some(LookupLayers { count: shadows.layers.len() as u32, disjoint, orthographic }))
    }

    /// The shaded pipeline into `format` at `samples` with `shading`, and its group 1 with
    /// shadows; uploads the slot classes noted since the last pass.
    pub(crate) fn shaded_pipeline(
        &mut self,
        format: wgpu::TextureFormat,
        samples: u32,
        shading: Shading,
    ) -> Result<(wgpu::RenderPipeline, Option<wgpu::BindGroup>), GpuError> {
        let clip = (self.sectioned(), self.dither_pipelines);
        let pipeline =
            self.pipelines.shaded(&self.device, format, samples, (self.mode, shading), clip).clone();
        if shading == Shading::Plain {
            return Ok((pipeline, None));
        }
        self.shadow.upload_classes(&self.device, &self.queue);
        if self.shadow.bind.is_none() {
            let map = self.shadow.map.as_ref().ok_or_else(no_map)?;
            self.shadow.bind = Some(self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("shadows"),
                layout: &self.pipelines.shadow_layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: self.shadow.uniforms.as_entire_binding() },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: self.shadow.class_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: wgpu::BindingResource::TextureView(&map.array_view),
                    },
                ],
            }));
        }
        Ok((pipeline, self.shadow.bind.clone()))
    }
}

/// Reads `layer` of `map` by copying its depth aspect to the readback buffer (every backend
/// but GL); waits for the GPU.
fn read_layer_direct(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    readback: &mut Readback,
    map: &ShadowMap,
    layer: u32,
) -> Result<Vec<f32>, GpuError> {
    let size = map.size;
    let row = padded_row(size, 4);
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("shadow map readback") });
    let buffer = readback.buffer(device, row as u64 * size as u64);
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture: &map.texture,
            mip_level: 0,
            origin: wgpu::Origin3d { x: 0, y: 0, z: layer },
            aspect: wgpu::TextureAspect::DepthOnly,
        },
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(size),
            },
        },
        wgpu::Extent3d { width: size, height: size, depth_or_array_layers: 1 },
    );
    readback.finish_f32(device, queue, encoder, row as usize, size as usize, size as usize)
}

/// The compute copy of one layer into a buffer (GL; shadow_read.wgsl).
struct LayerCopy {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    layer: wgpu::Buffer,
    storage: Option<wgpu::Buffer>,
}

impl LayerCopy {
    fn new(device: &wgpu::Device) -> LayerCopy {
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let buffer = |ty| wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("shadow map copy"),
            entries: &[
                entry(
                    0,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                ),
                entry(1, buffer(wgpu::BufferBindingType::Storage { read_only: false })),
                entry(2, buffer(wgpu::BufferBindingType::Uniform)),
            ],
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("shadow map copy"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shadow map copy"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shadow_read.wgsl").into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("shadow map copy"),
            layout: Some(&pl),
            module: &module,
            entry_point: Some("cs_copy_layer"),
            compilation_options: Default::default(),
            cache: None,
        });
        let layer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("shadow map copy layer"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        LayerCopy { layout, pipeline, layer, storage: None }
    }

    /// Reads `layer` of `map` through the compute copy; waits for the GPU.
    fn read(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        readback: &mut Readback,
        map: &ShadowMap,
        layer: u32,
    ) -> Result<Vec<f32>, GpuError> {
        let size = map.size;
        let bytes = size as u64 * size as u64 * 4;
        if bytes > device.limits().max_storage_buffer_binding_size {
            return Err(GpuError::Shadow(format!(
                "reading a {size}×{size} layer back on GL exceeds the storage-buffer binding limit"
            )));
        }
        if self.storage.as_ref().is_none_or(|b| b.size() < bytes) {
            self.storage = Some(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("shadow map copy"),
                size: bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }));
        }
        let storage = self.storage.as_ref().expect("just created");
        queue.write_buffer(&self.layer, 0, bytemuck::cast_slice(&[layer, 0, 0, 0]));
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shadow map copy"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&map.array_view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: storage,
                        offset: 0,
                        size: wgpu::BufferSize::new(bytes),
                    }),
                },
                wgpu::BindGroupEntry { binding: 2, resource: self.layer.as_entire_binding() },
            ],
        });
        let mut encoder = device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("shadow map readback") });
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(size.div_ceil(8), size.div_ceil(8), 1);
        }
        let target = readback.buffer(device, bytes);
        encoder.copy_buffer_to_buffer(storage, 0, target, 0, bytes);
        let row = size as usize * 4;
        readback.finish_f32(device, queue, encoder, row, size as usize, size as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gl_maps_are_always_two_dimensional_arrays() {
        for layers in 1..=MAX_SHADOW_LAYERS {
            assert_eq!(allocated_layers(layers, false), layers);
            let gl = allocated_layers(layers, true);
            assert!(gl >= 2 && !gl.is_multiple_of(6) && gl - layers <= 1, "{layers} -> {gl}");
        }
    }

    #[test]
    fn uniforms_match_the_shader_layout_and_keep_splits_finite() {
        assert_eq!(std::mem::size_of::<LayerUniform>(), 80);
        assert_eq!(std::mem::size_of::<ShadowUniforms>(), 48 + 6 * 80);
        let eye = Camera::new(glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Z, 1.0, 0.1, 100.0).unwrap();
        let shadows = Shadows {
            light: Light::Point { position: glam::Vec3::new(1.0, 2.0, 3.0) },
            layers: vec![tw_runtime::ShadowLayer { view_proj: Mat4::IDENTITY, split: [0.0, f32::INFINITY] }],
            size: 512,
            bias: 0.001,
        };
        let u = ShadowUniforms::new(&shadows, &eye);
        assert_eq!(u.light, [1.0, 2.0, 3.0, 1.0]);
        assert_eq!(u.view_dir, [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(u.params, [512.0, 0.001, 0.0, 0.0]);
        assert_eq!(u.layers[0].split, [0.0, f32::MAX, 0.0, 0.0]);
        let sun = Shadows { light: Light::Sun { towards: glam::Vec3::Z }, ..shadows };
        assert_eq!(ShadowUniforms::new(&sun, &eye).light, [0.0, 0.0, 1.0, 0.0]);
    }
}
