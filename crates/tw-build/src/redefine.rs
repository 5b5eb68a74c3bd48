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
//! Threads: the passes get raw records from a reader thread ([`WorkFile::scan_raw`]); the pool
//! decodes them and finds each triangle's piece or cell in fixed sub-chunks, then accumulates
//! in `LANES` lanes by key ([`for_each_lane`]), so that every piece's centroid sum adds its
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

use rayon::prelude::*;

use crate::error::BuildError;
use crate::hierarchy::Hierarchy;
use crate::ingest::{record_object, records, Ingested, WorkFile, WorkTri, RECORD_BYTES};
use crate::sampling::SampleRule;
use crate::types::{Grid, GridBox};
use crate::workio::{for_each_lane, SUB_CHUNK};

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
    /// holds up to 8 times this while streaming: [`crate::sampling`]).
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
    pub fn sample_rule(&self) -> SampleRule {
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
#[derive(Clone, Debug, Default, PartialEq, Eq)]
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

// ---------------------------------------------------------------------------------------------
// Geometry helpers

/// The scene-relative thresholds in input units.
struct Scale {
    step: f64,
    s1: f64,
    s2: f64,
    d: f64,
    v: f64,
    /// Smallest extent used for volumes.
    floor: f64,
}

impl Scale {
    fn new(ing: &Ingested, p: &RedefineParams) -> Scale {
        let ext: Vec<f64> = (0..3).map(|i| ing.max[i] - ing.min[i]).collect();
        let largest = ext.iter().copied().fold(0.0, f64::max);
        let largest = if largest > 0.0 { largest } else { 1.0 };
        let floor = 1e-3 * largest;
        let volume: f64 = ext.iter().map(|e| e.max(floor)).product();
        Scale {
            step: ing.grid.step,
            s1: p.s1 * largest,
            s2: p.s2 * largest,
            d: p.d * largest,
            v: p.v * volume,
            floor,
        }
    }

    fn grid_ext(&self, b: &GridBox) -> [f64; 3] {
        let e = |i: usize| b.max[i].saturating_sub(b.min[i]) as f64 * self.step;
        [e(0), e(1), e(2)]
    }

    fn volume(&self, b: &GridBox) -> f64 {
        self.grid_ext(b).iter().map(|e| e.max(self.floor)).product()
    }
}

fn diag(e: [f64; 3]) -> f64 {
    (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
}

/// Longest extent over the second longest.
fn aspect(e: [f64; 3]) -> f64 {
    let mut s = e;
    s.sort_by(|a, b| b.total_cmp(a));
    if s[0] <= 0.0 {
        1.0
    } else if s[1] <= 0.0 {
        f64::INFINITY
    } else {
        s[0] / s[1]
    }
}

/// Axes by decreasing extent (ties: lower axis first).
fn axes_by_extent(e: [f64; 3]) -> [usize; 3] {
    let mut a = [0, 1, 2];
    a.sort_by(|&x, &y| e[y].total_cmp(&e[x]));
    a
}

/// The smallest f32 above `v` (finite, non-NaN `v`).
fn next_up(v: f32) -> f32 {
    if v == 0.0 {
        return f32::from_bits(1);
    }
    let b = v.to_bits();
    f32::from_bits(if v > 0.0 { b + 1 } else { b - 1 })
}

/// A box in working-file coordinates (f32 offsets, input units).
#[derive(Clone, Copy, Debug)]
struct FBox {
    min: [f32; 3],
    max: [f32; 3],
}

impl FBox {
    const EMPTY: FBox = FBox { min: [f32::INFINITY; 3], max: [f32::NEG_INFINITY; 3] };

    #[inline]
    fn grow(&mut self, p: [f32; 3]) {
        for (i, x) in p.into_iter().enumerate() {
            self.min[i] = self.min[i].min(x);
            self.max[i] = self.max[i].max(x);
        }
    }

    /// Grows to contain `o`, which must not be empty (an empty box's +∞ minimum would become
    /// this box's maximum).
    fn union(&mut self, o: &FBox) {
        self.grow(o.min);
        self.grow(o.max);
    }

    fn ext(&self) -> [f64; 3] {
        let e = |i: usize| (self.max[i] as f64 - self.min[i] as f64).max(0.0);
        [e(0), e(1), e(2)]
    }

    fn to_grid(self, work: &WorkFile, grid: &Grid) -> GridBox {
        GridBox { min: work.quantize(grid, self.min), max: work.quantize(grid, self.max) }
    }
}

/// Moves the elements satisfying `pred` to the front; returns how many there are.
fn partition_in_place<T>(v: &mut [T], pred: impl Fn(&T) -> bool) -> usize {
    let mut n = 0;
    for i in 0..v.len() {
        if pred(&v[i]) {
            v.swap(n, i);
            n += 1;
        }
    }
    n
}

// ---------------------------------------------------------------------------------------------
// The triangle → cell function

/// A kd-tree node: a leaf (`axis == LEAF`, id in `a`) or a plane: centroids with
/// `c[axis] < pos` go to node `a`, the others to node `b`.
#[derive(Clone, Copy, Debug)]
struct KdNode {
    axis: u8,
    pos: f32,
    a: u32,
    b: u32,
}

const LEAF: u8 = 3;

impl KdNode {
    fn leaf(id: u32) -> KdNode {
        KdNode { axis: LEAF, pos: 0.0, a: id, b: 0 }
    }
}

#[inline]
fn walk(kd: &[KdNode], mut n: u32, c: [f32; 3]) -> u32 {
    loop {
        let k = kd[n as usize];
        if k.axis == LEAF {
            return k.a;
        }
        n = if c[k.axis as usize] < k.pos { k.a } else { k.b };
    }
}

/// Where a triangle goes: a fixed id, or the leaf of a kd plan (the root's index).
#[derive(Clone, Copy, Debug)]
enum Route {
    Fixed(u32),
    Plan(u32),
}

/// Where an object's triangle goes in partition-I: a [`Route`] to a piece, or, for an object
/// split at its part groups (`crate::parts`), the group's piece (index into [`Assigner::parts`]).
#[derive(Clone, Copy, Debug)]
enum ObjectRoute {
    Fixed(u32),
    Plan(u32),
    Parts(u32),
}

/// An object split at its part groups: group `g` (0 from its first triangle, then one more at
/// each start) is piece `first_piece + g`.
#[derive(Clone, Debug, Default)]
struct PartRoute {
    first_piece: u32,
    span_start: u64,
    starts: Vec<u64>,
}

#[derive(Clone, Debug, Default)]
struct Assigner {
    /// Partition-I plans; leaves are piece ids.
    plan1: Vec<KdNode>,
    /// Partition-II plans; leaves are cell ids.
    plan2: Vec<KdNode>,
    /// Per object.
    object_piece: Vec<ObjectRoute>,
    /// The objects split at their part groups (`ObjectRoute::Parts`).
    parts: Vec<PartRoute>,
    /// Per piece.
    piece_cell: Vec<Route>,
    /// Per cell (empty: none cut): the index in `splits` of the cell's count split, or
    /// `u32::MAX`. Keyed by the cell the routes give, which is also the split's first part.
    count_split: Vec<u32>,
    splits: Vec<CountSplit>,
}

/// How the count split cut one cell: part `j` holds the cell's triangles of working-file index
/// in `starts[j - 1]..starts[j]` (part 0 from 0, the last to the end), and is cell `cells[j]`.
#[derive(Clone, Debug, Default)]
struct CountSplit {
    starts: Vec<u64>,
    cells: Vec<u32>,
}

impl PartRoute {
    /// The piece of the object's working-file triangle `index`.
    #[inline]
    fn piece(&self, index: u64) -> u32 {
        let rel = index.saturating_sub(self.span_start);
        self.first_piece + self.starts.partition_point(|&s| s <= rel) as u32
    }
}

impl Assigner {
    /// The piece of working-file triangle `index`, `t`.
    #[inline]
    fn piece(&self, t: &WorkTri, index: u64) -> u32 {
        match self.object_piece[t.object as usize] {
            ObjectRoute::Fixed(p) => p,
            ObjectRoute::Plan(root) => walk(&self.plan1, root, t.centroid()),
            ObjectRoute::Parts(k) => self.parts[k as usize].piece(index),
        }
    }

    #[inline]
    fn cell(&self, t: &WorkTri, index: u64) -> u32 {
        match self.piece_cell[self.piece(t, index) as usize] {
            Route::Fixed(c) => c,
            Route::Plan(root) => walk(&self.plan2, root, t.centroid()),
        }
    }

    /// The final cell of working-file triangle `index` whose routes give cell `c`: one of the
    /// parts of `c` if the count split cut it, else `c`.
    #[inline]
    fn final_cell(&self, c: u32, index: u64) -> u32 {
        match self.count_split.get(c as usize) {
            Some(&s) if s != u32::MAX => {
                let split = &self.splits[s as usize];
                split.cells[split.starts.partition_point(|&start| start <= index)]
            }
            _ => c,
        }
    }

    /// Cell `c` becomes `map[c]` (`u32::MAX` for cells that no triangle reaches).
    fn remap_cells(&mut self, map: &[u32]) {
        let m = |c: u32| map.get(c as usize).copied().unwrap_or(u32::MAX);
        if !self.count_split.is_empty() {
            // New ids are below the old count: re-key the splits by the new ids.
            let mut keyed = vec![u32::MAX; map.len()];
            for (c, &s) in self.count_split.iter().enumerate() {
                if let Some(slot) = keyed.get_mut(m(c as u32) as usize) {
                    *slot = s;
                }
            }
            self.count_split = keyed;
            for split in &mut self.splits {
                for c in &mut split.cells {
                    *c = m(*c);
                }
            }
        }
        for r in &mut self.piece_cell {
            if let Route::Fixed(c) = r {
                *c = m(*c);
            }
        }
        for k in &mut self.plan2 {
            if k.axis == LEAF {
                k.a = m(k.a);
            }
        }
    }
}

/// Decodes and maps every triangle of a chunk of raw working-file records in parallel (fixed
/// sub-chunks: the result does not depend on the number of threads).
fn map_records(first: u64, bytes: &[u8], out: &mut Vec<u32>, f: impl Fn(&WorkTri, u64) -> u32 + Sync) {
    out.clear();
    out.resize(bytes.len() / RECORD_BYTES, 0);
    out.par_chunks_mut(SUB_CHUNK).zip(bytes.par_chunks(SUB_CHUNK * RECORD_BYTES)).enumerate().for_each(
        |(k, (o, b))| {
            let base = first + (k * SUB_CHUNK) as u64;
            for (j, (o, t)) in o.iter_mut().zip(records(b)).enumerate() {
                *o = f(&t, base + j as u64);
            }
        },
    );
}

/// Lanes of the per-piece and per-cell statistics ([`for_each_lane`]): fixed, so that the
/// floating-point sums happen in the same order for any number of threads.
const LANES: usize = 4;

/// Per-key statistics of the keys one lane owns (key `k` at `k / LANES`).
struct LaneStats {
    count: Vec<u64>,
    bounds: Vec<FBox>,
    /// Sum of centroids (pieces only; empty for cells).
    sum: Vec<[f64; 3]>,
}

impl LaneStats {
    /// The lanes for keys `0..n`, with centroid sums if `sums`.
    fn lanes(n: usize, sums: bool) -> Vec<LaneStats> {
        (0..LANES)
            .map(|l| {
                let len = (n + LANES - 1 - l) / LANES;
                LaneStats {
                    count: vec![0; len],
                    bounds: vec![FBox::EMPTY; len],
                    sum: if sums { vec![[0.0; 3]; len] } else { Vec::new() },
                }
            })
            .collect()
    }

    /// Key `k`'s figures back out of the lanes: (count, bounds, sum).
    fn get(lanes: &[LaneStats], k: usize) -> (u64, FBox, [f64; 3]) {
        let (l, j) = (&lanes[k % LANES], k / LANES);
        (l.count[j], l.bounds[j], l.sum.get(j).copied().unwrap_or_default())
    }
}

// ---------------------------------------------------------------------------------------------
// Pass A: samples

struct Samples {
    /// Centroids, grouped by object: object `o`'s are `start[o]..start[o + 1]`.
    points: Vec<[f32; 3]>,
    start: Vec<usize>,
    /// Triangles per sample of each object (0: not sampled).
    stride: Vec<u64>,
}

/// Pass A: the samples of [`SampleRule`]. Ingest takes them while streaming
/// ([`crate::sampling::OnlineSampler`]); only when it could not (no rule, another rule,
/// interleaved objects) is the working file read for them. Both give the same samples.
fn sample_objects(ing: &Ingested, p: &RedefineParams) -> Result<Samples, BuildError> {
    let rule = p.sample_rule();
    let online = ing.samples.lock().map(|mut s| s.take()).unwrap_or(None);
    match online {
        Some(s) if s.rule == Some(rule) && s.stride.len() == ing.objects.len() => {
            tracing::debug!(samples = s.points.len(), "pass A: samples taken by ingest");
            return Ok(Samples { points: s.points, start: s.start, stride: s.stride });
        }
        _ => tracing::debug!("pass A: reading the working file for samples"),
    }
    sample_file(ing, &rule)
}

/// Pass A over the working file: [`SampleRule`]'s samples.
fn sample_file(ing: &Ingested, rule: &SampleRule) -> Result<Samples, BuildError> {
    let objects = &ing.objects;
    let large = rule.large(objects.iter().map(|o| o.triangles));
    let stride: Vec<u64> = objects.iter().map(|o| rule.stride(o.triangles, large)).collect();
    let mut start = Vec::with_capacity(objects.len() + 1);
    start.push(0usize);
    for (o, &s) in objects.iter().zip(&stride) {
        let n = if s > 0 { o.triangles.div_ceil(s) as usize } else { 0 };
        start.push(start.last().copied().unwrap_or(0) + n);
    }
    let mut points = vec![[0f32; 3]; start.last().copied().unwrap_or(0)];
    let mut seen = vec![0u64; objects.len()];
    // The next sampled triangle of each object (counted within the object): the multiples of
    // its stride, so that only sampled triangles are decoded (none for unsampled objects).
    let mut next: Vec<u64> = stride.iter().map(|&s| if s > 0 { 0 } else { u64::MAX }).collect();
    let corrupt = |message: String| BuildError::Corrupt { path: ing.work.path().to_path_buf(), message };
    // Serial, but it reads only the object ids: the reader thread only reads.
    ing.work.scan_raw(|first, bytes| {
        for k in 0..bytes.len() / RECORD_BYTES {
            let o = record_object(bytes, k) as usize;
            let Some(n) = seen.get_mut(o) else {
                return Err(corrupt(format!(
                    "triangle {} has object {o} of {}",
                    first + k as u64,
                    objects.len()
                )));
            };
            if *n == next[o] {
                let s = stride[o];
                let i = start[o] + (*n / s) as usize;
                if i >= start[o + 1] {
                    return Err(corrupt(format!("object {o} has more triangles than ingest counted")));
                }
                points[i] = WorkTri::decode(&bytes[k * RECORD_BYTES..(k + 1) * RECORD_BYTES]).centroid();
                next[o] += s;
            }
            *n += 1;
        }
        Ok(())
    })?;
    if let Some(o) = (0..objects.len()).find(|&o| seen[o] != objects[o].triangles) {
        return Err(corrupt(format!(
            "object {o} has {} triangles, ingest counted {}",
            seen[o], objects[o].triangles
        )));
    }
    Ok(Samples { points, start, stride })
}

// ---------------------------------------------------------------------------------------------
// Partition-I

struct P1<'a> {
    p: &'a RedefineParams,
    scale: &'a Scale,
    kd: &'a mut Vec<KdNode>,
    piece_object: &'a mut Vec<u32>,
    object: u32,
}

/// Picks a plane for `pts`: along the axes by decreasing extent, the widest gap between
/// consecutive centroids among the splits that leave at least a quarter of the points on each
/// side (ties: the one nearest the median); an axis where all of the middle half coincide is
/// skipped; if no axis has such a gap, the most balanced non-empty split at the median.
/// Reorders `pts` so that the left side comes first; returns (axis, pos, left count).
///
/// Why a gap rather than the median: a plane cuts every part whose triangles' centroids lie on
/// both sides, and a cut part has seams that the LOD must lock up to HLOD. CAD assemblies put
/// thousands of parts on one plane (a board's components sit on its surface, their bottom faces'
/// centroids all on it): the median of the centroids is then that plane, and splitting there cut
/// every part on the board (measured on a generated 12 M-triangle board stack: 93 % of the
/// vertices of some cells were locked seams, and 30 % of the cells' triangles never simplified).
/// The widest gap in the middle half falls between parts, boards or layers instead, and on
/// continuous geometry (a pipe) it is as good as the median.
fn median_split(pts: &mut [[f32; 3]], ext: [f64; 3]) -> Option<(usize, f32, usize)> {
    let len = pts.len();
    let mut fallback: Option<(usize, f32, usize)> = None;
    let balance = |nl: usize| nl.min(len - nl);
    for axis in axes_by_extent(ext) {
        if let Some((pos, nl)) = widest_gap(pts, |c| c[axis], |_| 1.0) {
            return Some((axis, pos, nl));
        }
        let v = pts[len / 2][axis];
        for pos in [v, next_up(v)] {
            let nl = pts.iter().filter(|c| c[axis] < pos).count();
            if fallback.is_none_or(|b| balance(nl) > balance(b.2)) {
                fallback = Some((axis, pos, nl));
            }
        }
    }
    let (axis, pos, nl) = fallback?;
    if balance(nl) == 0 {
        return None;
    }
    partition_in_place(pts, |c| c[axis] < pos);
    Some((axis, pos, nl))
}

/// The split of `pts` along one coordinate at the widest gap between consecutive distinct
/// values that leaves at least a quarter of the total weight on each side (ties: the one whose
/// left weight is nearest half). Sorts `pts` by the coordinate; returns the plane (the first
/// value on the right, so that `c < pos` is the left side) and the left count, or `None` when
/// no such gap exists (the middle half coincides). See [`median_split`] for why a gap.
fn widest_gap<T>(
    pts: &mut [T],
    coord: impl Fn(&T) -> f32,
    weight: impl Fn(&T) -> f64,
) -> Option<(f32, usize)> {
    pts.sort_by(|a, b| coord(a).total_cmp(&coord(b)));
    let total: f64 = pts.iter().map(&weight).sum();
    let (lo, hi) = (total / 4.0, total - total / 4.0);
    let mut left = 0.0f64;
    let mut best: Option<(f64, f64, usize)> = None; // (gap, distance from half, index)
    for i in 1..pts.len() {
        left += weight(&pts[i - 1]);
        if left > hi {
            break;
        }
        let (a, b) = (coord(&pts[i - 1]), coord(&pts[i]));
        if left < lo || b <= a {
            continue;
        }
        let gap = b as f64 - a as f64;
        let off = (left - total / 2.0).abs();
        if best.is_none_or(|(g, o, _)| gap > g || (gap == g && off < o)) {
            best = Some((gap, off, i));
        }
    }
    best.map(|(_, _, i)| (coord(&pts[i]), i))
}

impl P1<'_> {
    /// Plans the split of one node; returns its kd index.
    fn split(&mut self, pts: &mut [[f32; 3]], estimate: f64, ext: [f64; 3]) -> u32 {
        let p = self.p;
        let uneven = diag(ext) > self.scale.s1 || aspect(ext) > p.r1;
        if estimate > p.t1 as f64 && uneven && pts.len() >= 2 {
            if let Some((axis, pos, nl)) = median_split(pts, ext) {
                let node = self.kd.len() as u32;
                self.kd.push(KdNode::leaf(0));
                let (l, r) = pts.split_at_mut(nl);
                let per = estimate / (l.len() + r.len()) as f64;
                let a = self.split(l, per * l.len() as f64, points_ext(l));
                let b = self.split(r, per * r.len() as f64, points_ext(r));
                self.kd[node as usize] = KdNode { axis: axis as u8, pos, a, b };
                return node;
            }
        }
        let node = self.kd.len() as u32;
        self.kd.push(KdNode::leaf(self.piece_object.len() as u32));
        self.piece_object.push(self.object);
        node
    }
}

