//! Single-ray traversal of the wide BVH: closest-child-first, with a short stack.
//!
//! Each visited node tests the ray against all `W` child boxes at once (the loop below is
//! written lane by lane so that the compiler maps it onto SIMD registers; compiled inside an
//! `avx2` entry point it uses one 8-wide register per plane). Hit children are pushed onto the
//! stack sorted by entry distance, the nearest continues at once, and entries farther than the
//! current hit are dropped when popped. Leaves are handed to a closure, so one traversal serves
//! both the triangle BVH and the generic [`crate::Bvh::traverse`].

use std::mem::MaybeUninit;

use crate::aabb::{max, min, SlabRay, ROBUST_FAR};
use crate::build::MAX_DEPTH;
use crate::wide::{WideNode, LEAF, W};

/// Stack entries needed: each level leaves at most `W - 1` siblings behind.
pub(crate) const STACK: usize = (MAX_DEPTH as usize + 1) * (W - 1) + 1;

/// Per-ray data for the node tests: which box side is the near one per axis (0: min, 1: max).
#[derive(Clone, Copy)]
pub(crate) struct NodeRay {
    pub origin: [f32; 3],
    pub inv: [f32; 3],
    pub near: [usize; 3],
}

impl NodeRay {
    #[inline(always)]
    pub fn new(s: &SlabRay) -> NodeRay {
        NodeRay { origin: s.origin, inv: s.inv, near: s.neg.map(|n| n as usize) }
    }
}

/// Entry distances of the `W` children and the mask of those the ray enters within
/// `[t_min, t_max]`.
#[inline(always)]
pub(crate) fn node_hits(node: &WideNode, r: &NodeRay, t_min: f32, t_max: f32) -> ([f32; W], u32) {
    let b = &node.bounds;
    // `& 1` lets the compiler see the side index is 0 or 1: no bounds checks below.
    let (nx_, ny_, nz_) = (&b[r.near[0] & 1][0], &b[r.near[1] & 1][1], &b[r.near[2] & 1][2]);
    let (fx_, fy_, fz_) =
        (&b[(r.near[0] ^ 1) & 1][0], &b[(r.near[1] ^ 1) & 1][1], &b[(r.near[2] ^ 1) & 1][2]);
    let mut near = [0.0f32; W];
    let mut hit = [false; W];
    for i in 0..W {
        let nx = (nx_[i] - r.origin[0]) * r.inv[0];
        let ny = (ny_[i] - r.origin[1]) * r.inv[1];
        let nz = (nz_[i] - r.origin[2]) * r.inv[2];
        let fx = (fx_[i] - r.origin[0]) * r.inv[0];
        let fy = (fy_[i] - r.origin[1]) * r.inv[1];
        let fz = (fz_[i] - r.origin[2]) * r.inv[2];
        // Candidates first, so a NaN (origin on a plane, direction 0) is ignored.
        let n = max(nx, max(ny, max(nz, t_min)));
        let f = min(fx, min(fy, min(fz, f32::INFINITY))) * ROBUST_FAR;
        near[i] = n;
        hit[i] = n <= min(f, t_max);
    }
    let mut mask = 0u32;
    for (i, h) in hit.iter().enumerate() {
        mask |= (*h as u32) << i;
    }
    (near, mask)
}

/// What a leaf visit tells the traversal.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Visit {
    Continue,
    /// Stop now (an occlusion query found a blocker).
    Stop,
}

