//! `terawalk build --plan DIR` and `build-job`: the build as a plan of jobs gives the plain
//! build's store byte for byte, with any number of local workers; a job run twice is a no-op;
//! a killed job run again gives the same outputs (`prepare`, `cells` and `pack` killed with
//! SIGKILL part-way through); a job whose predecessors have not finished, an unknown job and
//! damaged hand-over files are refused with messages naming them, and a failed job fails
//! `--jobs` naming it.

mod common;

use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use common::{stderr, stdout, terawalk};

fn run_ok(args: &[&str], dir: &Path) -> String {
    let o = terawalk(args, dir);
    assert!(o.status.success(), "terawalk {args:?}:\n{}\n{}", stdout(&o), stderr(&o));
    stdout(&o)
}

fn read(dir: &Path, name: &str) -> Vec<u8> {
    std::fs::read(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// A small plant, and its store built plainly.
fn plant(dir: &Path) {
    run_ok(&["generate", "plant", "--triangles", "300k", "-o", "p.ply"], dir);
    run_ok(&["build", "p.ply", "-o", "plain.tw", "--memory", "128M"], dir);
}

#[test]
fn a_plan_run_locally_builds_the_plain_store() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    plant(d);
    for (workers, shards) in [("local", "1"), ("local:2", "3"), ("local:3", "7")] {
        let out = run_ok(
            &["build", "p.ply", "-o", "plan.tw", "--memory", "128M", "--shards", shards, "--jobs", workers],
            d,
        );
        assert!(out.contains("pack done"), "{out}");
        assert!(read(d, "plan.tw") == read(d, "plain.tw"), "{workers}, {shards} shards: the stores differ");
        std::fs::remove_file(d.join("plan.tw")).unwrap();
    }
    // The temporary plan directories are gone.
    let left: Vec<_> = std::fs::read_dir(d).unwrap().flatten().filter(|e| e.path().is_dir()).collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn an_assembly_plan_builds_the_plain_store() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gen = ["--generate", "assembly:200k,one-object", "--memory", "128M"];
    run_ok(&[&["build", "-o", "plain.tw"][..], &gen].concat(), d);
    run_ok(
        &[&["build", "-o", "plan.tw", "--plan", "plan", "--shards", "4", "--jobs", "local:2"][..], &gen]
            .concat(),
        d,
    );
    assert!(read(d, "plan.tw") == read(d, "plain.tw"), "the stores differ");
}

/// The jobs one by one, as a scheduler runs them: order enforced, reruns idempotent, a killed
/// job's leftovers ignored.
#[test]
fn jobs_run_one_by_one_in_order_and_again() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    plant(d);
    let out = run_ok(
        &["build", "p.ply", "-o", "plan.tw", "--memory", "128M", "--plan", "plan", "--shards", "2"],
        d,
    );
    assert!(out.contains("build-job"), "says how to run it: {out}");

    // Out of order: refused, naming what is missing.
    let o = terawalk(&["build-job", "plan", "cells-000"], d);
    assert!(!o.status.success() && stderr(&o).contains("needs job prepare"), "{}", stderr(&o));
    let o = terawalk(&["build-job", "plan", "cells-9"], d);
    assert!(
        !o.status.success() && stderr(&o).contains("its jobs: prepare, cells-000, cells-001, pack"),
        "{}",
        stderr(&o)
    );

    run_ok(&["build-job", "plan", "prepare"], d);
    let out = run_ok(&["build-job", "plan", "cells-000"], d);
    // The shard builds the HLOD of the nodes inside it; pack only those spanning shards.
    let nodes: u64 = out
        .split(" HLOD nodes")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.replace(',', "").parse().ok())
        .unwrap_or(0);
    assert!(nodes > 0, "{out}");
    let first = read(d, "plan/cells/cells-000.bin");
    // Run again: nothing to do.
    assert!(run_ok(&["build-job", "plan", "cells-000"], d).contains("already done"));

    // A cells job killed half-way: its temporary output is there, no marker. Run again.
    std::fs::write(d.join("plan/cells/cells-001.bin.tmp"), b"half a shard").unwrap();
    run_ok(&["build-job", "plan", "cells-001"], d);
    assert!(!d.join("plan/cells/cells-001.bin.tmp").exists());
    // A job forced to run again writes the same bytes.
    std::fs::remove_file(d.join("plan/done/cells-000")).unwrap();
    run_ok(&["build-job", "plan", "cells-000"], d);
    assert!(read(d, "plan/cells/cells-000.bin") == first, "a rerun changed the shard");

    let out = run_ok(&["build-job", "plan", "pack"], d);
    assert!(out.contains("wrote") && out.contains("plan.tw"), "{out}");
    assert!(read(d, "plan.tw") == read(d, "plain.tw"), "the stores differ");
}

