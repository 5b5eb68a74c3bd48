//! Ray tracing a store (docs/DESIGN.md D8; Wald, Dietrich & Slusallek 2004): the frame's LOD
//! cut — the same clusters the rasterizer draws, selected by tw-runtime at the same pixel error
//! over the resident pages — becomes a two-level scene ([`cut::CutScene`]) over cluster BVHs
//! cached with their decoded pages ([`blas::BlasCache`]); primary rays through the pixel
//! centres find the visible triangle, which is shaded as the rasterizer shades it
//! ([`shade::Shader`]), optionally lit by a flashlight and by a shadow-casting light
//! (`tw_runtime::Light`), both with hard shadows by shadow rays ([`shadow`]).
//!
//! With a shadow-casting light the traced cut must hold the casters outside the eye's view too:
//! the caller selects it without frustum culling (or with the light's side included) at the
//! eye's LOD — tw-frame's `TracedWalkthrough` does — and primary rays, limited by the clip
//! planes, still see only what the eye's cut shows.
//!
//! Out-of-core behaviour comes from the cut: a page that is not resident yet is drawn by its
//! best resident ancestors (the availability rule, docs/FORMAT.md), i.e. the page's coarser LOD
//! from the cluster DAG serves as its proxy while the streamer fetches it by priority; rays
//! never touch a page that is not in memory.

pub mod blas;
pub mod casters;
pub mod cut;
pub mod proxies;
pub mod shade;
pub mod shadow;
pub mod stored;

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use tw_core::color::ColorMode;
use tw_runtime::{Camera, ClusterRef, Light, SelectionPages};
use tw_store::{PageCluster, Store};

use self::blas::{scene_position, BlasCache, BlasStats};
use self::cut::{split_prim, Clip, CutScene};
use self::shade::Shader;
use self::shadow::{visibility, SurfacePoint};
use crate::trace_image;

/// What a traced frame shows besides the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceSettings {
    pub coloring: ColorMode,
    /// A point light near the eye (Wald 2004's "flashlight") instead of the headlight
    /// direction, with hard shadows by shadow rays; through an orthographic camera a parallel
    /// light from the eye's side ([`flashlight`]).
    pub flashlight: bool,
    /// Where in each pixel the primary ray passes (`crate::Camera::subpixel`): the centre by
    /// default; successive positions are the samples of progressive supersampling.
    pub subpixel: [f32; 2],
    /// The shadow-casting light (`--light`): the shading's sun term takes its direction and is
    /// multiplied by a shadow ray's verdict (the reference the rasterized shadow maps are
    /// checked against); `None`: the fixed, unshadowed sun.
    pub light: Option<Light>,
    /// Section planes and box (scene space): primary rays see only what it keeps, and what it
    /// removes casts no shadow ([`cut::Clip`]).
    pub section: tw_runtime::Section,
}

impl Default for TraceSettings {
    fn default() -> Self {
        TraceSettings {
            coloring: ColorMode::Material,
            flashlight: false,
            subpixel: [0.5, 0.5],
            light: None,
            section: Default::default(),
        }
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
    /// Distance along the pixel's primary ray per pixel, `f32::INFINITY` where nothing: from the
    /// eye in perspective, from the near plane in orthographic (`crate::Camera::for_view`).
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

    /// Whether cluster BVHs come from the store's shapes when it has them (the default; see
    /// [`blas::BlasCache::use_stored`]) or are all built.
    pub fn use_stored_bvhs(&mut self, on: bool) {
        self.blas.use_stored(on);
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
        let clip = Clip { section: settings.section, ..Clip::for_view(camera) };
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

        let mut rt_camera = crate::Camera::for_view(camera, width as f32 / height.max(1) as f32);
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
            orthographic: camera.is_orthographic(),
            headlight: camera.headlight(),
            sun: camera.sun_direction(),
        };
        let lights = Lights {
            flashlight: settings.flashlight.then(|| flashlight(camera, &rt_camera)),
            light: settings.light,
        };
        let (frame, shadow_rays) = shade_pixels(
            &scene,
            &entries,
            &shader,
            &lights,
            self.grid_step,
            &rt_camera,
            (width, height),
            prims,
            distance,
        );
        stats.shade_time = t.elapsed();
        stats.rays += shadow_rays;
        self.last = Some((keys, scene));
        stats.total = start.elapsed();
        TracedFrame { stats, ..frame }
    }
}

