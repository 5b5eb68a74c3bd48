//! Fitting a light's shadow-map layers to what the eye will draw.
//!
//! **Sun** (parallel light): cascades split along the eye's depth between the nearest and the
//! farthest receiver (the eye cut's cluster boxes, clamped to the eye's clip planes) by the
//! *practical split scheme* of parallel-split shadow maps (Zhang et al. 2006, §3: each split the
//! mix `λ·log + (1 − λ)·uniform`, λ = [`SPLIT_LAMBDA`]), as many as the depth range needs
//! ([`cascades_needed`], at most `--cascades`). Each cascade is an orthographic view
//! down the light direction:
//! - x/y: the light-space rectangle of the receiver points in the cascade's depth slab (each
//!   box clipped to the slab, src/shadow/clip.rs), intersected with that of the eye frustum's
//!   slice (the crop of PSSM §3.2); then made square with a side quantized to powers of 2^¼ and
//!   its corner snapped to whole texels in light space, so that as the eye moves the texel grid
//!   stays put on the scene (no shimmering edges) and changes only when the quantized side does;
//! - depth (0 nearest the light): from the scene box's side nearest the light, since casters can
//!   be anywhere between, to the farthest receiver point of the slab — stretched further so that
//!   one depth unit is the same number of texels in every cascade (see the bias below).
//!
//! The first split starts at eye depth 0 and the last one ends at `f32::MAX` (no drawn point is
//! nearer than the nearest receiver or farther than the farthest); a cascade that holds no
//! receiver point (a gap in depth) is left out.
//!
//! **Point light**: the six faces of a cube around the light, 90° perspective views (slightly
//! wider, [`CUBE_FACE_SCALE`], so that rounding leaves no gap between faces) with standard depth
//! (0 at the near plane). Near: a small fraction of the scene's size ([`POINT_NEAR_FRACTION`]),
//! or 0.9 of the distance to the scene box for a light outside it; far: the farthest scene corner.
//! Only the faces whose frustum meets a receiver are kept (1–6 layers); their splits are
//! `0..f32::MAX` (every drawn point; `f32::MAX` rather than ∞ because WGSL implementations may
//! assume values are finite).
//!
//! **Bias** (rule 2's `d ≤ map + bias`, one value for all layers): `bias_texels` texels' worth of
//! depth, i.e. the depth a surface at 45° to the light changes by over that many texels. Sun:
//! ortho depth is linear, `Δd = Δz / range`, so a texel of side `t` is worth `t / range`; each
//! cascade's depth range is stretched to `t·K` (`K` the largest `range / t` of the cascades,
//! rounded up to a power of two), which makes that worth the same `1/K` in every cascade, and
//! `bias = bias_texels / K`.
//! Point light: perspective depth `d = f/(f−n)·(1 − n/z)` changes by `f·n/((f−n)·z²)` per unit
//! at distance `z`, where a texel is `2z/size` wide; the bias is taken at the nearest receiver's
//! distance `z₀` (the largest it must be; rounded down to a power of 2^¼),
//! `bias_texels · 2·f·n / (size·(f−n)·z₀)`: at least `bias_texels` texels everywhere, growing
//! linearly with distance beyond `z₀`.
//!
//! **Stable from frame to frame**: the rectangle of a cascade is padded by [`WINDOW_PAD`] on
//! each side, and the roundings of `K` and `z₀` keep the bias put, so that a moving eye often
//! finds last frame's layers still fit for it (src/shadow/reuse.rs).

use glam::{DMat4, DVec3, DVec4, Mat4, Vec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::error::RuntimeError;
use crate::frustum::{Containment, Frustum};
use crate::light::Light;
use crate::shadow::clip::{clip_box, corners, depth_slab};
use crate::shadow::reuse::reuse_layers;
use crate::shadow::{ShadowLayer, Shadows};

/// λ of the practical split scheme: 0 uniform, 1 logarithmic (Zhang et al. 2006 use ~0.5–0.8).
pub const SPLIT_LAMBDA: f64 = 0.7;

/// Point light near plane as a fraction of the scene box's diagonal (when the light is in it).
pub const POINT_NEAR_FRACTION: f64 = 1e-4;

/// Room around a cascade's receivers, as a fraction of their light-space extent on each side:
/// the eye can move that far before the receivers leave last frame's cascade and it must be
/// drawn again (src/shadow/reuse.rs); the price is texels up to `1 + 2·WINDOW_PAD` times wider.
pub const WINDOW_PAD: f64 = 0.08;

/// The projection scale of a cube face: `1/tan(fov/2)` a little below 1, i.e. a field of view a
/// little over 90°, so neighbouring faces overlap by a hair instead of leaving a seam.
pub const CUBE_FACE_SCALE: f64 = 1.0 - 1.0 / 4096.0;

/// How the shadow map is made (user input: [`ShadowOptions::validate`] it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowOptions {
    /// Texels per side of each layer (64..=8192).
    pub size: u32,
    /// Sun cascades (1..=4); a point light always has its cube's faces.
    pub cascades: u32,
    /// Depth bias in texels' worth of slope (0..=64), see the module documentation.
    pub bias_texels: f32,
}

