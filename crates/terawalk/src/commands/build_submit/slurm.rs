//! A plan's jobs as Slurm batch jobs: one `sbatch --parsable` each, in plan order, each with
//! `--dependency=afterok:` on the Slurm ids of its "after" jobs and `--kill-on-invalid-dep=yes`,
//! so that a failed job cancels the jobs that need it instead of leaving them pending forever.
//! Consecutive jobs of one family (`cells-000`, `cells-001`, …) with the same dependencies and
//! resources go as one array job; a job after some of its tasks waits on `afterok:ARRAY_TASK`,
//! after all of them on the array. The submitted ids go to DIR/slurm-jobs.json.

use std::collections::HashMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use serde_json::json;

use super::{Plan, PlanJob};

/// One sbatch submission: a single job, or an array job of consecutive jobs of a family.
#[derive(Debug)]
enum Unit<'a> {
    One(&'a PlanJob),
    Array { family: &'a str, jobs: Vec<&'a PlanJob> },
}

impl<'a> Unit<'a> {
    fn jobs(&self) -> &[&'a PlanJob] {
        match self {
            Unit::One(job) => std::slice::from_ref(job),
            Unit::Array { jobs, .. } => jobs,
        }
    }
    /// The name in job names and log files: the job's id, or the array's family.
    fn name(&self) -> &str {
        match self {
            Unit::One(job) => &job.id,
            Unit::Array { family, .. } => family,
        }
    }
}

/// Submits `plan` (see the module); `exe` is the terawalk every job runs.
pub fn submit(plan: &Plan, exe: &Path, quiet: bool) -> Result<()> {
    let logs = plan.dir.join("logs");
    std::fs::create_dir_all(&logs).with_context(|| format!("cannot create {}", logs.display()))?;
    let units = group_units(&plan.jobs);
    let mut submitted: Vec<String> = Vec::new();
    let mut ids: HashMap<&str, String> = HashMap::new();
    for unit in &units {
        let dependency = dependency_of(unit, &units, &submitted, &ids);
        let argv = sbatch_argv(unit, &plan.dir, exe, dependency.as_deref());
        let slurm_id = match run_sbatch(&argv) {
            Ok(id) => id,
            Err(e) => return Err(cancel_submitted(&submitted, unit.name(), e)),
        };
        record_ids(unit, &slurm_id, &mut ids);
        submitted.push(slurm_id);
    }
    write_job_ids(plan, &ids).inspect_err(|_| {
        let _ = scancel(&submitted);
    })?;
    if !quiet {
        print_summary(plan, &units, &submitted, &ids);
    }
    Ok(())
}

/// Plan jobs → submissions: a run of two or more consecutive jobs of one family with equal
/// dependencies and resources becomes an array job.
fn group_units(jobs: &[PlanJob]) -> Vec<Unit<'_>> {
    let mut units: Vec<Unit<'_>> = Vec::new();
    for job in jobs {
        let joins = match units.last() {
            Some(last) => family(&job.id).is_some_and(|f| {
                let first = last.jobs()[0];
                family(&first.id) == Some(f)
                    && first.after == job.after
                    && (first.memory_bytes, first.disk_bytes, first.cpus)
                        == (job.memory_bytes, job.disk_bytes, job.cpus)
            }),
            None => false,
        };
        match units.last_mut() {
            Some(Unit::Array { jobs, .. }) if joins => jobs.push(job),
            Some(last @ Unit::One(_)) if joins => {
                let first = last.jobs()[0];
                *last = Unit::Array { family: family(&first.id).expect("joins"), jobs: vec![first, job] };
            }
            _ => units.push(Unit::One(job)),
        }
    }
    units
}

/// `cells-003` → `cells`, `merge-1-000` → `merge-1`; an id without a numbered tail has no family.
fn family(id: &str) -> Option<&str> {
    let (head, tail) = id.rsplit_once('-')?;
    (!head.is_empty() && !tail.is_empty() && tail.bytes().all(|b| b.is_ascii_digit())).then_some(head)
}

