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
//!    equal-depth fragments). [`test_clusters_hierarchically`] gets the same visible set
//!    top-down: skeleton node boxes first, then group boxes, then the clusters under no hidden
//!    one.
//! 4. [`OcclusionHistory::update`]: next frame's occluders are the candidates drawn now plus the
//!    occluders that the same HZB still shows (an occluder hidden behind other occluders drops
//!    out, so the set follows visibility instead of only growing). With triangle tests
//!    ([`crate::triangle_test`]) the history keeps, per cluster, the triangles found visible
//!    ([`OcclusionHistory::update_masked`]), and the first pass draws only those.

use std::time::{Duration, Instant};

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use tw_store::{Group, Node};

use crate::frustum::grid_box;
use crate::hzb::{Hzb, HzbResult};
use crate::node_test::{test_hierarchy, NodeTestOptions};
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
///
/// Kept sorted by cluster rather than hashed: made with a parallel sort and read with parallel
/// binary searches, where a hash map is filled by one thread (at 10^5 clusters a frame, a few
/// milliseconds of the cull).
#[derive(Clone, Debug, Default)]
pub struct OcclusionHistory {
    visible: Vec<((u32, u32), TriangleMask)>,
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
    /// The look-ups run in parallel (a cut holds up to ~10^5 clusters); the split itself is one
    /// ordered walk, so the result does not depend on the threads.
    pub fn split(&self, cut: &[ClusterRef]) -> OcclusionSplit {
        let found: Vec<Option<TriangleMask>> =
            cut.par_iter().with_min_len(1024).map(|c| self.get(c)).collect();
        let mut s = OcclusionSplit::default();
        for (c, found) in cut.iter().zip(found) {
            if let Some(mask) = found {
                s.occluders.push(*c);
                s.occluder_masks.push(mask);
            } else {
                s.candidates.push(*c);
            }
        }
        s
    }

    /// Whether `c` is in the visible set.
    pub fn contains(&self, c: &ClusterRef) -> bool {
        self.get(c).is_some()
    }

    /// The triangles of `c` in the visible set, if it is there.
    fn get(&self, c: &ClusterRef) -> Option<TriangleMask> {
        let i = self.visible.binary_search_by_key(&key(c), |e| e.0).ok()?;
        Some(self.visible[i].1)
    }

    /// Next frame's visible set: `drawn_candidates` plus the `occluders` that `still_visible`
    /// keeps (the result of testing them against this frame's HZB).
    pub fn update(&mut self, still_visible_occluders: &[ClusterRef], drawn_candidates: &[ClusterRef]) {
        self.update_masked(still_visible_occluders.iter().chain(drawn_candidates).map(|c| (*c, u128::MAX)));
    }

    /// [`update`](Self::update) with each cluster's visible triangles (next frame's first pass
    /// draws only those). A cluster given twice keeps its last mask.
    pub fn update_masked(&mut self, visible: impl IntoIterator<Item = (ClusterRef, TriangleMask)>) {
        self.visible.clear();
        self.visible.extend(visible.into_iter().map(|(c, m)| (key(&c), m)));
        // Stable, so equal clusters keep their order and the last one's mask can be kept.
        self.visible.par_sort_by_key(|e| e.0);
        self.visible.dedup_by(|later, kept| {
            let same = later.0 == kept.0;
            if same {
                kept.1 = later.1;
            }
            same
        });
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
    let results = test_boxes(clusters, hzb, view_proj, cluster_box);
    sort_results(clusters, &results)
}

/// [`test_clusters`] as one result per cluster (input order), for callers that need to know
/// which of their clusters each result belongs to.
pub fn test_boxes(
    clusters: &[ClusterRef],
    hzb: &Hzb,
    view_proj: &Mat4,
    cluster_box: impl Fn(&ClusterRef) -> Option<(Vec3, Vec3)> + Sync,
) -> Vec<HzbResult> {
    clusters.par_iter().with_min_len(256).map(|c| test_one(hzb, view_proj, cluster_box(c))).collect()
}

/// The HZB test of one box; an unknown box is visible.
fn test_one(hzb: &Hzb, view_proj: &Mat4, scene_box: Option<(Vec3, Vec3)>) -> HzbResult {
    match scene_box {
        Some((lo, hi)) => hzb.test_box(view_proj, lo, hi),
        None => HzbResult::Visible,
    }
}

/// The clusters sorted by their results (each list in input order).
fn sort_results(clusters: &[ClusterRef], results: &[HzbResult]) -> OcclusionTest {
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

/// The store's skeleton as [`test_clusters_hierarchically`] walks it.
#[derive(Clone, Copy, Debug)]
pub struct Skeleton<'a> {
    /// Each node's parent (`u32::MAX` for a root; [`crate::node_test::parents`]).
    pub parents: &'a [u32],
    /// The nodes (their boxes: inclusive grid boxes of everything under them).
    pub nodes: &'a [Node],
    /// The groups (a cluster's `group` indexes them; each names the node it hangs under).
    pub groups: &'a [Group],
    /// Scene units per grid unit.
    pub grid_step: f64,
}

/// Which levels [`test_clusters_hierarchically`] tests above the clusters' own boxes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HierarchyOptions {
    /// Skeleton node boxes, breadth-first from the roots.
    pub nodes: bool,
    /// One box per group (the union of its candidates' boxes), between its node and its
    /// clusters: many clusters share a group, and the union is tighter than the node's box.
    pub groups: bool,
    /// Nodes and groups with fewer candidates under them are not tested
    /// ([`NodeTestOptions::min_candidates`]).
    pub min_candidates: usize,
}

