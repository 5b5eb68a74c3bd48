//! The cost of ray-traced shadows: frames of one camera traced without a light and with one
//! (`--light`), alternating in one process so that both see the same load on a shared machine.
//!
//! ```text
//! cargo run --release -p tw-rt --example shadow_bench -- STORE.tw (--camera "EYE;TARGET;UP;FOVY" | --walk K | --fly K) [options]
//!   --light L      sun | sun:AZ,EL | point:X,Y,Z (input coordinates; default sun)
//!   --size WxH     image size (default 640x480)
//!   --threads N    rayon threads while tracing (default 2)
//!   --runs N       timed frames per mode, alternating; medians are reported (default 7)
//!   --memory MIB   page cache budget in MiB (default 1536: the pages' share of --memory 2G)
//! ```
//!
//! `--walk K` / `--fly K`: frame K of the generated walk / fly-over path (600 frames, seed 2).
//! Without a light the cut is the eye's (τ = 1 px, frustum-culled, every page loaded); with one
//! it is the eye's LOD over the whole store cut down to the light's sweep of the view
//! (`CasterVolume`), as tw-frame's `TracedWalkthrough` selects it. Each mode keeps its own
//! tracer, warmed by one frame, so the timed frames reuse their cluster BVHs (a steady camera).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use tw_rt::scene::casters::CasterVolume;
use tw_rt::scene::{StoreTracer, TraceSettings, TraceStats};
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::{
    Camera, InputCamera, InputLight, Light, ResidentPage, SelectOptions, Selection, SelectionPages,
    StreamOptions, Streamer,
};
use tw_store::Store;

enum View {
    Camera(String),
    Path(PathPart, usize),
}

struct Args {
    store: PathBuf,
    view: View,
    light: String,
    width: u32,
    height: u32,
    threads: usize,
    runs: usize,
    memory_mib: u64,
}

