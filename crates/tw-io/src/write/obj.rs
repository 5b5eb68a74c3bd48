//! Wavefront OBJ writer with an MTL material library beside it (the OBJ and MTL sections of the
//! Wavefront "Advanced Visualizer" manual, as every OBJ reader implements them).
//!
//! - `mtllib <name>.mtl` first; the library is written next to the OBJ (uncompressed also for
//!   `.obj.gz`, since readers look for it by that name) with one material per distinct object
//!   colour (`Kd` r g b in 0..1 = the sRGB byte / 255, `d` alpha) and a `default` grey one for
//!   objects without a colour.
//! - `o <name>` and `usemtl <material>` when an object is announced, and again whenever the
//!   triangles switch to another object (so an object whose triangles come in several runs
//!   appears under several `o` lines with the same name). Names lose control characters; an
//!   unnamed object is called `object<id>`.
//! - `v x y z`: the shortest decimal that reads back as the same f32 when the coordinate is an
//!   f32, the shortest for the f64 otherwise, so no precision is lost either way.
//! - `f a b c`: absolute 1-based indices (never negative, so the file can be cut and
//!   concatenated by line tools).
//!
//! Lines are formatted into one reused buffer, no allocation per line.

use std::collections::HashSet;
use std::io::Write;
use std::path::{Path, PathBuf};

use tw_core::Rgba8;

use crate::error::ImportError;
use crate::{MeshChunk, ObjectId, ObjectInfo, Triangle, TriangleSink};

use super::{
    check_chunk, format_u64, io_err, to_f32, AtomicFile, Objects, Output, SceneWriter, WriteSummary,
};

/// Writes OBJ + MTL; see the module documentation.
pub struct ObjWriter {
    out: Output,
    mtl: AtomicFile,
    objects: Objects,
    /// Colours that have a material in the library already.
    materials: HashSet<Option<Rgba8>>,
    /// The object of the last `o` line.
    current: Option<ObjectId>,
    vertices: u64,
    triangles: u64,
    line: Vec<u8>,
}

/// The material library's path for an OBJ path: `dir/scene.obj[.gz]` gives `dir/scene.mtl`.
pub fn mtl_path(obj: &Path) -> PathBuf {
    let name = obj.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let strip = |s: &str, suffix: &str| {
        let cut = s.len().checked_sub(suffix.len()).filter(|&c| s.is_char_boundary(c));
        match cut {
            Some(c) if s[c..].eq_ignore_ascii_case(suffix) => s[..c].to_string(),
            _ => s.to_string(),
        }
    };
    let stem = strip(&strip(&name, ".gz"), ".obj");
    obj.with_file_name(format!("{stem}.mtl"))
}

pub(crate) fn material_name(color: Option<Rgba8>) -> String {
    match color {
        Some(Rgba8([r, g, b, a])) => format!("rgba_{r:02x}{g:02x}{b:02x}{a:02x}"),
        None => "default".to_string(),
    }
}

/// An object name fit for an `o` line: one line, no control characters, not empty.
fn object_name(id: ObjectId, info: &ObjectInfo) -> String {
    let s: String = info.name.chars().map(|c| if c.is_control() { '_' } else { c }).collect();
    let s = s.trim();
    if s.is_empty() {
        format!("object{id}")
    } else {
        s.to_string()
    }
}

/// Appends the coordinate: as f32 when that is exact, as f64 otherwise (both shortest).
#[inline]
fn push_coord(line: &mut Vec<u8>, v: f64) {
    let f = v as f32;
    // Writing into a Vec cannot fail.
    let _ = if f as f64 == v { write!(line, "{f}") } else { write!(line, "{v}") };
}

impl ObjWriter {
    /// Starts writing `path` (gzip'ed when `gzip`) and its material library (see [`mtl_path`]).
    /// Nothing appears before [`SceneWriter::finish`].
    pub fn create(path: &Path, gzip: bool) -> Result<ObjWriter, ImportError> {
        let mut out = Output::create(path, gzip)?;
        let mtl_target = mtl_path(path);
        let mut mtl = AtomicFile::create(&mtl_target)?;
        mtl.write_all(b"# written by terawalk\n").map_err(io_err(&mtl_target))?;
        let mtl_name = mtl_target.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        write!(out, "# written by terawalk\nmtllib {mtl_name}\n").map_err(io_err(path))?;
        Ok(ObjWriter {
            out,
            mtl,
            objects: Objects::default(),
            materials: HashSet::new(),
            current: None,
            vertices: 0,
            triangles: 0,
            line: Vec::with_capacity(256),
        })
    }

