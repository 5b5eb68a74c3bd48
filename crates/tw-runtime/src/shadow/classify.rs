//! Cross-culling (Govindaraju's thesis ch. 4, §4.2.2) against read-back light depth maps
//! instead of occlusion queries: the eye cut's clusters (receivers) are split into fully lit,
//! fully shadowed and partly shadowed ones, and the light cut's clusters into those the light
//! sees and, of these, the casters of the partly shadowed receivers' shadows.
//!
//! The thesis' four steps, and what stands for each here:
//! 1. draw the light-view set into the light's depth buffer — the read-back layers
//!    ([`LightDepth`], min and max pyramids over each);
//! 2. receivers with no fragment in front of the light's depth are fully shadowed — a box whose
//!    nearest depth is behind the map's *farthest* depth (plus the bias) over its footprint;
//! 3. with the depth test reversed, receivers with no fragment behind it are fully lit — a box
//!    whose farthest depth is within the map's *nearest* depth (plus the bias);
//! 4. the light-view set with depth EQUAL and the stencil of step 3's shadowed pixels gives the
//!    casters — the light-visible clusters whose footprint meets a partly shadowed receiver's
//!    and which lie in front of it ([`casters`]).
//!
//! **Conservative with respect to the lookup rule** ([`Shadows::lit`], what the GPU shader
//! does per fragment), so that drawing `Lit` receivers without lookups and `Shadowed` ones
//! without the light's term changes no pixel: `Lit` only when every point of the box is lit by
//! the rule in every layer it can fall into, `Shadowed` only when every point of the box is in
//! some layer (no point escapes to "in no layer, lit": the splits of the layers whose clip
//! volume holds all the box's points of their split cover the box's eye depths) and every point
//! is blocked in every layer it can fall into; otherwise `Partial`. The points of a box a layer
//! can hold are the box clipped to the layer's frustum and, for receivers, its eye-depth slab
//! (src/shadow/clip.rs); their projection's texel rectangle (the rule's floor and clamp) is the
//! footprint and their depth range is exact (linear in ortho depth; perspective depth is
//! monotone in the distance along the view axis, which is linear: extremes at vertices).
//! Against the GPU's own rounding the footprint is widened by [`FOOTPRINT_SLACK`] texels,
//! depths by [`DEPTH_SLACK`], and the planes by a relative 10⁻⁵. A box with a point behind a
//! layer's eye (w ≤ 0) is `Partial`. A box across two cube faces of a point light is never
//! `Shadowed` (no single face's clip volume holds it): conservative, and rare for clusters.

use glam::{DMat4, DVec4, Vec3, Vec4};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::frustum::{Containment, Frustum};
use crate::shadow::clip::{clip_box, corners, depth_slab, Plane};
use crate::shadow::depth::{LightDepth, MinMaxPyramid};
use crate::shadow::{ShadowClass, Shadows};

/// Texels by which a footprint is widened on each side before the rule's floor.
pub const FOOTPRINT_SLACK: f32 = 1.0 / 64.0;

/// Depth (0..1 units) by which a box's depth range is widened against rounding.
pub const DEPTH_SLACK: f32 = 1e-6;

/// Margin (clip units) by which a box must be inside a layer's clip volume to count as inside.
const REGION_MARGIN: f32 = 1e-5;

/// Pyramid blocks one footprint question may read before it gives up and answers "may" (the
/// receiver then is `Partial`, the light box visible): bounds the cost of receivers whose
/// footprint spans very many texels and whose depth follows the map within a few texels' worth
/// all over it (a large floor cluster close to the eye under a low sun), where a proof would
/// read most of the footprint.
pub const MAX_BLOCKS: usize = 256;

/// Cells per side of the casters' grid of partly shadowed receivers' depths (at most).
const CASTER_GRID: u32 = 128;

/// Where the points of a box that a layer can hold fall in it.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Reach {
    /// No point of the box is in the layer's region.
    None,
    /// Some point is behind the layer's eye (w ≤ 0) or not finite: the footprint is unknown.
    Unknown,
    /// Texel rectangle `[x0, y0, x1, y1]` (inclusive) and depth range of those points.
    Footprint { rect: [u32; 4], near: f32, far: f32 },
}

/// A layer's matrix, frustum and the planes a box is clipped by.
struct LayerGeometry {
    view_proj: glam::Mat4,
    /// `view_proj⁻ᵀ` (f64): takes a scene-space plane to the layer's clip space.
    inverse_transpose: DMat4,
    frustum: Frustum,
    /// The layer's frustum planes (its clip volume), widened against rounding.
    planes: [Plane; 6],
    /// The layer's split as half-spaces (see [`depth_slab`]), widened against rounding.
    slab: Vec<Plane>,
    split: [f32; 2],
}

fn widen(plane: Vec4) -> Plane {
    Vec4::new(plane.x, plane.y, plane.z, plane.w + 1e-5 * (plane.w.abs() + 1.0))
}

