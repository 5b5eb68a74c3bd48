//! The camera of one frame, in scene space (docs/DESIGN.md, D10: runtime math is f32 in scene
//! space, i.e. store grid coordinates × `grid_step`, relative to the grid origin).
//!
//! Conventions, as wgpu expects them:
//! - right-handed view space (the camera looks down −Z, +Y up), [`Camera::view`] is `look_at_rh`;
//! - clip-space depth 0..1: [`Camera::projection`] maps the near plane to depth 0 and the far
//!   plane to 1; [`Camera::projection_reverse_z`] maps near to 1 and far to 0 (use it with a
//!   `Greater` depth test and a clear depth of 0: far better depth precision for walkthroughs,
//!   whose near/far ratios are 10⁻⁵ and below). Both give the same frustum planes
//!   ([`crate::frustum::Frustum::from_view_projection`] works with either).
//!
//! A camera is perspective or orthographic ([`Projection`]). The orthographic camera keeps an
//! eye, a view direction and near/far planes (view depths measured from the eye along the view
//! direction, as in perspective), so everything that clips, culls and sorts by depth works on
//! both; only the projection differs: a view `height` in scene units instead of a field of view,
//! parallel projection rays, and a pixel size that does not depend on distance. The places that
//! need the difference ask the camera: [`Camera::projection`] (and the reverse-Z form),
//! [`Camera::pixel_scale`] / [`Camera::pixels`] (LOD selection's pixel error),
//! [`Camera::view_height_at`] (the size of the view at a depth), [`Camera::view_depth_reverse_z`]
//! (a depth-buffer value back to a view depth) and [`Camera::to_viewer`] (the direction towards
//! the viewer, for two-sided shading). tw-rt generates the primary rays of both from
//! `tw_rt::Camera::for_view`.
//!
//! Users give cameras in *input* coordinates (the units of the files they built from):
//! [`InputCamera`] parses the command-line form `"x,y,z;x,y,z;x,y,z;fovy"` (eye; target; up;
//! vertical field of view in degrees, as `terawalk preview --camera` accepts) and
//! [`InputCamera::to_scene`] / [`Camera::from_input_coordinates`] rebase it to scene space by
//! subtracting the store's grid origin.

use std::str::FromStr;

use glam::{DVec3, Mat4, Vec3, Vec4};
use tw_store::Header;

use crate::error::RuntimeError;

/// How a camera projects the scene onto its image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Central projection from the eye: `fovy` is the vertical field of view in radians, in
    /// (0, π).
    Perspective { fovy: f32 },
    /// Parallel projection along the view direction: `height` is the height of the view in
    /// scene units (> 0; its width is `height × aspect`), the same at every depth.
    Orthographic { height: f32 },
}

impl Projection {
    /// Whether this is the orthographic projection.
    pub fn is_orthographic(self) -> bool {
        matches!(self, Projection::Orthographic { .. })
    }

    /// The projection widened by `factor`: a perspective field of view times `factor` (at most
    /// 179°), an orthographic height times `factor`. Prefetching looks ahead with a widened
    /// camera.
    pub fn widened(self, factor: f32) -> Projection {
        match self {
            Projection::Perspective { fovy } => {
                Projection::Perspective { fovy: (fovy * factor).min(179f32.to_radians()) }
            }
            Projection::Orthographic { height } => Projection::Orthographic { height: height * factor },
        }
    }
}

/// A camera in scene space: perspective or orthographic ([`Projection`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    /// Approximate up direction (need not be unit length or orthogonal to the view direction).
    pub up: Vec3,
    /// Perspective (a field of view) or orthographic (a view height).
    pub projection: Projection,
    /// Distance of the near clip plane (> 0).
    pub near: f32,
    /// Distance of the far clip plane (> near).
    pub far: f32,
}

/// The field of view (degrees) of cameras given without one: `ortho:` camera strings
/// ([`InputCamera::parse`]).
pub const DEFAULT_FOVY_DEG: f64 = 60.0;

