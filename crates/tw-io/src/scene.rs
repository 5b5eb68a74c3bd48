//! Several inputs streamed as one scene.
//!
//! Each file numbers its objects from 0; the scene offsets them so that objects of different
//! files keep distinct ids. Degenerate triangles (repeated vertices, zero area) are dropped and
//! counted here, once for every format; a non-finite coordinate that slipped past a parser is an
//! error naming the file and the triangle.

use std::ops::Range;
use std::path::{Path, PathBuf};

use tw_core::Aabb;

use crate::error::{ImportError, Position};
use crate::format::{open_detected, Format, ImportOptions};
use crate::input::Input;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::{
    MeshChunk, NewObject, ObjectId, ObjectInfo, SourceSummary, Triangle, TriangleBatch, TriangleSink,
    TriangleSource,
};

#[derive(Clone, Debug, Default)]
pub struct SceneOptions {
    pub import: ImportOptions,
}

/// Inputs opened (headers read, formats detected) and ready to stream.
pub struct Scene {
    sources: Vec<(PathBuf, Box<dyn TriangleSource>)>,
    /// Each source's detected format (`None`: made in memory), for its up-axis convention.
    formats: Vec<Option<Format>>,
}

/// Progress across all files of a scene.
#[derive(Clone, Copy, Debug)]
pub struct SceneProgress {
    /// Index of the file being read.
    pub file: usize,
    pub files: usize,
    /// Progress within that file, in the source's unit (see [`TriangleSource::progress_total`]).
    pub done: u64,
    pub total: Option<u64>,
}

/// What streaming the whole scene found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SceneSummary {
    pub files: usize,
    pub objects: u32,
    /// Triangles passed to the sink.
    pub triangles: u64,
    /// Degenerate triangles dropped.
    pub degenerate: u64,
    pub vertices: u64,
    pub bytes: u64,
}

impl Scene {
    /// Opens every input, so that a missing or unreadable file fails before any work is done.
    pub fn open<P: AsRef<Path>>(paths: &[P], options: SceneOptions) -> Result<Scene, ImportError> {
        let mut sources = Vec::with_capacity(paths.len());
        let mut formats = Vec::with_capacity(paths.len());
        for p in paths {
            let p = p.as_ref();
            let (format, source) = open_detected(Input::open(p)?, &options.import)?;
            sources.push((p.to_path_buf(), source));
            formats.push(Some(format));
        }
        Ok(Scene { sources, formats })
    }

    /// A scene of already-made sources (a generator, tests).
    pub fn from_sources(sources: Vec<Box<dyn TriangleSource>>) -> Scene {
        let formats = vec![None; sources.len()];
        Scene { sources: sources.into_iter().map(|s| (PathBuf::from(s.name()), s)).collect(), formats }
    }

    /// Each input's format, in order (`None` for sources made in memory): what the default up
    /// axis follows ([`crate::up::format_default`]).
    pub fn formats(&self) -> &[Option<Format>] {
        &self.formats
    }

    pub fn len(&self) -> usize {
        self.sources.len()
    }

    pub fn is_empty(&self) -> bool {
        self.sources.is_empty()
    }

    pub fn names(&self) -> Vec<String> {
        self.sources.iter().map(|(_, s)| s.name()).collect()
    }

    pub fn stream(self, sink: &mut dyn TriangleSink) -> Result<SceneSummary, ImportError> {
        self.stream_with_progress(sink, &mut |_| {})
    }

    pub fn stream_with_progress(
        self,
        sink: &mut dyn TriangleSink,
        progress: &mut dyn FnMut(SceneProgress),
    ) -> Result<SceneSummary, ImportError> {
        let files = self.sources.len();
        let mut summary = SceneSummary { files, ..Default::default() };
        for (file, (path, source)) in self.sources.into_iter().enumerate() {
            let total = source.progress_total();
            let mut filter = SceneFilter {
                sink,
                path: &path,
                base: summary.objects,
                objects: 0,
                passed: 0,
                degenerate: 0,
                seen: 0,
                progress: &mut *progress,
                file,
                files,
                total,
            };
            let s: SourceSummary = source.stream(&mut filter)?;
            let (objects, passed, degenerate) = (filter.objects, filter.passed, filter.degenerate);
            if s.objects != objects {
                return Err(ImportError::Sink(format!(
                    "{}: importer announced {objects} objects but reported {}",
                    path.display(),
                    s.objects
                )));
            }
            summary.objects += objects;
            summary.triangles += passed;
            summary.degenerate += degenerate;
            summary.vertices += s.vertices;
            summary.bytes += s.bytes;
        }
        Ok(summary)
    }
}

