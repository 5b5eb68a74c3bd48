//! Full-visibility queries, the GPU operation of CULLIDE (Govindaraju 2004, ch. 5): triangles
//! drawn and queried in a caller-given order into one depth target, orthographic or not as the
//! caller's matrix says. A query draws its triangles with depth writes off and the depth test
//! `GreaterEqual` (or `Greater`, [`DepthTest::Strict`], S-CULLIDE's test for self-collision):
//! a fragment passes only where the geometry lies at or behind what was drawn before, so a
//! result of 0 means "fully visible" — strictly in front of everything drawn so far at every
//! pixel it covers. A draw writes depth with `LessEqual`, keeping the nearest surface.
//!
//! Faces are not culled by default ([`Faces::Both`]). For closed convex shapes (FAR's fattened
//! boxes) querying both faces answers as querying the far faces (a near face behind the stored
//! depth has its far face behind it too), and drawing both writes the near faces' depth;
//! [`Faces::Split`] draws only those (the thesis' halving of fill: back faces culled when
//! drawing, front faces when querying).
//!
//! This module knows nothing of objects or collisions (that is `tw-collide`); it runs a list of
//! [`VisOp`]s over triangles uploaded once ([`Visibility::upload`]) and returns one integer per
//! query: samples passed on Vulkan, 0 or 1 on GL (docs/DESIGN.md, D5). Depth is conventional
//! (clear 1, nearer is smaller), in a `Depth32Float` target of `resolution`² pixels, one sample
//! a pixel, no colour attachment.
//!
//! Where the device has storage buffers in the vertex and fragment stages (Vulkan, Metal, DX12; not GL),
//! a run is drawn in batches of consecutive queries and draws, one draw call each, the queries'
//! test done in the fragment stage (`crate::visibility_batch`): the same counts for a few draws
//! a run instead of one a query. Otherwise (GL), and with [`Visibility::set_batched`]`(false)`,
//! each query is an occlusion query: one query set of up to 4096 a render pass (wgpu's limit),
//! passes chained with the depth loaded, resolved into one buffer and read back once per
//! [`Visibility::run`].

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use glam::Mat4;

use crate::error::GpuError;
use crate::query::QueryShader;
use crate::readback::Readback;
use crate::visibility_batch::{self, Batched};

const MAX_QUERIES: u32 = 4096;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// One step of a visibility pass, over a range of uploaded vertices (three a triangle).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum VisOp {
    /// Draw with the query test, no depth writes, inside a new occlusion query.
    Query(Range<u32>),
    /// Draw writing depth.
    Draw(Range<u32>),
}

/// The test of a query's fragments against the stored depth.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthTest {
    /// At or behind (`GreaterEqual`): touching counts as not fully visible (CULLIDE, FAR).
    Inclusive,
    /// Strictly behind (`Greater`): touching neighbours do not block (S-CULLIDE).
    Strict,
}

/// Which faces queries and draws rasterize.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Faces {
    /// Both (any triangles).
    Both,
    /// Queries the faces turned away from the viewer, draws those turned towards it: for
    /// closed shapes wound counter-clockwise seen from outside, under a matrix that keeps
    /// orientation (positive determinant).
    Split,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Vertex {
    p: [f32; 3],
}

/// A device, a square depth target and the query and draw pipelines.
pub struct Visibility {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: wgpu::AdapterInfo,
    resolution: u32,
    depth_view: wgpu::TextureView,
    bind: wgpu::BindGroup,
    uniform: wgpu::Buffer,
    /// Indexed by [`Faces`] (both, split): the inclusive query, the strict query, the draw.
    pipelines: [[wgpu::RenderPipeline; 3]; 2],
    faces: Faces,
    vertices: Option<wgpu::Buffer>,
    vertex_count: u32,
    readback: Readback,
    /// The batched path, where the device has it ([`Visibility::set_batched`]).
    batched: Option<Batched>,
    use_batched: bool,
}

