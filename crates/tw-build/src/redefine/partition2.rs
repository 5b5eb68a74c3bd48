//! Partition-II: clusters with more than `t2` triangles that are too large or too uneven, and
//! clusters above `max_cell_triangles`, are split by planes about their centre of mass (see the
//! parent module).

use super::assign::{walk, Assigner, KdNode, ObjectRoute, Route, LEAF};
use super::cluster::Clusters;
use super::geometry::{aspect, axes_by_extent, diag, next_up, partition_in_place, FBox, Scale};
use super::partition1::widest_gap;
use super::pieces::Pieces;
use super::samples::Samples;
use super::{RedefineParams, RedefineReport};
use crate::ingest::Ingested;
use crate::types::GridBox;

/// A weighted point of a cluster: a whole piece (at its centre of mass, with its box) or a
/// sampled centroid of a large piece (`piece == u32::MAX`).
#[derive(Clone, Copy, Debug)]
struct WPoint {
    c: [f32; 3],
    w: f64,
    b: FBox,
    piece: u32,
}

/// The state of partition-II's recursive split of one cluster: its kd plan grows in `kd`, whole
/// pieces are placed in the cells it makes (`piece_cell`), numbered from `cells`.
struct P2<'a> {
    p: &'a RedefineParams,
    scale: &'a Scale,
    kd: &'a mut Vec<KdNode>,
    piece_cell: &'a mut Vec<Route>,
    cells: u32,
}

impl P2<'_> {
    fn split(&mut self, pts: &mut [WPoint]) -> u32 {
        let p = self.p;
        let total: f64 = pts.iter().map(|q| q.w).sum();
        let mut b = FBox::EMPTY;
        for q in pts.iter() {
            b.union(&q.b);
        }
        let ext = b.ext();
        let uneven = diag(ext) > self.scale.s2 || aspect(ext) > p.r2;
        let big = total > p.max_cell_triangles as f64 || (total > p.t2 as f64 && uneven);
        if big && pts.len() >= 2 {
            if let Some((axis, pos, nl)) = mass_split(pts, ext, total) {
                let node = self.kd.len() as u32;
                self.kd.push(KdNode::leaf(0));
                let (l, r) = pts.split_at_mut(nl);
                let a = self.split(l);
                let b = self.split(r);
                self.kd[node as usize] = KdNode { axis: axis as u8, pos, a, b };
                return node;
            }
        }
        let cell = self.cells;
        self.cells += 1;
        for q in pts.iter() {
            if q.piece != u32::MAX {
                self.piece_cell[q.piece as usize] = Route::Fixed(cell);
            }
        }
        let node = self.kd.len() as u32;
        self.kd.push(KdNode::leaf(cell));
        node
    }
}

/// A plane along the axes by decreasing extent: the widest gap between the points that leaves
/// at least a quarter of the weight on each side ([`widest_gap`]); where the middle half of an
/// axis coincides, about the centre of mass, or the weighted median when the centre of mass
/// leaves less than a quarter of the weight on one side.
fn mass_split(pts: &mut [WPoint], ext: [f64; 3], total: f64) -> Option<(usize, f32, usize)> {
    let left_weight = |pts: &[WPoint], axis: usize, pos: f32| -> f64 {
        pts.iter().filter(|q| q.c[axis] < pos).map(|q| q.w).sum()
    };
    let balance = |wl: f64| wl.min(total - wl);
    let mut best: Option<(usize, f32, f64)> = None;
    for axis in axes_by_extent(ext) {
        // Between parts rather than through them (median_split says why).
        if let Some((pos, nl)) = widest_gap(pts, |q| q.c[axis], |q| q.w) {
            return Some((axis, pos, nl));
        }
        let com = (pts.iter().map(|q| q.w * q.c[axis] as f64).sum::<f64>() / total) as f32;
        let mut candidates = vec![com];
        let wl = left_weight(pts, axis, com);
        if balance(wl) * 4.0 < total {
            pts.sort_by(|a, b| a.c[axis].total_cmp(&b.c[axis]));
            let mut acc = 0.0;
            let at = pts.iter().position(|q| {
                acc += q.w;
                acc * 2.0 >= total
            });
            if let Some(at) = at {
                let v = pts[at].c[axis];
                candidates.extend([v, next_up(v)]);
            }
        }
        for pos in candidates {
            let wl = left_weight(pts, axis, pos);
            if best.is_none_or(|b| balance(wl) > balance(b.2)) {
                best = Some((axis, pos, wl));
            }
        }
        if best.is_some_and(|b| balance(b.2) * 4.0 >= total) {
            break;
        }
    }
    let (axis, pos, wl) = best?;
    if balance(wl) <= 0.0 {
        return None;
    }
    let nl = partition_in_place(pts, |q| q.c[axis] < pos);
    (nl > 0 && nl < pts.len()).then_some((axis, pos, nl))
}