impl Default for ShadowOptions {
    fn default() -> Self {
        ShadowOptions { size: 1024, cascades: 3, bias_texels: 1.5 }
    }
}

impl ShadowOptions {
    /// Checks the ranges: a clear message naming the setting and its bounds.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        if !(64..=8192).contains(&self.size) {
            return Err(RuntimeError::Shadow(format!(
                "shadow map size {} must be 64..=8192 texels per side",
                self.size
            )));
        }
        if !(1..=4).contains(&self.cascades) {
            return Err(RuntimeError::Shadow(format!("sun cascades {} must be 1..=4", self.cascades)));
        }
        if !(self.bias_texels.is_finite() && (0.0..=64.0).contains(&self.bias_texels)) {
            return Err(RuntimeError::Shadow(format!(
                "shadow bias {} must be 0..=64 texels",
                self.bias_texels
            )));
        }
        Ok(())
    }
}

/// The layers of `light` for a frame whose eye camera is `eye` (viewport `aspect` = width /
/// height) and whose drawn clusters have the scene-space boxes `receivers`, in a scene whose
/// box is `scene` (see the module documentation). No receivers: no layers.
pub fn fit_layers(
    light: &Light,
    eye: &Camera,
    aspect: f32,
    receivers: &[(Vec3, Vec3)],
    scene: (Vec3, Vec3),
    options: &ShadowOptions,
) -> Shadows {
    fit(light, eye, aspect, receivers, scene, options).0
}

/// [`fit_layers`], taking `previous` frame's layers where they still serve
/// (src/shadow/reuse.rs): the layers, and per layer whether it is `previous`'s.
pub fn refit_layers(
    light: &Light,
    eye: &Camera,
    aspect: f32,
    receivers: &[(Vec3, Vec3)],
    scene: (Vec3, Vec3),
    options: &ShadowOptions,
    previous: &Shadows,
) -> (Shadows, Vec<bool>) {
    let (mut shadows, needs) = fit(light, eye, aspect, receivers, scene, options);
    let reused = reuse_layers(&mut shadows, &needs, previous);
    (shadows, reused)
}

/// The layers, and per sun cascade the box it must hold (the corners of its receivers' light-space
/// rectangle before padding, from the farthest receiver point up to the scene's side nearest the
/// light; none for a point light's faces).
fn fit(
    light: &Light,
    eye: &Camera,
    aspect: f32,
    receivers: &[(Vec3, Vec3)],
    scene: (Vec3, Vec3),
    options: &ShadowOptions,
) -> (Shadows, Vec<[Vec3; 8]>) {
    let empty = Shadows { light: *light, layers: Vec::new(), size: options.size.max(1), bias: 0.0 };
    if receivers.is_empty() {
        return (empty, Vec::new());
    }
    let fitted = match *light {
        Light::Sun { towards } => fit_sun(towards, eye, aspect, receivers, scene, options),
        Light::Point { position } => {
            fit_point(position, receivers, scene, options).map(|(l, b)| (l, b, Vec::new()))
        }
    };
    let (layers, bias, needs) = fitted.unwrap_or_default();
    (Shadows { layers, bias, ..empty }, needs)
}

/// The side of a layer's texels in scene units (for a point light: at unit distance from the
/// light), from its matrix: the light-space x extent of the map is `2 / |row 0|`.
pub fn texel_size(shadows: &Shadows, layer: usize) -> Option<f32> {
    let l = shadows.layers.get(layer)?;
    let scale = l.view_proj.row(0).truncate().length();
    (scale > 0.0).then(|| 2.0 / (scale * shadows.size.max(1) as f32))
}

/// An orthonormal basis `(right, up)` of the plane perpendicular to `towards` (unit).
fn light_basis(towards: DVec3) -> (DVec3, DVec3) {
    let helper = if towards.z.abs() < 0.9 { DVec3::Z } else { DVec3::X };
    let right = helper.cross(towards).normalize();
    (right, towards.cross(right))
}

