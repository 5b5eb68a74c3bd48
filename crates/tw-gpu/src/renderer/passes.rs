//! The draw passes: a frame's clusters made resident in the pool and drawn in batches into
//! the renderer's own target, a caller's view or the item buffer (shaded by [`crate::draw`]),
//! and the whole-frame calls built on them.

use std::time::{Duration, Instant};

use glam::{Mat4, Vec3};
use tw_runtime::{full_mask, Camera, PageCache, Selection, TriangleMask};
use tw_store::{PageCluster, Store};

use super::classified::push_classified;
use super::{bind_group, Attachments, Pass, Renderer, Target};
use crate::draw::{self, LookupLayers, Shading, Uniforms, DEPTH_FORMAT};
use crate::pool::{DrawArgs, Ensure, PoolKey};
use crate::{
    color, query, ClusterKey, DrawMode, FrameStats, GpuError, Image, ItemBuffer, COLOR_FORMAT, DEFAULT_COLOR,
};
use tw_runtime::SelectionPages;

/// A batch is submitted (and waited for before the next is prepared) once it has uploaded a
/// `1 / UPLOADS_PER_BATCH` part of the GPU budget. Each upload is staged in host memory until
/// its submission has run, so without this a frame drawn in chunks (a reference frame) staged
/// up to a whole pool's worth per batch, with the previous batch's still held: on the 10^8
/// plant with `--memory 512M --gpu-memory 512M` the peak RSS was 2.63 GB, against 1.73 GB for
/// the cache, pool, skeleton and fixed parts. Ordinary frames upload far less and are not split.
const UPLOADS_PER_BATCH: u64 = 4;

/// Where a pass looks from: the eye's camera (shaded passes, the item buffer), or a shadow-map
/// layer's scene-to-clip transform ([`Renderer::draw_shadow_map`]).
#[derive(Clone, Copy)]
pub(crate) enum Eye<'a> {
    Camera(&'a Camera),
    Light(&'a Mat4),
}

/// What a pass draws, as [`Renderer::flush`] encodes it.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// Shaded colour into `format`, with shadows of `shadow_layers` map layers (`None`: the
    /// unshadowed shading).
    Shade {
        format: wgpu::TextureFormat,
        shadow_layers: Option<LookupLayers>,
    },
    Items,
    /// Depth only, of the eye, into the own depth target (reverse-Z).
    EyeDepth,
    /// Depth only, into a shadow-map layer (cleared to 1, standard depth).
    ShadowMap,
}

/// A run's pipeline and, when it shades with shadows, the shadows' bind group.
type RunPipeline = (wgpu::RenderPipeline, Option<wgpu::BindGroup>);

/// The draws of one pass being gathered ([`Renderer::draw_pass`]), submitted in parts.
struct PassBatch {
    att: Attachments,
    kind: Kind,
    /// Whether the pass clears its target (only its first part does).
    clear: bool,
    /// Whether the pass records into a caller's encoder (then in one part).
    external: bool,
    /// Whether the pass draws the item buffer (each cluster's number goes to its slot).
    items: bool,
    draws: Vec<DrawArgs>,
    /// With shadows, the runs of `draws` of clusters that need lookups (`Partial`) or not
    /// (classified): (first draw, lookups), in order.
    runs: Vec<(usize, bool)>,
    /// The pool keys of the clusters in `draws`, released once the part is submitted.
    keys: Vec<PoolKey>,
    /// Whether no part was submitted yet.
    first: bool,
    /// Time spent making clusters resident.
    upload: Duration,
    /// The pool's uploaded bytes when the current part began.
    uploads_from: u64,
}

impl Renderer {
    /// Starts a frame: resets the stats; clusters drawn from now on are this frame's (the pool
    /// evicts only clusters not drawn in the current frame).
    pub fn begin_frame(&mut self) {
        self.pool.begin_frame();
        self.stats = FrameStats::default();
    }

    /// Draws `clusters` from `camera` into `target`: clusters not resident are uploaded first
    /// (positions are grid coordinates × `grid_step`, scene space). With `clear` the colour and
    /// depth targets are cleared first (colour to transparent black, depth to 0); without, the
    /// clusters are drawn on top of what the frame drew before (depth-tested against it). When
    /// the selection exceeds the GPU budget it is drawn in several batches (see [`pool`](crate::pool)).
    /// Submits without waiting. Malformed triangles (an index beyond the vertices) are skipped.
    pub fn draw(
        &mut self,
        target: Target<'_>,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        clear: bool,
    ) -> Result<(), GpuError> {
        self.draw_masked(target, camera, grid_step, clusters, None, clear)
    }

