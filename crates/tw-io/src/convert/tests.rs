use std::os::unix::fs::PermissionsExt;

use super::*;

/// An executable shell script `name` in `dir` with `body`.
fn fake_tool(dir: &Path, name: &str, body: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, format!("#!/bin/sh\n{body}\n")).unwrap();
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
    p
}

/// A model file `name` with `bytes`, and an empty directory to convert it into.
fn model(name: &str, bytes: &[u8]) -> (tempfile::TempDir, PathBuf, PathBuf) {
    let d = tempfile::tempdir().unwrap();
    let input = d.path().join(name);
    std::fs::write(&input, bytes).unwrap();
    let out = d.path().join("work");
    std::fs::create_dir(&out).unwrap();
    (d, input, out)
}

#[test]
fn converters_by_name_and_magic() {
    let d = tempfile::tempdir().unwrap();
    let by = |name: &str, bytes: &[u8]| {
        let p = d.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        Converter::for_path(&p)
    };
    assert_eq!(by("a.IFC", b""), Some((Converter::IfcOpenShell, "IFC")));
    assert_eq!(by("a.stp", b""), Some((Converter::OpenCascade, "STEP")));
    assert_eq!(by("a.igs", b""), Some((Converter::OpenCascade, "IGES")));
    assert_eq!(by("a.Fbx", b""), Some((Converter::Assimp, "FBX")));
    assert_eq!(by("a.dae", b""), Some((Converter::Assimp, "COLLADA")));
    assert_eq!(by("a.lwo", b""), Some((Converter::Assimp, "assimp-readable")));
    // Formats terawalk reads, gzip and unknown content: no converter.
    assert_eq!(by("a.obj", b"v 1 2 3\n"), None);
    assert_eq!(by("a.fbx.gz", b"\x1f\x8b"), None);
    assert_eq!(by("noext", b"v 1 2 3\n"), None);
    // Magic, when the name says nothing.
    let p21 = b"ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION((''),'2;1');\n";
    assert_eq!(
        by("m1", &[&p21[..], b"FILE_SCHEMA(('IFC4'));\n"].concat()),
        Some((Converter::IfcOpenShell, "IFC"))
    );
    let step = [&p21[..], b"FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));\n"].concat();
    assert_eq!(by("m2.dat", &step), Some((Converter::OpenCascade, "STEP")));
    assert_eq!(by("m3", b"Kaydara FBX Binary  \0\x1a\0"), Some((Converter::Assimp, "FBX")));
}

#[test]
fn a_missing_program_names_the_install_command() {
    let (_d, input, work) = model("m.fbx", b"Kaydara FBX Binary  \0");
    let options = ConvertOptions { assimp: "/nonexistent/assimp".into(), ..Default::default() };
    let e = convert(&input, Converter::Assimp, &work, &options).unwrap_err();
    assert!(matches!(e, ConvertError::MissingTool { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.starts_with(&input.display().to_string()), "{msg}");
    assert!(msg.contains("apt install assimp-utils"), "{msg}");
    assert!(msg.contains("FBX"), "{msg}");
}

#[test]
fn a_missing_python_module_names_the_pip_command() {
    let (d, input, work) = model("m.ifc", b"ISO-10303-21;\n");
    let python = fake_tool(d.path(), "python3", "echo 'No module named ifcopenshell' >&2; exit 3");
    let options = ConvertOptions { python, ..Default::default() };
    let e = convert(&input, Converter::IfcOpenShell, &work, &options).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("pip install ifcopenshell") && msg.contains("No module named"), "{msg}");
    let e = convert(&input, Converter::OpenCascade, &work, &options).unwrap_err();
    assert!(e.to_string().contains("pip install cadquery-ocp"), "{e}");
}

#[test]
fn a_failing_tool_reports_its_stderr_tail_and_status() {
    let (d, input, work) = model("m.dae", b"<COLLADA/>");
    let body =
        "for i in $(seq 1 40); do echo \"warning $i\" >&2; done\necho 'ERROR: bad COLLADA' >&2\nexit 1";
    let assimp = fake_tool(d.path(), "assimp", body);
    let options = ConvertOptions { assimp, ..Default::default() };
    let e = convert(&input, Converter::Assimp, &work, &options).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, ConvertError::Failed { .. }), "{e:?}");
    assert!(msg.contains("exit status: 1") && msg.ends_with("ERROR: bad COLLADA"), "{msg}");
    assert!(msg.contains("warning 40") && !msg.contains("warning 1\n"), "only the tail: {msg}");
    assert!(msg.contains(&format!("{} export", d.path().join("assimp").display())), "{msg}");
}

