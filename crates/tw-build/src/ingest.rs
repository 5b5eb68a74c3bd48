//! Phase 1, ingest: streams every input triangle into one on-disk working file and computes the
//! scene bounds, the scene-wide [`Grid`] and one [`ObjectRecord`] per input object
//! (GigaWalk §4.2 starts from "the objects in the initial database"; docs/BUILD.md, phase 1).
//!
//! # Working file
//!
//! One record of [`RECORD_BYTES`] = 40 bytes per triangle, in input order, little endian:
//! three vertices of three `f32` each, relative to a *provisional origin* (the first vertex of the
//! scene, kept in f64), then the `u32` object id. Nothing else of a triangle is kept (no normals,
//! no per-vertex colours: docs/DESIGN.md, D11).
//!
//! # Precision, and why borders still never crack
//!
//! Every later phase sees a vertex as `origin + (offset as f64)`, the *reconstructed* position,
//! and quantizes that to the grid. The reconstruction differs from the input by at most half an
//! f32 ulp of the offset (about 2^-25 of the scene extent, half a grid step at worst). What
//! matters for crack-free borders is that equal input coordinates give equal grid points, and
//! they do: the same f64 always gives the same f32 offset, hence the same reconstruction and the
//! same grid point, in whichever object or cell it appears. The scene bounds, the grid and the
//! object bounds are computed from the reconstructed positions too, so an object's
//! [`GridBox`] contains every quantized vertex of its triangles exactly (quantization is
//! monotone).
//!
//! # Threads
//!
//! Sources that hand over [`TriangleBatch`]es (binary PLY) have them converted to records on the
//! pool, `PIECE` triangles per task, while a pool thread appends the previous batch's pieces
//! in order (`append`): the working file, the bounds and the object records are those of the
//! one-by-one path, whatever the thread count.
//!
//! Each object's record also keeps what redefinition's pass B would otherwise read the file
//! for, for the objects it does not cut: the box of its vertices' offsets and the sum of its
//! triangles' centroids, added one triangle at a time in file order (pieces compute the
//! centroids in parallel; they are summed as the pieces are appended, in order).
//!
//! Memory: O(objects) (one record per object) and two batches' records; the triangles go to
//! disk as they arrive.

use std::path::Path;

use rayon::prelude::*;
use tempfile::TempPath;
use tw_io::scene::SceneProgress;
use tw_io::up::UpVotes;
use tw_io::{
    ImportError, MeshChunk, ObjectId, ObjectInfo, Scene, SceneSummary, Triangle, TriangleBatch, TriangleSink,
    BATCH_STEP,
};

use crate::error::BuildError;
use crate::parts::ObjectParts;
use crate::sampling::{CentroidSamples, OnlineSampler};
use crate::types::{Grid, GridBox, ObjectRecord};
use crate::workio::SpillWriter;

/// Bytes per triangle in the working file: 9 × f32 + u32 object id.
pub const RECORD_BYTES: usize = 40;

/// Triangles decoded per chunk by `WorkFile::scan` (2.5 MiB of records).
pub const SCAN_CHUNK: usize = 1 << 16;

/// Triangles of a [`TriangleBatch`] that one task of the pool converts to records.
const PIECE: usize = 4096;

/// One triangle of the working file: positions relative to [`WorkFile::origin`] (input units).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WorkTri {
    pub p: [[f32; 3]; 3],
    pub object: u32,
}

