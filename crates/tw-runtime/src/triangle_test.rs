//! Per-triangle occlusion tests of visible clusters against a hierarchical Z-buffer: which
//! triangles of a cluster that passed the cluster test ([`crate::occlusion::test_clusters`]) can
//! still show a pixel. The finer half of GigaWalk's HZB culling (Baxter et al. 2002 §4.2 tests
//! objects; the triangle level is what GPU-driven renderers add, e.g. Wihlidal 2016, "Optimizing
//! the graphics pipeline with compute"): a cluster is drawn whole once any part of its box is
//! visible, and on the plant about two thirds of such a cluster's triangles are hidden behind
//! nearer geometry, face away behind their own object's front, or cover no pixel centre
//! (docs/benchmarks-log.md, "Triangle-level HZB culling").
//!
//! A triangle whose corners all lie in front of the near plane is tested as the rasterizer
//! will draw it, in up to three steps, each run only when the one before found it visible:
//! 1. its screen rectangle, widened by the corners' rounding bound ([`PROJECTION_ROUNDING`]),
//!    is reduced to the pixel centres it holds, and those go through [`Hzb::test_pixels`] at
//!    the nearest corner's depth: most hidden triangles end here;
//! 2. a small triangle (at most [`SAMPLE_TEST_MAX_PIXELS`] centres) is then tested centre by
//!    centre: only the centres inside it count, each against its own occluder depth and with
//!    the depth the triangle has there, from its depth plane (reverse-Z depth is affine in
//!    screen space over a triangle), at most its nearest corner's;
//! 3. a larger one is kept when the pixel under its centroid shows it (a triangle drawn in the
//!    first pass finds its own depth there), and when it is a sliver (its rectangle mostly
//!    outside it); otherwise the pyramid is walked down over its rectangle
//!    ([`Hzb::test_pixels_by`]): a texel is passed over when the triangle cannot cover any of
//!    its pixel centres (its edge functions at the region's corners) or when its farthest
//!    occluder depth is nearer than the triangle's depth plane can be there, down to single
//!    centres, tested as in step 2. A walk that needs more than [`WALK_BUDGET`] texels keeps
//!    the triangle.
//!
//! "Inside" and the depth are widened by what the rasterizer's triangle can differ from the
//! one computed here: its sub-pixel snapping ([`SAMPLE_SLACK_PX`]) and the f32 rounding of the
//! two projections, per corner, in position and in depth, plus the depth buffer's own rounding
//! (GL's depth-range mapping, `tw_gpu::GL_DEPTH_ROUNDING`). A centre on or near an edge thus
//! counts whatever the fill rule, and the depth is at least the rasterizer's: it interpolates
//! its corners' depths at a point within that distance of a point of this triangle.
//!
//! A triangle with a corner at or before the near plane, or behind the eye, is clipped by the
//! rasterizer. It is dropped when all three corners lie outside one plane of the view volume
//! (the homogeneous clip-space test, with the rounding bound as margin): wholly behind the eye,
//! before the near plane, beyond the far one, or beside the view. Otherwise it is kept: the
//! part left after clipping reaches the near plane, where it is nearer than any occluder. In
//! the 10^8-triangle plant's interior walk such triangles were half of those drawn, and the
//! plane test drops four in five of them.
//!
//! So a triangle is dropped only when every pixel centre it could cover holds nearer geometry,
//! or when it covers none: drawing the kept triangles gives the image of drawing the whole
//! cluster. Positions are computed exactly as the renderer's pool computes them (grid
//! coordinates × step, rounded to f32). A non-finite corner keeps its triangle.
//!
//! The result is a [`TriangleMask`]: bit `t` for triangle `t` of the cluster (clusters hold at
//! most 128 triangles, docs/FORMAT.md).

use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;
use tw_store::PageCluster;

use crate::hzb::{Hzb, HzbResult};

/// How far (pixels) the rasterizer's triangle corners may lie from the ones computed here
/// because of its sub-pixel snapping: at most 1/512 px at the 1/256 px precision of lavapipe,
/// llvmpipe and every GPU, with a margin of 2. The f32 rounding of the two projections (the
/// shader's and this module's) comes on top, per vertex ([`PROJECTION_ROUNDING`]).
pub const SAMPLE_SLACK_PX: f64 = 1.0 / 256.0;

/// Relative rounding allowed between two f32 evaluations of a vertex's clip coordinates (this
/// module's and the vertex shader's, whose order of operations and fused multiply-adds may
/// differ): 4 ulps of the sum of the magnitudes of the terms, Σ |m_ij p_j|. Scene coordinates
/// are absolute, so near the eye and far from the scene origin a small triangle's corners can
/// move by a good fraction of a pixel between the two.
pub const PROJECTION_ROUNDING: f32 = 4.0 * f32::EPSILON;

/// One bit per triangle of a cluster (bit `t` = triangle `t`).
pub type TriangleMask = u128;

