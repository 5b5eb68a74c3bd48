//! The public box BVH: build, query the layout, traverse with a closure for leaves.

use crate::aabb::{Aabb, SlabRay};
use crate::build::{build_binary, BuildOptions};
use crate::packet::{traverse_packet, Packet, PacketLeaves};
use crate::ray::Ray;
use crate::simd::Simd;
use crate::spatial_split::{build_binary_spatial, SpatialSplits};
use crate::traverse::{traverse, LeafVisitor, NodeRay, Visit};
use crate::wide::{collapse, Leaf, WideNode};

/// A wide bounding volume hierarchy over primitive boxes.
///
/// Built by binned SAH, collapsed to 8-wide nodes. Leaves hold up to
/// [`BuildOptions::max_leaf_size`] primitives as ranges of [`Bvh::prim_indices`].
#[derive(Clone, Debug)]
pub struct Bvh {
    pub(crate) nodes: Vec<WideNode>,
    pub(crate) leaves: Vec<Leaf>,
    pub(crate) prim_indices: Vec<u32>,
    pub(crate) bounds: Aabb,
}

impl Bvh {
    /// Builds over `boxes` (primitive `i` has box `boxes[i]`) with the default options (leaves of
    /// at most 4). Empty or non-finite boxes are allowed: such primitives are never reached.
    pub fn build(boxes: &[Aabb]) -> Bvh {
        Bvh::build_with(boxes, &BuildOptions::default())
    }

    /// Builds with explicit options (e.g. `max_leaf_size: 1` for a top-level BVH over
    /// instances).
    pub fn build_with(boxes: &[Aabb], options: &BuildOptions) -> Bvh {
        Bvh::from_binary(build_binary(boxes, options))
    }

    /// Builds over triangles (`boxes[i]` the box of `tris[i]`) with spatial splits: a triangle
    /// may then sit in several leaves, each box holding only its part there, so
    /// [`Bvh::prim_indices`] can be longer than `boxes` (see `spatial_split`).
    pub(crate) fn build_spatial(
        tris: &[[glam::Vec3; 3]],
        boxes: &[Aabb],
        options: &BuildOptions,
        splits: &SpatialSplits,
    ) -> Bvh {
        Bvh::from_binary(build_binary_spatial(tris, boxes, options, splits))
    }

    /// Collapses a binary build into the wide layout.
    fn from_binary((root, prim_indices): (Option<crate::build::BuildNode>, Vec<u32>)) -> Bvh {
        let Some(root) = root else {
            return Bvh { nodes: Vec::new(), leaves: Vec::new(), prim_indices, bounds: Aabb::EMPTY };
        };
        let bounds = root.bounds();
        let (nodes, leaves) = collapse(&root);
        Bvh { nodes, leaves, prim_indices, bounds }
    }

    /// The primitive indices in leaf order: every leaf is a contiguous range of this slice.
    pub fn prim_indices(&self) -> &[u32] {
        &self.prim_indices
    }

    /// The box of everything in the tree.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Number of wide nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Number of leaves.
    pub fn leaf_count(&self) -> usize {
        self.leaves.len()
    }

