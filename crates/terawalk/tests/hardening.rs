//! Hostile and careless use of the program: outputs that are inputs, damaged stores, absurd
//! numbers, killed builds, closed pipes. Each test failed before the fix it covers.

use std::path::Path;
use std::process::{Command, Stdio};

mod common;

use common::{no_gpu, stderr, stdout, terawalk};

/// A small plant model and its store in a new folder.
fn plant_and_store() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["generate", "plant", "--triangles", "20k", "-o", "p.ply"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["build", "p.ply", "-o", "p.tw", "--memory", "256M"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    dir
}

#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let dir = plant_and_store();
    let d = dir.path();
    let model = std::fs::read(d.join("p.ply")).unwrap();
    let store = std::fs::read(d.join("p.tw")).unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(d.join("p.ply"), d.join("link.ply")).unwrap();
    std::fs::hard_link(d.join("p.tw"), d.join("hard.tw")).unwrap();
    let mut cases: Vec<Vec<&str>> = vec![
        vec!["build", "p.ply", "-o", "p.ply"],
        vec!["build", "p.ply", "-o", "./p.ply"],
        vec!["preview", "p.ply", "-o", "p.ply"],
        vec!["render", "p.tw", "-o", "p.tw"],
        vec!["render", "p.tw", "-o", "hard.tw"],
        vec!["path", "p.tw", "-o", "p.tw"],
    ];
    #[cfg(unix)]
    cases.push(vec!["build", "p.ply", "-o", "link.ply"]);
    for args in &cases {
        let o = terawalk(args, d);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains("destroy the input"), "{args:?}: {}", stderr(&o));
    }
    assert_eq!(std::fs::read(d.join("p.ply")).unwrap(), model, "the model was changed");
    assert_eq!(std::fs::read(d.join("p.tw")).unwrap(), store, "the store was changed");
    // Not a regular file: a directory, a device.
    std::fs::create_dir(d.join("folder.tw")).unwrap();
    let o = terawalk(&["build", "p.ply", "-o", "folder.tw"], d);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("is a directory, not a regular file"), "{}", stderr(&o));
    #[cfg(unix)]
    {
        let o = terawalk(&["preview", "p.ply", "-o", "/dev/null"], d);
        assert_eq!(o.status.code(), Some(1));
        assert!(stderr(&o).contains("character device"), "{}", stderr(&o));
    }
}

