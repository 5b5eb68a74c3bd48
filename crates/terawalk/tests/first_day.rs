//! What a new user meets on the first day: a pipe into `head`, a mistyped path, a camera with
//! negative coordinates, the files the program writes, the figures it prints, `build` without
//! `-o`. Each test failed before the change it covers.

use std::path::Path;
use std::process::{Command, Output, Stdio};

mod common;

use common::{no_gpu, stderr, stdout, terawalk};

/// A folder with a small plant model `p.ply` and its store `p.tw`.
fn model_and_store() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["generate", "plant", "--triangles", "10k", "-o", "p.ply"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["build", "p.ply", "-o", "p.tw", "--memory", "256M"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    dir
}

/// Runs the program with its standard output a pipe whose reader has already gone: every write
/// to it fails with EPIPE.
fn with_closed_stdout(args: &[&str], dir: &Path) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(args)
        .current_dir(dir)
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap()
}

/// `terawalk info p.tw | head -1`: the reader going away is not a failure, so no panic (exit
/// 101) and no death by SIGPIPE either, but exit 0, as ripgrep does; the files are written.
#[test]
fn a_closed_pipe_is_a_clean_exit() {
    let dir = model_and_store();
    let d = dir.path();
    let commands: [&[&str]; 6] = [
        &["info", "p.tw"],
        &["stats", "p.ply"],
        &["generate", "plant", "--triangles", "10k", "-o", "g.ply"],
        &["build", "p.ply", "-o", "b.tw", "--memory", "256M"],
        &["path", "p.tw", "-o", "p.json", "--frames", "10"],
        &["preview", "p.ply", "-o", "p.png", "--size", "32x24"],
    ];
    for args in commands {
        let o = with_closed_stdout(args, d);
        assert!(!stderr(&o).contains("panicked"), "{args:?}: {}", stderr(&o));
        assert!(o.status.success(), "{args:?}: {:?} {}", o.status, stderr(&o));
    }
    for written in ["g.ply", "b.tw", "p.json", "p.png"] {
        assert!(d.join(written).is_file(), "{written} was not written");
    }
    // As `head -1` does: read one line, then close the pipe.
    let mut child = Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(["info", "p.tw"])
        .current_dir(d)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufRead::read_line(&mut std::io::BufReader::new(child.stdout.take().unwrap()), &mut first)
        .unwrap();
    assert_eq!(first.trim(), "p.tw");
    let o = child.wait_with_output().unwrap();
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    assert!(o.status.success(), "{:?}", o.status);
    // bench prints with println!: the panic it meets ends the program the same way.
    let o = with_closed_stdout(&["bench", "p.tw", "--path", "p.json", "--size", "32x24", "--warmup", "0"], d);
    if !no_gpu(&o) {
        assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
        assert!(o.status.success(), "{:?} {}", o.status, stderr(&o));
    }
}

/// "missing.obj: No such file or directory (os error 2): No such file or directory (os error
/// 2)" said the cause twice; a missing folder for an output said the output's path twice.
#[test]
fn a_missing_file_names_its_path_and_the_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: [(&[&str], &str); 6] = [
        (&["stats", "missing.obj"], "missing.obj"),
        (&["build", "missing.ply", "-o", "m.tw"], "missing.ply"),
        (&["preview", "missing.stl", "-o", "m.png"], "missing.stl"),
        (&["info", "missing.tw"], "missing.tw"),
        (&["path", "missing.tw", "-o", "m.json"], "missing.tw"),
        (&["generate", "plant", "--triangles", "10k", "-o", "no-folder/g.ply"], "no-folder/g.ply"),
    ];
    for (args, path) in cases {
        let o = terawalk(args, d);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {e}");
        assert_eq!(e.matches("os error 2").count(), 1, "{args:?}: {e}");
        assert_eq!(e.matches(path).count(), 1, "{args:?}: {e}");
    }
}

/// `--camera "-105,249,155;…"` was "unexpected argument '-1'" in render and view.
#[test]
fn a_camera_may_start_with_a_minus_in_render_and_view() {
    let dir = model_and_store();
    let d = dir.path();
    let camera = "-10,-20,30;40,40,0;0,0,1;60";
    // The argument is parsed (exit 2 is a usage error): the store is missing, not the camera.
    let o = terawalk(&["view", "missing.tw", "--camera", camera], d);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("missing.tw"), "{}", stderr(&o));
    let o = terawalk(&["render", "p.tw", "-o", "r.png", "--size", "32x24", "--camera", camera], d);
    if !no_gpu(&o) {
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(d.join("r.png").is_file());
    }
}

