//! A frame's LOD cut as one two-level scene: a top-level BVH over the cut's clusters, each
//! with its own cluster BVH ([`super::blas`]). Rays see exactly the triangles the rasterizer
//! draws for the same cut, so both renderers agree on what is where (docs/DESIGN.md D8).

use std::sync::Arc;

use glam::Vec3;

use super::blas::ClusterBlas;
use crate::{Aabb, BuildOptions, Bvh, Hit, Ray, Trace};

/// Bits of [`Hit::prim`] that hold the triangle's index in its cluster (clusters hold at most
/// 128 triangles, docs/FORMAT.md); the bits above hold the cluster's position in the cut.
pub const TRIANGLE_BITS: u32 = 7;

/// The cluster (position in the cut) and the triangle (index in the cluster) of a [`Hit::prim`]
/// from a [`CutScene`].
pub fn split_prim(prim: u32) -> (u32, u32) {
    (prim >> TRIANGLE_BITS, prim & ((1 << TRIANGLE_BITS) - 1))
}

/// How the top-level BVH is built: one cluster per leaf, so that every cluster's box is tested
/// before its BVH is entered (a leaf of several sends a ray into each of them: on a 10^8 plant's
/// interior view 5.9 cluster visits a ray with leaves of up to 4, 3.1 with 1).
const TLAS_BUILD: BuildOptions = BuildOptions { max_leaf_size: 1, traversal_cost: 1.0, block_size: 1 };

/// The clusters of a cut under a top-level BVH, with the camera's clip planes.
pub struct CutScene {
    tlas: Bvh,
    clusters: Vec<Arc<ClusterBlas>>,
    clip: Clip,
}

/// The rasterizer's near and far planes as limits on a ray's parameter: a point is drawn when
/// its view depth (distance along `forward`) lies in `[near, far]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clip {
    pub forward: Vec3,
    pub near: f32,
    pub far: f32,
}

impl Clip {
    /// `ray` limited to the view depths between the planes; `None` for a ray that cannot reach
    /// them (pointing sideways or backwards).
    fn apply(&self, ray: &Ray) -> Option<Ray> {
        let along = ray.dir.dot(self.forward);
        if along <= 0.0 {
            return None;
        }
        let mut r = *ray;
        r.t_min = r.t_min.max(self.near / along);
        r.t_max = r.t_max.min(self.far / along);
        (r.t_min < r.t_max).then_some(r)
    }
}

impl CutScene {
    /// The top-level BVH over `clusters` (the cut, in its order).
    pub fn build(clusters: Vec<Arc<ClusterBlas>>, clip: Clip) -> CutScene {
        let boxes: Vec<Aabb> = clusters.iter().map(|c| c.bounds).collect();
        CutScene { tlas: Bvh::build_with(&boxes, &TLAS_BUILD), clusters, clip }
    }

    /// The same clusters seen with other clip planes (a new camera on an unchanged cut).
    pub fn with_clip(mut self, clip: Clip) -> CutScene {
        self.clip = clip;
        self
    }

    pub fn clusters(&self) -> &[Arc<ClusterBlas>] {
        &self.clusters
    }

    /// Bytes of the top-level BVH.
    pub fn tlas_bytes(&self) -> usize {
        self.tlas.memory_bytes()
    }

    /// Whether anything blocks `ray` within `[t_min, t_max)` (shadow rays; no clip planes: a
    /// light sees what the camera's planes cut away).
    pub fn occluded(&self, ray: &Ray) -> bool {
        let mut r = *ray;
        self.tlas.traverse_any(&mut r, |c, r| self.clusters[c as usize].bvh.occluded(r))
    }
}

impl Trace for CutScene {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let mut ray = self.clip.apply(ray)?;
        let mut best = None;
        self.tlas.traverse(&mut ray, |c, r| match self.clusters[c as usize].bvh.intersect(r) {
            Some(hit) => {
                r.t_max = hit.t;
                best = Some(Hit { prim: (c << TRIANGLE_BITS) | hit.prim, ..hit });
                true
            }
            None => false,
        });
        best
    }
}
