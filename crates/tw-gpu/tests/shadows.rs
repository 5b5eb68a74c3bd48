//! Shadow maps on the rasterizer (tw-gpu's `shadow` module): a box floating over a tiled floor,
//! lit by a sun or a point light. The shadow mask ([`ColorMode::Shadow`]) is checked pixel by
//! pixel against ray casting (away from edges) and against `tw_runtime::Shadows::lit` on the map
//! read back; cross-culling classes must not change the image where they are true; without
//! shadows the renderer draws exactly what it drew before; bad map sizes are errors.
//!
//! Without an adapter a test is skipped with a note, unless `TERAWALK_REQUIRE_GPU=1`. Vulkan on
//! machines without a GPU: `VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json`.

use std::sync::Mutex;
use std::time::Instant;

use glam::{Mat4, Vec3};
use tw_core::color::{SHADOW_AWAY, SHADOW_BLOCKED, SHADOW_LIT};
use tw_gpu::{ColorMode, GpuError, Image, Renderer, Target};
use tw_runtime::camera::{look_at_rh, perspective_rh};
use tw_runtime::{Camera, ClusterRef, Light, ShadowClass, ShadowLayer, Shadows};
use tw_store::PageCluster;

mod common;
use common::{key, quad};

const W: u32 = 256;
const H: u32 = 256;
/// The floor: `TILES`² tiles of `TILE` grid units (one cluster each), at z = 0.
const TILES: u32 = 10;
const TILE: u32 = 10;
/// The box (grid units = scene units: grid step 1).
const BOX_MIN: [u32; 3] = [35, 35, 20];
const BOX_MAX: [u32; 3] = [65, 65, 30];
const MAP: u32 = 512;

fn gpu_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

fn renderer(backends: wgpu::Backends) -> Option<Renderer> {
    match Renderer::new_headless_with(W, H, backends) {
        Ok(r) => {
            eprintln!("{backends:?}: {}", r.adapter_summary());
            Some(r)
        }
        Err(e @ GpuError::NoAdapter { .. })
            if std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1") =>
        {
            eprintln!("SKIPPED {backends:?}: {e} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)");
            None
        }
        Err(e) => panic!("{backends:?}: {e}"),
    }
}

/// An axis-aligned box of 12 triangles (mixed winding, as inputs come), object `object`.
fn cuboid(min: [u32; 3], max: [u32; 3], object: u32) -> PageCluster {
    let positions: Vec<[u32; 3]> = (0..8u32)
        .map(|i| {
            [
                if i & 1 == 0 { min[0] } else { max[0] },
                if i & 2 == 0 { min[1] } else { max[1] },
                if i & 4 == 0 { min[2] } else { max[2] },
            ]
        })
        .collect();
    let faces: [[u8; 4]; 6] =
        [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]];
    let indices = faces.iter().flat_map(|f| [f[0], f[1], f[2], f[0], f[2], f[3]]).collect();
    PageCluster { positions, indices, objects: vec![object; 12], level: 0, ..quad(0, 0, 1, 1, 0, 0) }
}

/// The scene: floor tiles (pages 0..TILES², object 0) and the box (the last page, object 1).
fn scene() -> Vec<(ClusterRef, PageCluster)> {
    let mut clusters: Vec<(ClusterRef, PageCluster)> = (0..TILES * TILES)
        .map(|i| {
            let (x, y) = ((i % TILES) * TILE, (i / TILES) * TILE);
            (key(i), quad(x, y, x + TILE, y + TILE, 0, 0))
        })
        .collect();
    clusters.push((key(TILES * TILES), cuboid(BOX_MIN, BOX_MAX, 1)));
    clusters
}

fn refs(scene: &[(ClusterRef, PageCluster)]) -> Vec<(ClusterRef, &PageCluster)> {
    scene.iter().map(|(k, c)| (*k, c)).collect()
}

fn eye() -> Camera {
    Camera::new(Vec3::new(50.0, -40.0, 110.0), Vec3::new(50.0, 50.0, 0.0), Vec3::Z, 1.0, 1.0, 500.0).unwrap()
}

/// A sun from `towards` with one orthographic layer over the scene, or a point light above the
/// box with the downward cube face.
fn shadows(light: Light) -> Shadows {
    let view_proj = match light {
        Light::Sun { towards } => {
            let centre = Vec3::new(50.0, 50.0, 15.0);
            let view = look_at_rh(centre + towards * 100.0, centre, Vec3::Y);
            orthographic(-80.0, 80.0, -80.0, 80.0, 1.0, 200.0) * view
        }
        Light::Point { position } => {
            let view = look_at_rh(position, position - Vec3::Z, Vec3::Y);
            perspective_rh(std::f32::consts::FRAC_PI_2, 1.0, 1.0, 200.0) * view
        }
    };
    Shadows {
        light,
        layers: vec![ShadowLayer { view_proj, split: [0.0, f32::INFINITY] }],
        size: MAP,
        bias: 0.0,
    }
}

