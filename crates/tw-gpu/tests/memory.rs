//! The process memory of a renderer does not grow with the frames it draws: after a warm-up,
//! another 100 frames of every kind of pass the strategies use (two shaded passes, box
//! queries, the GPU HZB cull, each colour mode, a shadow-map pass and the shading with shadows
//! every other frame) leave the resident set where it was.
//!
//! The regression this guards against: Mesa 22.3's lavapipe compiles a new copy of a shader
//! whose branches test uniform-buffer values alone each time its pipeline is bound, and never
//! frees the copies (docs/RUNTIME.md, "Memory"); the shaded vertex shader and the HZB cull
//! shader did, which grew a bench process by ~0.3 MB a pass (~50 MB a 100-frame run). The
//! growth is process memory on CPU drivers only: elsewhere the test draws the frames and
//! reports the figures without judging them.
//!
//! Its own test binary, so no other test's allocations run in the same process. Without an
//! adapter it is skipped with a note, unless `TERAWALK_REQUIRE_GPU=1`, where it fails. Vulkan
//! on machines without a GPU: `apt-get install mesa-vulkan-drivers` and
//! `VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json`.

use glam::Vec3;
use tw_gpu::{ColorMode, GpuError, Renderer, Target};
use tw_runtime::{Camera, ClusterRef, Light, ShadowClass, ShadowLayer, Shadows};
use tw_store::PageCluster;

mod common;
use common::{key, quad};

const W: u32 = 160;
const H: u32 = 100;
const FRAMES: usize = 100;
/// Allowed growth over [`FRAMES`] frames: far below the ~0.3 MB a pass of the leak (> 100 MB
/// here), above the allocator's noise.
const SLACK_BYTES: u64 = 16 << 20;

/// Looking down -z at the centre of [0, 100]², from z = 200, turning a little each frame.
fn camera(frame: usize) -> Camera {
    let a = frame as f32 * 0.05;
    Camera {
        eye: Vec3::new(50.0 + a.cos(), 50.0 + a.sin(), 200.0),
        target: Vec3::new(50.0, 50.0, 0.0),
        up: Vec3::Y,
        projection: tw_runtime::Projection::Perspective { fovy: 40f32.to_radians() },
        near: 1.0,
        far: 1000.0,
    }
}

/// The shadows of a sun straight above [0, 100]² (one orthographic layer of `SHADOW_MAP`²).
fn shadows() -> Shadows {
    let view =
        tw_runtime::camera::look_at_rh(Vec3::new(50.0, 50.0, 150.0), Vec3::new(50.0, 50.0, 0.0), Vec3::Y);
    // Orthographic over ±60 around the centre, depth 0 at 1, 1 at 200.
    let proj = glam::Mat4::from_cols(
        glam::Vec4::new(1.0 / 60.0, 0.0, 0.0, 0.0),
        glam::Vec4::new(0.0, 1.0 / 60.0, 0.0, 0.0),
        glam::Vec4::new(0.0, 0.0, -1.0 / 199.0, 0.0),
        glam::Vec4::new(0.0, 0.0, -1.0 / 199.0, 1.0),
    );
    Shadows {
        light: Light::Sun { towards: Vec3::Z },
        layers: vec![ShadowLayer { view_proj: proj * view, split: [0.0, f32::INFINITY] }],
        size: SHADOW_MAP,
        bias: 0.0,
    }
}

const SHADOW_MAP: u32 = 128;