fn points_ext(pts: &[[f32; 3]]) -> [f64; 3] {
    let mut b = FBox::EMPTY;
    for &p in pts {
        b.grow(p);
    }
    b.ext()
}

/// Partition-I: plans every object's pieces; returns the object of each piece.
fn partition_objects(
    ing: &Ingested,
    p: &RedefineParams,
    scale: &Scale,
    samples: &mut Samples,
    assign: &mut Assigner,
    report: &mut RedefineReport,
) -> Vec<u32> {
    let mut piece_object = Vec::with_capacity(ing.objects.len());
    assign.object_piece = vec![ObjectRoute::Fixed(u32::MAX); ing.objects.len()];
    for (o, rec) in ing.objects.iter().enumerate() {
        if rec.triangles == 0 {
            continue;
        }
        let ext = scale.grid_ext(&rec.bounds);
        let needs = rec.triangles > p.t1 && (diag(ext) > scale.s1 || aspect(ext) > p.r1);
        let first = piece_object.len() as u32;
        if needs && !rec.part_starts.is_empty() {
            // Between its parts rather than through them (crate::parts).
            assign.object_piece[o] = ObjectRoute::Parts(assign.parts.len() as u32);
            assign.parts.push(PartRoute {
                first_piece: first,
                span_start: rec.span.start,
                starts: rec.part_starts.clone(),
            });
            piece_object.extend(std::iter::repeat_n(o as u32, rec.part_starts.len() + 1));
            report.split_objects += 1;
            continue;
        }
        if needs && samples.stride[o] > 0 {
            let pts = &mut samples.points[samples.start[o]..samples.start[o + 1]];
            let mut ctx =
                P1 { p, scale, kd: &mut assign.plan1, piece_object: &mut piece_object, object: o as u32 };
            let root = ctx.split(pts, rec.triangles as f64, ext);
            if piece_object.len() as u32 > first + 1 {
                assign.object_piece[o] = ObjectRoute::Plan(root);
                report.split_objects += 1;
                continue;
            }
            // Not split after all: forget the lone leaf.
            assign.plan1.truncate(root as usize);
            piece_object.truncate(first as usize);
        }
        assign.object_piece[o] = ObjectRoute::Fixed(first);
        piece_object.push(o as u32);
    }
    piece_object
}