/// Every triangle of a cluster of `triangles` triangles (≤ 128).
pub fn full_mask(triangles: usize) -> TriangleMask {
    if triangles >= 128 {
        u128::MAX
    } else {
        (1u128 << triangles) - 1
    }
}

/// A vertex seen through the view-projection: its clip coordinates, the bound on their
/// rounding (clip units, [`PROJECTION_ROUNDING`] of the terms' magnitudes), and its screen
/// projection where it lies in front of the near plane.
#[derive(Clone, Copy, Debug)]
struct Vertex {
    clip: Vec4,
    clip_rounding: Vec4,
    screen: Option<Projected>,
}

/// A vertex on the screen: pixels (x right, y down), reverse-Z depth, and the bounds on the
/// rounding of both between this f32 evaluation and the vertex shader's.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Projected {
    x: f32,
    y: f32,
    depth: f32,
    /// Pixels, the larger of x and y.
    rounding: f32,
    depth_rounding: f32,
}

/// The triangles of `cluster` that may show a pixel over `hzb`, seen through `view_proj` (the
/// reverse-Z view-projection the depth was drawn with); `depth_rounding` is the absolute
/// rounding of the depths the renderer writes (`tw_gpu::Renderer::depth_rounding`: a few
/// ulps of 1.0 on GL, 0 on Vulkan). A malformed triangle (an index beyond the vertices) is
/// reported visible; triangles beyond the 128th (the format allows none) have no bit.
pub fn visible_triangles(
    cluster: &PageCluster,
    grid_step: f64,
    hzb: &Hzb,
    view_proj: &Mat4,
    depth_rounding: f64,
) -> TriangleMask {
    visible_triangles_assuming(cluster, grid_step, hzb, view_proj, depth_rounding, 0)
}

/// [`visible_triangles`], with the triangles of `assumed` reported visible without a test.
/// Reporting a hidden triangle visible is always safe (it is drawn for nothing); the caller uses
/// this for triangles it already drew, whose test would change nothing in the image.
pub fn visible_triangles_assuming(
    cluster: &PageCluster,
    grid_step: f64,
    hzb: &Hzb,
    view_proj: &Mat4,
    depth_rounding: f64,
    assumed: TriangleMask,
) -> TriangleMask {
    let all = full_mask(cluster.indices.len() / 3);
    if assumed & all == all {
        return all;
    }
    let (w, h) = hzb.size();
    let abs_view_proj = Mat4::from_cols_array(&view_proj.to_cols_array().map(f32::abs));
    let vertices: Vec<Vertex> = cluster
        .positions
        .iter()
        .map(|g| {
            let p = Vec3::from(g.map(|c| (c as f64 * grid_step) as f32));
            vertex(view_proj, &abs_view_proj, p, (w, h))
        })
        .collect();
    let mut mask: TriangleMask = assumed & all;
    for (t, tri) in cluster.indices.chunks_exact(3).enumerate().take(128) {
        if assumed >> t & 1 == 1 {
            continue;
        }
        let visible = match [tri[0], tri[1], tri[2]].map(|i| vertices.get(i as usize)) {
            [Some(a), Some(b), Some(c)] => match [a.screen, b.screen, c.screen] {
                [Some(a), Some(b), Some(c)] => projected_shows(hzb, [a, b, c], depth_rounding),
                _ => !outside_one_plane([a, b, c]),
            },
            _ => true,
        };
        if visible {
            mask |= 1u128 << t;
        }
    }
    mask
}

/// `p` through `view_proj` on a `size` image; `abs_view_proj` holds the magnitudes of
/// `view_proj`'s elements. The screen projection is `None` behind the eye, at or before the
/// near plane, or where the clip coordinates are not finite.
fn vertex(view_proj: &Mat4, abs_view_proj: &Mat4, p: Vec3, (w, h): (u32, u32)) -> Vertex {
    let c: Vec4 = *view_proj * p.extend(1.0);
    // x/w moves by (δx + |x/w|·δw)/w, with |δx| ≤ rounding × Σ |m_0j p_j|, the same for y, z, w.
    let magnitude = *abs_view_proj * p.abs().extend(1.0);
    let clip_rounding = magnitude * PROJECTION_ROUNDING;
    let screen = (c.is_finite() && c.w > 0.0 && c.z / c.w < 1.0).then(|| {
        let (x, y, depth) = (c.x / c.w, c.y / c.w, c.z / c.w);
        let error = |ndc: f32, of_axis: f32| (of_axis + ndc.abs() * clip_rounding.w) / c.w;
        Projected {
            x: (x * 0.5 + 0.5) * w as f32,
            y: (0.5 - y * 0.5) * h as f32,
            depth,
            rounding: (0.5 * w as f32 * error(x, clip_rounding.x))
                .max(0.5 * h as f32 * error(y, clip_rounding.y)),
            depth_rounding: error(depth, clip_rounding.z),
        }
    });
    Vertex { clip: c, clip_rounding, screen }
}