    /// [`draw`](Self::draw) of only some triangles: with `masks`, cluster `i` draws the
    /// triangles whose bits are set in `masks[i]` (bit `t` = triangle `t`; `u128::MAX` = all;
    /// see [`tw_runtime::triangle_test`]). A partial cluster is drawn as runs of consecutive
    /// triangles straight from its pooled index range (no copy), its smallest gaps bridged so that
    /// it takes at most [`MAX_RUNS`] draws; the frame's triangle count counts what was drawn.
    pub fn draw_masked(
        &mut self,
        target: Target<'_>,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        masks: Option<&[TriangleMask]>,
        clear: bool,
    ) -> Result<(), GpuError> {
        match target {
            Target::Own => {
                let view = self.color_view.clone();
                self.last_own = true;
                let size = (self.width, self.height);
                let pass = Pass::Shade { view: &view, format: COLOR_FORMAT, own: true };
                self.depth_stale = self.samples > 1;
                self.draw_pass(None, pass, size, Eye::Camera(camera), grid_step, clusters, masks, clear)
            }
            Target::View { view, format, size } => {
                self.last_own = false;
                self.draw_pass(
                    None,
                    Pass::Shade { view, format, own: false },
                    size,
                    Eye::Camera(camera),
                    grid_step,
                    clusters,
                    masks,
                    clear,
                )
            }
        }
    }

    /// [`draw_masked`](Self::draw_masked) into the own depth target only: no fragment shading,
    /// the colour target left as it was. What [`read_depth`](Self::read_depth) and
    /// [`query_boxes`](Self::query_boxes) then see is the depth a shaded pass of the same
    /// clusters would have left: the occluder pass of GigaWalk's OR, which renders depth only.
    pub fn draw_depth_masked(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        masks: Option<&[TriangleMask]>,
        clear: bool,
    ) -> Result<(), GpuError> {
        self.last_own = true;
        self.depth_stale = self.samples > 1;
        let size = (self.width, self.height);
        self.draw_pass(None, Pass::EyeDepth, size, Eye::Camera(camera), grid_step, clusters, masks, clear)
    }

    /// Hardware occlusion queries of `boxes` (scene-space min, max) against the own depth
    /// target as the frame's draws left it, from `camera` (the camera of those draws): per box
    /// the samples that passed on Vulkan, 0 or 1 on GL ([`Renderer::queries_count_samples`]),
    /// [`query::EYE_INSIDE`] for a box around the eye; > 0 means visible. Waits for the GPU.
    pub fn query_boxes(&mut self, camera: &Camera, boxes: &[(Vec3, Vec3)]) -> Result<Vec<u64>, GpuError> {
        if !self.last_own {
            return Err(GpuError::NotOwnTarget { what: "query_boxes" });
        }
        let start = Instant::now();
        let aspect = self.width as f32 / self.height as f32;
        let view_proj = camera.projection_reverse_z(aspect) * camera.view();
        // With multisampling the boxes are rasterized at the same samples against the
        // multisampled depth itself (no resolve); counts are given back in pixels (rounded up).
        let samples = self.samples;
        let depth_view = match &self.msaa_own {
            Some(t) if samples > 1 => t.depth.clone(),
            _ => self.depth_view.clone(),
        };
        let q = self
            .box_queries
            .get_or_insert_with(|| query::BoxQueries::new(&self.device, &self.queue, DEPTH_FORMAT, samples));
        let mut r =
            q.run(&self.device, &self.queue, &mut self.readback, &depth_view, view_proj, camera, boxes)?;
        if samples > 1 && self.queries_count_samples() {
            for c in r.iter_mut().filter(|c| **c != query::EYE_INSIDE) {
                *c = c.div_ceil(samples as u64);
            }
        }
        self.stats.render += start.elapsed();
        Ok(r)
    }

    /// A whole single-pass frame into the own target: [`begin_frame`](Self::begin_frame),
    /// [`draw`](Self::draw) (clearing), [`read_color`](Self::read_color).
    pub fn render_clusters(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
    ) -> Result<Image, GpuError> {
        self.begin_frame();
        self.draw(Target::Own, camera, grid_step, clusters, true)?;
        self.read_color()
    }

    /// A whole frame into the caller's colour `view` (`format`, `size`): begins a frame,
    /// draws (clearing) and submits, without waiting and without readback — the caller
    /// presents the surface texture or shows the egui texture. Formats without sRGB encoding
    /// (e.g. `Bgra8Unorm` surfaces) get it in the shader.
    pub fn render_to_view(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        view: &wgpu::TextureView,
        format: wgpu::TextureFormat,
        size: (u32, u32),
    ) -> Result<(), GpuError> {
        self.begin_frame();
        self.draw(Target::View { view, format, size }, camera, grid_step, clusters, true)
    }

