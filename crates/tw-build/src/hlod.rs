//! Phase 4b: HLOD above the cells — merging the coarsest clusters of sibling subtrees.
//!
//! Extends the cluster DAG of [`crate::lod`] across the hierarchy (Nanite-style cluster DAG,
//! Erikson's HLOD; docs/FORMAT.md, "Model"). The hierarchy is processed bottom-up; each
//! subtree is represented only by its current [`Roots`] (its root groups, error = ∞, and their
//! clusters). At a node, [`build_hlod`]:
//!
//! 1. merges the children's root clusters into one indexed mesh (vertices deduplicated by grid
//!    position);
//! 2. simplifies it across object and cell borders to `min(ratio × triangles, max_node_triangles)`
//!    triangles with meshopt's regular simplifier (small disconnected parts may be pruned; object
//!    borders and borders between the children are free), falling back to `simplify_sloppy`
//!    (error × 2, as clusterlod does) when the regular simplifier stalls above the target. Only
//!    the seams shared with cells outside the node (split objects) are locked, so that a cut that
//!    is coarse here and finer next door does not crack. Every result is checked (see
//!    `broken_edges`): each seam edge still open, used by one triangle (not lost, not folded
//!    into a double-sided pair, which would unlock it one level up), and no new boundary edge
//!    but along an object border (meshopt's topology rules are per directed half-edge, and
//!    the double-sided and non-manifold parts left by earlier levels fool them; the sloppy
//!    simplifier has none), and the surface area grown by at most 1 % (`MAX_AREA_GROWTH`:
//!    simplifying shrinks a curved surface, while a fold or a bridge over the gap between
//!    disjoint parts grows it; unchecked, 24 of the 40 sloppy results on the 10^7 plant grew it,
//!    up to 8.9×). A result that fails is simplified again with the neighbourhood of
//!    the broken edges locked (a few rounds), else the node keeps its merged mesh. If the result
//!    is still above the target, whole connected parts are dropped, smallest bound first
//!    (`prune_components`; the error grows to the largest dropped bound: the part's radius
//!    or its distance from its axis). Rods on a seam with a cell outside the node go too:
//!    the seam then opens across the rod's own section, no wider than the bound (rule 4 of
//!    `crate::clusterlod`). Before, a stalled node kept mostly the fans around those seams:
//!    on the 10^7 plant, 453 of 1,040 nodes ended above 1.5× their target with nearly every
//!    triangle on a seam vertex, the pieces of pipes that cell planes cut;
//! 3. splits the result into clusters (≤ 128 triangles, ≤ 255 vertices; meshopt's spatial
//!    clusterizer, as in the cells) and groups them.
//!
//! All of the children's root groups are replaced by the node's clusters as one simplification
//! step: they get the same finite `error` (= the new clusters' `self_error` = the largest child
//! cluster `self_error` plus this simplification's own error, as in [`crate::lod`]) and the
//! same `sphere` (= the new clusters' `self_sphere`, containing every child root group's
//! sphere). The caller applies that to its stored groups
//! ([`HlodNode::replaced`]). The node's new groups are roots until the parent node is built.
//!
//! Memory: a node holds only its children's roots, so a bottom-up pass needs
//! O(depth × fanout × root size). Triangles of a node's roots are at most `max_node_triangles`.
//!
//! Object ids of simplified triangles follow the rule of [`crate::lod`] (the object of a vertex's
//! first incident triangle in the merged mesh, majority of the three vertices).

use crate::lod::{
    accumulate, adapter, grow_sphere, round_up, sphere_center64, triangle_object, vertex_objects, Frame,
    MAX_CLUSTER_TRIANGLES, MAX_CLUSTER_VERTICES, MIN_ERROR,
};
use crate::part_shape::part_shapes;
use crate::types::{Grid, LodCluster, LodDag, LodGroup, Sphere};
use meshopt::{SimplifyOptions, VertexDataAdapter};

/// Most simplifications of one node, each locking more vertices around the edges the last broke.
const REPAIR_ROUNDS: usize = 8;

/// Most a result's surface area may exceed the merged input's (a fold or a bridge over a gap
/// grows it; simplifying a curved surface shrinks it).
const MAX_AREA_GROWTH: f64 = 1.01;

/// Parameters of `build_hlod`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HlodParams {
    /// Target triangles of a node relative to its children's root triangles.
    pub ratio: f32,
    /// Most triangles a node may keep (so the tree's root ends with a few clusters).
    pub max_node_triangles: usize,
    /// Triangles per cluster, 4..=128.
    pub max_triangles: usize,
    /// Vertices per cluster, 3..=255.
    pub max_vertices: usize,
    /// Most clusters per new group.
    pub group_clusters: usize,
}

impl Default for HlodParams {
    fn default() -> HlodParams {
        HlodParams {
            ratio: 0.5,
            max_node_triangles: 1024,
            max_triangles: MAX_CLUSTER_TRIANGLES,
            max_vertices: MAX_CLUSTER_VERTICES,
            group_clusters: 16,
        }
    }
}

/// The current top of a subtree: its root groups (error = ∞) and their clusters.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Roots {
    /// Only root groups; clusters' `group` indexes `dag.groups`.
    pub dag: LodDag,
    /// The id each group of `dag.groups` goes by: in the pipeline a provisional one
    /// (`crate::provisional`), resolved to the scene's when the node is emitted.
    pub group_ids: Vec<u32>,
}

impl Roots {
    /// Every vertex position of the roots' clusters (repeats included).
    pub fn positions(&self) -> impl Iterator<Item = [u32; 3]> + '_ {
        self.dag.clusters.iter().flat_map(|c| c.positions.iter().copied())
    }

    #[cfg(test)]
    pub fn triangle_count(&self) -> usize {
        self.dag.clusters.iter().map(|c| c.indices.len() / 3).sum()
    }
}

/// The roots of `dag` (its groups with infinite error); `group_base` is the caller's id of
/// `dag.groups[0]` (ids are `group_base + index`).
pub fn roots_of(dag: &LodDag, group_base: u32) -> Roots {
    let mut roots = Roots::default();
    for (gi, g) in dag.groups.iter().enumerate() {
        if g.error != f32::INFINITY {
            continue;
        }
        let new_g = roots.dag.groups.len() as u32;
        let mut members = Vec::with_capacity(g.clusters.len());
        for &ci in &g.clusters {
            if let Some(c) = dag.clusters.get(ci as usize) {
                members.push(roots.dag.clusters.len() as u32);
                roots.dag.clusters.push(LodCluster { group: new_g, ..c.clone() });
            }
        }
        roots.dag.groups.push(LodGroup { clusters: members, ..g.clone() });
        roots.group_ids.push(group_base + gi as u32);
    }
    roots
}

