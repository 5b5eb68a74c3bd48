//! The triangle → cell function ([`Assigner`]): kd plans of planes over centroids, each
//! object's route to its pieces (a fixed piece, a partition-I plan, or its part groups), each
//! piece's route to its cells (a fixed cell or a partition-II plan), and the runs of the cells
//! the count split cut. A pure function of a triangle's object, centroid and working-file
//! index, so that every pass evaluates it the same way.

use crate::ingest::WorkTri;

/// A kd-tree node: a leaf (`axis == LEAF`, id in `a`) or a plane: centroids with
/// `c[axis] < pos` go to node `a`, the others to node `b`.
#[derive(Clone, Copy, Debug)]
pub(super) struct KdNode {
    pub(super) axis: u8,
    pub(super) pos: f32,
    pub(super) a: u32,
    pub(super) b: u32,
}

pub(super) const LEAF: u8 = 3;

impl KdNode {
    pub(super) fn leaf(id: u32) -> KdNode {
        KdNode { axis: LEAF, pos: 0.0, a: id, b: 0 }
    }
}

#[inline]
pub(super) fn walk(kd: &[KdNode], mut n: u32, c: [f32; 3]) -> u32 {
    loop {
        let k = kd[n as usize];
        if k.axis == LEAF {
            return k.a;
        }
        n = if c[k.axis as usize] < k.pos { k.a } else { k.b };
    }
}

/// Where a triangle goes: a fixed id, or the leaf of a kd plan (the root's index).
#[derive(Clone, Copy, Debug)]
pub(super) enum Route {
    Fixed(u32),
    Plan(u32),
}

/// Where an object's triangle goes in partition-I: a [`Route`] to a piece, or, for an object
/// split at its part groups (`crate::parts`), the group's piece (index into [`Assigner::parts`]).
#[derive(Clone, Copy, Debug)]
pub(super) enum ObjectRoute {
    Fixed(u32),
    Plan(u32),
    Parts(u32),
}

/// An object split at its part groups: group `g` (0 from its first triangle, then one more at
/// each start) is piece `first_piece + g`.
///
/// Every triangle of the object is looked up twice (pass B and the distribution), so the group
/// is found through `bins` rather than by a binary search over all the starts (46 k of them in
/// the 24 M-triangle assembly written as one object, where the search was the largest single
/// cost of both passes): bin `k` covers the relative indices `k << shift ..` and holds how many
/// starts are at or before its first index, so a triangle's group is at most the starts of one
/// bin past it. `shift` makes a bin about as long as an average group: O(groups) entries.
#[derive(Clone, Debug, Default)]
pub(super) struct PartRoute {
    pub(super) first_piece: u32,
    pub(super) span_start: u64,
    pub(super) starts: Vec<u64>,
    pub(super) shift: u32,
    /// `bins[k]`: the starts `≤ k << shift`; one bin past the span's end.
    pub(super) bins: Vec<u32>,
}

#[derive(Clone, Debug, Default)]
pub(super) struct Assigner {
    /// Partition-I plans; leaves are piece ids.
    pub(super) plan1: Vec<KdNode>,
    /// Partition-II plans; leaves are cell ids.
    pub(super) plan2: Vec<KdNode>,
    /// Per object.
    pub(super) object_piece: Vec<ObjectRoute>,
    /// The objects split at their part groups (`ObjectRoute::Parts`).
    pub(super) parts: Vec<PartRoute>,
    /// Per piece.
    pub(super) piece_cell: Vec<Route>,
    /// Per cell (empty: none cut): the index in `splits` of the cell's count split, or
    /// `u32::MAX`. Keyed by the cell the routes give, which is also the split's first part.
    pub(super) count_split: Vec<u32>,
    pub(super) splits: Vec<CountSplit>,
}

/// How the count split cut one cell: part `j` holds the cell's triangles of working-file index
/// in `starts[j - 1]..starts[j]` (part 0 from 0, the last to the end), and is cell `cells[j]`.
#[derive(Clone, Debug, Default)]
pub(super) struct CountSplit {
    pub(super) starts: Vec<u64>,
    pub(super) cells: Vec<u32>,
}

