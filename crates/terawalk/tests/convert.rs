//! `terawalk build` of formats it converts with external tools (`tw_io::convert`): FBX and
//! COLLADA through assimp, IFC through IfcOpenShell, STEP through Open CASCADE (OCP). A tool
//! that is not installed skips its test with a note, unless `TERAWALK_REQUIRE_CONVERTERS=1`
//! (CI, which installs them). The failure paths (a missing tool, a failing or hanging one, a
//! signal during the conversion) use stand-in tools and always run.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;

use common::{stderr, stdout};

/// The fixture `name` of tests/fixtures/convert.
fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/convert").join(name)
}

/// A fresh folder holding a copy of the fixture `name`.
fn folder_with(name: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(fixture(name), dir.path().join(name)).unwrap();
    dir
}

/// The program with `args` in `dir` and the environment changes `env`.
fn terawalk_env(args: &[&str], dir: &Path, env: &[(&str, &std::ffi::OsStr)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_terawalk"));
    c.args(args).current_dir(dir);
    for (k, v) in env {
        // An empty value removes the variable (a tool named by it is then looked up on `PATH`).
        if v.is_empty() {
            c.env_remove(k);
        } else {
            c.env(k, v);
        }
    }
    c.output().expect("runs")
}

/// Whether `check` (a shell command) succeeds; else the test is skipped with `install` named,
/// or fails when the converters are required.
fn have(check: &str, install: &str) -> bool {
    let ok = Command::new("sh").args(["-c", check]).stdout(Stdio::null()).stderr(Stdio::null()).status();
    if ok.is_ok_and(|s| s.success()) {
        return true;
    }
    assert_ne!(
        std::env::var("TERAWALK_REQUIRE_CONVERTERS").as_deref(),
        Ok("1"),
        "`{check}` failed: install with `{install}`"
    );
    eprintln!("SKIPPED: `{check}` failed (install with `{install}`)");
    false
}

/// The names of the files in `dir`, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The store's object names.
fn object_names(store: &Path) -> Vec<String> {
    let s = tw_store::Store::open(store).unwrap();
    s.objects().iter().map(|o| o.name.clone()).collect()
}

/// Checks a successful build of `input` in `dir`: the report names the tool, the store exists
/// and no working files are left.
fn assert_built(o: &Output, dir: &Path, input: &str, tool: &str) -> PathBuf {
    assert!(o.status.success(), "{}{}", stdout(o), stderr(o));
    let out = stdout(o);
    assert!(out.contains(&format!("with {tool} in ")) && out.contains(input), "{out}");
    let store = dir.join(format!("{}.tw", input.rsplit_once('.').unwrap().0));
    assert_eq!(listing(dir), vec![input.to_string(), store.file_name().unwrap().to_string_lossy().into()]);
    store
}

#[test]
fn an_fbx_builds_through_assimp_with_its_node_names() {
    if !have("assimp version", "apt install assimp-utils") {
        return;
    }
    let dir = folder_with("cubes_with_names.fbx");
    let o = common::terawalk(&["build", "cubes_with_names.fbx"], dir.path());
    let store = assert_built(&o, dir.path(), "cubes_with_names.fbx", "assimp");
    let out = stdout(&o);
    assert!(out.contains("assimp export") && out.contains("-fglb2"), "the command is reported: {out}");
    let names = object_names(&store);
    assert!(names.iter().any(|n| n.contains("Cube")), "{names:?}");
}

#[test]
fn a_collada_file_builds_through_assimp() {
    if !have("assimp version", "apt install assimp-utils") {
        return;
    }
    let dir = folder_with("cube.dae");
    let o = common::terawalk(&["build", "cube.dae"], dir.path());
    let store = assert_built(&o, dir.path(), "cube.dae", "assimp");
    let s = tw_store::Store::open(&store).unwrap();
    assert_eq!(s.header().input_triangles, 12);
    assert_eq!(s.header().up_axis, 1, "assimp writes glTF, which is y-up");
}

#[test]
fn an_ifc_builds_with_its_global_ids_as_object_names() {
    if !have("${TERAWALK_PYTHON:-python3} -c 'import ifcopenshell.geom'", "pip install ifcopenshell") {
        return;
    }
    let dir = folder_with("two_walls.ifc");
    let o = common::terawalk(&["build", "two_walls.ifc"], dir.path());
    let store = assert_built(&o, dir.path(), "two_walls.ifc", "IfcOpenShell");
    assert!(stdout(&o).contains("3 products"), "{}", stdout(&o));
    let mut names = object_names(&store);
    names.sort();
    assert_eq!(
        names,
        [
            "East wall [0WallEast00000000000002]",
            "Floor slab [0SlabFloor0000000000003]",
            "North wall [0WallNorth0000000000001]"
        ]
    );
    let s = tw_store::Store::open(&store).unwrap();
    assert_eq!(s.units(), "m", "IfcOpenShell writes metres");
    // The model is 5.2 m × 4 m × 3 m, z up (IFC's convention, kept by the OBJ default).
    let h = s.header();
    let extent: Vec<f64> = (0..3).map(|i| h.bounds_max[i] - h.bounds_min[i]).collect();
    assert!((extent[0] - 5.2).abs() < 1e-3 && (extent[1] - 4.0).abs() < 1e-3, "{extent:?}");
    assert!((extent[2] - 3.0).abs() < 1e-3 && h.up_axis == 2, "{extent:?}");
}

#[test]
fn a_step_assembly_builds_with_its_part_names() {
    if !have("${TERAWALK_PYTHON:-python3} -c 'import OCP.STEPCAFControl'", "pip install cadquery-ocp") {
        return;
    }
    let dir = folder_with("two_parts.step");
    let o = common::terawalk(&["build", "two_parts.step"], dir.path());
    let store = assert_built(&o, dir.path(), "two_parts.step", "Open CASCADE (OCP)");
    let mut names = object_names(&store);
    names.sort();
    assert_eq!(names, ["bracket/pin", "bracket/plate"]);
    let s = tw_store::Store::open(&store).unwrap();
    assert_eq!(s.units(), "mm");
    // The pin (25 mm tall) stands 30 mm above the plate's base: placed by its assembly location.
    assert!((s.header().bounds_max[2] - 55.0).abs() < 1e-3, "{:?}", s.header().bounds_max);
}

/// A folder holding only a `sh` (the stand-in tools are shell scripts), for a `PATH` without
/// assimp and python3.
fn bare_path() -> tempfile::TempDir {
    let bin = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink("/bin/sh", bin.path().join("sh")).unwrap();
    bin
}

#[test]
fn a_missing_tool_names_the_install_command_and_leaves_nothing() {
    let bin = bare_path();
    for (input, hint) in [
        ("cube.dae", "apt install assimp-utils"),
        ("two_walls.ifc", "pip install ifcopenshell"),
        ("two_parts.step", "pip install cadquery-ocp"),
    ] {
        let dir = folder_with(input);
        let none = std::ffi::OsStr::new("");
        let env = [("PATH", bin.path().as_os_str()), ("TERAWALK_PYTHON", none), ("TERAWALK_ASSIMP", none)];
        let o = terawalk_env(&["build", input], dir.path(), &env);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(err.contains(input) && err.contains(&format!("install it with `{hint}`")), "{err}");
        assert_eq!(listing(dir.path()), [input], "no store and no working directory left");
    }
}

/// An executable shell script `name` in `dir`.
fn fake_tool(dir: &Path, name: &str, body: &str) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let p = dir.join(name);
    std::fs::write(&p, format!("#!/bin/sh\n{body}\n")).unwrap();
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
    p
}

