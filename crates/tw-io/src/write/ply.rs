//! Binary PLY writer (PLY 1.0, `binary_little_endian`, as Greg Turk's format description and
//! every common reader — rply, plyfile, trimesh, MeshLab/vcglib, tinyply — define it).
//!
//! Layout:
//! ```text
//! ply
//! format binary_little_endian 1.0
//! comment written by terawalk            <- padded with spaces, see below
//! element vertex N
//! property float x
//! property float y
//! property float z
//! element face M
//! property list uchar uint vertex_indices
//! property uint object                    <- the triangle's object id
//! end_header
//! N × 12 bytes, M × 17 bytes
//! ```
//!
//! Vertices and faces arrive interleaved, so vertices go straight into the file after a header
//! of fixed length and faces into an unnamed temporary file, appended at the end. The counts are known
//! only then: the header is written again over the first one, and its comment line is padded
//! with spaces so that the final header, with exact counts, has the length of the first one
//! (written with 20-digit counts). This keeps the counts plain decimal without leading zeros or
//! spaces, which some readers would misread (octal, or a split on single spaces). For `.gz`
//! output, which cannot seek, the vertices are spilled too and the file is assembled at the end.
//!
//! The per-face `object` property is ignored by tools that do not know it; terawalk's PLY
//! importer reads it back, numbering the ids densely in order of first appearance.
//!
//! Object names and colours are not written: they could go only in the header (as `comment
//! object …` lines), and objects are announced while the vertices already stream out behind a
//! header of fixed length, so adding them at the end would mean moving the vertex section, about
//! two thirds of the file. PLY output keeps the object of every triangle; OBJ and GLB output keep
//! names and colours too.

use std::io::{Seek, SeekFrom, Write};
use std::path::Path;

use crate::error::ImportError;
use crate::{MeshChunk, ObjectId, ObjectInfo, Triangle, TriangleSink};

use super::{check_chunk, io_err, to_f32, Objects, Output, SceneWriter, Spill, WriteSummary};

/// Bytes per vertex record (3 × f32).
const VERTEX_BYTES: usize = 12;
/// Bytes per face record (count u8, 3 × u32, object u32).
const FACE_BYTES: usize = 17;

/// Writes binary little-endian PLY; see the module documentation.
pub struct PlyWriter {
    out: Output,
    /// Vertices, when the output cannot seek (gzip); written to `out` directly otherwise.
    vertex_spill: Option<Spill>,
    faces: Spill,
    objects: Objects,
    /// Length of the header at the start of the file (plain output).
    header_len: usize,
    vertices: u64,
    triangles: u64,
    /// Scratch for encoding a mesh chunk's vertices or faces.
    scratch: Vec<u8>,
}

/// The header for the given counts; `pad_to` pads the comment line to give that total length.
fn header(vertices: u64, faces: u64, pad_to: usize) -> Vec<u8> {
    let build = |pad: usize| {
        format!(
            "ply\nformat binary_little_endian 1.0\ncomment written by terawalk{:pad$}\n\
             element vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\n\
             element face {faces}\nproperty list uchar uint vertex_indices\nproperty uint object\n\
             end_header\n",
            ""
        )
        .into_bytes()
    };
    let h = build(0);
    if h.len() >= pad_to {
        h
    } else {
        build(pad_to - h.len())
    }
}

/// The length of every header this writer makes: the header with the widest counts.
fn reserved_header_len() -> usize {
    header(u64::MAX, u64::MAX, 0).len()
}

impl PlyWriter {
    /// Starts writing `path` (gzip'ed when `gzip`). Nothing appears at `path` before
    /// [`SceneWriter::finish`].
    pub fn create(path: &Path, gzip: bool) -> Result<PlyWriter, ImportError> {
        let mut out = Output::create(path, gzip)?;
        let faces = Spill::create(path)?;
        let header_len = reserved_header_len();
        let vertex_spill = if gzip {
            Some(Spill::create(path)?)
        } else {
            out.write_all(&header(0, 0, header_len)).map_err(io_err(path))?;
            None
        };
        Ok(PlyWriter {
            out,
            vertex_spill,
            faces,
            objects: Objects::default(),
            header_len,
            vertices: 0,
            triangles: 0,
            scratch: Vec::new(),
        })
    }

    fn write_vertices(&mut self, bytes: &[u8]) -> Result<(), ImportError> {
        let r = match &mut self.vertex_spill {
            Some(s) => s.write_all(bytes),
            None => self.out.write_all(bytes),
        };
        r.map_err(io_err(self.out.target()))
    }

    /// Reserves `n` new vertex indices; the result is the first. Indices are u32 in the file.
    fn reserve_vertices(&mut self, n: u64) -> Result<u32, ImportError> {
        let first = self.vertices;
        if first + n > u32::MAX as u64 + 1 {
            return Err(ImportError::Sink(format!(
                "{}: more than 2^32 vertices, beyond PLY's 32-bit vertex indices",
                self.out.target().display()
            )));
        }
        self.vertices += n;
        Ok(first as u32)
    }
}