/// Atomic writers make a temporary file (mode 0600) and rename it: the report, the path, the
/// images and the store were readable by their owner only.
#[cfg(unix)]
#[test]
fn written_files_get_the_mode_of_a_new_file() {
    use std::os::unix::fs::PermissionsExt;
    let dir = model_and_store();
    let d = dir.path();
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    std::fs::File::create(d.join("plain")).unwrap();
    let expected = mode(&d.join("plain"));
    let o = terawalk(&["path", "p.tw", "-o", "p.json", "--frames", "10"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["preview", "p.ply", "-o", "p.png", "--size", "32x24"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut written = vec!["p.ply", "p.tw", "p.json", "p.png"];
    let o = terawalk(
        &["bench", "p.tw", "--path", "p.json", "--size", "32x24", "--warmup", "0", "--out", "rep"],
        d,
    );
    if !no_gpu(&o) {
        assert!(o.status.success(), "{}", stderr(&o));
        written.extend(["rep/index.html", "rep/report.json"]);
        let o = terawalk(&["render", "p.tw", "-o", "r.png", "--size", "32x24"], d);
        assert!(o.status.success(), "{}", stderr(&o));
        written.push("r.png");
    }
    for f in written {
        assert_eq!(mode(&d.join(f)), expected, "{f}: {:o}, a new file gets {expected:o}", mode(&d.join(f)));
    }
}

/// The significant digits of a printed number: "0.159" has 3, "12.4" 3, "512" 3.
fn significant_digits(number: &str) -> usize {
    number.trim_start_matches(['0', '.']).chars().filter(char::is_ascii_digit).count()
}

/// Rates printed with 4 decimals ("0.0123 M triangles/s" as "0.0123", "12.3456"), and one
/// byte budget in four units (GB, MB, GiB, MiB): rates now have 3 significant digits and
/// sizes binary units, as the size options take them.
#[test]
fn rates_have_three_digits_and_sizes_binary_units() {
    let dir = model_and_store();
    let d = dir.path();
    let o = terawalk(&["stats", "p.ply"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    let read = out.lines().find(|l| l.trim_start().starts_with("read ")).expect("a read line");
    // "  read 251 KiB in 0.06 s: 3.88 MiB/s, 0.159 M triangles/s"
    let rates = read.split_once(": ").unwrap().1;
    let (bytes, triangles) = rates.split_once(", ").unwrap();
    assert!(bytes.ends_with("iB/s"), "{read}");
    assert!(triangles.ends_with("triangles/s"), "{read}");
    for rate in [bytes, triangles] {
        let number = rate.split(' ').next().unwrap();
        assert!(significant_digits(number) <= 3, "{number} in {read}");
    }
    for unit in [" GB", " MB", " kB"] {
        assert!(!out.contains(unit), "{unit} in {out}");
    }
    let o = terawalk(&["build", "p.ply", "-o", "q.tw", "--memory", "256M"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("(budget 256 MiB)"), "{out}");
    let done = out.lines().find(|l| l.starts_with("done in")).expect("a done line");
    let rate = done.split(": ").nth(1).unwrap().split(' ').next().unwrap();
    assert!(significant_digits(rate) <= 3, "{rate} in {done}");
}

/// `build` needed `-o`: without it the store is the input's name with `.tw`, beside the input.
#[test]
fn build_without_an_output_writes_beside_the_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("models")).unwrap();
    let o = terawalk(&["generate", "plant", "--triangles", "10k", "-o", "models/m.ply.gz"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["build", "models/m.ply.gz", "--memory", "256M"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).starts_with("wrote models/m.tw "), "{}", stdout(&o));
    assert!(d.join("models/m.tw").is_file());
    let o = terawalk(&["info", "models/m.tw"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    // Several inputs make one store: its name is asked for.
    let o = terawalk(&["build", "models/m.ply.gz", "models/m.ply.gz"], d);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("-o"), "{}", stderr(&o));
    let help = stdout(&terawalk(&["build", "--help"], d));
    assert!(help.contains("terawalk build plant.ply  "), "{help}");
}
