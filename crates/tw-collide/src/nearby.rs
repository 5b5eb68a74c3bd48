//! The triangles a walker can touch: those within a box (the capsule's reach,
//! [`crate::capsule::Capsule::reach`]), in scene space, gathered into a buffer kept between
//! frames.
//!
//! It lives here rather than in the viewer because it is what turns a store's clusters into
//! collision geometry (grid coordinates × the grid step, as the renderers place them), and the
//! viewer, the tests along generated walks and the timing example all need the same answer.
//!
//! **Which clusters.** The full-detail (level 0) clusters within reach, found through the
//! store's skeleton (node boxes, then group spheres), and the clusters of the frame's cut within
//! reach. The cut alone is not enough: it is frustum culled, so the wall beside or behind the
//! walker is not in it; level 0 alone is not either: its page may not be resident yet, and then
//! the cut's coarser cluster there is the best geometry at hand (near the eye the cut is at full
//! detail anyway: a millimetre of error is a pixel at arm's length), so the cut is added when a
//! full-detail page is missing. Pages that are not resident are skipped and listed
//! ([`Nearby::missing_pages`], for the caller to request): a walk never waits for the disk.
//!
//! Cheapest test first: a cluster is skipped by its group's bounding sphere (the store's group
//! table, no page read), then by its vertex box (the resident page's bounds), and only then are
//! its triangles' boxes tested.

use std::sync::Arc;

use tw_runtime::{ClusterRef, ResidentPage};
use tw_store::Store;

use crate::capsule::Triangle;
use crate::Aabb;

/// The gathered triangles and what gave them.
#[derive(Clone, Debug, Default)]
pub struct Nearby {
    pub triangles: Vec<Triangle>,
    /// The clusters that gave at least one triangle, sorted.
    pub clusters: Vec<ClusterRef>,
    /// Clusters within the box whose page was not resident.
    pub missing: u64,
    /// Their pages.
    pub missing_pages: Vec<u32>,
    candidates: Vec<ClusterRef>,
    nodes: Vec<u32>,
}

impl Nearby {
    /// Gathers the triangles of the full-detail clusters that overlap `query`, and where one of
    /// their pages is not resident, of `cut`'s clusters there (the buffer is cleared first; a
    /// cluster listed twice counts once). `page` gives a resident page, or `None`. The cut is
    /// only read when a page is missing: walking through resident geometry costs the skeleton's
    /// few nodes around the walker, not a pass over the cut.
    pub fn gather<'a>(
        &mut self,
        store: &Store,
        query: &Aabb,
        cut: impl IntoIterator<Item = &'a ClusterRef>,
        mut page: impl FnMut(u32) -> Option<Arc<ResidentPage>>,
    ) {
        self.triangles.clear();
        self.clusters.clear();
        self.missing = 0;
        self.missing_pages.clear();
        self.candidates.clear();
        self.full_detail(store, query);
        self.add_candidates(store, query, &mut page);
        if self.missing == 0 {
            return;
        }
        let groups = store.groups();
        let (done, candidates) = (&self.clusters, &mut self.candidates);
        candidates.clear();
        candidates.extend(cut.into_iter().filter(|r| {
            groups.get(r.group as usize).is_some_and(|g| sphere_overlaps(g.sphere, query))
                && done.binary_search(r).is_err()
        }));
        self.add_candidates(store, query, &mut page);
        self.clusters.sort_unstable();
    }

    /// Adds the triangles of the candidate clusters that overlap `query`; counts and lists the
    /// candidates whose page is not resident.
    fn add_candidates(
        &mut self,
        store: &Store,
        query: &Aabb,
        page: &mut impl FnMut(u32) -> Option<Arc<ResidentPage>>,
    ) {
        self.candidates.sort_unstable();
        self.candidates.dedup();
        let step = store.header().grid_step;
        let mut held: Option<(u32, Arc<ResidentPage>)> = None;
        for r in &self.candidates {
            if held.as_ref().is_none_or(|(p, _)| *p != r.page) {
                held = page(r.page).map(|p| (r.page, p));
            }
            let Some((_, p)) = held.as_ref().filter(|(p, _)| *p == r.page) else {
                self.missing += 1;
                if self.missing_pages.last() != Some(&r.page) {
                    self.missing_pages.push(r.page);
                }
                continue;
            };
            let i = r.index_in_page as usize;
            let (Some(c), Some(&(lo, hi))) = (p.clusters.get(i), p.bounds.get(i)) else { continue };
            let b = Aabb { lo: lo.map(|g| scene(g, step)), hi: hi.map(|g| scene(g, step)) };
            if !b.overlaps(query) {
                continue;
            }
            let before = self.triangles.len();
            for tri in c.indices.chunks_exact(3) {
                let Some(t) = corners(&c.positions, tri, step) else { continue };
                if Aabb::of_triangle(&t).overlaps(query) {
                    self.triangles.push(t);
                }
            }
            if self.triangles.len() > before {
                self.clusters.push(*r);
            }
        }
    }

    /// Adds the level-0 clusters whose group sphere reaches `query` to the candidates: down the
    /// skeleton through the nodes whose box reaches it (a child's box lies in its parent's).
    fn full_detail(&mut self, store: &Store, query: &Aabb) {
        let (nodes, groups) = (store.nodes(), store.groups());
        let step = store.header().grid_step;
        self.nodes.clear();
        if !nodes.is_empty() {
            self.nodes.push(0);
        }
        while let Some(n) = self.nodes.pop() {
            let Some(node) = nodes.get(n as usize) else { continue };
            let b = Aabb { lo: node.min.map(|g| scene(g, step)), hi: node.max.map(|g| scene(g, step)) };
            if !b.grow(pad(&b)).overlaps(query) {
                continue;
            }
            let children = node.first_child..node.first_child.saturating_add(node.child_count);
            self.nodes.extend(children.filter(|&c| c > n && (c as usize) < nodes.len()));
            let first = node.first_group as usize;
            let end = first.saturating_add(node.group_count as usize).min(groups.len());
            for (g, group) in groups.iter().enumerate().take(end).skip(first) {
                if group.level == 0 && sphere_overlaps(group.sphere, query) {
                    self.candidates.extend((0..group.cluster_count).map(|i| ClusterRef {
                        page: group.page,
                        index_in_page: group.first_cluster.saturating_add(i),
                        group: g as u32,
                    }));
                }
            }
        }
    }
}