impl Visibility {
    /// Opens the first adapter of the backends in `WGPU_BACKEND` (default all) with a depth
    /// target of `resolution` × `resolution`.
    pub fn new_headless(resolution: u32) -> Result<Visibility, GpuError> {
        let backends = wgpu::Backends::all().with_env();
        let adapter = crate::Renderer::headless_adapter(backends)?;
        let info = adapter.get_info();
        let have = adapter.limits();
        let limits = wgpu::Limits {
            max_buffer_size: have.max_buffer_size,
            // The batched path reads the uploaded vertices as one storage buffer.
            max_storage_buffer_binding_size: have.max_storage_buffer_binding_size,
            ..wgpu::Limits::downlevel_defaults().using_resolution(have)
        };
        if resolution == 0 || resolution > limits.max_texture_dimension_2d {
            return Err(GpuError::Size {
                width: resolution,
                height: resolution,
                max: limits.max_texture_dimension_2d,
            });
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("terawalk visibility"),
            required_limits: limits,
            memory_hints: wgpu::MemoryHints::MemoryUsage,
            ..Default::default()
        }))
        .map_err(|source| GpuError::Device { adapter: info.name.clone(), source })?;
        Ok(Visibility::from_device(device, queue, &adapter, resolution))
    }

    /// Visibility queries on a device the caller has, opened on `adapter`.
    pub fn from_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter: &wgpu::Adapter,
        resolution: u32,
    ) -> Visibility {
        let batched = visibility_batch::supported(adapter).then(|| Batched::new(&device));
        let adapter = adapter.get_info();
        // The box-query shader is the same transform of a position by one matrix.
        let QueryShader { layout, pipeline_layout: pl, module } = QueryShader::new(&device, "visibility");
        let pipeline = |compare: wgpu::CompareFunction, write: bool, cull: Option<wgpu::Face>| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("visibility"),
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
                // Conventional depth looks along +z with y up: a face wound counter-clockwise
                // seen from outside shows clockwise to a viewer in front of it
                // (tests/visibility.rs checks the convention).
                primitive: wgpu::PrimitiveState {
                    cull_mode: cull,
                    front_face: wgpu::FrontFace::Cw,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(write),
                    depth_compare: Some(compare),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: None,
                multiview_mask: None,
                cache: None,
            })
        };
        use wgpu::CompareFunction::{Greater, GreaterEqual, LessEqual};
        let set = |query: Option<wgpu::Face>, draw: Option<wgpu::Face>| {
            [
                pipeline(GreaterEqual, false, query),
                pipeline(Greater, false, query),
                pipeline(LessEqual, true, draw),
            ]
        };
        let pipelines = [set(None, None), set(Some(wgpu::Face::Front), Some(wgpu::Face::Back))];
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("visibility"),
            size: 64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("visibility"),
            layout: &layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() }],
        });
        let depth_view = depth_target(&device, resolution);
        Visibility {
            device,
            queue,
            adapter,
            resolution,
            depth_view,
            bind,
            uniform,
            pipelines,
            faces: Faces::Both,
            vertices: None,
            vertex_count: 0,
            readback: Readback::default(),
            use_batched: batched.is_some(),
            batched,
        }
    }

    /// Runs later queries in batches (`true`, the default where the device allows it) or as one
    /// occlusion query each; returns whether batches are in use.
    pub fn set_batched(&mut self, batched: bool) -> bool {
        self.use_batched = batched && self.batched.is_some();
        self.use_batched
    }

    /// Whether queries run in batches (see [`Visibility::set_batched`]).
    pub fn batched(&self) -> bool {
        self.use_batched
    }

    /// The side of the depth target in pixels.
    pub fn resolution(&self) -> u32 {
        self.resolution
    }

    /// The adapter the queries run on.
    pub fn adapter(&self) -> &wgpu::AdapterInfo {
        &self.adapter
    }

    /// Whether query results are sample counts (false: 0 or 1, GL).
    pub fn counts_samples(&self) -> bool {
        self.adapter.backend != wgpu::Backend::Gl
    }

    /// Sets the faces later runs rasterize.
    pub fn set_faces(&mut self, faces: Faces) {
        self.faces = faces;
    }

    /// Replaces the vertices (three a triangle) the ops of [`run`](Self::run) refer to.
    pub fn upload(&mut self, vertices: &[[f32; 3]]) {
        let bytes = (vertices.len() * 12) as u64;
        if self.vertices.as_ref().is_none_or(|b| b.size() < bytes.max(12)) {
            self.vertices = Some(self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("visibility vertices"),
                size: bytes.max(12).next_power_of_two(),
                usage: wgpu::BufferUsages::VERTEX
                    | wgpu::BufferUsages::COPY_DST
                    | if self.batched.is_some() {
                        wgpu::BufferUsages::STORAGE
                    } else {
                        wgpu::BufferUsages::empty()
                    },
                mapped_at_creation: false,
            }));
        }
        if let Some(buffer) = &self.vertices {
            let data: Vec<Vertex> = vertices.iter().map(|&p| Vertex { p }).collect();
            if !data.is_empty() {
                self.queue.write_buffer(buffer, 0, bytemuck::cast_slice(&data));
            }
        }
        self.vertex_count = vertices.len() as u32;
    }

    /// Runs `ops` in order from a cleared depth target under `view_proj` (positions to clip
    /// space; depth 0..1) and returns one result per [`VisOp::Query`], in order: 0 when the
    /// queried triangles are fully visible. Ranges past the uploaded vertices are an error.
    pub fn run(&mut self, view_proj: Mat4, ops: &[VisOp], test: DepthTest) -> Result<Vec<u64>, GpuError> {
        let queries = ops.iter().filter(|o| matches!(o, VisOp::Query(_))).count() as u32;
        if let Some(bad) = ops.iter().find(|o| {
            let (VisOp::Query(r) | VisOp::Draw(r)) = o;
            r.start > r.end || r.end > self.vertex_count
        }) {
            return Err(GpuError::Gpu(format!(
                "visibility op {bad:?} is outside the {} uploaded vertices",
                self.vertex_count
            )));
        }
        if queries == 0 {
            return Ok(Vec::new());
        }
        let vertices = self.vertices.as_ref().ok_or_else(|| GpuError::Gpu("no vertices uploaded".into()))?;
        if let (Some(batched), true) = (&self.batched, self.use_batched) {
            let gpu = (&self.device, &self.queue, &mut self.readback);
            let split = self.faces == Faces::Split;
            let used = std::num::NonZeroU64::new(self.vertex_count as u64 * 12);
            let vertices = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: vertices,
                offset: 0,
                size: used,
            });
            return batched.run(gpu, &self.depth_view, vertices, view_proj, ops, test, split);
        }
        self.queue.write_buffer(&self.uniform, 0, bytemuck::cast_slice(&view_proj.to_cols_array()));
        let [inclusive, strict, draw_pipeline] = &self.pipelines[(self.faces == Faces::Split) as usize];
        let query_pipeline = match test {
            DepthTest::Inclusive => inclusive,
            DepthTest::Strict => strict,
        };
        let resolve = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("visibility results"),
            size: queries as u64 * 8,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let mut rest = ops;
        let mut done = 0u32;
        while done < queries {
            let n = (queries - done).min(MAX_QUERIES);
            // The ops up to and including this chunk's last query.
            let mut seen = 0;
            let end = rest
                .iter()
                .position(|o| {
                    seen += matches!(o, VisOp::Query(_)) as u32;
                    seen == n
                })
                .map_or(rest.len(), |i| i + 1);
            let set = self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("visibility"),
                ty: wgpu::QueryType::Occlusion,
                count: n,
            });
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("visibility"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &self.depth_view,
                        depth_ops: Some(wgpu::Operations {
                            load: if done == 0 { wgpu::LoadOp::Clear(1.0) } else { wgpu::LoadOp::Load },
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: Some(&set),
                    multiview_mask: None,
                });
                pass.set_bind_group(0, &self.bind, &[]);
                pass.set_vertex_buffer(0, vertices.slice(..));
                let mut q = 0;
                let mut querying = None;
                for op in &rest[..end] {
                    let (is_query, range) = match op {
                        VisOp::Query(r) => (true, r.clone()),
                        VisOp::Draw(r) => (false, r.clone()),
                    };
                    if querying != Some(is_query) {
                        pass.set_pipeline(if is_query { query_pipeline } else { draw_pipeline });
                        querying = Some(is_query);
                    }
                    if is_query {
                        pass.begin_occlusion_query(q);
                        if !range.is_empty() {
                            pass.draw(range, 0..1);
                        }
                        pass.end_occlusion_query();
                        q += 1;
                    } else if !range.is_empty() {
                        pass.draw(range, 0..1);
                    }
                }
            }
            encoder.resolve_query_set(&set, 0..n, &resolve, done as u64 * 8);
            rest = &rest[end..];
            done += n;
        }
        let bytes = queries as u64 * 8;
        let target = self.readback.buffer(&self.device, bytes);
        encoder.copy_buffer_to_buffer(&resolve, 0, target, 0, bytes);
        let out =
            self.readback.finish(&self.device, &self.queue, encoder, bytes as usize, bytes as usize, 1)?;
        Ok(out.chunks_exact(8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8]))).collect())
    }
}

fn depth_target(device: &wgpu::Device, resolution: u32) -> wgpu::TextureView {
    device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some("visibility depth"),
            size: wgpu::Extent3d { width: resolution, height: resolution, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            // Sampled by the batched path's queries (while attached read-only).
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        })
        .create_view(&Default::default())
}
