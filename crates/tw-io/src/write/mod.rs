//! Scene writers: binary PLY, OBJ with an MTL sidecar, binary STL and GLB (glTF 2.0 binary).
//!
//! Every writer is a [`TriangleSink`] that streams with bounded memory, whatever the size of the
//! scene: bytes whose place in the file depends on counts known only at the end go to an unnamed
//! temporary file in the target's directory and are appended by
//! [`SceneWriter::finish`]. Memory is a few MiB of buffers plus a small record per object (GLB
//! and OBJ also keep one per material colour, GLB one per run of consecutive triangles of an
//! object).
//!
//! Every writer is atomic ([`AtomicFile`]): it writes a temporary file beside the target and, in
//! `finish`, fsyncs it and renames it over the target. A writer dropped without `finish` (an
//! error, a panic, a cancelled run) leaves the target untouched and no file behind.
//!
//! | name          | format                                   | indices   | objects kept as          |
//! |---------------|------------------------------------------|-----------|--------------------------|
//! | `.ply[.gz]`   | PLY 1.0 binary little endian ([`ply`])   | yes       | per-face `uint object`   |
//! | `.obj[.gz]`   | Wavefront OBJ + `.mtl` ([`obj`])         | yes       | `o` name, `usemtl` colour|
//! | `.stl[.gz]`   | binary STL ([`stl`])                     | no        | not kept                 |
//! | `.glb`        | glTF 2.0 binary container ([`glb`])      | yes (u32) | node + mesh + material   |
//!
//! Indexed input ([`TriangleSink::mesh`]) keeps its indices where the format has them; plain
//! triangles ([`TriangleSink::triangle`]) become three new vertices each (no welding).
//! Coordinates are written as 32-bit floats (OBJ writes the exact f64 value where f32 would lose
//! it); a coordinate that is not finite or overflows f32 is an error.
//!
//! ```no_run
//! use tw_io::write::create_writer;
//! use tw_io::{Scene, SceneOptions};
//! let scene = Scene::open(&["in.obj"], SceneOptions::default()).unwrap();
//! let mut writer = create_writer("out.ply".as_ref()).unwrap();
//! scene.stream(&mut *writer).unwrap();
//! let summary = writer.finish().unwrap();
//! println!("{} triangles, {} bytes", summary.triangles, summary.bytes);
//! ```

pub mod glb;
pub mod obj;
pub mod ply;
pub mod stl;

use std::collections::HashMap;
use std::fs::File;
use std::io::{self, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use flate2::write::GzEncoder;
use tempfile::NamedTempFile;

use crate::error::{ImportError, Position};
use crate::{ObjectId, ObjectInfo, TriangleSink};

pub use glb::GlbWriter;
pub use obj::ObjWriter;
pub use ply::PlyWriter;
pub use stl::StlWriter;

/// Size of the buffers in front of the output and of every spill file.
const BUFFER: usize = 1 << 20;

/// A sink that writes a file. Call [`SceneWriter::finish`] once everything is streamed: only
/// then does the target file appear (or get replaced).
pub trait SceneWriter: TriangleSink + Send {
    /// Completes the file, fsyncs it and renames it over the target.
    fn finish(self: Box<Self>) -> Result<WriteSummary, ImportError>;
}

/// What a writer wrote.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WriteSummary {
    /// Objects announced to the writer.
    pub objects: u32,
    pub triangles: u64,
    /// Vertices written (three per plain triangle, every position of a mesh chunk).
    pub vertices: u64,
    /// Size of the written file on disk (compressed size for `.gz`; OBJ: without the `.mtl`).
    pub bytes: u64,
}

