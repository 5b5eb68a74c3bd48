//! The LOD cut and view-frustum culling of one frame (docs/DESIGN.md, D1–D3; docs/FORMAT.md,
//! "Render rule").
//!
//! A depth-first traversal of the skeleton from node 0 (children in index order, so the output
//! order is deterministic):
//!
//! 1. **Frustum** (optional): a node whose grid box is outside the frustum is skipped with its
//!    subtree (every vertex of a group lies in the box of its node, and child boxes lie in their
//!    parent's). A node entirely inside switches frustum tests off below it.
//! 2. **LOD**: a node is skipped when no group in its subtree can be drawn from. A group's
//!    clusters are drawn only when the group is *not replaced*, `proj(group.sphere,
//!    group.error) > τ`. Let `M` be the largest group error in the subtree and `B` a box
//!    containing every group sphere of the subtree (both precomputed by [`Selector::new`]). If
//!    the eye is outside `B` at distance `d_B > 0`, then for each group `G` of the subtree the
//!    nearest point of its sphere lies in `B`, so its distance `d_G ≥ d_B > 0` (the eye is not
//!    in the sphere either) and, with `e_G ≤ M`,
//!    `proj(G) = e_G·s / max(d_G, near) ≤ M·s / max(d_B, near) = proj_B(M)`.
//!    So `proj_B(M) ≤ τ` proves every group below is replaced by something coarser: skipping the
//!    subtree loses nothing. (With the eye in `B`, `proj_B(M) = ∞` for `M > 0`: never skipped;
//!    for `M = 0` every group projects to 0 and is replaced.) `M` is computed from the group
//!    table rather than trusted from `node.max_error`, and the bound is inflated by 10⁻⁹ against
//!    rounding, so a store that breaks invariant 10 still gets a correct cut.
//! 3. **Groups** of a visited node: a replaced group (`proj ≤ τ`) is skipped; so is one whose
//!    sphere is outside the frustum. The others' pages are fetched through the [`PageCache`].
//! 4. **Clusters** of such a group are drawn when `proj(self_sphere, self_error) ≤ τ` (the
//!    cluster is fine enough) and their vertex box is not outside the frustum.
//!
//! **Section** ([`SelectOptions::section`], [`crate::section`]): a node box, group sphere or
//! cluster box that lies entirely on a removed side of a section plane, or outside the section
//! box, is culled at steps 1, 3 and 4 exactly like a frustum miss (the same containment
//! argument: nothing below it has a kept point), and counted apart
//! ([`SelectStats::nodes_culled_section`] …). The renderer clips the rest per fragment, so
//! culling only saves work, it never decides what shows.
//!
//! **Per step, not per cluster.** A cluster's LOD decision depends only on its *step* — its
//! `(self_error, self_sphere)`, shared by the clusters one simplification made — and, when
//! streaming, on the availability of that step's sources. So the decision is evaluated once per
//! step a group holds (in cluster order, memoized for the group), from the compact per-cluster
//! data the loader computed when it decoded the page ([`ResidentPage::info`],
//! [`ResidentPage::steps`]): the selection never reads a cluster's vertex data.
//!
//! **Frame-to-frame state.** Once a group's page has been seen, the [`Selector`] keeps the
//! group's steps (in order of first appearance; pages never change). In later frames a group
//! whose every step is skipped (too coarse, and, when streaming, its finer sources available)
//! is selected without reading its page at all (`Selector::all_skip`) — 63% of the selected
//! groups on a path through the 10^8-triangle plant, the DAG's interior above the cut. The steps are
//! evaluated in the order the cluster loop would meet them and the evaluation stops at the first
//! step that is not skipped, so the residency snapshot is asked the same questions in the same
//! order: the cut, the statistics, the requests and even the page cache's LRU order are those
//! of the traversal without the shortcut (tests/coherence.rs drives a warm selector and fresh
//! ones over random camera sequences and compares all of them).
//!
//! Why not an incremental front (Hoppe, Yoon 2003 §5: refine and coarsen last frame's front)?
//! The skeleton is small (23,555 nodes for 10^8 triangles) and the node tests were 1–3% of the
//! traversal's time in a profile of the 10^8 walk and fly-over; the work is in the groups and
//! clusters at the cut, which an incremental front must test every frame as well. The state
//! kept here is what coherence buys: per-group data read once instead of every frame.
//!
//! Because each decision is a function of (error, sphere) evaluated the same way everywhere
//! ([`LodMetric`]), a group's "replaced" and its replacement's "fine enough" agree exactly, and
//! the drawn set is a crack-free cut of the DAG; the frustum only removes clusters whose
//! vertices are all outside the view.
//!
//! A page that cannot be loaded (checksum, decoding) is logged once (`tracing::error`), its
//! groups are counted in [`SelectStats::groups_failed`] and the frame goes on drawing the best
//! ancestor it has, in both modes: the streaming mode treats a failed group as unavailable (the
//! availability rule below), and the waiting mode, once a traversal met a failed page, selects
//! again by that rule over the settled cache ([`Selector::select_into`]). Only a failed root
//! page, which has no ancestor, leaves a hole; the commands report every failed page.
//!
//! **The light's view** (Govindaraju's thesis ch. 4, "LOD consistency": always the eye's LOD).
//! The clusters that can cast a shadow into a shadow-map layer are the *eye's* LOD cut culled
//! by the *layer's* frustum ([`Selector::select_light`], [`Selector::select_light_available`]):
//! the LOD metric is the eye camera's pixel error and only the culling frustum changes, so a
//! cluster drawn in both views is drawn at the same level (no false self-shadowing), and its
//! shadow changes only when the eye's cut does. A traversal takes both as a `View`; the eye's
//! own selection is the view whose frustum is the eye's. The thesis' other policy, "the finer
//! of both" ([`SelectOptions::light_lod`]), changes the metric of every view alike (the larger
//! of the eye's pixels and the light's texels), so the two views still agree on each level.
//!
//! **Two residency modes.** [`Selector::select`] waits: pages are loaded through
//! [`PageCache::get`] on a miss, and the cut is exactly the render rule's. [`Selector::select_available`]
//! never waits: it follows the availability rule of docs/FORMAT.md ([`crate::availability`]):
//! a group that is not available is treated as replaced (counted in
//! [`SelectStats::groups_unavailable`], the stalls avoided, and the pages it needs are added to
//! the frame's requests), and a simplified cluster whose step sources are not available is
//! drawn in their place (counted in [`SelectStats::clusters_fallback`]). With every needed page
//! resident both modes give the same cut. The LOD skip of step 2 stays valid: availability only
//! replaces more groups.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

