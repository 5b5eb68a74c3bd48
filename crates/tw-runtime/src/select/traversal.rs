//! One traversal of the skeleton ([`Selector`]'s LOD cut and frustum culling of one view), as
//! named steps: the node test, the group test, the shortcut through a group's kept steps, the
//! group's page, and the emission of its clusters. The rules each step applies and why they
//! give a crack-free cut are in the parent module's documentation; this module only orders
//! them.
//!
//! It runs every frame, for the eye and for each shadow-map layer, so the steps are plain
//! methods (no dynamic dispatch) and the only allocations are the traversal's stack, its page
//! list and its per-group verdict memo, one each per call, as before the split. The
//! residency mode, the view and the selection being written are passed to each step as
//! arguments, and [`Traversal`] holds only references: the compiler then knows that they do
//! not overlap and keeps them and their figures in registers through the group and cluster
//! loops. Kept in the struct (with the scratch by value), they were reloaded after every
//! counter update and every call into the availability snapshot: 2.6% more instructions in
//! the traversal along a 2 M-triangle plant's path (callgrind, `select_bench`); as it is, no
//! more than before the split.

use std::ops::ControlFlow;
use std::sync::atomic::Ordering;
use std::sync::Arc;

use glam::Vec3;
use tw_store::{Group, Node, Store};

use super::{step_sources, step_verdict, ClusterRef, Mode, SelectStats, Selection, Selector, Verdict, View};
use crate::cache::{ClusterInfo, ResidentPage};
use crate::error::RuntimeError;
use crate::frustum::{grid_box, Containment};

/// Inclusive grid box `(min, max)` of a cluster's vertices ([`ResidentPage::bounds`]).
type GridBox = ([u32; 3], [u32; 3]);

/// The state of one traversal besides its mode, view and output (the steps' arguments):
/// what it reads, and the scratch it reuses from node to node. Only references, so that the
/// compiler keeps them in registers (a scratch held by value here would give the struct an
/// address the calls might write through, and they would be reloaded after each).
pub(super) struct Traversal<'t> {
    selector: &'t Selector,
    store: &'t Store,
    scratch: &'t mut Scratch,
}

/// What a traversal reuses from group to group.
#[derive(Default)]
pub(super) struct Scratch {
    /// The pages of the selected groups, with repeats (counted at the end).
    pages: Vec<u32>,
    /// The current group's verdict of each step met so far ([`Traversal::verdict`]).
    verdicts: Vec<(u32, Verdict)>,
    /// Groups selected from their kept steps ([`Selector::groups_from_steps`]).
    from_steps: u64,
}

/// A group the traversal reached: its index, its record, and whether its node lies entirely
/// inside the frustum (no frustum tests below it).
#[derive(Clone, Copy)]
struct At<'g> {
    gi: u32,
    g: &'g Group,
    inside: bool,
}

impl<'t> Traversal<'t> {
    pub(super) fn new(selector: &'t Selector, store: &'t Store, scratch: &'t mut Scratch) -> Self {
        Traversal { selector, store, scratch }
    }

    /// The selection of `view` into `out` (cleared first): depth first from node 0, children
    /// in index order (the output order is deterministic), then the totals.
    pub(super) fn run(mut self, mode: &mut Mode<'_>, view: &View, out: &mut Selection) {
        out.clusters.clear();
        out.triangles = 0;
        out.stats = SelectStats::default();
        let (store, selector) = (self.store, self.selector);
        let nodes = store.nodes();
        // (node, inside): `inside` = an ancestor's box is entirely inside the frustum.
        let mut stack: Vec<(u32, bool)> = vec![(0, !view.cull)];
        if nodes.is_empty() {
            stack.clear();
        }
        while let Some((ni, inside)) = stack.pop() {
            let (Some(node), Some(&(lo, hi))) =
                (nodes.get(ni as usize), selector.node_boxes.get(ni as usize))
            else {
                continue;
            };
            let Some(inside) = self.node_test(view, &mut out.stats, ni as usize, (lo, hi), inside) else {
                continue;
            };
            self.visit_groups(mode, view, out, node, inside);
            let children = node.first_child..node.first_child.saturating_add(node.child_count);
            if node.child_count > 0 {
                stack.extend(children.rev().map(|c| (c, inside)));
            }
        }
        self.finish(out);
    }

