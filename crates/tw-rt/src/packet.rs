//! Packet traversal for coherent rays: 8 rays (or another width up to 32) walk the tree
//! together.
//!
//! Node culling uses interval arithmetic over the packet (the "ranged" or frustum-like test of
//! Wald, Boulos & Shirley 2007, "Ray Tracing Deformable Scenes using Dynamic Bounding Volume
//! Hierarchies", section 4; Reshetov et al. 2005): from the bounds of the packet's origins and
//! inverse directions, one lower bound of the entry distance and one upper bound of the exit
//! distance per child are computed for all rays at once, so a node costs about as much as for a
//! single ray however many rays the packet has. Leaves test each triangle against the 8 rays in
//! SIMD (the same watertight code as the single-ray path, so the results are identical).
//! Packets whose rays disagree in direction signs or in the watertight axis permutation are
//! traced ray by ray.
//!
//! The walk ([`traverse_packet`]) hands leaves to a visitor with the mask of rays entering
//! them, so it serves both a triangle BVH (triangle tests at the leaves) and the top level of a
//! two-level scene, whose leaves walk a cluster's BVH with the same prepared packet for the
//! rays that reached them ([`traverse_packet_lanes`]).

use crate::aabb::{max, min, ROBUST_FAR};
use crate::mesh::TriangleBvh;
use crate::ray::{Hit, Ray};
use crate::simd::Simd;
use crate::traverse::{prefetch, prefetch_children, Stack};
use crate::triangle::{lanes, Shear, TriGroup};
use crate::wide::{WideNode, LEAF, W};

/// Rays per packet of [`TriangleBvh::intersect_packet`] (one AVX2 register per value). The
/// traversal is generic in the width: a two-level scene uses wider packets (`scene::cut`).
pub const PACKET: usize = 8;

/// A packet of `N` rays (at most 32: lane masks are `u32`) prepared for traversal.
pub(crate) struct Packet<const N: usize> {
    /// Per-ray origins, `o[axis][lane]`.
    o: [[f32; N]; 3],
    /// Per-ray inverse directions, `inv[axis][lane]`.
    inv: [[f32; N]; 3],
    /// Shear per lane in the common permutation `k`.
    s: [[f32; N]; 3],
    k: [usize; 3],
    t_min: [f32; N],
    t_max: [f32; N],
    /// Interval data: origin bound to subtract from the near / far plane, inverse bounds.
    o_near: [f32; 3],
    o_far: [f32; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
    /// The near box side per axis (0: min, 1: max), as in `traverse::NodeRay`.
    near: [usize; 3],
    t_min_all: f32,
    /// All rays start at the same point (primary rays of a pinhole camera): the leaf test then
    /// subtracts the origin once per vertex instead of once per lane.
    common_origin: bool,
}

impl<const N: usize> Packet<N> {
    /// The lane mask of a full packet.
    pub(crate) const ALL: u32 = {
        assert!(N >= 1 && N <= 32, "lane masks are u32");
        u32::MAX >> (32 - N)
    };

