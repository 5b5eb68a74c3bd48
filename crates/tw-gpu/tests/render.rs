//! End-to-end tests of the GPU renderer on a built 50k-triangle plant: the full-resolution cut
//! (τ = 0) rendered from an oblique camera must show geometry in several colours and cover the
//! same pixels as tw-preview's CPU rasterizer drawing the input triangles from the same camera,
//! perspective or orthographic.
//!
//! One test per backend (default from `WGPU_BACKEND`, GL, Vulkan). Without an adapter a test
//! is skipped with a note, unless `TERAWALK_REQUIRE_GPU=1` (CI), where it fails. On machines
//! without a GPU: `apt-get install mesa-vulkan-drivers` (lavapipe) and
//! `VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json`; GL uses Mesa's llvmpipe.

use std::collections::HashSet;
use std::path::Path;
use std::sync::Mutex;

use tw_gpu::{ColorMode, GpuError, Image, Renderer};
use tw_runtime::{Camera, PageCache, SelectOptions, Selector};
use tw_store::Store;

const W: u32 = 640;
const H: u32 = 400;
const PLANT_TRIANGLES: u64 = 50_000;

fn plant_source() -> tw_io::generate::PlantSource {
    tw_io::generate::PlantSource::new(tw_io::generate::PlantParams { triangles: PLANT_TRIANGLES, seed: 1 })
        .unwrap()
}

/// The plant, built once per process (tw-testkit).
fn plant_path() -> &'static Path {
    let options = tw_build::BuildOptions { memory: 256 << 20, ..Default::default() };
    tw_testkit::plant(PLANT_TRIANGLES, 1, options).path()
}

/// The oblique camera of the tests, in input coordinates (tw-preview) and scene space.
fn cameras(store: &Store) -> (tw_preview::Camera, Camera) {
    let h = store.header();
    let bounds = tw_core::Aabb { min: h.bounds_min, max: h.bounds_max };
    let pc =
        tw_preview::Camera::frame_bounds(&bounds, [-0.55, -0.75, 0.55], [0.0, 0.0, 1.0], W as f64 / H as f64);
    let rc = Camera::from_input_coordinates(pc.eye, pc.target, pc.up, pc.fovy_deg, h).unwrap();
    (pc, rc)
}

/// One GPU test at a time: the machine is small and software rasterizers use every core.
fn gpu_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// A renderer on `backends`, or `None` (skip) when there is no adapter and the environment
/// does not require one.
fn renderer(backends: wgpu::Backends, what: &str) -> Option<Renderer> {
    match Renderer::new_headless_with(W, H, backends) {
        Ok(r) => {
            eprintln!("{what}: {}", r.adapter_summary());
            Some(r)
        }
        Err(e @ GpuError::NoAdapter { .. })
            if std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1") =>
        {
            eprintln!("SKIPPED {what}: {e} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)");
            None
        }
        Err(e) => panic!("{what}: {e}"),
    }
}

/// [`cameras`] made orthographic, as high as the perspective view is at the target.
fn orthographic_cameras(store: &Store) -> (tw_preview::Camera, Camera) {
    let (pc, rc) = cameras(store);
    let height = rc.view_height_at((rc.target - rc.eye).length() as f64);
    let pc = tw_preview::Camera { ortho_height: Some(height), ..pc };
    let projection = tw_runtime::Projection::Orthographic { height: height as f32 };
    (pc, Camera::with_projection(rc.eye, rc.target, rc.up, projection, rc.near, rc.far).unwrap())
}

/// Renders the plant at τ = 0 and checks it against the CPU preview.
fn check_backend(backends: wgpu::Backends, what: &str) {
    check_backend_with(backends, what, cameras);
}

