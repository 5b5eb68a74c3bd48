//! Structural checks of a built [`Bvh`], for tests and for debugging stores.

use crate::aabb::Aabb;
use crate::build::MAX_DEPTH;
use crate::bvh::Bvh;
use crate::wide::{Leaf, EMPTY, LEAF, W};

impl Bvh {
    /// Checks the tree against the `boxes` it was built from: every primitive in exactly one
    /// leaf, every node and leaf reached exactly once, every child box inside its parent's box
    /// and holding its contents, no inner node without children, no leaf without primitives,
    /// depth at most the builder's bound. The error names the node or leaf at fault.
    pub fn validate(&self, boxes: &[Aabb]) -> Result<(), String> {
        if self.prim_indices.len() != boxes.len() {
            return Err(format!("{} primitive indices for {} boxes", self.prim_indices.len(), boxes.len()));
        }
        if self.nodes.is_empty() {
            return match boxes.is_empty() && self.leaves.is_empty() {
                true => Ok(()),
                false => Err(format!("no nodes but {} boxes and {} leaves", boxes.len(), self.leaves.len())),
            };
        }
        let mut prim_seen = vec![false; boxes.len()];
        let mut node_seen = vec![false; self.nodes.len()];
        let mut leaf_seen = vec![false; self.leaves.len()];
        // (node, depth, the box the node's children must lie in)
        let mut stack = vec![(0usize, 1u32, self.bounds)];
        while let Some((n, depth, parent)) = stack.pop() {
            if depth > MAX_DEPTH + 1 {
                return Err(format!("node {n}: depth {depth} exceeds {}", MAX_DEPTH + 1));
            }
            if std::mem::replace(&mut node_seen[n], true) {
                return Err(format!("node {n} reached twice"));
            }
            let node = &self.nodes[n];
            if node.child.iter().all(|&c| c == EMPTY) {
                return Err(format!("node {n} has no children"));
            }
            for slot in 0..W {
                let (c, b) = (node.child[slot], node.child_bounds(slot));
                if c == EMPTY {
                    if !b.is_empty() {
                        return Err(format!("node {n} slot {slot}: unused slot with box {b:?}"));
                    }
                    continue;
                }
                if !parent.contains(&b) {
                    return Err(format!("node {n} slot {slot}: box {b:?} outside parent {parent:?}"));
                }
                if c & LEAF == 0 {
                    let child = c as usize;
                    if child >= self.nodes.len() {
                        return Err(format!("node {n} slot {slot}: child {child} out of range"));
                    }
                    stack.push((child, depth + 1, b));
                } else {
                    self.check_leaf(
                        n,
                        slot,
                        (c & !LEAF) as usize,
                        &b,
                        boxes,
                        &mut leaf_seen,
                        &mut prim_seen,
                    )?;
                }
            }
        }
        if let Some(n) = node_seen.iter().position(|s| !s) {
            return Err(format!("node {n} unreachable"));
        }
        if let Some(l) = leaf_seen.iter().position(|s| !s) {
            return Err(format!("leaf {l} unreachable"));
        }
        if let Some(p) = prim_seen.iter().position(|s| !s) {
            return Err(format!("primitive {p} in no leaf"));
        }
        Ok(())
    }

    /// Checks leaf `l`, referenced from slot `slot` of node `n` with box `b`.
    #[allow(clippy::too_many_arguments)]
    fn check_leaf(
        &self,
        n: usize,
        slot: usize,
        l: usize,
        b: &Aabb,
        boxes: &[Aabb],
        leaf_seen: &mut [bool],
        prim_seen: &mut [bool],
    ) -> Result<(), String> {
        let Some(&Leaf { first, count }) = self.leaves.get(l) else {
            return Err(format!("node {n} slot {slot}: leaf {l} out of range"));
        };
        if std::mem::replace(&mut leaf_seen[l], true) {
            return Err(format!("leaf {l} reached twice"));
        }
        let range = first as usize..first as usize + count as usize;
        if count == 0 || range.end > self.prim_indices.len() {
            return Err(format!("leaf {l}: bad range {range:?}"));
        }
        for &p in &self.prim_indices[range] {
            let p = p as usize;
            if p >= boxes.len() || std::mem::replace(&mut prim_seen[p], true) {
                return Err(format!("leaf {l}: primitive {p} out of range or in two leaves"));
            }
            if !b.contains(&boxes[p]) && boxes[p].min.is_finite() && boxes[p].max.is_finite() {
                return Err(format!("leaf {l}: primitive {p} box {:?} outside {b:?}", boxes[p]));
            }
        }
        Ok(())
    }
}