/// What [`build_hlod`] made at one node.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HlodNode {
    /// The node's clusters and groups; the groups are roots (error = ∞). The clusters'
    /// `refined_from` holds the caller's ids of the replaced groups (`replaced`).
    pub dag: LodDag,
    /// The children's root groups (caller's ids) that the node's clusters replace.
    pub replaced: Vec<u32>,
    /// The error and sphere to give every replaced group.
    pub error: f32,
    pub sphere: Sphere,
    /// How the simplification went (for the build's counters and logs).
    pub stats: HlodStats,
}

/// How one node's simplification went.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum HlodOutcome {
    /// Nothing to simplify (no triangles, or already at or below the target).
    #[default]
    Unchanged,
    /// The regular simplifier's result (within 1/8 of the target or not), checked.
    Regular,
    /// The sloppy simplifier's result, checked.
    Sloppy,
    /// Every result broke an edge: the merged mesh itself.
    Merged,
}

/// Triangles in and out of one node, and how they were reduced.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HlodStats {
    pub triangles_in: usize,
    pub target: usize,
    pub triangles_out: usize,
    pub outcome: HlodOutcome,
    /// Simplification rounds run (each repair round is one).
    pub rounds: usize,
    /// Triangles of the whole parts dropped after simplification (`prune_components`).
    pub pruned: usize,
    /// The node's error and the largest child cluster error (scene units).
    pub error: f32,
    pub child_error: f32,
    /// Surface area of the result ÷ that of the merged input (1 when unchanged). Simplifying a
    /// curved closed surface shrinks it; a fold (a part turned over onto itself) grows it.
    pub area_ratio: f32,
}

#[cfg(test)]
impl HlodNode {
    /// The node's roots, for its parent; `group_base` is the caller's id of `dag.groups[0]`.
    pub fn roots(&self, group_base: u32) -> Roots {
        roots_of(&self.dag, group_base)
    }
}

/// Builds the HLOD clusters of one hierarchy node from its children's roots. Deterministic.
///
/// `external(p)` tells whether grid point `p` is shared with a cell outside this node's subtree
/// (the pipeline knows each seam position's first and last cell; `seam_positions` is the
/// conservative scene-wide set); such vertices on the merged mesh's open edges are locked, so that a
/// cut that is coarse here and fine in a neighbouring subtree does not crack. Everything else,
/// open object borders included, may be simplified.
pub fn build_hlod(
    children: &[Roots],
    grid: &Grid,
    params: &HlodParams,
    external: &dyn Fn([u32; 3]) -> bool,
) -> HlodNode {
    // 1. Merge.
    let Merged { positions, indices, objects, child_error, level, replaced, sphere } =
        merge_children(children);
    if indices.is_empty() {
        let error = child_error.max(MIN_ERROR);
        let stats = HlodStats { error, child_error, ..HlodStats::default() };
        return HlodNode { dag: LodDag::default(), replaced, error, sphere, stats };
    }

    // 2. Simplify across borders.
    let frame = Frame::new(&positions, grid);
    let local = frame.local_positions(&positions);
    let vertices = adapter(&local);
    let tri_count = indices.len() / 3;
    let target = ((tri_count as f64 * params.ratio.clamp(0.0, 1.0) as f64).ceil() as usize)
        .min(params.max_node_triangles)
        .max(1);
    let locks: Vec<bool> = crate::lod::open_boundary_vertices(positions.len(), &indices)
        .into_iter()
        .zip(&positions)
        .map(|(open, &p)| open && external(p))
        .collect();
    let input = SimplifyInput {
        indices: &indices,
        local: &local,
        vertices: &vertices,
        locks: &locks,
        target,
        check: EdgeCheck::new(positions.len(), &indices, &locks),
        area_in: mesh_area(&local, &indices),
    };
    let s = if target < tri_count { input.simplify() } else { Simplified::unchanged(&indices) };
    // Accumulated from the input, as in the cells (crate::lod, "Accumulated errors"): the
    // children's largest error plus this simplification's own, measured against their clusters.
    let error = accumulate(child_error, round_up(s.error_local as f64 * frame.step)).max(MIN_ERROR);

    // 3. Re-cluster and group.
    let vertex_object = vertex_objects(positions.len(), &indices, &objects);
    let groups = NodeGroups { error, sphere, level: level.saturating_add(1), replaced: &replaced };
    let dag = recluster(&s.indices, &vertices, &positions, &vertex_object, params, &groups);
    let stats = HlodStats {
        triangles_in: tri_count,
        target,
        triangles_out: s.indices.len() / 3,
        outcome: s.outcome,
        rounds: s.rounds,
        pruned: s.pruned,
        error,
        child_error,
        area_ratio: (mesh_area(&local, &s.indices) / input.area_in.max(f64::MIN_POSITIVE)) as f32,
    };
    tracing::debug!(?stats, "hlod node");
    HlodNode { dag, replaced, error, sphere, stats }
}

/// The children's roots merged into one mesh ([`merge_children`]).
struct Merged {
    /// Grid points, deduplicated, in grid-point order.
    positions: Vec<[u32; 3]>,
    /// Triangles into `positions` (those that collapsed in the merge left out).
    indices: Vec<u32>,
    /// Each triangle's object.
    objects: Vec<u32>,
    /// The largest error and level of the children's clusters.
    child_error: f32,
    level: u8,
    /// The children's root groups (caller's ids), which the node replaces.
    replaced: Vec<u32>,
    /// A sphere around the replaced groups' spheres.
    sphere: Sphere,
}

/// Step 1, merge: the children's clusters as one mesh, positions deduplicated by grid point,
/// with the groups they replace.
fn merge_children(children: &[Roots]) -> Merged {
    let (merged_index, positions) = merge_positions(children);
    let mut indices: Vec<u32> = Vec::new();
    let mut objects: Vec<u32> = Vec::new();
    let mut child_error = 0.0f32;
    let mut level = 0u8;
    let mut replaced = Vec::new();
    let mut spheres: Vec<Sphere> = Vec::new();
    let mut first_slot = 0usize;
    for r in children {
        for c in &r.dag.clusters {
            child_error = child_error.max(c.self_error);
            level = level.max(c.level);
            let slots = &merged_index[first_slot..first_slot + c.positions.len()];
            first_slot += c.positions.len();
            for (t, tri) in c.indices.chunks_exact(3).enumerate() {
                let p = |k: usize| slots.get(tri[k] as usize).copied();
                let (Some(a), Some(b), Some(d)) = (p(0), p(1), p(2)) else { continue };
                let tri = [a, b, d];
                if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                    continue;
                }
                indices.extend_from_slice(&tri);
                objects.push(c.objects.get(t).copied().unwrap_or(0));
            }
        }
        for (g, &id) in r.dag.groups.iter().zip(&r.group_ids) {
            replaced.push(id);
            spheres.push(g.sphere);
        }
    }
    let sphere = enclosing_sphere(&spheres);
    Merged { positions, indices, objects, child_error, level, replaced, sphere }
}

