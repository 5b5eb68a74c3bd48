//! Tests of the frame API on Vulkan (lavapipe) and GL (llvmpipe), one test per backend and
//! feature: the resident pool under a tiny budget, indirect against direct draws, the item
//! buffer, two-pass drawing with depth readback, and the external-device entry points.
//!
//! Without an adapter a test is skipped with a note, unless `TERAWALK_REQUIRE_GPU=1`, where it
//! fails. Vulkan on machines without a GPU: `apt-get install mesa-vulkan-drivers` and
//! `VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json`.

use std::path::Path;
use std::sync::Mutex;

use glam::Vec3;
use tw_gpu::{ColorMode, DrawMode, GpuError, Image, Renderer, Target};
use tw_runtime::{Camera, ClusterRef, Hzb, HzbResult, PageCache, SelectOptions, Selector};
use tw_store::{PageCluster, Store};

mod common;
use common::{key, quad};

const W: u32 = 320;
const H: u32 = 200;

/// One GPU test at a time: the machine is small and software rasterizers use every core.
fn gpu_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

fn require_gpu() -> bool {
    std::env::var("TERAWALK_REQUIRE_GPU").as_deref() == Ok("1")
}

fn renderer(backends: wgpu::Backends, w: u32, h: u32) -> Option<Renderer> {
    match Renderer::new_headless_with(w, h, backends) {
        Ok(r) => {
            eprintln!("{backends:?}: {} (draw mode {:?})", r.adapter_summary(), r.draw_mode());
            Some(r)
        }
        Err(e @ GpuError::NoAdapter { .. }) if !require_gpu() => {
            eprintln!("SKIPPED {backends:?}: {e} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)");
            None
        }
        Err(e) => panic!("{backends:?}: {e}"),
    }
}

/// A 20 k-triangle plant (seed 3), built once per process (tw-testkit).
fn plant_path() -> &'static Path {
    let options = tw_build::BuildOptions { memory: 256 << 20, ..Default::default() };
    tw_testkit::plant(20_000, 3, options).path()
}

/// Cameras around the plant (scene space), from oblique directions.
fn plant_cameras(store: &Store, n: usize) -> Vec<Camera> {
    let h = store.header();
    let bounds = tw_core::Aabb { min: h.bounds_min, max: h.bounds_max };
    (0..n)
        .map(|i| {
            let a = i as f64 * 2.1;
            let dir = [-a.cos() * 0.8, -a.sin() * 0.8, 0.5];
            let pc = tw_preview::Camera::frame_bounds(&bounds, dir, [0.0, 0.0, 1.0], W as f64 / H as f64);
            Camera::from_input_coordinates(pc.eye, pc.target, pc.up, pc.fovy_deg, h).unwrap()
        })
        .collect()
}

fn select(store: &Store, cache: &PageCache, camera: &Camera, tau: f32) -> Vec<ClusterRef> {
    Selector::new(store)
        .select(
            store,
            cache,
            camera,
            &SelectOptions { tau, viewport: [W, H], frustum_culling: true, ..Default::default() },
        )
        .clusters
}

// ---------------------------------------------------------------------------------------------
// The pool: a tiny budget gives the same images as a large one.

fn pool_tiny_budget(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut big) = renderer(backends, W, H) else { return };
    let mut tiny = renderer(backends, W, H).unwrap();
    let budget = 256 << 10;
    tiny.set_gpu_budget(budget);
    // Room for the whole cut, but a full-resolution frame uploads more than a quarter of it
    // at once, so the first one is split to bound the staging memory.
    let mut mid = renderer(backends, W, H).unwrap();
    mid.set_gpu_budget(1 << 20);
    let store = Store::open(plant_path()).unwrap();
    let cache = PageCache::new(&store, 1 << 30);
    let step = store.header().grid_step;
    for r in [&mut big, &mut tiny, &mut mid] {
        r.set_store_colors(&store);
        r.set_color_mode(ColorMode::Cluster);
    }
    let cameras = plant_cameras(&store, 3);
    let mut frames = 0;
    for (i, cam) in cameras.iter().chain(cameras.iter()).enumerate() {
        let tau = if i % 2 == 0 { 0.0 } else { 2.0 };
        let sel = select(&store, &cache, cam, tau);
        let pages = tw_gpu::SelectionPages::resolve(&store, &cache, &sel);
        let list = pages.clusters();
        let a = big.render_clusters(cam, step, &list).unwrap();
        let sa = big.stats();
        let b = tiny.render_clusters(cam, step, &list).unwrap();
        let sb = tiny.stats();
        eprintln!(
            "{backends:?} frame {i}: {} clusters {} tris; big: up {} ({} B) ev {} res {} B; tiny: up {} ev {} res {} B, {} batches",
            sa.clusters, sa.triangles, sa.pool.uploaded_clusters, sa.pool.uploaded_bytes,
            sa.pool.evicted_clusters, sa.pool.resident_bytes, sb.pool.uploaded_clusters,
            sb.pool.evicted_clusters, sb.pool.resident_bytes, sb.pool.batches
        );
        assert!(a.covered_pixels() > 500, "frame {i} is nearly empty");
        assert_eq!(a.differing_pixels(&b).unwrap(), 0, "frame {i}: tiny budget differs");
        let m = mid.render_clusters(cam, step, &list).unwrap();
        let sm = mid.stats();
        assert_eq!(a.differing_pixels(&m).unwrap(), 0, "frame {i}: 1 MiB budget differs");
        assert_eq!(sm.triangles, sa.triangles);
        assert_eq!(sm.pool.evicted_clusters, 0, "frame {i}: the cuts fit 1 MiB");
        if i == 0 {
            assert!(sm.pool.uploaded_bytes > (1 << 18) && sm.pool.batches > 1, "{:?}", sm.pool);
        }
        if sm.pool.uploaded_bytes < (1 << 18) {
            assert_eq!(sm.pool.batches, 1, "frame {i}: {:?}", sm.pool);
        }
        assert_eq!(sa.triangles, sb.triangles);
        assert!(sb.pool.resident_bytes <= budget && sb.pool.arena_bytes <= budget);
        if tau == 0.0 {
            // The full-resolution cut (~560 KB of geometry) exceeds the 256 KiB budget.
            assert!(sb.pool.batches > 1, "frame {i}: the tiny budget should force batches");
        }
        assert_eq!(sa.pool.batches, 1);
        frames += 1;
    }
    // The same selection again: nothing to upload with the big budget.
    let sel = select(&store, &cache, &cameras[0], 0.0);
    let pages = tw_gpu::SelectionPages::resolve(&store, &cache, &sel);
    big.render_clusters(&cameras[0], step, &pages.clusters()).unwrap();
    assert_eq!(big.stats().pool.uploaded_clusters, 0);
    assert_eq!(big.stats().pool.evicted_clusters, 0);
    assert_eq!(frames, 6);
}

