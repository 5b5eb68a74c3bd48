//! The shadow stage of a frame (Govindaraju's thesis ch. 4; docs/RUNTIME.md "Shadows"): after the
//! eye's LOD cut is known and before it is drawn,
//! 1. **layers**: the light's shadow-map layers are fitted to the cut's boxes (the receivers):
//!    sun cascades along the eye's depth, or the faces of a cube around a point light
//!    ([`tw_runtime::shadow::fit_layers`]);
//! 2. **light-view sets**: per layer, the clusters that can cast into it — the eye's LOD cut
//!    (the thesis' LOD consistency: the eye's level for every cluster, so that a surface is never
//!    shadowed by a coarser copy of itself; or, with [`ShadowLod::Finer`], the finer of the eye's
//!    and the light's level, in both views alike) culled by the layer's frustum instead of the eye's,
//!    streamed under the same memory budget ([`tw_runtime::Streamer::select_light`]);
//! 3. **shadow map**: each layer's set drawn depth-only into its layer, occlusion culled from the
//!    light two-pass (what the light saw last frame first, the rest tested against it);
//! 4. **cross-culling** (optional, on by default): the layers are read back, and each receiver is
//!    classified against them by the lookup rule of [`tw_runtime::shadow`] as fully lit, fully
//!    shadowed or partly shadowed (the thesis' steps 2 and 3, against a min/max pyramid of the
//!    light's depth instead of occlusion queries); the light-visible clusters and the casters
//!    (those in front of a partly shadowed receiver, step 4) are counted. Only partly shadowed
//!    receivers look the map up when the eye's pass draws them; the classes follow the lookup
//!    rule conservatively, so the image is the same with or without cross-culling. **Finer
//!    classes:** the partly shadowed receivers that can cover the most pixels are classified
//!    again by subobjects of 8 triangles ([`tw_runtime::shadow::subobjects`]), and the renderer
//!    draws their lit and shadowed triangles without lookups.
//!
//! The eye's pass then draws as without shadows ([`crate::occlude::draw_culled`]), the renderer
//! shading each cluster by its class.
//!
//! **Reusing layers.** The scene and the light stand still while the eye moves, so a layer drawn
//! in an earlier frame is still a shadow map of the light for its own matrix. Where this frame's
//! fit can take last frame's layer ([`tw_runtime::shadow::reuse`]: it holds the cascade, its
//! texels are not much wider, same bias) and the layer's casters are still at the eye's level of
//! detail within a quarter of the bias (the clusters that entered and left its light-view set
//! since it was drawn moved the surface by less, [`tw_runtime::shadow::lod_within_bias`]; or the
//! swaps cannot have changed the map, see `still_serves`), steps 3 and the read-back of 4 are
//! skipped for it: the map's layer and its depth pyramid serve again. On the 10^8 plant's walk
//! 9 layers in 10 are reused; a cascade is drawn again when the eye has moved a few percent of
//! its width or the level of detail of casters it sees has changed (on a fly-over, every
//! frame).

use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use serde::{Deserialize, Serialize};
use tw_gpu::Renderer;
use tw_runtime::frustum::{grid_box, Containment, Frustum};
use tw_runtime::shadow::{
    casters, classify_receivers, classify_subobjects_cut, fit_layers, light_visible, lod_within_bias,
    refit_layers, LightDepth, ShadowSetStats, TriangleClasses,
};
use tw_runtime::{Camera, ClusterRef, Light, ResidentPage, SelectOptions, ShadowClass, Shadows, Streamer};
use tw_store::PageCluster;

use crate::{lookup, page_bounds, resident_pages, triangles, FrameError};
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
    /// The level of detail of both views (`--shadow-lod`): the eye's (the default) or the finer
    /// of the eye's and the light's.
    pub lod: ShadowLod,
}

