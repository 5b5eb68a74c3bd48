//! Format detection: gzip by magic bytes (see [`crate::input`]), then the model format by the
//! content's own magic where it has one (PLY, GLB) and by the file name otherwise. A name that
//! promises a format the content contradicts is an error, not a guess.

use std::path::{Path, PathBuf};

use crate::error::{ImportError, Position};
use crate::input::{logical_name, Input};
use crate::TriangleSource;

/// The model formats terawalk reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Obj,
    Ply,
    Stl,
    Gltf,
    Glb,
}

impl Format {
    /// The format a file name asks for ("x.ply.gz" asks for PLY), if any.
    pub fn from_name(path: &Path) -> Option<Format> {
        let name = logical_name(path);
        let ext = name.rsplit_once('.').map(|(_, e)| e)?;
        Some(match ext {
            "obj" => Format::Obj,
            "ply" => Format::Ply,
            "stl" => Format::Stl,
            "gltf" => Format::Gltf,
            "glb" => Format::Glb,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Format::Obj => "OBJ",
            Format::Ply => "PLY",
            Format::Stl => "STL",
            Format::Gltf => "glTF",
            Format::Glb => "GLB",
        }
    }
}

/// Options every importer receives.
#[derive(Clone, Debug)]
pub struct ImportOptions {
    /// Memory, in bytes, that vertex stores (OBJ, PLY) may keep before spilling to disk.
    pub vertex_memory: usize,
    /// Directory for spill files and decompressed copies; the system temp dir when `None`.
    pub spill_dir: Option<PathBuf>,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions { vertex_memory: 192 << 20, spill_dir: None }
    }
}

/// Detects the format of `input` from its first bytes and its name: a name that the content
/// contradicts is an error; otherwise the content's magic (PLY, GLB) decides, then the name,
/// then, for a name without a known extension, the content alone.
pub fn detect(input: &mut Input) -> Result<Format, ImportError> {
    let path = input.path.clone();
    let by_name = Format::from_name(&path);
    let head = input.peek(512)?;
    if head.is_empty() {
        return Err(ImportError::parse(&path, Position::File, "empty file"));
    }
    let magic = Magic::of(head);
    if let Some(named) = by_name {
        check_name(&path, named, &magic)?;
    }
    match by_name {
        _ if magic.ply => Ok(Format::Ply),
        _ if magic.glb => Ok(Format::Glb),
        Some(f) => Ok(f),
        None => by_content(&path, head, &magic),
    }
}

/// What the first bytes of a file say about its format.
struct Magic {
    /// It starts with the line "ply".
    ply: bool,
    /// It starts with GLB's magic "glTF".
    glb: bool,
    /// Its first byte that is not white space.
    first_text: Option<u8>,
}

impl Magic {
    fn of(head: &[u8]) -> Magic {
        Magic {
            ply: head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n"),
            glb: head.starts_with(b"glTF"),
            first_text: head.iter().find(|b| !b.is_ascii_whitespace()).copied(),
        }
    }
}

/// An error when the content contradicts the format that the name `named` promises (PLY and
/// GLB by their magic, glTF by being a JSON document or, misnamed, GLB).
fn check_name(path: &Path, named: Format, magic: &Magic) -> Result<(), ImportError> {
    let mismatch = |what: &str| {
        Err(ImportError::parse(path, Position::Byte(0), format!("not a {} file: {what}", named.name())))
    };
    match named {
        Format::Ply if !magic.ply => mismatch("it does not start with the line \"ply\""),
        Format::Glb if !magic.glb => mismatch("it does not start with the magic \"glTF\""),
        Format::Gltf if magic.first_text != Some(b'{') && !magic.glb => mismatch("it is not a JSON document"),
        _ => Ok(()),
    }
}

