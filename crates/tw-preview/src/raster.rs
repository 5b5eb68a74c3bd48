//! Triangle setup and scan conversion.
//!
//! 1. [`Projector::classify`]: outcodes of the three camera-space vertices against the view
//!    frustum (reject when all lie outside one plane) and against the near plane and a guard
//!    band 4× the image (clip when any vertex lies outside). An orthographic projector's view
//!    volume is a box: its side planes do not widen with depth.
//! 2. [`clip`]: Sutherland–Hodgman clipping of the triangle against those planes in camera space
//!    (Sutherland & Hodgman, "Reentrant polygon clipping", CACM 1974), giving a convex polygon
//!    of up to 8 vertices, drawn as a fan. Clipping in camera space before the divide is what
//!    makes triangles that cross the near plane (or pass behind the eye) correct.
//! 3. [`rasterize`]: the edge-function rasterizer of Pineda ("A parallel algorithm for polygon
//!    rasterization", SIGGRAPH 1988) over the triangle's bounding box, in exact 64-bit integer
//!    arithmetic on vertices snapped to 1/256 pixel, with the top-left fill rule of Direct3D and
//!    OpenGL: a pixel centre on a shared edge belongs to exactly one of the triangles. Depth is
//!    1/z, which is affine in screen space, so interpolating it linearly is perspective-correct;
//!    in an orthographic projection z itself is affine in screen space, so z is interpolated and
//!    inverted per pixel (the depth buffer holds 1/z either way).

/// Sub-pixel precision: vertices snap to 1/256 pixel.
const SUB_BITS: u32 = 8;
const SUB: i64 = 1 << SUB_BITS;
const HALF: i64 = SUB / 2;
/// The guard band as a multiple of the image's half-size: vertices within it are projected
/// directly; beyond it, triangles are clipped so that fixed-point coordinates stay small.
const GUARD: f64 = 4.0;

/// A projected vertex: pixel coordinates (x right, y down, pixel centres at +0.5) and the depth
/// that is affine in screen space: 1/z in perspective, z in orthographic ([`rasterize`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ScreenVertex {
    pub x: f64,
    pub y: f64,
    pub inv_z: f64,
}

/// Outcome of [`Projector::classify`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Class {
    /// Entirely outside the frustum: draw nothing.
    Outside,
    /// Within the near plane and the guard band: project directly.
    Inside,
    /// Crosses the near plane or the guard band: clip first.
    Clip,
}

/// Camera-space to pixel mapping.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Projector {
    pub width: u32,
    pub height: u32,
    /// Pixels per unit of x/z (and y/z); orthographic: pixels per scene unit of x (and y).
    pub focal: f64,
    pub near: f64,
    /// Parallel projection along z (the view volume is a box).
    pub orthographic: bool,
    /// Half-extents of the view frustum as slopes: |x| ≤ fx·z, |y| ≤ fy·z; orthographic: as
    /// lengths, |x| ≤ fx, |y| ≤ fy.
    fx: f64,
    fy: f64,
}

const NEAR: u8 = 1;
const LEFT: u8 = 2;
const RIGHT: u8 = 4;
const BOTTOM: u8 = 8;
const TOP: u8 = 16;

impl Projector {
    pub fn new(width: u32, height: u32, fovy: f64, near: f64) -> Projector {
        Projector::with_focal(width, height, 0.5 * height as f64 / (0.5 * fovy).tan(), near, false)
    }

    /// An orthographic projector whose view is `view_height` scene units high.
    pub fn orthographic(width: u32, height: u32, view_height: f64, near: f64) -> Projector {
        Projector::with_focal(width, height, height as f64 / view_height, near, true)
    }

    fn with_focal(width: u32, height: u32, focal: f64, near: f64, orthographic: bool) -> Projector {
        Projector {
            width,
            height,
            focal,
            near,
            orthographic,
            fx: 0.5 * width as f64 / focal,
            fy: 0.5 * height as f64 / focal,
        }
    }

    /// What the side planes scale with at `z`: the depth in perspective, 1 in orthographic.
    #[inline]
    fn spread(&self, z: f64) -> f64 {
        if self.orthographic {
            1.0
        } else {
            z
        }
    }

    /// Outcodes of a camera-space point against the frustum scaled by `g` (1 = the image).
    #[inline]
    fn code(&self, p: [f64; 3], g: f64) -> u8 {
        let z = self.spread(p[2]);
        let (sx, sy) = (self.fx * g * z, self.fy * g * z);
        ((p[2] < self.near) as u8 * NEAR)
            | ((p[0] < -sx) as u8 * LEFT)
            | ((p[0] > sx) as u8 * RIGHT)
            | ((p[1] < -sy) as u8 * BOTTOM)
            | ((p[1] > sy) as u8 * TOP)
    }