/// A box's padding against the rounding of grid coordinates to f32 (relative 2⁻²⁰).
fn pad(b: &Aabb) -> f32 {
    b.lo.iter().chain(&b.hi).fold(0.0f32, |m, v| m.max(v.abs())) * 2f32.powi(-20)
}

/// A grid coordinate in scene space (as the renderers place vertices).
fn scene(g: u32, step: f64) -> f32 {
    (g as f64 * step) as f32
}

/// The scene-space corners of triangle `tri` (local indices), `None` for an index beyond the
/// cluster's vertices (a damaged page is not a panic).
fn corners(positions: &[[u32; 3]], tri: &[u8], step: f64) -> Option<Triangle> {
    let p = |i: u8| positions.get(i as usize).map(|g| g.map(|c| scene(c, step)));
    Some([p(tri[0])?, p(tri[1])?, p(tri[2])?])
}

/// Whether the sphere `[x, y, z, r]` reaches the box (padded by a relative 2⁻²⁰ against the
/// rounding of sphere and box).
fn sphere_overlaps(s: [f32; 4], b: &Aabb) -> bool {
    let mut d2 = 0.0f64;
    for ((&c, &lo), &hi) in s.iter().zip(&b.lo).zip(&b.hi) {
        let (c, lo, hi) = (c as f64, lo as f64, hi as f64);
        let e = if c < lo {
            lo - c
        } else if c > hi {
            c - hi
        } else {
            0.0
        };
        d2 += e * e;
    }
    let r = s[3] as f64 * (1.0 + 2f64.powi(-20)) + 1e-6 * (s[0].abs().max(s[1].abs()).max(s[2].abs()) as f64);
    d2 <= r * r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spheres_against_boxes() {
        let b = Aabb { lo: [0.0; 3], hi: [1.0; 3] };
        assert!(sphere_overlaps([0.5, 0.5, 0.5, 0.1], &b));
        assert!(sphere_overlaps([2.0, 0.5, 0.5, 1.0], &b));
        assert!(!sphere_overlaps([2.0, 2.0, 0.5, 1.0], &b), "corner distance √2 > 1");
        assert!(sphere_overlaps([2.0, 2.0, 0.5, 1.5], &b));
    }

    #[test]
    fn a_bad_index_is_skipped_not_a_panic() {
        assert!(corners(&[[0, 0, 0]], &[0, 0, 3], 1.0).is_none());
        assert_eq!(corners(&[[0, 0, 0], [2, 0, 0]], &[0, 1, 0], 0.5).unwrap()[1], [1.0, 0.0, 0.0]);
    }
}
