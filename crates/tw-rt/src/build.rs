//! Binned SAH construction of a binary BVH over primitive boxes (Wald 2007, "On fast
//! Construction of SAH-based Bounding Volume Hierarchies"): at each node the primitives'
//! centroids are binned along each axis, the split plane with the lowest surface area cost is
//! taken, and the index range is partitioned in place. Subtrees of large nodes are built in
//! parallel with rayon. The binary tree is only an intermediate: `wide.rs` collapses it
//! into the wide nodes that traversal uses.

use glam::Vec3;

use crate::aabb::Aabb;

/// Centroid bins per axis.
pub(crate) const BINS: usize = 32;
/// Nodes with at least this many primitives build their two subtrees in parallel.
pub(crate) const PARALLEL_MIN: usize = 8 * 1024;
/// Below this depth the builder takes SAH splits; at and beyond it, median splits (which halve
/// the count), so no binary tree is deeper than `MEDIAN_DEPTH + 32` for `u32` counts.
pub(crate) const MEDIAN_DEPTH: u32 = 40;
/// The deepest a binary (and so any collapsed wide) tree can be; traversal stacks are sized by it.
pub(crate) const MAX_DEPTH: u32 = MEDIAN_DEPTH + 33;

/// Knobs of the SAH build.
#[derive(Clone, Copy, Debug)]
pub struct BuildOptions {
    /// Most primitives in one leaf (1 to 16).
    pub max_leaf_size: usize,
    /// Cost of visiting an inner node relative to intersecting one block of primitives.
    pub traversal_cost: f32,
    /// Primitives intersected together (SIMD lanes): the SAH counts a side of `n` primitives as
    /// `ceil(n / block_size)` blocks, since a part-filled block costs as much as a full one.
    /// With 1, leaves of 4 triangles tested as one 4-wide group held 1.8 triangles on average.
    pub block_size: usize,
}

impl Default for BuildOptions {
    fn default() -> BuildOptions {
        BuildOptions { max_leaf_size: 4, traversal_cost: 1.0, block_size: 1 }
    }
}

/// A node of the intermediate binary tree.
pub(crate) enum BuildNode {
    /// `prim_indices[first..first + count]`.
    Leaf {
        bounds: Aabb,
        first: u32,
        count: u32,
    },
    Inner {
        bounds: Aabb,
        children: Box<[BuildNode; 2]>,
    },
}

impl BuildNode {
    pub fn bounds(&self) -> Aabb {
        match self {
            BuildNode::Leaf { bounds, .. } | BuildNode::Inner { bounds, .. } => *bounds,
        }
    }
}

/// Read-only inputs shared by all recursive steps.
struct Ctx<'a> {
    boxes: &'a [Aabb],
    centroids: Vec<Vec3>,
    max_leaf: usize,
    traversal_cost: f32,
    block_size: u32,
}

impl Ctx<'_> {
    /// The SAH's cost count of `n` primitives: blocks, rounded up.
    fn blocks(&self, n: u32) -> f32 {
        n.div_ceil(self.block_size) as f32
    }
}

/// Builds the binary tree; returns it (`None` for no primitives) and the primitive order its
/// leaves index into.
pub(crate) fn build_binary(boxes: &[Aabb], options: &BuildOptions) -> (Option<BuildNode>, Vec<u32>) {
    let mut indices: Vec<u32> = (0..boxes.len() as u32).collect();
    if boxes.is_empty() {
        return (None, indices);
    }
    let ctx = Ctx {
        boxes,
        centroids: boxes.iter().map(robust_centroid).collect(),
        max_leaf: options.max_leaf_size.clamp(1, 16),
        traversal_cost: options.traversal_cost.max(0.0),
        block_size: options.block_size.clamp(1, 16) as u32,
    };
    let root = build_range(&ctx, &mut indices, 0, 0);
    (Some(root), indices)
}

/// The centroid of a box, or the origin for an empty or non-finite one (such primitives can
/// never be hit, and a NaN centroid would poison the binning).
fn robust_centroid(b: &Aabb) -> Vec3 {
    let c = b.centroid();
    if c.is_finite() {
        c
    } else {
        Vec3::ZERO
    }
}

/// Builds the subtree over `indices`, whose first element sits at `offset` in the final order.
fn build_range(ctx: &Ctx, indices: &mut [u32], offset: u32, depth: u32) -> BuildNode {
    let (bounds, cbounds) = range_bounds(ctx, indices);
    let n = indices.len();
    let leaf = || BuildNode::Leaf { bounds, first: offset, count: n as u32 };
    if n == 1 {
        return leaf();
    }
    let mid = if depth >= MEDIAN_DEPTH {
        median_split(ctx, indices, &cbounds)
    } else {
        match sah_split(ctx, indices, &bounds, &cbounds) {
            SahChoice::Leaf if n <= ctx.max_leaf => return leaf(),
            SahChoice::Split { axis, bin } => partition(ctx, indices, &cbounds, axis, bin),
            _ => 0,
        }
    };
    // A split that leaves one side empty (all centroids in one bin) falls back to the median.
    let mid = if mid == 0 || mid == n { median_split(ctx, indices, &cbounds) } else { mid };
    let (left, right) = indices.split_at_mut(mid);
    let right_offset = offset + mid as u32;
    let (l, r) = if n >= PARALLEL_MIN {
        rayon::join(
            || build_range(ctx, left, offset, depth + 1),
            || build_range(ctx, right, right_offset, depth + 1),
        )
    } else {
        (build_range(ctx, left, offset, depth + 1), build_range(ctx, right, right_offset, depth + 1))
    };
    BuildNode::Inner { bounds, children: Box::new([l, r]) }
}

