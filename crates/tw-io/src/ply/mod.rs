//! PLY importer: streams the triangles of ASCII and binary (little- and big-endian) PLY 1.0 files.
//!
//! Follows Greg Turk's "The PLY Polygon File Format" (1994) and the conventions of its common
//! writers (Stanford scans, MeshLab, Blender, Open3D, PCL):
//! - header: `comment`/`obj_info` lines, any elements with scalar properties of the types
//!   `char uchar short ushort int uint float double` (and `int8 … float64`) and list properties
//!   with any integer count type and any item type;
//! - element `vertex`: `x y z` (any numeric type), optional `nx ny nz` (or `normal_x …`) and
//!   `red green blue [alpha]` (or `diffuse_red …`; integers are 0..255, `ushort` 0..65535,
//!   floats 0..1); other properties are skipped;
//! - element `face`: the list `vertex_indices` (or `vertex_index`) of any integer types; polygons
//!   are fan-triangulated, faces of fewer than three vertices are skipped (and counted in a
//!   warning); a scalar integer property `object` (or `object_id`), as terawalk's PLY writer
//!   writes it, gives each face's object (see below); other face properties are skipped;
//! - any other element (`edge`, `material`, `tristrips`…), before, between or after these, is
//!   skipped.
//!
//! Objects: without a per-face `object` property (or without faces) the file is one object (id 0)
//! named after the file. With it, the file's ids are arbitrary integers: each new one, in order of
//! first appearance, becomes the next dense id (0, 1, 2, …), announced as `<file name>/<id in the
//! file>` just before its first triangle (memory grows with the number of objects, not of faces).
//!
//! Stages:
//! 1. [`open`] reads the header (`header::read_header`) and checks that a binary file is long
//!    enough for its declared counts, so that a broken file fails before any work.
//! 2. [`PlySource::stream`] walks the elements in file order: vertex records go into
//!    [`VertexStore`](crate::vertex_store::VertexStore)s (positions, and normals and colours when
//!    present) under the memory budget of [`ImportOptions::vertex_memory`], spilling to disk
//!    beyond it; positions are kept as `f32` when the file's coordinate types convert to `f32`
//!    exactly (the usual `float x y z`), which halves memory and spilling, and as `f64`
//!    otherwise. Face records are resolved through the stores and streamed as triangles; other
//!    elements are skipped.
//! 3. Binary faces whose records are triangles of one size (every property a scalar but the
//!    index list, its count 3: what terawalk writes and most large scans are) go in runs
//!    (`runs::Body::binary_triangles`): `scan_run` checks a run's counts and indices in order,
//!    makes the vertex blocks it uses resident and resolves its objects, and the run goes to
//!    the sink as one [`TriangleBatch`](crate::TriangleBatch), which the sink may resolve on
//!    several threads (the build does). Any other record (a polygon, a short face) is read the
//!    general way in between; triangles, order, objects and errors are the same either way.
//!
//! Binary records are decoded straight out of the read buffer (`reader::ByteReader`): a record of a
//! fixed layout is a constant set of offsets, a record with lists is measured once and decoded in
//! place, with no per-record allocation and no reads through a trait object. ASCII records are
//! one line each.
//!
//! Limits and choices: faces must come after vertices (the usual order; the other order would
//! need the faces held until the vertices arrive); lists in vertex and face records hold at most
//! [`MAX_LIST`] items; a file without faces (a point cloud) yields no triangles and its vertex
//! data is skipped unread; a non-finite position is an error, a non-finite normal becomes zero.
//!
//! Layout of the module: `header` reads the header into elements and properties (`scalar` holds
//! their types and their binary encodings); the body is read by `ascii` or `binary`, with `runs`
//! for binary triangle records; `vertices` and `faces` hold what the records give; `reader` is
//! the read buffer and tokenizer under all of them (and under the STL importer).

mod ascii;
mod binary;
mod faces;
mod header;
mod reader;
mod runs;
mod scalar;
#[cfg(test)]
mod test_util;
mod vertices;

