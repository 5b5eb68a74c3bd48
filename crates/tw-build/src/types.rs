//! Plain data handed between the build phases.

/// The scene-wide quantization grid. Every position after ingest is a `[u32; 3]` grid point;
/// scene space (f32, what the runtime uses) is `grid * step`, relative to `origin`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Grid {
    /// Input coordinates of grid point (0, 0, 0): the scene bounds' minimum.
    pub origin: [f64; 3],
    /// Size of one grid step in input units; longest extent / (2^24 - 1).
    pub step: f64,
}

/// Number of grid steps across the longest extent: coordinates fit in 24 bits, exact in f32.
pub const GRID_STEPS: u32 = (1 << 24) - 1;

impl Grid {
    /// The grid for scene bounds `min..max` (input coordinates, f64).
    pub fn for_bounds(min: [f64; 3], max: [f64; 3]) -> Grid {
        let extent = (0..3).map(|i| max[i] - min[i]).fold(0.0f64, f64::max);
        let step = if extent > 0.0 { extent / GRID_STEPS as f64 } else { 1.0 };
        Grid { origin: min, step }
    }

    /// The grid point nearest to an input position (clamped to the grid).
    pub fn quantize(&self, p: [f64; 3]) -> [u32; 3] {
        let q = |i: usize| ((p[i] - self.origin[i]) / self.step).round().clamp(0.0, GRID_STEPS as f64) as u32;
        [q(0), q(1), q(2)]
    }

    /// Scene-space position (f32, relative to the origin) of a grid point.
    pub fn to_scene(&self, g: [u32; 3]) -> [f32; 3] {
        [(g[0] as f64 * self.step) as f32, (g[1] as f64 * self.step) as f32, (g[2] as f64 * self.step) as f32]
    }

    /// Input coordinates of a grid point.
    pub fn to_input(&self, g: [u32; 3]) -> [f64; 3] {
        [
            self.origin[0] + g[0] as f64 * self.step,
            self.origin[1] + g[1] as f64 * self.step,
            self.origin[2] + g[2] as f64 * self.step,
        ]
    }
}

/// An axis-aligned box in grid coordinates (inclusive).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct GridBox {
    pub min: [u32; 3],
    pub max: [u32; 3],
}

impl GridBox {
    pub const EMPTY: GridBox = GridBox { min: [u32::MAX; 3], max: [0; 3] };

    pub fn is_empty(&self) -> bool {
        (0..3).any(|i| self.min[i] > self.max[i])
    }

    pub fn grow(&mut self, p: [u32; 3]) {
        for (i, v) in p.into_iter().enumerate() {
            self.min[i] = self.min[i].min(v);
            self.max[i] = self.max[i].max(v);
        }
    }

    pub fn union(&self, o: &GridBox) -> GridBox {
        let mut b = *self;
        for i in 0..3 {
            b.min[i] = b.min[i].min(o.min[i]);
            b.max[i] = b.max[i].max(o.max[i]);
        }
        b
    }

    #[cfg(test)]
    pub fn contains(&self, o: &GridBox) -> bool {
        (0..3).all(|i| self.min[i] <= o.min[i] && o.max[i] <= self.max[i])
    }
}

/// One input object, as ingest saw it.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectRecord {
    pub name: String,
    /// sRGB colour with alpha; `None` when the file gave none.
    pub color: Option<[u8; 4]>,
    pub triangles: u64,
    pub bounds: GridBox,
    /// The box of its vertices as working-file offsets (`f32`, before quantization; +∞/−∞
    /// when it has no triangle): what a scan of its triangles would find.
    pub offset_min: [f32; 3],
    pub offset_max: [f32; 3],
    /// The sum of its triangles' centroids ([`crate::ingest::WorkTri::centroid`] as `f64`),
    /// added in working-file order: what a serial scan of its triangles would find.
    pub centroid_sum: [f64; 3],
    /// The working-file triangles from its first to its last (empty: no triangle).
    pub span: std::ops::Range<u64>,
    /// Where its triangles pass from one group of whole closed parts to the next (indices from
    /// its first triangle, ascending; empty: one group): `crate::parts`.
    pub part_starts: Vec<u64>,
}

/// The indexed mesh of one cell (a redefined object: a hierarchy leaf), read back from the
/// working files. Vertices are deduplicated by exact grid position within the cell, so that
/// simplification sees connectivity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellMesh {
    pub positions: Vec<[u32; 3]>,
    /// Three indices per triangle into `positions`.
    pub indices: Vec<u32>,
    /// The input object id of each triangle (`indices.len() / 3` entries).
    pub objects: Vec<u32>,
    /// Exact duplicate triangles left out when the mesh was read (see
    /// `crate::cells::Bucket::mesh`): counted so that the build can report them.
    pub duplicates: u64,
}

impl CellMesh {
    #[cfg(test)]
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

/// A bounding sphere in scene space (f32, relative to the grid origin).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sphere {
    pub center: [f32; 3],
    pub radius: f32,
}