impl Default for HierarchyOptions {
    fn default() -> Self {
        HierarchyOptions {
            nodes: true,
            groups: true,
            min_candidates: NodeTestOptions::default().min_candidates,
        }
    }
}

impl HierarchyOptions {
    /// Every cluster's box tested on its own (GigaWalk's flat test).
    pub const FLAT: HierarchyOptions = HierarchyOptions { nodes: false, groups: false, min_candidates: 0 };
}

/// What [`test_clusters_hierarchically`] found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HierarchicalTest {
    /// Per cluster, as [`test_clusters`] sorts them; a cluster under a hidden node or group
    /// box is occluded.
    pub clusters: OcclusionTest,
    /// Skeleton node boxes tested, and of those found hidden.
    pub nodes_tested: u64,
    pub nodes_hidden: u64,
    /// Group boxes tested, and of those found hidden.
    pub groups_tested: u64,
    pub groups_hidden: u64,
    /// Clusters whose own box was tested (those no hidden node or group culled).
    pub clusters_tested: u64,
    /// Time of the node and group tests (all rounds, with the tree they walk), and of the
    /// clusters' own tests: what [`crate::NodeTestSwitch`] weighs.
    pub hierarchy_time: Duration,
    pub clusters_time: Duration,
}

/// [`test_clusters`] top-down: the boxes of the skeleton nodes holding `clusters` are tested
/// first, breadth-first by level ([`test_hierarchy`]: Govindaraju's thesis Alg. 3.4.1, as the
/// `queries` strategy does with hardware queries), then (`options.groups`) a box per group,
/// and only the clusters under no hidden box are tested on their own. A hidden node or group
/// culls everything under it with one test: behind a wall, a room's thousands of clusters cost
/// a handful of tests. Each round's boxes are tested in parallel.
///
/// The same answer as [`test_clusters`] up to rounding: a box inside a hidden box is hidden
/// (its screen rectangle lies inside the outer one's and its nearest depth is no nearer), so
/// only clusters the flat test finds occluded are culled. This needs every node box to contain
/// the clusters under it (docs/FORMAT.md); a group's box is made from its clusters' boxes. Only
/// [`HzbResult::Occluded`] hides a node or group: one covering no pixel centre opens its
/// children, whose own tests sort them into `no_pixels` as the flat test would. The output is
/// the same whatever the number of threads.
pub fn test_clusters_hierarchically(
    clusters: &[ClusterRef],
    skeleton: &Skeleton,
    hzb: &Hzb,
    view_proj: &Mat4,
    cluster_box: impl Fn(&ClusterRef) -> Option<(Vec3, Vec3)> + Sync,
    options: &HierarchyOptions,
) -> HierarchicalTest {
    let boxes: Vec<Option<(Vec3, Vec3)>> = clusters.par_iter().with_min_len(1024).map(&cluster_box).collect();
    let start = Instant::now();
    let tree = CandidateTree::new(clusters, skeleton, &boxes, options);
    let mut result = HierarchicalTest::default();
    let culled = match &tree {
        Some(tree) => {
            let n = skeleton.nodes.len() as u32;
            let (mut groups_tested, mut groups_hidden) = (0u64, 0u64);
            let walk = test_hierarchy::<std::convert::Infallible>(
                &tree.parents,
                &tree.leaf_of,
                &NodeTestOptions { min_candidates: options.min_candidates },
                |batch| {
                    let visible: Vec<bool> = batch
                        .par_iter()
                        .with_min_len(64)
                        .map(|&m| test_one(hzb, view_proj, tree.box_of(m, skeleton)) != HzbResult::Occluded)
                        .collect();
                    groups_tested += batch.iter().filter(|&&m| m >= n).count() as u64;
                    groups_hidden +=
                        batch.iter().zip(&visible).filter(|(&m, &v)| m >= n && !v).count() as u64;
                    Ok(visible)
                },
            );
            let walk = match walk {
                Ok(walk) => walk,
                Err(never) => match never {},
            };
            result.groups_tested = groups_tested;
            result.groups_hidden = groups_hidden;
            result.nodes_tested = walk.nodes_tested - groups_tested;
            result.nodes_hidden = walk.nodes_hidden - groups_hidden;
            walk.culled
        }
        None => vec![false; clusters.len()],
    };
    result.hierarchy_time = start.elapsed();
    let start = Instant::now();
    let results: Vec<HzbResult> = boxes
        .par_iter()
        .zip(&culled)
        .with_min_len(256)
        .map(|(b, &culled)| if culled { HzbResult::Occluded } else { test_one(hzb, view_proj, *b) })
        .collect();
    result.clusters_tested = culled.iter().filter(|&&c| !c).count() as u64;
    result.clusters = sort_results(clusters, &results);
    result.clusters_time = start.elapsed();
    result
}