/// A right-handed orthographic projection to depth 0 (at `near`) .. 1 (at `far`).
fn orthographic(left: f32, right: f32, bottom: f32, top: f32, near: f32, far: f32) -> Mat4 {
    Mat4::from_cols(
        glam::Vec4::new(2.0 / (right - left), 0.0, 0.0, 0.0),
        glam::Vec4::new(0.0, 2.0 / (top - bottom), 0.0, 0.0),
        glam::Vec4::new(0.0, 0.0, -1.0 / (far - near), 0.0),
        glam::Vec4::new(
            -(right + left) / (right - left),
            -(top + bottom) / (top - bottom),
            -near / (far - near),
            1.0,
        ),
    )
}

fn sun_above() -> Light {
    Light::Sun { towards: Vec3::Z }
}

/// Draws the map of `shadows` from the whole scene and sets the shadows.
fn prepare(r: &mut Renderer, s: &Shadows, scene: &[(ClusterRef, &PageCluster)]) {
    r.set_shadow_map(MAP, 1).unwrap();
    r.draw_shadow_map(0, &s.layers[0].view_proj, 1.0, scene, true).unwrap();
    r.set_shadows(Some(s));
}

fn render(r: &mut Renderer, mode: ColorMode, scene: &[(ClusterRef, &PageCluster)]) -> Image {
    r.set_color_mode(mode);
    r.render_clusters(&eye(), 1.0, scene).unwrap()
}

// ---------------------------------------------------------------------------------------------
// The reference: ray casting against the floor and the box.

#[derive(Clone, Copy, Debug, PartialEq)]
enum Label {
    Background,
    Mask([u8; 4], bool),
}

/// The nearest hit of the ray `o + t d` (t > `t_min`): (t, outward normal, is the box).
fn cast(o: Vec3, d: Vec3, t_min: f32) -> Option<(f32, Vec3, bool)> {
    let mut best: Option<(f32, Vec3, bool)> = None;
    if d.z != 0.0 {
        let t = -o.z / d.z;
        let p = o + d * t;
        let side = (TILES * TILE) as f32;
        if t > t_min && (0.0..=side).contains(&p.x) && (0.0..=side).contains(&p.y) {
            best = Some((t, Vec3::Z * -d.z.signum(), false));
        }
    }
    let (lo, hi) = (Vec3::from(BOX_MIN.map(|c| c as f32)), Vec3::from(BOX_MAX.map(|c| c as f32)));
    let (mut t0, mut t1, mut n) = (f32::NEG_INFINITY, f32::INFINITY, Vec3::ZERO);
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return best;
            }
            continue;
        }
        let (mut ta, mut tb) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
        if ta > tb {
            std::mem::swap(&mut ta, &mut tb);
        }
        if ta > t0 {
            t0 = ta;
            n = Vec3::ZERO;
            n[a] = -d[a].signum();
        }
        t1 = t1.min(tb);
    }
    if t0 <= t1 && t0 > t_min && best.is_none_or(|b| t0 < b.0) {
        best = Some((t0, n, true));
    }
    best
}

/// The ray of pixel (x, y)'s centre.
fn pixel_ray(camera: &Camera, x: u32, y: u32) -> (Vec3, Vec3) {
    let inv = camera.view_projection(W as f32 / H as f32).inverse();
    let ndc = |z: f32| {
        let v = inv
            * glam::Vec4::new(
                (x as f32 + 0.5) / W as f32 * 2.0 - 1.0,
                1.0 - (y as f32 + 0.5) / H as f32 * 2.0,
                z,
                1.0,
            );
        v.truncate() / v.w
    };
    let (a, b) = (ndc(0.0), ndc(1.0));
    (camera.eye, (b - a).normalize())
}

/// What pixel (x, y) must show in the shadow mask, and the scene point it sees.
fn expected(light: &Light, x: u32, y: u32) -> (Label, Vec3) {
    let (o, d) = pixel_ray(&eye(), x, y);
    let Some((t, n, _)) = cast(o, d, 0.0) else { return (Label::Background, Vec3::ZERO) };
    let p = o + d * t;
    let l = light.towards_from(p);
    if n.dot(l) <= 0.0 {
        return (Label::Mask(SHADOW_AWAY, false), p);
    }
    let blocked = cast(p + n * 1e-3, l, 0.0).is_some_and(|(s, _, _)| s < light.distance_from(p));
    (Label::Mask(if blocked { SHADOW_BLOCKED } else { SHADOW_LIT }, blocked), p)
}