/// Whether the triangle of `corners` lies wholly outside one plane of the view volume
/// (reverse-Z: −w ≤ x, y ≤ w and 0 ≤ z ≤ w): every corner beyond it by more than the rounding
/// of its plane distance. The rasterizer then draws none of it, whatever it clips. Corners
/// that are not finite decide nothing.
fn outside_one_plane(corners: [&Vertex; 3]) -> bool {
    if !corners.iter().all(|v| v.clip.is_finite()) {
        return false;
    }
    // Plane distance (≥ 0 inside) and its rounding bound, for one corner.
    type Plane = fn(&Vertex) -> (f32, f32);
    let planes: [Plane; 6] = [
        |v| (v.clip.w + v.clip.x, v.clip_rounding.w + v.clip_rounding.x),
        |v| (v.clip.w - v.clip.x, v.clip_rounding.w + v.clip_rounding.x),
        |v| (v.clip.w + v.clip.y, v.clip_rounding.w + v.clip_rounding.y),
        |v| (v.clip.w - v.clip.y, v.clip_rounding.w + v.clip_rounding.y),
        |v| (v.clip.w - v.clip.z, v.clip_rounding.w + v.clip_rounding.z),
        |v| (v.clip.z, v.clip_rounding.z),
    ];
    planes.iter().any(|plane| {
        corners.iter().all(|v| {
            let (distance, rounding) = plane(v);
            // Twice the bound: this module's own subtraction rounds too.
            distance < -2.0 * rounding
        })
    })
}

/// Whether a triangle with all corners in front of the near plane can show a pixel;
/// `depth_rounding`: the depth buffer's absolute rounding.
fn projected_shows(hzb: &Hzb, [a, b, c]: [Projected; 3], depth_rounding: f64) -> bool {
    // The rectangle, widened by the corners' rounding bound (the rectangle tests widen it by
    // the snapping allowance themselves).
    let rounding = a.rounding.max(b.rounding).max(c.rounding);
    let (x_lo, x_hi) = (a.x.min(b.x).min(c.x) - rounding, a.x.max(b.x).max(c.x) + rounding);
    let (y_lo, y_hi) = (a.y.min(b.y).min(c.y) - rounding, a.y.max(b.y).max(c.y) + rounding);
    if !(x_lo.is_finite() && x_hi.is_finite() && y_lo.is_finite() && y_hi.is_finite()) {
        return true;
    }
    let Some(rect) = hzb.pixel_rect(x_lo, y_lo, x_hi, y_hi) else {
        return false;
    };
    // Most hidden triangles are hidden at their nearest corner's depth already, which the
    // pyramid tells at once; the triangle's edges and depth plane are for the others.
    let depth_rounding = a.depth_rounding.max(b.depth_rounding).max(c.depth_rounding) as f64 + depth_rounding;
    let nearest = round_up(a.depth.max(b.depth).max(c.depth) as f64 + depth_rounding);
    if hzb.test_pixels(rect, nearest) != HzbResult::Visible {
        return false;
    }
    let triangle =
        ScreenTriangle::new([a, b, c], SAMPLE_SLACK_PX + rounding as f64, depth_rounding, hzb.samples());
    let [x0, y0, x1, y1] = rect;
    if pixel_count(rect) <= SAMPLE_TEST_MAX_PIXELS as u64 {
        return triangle.shows_at_a_centre(hzb, rect);
    }
    // A triangle drawn in the first pass finds its own depth in the buffer: most visible large
    // triangles show at the pixel under their centroid, which settles them at once.
    let (cx, cy) = ((a.x + b.x + c.x) / 3.0, (a.y + b.y + c.y) / 3.0);
    if cx >= x0 as f32 && cy >= y0 as f32 && cx < (x1 + 1) as f32 && cy < (y1 + 1) as f32 {
        let (px, py) = (cx as u32, cy as u32);
        if triangle.bound_f64([px, py, px, py]).is_some_and(|b| hzb.pixel_shows(px, py, b)) {
            return true;
        }
    }
    // A sliver's rectangle is mostly outside it, and the walk down the pyramid would follow it
    // texel by texel: it keeps the rectangle's answer. Other triangles are walked, within
    // WALK_BUDGET bounds; beyond it every texel is taken as unsettled, which ends the walk at
    // the next pixel with "visible".
    if triangle.area < SLIVER_FILL * pixel_count(rect) as f64 {
        return true;
    }
    let calls = std::cell::Cell::new(0u32);
    let bound = |region: [u32; 4]| {
        calls.set(calls.get() + 1);
        if calls.get() > WALK_BUDGET {
            Some(f32::INFINITY)
        } else {
            triangle.bound(region)
        }
    };
    hzb.test_pixels_by(rect, nearest, bound) == HzbResult::Visible
}