    /// Writes `o` and `usemtl` for an object, adding its material to the library if new.
    fn start_object(&mut self, id: ObjectId) -> Result<(), ImportError> {
        let target = self.out.target().to_path_buf();
        let dense = self.objects.get(&target, id)? as usize;
        let info = &self.objects.infos[dense].1;
        let color = info.color;
        let name = object_name(id, info);
        let material = material_name(color);
        if self.materials.insert(color) {
            let c = color.unwrap_or(Rgba8::GREY).to_f32();
            let mtl_target = self.mtl.target().to_path_buf();
            write!(self.mtl, "\nnewmtl {material}\nKd {} {} {}\nd {}\n", c[0], c[1], c[2], c[3])
                .map_err(io_err(&mtl_target))?;
        }
        // Geometry of the previous object may still sit in the line buffer: write it first.
        self.flush_line(true)?;
        write!(self.out, "o {name}\nusemtl {material}\n").map_err(io_err(&target))?;
        self.current = Some(id);
        Ok(())
    }

    #[inline]
    fn push_vertex(line: &mut Vec<u8>, p: [f64; 3]) {
        line.extend_from_slice(b"v ");
        push_coord(line, p[0]);
        line.push(b' ');
        push_coord(line, p[1]);
        line.push(b' ');
        push_coord(line, p[2]);
        line.push(b'\n');
    }

    #[inline]
    fn push_face(line: &mut Vec<u8>, a: u64, b: u64, c: u64) {
        let mut buf = [0u8; 20];
        line.extend_from_slice(b"f ");
        line.extend_from_slice(format_u64(a, &mut buf));
        line.push(b' ');
        line.extend_from_slice(format_u64(b, &mut buf));
        line.push(b' ');
        line.extend_from_slice(format_u64(c, &mut buf));
        line.push(b'\n');
    }

    /// Writes the line buffer out once it holds a good block of text.
    #[inline]
    fn flush_line(&mut self, force: bool) -> Result<(), ImportError> {
        if force || self.line.len() >= 1 << 16 {
            let r = self.out.write_all(&self.line);
            self.line.clear();
            r.map_err(io_err(self.out.target()))?;
        }
        Ok(())
    }
}

impl TriangleSink for ObjWriter {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        self.objects.announce(self.out.target(), id, info)?;
        self.start_object(id)
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.objects.get(self.out.target(), t.object)?;
        for p in &t.positions {
            to_f32(self.out.target(), *p)?;
        }
        if self.current != Some(t.object) {
            self.start_object(t.object)?;
        }
        for p in &t.positions {
            Self::push_vertex(&mut self.line, *p);
        }
        let n = self.vertices;
        Self::push_face(&mut self.line, n + 1, n + 2, n + 3);
        self.vertices += 3;
        self.triangles += 1;
        self.flush_line(false)
    }

    fn mesh(&mut self, chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        let target = self.out.target().to_path_buf();
        self.objects.get(&target, chunk.object)?;
        check_chunk(&target, chunk)?;
        for p in chunk.positions {
            to_f32(&target, *p)?;
        }
        if self.current != Some(chunk.object) {
            self.start_object(chunk.object)?;
        }
        for p in chunk.positions {
            Self::push_vertex(&mut self.line, *p);
            self.flush_line(false)?;
        }
        let base = self.vertices + 1;
        for t in chunk.indices.chunks_exact(3) {
            Self::push_face(&mut self.line, base + t[0] as u64, base + t[1] as u64, base + t[2] as u64);
            self.flush_line(false)?;
        }
        self.vertices += chunk.positions.len() as u64;
        self.triangles += (chunk.indices.len() / 3) as u64;
        Ok(())
    }
}

