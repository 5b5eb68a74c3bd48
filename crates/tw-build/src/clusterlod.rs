//! The build loop of a cell's cluster DAG: Nanite's (Karis 2021), as meshoptimizer's clusterlod
//! (`demo/clusterlod.h`) runs it, with pruning of small disconnected parts so that the DAG keeps
//! reducing on assemblies of many small parts.
//!
//! The loop, as in clusterlod: the mesh is split into clusters; while more than one cluster is
//! left, the clusters are partitioned into groups of about [`DagConfig::partition_size`]
//! (meshopt's partitioner: shared vertices, then spatial closeness), every vertex used by two
//! groups is locked, and each group is simplified to [`DagConfig::ratio`] of its triangles and
//! split into new clusters for the next round. A group that keeps more than
//! [`DagConfig::threshold`] of its triangles is *terminal* (its error is `f32::MAX`; HLOD,
//! `crate::hlod`, takes its clusters further).
//!
//! **Why a loop of our own.** clusterlod's simplification step is fixed inside its C++ loop, and
//! assemblies of many small disconnected parts (pins, screws, SMD parts, in one object) need two
//! things from it that it does not do:
//!
//! 1. *Removal of whole parts.* When a group's parts are closed and already at their few
//!    triangles (a 12-triangle box cannot be simplified without collapsing it), the simplifier
//!    stops above the target and the group becomes terminal. Here, whole *free* parts (no locked
//!    vertex: the part is entirely inside the group) are then removed, smallest first, until the
//!    group is at its target; free parts whose radius is within the error the simplifier reached
//!    anyway are removed too (they cost nothing). meshopt's own `Prune` option ignores locks (a
//!    part cut by a group border would lose one half: a crack), so it is not used.
//! 2. *Errors that bound what vanished.* The error of a removed part is the radius of the input
//!    part it is made of (half its box diagonal at level 0): every one of that part's input
//!    points lies within that distance of its centre, so a part whose radius projects below τ
//!    pixels covers less than a τ-pixel disc, the deviation the cut allows anywhere else. The
//!    input part's, not the current one's: the simplifier may have shrunk it at a quadric error
//!    that reads less than the shrinking. A part the simplifier collapsed to nothing counts the
//!    same way (a collapsed box reads less than its size). The group's error is the largest of
//!    the simplifier's and those radii. To keep parts from vanishing at a collapse's error in
//!    the first place, one triangle of every free part is locked while the group is
//!    simplified, so that parts go only by removal, smallest first. The price of the bound,
//!    measured on the 10^7 plant's 90-frame path: 534 k triangles in the median cut and 39.3 dB
//!    worst PSNR, against 351 k and 38.4 dB when collapsed parts keep meshopt's estimate
//!    (docs/benchmarks-log.md, "Assemblies", 2026-12-06).
//! 3. *Errors that grow step by step.* Reaching the target at any error made a group's error
//!    jump: to halve a group of small parts, parts up to the median size had to go, and the
//!    largest of them set the error of the whole group, ten times its clusters' (the overview
//!    of the 24 M assembly drew 3.4 M triangles from groups whose next step was 8–16 times
//!    coarser). So a group is first simplified within a limit of 2, then 4, then 8 times its
//!    clusters' largest error, removing free parts up to the limit, and the first try that
//!    keeps at most 60 % of the triangles ([`DagConfig::accept`]) is kept; only a group that no
//!    try reduces enough is simplified to its target at any error, as before. With this rule and
//!    the two below, the 24 M assembly's overview cut fell from 3.98 M to 1.44 M triangles, at
//!    1.85× the input over all levels instead of 1.83×. Keeping tries that remove only a fifth
//!    gave 1.34 M, but 2.29× on the KiCad boards, whose levels then shrink too slowly
//!    (docs/benchmarks-log.md, "Assemblies", session 26).
//!
//! Parts with an *anchored* vertex (shared with another group of the round, frozen, or on a
//! seam with another cell) are never removed, so the group's border, and a cell's seams, stay as
//! they were: the cut stays crack-free. A vertex on a tangled edge (non-manifold, inconsistently
//! wound) is locked for the simplifier but anchors nothing: a part whose only locks are its own
//! tangled edges lies wholly inside the group and is removed whole like any other (on the 24 M
//! assembly, where touching boxes weld into non-manifold edges, 2.6 M kept triangles were such
//! parts). A group whose output would be empty keeps its largest part whole (clusterlod keeps
//! one triangle, whose edges would be open).
//!
//! **Locks.** As in clusterlod, a vertex used by two groups of a round is locked for that round.
//! Unlike clusterlod, a vertex of a terminal group's clusters stays locked in every later round:
//! those clusters are never replaced, so a later group that moved (or removed) a vertex it shares
//! with them would open a crack between the two (clusterlod forgets such locks after the round;
//! with pruning, the other half of a part cut by a terminal group would be removed whole).
//!
//! Deterministic: every step is (meshopt's simplifier, clusterizer and partitioner are), and ties
//! among parts go to the first triangle.

