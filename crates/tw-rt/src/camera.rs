//! A camera that generates primary rays: a pinhole (perspective: every ray from the eye) or a
//! parallel one (orthographic: every ray along the view direction, from the near plane), the
//! projections of `tw_runtime::Camera` ([`Camera::for_view`]).

use glam::Vec3;
use tw_runtime::Projection;

use crate::ray::Ray;

/// A ray camera: position, an orthonormal view basis, the projection and aspect ratio (width /
/// height).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Perspective: the eye, where every ray starts. Orthographic: the centre of the plane the
    /// rays start from (the near plane of [`Camera::for_view`]).
    pub origin: Vec3,
    /// Unit vectors: image right, image up, viewing direction.
    pub right: Vec3,
    pub up: Vec3,
    pub forward: Vec3,
    /// The vertical field of view (radians) or the orthographic view height (scene units).
    pub projection: Projection,
    pub aspect: f32,
    /// Where in each pixel the ray passes, from its top-left corner in pixels: the centre
    /// `[0.5, 0.5]` by default (what the rasterizer samples); other positions give the samples
    /// of progressive supersampling.
    pub subpixel: [f32; 2],
}

impl Camera {
    /// A camera at `eye` looking at `target`, with `up` giving the image's up direction (it
    /// need not be orthogonal to the view; if parallel, another axis is chosen).
    pub fn look_at(eye: Vec3, target: Vec3, up: Vec3, fov_y: f32, aspect: f32) -> Camera {
        let forward = (target - eye).try_normalize().unwrap_or(Vec3::NEG_Z);
        let right = forward.cross(up).try_normalize().unwrap_or_else(|| forward.any_orthonormal_vector());
        let up = right.cross(forward);
        let projection = Projection::Perspective { fovy: fov_y };
        Camera { origin: eye, right, up, forward, projection, aspect, subpixel: [0.5, 0.5] }
    }

    /// The rays of `camera` on an image of aspect `aspect` (width / height): a pinhole at the
    /// eye for a perspective camera; for an orthographic one, parallel rays along the view
    /// direction starting on the near plane (what the rasterizer shows starts there), so a ray's
    /// `t` is the depth beyond the near plane.
    pub fn for_view(camera: &tw_runtime::Camera, aspect: f32) -> Camera {
        let mut c = Camera::look_at(camera.eye, camera.target, camera.up, 1.0, aspect);
        c.projection = camera.projection;
        if camera.is_orthographic() {
            c.origin = camera.eye + c.forward * camera.near;
        }
        c
    }

    /// Half the image plane's width and height: at unit distance from the eye in perspective
    /// (`tan(fov_y / 2)` high), in scene units in orthographic.
    fn half_extent(&self) -> (f32, f32) {
        let half_h = match self.projection {
            Projection::Perspective { fovy } => (fovy * 0.5).tan(),
            Projection::Orthographic { height } => height * 0.5,
        };
        (half_h * self.aspect, half_h)
    }

    /// The ray through pixel `(px, py)` of a `width x height` image (row 0 at the top), through
    /// its [`subpixel`](Self::subpixel) position; its direction is unit length, so `t` is the
    /// distance from the eye (perspective) or from the near plane (orthographic).
    pub fn pixel_ray(&self, px: u32, py: u32, width: u32, height: u32) -> Ray {
        PixelRays::new(self, width, height).ray(px, py)
    }

    /// The ray through the point `(x, y)` of the image in normalized device coordinates (−1..1
    /// from left to right and from bottom to top), as [`pixel_ray`](Self::pixel_ray) gives for
    /// pixels: picking casts it through a mouse position.
    pub fn ndc_ray(&self, x: f32, y: f32) -> Ray {
        let (half_w, half_h) = self.half_extent();
        screen_ray(self, x * half_w, y * half_h)
    }
}

/// The ray through the image-plane point `(sx, sy)` (the offsets along `right` and `up`: at unit
/// distance in perspective, in scene units in orthographic).
#[inline(always)]
fn screen_ray(c: &Camera, sx: f32, sy: f32) -> Ray {
    match c.projection {
        Projection::Perspective { .. } => {
            let dir = c.forward + c.right * sx + c.up * sy;
            Ray::new(c.origin, dir * (1.0 / dir.length()))
        }
        Projection::Orthographic { .. } => Ray::new(c.origin + c.right * sx + c.up * sy, c.forward),
    }
}

/// [`Camera::pixel_ray`] for many pixels of one image, with the per-image terms (a `tan`, the
/// pixel scales) computed once and 8-ray blocks computed lane-parallel: ray generation was a
/// tenth of the packet tracing time when done ray by ray with divisions.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PixelRays {
    camera: Camera,
    half_w: f32,
    half_h: f32,
    /// `2 / width`, `2 / height`.
    scale_x: f32,
    scale_y: f32,
}

impl PixelRays {
    pub fn new(camera: &Camera, width: u32, height: u32) -> PixelRays {
        let (half_w, half_h) = camera.half_extent();
        PixelRays {
            camera: *camera,
            half_w,
            half_h,
            scale_x: 2.0 / width.max(1) as f32,
            scale_y: 2.0 / height.max(1) as f32,
        }
    }

