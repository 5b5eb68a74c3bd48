//! Hard shadows by shadow rays: whether a light — the shadow-casting `tw_runtime::Light` or the
//! flashlight, both a point or a direction — reaches a surface point (Wald, Dietrich & Slusallek
//! 2004 trace their flashlight's shadows the same way). One any-hit query
//! ([`CutScene::occluded`]) per point, from the point towards the light, up to the light.
//!
//! **Leaving the surface.** The hit point carries the rounding of the primary ray and of the
//! triangle test, a few ulps of the larger of its coordinates and its distance from the eye
//! (f32 positions). The shadow ray starts [`SURFACE_OFFSET`] times that magnitude off the surface,
//! along the geometric normal on the light's side, not along the ray: a ray grazing a flat floor
//! (a low sun) then clears the floor's own triangles as well as a steep one, where an offset
//! along the ray would need to grow as 1 / sin(elevation). The offset is relative, so the same
//! rule holds for a part in millimetres and a plant in kilometres.
//!
//! **Cost.** Measured with `examples/shadow_bench.rs` on the 10^7-triangle plant, 640x480, 2
//! threads (a shared 2-core VM: medians of 9 alternating frames; the cut's selection is not
//! timed), frame time without → with a light:
//!
//! | view (`--walk K`, `--fly K`) | light | clusters (eye → light's cut) | shadow rays | ms |
//! |---|---|---|---|---|
//! | walk 300 | `sun` | 2102 → 2133 | 21 K | 44 → 62 |
//! | walk 100 | `sun:30,45` | 2003 → 2037 | 114 K | 59 → 169 |
//! | walk 100 | `sun:270,25` | 2003 → 6720 | 225 K | 67 → 328 |
//! | fly 300 | `sun` | 3555 → 3558 | 126 K | 75 → 116 |
//!
//! Shadow rays run one at a time (any-hit) at 1.2–3 M rays/s (the added shading time), against
//! 4.5–7 M rays/s for the primary rays' packets: inside the plant they start among dense
//! geometry and, when lit, must prove that nothing lies on their way. A low sun widens the
//! light's cut the most. Packets of shadow rays (a sun's are parallel) are the next step.

use glam::Vec3;
use tw_runtime::Light;

use super::cut::CutScene;
use crate::Ray;

/// How far a shadow ray starts off the surface, relative to the magnitude of the hit point (its
/// largest coordinate plus its distance from the eye): 2⁻¹⁶, 128 f32 ulps of that magnitude.
/// `tests::flat_floors_have_no_acne` measures the margin: on a floor 1000 units from the origin
/// seen from 2000 to 3000 units away (3600 hit points; suns at 90°, 20° and 2° elevation and a
/// point light), offsets of 2⁻¹² to 2⁻²² of the magnitude leave no point self-shadowed, 2⁻²³
/// leaves 4 of the 14,400 rays blocked, 2⁻²⁴ 439, 2⁻²⁶ 2884: a margin of 64. On the
/// 10^7-triangle plant's fly-over (`examples/shadow_bench.rs --fly 300`, suns `sun`,
/// `sun:30,45` and `sun:270,10`, 640x480) the shadowed pixels change by at most 0.5 % from 2⁻¹⁶
/// to 2⁻²² and grow by 3–31 % at 2⁻²⁴ (acne).
pub const SURFACE_OFFSET: f32 = 1.0 / 65_536.0;

/// A surface point hit by a primary ray: where, with which normal and how far from the eye.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub position: Vec3,
    /// Unit geometric normal of the hit triangle (either side).
    pub normal: Vec3,
    /// Distance from the ray's origin (the eye) to `position`.
    pub distance: f32,
}

impl SurfacePoint {
    /// The start of a shadow ray towards `towards` (unit): `position` moved off the surface by
    /// `offset` times the point's magnitude, on the side of the surface that faces `towards`.
    fn lifted(&self, towards: Vec3, offset: f32) -> Vec3 {
        let side = if self.normal.dot(towards) >= 0.0 { self.normal } else { -self.normal };
        let magnitude = self.position.abs().max_element() + self.distance.abs();
        self.position + side * (offset * magnitude.max(f32::MIN_POSITIVE))
    }
}

/// The visibility of `light` from `point` (1 lit, 0 blocked) and the unit direction towards
/// the light: a shadow ray through `scene`, which must hold every cluster that can cast (no clip
/// planes apply: a light sees what the camera's planes cut away).
pub fn visibility(scene: &CutScene, point: &SurfacePoint, light: &Light) -> (f32, Vec3) {
    let towards = light.towards_from(point.position);
    let blocked = scene.occluded(&shadow_ray(point, light, towards, SURFACE_OFFSET));
    (if blocked { 0.0 } else { 1.0 }, towards)
}

