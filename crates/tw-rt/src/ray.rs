//! Rays and hits, the values every query takes and returns.

use glam::Vec3;

/// A ray segment `origin + t * dir` for `t` in `[t_min, t_max)`.
///
/// `dir` need not be unit length; `t` is measured in multiples of `dir`. Coordinates must be
/// finite (an infinite origin makes the slab tests meaningless); direction components may be
/// `0.0` or `-0.0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub t_min: f32,
    pub t_max: f32,
}

impl Ray {
    /// A ray from `origin` along `dir` over `[0, inf)`.
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray { origin, dir, t_min: 0.0, t_max: f32::INFINITY }
    }

    /// The point at parameter `t`.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// The nearest intersection found along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit point.
    pub t: f32,
    /// The primitive hit: for a [`crate::TriangleBvh`], the index of the input triangle.
    pub prim: u32,
    /// Barycentric weight of the triangle's second vertex (the point is
    /// `(1 - u - v) * p0 + u * p1 + v * p2`).
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
}