/// Asks the cache for the memory of `item` ahead of use (all its cache lines). Children are
/// prefetched as soon as a node test finds them hit, so their loads overlap the work on their
/// siblings: node and leaf loads were the largest stalls on models larger than the caches.
#[inline(always)]
pub(crate) fn prefetch<T>(item: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let p = item as *const T as *const i8;
        for offset in (0..std::mem::size_of::<T>()).step_by(64) {
            // SAFETY: prefetching is a hint; the addresses lie inside `item`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.add(offset)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = item;
}

/// Prefetches the hit children of a node: inner nodes from `nodes`, leaves through `leaf`.
#[inline(always)]
pub(crate) fn prefetch_children(nodes: &[WideNode], child: &[u32; W], mut mask: u32, leaf: impl Fn(u32)) {
    while mask != 0 {
        let c = child[mask.trailing_zeros() as usize];
        mask &= mask - 1;
        if c & LEAF == 0 {
            if let Some(n) = nodes.get(c as usize) {
                prefetch(n);
            }
        } else {
            leaf(c & !LEAF);
        }
    }
}

/// The leaf handler of [`traverse`]. A trait with an `#[inline(always)]` method rather than a
/// closure: closures are not inlined into `#[target_feature]` callers reliably, and a leaf test
/// compiled without AVX2 and called per leaf cost a tenth of the time.
pub(crate) trait LeafVisitor {
    /// Tests leaf `leaf`; shrinks `t_max` on a hit.
    fn visit(&mut self, leaf: u32, t_max: &mut f32) -> Visit;

    /// Prefetches what [`LeafVisitor::visit`] will read for `leaf`.
    fn prefetch(&self, _leaf: u32) {}
}

/// The traversal stack: child references with their entry distances and a payload per entry
/// (packets keep the mask of rays that enter a leaf; single rays keep nothing). Never
/// zero-initialized (4 KB per ray was a measurable memset); only entries below `len` are read.
pub(crate) struct Stack<E: Copy = ()> {
    items: [MaybeUninit<(u32, f32, E)>; STACK],
    len: usize,
}

impl<E: Copy> Stack<E> {
    #[inline(always)]
    pub fn new() -> Stack<E> {
        Stack { items: [const { MaybeUninit::uninit() }; STACK], len: 0 }
    }

    /// Pushes the children in `mask` with their payloads sorted far to near, then pops and
    /// returns the nearest. `mask` must not be 0.
    #[inline(always)]
    pub fn push_sorted_pop_nearest(
        &mut self,
        child: &[u32; W],
        near: &[f32; W],
        extra: &[E; W],
        mut mask: u32,
    ) -> (u32, E) {
        let base = self.len;
        while mask != 0 {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let entry = (child[i], near[i], extra[i]);
            let mut j = self.len;
            // SAFETY: entries in `base..self.len` were written above.
            while j > base && unsafe { self.items[j - 1].assume_init() }.1 < entry.1 {
                self.items[j] = self.items[j - 1];
                j -= 1;
            }
            self.items[j] = MaybeUninit::new(entry);
            self.len += 1;
        }
        self.len -= 1;
        // SAFETY: written by the loop (the mask had at least one bit).
        let (c, _, e) = unsafe { self.items[self.len].assume_init() };
        (c, e)
    }

    /// Pops entries until one whose entry distance is at most `t_max`; `None` when empty.
    #[inline(always)]
    pub fn pop_within(&mut self, t_max: f32) -> Option<(u32, E)> {
        while self.len > 0 {
            self.len -= 1;
            // SAFETY: every entry below the old `len` was written by a push.
            let (c, t, e) = unsafe { self.items[self.len].assume_init() };
            if t <= t_max {
                return Some((c, e));
            }
        }
        None
    }
}

/// Walks the tree from node 0, handing every leaf the ray reaches (nearest first, roughly) to
/// `leaves`, which shrinks `t_max` when it finds a hit. Returns true when the visitor stopped
/// the walk.
#[inline(always)]
pub(crate) fn traverse<V: LeafVisitor>(
    nodes: &[WideNode],
    r: &NodeRay,
    t_min: f32,
    t_max: &mut f32,
    leaves: &mut V,
) -> bool {
    if nodes.is_empty() {
        return false;
    }
    let mut stack = Stack::<()>::new();
    let mut cur = 0u32;
    loop {
        if cur & LEAF == 0 {
            let node = &nodes[cur as usize];
            let (near, mask) = node_hits(node, r, t_min, *t_max);
            if mask != 0 {
                prefetch_children(nodes, &node.child, mask, |l| leaves.prefetch(l));
                cur = if mask & (mask - 1) == 0 {
                    node.child[mask.trailing_zeros() as usize]
                } else {
                    stack.push_sorted_pop_nearest(&node.child, &near, &[(); W], mask).0
                };
                continue;
            }
        } else if leaves.visit(cur & !LEAF, t_max) == Visit::Stop {
            return true;
        }
        match stack.pop_within(*t_max) {
            Some((c, ())) => cur = c,
            None => return false,
        }
    }
}
