//! Distributing the triangles into their cells, out of core (docs/BUILD.md, phases 4–5: the
//! working files that the LOD phase reads; the bucketing follows the usual external
//! distribution sort).
//!
//! 1. [`CellFiles::distribute`]: one streaming pass over the working file gives every triangle
//!    its cell ([`Redefined::cell_of`]) and its grid position
//!    ([`WorkFile::quantize`](crate::ingest::WorkFile::quantize)), and appends it to a *bucket*
//!    file. A bucket is a contiguous range of cells (in cell order, i.e. hierarchy leaf order once
//!    [`Redefined::order_by_hierarchy`] ran) sized so that reading it fits the memory budget (the
//!    first buckets smaller, so that the phases that read them start sooner: `bucket_ranges`). At
//!    most [`MAX_OPEN_BUCKETS`] bucket files are written per pass; a tiny budget over a huge input
//!    takes several passes rather than more open files. The pool decodes, assigns, quantizes and
//!    encodes each sub-chunk of 4096 triangles, grouped by bucket; the calling thread appends the
//!    groups in order (file order within each bucket).
//! 2. [`CellFiles::read_bucket`]: reads one bucket, groups its triangles by cell (a counting
//!    sort, stable: input order within a cell), and [`Bucket::mesh`] builds a cell's
//!    [`CellMesh`], its vertices deduplicated by exact grid position (an open-addressing table with
//!    a fixed hash; vertices numbered in order of first use, so deterministic). `mesh` takes `&self`, so cells of a bucket can be built
//!    in parallel. `CellFiles::for_each_cell` hands out every cell in cell order.
//!
//! Bucket record, 35 bytes little endian: nine grid coordinates of 24 bits (3 bytes each; grid
//! points are at most [`GRID_STEPS`] = 2^24 − 1), the object id and the cell (`u32` each). The
//! buckets are written once and read twice (seams, LOD), and the kernel's copies of those bytes
//! are much of the early phases' time; the 44-byte layout of plain `u32`s cost a quarter more.
//!
//! Memory: reading a bucket holds its records and a sort index, [`BUCKET_BYTES_PER_TRIANGLE`]
//! bytes per triangle, plus the mesh being built (at most [`CELL_BYTES_PER_TRIANGLE`] per
//! triangle of the cell). Buckets are sized so that both together stay within the budget; a
//! single cell that cannot fit is an error naming the cell and `--memory` (cells are capped at
//! `RedefineParams::max_cell_triangles`, 65 536 triangles, about 10.7 MB, by default; no cell
//! is larger, `redefine`'s count split sees to that).
//! Triangles that quantization makes degenerate are kept: every input triangle is in exactly one
//! cell.

use std::ops::Range;
use std::path::Path;

use tempfile::TempPath;
use tw_core::release_behind::ReleaseBehind;

use crate::error::BuildError;
use crate::ingest::Ingested;
use crate::redefine::Redefined;
use crate::types::{CellMesh, GRID_STEPS};
use crate::workio::{map_sub_chunks, temp_path, SpillWriter, WorkPath};

/// Bytes per triangle in a bucket file.
pub const RECORD_BYTES: usize = 35;
/// Memory per triangle of a bucket being read: its record, as read (decoded only when a cell's
/// mesh is built), and its sort index.
pub const BUCKET_BYTES_PER_TRIANGLE: u64 = RECORD_BYTES as u64 + 4;
/// Memory per triangle of the cell whose mesh is being built (an upper bound: the position
/// table, at most 48 bytes, positions, indices and object ids).
pub const CELL_BYTES_PER_TRIANGLE: u64 = 3 * 16 + 3 * 8 + 3 * 12 + 12 + 4;
/// Bucket files written at once.
pub const MAX_OPEN_BUCKETS: usize = 256;

/// One triangle of a bucket.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Rec {
    q: [[u32; 3]; 3],
    object: u32,
    cell: u32,
}

impl Rec {
    fn encode(&self) -> [u8; RECORD_BYTES] {
        let mut out = [0u8; RECORD_BYTES];
        for (o, &v) in out.chunks_exact_mut(3).zip(self.q.iter().flatten()) {
            debug_assert!(v <= GRID_STEPS);
            o.copy_from_slice(&v.to_le_bytes()[..3]);
        }
        out[27..31].copy_from_slice(&self.object.to_le_bytes());
        out[31..35].copy_from_slice(&self.cell.to_le_bytes());
        out
    }

    /// Vertex `v` (0..3) of an encoded record.
    #[inline]
    fn position_of(b: &[u8], v: usize) -> [u32; 3] {
        let g = |k: usize| u32::from_le_bytes([b[3 * k], b[3 * k + 1], b[3 * k + 2], 0]);
        [g(3 * v), g(3 * v + 1), g(3 * v + 2)]
    }

    #[inline]
    fn object_of(b: &[u8]) -> u32 {
        u32::from_le_bytes([b[27], b[28], b[29], b[30]])
    }

    #[inline]
    fn cell_of(b: &[u8]) -> u32 {
        u32::from_le_bytes([b[31], b[32], b[33], b[34]])
    }
}

struct BucketFile {
    path: WorkPath,
    cells: Range<u32>,
    triangles: u64,
}

/// [`CellFiles`] kept on disk for a build plan: each bucket's file name, cells and triangles.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CellFilesMeta {
    buckets: Vec<(String, u32, u32, u64)>,
    cell_triangles: Vec<u64>,
    objects: u32,
}