// ---------------------------------------------------------------------------------------------
// Pass B: piece statistics

struct Pieces {
    count: Vec<u64>,
    bounds: Vec<FBox>,
    grid: Vec<GridBox>,
    /// Centre of mass (mean centroid).
    centre: Vec<[f32; 3]>,
}

/// Pass B. A piece that is a whole object takes its ingest figures; only the file spans of the
/// objects partition-I cuts ([`crate::types::ObjectRecord::span`]) are read. Parallel: the pool decodes each chunk
/// and finds the pieces ([`map_records`]), then accumulates them in [`LANES`] lanes by piece,
/// so that each piece's centroid sum adds its triangles in file order, as a serial loop would.
fn piece_stats(ing: &Ingested, assign: &Assigner, n: usize) -> Result<Pieces, BuildError> {
    let mut lanes = LaneStats::lanes(n, true);
    // A whole object is one piece, and ingest summed exactly what a scan of its triangles
    // would (count, box, centroids in file order): only the objects partition-I cut are read.
    let cut: Vec<u32> = (0..ing.objects.len() as u32)
        .filter(|&o| !matches!(assign.object_piece[o as usize], ObjectRoute::Fixed(_)))
        .collect();
    let joined = joined_spans(&cut, |o| ing.objects[o as usize].span.clone());
    let read: u64 = joined.iter().map(|r| r.end - r.start).sum();
    tracing::debug!(spans = joined.len(), triangles = read, of = ing.work.triangles, "pass B reads");
    let mut ids = Vec::new();
    ing.work.scan_ranges_raw(&joined, |first, bytes| {
        map_records(first, bytes, &mut ids, |t, i| match assign.object_piece[t.object as usize] {
            ObjectRoute::Fixed(_) => u32::MAX,
            ObjectRoute::Plan(_) | ObjectRoute::Parts(_) => assign.piece(t, i),
        });
        for_each_lane(&mut lanes, &ids, |lane, k, p| {
            let t = WorkTri::decode(&bytes[k * RECORD_BYTES..(k + 1) * RECORD_BYTES]);
            let j = p as usize / LANES;
            lane.count[j] += 1;
            let b = &mut lane.bounds[j];
            for v in t.p {
                b.grow(v);
            }
            let c = t.centroid();
            let sum = &mut lane.sum[j];
            for i in 0..3 {
                sum[i] += c[i] as f64;
            }
        });
        Ok(())
    })?;
    for (o, route) in assign.object_piece.iter().enumerate() {
        if let (ObjectRoute::Fixed(p), Some(rec)) = (route, ing.objects.get(o)) {
            let (l, j) = (&mut lanes[*p as usize % LANES], *p as usize / LANES);
            l.count[j] = rec.triangles;
            l.bounds[j] = FBox { min: rec.offset_min, max: rec.offset_max };
            l.sum[j] = rec.centroid_sum;
        }
    }
    let (mut count, mut bounds, mut sum) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    for p in 0..n {
        let (c, b, s) = LaneStats::get(&lanes, p);
        count.push(c);
        bounds.push(b);
        sum.push(s);
    }
    drop(lanes);
    let grid = bounds
        .iter()
        .zip(&count)
        .map(|(b, &c)| if c > 0 { b.to_grid(&ing.work, &ing.grid) } else { GridBox::EMPTY })
        .collect();
    let centre = sum
        .iter()
        .zip(&count)
        .map(|(s, &c)| {
            let c = c.max(1) as f64;
            [(s[0] / c) as f32, (s[1] / c) as f32, (s[2] / c) as f32]
        })
        .collect();
    Ok(Pieces { count, bounds, grid, centre })
}

// ---------------------------------------------------------------------------------------------
// Clustering

