//! Streaming pages by priority (docs/DESIGN.md, D4; Manocha, "Interactive display of complex
//! environments", §5.5 "Parallel rendering & I/O management"): the frame selects from what is
//! resident and never waits, loader threads read and decode what it asked for, highest
//! priority first, and then what the next frames will need (prefetch, [`crate::prefetch`]).
//!
//! One frame ([`Streamer::frame`]):
//!
//! 1. [`PageCache::begin_frame`] and a new residency snapshot ([`Availability::begin`]);
//! 2. the cut by the availability rule ([`Selector::select_available`]): it draws the best
//!    available ancestors where pages are missing and collects the missing pages with their
//!    priority (the pixel error they would remove);
//! 3. when the frame asks for few pages (the loaders are idle enough), the prefetch views'
//!    missing pages are added, minus the frame's own. The views are selected every
//!    [`PrefetchOptions::every`] frames; with loader threads on a thread of their own (over
//!    their own peek-only residency snapshot; the frame submits the last list that thread
//!    finished, less what arrived), else on the frame thread over the frame's snapshot;
//! 4. both lists *replace* the loaders' queues ([`Streamer::submit`]): stale requests of
//!    earlier frames are dropped; pages resident, failed or being loaded are left out, so a
//!    page is never loaded twice at once;
//! 5. per-frame statistics ([`StreamStats`]), and the fit of τ to the cache ([`crate::fit`]):
//!    when the pages the cut draws from and asks for would not fit the budget, the next frames
//!    select at a raised τ (the frame's light views at the same one), back down when there is
//!    room.
//!
//! Loader threads (default 2) take the highest-priority page of the frame's queue, else of the
//! prefetch queue, read and decode it without any lock held, and hand it to the cache:
//! frame pages evict LRU ([`Eviction::Lru`]); prefetched pages may evict only pages outside the
//! current frame ([`Eviction::SparingThisFrame`]) and are dropped when that is not enough. A
//! page that fails (checksum, decoding) is logged once, marked failed in the cache and never
//! requested again; its groups fall back to their ancestors. Dropping the [`Streamer`] stops
//! and joins the threads (a load in progress is finished first).
//!
//! **The light's view** ([`Streamer::select_light`]): after [`Streamer::frame`], the shadow-map
//! layers' selections (the eye's LOD cut culled by each layer's frustum, [`Selector::select_light`])
//! run over the *same* residency snapshot, so the eye and the light draw from one resident set.
//! Their missing pages join the frame's own requests (merged, highest priority kept) and the
//! loaders' queues are replaced by the union: a frame never waits for the light's pages either.
//!
//! With `loader_threads = 0` nothing loads in the background: the caller loads with
//! [`Streamer::load_queued`] (deterministic tests, or a single-threaded program).

use std::collections::HashSet;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tw_store::Store;

use crate::availability::{Availability, Requests};
use crate::cache::{CacheStats, Eviction, Inserted, PageCache, ResidentPage};
use crate::camera::Camera;
use crate::error::RuntimeError;
use crate::fit::CacheFit;
use crate::prefetch::{prefetch_views, CameraHistory, PrefetchOptions};
use crate::select::{ClusterRef, SelectOptions, Selection, Selector};

/// How a [`Streamer`] loads.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StreamOptions {
    /// Decoded bytes the cache may hold (root pages are kept beyond it).
    pub budget_bytes: u64,
    /// Background loader threads; 0: only [`Streamer::load_queued`] loads.
    pub loader_threads: usize,
    pub prefetch: PrefetchOptions,
    /// Raise τ while the cut's pages would not fit the budget ([`crate::fit`]; on by default,
    /// `--fit-memory off` turns it off).
    #[serde(default = "fit_by_default")]
    pub fit_budget: bool,
}

fn fit_by_default() -> bool {
    true
}

impl Default for StreamOptions {
    fn default() -> Self {
        StreamOptions {
            budget_bytes: 512 << 20,
            loader_threads: 2,
            prefetch: PrefetchOptions::default(),
            fit_budget: true,
        }
    }
}

