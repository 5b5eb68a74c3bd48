//! Phase 2: GigaWalk's object redefinition, out of core (Baxter et al. 2002, GigaWalk §4.2;
//! Govindaraju 2004 thesis §3.3 and its parameter table; docs/DESIGN.md, D12).
//!
//! The input objects are redefined into *cells*, the leaves of the scene hierarchy:
//! 1. **Partition-I** (`partition_objects`): an object with more than `t1` triangles whose box
//!    has a diagonal above `s1` or an aspect ratio above `r1` is split along its longest axis at
//!    the median of its triangle centroids (the next axis when that split is unbalanced), and the
//!    pieces again, until every piece meets the thresholds.
//! 2. **Clustering** (`cluster_pieces`): Felzenszwalb–Huttenlocher segmentation of the graph
//!    whose nodes are the pieces and whose edges join pieces whose boxes are within distance `D`:
//!    edges by ascending weight, Kruskal style; components `C1`, `C2` merge when
//!    `w ≤ min(I(C1) + K/|C1|, I(C2) + K/|C2|)` (`I(C)` = the largest MST edge inside `C`), never
//!    when the merged box's volume would exceed `V`.
//! 3. **Partition-II** (`partition_clusters`): a cluster with more than `t2` triangles and a
//!    diagonal above `s2` or an aspect ratio above `r2` is split about its centre of mass
//!    (recursively), as is any cluster above `max_cell_triangles`.
//!
//! 4. **Count split** (`split_by_count`): a cell still above `max_cell_triangles` (space could
//!    not split it: its triangles' centroids coincide, or every plane left them on one side, or
//!    the samples misjudged its count) is cut into runs of consecutive working-file triangles.
//!
//! The hierarchy over the resulting cells is built by [`Redefined::order_by_hierarchy`].
//!
//! Files: `samples` (pass A), `partition1`, `pieces` (pass B), `cluster`, `partition2`,
//! `cell_stats` (pass C) and `count_split` (pass D) are the steps, in order; `assign` is the
//! triangle → cell function they build, `scan` how the passes read the working file, and
//! `geometry` the shared box helpers.
//!
//! # Out of core
//!
//! Splitting needs triangle centroids, which do not fit in memory at 10^9 triangles. So the
//! splits are *planned* from a deterministic sample and *applied* while streaming: every split is
//! a kd-tree of planes over centroids, and a triangle's cell is a pure function of its object id
//! and its centroid ([`Redefined::cell_of`]), evaluated the same way in every pass.
//! Three passes, of which only B and C usually read the working file (and a fourth, D, only
//! when a cell is above `max_cell_triangles` after C):
//! - A (`sample_objects`): every object of more than `t1` triangles keeps the centroids of every
//!   `stride`-th triangle, a power of two that keeps the total between `max_samples` and twice
//!   that, and at least `min_samples_per_object` per object ([`crate::sampling`]). Ingest takes
//!   these samples while it streams the triangles; the file is read for them only when it could
//!   not (objects not contiguous in the input), with the same result.
//! - B (`piece_stats`): after partition-I planned the pieces from the samples, the exact triangle
//!   count, bounds and centre of mass of every piece. An object partition-I leaves whole is one
//!   piece, whose figures ingest already summed in file order (`ObjectRecord::centroid_sum`
//!   and its offset box); only the objects it cuts are read again (their spans: 29 % of the
//!   10^7 plant's triangles).
//! - C (`cell_stats`): after clustering and partition-II, the exact count and bounds of every
//!   cell (empty cells, possible since plans come from samples, are dropped). Pieces placed
//!   whole add their pass-B figures; only the objects whose pieces a partition-II plan cuts
//!   are read again (their spans of the file, recorded by ingest).
//! - D (`split_by_count`): for the cells above `max_cell_triangles`, the count and box of
//!   their triangles per block of consecutive working-file triangles (the spans of the objects
//!   that reach them), from which each is cut into runs of whole blocks. A triangle's cell is
//!   then a function of its object, its centroid and, in those cells only, its position in the
//!   working file ([`Redefined::cell_of`]).
//!
//! Threads: the passes get raw records from a reader thread ([`crate::ingest::WorkFile::scan_raw`]); the pool
//! decodes them and finds each triangle's piece or cell in fixed sub-chunks, then accumulates
//! in `LANES` lanes by key ([`crate::workio::for_each_lane`]), so that every piece's centroid sum adds its
//! triangles in file order whatever the number of threads. Pass A only counts object ids.
//!
//! Memory: O(objects + samples + pieces · `neighbours`), nothing per triangle (pass D: one
//! entry per block of a cut cell, about two per cell it makes).
//!
//! # Choices (where the papers leave room)
//!
//! - Sizes are relative to the scene: `s1`, `s2` and `D` are fractions of the scene's largest
//!   extent ("model dimension", "largest bounding-box dimension"), `V` a fraction of the scene
//!   box's volume, so the defaults fit any model in any unit.
//! - The aspect ratio of a box is its longest extent over its second longest (a flat plate is not
//!   "uneven", a pipe is); an extent of zero counts as infinitely thin.
//! - Inside a plan, node sizes are estimated from the samples: the count is samples × stride and
//!   the box is the samples' centroid box (for partition-II, the union of the boxes of the whole
//!   pieces and of the sampled centroids).
//! - The graph is the `neighbours` nearest pieces of every piece within `D` (the k-nearest-
//!   neighbour graph of Felzenszwalb–Huttenlocher's §4), found with an AABB tree over the piece
//!   boxes: O(n log n) and O(k n) memory even when thousands of bolts sit within `D` of each other.
//! - Edge weight = box distance / `D` (0 for overlapping boxes), so `K` is unit-free. `|C|` is the
//!   number of *triangles* in `C`: with `K` = 1500, a cluster under 1 500 triangles accepts any
//!   neighbour within `D`, one of 15 000 only neighbours within `D/10` (plus `I(C)`); this is what
//!   makes clusters stop growing at a useful size whatever the object granularity of the input.
//! - Felzenszwalb–Huttenlocher's post-pass is added: a cluster under `min_cell_triangles` joins
//!   its nearest neighbour (edges again in ascending order) regardless of `K`, within
//!   `max_cell_triangles` and twice `V`. Without it, `V` strands small objects next to full
//!   clusters (a bolt beside a full room): a tenth of the cells had under 100 triangles.
//! - Box volumes clamp each extent to at least 10⁻³ of the scene's largest extent, so flat boxes
//!   still have a volume and `V` still limits them.
//! - Partition-II splits at the centre of mass; when that leaves less than a quarter of the
//!   weight on one side it splits at the weighted median instead. Pieces of at most `t1`
//!   triangles are placed whole (by their centre of mass); larger pieces are cut by centroid.
//!
//! # Cell size
//!
//! The renderer wants cells of roughly 1k–64k triangles (128-triangle clusters need bulk for good
//! LOD; larger cells cull worse). Partition-I cuts big uneven objects into pieces no longer than
//! `s1` (it stops below `t1`, so a piece has at least about `t1`/2 triangles); clustering glues
//! pieces and small objects until `K/|C|` or `V` stops it, never beyond `max_cell_triangles`,
//! and its post-pass folds clusters under `min_cell_triangles` (1 024) into a neighbour;
//! partition-II cuts clusters above `t2` = 10 000 triangles that are not compact (aspect > 1.25)
//! or are larger than `s2`, and every cluster above `max_cell_triangles` (default 65 536), into
//! halves of at least a quarter each. Cells under 1k triangles remain only where objects are
//! isolated (nothing within `D`) or boxed in by `2 V`. Because plans come from samples, a cell
//! can exceed `max_cell_triangles` by the sampling error, and no plane splits triangles whose
//! centroids coincide (a part placed many times at one spot); the count split cuts those, so
//! that no cell is above `max_cell_triangles`. The report gives the smallest and the largest
//! cell and how many the count split cut.