    /// Steps 1 and 2 of the parent module's documentation for node `ni` with box `lo..hi`:
    /// `None` when its subtree is culled (outside the frustum, or every group below replaced),
    /// else whether the node lies entirely inside the frustum (`inside`: an ancestor does).
    #[inline]
    fn node_test(
        &self,
        view: &View,
        stats: &mut SelectStats,
        ni: usize,
        (lo, hi): (Vec3, Vec3),
        inside: bool,
    ) -> Option<bool> {
        stats.nodes_visited += 1;
        let mut inside = inside;
        if !inside {
            match view.frustum.test_aabb(lo, hi) {
                Containment::Outside => {
                    stats.nodes_culled_frustum += 1;
                    return None;
                }
                Containment::Inside => inside = true,
                Containment::Intersecting => {}
            }
        }
        if !view.section.is_empty() && view.section.removes_box(lo, hi) {
            stats.nodes_culled_section += 1;
            return None;
        }
        let (blo, bhi) = self.selector.lod_boxes[ni];
        if view.metric.aabb(self.selector.subtree_error[ni], blo, bhi) * (1.0 + 1e-9) <= view.tau {
            stats.nodes_culled_lod += 1;
            return None;
        }
        Some(inside)
    }

    /// The groups of a visited node, in order; a group index beyond the tables ends them.
    #[inline]
    fn visit_groups(
        &mut self,
        mode: &mut Mode<'_>,
        view: &View,
        out: &mut Selection,
        node: &Node,
        inside: bool,
    ) {
        let first = node.first_group as usize;
        for gi in first..first + node.group_count as usize {
            if self.visit_group(mode, view, out, gi, inside).is_break() {
                break;
            }
        }
    }

    /// Group `gi`: tested (step 3), then selected if it is drawn from.
    #[inline]
    fn visit_group(
        &mut self,
        mode: &mut Mode<'_>,
        view: &View,
        out: &mut Selection,
        gi: usize,
        inside: bool,
    ) -> ControlFlow<()> {
        let Some(&(error, sphere)) = self.selector.group_lod.get(gi) else { return ControlFlow::Break(()) };
        if !group_test(view, &mut out.stats, error, sphere, inside) {
            return ControlFlow::Continue(());
        }
        let store = self.store;
        let Some(g) = store.groups().get(gi) else { return ControlFlow::Break(()) };
        self.select_group(mode, view, out, At { gi: gi as u32, g, inside });
        ControlFlow::Continue(())
    }

    /// A group that is drawn from: selected from its kept steps if they settle it, else from
    /// its page (step 4), its steps kept for later frames.
    #[inline]
    fn select_group(&mut self, mode: &mut Mode<'_>, view: &View, out: &mut Selection, at: At<'_>) {
        if self.selected_from_steps(mode, view, &mut out.stats, at) {
            return;
        }
        let Some(page) = self.group_page(mode, view, &mut out.stats, at) else { return };
        let Some((infos, bounds)) = group_clusters(at, &page, &mut out.stats) else { return };
        out.stats.groups_selected += 1;
        self.scratch.pages.push(at.g.page);
        self.selector.keep_steps(at.gi as usize, infos, &page);
        if matches!(mode, Mode::Wait(_)) && self.all_skip(mode, view, at.gi) == Some(true) {
            return;
        }
        self.emit_clusters(mode, view, out, at, &page, (infos, bounds));
    }

    /// Streaming: a group whose steps are known and all skipped is selected without reading
    /// its page (asked in the order the path through its page would ask).
    #[inline]
    fn selected_from_steps(
        &mut self,
        mode: &mut Mode<'_>,
        view: &View,
        stats: &mut SelectStats,
        at: At<'_>,
    ) -> bool {
        let store = self.store;
        let Mode::Stream { cache, availability, .. } = mode else { return false };
        if availability.available(store, cache, at.gi)
            && availability.is_resident(cache, at.g.page)
            && self.all_skip(mode, view, at.gi) == Some(true)
        {
            stats.groups_selected += 1;
            self.scratch.from_steps += 1;
            self.scratch.pages.push(at.g.page);
            return true;
        }
        false
    }