/// The flashlight of `camera` (whose rays are `rays`, [`crate::Camera::for_view`]).
///
/// Perspective: a point light above and to the right of the eye (by 8 % and 5 % of the
/// distance from the eye to the target, so that shadows show at any scale). An
/// orthographic camera has no centre of projection — its eye may sit anywhere back along the
/// view, and its rays are parallel — so a point light by the eye would light and shadow the
/// scene differently as the eye moves back without the image changing otherwise. There the
/// flashlight is a parallel light from the same side: from the target, the direction in which
/// the perspective flashlight would be seen (back along the view, tilted up and right by the
/// same fractions), so that shadows still show beside what casts them and do not depend on
/// where the eye is.
pub fn flashlight(camera: &Camera, rays: &crate::Camera) -> Light {
    if camera.is_orthographic() {
        let towards = -rays.forward + rays.up * FLASHLIGHT_UP + rays.right * FLASHLIGHT_RIGHT;
        return Light::Sun { towards: towards.normalize_or(camera.headlight()) };
    }
    let d = (camera.target - camera.eye).length();
    Light::Point {
        position: camera.eye + rays.up * (FLASHLIGHT_UP * d) + rays.right * (FLASHLIGHT_RIGHT * d),
    }
}

/// The lights whose shadows a frame traces.
#[derive(Clone, Copy, Debug, Default)]
struct Lights {
    /// Replaces the headlight ([`TraceSettings::flashlight`]).
    flashlight: Option<Light>,
    /// Replaces the fixed sun ([`TraceSettings::light`]).
    light: Option<Light>,
}

impl Lights {
    /// Whether a triangle's colour depends on the point (else it is flat: computed once).
    fn per_point(&self) -> bool {
        self.flashlight.is_some() || self.light.is_some()
    }

    /// The flashlight's and the light's visibility and direction at `point`; counts the shadow
    /// rays cast in `rays`. The flashlight lights both sides (its term takes `|n · l|`), so it
    /// always casts; the light casts only where it faces the surface (`n · l > 0`), since
    /// elsewhere its term is 0 whatever blocks it.
    fn at(&self, scene: &CutScene, point: &SurfacePoint, rays: &mut u64) -> [Option<(f32, Vec3)>; 2] {
        let mut cast = |light: &Light| {
            *rays += 1;
            visibility(scene, point, light)
        };
        let flashlight = self.flashlight.map(|l| cast(&l));
        let light = self.light.map(|l| {
            let towards = l.towards_from(point.position);
            if point.normal.dot(towards) > 0.0 {
                cast(&l)
            } else {
                (0.0, towards)
            }
        });
        [flashlight, light]
    }
}

/// The last shaded pixel of a row: its triangle, normal, lights and colour.
#[derive(Clone, Copy)]
struct Shaded {
    prim: u32,
    normal: Vec3,
    lit: [Option<(f32, Vec3)>; 2],
    color: [u8; 4],
}