/// The triangles of every cell, in bucket files on disk (deleted when dropped).
pub struct CellFiles {
    buckets: Vec<BucketFile>,
    /// Triangles per cell.
    cell_triangles: Vec<u64>,
    objects: u32,
}

impl CellFiles {
    /// Writes every triangle of `ing` to the bucket of its cell. `memory_budget` (bytes) bounds
    /// what reading one bucket and building one of its cells takes (see the module docs).
    /// Consumes the working file: its last pass gives its disk back behind the reader
    /// (`tw_core::release_behind`), so afterwards it reads as zeros; the caller removes it.
    pub fn distribute(
        ing: &Ingested,
        cells: &Redefined,
        work_dir: &Path,
        memory_budget: u64,
    ) -> Result<CellFiles, BuildError> {
        let cell_triangles: Vec<u64> = cells.cells.iter().map(|c| c.triangles).collect();
        let largest = cell_triangles.iter().copied().max().unwrap_or(0);
        let per_cell = largest * CELL_BYTES_PER_TRIANGLE;
        let per_bucket = |t: u64| t * BUCKET_BYTES_PER_TRIANGLE;
        if per_bucket(largest) + per_cell > memory_budget {
            let c = cell_triangles.iter().position(|&t| t == largest).unwrap_or(0);
            return Err(BuildError::Limit(format!(
                "cell {c} has {largest} triangles and needs {} MB to read, more than the memory budget \
                 of {} MB for a bucket of cells: raise the build's budget (`terawalk build --memory`)",
                (per_bucket(largest) + per_cell).div_ceil(1 << 20),
                memory_budget >> 20
            )));
        }
        let limit = (memory_budget - per_cell) / BUCKET_BYTES_PER_TRIANGLE;
        let ranges = bucket_ranges(&cell_triangles, limit);
        let mut bucket_of = vec![0u32; cell_triangles.len()];
        for (b, (r, _)) in ranges.iter().enumerate() {
            for c in r.clone() {
                bucket_of[c as usize] = b as u32;
            }
        }
        let mut buckets = Vec::with_capacity(ranges.len());
        for group in ranges.chunks(MAX_OPEN_BUCKETS) {
            let first = buckets.len();
            buckets.extend(write_group(ing, cells, work_dir, memory_budget, &bucket_of, first, group)?);
        }
        tracing::debug!(buckets = buckets.len(), cells = cell_triangles.len(), "distributed triangles");
        Ok(CellFiles { buckets, cell_triangles, objects: ing.objects.len() as u32 })
    }

    pub fn bucket_count(&self) -> usize {
        self.buckets.len()
    }

    /// Deletes bucket `b`'s file once its cells are built (a plain build's; a plan keeps its
    /// prepared files for the jobs that read them, and re-runs).
    pub fn discard_bucket(&self, b: usize) {
        self.buckets[b].path.discard();
    }

    /// Keeps the bucket files (see [`WorkPath::keep`]) and describes them by name, for a
    /// build plan's later jobs ([`CellFiles::reopen`]).
    pub fn keep(self) -> Result<CellFilesMeta, BuildError> {
        let mut buckets = Vec::with_capacity(self.buckets.len());
        for b in self.buckets {
            let path = b.path.keep()?;
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            buckets.push((name, b.cells.start, b.cells.end, b.triangles));
        }
        Ok(CellFilesMeta { buckets, cell_triangles: self.cell_triangles, objects: self.objects })
    }

    /// The bucket files [`CellFiles::keep`] described, in `dir`; they are not deleted on drop.
    pub fn reopen(meta: &CellFilesMeta, dir: &Path) -> CellFiles {
        let buckets = meta
            .buckets
            .iter()
            .map(|(name, start, end, triangles)| BucketFile {
                path: WorkPath::Kept(dir.join(name)),
                cells: *start..*end,
                triangles: *triangles,
            })
            .collect();
        CellFiles { buckets, cell_triangles: meta.cell_triangles.clone(), objects: meta.objects }
    }

    /// Triangles per cell.
    pub fn cell_triangles(&self) -> &[u64] {
        &self.cell_triangles
    }

    /// The cells of bucket `b`.
    pub fn bucket_cells(&self, b: usize) -> Range<u32> {
        self.buckets[b].cells.clone()
    }

    /// Triangles in bucket `b`.
    /// The bucket holding `cell` (buckets hold consecutive ranges of cells, in order).
    pub fn bucket_of_cell(&self, cell: u32) -> usize {
        self.buckets.partition_point(|b| b.cells.end <= cell).min(self.buckets.len().saturating_sub(1))
    }

    pub fn bucket_triangles(&self, b: usize) -> u64 {
        self.buckets[b].triangles
    }

    pub fn cell_count(&self) -> usize {
        self.cell_triangles.len()
    }