/// What streaming did in one frame (counts since the previous frame; resident figures now).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StreamStats {
    /// Frame number, from 0.
    pub frame: u64,
    /// Pages this frame's cut asked for (missing, not failed).
    pub pages_requested: u64,
    /// Pages the prefetch views asked for beyond those.
    pub prefetch_requested: u64,
    /// Pages loaded since the previous frame (frame and prefetch pages, failures excluded).
    pub pages_loaded: u64,
    /// Of which prefetched.
    pub prefetch_loaded: u64,
    /// Prefetched pages dropped since the previous frame (no room without evicting the frame's
    /// pages; most are dropped before they are read).
    pub prefetch_dropped: u64,
    pub pages_evicted: u64,
    /// Encoded bytes read from the store since the previous frame.
    pub bytes_read: u64,
    pub resident_bytes: u64,
    pub resident_pages: u64,
    /// Of the resident bytes, those of the pinned root pages.
    pub pinned_bytes: u64,
    /// Groups that wanted finer data but drew an ancestor (page not loaded yet).
    pub stalls_avoided: u64,
    /// Simplified clusters drawn in place of missing finer ones.
    pub clusters_fallback: u64,
    /// Groups whose page failed (their ancestors drawn).
    pub groups_failed: u64,
    /// Pages waiting in the loaders' queues after this frame's requests (frame + prefetch).
    pub pending: u64,
    /// Pages being read or decoded when the frame was submitted.
    pub in_flight: u64,
    /// Pages that failed to load so far (total).
    pub failed_pages: u64,
    pub clusters: u64,
    pub triangles: u64,
    /// The factor this frame's τ was raised by to fit the cache ([`crate::fit`]; 1: the
    /// asked-for τ; 0 in frames that were not streamed).
    #[serde(default)]
    pub tau_scale: f32,
    /// Decoded bytes the cut needs resident: the pages the frame used (drawn from or looked up
    /// on the way down), the pinned root pages and the pages it asked for (what the fit compares
    /// with the budget).
    #[serde(default)]
    pub cut_bytes: u64,
}

/// One streamed frame: the cut, the pages it draws (held, so eviction cannot take them away
/// before they are drawn), and the statistics.
#[derive(Debug, Default)]
pub struct StreamFrame {
    pub selection: Selection,
    /// Time of the frame's cut selection and of the prefetch views' selections.
    pub times: StreamTimes,
    /// The pages of the selection's clusters, sorted by page index.
    pub pages: Vec<(u32, Arc<ResidentPage>)>,
    pub stats: StreamStats,
}

/// Where a streamed frame's selection time went.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StreamTimes {
    /// The residency snapshot and the frame's own cut (the traversal from the root).
    pub cut: std::time::Duration,
    /// The prefetch views' traversals (wider field of view at τ/2, the extrapolated camera).
    pub prefetch: std::time::Duration,
}

impl StreamFrame {
    /// The resident page `page` of this frame, if the selection draws from it.
    pub fn page(&self, page: u32) -> Option<&Arc<ResidentPage>> {
        self.pages.binary_search_by_key(&page, |(p, _)| *p).ok().map(|i| &self.pages[i].1)
    }
}

/// The loaders' queues. Invariants: `demand` and `prefetch` are sorted by ascending priority
/// (the next page is the last), hold no page twice and no page of `in_flight`; `in_flight`
/// holds the pages a loader is reading or decoding now.
#[derive(Debug, Default)]
struct Queue {
    demand: Vec<(u32, f32)>,
    prefetch: Vec<(u32, f32)>,
    in_flight: HashSet<u32>,
    paused: bool,
    shutdown: bool,
    prefetch_loaded: u64,
    prefetch_dropped: u64,
}