impl WorkTri {
    /// The centroid, computed the one way every phase uses (split plans compare it to planes,
    /// so plan building and triangle assignment must agree bit for bit).
    #[inline]
    pub fn centroid(&self) -> [f32; 3] {
        let [a, b, c] = self.p;
        [(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0, (a[2] + b[2] + c[2]) / 3.0]
    }

    fn encode(&self, out: &mut [u8; RECORD_BYTES]) {
        for (k, v) in self.p.iter().flatten().enumerate() {
            out[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
        out[36..40].copy_from_slice(&self.object.to_le_bytes());
    }

    /// The triangle of one working-file record ([`RECORD_BYTES`] bytes).
    #[inline]
    pub fn decode(b: &[u8]) -> WorkTri {
        let f = |k: usize| f32::from_le_bytes([b[4 * k], b[4 * k + 1], b[4 * k + 2], b[4 * k + 3]]);
        WorkTri {
            p: [[f(0), f(1), f(2)], [f(3), f(4), f(5)], [f(6), f(7), f(8)]],
            object: u32::from_le_bytes([b[36], b[37], b[38], b[39]]),
        }
    }
}

/// The working file of all triangles (deleted when dropped).
#[derive(Debug)]
pub struct WorkFile {
    path: TempPath,
    /// The provisional origin: every stored position is relative to it.
    pub origin: [f64; 3],
    /// Number of triangle records.
    pub triangles: u64,
}

impl WorkFile {
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The reconstructed input position of a stored offset.
    #[inline]
    pub fn position(&self, off: [f32; 3]) -> [f64; 3] {
        [self.origin[0] + off[0] as f64, self.origin[1] + off[1] as f64, self.origin[2] + off[2] as f64]
    }

    /// The grid point of a stored offset: the same offset always gives the same point.
    #[inline]
    pub fn quantize(&self, grid: &Grid, off: [f32; 3]) -> [u32; 3] {
        grid.quantize(self.position(off))
    }

    /// Reads every record in order, handing out chunks of up to [`SCAN_CHUNK`] triangles with the
    /// index of the chunk's first triangle. Memory: one chunk.
    #[cfg(test)]
    pub fn scan(&self, f: impl FnMut(u64, &[WorkTri]) -> Result<(), BuildError>) -> Result<(), BuildError> {
        crate::workio::read_ahead(&self.path, self.triangles, RECORD_BYTES, SCAN_CHUNK, WorkTri::decode, f)
    }

    /// Like `WorkFile::scan`, but hands out each chunk's raw records ([`RECORD_BYTES`] each;
    /// [`WorkTri::decode`], [`record_object`]) undecoded: the reader thread only reads, and the
    /// caller decodes and processes the chunk on the pool ([`crate::workio::map_sub_chunks`]).
    pub fn scan_raw(&self, f: impl FnMut(u64, &[u8]) -> Result<(), BuildError>) -> Result<(), BuildError> {
        crate::workio::read_ahead_raw(&self.path, self.triangles, RECORD_BYTES, SCAN_CHUNK, f)
    }

    /// [`WorkFile::scan_raw`] over the triangles of `ranges` only, in the order given (each
    /// range read on its own: nothing between them is read).
    pub fn scan_ranges_raw(
        &self,
        ranges: &[std::ops::Range<u64>],
        f: impl FnMut(u64, &[u8]) -> Result<(), BuildError>,
    ) -> Result<(), BuildError> {
        crate::workio::read_ranges_raw(&self.path, self.triangles, ranges, RECORD_BYTES, SCAN_CHUNK, f)
    }
}

/// The object id of record `k` of raw working-file records (see [`WorkFile::scan_raw`]).
#[inline]
pub fn record_object(bytes: &[u8], k: usize) -> u32 {
    let o = k * RECORD_BYTES + 36;
    u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]])
}

/// The triangles of raw working-file records, in order.
pub fn records(bytes: &[u8]) -> impl Iterator<Item = WorkTri> + '_ {
    bytes.chunks_exact(RECORD_BYTES).map(WorkTri::decode)
}

/// What ingest produced: the working file, the grid, the objects.
#[derive(Debug)]
pub struct Ingested {
    pub work: WorkFile,
    /// Scene bounds (reconstructed input coordinates; see the module docs).
    pub min: [f64; 3],
    pub max: [f64; 3],
    pub grid: Grid,
    /// One record per input object, indexed by object id (objects whose triangles were all
    /// degenerate have 0 triangles and [`GridBox::EMPTY`] bounds).
    pub objects: Vec<ObjectRecord>,
    /// Triangles in the working file.
    pub triangles: u64,
    /// What streaming the inputs found (files, degenerate triangles dropped, bytes read).
    pub summary: SceneSummary,
    /// Redefinition's centroid samples, taken while streaming ([`crate::sampling`]): `None`
    /// when ingest was given no rule or the sampler gave up; taken by the first
    /// [`crate::redefine::redefine`] whose rule they follow.
    pub samples: std::sync::Mutex<Option<CentroidSamples>>,
    /// The `--up auto` statistic ([`tw_io::up::UpVotes`]) over every triangle in input order,
    /// when asked for ([`ingest_voting`]).
    pub up_votes: Option<UpVotes>,
}

/// Streams `scene` into a working file created in `work_dir` (which must exist). `progress` is
/// called now and then with how far the reading has got. Batches of triangles
/// ([`TriangleSink::batch`]) are converted on rayon's global pool.
#[cfg(test)]
pub fn ingest(
    scene: Scene,
    work_dir: &Path,
    progress: &mut dyn FnMut(SceneProgress),
) -> Result<Ingested, BuildError> {
    ingest_in(scene, work_dir, None, None, progress)
}

/// [`ingest`], converting batches on `pool` (the global pool when `None`), and taking
/// redefinition's centroid samples with `sampler` on the way. The working file is the same
/// whatever the pool.
#[cfg(test)]
pub fn ingest_in(
    scene: Scene,
    work_dir: &Path,
    pool: Option<&rayon::ThreadPool>,
    sampler: Option<OnlineSampler>,
    progress: &mut dyn FnMut(SceneProgress),
) -> Result<Ingested, BuildError> {
    ingest_voting(scene, work_dir, pool, sampler, false, progress)
}

