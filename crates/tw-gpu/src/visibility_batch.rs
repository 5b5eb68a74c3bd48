//! Full-visibility queries in batches (`crate::visibility`'s default where the device allows it):
//! the same answers as one occlusion query a draw, in a handful of draws per run.
//!
//! CULLIDE's passes query and draw each element on its own (tw-collide), hundreds of thousands a
//! step, and a draw costs the same whatever it holds: on Mesa's CPU drivers ~30 µs, so the bunny
//! falling through the dragon took seconds a step in query overhead alone. Here the ops of a
//! run are grouped into *batches* of consecutive queries and consecutive draws, and each batch
//! is one draw call:
//! - the vertex stage pulls its triangle from the uploaded vertices (a binary search over the
//!   run's per-op first triangles finds the op a triangle belongs to; a table per block of 16
//!   triangles and a forward scan measured no faster on lavapipe);
//! - a draw batch writes depth with `LessEqual`, as a draw op does;
//! - a query batch holds the depth read-only, and its fragment stage does the occlusion query's
//!   test by hand (`GreaterEqual`, or `Greater` for [`DepthTest::Strict`]) against the stored
//!   depth at its pixel, counting the fragments that pass per op with an atomic add.
//!
//! The queries of one batch all see the depth of the draws before it, as they would one after
//! the other (a query writes nothing), so the counts are those of the occlusion queries: samples
//! passed, at one sample a pixel (`crates/tw-gpu/tests/visibility.rs` compares both paths). It
//! needs storage buffers in the vertex and fragment stages and a depth texture read in the
//! fragment stage: not on GL ([`supported`]).

use std::ops::Range;

use glam::Mat4;
use wgpu::util::DeviceExt;

use crate::error::GpuError;
use crate::readback::Readback;
use crate::visibility::{DepthTest, VisOp};

/// What a run's batches share: `Params` in visibility_batch.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    view_proj: [f32; 16],
    strict: u32,
    ops: u32,
    pad: [u32; 2],
}

/// The pipelines of batched runs: indexed by faces (both, split) like `Visibility`'s.
pub(crate) struct Batched {
    pulled: wgpu::BindGroupLayout,
    counted: wgpu::BindGroupLayout,
    query: [wgpu::RenderPipeline; 2],
    draw: [wgpu::RenderPipeline; 2],
    uniform: wgpu::Buffer,
}

/// Whether `adapter` runs batched queries: storage buffers read in the vertex stage and
/// written in the fragment stage, and a depth texture loaded in the fragment stage, which
/// wgpu's GL backend cannot translate (naga's GLSL has no `textureLoad` of depth textures).
pub(crate) fn supported(adapter: &wgpu::Adapter) -> bool {
    let flags = adapter.get_downlevel_capabilities().flags;
    adapter.get_info().backend != wgpu::Backend::Gl
        && flags
            .contains(wgpu::DownlevelFlags::VERTEX_STORAGE | wgpu::DownlevelFlags::FRAGMENT_WRITABLE_STORAGE)
}

/// The depth format of the visibility target (`crate::visibility`).
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