#[derive(Debug, Default)]
struct Shared {
    queue: Mutex<Queue>,
    /// Signalled when there is work (or shutdown, or unpause).
    work: Condvar,
    /// Signalled when a load finishes.
    done: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A page taken from the queues.
struct Job {
    page: u32,
    prefetch: bool,
}

/// Takes the next page to load (frame pages first), marking it in flight; skips pages that
/// became resident or failed meanwhile, and prefetched pages that cannot fit without evicting
/// the current frame's pages (estimated from the page table's decoded size; counted as
/// dropped, without reading them).
fn take(q: &mut Queue, store: &Store, cache: &PageCache) -> Option<Job> {
    loop {
        let (page, prefetch) = if let Some((p, _)) = q.demand.pop() {
            (p, false)
        } else if let Some((p, _)) = q.prefetch.pop() {
            (p, true)
        } else {
            return None;
        };
        if q.in_flight.contains(&page) || cache.is_settled(page) {
            continue;
        }
        if prefetch {
            let estimate = store.pages().get(page as usize).map_or(0, |p| p.uncompressed_len as u64);
            if !cache.prefetch_fits(estimate) {
                q.prefetch_dropped += 1;
                continue;
            }
        }
        q.in_flight.insert(page);
        return Some(Job { page, prefetch });
    }
}

/// Reads, decodes and hands in one page (no lock held while decoding).
fn load(store: &Store, cache: &PageCache, shared: &Shared, job: Job) {
    let loaded = store.page_with_trees(job.page).map(|(c, t)| Arc::new(ResidentPage::with_trees(c, t)));
    let eviction = if job.prefetch { Eviction::SparingThisFrame } else { Eviction::Lru };
    let outcome = cache.insert(job.page, loaded, eviction);
    if let Inserted::Failed(e) = &outcome {
        tracing::error!(
            "page {} failed to load while streaming; its groups fall back to coarser ones: {e}",
            job.page
        );
    }
    let mut q = shared.lock();
    q.in_flight.remove(&job.page);
    match outcome {
        Inserted::Resident(_) if job.prefetch => q.prefetch_loaded += 1,
        Inserted::Dropped => q.prefetch_dropped += 1,
        _ => {}
    }
    drop(q);
    shared.done.notify_all();
}

fn loader_loop(store: Arc<Store>, cache: Arc<PageCache>, shared: Arc<Shared>) {
    loop {
        let job = {
            let mut q = shared.lock();
            loop {
                if q.shutdown {
                    return;
                }
                if !q.paused {
                    if let Some(job) = take(&mut q, &store, &cache) {
                        break job;
                    }
                }
                // Nothing to do: wake `wait_idle` callers (stale pages may have been skipped).
                shared.done.notify_all();
                q = shared.work.wait(q).unwrap_or_else(|e| e.into_inner());
            }
        };
        load(&store, &cache, &shared, job);
    }
}

/// Streams a store's pages for a walkthrough; see the module documentation.
pub struct Streamer {
    store: Arc<Store>,
    cache: Arc<PageCache>,
    selector: Arc<Selector>,
    options: StreamOptions,
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    availability: Availability,
    history: CameraHistory,
    frame: u64,
    /// Cache counters at the previous frame, for the per-frame deltas.
    last_cache: CacheStats,
    last_prefetch: (u64, u64),
    scratch: Selection,
    /// The last prefetch views' requests and the frame they were selected in (`None`: not
    /// since the last reset). With a [`PrefetchWorker`], the frame the last job was sent in.
    prefetch_list: (Requests, Option<u64>),
    /// Selects the prefetch views off the frame thread (with loader threads only).
    prefetch_worker: Option<PrefetchWorker>,
    /// Incremented by [`Streamer::reset_history`]: results of older prefetch jobs are dropped.
    generation: u64,
    /// The demand and prefetch requests last submitted by [`Streamer::frame`], to which the
    /// light views of the same frame add theirs ([`Streamer::select_light`]).
    submitted: (Requests, Requests),
    /// Whether `availability` holds a frame's snapshot (a [`Streamer::frame`] began one).
    snapshot_taken: bool,
    /// The scale of τ that keeps the cut within the budget, and the one the last frame used
    /// (its light views use the same).
    fit: CacheFit,
    frame_scale: f32,
}

/// The prefetch views' selection on a thread of its own (module documentation, step 3): the
/// frame thread sends the views every `every` frames when the worker is idle, and submits the
/// last list the worker finished. The worker has its own residency snapshot, looked up without
/// marking pages used (like the synchronous prefetch views), and releases it after each job.
struct PrefetchWorker {
    jobs: Option<std::sync::mpsc::Sender<PrefetchJob>>,
    results: std::sync::mpsc::Receiver<(u64, Requests)>,
    busy: bool,
    thread: Option<JoinHandle<()>>,
}

struct PrefetchJob {
    generation: u64,
    views: Vec<(Camera, SelectOptions)>,
}

/// The requests of `list` that the frame's `demand` does not hold and whose pages are neither
/// resident nor failed in `cache`: what is left of an earlier prefetch list.
fn unsettled_requests(list: &Requests, demand: &Requests, cache: &PageCache) -> Vec<(u32, f32)> {
    let mut left: Vec<(u32, f32)> =
        list.0.iter().map(|(&p, &q)| (p, q)).filter(|(p, _)| !demand.0.contains_key(p)).collect();
    cache.retain_unsettled(&mut left, |&(p, _)| p);
    left
}

fn prefetch_loop(
    store: Arc<Store>,
    cache: Arc<PageCache>,
    selector: Arc<Selector>,
    jobs: std::sync::mpsc::Receiver<PrefetchJob>,
    results: std::sync::mpsc::Sender<(u64, Requests)>,
) {
    let mut availability = Availability::default();
    let mut scratch = Selection::default();
    while let Ok(job) = jobs.recv() {
        availability.begin(&store);
        availability.set_peek_only(true);
        let mut requests = Requests::default();
        for (camera, options) in &job.views {
            selector.select_available(
                &store,
                &cache,
                &mut availability,
                &mut requests,
                camera,
                options,
                &mut scratch,
            );
        }
        // Release the snapshot's pages now rather than at the next job.
        availability.begin(&store);
        if results.send((job.generation, requests)).is_err() {
            return;
        }
    }
}

impl std::fmt::Debug for Streamer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Streamer")
            .field("options", &self.options)
            .field("threads", &self.threads.len())
            .field("cache", &self.cache)
            .finish()
    }
}