/// Triangles whose rectangle holds at most this many pixel centres are tested centre by centre
/// (after the rectangle test called them visible); larger ones are walked down the pyramid.
pub const SAMPLE_TEST_MAX_PIXELS: u32 = 64;

/// A large triangle covering less than this share of its rectangle (twice its area against the
/// rectangle's pixels: a sliver) keeps the rectangle test's answer.
const SLIVER_FILL: f64 = 0.5;

/// The most texel bounds a large triangle's walk down the pyramid computes before it gives up
/// and keeps the triangle.
pub const WALK_BUDGET: u32 = 48;

fn pixel_count([x0, y0, x1, y1]: [u32; 4]) -> u64 {
    (x1 - x0 + 1) as u64 * (y1 - y0 + 1) as u64
}

/// A projected triangle as [`Hzb::test_pixels_by`] sees it: which pixel centres it may cover
/// and how near it may be there, allowing for the rasterizer's corners lying up to `slack`
/// pixels from these and its corner depths differing by up to their rounding bounds.
struct ScreenTriangle {
    corners: [[f64; 2]; 3],
    /// Edge `i` from corner `i` to corner `i + 1`: (a, b, c) with a·x + b·y + c ≥ 0 inside.
    edges: [(f64, f64, f64); 3],
    /// How much the edge functions can drop for a moved corner within `slack` pixels (see
    /// [`ScreenTriangle::counts_centre`]).
    slack: f64,
    wide: f64,
    /// The nearest corner depth, plus the corners' depth rounding.
    nearest: f64,
    /// Depth at (x, y): a·x + b·y + c, plus `error` (the gradient over `slack` and the depth
    /// rounding); `None` for a degenerate triangle (its nearest corner decides).
    plane: Option<(f64, f64, f64, f64)>,
    /// Twice the area (square pixels).
    area: f64,
    /// A pixel's sample positions from its top-left corner ([`Hzb::samples`]) and their
    /// bounding box (x, y lowest; x, y highest).
    samples: Vec<[f64; 2]>,
    sample_box: [f64; 4],
}

impl ScreenTriangle {
    /// `depth_rounding`: the corners' largest, with the depth buffer's absolute rounding.
    fn new(corners: [Projected; 3], slack: f64, depth_rounding: f64, samples: &[[f32; 2]]) -> ScreenTriangle {
        let v = corners.map(|c| [c.x as f64, c.y as f64]);
        let d = corners.map(|c| c.depth as f64);
        let (e1, e2) = ([v[1][0] - v[0][0], v[1][1] - v[0][1]], [v[2][0] - v[0][0], v[2][1] - v[0][1]]);
        let area = e1[0] * e2[1] - e1[1] * e2[0];
        let sign = if area < 0.0 { -1.0 } else { 1.0 };
        // Edge i from u to w: sign·cross(w − u, p − u) = a·p.x + b·p.y + c, ≥ 0 inside.
        let edges = [0, 1, 2].map(|i| {
            let (u, w) = (v[i], v[(i + 1) % 3]);
            let (a, b) = (-sign * (w[1] - u[1]), sign * (w[0] - u[0]));
            (a, b, -a * u[0] - b * u[1])
        });
        let length2 = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
        let longest = length2(v[0], v[1]).max(length2(v[1], v[2])).max(length2(v[2], v[0])).sqrt();
        // Depth plane: d(p) = d0 + a·(x − x0) + b·(y − y0) through the three corners. Below a
        // thousandth of a square pixel the triangle has no plane worth the name.
        let plane = (area.abs() > 1e-3).then(|| {
            let (d1, d2) = (d[1] - d[0], d[2] - d[0]);
            let a = (d1 * e2[1] - d2 * e1[1]) / area;
            let b = (e1[0] * d2 - e2[0] * d1) / area;
            let error = (a * a + b * b).sqrt() * slack + depth_rounding;
            (a, b, d[0] - a * v[0][0] - b * v[0][1], error)
        });
        ScreenTriangle {
            corners: v,
            edges,
            slack,
            wide: 2.0 * slack * longest + 8.0 * slack * slack,
            nearest: d[0].max(d[1]).max(d[2]) + depth_rounding,
            plane: plane.filter(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite()),
            area: area.abs(),
            sample_box: samples.iter().fold(
                [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY],
                |b, p| {
                    [
                        b[0].min(p[0] as f64),
                        b[1].min(p[1] as f64),
                        b[2].max(p[0] as f64),
                        b[3].max(p[1] as f64),
                    ]
                },
            ),
            samples: samples.iter().map(|p| [p[0] as f64, p[1] as f64]).collect(),
        }
    }

