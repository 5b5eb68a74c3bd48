//! Screen-space (pixel) error of an object-space error, docs/DESIGN.md, D3: an error `e` (scene
//! units) at a bounding sphere `(c, r)` seen from `eye` projects to
//!
//! ```text
//! px = e · H / (2 · d · tan(fovy / 2)),   d = max(|c − eye| − r, near)
//! ```
//!
//! pixels, for a viewport `H` pixels high: `d` is the distance to the sphere's nearest point, so
//! the estimate bounds the error anywhere in the sphere. An orthographic camera, whose view is
//! `height` units high at every depth, projects the same error to the same pixels anywhere:
//!
//! ```text
//! px = e · H / height
//! ```
//!
//! (the camera's [`Camera::pixels`]; there is no eye to be inside of, and nothing gets finer
//! nearby: LOD selection picks one level of detail for the whole view). Special cases:
//! - `e = 0` (full-resolution clusters) projects to 0 everywhere, even with the eye inside;
//! - the eye inside (or on) the sphere: `+∞` for any `e > 0` (must refine; perspective only);
//! - `e = +∞` (root groups, which nothing replaces) stays `+∞`;
//! - `d` is clamped below by the near plane distance: geometry nearer than that is clipped
//!   (perspective only).
//!
//! The result is monotone: a larger error, or a sphere that contains another, never projects
//! to fewer pixels. That is what makes the per-cluster render rule of docs/FORMAT.md give a
//! complete, crack-free cut (errors grow and spheres nest up the DAG). The arithmetic is f64 so
//! that the tiny positive errors the build gives lossless simplifications
//! (`f32::MIN_POSITIVE`) never round to 0 pixels, which keeps τ = 0 meaning full resolution.
//! Every evaluation of the same (error, sphere) pair gives the same bits, so the decisions
//! "this group is replaced" and "its replacement is drawn" agree exactly.
//!
//! **The finer of both** ([`LodMetric::with_light`]): with a light's metric attached (shadow-map
//! texels, src/shadow/light_lod.rs), an error projects to the larger of its pixels and its
//! texels, so a cut is fine enough for both views. The larger of two monotone measures is
//! monotone, so the cut stays complete and crack-free.

use glam::{DVec3, Vec3};

use crate::camera::Camera;
use crate::shadow::LightLod;

/// Projects object-space errors to pixels for one camera and viewport.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodMetric {
    eye: DVec3,
    /// [`Camera::pixel_scale`]: `H / (2 tan(fovy / 2))` in perspective, `H / height` in
    /// orthographic.
    scale: f64,
    /// An orthographic camera: the distance does not matter.
    orthographic: bool,
    /// The smallest distance used (the near plane).
    min_distance: f64,
    /// A light's texels, counted as well (the finer of both LODs); `None`: the eye's alone.
    light: Option<LightLod>,
}

impl LodMetric {
    /// The metric of `camera` for a viewport `viewport_height` pixels high.
    pub fn new(camera: &Camera, viewport_height: f32) -> LodMetric {
        LodMetric {
            eye: camera.eye.as_dvec3(),
            scale: camera.pixel_scale(viewport_height),
            orthographic: camera.is_orthographic(),
            min_distance: (camera.near as f64).max(f64::MIN_POSITIVE),
            light: None,
        }
    }

    /// This metric taking the larger of its pixels and `light`'s texels (module documentation,
    /// "The finer of both"); `None` keeps the eye's alone.
    pub fn with_light(self, light: Option<LightLod>) -> LodMetric {
        LodMetric { light, ..self }
    }

    /// Pixels of `error` at `distance` (> 0 means outside; ≤ 0 means the eye is inside).
    #[inline]
    fn at_distance(&self, error: f32, distance: f64) -> f64 {
        // NaN (which the store rejects) is treated as no error.
        if error <= 0.0 || error.is_nan() {
            return 0.0;
        }
        if distance <= 0.0 && !self.orthographic {
            return f64::INFINITY;
        }
        crate::camera::pixels_at(error as f64, self.scale, self.orthographic, distance.max(self.min_distance))
    }

    /// Pixel error of `error` at the sphere `[x, y, z, r]` (scene space).
    #[inline]
    pub fn sphere(&self, error: f32, sphere: [f32; 4]) -> f64 {
        let c = DVec3::new(sphere[0] as f64, sphere[1] as f64, sphere[2] as f64);
        let eye = self.at_distance(error, c.distance(self.eye) - sphere[3] as f64);
        match &self.light {
            Some(light) => eye.max(light.sphere(error, sphere)),
            None => eye,
        }
    }

