//! The build pipeline: phases 1–6 wired together, with bounded memory.
//!
//! 1. ingest ([`crate::ingest`]) → working file and scene grid;
//! 2. redefine ([`crate::redefine`]) → cells; hierarchy ([`crate::hierarchy`]) over them, cells
//!    renumbered in leaf order;
//! 3. distribute ([`crate::cells`]) → one bucket file per range of cells;
//! 4. seams ([`crate::seams`], out of core): open-boundary vertices shared by two cells (the
//!    borders of split objects), with the first and last cell (leaf order) that has each: cells
//!    lock them ([`crate::lod::build_cell_lod_with_seams`]), and a node's HLOD keeps those shared
//!    with a cell outside the node's cell range, where a neighbouring subtree may be drawn finer
//!    ([`crate::hlod::build_hlod`]); each bucket reads its own seams, and a subtree passes up
//!    only those at its roots' vertices;
//! 5. one pass over all cells: LOD of the cells on the pool (`crate::lod::build_cell_lod`,
//!    their clusters encoded there too) while, on the calling thread (the consumer), in leaf
//!    order as they become ready, the cells' groups go to pages ([`crate::pages`]) and their
//!    roots up the tree. A node whose children are complete has its HLOD built by the pool
//!    between cells (`hlod_jobs`) and emitted `HLOD_LAG` cells later, a point fixed by
//!    the cell order — so only the roots of the subtrees on the current path, and the nodes in
//!    flight, are held in memory; a loader thread reads the next bucket (and its seams) while the
//!    current one is built (`BucketQueue`: two buckets held, each a sixth of the budget);
//! 6. write: group (with each group's sources, the groups its clusters were simplified from),
//!    node and object tables, atomically ([`tw_store::StoreWriter`]).
//!
//! Output is byte-identical for any thread count: parallel work is collected in cell order.

use std::path::{Path, PathBuf};
use std::time::Instant;

use tw_io::scene::SceneProgress;
use tw_io::up::{UpChoice, UpRequest};
use tw_io::Scene;
use tw_store::{EncodedCluster, StoreInfo, StoreWriter};

use crate::cell_pass::{BuiltCell, CellPass, CellSource};
use crate::cells::CellFiles;
use crate::error::BuildError;
use crate::hierarchy::{Hierarchy, TreeIndex};
use crate::hlod::{HlodNode, HlodOutcome, HlodParams, Roots};
use crate::hlod_jobs::{HlodBuilt, HlodInput, HlodJob, HlodJobs};
use crate::in_order::Window;
use crate::ingest::Ingested;
use crate::lod::LodParams;
use crate::pages::{PagePacker, PageParams};
use crate::plan::CellRecords;
use crate::redefine::{redefine, RedefineParams, RedefineReport, Redefined};
use crate::seams::{SeamFiles, SeamTable};
use crate::types::{Grid, LodDag, LodGroup};

/// The most worker threads a build starts: 4 per core. More cannot run at once and only add
/// contention and memory (each LOD worker holds a cell's working set; 10,000 threads on 2 cores
/// ran for minutes at a load of 4,000); the output is the same for any count.
pub fn max_worker_threads() -> usize {
    4 * std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Everything `terawalk build` can set.
#[derive(Clone, Debug)]
pub struct BuildOptions {
    /// Memory budget in bytes for the whole build (peak RSS goal).
    pub memory: u64,
    /// Worker threads (None: all cores; at most [`max_worker_threads`]).
    pub threads: Option<usize>,
    /// Up axis: given, the inputs' format convention, or estimated ([`tw_io::up`]).
    pub up: UpRequest,
    pub units: String,
    /// Where working files go (None: next to the output).
    pub work_dir: Option<PathBuf>,
    pub redefine: RedefineParams,
    pub lod: LodParams,
    pub hlod: HlodParams,
    pub pages: PageParams,
    /// HLOD groups of nodes this deep or shallower go to root pages (kept resident at run time).
    pub root_depth: usize,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            memory: 2 << 30,
            threads: None,
            up: UpRequest::FormatDefault,
            units: String::new(),
            work_dir: None,
            redefine: RedefineParams::gigawalk(),
            lod: LodParams::default(),
            hlod: HlodParams::default(),
            pages: PageParams::default(),
            root_depth: 6,
        }
    }
}

impl BuildOptions {
    /// The options as `key=value` lines, stored in the file's header.
    pub fn describe(&self) -> String {
        format!(
            "memory={}\nup={}\nt1={}\nk={}\nmax_cell_triangles={}\ncluster_triangles={}\n\
             hlod_ratio={}\nhlod_max_node_triangles={}\npage_triangles={}\nroot_depth={}\n{}",
            self.memory,
            self.up,
            self.redefine.t1,
            self.redefine.k,
            self.redefine.max_cell_triangles,
            self.lod.max_triangles,
            self.hlod.ratio,
            self.hlod.max_node_triangles,
            self.pages.page_triangles,
            self.root_depth,
            // Only when set, so that a default build's header is what it was before the option.
            if self.pages.rt_bvh.is_some() { "rt_bvh=1\n" } else { "" },
        )
    }
}

/// Receives progress: one phase at a time, with a total in the phase's own unit.
pub trait BuildProgress {
    fn phase(&mut self, name: &str, total: u64, unit: &str);
    fn advance(&mut self, done: u64);
    fn end_phase(&mut self);
}