/// Near plane distance as a fraction of the far plane distance, for cameras given without
/// clip planes ([`Camera::from_input_coordinates`]). With reverse-Z f32 depth this still leaves
/// ample precision.
pub const NEAR_FAR_RATIO: f32 = 1e-5;

impl Camera {
    /// A perspective camera from its parts (`fovy` in radians), checked with
    /// [`validate`](Self::validate).
    pub fn new(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        fovy: f32,
        near: f32,
        far: f32,
    ) -> Result<Camera, RuntimeError> {
        Camera::with_projection(eye, target, up, Projection::Perspective { fovy }, near, far)
    }

    /// An orthographic camera from its parts (`height`: the view's height in scene units),
    /// checked with [`validate`](Self::validate).
    pub fn orthographic(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        height: f32,
        near: f32,
        far: f32,
    ) -> Result<Camera, RuntimeError> {
        Camera::with_projection(eye, target, up, Projection::Orthographic { height }, near, far)
    }

    /// A camera of either projection, checked with [`validate`](Self::validate).
    pub fn with_projection(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        projection: Projection,
        near: f32,
        far: f32,
    ) -> Result<Camera, RuntimeError> {
        let c = Camera { eye, target, up, projection, near, far };
        c.validate()?;
        Ok(c)
    }

    /// Checks that the camera gives a view: finite values, eye ≠ target, `up` not parallel to
    /// the view direction, 0 < fovy < π (perspective) or a finite height > 0 (orthographic),
    /// 0 < near < far.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        let bad = |m: String| Err(RuntimeError::Camera(m));
        if !(self.eye.is_finite() && self.target.is_finite() && self.up.is_finite()) {
            return bad(format!(
                "eye {:?}, target {:?} and up {:?} must be finite (in scene space)",
                self.eye, self.target, self.up
            ));
        }
        let dir = self.target - self.eye;
        if dir.length_squared() == 0.0 || !dir.length_squared().is_finite() {
            return bad(format!("eye and target are the same point {:?}", self.eye));
        }
        let side = dir.normalize().cross(self.up.normalize_or_zero());
        if side.length_squared() < 1e-10 {
            return bad(format!("up {:?} is parallel to the view direction {:?}", self.up, dir));
        }
        match self.projection {
            Projection::Perspective { fovy } => {
                if !(fovy > 0.0 && fovy < std::f32::consts::PI) {
                    return bad(format!("vertical field of view {fovy} rad must be in (0, π)"));
                }
            }
            Projection::Orthographic { height } => {
                if !(height > 0.0 && height.is_finite()) {
                    return bad(format!("orthographic view height {height} must be finite and > 0"));
                }
            }
        }
        if !(self.near > 0.0 && self.near < self.far && self.far.is_finite()) {
            return bad(format!("clip planes near {} / far {} need 0 < near < far < ∞", self.near, self.far));
        }
        Ok(())
    }

    /// A camera given in input coordinates (f64, the units of the input files): eye and target
    /// are rebased to scene space by subtracting the grid origin; `up` is a direction and is
    /// kept. The clip planes are chosen to see the whole scene: `far` reaches the farthest corner
    /// of the store's bounds (plus 1 %), `near` = `far` × [`NEAR_FAR_RATIO`].
    pub fn from_input_coordinates(
        eye: [f64; 3],
        target: [f64; 3],
        up: [f64; 3],
        fovy_deg: f64,
        header: &Header,
    ) -> Result<Camera, RuntimeError> {
        let origin = DVec3::from_array(header.grid_origin);
        let eye_s = DVec3::from_array(eye) - origin;
        let target_s = DVec3::from_array(target) - origin;
        let lo = DVec3::from_array(header.bounds_min) - origin;
        let hi = DVec3::from_array(header.bounds_max) - origin;
        // The farthest corner of the bounds from the eye.
        let far_corner = DVec3::new(
            (eye_s.x - lo.x).abs().max((eye_s.x - hi.x).abs()),
            (eye_s.y - lo.y).abs().max((eye_s.y - hi.y).abs()),
            (eye_s.z - lo.z).abs().max((eye_s.z - hi.z).abs()),
        )
        .length();
        let far = (far_corner * 1.01).max(header.grid_step * 1024.0);
        let far = far as f32;
        Camera::new(
            eye_s.as_vec3(),
            target_s.as_vec3(),
            DVec3::from_array(up).as_vec3(),
            fovy_deg.to_radians() as f32,
            far * NEAR_FAR_RATIO,
            far,
        )
    }

    /// Unit view direction.
    pub fn direction(&self) -> Vec3 {
        (self.target - self.eye).normalize_or_zero()
    }

    /// World (scene) to view space, right-handed.
    pub fn view(&self) -> Mat4 {
        look_at_rh(self.eye, self.target, self.up)
    }

    /// Whether the camera is orthographic.
    pub fn is_orthographic(&self) -> bool {
        self.projection.is_orthographic()
    }

    /// The projection matrix, depth 0 at `near` and 1 at `far`. `aspect` = width / height.
    pub fn projection(&self, aspect: f32) -> Mat4 {
        self.projection_between(aspect, self.near, self.far)
    }

    /// Reverse-Z projection: depth 1 at `near` and 0 at `far`. For the orthographic camera the
    /// depth is linear in the view depth, `(far − z) / (far − near)`: f32 keeps it to about
    /// 10⁻⁷ × (far − near) everywhere, so reverse-Z changes little there but costs nothing.
    pub fn projection_reverse_z(&self, aspect: f32) -> Mat4 {
        self.projection_between(aspect, self.far, self.near)
    }

    /// [`perspective_rh`] or [`orthographic_rh`] with depth 0 at view depth `z_near` and 1 at
    /// `z_far`.
    fn projection_between(&self, aspect: f32, z_near: f32, z_far: f32) -> Mat4 {
        match self.projection {
            Projection::Perspective { fovy } => perspective_rh(fovy, aspect, z_near, z_far),
            Projection::Orthographic { height } => orthographic_rh(height, aspect, z_near, z_far),
        }
    }

    /// The view depth (distance along the view direction from the eye) of a depth-buffer value
    /// written with [`projection_reverse_z`](Self::projection_reverse_z): its inverse along the
    /// view axis.
    pub fn view_depth_reverse_z(&self, depth: f32) -> f32 {
        let (n, f) = (self.near as f64, self.far as f64);
        let d = depth as f64;
        let z = match self.projection {
            // depth = n (f − z) / (z (f − n)).
            Projection::Perspective { .. } => n * f / (d * (f - n) + n),
            // depth = (f − z) / (f − n).
            Projection::Orthographic { .. } => f - d * (f - n),
        };
        z as f32
    }

    /// The height in scene units of the view at view depth `depth`: `2 depth tan(fovy / 2)` in
    /// perspective, the view height (at every depth) in orthographic.
    pub fn view_height_at(&self, depth: f64) -> f64 {
        match self.projection {
            Projection::Perspective { fovy } => 2.0 * depth * (fovy as f64 * 0.5).tan(),
            Projection::Orthographic { height } => height as f64,
        }
    }

    /// `projection(aspect) * view()`.
    pub fn view_projection(&self, aspect: f32) -> Mat4 {
        self.projection(aspect) * self.view()
    }

    /// The shading's headlight: the unit direction from the target towards the eye (both
    /// renderers shade by it: tw-gpu's draw.wgsl and tw-rt).
    pub fn headlight(&self) -> Vec3 {
        (self.eye - self.target).normalize_or(Vec3::Z)
    }

    /// The shading's sun: a unit direction from above (the camera's up), tilted towards a fixed
    /// scene direction, so that faces of different orientation differ in brightness.
    pub fn sun_direction(&self) -> Vec3 {
        let up = self.up.normalize_or(Vec3::Z);
        let tilt = if up.dot(Vec3::X).abs() < 0.9 { Vec3::X } else { Vec3::Y };
        (up * 0.8 + (tilt - up * tilt.dot(up)).normalize_or_zero() * 0.35).normalize_or(up)
    }

    /// The unit direction from the scene point `p` towards the viewer: towards the eye in
    /// perspective, against the view direction (the [`headlight`](Self::headlight)) in
    /// orthographic, where every projection ray is parallel. Two-sided shading turns normals
    /// this way (tw-gpu's draw.wgsl, tw-rt's shader).
    pub fn to_viewer(&self, p: Vec3) -> Vec3 {
        match self.projection {
            Projection::Perspective { .. } => (self.eye - p).normalize_or_zero(),
            Projection::Orthographic { .. } => self.headlight(),
        }
    }

    /// Pixels per scene unit, for a viewport `viewport_height` pixels high (docs/DESIGN.md,
    /// D3): in perspective `H / (2 tan(fovy / 2))`, the pixels of a unit size at unit distance
    /// (divide by the distance, [`pixels`](Self::pixels)); in orthographic `H / height`, the
    /// pixels of a unit size at any distance.
    pub fn pixel_scale(&self, viewport_height: f32) -> f64 {
        let h = viewport_height as f64;
        match self.projection {
            Projection::Perspective { fovy } => h / (2.0 * (fovy as f64 / 2.0).tan()),
            Projection::Orthographic { height } => h / height as f64,
        }
    }

    /// Pixels that a size `size` (scene units) covers at `distance` from the eye (> 0), for a
    /// viewport `viewport_height` pixels high: [`pixel_scale`](Self::pixel_scale) divided by the
    /// distance in perspective, independent of the distance in orthographic. LOD selection's
    /// [`crate::LodMetric`] evaluates this (with its own clamping of the distance).
    pub fn pixels(&self, size: f64, distance: f64, viewport_height: f32) -> f64 {
        pixels_at(size, self.pixel_scale(viewport_height), self.is_orthographic(), distance)
    }
}