/// [`check_backend`] through the cameras `cameras` gives (tw-preview's and the renderer's).
fn check_backend_with(
    backends: wgpu::Backends,
    what: &str,
    cameras: fn(&Store) -> (tw_preview::Camera, Camera),
) {
    let _guard = gpu_lock();
    let Some(mut renderer) = renderer(backends, what) else { return };
    let store = Store::open(plant_path()).unwrap();
    let (pcam, camera) = cameras(&store);
    let cache = PageCache::new(&store, 1 << 30);
    cache.load_root_pages(&store);
    let selector = Selector::new(&store);
    let selection = selector.select(
        &store,
        &cache,
        &camera,
        &SelectOptions { tau: 0.0, viewport: [W, H], frustum_culling: true, ..Default::default() },
    );
    assert!(selection.triangles > 0);
    renderer.set_store_colors(&store);
    renderer.set_color_mode(ColorMode::Object);
    let image = renderer.render_selection(&store, &cache, &camera, &selection).unwrap();
    let stats = renderer.stats();
    eprintln!(
        "{what}: {} clusters, {} triangles, upload {:?}, render {:?}",
        stats.clusters, stats.triangles, stats.upload, stats.render
    );
    assert_eq!(stats.triangles, selection.triangles);
    assert_eq!(image.rgba.len(), (W * H * 4) as usize);

    // Not blank: much geometry, several colours.
    let covered = image.covered_pixels();
    let total = (W * H) as usize;
    assert!(covered > total / 20, "{what}: only {covered} of {total} pixels show geometry");
    let colors: HashSet<[u8; 3]> =
        image.rgba.chunks_exact(4).filter(|p| p[3] != 0).map(|p| [p[0], p[1], p[2]]).collect();
    assert!(colors.len() > 20, "{what}: only {} distinct colours", colors.len());

    // The same input triangles through the CPU rasterizer, from the same camera.
    let mut preview = tw_preview::Preview::new(W, H, pcam).unwrap();
    tw_io::Scene::from_sources(vec![Box::new(plant_source())]).stream(&mut preview).unwrap();
    let differ = preview
        .depth()
        .iter()
        .enumerate()
        .filter(|&(i, &d)| (d != 0.0) != image.covered(i as u32 % W, i as u32 / W))
        .count();
    let share = differ as f64 / total as f64;
    eprintln!(
        "{what}: coverage GPU {covered}, CPU {}, differing {differ} ({:.3} %)",
        preview.depth().iter().filter(|&&d| d != 0.0).count(),
        share * 100.0
    );
    // The brief's bound (2 % of the image), and one relative to the geometry shown.
    if share >= 0.02 || differ * 10 > covered {
        let dir = std::env::temp_dir();
        let _ = image.save_png(&dir.join(format!("tw-gpu-{what}.png")));
        let _ = preview.write_png(&dir.join(format!("tw-gpu-{what}-cpu.png")));
        panic!(
            "{what}: {:.2} % of the pixels differ in coverage from the CPU rasterizer (images in {})",
            share * 100.0,
            dir.display()
        );
    }
}

#[test]
fn plant_default_backend_matches_cpu_preview() {
    check_backend(wgpu::Backends::all().with_env(), "default");
}

#[test]
fn plant_gl_matches_cpu_preview() {
    check_backend(wgpu::Backends::GL, "gl");
}

#[test]
fn plant_vulkan_matches_cpu_preview() {
    check_backend(wgpu::Backends::VULKAN, "vulkan");
}

/// tw-preview's orthographic projection against the renderer's (the same pixels covered).
#[test]
fn plant_orthographic_matches_cpu_preview() {
    check_backend_with(wgpu::Backends::all().with_env(), "orthographic", orthographic_cameras);
}

#[test]
fn debug_color_modes_and_png() {
    let _guard = gpu_lock();
    let Some(mut renderer) = renderer(wgpu::Backends::all().with_env(), "modes") else { return };
    let store = Store::open(plant_path()).unwrap();
    let (_, camera) = cameras(&store);
    let cache = PageCache::new(&store, 1 << 30);
    let selection = Selector::new(&store).select(
        &store,
        &cache,
        &camera,
        &SelectOptions { tau: 1.0, viewport: [W, H], frustum_culling: true, ..Default::default() },
    );
    let mut images: Vec<Image> = Vec::new();
    for mode in [ColorMode::Material, ColorMode::Object, ColorMode::Level, ColorMode::Cluster] {
        renderer.set_color_mode(mode);
        let image = renderer.render_selection(&store, &cache, &camera, &selection).unwrap();
        assert!(image.covered_pixels() > 0, "{mode:?}");
        images.push(image);
    }
    // Same geometry, so the same coverage; different colours.
    for pair in images.windows(2) {
        assert_eq!(pair[0].covered_pixels(), pair[1].covered_pixels());
        assert_ne!(pair[0].rgba, pair[1].rgba);
    }
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("frame.png");
    images[3].save_png(&png).unwrap();
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let reader = decoder.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (W, H));
    // An empty frame: nothing covered.
    assert_eq!(renderer.render_clusters(&camera, 1.0, &[]).unwrap().covered_pixels(), 0);
}

