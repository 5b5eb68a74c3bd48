//! Cut extraction and the checks of the cluster DAG model (docs/FORMAT.md, "Model"), used by
//! tests of the build and of the runtime: DAG validity (cluster limits, indices, monotone
//! errors, nested spheres, `refined_from` consistency), completeness of a cut (every input
//! cluster is represented exactly once) and cracks (boundary edges of the cut mesh must be
//! boundary edges of the input).
//!
//! The render rule is [`crate::types::in_cut`] in object space (scene units).

use crate::types::{in_cut, Grid, LodCluster, LodDag, Sphere};

/// A triangle as three grid positions.
pub type GridTriangle = [[u32; 3]; 3];

/// The clusters in the cut for threshold `tau` (scene units), in index order.
pub fn extract_cut(dag: &LodDag, tau: f32) -> Vec<u32> {
    (0..dag.clusters.len()).filter(|&c| in_cut(dag, c, tau)).map(|c| c as u32).collect()
}

/// A cluster's triangles as grid positions with their object ids (invalid indices skipped).
pub fn cluster_triangles(c: &LodCluster) -> impl Iterator<Item = (GridTriangle, u32)> + '_ {
    c.indices.chunks_exact(3).enumerate().filter_map(|(t, tri)| {
        let p = |k: usize| c.positions.get(tri[k] as usize).copied();
        Some(([p(0)?, p(1)?, p(2)?], c.objects.get(t).copied().unwrap_or(u32::MAX)))
    })
}

/// All triangles of the given clusters.
pub fn cut_triangles(dag: &LodDag, cut: &[u32]) -> Vec<(GridTriangle, u32)> {
    cut.iter().filter_map(|&c| dag.clusters.get(c as usize)).flat_map(cluster_triangles).collect()
}

/// The triangle rotated so that its smallest vertex comes first (winding kept).
pub fn canonical(t: GridTriangle) -> GridTriangle {
    let k = (0..3).min_by_key(|&i| t[i]).unwrap_or(0);
    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
}

/// A sorted multiset of canonical triangles (with objects), for comparing meshes exactly.
#[cfg(test)]
pub fn triangle_multiset(tris: &[(GridTriangle, u32)]) -> Vec<(GridTriangle, u32)> {
    let mut v: Vec<_> = tris.iter().map(|&(t, o)| (canonical(t), o)).collect();
    v.sort_unstable();
    v
}

/// Undirected edges (by grid position, deduplicated triangles) used by exactly one triangle; sorted.
pub fn boundary_edges(tris: &[GridTriangle]) -> Vec<([u32; 3], [u32; 3])> {
    edges_where(tris, |n| n == 1)
}

/// Undirected edges not used by exactly two triangles (open or non-manifold); sorted. On a
/// closed manifold input this is empty.
pub fn open_edges(tris: &[GridTriangle]) -> Vec<([u32; 3], [u32; 3])> {
    edges_where(tris, |n| n != 2)
}

fn edges_where(tris: &[GridTriangle], keep: impl Fn(usize) -> bool) -> Vec<([u32; 3], [u32; 3])> {
    let mut unique: Vec<GridTriangle> = tris.iter().map(|&t| canonical(t)).collect();
    unique.sort_unstable();
    unique.dedup();
    let mut edges: Vec<([u32; 3], [u32; 3])> = Vec::with_capacity(unique.len() * 3);
    for t in &unique {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            edges.push(if a < b { (a, b) } else { (b, a) });
        }
    }
    edges.sort_unstable();
    let mut out = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j] == edges[i] {
            j += 1;
        }
        if keep(j - i) {
            out.push(edges[i]);
        }
        i = j;
    }
    out
}

/// Crack check of a cut at `tau`: every boundary edge of `cut` must be an allowed edge (on a
/// closed input, none; in general the input's [`open_edges`]: its boundary, and non-manifold
/// edges, which the simplifier keeps but may leave with fewer triangles when an attached part
/// is simplified away) or an opening of a thin part ([`ThinPieces`]). Returns the number of
/// offending edges in the error.
#[cfg(test)]
pub fn check_no_cracks(
    cut: &[GridTriangle],
    allowed: &[([u32; 3], [u32; 3])],
    thin: &ThinPieces,
    tau: f32,
) -> Result<(), String> {
    let bad: Vec<_> = boundary_edges(cut)
        .into_iter()
        .filter(|&e| allowed.binary_search(&e).is_err() && !thin.is_opening(e, tau))
        .collect();
    match bad.first() {
        None => Ok(()),
        Some(&e) => Err(format!(
            "{} crack edges in the cut, e.g. {e:?} (the thinnest input piece on it: {:?})",
            bad.len(),
            thin.bound(e)
        )),
    }
}

