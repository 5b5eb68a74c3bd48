//! terawalk input: every way triangles enter the system.
//!
//! All importers stream: they hand triangles to a [`TriangleSink`] as they parse, and never hold
//! the file in memory. Formats whose faces refer to vertices read earlier (OBJ, PLY) keep those
//! vertices in a [`vertex_store::VertexStore`], which spills to disk beyond a memory budget, so
//! files larger than RAM work in bounded memory.
//!
//! Main types:
//! - [`Triangle`]: positions in f64 (input coordinates), optional per-vertex normals and colours,
//!   and the id of the object it belongs to.
//! - [`TriangleSink`]: what a source pushes into (a statistics counter, a file writer, the build).
//! - [`open_source`]: detects the format of a file (gzip by magic bytes, then the format by its
//!   contents and extension) and returns a boxed [`TriangleSource`].
//! - [`Scene`]: several inputs streamed as one scene, object ids kept distinct, degenerate
//!   triangles dropped and counted.
//! - [`generate`]: the procedural power plant; [`write`](mod@write): PLY/OBJ/STL/GLB writers.
//! - [`convert`]: IFC, STEP/IGES, FBX, COLLADA, ... turned into OBJ/GLB by external tools
//!   (IfcOpenShell, Open CASCADE, assimp) for `terawalk build`.
//!
//! ```no_run
//! use tw_io::{Scene, SceneOptions, SceneStats};
//! let scene = Scene::open(&["plant.ply", "extra.obj.gz"], SceneOptions::default()).unwrap();
//! let mut stats = SceneStats::default();
//! let summary = scene.stream(&mut stats).unwrap();
//! println!("{} triangles in {} objects", stats.triangles, summary.objects);
//! ```

pub mod convert;
pub mod error;
pub mod format;
pub mod fuzz;
pub mod generate;
pub mod gltf;
pub mod input;
pub mod obj;
pub mod ply;
pub mod scene;
pub mod stl;
pub mod up;
pub mod vertex_store;
pub mod write;

pub use error::{ImportError, Position};
pub use format::{open_source, Format};
pub use scene::{Scene, SceneOptions, SceneStats, SceneSummary};

use std::ops::Range;

use tw_core::Rgba8;

/// Index of an object. Sources number their objects densely from 0 in the order they announce
/// them; a [`Scene`] offsets each file's ids so that objects of different files stay distinct.
pub type ObjectId = u32;

/// One triangle as an importer yields it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    /// Vertex positions in the input's coordinates and units.
    pub positions: [[f64; 3]; 3],
    /// Per-vertex normals when the file has them (not necessarily unit length).
    pub normals: Option<[[f32; 3]; 3]>,
    /// Per-vertex colours when the file has them. An object's colour (an OBJ material, a glTF
    /// base colour) is in [`ObjectInfo::color`] instead.
    pub colors: Option<[Rgba8; 3]>,
    /// The object this triangle belongs to; announced with [`TriangleSink::object`] first.
    pub object: ObjectId,
}

impl Triangle {
    pub fn new(positions: [[f64; 3]; 3], object: ObjectId) -> Triangle {
        Triangle { positions, normals: None, colors: None, object }
    }

    /// Twice the area (the length of the cross product of two edges).
    pub fn double_area(&self) -> f64 {
        self.double_area_squared().sqrt()
    }

    /// The square of [`Triangle::double_area`].
    #[inline]
    fn double_area_squared(&self) -> f64 {
        let [a, b, c] = self.positions;
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        n[0] * n[0] + n[1] * n[1] + n[2] * n[2]
    }

    /// A triangle with two equal vertices or zero area carries nothing visible.
    pub fn is_degenerate(&self) -> bool {
        let [a, b, c] = self.positions;
        // `double_area() == 0.0` without the square root: the sum of squares is 0 exactly when
        // its root is (and NaN, from overflowing coordinates, compares unequal either way).
        a == b || b == c || a == c || self.double_area_squared() == 0.0
    }
}

/// What a source says about an object when it first meets it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectInfo {
    /// The name in the file (OBJ `o`/`g`, glTF node or mesh name), or empty.
    pub name: String,
    /// The object's colour: an OBJ material's diffuse colour, a glTF base colour.
    pub color: Option<Rgba8>,
}

/// An indexed mesh chunk, for sources that naturally produce indexed geometry (the generator).
/// Writers that keep indices (PLY, OBJ, GLB) override [`TriangleSink::mesh`]; everyone else gets
/// it expanded into triangles.
#[derive(Clone, Copy, Debug)]
pub struct MeshChunk<'a> {
    pub object: ObjectId,
    pub positions: &'a [[f64; 3]],
    /// Three indices into `positions` per triangle; every index is `< positions.len()`.
    pub indices: &'a [u32],
}

