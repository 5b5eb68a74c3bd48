//! The shadow stage of a frame (Govindaraju's thesis ch. 4; docs/RUNTIME.md "Shadows"): after the
//! eye's LOD cut is known and before it is drawn,
//! 1. **layers**: the light's shadow-map layers are fitted to the cut's boxes (the receivers):
//!    sun cascades along the eye's depth, or the faces of a cube around a point light
//!    ([`tw_runtime::shadow::fit_layers`]);
//! 2. **light-view sets**: per layer, the clusters that can cast into it — the eye's LOD cut
//!    (the thesis' LOD consistency: the eye's level for every cluster, so that a surface is never
//!    shadowed by a coarser copy of itself) culled by the layer's frustum instead of the eye's,
//!    streamed under the same memory budget ([`tw_runtime::Streamer::select_light`]);
//! 3. **shadow map**: each layer's set drawn depth-only into its layer, occlusion culled from the
//!    light two-pass (what the light saw last frame first, the rest tested against it);
//! 4. **cross-culling** (optional, on by default): the layers are read back, and each receiver is
//!    classified against them by the lookup rule of [`tw_runtime::shadow`] as fully lit, fully
//!    shadowed or partly shadowed (the thesis' steps 2 and 3, against a min/max pyramid of the
//!    light's depth instead of occlusion queries); the light-visible clusters and the casters
//!    (those in front of a partly shadowed receiver, step 4) are counted. Only partly shadowed
//!    receivers look the map up when the eye's pass draws them; the classes follow the lookup
//!    rule conservatively, so the image is the same with or without cross-culling.
//!
//! The eye's pass then draws as without shadows ([`crate::occlude::draw_culled`]), the renderer
//! shading each cluster by its class.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use serde::{Deserialize, Serialize};
use tw_gpu::Renderer;
use tw_runtime::frustum::grid_box;
use tw_runtime::shadow::{
    casters, classify_receivers, fit_layers, light_visible, LightDepth, ShadowSetStats,
};
use tw_runtime::{Camera, ClusterRef, Light, ResidentPage, SelectOptions, ShadowClass, Shadows, Streamer};
use tw_store::PageCluster;

use crate::{lookup, page_bounds, resident_pages, FrameError};
pub use tw_runtime::shadow::ShadowOptions;

/// Shadows of a frame (`--light`, `--shadows`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowSettings {
    /// The light, in scene space.
    pub light: Light,
    /// Map size, cascades, bias.
    pub options: ShadowOptions,
    /// Classify receivers against the map (fully lit and fully shadowed ones drawn without
    /// lookups); off: every receiver looks the map up. The image is the same either way.
    pub cross_culling: bool,
}

/// What the shadow stage of one frame did: set sizes (thesis ch. 4's figures) and stage times.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ShadowInfo {
    /// Shadow-map layers drawn (sun cascades or cube faces).
    pub layers: u32,
    /// Triangles drawn into the layers (the light-view sets at the eye's LOD; a cluster in two
    /// layers counts twice); their clusters are `sets.light_cut`.
    pub light_triangles: u64,
    /// Of `light_triangles`, those drawn: the layers are occlusion culled from the light (the
    /// light-visible clusters of the last frame first, the rest tested against them).
    pub light_drawn_triangles: u64,
    /// The receivers by class and the light-view sets (cross-culling; without it every receiver
    /// counts as partly shadowed and only the light cut is counted).
    pub sets: ShadowSetStats,
    /// Triangles of the casters (`sets.casters` clusters).
    pub caster_triangles: u64,
    /// Fitting the layers.
    pub fit: Duration,
    /// Selecting the light-view sets.
    pub select: Duration,
    /// Drawing the layers (uploads included; waits for the GPU only where the pool must).
    pub draw: Duration,
    /// Reading the layers back (waits for them to be drawn: on a CPU driver, their rasterization).
    pub readback: Duration,
    /// Building the pyramids and classifying receivers and casters.
    pub classify: Duration,
    /// The whole stage.
    pub total: Duration,
}

