//! Streaming chosen clusters' triangles into a [`TriangleSink`] (tw-io's GLB writer).
//!
//! Clusters come sorted by page ([`crate::cut`]); each page is taken from the
//! [`PageCache`] once for its run of clusters, so memory is the cache's budget plus the
//! writer's per-run records. An object is announced to the sink when its first triangle comes
//! (name and colour from the store's object table), so a file lists only the objects it has.
//! A cluster's triangles are handed over one object at a time, each as an indexed chunk over
//! the vertices that object uses (positions in input coordinates, f64), so the GLB writer
//! keeps them indexed and makes one mesh per object.

use std::sync::Arc;

use tw_core::Rgba8;
use tw_io::{MeshChunk, ObjectInfo, TriangleSink};
use tw_runtime::{ClusterRef, PageCache, ResidentPage};
use tw_store::{PageCluster, Store};

use crate::cut::Region;
use crate::error::ExportError;
use crate::frame::grid_to_input;

/// What [`emit_clusters`] handed over.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Emitted {
    pub triangles: u64,
    /// Triangles left out because a vertex lies outside the region.
    pub outside: u64,
}

/// Streams the triangles of `clusters` (sorted by page) into `sink`. With a `region`, only the
/// triangles whose three vertices lie in it (a closed box) are kept.
pub fn emit_clusters(
    store: &Store,
    cache: &PageCache,
    clusters: &[ClusterRef],
    region: Option<&Region>,
    sink: &mut dyn TriangleSink,
) -> Result<Emitted, ExportError> {
    let mut announced = vec![false; store.objects().len()];
    let mut page: Option<(u32, Arc<ResidentPage>)> = None;
    let mut scratch = Scratch::default();
    let mut emitted = Emitted::default();
    for c in clusters {
        if page.as_ref().is_none_or(|(p, _)| *p != c.page) {
            let resident = cache
                .get(store, c.page)
                .map_err(|e| ExportError::Store { store: store.path().to_path_buf(), source: e })?;
            page = Some((c.page, resident));
        }
        let Some((_, resident)) = &page else { continue };
        let Some(cluster) = resident.clusters.get(c.index_in_page as usize) else {
            return Err(ExportError::Invalid(format!(
                "{}: page {} has no cluster {}",
                store.path().display(),
                c.page,
                c.index_in_page
            )));
        };
        emit_cluster(store, cluster, region, &mut announced, &mut scratch, sink, &mut emitted)?;
    }
    Ok(emitted)
}

/// Buffers reused from cluster to cluster.
#[derive(Default)]
struct Scratch {
    input: Vec<[f64; 3]>,
    positions: Vec<[f64; 3]>,
    indices: Vec<u32>,
    /// Per cluster vertex: its index in `positions` for the current object, or `u32::MAX`.
    remap: Vec<u32>,
    objects: Vec<u32>,
}

/// One cluster: its triangles grouped by object, each group as one indexed chunk.
fn emit_cluster(
    store: &Store,
    cluster: &PageCluster,
    region: Option<&Region>,
    announced: &mut [bool],
    s: &mut Scratch,
    sink: &mut dyn TriangleSink,
    emitted: &mut Emitted,
) -> Result<(), ExportError> {
    let header = store.header();
    s.input.clear();
    s.input.extend(cluster.positions.iter().map(|&g| grid_to_input(header, g)));
    s.objects.clear();
    s.objects.extend_from_slice(&cluster.objects);
    s.objects.sort_unstable();
    s.objects.dedup();
    let objects = std::mem::take(&mut s.objects);
    for &object in &objects {
        s.positions.clear();
        s.indices.clear();
        s.remap.clear();
        s.remap.resize(s.input.len(), u32::MAX);
        for (t, tri) in cluster.indices.chunks_exact(3).enumerate() {
            if cluster.objects.get(t) != Some(&object) {
                continue;
            }
            let corners = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
            let (Some(&a), Some(&b), Some(&c)) =
                (s.input.get(corners[0]), s.input.get(corners[1]), s.input.get(corners[2]))
            else {
                return Err(ExportError::Invalid(format!(
                    "{}: a cluster of group {} indexes a vertex it does not have",
                    store.path().display(),
                    cluster.group
                )));
            };
            let points = [a, b, c];
            if region.is_some_and(|r| !points.iter().all(|&p| r.contains(p))) {
                emitted.outside += 1;
                continue;
            }
            for (&i, p) in corners.iter().zip(points) {
                if s.remap[i] == u32::MAX {
                    s.remap[i] = s.positions.len() as u32;
                    s.positions.push(p);
                }
                s.indices.push(s.remap[i]);
            }
        }
        if s.indices.is_empty() {
            continue;
        }
        announce(store, object, announced, sink)?;
        sink.mesh(&MeshChunk { object, positions: &s.positions, indices: &s.indices })?;
        emitted.triangles += (s.indices.len() / 3) as u64;
    }
    s.objects = objects;
    Ok(())
}

/// Announces `object` to the sink the first time it is met.
fn announce(
    store: &Store,
    object: u32,
    announced: &mut [bool],
    sink: &mut dyn TriangleSink,
) -> Result<(), ExportError> {
    let Some(seen) = announced.get_mut(object as usize) else {
        return Err(ExportError::Invalid(format!(
            "{}: a triangle of object {object}, but the object table has {}",
            store.path().display(),
            store.objects().len()
        )));
    };
    if !*seen {
        *seen = true;
        let o = &store.objects()[object as usize];
        sink.object(object, &ObjectInfo { name: o.name.clone(), color: o.color.map(Rgba8) })?;
    }
    Ok(())
}