/// `afterok:…` on the Slurm ids of the unit's dependencies: a whole array by its id when the
/// unit needs every task of it, else the tasks one by one.
fn dependency_of(
    unit: &Unit<'_>,
    units: &[Unit<'_>],
    submitted: &[String],
    ids: &HashMap<&str, String>,
) -> Option<String> {
    let after = &unit.jobs()[0].after;
    if after.is_empty() {
        return None;
    }
    let mut tokens: Vec<String> = Vec::new();
    let mut covered: Vec<&str> = Vec::new();
    for (earlier, slurm_id) in units.iter().zip(submitted) {
        if let Unit::Array { jobs, .. } = earlier {
            if jobs.iter().all(|j| after.contains(&j.id)) {
                tokens.push(slurm_id.clone());
                covered.extend(jobs.iter().map(|j| j.id.as_str()));
            }
        }
    }
    tokens.extend(after.iter().filter(|a| !covered.contains(&a.as_str())).map(|a| ids[a.as_str()].clone()));
    Some(format!("afterok:{}", tokens.join(":")))
}

/// The argument list of `sbatch` for one unit (without the program name).
fn sbatch_argv(unit: &Unit<'_>, dir: &Path, exe: &Path, dependency: Option<&str>) -> Vec<OsString> {
    let job = unit.jobs()[0];
    let log = match unit {
        Unit::One(_) => format!("{}-%j.out", unit.name()),
        Unit::Array { .. } => format!("{}-%A_%a.out", unit.name()),
    };
    let mut argv: Vec<OsString> = vec![
        "--parsable".into(),
        format!("--job-name=terawalk-{}", unit.name()).into(),
        format!("--mem={}M", job.memory_bytes.div_ceil(1 << 20).max(1)).into(),
        format!("--cpus-per-task={}", job.cpus).into(),
        concat_os("--output=", dir.join("logs").join(log).as_os_str()),
        concat_os("--chdir=", dir.as_os_str()),
    ];
    if let Unit::Array { jobs, .. } = unit {
        argv.push(format!("--array=0-{}", jobs.len() - 1).into());
    }
    if let Some(dependency) = dependency {
        argv.push(format!("--dependency={dependency}").into());
        argv.push("--kill-on-invalid-dep=yes".into());
    }
    argv.push(concat_os("--wrap=", batch_script(unit, dir, exe).as_ref()));
    argv
}

/// The shell command Slurm runs: `terawalk build-job DIR ID`, an array task picking its id by
/// `SLURM_ARRAY_TASK_ID` from the list.
fn batch_script(unit: &Unit<'_>, dir: &Path, exe: &Path) -> String {
    let (exe, dir) = (sh_quote(&exe.to_string_lossy()), sh_quote(&dir.to_string_lossy()));
    match unit {
        Unit::One(job) => format!("exec {exe} build-job {dir} {}", sh_quote(&job.id)),
        Unit::Array { jobs, .. } => {
            let ids: Vec<String> = jobs.iter().map(|j| sh_quote(&j.id)).collect();
            format!(
                "set -- {}; shift \"$SLURM_ARRAY_TASK_ID\"; exec {exe} build-job {dir} \"$1\"",
                ids.join(" ")
            )
        }
    }
}

/// A word for `sh`: single quotes, each `'` inside as `'\''`.
fn sh_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

fn concat_os(a: &str, b: &std::ffi::OsStr) -> OsString {
    let mut s = OsString::from(a);
    s.push(b);
    s
}

/// Runs sbatch; its job id (`--parsable` prints `ID` or `ID;CLUSTER`).
fn run_sbatch(argv: &[OsString]) -> Result<String> {
    let out = match Command::new("sbatch").args(argv).output() {
        Ok(out) => out,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            bail!("sbatch not found: is Slurm installed? scripts/slurm-node.sh starts a one-node cluster for testing")
        }
        Err(e) => return Err(e).context("cannot run sbatch"),
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        let hint = if stderr.contains("configuration source") {
            "\n  no Slurm configuration here: run on a cluster's login node, or set SLURM_CONF \
             (scripts/slurm-node.sh start DIR starts a one-node cluster and prints it)"
        } else {
            ""
        };
        bail!("sbatch failed ({}): {}{hint}", out.status, stderr.trim());
    }
    let id = stdout.trim().split(';').next().unwrap_or("").to_owned();
    if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
        bail!("sbatch printed no job id: {:?}", stdout.trim());
    }
    Ok(id)
}

