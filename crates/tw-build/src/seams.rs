//! Phase 4: seams between cells, found out of core.
//!
//! A *seam* is a grid position on the open boundary (or a non-manifold edge) of two or more
//! cells: the border of an object that partitioning split, or where two objects of different
//! cells meet. Cells lock their seams ([`crate::lod::build_cell_lod_with_seams`]) and a node's
//! HLOD locks those shared with a cell outside the node's cell range
//! ([`crate::hlod::build_hlod`]), so that a cut mixing levels across cells never cracks. Each
//! seam carries the first and last cell (leaf order) that has it: as a node's cells are a
//! contiguous range in leaf order, a seam is shared with a cell outside the node iff one of the
//! two is outside the range.
//!
//! Memory is bounded by the build budget, not by the scene (GigaWalk §4 and Manocha §2 build
//! out of core; the seams were the last scene-sized table of the build: 16 bytes per open
//! position of every cell, ~450 MB on the 10^8-triangle plant):
//!
//! 1. every bucket's cells yield their open positions; the (position, cell) records are written
//!    to [`SeamFiles`] *partitions* by a hash of the position, so that all records of one
//!    position land in one partition, and a partition holds about `budget` bytes;
//! 2. each partition is sorted on its own; a position found in two or more cells becomes a seam
//!    `(position, first cell, last cell)`, written to the *seam file of each bucket* that has one
//!    of those cells;
//! 3. the LOD phase reads one bucket's seam file when it reaches the bucket ([`SeamTable`]), and
//!    passes up the hierarchy only the seams of the roots it keeps ([`SeamTable::retain`]).
//!
//! Deterministic: partitions and seam files are sorted before use, whatever the thread count.

use std::path::Path;

use rayon::prelude::*;
use tempfile::TempPath;

use crate::cells::{read_records, CellFiles};
use crate::error::BuildError;
use crate::workio::{temp_path, SpillWriter, WorkPath};

/// Bytes of one (position, cell) record in a partition file.
const OPEN_RECORD_BYTES: usize = 16;
/// Bytes of one (position, first, last) record in a bucket's seam file.
const SEAM_RECORD_BYTES: usize = 20;

/// Seams of some cells (sorted by position, each once) with the first and last cell that has
/// each.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SeamTable {
    positions: Vec<[u32; 3]>,
    cells: Vec<(u32, u32)>,
}

impl SeamTable {
    /// A table of `seams` in any order; duplicates (same position) must agree and are merged.
    pub fn from_unsorted(mut seams: Vec<([u32; 3], (u32, u32))>) -> SeamTable {
        seams.sort_unstable();
        seams.dedup_by(|a, b| a.0 == b.0);
        let (positions, cells) = seams.into_iter().unzip();
        SeamTable { positions, cells }
    }

    /// The union of several tables.
    pub fn merge<'a>(tables: impl IntoIterator<Item = &'a SeamTable>) -> SeamTable {
        SeamTable::from_unsorted(tables.into_iter().flat_map(|t| t.entries()).collect())
    }

    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    fn entries(&self) -> impl Iterator<Item = ([u32; 3], (u32, u32))> + '_ {
        self.positions.iter().copied().zip(self.cells.iter().copied())
    }

    /// Whether `p` is a seam.
    pub fn contains(&self, p: [u32; 3]) -> bool {
        self.positions.binary_search(&p).is_ok()
    }

    /// Whether `p` is a seam with a cell outside `range` (first cell, one past the last).
    pub fn external(&self, p: [u32; 3], range: (u32, u32)) -> bool {
        self.positions.binary_search(&p).is_ok_and(|i| {
            let (first, last) = self.cells[i];
            first < range.0 || last >= range.1
        })
    }

    /// The seams at `positions` that are shared with a cell outside `range`: what the subtree
    /// of `range`, represented by geometry at `positions`, must tell the nodes above it.
    pub fn retain(&self, positions: impl IntoIterator<Item = [u32; 3]>, range: (u32, u32)) -> SeamTable {
        let kept: Vec<([u32; 3], (u32, u32))> = positions
            .into_iter()
            .filter_map(|p| {
                let i = self.positions.binary_search(&p).ok()?;
                let (first, last) = self.cells[i];
                (first < range.0 || last >= range.1).then_some((p, (first, last)))
            })
            .collect();
        SeamTable::from_unsorted(kept)
    }
}