/// The merged positions, numbered in grid-point order, and the merged index of every cluster
/// vertex (a slot; clusters in order). Slots are sorted by their point packed into a u128 key
/// (which sorts like the [u32; 3] point), so each slot's merged index comes from one sort
/// rather than a search per triangle corner.
fn merge_positions(children: &[Roots]) -> (Vec<u32>, Vec<[u32; 3]>) {
    let key = |p: &[u32; 3]| (p[0] as u128) << 64 | (p[1] as u128) << 32 | p[2] as u128;
    let mut slots: Vec<(u128, u32)> = children
        .iter()
        .flat_map(|r| r.dag.clusters.iter().flat_map(|c| c.positions.iter().map(key)))
        .enumerate()
        .map(|(slot, k)| (k, slot as u32))
        .collect();
    slots.sort_unstable();
    let mut merged_index = vec![0u32; slots.len()];
    let mut positions: Vec<[u32; 3]> = Vec::new();
    let mut last = None;
    for &(k, slot) in &slots {
        if last != Some(k) {
            positions.push(unpack_triangle(k));
            last = Some(k);
        }
        merged_index[slot as usize] = positions.len() as u32 - 1;
    }
    (merged_index, positions)
}

/// The merged mesh of step 2 and what its results are checked against.
struct SimplifyInput<'a> {
    indices: &'a [u32],
    /// Positions in the node's local frame, and meshopt's view of them.
    local: &'a [[f32; 3]],
    vertices: &'a VertexDataAdapter<'a>,
    /// Vertices on open edges shared with a cell outside the node.
    locks: &'a [bool],
    /// Triangles to reach.
    target: usize,
    check: EdgeCheck<'a>,
    /// The merged mesh's surface area.
    area_in: f64,
}

/// The result of step 2.
struct Simplified {
    indices: Vec<u32>,
    /// Its error in local units.
    error_local: f32,
    outcome: HlodOutcome,
    rounds: usize,
    /// Triangles of the whole parts dropped.
    pruned: usize,
}

impl Simplified {
    /// The merged mesh itself, at or below the target already.
    fn unchanged(indices: &[u32]) -> Simplified {
        Simplified {
            indices: indices.to_vec(),
            error_local: 0.0,
            outcome: HlodOutcome::Unchanged,
            rounds: 0,
            pruned: 0,
        }
    }
}

impl SimplifyInput<'_> {
    /// Step 2, for a mesh above the target: the regular simplifier with repair rounds, then
    /// the sloppy one if that stalls above the target, then whole small parts dropped if still
    /// above it. A result is kept only if it breaks no edge ([`EdgeCheck::broken`]: seams kept
    /// open, no holes) and does not grow the area (a fold or a bridge over a gap, module
    /// comment, step 2); the last resort is the merged mesh itself (a lossless step: the parent
    /// tries again with more room).
    fn simplify(&self) -> Simplified {
        let mut s = Simplified { outcome: HlodOutcome::Merged, ..Simplified::unchanged(self.indices) };
        let sim_locks = self.regular_rounds(&mut s);
        self.sloppy_if_stalled(&sim_locks, &mut s);
        self.prune_if_above_target(&mut s);
        s
    }

    /// Whether `out` breaks no edge and does not grow the area.
    fn acceptable(&self, out: &[u32]) -> bool {
        self.check.broken(out).is_empty() && !self.grows(out)
    }

    /// A result whose area grew folded or bridged parts over gaps (module comment, step 2).
    fn grows(&self, out: &[u32]) -> bool {
        mesh_area(self.local, out) > self.area_in * MAX_AREA_GROWTH
    }

    /// The regular simplifier. If it breaks some edges, the neighbourhood of those edges is
    /// locked too and it runs again (at most [`REPAIR_ROUNDS`]); the first result that passes
    /// goes to `s`. Returns the locks it ended with, for the sloppy simplifier.
    fn regular_rounds(&self, s: &mut Simplified) -> Vec<bool> {
        let mut sim_locks = self.locks.to_vec();
        for _ in 0..REPAIR_ROUNDS {
            s.rounds += 1;
            let (out, err) = self.simplify_regular(&sim_locks);
            let bad = self.check.broken(&out);
            if !out.is_empty() && bad.is_empty() && !self.grows(&out) {
                s.indices = out;
                s.error_local = err;
                s.outcome = HlodOutcome::Regular;
                break;
            }
            if !self.lock_around(&bad, &mut sim_locks) {
                break;
            }
        }
        sim_locks
    }

    /// One run of the regular simplifier under `sim_locks`, with its error. Pruning removes
    /// whole components, locked vertices included: a pruned component on a seam would leave the
    /// finer neighbour's border open (a crack), and pruning everything would leave nothing. So
    /// it is tried only while no vertex is locked (with locks it broke a seam in 79 % of the
    /// 10^7 plant's rounds, and each then ran twice); if it still breaks something, simplify
    /// again without it.
    fn simplify_regular(&self, sim_locks: &[bool]) -> (Vec<u32>, f32) {
        let simplify = |options: SimplifyOptions, error: &mut f32| {
            meshopt::simplify_with_locks(
                self.indices,
                self.vertices,
                sim_locks,
                self.target * 3,
                f32::MAX,
                options,
                Some(error),
            )
        };
        let mut err = 0.0f32;
        let mut out = Vec::new();
        if !sim_locks.contains(&true) {
            out = simplify(SimplifyOptions::ErrorAbsolute | SimplifyOptions::Prune, &mut err);
        }
        if out.is_empty() || !self.check.broken(&out).is_empty() {
            err = 0.0;
            out = simplify(SimplifyOptions::ErrorAbsolute, &mut err);
        }
        (out, err)
    }

    /// Locks every vertex of the triangles that touch an end of a broken edge: the vertices
    /// that collapsed to break it are among its ends' neighbours. Returns whether any lock
    /// was added (if none, another round would repeat this one).
    fn lock_around(&self, bad: &[(u32, u32)], sim_locks: &mut [bool]) -> bool {
        let mut ends: Vec<u32> = bad.iter().flat_map(|&(a, b)| [a, b]).collect();
        ends.sort_unstable();
        ends.dedup();
        let mut grew = false;
        for t in self.indices.chunks_exact(3) {
            if t.iter().any(|v| ends.binary_search(v).is_ok()) {
                for &v in t {
                    if let Some(l) = sim_locks.get_mut(v as usize) {
                        grew |= !*l;
                        *l = true;
                    }
                }
            }
        }
        grew
    }

    /// Whether `s` is still more than 1/8 above the target.
    fn above_target(&self, s: &Simplified) -> bool {
        s.indices.len() / 3 > self.target + self.target / 8
    }

    /// The sloppy simplifier ignores topology: only when the regular one stalls above the
    /// target, and only if its result passes the same checks.
    fn sloppy_if_stalled(&self, sim_locks: &[bool], s: &mut Simplified) {
        if !self.above_target(s) {
            return;
        }
        let mut rel = 0.0f32;
        let sloppy = meshopt::simplify_sloppy_with_locks(
            self.indices,
            self.vertices,
            sim_locks,
            self.target * 3,
            f32::MAX,
            Some(&mut rel),
        );
        if !sloppy.is_empty() && sloppy.len() < s.indices.len() && self.acceptable(&sloppy) {
            s.indices = sloppy;
            s.error_local = s.error_local.max(rel * meshopt::simplify_scale(self.vertices) * 2.0);
            s.outcome = HlodOutcome::Sloppy;
        }
    }

    /// Still above the target: the rest is many small disjoint parts (bolts, pipe pieces, each
    /// already at the few triangles a closed part keeps). Drop whole parts, smallest first.
    /// Pinned: a part with an open edge on a seam with a cell outside the node (the locks). A
    /// seam position inside the node is closed in the merged mesh (both halves of the part are
    /// here), so it no longer pins the part.
    fn prune_if_above_target(&self, s: &mut Simplified) {
        if !self.above_target(s) {
            return;
        }
        let (radius, removed) = prune_components(&mut s.indices, self.local, self.locks, self.target);
        if removed > 0 {
            s.error_local = s.error_local.max(radius);
            s.pruned = removed;
        }
    }
}

