//! The external-device entry points a viewer uses: [`Renderer::from_device`] on a device the
//! caller opened, and [`Renderer::render_to_view`] into a caller-owned texture (here read back
//! by the test itself) give the same pixels as the headless path.

use tw_gpu::Renderer;
use tw_runtime::Camera;
use tw_store::PageCluster;

const W: u32 = 64;
const H: u32 = 48;

fn device(backends: wgpu::Backends) -> Option<(wgpu::Device, wgpu::Queue, wgpu::AdapterInfo)> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = backends;
    let instance = wgpu::Instance::new(desc);
    let adapter = match pollster::block_on(instance.request_adapter(&Default::default())) {
        Ok(a) => a,
        Err(e) if std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1") => {
            eprintln!("SKIPPED {backends:?}: {e}");
            return None;
        }
        Err(e) => panic!("{backends:?}: {e}"),
    };
    let info = adapter.get_info();
    let (d, q) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
        ..Default::default()
    }))
    .unwrap();
    Some((d, q, info))
}

/// A quad of two triangles facing the camera at the origin.
fn quad() -> PageCluster {
    PageCluster {
        positions: vec![[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]],
        indices: vec![0, 1, 2, 0, 2, 3],
        objects: vec![3, 3],
        self_error: 0.0,
        self_sphere: [5.0, 5.0, 0.0, 8.0],
        group: 0,
        level: 0,
    }
}

fn camera() -> Camera {
    Camera {
        eye: glam::Vec3::new(5.0, 5.0, 20.0),
        target: glam::Vec3::new(5.0, 5.0, 0.0),
        up: glam::Vec3::Y,
        fovy: 60f32.to_radians(),
        near: 0.1,
        far: 100.0,
    }
}

fn read_texture(device: &wgpu::Device, queue: &wgpu::Queue, tex: &wgpu::Texture) -> Vec<u8> {
    let row = 256u32;
    let buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: (row * H) as u64,
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
        wgpu::Extent3d { width: W, height: H, depth_or_array_layers: 1 },
    );
    queue.submit([enc.finish()]);
    buf.map_async(wgpu::MapMode::Read, .., |r| r.unwrap());
    device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    let data = buf.get_mapped_range(..).unwrap();
    data.chunks(row as usize).flat_map(|r| r[..(W * 4) as usize].to_vec()).collect()
}

fn check(backends: wgpu::Backends) {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let Some((device, queue, info)) = device(backends) else { return };
    let mut r = Renderer::from_device(device.clone(), queue.clone(), info, W, H).unwrap();
    let q = quad();
    r.upload_clusters(1.0, &[(tw_runtime::ClusterRef { page: 0, index_in_page: 0, group: 0 }, &q)]);
    let headless = r.render(&camera()).unwrap();
    assert!(headless.covered_pixels() > 100);

    let format = wgpu::TextureFormat::Rgba8UnormSrgb;
    let tex = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("viewer target"),
        size: wgpu::Extent3d { width: W, height: H, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    r.render_to_view(&camera(), &tex.create_view(&Default::default()), format, (W, H)).unwrap();
    assert_eq!(read_texture(&device, &queue, &tex), headless.rgba);

    // A linear target of another size: drawn (sRGB encoded in the shader), same coverage share.
    let format = wgpu::TextureFormat::Rgba8Unorm;
    let tex2 = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("linear target"),
        size: wgpu::Extent3d { width: W, height: H, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    r.render_to_view(&camera(), &tex2.create_view(&Default::default()), format, (W, H)).unwrap();
    let linear = read_texture(&device, &queue, &tex2);
    for (a, b) in linear.chunks(4).zip(headless.rgba.chunks(4)) {
        assert_eq!(a[3], b[3]);
        for c in 0..3 {
            assert!((a[c] as i32 - b[c] as i32).abs() <= 2, "{a:?} vs {b:?}");
        }
    }
}

#[test]
fn from_device_and_render_to_view_gl() {
    check(wgpu::Backends::GL);
}

#[test]
fn from_device_and_render_to_view_vulkan() {
    check(wgpu::Backends::VULKAN);
}
