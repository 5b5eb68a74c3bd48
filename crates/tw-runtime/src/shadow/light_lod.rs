//! The light's level of detail: how many shadow-map texels an object-space error covers, for the
//! LOD policy "the finer of both" (Govindaraju's thesis §4.2.1, method 1: `max(LOD_E, LOD_L)`,
//! after Lloyd). Where the eye's LOD is the default (method 2; src/select.rs, "The light's
//! view"), a far object near the light is drawn coarse and its coarse silhouette is magnified in
//! its shadow; with this metric a cluster is fine enough only when its error is at most τ
//! *pixels* seen from the eye **and** at most τ *texels* seen from the light, in both views,
//! so a cluster drawn in both is still drawn at the same level (no false self-shadowing).
//!
//! The texel density of a layer comes from its matrix ([`texel_size`]); the metric is made from
//! the layers a frame was fitted with:
//! - **Sun**: a point is looked up in the cascade of its eye depth (the lookup rule's rule 1,
//!   src/shadow/mod.rs), an orthographic view whose texels are `t` scene units wide, so an
//!   error `e` covers `e / t` texels. For a sphere or box, the cascade of its *nearest* eye
//!   depth is taken, with the texel sizes made non-decreasing with depth (each the smallest of
//!   it and the cascades behind it): a box that contains another then never projects to fewer
//!   texels, the monotony the render rule needs for a crack-free cut (src/lod_error.rs).
//!   Before the first cascade the first one's texels count, past the last the last one's.
//! - **Point light**: the cube faces are 90° perspective views from the light, texels of `t`
//!   scene units at unit distance, so an error `e` at distance `d` covers `e / (t·d)` texels,
//!   `d` the distance from the light to the nearest point, clamped below by the faces' near
//!   plane ([`point_near`]: a group around the light refines to its finest level, as one
//!   around the eye does).
//!
//! The metric is a pure function of its fields: every evaluation of the same (error, sphere)
//! pair gives the same bits, as src/lod_error.rs requires of the eye's.

use glam::{DVec3, Vec3};

use crate::camera::Camera;
use crate::light::Light;
use crate::shadow::fit::{point_near, texel_size};
use crate::shadow::Shadows;

/// The most sun cascades ([`crate::shadow::ShadowOptions::cascades`] is at most 4).
const MAX_CASCADES: usize = 4;

/// Texels of an object-space error in a light's shadow map (module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightLod {
    kind: Kind,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// Cascades along the eye's depth: `(end of the eye-depth range, texel side)`, in order,
    /// the texel sides non-decreasing; `count` of them used.
    Sun { eye: DVec3, forward: DVec3, cascades: [(f64, f64); MAX_CASCADES], count: usize },
    /// Cube faces from `light`: texel side at unit distance, and the nearest distance used.
    Point { light: DVec3, texel: f64, near: f64 },
}

impl LightLod {
    /// The light's metric for the layers `shadows` was fitted with in a scene whose box is
    /// `scene`, seen by `eye` (whose depth picks a sun's cascade). `None` without layers
    /// (nothing is shadowed, nothing to refine for), or when a layer's texel size cannot be
    /// read from its matrix.
    pub fn new(shadows: &Shadows, eye: &Camera, scene: (Vec3, Vec3)) -> Option<LightLod> {
        let sizes: Option<Vec<f64>> =
            (0..shadows.layers.len()).map(|i| texel_size(shadows, i).map(|t| t as f64)).collect();
        let sizes = sizes.filter(|s| !s.is_empty() && s.iter().all(|t| t.is_finite() && *t > 0.0))?;
        let kind = match shadows.light {
            Light::Sun { .. } => sun(shadows, eye, &sizes),
            Light::Point { position } => {
                let near = point_near(position, scene).max(f64::MIN_POSITIVE);
                let texel = sizes.iter().copied().fold(f64::INFINITY, f64::min);
                Kind::Point { light: position.as_dvec3(), texel, near }
            }
        };
        Some(LightLod { kind })
    }

    /// Texels of `error` at the sphere `[x, y, z, r]` (scene space).
    #[inline]
    pub fn sphere(&self, error: f32, sphere: [f32; 4]) -> f64 {
        let c = DVec3::new(sphere[0] as f64, sphere[1] as f64, sphere[2] as f64);
        let r = sphere[3] as f64;
        match self.kind {
            Kind::Sun { eye, forward, .. } => self.sun_texels(error, (c - eye).dot(forward) - r),
            Kind::Point { light, .. } => self.point_texels(error, c.distance(light) - r),
        }
    }

    /// Texels of `error` at the nearest point of the box `min..=max` (scene space); bounds
    /// [`sphere`](Self::sphere) for every sphere inside the box.
    #[inline]
    pub fn aabb(&self, error: f32, min: Vec3, max: Vec3) -> f64 {
        let (lo, hi) = (min.as_dvec3(), max.as_dvec3());
        match self.kind {
            Kind::Sun { eye, forward, .. } => {
                let (centre, half) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
                self.sun_texels(error, (centre - eye).dot(forward) - half.dot(forward.abs()))
            }
            Kind::Point { light, .. } => {
                let d = (lo - light).max(light - hi).max(DVec3::ZERO);
                self.point_texels(error, d.length())
            }
        }
    }

    /// A sun's texels of `error` at nearest eye depth `depth`.
    #[inline]
    fn sun_texels(&self, error: f32, depth: f64) -> f64 {
        let Kind::Sun { cascades, count, .. } = self.kind else { unreachable!("a sun's metric") };
        if error <= 0.0 || error.is_nan() {
            return 0.0;
        }
        let used = &cascades[..count];
        let texel = used.iter().find(|(end, _)| depth < *end).unwrap_or(&used[count - 1]).1;
        error as f64 / texel
    }

