//! Converting the formats terawalk does not read itself by running the tools that do.
//!
//! Building information models (IFC), mechanical CAD exchange files (STEP, IGES) and the
//! interchange formats of modelling tools (FBX, COLLADA, 3DS, ...) need a geometry kernel or a
//! format zoo to tessellate; terawalk leaves that to established tools and imports what they
//! write:
//!
//! | formats | tool | writes | install |
//! | --- | --- | --- | --- |
//! | FBX, DAE, 3DS, AC, LWO, X3D, ... ([`ASSIMP_EXTENSIONS`]) | `assimp export` | GLB | `apt install assimp-utils` |
//! | IFC | IfcOpenShell, `ifc_to_obj.py` | OBJ + MTL | `pip install ifcopenshell` |
//! | STEP, IGES | Open CASCADE through OCP, `step_to_obj.py` | OBJ + MTL | `pip install cadquery-ocp` |
//!
//! The two Python scripts are compiled into terawalk and written next to their output when
//! used. They keep what a viewer's pick should tell: IFC products become objects named
//! `Name [GlobalId]`, STEP solids objects named by their assembly path. Coordinates stay in
//! the units the tool writes (IFC: metres, STEP/IGES: millimetres; [`Converted::units`]).
//!
//! Steps of [`convert`]: find the program (a missing one is a [`ConvertError::MissingTool`]
//! naming the install command), run it into the given directory with a time limit
//! (`convert::run`), and check that it wrote a file; a failure reports the tail of the tool's
//! standard error.

mod run;

pub use run::{find_program, find_program_in};

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// Extensions that `assimp export` reads and terawalk does not: its importers' list (assimp
/// 5.2, `assimp listext`) less what terawalk reads natively (OBJ, PLY, STL, glTF) and IFC
/// (IfcOpenShell keeps the products' identities, assimp does not).
pub const ASSIMP_EXTENSIONS: &[&str] = &[
    "3d", "3ds", "3mf", "ac", "ac3d", "acc", "amf", "ase", "ask", "b3d", "blend", "bvh", "cob", "csm", "dae",
    "dxf", "enff", "fbx", "hmp", "irr", "irrmesh", "lwo", "lws", "lxo", "m3d", "md2", "md3", "md5mesh",
    "mdc", "mdl", "mesh", "mot", "ms3d", "ndo", "nff", "off", "ogex", "pk3", "pmx", "prj", "q3o", "q3s",
    "raw", "scn", "sib", "smd", "ter", "uc", "vta", "x", "x3d", "x3db", "xgl", "zae", "zgl",
];

/// The tool a format needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Converter {
    /// The Open Asset Import Library's command line tool.
    Assimp,
    /// IfcOpenShell's Python module, through `ifc_to_obj.py`.
    IfcOpenShell,
    /// Open CASCADE's Python binding OCP, through `step_to_obj.py`.
    OpenCascade,
}

/// The script that converts IFC (see its docstring).
const IFC_SCRIPT: &str = include_str!("ifc_to_obj.py");
/// The script that converts STEP and IGES (see its docstring).
const STEP_SCRIPT: &str = include_str!("step_to_obj.py");
/// The exit status the scripts give when their Python module is missing.
const MISSING_MODULE: i32 = 3;
/// Lines of a failed tool's standard error quoted in the error.
const STDERR_LINES: usize = 12;

impl Converter {
    /// The converter for `path` and the name of its format: by the file name, else (a name
    /// that says nothing) by the content's magic. `None` for the formats terawalk reads itself
    /// and for unknown ones.
    pub fn for_path(path: &Path) -> Option<(Converter, &'static str)> {
        Converter::for_name(path).or_else(|| Converter::for_magic(path))
    }

    /// The converter a file name asks for ("x.FBX" asks for assimp). The tools read no gzip:
    /// "x.fbx.gz" asks for none (and the importers then say they do not know the format).
    pub fn for_name(path: &Path) -> Option<(Converter, &'static str)> {
        let name = path.file_name()?.to_string_lossy().to_lowercase();
        let ext = name.rsplit_once('.').map(|(_, e)| e)?;
        Some(match ext {
            "ifc" => (Converter::IfcOpenShell, "IFC"),
            "step" | "stp" | "p21" => (Converter::OpenCascade, "STEP"),
            "iges" | "igs" => (Converter::OpenCascade, "IGES"),
            "fbx" => (Converter::Assimp, "FBX"),
            "dae" | "zae" => (Converter::Assimp, "COLLADA"),
            "3ds" => (Converter::Assimp, "3DS"),
            e if ASSIMP_EXTENSIONS.contains(&e) => (Converter::Assimp, "assimp-readable"),
            _ => return None,
        })
    }