/// `size × scale / distance` (perspective) or `size × scale` (orthographic): the one formula of
/// [`Camera::pixels`], shared with [`crate::LodMetric`].
#[inline]
pub(crate) fn pixels_at(size: f64, scale: f64, orthographic: bool, distance: f64) -> f64 {
    if orthographic {
        size * scale
    } else {
        size * scale / distance
    }
}

/// Right-handed view matrix (looking down −Z), as `gluLookAt`.
pub fn look_at_rh(eye: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let f = (target - eye).normalize();
    let s = f.cross(up).normalize();
    let u = s.cross(f);
    Mat4::from_cols(
        Vec4::new(s.x, u.x, -f.x, 0.0),
        Vec4::new(s.y, u.y, -f.y, 0.0),
        Vec4::new(s.z, u.z, -f.z, 0.0),
        Vec4::new(-s.dot(eye), -u.dot(eye), f.dot(eye), 1.0),
    )
}

/// Right-handed perspective projection to depth 0..1: view-space `z = −z_near` maps to depth 0
/// and `z = −z_far` to 1. Passing far as `z_near` and near as `z_far` gives reverse-Z.
pub fn perspective_rh(fovy: f32, aspect: f32, z_near: f32, z_far: f32) -> Mat4 {
    let h = 1.0 / (0.5 * fovy).tan();
    let w = h / aspect;
    let r = z_far / (z_near - z_far);
    Mat4::from_cols(
        Vec4::new(w, 0.0, 0.0, 0.0),
        Vec4::new(0.0, h, 0.0, 0.0),
        Vec4::new(0.0, 0.0, r, -1.0),
        Vec4::new(0.0, 0.0, r * z_near, 0.0),
    )
}

