//! [`PageCache`]: decoded pages under a memory budget (docs/DESIGN.md, D4), LRU eviction, root
//! pages pinned.
//!
//! A page is decoded once ([`tw_store::Store::page`]: checksum, then every cluster) into a
//! [`ResidentPage`] shared as an `Arc`, so the selection, a renderer's upload and a future ray
//! tracer can hold it while the cache evicts it. Resident bytes are the decoded pages' heap
//! sizes. After each load, least recently used unpinned pages are evicted until the resident
//! bytes fit the budget again, never the page just loaded, so the cache exceeds its budget by
//! at most one page — or by the pinned root pages (docs/FORMAT.md: flag bit 0), which are never
//! evicted, when those alone exceed the budget. (Pages evicted while someone still holds their
//! `Arc` stay in memory until dropped; the budget counts what the cache holds.)
//!
//! Two ways to fill it: [`PageCache::get`] decodes on a miss on the caller's thread (the
//! blocking mode of the selection), and the loader threads of [`crate::stream::Streamer`]
//! decode off-thread and hand pages in with [`PageCache::insert`]. Every method takes `&self`
//! (one mutex inside, never held while decoding).
//!
//! **Frames and prefetch** (Manocha §5.5: prefetching must not disturb the current frame).
//! [`PageCache::begin_frame`] starts a frame: every page used or loaded after it is *in the
//! current frame*. A page inserted with [`Eviction::SparingThisFrame`] (a prefetched page) may
//! only evict pages not in the current frame; when those do not free enough room the prefetched
//! page is dropped instead ([`Inserted::Dropped`]), so prefetching never evicts what the frame
//! draws and never pushes the cache past its budget.
//!
//! A page that fails (checksum, decoding) is remembered: later `get`s return
//! [`RuntimeError::PageFailed`] at once instead of reading and logging it again every frame.

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex, MutexGuard};

use tw_store::{PageCluster, RtTree, Store, StoreError};

use crate::error::RuntimeError;

/// One decoded page: its clusters, each cluster's grid bounding box (for culling), and the
/// compact per-cluster data the selection reads ([`ClusterInfo`], [`ResidentPage::steps`]),
/// computed once when the page is decoded (on a loader thread), so that a frame's selection
/// never touches the clusters' vertex data and evaluates the LOD test once per step instead of
/// once per cluster.
#[derive(Debug)]
pub struct ResidentPage {
    pub clusters: Vec<PageCluster>,
    /// Inclusive grid box `(min, max)` of each cluster's vertices.
    pub bounds: Vec<([u32; 3], [u32; 3])>,
    /// Per cluster (same order as `clusters`).
    info: Vec<ClusterInfo>,
    /// The page's distinct `(self_error, self_sphere)` pairs (bit for bit), in order of first
    /// appearance: clusters made by the same simplification step share one.
    steps: Vec<(f32, [f32; 4])>,
    /// The clusters' stored ray-tracing trees (same order), or none.
    trees: Vec<RtTree>,
    bytes: usize,
}

/// What the selection needs of one cluster (12 bytes; [`ResidentPage::info`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClusterInfo {
    /// `PageCluster::group`.
    pub group: u32,
    /// Index of the cluster's `(self_error, self_sphere)` in [`ResidentPage::steps`].
    pub step: u32,
    /// `PageCluster::triangle_count`.
    pub triangles: u32,
}

impl ResidentPage {
    /// Wraps decoded clusters and computes their bounds.
    pub fn new(clusters: Vec<PageCluster>) -> ResidentPage {
        ResidentPage::with_trees(clusters, Vec::new())
    }