    /// Pixel error of `error` at the nearest point of the box `min..=max` (scene space); `+∞`
    /// (for `error > 0`) when the eye is in the box. Bounds [`sphere`](Self::sphere) for every
    /// sphere inside the box.
    #[inline]
    pub fn aabb(&self, error: f32, min: Vec3, max: Vec3) -> f64 {
        let d = (min.as_dvec3() - self.eye).max(self.eye - max.as_dvec3()).max(DVec3::ZERO);
        let eye = self.at_distance(error, d.length());
        match &self.light {
            Some(light) => eye.max(light.aabb(error, min, max)),
            None => eye,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eye at the origin, 90° field of view, 1000 pixels high: scale = 500 px per unit at
    /// distance 1; near 0.1.
    fn metric() -> LodMetric {
        let c = Camera::new(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 90f32.to_radians(), 0.1, 1000.0).unwrap();
        LodMetric::new(&c, 1000.0)
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-6 * b.abs().max(1.0)
    }

    #[test]
    fn error_projects_with_distance_to_the_nearest_point() {
        let m = metric();
        // Centre at 12, radius 2: nearest point at 10 → 0.1 · 500 / 10 = 5 px.
        assert!(close(m.sphere(0.1, [0.0, 0.0, -12.0, 2.0]), 5.0));
        assert!(close(m.sphere(0.1, [0.0, 12.0, 0.0, 2.0]), 5.0), "direction does not matter");
        assert!(close(m.sphere(0.2, [0.0, 0.0, -12.0, 2.0]), 10.0), "linear in the error");
    }

    #[test]
    fn eye_inside_the_sphere_is_infinite() {
        let m = metric();
        assert_eq!(m.sphere(0.1, [1.0, 0.0, 0.0, 2.0]), f64::INFINITY);
        assert_eq!(m.sphere(0.1, [2.0, 0.0, 0.0, 2.0]), f64::INFINITY, "on the surface");
    }

    #[test]
    fn zero_error_is_zero_pixels_even_inside() {
        let m = metric();
        assert_eq!(m.sphere(0.0, [1.0, 0.0, 0.0, 2.0]), 0.0);
        assert_eq!(m.sphere(0.0, [100.0, 0.0, 0.0, 2.0]), 0.0);
        assert_eq!(m.aabb(0.0, Vec3::splat(-1.0), Vec3::splat(1.0)), 0.0);
    }

    #[test]
    fn infinite_error_stays_infinite() {
        let m = metric();
        assert_eq!(m.sphere(f32::INFINITY, [1e6, 0.0, 0.0, 1.0]), f64::INFINITY);
        assert_eq!(m.aabb(f32::INFINITY, Vec3::splat(1e6), Vec3::splat(1e6 + 1.0)), f64::INFINITY);
    }

    #[test]
    fn distance_is_clamped_at_the_near_plane() {
        let m = metric();
        // Nearest point 0.001 away, clamped to 0.1: 0.1 · 500 / 0.1 = 500 px.
        assert!(close(m.sphere(0.1, [0.0, 0.0, -1.001, 1.0]), 500.0));
    }

    #[test]
    fn smallest_positive_error_is_still_positive() {
        let m = metric();
        let px = m.sphere(f32::MIN_POSITIVE, [1e7, 0.0, 0.0, 1.0]);
        assert!(px > 0.0, "{px}");
    }

    /// Looking down −Z from the origin with a view 100 units high on a viewport 1000 pixels
    /// high: 10 pixels per unit at any distance.
    fn ortho_metric() -> LodMetric {
        let c = Camera::orthographic(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 100.0, 0.1, 1000.0).unwrap();
        LodMetric::new(&c, 1000.0)
    }

    #[test]
    fn orthographic_error_does_not_depend_on_distance() {
        let m = ortho_metric();
        for z in [-1.0, -12.0, -500.0] {
            assert!(close(m.sphere(0.5, [3.0, -2.0, z, 0.5]), 5.0), "at {z}");
            assert!(close(m.aabb(0.5, Vec3::new(1.0, 1.0, z - 1.0), Vec3::new(2.0, 2.0, z)), 5.0));
        }
        // No eye to be inside of: a sphere around the eye projects the same.
        assert!(close(m.sphere(0.5, [0.0, 0.0, 0.0, 2.0]), 5.0));
        assert!(close(m.aabb(0.5, Vec3::splat(-1.0), Vec3::splat(1.0)), 5.0));
        assert_eq!(m.sphere(0.0, [0.0, 0.0, -5.0, 1.0]), 0.0);
        assert_eq!(m.sphere(f32::INFINITY, [0.0, 0.0, -5.0, 1.0]), f64::INFINITY);
        assert!(m.sphere(f32::MIN_POSITIVE, [1e7, 0.0, 0.0, 1.0]) > 0.0);
    }

    /// Two equal boxes, one 5 and one 500 units ahead: the same pixels in orthographic, a
    /// hundred times fewer for the far one in perspective.
    #[test]
    fn equal_boxes_at_different_distances() {
        let boxes = |z: f32| (Vec3::new(-1.0, -1.0, z - 2.0), Vec3::new(1.0, 1.0, z));
        let ((a0, a1), (b0, b1)) = (boxes(-5.0), boxes(-500.0));
        let o = ortho_metric();
        assert_eq!(o.aabb(0.3, a0, a1), o.aabb(0.3, b0, b1));
        let p = metric();
        assert!(close(p.aabb(0.3, a0, a1), 100.0 * p.aabb(0.3, b0, b1)));
    }

    #[test]
    fn nested_spheres_project_monotonically() {
        let m = metric();
        let inner = [5.0, 3.0, -20.0, 1.0];
        let outer = [5.5, 3.0, -20.0, 2.0];
        assert!(m.sphere(0.5, outer) >= m.sphere(0.5, inner));
        assert!(m.sphere(0.6, outer) >= m.sphere(0.5, inner));
    }

    #[test]
    fn box_distance_is_to_its_nearest_point_and_bounds_inner_spheres() {
        let m = metric();
        // Box x in 3..5, y,z in -1..1: nearest point 3 away.
        let (lo, hi) = (Vec3::new(3.0, -1.0, -1.0), Vec3::new(5.0, 1.0, 1.0));
        assert!(close(m.aabb(0.3, lo, hi), 0.3 * 500.0 / 3.0));
        assert!(m.aabb(0.3, lo, hi) >= m.sphere(0.3, [4.0, 0.0, 0.0, 1.0]));
        // Corner distance: box at (3, 4, 0)..: nearest point 5 away.
        assert!(close(m.aabb(1.0, Vec3::new(3.0, 4.0, 0.0), Vec3::new(9.0, 9.0, 0.0)), 100.0));
        assert_eq!(m.aabb(1.0, Vec3::splat(-1.0), Vec3::splat(1.0)), f64::INFINITY, "eye inside");
    }
}
