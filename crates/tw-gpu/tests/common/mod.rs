//! Helpers shared by tw-gpu's integration tests: a small synthetic scene of axis-aligned quads
//! facing a camera on +z.
#![allow(dead_code)]

use tw_runtime::ClusterRef;
use tw_store::PageCluster;

/// The reference of a scene's `page`-th cluster (one cluster a page).
pub fn key(page: u32) -> ClusterRef {
    ClusterRef { page, index_in_page: 0, group: 0 }
}

/// A quad at height `z` over `[x0, x1] × [y0, y1]` (grid units), of object `object`.
pub fn quad(x0: u32, y0: u32, x1: u32, y1: u32, z: u32, object: u32) -> PageCluster {
    PageCluster {
        positions: vec![[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]],
        indices: vec![0, 1, 2, 0, 2, 3],
        objects: vec![object, object],
        self_error: 0.0,
        self_sphere: [0.0, 0.0, 0.0, 1.0],
        group: 0,
        level: 0,
    }
}
