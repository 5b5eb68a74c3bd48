//! Axis-aligned boxes and the robust ray/box slab test.
//!
//! The slab test takes precomputed inverse directions. A direction component of `0.0` or `-0.0`
//! gives an infinite inverse (with the zero's sign), and then `0 * inf = NaN` when the origin lies
//! exactly on a slab plane. Every min/max here is written `if candidate OP acc { candidate } else
//! { acc }` with the candidate first, which is what `minps`/`maxps` do, so a NaN candidate leaves
//! the running value unchanged: a ray running inside a slab plane counts as inside the slab. The
//! near and far planes are chosen by the sign of the inverse, and the far distance is scaled by
//! `1 + 2γ₃` as in Ize 2013, "Robust BVH Ray Traversal", so rounding never culls a box the ray
//! touches.

use glam::Vec3;

use crate::ray::Ray;

/// `1 + 2γ₃` with `γ₃ = 3u / (1 - 3u)`, `u = 2⁻²⁴` (Ize 2013, section 3), rounded up.
pub(crate) const ROBUST_FAR: f32 = 1.000_000_4;

/// An axis-aligned box. An empty box has `min = +inf` and `max = -inf`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Aabb {
        Aabb::EMPTY
    }
}

impl Aabb {
    /// The empty box: the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb { min: Vec3::INFINITY, max: Vec3::NEG_INFINITY };

    pub fn new(min: Vec3, max: Vec3) -> Aabb {
        Aabb { min, max }
    }

    /// The smallest box holding all `points`.
    pub fn from_points(points: &[Vec3]) -> Aabb {
        points.iter().fold(Aabb::EMPTY, |b, &p| b.grown(p))
    }

    /// This box grown to hold `p`.
    pub fn grown(self, p: Vec3) -> Aabb {
        Aabb { min: self.min.min(p), max: self.max.max(p) }
    }

    /// The smallest box holding both.
    pub fn union(self, other: Aabb) -> Aabb {
        Aabb { min: self.min.min(other.min), max: self.max.max(other.max) }
    }

    /// True when no point lies inside (also for NaN corners).
    pub fn is_empty(&self) -> bool {
        !(self.min.x <= self.max.x && self.min.y <= self.max.y && self.min.z <= self.max.z)
    }

    /// True when `other` lies inside this box (an empty `other` always does).
    pub fn contains(&self, other: &Aabb) -> bool {
        other.is_empty() || (self.min.cmple(other.min).all() && other.max.cmple(self.max).all())
    }

    pub fn centroid(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Half the surface area (what the SAH needs: only ratios matter); 0 for an empty box.
    pub fn half_area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let e = self.max - self.min;
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    /// The parameter interval `[near, far]` over which `ray` is inside the box, clipped to
    /// `[t_min, t_max]`, or `None` when the ray misses. Conservative: touching counts.
    pub fn intersect(&self, ray: &Ray) -> Option<(f32, f32)> {
        let s = SlabRay::new(ray);
        let lo = [self.min.x, self.min.y, self.min.z];
        let hi = [self.max.x, self.max.y, self.max.z];
        let mut near = ray.t_min;
        let mut far_box = f32::INFINITY;
        for a in 0..3 {
            let (n, f) = if s.neg[a] { (hi[a], lo[a]) } else { (lo[a], hi[a]) };
            near = max((n - s.origin[a]) * s.inv[a], near);
            far_box = min((f - s.origin[a]) * s.inv[a], far_box);
        }
        let far = min(far_box * ROBUST_FAR, ray.t_max);
        (near <= far).then_some((near, far))
    }
}

/// A ray prepared for slab tests: origin, inverse direction, and the sign of each inverse
/// (which slab plane is the near one).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SlabRay {
    pub origin: [f32; 3],
    pub inv: [f32; 3],
    pub neg: [bool; 3],
}

impl SlabRay {
    pub fn new(ray: &Ray) -> SlabRay {
        let d = ray.dir.to_array();
        let inv = d.map(|x| 1.0 / x);
        SlabRay { origin: ray.origin.to_array(), inv, neg: inv.map(|i| i < 0.0) }
    }
}

/// `min` that compiles to one SIMD instruction (`minps` order): a NaN `a` gives `b`.
#[inline(always)]
pub(crate) fn min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// `max`, the counterpart of [`min`]: a NaN `a` gives `b`.
#[inline(always)]
pub(crate) fn max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}