fn geometry(shadows: &Shadows, eye: &Camera) -> Vec<LayerGeometry> {
    let dir = eye.direction();
    shadows
        .layers
        .iter()
        .map(|l| {
            let frustum = Frustum::from_view_projection(&l.view_proj);
            let slack = 1e-5 * (l.split[0].abs().max(l.split[1].abs().min(f32::MAX / 2.0)).min(1e30) + 1.0);
            LayerGeometry {
                view_proj: l.view_proj,
                inverse_transpose: l.view_proj.as_dmat4().inverse().transpose(),
                frustum,
                planes: frustum.planes.map(widen),
                slab: depth_slab(eye.eye, dir, l.split[0], l.split[1], slack),
                split: l.split,
            }
        })
        .collect()
}

/// The footprint in layer `g` of the points of `lo..=hi` it can hold: the box clipped to the
/// layer's frustum and, when `in_split` (receivers, whose points rule 1 puts in the layer by
/// eye depth), to its slab.
fn reach(g: &LayerGeometry, size: u32, lo: Vec3, hi: Vec3, in_split: bool, points: &mut Vec<Vec3>) -> Reach {
    if g.frustum.test_aabb(lo, hi) == Containment::Outside {
        return Reach::None;
    }
    let mut planes: Vec<Plane> = Vec::with_capacity(8);
    planes.extend_from_slice(&g.planes);
    if in_split {
        planes.extend_from_slice(&g.slab);
    }
    clip_box(lo, hi, &planes, points);
    if points.is_empty() {
        return Reach::None;
    }
    let s = size as f32;
    let (mut x_lo, mut y_lo, mut near) = (f32::INFINITY, f32::INFINITY, f32::INFINITY);
    let (mut x_hi, mut y_hi, mut far) = (f32::NEG_INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY);
    for p in points.iter() {
        let c = g.view_proj * p.extend(1.0);
        if !(c.w > 0.0 && c.is_finite()) {
            return Reach::Unknown;
        }
        let n = c.truncate() / c.w;
        let (x, y) = ((n.x + 1.0) * 0.5 * s, (1.0 - n.y) * 0.5 * s);
        x_lo = x_lo.min(x);
        x_hi = x_hi.max(x);
        y_lo = y_lo.min(y);
        y_hi = y_hi.max(y);
        near = near.min(n.z);
        far = far.max(n.z);
    }
    let texel = |v: f32| v.floor().clamp(0.0, s - 1.0) as u32;
    let rect = [
        texel(x_lo - FOOTPRINT_SLACK),
        texel(y_lo - FOOTPRINT_SLACK),
        texel(x_hi + FOOTPRINT_SLACK),
        texel(y_hi + FOOTPRINT_SLACK),
    ];
    // Only depths 0..=1 are in the layer (rule 1).
    Reach::Footprint { rect, near: (near - DEPTH_SLACK).max(0.0), far: (far + DEPTH_SLACK).min(1.0) }
}

/// Depth bounds of a box's points in a layer as affine functions of their light NDC position:
/// `d ≤ a·x + b·y + c` for each `far` entry and `d ≥ …` for each `near` one, capped by the
/// range of the clipped vertices. Each half-space `π·p ≥ 0` bounding the points (the box's six
/// faces, the layer's slab) is `q·(x, y, d, 1) ≥ 0` in NDC with `q = view_proj⁻ᵀ·π` (dividing by
/// w > 0 keeps the sign): a depth bound affine in (x, y) for ortho and perspective layers alike
/// (depth over a plane is affine in screen space). Over a block of texels an affine function is
/// extreme at the block's corners, so the bound follows the receiver's surface across its
/// footprint: a floor cluster many texels wide under a low sun is proven lit texel block by texel
/// block, where its single farthest depth against the map's nearest would fail.
struct DepthBounds {
    far: Vec<[f64; 3]>,
    near: Vec<[f64; 3]>,
    /// The clipped vertices' depth range (already widened by [`DEPTH_SLACK`]).
    range: (f32, f32),
    size: f64,
}

impl DepthBounds {
    /// The bounds of `lo..=hi`'s points in layer `g` (cut to its slab when `in_split`, as
    /// [`reach`] cuts them) whose vertices' depths span `range`.
    fn new(
        g: &LayerGeometry,
        size: u32,
        (lo, hi): (Vec3, Vec3),
        range: (f32, f32),
        in_split: bool,
    ) -> DepthBounds {
        let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
        let faces = [
            DVec4::new(1.0, 0.0, 0.0, -lo.x),
            DVec4::new(-1.0, 0.0, 0.0, hi.x),
            DVec4::new(0.0, 1.0, 0.0, -lo.y),
            DVec4::new(0.0, -1.0, 0.0, hi.y),
            DVec4::new(0.0, 0.0, 1.0, -lo.z),
            DVec4::new(0.0, 0.0, -1.0, hi.z),
        ];
        let (mut far, mut near) = (Vec::with_capacity(4), Vec::with_capacity(4));
        let slab = if in_split { &g.slab[..] } else { &[] };
        for plane in faces.into_iter().chain(slab.iter().map(|p| p.as_dvec4())) {
            let q = g.inverse_transpose * plane;
            if !q.is_finite() || q.z.abs() <= 1e-12 * (q.x.abs() + q.y.abs() + q.w.abs()) {
                continue; // parallel to the light's rays: no depth bound
            }
            let affine = [-q.x / q.z, -q.y / q.z, -q.w / q.z];
            if q.z > 0.0 {
                near.push(affine);
            } else {
                far.push(affine);
            }
        }
        DepthBounds { far, near, range, size: size as f64 }
    }