/// Receives what a source streams. Sources call [`TriangleSink::object`] for an object before
/// any of its triangles.
pub trait TriangleSink {
    /// A new object, with the id its triangles will carry.
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError>;

    /// One triangle.
    fn triangle(&mut self, triangle: &Triangle) -> Result<(), ImportError>;

    /// An indexed chunk. The default expands it into [`TriangleSink::triangle`] calls.
    fn mesh(&mut self, chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        for t in chunk.indices.chunks_exact(3) {
            let p = |i: u32| chunk.positions[i as usize];
            self.triangle(&Triangle::new([p(t[0]), p(t[1]), p(t[2])], chunk.object))?;
        }
        Ok(())
    }

    /// A run of triangles the sink may resolve in any order and on several threads (the binary
    /// PLY reader hands its faces over this way). The default announces each of
    /// [`TriangleBatch::new_objects`] just before its first triangle and passes the triangles to
    /// [`TriangleSink::triangle`] in order, exactly as if the source had streamed them one by
    /// one. A sink that overrides it must give the same result, fetch every triangle of the
    /// batch exactly once (unless it stops at an error) and treat the batch's objects as
    /// announced before its first triangle.
    fn batch(&mut self, batch: &dyn TriangleBatch) -> Result<(), ImportError> {
        let mut tris = Vec::new();
        let mut done = 0;
        for o in batch.new_objects() {
            for start in (done..o.first.min(batch.len())).step_by(BATCH_STEP) {
                tris.clear();
                batch.triangles(start..(start + BATCH_STEP).min(o.first), &mut tris)?;
                tris.iter().try_for_each(|t| self.triangle(t))?;
            }
            done = done.max(o.first.min(batch.len()));
            self.object(o.id, &o.info)?;
        }
        for start in (done..batch.len()).step_by(BATCH_STEP) {
            tris.clear();
            batch.triangles(start..(start + BATCH_STEP).min(batch.len()), &mut tris)?;
            tris.iter().try_for_each(|t| self.triangle(t))?;
        }
        Ok(())
    }

    /// How far the source has got: bytes of the input file consumed (compressed bytes for a .gz),
    /// or for a generator the triangles produced. Called now and then, for progress bars.
    fn progress(&mut self, _done: u64) {}
}

/// Triangles fetched from a [`TriangleBatch`] at a time by the default [`TriangleSink::batch`]
/// (a few KiB: they are written and read back while in the cache).
pub const BATCH_STEP: usize = 64;

/// Triangles in input order that can be fetched by index ranges from any thread: what
/// [`TriangleSink::batch`] receives. Fetching is pure: the same range gives the same answer.
pub trait TriangleBatch: Sync {
    /// Triangles in the batch, before any are dropped (see [`TriangleBatch::triangles`]).
    fn len(&self) -> usize;

    /// True when the batch holds no triangles.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Appends to `out` the triangles of `range` (within `0..len()`), in order. A source yields
    /// every one; a [`Scene`] drops the degenerate ones on the way. Ranges of about
    /// [`BATCH_STEP`] keep the triangles in the cache between this and their use.
    fn triangles(&self, range: Range<usize>, out: &mut Vec<Triangle>) -> Result<(), ImportError>;

    /// Objects announced in this batch, in id order, each with the index of its first triangle.
    fn new_objects(&self) -> &[NewObject];
}

/// An object first met inside a [`TriangleBatch`].
#[derive(Clone, Debug, PartialEq)]
pub struct NewObject {
    /// Index in the batch of the object's first triangle (`len()` when it has none there).
    pub first: usize,
    pub id: ObjectId,
    pub info: ObjectInfo,
}

/// A stream of triangles from one file or generator.
pub trait TriangleSource {
    /// A name for messages: the file's path, or a description of the generator.
    fn name(&self) -> String;

    /// The total that [`TriangleSink::progress`] counts towards, when known.
    fn progress_total(&self) -> Option<u64>;

    /// Streams every object and triangle into `sink`, in file order. Consumes the source.
    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError>;
}

/// What a source reports when it has streamed everything.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SourceSummary {
    /// Objects announced.
    pub objects: u32,
    /// Vertices the file declares or defined (for statistics; STL counts 3 per triangle).
    pub vertices: u64,
    /// Bytes read from disk (compressed bytes for a .gz).
    pub bytes: u64,
}
