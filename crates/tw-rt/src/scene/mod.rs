//! Ray tracing a store (docs/DESIGN.md D8; Wald, Dietrich & Slusallek 2004): the frame's LOD
//! cut — the same clusters the rasterizer draws, selected by tw-runtime at the same pixel error
//! over the resident pages — becomes a two-level scene ([`cut::CutScene`]) over cluster BVHs
//! cached with their decoded pages ([`blas::BlasCache`]); primary rays through the pixel
//! centres find the visible triangle, which is shaded as the rasterizer shades it
//! ([`shade::Shader`]), optionally lit by a flashlight with hard shadows.
//!
//! Out-of-core behaviour comes from the cut: a page that is not resident yet is drawn by its
//! best resident ancestors (the availability rule, docs/FORMAT.md), i.e. the page's coarser LOD
//! from the cluster DAG serves as its proxy while the streamer fetches it by priority; rays
//! never touch a page that is not in memory.

pub mod blas;
pub mod cut;
pub mod shade;

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use tw_core::color::ColorMode;
use tw_runtime::{Camera, ClusterRef, SelectionPages};
use tw_store::{PageCluster, Store};

use self::blas::{scene_position, BlasCache, BlasStats};
use self::cut::{split_prim, Clip, CutScene};
use self::shade::Shader;
use crate::{trace_image, Ray};

/// What a traced frame shows besides the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceSettings {
    pub coloring: ColorMode,
    /// A point light near the eye (Wald 2004's "flashlight") instead of the headlight
    /// direction, with hard shadows by shadow rays.
    pub flashlight: bool,
    /// Where in each pixel the primary ray passes (`crate::Camera::subpixel`): the centre by
    /// default; successive positions are the samples of progressive supersampling.
    pub subpixel: [f32; 2],
}

impl Default for TraceSettings {
    fn default() -> Self {
        TraceSettings { coloring: ColorMode::Material, flashlight: false, subpixel: [0.5, 0.5] }
    }
}

/// Where the flashlight sits: above and to the right of the eye by these fractions of the
/// distance from the eye to the camera's target, so that shadows show at any scale (a walk at
/// eye height, a fly-over).
const FLASHLIGHT_UP: f32 = 0.08;
const FLASHLIGHT_RIGHT: f32 = 0.05;

/// One traced frame: the image and, per pixel, what it shows (rows from the top).
#[derive(Clone, Debug, Default)]
pub struct TracedFrame {
    pub width: u32,
    pub height: u32,
    /// sRGB, alpha 0 where no geometry was hit (as the rasterizer's read-back image).
    pub rgba: Vec<u8>,
    /// Input object id per pixel, `u32::MAX` where nothing was hit.
    pub objects: Vec<u32>,
    /// The hit cluster per pixel: its position in the traced cut, `u32::MAX` where nothing.
    pub clusters: Vec<u32>,
    /// The hit triangle per pixel: its index in the cluster, `u32::MAX` where nothing.
    pub triangles: Vec<u32>,
    /// Distance from the eye per pixel, `f32::INFINITY` where nothing.
    pub distance: Vec<f32>,
    pub stats: TraceStats,
}

/// What one traced frame did and took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TraceStats {
    /// Clusters and triangles in the traced cut.
    pub clusters: usize,
    pub triangles: u64,
    pub blas: BlasStats,
    /// Whether the top-level BVH was rebuilt (else the cut was unchanged).
    pub tlas_rebuilt: bool,
    pub tlas_time: Duration,
    /// Primary (and shadow) rays.
    pub rays: u64,
    pub trace_time: Duration,
    pub shade_time: Duration,
    pub total: Duration,
}

/// Ray traces a store's LOD cuts frame after frame; see the module documentation.
pub struct StoreTracer {
    grid_step: f64,
    object_colors: Vec<Option<[u8; 4]>>,
    blas: BlasCache,
    /// The last frame's cut and its scene, reused while the cut does not change.
    last: Option<(Vec<ClusterRef>, CutScene)>,
}

/// The share of a memory budget that [`StoreTracer::budget_split`] gives the cluster BVHs:
/// they take ~80 bytes a triangle against the decoded pages' ~20, but only the clusters of
/// recent cuts need them, while the page cache also holds the pages prefetched for the next.
pub const BVH_SHARE: f64 = 0.25;