#[inline]
fn face_record(a: u32, b: u32, c: u32, object: ObjectId) -> [u8; FACE_BYTES] {
    let mut f = [0u8; FACE_BYTES];
    f[0] = 3;
    f[1..5].copy_from_slice(&a.to_le_bytes());
    f[5..9].copy_from_slice(&b.to_le_bytes());
    f[9..13].copy_from_slice(&c.to_le_bytes());
    f[13..17].copy_from_slice(&object.to_le_bytes());
    f
}

#[inline]
fn put_vertex(dst: &mut [u8], p: [f32; 3]) {
    dst[0..4].copy_from_slice(&p[0].to_le_bytes());
    dst[4..8].copy_from_slice(&p[1].to_le_bytes());
    dst[8..12].copy_from_slice(&p[2].to_le_bytes());
}

impl TriangleSink for PlyWriter {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        self.objects.announce(self.out.target(), id, info)?;
        Ok(())
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.objects.get(self.out.target(), t.object)?;
        let mut v = [0u8; 3 * VERTEX_BYTES];
        for (k, p) in t.positions.iter().enumerate() {
            put_vertex(&mut v[k * VERTEX_BYTES..], to_f32(self.out.target(), *p)?);
        }
        let first = self.reserve_vertices(3)?;
        self.write_vertices(&v)?;
        self.faces
            .write_all(&face_record(first, first + 1, first + 2, t.object))
            .map_err(io_err(self.out.target()))?;
        self.triangles += 1;
        Ok(())
    }

    fn mesh(&mut self, chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        let target = self.out.target().to_path_buf();
        self.objects.get(&target, chunk.object)?;
        check_chunk(&target, chunk)?;
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        scratch.resize(chunk.positions.len() * VERTEX_BYTES, 0);
        for (dst, p) in scratch.chunks_exact_mut(VERTEX_BYTES).zip(chunk.positions) {
            put_vertex(dst, to_f32(&target, *p)?);
        }
        let first = self.reserve_vertices(chunk.positions.len() as u64)?;
        self.write_vertices(&scratch)?;
        scratch.clear();
        for t in chunk.indices.chunks_exact(3) {
            scratch.extend_from_slice(&face_record(first + t[0], first + t[1], first + t[2], chunk.object));
        }
        self.faces.write_all(&scratch).map_err(io_err(&target))?;
        self.triangles += (chunk.indices.len() / 3) as u64;
        self.scratch = scratch;
        Ok(())
    }
}