/// The Slurm id of each plan job: the job's, or `ARRAY_INDEX` for an array task.
fn record_ids<'a>(unit: &Unit<'a>, slurm_id: &str, ids: &mut HashMap<&'a str, String>) {
    match unit {
        Unit::One(job) => {
            ids.insert(&job.id, slurm_id.to_owned());
        }
        Unit::Array { jobs, .. } => {
            for (k, job) in jobs.iter().enumerate() {
                ids.insert(&job.id, format!("{slurm_id}_{k}"));
            }
        }
    }
}

/// After a failed submission of `name`: cancels what was submitted, and says so in the error.
fn cancel_submitted(submitted: &[String], name: &str, error: anyhow::Error) -> anyhow::Error {
    let cancelled = match scancel(submitted) {
        Ok(()) if submitted.is_empty() => String::new(),
        Ok(()) => format!(" (cancelled the Slurm jobs already submitted: {})", submitted.join(", ")),
        Err(e) => {
            format!(" (and cancelling the jobs already submitted, {}, failed: {e:#})", submitted.join(", "))
        }
    };
    error.context(format!("cannot submit job {name}{cancelled}"))
}

fn scancel(ids: &[String]) -> Result<()> {
    if ids.is_empty() {
        return Ok(());
    }
    let out = Command::new("scancel").args(ids).output().context("cannot run scancel")?;
    if !out.status.success() {
        bail!("scancel failed: {}", String::from_utf8_lossy(&out.stderr).trim());
    }
    Ok(())
}

