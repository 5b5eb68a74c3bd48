//! A frame's LOD cut as one two-level scene: a top-level BVH over the cut's clusters, each
//! with its own cluster BVH ([`super::blas`]). Rays see exactly the triangles the rasterizer
//! draws for the same cut, so both renderers agree on what is where (docs/DESIGN.md D8).

use std::sync::Arc;

use glam::Vec3;

use super::blas::ClusterBlas;
use crate::bvh::PrimPackets;
use crate::packet::Packet;
use crate::{Aabb, BuildOptions, Bvh, Hit, Ray, Simd, Trace};

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

/// Rays per packet through the two-level scene: 8x2 pixels, two of [`trace_image`]'s 4x2
/// blocks side by side. The top level's node tests cost the same for any packet width (interval
/// culling), so wider packets pay off more here than on one BVH: on a 10^8 plant's interior
/// view at 640x480 (8.6 K clusters) 16 traced 25 M rays per CPU-second against 19 with 8 and
/// 21 with 32 (`examples/cut_bench.rs`), while on one mesh (the dragon) 8 beat 16 by 6%.
/// Blocks of 4x4 pixels measured the same as 8x2.
///
/// [`trace_image`]: crate::trace_image
pub const SCENE_PACKET: usize = 16;

/// The clusters of a cut under a top-level BVH, with the camera's clip planes.
pub struct CutScene {
    tlas: Bvh,
    clusters: Vec<Arc<ClusterBlas>>,
    clip: Clip,
}

/// The rasterizer's near and far planes as limits on a ray's parameter: a point is drawn when
/// its depth (distance along `forward` from the plane through the rays' origin) lies in
/// `[near, far]` and the section keeps it (its kept part is convex, so a ray meets it in one
/// interval, `tw_runtime::Section::ray_interval`: the first hit in it is the one drawn).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clip {
    pub forward: Vec3,
    pub near: f32,
    pub far: f32,
    pub section: tw_runtime::Section,
}

impl Clip {
    /// The clip planes of `camera` for the rays of `crate::Camera::for_view`: the view depths
    /// `[near, far]` from the eye in perspective; in orthographic, whose rays start on the near
    /// plane, the depths `[0, far − near]` beyond it.
    pub fn for_view(camera: &tw_runtime::Camera) -> Clip {
        let forward = camera.direction();
        if camera.is_orthographic() {
            Clip { forward, near: 0.0, far: camera.far - camera.near, section: Default::default() }
        } else {
            Clip { forward, near: camera.near, far: camera.far, section: Default::default() }
        }
    }

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
        let r = section_limited(&self.section, r);
        (r.t_min < r.t_max).then_some(r)
    }

    /// [`Clip::apply`] for each of up to [`SCENE_PACKET`] rays; a ray that cannot reach the planes
    /// keeps its place with an empty interval (`t_max` -inf), so the packet's lanes stay in
    /// order and the lane never hits. Slots beyond `rays.len()` are unused copies.
    fn apply_packet(&self, rays: &[Ray]) -> [Ray; SCENE_PACKET] {
        let mut out = [rays.first().copied().unwrap_or(Ray::new(Vec3::ZERO, Vec3::Z)); SCENE_PACKET];
        for (o, r) in out.iter_mut().zip(rays) {
            *o = self.apply(r).unwrap_or(Ray { t_max: f32::NEG_INFINITY, ..*r });
        }
        out
    }
}