    /// Like [`render_to_view`](Self::render_to_view), but records the frame's one render pass
    /// into the caller's `encoder` (submitted by the caller; uploads go through the queue and
    /// land before that submit). The frame must fit the GPU budget in one batch, else
    /// [`GpuError::OverBudget`] (and nothing is recorded; use `render_to_view` or a larger
    /// budget).
    #[allow(clippy::too_many_arguments)]
    pub fn encode_to_view(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        view: &wgpu::TextureView,
        format: wgpu::TextureFormat,
        size: (u32, u32),
    ) -> Result<(), GpuError> {
        self.begin_frame();
        self.last_own = false;
        self.draw_pass(
            Some(encoder),
            Pass::Shade { view, format, own: false },
            size,
            Eye::Camera(camera),
            grid_step,
            clusters,
            None,
            true,
        )
    }

    /// Renders a [`Selection`] over `store` into the own target, taking the decoded pages from
    /// `cache` (clusters whose page cannot be loaded are skipped and logged).
    pub fn render_selection(
        &mut self,
        store: &Store,
        cache: &PageCache,
        camera: &Camera,
        selection: &Selection,
    ) -> Result<Image, GpuError> {
        let pages = SelectionPages::resolve(store, cache, &selection.clusters);
        self.render_clusters(camera, store.header().grid_step, &pages.clusters())
    }

    /// Draws `clusters` with depth test into the item buffer (own size, cleared) and reads it
    /// back: per pixel the object, the cluster (its position in `clusters`) and the triangle
    /// (see [`ids`](crate::ids)). Begins a frame of its own.
    pub fn item_buffer(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
    ) -> Result<ItemBuffer, GpuError> {
        self.begin_frame();
        self.draw_items(camera, grid_step, clusters, 0, true)?;
        let keys: Vec<ClusterKey> = clusters.iter().map(|c| c.0).collect();
        self.read_items(&keys)
    }

    /// Draws `clusters` into the item buffer (own size), the first of them numbered
    /// `first_number` (cluster ids in the buffer are positions in the whole list the caller
    /// later passes to [`read_items`](Self::read_items)); with `clear` the buffer and depth
    /// are cleared first, else the clusters are depth-tested against what the frame drew
    /// before — so a large set can be drawn in chunks.
    pub fn draw_items(
        &mut self,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        first_number: u32,
        clear: bool,
    ) -> Result<(), GpuError> {
        let size = (self.width, self.height);
        self.item_base = first_number;
        self.depth_stale = false;
        self.draw_pass(None, Pass::Items, size, Eye::Camera(camera), grid_step, clusters, None, clear)
    }

    /// Reads the item buffer back after [`draw_items`](Self::draw_items); `clusters` are the
    /// keys of every cluster drawn into it, in the numbering of those calls. Waits for the GPU.
    pub fn read_items(&mut self, clusters: &[ClusterKey]) -> Result<ItemBuffer, GpuError> {
        let Some((texture, _)) = &self.items else { return Err(GpuError::Gpu("no item target".into())) };
        let texture = texture.clone();
        let bytes = self.read_texture(&texture, 16)?;
        let raw = bytes
            .chunks_exact(16)
            .map(|p| {
                let w = |i: usize| u32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
                [w(0), w(4), w(8), w(12)]
            })
            .collect();
        Ok(ItemBuffer { width: self.width, height: self.height, raw, clusters: clusters.to_vec() })
    }

    /// [`item_buffer`](Self::item_buffer) of a [`Selection`] (pages from `cache`).
    pub fn item_buffer_selection(
        &mut self,
        store: &Store,
        cache: &PageCache,
        camera: &Camera,
        selection: &Selection,
    ) -> Result<ItemBuffer, GpuError> {
        let pages = SelectionPages::resolve(store, cache, &selection.clusters);
        self.item_buffer(camera, store.header().grid_step, &pages.clusters())
    }

    /// The draw shaders' uniforms for `camera` on a target of `size`. Nothing a shader branches
    /// on alone goes here (draw.wgsl: the colour mode and the sRGB encoding are pipeline
    /// constants, [`draw::Pipelines::shaded`]).
    pub(crate) fn write_uniforms(&self, camera: &Camera, (width, height): (u32, u32)) {
        let aspect = width as f32 / height as f32;
        let view_proj = camera.projection_reverse_z(aspect) * camera.view();
        let u = Uniforms {
            view_proj: view_proj.to_cols_array_2d(),
            // w = 0: an orthographic camera, whose viewer direction is the headlight
            // (Camera::to_viewer; draw.wgsl viewer_normal).
            eye: camera.eye.extend(if camera.is_orthographic() { 0.0 } else { 1.0 }).to_array(),
            sun: camera.sun_direction().extend(0.0).to_array(),
            params: [
                0,
                self.object_color_count,
                color::pack(DEFAULT_COLOR),
                self.highlight.unwrap_or(u32::MAX),
            ],
            headlight: camera.headlight().extend(0.0).to_array(),
            clip: self.clip_planes(),
        };
        self.queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
    }