use crate::union_find::UnionFind;
use meshopt::{SimplifyOptions, SimplifyVertex, VertexDataAdapter};

/// Parameters of [`build_dag`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct DagConfig {
    /// Most triangles per cluster (≤ 256; the store's clusters take ≤ 128).
    pub max_triangles: usize,
    /// Most vertices per cluster.
    pub max_vertices: usize,
    /// Clusters per group (the partitioner's target; groups may be up to a third larger).
    pub partition_size: usize,
    /// Each group is simplified to this fraction of its triangles.
    pub ratio: f32,
    /// A group that keeps more than this fraction of its triangles is terminal.
    pub threshold: f32,
    /// Error limits tried first, as multiples of the group's largest cluster error.
    pub growth: [f32; 3],
    /// A try within a limit is kept when it keeps at most this fraction of the triangles.
    pub accept: f32,
}

impl DagConfig {
    /// clusterlod's defaults (partition size 16, ratio ½, threshold 0.85) for clusters of
    /// `max_triangles` and `max_vertices`, and the error ladder of rule 3 (module comment):
    /// limits of 2, 4 and 8 times the group's cluster error, a try kept when it keeps at most 60 %
    /// of the triangles.
    pub fn new(max_triangles: usize, max_vertices: usize) -> DagConfig {
        DagConfig {
            max_triangles,
            max_vertices,
            partition_size: 16,
            ratio: 0.5,
            threshold: 0.85,
            growth: [2.0, 4.0, 8.0],
            accept: 0.6,
        }
    }
}

/// Bounds in the units of the positions: a sphere and, for a group, its simplification error.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct DagBounds {
    pub center: [f32; 3],
    pub radius: f32,
    /// For a group: the error of its own simplification against its clusters (`f32::MAX`:
    /// terminal). For a cluster: the error of the group it was simplified from (0 at level 0).
    pub error: f32,
}

/// One cluster as [`build_dag`] hands it out.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct DagCluster<'a> {
    /// Triangles, as indices into the mesh's vertices.
    pub indices: &'a [u32],
    /// Exact bounds at level 0; the bounds of the group it was simplified from above.
    pub bounds: DagBounds,
    /// The id (as returned by the output callback) of the group it was simplified from; −1 for
    /// the input's clusters.
    pub refined: i32,
}

/// What [`build_dag`] did, for the build report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct DagStats {
    /// Groups simplified (not terminal).
    pub groups: usize,
    /// Terminal groups (stuck, or the last cluster).
    pub terminal: usize,
    /// Triangles removed as whole parts by rule 2 (module comment).
    pub pruned_triangles: usize,
}

/// A cluster inside the loop: a range of `indices`, its bounds and its source group.
#[derive(Clone, Copy, Debug)]
struct Cluster {
    offset: usize,
    count: usize,
    refined: i32,
    bounds: DagBounds,
}