/// The LOD policy of a shadowed frame (Govindaraju's thesis §4.2.1): both keep each cluster at
/// one level in the eye's and the light's views, so a surface is never shadowed by a coarser
/// copy of itself.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ShadowLod {
    /// The eye's LOD everywhere (method 2): the fewest triangles, and shadows that change only
    /// when the eye's cut does; a coarse object near the light casts a coarse shadow.
    #[default]
    Eye,
    /// The finer of the eye's and the light's LOD (method 1, after Lloyd): a cluster is fine
    /// enough when its error is at most τ pixels from the eye and τ texels in the shadow map
    /// (src/shadow/light_lod.rs in tw-runtime), in both views; more triangles, and levels that
    /// change when the light moves.
    Finer,
}

impl ShadowLod {
    /// `eye` or `finer` (the `--shadow-lod` values).
    pub fn parse(s: &str) -> Option<ShadowLod> {
        match s.to_ascii_lowercase().as_str() {
            "eye" => Some(ShadowLod::Eye),
            "finer" => Some(ShadowLod::Finer),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            ShadowLod::Eye => "eye",
            ShadowLod::Finer => "finer",
        }
    }
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
    /// Partly shadowed receivers refined to subobjects of a few triangles (step 4, "Finer
    /// classes"), and of their triangles those found lit and shadowed: drawn without lookups.
    #[serde(default)]
    pub refined_receivers: u64,
    #[serde(default)]
    pub refined_lit_triangles: u64,
    #[serde(default)]
    pub refined_shadowed_triangles: u64,
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
    /// The light-view set drawn into it, for the level-of-detail check of a reuse.
    drawn: HashMap<ClusterRef, DrawnCluster>,
    /// The clusters the light saw in it: the first pass of its light occlusion culling when it
    /// is drawn again.
    seen: HashSet<ClusterRef>,
    /// Its depth pyramid, once read back (cross-culling).
    depth: Option<LightDepth>,
    /// Its cross-culling figures, once counted: kept while the layer is reused.
    figures: Option<LayerFigures>,
}

/// A cluster of a layer's light-view set as it was drawn: its simplification error (scene
/// units) and box.
#[derive(Clone, Copy, Debug)]
struct DrawnCluster {
    error: f32,
    lo: Vec3,
    hi: Vec3,
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
    let aspect = aspect(options.viewport);
    let boxes = receiver_boxes(receivers, &bounds, step);
    let map = (settings.options.size.max(1), map_layers(&settings.light, &settings.options));
    if cache.map != Some(map) {
        *cache = ShadowCache { map: Some(map), ..Default::default() };
    }
    let (light, scene) = (&settings.light, scene_box(&header));
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
    let context = LayerContext {
        shadows: &shadows,
        camera,
        eye: Frustum::from_view_projection(&camera.view_projection(aspect)),
        options,
        wait_for_pages,
        bias_texels: settings.options.bias_texels,
        grid_step: step,
    };
    let mut light_sets: Vec<LightSet> = Vec::with_capacity(shadows.layers.len());
    for (i, state) in cache.layers.iter_mut().enumerate() {
        let set_boxes = update_layer(&context, i, reusable[i], (streamer, renderer), state, &mut info)?;
        if settings.cross_culling {
            light_sets.push(set_boxes);
        }
    }
    cache.shadows = Some(shadows.clone());
    if settings.cross_culling {
        let layers = &mut cache.layers;
        let view = ReceiverView {
            view_proj: camera.view_projection(aspect),
            viewport: options.viewport,
            grid_step: step,
        };
        let cut = in_view(&view.view_proj, boxes);
        let receivers = (receivers, &cut[..], view);
        cross_cull(&mut info, renderer, &shadows, camera, receivers, &light_sets, layers)?;
    } else {
        info.sets.receivers_partial = receivers.len() as u64;
        info.sets.triangles_partial = triangles(receivers);
    }
    renderer.set_shadows(Some(&shadows));
    info.total = start.elapsed();
    Ok((info, shadows))
}

