//! Hardware occlusion queries for a batch of boxes — the test of Yoon et al. 2003 (§5,
//! "conservative occlusion culling": the previous frame's visible set is drawn as occluders,
//! then the bounding boxes of the remaining candidates are rasterized with depth test and no
//! writes inside occlusion queries, batched so the CPU waits once) and of the occlusion switch
//! (docs/DESIGN.md, D6, strategy `queries`).
//!
//! Boxes are drawn into the renderer's own depth target as the frame left it (after
//! [`crate::Renderer::draw`] to [`crate::Target::Own`]), with `GreaterEqual` (reverse-Z; a box
//! face coplanar with an occluder counts as visible), both faces, no colour attachment. One
//! query per box, up to 4096 per query set (wgpu's limit), all resolved and read back at once.
//! Results are what the backend counts: samples passed on Vulkan, 0 or 1 on GL (boolean
//! queries, docs/DESIGN.md, D5). A box the eye is inside (or within the near distance of) is
//! reported as [`EYE_INSIDE`] without a query: rasterization would clip it away. An orthographic
//! camera's near plane is as wide as its view: there every box that reaches the near plane is.

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};

use crate::error::GpuError;
use crate::readback::Readback;

/// The result for a box that contains the eye, or that an orthographic camera's near plane
/// cuts (always visible).
pub const EYE_INSIDE: u64 = u64::MAX;

const MAX_QUERIES: usize = 4096;

/// What every pass drawing with query.wgsl needs (the box queries here, the collision passes of
/// [`crate::visibility`]): the layout of its one uniform (a matrix), the pipeline layout and the
/// shader module.
pub(crate) struct QueryShader {
    pub layout: wgpu::BindGroupLayout,
    pub pipeline_layout: wgpu::PipelineLayout,
    pub module: wgpu::ShaderModule,
}

impl QueryShader {
    pub fn new(device: &wgpu::Device, label: &str) -> QueryShader {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(include_str!("query.wgsl").into()),
        });
        QueryShader { layout, pipeline_layout, module }
    }
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Corner {
    p: [f32; 3],
}

/// The box pipeline and its buffers.
pub(crate) struct BoxQueries {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
    uniform: wgpu::Buffer,
    indices: wgpu::Buffer,
}

/// The 12 triangles of a box over corners numbered by bits (x: 1, y: 2, z: 4).
const BOX_INDICES: [u32; 36] = [
    0, 1, 3, 0, 3, 2, // z min
    4, 6, 7, 4, 7, 5, // z max
    0, 4, 5, 0, 5, 1, // y min
    2, 3, 7, 2, 7, 6, // y max
    0, 2, 6, 0, 6, 4, // x min
    1, 5, 7, 1, 7, 3, // x max
];

impl BoxQueries {
    /// Box queries against a depth target of `depth_format` with `samples` per pixel.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        depth_format: wgpu::TextureFormat,
        samples: u32,
    ) -> BoxQueries {
        let QueryShader { layout, pipeline_layout: pl, module } = QueryShader::new(device, "box queries");
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("box queries"),
            layout: Some(&pl),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_box"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: 12,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3],
                })],
            },
            primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: depth_format,
                depth_write_enabled: Some(false),
                depth_compare: Some(wgpu::CompareFunction::GreaterEqual),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: wgpu::MultisampleState { count: samples, ..Default::default() },
            fragment: None,
            multiview_mask: None,
            cache: None,
        });
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("box queries"),
            size: 64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let indices = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("box indices"),
            size: std::mem::size_of_val(&BOX_INDICES) as u64,
            usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        queue.write_buffer(&indices, 0, bytemuck::cast_slice(&BOX_INDICES));
        BoxQueries { layout, pipeline, uniform, indices }
    }

    /// Queries `boxes` (scene-space min, max) against `depth_view`; see the module docs.
    #[allow(clippy::too_many_arguments)]
    pub fn run(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        readback: &mut Readback,
        depth_view: &wgpu::TextureView,
        view_proj: Mat4,
        camera: &tw_runtime::Camera,
        boxes: &[(Vec3, Vec3)],
    ) -> Result<Vec<u64>, GpuError> {
        let mut results = vec![0u64; boxes.len()];
        if boxes.is_empty() {
            return Ok(results);
        }
        queue.write_buffer(&self.uniform, 0, bytemuck::cast_slice(&view_proj.to_cols_array()));
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("box queries"),
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: self.uniform.as_entire_binding() }],
        });
        for (chunk_index, chunk) in boxes.chunks(MAX_QUERIES).enumerate() {
            let base = chunk_index * MAX_QUERIES;
            let mut corners = Vec::with_capacity(chunk.len() * 8);
            for &(lo, hi) in chunk {
                for c in 0..8 {
                    let p = Vec3::new(
                        if c & 1 != 0 { hi.x } else { lo.x },
                        if c & 2 != 0 { hi.y } else { lo.y },
                        if c & 4 != 0 { hi.z } else { lo.z },
                    );
                    corners.push(Corner { p: p.to_array() });
                }
            }
            let vertices = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("box corners"),
                size: (corners.len() * 12) as u64,
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            queue.write_buffer(&vertices, 0, bytemuck::cast_slice(&corners));
            let n = chunk.len() as u32;
            let set = device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("box queries"),
                ty: wgpu::QueryType::Occlusion,
                count: n,
            });
            let resolve = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("box query results"),
                size: n as u64 * 8,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let mut encoder = device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("box queries"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: depth_view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Load,
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: Some(&set),
                    multiview_mask: None,
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.set_vertex_buffer(0, vertices.slice(..));
                pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
                for i in 0..n {
                    pass.begin_occlusion_query(i);
                    pass.draw_indexed(0..36, (i * 8) as i32, 0..1);
                    pass.end_occlusion_query();
                }
            }
            encoder.resolve_query_set(&set, 0..n, &resolve, 0);
            let target = readback.buffer(device, n as u64 * 8);
            encoder.copy_buffer_to_buffer(&resolve, 0, target, 0, n as u64 * 8);
            let bytes = readback.finish(device, queue, encoder, n as usize * 8, n as usize * 8, 1)?;
            for (i, b) in bytes.chunks_exact(8).enumerate() {
                results[base + i] = u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]);
            }
        }
        for (r, &(lo, hi)) in results.iter_mut().zip(boxes) {
            if reaches_near_plane(camera, lo, hi) {
                *r = EYE_INSIDE;
            }
        }
        Ok(results)
    }
}

/// Whether rasterizing the box `lo..hi` could lose it to the near plane: in perspective when
/// the eye is inside it or within the near distance of it; in orthographic when its nearest
/// point is at most the near distance ahead (the near plane spans the whole view).
fn reaches_near_plane(camera: &tw_runtime::Camera, lo: Vec3, hi: Vec3) -> bool {
    let (eye, near) = (camera.eye, camera.near);
    if camera.is_orthographic() {
        let dir = camera.direction();
        let nearest = ((lo + hi) * 0.5 - eye).dot(dir) - ((hi - lo) * 0.5).dot(dir.abs());
        nearest <= near
    } else {
        let m = Vec3::splat(near);
        eye.cmpge(lo - m).all() && eye.cmple(hi + m).all()
    }
}
