//! The shadows' image check (BENCHMARKS.md "Shadows"): on frames of a camera path, the
//! rasterized shadow mask (shadow maps drawn from the light-view sets, cross-culled; the frame
//! pipeline with `ColorMode::Shadow`) against the ray tracer's (a shadow ray per pixel, the same
//! LOD cut), compared away from shadow edges (`tw_frame::mask`). Pages are loaded before each
//! frame, so both draw the complete cut. Every frame of the path is drawn in order (the layers
//! are reused from frame to frame as in a walkthrough); every EVERY-th is compared.
//!
//! `cargo run --release -p tw-frame --example shadow_check -- STORE PATH.json [EVERY] [LIGHT] [WxH] [MAP] [CASCADES] [LOD] [REF_TAU]`
//! (defaults: every 10th frame, `sun`, 640x360, the default layers of `ShadowOptions`, the
//! eye's LOD, the reference traced at the same τ = 1). `LOD` `finer` draws the rasterized
//! frames under the policy "the finer of both" (`ShadowLod::Finer`); `REF_TAU` 0 traces the
//! reference at full detail, so that both policies are compared with the same ground truth
//! (the ray tracer selects its own cut at the eye's LOD and that τ).

use std::sync::Arc;

use tw_frame::mask::compare_shadow_images;
use tw_frame::shadow::ShadowOptions;
use tw_frame::traced::TracedWalkthrough;
use tw_frame::{FrameSettings, Occlusion, ShadowLod, ShadowSettings, Walkthrough};
use tw_gpu::{ColorMode, Renderer};
use tw_rt::scene::TraceSettings;
use tw_runtime::{CameraPath, InputLight, StreamOptions};
use tw_store::Store;

/// Pixels this close to a lit/blocked boundary of the ray-traced mask are not compared.
const EDGE_PX: u32 = 2;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!(
            "usage: shadow_check STORE PATH.json [EVERY] [LIGHT] [WxH] [MAP] [CASCADES] [LOD] [REF_TAU]"
        );
        std::process::exit(2);
    }
    let store = Arc::new(Store::open(&args[1])?);
    let path = CameraPath::load(std::path::Path::new(&args[2]))?;
    let every: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(10).max(1);
    let light = InputLight::parse(args.get(4).map_or("sun", |s| s.as_str()))?;
    let (w, h) = match args.get(5).and_then(|s| s.split_once('x')) {
        Some((a, b)) => (a.parse()?, b.parse()?),
        None => (640u32, 360u32),
    };
    let defaults = ShadowOptions::default();
    let size: u32 = args.get(6).map(|s| s.parse()).transpose()?.unwrap_or(defaults.size);
    let cascades: u32 = args.get(7).map(|s| s.parse()).transpose()?.unwrap_or(defaults.cascades);
    let lod = match args.get(8) {
        Some(s) => ShadowLod::parse(s).ok_or_else(|| format!("LOD must be eye or finer, got {s:?}"))?,
        None => ShadowLod::Eye,
    };
    let reference_tau: f32 = args.get(9).map(|s| s.parse()).transpose()?.unwrap_or(1.0);
    let stream = StreamOptions { budget_bytes: 1 << 30, ..Default::default() };
    let mut renderer = Renderer::new_headless(w, h)?;
    renderer.set_color_mode(ColorMode::Shadow);
    println!(
        "{} at {w}x{h}, {size}-texel layers, every {every}th frame, {} LOD, reference at τ = {reference_tau}",
        renderer.adapter_summary(),
        lod.name()
    );
    let mut walk = Walkthrough::new(store.clone(), renderer, stream)?;
    let trace = TraceSettings { coloring: ColorMode::Shadow, ..Default::default() };
    let mut traced = TracedWalkthrough::new(store.clone(), (w, h), stream, trace)?;
    let (mut compared, mut agree, mut worst) = (0u64, 0u64, 1f64);
    // Every frame is drawn, in order, so that the layers are reused as along a walk; every
    // `every`-th is compared.
    for (i, f) in path.frames.iter().enumerate() {
        let camera = f.to_scene(store.header())?;
        let light = light.to_scene(store.header(), store.header().up_axis, &camera);
        let options = ShadowOptions { size, cascades, ..defaults };
        options.validate()?;
        let settings = FrameSettings {
            occlusion: Occlusion::Hzb,
            wait_for_pages: true,
            shadows: Some(ShadowSettings { light, options, cross_culling: true, lod }),
            ..Default::default()
        };
        let (raster, info) = walk.frame(&camera, &settings)?;
        if i % every != 0 {
            continue;
        }
        let (reference, ..) = traced.frame(&camera, &FrameSettings { tau: reference_tau, ..settings })?;
        let a = compare_shadow_images(&reference, &raster, EDGE_PX)?;
        compared += a.compared;
        agree += a.agree;
        worst = worst.min(a.ratio());
        println!(
            "frame {i:4} ({}): {:.3} % of {} pixels agree (lit as blocked {}, blocked as lit {}; {} edge pixels left out); {} layers, {} reused; cut {} triangles, light sets {}",
            f.segment,
            100.0 * a.ratio(),
            a.compared,
            a.lit_as_blocked,
            a.blocked_as_lit,
            a.excluded_edge,
            info.shadow.layers,
            info.shadow.layers_reused,
            info.cut_triangles,
            info.shadow.light_triangles
        );
    }
    println!(
        "all frames: {:.3} % of {compared} pixels agree away from shadow edges; worst frame {:.3} %",
        100.0 * agree as f64 / compared.max(1) as f64,
        100.0 * worst
    );
    Ok(())
}
