//! Runs of binary triangle records: faces whose records all hold one triangle (what terawalk
//! writes, and most large scans) are checked in order, a run at a time, and handed to the sink
//! as one [`TriangleBatch`] that it may resolve on several threads. Any other record is read the
//! general way in between (see [`super::binary`]); the triangles, their order, the objects and the
//! errors are the same either way.

use std::ops::Range;

use super::binary::{face_record, measure, truncated};
use super::faces::{Faces, Objects};
use super::header::{Element, FaceLayout, PropKind};
use super::reader::ByteReader;
use super::scalar::Scalar;
use super::vertices::{Corner, Vertices};
use super::{Body, RecordError, MAX_LIST};
use crate::error::{ImportError, Position};
use crate::vertex_store::BLOCK_SHIFT;
use crate::{NewObject, ObjectId, Triangle, TriangleBatch, TriangleSink};

/// Most faces in one [`TriangleRun`] (its memory, and the sink's for the batch, are bounded
/// by it whatever the buffer holds).
const MAX_RUN: usize = 1 << 17;

/// The layout of a binary face record that holds one triangle: every property a scalar except
/// the index list, whose count is 3. Such records all have the same size, so a run of them can
/// be delimited without reading them one by one (see [`Body::binary_triangles`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct TriangleRecord {
    size: usize,
    /// Offset of the index list's count, and of the three indices that follow it.
    count_at: usize,
    items_at: usize,
    /// Offset and type of the object id, when the faces have one.
    object: Option<(usize, Scalar)>,
}

impl TriangleRecord {
    /// The layout, when the face element has no list besides the indices.
    pub(super) fn of(el: &Element, layout: &FaceLayout) -> Option<TriangleRecord> {
        let (mut at, mut count_at, mut items_at, mut object) = (0, None, 0, None);
        for (pi, p) in el.props.iter().enumerate() {
            match p.kind {
                PropKind::Scalar(t) => {
                    if layout.object.is_some_and(|(op, _)| op == pi) {
                        object = Some((at, t));
                    }
                    at += t.size();
                }
                PropKind::List { count, item } if pi == layout.prop => {
                    count_at = Some(at);
                    items_at = at + count.size();
                    at = items_at + 3 * item.size();
                }
                PropKind::List { .. } => return None,
            }
        }
        Some(TriangleRecord { size: at, count_at: count_at?, items_at, object })
    }
}

/// A run of triangle records being handed to the sink as one [`TriangleBatch`]: the faces'
/// vertex indices (checked) and objects, and the objects they announce. Reused across runs.
#[derive(Default)]
struct TriangleRun {
    corners: Vec<[u64; 3]>,
    /// Dense object ids, one per face; empty when the file is one object (id 0).
    objects: Vec<ObjectId>,
    new_objects: Vec<NewObject>,
    /// Vertex blocks touched by the run: `stamp[b] == run` for those.
    stamp: Vec<u32>,
    run: u32,
    touched: usize,
}

/// Why [`Body::scan_run`] stopped.
enum RunEnd {
    /// At the end of the buffered records (or of the element).
    Window,
    /// The next record would touch more vertex blocks than stay resident together.
    Full,
    /// The next record is not a triangle (its count is not 3).
    NotTriangle,
    /// The next record is broken.
    Bad(RecordError),
}

/// The batch of a [`TriangleRun`]: triangles resolved from the touched vertex blocks, through
/// shared references, on whichever threads the sink uses.
struct RunBatch<'a> {
    run: &'a TriangleRun,
    vertices: &'a Vertices,
}

impl TriangleBatch for RunBatch<'_> {
    fn len(&self) -> usize {
        self.run.corners.len()
    }

    fn triangles(&self, range: Range<usize>, out: &mut Vec<Triangle>) -> Result<(), ImportError> {
        let objects = self.run.objects.get(range.clone());
        for (k, corners) in self.run.corners[range].iter().enumerate() {
            let [a, b, c] = corners.map(|v| self.vertices.corner_resident(v));
            out.push(Corner::triangle([&a, &b, &c], objects.map_or(0, |o| o[k])));
        }
        Ok(())
    }

    fn new_objects(&self) -> &[NewObject] {
        &self.run.new_objects
    }
}