/// DIR/slurm-jobs.json: each plan job's Slurm id, in plan order; written whole or not at all.
fn write_job_ids(plan: &Plan, ids: &HashMap<&str, String>) -> Result<PathBuf> {
    let jobs: Vec<_> =
        plan.jobs.iter().map(|j| json!({"id": j.id, "slurm_id": ids[j.id.as_str()]})).collect();
    let doc = json!({"format": "terawalk-slurm-jobs", "version": 1, "plan": plan.dir, "jobs": jobs});
    let path = plan.dir.join("slurm-jobs.json");
    let tmp = plan.dir.join("slurm-jobs.json.tmp");
    let text = serde_json::to_string_pretty(&doc).expect("JSON of strings") + "\n";
    std::fs::write(&tmp, text)
        .and_then(|()| std::fs::rename(&tmp, &path))
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

fn print_summary(plan: &Plan, units: &[Unit<'_>], submitted: &[String], ids: &HashMap<&str, String>) {
    let arrays: Vec<String> = units
        .iter()
        .zip(submitted)
        .filter_map(|(u, id)| match u {
            Unit::Array { jobs, .. } => {
                Some(format!("{} … {} as array {id}", jobs[0].id, jobs[jobs.len() - 1].id))
            }
            Unit::One(_) => None,
        })
        .collect();
    let arrays = if arrays.is_empty() { String::new() } else { format!("; {}", arrays.join(", ")) };
    let last = plan.final_job();
    outln!("submitted {} plan jobs to Slurm as {} sbatch jobs{arrays}", plan.jobs.len(), units.len());
    outln!("  job ids: {}", plan.dir.join("slurm-jobs.json").display());
    outln!("  watch: squeue -j {}   (logs: {})", submitted.join(","), plan.dir.join("logs").display());
    outln!(
        "  the store appears at {} when job {} ({}) ends",
        plan.output.display(),
        ids[last.id.as_str()],
        last.id
    );
}

#[cfg(test)]
mod tests {
    use super::super::tests::example;
    use super::*;

    fn strings(argv: &[OsString]) -> Vec<String> {
        argv.iter().map(|a| a.to_string_lossy().into_owned()).collect()
    }

    #[test]
    fn cells_become_one_array() {
        let plan = example();
        let units = group_units(&plan.jobs);
        let names: Vec<&str> = units.iter().map(Unit::name).collect();
        assert_eq!(names, ["prepare", "cells", "merge-1-000", "pack"]);
        assert_eq!(family("merge-1-000"), Some("merge-1"));
        assert_eq!(family("prepare"), None);
        assert_eq!(family("cells-"), None);
    }

    #[test]
    fn jobs_of_a_family_with_other_dependencies_stay_apart() {
        let mut plan = example();
        plan.jobs[2].after.clear();
        let units = group_units(&plan.jobs);
        assert_eq!(units.len(), 5);
    }

    #[test]
    fn dependencies_name_arrays_whole_or_by_task() {
        let plan = example();
        let units = group_units(&plan.jobs);
        let submitted: Vec<String> = ["10", "11", "12", "13"].map(String::from).to_vec();
        let mut ids = HashMap::new();
        for (u, id) in units.iter().zip(&submitted) {
            record_ids(u, id, &mut ids);
        }
        assert_eq!(ids["cells-001"], "11_1");
        assert_eq!(dependency_of(&units[0], &units, &submitted[..0], &ids), None);
        assert_eq!(dependency_of(&units[1], &units, &submitted[..1], &ids).as_deref(), Some("afterok:10"));
        assert_eq!(dependency_of(&units[2], &units, &submitted[..2], &ids).as_deref(), Some("afterok:11"));
        assert_eq!(
            dependency_of(&units[3], &units, &submitted[..3], &ids).as_deref(),
            Some("afterok:11:10:12")
        );
        let mut partial = plan.clone();
        partial.jobs[3].after = vec!["cells-001".into()];
        let units = group_units(&partial.jobs);
        assert_eq!(dependency_of(&units[2], &units, &submitted[..2], &ids).as_deref(), Some("afterok:11_1"));
    }

    #[test]
    fn sbatch_arguments_of_a_job_and_of_an_array() {
        let plan = example();
        let units = group_units(&plan.jobs);
        let exe = Path::new("/opt/tw/bin/terawalk");
        let pack = strings(&sbatch_argv(&units[3], &plan.dir, exe, Some("afterok:11:12")));
        assert_eq!(
            pack,
            [
                "--parsable",
                "--job-name=terawalk-pack",
                "--mem=1024M",
                "--cpus-per-task=1",
                "--output=/shared/plan/logs/pack-%j.out",
                "--chdir=/shared/plan",
                "--dependency=afterok:11:12",
                "--kill-on-invalid-dep=yes",
                "--wrap=exec '/opt/tw/bin/terawalk' build-job '/shared/plan' 'pack'",
            ]
        );
        let cells = strings(&sbatch_argv(&units[1], &plan.dir, exe, Some("afterok:10")));
        assert!(cells.contains(&"--array=0-1".to_owned()), "{cells:?}");
        assert!(cells.contains(&"--output=/shared/plan/logs/cells-%A_%a.out".to_owned()));
        assert_eq!(
            cells.last().unwrap(),
            "--wrap=set -- 'cells-000' 'cells-001'; shift \"$SLURM_ARRAY_TASK_ID\"; \
             exec '/opt/tw/bin/terawalk' build-job '/shared/plan' \"$1\""
        );
        let first = strings(&sbatch_argv(&units[0], &plan.dir, exe, None));
        assert!(!first.iter().any(|a| a.starts_with("--dependency") || a.starts_with("--kill")));
    }

    #[test]
    fn memory_rounds_up_to_whole_megabytes() {
        let mut job = example().jobs[0].clone();
        job.memory_bytes = (1 << 20) + 1;
        let argv = strings(&sbatch_argv(&Unit::One(&job), Path::new("/p"), Path::new("/t"), None));
        assert!(argv.contains(&"--mem=2M".to_owned()), "{argv:?}");
    }

    #[test]
    fn the_array_script_picks_its_job_in_sh() {
        let plan = example();
        let units = group_units(&plan.jobs);
        let script = batch_script(&units[1], Path::new("/d"), Path::new("/bin/echo"));
        let script = script.replace("exec '/bin/echo' build-job '/d'", "echo");
        for (k, id) in ["cells-000", "cells-001"].iter().enumerate() {
            let out = Command::new("sh")
                .arg("-c")
                .arg(&script)
                .env("SLURM_ARRAY_TASK_ID", k.to_string())
                .output()
                .unwrap();
            assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), *id);
        }
    }

    #[test]
    fn quoting_survives_odd_paths() {
        assert_eq!(sh_quote("/a b/it's"), r"'/a b/it'\''s'");
        let out = Command::new("sh")
            .arg("-c")
            .arg(format!("printf %s {}", sh_quote("/a b/it's $HOME")))
            .output()
            .unwrap();
        assert_eq!(String::from_utf8_lossy(&out.stdout), "/a b/it's $HOME");
    }
}
