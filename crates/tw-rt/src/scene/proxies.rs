//! Wald's 18-direction proxies ([`crate::proxy`]) for a store, kept in memory, and the
//! paper's way of drawing with pages missing: a ray that reaches a missing group's box is
//! killed there and shaded from the group's proxy (Wald, Dietrich & Slusallek 2004, §5.1; the
//! "blocky" artefact until the data arrives). docs/RUNTIME.md "Ray tracing" compares it with
//! the default, the coarser resident levels of the cluster DAG.
//!
//! **One proxy per group.** The store's unit of residency is the page, but a page packs many
//! groups that may lie far apart (docs/FORMAT.md: all clusters of a group are consecutive in
//! one page, a page may hold many groups), so a page's box would stand for empty space between
//! them. What a missing page leaves uncovered in a frame is the cut's groups on that page, each
//! a compact piece of surface with its own box — the counterpart of Wald's subtree behind a
//! pointer that crosses a tile. Groups on root pages never miss (root pages stay resident) and
//! get no proxy. Each proxy is kept with its group's scene-space box (24 bytes beside the
//! paper's 80: a kd-tree voxel's box is implicit in the tree, a group's is not).

use std::collections::HashMap;
use std::sync::Arc;

use glam::Vec3;
use rayon::prelude::*;
use tw_core::color::{ColorMode, DEFAULT_COLOR};
use tw_runtime::{ClusterRef, PageCache, ResidentPage, SelectionPages};
use tw_store::{PageCluster, Store, StoreError};

use super::blas::scene_position;
use super::cut::Clip;
use super::shade::Shader;
use super::{StoreTracer, TraceSettings, TracedFrame};
use crate::proxy::{generate, Proxy, ProxyError, ProxyInput, ProxySample};
use crate::{Aabb, BuildOptions, Bvh, Ray};

/// The proxies of a store's groups.
#[derive(Clone, Debug, Default)]
pub struct GroupProxies {
    /// Group → position in `proxies` and `boxes`.
    index: HashMap<u32, u32>,
    proxies: Vec<Proxy>,
    boxes: Vec<Aabb>,
}

/// Why [`GroupProxies::build`] failed.
#[derive(Debug, thiserror::Error)]
pub enum ProxiesError {
    #[error("page {page}: {source}")]
    Page { page: u32, source: StoreError },
    #[error("group {group}: {source}")]
    Proxy { group: u32, source: ProxyError },
}

impl GroupProxies {
    /// Proxies of the groups of the store's non-root pages for which `wanted(group)` holds,
    /// each from `rays` rays ([`crate::proxy::generate`]), coloured as `Shader` colours in
    /// `ColorMode::Material` (the object's colour). Pages are decoded in parallel on the current
    /// rayon pool, one at a time per thread.
    pub fn build(
        store: &Store,
        rays: u32,
        wanted: impl Fn(u32) -> bool + Sync,
    ) -> Result<GroupProxies, ProxiesError> {
        let colors: Vec<[u8; 3]> = store
            .objects()
            .iter()
            .map(|o| {
                let c = o.color.unwrap_or(DEFAULT_COLOR);
                [c[0], c[1], c[2]]
            })
            .collect();
        let mut by_page: HashMap<u32, Vec<u32>> = HashMap::new();
        for (g, group) in store.groups().iter().enumerate() {
            let root = store.pages().get(group.page as usize).is_none_or(|p| p.is_root());
            if !root && wanted(g as u32) {
                by_page.entry(group.page).or_default().push(g as u32);
            }
        }
        let mut pages: Vec<(u32, Vec<u32>)> = by_page.into_iter().collect();
        pages.sort_unstable_by_key(|(p, _)| *p);
        let grid_step = store.header().grid_step;
        let built: Vec<Vec<(u32, Proxy, Aabb)>> = pages
            .par_iter()
            .map(|(page, groups)| {
                let clusters =
                    store.page(*page).map_err(|source| ProxiesError::Page { page: *page, source })?;
                groups
                    .iter()
                    .map(|&g| {
                        let group = &store.groups()[g as usize];
                        let first = group.first_cluster as usize;
                        let members =
                            clusters.get(first..first + group.cluster_count as usize).unwrap_or(&[]);
                        let mesh = GroupMesh::new(members, grid_step, &colors);
                        let input = ProxyInput {
                            positions: &mesh.positions,
                            triangles: &mesh.triangles,
                            colors: &mesh.colors,
                        };
                        let proxy = generate(&input, rays, g)
                            .map_err(|source| ProxiesError::Proxy { group: g, source })?;
                        Ok((g, proxy, mesh.bounds()))
                    })
                    .collect()
            })
            .collect::<Result<_, ProxiesError>>()?;
        let mut out = GroupProxies::default();
        for (g, proxy, bounds) in built.into_iter().flatten() {
            out.index.insert(g, out.proxies.len() as u32);
            out.proxies.push(proxy);
            out.boxes.push(bounds);
        }
        Ok(out)
    }

