//! Cluster BVHs stored in the store (`terawalk build --rt-bvh`; docs/FORMAT.md, "Ray-tracing
//! trees"; docs/DESIGN.md D8).
//!
//! The builder runs the same SAH build as the ray tracer does at run time ([`TriangleBvh::build`]
//! on the cluster's scene-space triangles) and stores its shape: the triangle order of the
//! leaves and the binary tree ([`cluster_tree`]). The ray tracer then skips the SAH: it refits
//! the stored shape with the exact boxes of the decoded triangles and collapses it into the
//! wide layout ([`bvh_from_tree`]), which gives the very [`TriangleBvh`] a build would have
//! given (same nodes, boxes and leaves, bit for bit), hence the same hits and images. Boxes are
//! not stored: they would cost more bytes than the shape, and a refit from the triangles cannot
//! be wrong, whatever the bytes of the store.

use glam::Vec3;
use tw_store::rt::RT_MAX_DEPTH;
use tw_store::{PageCluster, RtTree};

use crate::build::{build_binary, BuildNode, BuildOptions, MAX_DEPTH};
use crate::bvh::Bvh;
use crate::scene::blas::scene_position;
use crate::triangle::GROUP;
use crate::wide::collapse;
use crate::{Aabb, TriangleBvh};

// A stored tree's depth bound must fit the traversal stacks.
const _: () = assert!(RT_MAX_DEPTH as u32 <= MAX_DEPTH);

/// The options [`TriangleBvh::build`] uses: the stored shape must be the one it builds.
fn options() -> BuildOptions {
    BuildOptions { max_leaf_size: GROUP, block_size: GROUP, traversal_cost: 1.0 }
}

/// The scene-space corners of every triangle of `cluster` (as [`ClusterBlas::build`] sees
/// them); `None` for an index out of range (not reachable from a decoded cluster).
///
/// [`ClusterBlas::build`]: crate::scene::blas::ClusterBlas::build
fn corners(cluster: &PageCluster, grid_step: f64) -> Option<Vec<[Vec3; 3]>> {
    cluster
        .indices
        .chunks_exact(3)
        .map(|t| {
            let p = |k: usize| {
                cluster.positions.get(t[k] as usize).map(|&g| Vec3::from(scene_position(g, grid_step)))
            };
            Some([p(0)?, p(1)?, p(2)?])
        })
        .collect()
}

/// The shape of the BVH the ray tracer builds for `cluster` (decoded, i.e. in canonical form)
/// at grid step `grid_step`: what `terawalk build --rt-bvh` stores after the cluster.
pub fn cluster_tree(cluster: &PageCluster, grid_step: f64) -> Result<RtTree, String> {
    let corners = corners(cluster, grid_step).ok_or("a triangle index is out of range")?;
    let boxes: Vec<Aabb> = corners.iter().map(|c| Aabb::from_points(c)).collect();
    let (root, order) = build_binary(&boxes, &options());
    let root = root.ok_or("a cluster without triangles")?;
    let mut nodes = Vec::with_capacity(2 * boxes.len());
    let mut stack = vec![&root];
    while let Some(n) = stack.pop() {
        match n {
            BuildNode::Leaf { count, .. } => nodes.push(*count as u8),
            BuildNode::Inner { children, .. } => {
                nodes.push(0);
                stack.push(&children[1]);
                stack.push(&children[0]);
            }
        }
    }
    let tree = RtTree { order: order.iter().map(|&i| i as u8).collect(), nodes };
    tree.validate(boxes.len())?;
    Ok(tree)
}

/// The ray tracer's BVH of `cluster` from its stored shape `tree`: the boxes are refitted from
/// the triangles, then the tree is collapsed and its leaves filled as [`TriangleBvh::build`]
/// does. Fails only for a tree that does not fit the cluster ([`RtTree::validate`]).
pub fn bvh_from_tree(cluster: &PageCluster, grid_step: f64, tree: &RtTree) -> Result<TriangleBvh, String> {
    let corners = corners(cluster, grid_step).ok_or("a triangle index is out of range")?;
    tree.validate(corners.len())?;
    let boxes: Vec<Aabb> = corners.iter().map(|c| Aabb::from_points(c)).collect();
    let mut next = (0usize, 0u32);
    let root = refit(tree, &boxes, &mut next);
    let prim_indices: Vec<u32> = tree.order.iter().map(|&i| i as u32).collect();
    let (nodes, leaves) = collapse(&root);
    let bvh = Bvh { nodes, leaves, prim_indices, bounds: root.bounds() };
    Ok(TriangleBvh::with_leaves(bvh, &corners))
}