/// Pixels whose 5×5 neighbourhood sees one label: away from silhouettes and shadow edges
/// (2 pixels ≈ 1.4 scene units here, several shadow-map texels).
fn interior(labels: &[Label]) -> Vec<bool> {
    let at =
        |x: i64, y: i64| labels[(y.clamp(0, H as i64 - 1) * W as i64 + x.clamp(0, W as i64 - 1)) as usize];
    (0..H as i64)
        .flat_map(|y| (0..W as i64).map(move |x| (x, y)))
        .map(|(x, y)| (-2..=2).all(|dy| (-2..=2).all(|dx| at(x + dx, y + dy) == at(x, y))))
        .collect()
}

fn pixel(image: &Image, i: usize) -> [u8; 4] {
    image.rgba[4 * i..4 * i + 4].try_into().unwrap()
}

/// The mask of `light` on `backends`: every interior pixel as ray casting says, and as the
/// lookup rule (`Shadows::lit`) on the map read back says; the floor around the shadow all lit
/// (no acne).
fn check_mask(backends: wgpu::Backends, light: Light) {
    let _g = gpu_lock();
    let Some(mut r) = renderer(backends) else { return };
    let scene = scene();
    let list = refs(&scene);
    let s = shadows(light);
    prepare(&mut r, &s, &list);
    let image = render(&mut r, ColorMode::Shadow, &list);
    let map = r.read_shadow_map(0).unwrap();
    assert_eq!(map.len(), (MAP * MAP) as usize);
    let (labels, points): (Vec<Label>, Vec<Vec3>) =
        (0..W * H).map(|i| expected(&light, i % W, i / W)).unzip();
    let inside = interior(&labels);
    let (mut counts, mut floor_lit) = ([0usize; 3], 0usize);
    for i in 0..(W * H) as usize {
        if !inside[i] {
            continue;
        }
        let got = pixel(&image, i);
        match labels[i] {
            Label::Background => assert_eq!(got[3], 0, "{light:?}: pixel {i} should be background"),
            Label::Mask(want, blocked) => {
                assert_eq!(
                    got,
                    want,
                    "{light:?}: pixel ({}, {}) at {}",
                    i as u32 % W,
                    i as u32 / W,
                    points[i]
                );
                if want != SHADOW_AWAY {
                    let rule = s.lit(&eye(), points[i], |_, x, y| map[(y * MAP + x) as usize]);
                    assert_eq!(rule, !blocked, "{light:?}: the lookup rule at {}", points[i]);
                }
                let k = [SHADOW_LIT, SHADOW_BLOCKED, SHADOW_AWAY].iter().position(|c| *c == want).unwrap();
                counts[k] += 1;
                floor_lit += (want == SHADOW_LIT && points[i].z == 0.0) as usize;
            }
        }
    }
    eprintln!(
        "{light:?}: interior pixels lit {} blocked {} away {}, lit floor {floor_lit}",
        counts[0], counts[1], counts[2]
    );
    assert!(counts[1] > 500, "{light:?}: too few shadowed pixels: {counts:?}");
    assert!(floor_lit > 10_000, "{light:?}: too few lit floor pixels: {counts:?}");
}

#[test]
fn sun_above_mask_vulkan() {
    check_mask(wgpu::Backends::VULKAN, sun_above());
}

#[test]
fn oblique_sun_mask_vulkan() {
    check_mask(wgpu::Backends::VULKAN, Light::Sun { towards: Vec3::new(0.5, 0.3, 1.0).normalize() });
}

#[test]
fn point_light_mask_vulkan() {
    check_mask(wgpu::Backends::VULKAN, Light::Point { position: Vec3::new(50.0, 50.0, 100.0) });
}

#[test]
fn sun_above_mask_gl() {
    check_mask(wgpu::Backends::GL, sun_above());
}

#[test]
fn oblique_sun_mask_gl() {
    check_mask(wgpu::Backends::GL, Light::Sun { towards: Vec3::new(0.5, 0.3, 1.0).normalize() });
}

// ---------------------------------------------------------------------------------------------
// Classes.