    /// Reads bucket `b` and groups its triangles by cell.
    pub fn read_bucket(&self, b: usize) -> Result<Bucket, BuildError> {
        let bf = &self.buckets[b];
        let path: &Path = &bf.path;
        let corrupt = |message: String| BuildError::Corrupt { path: path.to_path_buf(), message };
        let len = std::fs::metadata(path).map_err(|e| BuildError::io(path, e))?.len();
        if len != bf.triangles * RECORD_BYTES as u64 {
            return Err(corrupt(format!("{len} bytes, expected {} triangles", bf.triangles)));
        }
        // The raw records: the reader thread only reads and sorts; the pool decodes each
        // cell's records as it builds the cell's mesh (`Bucket::mesh`).
        let bytes = read_raw(path, len)?;
        let n = bytes.len() / RECORD_BYTES;
        // Counting sort by cell: stable, so input order within each cell.
        let cells = bf.cells.clone();
        let mut start = vec![0usize; cells.len() + 1];
        for (i, r) in bytes.chunks_exact(RECORD_BYTES).enumerate() {
            let (object, cell) = (Rec::object_of(r), Rec::cell_of(r));
            if !cells.contains(&cell) {
                return Err(corrupt(format!("triangle {i} has cell {cell} outside {cells:?}")));
            }
            // Grid positions are 24-bit fields: always within GRID_STEPS.
            if object >= self.objects {
                return Err(corrupt(format!("triangle {i} has a bad object id")));
            }
            start[(cell - cells.start) as usize + 1] += 1;
        }
        for k in 0..cells.len() {
            start[k + 1] += start[k];
            let c = cells.start as usize + k;
            if (start[k + 1] - start[k]) as u64 != self.cell_triangles[c] {
                return Err(corrupt(format!(
                    "cell {c} has {} triangles, expected {}",
                    start[k + 1] - start[k],
                    self.cell_triangles[c]
                )));
            }
        }
        let mut fill = start.clone();
        let mut order = vec![0u32; n];
        for (i, r) in bytes.chunks_exact(RECORD_BYTES).enumerate() {
            let k = (Rec::cell_of(r) - cells.start) as usize;
            order[fill[k]] = i as u32;
            fill[k] += 1;
        }
        Ok(Bucket { cells, bytes, order, start })
    }

    /// Calls `f` with every cell's mesh, in cell order. Memory: one bucket and one cell.
    #[cfg(test)]
    pub fn for_each_cell(
        &self,
        mut f: impl FnMut(u32, CellMesh) -> Result<(), BuildError>,
    ) -> Result<(), BuildError> {
        for b in 0..self.buckets.len() {
            let bucket = self.read_bucket(b)?;
            for c in bucket.cells() {
                f(c, bucket.mesh(c))?;
            }
        }
        Ok(())
    }
}

/// The first bucket holds at most `limit >> FIRST_BUCKET_SHIFT` triangles, and each next one at
/// most twice its predecessor's limit, up to `limit` ([`bucket_ranges`]).
const FIRST_BUCKET_SHIFT: u32 = 4;

/// The buckets of cells with `cell_triangles`: consecutive cells, greedily, while a bucket stays
/// within its limit (a cell above it gets a bucket of its own). Returns each bucket's cells and
/// triangles.
///
/// The limit ramps up: the seams and the LOD phases both start by reading bucket 0 on one
/// thread while the pool has nothing to do (0.4 s each on the 24 M-triangle assembly, 8 M
/// triangles a bucket), and then read bucket `b + 1` while the pool works on bucket `b`. A
/// small first bucket makes the first wait short; doubling keeps every later read shorter than
/// the work on the bucket before it (the pool spends about three times as long on a triangle
/// in the seams phase as the reader does, and much longer in the LOD phase). The output does
/// not depend on the buckets: a cell sees the seams of its own positions whatever its bucket.
fn bucket_ranges(cell_triangles: &[u64], limit: u64) -> Vec<(Range<u32>, u64)> {
    let mut ranges: Vec<(Range<u32>, u64)> = Vec::new();
    let mut cap = limit >> FIRST_BUCKET_SHIFT;
    let mut start = 0u32;
    let mut sum = 0u64;
    for (c, &t) in cell_triangles.iter().enumerate() {
        if sum + t > cap && sum > 0 {
            ranges.push((start..c as u32, sum));
            start = c as u32;
            sum = 0;
            cap = cap.saturating_mul(2).min(limit);
        }
        sum += t;
    }
    if sum > 0 || ranges.is_empty() {
        ranges.push((start..cell_triangles.len() as u32, sum));
    }
    ranges
}