    /// The NDC rectangle (x_lo, x_hi, y_lo, y_hi) of texels `block`, widened by the slack.
    fn ndc(&self, [x0, y0, x1, y1]: [u32; 4]) -> [f64; 4] {
        let (s, e) = (self.size, FOOTPRINT_SLACK as f64);
        [
            2.0 * (x0 as f64 - e) / s - 1.0,
            2.0 * (x1 as f64 + 1.0 + e) / s - 1.0,
            1.0 - 2.0 * (y1 as f64 + 1.0 + e) / s,
            1.0 - 2.0 * (y0 as f64 - e) / s,
        ]
    }

    /// The farthest depth a point in texels `block` can have.
    fn far_over(&self, block: [u32; 4]) -> f32 {
        let [xl, xh, yl, yh] = self.ndc(block);
        let bound = self
            .far
            .iter()
            .fold(f64::INFINITY, |m, &[a, b, c]| m.min((a * xl).max(a * xh) + (b * yl).max(b * yh) + c));
        (bound as f32 + DEPTH_SLACK).min(self.range.1)
    }

    /// The nearest depth a point in texels `block` can have.
    fn near_over(&self, block: [u32; 4]) -> f32 {
        let [xl, xh, yl, yh] = self.ndc(block);
        let bound = self
            .near
            .iter()
            .fold(f64::NEG_INFINITY, |m, &[a, b, c]| m.max((a * xl).min(a * xh) + (b * yl).min(b * yh) + c));
        (bound as f32 - DEPTH_SLACK).max(self.range.0)
    }
}

/// Whether rule 1 finds a layer for every point of `lo..=hi`: the splits of the layers whose
/// clip volume holds (with a margin) all of the box's points in their split cover the box's
/// eye-depth range. (A point in such a layer's split is in that layer or an earlier one.)
fn covered(geometry: &[LayerGeometry], eye: &Camera, lo: Vec3, hi: Vec3, points: &mut Vec<Vec3>) -> bool {
    let dir = eye.direction();
    let depths = corners(lo, hi).map(|p| (p - eye.eye).dot(dir));
    let d_lo = depths.iter().copied().fold(f32::INFINITY, f32::min);
    let d_hi = depths.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let slack = 1e-5 * (d_lo.abs().max(d_hi.abs()) + 1.0);
    let m = 1.0 - REGION_MARGIN;
    let mut spans: Vec<[f32; 2]> = Vec::with_capacity(geometry.len());
    for g in geometry {
        if g.split[1] <= d_lo - slack || g.split[0] > d_hi + slack {
            continue;
        }
        clip_box(lo, hi, &g.slab, points);
        let inside = !points.is_empty()
            && points.iter().all(|p| {
                let c = g.view_proj * p.extend(1.0);
                let n = c.truncate() / c.w;
                c.w > 0.0
                    && c.is_finite()
                    && n.x.abs() <= m
                    && n.y.abs() <= m
                    && n.z >= REGION_MARGIN
                    && n.z <= m
            });
        if inside {
            spans.push(g.split);
        }
    }
    spans.sort_by(|a, b| a[0].total_cmp(&b[0]));
    // Sweep: the covered depths reach from `d_lo − slack` up to `reach`.
    let mut reach = d_lo - slack;
    for [from, to] in spans {
        if from > reach {
            break;
        }
        reach = reach.max(to);
    }
    reach > d_hi + slack
}

/// Rule 2's comparison exactly as [`Shadows::lit`] evaluates it (f32): depth `d` against the
/// map's `map` is lit.
fn rule_lit(d: f32, map: f32, bias: f32) -> bool {
    d <= map + bias
}

/// The class of one receiver box (module documentation).
fn classify_box(
    shadows: &Shadows,
    geometry: &[LayerGeometry],
    depths: &[LightDepth],
    eye: &Camera,
    (lo, hi): (Vec3, Vec3),
    points: &mut Vec<Vec3>,
) -> ShadowClass {
    if !(lo.is_finite() && hi.is_finite()) {
        return ShadowClass::Partial;
    }
    let bias = shadows.bias;
    let mut may_be_lit = true;
    let mut may_be_shadowed = covered(geometry, eye, lo, hi, points);
    for (i, g) in geometry.iter().enumerate() {
        let (rect, near, far) = match reach(g, shadows.size, lo, hi, true, points) {
            Reach::None => continue,
            Reach::Unknown => return ShadowClass::Partial,
            Reach::Footprint { rect, near, far } => (rect, near, far),
        };
        let Some(map) = depths.get(i).filter(|d| d.size() == shadows.size) else {
            return ShadowClass::Partial;
        };
        let bounds = DepthBounds::new(g, shadows.size, (lo, hi), (near, far), true);
        // Rule 2, `d ≤ map + bias`, as f32 like the rule: some texel may block the farthest
        // point over it.
        if may_be_lit
            && map.pyramid().any_in(rect, MAX_BLOCKS, |min, _, b| !rule_lit(bounds.far_over(b), min, bias))
        {
            may_be_lit = false;
        }
        // Some texel may let the nearest point over it through.
        if may_be_shadowed
            && map.pyramid().any_in(rect, MAX_BLOCKS, |_, max, b| rule_lit(bounds.near_over(b), max, bias))
        {
            may_be_shadowed = false;
        }
        if !may_be_lit && !may_be_shadowed {
            return ShadowClass::Partial;
        }
    }
    if may_be_lit {
        ShadowClass::Lit
    } else if may_be_shadowed {
        ShadowClass::Shadowed
    } else {
        ShadowClass::Partial
    }
}