    /// `None` when the rays cannot share one traversal (mixed direction signs or mixed
    /// watertight permutations). Lanes beyond `rays.len()` repeat ray 0 with an empty interval.
    /// Computed lane-parallel: the per-ray divisions (inverse directions, shear) were a tenth
    /// of the packet time when done ray by ray.
    #[inline(always)]
    pub(crate) fn new(rays: &[Ray]) -> Option<Packet<N>> {
        let first = rays.first()?;
        let k = Shear::axes(first.dir.to_array());
        let mut d = [[0.0f32; N]; 3];
        let mut p = Packet {
            o: [[0.0; N]; 3],
            inv: [[0.0; N]; 3],
            s: [[0.0; N]; 3],
            k,
            t_min: [first.t_min; N],
            t_max: [f32::NEG_INFINITY; N],
            o_near: [0.0; 3],
            o_far: [0.0; 3],
            inv_lo: [0.0; 3],
            inv_hi: [0.0; 3],
            near: [0; 3],
            t_min_all: first.t_min,
            common_origin: true,
        };
        for lane in 0..N {
            let r = rays.get(lane).unwrap_or(first);
            for a in 0..3 {
                d[a][lane] = r.dir[a];
                p.o[a][lane] = r.origin[a];
            }
            if lane < rays.len() {
                p.t_min[lane] = r.t_min;
                p.t_max[lane] = r.t_max;
            }
        }
        let neg = [0, 1, 2].map(|a| d[a][0].is_sign_negative());
        if !uniform_lanes(&d) {
            return None;
        }
        for lane in 1..N {
            for a in 0..3 {
                p.common_origin &= p.o[a][lane].to_bits() == p.o[a][0].to_bits();
            }
        }
        let [kx, ky, kz] = k;
        for lane in 0..N {
            for a in 0..3 {
                p.inv[a][lane] = 1.0 / d[a][lane];
            }
            // The same operations as `Shear::new`, so the lanes match the single-ray path.
            p.s[0][lane] = d[kx][lane] / d[kz][lane];
            p.s[1][lane] = d[ky][lane] / d[kz][lane];
            p.s[2][lane] = 1.0 / d[kz][lane];
        }
        p.t_min_all = reduce(&p.t_min, min);
        for a in 0..3 {
            let (o_lo, o_hi) = (reduce(&p.o[a], min), reduce(&p.o[a], max));
            (p.inv_lo[a], p.inv_hi[a]) = (reduce(&p.inv[a], min), reduce(&p.inv[a], max));
            // Entry distances are smallest from the origin nearest the near plane, exits
            // largest from the origin farthest from the far plane.
            p.near[a] = neg[a] as usize;
            (p.o_near[a], p.o_far[a]) = if neg[a] { (o_lo, o_hi) } else { (o_hi, o_lo) };
        }
        Some(p)
    }

