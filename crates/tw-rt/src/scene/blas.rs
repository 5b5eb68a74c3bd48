//! Cluster BVHs, cached per decoded page (docs/DESIGN.md D8: per-page BVHs built at run time,
//! as pages load, instead of stored ones; docs/RUNTIME.md "Ray tracing" has the measurements).
//!
//! A cluster's BVH is built the first time the cluster is in a traced cut (a page holds many LOD
//! levels: only the clusters some cut needed are built) and lives at most as long as its decoded
//! page: an entry remembers its page weakly, and is dropped once the page cache has evicted the
//! page and no frame holds it any more; a page decoded again gets new entries. Within that, the
//! BVHs have a budget of their own ([`BlasCache::new`]): over it, the clusters unused for the
//! longest are dropped (least recently used; never those of the frame being traced, so a cut
//! larger than the budget is still traced whole).
//!
//! A store built with `--rt-bvh` carries each cluster's BVH shape ([`super::stored`]): the
//! cache then makes the BVH from it (a refit, no SAH) instead of building it, the same BVH bit
//! for bit.

use std::collections::HashMap;
use std::sync::{Arc, Weak};
use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use tw_runtime::{ResidentPage, SelectionPages};
use tw_store::{PageCluster, RtTree};

use crate::{Aabb, TriangleBvh};

/// One cluster, ready for rays: its triangles' BVH and their box in scene space.
#[derive(Debug)]
pub struct ClusterBlas {
    pub bvh: TriangleBvh,
    pub bounds: Aabb,
}

impl ClusterBlas {
    /// Builds the BVH of `cluster`, its grid positions scaled by `grid_step` exactly as the
    /// rasterizer scales them (tw-gpu's pool: `(g as f64 * grid_step) as f32`), so that both
    /// see the same triangles.
    pub fn build(cluster: &PageCluster, grid_step: f64) -> ClusterBlas {
        let positions: Vec<[f32; 3]> =
            cluster.positions.iter().map(|&g| scene_position(g, grid_step)).collect();
        let triangles: Vec<[u32; 3]> =
            cluster.indices.chunks_exact(3).map(|t| [t[0] as u32, t[1] as u32, t[2] as u32]).collect();
        let bounds = bounds_of(positions.iter().copied());
        let bvh = TriangleBvh::build(&positions, &triangles).unwrap_or_else(|e| {
            // A decoded page's indices were checked by the decoder: this is not reachable from
            // a store that opened, but a ray tracer must not take the process down for it.
            tracing::error!("cluster skipped by the ray tracer: {e}");
            TriangleBvh::build(&[], &[]).expect("an empty mesh builds")
        });
        ClusterBlas { bvh, bounds }
    }

    /// The BVH of `cluster` from its stored shape ([`super::stored::bvh_from_tree`]): the same
    /// as [`ClusterBlas::build`] when `tree` is the shape the builder stored; built instead
    /// (with an error logged) when the tree does not fit the cluster.
    pub fn from_tree(cluster: &PageCluster, grid_step: f64, tree: &RtTree) -> ClusterBlas {
        match super::stored::bvh_from_tree(cluster, grid_step, tree) {
            Ok(bvh) => ClusterBlas {
                bvh,
                bounds: bounds_of(cluster.positions.iter().map(|&g| scene_position(g, grid_step))),
            },
            Err(e) => {
                tracing::error!("stored cluster BVH unusable, built instead: {e}");
                ClusterBlas::build(cluster, grid_step)
            }
        }
    }

    /// Bytes held (the BVH and its triangles).
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.bvh.memory_bytes()
    }
}

/// The box of a cluster's scene-space positions.
fn bounds_of(positions: impl Iterator<Item = [f32; 3]>) -> Aabb {
    positions.fold(Aabb::EMPTY, |b, p| b.grown(Vec3::from(p)))
}

/// A scene-space position of a grid point.
pub fn scene_position(g: [u32; 3], grid_step: f64) -> [f32; 3] {
    g.map(|c| (c as f64 * grid_step) as f32)
}

struct PageEntry {
    page: Weak<ResidentPage>,
    /// Cluster index in the page → its BVH and the frame that last used it.
    clusters: HashMap<u32, (Arc<ClusterBlas>, u64)>,
    bytes: usize,
}

/// What [`BlasCache::prepare`] did in one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BlasStats {
    /// Cluster BVHs built (or made from stored shapes) for this frame.
    pub built: usize,
    /// Of which made from the store's shapes (`terawalk build --rt-bvh`) rather than built.
    pub stored: usize,
    /// Wall time of those builds (on the rayon pool).
    pub build_time: Duration,
    /// Bytes of all cached cluster BVHs after the frame.
    pub bytes: usize,
    /// Of which the BVHs of this frame's clusters (kept whatever the budget).
    pub frame_bytes: usize,
    /// Pages whose BVHs were dropped because the page cache evicted them.
    pub dropped_pages: usize,
    /// Cluster BVHs dropped to keep the budget.
    pub evicted: usize,
}

/// The cluster BVHs of the resident pages; see the module documentation.
pub struct BlasCache {
    pages: HashMap<u32, PageEntry>,
    bytes: usize,
    budget: usize,
    frame: u64,
    /// Use the pages' stored shapes when they have them.
    use_stored: bool,
}