/// Creates a writer for `path`, choosing the format by its extension (case-insensitive):
/// `.ply`, `.obj`, `.stl`, `.glb`, and for PLY, OBJ and STL optionally `.gz` appended. The
/// target's directory must exist; the target itself is not touched until
/// [`SceneWriter::finish`].
pub fn create_writer(path: &Path) -> Result<Box<dyn SceneWriter>, ImportError> {
    let name = path.file_name().map(|n| n.to_string_lossy().to_lowercase()).unwrap_or_default();
    let (base, gzip) = match name.strip_suffix(".gz") {
        Some(b) => (b, true),
        None => (name.as_str(), false),
    };
    let ext = base.rsplit_once('.').map(|(_, e)| e).unwrap_or("");
    Ok(match ext {
        "ply" => Box::new(PlyWriter::create(path, gzip)?),
        "obj" => Box::new(ObjWriter::create(path, gzip)?),
        "stl" => Box::new(StlWriter::create(path, gzip)?),
        "glb" if gzip => {
            return Err(ImportError::unsupported(
                path,
                "gzip'ed GLB: glTF tools do not read it; write .glb, or .ply.gz for a compressed file",
            ))
        }
        "glb" => Box::new(GlbWriter::create(path)?),
        "gltf" => {
            return Err(ImportError::unsupported(path, "writing .gltf (JSON + .bin): write .glb instead"))
        }
        _ => {
            return Err(ImportError::unsupported(
                path,
                "unknown output format: expected .ply, .obj, .stl (each optionally .gz) or .glb",
            ))
        }
    })
}

/// A file written atomically: the bytes go to a temporary file in the target's directory, which
/// [`AtomicFile::commit`] fsyncs and renames over the target. Dropping it without `commit`
/// deletes the temporary file and leaves the target as it was.
///
/// On Unix the file gets the usual permissions of a new file (0666 less the umask).
pub struct AtomicFile {
    target: PathBuf,
    file: BufWriter<NamedTempFile>,
    /// The temporary file stays registered for removal on a signal until it is renamed or
    /// dropped (`tw_core::cleanup`: Ctrl-C during `generate` leaves nothing behind).
    _cleanup: tw_core::cleanup::TempGuard,
}

impl AtomicFile {
    /// Creates the temporary file beside `target`. Fails now if the directory does not exist or
    /// is not writable, or if `target` exists and is not a regular file (a directory, a device:
    /// the rename would replace it; [`tw_core::output`]).
    pub fn create(target: &Path) -> Result<AtomicFile, ImportError> {
        let err = |e| ImportError::io(target, Position::File, e);
        let name = target
            .file_name()
            .ok_or_else(|| ImportError::Sink(format!("{}: not a file name to write to", target.display())))?;
        tw_core::output::check_replaceable(target).map_err(|e| ImportError::Sink(e.to_string()))?;
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        // A hidden name that says what it is; short enough for any file system's name limit.
        let stem: String = name.to_string_lossy().chars().take(64).collect();
        let prefix = format!(".{stem}.");
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".tmp");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(0o666));
        }
        let tmp = builder.tempfile_in(dir).map_err(err)?;
        let _cleanup = tw_core::cleanup::register(tmp.path());
        Ok(AtomicFile { target: target.to_path_buf(), file: BufWriter::with_capacity(BUFFER, tmp), _cleanup })
    }

    /// The file this will become.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Flushes, fsyncs and renames the file over the target; returns its size in bytes.
    pub fn commit(self) -> Result<u64, ImportError> {
        let target = self.target;
        let err = |e| ImportError::io(&target, Position::File, e);
        let tmp = self.file.into_inner().map_err(|e| err(e.into_error()))?;
        tmp.as_file().sync_all().map_err(err)?;
        let len = tmp.as_file().metadata().map_err(err)?.len();
        tmp.persist(&target).map_err(|e| err(e.error))?;
        // Make the rename itself durable. Some file systems refuse to fsync a directory; the
        // data is safe either way, so that is not an error.
        #[cfg(unix)]
        if let Some(dir) = target.parent() {
            let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(len)
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.file.write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.file.write_all(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl Seek for AtomicFile {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.file.seek(pos)
    }
}

/// The main output of a writer: an [`AtomicFile`], gzip'ed or not.
pub(crate) enum Output {
    Plain(AtomicFile),
    // Boxed: the encoder state is large, the plain variant small.
    Gzip(Box<GzEncoder<AtomicFile>>),
}

impl Output {
    pub(crate) fn create(path: &Path, gzip: bool) -> Result<Output, ImportError> {
        let file = AtomicFile::create(path)?;
        Ok(if gzip {
            // Level 1: model data compresses little better at higher levels, and much slower.
            Output::Gzip(Box::new(GzEncoder::new(file, flate2::Compression::fast())))
        } else {
            Output::Plain(file)
        })
    }

    pub(crate) fn target(&self) -> &Path {
        match self {
            Output::Plain(f) => f.target(),
            Output::Gzip(g) => g.get_ref().target(),
        }
    }

    /// The file, when it can seek (not gzip'ed).
    pub(crate) fn seekable(&mut self) -> Option<&mut AtomicFile> {
        match self {
            Output::Plain(f) => Some(f),
            Output::Gzip(_) => None,
        }
    }

    pub(crate) fn commit(self) -> Result<u64, ImportError> {
        match self {
            Output::Plain(f) => f.commit(),
            Output::Gzip(g) => {
                let path = g.get_ref().target().to_path_buf();
                g.finish().map_err(|e| ImportError::io(&path, Position::File, e))?.commit()
            }
        }
    }
}

impl Write for Output {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self {
            Output::Plain(f) => f.write(buf),
            Output::Gzip(g) => g.write(buf),
        }
    }
    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        match self {
            Output::Plain(f) => f.write_all(buf),
            Output::Gzip(g) => g.write_all(buf),
        }
    }
    fn flush(&mut self) -> io::Result<()> {
        match self {
            Output::Plain(f) => f.flush(),
            Output::Gzip(g) => g.flush(),
        }
    }
}