#[test]
fn a_failing_tool_reports_its_stderr_and_leaves_nothing() {
    let dir = folder_with("cube.dae");
    let bin = tempfile::tempdir().unwrap();
    let tool = fake_tool(bin.path(), "assimp", "echo 'ERROR: this is not COLLADA at line 3' >&2; exit 2");
    let o = terawalk_env(&["build", "cube.dae"], dir.path(), &[("TERAWALK_ASSIMP", tool.as_os_str())]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("cube.dae") && err.contains("exit status: 2"), "{err}");
    assert!(err.contains("ERROR: this is not COLLADA at line 3"), "{err}");
    assert_eq!(listing(dir.path()), ["cube.dae"]);
}

#[test]
fn a_hanging_tool_is_stopped_at_the_time_limit() {
    let dir = folder_with("cube.dae");
    let bin = tempfile::tempdir().unwrap();
    let tool = fake_tool(bin.path(), "assimp", "echo 'reading...' >&2; exec sleep 60");
    let start = Instant::now();
    let o = terawalk_env(
        &["build", "cube.dae"],
        dir.path(),
        &[("TERAWALK_ASSIMP", tool.as_os_str()), ("TERAWALK_CONVERT_TIMEOUT", "0.5".as_ref())],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(start.elapsed() < Duration::from_secs(30), "not waited out");
    assert!(err.contains("time limit") && err.contains("reading..."), "{err}");
    assert_eq!(listing(dir.path()), ["cube.dae"]);
}

/// SIGTERM while the tool runs: terawalk removes its working directory and the tool dies with
/// it (it would otherwise run on, writing into a folder that is gone).
#[test]
fn a_signal_during_the_conversion_ends_the_tool_and_leaves_nothing() {
    let dir = folder_with("cube.dae");
    let bin = tempfile::tempdir().unwrap();
    let pid_file = bin.path().join("tool.pid");
    let tool = fake_tool(bin.path(), "assimp", &format!("echo $$ > '{}'; exec sleep 60", pid_file.display()));
    let mut child = Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(["build", "cube.dae"])
        .current_dir(dir.path())
        .env("TERAWALK_ASSIMP", &tool)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    while std::fs::read_to_string(&pid_file).map_or(true, |s| !s.ends_with('\n')) {
        assert!(Instant::now() < deadline, "the tool never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    let tool_pid: i32 = std::fs::read_to_string(&pid_file).unwrap().trim().parse().unwrap();
    assert!(listing(dir.path()).iter().any(|n| n.starts_with(".terawalk-build-")));
    Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    let status = child.wait().unwrap();
    assert!(!status.success());
    assert_eq!(listing(dir.path()), ["cube.dae"]);
    let deadline = Instant::now() + Duration::from_secs(10);
    while Command::new("kill")
        .args(["-0", &tool_pid.to_string()])
        .stderr(Stdio::null())
        .status()
        .unwrap()
        .success()
    {
        assert!(Instant::now() < deadline, "the tool (pid {tool_pid}) outlived terawalk");
        std::thread::sleep(Duration::from_millis(20));
    }
}