/// Progress that goes nowhere (tests, library use).
pub struct NoProgress;

impl BuildProgress for NoProgress {
    fn phase(&mut self, _: &str, _: u64, _: &str) {}
    fn advance(&mut self, _: u64) {}
    fn end_phase(&mut self) {}
}

/// What a build did: the figures `terawalk build` prints and BENCHMARKS.md records.
#[derive(Clone, Debug, Default)]
pub struct BuildReport {
    /// (phase, seconds), in order.
    pub phases: Vec<(String, f64)>,
    pub input_triangles: u64,
    pub degenerate_dropped: u64,
    /// Exact duplicate triangles left out (same three grid positions in the same cyclic order
    /// as an earlier triangle of the cell: `crate::cells::Bucket::mesh`); `input_triangles`
    /// counts them.
    pub duplicate_dropped: u64,
    pub objects: u64,
    pub redefine: RedefineReport,
    pub nodes: u64,
    pub depth: u64,
    pub groups: u64,
    pub clusters: u64,
    /// Triangles over all LOD levels.
    pub stored_triangles: u64,
    pub pages: u32,
    pub root_pages: u32,
    pub file_bytes: u64,
    pub peak_rss: Option<u64>,
    /// HLOD counters by hierarchy depth (index = depth of the node; leaves have none).
    pub hlod: Vec<HlodDepthStats>,
    /// The up axis recorded in the store, and why (`terawalk build` prints it).
    pub up: UpChoice,
}

/// What HLOD did at the nodes of one hierarchy depth (logged at info level, `-v`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HlodDepthStats {
    pub nodes: u64,
    pub triangles_in: u64,
    pub target: u64,
    pub triangles_out: u64,
    /// Nodes whose result is within 1/8 of their target.
    pub on_target: u64,
    pub regular: u64,
    pub sloppy: u64,
    /// Nodes that kept their merged mesh (every simplification broke an edge).
    pub merged: u64,
    pub unchanged: u64,
    /// Triangles dropped as whole small parts.
    pub pruned: u64,
    /// Largest node error at this depth (scene units).
    pub max_error: f32,
}

impl BuildReport {
    pub fn seconds(&self) -> f64 {
        self.phases.iter().map(|p| p.1).sum()
    }
}

pub(crate) struct Timer<'a> {
    report: &'a mut BuildReport,
    start: Instant,
}

