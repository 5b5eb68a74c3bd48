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
//!
//! **Reusing layers.** The scene and the light stand still while the eye moves, so a layer drawn
//! in an earlier frame is still a shadow map of the light for its own matrix. Where this frame's
//! fit can take last frame's layer ([`tw_runtime::shadow::reuse`]: it holds the cascade, its
//! texels are not much wider, same bias) and the layer's casters are still at the eye's level of
//! detail within a quarter of the bias (the clusters that entered and left its light-view set
//! since it was drawn moved the surface by less, [`tw_runtime::shadow::lod_within_bias`]), steps
//! 3 and the read-back of 4 are skipped for it: the map's layer and its depth pyramid serve
//! again. On the 10^8 plant's walk three layers in four are reused; a cascade is drawn again
//! when the eye has moved a few percent of its width or the level of detail of its casters has
//! changed (on a fly-over, every frame).

use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use serde::{Deserialize, Serialize};
use tw_gpu::Renderer;
use tw_runtime::frustum::grid_box;
use tw_runtime::shadow::{
    casters, classify_receivers, fit_layers, light_visible, lod_within_bias, refit_layers, LightDepth,
    ShadowSetStats,
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
    /// Shadow-map layers of the frame (sun cascades or cube faces).
    pub layers: u32,
    /// Of `layers`, those kept from an earlier frame instead of drawn (module documentation,
    /// "Reusing layers"); their triangles are not in `light_drawn_triangles`.
    #[serde(default)]
    pub layers_reused: u32,
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
    /// Drawing the layers (uploads included; waits for the GPU only where the pool must), or
    /// checking that last frame's still serve.
    pub draw: Duration,
    /// Reading the layers back (waits for them to be drawn: on a CPU driver, their rasterization).
    pub readback: Duration,
    /// Building the pyramids and classifying receivers and casters.
    pub classify: Duration,
    /// The whole stage.
    pub total: Duration,
}

/// What the shadow stage keeps from frame to frame (module documentation, "Reusing layers").
#[derive(Default)]
pub(crate) struct ShadowCache {
    /// The map's size and layer count: a map set up anew holds nothing.
    map: Option<(u32, u32)>,
    /// The layers as the map holds them (`None` before the first frame and after a reset).
    shadows: Option<Shadows>,
    /// Per layer of `shadows`: what the map's layer holds.
    layers: Vec<LayerState>,
}

/// What one layer of the shadow map holds.
#[derive(Default)]
struct LayerState {
    /// The light-view set drawn into it: each cluster's simplification error (scene units) and
    /// box centre, for the level-of-detail check of a reuse.
    drawn: HashMap<ClusterRef, (f32, Vec3)>,
    /// The clusters the light saw in it: the first pass of its light occlusion culling when it
    /// is drawn again.
    seen: HashSet<ClusterRef>,
    /// Its depth pyramid, once read back (cross-culling).
    depth: Option<LightDepth>,
    /// Its cross-culling figures, once counted: kept while the layer is reused.
    figures: Option<LayerFigures>,
}

/// A layer's light-view set as cross-culling counts it (the thesis' figures, not the image).
#[derive(Clone, Copy, Debug)]
struct LayerFigures {
    /// Clusters the light sees.
    visible: u64,
    /// Clusters in front of a partly shadowed receiver, and their triangles.
    casters: u64,
    caster_triangles: u64,
}

