//! GPU hierarchical-Z occlusion culling, the `gpu-hzb` strategy of docs/DESIGN.md, D6: the
//! hierarchical Z pyramid of Greene, Kass and Miller 1993 ("Hierarchical Z-Buffer Visibility":
//! the pyramid of farthest depths, a box culled when its nearest depth is behind the pyramid
//! texels covering its screen rectangle, and last frame's visible geometry drawn first for
//! temporal coherence), built and tested in compute shaders, in the two-pass form of modern
//! GPU-driven renderers (draw last frame's visible set, build the HZB from its depth, cull the
//! other candidates against it and draw the newly visible ones in the same frame, then rebuild
//! the HZB from the final depth for next frame's visible set; e.g. Bevy's meshlet raster node,
//! Wihlidal, GDC 2016, "Optimizing the Graphics Pipeline with Compute"). The test is the CPU's
//! single-level one, [`tw_runtime::Hzb::test_box_single_level`] (the level where the rectangle
//! spans at most 2×2 texels decides), ported rule for rule to WGSL, with its constants passed as
//! uniforms ([`RECT_SLACK_PX`], [`DEPTH_MARGIN`]); it is therefore conservative in the same sense.
//! The CPU `hzb` strategy refines undecided texels down to pixels ([`tw_runtime::Hzb::test_box`])
//! and so culls somewhat more; that refinement is not ported (a bounded loop per box in WGSL).
//!
//! Stages of [`Renderer::draw_gpu_culled`], the second pass of a frame whose occluders were
//! drawn into the own target, all in one submission (the image never waits for the CPU):
//! 1. the candidates are made resident in the pool and their boxes and draw arguments written
//!    to a storage buffer (`CullSet::prepare`); if they do not all fit the GPU budget at
//!    once, nothing is culled: every candidate is drawn (batched) and reported visible;
//! 2. the pyramid is built from the own depth target (`Pyramid::encode_build`, hzb_build.wgsl:
//!    level 0 = the depth, each next level the minimum — reverse-Z, so the farthest — of 2×2
//!    texels, sizes rounding up, exactly as [`Hzb::build`]; levels 0 and 1 in one dispatch);
//! 3. each candidate's box is tested against it (hzb_cull.wgsl `cs_cull`), writing a flag and
//!    either its draw arguments in place with `instance_count` 0 when culled, or — where the
//!    device has `Features::MULTI_DRAW_INDIRECT_COUNT` (Vulkan) — a compaction in candidate
//!    order behind a count (`cs_compact`);
//! 4. the args are drawn on top of the occluders (`multi_draw_indexed_indirect[_count]`);
//! 5. with occluder boxes given, the pyramid is rebuilt from the final depth and they are tested
//!    (flags only): the occluders still visible stay in the history;
//! 6. the flags (a few bytes a cluster) and the compute timestamps are read back, for the
//!    history and the statistics only.
//!
//! Needs compute shaders and indirect execution (`DownlevelFlags::COMPUTE_SHADERS` and
//! `INDIRECT_EXECUTION`: every Vulkan device, GL ≥ 4.3 / GLES ≥ 3.1 — llvmpipe has both; wgpu's
//! GL backend has no indirect count, so GL takes the in-place path); else
//! [`GpuError::Unsupported`].

use std::time::{Duration, Instant};

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
use tw_runtime::hzb::{Hzb, HzbLevel, HzbResult, DEPTH_MARGIN, RECT_SLACK_PX};
use tw_runtime::Camera;
use tw_store::PageCluster;

use crate::draw::{LookupLayers, Shading};
use crate::error::GpuError;
use crate::pool::{DrawArgs, Ensure, PoolKey};
use crate::renderer::{bind_group, Eye, Pass};
use crate::{ClusterKey, Renderer, COLOR_FORMAT};

/// Pixels the GPU test widens a rectangle by beyond [`RECT_SLACK_PX`], and the relative amount
/// it moves a box's nearest depth towards the eye: the shader compiler may fuse or reorder the
/// projection's arithmetic, so the GPU's f32 results differ from the CPU's in the last bits;
/// these guards (far above that rounding, far below a pixel or [`DEPTH_MARGIN`]) keep every GPU
/// "occluded" an "occluded" of the CPU test on the same depth.
pub const GPU_RECT_GUARD_PX: f32 = 1.0 / 512.0;
/// See [`GPU_RECT_GUARD_PX`].
pub const GPU_DEPTH_GUARD: f32 = 1e-6;

/// Pyramid levels the shaders take: enough for [`crate::MAX_SIDE`] (16384 → 15 levels).
const MAX_LEVELS: usize = 16;

const FLAG_VISIBLE: u32 = 0;
const FLAG_OCCLUDED: u32 = 1;

/// Uniform of one hzb_build.wgsl dispatch (`Level`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct LevelUniform {
    src_offset: u32,
    src_width: u32,
    src_height: u32,
    dst_offset: u32,
    dst_width: u32,
    dst_height: u32,
    _pad: [u32; 2],
}

/// Uniform of hzb_cull.wgsl (`Cull`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct CullUniform {
    view_proj: [[f32; 4]; 4],
    size: [u32; 4],
    params: [f32; 4],
    levels: [[u32; 4]; MAX_LEVELS],
}

/// One box to test and the draw it guards (hzb_cull.wgsl `Candidate`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct Candidate {
    lo: [f32; 4],
    hi: [f32; 4],
    args: DrawArgs,
    _pad: [u32; 3],
}

const _: () = assert!(std::mem::size_of::<Candidate>() == 64);
const _: () = assert!(std::mem::size_of::<DrawArgs>() == 20);
const _: () = assert!(std::mem::size_of::<CullUniform>() == 352);

impl Candidate {
    fn new((lo, hi): (Vec3, Vec3), args: DrawArgs) -> Candidate {
        Candidate { lo: lo.extend(1.0).to_array(), hi: hi.extend(1.0).to_array(), args, _pad: [0; 3] }
    }
}

