//! A BVH over an indexed triangle mesh: single-ray closest hit and occlusion.

use glam::Vec3;

use crate::aabb::{Aabb, SlabRay};
use crate::build::BuildOptions;
use crate::bvh::Bvh;
use crate::image::Trace;
use crate::ray::{Hit, Ray};
use crate::simd::Simd;
use crate::spatial_split::SpatialSplits;
use crate::traverse::{prefetch, traverse, LeafVisitor, NodeRay, Visit};
use crate::triangle::{Shear, TriGroup, GROUP};
use crate::wide::Leaf;

/// Why a mesh cannot be built.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum MeshError {
    #[error("triangle {triangle} refers to vertex {vertex}, but there are only {vertices} vertices")]
    VertexOutOfRange { triangle: usize, vertex: u32, vertices: usize },
    #[error("{0} triangles: at most 2^31 - 1 are supported")]
    TooManyTriangles(usize),
}

/// A wide BVH over triangles with their vertices copied into the leaves (groups of 4 in SIMD
/// order), so traversal never touches the input arrays.
#[derive(Clone, Debug)]
pub struct TriangleBvh {
    pub(crate) bvh: Bvh,
    /// `groups[i]` holds the triangles of leaf `i`.
    pub(crate) groups: Vec<TriGroup>,
}

impl TriangleBvh {
    /// Builds over `triangles` (vertex indices into `positions`). Degenerate triangles and
    /// triangles with non-finite vertices are kept but never hit. `Hit::prim` is an index into
    /// `triangles`. Object splits only: see [`TriangleBvh::build_with`] for spatial splits.
    pub fn build(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Result<TriangleBvh, MeshError> {
        TriangleBvh::build_with(positions, triangles, None)
    }

    /// [`TriangleBvh::build`] with spatial splits (`Some`) or without (`None`). With them a
    /// triangle that crosses a split plane may be copied into several leaves (up to the
    /// budget), each leaf's box holding only its part: tighter boxes for long triangles at the
    /// cost of a slower build and more memory. Not the default because it did not pay on the
    /// models measured: on a 24 M triangle CAD assembly (`terawalk generate assembly
    /// --one-object`) primary-ray packets were as fast as without (within 3 %, run to run) for
    /// a build 3 times as long and 2.5 % more memory; on the Stanford dragon packets gained
    /// about 1 % for a build 4 times as long.
    pub fn build_with(
        positions: &[[f32; 3]],
        triangles: &[[u32; 3]],
        spatial_splits: Option<SpatialSplits>,
    ) -> Result<TriangleBvh, MeshError> {
        if triangles.len() >= (1 << 31) {
            return Err(MeshError::TooManyTriangles(triangles.len()));
        }
        let corners = triangles
            .iter()
            .enumerate()
            .map(|(t, tri)| {
                let p = |k: usize| {
                    positions.get(tri[k] as usize).map(|&q| Vec3::from(q)).ok_or(
                        MeshError::VertexOutOfRange {
                            triangle: t,
                            vertex: tri[k],
                            vertices: positions.len(),
                        },
                    )
                };
                Ok([p(0)?, p(1)?, p(2)?])
            })
            .collect::<Result<Vec<_>, _>>()?;
        let boxes: Vec<Aabb> = corners.iter().map(|c| Aabb::from_points(c)).collect();
        let options = BuildOptions { max_leaf_size: GROUP, block_size: GROUP, traversal_cost: 1.0 };
        let bvh = match spatial_splits {
            Some(splits) => Bvh::build_spatial(&corners, &boxes, &options, &splits),
            None => Bvh::build_with(&boxes, &options),
        };
        Ok(TriangleBvh::with_leaves(bvh, &corners))
    }

    /// `bvh` over the triangles `corners` (its leaves index them), with each leaf's triangles
    /// copied into its SIMD group: the last step of a build, and of a stored shape's refit
    /// (`scene::stored`).
    pub(crate) fn with_leaves(bvh: Bvh, corners: &[[Vec3; 3]]) -> TriangleBvh {
        let groups = bvh
            .leaves
            .iter()
            .map(|&Leaf { first, count }| {
                let prims = &bvh.prim_indices[first as usize..(first + count) as usize];
                let tris: Vec<_> = prims.iter().map(|&p| (corners[p as usize], p)).collect();
                TriGroup::new(&tris)
            })
            .collect();
        TriangleBvh { bvh, groups }
    }

    /// The underlying box BVH (its leaves index `prim_indices`, i.e. triangle indices).
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// Bytes of nodes, leaf records, index order and triangle groups.
    pub fn memory_bytes(&self) -> usize {
        self.bvh.memory_bytes() + self.groups.len() * std::mem::size_of::<TriGroup>()
    }

    /// The nearest hit along `ray` within `[t_min, t_max)`.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.intersect_simd(ray, Simd::detect())
    }

