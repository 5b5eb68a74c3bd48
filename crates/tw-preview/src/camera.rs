//! A pinhole (or orthographic) camera: where it is, what it looks at, and how to frame a
//! bounding box.

use glam::DVec3;
use tw_core::Aabb;

/// A perspective or orthographic camera in the scene's own coordinates (f64, so that
/// georeferenced scenes with large coordinates keep their precision: everything is made relative
/// to `eye` first).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Position of the eye.
    pub eye: [f64; 3],
    /// A point the camera looks at (the image centre); also sets the scale of the near plane.
    pub target: [f64; 3],
    /// The scene's up direction; need not be perpendicular to the view, nor unit length.
    pub up: [f64; 3],
    /// Vertical field of view in degrees (clamped to 1..=170 when used); unused while
    /// `ortho_height` is set.
    pub fovy_deg: f64,
    /// `Some(height)`: an orthographic camera whose view is `height` scene units high (> 0; the
    /// width follows the image's aspect), looking along eye → target; geometry behind the near
    /// plane (in front of the eye, as in perspective) is cut away. `None`: perspective.
    pub ortho_height: Option<f64>,
}

impl Default for Camera {
    /// At (0, 0, 1) looking at the origin, Y up, 45°.
    fn default() -> Self {
        Camera {
            eye: [0.0, 0.0, 1.0],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fovy_deg: 45.0,
            ortho_height: None,
        }
    }
}

/// Field of view that [`Camera::look_at_bounds`] uses.
pub const FRAMING_FOVY_DEG: f64 = 40.0;

impl Camera {
    /// A camera that sees the whole box `bounds` from `direction`: the eye lies in `direction`
    /// from the box centre (so `[1, 1, 1]` views from the +x +y +z corner, `[0, 0, 1]` from
    /// above), far enough that the box's bounding sphere fits the vertical field of view (and the
    /// horizontal one, for images at least as wide as high). Up is +Z, or +Y when `direction` is
    /// (nearly) vertical; use [`Camera::look_at_bounds_up`] for Y-up scenes.
    ///
    /// An empty box frames the unit box at the origin; a zero `direction` means `[1, 1, 1]`.
    pub fn look_at_bounds(bounds: &Aabb, direction: [f64; 3]) -> Camera {
        Camera::look_at_bounds_up(bounds, direction, [0.0, 0.0, 1.0])
    }

    /// [`Camera::look_at_bounds`] with the scene's up direction given (falls back to another
    /// axis when `direction` is parallel to `up`).
    pub fn look_at_bounds_up(bounds: &Aabb, direction: [f64; 3], up: [f64; 3]) -> Camera {
        let finite = |p: &[f64; 3]| p.iter().all(|v| v.is_finite());
        let (center, radius) = if bounds.is_empty() || !finite(&bounds.min) || !finite(&bounds.max) {
            ([0.5; 3], 0.75f64.sqrt())
        } else {
            let r = 0.5 * bounds.diagonal();
            (bounds.center(), if r > 0.0 { r } else { 1.0 })
        };
        let dir = DVec3::from(direction)
            .try_normalize()
            .unwrap_or_else(|| DVec3::ONE.try_normalize().unwrap_or(DVec3::Z));
        let up = DVec3::from(up).try_normalize().unwrap_or(DVec3::Z);
        let up = if dir.dot(up).abs() > 0.999 {
            // Looking along up: any perpendicular axis will do; prefer the one least aligned.
            least_aligned_axis(up)
        } else {
            up
        };
        let half = (FRAMING_FOVY_DEG * 0.5).to_radians();
        let distance = radius / half.sin() * 1.02;
        Camera {
            eye: (DVec3::from(center) + dir * distance).to_array(),
            target: center,
            up: up.to_array(),
            fovy_deg: FRAMING_FOVY_DEG,
            ortho_height: None,
        }
    }

    /// Like [`Camera::look_at_bounds_up`], but tight: moves the eye along the same direction
    /// until the box's eight corners just fit an image of `aspect` (width / height), with a
    /// small margin, instead of fitting the bounding sphere. Far better framing for flat scenes
    /// (a site seen from above at an angle).
    pub fn frame_bounds(bounds: &Aabb, direction: [f64; 3], up: [f64; 3], aspect: f64) -> Camera {
        let mut cam = Camera::look_at_bounds_up(bounds, direction, up);
        if bounds.is_empty() || !aspect.is_finite() || aspect <= 0.0 {
            return cam;
        }
        let b = cam.basis();
        let center = DVec3::from(cam.target);
        let tan_y = (cam.fovy() * 0.5).tan() * 0.95;
        let tan_x = tan_y * aspect;
        let mut distance: f64 = 0.0;
        for i in 0..8 {
            let corner = DVec3::new(
                if i & 1 == 0 { bounds.min[0] } else { bounds.max[0] },
                if i & 2 == 0 { bounds.min[1] } else { bounds.max[1] },
                if i & 4 == 0 { bounds.min[2] } else { bounds.max[2] },
            );
            let c = corner - center;
            // The eye is at center - forward * d; the corner's depth is d + c·forward.
            let need_x = c.dot(b.right).abs() / tan_x - c.dot(b.forward);
            let need_y = c.dot(b.up).abs() / tan_y - c.dot(b.forward);
            distance = distance.max(need_x).max(need_y);
        }
        if distance.is_finite() && distance > 0.0 {
            cam.eye = (center - b.forward * distance).to_array();
        }
        cam
    }

