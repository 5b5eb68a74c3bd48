//! Depth readback for GigaWalk's `hzb` occlusion strategy (Baxter et al. 2002 §5.1;
//! docs/DESIGN.md, D6): after the occluders are drawn, the reverse-Z `Depth32Float` buffer is read
//! back as f32 in the layout [`tw_runtime::hzb::Hzb::build`] takes (`width × height`, rows from the
//! top, 1 at the near plane, 0 at the far plane and on the cleared background).
//!
//! Vulkan (and the other native backends) copy the depth aspect straight into the readback
//! buffer. GL cannot `textureLoad` a `texture_depth_2d` nor copy a depth texture to a buffer
//! portably (glReadPixels of depth is not in GLES), so there a compute pass (depth.wgsl) loads
//! the depth texture bound as an unfilterable `texture_2d<f32>` into a storage buffer, which is
//! copied to the readback buffer. On lavapipe the direct copy saves the compute pass, a few
//! milliseconds of each `hzb` frame at 1280×720.

use crate::error::GpuError;
use crate::readback::Readback;

/// A depth buffer read back from the GPU; see the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    pub width: u32,
    pub height: u32,
    /// Reverse-Z depth, rows from the top; 0 where nothing was drawn.
    pub depth: Vec<f32>,
}

impl DepthImage {
    pub fn get(&self, x: u32, y: u32) -> Option<f32> {
        if x >= self.width || y >= self.height {
            return None;
        }
        self.depth.get(y as usize * self.width as usize + x as usize).copied()
    }

    /// Pixels with depth > 0 (something drawn).
    pub fn covered_pixels(&self) -> usize {
        self.depth.iter().filter(|&&d| d > 0.0).count()
    }
}

/// Reads `texture` (Depth32Float, COPY_SRC) back by copying its depth aspect to the buffer
/// (every backend but GL); waits for the GPU.
pub(crate) fn read_direct(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    readback: &mut Readback,
    texture: &wgpu::Texture,
) -> Result<DepthImage, GpuError> {
    let (width, height) = (texture.width(), texture.height());
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("depth readback") });
    readback.copy_texture_aspect(device, &mut encoder, texture, wgpu::TextureAspect::DepthOnly, 4);
    let pitch = crate::readback::padded_row(width, 4) as usize;
    let depth = readback.finish_f32(device, queue, encoder, pitch, width as usize, height as usize)?;
    Ok(DepthImage { width, height, depth })
}

/// The compute pipeline copying depth to a buffer (GL).
pub(crate) struct DepthCopy {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    storage: Option<wgpu::Buffer>,
}

impl DepthCopy {
    pub fn new(device: &wgpu::Device) -> DepthCopy {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("depth copy"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: false },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("depth copy"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("depth copy"),
            source: wgpu::ShaderSource::Wgsl(include_str!("depth.wgsl").into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("depth copy"),
            layout: Some(&pl),
            module: &module,
            entry_point: Some("cs_copy"),
            compilation_options: Default::default(),
            cache: None,
        });
        DepthCopy { layout, pipeline, storage: None }
    }

    /// Reads `texture` (Depth32Float, TEXTURE_BINDING) back through the compute pass (GL);
    /// waits for the GPU.
    pub fn read(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        readback: &mut Readback,
        texture: &wgpu::Texture,
    ) -> Result<DepthImage, GpuError> {
        let (width, height) = (texture.width(), texture.height());
        let size = width as u64 * height as u64 * 4;
        if size > device.limits().max_storage_buffer_binding_size {
            return Err(GpuError::Gpu(format!(
                "a {width}×{height} depth buffer exceeds the storage-buffer binding limit"
            )));
        }
        if self.storage.as_ref().is_none_or(|b| b.size() < size) {
            self.storage = Some(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("depth copy"),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }));
        }
        let storage = self.storage.as_ref().expect("just created");
        let view = texture.create_view(&wgpu::TextureViewDescriptor {
            aspect: wgpu::TextureAspect::DepthOnly,
            ..Default::default()
        });
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("depth copy"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&view) },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: storage,
                        offset: 0,
                        size: wgpu::BufferSize::new(size),
                    }),
                },
            ],
        });
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("depth readback") });
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(width.div_ceil(8), height.div_ceil(8), 1);
        }
        let target = readback.buffer(device, size);
        encoder.copy_buffer_to_buffer(storage, 0, target, 0, size);
        let row = width as usize * 4;
        let depth = readback.finish_f32(device, queue, encoder, row, width as usize, height as usize)?;
        Ok(DepthImage { width, height, depth })
    }
}