/// `ingest_in`, also taking the `--up auto` statistic when `up_votes` (one cross product
/// per triangle, in the in-order append step, so the votes are the same whatever the pool).
pub fn ingest_voting(
    scene: Scene,
    work_dir: &Path,
    pool: Option<&rayon::ThreadPool>,
    sampler: Option<OnlineSampler>,
    up_votes: bool,
    progress: &mut dyn FnMut(SceneProgress),
) -> Result<Ingested, BuildError> {
    let path = crate::workio::temp_path(work_dir, "tw-triangles-")?;
    let mut sink = IngestSink {
        pool,
        out: SpillWriter::direct(vec![path.to_path_buf()], 1 << 20)?,
        origin: None,
        objects: Vec::new(),
        triangles: 0,
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
        failure: None,
        scratch: Vec::new(),
        pieces: Vec::new(),
        pending: Vec::new(),
        pending_count: 0,
        sampler,
        parts: ObjectParts::default(),
        votes: up_votes.then(UpVotes::default),
    };
    let streamed = scene.stream_with_progress(&mut sink, progress);
    // The last batch's triangles; their errors come before any the stream stopped at later.
    let appended = sink.flush();
    if let Some(e) = sink.failure.take() {
        return Err(e);
    }
    appended?;
    let summary = streamed?;
    drop(sink.out.finish()?);
    let Some(origin) = sink.origin else { return Err(BuildError::Empty) };
    let work = WorkFile { path, origin, triangles: sink.triangles };
    let counts: Vec<u64> = sink.objects.iter().map(|o| o.triangles).collect();
    let sampled = sink.sampler.is_some();
    let samples = sink.sampler.take().and_then(|s| s.finish(&counts));
    if sampled {
        tracing::debug!(online = samples.is_some(), "ingest: centroid samples");
    }
    let (min, max) = (work.position(sink.min), work.position(sink.max));
    let grid = Grid::for_bounds(min, max);
    let mut part_starts = std::mem::take(&mut sink.parts).finish();
    let objects = sink
        .objects
        .into_iter()
        .enumerate()
        .map(|(i, o)| ObjectRecord {
            part_starts: part_starts.remove(&(i as u32)).unwrap_or_default(),
            name: o.name,
            color: o.color,
            triangles: o.triangles,
            offset_min: o.min,
            offset_max: o.max,
            centroid_sum: o.sum,
            span: o.span,
            bounds: if o.triangles == 0 {
                GridBox::EMPTY
            } else {
                GridBox { min: work.quantize(&grid, o.min), max: work.quantize(&grid, o.max) }
            },
        })
        .collect();
    Ok(Ingested {
        triangles: work.triangles,
        work,
        min,
        max,
        grid,
        objects,
        summary,
        samples: std::sync::Mutex::new(samples),
        up_votes: sink.votes,
    })
}

struct ObjectAcc {
    name: String,
    color: Option<[u8; 4]>,
    triangles: u64,
    min: [f32; 3],
    max: [f32; 3],
    /// Centroids summed one triangle at a time in file order (see [`ObjectRecord::centroid_sum`]).
    sum: [f64; 3],
    span: std::ops::Range<u64>,
}

impl ObjectAcc {
    #[inline]
    fn add_centroid(&mut self, c: [f32; 3]) {
        for (s, x) in self.sum.iter_mut().zip(c) {
            *s += x as f64;
        }
    }

    /// Extends the span by `n` triangles from the file's triangle `at` on.
    #[inline]
    fn extend_span(&mut self, at: u64, n: u64) {
        if self.span.is_empty() {
            self.span.start = at;
        }
        self.span.end = at + n;
    }
}

struct IngestSink<'p> {
    pool: Option<&'p rayon::ThreadPool>,
    out: SpillWriter,
    origin: Option<[f64; 3]>,
    objects: Vec<ObjectAcc>,
    triangles: u64,
    min: [f32; 3],
    max: [f32; 3],
    /// The real error behind an [`ImportError::Sink`] we returned (an I/O error on our file).
    failure: Option<BuildError>,
    scratch: Vec<[f32; 3]>,
    /// Reused pieces of [`TriangleSink::batch`]: those being converted, and the previous
    /// batch's, converted but not yet appended (the first `pending_count`).
    pieces: Vec<Piece>,
    pending: Vec<Piece>,
    pending_count: usize,
    sampler: Option<OnlineSampler>,
    /// Where big objects pass from one group of closed parts to the next.
    parts: ObjectParts,
    /// The `--up auto` statistic, when asked for.
    votes: Option<UpVotes>,
}