/// [`SeamFiles`] kept on disk for a build plan: each bucket's seam file name and seam count.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SeamFilesMeta {
    buckets: Vec<(String, u64)>,
    open_positions: u64,
    seams: u64,
    partitions: usize,
}

/// The seams of every bucket, one file each (deleted when dropped).
pub struct SeamFiles {
    buckets: Vec<(WorkPath, u64)>,
    /// Open positions over all cells, and seams over the scene (a seam counts once).
    pub open_positions: u64,
    pub seams: u64,
    pub partitions: usize,
}

impl SeamFiles {
    /// Finds the seams of `cells` with about `budget` bytes of records in memory at a time
    /// (besides one bucket, which `cells` bounds), in `work_dir`. `advance(cells done)` reports
    /// progress over the first pass.
    pub fn find(
        cells: &CellFiles,
        work_dir: &Path,
        budget: u64,
        pool: &rayon::ThreadPool,
        advance: &mut dyn FnMut(u64),
    ) -> Result<SeamFiles, BuildError> {
        let partitions = partition_count(cells, budget);
        let part_paths: Vec<TempPath> =
            (0..partitions).map(|_| temp_path(work_dir, "tw-open-")).collect::<Result<_, _>>()?;
        let mut parts =
            SpillWriter::direct(part_paths.iter().map(|p| p.to_path_buf()).collect(), WRITE_BUFFER)?;

        let mut lap = crate::types::StepTimer::new("seams");
        // 1. Open positions of every cell, by partition.
        let open_positions = write_open_positions(cells, pool, partitions, &mut parts, advance)?;

        // 2. Seams of each partition, to the seam files of their cells' buckets.
        drop(parts.finish()?);
        lap.step("open positions");
        let out_paths: Vec<TempPath> =
            (0..cells.bucket_count()).map(|_| temp_path(work_dir, "tw-seams-")).collect::<Result<_, _>>()?;
        let mut outs = BucketSeams {
            files: SpillWriter::direct(out_paths.iter().map(|p| p.to_path_buf()).collect(), WRITE_BUFFER)?,
            counts: vec![0u64; out_paths.len()],
            seams: 0,
        };
        for path in part_paths {
            let mut records = read_records(&path, OPEN_RECORD_BYTES, |b| {
                let v = get_u32s::<4>(b);
                ([v[0], v[1], v[2]], v[3])
            })?;
            drop(path); // deletes the partition file
            pool.install(|| records.par_sort_unstable());
            outs.write_partition(&records, cells)?;
        }
        let BucketSeams { files, counts, seams } = outs;
        drop(files.finish()?);
        lap.step("partitions");
        let buckets = out_paths.into_iter().map(WorkPath::Temp).zip(counts).collect();
        Ok(SeamFiles { buckets, open_positions, seams, partitions })
    }

    /// Deletes bucket `b`'s seam file once its cells are built (see [`CellFiles::discard_bucket`]).
    pub fn discard_bucket(&self, b: usize) {
        self.buckets[b].0.discard();
    }

    /// Keeps the seam files for a build plan's later jobs ([`SeamFiles::reopen`]).
    pub fn keep(self) -> Result<SeamFilesMeta, BuildError> {
        let mut buckets = Vec::with_capacity(self.buckets.len());
        for (path, n) in self.buckets {
            let path = path.keep()?;
            buckets.push((path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(), n));
        }
        let (open_positions, seams, partitions) = (self.open_positions, self.seams, self.partitions);
        Ok(SeamFilesMeta { buckets, open_positions, seams, partitions })
    }

    /// The seam files [`SeamFiles::keep`] described, in `dir`; they are not deleted on drop.
    pub fn reopen(meta: &SeamFilesMeta, dir: &Path) -> SeamFiles {
        SeamFiles {
            buckets: meta.buckets.iter().map(|(name, n)| (WorkPath::Kept(dir.join(name)), *n)).collect(),
            open_positions: meta.open_positions,
            seams: meta.seams,
            partitions: meta.partitions,
        }
    }