use std::io;
use std::path::{Path, PathBuf};

use crate::error::{ImportError, Position};
use crate::format::ImportOptions;
use crate::input::{DiskCounter, Input};
use crate::{ObjectInfo, SourceSummary, TriangleSink, TriangleSource};

use faces::{Faces, Objects};
use header::{min_record_size, read_header, ElementRole, Encoding, FaceLayout, Header};
pub(crate) use reader::{parse_f64, show, ByteReader, Line, Tokens};
use vertices::Vertices;

/// Most items a list in a vertex or face record may hold (so a face has at most this many
/// vertices); a longer list is an error, not an allocation.
pub const MAX_LIST: i64 = 1 << 16;
/// Most items a list in a skipped element may hold.
const MAX_SKIPPED_LIST: i64 = 1 << 20;

/// Opens a PLY file for streaming: reads and checks the header.
pub fn open(input: Input, options: &ImportOptions) -> Result<Box<dyn TriangleSource>, ImportError> {
    let path = input.path.clone();
    let (gzip, file_len, counter) = (input.gzip, input.file_len, input.disk_counter());
    let mut rd = ByteReader::new(input);
    let header = read_header(&mut rd, &path)?;
    if header.encoding != Encoding::Ascii && !gzip {
        // Every record takes at least its scalars and list counts: a file too short for the
        // declared counts is truncated, and we say so now rather than after hours of work.
        let need: u128 =
            header.elements.iter().map(|e| e.count as u128 * min_record_size(&e.props) as u128).sum();
        let have = file_len.saturating_sub(rd.position()) as u128;
        if need > have {
            return Err(ImportError::parse(
                &path,
                Position::Byte(file_len),
                format!(
                    "the file is truncated: the header declares {} needing at least {need} bytes of data, \
                     but only {have} follow the header",
                    header.describe_counts()
                ),
            ));
        }
    }
    Ok(Box::new(PlySource { path, rd, header, options: options.clone(), counter, file_len }))
}

/// The object name of a file: its name without `.gz` and without its extension.
pub(crate) fn object_name(path: &Path) -> String {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let name =
        if name.to_ascii_lowercase().ends_with(".gz") { name[..name.len() - 3].to_string() } else { name };
    match name.rfind('.') {
        Some(i) if i > 0 => name[..i].to_string(),
        _ => name,
    }
}

/// The PLY source: the header is read, the body streams on [`TriangleSource::stream`].
pub struct PlySource {
    path: PathBuf,
    rd: ByteReader,
    header: Header,
    options: ImportOptions,
    counter: DiskCounter,
    file_len: u64,
}

/// Why a record could not be used; it becomes an [`ImportError`] with the record's position.
enum RecordError {
    Bad(String),
    Io(io::Error),
    Sink(ImportError),
}

impl From<io::Error> for RecordError {
    fn from(e: io::Error) -> Self {
        RecordError::Io(e)
    }
}

impl From<ImportError> for RecordError {
    fn from(e: ImportError) -> Self {
        RecordError::Sink(e)
    }
}

impl RecordError {
    fn at(self, path: &Path, pos: Position, element: &str, index: u64) -> ImportError {
        match self {
            RecordError::Bad(msg) => ImportError::parse(path, pos, format!("{element} {index}: {msg}")),
            RecordError::Io(e) => ImportError::io(path, pos, e),
            RecordError::Sink(e) => e,
        }
    }
}

