//! `terawalk build --plan DIR --submit slurm|k8s`: hands the jobs of a written plan
//! (DIR/plan.json, docs/BUILD.md "A plan of jobs") to a scheduler. Each job runs
//! `terawalk build-job DIR ID`; the scheduler only has to start a job after the jobs of its
//! "after" list succeeded, which Slurm does with `afterok` dependencies ([`slurm`]) and a
//! Kubernetes manifest with init containers that wait for the plan's done markers ([`k8s`]).
//!
//! The plan is read here from its JSON, as a scheduler would see it, rather than from the
//! writer's types: what is submitted is exactly what the jobs will read.

mod k8s;
mod slurm;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use crate::cli::SubmitTarget;
use crate::commands::build_plan::PlanFile;
pub use crate::commands::build_plan::PlanJob;

/// A build plan as the schedulers need it: where the store appears and the job graph.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The plan directory (absolute), shared by every job.
    pub dir: PathBuf,
    /// The store the `pack` job writes.
    pub output: PathBuf,
    /// The jobs, each after the jobs it depends on.
    pub jobs: Vec<PlanJob>,
}

impl Plan {
    /// The job whose end means the store is written: `pack`, else the last job.
    pub fn final_job(&self) -> &PlanJob {
        self.jobs
            .iter()
            .find(|j| j.id == "pack")
            .unwrap_or_else(|| self.jobs.last().expect("a plan has jobs"))
    }
}

/// Submits the plan in `plan_dir` to `target` (see the module). `quiet` leaves out the summary.
pub fn submit(plan_dir: &Path, target: SubmitTarget, quiet: bool) -> Result<()> {
    let plan = read_plan(plan_dir)?;
    match target {
        SubmitTarget::Slurm => slurm::submit(&plan, &job_executable()?, quiet),
        SubmitTarget::K8s => k8s::write_manifest(&plan, quiet),
    }
}

/// The program each Slurm job runs: this terawalk, by its absolute path (the nodes share the
/// file system). `TERAWALK_JOB_EXE` replaces it, for tests that run the jobs as a stand-in.
fn job_executable() -> Result<PathBuf> {
    if let Some(exe) = std::env::var_os("TERAWALK_JOB_EXE") {
        return std::path::absolute(PathBuf::from(exe)).context("TERAWALK_JOB_EXE");
    }
    std::env::current_exe().context("cannot find the path of the terawalk executable")
}

/// Reads and checks `plan_dir/plan.json` ([`PlanFile::read`]); every error names the file.
pub fn read_plan(plan_dir: &Path) -> Result<Plan> {
    let dir = std::path::absolute(plan_dir)
        .with_context(|| format!("{}: bad plan directory", plan_dir.display()))?;
    let plan = PlanFile::read(&dir)?;
    Ok(Plan { dir, output: plan.output, jobs: plan.jobs })
}

/// Parses a plan's JSON text ([`PlanFile::parse`]); `dir` is the directory it came from.
#[cfg(test)]
fn parse_plan(text: &str, dir: PathBuf) -> Result<Plan> {
    let plan = PlanFile::parse(text)?;
    Ok(Plan { dir, output: plan.output, jobs: plan.jobs })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The plan of the schema's example (docs/BUILD.md, "A plan of jobs"), two cell shards.
    pub(crate) const EXAMPLE: &str = r#"{
      "format": "terawalk-build-plan", "version": 1, "created_by": "terawalk 0.1.0",
      "output": "/abs/path/scene.tw",
      "command": ["build", "/abs/in.ply", "-o", "/abs/path/scene.tw"],
      "shards": 2,
      "jobs": [
        {"id": "prepare", "after": [], "memory_bytes": 1073741824, "disk_bytes": 9000000000, "cpus": 2},
        {"id": "cells-000", "after": ["prepare"], "memory_bytes": 1073741824, "disk_bytes": 900000000, "cpus": 2},
        {"id": "cells-001", "after": ["prepare"], "memory_bytes": 1073741824, "disk_bytes": 900000000, "cpus": 2},
        {"id": "merge-1-000", "after": ["cells-000", "cells-001"], "memory_bytes": 1073741824, "disk_bytes": 10000000, "cpus": 2},
        {"id": "pack", "after": ["prepare", "cells-000", "cells-001", "merge-1-000"], "memory_bytes": 1073741824, "disk_bytes": 1200000000, "cpus": 1}
      ]
    }"#;

    pub(crate) fn example() -> Plan {
        parse_plan(EXAMPLE, PathBuf::from("/shared/plan")).unwrap()
    }

    fn error_of(text: &str) -> String {
        format!("{:#}", parse_plan(text, PathBuf::from("/p")).unwrap_err())
    }

    #[test]
    fn reads_the_example_plan() {
        let plan = example();
        assert_eq!(plan.jobs.len(), 5);
        assert_eq!(plan.output, Path::new("/abs/path/scene.tw"));
        assert_eq!(plan.jobs[3].after, ["cells-000", "cells-001"]);
        assert_eq!(plan.jobs[4].cpus, 1);
        assert_eq!(plan.final_job().id, "pack");
    }

    #[test]
    fn refuses_another_format_or_version() {
        let other = EXAMPLE.replace("terawalk-build-plan", "something-else");
        assert!(
            error_of(&other).contains("\"something-else\", not \"terawalk-build-plan\""),
            "{}",
            error_of(&other)
        );
        let newer = EXAMPLE.replace("\"version\": 1", "\"version\": 2");
        assert!(
            error_of(&newer).contains("plan version 2, but this terawalk reads version 1"),
            "{}",
            error_of(&newer)
        );
        assert!(error_of("[1, 2").contains("not JSON"));
        assert!(error_of(r#"{"format": "terawalk-build-plan"}"#).contains("no \"version\""));
    }

    #[test]
    fn refuses_a_broken_job_graph() {
        let forward =
            EXAMPLE.replace(r#""after": [], "memory_bytes""#, r#""after": ["pack"], "memory_bytes""#);
        assert!(
            error_of(&forward).contains("job prepare runs after pack, which is not a job listed before it")
        );
        let twice = EXAMPLE.replace("\"cells-001\", \"after\"", "\"cells-000\", \"after\"");
        assert!(error_of(&twice).contains("job cells-000 is listed twice"), "{}", error_of(&twice));
        let shell = EXAMPLE.replace("\"id\": \"pack\"", "\"id\": \"pack; rm -rf /\"");
        assert!(error_of(&shell).contains("ids are 1 to 40 letters"));
        let no_cpus = EXAMPLE.replace("\"cpus\": 1", "\"cpus\": 0");
        assert!(
            error_of(&no_cpus).contains("job pack: \"cpus\" must be 1 or more"),
            "{}",
            error_of(&no_cpus)
        );
        let no_memory = EXAMPLE.replace(
            "\"memory_bytes\": 1073741824, \"disk_bytes\": 9000000000",
            "\"disk_bytes\": 9000000000",
        );
        assert!(error_of(&no_memory).contains("missing field `memory_bytes`"), "{}", error_of(&no_memory));
        assert!(error_of(&EXAMPLE.replace("\"jobs\"", "\"jobz\"")).contains("missing field `jobs`"));
    }

    #[test]
    fn a_missing_plan_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let e = format!("{:#}", read_plan(dir.path()).unwrap_err());
        assert!(e.contains("plan.json") && e.contains("write the plan first"), "{e}");
    }
}
