//! FAR's fattened primitive (thesis ch. 5, "reliable culling"): the Minkowski sum of a triangle
//! with an axis-aligned cube of side p = max(2dX, 2dY, 2dZ) (d: the size of one cell of the
//! view's sampling grid) is enclosed in an oriented box — the tightest rectangle around the
//! triangle aligned with its longest edge, grown by √3·p/2 on every side in the plane and
//! √3·p/2 on each side along the normal (the sphere of radius √3·p/2 holds the cube in any
//! orientation, so the box holds the Minkowski sum in every view). Rasterized, such a box gives
//! a fragment at every pixel the triangle touches, whose depth range brackets the triangle's
//! depth there (the thesis' Lemmas 5–6), so full visibility of boxes can be trusted. The
//! within-distance variant grows the radius by D/2.

/// The 12 triangles of a box over corners numbered by bits (u: 1, v: 2, n: 4), wound outward
/// when (u, v, n) is right-handed.
pub const BOX_TRIANGLES: [[usize; 3]; 12] = [
    [0, 2, 3],
    [0, 3, 1],
    [4, 5, 7],
    [4, 7, 6],
    [0, 1, 5],
    [0, 5, 4],
    [2, 6, 7],
    [2, 7, 3],
    [0, 4, 6],
    [0, 6, 2],
    [1, 3, 7],
    [1, 7, 5],
];

type V = [f32; 3];

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V, b: V) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V, b: V) -> V {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn scale(a: V, s: f32) -> V {
    a.map(|x| x * s)
}
fn normalize(a: V) -> Option<V> {
    let l = dot(a, a).sqrt();
    (l > 0.0 && l.is_finite()).then(|| scale(a, 1.0 / l))
}

/// The 8 corners of the oriented box around triangle `t` grown by `radius`, numbered by bits
/// (see [`BOX_TRIANGLES`]). A degenerate triangle gets its axis-aligned box grown by `radius`.
pub fn oriented_box(t: &[V; 3], radius: f32) -> [V; 8] {
    let edges = [sub(t[1], t[0]), sub(t[2], t[1]), sub(t[0], t[2])];
    let longest =
        (0..3).max_by(|&a, &b| dot(edges[a], edges[a]).total_cmp(&dot(edges[b], edges[b]))).unwrap_or(0);
    let frame = normalize(edges[longest]).and_then(|u| {
        let n = normalize(cross(edges[0], scale(edges[2], -1.0)))?;
        Some([u, cross(n, u), n])
    });
    let [u, v, n] = frame.unwrap_or([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
    // Extents of the triangle along each axis of the frame, grown by the radius. The normal's
    // extent is nearly zero; rounding is covered by the radius, which is far larger than it.
    let range = |axis: V| {
        let d = t.map(|p| dot(p, axis));
        (d[0].min(d[1]).min(d[2]) - radius, d[0].max(d[1]).max(d[2]) + radius)
    };
    let (ru, rv, rn) = (range(u), range(v), range(n));
    std::array::from_fn(|c| {
        let a = if c & 1 != 0 { ru.1 } else { ru.0 };
        let b = if c & 2 != 0 { rv.1 } else { rv.0 };
        let m = if c & 4 != 0 { rn.1 } else { rn.0 };
        std::array::from_fn(|i| u[i] * a + v[i] * b + n[i] * m)
    })
}

/// FAR's fattening radius for cells of `cell` (dX, dY, dZ) and a distance `within` (0 for
/// overlap): √3·p/2 + D/2 with p = max(2dX, 2dY, 2dZ).
pub fn radius(cell: [f32; 3], within: f32) -> f32 {
    let p = 2.0 * cell[0].max(cell[1]).max(cell[2]);
    3f32.sqrt() * p / 2.0 + within / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inside(corners: &[V; 8], p: V) -> bool {
        // The box's own axes from its corners.
        let o = corners[0];
        [1usize, 2, 4].iter().all(|&k| {
            let axis = sub(corners[k], o);
            let d = dot(sub(p, o), axis) / dot(axis, axis);
            (-1e-4..=1.0 + 1e-4).contains(&d)
        })
    }

    #[test]
    fn box_holds_the_triangle_grown_by_the_radius() {
        let t = [[0.0, 0.0, 0.0], [3.0, 1.0, 0.5], [1.0, 2.0, -1.0]];
        let r = 0.25;
        let c = oriented_box(&t, r);
        // The corners of a cube of side 2r/√3 around every vertex: inside.
        let h = r / 3f32.sqrt();
        for p in t {
            for k in 0..8 {
                let q = [
                    p[0] + if k & 1 != 0 { h } else { -h },
                    p[1] + if k & 2 != 0 { h } else { -h },
                    p[2] + if k & 4 != 0 { h } else { -h },
                ];
                assert!(inside(&c, q), "{q:?}");
            }
        }
        // A point farther than the radius off the plane: outside.
        let n = normalize(cross(sub(t[1], t[0]), sub(t[2], t[0]))).unwrap();
        let centre = scale(
            [t[0][0] + t[1][0] + t[2][0], t[0][1] + t[1][1] + t[2][1], t[0][2] + t[1][2] + t[2][2]],
            1.0 / 3.0,
        );
        assert!(!inside(
            &c,
            [centre[0] + n[0] * 2.0 * r, centre[1] + n[1] * 2.0 * r, centre[2] + n[2] * 2.0 * r]
        ));
    }

    #[test]
    fn degenerate_triangle_gets_a_box() {
        let t = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        let c = oriented_box(&t, 0.1);
        assert!(c.iter().all(|p| p.iter().all(|v| v.is_finite())));
        assert!(inside(&c, [2.0, 0.05, -0.05]));
    }
}