/// What every group and cluster of a node shares: its error, sphere, level and the groups it
/// replaces.
struct NodeGroups<'a> {
    error: f32,
    sphere: Sphere,
    level: u8,
    replaced: &'a [u32],
}

/// Step 3, re-cluster and group: the simplified triangles as clusters, `group_clusters` to a
/// root group. meshopt's spatial clusterizer, as in the cells (crate::lod): on the 10^7 plant
/// it takes 10–18 % less of HLOD's time than the adjacency-driven one, for the same page bytes.
fn recluster(
    simplified: &[u32],
    vertices: &VertexDataAdapter,
    positions: &[[u32; 3]],
    vertex_object: &[u32],
    params: &HlodParams,
    node: &NodeGroups,
) -> LodDag {
    let max_triangles = (params.max_triangles.clamp(4, MAX_CLUSTER_TRIANGLES) / 4) * 4;
    let max_vertices = params.max_vertices.clamp(3, MAX_CLUSTER_VERTICES);
    let min_triangles = (max_triangles / 3).max(1);
    let meshlets = meshopt::build_meshlets_spatial(
        simplified,
        vertices,
        max_vertices,
        min_triangles,
        max_triangles,
        1.0,
    );
    let mut dag = LodDag::default();
    for m in meshlets.iter() {
        let group_clusters = params.group_clusters.max(1);
        if dag.groups.last().is_none_or(|g: &LodGroup| g.clusters.len() >= group_clusters) {
            let (sphere, level) = (node.sphere, node.level);
            dag.groups.push(LodGroup { error: f32::INFINITY, sphere, clusters: Vec::new(), level });
        }
        let gi = dag.groups.len() - 1;
        let cluster = LodCluster {
            positions: m.vertices.iter().map(|&v| positions[v as usize]).collect(),
            indices: m.triangles.to_vec(),
            objects: m
                .triangles
                .chunks_exact(3)
                .map(|t| {
                    let tri = [t[0], t[1], t[2]].map(|k| m.vertices[k as usize]);
                    triangle_object(vertex_object, tri)
                })
                .collect(),
            self_error: node.error,
            self_sphere: node.sphere,
            group: gi as u32,
            level: node.level,
            refined_from: node.replaced.to_vec(),
        };
        dag.groups[gi].clusters.push(dag.clusters.len() as u32);
        dag.clusters.push(cluster);
    }
    dag
}

/// Total area of the triangles `indices` over `positions`.
fn mesh_area(positions: &[[f32; 3]], indices: &[u32]) -> f64 {
    let p = |i: u32| positions[i as usize].map(f64::from);
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    indices
        .chunks_exact(3)
        .map(|t| {
            let (u, v) = (sub(p(t[1]), p(t[0])), sub(p(t[2]), p(t[0])));
            let c = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
            0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
        })
        .sum()
}