/// The class of a floor tile under the sun straight above: inside the box's footprint
/// shadowed, outside it lit, across its edge partial; the box partial.
fn tile_class(i: u32) -> ShadowClass {
    if i >= TILES * TILES {
        return ShadowClass::Partial;
    }
    let (x0, y0) = ((i % TILES) * TILE, (i / TILES) * TILE);
    let inside = |c: u32, a: usize| c >= BOX_MIN[a] && c + TILE <= BOX_MAX[a];
    let outside = |c: u32, a: usize| c + TILE <= BOX_MIN[a] || c >= BOX_MAX[a];
    if inside(x0, 0) && inside(y0, 1) {
        ShadowClass::Shadowed
    } else if outside(x0, 0) || outside(y0, 1) {
        ShadowClass::Lit
    } else {
        ShadowClass::Partial
    }
}

#[test]
fn true_classes_give_the_image_of_lookups() {
    let _g = gpu_lock();
    let Some(mut r) = renderer(wgpu::Backends::VULKAN) else { return };
    let scene = scene();
    let list = refs(&scene);
    prepare(&mut r, &shadows(sun_above()), &list);
    let classes: Vec<(ClusterRef, ShadowClass)> =
        list.iter().map(|(k, _)| (*k, tile_class(k.page))).collect();
    let n = |c: ShadowClass| classes.iter().filter(|x| x.1 == c).count();
    assert_eq!((n(ShadowClass::Shadowed), n(ShadowClass::Partial), n(ShadowClass::Lit)), (4, 13, 84));
    for mode in [ColorMode::Shadow, ColorMode::Material] {
        r.set_shadow_classes(&[]);
        let partial = render(&mut r, mode, &list);
        r.set_shadow_classes(&classes);
        let classified = render(&mut r, mode, &list);
        assert_eq!(partial.rgba, classified.rgba, "{mode:?}: true classes changed the image");
    }
    // The classes are used: a lit tile classed shadowed turns dark, a shadowed one classed lit
    // turns lit.
    let wrong: Vec<(ClusterRef, ShadowClass)> = classes
        .iter()
        .map(|&(k, c)| {
            let c = match c {
                ShadowClass::Lit => ShadowClass::Shadowed,
                ShadowClass::Shadowed => ShadowClass::Lit,
                ShadowClass::Partial => ShadowClass::Partial,
            };
            (k, c)
        })
        .collect();
    r.set_shadow_classes(&wrong);
    let swapped = render(&mut r, ColorMode::Shadow, &list);
    r.set_shadow_classes(&[]);
    let partial = render(&mut r, ColorMode::Shadow, &list);
    let (mut to_blocked, mut to_lit) = (0, 0);
    for i in 0..(W * H) as usize {
        match (pixel(&partial, i), pixel(&swapped, i)) {
            (SHADOW_LIT, SHADOW_BLOCKED) => to_blocked += 1,
            (SHADOW_BLOCKED, SHADOW_LIT) => to_lit += 1,
            (a, b) => assert_eq!(a, b, "pixel {i} changed otherwise"),
        }
    }
    assert!(to_blocked > 10_000 && to_lit > 500, "{to_blocked} {to_lit}");
}

#[test]
fn material_shadows_darken_exactly_the_blocked_pixels() {
    let _g = gpu_lock();
    let Some(mut r) = renderer(wgpu::Backends::VULKAN) else { return };
    let scene = scene();
    let list = refs(&scene);
    prepare(&mut r, &shadows(sun_above()), &list);
    let mask = render(&mut r, ColorMode::Shadow, &list);
    let shadowed = render(&mut r, ColorMode::Material, &list);
    let all_lit: Vec<(ClusterRef, ShadowClass)> = list.iter().map(|(k, _)| (*k, ShadowClass::Lit)).collect();
    r.set_shadow_classes(&all_lit);
    let unblocked = render(&mut r, ColorMode::Material, &list);
    for i in 0..(W * H) as usize {
        let (s, u) = (pixel(&shadowed, i), pixel(&unblocked, i));
        if pixel(&mask, i) == SHADOW_BLOCKED {
            assert!(s[..3].iter().zip(&u[..3]).all(|(a, b)| a < b), "pixel {i}: {s:?} not darker than {u:?}");
        } else {
            assert_eq!(s, u, "pixel {i}");
        }
    }
}

/// The scene-space bounds of a cluster (grid step 1).
fn bounds(c: &PageCluster) -> (Vec3, Vec3) {
    let p = c.positions.iter().map(|q| Vec3::from(q.map(|v| v as f32)));
    (p.clone().fold(Vec3::MAX, Vec3::min), p.fold(Vec3::MIN, Vec3::max))
}

