//! View-frustum culling: the six planes of a view-projection matrix (Gribb & Hartmann, "Fast
//! extraction of viewing frustum planes from the world-view-projection matrix", 2001, for
//! clip-space depth 0..1 as wgpu uses) and conservative tests of boxes and spheres against them.
//!
//! The tests are the usual plane-by-plane ones: a shape is `Outside` when it lies entirely on
//! the outer side of one plane, `Inside` when it lies on the inner side of all six, otherwise
//! `Intersecting`. `Outside` is exact (never reported for a shape that reaches into the
//! frustum); `Intersecting` may be reported for a shape that is outside near a frustum corner,
//! which only costs a little culling, never a missing object.
//!
//! Store boxes are inclusive grid boxes; [`grid_box`] converts them to scene space with the
//! store's grid step, rounded outwards so that f32 rounding never shrinks them.

use glam::{Mat4, Vec3, Vec4};

/// Where a shape lies relative to the frustum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Containment {
    Outside,
    Intersecting,
    Inside,
}

/// Six planes `(n, d)` with inward unit normals: a point `p` is inside when `n·p + d ≥ 0` for
/// all of them. Order: left, right, bottom, top, near, far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    pub planes: [Vec4; 6],
}

impl Frustum {
    /// The planes of `view_proj` (scene → clip space, depth 0..1). Works for standard and
    /// reverse-Z projections (the near and far planes swap roles, the set is the same). A plane
    /// that degenerates (an infinite far plane) becomes "always inside".
    pub fn from_view_projection(view_proj: &Mat4) -> Frustum {
        let r0 = view_proj.row(0);
        let r1 = view_proj.row(1);
        let r2 = view_proj.row(2);
        let r3 = view_proj.row(3);
        let raw = [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2];
        let planes = raw.map(|p| {
            let len = p.truncate().length();
            if len > 1e-20 && len.is_finite() {
                p / len
            } else if p.w >= 0.0 {
                Vec4::new(0.0, 0.0, 0.0, 1.0)
            } else {
                Vec4::new(0.0, 0.0, 0.0, -1.0)
            }
        });
        Frustum { planes }
    }

    /// Signed distance of `p` from plane `i` (positive inside).
    #[inline]
    fn distance(plane: Vec4, p: Vec3) -> f32 {
        plane.truncate().dot(p) + plane.w
    }

    /// Tests the box `min..=max` (scene space).
    pub fn test_aabb(&self, min: Vec3, max: Vec3) -> Containment {
        let mut result = Containment::Inside;
        for &plane in &self.planes {
            let n = plane.truncate();
            // The corner farthest along the normal (p-vertex) and the nearest (n-vertex).
            let far = Vec3::select(n.cmpge(Vec3::ZERO), max, min);
            if Self::distance(plane, far) < 0.0 {
                return Containment::Outside;
            }
            let near = Vec3::select(n.cmpge(Vec3::ZERO), min, max);
            if Self::distance(plane, near) < 0.0 {
                result = Containment::Intersecting;
            }
        }
        result
    }

    /// Tests the sphere at `center` with `radius` (scene space).
    pub fn test_sphere(&self, center: Vec3, radius: f32) -> Containment {
        let mut result = Containment::Inside;
        for &plane in &self.planes {
            let d = Self::distance(plane, center);
            if d < -radius {
                return Containment::Outside;
            }
            if d < radius {
                result = Containment::Intersecting;
            }
        }
        result
    }

    /// Tests an inclusive grid box of the store (see [`grid_box`]).
    pub fn test_grid_box(&self, min: [u32; 3], max: [u32; 3], grid_step: f64) -> Containment {
        let (lo, hi) = grid_box(min, max, grid_step);
        self.test_aabb(lo, hi)
    }
}