/// `ray` limited to where `section` keeps it (unchanged without a section).
fn section_limited(section: &tw_runtime::Section, mut ray: Ray) -> Ray {
    if !section.is_empty() {
        let (t0, t1) = section.ray_interval(ray.origin, ray.dir);
        ray.t_min = ray.t_min.max(t0);
        ray.t_max = ray.t_max.min(t1);
    }
    ray
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
        // What the section removes casts no shadow (the rasterizer clips its shadow maps too).
        let mut r = section_limited(&self.clip.section, *ray);
        if r.t_min >= r.t_max {
            return false;
        }
        self.tlas.traverse_any(&mut r, |c, r| self.clusters[c as usize].bvh.occluded(r))
    }

    /// [`Trace::intersect_packet`] on a chosen instruction set (tests force the portable path).
    ///
    /// Packets of [`SCENE_PACKET`] rays walk the top-level BVH together (interval culling per node,
    /// as in [`crate::TriangleBvh::intersect_packet`]); a cluster entered by some of the rays
    /// is traced for those rays as a packet through its own BVH, each ray within its current
    /// nearest hit, so the packet's coherence pays on both levels. Packets whose rays cannot
    /// share a traversal (mixed direction signs) are traced ray by ray. Results equal
    /// [`Trace::intersect`]'s up to ties.
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
        for (r, h) in rays.chunks(SCENE_PACKET).zip(hits.chunks_mut(SCENE_PACKET)) {
            let clipped = self.clip.apply_packet(r);
            match Packet::<SCENE_PACKET>::new(&clipped[..r.len()]) {
                Some(mut p) => {
                    let mut clusters =
                        ClusterPackets { clusters: &self.clusters, best: [None; SCENE_PACKET] };
                    self.tlas.traverse_packet(&mut p, &mut clusters);
                    for (h, b) in h.iter_mut().zip(clusters.best) {
                        *h = b;
                    }
                }
                None => {
                    for (ray, hit) in r.iter().zip(h.iter_mut()) {
                        *hit = self.intersect(ray);
                    }
                }
            }
        }
    }
}

/// The top level's primitive handler for packets: a cluster's BVH traced for the rays that
/// enter the cluster's box, the closest hits so far per lane.
struct ClusterPackets<'a> {
    clusters: &'a [Arc<ClusterBlas>],
    best: [Option<Hit>; SCENE_PACKET],
}

impl PrimPackets<SCENE_PACKET> for ClusterPackets<'_> {
    #[inline(always)]
    fn visit(&mut self, cluster: u32, lanes: u32, p: &mut Packet<SCENE_PACKET>) {
        if let Some(c) = self.clusters.get(cluster as usize) {
            c.bvh.packet_lanes(p, lanes, &mut self.best, cluster << TRIANGLE_BITS);
        }
    }
}