/// Classifies each receiver box (scene space; the eye cut's clusters) against the read-back
/// layers `depths` (one per layer of `shadows`, in order), as seen by `eye`: conservative with
/// respect to the lookup rule (module documentation). A layer whose map is missing or of another
/// size makes every box that reaches it `Partial`.
pub fn classify_receivers(
    shadows: &Shadows,
    depths: &[LightDepth],
    eye: &Camera,
    boxes: &[(Vec3, Vec3)],
) -> Vec<ShadowClass> {
    let geometry = geometry(shadows, eye);
    boxes
        .par_iter()
        .map_init(Vec::new, |points, &b| classify_box(shadows, &geometry, depths, eye, b, points))
        .collect()
}

/// Which of the light cut's cluster boxes of layer `layer` the light sees: those not entirely
/// behind the map (a box whose nearest depth is farther than the map's farthest depth over its
/// footprint is hidden). A cluster that wrote a texel of the map is never hidden; boxes outside
/// the layer are not seen. The light-view visible set of the thesis (a statistic, and the
/// candidates of [`casters`]).
pub fn light_visible(
    shadows: &Shadows,
    layer: usize,
    depth: &LightDepth,
    eye: &Camera,
    boxes: &[(Vec3, Vec3)],
) -> Vec<bool> {
    let geometry = geometry(shadows, eye);
    let Some(g) = geometry.get(layer) else { return vec![false; boxes.len()] };
    if depth.size() != shadows.size {
        return vec![true; boxes.len()];
    }
    boxes
        .par_iter()
        .map_init(Vec::new, |points, &(lo, hi)| match reach(g, shadows.size, lo, hi, false, points) {
            Reach::None => false,
            Reach::Unknown => true,
            Reach::Footprint { rect, near, far } => {
                let bounds = DepthBounds::new(g, shadows.size, (lo, hi), (near, far), false);
                depth.pyramid().any_in(rect, MAX_BLOCKS, |_, max, b| bounds.near_over(b) <= max)
            }
        })
        .collect()
}

/// The casters of layer `layer` (thesis step 4): of the light cut's boxes `light_boxes` that are
/// light-visible (`visible`, from [`light_visible`]), those whose footprint meets the footprint
/// of a `Partial` receiver (`receivers` with their `classes`) in this layer and which lie in
/// front of it (their nearest depth nearer than the receiver's farthest). Footprints meet on a
/// grid of at most `CASTER_GRID` (128)² cells, so the set may hold a few more than the exact one.
#[allow(clippy::too_many_arguments)]
pub fn casters(
    shadows: &Shadows,
    layer: usize,
    eye: &Camera,
    receivers: &[(Vec3, Vec3)],
    classes: &[ShadowClass],
    light_boxes: &[(Vec3, Vec3)],
    visible: &[bool],
) -> Vec<bool> {
    let geometry = geometry(shadows, eye);
    let Some(g) = geometry.get(layer) else { return vec![false; light_boxes.len()] };
    let size = shadows.size.max(1);
    let cell = size.div_ceil(CASTER_GRID).max(1);
    let cells = size.div_ceil(cell);
    let to_cells = |r: [u32; 4]| r.map(|v| v / cell);
    // Per cell, the farthest depth of a partly shadowed receiver over it (−∞: none).
    let grid = receivers
        .par_iter()
        .zip(classes.par_iter())
        .filter(|(_, &c)| c == ShadowClass::Partial)
        .fold(
            || (vec![f32::NEG_INFINITY; (cells * cells) as usize], Vec::new()),
            |(mut grid, mut points), (&(lo, hi), _)| {
                let (rect, far) = match reach(g, size, lo, hi, true, &mut points) {
                    Reach::None => return (grid, points),
                    Reach::Unknown => ([0, 0, size - 1, size - 1], f32::INFINITY),
                    Reach::Footprint { rect, far, .. } => (rect, far),
                };
                let [x0, y0, x1, y1] = to_cells(rect);
                for y in y0..=y1 {
                    for v in &mut grid[(y * cells + x0) as usize..=(y * cells + x1) as usize] {
                        *v = v.max(far);
                    }
                }
                (grid, points)
            },
        )
        .map(|(grid, _)| grid)
        .reduce(
            || vec![f32::NEG_INFINITY; (cells * cells) as usize],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x = x.max(y));
                a
            },
        );
    // −∞ stays "no receiver" in the max pyramid (non-finite values become +∞ there).
    let grid: Vec<f32> =
        grid.into_iter().map(|v| if v == f32::NEG_INFINITY { -1.0 } else { v.min(2.0) }).collect();
    let Some(pyramid) = MinMaxPyramid::from_grid(&grid, cells, cells) else {
        return vec![false; light_boxes.len()];
    };
    light_boxes
        .par_iter()
        .enumerate()
        .map_init(Vec::new, |points, (i, &(lo, hi))| {
            if !visible.get(i).copied().unwrap_or(false) {
                return false;
            }
            match reach(g, size, lo, hi, false, points) {
                Reach::None => false,
                Reach::Unknown => true,
                Reach::Footprint { rect, near, .. } => pyramid.any(to_cells(rect), |_, max| near < max),
            }
        })
        .collect()
}

