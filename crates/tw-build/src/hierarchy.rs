//! Phase 3: the AABB tree over the cells (GigaWalk §4.2 stage 4, "an AABB bounding volume
//! hierarchy on the final redefined set of objects (top-down)"; Govindaraju 2004 §3.3: "nodes
//! assigned by centres").
//!
//! Construction: top-down; a node's items are split at the median of their box centres along the
//! longest axis of the centres' bounds (ties broken by item index, so the tree depends only on the
//! input). Median splits keep the tree balanced (depth ⌈log2 n⌉), which bounds the HLOD pipeline's
//! memory ("tree + largest node with its children"), and split by centres as the papers do.
//!
//! Fanout 2: each internal node has exactly two children. A wider tree (4 or 8, for the runtime's
//! batched queries) is obtained by collapsing levels; HLOD building merges pairs, which keeps
//! every merge small and the error steps even.
//!
//! Layout: nodes in one array, node 0 the root; siblings are contiguous (`first_child`,
//! `child_count`) and every child index is greater than its parent's, so a forward pass visits
//! parents first and a backward pass children first. Leaves hold one item (a cell) each.
//! [`Hierarchy::leaf_order`] lists the items left to right: the build renumbers cells in that
//! order, so that spatially close cells are adjacent in the working files and pages.

use crate::types::GridBox;

/// One node of the tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct HNode {
    /// Contains the bounds of every item below the node (equal to their union).
    pub bounds: GridBox,
    /// Index of the first child; children are `first_child..first_child + child_count`.
    pub first_child: u32,
    /// 0 for a leaf, 2 otherwise.
    pub child_count: u32,
    /// The item (cell) of a leaf.
    pub cell: Option<u32>,
}

impl HNode {
    pub fn is_leaf(&self) -> bool {
        self.child_count == 0
    }

    pub fn children(&self) -> std::ops::Range<usize> {
        self.first_child as usize..(self.first_child + self.child_count) as usize
    }
}

/// A binary AABB tree (see the module docs for the layout).
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Hierarchy {
    pub nodes: Vec<HNode>,
}

impl Hierarchy {
    /// Builds the tree over `boxes` (item `i` has box `boxes[i]`; boxes must not be empty).
    /// No items give an empty tree.
    pub fn build(boxes: &[GridBox]) -> Hierarchy {
        let n = boxes.len();
        let mut nodes = Vec::with_capacity(2 * n.max(1) - 1);
        if n == 0 {
            return Hierarchy { nodes };
        }
        // Twice the centre, exact in integers.
        let centre2 = |i: u32, axis: usize| {
            let b = &boxes[i as usize];
            b.min[axis] as u64 + b.max[axis] as u64
        };
        let mut items: Vec<u32> = (0..n as u32).collect();
        nodes.push(HNode { bounds: GridBox::EMPTY, first_child: 0, child_count: 0, cell: None });
        // (node, start, end) to process; depth first, so subtrees end up mostly contiguous.
        let mut stack = vec![(0usize, 0usize, n)];
        while let Some((node, start, end)) = stack.pop() {
            let range = &mut items[start..end];
            let mut bounds = GridBox::EMPTY;
            let (mut cmin, mut cmax) = ([u64::MAX; 3], [0u64; 3]);
            for &i in range.iter() {
                bounds = bounds.union(&boxes[i as usize]);
                for a in 0..3 {
                    cmin[a] = cmin[a].min(centre2(i, a));
                    cmax[a] = cmax[a].max(centre2(i, a));
                }
            }
            nodes[node].bounds = bounds;
            if range.len() == 1 {
                nodes[node].cell = Some(range[0]);
                continue;
            }
            let axis =
                (0..3).fold(0, |best, a| if cmax[a] - cmin[a] > cmax[best] - cmin[best] { a } else { best });
            let mid = range.len() / 2;
            range.select_nth_unstable_by_key(mid, |&i| (centre2(i, axis), i));
            let first = nodes.len();
            nodes[node].first_child = first as u32;
            nodes[node].child_count = 2;
            let empty = HNode { bounds: GridBox::EMPTY, first_child: 0, child_count: 0, cell: None };
            nodes.push(empty);
            nodes.push(empty);
            // Right pushed first so the left subtree is built (and numbered) first.
            stack.push((first + 1, start + mid, end));
            stack.push((first, start, start + mid));
        }
        Hierarchy { nodes }
    }

    /// Number of leaves (items).
    pub fn leaf_count(&self) -> usize {
        self.nodes.iter().filter(|n| n.is_leaf()).count()
    }

    /// The items in left-to-right leaf order.
    pub fn leaf_order(&self) -> Vec<u32> {
        let mut out = Vec::with_capacity(self.nodes.len() / 2 + 1);
        let mut stack = Vec::new();
        if !self.nodes.is_empty() {
            stack.push(0usize);
        }
        while let Some(i) = stack.pop() {
            let n = &self.nodes[i];
            if let Some(c) = n.cell {
                out.push(c);
            }
            stack.extend(n.children().rev());
        }
        out
    }

