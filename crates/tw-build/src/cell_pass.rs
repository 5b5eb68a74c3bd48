//! Phase 5's pass over the cells (`crate::pipeline`): each cell's DAG made on the pool and
//! handed, in cell order, to a consumer on the calling thread, with the seams of its bucket.
//!
//! One pass serves three callers: a plain build (cells built from their buckets and consumed
//! into pages at once), a build plan's `cells` job (built and written to the plan's files:
//! `crate::plan`) and its `pack` job (read back from those files and consumed into pages, so
//! that the store is the plain build's, byte for byte). A loader thread reads the next bucket
//! (and its seams) while the pool works on the current one, so neither the read nor the end of
//! a bucket leaves a core idle; at most two buckets are held.

use std::ops::Range;

use tw_store::EncodedCluster;

use crate::bucket_queue::{BucketQueue, LoadedBucket};
use crate::cells::CellFiles;
use crate::error::BuildError;
use crate::in_order::{for_each_in_order, Window};
use crate::lod::{build_cell_lod_with_seams, LodParams};
use crate::pages::encode_clusters;
use crate::seams::{SeamFiles, SeamTable};
use crate::types::{Grid, LodDag};

/// A cell's DAG, its clusters encoded for the pages (one per cluster of `dag`), and the
/// duplicate triangles its mesh left out.
pub(crate) struct BuiltCell {
    pub dag: LodDag,
    pub encoded: Result<Vec<EncodedCluster>, String>,
    pub duplicates: u64,
}

impl BuiltCell {
    /// The heap the cell holds while it waits for the consumer.
    fn heap_bytes(&self) -> usize {
        let encoded = self.encoded.as_ref().map_or(0, |e| e.iter().map(|c| c.bytes.capacity()).sum());
        self.dag.heap_bytes() + encoded
    }
}

/// Where the cells' DAGs come from.
pub(crate) enum CellSource<'a> {
    /// Built from the cells' buckets, their seams locked.
    Build { grid: &'a Grid, params: &'a LodParams },
    /// Read back from a build plan's `cells` jobs.
    Read(&'a crate::plan::CellRecords),
}

impl<'a> CellSource<'a> {
    /// The plan's records, when the cells are read back from them.
    pub fn records(&self) -> Option<&'a crate::plan::CellRecords> {
        match self {
            CellSource::Build { .. } => None,
            CellSource::Read(r) => Some(r),
        }
    }
}

/// One pass: the buckets `buckets` of `cells` (all of them in a plain build, a shard's in a
/// plan), `window` of built cells held ahead of the consumer at most.
pub(crate) struct CellPass<'a> {
    pub cells: &'a CellFiles,
    pub seams: &'a SeamFiles,
    pub buckets: Range<usize>,
    pub window: Window,
    pub source: CellSource<'a>,
}

impl CellPass<'_> {
    /// The cells of the pass's buckets.
    pub fn cell_range(&self) -> Range<u32> {
        if self.buckets.is_empty() {
            return 0..0;
        }
        self.cells.bucket_cells(self.buckets.start).start..self.cells.bucket_cells(self.buckets.end - 1).end
    }

    /// Runs the pass: `take(cell, built, its bucket's seams)` for every cell in order, on this
    /// thread; `idle` runs on workers that have no cell to build (a plain build's HLOD nodes).
    /// Each bucket is released after its last cell, and its files deleted where they were a
    /// plain build's temporaries. Returns the most the window held.
    pub fn run(
        &self,
        pool: &rayon::ThreadPool,
        idle: &(dyn Fn() -> bool + Sync),
        mut take: impl FnMut(u32, BuiltCell, &SeamTable) -> Result<(), BuildError>,
    ) -> Result<Window, BuildError> {
        let cells = self.cell_range();
        let queue = BucketQueue::new(self.cells.bucket_count(), self.buckets.clone());
        let read_triangles = matches!(self.source, CellSource::Build { .. });
        std::thread::scope(|scope| -> Result<Window, BuildError> {
            let loader = scope.spawn(|| {
                queue.load_all(|b| {
                    let bucket = if read_triangles { Some(self.cells.read_bucket(b)?) } else { None };
                    Ok(LoadedBucket { bucket, seams: self.seams.read_bucket(b)? })
                })
            });
            let result = for_each_in_order(
                pool,
                cells.len(),
                self.window,
                |k| self.make(cells.start + k as u32, &queue),
                idle,
                |c| c.as_ref().map_or(0, |c| c.as_ref().map_or(0, BuiltCell::heap_bytes)),
                |k, built| self.hand_over(cells.start + k as u32, built, &queue, &mut take),
            );
            queue.stop();
            let loaded =
                loader.join().map_err(|_| BuildError::Internal("the bucket loader panicked".into()))?;
            let held = result?;
            loaded?;
            Ok(held)
        })
    }

    /// Cell `i`'s DAG, on the pool (`None`: its bucket failed to load; the queue has the error).
    fn make(&self, i: u32, queue: &BucketQueue) -> Option<Result<BuiltCell, BuildError>> {
        let loaded = queue.get(self.cells.bucket_of_cell(i))?;
        Some(match &self.source {
            CellSource::Build { grid, params } => {
                let bucket = loaded.bucket.as_ref()?;
                let external = |p: [u32; 3]| loaded.seams.contains(p);
                let mesh = bucket.mesh(i);
                let dag = build_cell_lod_with_seams(&mesh, grid, params, &external);
                let encoded = encode_clusters(&dag);
                Ok(BuiltCell { dag, encoded, duplicates: mesh.duplicates })
            }
            CellSource::Read(records) => records.read(i),
        })
    }

    /// Gives cell `i` to `take`, then frees its bucket if it was the bucket's last cell. On an
    /// error (or a bucket that failed to load) stops the loader, so that workers waiting for a
    /// bucket it will not read wake up.
    fn hand_over(
        &self,
        i: u32,
        built: Option<Result<BuiltCell, BuildError>>,
        queue: &BucketQueue,
        take: &mut impl FnMut(u32, BuiltCell, &SeamTable) -> Result<(), BuildError>,
    ) -> Result<(), BuildError> {
        let b = self.cells.bucket_of_cell(i);
        let (Some(built), Some(loaded)) = (built, queue.get(b)) else {
            queue.stop();
            return Err(queue.take_error());
        };
        if let Err(e) = built.and_then(|built| take(i, built, &loaded.seams)) {
            queue.stop();
            return Err(e);
        }
        if i + 1 == self.cells.bucket_cells(b).end {
            drop(loaded);
            queue.release(b);
            self.cells.discard_bucket(b);
            self.seams.discard_bucket(b);
            // A bucket's meshes and DAGs are freed: give their pages back, or the fragments
            // between live blocks stay resident (one heap for all threads).
            tw_core::mem::return_free_heap_pages();
        }
        Ok(())
    }
}
