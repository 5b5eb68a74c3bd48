//! Partition-I: objects with more than `t1` triangles whose box is too large or too uneven are
//! split, between their part groups when ingest found them (`crate::parts`), else by planes
//! planned from their samples (GigaWalk §4.2; see the parent module).

use super::assign::{Assigner, KdNode, ObjectRoute, PartRoute};
use super::geometry::{aspect, axes_by_extent, diag, next_up, partition_in_place, FBox, Scale};
use super::samples::Samples;
use super::{RedefineParams, RedefineReport};
use crate::ingest::Ingested;

/// The state of partition-I's recursive split of one object: its kd plan grows in `kd`, its
/// pieces are appended to `piece_object`.
struct P1<'a> {
    p: &'a RedefineParams,
    scale: &'a Scale,
    kd: &'a mut Vec<KdNode>,
    piece_object: &'a mut Vec<u32>,
    object: u32,
}

/// Picks a plane for `pts`: along the axes by decreasing extent, the widest gap between
/// consecutive centroids among the splits that leave at least a quarter of the points on each
/// side (ties: the one nearest the median); an axis where all of the middle half coincide is
/// skipped; if no axis has such a gap, the most balanced non-empty split at the median.
/// Reorders `pts` so that the left side comes first; returns (axis, pos, left count).
///
/// Why a gap rather than the median: a plane cuts every part whose triangles' centroids lie on
/// both sides, and a cut part has seams that the LOD must lock up to HLOD. CAD assemblies put
/// thousands of parts on one plane (a board's components sit on its surface, their bottom faces'
/// centroids all on it): the median of the centroids is then that plane, and splitting there cut
/// every part on the board (measured on a generated 12 M-triangle board stack: 93 % of the
/// vertices of some cells were locked seams, and 30 % of the cells' triangles never simplified).
/// The widest gap in the middle half falls between parts, boards or layers instead, and on
/// continuous geometry (a pipe) it is as good as the median.
pub(super) fn median_split(pts: &mut [[f32; 3]], ext: [f64; 3]) -> Option<(usize, f32, usize)> {
    let len = pts.len();
    let mut fallback: Option<(usize, f32, usize)> = None;
    let balance = |nl: usize| nl.min(len - nl);
    for axis in axes_by_extent(ext) {
        if let Some((pos, nl)) = widest_gap(pts, |c| c[axis], |_| 1.0) {
            return Some((axis, pos, nl));
        }
        let v = pts[len / 2][axis];
        for pos in [v, next_up(v)] {
            let nl = pts.iter().filter(|c| c[axis] < pos).count();
            if fallback.is_none_or(|b| balance(nl) > balance(b.2)) {
                fallback = Some((axis, pos, nl));
            }
        }
    }
    let (axis, pos, nl) = fallback?;
    if balance(nl) == 0 {
        return None;
    }
    partition_in_place(pts, |c| c[axis] < pos);
    Some((axis, pos, nl))
}

/// The split of `pts` along one coordinate at the widest gap between consecutive distinct
/// values that leaves at least a quarter of the total weight on each side (ties: the one whose
/// left weight is nearest half). Sorts `pts` by the coordinate; returns the plane (the first
/// value on the right, so that `c < pos` is the left side) and the left count, or `None` when
/// no such gap exists (the middle half coincides). See [`median_split`] for why a gap.
pub(super) fn widest_gap<T>(
    pts: &mut [T],
    coord: impl Fn(&T) -> f32,
    weight: impl Fn(&T) -> f64,
) -> Option<(f32, usize)> {
    pts.sort_by(|a, b| coord(a).total_cmp(&coord(b)));
    let total: f64 = pts.iter().map(&weight).sum();
    let (lo, hi) = (total / 4.0, total - total / 4.0);
    let mut left = 0.0f64;
    let mut best: Option<(f64, f64, usize)> = None; // (gap, distance from half, index)
    for i in 1..pts.len() {
        left += weight(&pts[i - 1]);
        if left > hi {
            break;
        }
        let (a, b) = (coord(&pts[i - 1]), coord(&pts[i]));
        if left < lo || b <= a {
            continue;
        }
        let gap = b as f64 - a as f64;
        let off = (left - total / 2.0).abs();
        if best.is_none_or(|(g, o, _)| gap > g || (gap == g && off < o)) {
            best = Some((gap, off, i));
        }
    }
    best.map(|(_, _, i)| (coord(&pts[i]), i))
}