    /// [`ResidentPage::new`] with the clusters' ray-tracing trees (`Store::page_with_trees`;
    /// empty for a store without them).
    pub fn with_trees(clusters: Vec<PageCluster>, trees: Vec<RtTree>) -> ResidentPage {
        let bounds = clusters
            .iter()
            .map(|c| {
                let mut lo = [u32::MAX; 3];
                let mut hi = [0u32; 3];
                for p in &c.positions {
                    for a in 0..3 {
                        lo[a] = lo[a].min(p[a]);
                        hi[a] = hi[a].max(p[a]);
                    }
                }
                if c.positions.is_empty() {
                    lo = [0; 3];
                }
                (lo, hi)
            })
            .collect::<Vec<_>>();
        // Distinct steps by their bits, so that evaluating a step gives the same bits as
        // evaluating any of its clusters.
        let mut steps: Vec<(f32, [f32; 4])> = Vec::new();
        let mut index: HashMap<(u32, [u32; 4]), u32> = HashMap::new();
        let info = clusters
            .iter()
            .map(|c| {
                let key = (c.self_error.to_bits(), c.self_sphere.map(f32::to_bits));
                let step = *index.entry(key).or_insert_with(|| {
                    steps.push((c.self_error, c.self_sphere));
                    steps.len() as u32 - 1
                });
                ClusterInfo { group: c.group, step, triangles: c.triangle_count() as u32 }
            })
            .collect::<Vec<_>>();
        let bytes = std::mem::size_of::<ResidentPage>()
            + clusters.capacity() * std::mem::size_of::<PageCluster>()
            + bounds.capacity() * std::mem::size_of::<([u32; 3], [u32; 3])>()
            + info.capacity() * std::mem::size_of::<ClusterInfo>()
            + steps.capacity() * std::mem::size_of::<(f32, [f32; 4])>()
            + clusters
                .iter()
                .map(|c| c.positions.capacity() * 12 + c.indices.capacity() + c.objects.capacity() * 4)
                .sum::<usize>()
            + trees
                .iter()
                .map(|t| std::mem::size_of::<RtTree>() + t.order.capacity() + t.nodes.capacity())
                .sum::<usize>();
        ResidentPage { clusters, bounds, info, steps, trees, bytes }
    }

    /// The stored ray-tracing tree of cluster `index`, if the store has them.
    pub fn rt_tree(&self, index: u32) -> Option<&RtTree> {
        self.trees.get(index as usize)
    }

    /// Per cluster: its group, step and triangle count (same order as `clusters`).
    pub fn info(&self) -> &[ClusterInfo] {
        &self.info
    }

    /// The distinct `(self_error, self_sphere)` pairs of the page's clusters.
    pub fn steps(&self) -> &[(f32, [f32; 4])] {
        &self.steps
    }

    /// Heap bytes this page holds (what the cache budget counts).
    pub fn bytes(&self) -> usize {
        self.bytes
    }
}

/// Counters of a [`PageCache`] since it was made (resident figures are current).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// `get`/`try_get` calls that found the page resident.
    pub hits: u64,
    /// Pages loaded (read and decoded), including failed ones.
    pub misses: u64,
    /// Pages evicted.
    pub evictions: u64,
    /// Encoded bytes read from the store.
    pub bytes_read: u64,
    /// Decoded bytes resident now (pinned included).
    pub resident_bytes: u64,
    /// Of which in pinned (root) pages.
    pub pinned_bytes: u64,
    pub resident_pages: u64,
    /// Pages that failed to load.
    pub failed_pages: u64,
}

/// What the cache holds for a page ([`PageCache::state`]).
#[derive(Clone, Debug)]
pub enum PageState {
    Resident(Arc<ResidentPage>),
    /// Not loaded (yet).
    Missing,
    /// Failed to load (checksum, decoding), or no such page: never retried.
    Failed,
}

/// How a page handed to [`PageCache::insert`] makes room.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Eviction {
    /// Evict least recently used pages (never the new one) until within the budget.
    Lru,
    /// A prefetched page: evict only pages outside the current frame
    /// ([`PageCache::begin_frame`]); drop the new page if that is not enough.
    SparingThisFrame,
}

/// What [`PageCache::insert`] did with a page.
#[derive(Debug)]
pub enum Inserted {
    /// Now resident.
    Resident(Arc<ResidentPage>),
    /// Someone else loaded it first; this is the resident copy.
    AlreadyResident(Arc<ResidentPage>),
    /// Reading or decoding failed; the page is marked failed.
    Failed(StoreError),
    /// A prefetched page that did not fit without evicting the current frame's pages.
    Dropped,
    /// The page index is beyond the store's pages.
    NoSuchPage,
}

enum Slot {
    Empty,
    Resident { page: Arc<ResidentPage>, last_use: u64, pinned: bool },
    Failed(String),
}