impl Streamer {
    /// A streamer over `store`: loads the root pages now (they stay resident; failures are
    /// logged) and starts `options.loader_threads` loader threads.
    pub fn new(store: Arc<Store>, options: StreamOptions) -> Result<Streamer, RuntimeError> {
        let cache = Arc::new(PageCache::new(&store, options.budget_bytes));
        cache.load_root_pages(&store);
        let shared = Arc::new(Shared::default());
        let mut threads = Vec::with_capacity(options.loader_threads);
        for i in 0..options.loader_threads {
            let (s, c, q) = (store.clone(), cache.clone(), shared.clone());
            let spawned = std::thread::Builder::new()
                .name(format!("tw-loader-{i}"))
                .spawn(move || loader_loop(s, c, q));
            match spawned {
                Ok(h) => threads.push(h),
                Err(e) => {
                    let mut streamer = Streamer::assemble(store, cache, shared, threads, options);
                    streamer.stop();
                    return Err(RuntimeError::Loader(format!("cannot start loader thread {i}: {e}")));
                }
            }
        }
        let mut streamer = Streamer::assemble(store, cache, shared, threads, options);
        if options.loader_threads > 0 {
            let (jobs, job_rx) = std::sync::mpsc::channel();
            let (result_tx, results) = std::sync::mpsc::channel();
            let (s, c, sel) = (streamer.store.clone(), streamer.cache.clone(), streamer.selector.clone());
            let spawned = std::thread::Builder::new()
                .name("tw-prefetch".into())
                .spawn(move || prefetch_loop(s, c, sel, job_rx, result_tx));
            match spawned {
                Ok(h) => {
                    streamer.prefetch_worker =
                        Some(PrefetchWorker { jobs: Some(jobs), results, busy: false, thread: Some(h) })
                }
                // Not fatal: the views are selected on the frame thread instead.
                Err(e) => {
                    tracing::warn!("cannot start the prefetch thread ({e}); prefetching on the frame thread")
                }
            }
        }
        Ok(streamer)
    }

    fn assemble(
        store: Arc<Store>,
        cache: Arc<PageCache>,
        shared: Arc<Shared>,
        threads: Vec<JoinHandle<()>>,
        options: StreamOptions,
    ) -> Streamer {
        let last_cache = cache.stats();
        Streamer {
            selector: Arc::new(Selector::new(&store)),
            store,
            cache,
            options,
            shared,
            threads,
            availability: Availability::default(),
            history: CameraHistory::default(),
            frame: 0,
            last_cache,
            last_prefetch: (0, 0),
            scratch: Selection::default(),
            prefetch_list: Default::default(),
            prefetch_worker: None,
            generation: 0,
            submitted: Default::default(),
            snapshot_taken: false,
            fit: CacheFit::default(),
            frame_scale: 1.0,
        }
    }