/// The tree [`test_clusters_hierarchically`] walks: the skeleton's nodes, then (with groups)
/// one extra node per group holding candidates, hung under the group's node.
struct CandidateTree {
    /// Parent of each node of the tree (`u32::MAX` for a root).
    parents: Vec<u32>,
    /// Per candidate, the tree node it hangs under (`u32::MAX`: none, never culled).
    leaf_of: Vec<u32>,
    /// The boxes of the group nodes (tree node `nodes.len() + i`).
    group_boxes: Vec<Option<(Vec3, Vec3)>>,
}

impl CandidateTree {
    /// `None` when nothing above the clusters is to be tested, or the skeleton's parent links
    /// do not match its nodes.
    fn new(
        clusters: &[ClusterRef],
        skeleton: &Skeleton,
        boxes: &[Option<(Vec3, Vec3)>],
        options: &HierarchyOptions,
    ) -> Option<CandidateTree> {
        let n = skeleton.nodes.len();
        if !(options.nodes || options.groups) || skeleton.parents.len() != n {
            return None;
        }
        let node_of_group = |g: u32| skeleton.groups.get(g as usize).map_or(u32::MAX, |g| g.node);
        // Without node tests the group nodes are the roots: the skeleton's nodes stay in the
        // tree but have no candidates under them, so none is tested.
        let group_parent = |g: u32| if options.nodes { node_of_group(g) } else { u32::MAX };
        if !options.groups {
            let leaf_of = clusters.par_iter().with_min_len(1024).map(|c| node_of_group(c.group)).collect();
            return Some(CandidateTree {
                parents: skeleton.parents.to_vec(),
                leaf_of,
                group_boxes: Vec::new(),
            });
        }
        // The groups holding candidates, in group order (so the tree does not depend on the
        // cut's order), each with the union of its candidates' boxes.
        let mut order: Vec<u32> = (0..clusters.len() as u32).collect();
        order.par_sort_by_key(|&i| clusters[i as usize].group);
        let mut parents = skeleton.parents.to_vec();
        let mut leaf_of = vec![u32::MAX; clusters.len()];
        let mut group_boxes: Vec<Option<(Vec3, Vec3)>> = Vec::new();
        let mut last_group = None;
        for &i in &order {
            let (group, b) = (clusters[i as usize].group, boxes[i as usize]);
            if last_group != Some(group) {
                last_group = Some(group);
                parents.push(group_parent(group));
                group_boxes.push(b);
            } else if let Some(union) = group_boxes.last_mut() {
                *union = union.zip(b).map(|((lo, hi), (l, h))| (lo.min(l), hi.max(h)));
            }
            leaf_of[i as usize] = (parents.len() - 1) as u32;
        }
        Some(CandidateTree { parents, leaf_of, group_boxes })
    }