/// The subtree of `tree` that starts at node `next.0` (its leaves from `order[next.1..]`), with
/// exact boxes. Recursion depth ≤ [`RT_MAX_DEPTH`] (checked by `validate`).
fn refit(tree: &RtTree, boxes: &[Aabb], next: &mut (usize, u32)) -> BuildNode {
    let n = tree.nodes[next.0];
    next.0 += 1;
    if n == 0 {
        let l = refit(tree, boxes, next);
        let r = refit(tree, boxes, next);
        BuildNode::Inner { bounds: l.bounds().union(r.bounds()), children: Box::new([l, r]) }
    } else {
        let first = next.1;
        next.1 += n as u32;
        let bounds = tree.order[first as usize..next.1 as usize]
            .iter()
            .fold(Aabb::EMPTY, |b, &t| b.union(boxes[t as usize]));
        BuildNode::Leaf { bounds, first, count: n as u32 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cluster of `t` random triangles over up to 255 vertices.
    fn cluster(seed: u64, t: usize) -> PageCluster {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut rnd = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let v = (t + 2).min(255);
        let positions = (0..v).map(|_| [0; 3].map(|_: u32| (rnd() % 5000) as u32 + 1_000_000)).collect();
        let indices = (0..3 * t).map(|_| (rnd() % v as u64) as u8).collect();
        PageCluster { positions, indices, objects: vec![0; t], ..Default::default() }
    }

    fn validate(bvh: &TriangleBvh, c: &PageCluster, step: f64) {
        let positions: Vec<[f32; 3]> = c.positions.iter().map(|&g| scene_position(g, step)).collect();
        let tris: Vec<[u32; 3]> =
            c.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]].map(u32::from)).collect();
        bvh.validate(&positions, &tris).unwrap();
    }

    /// The BVH from a stored shape is the one built at run time, bit for bit (compared through
    /// `Debug`, which prints every float exactly), for random clusters of every size.
    #[test]
    fn stored_shape_gives_the_built_bvh() {
        for t in 1..=128 {
            for seed in 0..3 {
                let c = cluster(seed * 1000 + t as u64, t);
                let step = 0.001 * (seed + 1) as f64;
                let tree = cluster_tree(&c, step).unwrap();
                let stored = bvh_from_tree(&c, step, &tree).unwrap();
                let built = crate::scene::blas::ClusterBlas::build(&c, step).bvh;
                assert_eq!(format!("{stored:?}"), format!("{built:?}"), "{t} triangles, seed {seed}");
                validate(&stored, &c, step);
            }
        }
    }

    /// Any valid shape (here: not the SAH's) gives a correct BVH: it finds every triangle.
    #[test]
    fn any_valid_shape_is_correct() {
        let c = cluster(7, 100);
        let tree = RtTree::halving(100);
        let bvh = bvh_from_tree(&c, 0.01, &tree).unwrap();
        validate(&bvh, &c, 0.01);
        let built = crate::scene::blas::ClusterBlas::build(&c, 0.01).bvh;
        for i in 0..400 {
            let x = 10_000.0 + (i % 20) as f32 * 2.5;
            let y = 10_000.0 + (i / 20) as f32 * 2.5;
            let ray = crate::Ray::new(Vec3::new(x, y, 0.0), Vec3::Z);
            let (a, b) = (bvh.intersect(&ray), built.intersect(&ray));
            assert_eq!(a.map(|h| (h.t, h.prim)), b.map(|h| (h.t, h.prim)));
        }
        assert!(bvh_from_tree(&c, 0.01, &RtTree::halving(99)).is_err());
    }
}
