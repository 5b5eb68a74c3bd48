//! `terawalk build --plan DIR --submit slurm` end to end on a one-node Slurm cluster
//! (scripts/slurm-node.sh, in a temporary directory, on free ports): a small plant built as a
//! plan of jobs through sbatch must give the same store, byte for byte, as a plain build.
//!
//! The cluster needs root and Debian's Slurm and munge packages (the script installs them when
//! missing; .ci/run installs them). Where it cannot start, the test fails and shows why; set
//! TERAWALK_SKIP_SLURM=1 to skip it on a machine that cannot run Slurm.

mod common;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use common::{stderr, stdout, terawalk};

/// How long the plan's jobs may take together before the test gives up.
const JOBS_TIMEOUT: Duration = Duration::from_secs(600);

/// Job states after which a Slurm job never succeeds (`squeue --states=all`).
const FAILED_STATES: [&str; 9] = [
    "FAILED",
    "CANCELLED",
    "TIMEOUT",
    "OUT_OF_MEMORY",
    "NODE_FAIL",
    "BOOT_FAIL",
    "DEADLINE",
    "PREEMPTED",
    "REVOKED",
];

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/slurm-node.sh")
}

/// A started one-node cluster; dropping it stops the daemons (also when the test fails).
struct Cluster {
    state: PathBuf,
}

impl Cluster {
    /// Starts the cluster on two free ports, so that another cluster on this machine (a
    /// developer's, on Slurm's default ports) does not get in the way.
    fn start(state: &Path) -> Cluster {
        let (ctld, slurmd) = free_ports();
        let o = Command::new("bash")
            .arg(script())
            .args(["start".as_ref(), state.as_os_str()])
            .env("SLURM_NODE_CTLD_PORT", ctld.to_string())
            .env("SLURM_NODE_D_PORT", slurmd.to_string())
            .output()
            .expect("runs bash");
        let cluster = Cluster { state: state.to_owned() };
        assert!(
            o.status.success(),
            "scripts/slurm-node.sh start failed (set TERAWALK_SKIP_SLURM=1 where Slurm cannot run):\n{}\n{}",
            stdout(&o),
            stderr(&o)
        );
        cluster
    }

    fn conf(&self) -> PathBuf {
        self.state.join("slurm.conf")
    }

    /// A Slurm client command against this cluster.
    fn client(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", self.conf());
        c
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new("bash").arg(script()).args(["stop".as_ref(), self.state.as_os_str()]).status();
    }
}

/// Two ports free now: both listeners are held until both are picked, so they differ, then
/// closed for the daemons.
fn free_ports() -> (u16, u16) {
    let bind = || std::net::TcpListener::bind("127.0.0.1:0").expect("a free port");
    let (a, b) = (bind(), bind());
    (a.local_addr().unwrap().port(), b.local_addr().unwrap().port())
}

/// Runs terawalk in `dir` against the cluster (sbatch reads SLURM_CONF).
fn terawalk_on(cluster: &Cluster, args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(args)
        .current_dir(dir)
        .env("SLURM_CONF", cluster.conf())
        .output()
        .expect("runs terawalk")
}

/// Each plan job's Slurm id (`ID`, or `ARRAY_TASK` for an array task), from DIR/slurm-jobs.json.
fn submitted(plan: &Path) -> Vec<(String, String)> {
    let text = std::fs::read_to_string(plan.join("slurm-jobs.json")).expect("submit writes slurm-jobs.json");
    let v: serde_json::Value = serde_json::from_str(&text).expect("slurm-jobs.json is JSON");
    let jobs = v["jobs"].as_array().expect("a jobs list");
    jobs.iter()
        .map(|j| {
            (j["id"].as_str().unwrap().to_owned(), j["slurm_id"].as_str().expect("a slurm_id").to_owned())
        })
        .collect()
}

/// `squeue`'s lines (`ID NAME STATE REASON`) for the plan's jobs, ended ones included.
fn queue(cluster: &Cluster, plan: &Path) -> String {
    let mut ids: Vec<String> =
        submitted(plan).into_iter().map(|(_, s)| s.split('_').next().unwrap().to_owned()).collect();
    ids.dedup();
    let o = cluster
        .client("squeue")
        .args(["-h", "--states=all", "-j", &ids.join(","), "-o", "%i %j %T %r"])
        .output();
    o.map(|o| stdout(&o)).unwrap_or_default()
}

/// The state of each plan job, by its plan id, from `queue`'s lines.
fn states(plan: &Path, queue: &str) -> HashMap<String, String> {
    let by_slurm: HashMap<&str, &str> = queue
        .lines()
        .filter_map(|l| {
            let mut words = l.split_whitespace();
            Some((words.next()?, words.nth(1)?))
        })
        .collect();
    submitted(plan)
        .into_iter()
        .filter_map(|(id, slurm)| by_slurm.get(slurm.as_str()).map(|state| (id, state.to_string())))
        .collect()
}

/// Waits until the plan's done/pack marker appears; panics with the logs when a job fails or
/// the time runs out.
fn wait_for_pack(cluster: &Cluster, plan: &Path) {
    let start = Instant::now();
    while !plan.join("done").join("pack").exists() {
        let queue = queue(cluster, plan);
        let failed = states(plan, &queue).values().any(|s| FAILED_STATES.contains(&s.as_str()));
        if failed || start.elapsed() > JOBS_TIMEOUT {
            let why = if failed { "a job failed" } else { "the jobs did not end in time" };
            panic!("{why}:\n{queue}\n{}", logs(cluster, plan));
        }
        std::thread::sleep(Duration::from_secs(1));
    }
}