    /// The scene-space box of tree node `m`.
    fn box_of(&self, m: u32, skeleton: &Skeleton) -> Option<(Vec3, Vec3)> {
        match skeleton.nodes.get(m as usize) {
            Some(node) => Some(grid_box(node.min, node.max, skeleton.grid_step)),
            None => self.group_boxes.get(m as usize - skeleton.nodes.len()).copied().flatten(),
        }
    }
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

    /// 64×48 view down +X from (0, 100, 10), z up; a wall at x = 10 covers the left half of
    /// the image (y > 100). Grid step 1/4, so scene = grid / 4.
    fn walled() -> (Hzb, Mat4) {
        let (w, h) = (64u32, 48u32);
        let eye = Vec3::new(0.0, 100.0, 10.0);
        let cam = Camera::new(eye, eye + Vec3::X, Vec3::Z, 60f32.to_radians(), 0.1, 1000.0).unwrap();
        let vp = cam.projection_reverse_z(w as f32 / h as f32) * cam.view();
        let p = vp * glam::Vec4::new(10.0, 100.0, 10.0, 1.0);
        let depth: Vec<f32> = (0..w * h).map(|i| if i % w < w / 2 { p.z / p.w } else { 0.0 }).collect();
        (Hzb::build(&depth, w, h).unwrap(), vp)
    }

    const STEP: f64 = 0.25;

    /// An inclusive grid box from scene corners.
    fn node(lo: [f32; 3], hi: [f32; 3], first_child: u32, child_count: u32) -> Node {
        let g = |v: [f32; 3]| v.map(|c| (c as f64 / STEP) as u32);
        Node { min: g(lo), max: g(hi), first_child, child_count, ..Default::default() }
    }

    /// A hidden node culls every candidate of its subtree with its one test, and no candidate
    /// under it is tested on its own; the result is the flat test's.
    #[test]
    fn a_hidden_node_culls_its_subtree_with_one_test() {
        let (hzb, vp) = walled();
        // 0 → {1, 2}; 1 (behind the wall, left) → {3, 4}; 2 (open, right).
        let nodes = [
            node([20.0, 80.0, 0.0], [30.0, 120.0, 20.0], 1, 2),
            node([20.0, 102.0, 5.0], [30.0, 112.0, 15.0], 3, 2),
            node([20.0, 88.0, 5.0], [30.0, 98.0, 15.0], 0, 0),
            node([20.0, 102.0, 5.0], [25.0, 112.0, 15.0], 0, 0),
            node([25.0, 102.0, 5.0], [30.0, 112.0, 15.0], 0, 0),
        ];
        let parents = crate::node_test::parents(nodes.iter().map(|n| (n.first_child, n.child_count)));
        // One group per leaf (groups 0, 1, 2 at nodes 3, 4, 2), 6 clusters in each, in one row
        // along x inside the leaf: 12 hidden behind the wall, 6 in the open.
        let groups: Vec<Group> =
            [3u32, 4, 2].iter().map(|&n| Group { node: n, ..Default::default() }).collect();
        let skeleton = Skeleton { parents: &parents, nodes: &nodes, groups: &groups, grid_step: STEP };
        let clusters: Vec<ClusterRef> =
            (0..18).map(|i| ClusterRef { page: i / 6, index_in_page: i % 6, group: i / 6 }).collect();
        let cluster_box = |c: &ClusterRef| {
            let n = &nodes[groups[c.group as usize].node as usize];
            let lo = grid_box(n.min, n.max, STEP).0 + Vec3::new(0.5 * c.index_in_page as f32 + 0.1, 1.0, 1.0);
            Some((lo, lo + Vec3::splat(1.0)))
        };
        let flat = test_clusters(&clusters, &hzb, &vp, cluster_box);
        assert_eq!((flat.occluded.len(), flat.visible.len()), (12, 6));
        for options in [HierarchyOptions { groups: false, ..Default::default() }, HierarchyOptions::default()]
        {
            let t = test_clusters_hierarchically(&clusters, &skeleton, &hzb, &vp, cluster_box, &options);
            // The root, then node 1 (node 2, the leaves and the groups have fewer than 8
            // candidates: not tested), which hides its subtree's 12 candidates.
            assert_eq!((t.nodes_tested, t.nodes_hidden), (2, 1), "{options:?}");
            assert_eq!((t.groups_tested, t.groups_hidden), (0, 0), "{options:?}");
            assert_eq!(t.clusters_tested, 6, "{options:?}: only the open node's candidates");
            assert_eq!(t.clusters, flat, "{options:?}");
        }
        let t = test_clusters_hierarchically(
            &clusters,
            &skeleton,
            &hzb,
            &vp,
            cluster_box,
            &HierarchyOptions::FLAT,
        );
        assert_eq!((t.nodes_tested, t.clusters_tested, &t.clusters), (0, 18, &flat));
        // With 5 candidates enough for a test, the groups (6 each) are tested too: without node
        // tests, the two hidden groups cull 12 candidates with a test each.
        let groups_only = HierarchyOptions { nodes: false, groups: true, min_candidates: 5 };
        let t = test_clusters_hierarchically(&clusters, &skeleton, &hzb, &vp, cluster_box, &groups_only);
        assert_eq!((t.nodes_tested, t.groups_tested, t.groups_hidden, t.clusters_tested), (0, 3, 2, 6));
        assert_eq!(t.clusters, flat);
    }