use glam::{Mat4, Vec3};
use tw_store::Store;

use crate::availability::{Availability, Requests};
use crate::cache::{ClusterInfo, PageCache, ResidentPage};
use crate::camera::Camera;
use crate::frustum::{grid_box, Frustum};
use crate::lod_error::LodMetric;
use crate::section::Section;
use crate::shadow::LightLod;

mod traversal;
use traversal::{Scratch, Traversal};

/// What to select for one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SelectOptions {
    /// Pixel error threshold τ (docs/DESIGN.md, D3; default 1).
    pub tau: f32,
    /// Viewport size in pixels (width, height): the height scales the pixel error, the aspect
    /// ratio shapes the frustum.
    pub viewport: [u32; 2],
    /// Cull against the view frustum (`--frustum off` turns it off).
    pub frustum_culling: bool,
    /// The LOD policy "the finer of both" (Govindaraju's thesis §4.2.1, method 1): a shadow
    /// light's metric, so that every view of the frame (the eye's and the light's) selects the
    /// cut fine enough in both the eye's pixels and the light's texels
    /// ([`LodMetric::with_light`]). `None`, the default: the eye's LOD alone (method 2).
    pub light_lod: Option<LightLod>,
    /// Section planes and box (scene space): what lies entirely on a removed side is culled
    /// like a frustum miss, in every view (the eye's, the light's, the prefetch views).
    pub section: Section,
}

impl Default for SelectOptions {
    fn default() -> Self {
        SelectOptions {
            tau: 1.0,
            viewport: [1280, 720],
            frustum_culling: true,
            light_lod: None,
            section: Section::default(),
        }
    }
}

/// One selected cluster: cluster `index_in_page` of page `page`, a member of group `group`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ClusterRef {
    pub page: u32,
    pub index_in_page: u32,
    pub group: u32,
}

