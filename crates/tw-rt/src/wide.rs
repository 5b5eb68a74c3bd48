//! The wide BVH: node layout and the collapse of the binary SAH tree into it.
//!
//! A wide node holds the boxes of up to [`W`] children in structure-of-arrays order, so one
//! ray tests all of them with a few SIMD instructions (8 lanes: one AVX2 register). The collapse
//! follows the usual greedy rule (Wald et al. 2008, "Getting rid of packets"; Embree's BVH8
//! builder): starting from a binary node's two children, repeatedly open the inner child with
//! the largest surface area until the node has `W` children or only leaves are left.

use crate::aabb::Aabb;
use crate::build::BuildNode;

/// Children per wide node.
pub(crate) const W: usize = 8;
/// Flag of a child reference that names a leaf (the low bits are the leaf's index).
pub(crate) const LEAF: u32 = 1 << 31;
/// An unused child slot (its box is empty, so no ray ever enters it).
pub(crate) const EMPTY: u32 = u32::MAX;

/// One wide node: child boxes as `bounds[side][axis][child]` (side 0: min, 1: max) and child
/// references. Traversal picks a ray's near side per axis as `sign bit as usize`, an index the
/// compiler knows is in range, so the hot loads carry no bounds checks.
#[derive(Clone, Debug)]
#[repr(C, align(32))]
pub(crate) struct WideNode {
    pub bounds: [[[f32; W]; 3]; 2],
    pub child: [u32; W],
}

impl WideNode {
    fn empty() -> WideNode {
        WideNode { bounds: [[[f32::INFINITY; W]; 3], [[f32::NEG_INFINITY; W]; 3]], child: [EMPTY; W] }
    }

    /// The box of child slot `i`.
    pub fn child_bounds(&self, i: usize) -> Aabb {
        let b = &self.bounds;
        Aabb::new(
            glam::Vec3::new(b[0][0][i], b[0][1][i], b[0][2][i]),
            glam::Vec3::new(b[1][0][i], b[1][1][i], b[1][2][i]),
        )
    }

    fn set_child(&mut self, i: usize, bounds: &Aabb, child: u32) {
        for a in 0..3 {
            self.bounds[0][a][i] = bounds.min[a];
            self.bounds[1][a][i] = bounds.max[a];
        }
        self.child[i] = child;
    }
}

/// A leaf: `prim_indices[first..first + count]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Leaf {
    pub first: u32,
    pub count: u32,
}

/// Collapses the binary tree under `root` into wide nodes (the root is node 0) and leaves.
pub(crate) fn collapse(root: &BuildNode) -> (Vec<WideNode>, Vec<Leaf>) {
    let mut nodes = vec![WideNode::empty()];
    let mut leaves = Vec::new();
    match root {
        // A lone leaf still gets a root node, so traversal always starts at an inner node.
        BuildNode::Leaf { bounds, first, count } => {
            leaves.push(Leaf { first: *first, count: *count });
            nodes[0].set_child(0, bounds, LEAF);
        }
        BuildNode::Inner { children, .. } => fill_node(0, children, &mut nodes, &mut leaves),
    }
    (nodes, leaves)
}

/// Fills wide node `index` (already allocated) for a binary inner node with `children`. The
/// node's inner children are allocated next to each other before any of them is filled, so the
/// siblings a node test finds lie in consecutive memory (their prefetches overlap), as do the
/// node's leaves.
fn fill_node(index: usize, children: &[BuildNode; 2], nodes: &mut Vec<WideNode>, leaves: &mut Vec<Leaf>) {
    let kids = gather_children(children);
    let mut node = WideNode::empty();
    let mut inner = Vec::new();
    for (slot, kid) in kids.iter().enumerate() {
        let child = match kid {
            BuildNode::Leaf { first, count, .. } => {
                leaves.push(Leaf { first: *first, count: *count });
                LEAF | (leaves.len() - 1) as u32
            }
            BuildNode::Inner { children, .. } => {
                nodes.push(WideNode::empty());
                inner.push((nodes.len() - 1, children));
                (nodes.len() - 1) as u32
            }
        };
        node.set_child(slot, &kid.bounds(), child);
    }
    nodes[index] = node;
    for (child, grandchildren) in inner {
        fill_node(child, grandchildren, nodes, leaves);
    }
}

/// Up to `W` descendants that together cover the node: open the largest inner one until full.
fn gather_children(children: &[BuildNode; 2]) -> Vec<&BuildNode> {
    let mut kids: Vec<&BuildNode> = children.iter().collect();
    while kids.len() < W {
        let largest = kids
            .iter()
            .enumerate()
            .filter(|(_, k)| matches!(k, BuildNode::Inner { .. }))
            .max_by(|a, b| a.1.bounds().half_area().total_cmp(&b.1.bounds().half_area()))
            .map(|(i, _)| i);
        let Some(i) = largest else { break };
        let BuildNode::Inner { children: grand, .. } = kids[i] else { break };
        kids[i] = &grand[0];
        kids.push(&grand[1]);
    }
    kids
}