    /// The ray through pixel `(px, py)` at the camera's [`subpixel`](Camera::subpixel) position.
    #[inline]
    pub fn ray(&self, px: u32, py: u32) -> Ray {
        let c = &self.camera;
        let [ox, oy] = c.subpixel;
        let sx = ((px as f32 + ox) * self.scale_x - 1.0) * self.half_w;
        let sy = (1.0 - (py as f32 + oy) * self.scale_y) * self.half_h;
        screen_ray(c, sx, sy)
    }

    /// The rays of the 4x2 pixels from `(x0, y0)`, row by row; the same values as
    /// [`PixelRays::ray`] gives, computed lane-parallel in perspective (orthographic rays, with
    /// one direction and no square roots, are computed ray by ray).
    #[inline(always)]
    pub fn block(&self, x0: u32, y0: u32) -> [Ray; 8] {
        let c = &self.camera;
        if c.projection.is_orthographic() {
            return std::array::from_fn(|k| self.ray(x0 + k as u32 % 4, y0 + k as u32 / 4));
        }
        let (f, r, u) = (c.forward.to_array(), c.right.to_array(), c.up.to_array());
        let [ox, oy] = c.subpixel;
        let mut d = [[0.0f32; 8]; 3];
        for lane in 0..8 {
            let sx = (((x0 + lane as u32 % 4) as f32 + ox) * self.scale_x - 1.0) * self.half_w;
            let sy = (1.0 - ((y0 + lane as u32 / 4) as f32 + oy) * self.scale_y) * self.half_h;
            // Grouped as glam groups `forward + right * sx + up * sy`.
            let v = [0, 1, 2].map(|a| f[a] + r[a] * sx + u[a] * sy);
            let inv = 1.0 / (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            for a in 0..3 {
                d[a][lane] = v[a] * inv;
            }
        }
        std::array::from_fn(|lane| Ray::new(c.origin, Vec3::new(d[0][lane], d[1][lane], d[2][lane])))
    }

    /// [`PixelRays::block`] in AVX2 registers: the same operations in the same order (no fused
    /// multiply-adds; square root and division are exact in both), so the same rays. The
    /// compiler kept the portable loop scalar, and ray generation was then a seventh of the
    /// time of packet tracing a 24 M triangle model.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    pub fn block_avx2(&self, x0: u32, y0: u32) -> [Ray; 8] {
        use std::arch::x86_64::*;
        let c = &self.camera;
        if c.projection.is_orthographic() {
            return self.block(x0, y0);
        }
        let (f, r, u) = (c.forward.to_array(), c.right.to_array(), c.up.to_array());
        let px = _mm256_cvtepi32_ps(_mm256_add_epi32(
            _mm256_set1_epi32(x0 as i32),
            _mm256_setr_epi32(0, 1, 2, 3, 0, 1, 2, 3),
        ));
        let py = _mm256_cvtepi32_ps(_mm256_add_epi32(
            _mm256_set1_epi32(y0 as i32),
            _mm256_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1),
        ));
        let (ox, oy) = (_mm256_set1_ps(c.subpixel[0]), _mm256_set1_ps(c.subpixel[1]));
        let one = _mm256_set1_ps(1.0);
        let sx = _mm256_mul_ps(
            _mm256_sub_ps(_mm256_mul_ps(_mm256_add_ps(px, ox), _mm256_set1_ps(self.scale_x)), one),
            _mm256_set1_ps(self.half_w),
        );
        let sy = _mm256_mul_ps(
            _mm256_sub_ps(one, _mm256_mul_ps(_mm256_add_ps(py, oy), _mm256_set1_ps(self.scale_y))),
            _mm256_set1_ps(self.half_h),
        );
        let v = [0, 1, 2].map(|a| {
            let fr = _mm256_add_ps(_mm256_set1_ps(f[a]), _mm256_mul_ps(_mm256_set1_ps(r[a]), sx));
            _mm256_add_ps(fr, _mm256_mul_ps(_mm256_set1_ps(u[a]), sy))
        });
        let dot = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(v[0], v[0]), _mm256_mul_ps(v[1], v[1])),
            _mm256_mul_ps(v[2], v[2]),
        );
        let inv = _mm256_div_ps(one, _mm256_sqrt_ps(dot));
        let mut d = [[0.0f32; 8]; 3];
        for a in 0..3 {
            // SAFETY: `d[a]` is 8 floats; the store is unaligned.
            unsafe { _mm256_storeu_ps(d[a].as_mut_ptr(), _mm256_mul_ps(v[a], inv)) };
        }
        std::array::from_fn(|lane| Ray::new(c.origin, Vec3::new(d[0][lane], d[1][lane], d[2][lane])))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every block path gives exactly the rays of [`PixelRays::ray`], which packets and single
    /// rays rely on to return the same hits.
    #[test]
    fn blocks_equal_single_pixel_rays() {
        let mut camera =
            Camera::look_at(Vec3::new(0.3, -2.0, 5.0), Vec3::new(0.1, 0.2, -0.4), Vec3::Y, 0.9, 1.7);
        for subpixel in [[0.5, 0.5], [0.125, 0.875]] {
            camera.subpixel = subpixel;
            blocks_equal_rays(&camera);
        }
    }

    /// The sub-pixel position moves the ray inside its pixel (progressive supersampling's
    /// samples differ): a quarter of the way into pixel (10, 7) of a 640×360 image is the centre
    /// of pixel (20, 14) at twice the resolution.
    #[test]
    fn rays_pass_through_the_subpixel_position() {
        let mut camera =
            Camera::look_at(Vec3::new(0.3, -2.0, 5.0), Vec3::new(0.1, 0.2, -0.4), Vec3::Y, 0.9, 1.7);
        let centre = camera.pixel_ray(10, 7, 640, 360);
        camera.subpixel = [0.25, 0.25];
        let quarter = camera.pixel_ray(10, 7, 640, 360);
        assert_ne!(quarter, centre);
        camera.subpixel = [0.5, 0.5];
        let fine = camera.pixel_ray(20, 14, 1280, 720);
        assert!((quarter.dir - fine.dir).length() < 1e-6, "{quarter:?} against {fine:?}");
    }

    /// Looking down −Z from (0, 0, 5) with a view 2 high on a 200×100 image, near 0.5.
    fn ortho() -> Camera {
        let view =
            tw_runtime::Camera::orthographic(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y, 2.0, 0.5, 100.0)
                .unwrap();
        Camera::for_view(&view, 2.0)
    }

    #[test]
    fn orthographic_rays_are_parallel_and_start_on_the_near_plane() {
        let camera = ortho();
        for (px, py) in [(0, 0), (199, 0), (57, 83), (199, 99)] {
            let r = camera.pixel_ray(px, py, 200, 100);
            assert_eq!(r.dir, Vec3::NEG_Z, "pixel {px}, {py}");
            assert!((r.origin.z - 4.5).abs() < 1e-6, "on the near plane: {:?}", r.origin);
        }
        // Pixel (0, 0)'s centre is half a pixel (0.01 units) in from the top left corner (−2, 1).
        let r = camera.pixel_ray(0, 0, 200, 100);
        assert!((r.origin - Vec3::new(-1.99, 0.99, 4.5)).length() < 1e-6, "{:?}", r.origin);
        let centre = camera.ndc_ray(0.0, 0.0);
        assert!((centre.origin - Vec3::new(0.0, 0.0, 4.5)).length() < 1e-6);
        assert_eq!(centre.dir, Vec3::NEG_Z);
    }

    #[test]
    fn orthographic_rays_pass_through_the_subpixel_position() {
        let mut camera = ortho();
        let centre = camera.pixel_ray(10, 7, 200, 100);
        camera.subpixel = [0.25, 0.25];
        let quarter = camera.pixel_ray(10, 7, 200, 100);
        assert_ne!(quarter, centre);
        assert_eq!(quarter.dir, centre.dir);
        // A quarter pixel is 0.005 units left and up of the centre.
        assert!((quarter.origin - centre.origin - Vec3::new(-0.005, 0.005, 0.0)).length() < 1e-6);
        camera.subpixel = [0.5, 0.5];
        let fine = camera.pixel_ray(20, 14, 400, 200);
        assert!((quarter.origin - fine.origin).length() < 1e-6, "{quarter:?} against {fine:?}");
        for subpixel in [[0.5, 0.5], [0.125, 0.875]] {
            camera.subpixel = subpixel;
            blocks_equal_rays(&camera);
        }
    }

    #[test]
    fn perspective_view_cameras_are_pinholes_at_the_eye() {
        let view = tw_runtime::Camera::new(
            Vec3::new(0.3, -2.0, 5.0),
            Vec3::new(0.1, 0.2, -0.4),
            Vec3::Y,
            0.9,
            0.1,
            50.0,
        )
        .unwrap();
        let c = Camera::for_view(&view, 1.7);
        assert_eq!(c, Camera::look_at(view.eye, view.target, view.up, 0.9, 1.7));
        let r = c.ndc_ray(1.0, 1.0);
        assert_eq!(r.origin, view.eye);
        let want = (c.forward + c.right * (0.45f32.tan() * 1.7) + c.up * 0.45f32.tan()).normalize();
        assert!((r.dir - want).length() < 1e-6);
    }

    fn blocks_equal_rays(camera: &Camera) {
        let gen = PixelRays::new(camera, 1283, 721);
        for (x0, y0) in [(0, 0), (4, 2), (640, 360), (1276, 718), (1000, 3)] {
            let want: [Ray; 8] = std::array::from_fn(|k| gen.ray(x0 + k as u32 % 4, y0 + k as u32 / 4));
            assert_eq!(gen.block(x0, y0), want, "block at {x0}, {y0}");
            #[cfg(target_arch = "x86_64")]
            if crate::Simd::detect() == crate::Simd::Avx2 {
                // SAFETY: the CPU has AVX2 and FMA.
                assert_eq!(unsafe { gen.block_avx2(x0, y0) }, want, "AVX2 block at {x0}, {y0}");
            }
        }
    }
}