    /// The seams of the cells of bucket `b`.
    pub fn read_bucket(&self, b: usize) -> Result<SeamTable, BuildError> {
        let (path, n) = &self.buckets[b];
        let records = read_records(path, SEAM_RECORD_BYTES, |r| {
            let v = get_u32s::<5>(r);
            ([v[0], v[1], v[2]], (v[3], v[4]))
        })?;
        if records.len() as u64 != *n {
            return Err(BuildError::Corrupt {
                path: path.to_path_buf(),
                message: format!("{} seams, expected {n}", records.len()),
            });
        }
        Ok(SeamTable::from_unsorted(records))
    }
}

/// The partition count of [`SeamFiles::find`]'s first pass. A cell has at most 3 open positions
/// per triangle; the count assumes that bound, so a partition never exceeds the budget (most
/// hold far less).
fn partition_count(cells: &CellFiles, budget: u64) -> usize {
    let triangles: u64 = (0..cells.bucket_count()).map(|b| cells.bucket_triangles(b)).sum();
    let worst = triangles * 3 * OPEN_RECORD_BYTES as u64;
    worst.div_ceil(budget.max(1 << 20)).clamp(1, 512) as usize
}

/// Pass 1 of [`SeamFiles::find`]: the open positions of every cell, bucket by bucket, to the
/// partition files `parts`. The next bucket is read on a helper thread while the pool works on
/// this one (two buckets held; the LOD phase holds as many). Returns the open positions
/// written; `advance(cells done)` reports progress.
fn write_open_positions(
    cells: &CellFiles,
    pool: &rayon::ThreadPool,
    partitions: usize,
    parts: &mut SpillWriter,
    advance: &mut dyn FnMut(u64),
) -> Result<u64, BuildError> {
    let mut open_positions = 0u64;
    let mut done = 0u64;
    std::thread::scope(|scope| -> Result<(), BuildError> {
        let n = cells.bucket_count();
        let mut next = (n > 0).then(|| scope.spawn(|| cells.read_bucket(0)));
        for b in 0..n {
            let bucket = match next.take().map(|h| h.join()) {
                Some(Ok(r)) => r?,
                _ => return Err(BuildError::Internal("the bucket reader panicked".into())),
            };
            if b + 1 < n {
                next = Some(scope.spawn(move || cells.read_bucket(b + 1)));
            }
            let per_cell = bucket_open_records(&bucket, pool, partitions);
            drop(bucket);
            open_positions += append_open_records(parts, &per_cell)?;
            done += per_cell.len() as u64;
            advance(done);
        }
        Ok(())
    })?;
    Ok(open_positions)
}

/// The pool finds each cell's open positions and encodes their records, grouped by partition
/// (in position order within each; see [`open_records`]), cell by cell.
fn bucket_open_records(
    bucket: &crate::cells::Bucket,
    pool: &rayon::ThreadPool,
    partitions: usize,
) -> Vec<(Vec<u8>, Vec<usize>)> {
    let ids: Vec<u32> = bucket.cells().collect();
    pool.install(|| {
        ids.par_iter()
            .map(|&c| {
                let open = crate::hlod::open_positions(&bucket.mesh(c));
                open_records(&open, c, partitions)
            })
            .collect()
    })
}

/// Appends the cells' records to their partitions, cell by cell on this thread, so every
/// partition file gets its records in the serial order. Returns the records appended.
fn append_open_records(
    parts: &mut SpillWriter,
    per_cell: &[(Vec<u8>, Vec<usize>)],
) -> Result<u64, BuildError> {
    let mut records = 0u64;
    for (bytes, start) in per_cell {
        for (k, w) in start.windows(2).enumerate() {
            if w[1] > w[0] {
                parts.write(k, &bytes[w[0] * OPEN_RECORD_BYTES..w[1] * OPEN_RECORD_BYTES])?;
            }
        }
        records += (bytes.len() / OPEN_RECORD_BYTES) as u64;
    }
    Ok(records)
}

/// Pass 2 of [`SeamFiles::find`]: the seam files of the buckets being filled, the seams
/// written to each, and the seams over the scene (a seam counts once).
struct BucketSeams {
    files: SpillWriter,
    counts: Vec<u64>,
    seams: u64,
}