/// What the selection did (per frame; docs/DESIGN.md "Measuring": "what was culled and why").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SelectStats {
    /// Nodes reached by the traversal (including the culled ones).
    pub nodes_visited: u64,
    /// Nodes skipped (with their subtrees) because their box is outside the frustum.
    pub nodes_culled_frustum: u64,
    /// Nodes skipped because every group below is replaced by something coarser.
    pub nodes_culled_lod: u64,
    /// Groups of visited nodes whose error was tested.
    pub groups_tested: u64,
    /// Groups outside the frustum (not replaced, but not visible).
    pub groups_culled_frustum: u64,
    /// Groups drawn from (not replaced, in the frustum, page loaded).
    pub groups_selected: u64,
    /// Groups skipped because their page could not be loaded (in the streaming mode: failed
    /// pages, their best available ancestor drawn instead).
    pub groups_failed: u64,
    /// Streaming mode: groups that wanted to be drawn (not replaced, in the frustum) but were
    /// not available, so an ancestor was drawn in their place — the stalls avoided.
    pub groups_unavailable: u64,
    /// Streaming mode: simplified clusters drawn because their finer sources were not
    /// available (the fallback geometry drawn).
    pub clusters_fallback: u64,
    /// Clusters of selected groups that were fine enough but outside the frustum.
    pub clusters_culled_frustum: u64,
    /// Nodes skipped (with their subtrees) because their box lies entirely on a removed side
    /// of the section ([`SelectOptions::section`]).
    pub nodes_culled_section: u64,
    /// Groups whose sphere lies entirely on a removed side of the section.
    pub groups_culled_section: u64,
    /// Clusters of selected groups, fine enough and in the frustum, whose box lies entirely on
    /// a removed side of the section.
    pub clusters_culled_section: u64,
    pub clusters_selected: u64,
    /// Distinct pages the selected groups live in.
    pub pages_touched: u64,
}

/// The clusters to draw this frame, in traversal order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Selection {
    pub clusters: Vec<ClusterRef>,
    pub triangles: u64,
    pub stats: SelectStats,
}

/// What one traversal measures and culls by: the LOD metric of the camera whose pixel error
/// decides the cut (always the eye's), and the frustum that culls (the eye's, or a shadow-map
/// layer's for the light's view; see the module documentation).
#[derive(Clone, Copy, Debug)]
struct View {
    metric: LodMetric,
    frustum: Frustum,
    /// Whether `frustum` culls at all (`--frustum off` turns culling off in every view).
    cull: bool,
    tau: f64,
    /// The section; culls only when not empty.
    section: Section,
}

impl View {
    /// The eye's own view: its LOD metric, culled by its frustum.
    fn eye(camera: &Camera, options: &SelectOptions) -> View {
        let [w, h] = options.viewport.map(|v| v.max(1) as f32);
        View::culled_by(camera, &camera.view_projection(w / h), options)
    }

    /// The eye's LOD metric, culled by the frustum of `view_proj` (a shadow-map layer's).
    fn culled_by(eye: &Camera, view_proj: &Mat4, options: &SelectOptions) -> View {
        let h = options.viewport[1].max(1) as f32;
        View {
            metric: LodMetric::new(eye, h).with_light(options.light_lod),
            frustum: Frustum::from_view_projection(view_proj),
            cull: options.frustum_culling,
            tau: options.tau as f64,
            section: options.section,
        }
    }
}

/// Per-store data for [`Selector::select`], computed once from the tables.
#[derive(Clone, Debug)]
pub struct Selector {
    grid_step: f64,
    /// Scene-space box of each node.
    node_boxes: Vec<(Vec3, Vec3)>,
    /// Box of each node's subtree group spheres (see the module documentation).
    lod_boxes: Vec<(Vec3, Vec3)>,
    /// Largest group error in each node's subtree.
    subtree_error: Vec<f32>,
    /// `(error, sphere)` of each group: the render rule's test reads 20 bytes a group here
    /// instead of the store's whole group record.
    group_lod: Vec<(f32, [f32; 4])>,
    /// Per group, once its page has been seen: the distinct `(self_error, self_sphere)` of its
    /// clusters (its steps), in order of first appearance among the clusters. With them a
    /// frame decides that none of a group's clusters is drawn without reading its page
    /// ([`Selector::all_skip`]); the page's content never changes (checksummed), so once is
    /// enough.
    group_steps: Vec<OnceLock<Box<[Step]>>>,
    /// Groups selected from their kept steps, since the selector was made
    /// ([`Selector::groups_from_steps`]).
    from_steps: Arc<AtomicU64>,
}