struct Clusters {
    /// Members of cluster `c`: `members[start[c]..start[c + 1]]`, in piece order.
    members: Vec<u32>,
    start: Vec<usize>,
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
fn nearest(
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
fn cluster_pieces(
    p: &RedefineParams,
    scale: &Scale,
    pieces: &Pieces,
    report: &mut RedefineReport,
) -> Clusters {
    let nodes: Vec<u32> = (0..pieces.count.len() as u32).filter(|&q| pieces.count[q as usize] > 0).collect();
    report.pieces = nodes.len() as u64;
    let boxes: Vec<GridBox> = nodes.iter().map(|&q| pieces.grid[q as usize]).collect();
    let tree = Hierarchy::build(&boxes);
    let dg = scale.d / scale.step;
    let r2 = if dg * dg >= 1e18 { u64::MAX / 4 } else { (dg * dg).floor() as u64 };
    let near: Vec<Vec<(u64, u32)>> = (0..nodes.len())
        .into_par_iter()
        .map_init(Vec::new, |stack, i| nearest(&tree, &boxes, i, p.neighbours, r2, stack))
        .collect();
    let mut edges: Vec<(u64, u32, u32)> = Vec::with_capacity(near.iter().map(Vec::len).sum());
    for (i, list) in near.into_iter().enumerate() {
        let i = i as u32;
        edges.extend(list.into_iter().map(|(d2, j)| (d2, i.min(j), i.max(j))));
    }
    edges.par_sort_unstable();
    edges.dedup();
    report.edges = edges.len() as u64;

    // Union-find with each root's triangles, largest internal MST edge and box.
    let n = nodes.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    let mut tris: Vec<u64> = nodes.iter().map(|&q| pieces.count[q as usize]).collect();
    let mut internal = vec![0f64; n];
    let mut bounds = boxes.clone();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            let g = parent[parent[x as usize] as usize];
            parent[x as usize] = g;
            x = g;
        }
        x
    }
    // Main pass (FH), then FH's post-pass: components under `min_cell_triangles` join their
    // nearest neighbour whatever K says, within `max_cell_triangles` and 2 V.
    for small_pass in [false, true] {
        if small_pass && p.min_cell_triangles == 0 {
            break;
        }
        for &(d2, a, b) in &edges {
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            if ra == rb {
                continue;
            }
            let (ua, ub) = (ra as usize, rb as usize);
            if tris[ua] + tris[ub] > p.max_cell_triangles {
                continue;
            }
            let w = if scale.d > 0.0 { (d2 as f64).sqrt() * scale.step / scale.d } else { 0.0 };
            let volume_limit = if small_pass {
                if tris[ua] >= p.min_cell_triangles && tris[ub] >= p.min_cell_triangles {
                    continue;
                }
                2.0 * scale.v
            } else {
                let ta = internal[ua] + p.k / tris[ua] as f64;
                let tb = internal[ub] + p.k / tris[ub] as f64;
                if w > ta.min(tb) {
                    continue;
                }
                scale.v
            };
            let merged = bounds[ua].union(&bounds[ub]);
            if scale.volume(&merged) > volume_limit {
                continue;
            }
            let (root, child) = if (tris[ub], ua) > (tris[ua], ub) { (ub, ua) } else { (ua, ub) };
            parent[child] = root as u32;
            tris[root] = tris[ua] + tris[ub];
            internal[root] = internal[ua].max(internal[ub]).max(w);
            bounds[root] = merged;
        }
    }

    // Number clusters in order of their first piece.
    let mut id_of_root = vec![u32::MAX; n];
    let mut of_piece = vec![u32::MAX; pieces.count.len()];
    let mut sizes: Vec<usize> = Vec::new();
    for i in 0..n {
        let r = find(&mut parent, i as u32) as usize;
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
    for &q in &nodes {
        let c = of_piece[q as usize] as usize;
        members[fill[c]] = q;
        fill[c] += 1;
    }
    report.clusters = sizes.len() as u64;
    Clusters { members, start }
}

// ---------------------------------------------------------------------------------------------
// Partition-II

/// A weighted point of a cluster: a whole piece (at its centre of mass, with its box) or a
/// sampled centroid of a large piece (`piece == u32::MAX`).
#[derive(Clone, Copy, Debug)]
struct WPoint {
    c: [f32; 3],
    w: f64,
    b: FBox,
    piece: u32,
}

struct P2<'a> {
    p: &'a RedefineParams,
    scale: &'a Scale,
    kd: &'a mut Vec<KdNode>,
    piece_cell: &'a mut Vec<Route>,
    cells: u32,
}

impl P2<'_> {
    fn split(&mut self, pts: &mut [WPoint]) -> u32 {
        let p = self.p;
        let total: f64 = pts.iter().map(|q| q.w).sum();
        let mut b = FBox::EMPTY;
        for q in pts.iter() {
            b.union(&q.b);
        }
        let ext = b.ext();
        let uneven = diag(ext) > self.scale.s2 || aspect(ext) > p.r2;
        let big = total > p.max_cell_triangles as f64 || (total > p.t2 as f64 && uneven);
        if big && pts.len() >= 2 {
            if let Some((axis, pos, nl)) = mass_split(pts, ext, total) {
                let node = self.kd.len() as u32;
                self.kd.push(KdNode::leaf(0));
                let (l, r) = pts.split_at_mut(nl);
                let a = self.split(l);
                let b = self.split(r);
                self.kd[node as usize] = KdNode { axis: axis as u8, pos, a, b };
                return node;
            }
        }
        let cell = self.cells;
        self.cells += 1;
        for q in pts.iter() {
            if q.piece != u32::MAX {
                self.piece_cell[q.piece as usize] = Route::Fixed(cell);
            }
        }
        let node = self.kd.len() as u32;
        self.kd.push(KdNode::leaf(cell));
        node
    }
}

/// A plane along the axes by decreasing extent: the widest gap between the points that leaves
/// at least a quarter of the weight on each side ([`widest_gap`]); where the middle half of an
/// axis coincides, about the centre of mass, or the weighted median when the centre of mass
/// leaves less than a quarter of the weight on one side.
fn mass_split(pts: &mut [WPoint], ext: [f64; 3], total: f64) -> Option<(usize, f32, usize)> {
    let left_weight = |pts: &[WPoint], axis: usize, pos: f32| -> f64 {
        pts.iter().filter(|q| q.c[axis] < pos).map(|q| q.w).sum()
    };
    let balance = |wl: f64| wl.min(total - wl);
    let mut best: Option<(usize, f32, f64)> = None;
    for axis in axes_by_extent(ext) {
        // Between parts rather than through them (median_split says why).
        if let Some((pos, nl)) = widest_gap(pts, |q| q.c[axis], |q| q.w) {
            return Some((axis, pos, nl));
        }
        let com = (pts.iter().map(|q| q.w * q.c[axis] as f64).sum::<f64>() / total) as f32;
        let mut candidates = vec![com];
        let wl = left_weight(pts, axis, com);
        if balance(wl) * 4.0 < total {
            pts.sort_by(|a, b| a.c[axis].total_cmp(&b.c[axis]));
            let mut acc = 0.0;
            let at = pts.iter().position(|q| {
                acc += q.w;
                acc * 2.0 >= total
            });
            if let Some(at) = at {
                let v = pts[at].c[axis];
                candidates.extend([v, next_up(v)]);
            }
        }
        for pos in candidates {
            let wl = left_weight(pts, axis, pos);
            if best.is_none_or(|b| balance(wl) > balance(b.2)) {
                best = Some((axis, pos, wl));
            }
        }
        if best.is_some_and(|b| balance(b.2) * 4.0 >= total) {
            break;
        }
    }
    let (axis, pos, wl) = best?;
    if balance(wl) <= 0.0 {
        return None;
    }
    let nl = partition_in_place(pts, |q| q.c[axis] < pos);
    (nl > 0 && nl < pts.len()).then_some((axis, pos, nl))
}

/// Partition-II over every cluster; fills `assign.piece_cell`; returns the number of cells.
#[allow(clippy::too_many_arguments)]
fn partition_clusters(
    ing: &Ingested,
    p: &RedefineParams,
    scale: &Scale,
    samples: &Samples,
    pieces: &Pieces,
    clusters: &Clusters,
    assign: &mut Assigner,
    report: &mut RedefineReport,
) -> u32 {
    let n_pieces = pieces.count.len();
    assign.piece_cell = vec![Route::Fixed(u32::MAX); n_pieces];
    // Samples of each piece, for pieces cut by centroid: group the sampled centroids by piece.
    let mut piece_samples_start = vec![0usize; n_pieces + 1];
    let mut sample_piece = vec![0u32; samples.points.len()];
    for o in 0..ing.objects.len() {
        let range = samples.start[o]..samples.start[o + 1];
        let (stride, span_start) = (samples.stride[o], ing.objects[o].span.start);
        for (k, (&c, q_out)) in samples.points[range.clone()].iter().zip(&mut sample_piece[range]).enumerate()
        {
            let q = match assign.object_piece[o] {
                ObjectRoute::Fixed(q) => q,
                ObjectRoute::Plan(root) => walk(&assign.plan1, root, c),
                // Samples of an object split at its parts are in file order, one every `stride`.
                ObjectRoute::Parts(r) => assign.parts[r as usize].piece(span_start + k as u64 * stride),
            };
            *q_out = q;
            if (q as usize) < n_pieces {
                piece_samples_start[q as usize + 1] += 1;
            }
        }
    }
    for q in 0..n_pieces {
        piece_samples_start[q + 1] += piece_samples_start[q];
    }
    let mut by_piece = vec![[0f32; 3]; piece_samples_start[n_pieces]];
    let mut fill = piece_samples_start.clone();
    for (i, &q) in sample_piece.iter().enumerate() {
        if (q as usize) < n_pieces {
            by_piece[fill[q as usize]] = samples.points[i];
            fill[q as usize] += 1;
        }
    }
    drop(sample_piece);

    let mut ctx = P2 { p, scale, kd: &mut assign.plan2, piece_cell: &mut assign.piece_cell, cells: 0 };
    let mut pts: Vec<WPoint> = Vec::new();
    for c in 0..clusters.start.len() - 1 {
        let members = &clusters.members[clusters.start[c]..clusters.start[c + 1]];
        let tris: u64 = members.iter().map(|&q| pieces.count[q as usize]).sum();
        let mut b = GridBox::EMPTY;
        for &q in members {
            b = b.union(&pieces.grid[q as usize]);
        }
        let ext = scale.grid_ext(&b);
        let uneven = diag(ext) > scale.s2 || aspect(ext) > p.r2;
        if !(tris > p.max_cell_triangles || (tris > p.t2 && uneven)) {
            let cell = ctx.cells;
            ctx.cells += 1;
            for &q in members {
                ctx.piece_cell[q as usize] = Route::Fixed(cell);
            }
            continue;
        }
        pts.clear();
        let mut cut_pieces = Vec::new();
        for &q in members {
            let qi = q as usize;
            let s = &by_piece[piece_samples_start[qi]..piece_samples_start[qi + 1]];
            if pieces.count[qi] > p.t1 && s.len() >= 2 {
                let w = pieces.count[qi] as f64 / s.len() as f64;
                pts.extend(s.iter().map(|&c| {
                    let mut b = FBox::EMPTY;
                    b.grow(c);
                    WPoint { c, w, b, piece: u32::MAX }
                }));
                cut_pieces.push(q);
            } else {
                pts.push(WPoint {
                    c: pieces.centre[qi],
                    w: pieces.count[qi] as f64,
                    b: pieces.bounds[qi],
                    piece: q,
                });
            }
        }
        let root = ctx.split(&mut pts);
        if ctx.kd[root as usize].axis != LEAF {
            report.split_clusters += 1;
        }
        for q in cut_pieces {
            ctx.piece_cell[q as usize] = Route::Plan(root);
        }
    }
    ctx.cells
}