/// What a cut may leave open besides the input's own open edges: the section of a thin part
/// whose other half, across a cell seam or a group border, was removed at a coarser level
/// (rule 4 of `crate::clusterlod`; `crate::hlod`, `prune_components`). The input is given as
/// *regions* (each cell, and the cells under each hierarchy node, where HLOD removes parts
/// made of several cells' pieces), and split into *pieces*, the connected parts (triangles
/// sharing a grid point) of each region; every piece gets the bound the build charges for
/// removing a part (`PartShape::bound` in `part_shape.rs`): its radius or,
/// when less, its vertices' largest distance from its principal axis. A boundary edge of a cut
/// at τ is an opening, not a crack, if both its ends are vertices of one piece whose bound is
/// within [`OPENING_SLACK`] × τ (the section of what is left may itself be simplified later,
/// along its new border, so its edges need not be input edges): what is missing there lies
/// within that of a line. A crack along a wide surface (a seam of a floor or a shell that one
/// side moved) has no such piece and is still found. That the build opens only rods, never a
/// shell, is its policy (`crate::part_shape`), checked where the input is closed (the
/// runtime's cuts of closed spheres).
pub struct ThinPieces {
    /// Every input grid point with a piece it belongs to (two or more on a seam), sorted.
    points: Vec<([u32; 3], u32)>,
    /// Each piece's bound (scene units).
    bounds: Vec<f64>,
}

/// How far beyond τ a piece's bound may be where a cut opens: the build measures the bound on
/// the part as it was when removed (in HLOD, a simplified union of pieces whose error is
/// accumulated into τ) and from that part's own principal axis, which need not be the line that
/// fits the input piece best.
pub const OPENING_SLACK: f64 = 2.0;

impl ThinPieces {
    /// The pieces of the input given region by region; `step` is the grid step (scene units).
    pub fn new<'a>(regions: impl IntoIterator<Item = &'a [GridTriangle]>, step: f64) -> ThinPieces {
        let mut thin = ThinPieces { points: Vec::new(), bounds: Vec::new() };
        for region in regions {
            thin.add_region(region, step);
        }
        thin.points.sort_unstable();
        thin.points.dedup();
        thin
    }

    fn add_region(&mut self, region: &[GridTriangle], step: f64) {
        let mut points: Vec<[u32; 3]> = region.iter().flatten().copied().collect();
        points.sort_unstable();
        points.dedup();
        let id = |p: &[u32; 3]| points.binary_search(p).unwrap_or(0) as u32;
        let mut parts = crate::union_find::UnionFind::new(points.len());
        for t in region {
            parts.union(id(&t[0]), id(&t[1]));
            parts.union(id(&t[0]), id(&t[2]));
        }
        let root: Vec<usize> = (0..points.len() as u32).map(|v| parts.find(v) as usize).collect();
        let shapes = crate::part_shape::part_shapes(points.len(), || {
            points.iter().enumerate().map(|(v, p)| (root[v], p.map(|c| c as f32), false))
        });
        // Pieces numbered after those of earlier regions, in order of their roots.
        let mut number = vec![u32::MAX; points.len()];
        for (v, p) in points.iter().enumerate() {
            let r = root[v];
            if number[r] == u32::MAX {
                number[r] = self.bounds.len() as u32;
                let s = shapes[r];
                self.bounds.push(s.bound() * step);
            }
            self.points.push((*p, number[r]));
        }
    }

    /// The pieces that grid point `p` belongs to.
    fn pieces(&self, p: [u32; 3]) -> &[([u32; 3], u32)] {
        let from = self.points.partition_point(|x| x.0 < p);
        let to = self.points.partition_point(|x| x.0 <= p);
        &self.points[from..to]
    }

    /// The smallest bound (scene units) of a piece that has both ends of `e` as vertices.
    pub fn bound(&self, e: ([u32; 3], [u32; 3])) -> Option<f64> {
        let ends = self.pieces(e.1);
        self.pieces(e.0)
            .iter()
            .filter(|a| ends.iter().any(|b| b.1 == a.1))
            .map(|a| self.bounds[a.1 as usize])
            .min_by(f64::total_cmp)
    }

    /// Whether boundary edge `e` of a cut at `tau` (scene units) is an opening.
    pub fn is_opening(&self, e: ([u32; 3], [u32; 3]), tau: f32) -> bool {
        self.bound(e).is_some_and(|b| b <= OPENING_SLACK * tau as f64)
    }
}

