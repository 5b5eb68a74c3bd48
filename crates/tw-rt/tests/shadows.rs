//! Ray-traced hard shadows through a store's cut ([`StoreTracer`] with a `Light`): on a box
//! floating over a floor, the shadow mask ([`ColorMode::Shadow`]) is blocked exactly where the
//! segment from the floor to the light crosses the box and lit elsewhere — no acne on the flat
//! floor, for a sun overhead, a low sun and a point light — and a frame lit by a light that
//! blocks nothing is the unshadowed frame, pixel for pixel.

use std::sync::Arc;

use glam::Vec3;
use tw_core::color::{ColorMode, SHADOW_AWAY, SHADOW_BLOCKED, SHADOW_LIT};
use tw_rt::scene::{StoreTracer, TraceSettings, TracedFrame};
use tw_runtime::{Camera, ClusterRef, Light, ResidentPage, SelectionPages};
use tw_store::{Group, Node, Object, PageCluster, Store, StoreInfo, StoreWriter};

const W: u32 = 160;
const H: u32 = 120;
/// Scene units per grid step.
const STEP: f64 = 0.01;
/// The box, in grid units: `BOX_LO..=BOX_HI` on each axis (4 m wide, 3 m to 7 m above the floor).
const BOX_LO: [u32; 3] = [800, 800, 300];
const BOX_HI: [u32; 3] = [1200, 1200, 700];

/// A 20 m floor of 8x8 squares (128 triangles) at height 0.
fn floor() -> PageCluster {
    let (n, size) = (8u32, 250u32);
    let positions = (0..=n).flat_map(|y| (0..=n).map(move |x| [x * size, y * size, 0])).collect();
    let mut indices = Vec::new();
    for y in 0..n {
        for x in 0..n {
            let v = |dx: u32, dy: u32| ((y + dy) * (n + 1) + x + dx) as u8;
            indices.extend([v(0, 0), v(1, 0), v(1, 1), v(0, 0), v(1, 1), v(0, 1)]);
        }
    }
    PageCluster { positions, indices, objects: vec![0; 128], ..Default::default() }
}

/// The box's six faces (12 triangles).
fn cube() -> PageCluster {
    let positions = (0..8u32)
        .map(|i| std::array::from_fn(|axis| if i >> axis & 1 == 0 { BOX_LO[axis] } else { BOX_HI[axis] }))
        .collect();
    let faces: [[u8; 4]; 6] =
        [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]];
    let indices = faces.iter().flat_map(|f| [f[0], f[1], f[2], f[0], f[2], f[3]]).collect();
    PageCluster { positions, indices, objects: vec![1; 12], ..Default::default() }
}

/// The two clusters as a one-page store (one root group), and the page decoded as a frame's.
fn store(dir: &tempfile::TempDir) -> (Store, SelectionPages) {
    let path = dir.path().join("scene.tw");
    let sphere = [10.0, 10.0, 3.5, 15.0];
    let clusters = [floor(), cube()].map(|c| PageCluster { self_sphere: sphere, ..c });
    let mut writer = StoreWriter::create(&path).unwrap();
    let page = writer.add_page(&clusters, true).unwrap();
    let info = StoreInfo {
        bounds_min: [0.0; 3],
        bounds_max: [20.0, 20.0, 7.0],
        grid_origin: [0.0; 3],
        grid_step: STEP,
        units: "m".into(),
        up_axis: 2,
        build_options: String::new(),
        input_triangles: 140,
    };
    let objects = [
        Object { name: "floor".into(), color: Some([200, 200, 200, 255]), triangles: 128 },
        Object { name: "box".into(), color: Some([200, 60, 40, 255]), triangles: 12 },
    ];
    let nodes = [Node {
        min: [0; 3],
        max: [2000, 2000, 700],
        group_count: 1,
        max_error: f32::INFINITY,
        ..Default::default()
    }];
    let groups = [Group {
        sphere,
        error: f32::INFINITY,
        page,
        cluster_count: 2,
        triangles: 140,
        ..Default::default()
    }];
    writer.finish(&info, &objects, &nodes, &groups, &[]).unwrap();
    let store = Store::open(&path).unwrap();
    let resident = Arc::new(ResidentPage::new(store.page(page).unwrap()));
    let refs: Vec<ClusterRef> = (0..2).map(|i| ClusterRef { page, index_in_page: i, group: 0 }).collect();
    let pages = SelectionPages::from_resident(&[(page, resident)], &refs);
    (store, pages)
}