    /// The section's half-spaces for the uniforms (common.wgsl `clip`).
    fn clip_planes(&self) -> [[f32; 4]; 12] {
        self.section.clip_planes().map(|p| p.to_array())
    }

    /// The draw shaders' uniforms for a shadow-map pass: only the transform matters to its
    /// vertex stage (shadow.wgsl `vs_depth`).
    fn write_light_uniforms(&self, view_proj: &Mat4) {
        let u = Uniforms {
            view_proj: view_proj.to_cols_array_2d(),
            eye: [0.0; 4],
            sun: [0.0; 4],
            params: [0, self.object_color_count, color::pack(DEFAULT_COLOR), 0],
            headlight: [0.0; 4],
            clip: self.clip_planes(),
        };
        self.queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
    }

    /// Draws `clusters` (with `masks`) from `eye` into `pass`'s target of `size`
    /// ([`draw_part`](Self::draw_part)). With cross-fades ([`Renderer::set_fades`]) an eye pass
    /// draws its clusters drawn whole first, with the pipelines without the dither test, then
    /// the fading ones with it: a fragment stage that may discard makes a CPU rasterizer test
    /// depth late, for every fragment of the pipeline. A pass into a caller's encoder stays one
    /// part, every draw with the dither test.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn draw_pass(
        &mut self,
        external: Option<&mut wgpu::CommandEncoder>,
        pass: Pass<'_>,
        size: (u32, u32),
        eye: Eye<'_>,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        masks: Option<&[TriangleMask]>,
        clear: bool,
    ) -> Result<(), GpuError> {
        let eye_pass = matches!(pass, Pass::Shade { .. } | Pass::EyeDepth);
        self.dither_pipelines = eye_pass && self.dithered();
        if !self.dither_pipelines || external.is_some() {
            return self.draw_part(external, pass, size, eye, grid_step, clusters, masks, clear);
        }
        let mut parts = [(Vec::new(), Vec::new()), (Vec::new(), Vec::new())];
        for (i, c) in clusters.iter().enumerate() {
            let part = &mut parts[self.fades(&c.0) as usize];
            part.0.push(*c);
            part.1.push(masks.and_then(|m| m.get(i).copied()).unwrap_or(u128::MAX));
        }
        let [(whole, whole_masks), (fading, fading_masks)] = parts;
        self.dither_pipelines = false;
        let first = self.draw_part(None, pass, size, eye, grid_step, &whole, Some(&whole_masks), clear);
        self.dither_pipelines = true;
        first?;
        self.draw_part(None, pass, size, eye, grid_step, &fading, Some(&fading_masks), false)
    }

    /// Draws `clusters` (with `masks`) from `eye` into `pass`'s target of `size`: makes each
    /// resident in the pool and gathers its draws, submitting the gathered part when the pool
    /// is full or the part's uploads reach the staging bound, and the rest at the end (into
    /// `external` when given: then the whole pass must fit the pool at once).
    #[allow(clippy::too_many_arguments)]
    fn draw_part(
        &mut self,
        mut external: Option<&mut wgpu::CommandEncoder>,
        pass: Pass<'_>,
        size: (u32, u32),
        eye: Eye<'_>,
        grid_step: f64,
        clusters: &[(ClusterKey, &PageCluster)],
        masks: Option<&[TriangleMask]>,
        clear: bool,
    ) -> Result<(), GpuError> {
        let max = self.device.limits().max_texture_dimension_2d;
        if size.0 == 0 || size.1 == 0 || size.0 > max || size.1 > max {
            return Err(GpuError::Size { width: size.0, height: size.1, max });
        }
        let mut b = self.begin_pass(pass, size, eye, clear, external.is_some())?;
        for (i, (key, cluster)) in clusters.iter().enumerate() {
            let mask = masks.and_then(|m| m.get(i).copied()).unwrap_or(u128::MAX);
            self.add_cluster(&mut b, i, *key, cluster, grid_step, mask)?;
        }
        self.flush(external.take(), &b.att, b.kind, &b.draws, &b.runs, b.clear && b.first)?;
        // Submitted: a later draw of the same frame (the second pass of occlusion culling, the
        // next chunk of a reference frame) may evict these if it needs the room.
        self.pool.release_batch(&b.keys);
        self.stats.upload += b.upload;
        Ok(())
    }

    /// Sets a pass up: the uniforms for `eye` (and the shadows' for a shaded pass with
    /// shadows), the depth, item and multisampled targets it draws into, and on GL a wait for
    /// earlier GPU work when the pool may evict.
    fn begin_pass(
        &mut self,
        pass: Pass<'_>,
        size: (u32, u32),
        eye: Eye<'_>,
        clear: bool,
        external: bool,
    ) -> Result<PassBatch, GpuError> {
        let items = matches!(pass, Pass::Items);
        let kind = match pass {
            Pass::Shade { format, .. } => Kind::Shade { format, shadow_layers: self.shadow_layers()? },
            Pass::Items => Kind::Items,
            Pass::EyeDepth => Kind::EyeDepth,
            Pass::ShadowMap { .. } => Kind::ShadowMap,
        };
        match eye {
            Eye::Camera(camera) => {
                self.write_uniforms(camera, size);
                if let Kind::Shade { shadow_layers: Some(_), .. } = kind {
                    self.shadow.write_uniforms(&self.queue, camera);
                }
            }
            Eye::Light(view_proj) => self.write_light_uniforms(view_proj),
        }
        let depth_view = match pass {
            Pass::ShadowMap { layer } => self.shadow.layer_view(layer)?,
            _ => self.depth_view_for(size),
        };
        if items {
            self.make_item_target();
        }
        let att = self.attachments(&pass, size, depth_view);
        // GL (llvmpipe) hazard, seen in tests: a queued write into an arena range that an
        // earlier, still running submission draws from is not always ordered after it. On GL,
        // wait for earlier work before any eviction can happen (the arena is full) and after
        // each batch; other backends order it themselves.
        let gl = self.info.backend == wgpu::Backend::Gl;
        if gl && self.pool.stats().arena_bytes >= self.pool.budget() {
            self.wait_idle()?;
        }
        Ok(PassBatch {
            att,
            kind,
            clear,
            external,
            items,
            draws: Vec::new(),
            runs: Vec::new(),
            keys: Vec::new(),
            first: true,
            upload: Duration::ZERO,
            uploads_from: self.pool.stats().uploaded_bytes,
        })
    }

    /// Makes cluster `i` of the pass (`key`) resident and adds the draws of its `mask` to `b`.
    /// When the pool is full, the part gathered so far is submitted first (once: a cluster that
    /// does not fit an emptied pool is an error); after adding, the part is submitted when its
    /// uploads reach the staging bound (see [`UPLOADS_PER_BATCH`]).
    fn add_cluster(
        &mut self,
        b: &mut PassBatch,
        i: usize,
        key: ClusterKey,
        cluster: &PageCluster,
        grid_step: f64,
        mask: TriangleMask,
    ) -> Result<(), GpuError> {
        let pk = (key.page, key.index_in_page);
        let mut retried = false;
        loop {
            let t = Instant::now();
            let r = self.pool.ensure(&self.device, &self.queue, pk, grid_step, cluster);
            b.upload += t.elapsed();
            match r {
                Ensure::Ready { args, slot } => {
                    if b.items {
                        self.pool.set_item(&self.queue, slot, self.item_base + i as u32 + 1);
                    }
                    if matches!(b.kind, Kind::Shade { .. } | Kind::EyeDepth) {
                        let fade = self.fades.get(&pk).copied().unwrap_or(0);
                        self.pool.set_fade(&self.queue, slot, fade);
                    }
                    let lookups = match b.kind {
                        Kind::Shade { shadow_layers: Some(_), .. } => self.shadow.note_slot(pk, slot),
                        _ => false,
                    };
                    let refined = (lookups && self.refines_shadow_classes())
                        .then(|| self.shadow.triangle_classes(pk))
                        .flatten();
                    let before = b.draws.len();
                    let (drawn, masked) = match refined {
                        Some(classes) => {
                            let codes = crate::shadow::CLASSIFIED_CODES;
                            push_classified(&mut b.draws, &mut b.runs, args, cluster, mask, classes, codes)
                        }
                        None => {
                            let counts = push_runs(&mut b.draws, args, cluster, mask);
                            if b.draws.len() > before && b.runs.last().is_none_or(|r| r.1 != lookups) {
                                b.runs.push((before, lookups));
                            }
                            counts
                        }
                    };
                    let cluster_drawn = (b.draws.len() > before) as u64;
                    if b.kind == Kind::ShadowMap {
                        self.stats.shadow_clusters += cluster_drawn;
                        self.stats.shadow_triangles += drawn;
                    } else {
                        self.stats.clusters += cluster_drawn;
                        self.stats.triangles += drawn;
                        self.stats.masked_triangles += masked;
                    }
                    b.keys.push(pk);
                    // Bound the staging memory of one batch (see `UPLOADS_PER_BATCH`).
                    let uploaded = self.pool.stats().uploaded_bytes - b.uploads_from;
                    // Multisampled, a batch is `samples` times smaller: lavapipe's binned
                    // scene of a batch grows with the samples (a 10^7 reference frame at 64
                    // MiB peaked 63 MB higher at 4 samples with the single-sample cap).
                    let cap = self.pool.budget() / (UPLOADS_PER_BATCH * self.samples as u64);
                    if !b.external && uploaded >= cap {
                        self.flush_part(b)?;
                    }
                    return Ok(());
                }
                Ensure::Empty => return Ok(()),
                Ensure::Full if b.external => {
                    return Err(GpuError::OverBudget { budget: self.pool.budget() });
                }
                Ensure::Full if !retried && !b.draws.is_empty() => {
                    self.flush_part(b)?;
                    retried = true;
                }
                Ensure::Full => {
                    return Err(GpuError::Gpu(format!(
                        "cluster {key:?} does not fit the GPU budget of {} bytes",
                        self.pool.budget()
                    )))
                }
            }
        }
    }

    /// Submits a part of a frame drawn in several batches and waits for it before the next is
    /// prepared, on every backend (staging, see [`UPLOADS_PER_BATCH`]; on GL also the hazard
    /// noted in `begin_pass`); its clusters may then be evicted. The next part's uploads are
    /// counted from here, and it does not clear.
    fn flush_part(&mut self, b: &mut PassBatch) -> Result<(), GpuError> {
        self.flush(None, &b.att, b.kind, &b.draws, &b.runs, b.clear && b.first)?;
        self.wait_idle()?;
        self.pool.release_batch(&b.keys);
        b.draws.clear();
        b.runs.clear();
        b.keys.clear();
        b.uploads_from = self.pool.stats().uploaded_bytes;
        b.first = false;
        Ok(())
    }

    pub(crate) fn wait_idle(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Gpu(format!("waiting for the GPU: {e}")))
    }

    /// Encodes and submits one batch of a pass of `kind`. With shadows, each of `runs` (first
    /// draw, whether its clusters need lookups) is drawn with its pipeline, in order: the order
    /// of the draws, and so the image where depths tie, is that of one pipeline.
    fn flush(
        &mut self,
        external: Option<&mut wgpu::CommandEncoder>,
        att: &Attachments,
        kind: Kind,
        batch: &[DrawArgs],
        runs: &[(usize, bool)],
        clear: bool,
    ) -> Result<(), GpuError> {
        let start = Instant::now();
        if self.bind_generation != self.pool.generation {
            self.bind_group =
                bind_group(&self.device, &self.pipelines, &self.uniforms, &self.pool, &self.object_colors);
            self.bind_generation = self.pool.generation;
        }
        let indirect = match self.draw_mode {
            DrawMode::Indirect if !batch.is_empty() => {
                Some(self.indirect.write(&self.device, &self.queue, batch).clone())
            }
            _ => None,
        };
        let (plain, classified, lookup) = self.pass_pipelines(kind, att.samples)?;
        let groups = run_groups(&plain, classified.as_ref(), lookup.as_ref(), runs, batch.len());
        let mut own = None;
        let encoder = match external {
            Some(e) => e,
            None => own.insert(
                self.device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("clusters") }),
            ),
        };
        self.encode_runs(encoder, att, kind, clear, &groups, batch, indirect.as_ref());
        if let Some(e) = own {
            self.submit_batch(e)?;
        }
        self.pool.note_batch();
        self.count_draws(kind, &groups, start);
        Ok(())
    }

    /// The pipelines of a pass of `kind`: the one for every draw, and with shadow layers the
    /// one for clusters the shadow stage classified and the one for clusters that need lookups
    /// (the first is then the classified one), each with the shadows' bind group where it
    /// shades with shadows.
    fn pass_pipelines(
        &mut self,
        kind: Kind,
        samples: u32,
    ) -> Result<(RunPipeline, Option<RunPipeline>, Option<RunPipeline>), GpuError> {
        Ok(match kind {
            Kind::Shade { format, shadow_layers: None } => {
                (self.shaded_pipeline(format, samples, Shading::Plain)?, None, None)
            }
            Kind::Shade { format, shadow_layers: Some(layers) } => {
                let classified = self.shaded_pipeline(format, samples, Shading::Classified)?;
                let lookup = self.shaded_pipeline(format, samples, Shading::Lookup(layers))?;
                (classified.clone(), Some(classified), Some(lookup))
            }
            Kind::Items => ((self.pipelines.item(&self.device, self.sectioned()).clone(), None), None, None),
            Kind::EyeDepth => {
                let clip = (self.sectioned(), self.dither_pipelines);
                let p = self.pipelines.eye_depth(&self.device, samples, clip).clone();
                ((p, None), None, None)
            }
            Kind::ShadowMap => {
                ((self.pipelines.shadow_depth(&self.device, self.sectioned()).clone(), None), None, None)
            }
        })
    }

    /// Encodes one render pass over `att` (cleared when `clear`: standard depth for the shadow
    /// map, 0 nearest the light, reverse-Z elsewhere) drawing each group's range of `batch`
    /// with its pipeline, indirectly from `indirect` when given.
    #[allow(clippy::too_many_arguments)]
    fn encode_runs(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        att: &Attachments,
        kind: Kind,
        clear: bool,
        groups: &[(&RunPipeline, std::ops::Range<usize>)],
        batch: &[DrawArgs],
        indirect: Option<&wgpu::Buffer>,
    ) {
        let clear_depth = if kind == Kind::ShadowMap { 1.0 } else { 0.0 };
        let load_color =
            if clear { wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT) } else { wgpu::LoadOp::Load };
        let color = att.color.as_ref().map(|view| wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: att.resolve.as_ref(),
            ops: wgpu::Operations { load: load_color, store: wgpu::StoreOp::Store },
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("clusters"),
            color_attachments: if color.is_some() { std::slice::from_ref(&color) } else { &[] },
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &att.depth,
                depth_ops: Some(wgpu::Operations {
                    load: if clear { wgpu::LoadOp::Clear(clear_depth) } else { wgpu::LoadOp::Load },
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        for ((pipeline, shadow_bind), range) in groups {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            if let Some(bind) = shadow_bind {
                pass.set_bind_group(1, bind, &[]);
            }
            if let Some(arena) = self.pool.arena() {
                let offset = (range.start * std::mem::size_of::<DrawArgs>()) as u64;
                let args = &batch[range.clone()];
                draw::encode_batch(&mut pass, arena, args, indirect.map(|b| (b, offset)));
            }
        }
    }

    /// Submits a batch's own encoder. At most two batches in flight: a CPU driver runs a
    /// submission long after it is made, and each holds the staging copies of its uploads (up
    /// to a quarter of the GPU budget, `UPLOADS_PER_BATCH`), so without this wait they piled
    /// up over frames. Waiting for the previous batch, not this one, keeps the CPU preparing
    /// the next batch while the GPU draws.
    fn submit_batch(&mut self, encoder: wgpu::CommandEncoder) -> Result<(), GpuError> {
        let index = self.queue.submit([encoder.finish()]);
        if let Some(previous) = self.in_flight.replace(index) {
            self.device
                .poll(wgpu::PollType::Wait { submission_index: Some(previous), timeout: None })
                .map_err(|e| GpuError::Gpu(format!("waiting for the GPU: {e}")))?;
        }
        Ok(())
    }

    /// Counts a batch's draw calls (one per group drawn indirectly, one per draw directly) and
    /// its time since `start`, under the shadow map's figures or the frame's.
    fn count_draws(&mut self, kind: Kind, groups: &[(&RunPipeline, std::ops::Range<usize>)], start: Instant) {
        let calls: u64 = groups
            .iter()
            .map(|(_, range)| match (self.draw_mode, range.is_empty()) {
                (_, true) => 0,
                (DrawMode::Indirect, false) => 1,
                (DrawMode::Direct, false) => range.len() as u64,
            })
            .sum();
        if kind == Kind::ShadowMap {
            self.stats.shadow_draw_calls += calls;
            self.stats.shadow_render += start.elapsed();
        } else {
            self.stats.draw_calls += calls;
            self.stats.render += start.elapsed();
        }
    }
}

/// The pipeline of each run of draws `[from, to)` of a batch of `n`: with shadow layers, each
/// of `runs` (first draw, whether it needs lookups) with the lookup or the classified
/// pipeline; else all of them with `plain`.
fn run_groups<'p>(
    plain: &'p RunPipeline,
    classified: Option<&'p RunPipeline>,
    lookup: Option<&'p RunPipeline>,
    runs: &[(usize, bool)],
    n: usize,
) -> Vec<(&'p RunPipeline, std::ops::Range<usize>)> {
    match (classified, lookup) {
        (Some(classified), Some(lookup)) => runs
            .iter()
            .enumerate()
            .map(|(i, &(from, lookups))| {
                let to = runs.get(i + 1).map_or(n, |r| r.0);
                (if lookups { lookup } else { classified }, from..to)
            })
            .collect(),
        _ => vec![(plain, 0..n)],
    }
}

