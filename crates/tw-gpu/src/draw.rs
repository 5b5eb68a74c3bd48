//! Drawing pooled clusters (docs/DESIGN.md, D5): the pipelines (shaded colour per target format,
//! the item buffer), their bind group, and the encoding of one batch of resident clusters as a
//! single `multi_draw_indexed_indirect` where the device supports indirect execution
//! (`DownlevelFlags::INDIRECT_EXECUTION`: Vulkan, Metal, DX12, GL ≥ 4.3 / ES ≥ 3.1 — wgpu's GL
//! backend then loops over the draws itself) or a loop of `draw_indexed` otherwise. Both give the
//! same draws in the same order, hence the same image. Depth is reverse-Z (`Greater`, clear 0)
//! in `Depth32Float`; both faces are drawn (inputs are not consistently wound).
//! Shaders: common.wgsl (uniforms, slot table, vertex stage), draw.wgsl (shading), shadow.wgsl
//! (the shadow map's depth pass and the shading with shadows, [`crate::shadow`]), ids.wgsl (item
//! buffer).

use crate::color::ColorMode;
use crate::pool::{DrawArgs, UNIT};

pub(crate) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
pub(crate) const ITEM_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;

/// How a batch's draws are issued.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DrawMode {
    /// One `multi_draw_indexed_indirect` per batch (needs `DownlevelFlags::INDIRECT_EXECUTION`).
    Indirect,
    /// One `draw_indexed` per cluster.
    Direct,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Uniforms {
    pub view_proj: [[f32; 4]; 4],
    pub eye: [f32; 4],
    pub sun: [f32; 4],
    pub params: [u32; 4],
    /// xyz: unit direction from the view's target towards the eye (the headlight).
    pub headlight: [f32; 4],
    /// The section's half-spaces (`tw_runtime::Section::clip_planes`; common.wgsl `clip`).
    pub clip: [[f32; 4]; 12],
}

/// How a shaded pipeline lights its triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Shading {
    /// The fixed sun, no shadows (draw.wgsl `vs_shade`).
    Plain,
    /// The shadows' light, on or off by the cluster's class (`Lit`, `Shadowed`), no lookup
    /// (shadow.wgsl `fs_classified`).
    Classified,
    /// The shadows' light, with a lookup in the map's layers for the fragments of `Partial`
    /// clusters (shadow.wgsl `fs_shadowed`).
    Lookup(LookupLayers),
}

/// The layers a lookup picks from, as pipeline constants (shadow.wgsl `SHADOW_LAYERS`,
/// `SHADOW_DISJOINT`, `SHADOW_ORTHO`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct LookupLayers {
    /// How many layers the shadows have.
    pub count: u32,
    /// Whether their splits are ascending and disjoint (sun cascades): then the depth alone
    /// picks the one layer to look up.
    pub disjoint: bool,
    /// Whether every layer is orthographic (w = 1: no perspective divide).
    pub orthographic: bool,
}

/// What a shaded pipeline is made for: (format, samples, mode, shading, section, dither).
type ShadedKey = (wgpu::TextureFormat, u32, ColorMode, Shading, bool, bool);

/// The pipelines and their layout.
pub(crate) struct Pipelines {
    pub bind_layout: wgpu::BindGroupLayout,
    layout: wgpu::PipelineLayout,
    /// Group 1 of the shading with shadows (shadow.wgsl: uniforms, slot classes, the map).
    pub shadow_layout: wgpu::BindGroupLayout,
    shadowed_layout: wgpu::PipelineLayout,
    shade: wgpu::ShaderModule,
    shaded: Vec<(ShadedKey, wgpu::RenderPipeline)>,
    /// The shadow map's depth-only pipelines, without and with a section.
    shadow_depth: [Option<wgpu::RenderPipeline>; 2],
    /// The eye's depth-only pipelines, by samples per pixel, section and dither.
    eye_depth: Vec<((u32, bool, bool), wgpu::RenderPipeline)>,
    /// The item-buffer pipelines, without and with a section.
    item: [Option<wgpu::RenderPipeline>; 2],
    /// Whether the item shader gets `@builtin(primitive_index)` (Features::PRIMITIVE_INDEX).
    pub primitive_index: bool,
}

fn storage_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        // Vertex: the shaded pipeline looks colours up per vertex (draw.wgsl vs_shade);
        // fragment: the item buffer reads the slot table (ids.wgsl).
        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