/// The largest ratio of far to near depth one cascade covers before another pays (each cascade
/// then spans at least this ratio, except when `--cascades` caps them).
pub const CASCADE_DEPTH_RATIO: f64 = 16.0;

/// How many cascades the receivers' depth range `near..far` needs, at most `max`: one per
/// [`CASCADE_DEPTH_RATIO`] of depth ratio. A room seen from inside (0.5–20 m) gets two, an
/// object seen whole one: each cascade is a shadow-map pass and, with cross-culling, a read-back,
/// which on a CPU driver cost more than the resolution a third cascade would add there.
pub fn cascades_needed(near: f64, far: f64, max: u32) -> u32 {
    let ratio = (far / near.max(f64::MIN_POSITIVE)).max(1.0);
    let needed = (ratio.ln() / CASCADE_DEPTH_RATIO.ln()).ceil().max(1.0);
    (needed.min(max.max(1) as f64)) as u32
}

/// The eye depths of the practical split scheme between `near` and `far` (`count + 1` values).
fn practical_splits(near: f64, far: f64, count: u32) -> Vec<f64> {
    (0..=count)
        .map(|i| {
            let f = i as f64 / count as f64;
            SPLIT_LAMBDA * near * (far / near).powf(f) + (1.0 - SPLIT_LAMBDA) * (near + (far - near) * f)
        })
        .collect()
}

/// A light-space bounding rectangle and depth range: `lo`/`hi` of (x, y, z) with z = towards · p
/// (larger is nearer the light).
#[derive(Clone, Copy, Debug)]
struct Bounds {
    lo: DVec3,
    hi: DVec3,
}

impl Bounds {
    const EMPTY: Bounds = Bounds { lo: DVec3::splat(f64::INFINITY), hi: DVec3::splat(f64::NEG_INFINITY) };

    fn add(&mut self, p: DVec3) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }

    fn union(a: Bounds, b: Bounds) -> Bounds {
        Bounds { lo: a.lo.min(b.lo), hi: a.hi.max(b.hi) }
    }

    fn is_empty(&self) -> bool {
        // NaN never compares: a box of NaN is empty as well.
        self.lo.x > self.hi.x || self.lo.x.is_nan() || self.hi.x.is_nan()
    }
}

/// The eye-depth range of the receivers' corners, clamped to the eye's clip planes.
fn receiver_depths(eye: &Camera, receivers: &[(Vec3, Vec3)]) -> Option<(f64, f64)> {
    let (o, dir) = (eye.eye.as_dvec3(), eye.direction().as_dvec3());
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(a, b) in receivers {
        for c in corners(a, b) {
            let d = (c.as_dvec3() - o).dot(dir);
            lo = lo.min(d);
            hi = hi.max(d);
        }
    }
    let (near, far) = (lo.max(eye.near as f64), hi.min(eye.far as f64));
    (near < far).then_some((near, far))
}

/// The corners of the eye frustum's slice between depths `d0` and `d1`.
fn frustum_slice(eye: &Camera, aspect: f64, d0: f64, d1: f64) -> [DVec3; 8] {
    let dir = eye.direction().as_dvec3();
    let right = dir.cross(eye.up.as_dvec3()).normalize();
    let up = right.cross(dir);
    std::array::from_fn(|i| {
        let d = if i & 4 == 0 { d0 } else { d1 };
        let sx = if i & 1 == 0 { -1.0 } else { 1.0 };
        let sy = if i & 2 == 0 { -1.0 } else { 1.0 };
        // Half the view's height at depth d (a box's in orthographic, a pyramid's in perspective).
        let ty = eye.view_height_at(d) * 0.5;
        eye.eye.as_dvec3() + dir * d + right * (sx * ty * aspect) + up * (sy * ty)
    })
}

/// The light-space bounds of the receivers' points in the eye-depth slab `d0..=d1`.
fn slab_bounds(eye: &Camera, receivers: &[(Vec3, Vec3)], d0: f64, d1: f64, basis: [DVec3; 3]) -> Bounds {
    let slack = (1e-5 * (d1.abs() + 1.0)) as f32;
    let slab = depth_slab(eye.eye, eye.direction(), d0 as f32, d1 as f32, slack);
    receivers
        .par_iter()
        .fold(
            || (Bounds::EMPTY, Vec::new()),
            |(mut b, mut points), &(lo, hi)| {
                clip_box(lo, hi, &slab, &mut points);
                for p in &points {
                    let p = p.as_dvec3();
                    b.add(DVec3::new(p.dot(basis[0]), p.dot(basis[1]), p.dot(basis[2])));
                }
                (b, points)
            },
        )
        .map(|(b, _)| b)
        .reduce(|| Bounds::EMPTY, Bounds::union)
}

