//! Conservative occlusion culling of a frame's LOD cut with a hierarchical Z-buffer built from
//! last frame's visible set — GigaWalk's scheme (Baxter et al. 2002 §4: occluders are the visible
//! set of an earlier frame *at this frame's LOD*, their depth is read back, the HZB is built on
//! the CPU and the candidates' screen rectangles are tested against it) in the two-pass form
//! modern renderers use (draw the previous visible set, build the HZB, test the rest, draw the
//! newly visible in the same frame, so nothing is missing even when visibility changes).
//!
//! Per frame, with `cut` the clusters [`crate::Selector`] chose (frustum + LOD):
//! 1. [`OcclusionHistory::split`]: `occluders` = the clusters of `cut` that were visible last
//!    frame, `candidates` = the rest. Because the occluders are taken *from this frame's cut*,
//!    they are exactly the geometry the frame draws there — the condition under which GigaWalk's
//!    test is conservative (its "same LOD for occluders and display").
//! 2. The caller draws `occluders` (colour and depth), reads the depth back and builds an
//!    [`Hzb`].
//! 3. [`test_clusters`] tests the candidates' boxes against it (rayon): `Visible` ones are drawn in
//!    a second pass over the same targets; `Occluded` and `NoPixels` ones cannot change a pixel,
//!    so skipping them leaves the image identical to drawing the whole cut (up to the order of
//!    equal-depth fragments).
//! 4. [`OcclusionHistory::update`]: next frame's occluders are the candidates drawn now plus the
//!    occluders that the same HZB still shows (an occluder hidden behind other occluders drops
//!    out, so the set follows visibility instead of only growing). With triangle tests
//!    ([`crate::triangle_test`]) the history keeps, per cluster, the triangles found visible
//!    ([`OcclusionHistory::update_masked`]), and the first pass draws only those.

use std::collections::HashMap;

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use crate::hzb::{Hzb, HzbResult};
use crate::select::ClusterRef;
use crate::triangle_test::TriangleMask;

/// Which clusters a frame draws in its first and second pass.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OcclusionSplit {
    /// In the cut and visible last frame: drawn first, they make the depth buffer.
    pub occluders: Vec<ClusterRef>,
    /// Per occluder, its triangles visible last frame (`u128::MAX`: all of them).
    pub occluder_masks: Vec<TriangleMask>,
    /// In the cut but not visible last frame: tested against the HZB.
    pub candidates: Vec<ClusterRef>,
}

/// Results of [`test_clusters`], in the order of the input.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OcclusionTest {
    pub visible: Vec<ClusterRef>,
    /// Hidden behind nearer geometry.
    pub occluded: Vec<ClusterRef>,
    /// Covering no pixel centre (or outside the viewport).
    pub no_pixels: Vec<ClusterRef>,
}

/// The visible set carried from one frame to the next: clusters, each with its visible
/// triangles (`u128::MAX` where triangles were not tested).
#[derive(Clone, Debug, Default)]
pub struct OcclusionHistory {
    visible: HashMap<(u32, u32), TriangleMask>,
}

fn key(c: &ClusterRef) -> (u32, u32) {
    (c.page, c.index_in_page)
}

impl OcclusionHistory {
    pub fn new() -> OcclusionHistory {
        OcclusionHistory::default()
    }

    /// Forgets the visible set (the next frame draws no occluders and tests everything against
    /// an empty depth buffer, i.e. draws the whole cut): after a camera teleport, a store change.
    pub fn clear(&mut self) {
        self.visible.clear();
    }

    /// Clusters in the visible set.
    pub fn len(&self) -> usize {
        self.visible.len()
    }

    pub fn is_empty(&self) -> bool {
        self.visible.is_empty()
    }

    /// Splits this frame's cut into occluders (visible last frame) and candidates, keeping the
    /// cut's order within each.
    pub fn split(&self, cut: &[ClusterRef]) -> OcclusionSplit {
        let mut s = OcclusionSplit::default();
        for c in cut {
            if let Some(&mask) = self.visible.get(&key(c)) {
                s.occluders.push(*c);
                s.occluder_masks.push(mask);
            } else {
                s.candidates.push(*c);
            }
        }
        s
    }

    /// Next frame's visible set: `drawn_candidates` plus the `occluders` that `still_visible`
    /// keeps (the result of testing them against this frame's HZB).
    pub fn update(&mut self, still_visible_occluders: &[ClusterRef], drawn_candidates: &[ClusterRef]) {
        self.visible.clear();
        self.visible
            .extend(still_visible_occluders.iter().chain(drawn_candidates).map(|c| (key(c), u128::MAX)));
    }