impl StoreTracer {
    /// A tracer of `store` whose cluster BVHs keep within `bvh_budget` bytes (beyond those of
    /// the frame being traced).
    pub fn new(store: &Store, bvh_budget: u64) -> StoreTracer {
        StoreTracer {
            grid_step: store.header().grid_step,
            object_colors: store.objects().iter().map(|o| o.color).collect(),
            blas: BlasCache::new(bvh_budget.min(usize::MAX as u64) as usize),
            last: None,
        }
    }

    /// One memory budget split between the page cache and the cluster BVHs ([`BVH_SHARE`]):
    /// `(pages, bvhs)`.
    pub fn budget_split(budget: u64) -> (u64, u64) {
        let bvhs = (budget as f64 * BVH_SHARE) as u64;
        (budget - bvhs, bvhs)
    }

    /// The threads a frame is traced on (the current rayon pool's).
    pub fn threads() -> usize {
        rayon::current_num_threads()
    }

    /// Bytes held by the cluster BVHs and the last top-level BVH.
    pub fn bytes(&self) -> usize {
        self.blas.bytes() + self.last.as_ref().map_or(0, |(keys, s)| s.tlas_bytes() + keys.len() * 12)
    }

    /// Forgets every cached BVH.
    pub fn clear(&mut self) {
        self.blas.clear();
        self.last = None;
    }

    /// Traces the clusters of `pages` (a frame's cut, resolved) from `camera` on a
    /// `width x height` image, on the current rayon pool.
    pub fn trace(
        &mut self,
        pages: &SelectionPages,
        camera: &Camera,
        (width, height): (u32, u32),
        settings: &TraceSettings,
    ) -> TracedFrame {
        let start = Instant::now();
        let entries: Vec<(ClusterRef, &PageCluster)> = pages.clusters();
        let keys: Vec<ClusterRef> = entries.iter().map(|(k, _)| *k).collect();
        let clip = Clip { forward: camera.direction(), near: camera.near, far: camera.far };
        let mut stats = TraceStats {
            clusters: entries.len(),
            triangles: entries.iter().map(|(_, c)| c.triangle_count() as u64).sum(),
            ..Default::default()
        };
        let scene = match self.last.take() {
            Some((last, scene)) if last == keys => scene.with_clip(clip),
            _ => {
                let (clusters, blas) = self.blas.prepare(pages, self.grid_step);
                stats.blas = blas;
                let t = Instant::now();
                let scene = CutScene::build(clusters, clip);
                stats.tlas_time = t.elapsed();
                stats.tlas_rebuilt = true;
                scene
            }
        };
        stats.blas.bytes = self.blas.bytes();

        let mut rt_camera = crate::Camera::look_at(
            camera.eye,
            camera.target,
            camera.up,
            camera.fovy,
            width as f32 / height.max(1) as f32,
        );
        rt_camera.subpixel = settings.subpixel;
        let t = Instant::now();
        let (prims, distance) = trace_image(&scene, &rt_camera, width, height);
        stats.trace_time = t.elapsed();
        stats.rays = prims.len() as u64;

        let t = Instant::now();
        let shader = Shader {
            mode: settings.coloring,
            object_colors: &self.object_colors,
            eye: camera.eye,
            headlight: camera.headlight(),
            sun: camera.sun_direction(),
        };
        let light = settings.flashlight.then(|| flashlight_position(camera, &rt_camera));
        let frame = shade_pixels(
            &scene,
            &entries,
            &shader,
            light,
            self.grid_step,
            &rt_camera,
            (width, height),
            prims,
            distance,
        );
        stats.shade_time = t.elapsed();
        if light.is_some() {
            stats.rays += frame.objects.iter().filter(|&&o| o != u32::MAX).count() as u64;
        }
        self.last = Some((keys, scene));
        stats.total = start.elapsed();
        TracedFrame { stats, ..frame }
    }
}

/// The flashlight's position for `camera` (see [`FLASHLIGHT_UP`]).
fn flashlight_position(camera: &Camera, rays: &crate::Camera) -> Vec3 {
    let d = (camera.target - camera.eye).length();
    camera.eye + rays.up * (FLASHLIGHT_UP * d) + rays.right * (FLASHLIGHT_RIGHT * d)
}

