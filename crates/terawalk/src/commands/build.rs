//! `terawalk build`: inputs → store file (tw-build), with a progress bar per phase and a summary.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use indicatif::ProgressBar;
use tw_build::{BuildOptions, BuildProgress};
use tw_io::{Scene, SceneOptions};

use crate::cli::BuildArgs;
use crate::progress;
use crate::units::{fmt_bytes, fmt_count, fmt_count_rate};

/// Progress bars for the build's phases.
struct Bars {
    bar: Option<ProgressBar>,
    quiet: bool,
}

impl BuildProgress for Bars {
    fn phase(&mut self, name: &str, total: u64, unit: &str) {
        if self.quiet {
            return;
        }
        // A phase of unknown size (total 0) gets a spinner, one that counts nothing (no unit)
        // the elapsed time only.
        self.bar = Some(match unit {
            "bytes" => progress::bytes(total, name),
            "" if total == 0 => progress::elapsed(name),
            _ => progress::count(total, name),
        });
    }
    fn advance(&mut self, done: u64) {
        if let Some(b) = &self.bar {
            // A count past its announced total stretches the bar rather than overflowing it.
            if b.length().is_some_and(|l| done > l) {
                b.set_length(done);
            }
            b.set_position(done);
        }
    }
    fn end_phase(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}

pub fn options(args: &BuildArgs) -> BuildOptions {
    let mut o =
        BuildOptions { memory: args.memory, threads: worker_threads(args.threads), ..Default::default() };
    o.up = args.up.unwrap_or_default();
    o.units = args.units.clone();
    o.work_dir = args.work_dir.clone();
    // A multiple of 4 (meshopt's clusterizer works in groups of 4 triangles).
    let cluster = (args.cluster_triangles as usize / 4) * 4;
    o.lod.max_triangles = cluster;
    o.hlod.max_triangles = cluster;
    o
}

/// `--threads`, capped at [`tw_build::max_worker_threads`] with a warning.
fn worker_threads(asked: Option<u32>) -> Option<usize> {
    let asked = asked? as usize;
    let cap = tw_build::max_worker_threads();
    if asked > cap {
        tracing::warn!(
            "--threads {asked} is more than 4 per core on this machine ({} cores): using {cap}",
            cap / 4
        );
    }
    Some(asked.min(cap))
}

/// The smallest `--memory` the build is known to keep (docs/BUILD.md, "Memory").
const MIN_HELD_BUDGET: u64 = 128 << 20;

/// The importers' options, their vertex tables held to a quarter of `--memory` (the ingest
/// phase's share of the budget; the working file's write buffers and the scene's object
/// records are the rest).
fn import_options(args: &BuildArgs) -> tw_io::format::ImportOptions {
    let mut import = args.import.options();
    import.vertex_memory = import.vertex_memory.min((args.memory / 4).min(usize::MAX as u64) as usize);
    import
}

/// The store to write: `-o`, else the one input's name with the extension `.tw`, beside it.
fn output_path(args: &BuildArgs) -> Result<PathBuf> {
    match (&args.output, args.inputs.as_slice()) {
        (Some(o), _) => Ok(o.clone()),
        (None, [input]) => Ok(crate::commands::store_name_for(input)),
        (None, _) => {
            anyhow::bail!("{} inputs make one store: name it with -o (e.g. -o scene.tw)", args.inputs.len())
        }
    }
}

pub fn run(args: BuildArgs, quiet: bool) -> Result<()> {
    let start = Instant::now();
    let output = output_path(&args)?;
    tw_core::output::check_output(&output, &args.inputs)?;
    // (main has made every thread allocate from one heap arena: tw_core::mem::use_one_heap_arena.)
    if args.memory < MIN_HELD_BUDGET {
        tracing::warn!(
            "--memory {} is below {}: the build's fixed part (the program, the LOD workers' \
             working memory, minimum bucket and I/O buffer sizes) takes 60-90 MB, so its peak \
             will exceed the budget",
            fmt_bytes(args.memory),
            fmt_bytes(MIN_HELD_BUDGET)
        );
    }
    tw_core::disk_space::set_limits(tw_core::disk_space::Limits {
        max_written: args.temp_space.unwrap_or(u64::MAX),
        ..Default::default()
    });
    let scene = Scene::open(&args.inputs, SceneOptions { import: import_options(&args) })?;
    let opts = options(&args);
    let mut bars = Bars { bar: None, quiet };
    let r = tw_build::build(scene, &output, &opts, &mut bars)
        .with_context(|| format!("building {}", output.display()))?;
    let secs = start.elapsed().as_secs_f64();
    outln!("wrote {} ({})", output.display(), fmt_bytes(r.file_bytes));
    outln!("  up: {}", r.up);
    outln!(
        "  input: {} triangles ({} degenerate dropped, {} duplicate dropped), {} objects",
        fmt_count(r.input_triangles),
        fmt_count(r.degenerate_dropped),
        fmt_count(r.duplicate_dropped),
        fmt_count(r.objects)
    );
    let d = &r.redefine;
    outln!(
        "  objects: {} → partition I: {} pieces ({} split) → clustering: {} → partition II: {} cells ({} split, {} by count)",
        fmt_count(d.objects),
        fmt_count(d.pieces),
        fmt_count(d.split_objects),
        fmt_count(d.clusters),
        fmt_count(d.cells),
        fmt_count(d.split_clusters),
        fmt_count(d.count_split_cells)
    );
    outln!(
        "  hierarchy: {} nodes, depth {}; LOD: {} groups, {} clusters, {} triangles over all levels ({:.2}x input)",
        fmt_count(r.nodes),
        r.depth,
        fmt_count(r.groups),
        fmt_count(r.clusters),
        fmt_count(r.stored_triangles),
        r.stored_triangles as f64 / r.input_triangles.max(1) as f64
    );
    outln!(
        "  pages: {} ({} root), {:.2} bytes per input triangle",
        fmt_count(r.pages as u64),
        r.root_pages,
        r.file_bytes as f64 / r.input_triangles.max(1) as f64
    );
    let phases: Vec<String> = r.phases.iter().map(|(n, s)| format!("{n} {s:.1} s")).collect();
    outln!("  phases: {}", phases.join(", "));
    outln!(
        "done in {:.1} s: {}, peak memory {} (budget {})",
        secs,
        fmt_count_rate(r.input_triangles, secs, "input triangles"),
        r.peak_rss.map(fmt_bytes).unwrap_or_else(|| "unknown".into()),
        fmt_bytes(args.memory)
    );
    Ok(())
}