/// Builds the DAG of `indices` over `positions`. `vertex_lock` (one per vertex) marks vertices
/// that must never move (seams with other cells, tangled edges); `anchor` (one per vertex) marks
/// those of them where the surface goes on outside the mesh (the seams): a part with one is
/// never removed, while a part that is only tangled is still removed whole (module comment,
/// "Locks"). `output(group, clusters)` is
/// called for every group, in an order where a cluster's source group always comes first, with
/// the group's bounds and the clusters it replaces; it returns the group's id, which the
/// clusters simplified from it carry in [`DagCluster::refined`].
pub(crate) fn build_dag(
    config: &DagConfig,
    positions: &[[f32; 3]],
    indices: &[u32],
    vertex_lock: &[SimplifyVertex],
    anchor: &[bool],
    mut output: impl FnMut(DagBounds, &[DagCluster<'_>]) -> i32,
) -> DagStats {
    let vertices = crate::lod::adapter(positions);
    let input_radius = input_part_radius(positions, indices);
    let mut stats = DagStats::default();
    let mut cluster_indices: Vec<u32> = Vec::new();
    let mut clusters: Vec<Cluster> = Vec::new();
    clusterize(&mut clusters, &mut cluster_indices, config, &vertices, indices, -1);
    for c in &mut clusters {
        let b = meshopt::compute_cluster_bounds(&cluster_indices[c.offset..c.offset + c.count], &vertices);
        c.bounds = DagBounds { center: b.center, radius: b.radius, error: 0.0 };
    }
    let mut emit = |group: &[Cluster], all: &[u32], bounds: DagBounds| {
        let members: Vec<DagCluster<'_>> = group
            .iter()
            .map(|c| DagCluster {
                indices: &all[c.offset..c.offset + c.count],
                bounds: c.bounds,
                refined: c.refined,
            })
            .collect();
        output(bounds, &members)
    };

    let mut locks = vec![SimplifyVertex::None; positions.len()];
    let mut anchored = vec![false; positions.len()];
    let mut last_group = vec![u32::MAX; positions.len()];
    // Vertices of terminal groups' clusters: those clusters stay in every cut above them, so
    // their vertices stay where they are for good (module comment, "Locks").
    let mut frozen = vec![false; positions.len()];
    while clusters.len() > 1 {
        let offsets = partition(&mut clusters, &cluster_indices, config, &vertices);
        lock_group_borders(
            &mut locks,
            &mut anchored,
            &mut last_group,
            &clusters,
            &offsets,
            &cluster_indices,
            (vertex_lock, anchor),
            &frozen,
        );
        let mut pending: Vec<Cluster> = Vec::new();
        let mut pending_indices: Vec<u32> = Vec::new();
        for range in offsets.windows(2) {
            let group = &clusters[range[0]..range[1]];
            let merged: Vec<u32> = group
                .iter()
                .flat_map(|c| cluster_indices[c.offset..c.offset + c.count].iter().copied())
                .collect();
            let target = ((merged.len() / 3) as f32 * config.ratio) as usize;
            let mut bounds = merge_bounds(group);
            let (simplified, error) = simplify_group(
                &vertices,
                &merged,
                &mut locks,
                (&anchored, &input_radius),
                target,
                bounds.error,
                config,
                &mut stats,
            );
            if simplified.len() as f32 > merged.len() as f32 * config.threshold {
                bounds.error = f32::MAX;
                stats.terminal += 1;
                for &v in &merged {
                    frozen[v as usize] = true;
                }
                emit(group, &cluster_indices, bounds);
                continue;
            }
            stats.groups += 1;
            bounds.error = error;
            let refined = emit(group, &cluster_indices, bounds);
            let first = pending.len();
            clusterize(&mut pending, &mut pending_indices, config, &vertices, &simplified, refined);
            for c in &mut pending[first..] {
                c.bounds = bounds;
            }
        }
        clusters = pending;
        cluster_indices = pending_indices;
    }
    if let [last] = clusters[..] {
        stats.terminal += 1;
        emit(&[last], &cluster_indices, DagBounds { error: f32::MAX, ..last.bounds });
    }
    stats
}

/// Splits `indices` into clusters with meshopt's spatial clusterizer (fill weight 1: full
/// clusters) and level-0 in-cluster reordering, appended to `clusters` (`refined` as given).
fn clusterize(
    clusters: &mut Vec<Cluster>,
    cluster_indices: &mut Vec<u32>,
    config: &DagConfig,
    vertices: &VertexDataAdapter<'_>,
    indices: &[u32],
    refined: i32,
) {
    let min_triangles = (config.max_triangles / 3).max(1);
    let mut meshlets = meshopt::build_meshlets_spatial(
        indices,
        vertices,
        config.max_vertices,
        min_triangles,
        config.max_triangles,
        1.0,
    );
    for m in &meshlets.meshlets {
        let (v0, vn) = (m.vertex_offset as usize, m.vertex_count as usize);
        let (t0, tn) = (m.triangle_offset as usize, m.triangle_count as usize * 3);
        meshopt::optimize_meshlet_level(
            &mut meshlets.vertices[v0..v0 + vn],
            &mut meshlets.triangles[t0..t0 + tn],
            0,
        );
        let offset = cluster_indices.len();
        let (verts, tris) = (&meshlets.vertices[v0..v0 + vn], &meshlets.triangles[t0..t0 + tn]);
        cluster_indices.extend(tris.iter().map(|&t| verts[t as usize]));
        clusters.push(Cluster { offset, count: tn, refined, bounds: DagBounds::default() });
    }
}

/// Partitions the clusters into groups (reordering `clusters` so that each group is contiguous)
/// and returns the groups' offsets (one more than there are groups).
fn partition(
    clusters: &mut Vec<Cluster>,
    cluster_indices: &[u32],
    config: &DagConfig,
    vertices: &VertexDataAdapter<'_>,
) -> Vec<usize> {
    if clusters.len() <= config.partition_size {
        return vec![0, clusters.len()];
    }
    let counts: Vec<u32> = clusters.iter().map(|c| c.count as u32).collect();
    let flat: Vec<u32> =
        clusters.iter().flat_map(|c| cluster_indices[c.offset..c.offset + c.count].iter().copied()).collect();
    let mut part = vec![0u32; clusters.len()];
    let parts = meshopt::partition_clusters_with_positions(
        &mut part,
        &flat,
        &counts,
        vertices,
        config.partition_size,
    );
    let mut offsets = vec![0usize; parts + 1];
    for &p in &part {
        offsets[p as usize + 1] += 1;
    }
    for i in 1..offsets.len() {
        offsets[i] += offsets[i - 1];
    }
    let mut write = offsets.clone();
    let mut sorted = clusters.clone();
    for (c, &p) in clusters.iter().zip(&part) {
        sorted[write[p as usize]] = *c;
        write[p as usize] += 1;
    }
    *clusters = sorted;
    offsets
}

/// Locks every vertex used by two groups, every `frozen` one, and every one the caller's
/// `vertex_lock` locks; marks in `anchored` those of them that tie a part to something outside
/// its group (all but the caller's locks that are not `anchor`s: tangled edges).
#[allow(clippy::too_many_arguments)]
fn lock_group_borders(
    locks: &mut [SimplifyVertex],
    anchored: &mut [bool],
    last_group: &mut [u32],
    clusters: &[Cluster],
    offsets: &[usize],
    cluster_indices: &[u32],
    (vertex_lock, anchor): (&[SimplifyVertex], &[bool]),
    frozen: &[bool],
) {
    let mut shared = vec![false; locks.len()];
    last_group.fill(u32::MAX);
    for (g, range) in offsets.windows(2).enumerate() {
        for c in &clusters[range[0]..range[1]] {
            for &v in &cluster_indices[c.offset..c.offset + c.count] {
                let last = &mut last_group[v as usize];
                if *last != u32::MAX && *last != g as u32 {
                    shared[v as usize] = true;
                }
                *last = g as u32;
            }
        }
    }
    for (v, (lock, anchored)) in locks.iter_mut().zip(anchored.iter_mut()).enumerate() {
        let fixed = vertex_lock.get(v).copied().unwrap_or(SimplifyVertex::None);
        *anchored = shared[v] || frozen[v] || anchor.get(v).copied().unwrap_or(false);
        *lock = if shared[v] || frozen[v] { SimplifyVertex::Lock } else { fixed };
    }
}

/// The merged sphere of the clusters (centre of their boxes, radius reaching every sphere) and
/// their largest error. Conservative, deterministic.
fn merge_bounds(clusters: &[Cluster]) -> DagBounds {
    let mut lo = [f32::MAX; 3];
    let mut hi = [f32::MIN; 3];
    for c in clusters {
        for i in 0..3 {
            lo[i] = lo[i].min(c.bounds.center[i] - c.bounds.radius);
            hi[i] = hi[i].max(c.bounds.center[i] + c.bounds.radius);
        }
    }
    let center: [f32; 3] = std::array::from_fn(|i| 0.5 * (lo[i] + hi[i]));
    let radius = clusters
        .iter()
        .map(|c| {
            let d2: f64 = (0..3).map(|i| (c.bounds.center[i] as f64 - center[i] as f64).powi(2)).sum();
            (d2.sqrt() + c.bounds.radius as f64) as f32
        })
        .fold(0.0f32, f32::max);
    let error = clusters.iter().map(|c| c.bounds.error).fold(0.0f32, f32::max);
    DagBounds { center, radius: radius.next_up(), error }
}

/// Simplifies one group to about `target` triangles with its locks; returns the triangles and
/// the error (module comment for the rules on parts). `locks` is restored before returning.
#[allow(clippy::too_many_arguments)]
fn simplify_group(
    vertices: &VertexDataAdapter<'_>,
    merged: &[u32],
    locks: &mut [SimplifyVertex],
    (anchored, input_radius): (&[bool], &[f32]),
    target: usize,
    child_error: f32,
    config: &DagConfig,
    stats: &mut DagStats,
) -> (Vec<u32>, f32) {
    let parts = Parts::new(merged, anchored, input_radius);
    let accept = (merged.len() / 3) as f32 * config.accept;
    if child_error > 0.0 {
        for growth in config.growth {
            let limit = child_error * growth;
            let (out, error, removed) = simplify_parts(&parts, vertices, merged, locks, target, limit);
            if (out.len() / 3) as f32 <= accept {
                stats.pruned_triangles += removed;
                return (out, error);
            }
        }
    }
    let (out, error, removed) = simplify_parts(&parts, vertices, merged, locks, target, f32::MAX);
    stats.pruned_triangles += removed;
    (out, error)
}

/// One try of [`simplify_group`]: simplification within `limit` and removal of free parts of
/// radius ≤ `limit`. Returns the triangles, the error and the triangles removed as parts.
fn simplify_parts(
    parts: &Parts,
    vertices: &VertexDataAdapter<'_>,
    merged: &[u32],
    locks: &mut [SimplifyVertex],
    target: usize,
    limit: f32,
) -> (Vec<u32>, f32, usize) {
    // The simplifier may reduce a free part but not make it vanish (one of its triangles is
    // locked): parts go only by `prune_free`, smallest first, each charged its radius. Left to
    // itself, the simplifier collapses whole parts wherever that is cheapest in its quadric
    // measure, whatever their size.
    let pinned: Vec<u32> = parts.first_triangles(merged);
    let saved: Vec<SimplifyVertex> = pinned.iter().map(|&v| locks[v as usize]).collect();
    for &v in &pinned {
        locks[v as usize] = SimplifyVertex::Lock;
    }
    let options = SimplifyOptions::Sparse | SimplifyOptions::ErrorAbsolute | SimplifyOptions::Permissive;
    let mut error = 0.0f32;
    let mut out =
        meshopt::simplify_with_locks(merged, vertices, locks, target * 3, limit, options, Some(&mut error));
    for (&v, &l) in pinned.iter().zip(&saved).rev() {
        locks[v as usize] = l;
    }
    if out.is_empty() {
        // A group never vanishes (its DAG would lose a leaf): its largest part stays whole, so
        // that no open edge appears (clusterlod keeps one triangle, whose edges would be open).
        parts.restore_largest(merged, &mut out);
    }
    let count = parts.count(&out);
    // A part the simplifier collapsed away is gone as if it had been removed: its radius bounds
    // the error there (meshopt's quadric error is an estimate, lower on a collapsed part).
    error = error.max(parts.vanished_radius(&count));
    let (removed, radius) = parts.prune_free(&mut out, &count, target, error, limit);
    (out, error.max(radius), removed)
}

/// Per vertex: the radius (half the box diagonal) of the connected part of the input triangles
/// it belongs to; 0 for a vertex on no triangle. Simplification only moves vertices onto
/// others of their part, so a part of any level is made of one input part, and that part's
/// radius bounds the distance of each of its input points from its centre, however the part
/// was simplified before (the simplifier's error is a quadric estimate: a part it shrank would
/// read smaller than what it stands for).
fn input_part_radius(positions: &[[f32; 3]], indices: &[u32]) -> Vec<f32> {
    let mut parts = UnionFind::new(positions.len());
    parts.union_triangles(indices, |v| v);
    let mut lo = vec![[f32::MAX; 3]; positions.len()];
    let mut hi = vec![[f32::MIN; 3]; positions.len()];
    for &v in indices {
        let root = parts.find(v) as usize;
        let q = positions[v as usize];
        for i in 0..3 {
            lo[root][i] = lo[root][i].min(q[i]);
            hi[root][i] = hi[root][i].max(q[i]);
        }
    }
    let mut radius = vec![0.0f32; positions.len()];
    for &v in indices {
        let root = parts.find(v) as usize;
        let d2: f64 = (0..3).map(|i| (hi[root][i] as f64 - lo[root][i] as f64).powi(2)).sum();
        radius[v as usize] = crate::lod::round_up(d2.sqrt() * 0.5);
    }
    radius
}

/// The connected parts of a group's input triangles: per part, its bounding radius and whether
/// it has a locked vertex.
struct Parts {
    /// The group's vertices, numbered densely in order of first use.
    local: rustc_hash::FxHashMap<u32, u32>,
    /// Per local vertex: its part.
    part_of: Vec<u32>,
    /// Per part: the radius of the input part it is made of ([`input_part_radius`]), whether a
    /// vertex is anchored, its first triangle.
    radius: Vec<f32>,
    locked: Vec<bool>,
    first: Vec<usize>,
}

impl Parts {
    fn new(merged: &[u32], anchored: &[bool], input_radius: &[f32]) -> Parts {
        // Union-find over the group's vertices, numbered densely in order of first use.
        let mut local: rustc_hash::FxHashMap<u32, u32> = rustc_hash::FxHashMap::default();
        for &v in merged {
            let next = local.len() as u32;
            local.entry(v).or_insert(next);
        }
        let mut parts = UnionFind::new(local.len());
        parts.union_triangles(merged, |v| local[&v]);
        let mut number = vec![u32::MAX; local.len()];
        let mut radius: Vec<f32> = Vec::new();
        let mut locked: Vec<bool> = Vec::new();
        let mut first: Vec<usize> = Vec::new();
        for (ti, t) in merged.chunks_exact(3).enumerate() {
            let root = parts.find(local[&t[0]]) as usize;
            if number[root] == u32::MAX {
                number[root] = radius.len() as u32;
                radius.push(0.0);
                locked.push(false);
                first.push(ti);
            }
            let p = number[root] as usize;
            for &v in t {
                radius[p] = radius[p].max(input_radius[v as usize]);
                locked[p] |= anchored[v as usize];
            }
        }
        // Every vertex is on a triangle, so every root has its number.
        let part_of = (0..local.len() as u32).map(|i| number[parts.find(i) as usize]).collect();
        Parts { local, part_of, radius, locked, first }
    }

    fn part(&self, v: u32) -> usize {
        self.local.get(&v).map_or(usize::MAX, |&i| self.part_of[i as usize] as usize)
    }

    /// The vertices of the first triangle of every free part (in part order; repeats possible).
    fn first_triangles(&self, merged: &[u32]) -> Vec<u32> {
        (0..self.first.len())
            .filter(|&p| !self.locked[p])
            .flat_map(|p| merged[self.first[p] * 3..self.first[p] * 3 + 3].iter().copied())
            .collect()
    }

    /// Triangles of `out` per part.
    fn count(&self, out: &[u32]) -> Vec<usize> {
        let mut count = vec![0usize; self.radius.len()];
        for t in out.chunks_exact(3) {
            if let Some(c) = count.get_mut(self.part(t[0])) {
                *c += 1;
            }
        }
        count
    }

    /// The largest radius of the parts with no triangle left (`count` from [`Parts::count`]).
    fn vanished_radius(&self, count: &[usize]) -> f32 {
        count.iter().zip(&self.radius).filter(|(&c, _)| c == 0).map(|(_, &r)| r).fold(0.0, f32::max)
    }

    /// Puts back the input triangles of the part with the largest radius (ties: the first).
    fn restore_largest(&self, merged: &[u32], out: &mut Vec<u32>) {
        let largest =
            (0..self.radius.len()).reduce(|a, b| if self.radius[b] > self.radius[a] { b } else { a });
        if let Some(largest) = largest {
            out.extend(merged.chunks_exact(3).filter(|t| self.part(t[0]) == largest).flatten());
        }
    }

    /// Removes whole free parts from `out`, smallest radius first (ties: first triangle), until
    /// at most `target` triangles are left, never the last part (rule 2). Returns the triangles
    /// removed and the largest removed radius.
    fn prune_free(
        &self,
        out: &mut Vec<u32>,
        count: &[usize],
        target: usize,
        free_below: f32,
        limit: f32,
    ) -> (usize, f32) {
        let mut order: Vec<usize> = (0..count.len()).filter(|&p| count[p] > 0 && !self.locked[p]).collect();
        order.sort_by(|&a, &b| {
            self.radius[a].total_cmp(&self.radius[b]).then(self.first[a].cmp(&self.first[b]))
        });
        let mut left = out.len() / 3;
        let mut remove = vec![false; count.len()];
        let mut radius = 0.0f32;
        for p in order {
            if (left <= target && self.radius[p] > free_below) || left == count[p] || self.radius[p] > limit {
                break;
            }
            left -= count[p];
            remove[p] = true;
            radius = radius.max(self.radius[p]);
        }
        let before = out.len() / 3;
        let kept: Vec<u32> = out
            .chunks_exact(3)
            .filter(|t| !remove.get(self.part(t[0])).copied().unwrap_or(false))
            .flatten()
            .copied()
            .collect();
        *out = kept;
        (before - out.len() / 3, radius)
    }
}
