//! Clustering: Felzenszwalb–Huttenlocher segmentation of the k-nearest-neighbour graph of the
//! pieces, with GigaWalk's volume limit and a minimum cluster size (see the parent module).

use rayon::prelude::*;

use super::pieces::Pieces;
use super::{geometry::Scale, RedefineParams, RedefineReport};
use crate::hierarchy::Hierarchy;
use crate::types::GridBox;

/// The clusters: each a list of pieces.
pub(super) struct Clusters {
    /// Members of cluster `c`: `members[start[c]..start[c + 1]]`, in piece order.
    pub(super) members: Vec<u32>,
    pub(super) start: Vec<usize>,
}

/// Squared distance between two boxes, in grid steps².
fn box_d2(a: &GridBox, b: &GridBox) -> u64 {
    (0..3)
        .map(|i| {
            let gap = b.min[i].saturating_sub(a.max[i]).max(a.min[i].saturating_sub(b.max[i])) as u64;
            gap * gap
        })
        .sum()
}

/// The `k` nearest boxes to `boxes[i]` within squared distance `r2` (ties by index).
pub(super) fn nearest(
    h: &Hierarchy,
    boxes: &[GridBox],
    i: usize,
    k: usize,
    r2: u64,
    stack: &mut Vec<u32>,
) -> Vec<(u64, u32)> {
    let mut best: Vec<(u64, u32)> = Vec::with_capacity(k + 1);
    if k == 0 || h.nodes.is_empty() {
        return best;
    }
    let me = &boxes[i];
    stack.clear();
    stack.push(0);
    while let Some(n) = stack.pop() {
        let node = &h.nodes[n as usize];
        let d2 = box_d2(me, &node.bounds);
        let limit = if best.len() == k { best[k - 1].0 } else { r2 };
        if d2 > limit {
            continue;
        }
        match node.cell {
            Some(j) if j as usize != i => {
                let cand = (d2, j);
                if best.len() < k || cand < best[k - 1] {
                    let at = best.partition_point(|b| *b < cand);
                    best.insert(at, cand);
                    best.truncate(k);
                }
            }
            Some(_) => {}
            None => stack.extend(node.children().map(|c| c as u32)),
        }
    }
    best
}

/// Felzenszwalb–Huttenlocher over the non-empty pieces.
pub(super) fn cluster_pieces(
    p: &RedefineParams,
    scale: &Scale,
    pieces: &Pieces,
    report: &mut RedefineReport,
) -> Clusters {
    let nodes: Vec<u32> = (0..pieces.count.len() as u32).filter(|&q| pieces.count[q as usize] > 0).collect();
    report.pieces = nodes.len() as u64;
    let boxes: Vec<GridBox> = nodes.iter().map(|&q| pieces.grid[q as usize]).collect();
    let edges = neighbour_edges(p, scale, &boxes);
    report.edges = edges.len() as u64;
    let tris = nodes.iter().map(|&q| pieces.count[q as usize]).collect();
    let mut components = Components::new(tris, boxes);
    // Main pass (FH), then FH's post-pass: components under `min_cell_triangles` join their
    // nearest neighbour whatever K says, within `max_cell_triangles` and 2 V.
    components.merge(p, scale, &edges, false);
    if p.min_cell_triangles > 0 {
        components.merge(p, scale, &edges, true);
    }
    let clusters = components.number(&nodes, pieces.count.len());
    report.clusters = (clusters.start.len() - 1) as u64;
    clusters
}

/// The graph's edges `(squared box distance, a, b)`, `a < b`, by ascending weight: every node
/// joined to its `neighbours` nearest within `D` (boxes in grid steps).
fn neighbour_edges(p: &RedefineParams, scale: &Scale, boxes: &[GridBox]) -> Vec<(u64, u32, u32)> {
    let tree = Hierarchy::build(boxes);
    let dg = scale.d / scale.step;
    let r2 = if dg * dg >= 1e18 { u64::MAX / 4 } else { (dg * dg).floor() as u64 };
    let near: Vec<Vec<(u64, u32)>> = (0..boxes.len())
        .into_par_iter()
        .map_init(Vec::new, |stack, i| nearest(&tree, boxes, i, p.neighbours, r2, stack))
        .collect();
    let mut edges: Vec<(u64, u32, u32)> = Vec::with_capacity(near.iter().map(Vec::len).sum());
    for (i, list) in near.into_iter().enumerate() {
        let i = i as u32;
        edges.extend(list.into_iter().map(|(d2, j)| (d2, i.min(j), i.max(j))));
    }
    edges.par_sort_unstable();
    edges.dedup();
    edges
}