    /// Bytes held by nodes, leaves and the index order.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<WideNode>()
            + self.leaves.len() * std::mem::size_of::<Leaf>()
            + self.prim_indices.len() * 4
    }

    /// Visits the primitives whose boxes `ray` passes through, near leaves first. `leaf(prim,
    /// ray)` tests primitive `prim` (an index into the build's `boxes`) and returns true when it
    /// hit, after shrinking `ray.t_max` to the hit, so later boxes beyond it are culled. Returns
    /// true when any call returned true.
    pub fn traverse(&self, ray: &mut Ray, mut leaf: impl FnMut(u32, &mut Ray) -> bool) -> bool {
        let mut any = false;
        self.walk(ray, Simd::detect(), |prim, r| {
            any |= leaf(prim, r);
            Visit::Continue
        });
        any
    }

    /// Like [`Bvh::traverse`] but stops at the first primitive for which `leaf` returns true
    /// (an any-hit query, for shadow rays); returns whether that happened.
    pub fn traverse_any(&self, ray: &mut Ray, mut leaf: impl FnMut(u32, &mut Ray) -> bool) -> bool {
        self.walk(ray, Simd::detect(), |prim, r| if leaf(prim, r) { Visit::Stop } else { Visit::Continue })
    }

    /// The shared walk: node tests on the chosen instruction set, `visit` per primitive.
    fn walk(&self, ray: &mut Ray, simd: Simd, visit: impl FnMut(u32, &mut Ray) -> Visit) -> bool {
        let node_ray = NodeRay::new(&SlabRay::new(ray));
        let t_min = ray.t_min;
        let mut t_max = ray.t_max;
        let mut prims = Prims { bvh: self, ray, visit };
        #[cfg(target_arch = "x86_64")]
        if simd.usable() == Simd::Avx2 {
            // SAFETY: `usable` checked that the CPU has AVX2 and FMA.
            return unsafe { walk_avx2(&self.nodes, &node_ray, t_min, &mut t_max, &mut prims) };
        }
        let _ = simd;
        traverse(&self.nodes, &node_ray, t_min, &mut t_max, &mut prims)
    }
}

/// The primitive handler of [`Bvh::traverse_packet`] (a trait for the reason given at
/// [`crate::traverse::LeafVisitor`]).
pub(crate) trait PrimPackets<const N: usize> {
    /// Tests the rays `lanes` (bit per lane) of `p` against primitive `prim`, shrinking the
    /// `p.t_max` of those that hit.
    fn visit(&mut self, prim: u32, lanes: u32, p: &mut Packet<N>);
}

impl Bvh {
    /// The packet counterpart of [`Bvh::traverse`]: walks the tree with the whole packet and
    /// hands each primitive whose leaf some ray enters to `prims`, with the mask of those rays.
    /// Compiled for whichever instruction set its caller is.
    #[inline(always)]
    pub(crate) fn traverse_packet<const N: usize, V: PrimPackets<N>>(
        &self,
        p: &mut Packet<N>,
        prims: &mut V,
    ) {
        traverse_packet(&self.nodes, p, &mut PacketPrims { bvh: self, prims });
    }
}

/// Leaf handler of [`Bvh::traverse_packet`]: the primitives of the leaf, one by one.
struct PacketPrims<'a, V> {
    bvh: &'a Bvh,
    prims: &'a mut V,
}

impl<const N: usize, V: PrimPackets<N>> PacketLeaves<N> for PacketPrims<'_, V> {
    #[inline(always)]
    fn visit(&mut self, leaf: u32, lanes: u32, p: &mut Packet<N>) {
        let Leaf { first, count } = self.bvh.leaves[leaf as usize];
        for &prim in &self.bvh.prim_indices[first as usize..(first + count) as usize] {
            self.prims.visit(prim, lanes, p);
        }
    }
}

/// Leaf visitor of [`Bvh::traverse`]: the caller's closure per primitive of the leaf.
struct Prims<'a, F> {
    bvh: &'a Bvh,
    ray: &'a mut Ray,
    visit: F,
}

impl<F: FnMut(u32, &mut Ray) -> Visit> LeafVisitor for Prims<'_, F> {
    #[inline(always)]
    fn visit(&mut self, leaf: u32, t_max: &mut f32) -> Visit {
        let Leaf { first, count } = self.bvh.leaves[leaf as usize];
        for &prim in &self.bvh.prim_indices[first as usize..(first + count) as usize] {
            self.ray.t_max = *t_max;
            let v = (self.visit)(prim, self.ray);
            *t_max = self.ray.t_max;
            if v == Visit::Stop {
                return Visit::Stop;
            }
        }
        Visit::Continue
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn walk_avx2(
    nodes: &[WideNode],
    r: &NodeRay,
    t_min: f32,
    t_max: &mut f32,
    leaves: &mut impl LeafVisitor,
) -> bool {
    traverse(nodes, r, t_min, t_max, leaves)
}
