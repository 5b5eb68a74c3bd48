//! Drawing with pages missing, from a cold start, the DAG's way and Wald's (docs/RUNTIME.md
//! "Ray tracing"), side by side in one process:
//!
//! - **dag** (the default of `--renderer rt`): the frame's cut by the availability rule — a
//!   missing page's groups drawn by their resident coarser ancestors of the cluster DAG — with
//!   pages loaded in the streamer's priority order (`Streamer::frame`'s requests);
//! - **dag + proxies**: the same frame, its empty pixels shaded from the proxies of the warm
//!   cut's missing groups ([`tw_rt::scene::proxies::ProxyPixels::Holes`]): proxies only in the
//!   DAG's holes;
//! - **proxies, same pages**: the paper's frame (next item) over the dag run's resident pages;
//! - **proxies** (Wald, Dietrich & Slusallek 2004, §5): the warm frame's cut, its resident groups
//!   at their level, every missing group's box killing the rays that reach it and shading them
//!   from the group's 18-direction proxy ([`tw_rt::scene::proxies`]); only the warm cut's pages
//!   loaded, in the paper's priority (the group's size over its distance to the eye, the page
//!   taking its largest group's).
//!
//! Both runs start from the root pages alone and load `--step` pages between frames on this
//! thread (reproducible; no loader threads, no prefetch); each frame is compared with the warm
//! frame (the cut with every page loaded): the share of the warm frame's covered pixels that it
//! covers (the bench's `cold start:` criterion), PSNR over the composited RGB, and an edge SSIM
//! (`ssim`: SSIM over the windows where the warm frame has structure), the one of the three
//! that a flat frame does not pass. The proxies are generated first, for every group of the
//! store's non-root pages (or only the warm cuts' groups with `--cut-proxies`), and their time
//! and size reported.
//!
//! ```text
//! cargo run --release -p tw-rt --example proxy_compare -- (STORE.tw | --plant TRIANGLES) [options]
//!   --plant N       a generated plant of N triangles (seed 1), built into a temporary store
//!   --camera C      a camera "EYE;TARGET;UP;FOVY" (repeatable)
//!   --path P.json   the first cameras of a camera path (repeatable)
//!   --cameras N     each path's first N cameras (default 1)
//!   (with neither: the first camera of each part of the path `terawalk path` generates)
//!   --size WxH      image size (default 640x480)
//!   --step N        pages loaded per step (default 4)
//!   --rays N        rays per proxy (default 10000, the paper's; at most 2^20)
//!   --psnr DB       the PSNR a "recognisable" frame reaches (default 20)
//!   --ssim S        the edge SSIM (see `ssim`) a "recognisable" frame reaches (default 0.5)
//!   --memory MIB    page cache budget (default 1536)
//!   --cut-proxies   proxies only for the groups of the cameras' warm cuts
//!   --threads N     rayon threads (default 2)
//!   --frames DIR    write each camera's warm frame and the first frames of the runs as PPM
//! ```

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tw_core::color::{ColorMode, BACKGROUND};
use tw_rt::proxy::{DEFAULT_RAYS, MAX_RAYS};
use tw_rt::scene::proxies::{missing_groups, GroupProxies, ProxyPixels};
use tw_rt::scene::{StoreTracer, TraceSettings, TracedFrame};
use tw_runtime::{
    Camera, CameraPath, ClusterRef, InputCamera, PageCache, PrefetchOptions, SelectOptions, SelectionPages,
    StreamOptions, Streamer,
};
use tw_store::Store;

struct Args {
    store: PathBuf,
    plant: Option<u64>,
    cameras: Vec<InputCamera>,
    paths: Vec<PathBuf>,
    path_cameras: usize,
    width: u32,
    height: u32,
    step: usize,
    rays: u32,
    psnr: f64,
    ssim: f64,
    memory_mib: u64,
    cut_proxies: bool,
    threads: usize,
    frames: Option<PathBuf>,
}

/// The most steps of one run (each loads `--step` pages): beyond, the run stops unconverged.
const MAX_STEPS: usize = 10_000;