/// Runs the shadow stage for `camera`'s cut `receivers` (decoded, with their grid boxes from
/// `bounds`) and leaves the renderer set up to shade the eye's pass with shadows; returns the
/// stage's figures and the layers it drew.
#[allow(clippy::too_many_arguments)]
pub(crate) fn prepare(
    settings: &ShadowSettings,
    streamer: &mut Streamer,
    renderer: &mut Renderer,
    camera: &Camera,
    options: &SelectOptions,
    wait_for_pages: bool,
    receivers: &[(ClusterRef, &PageCluster)],
    bounds: impl Fn(&ClusterRef) -> Option<([u32; 3], [u32; 3])>,
    light_seen: &mut HashSet<ClusterRef>,
) -> Result<(ShadowInfo, Shadows), FrameError> {
    let start = Instant::now();
    let mut info = ShadowInfo::default();
    let header = streamer.store().header().clone();
    let step = header.grid_step;
    let boxes: Vec<(Vec3, Vec3)> = receivers
        .iter()
        .map(|(k, _)| bounds(k).map_or((Vec3::ZERO, Vec3::ZERO), |(lo, hi)| grid_box(lo, hi, step)))
        .collect();
    let shadows = fit_layers(
        &settings.light,
        camera,
        aspect(options.viewport),
        &boxes,
        scene_box(&header),
        &settings.options,
    );
    info.fit = start.elapsed();
    info.layers = shadows.layers.len() as u32;
    renderer.set_shadows(None);
    if shadows.layers.is_empty() {
        info.total = start.elapsed();
        return Ok((info, shadows));
    }
    renderer.set_shadow_map(shadows.size, shadows.layers.len() as u32)?;
    let mut light_sets: Vec<LightSet> = Vec::with_capacity(shadows.layers.len());
    let mut seen_now: HashSet<ClusterRef> = HashSet::new();
    for (i, layer) in shadows.layers.iter().enumerate() {
        let t = Instant::now();
        let (selection, pages) = if wait_for_pages {
            let selection = streamer.select_light_blocking(camera, &layer.view_proj, options);
            let pages = resident_pages(streamer, &selection.clusters);
            (selection, pages)
        } else {
            streamer.select_light(camera, &layer.view_proj, options)
        };
        info.select += t.elapsed();
        let t = Instant::now();
        let set = lookup(&pages, &selection.clusters);
        info.sets.light_cut += set.len() as u64;
        info.light_triangles += triangles(&set);
        let set_boxes = light_boxes(&set, &pages, step);
        let seen =
            draw_layer_culled(&mut info, renderer, &shadows, i, camera, step, &set, &set_boxes, light_seen)?;
        seen_now.extend(seen);
        info.draw += t.elapsed();
        if settings.cross_culling {
            light_sets.push(set_boxes);
        }
    }
    *light_seen = seen_now;
    if settings.cross_culling {
        cross_cull(&mut info, renderer, &shadows, camera, receivers, &boxes, &light_sets)?;
    } else {
        info.sets.receivers_partial = receivers.len() as u64;
        info.sets.triangles_partial = triangles(receivers);
    }
    renderer.set_shadows(Some(&shadows));
    info.total = start.elapsed();
    Ok((info, shadows))
}

/// Steps 2–4 of the thesis' cross-culling against the read-back layers: the receivers' classes
/// (handed to the renderer), then per layer the light-visible clusters and the casters.
fn cross_cull(
    info: &mut ShadowInfo,
    renderer: &mut Renderer,
    shadows: &Shadows,
    camera: &Camera,
    receivers: &[(ClusterRef, &PageCluster)],
    boxes: &[(Vec3, Vec3)],
    light_sets: &[LightSet],
) -> Result<(), FrameError> {
    let t = Instant::now();
    let mut depths = Vec::with_capacity(shadows.layers.len());
    for i in 0..shadows.layers.len() {
        depths.push(renderer.read_shadow_map(i as u32)?);
    }
    info.readback += t.elapsed();
    let t = Instant::now();
    let depths: Vec<LightDepth> =
        depths.iter().map(|d| LightDepth::new(d, shadows.size)).collect::<Result<_, _>>()?;
    let classes = classify_receivers(shadows, &depths, camera, boxes);
    let mut sets = ShadowSetStats::default();
    let receiver_triangles: Vec<u32> = receivers.iter().map(|(_, c)| (c.indices.len() / 3) as u32).collect();
    sets.add_receivers(&classes, &receiver_triangles);
    for (i, set) in light_sets.iter().enumerate() {
        let set_boxes: Vec<(Vec3, Vec3)> = set.iter().map(|(b, _)| *b).collect();
        let visible = light_visible(shadows, i, &depths[i], camera, &set_boxes);
        let casters = casters(shadows, i, camera, boxes, &classes, &set_boxes, &visible);
        sets.add_layer(set.len(), &visible, &casters);
        info.caster_triangles +=
            set.iter().zip(&casters).filter(|(_, &c)| c).map(|((_, tris), _)| tris).sum::<u64>();
    }
    info.sets = sets;
    let keyed: Vec<(ClusterRef, ShadowClass)> = receivers.iter().map(|(k, _)| *k).zip(classes).collect();
    renderer.set_shadow_classes(&keyed);
    info.classify += t.elapsed();
    Ok(())
}

/// A layer's light-view set for cross-culling: its clusters' boxes and triangles.
type LightSet = Vec<((Vec3, Vec3), u64)>;

