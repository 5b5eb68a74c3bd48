//! Phase 5's HLOD nodes ([`crate::hlod`], GigaWalk §4's HLODs), built off the consumer thread.
//!
//! The LOD phase's consumer takes the cells in order and starts a node's HLOD once all its
//! children are complete. Building it depends on nothing but the children's roots and seams, so
//! it is a job that any thread may run: a pool worker between two cells ([`HlodJobs::run_one`]),
//! or the consumer itself when the node comes due and nobody has started it
//! ([`HlodJobs::result`]), so that a busy pool never holds the consumer up. When a node's groups
//! are emitted is decided by the cell order alone (the pipeline emits a node a fixed number of
//! cells after starting it), so the store does not depend on which thread built what, or when.

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

use tw_store::EncodedCluster;

use crate::hlod::{build_hlod, HlodNode, HlodParams, Roots};
use crate::pages::encode_clusters;
use crate::seams::SeamTable;
use crate::types::Grid;

/// What one node's HLOD is built from.
pub struct HlodInput {
    /// The hierarchy node.
    pub node: u32,
    /// Its children's roots, in child order.
    pub children: Vec<Roots>,
    /// Its children's seams: positions shared with other cells, and which cells.
    pub child_seams: Vec<SeamTable>,
    /// The node's cells (`first..last + 1`): only seams with cells outside stay locked.
    pub range: (u32, u32),
}

/// A node's HLOD, its clusters encoded for the pages, and the merged seams of its children.
pub struct HlodBuilt {
    pub node: u32,
    pub hl: HlodNode,
    pub encoded: Result<Vec<EncodedCluster>, String>,
    pub seams: SeamTable,
    pub range: (u32, u32),
}

enum State {
    Queued(Box<HlodInput>),
    Running,
    Done(Result<Box<HlodBuilt>, String>),
    Taken,
}

/// One node's build, shared by the queue and the consumer.
pub struct HlodJob {
    state: Mutex<State>,
    done: Condvar,
}

impl HlodJob {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The input, if nobody has started the job yet; the job is then the caller's to run.
    fn claim(&self) -> Option<Box<HlodInput>> {
        let mut st = self.lock();
        match std::mem::replace(&mut *st, State::Running) {
            State::Queued(input) => Some(input),
            other => {
                *st = other;
                None
            }
        }
    }
}

/// The queue of started HLOD nodes, and what building one needs.
pub struct HlodJobs<'a> {
    queue: Mutex<VecDeque<Arc<HlodJob>>>,
    grid: &'a Grid,
    params: &'a HlodParams,
}

impl<'a> HlodJobs<'a> {
    pub fn new(grid: &'a Grid, params: &'a HlodParams) -> HlodJobs<'a> {
        HlodJobs { queue: Mutex::new(VecDeque::new()), grid, params }
    }

    fn queue(&self) -> MutexGuard<'_, VecDeque<Arc<HlodJob>>> {
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Queues a node's build; the handle gives its result ([`HlodJobs::result`]).
    pub fn start(&self, input: HlodInput) -> Arc<HlodJob> {
        let job =
            Arc::new(HlodJob { state: Mutex::new(State::Queued(Box::new(input))), done: Condvar::new() });
        self.queue().push_back(job.clone());
        job
    }

    /// Builds the oldest queued node that nobody has started, if any; whether it built one.
    pub fn run_one(&self) -> bool {
        loop {
            let Some(job) = self.queue().pop_front() else { return false };
            if let Some(input) = job.claim() {
                let built = self.build(*input);
                *job.lock() = State::Done(built);
                job.done.notify_all();
                return true;
            }
        }
    }

    /// The node built by `job`: built here if nobody has started it, else waited for.
    pub fn result(&self, job: &HlodJob) -> Result<Box<HlodBuilt>, String> {
        if let Some(input) = job.claim() {
            *job.lock() = State::Taken;
            return self.build(*input);
        }
        let mut st = job.lock();
        loop {
            match std::mem::replace(&mut *st, State::Taken) {
                State::Done(built) => return built,
                State::Taken => return Err("an HLOD node's result was taken twice".into()),
                running => {
                    *st = running;
                    st = job.done.wait(st).unwrap_or_else(|e| e.into_inner());
                }
            }
        }
    }

    /// Builds a node; a panic becomes an error, so that nobody waits for a result forever.
    fn build(&self, input: HlodInput) -> Result<Box<HlodBuilt>, String> {
        let node = input.node;
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let seams = SeamTable::merge(&input.child_seams);
            let external = |p: [u32; 3]| seams.external(p, input.range);
            let hl = build_hlod(&input.children, self.grid, self.params, &external);
            let encoded = encode_clusters(&hl.dag);
            Box::new(HlodBuilt { node, hl, encoded, seams, range: input.range })
        }))
        .map_err(|_| format!("the HLOD of hierarchy node {node} panicked"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input(node: u32) -> HlodInput {
        HlodInput { node, children: Vec::new(), child_seams: Vec::new(), range: (0, 1) }
    }

    #[test]
    fn a_job_is_built_once_by_whoever_comes_first() {
        let grid = Grid { origin: [0.0; 3], step: 1.0 };
        let params = HlodParams::default();
        let jobs = HlodJobs::new(&grid, &params);
        // Nobody ran it: the consumer builds it.
        let a = jobs.start(input(3));
        assert_eq!(jobs.result(&a).unwrap().node, 3);
        assert!(jobs.result(&a).is_err(), "a result is taken once");
        // A worker ran it (the queue skips the job the consumer took).
        let b = jobs.start(input(5));
        assert!(jobs.run_one());
        assert!(!jobs.run_one());
        assert_eq!(jobs.result(&b).unwrap().node, 5);
        // Built on another thread while the consumer waits.
        let c = jobs.start(input(7));
        std::thread::scope(|s| {
            s.spawn(|| {
                std::thread::sleep(std::time::Duration::from_millis(20));
                jobs.run_one();
            });
            assert_eq!(jobs.result(&c).unwrap().node, 7);
        });
    }
}