impl Pipelines {
    pub fn new(device: &wgpu::Device) -> Pipelines {
        let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("clusters"),
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
                storage_entry(1),
                storage_entry(2),
            ],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("clusters"),
            bind_group_layouts: &[Some(&bind_layout)],
            immediate_size: 0,
        });
        let shadow_layout = crate::shadow::bind_layout(device);
        let shadowed_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("clusters with shadows"),
            bind_group_layouts: &[Some(&bind_layout), Some(&shadow_layout)],
            immediate_size: 0,
        });
        let source = format!(
            "{}\n{}\n{}\n{}",
            color_constants(),
            include_str!("common.wgsl"),
            include_str!("draw.wgsl"),
            include_str!("shadow.wgsl")
        );
        let shade = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("clusters"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        Pipelines {
            bind_layout,
            layout,
            shadow_layout,
            shadowed_layout,
            shade,
            shaded: Vec::new(),
            shadow_depth: [None, None],
            eye_depth: Vec::new(),
            item: [None, None],
            primitive_index: device.features().contains(wgpu::Features::PRIMITIVE_INDEX),
        }
    }

    /// The shaded pipeline drawing into `format` with `samples` per pixel in colour `mode`,
    /// created on first use. The mode and whether the shader encodes sRGB (a non-sRGB `format`)
    /// are the shader's pipeline constants (draw.wgsl `COLOR_MODE`, `ENCODE_SRGB`), not
    /// uniforms: lavapipe (Mesa 22.3) recompiles, and keeps, a copy of a shader that branches
    /// on uniform values at every bind (docs/RUNTIME.md, "Memory").
    ///
    /// With shadows ([`Shading::Classified`], [`Shading::Lookup`]: shadow.wgsl `vs_shadowed`,
    /// bind group 1 of [`Pipelines::shadow_layout`]) the number of map layers is the pipeline
    /// constant `SHADOW_LAYERS`. Classified clusters get a pipeline without the lookup code: on
    /// CPU drivers a branch not taken still costs its code (lavapipe runs both sides under a
    /// mask): with one pipeline branching on the class, a 1280×720 pass of only `Lit` clusters
    /// took 76 ms against 34 ms unshadowed; with its own pipeline, 25–33 ms (tests/shadows.rs
    /// `bench_shadow_passes`, release, a busy 2-core machine).
    ///
    /// With `section`, the pipeline constant `SECTION` turns on the fragment stage's clip test
    /// and the back faces' section colour (draw.wgsl `section_color`); without, no fragment
    /// stage discards. With `dither`, the constant `DITHER` turns on the cross-fade's test of
    /// each fragment against its cluster's fade word (common.wgsl `dither_keeps`,
    /// [`crate::dither`]).
    pub fn shaded(
        &mut self,
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
        samples: u32,
        (mode, shading): (ColorMode, Shading),
        (section, dither): (bool, bool),
    ) -> &wgpu::RenderPipeline {
        let key = (format, samples, mode, shading, section, dither);
        let i = match self.shaded.iter().position(|(k, _)| *k == key) {
            Some(i) => i,
            None => {
                let constants = [
                    ("COLOR_MODE", crate::color::mode_code(mode) as f64),
                    ("ENCODE_SRGB", if format.is_srgb() { 0.0 } else { 1.0 }),
                    ("SECTION", if section { 1.0 } else { 0.0 }),
                    ("DITHER", if dither { 1.0 } else { 0.0 }),
                ];
                let p = match shading {
                    Shading::Plain => pipeline(
                        device,
                        &self.layout,
                        &self.shade,
                        ("vs_shade", &constants),
                        ("fs_main", &constants),
                        format,
                        samples,
                    ),
                    Shading::Classified => pipeline(
                        device,
                        &self.shadowed_layout,
                        &self.shade,
                        ("vs_shadowed", &constants),
                        ("fs_classified", &constants),
                        format,
                        samples,
                    ),
                    Shading::Lookup(layers) => {
                        let all = [
                            constants[0],
                            constants[1],
                            constants[2],
                            constants[3],
                            ("SHADOW_LAYERS", layers.count as f64),
                            ("SHADOW_DISJOINT", if layers.disjoint { 1.0 } else { 0.0 }),
                            ("SHADOW_ORTHO", if layers.orthographic { 1.0 } else { 0.0 }),
                        ];
                        pipeline(
                            device,
                            &self.shadowed_layout,
                            &self.shade,
                            ("vs_shadowed", &all),
                            ("fs_shadowed", &all),
                            format,
                            samples,
                        )
                    }
                };
                self.shaded.push((key, p));
                self.shaded.len() - 1
            }
        };
        &self.shaded[i].1
    }

    /// The item-buffer pipeline ([`ITEM_FORMAT`]), created on first use; with `section` it
    /// discards the removed fragments (ids.wgsl).
    pub fn item(&mut self, device: &wgpu::Device, section: bool) -> &wgpu::RenderPipeline {
        let slot = section as usize;
        if self.item[slot].is_none() {
            let ids = if self.primitive_index {
                include_str!("ids.wgsl")
                    .replace("PRIM_ARG", ", @builtin(primitive_index) prim: u32")
                    .replace("PRIM_VALUE", "prim")
            } else {
                include_str!("ids.wgsl").replace("PRIM_ARG", "").replace("PRIM_VALUE", "0xffffffffu")
            };
            let enable = if self.primitive_index { "enable primitive_index;\n" } else { "" };
            let source = format!("{enable}{}\n{ids}", include_str!("common.wgsl"));
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("item buffer"),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
            let constants = [("SECTION", if section { 1.0 } else { 0.0 })];
            self.item[slot] = Some(pipeline(
                device,
                &self.layout,
                &module,
                ("vs_main", &constants),
                ("fs_items", &constants),
                ITEM_FORMAT,
                1,
            ));
        }
        self.item[slot].as_ref().expect("just created")
    }

    /// The eye's depth-only pipeline at `samples` per pixel (shadow.wgsl `vs_depth` with the
    /// camera's uniforms, no fragment stage), created on first use: reverse-Z (`Greater`),
    /// both faces, no bias, as the shaded pipelines write depth. The occluder pass of the
    /// parallel pipelines (GigaWalk's OR renders depth only) draws with it. With `dither` it
    /// discards what the cross-fade's shaded pass would (common.wgsl `fs_depth_fade`), so that
    /// its depth is that pass's.
    pub fn eye_depth(
        &mut self,
        device: &wgpu::Device,
        samples: u32,
        (section, dither): (bool, bool),
    ) -> &wgpu::RenderPipeline {
        let key = (samples, section, dither);
        if let Some(i) = self.eye_depth.iter().position(|(k, _)| *k == key) {
            return &self.eye_depth[i].1;
        }
        let depth = (wgpu::CompareFunction::Greater, Default::default());
        let label = ("eye depth", section, dither);
        let pipeline = depth_only(device, &self.layout, &self.shade, label, depth, samples);
        self.eye_depth.push((key, pipeline));
        &self.eye_depth.last().expect("just pushed").1
    }

    /// The shadow map's depth-only pipeline (shadow.wgsl `vs_depth`, no fragment stage),
    /// created on first use: standard depth (`Less`, 0 nearest the light), both faces drawn,
    /// and [`SHADOW_DEPTH_BIAS`] so that a lit surface is not shadowed by itself.
    pub fn shadow_depth(&mut self, device: &wgpu::Device, section: bool) -> &wgpu::RenderPipeline {
        let slot = section as usize;
        if self.shadow_depth[slot].is_none() {
            let depth = (wgpu::CompareFunction::Less, SHADOW_DEPTH_BIAS);
            let label = ("shadow map", section, false);
            self.shadow_depth[slot] = Some(depth_only(device, &self.layout, &self.shade, label, depth, 1));
        }
        self.shadow_depth[slot].as_ref().expect("just created")
    }
}