/// An unnamed temporary file for bytes that go into the output later (PLY faces, GLB's binary
/// chunk). It lives in the target's directory (not /tmp, which may be memory) and disappears
/// when dropped, even if the process is killed.
pub(crate) struct Spill {
    file: BufWriter<File>,
    len: u64,
}

impl Spill {
    pub(crate) fn create(target: &Path) -> Result<Spill, ImportError> {
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let file = tempfile::tempfile_in(dir).map_err(|e| ImportError::io(target, Position::File, e))?;
        Ok(Spill { file: BufWriter::with_capacity(BUFFER, file), len: 0 })
    }

    #[inline]
    pub(crate) fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.len += bytes.len() as u64;
        self.file.write_all(bytes)
    }

    /// Bytes written so far.
    pub(crate) fn len(&self) -> u64 {
        self.len
    }

    /// Appends everything written to `out`.
    pub(crate) fn copy_into(self, out: &mut impl Write) -> io::Result<()> {
        let mut file = self.file.into_inner().map_err(|e| e.into_error())?;
        file.seek(SeekFrom::Start(0))?;
        let mut buf = vec![0u8; BUFFER];
        let mut left = self.len;
        while left > 0 {
            let n = file.read(&mut buf)?;
            if n == 0 {
                return Err(io::Error::new(io::ErrorKind::UnexpectedEof, "temporary file shrank"));
            }
            let n = n.min(left as usize);
            out.write_all(&buf[..n])?;
            left -= n as u64;
        }
        Ok(())
    }
}

/// The objects a writer has been told about, with a dense index in announcement order.
#[derive(Default)]
pub(crate) struct Objects {
    index: HashMap<ObjectId, u32>,
    pub(crate) infos: Vec<(ObjectId, ObjectInfo)>,
    /// The last lookup, since triangles come in long runs of one object.
    last: Option<(ObjectId, u32)>,
}

impl Objects {
    /// Records an object; announcing an id twice is an error.
    pub(crate) fn announce(
        &mut self,
        target: &Path,
        id: ObjectId,
        info: &ObjectInfo,
    ) -> Result<u32, ImportError> {
        let dense = self.infos.len() as u32;
        if self.index.insert(id, dense).is_some() {
            return Err(ImportError::Sink(format!("{}: object {id} announced twice", target.display())));
        }
        self.infos.push((id, info.clone()));
        Ok(dense)
    }

    /// The dense index of an announced object.
    #[inline]
    pub(crate) fn get(&mut self, target: &Path, id: ObjectId) -> Result<u32, ImportError> {
        if let Some((last, dense)) = self.last {
            if last == id {
                return Ok(dense);
            }
        }
        match self.index.get(&id) {
            Some(&dense) => {
                self.last = Some((id, dense));
                Ok(dense)
            }
            None => Err(ImportError::Sink(format!(
                "{}: triangle of object {id}, which was never announced",
                target.display()
            ))),
        }
    }

