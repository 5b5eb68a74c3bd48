//! `terawalk build-job DIR JOB`: runs one job of a build plan (`commands::build_plan`). A job
//! that is done (DIR/done/JOB) exits at once; one whose predecessors are not done is refused;
//! its outputs appear atomically (`tw_build::plan`), and the marker is written last, so a
//! killed job is simply run again.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Parser;
use tw_build::plan::{run_cells, run_pack, run_prepare, JobKind};

use crate::cli::{BuildArgs, BuildJobArgs, Cli, Command};
use crate::commands::build::{open_scene, print_report, Bars};
use crate::commands::build_plan::{describe_job, done_marker, PlanFile};
use crate::units::{fmt_bytes, fmt_count, fmt_count_rate};

pub fn run(args: BuildJobArgs, quiet: bool) -> Result<()> {
    let start = Instant::now();
    let dir = std::path::absolute(&args.dir)?;
    let plan = PlanFile::read(&dir)?;
    let Some(job) = plan.job(&args.job) else {
        let ids: Vec<&str> = plan.jobs.iter().map(|j| j.id.as_str()).collect();
        bail!("{}: no job {:?} in this plan; its jobs: {}", dir.display(), args.job, ids.join(", "));
    };
    let kind = JobKind::parse(&job.id, plan.shards)
        .with_context(|| format!("{}: job {:?} is not one this terawalk knows", dir.display(), job.id))?;
    if done_marker(&dir, &job.id).exists() {
        if !quiet {
            outln!("{}: already done ({})", job.id, done_marker(&dir, &job.id).display());
        }
        return Ok(());
    }
    if let Some(missing) = job.after.iter().find(|a| !done_marker(&dir, a).exists()) {
        bail!(
            "job {} needs job {missing} to have finished first (no {})",
            job.id,
            done_marker(&dir, missing).display()
        );
    }
    tracing::info!("{}", describe_job(job));
    let build = build_args(&plan)?;
    let mut bars = Bars::new(quiet);
    let opts = match kind {
        JobKind::Prepare => {
            let (scene, opts, _inputs) = open_scene(&build, &plan.output, quiet)?;
            let r = run_prepare(scene, &dir, &opts, &mut bars).with_context(|| format!("job {}", job.id))?;
            if !quiet {
                outln!(
                    "prepared {} input triangles in {} cells",
                    fmt_count(r.input_triangles),
                    fmt_count(r.redefine.cells)
                );
            }
            opts
        }
        JobKind::Cells { shard } => {
            let opts = crate::commands::build::options(&build);
            let r = run_cells(&dir, shard, plan.shards, &opts, &mut bars)
                .with_context(|| format!("job {}", job.id))?;
            if !quiet {
                outln!(
                    "{}: {} cells of {} buckets, {} HLOD nodes, {} written, {}",
                    job.id,
                    fmt_count(r.cells),
                    fmt_count(r.buckets),
                    fmt_count(r.nodes),
                    fmt_bytes(r.bytes_written),
                    fmt_count_rate(r.input_triangles, r.seconds, "input triangles")
                );
            }
            opts
        }
        JobKind::Pack => {
            let opts = crate::commands::build::options(&build);
            let r = run_pack(&dir, plan.shards, &plan.output, &opts, &mut bars)
                .with_context(|| format!("job pack: building {}", plan.output.display()))?;
            if !quiet {
                print_report(&plan.output, &r, start.elapsed().as_secs_f64(), opts.memory);
            }
            opts
        }
    };
    write_marker(&dir, &job.id, start.elapsed().as_secs_f64(), opts.memory)
}

/// The plan's build arguments, parsed as `terawalk build` parses them.
fn build_args(plan: &PlanFile) -> Result<BuildArgs> {
    let argv = std::iter::once("terawalk".to_string()).chain(plan.command.iter().cloned());
    match Cli::try_parse_from(argv).map(|c| c.command) {
        Ok(Command::Build(b)) => Ok(b),
        Ok(_) => bail!("the plan's command is not a build: {:?}", plan.command),
        Err(e) => bail!("the plan's build command does not parse ({e}): {:?}", plan.command),
    }
}

/// DIR/done/JOB, atomically: what ran, how long, its peak memory.
fn write_marker(dir: &Path, job: &str, seconds: f64, budget: u64) -> Result<()> {
    let done = dir.join("done");
    std::fs::create_dir_all(&done).with_context(|| format!("creating {}", done.display()))?;
    let marker = serde_json::json!({
        "job": job,
        "seconds": seconds,
        "peak_rss_bytes": tw_core::mem::peak_rss_bytes(),
        "memory_budget_bytes": budget,
        "host": hostname(),
    });
    let path = done_marker(dir, job);
    let tmp = done.join(format!(".{job}.tmp"));
    std::fs::write(&tmp, serde_json::to_string_pretty(&marker)? + "\n")
        .and_then(|()| std::fs::rename(&tmp, &path))
        .with_context(|| format!("writing {}", path.display()))
}

fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname").map(|h| h.trim().to_string()).unwrap_or_default()
}
