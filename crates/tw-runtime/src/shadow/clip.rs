//! The part of a box on the inner side of some planes, as the points whose convex hull it is:
//! the eye-depth slab of a shadow layer's split (the points of a receiver that rule 1 can put
//! in that layer) and the layer's frustum (the points the layer holds at all).
//!
//! The box is a convex polyhedron given by its face polygons; each plane clips every face
//! (Sutherland–Hodgman) and closes the cut with a new face, the *cap*, whose corners are the
//! points where the faces' edges cross the plane (ordered by angle around their centroid). The
//! vertices of the faces left are exactly the vertices of the clipped polyhedron (with
//! repetitions), so every bound computed from them — a projection's rectangle, a depth's range
//! when the depth is linear or monotone along straight lines — is a bound of the clipped box.

use glam::{Vec3, Vec4};

/// A half-space `n · p + d ≥ 0` as `(n, d)`.
pub type Plane = Vec4;

/// The six faces of the box `lo..=hi` as corner indices (bit 0: x, bit 1: y, bit 2: z), each
/// a loop.
const FACES: [[usize; 4]; 6] =
    [[0, 2, 6, 4], [1, 5, 7, 3], [0, 4, 5, 1], [2, 3, 7, 6], [0, 1, 3, 2], [4, 6, 7, 5]];

/// The 8 corners of `lo..=hi` (bit 0 of the index selects x, bit 1 y, bit 2 z).
pub fn corners(lo: Vec3, hi: Vec3) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

/// The vertices of `lo..=hi` cut by the half-spaces `planes` (see the module documentation),
/// in `out` (cleared first). Empty when nothing of the box is left.
pub fn clip_box(lo: Vec3, hi: Vec3, planes: &[Plane], out: &mut Vec<Vec3>) {
    out.clear();
    let c = corners(lo, hi);
    let holds = |p: Plane| c.iter().all(|&q| side(p, q) >= 0.0);
    if planes.iter().all(|&p| holds(p)) {
        out.extend_from_slice(&c); // nothing cut (the common case)
        return;
    }
    // A plane with every corner outside leaves nothing (a receiver in another layer's slab: the
    // other common case), and one with every corner inside cuts nothing off: the box's points
    // are convex combinations of its corners. Neither is worth a pass over the faces.
    if planes.iter().any(|&p| c.iter().all(|&q| side(p, q) < 0.0)) {
        return;
    }
    let mut faces: Vec<Vec<Vec3>> = FACES.iter().map(|f| f.iter().map(|&i| c[i]).collect()).collect();
    let mut cap: Vec<Vec3> = Vec::new();
    for &plane in planes {
        if holds(plane) {
            continue;
        }
        cap.clear();
        let mut clipped = Vec::with_capacity(faces.len() + 1);
        for face in &faces {
            let mut kept = Vec::with_capacity(face.len() + 1);
            clip_polygon(face, plane, &mut kept, &mut cap);
            if kept.len() >= 3 {
                clipped.push(kept);
            }
        }
        if cap.len() >= 3 {
            clipped.push(order_around_centroid(&cap, plane.truncate()));
        }
        faces = clipped;
        if faces.is_empty() {
            return;
        }
    }
    for face in &faces {
        out.extend_from_slice(face);
    }
}

/// Signed distance-like value of `p` from `plane` (≥ 0 inside).
fn side(plane: Plane, p: Vec3) -> f32 {
    plane.truncate().dot(p) + plane.w
}

/// One Sutherland–Hodgman step: the part of the polygon loop `poly` where `plane` ≥ 0 into
/// `out`; the points where its edges cross the plane are added to `crossings` as well.
fn clip_polygon(poly: &[Vec3], plane: Plane, out: &mut Vec<Vec3>, crossings: &mut Vec<Vec3>) {
    for (i, &a) in poly.iter().enumerate() {
        let b = poly[(i + 1) % poly.len()];
        let (da, db) = (side(plane, a), side(plane, b));
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            let t = da / (da - db);
            let x = a + (b - a) * t;
            out.push(x);
            crossings.push(x);
        }
    }
}

/// The points `points` (on a plane with normal `normal`) as a loop: sorted by angle around
/// their centroid.
fn order_around_centroid(points: &[Vec3], normal: Vec3) -> Vec<Vec3> {
    let centroid = points.iter().copied().sum::<Vec3>() / points.len() as f32;
    let u = normal.any_orthonormal_vector();
    let v = normal.normalize_or(Vec3::Z).cross(u);
    let mut keyed: Vec<(f32, Vec3)> =
        points.iter().map(|&p| ((p - centroid).dot(v).atan2((p - centroid).dot(u)), p)).collect();
    keyed.sort_by(|a, b| a.0.total_cmp(&b.0));
    keyed.into_iter().map(|(_, p)| p).collect()
}

