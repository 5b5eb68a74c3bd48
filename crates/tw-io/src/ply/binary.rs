//! Binary bodies, the general way: every record of an element is delimited (at a constant size
//! when it has no lists, measured otherwise) and decoded in place from the read buffer. Faces
//! whose records are all triangles go through [`super::runs`] instead.

use std::path::Path;

use super::faces::{Faces, Objects};
use super::header::{Element, FaceLayout, PropKind, Property, Role, VertexLayout};
use super::reader::ByteReader;
use super::runs::TriangleRecord;
use super::scalar::{u32_at, Scalar};
use super::vertices::{VertexValues, Vertices};
use super::{Body, RecordError, MAX_LIST, MAX_SKIPPED_LIST};
use crate::error::{ImportError, Position};
use crate::{ObjectId, TriangleSink};

/// Offsets of the properties of a record made of scalars only, and its size; `None` when the
/// element has lists.
fn fixed_layout(props: &[Property], offsets: &mut [usize]) -> Option<usize> {
    let mut at = 0;
    for (p, o) in props.iter().zip(offsets.iter_mut()) {
        let PropKind::Scalar(t) = p.kind else { return None };
        *o = at;
        at += t.size();
    }
    Some(at)
}

/// Walks the binary record at the start of `bytes`: fills `offsets` with each property's offset
/// (a list's is that of its count) and returns the record's length, or `None` when `bytes` does
/// not hold all of it.
#[inline]
pub(super) fn measure(
    props: &[Property],
    bytes: &[u8],
    big: bool,
    list_cap: i64,
    offsets: &mut [usize],
) -> Result<Option<usize>, String> {
    let mut at = 0usize;
    for (p, o) in props.iter().zip(offsets.iter_mut()) {
        *o = at;
        match p.kind {
            PropKind::Scalar(t) => at += t.size(),
            PropKind::List { count, item } => {
                if bytes.len() < at + count.size() {
                    return Ok(None);
                }
                let n = count.i64(&bytes[at..], big);
                if n < 0 {
                    return Err(format!("list {} has a negative length {n}", p.name));
                }
                if n > list_cap {
                    return Err(format!("list {} has {n} items (at most {list_cap} are supported)", p.name));
                }
                at += count.size() + n as usize * item.size();
            }
        }
    }
    Ok((bytes.len() >= at).then_some(at))
}