impl PartRoute {
    /// The route of an object whose working-file triangles are `span` and whose groups start
    /// at `starts` (relative to `span.start`, ascending).
    pub(super) fn new(first_piece: u32, span: std::ops::Range<u64>, starts: Vec<u64>) -> PartRoute {
        let len = span.end.saturating_sub(span.start);
        let mean_group = (len / (starts.len() as u64 + 1)).max(1);
        let shift = mean_group.ilog2();
        let mut bins = Vec::with_capacity((len >> shift) as usize + 2);
        let mut before = 0usize;
        for k in 0..=(len >> shift) + 1 {
            let first = k << shift;
            while before < starts.len() && starts[before] <= first {
                before += 1;
            }
            bins.push(before as u32);
        }
        PartRoute { first_piece, span_start: span.start, starts, shift, bins }
    }

    /// The piece of the object's working-file triangle `index`: the number of starts at or
    /// before it, counted from its bin's.
    #[inline]
    pub(super) fn piece(&self, index: u64) -> u32 {
        let rel = index.saturating_sub(self.span_start);
        let bin = usize::try_from(rel >> self.shift).unwrap_or(usize::MAX);
        let (Some(&lo), Some(&hi)) = (self.bins.get(bin), self.bins.get(bin.saturating_add(1))) else {
            // Past the span (not a triangle of the object): the same answer, searched.
            return self.first_piece + self.starts.partition_point(|&s| s <= rel) as u32;
        };
        let mut group = lo as usize;
        while group < hi as usize && self.starts[group] <= rel {
            group += 1;
        }
        self.first_piece + group as u32
    }
}

impl Assigner {
    /// The piece of working-file triangle `index`, `t`.
    #[inline]
    pub(super) fn piece(&self, t: &WorkTri, index: u64) -> u32 {
        match self.object_piece[t.object as usize] {
            ObjectRoute::Fixed(p) => p,
            ObjectRoute::Plan(root) => walk(&self.plan1, root, t.centroid()),
            ObjectRoute::Parts(k) => self.parts[k as usize].piece(index),
        }
    }

    #[inline]
    pub(super) fn cell(&self, t: &WorkTri, index: u64) -> u32 {
        match self.piece_cell[self.piece(t, index) as usize] {
            Route::Fixed(c) => c,
            Route::Plan(root) => walk(&self.plan2, root, t.centroid()),
        }
    }

    /// The final cell of working-file triangle `index` whose routes give cell `c`: one of the
    /// parts of `c` if the count split cut it, else `c`.
    #[inline]
    pub(super) fn final_cell(&self, c: u32, index: u64) -> u32 {
        match self.count_split.get(c as usize) {
            Some(&s) if s != u32::MAX => {
                let split = &self.splits[s as usize];
                split.cells[split.starts.partition_point(|&start| start <= index)]
            }
            _ => c,
        }
    }

    /// Cell `c` becomes `map[c]` (`u32::MAX` for cells that no triangle reaches).
    pub(super) fn remap_cells(&mut self, map: &[u32]) {
        let m = |c: u32| map.get(c as usize).copied().unwrap_or(u32::MAX);
        if !self.count_split.is_empty() {
            // New ids are below the old count: re-key the splits by the new ids.
            let mut keyed = vec![u32::MAX; map.len()];
            for (c, &s) in self.count_split.iter().enumerate() {
                if let Some(slot) = keyed.get_mut(m(c as u32) as usize) {
                    *slot = s;
                }
            }
            self.count_split = keyed;
            for split in &mut self.splits {
                for c in &mut split.cells {
                    *c = m(*c);
                }
            }
        }
        for r in &mut self.piece_cell {
            if let Route::Fixed(c) = r {
                *c = m(*c);
            }
        }
        for k in &mut self.plan2 {
            if k.axis == LEAF {
                k.a = m(k.a);
            }
        }
    }
}