impl<'a> Timer<'a> {
    pub(crate) fn new(report: &'a mut BuildReport) -> Timer<'a> {
        Timer { report, start: Instant::now() }
    }

    pub(crate) fn lap(&mut self, name: &str) {
        let now = Instant::now();
        self.report.phases.push((name.to_string(), (now - self.start).as_secs_f64()));
        self.start = now;
    }
}

/// Builds the store at `output` from `scene`. The file appears only when everything succeeded.
pub fn build(
    scene: Scene,
    output: &Path,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
) -> Result<BuildReport, BuildError> {
    build_with_pool(scene, output, options, progress, &worker_pool(options)?)
}

/// The build's worker threads: `options.threads` (at most [`max_worker_threads`]), else one
/// per core.
pub(crate) fn worker_pool(options: &BuildOptions) -> Result<rayon::ThreadPool, BuildError> {
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = options.threads {
        pool = pool.num_threads(n.clamp(1, max_worker_threads()));
    }
    pool.build().map_err(|e| BuildError::Param(format!("thread pool: {e}")))
}

/// The name prefix of a build's working directory.
const WORK_DIR_PREFIX: &str = ".terawalk-build-";

/// Removes what earlier builds killed without a chance to clean up (SIGKILL, a crash) left in
/// the working folder and beside the output: working directories and temporary stores that no
/// live build holds (`tw_store::cleanup::remove_stale`). Each is logged: they may be gigabytes.
pub(crate) fn remove_stale_temporaries(output: &Path, work_root: &Path) {
    let mut removed = tw_store::cleanup::remove_stale(work_root, &[WORK_DIR_PREFIX]);
    let out_dir = output.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if let Some(name) = output.file_name() {
        let prefix = tw_store::temporary_prefix(&name.to_string_lossy());
        removed.extend(tw_store::cleanup::remove_stale(out_dir, &[&prefix]));
    }
    for p in &removed {
        tracing::warn!("removed {}, left behind by an earlier build that was killed", p.display());
    }
}

/// A build's temporary working directory. It is removed when dropped, by the program's signal
/// handler (registered with `tw_store::cleanup`), and after a SIGKILL by the next build into the
/// same folder (locked while it lives; see `remove_stale_temporaries`). Steps before the
/// build proper (converting inputs, `tw_io::convert`) keep their files in one too.
#[derive(Debug)]
pub struct WorkDir {
    // Dropped in this order: the directory goes while it is still registered and locked.
    dir: tempfile::TempDir,
    _cleanup: tw_store::cleanup::TempGuard,
    _lock: std::fs::File,
}

impl WorkDir {
    /// Creates a working directory in `root` (which must exist).
    pub fn create(root: &Path) -> Result<WorkDir, BuildError> {
        let dir = tempfile::Builder::new()
            .prefix(WORK_DIR_PREFIX)
            .tempdir_in(root)
            .map_err(|e| BuildError::io(root, e))?;
        let _cleanup = tw_store::cleanup::register(dir.path());
        let _lock = tw_store::cleanup::lock_dir(dir.path()).map_err(|e| BuildError::io(dir.path(), e))?;
        Ok(WorkDir { dir, _cleanup, _lock })
    }

    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// Renames the directory to `to` (on the same file system) and keeps it: a build plan's
    /// prepared files, complete. Until then it is removed like any working directory.
    pub(crate) fn persist(self, to: &Path) -> Result<(), BuildError> {
        std::fs::rename(self.dir.path(), to).map_err(|e| BuildError::io(to, e))?;
        let WorkDir { dir, _cleanup, _lock } = self;
        let _ = dir.keep();
        drop(std::fs::remove_file(to.join(tw_store::cleanup::DIR_LOCK)));
        Ok(())
    }
}

/// The folder a build's working directories go into: `work_dir`, else the output's folder.
pub fn work_root(output: &Path, work_dir: Option<&Path>) -> PathBuf {
    match work_dir {
        Some(d) => d.to_path_buf(),
        None => output.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_path_buf(),
    }
}

/// The phases; parallel steps run on `pool` (the importers themselves need not be `Send`).
fn build_with_pool(
    scene: Scene,
    output: &Path,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
    pool: &rayon::ThreadPool,
) -> Result<BuildReport, BuildError> {
    let mut report = BuildReport::default();
    let work_root = work_root(output, options.work_dir.as_deref());
    remove_stale_temporaries(output, &work_root);
    let work = WorkDir::create(&work_root)?;
    let writer = StoreWriter::create(output).map_err(BuildError::store)?;
    let mut t = Timer::new(&mut report);
    let prepared = prepare(scene, work.path(), options, progress, pool, &mut t)?;
    let source = CellSource::Build { grid: &prepared.facts.grid, params: &options.lod };
    finish(&prepared, source, writer, options, progress, pool, &mut t)?;
    Ok(report)
}

/// What phases 1–4 leave for the rest: the scene's figures, the hierarchy over the cells, and
/// the cells and their seams on disk. A build plan's `prepare` job keeps it (`crate::plan`).
pub(crate) struct Prepared {
    pub facts: SceneFacts,
    pub hierarchy: Hierarchy,
    pub cells: CellFiles,
    pub seams: SeamFiles,
}

/// The figures of the scene that phases 5–6 and the report need.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub(crate) struct SceneFacts {
    pub grid: Grid,
    pub min: [f64; 3],
    pub max: [f64; 3],
    /// Input triangles (degenerate ones dropped).
    pub triangles: u64,
    /// Every input object: name, colour, triangles.
    pub objects: Vec<(String, Option<[u8; 4]>, u64)>,
    pub up_axis: u8,
    pub up_reason: String,
    pub degenerate: u64,
    pub redefine: RedefineReport,
    /// The units recorded in the store (`--units`, or what the inputs are known to be in).
    pub units: String,
}

impl SceneFacts {
    fn of(ing: &Ingested, red: &Redefined, up: UpChoice, units: &str) -> SceneFacts {
        SceneFacts {
            grid: ing.grid,
            min: ing.min,
            max: ing.max,
            triangles: ing.triangles,
            objects: ing.objects.iter().map(|o| (o.name.clone(), o.color, o.triangles)).collect(),
            up_axis: up.axis,
            up_reason: up.reason,
            degenerate: ing.summary.degenerate,
            redefine: red.report.clone(),
            units: units.to_string(),
        }
    }
}

/// Phases 1–4: ingest, redefine and hierarchy, distribute, seams; working files in `work_dir`.
pub(crate) fn prepare(
    scene: Scene,
    work_dir: &Path,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
    pool: &rayon::ThreadPool,
    t: &mut Timer,
) -> Result<Prepared, BuildError> {
    let (ing, up) = ingest_phase(scene, work_dir, options, progress, pool)?;
    t.lap("ingest");
    let (red, hierarchy) = redefine_phase(&ing, options, progress, pool)?;
    t.lap("redefine+hierarchy");
    let cells = distribute_phase(&ing, &red, work_dir, options, progress, pool)?;
    t.lap("distribute");
    let seams = seams_phase(&cells, work_dir, options, progress, pool)?;
    t.lap("seams");
    Ok(Prepared { facts: SceneFacts::of(&ing, &red, up, &options.units), hierarchy, cells, seams })
}