    pub(crate) fn len(&self) -> u32 {
        self.infos.len() as u32
    }
}

/// A position as f32, or an error if it is not finite or out of f32's range.
#[inline]
pub(crate) fn to_f32(target: &Path, p: [f64; 3]) -> Result<[f32; 3], ImportError> {
    let q = p.map(|v| v as f32);
    if q.iter().all(|v| v.is_finite()) {
        Ok(q)
    } else {
        Err(ImportError::Sink(format!(
            "{}: coordinate ({}, {}, {}) is not finite or does not fit in a 32-bit float",
            target.display(),
            p[0],
            p[1],
            p[2]
        )))
    }
}

/// Checks that every index of a chunk is in range (the [`crate::MeshChunk`] contract; checked
/// because an out-of-range index would write a broken file, not fail).
pub(crate) fn check_chunk(target: &Path, chunk: &crate::MeshChunk<'_>) -> Result<(), ImportError> {
    if !chunk.indices.chunks_exact(3).remainder().is_empty() {
        return Err(ImportError::Sink(format!(
            "{}: mesh chunk has {} indices, not a multiple of 3",
            target.display(),
            chunk.indices.len()
        )));
    }
    let n = chunk.positions.len();
    if let Some(&bad) = chunk.indices.iter().find(|&&i| i as usize >= n) {
        return Err(ImportError::Sink(format!(
            "{}: mesh chunk index {bad} is out of range ({n} positions)",
            target.display()
        )));
    }
    Ok(())
}

/// Maps an I/O error on the output to an [`ImportError`] naming the target.
pub(crate) fn io_err(target: &Path) -> impl Fn(io::Error) -> ImportError + '_ {
    move |e| ImportError::io(target, Position::File, e)
}

/// Writes `v` in decimal into `buf` without allocating; returns the digits.
#[inline]
pub(crate) fn format_u64(mut v: u64, buf: &mut [u8; 20]) -> &[u8] {
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (v % 10) as u8;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    &buf[i..]
}

#[cfg(test)]
pub(crate) mod test_scene {
    //! The small scene every writer's tests write: two objects, an indexed chunk, plain
    //! triangles, and object 0 coming back after object 1 (a second run).
    use crate::{ImportError, MeshChunk, ObjectInfo, Triangle, TriangleSink};
    use tw_core::Rgba8;

    pub const RED: Rgba8 = Rgba8([255, 0, 0, 255]);

    /// Quad in z = 0 (two triangles sharing an edge).
    pub const QUAD: [[f64; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    pub const QUAD_INDICES: [u32; 6] = [0, 1, 2, 0, 2, 3];
    pub const T1: [[f64; 3]; 3] = [[2.0, 0.0, 0.0], [3.0, 0.0, 0.0], [2.0, 0.0, 1.0]];
    pub const T2: [[f64; 3]; 3] = [[2.0, 1.0, 0.0], [3.0, 1.0, 0.5], [2.0, 2.0, -1.5]];
    pub const T3: [[f64; 3]; 3] = [[-1.0, -1.0, -1.0], [-2.0, -1.0, -1.0], [-1.0, -2.0, -1.25]];

    /// 3 objects announced (the last one empty), 5 triangles, 13 vertices.
    pub fn stream(sink: &mut dyn TriangleSink) -> Result<(), ImportError> {
        sink.object(0, &ObjectInfo { name: "red part".into(), color: Some(RED) })?;
        sink.mesh(&MeshChunk { object: 0, positions: &QUAD, indices: &QUAD_INDICES })?;
        sink.object(1, &ObjectInfo { name: String::new(), color: None })?;
        sink.triangle(&Triangle::new(T1, 1))?;
        sink.triangle(&Triangle::new(T2, 1))?;
        sink.triangle(&Triangle::new(T3, 0))?;
        sink.object(2, &ObjectInfo { name: "empty\nline".into(), color: Some(Rgba8([0, 128, 255, 128])) })?;
        Ok(())
    }

    pub const TRIANGLES: u64 = 5;
    pub const VERTICES: u64 = 13;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Triangle;

    fn files_in(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into())
            .collect();
        v.sort();
        v
    }

    const ALL: [&str; 7] = ["a.ply", "a.ply.gz", "a.obj", "a.obj.gz", "a.stl", "a.stl.gz", "a.glb"];

    #[test]
    fn every_format_by_extension_case_insensitive() {
        let dir = tempfile::tempdir().unwrap();
        for name in ALL.iter().copied().chain(["B.PLY", "C.Obj.GZ", "D.GLB"]) {
            let w = create_writer(&dir.path().join(name)).unwrap();
            let s = w.finish().unwrap();
            assert_eq!(s.triangles, 0, "{name}");
            assert!(s.bytes > 0, "{name}");
        }
    }

    #[test]
    fn unknown_and_unwritable_formats_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        for (name, expect) in [
            ("a.xyz", "unknown output format"),
            ("noext", "unknown output format"),
            ("a.gltf", "write .glb instead"),
            ("a.glb.gz", "gzip'ed GLB"),
        ] {
            let e = create_writer(&dir.path().join(name)).err().unwrap();
            assert!(e.to_string().contains(expect), "{name}: {e}");
            assert!(e.to_string().contains(name), "{name}: {e}");
        }
        assert!(files_in(dir.path()).is_empty());
    }