#[test]
fn pool_tiny_budget_gl() {
    pool_tiny_budget(wgpu::Backends::GL);
}

#[test]
fn pool_tiny_budget_vulkan() {
    pool_tiny_budget(wgpu::Backends::VULKAN);
}

// ---------------------------------------------------------------------------------------------
// Indirect and direct draws give the same images.

fn indirect_vs_direct(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut r) = renderer(backends, W, H) else { return };
    let store = Store::open(plant_path()).unwrap();
    let cache = PageCache::new(&store, 1 << 30);
    r.set_store_colors(&store);
    let cam = &plant_cameras(&store, 1)[0];
    let sel = select(&store, &cache, cam, 0.0);
    let pages = tw_gpu::SelectionPages::resolve(&store, &cache, &sel);
    let list = pages.clusters();
    let step = store.header().grid_step;
    let mut images = Vec::new();
    for mode in [DrawMode::Indirect, DrawMode::Direct] {
        let got = r.set_draw_mode(mode);
        if got != mode {
            eprintln!("{backends:?}: {mode:?} unsupported, {got:?} used");
        }
        let t = std::time::Instant::now();
        let img = r.render_clusters(cam, step, &list).unwrap();
        let s = r.stats();
        eprintln!(
            "{backends:?} {got:?}: {} clusters, {} draw calls, {:?}",
            s.clusters,
            s.draw_calls,
            t.elapsed()
        );
        images.push(img);
    }
    assert!(images[0].covered_pixels() > 1000);
    assert_eq!(images[0].differing_pixels(&images[1]).unwrap(), 0);
    assert_eq!(images[0].psnr(&images[1]).unwrap(), f64::INFINITY);
}

#[test]
fn indirect_equals_direct_gl() {
    indirect_vs_direct(wgpu::Backends::GL);
}

#[test]
fn indirect_equals_direct_vulkan() {
    indirect_vs_direct(wgpu::Backends::VULKAN);
}

// ---------------------------------------------------------------------------------------------
// A small synthetic scene: axis-aligned quads facing a camera on +z (`common::quad`).

/// A strip over `[x0, x1] × [0, 100]` at height `z` of 128 triangles (64 quads along y).
fn strip(x0: u32, x1: u32, z: u32, object: u32) -> PageCluster {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for j in 0..=64u32 {
        let y = j * 100 / 64;
        positions.push([x0, y, z]);
        positions.push([x1, y, z]);
    }
    for j in 0..64u8 {
        let (a, b, c, d) = (2 * j, 2 * j + 1, 2 * j + 3, 2 * j + 2);
        indices.extend_from_slice(&[a, b, c, a, c, d]);
    }
    PageCluster {
        positions,
        indices,
        objects: vec![object; 128],
        self_error: 0.0,
        self_sphere: [0.0, 0.0, 0.0, 1.0],
        group: 0,
        level: 0,
    }
}

/// Looking down -z at the centre of [0, 100]², from z = 200.
fn top_camera() -> Camera {
    Camera {
        eye: Vec3::new(50.0, 50.0, 200.0),
        target: Vec3::new(50.0, 50.0, 0.0),
        up: Vec3::Y,
        projection: tw_runtime::Projection::Perspective { fovy: 40f32.to_radians() },
        near: 1.0,
        far: 1000.0,
    }
}