/// A step: the `(self_error, self_sphere)` its clusters share.
type Step = (f32, [f32; 4]);

/// Where a selection gets its pages (see the module documentation).
enum Mode<'a> {
    /// Load on a miss and wait.
    Wait(&'a PageCache),
    /// The availability rule over a residency snapshot; missing pages are requested.
    Stream { cache: &'a PageCache, availability: &'a mut Availability, requests: &'a mut Requests },
}

/// The sources of the step of a cluster of group `g` whose self error and self sphere are
/// `error` and `sphere`: the sources of `g` with that error and sphere (docs/FORMAT.md,
/// "Links").
fn step_sources<'s>(
    store: &'s Store,
    group_lod: &'s [(f32, [f32; 4])],
    g: u32,
    error: f32,
    sphere: [f32; 4],
) -> impl Iterator<Item = u32> + 's {
    store
        .group_sources(g)
        .iter()
        .copied()
        .filter(move |&s| group_lod.get(s as usize).is_some_and(|&(e, sp)| e == error && sp == sphere))
}

/// What a cluster's step says about the cluster (a function of its group, its self error and
/// self sphere, and the frame's availability; [`step_verdict`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Verdict {
    /// Fine enough: drawn (if in the frustum).
    Draw,
    /// Too coarse: finer clusters are drawn instead.
    Skip,
    /// Too coarse, but its step's sources are not available: drawn in their place.
    Fallback,
}

/// Widens `v` by a relative 2⁻²⁰ (outwards in direction `sign`) before rounding to f32.
fn widen(v: f64, sign: f64) -> f32 {
    (v + sign * v.abs() * 2f64.powi(-20)) as f32
}

/// The [`Verdict`] of a cluster of group `g` with self error `error` and self sphere `sphere`:
/// `Draw` when `proj(sphere, error) ≤ τ`; otherwise, when streaming, `Fallback` if the sources
/// of its step are not all available (and it has a recorded step), else `Skip`.
#[allow(clippy::too_many_arguments)]
fn step_verdict(
    store: &Store,
    group_lod: &[(f32, [f32; 4])],
    mode: &mut Mode<'_>,
    metric: &LodMetric,
    tau: f64,
    g: u32,
    error: f32,
    sphere: [f32; 4],
) -> Verdict {
    if metric.sphere(error, sphere) <= tau {
        return Verdict::Draw;
    }
    // Too coarse: finer clusters of another group are drawn — unless, when streaming, those
    // (the sources of its step) are not available.
    let Mode::Stream { cache, availability, .. } = mode else { return Verdict::Skip };
    if error <= 0.0 {
        return Verdict::Skip;
    }
    let mut step = step_sources(store, group_lod, g, error, sphere).peekable();
    if step.peek().is_none() {
        return Verdict::Skip; // no step recorded (a store that breaks invariant 12)
    }
    if step.all(|s| availability.available(store, cache, s)) {
        return Verdict::Skip;
    }
    Verdict::Fallback
}