mod assign;
mod cell_stats;
mod cluster;
mod count_split;
mod geometry;
mod partition1;
mod partition2;
mod pieces;
mod samples;
mod scan;
#[cfg(test)]
mod tests;

use assign::{Assigner, ObjectRoute, Route};
use cell_stats::cell_stats;
use cluster::cluster_pieces;
use count_split::split_by_count;
use geometry::Scale;
use partition1::partition_objects;
use partition2::partition_clusters;
use pieces::piece_stats;
use samples::sample_objects;

use crate::error::BuildError;
use crate::hierarchy::Hierarchy;
use crate::ingest::{Ingested, WorkTri};
use crate::sampling::SampleRule;
use crate::types::GridBox;

/// The thresholds of object redefinition (see the module docs for their meaning and units).
#[derive(Clone, Debug, PartialEq)]
pub struct RedefineParams {
    /// Partition-I: only objects with more than `t1` triangles are split.
    pub t1: u64,
    /// Partition-I: box diagonal limit, as a fraction of the scene's largest extent.
    pub s1: f64,
    /// Partition-I: aspect ratio limit (longest / second longest extent).
    pub r1: f64,
    /// Clustering: edge length limit `D`, as a fraction of the scene's largest extent.
    pub d: f64,
    /// Clustering: the Felzenszwalb–Huttenlocher constant `K` (triangles × distance / `D`).
    pub k: f64,
    /// Clustering: largest merged box volume `V`, as a fraction of the scene box's volume.
    pub v: f64,
    /// Partition-II: only clusters with more than `t2` triangles are split (unless above
    /// `max_cell_triangles`).
    pub t2: u64,
    /// Partition-II: box diagonal limit, as a fraction of the scene's largest extent.
    pub s2: f64,
    /// Partition-II: aspect ratio limit.
    pub r2: f64,
    /// No cluster grows beyond this and partition-II splits every cell above it.
    pub max_cell_triangles: u64,
    /// Clustering's post-pass (Felzenszwalb–Huttenlocher's minimum component size): a cluster
    /// under this many triangles joins its nearest neighbour within `D` regardless of `K`, as
    /// long as the result stays within `max_cell_triangles` and twice `V`. 0 disables it.
    pub min_cell_triangles: u64,
    /// Clustering: each piece is joined to at most this many nearest pieces within `D`.
    pub neighbours: usize,
    /// Centroid samples kept in memory for planning splits (12 bytes each): between this and
    /// twice this, plus up to twice `min_samples_per_object` for each sampled object (ingest
    /// holds about twice this more while streaming: `sampling`, "Memory").
    pub max_samples: u64,
    /// Every object of more than `t1` triangles keeps at least this many samples.
    pub min_samples_per_object: u64,
}