/// One cluster of the LOD DAG: ≤ 128 triangles, ≤ 255 vertices.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LodCluster {
    /// Grid positions of the cluster's vertices.
    pub positions: Vec<[u32; 3]>,
    /// Three local indices per triangle.
    pub indices: Vec<u8>,
    /// Input object id per triangle.
    pub objects: Vec<u32>,
    /// Error (scene units) of the simplification that produced this cluster: 0 for input clusters.
    pub self_error: f32,
    /// Where `self_error` is measured from (the sphere of the group this cluster was made from;
    /// for input clusters, the cluster's own bounding sphere).
    pub self_sphere: Sphere,
    /// Index of the group this cluster belongs to (in the same [`LodDag`]).
    pub group: u32,
    /// The groups whose simplification produced this cluster (their `error`/`sphere` equal this
    /// cluster's `self_error`/`self_sphere`): empty for input clusters, one group inside a cell,
    /// every root group of the node's children for an HLOD cluster. Indices into the same
    /// [`LodDag`] (for HLOD clusters: the caller's scene-wide group ids, see `hlod`).
    pub refined_from: Vec<u32>,
    /// 0 for full-resolution clusters, +1 per simplification step (HLOD continues the count).
    pub level: u8,
}

/// One group of the LOD DAG: clusters simplified together.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LodGroup {
    /// Error (scene units) of the coarser clusters that replace this group; `f32::INFINITY` for a
    /// root group (nothing replaces it). Always ≥ the `self_error` of each member cluster.
    pub error: f32,
    /// Bounds the group's geometry; contains the member clusters' `self_sphere`s.
    pub sphere: Sphere,
    /// Member clusters (indices into [`LodDag::clusters`]).
    pub clusters: Vec<u32>,
    /// The simplification level of the member clusters (the max if mixed).
    pub level: u8,
}

/// A cluster DAG: the LOD of one cell, or of an HLOD node together with what it was built from.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LodDag {
    pub clusters: Vec<LodCluster>,
    pub groups: Vec<LodGroup>,
}

impl LodDag {
    /// Bytes the DAG holds on the heap (its vectors' capacities), for memory accounting.
    pub fn heap_bytes(&self) -> usize {
        use std::mem::size_of;
        let clusters: usize = self
            .clusters
            .iter()
            .map(|c| {
                c.positions.capacity() * size_of::<[u32; 3]>()
                    + c.indices.capacity()
                    + (c.objects.capacity() + c.refined_from.capacity()) * size_of::<u32>()
            })
            .sum();
        let groups: usize = self.groups.iter().map(|g| g.clusters.capacity() * size_of::<u32>()).sum();
        clusters
            + groups
            + self.clusters.capacity() * size_of::<LodCluster>()
            + self.groups.capacity() * size_of::<LodGroup>()
    }
}

/// The render rule, in object space: cluster `c` is part of the cut for error threshold `tau`
/// (scene units) when `self_error <= tau < group.error`. (The runtime uses the projected form.)
pub fn in_cut(dag: &LodDag, cluster: usize, tau: f32) -> bool {
    let c = &dag.clusters[cluster];
    c.self_error <= tau && tau < dag.groups[c.group as usize].error
}

/// Times the steps of a phase: each [`StepTimer::step`] logs (debug level, target `tw_build`)
/// the seconds since the previous one, for profiling the build (`TERAWALK_LOG=tw_build=debug`).
pub struct StepTimer {
    phase: &'static str,
    last: std::time::Instant,
}

impl StepTimer {
    pub fn new(phase: &'static str) -> StepTimer {
        StepTimer { phase, last: std::time::Instant::now() }
    }

    pub fn step(&mut self, step: &str) {
        let now = std::time::Instant::now();
        tracing::debug!(phase = self.phase, step, seconds = (now - self.last).as_secs_f64(), "step");
        self.last = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_quantizes_exactly_and_round_trips() {
        let g = Grid::for_bounds([-10.0, 0.0, 5.0], [290.0, 100.0, 20.0]);
        assert_eq!(g.quantize([-10.0, 0.0, 5.0]), [0, 0, 0]);
        assert_eq!(g.quantize([290.0, 0.0, 5.0])[0], GRID_STEPS);
        let p = [12.345678, 55.5, 7.25];
        let q = g.quantize(p);
        let back = g.to_input(q);
        for i in 0..3 {
            assert!((back[i] - p[i]).abs() <= g.step * 0.5 + 1e-12);
        }
        assert_eq!(g.quantize(p), g.quantize(back), "quantization is idempotent");
    }

    #[test]
    fn degenerate_bounds_get_a_unit_step() {
        let g = Grid::for_bounds([1.0; 3], [1.0; 3]);
        assert_eq!(g.step, 1.0);
        assert_eq!(g.quantize([1.0; 3]), [0, 0, 0]);
    }
}
