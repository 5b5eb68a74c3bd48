//! Per-triangle occlusion tests of visible clusters against a hierarchical Z-buffer: which
//! triangles of a cluster that passed the cluster test ([`crate::occlusion::test_clusters`]) can
//! still show a pixel. The finer half of GigaWalk's HZB culling (Baxter et al. 2002 §4.2 tests
//! objects; the triangle level is what GPU-driven renderers add, e.g. Wihlidal 2016, "Optimizing
//! the graphics pipeline with compute"): a cluster is drawn whole once any part of its box is
//! visible, and on the plant about two thirds of such a cluster's triangles are hidden behind
//! nearer geometry, face away behind their own object's front, or cover no pixel centre
//! (BENCHMARKS.md, "Triangle-level HZB culling").
//!
//! Each triangle is first tested like a box: the screen rectangle of its three projected
//! corners, widened by their rounding bound ([`PROJECTION_ROUNDING`]), is reduced to the pixel
//! centres it holds, and those and the corners' nearest depth go through [`Hzb::test_pixels`],
//! with the cluster test's depth margin. A small triangle that passes (at most
//! [`SAMPLE_TEST_MAX_PIXELS`] centres) is then tested sample by sample, as the rasterizer will:
//! only the pixel centres inside the triangle count, each against its own occluder depth (the
//! nearest corner depth, with the same margin). Most triangles of a 1-pixel LOD cut are a pixel
//! or two across, and a rectangle holds about twice the centres its triangle covers, so this
//! drops the many that cover no centre at all and those whose covered centres are all hidden.
//! "Inside" is widened by the distance the rasterizer's corners can lie from the ones computed
//! here (its sub-pixel snapping, [`SAMPLE_SLACK_PX`], plus the corners' rounding bound), so a
//! centre on or near an edge counts whatever the fill rule. A triangle with a corner behind the eye, at or before the near plane, or not
//! finite is kept. So a triangle is dropped only when every pixel centre it could cover holds
//! nearer geometry, or when it covers none: drawing the kept triangles gives the image of
//! drawing the whole cluster. Positions are computed exactly as the renderer's pool computes
//! them (grid coordinates × step, rounded to f32).
//!
//! The result is a [`TriangleMask`]: bit `t` for triangle `t` of the cluster (clusters hold at
//! most 128 triangles, docs/FORMAT.md).

use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;
use tw_store::PageCluster;

use crate::hzb::{Hzb, HzbResult, DEPTH_MARGIN};

/// Triangles whose rectangle holds at most this many pixel centres are tested centre by centre
/// (after the rectangle test called them visible); larger ones keep the rectangle's answer.
pub const SAMPLE_TEST_MAX_PIXELS: u32 = 64;

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