/// The receivers' boxes (or their subobjects') cut to the eye's view `view_proj`, for
/// cross-culling: each box replaced by the bounding box of its part inside the view frustum (its
/// planes widened by a hair against rounding; [`tw_runtime::shadow::clip`]), a box with no part
/// inside kept whole. The
/// eye's pass shades a receiver only inside the frustum, so a class found for the cut box is the
/// class of every fragment drawn: the image is the same. What a box loses is what it held out of
/// view — on a walk, the floor cluster under the eye reaches behind it, a wall cluster beyond
/// the view's side — where a texel the light reaches made an otherwise fully shadowed receiver
/// partly shadowed, looked up per fragment (on the 10^8 walk, half the partly shadowed
/// triangles). The layers are still fitted to the whole boxes: fitted to the cut ones, the
/// splits move out with the nearest receiver and the light-view sets grow by an eighth.
fn in_view(view_proj: &glam::Mat4, boxes: Vec<(Vec3, Vec3)>) -> Vec<(Vec3, Vec3)> {
    use rayon::prelude::*;
    let planes = Frustum::from_view_projection(view_proj)
        .planes
        .map(|p| p + glam::Vec4::new(0.0, 0.0, 0.0, 1e-4 * (1.0 + p.w.abs())));
    if !planes.iter().all(|p| p.is_finite()) {
        return boxes;
    }
    let cut = |points: &mut Vec<Vec3>, (lo, hi): (Vec3, Vec3)| {
        tw_runtime::shadow::clip::clip_box(lo, hi, &planes, points);
        if points.is_empty() {
            return (lo, hi);
        }
        let (a, b) =
            points.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), &p| (a.min(p), b.max(p)));
        // Never outside the box itself (the points of a cut lie on its faces, up to rounding).
        let (a, b) = (a.max(lo), b.min(hi));
        if a.cmple(b).all() {
            (a, b)
        } else {
            (lo, hi)
        }
    };
    // A box in view costs a fraction of a microsecond: a walk's few hundred are cut on this
    // thread (handing them to the pool costs more), a fly-over's thousands on all.
    if boxes.len() < 4096 {
        let mut points = Vec::new();
        boxes.into_iter().map(|b| cut(&mut points, b)).collect()
    } else {
        boxes.into_par_iter().map_init(Vec::new, cut).collect()
    }
}

/// What every layer of a frame's shadow stage is selected and checked with.
struct LayerContext<'a> {
    shadows: &'a Shadows,
    camera: &'a Camera,
    /// The eye's frustum (`still_serves`).
    eye: Frustum,
    options: &'a SelectOptions,
    wait_for_pages: bool,
    bias_texels: f32,
    grid_step: f64,
}

/// Layer `i` of a frame: selects its light-view set, then keeps the map's layer where it still
/// serves (`reusable`: this frame's fit kept its matrix; [`still_serves`]) or draws it again.
/// Returns the set's boxes for cross-culling.
fn update_layer(
    context: &LayerContext<'_>,
    i: usize,
    reusable: bool,
    (streamer, renderer): (&mut Streamer, &mut Renderer),
    state: &mut LayerState,
    info: &mut ShadowInfo,
) -> Result<LightSet, FrameError> {
    let LayerContext { shadows, camera, options, grid_step, .. } = *context;
    let view_proj = &shadows.layers[i].view_proj;
    let t = Instant::now();
    let (selection, pages) = if context.wait_for_pages {
        let selection = streamer.select_light_blocking(camera, view_proj, options);
        let pages = resident_pages(streamer, &selection.clusters);
        (selection, pages)
    } else {
        streamer.select_light(camera, view_proj, options)
    };
    info.select += t.elapsed();
    let t = Instant::now();
    let set = lookup(&pages, &selection.clusters);
    info.sets.light_cut += set.len() as u64;
    info.light_triangles += triangles(&set);
    let set_boxes = light_boxes(&set, &pages, grid_step);
    let eye = (camera, &context.eye);
    if reusable && still_serves(shadows, i, context.bias_texels, eye, (&set, &set_boxes), state) {
        info.layers_reused += 1;
    } else {
        let why = if reusable { "its casters' level of detail changed" } else { "the fit moved" };
        tracing::debug!("shadow layer {i} drawn again: {why}");
        *state =
            draw_layer_culled(info, renderer, shadows, i, camera, grid_step, &set, &set_boxes, &state.seen)?;
    }
    info.draw += t.elapsed();
    Ok(set_boxes)
}