/// The format of a file whose name has no known extension and whose content has no magic:
/// only what the content makes unambiguous (STL's "solid … facet", glTF's JSON "asset", OBJ's
/// vertex lines); a format that `terawalk build` converts, or an unknown one, is an error.
fn by_content(path: &Path, head: &[u8], magic: &Magic) -> Result<Format, ImportError> {
    let text = std::str::from_utf8(&head[..head.len().min(256)]).unwrap_or("");
    if text.trim_start().starts_with("solid") && text.contains("facet") {
        Ok(Format::Stl)
    } else if magic.first_text == Some(b'{') && text.contains("\"asset\"") {
        Ok(Format::Gltf)
    } else if text.lines().any(|l| l.starts_with("v ")) {
        Ok(Format::Obj)
    } else if let Some((converter, format)) = crate::convert::Converter::for_name(path) {
        // Only `terawalk build` (and the commands that build on the fly) convert.
        Err(ImportError::parse(
            path,
            Position::File,
            format!(
                "{format} is not read directly: `terawalk build` converts it with {} first",
                converter.tool()
            ),
        ))
    } else {
        Err(ImportError::parse(
            path,
            Position::File,
            "unknown format: expected .obj, .ply, .stl, .gltf or .glb (each optionally .gz)",
        ))
    }
}

/// Opens `path` as a triangle source, detecting gzip and the format.
pub fn open_source(path: &Path, options: &ImportOptions) -> Result<Box<dyn TriangleSource>, ImportError> {
    open_input(Input::open(path)?, options)
}

/// Detects the format of an opened input and returns its source.
pub fn open_input(input: Input, options: &ImportOptions) -> Result<Box<dyn TriangleSource>, ImportError> {
    open_detected(input, options).map(|(_, source)| source)
}

/// [`open_input`], also returning the format detected (its conventions, such as glTF's up
/// axis, matter beyond the importer).
pub fn open_detected(
    mut input: Input,
    options: &ImportOptions,
) -> Result<(Format, Box<dyn TriangleSource>), ImportError> {
    let format = detect(&mut input)?;
    let source = match format {
        Format::Obj => crate::obj::open(input, options),
        Format::Ply => crate::ply::open(input, options),
        Format::Stl => crate::stl::open(input, options),
        Format::Gltf | Format::Glb => crate::gltf::open(input, format, options),
    }?;
    Ok((format, source))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn detect_bytes(name: &str, bytes: &[u8]) -> Result<Format, ImportError> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        detect(&mut Input::open(&p).unwrap())
    }

    #[test]
    fn formats_by_magic_and_name() {
        assert_eq!(detect_bytes("a.ply", b"ply\nformat ascii 1.0\n").unwrap(), Format::Ply);
        assert_eq!(detect_bytes("a.bin", b"ply\r\nformat ascii 1.0\n").unwrap(), Format::Ply);
        assert_eq!(detect_bytes("a.glb", b"glTF\x02\0\0\0").unwrap(), Format::Glb);
        assert_eq!(detect_bytes("a.obj", b"v 1 2 3\n").unwrap(), Format::Obj);
        assert_eq!(detect_bytes("a.STL", b"\0\0\0").unwrap(), Format::Stl);
        assert_eq!(detect_bytes("a.gltf", b" {\"asset\":{}}").unwrap(), Format::Gltf);
        assert_eq!(detect_bytes("noext", b"# hi\nv 1 2 3\n").unwrap(), Format::Obj);
    }

    #[test]
    fn wrong_extension_and_garbage_are_errors() {
        let e = detect_bytes("a.ply", b"solid x\n").unwrap_err();
        assert!(e.to_string().contains("not a PLY file"), "{e}");
        let e = detect_bytes("a.glb", b"{}").unwrap_err();
        assert!(e.to_string().contains("not a GLB file"), "{e}");
        let e = detect_bytes("a.gltf", b"\x00\x01garbage").unwrap_err();
        assert!(e.to_string().contains("not a glTF file"), "{e}");
        let e = detect_bytes("a.xyz", b"\x00\x01\x02garbage").unwrap_err();
        assert!(e.to_string().contains("unknown format"), "{e}");
        let e = detect_bytes("a.obj", b"").unwrap_err();
        assert!(e.to_string().contains("empty file"), "{e}");
        let e = detect_bytes("a.ifc", b"ISO-10303-21;\nHEADER;\n").unwrap_err();
        assert!(e.to_string().contains("IFC is not read directly: `terawalk build` converts it"), "{e}");
    }
}