/// Colours every pixel from its hit (and, with a flashlight or a light, its shadow rays), in
/// parallel rows; returns the frame and the number of shadow rays.
#[allow(clippy::too_many_arguments)]
fn shade_pixels(
    scene: &CutScene,
    entries: &[(ClusterRef, &PageCluster)],
    shader: &Shader,
    lights: &Lights,
    grid_step: f64,
    camera: &crate::Camera,
    (width, height): (u32, u32),
    prims: Vec<u32>,
    distance: Vec<f32>,
) -> (TracedFrame, u64) {
    let w = width as usize;
    let mut rgba = vec![0u8; w * height as usize * 4];
    let mut objects = vec![u32::MAX; prims.len()];
    let mut clusters = vec![u32::MAX; prims.len()];
    let mut triangles = vec![u32::MAX; prims.len()];
    let shadow_rays = rgba
        .par_chunks_mut(w * 4)
        .zip(objects.par_chunks_mut(w))
        .zip(clusters.par_chunks_mut(w))
        .zip(triangles.par_chunks_mut(w))
        .enumerate()
        .map(|(y, (((rgba, objects), clusters), triangles))| {
            // Flat shading (as the rasterizer's): a triangle's colour depends only on how the
            // lights reach it, so neighbouring pixels on the same triangle reuse its normal, and
            // its colour where the lights reach them alike (always without shadow rays; a sun's
            // lit and blocked pixels take one of two colours).
            let mut last: Option<Shaded> = None;
            let mut rays = 0;
            for x in 0..w {
                let i = y * w + x;
                if prims[i] == u32::MAX {
                    continue;
                }
                let (c, t) = split_prim(prims[i]);
                let Some(&(key, cluster)) = entries.get(c as usize) else { continue };
                let normal = match last {
                    Some(s) if s.prim == prims[i] => s.normal,
                    _ => match corners(cluster, t as usize, grid_step) {
                        Some(corners) => shader.normal(corners),
                        None => continue,
                    },
                };
                let lit = if lights.per_point() {
                    let ray = camera.pixel_ray(x as u32, y as u32, width, height);
                    let point = SurfacePoint {
                        position: ray.at(distance[i]),
                        normal,
                        distance: distance[i] * ray.dir.length(),
                    };
                    lights.at(scene, &point, &mut rays)
                } else {
                    [None, None]
                };
                let color = match last {
                    Some(s) if s.prim == prims[i] && s.lit == lit => s.color,
                    _ => {
                        let [flashlight, light] = lit;
                        shader.shade(key, cluster, t as usize, normal, flashlight, light)
                    }
                };
                last = Some(Shaded { prim: prims[i], normal, lit, color });
                rgba[x * 4..x * 4 + 4].copy_from_slice(&color);
                objects[x] = cluster.objects.get(t as usize).copied().unwrap_or(u32::MAX);
                clusters[x] = c;
                triangles[x] = t;
            }
            rays
        })
        .sum();
    let frame = TracedFrame {
        width,
        height,
        rgba,
        objects,
        clusters,
        triangles,
        distance,
        stats: TraceStats::default(),
    };
    (frame, shadow_rays)
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
    use crate::{Ray, Trace};

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
        let clip = Clip { forward: -Vec3::Z, near: 0.01, far: 1e6, section: Default::default() };
        CutScene::build(blas, clip)
    }

    #[test]
    fn a_blocker_between_the_flashlight_and_a_point_shadows_it() {
        // A floor at z = 0 and a small roof at z = 5 over the floor's middle.
        let scene = scene(&[square(0, 0, 0, 100, 0), square(40, 40, 5, 20, 1)]);
        let lights =
            Lights { flashlight: Some(Light::Point { position: Vec3::new(50.0, 50.0, 20.0) }), light: None };
        let at = |x: f32, y: f32, z: f32| SurfacePoint {
            position: Vec3::new(x, y, z),
            normal: Vec3::Z,
            distance: 20.0,
        };
        let mut rays = 0;
        let [under, light] = lights.at(&scene, &at(50.0, 50.0, 0.0), &mut rays);
        let (under, dir) = under.unwrap();
        assert_eq!((under, light), (0.0, None), "the point under the roof is lit");
        assert!((dir - Vec3::Z).length() < 1e-6);
        let [beside, _] = lights.at(&scene, &at(5.0, 5.0, 0.0), &mut rays);
        assert_eq!(beside.unwrap().0, 1.0, "a point in the open is in shadow");
        // The roof's top is lit: no self-shadowing from the surface it leaves.
        let [roof, _] = lights.at(&scene, &at(50.0, 50.0, 5.0), &mut rays);
        assert_eq!(roof.unwrap().0, 1.0, "the roof shadows itself");
        assert_eq!(rays, 3);
    }

    #[test]
    fn the_light_casts_only_where_it_faces_the_surface() {
        let scene = scene(&[square(0, 0, 0, 100, 0), square(40, 40, 5, 20, 1)]);
        let lights = Lights { flashlight: None, light: Some(Light::Sun { towards: Vec3::Z }) };
        let mut rays = 0;
        let under = SurfacePoint { position: Vec3::new(50.0, 50.0, 0.0), normal: Vec3::Z, distance: 20.0 };
        assert_eq!(lights.at(&scene, &under, &mut rays), [None, Some((0.0, Vec3::Z))]);
        assert_eq!(rays, 1);
        // The floor seen from below faces away from the sun: no ray, no light.
        let below = SurfacePoint { normal: -Vec3::Z, position: Vec3::new(5.0, 5.0, 0.0), ..under };
        assert_eq!(lights.at(&scene, &below, &mut rays), [None, Some((0.0, Vec3::Z))]);
        assert_eq!(rays, 1);
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
        let near_only = CutScene::build(
            scene.clusters().to_vec(),
            Clip { forward: -Vec3::Z, near: 0.01, far: 4.0, section: Default::default() },
        );
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