fn contains(outer: &Sphere, inner_center: [f64; 3], inner_radius: f64, tol: f64) -> bool {
    let d = (0..3).map(|i| (inner_center[i] - outer.center[i] as f64).powi(2)).sum::<f64>().sqrt();
    d + inner_radius <= outer.radius as f64 + tol
}

/// Structural checks of a DAG: cluster limits and indices, group membership, monotone errors,
/// nested spheres, `refined_from` consistency (the cluster's self error/sphere are exactly its
/// source groups' error/sphere), every finite-error group replaced by some cluster, and (with
/// `grid`) every vertex inside its cluster's self sphere and its group's sphere.
pub fn check_dag(dag: &LodDag, grid: Option<&Grid>) -> Result<(), String> {
    let ng = dag.groups.len();
    let mut member_of = vec![u32::MAX; dag.clusters.len()];
    for (gi, g) in dag.groups.iter().enumerate() {
        if g.clusters.is_empty() {
            return Err(format!("group {gi} is empty"));
        }
        if g.error.is_nan() || g.sphere.radius.is_nan() || g.sphere.radius < 0.0 {
            return Err(format!("group {gi} has a NaN error or bad sphere"));
        }
        for &c in &g.clusters {
            let slot =
                member_of.get_mut(c as usize).ok_or(format!("group {gi} lists missing cluster {c}"))?;
            if *slot != u32::MAX {
                return Err(format!("cluster {c} is in two groups"));
            }
            *slot = gi as u32;
        }
    }
    let mut replaced = vec![false; ng];
    for (ci, c) in dag.clusters.iter().enumerate() {
        let tris = c.indices.len() / 3;
        if c.indices.len() % 3 != 0 || tris == 0 || tris > 128 || c.positions.len() > 255 {
            return Err(format!("cluster {ci}: {} indices, {} vertices", c.indices.len(), c.positions.len()));
        }
        if c.objects.len() != tris {
            return Err(format!("cluster {ci}: {} objects for {tris} triangles", c.objects.len()));
        }
        if c.indices.iter().any(|&i| i as usize >= c.positions.len()) {
            return Err(format!("cluster {ci}: local index out of range"));
        }
        if member_of[ci] != c.group {
            return Err(format!("cluster {ci}: group {} does not list it", c.group));
        }
        let g = &dag.groups[c.group as usize];
        if c.self_error.is_nan() || g.error < c.self_error {
            return Err(format!("cluster {ci}: self error {} > group error {}", c.self_error, g.error));
        }
        let tol = |r: f32| r as f64 * 1e-6;
        if !contains(
            &g.sphere,
            c.self_sphere.center.map(|v| v as f64),
            c.self_sphere.radius as f64,
            tol(g.sphere.radius),
        ) {
            return Err(format!("cluster {ci}: self sphere not inside group {}'s sphere", c.group));
        }
        if c.refined_from.is_empty() && (c.self_error != 0.0 || c.level != 0) {
            return Err(format!("cluster {ci}: input cluster with error {} level {}", c.self_error, c.level));
        }
        for &r in &c.refined_from {
            let src =
                dag.groups.get(r as usize).ok_or(format!("cluster {ci}: refined from missing group {r}"))?;
            if src.error != c.self_error || src.sphere != c.self_sphere {
                return Err(format!(
                    "cluster {ci}: self error/sphere {} {:?} differ from source group {r}: {} {:?}",
                    c.self_error, c.self_sphere, src.error, src.sphere
                ));
            }
            if r == c.group {
                return Err(format!("cluster {ci} is refined from its own group"));
            }
            replaced[r as usize] = true;
        }
        if let Some(grid) = grid {
            for &p in &c.positions {
                let s = grid.to_scene(p).map(|v| v as f64);
                let t = grid.step * 2.0;
                if !contains(&c.self_sphere, s, 0.0, t + tol(c.self_sphere.radius))
                    || !contains(&g.sphere, s, 0.0, t + tol(g.sphere.radius))
                {
                    return Err(format!("cluster {ci}: vertex {p:?} outside its spheres"));
                }
            }
        }
    }
    for (gi, g) in dag.groups.iter().enumerate() {
        if g.error.is_finite() != replaced[gi] {
            return Err(format!("group {gi}: error {} but replaced = {}", g.error, replaced[gi]));
        }
    }
    check_steps(dag)
}

