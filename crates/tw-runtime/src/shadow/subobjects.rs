//! Finer receiver classes from subobjects (Govindaraju's thesis ch. 4, §4.2.2: cross-culling
//! "at the granularity of subobjects of k triangles"): a receiver cluster that cross-culling
//! found partly shadowed is cut into runs of [`SUBOBJECT_TRIANGLES`] consecutive triangles, and
//! each run's box is classified again by the same rule ([`classify_receivers`]). The triangles
//! of a lit or shadowed run are then drawn without lookups, only those of partly shadowed runs
//! with them: on a CPU driver the lookups are the largest cost of shadows, and a large floor or
//! wall cluster with a shadow edge across one corner is mostly lit or mostly dark.
//!
//! A cluster's triangles are in the order its pool draws them (the store's order), so bit `t`
//! of a [`TriangleClasses`] mask is the cluster's triangle `t`, as in
//! [`crate::triangle_test::TriangleMask`]. The subobject boxes are the exact bounds of their
//! triangles' grid vertices ([`grid_box`] rounds outwards), so the classes keep the guarantee of
//! [`classify_receivers`]: a triangle drawn without lookups is drawn as a lookup would draw it.

use glam::Vec3;

use crate::camera::Camera;
use crate::frustum::grid_box;
use crate::shadow::classify::classify_receivers;
use crate::shadow::depth::LightDepth;
use crate::shadow::{ShadowClass, Shadows};
use crate::triangle_test::{full_mask, TriangleMask};
use tw_store::PageCluster;

/// Triangles per subobject: the thesis' `k` (its default is 8).
pub const SUBOBJECT_TRIANGLES: usize = 8;

/// The most triangles a cluster may have to be refined: a mask holds 128.
const MAX_TRIANGLES: usize = 128;

/// The classes of a partly shadowed receiver's triangles, a bit per triangle; a triangle in
/// neither mask is partly shadowed (looked up).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct TriangleClasses {
    /// Triangles every point of which is lit.
    pub lit: TriangleMask,
    /// Triangles no point of which is lit.
    pub shadowed: TriangleMask,
}

impl TriangleClasses {
    /// The triangles of a cluster of `triangles` that need lookups.
    pub fn partial(&self, triangles: usize) -> TriangleMask {
        full_mask(triangles) & !(self.lit | self.shadowed)
    }

    /// Whether some triangle is drawn without lookups.
    pub fn refines(&self) -> bool {
        (self.lit | self.shadowed) != 0
    }
}