    pub fn store(&self) -> &Arc<Store> {
        &self.store
    }

    /// The page cache (shared with the loader threads).
    pub fn cache(&self) -> &Arc<PageCache> {
        &self.cache
    }

    pub fn selector(&self) -> &Selector {
        &self.selector
    }

    pub fn options(&self) -> &StreamOptions {
        &self.options
    }

    /// Turns prefetching on or off (and its other settings) from the next frame on.
    pub fn set_prefetch(&mut self, prefetch: PrefetchOptions) {
        self.options.prefetch = prefetch;
    }

    /// Forgets the camera history (no extrapolation across a teleport).
    pub fn reset_history(&mut self) {
        self.history.clear();
        self.prefetch_list = Default::default();
        self.generation += 1;
    }

    /// One frame: select without waiting, request, prefetch, statistics (module documentation).
    pub fn frame(&mut self, camera: &Camera, options: &SelectOptions) -> StreamFrame {
        let start = std::time::Instant::now();
        self.frame_scale = self.tau_scale();
        let options = &self.fitted(options);
        self.cache.begin_frame();
        self.availability.begin(&self.store);
        self.snapshot_taken = true;
        let (store, cache) = (&*self.store, &*self.cache);
        let mut demand = Requests::default();
        let mut selection = Selection::default();
        self.selector.select_available(
            store,
            cache,
            &mut self.availability,
            &mut demand,
            camera,
            options,
            &mut selection,
        );
        let cut = start.elapsed();
        let mut prefetch = Requests::default();
        let every = self.options.prefetch.every.max(1) as u64;
        // Selected every `every` frames, whether or not the last selection found pages to
        // request (an empty list used to count as stale, so with every page of the views
        // resident — the common case once the cache is warm — the views were selected every
        // frame).
        let fresh = self.prefetch_list.1.is_none_or(|f| self.frame >= f + every);
        let wanted = self.options.prefetch.enabled && demand.len() <= self.options.prefetch.idle_below;
        let prefetch_options = self.prefetch_options();
        if let Some(worker) = &mut self.prefetch_worker {
            while let Ok((generation, list)) = worker.results.try_recv() {
                worker.busy = false;
                if generation == self.generation {
                    self.prefetch_list.0 = list;
                }
            }
            if wanted && fresh && !worker.busy {
                let views = prefetch_views(camera, &self.history, options, &prefetch_options);
                let job = PrefetchJob { generation: self.generation, views };
                if worker.jobs.as_ref().is_some_and(|j| j.send(job).is_ok()) {
                    worker.busy = true;
                    self.prefetch_list.1 = Some(self.frame);
                }
            }
            if wanted {
                prefetch.0.extend(unsettled_requests(&self.prefetch_list.0, &demand, cache));
            }
        } else if wanted && !fresh {
            // Between prefetch selections: the last list, less what arrived meanwhile.
            prefetch.0.extend(unsettled_requests(&self.prefetch_list.0, &demand, cache));
        } else if wanted {
            // Prefetch views do not refresh pages in the LRU order.
            self.availability.set_peek_only(true);
            for (cam, opts) in prefetch_views(camera, &self.history, options, &prefetch_options) {
                self.selector.select_available(
                    store,
                    cache,
                    &mut self.availability,
                    &mut prefetch,
                    &cam,
                    &opts,
                    &mut self.scratch,
                );
            }
            prefetch.0.retain(|p, _| !demand.0.contains_key(p));
            self.availability.set_peek_only(false);
            self.prefetch_list = (prefetch.clone(), Some(self.frame));
        }
        let times = StreamTimes { cut, prefetch: start.elapsed() - cut };
        self.history.push(*camera);
        let pages = self.held_pages(&selection.clusters);
        let cut_bytes = self.cut_bytes(&demand);
        if self.options.fit_budget {
            self.fit.update(cut_bytes, self.options.budget_bytes, !demand.is_empty());
        }
        let (pending, in_flight) = self.submit(&demand, &prefetch);
        let queues = (demand.len() as u64, prefetch.len() as u64, pending as u64, in_flight as u64);
        self.submitted = (demand, prefetch);
        let mut stats = self.frame_stats(&selection, queues);
        (stats.tau_scale, stats.cut_bytes) = (self.frame_scale, cut_bytes);
        StreamFrame { selection, times, pages, stats }
    }