    #[inline]
    pub fn classify(&self, c: &[[f64; 3]; 3]) -> Class {
        let f = [self.code(c[0], 1.0), self.code(c[1], 1.0), self.code(c[2], 1.0)];
        if f[0] & f[1] & f[2] != 0 {
            return Class::Outside;
        }
        let g = self.code(c[0], GUARD) | self.code(c[1], GUARD) | self.code(c[2], GUARD);
        if g == 0 {
            Class::Inside
        } else {
            Class::Clip
        }
    }

    /// Projects a camera-space point with z ≥ near.
    #[inline]
    pub fn project(&self, p: [f64; 3]) -> ScreenVertex {
        let (scale, depth) = if self.orthographic { (1.0, p[2]) } else { (1.0 / p[2], 1.0 / p[2]) };
        ScreenVertex {
            x: 0.5 * self.width as f64 + p[0] * scale * self.focal,
            y: 0.5 * self.height as f64 - p[1] * scale * self.focal,
            inv_z: depth,
        }
    }

    /// The planes a clipped polygon must be inside of, as (a, b, c, d): a·x + b·y + c·z + d ≥ 0.
    fn clip_planes(&self) -> [[f64; 4]; 5] {
        let (gx, gy) = (self.fx * GUARD, self.fy * GUARD);
        // The side planes: |x| ≤ gx·z in perspective, |x| ≤ gx in orthographic.
        let (pz, pd) = if self.orthographic { (0.0, 1.0) } else { (1.0, 0.0) };
        [
            [0.0, 0.0, 1.0, -self.near],
            [1.0, 0.0, gx * pz, gx * pd],
            [-1.0, 0.0, gx * pz, gx * pd],
            [0.0, 1.0, gy * pz, gy * pd],
            [0.0, -1.0, gy * pz, gy * pd],
        ]
    }
}

/// A convex polygon of up to [`MAX_POLY`] vertices.
pub(crate) struct Polygon {
    pub v: [[f64; 3]; MAX_POLY],
    pub len: usize,
}

/// A triangle clipped by 5 planes has at most 3 + 5 vertices.
pub(crate) const MAX_POLY: usize = 8;

/// Clips a camera-space triangle to the near plane and the guard band. The result may be empty.
pub(crate) fn clip(p: &Projector, tri: &[[f64; 3]; 3]) -> Polygon {
    let mut a = Polygon { v: [[0.0; 3]; MAX_POLY], len: 3 };
    a.v[..3].copy_from_slice(tri);
    let mut b = Polygon { v: [[0.0; 3]; MAX_POLY], len: 0 };
    for plane in p.clip_planes() {
        let d = |q: [f64; 3]| plane[0] * q[0] + plane[1] * q[1] + plane[2] * q[2] + plane[3];
        b.len = 0;
        for i in 0..a.len {
            let cur = a.v[i];
            let next = a.v[(i + 1) % a.len];
            let (dc, dn) = (d(cur), d(next));
            if dc >= 0.0 && b.len < MAX_POLY {
                b.v[b.len] = cur;
                b.len += 1;
            }
            if (dc >= 0.0) != (dn >= 0.0) && b.len < MAX_POLY {
                let t = dc / (dc - dn);
                b.v[b.len] = [
                    cur[0] + (next[0] - cur[0]) * t,
                    cur[1] + (next[1] - cur[1]) * t,
                    cur[2] + (next[2] - cur[2]) * t,
                ];
                b.len += 1;
            }
        }
        std::mem::swap(&mut a, &mut b);
        if a.len < 3 {
            a.len = 0;
            break;
        }
    }
    // Intersections computed in floating point may land a hair outside the near plane.
    for q in &mut a.v[..a.len] {
        q[2] = q[2].max(p.near);
    }
    a
}

#[inline]
fn ceil_div(a: i64, b: i64) -> i64 {
    -((-a).div_euclid(b))
}