#[test]
fn damaged_hand_over_files_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    plant(d);
    run_ok(
        &[
            "build", "p.ply", "-o", "plan.tw", "--memory", "128M", "--plan", "plan", "--shards", "2",
            "--jobs", "local",
        ],
        d,
    );

    // A flipped byte in a shard: pack fails, naming the file and the cell.
    let bin = d.join("plan/cells/cells-000.bin");
    let mut bytes = std::fs::read(&bin).unwrap();
    let k = bytes.len() / 2;
    bytes[k] ^= 0x40;
    std::fs::write(&bin, bytes).unwrap();
    std::fs::remove_file(d.join("plan/done/pack")).unwrap();
    let o = terawalk(&["build-job", "plan", "pack"], d);
    assert!(!o.status.success(), "a damaged shard was packed");
    assert!(stderr(&o).contains("cells-000.bin") && stderr(&o).contains("checksum"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));

    // A truncated prepared state: the cells job fails, naming it; --jobs names the job.
    let state = d.join("plan/prepared/state.bin");
    let len = std::fs::metadata(&state).unwrap().len();
    std::fs::OpenOptions::new().write(true).open(&state).unwrap().set_len(len / 2).unwrap();
    std::fs::remove_file(d.join("plan/done/cells-001")).unwrap();
    let o = terawalk(&["build-job", "plan", "cells-001"], d);
    assert!(!o.status.success() && stderr(&o).contains("state.bin"), "{}", stderr(&o));

    // A plan of another version is refused.
    let plan = std::fs::read_to_string(d.join("plan/plan.json")).unwrap();
    std::fs::write(d.join("plan/plan.json"), plan.replace("\"version\": 1", "\"version\": 99")).unwrap();
    let o = terawalk(&["build-job", "plan", "pack"], d);
    assert!(!o.status.success() && stderr(&o).contains("version 99"), "{}", stderr(&o));
}

// Real kills: jobs killed with SIGKILL part-way through, then run again.

/// Runs `terawalk build-job plan JOB` in `dir` and kills it with SIGKILL as soon as `part_way`
/// says it is part-way through (its temporary output has grown). A job that finished first is
/// undone (its marker removed, then `undo`) and started again, up to 5 times. Returns the
/// attempts it took.
fn kill_part_way(dir: &Path, job: &str, undo: impl Fn(), part_way: impl Fn() -> bool) -> u32 {
    for attempt in 1..=5 {
        let mut child = Command::new(env!("CARGO_BIN_EXE_terawalk"))
            .args(["-q", "build-job", "plan", job])
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("starts");
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            if part_way() {
                child.kill().unwrap();
                break child.wait().unwrap();
            }
            std::thread::sleep(Duration::from_millis(1));
        };
        if status.signal() == Some(libc::SIGKILL) {
            return attempt;
        }
        assert!(status.success(), "{job} failed before it was killed: {status}");
        std::fs::remove_file(dir.join("plan/done").join(job)).unwrap();
        undo();
    }
    panic!("{job} finished each time before it could be killed");
}

/// The names in `dir` that start with `prefix`.
fn names_with_prefix(dir: &Path, prefix: &str) -> Vec<String> {
    let names =
        std::fs::read_dir(dir).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned());
    names.filter(|n| n.starts_with(prefix)).collect()
}