impl Default for RedefineParams {
    fn default() -> Self {
        RedefineParams::gigawalk()
    }
}

impl RedefineParams {
    /// The thesis table: t1 1000, s1 0.1 × model dimension, r1 2.5, D 0.1 × largest dimension,
    /// K 1500, V 10⁻³ × scene volume, s2 2·s1, t2 10·t1, r2 0.5·r1; plus terawalk's cell cap.
    /// The rule of redefinition's centroid samples ([`crate::sampling`]).
    pub(crate) fn sample_rule(&self) -> SampleRule {
        SampleRule {
            t1: self.t1,
            max_samples: self.max_samples,
            min_samples_per_object: self.min_samples_per_object,
        }
    }

    pub fn gigawalk() -> RedefineParams {
        RedefineParams {
            t1: 1000,
            s1: 0.1,
            r1: 2.5,
            d: 0.1,
            k: 1500.0,
            v: 1e-3,
            t2: 10_000,
            s2: 0.2,
            r2: 1.25,
            max_cell_triangles: 1 << 16,
            min_cell_triangles: 1024,
            neighbours: 10,
            max_samples: 2_000_000,
            min_samples_per_object: 64,
        }
    }

    fn check(&self) -> Result<(), BuildError> {
        let bad = |what: &str| Err(BuildError::Param(format!("redefine: {what}")));
        let positive = [("s1", self.s1), ("r1", self.r1), ("s2", self.s2), ("r2", self.r2), ("v", self.v)];
        for (name, x) in positive {
            if !(x.is_finite() && x > 0.0) {
                return bad(&format!("{name} = {x} must be positive"));
            }
        }
        if !(self.d.is_finite() && self.d >= 0.0 && self.k.is_finite() && self.k >= 0.0) {
            return bad("d and k must be finite and not negative");
        }
        if self.t1 == 0 || self.t2 == 0 || self.max_cell_triangles == 0 {
            return bad("t1, t2 and max_cell_triangles must be at least 1");
        }
        if self.max_samples == 0 || self.min_samples_per_object < 2 {
            return bad("max_samples must be at least 1 and min_samples_per_object at least 2");
        }
        Ok(())
    }
}

/// Counts after each step (the papers' Table 1), and what the cells came to.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct RedefineReport {
    /// Input objects with at least one triangle.
    pub objects: u64,
    /// Objects that partition-I split.
    pub split_objects: u64,
    /// Non-empty pieces after partition-I.
    pub pieces: u64,
    /// Centroid samples used for planning.
    pub samples: u64,
    /// Edges of the clustering graph.
    pub edges: u64,
    /// Clusters after clustering.
    pub clusters: u64,
    /// Clusters that partition-II split.
    pub split_clusters: u64,
    /// Non-empty cells after partition-II.
    pub cells: u64,
    pub min_cell_triangles: u64,
    pub max_cell_triangles: u64,
    /// Cells above `max_cell_triangles` after partition-II, cut by count (`split_by_count`).
    pub count_split_cells: u64,
}