/// The sizes of a frame's shadow sets (docs/DESIGN.md "Measuring"), for the frame's report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ShadowSetStats {
    pub receivers_lit: u64,
    pub receivers_shadowed: u64,
    pub receivers_partial: u64,
    /// Triangles of the receivers of each class (when the caller gave triangle counts).
    pub triangles_lit: u64,
    pub triangles_shadowed: u64,
    pub triangles_partial: u64,
    /// Clusters of the light cuts, summed over the layers.
    pub light_cut: u64,
    /// Of which the light sees ([`light_visible`]).
    pub light_visible: u64,
    /// Of which cast onto partly shadowed receivers ([`casters`]).
    pub casters: u64,
}

impl ShadowSetStats {
    /// Counts the receivers' classes; `triangles[i]` (if given: empty for none) is receiver
    /// `i`'s triangle count.
    pub fn add_receivers(&mut self, classes: &[ShadowClass], triangles: &[u32]) {
        for (i, c) in classes.iter().enumerate() {
            let t = triangles.get(i).copied().unwrap_or(0) as u64;
            let (n, tri) = match c {
                ShadowClass::Lit => (&mut self.receivers_lit, &mut self.triangles_lit),
                ShadowClass::Shadowed => (&mut self.receivers_shadowed, &mut self.triangles_shadowed),
                ShadowClass::Partial => (&mut self.receivers_partial, &mut self.triangles_partial),
            };
            *n += 1;
            *tri += t;
        }
    }