impl Body<'_> {
    /// Calls `each` with every record of a binary element, decoded in place from the buffer.
    #[inline]
    fn binary_records(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        list_cap: i64,
        sink: &mut dyn TriangleSink,
        mut each: impl FnMut(&[u8], &[usize], u64, &mut dyn TriangleSink) -> Result<(), RecordError>,
    ) -> Result<(), ImportError> {
        let path = self.path;
        let mut offsets = vec![0usize; el.props.len()];
        let fixed = fixed_layout(&el.props, &mut offsets);
        let mut index = 0u64;
        while index < el.count {
            let start = rd.position();
            let avail = rd.available();
            let mut used = 0usize;
            while index < el.count {
                let rest = &avail[used..];
                let len = match fixed {
                    Some(size) if rest.len() >= size => size,
                    Some(_) => break,
                    None => match measure(&el.props, rest, self.big, list_cap, &mut offsets) {
                        Ok(Some(len)) => len,
                        Ok(None) => break,
                        Err(msg) => {
                            let pos = Position::Byte(start + used as u64);
                            return Err(RecordError::Bad(msg).at(path, pos, &el.name, index));
                        }
                    },
                };
                if let Err(e) = each(&rest[..len], &offsets, index, sink) {
                    return Err(e.at(path, Position::Byte(start + used as u64), &el.name, index));
                }
                used += len;
                index += 1;
            }
            rd.consume(used);
            if index < el.count {
                let got =
                    rd.fill_more().map_err(|e| ImportError::io(path, Position::Byte(rd.position()), e))?;
                if got == 0 {
                    return Err(truncated(path, rd, el, index));
                }
            }
            if rd.take_refilled() {
                sink.progress(self.counter.get());
            }
        }
        Ok(())
    }

    /// Reads the vertex element into `out`.
    pub(super) fn binary_vertices(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &VertexLayout,
        out: &mut Vertices,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        let big = self.big;
        // The usual layout, `float x y z` (little endian) and nothing else read: without the
        // dispatch on roles and types.
        if let ([(px, Role::X, Scalar::F32), (py, Role::Y, Scalar::F32), (pz, Role::Z, Scalar::F32)], false) =
            (layout.fields.as_slice(), big)
        {
            let (px, py, pz) = (*px, *py, *pz);
            let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64;
            return self.binary_records(rd, el, MAX_LIST, sink, |rec, offsets, _, _| {
                let pos = [f(&rec[offsets[px]..]), f(&rec[offsets[py]..]), f(&rec[offsets[pz]..])];
                let mut v = VertexValues { pos, ..VertexValues::NEW };
                v.check()?;
                out.push(&v)?;
                Ok(())
            });
        }
        self.binary_records(rd, el, MAX_LIST, sink, |rec, offsets, _, _| {
            let mut v = VertexValues::NEW;
            for &(p, role, ty) in &layout.fields {
                v.set(role, ty, ty.f64(&rec[offsets[p]..], big));
            }
            v.check()?;
            out.push(&v)?;
            Ok(())
        })
    }

    /// Reads the face element and streams its triangles: in runs when every record is a
    /// triangle of one size ([`TriangleRecord`]), else record by record.
    pub(super) fn binary_faces(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &FaceLayout,
        v: &mut Vertices,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        if let Some(rec) = TriangleRecord::of(el, layout) {
            return self.binary_triangles(rd, el, layout, rec, v, sink);
        }
        let big = self.big;
        let mut objects = self.objects.take();
        // Two instances of the record loop, so that files without objects pay nothing for them.
        // `measure` delimited the record, so the scalar at `offsets[p]` lies within it.
        let result = match (&mut objects, layout.object) {
            // As terawalk writes it: a loop without a dispatch on the type.
            (Some(objects), Some((p, Scalar::U32))) if !big => {
                self.binary_faces_with(rd, el, layout, v, sink, |rec, offsets, sink| {
                    objects.id(u32_at(&rec[offsets[p]..], false) as i64, sink)
                })
            }
            (Some(objects), Some((p, ty))) => {
                self.binary_faces_with(rd, el, layout, v, sink, |rec, offsets, sink| {
                    objects.id(ty.i64(&rec[offsets[p]..], big), sink)
                })
            }
            _ => self.binary_faces_with(rd, el, layout, v, sink, |_, _, _| Ok(0)),
        };
        self.objects = objects;
        result
    }

    /// Reads binary faces; `object_of` gives the object of a face that has triangles.
    #[inline]
    fn binary_faces_with(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &FaceLayout,
        v: &mut Vertices,
        sink: &mut dyn TriangleSink,
        mut object_of: impl FnMut(&[u8], &[usize], &mut dyn TriangleSink) -> Result<ObjectId, RecordError>,
    ) -> Result<(), ImportError> {
        let big = self.big;
        let mut faces = std::mem::replace(&mut self.faces, Faces { indices: Vec::new(), short: 0 });
        let n_vertices = v.len();
        let (csize, isize_) = (layout.count.size(), layout.item.size());
        let result = self.binary_records(rd, el, MAX_LIST, sink, |rec, offsets, _, sink| {
            let at = offsets[layout.prop];
            // `measure` checked the count and that the items are in `rec`.
            let n = layout.count.i64(&rec[at..], big) as usize;
            let items = &rec[at + csize..at + csize + n * isize_];
            faces.indices.clear();
            for item in items.chunks_exact(isize_) {
                faces.add(layout.item.i64(item, big), n_vertices)?;
            }
            let object = if faces.indices.len() >= 3 { object_of(rec, offsets, sink)? } else { 0 };
            faces.emit(v, object, sink)
        });
        self.faces = faces;
        result
    }

    /// Skips an element we do not use: in one jump when its records have a fixed size, else
    /// record by record (lists must be measured to find where a record ends).
    pub(super) fn binary_skip(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        let mut offsets = vec![0usize; el.props.len()];
        if let Some(size) = fixed_layout(&el.props, &mut offsets) {
            let bytes = el.count.saturating_mul(size as u64);
            let skipped =
                rd.skip(bytes).map_err(|e| ImportError::io(self.path, Position::Byte(rd.position()), e))?;
            if skipped < bytes {
                return Err(truncated(self.path, rd, el, skipped / size as u64));
            }
            sink.progress(self.counter.get());
            return Ok(());
        }
        self.binary_records(rd, el, MAX_SKIPPED_LIST, sink, |_, _, _, _| Ok(()))
    }
}