/// Looking down at the box from the side, low enough to see the floor under it.
fn camera() -> Camera {
    Camera::new(Vec3::new(-4.0, -2.0, 9.0), Vec3::new(10.0, 10.0, 1.5), Vec3::Z, 1.0, 0.05, 100.0).unwrap()
}

fn trace(store: &Store, pages: &SelectionPages, coloring: ColorMode, light: Option<Light>) -> TracedFrame {
    let mut tracer = StoreTracer::new(store, 64 << 20);
    tracer.trace(pages, &camera(), (W, H), &TraceSettings { coloring, light, ..Default::default() })
}

/// Whether the segment from `p` towards `light` meets the box grown by `grow` (scene units).
fn crosses_box(p: Vec3, light: &Light, grow: f32) -> bool {
    let lo = Vec3::from(BOX_LO.map(|g| g as f32 * STEP as f32)) - grow;
    let hi = Vec3::from(BOX_HI.map(|g| g as f32 * STEP as f32)) + grow;
    let dir = light.towards_from(p);
    let (mut t0, mut t1) = (0.0f32, light.distance_from(p));
    for a in 0..3 {
        let (near, far) = ((lo[a] - p[a]) / dir[a], (hi[a] - p[a]) / dir[a]);
        t0 = t0.max(near.min(far));
        t1 = t1.min(near.max(far));
    }
    t0 <= t1
}

/// The floor's pixels of a shadow mask against the box's shadow computed analytically: (lit
/// where the segment misses the box, blocked where it crosses it, wrong) — pixels within 5 cm
/// of the shadow's edge are left out.
fn floor_against_analytic(frame: &TracedFrame, light: &Light) -> (usize, usize, Vec<(u32, u32)>) {
    let c = camera();
    let rays = tw_rt::Camera::for_view(&c, W as f32 / H as f32);
    let (mut lit, mut blocked, mut wrong) = (0, 0, Vec::new());
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            if frame.objects[i] != 0 {
                continue;
            }
            let p = rays.pixel_ray(x, y, W, H).at(frame.distance[i]);
            let pixel: [u8; 4] = frame.rgba[i * 4..i * 4 + 4].try_into().unwrap();
            if !crosses_box(p, light, 0.05) {
                lit += 1;
                if pixel != SHADOW_LIT {
                    wrong.push((x, y));
                }
            } else if crosses_box(p, light, -0.05) {
                blocked += 1;
                if pixel != SHADOW_BLOCKED {
                    wrong.push((x, y));
                }
            }
        }
    }
    (lit, blocked, wrong)
}

#[test]
fn the_shadow_mask_is_blocked_under_the_box_and_lit_elsewhere() {
    let dir = tempfile::tempdir().unwrap();
    let (store, pages) = store(&dir);
    let lights = [
        Light::Sun { towards: Vec3::Z },
        Light::Sun { towards: Vec3::new(0.8, 0.5, 0.35).normalize() },
        Light::Point { position: Vec3::new(10.0, 10.0, 12.0) },
    ];
    for light in lights {
        let frame = trace(&store, &pages, ColorMode::Shadow, Some(light));
        let (lit, blocked, wrong) = floor_against_analytic(&frame, &light);
        assert!(
            lit > 4000 && blocked > 150,
            "{light:?}: too few floor pixels to judge ({lit} lit, {blocked} blocked)"
        );
        assert!(
            wrong.is_empty(),
            "{light:?}: {} floor pixels wrong (acne or leaks), first {:?}",
            wrong.len(),
            &wrong[..wrong.len().min(5)]
        );
        // Every pixel of the box is a mask colour, and the box's top faces an overhead sun.
        for (p, o) in frame.rgba.chunks_exact(4).zip(&frame.objects) {
            if *o == 1 {
                assert!([SHADOW_LIT, SHADOW_BLOCKED, SHADOW_AWAY].contains(&p.try_into().unwrap()), "{p:?}");
            }
        }
        assert!(frame.stats.rays > u64::from(W * H) / 2, "shadow rays are counted");
    }
    // An overhead sun: the box's sides face it edge-on (away), its top is lit.
    let frame = trace(&store, &pages, ColorMode::Shadow, Some(Light::Sun { towards: Vec3::Z }));
    let box_pixels: Vec<[u8; 4]> = frame
        .rgba
        .chunks_exact(4)
        .zip(&frame.objects)
        .filter(|(_, &o)| o == 1)
        .map(|(p, _)| p.try_into().unwrap())
        .collect();
    assert!(box_pixels.contains(&SHADOW_LIT) && box_pixels.contains(&SHADOW_AWAY));
    assert!(!box_pixels.contains(&SHADOW_BLOCKED));
}

