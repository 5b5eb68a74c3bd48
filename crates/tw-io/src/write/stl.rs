//! Binary STL writer (the 3D Systems StereoLithography Interface Specification, 1989/1988:
//! an 80-byte header, a u32 triangle count, then 50 bytes per triangle: normal, three vertices
//! as little-endian f32, and a u16 attribute, here 0).
//!
//! The header never starts with "solid", which would make readers take the file for ASCII STL.
//! The count is patched in at the end (for `.gz` output, which cannot seek, the triangles are
//! spilled and the file assembled at the end). The normal is the unit normal of the vertices in
//! their order (counter-clockwise front face), zero for a degenerate triangle. STL has no objects
//! or indices: chunks are expanded and object ids dropped.

use std::io::{Seek, SeekFrom, Write};
use std::path::Path;

use crate::error::ImportError;
use crate::{MeshChunk, ObjectId, ObjectInfo, Triangle, TriangleSink};

use super::{check_chunk, io_err, to_f32, Objects, Output, SceneWriter, Spill, WriteSummary};

const HEADER: &[u8] = b"binary STL written by terawalk";
const FACET_BYTES: usize = 50;

/// Writes binary STL; see the module documentation.
pub struct StlWriter {
    out: Output,
    /// The triangles, when the output cannot seek (gzip).
    spill: Option<Spill>,
    objects: Objects,
    triangles: u64,
    /// The most triangles the count field holds (a field so tests can lower it).
    max_triangles: u64,
}

fn header(count: u32) -> [u8; 84] {
    let mut h = [0u8; 84];
    h[..HEADER.len()].copy_from_slice(HEADER);
    h[80..].copy_from_slice(&count.to_le_bytes());
    h
}

/// The unit normal of a triangle (right-handed, counter-clockwise front), zero if degenerate.
fn normal(p: &[[f64; 3]; 3]) -> [f32; 3] {
    let [a, b, c] = *p;
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        n.map(|x| (x / len) as f32)
    } else {
        [0.0; 3]
    }
}

impl StlWriter {
    /// Starts writing `path` (gzip'ed when `gzip`). Nothing appears before
    /// [`SceneWriter::finish`].
    pub fn create(path: &Path, gzip: bool) -> Result<StlWriter, ImportError> {
        let mut out = Output::create(path, gzip)?;
        let spill = if gzip {
            Some(Spill::create(path)?)
        } else {
            out.write_all(&header(0)).map_err(io_err(path))?;
            None
        };
        Ok(StlWriter {
            out,
            spill,
            objects: Objects::default(),
            triangles: 0,
            max_triangles: u32::MAX as u64,
        })
    }
}

impl TriangleSink for StlWriter {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        self.objects.announce(self.out.target(), id, info)?;
        Ok(())
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.objects.get(self.out.target(), t.object)?;
        if self.triangles >= self.max_triangles {
            return Err(ImportError::Sink(format!(
                "{}: more than {} triangles, beyond binary STL's 32-bit count; write PLY instead",
                self.out.target().display(),
                self.max_triangles
            )));
        }
        let mut f = [0u8; FACET_BYTES];
        let mut put = |k: usize, v: [f32; 3]| {
            for (i, x) in v.iter().enumerate() {
                f[12 * k + 4 * i..12 * k + 4 * i + 4].copy_from_slice(&x.to_le_bytes());
            }
        };
        put(0, normal(&t.positions));
        for (k, p) in t.positions.iter().enumerate() {
            put(k + 1, to_f32(self.out.target(), *p)?);
        }
        let r = match &mut self.spill {
            Some(s) => s.write_all(&f),
            None => self.out.write_all(&f),
        };
        r.map_err(io_err(self.out.target()))?;
        self.triangles += 1;
        Ok(())
    }

    fn mesh(&mut self, chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        check_chunk(self.out.target(), chunk)?;
        for t in chunk.indices.chunks_exact(3) {
            let p = |i: u32| chunk.positions[i as usize];
            self.triangle(&Triangle::new([p(t[0]), p(t[1]), p(t[2])], chunk.object))?;
        }
        Ok(())
    }
}

impl SceneWriter for StlWriter {
    fn finish(self: Box<Self>) -> Result<WriteSummary, ImportError> {
        let StlWriter { mut out, spill, objects, triangles, .. } = *self;
        let target = out.target().to_path_buf();
        let err = io_err(&target);
        // The count was checked against u32::MAX on every triangle.
        let head = header(triangles.min(u32::MAX as u64) as u32);
        match spill {
            Some(s) => {
                out.write_all(&head).map_err(&err)?;
                s.copy_into(&mut out).map_err(&err)?;
            }
            None => {
                let Some(file) = out.seekable() else {
                    return Err(ImportError::Sink(format!(
                        "{}: internal: output cannot seek",
                        target.display()
                    )));
                };
                file.seek(SeekFrom::Start(80)).map_err(&err)?;
                file.write_all(&head[80..]).map_err(&err)?;
            }
        }
        let bytes = out.commit()?;
        Ok(WriteSummary { objects: objects.len(), triangles, vertices: 3 * triangles, bytes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::write::{create_writer, test_scene};

    fn write(name: &str) -> Vec<u8> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        let mut w = create_writer(&p).unwrap();
        test_scene::stream(&mut *w).unwrap();
        w.finish().unwrap();
        std::fs::read(&p).unwrap()
    }

    fn f32s(b: &[u8]) -> Vec<f32> {
        b.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
    }

    #[test]
    fn size_count_and_header() {
        let b = write("a.stl");
        assert_eq!(b.len(), 84 + 5 * FACET_BYTES);
        assert_eq!(u32::from_le_bytes(b[80..84].try_into().unwrap()), 5);
        assert!(!b.starts_with(b"solid"));
    }

    #[test]
    fn facets_hold_normal_vertices_and_zero_attribute() {
        let b = write("a.stl");
        // First facet: the quad's triangle (0,0,0) (1,0,0) (1,1,0), normal +z.
        let f = f32s(&b[84..84 + 48]);
        assert_eq!(f, [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0]);
        assert_eq!(&b[84 + 48..84 + 50], &[0, 0]);
        // Third facet: T1 = (2,0,0) (3,0,0) (2,0,1), normal -y.
        let o = 84 + 2 * FACET_BYTES;
        assert_eq!(f32s(&b[o..o + 48]), [0.0, -1.0, 0.0, 2.0, 0.0, 0.0, 3.0, 0.0, 0.0, 2.0, 0.0, 1.0]);
    }

    #[test]
    fn gzip_output_decompresses_to_the_plain_file() {
        use std::io::Read;
        let plain = write("a.stl");
        let gz = write("a.stl.gz");
        let mut out = Vec::new();
        flate2::read::GzDecoder::new(&gz[..]).read_to_end(&mut out).unwrap();
        assert_eq!(out, plain);
    }

    #[test]
    fn degenerate_triangle_gets_a_zero_normal() {
        assert_eq!(normal(&[[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [3.0, 3.0, 3.0]]), [0.0; 3]);
    }

    #[test]
    fn too_many_triangles_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = StlWriter::create(&dir.path().join("a.stl"), false).unwrap();
        w.max_triangles = 2;
        w.object(0, &ObjectInfo::default()).unwrap();
        w.triangle(&Triangle::new(test_scene::T1, 0)).unwrap();
        w.triangle(&Triangle::new(test_scene::T2, 0)).unwrap();
        let e = w.triangle(&Triangle::new(test_scene::T3, 0)).unwrap_err();
        assert!(e.to_string().contains("32-bit count"), "{e}");
    }
}