    #[test]
    fn missing_directory_fails_at_create() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("no/such/dir/a.ply");
        let e = create_writer(&p).err().unwrap();
        assert!(e.to_string().contains("no/such/dir/a.ply"), "{e}");
    }

    #[test]
    fn directory_target_fails_at_create() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("x.ply")).unwrap();
        let e = create_writer(&dir.path().join("x.ply")).err().unwrap();
        assert!(e.to_string().contains("is a directory"), "{e}");
    }

    #[test]
    fn dropped_writer_leaves_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        for name in ALL {
            let mut w = create_writer(&dir.path().join(name)).unwrap();
            test_scene::stream(&mut *w).unwrap();
            drop(w);
            assert!(files_in(dir.path()).is_empty(), "{name}: {:?}", files_in(dir.path()));
        }
    }

    #[test]
    fn target_is_untouched_until_finish() {
        let dir = tempfile::tempdir().unwrap();
        for name in ALL {
            let p = dir.path().join(name);
            std::fs::write(&p, b"old contents").unwrap();
            let mut w = create_writer(&p).unwrap();
            test_scene::stream(&mut *w).unwrap();
            assert_eq!(std::fs::read(&p).unwrap(), b"old contents", "{name}");
            let s = w.finish().unwrap();
            let new = std::fs::read(&p).unwrap();
            assert_ne!(new, b"old contents", "{name}");
            assert_eq!(s.bytes, new.len() as u64, "{name}");
            assert_eq!(s.triangles, test_scene::TRIANGLES, "{name}");
            assert_eq!(s.objects, 3, "{name}");
        }
        // Only the targets (and OBJ's material files): no temporary files.
        let mut expect: Vec<String> = ALL.iter().map(|s| s.to_string()).collect();
        expect.push("a.mtl".into());
        expect.sort();
        assert_eq!(files_in(dir.path()), expect);
    }

    #[test]
    fn summary_counts_vertices() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["a.ply", "a.obj", "a.glb"] {
            let mut w = create_writer(&dir.path().join(name)).unwrap();
            test_scene::stream(&mut *w).unwrap();
            assert_eq!(w.finish().unwrap().vertices, test_scene::VERTICES, "{name}");
        }
        let mut w = create_writer(&dir.path().join("a.stl")).unwrap();
        test_scene::stream(&mut *w).unwrap();
        assert_eq!(w.finish().unwrap().vertices, 3 * test_scene::TRIANGLES);
    }

    #[cfg(unix)]
    #[test]
    fn written_file_has_ordinary_permissions() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.stl");
        create_writer(&p).unwrap().finish().unwrap();
        let mode = std::fs::metadata(&p).unwrap().permissions().mode();
        // 0666 less the umask: at least readable by the owner, and not the 0600 of a temp file
        // unless the umask asks for it.
        assert_eq!(mode & 0o600, 0o600);
        assert_eq!(mode & 0o111, 0);
    }

    #[test]
    fn every_writer_rejects_unannounced_objects_and_huge_coordinates() {
        let dir = tempfile::tempdir().unwrap();
        for name in ALL {
            let mut w = create_writer(&dir.path().join(name)).unwrap();
            let e = w.triangle(&Triangle::new(test_scene::T1, 7)).unwrap_err();
            assert!(e.to_string().contains("never announced"), "{name}: {e}");
            w.object(7, &ObjectInfo::default()).unwrap();
            let e = w.object(7, &ObjectInfo::default()).unwrap_err();
            assert!(e.to_string().contains("announced twice"), "{name}: {e}");
            let mut t = Triangle::new(test_scene::T1, 7);
            t.positions[1][2] = 1e300;
            let e = w.triangle(&t).unwrap_err();
            assert!(e.to_string().contains("does not fit in a 32-bit float"), "{name}: {e}");
            t.positions[1][2] = f64::NAN;
            assert!(w.triangle(&t).is_err(), "{name}");
            let bad = crate::MeshChunk { object: 7, positions: &test_scene::QUAD, indices: &[0, 1, 4] };
            let e = w.mesh(&bad).unwrap_err();
            assert!(e.to_string().contains("out of range"), "{name}: {e}");
        }
        assert!(files_in(dir.path()).is_empty());
    }

    #[test]
    fn format_u64_matches_display() {
        let mut buf = [0u8; 20];
        for v in [0u64, 7, 10, 99, 100, 12345, u32::MAX as u64, u64::MAX] {
            assert_eq!(format_u64(v, &mut buf), v.to_string().as_bytes());
        }
    }
}