/// Reads one binary face record the general way (any list length) and streams its triangles.
#[allow(clippy::too_many_arguments)]
pub(super) fn face_record(
    rec: &[u8],
    offsets: &[usize],
    layout: &FaceLayout,
    big: bool,
    faces: &mut Faces,
    v: &mut Vertices,
    objects: &mut Option<Objects>,
    sink: &mut dyn TriangleSink,
) -> Result<(), RecordError> {
    let at = offsets[layout.prop];
    // `measure` checked the count and that the items are in `rec`.
    let n = layout.count.i64(&rec[at..], big) as usize;
    let (csize, isize_) = (layout.count.size(), layout.item.size());
    let items = &rec[at + csize..at + csize + n * isize_];
    faces.indices.clear();
    let n_vertices = v.len();
    for item in items.chunks_exact(isize_) {
        faces.add(layout.item.i64(item, big), n_vertices)?;
    }
    let object = match (objects.as_mut(), layout.object) {
        (Some(objects), Some((p, ty))) if faces.indices.len() >= 3 => {
            objects.id(ty.i64(&rec[offsets[p]..], big), sink)?
        }
        _ => 0,
    };
    faces.emit(v, object, sink)
}

pub(super) fn truncated(path: &Path, rd: &ByteReader, el: &Element, index: u64) -> ImportError {
    let end = rd.position() + rd.available().len() as u64;
    ImportError::parse(
        path,
        Position::Byte(end),
        format!("the file is truncated: it ends in {} {index} of {}", el.name, el.count),
    )
}

#[cfg(test)]
mod tests {
    use crate::error::Position;

    use super::super::test_util::*;

    #[test]
    fn truncated_binary_body_plain_is_found_at_open() {
        let mut bytes = square("binary_little_endian");
        bytes.truncate(bytes.len() - 3);
        assert_err(&err("t.ply", &bytes), Position::Byte(bytes.len() as u64), "truncated");
    }

    #[test]
    fn truncated_binary_body_gzip_is_found_while_streaming() {
        for cut in [3, 20, 60] {
            let mut bytes = square("binary_big_endian");
            bytes.truncate(bytes.len() - cut);
            let e = err("t.ply.gz", &gz(&bytes));
            assert_err(&e, Position::Byte(bytes.len() as u64), "the file is truncated");
        }
    }

    #[test]
    fn absurd_vertex_count_does_not_allocate() {
        let header = "ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\n\
                      property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
                      end_header\n";
        let mut bytes = header.as_bytes().to_vec();
        bytes.extend_from_slice(&[0; 100]);
        assert_err(&err("a.ply", &bytes), Position::Byte(bytes.len() as u64), "truncated");
        // Compressed: the size is unknown, found lazily.
        let e = err("a.ply.gz", &gz(&bytes));
        assert_err(&e, Position::Byte(bytes.len() as u64), "ends in vertex 8 of 99999999999");
        let text = "ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\n\
                    property float z\nend_header\n1 2 3\n";
        assert_err(&err("a.ply", text.as_bytes()), Position::Line(9), "ends before vertex 1");
        let text = "ply\nformat ascii 1.0\nelement vertex -5\nend_header\n";
        assert_err(&err("a.ply", text.as_bytes()), Position::Line(3), "invalid count");
    }

    #[test]
    fn absurd_list_count() {
        let header =
            "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                      property float z\nelement face 1\nproperty list uint int vertex_indices\nend_header\n";
        let mut w = W::new(header, false);
        for _ in 0..9 {
            w.f32(0.0);
        }
        let face_at = w.out.len() as u64;
        w.u32(4_000_000_000).i32(0).i32(1).i32(2);
        assert_err(&err("l.ply", &w.out), Position::Byte(face_at), "4000000000 items (at most 65536");
        let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 1\nproperty list uint int vertex_indices\nend_header\n0 0 0\n4000000000 0 0 0\n";
        assert_err(&err("l.ply", text.as_bytes()), Position::Line(11), "at most 65536");
        let text = text.replace("4000000000", "-3");
        assert_err(&err("l.ply", text.as_bytes()), Position::Line(11), "negative length");
    }

    #[test]
    fn index_out_of_range_or_negative() {
        for (bad, what) in [(4i32, "index 4 out of range"), (-1, "index -1 out of range")] {
            let mut bytes = square("binary_little_endian");
            let n = bytes.len();
            bytes[n - 4..].copy_from_slice(&bad.to_le_bytes());
            let face1 = (n - 13) as u64;
            assert_err(&err("r.ply", &bytes), Position::Byte(face1), &format!("face 1: vertex {what}"));
            let text =
                String::from_utf8(square("ascii")).unwrap().replace("3 3 2 1", &format!("3 3 2 {bad}"));
            assert_err(&err("r.ply", text.as_bytes()), Position::Line(17), what);
        }
    }

    #[test]
    fn trailing_data_is_tolerated() {
        let mut bytes = square("binary_little_endian");
        bytes.extend_from_slice(b"trailing junk");
        let (c, _) = run("t.ply", &bytes).unwrap();
        assert_eq!(c.tris.len(), 3);
    }
}