impl SceneWriter for PlyWriter {
    fn finish(self: Box<Self>) -> Result<WriteSummary, ImportError> {
        let PlyWriter { mut out, vertex_spill, faces, objects, header_len, vertices, triangles, .. } = *self;
        let target = out.target().to_path_buf();
        let err = io_err(&target);
        debug_assert_eq!(faces.len(), triangles * FACE_BYTES as u64);
        let head = header(vertices, triangles, header_len);
        debug_assert_eq!(head.len(), header_len);
        match vertex_spill {
            Some(vs) => {
                out.write_all(&head).map_err(&err)?;
                vs.copy_into(&mut out).map_err(&err)?;
                faces.copy_into(&mut out).map_err(&err)?;
            }
            None => {
                faces.copy_into(&mut out).map_err(&err)?;
                let Some(file) = out.seekable() else {
                    return Err(ImportError::Sink(format!(
                        "{}: internal: output cannot seek",
                        target.display()
                    )));
                };
                file.seek(SeekFrom::Start(0)).map_err(&err)?;
                file.write_all(&head).map_err(&err)?;
            }
        }
        let bytes = out.commit()?;
        Ok(WriteSummary { objects: objects.len(), triangles, vertices, bytes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::write::{create_writer, test_scene};

    /// Parses our own PLY output minimally: header lines, then the two element blocks.
    struct Parsed {
        header: Vec<String>,
        vertices: Vec<[f32; 3]>,
        faces: Vec<([u32; 3], u32)>,
    }

    fn parse(bytes: &[u8]) -> Parsed {
        let end = bytes.windows(11).position(|w| w == b"end_header\n").expect("end_header") + 11;
        let text = std::str::from_utf8(&bytes[..end]).unwrap();
        let header: Vec<String> = text.lines().map(str::to_string).collect();
        let count = |el: &str| -> usize {
            let l = header.iter().find(|l| l.starts_with(&format!("element {el} "))).unwrap();
            l.split_whitespace().nth(2).unwrap().parse().unwrap()
        };
        let (nv, nf) = (count("vertex"), count("face"));
        assert_eq!(bytes.len(), end + nv * VERTEX_BYTES + nf * FACE_BYTES, "file size");
        let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
        let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
        let vertices =
            (0..nv).map(|i| end + i * 12).map(|o| [f32_at(o), f32_at(o + 4), f32_at(o + 8)]).collect();
        let fstart = end + nv * VERTEX_BYTES;
        let faces = (0..nf)
            .map(|i| fstart + i * FACE_BYTES)
            .map(|o| {
                assert_eq!(bytes[o], 3, "list count");
                ([u32_at(o + 1), u32_at(o + 5), u32_at(o + 9)], u32_at(o + 13))
            })
            .collect();
        Parsed { header, vertices, faces }
    }

    fn write(name: &str) -> (tempfile::TempDir, Vec<u8>) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        let mut w = create_writer(&p).unwrap();
        test_scene::stream(&mut *w).unwrap();
        let s = w.finish().unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(s.bytes, bytes.len() as u64);
        (dir, bytes)
    }

    fn gunzip(bytes: &[u8]) -> Vec<u8> {
        use std::io::Read;
        let mut out = Vec::new();
        flate2::read::GzDecoder::new(bytes).read_to_end(&mut out).unwrap();
        out
    }

    #[test]
    fn header_declares_exact_counts_and_standard_properties() {
        let (_d, bytes) = write("a.ply");
        let p = parse(&bytes);
        assert_eq!(p.header[0], "ply");
        assert_eq!(p.header[1], "format binary_little_endian 1.0");
        assert!(p.header.contains(&"element vertex 13".to_string()), "{:?}", p.header);
        assert!(p.header.contains(&"element face 5".to_string()), "{:?}", p.header);
        assert!(p.header.contains(&"property list uchar uint vertex_indices".to_string()));
        assert_eq!(p.header.last().unwrap(), "end_header");
    }

    #[test]
    fn header_keeps_its_reserved_length() {
        let (_d, bytes) = write("a.ply");
        let end = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        assert_eq!(end, reserved_header_len());
        for (v, f) in [(0, 0), (1, 1), (123456789, 987654321), (u64::MAX, 0)] {
            assert_eq!(header(v, f, reserved_header_len()).len(), reserved_header_len());
        }
    }

    #[test]
    fn indexed_chunks_keep_indices_and_triangles_get_three_vertices() {
        let (_d, bytes) = write("a.ply");
        let p = parse(&bytes);
        assert_eq!(p.vertices.len(), 13);
        assert_eq!(p.vertices[2], [1.0, 1.0, 0.0]);
        assert_eq!(p.vertices[4], [2.0, 0.0, 0.0]);
        assert_eq!(p.vertices[12], [-1.0, -2.0, -1.25]);
        assert_eq!(
            p.faces,
            vec![([0, 1, 2], 0), ([0, 2, 3], 0), ([4, 5, 6], 1), ([7, 8, 9], 1), ([10, 11, 12], 0)]
        );
    }

    #[test]
    fn gzip_output_decompresses_to_the_plain_file() {
        let (_d, plain) = write("a.ply");
        let (_e, gz) = write("a.ply.gz");
        assert_eq!(&gz[..2], &[0x1f, 0x8b]);
        assert_eq!(gunzip(&gz), plain);
    }

    #[test]
    fn empty_scene_is_a_valid_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("e.ply");
        create_writer(&path).unwrap().finish().unwrap();
        let p = parse(&std::fs::read(&path).unwrap());
        assert!(p.header.contains(&"element vertex 0".to_string()));
        assert!(p.vertices.is_empty() && p.faces.is_empty());
    }

    #[test]
    fn object_ids_read_back_densely_in_order_of_first_appearance() {
        // Objects 0..3 announced; triangles only in 2, 0, 2 (1 is empty): the file holds the ids
        // 2, 0, 2, which the importer numbers 0, 1, 0.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("objs.ply");
        let mut w = create_writer(&path).unwrap();
        for id in 0..3 {
            w.object(id, &ObjectInfo { name: format!("n{id}"), color: None }).unwrap();
        }
        w.triangle(&Triangle::new(test_scene::T1, 2)).unwrap();
        w.mesh(&MeshChunk { object: 0, positions: &test_scene::QUAD, indices: &test_scene::QUAD_INDICES })
            .unwrap();
        w.triangle(&Triangle::new(test_scene::T2, 2)).unwrap();
        assert_eq!(w.finish().unwrap().objects, 3);
        let p = parse(&std::fs::read(&path).unwrap());
        let file_ids: Vec<u32> = p.faces.iter().map(|f| f.1).collect();
        assert_eq!(file_ids, vec![2, 0, 0, 2]);

        #[derive(Default)]
        struct Got(Vec<(ObjectId, String)>, Vec<ObjectId>);
        impl TriangleSink for Got {
            fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
                self.0.push((id, info.name.clone()));
                Ok(())
            }
            fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
                self.1.push(t.object);
                Ok(())
            }
        }
        let mut got = Got::default();
        let source = crate::open_source(&path, &crate::format::ImportOptions::default()).unwrap();
        assert_eq!(source.stream(&mut got).unwrap().objects, 2);
        assert_eq!(got.0, vec![(0, "objs/2".to_string()), (1, "objs/0".to_string())]);
        assert_eq!(got.1, vec![0, 1, 1, 0]);
    }

    #[test]
    fn too_many_vertices_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = PlyWriter::create(&dir.path().join("a.ply"), false).unwrap();
        w.vertices = u32::MAX as u64 - 1;
        w.object(0, &ObjectInfo::default()).unwrap();
        let e = w.triangle(&Triangle::new(test_scene::T1, 0)).unwrap_err();
        assert!(e.to_string().contains("2^32 vertices"), "{e}");
    }
}