    /// Orthonormal view basis: right, up, forward (unit vectors, right-handed: right = forward ×
    /// up). Degenerate inputs fall back: eye = target looks along −Z, `up` parallel to the view
    /// direction picks another up.
    pub fn basis(&self) -> Basis {
        let f = (DVec3::from(self.target) - DVec3::from(self.eye)).try_normalize().unwrap_or(DVec3::NEG_Z);
        let up = DVec3::from(self.up).try_normalize().unwrap_or(DVec3::Y);
        let ortho = |u: DVec3| (u - f * u.dot(f)).try_normalize();
        let u = ortho(up).or_else(|| ortho(least_aligned_axis(f))).unwrap_or(DVec3::Y);
        let r = f.cross(u);
        Basis { right: r, up: u, forward: f }
    }

    /// The vertical field of view in radians, clamped to 1°..=170° (45° if not finite).
    pub fn fovy(&self) -> f64 {
        let d = if self.fovy_deg.is_finite() { self.fovy_deg.clamp(1.0, 170.0) } else { 45.0 };
        d.to_radians()
    }

    /// The orthographic view height, when the camera is orthographic with a usable one (finite,
    /// > 0); `None` for perspective.
    pub fn orthographic_height(&self) -> Option<f64> {
        self.ortho_height.filter(|h| h.is_finite() && *h > 0.0)
    }

    /// Distance from eye to target (0 if they coincide or are not finite).
    pub fn target_distance(&self) -> f64 {
        let l = (DVec3::from(self.target) - DVec3::from(self.eye)).length();
        if l.is_finite() {
            l
        } else {
            0.0
        }
    }
}

/// The camera's orthonormal axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Basis {
    pub right: DVec3,
    pub up: DVec3,
    pub forward: DVec3,
}

impl Basis {
    /// `v` (a scene-space direction or offset from the eye) in camera coordinates: its
    /// components along right, up and forward.
    #[inline]
    pub fn to_camera(&self, v: DVec3) -> DVec3 {
        DVec3::new(v.dot(self.right), v.dot(self.up), v.dot(self.forward))
    }
}

/// The coordinate axis least aligned with `v`.
pub(crate) fn least_aligned_axis(v: DVec3) -> DVec3 {
    let a = v.abs();
    if a.x <= a.y && a.x <= a.z {
        DVec3::X
    } else if a.y <= a.z {
        DVec3::Y
    } else {
        DVec3::Z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: DVec3, b: DVec3) -> bool {
        (a - b).abs().max_element() < 1e-12
    }

    #[test]
    fn basis_is_orthonormal_and_right_handed() {
        let c = Camera {
            eye: [0.0, 0.0, 5.0],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fovy_deg: 60.0,
            ortho_height: None,
        };
        let b = c.basis();
        assert!(close(b.forward, DVec3::NEG_Z));
        assert!(close(b.up, DVec3::Y));
        assert!(close(b.right, DVec3::X));
    }

    #[test]
    fn degenerate_cameras_get_a_usable_basis() {
        let same =
            Camera { eye: [1.0; 3], target: [1.0; 3], up: [0.0; 3], fovy_deg: f64::NAN, ortho_height: None };
        let b = same.basis();
        assert!(close(b.forward, DVec3::NEG_Z));
        assert!((b.up.length_squared() - 1.0).abs() < 1e-12 && b.up.dot(b.forward).abs() < 1e-12);
        assert_eq!(same.fovy(), 45f64.to_radians());
        let parallel = Camera {
            eye: [0.0; 3],
            target: [0.0, 0.0, -3.0],
            up: [0.0, 0.0, 2.0],
            fovy_deg: 400.0,
            ortho_height: None,
        };
        let b = parallel.basis();
        assert!(b.up.dot(b.forward).abs() < 1e-12 && (b.right.length_squared() - 1.0).abs() < 1e-12);
        assert_eq!(parallel.fovy(), 170f64.to_radians());
    }

    #[test]
    fn look_at_bounds_centres_the_box_from_the_direction() {
        let b = Aabb::from_points(&[[0.0, 0.0, 0.0], [2.0, 4.0, 6.0]]);
        let c = Camera::look_at_bounds(&b, [0.0, -1.0, 0.0]);
        assert_eq!(c.target, [1.0, 2.0, 3.0]);
        assert!(c.eye[1] < 0.0 && (c.eye[0] - 1.0).abs() < 1e-12 && (c.eye[2] - 3.0).abs() < 1e-12);
        assert_eq!(c.up, [0.0, 0.0, 1.0]);
        // Straight down: up must change.
        let top = Camera::look_at_bounds(&b, [0.0, 0.0, 1.0]);
        assert!(top.eye[2] > 6.0);
        assert!(DVec3::from(top.up).dot(DVec3::Z).abs() < 1e-12);
    }

    #[test]
    fn look_at_bounds_of_empty_or_flat_boxes() {
        let c = Camera::look_at_bounds(&Aabb::EMPTY, [0.0; 3]);
        assert_eq!(c.target, [0.5; 3]);
        assert!(c.eye.iter().all(|v| v.is_finite() && *v > 0.5));
        let point = Aabb::from_points(&[[3.0, 3.0, 3.0]]);
        let c = Camera::look_at_bounds(&point, [1.0, 0.0, 0.0]);
        assert!(c.target_distance() > 0.0);
    }
}