    /// The nearest depth the triangle can have at a pixel centre (a sample position, with
    /// multisampling) of `region` (inclusive pixel bounds) that it may cover, or `None` when it
    /// can cover none of them. For one pixel its samples are tested exactly; for more, each
    /// edge's function at the corners of the region's samples.
    fn bound(&self, region: [u32; 4]) -> Option<f32> {
        self.bound_f64(region).map(round_up)
    }

    /// [`bound`](Self::bound) in f64.
    fn bound_f64(&self, [x0, y0, x1, y1]: [u32; 4]) -> Option<f64> {
        if x0 == x1 && y0 == y1 {
            // Each sample the triangle may cover, at the depth it has there.
            let (x, y) = (x0 as f64, y0 as f64);
            return self
                .samples
                .iter()
                .map(|s| [x + s[0], y + s[1]])
                .filter(|&p| self.counts_centre(p))
                .map(|p| match self.plane {
                    Some((a, b, c, error)) => (c + a * p[0] + b * p[1] + error).min(self.nearest),
                    None => self.nearest,
                })
                .reduce(f64::max);
        }
        let [sx0, sy0, sx1, sy1] = self.sample_box;
        let (cx0, cy0, cx1, cy1) = (x0 as f64 + sx0, y0 as f64 + sy0, x1 as f64 + sx1, y1 as f64 + sy1);
        if self
            .edges
            .iter()
            .any(|&(a, b, c)| c + (a * cx0).max(a * cx1) + (b * cy0).max(b * cy1) < -self.wide)
        {
            return None;
        }
        Some(match self.plane {
            Some((a, b, c, error)) => {
                (c + (a * cx0).max(a * cx1) + (b * cy0).max(b * cy1) + error).min(self.nearest)
            }
            None => self.nearest,
        })
    }

    /// Whether a pixel centre (a sample position, with multisampling) of `rect` (inclusive
    /// pixel bounds) inside the triangle holds an occluder depth the triangle's depth there can
    /// pass: [`bound`](Self::bound) of each pixel, with the edge functions and the depth plane
    /// stepped along each row, for each sample position.
    fn shows_at_a_centre(&self, hzb: &Hzb, [x0, y0, x1, y1]: [u32; 4]) -> bool {
        let (pa, pb, pc, error) = self.plane.unwrap_or((0.0, 0.0, f64::INFINITY, 0.0));
        (y0..=y1).any(|y| {
            self.samples
                .iter()
                .any(|&[sx, sy]| self.shows_in_row(hzb, [x0, x1], y, [sx, sy], (pa, pb, pc, error)))
        })
    }

    /// [`shows_at_a_centre`](Self::shows_at_a_centre) of the samples at (`sx`, `sy`) of the
    /// pixels `x0..=x1` of row `y`.
    fn shows_in_row(
        &self,
        hzb: &Hzb,
        [x0, x1]: [u32; 2],
        y: u32,
        [sx, sy]: [f64; 2],
        (pa, pb, pc, error): (f64, f64, f64, f64),
    ) -> bool {
        let cx0 = x0 as f64 + sx;
        let py = y as f64 + sy;
        let mut e = self.edges.map(|(a, b, c)| a * cx0 + b * py + c);
        let mut depth = pa * cx0 + pb * py + pc + error;
        (x0..=x1).any(|x| {
            let p = [x as f64 + sx, py];
            let shows = self.inside(e, p) && hzb.pixel_shows(x, y, depth.min(self.nearest));
            for (ei, edge) in e.iter_mut().zip(&self.edges) {
                *ei += edge.0;
            }
            depth += pa;
            shows
        })
    }

    /// Whether the centre `p` lies inside the triangle with corners moved by up to `slack`
    /// pixels. Moving an edge's ends u, w by up to s changes its edge function at p by at most
    /// s·(|p − u| + |p − w|) + 2s². A centre the rasterizer's (moved) triangle covers lies
    /// inside it, so both distances are at most its longest edge + 3s: that bound (`wide`)
    /// decides at once for most centres, the exact distances for the few in between.
    fn counts_centre(&self, p: [f64; 2]) -> bool {
        self.inside(self.edges.map(|(a, b, c)| a * p[0] + b * p[1] + c), p)
    }

    /// [`counts_centre`](Self::counts_centre) of `p` with its edge functions `e` given.
    fn inside(&self, e: [f64; 3], p: [f64; 2]) -> bool {
        (0..3).all(|i| e[i] >= 0.0 || (e[i] >= -self.wide && self.near_edge(i, e[i], p)))
    }

    /// Whether edge `i`'s function `e` at `p`, below 0, is within what moving the edge's ends
    /// by `slack` can change it by.
    fn near_edge(&self, i: usize, e: f64, p: [f64; 2]) -> bool {
        let s = self.slack;
        let distance = |q: [f64; 2]| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
        let (u, w) = (self.corners[i], self.corners[(i + 1) % 3]);
        e >= -(s * (distance(u) + distance(w)) + 2.0 * s * s)
    }
}