/// Partition-II over every cluster; fills `assign.piece_cell`; returns the number of cells.
#[allow(clippy::too_many_arguments)]
pub(super) fn partition_clusters(
    ing: &Ingested,
    p: &RedefineParams,
    scale: &Scale,
    samples: &Samples,
    pieces: &Pieces,
    clusters: &Clusters,
    assign: &mut Assigner,
    report: &mut RedefineReport,
) -> u32 {
    assign.piece_cell = vec![Route::Fixed(u32::MAX); pieces.count.len()];
    let by_piece = PieceSamples::new(ing, samples, assign, pieces.count.len());
    let mut ctx = P2 { p, scale, kd: &mut assign.plan2, piece_cell: &mut assign.piece_cell, cells: 0 };
    let mut pts: Vec<WPoint> = Vec::new();
    for c in 0..clusters.start.len() - 1 {
        let members = &clusters.members[clusters.start[c]..clusters.start[c + 1]];
        if !needs_split(p, scale, pieces, members) {
            let cell = ctx.cells;
            ctx.cells += 1;
            for &q in members {
                ctx.piece_cell[q as usize] = Route::Fixed(cell);
            }
            continue;
        }
        let cut_pieces = weighted_points(p, pieces, &by_piece, members, &mut pts);
        let root = ctx.split(&mut pts);
        if ctx.kd[root as usize].axis != LEAF {
            report.split_clusters += 1;
        }
        for q in cut_pieces {
            ctx.piece_cell[q as usize] = Route::Plan(root);
        }
    }
    ctx.cells
}

/// Whether the cluster of `members` is above `max_cell_triangles`, or above `t2` and too large
/// or too uneven (from its pieces' exact counts and boxes).
fn needs_split(p: &RedefineParams, scale: &Scale, pieces: &Pieces, members: &[u32]) -> bool {
    let tris: u64 = members.iter().map(|&q| pieces.count[q as usize]).sum();
    let mut b = GridBox::EMPTY;
    for &q in members {
        b = b.union(&pieces.grid[q as usize]);
    }
    let ext = scale.grid_ext(&b);
    let uneven = diag(ext) > scale.s2 || aspect(ext) > p.r2;
    tris > p.max_cell_triangles || (tris > p.t2 && uneven)
}

/// The weighted points of a cluster to split, into `pts`: a piece of at most `t1` triangles
/// (or with fewer than two samples) at its centre of mass, a larger one as its sampled
/// centroids. Returns the pieces given as samples (a plan will cut them).
fn weighted_points(
    p: &RedefineParams,
    pieces: &Pieces,
    by_piece: &PieceSamples,
    members: &[u32],
    pts: &mut Vec<WPoint>,
) -> Vec<u32> {
    pts.clear();
    let mut cut_pieces = Vec::new();
    for &q in members {
        let qi = q as usize;
        let s = by_piece.of(qi);
        if pieces.count[qi] > p.t1 && s.len() >= 2 {
            let w = pieces.count[qi] as f64 / s.len() as f64;
            pts.extend(s.iter().map(|&c| {
                let mut b = FBox::EMPTY;
                b.grow(c);
                WPoint { c, w, b, piece: u32::MAX }
            }));
            cut_pieces.push(q);
        } else {
            pts.push(WPoint {
                c: pieces.centre[qi],
                w: pieces.count[qi] as f64,
                b: pieces.bounds[qi],
                piece: q,
            });
        }
    }
    cut_pieces
}

/// The sampled centroids grouped by piece (for the pieces cut by centroid).
struct PieceSamples {
    /// Piece `q`'s samples are `points[start[q]..start[q + 1]]`, in sample order.
    start: Vec<usize>,
    points: Vec<[f32; 3]>,
}

impl PieceSamples {
    /// Routes every sample to its piece (of `n_pieces`) as partition-I routes triangles, and
    /// groups them by piece (a counting sort).
    fn new(ing: &Ingested, samples: &Samples, assign: &Assigner, n_pieces: usize) -> PieceSamples {
        let mut start = vec![0usize; n_pieces + 1];
        let mut sample_piece = vec![0u32; samples.points.len()];
        for o in 0..ing.objects.len() {
            let range = samples.start[o]..samples.start[o + 1];
            let (stride, span_start) = (samples.stride[o], ing.objects[o].span.start);
            for (k, (&c, q_out)) in
                samples.points[range.clone()].iter().zip(&mut sample_piece[range]).enumerate()
            {
                let q = match assign.object_piece[o] {
                    ObjectRoute::Fixed(q) => q,
                    ObjectRoute::Plan(root) => walk(&assign.plan1, root, c),
                    // Samples of an object split at its parts are in file order, one every
                    // `stride`.
                    ObjectRoute::Parts(r) => assign.parts[r as usize].piece(span_start + k as u64 * stride),
                };
                *q_out = q;
                if (q as usize) < n_pieces {
                    start[q as usize + 1] += 1;
                }
            }
        }
        for q in 0..n_pieces {
            start[q + 1] += start[q];
        }
        let mut points = vec![[0f32; 3]; start[n_pieces]];
        let mut fill = start.clone();
        for (i, &q) in sample_piece.iter().enumerate() {
            if (q as usize) < n_pieces {
                points[fill[q as usize]] = samples.points[i];
                fill[q as usize] += 1;
            }
        }
        PieceSamples { start, points }
    }

    /// The samples of piece `q`.
    fn of(&self, q: usize) -> &[[f32; 3]] {
        &self.points[self.start[q]..self.start[q + 1]]
    }
}
