//! The decoded pages of a selection: what a renderer holds while it draws a frame (the
//! rasterizer in tw-gpu, the ray tracer in tw-rt), so that pages evicted meanwhile stay alive
//! until the frame is done.

use std::sync::Arc;

use tw_store::{PageCluster, Store};

use crate::{ClusterRef, PageCache, ResidentPage};

/// The decoded pages of a selection's clusters, held while the frame is drawn.
pub struct SelectionPages {
    pages: Vec<Arc<ResidentPage>>,
    refs: Vec<(ClusterRef, usize)>,
}

impl SelectionPages {
    /// Looks the pages of `clusters` up in `cache` (loading them if needed); clusters whose page
    /// fails are skipped and logged.
    pub fn resolve(store: &Store, cache: &PageCache, clusters: &[ClusterRef]) -> SelectionPages {
        let mut pages = Vec::new();
        let mut slot_of: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
        let mut refs = Vec::with_capacity(clusters.len());
        for r in clusters {
            let slot = match slot_of.get(&r.page) {
                Some(&s) => s,
                None => match cache.get(store, r.page) {
                    Ok(page) => {
                        pages.push(page);
                        slot_of.insert(r.page, pages.len() - 1);
                        pages.len() - 1
                    }
                    Err(e) => {
                        tracing::error!("cluster {r:?} skipped: {e}");
                        continue;
                    }
                },
            };
            refs.push((*r, slot));
        }
        SelectionPages { pages, refs }
    }

    /// The pages of `clusters` from `pages` (sorted by page, as a streamed frame holds them,
    /// [`crate::StreamFrame`]); clusters whose page is not there are skipped.
    pub fn from_resident(pages: &[(u32, Arc<ResidentPage>)], clusters: &[ClusterRef]) -> SelectionPages {
        let mut held: Vec<Arc<ResidentPage>> = Vec::new();
        let mut slot_of: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
        let mut refs = Vec::with_capacity(clusters.len());
        for r in clusters {
            let slot = match slot_of.get(&r.page) {
                Some(&s) => s,
                None => {
                    let Ok(i) = pages.binary_search_by_key(&r.page, |(p, _)| *p) else { continue };
                    held.push(pages[i].1.clone());
                    slot_of.insert(r.page, held.len() - 1);
                    held.len() - 1
                }
            };
            refs.push((*r, slot));
        }
        SelectionPages { pages: held, refs }
    }

    /// The clusters, in the selection's order (clusters beyond their page are skipped).
    pub fn clusters(&self) -> Vec<(ClusterRef, &PageCluster)> {
        self.refs
            .iter()
            .filter_map(|&(k, slot)| self.pages[slot].clusters.get(k.index_in_page as usize).map(|c| (k, c)))
            .collect()
    }

    /// The clusters with their pages, in the selection's order (clusters beyond their page are
    /// skipped): for caches keyed by the decoded page (the ray tracer's cluster BVHs).
    pub fn entries(&self) -> impl Iterator<Item = (ClusterRef, &Arc<ResidentPage>, &PageCluster)> {
        self.refs.iter().filter_map(|&(k, slot)| {
            let page = &self.pages[slot];
            page.clusters.get(k.index_in_page as usize).map(|c| (k, page, c))
        })
    }
}