#[test]
fn a_tool_that_writes_nothing_or_hangs_is_an_error() {
    let (d, input, work) = model("m.3ds", b"MM");
    let options = ConvertOptions { assimp: fake_tool(d.path(), "assimp", "exit 0"), ..Default::default() };
    let e = convert(&input, Converter::Assimp, &work, &options).unwrap_err();
    assert!(matches!(e, ConvertError::NoOutput { .. }), "{e:?}");
    let options = ConvertOptions {
        assimp: fake_tool(d.path(), "assimp", "echo working >&2; exec sleep 30"),
        timeout: Duration::from_millis(300),
        ..Default::default()
    };
    let e = convert(&input, Converter::Assimp, &work, &options).unwrap_err();
    assert!(matches!(e, ConvertError::TimedOut { .. }), "{e:?}");
    assert!(e.to_string().contains("time limit") && e.to_string().contains("working"), "{e}");
}

#[test]
fn the_tool_gets_absolute_paths_and_the_output_is_reported() {
    let (d, input, _) = model("part v2.off", b"OFF\n");
    // A working directory given relative to the current one, as `--work-dir .` gives it.
    let here = tempfile::Builder::new().prefix(".convert-test-").tempdir_in(".").unwrap();
    let relative_work = Path::new(".").join(here.path().file_name().unwrap());
    // Copies the input to the output: the arguments are `export INPUT OUTPUT -fglb2`.
    let assimp = fake_tool(d.path(), "assimp", "cp \"$2\" \"$3\" && echo 'wrote output file'");
    let options = ConvertOptions { assimp, ..Default::default() };
    let c = convert(&input, Converter::Assimp, &relative_work, &options).unwrap();
    assert_eq!(c.output, std::fs::canonicalize(here.path()).unwrap().join("part v2.glb"));
    assert_eq!(std::fs::read(&c.output).unwrap(), b"OFF\n");
    assert_eq!(c.summary, "", "assimp's own line is not repeated");
    assert!(c.command.contains("'") && c.command.ends_with("-fglb2"), "{}", c.command);
}

/// The real assimp, where installed: a COLLADA cube becomes a GLB the glTF importer reads.
#[test]
fn assimp_converts_collada_to_glb_when_installed() {
    if run::find_program(Path::new("assimp")).is_none() {
        eprintln!("SKIPPED: assimp is not installed (apt install assimp-utils)");
        return;
    }
    let dae = include_bytes!("../../../terawalk/tests/fixtures/convert/cube.dae");
    let (_d, input, work) = model("cube.dae", dae);
    let c = convert(&input, Converter::Assimp, &work, &ConvertOptions::default()).unwrap();
    let source = crate::open_source(&c.output, &Default::default()).unwrap();
    let mut stats = crate::SceneStats::default();
    let summary = source.stream(&mut stats).unwrap();
    assert!(summary.objects >= 1);
    assert_eq!(stats.triangles, 12);
}

#[test]
fn a_tool_given_by_a_relative_path_runs_from_another_directory() {
    let (_d, input, work) = model("m.x3d", b"<X3D/>");
    // `TERAWALK_ASSIMP=./tools/assimp`: relative to the current directory, not to `work`.
    let here = tempfile::Builder::new().prefix(".convert-test-").tempdir_in(".").unwrap();
    fake_tool(here.path(), "assimp", "cp \"$2\" \"$3\"");
    let relative = Path::new(".").join(here.path().file_name().unwrap()).join("assimp");
    let options = ConvertOptions { assimp: relative, ..Default::default() };
    let c = convert(&input, Converter::Assimp, &work, &options).unwrap();
    assert_eq!(std::fs::read(&c.output).unwrap(), b"<X3D/>");
}
