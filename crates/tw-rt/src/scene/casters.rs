//! Which clusters can cast a shadow into the eye's view: the clusters a traced frame must hold
//! for its shadow rays besides those the eye sees.
//!
//! A shadow ray runs from a visible point — inside the eye's frustum `F` — towards the light. So
//! every shadow ray lies in the light's sweep of `F`: `{p + t·l : p ∈ F, t ≥ 0}` for a sun
//! (direction `l` towards it), the convex hull of `F` and the light's position for a point
//! light. A cluster whose box misses that volume blocks no shadow ray of the frame. The test is
//! conservative, plane by plane: a plane of `F` that also bounds the sweep (the light on its
//! inner side: `n · l ≥ 0` for a sun, the light's position inside for a point light) keeps the
//! property that a box entirely outside it misses the volume; planes the light lies beyond are
//! dropped. More planes bound the sweep from the sides the frustum's planes leave open: for a
//! sun, eight planes parallel to its direction around the frustum's corners (the sweep is a
//! prism along the light: its cross-section is bounded by an octagon); for a point light one
//! plane through the light (or the frustum corner farthest out), facing the frustum's centre.
//! A box is culled only when it is entirely outside a kept plane, so no cluster that could cast
//! is ever culled, and the eye's own clusters (inside `F`) always stay.

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec4};
use tw_runtime::frustum::grid_box;
use tw_runtime::{Camera, Frustum, Light, ResidentPage, Selection};

/// The planes that bound the light's sweep of the eye's frustum; see the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct CasterVolume {
    /// Inward unit normals and offsets: `n · p + d ≥ 0` inside.
    planes: Vec<Vec4>,
}

impl CasterVolume {
    /// The sweep of `camera`'s frustum (viewport aspect `aspect`) towards `light`.
    pub fn new(camera: &Camera, aspect: f32, light: &Light) -> CasterVolume {
        let view_proj = camera.view_projection(aspect);
        let frustum = Frustum::from_view_projection(&view_proj);
        let mut planes: Vec<Vec4> =
            frustum.planes.into_iter().filter(|&plane| bounds_the_sweep(plane, light)).collect();
        let corners = corners(&view_proj);
        match *light {
            Light::Sun { towards } => planes.extend(prism_planes(&corners, towards)),
            Light::Point { position } => planes.extend(facing_plane(&corners, position)),
        }
        CasterVolume { planes }
    }

    /// Whether a cluster in the scene-space box `min..=max` may block a shadow ray of the frame
    /// (false only when it certainly cannot).
    pub fn may_cast(&self, min: Vec3, max: Vec3) -> bool {
        self.planes.iter().all(|&plane| {
            let n = plane.truncate();
            // The box's corner farthest along the normal: inside if any corner is.
            let far = Vec3::select(n.cmpge(Vec3::ZERO), max, min);
            n.dot(far) + plane.w >= 0.0
        })
    }

    /// Drops from `selection` the clusters outside the volume: those no shadow ray of the frame
    /// can meet. Their boxes come from their decoded `pages` (sorted by page, as a streamed
    /// frame holds them), scaled by `grid_step`; a cluster whose page is not there stays (the
    /// tracer skips it anyway). Returns how many clusters were dropped.
    pub fn keep_casters(
        &self,
        selection: &mut Selection,
        pages: &[(u32, Arc<ResidentPage>)],
        grid_step: f64,
    ) -> usize {
        let before = selection.clusters.len();
        let mut dropped_triangles = 0u64;
        selection.clusters.retain(|c| {
            let Ok(i) = pages.binary_search_by_key(&c.page, |(p, _)| *p) else { return true };
            let page = &pages[i].1;
            let Some(&(lo, hi)) = page.bounds.get(c.index_in_page as usize) else { return true };
            let (min, max) = grid_box(lo, hi, grid_step);
            let keep = self.may_cast(min, max);
            if !keep {
                dropped_triangles +=
                    page.clusters.get(c.index_in_page as usize).map_or(0, |k| k.triangle_count() as u64);
            }
            keep
        });
        selection.triangles = selection.triangles.saturating_sub(dropped_triangles);
        before - selection.clusters.len()
    }
}

/// Whether the light's sweep of the frustum stays on the inner side of `plane` (one of the
/// frustum's): shadow rays leave every point of the frustum towards the light, so they stay
/// inside when the light's direction does not point outwards (sun) or the light itself is
/// inside (point light).
fn bounds_the_sweep(plane: Vec4, light: &Light) -> bool {
    let n = plane.truncate();
    match *light {
        Light::Sun { towards } => n.dot(towards) >= 0.0,
        Light::Point { position } => n.dot(position) + plane.w >= 0.0,
    }
}

/// The eight corners of the frustum of `view_proj` (clip depth 0..1).
fn corners(view_proj: &Mat4) -> [Vec3; 8] {
    let inverse = view_proj.inverse();
    std::array::from_fn(|i| {
        let ndc = Vec3::new(
            if i & 1 == 0 { -1.0 } else { 1.0 },
            if i & 2 == 0 { -1.0 } else { 1.0 },
            if i & 4 == 0 { 0.0 } else { 1.0 },
        );
        inverse.project_point3(ndc)
    })
}

/// Eight planes parallel to `towards` (a sun's direction) with every corner on their inner
/// side: their normals, perpendicular to the light, every 45° around it. Empty when the
/// corners are not finite.
fn prism_planes(corners: &[Vec3; 8], towards: Vec3) -> Vec<Vec4> {
    let (u, v) = towards.any_orthonormal_pair();
    (0..8)
        .map(|k| {
            let (sin, cos) = (k as f32 * std::f32::consts::FRAC_PI_4).sin_cos();
            u * cos + v * sin
        })
        .filter_map(|n| {
            let nearest = corners.iter().map(|c| n.dot(*c)).fold(f32::INFINITY, f32::min);
            nearest.is_finite().then(|| n.extend(margin(corners) - nearest))
        })
        .collect()
}