    /// The prefetch views' options: while the fit has raised τ (the cache is what limits the
    /// cut), no view asks for the next finer level, which would not fit either.
    fn prefetch_options(&self) -> PrefetchOptions {
        let p = self.options.prefetch;
        if self.frame_scale > 1.0 {
            PrefetchOptions { tau_scale: p.tau_scale.max(1.0), ..p }
        } else {
            p
        }
    }

    /// `options` with the τ of the current frame's fit ([`crate::fit`]).
    fn fitted(&self, options: &SelectOptions) -> SelectOptions {
        SelectOptions { tau: options.tau * self.frame_scale, ..*options }
    }

    /// What the cut needs resident: the pages the frame holds (used or loaded since the
    /// frame began, drawn from or only looked up on the way down, and the pinned root pages)
    /// and the decoded sizes the store records for the pages `demand` asks for.
    fn cut_bytes(&self, demand: &Requests) -> u64 {
        let entries = self.store.pages();
        let asked: u64 =
            demand.0.keys().filter_map(|&p| entries.get(p as usize)).map(|e| e.uncompressed_len as u64).sum();
        self.cache.frame_bytes() + asked
    }

    /// The factor τ is raised by to fit the cache now ([`crate::fit`]; 1 with
    /// [`StreamOptions::fit_budget`] off).
    pub fn tau_scale(&self) -> f32 {
        if self.options.fit_budget {
            self.fit.scale()
        } else {
            1.0
        }
    }

    /// The pages of `clusters` from the frame's residency snapshot, sorted by page index.
    fn held_pages(&mut self, clusters: &[ClusterRef]) -> Vec<(u32, Arc<ResidentPage>)> {
        let mut pages: Vec<(u32, Arc<ResidentPage>)> = Vec::new();
        for c in clusters {
            if pages.last().map(|(p, _)| *p) != Some(c.page) {
                if let Some(p) = self.availability.page(&self.cache, c.page) {
                    pages.push((c.page, p));
                }
            }
        }
        pages.sort_by_key(|(p, _)| *p);
        pages.dedup_by_key(|(p, _)| *p);
        pages
    }

    /// The light's view of one shadow-map layer in the current frame (module documentation):
    /// the cut of `eye`'s LOD metric culled by `layer_view_proj`, by the availability rule over
    /// the residency snapshot of the last [`frame`](Self::frame) (call it after `frame`, with
    /// the same `eye` and `options`), and the pages its clusters draw from (held). Its missing
    /// pages are requested along with the frame's (never waiting; a frame asks for a missing
    /// page once, for the first view that meets it, so a page the eye's cut already wants keeps
    /// the eye's priority, and one that the frame's prefetch views met first — selected on the
    /// frame thread only without loader threads — stays in the prefetch queue). Called before any
    /// frame, it selects over an empty snapshot: the root pages only.
    pub fn select_light(
        &mut self,
        eye: &Camera,
        layer_view_proj: &glam::Mat4,
        options: &SelectOptions,
    ) -> (Selection, Vec<(u32, Arc<ResidentPage>)>) {
        if !self.snapshot_taken {
            self.availability.begin(&self.store);
            self.snapshot_taken = true;
        }
        let mut light = Requests::default();
        let mut selection = Selection::default();
        let options = &self.fitted(options);
        self.selector.select_light_available(
            &self.store,
            &self.cache,
            &mut self.availability,
            &mut light,
            eye,
            layer_view_proj,
            options,
            &mut selection,
        );
        let pages = self.held_pages(&selection.clusters);
        if !light.is_empty() {
            let (demand, prefetch) = &mut self.submitted;
            for (&page, &priority) in &light.0 {
                demand.add(page, priority);
            }
            prefetch.0.retain(|p, _| !light.0.contains_key(p));
            let (demand, prefetch) = std::mem::take(&mut self.submitted);
            self.submit(&demand, &prefetch);
            self.submitted = (demand, prefetch);
        }
        (selection, pages)
    }

