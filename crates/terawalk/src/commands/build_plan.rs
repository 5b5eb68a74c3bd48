//! `terawalk build --plan DIR | --jobs local[:N]`: the build as a plan of jobs
//! (`tw_build::plan`; docs/BUILD.md, "A plan of jobs"), written to DIR/plan.json, and run on
//! this machine (`--jobs`) or submitted to a scheduler (`--submit`, `commands::build_submit`).
//! Each job is `terawalk build-job DIR JOB` (`commands::build_job`).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use tw_build::plan::{job_graph, Estimate, JobSpec};

use crate::cli::BuildArgs;
use crate::units::{fmt_bytes, fmt_count};

/// plan.json's `format` and `version`: a plan of another version is refused, not misread.
pub const PLAN_FORMAT: &str = "terawalk-build-plan";
pub const PLAN_VERSION: u32 = 1;

/// DIR/plan.json.
#[derive(Serialize, Deserialize, Debug, Clone)]
pub struct PlanFile {
    pub format: String,
    pub version: u32,
    pub created_by: String,
    /// The store the `pack` job writes (absolute).
    pub output: PathBuf,
    /// The build's arguments after `terawalk`, absolute paths, which every job parses again.
    pub command: Vec<String>,
    pub shards: u32,
    /// Each input file's path, size and modification time: a plan written again for the same
    /// build over unchanged inputs resumes (jobs done stay done); otherwise it starts over.
    #[serde(default)]
    pub inputs: Vec<String>,
    /// In an order where each job comes after those in its `after`.
    pub jobs: Vec<PlanJob>,
}

#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
pub struct PlanJob {
    pub id: String,
    pub after: Vec<String>,
    pub memory_bytes: u64,
    pub disk_bytes: u64,
    pub cpus: u32,
}

impl PlanFile {
    /// Reads `dir/plan.json`; every error names the file.
    pub fn read(dir: &Path) -> Result<PlanFile> {
        let path = dir.join("plan.json");
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!(
                "cannot read {}: write the plan first (terawalk build INPUT -o OUT.tw --plan DIR)",
                path.display()
            )
        })?;
        PlanFile::parse(&text).with_context(|| format!("{}: not a usable build plan", path.display()))
    }

    /// Parses a plan's JSON: its format and version first (a plan of another version is
    /// refused, not misread), then the fields, then the job graph ([`check_graph`]).
    pub fn parse(text: &str) -> Result<PlanFile> {
        let root: serde_json::Value = serde_json::from_str(text).context("not JSON")?;
        check_format(&root)?;
        let plan: PlanFile = serde_json::from_value(root)?;
        check_graph(&plan.jobs)?;
        Ok(plan)
    }

    /// Whether `other` is this plan's build: the same command, shards, inputs and jobs.
    fn same_build(&self, other: &PlanFile) -> bool {
        self.command == other.command
            && self.shards == other.shards
            && self.inputs == other.inputs
            && self.output == other.output
            && self.jobs == other.jobs
    }

    pub fn job(&self, id: &str) -> Option<&PlanJob> {
        self.jobs.iter().find(|j| j.id == id)
    }
}

/// Refuses a file of another format, or of a plan version this terawalk does not know.
fn check_format(root: &serde_json::Value) -> Result<()> {
    let format = root.get("format").and_then(serde_json::Value::as_str);
    if format != Some(PLAN_FORMAT) {
        bail!(
            "its \"format\" is {}, not \"{PLAN_FORMAT}\"",
            format.map_or("missing".into(), |f| format!("\"{f}\""))
        );
    }
    match root.get("version").and_then(serde_json::Value::as_u64) {
        Some(v) if v == PLAN_VERSION as u64 => Ok(()),
        Some(v) => bail!(
            "plan version {v}, but this terawalk reads version {PLAN_VERSION}: write the plan again with this \
             terawalk, or run it with the terawalk that wrote it"
        ),
        None => bail!("no \"version\" number"),
    }
}