    /// The proxy of `group` and its box, if it has one.
    pub fn get(&self, group: u32) -> Option<(&Proxy, Aabb)> {
        let i = *self.index.get(&group)? as usize;
        Some((&self.proxies[i], self.boxes[i]))
    }

    /// Number of proxies.
    pub fn len(&self) -> usize {
        self.proxies.len()
    }

    pub fn is_empty(&self) -> bool {
        self.proxies.is_empty()
    }

    /// Bytes the proxies need resident: 80 a proxy (the paper's record) and 24 for its box.
    /// (The map from group to proxy is not counted: a store would index proxies by group.)
    pub fn bytes(&self) -> usize {
        self.proxies.len() * (std::mem::size_of::<Proxy>() + 6 * 4)
    }
}

/// A group's triangles in scene space with a colour per triangle.
struct GroupMesh {
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    colors: Vec<[u8; 3]>,
}

impl GroupMesh {
    fn new(clusters: &[PageCluster], grid_step: f64, object_colors: &[[u8; 3]]) -> GroupMesh {
        let mut mesh = GroupMesh { positions: Vec::new(), triangles: Vec::new(), colors: Vec::new() };
        for c in clusters {
            let base = mesh.positions.len() as u32;
            mesh.positions.extend(c.positions.iter().map(|&g| scene_position(g, grid_step)));
            for (t, idx) in c.indices.chunks_exact(3).enumerate() {
                mesh.triangles.push([0, 1, 2].map(|k| base + idx[k] as u32));
                let object = c.objects.get(t).copied().unwrap_or(u32::MAX);
                let [r, g, b, _] = DEFAULT_COLOR;
                let color = object_colors.get(object as usize).copied().unwrap_or([r, g, b]);
                mesh.colors.push(color);
            }
        }
        mesh
    }

    fn bounds(&self) -> Aabb {
        self.positions.iter().fold(Aabb::EMPTY, |b, &p| b.grown(Vec3::from(p)))
    }
}

/// The boxes of a frame's missing groups with their proxies, under a BVH.
pub struct ProxyScene<'a> {
    bvh: Bvh,
    items: Vec<(&'a Proxy, Aabb)>,
}