impl Body<'_> {
    /// Reads binary faces whose records are triangles of one size ([`TriangleRecord`]): runs of
    /// them are checked here, in order, and handed to the sink as [`TriangleBatch`]es, which
    /// it may resolve on several threads; any other record (a polygon, a short face, one that
    /// needs more vertex blocks than stay resident together) is read the general way. The
    /// triangles, their order, the objects and the errors are those of the general path.
    pub(super) fn binary_triangles(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &FaceLayout,
        rec: TriangleRecord,
        v: &mut Vertices,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        let (path, big) = (self.path, self.big);
        let mut faces = std::mem::replace(&mut self.faces, Faces { indices: Vec::new(), short: 0 });
        let mut objects = self.objects.take();
        let mut run =
            TriangleRun { stamp: vec![0; v.len().div_ceil(1 << BLOCK_SHIFT) as usize], ..Default::default() };
        let mut offsets = vec![0usize; el.props.len()];
        let mut index = 0u64;
        let result = (|| -> Result<(), ImportError> {
            while index < el.count {
                let start = rd.position();
                let records =
                    ((rd.available().len() / rec.size).min(MAX_RUN) as u64).min(el.count - index) as usize;
                let end = scan_run(
                    &rd.available()[..records * rec.size],
                    rec,
                    layout,
                    big,
                    &mut run,
                    v,
                    &mut objects,
                );
                let n = run.corners.len();
                if n > 0 {
                    sink.batch(&RunBatch { run: &run, vertices: v })?;
                    rd.consume(n * rec.size);
                    index += n as u64;
                }
                let one_record = match end {
                    RunEnd::Window if index < el.count => {
                        // At the end of the file the bytes left are fewer than a triangle's
                        // record, but may still hold a shorter record (a face of fewer than 3
                        // vertices, skipped like in ASCII): the general way reads it, or says
                        // the file is truncated.
                        rd.fill_more().map_err(|e| ImportError::io(path, Position::Byte(rd.position()), e))?
                            == 0
                    }
                    RunEnd::Window => false,
                    RunEnd::Full if n > 0 => false,
                    RunEnd::Full | RunEnd::NotTriangle => true,
                    RunEnd::Bad(e) => {
                        return Err(e.at(
                            path,
                            Position::Byte(start + (n * rec.size) as u64),
                            &el.name,
                            index,
                        ))
                    }
                };
                if one_record {
                    // One record the general way.
                    let at = rd.position();
                    let len = loop {
                        match measure(&el.props, rd.available(), big, MAX_LIST, &mut offsets) {
                            Ok(Some(len)) => break len,
                            Ok(None) => {
                                let got = rd
                                    .fill_more()
                                    .map_err(|e| ImportError::io(path, Position::Byte(rd.position()), e))?;
                                if got == 0 {
                                    return Err(truncated(path, rd, el, index));
                                }
                            }
                            Err(msg) => {
                                return Err(RecordError::Bad(msg).at(
                                    path,
                                    Position::Byte(at),
                                    &el.name,
                                    index,
                                ))
                            }
                        }
                    };
                    let record = &rd.available()[..len];
                    let r = face_record(record, &offsets, layout, big, &mut faces, v, &mut objects, sink);
                    if let Err(e) = r {
                        return Err(e.at(path, Position::Byte(at), &el.name, index));
                    }
                    rd.consume(len);
                    index += 1;
                }
                if rd.take_refilled() {
                    sink.progress(self.counter.get());
                }
            }
            Ok(())
        })();
        self.faces = faces;
        self.objects = objects;
        result
    }
}

/// Collects into `run` the triangle records at the start of `bytes` (whole records) that can go
/// to the sink as one batch: checks their counts and indices, touches the vertex blocks they
/// use, resolves their objects. Stops at the first record that cannot join the run, and says why.
#[allow(clippy::too_many_arguments)]
fn scan_run(
    bytes: &[u8],
    rec: TriangleRecord,
    layout: &FaceLayout,
    big: bool,
    run: &mut TriangleRun,
    v: &mut Vertices,
    objects: &mut Option<Objects>,
) -> RunEnd {
    let le32 = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    // The usual layout (terawalk's, and most scanners'), without a dispatch on the types.
    match (layout.count, layout.item, big) {
        (Scalar::U8, Scalar::U32, false) => {
            scan_run_with(bytes, rec, big, run, v, objects, |b| b[0] as i64, 4, |b| le32(b) as i64)
        }
        (Scalar::U8, Scalar::I32, false) => {
            scan_run_with(bytes, rec, big, run, v, objects, |b| b[0] as i64, 4, |b| le32(b) as i32 as i64)
        }
        (count, item, _) => scan_run_with(
            bytes,
            rec,
            big,
            run,
            v,
            objects,
            |b| count.i64(b, big),
            item.size(),
            |b| item.i64(b, big),
        ),
    }
}