// ---------------------------------------------------------------------------------------------
// Pass C: cell statistics

/// Gaps (in triangles) between the file spans of pass B's and C's objects that are read through
/// rather than skipped (160 KB: about one device round trip's worth of transfer). The spans are
/// read by one reader, each on its own ([`WorkFile::scan_ranges_raw`]). At 10^8 triangles pass C
/// reads 2,491 spans, 55 % of the file (joined across 10 MB gaps: 2 spans, 99.6 %): 3.5 → 2.1 s.
const SPAN_GAP: u64 = 1 << 12;

/// The working-file ranges to read for `objects` (their spans, sorted, joined across gaps of at
/// most [`SPAN_GAP`] triangles).
fn joined_spans(objects: &[u32], span: impl Fn(u32) -> std::ops::Range<u64>) -> Vec<std::ops::Range<u64>> {
    let mut spans: Vec<std::ops::Range<u64>> =
        objects.iter().map(|&o| span(o)).filter(|r| !r.is_empty()).collect();
    spans.sort_unstable_by_key(|r| (r.start, r.end));
    let mut joined: Vec<std::ops::Range<u64>> = Vec::new();
    for r in spans {
        match joined.last_mut() {
            Some(last) if r.start <= last.end + SPAN_GAP => last.end = last.end.max(r.end),
            _ => joined.push(r),
        }
    }
    joined
}

/// Pass C: the count and box of every cell. A piece placed whole in a cell (`Route::Fixed`)
/// adds its pass-B count and box; only the triangles of pieces that a partition-II plan cuts
/// are read again, from the file spans of their objects ([`crate::types::ObjectRecord::span`]), decoded and
/// accumulated in lanes as in pass B. Counts are sums and boxes minima and maxima, so the result
/// does not depend on the order (a −0 and a +0 bound quantize to the same grid point).
fn cell_stats(
    ing: &Ingested,
    assign: &Assigner,
    pieces: &Pieces,
    piece_object: &[u32],
    n: u32,
) -> Result<Vec<CellInfo>, BuildError> {
    let n = n as usize;
    let mut count = vec![0u64; n];
    let mut bounds = vec![FBox::EMPTY; n];
    let mut bad = None;
    let mut cut_objects = Vec::new();
    for (q, &tris) in pieces.count.iter().enumerate() {
        if tris == 0 {
            continue;
        }
        match assign.piece_cell[q] {
            Route::Fixed(c) => match count.get_mut(c as usize) {
                Some(cnt) => {
                    *cnt += tris;
                    bounds[c as usize].union(&pieces.bounds[q]);
                }
                None => bad = Some(ing.objects[piece_object[q] as usize].span.start),
            },
            Route::Plan(_) => cut_objects.push(piece_object[q]),
        }
    }
    cut_objects.dedup();
    let joined = joined_spans(&cut_objects, |o| ing.objects[o as usize].span.clone());
    let read: u64 = joined.iter().map(|r| r.end - r.start).sum();
    tracing::debug!(spans = joined.len(), triangles = read, of = ing.work.triangles, "pass C reads");
    // Triangles of whole pieces in the spans are skipped (`u32::MAX`); a plan that gives no
    // cell is a bug, reported (`n`) rather than left to panic.
    let mut lanes = LaneStats::lanes(n, false);
    let mut ids = Vec::new();
    ing.work.scan_ranges_raw(&joined, |first, bytes| {
        map_records(first, bytes, &mut ids, |t, i| match assign.piece_cell[assign.piece(t, i) as usize] {
            Route::Fixed(_) => u32::MAX,
            Route::Plan(root) => {
                let c = walk(&assign.plan2, root, t.centroid());
                if (c as usize) < n {
                    c
                } else {
                    n as u32
                }
            }
        });
        if let Some(k) = ids.iter().rposition(|&c| c != u32::MAX && c as usize >= n) {
            bad = Some(first + k as u64);
        }
        for_each_lane(&mut lanes, &ids, |lane, k, c| {
            let j = c as usize / LANES;
            let Some(cnt) = lane.count.get_mut(j) else { return };
            *cnt += 1;
            let t = WorkTri::decode(&bytes[k * RECORD_BYTES..(k + 1) * RECORD_BYTES]);
            for v in t.p {
                lane.bounds[j].grow(v);
            }
        });
        Ok(())
    })?;
    for c in 0..n {
        let (cnt, b, _) = LaneStats::get(&lanes, c);
        if cnt > 0 {
            count[c] += cnt;
            bounds[c].union(&b);
        }
    }
    if let Some(t) = bad {
        // Only reachable through a bug in the plans; say so rather than panic later.
        return Err(BuildError::Corrupt {
            path: ing.work.path().to_path_buf(),
            message: format!("triangle {t} was assigned no cell"),
        });
    }
    Ok(count
        .iter()
        .zip(&bounds)
        .map(|(&triangles, b)| CellInfo {
            triangles,
            bounds: if triangles > 0 { b.to_grid(&ing.work, &ing.grid) } else { GridBox::EMPTY },
        })
        .collect())
}

// ---------------------------------------------------------------------------------------------
// Pass D: the count split

/// Whether a leaf of the kd plan below `root` satisfies `f`.
fn plan_has_leaf(kd: &[KdNode], root: u32, f: impl Fn(u32) -> bool) -> bool {
    let mut stack = vec![root];
    while let Some(n) = stack.pop() {
        let k = kd[n as usize];
        if k.axis == LEAF {
            if f(k.a) {
                return true;
            }
        } else {
            stack.extend([k.a, k.b]);
        }
    }
    false
}

/// One block of consecutive working-file triangles of a cell being cut: how many of them are
/// the cell's, and their box.
#[derive(Clone, Copy, Debug)]
struct BlockStats {
    block: u64,
    count: u64,
    bounds: FBox,
}