    #[inline(always)]
    fn t_max_any(&self) -> f32 {
        reduce(&self.t_max, max)
    }
}

/// True when all lanes of the directions `d` share the watertight permutation and the
/// direction signs: one small code per lane (major axis and sign bits), computed branch-free
/// for all lanes at once and compared with lane 0's. (Written lane by lane with
/// `Shear::major_axis`'s branches, the packet set-up around this check was about a fifth of
/// the packet time on a 24 M triangle CAD model, by perf.)
#[inline(always)]
fn uniform_lanes<const N: usize>(d: &[[f32; N]; 3]) -> bool {
    let mut code = [0u32; N];
    for lane in 0..N {
        let (x, y, z) = (d[0][lane].abs(), d[1][lane].abs(), d[2][lane].abs());
        // `Shear::major_axis`: x on ties with y or z, then y on ties with z.
        let x_major = (x >= y) & (x >= z);
        let y_major = !x_major & (y >= z);
        let major = !x_major as u32 + (!x_major & !y_major) as u32;
        let signs = d[0][lane].to_bits() >> 31
            | (d[1][lane].to_bits() >> 31) << 1
            | (d[2][lane].to_bits() >> 31) << 2;
        code[lane] = major | signs << 2;
    }
    let mut same = true;
    for lane in 1..N {
        same &= code[lane] == code[0];
    }
    same
}

/// `f` (a `min` or `max`) over the lanes, as a tree of halves: the compiler keeps a chain of
/// scalar steps as written, while halving lets it use vector instructions. The result is the
/// same value as a chain's for lanes without NaN (up to the sign of a zero, which no box test
/// can tell apart).
#[inline(always)]
fn reduce<const N: usize>(v: &[f32; N], f: impl Fn(f32, f32) -> f32) -> f32 {
    let mut a = *v;
    let mut n = N;
    while n > 1 {
        let h = n / 2;
        for i in 0..h {
            a[i] = f(a[i + n - h], a[i]);
        }
        n -= h;
    }
    a[0]
}

/// The slots of `node` whose child is a leaf.
#[inline(always)]
fn leaf_mask(node: &WideNode) -> u32 {
    let mut mask = 0;
    for i in 0..W {
        mask |= (node.child[i] >> 31) << i;
    }
    mask
}

/// Conservative entry distances of the `W` children for the whole packet and the mask of
/// children some ray may enter before `t_max_any`.
#[inline(always)]
fn node_hits<const N: usize>(node: &WideNode, p: &Packet<N>, t_max_any: f32) -> ([f32; W], u32) {
    let b = &node.bounds;
    let mut near = [0.0f32; W];
    let mut hit = [false; W];
    for i in 0..W {
        let mut n = p.t_min_all;
        let mut f = f32::INFINITY;
        for a in 0..3 {
            let dn = b[p.near[a] & 1][a][i] - p.o_near[a];
            // NaN products (0 * inf) are ignored: candidates come first (see `aabb`).
            n = max(min(dn * p.inv_lo[a], dn * p.inv_hi[a]), n);
            let df = b[(p.near[a] ^ 1) & 1][a][i] - p.o_far[a];
            f = min(max(df * p.inv_lo[a], df * p.inv_hi[a]), f);
        }
        near[i] = n;
        hit[i] = n <= min(f * ROBUST_FAR, t_max_any);
    }
    let mut mask = 0u32;
    for (i, h) in hit.iter().enumerate() {
        mask |= (*h as u32) << i;
    }
    (near, mask)
}

/// The rays of the packet that enter child `slot`'s box before their current hits (bit per
/// lane). The interval test is conservative for the packet as a whole; leaf children also pass
/// this per-ray test, with the box still in cache from the node test, and the mask they carry
/// on the stack decides how their triangles are tested (see `TriPackets::visit`).
#[inline(always)]
fn lanes_entering<const N: usize>(node: &WideNode, slot: usize, p: &Packet<N>) -> u32 {
    let b = &node.bounds;
    let mut hit = [false; N];
    for lane in 0..N {
        let mut n = p.t_min[lane];
        let mut f = f32::INFINITY;
        for a in 0..3 {
            let near_plane = b[p.near[a] & 1][a][slot];
            let far_plane = b[(p.near[a] ^ 1) & 1][a][slot];
            n = max((near_plane - p.o[a][lane]) * p.inv[a][lane], n);
            f = min((far_plane - p.o[a][lane]) * p.inv[a][lane], f);
        }
        hit[lane] = n <= min(f * ROBUST_FAR, p.t_max[lane]);
    }
    let mut mask = 0;
    for (lane, h) in hit.iter().enumerate() {
        mask |= (*h as u32) << lane;
    }
    mask
}

/// Leaves entered by at most this many rays of a packet test them one by one against the
/// leaf's 4 triangles at once, instead of each triangle against all 8 lanes. Measured on the
/// dragon: 3 beat 2 and equalled 5 and 8. (Handing whole subtrees entered by few rays to
/// single-ray traversal, as Embree's hybrid mode does, measured slower here; so did tracing
/// the rays of a two-level scene's cluster one by one when at most 2, 4 or 8 of 16 reach it.)
const FEW_RAYS: u32 = 3;

/// The leaf handler of [`traverse_packet`] (a trait rather than a closure for the reason given
/// at [`crate::traverse::LeafVisitor`]: it must inline into the AVX2 entry points).
pub(crate) trait PacketLeaves<const N: usize> {
    /// Tests the rays `lanes` (bit per lane) of `p` against leaf `leaf`, shrinking `p.t_max` of
    /// those that hit.
    fn visit(&mut self, leaf: u32, lanes: u32, p: &mut Packet<N>);