fn items(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut r) = renderer(backends, W, H) else { return };
    // Back: a big quad (object 5) at z = 10; in front: a small one (object 7) at z = 50;
    // hidden: a quad (object 9) at z = 0 under the big one.
    let back = quad(0, 0, 100, 100, 10, 5);
    let front = quad(40, 40, 60, 60, 50, 7);
    let hidden = quad(20, 20, 30, 30, 0, 9);
    let list = [(key(1), &hidden), (key(2), &back), (key(3), &front)];
    let buf = r.item_buffer(&top_camera(), 1.0, &list).unwrap();
    let v = buf.visible();
    eprintln!("{backends:?}: {:?}", v);
    assert_eq!(v.objects.keys().copied().collect::<Vec<_>>(), vec![5, 7]);
    assert_eq!(v.clusters.keys().copied().collect::<Vec<_>>(), vec![key(2), key(3)]);
    let centre = buf.item(W / 2, H / 2).unwrap();
    assert_eq!((centre.object, centre.cluster), (7, 2));
    let corner = buf.item(W / 2 - 60, H / 2 - 60).unwrap();
    assert_eq!(corner.object, 5);
    // The background beyond the big quad's sides (it spans ±~137 px horizontally at 320×200).
    assert_eq!(buf.item(2, H / 2), None);
    assert_eq!(v.covered_pixels, v.objects.values().sum::<u64>());
    // The shaded frame covers the same pixels.
    let img = r.render_clusters(&top_camera(), 1.0, &list).unwrap();
    assert_eq!(img.covered_pixels() as u64, v.covered_pixels);
    if r.has_triangle_ids() {
        assert!(v.triangles_known);
        assert_eq!(v.clusters[&key(3)].triangles, 2);
        assert_eq!(v.clusters[&key(2)].triangles, 2);
        assert_eq!(v.triangles, 4);
        let t = centre.triangle.unwrap();
        assert!(t < 2);
    } else {
        eprintln!("{backends:?}: no primitive index; triangle counts unknown");
        assert!(!v.triangles_known);
    }
    // The same with a budget too small for one batch: items stay right across batches.
    r.set_gpu_budget(0);
    let many: Vec<PageCluster> = (0..40).map(|i| strip(i * 2, i * 2 + 2, 20 + i, 100 + i)).collect();
    let list: Vec<(ClusterRef, &PageCluster)> =
        many.iter().enumerate().map(|(i, c)| (key(i as u32 + 10), c)).collect();
    let buf = r.item_buffer(&top_camera(), 1.0, &list).unwrap();
    let v = buf.visible();
    eprintln!("{backends:?}: {} batches for 40 strips", r.stats().pool.batches);
    assert!(r.stats().pool.batches > 1);
    assert_eq!(v.objects.len(), 40);
    assert_eq!(v.clusters.len(), 40);
    for (k, c) in &v.clusters {
        let i = k.page - 10;
        assert!(c.pixels > 0, "strip {i}");
    }
    let centre = buf.item(W / 2, H / 2).unwrap();
    assert_eq!(list[centre.cluster as usize].1.objects[0], centre.object);
}

#[test]
fn item_buffer_gl() {
    items(wgpu::Backends::GL);
}

#[test]
fn item_buffer_vulkan() {
    items(wgpu::Backends::VULKAN);
}

// ---------------------------------------------------------------------------------------------
// Two passes without clear equal one pass; depth readback of a known quad.

fn two_pass(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut r) = renderer(backends, W, H) else { return };
    // Depth of a known quad: the plane z = 10 seen from z = 200 is 190 away.
    let cam = top_camera();
    let back = quad(0, 0, 100, 100, 10, 5);
    r.begin_frame();
    r.draw(Target::Own, &cam, 1.0, &[(key(1), &back)], true).unwrap();
    let depth = r.read_depth().unwrap();
    assert_eq!((depth.width, depth.height), (W, H));
    let vp = cam.projection_reverse_z(W as f32 / H as f32) * cam.view();
    let clip = vp * glam::Vec4::new(50.0, 50.0, 10.0, 1.0);
    let expected = clip.z / clip.w;
    let got = depth.get(W / 2, H / 2).unwrap();
    eprintln!("{backends:?}: centre depth {got}, expected {expected}");
    assert!((got - expected).abs() <= expected * 1e-4, "{got} vs {expected}");
    assert!(expected > 0.0 && expected < 1.0);
    assert_eq!(depth.get(1, H / 2), Some(0.0), "background");
    // The CPU HZB takes it as is: a box under the quad is occluded, one above is visible.
    let hzb = Hzb::build(&depth.depth, depth.width, depth.height).unwrap();
    assert_eq!(
        hzb.test_box(&vp, Vec3::new(40.0, 40.0, 0.0), Vec3::new(60.0, 60.0, 5.0)),
        HzbResult::Occluded
    );
    assert_eq!(
        hzb.test_box(&vp, Vec3::new(40.0, 40.0, 20.0), Vec3::new(60.0, 60.0, 30.0)),
        HzbResult::Visible
    );
    // Colour after the second pass on top: the front quad over the back one.
    let front = quad(40, 40, 60, 60, 50, 7);
    r.draw(Target::Own, &cam, 1.0, &[(key(2), &front)], false).unwrap();
    let two = r.read_color().unwrap();
    let one = r.render_clusters(&cam, 1.0, &[(key(1), &back), (key(2), &front)]).unwrap();
    assert_eq!(two.differing_pixels(&one).unwrap(), 0);

    // The plant: first half then second half without clear = everything in one pass.
    let store = Store::open(plant_path()).unwrap();
    let cache = PageCache::new(&store, 1 << 30);
    r.set_store_colors(&store);
    let step = store.header().grid_step;
    let cam = &plant_cameras(&store, 2)[1];
    let sel = select(&store, &cache, cam, 0.0);
    let pages = tw_gpu::SelectionPages::resolve(&store, &cache, &sel);
    let list = pages.clusters();
    let (a, b) = list.split_at(list.len() / 2);
    let t = std::time::Instant::now();
    r.begin_frame();
    r.draw(Target::Own, cam, step, a, true).unwrap();
    let d = r.read_depth().unwrap();
    let depth_time = t.elapsed();
    r.draw(Target::Own, cam, step, b, false).unwrap();
    let two = r.read_color().unwrap();
    eprintln!("{backends:?}: two-pass frame {:?} (first pass + depth readback {depth_time:?})", t.elapsed());
    assert!(d.covered_pixels() > 100);
    let one = r.render_clusters(cam, step, &list).unwrap();
    assert_eq!(two.differing_pixels(&one).unwrap(), 0, "two passes differ from one");
    assert!(one.covered_pixels() > 1000);
}