    /// Renames the items: leaf item `c` becomes `new_id[c]`.
    pub fn renumber(&mut self, new_id: &[u32]) {
        for n in &mut self.nodes {
            if let Some(c) = n.cell.as_mut() {
                *c = new_id[*c as usize];
            }
        }
    }

    /// The number of levels (1 for a single leaf, 0 when empty).
    pub fn depth(&self) -> usize {
        let mut depth = vec![0usize; self.nodes.len()];
        let mut max = 0;
        for i in 0..self.nodes.len() {
            let d = if i == 0 { 1 } else { depth[i] };
            max = max.max(d);
            for c in self.nodes[i].children() {
                if c < depth.len() {
                    depth[c] = d + 1;
                }
            }
        }
        max
    }

    /// Checks the invariants: children after parents and in range, every node but the root has
    /// exactly one parent, internal nodes have two children and no item, parents' bounds are the
    /// union of their children's, leaves hold one item whose box is the leaf's bounds, and every
    /// item of `boxes` is in exactly one leaf.
    #[cfg(test)]
    pub fn validate(&self, boxes: &[GridBox]) -> Result<(), String> {
        if self.nodes.is_empty() {
            return if boxes.is_empty() { Ok(()) } else { Err("empty tree over items".into()) };
        }
        let mut parents = vec![0u32; self.nodes.len()];
        let mut seen = vec![false; boxes.len()];
        for (i, n) in self.nodes.iter().enumerate() {
            match (n.child_count, n.cell) {
                (0, Some(c)) => {
                    let Some(b) = boxes.get(c as usize) else {
                        return Err(format!("leaf {i} holds item {c} of {}", boxes.len()));
                    };
                    if std::mem::replace(&mut seen[c as usize], true) {
                        return Err(format!("item {c} is in two leaves"));
                    }
                    if n.bounds != *b {
                        return Err(format!("leaf {i} bounds {:?} differ from item {c}'s {b:?}", n.bounds));
                    }
                }
                (2, None) => {
                    if (n.first_child as usize) <= i || n.first_child as usize + 2 > self.nodes.len() {
                        return Err(format!("node {i} has children {:?}", n.children()));
                    }
                    let mut u = GridBox::EMPTY;
                    for c in n.children() {
                        parents[c] += 1;
                        u = u.union(&self.nodes[c].bounds);
                    }
                    if u != n.bounds {
                        return Err(format!("node {i} bounds {:?} are not its children's {u:?}", n.bounds));
                    }
                }
                (k, c) => return Err(format!("node {i} has {k} children and item {c:?}")),
            }
        }
        if parents[0] != 0 {
            return Err("the root has a parent".into());
        }
        if let Some(i) = parents.iter().skip(1).position(|&p| p != 1) {
            return Err(format!("node {} has {} parents", i + 1, parents[i + 1]));
        }
        if let Some(c) = seen.iter().position(|s| !s) {
            return Err(format!("item {c} is in no leaf"));
        }
        Ok(())
    }
}

/// Lookups over a [`Hierarchy`] that phase 5 needs per node: parent, depth, the leaf of each
/// cell and the cells under each node.
pub(crate) struct TreeIndex {
    /// `u32::MAX` for the root.
    pub parent: Vec<u32>,
    pub depth: Vec<u32>,
    pub leaf_of_cell: Vec<u32>,
    /// The cells (leaf order) under each node: `first..last + 1`.
    pub cell_range: Vec<(u32, u32)>,
}

impl TreeIndex {
    pub fn new(hierarchy: &Hierarchy) -> TreeIndex {
        let n = hierarchy.nodes.len();
        let mut parent = vec![u32::MAX; n];
        let mut depth = vec![0u32; n];
        let mut leaf_of_cell = vec![u32::MAX; hierarchy.leaf_count()];
        for (i, node) in hierarchy.nodes.iter().enumerate() {
            for c in node.children() {
                parent[c] = i as u32;
                depth[c] = depth[i] + 1;
            }
            if let Some(cell) = node.cell {
                leaf_of_cell[cell as usize] = i as u32;
            }
        }
        // Children come after parents: a reverse sweep sees every child before its parent.
        let mut cell_range = vec![(u32::MAX, 0u32); n];
        for i in (0..n).rev() {
            let node = &hierarchy.nodes[i];
            if let Some(cell) = node.cell {
                cell_range[i] = (cell, cell + 1);
            }
            for c in node.children() {
                let (lo, hi) = cell_range[c];
                cell_range[i] = (cell_range[i].0.min(lo), cell_range[i].1.max(hi));
            }
        }
        TreeIndex { parent, depth, leaf_of_cell, cell_range }
    }