/// Scan-converts a triangle into a `width` × `height` image, calling `plot(pixel index, 1/z)`
/// for every pixel whose centre it covers (top-left rule on edges). Either winding is drawn.
/// Vertices must lie within the guard band (coordinates of at most a few million pixels).
/// `orthographic`: the vertices carry z, not 1/z ([`Projector::project`]); it is interpolated
/// and inverted per pixel.
#[inline]
pub(crate) fn rasterize(
    v: [ScreenVertex; 3],
    width: u32,
    height: u32,
    orthographic: bool,
    mut plot: impl FnMut(usize, f32),
) {
    let snap =
        |s: &ScreenVertex| ((s.x * SUB as f64).round() as i64, (s.y * SUB as f64).round() as i64, s.inv_z);
    let (p0, mut p1, mut p2) = (snap(&v[0]), snap(&v[1]), snap(&v[2]));
    let mut area = (p1.0 - p0.0) * (p2.1 - p0.1) - (p1.1 - p0.1) * (p2.0 - p0.0);
    if area == 0 {
        return;
    }
    if area < 0 {
        std::mem::swap(&mut p1, &mut p2);
        area = -area;
    }
    // Pixels whose centres (i·SUB + HALF) lie in the bounding box, clamped to the image.
    let (min_x, max_x) = (p0.0.min(p1.0).min(p2.0), p0.0.max(p1.0).max(p2.0));
    let (min_y, max_y) = (p0.1.min(p1.1).min(p2.1), p0.1.max(p1.1).max(p2.1));
    let i0 = ceil_div(min_x - HALF, SUB).max(0);
    let i1 = (max_x - HALF).div_euclid(SUB).min(width as i64 - 1);
    let j0 = ceil_div(min_y - HALF, SUB).max(0);
    let j1 = (max_y - HALF).div_euclid(SUB).min(height as i64 - 1);
    if i0 > i1 || j0 > j1 {
        return;
    }
    let (px, py) = (i0 * SUB + HALF, j0 * SUB + HALF);
    // Edge a→b: E(p) = (b.x − a.x)(p.y − a.y) − (b.y − a.y)(p.x − a.x), positive inside. Edges
    // that are not top or left lose 1 so that a centre exactly on them is outside.
    let edge = |a: (i64, i64, f64), b: (i64, i64, f64)| {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let top_left = dy < 0 || (dy == 0 && dx > 0);
        let e = dx * (py - a.1) - dy * (px - a.0) - (!top_left) as i64;
        (e, -dy * SUB, dx * SUB)
    };
    let (mut r0, sx0, sy0) = edge(p1, p2); // weight of p0
    let (mut r1, sx1, sy1) = edge(p2, p0); // weight of p1
    let (mut r2, sx2, sy2) = edge(p0, p1); // weight of p2
    let inv_area = 1.0 / area as f64;
    let (z0, k1, k2) = (p0.2, (p1.2 - p0.2) * inv_area, (p2.2 - p0.2) * inv_area);
    let w = width as usize;
    for j in j0..=j1 {
        let (mut e0, mut e1, mut e2) = (r0, r1, r2);
        let row = j as usize * w;
        for i in i0..=i1 {
            if (e0 | e1 | e2) >= 0 {
                let z = z0 + e1 as f64 * k1 + e2 as f64 * k2;
                plot(row + i as usize, if orthographic { 1.0 / z } else { z } as f32);
            }
            e0 += sx0;
            e1 += sx1;
            e2 += sx2;
        }
        r0 += sy0;
        r1 += sy1;
        r2 += sy2;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tw_core::Rng;

    fn sv(x: f64, y: f64) -> ScreenVertex {
        ScreenVertex { x, y, inv_z: 1.0 }
    }

    fn coverage(tris: &[[ScreenVertex; 3]], w: u32, h: u32) -> Vec<u32> {
        let mut c = vec![0u32; (w * h) as usize];
        for t in tris {
            rasterize(*t, w, h, false, |i, _| c[i] += 1);
        }
        c
    }

    #[test]
    fn right_triangle_covers_exactly_the_centres_inside() {
        // Legs on x = 2 and y = 2, hypotenuse x + y = 10: centres (i+.5, j+.5) with i, j ≥ 2 and
        // i + j + 1 < 10 (centres on the hypotenuse, a right/bottom edge, are outside).
        let c = coverage(&[[sv(2.0, 2.0), sv(8.0, 2.0), sv(2.0, 8.0)]], 10, 10);
        for j in 0..10 {
            for i in 0..10 {
                let inside = i >= 2 && j >= 2 && i + j < 9;
                assert_eq!(c[j * 10 + i], inside as u32, "pixel {i},{j}");
            }
        }
    }

    #[test]
    fn winding_does_not_matter() {
        let a = coverage(&[[sv(1.3, 0.2), sv(7.7, 3.1), sv(2.2, 9.4)]], 10, 10);
        let b = coverage(&[[sv(1.3, 0.2), sv(2.2, 9.4), sv(7.7, 3.1)]], 10, 10);
        assert_eq!(a, b);
        assert!(a.iter().sum::<u32>() > 20);
    }

    #[test]
    fn shared_edges_are_drawn_exactly_once() {
        // A jittered grid of triangles covering more than the image, with vertices on pixel
        // centres and edges through them: every pixel is covered exactly once.
        let (w, h) = (64u32, 48u32);
        let n = 9;
        let mut rng = Rng::new(3);
        let mut grid = vec![[0.0f64; 2]; (n + 1) * (n + 1)];
        for y in 0..=n {
            for x in 0..=n {
                let edge = x == 0 || y == 0 || x == n || y == n;
                let jitter = |r: &mut Rng| if edge { 0.0 } else { r.range_f64(-1.2, 1.2) };
                // Snap some vertices onto pixel centres to exercise exact ties.
                let mut p =
                    [-4.0 + x as f64 * 9.0 + jitter(&mut rng), -4.0 + y as f64 * 7.0 + jitter(&mut rng)];
                if rng.chance(0.3) && !edge {
                    p = [p[0].floor() + 0.5, p[1].floor() + 0.5];
                }
                grid[y * (n + 1) + x] = p;
            }
        }
        let v = |x: usize, y: usize| {
            let p = grid[y * (n + 1) + x];
            sv(p[0], p[1])
        };
        let mut tris = Vec::new();
        for y in 0..n {
            for x in 0..n {
                tris.push([v(x, y), v(x + 1, y), v(x + 1, y + 1)]);
                tris.push([v(x, y), v(x + 1, y + 1), v(x, y + 1)]);
            }
        }
        let c = coverage(&tris, w, h);
        assert!(c.iter().all(|&k| k == 1), "{:?}", c.iter().enumerate().find(|(_, &k)| k != 1));
    }

    #[test]
    fn degenerate_and_offscreen_triangles_draw_nothing() {
        let c = coverage(
            &[
                [sv(1.0, 1.0), sv(5.0, 5.0), sv(9.0, 9.0)],
                [sv(-50.0, -50.0), sv(-10.0, -50.0), sv(-50.0, -10.0)],
                [sv(20.0, 1.0), sv(30.0, 1.0), sv(20.0, 9.0)],
            ],
            10,
            10,
        );
        assert!(c.iter().all(|&k| k == 0));
    }

    #[test]
    fn depth_is_interpolated_linearly_in_screen_space() {
        let t = [
            ScreenVertex { x: 0.0, y: 0.0, inv_z: 1.0 },
            ScreenVertex { x: 100.0, y: 0.0, inv_z: 0.5 },
            ScreenVertex { x: 0.0, y: 100.0, inv_z: 1.0 },
        ];
        let mut z = vec![0f32; 100 * 100];
        rasterize(t, 100, 100, false, |i, d| z[i] = d);
        // At x = 50.5 on any covered row, 1/z = 1 − 0.5·0.505.
        assert!((z[10 * 100 + 50] - (1.0 - 0.5 * 0.505)).abs() < 1e-6, "{}", z[10 * 100 + 50]);
    }

    #[test]
    fn clipping_at_the_near_plane() {
        let p = Projector::new(100, 100, 90f64.to_radians(), 0.1);
        // One vertex behind the eye.
        let tri = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 0.5, -1.0]];
        assert_eq!(p.classify(&tri), Class::Clip);
        let poly = clip(&p, &tri);
        // The near plane cuts off one corner (4 vertices); the guard band, narrow that close to
        // the eye, cuts one more.
        assert_eq!(poly.len, 5);
        assert!(poly.v[..poly.len].iter().all(|q| q[2] >= 0.1));
        assert_eq!(
            clip(
                &Projector::new(100, 100, 90f64.to_radians(), 0.9),
                &[[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.05, -1.0]]
            )
            .len,
            4
        );
        // Entirely behind.
        let back = [[0.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 1.0, -2.0]];
        assert_eq!(p.classify(&back), Class::Outside);
        // Through the eye itself.
        let eye = [[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]];
        let poly = clip(&p, &eye);
        assert!(poly.len >= 3);
        assert!(poly.v[..poly.len].iter().all(|q| q[2] >= 0.1 && q.iter().all(|v| v.is_finite())));
    }

    #[test]
    fn clipping_to_the_guard_band_bounds_coordinates() {
        let p = Projector::new(100, 100, 90f64.to_radians(), 0.01);
        // Huge triangle in front of the camera.
        let tri = [[-1e6, -1e6, 1.0], [1e6, -1e6, 1.0], [0.0, 1e6, 1.0]];
        assert_eq!(p.classify(&tri), Class::Clip);
        let poly = clip(&p, &tri);
        assert!(poly.len >= 3);
        for q in &poly.v[..poly.len] {
            let s = p.project(*q);
            assert!(s.x.abs() <= 50.0 + 50.0 * GUARD + 1e-6 && s.y.abs() <= 50.0 + 50.0 * GUARD + 1e-6);
        }
        // Left of the frustum entirely.
        let left = [[-10.0, 0.0, 1.0], [-20.0, 1.0, 1.0], [-10.0, 2.0, 2.0]];
        assert_eq!(p.classify(&left), Class::Outside);
    }
}