impl Batched {
    pub(crate) fn new(device: &wgpu::Device) -> Batched {
        let storage = |binding, read_only, visibility| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let vertex = wgpu::ShaderStages::VERTEX;
        let pulled = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("visibility batch"),
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
                storage(1, true, vertex),
                storage(2, true, vertex),
                storage(3, true, vertex),
            ],
        });
        let counted = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("visibility batch counts"),
            entries: &[
                storage(0, false, wgpu::ShaderStages::FRAGMENT),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
            ],
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("visibility batch"),
            source: wgpu::ShaderSource::Wgsl(include_str!("visibility_batch.wgsl").into()),
        });
        let layout = |groups: &[Option<&wgpu::BindGroupLayout>]| {
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("visibility batch"),
                bind_group_layouts: groups,
                immediate_size: 0,
            })
        };
        let query_layout = layout(&[Some(&pulled), Some(&counted)]);
        let draw_layout = layout(&[Some(&pulled)]);
        let pipeline = |query: bool, cull: Option<wgpu::Face>| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(if query { "visibility batch query" } else { "visibility batch draw" }),
                layout: Some(if query { &query_layout } else { &draw_layout }),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_pull"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                // The same convention as `Visibility`'s pipelines (tests/visibility.rs).
                primitive: wgpu::PrimitiveState {
                    cull_mode: cull,
                    front_face: wgpu::FrontFace::Cw,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(!query),
                    // A query tests in its fragment stage: every fragment must reach it.
                    depth_compare: Some(if query {
                        wgpu::CompareFunction::Always
                    } else {
                        wgpu::CompareFunction::LessEqual
                    }),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: query.then(|| wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_query"),
                    compilation_options: Default::default(),
                    targets: &[],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let query = [pipeline(true, None), pipeline(true, Some(wgpu::Face::Front))];
        let draw = [pipeline(false, None), pipeline(false, Some(wgpu::Face::Back))];
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("visibility batch"),
            size: std::mem::size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Batched { pulled, counted, query, draw, uniform }
    }

    /// `Visibility::run` in batches: `ops` (checked against the uploaded vertices by the
    /// caller, at least one query) over `vertices` (the uploaded ones, three floats each) into
    /// the depth target `depth`, cleared first.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run(
        &self,
        (device, queue, readback): (&wgpu::Device, &wgpu::Queue, &mut Readback),
        depth: &wgpu::TextureView,
        vertices: wgpu::BindingResource<'_>,
        view_proj: Mat4,
        ops: &[VisOp],
        test: DepthTest,
        split: bool,
    ) -> Result<Vec<u64>, GpuError> {
        let (first_triangle, first_vertex) = op_tables(ops)?;
        let params = Params {
            view_proj: view_proj.to_cols_array(),
            strict: (test == DepthTest::Strict) as u32,
            ops: ops.len() as u32,
            pad: [0; 2],
        };
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&params));
        let table = |label, data: &[u32]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::cast_slice(data),
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let first_triangle_buffer = table("visibility batch first triangles", &first_triangle);
        let first_vertex_buffer = table("visibility batch first vertices", &first_vertex);
        let counts_bytes = ops.len() as u64 * 4;
        let passed = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("visibility batch counts"),
            size: counts_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let pulled = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("visibility batch"),
            layout: &self.pulled,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: self.uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: vertices },
                wgpu::BindGroupEntry { binding: 2, resource: first_triangle_buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: first_vertex_buffer.as_entire_binding() },
            ],
        });
        let counted = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("visibility batch counts"),
            layout: &self.counted,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: passed.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(depth) },
            ],
        });

        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&passed, 0, None);
        // The target starts cleared, whatever the first batch is.
        drop(depth_pass(&mut encoder, depth, Some(wgpu::LoadOp::Clear(1.0))));
        for (query, range) in batches(ops) {
            let vertices = first_triangle[range.start] * 3..first_triangle[range.end] * 3;
            if vertices.is_empty() {
                continue;
            }
            let mut pass = depth_pass(&mut encoder, depth, (!query).then_some(wgpu::LoadOp::Load));
            pass.set_bind_group(0, &pulled, &[]);
            if query {
                pass.set_pipeline(&self.query[split as usize]);
                pass.set_bind_group(1, &counted, &[]);
            } else {
                pass.set_pipeline(&self.draw[split as usize]);
            }
            pass.draw(vertices, 0..1);
        }
        let target = readback.buffer(device, counts_bytes);
        encoder.copy_buffer_to_buffer(&passed, 0, target, 0, counts_bytes);
        let out = readback.finish(device, queue, encoder, counts_bytes as usize, counts_bytes as usize, 1)?;
        let counts: Vec<u32> =
            out.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        Ok(ops
            .iter()
            .zip(counts)
            .filter(|(op, _)| matches!(op, VisOp::Query(_)))
            .map(|(_, n)| n as u64)
            .collect())
    }
}

/// A render pass over the depth target alone: written (`load` given: `Clear` or `Load`, then
/// stored) or read-only (`None`: a query batch samples it in the same pass).
fn depth_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    depth: &wgpu::TextureView,
    load: Option<wgpu::LoadOp<f32>>,
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("visibility batch"),
        color_attachments: &[],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: load.map(|load| wgpu::Operations { load, store: wgpu::StoreOp::Store }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// Per op, its first triangle in the run (and the total after the last), and its first vertex;
/// an op's vertices are taken three at a time (a trailing one or two are no triangle).
fn op_tables(ops: &[VisOp]) -> Result<(Vec<u32>, Vec<u32>), GpuError> {
    let mut first_triangle = Vec::with_capacity(ops.len() + 1);
    let mut first_vertex = Vec::with_capacity(ops.len());
    let mut triangles = 0u64;
    for op in ops {
        let (VisOp::Query(r) | VisOp::Draw(r)) = op;
        first_triangle.push(triangles as u32);
        first_vertex.push(r.start);
        triangles += ((r.end - r.start) / 3) as u64;
        if triangles * 3 > u32::MAX as u64 {
            return Err(GpuError::Gpu(format!(
                "a visibility run of more than {} triangles does not fit one batch",
                u32::MAX / 3
            )));
        }
    }
    first_triangle.push(triangles as u32);
    Ok((first_triangle, first_vertex))
}

/// The ops as maximal runs of queries (`true`) and of draws (`false`): ranges of op indices.
fn batches(ops: &[VisOp]) -> Vec<(bool, Range<usize>)> {
    let mut out: Vec<(bool, Range<usize>)> = Vec::new();
    for (i, op) in ops.iter().enumerate() {
        let query = matches!(op, VisOp::Query(_));
        match out.last_mut() {
            Some((q, range)) if *q == query => range.end = i + 1,
            _ => out.push((query, i..i + 1)),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ops_batch_by_kind_and_number_their_triangles() {
        let ops = [
            VisOp::Query(0..6),
            VisOp::Query(6..6),
            VisOp::Query(6..9),
            VisOp::Draw(0..6),
            VisOp::Draw(9..12),
            VisOp::Query(12..13),
        ];
        assert_eq!(batches(&ops), vec![(true, 0..3), (false, 3..5), (true, 5..6)]);
        let (first_triangle, first_vertex) = op_tables(&ops).unwrap();
        // The empty op shares its first triangle with the next; a lone vertex is no triangle.
        assert_eq!(first_triangle, vec![0, 2, 2, 3, 5, 6, 6]);
        assert_eq!(first_vertex, vec![0, 6, 6, 0, 9, 12]);
    }
}