/// The shadow map's depth bias (pushing stored depths away from the light). The slope term
/// covers a surface's own depth change across a texel: a point is compared with the depth
/// rasterized at its texel's centre (shadow.wgsl `light_reaches`), at most half a texel away in
/// x and y, i.e. at most one texel's change along the steeper axis; 2 doubles that for margin.
/// The constant term (units of the float depth's precision at the primitive's depth) covers the
/// rounding between the rasterized depth and the depth the shading computes for a surface facing
/// the light squarely (a floor under the sun at noon), where the slope term is 0.
pub(crate) const SHADOW_DEPTH_BIAS: wgpu::DepthBiasState =
    wgpu::DepthBiasState { constant: 16, slope_scale: 2.0, clamp: 0.0 };

/// WGSL constants of [`ColorMode::Shadow`]'s mask colours and of the highlight's tint (sRGB,
/// 0..1), from `tw_core::color`.
fn color_constants() -> String {
    use tw_core::color::{HIGHLIGHT, SECTION, SHADOW_AWAY, SHADOW_BLOCKED, SHADOW_LIT};
    let c = |name: &str, v: [u8; 4]| {
        let f = |b: u8| format!("{:?}", b as f32 / 255.0);
        format!("const {name}: vec3<f32> = vec3<f32>({}, {}, {});\n", f(v[0]), f(v[1]), f(v[2]))
    };
    c("SHADOW_LIT", SHADOW_LIT)
        + &c("SHADOW_BLOCKED", SHADOW_BLOCKED)
        + &c("SHADOW_AWAY", SHADOW_AWAY)
        + &c("HIGHLIGHT", HIGHLIGHT)
        + &c("SECTION_COLOR", SECTION)
}