/// One cell (a redefined object, a hierarchy leaf).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CellInfo {
    pub triangles: u64,
    /// Contains every quantized vertex of the cell's triangles.
    pub bounds: GridBox,
}

/// The redefinition: the cells and the function that sends each triangle to its cell.
#[derive(Clone, Debug)]
pub struct Redefined {
    /// Every cell, non-empty, indexed by cell id.
    pub cells: Vec<CellInfo>,
    pub report: RedefineReport,
    assign: Assigner,
}

impl Redefined {
    /// The cell of working-file triangle `index`, `t`: a function of its object and centroid,
    /// and of `index` only in the cells that the count split cut (`split_by_count`).
    #[inline]
    pub fn cell_of(&self, t: &WorkTri, index: u64) -> u32 {
        self.assign.final_cell(self.assign.cell(t, index), index)
    }

    /// Builds the AABB tree over the cells and renumbers the cells in its leaf order (so that
    /// spatially close cells get close ids). Returns the tree, its leaves naming the new ids.
    pub fn order_by_hierarchy(&mut self) -> Hierarchy {
        let boxes: Vec<GridBox> = self.cells.iter().map(|c| c.bounds).collect();
        let mut h = Hierarchy::build(&boxes);
        let order = h.leaf_order();
        let mut new_id = vec![u32::MAX; self.cells.len()];
        for (k, &c) in order.iter().enumerate() {
            new_id[c as usize] = k as u32;
        }
        h.renumber(&new_id);
        self.cells = order.iter().map(|&c| self.cells[c as usize]).collect();
        self.assign.remap_cells(&new_id);
        h
    }
}

/// Runs the three steps over an ingested scene (three passes over its working file).
pub fn redefine(ing: &Ingested, params: &RedefineParams) -> Result<Redefined, BuildError> {
    params.check()?;
    let scale = Scale::new(ing, params);
    let mut report = RedefineReport {
        objects: ing.objects.iter().filter(|o| o.triangles > 0).count() as u64,
        ..Default::default()
    };
    let mut lap = crate::types::StepTimer::new("redefine");
    let mut samples = sample_objects(ing, params)?;
    lap.step("pass A: samples");
    report.samples = samples.points.len() as u64;
    let mut assign = Assigner::default();
    let piece_object = partition_objects(ing, params, &scale, &mut samples, &mut assign, &mut report);
    lap.step("partition-I");
    let pieces = piece_stats(ing, &assign, piece_object.len())?;
    lap.step("pass B: pieces");
    let clusters = cluster_pieces(params, &scale, &pieces, &mut report);
    lap.step("clustering");
    let cell_count =
        partition_clusters(ing, params, &scale, &samples, &pieces, &clusters, &mut assign, &mut report);
    lap.step("partition-II");
    if tracing::enabled!(tracing::Level::DEBUG) {
        let cut: u64 = (0..pieces.count.len())
            .filter(|&q| matches!(assign.piece_cell[q], Route::Plan(_)))
            .map(|q| pieces.count[q])
            .sum();
        let cut_objects = (0..ing.objects.len())
            .filter(|&o| matches!(assign.object_piece[o], ObjectRoute::Plan(_)))
            .count();
        tracing::debug!(cut_piece_triangles = cut, split_objects = cut_objects, "partition-II routes");
    }
    let cells = cell_stats(ing, &assign, &pieces, &piece_object, cell_count)?;
    lap.step("pass C: cells");
    // Drop the cells no triangle reached.
    let mut new_id = vec![u32::MAX; cells.len()];
    let mut kept = Vec::new();
    for (c, info) in cells.iter().enumerate() {
        if info.triangles > 0 {
            new_id[c] = kept.len() as u32;
            kept.push(*info);
        }
    }
    assign.remap_cells(&new_id);
    let kept = split_by_count(ing, params, &pieces, &piece_object, &mut assign, kept, &mut report)?;
    lap.step("pass D: count split");
    report.cells = kept.len() as u64;
    report.min_cell_triangles = kept.iter().map(|c| c.triangles).min().unwrap_or(0);
    report.max_cell_triangles = kept.iter().map(|c| c.triangles).max().unwrap_or(0);
    tracing::debug!(?report, "redefined");
    Ok(Redefined { cells: kept, report, assign })
}
