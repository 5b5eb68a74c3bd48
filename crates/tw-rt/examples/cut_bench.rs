//! Primary rays through a store's LOD cut (the two-level [`CutScene`]): single rays against
//! packets, in one process, so that both see the same cut, the same cluster BVHs and the same
//! load on a shared machine.
//!
//! ```text
//! cargo run --release -p tw-rt --example cut_bench -- STORE.tw --camera "EYE;TARGET;UP;FOVY" [options]
//!   --size WxH     image size (default 640x480)
//!   --threads N    rayon threads while tracing (default 2)
//!   --runs N       timed runs per mode, alternating; medians are reported (default 9)
//!   --memory MIB   page cache budget in MiB (default 1536: the pages' share of --memory 2G)
//! ```
//!
//! The cut is selected at τ = 1 px with every page loaded (as `terawalk render` does), the
//! clip planes are the camera's, and the rays are those of `StoreTracer::trace`.
//!
//! The figures in the crate documentation are of the 10^8-triangle plant with these cameras:
//!
//! ```text
//! interior  362.79113355739986,358.07593451070153,6.299999999999997;363.1716111917628,348.0879761003544,5.990284706665417;0,0,1;60
//! fly-over  649.2882423319556,-270.67446948868417,347.826559455982;643.9996648471744,-263.01063948907233,344.1801011846571;0,0,1;60
//! ```

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use tw_rt::scene::blas::BlasCache;
use tw_rt::scene::cut::{Clip, CutScene};
use tw_rt::{trace_image_with, TraceMode};
use tw_runtime::{Camera, InputCamera, SelectOptions, SelectionPages, StreamOptions, Streamer};
use tw_store::Store;

struct Args {
    store: PathBuf,
    camera: String,
    width: u32,
    height: u32,
    threads: usize,
    runs: usize,
    memory_mib: u64,
}

fn main() {
    if let Err(e) = run() {
        eprintln!("cut_bench: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args = parse_args()?;
    let store = Arc::new(Store::open(&args.store).map_err(|e| format!("{}: {e}", args.store.display()))?);
    let input = InputCamera::parse(&args.camera).map_err(|e| e.to_string())?;
    let camera = input.to_scene(store.header()).map_err(|e| e.to_string())?;
    let (scene, triangles) = cut_scene(&store, &camera, &args)?;
    let rt_camera = tw_rt::Camera::for_view(&camera, args.width as f32 / args.height as f32);
    let pool =
        rayon::ThreadPoolBuilder::new().num_threads(args.threads).build().map_err(|e| e.to_string())?;
    let trace = |mode| pool.install(|| trace_image_with(&scene, &rt_camera, args.width, args.height, mode));
    let (single_ids, single_depth) = trace(TraceMode::Single);
    let (packet_ids, packet_depth) = trace(TraceMode::Packet);
    let differ = single_depth.iter().zip(&packet_depth).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
    let other_prim = single_ids.iter().zip(&packet_ids).filter(|(a, b)| a != b).count();
    eprintln!(
        "cut: {} clusters, {triangles} triangles; {differ} pixels differ in depth, {other_prim} in the triangle hit",
        scene.clusters().len()
    );

    // Alternate the modes so that both see the same load; medians of wall and on-CPU time.
    let mut times = [(Vec::new(), Vec::new()), (Vec::new(), Vec::new())];
    for _ in 0..args.runs {
        for (k, mode) in [TraceMode::Single, TraceMode::Packet].into_iter().enumerate() {
            let (t, c) = (Instant::now(), cpu_seconds());
            trace(mode);
            times[k].0.push(t.elapsed().as_secs_f64());
            times[k].1.push(cpu_seconds() - c);
        }
    }
    let rays = (args.width * args.height) as f64;
    println!("{:<8} {:>9} {:>10} {:>16}", "", "ms", "M rays/s", "M rays/s (cpu)");
    for (name, (wall, cpu)) in ["single", "packet"].iter().zip(times) {
        let (wall, cpu) = (median(wall), median(cpu) / args.threads as f64);
        println!("{name:<8} {:>9.1} {:>10.2} {:>16.2}", wall * 1e3, rays / wall / 1e6, rays / cpu / 1e6);
    }
    Ok(())
}

/// The cut of `camera` at τ = 1 with all its pages loaded, and its triangle count.
fn cut_scene(store: &Arc<Store>, camera: &Camera, args: &Args) -> Result<(CutScene, u64), String> {
    let options =
        StreamOptions { budget_bytes: args.memory_mib << 20, loader_threads: 0, ..Default::default() };
    let mut streamer = Streamer::new(store.clone(), options).map_err(|e| e.to_string())?;
    let select = SelectOptions {
        tau: 1.0,
        viewport: [args.width, args.height],
        frustum_culling: true,
        ..Default::default()
    };
    let (selection, _) = streamer.frame_blocking(camera, &select);
    let mut pages = Vec::new();
    for c in &selection.clusters {
        if pages.last().map(|(p, _)| *p) != Some(c.page) {
            pages.push((c.page, streamer.cache().get(store, c.page).map_err(|e| e.to_string())?));
        }
    }
    pages.sort_by_key(|(p, _)| *p);
    pages.dedup_by_key(|(p, _)| *p);
    let held = SelectionPages::from_resident(&pages, &selection.clusters);
    let triangles = held.clusters().iter().map(|(_, c)| c.triangle_count() as u64).sum();
    let (clusters, _) = BlasCache::new(usize::MAX).prepare(&held, store.header().grid_step);
    let clip =
        Clip { forward: camera.direction(), near: camera.near, far: camera.far, section: Default::default() };
    Ok((CutScene::build(clusters, clip), triangles))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Seconds this process's threads have run on a CPU (Linux schedstat; see rt_bench.rs).
fn cpu_seconds() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else { return 0.0 };
    let ns: u64 = tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum();
    ns as f64 * 1e-9
}

fn parse_args() -> Result<Args, String> {
    let mut args = std::env::args().skip(1);
    let mut parsed = Args {
        store: PathBuf::new(),
        camera: String::new(),
        width: 640,
        height: 480,
        threads: 2,
        runs: 9,
        memory_mib: 1536,
    };
    let value = |name: &str, args: &mut dyn Iterator<Item = String>| {
        args.next().ok_or_else(|| format!("{name} needs a value"))
    };
    let number = |name: &str, s: String| s.parse::<u64>().map_err(|_| format!("{name}: not a number: {s}"));
    while let Some(a) = args.next() {
        match a.as_str() {
            "--camera" => parsed.camera = value("--camera", &mut args)?,
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
    if parsed.store.as_os_str().is_empty() || parsed.camera.is_empty() {
        return Err("usage: cut_bench STORE.tw --camera \"EYE;TARGET;UP;FOVY\" [--size WxH] [--threads N] [--runs N] [--memory MIB]".into());
    }
    Ok(parsed)
}
