//! Binned SAH construction with spatial splits over triangle references (Stich, Friedrich &
//! Dietrich 2009, "Spatial Splits in Bounding Volume Hierarchies", the SBVH).
//!
//! The object-split builder in `build.rs` puts every triangle in exactly one leaf, so a long
//! thin triangle (a CAD part's side, a board's face) widens every box it lands in, and boxes of
//! neighbouring parts overlap. Here the builder works on references: a triangle and the box of
//! the part of it a subtree covers. At each node it takes the cheaper of the usual binned object
//! split (section 4.1 of the paper) and a spatial split (section 4.2): bins over the node's box,
//! each reference clipped to the bins it spans, and the plane with the lowest SAH cost; the
//! references that straddle that plane go to both sides with their boxes clipped to each side,
//! unless keeping one on a single side costs less ("reference unsplitting", section 4.4).
//! Spatial splits are tried only where the object split's children overlap by more than a
//! fraction of the root's area (section 4.3), and the duplicates a subtree may create are a
//! budget handed down to the children in proportion to their sizes, so the build is
//! deterministic and its memory bounded.
//!
//! Clipped boxes are conservative: the points where triangle edges cross a plane are widened
//! by a few ulps off the split axis and the result is intersected with the reference's box, so
//! every point of a triangle lies in the box of some leaf that holds it (the traversal's robust
//! box test then never loses a hit).

use glam::Vec3;

use crate::aabb::Aabb;
use crate::build::{
    bin_mapping, bin_of, fill_bins, suffix_sums, BuildNode, BuildOptions, BINS, MEDIAN_DEPTH, PARALLEL_MIN,
};

/// Spatial bins per axis.
const SPATIAL_BINS: usize = 32;

/// Knobs of the spatial splits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialSplits {
    /// The most references the build may add, as a fraction of the triangle count (Embree's
    /// default allows 20 % more).
    pub budget: f32,
    /// Spatial splits are tried at a node when its best object split's children overlap by more
    /// than this fraction of the root's surface area (the paper's α, 10⁻⁵).
    pub min_overlap: f32,
}

impl Default for SpatialSplits {
    fn default() -> SpatialSplits {
        SpatialSplits { budget: 0.2, min_overlap: 1e-5 }
    }
}

/// A triangle and the box of the part of it that one subtree holds.
#[derive(Clone, Copy, Debug)]
struct Ref {
    prim: u32,
    bounds: Aabb,
}

impl Ref {
    fn centroid(&self) -> Vec3 {
        let c = self.bounds.centroid();
        if c.is_finite() {
            c
        } else {
            Vec3::ZERO
        }
    }

    /// Empty or non-finite boxes (degenerate input) are never split: they only follow the
    /// object splits.
    fn splittable(&self) -> bool {
        !self.bounds.is_empty() && self.bounds.min.is_finite() && self.bounds.max.is_finite()
    }
}

/// A node of the reference tree; leaves keep their triangles until the tree is linearized.
enum RefNode {
    Leaf { bounds: Aabb, prims: Box<[u32]> },
    Inner { bounds: Aabb, children: Box<[RefNode; 2]> },
}

/// Read-only inputs shared by all recursive steps.
struct Ctx<'a> {
    tris: &'a [[Vec3; 3]],
    max_leaf: usize,
    traversal_cost: f32,
    block_size: u32,
    /// Overlap (half area) above which spatial splits are tried.
    min_overlap_area: f32,
}

impl Ctx<'_> {
    /// The SAH's cost count of `n` references: blocks, rounded up (see `BuildOptions`).
    fn blocks(&self, n: u32) -> f32 {
        n.div_ceil(self.block_size) as f32
    }
}