#[test]
fn two_pass_and_depth_gl() {
    two_pass(wgpu::Backends::GL);
}

#[test]
fn two_pass_and_depth_vulkan() {
    two_pass(wgpu::Backends::VULKAN);
}

// ---------------------------------------------------------------------------------------------
// The external-device entry points: from_device on a device the caller opened, and
// render_to_view into a caller-owned texture give the same pixels as the headless path.

fn open_device(backends: wgpu::Backends) -> Option<(wgpu::Adapter, wgpu::Device, wgpu::Queue)> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = backends;
    let instance = wgpu::Instance::new(desc);
    let adapter = match pollster::block_on(instance.request_adapter(&Default::default())) {
        Ok(a) => a,
        Err(e) if !require_gpu() => {
            eprintln!("SKIPPED {backends:?}: {e}");
            return None;
        }
        Err(e) => panic!("{backends:?}: {e}"),
    };
    let (d, q) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_features: adapter.features() & Renderer::optional_features(),
        required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
        ..Default::default()
    }))
    .unwrap();
    Some((adapter, d, q))
}

fn read_texture(device: &wgpu::Device, queue: &wgpu::Queue, tex: &wgpu::Texture) -> Vec<u8> {
    let (w, h) = (tex.width(), tex.height());
    let row = (w * 4).div_ceil(256) * 256;
    let buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: (row * h) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_texture_to_buffer(
        tex.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: None },
        },
        wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
    );
    queue.submit([enc.finish()]);
    buf.map_async(wgpu::MapMode::Read, .., |r| r.unwrap());
    device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    let data = buf.get_mapped_range(..).unwrap();
    data.chunks(row as usize).flat_map(|r| r[..(w * 4) as usize].to_vec()).collect()
}