#[test]
fn gpu_culled_and_multisampled_passes_shade_with_shadows() {
    let _g = gpu_lock();
    let Some(mut r) = renderer(wgpu::Backends::VULKAN) else { return };
    let scene = scene();
    let list = refs(&scene);
    prepare(&mut r, &shadows(Light::Sun { towards: Vec3::new(0.5, 0.3, 1.0).normalize() }), &list);
    // Classes that change the image (every tile lit, the box looked up), so that a pass
    // ignoring them would differ.
    let classes: Vec<(ClusterRef, ShadowClass)> = list.iter().map(|(k, _)| (*k, ShadowClass::Lit)).collect();
    r.set_shadow_classes(&classes[..100]);
    r.set_color_mode(ColorMode::Shadow);
    let (a, b) = list.split_at(20);
    r.begin_frame();
    r.draw(Target::Own, &eye(), 1.0, a, true).unwrap();
    r.draw(Target::Own, &eye(), 1.0, b, false).unwrap();
    let reference = r.read_color().unwrap();
    r.set_shadow_classes(&[]);
    r.begin_frame();
    r.draw(Target::Own, &eye(), 1.0, &list, true).unwrap();
    assert!(r.read_color().unwrap().differing_pixels(&reference).unwrap() > 1000, "the classes show");
    r.set_shadow_classes(&classes[..100]);
    if r.gpu_cull_supported().is_ok() {
        let boxes: Vec<(Vec3, Vec3)> = b.iter().map(|(_, c)| bounds(c)).collect();
        r.begin_frame();
        r.draw(Target::Own, &eye(), 1.0, a, true).unwrap();
        r.draw_gpu_culled(&eye(), 1.0, b, &boxes, &[]).unwrap();
        assert_eq!(r.read_color().unwrap().rgba, reference.rgba, "GPU-culled pass");
    }
    // Multisampled: the same colours inside surfaces (edges are resolved).
    r.set_samples(4).unwrap();
    let msaa = render(&mut r, ColorMode::Shadow, &list);
    let labels: Vec<Label> = (0..W * H)
        .map(|i| match pixel(&reference, i as usize) {
            p if p[3] == 0 => Label::Background,
            p => Label::Mask(p, false),
        })
        .collect();
    let inside = interior(&labels);
    let checked = (0..(W * H) as usize)
        .filter(|&i| inside[i])
        .map(|i| assert_eq!(pixel(&msaa, i), pixel(&reference, i), "pixel {i}"))
        .count();
    assert!(checked > 15_000, "{checked}");
}

#[test]
fn a_tiny_budget_draws_the_same_map_and_shadows() {
    let _g = gpu_lock();
    let Some(mut big) = renderer(wgpu::Backends::VULKAN) else { return };
    let mut tiny = renderer(wgpu::Backends::VULKAN).unwrap();
    tiny.set_gpu_budget(tw_gpu::MIN_BUDGET);
    // 1600 overlapping floor tiles (3 units every 2 or 3) and the box: far more than the budget
    // holds. The overlaps are coplanar, so the image also depends on the order of the draws,
    // which the runs of classified and looked-up clusters keep.
    let mut scene: Vec<(ClusterRef, PageCluster)> = (0..1600u32)
        .map(|i| {
            let (x, y) = ((i % 40) * 5 / 2, (i / 40) * 5 / 2);
            (key(i), quad(x, y, x + 3, y + 3, 0, i % 3))
        })
        .collect();
    scene.push((key(1600), cuboid(BOX_MIN, BOX_MAX, 1)));
    let list = refs(&scene);
    // Classes of every kind, true or not: both renderers must draw them alike, although the
    // tiny one reuses pool slots for other clusters within a pass.
    let classes: Vec<(ClusterRef, ShadowClass)> = list
        .iter()
        .map(|(k, _)| {
            (*k, [ShadowClass::Lit, ShadowClass::Shadowed, ShadowClass::Partial][k.page as usize % 3])
        })
        .collect();
    let s = shadows(Light::Sun { towards: Vec3::new(0.5, 0.3, 1.0).normalize() });
    let mut images = Vec::new();
    for r in [&mut big, &mut tiny] {
        r.begin_frame();
        prepare(r, &s, &list);
        r.set_shadow_classes(&classes);
        let map = r.read_shadow_map(0).unwrap();
        r.set_color_mode(ColorMode::Material);
        r.draw(Target::Own, &eye(), 1.0, &list, true).unwrap();
        images.push((map, r.read_color().unwrap(), r.stats()));
    }
    let (b, t) = (&images[0], &images[1]);
    assert_eq!(b.2.pool.batches, 2, "one batch a pass");
    assert!(t.2.pool.batches > 4 && t.2.pool.evicted_clusters > 0, "{:?}", t.2.pool);
    assert_eq!(b.2.shadow_triangles, t.2.shadow_triangles);
    assert!(b.0 == t.0, "the maps differ");
    assert_eq!(b.1.differing_pixels(&t.1).unwrap(), 0);
}