    /// A point light's texels of `error` at distance `distance` from the light.
    #[inline]
    fn point_texels(&self, error: f32, distance: f64) -> f64 {
        let Kind::Point { texel, near, .. } = self.kind else { unreachable!("a point light's metric") };
        if error <= 0.0 || error.is_nan() {
            return 0.0;
        }
        error as f64 / (texel * distance.max(near))
    }
}

/// The cascades of a sun, in order of eye depth, with texel sides made non-decreasing from the
/// far end (module documentation).
fn sun(shadows: &Shadows, eye: &Camera, sizes: &[f64]) -> Kind {
    let mut order: Vec<usize> = (0..sizes.len().min(MAX_CASCADES)).collect();
    order.sort_by(|&a, &b| shadows.layers[a].split[0].total_cmp(&shadows.layers[b].split[0]));
    let mut cascades = [(f64::INFINITY, f64::INFINITY); MAX_CASCADES];
    for (slot, &i) in cascades.iter_mut().zip(&order) {
        *slot = (shadows.layers[i].split[1] as f64, sizes[i]);
    }
    let count = order.len();
    for k in (0..count.saturating_sub(1)).rev() {
        cascades[k].1 = cascades[k].1.min(cascades[k + 1].1);
    }
    Kind::Sun { eye: eye.eye.as_dvec3(), forward: eye.direction().as_dvec3(), cascades, count }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shadow::{fit_layers, ShadowOptions};

    fn eye() -> Camera {
        Camera::new(Vec3::new(0.0, 0.0, 2.0), Vec3::X, Vec3::Z, 60f32.to_radians(), 0.1, 1000.0).unwrap()
    }

    /// A row of unit boxes along +x from 1 to 400 scene units ahead of the eye.
    fn receivers() -> Vec<(Vec3, Vec3)> {
        (0..40)
            .map(|i| i as f32 * 10.0 + 1.0)
            .map(|x| (Vec3::new(x, -1.0, 0.0), Vec3::new(x + 1.0, 1.0, 2.0)))
            .collect()
    }

    fn scene() -> (Vec3, Vec3) {
        (Vec3::new(0.0, -10.0, -1.0), Vec3::new(420.0, 10.0, 10.0))
    }

    fn fitted(light: Light, cascades: u32) -> Shadows {
        let options = ShadowOptions { size: 1024, cascades, ..ShadowOptions::default() };
        fit_layers(&light, &eye(), 16.0 / 9.0, &receivers(), scene(), &options)
    }

    fn sun_lod(cascades: u32) -> (Shadows, LightLod) {
        let sun = Light::Sun { towards: Vec3::new(0.3, 0.2, 1.0).normalize() };
        let shadows = fitted(sun, cascades);
        let lod = LightLod::new(&shadows, &eye(), scene()).expect("layers fitted");
        (shadows, lod)
    }

    #[test]
    fn a_sun_error_covers_its_cascades_texels() {
        let (shadows, lod) = sun_lod(1);
        assert_eq!(shadows.layers.len(), 1);
        let t = texel_size(&shadows, 0).unwrap() as f64;
        let px = lod.sphere(0.5, [50.0, 0.0, 1.0, 0.5]);
        assert!((px - 0.5 / t).abs() <= 1e-9 * px, "{px} against {}", 0.5 / t);
        assert_eq!(lod.sphere(0.0, [50.0, 0.0, 1.0, 0.5]), 0.0);
    }

    #[test]
    fn nearer_cascades_are_finer_and_containing_boxes_never_project_less() {
        let (shadows, lod) = sun_lod(4);
        assert!(shadows.layers.len() >= 2, "a 1..400 depth range needs cascades");
        let (near, far) = (lod.sphere(0.5, [3.0, 0.0, 1.0, 0.5]), lod.sphere(0.5, [390.0, 0.0, 1.0, 0.5]));
        assert!(near > far, "near {near} far {far}");
        // Nested boxes: the outer one is never fewer texels.
        let mut prev = 0.0;
        for grow in [0.5f32, 2.0, 20.0, 100.0, 300.0] {
            let c = Vec3::new(380.0, 0.0, 1.0);
            let t = lod.aabb(0.5, c - Vec3::splat(grow), c + Vec3::splat(grow));
            assert!(t >= prev, "{grow}: {t} < {prev}");
            assert!(t >= lod.sphere(0.5, [c.x, c.y, c.z, 0.5]));
            prev = t;
        }
    }

    #[test]
    fn a_point_light_projects_with_distance_from_the_light() {
        let light = Light::Point { position: Vec3::new(100.0, 0.0, 5.0) };
        let shadows = fitted(light, 4);
        let lod = LightLod::new(&shadows, &eye(), scene()).expect("faces fitted");
        let (at10, at20) = (lod.sphere(0.5, [110.0, 0.0, 5.0, 0.0]), lod.sphere(0.5, [120.0, 0.0, 5.0, 0.0]));
        assert!((at10 / at20 - 2.0).abs() < 1e-6, "{at10} {at20}");
        let t = texel_size(&shadows, 0).unwrap() as f64;
        assert!((at10 - 0.5 / (t * 10.0)).abs() <= 1e-6 * at10);
        // A sphere around the light: the nearest distance is the near plane's.
        let around = lod.sphere(0.5, [100.0, 0.0, 5.0, 1.0]);
        assert!(around > at10 * 100.0, "{around}");
        assert!(around.is_finite());
    }

    #[test]
    fn no_layers_no_metric() {
        let (mut shadows, _) = sun_lod(1);
        shadows.layers.clear();
        assert!(LightLod::new(&shadows, &eye(), scene()).is_none());
    }
}