fn target(device: &wgpu::Device, format: wgpu::TextureFormat, w: u32, h: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("viewer target"),
        size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

fn external(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some((adapter, device, queue)) = open_device(backends) else { return };
    let mut r = Renderer::from_device(device.clone(), queue.clone(), adapter.get_info(), W, H).unwrap();
    r.set_downlevel(&adapter.get_downlevel_capabilities());
    r.set_color_mode(ColorMode::Object);
    let cam = top_camera();
    let back = quad(0, 0, 100, 100, 10, 5);
    let front = quad(40, 40, 60, 60, 50, 7);
    let list = [(key(1), &back), (key(2), &front)];
    let headless: Image = r.render_clusters(&cam, 1.0, &list).unwrap();
    assert!(headless.covered_pixels() > 1000);

    // The viewer's path: the own target (Rgba8Unorm, sRGB-encoded bytes) copied into an sRGB
    // texture keeps the bytes.
    let shown = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("shown"),
        size: wgpu::Extent3d { width: W, height: H, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8UnormSrgb,
        usage: wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_texture_to_texture(
        r.color_texture().as_image_copy(),
        shown.as_image_copy(),
        wgpu::Extent3d { width: W, height: H, depth_or_array_layers: 1 },
    );
    queue.submit([enc.finish()]);
    assert_eq!(read_texture(&device, &queue, &shown), headless.rgba);

    let format = wgpu::TextureFormat::Rgba8UnormSrgb;
    let tex = target(&device, format, W, H);
    r.render_to_view(&cam, 1.0, &list, &tex.create_view(&Default::default()), format, (W, H)).unwrap();
    assert_eq!(read_texture(&device, &queue, &tex), headless.rgba);
    assert_eq!(r.stats().pool.uploaded_clusters, 0, "already resident");
    assert!(matches!(r.read_color(), Err(GpuError::NotOwnTarget { .. })));
    // The same into the caller's encoder.
    let tex3 = target(&device, format, W, H);
    let mut enc = device.create_command_encoder(&Default::default());
    r.encode_to_view(&mut enc, &cam, 1.0, &list, &tex3.create_view(&Default::default()), format, (W, H))
        .unwrap();
    queue.submit([enc.finish()]);
    assert_eq!(read_texture(&device, &queue, &tex3), headless.rgba);
    // More than the budget holds cannot go into one caller-owned pass.
    let mut small = Renderer::from_device(device.clone(), queue.clone(), adapter.get_info(), W, H).unwrap();
    small.set_gpu_budget(0);
    let many: Vec<PageCluster> = (0..40).map(|i| strip(i * 2, i * 2 + 2, 20 + i, 100 + i)).collect();
    let many: Vec<(ClusterRef, &PageCluster)> =
        many.iter().enumerate().map(|(i, c)| (key(i as u32 + 10), c)).collect();
    let mut enc = device.create_command_encoder(&Default::default());
    let view3 = tex3.create_view(&Default::default());
    let err = small.encode_to_view(&mut enc, &cam, 1.0, &many, &view3, format, (W, H));
    assert!(matches!(err, Err(GpuError::OverBudget { .. })), "{err:?}");

    // A linear target of another size (a surface): sRGB-encoded in the shader.
    let format = wgpu::TextureFormat::Rgba8Unorm;
    let (w2, h2) = (W / 2, H / 2);
    let tex2 = target(&device, format, w2, h2);
    r.render_to_view(&cam, 1.0, &list, &tex2.create_view(&Default::default()), format, (w2, h2)).unwrap();
    let small = read_texture(&device, &queue, &tex2);
    // Centre pixel: the front quad, about the headless colour.
    let c = ((h2 / 2 * w2 + w2 / 2) * 4) as usize;
    let hc = ((H / 2 * W + W / 2) * 4) as usize;
    for ch in 0..4 {
        assert!((small[c + ch] as i32 - headless.rgba[hc + ch] as i32).abs() <= 3, "{:?}", &small[c..c + 4]);
    }
    assert_eq!(small[3], 0, "corner is background");
}

#[test]
fn from_device_and_render_to_view_gl() {
    external(wgpu::Backends::GL);
}

#[test]
fn from_device_and_render_to_view_vulkan() {
    external(wgpu::Backends::VULKAN);
}

// ---------------------------------------------------------------------------------------------
// The orthographic projection.

/// Orthographic: two equal 10 × 10 quads, one 190 and one 50 units below the eye, cover the
/// same pixels (a view 100 units high on 200 pixels: 20 × 20 each), where perspective makes
/// the near one about 14 times larger; the shading's viewer direction is the headlight, so both
/// are shaded alike; a box the near plane cuts anywhere in the view is not queried.
fn orthographic(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut r) = renderer(backends, W, H) else { return };
    let far = quad(30, 45, 40, 55, 10, 3);
    let near = quad(60, 45, 70, 55, 150, 4);
    let list = [(key(1), &far), (key(2), &near)];
    let ortho = Camera { projection: tw_runtime::Projection::Orthographic { height: 100.0 }, ..top_camera() };
    let buf = r.item_buffer(&ortho, 1.0, &list).unwrap();
    let v = buf.visible();
    eprintln!("{backends:?}: orthographic pixels {:?}", v.objects);
    let (a, b) = (v.objects[&3], v.objects[&4]);
    assert_eq!(a, b, "equal quads at different distances");
    assert!((380..=420).contains(&a), "20 x 20 pixels expected, got {a}");
    let persp = r.item_buffer(&top_camera(), 1.0, &list).unwrap().visible();
    assert!(persp.objects[&4] > 10 * persp.objects[&3], "{:?}", persp.objects);
    let img = r.render_clusters(&ortho, 1.0, &list).unwrap();
    let at = |x: u32, y: u32| img.rgba[((y * W + x) * 4) as usize..][..3].to_vec();
    // Quad centres: x = 35 and 65 are 15 units left and right of the centre, 30 pixels.
    assert_eq!(at(W / 2 - 30, H / 2), at(W / 2 + 30, H / 2), "the same shade at any distance");
    r.begin_frame();
    r.draw(Target::Own, &ortho, 1.0, &list, true).unwrap();
    let boxes = [
        (Vec3::new(0.0, 0.0, 199.5), Vec3::new(5.0, 5.0, 205.0)), // cut by the near plane, off-centre
        (Vec3::new(32.0, 47.0, 0.0), Vec3::new(38.0, 53.0, 5.0)), // under the far quad: hidden
        (Vec3::new(10.0, 40.0, 0.0), Vec3::new(20.0, 60.0, 5.0)), // beside it: visible
    ];
    let got = r.query_boxes(&ortho, &boxes).unwrap();
    eprintln!("{backends:?}: orthographic query results {got:?}");
    assert_eq!(got[0], tw_gpu::query::EYE_INSIDE);
    assert_eq!(got[1], 0);
    assert!(got[2] > 0);
}

#[test]
fn orthographic_gl() {
    orthographic(wgpu::Backends::GL);
}

#[test]
fn orthographic_vulkan() {
    orthographic(wgpu::Backends::VULKAN);
}

// ---------------------------------------------------------------------------------------------
// Hardware occlusion queries of boxes against the frame's depth.

fn queries(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut r) = renderer(backends, W, H) else { return };
    let cam = top_camera();
    let back = quad(0, 0, 100, 100, 10, 5);
    r.begin_frame();
    r.draw(Target::Own, &cam, 1.0, &[(key(1), &back)], true).unwrap();
    let boxes = [
        (Vec3::new(40.0, 40.0, 0.0), Vec3::new(60.0, 60.0, 5.0)), // under the quad: hidden
        (Vec3::new(40.0, 40.0, 20.0), Vec3::new(60.0, 60.0, 30.0)), // above it: visible
        (Vec3::new(90.0, 90.0, 0.0), Vec3::new(130.0, 95.0, 5.0)), // under, but sticks out
        (Vec3::new(500.0, 0.0, 0.0), Vec3::new(510.0, 10.0, 5.0)), // off screen
        (Vec3::new(40.0, 40.0, 150.0), Vec3::new(60.0, 60.0, 250.0)), // around the eye
    ];
    let got = r.query_boxes(&cam, &boxes).unwrap();
    eprintln!("{backends:?}: query results {got:?} (samples: {})", r.queries_count_samples());
    assert_eq!(got[0], 0);
    assert!(got[1] > 0);
    assert!(got[2] > 0);
    assert_eq!(got[3], 0);
    assert_eq!(got[4], tw_gpu::query::EYE_INSIDE);
    if r.queries_count_samples() {
        // The visible box covers about its projected area in pixels.
        assert!(got[1] > 100, "{}", got[1]);
    }
}