/// Right-handed orthographic projection to depth 0..1 of a view `height` high and
/// `height × aspect` wide: view-space `z = −z_near` maps to depth 0 and `z = −z_far` to 1.
/// Passing far as `z_near` and near as `z_far` gives reverse-Z, as for [`perspective_rh`].
pub fn orthographic_rh(height: f32, aspect: f32, z_near: f32, z_far: f32) -> Mat4 {
    let h = 2.0 / height;
    let w = h / aspect;
    let r = 1.0 / (z_near - z_far);
    Mat4::from_cols(
        Vec4::new(w, 0.0, 0.0, 0.0),
        Vec4::new(0.0, h, 0.0, 0.0),
        Vec4::new(0.0, 0.0, r, 0.0),
        Vec4::new(0.0, 0.0, r * z_near, 1.0),
    )
}

/// A camera as the user gives it: input coordinates, field of view in degrees, or an
/// orthographic view height in input units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputCamera {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
    /// Vertical field of view, degrees. An orthographic camera keeps one too: the perspective
    /// it returns to (the viewer's O key), and what readers that know only perspective use.
    pub fovy_deg: f64,
    /// `Some(height)`: orthographic, the view `height` input units high (input and scene units
    /// are the same; scene space only moves the origin). `None`: perspective.
    pub ortho_height: Option<f64>,
}