/// The layers the map is allocated with: as many as the light can ever need, so that a frame
/// needing fewer or more cascades keeps the map (and the layers it can reuse).
fn map_layers(light: &Light, options: &ShadowOptions) -> u32 {
    match light {
        Light::Sun { .. } => options.cascades,
        Light::Point { .. } => tw_gpu::MAX_SHADOW_LAYERS,
    }
}

/// Whether layer `layer`, drawn in an earlier frame (`drawn`), serves for this frame's set `set`
/// (with its boxes `set_boxes`) seen from `camera` (and its frustum).
///
/// A cluster that entered or left the set with no other doing the opposite is a caster that
/// came or went: the layer is drawn again. Otherwise levels swapped, and
/// 1. when none of the clusters that left was seen by the light and each that entered lies
///    behind the layer's depth over its footprint, drawing the layer again would give the same
///    map: it serves (on the 10^8 walk, the interiors under the far cascade's roofs swap levels
///    every few frames as the eye moves);
/// 2. else the swaps that matter are those the eye can see: a surface drawn by the eye at one
///    level and held by the map at another shadows itself falsely unless they are within the
///    bias' share for level of detail (the thesis' LOD consistency). A cluster entirely outside
///    the eye's frustum is not drawn by the eye, so its swap only moves its shadow by its own
///    simplification error — which a map drawn afresh at the eye's level has too, against the
///    full-detail caster — and is not counted.
fn still_serves(
    shadows: &Shadows,
    layer: usize,
    bias_texels: f32,
    (camera, eye): (&Camera, &Frustum),
    (set, set_boxes): (&[Decoded<'_>], &[LightBox]),
    drawn: &LayerState,
) -> bool {
    let keys: HashSet<ClusterRef> = set.iter().map(|(k, _)| *k).collect();
    let entered: Vec<usize> = (0..set.len()).filter(|&i| !drawn.drawn.contains_key(&set[i].0)).collect();
    let left: Vec<(&ClusterRef, &DrawnCluster)> =
        drawn.drawn.iter().filter(|(k, _)| !keys.contains(k)).collect();
    // The eye's cut covers the scene once at some level, so within a layer's unchanged frustum
    // clusters enter only as others leave (a level for another). One without the other is a
    // caster that came or went (a page that arrived with nothing drawn for it before): drawn.
    if entered.is_empty() != left.is_empty() {
        tracing::debug!(
            "shadow layer {layer}: {} clusters entered its set, {} left",
            entered.len(),
            left.len()
        );
        return false;
    }
    if entered.is_empty()
        || swaps_unseen_by_the_light(shadows, layer, camera, drawn, &entered, set_boxes, &left)
    {
        return true;
    }
    let seen = |lo: Vec3, hi: Vec3| eye.test_aabb(lo, hi) != Containment::Outside;
    let (mut entered_error, mut left_error) = (0f32, 0f32);
    let mut changed = Vec::new();
    for &i in &entered {
        let (lo, hi) = set_boxes[i].0;
        if seen(lo, hi) {
            entered_error = entered_error.max(set[i].1.self_error);
            changed.push((lo + hi) * 0.5);
        }
    }
    for (_, d) in &left {
        if seen(d.lo, d.hi) {
            left_error = left_error.max(d.error);
            changed.push((d.lo + d.hi) * 0.5);
        }
    }
    tracing::debug!(
        "shadow layer {layer}: levels swapped in view, error {} scene units",
        entered_error + left_error
    );
    // Where the texels are narrowest: for a point light, nearest the light.
    let at = match shadows.light {
        Light::Point { position } => {
            changed.iter().copied().min_by(|a, b| a.distance(position).total_cmp(&b.distance(position)))
        }
        Light::Sun { .. } => changed.first().copied(),
    };
    lod_within_bias(shadows, layer, bias_texels, entered_error + left_error, at.unwrap_or(Vec3::ZERO))
}

/// Whether layer `layer`'s map is what drawing its set again would give after the swaps
/// (`entered`: indices into `set_boxes`; `left`): no cluster that left wrote a texel of it (the
/// light did not see it when the layer was drawn), and each that entered lies behind its depth
/// over its footprint (it would write none). Unknown without the layer's depth pyramid.
fn swaps_unseen_by_the_light(
    shadows: &Shadows,
    layer: usize,
    camera: &Camera,
    drawn: &LayerState,
    entered: &[usize],
    set_boxes: &[LightBox],
    left: &[(&ClusterRef, &DrawnCluster)],
) -> bool {
    let Some(depth) = &drawn.depth else { return false };
    if left.iter().any(|(k, _)| drawn.seen.contains(k)) {
        return false;
    }
    let boxes: Vec<(Vec3, Vec3)> = entered.iter().map(|&i| set_boxes[i].0).collect();
    !light_visible(shadows, layer, depth, camera, &boxes).contains(&true)
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
    (receivers, boxes, view): (&[Decoded<'_>], &[(Vec3, Vec3)], ReceiverView),
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
    if renderer.refines_shadow_classes() {
        let refined = refine_partial(info, shadows, &depths, camera, receivers, boxes, &keyed, view);
        renderer.set_shadow_triangle_classes(&refined);
    }
    for (state, depth) in layers.iter_mut().zip(depths) {
        state.depth = Some(depth);
    }
    info.classify += t.elapsed();
    Ok(())
}

/// A decoded cluster of a cut.
type Decoded<'a> = (ClusterRef, &'a PageCluster);

/// Screen pixels a partly shadowed receiver must be able to cover (its box's projection) to be
/// refined. On the 10^8 walk (lavapipe) refining the 32 largest from 4,096 pixels saved ~2 ms
/// of lookups for ~1.6 ms of classification; refining up to 256 from 1,024 pixels saved no
/// more lookups (the rest are truly partial: large triangles across a shadow edge) for twice
/// the classification (docs/benchmarks-log.md).
const REFINE_MIN_PIXELS: f32 = 4096.0;

/// The most receivers refined in a frame, the largest on screen first: bounds the stage's cost
/// where a wide view holds thousands of partly shadowed clusters (a fly-over).
const REFINE_MAX_RECEIVERS: usize = 32;

/// How the receivers are seen and placed: the eye's view-projection, the viewport in pixels,
/// and the store's grid step (cluster positions are grid coordinates).
#[derive(Clone, Copy)]
struct ReceiverView {
    view_proj: glam::Mat4,
    viewport: [u32; 2],
    grid_step: f64,
}

/// Finer classes (thesis ch. 4, subobjects of k triangles): the partly shadowed receivers that
/// can cover the most pixels are cut into subobjects of [`tw_runtime::shadow::SUBOBJECT_TRIANGLES`]
/// and classified again, so that their lit and shadowed triangles are drawn without lookups.
#[allow(clippy::too_many_arguments)]
fn refine_partial(
    info: &mut ShadowInfo,
    shadows: &Shadows,
    depths: &[LightDepth],
    camera: &Camera,
    receivers: &[Decoded<'_>],
    boxes: &[(Vec3, Vec3)],
    classes: &[(ClusterRef, ShadowClass)],
    view: ReceiverView,
) -> Vec<(ClusterRef, TriangleClasses)> {
    let mut candidates: Vec<(f32, usize)> = classes
        .iter()
        .enumerate()
        .filter(|(_, (_, class))| *class == ShadowClass::Partial)
        .map(|(i, _)| (screen_pixels(&view, boxes[i]), i))
        .filter(|&(pixels, _)| pixels >= REFINE_MIN_PIXELS)
        .collect();
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    candidates.truncate(REFINE_MAX_RECEIVERS);
    let clusters: Vec<&PageCluster> = candidates.iter().map(|&(_, i)| receivers[i].1).collect();
    let cut = |boxes| in_view(&view.view_proj, boxes);
    let refined = classify_subobjects_cut(shadows, depths, camera, &clusters, view.grid_step, cut);
    let mut out = Vec::with_capacity(refined.len());
    for (&(_, i), triangles) in candidates.iter().zip(refined) {
        if triangles.refines() {
            info.refined_receivers += 1;
            info.refined_lit_triangles += triangles.lit.count_ones() as u64;
            info.refined_shadowed_triangles += triangles.shadowed.count_ones() as u64;
            out.push((receivers[i].0, triangles));
        }
    }
    tracing::debug!(
        "shadow subobjects: {} of {} candidates refined, {} lit and {} shadowed triangles without lookups",
        out.len(),
        candidates.len(),
        info.refined_lit_triangles,
        info.refined_shadowed_triangles
    );
    out
}

/// The pixels of `view`'s viewport that the screen rectangle of box `(lo, hi)` covers; a box
/// reaching behind the eye counts as the whole viewport.
fn screen_pixels(view: &ReceiverView, (lo, hi): (Vec3, Vec3)) -> f32 {
    let [w, h] = view.viewport.map(|v| v as f32);
    let (mut x0, mut y0, mut x1, mut y1) =
        (f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY);
    for p in tw_runtime::shadow::clip::corners(lo, hi) {
        let c = view.view_proj * p.extend(1.0);
        if !c.is_finite() || c.w <= 0.0 {
            return w * h;
        }
        let (x, y) = (c.x / c.w, c.y / c.w);
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    let span = |a: f32, b: f32, size: f32| ((b.min(1.0) - a.max(-1.0)).max(0.0)) * 0.5 * size;
    span(x0, x1, w) * span(y0, y1, h)
}

/// A layer's light-view set for cross-culling: its clusters' boxes and triangles.
type LightSet = Vec<LightBox>;

/// A light-view cluster's box (scene space) and triangles.
type LightBox = ((Vec3, Vec3), u64);

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
    set_boxes: &[LightBox],
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
        .map(|((k, c), &((lo, hi), _))| (*k, DrawnCluster { error: c.self_error, lo, hi }))
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

/// The scene-space boxes of `receivers` (from their grid boxes, `bounds`).
fn receiver_boxes(
    receivers: &[(ClusterRef, &PageCluster)],
    bounds: impl Fn(&ClusterRef) -> Option<([u32; 3], [u32; 3])>,
    step: f64,
) -> Vec<(Vec3, Vec3)> {
    receivers
        .iter()
        .map(|(k, _)| bounds(k).map_or((Vec3::ZERO, Vec3::ZERO), |(lo, hi)| grid_box(lo, hi, step)))
        .collect()
}

/// Layers fitted to the whole cut `cut` of `camera` (a frame's first, before any was drawn):
/// what [`ShadowLod::Finer`] measures the light's texels in until a frame has drawn its own.
pub(crate) fn fit_to_cut(
    settings: &ShadowSettings,
    header: &tw_store::Header,
    camera: &Camera,
    viewport: [u32; 2],
    cut: &[(ClusterRef, &PageCluster)],
    bounds: impl Fn(&ClusterRef) -> Option<([u32; 3], [u32; 3])>,
) -> Shadows {
    let boxes = receiver_boxes(cut, &bounds, header.grid_step);
    fit_layers(&settings.light, camera, aspect(viewport), &boxes, scene_box(header), &settings.options)
}

/// Unshadowed shading for the next frames.
pub(crate) fn clear(renderer: &mut Renderer) {
    renderer.set_shadows(None);
}

fn aspect([w, h]: [u32; 2]) -> f32 {
    w.max(1) as f32 / h.max(1) as f32
}

/// The store's bounds in scene space.
pub fn scene_box(header: &tw_store::Header) -> (Vec3, Vec3) {
    let o = glam::DVec3::from_array(header.grid_origin);
    let lo = (glam::DVec3::from_array(header.bounds_min) - o).as_vec3();
    let hi = (glam::DVec3::from_array(header.bounds_max) - o).as_vec3();
    (lo, hi)
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

    /// An eye above the unit box looking down at it, and one looking away from it.
    fn eyes() -> (Camera, Camera) {
        let at = |target: Vec3| {
            Camera::new(Vec3::new(0.5, 0.5, 80.0), target, Vec3::Y, 60f32.to_radians(), 0.1, 1000.0)
                .expect("a valid camera")
        };
        (at(Vec3::new(0.5, 0.5, 0.0)), at(Vec3::new(0.5, 0.5, 200.0)))
    }

    /// What a layer holds: `drawn` clusters, of which the light saw `seen`, and a map of depth 0
    /// (everything nearer than depth 0 is hidden behind it: every box here).
    fn layer(drawn: &[(ClusterRef, DrawnCluster)], seen: &[ClusterRef], with_depth: bool) -> LayerState {
        LayerState {
            drawn: drawn.iter().copied().collect(),
            seen: seen.iter().copied().collect(),
            depth: with_depth.then(|| LightDepth::new(&vec![0.0; 1024 * 1024], 1024).expect("a depth map")),
            figures: None,
        }
    }

    fn serves(
        s: &Shadows,
        camera: &Camera,
        set: &[(ClusterRef, &PageCluster)],
        boxes: &[(Vec3, Vec3)],
        state: &LayerState,
    ) -> bool {
        let eye = Frustum::from_view_projection(&camera.view_projection(1.0));
        let set_boxes: Vec<((Vec3, Vec3), u64)> = boxes.iter().map(|&b| (b, 1)).collect();
        still_serves(s, 0, 1.5, (camera, &eye), (set, &set_boxes), state)
    }

    #[test]
    fn receiver_boxes_are_cut_to_the_part_the_eye_can_see() {
        // The eye at (0.5, 0.5, 80) looking down at the origin, a 60° view.
        let (eye, _) = eyes();
        let view_proj = eye.view_projection(1.0);
        let frustum = Frustum::from_view_projection(&view_proj);
        // A floor far wider than the view, a box inside it, one behind the eye, one beside.
        let floor = (Vec3::new(-500.0, -500.0, -1.0), Vec3::new(500.0, 500.0, 0.0));
        let inside = (Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 1.0));
        let behind = (Vec3::new(0.0, 0.0, 90.0), Vec3::new(1.0, 1.0, 91.0));
        let across = (Vec3::new(20.0, -5.0, 0.0), Vec3::new(400.0, 5.0, 1.0));
        let cut = in_view(&view_proj, vec![floor, inside, behind, across]);
        assert_eq!(cut[1], inside, "a box in view is kept");
        assert_eq!(cut[2], behind, "a box out of view is kept whole");
        // The floor's cut: within the floor, no wider than the view's footprint at z = 0 (±47 at
        // 80 units with a 60° view) with a hair of slack.
        assert!(cut[0].0.cmpge(floor.0).all() && cut[0].1.cmple(floor.1).all());
        assert!(
            cut[0].0.x > -50.0 && cut[0].1.x < 50.0 && cut[0].0.y > -50.0 && cut[0].1.y < 50.0,
            "{cut:?}"
        );
        assert!(cut[3].1.x < 60.0 && cut[3].0.x == 20.0, "{cut:?}");
        // Every point of a box in view is in its cut box.
        for (i, &(lo, hi)) in [floor, across].iter().enumerate() {
            let (a, b) = cut[[0, 3][i]];
            for ix in 0..=40 {
                for iy in 0..=40 {
                    for z in [lo.z, hi.z] {
                        let t = Vec3::new(ix as f32 / 40.0, iy as f32 / 40.0, 0.0);
                        let p = Vec3::new(lo.x + t.x * (hi.x - lo.x), lo.y + t.y * (hi.y - lo.y), z);
                        if frustum.test_aabb(p, p) != Containment::Outside {
                            assert!(p.cmpge(a).all() && p.cmple(b).all(), "{p} in view, not in {a}..{b}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn a_layer_serves_while_levels_swap_within_the_slack_and_not_when_a_caster_comes_or_goes() {
        let s = shadows();
        let texel = tw_runtime::shadow::texel_size(&s, 0).unwrap();
        let small = 0.1 * tw_runtime::shadow::reuse::LOD_SHARE * 1.5 * texel;
        let (a, b, c) = (cluster(small), cluster(0.0), cluster(0.0));
        let unit = (Vec3::ZERO, Vec3::ONE);
        let drawn = |error: f32| DrawnCluster { error, lo: unit.0, hi: unit.1 };
        // Both clusters wrote texels of the map (the light saw them).
        let state = layer(&[(key(1), drawn(small)), (key(2), drawn(0.0))], &[key(1), key(2)], true);
        let (eye, away) = eyes();
        // The same set: serves.
        assert!(serves(&s, &eye, &[(key(1), &a), (key(2), &b)], &[unit; 2], &state));
        // Cluster 1 swapped for its children (3): the surface moved by at most `small`.
        assert!(serves(&s, &eye, &[(key(3), &c), (key(2), &b)], &[unit; 2], &state));
        // A swap by more than the slack: drawn again, unless the eye cannot see it.
        let coarse = cluster(10.0 * texel);
        assert!(!serves(&s, &eye, &[(key(4), &coarse), (key(2), &b)], &[unit; 2], &state));
        assert!(serves(&s, &away, &[(key(4), &coarse), (key(2), &b)], &[unit; 2], &state));
        // A caster of error 0 appears with nothing leaving, or one goes: drawn again, seen or not.
        for eye in [&eye, &away] {
            assert!(!serves(&s, eye, &[(key(1), &a), (key(2), &b), (key(3), &c)], &[unit; 3], &state));
            assert!(!serves(&s, eye, &[(key(1), &a)], &[unit; 1], &state));
        }
    }

    #[test]
    fn swaps_the_light_cannot_see_keep_the_layer_whatever_their_error() {
        let s = shadows();
        let texel = tw_runtime::shadow::texel_size(&s, 0).unwrap();
        let coarse = cluster(10.0 * texel);
        let fine = cluster(0.0);
        // Depths 0.5–0.6 in the layer: behind the map's 0 everywhere.
        let deep = (Vec3::new(0.0, 0.0, 50.0), Vec3::new(1.0, 1.0, 60.0));
        let drawn = DrawnCluster { error: 0.0, lo: deep.0, hi: deep.1 };
        let (eye, _) = eyes();
        let set = [(key(4), &coarse), (key(2), &fine)];
        // Cluster 1 (unseen by the light) swapped for a coarse 4 behind the map: the map is
        // what drawing again would give.
        let unseen = layer(&[(key(1), drawn), (key(2), drawn)], &[key(2)], true);
        assert!(serves(&s, &eye, &set, &[deep; 2], &unseen));
        // Not when the light saw cluster 1, when 4 may be in front of the map, or without the
        // map's pyramid: then the level-of-detail slack decides (and 4 is too coarse).
        let seen = layer(&[(key(1), drawn), (key(2), drawn)], &[key(1), key(2)], true);
        assert!(!serves(&s, &eye, &set, &[deep; 2], &seen));
        let near = (Vec3::ZERO, Vec3::ONE);
        assert!(!serves(&s, &eye, &set, &[near, deep], &unseen));
        let no_pyramid = layer(&[(key(1), drawn), (key(2), drawn)], &[key(2)], false);
        assert!(!serves(&s, &eye, &set, &[deep; 2], &no_pyramid));
    }
}