/// The highlighted object is tinted in every colour mode: exactly the pixels the item buffer
/// gives to that object change, each towards the highlight's orange (less blue); clearing the
/// highlight draws the first image again.
#[test]
fn highlight_tints_exactly_its_objects_pixels_in_every_mode() {
    let _guard = gpu_lock();
    let Some(mut renderer) = renderer(wgpu::Backends::all().with_env(), "highlight") else { return };
    let store = Store::open(plant_path()).unwrap();
    let (_, camera) = cameras(&store);
    let cache = PageCache::new(&store, 1 << 30);
    let options = SelectOptions { tau: 1.0, viewport: [W, H], frustum_culling: true, ..Default::default() };
    let selection = Selector::new(&store).select(&store, &cache, &camera, &options);
    let items = renderer.item_buffer_selection(&store, &cache, &camera, &selection).unwrap();
    let visible = items.visible();
    let (&object, &pixels) = visible.objects.iter().max_by_key(|(_, &p)| p).unwrap();
    assert!(pixels > 100 && pixels < visible.covered_pixels, "{pixels} of {}", visible.covered_pixels);
    for mode in [ColorMode::Material, ColorMode::Object, ColorMode::Level, ColorMode::Cluster] {
        renderer.set_color_mode(mode);
        renderer.set_highlight(None);
        let plain = renderer.render_selection(&store, &cache, &camera, &selection).unwrap();
        renderer.set_highlight(Some(object));
        let tinted = renderer.render_selection(&store, &cache, &camera, &selection).unwrap();
        let (mut changed, mut outside) = (0u64, 0u64);
        for y in 0..H {
            for x in 0..W {
                let i = (y * W + x) as usize * 4;
                let (a, b) = (&plain.rgba[i..i + 4], &tinted.rgba[i..i + 4]);
                if a == b {
                    continue;
                }
                match items.item(x, y) {
                    Some(item) if item.object == object => {
                        changed += 1;
                        assert!(b[2] <= a[2], "{mode:?} ({x}, {y}): {a:?} -> {b:?} is not towards orange");
                    }
                    _ => outside += 1,
                }
            }
        }
        // Edge pixels may differ in coverage between the item buffer and the shaded pass.
        assert!(changed as f64 > 0.9 * pixels as f64, "{mode:?}: {changed} of {pixels} pixels tinted");
        assert!(outside * 100 < pixels, "{mode:?}: {outside} pixels of other objects changed");
        renderer.set_highlight(None);
        let again = renderer.render_selection(&store, &cache, &camera, &selection).unwrap();
        assert_eq!(again.rgba, plain.rgba, "{mode:?}: no highlight, the plain image");
    }
}

/// Frame times of the 50k plant at 1280×720, τ = 0 (run with `--ignored --nocapture`; pick the
/// backend with WGPU_BACKEND).
#[test]
#[ignore]
fn bench_plant_1280x720() {
    let Some(mut renderer) = Renderer::new_headless(1280, 720).ok() else { return };
    let store = Store::open(plant_path()).unwrap();
    let h = store.header();
    let bounds = tw_core::Aabb { min: h.bounds_min, max: h.bounds_max };
    let pc = tw_preview::Camera::frame_bounds(&bounds, [-0.55, -0.75, 0.55], [0.0, 0.0, 1.0], 1280.0 / 720.0);
    let camera = Camera::from_input_coordinates(pc.eye, pc.target, pc.up, pc.fovy_deg, h).unwrap();
    let cache = PageCache::new(&store, 1 << 30);
    let options =
        SelectOptions { tau: 0.0, viewport: [1280, 720], frustum_culling: true, ..Default::default() };
    let selection = Selector::new(&store).select(&store, &cache, &camera, &options);
    let mut times = Vec::new();
    for _ in 0..11 {
        renderer.render_selection(&store, &cache, &camera, &selection).unwrap();
        times.push((renderer.stats().upload, renderer.stats().render));
    }
    let first = times[0];
    times.sort_by_key(|t| t.1);
    eprintln!(
        "{}: {} triangles; first frame upload {:?} render {:?}; median render (GPU + readback) {:?}, upload {:?}",
        renderer.adapter_summary(),
        selection.triangles,
        first.0,
        first.1,
        times[5].1,
        times[5].0
    );
}