impl InputCamera {
    /// Parses `"x,y,z;x,y,z;x,y,z;fovy"`: eye; target; up; vertical field of view in degrees
    /// (1..=179), or `ortho:HEIGHT` for an orthographic camera whose view is HEIGHT input units
    /// high (its `fovy_deg` is then [`DEFAULT_FOVY_DEG`]). Whitespace around numbers is allowed.
    /// Eye and target must differ.
    pub fn parse(s: &str) -> Result<InputCamera, RuntimeError> {
        let err = |msg: String| RuntimeError::CameraParse { input: s.to_string(), msg };
        let parts: Vec<&str> = s.split(';').map(str::trim).collect();
        let [eye, target, up, fovy] = parts.as_slice() else {
            return Err(err(format!(
                "expected \"eye;target;up;fovy\" (eye, target, up as x,y,z; fovy in degrees), got {} \
                 part(s)",
                parts.len()
            )));
        };
        let vec3 = |p: &str, what: &str| -> Result<[f64; 3], RuntimeError> {
            let mut v = [0f64; 3];
            let mut n = 0;
            for c in p.split(',') {
                let x: f64 =
                    c.trim().parse().map_err(|_| err(format!("bad number {:?} in {what}", c.trim())))?;
                if !x.is_finite() {
                    return Err(err(format!("{what} must be finite, got {:?}", c.trim())));
                }
                if n < 3 {
                    v[n] = x;
                }
                n += 1;
            }
            if n != 3 {
                return Err(err(format!("{what} must be three numbers x,y,z, got {p:?}")));
            }
            Ok(v)
        };
        let (fovy_deg, ortho_height) = match fovy.strip_prefix("ortho:") {
            Some(h) => {
                let h: f64 = h.trim().parse().map_err(|_| err(format!("bad orthographic height {h:?}")))?;
                if !(h > 0.0 && h.is_finite()) {
                    return Err(err(format!("orthographic height must be finite and > 0, got {h}")));
                }
                (DEFAULT_FOVY_DEG, Some(h))
            }
            None => (fovy.parse().map_err(|_| err(format!("bad field of view {fovy:?}")))?, None),
        };
        let cam = InputCamera {
            eye: vec3(eye, "eye")?,
            target: vec3(target, "target")?,
            up: vec3(up, "up")?,
            fovy_deg,
            ortho_height,
        };
        if !(1.0..=179.0).contains(&cam.fovy_deg) {
            return Err(err(format!("field of view must be 1..=179 degrees, got {}", cam.fovy_deg)));
        }
        if cam.eye == cam.target {
            return Err(err("eye and target are the same point".into()));
        }
        if cam.up == [0.0; 3] {
            return Err(err("up must not be zero".into()));
        }
        let [d, u] = [sub(cam.target, cam.eye), cam.up];
        let cross = [d[1] * u[2] - d[2] * u[1], d[2] * u[0] - d[0] * u[2], d[0] * u[1] - d[1] * u[0]];
        let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if norm(cross) <= 1e-9 * norm(d) * norm(u) {
            return Err(err("up must not point along the view direction (eye to target)".into()));
        }
        Ok(cam)
    }