#[test]
fn occlusion_queries_gl() {
    queries(wgpu::Backends::GL);
}

#[test]
fn occlusion_queries_vulkan() {
    queries(wgpu::Backends::VULKAN);
}

// ---------------------------------------------------------------------------------------------
// GPU HZB culling (gpu_cull.rs): the pyramid of the depth target equals the CPU one, the cull
// agrees with the CPU test, and the GPU-culled second pass draws the image of drawing it all.

fn gpu_cull(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut r) = renderer(backends, W, H) else { return };
    r.gpu_cull_supported().unwrap();
    eprintln!("{backends:?}: GPU cull compacts: {}", r.gpu_cull_compacts());
    check_wall_with_a_gap(&mut r);
    // The plant: half of the cut as occluders, the other half GPU-culled.
    let store = Store::open(plant_path()).unwrap();
    let cache = PageCache::new(&store, 1 << 30);
    r.set_store_colors(&store);
    for cam in &plant_cameras(&store, 3) {
        check_plant_view(&mut r, backends, &store, &cache, cam);
    }
}

/// A wall at z = 10 with a gap of one grid unit (about 1.4 px) at x = 89..90: the pyramids
/// agree, and the GPU test of boxes under, above, beside and around it is the CPU one.
fn check_wall_with_a_gap(r: &mut Renderer) {
    let cam = top_camera();
    let left = quad(0, 0, 89, 100, 10, 5);
    let right = quad(90, 0, 100, 100, 10, 5);
    r.begin_frame();
    r.draw(Target::Own, &cam, 1.0, &[(key(1), &left), (key(2), &right)], true).unwrap();
    let cpu = pyramids_of_the_depth(r);
    let boxes = [
        (Vec3::new(20.0, 40.0, 0.0), Vec3::new(30.0, 60.0, 5.0)), // under the wall
        (Vec3::new(84.0, 48.0, 0.0), Vec3::new(87.5, 52.0, 5.0)), // under the wall, 2 px from the gap
        (Vec3::new(88.0, 40.0, 0.0), Vec3::new(91.0, 60.0, 5.0)), // under the gap
        (Vec3::new(20.0, 40.0, 20.0), Vec3::new(30.0, 60.0, 30.0)), // above the wall
        (Vec3::new(500.0, 0.0, 0.0), Vec3::new(510.0, 10.0, 5.0)), // off screen
        (Vec3::new(40.0, 40.0, 150.0), Vec3::new(60.0, 60.0, 250.0)), // around the eye
    ];
    use HzbResult::*;
    let got = r.test_boxes_gpu(&cam, &boxes).unwrap();
    assert_eq!(got, vec![Occluded, Occluded, Visible, Visible, NoPixels, Visible]);
    let vp = cam.projection_reverse_z(W as f32 / H as f32) * cam.view();
    let want: Vec<HzbResult> = boxes.iter().map(|b| cpu.test_box_single_level(&vp, b.0, b.1)).collect();
    assert_eq!(got, want);
}

/// The CPU pyramid of the own depth target, after checking that the GPU built the same one.
fn pyramids_of_the_depth(r: &mut Renderer) -> Hzb {
    let depth = r.read_depth().unwrap();
    let cpu = Hzb::build(&depth.depth, depth.width, depth.height).unwrap();
    assert_eq!(r.read_gpu_hzb().unwrap(), cpu, "GPU and CPU pyramids of the same depth");
    cpu
}

/// One view's cut split in half: the first half drawn as occluders, the second GPU-culled,
/// each with its clusters' scene-space boxes.
struct Halves<'a> {
    occluders: &'a [(ClusterRef, &'a PageCluster)],
    occluder_boxes: Vec<(Vec3, Vec3)>,
    candidates: &'a [(ClusterRef, &'a PageCluster)],
    candidate_boxes: Vec<(Vec3, Vec3)>,
}

/// The plant from `cam`: the occluders' pyramids agree, random boxes near the candidates are
/// culled no more than the CPU test culls them, and the GPU-culled second pass draws the image
/// of drawing both halves.
fn check_plant_view(
    r: &mut Renderer,
    backends: wgpu::Backends,
    store: &Store,
    cache: &PageCache,
    cam: &Camera,
) {
    let step = store.header().grid_step;
    let sel = select(store, cache, cam, 0.0);
    let pages = tw_gpu::SelectionPages::resolve(store, cache, &sel);
    let list = pages.clusters();
    let (occluders, candidates) = list.split_at(list.len() / 2);
    let box_of = |(k, _): &(ClusterRef, &PageCluster)| {
        let (lo, hi) = cache.get(store, k.page).unwrap().bounds[k.index_in_page as usize];
        tw_runtime::frustum::grid_box(lo, hi, step)
    };
    let halves = Halves {
        occluders,
        occluder_boxes: occluders.iter().map(box_of).collect(),
        candidates,
        candidate_boxes: candidates.iter().map(box_of).collect(),
    };
    // Reference: both halves drawn, in the same order.
    r.begin_frame();
    r.draw(Target::Own, cam, step, halves.occluders, true).unwrap();
    let cpu = pyramids_of_the_depth(r);
    check_random_boxes(r, backends, cam, &cpu, &halves.candidate_boxes);
    r.draw(Target::Own, cam, step, halves.candidates, false).unwrap();
    let reference = r.read_color().unwrap();
    check_culled_second_pass(r, backends, cam, step, &halves, &cpu, &reference);
}

