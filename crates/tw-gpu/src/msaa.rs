//! Multisampled shading (`--samples 4`): the shaded passes draw into a multisampled colour and
//! depth target and resolve the colour into the frame's single-sample target (the own target's
//! once per frame, when it is read, not after every pass: ~6 ms a resolve at 1280×720 on
//! lavapipe). The fidelity
//! goal (PSNR against the full-detail reference) is limited by aliasing at one sample per
//! pixel: a LOD cut moves sub-pixel edges, which flips whole pixels (docs/benchmarks-log.md,
//! "Fidelity and anti-aliasing").
//!
//! The occlusion strategies read a single-sample depth: the CPU HZB's read-back
//! ([`crate::Renderer::read_depth`]) and the GPU HZB's pyramid ([`crate::gpu_cull`]). For them
//! the multisampled depth is resolved to the *farthest* of each pixel's samples (msaa.wgsl; a
//! pixel with any uncovered sample reads 0, the background), so that a depth test against the
//! resolved value is conservative for every sample; the CPU tests then treat a pixel as the
//! four sample positions of WebGPU's standard pattern ([`tw_runtime::hzb::SAMPLES_4X`],
//! [`tw_runtime::hzb::Hzb::with_samples`]). Hardware occlusion queries ([`crate::query`]) run on the
//! multisampled depth itself, with the same sample count. The item buffer stays
//! single-sample: it counts what covers pixel centres.

use crate::draw::DEPTH_FORMAT;

/// The sample counts [`crate::Renderer::set_samples`] accepts (WebGPU guarantees 4 for the
/// formats used here).
pub const SUPPORTED_SAMPLES: [u32; 2] = [1, 4];

/// The multisampled colour and depth targets of one size and format.
pub(crate) struct MsaaTarget {
    pub size: (u32, u32),
    pub format: wgpu::TextureFormat,
    pub color: wgpu::TextureView,
    pub depth: wgpu::TextureView,
    /// The depth aspect alone, for [`DepthResolve::encode`].
    pub depth_only: wgpu::TextureView,
}

impl MsaaTarget {
    pub fn new(
        device: &wgpu::Device,
        size: (u32, u32),
        format: wgpu::TextureFormat,
        samples: u32,
    ) -> MsaaTarget {
        let texture = |label, format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let color = texture("msaa colour", format, wgpu::TextureUsages::RENDER_ATTACHMENT)
            .create_view(&Default::default());
        let depth_texture = texture(
            "msaa depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let depth = depth_texture.create_view(&Default::default());
        let depth_only = depth_texture.create_view(&wgpu::TextureViewDescriptor {
            aspect: wgpu::TextureAspect::DepthOnly,
            ..Default::default()
        });
        MsaaTarget { size, format, color, depth, depth_only }
    }
}

/// The pass writing the farthest sample of a multisampled depth into a single-sample depth.
pub(crate) struct DepthResolve {
    samples: u32,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
}

impl DepthResolve {
    pub fn new(device: &wgpu::Device, samples: u32) -> DepthResolve {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("depth resolve"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    // Unfilterable float, not depth: the form GL accepts (see crate::depth).
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: true,
                },
                count: None,
            }],
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("depth resolve"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let source = include_str!("msaa.wgsl").replace("SAMPLES", &format!("{}", samples as i32));
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("depth resolve"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("depth resolve"),
            layout: Some(&pl),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_full"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Always),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_resolve"),
                compilation_options: Default::default(),
                targets: &[],
            }),
            multiview_mask: None,
            cache: None,
        });
        DepthResolve { samples, layout, pipeline }
    }

    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Records the resolve of `source` (the multisampled depth view) into `target` (a
    /// single-sample depth view of the same size).
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        source: &wgpu::TextureView,
        target: &wgpu::TextureView,
    ) {
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("depth resolve"),
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(source),
            }],
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("depth resolve"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: target,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.draw(0..3, 0..1);
    }
}