    /// The converter the first bytes of `path` ask for: ISO 10303-21 text (IFC when its schema
    /// says so, STEP otherwise) or binary FBX. Files without such a magic need their extension.
    fn for_magic(path: &Path) -> Option<(Converter, &'static str)> {
        use std::io::Read;
        let mut head = Vec::with_capacity(4096);
        std::fs::File::open(path).ok()?.take(4096).read_to_end(&mut head).ok()?;
        if head.starts_with(b"Kaydara FBX Binary") {
            return Some((Converter::Assimp, "FBX"));
        }
        let text = String::from_utf8_lossy(&head);
        if !text.trim_start().starts_with("ISO-10303-21;") {
            return None;
        }
        let schema = text.split_once("FILE_SCHEMA").map(|(_, s)| s.to_ascii_uppercase()).unwrap_or_default();
        Some(if schema.trim_start_matches(|c: char| !c.is_ascii_alphanumeric()).starts_with("IFC") {
            (Converter::IfcOpenShell, "IFC")
        } else {
            (Converter::OpenCascade, "STEP")
        })
    }

    /// The tool's name, for messages.
    pub fn tool(self) -> &'static str {
        match self {
            Converter::Assimp => "assimp",
            Converter::IfcOpenShell => "IfcOpenShell",
            Converter::OpenCascade => "Open CASCADE (OCP)",
        }
    }

    /// The command that installs the tool.
    pub fn install_hint(self) -> &'static str {
        match self {
            Converter::Assimp => "apt install assimp-utils",
            Converter::IfcOpenShell => "pip install ifcopenshell",
            Converter::OpenCascade => "pip install cadquery-ocp",
        }
    }

    /// The units of the coordinates the tool writes, when fixed.
    pub fn units(self) -> Option<&'static str> {
        match self {
            Converter::Assimp => None,
            Converter::IfcOpenShell => Some("m"),
            Converter::OpenCascade => Some("mm"),
        }
    }

    fn output_extension(self) -> &'static str {
        match self {
            Converter::Assimp => "glb",
            Converter::IfcOpenShell | Converter::OpenCascade => "obj",
        }
    }
}

/// Where the tools are and how long they may run.
#[derive(Clone, Debug)]
pub struct ConvertOptions {
    /// The assimp program (a bare name is looked up in `PATH`).
    pub assimp: PathBuf,
    /// The Python interpreter that runs the IFC and STEP scripts (one whose environment has
    /// the modules: a virtual environment's `bin/python` works).
    pub python: PathBuf,
    /// The longest a conversion may run before it is stopped.
    pub timeout: Duration,
}

/// The default time limit: hours of tessellation are plausible for a large plant model, a
/// tool that runs longer has most likely hung.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(4 * 3600);

impl Default for ConvertOptions {
    fn default() -> Self {
        ConvertOptions { assimp: "assimp".into(), python: "python3".into(), timeout: DEFAULT_TIMEOUT }
    }
}

/// What a conversion made.
#[derive(Clone, Debug)]
pub struct Converted {
    /// The file to import (a GLB or an OBJ with its MTL beside it).
    pub output: PathBuf,
    /// The command that ran, for the report.
    pub command: String,
    pub elapsed: Duration,
    /// The units of the output's coordinates ([`Converter::units`]).
    pub units: Option<&'static str>,
    /// The scripts' summary (the last line they print), such as "110 products, 36290
    /// triangles"; empty for assimp.
    pub summary: String,
}

/// Why a conversion failed. Every message names the input file.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error("{}: reading {format} files needs {tool}, which is not installed here ({why}): install it with `{hint}`", path.display())]
    MissingTool { path: PathBuf, format: &'static str, tool: &'static str, why: String, hint: &'static str },
    #[error("{}: `{command}` failed ({status}){}", path.display(), quoted(stderr_tail))]
    Failed { path: PathBuf, command: String, status: String, stderr_tail: String },
    #[error("{}: `{command}` was stopped after running {} s, the time limit{}", path.display(), limit.as_secs(), quoted(stderr_tail))]
    TimedOut { path: PathBuf, command: String, limit: Duration, stderr_tail: String },
    #[error("{}: `{command}` exited successfully but wrote nothing to {}{}", path.display(), output.display(), quoted(stderr_tail))]
    NoOutput { path: PathBuf, command: String, output: PathBuf, stderr_tail: String },
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
}

/// A tool's standard error tail as the end of a message.
fn quoted(tail: &str) -> String {
    if tail.is_empty() {
        String::new()
    } else {
        format!("; its last messages:\n{tail}")
    }
}