/// [`scan_run`] with the readers of the list count and of an index (`isz` bytes).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn scan_run_with(
    bytes: &[u8],
    rec: TriangleRecord,
    big: bool,
    run: &mut TriangleRun,
    v: &mut Vertices,
    objects: &mut Option<Objects>,
    count: impl Fn(&[u8]) -> i64,
    isz: usize,
    item: impl Fn(&[u8]) -> i64,
) -> RunEnd {
    run.corners.clear();
    run.objects.clear();
    run.new_objects.clear();
    run.run = run.run.wrapping_add(1);
    if run.run == 0 {
        run.stamp.fill(0);
        run.run = 1;
    }
    run.touched = 0;
    let touchable = v.touchable_blocks();
    let n_vertices = v.len();
    for r in bytes.chunks_exact(rec.size) {
        if count(&r[rec.count_at..]) != 3 {
            return RunEnd::NotTriangle;
        }
        let mut corner = [0u64; 3];
        for (k, c) in corner.iter_mut().enumerate() {
            let i = item(&r[rec.items_at + k * isz..]);
            if i < 0 || i as u64 >= n_vertices {
                return RunEnd::Bad(RecordError::Bad(format!(
                    "vertex index {i} out of range (the file has {n_vertices} vertices)"
                )));
            }
            *c = i as u64;
        }
        // The blocks this face adds to the run, all of them or none.
        let blocks = corner.map(|c| (c >> BLOCK_SHIFT) as usize);
        let mut new = 0;
        for (k, &b) in blocks.iter().enumerate() {
            if run.stamp[b] != run.run && !blocks[..k].contains(&b) {
                new += 1;
            }
        }
        if new > 0 {
            if run.touched + new > touchable {
                return RunEnd::Full;
            }
            for b in blocks {
                if run.stamp[b] != run.run {
                    if let Err(e) = v.touch(b) {
                        return RunEnd::Bad(RecordError::Io(e));
                    }
                    run.stamp[b] = run.run;
                    run.touched += 1;
                }
            }
        }
        if let (Some(objects), Some((at, ty))) = (objects.as_mut(), rec.object) {
            match objects.resolve(ty.i64(&r[at..], big)) {
                Ok((id, new)) => {
                    if let Some(info) = new {
                        run.new_objects.push(NewObject { first: run.corners.len(), id, info });
                    }
                    run.objects.push(id);
                }
                Err(e) => return RunEnd::Bad(e),
            }
        }
        run.corners.push(corner);
    }
    RunEnd::Window
}

#[cfg(test)]
mod tests {
    use crate::error::{ImportError, Position};
    use crate::format::ImportOptions;
    use crate::input::Input;
    use crate::ply::open;
    use crate::{ObjectInfo, SourceSummary, Triangle, TriangleBatch, TriangleSink};

    use super::super::test_util::*;

    /// Regression: a binary file whose last face has fewer than 3 vertices was called truncated
    /// (its record is shorter than a triangle's), while ASCII skips such a face. Every encoding
    /// now gives the same triangles; a record that really is cut short is still an error.
    #[test]
    fn short_last_face_is_skipped_in_every_encoding() {
        for k in 0..3u8 {
            let header = |enc: &str| {
                format!(
                    "ply\nformat {enc} 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                     property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
                )
            };
            let mut text = header("ascii");
            for v in SQUARE {
                text += &format!("{} {} {}\n", v[0], v[1], v[2]);
            }
            text += "3 0 1 2\n";
            text += &format!("{k}{}\n", (0..k).map(|i| format!(" {i}")).collect::<String>());
            let (ascii, _) = run("short.ply", text.as_bytes()).unwrap();
            assert_eq!(ascii.tris.len(), 1);
            for enc in ["binary_little_endian", "binary_big_endian"] {
                let mut w = W::new(&header(enc), enc == "binary_big_endian");
                for v in SQUARE {
                    w.f32(v[0]).f32(v[1]).f32(v[2]);
                }
                w.u8(3).i32(0).i32(1).i32(2);
                w.u8(k);
                for i in 0..k {
                    w.i32(i as i32);
                }
                let (c, _) = run("short.ply", &w.out).unwrap_or_else(|e| panic!("{enc}, {k} vertices: {e}"));
                assert_eq!(positions(&c), positions(&ascii), "{enc}, {k} vertices");
                // The same face cut short (its count says 3) is truncated.
                let mut cut = W::new(&header(enc), enc == "binary_big_endian");
                for v in SQUARE {
                    cut.f32(v[0]).f32(v[1]).f32(v[2]);
                }
                cut.u8(3).i32(0).i32(1).i32(2);
                cut.u8(3).i32(0).i32(1);
                let e = run("cut.ply", &cut.out).err().unwrap().to_string();
                assert!(e.contains("truncated"), "{enc}: {e}");
            }
        }
    }

