//! Fixtures shared by the tests of the PLY importer: a collecting sink, files written to a
//! temporary folder and streamed, and a writer of binary records in either byte order.

use std::io::Write;

use super::open;
use crate::error::{ImportError, Position};
use crate::format::ImportOptions;
use crate::input::Input;
use crate::{ObjectInfo, SourceSummary, Triangle, TriangleSink};

/// A sink that keeps everything.
#[derive(Default)]
pub(super) struct Collect {
    pub(super) objects: Vec<(u32, ObjectInfo)>,
    pub(super) tris: Vec<Triangle>,
    pub(super) progress_calls: u64,
}

impl TriangleSink for Collect {
    fn object(&mut self, id: u32, info: &ObjectInfo) -> Result<(), ImportError> {
        self.objects.push((id, info.clone()));
        Ok(())
    }
    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        assert!(!self.objects.is_empty(), "triangle before object");
        self.tris.push(*t);
        Ok(())
    }
    fn progress(&mut self, _done: u64) {
        self.progress_calls += 1;
    }
}

pub(super) fn gz(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(bytes).unwrap();
    enc.finish().unwrap()
}

pub(super) fn run_opts(
    name: &str,
    bytes: &[u8],
    options: &ImportOptions,
) -> Result<(Collect, SourceSummary), ImportError> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(name);
    std::fs::write(&p, bytes).unwrap();
    let source = open(Input::open(&p)?, options)?;
    let mut sink = Collect::default();
    let summary = source.stream(&mut sink)?;
    Ok((sink, summary))
}

pub(super) fn run(name: &str, bytes: &[u8]) -> Result<(Collect, SourceSummary), ImportError> {
    run_opts(name, bytes, &ImportOptions::default())
}

pub(super) fn err(name: &str, bytes: &[u8]) -> ImportError {
    match run(name, bytes) {
        Ok((c, _)) => panic!("expected an error, got {} triangles", c.tris.len()),
        Err(e) => e,
    }
}

pub(super) fn positions(c: &Collect) -> Vec<[[f64; 3]; 3]> {
    c.tris.iter().map(|t| t.positions).collect()
}

/// Binary writer for fixtures.
pub(super) struct W {
    pub(super) big: bool,
    pub(super) out: Vec<u8>,
}

impl W {
    pub(super) fn new(header: &str, big: bool) -> W {
        W { big, out: header.as_bytes().to_vec() }
    }
    pub(super) fn put(&mut self, le: &[u8], be: &[u8]) -> &mut Self {
        self.out.extend_from_slice(if self.big { be } else { le });
        self
    }
    pub(super) fn f32(&mut self, v: f32) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    pub(super) fn f64(&mut self, v: f64) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    pub(super) fn i32(&mut self, v: i32) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    pub(super) fn u32(&mut self, v: u32) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    pub(super) fn i16(&mut self, v: i16) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    pub(super) fn u16(&mut self, v: u16) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    pub(super) fn u8(&mut self, v: u8) -> &mut Self {
        self.out.push(v);
        self
    }
}

pub(super) const SQUARE: [[f32; 3]; 4] =
    [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.5, -2.25]];

/// A quad (fanned into two triangles) and a triangle, in the three encodings.
pub(super) fn square(encoding: &str) -> Vec<u8> {
    let header = format!(
        "ply\nformat {encoding} 1.0\ncomment made by hand\nobj_info test\nelement vertex 4\n\
         property float x\nproperty float y\nproperty float z\nelement face 2\n\
         property list uchar int vertex_indices\nend_header\n"
    );
    if encoding == "ascii" {
        let mut s = header;
        for v in SQUARE {
            s += &format!("{} {} {}\n", v[0], v[1], v[2]);
        }
        s += "4 0 1 2 3\n3 3 2 1\n";
        return s.into_bytes();
    }
    let mut w = W::new(&header, encoding == "binary_big_endian");
    for v in SQUARE {
        w.f32(v[0]).f32(v[1]).f32(v[2]);
    }
    w.u8(4).i32(0).i32(1).i32(2).i32(3);
    w.u8(3).i32(3).i32(2).i32(1);
    w.out
}

pub(super) fn square_triangles() -> Vec<[[f64; 3]; 3]> {
    let v = |i: usize| SQUARE[i].map(|c| c as f64);
    vec![[v(0), v(1), v(2)], [v(0), v(2), v(3)], [v(3), v(2), v(1)]]
}

pub(super) fn assert_err(e: &ImportError, pos: Position, text: &str) {
    assert_eq!(e.position(), Some(pos), "{e}");
    assert!(e.to_string().contains(text), "{e:?} does not contain {text:?}");
}