/// Runs the shadow stage for `camera`'s cut `receivers` (decoded, with their grid boxes from
/// `bounds`) and leaves the renderer set up to shade the eye's pass with shadows; returns the
/// stage's figures and the layers it used. `cache` carries the layers from frame to frame.
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
    cache: &mut ShadowCache,
) -> Result<(ShadowInfo, Shadows), FrameError> {
    let start = Instant::now();
    let mut info = ShadowInfo::default();
    let header = streamer.store().header().clone();
    let step = header.grid_step;
    let boxes: Vec<(Vec3, Vec3)> = receivers
        .iter()
        .map(|(k, _)| bounds(k).map_or((Vec3::ZERO, Vec3::ZERO), |(lo, hi)| grid_box(lo, hi, step)))
        .collect();
    let map = (settings.options.size.max(1), map_layers(&settings.light, &settings.options));
    if cache.map != Some(map) {
        *cache = ShadowCache { map: Some(map), ..Default::default() };
    }
    let (light, aspect, scene) = (&settings.light, aspect(options.viewport), scene_box(&header));
    let (shadows, reusable) = match &cache.shadows {
        Some(previous) => refit_layers(light, camera, aspect, &boxes, scene, &settings.options, previous),
        None => {
            let shadows = fit_layers(light, camera, aspect, &boxes, scene, &settings.options);
            let fresh = vec![false; shadows.layers.len()];
            (shadows, fresh)
        }
    };
    info.fit = start.elapsed();
    info.layers = shadows.layers.len() as u32;
    renderer.set_shadows(None);
    if shadows.layers.is_empty() {
        *cache = ShadowCache { map: cache.map, ..Default::default() };
        info.total = start.elapsed();
        return Ok((info, shadows));
    }
    renderer.set_shadow_map(map.0, map.1)?;
    cache.layers.resize_with(shadows.layers.len(), LayerState::default);
    let mut light_sets: Vec<LightSet> = Vec::with_capacity(shadows.layers.len());
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
        let state = &mut cache.layers[i];
        let bias_texels = settings.options.bias_texels;
        if reusable[i] && still_serves(&shadows, i, bias_texels, &set, &set_boxes, &state.drawn) {
            info.layers_reused += 1;
        } else {
            *state = draw_layer_culled(
                &mut info,
                renderer,
                &shadows,
                i,
                camera,
                step,
                &set,
                &set_boxes,
                &state.seen,
            )?;
        }
        info.draw += t.elapsed();
        if settings.cross_culling {
            light_sets.push(set_boxes);
        }
    }
    cache.shadows = Some(shadows.clone());
    if settings.cross_culling {
        let layers = &mut cache.layers;
        cross_cull(&mut info, renderer, &shadows, camera, (receivers, &boxes), &light_sets, layers)?;
    } else {
        info.sets.receivers_partial = receivers.len() as u64;
        info.sets.triangles_partial = triangles(receivers);
    }
    renderer.set_shadows(Some(&shadows));
    info.total = start.elapsed();
    Ok((info, shadows))
}

/// The layers the map is allocated with: as many as the light can ever need, so that a frame
/// needing fewer or more cascades keeps the map (and the layers it can reuse).
fn map_layers(light: &Light, options: &ShadowOptions) -> u32 {
    match light {
        Light::Sun { .. } => options.cascades,
        Light::Point { .. } => tw_gpu::MAX_SHADOW_LAYERS,
    }
}

/// Whether layer `layer`, drawn in an earlier frame from the light-view set `drawn`, serves for
/// this frame's set `set` (with its boxes `set_boxes`): the clusters that left and entered the
/// set since moved the casters' surface within the bias' share for level of detail.
fn still_serves(
    shadows: &Shadows,
    layer: usize,
    bias_texels: f32,
    set: &[(ClusterRef, &PageCluster)],
    set_boxes: &[((Vec3, Vec3), u64)],
    drawn: &HashMap<ClusterRef, (f32, Vec3)>,
) -> bool {
    let keys: HashSet<ClusterRef> = set.iter().map(|(k, _)| *k).collect();
    let (mut entered, mut left) = (0f32, 0f32);
    let (mut entering, mut leaving) = (0, 0);
    let mut changed = Vec::new();
    for ((k, c), ((lo, hi), _)) in set.iter().zip(set_boxes) {
        if !drawn.contains_key(k) {
            entered = entered.max(c.self_error);
            entering += 1;
            changed.push((*lo + *hi) * 0.5);
        }
    }
    for (k, &(error, centre)) in drawn {
        if !keys.contains(k) {
            left = left.max(error);
            leaving += 1;
            changed.push(centre);
        }
    }
    // The eye's cut covers the scene once at some level, so within a layer's unchanged frustum
    // clusters enter only as others leave (a level for another). One without the other is a
    // caster that came or went (a page that arrived with nothing drawn for it before): drawn.
    if (entering == 0) != (leaving == 0) {
        return false;
    }
    // Where the texels are narrowest: for a point light, nearest the light.
    let at = match shadows.light {
        Light::Point { position } => {
            changed.iter().copied().min_by(|a, b| a.distance(position).total_cmp(&b.distance(position)))
        }
        Light::Sun { .. } => changed.first().copied(),
    };
    lod_within_bias(shadows, layer, bias_texels, entered + left, at.unwrap_or(Vec3::ZERO))
}

