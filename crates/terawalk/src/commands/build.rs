//! `terawalk build`: inputs → store file (tw-build), with a progress bar per phase and a summary.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use indicatif::ProgressBar;
use tw_build::{BuildOptions, BuildProgress};
use tw_io::convert::{ConvertOptions, Converter};
use tw_io::{Scene, SceneOptions};

use crate::cli::BuildArgs;
use crate::progress;
use crate::units::{fmt_bytes, fmt_count, fmt_count_rate};

/// Progress bars for the build's phases.
pub struct Bars {
    bar: Option<ProgressBar>,
    quiet: bool,
}

impl Bars {
    pub fn new(quiet: bool) -> Bars {
        Bars { bar: None, quiet }
    }
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
    o.pages.page_triangles = args.page_triangles as usize;
    if args.rt_bvh {
        o.pages.rt_bvh = Some(tw_rt::scene::stored::cluster_tree);
    }
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
        (None, _) if args.generate.is_some() => {
            anyhow::bail!("--generate needs -o: name the store to write (e.g. -o plant.tw)")
        }
        (None, [input]) => Ok(crate::commands::store_name_for(input)),
        (None, _) => {
            anyhow::bail!("{} inputs make one store: name it with -o (e.g. -o scene.tw)", args.inputs.len())
        }
    }
}

/// Builds `args.inputs` into `output` with the phases' progress bars: the one build that
/// `terawalk build` and the commands opening a model directly (`commands::open`) share. The
/// store appears atomically (tw-build writes a temporary file and renames it).
pub fn build_store(args: &BuildArgs, output: &std::path::Path, quiet: bool) -> Result<tw_build::BuildReport> {
    build_store_with(args, output, quiet, &mut Bars { bar: None, quiet })
}

/// [`build_store`] reporting its phases to `progress` (the viewer's progress window).
pub fn build_store_with(
    args: &BuildArgs,
    output: &std::path::Path,
    quiet: bool,
    progress: &mut dyn BuildProgress,
) -> Result<tw_build::BuildReport> {
    let (scene, opts, _prepared) = open_scene(args, output, quiet)?;
    tw_build::build(scene, output, &opts, progress).with_context(|| format!("building {}", output.display()))
}

/// The build's scene and options from its arguments: the generator of `--generate`, or the
/// input files (converted first where terawalk does not read their format), with `--units`
/// defaulting to what the scene is known to be in. Every way of building (`build`, a plan's
/// jobs, the commands that open a model directly) opens its scene here, so they agree on it.
/// The [`Prepared`] inputs must live until the build has read the scene.
pub fn open_scene(args: &BuildArgs, output: &Path, quiet: bool) -> Result<(Scene, BuildOptions, Prepared)> {
    let mut opts = options(args);
    let (scene, units, prepared) = match &args.generate {
        Some(spec) => {
            let source = spec.source().with_context(|| format!("--generate {spec}"))?;
            (Scene::from_sources(vec![source]), Some(spec.units()), Prepared::nothing())
        }
        None => {
            let prepared = convert_inputs(args, output, quiet)?;
            let scene = Scene::open(&prepared.inputs, SceneOptions { import: import_options(args) })?;
            (scene, prepared.units, prepared)
        }
    };
    if opts.units.is_empty() {
        opts.units = units.unwrap_or_default().to_string();
    }
    Ok((scene, opts, prepared))
}

/// The inputs as the importers get them: those in a format terawalk does not read (IFC, STEP,
/// FBX, ...: `tw_io::convert`) converted into a working directory like the build's own
/// (`tw_build::WorkDir`: removed when this is dropped, on a signal, and after a kill
/// by the next build), which lives until the build has read them.
pub struct Prepared {
    inputs: Vec<PathBuf>,
    /// The units of the coordinates when every input was converted by tools that agree on them.
    units: Option<&'static str>,
    _work: Option<tw_build::WorkDir>,
}