/// The smallest power of 2^¼ at least `x` (> 0).
fn quantize_up(x: f64) -> f64 {
    2f64.powf((x.log2() * 4.0).ceil() / 4.0)
}

/// The largest power of 2^¼ at most `x` (> 0).
fn quantize_down(x: f64) -> f64 {
    2f64.powf((x.log2() * 4.0).floor() / 4.0)
}

/// A cascade's depth range in texels, `K`, rounded up to a power of two: a longer range only
/// spends depth precision, and a `K` that stays put as the eye moves keeps the bias
/// (`bias_texels / K`) the same from frame to frame, so that last frame's layers can serve
/// again (src/shadow/reuse.rs).
fn quantize_k(k: f64) -> f64 {
    if k.is_finite() && k > 0.0 {
        2f64.powf(k.log2().ceil())
    } else {
        k
    }
}

/// Each side of a cascade's light-space rectangle grows by [`WINDOW_PAD`] of its extent.
fn padded(lo: [f64; 2], hi: [f64; 2]) -> ([f64; 2], [f64; 2]) {
    let pad = WINDOW_PAD * (hi[0] - lo[0]).max(hi[1] - lo[1]);
    ([lo[0] - pad, lo[1] - pad], [hi[0] + pad, hi[1] + pad])
}

/// A square window of side quantized from the rectangle `lo..hi` (light-space x, y) for a map of
/// `size` texels, its corner snapped to whole texels: `(x0, y0, side)`, containing the rectangle.
/// `None` for a rectangle that is not finite (receiver boxes of NaN or infinite coordinates).
fn snapped_window(lo: [f64; 2], hi: [f64; 2], size: u32) -> Option<(f64, f64, f64)> {
    if !lo.iter().chain(&hi).all(|v| v.is_finite()) {
        return None;
    }
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9 * (lo[0].abs() + lo[1].abs() + 1.0));
    // One texel of room on each side for the snapping, which moves the corner by < 1 texel.
    let mut side = quantize_up(extent * (1.0 + 2.0 / size as f64));
    for _ in 0..8 {
        let texel = side / size as f64;
        let (x0, y0) = ((lo[0] / texel).floor() * texel, (lo[1] / texel).floor() * texel);
        if x0 + side >= hi[0] && y0 + side >= hi[1] {
            return Some((x0, y0, side));
        }
        side *= 2f64.powf(0.25); // only when rounding defeated the room left above
    }
    None
}

/// Right-handed orthographic projection to depth 0..1 (view z = −`near` → 0, −`far` → 1), in
/// f64 as glam's `Mat4::orthographic_rh`: the layers are computed in f64 and rounded once.
fn orthographic_rh(left: f64, right: f64, bottom: f64, top: f64, near: f64, far: f64) -> DMat4 {
    let (w, h, r) = (1.0 / (right - left), 1.0 / (top - bottom), 1.0 / (near - far));
    DMat4::from_cols(
        DVec4::new(2.0 * w, 0.0, 0.0, 0.0),
        DVec4::new(0.0, 2.0 * h, 0.0, 0.0),
        DVec4::new(0.0, 0.0, r, 0.0),
        DVec4::new(-(left + right) * w, -(top + bottom) * h, r * near, 1.0),
    )
}

/// Right-handed view from `eye` looking along the unit `forward` (as [`crate::camera::look_at_rh`]).
fn look_at_rh(eye: DVec3, forward: DVec3, up: DVec3) -> DMat4 {
    let s = forward.cross(up).normalize();
    let u = s.cross(forward);
    DMat4::from_cols(
        DVec4::new(s.x, u.x, -forward.x, 0.0),
        DVec4::new(s.y, u.y, -forward.y, 0.0),
        DVec4::new(s.z, u.z, -forward.z, 0.0),
        DVec4::new(-s.dot(eye), -u.dot(eye), forward.dot(eye), 1.0),
    )
}

/// A sun cascade before its depth range is stretched (see the module documentation).
struct Cascade {
    split: [f32; 2],
    /// The snapped window: corner x, y and side in light space.
    window: (f64, f64, f64),
    /// Light-space z (towards · p) of the scene's side nearest the light, and of the farthest
    /// receiver point.
    top: f64,
    bottom: f64,
    /// The box the cascade must hold, in scene space (see [`fit`]).
    need: [Vec3; 8],
}