/// The shadow ray from `point` towards `light` (unit direction `towards`), starting `offset`
/// (relative, see [`SURFACE_OFFSET`]) off the surface and ending at the light (a sun: never).
fn shadow_ray(point: &SurfacePoint, light: &Light, towards: Vec3, offset: f32) -> Ray {
    let origin = point.lifted(towards, offset);
    let t_max = match *light {
        Light::Sun { .. } => f32::INFINITY,
        // From the lifted origin; the light itself is not geometry, so ending exactly there is
        // safe.
        Light::Point { .. } => light.distance_from(origin),
    };
    Ray { origin, dir: towards, t_min: 0.0, t_max }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use tw_store::PageCluster;

    use super::super::blas::ClusterBlas;
    use super::super::cut::Clip;
    use super::*;

    /// A square of side `size` at height `z` with its corner at `(x, y)` (grid units).
    fn square(x: u32, y: u32, z: u32, size: u32) -> PageCluster {
        PageCluster {
            positions: vec![[x, y, z], [x + size, y, z], [x + size, y + size, z], [x, y + size, z]],
            indices: vec![0, 1, 2, 0, 2, 3],
            objects: vec![0; 2],
            ..Default::default()
        }
    }

    fn scene(clusters: &[PageCluster], grid_step: f64) -> CutScene {
        let blas = clusters.iter().map(|c| Arc::new(ClusterBlas::build(c, grid_step))).collect();
        CutScene::build(blas, Clip { forward: -Vec3::Z, near: 0.01, far: 1e9, section: Default::default() })
    }

    fn sun(elevation_deg: f32) -> Light {
        let e = elevation_deg.to_radians();
        Light::Sun { towards: Vec3::new(e.cos() * 0.6, e.cos() * 0.8, e.sin()) }
    }

    /// Points on the floor where a primary ray from `eye` meets it, over a grid of `n`x`n`
    /// targets in `[lo, hi]^2`: the hit points with their rounding, as the tracer computes them.
    fn floor_hits(scene: &CutScene, eye: Vec3, lo: f32, hi: f32, n: usize) -> Vec<SurfacePoint> {
        use crate::Trace;
        let mut points = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let f = |k: usize| lo + (hi - lo) * (k as f32 + 0.5) / n as f32;
                let target = Vec3::new(f(i), f(j), 1000.0);
                let ray = Ray::new(eye, (target - eye).normalize());
                if let Some(hit) = scene.intersect(&ray) {
                    points.push(SurfacePoint { position: ray.at(hit.t), normal: Vec3::Z, distance: hit.t });
                }
            }
        }
        points
    }

    #[test]
    fn flat_floors_have_no_acne() {
        // A floor of 8x8 squares (many triangles, shared edges) at height 1000, 1000 units from
        // the origin, seen from 3000 units away: the hit points carry real rounding.
        let floor: Vec<PageCluster> =
            (0..64).map(|k| square(1000 + (k % 8) * 125, 1000 + (k / 8) * 125, 1000, 125)).collect();
        let scene = scene(&floor, 1.0);
        let eye = Vec3::new(-800.0, 200.0, 3100.0);
        let points = floor_hits(&scene, eye, 1001.0, 1999.0, 60);
        assert!(points.len() > 3000, "only {} floor hits", points.len());
        let acne = |offset: f32, light: &Light| {
            points
                .iter()
                .filter(|p| scene.occluded(&shadow_ray(p, light, light.towards_from(p.position), offset)))
                .count()
        };
        let lights =
            [sun(90.0), sun(20.0), sun(2.0), Light::Point { position: Vec3::new(1500.0, 1500.0, 1300.0) }];
        for light in &lights {
            assert_eq!(acne(SURFACE_OFFSET, light), 0, "acne with the chosen offset, {light:?}");
            assert_eq!(acne(SURFACE_OFFSET / 64.0, light), 0, "no margin below the offset, {light:?}");
        }
        // With an offset of one ulp rounding does shadow the floor: the offset is needed.
        let unprotected: usize = lights.iter().map(|l| acne(SURFACE_OFFSET / 256.0, l)).sum();
        assert!(
            unprotected > 100,
            "the floor self-shadows at {unprotected} points only: the test does not exercise rounding"
        );
    }

    #[test]
    fn a_box_over_a_floor_blocks_the_light_under_it() {
        // A floor at z = 0 and a roof at z = 5 over its middle.
        let scene = scene(&[square(0, 0, 0, 100), square(40, 40, 5, 20)], 1.0);
        let at = |x: f32, y: f32, z: f32| SurfacePoint {
            position: Vec3::new(x, y, z),
            normal: Vec3::Z,
            distance: 30.0,
        };
        for light in [Light::Sun { towards: Vec3::Z }, Light::Point { position: Vec3::new(50.0, 50.0, 20.0) }]
        {
            assert_eq!(visibility(&scene, &at(50.0, 50.0, 0.0), &light).0, 0.0, "under the roof, {light:?}");
            assert_eq!(visibility(&scene, &at(5.0, 5.0, 0.0), &light).0, 1.0, "in the open, {light:?}");
            assert_eq!(visibility(&scene, &at(50.0, 50.0, 5.0), &light).0, 1.0, "the roof's top, {light:?}");
        }
        // A point light below the roof lights the floor under it: the ray ends at the light.
        let low = Light::Point { position: Vec3::new(50.0, 50.0, 3.0) };
        let (lit, towards) = visibility(&scene, &at(45.0, 50.0, 0.0), &low);
        assert_eq!(lit, 1.0);
        assert!((towards - Vec3::new(5.0, 0.0, 3.0).normalize()).length() < 1e-6);
        // The normal may point either way: the ray leaves on the light's side.
        let flipped = SurfacePoint { normal: -Vec3::Z, ..at(5.0, 5.0, 0.0) };
        assert_eq!(visibility(&scene, &flipped, &Light::Sun { towards: Vec3::Z }).0, 1.0);
    }
}
