//! Per-triangle occlusion tests of visible clusters against a hierarchical Z-buffer: which
//! triangles of a cluster that passed the cluster test ([`crate::occlusion::test_clusters`]) can
//! still show a pixel. The finer half of GigaWalk's HZB culling (Baxter et al. 2002 §4.2 tests
//! objects; the triangle level is what GPU-driven renderers add, e.g. Wihlidal 2016, "Optimizing
//! the graphics pipeline with compute"): a cluster is drawn whole once any part of its box is
//! visible, and on the plant about two thirds of such a cluster's triangles are hidden behind
//! nearer geometry, face away behind their own object's front, or cover no pixel centre
//! (BENCHMARKS.md, "Triangle-level HZB culling").
//!
//! Each triangle is tested like a box: the screen rectangle of its three projected corners and
//! their nearest depth go through [`Hzb::test_rect`], which widens the rectangle and lowers the
//! depth bound by the same margins as the cluster test. A triangle with a corner behind the eye,
//! at or before the near plane, or not finite is kept. So a triangle is dropped only when every
//! pixel centre it could cover holds nearer geometry, or when it covers none: drawing the kept
//! triangles gives the image of drawing the whole cluster. Positions are computed exactly as the
//! renderer's pool computes them (grid coordinates × step, rounded to f32).
//!
//! The result is a [`TriangleMask`]: bit `t` for triangle `t` of the cluster (clusters hold at
//! most 128 triangles, docs/FORMAT.md).

use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;
use tw_store::PageCluster;

use crate::hzb::{Hzb, HzbResult};

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
    // Screen x, y and depth of each vertex; `None` where the test cannot tell.
    let projected: Vec<Option<[f32; 3]>> = cluster
        .positions
        .iter()
        .map(|g| {
            let p = Vec3::from(g.map(|c| (c as f64 * grid_step) as f32));
            let c: Vec4 = *view_proj * p.extend(1.0);
            if !c.is_finite() || c.w <= 0.0 {
                return None;
            }
            let depth = c.z / c.w;
            if depth >= 1.0 {
                return None;
            }
            Some([(c.x / c.w * 0.5 + 0.5) * w as f32, (0.5 - c.y / c.w * 0.5) * h as f32, depth])
        })
        .collect();
    let mut mask: TriangleMask = 0;
    for (t, tri) in cluster.indices.chunks_exact(3).enumerate().take(128) {
        let corners = [tri[0], tri[1], tri[2]].map(|i| projected.get(i as usize).copied().flatten());
        let visible = match corners {
            [Some(a), Some(b), Some(c)] => {
                let (x_lo, x_hi) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
                let (y_lo, y_hi) = (a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]));
                let nearest = a[2].max(b[2]).max(c[2]);
                hzb.test_rect(x_lo, y_lo, x_hi, y_hi, nearest) == HzbResult::Visible
            }
            _ => true,
        };
        if visible {
            mask |= 1u128 << t;
        }
    }
    mask
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

    #[test]
    fn full_masks() {
        assert_eq!(full_mask(0), 0);
        assert_eq!(full_mask(3), 0b111);
        assert_eq!(full_mask(128), u128::MAX);
    }
}