/// At most this many draws per partially drawn cluster: beyond, the smallest gaps between its
/// runs of visible triangles are drawn too. Each draw has a fixed cost on Mesa's CPU drivers
/// that outweighs a few triangles' (docs/benchmarks-log.md, "Triangle-level HZB culling").
pub const MAX_RUNS: usize = 4;

/// Appends the draws of `mask`'s triangles of a resident cluster drawn whole by `args` and
/// returns how many triangles they draw and how many of those are in the mask. A cluster with
/// a malformed triangle (which the pool skipped, shifting the others) is drawn whole.
pub(super) fn push_runs(
    batch: &mut Vec<DrawArgs>,
    args: DrawArgs,
    cluster: &PageCluster,
    mask: TriangleMask,
) -> (u64, u64) {
    let triangles = args.index_count / 3;
    let full = full_mask(triangles as usize);
    let well_formed = || cluster.indices.iter().all(|&v| (v as usize) < cluster.positions.len());
    if mask & full == full || triangles > 128 || !well_formed() {
        batch.push(args);
        return (triangles as u64, triangles as u64);
    }
    let mut runs = triangle_runs(mask & full);
    while runs.len() > MAX_RUNS {
        let i = (1..runs.len()).min_by_key(|&i| runs[i].0 - runs[i - 1].1).expect("two runs or more");
        runs[i - 1].1 = runs[i].1;
        runs.remove(i);
    }
    let mut drawn = 0u64;
    for (start, end) in runs {
        batch.push(DrawArgs {
            index_count: 3 * (end - start),
            first_index: args.first_index + 3 * start,
            ..args
        });
        drawn += (end - start) as u64;
    }
    (drawn, (mask & full).count_ones() as u64)
}