/// The stored offset of `p` from the origin `o`, or why it cannot be stored.
#[inline]
fn offset_from(o: [f64; 3], p: [f64; 3]) -> Result<[f32; 3], BuildError> {
    let off = [(p[0] - o[0]) as f32, (p[1] - o[1]) as f32, (p[2] - o[2]) as f32];
    if off.iter().any(|v| !v.is_finite()) {
        let msg = format!(
            "vertex {p:?} is too far from the scene's first vertex {o:?} for the working format (f32)"
        );
        return Err(BuildError::Limit(msg));
    }
    Ok(off)
}

/// Appends converted pieces in order: their records to `out`, their counts and bounds to the
/// objects' and the scene's (in the order the one-by-one path folds them). Stops at the first
/// piece that failed.
#[allow(clippy::too_many_arguments)]
fn append(
    pieces: &mut [Piece],
    out: &mut SpillWriter,
    objects: &mut [ObjectAcc],
    triangles: &mut u64,
    scene_min: &mut [f32; 3],
    scene_max: &mut [f32; 3],
    sampler: &mut Option<OnlineSampler>,
    parts: &mut ObjectParts,
    votes: &mut Option<UpVotes>,
) -> Result<(), PieceError> {
    for p in pieces {
        if let Some(e) = p.error.take() {
            return Err(e);
        }
        let mut first = 0;
        for &(object, n, min, max) in &p.runs {
            let acc = &mut objects[object as usize];
            let seen = acc.triangles > 0;
            for k in first..first + n as usize {
                let t = WorkTri::decode(&p.bytes[k * RECORD_BYTES..(k + 1) * RECORD_BYTES]);
                parts.add(object, t.p, || seen);
                if let Some(v) = votes.as_mut() {
                    v.add(widen(t.p));
                }
            }
            acc.triangles += n;
            acc.extend_span(*triangles, n);
            let centroids = &p.centroids[first..first + n as usize];
            first += n as usize;
            for &c in centroids {
                acc.add_centroid(c);
            }
            if let Some(s) = sampler.as_mut() {
                s.add_run(object, centroids);
            }
            for i in 0..3 {
                acc.min[i] = acc.min[i].min(min[i]);
                acc.max[i] = acc.max[i].max(max[i]);
                scene_min[i] = scene_min[i].min(acc.min[i]);
                scene_max[i] = scene_max[i].max(acc.max[i]);
            }
            *triangles += n;
        }
        out.write(0, &p.bytes).map_err(PieceError::Build)?;
    }
    Ok(())
}

/// A triangle of stored offsets in f64 (the up statistic needs only its edges).
#[inline]
fn widen(p: [[f32; 3]; 3]) -> [[f64; 3]; 3] {
    p.map(|v| v.map(f64::from))
}

/// Why a piece stopped: the source's error, or ours.
enum PieceError {
    Import(ImportError),
    Build(BuildError),
}

/// A run of triangles of a batch converted on one thread: their records, in order, and per
/// run of consecutive triangles of one object its count and bounds; merged in batch order, so
/// the working file and every figure are those of the one-by-one path, whatever the threads.
#[derive(Default)]
struct Piece {
    range: std::ops::Range<usize>,
    bytes: Vec<u8>,
    /// (object, triangles, min, max) per run of one object.
    runs: Vec<(ObjectId, u64, [f32; 3], [f32; 3])>,
    /// Each triangle's centroid, in order (summed per object when appended).
    centroids: Vec<[f32; 3]>,
    error: Option<PieceError>,
}

impl Piece {
    /// Converts the piece's triangles of `batch` with the scene origin `origin`; `objects` are
    /// the objects announced.
    fn fill(&mut self, batch: &dyn TriangleBatch, origin: [f64; 3], objects: usize) {
        self.bytes.clear();
        self.runs.clear();
        self.centroids.clear();
        self.error = None;
        let mut tris = Vec::with_capacity(BATCH_STEP);
        for start in self.range.clone().step_by(BATCH_STEP) {
            tris.clear();
            if let Err(e) = batch.triangles(start..(start + BATCH_STEP).min(self.range.end), &mut tris) {
                self.error = Some(PieceError::Import(e));
                return;
            }
            if let Err(e) = self.push(&tris, origin, objects) {
                self.error = Some(e);
                return;
            }
        }
    }

    /// Converts and appends `tris`.
    #[inline]
    fn push(&mut self, tris: &[Triangle], origin: [f64; 3], objects: usize) -> Result<(), PieceError> {
        for t in tris {
            if t.object as usize >= objects {
                let msg = format!("triangle of unannounced object {}", t.object);
                return Err(PieceError::Import(ImportError::Sink(msg)));
            }
            let mut p = [[0f32; 3]; 3];
            for (q, &v) in p.iter_mut().zip(&t.positions) {
                *q = offset_from(origin, v).map_err(PieceError::Build)?;
            }
            match self.runs.last_mut() {
                Some(run) if run.0 == t.object => run.1 += 1,
                _ => self.runs.push((t.object, 1, [f32::INFINITY; 3], [f32::NEG_INFINITY; 3])),
            }
            let run = self.runs.last_mut().expect("pushed above");
            for v in &p {
                for (i, &x) in v.iter().enumerate() {
                    run.2[i] = run.2[i].min(x);
                    run.3[i] = run.3[i].max(x);
                }
            }
            let mut rec = [0u8; RECORD_BYTES];
            let tri = WorkTri { p, object: t.object };
            tri.encode(&mut rec);
            self.bytes.extend_from_slice(&rec);
            self.centroids.push(tri.centroid());
        }
        Ok(())
    }
}

