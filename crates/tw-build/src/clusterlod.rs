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
//! assemblies of many small disconnected parts (pins, screws, SMD parts, in one object) need more
//! from it than it does:
//!
//! 1. *Removal of whole parts.* When a group's parts are closed and already at their few
//!    triangles (a 12-triangle box cannot be simplified without collapsing it), the simplifier
//!    stops above the target and the group becomes terminal. Here, whole parts are then removed,
//!    smallest bound first, until the group is at its target; parts whose bound is within the
//!    error the simplifier reached anyway are removed too (they cost nothing). meshopt's own
//!    `Prune` option ignores locks and charges nothing for what it removes, so it is not used.
//! 2. *Errors that bound what vanished.* A removed part is charged how far the input points it
//!    stands for lie from a set with no area: the radius of the input part it is made of (half
//!    its box diagonal: every point lies within it of the centre), or, when smaller, the
//!    largest distance of that input part's vertices from its principal axis, a line
//!    ([`input_parts`]). Removing the part is collapsing it onto that point or line, a
//!    deviation the cut allows anywhere else, and a part narrower than τ pixels covers no more
//!    than a τ-pixel band. The line matters on real assemblies: pins, rails, pipes, cable trays
//!    and beams are far thinner than they are long, and the radius charged them their length
//!    (measured: the 24 M assembly's overview cut 1.44 M → 0.60 M triangles, the 10^7 plant's
//!    fly-over 790 k → 393 k; docs/benchmarks-log.md, "Assemblies", session 27). The input
//!    part's bound, not the current one's: the simplifier may have shrunk it at a quadric error
//!    that reads less than the shrinking. A part the simplifier collapsed to nothing counts the
//!    same way (a collapsed box reads less than its size). The group's error is the largest of
//!    the simplifier's and those bounds. To keep parts from vanishing at a collapse's error in
//!    the first place, one triangle of every free part is locked while the group is
//!    simplified, so that parts go only by removal, smallest first. The price of charging
//!    collapsed parts, measured on the 10^7 plant's 90-frame path: 534 k triangles in the median
//!    cut and 39.3 dB worst PSNR, against 351 k and 38.4 dB when collapsed parts keep meshopt's
//!    estimate (docs/benchmarks-log.md, "Assemblies", 2026-12-06).
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
//! 4. *Thin parts across borders.* A *rod* (an input part far longer than thick,
//!    `crate::part_shape`) with an *anchored* vertex (shared with another group of the round,
//!    frozen, or on a seam with another cell) is removed like a free part, charged the same
//!    bound. Its other half, across the border, may stay in a cut beside the coarser level:
//!    what opens there is the rod's own cross-section, within the bound of the line it
//!    collapses onto, so the gap is no wider than the rod, which the cut already allows to
//!    vanish (a pipe thinner than τ pixels may be missing; its open end is as thin). Cracks
//!    elsewhere stay closed: an anchored part that is no rod is never removed, and what is
//!    kept keeps its locked border. Locking seams and group borders for good held the plant's
//!    pipes, cut by cell planes into pieces, at full section up to the top of the hierarchy:
//!    HLOD nodes whose every triangle touched a seam, and levels that shrank by a tenth
//!    instead of a half (docs/benchmarks-log.md, "Thin parts across seams", session 34).
//!    The cut checks allow such openings, and only where the missing input lies within twice
//!    the cut's error of a line (`crate::cut::ThinPieces`).
//!
//! A vertex on a tangled edge (non-manifold, inconsistently wound) is locked for the simplifier
//! but anchors nothing: a part whose only locks are its own tangled edges lies wholly inside the
//! group and is free (on the 24 M assembly, where touching boxes weld into non-manifold edges,
//! 2.6 M kept triangles were such parts). A group whose output would be empty keeps its largest
//! part whole (clusterlod keeps one triangle, whose edges would be open).
//!
//! **Locks.** As in clusterlod, a vertex used by two groups of a round is locked for that round.
//! Unlike clusterlod, a vertex of a terminal group's clusters stays locked in every later round:
//! those clusters are never replaced, so a later group that moved a vertex it shares with them
//! would open a crack between the two (clusterlod forgets such locks after the round). Such a
//! vertex anchors its part: the part goes only whole, under rule 4.
//!
//! Deterministic: every step is (meshopt's simplifier, clusterizer and partitioner are), and ties
//! among parts go to the first triangle.