    /// Counts one layer's light cut, its visible clusters and its casters.
    pub fn add_layer(&mut self, light_cut: usize, visible: &[bool], casters: &[bool]) {
        self.light_cut += light_cut as u64;
        self.light_visible += visible.iter().filter(|&&v| v).count() as u64;
        self.casters += casters.iter().filter(|&&v| v).count() as u64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::Light;
    use crate::shadow::fit::{fit_layers, ShadowOptions};
    use tw_core::rng::Rng;

    /// A horizontal rectangle `z = h` over `lo..=hi` in x and y: an occluder of the synthetic maps.
    #[derive(Clone, Copy, Debug)]
    struct Rect {
        h: f32,
        lo: [f32; 2],
        hi: [f32; 2],
    }

    /// The depth map of layer `layer` rasterized on the CPU with the layer's own projection:
    /// each texel's centre ray (unprojected at depths 0 and 1) meets the rectangles; the nearest
    /// depth in 0..=1 is kept, 1.0 where none.
    fn rasterize(shadows: &Shadows, layer: usize, rects: &[Rect]) -> LightDepth {
        let vp = shadows.layers[layer].view_proj.as_dmat4();
        let inv = vp.inverse();
        let n = shadows.size;
        let mut map = vec![1f32; (n * n) as usize];
        for y in 0..n {
            for x in 0..n {
                let nx = (x as f64 + 0.5) / n as f64 * 2.0 - 1.0;
                let ny = 1.0 - (y as f64 + 0.5) / n as f64 * 2.0;
                let a = inv * glam::DVec4::new(nx, ny, 0.0, 1.0);
                let b = inv * glam::DVec4::new(nx, ny, 1.0, 1.0);
                let (a, b) = (a.truncate() / a.w, b.truncate() / b.w);
                for r in rects {
                    let t = (r.h as f64 - a.z) / (b.z - a.z);
                    if !t.is_finite() {
                        continue;
                    }
                    let p = a + (b - a) * t;
                    if p.x < r.lo[0] as f64
                        || p.x > r.hi[0] as f64
                        || p.y < r.lo[1] as f64
                        || p.y > r.hi[1] as f64
                    {
                        continue;
                    }
                    let c = vp * p.extend(1.0);
                    let d = (c.z / c.w) as f32;
                    if c.w > 0.0 && (0.0..=1.0).contains(&d) {
                        let v = &mut map[(y * n + x) as usize];
                        *v = v.min(d);
                    }
                }
            }
        }
        LightDepth::new(&map, n).unwrap()
    }

    fn eye() -> Camera {
        Camera::new(Vec3::new(-25.0, -18.0, 16.0), Vec3::new(0.0, 0.0, 0.0), Vec3::Z, 1.0, 0.1, 300.0)
            .unwrap()
    }

    /// 2×2 floor tiles over −20..20, 0.05 thick.
    fn tiles() -> Vec<(Vec3, Vec3)> {
        let mut v = Vec::new();
        for x in -10..10 {
            for y in -10..10 {
                let lo = Vec3::new(x as f32 * 2.0, y as f32 * 2.0, 0.0);
                v.push((lo, lo + Vec3::new(2.0, 2.0, 0.05)));
            }
        }
        v
    }

    fn tile_at(x: f32, y: f32) -> (Vec3, Vec3) {
        (Vec3::new(x, y, 0.0), Vec3::new(x + 2.0, y + 2.0, 0.05))
    }

    /// A block (top at z = 4 over −3..3) on a 40×40 floor: the block's box, the receivers (the
    /// floor's tiles and the block), the scene's box and what the light's map holds.
    struct BlockScene {
        block: (Vec3, Vec3),
        receivers: Vec<(Vec3, Vec3)>,
        scene: (Vec3, Vec3),
        occluders: [Rect; 2],
    }

    fn block_scene() -> BlockScene {
        let block = (Vec3::new(-3.0, -3.0, 0.0), Vec3::new(3.0, 3.0, 4.0));
        let mut receivers = tiles();
        receivers.push(block);
        let scene = (Vec3::new(-20.0, -20.0, 0.0), Vec3::new(20.0, 20.0, 4.0));
        let occluders = [
            Rect { h: 0.0, lo: [-20.0, -20.0], hi: [20.0, 20.0] },
            Rect { h: 4.0, lo: [-3.0, -3.0], hi: [3.0, 3.0] },
        ];
        BlockScene { block, receivers, scene, occluders }
    }

    /// A block (top at z = 4 over −3..3) on a floor, the sun straight above: tiles far from the
    /// block are lit, tiles well under it shadowed, tiles across its edge partly shadowed, and the
    /// block itself (its top is its own occluder) partly.
    #[test]
    fn a_block_on_a_floor_under_the_sun() {
        let cam = eye();
        let BlockScene { block, receivers, scene, occluders } = block_scene();
        for cascades in [1, 3] {
            let options = ShadowOptions { size: 256, cascades, bias_texels: 1.5 };
            let shadows =
                fit_layers(&Light::Sun { towards: Vec3::Z }, &cam, 1.5, &receivers, scene, &options);
            assert!(!shadows.layers.is_empty());
            let depths: Vec<LightDepth> =
                (0..shadows.layers.len()).map(|i| rasterize(&shadows, i, &occluders)).collect();
            let boxes = [
                tile_at(10.0, 10.0),
                tile_at(-16.0, 6.0),
                tile_at(-2.0, -2.0),
                tile_at(0.0, 0.0),
                tile_at(2.0, 0.0),
                tile_at(-4.0, -2.0),
                block,
            ];
            let classes = classify_receivers(&shadows, &depths, &cam, &boxes);
            use ShadowClass::*;
            assert_eq!(
                classes,
                vec![Lit, Lit, Shadowed, Shadowed, Partial, Partial, Partial],
                "{cascades} cascades"
            );
            // Every tile: under the block shadowed or partly, far from it lit.
            let all = classify_receivers(&shadows, &depths, &cam, &tiles());
            for (&(lo, hi), c) in tiles().iter().zip(&all) {
                let gap =
                    (Vec3::new(-3.0, -3.0, 0.0) - hi).max(lo - Vec3::new(3.0, 3.0, 0.0)).max(Vec3::ZERO);
                if gap.x.max(gap.y) > 0.5 {
                    assert_eq!(*c, Lit, "tile {lo}");
                }
            }
            let mut stats = ShadowSetStats::default();
            stats.add_receivers(&all, &vec![2; all.len()]);
            // The four tiles entirely under the block (tiles are aligned to even coordinates).
            assert_eq!(stats.receivers_shadowed, 4, "{stats:?}");
            assert_eq!(stats.triangles_shadowed, 8);
            assert_eq!(stats.receivers_lit + stats.receivers_partial + 4, 400);
        }
    }

    /// The light sees the block's top and the lit floor, not a box under the block; the casters of
    /// the partly shadowed tiles include the block and not a lit tile far away.
    #[test]
    fn light_visible_set_and_casters() {
        let cam = eye();
        let BlockScene { block, receivers, scene, occluders } = block_scene();
        let options = ShadowOptions { size: 256, cascades: 1, bias_texels: 1.5 };
        let shadows = fit_layers(&Light::Sun { towards: Vec3::Z }, &cam, 1.5, &receivers, scene, &options);
        let depth = rasterize(&shadows, 0, &occluders);
        let hidden = (Vec3::new(-1.0, -1.0, 0.5), Vec3::new(1.0, 1.0, 1.0));
        let far_tile = tile_at(14.0, 14.0);
        let light_boxes = [block, hidden, far_tile, tile_at(-16.0, -16.0)];
        let visible = light_visible(&shadows, 0, &depth, &cam, &light_boxes);
        assert_eq!(visible, vec![true, false, true, true]);
        let classes = classify_receivers(&shadows, &[depth], &cam, &receivers);
        let casters = casters(&shadows, 0, &cam, &receivers, &classes, &light_boxes, &visible);
        assert!(casters[0], "the block casts onto the tiles across its edge");
        assert!(!casters[1] && !casters[2], "{casters:?}");
        let mut stats = ShadowSetStats::default();
        stats.add_layer(light_boxes.len(), &visible, &casters);
        assert_eq!((stats.light_cut, stats.light_visible), (4, 3));
    }

    /// A floor of tiles each many texels wide under a low sun: the floor's depth changes by several
    /// texels' worth across a tile, more than the bias, so only a bound that follows the tile
    /// across its footprint proves the tiles lit (their farthest depth against the map's nearest
    /// over the whole footprint does not).
    #[test]
    fn wide_tiles_under_a_low_sun_are_lit() {
        let cam = eye();
        let mut tiles = Vec::new();
        for x in 0..100 {
            for y in 0..100 {
                let lo = Vec3::new(-20.0 + x as f32 * 0.4, -20.0 + y as f32 * 0.4, 0.0);
                tiles.push((lo, lo + Vec3::new(0.4, 0.4, 0.02)));
            }
        }
        let scene = (Vec3::new(-20.0, -20.0, 0.0), Vec3::new(20.0, 20.0, 6.0));
        let options = ShadowOptions { size: 1024, cascades: 3, bias_texels: 1.5 };
        let light = Light::Sun { towards: Vec3::new(0.3, 0.2, 1.0).normalize() };
        let shadows = fit_layers(&light, &cam, 1.5, &tiles, scene, &options);
        let floor = [Rect { h: 0.0, lo: [-20.0, -20.0], hi: [20.0, 20.0] }];
        let depths: Vec<LightDepth> =
            (0..shadows.layers.len()).map(|i| rasterize(&shadows, i, &floor)).collect();
        let classes = classify_receivers(&shadows, &depths, &cam, &tiles);
        let mut stats = ShadowSetStats::default();
        stats.add_receivers(&classes, &[]);
        assert_eq!(stats.receivers_lit, tiles.len() as u64, "{stats:?}");
    }

    /// The `f32` draws these tests make, from the project's generator.
    trait DrawF32 {
        /// Uniform in [0, 1].
        fn unit(&mut self) -> f32;
        /// Uniform in [a, b].
        fn range(&mut self, a: f32, b: f32) -> f32;
    }

    impl DrawF32 for Rng {
        fn unit(&mut self) -> f32 {
            self.f64() as f32
        }
        fn range(&mut self, a: f32, b: f32) -> f32 {
            self.range_f64(a.into(), b.into()) as f32
        }
    }

    /// THE property: for random lights, maps and boxes, every point of a box classified `Lit` or
    /// `Shadowed` gets that answer from the lookup rule itself.
    #[test]
    fn lit_and_shadowed_boxes_agree_with_the_lookup_rule_everywhere() {
        let mut rng = Rng::new(0x5eed_ab1e);
        let (mut lit, mut shadowed, mut partial, mut hidden) = (0, 0, 0, 0);
        for round in 0..12 {
            let cam = Camera::new(
                Vec3::new(rng.range(-30.0, 30.0), rng.range(-30.0, 30.0), rng.range(3.0, 25.0)),
                Vec3::new(rng.range(-5.0, 5.0), rng.range(-5.0, 5.0), 0.0),
                Vec3::Z,
                rng.range(0.6, 1.4),
                0.1,
                300.0,
            )
            .unwrap();
            let light = if round % 3 == 2 {
                Light::Point {
                    position: Vec3::new(rng.range(-8.0, 8.0), rng.range(-8.0, 8.0), rng.range(9.0, 14.0)),
                }
            } else {
                let (az, el) = (rng.range(0.0, std::f32::consts::TAU), rng.range(0.4, 1.5));
                Light::Sun { towards: Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin()) }
            };
            let mut rects = vec![Rect { h: 0.0, lo: [-20.0, -20.0], hi: [20.0, 20.0] }];
            for _ in 0..8 {
                let (x, y, w, d) = (
                    rng.range(-15.0, 12.0),
                    rng.range(-15.0, 12.0),
                    rng.range(2.0, 9.0),
                    rng.range(2.0, 9.0),
                );
                rects.push(Rect { h: rng.range(0.5, 8.0), lo: [x, y], hi: [x + w, y + d] });
            }
            let mut boxes = tiles();
            for _ in 0..150 {
                let lo = Vec3::new(rng.range(-20.0, 18.0), rng.range(-20.0, 18.0), rng.range(0.0, 7.0));
                let size = Vec3::new(rng.range(0.05, 2.5), rng.range(0.05, 2.5), rng.range(0.0, 1.5));
                boxes.push((lo, lo + size));
            }
            let scene = (Vec3::new(-20.0, -20.0, 0.0), Vec3::new(20.0, 20.0, 9.0));
            let options =
                ShadowOptions { size: 128, cascades: 1 + round % 4, bias_texels: rng.range(0.0, 3.0) };
            let shadows = fit_layers(&light, &cam, 1.5, &boxes, scene, &options);
            let depths: Vec<LightDepth> =
                (0..shadows.layers.len()).map(|i| rasterize(&shadows, i, &rects)).collect();
            let classes = classify_receivers(&shadows, &depths, &cam, &boxes);
            let map = |l: usize, x: u32, y: u32| depths[l].texel(x, y);
            // A box the light does not see has every point of it in layer 0 behind the map.
            let visible = light_visible(&shadows, 0, &depths[0], &cam, &boxes);
            for (&(lo, hi), _) in boxes.iter().zip(&visible).filter(|(_, &v)| !v) {
                hidden += 1;
                for _ in 0..100 {
                    let p = lo + (hi - lo) * Vec3::new(rng.unit(), rng.unit(), rng.unit());
                    let c = shadows.layers[0].view_proj * p.extend(1.0);
                    let n = c.truncate() / c.w;
                    if c.w > 0.0 && n.x.abs() <= 1.0 && n.y.abs() <= 1.0 && (0.0..=1.0).contains(&n.z) {
                        let (x, y) = shadows.texel(n);
                        assert!(
                            depths[0].texel(x, y) < n.z,
                            "round {round}: hidden box {lo}..{hi} shows at {p}"
                        );
                    }
                }
            }
            for (&(lo, hi), &class) in boxes.iter().zip(&classes) {
                match class {
                    ShadowClass::Lit => lit += 1,
                    ShadowClass::Shadowed => shadowed += 1,
                    ShadowClass::Partial => {
                        partial += 1;
                        continue;
                    }
                }
                let want = class == ShadowClass::Lit;
                let points = corners(lo, hi)
                    .into_iter()
                    .chain((0..150).map(|_| lo + (hi - lo) * Vec3::new(rng.unit(), rng.unit(), rng.unit())));
                for p in points {
                    assert_eq!(
                        shadows.lit(&cam, p, map),
                        want,
                        "round {round}, {light:?}: box {lo}..{hi} is {class:?} but {p} is not"
                    );
                }
            }
        }
        eprintln!("{lit} lit, {shadowed} shadowed, {partial} partial, {hidden} hidden from the light");
        assert!(hidden > 50, "{hidden} boxes hidden from the light");
        assert!(
            lit > 500 && shadowed > 200 && partial > 100,
            "{lit} lit, {shadowed} shadowed, {partial} partial"
        );
    }