    /// What [`random_scene`] makes: a skeleton, clusters with their boxes, a pyramid and the
    /// view it was drawn with.
    struct RandomScene {
        nodes: Vec<Node>,
        groups: Vec<Group>,
        clusters: Vec<ClusterRef>,
        boxes: Vec<(Vec3, Vec3)>,
        hzb: Hzb,
        vp: Mat4,
    }

    /// A pseudo-random scene: a 4 × 4 × 2 grid of leaf nodes under 4 inner nodes and a root,
    /// 3 groups a leaf, clusters scattered in them, walls at several depths.
    fn random_scene(count: u32) -> RandomScene {
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f32 / (1u64 << 53) as f32
        };
        let (hzb, vp) = {
            let (w, h) = (96u32, 64u32);
            let eye = Vec3::new(0.0, 100.0, 10.0);
            let cam = Camera::new(eye, eye + Vec3::X, Vec3::Z, 70f32.to_radians(), 0.1, 1000.0).unwrap();
            let vp = cam.projection_reverse_z(w as f32 / h as f32) * cam.view();
            let depth_at = |x: f32| {
                let p = vp * glam::Vec4::new(x, 100.0, 10.0, 1.0);
                p.z / p.w
            };
            let walls = [depth_at(12.0), depth_at(25.0), depth_at(40.0), 0.0];
            let depth: Vec<f32> =
                (0..w * h).map(|i| walls[((i % w) / 17 + (i / w) / 23) as usize % 4]).collect();
            (Hzb::build(&depth, w, h).unwrap(), vp)
        };
        // Leaves: x 20..60 in 4 slabs, y 80..120 in 4, z 0..20 in 2; inner nodes by x slab.
        let mut nodes = vec![node([20.0, 80.0, 0.0], [60.0, 120.0, 20.0], 1, 4)];
        for sx in 0..4 {
            let x = 20.0 + 10.0 * sx as f32;
            nodes.push(node([x, 80.0, 0.0], [x + 10.0, 120.0, 20.0], 5 + 8 * sx, 8));
        }
        for sx in 0..4 {
            for k in 0..8 {
                let (x, y, z) =
                    (20.0 + 10.0 * sx as f32, 80.0 + 10.0 * (k / 2) as f32, 10.0 * (k % 2) as f32);
                nodes.push(node([x, y, z], [x + 10.0, y + 10.0, z + 10.0], 0, 0));
            }
        }
        let groups: Vec<Group> =
            (0..32 * 3).map(|g| Group { node: 5 + g / 3, ..Default::default() }).collect();
        let mut clusters = Vec::new();
        let mut boxes = Vec::new();
        for i in 0..count {
            let group = (next() * groups.len() as f32) as u32 % groups.len() as u32;
            let n = &nodes[groups[group as usize].node as usize];
            let (lo, hi) = grid_box(n.min, n.max, STEP);
            let size = Vec3::new(next(), next(), next()) * 2.0;
            let at = lo + (hi - lo - size) * Vec3::new(next(), next(), next());
            clusters.push(ClusterRef { page: i / 64, index_in_page: i % 64, group });
            boxes.push((at, at + size));
        }
        RandomScene { nodes, groups, clusters, boxes, hzb, vp }
    }

    /// Hierarchical tests give the flat test's result on a scattered scene, and every test
    /// here gives the same output on one thread as on several.
    #[test]
    fn hierarchical_equals_flat_and_parallel_equals_serial() {
        let RandomScene { nodes, groups, clusters, boxes, hzb, vp } = random_scene(5_000);
        let parents = crate::node_test::parents(nodes.iter().map(|n| (n.first_child, n.child_count)));
        let skeleton = Skeleton { parents: &parents, nodes: &nodes, groups: &groups, grid_step: STEP };
        let by_ref = |c: &ClusterRef| Some(boxes[(c.page * 64 + c.index_in_page) as usize]);
        let run = || {
            let flat = test_clusters(&clusters, &hzb, &vp, by_ref);
            let options =
                [HierarchyOptions { groups: false, ..Default::default() }, HierarchyOptions::default()];
            let hierarchical = options.map(|o| HierarchicalTest {
                hierarchy_time: Duration::ZERO,
                clusters_time: Duration::ZERO,
                ..test_clusters_hierarchically(&clusters, &skeleton, &hzb, &vp, by_ref, &o)
            });
            let mut history = OcclusionHistory::new();
            history.update_masked(flat.visible.iter().enumerate().map(|(i, c)| (*c, i as u128)));
            (flat, hierarchical, history.split(&clusters))
        };
        let serial = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(run);
        let parallel = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap().install(run);
        assert_eq!(serial, parallel);
        let (flat, hierarchical, split) = serial;
        let (occluded, visible) = (flat.occluded.len(), flat.visible.len());
        assert!(occluded > 500 && visible > 500, "{occluded} occluded, {visible} visible");
        for h in &hierarchical {
            assert_same_visible(&h.clusters, &flat);
            let (hidden, tested) = (h.nodes_hidden, h.clusters_tested);
            assert!(hidden > 0 && tested < clusters.len() as u64, "{hidden} nodes hidden, {tested} tested");
        }
        assert!(hierarchical[1].groups_tested > 0);
        assert_eq!(split.occluders, flat.visible);
    }

    /// The same clusters visible; those the flat test found covering no pixel centre may be
    /// under a hidden node (then occluded), the flat test's occluded ones stay occluded.
    fn assert_same_visible(hierarchical: &OcclusionTest, flat: &OcclusionTest) {
        assert_eq!(hierarchical.visible, flat.visible);
        let set = |l: &[ClusterRef]| l.iter().map(key).collect::<std::collections::BTreeSet<_>>();
        let (occluded, no_pixels) = (set(&hierarchical.occluded), set(&hierarchical.no_pixels));
        assert!(occluded.is_superset(&set(&flat.occluded)));
        assert!(set(&flat.no_pixels).is_superset(&no_pixels));
        assert_eq!(occluded.len() + no_pixels.len(), flat.occluded.len() + flat.no_pixels.len());
    }

    #[test]
    fn a_history_given_a_cluster_twice_keeps_its_last_mask() {
        let mut h = OcclusionHistory::new();
        h.update_masked([(c(3, 1), 1), (c(0, 2), 2), (c(3, 1), 3)]);
        assert_eq!(h.len(), 2);
        let s = h.split(&[c(3, 1), c(0, 2)]);
        assert_eq!(s.occluder_masks, vec![3, 2]);
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