impl<'a> ProxyScene<'a> {
    /// The proxies of `groups` (those without a proxy are left out).
    pub fn new(proxies: &'a GroupProxies, groups: impl IntoIterator<Item = u32>) -> ProxyScene<'a> {
        let items: Vec<(&Proxy, Aabb)> = groups.into_iter().filter_map(|g| proxies.get(g)).collect();
        let boxes: Vec<Aabb> = items.iter().map(|(_, b)| *b).collect();
        let bvh = Bvh::build_with(&boxes, &BuildOptions { max_leaf_size: 1, ..BuildOptions::default() });
        ProxyScene { bvh, items }
    }

    /// Number of boxes.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Where `ray` first enters a box within `[ray.t_min, ray.t_max)` whose proxy saw a surface
    /// around the ray's direction, with that look (a proxy that saw nothing from there lets the
    /// ray through, as the region's geometry would).
    pub fn entry(&self, ray: &Ray) -> Option<(f32, ProxySample)> {
        let mut ray = *ray;
        let mut best: Option<(f32, ProxySample)> = None;
        self.bvh.traverse(&mut ray, |prim, r| {
            let (proxy, bounds) = self.items[prim as usize];
            let Some((near, _)) = bounds.intersect(r) else { return false };
            if near >= r.t_max {
                return false;
            }
            let Some(look) = proxy.sample(r.dir) else { return false };
            r.t_max = near;
            best = Some((near, look));
            true
        });
        best
    }
}

impl StoreTracer {
    /// Traces `cut` — a frame's cut selected as if every page were resident (the warm cut) —
    /// the paper's way: its clusters on pages resident in `cache` at their level, and every
    /// group on a missing page as its box shaded from its proxy ([`overlay_proxies`]; the
    /// proxies are coloured as [`ColorMode::Material`] colours, whatever `settings` says).
    /// Returns the frame and how many pixels the proxies shaded.
    #[allow(clippy::too_many_arguments)]
    pub fn trace_with_proxies(
        &mut self,
        cache: &PageCache,
        cut: &[ClusterRef],
        proxies: &GroupProxies,
        camera: &tw_runtime::Camera,
        size: (u32, u32),
        settings: &TraceSettings,
    ) -> (TracedFrame, usize) {
        let mut pages: Vec<(u32, Arc<ResidentPage>)> =
            cut.iter().filter_map(|c| Some((c.page, cache.try_get(c.page)?))).collect();
        pages.sort_unstable_by_key(|(p, _)| *p);
        pages.dedup_by_key(|(p, _)| *p);
        let missing = missing_groups(cut, cache);
        let held = SelectionPages::from_resident(&pages, cut);
        let mut frame = self.trace(&held, camera, size, settings);
        let shaded = self.shade_missing(&mut frame, proxies, missing, camera, ProxyPixels::BeforeHits);
        (frame, shaded)
    }

    /// [`overlay_proxies`] of the proxies of `groups` on `frame` (traced from `camera`) at
    /// `pixels`, lit as this tracer lights a frame; returns the pixels they shaded. With
    /// [`ProxyPixels::Holes`] and the [`missing_groups`] of a warm cut, the hybrid.
    pub fn shade_missing(
        &self,
        frame: &mut TracedFrame,
        proxies: &GroupProxies,
        groups: impl IntoIterator<Item = u32>,
        camera: &tw_runtime::Camera,
        pixels: ProxyPixels,
    ) -> usize {
        let scene = ProxyScene::new(proxies, groups);
        let rt_camera = crate::Camera::for_view(camera, frame.width as f32 / frame.height.max(1) as f32);
        let shader = Shader {
            mode: ColorMode::Material,
            object_colors: &self.object_colors,
            eye: camera.eye,
            orthographic: camera.is_orthographic(),
            headlight: camera.headlight(),
            sun: camera.sun_direction(),
        };
        overlay_proxies(frame, &scene, camera, &rt_camera, &shader, pixels)
    }
}

/// The groups of `cut` whose page `cache` does not hold: what a frame drawn the paper's way
/// shows from proxies.
pub fn missing_groups(cut: &[ClusterRef], cache: &PageCache) -> Vec<u32> {
    let mut missing: Vec<u32> = cut.iter().filter(|c| !cache.contains(c.page)).map(|c| c.group).collect();
    missing.sort_unstable();
    missing.dedup();
    missing
}

/// Which pixels [`overlay_proxies`] may shade.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProxyPixels {
    /// Every pixel whose ray enters a box before its hit (the paper's way).
    BeforeHits,
    /// Only the pixels the frame left empty (the hybrid: the DAG's coarser levels where they
    /// draw something, proxies in the holes they leave).
    Holes,
}