impl P1<'_> {
    /// Plans the split of one node; returns its kd index.
    fn split(&mut self, pts: &mut [[f32; 3]], estimate: f64, ext: [f64; 3]) -> u32 {
        let p = self.p;
        let uneven = diag(ext) > self.scale.s1 || aspect(ext) > p.r1;
        if estimate > p.t1 as f64 && uneven && pts.len() >= 2 {
            if let Some((axis, pos, nl)) = median_split(pts, ext) {
                let node = self.kd.len() as u32;
                self.kd.push(KdNode::leaf(0));
                let (l, r) = pts.split_at_mut(nl);
                let per = estimate / (l.len() + r.len()) as f64;
                let a = self.split(l, per * l.len() as f64, points_ext(l));
                let b = self.split(r, per * r.len() as f64, points_ext(r));
                self.kd[node as usize] = KdNode { axis: axis as u8, pos, a, b };
                return node;
            }
        }
        let node = self.kd.len() as u32;
        self.kd.push(KdNode::leaf(self.piece_object.len() as u32));
        self.piece_object.push(self.object);
        node
    }
}

fn points_ext(pts: &[[f32; 3]]) -> [f64; 3] {
    let mut b = FBox::EMPTY;
    for &p in pts {
        b.grow(p);
    }
    b.ext()
}

/// Partition-I: plans every object's pieces; returns the object of each piece.
pub(super) fn partition_objects(
    ing: &Ingested,
    p: &RedefineParams,
    scale: &Scale,
    samples: &mut Samples,
    assign: &mut Assigner,
    report: &mut RedefineReport,
) -> Vec<u32> {
    let mut piece_object = Vec::with_capacity(ing.objects.len());
    assign.object_piece = vec![ObjectRoute::Fixed(u32::MAX); ing.objects.len()];
    for (o, rec) in ing.objects.iter().enumerate() {
        if rec.triangles == 0 {
            continue;
        }
        let ext = scale.grid_ext(&rec.bounds);
        let needs = rec.triangles > p.t1 && (diag(ext) > scale.s1 || aspect(ext) > p.r1);
        let first = piece_object.len() as u32;
        if needs && !rec.part_starts.is_empty() {
            // Between its parts rather than through them (crate::parts).
            assign.object_piece[o] = ObjectRoute::Parts(assign.parts.len() as u32);
            assign.parts.push(PartRoute::new(first, rec.span.clone(), rec.part_starts.clone()));
            piece_object.extend(std::iter::repeat_n(o as u32, rec.part_starts.len() + 1));
            report.split_objects += 1;
            continue;
        }
        if needs && samples.stride[o] > 0 {
            let pts = &mut samples.points[samples.start[o]..samples.start[o + 1]];
            let mut ctx =
                P1 { p, scale, kd: &mut assign.plan1, piece_object: &mut piece_object, object: o as u32 };
            let root = ctx.split(pts, rec.triangles as f64, ext);
            if piece_object.len() as u32 > first + 1 {
                assign.object_piece[o] = ObjectRoute::Plan(root);
                report.split_objects += 1;
                continue;
            }
            // Not split after all: forget the lone leaf.
            assign.plan1.truncate(root as usize);
            piece_object.truncate(first as usize);
        }
        assign.object_piece[o] = ObjectRoute::Fixed(first);
        piece_object.push(o as u32);
    }
    piece_object
}