/// Builds the binary tree over triangles `tris` (`boxes[i]` the box of `tris[i]`) with spatial
/// splits; returns it (`None` for no triangles) and the triangle order its leaves index into,
/// in which a split triangle appears once per leaf that holds part of it.
pub(crate) fn build_binary_spatial(
    tris: &[[Vec3; 3]],
    boxes: &[Aabb],
    options: &BuildOptions,
    splits: &SpatialSplits,
) -> (Option<BuildNode>, Vec<u32>) {
    let refs: Vec<Ref> =
        boxes.iter().enumerate().map(|(i, &bounds)| Ref { prim: i as u32, bounds }).collect();
    if refs.is_empty() {
        return (None, Vec::new());
    }
    let root_bounds = refs.iter().filter(|r| r.splittable()).fold(Aabb::EMPTY, |b, r| b.union(r.bounds));
    let ctx = Ctx {
        tris,
        max_leaf: options.max_leaf_size.clamp(1, 16),
        traversal_cost: options.traversal_cost.max(0.0),
        block_size: options.block_size.clamp(1, 16) as u32,
        min_overlap_area: splits.min_overlap.max(0.0) * root_bounds.half_area(),
    };
    let budget = (splits.budget.max(0.0) as f64 * refs.len() as f64) as usize;
    let root = build_node(&ctx, refs, budget, 0);
    let mut order = Vec::new();
    let root = linearize(root, &mut order);
    (Some(root), order)
}

/// Builds the subtree over `refs`, which may add at most `budget` references.
fn build_node(ctx: &Ctx, refs: Vec<Ref>, budget: usize, depth: u32) -> RefNode {
    let (bounds, cbounds) = ref_bounds(&refs);
    let n = refs.len();
    if n == 1 {
        return leaf(bounds, &refs);
    }
    let (left, right) = if depth >= MEDIAN_DEPTH {
        median_split(refs, &cbounds)
    } else {
        let object = object_split(&refs, &cbounds, ctx);
        let spatial = match object {
            Some(o) if budget > 0 && o.overlap > ctx.min_overlap_area => spatial_split(&refs, &bounds, ctx),
            _ => None,
        };
        let best = object
            .map(|o| o.cost)
            .into_iter()
            .chain(spatial.as_ref().map(|s| s.cost))
            .fold(f32::INFINITY, f32::min);
        let area = bounds.half_area();
        let split_cost = if area > 0.0 { ctx.traversal_cost + best / area } else { f32::INFINITY };
        if n <= ctx.max_leaf && !(best.is_finite() && split_cost < ctx.blocks(n as u32)) {
            return leaf(bounds, &refs);
        }
        match (object, spatial) {
            (_, Some(s)) if s.cost < object.map_or(f32::INFINITY, |o| o.cost) => {
                match apply_spatial(ctx, refs, &s, budget) {
                    Ok(sides) => sides,
                    Err(refs) => object_or_median(refs, &cbounds, object),
                }
            }
            _ => object_or_median(refs, &cbounds, object),
        }
    };
    // The budget left after this node's duplicates, shared in proportion to the sides' sizes.
    let spent = (left.len() + right.len()).saturating_sub(n);
    let rest = budget.saturating_sub(spent);
    let left_budget = (rest as u64 * left.len() as u64 / (left.len() + right.len()) as u64) as usize;
    let right_budget = rest - left_budget;
    let (l, r) = if n >= PARALLEL_MIN {
        rayon::join(
            || build_node(ctx, left, left_budget, depth + 1),
            || build_node(ctx, right, right_budget, depth + 1),
        )
    } else {
        (build_node(ctx, left, left_budget, depth + 1), build_node(ctx, right, right_budget, depth + 1))
    };
    RefNode::Inner { bounds, children: Box::new([l, r]) }
}

fn leaf(bounds: Aabb, refs: &[Ref]) -> RefNode {
    RefNode::Leaf { bounds, prims: refs.iter().map(|r| r.prim).collect() }
}

/// The union of the references' boxes and the box of their centroids.
fn ref_bounds(refs: &[Ref]) -> (Aabb, Aabb) {
    refs.iter().fold((Aabb::EMPTY, Aabb::EMPTY), |(b, c), r| (b.union(r.bounds), c.grown(r.centroid())))
}

/// The best object split: references whose centroids fall in bins `< bin` along `axis` go left.
#[derive(Clone, Copy)]
struct ObjectSplit {
    cost: f32,
    axis: usize,
    bin: usize,
    /// Half area of the intersection of the two sides' boxes.
    overlap: f32,
}