    /// Prefetches what [`PacketLeaves::visit`] will read for `leaf`.
    fn prefetch(&self, _leaf: u32) {}
}

/// Walks the tree of `nodes` with the whole packet: interval culling of inner children
/// ([`node_hits`]), a per-ray test of leaf children ([`lanes_entering`]), and every reached leaf
/// handed to `leaves` with the mask of rays entering it, near leaves first (roughly). One walk
/// serves both triangle BVHs and the top level of a two-level scene, whose leaf handler walks a
/// cluster's tree with the same packet ([`traverse_packet_lanes`]).
#[inline(always)]
pub(crate) fn traverse_packet<const N: usize, V: PacketLeaves<N>>(
    nodes: &[WideNode],
    p: &mut Packet<N>,
    leaves: &mut V,
) {
    if nodes.is_empty() {
        return;
    }
    let mut t_max_any = p.t_max_any();
    let mut stack = Stack::<u32>::new();
    let (mut cur, mut cur_lanes) = (0u32, Packet::<N>::ALL);
    loop {
        if cur & LEAF == 0 {
            let node = &nodes[cur as usize];
            let (near, mut mask) = node_hits(node, p, t_max_any);
            let mut lanes_in = [Packet::<N>::ALL; W];
            let mut leaf_slots = mask & leaf_mask(node);
            while leaf_slots != 0 {
                let slot = leaf_slots.trailing_zeros() as usize;
                leaf_slots &= leaf_slots - 1;
                lanes_in[slot] = lanes_entering(node, slot, p);
                if lanes_in[slot] == 0 {
                    mask &= !(1 << slot);
                }
            }
            if mask != 0 {
                prefetch_children(nodes, &node.child, mask, |l| leaves.prefetch(l));
                (cur, cur_lanes) = stack.push_sorted_pop_nearest(&node.child, &near, &lanes_in, mask);
                continue;
            }
        } else {
            leaves.visit(cur & !LEAF, cur_lanes, p);
            t_max_any = p.t_max_any();
        }
        match stack.pop_within(t_max_any) {
            Some(entry) => (cur, cur_lanes) = entry,
            None => break,
        }
    }
}

/// [`traverse_packet`] for the rays `lanes` of the packet only (a cluster's tree entered by part
/// of a packet): the other rays' `t_max` is -inf during the walk, so no box or triangle test
/// passes for them and they do not widen the packet's cull distance, and is restored after.
#[inline(always)]
pub(crate) fn traverse_packet_lanes<const N: usize, V: PacketLeaves<N>>(
    nodes: &[WideNode],
    p: &mut Packet<N>,
    lanes: u32,
    leaves: &mut V,
) {
    let saved = p.t_max;
    for lane in 0..N {
        if lanes & (1 << lane) == 0 {
            p.t_max[lane] = f32::NEG_INFINITY;
        }
    }
    traverse_packet(nodes, p, leaves);
    for lane in 0..N {
        if lanes & (1 << lane) == 0 {
            p.t_max[lane] = saved[lane];
        }
    }
}

impl TriangleBvh {
    /// Closest hits of `rays` into `hits` (index by index), tracing them in packets of
    /// [`PACKET`]: fastest when consecutive rays are coherent (neighbouring pixels). Results
    /// equal [`TriangleBvh::intersect`]'s up to ties. Only `min(rays.len(), hits.len())` rays
    /// are traced.
    pub fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.intersect_packet_simd(rays, hits, Simd::detect())
    }