    /// A mesh of `n` vertices and mostly triangular faces in `encoding`, with a scalar before
    /// the index list and the object after it: a quad, short faces, far references and object
    /// changes sprinkled in. Face `bad_at` (if any) gets the list `bad_list` instead.
    fn mixed(encoding: &str, n: u32, faces: u32, count_ty: &str, bad: Option<(u32, &[i64])>) -> Vec<u8> {
        let header = format!(
            "ply\nformat {encoding} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n\
             property float z\nelement face {faces}\nproperty uchar flags\n\
             property list {count_ty} int vertex_indices\nproperty int object\nend_header\n"
        );
        let list = |f: u32| -> Vec<i64> {
            if let Some((at, l)) = bad {
                if f == at {
                    return l.to_vec();
                }
            }
            let a = |k: u32| ((f + k) % n) as i64;
            match f % 997 {
                500 => vec![a(0), a(1), a(2), a(3)],
                600 => vec![a(0), a(1)],
                700 => vec![],
                // A vertex far behind: its spilled block is read back.
                _ if f.is_multiple_of(211) => vec![a(0), ((f * 7919) % n) as i64, a(2)],
                _ => vec![a(0), a(1), a(2)],
            }
        };
        let object = |f: u32| ((f / 37) % 5) as i32 - 2;
        if encoding == "ascii" {
            let mut t = header;
            for i in 0..n {
                t += &format!("{} {} {}\n", i, i % 13, (i * i) % 101);
            }
            for f in 0..faces {
                let l = list(f);
                let items: Vec<String> = l.iter().map(|i| i.to_string()).collect();
                t += &format!("9 {} {} {}\n", l.len(), items.join(" "), object(f));
            }
            return t.into_bytes();
        }
        let mut w = W::new(&header, encoding == "binary_big_endian");
        for i in 0..n {
            w.f32(i as f32).f32((i % 13) as f32).f32(((i * i) % 101) as f32);
        }
        for f in 0..faces {
            let l = list(f);
            w.u8(9);
            match count_ty {
                "uchar" => w.u8(l.len() as u8),
                _ => w.i32(l.len() as i32),
            };
            for i in l {
                w.i32(i as i32);
            }
            w.i32(object(f));
        }
        w.out
    }

    /// Objects and triangles in the order a sink saw them.
    #[derive(Default)]
    struct Seen(Vec<(Option<ObjectInfo>, Option<Triangle>)>);

    impl TriangleSink for Seen {
        fn object(&mut self, id: u32, info: &ObjectInfo) -> Result<(), ImportError> {
            assert_eq!(id as usize, self.0.iter().filter(|e| e.0.is_some()).count());
            self.0.push((Some(info.clone()), None));
            Ok(())
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.0.push((None, Some(*t)));
            Ok(())
        }
    }

