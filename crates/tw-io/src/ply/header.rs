//! The PLY header: its lines are read and checked, then the vertex and face elements are found and
//! the properties we read from them are laid out ([`VertexLayout`], [`FaceLayout`]).

use std::path::Path;

use super::reader::{ByteReader, Line};
use super::scalar::Scalar;
use crate::error::{ImportError, Position};

/// Longest header line, and the most bytes a header may take.
const MAX_HEADER_LINE: usize = 64 << 10;
const MAX_HEADER_BYTES: usize = 16 << 20;
/// Most elements, and properties over all elements, a header may declare.
const MAX_ELEMENTS: usize = 4096;
const MAX_PROPERTIES: usize = 4096;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Encoding {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
pub(super) struct Property {
    pub(super) name: String,
    pub(super) kind: PropKind,
    line: u64,
}

/// What a vertex property means to us.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Role {
    X,
    Y,
    Z,
    Nx,
    Ny,
    Nz,
    R,
    G,
    B,
    A,
}

impl Role {
    fn of(name: &str) -> Option<Role> {
        Some(match name {
            "x" => Role::X,
            "y" => Role::Y,
            "z" => Role::Z,
            "nx" | "normal_x" => Role::Nx,
            "ny" | "normal_y" => Role::Ny,
            "nz" | "normal_z" => Role::Nz,
            "red" | "diffuse_red" => Role::R,
            "green" | "diffuse_green" => Role::G,
            "blue" | "diffuse_blue" => Role::B,
            "alpha" | "diffuse_alpha" => Role::A,
            _ => return None,
        })
    }
}

/// The vertex properties we read: (property index, role, type), and which attributes exist.
#[derive(Clone, Debug)]
pub(super) struct VertexLayout {
    pub(super) fields: Vec<(usize, Role, Scalar)>,
    /// `roles[p]` is the role of property `p`, if we read it.
    pub(super) roles: Vec<Option<Role>>,
    pub(super) normals: bool,
    pub(super) colors: bool,
}

/// Where a face keeps its indices: property index and the list's types; and its object id,
/// when it has one: property index and type.
#[derive(Clone, Copy, Debug)]
pub(super) struct FaceLayout {
    pub(super) prop: usize,
    pub(super) count: Scalar,
    pub(super) item: Scalar,
    pub(super) object: Option<(usize, Scalar)>,
}

#[derive(Clone, Debug)]
pub(super) enum ElementRole {
    Vertex(VertexLayout),
    Face(FaceLayout),
    Other,
}

#[derive(Clone, Debug)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: u64,
    pub(super) props: Vec<Property>,
    line: u64,
    pub(super) role: ElementRole,
}

#[derive(Clone, Debug)]
pub(super) struct Header {
    pub(super) encoding: Encoding,
    pub(super) elements: Vec<Element>,
    /// Lines in the header, `end_header` included.
    pub(super) lines: u64,
}

impl Header {
    pub(super) fn count_of(&self, f: impl Fn(&ElementRole) -> bool) -> u64 {
        self.elements.iter().find(|e| f(&e.role)).map_or(0, |e| e.count)
    }

    pub(super) fn describe_counts(&self) -> String {
        let v: Vec<String> = self.elements.iter().map(|e| format!("{} {}", e.count, e.name)).collect();
        v.join(", ")
    }
}

/// Smallest possible size of a binary record: its scalars and list counts.
pub(super) fn min_record_size(props: &[Property]) -> usize {
    props
        .iter()
        .map(|p| match p.kind {
            PropKind::Scalar(t) => t.size(),
            PropKind::List { count, .. } => count.size(),
        })
        .sum()
}

