//! terawalk build: turns triangle inputs into a paged, out-of-core store (see docs/FORMAT.md).
//!
//! Pipeline (GigaWalk §4, Yoon 2003 §4, Manocha §2), one module per phase:
//! 1. [`ingest`]: stream inputs into on-disk working files, compute the scene [`types::Grid`].
//! 2. [`redefine`]: GigaWalk's partition → MST clustering → partition of objects into cells.
//! 3. [`hierarchy`]: AABB tree over the cells.
//! 4. [`lod`] (its build loop in `clusterlod`) and [`hlod`]: cluster DAG inside each cell, HLOD groups above the cells (built
//!    off the consumer thread: `hlod_jobs`).
//! 5. [`pages`]: clusters packed into compressed, checksummed pages.
//! 6. write: the store file, atomically; [`pipeline::build`] runs all phases.

mod bucket_queue;
pub mod cells;
mod clusterlod;
pub mod cut;
pub mod error;
pub mod hierarchy;
pub mod hlod;
mod hlod_jobs;
mod in_order;
pub mod ingest;
pub mod lod;
pub mod pages;
mod parts;
pub mod pipeline;
pub mod redefine;
pub mod sampling;
pub mod seams;
pub mod types;
mod union_find;
pub mod workio;

pub use error::BuildError;
pub use pipeline::{build, max_worker_threads, BuildOptions, BuildProgress, BuildReport, NoProgress};