/// Steps 2–4 of the thesis' cross-culling against the layers' depth pyramids (read back now
/// where `layers` has none): the receivers' classes (handed to the renderer), then per layer the
/// light-visible clusters and the casters — counted once per drawing of a layer: a reused layer
/// keeps the figures of the frame that drew it (they are figures, the image does not use them).
fn cross_cull(
    info: &mut ShadowInfo,
    renderer: &mut Renderer,
    shadows: &Shadows,
    camera: &Camera,
    (receivers, boxes): (&[Decoded<'_>], &[(Vec3, Vec3)]),
    light_sets: &[LightSet],
    layers: &mut [LayerState],
) -> Result<(), FrameError> {
    let mut depths = Vec::with_capacity(shadows.layers.len());
    for (i, state) in layers.iter_mut().enumerate().take(shadows.layers.len()) {
        let depth = match state.depth.take() {
            Some(depth) => depth,
            None => {
                let t = Instant::now();
                let texels = renderer.read_shadow_map(i as u32)?;
                info.readback += t.elapsed();
                let t = Instant::now();
                let depth = LightDepth::new(&texels, shadows.size)?;
                info.classify += t.elapsed();
                depth
            }
        };
        depths.push(depth);
    }
    let t = Instant::now();
    let classes = classify_receivers(shadows, &depths, camera, boxes);
    let mut sets = ShadowSetStats::default();
    let receiver_triangles: Vec<u32> = receivers.iter().map(|(_, c)| (c.indices.len() / 3) as u32).collect();
    sets.add_receivers(&classes, &receiver_triangles);
    for (i, set) in light_sets.iter().enumerate() {
        let figures = *layers[i].figures.get_or_insert_with(|| {
            let set_boxes: Vec<(Vec3, Vec3)> = set.iter().map(|(b, _)| *b).collect();
            let visible = light_visible(shadows, i, &depths[i], camera, &set_boxes);
            let casters = casters(shadows, i, camera, boxes, &classes, &set_boxes, &visible);
            let count = |flags: &[bool]| flags.iter().filter(|&&f| f).count() as u64;
            let caster_triangles =
                set.iter().zip(&casters).filter(|(_, &c)| c).map(|((_, tris), _)| tris).sum::<u64>();
            LayerFigures { visible: count(&visible), casters: count(&casters), caster_triangles }
        });
        sets.light_cut += set.len() as u64;
        sets.light_visible += figures.visible;
        sets.casters += figures.casters;
        info.caster_triangles += figures.caster_triangles;
    }
    info.sets = sets;
    let keyed: Vec<(ClusterRef, ShadowClass)> = receivers.iter().map(|(k, _)| *k).zip(classes).collect();
    renderer.set_shadow_classes(&keyed);
    for (state, depth) in layers.iter_mut().zip(depths) {
        state.depth = Some(depth);
    }
    info.classify += t.elapsed();
    Ok(())
}

/// A decoded cluster of a cut.
type Decoded<'a> = (ClusterRef, &'a PageCluster);

/// A layer's light-view set for cross-culling: its clusters' boxes and triangles.
type LightSet = Vec<((Vec3, Vec3), u64)>;

/// Draws layer `layer`'s light-view set `set` with occlusion culling from the light, two-pass
/// as the eye's hzb (crate::occlude): the clusters the light saw when the layer was last drawn
/// (`seen`) first, then the layer is read back and every cluster is tested against it (a box
/// entirely behind the map's farthest depth over its footprint is hidden, [`light_visible`]);
/// the visible others are drawn on top. The map is the one drawing the whole set would give,
/// without drawing what the light cannot see: from inside the 10^8 plant, the floors and roof
/// above a room (a light-view set of 0.4–0.5 M triangles of which ~35 k are drawn). Returns what
/// the layer now holds: the set, the clusters the light sees (the visible others and the first
/// pass's clusters still visible) and, when the second pass drew nothing, the first pass's depth
/// pyramid, which is then the layer's. Without a history the whole set is drawn and tested once.
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
    seen: &HashSet<ClusterRef>,
) -> Result<LayerState, FrameError> {
    let view_proj = &shadows.layers[layer].view_proj;
    let (first, rest): (Vec<usize>, Vec<usize>) = if seen.is_empty() {
        ((0..set.len()).collect(), Vec::new())
    } else {
        (0..set.len()).partition(|&i| seen.contains(&set[i].0))
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
    let drawn = set
        .iter()
        .zip(set_boxes)
        .map(|((k, c), ((lo, hi), _))| (*k, (c.self_error, (*lo + *hi) * 0.5)))
        .collect();
    let seen = first.iter().chain(&shown).filter(|&&i| visible[i]).map(|&i| set[i].0).collect();
    Ok(LayerState { drawn, seen, depth: second.is_empty().then_some(depth), figures: None })
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

#[cfg(test)]
mod tests {
    use super::*;

    fn cluster(error: f32) -> PageCluster {
        PageCluster {
            positions: vec![[0, 0, 0], [1, 0, 0], [0, 1, 0]],
            indices: vec![0, 1, 2],
            objects: vec![0],
            self_error: error,
            self_sphere: [0.0, 0.0, 0.0, 1.0],
            group: 0,
            level: 0,
        }
    }

    fn key(page: u32) -> ClusterRef {
        ClusterRef { page, index_in_page: 0, group: 0 }
    }

    /// A sun layer with texels of 1/1024 scene units over a 2-unit window.
    fn shadows() -> Shadows {
        let layer = tw_runtime::ShadowLayer {
            view_proj: glam::Mat4::from_scale(Vec3::new(1.0, 1.0, 0.01)),
            split: [0.0, f32::MAX],
        };
        Shadows { light: Light::Sun { towards: Vec3::Z }, layers: vec![layer], size: 1024, bias: 1e-3 }
    }

    #[test]
    fn a_layer_serves_while_levels_swap_within_the_slack_and_not_when_a_caster_comes_or_goes() {
        let s = shadows();
        let texel = tw_runtime::shadow::texel_size(&s, 0).unwrap();
        let small = 0.1 * tw_runtime::shadow::reuse::LOD_SHARE * 1.5 * texel;
        let (a, b, c) = (cluster(small), cluster(0.0), cluster(0.0));
        let boxes = |n: usize| vec![((Vec3::ZERO, Vec3::ONE), 1u64); n];
        let drawn: HashMap<ClusterRef, (f32, Vec3)> =
            [(key(1), (small, Vec3::ZERO)), (key(2), (0.0, Vec3::ZERO))].into_iter().collect();
        // The same set: serves.
        assert!(still_serves(&s, 0, 1.5, &[(key(1), &a), (key(2), &b)], &boxes(2), &drawn));
        // Cluster 1 swapped for its children (3): the surface moved by at most `small`.
        assert!(still_serves(&s, 0, 1.5, &[(key(3), &c), (key(2), &b)], &boxes(2), &drawn));
        // A swap by more than the slack: drawn again.
        let coarse = cluster(10.0 * texel);
        assert!(!still_serves(&s, 0, 1.5, &[(key(4), &coarse), (key(2), &b)], &boxes(2), &drawn));
        // A caster of error 0 appears with nothing leaving, or one goes: drawn again.
        assert!(!still_serves(&s, 0, 1.5, &[(key(1), &a), (key(2), &b), (key(3), &c)], &boxes(3), &drawn));
        assert!(!still_serves(&s, 0, 1.5, &[(key(1), &a)], &boxes(1), &drawn));
    }
}