impl Prepared {
    /// No input files (a generated scene).
    fn nothing() -> Prepared {
        Prepared { inputs: Vec::new(), units: None, _work: None }
    }
}

/// Converts the inputs that need it (see [`Prepared`]), reporting each tool's command and time.
fn convert_inputs(args: &BuildArgs, output: &Path, quiet: bool) -> Result<Prepared> {
    let converters: Vec<_> = args.inputs.iter().map(|p| Converter::for_path(p)).collect();
    if converters.iter().all(Option::is_none) {
        return Ok(Prepared { inputs: args.inputs.clone(), units: None, _work: None });
    }
    let root = tw_build::work_root(output, args.work_dir.as_deref());
    let work = tw_build::WorkDir::create(&root)?;
    let options = convert_options()?;
    let (mut inputs, mut units) = (Vec::new(), Vec::new());
    for (i, (input, converter)) in args.inputs.iter().zip(converters).enumerate() {
        let Some((converter, format)) = converter else {
            inputs.push(input.clone());
            units.push(None);
            continue;
        };
        let dir = work.path().join(format!("input-{i}"));
        std::fs::create_dir(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let spinner = (!quiet).then(|| progress::elapsed("convert"));
        if let Some(s) = &spinner {
            s.set_message(format!("{} ({format}) with {}", input.display(), converter.tool()));
        }
        let converted = tw_io::convert::convert(input, converter, &dir, &options);
        if let Some(s) = spinner {
            s.finish_and_clear();
        }
        let c = converted?;
        let summary = if c.summary.is_empty() { String::new() } else { format!(" ({})", c.summary) };
        let line = format!(
            "converted {} ({format}) with {} in {:.1} s{summary}: {}",
            input.display(),
            converter.tool(),
            c.elapsed.as_secs_f64(),
            c.command
        );
        tracing::info!("{line}");
        if !quiet {
            outln!("{line}");
        }
        inputs.push(c.output);
        units.push(c.units);
    }
    let agreed = units.first().copied().flatten().filter(|u| units.iter().all(|x| *x == Some(*u)));
    Ok(Prepared { inputs, units: agreed, _work: Some(work) })
}

/// The converters' settings: the tools from `PATH` unless `TERAWALK_ASSIMP` or
/// `TERAWALK_PYTHON` (a virtual environment's python, say) name others, and the time limit
/// `TERAWALK_CONVERT_TIMEOUT` (seconds; default [`tw_io::convert::DEFAULT_TIMEOUT`]).
fn convert_options() -> Result<ConvertOptions> {
    let mut o = ConvertOptions::default();
    if let Some(p) = std::env::var_os("TERAWALK_ASSIMP") {
        o.assimp = p.into();
    }
    if let Some(p) = std::env::var_os("TERAWALK_PYTHON") {
        o.python = p.into();
    }
    if let Ok(text) = std::env::var("TERAWALK_CONVERT_TIMEOUT") {
        let secs = text.trim().parse::<f64>().ok().filter(|s| s.is_finite() && *s > 0.0);
        let secs = secs.with_context(|| {
            format!("TERAWALK_CONVERT_TIMEOUT={text:?}: expected a positive number of seconds")
        })?;
        o.timeout = std::time::Duration::from_secs_f64(secs.min(1e9));
    }
    Ok(o)
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
    if args.plan.plan.is_some() || args.plan.jobs.is_some() {
        return crate::commands::build_plan::run(&args, &output, quiet);
    }
    let r = build_store(&args, &output, quiet)?;
    print_report(&output, &r, start.elapsed().as_secs_f64(), args.memory);
    Ok(())
}

/// The build's summary: what was written, the redefinition's and the LOD's figures, the phases'
/// times, the throughput and the peak memory against the budget.
pub fn print_report(output: &Path, r: &tw_build::BuildReport, secs: f64, memory: u64) {
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
        fmt_bytes(memory)
    );
}