/// Ids that are safe in file names, job names and shell words; each dependency listed earlier
/// (which also rules out cycles); no id twice; at least one cpu each.
fn check_graph(jobs: &[PlanJob]) -> Result<()> {
    if jobs.is_empty() {
        bail!("the plan has no jobs");
    }
    let mut seen = std::collections::HashSet::new();
    for job in jobs {
        let id_ok = !job.id.is_empty()
            && job.id.len() <= 40
            && job.id.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_' || b == b'.')
            && !job.id.starts_with(['.', '-']);
        if !id_ok {
            bail!("job id {:?}: ids are 1 to 40 letters, digits, '-', '_' or '.'", job.id);
        }
        if let Some(dep) = job.after.iter().find(|d| !seen.contains(d.as_str())) {
            bail!("job {} runs after {dep}, which is not a job listed before it", job.id);
        }
        if !seen.insert(job.id.as_str()) {
            bail!("job {} is listed twice", job.id);
        }
        if job.cpus == 0 {
            bail!("job {}: \"cpus\" must be 1 or more", job.id);
        }
    }
    Ok(())
}

/// Where a job's completion is recorded: DIR/done/JOB.
pub fn done_marker(dir: &Path, job: &str) -> PathBuf {
    dir.join("done").join(job)
}

/// `build --plan DIR` / `--jobs local[:N]`: writes the plan, then runs or submits it.
pub fn run(args: &BuildArgs, output: &Path, quiet: bool) -> Result<()> {
    let start = Instant::now();
    let output = std::path::absolute(output).with_context(|| format!("{}", output.display()))?;
    let (dir, _temporary) = plan_dir(args, &output)?;
    let (plan, resumed) = write_plan(args, &output, &dir)?;
    if !quiet {
        let done = plan.jobs.iter().filter(|j| done_marker(&dir, &j.id).exists()).count();
        let state = if resumed { format!("; the same build: {done} done, resuming") } else { String::new() };
        outln!(
            "wrote {} ({} jobs, {} shards{state})",
            dir.join("plan.json").display(),
            plan.jobs.len(),
            plan.shards
        );
    }
    if let Some(target) = args.plan.submit {
        return crate::commands::build_submit::submit(&dir, target, quiet);
    }
    match args.plan.jobs {
        Some(workers) => {
            run_local(&dir, &plan, workers, quiet)?;
            if !quiet {
                outln!("plan done in {:.1} s: {}", start.elapsed().as_secs_f64(), output.display());
            }
        }
        None if !quiet => {
            outln!(
                "run it with: terawalk build-job {} JOB, for each job in order (see plan.json),",
                dir.display()
            );
            outln!("  or: terawalk build ... --plan {} --jobs local:N | --submit slurm", dir.display());
        }
        None => {}
    }
    Ok(())
}

/// The plan directory: `--plan DIR` (created if missing; an existing plan there is replaced),
/// or, with `--jobs` alone, a temporary one beside the output, removed when done.
fn plan_dir(args: &BuildArgs, output: &Path) -> Result<(PathBuf, Option<tw_build::WorkDir>)> {
    if let Some(dir) = &args.plan.plan {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the plan directory {}", dir.display()))?;
        return Ok((std::path::absolute(dir)?, None));
    }
    let root = tw_build::work_root(output, args.work_dir.as_deref());
    let work = tw_build::WorkDir::create(&root)?;
    Ok((work.path().to_path_buf(), Some(work)))
}