/// A plane with `corners` and `light` on its inner side, its normal from the light towards the
/// corners' centre: it passes through the light unless a corner lies farther out. `None` when
/// the corners are not finite (a degenerate projection) or the light is at their centre.
fn facing_plane(corners: &[Vec3; 8], light: Vec3) -> Option<Vec4> {
    let centre = corners.iter().sum::<Vec3>() / 8.0;
    let n = (centre - light).try_normalize()?;
    let nearest = corners.iter().map(|c| n.dot(*c)).fold(n.dot(light), f32::min);
    nearest.is_finite().then(|| n.extend(margin(corners) - nearest))
}

/// How far the planes made from `corners` are moved outwards: the corners come from inverting
/// the projection in f32, so they may lie a little inside the true frustum; 2⁻¹⁶ of their
/// magnitude is far beyond that rounding.
fn margin(corners: &[Vec3; 8]) -> f32 {
    corners.iter().map(|c| c.abs().max_element()).fold(0.0, f32::max) / 65_536.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Looking along +x from the origin, 90° vertical field of view, square viewport, far 100.
    fn camera() -> Camera {
        Camera::new(Vec3::ZERO, Vec3::new(10.0, 0.0, 0.0), Vec3::Z, 90f32.to_radians(), 0.1, 100.0).unwrap()
    }

    fn cube(centre: Vec3) -> (Vec3, Vec3) {
        (centre - Vec3::splat(1.0), centre + Vec3::splat(1.0))
    }

    #[test]
    fn the_eyes_clusters_always_stay() {
        for light in [
            Light::Sun { towards: Vec3::Z },
            Light::Sun { towards: -Vec3::X },
            Light::Point { position: Vec3::new(0.0, 0.0, 50.0) },
        ] {
            let volume = CasterVolume::new(&camera(), 1.0, &light);
            for x in [2.0, 20.0, 90.0] {
                let (lo, hi) = cube(Vec3::new(x, 0.0, 0.0));
                assert!(volume.may_cast(lo, hi), "{light:?}: a visible cube at x = {x} was culled");
            }
        }
    }

    #[test]
    fn a_selection_keeps_its_casters_and_loses_the_rest() {
        use tw_runtime::ClusterRef;
        use tw_store::PageCluster;
        // Grid step 0.5: a triangle in view at x = 20 and one 40 below the view.
        let triangle = |x: u32, z: u32| PageCluster {
            positions: vec![[x, 0, z], [x + 2, 0, z], [x, 2, z]],
            indices: vec![0, 1, 2],
            objects: vec![0],
            ..Default::default()
        };
        let page = Arc::new(ResidentPage::new(vec![triangle(40, 100), triangle(40, 20)]));
        let refs = |pages: &[u32]| -> Vec<ClusterRef> {
            pages
                .iter()
                .flat_map(|&p| [0, 1].map(|i| ClusterRef { page: p, index_in_page: i, group: 0 }))
                .collect()
        };
        // The view looks along +x from (0, 0, 50) (grid z = 100).
        let eye =
            Camera::new(Vec3::new(0.0, 0.0, 50.0), Vec3::new(10.0, 0.0, 50.0), Vec3::Z, 1.5, 0.1, 100.0)
                .unwrap();
        let volume = CasterVolume::new(&eye, 1.0, &Light::Sun { towards: Vec3::Z });
        // Page 7 is not resident: its clusters stay.
        let mut selection = Selection { clusters: refs(&[3, 7]), triangles: 4, ..Default::default() };
        assert_eq!(volume.keep_casters(&mut selection, &[(3, page)], 0.5), 1);
        assert_eq!(selection.clusters, [refs(&[3])[0], refs(&[7])[0], refs(&[7])[1]]);
        assert_eq!(selection.triangles, 3);
    }

    #[test]
    fn only_boxes_on_the_lights_side_are_added() {
        // A sun straight above: what hangs above the view can shade it, what lies below or
        // beside it cannot.
        let above = CasterVolume::new(&camera(), 1.0, &Light::Sun { towards: Vec3::Z });
        let check = |volume: &CasterVolume, at: Vec3| {
            let (lo, hi) = cube(at);
            volume.may_cast(lo, hi)
        };
        assert!(check(&above, Vec3::new(20.0, 0.0, 500.0)), "a roof high over the view");
        assert!(!check(&above, Vec3::new(20.0, 0.0, -50.0)), "under the view");
        assert!(!check(&above, Vec3::new(20.0, 80.0, 0.0)), "beside the view");
        assert!(!check(&above, Vec3::new(-20.0, 0.0, 0.0)), "behind the eye");
        // A sun behind the eye: what stands behind the eye shades the view.
        let behind = CasterVolume::new(&camera(), 1.0, &Light::Sun { towards: -Vec3::X });
        assert!(check(&behind, Vec3::new(-20.0, 0.0, 0.0)));
        assert!(!check(&behind, Vec3::new(20.0, 0.0, 500.0)));
        // A point light beside the view: boxes between it and the view stay, those beyond it go.
        let lamp = CasterVolume::new(&camera(), 1.0, &Light::Point { position: Vec3::new(20.0, 60.0, 0.0) });
        assert!(check(&lamp, Vec3::new(20.0, 40.0, 0.0)), "between the lamp and the view");
        assert!(!check(&lamp, Vec3::new(20.0, 90.0, 0.0)), "beyond the lamp");
    }
}