/// The maximal runs `[start, end)` of set bits of `mask`, in order.
fn triangle_runs(mut mask: TriangleMask) -> Vec<(u32, u32)> {
    let mut runs = Vec::new();
    let mut base = 0u32;
    while mask != 0 {
        let skip = mask.trailing_zeros();
        mask >>= skip;
        let len = mask.trailing_ones();
        runs.push((base + skip, base + skip + len));
        base += skip + len;
        mask = if len >= 128 { 0 } else { mask >> len };
    }
    runs
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strip(triangles: u8) -> PageCluster {
        PageCluster {
            positions: (0..triangles as u32 + 2).map(|i| [i, i % 2, 0]).collect(),
            indices: (0..triangles).flat_map(|t| [t, t + 1, t + 2]).collect(),
            objects: vec![0; triangles as usize],
            ..Default::default()
        }
    }

    #[test]
    fn masked_clusters_draw_runs_of_their_pooled_index_range() {
        let c = strip(10);
        let args = DrawArgs {
            index_count: 30,
            instance_count: 1,
            first_index: 300,
            base_vertex: 40,
            first_instance: 0,
        };
        let ranges = |mask: TriangleMask| {
            let mut batch = Vec::new();
            let (drawn, masked) = push_runs(&mut batch, args, &c, mask);
            for a in &batch {
                assert_eq!((a.base_vertex, a.instance_count, a.first_instance), (40, 1, 0));
            }
            assert_eq!(masked, (mask & 0b11_1111_1111).count_ones() as u64);
            (drawn, batch.iter().map(|a| (a.first_index, a.index_count)).collect::<Vec<_>>())
        };
        // Everything (and bits beyond the cluster): the whole range, one draw.
        assert_eq!(ranges(u128::MAX), (10, vec![(300, 30)]));
        assert_eq!(ranges(0b11_1111_1111), (10, vec![(300, 30)]));
        assert_eq!(ranges(0), (0, vec![]));
        assert_eq!(MAX_RUNS, 4);
        // Triangles 0-2, 5, 9: three runs, three draws.
        assert_eq!(ranges(0b10_0010_0111), (5, vec![(300, 9), (315, 3), (327, 3)]));
        assert_eq!(ranges(0b10_0000_0000), (1, vec![(327, 3)]));
        // Triangles 0, 2, 4, 6, 9: five runs; the first of the smallest gaps (triangle 1) is
        // bridged.
        assert_eq!(ranges(0b10_0101_0101), (6, vec![(300, 9), (312, 3), (318, 3), (327, 3)]));
        assert_eq!(triangle_runs(u128::MAX), vec![(0, 128)]);
        assert_eq!(triangle_runs(1 << 127 | 0b110), vec![(1, 3), (127, 128)]);
        assert_eq!(triangle_runs(0), vec![]);
        // A malformed triangle shifts the pooled ones: the cluster is drawn whole.
        let mut bad = c.clone();
        bad.indices[4] = 200;
        let mut batch = Vec::new();
        assert_eq!(push_runs(&mut batch, args, &bad, 0b1), (10, 10));
        assert_eq!(batch.len(), 1);
    }
}