/// 4000 boxes of random centres and sizes around randomly chosen `boxes` (seeded, so the same
/// every run).
fn random_boxes_around(boxes: &[(Vec3, Vec3)]) -> Vec<(Vec3, Vec3)> {
    let mut rng = tw_core::Rng::new(3);
    (0..4000)
        .map(|_| {
            let (lo, hi) = boxes[(rng.f64() * boxes.len() as f64) as usize];
            let size = (hi - lo).max(Vec3::splat(1e-3));
            let c = lo
                + (hi - lo) * 0.5
                + (Vec3::new(rng.f64() as f32, rng.f64() as f32, rng.f64() as f32) - 0.5) * size * 4.0;
            let half = size * (0.05 + 2.0 * rng.f64() as f32);
            (c - half, c + half)
        })
        .collect()
}

/// Random boxes around the plant's cut against the occluders' pyramid `cpu`: the GPU never
/// culls what the CPU test sees, and agrees with it on at least 99% of them.
fn check_random_boxes(
    r: &mut Renderer,
    backends: wgpu::Backends,
    cam: &Camera,
    cpu: &Hzb,
    near: &[(Vec3, Vec3)],
) {
    use HzbResult::*;
    let random = random_boxes_around(near);
    let gpu = r.test_boxes_gpu(cam, &random).unwrap();
    let (mut agree, mut occluded) = (0, 0);
    for (bx, g) in random.iter().zip(&gpu) {
        // Occluded and NoPixels both mean "not drawn": a box the CPU sees, the GPU sees.
        // The GPU computes the single-level test; the exact CPU test may cull more.
        let c = cpu.test_box_single_level(&vp_of(cam), bx.0, bx.1);
        if c == Visible {
            assert_eq!(*g, Visible, "{backends:?}: GPU culls {bx:?}, the CPU test sees it");
        }
        if *g == Occluded {
            assert_ne!(cpu.test_box(&vp_of(cam), bx.0, bx.1), Visible, "{backends:?}: {bx:?}");
        }
        occluded += usize::from(*g == Occluded);
        agree += usize::from(c == *g);
    }
    eprintln!("{backends:?}: random boxes: {agree} of {} agree, {occluded} occluded", random.len());
    assert!(agree * 100 >= random.len() * 99);
}

/// The occluders drawn, then the candidates GPU-culled on top: within budget, one flag per
/// candidate, the `reference` image exactly, and every candidate the CPU test against the
/// occluders' pyramid `cpu` sees was drawn.
fn check_culled_second_pass(
    r: &mut Renderer,
    backends: wgpu::Backends,
    cam: &Camera,
    step: f64,
    halves: &Halves,
    cpu: &Hzb,
    reference: &Image,
) {
    use HzbResult::*;
    let (a, b) = (halves.occluders, halves.candidates);
    r.begin_frame();
    r.draw(Target::Own, cam, step, a, true).unwrap();
    let res = r.draw_gpu_culled(cam, step, b, &halves.candidate_boxes, &halves.occluder_boxes).unwrap();
    let image = r.read_color().unwrap();
    let culled = res.candidates.iter().filter(|f| **f == Occluded).count();
    let hidden = res.occluders.iter().filter(|f| **f != Visible).count();
    eprintln!(
        "{backends:?}: {} candidates, {culled} culled; {hidden} of {} occluders hidden at the end; \
         gpu {:?}, encode {:?}, compacted {}",
        b.len(),
        a.len(),
        res.gpu_time,
        res.encode_time,
        res.compacted
    );
    assert!(!res.over_budget);
    assert_eq!(res.candidates.len(), b.len());
    assert_eq!(image.differing_pixels(reference).unwrap(), 0, "GPU culling changed the image");
    // The CPU test of the same candidates against the occluders' depth: every candidate it
    // sees, the GPU drew.
    for (bx, g) in halves.candidate_boxes.iter().zip(&res.candidates) {
        if cpu.test_box(&vp_of(cam), bx.0, bx.1) == Visible {
            assert_eq!(*g, Visible, "{backends:?}: GPU culls {bx:?}, the CPU test sees it");
        }
    }
}

/// Candidates beyond the GPU budget: nothing is culled, everything is drawn (batched), and the
/// image is still that of drawing it all.
fn gpu_cull_over_budget(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut r) = renderer(backends, W, H) else { return };
    let store = Store::open(plant_path()).unwrap();
    let cache = PageCache::new(&store, 1 << 30);
    r.set_store_colors(&store);
    r.set_gpu_budget(tw_gpu::MIN_BUDGET);
    let step = store.header().grid_step;
    let cam = &plant_cameras(&store, 1)[0];
    let sel = select(&store, &cache, cam, 0.0);
    let pages = tw_gpu::SelectionPages::resolve(&store, &cache, &sel);
    let list = pages.clusters();
    let (a, b) = list.split_at(list.len() / 2);
    let boxes: Vec<(Vec3, Vec3)> = b
        .iter()
        .map(|(k, _)| {
            let (lo, hi) = cache.get(&store, k.page).unwrap().bounds[k.index_in_page as usize];
            tw_runtime::frustum::grid_box(lo, hi, step)
        })
        .collect();
    r.begin_frame();
    r.draw(Target::Own, cam, step, a, true).unwrap();
    r.draw(Target::Own, cam, step, b, false).unwrap();
    let reference = r.read_color().unwrap();
    r.begin_frame();
    r.draw(Target::Own, cam, step, a, true).unwrap();
    let res = r.draw_gpu_culled(cam, step, b, &boxes, &[]).unwrap();
    assert!(res.over_budget, "{} candidates fit {} bytes", b.len(), tw_gpu::MIN_BUDGET);
    assert!(res.candidates.iter().all(|f| *f == HzbResult::Visible));
    assert!(r.stats().pool.batches > 2);
    assert_eq!(r.read_color().unwrap().differing_pixels(&reference).unwrap(), 0);
}

