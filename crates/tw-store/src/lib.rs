//! The terawalk store: the `scene.tw` file that `terawalk build` writes and the runtime, the ray
//! tracer and the collision code read. The format is specified in `docs/FORMAT.md`.
//!
//! A store holds a scene as a *cluster DAG* (clusters of ≤ 128 triangles over vertices on one
//! scene-wide integer grid, grouped into LOD groups with monotone object-space errors), attached
//! to the nodes of a spatial hierarchy (the *skeleton*), with the links between groups (each
//! group's *sources*, the finer groups it was simplified from, and their inverse, its
//! *parents*), and paged: clusters are packed into
//! compressed, checksummed pages that can be loaded and decoded independently.
//!
//! - [`format`](mod@format): the on-disk structures (header, object table, nodes, groups, page table) and
//!   their structural invariants.
//! - [`codec`]: encoding and decoding of one page ([`PageCluster`]s).
//! - [`StoreWriter`]: streams pages to disk, then writes the tables; atomic and deterministic.
//! - [`Store`]: opens (memory-mapped) and validates a store, decodes pages, verifies it.
//!
//! ```
//! use tw_store::{Group, Node, Object, PageCluster, Store, StoreInfo, StoreWriter};
//!
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("scene.tw");
//!
//! // One cluster: a single triangle of object 0, in one root group on the root node.
//! let cluster = PageCluster {
//!     positions: vec![[0, 0, 0], [10, 0, 0], [0, 10, 0]],
//!     indices: vec![0, 1, 2],
//!     objects: vec![0],
//!     self_error: 0.0,
//!     self_sphere: [0.5, 0.5, 0.0, 1.0],
//!     group: 0,
//!     level: 0,
//! };
//! let mut writer = StoreWriter::create(&path)?;
//! let page = writer.add_page(std::slice::from_ref(&cluster), true)?;
//! let info = StoreInfo {
//!     bounds_min: [0.0; 3],
//!     bounds_max: [1.0, 1.0, 0.0],
//!     grid_origin: [0.0; 3],
//!     grid_step: 0.1,
//!     units: "m".into(),
//!     up_axis: 2,
//!     build_options: "memory=2G".into(),
//!     input_triangles: 1,
//! };
//! let objects = [Object { name: "floor".into(), color: Some([200, 200, 200, 255]), triangles: 1 }];
//! let nodes = [Node { min: [0; 3], max: [10, 10, 0], group_count: 1, max_error: f32::INFINITY, ..Default::default() }];
//! let groups = [Group {
//!     sphere: [0.5, 0.5, 0.0, 1.0],
//!     error: f32::INFINITY,
//!     page,
//!     cluster_count: 1,
//!     triangles: 1,
//!     ..Default::default()
//! }];
//! writer.finish(&info, &objects, &nodes, &groups, &[])?;
//!
//! let store = Store::open(&path)?;
//! assert_eq!(store.objects()[0].name, "floor");
//! let clusters = store.page(store.groups()[0].page)?;
//! assert_eq!(clusters, vec![cluster.canonical()]);
//! let report = store.verify(|_done, _total| {})?;
//! assert_eq!(report.triangles, 1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![deny(unsafe_code)]

/// Temporary paths removed on a signal or by the next build (in tw-core: the importers' writers
/// register theirs too).
pub use tw_core::cleanup;
pub mod codec;
pub mod error;
pub mod format;
mod read;
pub mod rt;
pub mod units;
mod write;

pub use codec::{ClusterParts, EncodedCluster, PageCluster, MAX_TRIANGLES, MAX_VERTICES};
pub use error::{CodecError, StoreError};
pub use format::{Group, GroupLinks, Header, Node, PageEntry, FORMAT_VERSION};
pub use read::{Store, VerifyReport};
pub use rt::RtTree;
pub use write::{temporary_prefix, Object, StoreInfo, StoreWriter, WriteSummary};

/// Fuzzing entry point: opens `data` as a store and, when it opens, verifies it and decodes
/// every page. Must never panic, whatever the bytes.
pub fn fuzz_bytes(data: &[u8]) {
    if let Ok(store) = Store::from_bytes(data.to_vec()) {
        let _ = store.verify(|_, _| {});
        for i in 0..store.pages().len() as u32 {
            let _ = store.page(i);
        }
        for g in 0..store.groups().len() as u32 + 1 {
            let _ = (store.group_sources(g), store.group_parents(g));
        }
    }
}
