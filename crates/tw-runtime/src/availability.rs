//! The availability rule of docs/FORMAT.md ("Availability: drawing with pages missing";
//! docs/DESIGN.md, D4: a frame never waits for the disk, it draws the best resident ancestor), and
//! the pages a frame must request to make a wanted group available.
//!
//! Per frame, over a *snapshot* of the page cache:
//!
//! - `resident(G)`: the page of G is loaded. The first time a frame asks about a page, the
//!   cache's answer is recorded (with the page's `Arc`, so it cannot go away under the frame);
//!   every later question in the same frame gets the same answer, however the loader threads
//!   change the cache meanwhile. The rule's proof assumes one fixed resident set per frame:
//!   this is it.
//! - `A(G)`: a root group (no parents) is available when resident; another group when every
//!   parent P is available and every source of P is resident. Memoized per frame; computed
//!   with an explicit stack (parents first), never by recursion, so a deep DAG cannot overflow
//!   the stack. A parent whose index is not larger than its child's (which `tw-store` rejects at
//!   open) counts as unavailable, so the evaluation always ends.
//! - [`Availability::request_for`]: the missing pages that keep a wanted group G from being
//!   available: its own page, the pages of the sources of its parents, and so on up through
//!   the unavailable ancestors. Each page is requested with the largest priority of the groups
//!   that need it, the priority of a group being the pixel error its coarser replacement shows
//!   (`proj(G.sphere, G.error)`, the error that loading it removes; FORMAT.md's render rule).
//!
//! Cost: O(groups and links reached from the groups the traversal tests) per frame; the
//! per-group and per-page arrays are allocated once and reset by bumping a frame stamp.

use std::collections::HashMap;
use std::sync::Arc;

use tw_store::Store;

use crate::cache::{PageCache, PageState, ResidentPage};
use crate::lod_error::LodMetric;

/// Residency snapshot and availability memo of one frame (see the module documentation).
///
/// Invariants: an entry of `page_stamp`/`group_stamp`/`walk_stamp` equal to `frame` means the
/// matching `page_state`/`group_avail`/walk mark is valid for this frame; `touched` lists the
/// pages whose `page_state` holds an `Arc` (released at the next [`begin`](Self::begin)).
#[derive(Debug, Default)]
pub struct Availability {
    frame: u32,
    page_stamp: Vec<u32>,
    page_state: Vec<Snap>,
    touched: Vec<u32>,
    group_stamp: Vec<u32>,
    group_avail: Vec<bool>,
    walk_stamp: Vec<u32>,
    stack: Vec<u32>,
    /// Whether looking a page up marks it used in the cache (LRU); off for prefetch views.
    peek_only: bool,
}

#[derive(Clone, Debug, Default)]
enum Snap {
    #[default]
    Missing,
    Failed,
    Resident(Arc<ResidentPage>),
}

/// Pages to load, page → priority (pixels; larger first). Repeated requests keep the largest.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Requests(pub HashMap<u32, f32>);

impl Requests {
    pub fn add(&mut self, page: u32, priority: f32) {
        let p = self.0.entry(page).or_insert(priority);
        if priority > *p {
            *p = priority;
        }
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Highest priority first (ties: lower page first).
    pub fn sorted(&self) -> Vec<(u32, f32)> {
        let mut v: Vec<(u32, f32)> = self.0.iter().map(|(&p, &q)| (p, q)).collect();
        v.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        v
    }
}

impl Availability {
    /// Starts a new frame for `store`: forgets the previous frame's snapshot.
    pub fn begin(&mut self, store: &Store) {
        let (pages, groups) = (store.pages().len(), store.groups().len());
        if self.page_stamp.len() != pages || self.group_stamp.len() != groups {
            *self = Availability {
                page_stamp: vec![0; pages],
                page_state: vec![Snap::Missing; pages],
                group_stamp: vec![0; groups],
                group_avail: vec![false; groups],
                walk_stamp: vec![0; groups],
                ..Default::default()
            };
        }
        for p in self.touched.drain(..) {
            self.page_state[p as usize] = Snap::Missing;
        }
        self.peek_only = false;
        self.frame = self.frame.wrapping_add(1);
        if self.frame == 0 {
            // Stamps wrapped: clear them so that no stale entry reads as current.
            self.page_stamp.iter_mut().for_each(|s| *s = 0);
            self.group_stamp.iter_mut().for_each(|s| *s = 0);
            self.walk_stamp.iter_mut().for_each(|s| *s = 0);
            self.frame = 1;
        }
    }

    /// With `true`, pages first looked up from now on are not marked used in the cache (for the
    /// prefetch views, which must not change what LRU evicts). Reset by [`begin`](Self::begin).
    pub fn set_peek_only(&mut self, peek_only: bool) {
        self.peek_only = peek_only;
    }