    /// Streams `bytes` into a [`Seen`] and returns it with the result.
    fn seen(bytes: &[u8], vertex_memory: usize) -> (Seen, Result<SourceSummary, ImportError>) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        std::fs::write(&p, bytes).unwrap();
        let options = ImportOptions { vertex_memory, spill_dir: None };
        let mut sink = Seen::default();
        let r = open(Input::open(&p).unwrap(), &options).and_then(|s| s.stream(&mut sink));
        (sink, r)
    }

    #[test]
    fn triangle_runs_give_what_the_general_path_gives() {
        // ASCII goes the general way, record by record; binary in runs, with polygons, short
        // faces and (with no vertex memory) faces whose blocks are not resident in between.
        let (n, faces) = (30_000, 50_000);
        let (want, r) = seen(&mixed("ascii", n, faces, "uchar", None), 192 << 20);
        r.unwrap();
        assert_eq!(want.0.iter().filter(|e| e.1.is_some()).count(), 50_000 - 2 * 50 + 50);
        assert_eq!(want.0.iter().filter(|e| e.0.is_some()).count(), 5);
        for encoding in ["binary_little_endian", "binary_big_endian"] {
            for count_ty in ["uchar", "int"] {
                for memory in [0, 1 << 16, 192 << 20] {
                    let (got, r) = seen(&mixed(encoding, n, faces, count_ty, None), memory);
                    r.unwrap();
                    assert!(got.0 == want.0, "{encoding} {count_ty} {memory}");
                }
            }
        }
    }

    #[test]
    fn bad_index_in_a_run_names_its_face_after_streaming_the_ones_before() {
        let (n, faces) = (20_000, 30_000);
        for (at, list, text) in [
            (12_345u32, &[1i64, 20_000, 2][..], "face 12345: vertex index 20000 out of range"),
            (29_999, &[-1, 0, 1][..], "face 29999: vertex index -1 out of range"),
        ] {
            let bytes = mixed("binary_little_endian", n, faces, "uchar", Some((at, list)));
            let (sink, r) = seen(&bytes, 1 << 16);
            // Every face record before `at` is the same size but for the polygons and short ones.
            let ascii = mixed("ascii", n, at, "uchar", None);
            let (before, _) = seen(&ascii, 1 << 16);
            let header = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
            let record = |f: u32| {
                1 + 1
                    + 4 * (if f % 997 == 500 {
                        4
                    } else if f % 997 == 600 {
                        2
                    } else if f % 997 == 700 {
                        0
                    } else {
                        3
                    })
                    + 4
            };
            let offset = header as u64 + 12 * n as u64 + (0..at).map(|f| record(f) as u64).sum::<u64>();
            assert_err(&r.unwrap_err(), Position::Byte(offset), text);
            assert!(sink.0 == before.0, "the triangles before face {at} are streamed");
        }
    }

    #[test]
    fn bad_list_counts_mid_file_are_errors_at_their_face() {
        let (n, faces) = (5_000, 9_000);
        let header_and_vertices = |bytes: &[u8]| {
            bytes.windows(11).position(|w| w == b"end_header\n").unwrap() as u64 + 11 + 12 * n as u64
        };
        // `int` counts: a negative one and one beyond MAX_LIST, after a long run of triangles.
        let record = |f: u32| {
            1 + 4
                + 4 * (if f % 997 == 500 {
                    4
                } else if f % 997 == 600 {
                    2
                } else if f % 997 == 700 {
                    0
                } else {
                    3
                })
                + 4
        };
        for (count, text) in [(-1i64, "a negative length -1"), (70_000, "70000 items")] {
            let mut bytes = mixed("binary_little_endian", n, faces, "int", Some((8_000, &[0, 1, 2])));
            let at = header_and_vertices(&bytes) + (0..8_000).map(|f| record(f) as u64).sum::<u64>();
            bytes[at as usize + 1..at as usize + 5].copy_from_slice(&(count as i32).to_le_bytes());
            let (_, r) = seen(&bytes, 192 << 20);
            assert_err(
                &r.unwrap_err(),
                Position::Byte(at),
                &format!("face 8000: list vertex_indices has {text}"),
            );
        }
        // A count that runs past the end of the file in the last face.
        let mut bytes = mixed("binary_little_endian", n, faces, "uchar", None);
        let last = header_and_vertices(&bytes) + (0..faces - 1).map(|f| record(f) as u64 - 3).sum::<u64>();
        bytes[last as usize + 1] = 200;
        let (sink, r) = seen(&gz(&bytes), 192 << 20);
        let e = r.unwrap_err();
        assert!(e.to_string().contains("truncated: it ends in face 8999 of 9000"), "{e}");
        assert_eq!(sink.0.iter().filter(|e| e.1.is_some()).count(), 8_999 - 2 * 9 + 9);
    }

    /// A sink that fetches each batch's triangles backwards, in ranges of 7: the order of
    /// fetching must not matter.
    #[derive(Default)]
    struct Backwards(Seen);

    impl TriangleSink for Backwards {
        fn object(&mut self, id: u32, info: &ObjectInfo) -> Result<(), ImportError> {
            self.0.object(id, info)
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.0.triangle(t)
        }
        fn batch(&mut self, batch: &dyn TriangleBatch) -> Result<(), ImportError> {
            let mut parts = Vec::new();
            for end in (0..batch.len()).rev().step_by(7) {
                let mut out = Vec::new();
                batch.triangles(end.saturating_sub(6)..end + 1, &mut out)?;
                parts.push(out);
            }
            let tris: Vec<Triangle> = parts.into_iter().rev().flatten().collect();
            let mut new = batch.new_objects().iter().peekable();
            for (i, t) in tris.iter().enumerate() {
                while let Some(o) = new.next_if(|o| o.first == i) {
                    self.0.object(o.id, &o.info)?;
                }
                self.0.triangle(t)?;
            }
            Ok(())
        }
    }

    #[test]
    fn batches_can_be_fetched_in_any_order() {
        let bytes = mixed("binary_little_endian", 10_000, 20_000, "uchar", None);
        let (want, _) = seen(&bytes, 192 << 20);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        std::fs::write(&p, &bytes).unwrap();
        let mut sink = Backwards::default();
        open(Input::open(&p).unwrap(), &ImportOptions::default()).unwrap().stream(&mut sink).unwrap();
        assert!(sink.0 .0 == want.0);
    }
}