/// Phases 5–6: LOD, HLOD and pages over the cells from `source`, then the store's tables and
/// the file; the figures go to `t`'s report.
pub(crate) fn finish<'h>(
    prepared: &'h Prepared,
    source: CellSource<'h>,
    mut writer: StoreWriter,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
    pool: &rayon::ThreadPool,
    t: &mut Timer,
) -> Result<(), BuildError> {
    writer.set_rt_trees(options.pages.rt_bvh.is_some());
    let (state, duplicates) = lod_phase(prepared, source, options, &mut writer, progress, pool)?;
    t.lap("lod+hlod+pages");
    log_lod_figures(&state);
    let written = write_phase(state, &prepared.facts, options, writer, progress)?;
    t.lap("write");

    let facts = &prepared.facts;
    let report = &mut *t.report;
    report.input_triangles = facts.triangles;
    report.up = UpChoice { axis: facts.up_axis, reason: facts.up_reason.clone() };
    report.degenerate_dropped = facts.degenerate;
    report.duplicate_dropped = duplicates;
    report.objects = facts.objects.len() as u64;
    report.redefine = facts.redefine.clone();
    report.nodes = written.nodes;
    report.depth = prepared.hierarchy.depth() as u64;
    report.groups = written.groups;
    report.clusters = written.clusters;
    report.stored_triangles = written.stored_triangles;
    report.pages = written.pages;
    report.root_pages = written.root_pages;
    report.file_bytes = written.file_bytes;
    report.peak_rss = tw_core::mem::peak_rss_bytes();
    report.hlod = written.hlod;
    Ok(())
}

/// Phase 1: reads the scene into the working file, taking redefinition's samples on the way
/// (no pass over the working file for them) with an eighth of the budget beyond the final
/// samples (`crate::sampling`, "Memory"; the importers' vertices take a quarter), and settles the up axis (voted on the way when asked for `auto`).
fn ingest_phase(
    scene: Scene,
    work_dir: &Path,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
    pool: &rayon::ThreadPool,
) -> Result<(Ingested, UpChoice), BuildError> {
    progress.phase("ingest", 0, "bytes");
    let sampler = crate::sampling::OnlineSampler::new(options.redefine.sample_rule(), options.memory / 8);
    let formats = scene.formats().to_vec();
    let auto_up = options.up == UpRequest::Auto;
    let ing = crate::ingest::ingest_voting(
        scene,
        work_dir,
        Some(pool),
        Some(sampler),
        auto_up,
        &mut |p: SceneProgress| {
            progress.advance(p.done);
        },
    )?;
    let votes = ing.up_votes.unwrap_or_default();
    let up = tw_io::up::resolve(options.up, &formats, &votes, ing.min, ing.max);
    progress.end_phase();
    Ok((ing, up))
}

/// Phase 2: redefines the objects into cells and builds the hierarchy over them (the cells
/// renumbered in leaf order).
fn redefine_phase(
    ing: &Ingested,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
    pool: &rayon::ThreadPool,
) -> Result<(Redefined, Hierarchy), BuildError> {
    progress.phase("redefine", 0, "");
    let mut red = pool.install(|| redefine(ing, &options.redefine))?;
    let mut lap = crate::types::StepTimer::new("redefine");
    let hierarchy = red.order_by_hierarchy();
    lap.step("hierarchy");
    progress.end_phase();
    Ok((red, hierarchy))
}

/// Phase 3: distributes the triangles to the cells' bucket files, then drops the working file.
/// A sixth of the budget for one bucket: the LOD phase holds two (the one being built and the
/// next, read ahead), and the LOD of the cells in flight holds about as much again as one.
fn distribute_phase(
    ing: &Ingested,
    red: &Redefined,
    work_dir: &Path,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
    pool: &rayon::ThreadPool,
) -> Result<CellFiles, BuildError> {
    progress.phase("distribute", 0, "");
    let bucket_budget = (options.memory / 6).max(16 << 20);
    let cells = pool.install(|| CellFiles::distribute(ing, red, work_dir, bucket_budget))?;
    drop(std::fs::remove_file(ing.work.path()));
    progress.end_phase();
    Ok(cells)
}

/// Phase 4: the seams between cells, out of core, a quarter of the budget of records at a time.
fn seams_phase(
    cells: &CellFiles,
    work_dir: &Path,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
    pool: &rayon::ThreadPool,
) -> Result<SeamFiles, BuildError> {
    progress.phase("seams", cells.cell_count() as u64, "cells");
    let budget = (options.memory / 4).max(16 << 20);
    let seams = SeamFiles::find(cells, work_dir, budget, pool, &mut |done| progress.advance(done))?;
    tracing::info!(
        open_positions = seams.open_positions,
        seams = seams.seams,
        partitions = seams.partitions,
        "seams"
    );
    progress.end_phase();
    Ok(seams)
}

/// Phase 5: LOD, HLOD and pages in one pass over every cell (cells are numbered in bucket
/// order; [`CellPass`]). The pool makes the cells' DAGs, taking cells in order, and builds the
/// HLOD nodes this thread starts; this thread consumes the DAGs in cell order
/// ([`CellConsumer`]: pages; HLOD nodes started and emitted) as they come, so the sequential
/// part overlaps the parallel one. Returns the bottom-up state, for the tables, and the
/// duplicate triangles the cells dropped.
fn lod_phase<'h>(
    prepared: &'h Prepared,
    source: CellSource<'h>,
    options: &BuildOptions,
    writer: &mut StoreWriter,
    progress: &mut dyn BuildProgress,
    pool: &rayon::ThreadPool,
) -> Result<(LodState<'h>, u64), BuildError> {
    progress.phase("lod", prepared.facts.triangles, "triangles");
    let cells = &prepared.cells;
    let jobs = HlodJobs::new(&prepared.facts.grid, &options.hlod);
    let mut consumer = CellConsumer {
        state: LodState::new(&prepared.hierarchy, options, source.records(), prepared.facts.grid.step),
        writer,
        progress: &mut *progress,
        jobs: &jobs,
        cell_triangles: cells.cell_triangles(),
        done_triangles: 0,
        duplicates: 0,
        busy: std::time::Duration::ZERO,
    };
    let pass = CellPass {
        cells,
        seams: &prepared.seams,
        buckets: 0..cells.bucket_count(),
        window: lod_window(options.memory),
        source,
    };
    let held = pass.run(pool, &|| jobs.run_one(), |i, cell, seams| consumer.take(i, cell, seams))?;
    consumer.finish(held)?;
    let duplicates = consumer.duplicates;
    let state = consumer.state;
    progress.end_phase();
    Ok((state, duplicates))
}

