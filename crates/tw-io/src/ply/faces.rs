//! Faces: the general path's polygon state ([`Faces`], fan-triangulated into the sink) and the
//! per-face object ids ([`Objects`]), mapped to dense ids in order of first appearance.

use std::collections::HashMap;

use super::vertices::{Corner, Vertices};
use super::RecordError;
use crate::{ObjectId, ObjectInfo, TriangleSink};

/// Reused state for faces.
pub(super) struct Faces {
    pub(super) indices: Vec<u64>,
    /// Faces of fewer than three vertices, skipped.
    pub(super) short: u64,
}

impl Faces {
    /// Checks and keeps one index.
    #[inline(always)]
    pub(super) fn add(&mut self, i: i64, vertices: u64) -> Result<(), RecordError> {
        if i < 0 || i as u64 >= vertices {
            return Err(RecordError::Bad(format!(
                "vertex index {i} out of range (the file has {vertices} vertices)"
            )));
        }
        self.indices.push(i as u64);
        Ok(())
    }

    /// Fan-triangulates the collected polygon into `sink`.
    #[inline]
    pub(super) fn emit(
        &mut self,
        v: &mut Vertices,
        object: ObjectId,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), RecordError> {
        let [first, second, rest @ ..] = self.indices.as_slice() else {
            self.short += 1;
            return Ok(());
        };
        if rest.is_empty() {
            self.short += 1;
            return Ok(());
        }
        let a = v.corner(*first)?;
        let mut b = v.corner(*second)?;
        for &i in rest {
            let c = v.corner(i)?;
            sink.triangle(&Corner::triangle([&a, &b, &c], object))?;
            b = c;
        }
        Ok(())
    }
}

/// Per-face object ids: the file's ids, mapped to dense ids in order of first appearance.
pub(super) struct Objects {
    /// Object name prefix: the file's name.
    stem: String,
    ids: HashMap<i64, ObjectId>,
    /// The last face's file id and dense id: consecutive faces mostly share their object.
    last: Option<(i64, ObjectId)>,
}

impl Objects {
    pub(super) fn new(stem: String) -> Objects {
        Objects { stem, ids: HashMap::new(), last: None }
    }

    /// Objects announced.
    pub(super) fn len(&self) -> u32 {
        self.ids.len() as u32
    }

    /// The dense id of file id `raw`, announcing it to `sink` when it is new.
    #[inline(always)]
    pub(super) fn id(&mut self, raw: i64, sink: &mut dyn TriangleSink) -> Result<ObjectId, RecordError> {
        match self.last {
            Some((r, id)) if r == raw => Ok(id),
            _ => self.lookup(raw, sink),
        }
    }

    #[cold]
    #[inline(never)]
    fn lookup(&mut self, raw: i64, sink: &mut dyn TriangleSink) -> Result<ObjectId, RecordError> {
        let (id, new) = self.resolve_new(raw)?;
        if let Some(info) = new {
            sink.object(id, &info)?;
        }
        Ok(id)
    }

    /// The dense id of file id `raw`, and the object's description when it is new (for the
    /// caller to announce before the object's first triangle).
    #[inline(always)]
    pub(super) fn resolve(&mut self, raw: i64) -> Result<(ObjectId, Option<ObjectInfo>), RecordError> {
        match self.last {
            Some((r, id)) if r == raw => Ok((id, None)),
            _ => self.resolve_new(raw),
        }
    }

    #[cold]
    #[inline(never)]
    fn resolve_new(&mut self, raw: i64) -> Result<(ObjectId, Option<ObjectInfo>), RecordError> {
        let (id, new) = match self.ids.get(&raw) {
            Some(&id) => (id, None),
            None => {
                let id = u32::try_from(self.ids.len())
                    .map_err(|_| RecordError::Bad("more than 2^32 objects".into()))?;
                self.ids.insert(raw, id);
                (id, Some(ObjectInfo { name: format!("{}/{raw}", self.stem), color: None }))
            }
        };
        self.last = Some((raw, id));
        Ok((id, new))
    }
}

#[cfg(test)]
mod tests {
    use crate::error::{ImportError, Position};
    use crate::format::ImportOptions;
    use crate::input::Input;
    use crate::ply::open;
    use crate::{ObjectInfo, Triangle, TriangleSink};

    use super::super::test_util::*;

