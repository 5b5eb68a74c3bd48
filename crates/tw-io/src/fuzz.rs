//! The entry point of the fuzz targets in fuzz/ (one per parser): bytes in, any error allowed,
//! no panic, no unbounded allocation. Also used by unit tests to replay crashers.

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