/// What [`Renderer::draw_gpu_culled`] found, per candidate and per occluder in the order given.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GpuCullResult {
    /// [`HzbResult::Visible`] candidates were drawn; the others were not.
    pub candidates: Vec<HzbResult>,
    /// The occluders against the final depth (all `Visible` when none were given to test).
    pub occluders: Vec<HzbResult>,
    /// GPU time of the compute passes (pyramid builds, culls, compaction) by timestamp queries,
    /// where the device has `Features::TIMESTAMP_QUERY`.
    pub gpu_time: Option<Duration>,
    /// CPU time spent recording and submitting them.
    pub encode_time: Duration,
    /// Drawn with an indirect count after compaction (else in place, culled ones with 0
    /// instances).
    pub compacted: bool,
    /// The candidates did not fit the GPU budget together: none was tested, all were drawn.
    pub over_budget: bool,
}

/// Level `k`: (offset in the pyramid buffer, width, height), sizes as [`Hzb::build`].
fn level_layout(width: u32, height: u32) -> Vec<(u32, u32, u32)> {
    let mut levels = vec![(0, width, height)];
    loop {
        let &(offset, w, h) = levels.last().expect("level 0");
        if w == 1 && h == 1 {
            return levels;
        }
        levels.push((offset + w * h, w.div_ceil(2), h.div_ceil(2)));
    }
}

/// The pyramid of one depth-target size: one f32 storage buffer holding every level.
pub(crate) struct Pyramid {
    size: (u32, u32),
    levels: Vec<(u32, u32, u32)>,
    buffer: wgpu::Buffer,
    /// `binds[k]` writes level `k` from level k − 1 (level 0: from the depth texture).
    binds: Vec<wgpu::BindGroup>,
    _uniforms: wgpu::Buffer,
}

impl Pyramid {
    fn texels(&self) -> u64 {
        let &(offset, w, h) = self.levels.last().expect("level 0");
        offset as u64 + w as u64 * h as u64
    }

    /// Records the build into `pass`: levels 0 and 1 from the depth texture (`from_depth`),
    /// else level 1 from level 0 as already written to the buffer, then each next level.
    fn encode_build(&self, pass: &mut wgpu::ComputePass<'_>, pipes: &GpuCull, from_depth: bool) {
        for (k, &(_, w, h)) in self.levels.iter().enumerate() {
            let pipeline = match (k, from_depth) {
                (0, true) if self.levels.len() == 1 => &pipes.copy,
                (0, _) => continue,
                (1, true) => &pipes.copy2,
                _ => &pipes.reduce,
            };
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &self.binds[k], &[]);
            pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        }
    }

    fn level_table(&self) -> [[u32; 4]; MAX_LEVELS] {
        let mut t = [[0; 4]; MAX_LEVELS];
        for (row, &(o, w, h)) in t.iter_mut().zip(&self.levels) {
            *row = [o, w, h, 0];
        }
        t
    }
}

/// The buffers of one set of boxes (candidates or occluders) tested in a submission.
#[derive(Default)]
pub(crate) struct CullSet {
    capacity: u64,
    buffers: Option<CullBuffers>,
}

struct CullBuffers {
    uniform: wgpu::Buffer,
    input: wgpu::Buffer,
    /// Draw arguments (INDIRECT).
    args: wgpu::Buffer,
    /// The count (INDIRECT, offset 0) then one flag per box.
    state: wgpu::Buffer,
}

impl CullSet {
    /// Writes `boxes` and the uniform (through the queue: before the next submit), growing the
    /// buffers as needed.
    fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        boxes: &[Candidate],
        uniform: &CullUniform,
    ) -> &CullBuffers {
        let n = (boxes.len() as u64).max(1);
        if self.buffers.is_none() || self.capacity < n {
            let capacity = n.next_power_of_two().max(64);
            let buffer = |label, size, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage,
                    mapped_at_creation: false,
                })
            };
            use wgpu::BufferUsages as U;
            self.buffers = Some(CullBuffers {
                uniform: buffer(
                    "hzb cull",
                    std::mem::size_of::<CullUniform>() as u64,
                    U::UNIFORM | U::COPY_DST,
                ),
                input: buffer("hzb cull boxes", capacity * 64, U::STORAGE | U::COPY_DST),
                args: buffer("hzb cull draws", capacity * 20, U::STORAGE | U::INDIRECT),
                state: buffer("hzb cull flags", 4 + capacity * 4, U::STORAGE | U::INDIRECT | U::COPY_SRC),
            });
            self.capacity = capacity;
        }
        let b = self.buffers.as_ref().expect("just created");
        queue.write_buffer(&b.input, 0, bytemuck::cast_slice(boxes));
        queue.write_buffer(&b.uniform, 0, bytemuck::bytes_of(uniform));
        b
    }
}

/// The compute pipelines, the pyramid of the own size and the per-set buffers.
pub(crate) struct GpuCull {
    build_layout: wgpu::BindGroupLayout,
    copy: wgpu::ComputePipeline,
    copy2: wgpu::ComputePipeline,
    reduce: wgpu::ComputePipeline,
    cull_layout: wgpu::BindGroupLayout,
    /// `cs_cull` writing the candidates' draw arguments in place (`WRITE_ARGS`), and writing
    /// the flags only (compaction follows, or the boxes are the occluders').
    cull: wgpu::ComputePipeline,
    cull_flags: wgpu::ComputePipeline,
    compact: wgpu::ComputePipeline,
    pyramid: Option<Pyramid>,
    /// 0: the candidates, 1: the occluders.
    sets: [CullSet; 2],
    timestamps: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    /// How far a pixel's samples reach from its centre ([`tw_runtime::hzb::sample_spread`]):
    /// the rectangles are widened by it, as the CPU test does with multisampling.
    pub spread: f32,
}

fn layout_entry(binding: u32, ty: wgpu::BindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry { binding, visibility: wgpu::ShaderStages::COMPUTE, ty, count: None }
}

fn storage(read_only: bool) -> wgpu::BindingType {
    wgpu::BindingType::Buffer {
        ty: wgpu::BufferBindingType::Storage { read_only },
        has_dynamic_offset: false,
        min_binding_size: None,
    }
}

const UNIFORM: wgpu::BindingType = wgpu::BindingType::Buffer {
    ty: wgpu::BufferBindingType::Uniform,
    has_dynamic_offset: false,
    min_binding_size: None,
};

fn compute_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    module: &wgpu::ShaderModule,
    entry: &str,
    constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(entry),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: Some(&pl),
        module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
        cache: None,
    })
}