impl TriangleSource for PlySource {
    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn progress_total(&self) -> Option<u64> {
        Some(self.file_len)
    }

    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        let PlySource { path, mut rd, header, options, counter, .. } = *self;
        // Per-face objects when the faces have them; otherwise the file is one object.
        let per_face_objects = header
            .elements
            .iter()
            .any(|e| e.count > 0 && matches!(e.role, ElementRole::Face(FaceLayout { object: Some(_), .. })));
        let objects = if per_face_objects {
            Some(Objects::new(object_name(&path)))
        } else {
            sink.object(0, &ObjectInfo { name: object_name(&path), color: None })?;
            None
        };
        let faces_declared = header.count_of(|r| matches!(r, ElementRole::Face(_)));
        let vertices_declared = header.count_of(|r| matches!(r, ElementRole::Vertex(_)));
        let mut body = Body {
            path: &path,
            counter: &counter,
            big: header.encoding == Encoding::BinaryBe,
            line: header.lines,
            vertices: None,
            faces: Faces { indices: Vec::new(), short: 0 },
            objects,
        };
        for el in &header.elements {
            match (&el.role, header.encoding) {
                (ElementRole::Vertex(layout), _) if faces_declared > 0 => {
                    let mut v = Vertices::new(Some(layout), &options);
                    if header.encoding == Encoding::Ascii {
                        body.ascii_vertices(&mut rd, el, layout, &mut v, sink)?;
                    } else {
                        body.binary_vertices(&mut rd, el, layout, &mut v, sink)?;
                    }
                    body.vertices = Some(v);
                }
                (ElementRole::Face(layout), _) if el.count > 0 => {
                    let mut v = body.vertices.take().unwrap_or_else(|| Vertices::new(None, &options));
                    let result = if header.encoding == Encoding::Ascii {
                        body.ascii_faces(&mut rd, el, layout, &mut v, sink)
                    } else {
                        body.binary_faces(&mut rd, el, layout, &mut v, sink)
                    };
                    body.vertices = Some(v);
                    result?;
                }
                (_, Encoding::Ascii) => body.ascii_skip(&mut rd, el, sink)?,
                _ => body.binary_skip(&mut rd, el, sink)?,
            }
        }
        let trailing = if header.encoding == Encoding::Ascii {
            rd.only_whitespace_left().map(|w| !w)
        } else {
            rd.ensure(1)
        }
        .map_err(|e| ImportError::io(&path, Position::Byte(rd.position()), e))?;
        if trailing {
            tracing::warn!("{}: data after the last element ignored", path.display());
        }
        if body.faces.short > 0 {
            tracing::warn!("{}: {} faces of fewer than 3 vertices skipped", path.display(), body.faces.short);
        }
        if let Some(v) = &body.vertices {
            let st = v.stats();
            if st.blocks_spilled > 0 {
                tracing::debug!(
                    "{}: vertex store spilled {} blocks, loaded {}",
                    path.display(),
                    st.blocks_spilled,
                    st.blocks_loaded
                );
            }
        }
        sink.progress(counter.get());
        let objects = body.objects.as_ref().map_or(1, Objects::len);
        Ok(SourceSummary { objects, vertices: vertices_declared, bytes: counter.get() })
    }
}

/// Body-reading state shared by the element readers. It is defined here, in their parent
/// module, so that `ascii`, `binary` and `runs` each add their readers to it as methods with
/// access to its fields.
struct Body<'a> {
    path: &'a Path,
    counter: &'a DiskCounter,
    big: bool,
    /// Last line read (ASCII).
    line: u64,
    vertices: Option<Vertices>,
    faces: Faces,
    /// Per-face objects, when the faces have an object property.
    objects: Option<Objects>,
}

#[cfg(test)]
mod tests {
    use super::test_util::*;
    use super::*;

    #[test]
    fn all_encodings_plain_and_gzip_give_the_same_triangles() {
        for enc in ["ascii", "binary_little_endian", "binary_big_endian"] {
            for zipped in [false, true] {
                let bytes = if zipped { gz(&square(enc)) } else { square(enc) };
                let (c, s) = run("square.ply", &bytes).unwrap_or_else(|e| panic!("{enc} {zipped}: {e}"));
                assert_eq!(positions(&c), square_triangles(), "{enc} gzip={zipped}");
                assert_eq!(c.objects, vec![(0, ObjectInfo { name: "square".into(), color: None })]);
                assert_eq!(s.objects, 1);
                assert_eq!(s.vertices, 4);
                assert_eq!(s.bytes, bytes.len() as u64);
                assert!(c.tris.iter().all(|t| t.normals.is_none() && t.colors.is_none() && t.object == 0));
                assert!(c.progress_calls > 0);
            }
        }
    }