impl BlasCache {
    /// An empty cache whose BVHs may hold `budget` bytes beyond the clusters of the frame
    /// being traced.
    pub fn new(budget: usize) -> BlasCache {
        BlasCache { pages: HashMap::new(), bytes: 0, budget, frame: 0, use_stored: true }
    }

    /// Whether the pages' stored BVH shapes are used (the default) or every BVH is built (to
    /// compare both; the BVHs are the same).
    pub fn use_stored(&mut self, on: bool) {
        self.use_stored = on;
    }

    /// The BVH of every cluster of `pages`, in its order, building the missing ones in
    /// parallel; entries of pages no longer resident are dropped first.
    pub fn prepare(&mut self, pages: &SelectionPages, grid_step: f64) -> (Vec<Arc<ClusterBlas>>, BlasStats) {
        self.frame += 1;
        let mut stats = BlasStats { dropped_pages: self.drop_evicted(), ..Default::default() };
        let entries: Vec<_> = pages.entries().collect();
        let missing: Vec<usize> = (0..entries.len())
            .filter(|&i| self.get(entries[i].0.page, entries[i].1, entries[i].0.index_in_page).is_none())
            .collect();
        if !missing.is_empty() {
            let start = Instant::now();
            let use_stored = self.use_stored;
            let built: Vec<(Arc<ClusterBlas>, bool)> = missing
                .par_iter()
                .map(|&i| {
                    let (r, page, cluster) = entries[i];
                    match page.rt_tree(r.index_in_page).filter(|_| use_stored) {
                        Some(tree) => (Arc::new(ClusterBlas::from_tree(cluster, grid_step, tree)), true),
                        None => (Arc::new(ClusterBlas::build(cluster, grid_step)), false),
                    }
                })
                .collect();
            stats.build_time = start.elapsed();
            stats.built = built.len();
            stats.stored = built.iter().filter(|b| b.1).count();
            let built = built.into_iter().map(|b| b.0);
            for (&i, blas) in missing.iter().zip(built) {
                let (r, page, _) = entries[i];
                self.insert(r.page, page, r.index_in_page, blas);
            }
        }
        let blas: Vec<Arc<ClusterBlas>> = entries
            .iter()
            .map(|(r, page, _)| self.get(r.page, page, r.index_in_page).expect("inserted above"))
            .collect();
        stats.frame_bytes = blas.iter().map(|b| b.bytes()).sum();
        stats.evicted = self.keep_budget();
        stats.bytes = self.bytes;
        (blas, stats)
    }

    /// Drops the least recently used cluster BVHs not used by this frame until the cache is
    /// within its budget; returns how many.
    fn keep_budget(&mut self) -> usize {
        if self.bytes <= self.budget {
            return 0;
        }
        let mut old: Vec<(u64, u32, u32, usize)> = self
            .pages
            .iter()
            .flat_map(|(&page, e)| {
                e.clusters
                    .iter()
                    .filter(|(_, (_, used))| *used < self.frame)
                    .map(move |(&i, (b, used))| (*used, page, i, b.bytes()))
            })
            .collect();
        old.sort_unstable();
        let mut evicted = 0;
        for (_, page, index, bytes) in old {
            if self.bytes <= self.budget {
                break;
            }
            if let Some(e) = self.pages.get_mut(&page) {
                e.clusters.remove(&index);
                e.bytes -= bytes;
                self.bytes -= bytes;
                evicted += 1;
            }
        }
        self.pages.retain(|_, e| !e.clusters.is_empty());
        evicted
    }

    /// Bytes of all cached cluster BVHs.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// Forgets every entry.
    pub fn clear(&mut self) {
        self.pages.clear();
        self.bytes = 0;
    }

    /// The BVH of cluster `index` of `page` (decoded as `resident`), marked used by this frame.
    fn get(&mut self, page: u32, resident: &Arc<ResidentPage>, index: u32) -> Option<Arc<ClusterBlas>> {
        let entry = self.pages.get_mut(&page)?;
        if !std::ptr::eq(entry.page.as_ptr(), Arc::as_ptr(resident)) {
            return None;
        }
        let (blas, used) = entry.clusters.get_mut(&index)?;
        *used = self.frame;
        Some(blas.clone())
    }

    fn insert(&mut self, page: u32, resident: &Arc<ResidentPage>, index: u32, blas: Arc<ClusterBlas>) {
        let entry = self.pages.entry(page).or_insert_with(|| PageEntry {
            page: Arc::downgrade(resident),
            clusters: HashMap::new(),
            bytes: 0,
        });
        if !std::ptr::eq(entry.page.as_ptr(), Arc::as_ptr(resident)) {
            // The page was evicted and decoded again: its old BVHs describe the old copy.
            self.bytes -= entry.bytes;
            *entry = PageEntry { page: Arc::downgrade(resident), clusters: HashMap::new(), bytes: 0 };
        }
        let bytes = blas.bytes();
        if entry.clusters.insert(index, (blas, self.frame)).is_none() {
            entry.bytes += bytes;
            self.bytes += bytes;
        }
    }

    /// Drops the entries of pages nobody holds any more; returns how many.
    fn drop_evicted(&mut self) -> usize {
        let before = self.pages.len();
        let mut freed = 0;
        self.pages.retain(|_, e| {
            let alive = e.page.strong_count() > 0;
            if !alive {
                freed += e.bytes;
            }
            alive
        });
        self.bytes -= freed;
        before - self.pages.len()
    }
}