/// Colours every pixel from its hit (and, with a flashlight, a shadow ray), in parallel rows.
#[allow(clippy::too_many_arguments)]
fn shade_pixels(
    scene: &CutScene,
    entries: &[(ClusterRef, &PageCluster)],
    shader: &Shader,
    light: Option<Vec3>,
    grid_step: f64,
    camera: &crate::Camera,
    (width, height): (u32, u32),
    prims: Vec<u32>,
    distance: Vec<f32>,
) -> TracedFrame {
    let w = width as usize;
    let mut rgba = vec![0u8; w * height as usize * 4];
    let mut objects = vec![u32::MAX; prims.len()];
    let mut clusters = vec![u32::MAX; prims.len()];
    let mut triangles = vec![u32::MAX; prims.len()];
    rgba.par_chunks_mut(w * 4)
        .zip(objects.par_chunks_mut(w))
        .zip(clusters.par_chunks_mut(w))
        .zip(triangles.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (((rgba, objects), clusters), triangles))| {
            // Without a flashlight a triangle has one colour (flat shading, as the rasterizer's):
            // neighbouring pixels on the same triangle reuse it.
            let mut last: Option<(u32, [u8; 4])> = None;
            for x in 0..w {
                let i = y * w + x;
                if prims[i] == u32::MAX {
                    continue;
                }
                let (c, t) = split_prim(prims[i]);
                let Some(&(key, cluster)) = entries.get(c as usize) else { continue };
                let color = match last {
                    Some((prim, color)) if prim == prims[i] && light.is_none() => color,
                    _ => {
                        let Some(corners) = corners(cluster, t as usize, grid_step) else { continue };
                        let headlight = light.map(|l| {
                            let p = camera.pixel_ray(x as u32, y as u32, width, height).at(distance[i]);
                            flashlight(scene, p, l)
                        });
                        let color = shader.shade(key, cluster, t as usize, corners, headlight);
                        last = Some((prims[i], color));
                        color
                    }
                };
                rgba[x * 4..x * 4 + 4].copy_from_slice(&color);
                objects[x] = cluster.objects.get(t as usize).copied().unwrap_or(u32::MAX);
                clusters[x] = c;
                triangles[x] = t;
            }
        });
    TracedFrame { width, height, rgba, objects, clusters, triangles, distance, stats: TraceStats::default() }
}

/// How much of the flashlight at `light` reaches `p` (1 or 0: a shadow ray) and the direction
/// towards it.
fn flashlight(scene: &CutScene, p: Vec3, light: Vec3) -> (f32, Vec3) {
    let to_light = light - p;
    let d = to_light.length();
    let dir = to_light / d.max(f32::MIN_POSITIVE);
    // Leave the surface by a small distance relative to the point's magnitude (f32 positions):
    // no self-shadowing from rounding, no light leaking through thin walls.
    let offset = 1e-4 * (p.abs().max_element() + d).max(1e-3);
    let ray = Ray { origin: p, dir, t_min: offset, t_max: d - offset };
    let lit = if ray.t_min < ray.t_max && scene.occluded(&ray) { 0.0 } else { 1.0 };
    (lit, dir)
}