/// Phase 5's consumer, on the calling thread: takes the built cells in cell order.
struct CellConsumer<'a, 'h> {
    state: LodState<'h>,
    writer: &'a mut StoreWriter,
    progress: &'a mut dyn BuildProgress,
    jobs: &'a HlodJobs<'a>,
    cell_triangles: &'a [u64],
    /// Input triangles of the cells taken so far (the phase's progress).
    done_triangles: u64,
    /// Duplicate triangles the cells' meshes left out.
    duplicates: u64,
    /// The consumer's working time: the floor of this phase however many cores the pool has.
    busy: std::time::Duration,
}

impl CellConsumer<'_, '_> {
    /// Takes cell `i`: its groups to pages, its roots up the tree (with `seams`, its bucket's),
    /// the HLOD nodes it completes started and those due emitted.
    fn take(&mut self, i: u32, cell: BuiltCell, seams: &SeamTable) -> Result<(), BuildError> {
        let state = &mut self.state;
        let leaf = state.index.leaf_of_cell[i as usize];
        let busy_since = Instant::now();
        self.duplicates += cell.duplicates;
        let r = cell
            .encoded
            .map_err(|m| invalid_cluster(leaf, m))
            .and_then(|encoded| state.add_cell(self.writer, leaf, cell.dag, encoded, seams))
            .and_then(|()| {
                state.start_parent(leaf, i as usize + HLOD_LAG, self.jobs);
                state.emit_due(self.writer, Some(i as usize), self.jobs)
            });
        self.busy += busy_since.elapsed();
        r?;
        self.done_triangles += self.cell_triangles[i as usize];
        self.progress.advance(self.done_triangles);
        Ok(())
    }

    /// After the last cell: emits the nodes still pending (the top of the hierarchy, above
    /// the last cells) and logs what the pass held and how busy the consumer was.
    fn finish(&mut self, held: Window) -> Result<(), BuildError> {
        let busy_since = Instant::now();
        self.state.emit_due(self.writer, None, self.jobs)?;
        self.busy += busy_since.elapsed();
        tracing::debug!(
            results = held.results,
            bytes = held.bytes,
            "lod: most cell DAGs held ahead of the consumer"
        );
        tracing::debug!(
            seconds = self.busy.as_secs_f64(),
            "lod: consumer busy (pages, HLOD nodes emitted, or built when due)"
        );
        Ok(())
    }
}

/// Logs phase 5's figures (`-v`): the cells' LOD roots and what HLOD did at each depth.
fn log_lod_figures(state: &LodState) {
    let (cell_count, cell_triangles, cell_root_triangles) = state.cell_counts;
    tracing::info!(cells = cell_count, cell_triangles, cell_root_triangles, "cell lod roots");
    tracing::info!(built_here = state.hlod_built, read_from_plan_shards = state.hlod_read, "hlod nodes");
    for (depth, d) in state.hlod.iter().enumerate().filter(|(_, d)| d.nodes > 0) {
        tracing::info!(
            depth,
            nodes = d.nodes,
            triangles_in = d.triangles_in,
            target = d.target,
            triangles_out = d.triangles_out,
            on_target = d.on_target,
            regular = d.regular,
            sloppy = d.sloppy,
            merged = d.merged,
            unchanged = d.unchanged,
            pruned = d.pruned,
            max_error = d.max_error,
            "hlod depth"
        );
    }
}

/// What phase 6 wrote, for the report.
struct Written {
    nodes: u64,
    groups: u64,
    clusters: u64,
    stored_triangles: u64,
    pages: u32,
    root_pages: u32,
    file_bytes: u64,
    hlod: Vec<HlodDepthStats>,
}

/// Phase 6: the last pages, the group table with each group's page, the node and object
/// tables and the header's scene description, then the file, atomically.
fn write_phase(
    state: LodState,
    facts: &SceneFacts,
    options: &BuildOptions,
    mut writer: StoreWriter,
    progress: &mut dyn BuildProgress,
) -> Result<Written, BuildError> {
    progress.phase("write", 0, "");
    let LodState {
        hierarchy, packer, groups, sources, node_groups, clusters, stored_triangles, hlod, ..
    } = state;
    let (placements, pages, root_pages) = packer.finish(&mut writer)?;
    let mut table: Vec<tw_store::Group> = groups;
    for p in placements {
        let g = &mut table[p.group as usize];
        g.page = p.page;
        g.first_cluster = p.first_cluster;
    }
    let nodes = store_nodes(hierarchy, &node_groups, &table);
    let objects: Vec<tw_store::Object> = facts
        .objects
        .iter()
        .map(|(name, color, triangles)| tw_store::Object {
            name: name.clone(),
            color: *color,
            triangles: *triangles,
        })
        .collect();
    let info = StoreInfo {
        bounds_min: facts.min,
        bounds_max: facts.max,
        grid_origin: facts.grid.origin,
        grid_step: facts.grid.step,
        units: facts.units.clone(),
        up_axis: facts.up_axis,
        build_options: options.describe(),
        input_triangles: facts.triangles,
    };
    let summary = writer.finish(&info, &objects, &nodes, &table, &sources).map_err(BuildError::store)?;
    progress.end_phase();
    Ok(Written {
        nodes: nodes.len() as u64,
        groups: table.len() as u64,
        clusters,
        stored_triangles,
        pages,
        root_pages,
        file_bytes: summary.file_bytes,
        hlod,
    })
}

