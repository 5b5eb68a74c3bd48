//! The exact triangle–triangle overlap test of Guigue and Devillers ("Fast and robust triangle-
//! triangle overlap test using orientation predicates", 2003): only signs of 3×3 determinants
//! (orientations) decide, so no intersection segment is ever computed and no division is made.
//!
//! Triangles are closed sets: touching at a vertex, along an edge or in a coplanar region counts as
//! overlapping. Coordinates are given in f32 and every predicate is evaluated in f64 on
//! differences of the inputs, which keeps the signs right for all but extremely near-degenerate
//! configurations (a product of three 25-bit differences needs 75 bits; the rounding error of f64
//! is below 2^-50 of the largest term). A degenerate triangle (three collinear points) has no
//! plane to orient against; it is reported as not overlapping anything (the scenes and importers
//! drop them, see `tw_io::Scene`).

type V = [f64; 3];

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: V, b: V) -> V {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The side of `d` against the plane through `a`, `b`, `c`: positive on the side the normal
/// (b − a) × (c − a) points to, negative on the other, zero on the plane. (The paper's
/// [a, b, c, d] with the sign its case tables assume.)
fn side(a: V, b: V, c: V, d: V) -> f64 {
    dot(sub(d, c), cross(sub(a, c), sub(b, c)))
}

fn widen(p: [f32; 3]) -> V {
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

/// Whether the closed triangles `t1` and `t2` overlap (share at least one point).
pub fn triangles_overlap(t1: &[[f32; 3]; 3], t2: &[[f32; 3]; 3]) -> bool {
    let [p1, q1, r1] = t1.map(widen);
    let [p2, q2, r2] = t2.map(widen);
    let n1 = cross(sub(q1, p1), sub(r1, p1));
    let n2 = cross(sub(q2, p2), sub(r2, p2));
    if n1 == [0.0; 3] || n2 == [0.0; 3] {
        return false;
    }
    // Triangle 1 against the plane of triangle 2.
    let dp1 = side(p2, q2, r2, p1);
    let dq1 = side(p2, q2, r2, q1);
    let dr1 = side(p2, q2, r2, r1);
    if (dp1 > 0.0 && dq1 > 0.0 && dr1 > 0.0) || (dp1 < 0.0 && dq1 < 0.0 && dr1 < 0.0) {
        return false;
    }
    // Triangle 2 against the plane of triangle 1.
    let dp2 = side(p1, q1, r1, p2);
    let dq2 = side(p1, q1, r1, q2);
    let dr2 = side(p1, q1, r1, r2);
    if (dp2 > 0.0 && dq2 > 0.0 && dr2 > 0.0) || (dp2 < 0.0 && dq2 < 0.0 && dr2 < 0.0) {
        return false;
    }
    let t2v = [p2, q2, r2];
    let d2 = [dp2, dq2, dr2];
    // Permute triangle 1 so that p1 is alone on its side of plane 2 (the paper's case table).
    if dp1 > 0.0 {
        if dq1 > 0.0 {
            stage2([r1, p1, q1], swap(t2v), swap(d2), n1)
        } else if dr1 > 0.0 {
            stage2([q1, r1, p1], swap(t2v), swap(d2), n1)
        } else {
            stage2([p1, q1, r1], t2v, d2, n1)
        }
    } else if dp1 < 0.0 {
        if dq1 < 0.0 {
            stage2([r1, p1, q1], t2v, d2, n1)
        } else if dr1 < 0.0 {
            stage2([q1, r1, p1], t2v, d2, n1)
        } else {
            stage2([p1, q1, r1], swap(t2v), swap(d2), n1)
        }
    } else if dq1 < 0.0 {
        if dr1 >= 0.0 {
            stage2([q1, r1, p1], swap(t2v), swap(d2), n1)
        } else {
            stage2([p1, q1, r1], t2v, d2, n1)
        }
    } else if dq1 > 0.0 {
        if dr1 > 0.0 {
            stage2([p1, q1, r1], swap(t2v), swap(d2), n1)
        } else {
            stage2([q1, r1, p1], t2v, d2, n1)
        }
    } else if dr1 > 0.0 {
        stage2([r1, p1, q1], t2v, d2, n1)
    } else if dr1 < 0.0 {
        stage2([r1, p1, q1], swap(t2v), swap(d2), n1)
    } else {
        coplanar_overlap([p1, q1, r1], [p2, q2, r2], n1)
    }
}

/// Swaps the last two of three (reverses the orientation of a triangle).
fn swap<T: Copy>(t: [T; 3]) -> [T; 3] {
    [t[0], t[2], t[1]]
}

/// The second permutation of the paper (`TRI_TRI_3D`): p2 alone on its side of plane 1, then
/// the interval check.
fn stage2(t1: [V; 3], t2: [V; 3], d2: [f64; 3], n1: V) -> bool {
    let [p1, q1, r1] = t1;
    let [p2, q2, r2] = t2;
    let [dp2, dq2, dr2] = d2;
    if dp2 > 0.0 {
        if dq2 > 0.0 {
            check_min_max([p1, r1, q1], [r2, p2, q2])
        } else if dr2 > 0.0 {
            check_min_max([p1, r1, q1], [q2, r2, p2])
        } else {
            check_min_max([p1, q1, r1], [p2, q2, r2])
        }
    } else if dp2 < 0.0 {
        if dq2 < 0.0 {
            check_min_max([p1, q1, r1], [r2, p2, q2])
        } else if dr2 < 0.0 {
            check_min_max([p1, q1, r1], [q2, r2, p2])
        } else {
            check_min_max([p1, r1, q1], [p2, q2, r2])
        }
    } else if dq2 < 0.0 {
        if dr2 >= 0.0 {
            check_min_max([p1, r1, q1], [q2, r2, p2])
        } else {
            check_min_max([p1, q1, r1], [p2, q2, r2])
        }
    } else if dq2 > 0.0 {
        if dr2 > 0.0 {
            check_min_max([p1, r1, q1], [p2, q2, r2])
        } else {
            check_min_max([p1, q1, r1], [q2, r2, p2])
        }
    } else if dr2 > 0.0 {
        check_min_max([p1, q1, r1], [r2, p2, q2])
    } else if dr2 < 0.0 {
        check_min_max([p1, r1, q1], [r2, p2, q2])
    } else {
        coplanar_overlap(t1, t2, n1)
    }
}

/// Whether the two intervals the triangles cut on the planes' common line overlap, decided by
/// two orientations (the paper's `CHECK_MIN_MAX`).
fn check_min_max(t1: [V; 3], t2: [V; 3]) -> bool {
    let [p1, q1, r1] = t1;
    let [p2, q2, r2] = t2;
    if dot(sub(q2, q1), cross(sub(p2, q1), sub(p1, q1))) > 0.0 {
        return false;
    }
    dot(sub(r2, p1), cross(sub(p2, p1), sub(r1, p1))) <= 0.0
}

/// Coplanar triangles: projected on the coordinate plane where the common normal `n` is largest
/// (which keeps their orientation up to sign), then the 2-D test.
fn coplanar_overlap(t1: [V; 3], t2: [V; 3], n: V) -> bool {
    let (ax, ay, az) = (n[0].abs(), n[1].abs(), n[2].abs());
    let (i, j) = if az >= ax && az >= ay {
        (0, 1)
    } else if ax >= ay {
        (1, 2)
    } else {
        (0, 2)
    };
    let flat = |t: [V; 3]| t.map(|p| [p[i], p[j]]);
    triangles_overlap_2d(flat(t1), flat(t2))
}

/// Whether the closed triangles `t1` and `t2` come within `distance` of each other (overlap for
/// 0): FAR's within-distance query. Two disjoint triangles are nearest either between two edges
/// or between a vertex and the other's face, so the distance is the least of 9 segment–segment
/// and 6 point–triangle distances.
pub fn triangles_within(t1: &[[f32; 3]; 3], t2: &[[f32; 3]; 3], distance: f32) -> bool {
    if triangles_overlap(t1, t2) {
        return true;
    }
    if distance <= 0.0 {
        return false;
    }
    let (a, b) = (t1.map(widen), t2.map(widen));
    let d2 = (distance as f64) * (distance as f64);
    for i in 0..3 {
        if point_triangle_sq(a[i], b) <= d2 || point_triangle_sq(b[i], a) <= d2 {
            return true;
        }
        for j in 0..3 {
            if segment_segment_sq(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]) <= d2 {
                return true;
            }
        }
    }
    false
}

fn norm_sq(a: V) -> f64 {
    dot(a, a)
}

/// Squared distance from `p` to the closed segment `ab`.
fn point_segment_sq(p: V, a: V, b: V) -> f64 {
    let ab = sub(b, a);
    let len = norm_sq(ab);
    let t = if len > 0.0 { (dot(sub(p, a), ab) / len).clamp(0.0, 1.0) } else { 0.0 };
    norm_sq(sub(p, [a[0] + ab[0] * t, a[1] + ab[1] * t, a[2] + ab[2] * t]))
}

/// Squared distance from `p` to the closed triangle `t` (non-degenerate).
fn point_triangle_sq(p: V, t: [V; 3]) -> f64 {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let nn = norm_sq(n);
    if nn > 0.0 {
        // Inside the prism over the triangle: the distance to the plane.
        let inside = (0..3).all(|k| dot(cross(sub(t[(k + 1) % 3], t[k]), sub(p, t[k])), n) >= 0.0);
        if inside {
            let h = dot(sub(p, t[0]), n);
            return h * h / nn;
        }
    }
    (0..3).map(|k| point_segment_sq(p, t[k], t[(k + 1) % 3])).fold(f64::INFINITY, f64::min)
}

/// Squared distance between the closed segments `p1q1` and `p2q2` (Ericson, "Real-Time
/// Collision Detection", §5.1.9).
fn segment_segment_sq(p1: V, q1: V, p2: V, q2: V) -> f64 {
    let (d1, d2, r) = (sub(q1, p1), sub(q2, p2), sub(p1, p2));
    let (a, e, f) = (norm_sq(d1), norm_sq(d2), dot(d2, r));
    if a <= 0.0 && e <= 0.0 {
        return norm_sq(r);
    }
    if a <= 0.0 {
        return point_segment_sq(p1, p2, q2);
    }
    let c = dot(d1, r);
    if e <= 0.0 {
        return point_segment_sq(p2, p1, q1);
    }
    let b = dot(d1, d2);
    let denom = a * e - b * b;
    let mut s = if denom > 0.0 { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
    let mut t = (b * s + f) / e;
    if t < 0.0 {
        t = 0.0;
        s = (-c / a).clamp(0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = ((b - c) / a).clamp(0.0, 1.0);
    }
    let c1 = [p1[0] + d1[0] * s, p1[1] + d1[1] * s, p1[2] + d1[2] * s];
    let c2 = [p2[0] + d2[0] * t, p2[1] + d2[1] * t, p2[2] + d2[2] * t];
    norm_sq(sub(c1, c2))
}

type P = [f64; 2];

fn orient2d(a: P, b: P, c: P) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Whether the closed 2-D triangles overlap: an edge of one meets an edge of the other, or one
/// lies inside the other.
pub(crate) fn triangles_overlap_2d(t1: [P; 3], t2: [P; 3]) -> bool {
    for a in 0..3 {
        for b in 0..3 {
            if segments_meet(t1[a], t1[(a + 1) % 3], t2[b], t2[(b + 1) % 3]) {
                return true;
            }
        }
    }
    point_in_triangle(t1[0], t2) || point_in_triangle(t2[0], t1)
}

/// Whether the closed segments `ab` and `cd` share a point.
fn segments_meet(a: P, b: P, c: P, d: P) -> bool {
    let d1 = orient2d(c, d, a);
    let d2 = orient2d(c, d, b);
    let d3 = orient2d(a, b, c);
    let d4 = orient2d(a, b, d);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(c, d, a))
        || (d2 == 0.0 && on_segment(c, d, b))
        || (d3 == 0.0 && on_segment(a, b, c))
        || (d4 == 0.0 && on_segment(a, b, d))
}

/// For `p` collinear with `ab`: whether it lies between them.
fn on_segment(a: P, b: P, p: P) -> bool {
    p[0] >= a[0].min(b[0]) && p[0] <= a[0].max(b[0]) && p[1] >= a[1].min(b[1]) && p[1] <= a[1].max(b[1])
}

/// Whether `p` lies in the closed triangle `t` (either orientation).
fn point_in_triangle(p: P, t: [P; 3]) -> bool {
    let d = [orient2d(t[0], t[1], p), orient2d(t[1], t[2], p), orient2d(t[2], t[0], p)];
    let neg = d.iter().any(|&x| x < 0.0);
    let pos = d.iter().any(|&x| x > 0.0);
    !(neg && pos)
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

    fn both(a: &[[f32; 3]; 3], b: &[[f32; 3]; 3]) -> bool {
        let r = triangles_overlap(a, b);
        // The answer must not depend on the order or the orientation of either triangle.
        assert_eq!(r, triangles_overlap(b, a));
        assert_eq!(r, triangles_overlap(&swap(*a), b));
        assert_eq!(r, triangles_overlap(a, &[b[1], b[2], b[0]]));
        r
    }

    #[test]
    fn piercing_triangle_overlaps() {
        let t = [[0.2, 0.2, -1.0], [0.3, 0.2, 1.0], [0.2, 0.3, 1.0]];
        assert!(both(&BASE, &t));
    }

    #[test]
    fn separated_triangles_do_not() {
        let t = [[0.2, 0.2, 0.5], [0.3, 0.2, 1.0], [0.2, 0.3, 1.0]];
        assert!(!both(&BASE, &t));
    }

    #[test]
    fn touching_edge_overlaps() {
        // A vertical triangle whose lower edge lies on the base triangle's hypotenuse.
        let t = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, 1.0]];
        assert!(both(&BASE, &t));
        // Touching at one vertex only.
        let v = [[1.0, 0.0, 0.0], [2.0, 0.0, 1.0], [2.0, 1.0, 1.0]];
        assert!(both(&BASE, &v));
    }

    #[test]
    fn near_miss_does_not() {
        // Just above the base triangle's plane, by one part in a million.
        let t = [[0.2, 0.2, 1e-6], [0.3, 0.2, 1.0], [0.2, 0.3, 1.0]];
        assert!(!both(&BASE, &t));
        // Past the hypotenuse by a hair, crossing the plane.
        let e = 1e-6;
        let u = [[0.5 + e, 0.5 + e, -1.0], [0.5 + e, 0.5 + e, 1.0], [1.0, 1.0, 0.0]];
        assert!(!both(&BASE, &u));
    }

    #[test]
    fn coplanar_cases() {
        // Overlapping regions.
        let o = [[0.2, 0.2, 0.0], [2.0, 0.2, 0.0], [0.2, 2.0, 0.0]];
        assert!(both(&BASE, &o));
        // One inside the other.
        let inside = [[0.1, 0.1, 0.0], [0.3, 0.1, 0.0], [0.1, 0.3, 0.0]];
        assert!(both(&BASE, &inside));
        // Sharing an edge.
        let shared = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]];
        assert!(both(&BASE, &shared));
        // Disjoint in the same plane.
        let apart = [[0.6, 0.6, 0.0], [2.0, 0.6, 0.0], [0.6, 2.0, 0.0]];
        assert!(!both(&BASE, &apart));
        // Coplanar in a plane that is not a coordinate plane.
        let tilt = |t: [[f32; 3]; 3]| t.map(|p| [p[0], p[1], p[0] + p[1]]);
        assert!(both(&tilt(BASE), &tilt(o)));
        assert!(!both(&tilt(BASE), &tilt(apart)));
    }

    /// Whether the closed segment `ab` meets the closed triangle `t` (exact for small integer
    /// coordinates): an independent test built from edges, for the cross-check below.
    fn segment_meets_triangle(a: V, b: V, t: [V; 3]) -> bool {
        let (sa, sb) = (side(t[0], t[1], t[2], a), side(t[0], t[1], t[2], b));
        if (sa > 0.0 && sb > 0.0) || (sa < 0.0 && sb < 0.0) {
            return false;
        }
        if sa == 0.0 && sb == 0.0 {
            let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
            let (ax, ay, az) = (n[0].abs(), n[1].abs(), n[2].abs());
            let (i, j) = if az >= ax && az >= ay {
                (0, 1)
            } else if ax >= ay {
                (1, 2)
            } else {
                (0, 2)
            };
            let f = |p: V| [p[i], p[j]];
            let t = t.map(f);
            return (0..3).any(|k| segments_meet(f(a), f(b), t[k], t[(k + 1) % 3]))
                || point_in_triangle(f(a), t)
                || point_in_triangle(f(b), t);
        }
        // The line ab crosses the plane within the segment: inside the triangle iff it passes
        // on the same side of all three edges.
        let o = [side(a, b, t[0], t[1]), side(a, b, t[1], t[2]), side(a, b, t[2], t[0])];
        !(o.iter().any(|&x| x > 0.0) && o.iter().any(|&x| x < 0.0))
    }

    #[test]
    fn agrees_with_an_edge_based_test_on_integer_grids() {
        let mut n = 0u64;
        let mut next = || {
            n += 1;
            (crate::scenes::random_soup(1, 1, 0.0, n)[0].positions[0][0] * 4.0).floor()
        };
        let mut hits = 0;
        for _ in 0..20_000 {
            let t1: [[f32; 3]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| next()));
            let t2: [[f32; 3]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| next()));
            let (w1, w2) = (t1.map(widen), t2.map(widen));
            if cross(sub(w1[1], w1[0]), sub(w1[2], w1[0])) == [0.0; 3]
                || cross(sub(w2[1], w2[0]), sub(w2[2], w2[0])) == [0.0; 3]
            {
                continue;
            }
            let edges = (0..3).any(|k| segment_meets_triangle(w1[k], w1[(k + 1) % 3], w2))
                || (0..3).any(|k| segment_meets_triangle(w2[k], w2[(k + 1) % 3], w1));
            assert_eq!(triangles_overlap(&t1, &t2), edges, "{t1:?} {t2:?}");
            hits += edges as usize;
        }
        assert!(hits > 1000, "{hits}");
    }

    #[test]
    fn within_distance_measures_the_gap() {
        // Parallel, 0.5 apart: face to face.
        let above = BASE.map(|p| [p[0], p[1], 0.5]);
        assert!(!triangles_within(&BASE, &above, 0.49));
        assert!(triangles_within(&BASE, &above, 0.51));
        // Edge to edge: a vertical triangle beyond the hypotenuse, crossing it at right angles.
        let g = 0.3 / 2f32.sqrt();
        let fin = [[0.5 + g, 0.5 + g, -1.0], [0.5 + g, 0.5 + g, 1.0], [2.0, 2.0, 0.0]];
        assert!(!triangles_within(&BASE, &fin, 0.29));
        assert!(triangles_within(&BASE, &fin, 0.31));
        // Vertex to vertex, diagonally.
        let far = [[-1.0, -1.0, -1.0], [-2.0, -1.0, -1.0], [-1.0, -2.0, -1.0]];
        assert!(!triangles_within(&BASE, &far, 1.73));
        assert!(triangles_within(&BASE, &far, 1.74));
        // Overlap is distance 0.
        assert!(triangles_within(&BASE, &BASE, 0.0));
    }

    #[test]
    fn degenerate_triangles_never_overlap() {
        let line = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        assert!(!triangles_overlap(&BASE, &line));
        assert!(!triangles_overlap(&line, &BASE));
    }
}