/// A file's size, 0 when it is missing.
fn size(path: &Path) -> u64 {
    std::fs::metadata(path).map_or(0, |m| m.len())
}

/// The prefix of a build's working directories (`tw_build::WorkDir`).
const WORK_DIR_PREFIX: &str = ".terawalk-build-";

/// `prepare` killed while its working directory fills: no marker, no `prepared/`, only the
/// stale working directory; run again, it removes that directory and prepares.
fn kill_prepare_and_run_it_again(d: &Path) {
    let plan = d.join("plan");
    let undo = || std::fs::remove_dir_all(plan.join("prepared")).unwrap();
    let attempts = kill_part_way(d, "prepare", undo, || {
        // A file besides its lock: phase 1 is writing.
        let working = |w: &String| std::fs::read_dir(plan.join(w)).into_iter().flatten().flatten();
        let lock = std::ffi::OsStr::new(tw_store::cleanup::DIR_LOCK);
        names_with_prefix(&plan, WORK_DIR_PREFIX).iter().any(|w| working(w).any(|e| e.file_name() != lock))
    });
    eprintln!("prepare killed part-way (attempt {attempts})");
    assert!(!plan.join("done/prepare").exists(), "a killed prepare left its marker");
    assert!(!plan.join("prepared").exists(), "a killed prepare left prepared/");
    let stale = names_with_prefix(&plan, WORK_DIR_PREFIX);
    assert_eq!(stale.len(), 1, "the killed prepare's working directory: {stale:?}");

    run_ok(&["build-job", "plan", "prepare"], d);
    assert!(plan.join("prepared/state.bin").exists());
    let left = names_with_prefix(&plan, WORK_DIR_PREFIX);
    assert!(left.is_empty(), "the stale working directory was not removed: {left:?}");
}

/// `cells-000` run once, then killed once it has written 4 MiB: no marker, none of its files
/// but the temporary one; run again, it writes the clean run's bytes.
fn kill_cells_and_run_it_again(d: &Path) {
    run_ok(&["build-job", "plan", "cells-000"], d);
    let (bin, idx) = (read(d, "plan/cells/cells-000.bin"), read(d, "plan/cells/cells-000.idx"));
    let outputs = ["plan/cells/cells-000.bin", "plan/cells/cells-000.idx"];
    let tmp = d.join("plan/cells/cells-000.bin.tmp");
    let undo = || outputs.iter().for_each(|name| std::fs::remove_file(d.join(name)).unwrap());
    std::fs::remove_file(d.join("plan/done/cells-000")).unwrap();
    undo();
    let attempts = kill_part_way(d, "cells-000", undo, || size(&tmp) >= 4 << 20);
    eprintln!("cells-000 killed part-way (attempt {attempts}) at {} bytes of {}", size(&tmp), bin.len());
    assert!(size(&tmp) < bin.len() as u64, "cells-000 was killed after it wrote its shard");
    assert!(!d.join("plan/done/cells-000").exists(), "a killed cells job left its marker");
    for name in outputs {
        assert!(!d.join(name).exists(), "a killed cells job left {name}");
    }

    run_ok(&["build-job", "plan", "cells-000"], d);
    assert!(read(d, "plan/cells/cells-000.bin") == bin, "the shard differs after a kill");
    assert!(read(d, "plan/cells/cells-000.idx") == idx, "the shard's index differs after a kill");
    assert!(!tmp.exists(), "the killed job's temporary shard is still there");
}