impl GpuCull {
    pub fn new(device: &wgpu::Device) -> GpuCull {
        let build_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("hzb build"),
            entries: &[
                layout_entry(0, UNIFORM),
                layout_entry(1, storage(false)),
                layout_entry(
                    2,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                ),
            ],
        });
        let cull_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("hzb cull"),
            entries: &[
                layout_entry(0, UNIFORM),
                layout_entry(1, storage(true)),
                layout_entry(2, storage(true)),
                layout_entry(3, storage(false)),
                layout_entry(4, storage(false)),
            ],
        });
        let module = |label, source: &'static str| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
        };
        let build = module("hzb build", include_str!("hzb_build.wgsl"));
        let cull = module("hzb cull", include_str!("hzb_cull.wgsl"));
        let timestamps = device.features().contains(wgpu::Features::TIMESTAMP_QUERY).then(|| {
            let set = device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("hzb timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 4,
            });
            let resolve = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("hzb timestamps"),
                size: 4 * wgpu::QUERY_SIZE as u64,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            (set, resolve)
        });
        GpuCull {
            copy: compute_pipeline(device, &build_layout, &build, "cs_copy", &[]),
            copy2: compute_pipeline(device, &build_layout, &build, "cs_copy2", &[]),
            reduce: compute_pipeline(device, &build_layout, &build, "cs_reduce", &[]),
            cull: compute_pipeline(device, &cull_layout, &cull, "cs_cull", &[("WRITE_ARGS", 1.0)]),
            cull_flags: compute_pipeline(device, &cull_layout, &cull, "cs_cull", &[("WRITE_ARGS", 0.0)]),
            compact: compute_pipeline(device, &cull_layout, &cull, "cs_compact", &[]),
            build_layout,
            cull_layout,
            pyramid: None,
            sets: Default::default(),
            timestamps,
            spread: 0.0,
        }
    }

    /// The pyramid for a `depth` texture (Depth32Float, TEXTURE_BINDING), made on first use
    /// and when the size changes.
    fn pyramid(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        depth: &wgpu::Texture,
    ) -> Result<&Pyramid, GpuError> {
        let size = (depth.width(), depth.height());
        if self.pyramid.as_ref().is_some_and(|p| p.size == size) {
            return Ok(self.pyramid.as_ref().expect("checked"));
        }
        let levels = level_layout(size.0, size.1);
        if levels.len() > MAX_LEVELS {
            return Err(GpuError::Gpu(format!(
                "a {}×{} HZB has more than {MAX_LEVELS} levels",
                size.0, size.1
            )));
        }
        let &(offset, w, h) = levels.last().expect("level 0");
        let bytes = (offset as u64 + w as u64 * h as u64) * 4;
        if bytes > device.limits().max_storage_buffer_binding_size {
            return Err(GpuError::Gpu(format!(
                "a {}×{} HZB ({bytes} bytes) exceeds the storage-buffer binding limit",
                size.0, size.1
            )));
        }
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("hzb"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let stride = (std::mem::size_of::<LevelUniform>() as u64)
            .next_multiple_of(device.limits().min_uniform_buffer_offset_alignment as u64);
        let mut table = vec![0u8; (stride * levels.len() as u64) as usize];
        for (k, &(o, w, h)) in levels.iter().enumerate() {
            let (so, sw, sh) = if k == 0 { (0, w, h) } else { levels[k - 1] };
            let u = LevelUniform {
                src_offset: so,
                src_width: sw,
                src_height: sh,
                dst_offset: o,
                dst_width: w,
                dst_height: h,
                _pad: [0; 2],
            };
            let at = k * stride as usize;
            table[at..at + std::mem::size_of::<LevelUniform>()].copy_from_slice(bytemuck::bytes_of(&u));
        }
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("hzb levels"),
            size: table.len() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        queue.write_buffer(&uniforms, 0, &table);
        let view = depth.create_view(&wgpu::TextureViewDescriptor {
            aspect: wgpu::TextureAspect::DepthOnly,
            ..Default::default()
        });
        let binds = (0..levels.len() as u64)
            .map(|k| {
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("hzb level"),
                    layout: &self.build_layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer: &uniforms,
                                offset: k * stride,
                                size: wgpu::BufferSize::new(std::mem::size_of::<LevelUniform>() as u64),
                            }),
                        },
                        wgpu::BindGroupEntry { binding: 1, resource: buffer.as_entire_binding() },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: wgpu::BindingResource::TextureView(&view),
                        },
                    ],
                })
            })
            .collect();
        self.pyramid = Some(Pyramid { size, levels, buffer, binds, _uniforms: uniforms });
        Ok(self.pyramid.as_ref().expect("just made"))
    }

    fn uniform(&self, view_proj: &Mat4, n: usize) -> CullUniform {
        let p = self.pyramid.as_ref().expect("pyramid made before the uniform");
        CullUniform {
            view_proj: view_proj.to_cols_array_2d(),
            size: [p.size.0, p.size.1, p.levels.len() as u32, n as u32],
            params: [RECT_SLACK_PX + GPU_RECT_GUARD_PX + self.spread, DEPTH_MARGIN, GPU_DEPTH_GUARD, 0.0],
            levels: p.level_table(),
        }
    }

    fn cull_bind(&self, device: &wgpu::Device, set: usize) -> wgpu::BindGroup {
        let p = self.pyramid.as_ref().expect("pyramid made before the cull");
        let b = self.sets[set].buffers.as_ref().expect("set prepared before the cull");
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("hzb cull"),
            layout: &self.cull_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: b.uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: p.buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: b.input.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: b.args.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: b.state.as_entire_binding() },
            ],
        })
    }

    /// Records a compute pass: the pyramid build (from the depth texture or from level 0 as
    /// written), then the test of `n` boxes of `set` (and the compaction with `compact`),
    /// timestamps at `timestamp` and `timestamp + 1` when the device has them.
    #[allow(clippy::too_many_arguments)]
    fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        from_depth: bool,
        set: usize,
        n: usize,
        compact: bool,
        timestamp: u32,
    ) {
        let bind = (n > 0).then(|| self.cull_bind(device, set));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("gpu hzb"),
            timestamp_writes: self.timestamps.as_ref().map(|(q, _)| wgpu::ComputePassTimestampWrites {
                query_set: q,
                beginning_of_pass_write_index: Some(timestamp),
                end_of_pass_write_index: Some(timestamp + 1),
            }),
        });
        let pyramid = self.pyramid.as_ref().expect("pyramid made before encoding");
        pyramid.encode_build(&mut pass, self, from_depth);
        if let Some(bind) = &bind {
            // Set 0 (the candidates) gets its draw arguments written in place unless they are
            // compacted; set 1 (the occluders') only its flags.
            pass.set_pipeline(if set == 0 && !compact { &self.cull } else { &self.cull_flags });
            pass.set_bind_group(0, bind, &[]);
            pass.dispatch_workgroups((n as u32).div_ceil(64), 1, 1);
            if compact {
                pass.set_pipeline(&self.compact);
                pass.dispatch_workgroups(1, 1, 1);
            }
        }
    }
}

