//! The LOD phase's bucket loader (`crate::pipeline`, step 5): one thread reads the buckets of
//! cells and their seams in order, a bounded number ahead of the consumer, while the pool builds
//! the cells of the buckets already read.

use crate::error::BuildError;
use crate::seams::SeamTable;

/// A bucket of cells and its seams, read ahead of the cells that need them.
pub(crate) struct LoadedBucket {
    /// The triangles (`None` where the cells' DAGs are read from a build plan's files instead).
    pub bucket: Option<crate::cells::Bucket>,
    pub seams: SeamTable,
}

/// Buckets read in order by one loader thread, at most [`BUCKETS_AHEAD`] + 1 held at a time:
/// the consumer's current bucket and the next ones.
pub(crate) struct BucketQueue {
    state: std::sync::Mutex<QueueState>,
    cond: std::sync::Condvar,
    /// The buckets this queue reads (a build plan's job reads a range of them).
    range: std::ops::Range<usize>,
}

/// Buckets the loader may read beyond the one the consumer is in.
const BUCKETS_AHEAD: usize = 1;

struct QueueState {
    slots: Vec<Option<std::sync::Arc<LoadedBucket>>>,
    /// Buckets `0..loaded` have been read (or failed: `error`).
    loaded: usize,
    /// Buckets `0..released` are done with.
    released: usize,
    error: Option<BuildError>,
    stop: bool,
}

impl BucketQueue {
    /// A queue over buckets `range` of `buckets`.
    pub(crate) fn new(buckets: usize, range: std::ops::Range<usize>) -> BucketQueue {
        BucketQueue {
            state: std::sync::Mutex::new(QueueState {
                slots: vec![None; buckets],
                loaded: range.start,
                released: range.start,
                error: None,
                stop: false,
            }),
            cond: std::sync::Condvar::new(),
            range,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, QueueState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The loader: reads every bucket in order, waiting while [`BUCKETS_AHEAD`] are ahead of the
    /// consumer; stops at the first error (kept for the consumer) or at [`BucketQueue::stop`].
    pub(crate) fn load_all(
        &self,
        load: impl Fn(usize) -> Result<LoadedBucket, BuildError>,
    ) -> Result<(), BuildError> {
        let n = self.range.end;
        for b in self.range.clone() {
            {
                let mut st = self.lock();
                while !st.stop && b > st.released + BUCKETS_AHEAD {
                    st = self.cond.wait(st).unwrap_or_else(|e| e.into_inner());
                }
                if st.stop {
                    return Ok(());
                }
            }
            let r = load(b);
            let mut st = self.lock();
            st.loaded = b + 1;
            match r {
                Ok(l) => st.slots[b] = Some(std::sync::Arc::new(l)),
                Err(e) => {
                    st.error = Some(e);
                    st.loaded = n;
                    drop(st);
                    self.cond.notify_all();
                    return Ok(());
                }
            }
            drop(st);
            self.cond.notify_all();
        }
        Ok(())
    }

    /// Bucket `b` once it is read; None if it could not be (see [`BucketQueue::take_error`]) or
    /// the queue stopped.
    pub(crate) fn get(&self, b: usize) -> Option<std::sync::Arc<LoadedBucket>> {
        let mut st = self.lock();
        while st.loaded <= b && !st.stop {
            st = self.cond.wait(st).unwrap_or_else(|e| e.into_inner());
        }
        st.slots.get(b).cloned().flatten()
    }

    /// The consumer is done with bucket `b` (and every one before it).
    pub(crate) fn release(&self, b: usize) {
        let mut st = self.lock();
        st.slots[b] = None;
        st.released = b + 1;
        drop(st);
        self.cond.notify_all();
    }

    /// Why a bucket could not be had.
    pub(crate) fn take_error(&self) -> BuildError {
        self.lock().error.take().unwrap_or_else(|| BuildError::Param("bucket loading stopped".into()))
    }

    pub(crate) fn stop(&self) {
        self.lock().stop = true;
        self.cond.notify_all();
    }
}