// ---------------------------------------------------------------------------------------------
// Without shadows, what it drew before; stats; the map's layout; errors.

#[test]
fn no_shadows_draws_bit_identically_vulkan() {
    no_shadows_draws_bit_identically(wgpu::Backends::VULKAN);
}

#[test]
fn no_shadows_draws_bit_identically_gl() {
    no_shadows_draws_bit_identically(wgpu::Backends::GL);
}

fn no_shadows_draws_bit_identically(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut fresh) = renderer(backends) else { return };
    let mut used = renderer(backends).unwrap();
    let scene = scene();
    let list = refs(&scene);
    prepare(&mut used, &shadows(Light::Sun { towards: Vec3::new(0.5, 0.3, 1.0).normalize() }), &list);
    used.set_shadow_classes(&[(list[0].0, ShadowClass::Shadowed)]);
    let with = render(&mut used, ColorMode::Material, &list);
    used.set_shadows(None);
    for mode in [ColorMode::Material, ColorMode::Object, ColorMode::Shadow] {
        let a = render(&mut fresh, mode, &list);
        let b = render(&mut used, mode, &list);
        assert_eq!(a.rgba, b.rgba, "{mode:?}");
        assert!(a.covered_pixels() > 20_000, "{}", a.covered_pixels());
        if mode == ColorMode::Material {
            assert!(a.differing_pixels(&with).unwrap() > 1000, "the shadows showed");
        }
    }
    // Shadows of the default sun that block nothing (every cluster classed lit) shade as the
    // unshadowed pipeline does: turning shadows on changes only where the light is blocked.
    let sun = shadows(Light::default_sun(&eye()));
    prepare(&mut used, &sun, &list);
    let lit: Vec<(ClusterRef, ShadowClass)> = list.iter().map(|(k, _)| (*k, ShadowClass::Lit)).collect();
    used.set_shadow_classes(&lit);
    for mode in [ColorMode::Material, ColorMode::Object, ColorMode::Shadow] {
        let a = render(&mut fresh, mode, &list);
        let b = render(&mut used, mode, &list);
        assert_eq!(a.rgba, b.rgba, "{mode:?} with the default sun");
    }
    // The mask without shadows: lit or away by the fixed sun only.
    let mask = render(&mut fresh, ColorMode::Shadow, &list);
    for i in 0..(W * H) as usize {
        let p = pixel(&mask, i);
        assert!(p[3] == 0 || p == SHADOW_LIT || p == SHADOW_AWAY, "pixel {i}: {p:?}");
    }
}

#[test]
fn shadow_passes_count_apart_and_the_map_reads_back_by_the_rule() {
    let _g = gpu_lock();
    let Some(mut r) = renderer(wgpu::Backends::VULKAN) else { return };
    let scene = scene();
    let list = refs(&scene);
    let s = shadows(sun_above());
    r.set_shadow_map(MAP, 2).unwrap();
    assert!(r.read_shadow_map(1).unwrap().iter().all(|&d| d == 1.0), "a new map is cleared to 1");
    r.begin_frame();
    r.draw_shadow_map(1, &s.layers[0].view_proj, 1.0, &list, true).unwrap();
    let st = r.stats();
    assert_eq!((st.shadow_clusters, st.shadow_triangles, st.clusters, st.triangles), (101, 212, 0, 0));
    assert!(st.shadow_draw_calls >= 1 && st.draw_calls == 0);
    r.draw(Target::Own, &eye(), 1.0, &list, true).unwrap();
    assert_eq!((r.stats().clusters, r.stats().shadow_clusters), (101, 101));
    let map = r.read_shadow_map(1).unwrap();
    assert!(r.read_shadow_map(0).unwrap().iter().all(|&d| d == 1.0), "layer 0 untouched");
    // Texels found by the rule's texel(): the floor, the box top, beyond the floor (cleared);
    // asymmetric points, so a flipped map would fail.
    let depth_at = |p: Vec3| {
        let c = s.layers[0].view_proj * p.extend(1.0);
        let (x, y) = s.texel(c.truncate() / c.w);
        (map[(y * MAP + x) as usize], c.z / c.w)
    };
    for p in [Vec3::new(20.0, 80.0, 0.0), Vec3::new(90.0, 10.0, 0.0), Vec3::new(40.0, 60.0, 30.0)] {
        let (stored, d) = depth_at(p);
        assert!(stored >= d && stored - d < 1e-5, "{p}: stored {stored}, surface {d}");
    }
    assert_eq!(depth_at(Vec3::new(120.0, -15.0, 0.0)).0, 1.0);
    // Clearing again.
    r.draw_shadow_map(1, &s.layers[0].view_proj, 1.0, &[], true).unwrap();
    assert!(r.read_shadow_map(1).unwrap().iter().all(|&d| d == 1.0));
}