use crate::part_shape::part_shapes;
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
    /// Simplifier runs (a group takes one per try of [`DagConfig::growth`], plus the last).
    pub tries: usize,
    /// Triangles fed to the simplifier over all tries.
    pub tried_triangles: usize,
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
    let input = input_parts(positions, indices);
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
    let mut part_table = PartTable::new(positions.len());
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
                &mut part_table,
                (&anchored, &input),
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
///
/// The reordering is the one `meshopt::build_meshlets_spatial` already applies to every meshlet
/// (`meshopt_optimizeMeshlet`, which is level 0); running `optimize_meshlet_level(.., 0)` on its
/// output again changed nothing (level 0 is idempotent) and was 4–5 % of a build's time.
/// `spatial_clusters_come_reordered_at_level_0` checks that the wrapper keeps doing it.
fn clusterize(
    clusters: &mut Vec<Cluster>,
    cluster_indices: &mut Vec<u32>,
    config: &DagConfig,
    vertices: &VertexDataAdapter<'_>,
    indices: &[u32],
    refined: i32,
) {
    let min_triangles = (config.max_triangles / 3).max(1);
    let meshlets = meshopt::build_meshlets_spatial(
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
/// the error (module comment for the rules on parts). The tries within `config.growth` times
/// `child_error` come first (none for the input's clusters, whose error is 0); the first that
/// keeps at most `config.accept` of the triangles is taken, else a try at any error (rule 3).
/// `locks` is restored before returning.
#[allow(clippy::too_many_arguments)]
fn simplify_group(
    vertices: &VertexDataAdapter<'_>,
    merged: &[u32],
    locks: &mut [SimplifyVertex],
    part_table: &mut PartTable,
    (anchored, input): (&[bool], &[InputPart]),
    target: usize,
    child_error: f32,
    config: &DagConfig,
    stats: &mut DagStats,
) -> (Vec<u32>, f32) {
    let parts = Parts::new(part_table, merged, anchored, input);
    let accept = (merged.len() / 3) as f32 * config.accept;
    let limits = config.growth.iter().filter(|_| child_error > 0.0).map(|g| child_error * g);
    let mut kept = None;
    for limit in limits {
        stats.tries += 1;
        stats.tried_triangles += merged.len() / 3;
        let tried = simplify_parts(&parts, vertices, merged, locks, target, limit);
        if (tried.0.len() / 3) as f32 <= accept {
            kept = Some(tried);
            break;
        }
    }
    let (out, error, removed) = kept.unwrap_or_else(|| {
        stats.tries += 1;
        stats.tried_triangles += merged.len() / 3;
        simplify_parts(&parts, vertices, merged, locks, target, f32::MAX)
    });
    stats.pruned_triangles += removed;
    (out, error)
}

/// One try of [`simplify_group`]: simplification within `limit` and removal of free parts of
/// bound ≤ `limit`. Returns the triangles, the error and the triangles removed as parts.
fn simplify_parts(
    parts: &Parts<'_>,
    vertices: &VertexDataAdapter<'_>,
    merged: &[u32],
    locks: &mut [SimplifyVertex],
    target: usize,
    limit: f32,
) -> (Vec<u32>, f32, usize) {
    // The simplifier may reduce a free part but not make it vanish (one of its triangles is
    // locked): parts go only by `Parts::prune`, smallest first, each charged its bound. Left to
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
    // A part the simplifier collapsed away is gone as if it had been removed: its bound holds
    // the error there (meshopt's quadric error is an estimate, lower on a collapsed part).
    error = error.max(parts.vanished_radius(&count));
    let (removed, radius) = parts.prune(&mut out, &count, target, error, limit);
    (out, error.max(radius), removed)
}

/// What a part charges when it goes, and whether it may go across a border.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct InputPart {
    /// The input part's [`PartShape::bound`](crate::part_shape::PartShape::bound), rounded up.
    bound: f32,
    /// Whether the input part is a rod
    /// ([`PartShape::is_rod`](crate::part_shape::PartShape::is_rod)): it may go where it
    /// continues across a group border or a cell seam (rule 4).
    rod: bool,
}

/// Per vertex: the [`InputPart`] of the connected input part it belongs to (the default for a
/// vertex on no triangle). Removing a part is collapsing it onto its centre or its axis, so
/// its bound bounds the deviation (module comment, rule 2). Simplification only moves
/// vertices onto others of their part, so a part of any level is made of one input part, and
/// the bound holds however the part was simplified before (the simplifier's error is a quadric
/// estimate: a part it shrank would read smaller than what it stands for).
///
/// Walks the used vertices, not the indices (a vertex is on about six triangles).
fn input_parts(positions: &[[f32; 3]], indices: &[u32]) -> Vec<InputPart> {
    let mut union = UnionFind::new(positions.len());
    union.union_triangles(indices, |v| v);
    let mut used = vec![false; positions.len()];
    for &v in indices {
        used[v as usize] = true;
    }
    // Dense part numbers, in order of each part's smallest vertex.
    let mut part = vec![u32::MAX; positions.len()];
    let mut count = 0u32;
    for v in (0..positions.len()).filter(|&v| used[v]) {
        let root = union.find(v as u32) as usize;
        if part[root] == u32::MAX {
            part[root] = count;
            count += 1;
        }
        part[v] = part[root];
    }
    let shapes = part_shapes(count as usize, || {
        (0..positions.len()).filter(|&v| used[v]).map(|v| (part[v] as usize, positions[v], false))
    });
    let parts: Vec<InputPart> = shapes
        .iter()
        .map(|s| InputPart { bound: crate::lod::round_up(s.bound()), rod: s.is_rod() })
        .collect();
    part.iter().map(|&p| parts.get(p as usize).copied().unwrap_or_default()).collect()
}

/// Per vertex of the mesh: its part in the group being simplified (`u32::MAX`: not in the
/// group). One table for the whole DAG, filled for a group's vertices by [`Parts::new`] and
/// cleared for them when the [`Parts`] is dropped, so a group costs its own size: a hash map
/// per group (vertex → dense id) was 6 % of a build's time on the 10 M assembly.
struct PartTable {
    part: Vec<u32>,
}

impl PartTable {
    fn new(vertices: usize) -> PartTable {
        PartTable { part: vec![u32::MAX; vertices] }
    }
}

/// The connected parts of a group's input triangles: per part, its bound, whether it has an
/// anchored vertex and whether it is a rod. Parts are numbered in order of their first triangle.
struct Parts<'a> {
    /// Per vertex of the mesh: its part (the group's vertices), `u32::MAX` (the others).
    table: &'a mut PartTable,
    /// The group's vertices, in order of first use (the entries of `table` to clear).
    vertices: Vec<u32>,
    /// Per part: the bound of the input part it is made of ([`input_parts`]), whether a
    /// vertex is anchored, whether that input part is a rod, its first triangle.
    radius: Vec<f32>,
    locked: Vec<bool>,
    rod: Vec<bool>,
    first: Vec<usize>,
}