/// A depth-only pipeline: shadow.wgsl's `vs_depth` (positions only, through `u.view_proj`), no
/// fragment stage, both faces, depth written with `compare` and `bias`, at `samples` per pixel.
/// With a section (`label.1`): common.wgsl's `vs_depth_world` and a fragment stage,
/// `fs_depth_clip`, that discards the removed points, so that the depth the occlusion tests
/// and the shadow lookups read holds only what is drawn. With a cross-fade (`label.2`):
/// common.wgsl's `vs_depth_fade` (positions and slots) and `fs_depth_fade`, which discards what
/// the dithered shaded pass discards (and the removed points where there is a section).
fn depth_only(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    (label, section, dither): (&str, bool, bool),
    (compare, bias): (wgpu::CompareFunction, wgpu::DepthBiasState),
    samples: u32,
) -> wgpu::RenderPipeline {
    let (vertex, fragment) = match (dither, section) {
        (true, _) => ("vs_depth_fade", Some("fs_depth_fade")),
        (false, true) => ("vs_depth_world", Some("fs_depth_clip")),
        (false, false) => ("vs_depth", None),
    };
    let constants = [("SECTION", if section { 1.0 } else { 0.0 })];
    let positions = wgpu::vertex_attr_array![0 => Float32x3];
    // Position at 0, object at 12, slot at 16 (pool.rs PoolVertex).
    let with_slots = wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32, 2 => Uint32];
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(vertex),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: UNIT,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: if dither { &with_slots[..] } else { &positions[..] },
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
            depth_compare: Some(compare),
            stencil: Default::default(),
            bias,
        }),
        multisample: wgpu::MultisampleState { count: samples, ..Default::default() },
        fragment: fragment.map(|entry| wgpu::FragmentState {
            module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &constants,
                ..Default::default()
            },
            targets: &[],
        }),
        multiview_mask: None,
        cache: None,
    })
}

fn pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    (vertex, constants): (&str, &[(&str, f64)]),
    (fragment, fragment_constants): (&str, &[(&str, f64)]),
    format: wgpu::TextureFormat,
    samples: u32,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(fragment),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(vertex),
            compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: UNIT,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32, 2 => Uint32, 3 => Uint32],
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
        multisample: wgpu::MultisampleState { count: samples, ..Default::default() },
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fragment),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: fragment_constants,
                ..Default::default()
            },
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

/// A growable INDIRECT buffer for one batch's arguments.
#[derive(Default)]
pub(crate) struct IndirectArgs {
    buffer: Option<wgpu::Buffer>,
}

impl IndirectArgs {
    /// Writes `args` (through the queue, so before the next submit) and returns the buffer.
    pub fn write(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, args: &[DrawArgs]) -> &wgpu::Buffer {
        let size = (std::mem::size_of_val(args) as u64).max(64);
        if self.buffer.as_ref().is_none_or(|b| b.size() < size) {
            self.buffer = Some(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("indirect draws"),
                size: size.next_power_of_two(),
                usage: wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let buffer = self.buffer.as_ref().expect("just created");
        queue.write_buffer(buffer, 0, bytemuck::cast_slice(args));
        buffer
    }
}

/// Records the draws of one batch into `pass` (pipeline and bind group already set); indirect:
/// `args` are in the buffer from the given byte offset.
pub(crate) fn encode_batch(
    pass: &mut wgpu::RenderPass<'_>,
    arena: &wgpu::Buffer,
    args: &[DrawArgs],
    indirect: Option<(&wgpu::Buffer, u64)>,
) {
    if args.is_empty() {
        return;
    }
    pass.set_vertex_buffer(0, arena.slice(..));
    pass.set_index_buffer(arena.slice(..), wgpu::IndexFormat::Uint32);
    match indirect {
        Some((buffer, offset)) => pass.multi_draw_indexed_indirect(buffer, offset, args.len() as u32),
        None => {
            for a in args {
                pass.draw_indexed(a.first_index..a.first_index + a.index_count, a.base_vertex, 0..1);
            }
        }
    }
}