/// Where a GPU-culled frame's readback puts what it reads: the candidates' flags (a count and
/// one word each) at 0, the occluders' after them (none when there are no occluders), then the
/// timestamps at an 8-byte boundary (none without a timestamp query set or passes).
struct ReadbackLayout {
    bytes0: u64,
    bytes1: u64,
    ts_at: u64,
    ts_bytes: u64,
    total: u64,
}

impl ReadbackLayout {
    fn new(candidates: usize, occluders: usize, passes: u32, cull: Option<&GpuCull>) -> ReadbackLayout {
        let bytes0 = 4 + 4 * candidates as u64;
        let bytes1 = if occluders == 0 { 0 } else { 4 + 4 * occluders as u64 };
        let ts_at = (bytes0 + bytes1).next_multiple_of(8);
        let timestamps = cull.and_then(|c| c.timestamps.as_ref()).filter(|_| passes > 0);
        let ts_bytes = if timestamps.is_some() { 2 * passes as u64 * wgpu::QUERY_SIZE as u64 } else { 0 };
        ReadbackLayout { bytes0, bytes1, ts_at, ts_bytes, total: ts_at + ts_bytes }
    }
}

fn decode_flags(bytes: &[u8], n: usize) -> Vec<HzbResult> {
    bytes
        .chunks_exact(4)
        .skip(1)
        .take(n)
        .map(|b| match u32::from_le_bytes([b[0], b[1], b[2], b[3]]) {
            FLAG_VISIBLE => HzbResult::Visible,
            FLAG_OCCLUDED => HzbResult::Occluded,
            _ => HzbResult::NoPixels,
        })
        .collect()
}

/// The GPU-culled second pass and its HZB; see the module documentation.
impl Renderer {
    /// Whether this renderer can run [`draw_gpu_culled`](Self::draw_gpu_culled): compute
    /// shaders and indirect execution (on GL known only after
    /// [`set_downlevel`](Self::set_downlevel)); else the reason.
    pub fn gpu_cull_supported(&self) -> Result<(), GpuError> {
        let missing = match (self.compute_supported, self.indirect_supported) {
            (true, true) => return Ok(()),
            (false, _) => "compute shaders (DownlevelFlags::COMPUTE_SHADERS: GL ≥ 4.3 or GLES ≥ 3.1)",
            (true, false) => "indirect draws (DownlevelFlags::INDIRECT_EXECUTION)",
        };
        Err(GpuError::Unsupported {
            what: "GPU occlusion culling (gpu-hzb)",
            missing,
            adapter: self.adapter_summary(),
        })
    }

    /// Whether [`draw_gpu_culled`](Self::draw_gpu_culled) compacts its draws behind an
    /// indirect count (`Features::MULTI_DRAW_INDIRECT_COUNT`; not on wgpu's GL backend).
    pub fn gpu_cull_compacts(&self) -> bool {
        self.device.features().contains(wgpu::Features::MULTI_DRAW_INDIRECT_COUNT)
    }