/// The store tells the simplification steps apart by error and sphere alone (docs/FORMAT.md,
/// invariant 12): the sources of one group with equal error and sphere must have the same
/// parents, so that the availability rule replaces them together. Two different steps whose
/// input groups share a parent and whose error and sphere are equal break this.
pub fn check_steps(dag: &LodDag) -> Result<(), String> {
    let sources: Vec<Vec<u32>> = dag
        .groups
        .iter()
        .map(|g| {
            let mut s: Vec<u32> = g
                .clusters
                .iter()
                .filter_map(|&c| dag.clusters.get(c as usize))
                .flat_map(|c| c.refined_from.iter().copied())
                .collect();
            s.sort_unstable();
            s.dedup();
            s
        })
        .collect();
    let mut parents: Vec<Vec<u32>> = vec![Vec::new(); dag.groups.len()];
    for (gi, s) in sources.iter().enumerate() {
        for &r in s {
            if let Some(p) = parents.get_mut(r as usize) {
                p.push(gi as u32);
            }
        }
    }
    let key = |s: u32| {
        let g = &dag.groups[s as usize];
        (g.error.to_bits(), g.sphere.center.map(f32::to_bits), g.sphere.radius.to_bits())
    };
    for (gi, s) in sources.iter().enumerate() {
        let mut s: Vec<u32> = s.iter().copied().filter(|&r| (r as usize) < dag.groups.len()).collect();
        s.sort_by_key(|&r| (key(r), r));
        for w in s.windows(2) {
            if key(w[0]) == key(w[1]) && parents[w[0] as usize] != parents[w[1] as usize] {
                return Err(format!(
                    "group {gi}: sources {} and {} have the same error and sphere but different parents \
                     {:?} and {:?}",
                    w[0], w[1], parents[w[0] as usize], parents[w[1] as usize]
                ));
            }
        }
    }
    Ok(())
}

/// Completeness of the cut for `tau`: replays the simplification steps. Start from the input
/// clusters (empty `refined_from`); every group that the cut coarsens (`tau >= error`) must be
/// replaceable, i.e. all of its member clusters present exactly once, and is replaced by the
/// clusters made from it (a cluster made from several groups appears when all of them are
/// replaced). The clusters left must be exactly [`extract_cut`]'s, each once. So every input
/// triangle is represented exactly once, at the granularity of simplification steps.
pub fn check_complete(dag: &LodDag, tau: f32) -> Result<(), String> {
    check_complete_with(dag, |g| tau >= dag.groups[g].error, |c| in_cut(dag, c, tau))
        .map_err(|e| format!("{e} at tau {tau}"))
}