impl IngestSink<'_> {
    fn piece_failed(&mut self, e: PieceError) -> ImportError {
        match e {
            PieceError::Import(e) => e,
            PieceError::Build(e) => self.fail(e),
        }
    }

    /// Appends the last batch's pieces, before anything else is written.
    fn flush(&mut self) -> Result<(), ImportError> {
        let n = std::mem::take(&mut self.pending_count);
        if n == 0 {
            return Ok(());
        }
        let IngestSink { out, objects, triangles, min, max, pending, sampler, parts, votes, .. } = self;
        append(&mut pending[..n], out, objects, triangles, min, max, sampler, parts, votes)
            .map_err(|e| self.piece_failed(e))
    }

    fn fail(&mut self, e: BuildError) -> ImportError {
        let msg = e.to_string();
        self.failure = Some(e);
        ImportError::Sink(msg)
    }

    #[inline]
    fn offset(&mut self, p: [f64; 3]) -> Result<[f32; 3], ImportError> {
        let o = *self.origin.get_or_insert(p);
        offset_from(o, p).map_err(|e| self.fail(e))
    }

    #[inline]
    fn push(&mut self, p: [[f32; 3]; 3], object: ObjectId) -> Result<(), ImportError> {
        let Some(acc) = self.objects.get_mut(object as usize) else {
            return Err(ImportError::Sink(format!("triangle of unannounced object {object}")));
        };
        self.parts.add(object, p, || acc.triangles > 0);
        if let Some(v) = self.votes.as_mut() {
            v.add(widen(p));
        }
        acc.triangles += 1;
        for v in &p {
            for (i, &x) in v.iter().enumerate() {
                acc.min[i] = acc.min[i].min(x);
                acc.max[i] = acc.max[i].max(x);
            }
        }
        let tri = WorkTri { p, object };
        acc.add_centroid(tri.centroid());
        acc.extend_span(self.triangles, 1);
        if let Some(s) = self.sampler.as_mut() {
            s.add(object, tri.centroid());
        }
        for i in 0..3 {
            self.min[i] = self.min[i].min(acc.min[i]);
            self.max[i] = self.max[i].max(acc.max[i]);
        }
        let mut rec = [0u8; RECORD_BYTES];
        tri.encode(&mut rec);
        if let Err(e) = self.out.write(0, &rec) {
            return Err(self.fail(e));
        }
        self.triangles += 1;
        Ok(())
    }
}