/// Offsets object ids, drops degenerate triangles, rejects non-finite ones.
struct SceneFilter<'a> {
    sink: &'a mut dyn TriangleSink,
    path: &'a Path,
    base: ObjectId,
    objects: u32,
    passed: u64,
    degenerate: u64,
    seen: u64,
    progress: &'a mut dyn FnMut(SceneProgress),
    file: usize,
    files: usize,
    total: Option<u64>,
}

impl TriangleSink for SceneFilter<'_> {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        if id != self.objects {
            return Err(ImportError::Sink(format!(
                "{}: importer announced object {id} out of order (expected {})",
                self.path.display(),
                self.objects
            )));
        }
        self.objects += 1;
        self.sink.object(self.base + id, info)
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.seen += 1;
        if t.object >= self.objects {
            return Err(ImportError::Sink(format!(
                "{}: triangle {} belongs to object {} that was never announced",
                self.path.display(),
                self.seen,
                t.object
            )));
        }
        if t.positions.iter().flatten().any(|v| !v.is_finite()) {
            return Err(ImportError::parse(
                self.path,
                Position::File,
                format!("triangle {} has a non-finite coordinate", self.seen),
            ));
        }
        if t.is_degenerate() {
            self.degenerate += 1;
            return Ok(());
        }
        self.passed += 1;
        let mut out = *t;
        out.object += self.base;
        self.sink.triangle(&out)
    }

    fn mesh(&mut self, chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        // Expand so that every triangle is filtered the same way; sinks that want indices keep
        // them only for inputs without degenerate triangles, which is every generated chunk.
        if chunk.object >= self.objects {
            return Err(ImportError::Sink(format!(
                "{}: mesh chunk for unannounced object {}",
                self.path.display(),
                chunk.object
            )));
        }
        if chunk.positions.iter().flatten().any(|v| !v.is_finite()) {
            return Err(ImportError::parse(
                self.path,
                Position::File,
                "mesh chunk has a non-finite coordinate",
            ));
        }
        let any_degenerate = chunk.indices.chunks_exact(3).any(|t| {
            let p = |i: u32| chunk.positions[i as usize];
            Triangle::new([p(t[0]), p(t[1]), p(t[2])], 0).is_degenerate()
        });
        if any_degenerate {
            for t in chunk.indices.chunks_exact(3) {
                let p = |i: u32| chunk.positions[i as usize];
                self.triangle(&Triangle::new([p(t[0]), p(t[1]), p(t[2])], chunk.object))?;
            }
            return Ok(());
        }
        let n = (chunk.indices.len() / 3) as u64;
        self.seen += n;
        self.passed += n;
        self.sink.mesh(&MeshChunk { object: chunk.object + self.base, ..*chunk })
    }

    fn batch(&mut self, batch: &dyn TriangleBatch) -> Result<(), ImportError> {
        let mut new_objects = Vec::with_capacity(batch.new_objects().len());
        for o in batch.new_objects() {
            if o.id != self.objects {
                return Err(ImportError::Sink(format!(
                    "{}: importer announced object {} out of order (expected {})",
                    self.path.display(),
                    o.id,
                    self.objects
                )));
            }
            self.objects += 1;
            new_objects.push(NewObject { id: o.id + self.base, ..o.clone() });
        }
        let filtered = FilteredBatch {
            inner: batch,
            new_objects,
            path: self.path,
            base: self.base,
            objects: self.objects,
            seen: self.seen,
            degenerate: AtomicU64::new(0),
        };
        self.sink.batch(&filtered)?;
        let degenerate = filtered.degenerate.into_inner();
        self.seen += batch.len() as u64;
        self.degenerate += degenerate;
        self.passed += batch.len() as u64 - degenerate;
        Ok(())
    }

    fn progress(&mut self, done: u64) {
        (self.progress)(SceneProgress { file: self.file, files: self.files, done, total: self.total });
    }
}

/// A source's batch as [`SceneFilter`] passes it on: ids offset, degenerate triangles dropped
/// (and counted: the sink fetches every triangle once), non-finite ones rejected; the same
/// checks as [`SceneFilter::triangle`], per triangle, on whichever thread fetches it.
struct FilteredBatch<'a> {
    inner: &'a dyn TriangleBatch,
    new_objects: Vec<NewObject>,
    path: &'a Path,
    base: ObjectId,
    /// Objects of this source announced up to the end of the batch.
    objects: u32,
    /// Triangles of this source before the batch.
    seen: u64,
    degenerate: AtomicU64,
}