/// Cell DAGs the LOD phase may hold ahead of its consumer: 16, and a sixteenth of the budget.
/// Under load the consumer (HLOD, pages) falls behind the pool and the window fills; at 10^8
/// triangles and `--memory 256M`, 16 DAGs of the largest cells (65,536 triangles, ~2.5 MB each)
/// would be 40 MB of a 268 MB budget.
pub(crate) fn lod_window(memory: u64) -> Window {
    Window { results: 16, bytes: (memory / 16).min(usize::MAX as u64) as usize }
}

/// Cells the consumer takes between starting an HLOD node and emitting it: the time the pool
/// has to build it. Emitting at a point fixed by the cell order keeps the store independent of
/// the threads; a node not built by then is built by the consumer itself.
pub(crate) const HLOD_LAG: usize = 8;

/// The bottom-up state of phase 5.
struct LodState<'h> {
    hierarchy: &'h Hierarchy,
    index: TreeIndex,
    /// HLOD nodes built by a build plan's `cells` jobs (read back instead of built here).
    prebuilt: Option<&'h CellRecords>,
    /// Roots of completed subtrees, by node, with the seams at their vertices that are shared
    /// with a cell outside the subtree.
    roots: Vec<Option<(Roots, SeamTable)>>,
    /// The group table (page references filled in at the end).
    groups: Vec<tw_store::Group>,
    /// The sources of every group, group after group (`groups[i].source_count` each).
    sources: Vec<u32>,
    /// The range of groups attached to each node.
    node_groups: Vec<(u32, u32)>,
    packer: PagePacker,
    root_depth: usize,
    clusters: u64,
    stored_triangles: u64,
    hlod: Vec<HlodDepthStats>,
    /// Cells, their level-0 triangles and their root groups' triangles (where the cell DAG stops).
    cell_counts: (u64, u64, u64),
    /// HLOD nodes started and not yet emitted, with the cell after which each is due.
    pending: std::collections::VecDeque<(usize, PendingNode)>,
    /// HLOD nodes built here and read back from a plan's shards (`prebuilt`).
    hlod_built: u64,
    hlod_read: u64,
}

/// An HLOD node started by phase 5's consumer.
enum PendingNode {
    /// Being built on the pool (or by the consumer when due).
    Job(std::sync::Arc<HlodJob>),
    /// Built by a build plan's `cells` job: read back when due.
    Prebuilt(u32),
}