impl<'a> Parts<'a> {
    /// `table` must be clear (all `u32::MAX`) for the vertices of `merged`; it is again once
    /// the returned value is dropped.
    fn new(table: &'a mut PartTable, merged: &[u32], anchored: &[bool], input: &[InputPart]) -> Parts<'a> {
        // Union-find over the group's vertices, numbered densely in order of first use (the
        // table holds the dense number until the parts are known).
        let mut vertices: Vec<u32> = Vec::new();
        for &v in merged {
            let slot = &mut table.part[v as usize];
            if *slot == u32::MAX {
                *slot = vertices.len() as u32;
                vertices.push(v);
            }
        }
        let local = &table.part;
        let mut parts = UnionFind::new(vertices.len());
        parts.union_triangles(merged, |v| local[v as usize]);
        let mut number = vec![u32::MAX; vertices.len()];
        let mut radius: Vec<f32> = Vec::new();
        let mut locked: Vec<bool> = Vec::new();
        let mut rod: Vec<bool> = Vec::new();
        let mut first: Vec<usize> = Vec::new();
        for (ti, t) in merged.chunks_exact(3).enumerate() {
            let root = parts.find(local[t[0] as usize]) as usize;
            if number[root] == u32::MAX {
                number[root] = radius.len() as u32;
                radius.push(0.0);
                locked.push(false);
                rod.push(true);
                first.push(ti);
            }
        }
        // Every vertex is on a triangle, so every root has its number. A part's bound, lock and
        // shape are those of its vertices, each looked at once (not once per corner).
        for (i, &v) in vertices.iter().enumerate() {
            let p = number[parts.find(i as u32) as usize];
            table.part[v as usize] = p;
            radius[p as usize] = radius[p as usize].max(input[v as usize].bound);
            locked[p as usize] |= anchored[v as usize];
            rod[p as usize] &= input[v as usize].rod;
        }
        Parts { table, vertices, radius, locked, rod, first }
    }

    fn part(&self, v: u32) -> usize {
        match self.table.part.get(v as usize) {
            Some(&p) if p != u32::MAX => p as usize,
            _ => usize::MAX,
        }
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

    /// Puts back the input triangles of the part with the largest bound (ties: the first).
    fn restore_largest(&self, merged: &[u32], out: &mut Vec<u32>) {
        let largest =
            (0..self.radius.len()).reduce(|a, b| if self.radius[b] > self.radius[a] { b } else { a });
        if let Some(largest) = largest {
            out.extend(merged.chunks_exact(3).filter(|t| self.part(t[0]) == largest).flatten());
        }
    }

    /// Removes whole parts from `out`, free ones and anchored rods (rule 4), smallest bound
    /// first (ties: first triangle), until at most `target` triangles are left, never the last
    /// part (rule 2). Returns the triangles removed and the largest removed bound.
    fn prune(
        &self,
        out: &mut Vec<u32>,
        count: &[usize],
        target: usize,
        free_below: f32,
        limit: f32,
    ) -> (usize, f32) {
        let mut order: Vec<usize> =
            (0..count.len()).filter(|&p| count[p] > 0 && (!self.locked[p] || self.rod[p])).collect();
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

impl Drop for Parts<'_> {
    /// Clears the group's entries of the table for the next group.
    fn drop(&mut self) {
        for &v in &self.vertices {
            self.table.part[v as usize] = u32::MAX;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An `n`×`n` grid of unit quads in the plane z = 0, two triangles each.
    fn grid_mesh(n: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
        let positions = (0..=n).flat_map(|y| (0..=n).map(move |x| [x as f32, y as f32, 0.0])).collect();
        let v = move |x: u32, y: u32| y * (n + 1) + x;
        let indices = (0..n)
            .flat_map(|y| {
                (0..n).flat_map(move |x| {
                    [v(x, y), v(x + 1, y), v(x + 1, y + 1), v(x, y), v(x + 1, y + 1), v(x, y + 1)]
                })
            })
            .collect();
        (positions, indices)
    }

    #[test]
    fn spatial_clusters_come_reordered_at_level_0() {
        // `clusterize` takes the clusters in the order meshopt's wrapper leaves them: reordered
        // at level 0. Reordering them again must change nothing.
        let (positions, indices) = grid_mesh(64);
        let vertices = crate::lod::adapter(&positions);
        let config = DagConfig::new(crate::lod::MAX_CLUSTER_TRIANGLES, crate::lod::MAX_CLUSTER_VERTICES);
        let meshlets = meshopt::build_meshlets_spatial(
            &indices,
            &vertices,
            config.max_vertices,
            (config.max_triangles / 3).max(1),
            config.max_triangles,
            1.0,
        );
        assert!(meshlets.meshlets.len() >= 16, "{} clusters", meshlets.meshlets.len());
        let mut shuffled_moved = false;
        for m in &meshlets.meshlets {
            let (v0, vn) = (m.vertex_offset as usize, m.vertex_count as usize);
            let (t0, tn) = (m.triangle_offset as usize, m.triangle_count as usize * 3);
            let (verts, tris) = (&meshlets.vertices[v0..v0 + vn], &meshlets.triangles[t0..t0 + tn]);
            let (mut again_verts, mut again_tris) = (verts.to_vec(), tris.to_vec());
            meshopt::optimize_meshlet_level(&mut again_verts, &mut again_tris, 0);
            assert_eq!((&again_verts[..], &again_tris[..]), (verts, tris));
            // The check has teeth: the reordering does move triangles that are not in its order
            // (the even ones first, then the odd ones).
            let mut shuffled: Vec<u8> = tris.chunks_exact(3).step_by(2).flatten().copied().collect();
            shuffled.extend(tris.chunks_exact(3).skip(1).step_by(2).flatten());
            let (mut moved_verts, mut moved_tris) = (verts.to_vec(), shuffled.clone());
            meshopt::optimize_meshlet_level(&mut moved_verts, &mut moved_tris, 0);
            shuffled_moved |= moved_tris != shuffled;
        }
        assert!(shuffled_moved);
    }

    /// The 12 triangles of the box from `lo` to `hi`, its corners appended to `positions`.
    fn push_box(positions: &mut Vec<[f32; 3]>, indices: &mut Vec<u32>, lo: [f32; 3], hi: [f32; 3]) {
        let base = positions.len() as u32;
        positions
            .extend((0..8).map(|k| std::array::from_fn(|i| if k >> i & 1 == 1 { hi[i] } else { lo[i] })));
        for [a, b, c, d] in
            [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
        {
            indices.extend([a, b, c, a, c, d].map(|k| base + k));
        }
    }

    #[test]
    fn a_part_is_charged_its_distance_from_a_point_or_a_line() {
        // A 10×1×1 beam, far from the origin (the moments keep their digits), a 2×2×2 cube, and
        // a vertex on no triangle.
        let (mut positions, mut indices) = (Vec::new(), Vec::new());
        push_box(&mut positions, &mut indices, [1e6, 2e6, 3e6], [1e6 + 10.0, 2e6 + 1.0, 3e6 + 1.0]);
        push_box(&mut positions, &mut indices, [0.0; 3], [2.0; 3]);
        positions.push([5.0; 3]);
        let parts = input_parts(&positions, &indices);
        let bound: Vec<f32> = parts.iter().map(|p| p.bound).collect();
        // The beam: half its cross-section's diagonal from its axis, not half its length; it
        // is 5 / 0.71 = 7 times longer than thick, a rod.
        let beam = 0.5f32.hypot(0.5);
        assert!(bound[..8].iter().all(|&b| (b - beam).abs() < 1e-3), "{:?}", &bound[..8]);
        assert!(parts[..8].iter().all(|p| p.rod));
        // The cube: no line is better than its centre by much; the x axis through the centre
        // gives √2, less than the radius √3. No rod.
        assert!(bound[8..16].iter().all(|&b| (b - 2f32.sqrt()).abs() < 1e-4), "{:?}", &bound[8..16]);
        assert!(parts[8..16].iter().all(|p| !p.rod));
        assert_eq!(parts[16], InputPart::default(), "a vertex on no triangle");
    }

    #[test]
    fn parts_are_numbered_by_first_triangle_and_leave_the_table_clear() {
        // Part A (vertices 10–13) has triangles 0 and 2, part B (20–22, 21 anchored) triangle 1.
        let merged = [10, 11, 12, 20, 21, 22, 12, 11, 13];
        let mut anchored = vec![false; 30];
        anchored[21] = true;
        let input: Vec<InputPart> =
            (0..30).map(|v| InputPart { bound: if v >= 20 { 2.0 } else { 1.0 }, rod: v >= 20 }).collect();
        let mut table = PartTable::new(30);
        {
            let parts = Parts::new(&mut table, &merged, &anchored, &input);
            assert_eq!((parts.part(13), parts.part(22), parts.part(5)), (0, 1, usize::MAX));
            assert_eq!(parts.radius, [1.0, 2.0]);
            assert_eq!(parts.locked, [false, true]);
            assert_eq!(parts.rod, [false, true]);
            assert_eq!(parts.first, [0, 1]);
            assert_eq!(parts.count(&[13, 12, 11, 20, 21, 22, 10, 11, 12]), [2, 1]);
            assert_eq!(parts.first_triangles(&merged), [10, 11, 12], "the free part's first triangle");
        }
        assert!(table.part.iter().all(|&p| p == u32::MAX), "cleared for the next group");
        // The next group sees only its own vertices.
        let parts = Parts::new(&mut table, &[20, 21, 22], &anchored, &input);
        assert_eq!((parts.part(20), parts.part(10)), (0, usize::MAX));
    }
}