impl TriangleSink for IngestSink<'_> {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        if id as usize != self.objects.len() {
            return Err(ImportError::Sink(format!(
                "object {id} announced out of order (expected {})",
                self.objects.len()
            )));
        }
        self.objects.push(ObjectAcc {
            name: info.name.clone(),
            color: info.color.map(|c| c.0),
            triangles: 0,
            min: [f32::INFINITY; 3],
            max: [f32::NEG_INFINITY; 3],
            sum: [0.0; 3],
            span: 0..0,
        });
        Ok(())
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.flush()?;
        let p = [self.offset(t.positions[0])?, self.offset(t.positions[1])?, self.offset(t.positions[2])?];
        self.push(p, t.object)
    }

    /// Converts the batch's triangles on the pool's threads, [`PIECE`] at a time, while the
    /// previous batch's pieces are appended in order; this batch's are appended by the next
    /// call or by `flush`. The same records and figures as [`IngestSink::triangle`] one by one.
    fn batch(&mut self, batch: &dyn TriangleBatch) -> Result<(), ImportError> {
        for o in batch.new_objects() {
            self.object(o.id, &o.info)?;
        }
        // The scene's first vertex is the origin of all the others.
        let n = batch.len();
        let mut first = 0;
        while self.origin.is_none() && first < n {
            let mut t = Vec::with_capacity(1);
            batch.triangles(first..first + 1, &mut t)?;
            if let Some(t) = t.first() {
                self.triangle(t)?;
            }
            first += 1;
        }
        let Some(origin) = self.origin else { return Ok(()) };
        let count = (n - first).div_ceil(PIECE);
        self.pieces.resize_with(count.max(self.pieces.len()), Piece::default);
        for (k, p) in self.pieces[..count].iter_mut().enumerate() {
            p.range = first + k * PIECE..(first + (k + 1) * PIECE).min(n);
        }
        // Convert this batch while a thread of the pool appends the previous one.
        let objects = self.objects.len();
        let pending = std::mem::take(&mut self.pending_count);
        let IngestSink {
            pool,
            out,
            objects: accs,
            triangles,
            min,
            max,
            pieces,
            pending: done,
            sampler,
            parts,
            votes,
            ..
        } = self;
        let (work, done) = (&mut pieces[..count], &mut done[..pending]);
        let mut both = || {
            rayon::join(
                || work.par_iter_mut().for_each(|p| p.fill(batch, origin, objects)),
                || append(done, out, accs, triangles, min, max, sampler, parts, votes),
            )
            .1
        };
        let appended = match pool {
            Some(pool) => pool.install(both),
            None => both(),
        };
        std::mem::swap(&mut self.pieces, &mut self.pending);
        self.pending_count = count;
        appended.map_err(|e| self.piece_failed(e))
    }

    fn mesh(&mut self, chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        self.flush()?;
        // Convert each shared vertex once.
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        for &p in chunk.positions {
            match self.offset(p) {
                Ok(o) => scratch.push(o),
                Err(e) => {
                    self.scratch = scratch;
                    return Err(e);
                }
            }
        }
        let mut result = Ok(());
        for t in chunk.indices.chunks_exact(3) {
            let v = |i: u32| scratch.get(i as usize).copied();
            let (Some(a), Some(b), Some(c)) = (v(t[0]), v(t[1]), v(t[2])) else {
                result = Err(ImportError::Sink(format!(
                    "mesh chunk of object {} has an index out of range",
                    chunk.object
                )));
                break;
            };
            result = self.push([a, b, c], chunk.object);
            if result.is_err() {
                break;
            }
        }
        self.scratch = scratch;
        result
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use tw_io::{SourceSummary, TriangleSource};

    /// A source from a list of objects, each a name, a colour and its triangles.
    /// An object of a [`ListSource`]: name, colour, triangles.
    pub(crate) type ListObject = (String, Option<[u8; 4]>, Vec<[[f64; 3]; 3]>);

    pub(crate) struct ListSource(pub Vec<ListObject>);

    impl TriangleSource for ListSource {
        fn name(&self) -> String {
            "list".into()
        }
        fn progress_total(&self) -> Option<u64> {
            None
        }
        fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
            let n = self.0.len() as u32;
            for (id, (name, color, tris)) in self.0.into_iter().enumerate() {
                sink.object(id as u32, &ObjectInfo { name, color: color.map(tw_core::Rgba8) })?;
                for t in tris {
                    sink.triangle(&Triangle::new(t, id as u32))?;
                }
            }
            Ok(SourceSummary { objects: n, vertices: 0, bytes: 0 })
        }
    }

    pub(crate) fn ingest_list(dir: &Path, objects: Vec<ListObject>) -> Ingested {
        ingest(Scene::from_sources(vec![Box::new(ListSource(objects))]), dir, &mut |_| {}).unwrap()
    }

    pub(crate) fn ingest_plant(dir: &Path, triangles: u64) -> Ingested {
        let src =
            tw_io::generate::PlantSource::new(tw_io::generate::PlantParams { triangles, seed: 7 }).unwrap();
        ingest(Scene::from_sources(vec![Box::new(src)]), dir, &mut |_| {}).unwrap()
    }

    fn all(work: &WorkFile) -> Vec<WorkTri> {
        let mut v = Vec::new();
        work.scan(|first, c| {
            assert_eq!(first, v.len() as u64);
            v.extend_from_slice(c);
            Ok(())
        })
        .unwrap();
        v
    }

    #[test]
    fn ingest_round_trip_keeps_triangles_objects_and_bounds() {
        let dir = tempfile::tempdir().unwrap();
        let t = |x: f64| [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 2.0, 3.0]];
        let degenerate = [[5.0, 5.0, 5.0], [5.0, 5.0, 5.0], [6.0, 6.0, 6.0]];
        let ing = ingest_list(
            dir.path(),
            vec![
                ("a".into(), Some([1, 2, 3, 4]), vec![t(10.0), t(20.0)]),
                ("only degenerate".into(), None, vec![degenerate]),
                ("b".into(), None, vec![t(-5.0)]),
            ],
        );
        assert_eq!(ing.triangles, 3);
        assert_eq!(ing.summary.degenerate, 1);
        assert_eq!(ing.min, [-5.0, 0.0, 0.0]);
        assert_eq!(ing.max, [21.0, 2.0, 3.0]);
        assert_eq!(ing.grid, Grid::for_bounds([-5.0, 0.0, 0.0], [21.0, 2.0, 3.0]));
        assert_eq!(ing.objects.len(), 3);
        assert_eq!(ing.objects[0].name, "a");
        assert_eq!(ing.objects[0].color, Some([1, 2, 3, 4]));
        assert_eq!(ing.objects[0].triangles, 2);
        assert_eq!(ing.objects[0].bounds.min, ing.grid.quantize([10.0, 0.0, 0.0]));
        assert_eq!(ing.objects[0].bounds.max, ing.grid.quantize([21.0, 2.0, 3.0]));
        assert_eq!(ing.objects[1].triangles, 0);
        assert!(ing.objects[1].bounds.is_empty());
        assert_eq!(ing.objects[2].color, None);
        let tris = all(&ing.work);
        assert_eq!(tris.len(), 3);
        assert_eq!(tris.iter().map(|t| t.object).collect::<Vec<_>>(), vec![0, 0, 2]);
        // Small integers survive the f32 offsets exactly.
        assert_eq!(ing.work.position(tris[1].p[1]), [21.0, 0.0, 0.0]);
        assert_eq!(std::fs::metadata(ing.work.path()).unwrap().len(), 3 * RECORD_BYTES as u64);
    }

    #[test]
    fn equal_input_coordinates_quantize_to_equal_grid_points() {
        let dir = tempfile::tempdir().unwrap();
        // An awkward shared vertex, far from the provisional origin, used by two objects.
        let shared = [1234.567891234, -0.000123456789, 98.7654321];
        let ing = ingest_list(
            dir.path(),
            vec![
                ("o".into(), None, vec![[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]]),
                ("a".into(), None, vec![[shared, [1500.0, 0.0, 0.0], [1400.0, 50.0, 0.0]]]),
                ("b".into(), None, vec![[[1300.0, 9.0, 0.0], shared, [1400.0, -50.0, 20.0]]]),
            ],
        );
        let tris = all(&ing.work);
        let qa = ing.work.quantize(&ing.grid, tris[1].p[0]);
        let qb = ing.work.quantize(&ing.grid, tris[2].p[1]);
        assert_eq!(qa, qb);
        // ... and within a grid step of the direct quantization of the input.
        let direct = ing.grid.quantize(shared);
        for i in 0..3 {
            assert!(qa[i].abs_diff(direct[i]) <= 1, "{qa:?} vs {direct:?}");
        }
        // Object bounds contain their quantized vertices.
        for t in &tris {
            let b = ing.objects[t.object as usize].bounds;
            for v in t.p {
                let q = ing.work.quantize(&ing.grid, v);
                assert!(b.contains(&GridBox { min: q, max: q }));
            }
        }
    }

    #[test]
    fn empty_scene_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let src = ListSource(vec![("nothing".into(), None, vec![])]);
        let r = ingest(Scene::from_sources(vec![Box::new(src)]), dir.path(), &mut |_| {});
        assert!(matches!(r, Err(BuildError::Empty)));
    }

    #[test]
    fn coordinates_beyond_f32_offsets_are_a_limit_error() {
        let dir = tempfile::tempdir().unwrap();
        let src = ListSource(vec![(
            "huge".into(),
            None,
            vec![
                [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                [[1e300, 0.0, 0.0], [0.0; 3], [0.0, 1.0, 1.0]],
            ],
        )]);
        let r = ingest(Scene::from_sources(vec![Box::new(src)]), dir.path(), &mut |_| {});
        assert!(matches!(r, Err(BuildError::Limit(_))), "{r:?}");
    }

    #[test]
    fn generated_mesh_chunks_are_ingested_whole() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 20_000);
        assert_eq!(ing.triangles, 20_000);
        let per_object: u64 = ing.objects.iter().map(|o| o.triangles).sum();
        assert_eq!(per_object, 20_000);
        let tris = all(&ing.work);
        for t in &tris {
            let b = ing.objects[t.object as usize].bounds;
            for v in t.p {
                let q = ing.work.quantize(&ing.grid, v);
                assert!(b.contains(&GridBox { min: q, max: q }));
            }
        }
    }

    #[test]
    fn a_truncated_working_file_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 10_000);
        let f = std::fs::OpenOptions::new().write(true).open(ing.work.path()).unwrap();
        f.set_len(100).unwrap();
        let r = ing.work.scan(|_, _| Ok(()));
        assert!(matches!(r, Err(BuildError::Corrupt { .. })), "{r:?}");
    }

    /// Streams a source's triangles one by one (the sink's `batch` is never called).
    struct OneByOne(Box<dyn TriangleSource>);

    struct Forward<'a>(&'a mut dyn TriangleSink);

    impl TriangleSink for Forward<'_> {
        fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
            self.0.object(id, info)
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.0.triangle(t)
        }
    }

    impl TriangleSource for OneByOne {
        fn name(&self) -> String {
            self.0.name()
        }
        fn progress_total(&self) -> Option<u64> {
            None
        }
        fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
            self.0.stream(&mut Forward(sink))
        }
    }

    #[test]
    fn batches_give_the_working_file_of_one_by_one_whatever_the_threads() {
        let dir = tempfile::tempdir().unwrap();
        let ply = dir.path().join("plant.ply");
        let mut w = tw_io::write::create_writer(&ply).unwrap();
        let plant =
            tw_io::generate::PlantSource::new(tw_io::generate::PlantParams { triangles: 150_000, seed: 3 })
                .unwrap();
        Box::new(plant).stream(&mut *w).unwrap();
        w.finish().unwrap();
        let options = tw_io::format::ImportOptions { vertex_memory: 1 << 18, spill_dir: None };
        let open = || tw_io::open_source(&ply, &options).unwrap();
        // A sample budget small enough that the global stride doubles several times.
        let rule = crate::sampling::SampleRule { t1: 1000, max_samples: 3000, min_samples_per_object: 16 };
        let sampler = || Some(OnlineSampler::new(rule, 1 << 30));
        let one_by_one = ingest_in(
            Scene::from_sources(vec![Box::new(OneByOne(open()))]),
            dir.path(),
            None,
            sampler(),
            &mut |_| {},
        )
        .unwrap();
        let samples = |i: &Ingested| i.samples.lock().unwrap().clone();
        let expected = samples(&one_by_one).expect("the plant's objects are contiguous");
        assert!(expected.points.len() > 3000 && expected.stride.iter().any(|&s| s > 1));
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let got =
                ingest_in(Scene::from_sources(vec![open()]), dir.path(), Some(&pool), sampler(), &mut |_| {})
                    .unwrap();
            assert_eq!(samples(&got).as_ref(), Some(&expected));
            assert_eq!(got.triangles, one_by_one.triangles);
            assert_eq!(got.work.origin, one_by_one.work.origin);
            assert_eq!((got.min, got.max), (one_by_one.min, one_by_one.max));
            assert_eq!(got.objects, one_by_one.objects);
            assert_eq!(got.summary, one_by_one.summary);
            let bytes = |i: &Ingested| std::fs::read(i.work.path()).unwrap();
            assert!(bytes(&got) == bytes(&one_by_one), "{threads} threads");
        }
        assert!(one_by_one.objects.len() > 10);
    }

    #[test]
    fn a_coordinate_too_far_in_a_batch_is_a_limit_error() {
        let dir = tempfile::tempdir().unwrap();
        let ply = dir.path().join("far.ply");
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty double x\n\
            property double y\nproperty double z\nelement face 2\nproperty list uchar int vertex_indices\n\
            end_header\n"
            .to_vec();
        for v in [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1e300, 0.0, 0.0]] {
            for c in v {
                bytes.extend_from_slice(&f64::to_le_bytes(c));
            }
        }
        for f in [[0i32, 1, 2], [3, 1, 2]] {
            bytes.push(3);
            for i in f {
                bytes.extend_from_slice(&i.to_le_bytes());
            }
        }
        std::fs::write(&ply, bytes).unwrap();
        let scene = Scene::open(&[&ply], Default::default()).unwrap();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let r = ingest_in(scene, dir.path(), Some(&pool), None, &mut |_| {});
        assert!(matches!(r, Err(BuildError::Limit(_))), "{r:?}");
    }

    /// The `--up auto` votes are taken only when asked, and are the same on the one-by-one
    /// path and the batch path whatever the threads (they are summed in the in-order append).
    #[test]
    fn up_votes_are_the_same_on_every_path() {
        let dir = tempfile::tempdir().unwrap();
        let ply = dir.path().join("plant.ply");
        let mut w = tw_io::write::create_writer(&ply).unwrap();
        let plant =
            tw_io::generate::PlantSource::new(tw_io::generate::PlantParams { triangles: 60_000, seed: 5 })
                .unwrap();
        Box::new(plant).stream(&mut *w).unwrap();
        w.finish().unwrap();
        let open = || tw_io::open_source(&ply, &Default::default()).unwrap();
        let not_asked = ingest_in(Scene::from_sources(vec![open()]), dir.path(), None, None, &mut |_| {});
        assert!(not_asked.unwrap().up_votes.is_none());
        let one_by_one = Scene::from_sources(vec![Box::new(OneByOne(open()))]);
        let expected = ingest_voting(one_by_one, dir.path(), None, None, true, &mut |_| {}).unwrap().up_votes;
        let expected = expected.expect("asked for");
        assert!(expected.total > 0.0 && expected.facing.iter().all(|&a| a > 0.0), "{expected:?}");
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let scene = Scene::from_sources(vec![open()]);
            let got = ingest_voting(scene, dir.path(), Some(&pool), None, true, &mut |_| {}).unwrap();
            assert_eq!(got.up_votes, Some(expected), "{threads} threads");
        }
    }
}