#[test]
fn bad_maps_and_mismatched_shadows_are_errors() {
    let _g = gpu_lock();
    let Some(mut r) = renderer(wgpu::Backends::VULKAN) else { return };
    let max = r.device().0.limits().max_texture_dimension_2d;
    for (size, layers) in [(0, 1), (max + 1, 1), (64, 0), (64, 7), (u32::MAX, 1)] {
        let e = r.set_shadow_map(size, layers).unwrap_err();
        assert!(matches!(e, GpuError::Shadow(_)), "{size} × {layers}: {e}");
        assert!(e.to_string().contains("shadow map"), "{e}");
    }
    let scene = scene();
    let list = refs(&scene);
    let s = shadows(sun_above());
    assert!(matches!(
        r.draw_shadow_map(0, &s.layers[0].view_proj, 1.0, &list, true),
        Err(GpuError::Shadow(_))
    ));
    assert!(r.read_shadow_map(0).is_err());
    r.set_shadows(Some(&s));
    let e = r.draw(Target::Own, &eye(), 1.0, &list, true).unwrap_err();
    assert!(e.to_string().contains("set_shadow_map"), "{e}");
    r.set_shadow_map(256, 1).unwrap();
    assert!(matches!(
        r.draw_shadow_map(1, &s.layers[0].view_proj, 1.0, &list, true),
        Err(GpuError::Shadow(_))
    ));
    assert!(r.read_shadow_map(1).is_err());
    let e = r.draw(Target::Own, &eye(), 1.0, &list, true).unwrap_err();
    assert!(e.to_string().contains("512"), "size mismatch: {e}");
    let two = Shadows { size: 256, layers: vec![s.layers[0]; 2], ..s.clone() };
    r.set_shadows(Some(&two));
    assert!(r.draw(Target::Own, &eye(), 1.0, &list, true).is_err(), "more layers than the map");
    r.set_shadow_map(MAP, 6).unwrap();
    r.set_shadows(Some(&s));
    r.draw(Target::Own, &eye(), 1.0, &list, true).unwrap();
}

// ---------------------------------------------------------------------------------------------
// Cost (run with --ignored --nocapture, release).

#[test]
#[ignore]
fn bench_shadow_passes() {
    let _g = gpu_lock();
    let Some(mut r) = Renderer::new_headless_with(1280, 720, wgpu::Backends::VULKAN).ok() else { return };
    // A denser scene: the tiled floor at 100² tiles of 2 triangles plus 400 boxes.
    let mut scene: Vec<(ClusterRef, PageCluster)> = Vec::new();
    for i in 0..100 * 100u32 {
        let (x, y) = ((i % 100) * 10, (i / 100) * 10);
        scene.push((key(i), quad(x, y, x + 10, y + 10, 0, 0)));
    }
    for i in 0..400u32 {
        let (x, y) = ((i % 20) * 50 + 10, (i / 20) * 50 + 10);
        scene.push((key(10_000 + i), cuboid([x, y, 10], [x + 20, y + 20, 10 + (i % 7) * 5 + 5], 1)));
    }
    let list = refs(&scene);
    let centre = Vec3::new(500.0, 500.0, 20.0);
    let towards = Vec3::new(0.4, 0.3, 1.0).normalize();
    let view = look_at_rh(centre + towards * 800.0, centre, Vec3::Y);
    let view_proj = orthographic(-720.0, 720.0, -720.0, 720.0, 1.0, 1600.0) * view;
    let s = Shadows {
        light: Light::Sun { towards },
        layers: vec![ShadowLayer { view_proj, split: [0.0, f32::INFINITY] }],
        size: 2048,
        bias: 0.0,
    };
    let eye = Camera::new(Vec3::new(500.0, -100.0, 300.0), centre, Vec3::Z, 1.0, 1.0, 3000.0).unwrap();
    r.set_shadow_map(2048, 1).unwrap();
    let time = |r: &mut Renderer, f: &mut dyn FnMut(&mut Renderer)| {
        f(r);
        let _ = r.read_shadow_map(0);
        let t = Instant::now();
        for _ in 0..10 {
            r.begin_frame();
            f(r);
            r.device().0.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        }
        t.elapsed().as_secs_f64() * 100.0
    };
    let depth = time(&mut r, &mut |r| r.draw_shadow_map(0, &view_proj, 1.0, &list, true).unwrap());
    r.set_shadows(None);
    let plain = time(&mut r, &mut |r| r.draw(Target::Own, &eye, 1.0, &list, true).unwrap());
    r.set_shadows(Some(&s));
    let lookups = time(&mut r, &mut |r| r.draw(Target::Own, &eye, 1.0, &list, true).unwrap());
    let lit: Vec<(ClusterRef, ShadowClass)> = list.iter().map(|(k, _)| (*k, ShadowClass::Lit)).collect();
    r.set_shadow_classes(&lit);
    let classified = time(&mut r, &mut |r| r.draw(Target::Own, &eye, 1.0, &list, true).unwrap());
    eprintln!(
        "{} triangles, {}: 2048² depth pass {depth:.1} ms; 1280×720 shaded pass: no shadows {plain:.1} ms, \
         lookups {lookups:.1} ms, all classed lit {classified:.1} ms",
        r.stats().triangles,
        r.adapter_summary()
    );
}