#[test]
fn gpu_hzb_cull_over_budget_gl() {
    gpu_cull_over_budget(wgpu::Backends::GL);
}

#[test]
fn gpu_hzb_cull_over_budget_vulkan() {
    gpu_cull_over_budget(wgpu::Backends::VULKAN);
}

fn vp_of(cam: &Camera) -> glam::Mat4 {
    cam.projection_reverse_z(W as f32 / H as f32) * cam.view()
}

#[test]
fn gpu_hzb_cull_gl() {
    gpu_cull(wgpu::Backends::GL);
}

#[test]
fn gpu_hzb_cull_vulkan() {
    gpu_cull(wgpu::Backends::VULKAN);
}

/// 4× multisampling: the resolved frame equals the single-sample one inside the quads, blends
/// with the background only on their edges (premultiplied by coverage: alpha strictly between 0
/// and 255 there), and its depth resolve is the farthest sample of each pixel.
fn msaa(backends: wgpu::Backends) {
    let _g = gpu_lock();
    let Some(mut r) = renderer(backends, W, H) else { return };
    let back = quad(0, 0, 100, 100, 10, 5);
    let front = quad(40, 40, 61, 61, 50, 7);
    let list = [(key(1), &back), (key(2), &front)];
    let one = r.render_clusters(&top_camera(), 1.0, &list).unwrap();
    let depth_one = r.read_depth().unwrap();
    if !r.multisampling_supported() {
        let e = r.set_samples(4).unwrap_err().to_string();
        assert!(e.contains("not supported"), "{e}");
        assert_eq!(r.samples(), 1);
        return;
    }
    r.set_samples(4).unwrap();
    assert_eq!(r.samples(), 4);
    let four = r.render_clusters(&top_camera(), 1.0, &list).unwrap();
    let depth_four = r.read_depth().unwrap();
    let alpha = |img: &tw_gpu::Image, x: u32, y: u32| img.rgba[((y * W + x) * 4 + 3) as usize];
    let mut partial = 0;
    let mut inner_differ = 0;
    for y in 0..H {
        for x in 0..W {
            let a = alpha(&four, x, y);
            if a != 0 && a != 255 {
                partial += 1;
            }
            let d1 = depth_one.get(x, y).unwrap();
            let d4 = depth_four.get(x, y).unwrap();
            // The farthest sample is never nearer than the centre's depth.
            assert!(d4 <= d1 + 1e-6, "{backends:?}: pixel ({x}, {y}) resolved depth {d4} nearer than {d1}");
            let i = ((y * W + x) * 4) as usize;
            let fully = a == 255 && d4 == d1;
            if fully && x > 0 && y > 0 && one.rgba[i..i + 4] != four.rgba[i..i + 4] {
                inner_differ += 1;
            }
        }
    }
    let covered = one.covered_pixels();
    eprintln!("{backends:?}: {covered} covered pixels, {partial} partially covered with 4 samples");
    assert!(covered > 1000, "{backends:?}: the single-sample frame is nearly empty");
    assert!(four.covered_pixels() >= covered, "{backends:?}: multisampling lost pixels");
    assert!(partial > 100 && partial < covered / 4, "{backends:?}: {partial} edge pixels");
    assert!(inner_differ < covered / 100, "{backends:?}: {inner_differ} inner pixels differ");

    // The own target's colour is resolved once, when read: a frame drawn in two passes reads
    // as the same frame drawn in one, and so does the own colour texture a viewer copies.
    r.begin_frame();
    r.draw(Target::Own, &top_camera(), 1.0, &list[..1], true).unwrap();
    r.draw(Target::Own, &top_camera(), 1.0, &list[1..], false).unwrap();
    let (device, queue) = (r.device().0.clone(), r.device().1.clone());
    assert_eq!(read_texture(&device, &queue, r.color_texture()), four.rgba, "{backends:?}: own texture");
    assert_eq!(r.read_color().unwrap().rgba, four.rgba, "{backends:?}: two passes");
    // A caller's view of the own size shares the multisampled target: drawing into it keeps
    // the own frame, not yet resolved, intact.
    r.begin_frame();
    r.draw(Target::Own, &top_camera(), 1.0, &list, true).unwrap();
    let format = wgpu::TextureFormat::Rgba8UnormSrgb;
    let tex = target(&device, format, W, H);
    r.render_to_view(&top_camera(), 1.0, &list[..1], &tex.create_view(&Default::default()), format, (W, H))
        .unwrap();
    let own = read_texture(&device, &queue, r.color_texture());
    assert_eq!(own, four.rgba, "{backends:?}: own frame after a view");
    assert_ne!(read_texture(&device, &queue, &tex), four.rgba, "{backends:?}: the view's frame");

    assert!(r.set_samples(3).is_err());
    r.set_samples(1).unwrap();
    let again = r.render_clusters(&top_camera(), 1.0, &list).unwrap();
    assert_eq!(again.rgba, one.rgba, "{backends:?}: back to one sample");
}

#[test]
fn msaa_gl() {
    msaa(wgpu::Backends::GL);
}

#[test]
fn msaa_vulkan() {
    msaa(wgpu::Backends::VULKAN);
}