/// The cheapest binned object split over the three axes (as `build::sah_split`), or `None`
/// when the centroids coincide.
fn object_split(refs: &[Ref], cbounds: &Aabb, ctx: &Ctx) -> Option<ObjectSplit> {
    let mut best: Option<ObjectSplit> = None;
    for axis in 0..3 {
        let (lo, scale) = bin_mapping(cbounds, axis);
        if scale == 0.0 {
            continue;
        }
        let (counts, boxes) = fill_bins(refs.iter().map(|r| (r.centroid()[axis], r.bounds)), lo, scale);
        let (right_box, right_n) = suffix_sums(&boxes, &counts);
        let (mut lb, mut ln) = (Aabb::EMPTY, 0u32);
        for k in 1..BINS {
            lb = lb.union(boxes[k - 1]);
            ln += counts[k - 1];
            let cost = lb.half_area() * ctx.blocks(ln) + right_box[k].half_area() * ctx.blocks(right_n[k]);
            if best.is_none_or(|b| cost < b.cost) {
                let overlap = intersection(&lb, &right_box[k]).half_area();
                best = Some(ObjectSplit { cost, axis, bin: k, overlap });
            }
        }
    }
    best.filter(|b| b.cost.is_finite())
}

fn intersection(a: &Aabb, b: &Aabb) -> Aabb {
    Aabb::new(a.min.max(b.min), a.max.min(b.max))
}

/// Partitions by the object split, or at the median when it is missing or leaves a side empty.
fn object_or_median(refs: Vec<Ref>, cbounds: &Aabb, object: Option<ObjectSplit>) -> (Vec<Ref>, Vec<Ref>) {
    if let Some(o) = object {
        let (lo, scale) = bin_mapping(cbounds, o.axis);
        let (left, right): (Vec<Ref>, Vec<Ref>) =
            refs.iter().partition(|r| bin_of(r.centroid()[o.axis], lo, scale) < o.bin);
        if !left.is_empty() && !right.is_empty() {
            return (left, right);
        }
    }
    median_split(refs, cbounds)
}

/// Halves the references at the median centroid along the widest centroid axis.
fn median_split(mut refs: Vec<Ref>, cbounds: &Aabb) -> (Vec<Ref>, Vec<Ref>) {
    let axis = (cbounds.max - cbounds.min).max_position();
    let mid = refs.len() / 2;
    refs.select_nth_unstable_by(mid, |a, b| a.centroid()[axis].total_cmp(&b.centroid()[axis]));
    let right = refs.split_off(mid);
    (refs, right)
}

/// The best spatial split: the plane `plane` along `axis`, with the binned estimates of the
/// two sides (used again to decide which straddling references to unsplit).
struct SpatialSplit {
    cost: f32,
    axis: usize,
    plane: f32,
    left: Aabb,
    right: Aabb,
    left_n: u32,
    right_n: u32,
}

/// The bin planes of a spatial split along one axis of the node's box.
struct Planes {
    lo: f32,
    width: f32,
}

impl Planes {
    /// `None` when the box is flat (or unbounded) along the axis.
    fn new(bounds: &Aabb, axis: usize) -> Option<Planes> {
        let (lo, hi) = (bounds.min[axis], bounds.max[axis]);
        let width = (hi - lo) / SPATIAL_BINS as f32;
        (width > 0.0 && width.is_finite()).then_some(Planes { lo, width })
    }

    /// The plane between bins `k - 1` and `k`.
    fn plane(&self, k: usize) -> f32 {
        self.lo + k as f32 * self.width
    }

    /// The bin holding coordinate `x`.
    fn bin(&self, x: f32) -> usize {
        (((x - self.lo) / self.width) as usize).min(SPATIAL_BINS - 1)
    }
}