fn main() {
    if let Err(e) = run() {
        eprintln!("shadow_bench: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args = parse_args()?;
    let store = Arc::new(Store::open(&args.store).map_err(|e| format!("{}: {e}", args.store.display()))?);
    let camera = camera(&store, &args.view)?;
    let input = InputLight::parse(&args.light).map_err(|e| e.to_string())?;
    let header = store.header();
    let light = input.to_scene(header, header.up_axis, &camera);
    eprintln!("camera {camera:?}\nlight {light:?}");
    let options =
        StreamOptions { budget_bytes: args.memory_mib << 20, loader_threads: 0, ..Default::default() };
    let mut streamer = Streamer::new(store.clone(), options).map_err(|e| e.to_string())?;
    let (eye_cut, eye_pages) = cut(&mut streamer, &camera, &args, None)?;
    let (light_cut, light_pages) = cut(&mut streamer, &camera, &args, Some(light))?;

    let pool =
        rayon::ThreadPoolBuilder::new().num_threads(args.threads).build().map_err(|e| e.to_string())?;
    // The BVHs' share beside pages of `--memory` (`StoreTracer::budget_split`: a quarter of the
    // whole, a third of the pages' three quarters).
    let bvhs = (args.memory_mib << 20) / 3;
    let modes = [
        ("no light", eye_cut, eye_pages, TraceSettings::default()),
        ("light", light_cut, light_pages, TraceSettings { light: Some(light), ..Default::default() }),
    ];
    let mut tracers: Vec<StoreTracer> = modes.iter().map(|_| StoreTracer::new(&store, bvhs)).collect();
    let mut stats: Vec<Vec<TraceStats>> = vec![Vec::new(); modes.len()];
    for run in 0..=args.runs {
        for (k, (_, selection, pages, settings)) in modes.iter().enumerate() {
            let held = SelectionPages::from_resident(pages, &selection.clusters);
            let t = Instant::now();
            let frame =
                pool.install(|| tracers[k].trace(&held, &camera, (args.width, args.height), settings));
            let mut s = frame.stats;
            s.total = t.elapsed();
            if run > 0 {
                stats[k].push(s);
            }
        }
    }
    println!(
        "{:<9} {:>8} {:>10} {:>9} {:>9} {:>9} {:>9} {:>10} {:>9}",
        "", "clusters", "triangles", "BVH MiB", "total ms", "trace ms", "shade ms", "rays", "M rays/s"
    );
    for (((name, ..), s), tracer) in modes.iter().zip(&stats).zip(&tracers) {
        let ms = |f: &dyn Fn(&TraceStats) -> f64| median(s.iter().map(f).collect()) * 1e3;
        let total = ms(&|s| s.total.as_secs_f64());
        let rays = s[0].rays;
        println!(
            "{name:<9} {:>8} {:>10} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>10} {:>9.2}",
            s[0].clusters,
            s[0].triangles,
            tracer.bytes() as f64 / (1 << 20) as f64,
            total,
            ms(&|s| s.trace_time.as_secs_f64()),
            ms(&|s| s.shade_time.as_secs_f64()),
            rays,
            rays as f64 / (ms(&|s| (s.trace_time + s.shade_time).as_secs_f64()) * 1e-3) / 1e6,
        );
    }
    Ok(())
}

/// The camera of `view`.
fn camera(store: &Store, view: &View) -> Result<Camera, String> {
    match view {
        View::Camera(s) => {
            let input = InputCamera::parse(s).map_err(|e| e.to_string())?;
            input.to_scene(store.header()).map_err(|e| e.to_string())
        }
        View::Path(part, frame) => {
            let options = PathOptions { frames: 600, part: *part, seed: 2, ..Default::default() };
            let path = generate_path(store, &options, &mut |_, _, _| {}).map_err(|e| e.to_string())?.path;
            let f = path
                .frames
                .get(*frame)
                .ok_or_else(|| format!("the path has {} frames", path.frames.len()))?;
            f.to_scene(store.header()).map_err(|e| e.to_string())
        }
    }
}

/// The frame's cut at τ = 1 with every page loaded: the eye's (frustum-culled), or for `light`
/// the eye's LOD over the whole store, cut down to the light's sweep of the view.
#[allow(clippy::type_complexity)]
fn cut(
    streamer: &mut Streamer,
    camera: &Camera,
    args: &Args,
    light: Option<Light>,
) -> Result<(Selection, Vec<(u32, Arc<ResidentPage>)>), String> {
    let select = SelectOptions {
        tau: 1.0,
        viewport: [args.width, args.height],
        frustum_culling: light.is_none(),
        ..Default::default()
    };
    let (mut selection, _) = streamer.frame_blocking(camera, &select);
    let store = streamer.store().clone();
    let mut pages = Vec::new();
    for c in &selection.clusters {
        if pages.last().map(|(p, _)| *p) != Some(c.page) {
            pages.push((c.page, streamer.cache().get(&store, c.page).map_err(|e| e.to_string())?));
        }
    }
    pages.sort_by_key(|(p, _)| *p);
    pages.dedup_by_key(|(p, _)| *p);
    if let Some(light) = light {
        let all = selection.clusters.len();
        let volume = CasterVolume::new(camera, args.width as f32 / args.height.max(1) as f32, &light);
        let dropped = volume.keep_casters(&mut selection, &pages, store.header().grid_step);
        eprintln!(
            "light's cut: {all} clusters over the store, {dropped} outside the light's sweep of the view"
        );
    }
    Ok((selection, pages))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn parse_args() -> Result<Args, String> {
    let mut args = std::env::args().skip(1);
    let mut parsed = Args {
        store: PathBuf::new(),
        view: View::Camera(String::new()),
        light: "sun".into(),
        width: 640,
        height: 480,
        threads: 2,
        runs: 7,
        memory_mib: 1536,
    };
    let value = |name: &str, args: &mut dyn Iterator<Item = String>| {
        args.next().ok_or_else(|| format!("{name} needs a value"))
    };
    let number = |name: &str, s: String| s.parse::<u64>().map_err(|_| format!("{name}: not a number: {s}"));
    while let Some(a) = args.next() {
        match a.as_str() {
            "--camera" => parsed.view = View::Camera(value("--camera", &mut args)?),
            "--walk" => {
                parsed.view =
                    View::Path(PathPart::Walk, number("--walk", value("--walk", &mut args)?)? as usize)
            }
            "--fly" => {
                parsed.view = View::Path(PathPart::Fly, number("--fly", value("--fly", &mut args)?)? as usize)
            }
            "--light" => parsed.light = value("--light", &mut args)?,
            "--size" => {
                let s = value("--size", &mut args)?;
                let (w, h) = s.split_once('x').ok_or_else(|| format!("--size: expected WxH, got {s}"))?;
                parsed.width = number("--size", w.to_string())? as u32;
                parsed.height = number("--size", h.to_string())? as u32;
            }
            "--threads" => {
                parsed.threads = number("--threads", value("--threads", &mut args)?)?.max(1) as usize
            }
            "--runs" => parsed.runs = number("--runs", value("--runs", &mut args)?)?.max(1) as usize,
            "--memory" => parsed.memory_mib = number("--memory", value("--memory", &mut args)?)?,
            _ if parsed.store.as_os_str().is_empty() && !a.starts_with("--") => parsed.store = a.into(),
            _ => return Err(format!("unexpected argument {a}")),
        }
    }
    if parsed.store.as_os_str().is_empty() || matches!(&parsed.view, View::Camera(c) if c.is_empty()) {
        return Err("usage: shadow_bench STORE.tw (--camera \"EYE;TARGET;UP;FOVY\" | --walk K | --fly K) [--light L] [--size WxH] [--threads N] [--runs N] [--memory MIB]".into());
    }
    Ok(parsed)
}
