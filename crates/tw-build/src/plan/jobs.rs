//! The plan's jobs, each a function over the plan directory (see the module docs of
//! `crate::plan`). Every job takes the same [`BuildOptions`] (the plan records the build's
//! command line, and each job parses it again), so they agree on budgets and parameters.

use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use tw_io::Scene;
use tw_store::StoreWriter;

use super::graph::shard_buckets;
use super::records::{read_value, write_value, CellRecords, ShardWriter};
use super::shard_hlod::{strip_geometry, ShardHlod};
use crate::cell_pass::{CellPass, CellSource};
use crate::cells::{CellFiles, CellFilesMeta};
use crate::error::BuildError;
use crate::hierarchy::Hierarchy;
use crate::hlod_jobs::HlodJobs;
use crate::pipeline::{
    finish, lod_window, prepare, remove_stale_temporaries, worker_pool, BuildOptions, BuildProgress,
    BuildReport, Prepared, SceneFacts, Timer, WorkDir,
};
use crate::seams::{SeamFiles, SeamFilesMeta};

/// The prepared folder, inside the plan directory.
const PREPARED: &str = "prepared";
/// The prepared state's file, inside it.
const STATE: &str = "state.bin";
/// The shards' cells, inside the plan directory.
const CELLS: &str = "cells";

/// What `prepare` keeps for the later jobs, besides the bucket and seam files.
#[derive(Serialize, Deserialize)]
struct PreparedState {
    facts: SceneFacts,
    hierarchy: Hierarchy,
    cells: CellFilesMeta,
    seams: SeamFilesMeta,
    /// The seconds each of phases 1–4 took, for the pack job's report.
    phases: Vec<(String, f64)>,
}

/// Job `prepare`: phases 1–4 of `scene` into `plan/prepared/`, which appears only when complete
/// (it is built in a working directory beside it, removed on failure, and after a kill by the
/// next run). Returns the phases' report.
pub fn run_prepare(
    scene: Scene,
    plan: &Path,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
) -> Result<BuildReport, BuildError> {
    let pool = worker_pool(options)?;
    let target = plan.join(PREPARED);
    remove_stale_temporaries(&target, plan);
    if target.exists() {
        std::fs::remove_dir_all(&target).map_err(|e| BuildError::io(&target, e))?;
    }
    let work = WorkDir::create(plan)?;
    let mut report = BuildReport::default();
    let mut t = Timer::new(&mut report);
    let Prepared { facts, hierarchy, cells, seams } =
        prepare(scene, work.path(), options, progress, &pool, &mut t)?;
    let (cells, seams) = (cells.keep()?, seams.keep()?);
    let phases = report.phases.clone();
    let state = PreparedState { facts, hierarchy, cells, seams, phases };
    write_value(&work.path().join(STATE), &state)?;
    work.persist(&target)?;
    report.input_triangles = state.facts.triangles;
    report.objects = state.facts.objects.len() as u64;
    report.redefine = state.facts.redefine.clone();
    Ok(report)
}

/// What a `cells` job did.
#[derive(Clone, Debug, Default)]
pub struct CellsReport {
    pub cells: u64,
    /// HLOD nodes built (those whose cells all lie in the shard).
    pub nodes: u64,
    pub buckets: u64,
    pub input_triangles: u64,
    pub bytes_written: u64,
    pub seconds: f64,
}

/// Opens what `prepare` kept.
fn open_prepared(plan: &Path) -> Result<(Prepared, Vec<(String, f64)>), BuildError> {
    let dir = plan.join(PREPARED);
    let state: PreparedState = read_value(&dir.join(STATE))?;
    let PreparedState { facts, hierarchy, cells, seams, phases } = state;
    let prepared = Prepared {
        facts,
        hierarchy,
        cells: CellFiles::reopen(&cells, &dir),
        seams: SeamFiles::reopen(&seams, &dir),
    };
    Ok((prepared, phases))
}

/// Job `cells-K`: the LOD of shard `shard` of `shards` (its cells' DAGs and encoded clusters)
/// into `plan/cells/`.
pub fn run_cells(
    plan: &Path,
    shard: u32,
    shards: u32,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
) -> Result<CellsReport, BuildError> {
    let start = Instant::now();
    let pool = worker_pool(options)?;
    let (prepared, _) = open_prepared(plan)?;
    let cells = &prepared.cells;
    let bucket_triangles: Vec<u64> = (0..cells.bucket_count()).map(|b| cells.bucket_triangles(b)).collect();
    let buckets = shard_buckets(&bucket_triangles, shards, shard);
    let triangles: u64 = bucket_triangles[buckets.clone()].iter().sum();
    let pass = CellPass {
        cells,
        seams: &prepared.seams,
        buckets: buckets.clone(),
        window: lod_window(options.memory),
        source: CellSource::Build { grid: &prepared.facts.grid, params: &options.lod },
    };
    let cells_dir = plan.join(CELLS);
    let mut writer = ShardWriter::create(&cells_dir, shard)?;
    let jobs = HlodJobs::new(&prepared.facts.grid, &options.hlod);
    let range = pass.cell_range();
    let mut hlod = ShardHlod::new(&prepared.hierarchy, (range.start, range.end), &jobs);
    progress.phase("lod", triangles, "triangles");
    let mut done = 0u64;
    let mut count = 0u64;
    pass.run(&pool, &|| jobs.run_one(), |i, built, seams| {
        done += cells.cell_triangles()[i as usize];
        count += 1;
        progress.advance(done);
        hlod.add_cell(i, &built.dag, seams)?;
        let mut built = built;
        strip_geometry(&mut built.dag, hlod.pack_needs_roots_of_cell(i));
        writer.append(i, built)?;
        hlod.write_due(Some(i as usize), &mut writer)
    })?;
    hlod.write_due(None, &mut writer)?;
    writer.finish()?;
    progress.end_phase();
    let (bin, _) = super::records::shard_paths(&cells_dir, shard);
    Ok(CellsReport {
        cells: count,
        nodes: hlod.nodes,
        buckets: buckets.len() as u64,
        input_triangles: triangles,
        bytes_written: std::fs::metadata(&bin).map_or(0, |m| m.len()),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Job `pack`: the plain build's phases 5–6 over every shard's cells and HLOD nodes, read back
/// in cell order: the HLOD of the nodes that span shards, pages, tables, and the store at
/// `output` (atomically).
pub fn run_pack(
    plan: &Path,
    shards: u32,
    output: &Path,
    options: &BuildOptions,
    progress: &mut dyn BuildProgress,
) -> Result<BuildReport, BuildError> {
    let pool = worker_pool(options)?;
    let (prepared, phases) = open_prepared(plan)?;
    let records = CellRecords::open(&plan.join(CELLS), shards, prepared.cells.cell_count())?;
    remove_stale_temporaries(output, &crate::pipeline::work_root(output, None));
    let writer = StoreWriter::create(output).map_err(BuildError::store)?;
    let mut report = BuildReport { phases, ..BuildReport::default() };
    let mut t = Timer::new(&mut report);
    finish(&prepared, CellSource::Read(&records), writer, options, progress, &pool, &mut t)?;
    Ok(report)
}