/// Draws layer `layer`'s light-view set `set` with occlusion culling from the light, two-pass
/// as the eye's hzb (crate::occlude): the clusters the light saw last frame (`light_seen`)
/// first, then the layer is read back and every cluster is tested against it (a box entirely
/// behind the map's farthest depth over its footprint is hidden, [`light_visible`]); the
/// visible others are drawn on top. The map is the one drawing the whole set would give,
/// without drawing what the light cannot see: from inside the 10^8 plant, the floors and roof
/// above a room (a light-view set of 0.4–0.5 M triangles of which ~35 k are drawn). Returns the
/// clusters the light sees, next frame's first pass: the visible others and the first pass's
/// clusters still visible. Without a history (the first frame, after a reset) the whole set is
/// drawn and tested once.
#[allow(clippy::too_many_arguments)]
fn draw_layer_culled(
    info: &mut ShadowInfo,
    renderer: &mut Renderer,
    shadows: &Shadows,
    layer: usize,
    camera: &Camera,
    grid_step: f64,
    set: &[(ClusterRef, &PageCluster)],
    set_boxes: &[((Vec3, Vec3), u64)],
    light_seen: &HashSet<ClusterRef>,
) -> Result<Vec<ClusterRef>, FrameError> {
    let view_proj = &shadows.layers[layer].view_proj;
    let (first, rest): (Vec<usize>, Vec<usize>) = if light_seen.is_empty() {
        ((0..set.len()).collect(), Vec::new())
    } else {
        (0..set.len()).partition(|&i| light_seen.contains(&set[i].0))
    };
    let pick = |ids: &[usize]| -> Vec<(ClusterRef, &PageCluster)> { ids.iter().map(|&i| set[i]).collect() };
    let occluders = pick(&first);
    renderer.draw_shadow_map(layer as u32, view_proj, grid_step, &occluders, true)?;
    let t = Instant::now();
    let depth = renderer.read_shadow_map(layer as u32)?;
    info.readback += t.elapsed();
    let t = Instant::now();
    let depth = LightDepth::new(&depth, shadows.size)?;
    let boxes: Vec<(Vec3, Vec3)> = set_boxes.iter().map(|(b, _)| *b).collect();
    let visible = light_visible(shadows, layer, &depth, camera, &boxes);
    info.classify += t.elapsed();
    let shown: Vec<usize> = rest.iter().copied().filter(|&i| visible[i]).collect();
    let second = pick(&shown);
    if !second.is_empty() {
        renderer.draw_shadow_map(layer as u32, view_proj, grid_step, &second, false)?;
    }
    info.light_drawn_triangles += triangles(&occluders) + triangles(&second);
    Ok(first.iter().chain(&shown).filter(|&&i| visible[i]).map(|&i| set[i].0).collect())
}

/// The scene-space boxes and triangle counts of a light-view set's clusters.
fn light_boxes(
    set: &[(ClusterRef, &PageCluster)],
    pages: &[(u32, Arc<ResidentPage>)],
    step: f64,
) -> Vec<((Vec3, Vec3), u64)> {
    set.iter()
        .map(|(k, c)| {
            let b = page_bounds(pages, k).map_or((Vec3::ZERO, Vec3::ZERO), |(lo, hi)| grid_box(lo, hi, step));
            (b, (c.indices.len() / 3) as u64)
        })
        .collect()
}

/// The receivers the layers are fitted to and cross-culling classifies: the clusters of the cut
/// the eye saw last frame (the occlusion history, which this frame's occlusion culling draws
/// first), or the whole cut without one (no occlusion culling, a first frame, after a reset).
///
/// Fitting to the cut would make the light's layers cover everything the eye's frustum holds —
/// behind the walls of an interior, the rest of the plant — and the light-view sets with it (on
/// the 10^8 walk, 2.7 M triangles for a room showing a few thousand). The price is the thesis'
/// one frame of latency (ch. 4, "Limitations"): a cluster that becomes visible this frame
/// outside every layer is lit by the lookup rule until the next frame fits it in. Clusters left
/// out are `Partial` (looked up), so the classes stay conservative.
pub(crate) fn receivers<'a>(
    occlusion: crate::Occlusion,
    state: &crate::occlude::OcclusionState,
    cut: &[(ClusterRef, &'a PageCluster)],
) -> Vec<(ClusterRef, &'a PageCluster)> {
    let history = state.history();
    if occlusion == crate::Occlusion::None || history.is_empty() {
        return cut.to_vec();
    }
    let visible: Vec<_> = cut.iter().filter(|(k, _)| history.contains(k)).copied().collect();
    if visible.is_empty() {
        cut.to_vec()
    } else {
        visible
    }
}

/// Unshadowed shading for the next frames.
pub(crate) fn clear(renderer: &mut Renderer) {
    renderer.set_shadows(None);
}

fn aspect([w, h]: [u32; 2]) -> f32 {
    w.max(1) as f32 / h.max(1) as f32
}

/// The store's bounds in scene space.
fn scene_box(header: &tw_store::Header) -> (Vec3, Vec3) {
    let o = glam::DVec3::from_array(header.grid_origin);
    let lo = (glam::DVec3::from_array(header.bounds_min) - o).as_vec3();
    let hi = (glam::DVec3::from_array(header.bounds_max) - o).as_vec3();
    (lo, hi)
}

fn triangles(clusters: &[(ClusterRef, &PageCluster)]) -> u64 {
    clusters.iter().map(|(_, c)| (c.indices.len() / 3) as u64).sum()
}