    /// [`Selector::all_skip`] for group `g` in this traversal's mode and `view`.
    #[inline]
    fn all_skip(&self, mode: &mut Mode<'_>, view: &View, g: u32) -> Option<bool> {
        self.selector.all_skip(self.store, mode, &view.metric, view.tau, g)
    }

    /// The page of the group: waited for, or, when streaming, taken if the group is available
    /// and otherwise requested (the group is then treated as replaced: its available ancestors
    /// are drawn). `None`, counted, when there is none to draw from.
    #[inline]
    fn group_page(
        &self,
        mode: &mut Mode<'_>,
        view: &View,
        stats: &mut SelectStats,
        at: At<'_>,
    ) -> Option<Arc<ResidentPage>> {
        let (store, gi, page) = (self.store, at.gi, at.g.page);
        match mode {
            Mode::Wait(cache) => match cache.get(store, page) {
                Ok(p) => Some(p),
                Err(e) => {
                    page_error(gi, &e);
                    stats.groups_failed += 1;
                    None
                }
            },
            Mode::Stream { cache, availability, requests } => {
                let resident = if availability.available(store, cache, gi) {
                    availability.page(cache, page)
                } else {
                    None
                };
                if resident.is_none() {
                    if availability.page_failed(cache, page) {
                        stats.groups_failed += 1;
                    } else {
                        stats.groups_unavailable += 1;
                    }
                    availability.request_for(store, cache, &view.metric, gi, requests);
                }
                resident
            }
        }
    }

    /// Step 4 for a group drawn from `page` with members `infos` and `bounds`: its clusters
    /// whose step says draw (or fall back) and whose box is not outside the frustum, in
    /// cluster order.
    #[inline]
    fn emit_clusters(
        &mut self,
        mode: &mut Mode<'_>,
        view: &View,
        out: &mut Selection,
        at: At<'_>,
        page: &ResidentPage,
        (infos, bounds): (&[ClusterInfo], &[GridBox]),
    ) {
        self.scratch.verdicts.clear();
        for (k, (info, &(cmin, cmax))) in infos.iter().zip(bounds).enumerate() {
            let fallback = match self.verdict(mode, view, at.gi, page, info.step) {
                Verdict::Skip => continue,
                Verdict::Draw => false,
                Verdict::Fallback => true,
            };
            if !at.inside && self.cluster_outside(view, cmin, cmax) {
                out.stats.clusters_culled_frustum += 1;
                continue;
            }
            if !view.section.is_empty() && self.cluster_removed(view, cmin, cmax) {
                out.stats.clusters_culled_section += 1;
                continue;
            }
            if fallback {
                out.stats.clusters_fallback += 1;
                self.request_step_sources(mode, view, at.gi, page.steps()[info.step as usize]);
            }
            out.clusters.push(ClusterRef {
                page: at.g.page,
                index_in_page: at.g.first_cluster + k as u32,
                group: at.gi,
            });
            out.triangles += info.triangles as u64;
        }
    }

    /// The verdict of step `step` of `page` for group `gi`. The LOD test of a cluster depends
    /// only on its step (self error and sphere): evaluated once per step met in this group, in
    /// cluster order, so that the availability snapshot is consulted in the same order as
    /// cluster by cluster.
    #[inline]
    fn verdict(
        &mut self,
        mode: &mut Mode<'_>,
        view: &View,
        gi: u32,
        page: &ResidentPage,
        step: u32,
    ) -> Verdict {
        if let Some(&(_, v)) = self.scratch.verdicts.iter().find(|(s, _)| *s == step) {
            return v;
        }
        let (error, sphere) = page.steps()[step as usize];
        let v = step_verdict(
            self.store,
            &self.selector.group_lod,
            mode,
            &view.metric,
            view.tau,
            gi,
            error,
            sphere,
        );
        self.scratch.verdicts.push((step, v));
        v
    }

    /// Whether a cluster's vertex box (grid coordinates `cmin..=cmax`) is outside the frustum.
    #[inline]
    fn cluster_outside(&self, view: &View, cmin: [u32; 3], cmax: [u32; 3]) -> bool {
        let (clo, chi) = grid_box(cmin, cmax, self.selector.grid_step);
        view.frustum.test_aabb(clo, chi) == Containment::Outside
    }