    /// [`TriangleBvh::intersect`] on a chosen instruction set (tests force the portable path).
    pub fn intersect_simd(&self, ray: &Ray, simd: Simd) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if simd.usable() == Simd::Avx2 {
            // SAFETY: `usable` checked that the CPU has AVX2 and FMA.
            return unsafe { self.intersect_avx2(ray) };
        }
        let _ = simd;
        self.intersect_impl(ray)
    }

    /// True when anything blocks `ray` within `[t_min, t_max)`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.occluded_simd(ray, Simd::detect())
    }

    /// [`TriangleBvh::occluded`] on a chosen instruction set.
    pub fn occluded_simd(&self, ray: &Ray, simd: Simd) -> bool {
        #[cfg(target_arch = "x86_64")]
        if simd.usable() == Simd::Avx2 {
            // SAFETY: `usable` checked that the CPU has AVX2 and FMA.
            return unsafe { self.occluded_avx2(ray) };
        }
        let _ = simd;
        self.occluded_impl(ray)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn intersect_avx2(&self, ray: &Ray) -> Option<Hit> {
        self.intersect_impl(ray)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn occluded_avx2(&self, ray: &Ray) -> bool {
        self.occluded_impl(ray)
    }

    #[inline(always)]
    pub(crate) fn intersect_impl(&self, ray: &Ray) -> Option<Hit> {
        let node_ray = NodeRay::new(&SlabRay::new(ray));
        let mut closest = Closest { groups: &self.groups, ray: GroupRay::new(ray), hit: None };
        let mut t_max = ray.t_max;
        traverse(&self.bvh.nodes, &node_ray, ray.t_min, &mut t_max, &mut closest);
        closest.hit
    }

    #[inline(always)]
    fn occluded_impl(&self, ray: &Ray) -> bool {
        let node_ray = NodeRay::new(&SlabRay::new(ray));
        let mut any = AnyHit { groups: &self.groups, ray: GroupRay::new(ray) };
        let mut t_max = ray.t_max;
        traverse(&self.bvh.nodes, &node_ray, ray.t_min, &mut t_max, &mut any)
    }
}

/// What the leaf tests need of a ray.
struct GroupRay {
    origin: [f32; 3],
    shear: Shear,
    t_min: f32,
}

impl GroupRay {
    #[inline(always)]
    fn new(ray: &Ray) -> GroupRay {
        GroupRay { origin: ray.origin.to_array(), shear: Shear::new(ray.dir), t_min: ray.t_min }
    }
}

/// Leaf visitor of closest-hit queries.
struct Closest<'a> {
    groups: &'a [TriGroup],
    ray: GroupRay,
    hit: Option<Hit>,
}

impl LeafVisitor for Closest<'_> {
    #[inline(always)]
    fn visit(&mut self, leaf: u32, t_max: &mut f32) -> Visit {
        let g = &self.groups[leaf as usize];
        if let Some((lane, t, u, v)) = g.intersect(&self.ray.origin, &self.ray.shear, self.ray.t_min, *t_max)
        {
            *t_max = t;
            self.hit = Some(Hit { t, prim: g.prim[lane], u, v });
        }
        Visit::Continue
    }

    #[inline(always)]
    fn prefetch(&self, leaf: u32) {
        if let Some(g) = self.groups.get(leaf as usize) {
            prefetch(g);
        }
    }
}

/// Leaf visitor of occlusion queries: stops at the first hit.
struct AnyHit<'a> {
    groups: &'a [TriGroup],
    ray: GroupRay,
}

impl LeafVisitor for AnyHit<'_> {
    #[inline(always)]
    fn visit(&mut self, leaf: u32, t_max: &mut f32) -> Visit {
        match self.groups[leaf as usize].occluded(&self.ray.origin, &self.ray.shear, self.ray.t_min, *t_max) {
            true => Visit::Stop,
            false => Visit::Continue,
        }
    }

    #[inline(always)]
    fn prefetch(&self, leaf: u32) {
        if let Some(g) = self.groups.get(leaf as usize) {
            prefetch(g);
        }
    }
}

impl Trace for TriangleBvh {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        TriangleBvh::intersect(self, ray)
    }

    fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        TriangleBvh::intersect_packet(self, rays, hits)
    }
}