impl TriangleBatch for FilteredBatch<'_> {
    fn len(&self) -> usize {
        self.inner.len()
    }

    fn triangles(&self, range: Range<usize>, out: &mut Vec<Triangle>) -> Result<(), ImportError> {
        let first = out.len();
        self.inner.triangles(range.clone(), out)?;
        // Sources drop nothing: the k-th triangle appended is triangle `range.start + k`.
        let mut kept = first;
        for k in first..out.len() {
            let mut t = out[k];
            let seen = self.seen + (range.start + k - first) as u64 + 1;
            if t.object >= self.objects {
                return Err(ImportError::Sink(format!(
                    "{}: triangle {seen} belongs to object {} that was never announced",
                    self.path.display(),
                    t.object
                )));
            }
            if t.positions.iter().flatten().any(|v| !v.is_finite()) {
                return Err(ImportError::parse(
                    self.path,
                    Position::File,
                    format!("triangle {seen} has a non-finite coordinate"),
                ));
            }
            if t.is_degenerate() {
                continue;
            }
            t.object += self.base;
            out[kept] = t;
            kept += 1;
        }
        self.degenerate.fetch_add((out.len() - kept) as u64, Ordering::Relaxed);
        out.truncate(kept);
        Ok(())
    }

    fn new_objects(&self) -> &[NewObject] {
        &self.new_objects
    }
}

/// A sink that counts: triangles, objects, bounds, attributes present.
#[derive(Clone, Debug, Default)]
pub struct SceneStats {
    pub triangles: u64,
    pub objects: u64,
    pub with_normals: u64,
    pub with_colors: u64,
    pub bounds: Aabb,
    /// Triangles per object, indexed by object id.
    pub per_object: Vec<u64>,
}

impl TriangleSink for SceneStats {
    fn object(&mut self, id: ObjectId, _info: &ObjectInfo) -> Result<(), ImportError> {
        self.objects += 1;
        if self.per_object.len() <= id as usize {
            self.per_object.resize(id as usize + 1, 0);
        }
        Ok(())
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.triangles += 1;
        self.with_normals += t.normals.is_some() as u64;
        self.with_colors += t.colors.is_some() as u64;
        for p in &t.positions {
            self.bounds.grow(*p);
        }
        if let Some(c) = self.per_object.get_mut(t.object as usize) {
            *c += 1;
        }
        Ok(())
    }

    fn mesh(&mut self, chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        let n = (chunk.indices.len() / 3) as u64;
        self.triangles += n;
        for &i in chunk.indices {
            self.bounds.grow(chunk.positions[i as usize]);
        }
        if let Some(c) = self.per_object.get_mut(chunk.object as usize) {
            *c += n;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A source made from a list of objects, each a list of triangles.
    struct ListSource(Vec<Vec<[[f64; 3]; 3]>>);

    impl TriangleSource for ListSource {
        fn name(&self) -> String {
            "list".into()
        }
        fn progress_total(&self) -> Option<u64> {
            None
        }
        fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
            for (o, tris) in self.0.iter().enumerate() {
                sink.object(o as u32, &ObjectInfo::default())?;
                for t in tris {
                    sink.triangle(&Triangle::new(*t, o as u32))?;
                }
            }
            Ok(SourceSummary { objects: self.0.len() as u32, ..Default::default() })
        }
    }

    const T: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    const LINE: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
    const REPEAT: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [2.0, 0.0, 0.0]];

    #[test]
    fn object_ids_stay_distinct_across_files_and_degenerates_are_counted() {
        let a = Box::new(ListSource(vec![vec![T, LINE], vec![T]]));
        let b = Box::new(ListSource(vec![vec![T, T, REPEAT]]));
        let mut stats = SceneStats::default();
        let s = Scene::from_sources(vec![a, b]).stream(&mut stats).unwrap();
        assert_eq!(s.objects, 3);
        assert_eq!(s.triangles, 4);
        assert_eq!(s.degenerate, 2);
        assert_eq!(stats.per_object, vec![1, 1, 2]);
    }

    #[test]
    fn non_finite_coordinates_are_errors() {
        let bad = [[0.0, 0.0, 0.0], [f64::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let a = Box::new(ListSource(vec![vec![T, bad]]));
        let e = Scene::from_sources(vec![a]).stream(&mut SceneStats::default()).unwrap_err();
        assert!(e.to_string().contains("triangle 2 has a non-finite"), "{e}");
    }
}
