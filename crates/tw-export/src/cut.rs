//! Choosing the clusters to export: a cut of the store's cluster DAG.
//!
//! - [`camera_cut`]: what `render` draws — [`tw_runtime::Selector::select`] for a camera, pixel
//!   error and viewport, frustum culling on.
//! - [`object_space_cut`]: the cut at an object-space error `ε` (scene units) of the part of the
//!   DAG below one skeleton node, optionally only clusters that reach into a box. This is the
//!   render rule of docs/FORMAT.md with the projection left out: a cluster is in the cut when
//!   `self_error ≤ ε < group.error`. For a node `N` other than the root, the groups attached to
//!   `N` that are simplified at `N`'s parent (no parent group at `N`) count as roots (error +∞):
//!   the sub-DAG below `N` is closed under sources (a group's sources hang at its node or its
//!   children), so this is a complete, crack-free cut of `N`'s geometry. `ε = 0` gives full
//!   detail; `ε = +∞` the coarsest clusters of the part.
//!
//! Clusters are returned sorted by page, so that [`crate::emit`] decodes each page once.

use tw_runtime::{Camera, ClusterRef, PageCache, SelectOptions, Selector};
use tw_store::Store;

use crate::error::ExportError;
use crate::frame::grid_to_input;

/// Chosen clusters, by page.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Cut {
    pub clusters: Vec<ClusterRef>,
    /// Triangles of the chosen clusters.
    pub triangles: u64,
    /// The largest `self_error` among them (scene units): the cut's object-space error
    /// ([`object_space_cut`] only; 0 for a camera's cut).
    pub error: f32,
    /// Whether some chosen cluster belongs to a group attached to the cut's node itself (not
    /// to a descendant); [`object_space_cut`] only.
    pub own: bool,
}

/// The clusters `render` draws for `camera` (see the module documentation).
pub fn camera_cut(store: &Store, cache: &PageCache, camera: &Camera, options: &SelectOptions) -> Cut {
    let selection = Selector::new(store).select(store, cache, camera, options);
    let mut clusters = selection.clusters;
    clusters.sort_unstable();
    Cut { clusters, triangles: selection.triangles, error: 0.0, own: false }
}

/// Per-node data of the skeleton, computed once from the tables.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    /// Largest group error in each node's subtree.
    pub subtree_error: Vec<f32>,
    /// Full-detail triangles (groups without sources) in each node's subtree.
    pub subtree_triangles: Vec<u64>,
    /// Smallest `self_error` of each group's clusters: 0 for full-detail groups, else the
    /// smallest error of its sources (a step's clusters carry its input groups' error).
    pub group_min_self_error: Vec<f32>,
}

impl Hierarchy {
    pub fn new(store: &Store) -> Hierarchy {
        let nodes = store.nodes();
        let groups = store.groups();
        let group_min_self_error = (0..groups.len() as u32)
            .map(|g| {
                let sources = store.group_sources(g);
                sources
                    .iter()
                    .filter_map(|&s| groups.get(s as usize))
                    .map(|s| s.error)
                    .fold(if sources.is_empty() { 0.0 } else { f32::INFINITY }, f32::min)
            })
            .collect();
        let mut subtree_error = vec![0f32; nodes.len()];
        let mut subtree_triangles = vec![0u64; nodes.len()];
        // Children have larger indices than their parent (checked when the store is opened).
        for i in (0..nodes.len()).rev() {
            let n = &nodes[i];
            let own = groups.get(n.first_group as usize..(n.first_group + n.group_count) as usize);
            for (k, g) in own.unwrap_or_default().iter().enumerate() {
                subtree_error[i] = subtree_error[i].max(g.error);
                if store.group_sources(n.first_group + k as u32).is_empty() {
                    subtree_triangles[i] += g.triangles as u64;
                }
            }
            for c in n.first_child as usize..(n.first_child + n.child_count) as usize {
                if c > i && c < nodes.len() {
                    subtree_error[i] = subtree_error[i].max(subtree_error[c]);
                    subtree_triangles[i] += subtree_triangles[c];
                }
            }
        }
        Hierarchy { subtree_error, subtree_triangles, group_min_self_error }
    }
}