struct Inner {
    /// Invariant: `stats.resident_bytes` / `resident_pages` / `pinned_bytes` are the sums over
    /// the `Resident` slots; every unpinned resident page is in `lru` exactly once, under its
    /// `last_use` tick, and no other page is.
    slots: Vec<Slot>,
    /// Unpinned resident pages by last use (tick → page): the first entry is evicted first.
    lru: BTreeMap<u64, u32>,
    tick: u64,
    /// Tick at the last [`PageCache::begin_frame`]: pages with `last_use > frame_start` are in
    /// the current frame.
    frame_start: u64,
    requests: HashMap<u32, f32>,
    stats: CacheStats,
}

/// Decoded pages of one store under a byte budget; see the module documentation.
pub struct PageCache {
    budget: u64,
    /// Root page flags, by page.
    pinned: Vec<bool>,
    /// Encoded length of each page.
    encoded: Vec<u32>,
    inner: Mutex<Inner>,
}

impl std::fmt::Debug for PageCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PageCache").field("budget", &self.budget).field("stats", &self.stats()).finish()
    }
}

impl PageCache {
    /// An empty cache for `store`'s pages with a budget of `budget_bytes` decoded bytes.
    pub fn new(store: &Store, budget_bytes: u64) -> PageCache {
        let pages = store.pages();
        PageCache {
            budget: budget_bytes,
            pinned: pages.iter().map(|p| p.is_root()).collect(),
            encoded: pages.iter().map(|p| p.compressed_len).collect(),
            inner: Mutex::new(Inner {
                slots: pages.iter().map(|_| Slot::Empty).collect(),
                lru: BTreeMap::new(),
                tick: 0,
                frame_start: 0,
                requests: HashMap::new(),
                stats: CacheStats::default(),
            }),
        }
    }

    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// Number of pages of the store this cache is for.
    pub fn page_count(&self) -> usize {
        self.pinned.len()
    }