/// `depth` in f32, rounded up (so a bound stays a bound).
fn round_up(depth: f64) -> f32 {
    let bound = depth as f32;
    if (bound as f64) < depth {
        bound.next_up()
    } else {
        bound
    }
}

/// [`visible_triangles`] of many clusters, in parallel; the output keeps the input order. With
/// `assumed` (one mask per cluster), [`visible_triangles_assuming`].
pub fn test_triangles(
    clusters: &[&PageCluster],
    assumed: Option<&[TriangleMask]>,
    grid_step: f64,
    hzb: &Hzb,
    view_proj: &Mat4,
    depth_rounding: f64,
) -> Vec<TriangleMask> {
    clusters
        .par_iter()
        .enumerate()
        .with_min_len(16)
        .map(|(i, c)| {
            let assumed = assumed.and_then(|a| a.get(i)).copied().unwrap_or(0);
            visible_triangles_assuming(c, grid_step, hzb, view_proj, depth_rounding, assumed)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    /// 64×48 view down +X from the origin; a wall at x = 10 covers the left half of the image.
    #[test]
    fn multisampled_pixels_count_their_samples() {
        use crate::hzb::SAMPLES_4X;
        let (one, _) = scene();
        let four = one.clone().with_samples(&SAMPLES_4X);
        let shows = |hzb: &Hzb, c: [[f32; 2]; 3], depth: f32| {
            projected_shows(
                hzb,
                c.map(|[x, y]| Projected { x, y, depth, rounding: 0.0, depth_rounding: 0.0 }),
                0.0,
            )
        };
        let far = one.pixel_depth(0, 0) * 0.5;
        // Around the sample (50.375, 20.125) of the open pixel (50, 20), away from its centre.
        let at_sample = [[50.3, 20.05], [50.45, 20.05], [50.3, 20.2]];
        assert!(!shows(&one, at_sample, far), "covers no pixel centre");
        assert!(shows(&four, at_sample, far), "covers a sample");
        // Between the samples of pixel (50, 20): none with 4 samples either.
        let between = [[50.05, 20.3], [50.2, 20.3], [50.05, 20.45]];
        assert!(!shows(&four, between, far));
        // A large triangle over open pixels, its samples only: the walk (step 3) keeps it.
        let big = [[36.0, 2.0], [60.0, 2.0], [36.0, 40.0]];
        assert!(shows(&four, big, far));
        // Behind the wall it is hidden at every sample.
        let hidden = [[2.0, 2.0], [28.0, 2.0], [2.0, 40.0]];
        assert!(!shows(&four, hidden, far));
        // The rectangle of pixels a sample of which may lie in a thin rectangle: with 4
        // samples it reaches the pixels whose outer samples it touches.
        assert_eq!(one.pixel_rect(40.6, 10.6, 40.9, 10.9), None);
        assert_eq!(four.pixel_rect(40.6, 10.6, 40.9, 10.9), Some([40, 10, 40, 10]));
        assert_eq!(four.test_rect(40.6, 10.6, 40.9, 10.9, far), HzbResult::Visible);
    }

    fn scene() -> (Hzb, Mat4) {
        let (w, h) = (64u32, 48u32);
        let cam = Camera::new(Vec3::ZERO, Vec3::X, Vec3::Z, 60f32.to_radians(), 0.1, 1000.0).unwrap();
        let vp = cam.projection_reverse_z(w as f32 / h as f32) * cam.view();
        let p = vp * Vec4::new(10.0, 0.0, 0.0, 1.0);
        let wall = p.z / p.w;
        let depth: Vec<f32> = (0..w * h).map(|i| if i % w < w / 2 { wall } else { 0.0 }).collect();
        (Hzb::build(&depth, w, h).unwrap(), vp)
    }

    /// A cluster of one triangle per corner triple, on a grid of step 1/16 (exact in f32).
    fn cluster(triangles: &[[[f32; 3]; 3]]) -> PageCluster {
        let mut c = PageCluster::default();
        for t in triangles {
            for p in t {
                c.indices.push(c.positions.len() as u8);
                // Scene = grid × step with the grid offset by 1024 so that negative scene
                // coordinates are representable; the camera below is shifted to match.
                c.positions.push(p.map(|v| ((v + 1024.0) * 16.0) as u32));
            }
        }
        c.objects = vec![0; triangles.len()];
        c
    }

    fn shifted(vp: Mat4) -> Mat4 {
        vp * Mat4::from_translation(Vec3::splat(-1024.0))
    }

    #[test]
    fn hidden_visible_near_and_subpixel_triangles() {
        let (hzb, vp) = scene();
        let vp = shifted(vp);
        let c = cluster(&[
            // 0: behind the wall, left half: hidden.
            [[20.0, 2.0, -0.5], [20.0, 3.0, -0.5], [20.0, 2.5, 0.5]],
            // 1: right half, open: visible.
            [[20.0, -3.0, -0.5], [20.0, -2.0, -0.5], [20.0, -2.5, 0.5]],
            // 2: in front of the wall, left half: visible.
            [[5.0, 1.0, -0.5], [5.0, 2.0, -0.5], [5.0, 1.5, 0.5]],
            // 3: a corner behind the eye: kept.
            [[-1.0, 2.0, 0.0], [20.0, 2.0, 0.0], [20.0, 3.0, 0.0]],
            // 4: far away in the open half and tiny, between pixel centres: covers no pixel centre,
            // dropped.
            [[500.0, -0.3, 0.3], [500.0, -0.3625, 0.3], [500.0, -0.3, 0.3625]],
        ]);
        let m = visible_triangles(&c, 1.0 / 16.0, &hzb, &vp, 0.0);
        assert_eq!(m, 0b01110, "mask {m:#b}");
        assert_eq!(test_triangles(&[&c, &c], None, 1.0 / 16.0, &hzb, &vp, 0.0), vec![m, m]);
        // Assumed triangles are reported visible untested; the others are tested as before.
        let assumed = [0b00001, 0b11111, 0b10000];
        assert_eq!(
            test_triangles(&[&c, &c, &c], Some(&assumed), 1.0 / 16.0, &hzb, &vp, 0.0),
            vec![m | 0b00001, 0b11111, m | 0b10000]
        );
    }

    /// The sample test on screen-space corners against the wall scene (pixels x < 32 hold the
    /// wall, the others the far background).
    #[test]
    fn only_covered_pixel_centres_count() {
        let (hzb, _) = scene();
        let wall = hzb.pixel_depth(0, 0);
        assert!(wall > 0.0 && hzb.pixel_depth(40, 10) == 0.0);
        let test = |c: [[f32; 2]; 3], depth: f32| {
            let (x_lo, x_hi) = (c[0][0].min(c[1][0]).min(c[2][0]), c[0][0].max(c[1][0]).max(c[2][0]));
            let (y_lo, y_hi) = (c[0][1].min(c[1][1]).min(c[2][1]), c[0][1].max(c[1][1]).max(c[2][1]));
            let rect = hzb.pixel_rect(x_lo, y_lo, x_hi, y_hi).expect("the rectangle holds pixel centres");
            assert_eq!(
                hzb.test_rect(x_lo, y_lo, x_hi, y_hi, depth),
                HzbResult::Visible,
                "rectangle test of {c:?}"
            );
            assert!(hzb.test_pixels(rect, depth) == HzbResult::Visible);
            projected_shows(
                &hzb,
                c.map(|[x, y]| Projected { x, y, depth, rounding: 0.0, depth_rounding: 0.0 }),
                0.0,
            )
        };
        let near = wall * 2.0;
        let far = wall * 0.5;
        // A sliver along the diagonal between the centres (x + ½, y + ½): its rectangle holds
        // 12 open centres, the sliver none.
        assert!(!test([[40.0, 10.5], [43.0, 13.5], [43.0, 13.6]], far));
        // A small triangle over the open centre (50.5, 20.5), in either winding.
        assert!(test([[50.0, 20.0], [51.2, 20.0], [50.0, 21.2]], far));
        assert!(test([[50.0, 20.0], [50.0, 21.2], [51.2, 20.0]], far));
        // A centre exactly on a corner, and one exactly on an edge, count as covered.
        assert!(test([[50.5, 20.5], [52.0, 20.5], [50.5, 22.0]], far));
        assert!(test([[50.0, 20.5], [51.0, 20.5], [50.5, 19.6]], far));
        // A degenerate triangle through an open centre keeps it.
        assert!(test([[49.5, 19.5], [51.5, 21.5], [50.5, 20.5]], far));
        // Straddling the wall's edge: the rectangle reaches the open centre x = 32.5, the
        // triangle covers only wall centres: hidden behind the wall, kept in front of it.
        let straddle = [[29.9, 5.0], [32.6, 5.0], [29.9, 7.7]];
        assert!(!test(straddle, far));
        assert!(test(straddle, near));
    }

    /// The rounding bound covers this module's own f32 error against an exact (f64)
    /// projection twice over (the vertex shader's error is the other half), near the eye and
    /// thousands of units from the origin, where it reaches a good part of a pixel.
    #[test]
    fn projection_rounding_bounds_the_f32_error() {
        let mut rng = tw_core::rng::Rng::new(7);
        let mut largest = 0f32;
        for _ in 0..2000 {
            let r = |rng: &mut tw_core::rng::Rng, s: f32| (rng.f64() as f32 * 2.0 - 1.0) * s;
            let eye = Vec3::new(r(&mut rng, 4096.0), r(&mut rng, 4096.0), r(&mut rng, 100.0));
            let dir = Vec3::new(r(&mut rng, 1.0), r(&mut rng, 1.0), r(&mut rng, 0.3)).normalize_or(Vec3::X);
            let cam = Camera::new(eye, eye + dir, Vec3::Z, 60f32.to_radians(), 0.1, 1e5).unwrap();
            let vp = cam.projection_reverse_z(1280.0 / 720.0) * cam.view();
            let abs = Mat4::from_cols_array(&vp.to_cols_array().map(f32::abs));
            let distance = 0.5 + rng.f64() as f32 * 50.0;
            let p = eye
                + dir * distance
                + Vec3::new(r(&mut rng, 0.4), r(&mut rng, 0.4), r(&mut rng, 0.4)) * distance;
            let Some(v) = vertex(&vp, &abs, p, (1280, 720)).screen else { continue };
            let exact = vp.as_dmat4() * p.as_dvec3().extend(1.0);
            let (ex, ey) =
                ((exact.x / exact.w * 0.5 + 0.5) * 1280.0, (0.5 - exact.y / exact.w * 0.5) * 720.0);
            let error = ((v.x as f64 - ex).abs()).max((v.y as f64 - ey).abs()) as f32;
            assert!(
                error <= v.rounding / 2.0 + 1e-4,
                "error {error} px, bound {} px at {p} from {eye}",
                v.rounding
            );
            let depth_error = (v.depth as f64 - exact.z / exact.w).abs() as f32;
            assert!(
                depth_error <= v.depth_rounding / 2.0 + 1e-9,
                "depth error {depth_error}, bound {} at {p} from {eye}",
                v.depth_rounding
            );
            largest = largest.max(v.rounding);
        }
        assert!(largest > 0.05, "the bound should matter here: at most {largest} px");
    }

    /// A floor-like triangle reaching from below the view, in front of the wall, to behind
    /// it: every pixel it shows on screen is behind the wall there, though its nearest corner
    /// is in front of it. The depth plane culls it; its nearest corner alone would not. In the
    /// open half it shows.
    #[test]
    fn the_depth_plane_decides_where_the_nearest_corner_would_not() {
        let (hzb, vp) = scene();
        let vp = shifted(vp);
        // Left half (y > 0), under the wall's pixels; the near corner (x = 5) is below the view.
        let hidden = [[5.0, 1.0, -20.0], [30.0, 1.0, -1.0], [30.0, 3.0, -1.0]];
        let open = hidden.map(|[x, y, z]| [x, -y, z]);
        let m = visible_triangles(&cluster(&[hidden, open]), 1.0 / 16.0, &hzb, &vp, 0.0);
        assert_eq!(m, 0b10, "mask {m:#b}");
        // The nearest corner is in front of the wall: a rectangle test with it passes.
        let abs = Mat4::from_cols_array(&vp.to_cols_array().map(f32::abs));
        let near = vertex(&vp, &abs, Vec3::new(5.0, 1.0, -20.0) + 1024.0, hzb.size()).screen.unwrap();
        assert!(near.depth > hzb.pixel_depth(0, 0));
    }

    /// Triangles reaching behind the eye: kept when part of them lies in the view in front of
    /// the wall, dropped when they lie wholly behind the eye or wholly beside the view.
    #[test]
    fn triangles_crossing_the_near_plane_are_tested_against_the_view_volume() {
        let (hzb, vp) = scene();
        let vp = shifted(vp);
        let c = cluster(&[
            // 0: from behind the eye to the open half ahead: kept.
            [[-1.0, 0.0, -0.5], [5.0, -0.5, -0.5], [5.0, 0.5, -0.5]],
            // 1: wholly behind the eye: dropped.
            [[-1.0, 0.0, 0.0], [-2.0, 1.0, 0.0], [-2.0, -1.0, 0.0]],
            // 2: from behind the eye to ahead, all of it left of the view: dropped.
            [[-1.0, 5.0, 0.0], [1.0, 5.0, 0.0], [1.0, 6.0, 0.0]],
            // 3: the same on the right: dropped.
            [[-1.0, -5.0, 0.0], [1.0, -5.0, 0.0], [1.0, -6.0, 0.0]],
            // 4: from behind the eye to above the view: dropped.
            [[-1.0, 0.0, 3.0], [1.0, 0.0, 3.0], [1.0, 1.0, 4.0]],
            // 5: between the eye and the near plane (0.1 ahead): dropped.
            [[0.05, 0.0, 0.0], [0.05, 0.01, 0.0], [0.05, 0.0, 0.01]],
        ]);
        let m = visible_triangles(&c, 1.0 / 16.0, &hzb, &vp, 0.0);
        assert_eq!(m, 0b1, "mask {m:#b}");
    }

    #[test]
    fn full_masks() {
        assert_eq!(full_mask(0), 0);
        assert_eq!(full_mask(3), 0b111);
        assert_eq!(full_mask(128), u128::MAX);
    }
}