impl BucketSeams {
    /// The seams of one partition's sorted (position, cell) records: each position of two or
    /// more records is a seam, with its first and last cell, written once to each bucket that
    /// has one of its cells.
    fn write_partition(&mut self, records: &[([u32; 3], u32)], cells: &CellFiles) -> Result<(), BuildError> {
        let mut seam_record = [0u8; SEAM_RECORD_BYTES];
        let mut i = 0;
        while i < records.len() {
            let mut j = i + 1;
            while j < records.len() && records[j].0 == records[i].0 {
                j += 1;
            }
            if j - i > 1 {
                self.seams += 1;
                let p = records[i].0;
                let (first, last) = (records[i].1, records[j - 1].1);
                put_u32s(&mut seam_record, &[p[0], p[1], p[2], first, last]);
                let mut last_bucket = usize::MAX;
                for &(_, cell) in &records[i..j] {
                    let b = cells.bucket_of_cell(cell);
                    if b != last_bucket {
                        self.files.write(b, &seam_record)?;
                        self.counts[b] += 1;
                        last_bucket = b;
                    }
                }
            }
            i = j;
        }
        Ok(())
    }
}

/// The (position, cell) records of `cell`'s open positions grouped by partition, stable: the
/// bytes of partition `k` are `bytes[start[k] * OPEN_RECORD_BYTES..start[k + 1] * …]`, in the
/// order of `open`. Returns `(bytes, start)`.
fn open_records(open: &[[u32; 3]], cell: u32, partitions: usize) -> (Vec<u8>, Vec<usize>) {
    let part: Vec<u32> = open.iter().map(|&p| partition_of(p, partitions) as u32).collect();
    let mut start = vec![0usize; partitions + 1];
    for &k in &part {
        start[k as usize + 1] += 1;
    }
    for k in 0..partitions {
        start[k + 1] += start[k];
    }
    let mut fill = start.clone();
    let mut bytes = vec![0u8; open.len() * OPEN_RECORD_BYTES];
    for (&p, &k) in open.iter().zip(&part) {
        let at = &mut fill[k as usize];
        put_u32s(
            &mut bytes[*at * OPEN_RECORD_BYTES..(*at + 1) * OPEN_RECORD_BYTES],
            &[p[0], p[1], p[2], cell],
        );
        *at += 1;
    }
    (bytes, start)
}

