//! Frames whose visible set comes from elsewhere: the render side of the network cull server
//! (docs/DESIGN.md, D7; Govindaraju's thesis ch. 3, whose display GPU draws the node ids the
//! culling GPU streams to it). Two pieces:
//! - [`ClusterIds`]: one stable number per cluster of a store, its position in the store's page
//!   order (page 0's clusters in their order within the page, then page 1's, …), which is what
//!   travels on the wire as a 4-byte id; the same store on both ends gives the same numbers.
//! - [`Walkthrough::draw_clusters`]: draws exactly a given list of clusters with the frame's
//!   camera, no selection and no culling of its own.

use std::time::Instant;

use tw_gpu::{Image, Target};
use tw_runtime::{Camera, ClusterRef, SelectStats, StreamStats};
use tw_store::Store;

use crate::{lookup, resident_pages, FrameError, FrameInfo, FrameTimes, OcclusionStats, Walkthrough};

/// The global cluster numbering of a store (see the module): id ↔ [`ClusterRef`].
#[derive(Clone, Debug, Default)]
pub struct ClusterIds {
    /// Id of each page's first cluster, and the total at the end.
    first: Vec<u32>,
    /// The group of each id.
    group: Vec<u32>,
}

impl ClusterIds {
    /// The numbering of `store`. A store whose groups do not cover its clusters exactly
    /// (`Store::verify` refuses those) leaves the uncovered ids in group `u32::MAX`.
    pub fn new(store: &Store) -> ClusterIds {
        let mut first = Vec::with_capacity(store.pages().len() + 1);
        let mut total = 0u32;
        for p in store.pages() {
            first.push(total);
            total = total.saturating_add(p.cluster_count);
        }
        first.push(total);
        let mut group = vec![u32::MAX; total as usize];
        for (gi, g) in store.groups().iter().enumerate() {
            let Some(&base) = first.get(g.page as usize) else { continue };
            let start = base as usize + g.first_cluster as usize;
            let end = (start + g.cluster_count as usize).min(group.len());
            if start < end {
                group[start..end].fill(gi as u32);
            }
        }
        ClusterIds { first, group }
    }

    /// Clusters numbered.
    pub fn len(&self) -> usize {
        self.group.len()
    }

    pub fn is_empty(&self) -> bool {
        self.group.is_empty()
    }

    /// The id of `c`, `None` when `c` is not a cluster of the store.
    pub fn id(&self, c: &ClusterRef) -> Option<u32> {
        let (start, end) = (*self.first.get(c.page as usize)?, *self.first.get(c.page as usize + 1)?);
        let id = start.checked_add(c.index_in_page).filter(|&id| id < end)?;
        Some(id)
    }

    /// The cluster numbered `id`, `None` past the last (an id from a peer is not trusted).
    pub fn cluster(&self, id: u32) -> Option<ClusterRef> {
        let group = *self.group.get(id as usize)?;
        // The last page whose first id is ≤ id (empty pages share their first id with the next).
        let page = self.first.partition_point(|&f| f <= id).checked_sub(1)?;
        Some(ClusterRef { page: page as u32, index_in_page: id - self.first[page], group })
    }
}

impl Walkthrough {
    /// Draws exactly `clusters` (no selection, no culling) with `camera` into the renderer's
    /// own target; their pages are loaded through the page cache where not resident (the
    /// frame may wait for the disk). Unknown or undecodable clusters are skipped.
    pub fn draw_clusters(
        &mut self,
        camera: &Camera,
        clusters: &[ClusterRef],
    ) -> Result<FrameInfo, FrameError> {
        let start = Instant::now();
        let pages = resident_pages(&self.streamer, clusters);
        let decoded = lookup(&pages, clusters);
        let select = start.elapsed();
        let grid_step = self.streamer.store().header().grid_step;
        self.renderer.begin_frame();
        self.renderer.draw(Target::Own, camera, grid_step, &decoded, true)?;
        let gpu = self.renderer.stats();
        let triangles = crate::triangles(&decoded);
        Ok(FrameInfo {
            times: FrameTimes {
                select,
                select_cut: select,
                upload: gpu.upload,
                render: gpu.render,
                total: start.elapsed(),
                ..FrameTimes::default()
            },
            select: SelectStats::default(),
            stream: StreamStats::default(),
            cut_triangles: triangles,
            triangles: gpu.triangles,
            masked_triangles: gpu.masked_triangles,
            clusters: gpu.clusters,
            draw_calls: gpu.draw_calls,
            occlusion: OcclusionStats::default(),
            gpu: gpu.pool,
            shadow: Default::default(),
        })
    }

    /// [`draw_clusters`](Self::draw_clusters), then the image read back (as
    /// [`frame`](Self::frame) does: the time includes the GPU finishing).
    pub fn frame_of_clusters(
        &mut self,
        camera: &Camera,
        clusters: &[ClusterRef],
    ) -> Result<(Image, FrameInfo), FrameError> {
        let start = Instant::now();
        let mut info = self.draw_clusters(camera, clusters)?;
        let image = self.renderer.read_color()?;
        info.times.render = self.renderer.stats().render;
        info.times.total = start.elapsed();
        Ok((image, info))
    }
}