/// The cheapest spatial split over the three axes (section 4.2 of the paper): each reference
/// is clipped to every bin it spans, its entry counted in its first bin and its exit in its
/// last; a plane's left side holds the entries before it, its right side the exits after it.
fn spatial_split(refs: &[Ref], bounds: &Aabb, ctx: &Ctx) -> Option<SpatialSplit> {
    let mut best: Option<SpatialSplit> = None;
    let longest =
        refs.iter().filter(|r| r.splittable()).fold(Vec3::ZERO, |m, r| m.max(r.bounds.max - r.bounds.min));
    for axis in 0..3 {
        let Some(planes) = Planes::new(bounds, axis) else { continue };
        // With no reference longer than a bin, a spatial split would cut only the few that
        // happen to straddle its plane: it can barely beat the object split, so skip the axis
        // (this keeps builds of finely tessellated models like scans close to object-split
        // build times).
        if longest[axis] <= planes.width {
            continue;
        }
        let mut boxes = [Aabb::EMPTY; SPATIAL_BINS];
        let mut entries = [0u32; SPATIAL_BINS];
        let mut exits = [0u32; SPATIAL_BINS];
        for r in refs.iter().filter(|r| r.splittable()) {
            let (first, last) = (planes.bin(r.bounds.min[axis]), planes.bin(r.bounds.max[axis]));
            entries[first] += 1;
            exits[last.max(first)] += 1;
            let mut rest = r.bounds;
            for k in first..last {
                let (l, r) = split_reference(&ctx.tris[r.prim as usize], &rest, axis, planes.plane(k + 1));
                boxes[k] = boxes[k].union(l);
                rest = r;
            }
            boxes[last.max(first)] = boxes[last.max(first)].union(rest);
        }
        let (right_box, right_n) = suffix_sums(&boxes, &exits);
        let (mut lb, mut ln) = (Aabb::EMPTY, 0u32);
        for k in 1..SPATIAL_BINS {
            lb = lb.union(boxes[k - 1]);
            ln += entries[k - 1];
            let rb = right_box[k];
            let cost = lb.half_area() * ctx.blocks(ln) + rb.half_area() * ctx.blocks(right_n[k]);
            if ln > 0 && right_n[k] > 0 && best.as_ref().is_none_or(|b| cost < b.cost) {
                best = Some(SpatialSplit {
                    cost,
                    axis,
                    plane: planes.plane(k),
                    left: lb,
                    right: rb,
                    left_n: ln,
                    right_n: right_n[k],
                });
            }
        }
    }
    best.filter(|b| b.cost.is_finite())
}

/// Partitions `refs` by the spatial split `s`: references on one side of the plane go there,
/// straddling ones are clipped into both sides or, where cheaper, kept whole on one (section
/// 4.4). Hands `refs` back when the split would add more references than `budget` or would
/// not shrink both sides (the caller then takes the object split).
fn apply_spatial(
    ctx: &Ctx,
    refs: Vec<Ref>,
    s: &SpatialSplit,
    budget: usize,
) -> Result<(Vec<Ref>, Vec<Ref>), Vec<Ref>> {
    let (axis, plane) = (s.axis, s.plane);
    let (mut left, mut right) = (Vec::new(), Vec::new());
    let (nl, nr) = (s.left_n as f32, s.right_n as f32);
    let split_cost = s.left.half_area() * nl + s.right.half_area() * nr;
    for r in &refs {
        if !r.splittable() || r.bounds.max[axis] <= plane {
            left.push(*r);
        } else if r.bounds.min[axis] >= plane {
            right.push(*r);
        } else {
            let only_left = s.left.union(r.bounds).half_area() * nl + s.right.half_area() * (nr - 1.0);
            let only_right = s.left.half_area() * (nl - 1.0) + s.right.union(r.bounds).half_area() * nr;
            if only_left < split_cost && only_left <= only_right {
                left.push(*r);
            } else if only_right < split_cost {
                right.push(*r);
            } else {
                let (l, rb) = split_reference(&ctx.tris[r.prim as usize], &r.bounds, axis, plane);
                left.push(Ref { prim: r.prim, bounds: l });
                right.push(Ref { prim: r.prim, bounds: rb });
            }
        }
    }
    let n = refs.len();
    let fits = left.len() + right.len() <= n + budget;
    match fits && !left.is_empty() && !right.is_empty() && left.len() < n && right.len() < n {
        true => Ok((left, right)),
        false => Err(refs),
    }
}

/// The boxes of the parts of triangle `tri` on either side of the plane `axis = plane`, each
/// intersected with `bounds` (the reference's box, which holds the part being split).
///
/// Conservative: an edge's crossing point is computed by interpolation, which may round a few
/// ulps off the true line, so it is widened by a relative 2⁻²⁰ (about 8 ulps) off the split
/// axis; on the split axis the plane itself bounds both sides.
pub(crate) fn split_reference(tri: &[Vec3; 3], bounds: &Aabb, axis: usize, plane: f32) -> (Aabb, Aabb) {
    let (mut left, mut right) = (Aabb::EMPTY, Aabb::EMPTY);
    for i in 0..3 {
        let (a, b) = (tri[i], tri[(i + 1) % 3]);
        let (da, db) = (a[axis], b[axis]);
        if da <= plane {
            left = left.grown(a);
        }
        if da >= plane {
            right = right.grown(a);
        }
        if (da < plane && plane < db) || (db < plane && plane < da) {
            let t = ((plane - da) / (db - da)).clamp(0.0, 1.0);
            let mut p = a + (b - a) * t;
            p[axis] = plane;
            let mut margin =
                a.abs().max(b.abs()) * (1.0 / (1u32 << 20) as f32) + Vec3::splat(f32::MIN_POSITIVE);
            margin[axis] = 0.0;
            let crossing = Aabb::new(p - margin, p + margin);
            left = left.union(crossing);
            right = right.union(crossing);
        }
    }
    left.max[axis] = left.max[axis].min(plane);
    right.min[axis] = right.min[axis].max(plane);
    (intersection(&left, bounds), intersection(&right, bounds))
}