impl Selector {
    /// Precomputes node boxes, subtree sphere boxes and subtree errors: O(nodes + groups).
    pub fn new(store: &Store) -> Selector {
        let step = store.header().grid_step;
        let nodes = store.nodes();
        let groups = store.groups();
        let node_boxes: Vec<(Vec3, Vec3)> = nodes.iter().map(|n| grid_box(n.min, n.max, step)).collect();
        let mut lod_boxes = node_boxes.clone();
        let mut subtree_error = vec![0f32; nodes.len()];
        // Children have larger indices than their parent (checked when the store is opened).
        for i in (0..nodes.len()).rev() {
            let n = &nodes[i];
            let (mut lo, mut hi) = lod_boxes[i];
            let mut err = 0f32;
            let range = n.first_group as usize..n.first_group as usize + n.group_count as usize;
            for g in groups.get(range).unwrap_or_default() {
                err = err.max(g.error);
                let [x, y, z, r] = g.sphere.map(|v| v as f64);
                lo = lo.min(Vec3::new(widen(x - r, -1.0), widen(y - r, -1.0), widen(z - r, -1.0)));
                hi = hi.max(Vec3::new(widen(x + r, 1.0), widen(y + r, 1.0), widen(z + r, 1.0)));
            }
            let children = n.first_child as usize..n.first_child as usize + n.child_count as usize;
            if let (Some(errs), Some(boxes)) = (subtree_error.get(children.clone()), lod_boxes.get(children))
            {
                for (&e, &(clo, chi)) in errs.iter().zip(boxes) {
                    err = err.max(e);
                    lo = lo.min(clo);
                    hi = hi.max(chi);
                }
            }
            lod_boxes[i] = (lo, hi);
            subtree_error[i] = err;
        }
        let group_lod = groups.iter().map(|g| (g.error, g.sphere)).collect();
        let group_steps = (0..groups.len()).map(|_| OnceLock::new()).collect();
        Selector {
            grid_step: step,
            node_boxes,
            lod_boxes,
            subtree_error,
            group_lod,
            group_steps,
            from_steps: Arc::default(),
        }
    }

    /// Groups selected from their kept steps without reading their page, over every selection
    /// this selector (and its clones) made. A diagnostic: the selections themselves do not
    /// depend on it.
    pub fn groups_from_steps(&self) -> u64 {
        self.from_steps.load(Ordering::Relaxed)
    }

    /// Whether no cluster of group `g` is drawn this frame, from its recorded steps alone:
    /// every step's verdict is [`Verdict::Skip`]. `None` when the steps are not known yet.
    /// The steps are evaluated in their recorded order and the evaluation stops at the first
    /// other verdict, so the availability snapshot sees the same questions in the same order
    /// as the cluster loop would ask them (which keeps the page cache's LRU order identical).
    fn all_skip(
        &self,
        store: &Store,
        mode: &mut Mode<'_>,
        metric: &LodMetric,
        tau: f64,
        g: u32,
    ) -> Option<bool> {
        let steps = self.group_steps.get(g as usize)?.get()?;
        Some(steps.iter().all(|&(error, sphere)| {
            step_verdict(store, &self.group_lod, mode, metric, tau, g, error, sphere) == Verdict::Skip
        }))
    }

    /// Selects the clusters to draw for `camera` (see the module documentation). Pages come
    /// from `cache` (loaded on a miss).
    pub fn select(
        &self,
        store: &Store,
        cache: &PageCache,
        camera: &Camera,
        options: &SelectOptions,
    ) -> Selection {
        let mut out = Selection::default();
        self.select_into(store, cache, camera, options, &mut out);
        out
    }

    /// [`select`](Self::select) into `out` (cleared first), reusing its allocation.
    pub fn select_into(
        &self,
        store: &Store,
        cache: &PageCache,
        camera: &Camera,
        options: &SelectOptions,
        out: &mut Selection,
    ) {
        self.select_view(store, cache, &View::eye(camera, options), out);
    }

    /// The light's view of a shadow-map layer, waiting for pages: the cut of the *eye's* LOD
    /// metric (`eye`, `options.tau`, `options.viewport`) culled by the frustum of
    /// `layer_view_proj` instead of the eye's (module documentation, "The light's view"). A
    /// cluster it selects is at the level the eye's cut has it, wherever the eye looks.
    pub fn select_light(
        &self,
        store: &Store,
        cache: &PageCache,
        eye: &Camera,
        layer_view_proj: &Mat4,
        options: &SelectOptions,
    ) -> Selection {
        let mut out = Selection::default();
        self.select_view(store, cache, &View::culled_by(eye, layer_view_proj, options), &mut out);
        out
    }

    /// The waiting mode's selection of `view` (with the failed-page fallback).
    fn select_view(&self, store: &Store, cache: &PageCache, view: &View, out: &mut Selection) {
        self.traverse(store, &mut Mode::Wait(cache), view, out);
        if out.stats.groups_failed > 0 {
            self.select_around_failures(store, cache, view, out);
        }
    }