    /// The second pass of a GPU-culled frame (see the module documentation): after the
    /// occluders were drawn with [`draw`](Self::draw) into [`crate::Target::Own`] from the same
    /// `camera`, builds the HZB from the own depth target, tests each of `candidates` with its
    /// scene-space `boxes[i]` (min, max; a box with a non-finite corner is visible) and draws
    /// the visible ones on top, all on the GPU; then, if `occluder_boxes` is not empty, rebuilds
    /// the HZB from the final depth and tests those boxes. Waits for the GPU to read the flags
    /// back. Panics unless `boxes.len() == candidates.len()`.
    pub fn draw_gpu_culled(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        candidates: &[(ClusterKey, &PageCluster)],
        boxes: &[(Vec3, Vec3)],
        occluder_boxes: &[(Vec3, Vec3)],
    ) -> Result<GpuCullResult, GpuError> {
        assert_eq!(candidates.len(), boxes.len(), "one box per candidate");
        self.gpu_cull_supported()?;
        if !self.last_own {
            return Err(GpuError::NotOwnTarget { what: "draw_gpu_culled" });
        }
        let start = Instant::now();
        let size = (self.width, self.height);
        let gl = self.info.backend == wgpu::Backend::Gl;
        if gl && self.pool.stats().arena_bytes >= self.pool.budget() {
            self.wait_idle()?; // the GL ordering hazard of draw_pass
        }
        let shadow_layers = self.shadow_layers()?;
        // 1. Residency.
        let Some((list, keys)) =
            self.resident_candidates(grid_step, candidates, boxes, shadow_layers.is_some())
        else {
            return self.draw_all_over_budget(camera, grid_step, candidates, occluder_boxes.len());
        };
        let encode_start = Instant::now();
        let compact = self.gpu_cull_compacts();
        let occluders: Vec<Candidate> =
            occluder_boxes.iter().map(|&b| Candidate::new(b, DrawArgs::zeroed())).collect();
        self.prepare_cull(camera, size, &list, &occluders, shadow_layers.is_some())?;
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("gpu hzb") });
        // 2–3. Pyramid from the occluders' depth, cull (and compaction). Timestamps: a pair
        // per compute pass encoded.
        let mut passes = 0u32;
        self.encode_depth_resolve(&mut encoder);
        let cull = self.gpu_cull.as_ref().expect("made above");
        if !list.is_empty() {
            cull.encode(&self.device, &mut encoder, true, 0, list.len(), compact, 0);
            passes += 1;
        }
        // 4. Draw.
        let state0 = self.encode_visible_draw(&mut encoder, size, list.len(), compact, shadow_layers)?;
        // 5. Rebuild from the final depth, test the occluders.
        self.depth_stale = self.samples > 1;
        if !occluders.is_empty() {
            self.encode_depth_resolve(&mut encoder);
            let cull = self.gpu_cull.as_ref().expect("made above");
            cull.encode(&self.device, &mut encoder, true, 1, occluders.len(), false, 2 * passes);
            passes += 1;
        }
        // 6. Read back the flags and timestamps.
        let layout = ReadbackLayout::new(list.len(), occluders.len(), passes, self.gpu_cull.as_ref());
        self.encode_readback(&mut encoder, &state0, &layout, passes);
        let encode_time = encode_start.elapsed();
        let total = layout.total as usize;
        let bytes = self.readback.finish(&self.device, &self.queue, encoder, total, total, 1)?;
        self.pool.note_batch();
        self.pool.release_batch(&keys);
        let (b0, b1) = (layout.bytes0 as usize, (layout.bytes0 + layout.bytes1) as usize);
        let flags = decode_flags(&bytes[..b0], list.len());
        let occluder_flags = if layout.bytes1 > 0 {
            decode_flags(&bytes[b0..b1], occluders.len())
        } else {
            vec![HzbResult::Visible; occluder_boxes.len()]
        };
        let gpu_time = (layout.ts_bytes > 0).then(|| self.gpu_time(&bytes[layout.ts_at as usize..]));
        self.count_visible(&list, &flags);
        self.stats.render += start.elapsed();
        Ok(GpuCullResult {
            candidates: flags,
            occluders: occluder_flags,
            gpu_time,
            encode_time,
            compacted: compact,
            over_budget: false,
        })
    }

    /// Makes the candidates' clusters resident (noting their slots for the shadow stage when
    /// `shadows`): each as a [`Candidate`] with its box, empty clusters with no draw, and the
    /// keys of those in the pool. `None` when the pool is full (the keys taken are released).
    fn resident_candidates(
        &mut self,
        grid_step: f64,
        candidates: &[(ClusterKey, &PageCluster)],
        boxes: &[(Vec3, Vec3)],
        shadows: bool,
    ) -> Option<(Vec<Candidate>, Vec<PoolKey>)> {
        let t = Instant::now();
        let mut list = Vec::with_capacity(candidates.len());
        let mut keys: Vec<PoolKey> = Vec::with_capacity(candidates.len());
        let mut over_budget = false;
        for ((key, cluster), &b) in candidates.iter().zip(boxes) {
            let pk = (key.page, key.index_in_page);
            match self.pool.ensure(&self.device, &self.queue, pk, grid_step, cluster) {
                Ensure::Ready { args, slot } => {
                    if shadows {
                        self.shadow.note_slot(pk, slot);
                    }
                    let fade = self.fades.get(&pk).copied().unwrap_or(0);
                    self.pool.set_fade(&self.queue, slot, fade);
                    list.push(Candidate::new(b, args));
                    keys.push(pk);
                }
                Ensure::Empty => list.push(Candidate::new(b, DrawArgs::zeroed())),
                Ensure::Full => {
                    over_budget = true;
                    break;
                }
            }
        }
        self.stats.upload += t.elapsed();
        if over_budget {
            self.pool.release_batch(&keys);
            return None;
        }
        Some((list, keys))
    }

    /// Over the GPU budget: conservatively draws every candidate, in batches, and keeps every
    /// occluder.
    fn draw_all_over_budget(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        candidates: &[(ClusterKey, &PageCluster)],
        occluders: usize,
    ) -> Result<GpuCullResult, GpuError> {
        let size = (self.width, self.height);
        let view = self.color_view.clone();
        let shade = Pass::Shade { view: &view, format: COLOR_FORMAT, own: true };
        self.depth_stale = self.samples > 1;
        self.draw_pass(None, shade, size, Eye::Camera(camera), grid_step, candidates, None, false)?;
        Ok(GpuCullResult {
            candidates: vec![HzbResult::Visible; candidates.len()],
            occluders: vec![HzbResult::Visible; occluders],
            over_budget: true,
            ..Default::default()
        })
    }

    /// Writes the frame's uniforms (and the shadows' when `shadows`), builds the HZB pyramid's
    /// resources from the own depth target and uploads the candidates (set 0) and occluders
    /// (set 1, if any) with their cull uniforms.
    fn prepare_cull(
        &mut self,
        camera: &Camera,
        size: (u32, u32),
        list: &[Candidate],
        occluders: &[Candidate],
        shadows: bool,
    ) -> Result<(), GpuError> {
        self.write_uniforms(camera, size);
        if shadows {
            self.shadow.write_uniforms(&self.queue, camera);
        }
        let view_proj = camera.projection_reverse_z(size.0 as f32 / size.1 as f32) * camera.view();
        let spread = tw_runtime::hzb::sample_spread(self.sample_positions());
        let cull = self.gpu_cull.get_or_insert_with(|| GpuCull::new(&self.device));
        cull.spread = spread;
        cull.pyramid(&self.device, &self.queue, &self.depth)?;
        let u0 = cull.uniform(&view_proj, list.len());
        cull.sets[0].prepare(&self.device, &self.queue, list, &u0);
        if !occluders.is_empty() {
            let u1 = cull.uniform(&view_proj, occluders.len());
            cull.sets[1].prepare(&self.device, &self.queue, occluders, &u1);
        }
        Ok(())
    }

    /// Encodes the draw of the visible candidates: one indirect list of `n` draws (compacted
    /// behind a count when `compact`), every cluster with the lookup pipeline (which honours
    /// the shadow stage's classes). Returns the candidate set's state buffer, whose flags are
    /// read back.
    fn encode_visible_draw(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        size: (u32, u32),
        n: usize,
        compact: bool,
        shadow_layers: Option<LookupLayers>,
    ) -> Result<wgpu::Buffer, GpuError> {
        if self.bind_generation != self.pool.generation {
            self.bind_group =
                bind_group(&self.device, &self.pipelines, &self.uniforms, &self.pool, &self.object_colors);
            self.bind_generation = self.pool.generation;
        }
        let color_view = self.color_view.clone();
        let shade = Pass::Shade { view: &color_view, format: COLOR_FORMAT, own: true };
        let att = self.attachments(&shade, size, self.depth_view.clone());
        let shading = shadow_layers.map_or(Shading::Plain, Shading::Lookup);
        // Its draws are the GPU's to pick: every one tests its fade word when any fades.
        self.dither_pipelines = self.dithered();
        let (pipeline, shadow_bind) = self.shaded_pipeline(COLOR_FORMAT, att.samples, shading)?;
        let Some(color) = att.color.clone() else {
            return Err(GpuError::Gpu("the GPU-culled draw has no colour target".into()));
        };
        let cull = self.gpu_cull.as_ref().expect("made above");
        let set0 = cull.sets[0].buffers.as_ref().expect("prepared above");
        // Handles, so that the depth resolve after this may borrow the renderer.
        let (args0, state0) = (set0.args.clone(), set0.state.clone());
        if let (Some(arena), false) = (self.pool.arena(), n == 0) {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("gpu hzb draw"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &color,
                    depth_slice: None,
                    resolve_target: att.resolve.as_ref(),
                    ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &att.depth,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Load,
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
            if let Some(bind) = &shadow_bind {
                pass.set_bind_group(1, bind, &[]);
            }
            pass.set_vertex_buffer(0, arena.slice(..));
            pass.set_index_buffer(arena.slice(..), wgpu::IndexFormat::Uint32);
            if compact {
                pass.multi_draw_indexed_indirect_count(&args0, 0, &state0, 0, n as u32);
            } else {
                pass.multi_draw_indexed_indirect(&args0, 0, n as u32);
            }
        }
        Ok(state0)
    }

    /// Encodes the copies of the candidates' flags (`state0`), the occluders' and the resolved
    /// timestamps of `passes` compute passes into the readback buffer, at `layout`'s offsets.
    fn encode_readback(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        state0: &wgpu::Buffer,
        layout: &ReadbackLayout,
        passes: u32,
    ) {
        let cull = self.gpu_cull.as_ref().expect("made above");
        let timestamps = cull.timestamps.as_ref().filter(|_| passes > 0);
        if let Some((q, resolve)) = timestamps {
            encoder.resolve_query_set(q, 0..2 * passes, resolve, 0);
        }
        let target = self.readback.buffer(&self.device, layout.total);
        encoder.copy_buffer_to_buffer(state0, 0, target, 0, layout.bytes0);
        if layout.bytes1 > 0 {
            let set1 = cull.sets[1].buffers.as_ref().expect("prepared above");
            encoder.copy_buffer_to_buffer(&set1.state, 0, target, layout.bytes0, layout.bytes1);
        }
        if let Some((_, resolve)) = timestamps {
            encoder.copy_buffer_to_buffer(resolve, 0, target, layout.ts_at, layout.ts_bytes);
        }
    }

    /// The GPU time of the compute passes from their timestamp pairs (`bytes`).
    fn gpu_time(&self, bytes: &[u8]) -> Duration {
        let ts: Vec<u64> =
            bytes.chunks_exact(8).map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes"))).collect();
        let ticks: u64 = ts.chunks_exact(2).map(|p| p[1].saturating_sub(p[0])).sum();
        Duration::from_nanos((ticks as f64 * self.queue.get_timestamp_period() as f64) as u64)
    }

    /// Counts the drawn candidates (visible, with triangles) in the frame's figures, and the
    /// one indirect draw call if there were any.
    fn count_visible(&mut self, list: &[Candidate], flags: &[HzbResult]) {
        for (c, f) in list.iter().zip(flags) {
            if *f == HzbResult::Visible && c.args.index_count > 0 {
                self.stats.clusters += 1;
                self.stats.triangles += c.args.index_count as u64 / 3;
                self.stats.masked_triangles += c.args.index_count as u64 / 3;
            }
        }
        self.stats.draw_calls += u64::from(!list.is_empty());
    }

    /// Builds the HZB from the own depth target as the frame's draws left it and tests `boxes`
    /// (scene-space min, max) against it from `camera` (the camera of those draws): the GPU's
    /// answer to [`Hzb::test_box_single_level`]. Waits for the GPU.
    pub fn test_boxes_gpu(
        &mut self,
        camera: &Camera,
        boxes: &[(Vec3, Vec3)],
    ) -> Result<Vec<HzbResult>, GpuError> {
        self.gpu_cull_supported()?;
        if !self.last_own {
            return Err(GpuError::NotOwnTarget { what: "test_boxes_gpu" });
        }
        let view_proj = camera.projection_reverse_z(self.width as f32 / self.height as f32) * camera.view();
        self.resolve_depth();
        let spread = tw_runtime::hzb::sample_spread(self.sample_positions());
        let (device, queue) = (&self.device, &self.queue);
        let cull = self.gpu_cull.get_or_insert_with(|| GpuCull::new(device));
        cull.spread = spread;
        cull.pyramid(device, queue, &self.depth)?;
        test_boxes(cull, device, queue, &mut self.readback, true, &view_proj, boxes)
    }

    /// Builds the HZB from the own depth target and reads every level back (for tests and
    /// debugging: the same values as [`Hzb::build`] of [`read_depth`](Self::read_depth)).
    /// Waits for the GPU.
    pub fn read_gpu_hzb(&mut self) -> Result<Hzb, GpuError> {
        self.gpu_cull_supported()?;
        if !self.last_own {
            return Err(GpuError::NotOwnTarget { what: "read_gpu_hzb" });
        }
        self.resolve_depth();
        let (device, queue) = (&self.device, &self.queue);
        let cull = self.gpu_cull.get_or_insert_with(|| GpuCull::new(device));
        cull.pyramid(device, queue, &self.depth)?;
        read_pyramid(cull, device, queue, &mut self.readback, true)
    }
}