    #[test]
    fn polygons_are_fanned_and_short_faces_skipped() {
        let text =
            "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 4\nproperty list uchar int vertex_indices\nend_header\n\
                    0 0 0\n1 0 0\n2 1 0\n1 2 0\n0 1 0\n5 0 1 2 3 4\n2 0 1\n0\n1 4\n";
        let (c, _) = run("fan.ply", text.as_bytes()).unwrap();
        let v = |i: usize| {
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 1.0, 0.0]][i]
        };
        assert_eq!(positions(&c), vec![[v(0), v(1), v(2)], [v(0), v(2), v(3)], [v(0), v(3), v(4)]]);
    }

    /// Four vertices and four triangles with the file object ids 7, 3, 7, 100, in `property uint
    /// object` after the indices (as terawalk's writer lays it out).
    fn with_objects(encoding: &str) -> Vec<u8> {
        let header = format!(
            "ply\nformat {encoding} 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
             property float z\nelement face 4\nproperty list uchar uint vertex_indices\n\
             property uint object\nend_header\n"
        );
        let faces = [([0u32, 1, 2], 7u32), ([0, 2, 3], 3), ([3, 2, 1], 7), ([1, 3, 0], 100)];
        if encoding == "ascii" {
            let mut s = header;
            for v in SQUARE {
                s += &format!("{} {} {}\n", v[0], v[1], v[2]);
            }
            for ([a, b, c], o) in faces {
                s += &format!("3 {a} {b} {c} {o}\n");
            }
            return s.into_bytes();
        }
        let mut w = W::new(&header, encoding == "binary_big_endian");
        for v in SQUARE {
            w.f32(v[0]).f32(v[1]).f32(v[2]);
        }
        for ([a, b, c], o) in faces {
            w.u8(3).u32(a).u32(b).u32(c).u32(o);
        }
        w.out
    }

    fn object_names(c: &Collect) -> Vec<(u32, String)> {
        c.objects.iter().map(|(id, info)| (*id, info.name.clone())).collect()
    }

    fn tri_objects(c: &Collect) -> Vec<u32> {
        c.tris.iter().map(|t| t.object).collect()
    }

    #[test]
    fn per_face_object_ids_become_dense_in_order_of_first_appearance() {
        for enc in ["ascii", "binary_little_endian", "binary_big_endian"] {
            for zipped in [false, true] {
                let bytes = if zipped { gz(&with_objects(enc)) } else { with_objects(enc) };
                let (c, s) = run("obj.ply", &bytes).unwrap_or_else(|e| panic!("{enc}: {e}"));
                let names =
                    vec![(0, "obj/7".to_string()), (1, "obj/3".to_string()), (2, "obj/100".to_string())];
                assert_eq!(object_names(&c), names, "{enc} gzip={zipped}");
                assert!(c.objects.iter().all(|(_, i)| i.color.is_none()));
                assert_eq!(tri_objects(&c), vec![0, 1, 0, 2], "{enc} gzip={zipped}");
                assert_eq!(s.objects, 3, "{enc} gzip={zipped}");
                let v = |i: usize| SQUARE[i].map(|c| c as f64);
                assert_eq!(c.tris[3].positions, [v(1), v(3), v(0)], "{enc}");
            }
        }
    }

    /// A sink that records the order of announcements and triangles.
    #[derive(Default)]
    struct Events(Vec<String>);

    impl TriangleSink for Events {
        fn object(&mut self, id: u32, _: &ObjectInfo) -> Result<(), ImportError> {
            self.0.push(format!("object {id}"));
            Ok(())
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.0.push(format!("triangle {}", t.object));
            Ok(())
        }
    }

    #[test]
    fn each_object_is_announced_just_before_its_first_triangle() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("o.ply");
        std::fs::write(&p, with_objects("binary_little_endian")).unwrap();
        let mut events = Events::default();
        open(Input::open(&p).unwrap(), &ImportOptions::default()).unwrap().stream(&mut events).unwrap();
        let want =
            ["object 0", "triangle 0", "object 1", "triangle 1", "triangle 0", "object 2", "triangle 2"];
        assert_eq!(events.0, want);
    }

    #[test]
    fn object_id_property_signed_and_before_the_indices() {
        // `object_id`, a signed type, before the list; a quad's two triangles share its object.
        let header =
            "ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                      property float z\nelement face 3\nproperty short object_id\n\
                      property list uchar int vertex_indices\nend_header\n";
        let mut w = W::new(header, true);
        for v in SQUARE {
            w.f32(v[0]).f32(v[1]).f32(v[2]);
        }
        w.i16(-1).u8(4).i32(0).i32(1).i32(2).i32(3);
        w.i16(5).u8(3).i32(3).i32(2).i32(1);
        w.i16(-1).u8(3).i32(0).i32(1).i32(3);
        let (c, s) = run("s.ply", &w.out).unwrap();
        assert_eq!(object_names(&c), vec![(0, "s/-1".to_string()), (1, "s/5".to_string())]);
        assert_eq!(tri_objects(&c), vec![0, 0, 1, 0]);
        assert_eq!(s.objects, 2);
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 2\nproperty int object_id\nproperty list uchar int vertex_indices\nend_header\n\
                    0 0 0\n1 0 0\n0 1 0\n-1 3 0 1 2\n42 3 2 1 0\n";
        let (c, _) = run("s.ply", text.as_bytes()).unwrap();
        assert_eq!(object_names(&c), vec![(0, "s/-1".to_string()), (1, "s/42".to_string())]);
        assert_eq!(tri_objects(&c), vec![0, 1]);
    }

    #[test]
    fn object_is_preferred_over_object_id() {
        let text =
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 1\nproperty int object_id\nproperty list uchar int vertex_indices\n\
                    property uchar object\nend_header\n0 0 0\n1 0 0\n0 1 0\n9 3 0 1 2 4\n";
        let (c, _) = run("p.ply", text.as_bytes()).unwrap();
        assert_eq!(object_names(&c), vec![(0, "p/4".to_string())]);
    }

    #[test]
    fn non_integer_object_property_is_ignored() {
        for (decl, a, b) in [("float object", "1.5", "2"), ("list uchar int object", "1 7", "2 8 9")] {
            let text = format!(
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                 element face 2\nproperty list uchar int vertex_indices\nproperty {decl}\nend_header\n\
                 0 0 0\n1 0 0\n0 1 0\n3 0 1 2 {a}\n3 2 1 0 {b}\n"
            );
            let (c, s) = run("f.ply", text.as_bytes()).unwrap();
            assert_eq!(object_names(&c), vec![(0, "f".to_string())], "{decl}");
            assert_eq!(tri_objects(&c), vec![0, 0]);
            assert_eq!(s.objects, 1);
        }
    }

    #[test]
    fn object_property_without_faces_keeps_the_file_object() {
        let text =
            "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
                    property float z\nelement face 0\nproperty list uchar int vertex_indices\n\
                    property uint object\nend_header\n";
        let (c, s) = run("e.ply", text.as_bytes()).unwrap();
        assert_eq!(object_names(&c), vec![(0, "e".to_string())]);
        assert_eq!(s.objects, 1);
    }

    #[test]
    fn short_faces_announce_no_object() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 3\nproperty list uchar int vertex_indices\nproperty uint object\nend_header\n\
                    0 0 0\n1 0 0\n0 1 0\n2 0 1 5\n3 0 1 2 9\n0 6\n";
        let (c, s) = run("s.ply", text.as_bytes()).unwrap();
        assert_eq!(object_names(&c), vec![(0, "s/9".to_string())]);
        assert_eq!(tri_objects(&c), vec![0]);
        assert_eq!(s.objects, 1);
    }

    #[test]
    fn many_objects_in_a_large_binary_file() {
        // Runs of faces per object, ids revisited out of order: the last-id cache and the map
        // must agree.
        let n = 50_000u32;
        let header = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nelement face {n}\nproperty list uchar int vertex_indices\n\
             property uint object\nend_header\n"
        );
        let mut w = W::new(&header, false);
        w.f32(0.0).f32(0.0).f32(0.0).f32(1.0).f32(0.0).f32(0.0).f32(0.0).f32(1.0).f32(0.0);
        let raw = |i: u32| ((i / 3) % 1000).wrapping_mul(2_654_435_761);
        for i in 0..n {
            w.u8(3).i32(0).i32(1).i32(2).u32(raw(i));
        }
        let (c, s) = run("m.ply", &w.out).unwrap();
        assert_eq!(s.objects, 1000);
        assert_eq!(c.objects.len(), 1000);
        for (i, t) in c.tris.iter().enumerate() {
            let name = &c.objects[t.object as usize].1.name;
            assert_eq!(*name, format!("m/{}", raw(i as u32)), "triangle {i}");
        }
    }

    #[test]
    fn bad_ascii_object_value() {
        let text = String::from_utf8(with_objects("ascii")).unwrap();
        let e = err("b.ply", text.replace("3 3 2 1 7", "3 3 2 1 seven").as_bytes());
        assert_err(&e, Position::Line(17), "face 2: invalid number \"seven\" for object");
        let e = err("b.ply", text.replace("3 3 2 1 7", "3 3 2 1").as_bytes());
        assert_err(&e, Position::Line(17), "fewer values than the header declares (no object)");
    }
}