/// Turns the reference tree into the builder's binary tree, appending each leaf's triangles to
/// `order` (near leaves first, as `build_binary` lays them out).
fn linearize(node: RefNode, order: &mut Vec<u32>) -> BuildNode {
    match node {
        RefNode::Leaf { bounds, prims } => {
            let first = order.len() as u32;
            order.extend_from_slice(&prims);
            BuildNode::Leaf { bounds, first, count: prims.len() as u32 }
        }
        RefNode::Inner { bounds, children } => {
            let [l, r] = *children;
            let l = linearize(l, order);
            let r = linearize(r, order);
            BuildNode::Inner { bounds, children: Box::new([l, r]) }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f32, y: f32, z: f32) -> Vec3 {
        Vec3::new(x, y, z)
    }

    #[test]
    fn split_reference_bounds_both_parts() {
        let tri = [v(0.0, 0.0, 0.0), v(4.0, 0.0, 0.0), v(0.0, 4.0, 2.0)];
        let whole = Aabb::from_points(&tri);
        let (l, r) = split_reference(&tri, &whole, 0, 1.0);
        // Left: x in [0, 1]; the crossings (1, 0, 0) and (1, 3, 1.5) widen y and z slightly.
        assert_eq!(l.min.x, 0.0);
        assert_eq!(l.max.x, 1.0);
        assert_eq!(l.max.y, 4.0);
        // Right: x in [1, 4]; y up to 3 and z up to 1.5 (plus the margin).
        assert_eq!(r.min.x, 1.0);
        assert_eq!(r.max.x, 4.0);
        assert!(r.max.y >= 3.0 && r.max.y < 3.0001, "{r:?}");
        assert!(r.max.z >= 1.5 && r.max.z < 1.5001, "{r:?}");
        assert!(whole.contains(&l) && whole.contains(&r));
    }

    #[test]
    fn split_reference_on_one_side_leaves_the_other_empty() {
        let tri = [v(2.0, 0.0, 0.0), v(3.0, 0.0, 0.0), v(2.0, 1.0, 0.0)];
        let whole = Aabb::from_points(&tri);
        let (l, r) = split_reference(&tri, &whole, 0, 1.0);
        assert!(l.is_empty());
        assert_eq!(r, whole);
    }

    #[test]
    fn long_triangles_are_split_within_budget() {
        // Long diagonal slivers crossing each other over a field of small triangles: any object
        // split leaves their boxes overlapping, so the spatial splits must cut them.
        let mut tris = Vec::new();
        for i in 0..64 {
            let y = i as f32 * 1.5;
            tris.push([v(0.0, y, 0.5), v(96.0, 96.0 - y, 0.5), v(0.0, y + 0.5, 0.5)]);
        }
        for i in 0..512 {
            let (x, y) = ((i % 32) as f32 * 3.0, (i / 32) as f32 * 4.0);
            tris.push([v(x, y, 1.0), v(x + 1.0, y, 1.0), v(x, y + 1.0, 1.0)]);
        }
        let boxes: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(t)).collect();
        let options = BuildOptions { max_leaf_size: 4, block_size: 4, traversal_cost: 1.0 };
        let splits = SpatialSplits::default();
        let (root, order) = build_binary_spatial(&tris, &boxes, &options, &splits);
        assert!(root.is_some());
        assert!(order.len() > tris.len(), "no reference was split");
        assert!(order.len() <= tris.len() + (splits.budget * tris.len() as f32) as usize);
        let none = SpatialSplits { budget: 0.0, ..splits };
        assert_eq!(build_binary_spatial(&tris, &boxes, &options, &none).1.len(), tris.len());
    }
}