    fn snap(&mut self, cache: &PageCache, page: u32) -> &Snap {
        let i = page as usize;
        if i >= self.page_stamp.len() {
            return &Snap::Failed;
        }
        if self.page_stamp[i] != self.frame {
            self.page_stamp[i] = self.frame;
            let state = if self.peek_only { cache.peek_state(page) } else { cache.state(page) };
            self.page_state[i] = match state {
                PageState::Resident(p) => {
                    self.touched.push(page);
                    Snap::Resident(p)
                }
                PageState::Missing => Snap::Missing,
                PageState::Failed => Snap::Failed,
            };
        }
        &self.page_state[i]
    }

    /// The page if it is resident in this frame's snapshot.
    pub fn page(&mut self, cache: &PageCache, page: u32) -> Option<Arc<ResidentPage>> {
        match self.snap(cache, page) {
            Snap::Resident(p) => Some(p.clone()),
            _ => None,
        }
    }

    /// Whether `page` is resident in this frame's snapshot (without cloning its `Arc`).
    pub fn is_resident(&mut self, cache: &PageCache, page: u32) -> bool {
        self.page_resident(cache, page)
    }

    /// Whether `page` failed (or does not exist), in this frame's snapshot.
    pub fn page_failed(&mut self, cache: &PageCache, page: u32) -> bool {
        matches!(self.snap(cache, page), Snap::Failed)
    }

    fn page_resident(&mut self, cache: &PageCache, page: u32) -> bool {
        matches!(self.snap(cache, page), Snap::Resident(_))
    }

    /// `resident(G)`: the page of group `g` is resident (false for an unknown group).
    pub fn group_resident(&mut self, store: &Store, cache: &PageCache, g: u32) -> bool {
        match store.groups().get(g as usize) {
            Some(grp) => self.page_resident(cache, grp.page),
            None => false,
        }
    }

    /// Every source of `p` is resident.
    fn sources_resident(&mut self, store: &Store, cache: &PageCache, p: u32) -> bool {
        store.group_sources(p).iter().all(|&s| self.group_resident(store, cache, s))
    }

    fn known(&self, g: u32) -> Option<bool> {
        let i = g as usize;
        (self.group_stamp.get(i) == Some(&self.frame)).then(|| self.group_avail[i])
    }

    /// `A(g)` of the availability rule (false for an unknown group).
    pub fn available(&mut self, store: &Store, cache: &PageCache, g: u32) -> bool {
        if g as usize >= self.group_stamp.len() {
            return false;
        }
        if let Some(a) = self.known(g) {
            return a;
        }
        let mut stack = std::mem::take(&mut self.stack);
        stack.clear();
        stack.push(g);
        while let Some(&x) = stack.last() {
            if self.known(x).is_some() {
                stack.pop();
                continue;
            }
            let parents = store.group_parents(x);
            let value = if parents.is_empty() {
                Some(self.group_resident(store, cache, x))
            } else {
                let mut pending = false;
                let mut value = true;
                for &p in parents {
                    if p <= x || p as usize >= self.group_stamp.len() {
                        value = false; // broken link: never reached from a valid store
                        continue;
                    }
                    match self.known(p) {
                        Some(a) => value &= a,
                        None => {
                            stack.push(p);
                            pending = true;
                        }
                    }
                }
                if pending {
                    None
                } else {
                    Some(value && parents.iter().all(|&p| self.sources_resident(store, cache, p)))
                }
            };
            if let Some(v) = value {
                self.group_stamp[x as usize] = self.frame;
                self.group_avail[x as usize] = v;
                stack.pop();
            }
        }
        self.stack = stack;
        self.group_avail[g as usize]
    }

    /// Adds to `out` the missing pages that keep group `g` from being available (see the
    /// module documentation), each with the priority of the group that needs it under
    /// `metric`. Each group is walked at most once per frame.
    pub fn request_for(
        &mut self,
        store: &Store,
        cache: &PageCache,
        metric: &LodMetric,
        g: u32,
        out: &mut Requests,
    ) {
        let mut stack = vec![g];
        while let Some(x) = stack.pop() {
            let Some(slot) = self.walk_stamp.get_mut(x as usize) else { continue };
            if *slot == self.frame {
                continue;
            }
            *slot = self.frame;
            self.request_group(store, cache, metric, x, out);
            for &p in store.group_parents(x) {
                if p <= x {
                    continue;
                }
                for &s in store.group_sources(p) {
                    self.request_group(store, cache, metric, s, out);
                }
                if !self.available(store, cache, p) {
                    stack.push(p);
                }
            }
        }
    }

    /// Requests the page of group `g` if it is missing (not resident, not failed).
    fn request_group(
        &mut self,
        store: &Store,
        cache: &PageCache,
        metric: &LodMetric,
        g: u32,
        out: &mut Requests,
    ) {
        let Some(grp) = store.groups().get(g as usize) else { return };
        if matches!(self.snap(cache, grp.page), Snap::Missing) {
            out.add(grp.page, metric.sphere(grp.error, grp.sphere) as f32);
        }
    }
}
