//! The entry points of the fuzz targets in fuzz/ (one per parser): bytes in, any error allowed,
//! no panic, no unbounded allocation. The tests below feed every file of the corpus and of
//! fuzz/regressions through the same functions in the ordinary test run.

use std::path::Path;

use crate::format::{open_input, ImportOptions};
use crate::input::Input;
use crate::{ImportError, ObjectId, ObjectInfo, Scene, SceneStats, Triangle, TriangleSink};

/// Streams `data` as if it were a file called `name` (the extension picks the importer when the
/// content does not). Returns the triangles read, or the error.
pub fn import_bytes(name: &str, data: &[u8]) -> Result<u64, ImportError> {
    let options = ImportOptions { vertex_memory: 1 << 20, spill_dir: None };
    let source = open_input(Input::from_bytes(Path::new(name), data.to_vec()), &options)?;
    let mut sink = Limit { stats: SceneStats::default(), left: 1 << 22 };
    let summary = Scene::from_sources(vec![source]).stream(&mut sink)?;
    Ok(summary.triangles)
}

/// Parses `data` as an MTL material library, as an OBJ's `mtllib` statement reads one. Returns
/// the number of materials defined (malformed statements are warnings, never errors).
pub fn mtl_bytes(data: &[u8]) -> Result<usize, std::io::Error> {
    let mut materials = crate::obj::mtl::Materials::new();
    crate::obj::mtl::read(data, Path::new("fuzz.mtl"), &mut materials)?;
    Ok(materials.len())
}

/// The byte that separates the two files of a [`gltf_with_buffer`] input (JSON has no NUL).
pub const GLTF_BUFFER_SEPARATOR: u8 = 0;

/// A `.gltf` with an external buffer: `data` up to the first NUL byte is written as
/// `scene.gltf`, the rest as `buffer.bin`, both in a fresh temporary folder, and the `.gltf` is
/// imported from there. This reaches what [`import_bytes`] cannot: buffers read through the
/// file system by their relative `uri`, with their lengths checked against the file's.
pub fn gltf_with_buffer(data: &[u8]) -> Result<u64, ImportError> {
    let (json, bin) = match data.iter().position(|&b| b == GLTF_BUFFER_SEPARATOR) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &data[data.len()..]),
    };
    let folder = Path::new("fuzz");
    let io = |e| ImportError::io(folder, crate::error::Position::File, e);
    let dir = tempfile::tempdir().map_err(io)?;
    let gltf = dir.path().join("scene.gltf");
    std::fs::write(&gltf, json).map_err(io)?;
    std::fs::write(dir.path().join("buffer.bin"), bin).map_err(io)?;
    let options = ImportOptions { vertex_memory: 1 << 20, spill_dir: None };
    let source = crate::format::open_source(&gltf, &options)?;
    let mut sink = Limit { stats: SceneStats::default(), left: 1 << 22 };
    let summary = Scene::from_sources(vec![source]).stream(&mut sink)?;
    Ok(summary.triangles)
}

/// Stops a stream after a number of triangles, so that tiny inputs that legitimately describe
/// huge outputs (a face with many vertices) do not make a fuzz run time out.
struct Limit {
    stats: SceneStats,
    left: u64,
}

impl TriangleSink for Limit {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        self.stats.object(id, info)
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        if self.left == 0 {
            return Err(ImportError::Sink("fuzz triangle limit reached".into()));
        }
        self.left -= 1;
        self.stats.triangle(t)
    }
}

/// Feeds every file of fuzz/corpus/TARGET and fuzz/regressions/TARGET to `run`, and fails
/// naming the files that panic (errors are fine), or when the corpus is missing: a fixed crash
/// stays fixed without a fuzzer (scripts/fuzz.sh adds the crashers). For the replay tests of
/// every crate with fuzz targets.
pub fn replay_corpus(target: &str, run: impl Fn(&[u8])) {
    let fuzz = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let mut files = Vec::new();
    for dir in ["corpus", "regressions"] {
        if let Ok(entries) = std::fs::read_dir(fuzz.join(dir).join(target)) {
            files.extend(entries.filter_map(|e| e.ok()).map(|e| e.path()));
        }
    }
    files.sort();
    assert!(!files.is_empty(), "no corpus for the {target} fuzz target in {}", fuzz.display());
    let panicked: Vec<_> = files
        .iter()
        .filter(|f| {
            let data = std::fs::read(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(&data))).is_err()
        })
        .collect();
    assert!(panicked.is_empty(), "{target}: these inputs panic: {panicked:?}");
}

/// The committed corpus and every crasher found so far, through the entry points above.
#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::replay_corpus as replay;

    #[test]
    fn obj_corpus_replays() {
        replay("obj", |d| drop(super::import_bytes("fuzz.obj", d)));
    }

    #[test]
    fn ply_corpus_replays() {
        replay("ply", |d| drop(super::import_bytes("fuzz.ply", d)));
    }

    #[test]
    fn stl_corpus_replays() {
        replay("stl", |d| drop(super::import_bytes("fuzz.stl", d)));
    }

    #[test]
    fn gltf_corpus_replays() {
        replay("gltf", |d| {
            drop(super::import_bytes("fuzz.glb", d));
            drop(super::import_bytes("fuzz.gltf", d));
        });
    }

    #[test]
    fn mtl_corpus_replays() {
        replay("mtl", |d| drop(super::mtl_bytes(d)));
    }

    #[test]
    fn gltf_buffer_corpus_replays() {
        replay("gltf_buffer", |d| drop(super::gltf_with_buffer(d)));
    }

    /// The seeds are valid inputs: each imports triangles (a seed that stopped parsing would
    /// leave the fuzzer starting from nothing).
    #[test]
    fn seeds_are_valid_models() {
        for (target, name) in [("obj", "cube.obj"), ("ply", "binary_le.ply"), ("stl", "binary.stl")] {
            let path =
                PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus").join(target).join(name);
            let data = std::fs::read(&path).unwrap();
            assert!(super::import_bytes(name, &data).unwrap() > 0, "{}", path.display());
        }
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus");
        let glb = std::fs::read(dir.join("gltf/square.glb")).unwrap();
        assert_eq!(super::import_bytes("square.glb", &glb).unwrap(), 4);
        let external = std::fs::read(dir.join("gltf_buffer/external.bin")).unwrap();
        assert_eq!(super::gltf_with_buffer(&external).unwrap(), 4);
        let mtl = std::fs::read(dir.join("mtl/materials.mtl")).unwrap();
        assert_eq!(super::mtl_bytes(&mtl).unwrap(), 4);
    }
}