/// Converts `input` with `converter` into a file in `dir` (an existing directory of its own:
/// the output, the tool's logs and any files it writes on the side go there).
pub fn convert(
    input: &Path,
    converter: Converter,
    dir: &Path,
    options: &ConvertOptions,
) -> Result<Converted, ConvertError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ConvertError::Io { path, source }
    };
    // The tool runs in `dir`, so no path it gets may depend on the current directory.
    let absolute = std::fs::canonicalize(input).map_err(io(input))?;
    let dir = &std::fs::canonicalize(dir).map_err(io(dir))?;
    let output = dir.join(output_name(input, converter));
    let mut command = command_for(converter, &absolute, &output, dir, options)?;
    command.current_dir(dir);
    let shown = show(&command);
    let (stdout, stderr) = (dir.join("convert.stdout"), dir.join("convert.stderr"));
    let outcome = run::run(&mut command, &stdout, &stderr, options.timeout).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            missing(input, converter, format!("cannot run {}", command.get_program().to_string_lossy()))
        } else {
            ConvertError::Io { path: input.to_path_buf(), source: e }
        }
    })?;
    let tail = || run::tail(&stderr, STDERR_LINES);
    let elapsed = match outcome {
        run::Outcome::TimedOut => {
            return Err(ConvertError::TimedOut {
                path: input.into(),
                command: shown,
                limit: options.timeout,
                stderr_tail: tail(),
            })
        }
        run::Outcome::Exited { status, .. }
            if status.code() == Some(MISSING_MODULE) && converter != Converter::Assimp =>
        {
            return Err(missing(input, converter, run::tail(&stderr, 1)));
        }
        run::Outcome::Exited { status, .. } if !status.success() => {
            return Err(ConvertError::Failed {
                path: input.into(),
                command: shown,
                status: status.to_string(),
                stderr_tail: tail(),
            })
        }
        run::Outcome::Exited { elapsed, .. } => elapsed,
    };
    if std::fs::metadata(&output).map_or(true, |m| m.len() == 0) {
        return Err(ConvertError::NoOutput {
            path: input.into(),
            command: shown,
            output,
            stderr_tail: tail(),
        });
    }
    // assimp's last line only repeats the output's path.
    let summary = if converter == Converter::Assimp { String::new() } else { run::tail(&stdout, 1) };
    Ok(Converted { output, command: shown, elapsed, units: converter.units(), summary })
}

/// The output's name: the input's stem (objects a format leaves unnamed are named after it)
/// with the extension the tool writes.
fn output_name(input: &Path, converter: Converter) -> String {
    let stem = input.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let stem = if stem.is_empty() { "model".into() } else { stem };
    format!("{stem}.{}", converter.output_extension())
}

/// The command that converts `input` into `output`, the Python script written into `dir`
/// first where one is needed. The program must exist: else a [`ConvertError::MissingTool`].
fn command_for(
    converter: Converter,
    input: &Path,
    output: &Path,
    dir: &Path,
    options: &ConvertOptions,
) -> Result<Command, ConvertError> {
    let (program, script) = match converter {
        Converter::Assimp => (&options.assimp, None),
        Converter::IfcOpenShell => (&options.python, Some(("ifc_to_obj.py", IFC_SCRIPT))),
        Converter::OpenCascade => (&options.python, Some(("step_to_obj.py", STEP_SCRIPT))),
    };
    let Some(program) = run::find_program(program) else {
        let why = format!("no program {} in PATH", program.display());
        return Err(missing(input, converter, why));
    };
    let mut command = Command::new(program);
    match script {
        None => {
            // glb2: binary glTF 2.0 (plain "glb" would be assimp's glTF 1.0 exporter).
            command.arg("export").arg(input).arg(output).arg("-fglb2");
        }
        Some((name, text)) => {
            let script = dir.join(name);
            std::fs::write(&script, text)
                .map_err(|source| ConvertError::Io { path: script.clone(), source })?;
            command.arg(script).arg(input).arg(output);
        }
    }
    Ok(command)
}

fn missing(input: &Path, converter: Converter, why: String) -> ConvertError {
    let format = Converter::for_path(input).map_or("these", |(_, f)| f);
    ConvertError::MissingTool {
        path: input.to_path_buf(),
        format,
        tool: converter.tool(),
        why,
        hint: converter.install_hint(),
    }
}

/// A command as a shell line, for reports.
fn show(command: &Command) -> String {
    std::iter::once(command.get_program())
        .chain(command.get_args())
        .map(|a| {
            let a = a.to_string_lossy();
            if a.contains(char::is_whitespace) {
                format!("'{a}'")
            } else {
                a.into_owned()
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests;