/// Builds the pyramid (`from_depth`, or from level 0 as written) and tests `boxes` (set 1).
fn test_boxes(
    cull: &mut GpuCull,
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    readback: &mut crate::readback::Readback,
    from_depth: bool,
    view_proj: &Mat4,
    boxes: &[(Vec3, Vec3)],
) -> Result<Vec<HzbResult>, GpuError> {
    let list: Vec<Candidate> = boxes.iter().map(|&b| Candidate::new(b, DrawArgs::zeroed())).collect();
    let u = cull.uniform(view_proj, list.len());
    cull.sets[1].prepare(device, queue, &list, &u);
    let mut encoder = device.create_command_encoder(&Default::default());
    cull.encode(device, &mut encoder, from_depth, 1, list.len(), false, 0);
    let bytes = 4 + 4 * list.len() as u64;
    let target = readback.buffer(device, bytes);
    let state = &cull.sets[1].buffers.as_ref().expect("prepared above").state;
    encoder.copy_buffer_to_buffer(state, 0, target, 0, bytes);
    let out = readback.finish(device, queue, encoder, bytes as usize, bytes as usize, 1)?;
    Ok(decode_flags(&out, list.len()))
}

/// Builds the pyramid and reads all of it back.
fn read_pyramid(
    cull: &mut GpuCull,
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    readback: &mut crate::readback::Readback,
    from_depth: bool,
) -> Result<Hzb, GpuError> {
    let mut encoder = device.create_command_encoder(&Default::default());
    cull.encode(device, &mut encoder, from_depth, 1, 0, false, 0);
    let pyramid = cull.pyramid.as_ref().expect("made by the caller");
    let bytes = pyramid.texels() * 4;
    let target = readback.buffer(device, bytes);
    encoder.copy_buffer_to_buffer(&pyramid.buffer, 0, target, 0, bytes);
    let out = readback.finish(device, queue, encoder, bytes as usize, bytes as usize, 1)?;
    let values: Vec<f32> =
        out.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    let levels = pyramid
        .levels
        .iter()
        .map(|&(o, w, h)| HzbLevel {
            width: w,
            height: h,
            depth: values[o as usize..(o + w * h) as usize].to_vec(),
        })
        .collect();
    Ok(Hzb::from_levels(levels))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4;

    // Odd sizes: the last row and column of each level cover a single texel below.
    const W: u32 = 61;
    const H: u32 = 37;

    #[test]
    fn levels_round_up_like_the_cpu_pyramid() {
        let layout = level_layout(5, 3);
        let sizes: Vec<(u32, u32)> = layout.iter().map(|&(_, w, h)| (w, h)).collect();
        assert_eq!(sizes, vec![(5, 3), (3, 2), (2, 1), (1, 1)]);
        assert_eq!(layout.iter().map(|l| l.0).collect::<Vec<_>>(), vec![0, 15, 21, 23]);
        let cpu = Hzb::build(&[0.5; 1920 * 1080], 1920, 1080).unwrap();
        assert_eq!(cpu.levels.len(), level_layout(1920, 1080).len());
        assert!(level_layout(crate::MAX_SIDE, crate::MAX_SIDE).len() <= MAX_LEVELS);
    }

    /// A renderer per backend with compute (skipped without an adapter unless
    /// `TERAWALK_REQUIRE_GPU=1`).
    fn renderers() -> Vec<(&'static str, Renderer)> {
        static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _lock = LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let mut out = Vec::new();
        for (name, backends) in [("vulkan", wgpu::Backends::VULKAN), ("gl", wgpu::Backends::GL)] {
            match Renderer::new_headless_with(W, H, backends) {
                Ok(r) => {
                    r.gpu_cull_supported().unwrap();
                    out.push((name, r));
                }
                Err(e @ GpuError::NoAdapter { .. })
                    if std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1") =>
                {
                    eprintln!("SKIPPED {name}: {e}");
                }
                Err(e) => panic!("{name}: {e}"),
            }
        }
        out
    }

    /// Builds the GPU pyramid of `r` from `depth` (level 0 written directly).
    fn upload(r: &mut Renderer, depth: &[f32]) {
        let cull = r.gpu_cull.get_or_insert_with(|| GpuCull::new(&r.device));
        cull.pyramid(&r.device, &r.queue, &r.depth).unwrap();
        r.queue.write_buffer(&cull.pyramid.as_ref().unwrap().buffer, 0, bytemuck::cast_slice(depth));
    }

    fn gpu_pyramid(r: &mut Renderer, depth: &[f32]) -> Hzb {
        upload(r, depth);
        let cull = r.gpu_cull.as_mut().unwrap();
        read_pyramid(cull, &r.device, &r.queue, &mut r.readback, false).unwrap()
    }

    fn gpu_test(r: &mut Renderer, depth: &[f32], vp: &Mat4, boxes: &[(Vec3, Vec3)]) -> Vec<HzbResult> {
        upload(r, depth);
        let cull = r.gpu_cull.as_mut().unwrap();
        test_boxes(cull, &r.device, &r.queue, &mut r.readback, false, vp, boxes).unwrap()
    }

    /// A camera at the origin looking down +X, z up (as tw_runtime's HZB tests).
    fn view_proj() -> Mat4 {
        let c = Camera::new(Vec3::ZERO, Vec3::X, Vec3::Z, 60f32.to_radians(), 0.1, 1000.0).unwrap();
        c.projection_reverse_z(W as f32 / H as f32) * c.view()
    }

    fn depth_at(vp: &Mat4, x: f32) -> f32 {
        let c = *vp * Vec4::new(x, 0.0, 0.0, 1.0);
        c.z / c.w
    }

    fn unit_box_at(x: f32, y: f32) -> (Vec3, Vec3) {
        (Vec3::new(x - 0.5, y - 0.5, -0.5), Vec3::new(x + 0.5, y + 0.5, 0.5))
    }

    #[test]
    fn gpu_pyramid_equals_the_cpu_pyramid() {
        let mut rng = tw_core::Rng::new(11);
        for (name, mut r) in renderers() {
            for _ in 0..4 {
                let depth: Vec<f32> = (0..W * H).map(|_| rng.f64() as f32).collect();
                let gpu = gpu_pyramid(&mut r, &depth);
                assert_eq!(gpu, Hzb::build(&depth, W, H).unwrap(), "{name}");
            }
        }
    }

    /// A quad at height `z` over `[x0, x1] × [y0, y1]` (grid units).
    fn quad(x0: u32, y0: u32, x1: u32, y1: u32, z: u32) -> PageCluster {
        PageCluster {
            positions: vec![[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]],
            indices: vec![0, 1, 2, 0, 2, 3],
            objects: vec![0, 0],
            self_error: 0.0,
            self_sphere: [0.0, 0.0, 0.0, 1.0],
            group: 0,
            level: 0,
        }
    }

    #[test]
    fn pyramid_of_the_depth_target_equals_the_cpu_pyramid_at_odd_sizes() {
        // Looking down −z at [0, 100]² from z = 200, two quads at different heights.
        let cam = Camera {
            eye: Vec3::new(50.0, 50.0, 200.0),
            target: Vec3::new(50.0, 50.0, 0.0),
            up: Vec3::Y,
            projection: tw_runtime::Projection::Perspective { fovy: 40f32.to_radians() },
            near: 1.0,
            far: 1000.0,
        };
        let (a, b) = (quad(0, 0, 70, 100, 10), quad(40, 20, 100, 60, 30));
        let key = |page| ClusterKey { page, index_in_page: 0, group: 0 };
        for (w, h) in [(W, H), (1, 1), (2, 1), (7, 3)] {
            for (name, _) in renderers() {
                let backends = if name == "gl" { wgpu::Backends::GL } else { wgpu::Backends::VULKAN };
                let mut r = Renderer::new_headless_with(w, h, backends).unwrap();
                r.begin_frame();
                r.draw(crate::Target::Own, &cam, 1.0, &[(key(1), &a), (key(2), &b)], true).unwrap();
                let depth = r.read_depth().unwrap();
                let cpu = Hzb::build(&depth.depth, w, h).unwrap();
                assert_eq!(r.read_gpu_hzb().unwrap(), cpu, "{name}, {w}×{h}");
            }
        }
    }

    #[test]
    fn a_wall_hides_a_box_and_a_one_pixel_gap_shows_it() {
        let vp = view_proj();
        let d = depth_at(&vp, 10.0);
        let gap = W / 2;
        let wall: Vec<f32> = (0..W * H).map(|i| if i % W == gap { 0.0 } else { d }).collect();
        let solid = vec![d; (W * H) as usize];
        // Behind the wall, in the middle (over the gap column); behind it to the side (no gap);
        // in front of the wall; straddling it.
        let boxes =
            [unit_box_at(20.0, 0.0), unit_box_at(20.0, 4.0), unit_box_at(5.0, 0.0), unit_box_at(10.2, 0.0)];
        for (name, mut r) in renderers() {
            use HzbResult::*;
            assert_eq!(
                gpu_test(&mut r, &solid, &vp, &boxes),
                vec![Occluded, Occluded, Visible, Visible],
                "{name}"
            );
            assert_eq!(
                gpu_test(&mut r, &wall, &vp, &boxes),
                vec![Visible, Occluded, Visible, Visible],
                "{name}"
            );
            let hzb = Hzb::build(&wall, W, H).unwrap();
            let cpu: Vec<HzbResult> =
                boxes.iter().map(|b| hzb.test_box_single_level(&vp, b.0, b.1)).collect();
            assert_eq!(gpu_test(&mut r, &wall, &vp, &boxes), cpu, "{name}");
        }
    }

    #[test]
    fn gpu_never_culls_what_the_cpu_test_sees() {
        let vp = view_proj();
        let mut rng = tw_core::Rng::new(5);
        let mut f = move || rng.f64() as f32;
        for (name, mut r) in renderers() {
            let (mut agree, mut total, mut occluded) = (0, 0, 0);
            for _ in 0..6 {
                // Occluders: rectangles at random distances, with one-pixel gaps left open.
                let mut depth = vec![0f32; (W * H) as usize];
                for _ in 0..12 {
                    let (x0, y0) = ((f() * W as f32) as u32, (f() * H as f32) as u32);
                    let (x1, y1) =
                        ((x0 + 4 + (f() * 40.0) as u32).min(W), (y0 + 4 + (f() * 30.0) as u32).min(H));
                    let d = depth_at(&vp, 2.0 + 30.0 * f());
                    for y in y0..y1 {
                        for x in x0..x1 {
                            let px = &mut depth[(y * W + x) as usize];
                            *px = px.max(d);
                        }
                    }
                }
                for _ in 0..8 {
                    let x = (f() * W as f32) as u32;
                    for y in 0..H {
                        depth[(y * W + x) as usize] = 0.0;
                    }
                }
                let boxes: Vec<(Vec3, Vec3)> = (0..2000)
                    .map(|_| {
                        let dist = 1.0 + 60.0 * f();
                        let c = Vec3::new(dist, (f() - 0.5) * dist * 1.6, (f() - 0.5) * dist);
                        let half = Vec3::new(f(), f(), f()) * (0.02 + 2.0 * f());
                        (c - half, c + half)
                    })
                    .collect();
                let hzb = Hzb::build(&depth, W, H).unwrap();
                let gpu = gpu_test(&mut r, &depth, &vp, &boxes);
                for (b, g) in boxes.iter().zip(&gpu) {
                    // Occluded and NoPixels are both "not drawn"; the guard may turn a CPU
                    // NoPixels into a GPU Occluded or Visible, never a CPU Visible into less.
                    // The GPU computes the single-level test; the CPU's exact (refined) test
                    // may cull more, never less.
                    let c = hzb.test_box_single_level(&vp, b.0, b.1);
                    if c == HzbResult::Visible {
                        assert_eq!(*g, HzbResult::Visible, "{name}: GPU culls {b:?}, the CPU test sees it");
                    }
                    if *g == HzbResult::Occluded {
                        assert_ne!(hzb.test_box(&vp, b.0, b.1), HzbResult::Visible, "{name}: {b:?}");
                    }
                    if *g == HzbResult::NoPixels {
                        assert_eq!(c, HzbResult::NoPixels, "{name}: {b:?}");
                    }
                    occluded += usize::from(*g == HzbResult::Occluded);
                    agree += (c == *g) as usize;
                    total += 1;
                }
            }
            eprintln!("{name}: GPU and CPU agree on {agree} of {total} boxes; {occluded} occluded");
            assert!(
                occluded > total / 20,
                "{name}: too few occluded boxes ({occluded}) for a meaningful test"
            );
            // They differ only where the guard reaches a pixel centre the CPU rectangle misses.
            assert!(agree * 100 >= total * 99, "{name}: agree on {agree} of {total}");
        }
    }
}
