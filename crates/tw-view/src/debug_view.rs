//! Geometry of the third-person debug view, plain data in and out. It follows the papers'
//! debug figures (GigaWalk, Baxter et al. 2002, Figure 5; Yoon et al. 2003, Figure 7): the
//! culling camera is frozen, a second camera is moved out, and the frozen camera's view
//! frustum is drawn together with the bounding boxes of the nodes found visible (pink) and
//! occluded (yellow).
//!
//! - [`frustum_corners`] / [`frustum_edges`]: the 12 edges of a camera's frustum (far plane
//!   optionally pulled in so it stays readable);
//! - [`box_edges`]: the 12 edges of an axis-aligned box;
//! - [`project_segment`]: a scene segment seen by the debug camera, clipped against the near
//!   plane, in window pixels (y down); the UI draws the results as 2D lines over the image;
//! - [`third_person`]: a starting point for the second camera, behind and above the frozen one.

use glam::{Mat4, Vec3, Vec4};
use tw_runtime::{Camera, Projection};

/// The third-person camera's field of view behind an orthographic camera (60°).
const THIRD_PERSON_FOVY: f32 = std::f32::consts::FRAC_PI_3;

/// Colour of visible nodes' boxes (sRGB).
pub const VISIBLE_COLOR: [u8; 4] = [255, 105, 180, 255];
/// Colour of occluded nodes' boxes (sRGB).
pub const OCCLUDED_COLOR: [u8; 4] = [255, 220, 40, 255];
/// Colour of the frozen camera's frustum.
pub const FRUSTUM_COLOR: [u8; 4] = [40, 220, 255, 255];

/// A line segment in scene space.
pub type Segment = (Vec3, Vec3);

/// The 8 corners of `camera`'s frustum for `aspect` (near plane first: bottom-left,
/// bottom-right, top-right, top-left, then the far plane in the same order). The far plane is
/// placed at `far` (≤ the camera's) when given.
pub fn frustum_corners(camera: &Camera, aspect: f32, far: Option<f32>) -> [Vec3; 8] {
    let far = far.map_or(camera.far, |f| f.clamp(camera.near * 2.0, camera.far));
    let c = Camera { far, ..*camera };
    let inv = c.view_projection(aspect).inverse();
    let ndc = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
    let mut out = [Vec3::ZERO; 8];
    for (k, z) in [0.0f32, 1.0].into_iter().enumerate() {
        for (i, [x, y]) in ndc.into_iter().enumerate() {
            let p = inv * Vec4::new(x, y, z, 1.0);
            out[k * 4 + i] = p.truncate() / p.w;
        }
    }
    out
}

/// The 12 edges of a frustum from its [`frustum_corners`].
pub fn frustum_edges(c: &[Vec3; 8]) -> [Segment; 12] {
    let mut e = [(Vec3::ZERO, Vec3::ZERO); 12];
    for i in 0..4 {
        e[i] = (c[i], c[(i + 1) % 4]);
        e[4 + i] = (c[4 + i], c[4 + (i + 1) % 4]);
        e[8 + i] = (c[i], c[4 + i]);
    }
    e
}

/// The 12 edges of the box `lo`..`hi`.
pub fn box_edges(lo: Vec3, hi: Vec3) -> [Segment; 12] {
    let p = |i: u32| {
        Vec3::new(
            if i & 1 != 0 { hi.x } else { lo.x },
            if i & 2 != 0 { hi.y } else { lo.y },
            if i & 4 != 0 { hi.z } else { lo.z },
        )
    };
    const EDGES: [(u32, u32); 12] =
        [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)];
    EDGES.map(|(a, b)| (p(a), p(b)))
}

/// `seg` through `view_proj` (any depth convention) into a `size` = (width, height) pixel
/// viewport, y down; the part behind the near plane (clip w ≤ ε) is cut away. `None` when
/// nothing is in front.
pub fn project_segment(view_proj: &Mat4, seg: Segment, size: [f32; 2]) -> Option<([f32; 2], [f32; 2])> {
    const EPS: f32 = 1e-6;
    let mut a = *view_proj * seg.0.extend(1.0);
    let mut b = *view_proj * seg.1.extend(1.0);
    if a.w <= EPS && b.w <= EPS {
        return None;
    }
    if a.w <= EPS || b.w <= EPS {
        let t = (EPS - a.w) / (b.w - a.w);
        let m = a + (b - a) * t;
        if a.w <= EPS {
            a = m;
        } else {
            b = m;
        }
    }
    let px = |v: Vec4| [(v.x / v.w * 0.5 + 0.5) * size[0], (0.5 - v.y / v.w * 0.5) * size[1]];
    let (pa, pb) = (px(a), px(b));
    // Segments far outside the viewport are dropped (the painter would clip them anyway, but
    // huge coordinates lose precision).
    let lim = 64.0 * size[0].max(size[1]);
    if pa.iter().chain(&pb).any(|v| !v.is_finite() || v.abs() > lim) {
        return None;
    }
    Some((pa, pb))
}