/// Writes the buckets of one group (at most [`MAX_OPEN_BUCKETS`]) in one pass.
fn write_group(
    ing: &Ingested,
    cells: &Redefined,
    work_dir: &Path,
    memory_budget: u64,
    bucket_of: &[u32],
    first: usize,
    group: &[(Range<u32>, u64)],
) -> Result<Vec<BucketFile>, BuildError> {
    // Write buffers share a quarter of the budget, 64 KiB to 1 MiB each.
    let buf_size = (memory_budget / 4 / group.len() as u64).clamp(64 << 10, 1 << 20) as usize;
    let paths: Vec<TempPath> =
        group.iter().map(|_| temp_path(work_dir, "tw-bucket-")).collect::<Result<_, _>>()?;
    let mut writer = SpillWriter::direct(paths.iter().map(|p| p.to_path_buf()).collect(), buf_size)?;
    let end = first + group.len();
    let (work, grid) = (&ing.work, &ing.grid);
    // The last group's pass is the working file's last read (the pipeline removes it next):
    // its disk is released behind the reader, so that it and the buckets are not both on disk
    // in full. Buckets hold cells in order, so the last cell's bucket is the last bucket.
    let last_pass = bucket_of.last().is_none_or(|&b| (b as usize) < end);
    // Tests release every 64 KiB, so that their small builds go through it too.
    let step = if cfg!(test) { 64 << 10 } else { tw_core::release_behind::RELEASE_STEP };
    let mut release = last_pass.then(|| ReleaseBehind::with_step(work.path(), step));
    // The pool decodes, assigns, quantizes and encodes each sub-chunk of the working file, its
    // records grouped by bucket (stable: file order within a bucket); this thread only appends
    // each sub-chunk's runs, in order, so every bucket file gets its triangles in file order.
    ing.work.scan_raw(|chunk_start, bytes| {
        let parts = map_sub_chunks(bytes, crate::ingest::RECORD_BYTES, |at, b| {
            let mut recs: Vec<(u32, [u8; RECORD_BYTES])> =
                Vec::with_capacity(b.len() / crate::ingest::RECORD_BYTES);
            for (k, t) in crate::ingest::records(b).enumerate() {
                let cell = cells.cell_of(&t, chunk_start + (at + k) as u64);
                let b = bucket_of.get(cell as usize).map_or(usize::MAX, |&b| b as usize);
                if (first..end).contains(&b) {
                    let q = t.p.map(|v| work.quantize(grid, v));
                    recs.push(((b - first) as u32, Rec { q, object: t.object, cell }.encode()));
                }
            }
            group_by_bucket(&recs, group.len())
        });
        for (out, start) in &parts {
            for (b, w) in start.windows(2).enumerate() {
                if w[1] > w[0] {
                    writer.write(b, &out[w[0] * RECORD_BYTES..w[1] * RECORD_BYTES])?;
                }
            }
        }
        let read = chunk_start * crate::ingest::RECORD_BYTES as u64 + bytes.len() as u64;
        release.iter_mut().for_each(|r| r.consumed(read));
        Ok(())
    })?;
    if release.is_some_and(|r| r.keeps_file()) {
        tracing::debug!("the working file's disk is kept to the end of distribute (no hole punching here)");
    }
    drop(writer.finish()?);
    Ok(paths
        .into_iter()
        .zip(group)
        .map(|(path, (cells, triangles))| BucketFile {
            path: WorkPath::Temp(path),
            cells: cells.clone(),
            triangles: *triangles,
        })
        .collect())
}

/// Encoded records `(bucket, bytes)` grouped by bucket (`0..buckets`), stable: the bytes of
/// bucket `b`'s records are `out[start[b] * RECORD_BYTES..start[b + 1] * RECORD_BYTES]`, in
/// input order. Returns `(out, start)`.
fn group_by_bucket(recs: &[(u32, [u8; RECORD_BYTES])], buckets: usize) -> (Vec<u8>, Vec<usize>) {
    let mut start = vec![0usize; buckets + 1];
    for &(b, _) in recs {
        start[b as usize + 1] += 1;
    }
    for b in 0..buckets {
        start[b + 1] += start[b];
    }
    let mut fill = start.clone();
    let mut out = vec![0u8; recs.len() * RECORD_BYTES];
    for (b, r) in recs {
        let at = &mut fill[*b as usize];
        out[*at * RECORD_BYTES..(*at + 1) * RECORD_BYTES].copy_from_slice(r);
        *at += 1;
    }
    (out, start)
}

/// One bucket in memory, its triangles grouped by cell.
pub struct Bucket {
    cells: Range<u32>,
    /// The records as read ([`RECORD_BYTES`] each).
    bytes: Vec<u8>,
    /// Record indices in cell order; cell `cells.start + k` is `order[start[k]..start[k + 1]]`.
    order: Vec<u32>,
    start: Vec<usize>,
}

impl Bucket {
    /// The cells of the bucket.
    pub fn cells(&self) -> Range<u32> {
        self.cells.clone()
    }

    /// The indexed mesh of `cell` (a cell of this bucket): triangles in input order, vertices
    /// deduplicated by grid position, numbered in order of first use, and exact duplicate
    /// triangles left out (`remove_duplicate_triangles`; `CellMesh::duplicates` counts them).
    pub fn mesh(&self, cell: u32) -> CellMesh {
        assert!(self.cells.contains(&cell), "cell {cell} is not in bucket {:?}", self.cells);
        let k = (cell - self.cells.start) as usize;
        let tris = &self.order[self.start[k]..self.start[k + 1]];
        let mut table = PositionTable::with_corners(3 * tris.len());
        let mut indices = Vec::with_capacity(3 * tris.len());
        let mut objects = Vec::with_capacity(tris.len());
        for &i in tris {
            let r = &self.bytes[i as usize * RECORD_BYTES..(i as usize + 1) * RECORD_BYTES];
            for v in 0..3 {
                indices.push(table.vertex(Rec::position_of(r, v)));
            }
            objects.push(Rec::object_of(r));
        }
        // The position table's slots go before the triangle table is made: the two are never
        // held together (CELL_BYTES_PER_TRIANGLE counts the larger).
        let positions = table.positions;
        drop(table.slots);
        let duplicates = remove_duplicate_triangles(&mut indices, &mut objects);
        CellMesh { positions, indices, objects, duplicates }
    }
}

