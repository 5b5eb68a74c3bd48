//! Picking by ray casting on the CPU, plain data: the ray through a pixel of a camera, ray–box
//! and ray–triangle (Möller–Trumbore) tests, and [`pick_clusters`], the nearest hit among the
//! clusters a frame drew (cluster boxes first), [`pick_triangle`], the same with the hit
//! triangle's object and corners (which [`crate::snap`] snaps measurement points to). The
//! viewer uses it for the orbit pivot (a clicked point), the ground below the eye in walk mode,
//! picking objects and measuring.

use glam::Vec3;
use tw_runtime::Camera;
use tw_store::PageCluster;

/// A ray: `origin + t · dir`, `t ≥ 0`; `dir` is unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
}

impl Ray {
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// The ray of `camera` through the point (`x`, `y`) of a `w` × `h` viewport (pixels, y down):
/// tw-rt's primary ray (`tw_rt::Camera::ndc_ray`), from the eye in perspective, from the near
/// plane along the view direction in orthographic.
pub fn camera_ray(camera: &Camera, x: f32, y: f32, w: f32, h: f32) -> Ray {
    let aspect = w / h.max(1.0);
    let ndc_x = (x / w.max(1.0)) * 2.0 - 1.0;
    let ndc_y = 1.0 - (y / h.max(1.0)) * 2.0;
    let r = tw_rt::Camera::for_view(camera, aspect).ndc_ray(ndc_x, ndc_y);
    Ray { origin: r.origin, dir: r.dir }
}

/// Entry distance of `ray` into the box (0 if it starts inside), `None` when it misses.
pub fn ray_box(ray: &Ray, lo: Vec3, hi: Vec3) -> Option<f32> {
    let inv = ray.dir.recip();
    let t0 = (lo - ray.origin) * inv;
    let t1 = (hi - ray.origin) * inv;
    let tmin = t0.min(t1);
    let tmax = t0.max(t1);
    // NaN (0 × ∞ on a face) is treated as no constraint by max/min of f32 in glam.
    let near = tmin.max_element().max(0.0);
    let far = tmax.min_element();
    (near <= far).then_some(near)
}

/// Distance along `ray` to triangle `a b c` (both sides), `None` when it misses.
pub fn ray_triangle(ray: &Ray, a: Vec3, b: Vec3, c: Vec3) -> Option<f32> {
    let e1 = b - a;
    let e2 = c - a;
    let p = ray.dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = ray.origin - a;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = ray.dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t >= 0.0).then_some(t)
}

/// The nearest hit of `ray` on the triangles of `clusters` (each with its scene-space box;
/// grid positions × `grid_step`), within `max_t`.
pub fn pick_clusters<'a>(
    ray: &Ray,
    clusters: impl IntoIterator<Item = ((Vec3, Vec3), &'a PageCluster)>,
    grid_step: f64,
    max_t: f32,
) -> Option<f32> {
    pick_triangle(ray, clusters, grid_step, max_t, |_| true).map(|h| h.t)
}

/// A triangle hit by a ray: the distance along it, the triangle's input object id and its
/// scene-space corners (for snapping to a vertex or an edge).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    pub t: f32,
    pub object: u32,
    pub corners: [Vec3; 3],
}