/// Reads the header, up to and including the `end_header` line, and works out the layouts of
/// the vertex and face elements.
pub(super) fn read_header(rd: &mut ByteReader, path: &Path) -> Result<Header, ImportError> {
    let mut line_no = 0u64;
    let mut header_bytes = 0usize;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut properties = 0usize;
    loop {
        line_no += 1;
        let err = |msg: String| ImportError::parse(path, Position::Line(line_no), msg);
        let range = match rd
            .read_line(MAX_HEADER_LINE)
            .map_err(|e| ImportError::io(path, Position::Line(line_no), e))?
        {
            Line::Text(r) => r,
            Line::Eof if line_no == 1 => return Err(ImportError::parse(path, Position::File, "empty file")),
            Line::Eof => return Err(err("the file ends inside the header (no \"end_header\" line)".into())),
            Line::TooLong => return Err(err(format!("header line longer than {MAX_HEADER_LINE} bytes"))),
        };
        header_bytes += range.len() + 1;
        if header_bytes > MAX_HEADER_BYTES {
            return Err(err(format!("the header is longer than {MAX_HEADER_BYTES} bytes")));
        }
        let bytes = rd.bytes(range);
        if line_no == 1 {
            if bytes.trim_ascii_end() != b"ply" {
                return Err(err("not a PLY file: the first line must be \"ply\"".into()));
            }
            continue;
        }
        let Ok(text) = std::str::from_utf8(bytes) else {
            return Err(err("the header line is not text (binary data inside the header?)".into()));
        };
        let mut words = text.split_ascii_whitespace();
        let Some(keyword) = words.next() else { continue };
        match keyword {
            "comment" | "obj_info" => continue,
            "format" => encoding = Some(format_line(words, encoding.is_some()).map_err(err)?),
            "element" => {
                let element = element_line(words, line_no).map_err(err)?;
                if elements.len() >= MAX_ELEMENTS {
                    return Err(err(format!("more than {MAX_ELEMENTS} elements")));
                }
                elements.push(element);
            }
            "property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(err("a property before any element".into()));
                };
                let property = property_line(words, line_no).map_err(err)?;
                properties += 1;
                if properties > MAX_PROPERTIES {
                    return Err(err(format!("more than {MAX_PROPERTIES} properties")));
                }
                element.props.push(property);
            }
            "end_header" => break,
            // Real exporters write stray lines (Blender 2.47: "Created by Blender3D ..." without
            // "comment"); readers such as trimesh and assimp skip them, and so do we.
            _ => {
                tracing::warn!("{}: line {line_no}: skipping unknown header line", path.display());
            }
        }
    }
    let Some(encoding) = encoding else {
        return Err(ImportError::parse(path, Position::Line(line_no), "the header has no \"format\" line"));
    };
    assign_roles(&mut elements, path)?;
    Ok(Header { encoding, elements, lines: line_no })
}

/// The encoding a `format` line gives (the words after `format`); `seen` when an earlier line
/// gave one already.
fn format_line<'a>(mut words: impl Iterator<Item = &'a str>, seen: bool) -> Result<Encoding, String> {
    let (Some(name), Some(version), None) = (words.next(), words.next(), words.next()) else {
        return Err("expected \"format <ascii|binary_little_endian|binary_big_endian> 1.0\"".into());
    };
    if seen {
        return Err("a second \"format\" line".into());
    }
    let encoding = match name {
        "ascii" => Encoding::Ascii,
        "binary_little_endian" => Encoding::BinaryLe,
        "binary_big_endian" => Encoding::BinaryBe,
        _ => {
            return Err(format!(
                "unknown format \"{name}\" (expected ascii, binary_little_endian or binary_big_endian)"
            ))
        }
    };
    if version != "1.0" && version != "1" {
        return Err(format!("unsupported PLY version {version} (only 1.0 is defined)"));
    }
    Ok(encoding)
}

/// The element an `element` line on header line `line` declares (the words after `element`),
/// still without properties and role.
fn element_line<'a>(mut words: impl Iterator<Item = &'a str>, line: u64) -> Result<Element, String> {
    let (Some(name), Some(count), None) = (words.next(), words.next(), words.next()) else {
        return Err("expected \"element <name> <count>\"".into());
    };
    let Ok(count) = count.parse::<u64>() else {
        return Err(format!("invalid count \"{count}\" for element {name}"));
    };
    Ok(Element { name: name.to_string(), count, props: Vec::new(), line, role: ElementRole::Other })
}