    /// [`TriangleBvh::intersect_packet`] on a chosen instruction set.
    pub fn intersect_packet_simd(&self, rays: &[Ray], hits: &mut [Option<Hit>], simd: Simd) {
        #[cfg(target_arch = "x86_64")]
        if simd.usable() == Simd::Avx2 {
            // SAFETY: `usable` checked that the CPU has AVX2 and FMA.
            return unsafe { self.packets_avx2(rays, hits) };
        }
        let _ = simd;
        self.packets_impl(rays, hits)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn packets_avx2(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.packets_impl(rays, hits)
    }

    #[inline(always)]
    fn packets_impl(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        for (r, h) in rays.chunks(PACKET).zip(hits.chunks_mut(PACKET)) {
            match Packet::<PACKET>::new(r) {
                Some(mut p) => {
                    let mut best = [None; PACKET];
                    self.packet_lanes(&mut p, Packet::<PACKET>::ALL, &mut best, 0);
                    for (h, b) in h.iter_mut().zip(best) {
                        *h = b;
                    }
                }
                None => {
                    for (ray, hit) in r.iter().zip(h.iter_mut()) {
                        *hit = self.intersect_impl(ray);
                    }
                }
            }
        }
    }

    /// Traces the rays `lanes` of a prepared packet, each within its current `[t_min, t_max]`;
    /// a nearer hit replaces `best[lane]` (with `tag | triangle` as its primitive) and shrinks
    /// the lane's `t_max`.
    #[inline(always)]
    pub(crate) fn packet_lanes<const N: usize>(
        &self,
        p: &mut Packet<N>,
        lanes: u32,
        best: &mut [Option<Hit>; N],
        tag: u32,
    ) {
        let nodes = &self.bvh.nodes;
        if p.common_origin {
            traverse_packet_lanes(
                nodes,
                p,
                lanes,
                &mut TriPackets::<N, true> { groups: &self.groups, best, tag },
            );
        } else {
            traverse_packet_lanes(
                nodes,
                p,
                lanes,
                &mut TriPackets::<N, false> { groups: &self.groups, best, tag },
            );
        }
    }
}

/// Leaf handler of triangle packets: the closest hits so far, per lane.
struct TriPackets<'a, const N: usize, const COMMON_ORIGIN: bool> {
    groups: &'a [TriGroup],
    best: &'a mut [Option<Hit>; N],
    /// ORed into every hit's primitive (a two-level scene's cluster bits; 0 for a mesh).
    tag: u32,
}

impl<const N: usize, const COMMON_ORIGIN: bool> PacketLeaves<N> for TriPackets<'_, N, COMMON_ORIGIN> {
    /// Tests the rays `lanes_in` against every triangle of leaf `leaf`.
    #[inline(always)]
    fn visit(&mut self, leaf: u32, lanes_in: u32, p: &mut Packet<N>) {
        let g = &self.groups[leaf as usize];
        if lanes_in.count_ones() <= FEW_RAYS {
            // Ray by ray: one 4-lane test covers the whole group; the same arithmetic per
            // (triangle, ray) pair as below, so the hits are identical.
            let mut m = lanes_in;
            while m != 0 {
                let lane = m.trailing_zeros() as usize;
                m &= m - 1;
                let origin = [p.o[0][lane], p.o[1][lane], p.o[2][lane]];
                let shear = Shear { k: p.k, s: [p.s[0][lane], p.s[1][lane], p.s[2][lane]] };
                if let Some((tri, t, u, v)) = g.intersect(&origin, &shear, p.t_min[lane], p.t_max[lane]) {
                    p.t_max[lane] = t;
                    self.best[lane] = Some(Hit { t, prim: self.tag | g.prim[tri], u, v });
                }
            }
            return;
        }
        for tri in 0..g.count() {
            let rel = |vert: usize| {
                let mut r = [[0.0f32; N]; 3];
                for (j, &axis) in p.k.iter().enumerate() {
                    let v = g.v[vert][axis][tri];
                    if COMMON_ORIGIN {
                        // The same value every lane would compute, computed once.
                        r[j] = [v - p.o[axis][0]; N];
                    } else {
                        for lane in 0..N {
                            r[j][lane] = v - p.o[axis][lane];
                        }
                    }
                }
                r
            };
            let h = lanes::<N>(&rel(0), &rel(1), &rel(2), &p.s, &p.t_min, &p.t_max);
            let mut m = h.mask;
            while m != 0 {
                let lane = m.trailing_zeros() as usize;
                m &= m - 1;
                p.t_max[lane] = h.t[lane];
                self.best[lane] =
                    Some(Hit { t: h.t[lane], prim: self.tag | g.prim[tri], u: h.u[lane], v: h.v[lane] });
            }
        }
    }

    #[inline(always)]
    fn prefetch(&self, leaf: u32) {
        if let Some(g) = self.groups.get(leaf as usize) {
            prefetch(g);
        }
    }
}