    /// Whether `page` is a root page (pinned once loaded).
    pub fn is_pinned(&self, page: u32) -> bool {
        self.pinned.get(page as usize).copied().unwrap_or(false)
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic while holding the lock cannot leave the cache inconsistent in a way that
        // matters more than losing the frame; keep going with the data as it is.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Looks `page` up without loading; marks it used.
    fn lookup(inner: &mut Inner, page: u32) -> Option<Result<Arc<ResidentPage>, RuntimeError>> {
        inner.tick += 1;
        let tick = inner.tick;
        match inner.slots.get_mut(page as usize)? {
            Slot::Empty => None,
            Slot::Failed(msg) => Some(Err(RuntimeError::PageFailed { page, msg: msg.clone() })),
            Slot::Resident { page: p, last_use, pinned } => {
                let p = p.clone();
                let old = std::mem::replace(last_use, tick);
                if !*pinned {
                    inner.lru.remove(&old);
                    inner.lru.insert(tick, page);
                }
                inner.stats.hits += 1;
                Some(Ok(p))
            }
        }
    }

    /// The page if it is resident (marks it used; never loads). `None` for pages that are not
    /// resident, failed, or do not exist.
    pub fn try_get(&self, page: u32) -> Option<Arc<ResidentPage>> {
        Self::lookup(&mut self.lock(), page).and_then(Result::ok)
    }

    /// Whether `page` is resident (does not mark it used).
    pub fn contains(&self, page: u32) -> bool {
        matches!(self.lock().slots.get(page as usize), Some(Slot::Resident { .. }))
    }

    /// The page, loading it from `store` on a miss (then evicting down to the budget). Errors:
    /// the page's checksum or decoding failed now ([`RuntimeError::Page`]) or earlier
    /// ([`RuntimeError::PageFailed`]), or there is no such page.
    pub fn get(&self, store: &Store, page: u32) -> Result<Arc<ResidentPage>, RuntimeError> {
        if let Some(r) = Self::lookup(&mut self.lock(), page) {
            return r;
        }
        if page as usize >= self.pinned.len() {
            return Err(RuntimeError::PageFailed {
                page,
                msg: format!("no such page (the cache has {})", self.pinned.len()),
            });
        }
        // Decode without holding the lock, so that other threads keep using the cache.
        let loaded = store.page_with_trees(page).map(|(c, t)| Arc::new(ResidentPage::with_trees(c, t)));
        match self.insert(page, loaded, Eviction::Lru) {
            Inserted::Resident(p) | Inserted::AlreadyResident(p) => Ok(p),
            Inserted::Failed(e) => Err(e.into()),
            // Not produced by `Eviction::Lru`; kept total for the match.
            Inserted::Dropped | Inserted::NoSuchPage => {
                Err(RuntimeError::PageFailed { page, msg: "not kept by the cache".into() })
            }
        }
    }

    /// Hands in the result of reading and decoding `page` (what [`get`](Self::get) does after a
    /// miss; loader threads call it): counts the read, remembers a failure, or makes the page
    /// resident and evicts as `eviction` says (see the module documentation).
    pub fn insert(
        &self,
        page: u32,
        loaded: Result<Arc<ResidentPage>, StoreError>,
        eviction: Eviction,
    ) -> Inserted {
        let Some(&encoded) = self.encoded.get(page as usize) else {
            return Inserted::NoSuchPage;
        };
        let mut inner = self.lock();
        inner.stats.misses += 1;
        inner.stats.bytes_read += encoded as u64;
        inner.requests.remove(&page);
        let loaded = match loaded {
            Ok(p) => p,
            Err(e) => {
                if matches!(inner.slots[page as usize], Slot::Empty) {
                    inner.slots[page as usize] = Slot::Failed(e.to_string());
                    inner.stats.failed_pages += 1;
                }
                return Inserted::Failed(e);
            }
        };
        // Another thread may have loaded it meanwhile: keep the resident copy.
        if let Slot::Resident { page: p, .. } = &inner.slots[page as usize] {
            return Inserted::AlreadyResident(p.clone());
        }
        let pinned = self.pinned[page as usize];
        let bytes = loaded.bytes() as u64;
        if eviction == Eviction::SparingThisFrame && !pinned && !self.room_sparing_frame(&inner, bytes) {
            return Inserted::Dropped;
        }
        inner.tick += 1;
        let tick = inner.tick;
        inner.slots[page as usize] = Slot::Resident { page: loaded.clone(), last_use: tick, pinned };
        inner.stats.resident_bytes += bytes;
        inner.stats.resident_pages += 1;
        if pinned {
            inner.stats.pinned_bytes += bytes;
        } else {
            inner.lru.insert(tick, page);
        }
        self.evict(&mut inner, page);
        Inserted::Resident(loaded)
    }

    /// Whether evicting only pages outside the current frame (oldest first) makes room for
    /// `bytes` more within the budget.
    fn room_sparing_frame(&self, inner: &Inner, bytes: u64) -> bool {
        let mut need = (inner.stats.resident_bytes + bytes).saturating_sub(self.budget);
        for (&tick, &p) in &inner.lru {
            if need == 0 || tick > inner.frame_start {
                break;
            }
            if let Some(Slot::Resident { page, .. }) = inner.slots.get(p as usize) {
                need = need.saturating_sub(page.bytes() as u64);
            }
        }
        need == 0
    }

    /// Whether a prefetched page of about `bytes` decoded bytes would fit without evicting the
    /// current frame's pages (a loader checks this before reading a prefetched page).
    pub fn prefetch_fits(&self, bytes: u64) -> bool {
        self.room_sparing_frame(&self.lock(), bytes)
    }

    /// Decoded bytes the current frame holds resident: the pages used or loaded since
    /// [`begin_frame`](Self::begin_frame) and the pinned root pages (what a streamed cut needs
    /// of the budget, `crate::fit`).
    pub fn frame_bytes(&self) -> u64 {
        let inner = self.lock();
        let used: u64 = inner
            .lru
            .range(inner.frame_start + 1..)
            .filter_map(|(_, &p)| match inner.slots.get(p as usize) {
                Some(Slot::Resident { page, .. }) => Some(page.bytes() as u64),
                _ => None,
            })
            .sum();
        used + inner.stats.pinned_bytes
    }

    /// Starts a frame: pages used or loaded from now on are in the current frame, which
    /// prefetched pages may not evict ([`Eviction::SparingThisFrame`]).
    pub fn begin_frame(&self) {
        let mut inner = self.lock();
        inner.frame_start = inner.tick;
    }

    /// What the cache holds for `page` now; marks a resident page used (like
    /// [`try_get`](Self::try_get)). Pages that do not exist are [`PageState::Failed`].
    pub fn state(&self, page: u32) -> PageState {
        match Self::lookup(&mut self.lock(), page) {
            Some(Ok(p)) => PageState::Resident(p),
            Some(Err(_)) => PageState::Failed,
            None if (page as usize) < self.pinned.len() => PageState::Missing,
            None => PageState::Failed,
        }
    }

    /// Like [`state`](Self::state) but without marking the page used (prefetch views look at
    /// pages without making them recently used).
    pub fn peek_state(&self, page: u32) -> PageState {
        match self.lock().slots.get(page as usize) {
            Some(Slot::Resident { page, .. }) => PageState::Resident(page.clone()),
            Some(Slot::Empty) => PageState::Missing,
            Some(Slot::Failed(_)) | None => PageState::Failed,
        }
    }

    /// Whether `page` is resident or has failed (nothing left to load), or does not exist.
    pub fn is_settled(&self, page: u32) -> bool {
        !matches!(self.lock().slots.get(page as usize), Some(Slot::Empty))
    }

    /// Keeps the items of `items` whose page (`page_of`) is not settled
    /// ([`is_settled`](Self::is_settled)), in order, under one lock (the frame's request
    /// lists, without a lock per page that the loaders would contend for).
    pub fn retain_unsettled<T>(&self, items: &mut Vec<T>, page_of: impl Fn(&T) -> u32) {
        let inner = self.lock();
        items.retain(|t| matches!(inner.slots.get(page_of(t) as usize), Some(Slot::Empty)));
    }

    /// Evicts least recently used unpinned pages, except `keep`, until within the budget.
    fn evict(&self, inner: &mut Inner, keep: u32) {
        while inner.stats.resident_bytes > self.budget {
            let victim = inner.lru.iter().map(|(&t, &p)| (t, p)).find(|&(_, p)| p != keep);
            let Some((tick, victim)) = victim else { break };
            inner.lru.remove(&tick);
            if let Slot::Resident { page, .. } =
                std::mem::replace(&mut inner.slots[victim as usize], Slot::Empty)
            {
                inner.stats.resident_bytes -= page.bytes() as u64;
                inner.stats.resident_pages -= 1;
                inner.stats.evictions += 1;
            }
        }
    }

    /// Loads every root page (they stay resident). Returns how many failed; each failure is
    /// logged.
    pub fn load_root_pages(&self, store: &Store) -> usize {
        let mut failed = 0;
        for (i, _) in self.pinned.iter().enumerate().filter(|(_, &p)| p) {
            if let Err(e) = self.get(store, i as u32) {
                tracing::error!("root page {i}: {e}");
                failed += 1;
            }
        }
        failed
    }

    /// Asks for `page` to be loaded with `priority` (larger first; e.g. the pixel error it
    /// would remove). Repeated requests keep the highest priority. Resident, failed or unknown
    /// pages are ignored.
    pub fn request(&self, page: u32, priority: f32) {
        let mut inner = self.lock();
        if !matches!(inner.slots.get(page as usize), Some(Slot::Empty)) {
            return;
        }
        let p = inner.requests.entry(page).or_insert(priority);
        if priority > *p {
            *p = priority;
        }
    }

    /// Removes and returns up to `max` requested pages, highest priority first (ties: lower
    /// page first), for a loader to `get`.
    pub fn take_requests(&self, max: usize) -> Vec<(u32, f32)> {
        let mut inner = self.lock();
        let mut all: Vec<(u32, f32)> = inner.requests.iter().map(|(&p, &q)| (p, q)).collect();
        all.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        all.truncate(max);
        for (p, _) in &all {
            inner.requests.remove(p);
        }
        all
    }

    /// Pages waiting in the request queue.
    pub fn pending_requests(&self) -> usize {
        self.lock().requests.len()
    }

    pub fn stats(&self) -> CacheStats {
        self.lock().stats
    }

    /// The pages that failed to load (checksum, decoding), ascending, each with its error: a
    /// store's damage as far as this cache met it, for the commands' summaries and reports.
    pub fn failed_pages(&self) -> Vec<(u32, String)> {
        let inner = self.lock();
        let failed = inner.slots.iter().enumerate().filter_map(|(i, slot)| match slot {
            Slot::Failed(e) => Some((i as u32, e.clone())),
            _ => None,
        });
        failed.collect()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use tw_store::{Group, Node, Object, StoreInfo, StoreWriter};

    /// A store of `pages` pages, page `i` holding one group (on the root node) of `i + 1`
    /// one-triangle clusters; the pages listed in `roots` are root pages.
    pub(crate) fn store_with_pages(dir: &std::path::Path, pages: u32, roots: &[u32]) -> Store {
        let path = dir.join("pages.tw");
        let mut w = StoreWriter::create(&path).unwrap();
        let mut groups = Vec::new();
        for i in 0..pages {
            let clusters: Vec<PageCluster> = (0..=i)
                .map(|k| PageCluster {
                    positions: vec![[k, 0, 0], [k + 1, 0, 0], [k, 1, i]],
                    indices: vec![0, 1, 2],
                    objects: vec![0],
                    self_error: 0.0,
                    self_sphere: [0.0, 0.0, 0.0, 0.0],
                    group: i,
                    level: 0,
                })
                .collect();
            let page = w.add_page(&clusters, roots.contains(&i)).unwrap();
            groups.push(Group {
                sphere: [0.0, 0.0, 0.0, 1e3],
                error: f32::INFINITY,
                page,
                cluster_count: i + 1,
                triangles: i + 1,
                ..Default::default()
            });
        }
        let info = StoreInfo {
            bounds_min: [0.0; 3],
            bounds_max: [100.0; 3],
            grid_origin: [0.0; 3],
            grid_step: 1.0,
            units: String::new(),
            up_axis: 2,
            build_options: String::new(),
            input_triangles: groups.iter().map(|g| g.triangles as u64).sum(),
        };
        let objects = [Object { name: "o".into(), color: None, triangles: info.input_triangles }];
        let nodes = [Node {
            min: [0; 3],
            max: [100; 3],
            group_count: pages,
            max_error: f32::INFINITY,
            ..Default::default()
        }];
        w.finish(&info, &objects, &nodes, &groups, &[]).unwrap();
        Store::open(&path).unwrap()
    }

    #[test]
    fn hit_after_miss_and_bounds_are_computed() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_pages(dir.path(), 3, &[]);
        let cache = PageCache::new(&store, 1 << 20);
        assert!(cache.try_get(2).is_none());
        let p = cache.get(&store, 2).unwrap();
        assert_eq!(p.clusters.len(), 3);
        assert_eq!(p.bounds[1], ([1, 0, 0], [2, 1, 2]));
        let q = cache.get(&store, 2).unwrap();
        assert!(Arc::ptr_eq(&p, &q));
        assert!(cache.try_get(2).is_some());
        let s = cache.stats();
        assert_eq!((s.hits, s.misses, s.evictions, s.resident_pages), (2, 1, 0, 1));
        assert_eq!(s.bytes_read, store.pages()[2].compressed_len as u64);
        assert_eq!(s.resident_bytes, p.bytes() as u64);
    }

    #[test]
    fn least_recently_used_page_is_evicted_first() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_pages(dir.path(), 4, &[]);
        let size = |p| ResidentPage::new(store.page(p).unwrap()).bytes() as u64;
        // One byte short of all four pages.
        let cache = PageCache::new(&store, (0..4).map(size).sum::<u64>() - 1);
        for p in [0, 1, 2, 0] {
            cache.get(&store, p).unwrap();
        }
        assert_eq!(cache.stats().evictions, 0);
        // Page 1 is the least recently used (0 was used again after 2).
        cache.get(&store, 3).unwrap();
        assert!(cache.contains(0) && !cache.contains(1) && cache.contains(2) && cache.contains(3));
        let s = cache.stats();
        assert_eq!((s.evictions, s.resident_pages), (1, 3));
        assert_eq!(s.resident_bytes, size(0) + size(2) + size(3));
        assert!(s.resident_bytes <= cache.budget());
    }