/// The property a `property` line on header line `line` declares (the words after
/// `property`): a scalar, or a list whose count type is an integer type.
fn property_line<'a>(words: impl Iterator<Item = &'a str>, line: u64) -> Result<Property, String> {
    let words: Vec<&str> = words.collect();
    let ty = |name: &str| Scalar::parse(name).ok_or_else(|| format!("unknown property type \"{name}\""));
    let (kind, name) =
        match words.as_slice() {
            ["list", count, item, name] => {
                let count = ty(count)?;
                if !count.is_integer() {
                    return Err(format!("the count type of list {name} must be an integer type"));
                }
                (PropKind::List { count, item: ty(item)? }, name)
            }
            [t, name] if *t != "list" => (PropKind::Scalar(ty(t)?), name),
            _ => return Err(
                "expected \"property <type> <name>\" or \"property list <count type> <item type> <name>\""
                    .into(),
            ),
        };
    Ok(Property { name: name.to_string(), kind, line })
}

/// Finds the vertex and face elements and the properties we read from them.
fn assign_roles(elements: &mut [Element], path: &Path) -> Result<(), ImportError> {
    let at = |line: u64, msg: String| ImportError::parse(path, Position::Line(line), msg);
    let mut vertex_at: Option<usize> = None;
    let mut face_at: Option<usize> = None;
    for (ei, el) in elements.iter_mut().enumerate() {
        match el.name.as_str() {
            "vertex" => {
                if vertex_at.is_some() {
                    return Err(at(el.line, "a second \"vertex\" element is not supported".into()));
                }
                vertex_at = Some(ei);
                el.role = ElementRole::Vertex(vertex_layout(el, path)?);
            }
            "face" => {
                if face_at.is_some() {
                    return Err(at(el.line, "a second \"face\" element is not supported".into()));
                }
                face_at = Some(ei);
                el.role = ElementRole::Face(face_layout(el, path)?);
            }
            _ => {
                if el.name == "tristrips" && el.count > 0 {
                    tracing::warn!(
                        "{}: element \"tristrips\" is not read; its triangles are skipped",
                        path.display()
                    );
                }
            }
        }
    }
    if let Some(f) = face_at {
        let face = &elements[f];
        match vertex_at {
            _ if face.count == 0 => {}
            None => return Err(at(face.line, "faces but no vertex element".into())),
            Some(v) if v > f => {
                return Err(ImportError::unsupported(
                    path,
                    format!(
                        "faces before vertices are not supported (element face on line {} precedes \
                         element vertex on line {})",
                        face.line, elements[v].line
                    ),
                ))
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// The layout of the vertex element: the position, and the normals and colours when all their
/// components are there (an incomplete set is ignored, with a warning).
fn vertex_layout(el: &Element, path: &Path) -> Result<VertexLayout, ImportError> {
    let at = |line: u64, msg: String| ImportError::parse(path, Position::Line(line), msg);
    let mut roles = vec![None; el.props.len()];
    let mut fields: Vec<(usize, Role, Scalar)> = Vec::new();
    for (pi, p) in el.props.iter().enumerate() {
        let Some(role) = Role::of(&p.name) else { continue };
        let PropKind::Scalar(t) = p.kind else {
            return Err(at(p.line, format!("vertex property {} must be a scalar, not a list", p.name)));
        };
        if fields.iter().any(|f| f.1 == role) {
            return Err(at(p.line, format!("vertex property {} given twice", p.name)));
        }
        roles[pi] = Some(role);
        fields.push((pi, role, t));
    }
    let has = |r: Role| fields.iter().any(|f| f.1 == r);
    for (r, name) in [(Role::X, "x"), (Role::Y, "y"), (Role::Z, "z")] {
        if !has(r) {
            return Err(at(el.line, format!("the vertex element has no property \"{name}\"")));
        }
    }
    let normals = has(Role::Nx) && has(Role::Ny) && has(Role::Nz);
    let colors = has(Role::R) && has(Role::G) && has(Role::B);
    let partial_normals = !normals && (has(Role::Nx) || has(Role::Ny) || has(Role::Nz));
    let partial_colors = !colors && (has(Role::R) || has(Role::G) || has(Role::B) || has(Role::A));
    if partial_normals || partial_colors {
        tracing::warn!(
            "{}: vertex normals or colours are incomplete (need nx ny nz, red green blue); ignored",
            path.display()
        );
    }
    let used = |r: Role| match r {
        Role::X | Role::Y | Role::Z => true,
        Role::Nx | Role::Ny | Role::Nz => normals,
        Role::R | Role::G | Role::B | Role::A => colors,
    };
    fields.retain(|f| used(f.1));
    for r in roles.iter_mut() {
        if r.is_some_and(|r| !used(r)) {
            *r = None;
        }
    }
    Ok(VertexLayout { fields, roles, normals, colors })
}

/// The layout of the face element: its index list, and its object property if any.
fn face_layout(el: &Element, path: &Path) -> Result<FaceLayout, ImportError> {
    let at = |line: u64, msg: String| ImportError::parse(path, Position::Line(line), msg);
    let Some((prop, p)) =
        el.props.iter().enumerate().find(|(_, p)| p.name == "vertex_indices" || p.name == "vertex_index")
    else {
        return Err(at(el.line, "the face element has no list \"vertex_indices\"".into()));
    };
    let PropKind::List { count, item } = p.kind else {
        return Err(at(p.line, format!("{} must be a list", p.name)));
    };
    if !item.is_integer() {
        return Err(at(p.line, format!("{} must be a list of integers", p.name)));
    }
    Ok(FaceLayout { prop, count, item, object: object_property(el, path) })
}

/// The face property that gives each face's object: a scalar integer named `object`, else one
/// named `object_id`. One of another type is skipped, with a warning.
fn object_property(el: &Element, path: &Path) -> Option<(usize, Scalar)> {
    let find = |name: &str| el.props.iter().position(|p| p.name == name);
    let pi = find("object").or_else(|| find("object_id"))?;
    let p = &el.props[pi];
    match p.kind {
        PropKind::Scalar(t) if t.is_integer() => Some((pi, t)),
        _ => {
            tracing::warn!(
                "{}: line {}: face property {} is not a scalar integer; faces keep the file's single object",
                path.display(),
                p.line,
                p.name
            );
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::error::{ImportError, Position};

    use super::super::test_util::*;

    #[test]
    fn empty_file() {
        assert_err(&err("e.ply", b""), Position::File, "empty file");
    }

    #[test]
    fn garbage_bytes() {
        assert_err(&err("g.ply", b"\x00\x9f\x13garbage\n\x01"), Position::Line(1), "not a PLY file");
        assert_err(&err("g.ply", b"ply\n\xff\xfe\xfd\n"), Position::Line(2), "not text");
    }

    #[test]
    fn stray_header_lines_are_skipped() {
        // As Blender 2.47 writes them (assimp's Wuson.ply).
        let (c, _) = run(
            "w.ply",
            b"ply\nformat ascii 1.0\nCreated by Blender3D 247\nelement vertex 3\nproperty float x\n\
              property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
              end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        )
        .unwrap();
        assert_eq!(c.tris.len(), 1);
    }

    #[test]
    fn truncated_header() {
        let e = err("t.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n");
        assert_err(&e, Position::Line(5), "ends inside the header");
    }

    #[test]
    fn unknown_format_and_version() {
        assert_err(
            &err("f.ply", b"ply\nformat binary_middle_endian 1.0\nend_header\n"),
            Position::Line(2),
            "unknown format",
        );
        assert_err(&err("f.ply", b"ply\nformat ascii 2.0\nend_header\n"), Position::Line(2), "version 2.0");
        assert_err(&err("f.ply", b"ply\nend_header\n"), Position::Line(2), "no \"format\" line");
    }

    #[test]
    fn unknown_property_type() {
        let text = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n";
        assert_err(&err("p.ply", text), Position::Line(4), "unknown property type \"float128\"");
        let text = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\nend_header\n";
        assert_err(&err("p.ply", text), Position::Line(4), "must be an integer type");
    }

    #[test]
    fn missing_z() {
        let text =
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n";
        assert_err(&err("z.ply", text), Position::Line(3), "no property \"z\"");
    }

    #[test]
    fn face_without_vertex_indices() {
        let text = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                     element face 1\nproperty list uchar int corners\nend_header\n";
        assert_err(&err("f.ply", text), Position::Line(7), "no list \"vertex_indices\"");
        let text = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                     element face 1\nproperty list uchar float vertex_indices\nend_header\n";
        assert_err(&err("f.ply", text), Position::Line(8), "list of integers");
    }

    #[test]
    fn faces_before_vertices() {
        let text = b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
                     element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
        let e = err("o.ply", text);
        assert!(matches!(e, ImportError::Unsupported { .. }), "{e:?}");
        assert!(e.to_string().contains("faces before vertices are not supported"), "{e}");
    }
}