/// Pass D: cuts every cell above `max_cell_triangles` into parts of at most that many, by
/// count rather than by space: its triangles in working-file order, in runs of whole blocks of
/// `block` consecutive file positions (at most half the cap, so a part closes above half the
/// cap and a cell of `n` makes at most about `2 n / max` parts; with the parts' target the
/// cell's count over the fewest parts that fit, they come out nearly even). This is what is
/// left when space cannot split a cell: triangles whose centroids coincide (a part inserted
/// many times at one spot) have no plane between them, and for them the file order is as good
/// an order as any; it also takes the overshoot of plans made from samples.
///
/// Deterministic: blocks are fixed by file position, counts and boxes (minima and maxima) do not
/// depend on the order of accumulation. Only the file spans of objects that reach a cut cell
/// are read; nothing is read when no cell is above the cap (the cells are then unchanged).
/// Part 0 keeps the cell's id; the other parts get new ids after the last cell.
fn split_by_count(
    ing: &Ingested,
    params: &RedefineParams,
    pieces: &Pieces,
    piece_object: &[u32],
    assign: &mut Assigner,
    mut cells: Vec<CellInfo>,
    report: &mut RedefineReport,
) -> Result<Vec<CellInfo>, BuildError> {
    let max = params.max_cell_triangles;
    // Slot of each cut cell in `blocks`, or u32::MAX.
    let mut slot = vec![u32::MAX; cells.len()];
    let mut cut = 0u32;
    for (c, info) in cells.iter().enumerate() {
        if info.triangles > max {
            slot[c] = cut;
            cut += 1;
        }
    }
    if cut == 0 {
        return Ok(cells);
    }
    report.count_split_cells = cut as u64;
    let block = (max / 2).clamp(1, SUB_CHUNK as u64);
    let reaches = |c: u32| slot.get(c as usize).is_some_and(|&s| s != u32::MAX);
    let mut objects: Vec<u32> = (0..pieces.count.len())
        .filter(|&q| pieces.count[q] > 0)
        .filter(|&q| match assign.piece_cell[q] {
            Route::Fixed(c) => reaches(c),
            Route::Plan(root) => plan_has_leaf(&assign.plan2, root, reaches),
        })
        .map(|q| piece_object[q])
        .collect();
    objects.sort_unstable();
    objects.dedup();
    let joined = joined_spans(&objects, |o| ing.objects[o as usize].span.clone());
    let read: u64 = joined.iter().map(|r| r.end - r.start).sum();
    tracing::debug!(cells = cut, spans = joined.len(), triangles = read, "pass D reads");
    // Per cut cell, its blocks in file order (the spans are sorted and read in order).
    let mut blocks: Vec<Vec<BlockStats>> = vec![Vec::new(); cut as usize];
    let mut ids = Vec::new();
    let a: &Assigner = assign;
    ing.work.scan_ranges_raw(&joined, |first, bytes| {
        map_records(first, bytes, &mut ids, |t, i| a.cell(t, i));
        for (k, &c) in ids.iter().enumerate() {
            let Some(&s) = slot.get(c as usize).filter(|&&s| s != u32::MAX) else { continue };
            let b = (first + k as u64) / block;
            let list = &mut blocks[s as usize];
            if list.last().is_none_or(|e| e.block != b) {
                list.push(BlockStats { block: b, count: 0, bounds: FBox::EMPTY });
            }
            if let Some(e) = list.last_mut() {
                e.count += 1;
                for v in WorkTri::decode(&bytes[k * RECORD_BYTES..(k + 1) * RECORD_BYTES]).p {
                    e.bounds.grow(v);
                }
            }
        }
        Ok(())
    })?;
    let mut count_split = vec![u32::MAX; cells.len()];
    let mut splits = Vec::with_capacity(cut as usize);
    for c in 0..slot.len() {
        let s = slot[c];
        if s == u32::MAX {
            continue;
        }
        let list = &blocks[s as usize];
        let total: u64 = list.iter().map(|e| e.count).sum();
        if total != cells[c].triangles {
            return Err(BuildError::Corrupt {
                path: ing.work.path().to_path_buf(),
                message: format!("cell {c}: {total} triangles read again, {} counted", cells[c].triangles),
            });
        }
        let target = total.div_ceil(total.div_ceil(max));
        let mut split = CountSplit::default();
        let (mut count, mut bounds) = (0u64, FBox::EMPTY);
        for (j, e) in list.iter().enumerate() {
            if count > 0 && count + e.count > target {
                split.starts.push(e.block * block);
                let info = CellInfo { triangles: count, bounds: bounds.to_grid(&ing.work, &ing.grid) };
                split.cells.push(part_cell(&mut cells, c, split.cells.len(), info));
                (count, bounds) = (0, FBox::EMPTY);
            }
            count += e.count;
            bounds.union(&e.bounds);
            if j + 1 == list.len() {
                let info = CellInfo { triangles: count, bounds: bounds.to_grid(&ing.work, &ing.grid) };
                split.cells.push(part_cell(&mut cells, c, split.cells.len(), info));
            }
        }
        count_split[c] = splits.len() as u32;
        splits.push(split);
    }
    count_split.resize(cells.len(), u32::MAX);
    assign.count_split = count_split;
    assign.splits = splits;
    Ok(cells)
}

