//! Where a frame's time goes on this machine's rasterizer: times the fixed stages of a frame —
//! clearing, drawing the frame's cut, the depth read-back and CPU HZB build that `hzb` needs,
//! the colour read-back — separately, waiting for the GPU after each, on the walk frames of a
//! camera path. A profiling tool for docs/benchmarks-log.md, not a benchmark of the pipeline itself
//! (`terawalk bench` is that).
//!
//! `cargo run --release -p tw-frame --example stage_times -- STORE PATH.json [FRAMES] [WxH]`

use std::sync::Arc;
use std::time::{Duration, Instant};

use tw_frame::{FrameSettings, Occlusion, Walkthrough};
use tw_gpu::{Renderer, Target};
use tw_runtime::{CameraPath, Hzb, StreamOptions};
use tw_store::Store;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: stage_times STORE PATH.json [FRAMES] [WxH]");
        std::process::exit(2);
    }
    let store = Arc::new(Store::open(&args[1])?);
    let path = CameraPath::load(std::path::Path::new(&args[2]))?;
    let frames: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(20);
    let (w, h) = match args.get(4).and_then(|s| s.split_once('x')) {
        Some((a, b)) => (a.parse()?, b.parse()?),
        None => (1280u32, 720u32),
    };
    let renderer = Renderer::new_headless(w, h)?;
    println!("{} at {w}×{h}", renderer.adapter_summary());
    let options = StreamOptions { budget_bytes: 512 << 20, ..Default::default() };
    let mut walk = Walkthrough::new(store.clone(), renderer, options)?;
    let grid_step = store.header().grid_step;
    let settings = FrameSettings { occlusion: Occlusion::Hzb, wait_for_pages: true, ..Default::default() };
    let mut rows: Vec<[Duration; 6]> = Vec::new();
    let cameras: Vec<_> = path.frames.iter().filter(|f| f.segment == "walk").take(frames).collect();
    for f in cameras {
        let camera = f.to_scene(store.header())?;
        let drawn_refs = walk.draw_frame(&camera, &settings)?.drawn;
        walk.renderer_mut().read_color()?;
        // The frame's whole cut (no occlusion), pages resident after the frame above.
        let refs = walk.selection().clusters.clone();
        let cache = walk.streamer().cache().clone();
        let pages: Vec<_> =
            refs.iter().filter_map(|c| cache.get(&store, c.page).ok().map(|p| (*c, p))).collect();
        let clusters: Vec<_> = pages
            .iter()
            .filter_map(|(c, p)| p.clusters.get(c.index_in_page as usize).map(|pc| (*c, pc)))
            .collect();
        let drawn: Vec<_> = clusters.iter().filter(|(c, _)| drawn_refs.contains(c)).copied().collect();
        let r = walk.renderer_mut();
        let wait = |r: &Renderer| {
            let _ = r.device().0.poll(tw_gpu::wgpu::PollType::wait_indefinitely());
        };
        let t = Instant::now();
        r.begin_frame();
        r.draw(Target::Own, &camera, grid_step, &[], true)?;
        wait(r);
        let clear = t.elapsed();
        let t = Instant::now();
        r.begin_frame();
        r.draw(Target::Own, &camera, grid_step, &drawn, true)?;
        wait(r);
        let draw_drawn = t.elapsed();
        let t = Instant::now();
        r.begin_frame();
        r.draw(Target::Own, &camera, grid_step, &clusters, true)?;
        wait(r);
        let draw_cut = t.elapsed();
        let t = Instant::now();
        let depth = r.read_depth()?;
        let read_depth = t.elapsed();
        let t = Instant::now();
        let _hzb = Hzb::build(&depth.depth, depth.width, depth.height)?;
        let hzb = t.elapsed();
        let t = Instant::now();
        let _ = r.read_color()?;
        let read_color = t.elapsed();
        rows.push([clear, draw_drawn, draw_cut, read_depth, hzb, read_color]);
    }
    let names = [
        "clear",
        "draw what hzb drew (both passes)",
        "draw the whole cut",
        "read depth",
        "build HZB (CPU)",
        "read colour",
    ];
    for (i, name) in names.iter().enumerate() {
        let mut v: Vec<f64> = rows.iter().map(|r| r[i].as_secs_f64() * 1e3).collect();
        v.sort_by(|a, b| a.total_cmp(b));
        println!("{name:>36}: median {:7.2} ms over {} frames", v[v.len() / 2], v.len());
    }
    Ok(())
}