    /// The cost of a frame's CPU shadow work at full size (run in release with `--ignored
    /// --nocapture`): 40,000 floor tiles and 2,000 boxes, three 2048² cascades.
    #[test]
    #[ignore]
    fn cost_of_a_frame() {
        let mut rng = Rng::new(7);
        let cam = eye();
        let mut boxes = Vec::new();
        for x in 0..200 {
            for y in 0..200 {
                let lo = Vec3::new(-20.0 + x as f32 * 0.2, -20.0 + y as f32 * 0.2, 0.0);
                boxes.push((lo, lo + Vec3::new(0.2, 0.2, 0.02)));
            }
        }
        let mut rects = vec![Rect { h: 0.0, lo: [-20.0, -20.0], hi: [20.0, 20.0] }];
        for _ in 0..2000 {
            let lo = Vec3::new(rng.range(-20.0, 19.0), rng.range(-20.0, 19.0), rng.range(0.0, 5.0));
            let size = Vec3::new(rng.range(0.1, 1.0), rng.range(0.1, 1.0), rng.range(0.0, 0.5));
            boxes.push((lo, lo + size));
            if rects.len() < 40 {
                rects.push(Rect { h: lo.z + size.z, lo: [lo.x, lo.y], hi: [lo.x + size.x, lo.y + size.y] });
            }
        }
        let scene = (Vec3::new(-20.0, -20.0, 0.0), Vec3::new(20.0, 20.0, 6.0));
        let options = ShadowOptions { size: 2048, cascades: 3, bias_texels: 1.5 };
        let light = Light::Sun { towards: Vec3::new(0.3, 0.2, 1.0).normalize() };
        let t = std::time::Instant::now();
        let shadows = fit_layers(&light, &cam, 1.5, &boxes, scene, &options);
        let fit = t.elapsed();
        let maps: Vec<Vec<f32>> = (0..shadows.layers.len())
            .map(|i| {
                let d = rasterize(&shadows, i, &rects);
                (0..2048 * 2048).map(|k| d.texel(k % 2048, k / 2048)).collect()
            })
            .collect();
        let t = std::time::Instant::now();
        let depths: Vec<LightDepth> = maps.iter().map(|m| LightDepth::new(m, 2048).unwrap()).collect();
        let pyramids = t.elapsed();
        let t = std::time::Instant::now();
        let classes = classify_receivers(&shadows, &depths, &cam, &boxes);
        let classify = t.elapsed();
        let t = std::time::Instant::now();
        let visible = light_visible(&shadows, 0, &depths[0], &cam, &boxes);
        let cast = casters(&shadows, 0, &cam, &boxes, &classes, &boxes, &visible);
        let layer0 = t.elapsed();
        let mut stats = ShadowSetStats::default();
        stats.add_receivers(&classes, &[]);
        stats.add_layer(boxes.len(), &visible, &cast);
        eprintln!(
            "{} boxes, {} layers: fit {fit:?}, pyramids {pyramids:?}, classify {classify:?}, \
             light visible + casters of layer 0 {layer0:?}; {stats:?}",
            boxes.len(),
            shadows.layers.len()
        );
    }

    #[test]
    fn missing_or_mismatched_maps_give_partial() {
        let cam = eye();
        let receivers = tiles();
        let scene = (Vec3::new(-20.0, -20.0, 0.0), Vec3::new(20.0, 20.0, 4.0));
        let options = ShadowOptions { size: 64, cascades: 1, bias_texels: 1.0 };
        let shadows = fit_layers(&Light::Sun { towards: Vec3::Z }, &cam, 1.5, &receivers, scene, &options);
        let classes = classify_receivers(&shadows, &[], &cam, &receivers[..5]);
        assert!(classes.iter().all(|&c| c == ShadowClass::Partial));
        let small = LightDepth::new(&[1.0; 16], 4).unwrap();
        let classes = classify_receivers(&shadows, &[small], &cam, &receivers[..5]);
        assert!(classes.iter().all(|&c| c == ShadowClass::Partial));
        let bad = (Vec3::splat(f32::NAN), Vec3::ONE);
        let full = LightDepth::new(&vec![1.0; 64 * 64], 64).unwrap();
        assert_eq!(classify_receivers(&shadows, &[full], &cam, &[bad]), vec![ShadowClass::Partial]);
    }
}