/// The cell id of part `j` of cut cell `c`, with its figures: part 0 replaces `c`, the others
/// are appended.
fn part_cell(cells: &mut Vec<CellInfo>, c: usize, j: usize, info: CellInfo) -> u32 {
    if j == 0 {
        cells[c] = info;
        c as u32
    } else {
        cells.push(info);
        cells.len() as u32 - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ingest::tests::{ingest_list, ingest_plant};

    use crate::ingest::tests::ListObject as Obj;

    #[test]
    fn samples_taken_by_ingest_equal_pass_a_over_the_file() {
        let dir = tempfile::tempdir().unwrap();
        for p in [
            RedefineParams::default(),
            // A budget small enough that ingest's global stride doubles several times.
            RedefineParams { max_samples: 5000, min_samples_per_object: 8, ..Default::default() },
        ] {
            let rule = p.sample_rule();
            let src = tw_io::generate::PlantSource::new(tw_io::generate::PlantParams {
                triangles: 300_000,
                seed: 5,
            })
            .unwrap();
            let scene = tw_io::Scene::from_sources(vec![Box::new(src)]);
            let sampler = crate::sampling::OnlineSampler::new(rule, 1 << 30);
            let ing = crate::ingest::ingest_in(scene, dir.path(), None, Some(sampler), &mut |_| {}).unwrap();
            assert!(ing.samples.lock().unwrap().is_some(), "the plant's objects are contiguous");
            let online = sample_objects(&ing, &p).unwrap();
            // Taken once: a second redefinition reads the file.
            assert!(ing.samples.lock().unwrap().is_none());
            let file = sample_objects(&ing, &p).unwrap();
            assert!(online.points.len() as u64 >= p.max_samples.min(1000));
            assert_eq!(online.stride, file.stride);
            assert_eq!(online.start, file.start);
            let bits = |s: &Samples| s.points.iter().map(|c| c.map(f32::to_bits)).collect::<Vec<_>>();
            assert!(bits(&online) == bits(&file));
        }
    }

    #[test]
    fn spans_to_read_are_sorted_joined_across_small_gaps_and_skip_empty_objects() {
        let g = SPAN_GAP;
        let span = [5 * g..6 * g, 0..0, 10..20, 20 + g..30 + g, 4 * g..4 * g + 1, 7..7];
        // Objects 2 and 3 are one gap apart (joined); 4 and 0 are more than a gap from 3 but
        // within one of each other; 1 and 5 have no triangle.
        let span = |o: u32| span[o as usize].clone();
        assert_eq!(joined_spans(&[0, 1, 2, 3, 4, 5], span), vec![10..30 + g, 4 * g..6 * g]);
        assert_eq!(joined_spans(&[3], span), vec![20 + g..30 + g]);
        assert!(joined_spans(&[1, 5], span).is_empty());
    }

    /// A strip of `n` triangles along x from `x0` to `x0 + len`, at (y, z).
    fn strip(name: &str, n: usize, x0: f64, len: f64, y: f64, z: f64) -> Obj {
        let dx = len / n as f64;
        let tris = (0..n)
            .map(|i| {
                let x = x0 + i as f64 * dx;
                [[x, y, z], [x + dx, y, z], [x, y + 0.5, z + 0.5]]
            })
            .collect();
        (name.into(), None, tris)
    }

    /// A small cube-ish object of 12 triangles at `c` with half size `h`.
    fn cube(name: &str, c: [f64; 3], h: f64) -> Obj {
        let v = |i: u32| {
            [
                c[0] + if i & 1 > 0 { h } else { -h },
                c[1] + if i & 2 > 0 { h } else { -h },
                c[2] + if i & 4 > 0 { h } else { -h },
            ]
        };
        let faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
        let mut tris = Vec::new();
        for f in faces {
            tris.push([v(f[0]), v(f[1]), v(f[2])]);
            tris.push([v(f[0]), v(f[2]), v(f[3])]);
        }
        (name.into(), None, tris)
    }

    fn cells_of(ing: &Ingested, r: &Redefined) -> Vec<u32> {
        let mut v = Vec::new();
        ing.work
            .scan(|first, tris| {
                v.extend(tris.iter().enumerate().map(|(k, t)| r.cell_of(t, first + k as u64)));
                Ok(())
            })
            .unwrap();
        v
    }

    #[test]
    fn partition_one_splits_a_long_object_into_pieces_under_thresholds() {
        let dir = tempfile::tempdir().unwrap();
        // A 100 m pipe of 20 000 triangles beside a 1 m cube (so the scene is the pipe).
        let ing = ingest_list(
            dir.path(),
            vec![strip("pipe", 20_000, 0.0, 100.0, 0.0, 0.0), cube("c", [50.0, 20.0, 0.0], 0.5)],
        );
        // No clustering, no partition-II: the pieces are the cells.
        let params = RedefineParams {
            neighbours: 0,
            t2: u64::MAX / 2,
            max_cell_triangles: u64::MAX / 2,
            ..Default::default()
        };
        let r = redefine(&ing, &params).unwrap();
        assert_eq!(r.report.objects, 2);
        assert_eq!(r.report.split_objects, 1);
        assert!(r.report.pieces >= 10, "{:?}", r.report);
        assert_eq!(r.report.cells, r.report.pieces);
        let scale = Scale::new(&ing, &params);
        let total: u64 = r.cells.iter().map(|c| c.triangles).sum();
        assert_eq!(total, 20_012);
        for c in &r.cells {
            let ext = scale.grid_ext(&c.bounds);
            // Each piece is short enough (up to a triangle's width) or small enough.
            assert!(
                c.triangles <= params.t1 * 2 || diag(ext) <= scale.s1 * 1.2,
                "piece of {} triangles, diagonal {}",
                c.triangles,
                diag(ext)
            );
        }
        // Pieces of the pipe are contiguous intervals of x: balanced medians give equal counts.
        let pipe: Vec<u64> = r.cells.iter().map(|c| c.triangles).filter(|&t| t > 12).collect();
        let (min, max) = (pipe.iter().min().unwrap(), pipe.iter().max().unwrap());
        assert!(max - min <= max / 4, "unbalanced pieces {pipe:?}");
    }

    #[test]
    fn compact_objects_are_not_split() {
        let dir = tempfile::tempdir().unwrap();
        let mut objs = vec![cube("a", [0.0; 3], 1.0), cube("b", [100.0, 100.0, 100.0], 1.0)];
        // 2000 triangles, but a 1 m square patch: fine for partition-I.
        let patch: Vec<[[f64; 3]; 3]> = (0..2000)
            .map(|i| {
                let x = (i % 40) as f64 * 0.025;
                let y = (i / 40) as f64 * 0.02;
                [[x, y, 0.0], [x + 0.025, y, 0.0], [x, y + 0.02, 0.0]]
            })
            .collect();
        objs.push(("patch".into(), None, patch));
        let ing = ingest_list(dir.path(), objs);
        let params = RedefineParams { neighbours: 0, ..Default::default() };
        let r = redefine(&ing, &params).unwrap();
        assert_eq!(r.report.split_objects, 0);
        assert_eq!(r.report.pieces, 3);
    }

    #[test]
    fn clustering_merges_nearby_small_objects_but_not_far_apart_ones() {
        let dir = tempfile::tempdir().unwrap();
        let mut objs = Vec::new();
        // Two groups of 50 bolts, 1 000 m apart; inside a group the bolts are 0.5 m apart.
        for g in 0..2 {
            for i in 0..50 {
                let c = [g as f64 * 1000.0 + (i % 10) as f64 * 0.5, (i / 10) as f64 * 0.5, 0.0];
                objs.push(cube(&format!("bolt {g} {i}"), c, 0.1));
            }
        }
        let ing = ingest_list(dir.path(), objs);
        // The scene box is 1005 × 2.2 × 1 m (the floor on extents), a group 4.7 × 2.2 × 1 m:
        // V must allow 1 % of the scene volume.
        let r = redefine(&ing, &RedefineParams { v: 0.01, ..Default::default() }).unwrap();
        assert_eq!(r.report.pieces, 100);
        assert_eq!(r.report.clusters, 2, "{:?}", r.report);
        assert_eq!(r.report.cells, 2);
        let cells = cells_of(&ing, &r);
        // Each group is one cell, and the groups differ.
        assert!(cells[..600].iter().all(|&c| c == cells[0]));
        assert!(cells[600..].iter().all(|&c| c == cells[600]));
        assert_ne!(cells[0], cells[600]);
    }

    #[test]
    fn clustering_respects_the_volume_limit() {
        let dir = tempfile::tempdir().unwrap();
        // A row of 40 touching boxes 1 m wide in a 40 × 40 × 40 m scene (volume 64 000 m³);
        // with V = 10⁻³ of it (64 m³) a cluster spans at most 64 / (1 × 1 × 1) m along the row...
        let mut objs: Vec<Obj> =
            (0..40).map(|i| cube(&format!("b{i}"), [i as f64 + 0.5, 0.5, 0.5], 0.5)).collect();
        objs.push(cube("far corner", [39.5, 39.5, 39.5], 0.5));
        let ing = ingest_list(dir.path(), objs);
        let unlimited = redefine(&ing, &RedefineParams { v: 1.0, ..Default::default() }).unwrap();
        assert_eq!(unlimited.report.clusters, 2, "{:?}", unlimited.report);
        // ... and with V = 1.5e-4 (9.6 m³) at most 9 boxes of 1 m³.
        let params = RedefineParams { v: 1.5e-4, min_cell_triangles: 0, ..Default::default() };
        let limited = redefine(&ing, &params).unwrap();
        assert!(limited.report.clusters >= 5, "{:?}", limited.report);
        let scale = Scale::new(&ing, &params);
        for c in &limited.cells {
            assert!(scale.volume(&c.bounds) <= scale.v * 1.01, "cell volume {}", scale.volume(&c.bounds));
        }
        // The small-cluster post-pass may go up to 2 V.
        let relaxed = redefine(&ing, &RedefineParams { min_cell_triangles: 1000, ..params }).unwrap();
        assert!(relaxed.report.clusters < limited.report.clusters, "{:?}", relaxed.report);
        for c in &relaxed.cells {
            assert!(
                scale.volume(&c.bounds) <= 2.0 * scale.v * 1.01,
                "cell volume {}",
                scale.volume(&c.bounds)
            );
        }
    }

    #[test]
    fn partition_two_splits_large_uneven_clusters() {
        let dir = tempfile::tempdir().unwrap();
        // 60 touching slabs of 1000 triangles along x: one cluster of 60 000 triangles, 60 m
        // long and 1 m wide: partition-II must cut it into compact cells of ≤ t2-ish triangles.
        let objs: Vec<Obj> =
            (0..60).map(|i| strip(&format!("s{i}"), 1000, i as f64, 1.0, 0.0, 0.0)).collect();
        let ing = ingest_list(dir.path(), objs);
        let params = RedefineParams { v: 1.0, d: 0.05, ..Default::default() };
        let no_p2 = RedefineParams { t2: u64::MAX / 2, r2: 1e9, s2: 1e9, ..params.clone() };
        let r0 = redefine(&ing, &no_p2).unwrap();
        assert_eq!(r0.report.clusters, 1, "{:?}", r0.report);
        assert_eq!(r0.report.cells, 1);
        let r = redefine(&ing, &params).unwrap();
        assert_eq!(r.report.clusters, 1);
        assert_eq!(r.report.split_clusters, 1);
        assert!(r.report.cells >= 6, "{:?}", r.report);
        assert!(r.report.max_cell_triangles <= 10_000, "{:?}", r.report);
        assert_eq!(r.cells.iter().map(|c| c.triangles).sum::<u64>(), 60_000);
    }

    #[test]
    fn partition_two_caps_cells() {
        let dir = tempfile::tempdir().unwrap();
        // One compact object of 40 000 triangles (a 10 × 10 m patch): no uneven split applies,
        // but the cap of 8 192 does, through the object's samples.
        let patch: Vec<[[f64; 3]; 3]> = (0..40_000)
            .map(|i| {
                let x = (i % 200) as f64 * 0.05;
                let y = (i / 200) as f64 * 0.05;
                [[x, y, 0.0], [x + 0.05, y, 0.0], [x, y + 0.05, 0.0]]
            })
            .collect();
        let ing = ingest_list(dir.path(), vec![("patch".into(), None, patch)]);
        let params = RedefineParams { max_cell_triangles: 8192, ..Default::default() };
        let r = redefine(&ing, &params).unwrap();
        assert!(r.report.cells >= 5, "{:?}", r.report);
        assert!(r.report.max_cell_triangles <= 8192, "{:?}", r.report);
    }

    /// Every triangle's cell from a pass over the file agrees with the cells' counts and boxes.
    fn check_cells(ing: &Ingested, r: &Redefined) {
        let mut count = vec![0u64; r.cells.len()];
        let mut boxes = vec![GridBox::EMPTY; r.cells.len()];
        let mut next = 0u64;
        ing.work
            .scan(|first, tris| {
                assert_eq!(first, next);
                next += tris.len() as u64;
                for (k, t) in tris.iter().enumerate() {
                    let c = r.cell_of(t, first + k as u64) as usize;
                    count[c] += 1;
                    for v in t.p {
                        boxes[c].grow(ing.work.quantize(&ing.grid, v));
                    }
                }
                Ok(())
            })
            .unwrap();
        assert_eq!(count, r.cells.iter().map(|c| c.triangles).collect::<Vec<_>>());
        assert_eq!(boxes, r.cells.iter().map(|c| c.bounds).collect::<Vec<_>>(), "exact boxes");
    }

    #[test]
    fn coincident_triangles_are_cut_by_count_under_the_cap() {
        let dir = tempfile::tempdir().unwrap();
        let one = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let moved = |d: f64| one.map(|p| [p[0] + d, p[1], p[2]]);
        // Copies of one triangle (no plane between them), a second pile nearby, and a strip
        // that space splits as usual.
        let objs = vec![
            ("pile".into(), None, vec![one; 10_000]),
            ("strip".into(), None, strip("strip", 3000, 0.0, 30.0, 2.0, 0.0).2),
            ("pile2".into(), None, vec![moved(0.5); 2500]),
        ];
        let ing = ingest_list(dir.path(), objs);
        let params = RedefineParams { max_cell_triangles: 1000, ..Default::default() };
        let mut r = redefine(&ing, &params).unwrap();
        assert!(r.report.count_split_cells >= 1, "{:?}", r.report);
        assert!(r.report.max_cell_triangles <= 1000, "{:?}", r.report);
        assert!(r.cells.iter().all(|c| c.triangles <= 1000));
        assert!(r.report.cells >= 16, "{:?}", r.report);
        check_cells(&ing, &r);
        // The same again, and after the hierarchy renumbered the cells.
        let again = redefine(&ing, &params).unwrap();
        assert_eq!(again.cells, r.cells);
        assert_eq!(cells_of(&ing, &again), cells_of(&ing, &r));
        r.order_by_hierarchy();
        check_cells(&ing, &r);
    }

    #[test]
    fn a_cap_of_one_triangle_gives_a_cell_per_triangle() {
        let dir = tempfile::tempdir().unwrap();
        let one = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let ing = ingest_list(dir.path(), vec![("pile".into(), None, vec![one; 50])]);
        let params = RedefineParams { max_cell_triangles: 1, ..Default::default() };
        let r = redefine(&ing, &params).unwrap();
        assert_eq!(r.cells.len(), 50, "{:?}", r.report);
        check_cells(&ing, &r);
    }

    #[test]
    fn the_plant_needs_no_count_split() {
        // Inputs that space splits keep their cells (and their stores) as before.
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 200_000);
        let r = redefine(&ing, &RedefineParams::default()).unwrap();
        assert_eq!(r.report.count_split_cells, 0, "{:?}", r.report);
        assert!(r.assign.count_split.is_empty());
    }

    #[test]
    fn every_triangle_gets_an_existing_cell_and_counts_match() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 200_000);
        let r = redefine(&ing, &RedefineParams::default()).unwrap();
        let cells = cells_of(&ing, &r);
        let mut count = vec![0u64; r.cells.len()];
        for &c in &cells {
            count[c as usize] += 1;
        }
        assert_eq!(count, r.cells.iter().map(|c| c.triangles).collect::<Vec<_>>());
        assert!(r.report.objects > r.report.clusters, "{:?}", r.report);
        assert!(r.report.pieces >= r.report.objects);
    }

    #[test]
    fn plant_hierarchy_is_valid_and_renumbering_keeps_assignment() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 200_000);
        let mut r = redefine(&ing, &RedefineParams::default()).unwrap();
        let before = cells_of(&ing, &r);
        let old_cells = r.cells.clone();
        let h = r.order_by_hierarchy();
        let boxes: Vec<GridBox> = r.cells.iter().map(|c| c.bounds).collect();
        h.validate(&boxes).unwrap();
        assert_eq!(h.leaf_order(), (0..r.cells.len() as u32).collect::<Vec<_>>());
        let after = cells_of(&ing, &r);
        for (b, a) in before.iter().zip(&after) {
            assert_eq!(old_cells[*b as usize], r.cells[*a as usize]);
        }
    }

    #[test]
    fn redefinition_is_deterministic() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 100_000);
        let a = redefine(&ing, &RedefineParams::default()).unwrap();
        let b = redefine(&ing, &RedefineParams::default()).unwrap();
        assert_eq!(a.cells, b.cells);
        assert_eq!(a.report, b.report);
        assert_eq!(cells_of(&ing, &a), cells_of(&ing, &b));
    }

    #[test]
    fn bad_parameters_are_rejected() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_list(dir.path(), vec![cube("a", [0.0; 3], 1.0)]);
        for p in [
            RedefineParams { s1: 0.0, ..Default::default() },
            RedefineParams { r2: f64::NAN, ..Default::default() },
            RedefineParams { t1: 0, ..Default::default() },
            RedefineParams { d: -1.0, ..Default::default() },
        ] {
            assert!(matches!(redefine(&ing, &p), Err(BuildError::Param(_))));
        }
    }

    #[test]
    fn aspect_and_next_up_edge_cases() {
        assert_eq!(aspect([0.0; 3]), 1.0);
        assert_eq!(aspect([1.0, 0.0, 0.0]), f64::INFINITY);
        assert_eq!(aspect([4.0, 2.0, 0.0]), 2.0);
        for v in [0.0f32, 1.0, -1.0, 1e-30, -1e30, f32::MIN_POSITIVE] {
            let u = next_up(v);
            assert!(u > v && (u as f64 - v as f64) > 0.0);
            assert!(!(v < u && u < v), "no value between");
        }
        assert!(next_up(-f32::from_bits(1)) == 0.0 || next_up(-f32::from_bits(1)) == -0.0);
    }

    /// Passes A, B and C against the obvious serial loops over decoded triangles, on a plant
    /// of several scan chunks, on pools of 1 and 3 threads: bit for bit the same samples, counts,
    /// boxes and centres (the centroid sums must add in file order).
    #[test]
    fn parallel_passes_equal_the_serial_loops() {
        let dir = tempfile::tempdir().unwrap();
        let ing = crate::ingest::tests::ingest_plant(dir.path(), 150_000);
        assert!(ing.triangles > crate::ingest::SCAN_CHUNK as u64, "several chunks");
        // The defaults split objects (partition-I); without partition-I and with small cells,
        // partition-II cuts whole large objects by plan (pass C reads them again).
        let presets = [
            (RedefineParams::default(), false),
            (
                RedefineParams {
                    s1: 10.0,
                    r1: 1e9,
                    max_cell_triangles: 4096,
                    t2: 2000,
                    ..Default::default()
                },
                true,
            ),
        ];
        for ((p, cuts), threads) in presets.iter().flat_map(|p| [(p, 1), (p, 3)]) {
            let scale = Scale::new(&ing, p);
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let mut samples = sample_objects(&ing, p).unwrap();
                // Pass A, serially: every stride-th triangle of each sampled object.
                let mut seen = vec![0u64; ing.objects.len()];
                let mut expected = vec![[0f32; 3]; samples.points.len()];
                ing.work
                    .scan(|_, tris| {
                        for t in tris {
                            let o = t.object as usize;
                            let s = samples.stride[o];
                            if s > 0 && seen[o].is_multiple_of(s) {
                                expected[samples.start[o] + (seen[o] / s) as usize] = t.centroid();
                            }
                            seen[o] += 1;
                        }
                        Ok(())
                    })
                    .unwrap();
                assert!(samples
                    .points
                    .iter()
                    .zip(&expected)
                    .all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits)));

                let mut assign = Assigner::default();
                let mut report = RedefineReport::default();
                let piece_object = partition_objects(&ing, p, &scale, &mut samples, &mut assign, &mut report);
                let n = piece_object.len();
                assert!(*cuts || report.split_objects > 0, "the plant has split objects");
                let pieces = piece_stats(&ing, &assign, n).unwrap();
                let (mut count, mut sum, mut lo, mut hi) = (
                    vec![0u64; n],
                    vec![[0f64; 3]; n],
                    vec![[f32::INFINITY; 3]; n],
                    vec![[f32::NEG_INFINITY; 3]; n],
                );
                ing.work
                    .scan(|first, tris| {
                        for (k, t) in tris.iter().enumerate() {
                            let q = assign.piece(t, first + k as u64) as usize;
                            count[q] += 1;
                            let c = t.centroid();
                            for i in 0..3 {
                                sum[q][i] += c[i] as f64;
                                for v in t.p {
                                    lo[q][i] = lo[q][i].min(v[i]);
                                    hi[q][i] = hi[q][i].max(v[i]);
                                }
                            }
                        }
                        Ok(())
                    })
                    .unwrap();
                assert_eq!(pieces.count, count);
                for q in 0..n {
                    let c = count[q].max(1) as f64;
                    let centre = sum[q].map(|s| (s / c) as f32);
                    assert_eq!(pieces.centre[q].map(f32::to_bits), centre.map(f32::to_bits), "piece {q}");
                    assert_eq!(pieces.bounds[q].min.map(f32::to_bits), lo[q].map(f32::to_bits));
                    assert_eq!(pieces.bounds[q].max.map(f32::to_bits), hi[q].map(f32::to_bits));
                }

                let clusters = cluster_pieces(p, &scale, &pieces, &mut report);
                let cells = partition_clusters(
                    &ing,
                    p,
                    &scale,
                    &samples,
                    &pieces,
                    &clusters,
                    &mut assign,
                    &mut report,
                );
                let cut = (0..n).filter(|&q| matches!(assign.piece_cell[q], Route::Plan(_))).count();
                assert!(
                    !cuts || (cut > 0 && cut < n),
                    "some pieces cut by a plan ({cut} of {n}), some whole"
                );
                let stats = cell_stats(&ing, &assign, &pieces, &piece_object, cells).unwrap();
                let mut tris_of = vec![0u64; cells as usize];
                let mut box_of = vec![FBox::EMPTY; cells as usize];
                ing.work
                    .scan(|first, tris| {
                        for (k, t) in tris.iter().enumerate() {
                            let c = assign.cell(t, first + k as u64) as usize;
                            tris_of[c] += 1;
                            for v in t.p {
                                box_of[c].grow(v);
                            }
                        }
                        Ok(())
                    })
                    .unwrap();
                assert_eq!(stats.iter().map(|c| c.triangles).collect::<Vec<_>>(), tris_of);
                for (c, info) in stats.iter().enumerate() {
                    if tris_of[c] > 0 {
                        assert_eq!(info.bounds, box_of[c].to_grid(&ing.work, &ing.grid), "cell {c}");
                    }
                }
            });
        }
    }
}