#[cfg(test)]
mod round_trip {
    //! Writes the test scene in every format and reads it back through [`crate::open_source`].
    use super::*;
    use crate::format::{open_source, ImportOptions};
    use crate::{Triangle, TriangleSink};

    #[derive(Default)]
    struct Collect {
        objects: Vec<(ObjectId, ObjectInfo)>,
        triangles: Vec<Triangle>,
    }

    impl TriangleSink for Collect {
        fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
            self.objects.push((id, info.clone()));
            Ok(())
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.triangles.push(*t);
            Ok(())
        }
    }

    fn expected() -> Collect {
        let mut c = Collect::default();
        test_scene::stream(&mut c).unwrap();
        c
    }

    fn read_back(name: &str) -> Collect {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        let mut w = create_writer(&p).unwrap();
        test_scene::stream(&mut *w).unwrap();
        w.finish().unwrap();
        let mut c = Collect::default();
        open_source(&p, &ImportOptions::default()).unwrap().stream(&mut c).unwrap();
        c
    }

    /// The same triangles, as sets of positions, in the same order.
    fn assert_same_geometry(name: &str, got: &Collect) {
        let want = expected();
        assert_eq!(got.triangles.len(), want.triangles.len(), "{name}");
        for (g, w) in got.triangles.iter().zip(&want.triangles) {
            assert_eq!(g.positions, w.positions, "{name}");
        }
    }

    #[test]
    fn ply_round_trip_keeps_object_ids() {
        for name in ["a.ply", "a.ply.gz"] {
            let got = read_back(name);
            assert_same_geometry(name, &got);
            // PLY keeps each triangle's object id, not names or colours; the importer names
            // objects `<file>/<id>`. Object 2 has no triangles, so it is not in the file.
            let want: Vec<ObjectId> = expected().triangles.iter().map(|t| t.object).collect();
            let objects: Vec<ObjectId> = got.triangles.iter().map(|t| t.object).collect();
            assert_eq!(objects, want, "{name}");
            let names: Vec<(ObjectId, &str)> =
                got.objects.iter().map(|(id, i)| (*id, i.name.as_str())).collect();
            assert_eq!(names, vec![(0, "a/0"), (1, "a/1")], "{name}");
        }
    }

    #[test]
    fn obj_round_trip_keeps_objects_and_colours() {
        for name in ["a.obj", "a.obj.gz"] {
            let got = read_back(name);
            assert_same_geometry(name, &got);
            let names: Vec<&str> = got.objects.iter().map(|(_, i)| i.name.as_str()).collect();
            assert!(names.contains(&"red part"), "{name}: {names:?}");
            let red = got.objects.iter().find(|(_, i)| i.name == "red part").unwrap();
            assert_eq!(red.1.color, Some(test_scene::RED), "{name}");
        }
    }

    #[test]
    fn stl_round_trip() {
        for name in ["a.stl", "a.stl.gz"] {
            assert_same_geometry(name, &read_back(name));
        }
    }

    #[test]
    fn glb_round_trip_keeps_objects() {
        let got = read_back("a.glb");
        // GLB groups an object's triangles (its two runs become two primitives of one mesh), so
        // compare as multisets of triangles; the z-up scene comes back y-up, (x, y, z) → (x, z,
        // −y), as glTF wants (`glb` module docs; `+ 0.0` makes −0 print as 0).
        let y_up = |p: [f64; 3]| [p[0], p[2], -p[1] + 0.0];
        let mut g: Vec<String> = got.triangles.iter().map(|t| format!("{:?}", t.positions)).collect();
        let mut w: Vec<String> =
            expected().triangles.iter().map(|t| format!("{:?}", t.positions.map(y_up))).collect();
        g.sort();
        w.sort();
        assert_eq!(g, w);
        assert!(got.objects.iter().any(|(_, i)| i.name == "red part"));
    }
}