/// Removes, in place, every triangle whose three vertices equal an earlier triangle's in the
/// same cyclic order (any rotation of the corners: `a b c`, `b c a` and `c a b` are one
/// triangle), keeping the first (its object too); returns how many went. Stable: the triangles
/// kept stay in input order, so a cell without duplicates is unchanged and its store identical.
///
/// The mirrored winding (`a c b`) is *not* a duplicate: it is the same surface facing the other
/// way, which is how CAD exports make a sheet visible from both sides, and the renderer's
/// back-face culling and shading tell the two apart. Duplicates only ever add work (copies
/// draw to the same pixels and z-fight); at a million copies of one triangle they also made a
/// vertex of a million triangles, which the clusterizer handles in quadratic time.
///
/// Memory: a table of at most 16 bytes per triangle (open addressing, load ≤ 1/2), less than
/// the position table dropped before it. The hash is fixed, so the result does not depend on
/// anything but the triangles.
fn remove_duplicate_triangles(indices: &mut Vec<u32>, objects: &mut Vec<u32>) -> u64 {
    let n = indices.len() / 3;
    // Rotated so that the smallest index comes first: one key per cyclic order.
    let key = |t: &[u32]| -> [u32; 3] {
        let m = (0..3).min_by_key(|&i| t[i]).unwrap_or(0);
        [t[m], t[(m + 1) % 3], t[(m + 2) % 3]]
    };
    let len = (2 * n).next_power_of_two().max(16);
    let mask = len - 1;
    // Kept triangle index + 1 per slot (0: empty).
    let mut slots = vec![0u32; len];
    let mut kept = 0usize;
    for t in 0..n {
        let k = key(&indices[3 * t..3 * t + 3]);
        let h = ((k[0] as u64) | (k[1] as u64) << 32).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (k[2] as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        let mut i = (h >> 32) as usize & mask;
        let duplicate = loop {
            let s = slots[i] as usize;
            if s == 0 {
                slots[i] = kept as u32 + 1;
                break false;
            }
            // Kept triangles are already moved to their final place (before `kept`).
            if key(&indices[3 * (s - 1)..3 * s]) == k {
                break true;
            }
            i = (i + 1) & mask;
        };
        if !duplicate {
            if kept != t {
                indices.copy_within(3 * t..3 * t + 3, 3 * kept);
                objects[kept] = objects[t];
            }
            kept += 1;
        }
    }
    indices.truncate(3 * kept);
    objects.truncate(kept);
    (n - kept) as u64
}

/// Vertex ids by exact grid position, numbered in order of first use: an open-addressing table
/// with a fixed hash, so the numbering depends only on the order of the queries.
struct PositionTable {
    /// Vertex id + 1 per slot (0: empty); the length is a power of two.
    slots: Vec<u32>,
    positions: Vec<[u32; 3]>,
}

impl PositionTable {
    /// A table for at most `corners` distinct positions (load factor ≤ 1/2).
    fn with_corners(corners: usize) -> PositionTable {
        let len = (2 * corners).next_power_of_two().max(16);
        PositionTable { slots: vec![0; len], positions: Vec::with_capacity(corners / 2 + 16) }
    }

    fn vertex(&mut self, p: [u32; 3]) -> u32 {
        let mask = self.slots.len() - 1;
        let h = ((p[0] as u64) | (p[1] as u64) << 32).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (p[2] as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        let mut i = (h >> 32) as usize & mask;
        loop {
            let s = self.slots[i];
            if s == 0 {
                self.positions.push(p);
                self.slots[i] = self.positions.len() as u32;
                return self.positions.len() as u32 - 1;
            }
            if self.positions[s as usize - 1] == p {
                return s - 1;
            }
            i = (i + 1) & mask;
        }
    }
}

/// Reads the `len` bytes of `path` (direct where the file system allows).
fn read_raw(path: &Path, len: u64) -> Result<Vec<u8>, BuildError> {
    let buffer = len.clamp(1, 4 << 20) as usize;
    let mut file =
        tw_core::direct_io::DirectReader::open(path, buffer).map_err(|e| BuildError::io(path, e))?;
    if file.file_len() != len {
        return Err(BuildError::Corrupt { path: path.to_path_buf(), message: "changed while read".into() });
    }
    let mut bytes = vec![0u8; len as usize];
    std::io::Read::read_exact(&mut file, &mut bytes).map_err(|e| BuildError::io(path, e))?;
    Ok(bytes)
}

/// Reads a file of fixed-size records (`size` bytes each) and decodes each.
pub(crate) fn read_records<T>(
    path: &Path,
    size: usize,
    decode: impl Fn(&[u8]) -> T,
) -> Result<Vec<T>, BuildError> {
    let len = std::fs::metadata(path).map_err(|e| BuildError::io(path, e))?.len();
    if len % size as u64 != 0 {
        return Err(BuildError::Corrupt {
            path: path.to_path_buf(),
            message: format!("{len} bytes is not a whole number of {size}-byte records"),
        });
    }
    let n = len / size as u64;
    // Decoded straight into the result on this thread (the direct reader's own thread reads
    // ahead): no second thread and no copy of the decoded records.
    let buffer = len.clamp(1, 4 << 20) as usize;
    let mut file =
        tw_core::direct_io::DirectReader::open(path, buffer).map_err(|e| BuildError::io(path, e))?;
    if file.file_len() != len {
        return Err(BuildError::Corrupt { path: path.to_path_buf(), message: "changed while read".into() });
    }
    let mut out = Vec::with_capacity(n as usize);
    let mut bytes = vec![0u8; (1 << 14) * size];
    let mut left = n as usize;
    while left > 0 {
        let k = left.min(1 << 14);
        let b = &mut bytes[..k * size];
        std::io::Read::read_exact(&mut file, b).map_err(|e| BuildError::io(path, e))?;
        out.extend(b.chunks_exact(size).map(&decode));
        left -= k;
    }
    Ok(out)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::ingest::tests::{ingest_list, ingest_plant};
    use crate::redefine::{redefine, RedefineParams};
    use crate::types::Grid;

    /// Every triangle as three grid points (from the mesh), sorted: a multiset.
    fn mesh_triangles(files: &CellFiles) -> Vec<([[u32; 3]; 3], u32)> {
        let mut v = Vec::new();
        let mut next = 0;
        files
            .for_each_cell(|c, m| {
                assert_eq!(c, next, "cells in order");
                next += 1;
                assert_eq!(m.objects.len(), m.triangle_count());
                assert_eq!(m.duplicates, 0, "these inputs have no duplicate triangle");
                for (t, &o) in m.indices.chunks_exact(3).zip(&m.objects) {
                    v.push(([t[0], t[1], t[2]].map(|i| m.positions[i as usize]), o));
                }
                Ok(())
            })
            .unwrap();
        v.sort_unstable();
        v
    }

    fn direct_triangles(ing: &Ingested) -> Vec<([[u32; 3]; 3], u32)> {
        let mut v = Vec::new();
        ing.work
            .scan(|_, tris| {
                v.extend(tris.iter().map(|t| (t.p.map(|p| ing.work.quantize(&ing.grid, p)), t.object)));
                Ok(())
            })
            .unwrap();
        v.sort_unstable();
        v
    }

    /// A generated plant of `triangles`, ingested, redefined and distributed to cell buckets
    /// of `budget` bytes in `dir`.
    pub(crate) fn plant_cells(dir: &Path, triangles: u64, budget: u64) -> (Ingested, CellFiles) {
        let ing = ingest_plant(dir, triangles);
        let mut r = redefine(&ing, &RedefineParams::default()).unwrap();
        r.order_by_hierarchy();
        let files = CellFiles::distribute(&ing, &r, dir, budget).unwrap();
        (ing, files)
    }

    #[test]
    fn every_triangle_lands_in_exactly_one_cell() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 200_000);
        // Read before distributing: distribute releases the working file's disk as it reads it.
        let expected = direct_triangles(&ing);
        let mut r = redefine(&ing, &RedefineParams::default()).unwrap();
        r.order_by_hierarchy();
        let files = CellFiles::distribute(&ing, &r, dir.path(), 4 << 20).unwrap();
        assert!(files.bucket_count() > 1);
        let got = mesh_triangles(&files);
        assert_eq!(got.len(), 200_000);
        assert_eq!(got, expected);
        // Released in the tests' 64 KiB steps (where the file system can punch holes): all but
        // the last partial step.
        let meta = std::fs::metadata(ing.work.path()).unwrap();
        let probe = std::fs::File::create(dir.path().join("probe")).unwrap();
        if tw_core::release_behind::punch_hole(&probe, 0, 4096).is_ok() {
            use std::os::unix::fs::MetadataExt;
            let kept = meta.blocks() * 512;
            assert!(kept <= 2 * (64 << 10), "{kept} of {} bytes kept", meta.len());
        }
    }

    #[test]
    fn duplicate_triangles_go_in_any_rotation_but_not_mirrored() {
        // 0 1 2 | 1 2 0 (rotation) | 0 2 1 (mirror) | 3 4 5 | 2 0 1 (rotation) | 3 4 5 | 5 4 3
        let mut indices = vec![0, 1, 2, 1, 2, 0, 0, 2, 1, 3, 4, 5, 2, 0, 1, 3, 4, 5, 5, 4, 3];
        let mut objects = vec![10, 11, 12, 13, 14, 15, 16];
        assert_eq!(remove_duplicate_triangles(&mut indices, &mut objects), 3);
        assert_eq!(indices, [0, 1, 2, 0, 2, 1, 3, 4, 5, 5, 4, 3], "the first kept, in order");
        assert_eq!(objects, [10, 12, 13, 16]);
        // Nothing to remove: unchanged.
        let (mut i, mut o) = (vec![0, 1, 2, 2, 1, 3], vec![1, 2]);
        assert_eq!(remove_duplicate_triangles(&mut i, &mut o), 0);
        assert_eq!((i, o), (vec![0, 1, 2, 2, 1, 3], vec![1, 2]));
        // Many copies (a vertex of 100 000 triangles): one left.
        let (mut i, mut o) = ([7, 8, 9].repeat(100_000), vec![0; 100_000]);
        assert_eq!(remove_duplicate_triangles(&mut i, &mut o), 99_999);
        assert_eq!(i, [7, 8, 9]);
    }

    #[test]
    fn position_table_numbers_in_first_use_order_with_collisions() {
        // 8 slots' worth of positions in a 16-slot table: probing wraps and collides.
        let mut t = PositionTable::with_corners(8);
        assert_eq!(t.slots.len(), 16);
        let ps: Vec<[u32; 3]> = (0..8u32).map(|i| [i * 7, i * 7 + 1, u32::MAX - i]).collect();
        for (i, &p) in ps.iter().enumerate() {
            assert_eq!(t.vertex(p), i as u32);
        }
        for (i, &p) in ps.iter().enumerate().rev() {
            assert_eq!(t.vertex(p), i as u32, "repeat lookup");
        }
        assert_eq!(t.positions, ps);
        assert_eq!(t.vertex([0, 0, 0]), 8, "a new position after repeats");
    }

    #[test]
    fn meshes_share_vertices_and_match_cell_info() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 50_000);
        let mut r = redefine(&ing, &RedefineParams::default()).unwrap();
        r.order_by_hierarchy();
        let files = CellFiles::distribute(&ing, &r, dir.path(), 64 << 20).unwrap();
        files
            .for_each_cell(|c, m| {
                let info = r.cells[c as usize];
                assert_eq!(m.triangle_count() as u64, info.triangles);
                let mut seen = m.positions.clone();
                seen.sort_unstable();
                seen.dedup();
                assert_eq!(seen.len(), m.positions.len(), "cell {c}: duplicate vertices");
                // Generated meshes are indexed: far fewer vertices than corners.
                assert!(m.positions.len() < m.indices.len());
                // First-use order: the first index is 0, and each new index is the next one.
                let mut next = 0;
                for &i in &m.indices {
                    assert!(i <= next);
                    next = next.max(i + 1);
                }
                for p in &m.positions {
                    let b = info.bounds;
                    assert!((0..3).all(|k| b.min[k] <= p[k] && p[k] <= b.max[k]));
                }
                Ok(())
            })
            .unwrap();
    }

    #[test]
    fn distribution_is_deterministic() {
        let dir = tempfile::tempdir().unwrap();
        let run = || {
            // A working file per run: distribute releases it as it reads it.
            let ing = ingest_plant(dir.path(), 60_000);
            let mut r = redefine(&ing, &RedefineParams::default()).unwrap();
            r.order_by_hierarchy();
            let files = CellFiles::distribute(&ing, &r, dir.path(), 1 << 20).unwrap();
            let mut all = Vec::new();
            files
                .for_each_cell(|c, m| {
                    all.push((c, m));
                    Ok(())
                })
                .unwrap();
            all
        };
        let a = run();
        assert_eq!(a, run());
        // Reading the same files twice gives the same meshes too.
    }

    #[test]
    fn buckets_honour_the_memory_budget() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 100_000);
        let params = RedefineParams { max_cell_triangles: 4096, ..Default::default() };
        let mut r = redefine(&ing, &params).unwrap();
        r.order_by_hierarchy();
        let largest = r.cells.iter().map(|c| c.triangles).max().unwrap();
        for budget in [1u64 << 20, 3 << 20] {
            let files = CellFiles::distribute(&ing, &r, dir.path(), budget).unwrap();
            let mut covered = 0;
            for b in 0..files.bucket_count() {
                let t = files.bucket_triangles(b);
                assert!(t * BUCKET_BYTES_PER_TRIANGLE + largest * CELL_BYTES_PER_TRIANGLE <= budget);
                let cells = files.bucket_cells(b);
                assert_eq!(cells.start, covered, "buckets are consecutive cell ranges");
                covered = cells.end;
                let sum: u64 = cells.map(|c| r.cells[c as usize].triangles).sum();
                assert_eq!(sum, t);
            }
            assert_eq!(covered as usize, r.cells.len());
            assert!(files.bucket_count() as u64 >= 100_000 * BUCKET_BYTES_PER_TRIANGLE / budget);
        }
    }

    #[test]
    fn the_first_buckets_are_small_and_double_up_to_the_limit() {
        let limit = 16_000;
        let cells: Vec<u64> = (0..400).map(|c| 100 + (c * 37) % 300).collect();
        let ranges = bucket_ranges(&cells, limit);
        let mut covered = 0;
        let mut cap = limit >> FIRST_BUCKET_SHIFT;
        for (k, (r, t)) in ranges.iter().enumerate() {
            assert_eq!(r.start, covered, "consecutive");
            covered = r.end;
            assert_eq!(*t, cells[r.start as usize..r.end as usize].iter().sum::<u64>());
            assert!(*t <= cap, "bucket {k}: {t} above {cap}");
            if k + 1 < ranges.len() {
                // Full: the next cell would not have fitted.
                assert!(t + cells[r.end as usize] > cap, "bucket {k} stopped early");
            }
            cap = (cap * 2).min(limit);
        }
        assert_eq!(covered as usize, cells.len());
        assert!(ranges[0].1 <= limit / 16 && ranges[4].1 > limit / 2);
        // A cell above the first limits still gets a bucket; no cell, one empty bucket.
        assert_eq!(bucket_ranges(&[5000, 1], limit), vec![(0..1, 5000), (1..2, 1)]);
        assert_eq!(bucket_ranges(&[], limit), vec![(0..0, 0)]);
    }

    #[test]
    fn a_cell_larger_than_the_budget_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 50_000);
        let r = redefine(&ing, &RedefineParams::default()).unwrap();
        let e = CellFiles::distribute(&ing, &r, dir.path(), 1000).err().unwrap();
        assert!(matches!(e, BuildError::Limit(_)));
        assert!(e.to_string().contains("memory budget"), "{e}");
        assert!(e.to_string().contains("--memory"), "the advice names the option: {e}");
    }

    #[test]
    fn more_buckets_than_open_files_take_several_passes() {
        let dir = tempfile::tempdir().unwrap();
        // 600 tiny far-apart objects: 600 cells; a budget of ~2 cells per bucket gives > 256.
        let objs = (0..600)
            .map(|i| {
                let x = i as f64 * 100.0;
                (format!("o{i}"), None, vec![[[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]])
            })
            .collect();
        let ing = ingest_list(dir.path(), objs);
        let r = redefine(&ing, &RedefineParams { neighbours: 0, ..Default::default() }).unwrap();
        assert_eq!(r.cells.len(), 600);
        let budget = 2 * BUCKET_BYTES_PER_TRIANGLE + CELL_BYTES_PER_TRIANGLE;
        let files = CellFiles::distribute(&ing, &r, dir.path(), budget).unwrap();
        // 300 of two cells, and the first few (smaller limits: `bucket_ranges`) of one.
        assert!(files.bucket_count() >= 300 && files.bucket_count() > MAX_OPEN_BUCKETS);
        assert_eq!(mesh_triangles(&files), direct_triangles(&ing));
    }

    #[test]
    fn grid_quantization_is_consistent_across_cells() {
        let dir = tempfile::tempdir().unwrap();
        // Two far-apart objects sharing an awkward vertex coordinate pattern: the shared border
        // point of two triangles in different cells lands on one grid point.
        let s = [0.1234567891, 0.3333333333, 0.7777777777];
        let objs = vec![
            ("a".into(), None, vec![[s, [-500.0, 0.0, 0.0], [-500.0, 1.0, 0.0]]]),
            ("b".into(), None, vec![[[500.0, 0.0, 0.0], s, [500.0, 1.0, 0.0]]]),
        ];
        let ing = ingest_list(dir.path(), objs);
        let r = redefine(&ing, &RedefineParams { neighbours: 0, ..Default::default() }).unwrap();
        assert_eq!(r.cells.len(), 2);
        let files = CellFiles::distribute(&ing, &r, dir.path(), 1 << 20).unwrap();
        let mut shared = Vec::new();
        files
            .for_each_cell(|_, m| {
                shared
                    .extend(m.positions.iter().copied().filter(|p| p[0] > 1000 && p[0] < GRID_STEPS - 1000));
                Ok(())
            })
            .unwrap();
        assert_eq!(shared.len(), 2);
        assert_eq!(shared[0], shared[1]);
        let g: Grid = ing.grid;
        let direct = g.quantize(s);
        assert!((0..3).all(|i| shared[0][i].abs_diff(direct[i]) <= 1));
    }

    #[test]
    fn a_corrupted_bucket_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let ing = ingest_plant(dir.path(), 10_000);
        let r = redefine(&ing, &RedefineParams::default()).unwrap();
        let files = CellFiles::distribute(&ing, &r, dir.path(), 64 << 20).unwrap();
        let path: &Path = &files.buckets[0].path;
        let mut bytes = std::fs::read(path).unwrap();
        bytes[RECORD_BYTES - 4..RECORD_BYTES].copy_from_slice(&u32::MAX.to_le_bytes());
        std::fs::write(path, &bytes).unwrap();
        assert!(matches!(files.read_bucket(0), Err(BuildError::Corrupt { .. })));
        std::fs::write(path, &bytes[..100]).unwrap();
        assert!(matches!(files.read_bucket(0), Err(BuildError::Corrupt { .. })));
    }

    /// Phase timings on a generated plant: `TW_MEASURE_TRIANGLES=10000000 cargo test --release
    /// -p tw-build measure_phases -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn measure_phases() {
        use std::time::Instant;
        let n: u64 =
            std::env::var("TW_MEASURE_TRIANGLES").ok().and_then(|v| v.parse().ok()).unwrap_or(10_000_000);
        let budget: u64 =
            std::env::var("TW_MEASURE_BUDGET").ok().and_then(|v| v.parse().ok()).unwrap_or(256 << 20);
        let dir = tempfile::tempdir().unwrap();
        let mb = |b: Option<u64>| b.unwrap_or(0) as f64 / (1 << 20) as f64;
        let rate = |s: f64| n as f64 / s / 1e6;
        let t = Instant::now();
        let ing = ingest_plant(dir.path(), n);
        let t_ingest = t.elapsed().as_secs_f64();
        println!(
            "ingest        {t_ingest:7.2} s  {:6.2} M tri/s  peak RSS {:7.1} MB",
            rate(t_ingest),
            mb(tw_core::mem::peak_rss_bytes())
        );
        let t = Instant::now();
        let mut r = redefine(&ing, &RedefineParams::default()).unwrap();
        let t_redefine = t.elapsed().as_secs_f64();
        println!(
            "redefine      {t_redefine:7.2} s  {:6.2} M tri/s  peak RSS {:7.1} MB",
            rate(t_redefine),
            mb(tw_core::mem::peak_rss_bytes())
        );
        let t = Instant::now();
        let h = r.order_by_hierarchy();
        let t_h = t.elapsed().as_secs_f64();
        println!("hierarchy     {t_h:7.3} s  {} nodes, depth {}", h.nodes.len(), h.depth());
        let t = Instant::now();
        let files = CellFiles::distribute(&ing, &r, dir.path(), budget).unwrap();
        let t_dist = t.elapsed().as_secs_f64();
        println!(
            "distribute    {t_dist:7.2} s  {:6.2} M tri/s  {} buckets, peak RSS {:7.1} MB",
            rate(t_dist),
            files.bucket_count(),
            mb(tw_core::mem::peak_rss_bytes())
        );
        let t = Instant::now();
        let (mut tris, mut verts) = (0u64, 0u64);
        files
            .for_each_cell(|_, m| {
                tris += m.triangle_count() as u64;
                verts += m.positions.len() as u64;
                Ok(())
            })
            .unwrap();
        let t_read = t.elapsed().as_secs_f64();
        println!(
            "read cells    {t_read:7.2} s  {:6.2} M tri/s  {verts} vertices, peak RSS {:7.1} MB",
            rate(t_read),
            mb(tw_core::mem::peak_rss_bytes())
        );
        assert_eq!(tris, n);
        let total = t_ingest + t_redefine + t_h + t_dist + t_read;
        println!("total         {total:7.2} s  {:6.2} M tri/s", rate(total));
        println!("{:?}", r.report);
        let mut sizes: Vec<u64> = r.cells.iter().map(|c| c.triangles).collect();
        sizes.sort_unstable();
        let q = |f: f64| sizes[((sizes.len() - 1) as f64 * f) as usize];
        println!("cell triangles: p10 {} p50 {} p90 {} max {}", q(0.1), q(0.5), q(0.9), q(1.0));
    }
}