/// The sun's cascades and bias (module documentation).
fn fit_sun(
    towards: Vec3,
    eye: &Camera,
    aspect: f32,
    receivers: &[(Vec3, Vec3)],
    scene: (Vec3, Vec3),
    options: &ShadowOptions,
) -> Option<(Vec<ShadowLayer>, f32, Vec<[Vec3; 8]>)> {
    let t = towards.as_dvec3().normalize();
    if !t.is_finite() {
        return None;
    }
    let (right, up) = light_basis(t);
    let basis = [right, up, t];
    let (near, far) = receiver_depths(eye, receivers)?;
    let splits = practical_splits(near, far, cascades_needed(near, far, options.cascades));
    // The scene's side nearest the light: the largest towards · p of its corners.
    let scene_top =
        corners(scene.0, scene.1).iter().map(|c| c.as_dvec3().dot(t)).fold(f64::NEG_INFINITY, f64::max);
    let size = options.size.max(1);
    // Per cascade: window (x0, y0, side), nearest z (light side) and farthest receiver z.
    let mut fitted: Vec<Cascade> = Vec::new();
    for (i, pair) in splits.windows(2).enumerate() {
        let (d0, d1) = (pair[0], pair[1]);
        let got = slab_bounds(eye, receivers, d0, d1, basis);
        if got.is_empty() {
            continue;
        }
        let mut slice = Bounds::EMPTY;
        for c in frustum_slice(eye, aspect as f64, d0.max(eye.near as f64), d1) {
            slice.add(DVec3::new(c.dot(right), c.dot(up), c.dot(t)));
        }
        let lo = [got.lo.x.max(slice.lo.x), got.lo.y.max(slice.lo.y)];
        let hi = [got.hi.x.min(slice.hi.x), got.hi.y.min(slice.hi.y)];
        if !(lo[0] <= hi[0] && lo[1] <= hi[1]) {
            continue; // no receiver point in the eye's view in this slab
        }
        let top = scene_top.max(got.hi.z);
        let need = std::array::from_fn(|c| {
            let x = if c & 1 == 0 { lo[0] } else { hi[0] };
            let y = if c & 2 == 0 { lo[1] } else { hi[1] };
            let z = if c & 4 == 0 { got.lo.z } else { top };
            (right * x + up * y + t * z).as_vec3()
        });
        let (lo, hi) = padded(lo, hi);
        let Some(window) = snapped_window(lo, hi, size) else { continue };
        let split =
            [if i == 0 { 0.0 } else { d0 as f32 }, if i + 2 == splits.len() { f32::MAX } else { d1 as f32 }];
        fitted.push(Cascade { split, window, top, bottom: got.lo.z, need });
    }
    if fitted.is_empty() {
        return None;
    }
    // K: the largest depth range in texels; every cascade's range becomes K of its texels.
    let k = fitted
        .iter()
        .map(|c| {
            let side = c.window.2;
            (c.top - c.bottom + 2e-6 * (c.top.abs() + side)).max(side * 1e-6) / (side / size as f64)
        })
        .fold(0f64, f64::max)
        * (1.0 + 1e-4);
    let k = quantize_k(k);
    let view = DMat4::from_cols(
        DVec4::new(right.x, up.x, t.x, 0.0),
        DVec4::new(right.y, up.y, t.y, 0.0),
        DVec4::new(right.z, up.z, t.z, 0.0),
        DVec4::W,
    );
    let layers = fitted
        .iter()
        .map(|&Cascade { split, window: (x0, y0, side), top, .. }| {
            // View z = towards · p; depth 0 at z = top (plus a hair of room), 1 at K texels below.
            let margin = 1e-6 * (top.abs() + side);
            let z_near = -(top + margin);
            let z_far = z_near + k * side / size as f64;
            let proj = orthographic_rh(x0, x0 + side, y0, y0 + side, z_near, z_far);
            ShadowLayer { view_proj: (proj * view).as_mat4(), split }
        })
        .collect();
    let needs = fitted.iter().map(|c| c.need).collect();
    Some((layers, (options.bias_texels as f64 / k) as f32, needs))
}

/// The near plane of a point light's cube faces at `position` in a scene whose box is `scene`
/// (module documentation): a small fraction of the scene's diagonal, or 0.9 of the distance to
/// the box for a light outside it.
pub fn point_near(position: Vec3, scene: (Vec3, Vec3)) -> f64 {
    let p = position.as_dvec3();
    let (lo, hi) = (scene.0.as_dvec3(), scene.1.as_dvec3());
    let diag = (hi - lo).length().max(1e-6 * (p.length() + 1.0));
    let outside = (lo - p).max(p - hi).max(DVec3::ZERO).length();
    (diag * POINT_NEAR_FRACTION).max(0.9 * outside)
}

