//! Structural checks of a built [`Bvh`], for tests and for debugging stores.

use glam::Vec3;

use crate::aabb::Aabb;
use crate::build::MAX_DEPTH;
use crate::bvh::Bvh;
use crate::mesh::TriangleBvh;
use crate::wide::{Leaf, EMPTY, LEAF, W};

impl Bvh {
    /// Checks the tree against the `boxes` it was built from: every primitive in exactly one
    /// leaf, every node and leaf reached exactly once, every child box inside its parent's box
    /// and holding its contents, no inner node without children, no leaf without primitives,
    /// depth at most the builder's bound. The error names the node or leaf at fault.
    ///
    /// A tree built with spatial splits (more primitive indices than boxes) may hold a
    /// primitive in several leaves, each with the box of only part of it: there every
    /// primitive must be in at least one leaf, never twice in one, and each leaf's box must
    /// overlap the boxes of its primitives ([`TriangleBvh::validate`] checks that the parts
    /// cover the triangles).
    pub fn validate(&self, boxes: &[Aabb]) -> Result<(), String> {
        if self.prim_indices.len() < boxes.len() {
            return Err(format!("{} primitive indices for {} boxes", self.prim_indices.len(), boxes.len()));
        }
        let split = self.prim_indices.len() > boxes.len();
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
                        split,
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
        split: bool,
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
        let prims = &self.prim_indices[range];
        for (k, &p) in prims.iter().enumerate() {
            let p = p as usize;
            if p >= boxes.len() {
                return Err(format!("leaf {l}: primitive {p} out of range"));
            }
            if std::mem::replace(&mut prim_seen[p], true) && !split {
                return Err(format!("leaf {l}: primitive {p} in two leaves"));
            }
            if prims[..k].contains(&(p as u32)) {
                return Err(format!("leaf {l}: primitive {p} twice"));
            }
            let finite = boxes[p].min.is_finite() && boxes[p].max.is_finite();
            let outside = match split {
                false => !b.contains(&boxes[p]),
                true => !boxes[p].is_empty() && overlap(b, &boxes[p]).is_empty(),
            };
            if outside && finite {
                return Err(format!("leaf {l}: primitive {p} box {:?} outside {b:?}", boxes[p]));
            }
        }
        Ok(())
    }
}

impl Bvh {
    /// Calls `f(leaf, box)` for every leaf reached from the root, with its box in the parent.
    fn for_each_leaf(&self, mut f: impl FnMut(usize, Aabb)) {
        let mut stack = if self.nodes.is_empty() { vec![] } else { vec![0usize] };
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n];
            for slot in 0..W {
                match node.child[slot] {
                    EMPTY => {}
                    c if c & LEAF != 0 => f((c & !LEAF) as usize, node.child_bounds(slot)),
                    c => stack.push(c as usize),
                }
            }
        }
    }
}

fn overlap(a: &Aabb, b: &Aabb) -> Aabb {
    Aabb::new(a.min.max(b.min), a.max.min(b.max))
}

impl TriangleBvh {
    /// [`Bvh::validate`] over the triangles' boxes, and then that the leaves cover the
    /// triangles: each triangle's vertices, edge midpoints and centroid lie in the box of some
    /// leaf that holds it, and each leaf's triangle group holds the leaf's triangles. With
    /// spatial splits this checks that clipping kept every part of a triangle reachable.
    pub fn validate(&self, positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Result<(), String> {
        let corner = |t: &[u32; 3], k: usize| positions.get(t[k] as usize).map(|&p| Vec3::from(p));
        let corners: Vec<Option<[Vec3; 3]>> =
            triangles.iter().map(|t| Some([corner(t, 0)?, corner(t, 1)?, corner(t, 2)?])).collect();
        let boxes: Vec<Aabb> =
            corners.iter().map(|c| c.map_or(Aabb::EMPTY, |c| Aabb::from_points(&c))).collect();
        self.bvh.validate(&boxes)?;
        if self.groups.len() != self.bvh.leaves.len() {
            return Err(format!(
                "{} triangle groups for {} leaves",
                self.groups.len(),
                self.bvh.leaves.len()
            ));
        }
        let mut leaf_boxes: Vec<Vec<Aabb>> = vec![Vec::new(); triangles.len()];
        self.bvh.for_each_leaf(|leaf, b| {
            let Leaf { first, count } = self.bvh.leaves[leaf];
            for &p in &self.bvh.prim_indices[first as usize..(first + count) as usize] {
                leaf_boxes[p as usize].push(b);
            }
        });
        for (l, (g, &Leaf { first, count })) in self.groups.iter().zip(&self.bvh.leaves).enumerate() {
            let prims = &self.bvh.prim_indices[first as usize..(first + count) as usize];
            if g.count() != prims.len() || g.prim[..prims.len()] != *prims {
                return Err(format!("leaf {l}: group holds {:?}, leaf {prims:?}", &g.prim[..g.count()]));
            }
        }
        for (t, c) in corners.iter().enumerate() {
            let Some(c) = c.filter(|c| c.iter().all(|p| p.is_finite())) else { continue };
            let mids =
                [(c[0] + c[1]) * 0.5, (c[1] + c[2]) * 0.5, (c[2] + c[0]) * 0.5, (c[0] + c[1] + c[2]) / 3.0];
            // Vertices are exact; the other points are rounded, so they may lie a relative 2^-20
            // off the boxes.
            let samples = c.iter().map(|&p| (p, 0.0)).chain(mids.map(|p| (p, 1.0 / (1u32 << 20) as f32)));
            for (p, rel) in samples {
                let slack = p.abs() * rel;
                let near = Aabb::new(p - slack, p + slack);
                if !leaf_boxes[t].iter().any(|b| !overlap(b, &near).is_empty()) {
                    return Err(format!(
                        "triangle {t}: point {p} in none of its leaves' boxes {:?}",
                        leaf_boxes[t]
                    ));
                }
            }
        }
        Ok(())
    }
}