/// A floor strip of 32 quads (64 triangles, one cluster) along x at z = 0, under the box's
/// shadow for x in 35..65 under a sun straight above: its subobjects of 8 triangles (4 quads,
/// 12 units) are lit, partly shadowed or shadowed.
fn strip() -> PageCluster {
    let positions: Vec<[u32; 3]> = (0..=32u32).flat_map(|i| [[3 * i, 40, 0], [3 * i, 50, 0]]).collect();
    let indices: Vec<u8> =
        (0..32u8).flat_map(|i| [2 * i, 2 * i + 2, 2 * i + 3, 2 * i, 2 * i + 3, 2 * i + 1]).collect();
    PageCluster { positions, indices, objects: vec![0; 64], level: 0, ..quad(0, 0, 1, 1, 0, 0) }
}

#[test]
fn triangle_classes_draw_parts_of_a_cluster_without_lookups() {
    use tw_runtime::shadow::{classify_subobjects, LightDepth};
    use tw_runtime::TriangleClasses;
    let _g = gpu_lock();
    let Some(mut r) = renderer(wgpu::Backends::VULKAN) else { return };
    assert!(r.refines_shadow_classes(), "Vulkan draws indirectly with a first instance");
    let scene = [(key(0), strip()), (key(1), cuboid(BOX_MIN, BOX_MAX, 1))];
    let list = refs(&scene);
    // A bias, so that the strip's own depth in the map proves its lit parts lit.
    let s = Shadows { bias: 1e-3, ..shadows(sun_above()) };
    prepare(&mut r, &s, &list);
    r.set_shadow_classes(&[]);
    let lookups = render(&mut r, ColorMode::Shadow, &list);
    // The subobjects' classes as cross-culling finds them, against the map read back.
    let depth = LightDepth::new(&r.read_shadow_map(0).unwrap(), MAP).unwrap();
    let classes = classify_subobjects(&s, &[depth], &eye(), &[list[0].1], 1.0);
    let full = u64::MAX as u128;
    assert_eq!(classes[0].lit.count_ones(), 32, "{:x?}", classes[0]);
    assert_eq!(classes[0].shadowed.count_ones(), 16, "{:x?}", classes[0]);
    r.set_shadow_triangle_classes(&[(key(0), classes[0])]);
    let parts = render(&mut r, ColorMode::Shadow, &list);
    assert_eq!(lookups.rgba, parts.rgba, "true triangle classes changed the image");
    // The parts' classes are used: every triangle classed lit turns the strip's shadow lit.
    r.set_shadow_triangle_classes(&[(key(0), TriangleClasses { lit: full, shadowed: 0 })]);
    let wrong = render(&mut r, ColorMode::Shadow, &list);
    let mut to_lit = 0;
    for i in 0..(W * H) as usize {
        match (pixel(&lookups, i), pixel(&wrong, i)) {
            (SHADOW_BLOCKED, SHADOW_LIT) => to_lit += 1,
            (a, b) => assert_eq!(a, b, "pixel {i} changed otherwise"),
        }
    }
    assert!(to_lit > 100, "{to_lit} pixels turned lit");
    // Classes for the whole clusters again forget the triangles' (the next frame's start).
    r.set_shadow_classes(&[]);
    assert_eq!(render(&mut r, ColorMode::Shadow, &list).rgba, lookups.rgba);
}