/// The boxes (scene space) of `cluster`'s subobjects: runs of [`SUBOBJECT_TRIANGLES`]
/// consecutive triangles, the last one shorter. Empty for a cluster a mask cannot hold or with an
/// index past its vertices (the pool draws such a cluster whole).
pub fn subobject_boxes(cluster: &PageCluster, grid_step: f64) -> Vec<(Vec3, Vec3)> {
    let triangles = cluster.indices.len() / 3;
    let well_formed = cluster.indices.iter().all(|&v| (v as usize) < cluster.positions.len());
    if triangles == 0 || triangles > MAX_TRIANGLES || !well_formed {
        return Vec::new();
    }
    cluster
        .indices
        .chunks(3 * SUBOBJECT_TRIANGLES)
        .map(|run| {
            let (mut lo, mut hi) = ([u32::MAX; 3], [0u32; 3]);
            for &v in run {
                let p = cluster.positions[v as usize];
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
            grid_box(lo, hi, grid_step)
        })
        .collect()
}

/// The triangle classes of each of `clusters` (partly shadowed receivers, decoded) against the
/// read-back layers `depths`, as [`classify_receivers`] would classify each subobject as a
/// receiver of its own. A cluster that cannot be cut (see [`subobject_boxes`]) gets no lit or
/// shadowed triangle.
pub fn classify_subobjects(
    shadows: &Shadows,
    depths: &[LightDepth],
    eye: &Camera,
    clusters: &[&PageCluster],
    grid_step: f64,
) -> Vec<TriangleClasses> {
    classify_subobjects_cut(shadows, depths, eye, clusters, grid_step, |boxes| boxes)
}

/// [`classify_subobjects`] with each subobject's box replaced by `cut` (all of them at once, in
/// order) before it is classified: a caller that knows where the subobjects can be drawn (the
/// eye's view) passes the boxes of their parts there. `cut` must return, for each box, one that
/// holds every point of the subobject that can be drawn.
pub fn classify_subobjects_cut(
    shadows: &Shadows,
    depths: &[LightDepth],
    eye: &Camera,
    clusters: &[&PageCluster],
    grid_step: f64,
    cut: impl FnOnce(Vec<(Vec3, Vec3)>) -> Vec<(Vec3, Vec3)>,
) -> Vec<TriangleClasses> {
    let per_cluster: Vec<Vec<(Vec3, Vec3)>> =
        clusters.iter().map(|c| subobject_boxes(c, grid_step)).collect();
    let boxes = cut(per_cluster.iter().flatten().copied().collect());
    assert_eq!(boxes.len(), per_cluster.iter().map(Vec::len).sum::<usize>(), "one box per subobject");
    let classes = classify_receivers(shadows, depths, eye, &boxes);
    let mut next = classes.iter();
    clusters
        .iter()
        .zip(&per_cluster)
        .map(|(cluster, runs)| {
            let triangles = cluster.indices.len() / 3;
            let mut out = TriangleClasses::default();
            for (i, class) in next.by_ref().take(runs.len()).enumerate() {
                let first = i * SUBOBJECT_TRIANGLES;
                let run = full_mask(triangles.min(first + SUBOBJECT_TRIANGLES)) & !full_mask(first);
                match class {
                    ShadowClass::Lit => out.lit |= run,
                    ShadowClass::Shadowed => out.shadowed |= run,
                    ShadowClass::Partial => {}
                }
            }
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strip of `n` triangles along x, triangle `t` spanning x in `[t, t + 1]`.
    fn strip(n: u8) -> PageCluster {
        let positions: Vec<[u32; 3]> = (0..=n as u32).flat_map(|x| [[x, 0, 0], [x, 1, 0]]).collect();
        let indices = (0..n).flat_map(|t| [2 * t, 2 * t + 2, 2 * t + 1]).collect();
        PageCluster {
            positions,
            indices,
            objects: vec![0; n as usize],
            self_error: 0.0,
            self_sphere: [0.0; 4],
            group: 0,
            level: 0,
        }
    }

    #[test]
    fn subobjects_are_runs_of_k_triangles_bounded_exactly() {
        let boxes = subobject_boxes(&strip(20), 1.0);
        assert_eq!(boxes.len(), 3);
        for (i, (lo, hi)) in boxes.iter().enumerate() {
            let first = (i * SUBOBJECT_TRIANGLES) as f32;
            let last = ((i + 1) * SUBOBJECT_TRIANGLES).min(20) as f32;
            assert!((lo.x - first).abs() < 1e-4 && (hi.x - last).abs() < 1e-4, "{i}: {lo} {hi}");
            assert!(lo.x <= first && hi.x >= last, "{i}: rounded outwards");
            assert!(lo.y.abs() < 1e-5 && (hi.y - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn clusters_a_mask_cannot_hold_or_with_bad_indices_are_not_cut() {
        assert!(subobject_boxes(&strip(0), 1.0).is_empty());
        let mut bad = strip(4);
        bad.indices[5] = 200;
        assert!(subobject_boxes(&bad, 1.0).is_empty());
        let classes = TriangleClasses { lit: 0b0011, shadowed: 0b0100 };
        assert_eq!(classes.partial(4), 0b1000);
        assert!(classes.refines());
        assert!(!TriangleClasses::default().refines());
    }
}
