//! terawalk build: turns triangle inputs into a paged, out-of-core store (see docs/FORMAT.md).
//!
//! Pipeline (GigaWalk §4, Yoon 2003 §4, Manocha §2), one module per phase:
//! 1. `ingest`: stream inputs into on-disk working files, compute the scene [`Grid`].
//! 2. `redefine`: GigaWalk's partition → MST clustering → partition of objects into cells.
//! 3. `hierarchy`: AABB tree over the cells.
//! 4. `lod` (its build loop in `clusterlod`) and `hlod`: cluster DAG inside each cell, HLOD groups above the cells (built
//!    off the consumer thread: `hlod_jobs`).
//! 5. `pages`: clusters packed into compressed, checksummed pages.
//! 6. write: the store file, atomically; [`build`] runs all phases (`pipeline`).
//!
//! [`plan`] runs the same phases as separate jobs (a build plan for a cluster's scheduler).
//!
//! Beside them: `cells` (triangles distributed into their cells, out of core), `seams` (seams
//! between cells), `sampling` (the centroid samples redefinition plans its splits from), `cut`
//! (cut extraction and the checks of the cluster DAG model), `types` (plain data handed between
//! the phases), `workio` (working-file I/O off the calling thread), `error` ([`BuildError`]).
//!
//! The modules are private; what other crates use is re-exported here. `unnameable_types` keeps
//! every type that a public signature or field shows reachable by name.

#![warn(unnameable_types)]

mod bucket_queue;
mod cell_pass;
mod cells;
mod clusterlod;
mod cut;
mod error;
mod hierarchy;
mod hlod;
mod hlod_jobs;
mod in_order;
mod ingest;
mod lod;
mod pages;
mod part_shape;
mod parts;
mod pipeline;
pub mod plan;
mod provisional;
mod redefine;
mod sampling;
mod seams;
mod types;
mod union_find;
mod workio;

pub use cut::{
    boundary_edges, check_complete, check_complete_with, check_dag, cluster_triangles, cut_triangles,
    extract_cut, open_edges, GridTriangle, ThinPieces, OPENING_SLACK,
};
pub use error::BuildError;
pub use hlod::HlodParams;
pub use lod::LodParams;
pub use pages::{PageParams, RtTreeFn};
pub use pipeline::{
    build, max_worker_threads, work_root, BuildOptions, BuildProgress, BuildReport, HlodDepthStats,
    NoProgress, WorkDir,
};
pub use redefine::{RedefineParams, RedefineReport};
pub use types::{Grid, LodCluster, LodDag, LodGroup, Sphere};