#[cfg(test)]
mod bench {
    //! Write throughput:
    //! `cargo test --release -p tw-io write::bench -- --ignored --nocapture`
    //! (`TW_BENCH_TRIANGLES` sets the scene size, default 8 million; `TW_BENCH_DIR` the directory).
    use super::*;
    use crate::{MeshChunk, Triangle};

    /// A 128 × 128 quad grid: 16641 vertices, 32768 triangles.
    fn grid() -> (Vec<[f64; 3]>, Vec<u32>) {
        const N: u32 = 128;
        let mut p = Vec::new();
        for y in 0..=N {
            for x in 0..=N {
                p.push([x as f64 * 0.01, y as f64 * 0.01, ((x * 7 + y * 13) % 17) as f64 * 0.001]);
            }
        }
        let mut idx = Vec::new();
        for y in 0..N {
            for x in 0..N {
                let i = y * (N + 1) + x;
                idx.extend_from_slice(&[i, i + 1, i + N + 2, i, i + N + 2, i + N + 1]);
            }
        }
        (p, idx)
    }

    #[test]
    #[ignore = "benchmark"]
    fn bench_write_throughput() {
        let total: u64 =
            std::env::var("TW_BENCH_TRIANGLES").ok().and_then(|s| s.parse().ok()).unwrap_or(8_000_000);
        let tmp = tempfile::tempdir_in(std::env::var("TW_BENCH_DIR").unwrap_or_else(|_| ".".into())).unwrap();
        let (mut pos, idx) = grid();
        let per_chunk = (idx.len() / 3) as u64;
        for name in ["a.ply", "a.stl", "a.glb", "a.obj", "a.ply.gz"] {
            let path = tmp.path().join(name);
            let start = std::time::Instant::now();
            let mut w = create_writer(&path).unwrap();
            w.object(0, &ObjectInfo { name: "grid".into(), color: None }).unwrap();
            w.object(1, &ObjectInfo { name: "soup".into(), color: None }).unwrap();
            let mut done = 0u64;
            let mut k = 0u64;
            while done < total {
                // Three chunks indexed, one as plain triangles (object 1).
                for p in pos.iter_mut() {
                    p[2] += 0.5;
                }
                if k % 4 == 3 {
                    for t in idx.chunks_exact(3) {
                        let q = |i: u32| pos[i as usize];
                        w.triangle(&Triangle::new([q(t[0]), q(t[1]), q(t[2])], 1)).unwrap();
                    }
                } else {
                    w.mesh(&MeshChunk { object: 0, positions: &pos, indices: &idx }).unwrap();
                }
                done += per_chunk;
                k += 1;
            }
            let s = w.finish().unwrap();
            let secs = start.elapsed().as_secs_f64();
            println!(
                "{name:9} {:>6.1} M triangles {:>8.1} MB in {secs:6.2} s: {:>7.1} MB/s, {:>6.2} M triangles/s",
                s.triangles as f64 / 1e6,
                s.bytes as f64 / 1e6,
                s.bytes as f64 / 1e6 / secs,
                s.triangles as f64 / 1e6 / secs
            );
            std::fs::remove_file(&path).unwrap();
        }
    }
}