/// Kills every pixel's ray of `frame` (traced from `camera`, `rt_camera` its rays) that enters
/// a box of `scene` before its hit, within the clip planes, and shades it from that box's proxy
/// with `shader`'s headlight and sun ([`Shader::shade_color`]); with [`ProxyPixels::Holes`] only
/// the rays that hit nothing. Returns how many pixels were shaded so. The pixel's object, cluster and triangle become `u32::MAX`, its distance the
/// box's entry.
pub fn overlay_proxies(
    frame: &mut TracedFrame,
    scene: &ProxyScene,
    camera: &tw_runtime::Camera,
    rt_camera: &crate::Camera,
    shader: &Shader,
    pixels: ProxyPixels,
) -> usize {
    if scene.is_empty() {
        return 0;
    }
    let (width, height) = (frame.width, frame.height);
    let w = width as usize;
    let clip = Clip::for_view(camera);
    frame
        .rgba
        .par_chunks_mut(w * 4)
        .zip(frame.distance.par_chunks_mut(w))
        .zip(frame.objects.par_chunks_mut(w))
        .zip(frame.clusters.par_chunks_mut(w))
        .zip(frame.triangles.par_chunks_mut(w))
        .enumerate()
        .map(|(y, ((((rgba, distance), objects), clusters), triangles))| {
            let mut shaded = 0;
            for x in 0..w {
                if pixels == ProxyPixels::Holes && distance[x].is_finite() {
                    continue;
                }
                let mut ray = rt_camera.pixel_ray(x as u32, y as u32, width, height);
                let along = ray.dir.dot(clip.forward);
                if along <= 0.0 {
                    continue;
                }
                ray.t_min = clip.near / along;
                ray.t_max = (clip.far / along).min(distance[x]);
                let Some((t, look)) = scene.entry(&ray) else { continue };
                rgba[x * 4..x * 4 + 4].copy_from_slice(&shader.shade_color(look.color, look.normal));
                distance[x] = t;
                (objects[x], clusters[x], triangles[x]) = (u32::MAX, u32::MAX, u32::MAX);
                shaded += 1;
            }
            shaded
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::proxy::{normal_encode, rgb565_encode, DIRECTIONS};

    fn proxy(color: [u8; 3]) -> Proxy {
        let sample = [rgb565_encode(color), normal_encode(Vec3::Z)];
        Proxy { samples: [sample; DIRECTIONS], area: 1.0, id: 0 }
    }

    #[test]
    fn a_ray_is_killed_at_the_nearest_box_before_its_limit() {
        let mut proxies = GroupProxies::default();
        for (g, (z, color)) in [(0.0, [255, 0, 0]), (5.0, [0, 0, 255])].into_iter().enumerate() {
            proxies.index.insert(g as u32 + 10, g as u32);
            proxies.proxies.push(proxy(color));
            proxies.boxes.push(Aabb::new(Vec3::new(0.0, 0.0, z), Vec3::new(1.0, 1.0, z + 1.0)));
        }
        let scene = ProxyScene::new(&proxies, [10, 11, 99]);
        assert_eq!(scene.len(), 2, "a group without a proxy is left out");
        let down = Ray::new(Vec3::new(0.5, 0.5, 10.0), -Vec3::Z);
        let (t, look) = scene.entry(&down).unwrap();
        assert_eq!((t, look.color), (4.0, [0, 0, 255]));
        // Geometry hit before the first box: no proxy.
        assert!(scene.entry(&Ray { t_max: 3.0, ..down }).is_none());
        // Starting beyond the first box's entry: inside it, killed at once.
        let (t, _) = scene.entry(&Ray { t_min: 4.5, ..down }).unwrap();
        assert_eq!(t, 4.5);
        assert!(scene.entry(&Ray::new(Vec3::new(3.0, 0.5, 10.0), -Vec3::Z)).is_none());
        // A proxy that saw nothing from above lets the ray through to the next box.
        proxies.proxies[1].samples = [[0, 0]; DIRECTIONS];
        let scene = ProxyScene::new(&proxies, [10, 11]);
        let (t, look) = scene.entry(&down).unwrap();
        assert_eq!((t, look.color), (9.0, [255, 0, 0]));
    }
}