    /// Whether a cluster's vertex box (grid coordinates `cmin..=cmax`) lies entirely on a
    /// removed side of the section.
    #[inline]
    fn cluster_removed(&self, view: &View, cmin: [u32; 3], cmax: [u32; 3]) -> bool {
        let (clo, chi) = grid_box(cmin, cmax, self.selector.grid_step);
        view.section.removes_box(clo, chi)
    }

    /// When streaming, requests the sources of the step `(error, sphere)` that a fallback
    /// cluster of group `gi` stands in for.
    #[inline]
    fn request_step_sources(
        &self,
        mode: &mut Mode<'_>,
        view: &View,
        gi: u32,
        (error, sphere): (f32, [f32; 4]),
    ) {
        if let Mode::Stream { cache, availability, requests } = mode {
            for s in step_sources(self.store, &self.selector.group_lod, gi, error, sphere) {
                availability.request_for(self.store, cache, &view.metric, s, requests);
            }
        }
    }

    /// The totals: clusters selected, distinct pages touched, and the groups selected from
    /// their kept steps added to the selector's diagnostic.
    fn finish(self, out: &mut Selection) {
        self.selector.from_steps.fetch_add(self.scratch.from_steps, Ordering::Relaxed);
        out.stats.clusters_selected = out.clusters.len() as u64;
        self.scratch.pages.sort_unstable();
        self.scratch.pages.dedup();
        out.stats.pages_touched = self.scratch.pages.len() as u64;
    }
}

/// Step 3: whether a group of error `error` and bounding sphere `sphere` is drawn from — not
/// replaced by coarser clusters, and not outside the frustum (`inside`: its node is inside).
#[inline]
fn group_test(view: &View, stats: &mut SelectStats, error: f32, sphere: [f32; 4], inside: bool) -> bool {
    stats.groups_tested += 1;
    if view.metric.sphere(error, sphere) <= view.tau {
        return false; // replaced by coarser clusters
    }
    if !inside
        && view.frustum.test_sphere(Vec3::new(sphere[0], sphere[1], sphere[2]), sphere[3])
            == Containment::Outside
    {
        stats.groups_culled_frustum += 1;
        return false;
    }
    if !view.section.is_empty()
        && view.section.removes_sphere(Vec3::new(sphere[0], sphere[1], sphere[2]), sphere[3])
    {
        stats.groups_culled_section += 1;
        return false;
    }
    true
}

/// The clusters of the group in `page` (their info and grid boxes), or `None`, logged and
/// counted as failed, when the page does not hold them as the group record says.
#[inline]
fn group_clusters<'p>(
    at: At<'_>,
    page: &'p ResidentPage,
    stats: &mut SelectStats,
) -> Option<(&'p [ClusterInfo], &'p [GridBox])> {
    let (gi, g) = (at.gi, at.g);
    let range = g.first_cluster as usize..g.first_cluster as usize + g.cluster_count as usize;
    let (Some(infos), Some(bounds)) = (page.info().get(range.clone()), page.bounds.get(range)) else {
        tracing::error!(
            "group {gi} skipped: clusters {}..+{} beyond the {} clusters of page {}",
            g.first_cluster,
            g.cluster_count,
            page.clusters.len(),
            g.page
        );
        stats.groups_failed += 1;
        return None;
    };
    if let Some(c) = infos.iter().find(|c| c.group != gi) {
        tracing::error!("group {gi} skipped: page {} lists a member of group {}", g.page, c.group);
        stats.groups_failed += 1;
        return None;
    }
    Some((infos, bounds))
}

/// Logs a page that could not be loaded for group `gi`: once as an error, or, when it is a
/// page already known to have failed, quietly. Out of line: a healthy store never comes here.
#[cold]
#[inline(never)]
fn page_error(gi: u32, e: &RuntimeError) {
    match e {
        RuntimeError::PageFailed { .. } => tracing::debug!("group {gi}: {e}"),
        _ => tracing::error!("group {gi} skipped: {e}"),
    }
}