/// The nearest hit of `ray` on the triangles of `clusters` whose object `shown` accepts
/// (hidden objects are not pickable), within `max_t`; see [`pick_clusters`].
pub fn pick_triangle<'a>(
    ray: &Ray,
    clusters: impl IntoIterator<Item = ((Vec3, Vec3), &'a PageCluster)>,
    grid_step: f64,
    max_t: f32,
    shown: impl Fn(u32) -> bool,
) -> Option<TriangleHit> {
    let mut best: Option<TriangleHit> = None;
    let pos = |c: &PageCluster, i: u8| {
        c.positions.get(i as usize).map(|p| Vec3::from_array(p.map(|g| (g as f64 * grid_step) as f32)))
    };
    for ((lo, hi), c) in clusters {
        let limit = best.map_or(max_t, |b| b.t);
        match ray_box(ray, lo, hi) {
            Some(t) if t < limit => {}
            _ => continue,
        }
        for (i, tri) in c.indices.chunks_exact(3).enumerate() {
            let object = c.objects.get(i).copied().unwrap_or(u32::MAX);
            if !shown(object) {
                continue;
            }
            let (Some(a), Some(b), Some(d)) = (pos(c, tri[0]), pos(c, tri[1]), pos(c, tri[2])) else {
                continue;
            };
            if let Some(t) = ray_triangle(ray, a, b, d) {
                if t < best.map_or(max_t, |b| b.t) {
                    best = Some(TriangleHit { t, object, corners: [a, b, d] });
                }
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_hits_and_misses() {
        let r = Ray { origin: Vec3::new(0.2, 0.2, 5.0), dir: -Vec3::Z };
        let t = ray_triangle(&r, Vec3::ZERO, Vec3::X, Vec3::Y).unwrap();
        assert!((t - 5.0).abs() < 1e-5);
        let miss = Ray { origin: Vec3::new(2.0, 2.0, 5.0), dir: -Vec3::Z };
        assert!(ray_triangle(&miss, Vec3::ZERO, Vec3::X, Vec3::Y).is_none());
        let away = Ray { origin: Vec3::new(0.2, 0.2, 5.0), dir: Vec3::Z };
        assert!(ray_triangle(&away, Vec3::ZERO, Vec3::X, Vec3::Y).is_none());
    }

    #[test]
    fn box_entry_distance() {
        let r = Ray { origin: Vec3::new(-5.0, 0.5, 0.5), dir: Vec3::X };
        assert_eq!(ray_box(&r, Vec3::ZERO, Vec3::ONE), Some(5.0));
        let inside = Ray { origin: Vec3::splat(0.5), dir: Vec3::X };
        assert_eq!(ray_box(&inside, Vec3::ZERO, Vec3::ONE), Some(0.0));
        let miss = Ray { origin: Vec3::new(-5.0, 3.0, 0.5), dir: Vec3::X };
        assert_eq!(ray_box(&miss, Vec3::ZERO, Vec3::ONE), None);
    }

    /// A cluster of one triangle of object 7 over the unit square's lower-left half.
    fn one_triangle() -> PageCluster {
        PageCluster {
            positions: vec![[0, 0, 0], [1, 0, 0], [0, 1, 0]],
            indices: vec![0, 1, 2],
            objects: vec![7],
            self_error: 0.0,
            self_sphere: [0.0; 4],
            group: 0,
            level: 0,
        }
    }

    #[test]
    fn the_picked_triangle_names_its_object_and_hidden_objects_are_skipped() {
        let c = one_triangle();
        let r = Ray { origin: Vec3::new(0.2, 0.2, 5.0), dir: -Vec3::Z };
        let items = [((Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)), &c)];
        let hit = pick_triangle(&r, items, 1.0, 100.0, |_| true).unwrap();
        assert_eq!(hit.object, 7);
        assert!((hit.t - 5.0).abs() < 1e-5);
        assert_eq!(hit.corners[1], Vec3::X);
        assert!(pick_triangle(&r, items, 1.0, 100.0, |o| o != 7).is_none());
    }

    #[test]
    fn centre_pixel_ray_is_the_view_direction() {
        let c = Camera::new(Vec3::ZERO, Vec3::new(0.0, 3.0, 0.0), Vec3::Z, 1.0, 0.1, 10.0).unwrap();
        let r = camera_ray(&c, 50.0, 25.0, 100.0, 50.0);
        assert!((r.dir - Vec3::Y).length() < 1e-5);
        // The top of the image is up.
        let top = camera_ray(&c, 50.0, 0.0, 100.0, 50.0);
        assert!(top.dir.z > 0.0);
        let left = camera_ray(&c, 0.0, 25.0, 100.0, 50.0);
        assert!(left.dir.x < 0.0);
    }

    /// Orthographic picking: parallel rays from the near plane, a view 4 high and 8 wide.
    #[test]
    fn orthographic_pixel_rays_are_parallel() {
        let c = Camera::orthographic(Vec3::ZERO, Vec3::new(0.0, 3.0, 0.0), Vec3::Z, 4.0, 0.1, 10.0).unwrap();
        let centre = camera_ray(&c, 50.0, 25.0, 100.0, 50.0);
        let corner = camera_ray(&c, 100.0, 0.0, 100.0, 50.0);
        assert_eq!((centre.dir, corner.dir), (Vec3::Y, Vec3::Y));
        assert!((centre.origin - Vec3::new(0.0, 0.1, 0.0)).length() < 1e-6);
        assert!((corner.origin - Vec3::new(4.0, 0.1, 2.0)).length() < 1e-5, "{:?}", corner.origin);
    }
}
