//! Renders the same frame N times and prints each frame's times, to separate cold (pipeline
//! compilation, first uploads) from warm frames:
//!
//! ```text
//! cargo run --release -p tw-gpu --example frames -- STORE [WxH] [CAMERA|iso] [N] [TAU] [OUT.png]
//! ```
//!
//! CAMERA is "eye;target;up;fovy" in input coordinates (as `terawalk render --camera`); `iso`
//! (the default) frames the whole store like `terawalk render` without `--camera`. The backend
//! comes from WGPU_BACKEND; TW_DRAW_MODE=direct draws with a `draw_indexed` loop. Prints per frame: upload, render (encode + submit + GPU + readback)
//! and the wall time of `render_selection`, then the median of the warm frames (all but the first).

use std::time::Instant;

use tw_gpu::Renderer;
use tw_runtime::{Camera, InputCamera, PageCache, SelectOptions, Selector};
use tw_store::Store;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().expect("usage: frames STORE [WxH] [CAMERA|iso] [N] [TAU]");
    let (w, h) = args
        .get(1)
        .and_then(|s| s.split_once('x'))
        .map(|(a, b)| (a.parse().unwrap(), b.parse().unwrap()))
        .unwrap_or((1280u32, 720u32));
    let cam = args.get(2).map(String::as_str).unwrap_or("iso");
    let n: usize = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(10);
    let tau: f32 = args.get(4).map(|s| s.parse().unwrap()).unwrap_or(1.0);

    let store = Store::open(path).unwrap();
    let header = store.header();
    let camera = if cam == "iso" {
        let bounds = tw_core::Aabb { min: header.bounds_min, max: header.bounds_max };
        let pc = tw_preview::Camera::frame_bounds(
            &bounds,
            [-0.55, -0.75, 0.55],
            [0.0, 0.0, 1.0],
            w as f64 / h as f64,
        );
        Camera::from_input_coordinates(pc.eye, pc.target, pc.up, pc.fovy_deg, header).unwrap()
    } else {
        InputCamera::parse(cam).unwrap().to_scene(header).unwrap()
    };
    let t = Instant::now();
    let mut renderer = Renderer::new_headless(w, h).unwrap();
    eprintln!(
        "adapter: {} (created in {:.1} ms)",
        renderer.adapter_summary(),
        t.elapsed().as_secs_f64() * 1e3
    );
    renderer.set_store_colors(&store);
    if std::env::var("TW_DRAW_MODE").as_deref() == Ok("direct") {
        renderer.set_draw_mode(tw_gpu::DrawMode::Direct);
    }
    eprintln!("draw mode: {:?}", renderer.draw_mode());
    let cache = PageCache::new(&store, 1 << 30);
    cache.load_root_pages(&store);
    let options = SelectOptions { tau, viewport: [w, h], frustum_culling: true, ..Default::default() };
    let selection = Selector::new(&store).select(&store, &cache, &camera, &options);
    let mut warm = Vec::new();
    let mut image = None;
    for i in 0..n {
        let t = Instant::now();
        image = Some(renderer.render_selection(&store, &cache, &camera, &selection).unwrap());
        let wall = t.elapsed().as_secs_f64() * 1e3;
        let s = renderer.stats();
        eprintln!(
            "frame {i}: {} triangles, upload {:.1} ms, render {:.1} ms, wall {wall:.1} ms",
            s.triangles,
            s.upload.as_secs_f64() * 1e3,
            s.render.as_secs_f64() * 1e3
        );
        if i > 0 {
            warm.push(s.render.as_secs_f64() * 1e3);
        }
    }
    warm.sort_by(f64::total_cmp);
    if !warm.is_empty() {
        eprintln!(
            "warm render: median {:.1} ms, min {:.1} ms, max {:.1} ms ({} frames)",
            warm[warm.len() / 2],
            warm[0],
            warm[warm.len() - 1],
            warm.len()
        );
    }
    if let (Some(out), Some(image)) = (args.get(5), image) {
        image.save_png(std::path::Path::new(out)).unwrap();
    }
}