/// One frame of each strategy's passes: occluders, box queries, the second pass; then the GPU
/// HZB cull and its draw where the device has it. Every other frame draws the shadow map first
/// and shades with shadows (one cluster classed lit, the others looked up).
fn frame(r: &mut Renderer, i: usize, scene: &[PageCluster], gpu_cull: bool) {
    let cam = camera(i);
    let list: Vec<(ClusterRef, &PageCluster)> =
        scene.iter().enumerate().map(|(k, c)| (key(k as u32 + 1), c)).collect();
    if i.is_multiple_of(2) {
        let s = shadows();
        r.draw_shadow_map(0, &s.layers[0].view_proj, 1.0, &list, true).unwrap();
        r.set_shadows(Some(&s));
        r.set_shadow_classes(&[(list[0].0, ShadowClass::Lit)]);
    } else {
        r.set_shadows(None);
    }
    let (occluders, candidates) = list.split_at(1);
    let boxes: Vec<(Vec3, Vec3)> = candidates
        .iter()
        .map(|(_, c)| {
            let lo = c
                .positions
                .iter()
                .fold([u32::MAX; 3], |m, p| [m[0].min(p[0]), m[1].min(p[1]), m[2].min(p[2])]);
            let hi = c.positions.iter().fold([0; 3], |m, p| [m[0].max(p[0]), m[1].max(p[1]), m[2].max(p[2])]);
            (Vec3::from_array(lo.map(|v| v as f32)), Vec3::from_array(hi.map(|v| v as f32)))
        })
        .collect();
    r.begin_frame();
    r.draw(Target::Own, &cam, 1.0, occluders, true).unwrap();
    let samples = r.query_boxes(&cam, &boxes).unwrap();
    assert_eq!(samples.len(), boxes.len());
    r.draw(Target::Own, &cam, 1.0, candidates, false).unwrap();
    r.read_color().unwrap();
    if gpu_cull {
        r.begin_frame();
        r.draw(Target::Own, &cam, 1.0, occluders, true).unwrap();
        r.draw_gpu_culled(&cam, 1.0, candidates, &boxes, &boxes[..1]).unwrap();
        r.read_color().unwrap();
    }
}

#[test]
fn frames_do_not_grow_process_memory_vulkan() {
    let mut r = match Renderer::new_headless_with(W, H, wgpu::Backends::VULKAN) {
        Ok(r) => r,
        Err(e @ GpuError::NoAdapter { .. })
            if std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1") =>
        {
            eprintln!("SKIPPED: {e} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    eprintln!("{}", r.adapter_summary());
    let Some(_) = tw_core::mem::rss_bytes() else {
        eprintln!("SKIPPED: no /proc/self/status to read the resident set from");
        return;
    };
    // A floor, a wall across it and two quads behind the wall (occluded) and in front of it.
    let scene = vec![
        quad(0, 0, 100, 100, 0, 1),
        quad(20, 20, 80, 80, 40, 2),
        quad(30, 30, 40, 40, 20, 3),
        quad(60, 60, 70, 70, 60, 4),
    ];
    let gpu_cull = r.gpu_cull_supported().is_ok();
    r.set_shadow_map(SHADOW_MAP, 1).unwrap();
    // Warm-up: every pipeline made (each colour mode, with and without shadows, is one), pool
    // and read-back buffers at size.
    let modes =
        [ColorMode::Material, ColorMode::Object, ColorMode::Level, ColorMode::Cluster, ColorMode::Shadow];
    for (i, &mode) in modes.iter().enumerate() {
        r.set_color_mode(mode);
        frame(&mut r, 2 * i, &scene, gpu_cull);
        frame(&mut r, 2 * i + 1, &scene, gpu_cull);
    }
    for i in 0..10 {
        frame(&mut r, i, &scene, gpu_cull);
    }
    let before = tw_core::mem::rss_bytes().unwrap();
    for i in 0..FRAMES {
        r.set_color_mode(modes[i % modes.len()]);
        frame(&mut r, i, &scene, gpu_cull);
    }
    let after = tw_core::mem::rss_bytes().unwrap();
    let grown = after.saturating_sub(before);
    eprintln!(
        "resident set {:.1} -> {:.1} MB over {FRAMES} frames (+{:.1} MB; GPU HZB cull: {gpu_cull})",
        before as f64 / 1e6,
        after as f64 / 1e6,
        grown as f64 / 1e6
    );
    if r.info().device_type == wgpu::DeviceType::Cpu {
        assert!(
            grown <= SLACK_BYTES,
            "the resident set grew by {:.1} MB over {FRAMES} frames (allowed {} MB): is a shader \
             branching on a uniform again? (docs/RUNTIME.md, \"Memory\")",
            grown as f64 / 1e6,
            SLACK_BYTES >> 20
        );
    }
}