impl<'h> LodState<'h> {
    fn new(
        hierarchy: &'h Hierarchy,
        options: &BuildOptions,
        prebuilt: Option<&'h CellRecords>,
        grid_step: f64,
    ) -> LodState<'h> {
        let n = hierarchy.nodes.len();
        let index = TreeIndex::new(hierarchy);
        LodState {
            hierarchy,
            index,
            prebuilt,
            roots: vec![None; n],
            groups: Vec::new(),
            sources: Vec::new(),
            node_groups: vec![(0, 0); n],
            packer: PagePacker::new(options.pages, grid_step),
            root_depth: options.root_depth,
            clusters: 0,
            stored_triangles: 0,
            hlod: Vec::new(),
            cell_counts: (0, 0, 0),
            pending: std::collections::VecDeque::new(),
            hlod_built: 0,
            hlod_read: 0,
        }
    }

    /// Gives `dag`'s groups scene ids, sends their clusters (`encoded`: one per cluster of
    /// `dag`, see [`encode_clusters`]) to pages and records the groups and
    /// their sources: the union of their clusters' `refined_from`, which are indices into `dag`
    /// when `local_sources` (a cell's DAG) and scene ids otherwise (an HLOD node's). Sources are
    /// always groups emitted earlier (the store writer checks it).
    fn emit(
        &mut self,
        writer: &mut StoreWriter,
        node: u32,
        dag: &LodDag,
        mut encoded: Vec<EncodedCluster>,
        local_sources: bool,
    ) -> Result<(), BuildError> {
        if encoded.len() != dag.clusters.len() {
            let m = format!("{} encoded clusters for {}", encoded.len(), dag.clusters.len());
            return Err(invalid_cluster(node, m));
        }
        let base = self.groups.len() as u32;
        let mut group_sources: Vec<u32> = Vec::new();
        let root = (self.index.depth[node as usize] as usize) <= self.root_depth
            && !self.hierarchy.nodes[node as usize].is_leaf();
        for (gi, g) in dag.groups.iter().enumerate() {
            let id = base + gi as u32;
            let mut clusters: Vec<EncodedCluster> = Vec::with_capacity(g.clusters.len());
            for &c in &g.clusters {
                // Each cluster is in one group: taken once.
                let mut e = encoded.get_mut(c as usize).map(std::mem::take).unwrap_or_default();
                if e.bytes.is_empty() {
                    return Err(invalid_cluster(
                        node,
                        format!("cluster {c} of group {gi} is missing or repeated"),
                    ));
                }
                e.set_group(id);
                clusters.push(e);
            }
            let triangles: usize = clusters.iter().map(|c| c.triangles).sum();
            self.clusters += clusters.len() as u64;
            self.stored_triangles += triangles as u64;
            group_sources.clear();
            for &c in &g.clusters {
                let from = &dag.clusters[c as usize].refined_from;
                group_sources.extend(from.iter().map(|&r| if local_sources { base + r } else { r }));
            }
            group_sources.sort_unstable();
            group_sources.dedup();
            self.sources.extend_from_slice(&group_sources);
            let mut entry = store_group(g, node, triangles as u32, clusters.len() as u32);
            entry.source_count = group_sources.len() as u32;
            self.groups.push(entry);
            self.packer.add_group(writer, id, g.level, root, clusters)?;
        }
        self.node_groups[node as usize] = (base, dag.groups.len() as u32);
        Ok(())
    }

    fn add_cell(
        &mut self,
        writer: &mut StoreWriter,
        leaf: u32,
        dag: LodDag,
        encoded: Vec<EncodedCluster>,
        seams: &SeamTable,
    ) -> Result<(), BuildError> {
        // Counted from the encoded clusters: a plan's shards leave out the geometry nobody reads.
        let level0: usize = encoded.iter().filter(|c| c.level == 0).map(|c| c.triangles).sum();
        let root_triangles: usize = dag
            .clusters
            .iter()
            .zip(&encoded)
            .filter(|(c, _)| dag.groups[c.group as usize].error == f32::INFINITY)
            .map(|(_, e)| e.triangles)
            .sum();
        self.emit(writer, leaf, &dag, encoded, true)?;
        self.cell_counts.0 += 1;
        self.cell_counts.1 += level0 as u64;
        self.cell_counts.2 += root_triangles as u64;
        let range = self.index.cell_range[leaf as usize];
        self.hand_up(leaf, &dag, seams, range)
    }

    /// Starts the HLOD of `node`'s parent if all its children are complete, to be emitted when
    /// the consumer has taken cell `due` (or at the end).
    fn start_parent(&mut self, node: u32, due: usize, jobs: &HlodJobs) {
        let parent = self.index.parent[node as usize];
        if parent == u32::MAX {
            return;
        }
        let children = self.hierarchy.nodes[parent as usize].children();
        if children.clone().any(|c| self.roots[c].is_none()) {
            return;
        }
        if self.prebuilt.is_some_and(|p| p.has_node(parent)) {
            children.for_each(|c| self.roots[c] = None);
            self.pending.push_back((due, PendingNode::Prebuilt(parent)));
            return;
        }
        let (children, child_seams): (Vec<Roots>, Vec<SeamTable>) =
            children.map(|c| self.roots[c].take().expect("checked above")).unzip();
        let range = self.index.cell_range[parent as usize];
        let job = jobs.start(HlodInput { node: parent, children, child_seams, range });
        self.pending.push_back((due, PendingNode::Job(job)));
    }

    /// Emits the started HLOD nodes that are due once cell `cell` has been taken, in the order
    /// they were started (with `None`, all of them, and the ancestors they complete). The
    /// order depends on the cell order alone, not on which thread built a node or when.
    fn emit_due(
        &mut self,
        writer: &mut StoreWriter,
        cell: Option<usize>,
        jobs: &HlodJobs,
    ) -> Result<(), BuildError> {
        while let Some((due, _)) = self.pending.front() {
            if cell.is_some_and(|c| *due > c) {
                return Ok(());
            }
            let built = match self.pending.pop_front().expect("checked above").1 {
                PendingNode::Job(job) => {
                    self.hlod_built += 1;
                    jobs.result(&job).map_err(BuildError::Internal)?
                }
                PendingNode::Prebuilt(node) => {
                    self.hlod_read += 1;
                    Box::new(self.prebuilt.expect("prebuilt nodes come from it").read_node(node)?)
                }
            };
            let node = built.node;
            self.emit_hlod(writer, *built)?;
            self.start_parent(node, cell.unwrap_or(0) + HLOD_LAG, jobs);
        }
        Ok(())
    }

    /// Gives an HLOD node's replaced groups and its clusters' sources their scene ids (its
    /// children have been emitted: their first groups' ids are known).
    fn resolve_provisional(&self, node: u32, hl: &mut HlodNode) -> Result<(), BuildError> {
        let bases: Vec<u32> =
            self.hierarchy.nodes[node as usize].children().map(|c| self.node_groups[c].0).collect();
        for id in
            hl.replaced.iter_mut().chain(hl.dag.clusters.iter_mut().flat_map(|c| c.refined_from.iter_mut()))
        {
            *id = crate::provisional::resolve(*id, &bases)?;
        }
        Ok(())
    }

    /// Records a built HLOD node: its statistics, the error and sphere of the groups it
    /// replaces, its groups (to pages), and its roots for its parent.
    fn emit_hlod(&mut self, writer: &mut StoreWriter, built: HlodBuilt) -> Result<(), BuildError> {
        let HlodBuilt { node, hl, encoded, seams, range } = built;
        let depth = self.index.depth[node as usize] as usize;
        if self.hlod.len() <= depth {
            self.hlod.resize(depth + 1, HlodDepthStats::default());
        }
        let (d, st) = (&mut self.hlod[depth], &hl.stats);
        d.nodes += 1;
        d.triangles_in += st.triangles_in as u64;
        d.target += st.target as u64;
        d.triangles_out += st.triangles_out as u64;
        d.on_target += (st.triangles_out <= st.target + st.target / 8) as u64;
        match st.outcome {
            HlodOutcome::Unchanged => d.unchanged += 1,
            HlodOutcome::Regular => d.regular += 1,
            HlodOutcome::Sloppy => d.sloppy += 1,
            HlodOutcome::Merged => d.merged += 1,
        }
        d.max_error = d.max_error.max(st.error);
        d.pruned += st.pruned as u64;
        let mut hl = hl;
        self.resolve_provisional(node, &mut hl)?;
        for &g in &hl.replaced {
            let e = &mut self.groups[g as usize];
            e.error = hl.error;
            e.sphere = [hl.sphere.center[0], hl.sphere.center[1], hl.sphere.center[2], hl.sphere.radius];
        }
        let encoded = encoded.map_err(|m| invalid_cluster(node, m))?;
        self.emit(writer, node, &hl.dag, encoded, false)?;
        self.hand_up(node, &hl.dag, &seams, range)
    }

    /// Records `node` as complete, with its roots (from `dag`) and their seams for its parent's
    /// HLOD: empty when the parent was built by a build plan's shard (nobody reads them).
    fn hand_up(
        &mut self,
        node: u32,
        dag: &LodDag,
        seams: &SeamTable,
        range: (u32, u32),
    ) -> Result<(), BuildError> {
        let parent = self.index.parent[node as usize];
        if self.prebuilt.is_some_and(|p| parent != u32::MAX && p.has_node(parent)) {
            self.roots[node as usize] = Some((Roots::default(), SeamTable::default()));
            return Ok(());
        }
        self.roots[node as usize] =
            Some(self.index.subtree_roots(self.hierarchy, node, dag, seams, range)?);
        Ok(())
    }
}