    /// The waiting mode of [`select_light`](Self::select_light): the light's view of the render
    /// rule's cut (pages loaded on the caller's thread, as
    /// [`select_blocking`](Self::select_blocking)).
    pub fn select_light_blocking(
        &self,
        eye: &Camera,
        layer_view_proj: &glam::Mat4,
        options: &SelectOptions,
    ) -> Selection {
        self.selector.select_light(&self.store, &self.cache, eye, layer_view_proj, options)
    }

    /// The statistics of the frame that selected `selection` (the cache's counters since the
    /// last frame; `queues`: demand and prefetch requests, then pending and in-flight pages),
    /// and the frame counter advanced.
    fn frame_stats(&mut self, selection: &Selection, queues: (u64, u64, u64, u64)) -> StreamStats {
        let (demand, prefetch, pending, in_flight) = queues;
        let now = self.cache.stats();
        let last = std::mem::replace(&mut self.last_cache, now);
        let q = self.shared.lock();
        let (pl, pd) = (q.prefetch_loaded, q.prefetch_dropped);
        drop(q);
        let (lpl, lpd) = std::mem::replace(&mut self.last_prefetch, (pl, pd));
        let s = &selection.stats;
        let stats = StreamStats {
            frame: self.frame,
            pages_requested: demand,
            prefetch_requested: prefetch,
            pages_loaded: (now.misses - last.misses).saturating_sub(now.failed_pages - last.failed_pages),
            prefetch_loaded: pl - lpl,
            prefetch_dropped: pd - lpd,
            pages_evicted: now.evictions - last.evictions,
            bytes_read: now.bytes_read - last.bytes_read,
            resident_bytes: now.resident_bytes,
            resident_pages: now.resident_pages,
            pinned_bytes: now.pinned_bytes,
            stalls_avoided: s.groups_unavailable,
            clusters_fallback: s.clusters_fallback,
            groups_failed: s.groups_failed,
            pending,
            in_flight,
            failed_pages: now.failed_pages,
            clusters: selection.clusters.len() as u64,
            triangles: selection.triangles,
            // Set by a streamed frame (`frame`).
            tau_scale: 0.0,
            cut_bytes: 0,
        };
        self.frame += 1;
        stats
    }

    /// The blocking cut of the render rule (pages loaded on the caller's thread through the
    /// same cache): the reference a streamed frame converges to.
    pub fn select_blocking(&self, camera: &Camera, options: &SelectOptions) -> Selection {
        self.selector.select(&self.store, &self.cache, camera, options)
    }

    /// [`select_blocking`](Self::select_blocking) as a frame of its own: the statistics of the
    /// pages it loaded, read and holds, as [`frame`](Self::frame) gives them (`bench --wait`
    /// reports memory and disk like a streamed run; no requests or prefetch).
    pub fn frame_blocking(&mut self, camera: &Camera, options: &SelectOptions) -> (Selection, StreamStats) {
        let selection = self.select_blocking(camera, options);
        let stats = self.frame_stats(&selection, (0, 0, 0, 0));
        (selection, stats)
    }

    /// Replaces the loaders' queues by `demand` (first) and `prefetch`, highest priority first;
    /// resident, failed and in-flight pages are left out. Returns (queued, in flight).
    pub fn submit(&self, demand: &Requests, prefetch: &Requests) -> (usize, usize) {
        let filter = |r: &Requests| -> Vec<(u32, f32)> {
            let mut v = r.sorted();
            self.cache.retain_unsettled(&mut v, |&(p, _)| p);
            v.reverse(); // ascending: the next page is the last
            v
        };
        let (mut d, mut p) = (filter(demand), filter(prefetch));
        let mut q = self.shared.lock();
        d.retain(|(page, _)| !q.in_flight.contains(page));
        p.retain(|(page, _)| !q.in_flight.contains(page));
        q.demand = d;
        q.prefetch = p;
        let counts = (q.demand.len() + q.prefetch.len(), q.in_flight.len());
        drop(q);
        self.shared.work.notify_all();
        counts
    }