/// Removes whole connected parts of `indices` (triangles sharing vertices), smallest bound
/// first, until at most `target` triangles are left; a part is skipped if removing it would
/// leave fewer than half the target. A part's bound is its
/// [`PartShape::bound`](crate::part_shape::PartShape::bound) in local units: removing it is
/// collapsing it onto its centre or its axis (as in the cells, `crate::clusterlod`, rule 2).
/// A part with a vertex `pinned` (shared with a cell outside the node) goes only if it is a
/// rod pinned at its ends alone
/// ([`PartShape::is_rod_held_at_ends`](crate::part_shape::PartShape::is_rod_held_at_ends)):
/// that cell's half then ends open across the rod's own section, within the bound (rule 4 of
/// `crate::clusterlod`). Unlike the cells, HLOD sees only simplified parts, not the input
/// pieces they stand for, so a part that simplification left long and thin is no rod if a
/// seam holds it along its length. Returns the largest removed bound and the triangles
/// removed. A removed part shares no edge with what is left. Deterministic (ties by first
/// triangle).
fn prune_components(
    indices: &mut Vec<u32>,
    local: &[[f32; 3]],
    pinned: &[bool],
    target: usize,
) -> (f32, usize) {
    let n = local.len();
    let mut parts_of = crate::union_find::UnionFind::new(n);
    parts_of.union_triangles(indices, |v| v);
    // Per part (by root): triangles, first triangle, pinned.
    struct Part {
        triangles: usize,
        first: usize,
        pinned: bool,
    }
    let mut part_of: Vec<u32> = vec![u32::MAX; n];
    let mut parts: Vec<Part> = Vec::new();
    let mut tri_part: Vec<u32> = Vec::with_capacity(indices.len() / 3);
    for (ti, t) in indices.chunks_exact(3).enumerate() {
        let r = parts_of.find(t[0]) as usize;
        if part_of[r] == u32::MAX {
            part_of[r] = parts.len() as u32;
            parts.push(Part { triangles: 0, first: ti, pinned: false });
        }
        let p = &mut parts[part_of[r] as usize];
        p.triangles += 1;
        p.pinned |= t.iter().any(|&v| pinned.get(v as usize) == Some(&true));
        tri_part.push(part_of[r]);
    }
    let corners = || {
        indices.chunks_exact(3).zip(&tri_part).flat_map(|(t, &p)| {
            t.iter().map(move |&v| (p as usize, local[v as usize], pinned.get(v as usize) == Some(&true)))
        })
    };
    let shapes = part_shapes(parts.len(), corners);
    let bounds: Vec<f32> = shapes.iter().map(|s| round_up(s.bound())).collect();
    let mut order: Vec<usize> =
        (0..parts.len()).filter(|&i| !parts[i].pinned || shapes[i].is_rod_held_at_ends()).collect();
    order.sort_by(|&a, &b| bounds[a].total_cmp(&bounds[b]).then(parts[a].first.cmp(&parts[b].first)));
    let mut count = indices.len() / 3;
    let keep_at_least = (target / 2).max(1);
    let mut remove = vec![false; parts.len()];
    let mut max_bound = 0.0f32;
    for i in order {
        if count <= target {
            break;
        }
        if count - parts[i].triangles < keep_at_least {
            continue;
        }
        count -= parts[i].triangles;
        remove[i] = true;
        max_bound = max_bound.max(bounds[i]);
    }
    let removed = indices.len() / 3 - count;
    if removed > 0 {
        let mut out = Vec::with_capacity(count * 3);
        for (t, &p) in indices.chunks_exact(3).zip(&tri_part) {
            if !remove[p as usize] {
                out.extend_from_slice(t);
            }
        }
        *indices = out;
    }
    (max_bound, removed)
}

/// A triangle with its vertices rotated so the smallest comes first (winding kept), packed into a
/// `u128` (`a << 64 | b << 32 | c`): two triangles are the same for crack checks
/// (`crate::cut::boundary_edges`) iff their keys are equal.
fn triangle_key(t: &[u32]) -> u128 {
    let k = (0..3).min_by_key(|&i| t[i]).unwrap_or(0);
    (t[k] as u128) << 64 | (t[(k + 1) % 3] as u128) << 32 | t[(k + 2) % 3] as u128
}

/// The vertices of a triangle packed by [`triangle_key`].
fn unpack_triangle(t: u128) -> [u32; 3] {
    [(t >> 64) as u32, (t >> 32) as u32, t as u32]
}

/// An undirected edge packed into a `u64`, smaller index in the high half (sorts like the pair).
fn edge_key(a: u32, b: u32) -> u64 {
    (a.min(b) as u64) << 32 | a.max(b) as u64
}

fn edge_pair(e: u64) -> (u32, u32) {
    ((e >> 32) as u32, e as u32)
}

/// Undirected edges ([`edge_key`]) with the number of triangles using each. A hash table: the
/// checks below only count and look up, and every list they return is sorted afterwards.
#[derive(Default)]
struct EdgeUses(rustc_hash::FxHashMap<u64, u32>);

impl EdgeUses {
    fn with_capacity(edges: usize) -> EdgeUses {
        EdgeUses(rustc_hash::FxHashMap::with_capacity_and_hasher(edges, Default::default()))
    }

    /// The edges of every triangle of `indices` for which `keep` holds.
    fn of_triangles(indices: &[u32], keep: impl Fn(u32, u32) -> bool) -> EdgeUses {
        let mut uses = EdgeUses::default();
        for t in indices.chunks_exact(3) {
            uses.add_triangle([t[0], t[1], t[2]], &keep);
        }
        uses
    }

    /// The edges of the unique triangles ([`triangle_key`]) of `indices`.
    fn of_unique_triangles(indices: &[u32]) -> EdgeUses {
        let n = indices.len() / 3;
        let mut seen: rustc_hash::FxHashSet<u128> =
            rustc_hash::FxHashSet::with_capacity_and_hasher(n, Default::default());
        let mut uses = EdgeUses::with_capacity(n * 3 / 2 + 8);
        for t in indices.chunks_exact(3) {
            if seen.insert(triangle_key(t)) {
                uses.add_triangle([t[0], t[1], t[2]], &|_, _| true);
            }
        }
        uses
    }

    fn add_triangle(&mut self, t: [u32; 3], keep: &impl Fn(u32, u32) -> bool) {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            if keep(a, b) {
                *self.0.entry(edge_key(a, b)).or_insert(0) += 1;
            }
        }
    }

    /// How many triangles use edge `e`.
    fn of(&self, e: u64) -> u32 {
        self.0.get(&e).copied().unwrap_or(0)
    }

    /// The edges used by exactly one triangle, in no particular order.
    fn single(&self) -> impl Iterator<Item = u64> + '_ {
        self.0.iter().filter(|&(_, &n)| n == 1).map(|(&e, _)| e)
    }
}

/// The vertices of the merged mesh on its free border: on a boundary edge (used by one triangle)
/// that is not a seam edge (both ends locked). These are object borders, which HLOD may simplify
/// (meshopt moves border vertices along the border); vertices that are only on seams, or only
/// on non-manifold edges (left by earlier simplification: a vertex inside the input's surface),
/// are not.
#[cfg(test)]
fn free_border_vertices(n: usize, indices: &[u32], locks: &[bool]) -> Vec<bool> {
    EdgeCheck::new(n, indices, locks).free_border
}

/// [`EdgeCheck::broken`] for one pair (tests).
#[cfg(test)]
fn broken_edges(before: &[u32], after: &[u32], locks: &[bool], free_border: &[bool]) -> Vec<(u32, u32)> {
    let mut check = EdgeCheck::new(free_border.len(), before, locks);
    check.free_border = free_border.to_vec();
    check.broken(after)
}