/// A cluster the page codec refuses (a bug of the build, reported rather than written).
fn invalid_cluster(node: u32, message: String) -> BuildError {
    BuildError::store(tw_store::StoreError::Invalid(format!("hierarchy node {node}: {message}")))
}

fn store_group(g: &LodGroup, node: u32, triangles: u32, cluster_count: u32) -> tw_store::Group {
    tw_store::Group {
        sphere: [g.sphere.center[0], g.sphere.center[1], g.sphere.center[2], g.sphere.radius],
        error: g.error,
        node,
        level: g.level,
        page: u32::MAX,
        first_cluster: 0,
        cluster_count,
        triangles,
        source_count: 0,
    }
}

/// The node table: the hierarchy with each node's group range and the largest group error at
/// or below it.
fn store_nodes(h: &Hierarchy, node_groups: &[(u32, u32)], groups: &[tw_store::Group]) -> Vec<tw_store::Node> {
    let mut nodes: Vec<tw_store::Node> = h
        .nodes
        .iter()
        .zip(node_groups)
        .map(|(n, &(first, count))| {
            let max_error = groups[first as usize..(first + count) as usize]
                .iter()
                .map(|g| g.error)
                .fold(0.0f32, f32::max);
            tw_store::Node {
                min: n.bounds.min,
                max: n.bounds.max,
                first_child: n.first_child,
                child_count: n.child_count,
                first_group: first,
                group_count: count,
                max_error,
            }
        })
        .collect();
    // Children come after parents: a reverse sweep sees every child before its parent.
    for i in (0..nodes.len()).rev() {
        let (first, count) = (nodes[i].first_child as usize, nodes[i].child_count as usize);
        let child_max = nodes[first..first + count].iter().map(|c| c.max_error).fold(0.0f32, f32::max);
        nodes[i].max_error = nodes[i].max_error.max(child_max);
    }
    nodes
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::LodCluster;

    #[test]
    fn lod_window_is_a_sixteenth_of_the_budget() {
        assert_eq!(lod_window(256 << 20), Window { results: 16, bytes: 16 << 20 });
    }

    #[test]
    fn a_dags_heap_bytes_count_its_clusters_and_groups() {
        let empty = LodDag::default();
        assert_eq!(empty.heap_bytes(), 0);
        let dag = LodDag {
            clusters: vec![LodCluster {
                positions: vec![[0; 3]; 3],
                indices: vec![0, 1, 2],
                objects: vec![7],
                ..LodCluster::default()
            }],
            groups: vec![LodGroup { clusters: vec![0], ..LodGroup::default() }],
        };
        let own = 3 * 12 + 3 + 4 + 4;
        let structs = std::mem::size_of::<LodCluster>() + std::mem::size_of::<LodGroup>();
        assert_eq!(dag.heap_bytes(), own + structs);
    }
}