#[test]
fn thread_counts_are_checked_and_capped() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = terawalk(&["generate", "plant", "--triangles", "10k", "-o", "p.obj"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    for bad in ["0", "-3", "many", "1000000"] {
        let o = terawalk(&["build", "p.obj", "-o", "x.tw", "--threads", bad], d);
        assert_eq!(o.status.code(), Some(2), "--threads {bad}: {}", stderr(&o));
    }
    // Far more than the cores: capped with a warning, and quick (10,000 threads took minutes).
    let start = std::time::Instant::now();
    let o = terawalk(&["build", "p.obj", "-o", "x.tw", "--threads", "10000"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("more than 4 per core"), "{}", stderr(&o));
    assert!(start.elapsed().as_secs() < 60, "{:?}", start.elapsed());
}

/// The byte offset of the middle of a root page of `store`.
fn root_page_middle(store: &Path) -> usize {
    let s = tw_store::Store::open(store).unwrap();
    let page = s.pages().iter().find(|p| p.is_root()).expect("a root page");
    page.offset as usize + page.compressed_len as usize / 2
}

#[test]
fn a_damaged_store_fails_render_and_bench_unless_allowed() {
    let dir = plant_and_store();
    let d = dir.path();
    let mut bytes = std::fs::read(d.join("p.tw")).unwrap();
    bytes[root_page_middle(&d.join("p.tw"))] ^= 0x10;
    std::fs::write(d.join("bad.tw"), &bytes).unwrap();

    let o = terawalk(&["render", "bad.tw", "-o", "bad.png", "--size", "160x100"], d);
    if no_gpu(&o) {
        return;
    }
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stdout(&o).contains("damaged store: 1 page(s)"), "{}", stdout(&o));
    assert!(stderr(&o).contains("--allow-damaged") && stderr(&o).contains("bad.tw"), "{}", stderr(&o));
    let o = terawalk(&["render", "bad.tw", "-o", "bad.png", "--size", "160x100", "--allow-damaged"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("damaged store"), "{}", stdout(&o));
    // A sound store says nothing of damage.
    let o = terawalk(&["render", "p.tw", "-o", "good.png", "--size", "160x100"], d);
    assert!(o.status.success() && !stdout(&o).contains("damaged"), "{}", stdout(&o));

    let path = d.join("path.json");
    let o = terawalk(&["path", "p.tw", "-o", path.to_str().unwrap(), "--frames", "4"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let bench =
        ["bench", "bad.tw", "--path", "path.json", "--out", "rep", "--size", "160x100", "--warmup", "0"];
    let o = terawalk(&bench, d);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let json = std::fs::read_to_string(d.join("rep/report.json")).unwrap();
    let report = tw_report::BenchReport::from_json(&json).unwrap();
    assert_eq!(report.damaged_pages.len(), 1, "{json}");
    assert!(std::fs::read_to_string(d.join("rep/index.html")).unwrap().contains("Damaged store"));
    let mut allowed = bench.to_vec();
    allowed.push("--allow-damaged");
    let o = terawalk(&allowed, d);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// SIGKILL runs no handler: the killed build's working directory and temporary store stay, and
/// the next build into the same folder removes them (and says so).
#[cfg(unix)]
#[test]
fn a_killed_builds_leftovers_are_removed_by_the_next_build() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = terawalk(&["generate", "plant", "--triangles", "300k", "-o", "in.ply"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let names = || -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n != "in.ply")
            .collect();
        v.sort();
        v
    };
    let mut child = Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(["-q", "build", "in.ply", "-o", "out.tw"])
        .current_dir(d)
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while names().len() < 2 && child.try_wait().unwrap().is_none() {
        assert!(start.elapsed().as_secs() < 120, "the build made no temporary files");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert!(child.try_wait().unwrap().is_none(), "the build ended before the kill; use a bigger input");
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let left = names();
    assert!(left.iter().any(|n| n.starts_with(".terawalk-build-")), "{left:?}");
    assert!(left.iter().any(|n| n.starts_with(".out.tw.tmp")), "{left:?}");

    let o = terawalk(&["build", "in.ply", "-o", "out.tw"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("left behind by an earlier build that was killed"), "{}", stderr(&o));
    assert_eq!(names(), vec!["out.tw".to_string()]);
}

#[test]
fn a_temp_space_cap_stops_the_build_with_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = terawalk(&["generate", "plant", "--triangles", "50k", "-o", "p.ply"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["build", "p.ply", "-o", "p.tw", "--temp-space", "100K"], d);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("--temp-space"), "{}", stderr(&o));
    let left: Vec<_> = std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, vec![std::ffi::OsString::from("p.ply")], "nothing left behind");
}

#[test]
fn an_error_says_its_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["stats", "missing.obj"], dir.path());
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    let cause = "No such file or directory";
    assert_eq!(e.matches(cause).count(), 1, "{e}");
}

/// `terawalk stats m.obj | head -1` where the reader has gone: no panic (exit 101) on EPIPE.
#[cfg(unix)]
#[test]
fn a_closed_pipe_ends_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["generate", "plant", "--triangles", "10k", "-o", "p.obj"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader); // every write to the pipe fails
    let o = Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(["stats", "p.obj"])
        .current_dir(dir.path())
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    assert!(o.status.success(), "a reader gone is a clean exit, as in ripgrep: {:?}", o.status);
}

/// Site coordinates are negative somewhere: `--camera "-105,249,155;…"` is a camera, not an
/// unknown option.
#[test]
fn a_camera_may_start_with_a_minus() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = terawalk(&["generate", "plant", "--triangles", "10k", "-o", "p.obj"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(
        &["preview", "p.obj", "-o", "p.png", "--size", "64x48", "--camera", "-105,-249,155;0,0,0;0,0,1;60"],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("p.png").exists());
}

/// `terawalk info model.glb` said only "not a terawalk store": now it says how to make one.
/// (`render` and `view` open a model themselves, through the build cache: tests/open_any.rs.)
#[test]
fn a_model_given_as_a_store_gets_the_build_command() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = terawalk(&["generate", "plant", "--triangles", "10k", "-o", "m.ply.gz"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    for cmd in ["info", "path", "bench"] {
        let mut args = vec![cmd, "m.ply.gz"];
        if cmd == "path" {
            args.extend(["-o", "out.x"]);
        }
        let o = terawalk(&args, d);
        assert_eq!(o.status.code(), Some(1), "{cmd}: {}", stderr(&o));
        assert!(stderr(&o).contains("terawalk build m.ply.gz -o m.tw"), "{cmd}: {}", stderr(&o));
    }
}
