//! `terawalk build --plan DIR` and `build-job`: the build as a plan of jobs gives the plain
//! build's store byte for byte, with any number of local workers; a job run twice is a no-op;
//! a killed job run again gives the same outputs; a job whose predecessors have not finished,
//! an unknown job and damaged hand-over files are refused with messages naming them.

mod common;

use std::path::Path;

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