/// The union of the primitives' boxes and the box of their centroids.
fn range_bounds(ctx: &Ctx, indices: &[u32]) -> (Aabb, Aabb) {
    let mut b = Aabb::EMPTY;
    let mut c = Aabb::EMPTY;
    for &i in indices {
        b = b.union(ctx.boxes[i as usize]);
        c = c.grown(ctx.centroids[i as usize]);
    }
    (b, c)
}

enum SahChoice {
    Leaf,
    /// Primitives in bins `< bin` go left.
    Split {
        axis: usize,
        bin: usize,
    },
}

/// The cheapest binned split over all three axes, or `Leaf` when no split beats a leaf.
fn sah_split(ctx: &Ctx, indices: &[u32], bounds: &Aabb, cbounds: &Aabb) -> SahChoice {
    let mut best = (f32::INFINITY, 0, 0);
    for axis in 0..3 {
        let (lo, scale) = bin_mapping(cbounds, axis);
        if scale == 0.0 {
            continue;
        }
        let items = indices.iter().map(|&i| (ctx.centroids[i as usize][axis], ctx.boxes[i as usize]));
        let (counts, boxes) = fill_bins(items, lo, scale);
        // The right side of every plane, then a sweep from the left.
        let (right_box, right_n) = suffix_sums(&boxes, &counts);
        let (mut lb, mut ln) = (Aabb::EMPTY, 0u32);
        for k in 1..BINS {
            lb = lb.union(boxes[k - 1]);
            ln += counts[k - 1];
            let cost = lb.half_area() * ctx.blocks(ln) + right_box[k].half_area() * ctx.blocks(right_n[k]);
            if cost < best.0 {
                best = (cost, axis, k);
            }
        }
    }
    let area = bounds.half_area();
    let leaf_cost = ctx.blocks(indices.len() as u32);
    let split_cost = if area > 0.0 { ctx.traversal_cost + best.0 / area } else { f32::INFINITY };
    if best.0.is_finite() && (split_cost < leaf_cost || indices.len() > ctx.max_leaf) {
        SahChoice::Split { axis: best.1, bin: best.2 }
    } else {
        SahChoice::Leaf
    }
}

/// `(lower end, bins per unit)` of the centroid bins along `axis` (scale 0: flat extent).
pub(crate) fn bin_mapping(cbounds: &Aabb, axis: usize) -> (f32, f32) {
    let lo = cbounds.min[axis];
    let extent = cbounds.max[axis] - lo;
    if extent > 0.0 && extent.is_finite() {
        (lo, BINS as f32 * (1.0 - 1e-6) / extent)
    } else {
        (lo, 0.0)
    }
}

pub(crate) fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// Per centroid bin ([`bin_of`]): how many of `items` (centroid along the axis, box) fall in it
/// and the union of their boxes.
pub(crate) fn fill_bins(
    items: impl Iterator<Item = (f32, Aabb)>,
    lo: f32,
    scale: f32,
) -> ([u32; BINS], [Aabb; BINS]) {
    let mut counts = [0u32; BINS];
    let mut boxes = [Aabb::EMPTY; BINS];
    for (c, b) in items {
        let k = bin_of(c, lo, scale);
        counts[k] += 1;
        boxes[k] = boxes[k].union(b);
    }
    (counts, boxes)
}

/// `(union of boxes[k..], sum of counts[k..])` for every `k`: the right side of each plane.
pub(crate) fn suffix_sums<const B: usize>(boxes: &[Aabb; B], counts: &[u32; B]) -> ([Aabb; B], [u32; B]) {
    let mut sb = [Aabb::EMPTY; B];
    let mut sn = [0u32; B];
    let (mut b, mut n) = (Aabb::EMPTY, 0);
    for k in (0..B).rev() {
        b = b.union(boxes[k]);
        n += counts[k];
        (sb[k], sn[k]) = (b, n);
    }
    (sb, sn)
}

/// Moves the primitives of bins `< bin` to the front; returns how many there are.
fn partition(ctx: &Ctx, indices: &mut [u32], cbounds: &Aabb, axis: usize, bin: usize) -> usize {
    let (lo, scale) = bin_mapping(cbounds, axis);
    let goes_left = |i: u32| bin_of(ctx.centroids[i as usize][axis], lo, scale) < bin;
    let (mut a, mut b) = (0, indices.len());
    while a < b {
        if goes_left(indices[a]) {
            a += 1;
        } else {
            b -= 1;
            indices.swap(a, b);
        }
    }
    a
}

/// Splits at the median centroid along the widest centroid axis; returns `len / 2`.
fn median_split(ctx: &Ctx, indices: &mut [u32], cbounds: &Aabb) -> usize {
    let axis = (cbounds.max - cbounds.min).max_position();
    let mid = indices.len() / 2;
    let key = |i: &u32| ctx.centroids[*i as usize][axis];
    indices.select_nth_unstable_by(mid, |a, b| key(a).total_cmp(&key(b)));
    mid
}
