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
//! Users give cameras in *input* coordinates (the units of the files they built from):
//! [`InputCamera`] parses the command-line form `"x,y,z;x,y,z;x,y,z;fovy"` (eye; target; up;
//! vertical field of view in degrees, as `terawalk preview --camera` accepts) and
//! [`InputCamera::to_scene`] / [`Camera::from_input_coordinates`] rebase it to scene space by
//! subtracting the store's grid origin.

use std::str::FromStr;

use glam::{DVec3, Mat4, Vec3, Vec4};
use tw_store::Header;

use crate::error::RuntimeError;

/// A perspective camera in scene space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    /// Approximate up direction (need not be unit length or orthogonal to the view direction).
    pub up: Vec3,
    /// Vertical field of view in radians, in (0, π).
    pub fovy: f32,
    /// Distance of the near clip plane (> 0).
    pub near: f32,
    /// Distance of the far clip plane (> near).
    pub far: f32,
}

/// Near plane distance as a fraction of the far plane distance, for cameras given without
/// clip planes ([`Camera::from_input_coordinates`]). With reverse-Z f32 depth this still leaves
/// ample precision.
pub const NEAR_FAR_RATIO: f32 = 1e-5;

impl Camera {
    /// A camera from its parts, checked with [`validate`](Self::validate).
    pub fn new(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        fovy: f32,
        near: f32,
        far: f32,
    ) -> Result<Camera, RuntimeError> {
        let c = Camera { eye, target, up, fovy, near, far };
        c.validate()?;
        Ok(c)
    }

    /// Checks that the camera gives a view: finite values, eye ≠ target, `up` not parallel to
    /// the view direction, 0 < fovy < π, 0 < near < far.
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
        if !(self.fovy > 0.0 && self.fovy < std::f32::consts::PI) {
            return bad(format!("vertical field of view {} rad must be in (0, π)", self.fovy));
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

    /// Perspective projection, depth 0 at `near` and 1 at `far`. `aspect` = width / height.
    pub fn projection(&self, aspect: f32) -> Mat4 {
        perspective_rh(self.fovy, aspect, self.near, self.far)
    }

    /// Reverse-Z perspective projection: depth 1 at `near` and 0 at `far`.
    pub fn projection_reverse_z(&self, aspect: f32) -> Mat4 {
        perspective_rh(self.fovy, aspect, self.far, self.near)
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

    /// `H / (2 tan(fovy / 2))`: pixels per unit of size at unit distance, for a viewport
    /// `viewport_height` pixels high (docs/DESIGN.md, D3).
    pub fn pixel_scale(&self, viewport_height: f32) -> f64 {
        viewport_height as f64 / (2.0 * (self.fovy as f64 / 2.0).tan())
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

/// A camera as the user gives it: input coordinates, field of view in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputCamera {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
    pub fovy_deg: f64,
}

impl InputCamera {
    /// Parses `"x,y,z;x,y,z;x,y,z;fovy"`: eye; target; up; vertical field of view in degrees
    /// (1..=179). Whitespace around numbers is allowed. Eye and target must differ.
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
        let cam = InputCamera {
            eye: vec3(eye, "eye")?,
            target: vec3(target, "target")?,
            up: vec3(up, "up")?,
            fovy_deg: fovy.parse().map_err(|_| err(format!("bad field of view {fovy:?}")))?,
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

    /// The scene-space camera for a store (see [`Camera::from_input_coordinates`]).
    pub fn to_scene(&self, header: &Header) -> Result<Camera, RuntimeError> {
        Camera::from_input_coordinates(self.eye, self.target, self.up, self.fovy_deg, header)
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
            Camera { fovy: 0.0, ..ok },
            Camera { fovy: std::f32::consts::PI, ..ok },
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
        assert!((c.fovy - 60f32.to_radians()).abs() < 1e-6);
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
                fovy_deg: 60.0
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
        let c = Camera { fovy: 90f32.to_radians(), ..cam() };
        assert!((c.pixel_scale(1000.0) - 500.0).abs() < 1e-3);
    }
}