    /// The scene-space camera for a store (see [`Camera::from_input_coordinates`]), with the
    /// orthographic projection when [`ortho_height`](Self::ortho_height) is set.
    pub fn to_scene(&self, header: &Header) -> Result<Camera, RuntimeError> {
        let c = Camera::from_input_coordinates(self.eye, self.target, self.up, self.fovy_deg, header)?;
        match self.ortho_height {
            None => Ok(c),
            Some(h) => Camera::with_projection(
                c.eye,
                c.target,
                c.up,
                Projection::Orthographic { height: h as f32 },
                c.near,
                c.far,
            ),
        }
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

impl FromStr for InputCamera {
    type Err = RuntimeError;
    fn from_str(s: &str) -> Result<InputCamera, RuntimeError> {
        InputCamera::parse(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(origin: [f64; 3], step: f64, min: [f64; 3], max: [f64; 3]) -> Header {
        Header::empty(min, max, origin, step)
    }

    fn cam() -> Camera {
        Camera::new(Vec3::ZERO, Vec3::new(0.0, 0.0, -10.0), Vec3::Y, 60f32.to_radians(), 0.5, 100.0).unwrap()
    }

    fn depth(m: Mat4, p: Vec3) -> f32 {
        let c = m * Vec4::new(p.x, p.y, p.z, 1.0);
        c.z / c.w
    }

    #[test]
    fn projection_maps_near_to_0_and_far_to_1() {
        let c = cam();
        let m = c.view_projection(1.5);
        assert!(depth(m, Vec3::new(0.0, 0.0, -0.5)).abs() < 1e-6);
        assert!((depth(m, Vec3::new(0.0, 0.0, -100.0)) - 1.0).abs() < 1e-5);
    }

    #[test]
    fn reverse_z_maps_near_to_1_and_far_to_0() {
        let c = cam();
        let m = c.projection_reverse_z(1.5) * c.view();
        assert!((depth(m, Vec3::new(0.0, 0.0, -0.5)) - 1.0).abs() < 1e-5);
        assert!(depth(m, Vec3::new(0.0, 0.0, -100.0)).abs() < 1e-6);
    }

    #[test]
    fn view_is_right_handed_looking_down_minus_z() {
        let c = Camera::new(Vec3::new(5.0, 0.0, 0.0), Vec3::ZERO, Vec3::Z, 1.0, 0.1, 10.0).unwrap();
        let v = c.view() * Vec4::new(0.0, 0.0, 0.0, 1.0);
        assert!((v.z + 5.0).abs() < 1e-6, "target straight ahead at -5: {v:?}");
        let up = c.view() * Vec4::new(5.0, 0.0, 1.0, 1.0);
        assert!(up.y > 0.9, "scene +Z is view +Y: {up:?}");
    }

    #[test]
    fn invalid_cameras_are_rejected() {
        let ok = cam();
        for c in [
            Camera { target: ok.eye, ..ok },
            Camera { up: Vec3::new(0.0, 0.0, 3.0), ..ok },
            Camera { up: Vec3::ZERO, ..ok },
            Camera { projection: Projection::Perspective { fovy: 0.0 }, ..ok },
            Camera { projection: Projection::Perspective { fovy: std::f32::consts::PI }, ..ok },
            Camera { projection: Projection::Orthographic { height: 0.0 }, ..ok },
            Camera { projection: Projection::Orthographic { height: f32::INFINITY }, ..ok },
            Camera { projection: Projection::Orthographic { height: f32::NAN }, ..ok },
            Camera { near: 0.0, ..ok },
            Camera { near: 200.0, ..ok },
            Camera { far: f32::INFINITY, ..ok },
            Camera { eye: Vec3::new(f32::NAN, 0.0, 0.0), ..ok },
        ] {
            assert!(c.validate().is_err(), "{c:?}");
        }
    }

    #[test]
    fn input_coordinates_are_rebased_to_the_grid_origin() {
        let h = header([1000.0, 2000.0, 3000.0], 0.01, [1000.0, 2000.0, 3000.0], [1010.0, 2010.0, 3010.0]);
        let c = Camera::from_input_coordinates(
            [1005.0, 1990.0, 3005.0],
            [1005.0, 2005.0, 3005.0],
            [0.0, 0.0, 1.0],
            60.0,
            &h,
        )
        .unwrap();
        assert_eq!(c.eye, Vec3::new(5.0, -10.0, 5.0));
        assert_eq!(c.target, Vec3::new(5.0, 5.0, 5.0));
        assert_eq!(c.up, Vec3::Z);
        assert_eq!(c.projection, Projection::Perspective { fovy: 60f32.to_radians() });
        // Far reaches the farthest corner (5, 20, 5) away.
        let corner = (25.0f32 + 400.0 + 25.0).sqrt();
        assert!(c.far >= corner && c.far < corner * 1.02, "far {}", c.far);
        assert!((c.near - c.far * NEAR_FAR_RATIO).abs() < 1e-9);
    }

    #[test]
    fn camera_string_parses_in_input_coordinates() {
        let c = InputCamera::parse("1,2,3; 4, 5 ,6;0,0,1; 60").unwrap();
        assert_eq!(
            c,
            InputCamera {
                eye: [1.0, 2.0, 3.0],
                target: [4.0, 5.0, 6.0],
                up: [0.0, 0.0, 1.0],
                fovy_deg: 60.0,
                ortho_height: None,
            }
        );
        let c: InputCamera = "-1e3,0,0;0,0,0;0,1,0;90".parse().unwrap();
        assert_eq!(c.eye, [-1000.0, 0.0, 0.0]);
    }

    #[test]
    fn bad_camera_strings_are_errors() {
        for s in [
            "",
            "1,2,3;4,5,6;0,0,1",
            "1,2,3;4,5,6;0,0,1;60;7",
            "1,2;4,5,6;0,0,1;60",
            "1,2,3,4;4,5,6;0,0,1;60",
            "1,2,x;4,5,6;0,0,1;60",
            "nan,2,3;4,5,6;0,0,1;60",
            "inf,2,3;4,5,6;0,0,1;60",
            "1,2,3;4,5,6;0,0,1;0",
            "1,2,3;4,5,6;0,0,1;180",
            "1,2,3;4,5,6;0,0,1;abc",
            "1,2,3;1,2,3;0,0,1;60",
            "1,2,3;4,5,6;0,0,0;60",
        ] {
            let e = InputCamera::parse(s).expect_err(s);
            assert!(e.to_string().contains("camera"), "{s}: {e}");
        }
    }

    #[test]
    fn pixel_scale_is_half_height_over_tan_half_fovy() {
        let c = Camera { projection: Projection::Perspective { fovy: 90f32.to_radians() }, ..cam() };
        assert!((c.pixel_scale(1000.0) - 500.0).abs() < 1e-3);
        assert!((c.pixels(2.0, 10.0, 1000.0) - 100.0).abs() < 1e-3, "2 units at distance 10");
    }

    /// Looking down −Z from the origin, a view 4 units high, near 0.5, far 100.
    fn ortho() -> Camera {
        Camera::orthographic(Vec3::ZERO, Vec3::new(0.0, 0.0, -10.0), Vec3::Y, 4.0, 0.5, 100.0).unwrap()
    }

    fn clip(m: Mat4, p: Vec3) -> Vec3 {
        let c = m * p.extend(1.0);
        c.truncate() / c.w
    }

    #[test]
    fn orthographic_projection_is_parallel_and_maps_the_view_box_to_clip_space() {
        let c = ortho();
        let m = c.view_projection(2.0);
        // The view is 4 high and 8 wide at every depth: (4, 2) is the top right corner.
        for z in [-0.5, -3.0, -100.0] {
            let q = clip(m, Vec3::new(4.0, 2.0, z));
            assert!((q.x - 1.0).abs() < 1e-6 && (q.y - 1.0).abs() < 1e-6, "at depth {z}: {q:?}");
        }
        assert!(depth(m, Vec3::new(0.0, 0.0, -0.5)).abs() < 1e-6);
        assert!((depth(m, Vec3::new(0.0, 0.0, -100.0)) - 1.0).abs() < 1e-6);
        assert!((depth(m, Vec3::new(3.0, -1.0, -50.25)) - 0.5).abs() < 1e-6, "depth is linear");
        assert_eq!((m * Vec4::new(1.0, 2.0, -7.0, 1.0)).w, 1.0, "no perspective division");
    }

    #[test]
    fn orthographic_reverse_z_maps_near_to_1_and_far_to_0() {
        let c = ortho();
        let m = c.projection_reverse_z(2.0) * c.view();
        assert!((depth(m, Vec3::new(0.0, 0.0, -0.5)) - 1.0).abs() < 1e-6);
        assert!(depth(m, Vec3::new(0.0, 0.0, -100.0)).abs() < 1e-6);
        assert!(depth(m, Vec3::new(0.0, 0.0, 1.0)) > 1.0, "behind the eye: beyond near");
        // Back to view depths, both projections.
        for c in [ortho(), cam()] {
            let m = c.projection_reverse_z(2.0) * c.view();
            for z in [0.5f32, 2.0, 37.0, 99.0] {
                let back = c.view_depth_reverse_z(depth(m, Vec3::new(0.1, 0.2, -z)));
                assert!((back - z).abs() < z * 1e-4, "{:?}: {z} came back as {back}", c.projection);
            }
        }
    }

    #[test]
    fn orthographic_pixel_size_does_not_depend_on_distance() {
        let c = ortho();
        assert!((c.pixel_scale(1000.0) - 250.0).abs() < 1e-9, "1000 px over 4 units");
        for d in [0.5, 10.0, 1e4] {
            assert!((c.pixels(0.1, d, 1000.0) - 25.0).abs() < 1e-9);
        }
        assert_eq!(c.view_height_at(0.5), 4.0);
        assert_eq!(c.view_height_at(80.0), 4.0);
        let p = cam();
        assert!(p.view_height_at(20.0) > p.view_height_at(10.0));
    }

    #[test]
    fn orthographic_viewer_direction_is_the_headlight() {
        let c = ortho();
        assert_eq!(c.to_viewer(Vec3::new(5.0, -3.0, -20.0)), Vec3::Z);
        let p = cam();
        let to = p.to_viewer(Vec3::new(3.0, 0.0, -4.0));
        assert!((to - Vec3::new(-0.6, 0.0, 0.8)).length() < 1e-6);
    }

    #[test]
    fn widening_scales_the_angle_or_the_height() {
        let w = Projection::Orthographic { height: 4.0 }.widened(1.5);
        assert_eq!(w, Projection::Orthographic { height: 6.0 });
        let p = Projection::Perspective { fovy: 1.0 }.widened(1.2);
        assert_eq!(p, Projection::Perspective { fovy: 1.2 });
        let cap = Projection::Perspective { fovy: 3.0 }.widened(2.0);
        assert_eq!(cap, Projection::Perspective { fovy: 179f32.to_radians() });
    }

    #[test]
    fn orthographic_camera_strings() {
        let c = InputCamera::parse("0,0,10;0,0,0;0,1,0;ortho: 25").unwrap();
        assert_eq!((c.ortho_height, c.fovy_deg), (Some(25.0), DEFAULT_FOVY_DEG));
        let h = header([100.0; 3], 0.01, [100.0; 3], [110.0; 3]);
        let s = c.to_scene(&h).unwrap();
        assert_eq!(s.projection, Projection::Orthographic { height: 25.0 });
        assert_eq!(s.eye, Vec3::new(-100.0, -100.0, -90.0));
        for bad in ["0,0,10;0,0,0;0,1,0;ortho:0", "0,0,10;0,0,0;0,1,0;ortho:x", "0,0,10;0,0,0;0,1,0;ortho:-3"]
        {
            assert!(InputCamera::parse(bad).is_err(), "{bad}");
        }
    }
}