/// What [`EdgeCheck::broken`] needs of the merged mesh (`before`), computed once per node: every
/// simplification round of the node is checked against the same mesh and locks.
struct EdgeCheck<'a> {
    locks: &'a [bool],
    /// See [`free_border_vertices`].
    free_border: Vec<bool>,
    /// The seam edges of `before` (both ends locked) used by exactly one triangle.
    seams_before: Vec<u64>,
    /// Every edge of `before`'s unique triangles with its uses.
    old: EdgeUses,
}

impl<'a> EdgeCheck<'a> {
    fn new(n: usize, before: &[u32], locks: &'a [bool]) -> EdgeCheck<'a> {
        let locked = |v: u32| locks.get(v as usize) == Some(&true);
        let old = EdgeUses::of_unique_triangles(before);
        let mut free_border = vec![false; n];
        for e in old.single() {
            let (a, b) = edge_pair(e);
            if !(locked(a) && locked(b)) {
                for v in [a, b] {
                    if let Some(f) = free_border.get_mut(v as usize) {
                        *f = true;
                    }
                }
            }
        }
        let seams_before = EdgeUses::of_triangles(before, |a, b| locked(a) && locked(b)).single().collect();
        EdgeCheck { locks, free_border, seams_before, old }
    }

    /// The edges that `after` (a simplification of `before`) breaks, sorted:
    ///
    /// * seams: an edge of `before` used by one triangle, between two locked vertices (a seam
    ///   with a cell outside the node), must still be used by exactly one triangle. Lost, the
    ///   finer neighbour's border is open; folded into two triangles (a double-sided pair, which
    ///   meshopt makes of thin parts), it is no longer open in the parent's merged mesh, so its
    ///   vertices are not locked there and the seam is lost one level up;
    /// * holes: every boundary edge of `after` (used by one of its unique triangles, as crack
    ///   checks count) must be one of `before` or join two free border vertices of `before` (a
    ///   simplified object border). Anything else is a hole inside the surface, a crack in every
    ///   cut that uses these clusters (meshopt's topology rules are per directed half-edge, so
    ///   the double-sided and non-manifold parts that earlier levels leave can lose triangles
    ///   next to an edge it takes for interior; the sloppy simplifier ignores topology
    ///   altogether).
    fn broken(&self, after: &[u32]) -> Vec<(u32, u32)> {
        let locked = |v: u32| self.locks.get(v as usize) == Some(&true);
        let free = |v: u32| self.free_border.get(v as usize) == Some(&true);
        let seams_after = EdgeUses::of_triangles(after, |a, b| locked(a) && locked(b));
        let mut bad: Vec<u64> =
            self.seams_before.iter().copied().filter(|&e| seams_after.of(e) != 1).collect();
        bad.extend(EdgeUses::of_unique_triangles(after).single().filter(|&e| {
            let (a, b) = edge_pair(e);
            !(free(a) && free(b)) && self.old.of(e) != 1
        }));
        bad.sort_unstable();
        bad.dedup();
        bad.into_iter().map(edge_pair).collect()
    }
}

/// The positions on open (or non-manifold) edges of at least two of the given cells, sorted:
/// the seams of split objects. A node's `external` predicate can test membership (it is
/// conservative to use the scene-wide set for every node: only vertices on the merged mesh's
/// own open edges are locked).
#[cfg(test)]
pub fn seam_positions(cells: &[&crate::types::CellMesh]) -> Vec<[u32; 3]> {
    shared_positions(cells.iter().flat_map(|m| open_positions(m)).collect())
}

/// The grid positions of a cell's vertices on open (or non-manifold) edges, sorted, once each.
pub fn open_positions(mesh: &crate::types::CellMesh) -> Vec<[u32; 3]> {
    let (indices, _) = crate::lod::clean_triangles(mesh);
    let mut open: Vec<[u32; 3]> = crate::lod::open_boundary_vertices(mesh.positions.len(), &indices)
        .into_iter()
        .zip(&mesh.positions)
        .filter(|(o, _)| *o)
        .map(|(_, &p)| p)
        .collect();
    open.sort_unstable();
    open.dedup();
    open
}

/// The positions that occur more than once in `all` (the concatenated [`open_positions`] of
/// several cells), sorted. The sort runs on the current rayon pool.
#[cfg(test)]
pub fn shared_positions(mut all: Vec<[u32; 3]>) -> Vec<[u32; 3]> {
    use rayon::slice::ParallelSliceMut;
    all.par_sort_unstable();
    let mut seams: Vec<[u32; 3]> = all.windows(2).filter(|w| w[0] == w[1]).map(|w| w[0]).collect();
    seams.dedup();
    seams
}

/// A sphere containing all `spheres` (meshopt's estimate, grown to contain each exactly).
fn enclosing_sphere(spheres: &[Sphere]) -> Sphere {
    let Some(first) = spheres.first() else { return Sphere::default() };
    let packed: Vec<[f32; 4]> =
        spheres.iter().map(|s| [s.center[0], s.center[1], s.center[2], s.radius]).collect();
    let bytes = meshopt::typed_to_bytes(&packed);
    let est = meshopt::compute_sphere_bounds(
        meshopt::PositionDataAdapter {
            data: bytes,
            position_count: packed.len(),
            position_stride: 16,
            position_offset: 0,
        },
        Some(meshopt::RadiusDataAdapter {
            data: bytes,
            radius_count: packed.len(),
            radius_stride: 16,
            radius_offset: 12,
        }),
    );
    let mut s = if est.center.iter().all(|v| v.is_finite()) && est.radius.is_finite() {
        Sphere { center: est.center, radius: est.radius.max(0.0) }
    } else {
        *first
    };
    for o in spheres {
        grow_sphere(&mut s, sphere_center64(o), o.radius as f64);
    }
    s
}

/// Appends a cell's DAG to a scene-wide DAG (reindexing its groups and `refined_from`);
/// returns the scene id of the cell's group 0.
#[cfg(test)]
pub fn append_cell(scene: &mut LodDag, cell: &LodDag) -> u32 {
    let gbase = scene.groups.len() as u32;
    let cbase = scene.clusters.len() as u32;
    for c in &cell.clusters {
        scene.clusters.push(LodCluster {
            group: c.group + gbase,
            refined_from: c.refined_from.iter().map(|r| r + gbase).collect(),
            ..c.clone()
        });
    }
    for g in &cell.groups {
        scene.groups.push(LodGroup { clusters: g.clusters.iter().map(|c| c + cbase).collect(), ..g.clone() });
    }
    gbase
}

/// Applies an HLOD node to a scene-wide DAG: the replaced groups get the node's error and
/// sphere, and the node's clusters and groups are appended (their `refined_from` already holds
/// scene ids). Returns the scene id of the node's group 0.
#[cfg(test)]
pub fn append_node(scene: &mut LodDag, node: &HlodNode) -> u32 {
    for &id in &node.replaced {
        if let Some(g) = scene.groups.get_mut(id as usize) {
            g.error = node.error;
            g.sphere = node.sphere;
        }
    }
    let gbase = scene.groups.len() as u32;
    let cbase = scene.clusters.len() as u32;
    for c in &node.dag.clusters {
        scene.clusters.push(LodCluster { group: c.group + gbase, ..c.clone() });
    }
    for g in &node.dag.groups {
        scene.groups.push(LodGroup { clusters: g.clusters.iter().map(|c| c + cbase).collect(), ..g.clone() });
    }
    gbase
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cut::fixtures::{cell, grid_for, icosphere, mesh_triangles, plant, torus, Soup};
    use crate::cut::*;
    use crate::lod::{build_cell_lod, LodParams};
    use crate::types::CellMesh;

    /// Builds the scene-wide DAG of `cells` under a balanced binary hierarchy, bottom-up keeping
    /// only the current roots (as the pipeline does). Returns the scene DAG and the root's
    /// triangle count.
    fn build_scene(cells: &[CellMesh], grid: &Grid, params: &HlodParams) -> Scene {
        let seams = seam_positions(&cells.iter().collect::<Vec<_>>());
        let external = |p: [u32; 3]| seams.binary_search(&p).is_ok();
        let mut node_borders = Vec::new();
        let mut scene = LodDag::default();
        let mut level: Vec<Roots> = cells
            .iter()
            .map(|m| {
                let dag = build_cell_lod(m, grid, &LodParams::default());
                let base = append_cell(&mut scene, &dag);
                roots_of(&dag, base)
            })
            .collect();
        while level.len() > 1 {
            let mut next = Vec::new();
            for pair in level.chunks(2) {
                if pair.len() == 1 {
                    next.push(pair[0].clone());
                    continue;
                }
                let node = build_hlod(pair, grid, params, &external);
                // No result may fold or bridge (MAX_AREA_GROWTH; a literal here, so that this
                // fails if the check is loosened).
                assert!(node.stats.area_ratio <= 1.010_001, "the area grew: {:?}", node.stats);
                let tris: Vec<GridTriangle> =
                    node.dag.clusters.iter().flat_map(|c| cluster_triangles(c).map(|t| t.0)).collect();
                node_borders.extend(boundary_edges(&tris));
                assert!(
                    node.error
                        >= pair
                            .iter()
                            .flat_map(|r| &r.dag.clusters)
                            .map(|c| c.self_error)
                            .fold(0.0, f32::max)
                );
                let base = append_node(&mut scene, &node);
                next.push(node.roots(base));
            }
            level = next;
        }
        let root_tris = level[0].triangle_count();
        node_borders.sort_unstable();
        node_borders.dedup();
        Scene { dag: scene, root_tris, node_borders }
    }

    #[derive(Debug, PartialEq)]
    struct Scene {
        dag: LodDag,
        root_tris: usize,
        /// Boundary edges of each HLOD node's own mesh (simplified open borders).
        node_borders: Vec<([u32; 3], [u32; 3])>,
    }

    fn taus(dag: &LodDag) -> Vec<f32> {
        let mut e: Vec<f32> = dag.groups.iter().map(|g| g.error).filter(|e| e.is_finite()).collect();
        e.sort_by(f32::total_cmp);
        e.dedup();
        let mut t = vec![0.0];
        let step = (e.len() / 12).max(1);
        for &x in e.iter().step_by(step) {
            t.push(x * 0.999);
            t.push(x);
        }
        if let Some(&x) = e.last() {
            t.push(x);
            t.push(x * 1.001);
        }
        t
    }

    /// All checks on a scene: validity, τ = 0 is the input, complete crack-free cuts.
    /// On closed inputs (`closed`) no boundary edge may appear at all; on open inputs, an HLOD
    /// node may simplify object borders, so its own mesh's boundary edges are allowed too.
    fn check_scene(cells: &[CellMesh], grid: &Grid, s: &Scene, closed: bool) {
        let scene = &s.dag;
        check_dag(scene, Some(grid)).unwrap();
        let input: Vec<(GridTriangle, u32)> = cells.iter().flat_map(mesh_triangles).collect();
        let cut0 = extract_cut(scene, 0.0);
        assert_eq!(triangle_multiset(&cut_triangles(scene, &cut0)), triangle_multiset(&input));
        let input_tris: Vec<GridTriangle> = input.iter().map(|t| t.0).collect();
        let mut allowed = open_edges(&input_tris);
        if closed {
            assert!(allowed.is_empty(), "closed input");
        } else {
            allowed.extend(s.node_borders.iter().copied());
            allowed.sort_unstable();
        }
        let by_cell: Vec<Vec<GridTriangle>> =
            cells.iter().map(|c| mesh_triangles(c).into_iter().map(|t| t.0).collect()).collect();
        let thin = ThinPieces::new(by_cell.iter().map(Vec::as_slice), grid.step);
        for tau in taus(scene) {
            check_complete(scene, tau).unwrap();
            let cut: Vec<GridTriangle> =
                cut_triangles(scene, &extract_cut(scene, tau)).into_iter().map(|t| t.0).collect();
            check_no_cracks(&cut, &allowed, &thin, tau).unwrap_or_else(|e| panic!("tau {tau}: {e}"));
        }
        let top = extract_cut(scene, f32::MAX);
        assert!(top
            .iter()
            .all(|&c| scene.groups[scene.clusters[c as usize].group as usize].error.is_infinite()));
    }

    fn cells_of(soups: &[Soup]) -> (Vec<CellMesh>, Grid) {
        let grid = grid_for(&soups.iter().collect::<Vec<_>>());
        (soups.iter().map(|s| cell(s, &grid)).collect(), grid)
    }

    #[test]
    fn four_spheres_merge_into_a_few_root_clusters() {
        let soups: Vec<Soup> =
            (0..4).map(|i| icosphere([i as f64 * 25.0, (i % 2) as f64 * 5.0, 0.0], 10.0, 5, i)).collect();
        let (cells, grid) = cells_of(&soups);
        let s = build_scene(&cells, &grid, &HlodParams::default());
        check_scene(&cells, &grid, &s, true);
        let (scene, root_tris) = (&s.dag, s.root_tris);
        let roots: Vec<&LodGroup> = scene.groups.iter().filter(|g| g.error.is_infinite()).collect();
        let root_clusters: usize = roots.iter().map(|g| g.clusters.len()).sum();
        assert!(root_clusters <= 8 && root_tris <= 1024, "{root_clusters} clusters, {root_tris} triangles");
        println!("spheres: root {root_clusters} clusters, {root_tris} triangles");
        assert!(scene.clusters.iter().any(|c| c.level > 8), "HLOD levels continue the count");
    }

    #[test]
    fn torus_split_in_two_cells_does_not_crack() {
        let soups = vec![torus(96, 48, 0..48, 1), torus(96, 48, 48..96, 2)];
        let (cells, grid) = cells_of(&soups);
        let input: Vec<GridTriangle> = cells.iter().flat_map(mesh_triangles).map(|t| t.0).collect();
        assert!(open_edges(&input).is_empty(), "the two halves form a closed torus");
        check_scene(&cells, &grid, &build_scene(&cells, &grid, &HlodParams::default()), true);
    }

    #[test]
    fn torus_in_four_cells_does_not_crack_between_levels() {
        // Quarters 0+1 and 2+3 become sibling HLOD nodes; each is coarsened while the other
        // subtree is still fine at some τ, so their shared seams must stay locked.
        let soups: Vec<Soup> = (0..4).map(|q| torus(96, 48, q * 24..(q + 1) * 24, q as u32)).collect();
        let (cells, grid) = cells_of(&soups);
        assert_eq!(seam_positions(&cells.iter().collect::<Vec<_>>()).len(), 4 * 48);
        check_scene(&cells, &grid, &build_scene(&cells, &grid, &HlodParams::default()), true);
    }

    #[test]
    fn plant_split_by_object_into_cells() {
        let soup = plant(20_000, 11);
        let grid = grid_for(&[&soup]);
        let mut by_cell: Vec<Soup> = vec![Vec::new(); 4];
        for t in &soup {
            by_cell[(t.1 % 4) as usize].push(*t);
        }
        let cells: Vec<CellMesh> = by_cell.iter().map(|s| cell(s, &grid)).collect();
        let s = build_scene(&cells, &grid, &HlodParams::default());
        check_scene(&cells, &grid, &s, false);
        assert!(s.root_tris <= 1024, "{} root triangles", s.root_tris);
        println!(
            "plant: {} root triangles, {} clusters, {} groups",
            s.root_tris,
            s.dag.clusters.len(),
            s.dag.groups.len()
        );
    }

    #[test]
    fn mesh_area_sums_the_triangles() {
        // A unit square in two triangles, and a degenerate one.
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [2.0, 0.0, 0.0]];
        assert!((mesh_area(&p, &[0, 1, 2, 0, 2, 3]) - 1.0).abs() < 1e-12);
        assert_eq!(mesh_area(&p, &[0, 1, 4]), 0.0);
        assert_eq!(mesh_area(&p, &[]), 0.0);
    }