/// The jobs' output and the daemons' log tails, for a failure message.
fn logs(cluster: &Cluster, plan: &Path) -> String {
    let mut out = String::new();
    let mut files: Vec<PathBuf> = std::fs::read_dir(plan.join("logs"))
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    files.sort();
    for log in ["slurmctld.log", "slurmd.log"] {
        files.push(cluster.state.join("log").join(log));
    }
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap_or_default();
        let tail: Vec<&str> = text.lines().rev().take(40).collect();
        out += &format!("---- {}\n", file.display());
        for line in tail.iter().rev() {
            out += line;
            out.push('\n');
        }
    }
    out
}

#[test]
fn a_plan_on_slurm_builds_the_same_store() {
    if std::env::var("TERAWALK_SKIP_SLURM").as_deref() == Ok("1") {
        eprintln!("SKIPPED: TERAWALK_SKIP_SLURM=1");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let cluster = Cluster::start(&dir.path().join("slurm"));
    let o = terawalk(&["generate", "plant", "--triangles", "200k", "-o", "p.ply"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));

    let start = Instant::now();
    let plan = dir.path().join("plan");
    let args = ["build", "p.ply", "-o", "plan.tw", "--memory", "1G", "--plan", "plan", "--shards", "3"];
    let o = terawalk_on(&cluster, &[&args[..], &["--submit", "slurm"]].concat(), dir.path());
    assert!(o.status.success(), "{}\n{}", stdout(&o), stderr(&o));
    assert!(stdout(&o).contains("squeue"), "the summary says how to watch: {}", stdout(&o));
    wait_for_pack(&cluster, &plan);
    eprintln!("the plan's jobs on Slurm: {:.1} s", start.elapsed().as_secs_f64());

    let o = terawalk(&["build", "p.ply", "-o", "plain.tw", "--memory", "1G"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let planned = std::fs::read(dir.path().join("plan.tw")).expect("the pack job wrote plan.tw");
    let plain = std::fs::read(dir.path().join("plain.tw")).unwrap();
    assert!(
        planned == plain,
        "the plan's store differs from the plain build's ({} and {} bytes)",
        planned.len(),
        plain.len()
    );
}

/// A job that fails cancels the jobs after it (`--kill-on-invalid-dep=yes`) and the rest run:
/// the plan's jobs here are a stand-in (`TERAWALK_JOB_EXE`) that fails on cells-001 and
/// otherwise only leaves its done marker.
#[test]
fn a_failed_job_cancels_the_jobs_after_it() {
    if std::env::var("TERAWALK_SKIP_SLURM").as_deref() == Ok("1") {
        eprintln!("SKIPPED: TERAWALK_SKIP_SLURM=1");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let cluster = Cluster::start(&dir.path().join("slurm"));
    let o = terawalk(&["generate", "plant", "--triangles", "20k", "-o", "p.ply"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let stand_in = dir.path().join("stand-in.sh");
    let script = "#!/bin/sh\n[ \"$3\" = cells-001 ] && { echo failing on purpose; exit 7; }\n\
                  mkdir -p \"$2/done\" && : > \"$2/done/$3\"\n";
    std::fs::write(&stand_in, script).unwrap();
    let o = Command::new("chmod").arg("+x").arg(&stand_in).output().unwrap();
    assert!(o.status.success());

    let plan = dir.path().join("plan");
    let args = [
        "build", "p.ply", "-o", "x.tw", "--memory", "1G", "--plan", "plan", "--shards", "3", "--submit",
        "slurm",
    ];
    let o = Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(args)
        .current_dir(dir.path())
        .env("SLURM_CONF", cluster.conf())
        .env("TERAWALK_JOB_EXE", &stand_in)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}\n{}", stdout(&o), stderr(&o));
    let start = Instant::now();
    let ended = loop {
        let queue = queue(&cluster, &plan);
        let states = states(&plan, &queue);
        let running = ["PENDING", "CONFIGURING", "RUNNING", "COMPLETING"];
        if states.len() == submitted(&plan).len() && !states.values().any(|s| running.contains(&s.as_str())) {
            break states;
        }
        assert!(start.elapsed() < JOBS_TIMEOUT, "the jobs did not end:\n{queue}\n{}", logs(&cluster, &plan));
        std::thread::sleep(Duration::from_secs(1));
    };
    let context = format!("{ended:?}\n{}", logs(&cluster, &plan));
    assert_eq!(ended["prepare"], "COMPLETED", "{context}");
    assert_eq!(ended["cells-000"], "COMPLETED", "{context}");
    assert_eq!(ended["cells-001"], "FAILED", "{context}");
    assert_eq!(ended["pack"], "CANCELLED", "{context}");
    assert!(!plan.join("done").join("pack").exists());
    let log = std::fs::read_dir(plan.join("logs"))
        .unwrap()
        .filter_map(|e| e.ok())
        .find(|e| std::fs::read_to_string(e.path()).is_ok_and(|t| t.contains("failing on purpose")));
    assert!(log.is_some(), "the failing job's output is in DIR/logs: {context}");
}