/// The half-spaces of the eye depths `from..=to` (`(p − eye) · dir`), each widened by `slack`
/// (scene units) against rounding; an open end (`from ≤ −f32::MAX`, `to ≥ f32::MAX`) gives no
/// plane.
pub fn depth_slab(eye: Vec3, dir: Vec3, from: f32, to: f32, slack: f32) -> Vec<Plane> {
    let base = dir.dot(eye);
    let mut planes = Vec::with_capacity(2);
    if from > -f32::MAX {
        planes.push(dir.extend(-base - from + slack));
    }
    if to < f32::MAX {
        planes.push((-dir).extend(base + to + slack));
    }
    planes
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box cut by three planes meeting inside it (a corner of a frustum): the vertex where they
    /// meet is among the points, and every point satisfies every plane.
    #[test]
    fn three_planes_meeting_inside_the_box_give_their_common_vertex() {
        let mut out = Vec::new();
        let planes =
            [Vec4::new(1.0, 0.0, 0.0, -0.5), Vec4::new(0.0, 1.0, 0.0, -0.5), Vec4::new(0.0, 0.0, 1.0, -0.5)];
        clip_box(Vec3::ZERO, Vec3::ONE, &planes, &mut out);
        assert!(out.iter().any(|p| (*p - Vec3::splat(0.5)).length() < 1e-6), "{out:?}");
        assert!(out.iter().all(|&p| planes.iter().all(|&q| side(q, p) >= -1e-6)));
        // An oblique plane through the box's middle and two more: the result's bounds are those
        // of a dense sampling of the clipped box.
        let planes = [
            Vec4::new(1.0, 1.0, 1.0, -1.2).normalize(),
            Vec4::new(-1.0, 0.2, 0.0, 0.8),
            Vec4::new(0.0, -1.0, 0.3, 0.9),
        ];
        clip_box(Vec3::ZERO, Vec3::ONE, &planes, &mut out);
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for p in &out {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let (mut slo, mut shi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for i in 0..=40 {
            for j in 0..=40 {
                for k in 0..=40 {
                    let p = Vec3::new(i as f32, j as f32, k as f32) / 40.0;
                    if planes.iter().all(|&q| side(q, p) >= 0.0) {
                        slo = slo.min(p);
                        shi = shi.max(p);
                    }
                }
            }
        }
        assert!(lo.cmple(slo + 1e-5).all() && hi.cmpge(shi - 1e-5).all(), "{lo} {hi} vs {slo} {shi}");
        assert!((lo - slo).max_element() > -0.03 && (shi - hi).max_element() > -0.03, "tight");
    }

    #[test]
    fn without_planes_the_corners() {
        let mut out = Vec::new();
        clip_box(Vec3::ZERO, Vec3::ONE, &[], &mut out);
        assert_eq!(out.len(), 8);
    }

    #[test]
    fn a_slab_cuts_the_box_exactly() {
        let mut out = Vec::new();
        // Depths along the diagonal direction from the origin, between 0.5 and 1.
        let dir = Vec3::ONE.normalize();
        let slab = depth_slab(Vec3::ZERO, dir, 0.5, 1.0, 0.0);
        clip_box(Vec3::ZERO, Vec3::ONE, &slab, &mut out);
        assert!(!out.is_empty());
        let depths: Vec<f32> = out.iter().map(|p| p.dot(dir)).collect();
        let lo = depths.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = depths.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        assert!((lo - 0.5).abs() < 1e-5 && (hi - 1.0).abs() < 1e-5, "{lo} {hi}");
        // Every point stays in the box.
        assert!(out
            .iter()
            .all(|p| p.cmpge(Vec3::splat(-1e-6)).all() && p.cmple(Vec3::splat(1.0 + 1e-6)).all()));
        // A slab that misses the box leaves nothing.
        clip_box(Vec3::ZERO, Vec3::ONE, &depth_slab(Vec3::ZERO, dir, 2.0, 3.0, 0.0), &mut out);
        assert!(out.is_empty());
        // Open ends give no planes.
        assert!(depth_slab(Vec3::ZERO, dir, -f32::MAX, f32::MAX, 0.0).is_empty());
    }

    #[test]
    fn planes_that_cut_nothing_off_or_leave_nothing_need_no_pass() {
        let dir = Vec3::ONE.normalize();
        let cut = depth_slab(Vec3::ZERO, dir, 0.5, 1.0, 0.0);
        let (mut alone, mut with) = (Vec::new(), Vec::new());
        clip_box(Vec3::ZERO, Vec3::ONE, &cut, &mut alone);
        // A plane every corner is inside of, before and after the cutting ones: the same points.
        let wide = Vec4::new(1.0, 0.0, 0.0, 5.0);
        clip_box(Vec3::ZERO, Vec3::ONE, &[wide, cut[0], cut[1], wide], &mut with);
        assert_eq!(alone, with);
        // A plane every corner is outside of, after a cutting one: nothing.
        let away = Vec4::new(1.0, 0.0, 0.0, -5.0);
        clip_box(Vec3::ZERO, Vec3::ONE, &[cut[0], away], &mut with);
        assert!(with.is_empty());
    }
}