impl SceneWriter for ObjWriter {
    fn finish(mut self: Box<Self>) -> Result<WriteSummary, ImportError> {
        self.flush_line(true)?;
        let ObjWriter { out, mtl, objects, vertices, triangles, .. } = *self;
        mtl.commit()?;
        let bytes = out.commit()?;
        Ok(WriteSummary { objects: objects.len(), triangles, vertices, bytes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::write::{create_writer, test_scene};

    fn write(name: &str) -> (tempfile::TempDir, String, String) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        let mut w = create_writer(&p).unwrap();
        test_scene::stream(&mut *w).unwrap();
        w.finish().unwrap();
        let mut bytes = std::fs::read(&p).unwrap();
        if name.ends_with(".gz") {
            use std::io::Read;
            let mut plain = Vec::new();
            flate2::read::GzDecoder::new(&bytes[..]).read_to_end(&mut plain).unwrap();
            bytes = plain;
        }
        let mtl = std::fs::read_to_string(dir.path().join("a.mtl")).unwrap();
        (dir, String::from_utf8(bytes).unwrap(), mtl)
    }

    fn lines<'a>(text: &'a str, prefix: &str) -> Vec<&'a str> {
        text.lines().filter(|l| l.starts_with(prefix)).collect()
    }

    #[test]
    fn vertices_faces_and_objects() {
        let (_d, obj, _) = write("a.obj");
        let v = lines(&obj, "v ");
        assert_eq!(v.len(), 13);
        assert_eq!(v[2], "v 1 1 0");
        assert_eq!(v[12], "v -1 -2 -1.25");
        assert_eq!(lines(&obj, "f "), ["f 1 2 3", "f 1 3 4", "f 5 6 7", "f 8 9 10", "f 11 12 13"]);
        assert_eq!(lines(&obj, "mtllib "), ["mtllib a.mtl"]);
        // Object 0 comes back after object 1; the empty object 2 keeps its `o` line.
        assert_eq!(lines(&obj, "o "), ["o red part", "o object1", "o red part", "o empty_line"]);
        assert_eq!(
            lines(&obj, "usemtl "),
            ["usemtl rgba_ff0000ff", "usemtl default", "usemtl rgba_ff0000ff", "usemtl rgba_0080ff80"]
        );
    }

    #[test]
    fn one_material_per_colour() {
        let (_d, _, mtl) = write("a.obj");
        assert_eq!(
            lines(&mtl, "newmtl "),
            ["newmtl rgba_ff0000ff", "newmtl default", "newmtl rgba_0080ff80"]
        );
        assert!(mtl.contains("newmtl rgba_ff0000ff\nKd 1 0 0\nd 1\n"), "{mtl}");
        // Kd reads back as the same byte.
        let kd: Vec<f32> =
            lines(&mtl, "Kd ")[2].split_whitespace().skip(1).map(|s| s.parse().unwrap()).collect();
        assert_eq!(Rgba8::from_f32([kd[0], kd[1], kd[2], 1.0]), Rgba8([0, 128, 255, 255]));
    }

    #[test]
    fn gzip_output_decompresses_to_the_plain_file_and_mtl_stays_plain() {
        let (_d, plain, mtl) = write("a.obj");
        let (_e, gz, mtl_gz) = write("a.obj.gz");
        assert_eq!(gz, plain);
        assert_eq!(mtl_gz, mtl);
    }

    #[test]
    fn coordinates_that_are_not_f32_keep_their_f64_digits() {
        let mut line = Vec::new();
        push_coord(&mut line, 0.1);
        line.push(b' ');
        push_coord(&mut line, 0.1f32 as f64);
        line.push(b' ');
        push_coord(&mut line, 123456.789);
        line.push(b' ');
        push_coord(&mut line, -0.0);
        let s = String::from_utf8(line).unwrap();
        assert_eq!(s, "0.1 0.1 123456.789 -0");
        let parts: Vec<f64> = s.split(' ').map(|p| p.parse().unwrap()).collect();
        assert_eq!(parts[0], 0.1);
        assert_eq!(parts[1] as f32, 0.1f32);
        assert_eq!(parts[2], 123456.789);
    }

    #[test]
    fn mtl_path_strips_gz_and_obj_in_any_case() {
        assert_eq!(mtl_path(Path::new("/x/Scene.OBJ.gz")), Path::new("/x/Scene.mtl"));
        assert_eq!(mtl_path(Path::new("a.obj")), Path::new("a.mtl"));
        assert_eq!(mtl_path(Path::new("dir/a.b.obj")), Path::new("dir/a.b.mtl"));
    }
}