    #[test]
    fn a_budget_smaller_than_one_page_keeps_only_the_last_page() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_pages(dir.path(), 3, &[]);
        let cache = PageCache::new(&store, 10);
        for p in [0, 1, 2] {
            cache.get(&store, p).unwrap();
            assert!(cache.contains(p));
            assert_eq!(cache.stats().resident_pages, 1);
        }
    }

    #[test]
    fn pinned_root_pages_are_never_evicted() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_pages(dir.path(), 6, &[0, 5]);
        let cache = PageCache::new(&store, 1);
        assert_eq!(cache.load_root_pages(&store), 0);
        assert!(cache.contains(0) && cache.contains(5));
        for p in [1, 2, 3, 4, 1, 2] {
            cache.get(&store, p).unwrap();
            assert!(cache.contains(0) && cache.contains(5), "after page {p}");
            assert!(cache.contains(p), "the page just loaded stays");
        }
        let s = cache.stats();
        assert_eq!(s.resident_pages, 3, "two pinned and the last one");
        assert!(s.pinned_bytes > 0 && s.evictions == 5, "each load after the first evicts one: {s:?}");
    }

    #[test]
    fn corrupt_page_is_an_error_once_then_remembered() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_pages(dir.path(), 2, &[]);
        let path = store.path().to_path_buf();
        let offset = store.pages()[1].offset as usize + 5;
        drop(store);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[offset] ^= 0x40;
        let store = Store::from_bytes(bytes).unwrap();
        let cache = PageCache::new(&store, 1 << 20);
        let e = cache.get(&store, 1).unwrap_err();
        assert!(matches!(e, RuntimeError::Page(_)), "{e}");
        assert!(e.to_string().contains("page 1"), "{e}");
        let e = cache.get(&store, 1).unwrap_err();
        assert!(matches!(e, RuntimeError::PageFailed { page: 1, .. }), "{e}");
        assert!(cache.try_get(1).is_none());
        assert!(cache.get(&store, 0).is_ok(), "other pages still load");
        let s = cache.stats();
        assert_eq!((s.misses, s.failed_pages, s.resident_pages), (2, 1, 1));
    }

    #[test]
    fn missing_page_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_pages(dir.path(), 1, &[]);
        let cache = PageCache::new(&store, 1 << 20);
        assert!(cache.get(&store, 7).is_err());
        assert!(cache.try_get(7).is_none());
    }

    #[test]
    fn requests_come_out_by_priority_and_skip_resident_pages() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_pages(dir.path(), 5, &[]);
        let cache = PageCache::new(&store, 1 << 20);
        cache.get(&store, 4).unwrap();
        cache.request(1, 2.0);
        cache.request(2, 9.0);
        cache.request(3, 2.0);
        cache.request(1, 5.0);
        cache.request(4, 100.0);
        cache.request(99, 100.0);
        assert_eq!(cache.pending_requests(), 3);
        assert_eq!(cache.take_requests(2), vec![(2, 9.0), (1, 5.0)]);
        cache.get(&store, 3).unwrap();
        assert_eq!(cache.take_requests(10), vec![], "loading a page drops its request");
    }

    #[test]
    fn prefetched_pages_never_evict_the_current_frame() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_pages(dir.path(), 4, &[]);
        let load = |p: u32| store.page(p).map(|c| Arc::new(ResidentPage::new(c)));
        let size = |p| ResidentPage::new(store.page(p).unwrap()).bytes() as u64;
        // Room for pages 2 and 3 (the largest two).
        let cache = PageCache::new(&store, size(2) + size(3));
        cache.get(&store, 0).unwrap();
        cache.begin_frame();
        cache.get(&store, 2).unwrap();
        // A prefetched page 3 may evict page 0 (not in this frame), and does.
        assert!(matches!(cache.insert(3, load(3), Eviction::SparingThisFrame), Inserted::Resident(_)));
        assert!(!cache.contains(0) && cache.contains(2) && cache.contains(3));
        // Next frame uses 2 and 3: a prefetched page 1 finds no room outside the frame.
        cache.begin_frame();
        cache.try_get(2);
        cache.try_get(3);
        assert!(matches!(cache.insert(1, load(1), Eviction::SparingThisFrame), Inserted::Dropped));
        assert!(cache.contains(2) && cache.contains(3) && !cache.contains(1));
        assert!(cache.stats().resident_bytes <= cache.budget(), "prefetch never exceeds the budget");
        // A frame page (LRU) may still evict the current frame's pages, oldest first.
        assert!(matches!(cache.insert(1, load(1), Eviction::Lru), Inserted::Resident(_)));
        assert!(cache.contains(1) && !cache.contains(2) && cache.contains(3));
    }
}