/// The components while they merge: union-find with each root's triangles, largest internal
/// MST edge `I(C)` and box.
struct Components {
    parent: Vec<u32>,
    tris: Vec<u64>,
    internal: Vec<f64>,
    bounds: Vec<GridBox>,
}

impl Components {
    /// Every node its own component.
    fn new(tris: Vec<u64>, bounds: Vec<GridBox>) -> Components {
        let n = tris.len();
        Components { parent: (0..n as u32).collect(), tris, internal: vec![0.0; n], bounds }
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let g = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = g;
            x = g;
        }
        x
    }

    /// One pass over the edges in order, merging the components each joins when allowed: by
    /// FH's criterion and `V` (`small_pass` false), or when one of them is under
    /// `min_cell_triangles`, within 2 `V` (`small_pass` true); never beyond
    /// `max_cell_triangles`.
    fn merge(&mut self, p: &RedefineParams, scale: &Scale, edges: &[(u64, u32, u32)], small_pass: bool) {
        for &(d2, a, b) in edges {
            let (ra, rb) = (self.find(a), self.find(b));
            if ra == rb {
                continue;
            }
            let (ua, ub) = (ra as usize, rb as usize);
            let (ta, tb) = (self.tris[ua], self.tris[ub]);
            if ta + tb > p.max_cell_triangles {
                continue;
            }
            let w = if scale.d > 0.0 { (d2 as f64).sqrt() * scale.step / scale.d } else { 0.0 };
            let volume_limit = if small_pass {
                if ta >= p.min_cell_triangles && tb >= p.min_cell_triangles {
                    continue;
                }
                2.0 * scale.v
            } else {
                let threshold_a = self.internal[ua] + p.k / ta as f64;
                let threshold_b = self.internal[ub] + p.k / tb as f64;
                if w > threshold_a.min(threshold_b) {
                    continue;
                }
                scale.v
            };
            let merged = self.bounds[ua].union(&self.bounds[ub]);
            if scale.volume(&merged) > volume_limit {
                continue;
            }
            let (root, child) = if (tb, ua) > (ta, ub) { (ub, ua) } else { (ua, ub) };
            self.parent[child] = root as u32;
            self.tris[root] = ta + tb;
            self.internal[root] = self.internal[ua].max(self.internal[ub]).max(w);
            self.bounds[root] = merged;
        }
    }

    /// The clusters, numbered in order of their first piece (`nodes[i]` is node `i`'s piece, of
    /// `n_pieces`).
    fn number(&mut self, nodes: &[u32], n_pieces: usize) -> Clusters {
        let n = nodes.len();
        let mut id_of_root = vec![u32::MAX; n];
        let mut of_piece = vec![u32::MAX; n_pieces];
        let mut sizes: Vec<usize> = Vec::new();
        for i in 0..n {
            let r = self.find(i as u32) as usize;
            if id_of_root[r] == u32::MAX {
                id_of_root[r] = sizes.len() as u32;
                sizes.push(0);
            }
            of_piece[nodes[i] as usize] = id_of_root[r];
            sizes[id_of_root[r] as usize] += 1;
        }
        let mut start = Vec::with_capacity(sizes.len() + 1);
        start.push(0);
        for s in &sizes {
            start.push(start.last().copied().unwrap_or(0) + s);
        }
        let mut fill = start.clone();
        let mut members = vec![0u32; n];
        for &q in nodes {
            let c = of_piece[q as usize] as usize;
            members[fill[c]] = q;
            fill[c] += 1;
        }
        Clusters { members, start }
    }
}
