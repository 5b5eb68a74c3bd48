//! Phase 5: packing clusters into pages (docs/DESIGN.md, D4; Manocha §5.4 for the paging idea).
//!
//! Groups arrive one at a time (a cell's LOD groups, then HLOD groups as the hierarchy is built
//! bottom-up). Each group goes whole into the open page of its LOD level, so that a page holds
//! spatially coherent clusters of one level (cells arrive in hierarchy leaf order); a page is
//! written when it reaches [`PageParams::page_triangles`]. Groups of the top of the hierarchy go
//! to separate "root" pages, which the runtime keeps resident. The page index and the position of
//! each group's first cluster are reported back so that the group table can point at them.
//! Clusters arrive encoded (`tw_store::EncodedCluster`, a cell's on the pool that built its
//! DAG): a page is the concatenation of its clusters' encodings.
//!
//! With [`PageParams::rt_bvh`] (`terawalk build --rt-bvh`) each cluster is followed by the shape
//! of its ray-tracing BVH (docs/FORMAT.md, "Ray-tracing trees"), made when its page is written,
//! on the rayon pool, from the cluster as a reader decodes it.

use rayon::prelude::*;
use tw_store::{ClusterParts, EncodedCluster, PageCluster, RtTree, StoreWriter};

use crate::error::BuildError;
use crate::types::{LodCluster, LodDag};

/// Makes the ray-tracing tree of a decoded cluster at a grid step (`tw_rt::scene::stored::
/// cluster_tree`; passed in because the ray tracer's crate depends on the runtime's, not on the
/// builder's).
pub type RtTreeFn = fn(&PageCluster, f64) -> Result<RtTree, String>;

/// Page sizing, and the optional ray-tracing trees.
#[derive(Clone, Copy, Debug)]
pub struct PageParams {
    /// A page is written once it holds this many triangles (a group is never split; a single
    /// group larger than this gets a page of its own). 2048 triangles encode to ~10–15 KiB.
    /// Smaller pages hold less that a frame does not draw: a cut draws 16–18 % of the bytes of
    /// 8192-triangle pages it draws from and 35–41 % of 2048-triangle ones, so the 10^9 plant's
    /// walk at τ = 1 fits `--memory 1G` with 2048 and needed ~3G with 8192, at the same build
    /// time and frame times at 10^8 (docs/benchmarks-log.md, session 33).
    pub page_triangles: usize,
    /// Store each cluster's ray-tracing tree, made by this function (None: no trees, the
    /// default; the ray tracer then builds the BVHs as pages load).
    pub rt_bvh: Option<RtTreeFn>,
}

impl Default for PageParams {
    fn default() -> Self {
        PageParams { page_triangles: 2048, rt_bvh: None }
    }
}

/// Where a group's clusters ended up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GroupPlacement {
    pub group: u32,
    pub page: u32,
    pub first_cluster: u32,
}

struct OpenPage {
    clusters: Vec<EncodedCluster>,
    triangles: usize,
    /// (group, first cluster) of every group in the page.
    groups: Vec<(u32, u32)>,
}

/// Packs groups into pages and streams the pages to the store writer.
pub struct PagePacker {
    params: PageParams,
    /// The store's grid step (scene space of the ray-tracing trees).
    grid_step: f64,
    /// Open pages by (root, level).
    open: Vec<Option<OpenPage>>,
    placements: Vec<GroupPlacement>,
    pub pages_written: u32,
    pub root_pages: u32,
}

impl PagePacker {
    pub fn new(params: PageParams, grid_step: f64) -> PagePacker {
        PagePacker {
            params,
            grid_step,
            open: Vec::new(),
            placements: Vec::new(),
            pages_written: 0,
            root_pages: 0,
        }
    }

    /// Adds one group (all its clusters, encoded with the scene-wide group id).
    pub fn add_group(
        &mut self,
        writer: &mut StoreWriter,
        group: u32,
        level: u8,
        root: bool,
        clusters: Vec<EncodedCluster>,
    ) -> Result<(), BuildError> {
        let slot = level as usize * 2 + root as usize;
        if self.open.len() <= slot {
            self.open.resize_with(slot + 1, || None);
        }
        let tris: usize = clusters.iter().map(|c| c.triangles).sum();
        if let Some(p) = &self.open[slot] {
            if p.triangles > 0 && p.triangles + tris > self.params.page_triangles {
                self.flush(writer, slot)?;
            }
        }
        let page = self.open[slot].get_or_insert_with(|| OpenPage {
            clusters: Vec::new(),
            triangles: 0,
            groups: Vec::new(),
        });
        page.groups.push((group, page.clusters.len() as u32));
        page.triangles += tris;
        page.clusters.extend(clusters);
        Ok(())
    }

    fn flush(&mut self, writer: &mut StoreWriter, slot: usize) -> Result<(), BuildError> {
        let Some(mut page) = self.open[slot].take() else { return Ok(()) };
        if let Some(rt) = self.params.rt_bvh {
            let step = self.grid_step;
            page.clusters
                .par_iter_mut()
                .try_for_each(|c| append_rt_tree(c, rt, step))
                .map_err(BuildError::Internal)?;
        }
        let root = slot % 2 == 1;
        let index = writer.add_encoded_page(&page.clusters, root).map_err(BuildError::store)?;
        self.pages_written += 1;
        self.root_pages += root as u32;
        for (group, first_cluster) in page.groups {
            self.placements.push(GroupPlacement { group, page: index, first_cluster });
        }
        Ok(())
    }

    /// Writes every open page; returns the placement of every group added.
    pub fn finish(mut self, writer: &mut StoreWriter) -> Result<(Vec<GroupPlacement>, u32, u32), BuildError> {
        for slot in 0..self.open.len() {
            self.flush(writer, slot)?;
        }
        Ok((self.placements, self.pages_written, self.root_pages))
    }
}

/// Appends the ray-tracing tree of `c` to its bytes: the tree of the cluster as a reader decodes
/// it (canonical form), at the store's grid step.
fn append_rt_tree(c: &mut EncodedCluster, rt: RtTreeFn, grid_step: f64) -> Result<(), String> {
    let decoded = tw_store::codec::decode_page(&c.bytes, 1).map_err(|e| format!("ray-tracing tree: {e}"))?;
    let tree = rt(&decoded[0], grid_step)?;
    tree.encode(c.triangles, &mut c.bytes)
}

/// Every cluster of `dag`, encoded for a page (group id 0 until the pipeline sets it).
pub(crate) fn encode_clusters(dag: &LodDag) -> Result<Vec<EncodedCluster>, String> {
    dag.clusters
        .iter()
        .enumerate()
        .map(|(i, c)| EncodedCluster::from_parts(cluster_parts(c)).map_err(|m| format!("cluster {i}: {m}")))
        .collect()
}

/// `c` as the codec takes it, under group 0.
fn cluster_parts(c: &LodCluster) -> ClusterParts<'_> {
    ClusterParts {
        positions: &c.positions,
        indices: &c.indices,
        objects: &c.objects,
        self_error: c.self_error,
        self_sphere: [
            c.self_sphere.center[0],
            c.self_sphere.center[1],
            c.self_sphere.center[2],
            c.self_sphere.radius,
        ],
        group: 0,
        level: c.level,
    }
}