    /// `node`'s index among its parent's children (0 for the root): its provisional group ids'
    /// slot (`crate::provisional`).
    fn slot(&self, hierarchy: &Hierarchy, node: u32) -> u32 {
        match self.parent[node as usize] {
            u32::MAX => 0,
            p => node - hierarchy.nodes[p as usize].first_child,
        }
    }

    /// What a complete `node` hands up to its parent's HLOD: the roots of `dag` (its DAG) under
    /// provisional ids, and the seams among `seams` at their vertices that are shared with a cell
    /// outside `range` (the node's cells).
    pub fn subtree_roots(
        &self,
        hierarchy: &Hierarchy,
        node: u32,
        dag: &crate::types::LodDag,
        seams: &crate::seams::SeamTable,
        range: (u32, u32),
    ) -> Result<(crate::hlod::Roots, crate::seams::SeamTable), crate::error::BuildError> {
        let base = crate::provisional::base(self.slot(hierarchy, node), dag.groups.len())?;
        let roots = crate::hlod::roots_of(dag, base);
        let root_seams = seams.retain(roots.positions(), range);
        Ok((roots, root_seams))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tw_core::Rng;

    fn random_boxes(n: usize, seed: u64) -> Vec<GridBox> {
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| {
                let mut b = GridBox::EMPTY;
                let c = [rng.range_u32(0, 1 << 20), rng.range_u32(0, 1 << 20), rng.range_u32(0, 1 << 16)];
                b.grow(c);
                b.grow([c[0] + rng.range_u32(0, 5000), c[1] + rng.range_u32(0, 5000), c[2] + 3]);
                b
            })
            .collect()
    }

    #[test]
    fn random_boxes_give_a_valid_balanced_tree() {
        for n in [1, 2, 3, 7, 1000] {
            let boxes = random_boxes(n, n as u64);
            let h = Hierarchy::build(&boxes);
            h.validate(&boxes).unwrap();
            assert_eq!(h.nodes.len(), 2 * n - 1);
            assert_eq!(h.leaf_count(), n);
            let depth_bound = (n as f64).log2().ceil() as usize + 1;
            assert!(h.depth() <= depth_bound, "n {n}: depth {} > {depth_bound}", h.depth());
            let mut order = h.leaf_order();
            order.sort();
            assert_eq!(order, (0..n as u32).collect::<Vec<_>>());
        }
    }

    #[test]
    fn empty_input_gives_an_empty_tree() {
        let h = Hierarchy::build(&[]);
        assert!(h.nodes.is_empty());
        h.validate(&[]).unwrap();
        assert!(h.leaf_order().is_empty());
        assert_eq!(h.depth(), 0);
    }

    #[test]
    fn identical_boxes_still_split() {
        let b = GridBox { min: [5; 3], max: [9; 3] };
        let boxes = vec![b; 9];
        let h = Hierarchy::build(&boxes);
        h.validate(&boxes).unwrap();
        assert!(h.depth() <= 5);
    }

    #[test]
    fn leaf_order_follows_space() {
        // Boxes along x in shuffled order: the leaf order is sorted by x.
        let xs = [7u32, 2, 9, 0, 5, 1, 8, 3, 6, 4];
        let boxes: Vec<GridBox> =
            xs.iter().map(|&x| GridBox { min: [x * 10, 0, 0], max: [x * 10 + 5, 1, 1] }).collect();
        let h = Hierarchy::build(&boxes);
        let order: Vec<u32> = h.leaf_order().iter().map(|&i| xs[i as usize]).collect();
        assert_eq!(order, (0..10).collect::<Vec<_>>());
    }

    #[test]
    fn renumbering_follows_leaf_order() {
        let boxes = random_boxes(50, 3);
        let mut h = Hierarchy::build(&boxes);
        let order = h.leaf_order();
        let mut new_id = vec![0u32; order.len()];
        for (k, &c) in order.iter().enumerate() {
            new_id[c as usize] = k as u32;
        }
        let renamed: Vec<GridBox> = order.iter().map(|&c| boxes[c as usize]).collect();
        h.renumber(&new_id);
        h.validate(&renamed).unwrap();
        assert_eq!(h.leaf_order(), (0..50).collect::<Vec<_>>());
    }

    #[test]
    fn validate_catches_broken_trees() {
        let boxes = random_boxes(8, 1);
        let h = Hierarchy::build(&boxes);
        let mut bad = h.clone();
        bad.nodes[0].bounds.max[0] -= 1;
        assert!(bad.validate(&boxes).is_err());
        let mut bad = h.clone();
        let leaf = bad.nodes.iter().position(|n| n.is_leaf()).unwrap();
        bad.nodes[leaf].cell = Some(99);
        assert!(bad.validate(&boxes).is_err());
        let mut bad = h.clone();
        bad.nodes[0].first_child = 0;
        assert!(bad.validate(&boxes).is_err());
        assert!(h.validate(&boxes[..7]).is_err());
    }
}