/// The partition of position `p` (a multiplicative hash, the same on every machine).
fn partition_of(p: [u32; 3], partitions: usize) -> usize {
    let h = (p[0] as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (p[1] as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (p[2] as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    ((h >> 32) % partitions as u64) as usize
}

/// Write buffer per partition or seam file.
const WRITE_BUFFER: usize = 1 << 16;

fn put_u32s(out: &mut [u8], values: &[u32]) {
    for (k, v) in values.iter().enumerate() {
        out[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
}

fn get_u32s<const N: usize>(b: &[u8]) -> [u32; N] {
    std::array::from_fn(|k| u32::from_le_bytes([b[4 * k], b[4 * k + 1], b[4 * k + 2], b[4 * k + 3]]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(entries: &[([u32; 3], (u32, u32))]) -> SeamTable {
        SeamTable::from_unsorted(entries.to_vec())
    }

    #[test]
    fn external_means_a_cell_outside_the_range() {
        let t = table(&[([1, 0, 0], (2, 3)), ([0, 0, 0], (0, 5))]);
        assert!(t.contains([0, 0, 0]) && t.contains([1, 0, 0]) && !t.contains([2, 0, 0]));
        assert!(!t.external([1, 0, 0], (2, 4)), "both cells inside");
        assert!(t.external([1, 0, 0], (3, 6)), "first cell outside");
        assert!(t.external([1, 0, 0], (0, 3)), "last cell outside");
        assert!(t.external([0, 0, 0], (0, 5)), "last cell is one past the range");
        assert!(!t.external([2, 0, 0], (0, 1)), "not a seam");
    }

    #[test]
    fn retain_keeps_only_present_external_seams_and_merge_unites() {
        let t = table(&[([0, 0, 0], (0, 1)), ([1, 0, 0], (0, 4)), ([2, 0, 0], (1, 2))]);
        let kept = t.retain([[0, 0, 0], [1, 0, 0], [9, 9, 9]], (0, 2));
        assert_eq!(kept, table(&[([1, 0, 0], (0, 4))]));
        let other = table(&[([1, 0, 0], (0, 4)), ([5, 0, 0], (3, 7))]);
        let m = SeamTable::merge([&kept, &other]);
        assert_eq!(m.len(), 2);
        assert!(m.external([5, 0, 0], (0, 4)));
    }

    /// The out-of-core search against the obvious in-memory one, on a plant split into many
    /// buckets, with a budget small enough for many partitions.
    #[test]
    fn out_of_core_seams_equal_the_in_memory_ones() {
        let dir = tempfile::tempdir().unwrap();
        let (_, files) = crate::cells::tests::plant_cells(dir.path(), 200_000, 4 << 20);
        assert!(files.bucket_count() > 2, "{} buckets", files.bucket_count());
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();

        let mut expected: std::collections::BTreeMap<[u32; 3], Vec<u32>> = Default::default();
        files
            .for_each_cell(|c, m| {
                for p in crate::hlod::open_positions(&m) {
                    expected.entry(p).or_default().push(c);
                }
                Ok(())
            })
            .unwrap();
        expected.retain(|_, cells| cells.len() > 1);
        assert!(expected.len() > 100, "the plant has seams: {}", expected.len());

        let mut progress = 0;
        let seams = SeamFiles::find(&files, dir.path(), 1 << 20, &pool, &mut |d| progress = d).unwrap();
        assert!(seams.partitions > 1, "{} partitions", seams.partitions);
        assert_eq!(progress, files.cell_count() as u64);
        assert_eq!(seams.seams, expected.len() as u64);
        for b in 0..files.bucket_count() {
            let table = seams.read_bucket(b).unwrap();
            let cells = files.bucket_cells(b);
            let want: Vec<([u32; 3], (u32, u32))> = expected
                .iter()
                .filter(|(_, cs)| cs.iter().any(|c| cells.contains(c)))
                .map(|(&p, cs)| (p, (cs[0], *cs.last().unwrap())))
                .collect();
            assert_eq!(table, SeamTable::from_unsorted(want), "bucket {b}");
        }
        // Nothing of the partitions is left behind; the seam files go with `seams`.
        drop(seams);
        drop(files);
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("tw-open-") || n.starts_with("tw-seams-"))
            .collect();
        assert!(left.is_empty(), "{left:?}");
    }

    #[test]
    fn partitions_cover_every_index_deterministically() {
        let mut seen = [false; 7];
        for x in 0..200u32 {
            let k = partition_of([x, x * 3, 7], 7);
            assert_eq!(k, partition_of([x, x * 3, 7], 7));
            seen[k] = true;
        }
        assert!(seen.iter().all(|&s| s));
        assert_eq!(partition_of([5, 6, 7], 1), 0);
    }

    #[test]
    fn open_records_group_by_partition_in_input_order() {
        let open: Vec<[u32; 3]> = (0..300u32).map(|x| [x, x * 5 % 17, 3]).collect();
        for partitions in [1, 2, 7] {
            let (bytes, start) = open_records(&open, 42, partitions);
            assert_eq!(start.len(), partitions + 1);
            assert_eq!(start[partitions] * OPEN_RECORD_BYTES, bytes.len());
            for k in 0..partitions {
                let got: Vec<[u32; 4]> = bytes
                    [start[k] * OPEN_RECORD_BYTES..start[k + 1] * OPEN_RECORD_BYTES]
                    .chunks_exact(OPEN_RECORD_BYTES)
                    .map(get_u32s::<4>)
                    .collect();
                let want: Vec<[u32; 4]> = open
                    .iter()
                    .filter(|&&p| partition_of(p, partitions) == k)
                    .map(|p| [p[0], p[1], p[2], 42])
                    .collect();
                assert_eq!(got, want, "partition {k} of {partitions}");
            }
        }
        let (bytes, start) = open_records(&[], 0, 3);
        assert!(bytes.is_empty() && start == vec![0; 4]);
    }
}