    #[test]
    fn object_name_is_the_file_stem() {
        let (c, _) = run("Pump House.ply.gz", &gz(&square("ascii"))).unwrap();
        assert_eq!(c.objects[0].1.name, "Pump House");
        assert_eq!(object_name(Path::new("/a/b.c.PLY.GZ")), "b.c");
        assert_eq!(object_name(Path::new(".hidden")), ".hidden");
    }

    /// Extra elements before, between and after, with lists, and extra vertex and face properties.
    fn cluttered(encoding: &str) -> Vec<u8> {
        let header = format!(
            "ply\nformat {encoding} 1.0\nelement material 2\nproperty list uchar uchar name\nproperty float shine\n\
             element vertex 3\nproperty float confidence\nproperty float x\nproperty list uchar short tags\n\
             property float y\nproperty float z\nproperty uchar flags\n\
             element edge 1\nproperty int vertex1\nproperty int vertex2\n\
             element face 2\nproperty uchar kind\nproperty list uchar int vertex_indices\n\
             property list uchar float texcoord\nelement extra 1\nproperty list int double values\nend_header\n"
        );
        if encoding == "ascii" {
            return (header
                + "3 65 66 67 0.5\n0 1\n\
                   0.9 0 2 5 6 0 0 7\n0.8 1 0 0 0 0\n0.7 0 1 1 1 0 0\n\
                   0 1\n\
                   9 3 0 1 2 6 0 0 1 0 0 1\n1 4 2 1 0 2 0\n\
                   2 1.5 2.5\n")
                .into_bytes();
        }
        let mut w = W::new(&header, encoding == "binary_big_endian");
        w.u8(3).u8(65).u8(66).u8(67).f32(0.5);
        w.u8(0).f32(1.0);
        w.f32(0.9).f32(0.0).u8(2).i16(5).i16(6).f32(0.0).f32(0.0).u8(7);
        w.f32(0.8).f32(1.0).u8(0).f32(0.0).f32(0.0).u8(0);
        w.f32(0.7).f32(0.0).u8(1).i16(1).f32(1.0).f32(0.0).u8(0);
        w.i32(0).i32(1);
        w.u8(9).u8(3).i32(0).i32(1).i32(2).u8(6).f32(0.0).f32(0.0).f32(1.0).f32(0.0).f32(0.0).f32(1.0);
        w.u8(1).u8(4).i32(2).i32(1).i32(0).i32(2).u8(0);
        w.i32(2).f64(1.5).f64(2.5);
        w.out
    }

    #[test]
    fn extra_elements_and_properties_are_skipped_in_every_encoding() {
        let a = [0.0, 0.0, 0.0];
        let b = [1.0, 0.0, 0.0];
        let c = [0.0, 1.0, 0.0];
        for enc in ["ascii", "binary_little_endian", "binary_big_endian"] {
            let (got, s) = run("x.ply", &cluttered(enc)).unwrap_or_else(|e| panic!("{enc}: {e}"));
            // The quad 2 1 0 2 fans into (2 1 0) and (2 0 2).
            assert_eq!(positions(&got), vec![[a, b, c], [c, b, a], [c, a, c]], "{enc}");
            assert_eq!(s.vertices, 3);
        }
    }

    #[test]
    fn point_cloud_without_faces_announces_the_object() {
        let text =
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
                    end_header\n1 2 3\nnan 0 0\n";
        let (c, s) = run("cloud.ply", text.as_bytes()).unwrap();
        assert_eq!(c.objects.len(), 1);
        assert!(c.tris.is_empty());
        assert_eq!(s, SourceSummary { objects: 1, vertices: 2, bytes: text.len() as u64 });
    }

    #[test]
    fn zero_faces_declared() {
        let text =
            "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
                    property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n";
        let (c, s) = run("empty.ply", text.as_bytes()).unwrap();
        assert_eq!((c.objects.len(), c.tris.len(), s.objects), (1, 0, 1));
    }
}