/// The scene-space corners of triangle `t` of `cluster`.
fn corners(cluster: &PageCluster, t: usize, grid_step: f64) -> Option<[Vec3; 3]> {
    let idx = cluster.indices.get(t * 3..t * 3 + 3)?;
    let p =
        |k: usize| cluster.positions.get(idx[k] as usize).map(|&g| Vec3::from(scene_position(g, grid_step)));
    Some([p(0)?, p(1)?, p(2)?])
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use tw_runtime::ResidentPage;

    use super::blas::{BlasCache, ClusterBlas};
    use super::*;
    use crate::Trace;

    /// A square of side `size` at height `z` with its corner at `(x, y)` (grid units), two
    /// triangles of object `object`.
    fn square(x: u32, y: u32, z: u32, size: u32, object: u32) -> PageCluster {
        PageCluster {
            positions: vec![[x, y, z], [x + size, y, z], [x + size, y + size, z], [x, y + size, z]],
            indices: vec![0, 1, 2, 0, 2, 3],
            objects: vec![object; 2],
            ..Default::default()
        }
    }

    fn scene(clusters: &[PageCluster]) -> CutScene {
        let blas = clusters.iter().map(|c| Arc::new(ClusterBlas::build(c, 1.0))).collect();
        let clip = Clip { forward: -Vec3::Z, near: 0.01, far: 1e6 };
        CutScene::build(blas, clip)
    }

    #[test]
    fn a_blocker_between_the_flashlight_and_a_point_shadows_it() {
        // A floor at z = 0 and a small roof at z = 5 over the floor's middle.
        let scene = scene(&[square(0, 0, 0, 100, 0), square(40, 40, 5, 20, 1)]);
        let light = Vec3::new(50.0, 50.0, 20.0);
        let (under, dir) = flashlight(&scene, Vec3::new(50.0, 50.0, 0.0), light);
        assert_eq!(under, 0.0, "the point under the roof is lit");
        assert!((dir - Vec3::Z).length() < 1e-6);
        let (beside, _) = flashlight(&scene, Vec3::new(5.0, 5.0, 0.0), light);
        assert_eq!(beside, 1.0, "a point in the open is in shadow");
        // The roof's top is lit: no self-shadowing from the surface it leaves.
        let (roof, _) = flashlight(&scene, Vec3::new(50.0, 50.0, 5.0), light);
        assert_eq!(roof, 1.0, "the roof shadows itself");
    }

    #[test]
    fn rays_report_the_cluster_and_triangle_they_hit() {
        let scene = scene(&[square(0, 0, 0, 10, 7), square(0, 0, 5, 10, 8)]);
        let ray = Ray::new(Vec3::new(2.0, 7.0, 10.0), -Vec3::Z);
        let hit = scene.intersect(&ray).expect("the upper square is hit");
        let (cluster, triangle) = cut::split_prim(hit.prim);
        assert_eq!((cluster, hit.t), (1, 5.0), "the nearer square, 5 below the eye");
        assert_eq!(triangle, 1, "(2, 7) lies in the square's second triangle");
        // Beyond the far plane nothing is hit, as nothing is drawn there.
        let near_only =
            CutScene::build(scene.clusters().to_vec(), Clip { forward: -Vec3::Z, near: 0.01, far: 4.0 });
        assert!(near_only.intersect(&ray).is_none());
    }

    #[test]
    fn cluster_bvhs_keep_their_budget_and_follow_their_pages() {
        let page =
            |n: u32| Arc::new(ResidentPage::new((0..n).map(|i| square(i * 20, 0, 0, 10, i)).collect()));
        let refs = |page_id: u32, n: u32| -> Vec<ClusterRef> {
            (0..n).map(|i| ClusterRef { page: page_id, index_in_page: i, group: 0 }).collect()
        };
        let one = ClusterBlas::build(&square(0, 0, 0, 10, 0), 1.0).bytes();
        let mut cache = BlasCache::new(3 * one);

        let (a, b) = (page(4), page(4));
        let pages = [(0, a.clone()), (1, b.clone())];
        let frame_a = SelectionPages::from_resident(&pages, &refs(0, 4));
        let (blas, stats) = cache.prepare(&frame_a, 1.0);
        assert_eq!(
            (blas.len(), stats.built, stats.evicted),
            (4, 4, 0),
            "a frame's clusters stay, over budget or not"
        );
        assert_eq!(stats.bytes, 4 * one);

        let frame_b = SelectionPages::from_resident(&pages, &refs(1, 2));
        let (_, stats) = cache.prepare(&frame_b, 1.0);
        assert_eq!((stats.built, stats.evicted), (2, 3), "the oldest clusters go first, down to the budget");
        assert_eq!(stats.bytes, 3 * one);

        // Page 1 evicted by the page cache (no one holds it): its BVHs go with it.
        drop((frame_b, pages));
        drop(b);
        // Of page 0's clusters (all last used together) the last one was kept.
        let frame_a = SelectionPages::from_resident(&[(0, a.clone())], &refs(0, 4)[3..]);
        let (_, stats) = cache.prepare(&frame_a, 1.0);
        assert_eq!(stats.dropped_pages, 1);
        assert_eq!(stats.built, 0, "page 0's last cluster was not kept");
        assert_eq!(stats.bytes, one);

        // Page 0 decoded again: new BVHs, not the old copy's.
        let a2 = page(4);
        let frame = SelectionPages::from_resident(&[(0, a2)], &refs(0, 1));
        let (_, stats) = cache.prepare(&frame, 1.0);
        assert_eq!(stats.built, 1);
    }
}