impl Trace for CutScene {
    fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.intersect_packet_simd(rays, hits, Simd::detect())
    }

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{intersect_triangle, trace_image_with, Camera, TraceMode, TriangleBvh};
    use tw_core::rng::Rng;

    /// Test randomness from the shared generator, as `f32`s and vectors.
    trait TestRng {
        /// Uniform in [lo, hi).
        fn f(&mut self, lo: f32, hi: f32) -> f32;
        /// Each coordinate uniform in [lo, hi).
        fn v(&mut self, lo: f32, hi: f32) -> Vec3;
    }

    impl TestRng for Rng {
        fn f(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32 * (hi - lo)
        }
        fn v(&mut self, lo: f32, hi: f32) -> Vec3 {
            Vec3::new(self.f(lo, hi), self.f(lo, hi), self.f(lo, hi))
        }
    }

    /// Many small clusters (1 to 128 triangles each) whose boxes overlap, in `[-1, 1]^3`, and
    /// each cluster's triangle corners (to check ties).
    fn random_scene(rng: &mut Rng, clusters: usize, clip: Clip) -> (CutScene, Vec<Vec<[Vec3; 3]>>) {
        let mut blas = Vec::new();
        let mut corners = Vec::new();
        for _ in 0..clusters {
            let centre = rng.v(-1.0, 1.0);
            let n = 1 + (rng.next_u64() % 128) as usize;
            let mut pos = Vec::new();
            let mut tris = Vec::new();
            let mut tri_corners = Vec::new();
            for i in 0..n as u32 {
                let c = centre + rng.v(-0.2, 0.2);
                let t = [0, 1, 2].map(|_| c + rng.v(-0.06, 0.06));
                pos.extend(t.map(|p| p.to_array()));
                tris.push([3 * i, 3 * i + 1, 3 * i + 2]);
                tri_corners.push(t);
            }
            let bvh = TriangleBvh::build(&pos, &tris).unwrap();
            let bounds = pos.iter().fold(Aabb::EMPTY, |b, &p| b.grown(Vec3::from(p)));
            blas.push(Arc::new(ClusterBlas { bvh, bounds }));
            corners.push(tri_corners);
        }
        (CutScene::build(blas, clip), corners)
    }

    /// Equal `t`; the same triangle unless the other one is hit at exactly that `t` too.
    fn assert_same(
        scene: &CutScene,
        corners: &[Vec<[Vec3; 3]>],
        ray: &Ray,
        got: Option<Hit>,
        want: Option<Hit>,
    ) {
        match (got, want) {
            (None, None) => {}
            (Some(g), Some(w)) if g.prim == w.prim => assert_eq!(g, w, "for {ray:?}"),
            (Some(g), Some(w)) => {
                let (c, t) = split_prim(g.prim);
                let clipped = scene.clip.apply(ray).expect("a hit ray reaches the planes");
                let tie = intersect_triangle(&clipped, corners[c as usize][t as usize]).map(|h| h.0);
                assert_eq!((g.t, tie), (w.t, Some(w.t)), "prim {} instead of {} for {ray:?}", g.prim, w.prim);
            }
            _ => panic!("packet {got:?}, single ray {want:?} for {ray:?}"),
        }
    }

    /// Coherent packets (4x2 pixel blocks of random cameras looking into the scene) and
    /// incoherent ones (random origins and directions, some pointing away from the clip
    /// planes' forward direction).
    fn rays(rng: &mut Rng) -> Vec<Ray> {
        let mut rays = Vec::new();
        for _ in 0..150 {
            let eye = rng.v(-1.0, 1.0).normalize() * 2.5;
            let cam = Camera::look_at(eye, rng.v(-0.5, 0.5), Vec3::Z, 0.9, 1.5);
            let (x0, y0) = ((rng.next_u64() % 60) as u32, (rng.next_u64() % 40) as u32);
            rays.extend((0..8).map(|k| cam.pixel_ray(x0 + k % 4, y0 + k / 4, 64, 48)));
        }
        for _ in 0..400 {
            let o = rng.v(-1.5, 1.5);
            rays.push(Ray {
                origin: o,
                dir: rng.v(-1.0, 1.0),
                t_min: rng.f(0.0, 0.2),
                t_max: rng.f(0.5, 8.0),
            });
        }
        rays
    }

    #[test]
    fn packets_through_the_two_level_scene_equal_single_rays() {
        let mut rng = Rng::new(23);
        // Clip planes with a forward direction that part of the random rays point away from.
        let forward = Vec3::new(0.3, -0.2, 0.9).normalize();
        let clip = Clip { forward, near: 0.05, far: 3.0, section: Default::default() };
        let (scene, corners) = random_scene(&mut rng, 400, clip);
        let rays = rays(&mut rng);
        let mut hit = 0;
        for simd in [Simd::Avx2, Simd::Portable] {
            let mut start = 0;
            while start < rays.len() {
                // Partial packets: chunks of 1 to 16 rays, and a longer run now and then.
                let len = match rng.next_u64() % 10 {
                    0 => 40,
                    n => 1 + (n as usize * 7 % SCENE_PACKET),
                };
                let chunk = &rays[start..(start + len).min(rays.len())];
                let mut hits = vec![None; chunk.len()];
                scene.intersect_packet_simd(chunk, &mut hits, simd);
                for (ray, got) in chunk.iter().zip(hits) {
                    let want = scene.intersect(ray);
                    hit += want.is_some() as usize;
                    assert_same(&scene, &corners, ray, got, want);
                }
                start += chunk.len();
            }
        }
        assert!(hit > rays.len() / 2, "too few rays hit ({hit} of {}) to compare", 2 * rays.len());
    }

    #[test]
    fn traced_images_of_a_clipped_two_level_scene_equal_single_rays() {
        let mut rng = Rng::new(5);
        let eye = Vec3::new(0.4, -2.6, 0.7);
        let target = Vec3::ZERO;
        // The far plane cuts through the scene, so clipped lanes sit in packets with others.
        let clip =
            Clip { forward: (target - eye).normalize(), near: 1.0, far: 2.8, section: Default::default() };
        let (scene, _) = random_scene(&mut rng, 300, clip);
        let camera = Camera::look_at(eye, target, Vec3::Z, 1.0, 1.3);
        // 37 x 29: blocks at the right and bottom edges are partial packets.
        let single = trace_image_with(&scene, &camera, 37, 29, TraceMode::Single);
        let packet = trace_image_with(&scene, &camera, 37, 29, TraceMode::Packet);
        assert_eq!(packet.1, single.1, "distances differ");
        // Random triangles tie with probability 0: the same triangles are hit.
        assert_eq!(packet.0, single.0, "hit triangles differ");
        let hits = single.0.iter().filter(|&&p| p != u32::MAX).count();
        assert!(hits > 200, "only {hits} pixels hit");
        let far = single.1.iter().filter(|d| d.is_finite()).fold(0.0f32, |a, &d| a.max(d));
        assert!(far > 2.0, "the far plane should be reached (farthest hit {far})");
    }
}