/// [`check_complete`] for any set of coarsened groups (`coarsened(g)`: the cut draws something
/// coarser than group `g`) and the cut `in_cut(c)` that is claimed to follow from it (e.g. the
/// runtime's cut when some pages are missing, docs/FORMAT.md "Availability"): replays the
/// simplification steps of the coarsened groups and checks that exactly the claimed clusters
/// are left, each once.
pub fn check_complete_with(
    dag: &LodDag,
    coarsened: impl Fn(usize) -> bool,
    in_cut: impl Fn(usize) -> bool,
) -> Result<(), String> {
    let ng = dag.groups.len();
    let mut made_from: Vec<Vec<u32>> = vec![Vec::new(); ng];
    let mut sources_left: Vec<usize> = Vec::with_capacity(dag.clusters.len());
    for (ci, c) in dag.clusters.iter().enumerate() {
        for &r in &c.refined_from {
            made_from
                .get_mut(r as usize)
                .ok_or(format!("cluster {ci}: bad refined_from {r}"))?
                .push(ci as u32);
        }
        sources_left.push(c.refined_from.len());
    }
    let mut present = vec![0u32; dag.clusters.len()];
    let mut members_present = vec![0usize; ng];
    let mut done = vec![false; ng];
    let mut ready: Vec<u32> = Vec::new();
    let add = |c: usize, present: &mut Vec<u32>, members_present: &mut Vec<usize>, ready: &mut Vec<u32>| {
        present[c] += 1;
        let g = dag.clusters[c].group as usize;
        members_present[g] += 1;
        if members_present[g] == dag.groups[g].clusters.len() && coarsened(g) {
            ready.push(g as u32);
        }
    };
    for (ci, c) in dag.clusters.iter().enumerate() {
        if c.refined_from.is_empty() {
            add(ci, &mut present, &mut members_present, &mut ready);
        }
    }
    while let Some(g) = ready.pop() {
        let g = g as usize;
        if done[g] {
            return Err(format!("group {g} replaced twice"));
        }
        done[g] = true;
        for &m in &dag.groups[g].clusters {
            if present[m as usize] != 1 {
                return Err(format!("group {g}: member {m} present {} times", present[m as usize]));
            }
            present[m as usize] = 0;
        }
        for &p in &made_from[g] {
            sources_left[p as usize] -= 1;
            if sources_left[p as usize] == 0 {
                add(p as usize, &mut present, &mut members_present, &mut ready);
            }
        }
    }
    if let Some(g) = (0..ng).find(|&g| coarsened(g) && !done[g]) {
        return Err(format!("group {g} is coarsened but not all its clusters are drawn"));
    }
    for (ci, &n) in present.iter().enumerate() {
        let cut = in_cut(ci);
        if n > 1 || (n == 1) != cut {
            return Err(format!("cluster {ci}: present {n} times, in cut {cut}"));
        }
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod fixtures {
    //! Meshes for the LOD tests: closed spheres and tori, cells built from triangle soups.
    use crate::types::{CellMesh, Grid};
    use std::collections::HashMap;

    pub type Soup = Vec<([[f64; 3]; 3], u32)>;

    /// An icosphere with `20 × 4^level` triangles.
    pub fn icosphere(center: [f64; 3], r: f64, level: u32, object: u32) -> Soup {
        let (v, f) = tw_io::generate::icosphere(center, r, level);
        f.iter().map(|t| (t.map(|i| v[i as usize]), object)).collect()
    }

    /// A torus of `2 × nu × nv` triangles; only the quads with `u` in `us` (to split it).
    pub fn torus(nu: usize, nv: usize, us: std::ops::Range<usize>, object: u32) -> Soup {
        let (rr, r) = (10.0, 3.0);
        let p = |u: usize, v: usize| {
            let a = (u % nu) as f64 / nu as f64 * std::f64::consts::TAU;
            let b = (v % nv) as f64 / nv as f64 * std::f64::consts::TAU;
            [(rr + r * b.cos()) * a.cos(), (rr + r * b.cos()) * a.sin(), r * b.sin()]
        };
        let mut out = Vec::new();
        for u in us {
            for v in 0..nv {
                let (a, b, c, d) = (p(u, v), p(u + 1, v), p(u + 1, v + 1), p(u, v + 1));
                out.push(([a, b, c], object));
                out.push(([a, c, d], object));
            }
        }
        out
    }

    /// The grid of a set of soups.
    pub fn grid_for(soups: &[&Soup]) -> Grid {
        let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
        for s in soups {
            for (t, _) in s.iter() {
                for p in t {
                    for i in 0..3 {
                        lo[i] = lo[i].min(p[i]);
                        hi[i] = hi[i].max(p[i]);
                    }
                }
            }
        }
        Grid::for_bounds(lo, hi)
    }

    /// Quantizes and deduplicates (by grid position, first-seen order) into a cell mesh.
    pub fn cell(soup: &Soup, grid: &Grid) -> CellMesh {
        let mut map: HashMap<[u32; 3], u32> = HashMap::new();
        let mut m = CellMesh::default();
        for (t, o) in soup {
            for p in t {
                let q = grid.quantize(*p);
                let n = map.len() as u32;
                let i = *map.entry(q).or_insert_with(|| {
                    m.positions.push(q);
                    n
                });
                m.indices.push(i);
            }
            m.objects.push(*o);
        }
        m
    }

    /// Everything a source streams, as a triangle soup.
    fn soup_of(source: Box<dyn tw_io::TriangleSource>) -> Soup {
        use tw_io::{ImportError, ObjectId, ObjectInfo, Triangle, TriangleSink};
        struct Collect(Soup);
        impl TriangleSink for Collect {
            fn object(&mut self, _id: ObjectId, _info: &ObjectInfo) -> Result<(), ImportError> {
                Ok(())
            }
            fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
                self.0.push((t.positions, t.object));
                Ok(())
            }
        }
        let mut sink = Collect(Vec::new());
        source.stream(&mut sink).expect("the generator streams");
        sink.0
    }

    /// The generated plant as a triangle soup.
    pub fn plant(triangles: u64, seed: u64) -> Soup {
        use tw_io::generate::{PlantParams, PlantSource};
        soup_of(Box::new(PlantSource::new(PlantParams { triangles, seed }).expect("plant params")))
    }

    /// The generated CAD-like assembly (`tw_io::generate::AssemblySource`, one object) as a
    /// triangle soup: thousands of small closed parts.
    pub fn assembly(triangles: u64, seed: u64) -> Soup {
        use tw_io::generate::{AssemblyObjects, AssemblyParams, AssemblySource};
        let params = AssemblyParams { triangles, seed, objects: AssemblyObjects::One };
        soup_of(Box::new(AssemblySource::new(params).expect("assembly params")))
    }

    /// A mesh's non-degenerate triangles as grid positions with objects.
    pub fn mesh_triangles(m: &CellMesh) -> Vec<(super::GridTriangle, u32)> {
        m.indices
            .chunks_exact(3)
            .zip(&m.objects)
            .filter(|(t, _)| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
            .map(|(t, &o)| ([t[0], t[1], t[2]].map(|i| m.positions[i as usize]), o))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::LodGroup;

    fn sphere(c: [f32; 3], r: f32) -> Sphere {
        Sphere { center: c, radius: r }
    }

    /// Two input clusters (one triangle each, a closed "sandwich" is not needed here) in one group,
    /// replaced by one coarser cluster in a root group.
    fn tiny_dag() -> LodDag {
        let tri = |o: u32, lvl: u8, err: f32, s: Sphere, group: u32, from: Vec<u32>| LodCluster {
            positions: vec![[0, 0, 0], [1, 0, 0], [0, 1, 0]],
            indices: vec![0, 1, 2],
            objects: vec![o],
            self_error: err,
            self_sphere: s,
            group,
            level: lvl,
            refined_from: from,
        };
        let s0 = sphere([0.0; 3], 2.0);
        let s1 = sphere([0.0; 3], 3.0);
        LodDag {
            clusters: vec![
                tri(0, 0, 0.0, s0, 0, vec![]),
                tri(1, 0, 0.0, s0, 0, vec![]),
                tri(0, 1, 0.5, s1, 1, vec![0]),
            ],
            groups: vec![
                LodGroup { error: 0.5, sphere: s1, clusters: vec![0, 1], level: 0 },
                LodGroup { error: f32::INFINITY, sphere: s1, clusters: vec![2], level: 1 },
            ],
        }
    }

    #[test]
    fn tiny_dag_is_valid_and_complete() {
        let d = tiny_dag();
        check_dag(&d, None).unwrap();
        for tau in [0.0, 0.4, 0.5, 10.0] {
            check_complete(&d, tau).unwrap();
        }
        assert_eq!(extract_cut(&d, 0.0), vec![0, 1]);
        assert_eq!(extract_cut(&d, 0.5), vec![2]);
    }

    #[test]
    fn non_monotone_error_is_reported() {
        let mut d = tiny_dag();
        d.groups[0].error = 0.1; // below nothing, but now differs from the coarse cluster's self error
        assert!(check_dag(&d, None).is_err());
        let mut d = tiny_dag();
        d.clusters[0].self_error = 1.0;
        assert!(check_dag(&d, None).is_err());
    }

    #[test]
    fn escaping_sphere_is_reported() {
        let mut d = tiny_dag();
        d.clusters[0].self_sphere = sphere([5.0, 0.0, 0.0], 1.0);
        assert!(check_dag(&d, None).unwrap_err().contains("sphere"));
    }

    #[test]
    fn unreplaced_finite_group_is_reported() {
        let mut d = tiny_dag();
        d.clusters[2].refined_from.clear();
        d.clusters[2].self_error = 0.0;
        d.clusters[2].level = 0;
        assert!(check_dag(&d, None).unwrap_err().contains("replaced"));
    }

    #[test]
    fn double_coverage_is_reported() {
        let mut d = tiny_dag();
        d.clusters[2].self_error = 0.0; // coarse cluster now also drawn at tau 0
        assert!(check_complete(&d, 0.0).unwrap_err().contains("in cut true"));
        let mut d = tiny_dag();
        d.groups[1].error = 0.2; // nothing drawn at tau 0.3
        assert!(check_complete(&d, 0.3).is_err());
    }

    #[test]
    fn crack_is_detected() {
        // A closed tetrahedron has no boundary; removing one face leaves three boundary edges.
        let p = [[0, 0, 0], [9, 0, 0], [0, 9, 0], [0, 0, 9]];
        let tet: Vec<GridTriangle> =
            vec![[p[0], p[2], p[1]], [p[0], p[1], p[3]], [p[1], p[2], p[3]], [p[0], p[3], p[2]]];
        assert!(boundary_edges(&tet).is_empty());
        let thin = ThinPieces::new([tet.as_slice()], 1.0);
        check_no_cracks(&tet, &[], &thin, 0.0).unwrap();
        let err = check_no_cracks(&tet[1..], &[], &thin, 0.0).unwrap_err();
        assert!(err.starts_with("3 crack edges"), "{err}");
    }

    /// A thin rod cut in two cells: where its half is missing, the other half's open end is an
    /// opening once τ reaches its thickness (within the slack), never before; a wide plate cut
    /// the same way stays a crack at that τ.
    #[test]
    fn thin_openings_are_bounded_by_the_pieces_thickness() {
        // A square tube along x, 2 units thick, 40 long, split at x = 20 (open ends at x = 0
        // and 40 are the input's border; the ring at x = 20 is the seam).
        let ring = |x: u32| [[x, 0, 0], [x, 2, 0], [x, 2, 2], [x, 0, 2]];
        let tube = |x0: u32, x1: u32| -> Vec<GridTriangle> {
            let (a, b) = (ring(x0), ring(x1));
            (0..4)
                .flat_map(|k| [[a[k], b[k], b[(k + 1) % 4]], [a[k], b[(k + 1) % 4], a[(k + 1) % 4]]])
                .collect()
        };
        let (left, right) = (tube(0, 20), tube(20, 40));
        let input: Vec<GridTriangle> = left.iter().chain(&right).copied().collect();
        let allowed = open_edges(&input);
        let thin = ThinPieces::new([left.as_slice(), right.as_slice()], 1.0);
        // The pieces' bound: every vertex within √2 of the axis (the radius is ~10).
        let seam_edge = ([20, 0, 0], [20, 2, 0]);
        assert!((thin.bound(seam_edge).unwrap() - 2f64.sqrt()).abs() < 1e-6);
        // The right half removed: the seam ring opens.
        assert!(check_no_cracks(&left, &allowed, &thin, 0.5).unwrap_err().starts_with("4 crack edges"));
        check_no_cracks(&left, &allowed, &thin, 1.0).unwrap();
        // A plate 40 wide cut the same way is no thin piece.
        let plate = |x0: u32, x1: u32| -> Vec<GridTriangle> {
            vec![[[x0, 0, 0], [x1, 0, 0], [x1, 40, 0]], [[x0, 0, 0], [x1, 40, 0], [x0, 40, 0]]]
        };
        let (pl, pr) = (plate(0, 20), plate(20, 40));
        let plate_input: Vec<GridTriangle> = pl.iter().chain(&pr).copied().collect();
        let thin = ThinPieces::new([pl.as_slice(), pr.as_slice()], 1.0);
        let err = check_no_cracks(&pl, &open_edges(&plate_input), &thin, 1.0).unwrap_err();
        assert!(err.starts_with("1 crack edges"), "{err}");
    }

    #[test]
    fn canonical_keeps_winding() {
        let t = [[2, 0, 0], [0, 0, 0], [1, 0, 0]];
        assert_eq!(canonical(t), [[0, 0, 0], [1, 0, 0], [2, 0, 0]]);
        let u = [[2, 0, 0], [1, 0, 0], [0, 0, 0]];
        assert_eq!(canonical(u), [[0, 0, 0], [2, 0, 0], [1, 0, 0]]);
    }
}