fn main() {
    if let Err(e) = run() {
        eprintln!("proxy_compare: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args = parse_args()?;
    rayon::ThreadPoolBuilder::new().num_threads(args.threads).build_global().map_err(|e| e.to_string())?;
    let (store, _built) = open_store(&args)?;
    let cameras = cameras(&args, &store)?;
    let select = SelectOptions {
        tau: 1.0,
        viewport: [args.width, args.height],
        frustum_culling: true,
        ..Default::default()
    };

    // The warm frames: every page of each cut loaded.
    let warm: Vec<Warm> =
        cameras.iter().map(|c| Warm::new(&store, c, &select, &args)).collect::<Result<_, _>>()?;
    let non_root = store.pages().iter().filter(|p| !p.is_root()).count();
    let input_triangles: u64 = store.header().input_triangles;
    let name = args.plant.map_or(args.store.display().to_string(), |n| format!("plant {n}"));
    println!(
        "store {}: {} groups, {} pages ({} not root), {input_triangles} input triangles; {} cameras at {}x{}, {} threads",
        name,
        store.groups().len(),
        store.pages().len(),
        non_root,
        cameras.len(),
        args.width,
        args.height,
        args.threads,
    );

    // The proxies.
    let wanted: HashSet<u32> = warm.iter().flat_map(|w| w.cut.iter().map(|c| c.group)).collect();
    let t = Instant::now();
    let proxies = GroupProxies::build(&store, args.rays, |g| !args.cut_proxies || wanted.contains(&g))
        .map_err(|e| format!("{}: {e}", args.store.display()))?;
    let build = t.elapsed();
    let triangles: u64 = if args.cut_proxies {
        wanted.iter().map(|&g| store.groups()[g as usize].triangles as u64).sum()
    } else {
        store
            .groups()
            .iter()
            .filter(|g| store.pages().get(g.page as usize).is_some_and(|p| !p.is_root()))
            .map(|g| g.triangles as u64)
            .sum()
    };
    println!(
        "proxies: {} ({}) from {} rays each in {:.2} s ({:.1} µs a proxy, {:.0} ns a stored triangle); {:.2} MB resident \
         ({} B a proxy with its box, {:.3} B per input triangle, {:.3} per stored triangle of the groups)",
        proxies.len(),
        if args.cut_proxies { "the warm cuts' groups" } else { "every group of the non-root pages" },
        args.rays,
        build.as_secs_f64(),
        build.as_secs_f64() * 1e6 / proxies.len().max(1) as f64,
        build.as_secs_f64() * 1e9 / triangles.max(1) as f64,
        proxies.bytes() as f64 / 1e6,
        proxies.bytes() / proxies.len().max(1),
        proxies.bytes() as f64 / input_triangles.max(1) as f64,
        proxies.bytes() as f64 / triangles.max(1) as f64,
    );

    for (k, warm) in warm.iter().enumerate() {
        let camera = &cameras[k];
        println!(
            "\ncamera {k}: warm cut {} clusters in {} pages ({:.1} MB read), warm frame covers {} pixels",
            warm.cut.len(),
            warm.pages.len(),
            warm.page_bytes as f64 / 1e6,
            warm.covered
        );
        write_frame(&args, k, "warm", &warm.frame)?;
        let dag = run_dag(&store, k, camera, &select, warm, &proxies, &args)?;
        let proxy = run_proxy(&store, k, camera, warm, &proxies, &args)?;
        print_steps(&dag, &proxy, (args.width * args.height) as usize);
        let same: Vec<Step> = dag.iter().filter_map(|s| s.same_pages.as_deref().cloned()).collect();
        let hybrid: Vec<Step> = dag.iter().filter_map(|s| s.hybrid.as_deref().cloned()).collect();
        let runs = [
            ("dag", &dag),
            ("dag + proxies in its holes", &hybrid),
            ("proxies over the dag's pages", &same),
            ("proxies", &proxy),
        ];
        for (name, steps) in runs {
            println!("  {name}: {}", summary(steps, args.psnr, args.ssim));
        }
    }
    Ok(())
}

/// A camera's warm frame.
struct Warm {
    cut: Vec<ClusterRef>,
    /// The cut's pages that are not root pages, each with its priority for the proxy run.
    pages: Vec<(u32, f32)>,
    page_bytes: u64,
    frame: TracedFrame,
    covered: usize,
}

impl Warm {
    fn new(store: &Arc<Store>, camera: &Camera, select: &SelectOptions, args: &Args) -> Result<Warm, String> {
        let mut streamer = Streamer::new(store.clone(), stream_options(args)).map_err(|e| e.to_string())?;
        let (selection, _) = streamer.frame_blocking(camera, select);
        let cut = selection.clusters;
        let held = SelectionPages::resolve(store, streamer.cache(), &cut);
        let mut tracer = StoreTracer::new(store, u64::MAX);
        let frame = tracer.trace(&held, camera, (args.width, args.height), &settings());
        let covered = covered(&frame);
        let mut priority: HashMap<u32, f32> = HashMap::new();
        for c in &cut {
            if store.pages()[c.page as usize].is_root() {
                continue;
            }
            let p = priority.entry(c.page).or_insert(0.0);
            *p = p.max(group_priority(store, camera, c.group));
        }
        let mut pages: Vec<(u32, f32)> = priority.into_iter().collect();
        pages.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        let page_bytes = pages.iter().map(|&(p, _)| store.pages()[p as usize].compressed_len as u64).sum();
        Ok(Warm { cut, pages, page_bytes, frame, covered })
    }
}

/// Wald's fetch priority: the size of what a ray was entering over its distance to the camera
/// (here the group's bounding sphere).
fn group_priority(store: &Store, camera: &Camera, group: u32) -> f32 {
    let [x, y, z, r] = store.groups()[group as usize].sphere;
    let d = (glam::Vec3::new(x, y, z) - camera.eye).length();
    r / d.max(1e-6)
}

fn settings() -> TraceSettings {
    TraceSettings { coloring: ColorMode::Material, ..Default::default() }
}

fn stream_options(args: &Args) -> StreamOptions {
    StreamOptions {
        budget_bytes: args.memory_mib << 20,
        loader_threads: 0,
        prefetch: PrefetchOptions { enabled: false, ..Default::default() },
        fit_budget: false,
    }
}

/// One frame of a cold start.
#[derive(Clone, Debug)]
struct Step {
    /// Non-root pages resident, and their bytes in the store.
    pages: usize,
    bytes: u64,
    /// Time spent loading (reading and decoding on this thread) since the cold start.
    load: Duration,
    /// This frame's time (selection and tracing; with proxies also the proxy pass).
    frame: Duration,
    covered: f64,
    psnr: f64,
    ssim: f64,
    /// Pixels shaded from proxies.
    proxied: usize,
    /// The DAG run's steps: the paper's frame over the same resident pages.
    same_pages: Option<Box<Step>>,
    /// The DAG run's steps: its frame with proxies where its cut leaves holes.
    hybrid: Option<Box<Step>>,
}

impl Step {
    /// The step of `image` against the warm frame, with `pages` (count, bytes) resident after
    /// `load`, drawn in `frame` with `proxied` pixels from proxies; no nested runs.
    fn of(
        image: &TracedFrame,
        warm: &Warm,
        (pages, bytes): (usize, u64),
        load: Duration,
        frame: Duration,
        proxied: usize,
    ) -> Step {
        Step {
            pages,
            bytes,
            load,
            frame,
            covered: covered(image) as f64 / warm.covered.max(1) as f64,
            psnr: psnr(image, &warm.frame),
            ssim: ssim(image, &warm.frame),
            proxied,
            same_pages: None,
            hybrid: None,
        }
    }
}

/// The default: the availability rule's cut over what the streamer loaded so far.
fn run_dag(
    store: &Arc<Store>,
    camera_index: usize,
    camera: &Camera,
    select: &SelectOptions,
    warm: &Warm,
    proxies: &GroupProxies,
    args: &Args,
) -> Result<Vec<Step>, String> {
    let mut streamer = Streamer::new(store.clone(), stream_options(args)).map_err(|e| e.to_string())?;
    let mut tracer = StoreTracer::new(store, u64::MAX);
    let mut same = ProxyFrames::new(store, camera, warm, proxies, args, (camera_index, "same-first"));
    let (mut steps, mut load) = (Vec::new(), Duration::ZERO);
    for _ in 0..MAX_STEPS {
        let t = Instant::now();
        let frame = streamer.frame(camera, select);
        let held = SelectionPages::from_resident(&frame.pages, &frame.selection.clusters);
        let traced = tracer.trace(&held, camera, (args.width, args.height), &settings());
        let frame_time = t.elapsed();
        // The hybrid: this frame, with proxies in the holes its cut leaves.
        let t = Instant::now();
        let mut hybrid = traced.clone();
        let missing = missing_groups(&warm.cut, streamer.cache());
        let proxied = tracer.shade_missing(&mut hybrid, proxies, missing, camera, ProxyPixels::Holes);
        let hybrid_time = frame_time + t.elapsed();
        if steps.is_empty() {
            write_frame(args, camera_index, "dag-first", &traced)?;
            write_frame(args, camera_index, "hybrid-first", &hybrid)?;
        }
        let (pages, bytes) = resident(store, streamer.cache());
        steps.push(Step {
            same_pages: Some(Box::new(same.step(streamer.cache(), load)?)),
            hybrid: Some(Box::new(Step::of(&hybrid, warm, (pages, bytes), load, hybrid_time, proxied))),
            ..Step::of(&traced, warm, (pages, bytes), load, frame_time, 0)
        });
        let t = Instant::now();
        if streamer.load_queued(args.step) == 0 {
            break;
        }
        load += t.elapsed();
    }
    Ok(steps)
}

/// Frames drawn the paper's way ([`StoreTracer::trace_with_proxies`]).
struct ProxyFrames<'a> {
    store: &'a Arc<Store>,
    camera: &'a Camera,
    warm: &'a Warm,
    proxies: &'a GroupProxies,
    tracer: StoreTracer,
    size: (u32, u32),
    /// Where the first frame goes (`--frames`), until it is written.
    first: Option<(&'a Args, usize, &'static str)>,
}

impl<'a> ProxyFrames<'a> {
    fn new(
        store: &'a Arc<Store>,
        camera: &'a Camera,
        warm: &'a Warm,
        proxies: &'a GroupProxies,
        args: &'a Args,
        (index, name): (usize, &'static str),
    ) -> Self {
        let tracer = StoreTracer::new(store, u64::MAX);
        let first = Some((args, index, name));
        ProxyFrames { store, camera, warm, proxies, tracer, size: (args.width, args.height), first }
    }

    fn step(&mut self, cache: &PageCache, load: Duration) -> Result<Step, String> {
        let t = Instant::now();
        let (traced, proxied) = self.tracer.trace_with_proxies(
            cache,
            &self.warm.cut,
            self.proxies,
            self.camera,
            self.size,
            &settings(),
        );
        let frame = t.elapsed();
        if let Some((args, camera_index, name)) = self.first.take() {
            write_frame(args, camera_index, name, &traced)?;
        }
        let (pages, bytes) = resident(self.store, cache);
        Ok(Step::of(&traced, self.warm, (pages, bytes), load, frame, proxied))
    }
}

/// The paper's way with its own loading order: the warm cut's missing pages by Wald's priority.
fn run_proxy(
    store: &Arc<Store>,
    camera_index: usize,
    camera: &Camera,
    warm: &Warm,
    proxies: &GroupProxies,
    args: &Args,
) -> Result<Vec<Step>, String> {
    let cache = PageCache::new(store, args.memory_mib << 20);
    cache.load_root_pages(store);
    let mut frames = ProxyFrames::new(store, camera, warm, proxies, args, (camera_index, "proxy-first"));
    let (mut steps, mut load, mut next) = (Vec::new(), Duration::ZERO, 0);
    loop {
        steps.push(frames.step(&cache, load)?);
        if next >= warm.pages.len() || steps.len() >= MAX_STEPS {
            break;
        }
        let t = Instant::now();
        for &(page, _) in &warm.pages[next..(next + args.step).min(warm.pages.len())] {
            cache.get(store, page).map_err(|e| format!("page {page}: {e}"))?;
        }
        next += args.step;
        load += t.elapsed();
    }
    Ok(steps)
}

/// Writes `frame` as `DIR/cCAMERA-NAME.ppm` (composited over the background) under `--frames`.
fn write_frame(args: &Args, camera: usize, name: &str, frame: &TracedFrame) -> Result<(), String> {
    let Some(dir) = &args.frames else { return Ok(()) };
    let path = dir.join(format!("c{camera}-{name}.ppm"));
    let mut bytes = format!("P6\n{} {}\n255\n", frame.width, frame.height).into_bytes();
    for p in frame.rgba.chunks_exact(4) {
        let a = p[3] as u32;
        bytes.extend((0..3).map(|c| ((p[c] as u32 * a + BACKGROUND[c] as u32 * (255 - a)) / 255) as u8));
    }
    std::fs::create_dir_all(dir)
        .and_then(|_| std::fs::write(&path, bytes))
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// Non-root pages resident in `cache` and their bytes in the store.
fn resident(store: &Store, cache: &PageCache) -> (usize, u64) {
    let mut n = (0, 0);
    for (i, p) in store.pages().iter().enumerate() {
        if !p.is_root() && cache.contains(i as u32) {
            n.0 += 1;
            n.1 += p.compressed_len as u64;
        }
    }
    n
}

fn covered(frame: &TracedFrame) -> usize {
    frame.rgba.chunks_exact(4).filter(|p| p[3] != 0).count()
}

/// PSNR (dB) of the RGB of two frames composited over the background (as `tw_gpu::Image::psnr`).
fn psnr(a: &TracedFrame, b: &TracedFrame) -> f64 {
    let rgb = |p: &[u8]| -> [f64; 3] {
        let alpha = p[3] as f64 / 255.0;
        [0, 1, 2].map(|c| p[c] as f64 * alpha + BACKGROUND[c] as f64 * (1.0 - alpha))
    };
    let mut sum = 0.0;
    for (p, q) in a.rgba.chunks_exact(4).zip(b.rgba.chunks_exact(4)) {
        let (p, q) = (rgb(p), rgb(q));
        sum += (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>();
    }
    let mse = sum / (a.rgba.len() / 4 * 3).max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0 * 255.0 / mse).log10()
    }
}

/// Mean SSIM (Wang, Bovik, Sheikh & Simoncelli 2004) of the luma of frame `a` against the warm
/// frame `b`, both composited over the background, over 8x8 windows every 4 pixels with the
/// paper's constants — counting only the windows where `b` shows structure (luma standard
/// deviation ≥ [`EDGE_SIGMA`]): the edges and silhouettes by which a view is recognised. Plain
/// PSNR and plain SSIM both reward flat frames on these mostly flat grey models: a proxy box
/// around the eye fills the view with one grey close to the mean, and most windows of the warm
/// frame are flat too.
const EDGE_SIGMA: f64 = 8.0;

fn ssim(a: &TracedFrame, b: &TracedFrame) -> f64 {
    let luma = |f: &TracedFrame| -> Vec<f64> {
        f.rgba
            .chunks_exact(4)
            .map(|p| {
                let alpha = p[3] as f64 / 255.0;
                let c = |k: usize| p[k] as f64 * alpha + BACKGROUND[k] as f64 * (1.0 - alpha);
                0.299 * c(0) + 0.587 * c(1) + 0.114 * c(2)
            })
            .collect()
    };
    let (x, y) = (luma(a), luma(b));
    let (w, h) = (a.width as usize, a.height as usize);
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let (mut sum, mut n) = (0.0, 0usize);
    for y0 in (0..h.saturating_sub(7)).step_by(4) {
        for x0 in (0..w.saturating_sub(7)).step_by(4) {
            let (mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for j in y0..y0 + 8 {
                for i in x0..x0 + 8 {
                    let (p, q) = (x[j * w + i], y[j * w + i]);
                    (sx, sy, sxx, syy, sxy) = (sx + p, sy + q, sxx + p * p, syy + q * q, sxy + p * q);
                }
            }
            let (mx, my) = (sx / 64.0, sy / 64.0);
            let (vx, vy, cov) = (sxx / 64.0 - mx * mx, syy / 64.0 - my * my, sxy / 64.0 - mx * my);
            if vy < EDGE_SIGMA * EDGE_SIGMA {
                continue;
            }
            sum += ((2.0 * mx * my + c1) * (2.0 * cov + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

/// One line per step: the DAG run, the hybrid and the proxies over the DAG run's pages, the
/// proxy run.
fn print_steps(dag: &[Step], proxy: &[Step], pixels: usize) {
    println!(
        "  {:>4} | {:^48} | {:^19} | {:^19} | {:^56}",
        "", "dag (streamer's order)", "dag + proxies", "proxies, same", "proxies (Wald's order)"
    );
    let run = format!("{:>6} {:>6} {:>7} {:>6} {:>5}", "pages", "MB", "load ms", "cover%", "PSNR");
    let short = format!("{:>6} {:>5} {:>5}", "cover%", "PSNR", "SSIM");
    println!(
        "  {:>4} | {run} {:>5} | {short} | {short} | {run} {:>5} {:>6}",
        "step", "SSIM", "SSIM", "proxy%"
    );
    let n = dag.len().max(proxy.len());
    // Every step while either changes fast, then every 8th, and the last.
    for i in (0..n).filter(|&i| i < 24 || i % 8 == 0 || i + 1 == n) {
        let cell = |s: Option<&Step>| match s {
            Some(s) => format!(
                "{:>6} {:>6.2} {:>7.0} {:>6.1} {:>5.1} {:>5.2}",
                s.pages,
                s.bytes as f64 / 1e6,
                s.load.as_secs_f64() * 1e3,
                100.0 * s.covered,
                s.psnr.min(99.0),
                s.ssim
            ),
            None => format!("{:>48}", ""),
        };
        let short = |s: Option<&Step>| match s {
            Some(s) => format!("{:>6.1} {:>5.1} {:>5.2}", 100.0 * s.covered, s.psnr.min(99.0), s.ssim),
            None => format!("{:>18}", ""),
        };
        let d = dag.get(i);
        let (hybrid, same) = (d.and_then(|s| s.hybrid.as_deref()), d.and_then(|s| s.same_pages.as_deref()));
        let p = proxy.get(i);
        let share =
            p.map_or(String::new(), |s| format!("{:>6.1}", 100.0 * s.proxied as f64 / pixels.max(1) as f64));
        println!("  {i:>4} | {} | {} | {} | {} {share}", cell(d), short(hybrid), short(same), cell(p));
    }
}

/// When a run first covered ≥ 95 % of the warm frame and first reached `psnr_goal`.
fn summary(steps: &[Step], psnr_goal: f64, ssim_goal: f64) -> String {
    let at = |i: usize| {
        let s = &steps[i];
        format!(
            "step {i} ({} pages, {:.2} MB, {:.0} ms loading)",
            s.pages,
            s.bytes as f64 / 1e6,
            s.load.as_secs_f64() * 1e3
        )
    };
    let first = steps.first().map_or(String::new(), |s| {
        format!(
            "first frame {:.1} % covered, {:.1} dB, edge SSIM {:.2}",
            100.0 * s.covered,
            s.psnr.min(99.0),
            s.ssim
        )
    });
    let cover = steps.iter().position(|s| s.covered >= 0.95).map_or("never".into(), at);
    let good = steps.iter().position(|s| s.psnr >= psnr_goal).map_or("never".into(), at);
    let structure = steps.iter().position(|s| s.ssim >= ssim_goal).map_or("never".into(), at);
    let mut frames: Vec<f64> = steps.iter().map(|s| s.frame.as_secs_f64() * 1e3).collect();
    frames.sort_by(f64::total_cmp);
    let last = steps.last().map_or(String::new(), |s| {
        format!(
            "complete after {} pages, {:.2} MB, {:.0} ms loading, {:.1} dB",
            s.pages,
            s.bytes as f64 / 1e6,
            s.load.as_secs_f64() * 1e3,
            s.psnr.min(99.0)
        )
    });
    format!(
        "{first}; ≥ 95 % covered at {cover}; ≥ {psnr_goal} dB at {good}; edge SSIM ≥ {ssim_goal} at {structure}; {last}; frame median {:.1} ms",
        frames.get(frames.len() / 2).copied().unwrap_or(0.0)
    )
}

/// The store of `--plant` (built now, kept while the returned guard lives) or the named one.
fn open_store(args: &Args) -> Result<(Arc<Store>, Option<tw_testkit::Built>), String> {
    let Some(triangles) = args.plant else {
        let store = Store::open(&args.store).map_err(|e| e.to_string())?;
        return Ok((Arc::new(store), None));
    };
    let source = tw_testkit::Generated::Plant(tw_io::generate::PlantParams { triangles, seed: 1 }).source();
    let built = tw_testkit::build(source, &Default::default());
    Ok((built.store(), Some(built)))
}

fn cameras(args: &Args, store: &Store) -> Result<Vec<Camera>, String> {
    let mut inputs = args.cameras.clone();
    for path in &args.paths {
        let p = CameraPath::load(path).map_err(|e| format!("{}: {e}", path.display()))?;
        inputs.extend(p.frames.iter().take(args.path_cameras).map(|f| f.input_camera()));
    }
    if inputs.is_empty() {
        // The first camera of each part (walk, fly-over) of the generated path.
        let options = tw_runtime::PathOptions { frames: 300, ..Default::default() };
        let generated =
            tw_runtime::generate_path(store, &options, &mut |_, _, _| {}).map_err(|e| e.to_string())?;
        let frames = &generated.path.frames;
        for (i, f) in frames.iter().enumerate() {
            if i == 0 || frames[i - 1].segment != f.segment {
                inputs.push(f.input_camera());
            }
        }
    }
    inputs.iter().map(|c| c.to_scene(store.header()).map_err(|e| e.to_string())).collect()
}

fn parse_args() -> Result<Args, String> {
    let mut args = std::env::args().skip(1);
    let mut parsed = Args {
        store: PathBuf::new(),
        plant: None,
        cameras: Vec::new(),
        paths: Vec::new(),
        path_cameras: 1,
        width: 640,
        height: 480,
        step: 4,
        rays: DEFAULT_RAYS,
        psnr: 20.0,
        ssim: 0.5,
        memory_mib: 1536,
        cut_proxies: false,
        threads: 2,
        frames: None,
    };
    let value = |name: &str, args: &mut dyn Iterator<Item = String>| {
        args.next().ok_or_else(|| format!("{name} needs a value"))
    };
    let number = |name: &str, s: String, max: u64| match s.parse::<u64>() {
        Ok(n) if (1..=max).contains(&n) => Ok(n),
        _ => Err(format!("{name}: not a number in 1..={max}: {s}")),
    };
    while let Some(a) = args.next() {
        match a.as_str() {
            "--camera" => {
                let s = value("--camera", &mut args)?;
                parsed.cameras.push(InputCamera::parse(&s).map_err(|e| format!("--camera: {e}"))?);
            }
            "--path" => parsed.paths.push(PathBuf::from(value("--path", &mut args)?)),
            "--cameras" => {
                parsed.path_cameras = number("--cameras", value("--cameras", &mut args)?, 1000)? as usize
            }
            "--size" => {
                let s = value("--size", &mut args)?;
                let (w, h) = s.split_once('x').ok_or_else(|| format!("--size: expected WxH, got {s}"))?;
                parsed.width = number("--size", w.to_string(), 8192)? as u32;
                parsed.height = number("--size", h.to_string(), 8192)? as u32;
            }
            "--step" => parsed.step = number("--step", value("--step", &mut args)?, 1 << 20)? as usize,
            "--rays" => parsed.rays = number("--rays", value("--rays", &mut args)?, MAX_RAYS as u64)? as u32,
            "--psnr" => {
                let s = value("--psnr", &mut args)?;
                parsed.psnr = s
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite())
                    .ok_or(format!("--psnr: not a number: {s}"))?;
            }
            "--ssim" => {
                let s = value("--ssim", &mut args)?;
                parsed.ssim = s
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite())
                    .ok_or(format!("--ssim: not a number: {s}"))?;
            }
            "--memory" => parsed.memory_mib = number("--memory", value("--memory", &mut args)?, 1 << 20)?,
            "--cut-proxies" => parsed.cut_proxies = true,
            "--frames" => parsed.frames = Some(PathBuf::from(value("--frames", &mut args)?)),
            "--plant" => parsed.plant = Some(number("--plant", value("--plant", &mut args)?, 1 << 30)?),
            "--threads" => {
                parsed.threads = number("--threads", value("--threads", &mut args)?, 256)? as usize
            }
            s if s.starts_with("--") => return Err(format!("unknown option {s}")),
            s => parsed.store = PathBuf::from(s),
        }
    }
    if parsed.store.as_os_str().is_empty() == parsed.plant.is_none() {
        return Err("give a store or --plant".into());
    }
    Ok(parsed)
}
