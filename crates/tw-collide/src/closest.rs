//! Exact closest points between a segment and a triangle (Ericson, "Real-Time Collision
//! Detection", 2005, §5.1.5 point–triangle, §5.1.9 segment–segment), in f64: the distance a
//! capsule keeps from the geometry ([`crate::capsule`]) is the distance of its core segment.
//!
//! If the segment does not cross the triangle, the closest pair has a segment endpoint or a
//! point of the triangle's boundary in it (the distance is a convex function along the segment
//! and over the triangle, so an interior minimum of both at once is a crossing). So the answer
//! is the nearest of: each endpoint against the triangle, the segment against each edge, and
//! the segment's crossing of the triangle's plane when it crosses inside the triangle.

use glam::DVec3;

/// The point of triangle `a b c` nearest to `p` (a degenerate triangle gives a point of one
/// of its edges).
pub fn point_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE {
        // Degenerate (all regions' tests inconclusive): nearest of the edges.
        return nearest_of(p, [segment_point(p, a, b), segment_point(p, b, c), segment_point(p, c, a)]);
    }
    a + ab * (vb / denom) + ac * (vc / denom)
}

/// The point of segment `a b` nearest to `p`.
fn segment_point(p: DVec3, a: DVec3, b: DVec3) -> DVec3 {
    let ab = b - a;
    let l = ab.length_squared();
    if l <= 0.0 {
        return a;
    }
    a + ab * ((p - a).dot(ab) / l).clamp(0.0, 1.0)
}

fn nearest_of(p: DVec3, candidates: [DVec3; 3]) -> DVec3 {
    candidates.into_iter().min_by(|x, y| x.distance_squared(p).total_cmp(&y.distance_squared(p))).unwrap_or(p)
}

/// The closest points of segments `p1 q1` and `p2 q2` (first on the first).
pub fn segment_segment(p1: DVec3, q1: DVec3, p2: DVec3, q2: DVec3) -> (DVec3, DVec3) {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = d1.length_squared();
    let e = d2.length_squared();
    let f = d2.dot(r);
    let eps = 1e-300;
    if a <= eps && e <= eps {
        return (p1, p2);
    }
    let (s, t);
    if a <= eps {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(r);
        if e <= eps {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let s0 = if denom > 0.0 { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            } else {
                t = t0;
                s = s0;
            }
        }
    }
    (p1 + d1 * s, p2 + d2 * t)
}

/// The closest points of segment `p q` and triangle `tri` (first on the segment): equal where
/// the segment crosses the triangle.
pub fn segment_triangle(p: DVec3, q: DVec3, tri: &[DVec3; 3]) -> (DVec3, DVec3) {
    let [a, b, c] = *tri;
    let mut best = (p, point_triangle(p, a, b, c));
    let mut best_d = best.0.distance_squared(best.1);
    let mut consider = |pair: (DVec3, DVec3)| {
        let d = pair.0.distance_squared(pair.1);
        if d < best_d {
            best_d = d;
            best = pair;
        }
    };
    consider((q, point_triangle(q, a, b, c)));
    for (u, v) in [(a, b), (b, c), (c, a)] {
        consider(segment_segment(p, q, u, v));
    }
    // The crossing of the plane, if the segment crosses it (inside the triangle it is at
    // distance 0; outside, the pair is still a valid one and never the nearest).
    let n = (b - a).cross(c - a);
    let (dp, dq) = (n.dot(p - a), n.dot(q - a));
    if n != DVec3::ZERO && dp * dq <= 0.0 && dp != dq {
        let x = p + (q - p) * (dp / (dp - dq));
        consider((x, point_triangle(x, a, b, c)));
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use tw_core::rng::Rng;

    /// Uniform in the cube [-1, 1]³, from the project's generator.
    fn v(rng: &mut Rng) -> DVec3 {
        DVec3::from_array([(); 3].map(|_| rng.range_f64(-1.0, 1.0)))
    }

    /// The distance by dense sampling of the segment and the triangle (barycentric grid).
    fn brute(p: DVec3, q: DVec3, t: &[DVec3; 3], n: usize, m: usize) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..=n {
            let s = p + (q - p) * (i as f64 / n as f64);
            for j in 0..=m {
                for k in 0..=(m - j) {
                    let (u, v) = (j as f64 / m as f64, k as f64 / m as f64);
                    let x = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
                    best = best.min(s.distance(x));
                }
            }
        }
        best
    }

    #[test]
    fn segment_triangle_distance_matches_brute_force() {
        let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
        for case in 0..150 {
            let t = [v(&mut rng), v(&mut rng), v(&mut rng)];
            // Some segments cross, some lie near the plane, some are far.
            let (p, q) = match case % 3 {
                0 => (v(&mut rng) * 2.0, v(&mut rng) * 2.0),
                1 => {
                    let c = (t[0] + t[1] + t[2]) / 3.0;
                    let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
                    (c + n * 0.3 + v(&mut rng) * 0.2, c - n * 0.3 + v(&mut rng) * 0.2)
                }
                _ => (v(&mut rng) * 0.5, v(&mut rng) * 0.5),
            };
            let (s, x) = segment_triangle(p, q, &t);
            let exact = s.distance(x);
            // Both points lie on their shapes: the pair is a real one.
            assert!(s.distance(segment_point(s, p, q)) < 1e-9, "case {case}: not on the segment");
            assert!(
                x.distance(point_triangle(x, t[0], t[1], t[2])) < 1e-9,
                "case {case}: not on the triangle"
            );
            let sampled = brute(p, q, &t, 64, 40);
            // Sampling overestimates by at most the sample spacing.
            let spacing = (q - p).length() / 64.0
                + [t[1] - t[0], t[2] - t[0]].map(|e| e.length()).iter().sum::<f64>() / 40.0;
            assert!(exact <= sampled + 1e-9, "case {case}: exact {exact} > sampled {sampled}");
            assert!(sampled - exact <= spacing, "case {case}: exact {exact} far below sampled {sampled}");
        }
    }

    #[test]
    fn a_crossing_segment_is_at_distance_zero() {
        let t = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let (s, x) = segment_triangle(DVec3::new(0.2, 0.2, -1.0), DVec3::new(0.2, 0.2, 1.0), &t);
        assert!(s.distance(x) < 1e-12 && (x - DVec3::new(0.2, 0.2, 0.0)).length() < 1e-12);
        // Parallel above: the distance is the height.
        let (s, x) = segment_triangle(DVec3::new(-1.0, 0.1, 0.5), DVec3::new(2.0, 0.1, 0.5), &t);
        assert!((s.distance(x) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn degenerate_triangles_and_segments_are_answered() {
        let line = [DVec3::ZERO, DVec3::X, DVec3::X * 2.0];
        let (s, x) = segment_triangle(DVec3::new(1.0, 1.0, 0.0), DVec3::new(1.0, 1.0, 0.0), &line);
        assert!((s.distance(x) - 1.0).abs() < 1e-12);
        let point = [DVec3::ONE; 3];
        let (s, x) = segment_triangle(DVec3::ZERO, DVec3::ZERO, &point);
        assert!((s.distance(x) - 3f64.sqrt()).abs() < 1e-12);
    }
}
