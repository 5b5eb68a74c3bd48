//! The item buffer (docs/DESIGN.md "Measuring": exact visibility; the papers' "item buffer", e.g.
//! GigaWalk §6 and Yoon 2003 §7 measure culling against it): the frame's clusters drawn at the
//! caller's LOD cut, with depth test, into an `Rgba32Uint` target holding per pixel the object
//! id, 1 + the cluster's position in the drawn list (0 = background) and the triangle's index in
//! its cluster; read back and reduced to the exact visible sets ([`VisibleSet`]).
//!
//! Triangle indices come from `@builtin(primitive_index)` (`Features::PRIMITIVE_INDEX`: Vulkan
//! lavapipe, GL ≥ 3.2 / ES 3.2 llvmpipe); without it they are unknown ([`Item::triangle`] is
//! `None`, [`VisibleSet::triangles_known`] false). The cluster number is written into the pool's
//! slot table before each batch (ids.wgsl reads it by slot), so it stays right when the frame is
//! drawn in several batches that reuse slots.

use std::collections::{BTreeMap, HashSet};

use crate::ClusterKey;

/// What one pixel of the item buffer shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Item {
    pub object: u32,
    /// Position of the cluster in the list given to [`crate::Renderer::item_buffer`].
    pub cluster: u32,
    /// Index of the triangle in its cluster (`None` without primitive indices).
    pub triangle: Option<u32>,
}

/// An item buffer read back from the GPU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ItemBuffer {
    pub width: u32,
    pub height: u32,
    /// Per pixel, rows from the top: `[object, 1 + cluster position (0 = nothing), triangle
    /// (u32::MAX = unknown), 1]`.
    pub raw: Vec<[u32; 4]>,
    /// The drawn clusters, in the order given (index = [`Item::cluster`]).
    pub clusters: Vec<ClusterKey>,
}

/// How much of one cluster is visible.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClusterVisibility {
    /// Pixels showing the cluster.
    pub pixels: u64,
    /// Distinct triangles of the cluster seen in at least one pixel (0 when unknown).
    pub triangles: u32,
}

/// The exact visible sets of a frame, from its item buffer.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VisibleSet {
    /// Pixels showing geometry.
    pub covered_pixels: u64,
    /// Visible objects: object id → pixels showing it.
    pub objects: BTreeMap<u32, u64>,
    /// Visible clusters: key → pixels and distinct visible triangles.
    pub clusters: BTreeMap<ClusterKey, ClusterVisibility>,
    /// Distinct visible triangles over all clusters (0 when unknown).
    pub triangles: u64,
    /// Whether triangle counts are known (the adapter has primitive indices).
    pub triangles_known: bool,
}

impl ItemBuffer {
    /// The item at pixel `(x, y)`, `None` on the background or outside the image.
    pub fn item(&self, x: u32, y: u32) -> Option<Item> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let p = self.raw.get(y as usize * self.width as usize + x as usize)?;
        if p[1] == 0 {
            return None;
        }
        Some(Item { object: p[0], cluster: p[1] - 1, triangle: (p[2] != u32::MAX).then_some(p[2]) })
    }

    /// The exact visible sets. Pixels naming a cluster beyond the list (never written by this
    /// crate) are ignored.
    pub fn visible(&self) -> VisibleSet {
        let mut set = VisibleSet { triangles_known: true, ..Default::default() };
        let mut seen: HashSet<(u32, u32)> = HashSet::new();
        for p in &self.raw {
            if p[1] == 0 {
                continue;
            }
            let Some(&key) = self.clusters.get(p[1] as usize - 1) else { continue };
            set.covered_pixels += 1;
            *set.objects.entry(p[0]).or_default() += 1;
            let c = set.clusters.entry(key).or_default();
            c.pixels += 1;
            if p[2] == u32::MAX {
                set.triangles_known = false;
            } else if seen.insert((p[1], p[2])) {
                c.triangles += 1;
                set.triangles += 1;
            }
        }
        if !set.triangles_known {
            set.triangles = 0;
            for c in set.clusters.values_mut() {
                c.triangles = 0;
            }
        }
        set
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn visible_sets_from_raw_items() {
        let k = |page| ClusterKey { page, index_in_page: 0, group: 0 };
        let buf = ItemBuffer {
            width: 3,
            height: 2,
            raw: vec![
                [7, 1, 0, 1],
                [7, 1, 0, 1],
                [7, 1, 5, 1],
                [0, 0, 0, 0],
                [9, 2, 3, 1],
                [4, 9, 0, 1], // cluster beyond the list: ignored
            ],
            clusters: vec![k(10), k(11)],
        };
        assert_eq!(buf.item(2, 0), Some(Item { object: 7, cluster: 0, triangle: Some(5) }));
        assert_eq!(buf.item(0, 1), None);
        assert_eq!(buf.item(3, 0), None);
        let v = buf.visible();
        assert_eq!(v.covered_pixels, 4);
        assert_eq!(v.objects, BTreeMap::from([(7, 3), (9, 1)]));
        assert_eq!(v.clusters[&k(10)], ClusterVisibility { pixels: 3, triangles: 2 });
        assert_eq!(v.clusters[&k(11)], ClusterVisibility { pixels: 1, triangles: 1 });
        assert_eq!(v.triangles, 3);
        assert!(v.triangles_known);
    }
}