    /// [`update`](Self::update) with each cluster's visible triangles (next frame's first pass
    /// draws only those).
    pub fn update_masked(&mut self, visible: impl IntoIterator<Item = (ClusterRef, TriangleMask)>) {
        self.visible.clear();
        self.visible.extend(visible.into_iter().map(|(c, m)| (key(&c), m)));
    }
}

/// Tests each cluster's scene-space box (`cluster_box`; `None` = unknown, kept visible) against
/// `hzb` seen through `view_proj` (reverse-Z, as the depth was drawn). Runs in parallel; the
/// output keeps the input order.
pub fn test_clusters(
    clusters: &[ClusterRef],
    hzb: &Hzb,
    view_proj: &Mat4,
    cluster_box: impl Fn(&ClusterRef) -> Option<(Vec3, Vec3)> + Sync,
) -> OcclusionTest {
    let results: Vec<HzbResult> = clusters
        .par_iter()
        .with_min_len(256)
        .map(|c| match cluster_box(c) {
            Some((lo, hi)) => hzb.test_box(view_proj, lo, hi),
            None => HzbResult::Visible,
        })
        .collect();
    let mut out = OcclusionTest::default();
    for (c, r) in clusters.iter().zip(results) {
        match r {
            HzbResult::Visible => out.visible.push(*c),
            HzbResult::Occluded => out.occluded.push(*c),
            HzbResult::NoPixels => out.no_pixels.push(*c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    fn c(page: u32, i: u32) -> ClusterRef {
        ClusterRef { page, index_in_page: i, group: 0 }
    }

    #[test]
    fn split_follows_the_history_and_keeps_order() {
        let mut h = OcclusionHistory::new();
        let cut = vec![c(0, 0), c(0, 1), c(1, 0), c(2, 5)];
        let s = h.split(&cut);
        assert!(s.occluders.is_empty());
        assert_eq!(s.candidates, cut);
        h.update(&[], &[c(2, 5), c(0, 1)]);
        let s = h.split(&cut);
        assert_eq!(s.occluders, vec![c(0, 1), c(2, 5)]);
        assert_eq!(s.occluder_masks, vec![u128::MAX; 2]);
        assert_eq!(s.candidates, vec![c(0, 0), c(1, 0)]);
        h.update_masked([(c(1, 0), 0b101)]);
        let s = h.split(&cut);
        assert_eq!((s.occluders, s.occluder_masks), (vec![c(1, 0)], vec![0b101]));
        // A cluster of the history that left the cut is simply not drawn.
        let s = h.split(&[c(0, 0)]);
        assert!(s.occluders.is_empty());
        h.clear();
        assert!(h.is_empty());
    }

    #[test]
    fn clusters_behind_a_wall_are_occluded_and_the_rest_kept() {
        let (w, h) = (64u32, 48u32);
        let cam = Camera::new(Vec3::ZERO, Vec3::X, Vec3::Z, 60f32.to_radians(), 0.1, 1000.0).unwrap();
        let vp = cam.projection_reverse_z(w as f32 / h as f32) * cam.view();
        let wall_depth = {
            let p = vp * glam::Vec4::new(10.0, 0.0, 0.0, 1.0);
            p.z / p.w
        };
        // The wall covers the left half of the image only.
        let depth: Vec<f32> = (0..w * h).map(|i| if i % w < w / 2 { wall_depth } else { 0.0 }).collect();
        let hzb = Hzb::build(&depth, w, h).unwrap();
        // y > 0 is to the left when looking down +X with z up.
        let boxes = |r: &ClusterRef| -> Option<(Vec3, Vec3)> {
            match r.index_in_page {
                0 => Some((Vec3::new(20.0, 2.0, -0.5), Vec3::new(21.0, 3.0, 0.5))), // behind, left
                1 => Some((Vec3::new(20.0, -3.0, -0.5), Vec3::new(21.0, -2.0, 0.5))), // right: open
                2 => Some((Vec3::new(5.0, 1.0, -0.5), Vec3::new(6.0, 2.0, 0.5))),   // in front
                3 => Some((Vec3::new(20.0, 200.0, 0.0), Vec3::new(21.0, 201.0, 1.0))), // off-screen
                _ => None,
            }
        };
        let list: Vec<ClusterRef> = (0..5).map(|i| c(7, i)).collect();
        let t = test_clusters(&list, &hzb, &vp, boxes);
        assert_eq!(t.occluded, vec![c(7, 0)]);
        assert_eq!(t.visible, vec![c(7, 1), c(7, 2), c(7, 4)]);
        assert_eq!(t.no_pixels, vec![c(7, 3)]);
    }
}