/// The triangles of `cluster` that may show a pixel over `hzb`, seen through `view_proj` (the
/// reverse-Z view-projection the depth was drawn with). A malformed triangle (an index beyond
/// the vertices) is reported visible; triangles beyond the 128th (the format allows none) have
/// no bit.
pub fn visible_triangles(cluster: &PageCluster, grid_step: f64, hzb: &Hzb, view_proj: &Mat4) -> TriangleMask {
    let (w, h) = hzb.size();
    let abs_view_proj = Mat4::from_cols_array(&view_proj.to_cols_array().map(f32::abs));
    // Screen x, y, depth and the bound on the screen position's rounding error (pixels) of each
    // vertex; `None` where the test cannot tell.
    let projected: Vec<Option<[f32; 4]>> = cluster
        .positions
        .iter()
        .map(|g| {
            project(view_proj, &abs_view_proj, Vec3::from(g.map(|c| (c as f64 * grid_step) as f32)), (w, h))
        })
        .collect();
    let mut mask: TriangleMask = 0;
    for (t, tri) in cluster.indices.chunks_exact(3).enumerate().take(128) {
        let corners = [tri[0], tri[1], tri[2]].map(|i| projected.get(i as usize).copied().flatten());
        let visible = match corners {
            [Some(a), Some(b), Some(c)] => {
                // The rectangle, widened by the corners' rounding bound (the rectangle tests
                // widen it by the snapping allowance themselves).
                let rounding = a[3].max(b[3]).max(c[3]);
                let (x_lo, x_hi) = (a[0].min(b[0]).min(c[0]) - rounding, a[0].max(b[0]).max(c[0]) + rounding);
                let (y_lo, y_hi) = (a[1].min(b[1]).min(c[1]) - rounding, a[1].max(b[1]).max(c[1]) + rounding);
                let nearest = a[2].max(b[2]).max(c[2]);
                if !(x_lo.is_finite() && x_hi.is_finite() && y_lo.is_finite() && y_hi.is_finite()) {
                    true
                } else {
                    match hzb.pixel_rect(x_lo, y_lo, x_hi, y_hi) {
                        None => false,
                        Some(rect) if hzb.test_pixels(rect, nearest) != HzbResult::Visible => false,
                        Some(rect) if pixel_count(rect) <= SAMPLE_TEST_MAX_PIXELS as u64 => {
                            let slack = SAMPLE_SLACK_PX + rounding as f64;
                            shows_a_sample(hzb, [a, b, c].map(|v| [v[0], v[1]]), rect, nearest, slack)
                        }
                        Some(_) => true,
                    }
                }
            }
            _ => true,
        };
        if visible {
            mask |= 1u128 << t;
        }
    }
    mask
}

/// Screen x, y (pixels, y down), reverse-Z depth of `p` through `view_proj` on a `size` image,
/// and the bound on the screen position's rounding (pixels) between this f32 evaluation and the
/// vertex shader's ([`PROJECTION_ROUNDING`]); `None` behind the eye, at or before the near
/// plane, or not finite. `abs_view_proj` holds the magnitudes of `view_proj`'s elements.
fn project(view_proj: &Mat4, abs_view_proj: &Mat4, p: Vec3, (w, h): (u32, u32)) -> Option<[f32; 4]> {
    let c: Vec4 = *view_proj * p.extend(1.0);
    if !c.is_finite() || c.w <= 0.0 {
        return None;
    }
    let depth = c.z / c.w;
    if depth >= 1.0 {
        return None;
    }
    let (x, y) = (c.x / c.w, c.y / c.w);
    // x/w moves by (δx + |x/w|·δw)/w, with |δx| ≤ rounding × Σ |m_0j p_j|, the same for w.
    let magnitude = *abs_view_proj * p.abs().extend(1.0);
    let error = |size: u32, ndc: f32, of_axis: f32| {
        0.5 * size as f32 * PROJECTION_ROUNDING * (of_axis + ndc.abs() * magnitude.w) / c.w
    };
    let rounding = error(w, x, magnitude.x).max(error(h, y, magnitude.y));
    Some([(x * 0.5 + 0.5) * w as f32, (0.5 - y * 0.5) * h as f32, depth, rounding])
}

fn pixel_count([x0, y0, x1, y1]: [u32; 4]) -> u64 {
    (x1 - x0 + 1) as u64 * (y1 - y0 + 1) as u64
}