/// The point light's cube faces and bias (module documentation).
fn fit_point(
    position: Vec3,
    receivers: &[(Vec3, Vec3)],
    scene: (Vec3, Vec3),
    options: &ShadowOptions,
) -> Option<(Vec<ShadowLayer>, f32)> {
    let p = position.as_dvec3();
    let near = point_near(position, scene);
    let farthest = corners(scene.0, scene.1).iter().map(|c| (c.as_dvec3() - p).length()).fold(0f64, f64::max);
    let far = (farthest * 1.01).max(near * 2.0);
    // Standard depth, 0 at `near`: view z = −near → 0, z = −far → 1.
    let s = CUBE_FACE_SCALE;
    let r = far / (near - far);
    let proj = DMat4::from_cols(
        DVec4::new(s, 0.0, 0.0, 0.0),
        DVec4::new(0.0, s, 0.0, 0.0),
        DVec4::new(0.0, 0.0, r, -1.0),
        DVec4::new(0.0, 0.0, r * near, 0.0),
    );
    let faces = [
        (DVec3::X, DVec3::Z),
        (DVec3::NEG_X, DVec3::Z),
        (DVec3::Y, DVec3::Z),
        (DVec3::NEG_Y, DVec3::Z),
        (DVec3::Z, DVec3::Y),
        (DVec3::NEG_Z, DVec3::Y),
    ];
    let layers: Vec<ShadowLayer> = faces
        .iter()
        .filter_map(|&(axis, up)| {
            let view = look_at_rh(p, axis, up);
            let view_proj: Mat4 = (proj * view).as_mat4();
            let frustum = Frustum::from_view_projection(&view_proj);
            receivers
                .iter()
                .any(|&(a, b)| frustum.test_aabb(a, b) != Containment::Outside)
                .then_some(ShadowLayer { view_proj, split: [0.0, f32::MAX] })
        })
        .collect();
    if layers.is_empty() {
        return None;
    }
    // The nearest receiver's distance (at least the near plane) sets the bias.
    let z0 = receivers
        .iter()
        .map(|&(a, b)| (a.as_dvec3() - p).max(p - b.as_dvec3()).max(DVec3::ZERO).length())
        .fold(f64::INFINITY, f64::min)
        .max(near);
    // Down to a power of 2^¼ (a larger bias): the same bias while the eye moves a little keeps
    // last frame's faces usable (src/shadow/reuse.rs).
    let z0 = quantize_down(z0).max(near);
    let bias =
        options.bias_texels as f64 * 2.0 * far * near / (options.size.max(1) as f64 * s * (far - near) * z0);
    Some((layers, bias as f32))
}

#[cfg(test)]
mod cascade_count_tests {
    use super::*;