/// The scene-space box of the inclusive grid box `min..=max`: `g × grid_step`, computed in f64
/// and widened by a relative 2⁻²⁰ so that rounding to f32 never shrinks it.
pub fn grid_box(min: [u32; 3], max: [u32; 3], grid_step: f64) -> (Vec3, Vec3) {
    let lo = min.map(|g| {
        let v = g as f64 * grid_step;
        (v - v.abs() * 2f64.powi(-20)) as f32
    });
    let hi = max.map(|g| {
        let v = g as f64 * grid_step;
        (v + v.abs() * 2f64.powi(-20)) as f32
    });
    (Vec3::from_array(lo), Vec3::from_array(hi))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    /// Eye at the origin looking down −Z, 90° vertical field of view, square aspect, near 1,
    /// far 100: the frustum is |x| ≤ −z, |y| ≤ −z, 1 ≤ −z ≤ 100.
    fn frustum() -> Frustum {
        let c = Camera::new(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 90f32.to_radians(), 1.0, 100.0).unwrap();
        Frustum::from_view_projection(&c.view_projection(1.0))
    }

    fn aabb(min: [f32; 3], max: [f32; 3]) -> Containment {
        frustum().test_aabb(Vec3::from_array(min), Vec3::from_array(max))
    }

    #[test]
    fn planes_are_unit_and_point_inwards() {
        let f = frustum();
        for p in f.planes {
            assert!((p.truncate().length() - 1.0).abs() < 1e-5);
            assert!(Frustum::distance(p, Vec3::new(0.0, 0.0, -10.0)) > 0.0, "{p:?}");
        }
        // Near plane at z = -1, far at z = -100.
        assert!((Frustum::distance(f.planes[4], Vec3::new(0.0, 0.0, -1.0))).abs() < 1e-4);
        assert!((Frustum::distance(f.planes[5], Vec3::new(0.0, 0.0, -100.0))).abs() < 1e-2);
    }

    #[test]
    fn box_in_front_is_inside() {
        assert_eq!(aabb([-1.0, -1.0, -11.0], [1.0, 1.0, -9.0]), Containment::Inside);
    }

    #[test]
    fn box_behind_the_eye_is_outside() {
        assert_eq!(aabb([-1.0, -1.0, 5.0], [1.0, 1.0, 9.0]), Containment::Outside);
        // Just behind the near plane, still in front of the eye.
        assert_eq!(aabb([-0.1, -0.1, -0.9], [0.1, 0.1, -0.5]), Containment::Outside);
    }

    #[test]
    fn box_straddling_the_near_plane_intersects() {
        assert_eq!(aabb([-0.1, -0.1, -2.0], [0.1, 0.1, 0.5]), Containment::Intersecting);
    }

    #[test]
    fn huge_box_containing_the_eye_intersects() {
        assert_eq!(aabb([-1e6, -1e6, -1e6], [1e6, 1e6, 1e6]), Containment::Intersecting);
    }

    #[test]
    fn box_beside_or_beyond_far_is_outside() {
        assert_eq!(aabb([20.0, -1.0, -11.0], [22.0, 1.0, -9.0]), Containment::Outside);
        assert_eq!(aabb([-1.0, 20.0, -11.0], [1.0, 22.0, -9.0]), Containment::Outside);
        assert_eq!(aabb([-1.0, -1.0, -300.0], [1.0, 1.0, -101.0]), Containment::Outside);
        assert_eq!(aabb([-1.0, -1.0, -300.0], [1.0, 1.0, -50.0]), Containment::Intersecting);
    }

    #[test]
    fn box_crossing_a_side_plane_intersects() {
        assert_eq!(aabb([5.0, -1.0, -11.0], [15.0, 1.0, -9.0]), Containment::Intersecting);
    }

    #[test]
    fn spheres() {
        let f = frustum();
        assert_eq!(f.test_sphere(Vec3::new(0.0, 0.0, -10.0), 1.0), Containment::Inside);
        assert_eq!(f.test_sphere(Vec3::new(0.0, 0.0, 10.0), 1.0), Containment::Outside);
        assert_eq!(f.test_sphere(Vec3::ZERO, 0.5), Containment::Outside, "around the eye, before near");
        assert_eq!(f.test_sphere(Vec3::ZERO, 2.0), Containment::Intersecting, "reaches past near");
        assert_eq!(f.test_sphere(Vec3::ZERO, 1e6), Containment::Intersecting, "contains the eye");
        // Centre outside the right plane x = -z, at distance 2/√2 ≈ 1.41 from it.
        assert_eq!(f.test_sphere(Vec3::new(12.0, 0.0, -10.0), 1.0), Containment::Outside);
        assert_eq!(f.test_sphere(Vec3::new(12.0, 0.0, -10.0), 1.5), Containment::Intersecting);
    }

    #[test]
    fn reverse_z_gives_the_same_planes() {
        let c = Camera::new(Vec3::ONE, Vec3::new(3.0, -2.0, 0.5), Vec3::Z, 1.0, 0.5, 50.0).unwrap();
        let a = Frustum::from_view_projection(&c.view_projection(1.6));
        let b = Frustum::from_view_projection(&(c.projection_reverse_z(1.6) * c.view()));
        let (mut pa, mut pb) = (a.planes.to_vec(), b.planes.to_vec());
        pb.swap(4, 5);
        for (x, y) in pa.iter_mut().zip(&mut pb) {
            assert!((*x - *y).abs().max_element() < 1e-3, "{x:?} vs {y:?}");
        }
    }

    #[test]
    fn infinite_far_plane_is_always_inside() {
        let c = Camera::new(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 1.0, 0.5, 50.0).unwrap();
        // Reverse-Z with the far plane at infinity: depth = near / −z.
        let h = 2.0 / c.view_height_at(1.0) as f32;
        let proj = Mat4::from_cols(
            Vec4::new(h, 0.0, 0.0, 0.0),
            Vec4::new(0.0, h, 0.0, 0.0),
            Vec4::new(0.0, 0.0, 0.0, -1.0),
            Vec4::new(0.0, 0.0, 0.5, 0.0),
        );
        let f = Frustum::from_view_projection(&(proj * c.view()));
        assert_eq!(f.test_sphere(Vec3::new(0.0, 0.0, -1e9), 1.0), Containment::Inside);
        assert_eq!(f.test_sphere(Vec3::new(0.0, 0.0, 1e9), 1.0), Containment::Outside);
    }

    /// Looking down −Z from the origin, a view 4 high and 8 wide, near 1, far 100: the frustum
    /// is the box |x| ≤ 4, |y| ≤ 2, 1 ≤ −z ≤ 100, the same with reverse-Z.
    #[test]
    fn orthographic_frustum_is_a_box() {
        let c = Camera::orthographic(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 4.0, 1.0, 100.0).unwrap();
        for vp in [c.view_projection(2.0), c.projection_reverse_z(2.0) * c.view()] {
            let f = Frustum::from_view_projection(&vp);
            let want = [
                Vec4::new(1.0, 0.0, 0.0, 4.0),
                Vec4::new(-1.0, 0.0, 0.0, 4.0),
                Vec4::new(0.0, 1.0, 0.0, 2.0),
                Vec4::new(0.0, -1.0, 0.0, 2.0),
            ];
            for (p, w) in f.planes.iter().zip(want) {
                assert!((*p - w).abs().max_element() < 1e-5, "{p:?} against {w:?}");
            }
            let b = |lo: [f32; 3], hi: [f32; 3]| f.test_aabb(Vec3::from_array(lo), Vec3::from_array(hi));
            // Parallel sides: a box 3.5 off the axis is inside near and far alike.
            assert_eq!(b([3.0, -1.0, -3.0], [3.5, 1.0, -2.0]), Containment::Inside);
            assert_eq!(b([3.0, -1.0, -99.0], [3.5, 1.0, -98.0]), Containment::Inside);
            assert_eq!(b([4.5, -1.0, -99.0], [5.0, 1.0, -98.0]), Containment::Outside);
            assert_eq!(b([-1.0, 2.5, -50.0], [1.0, 3.0, -40.0]), Containment::Outside);
            assert_eq!(b([-1.0, -1.0, -0.9], [1.0, 1.0, -0.5]), Containment::Outside, "before near");
            assert_eq!(b([-1.0, -1.0, 0.5], [1.0, 1.0, 3.0]), Containment::Outside, "behind the eye");
            assert_eq!(b([-1.0, -1.0, -101.0], [1.0, 1.0, -100.5]), Containment::Outside, "beyond far");
            assert_eq!(b([3.0, 1.0, -5.0], [6.0, 3.0, -4.0]), Containment::Intersecting);
            assert_eq!(f.test_sphere(Vec3::new(4.5, 0.0, -50.0), 0.6), Containment::Intersecting);
            assert_eq!(f.test_sphere(Vec3::new(4.5, 0.0, -50.0), 0.4), Containment::Outside);
        }
    }

    #[test]
    fn grid_boxes_scale_by_the_step_and_round_outwards() {
        let (lo, hi) = grid_box([10, 0, 3], [20, 1, 16_777_215], 0.1);
        assert!(lo.x <= 1.0 && lo.x > 0.999_99);
        assert!(hi.x >= 2.0 && hi.x < 2.000_01);
        assert!(hi.z as f64 >= 16_777_215.0 * 0.1);
        assert_eq!(lo.y, 0.0);
        let f = frustum();
        // Grid boxes have z ≥ 0: behind the eye, which looks down −Z.
        assert_eq!(f.test_grid_box([0, 0, 0], [10, 10, 10], 1.0), Containment::Outside);
    }
}