/// Whether a pixel centre of `rect` (inclusive pixel bounds) inside the triangle of screen
/// corners `corners` (x, y) holds an occluder depth the triangle's `nearest` depth can pass. Edge functions in f64 from the f32 corners, stepped along each row; a centre
/// counts as inside when it would be inside for corners moved by up to `slack` pixels (a
/// degenerate triangle thus keeps the centres on its line).
fn shows_a_sample(
    hzb: &Hzb,
    corners: [[f32; 2]; 3],
    [x0, y0, x1, y1]: [u32; 4],
    nearest: f32,
    slack: f64,
) -> bool {
    let v = corners.map(|c| [c[0] as f64, c[1] as f64]);
    let area = (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
    let sign = if area < 0.0 { -1.0 } else { 1.0 };
    let bound = nearest / (1.0 - DEPTH_MARGIN);
    // Moving an edge's ends u, w by up to d changes its edge function at p by at most
    // d·(|p − u| + |p − w|) + 2d². A centre the rasterizer's (moved) triangle covers lies
    // inside it, so both distances are at most its longest edge + 3d: that bound decides
    // at once for most centres, the exact distances for the few in between.
    let d = slack;
    let length2 = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]);
    let longest = length2(v[0], v[1]).max(length2(v[1], v[2])).max(length2(v[2], v[0])).sqrt();
    let wide = 2.0 * d * longest + 8.0 * d * d;
    // Edge i from u to w: sign·cross(w − u, p − u) = a·p.x + b·p.y + c, ≥ 0 inside.
    let edges = [0, 1, 2].map(|i| {
        let (u, w) = (v[i], v[(i + 1) % 3]);
        let (a, b) = (-sign * (w[1] - u[1]), sign * (w[0] - u[0]));
        (a, b, -a * u[0] - b * u[1])
    });
    let near_edge = |i: usize, e: f64, p: [f64; 2]| {
        let (u, w) = (v[i], v[(i + 1) % 3]);
        e >= -(d * (length2(p, u).sqrt() + length2(p, w).sqrt()) + 2.0 * d * d)
    };
    let cx0 = x0 as f64 + 0.5;
    (y0..=y1).any(|y| {
        let py = y as f64 + 0.5;
        let mut e = edges.map(|(a, b, c)| a * cx0 + b * py + c);
        (x0..=x1).any(|x| {
            let p = [x as f64 + 0.5, py];
            let inside = (0..3).all(|i| e[i] >= 0.0 || (e[i] >= -wide && near_edge(i, e[i], p)));
            for (ei, edge) in e.iter_mut().zip(&edges) {
                *ei += edge.0;
            }
            inside && hzb.pixel_depth(x, y) <= bound
        })
    })
}

/// [`visible_triangles`] of many clusters, in parallel; the output keeps the input order.
pub fn test_triangles(
    clusters: &[&PageCluster],
    grid_step: f64,
    hzb: &Hzb,
    view_proj: &Mat4,
) -> Vec<TriangleMask> {
    clusters.par_iter().with_min_len(16).map(|c| visible_triangles(c, grid_step, hzb, view_proj)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    /// 64×48 view down +X from the origin; a wall at x = 10 covers the left half of the image.
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
        let m = visible_triangles(&c, 1.0 / 16.0, &hzb, &vp);
        assert_eq!(m, 0b01110, "mask {m:#b}");
        assert_eq!(test_triangles(&[&c, &c], 1.0 / 16.0, &hzb, &vp), vec![m, m]);
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
            shows_a_sample(&hzb, c, rect, depth, SAMPLE_SLACK_PX)
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
            let Some([x, y, _, rounding]) = project(&vp, &abs, p, (1280, 720)) else { continue };
            let exact = vp.as_dmat4() * p.as_dvec3().extend(1.0);
            let (ex, ey) =
                ((exact.x / exact.w * 0.5 + 0.5) * 1280.0, (0.5 - exact.y / exact.w * 0.5) * 720.0);
            let error = ((x as f64 - ex).abs()).max((y as f64 - ey).abs()) as f32;
            assert!(
                error <= rounding / 2.0 + 1e-4,
                "error {error} px, bound {rounding} px at {p} from {eye}"
            );
            largest = largest.max(rounding);
        }
        assert!(largest > 0.05, "the bound should matter here: at most {largest} px");
    }

    #[test]
    fn full_masks() {
        assert_eq!(full_mask(0), 0);
        assert_eq!(full_mask(3), 0b111);
        assert_eq!(full_mask(128), u128::MAX);
    }
}