    /// Pauses or resumes the loader threads (a load in progress finishes).
    pub fn set_paused(&self, paused: bool) {
        self.shared.lock().paused = paused;
        self.shared.work.notify_all();
    }

    /// Loads up to `max` queued pages on the caller's thread, in priority order (frame pages
    /// first); returns how many were taken. Works whether or not loader threads run.
    pub fn load_queued(&self, max: usize) -> usize {
        let mut n = 0;
        while n < max {
            let Some(job) = take(&mut self.shared.lock(), &self.store, &self.cache) else { break };
            load(&self.store, &self.cache, &self.shared, job);
            n += 1;
        }
        n
    }

    /// Pages queued (frame + prefetch) and in flight.
    pub fn pending(&self) -> (usize, usize) {
        let q = self.shared.lock();
        (q.demand.len() + q.prefetch.len(), q.in_flight.len())
    }

    /// Waits until the queues are empty and no load is in flight, or `timeout` passes (then
    /// false). With paused or no loader threads, queued pages stay queued.
    pub fn wait_idle(&self, timeout: Duration) -> bool {
        let end = Instant::now() + timeout;
        let mut q = self.shared.lock();
        loop {
            if q.demand.is_empty() && q.prefetch.is_empty() && q.in_flight.is_empty() {
                return true;
            }
            let now = Instant::now();
            if now >= end {
                return false;
            }
            q = self.shared.done.wait_timeout(q, end - now).unwrap_or_else(|e| e.into_inner()).0;
        }
    }

    /// Number of loader threads running.
    pub fn loader_threads(&self) -> usize {
        self.threads.len()
    }

    fn stop(&mut self) {
        if let Some(worker) = &mut self.prefetch_worker {
            worker.jobs = None; // the worker's loop ends
            if let Some(t) = worker.thread.take() {
                if t.join().is_err() {
                    tracing::error!("the prefetch thread panicked");
                }
            }
        }
        self.shared.lock().shutdown = true;
        self.shared.work.notify_all();
        for t in self.threads.drain(..) {
            if t.join().is_err() {
                tracing::error!("a page loader thread panicked");
            }
        }
    }
}

impl Drop for Streamer {
    /// Stops the loader threads and waits for them.
    fn drop(&mut self) {
        self.stop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::tests::store_with_pages;

    fn requests(list: &[(u32, f32)]) -> Requests {
        let mut r = Requests::default();
        for &(p, q) in list {
            r.add(p, q);
        }
        r
    }

    #[test]
    fn each_frame_replaces_the_queue_by_priority_without_duplicates() {
        let dir = tempfile::tempdir().unwrap();
        let store = Arc::new(store_with_pages(dir.path(), 6, &[0]));
        let options = StreamOptions { budget_bytes: 1 << 20, loader_threads: 0, ..Default::default() };
        let s = Streamer::new(store, options).unwrap();
        assert!(s.cache().contains(0), "root pages are loaded up front");
        // Page 0 is resident: left out. Page 2 twice: once, with the larger priority.
        assert_eq!(
            s.submit(&requests(&[(0, 9.0), (1, 1.0), (2, 3.0), (2, 5.0)]), &requests(&[(3, 8.0)])),
            (3, 0)
        );
        // The next frame's requests replace these: pages 1 and 3 are stale.
        s.submit(&requests(&[(4, 1.0), (2, 2.0)]), &requests(&[(5, 7.0)]));
        assert_eq!(s.pending(), (3, 0));
        // Frame pages first (highest priority first), then prefetch.
        assert_eq!(s.load_queued(1), 1);
        assert!(s.cache().contains(2) && !s.cache().contains(4));
        assert_eq!(s.load_queued(10), 2);
        assert!(s.cache().contains(4) && s.cache().contains(5));
        assert!(!s.cache().contains(1) && !s.cache().contains(3), "stale requests were dropped");
        assert_eq!(s.pending(), (0, 0));
        assert!(s.wait_idle(Duration::from_millis(1)));
        // Resident pages are not queued again.
        assert_eq!(s.submit(&requests(&[(2, 1.0), (4, 1.0)]), &Requests::default()), (0, 0));
    }
}