/// `pack` killed while it writes the store: the output path keeps what it held, the temporary
/// store stays beside it; run again, it writes the plain build's store and removes the
/// temporary one.
fn kill_pack_and_run_it_again(d: &Path) {
    let older = b"an older store, which a killed pack must leave alone";
    let undo = || std::fs::write(d.join("plan.tw"), older).unwrap();
    undo();
    let prefix = tw_store::temporary_prefix("plan.tw");
    let attempts =
        kill_part_way(d, "pack", undo, || names_with_prefix(d, &prefix).iter().any(|t| size(&d.join(t)) > 0));
    let tmp = names_with_prefix(d, &prefix);
    assert_eq!(tmp.len(), 1, "the killed pack's temporary store: {tmp:?}");
    let (written, whole) = (size(&d.join(&tmp[0])), size(&d.join("plain.tw")));
    eprintln!("pack killed part-way (attempt {attempts}) at {written} bytes of {whole}");
    assert!(written < whole, "pack was killed after it wrote the store");
    assert!(!d.join("plan/done/pack").exists(), "a killed pack left its marker");
    assert!(read(d, "plan.tw") == older, "a killed pack replaced the output");

    run_ok(&["build-job", "plan", "pack"], d);
    assert!(read(d, "plan.tw") == read(d, "plain.tw"), "the stores differ");
    let left = names_with_prefix(d, &prefix);
    assert!(left.is_empty(), "the killed pack's temporary store is still there: {left:?}");
}

/// A killed job run again gives the same outputs: `prepare`, a `cells` job and `pack`, each
/// killed with SIGKILL part-way through and run again, end in the plain build's store.
#[test]
fn jobs_killed_part_way_run_again_to_the_same_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gen = ["--generate", "plant:1M", "--memory", "128M"];
    run_ok(&[&["build", "-o", "plain.tw"][..], &gen].concat(), d);
    run_ok(&[&["build", "-o", "plan.tw", "--plan", "plan", "--shards", "2"][..], &gen].concat(), d);

    kill_prepare_and_run_it_again(d);
    run_ok(&["build-job", "plan", "cells-001"], d);
    kill_cells_and_run_it_again(d);
    kill_pack_and_run_it_again(d);
}

/// A failed job fails `--jobs local:2` with a message naming it and quoting its log; the jobs
/// after it do not run, and the plan finishes once the cause is gone.
#[test]
fn a_failed_job_fails_the_plan_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    plant(d);
    // cells-001 cannot write its shard: a directory where its temporary file goes.
    std::fs::create_dir_all(d.join("plan/cells/cells-001.bin.tmp")).unwrap();
    let build = ["build", "p.ply", "-o", "plan.tw", "--memory", "128M", "--plan", "plan", "--shards", "2"];
    let o = terawalk(&[&build[..], &["--jobs", "local:2"]].concat(), d);
    let err = stderr(&o);
    assert!(!o.status.success(), "the plan succeeded with a failing job");
    assert!(err.contains("job cells-001 failed"), "names the job: {err}");
    assert!(err.contains("logs/cells-001.log"), "names its log: {err}");
    assert!(err.contains("cells-001.bin.tmp"), "quotes the log's error: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(d.join("plan/done/cells-000").exists(), "the job beside it finishes");
    assert!(!d.join("plan/done/pack").exists() && !d.join("plan.tw").exists(), "pack ran");

    // The cause removed, the same command resumes: what finished stays finished.
    std::fs::remove_dir(d.join("plan/cells/cells-001.bin.tmp")).unwrap();
    let prepared = std::fs::metadata(d.join("plan/prepared/state.bin")).unwrap().modified().unwrap();
    let out = run_ok(&[&build[..], &["--jobs", "local:2"]].concat(), d);
    assert!(out.contains("the same build: 2 done, resuming"), "{out}");
    let again = std::fs::metadata(d.join("plan/prepared/state.bin")).unwrap().modified().unwrap();
    assert_eq!(prepared, again, "prepare ran again");
    assert!(read(d, "plan.tw") == read(d, "plain.tw"), "the stores differ");

    // A changed input is another build: every job runs again.
    run_ok(&["generate", "plant", "--triangles", "300k", "--seed", "2", "-o", "p.ply"], d);
    let out = run_ok(&[&build[..], &["--jobs", "local:2"]].concat(), d);
    assert!(!out.contains("resuming"), "{out}");
    assert!(read(d, "plan.tw") != read(d, "plain.tw"), "the old input's store");
}