    #[test]
    fn hlod_is_deterministic() {
        let soups: Vec<Soup> = (0..3).map(|i| icosphere([i as f64 * 25.0, 0.0, 0.0], 10.0, 4, i)).collect();
        let (cells, grid) = cells_of(&soups);
        let a = build_scene(&cells, &grid, &HlodParams::default());
        let b = build_scene(&cells, &grid, &HlodParams::default());
        assert_eq!(a, b);
    }

    #[test]
    fn node_of_no_children_is_empty() {
        let grid = Grid::for_bounds([0.0; 3], [1.0; 3]);
        let node = build_hlod(&[], &grid, &HlodParams::default(), &|_| false);
        assert!(node.dag.clusters.is_empty() && node.replaced.is_empty());
    }

    /// A 3 × 3 grid of vertices (`row * 3 + column`), two triangles per square; vertex 4 is the
    /// only one inside.
    fn grid_mesh() -> Vec<u32> {
        vec![0, 1, 4, 0, 4, 3, 1, 2, 5, 1, 5, 4, 3, 4, 7, 3, 7, 6, 4, 5, 8, 4, 8, 7]
    }

    fn broken(after: &[u32], locks: &[bool]) -> Vec<(u32, u32)> {
        let before = grid_mesh();
        broken_edges(&before, after, locks, &free_border_vertices(9, &before, locks))
    }