#[test]
fn a_light_that_blocks_nothing_leaves_the_image_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let (store, pages) = store(&dir);
    let sun = Light::Sun { towards: camera().sun_direction() };
    for coloring in [ColorMode::Material, ColorMode::Object] {
        let plain = trace(&store, &pages, coloring, None);
        let lit = trace(&store, &pages, coloring, Some(sun));
        let mask = trace(&store, &pages, ColorMode::Shadow, Some(sun));
        let mut shadowed = 0;
        for (i, m) in mask.rgba.chunks_exact(4).enumerate() {
            let (a, b) = (&plain.rgba[i * 4..i * 4 + 4], &lit.rgba[i * 4..i * 4 + 4]);
            if m == SHADOW_BLOCKED {
                shadowed += 1;
                assert_ne!(a, b, "pixel {i}: a blocked pixel keeps its sunlight");
            } else {
                assert_eq!(a, b, "pixel {i}: the light changed a pixel it reaches (or faces away from)");
            }
        }
        assert!(shadowed > 100, "the box casts no shadow to compare ({shadowed} pixels)");
        assert_eq!((plain.objects, plain.distance), (lit.objects, lit.distance));
        assert_eq!(plain.stats.rays, u64::from(W * H), "no shadow rays without a light");
    }
}

/// An orthographic view of the box and floor from the side, its eye `back` units from the
/// target.
fn ortho_camera(back: f32) -> Camera {
    let target = Vec3::new(10.0, 10.0, 1.5);
    let eye = target + Vec3::new(-14.0, -12.0, 7.5).normalize() * back;
    Camera::orthographic(eye, target, Vec3::Z, 22.0, 0.05, back + 40.0).unwrap()
}

/// Through an orthographic camera the flashlight is a parallel light from the eye's side: the
/// image does not change as the eye moves back along the view (a point light by the eye would
/// light and shadow differently from each distance), and the box's shadow on the floor is where
/// that light's parallel rays cross the box. In perspective it stays a point light by the eye.
#[test]
fn the_flashlight_of_an_orthographic_view_is_parallel_and_does_not_depend_on_the_eye() {
    let dir = tempfile::tempdir().unwrap();
    let (store, pages) = store(&dir);
    let settings = TraceSettings { flashlight: true, ..Default::default() };
    let mut tracer = StoreTracer::new(&store, 64 << 20);
    let near = tracer.trace(&pages, &ortho_camera(25.0), (W, H), &settings);
    let far = tracer.trace(&pages, &ortho_camera(400.0), (W, H), &settings);
    assert_eq!(near.objects, far.objects, "the same view");
    assert!(near.rgba == far.rgba, "the flashlight changed with the eye's distance");

    let ortho = ortho_camera(25.0);
    let rays = tw_rt::Camera::for_view(&ortho, W as f32 / H as f32);
    let light = tw_rt::scene::flashlight(&ortho, &rays);
    let Light::Sun { towards } = light else { panic!("a point light in orthographic: {light:?}") };
    assert!(towards.dot(ortho.headlight()) > 0.99, "from the eye's side: {towards}");
    // The floor (flat, lit by a parallel light) has one colour where the light reaches it and
    // a darker one where the box blocks it, as the light's rays say (5 cm from the edge left out).
    let (mut lit, mut blocked) = (Vec::new(), Vec::new());
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            if near.objects[i] != 0 {
                continue;
            }
            let p = rays.pixel_ray(x, y, W, H).at(near.distance[i]);
            let pixel: [u8; 4] = near.rgba[i * 4..i * 4 + 4].try_into().unwrap();
            if !crosses_box(p, &light, 0.05) {
                lit.push(pixel);
            } else if crosses_box(p, &light, -0.05) {
                blocked.push(pixel);
            }
        }
    }
    assert!(lit.len() > 1000 && blocked.len() > 100, "{} lit, {} blocked", lit.len(), blocked.len());
    assert!(lit.iter().all(|p| *p == lit[0]), "the lit floor is one colour");
    assert!(blocked.iter().all(|p| *p == blocked[0]), "the shadow is one colour");
    assert!(blocked[0][0] < lit[0][0], "the shadow is darker: {:?} against {:?}", blocked[0], lit[0]);

    // Perspective: the point light above and beside the eye.
    let perspective = camera();
    let rays = tw_rt::Camera::for_view(&perspective, W as f32 / H as f32);
    match tw_rt::scene::flashlight(&perspective, &rays) {
        Light::Point { position } => {
            assert!(
                (position - perspective.eye).length() < 0.1 * (perspective.target - perspective.eye).length()
            )
        }
        sun => panic!("a parallel flashlight in perspective: {sun:?}"),
    }
}