/// Writes DIR/plan.json for `args` (atomically). When DIR already holds the plan of the same
/// build over unchanged inputs, its finished jobs stay finished (returns true: resumed);
/// otherwise its done markers are removed, so every job runs again.
fn write_plan(args: &BuildArgs, output: &Path, dir: &Path) -> Result<(PlanFile, bool)> {
    let estimate = estimate(args)?;
    let shards = args.plan.shards.unwrap_or_else(|| default_shards(estimate.triangles));
    let jobs = job_graph(shards, &estimate).iter().map(plan_job).collect();
    let plan = PlanFile {
        format: PLAN_FORMAT.into(),
        version: PLAN_VERSION,
        created_by: format!("terawalk {}", env!("CARGO_PKG_VERSION")),
        output: output.to_path_buf(),
        command: command_of(args, output)?,
        shards,
        inputs: fingerprints(&args.inputs),
        jobs,
    };
    let resumed = PlanFile::read(dir).is_ok_and(|old| old.same_build(&plan));
    if !resumed {
        drop(std::fs::remove_dir_all(dir.join("done")));
    }
    let path = dir.join("plan.json");
    let tmp = dir.join("plan.json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(&plan)? + "\n")
        .and_then(|()| std::fs::rename(&tmp, &path))
        .with_context(|| format!("writing {}", path.display()))?;
    Ok((plan, resumed))
}

/// "path size mtime" of each input (unreadable metadata leaves the time out).
fn fingerprints(inputs: &[PathBuf]) -> Vec<String> {
    inputs
        .iter()
        .map(|p| {
            let m = std::fs::metadata(p).ok();
            let modified = m
                .as_ref()
                .and_then(|m| m.modified().ok())
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok());
            let abs = std::path::absolute(p).unwrap_or_else(|_| p.clone());
            format!("{} {} {}", abs.display(), m.map_or(0, |m| m.len()), modified.map_or(0, |d| d.as_nanos()))
        })
        .collect()
}

fn plan_job(j: &JobSpec) -> PlanJob {
    PlanJob {
        id: j.kind.id(),
        after: j.after.iter().map(|k| k.id()).collect(),
        memory_bytes: j.memory,
        disk_bytes: j.disk,
        cpus: j.cpus,
    }
}

/// Input triangles per shard by default: a cells job then takes a minute or two on 2 cores.
const TRIANGLES_PER_SHARD: u64 = 10_000_000;

fn default_shards(triangles: u64) -> u32 {
    triangles.div_ceil(TRIANGLES_PER_SHARD).clamp(1, 4096) as u32
}

/// The plan's sizes: the generator's count, or the inputs' sizes over typical bytes per
/// triangle of their format (binary PLY and STL ~25–50, text formats ~60–100; 25 errs towards
/// more shards).
fn estimate(args: &BuildArgs) -> Result<Estimate> {
    let triangles = match &args.generate {
        Some(spec) => spec.triangles,
        None => {
            let mut bytes = 0u64;
            for input in &args.inputs {
                bytes += std::fs::metadata(input).with_context(|| format!("{}", input.display()))?.len();
            }
            bytes / 25
        }
    };
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get()) as u32;
    Ok(Estimate { triangles, memory: args.memory, cpus: args.threads.unwrap_or(cpus).min(cpus.max(1)) })
}

/// The build's arguments as a command line that `build-job` parses again: every option that
/// changes the store, with absolute paths (a job may run in another directory or on another
/// machine with the same shared paths). The plan's own flags are left out.
pub fn command_of(args: &BuildArgs, output: &Path) -> Result<Vec<String>> {
    let abs = |p: &Path| -> Result<String> { Ok(std::path::absolute(p)?.to_string_lossy().into_owned()) };
    let mut c = vec!["build".to_string()];
    for input in &args.inputs {
        c.push(abs(input)?);
    }
    let mut flag = |name: &str, value: String| {
        c.push(format!("--{name}"));
        c.push(value);
    };
    flag("output", abs(output)?);
    flag("memory", args.memory.to_string());
    if let Some(n) = args.threads {
        flag("threads", n.to_string());
    }
    if let Some(up) = args.up {
        flag("up", up.to_string());
    }
    flag("units", args.units.clone());
    if let Some(d) = &args.work_dir {
        flag("work-dir", abs(d)?);
    }
    if let Some(t) = args.temp_space {
        flag("temp-space", t.to_string());
    }
    flag("cluster-triangles", args.cluster_triangles.to_string());
    flag("page-triangles", args.page_triangles.to_string());
    flag("vertex-memory", args.import.vertex_memory.to_string());
    if let Some(d) = &args.import.spill_dir {
        flag("spill-dir", abs(d)?);
    }
    if let Some(g) = &args.generate {
        flag("generate", g.to_string());
    }
    if args.rt_bvh {
        c.push("--rt-bvh".to_string());
    }
    Ok(c)
}