    #[test]
    fn simplified_object_border_is_not_broken() {
        // Vertex 1 (on the border) collapsed onto 0: the new border edge 0-2 joins two border
        // vertices.
        let after = [0, 4, 3, 0, 2, 5, 0, 5, 4, 3, 4, 7, 3, 7, 6, 4, 5, 8, 4, 8, 7];
        assert_eq!(broken(&after, &[false; 9]), []);
    }

    #[test]
    fn hole_next_to_an_inner_vertex_is_broken() {
        // Triangle 0-1-4 gone: edges 0-4 and 1-4 end inside the surface.
        let mesh = grid_mesh();
        assert_eq!(broken(&mesh[3..], &[false; 9]), [(0, 4), (1, 4)]);
    }

    #[test]
    fn lost_or_folded_seam_is_broken() {
        // The top row is a seam with a cell outside the node.
        let mut locks = [false; 9];
        locks[..3].fill(true);
        assert_eq!(broken(&grid_mesh(), &locks), []);
        let collapsed = [0, 4, 3, 0, 2, 5, 0, 5, 4, 3, 4, 7, 3, 7, 6, 4, 5, 8, 4, 8, 7];
        assert_eq!(broken(&collapsed, &locks), [(0, 1), (1, 2)]);
        // Triangle 0-1-4 doubled into a double-sided pair: 0-1 is no longer open.
        let mut folded = grid_mesh();
        folded.splice(0..0, [0, 4, 1]);
        assert_eq!(broken(&folded, &locks), [(0, 1)]);
    }

    #[test]
    fn roots_of_keeps_only_infinite_groups() {
        let soup = icosphere([0.0; 3], 1.0, 3, 0);
        let grid = grid_for(&[&soup]);
        let dag = build_cell_lod(&cell(&soup, &grid), &grid, &LodParams::default());
        let r = roots_of(&dag, 100);
        assert!(!r.dag.groups.is_empty());
        assert!(r.dag.groups.iter().all(|g| g.error.is_infinite()));
        for (g, &id) in r.dag.groups.iter().zip(&r.group_ids) {
            assert_eq!(dag.groups[(id - 100) as usize].sphere, g.sphere);
            assert!(g.clusters.iter().all(|&c| r.dag.clusters[c as usize].group as usize
                == r.dag.groups.iter().position(|x| x == g).unwrap()));
        }
    }
}