    #[test]
    fn cascades_follow_the_depth_ratio_up_to_the_cap() {
        assert_eq!(cascades_needed(1.0, 1.0, 3), 1);
        assert_eq!(cascades_needed(1.0, 15.0, 3), 1);
        assert_eq!(cascades_needed(1.0, 17.0, 3), 2);
        assert_eq!(cascades_needed(0.5, 20.0, 3), 2);
        assert_eq!(cascades_needed(0.1, 3000.0, 3), 3);
        assert_eq!(cascades_needed(0.1, 3000.0, 1), 1);
        assert_eq!(cascades_needed(0.0, 10.0, 4), 4);
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn eye() -> Camera {
        Camera::new(Vec3::new(-30.0, -30.0, 10.0), Vec3::new(0.0, 0.0, 0.0), Vec3::Z, 1.0, 0.1, 500.0)
            .unwrap()
    }

    /// A grid of floor tiles and a few boxes standing on it.
    pub(crate) fn receivers() -> Vec<(Vec3, Vec3)> {
        let mut v = Vec::new();
        for x in -20..20 {
            for y in -20..20 {
                let lo = Vec3::new(x as f32 * 2.0, y as f32 * 2.0, 0.0);
                v.push((lo, lo + Vec3::new(2.0, 2.0, 0.1)));
            }
        }
        v.push((Vec3::new(-3.0, -3.0, 0.0), Vec3::new(3.0, 3.0, 8.0)));
        v.push((Vec3::new(10.0, -5.0, 0.0), Vec3::new(12.0, 5.0, 4.0)));
        v
    }

    pub(crate) fn scene() -> (Vec3, Vec3) {
        (Vec3::new(-40.0, -40.0, 0.0), Vec3::new(40.0, 40.0, 8.0))
    }

    fn in_view(eye: &Camera, aspect: f32, p: Vec3) -> bool {
        let c = eye.view_projection(aspect) * p.extend(1.0);
        c.w > 0.0 && {
            let n = c.truncate() / c.w;
            n.x.abs() <= 1.0 && n.y.abs() <= 1.0 && (0.0..=1.0).contains(&n.z)
        }
    }

    /// Samples each box on a lattice (corners included).
    fn samples(lo: Vec3, hi: Vec3) -> impl Iterator<Item = Vec3> {
        (0..64).map(move |i| {
            let f = Vec3::new((i % 4) as f32 / 3.0, ((i / 4) % 4) as f32 / 3.0, (i / 16) as f32 / 3.0);
            lo + (hi - lo) * f
        })
    }

    #[test]
    fn options_are_validated_with_clear_messages() {
        assert!(ShadowOptions::default().validate().is_ok());
        for (bad, what) in [
            (ShadowOptions { size: 10, ..Default::default() }, "size"),
            (ShadowOptions { size: 100_000, ..Default::default() }, "size"),
            (ShadowOptions { cascades: 0, ..Default::default() }, "cascades"),
            (ShadowOptions { cascades: 5, ..Default::default() }, "cascades"),
            (ShadowOptions { bias_texels: -1.0, ..Default::default() }, "bias"),
            (ShadowOptions { bias_texels: f32::NAN, ..Default::default() }, "bias"),
        ] {
            let e = bad.validate().unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
        }
    }

    #[test]
    fn sun_cascades_cover_every_receiver_point_in_view_and_their_splits_cover_near_to_far() {
        let (cam, aspect) = (eye(), 1.6);
        let recv = receivers();
        for towards in [Vec3::Z, Vec3::new(0.3, 0.5, 0.8).normalize(), Vec3::new(-0.9, 0.1, 0.2).normalize()]
        {
            for cascades in 1..=4 {
                let options = ShadowOptions { cascades, size: 512, ..Default::default() };
                let s = fit_layers(&Light::Sun { towards }, &cam, aspect, &recv, scene(), &options);
                let (near, far) = receiver_depths(&cam, &recv).unwrap();
                assert_eq!(s.layers.len(), cascades_needed(near, far, cascades) as usize, "{towards}");
                assert!(
                    s.layers.len() >= cascades.min(3) as usize,
                    "{towards}: the test's depth range needs 3"
                );
                assert_eq!(s.layers[0].split[0], 0.0);
                assert_eq!(s.layers.last().unwrap().split[1], f32::MAX);
                for w in s.layers.windows(2) {
                    assert_eq!(w[0].split[1], w[1].split[0], "contiguous splits");
                    assert!(w[0].split[0] < w[0].split[1]);
                }
                // The bias is `bias_texels` texels' worth of depth in every cascade.
                for i in 0..s.layers.len() {
                    let depth_per_unit = s.layers[i].view_proj.row(2).truncate().length();
                    let texels = s.bias / depth_per_unit / texel_size(&s, i).unwrap();
                    assert!((texels - options.bias_texels).abs() < 1e-3, "layer {i}: {texels} texels");
                }
                let mut checked = 0;
                for &(lo, hi) in &recv {
                    for p in samples(lo, hi).filter(|&p| in_view(&cam, aspect, p)) {
                        assert!(s.layer_of(&cam, p).is_some(), "{towards} {cascades}: {p} in no layer");
                        checked += 1;
                    }
                }
                assert!(checked > 1000, "{checked}");
            }
        }
    }

    #[test]
    fn cascades_are_finer_near_the_eye_and_snap_to_texels() {
        let (cam, aspect) = (eye(), 1.6);
        let options = ShadowOptions { cascades: 3, size: 1024, ..Default::default() };
        let light = Light::Sun { towards: Vec3::new(0.2, 0.1, 1.0).normalize() };
        let s = fit_layers(&light, &cam, aspect, &receivers(), scene(), &options);
        let t: Vec<f32> = (0..3).map(|i| texel_size(&s, i).unwrap()).collect();
        assert!(t[0] < t[1] && t[1] < t[2], "{t:?}");
        // A small move of the eye keeps the texel grid: same texel size, and the window's
        // corner moves by whole texels.
        let moved = Camera {
            eye: cam.eye + Vec3::new(0.05, 0.02, 0.0),
            target: cam.target + Vec3::new(0.05, 0.02, 0.0),
            ..cam
        };
        let s2 = fit_layers(&light, &moved, aspect, &receivers(), scene(), &options);
        let mut same_grid = 0;
        for (i, &texel) in t.iter().enumerate() {
            let (a, b) = (s.layers[i].view_proj, s2.layers[i].view_proj);
            if (texel_size(&s2, i).unwrap() - texel).abs() > 1e-6 * texel {
                continue; // the quantized side changed: a new grid
            }
            // The image of a fixed point moves by a whole number of texels.
            let p = Vec3::new(1.0, 2.0, 0.0);
            let (na, nb) = ((a * p.extend(1.0)).truncate(), (b * p.extend(1.0)).truncate());
            let shift = (na - nb) * 0.5 * options.size as f32;
            assert!(
                (shift.x - shift.x.round()).abs() < 1e-2 && (shift.y - shift.y.round()).abs() < 1e-2,
                "{shift}"
            );
            same_grid += 1;
        }
        assert!(same_grid > 0, "every cascade changed its texel size: nothing was checked");
    }

    #[test]
    fn point_light_faces_cover_every_direction_and_only_needed_faces_are_kept() {
        let cam = eye();
        let light = Light::Point { position: Vec3::new(1.0, -2.0, 5.0) };
        // Receivers all around the light: all six faces.
        let mut around = Vec::new();
        for d in [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z] {
            let c = Vec3::new(1.0, -2.0, 5.0) + d * 10.0;
            around.push((c - Vec3::ONE, c + Vec3::ONE));
        }
        let big = (Vec3::splat(-50.0), Vec3::splat(50.0));
        let s = fit_layers(&light, &cam, 1.0, &around, big, &ShadowOptions::default());
        assert_eq!(s.layers.len(), 6);
        assert!(s.layers.iter().all(|l| l.split == [0.0, f32::MAX]));
        // Every direction from the light lands in a face (eye depth ≥ 0 for these points).
        let back = Camera {
            eye: Vec3::new(1.0, -2.0, 5.0) - Vec3::new(100.0, 0.0, 0.0),
            target: Vec3::new(1.0, -2.0, 5.0),
            ..cam
        };
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..5000 {
            let mut next = || {
                rng ^= rng >> 12;
                rng ^= rng << 25;
                rng ^= rng >> 27;
                (rng.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
            };
            let d = Vec3::new(next(), next(), next()).normalize_or(Vec3::X);
            let p = Vec3::new(1.0, -2.0, 5.0) + d * 20.0;
            assert!(s.layer_of(&back, p).is_some(), "direction {d}");
        }
        // Receivers only below the light: the −Z face and the side faces that see below.
        let below = vec![(Vec3::new(0.0, -3.0, 0.0), Vec3::new(2.0, -1.0, 0.1))];
        let s = fit_layers(&light, &cam, 1.0, &below, big, &ShadowOptions::default());
        assert_eq!(s.layers.len(), 1, "{:?}", s.layers);
        assert!(s.bias > 0.0);
        assert!(fit_layers(&light, &cam, 1.0, &[], big, &ShadowOptions::default()).layers.is_empty());
    }

    /// Bad receiver boxes (NaN, infinite) neither hang nor panic the fit, and give no layer of
    /// non-finite matrices.
    #[test]
    fn non_finite_receivers_are_survived() {
        let bad = vec![
            (Vec3::splat(f32::NAN), Vec3::ONE),
            (Vec3::splat(f32::NEG_INFINITY), Vec3::splat(f32::INFINITY)),
            (Vec3::ZERO, Vec3::new(1.0, f32::INFINITY, 1.0)),
        ];
        for light in [
            Light::Sun { towards: Vec3::new(0.3, 0.2, 0.9).normalize() },
            Light::Point { position: Vec3::Z * 9.0 },
        ] {
            for receivers in [bad.clone(), bad.iter().copied().chain(receivers()).collect()] {
                let s = fit_layers(&light, &eye(), 1.5, &receivers, scene(), &ShadowOptions::default());
                assert!(s.bias.is_finite(), "{light:?}");
                for l in &s.layers {
                    assert!(l.view_proj.is_finite(), "{light:?}: {:?}", l.view_proj);
                }
            }
        }
    }

    #[test]
    fn no_receivers_no_layers() {
        let s = fit_layers(
            &Light::Sun { towards: Vec3::Z },
            &eye(),
            1.0,
            &[],
            scene(),
            &ShadowOptions::default(),
        );
        assert!(s.layers.is_empty());
        // Receivers all behind the eye: nothing drawn, no layers.
        let behind = vec![(Vec3::new(-60.0, -60.0, 0.0), Vec3::new(-55.0, -55.0, 1.0))];
        let s = fit_layers(
            &Light::Sun { towards: Vec3::Z },
            &eye(),
            1.0,
            &behind,
            scene(),
            &ShadowOptions::default(),
        );
        assert!(s.layers.is_empty());
    }
}