/// A second camera for the debug view: behind and above `frozen`, looking at a point ahead of
/// it, `scene_size` scaling the step back.
pub fn third_person(frozen: &Camera, scene_size: f32) -> Camera {
    let d = frozen.direction();
    let up = frozen.up.normalize_or(Vec3::Z);
    let back = scene_size * 0.15;
    let look = frozen.eye + d * back;
    let eye = frozen.eye - d * back + up * back * 0.8;
    let far = frozen.far + back * 3.0;
    // Perspective even behind an orthographic camera: the box of its view then shows as one.
    let projection = match frozen.projection {
        Projection::Perspective { .. } => frozen.projection,
        Projection::Orthographic { .. } => Projection::Perspective { fovy: THIRD_PERSON_FOVY },
    };
    Camera { eye, target: look, up, projection, near: frozen.near, far }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::new(Vec3::ZERO, Vec3::X, Vec3::Z, 90f32.to_radians(), 0.1, 100.0).unwrap()
    }

    #[test]
    fn frustum_corners_lie_on_the_clip_planes() {
        let c = frustum_corners(&cam(), 1.0, Some(10.0));
        for p in &c[..4] {
            assert!((p.x - 0.1).abs() < 1e-4, "{p:?}");
        }
        for p in &c[4..] {
            assert!((p.x - 10.0).abs() < 1e-2, "{p:?}");
            // 90° vertical and aspect 1: half-width = distance.
            assert!((p.y.abs() - 10.0).abs() < 1e-2 && (p.z.abs() - 10.0).abs() < 1e-2, "{p:?}");
        }
        let e = frustum_edges(&c);
        assert!(e.iter().all(|(a, b)| a != b));
    }

    #[test]
    fn box_edges_are_the_twelve_unit_edges() {
        let e = box_edges(Vec3::ZERO, Vec3::ONE);
        assert!(e.iter().all(|(a, b)| ((*a - *b).length() - 1.0).abs() < 1e-6));
        let mut set: Vec<_> = e.iter().map(|(a, b)| format!("{a:?}{b:?}")).collect();
        set.dedup();
        assert_eq!(set.len(), 12);
    }

    #[test]
    fn segments_are_projected_and_clipped_at_the_near_plane() {
        let c = cam();
        let vp = c.view_projection(1.0);
        let size = [200.0, 100.0];
        // Straight ahead: the centre of the image.
        let (a, _) =
            project_segment(&vp, (Vec3::new(10.0, 0.0, 0.0), Vec3::new(20.0, 0.0, 0.0)), size).unwrap();
        assert!((a[0] - 100.0).abs() < 1e-3 && (a[1] - 50.0).abs() < 1e-3);
        // Above the axis is up in the image (smaller y); to the left (+Y) is smaller x.
        let (a, _) =
            project_segment(&vp, (Vec3::new(10.0, 5.0, 5.0), Vec3::new(10.0, 5.0, 5.0)), size).unwrap();
        assert!(a[0] < 100.0 && a[1] < 50.0, "{a:?}");
        // Entirely behind: nothing; crossing the eye plane: clipped but present.
        assert!(project_segment(&vp, (Vec3::new(-5.0, 0.0, 0.0), Vec3::new(-1.0, 1.0, 0.0)), size).is_none());
        assert!(
            project_segment(&vp, (Vec3::new(-5.0, 1.0, 0.0), Vec3::new(5.0, 1.0, 0.0)), size).is_none()
                || project_segment(&vp, (Vec3::new(-5.0, 1.0, 0.0), Vec3::new(5.0, 1.0, 0.0)), size)
                    .is_some_and(|(a, b)| a.iter().chain(&b).all(|v| v.is_finite()))
        );
    }

    #[test]
    fn third_person_camera_sees_the_frozen_eye() {
        let f = cam();
        let t = third_person(&f, 100.0);
        assert!(t.validate().is_ok());
        let vp = t.view_projection(1.0);
        let (a, _) = project_segment(&vp, (f.eye, f.eye), [100.0, 100.0]).unwrap();
        assert!((0.0..=100.0).contains(&a[0]) && (0.0..=100.0).contains(&a[1]), "{a:?}");
    }
}