    /// The waiting mode's answer to a failed page: the best resident ancestor is drawn in place
    /// of the failed groups, as the streaming mode does. Selects by the availability rule, loads
    /// (waiting) the pages that selection still wants, and repeats until it wants nothing more
    /// (the wanted pages are resident or failed). A healthy store never comes here, so its cut
    /// is the render rule's exactly; with a failed page the cut is the availability rule's
    /// over a cache that holds every page it could load: crack-free, and complete but for the
    /// failed pages' geometry that no loaded ancestor covers.
    fn select_around_failures(&self, store: &Store, cache: &PageCache, view: &View, out: &mut Selection) {
        // Each round loads every page the last one wanted; a round wants more only where a
        // newly loaded group exposes finer ones, so the rounds are bounded by the DAG's depth.
        // The cap guards against a cache budget too small to hold a whole cut (loads evicting
        // each other): the last selection is drawn, never a loop.
        const MAX_ROUNDS: usize = 64;
        let failed = out.stats.groups_failed;
        let mut availability = Availability::default();
        for _ in 0..MAX_ROUNDS {
            availability.begin(store);
            let mut requests = Requests::default();
            let mut mode = Mode::Stream { cache, availability: &mut availability, requests: &mut requests };
            self.traverse(store, &mut mode, view, out);
            let mut loaded = false;
            for (page, _) in requests.sorted() {
                loaded |= cache.get(store, page).is_ok();
            }
            if !loaded {
                break;
            }
        }
        out.stats.groups_failed = out.stats.groups_failed.max(failed);
    }

    /// Selects without waiting for pages: the availability rule of docs/FORMAT.md over the
    /// frame's residency snapshot `availability` (call [`Availability::begin`] once per frame
    /// first; several selections of one frame may share it). Missing pages the cut wants are
    /// added to `requests` (priority: the pixel error they would remove). Never reads a page.
    // The frame's snapshot and request list stay separate arguments: the prefetch views share
    // the snapshot but collect into their own list.
    #[allow(clippy::too_many_arguments)]
    pub fn select_available(
        &self,
        store: &Store,
        cache: &PageCache,
        availability: &mut Availability,
        requests: &mut Requests,
        camera: &Camera,
        options: &SelectOptions,
        out: &mut Selection,
    ) {
        let mut mode = Mode::Stream { cache, availability, requests };
        self.traverse(store, &mut mode, &View::eye(camera, options), out);
    }

    /// [`select_light`](Self::select_light) without waiting: the availability rule over the
    /// frame's residency snapshot, as [`select_available`](Self::select_available) (the same
    /// snapshot as the eye's cut of the frame, so both views draw from the same resident set;
    /// missing pages are added to `requests` with the eye metric's priority).
    #[allow(clippy::too_many_arguments)]
    pub fn select_light_available(
        &self,
        store: &Store,
        cache: &PageCache,
        availability: &mut Availability,
        requests: &mut Requests,
        eye: &Camera,
        layer_view_proj: &Mat4,
        options: &SelectOptions,
        out: &mut Selection,
    ) {
        let mut mode = Mode::Stream { cache, availability, requests };
        self.traverse(store, &mut mode, &View::culled_by(eye, layer_view_proj, options), out);
    }

    /// One traversal of `view` into `out` (cleared first): the steps of the module
    /// documentation, in [`traversal`].
    fn traverse(&self, store: &Store, mode: &mut Mode<'_>, view: &View, out: &mut Selection) {
        let mut scratch = Scratch::default();
        Traversal::new(self, store, &mut scratch).run(mode, view, out);
    }

    /// Keeps group `g`'s steps the first time its page is read: the distinct steps of its
    /// clusters `infos` (in `page`), in order of first appearance ([`Selector::all_skip`]
    /// reads them in later frames).
    fn keep_steps(&self, g: usize, infos: &[ClusterInfo], page: &ResidentPage) {
        self.group_steps[g].get_or_init(|| {
            let mut seen: Vec<u32> = Vec::new();
            for info in infos {
                if !seen.contains(&info.step) {
                    seen.push(info.step);
                }
            }
            seen.iter().map(|&k| page.steps()[k as usize]).collect()
        });
    }
}