/// One job running as a child process.
struct Running {
    id: String,
    child: Child,
    started: Instant,
}

/// Runs the plan's jobs on this machine, `workers` at a time, each as `terawalk build-job DIR
/// JOB` (the same command a scheduler runs), its output in DIR/logs/JOB.log. Stops starting
/// jobs at the first failure, waits for those running, and names the job that failed.
fn run_local(dir: &Path, plan: &PlanFile, workers: usize, quiet: bool) -> Result<()> {
    let exe = std::env::current_exe().context("finding the terawalk executable")?;
    let logs = dir.join("logs");
    std::fs::create_dir_all(&logs).with_context(|| format!("creating {}", logs.display()))?;
    let mut pending: Vec<&PlanJob> = plan.jobs.iter().collect();
    let mut running: Vec<Running> = Vec::new();
    let (mut finished, total) = (0usize, plan.jobs.len());
    let mut failure: Option<String> = None;
    while !pending.is_empty() || !running.is_empty() {
        while failure.is_none() && running.len() < workers {
            let Some(k) = pending.iter().position(|j| j.after.iter().all(|a| done_marker(dir, a).exists()))
            else {
                break;
            };
            let job = pending.remove(k);
            running.push(start_job(&exe, dir, &logs, &job.id)?);
        }
        if failure.is_some() && running.is_empty() {
            break;
        }
        if running.is_empty() {
            bail!("the plan's jobs wait for each other: {} cannot start", pending[0].id);
        }
        std::thread::sleep(Duration::from_millis(100));
        let mut k = 0;
        while k < running.len() {
            let Some(status) = running[k].child.try_wait()? else {
                k += 1;
                continue;
            };
            let r = running.swap_remove(k);
            let secs = r.started.elapsed().as_secs_f64();
            if status.success() {
                finished += 1;
                if !quiet {
                    outln!("[{finished}/{total}] {} done in {secs:.1} s", r.id);
                }
            } else if failure.is_none() {
                failure = Some(failed_job_message(&logs, &r.id, status));
            }
        }
    }
    match failure {
        Some(message) => bail!(message),
        None => Ok(()),
    }
}

fn start_job(exe: &Path, dir: &Path, logs: &Path, id: &str) -> Result<Running> {
    let log_path = logs.join(format!("{id}.log"));
    let log = std::fs::File::create(&log_path).with_context(|| format!("creating {}", log_path.display()))?;
    let child = Command::new(exe)
        .arg("-q")
        .arg("build-job")
        .arg(dir)
        .arg(id)
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .with_context(|| format!("starting job {id}"))?;
    Ok(Running { id: id.to_string(), child, started: Instant::now() })
}

/// "job X failed (exit status): the last lines of its log".
fn failed_job_message(logs: &Path, id: &str, status: std::process::ExitStatus) -> String {
    let log = logs.join(format!("{id}.log"));
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    let tail = lines[lines.len().saturating_sub(8)..].join("\n  ");
    format!("job {id} failed ({status}); its log {}:\n  {tail}", log.display())
}

/// A summary line for a job's resources (for `build-job`'s output).
pub fn describe_job(job: &PlanJob) -> String {
    format!(
        "{}: after [{}], memory {}, disk ~{}, {} cpus",
        job.id,
        job.after.join(", "),
        fmt_bytes(job.memory_bytes),
        fmt_bytes(job.disk_bytes),
        fmt_count(job.cpus as u64)
    )
}