/// A box in input coordinates (inclusive).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Region {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl Region {
    /// Parses `minx,miny,minz,maxx,maxy,maxz`; the box must be finite and not inverted.
    pub fn parse(s: &str) -> Result<Region, ExportError> {
        let err = |why: &str| ExportError::Invalid(format!("region {s:?}: {why}"));
        let v: Vec<f64> = s
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| err(&format!("{e} (expected minx,miny,minz,maxx,maxy,maxz)")))?;
        let [a, b, c, d, e, f] = v[..] else {
            return Err(err(&format!("{} numbers, expected 6: minx,miny,minz,maxx,maxy,maxz", v.len())));
        };
        if !v.iter().all(|x| x.is_finite()) {
            return Err(err("not finite"));
        }
        if a > d || b > e || c > f {
            return Err(err("a minimum is above its maximum"));
        }
        Ok(Region { min: [a, b, c], max: [d, e, f] })
    }

    pub fn contains(&self, p: [f64; 3]) -> bool {
        (0..3).all(|a| self.min[a] <= p[a] && p[a] <= self.max[a])
    }

    /// Whether the grid box `lo..=hi` of the store overlaps the region.
    pub fn overlaps_grid_box(&self, store: &Store, lo: [u32; 3], hi: [u32; 3]) -> bool {
        let lo = grid_to_input(store.header(), lo);
        let hi = grid_to_input(store.header(), hi);
        (0..3).all(|a| lo[a] <= self.max[a] && self.min[a] <= hi[a])
    }
}

/// The cut at object-space error `eps` of the sub-DAG below `node` (module documentation),
/// restricted to clusters whose box overlaps `region` when one is given.
pub fn object_space_cut(
    store: &Store,
    cache: &PageCache,
    hierarchy: &Hierarchy,
    node: u32,
    eps: f32,
    region: Option<&Region>,
) -> Result<Cut, ExportError> {
    let nodes = store.nodes();
    let groups = store.groups();
    let mut cut = Cut::default();
    let mut stack = vec![node];
    while let Some(m) = stack.pop() {
        let Some(n) = nodes.get(m as usize) else { continue };
        if region.is_some_and(|r| !r.overlaps_grid_box(store, n.min, n.max)) {
            continue;
        }
        // Below `node`, a subtree whose every group is replaced holds nothing of the cut.
        if m != node && hierarchy.subtree_error.get(m as usize).is_none_or(|&e| e <= eps) {
            continue;
        }
        for g in n.first_group..n.first_group + n.group_count {
            let Some(group) = groups.get(g as usize) else { continue };
            let replaced_at_node = m != node
                || store
                    .group_parents(g)
                    .iter()
                    .any(|&p| groups.get(p as usize).is_some_and(|p| p.node == node));
            if group.error <= eps && replaced_at_node {
                continue;
            }
            if hierarchy.group_min_self_error.get(g as usize).is_none_or(|&e| e > eps) {
                continue;
            }
            let page = cache
                .get(store, group.page)
                .map_err(|e| ExportError::Store { store: store.path().to_path_buf(), source: e })?;
            for k in group.first_cluster..group.first_cluster + group.cluster_count {
                let (Some(c), Some(&(lo, hi))) = (page.clusters.get(k as usize), page.bounds.get(k as usize))
                else {
                    continue;
                };
                if c.self_error > eps || region.is_some_and(|r| !r.overlaps_grid_box(store, lo, hi)) {
                    continue;
                }
                cut.clusters.push(ClusterRef { page: group.page, index_in_page: k, group: g });
                cut.triangles += c.triangle_count() as u64;
                cut.error = cut.error.max(c.self_error);
                cut.own |= m == node;
            }
        }
        // Children in reverse, so that they are visited in index order.
        for c in (n.first_child..n.first_child + n.child_count).rev() {
            if c > m {
                stack.push(c);
            }
        }
    }
    cut.clusters.sort_unstable();
    Ok(cut)
}

/// The selection options `render` uses for `tau` and a viewport.
pub fn render_options(tau: f32, viewport: [u32; 2]) -> SelectOptions {
    SelectOptions { tau, viewport, frustum_culling: true, ..Default::default() }
}
