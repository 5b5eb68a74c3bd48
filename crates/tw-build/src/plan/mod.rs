//! The build as a plan of jobs (docs/BUILD.md, "A plan of jobs"): Wald 2004's preprocessing
//! and GigaWalk §4's independent cells, run as separate processes that hand their results over
//! in files, so that a scheduler (Slurm, Kubernetes) can run them on other machines.
//!
//! Jobs (`graph`):
//! 1. `prepare`: phases 1–4 (ingest, redefine and hierarchy, distribute, seams) into
//!    `DIR/prepared/`: the bucket and seam files, and `state.bin` (the scene's figures, the
//!    hierarchy, the files' layout);
//! 2. `cells-K`, one per shard (a range of buckets, about equal in triangles): the LOD of its
//!    cells (`crate::cell_pass`) and the HLOD of the hierarchy nodes whose cells all lie in the
//!    shard (`shard_hlod`), each cell's DAG and each node with their encoded clusters written
//!    to `DIR/cells/cells-K.bin` with an index (`records`);
//! 3. `pack`: phase 5's consumer and phase 6 over the cells read back in order: the HLOD of the
//!    nodes that span shards (the merges up the tree), pages, tables, the store. It runs the
//!    plain build's code on the same inputs, and HLOD nodes name their groups by provisional ids
//!    until the consumer emits them (`crate::provisional`), so the store is byte-identical to
//!    a plain build's.
//!
//! Every job writes its outputs under temporary names and renames them into place when done, so
//! a killed job leaves nothing that a later job could mistake for a result; re-running it
//! starts it over. Which jobs are done is the caller's record (`terawalk build-job` writes
//! `DIR/done/JOB`).

mod graph;
mod jobs;
mod records;
mod shard_hlod;

pub use graph::{job_graph, Estimate, JobKind, JobSpec};
pub use jobs::{run_cells, run_pack, run_prepare, CellsReport};
pub(crate) use records::CellRecords;
