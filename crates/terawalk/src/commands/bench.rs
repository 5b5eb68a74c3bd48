//! `terawalk bench`: renders a camera path headless through the frame pipeline (tw-frame) and
//! writes a self-contained report (tw-report: index.html with SVG plots, report.json with every
//! figure).
//!
//! Runs, all in one process so that their ratios are measured under the same conditions:
//! - one run per `--occlusion` strategy (default: the default strategy), each over the whole
//!   path after `--warmup` frames at the first camera;
//! - `--reference`: the main run is the reference itself (full detail, no culling);
//! - `--compare K`: every K-th frame is also rendered as the reference (once, before the runs,
//!   so that its full-detail draws do not empty the caches in the middle of one); every run's records of those frames get PSNR and the share of differing pixels, and
//!   a "reference" run holds the reference frame times (same frames), so the speed-up is a
//!   ratio of the same frames;
//! - `--reference-samples N` (with `--compare`): the compared frames' references are also
//!   rendered supersampled, N samples per pixel (tw-frame's `supersample`), and every run's
//!   compared frames get their PSNR against it beside the brute-force frame's (the 1-sample
//!   reference above, at the run's samples) and the difference: what the LOD loses, apart from
//!   the aliasing both share;
//! - `--exact`: on the same frames, the item buffer at full detail gives the exact visible
//!   objects and triangles, and every run's culling efficiency (drawn ÷ exact visible).
//!
//! Every frame also gets its LOD efficiency (tw_report::lod): the cut's triangles against the
//! triangles a screen can use at ε over the pixels the model covers. The coverage is counted on
//! the colour image the frame reads back anyway (alpha ≠ 0 where geometry was drawn), after the
//! frame's clock has stopped: no extra readback, and the count is not in the frame time.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use tw_frame::traced::TracedWalkthrough;
use tw_frame::{ExactVisibility, FrameInfo, FrameSettings, Occlusion, Walkthrough};
use tw_gpu::{Image, Renderer};
use tw_report::{BenchReport, DamagedPage, FrameRecord, ReportImage, Run, RunKind, RunMeta};
use tw_rt::scene::TraceSettings;
use tw_runtime::pathgen::{generate_path, PathOptions};
use tw_runtime::{Camera, CameraPath, StreamOptions};

use crate::cli::{BenchArgs, RendererChoice};
use crate::units::fmt_count;

/// What `run` measured, for callers such as `demo`.
pub struct BenchOutcome {
    pub html: PathBuf,
}

pub fn run(args: BenchArgs) -> Result<BenchOutcome> {
    if !(args.error.is_finite() && args.error >= 0.0) {
        bail!("--error must be a finite number ≥ 0, got {}", args.error);
    }
    if args.compare == Some(0) {
        bail!("--compare K needs K ≥ 1 (every K-th frame)");
    }
    if args.shadows.light.is_some() && (args.reference || args.compare.is_some() || args.exact) {
        // The references are unshadowed full-detail frames: a PSNR against them would measure
        // the shadows, not the culling. The shadows' own check is the ray-traced mask
        // (tw-frame's `shadow_check` example).
        bail!("--light cannot be combined with --reference, --compare or --exact");
    }
    if args.shadows.light.is_some() && args.cull_server.is_some() {
        bail!("--light cannot be combined with --cull-server (the server culls the eye's view only)");
    }
    let inputs: Vec<&std::path::Path> =
        [Some(args.store.as_path()), args.path.as_deref()].into_iter().flatten().collect();
    for file in tw_report::ReportFiles::in_folder(&args.out).all() {
        tw_core::output::check_output(&file, &inputs)?;
    }
    let store = crate::commands::open_store(&args.store)?;
    let store_bytes = std::fs::metadata(&args.store).map(|m| m.len()).unwrap_or(0);
    let input_triangles = store.header().input_triangles;
    let path = match &args.path {
        Some(p) => CameraPath::load(p)?,
        None => {
            let options = PathOptions { frames: args.frames.unwrap_or(300).max(2), ..Default::default() };
            let generated = generate_path(&store, &options, &mut |_, _, _| {})
                .with_context(|| format!("cannot generate a camera path for {}", args.store.display()))?;
            let r = &generated.report;
            outln!(
                "path: generated {} frames ({} walking, {} flying){}",
                generated.path.frames.len(),
                r.walk_frames,
                r.fly_frames,
                r.fallback.as_ref().map(|f| format!("; {f}")).unwrap_or_default()
            );
            generated.path
        }
    };
    let mut frames = path.frames.clone();
    if let Some(n) = args.frames {
        frames.truncate(n);
    }
    if frames.is_empty() {
        bail!("the camera path has no frames");
    }
    let cameras: Vec<Camera> = frames
        .iter()
        .enumerate()
        .map(|(i, f)| f.to_scene(store.header()).with_context(|| format!("path frame {i}")))
        .collect::<Result<_>>()?;

    let mut renderer = Renderer::new_headless(args.size.0, args.size.1)?;
    renderer.set_gpu_budget(args.gpu_memory);
    if renderer.gpu_budget() + (64 << 10) < args.gpu_memory {
        outln!(
            "note: GPU budget {} MiB, the most one buffer can hold on this device (asked for {} MiB)",
            renderer.gpu_budget() >> 20,
            args.gpu_memory >> 20
        );
    }
    let adapter = renderer.adapter_summary();
    outln!("adapter: {adapter}");
    let samples = args.samples.resolve(&renderer);
    renderer.set_samples(samples)?;
    if args.reference_samples > 1 {
        // Before any frame: a supersampled target the device cannot hold fails now, not after
        // the first reference.
        tw_frame::supersample::check_grid(&renderer, args.reference_samples)?;
    }
    let stream = StreamOptions { budget_bytes: args.memory, ..Default::default() };
    let mut walk = Walkthrough::new(Arc::new(store), renderer, stream)?;
    walk.set_color_mode(args.color.mode());

    let (mut traced, cold_start) = match args.renderer {
        RendererChoice::Raster => (None, None),
        RendererChoice::Rt => {
            let (t, cold) = traced_walkthrough(&args, walk.store().clone(), &cameras[0])?;
            (Some(t), Some(cold))
        }
    };
    let strategies: Vec<Occlusion> = if args.reference || traced.is_some() {
        vec![Occlusion::None]
    } else {
        args.occlusion.iter().map(|o| o.resolve(walk.renderer())).collect()
    };
    let header = walk.store().header().clone();
    let shadows = args.shadows.settings(&header, header.up_axis, &cameras[0])?;
    // With --light every strategy runs with shadows, then without: their ratio is the shadows'
    // cost, measured in the same process on the same frames.
    let runs_wanted: Vec<(Occlusion, bool)> = strategies
        .iter()
        .flat_map(|&s| {
            // The ray tracer's run casts shadow rays when there is a light (one run: it has no
            // occlusion strategies to compare).
            let both: &[bool] = match (shadows.is_some(), traced.is_some()) {
                (true, false) => &[true, false],
                (true, true) => &[true],
                (false, _) => &[false],
            };
            both.iter().map(move |&shadowed| (s, shadowed))
        })
        .collect();
    let mut remote = args.cull_server.as_deref().map(|addr| {
        let wait = std::time::Duration::from_millis(args.cull_timeout_ms);
        crate::commands::cull_client::RemoteCulling::start(addr, walk.store(), wait)
    });
    let mut net_lines = Vec::new();
    let every = args.compare.or(if args.exact { Some(10) } else { None });
    let image_frames = image_frames(cameras.len(), args.images);
    let mut images = Vec::new();
    let mut runs = Vec::new();
    let mut reference_frames = Vec::new();
    // The reference (PNG-compressed: 0.1–1 MB a frame instead of 3.7) and the exact visible
    // set depend on the camera only: made once, before the runs, so that their full-detail
    // draws do not empty the page cache and the GPU pool in the middle of a measured run (the
    // frames after a reference would start cold: a coarser cut, a slower frame).
    let mut references: HashMap<usize, Vec<u8>> = HashMap::new();
    let mut exacts: HashMap<usize, (ExactVisibility, ExactVisibility)> = HashMap::new();
    let mut truths: HashMap<usize, Truth> = HashMap::new();
    let mut truth_time = std::time::Duration::ZERO;
    if let (Some(k), false) = (every, args.reference) {
        let compared: Vec<usize> = (0..cameras.len()).step_by(k).collect();
        let bar = crate::progress::count(compared.len() as u64, "reference".to_string());
        for &i in &compared {
            let (reference, rinfo) = walk.reference(&cameras[i])?;
            reference_frames.push(record(i, &frames[i].segment, &rinfo));
            if args.compare.is_some() {
                if args.reference_samples > 1 {
                    let start = std::time::Instant::now();
                    truths.insert(i, Truth::of(&mut walk, &cameras[i], &reference, args.reference_samples)?);
                    truth_time += start.elapsed();
                }
                references.insert(i, reference.png_bytes()?);
            }
            if args.exact {
                let full = walk.exact_visibility(&cameras[i])?;
                exacts.insert(i, (full, walk.exact_visibility_of_cut(&cameras[i], args.error)?));
            }
            bar.inc(1);
        }
        bar.finish_and_clear();
        if !truths.is_empty() {
            outln!(
                "{:>10}: {} supersampled references ({} samples per pixel) in {:.1} s",
                "reference",
                truths.len(),
                args.reference_samples,
                truth_time.as_secs_f64()
            );
        }
    }
    for (ri, &(strategy, shadowed)) in runs_wanted.iter().enumerate() {
        // A strategy given again (`--occlusion none,queries,none`: does memory come back down?)
        // is a run of its own: "none #2" (the report's runs have distinct names).
        let repeat = runs_wanted[..ri].iter().filter(|&&r| r == (strategy, shadowed)).count();
        let base =
            if shadowed { format!("{}+shadows", strategy.name()) } else { strategy.name().to_string() };
        let name = match (args.reference, repeat) {
            _ if traced.is_some() => "rt".to_string(),
            (true, _) => "reference".to_string(),
            (false, 0) => base,
            (false, k) => format!("{base} #{}", k + 1),
        };
        let settings = FrameSettings {
            tau: args.error,
            frustum_culling: true,
            occlusion: strategy,
            wait_for_pages: args.wait,
            visible_pixels: args.visible_pixels,
            triangle_culling: !args.whole_clusters,
            shadows: if shadowed { shadows } else { None },
        };
        walk.reset();
        if let Some(t) = traced.as_mut() {
            t.reset();
        }
        for _ in 0..args.warmup {
            frame(&mut walk, traced.as_mut(), remote.as_mut(), &cameras[0], &settings, args.reference)?;
        }
        if let Some(r) = &mut remote {
            // The warm-up frames' figures are not the run's.
            r.take_totals();
        }
        let mut records = Vec::with_capacity(cameras.len());
        let bar = crate::progress::count(cameras.len() as u64, name.clone());
        for (i, camera) in cameras.iter().enumerate() {
            let previous = (args.popping && i > 0).then(|| walk.selection().clone());
            let (image, info) =
                frame(&mut walk, traced.as_mut(), remote.as_mut(), camera, &settings, args.reference)?;
            if let (0, Some(cold)) = (i, &cold_start) {
                cold.report(image.covered_pixels());
            }
            let mut rec = record(i, &frames[i].segment, &info);
            // The reference draws full detail (τ = 0): no model of what it needs.
            let tau = if args.reference { 0.0 } else { settings.tau as f64 };
            rec.set_coverage(image.covered_pixels() as u64, tau);
            if ri == 0 && image_frames.contains(&i) {
                images.push(ReportImage {
                    caption: format!("{name}, frame {i} ({})", frames[i].segment),
                    png: image.png_bytes()?,
                });
            }
            if !args.reference && every.is_some_and(|k| i % k == 0) {
                if let Some(png) = references.get(&i) {
                    let (reference, image) = (Image::from_png_bytes(png)?, image.to_opaque());
                    rec.psnr_db = Some(image.psnr(&reference)?.min(99.0));
                    rec.differing_pixels = Some(image.differing_share(&reference)?);
                }
                if let Some(truth) = truths.get(&i) {
                    truth.record(&mut rec, &image)?;
                }
                if let Some((exact, of_cut)) = exacts.get(&i) {
                    rec.exact_visible_triangles = Some(exact.triangles);
                    rec.exact_visible_objects = Some(exact.objects);
                    rec.cut_visible_triangles = Some(of_cut.triangles);
                    rec.cut_efficiency = Some(info.triangles as f64 / of_cut.triangles.max(1) as f64);
                    rec.culling_efficiency = Some(info.triangles as f64 / exact.triangles.max(1) as f64);
                    rec.test_efficiency = Some(info.masked_triangles as f64 / exact.triangles.max(1) as f64);
                }
            }
            if args.popping {
                let change = match &previous {
                    Some(previous) => Some(walk.lod_change(camera, previous)?),
                    None => None,
                };
                rec.popping_changed_pixels = Some(change.map_or(0.0, |c| c.changed_pixels));
                rec.popping_psnr_db = change.and_then(|c| c.psnr_db).map(|p| p.min(99.0));
            }
            records.push(rec);
            if tracing::enabled!(tracing::Level::DEBUG) {
                tracing::debug!("{name} frame {i}: {}", memory_now());
            }
            bar.inc(1);
        }
        bar.finish_and_clear();
        let description = if let Some(t) = &traced {
            let light = match (shadowed, &shadows) {
                (true, Some(s)) => format!(", shadow rays of the {}", light_name(&s.light)),
                _ => String::new(),
            };
            format!(
                "ray traced on the CPU (tw-rt, {} threads{}{light}), LOD cut at {} px, frustum culling",
                tw_rt::scene::StoreTracer::threads(),
                if t.trace.flashlight { ", flashlight with hard shadows" } else { "" },
                args.error
            )
        } else if args.reference {
            "full detail, no culling (τ = 0, frustum and occlusion culling off)".to_string()
        } else {
            let cutoff = if strategy == Occlusion::Queries && args.visible_pixels > 0 {
                format!(", visible-pixel cut-off {} samples (approximate)", args.visible_pixels)
            } else if strategy == Occlusion::Hzb && args.whole_clusters {
                ", visible clusters drawn whole (no triangle tests)".to_string()
            } else {
                String::new()
            };
            let shadows = match (shadowed, &shadows) {
                (true, Some(s)) => format!(
                    ", shadows: {} ({} texels, cross-culling {})",
                    light_name(&s.light),
                    s.options.size,
                    if s.cross_culling { "on" } else { "off" }
                ),
                _ => String::new(),
            };
            format!(
                "LOD cut at {} px, frustum culling, occlusion culling: {}{cutoff}{shadows}",
                args.error,
                strategy.name()
            )
        };
        let run = Run::new(name, description, records, tw_report::peak_rss_bytes());
        print_run(&run);
        if let Some(r) = &mut remote {
            for (key, value) in r.take_totals().lines(&run.name) {
                outln!("{:>10}: {key}: {value}", "network");
                net_lines.push((key, value));
            }
        }
        tracing::info!("after {}: {}", run.name, memory_now());
        runs.push(run);
    }
    if !reference_frames.is_empty() {
        // Reference renderings, not walkthrough frames: in the summary (the speed-up against
        // the reference is a ratio of the same frames), out of the per-frame plots, where one
        // full-detail frame of seconds would flatten the walkthroughs' milliseconds.
        let run = Run::new(
            "reference",
            "full detail, no culling, on the compared frames",
            reference_frames,
            tw_report::peak_rss_bytes(),
        )
        .with_kind(RunKind::Reference);
        print_run(&run);
        runs.push(run);
    }

    let store_name = args.store.display().to_string();
    let meta = RunMeta {
        store: store_name,
        command_line: std::env::args().collect::<Vec<_>>().join(" "),
        adapter,
        size: [args.size.0, args.size.1],
        error_px: args.error as f64,
        memory_budget_bytes: args.memory,
        date: tw_report::utc_now(),
        machine: machine(),
        path: args.path.as_ref().map(|p| p.display().to_string()).unwrap_or_else(|| "generated".into()),
        store_bytes,
        input_triangles,
        version: env!("CARGO_PKG_VERSION").into(),
        // Set by build.rs: the short hash of the commit built, or "unknown".
        commit: env!("TERAWALK_COMMIT").into(),
        extra: vec![
            ("frames".into(), cameras.len().to_string()),
            ("warmup".into(), args.warmup.to_string()),
            ("samples per pixel".into(), samples.to_string()),
        ]
        .into_iter()
        .chain((args.reference_samples > 1).then(|| {
            ("reference samples per pixel".to_string(), format!("{} (supersampled)", args.reference_samples))
        }))
        .chain(args.cull_server.iter().map(|a| ("cull server".to_string(), a.clone())))
        .chain(net_lines)
        .collect(),
    };
    let mut report = BenchReport::new(meta, runs);
    let failed = walk.streamer().cache().failed_pages();
    report.damaged_pages =
        failed.iter().map(|(page, error)| DamagedPage { page: *page, error: error.clone() }).collect();
    print_comparison(&report);
    let files = tw_report::write_report(&args.out, &report, &images)?;
    outln!("report: {} (open it in a browser), figures in {}", files.html.display(), files.json.display());
    crate::commands::damage::check(&args.store, &failed, args.allow_damaged)?;
    Ok(BenchOutcome { html: files.html })
}

/// One frame: the reference, or ray traced with `--renderer rt`, or through the cull server
/// with `--cull-server`, or culled here.
fn frame(
    walk: &mut Walkthrough,
    traced: Option<&mut TracedWalkthrough>,
    remote: Option<&mut crate::commands::cull_client::RemoteCulling>,
    camera: &Camera,
    settings: &FrameSettings,
    reference: bool,
) -> Result<(Image, FrameInfo)> {
    if let Some(t) = traced {
        let (image, info, _) = t.frame(camera, settings)?;
        return Ok((image, info));
    }
    Ok(match remote {
        _ if reference => walk.reference(camera)?,
        Some(r) => r.frame(walk, camera, settings)?,
        None => walk.frame(camera, settings)?,
    })
}

/// The first ray-traced frames after a cold start (a page cache holding the root pages only),
/// all of the first camera: when each was complete and how many pixels it covered, to tell when
/// the image became recognisable against the first measured (warm) frame of the same camera.
struct ColdStart {
    frames: Vec<(std::time::Duration, usize)>,
}

/// Frames [`ColdStart`] traces: the streamer loads a walk's first view within a few.
const COLD_FRAMES: usize = 8;

impl ColdStart {
    fn report(&self, warm_covered: usize) {
        let share = |covered: usize| 100.0 * covered as f64 / warm_covered.max(1) as f64;
        let Some(&(first, covered)) = self.frames.first() else { return };
        let mut line = format!(
            "cold start: first ray-traced image after {:.0} ms covering {:.1} % of what the warm frame covers",
            first.as_secs_f64() * 1e3,
            share(covered)
        );
        match self.frames.iter().find(|&&(_, c)| share(c) >= 95.0) {
            Some((t, c)) => {
                line += &format!("; ≥ 95 % ({:.1} %) after {:.0} ms", share(*c), t.as_secs_f64() * 1e3)
            }
            None => line += &format!("; under 95 % for its first {} frames", self.frames.len()),
        }
        outln!("{line}");
    }
}

/// `--renderer rt`: the ray tracer's walkthrough, with its first frames timed from a cold start.
fn traced_walkthrough(
    args: &BenchArgs,
    store: Arc<tw_store::Store>,
    first: &Camera,
) -> Result<(TracedWalkthrough, ColdStart)> {
    let start = std::time::Instant::now();
    let stream = StreamOptions { budget_bytes: args.memory, ..Default::default() };
    let trace =
        TraceSettings { coloring: args.color.mode(), flashlight: args.flashlight, ..Default::default() };
    let mut traced = TracedWalkthrough::new(store, args.size, stream, trace)?;
    let settings = FrameSettings { tau: args.error, wait_for_pages: args.wait, ..Default::default() };
    let mut cold = ColdStart { frames: Vec::with_capacity(COLD_FRAMES) };
    for _ in 0..COLD_FRAMES {
        let (image, ..) = traced.frame(first, &settings)?;
        cold.frames.push((start.elapsed(), image.covered_pixels()));
    }
    outln!("renderer: CPU ray tracer, {} threads", tw_rt::scene::StoreTracer::threads());
    Ok((traced, cold))
}

fn record(i: usize, segment: &str, info: &FrameInfo) -> FrameRecord {
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let st = &info.stream;
    FrameRecord {
        frame: i as u32,
        segment: segment.to_string(),
        frame_ms: ms(info.times.total),
        select_ms: ms(info.times.select),
        cut_ms: ms(info.times.select_cut),
        prefetch_ms: ms(info.times.select_prefetch),
        // The version-1 name of `culling_ms` (occlusion culling), kept equal to it. Frustum
        // culling has no time of its own: it is part of the selection (`select_ms`).
        cull_ms: ms(info.times.cull),
        upload_ms: ms(info.times.upload),
        render_ms: ms(info.times.render),
        triangles: info.triangles,
        masked_triangles: info.masked_triangles,
        cut_triangles: info.cut_triangles,
        clusters: info.clusters,
        nodes_visited: info.select.nodes_visited,
        nodes_culled_frustum: info.select.nodes_culled_frustum,
        nodes_culled_lod: info.select.nodes_culled_lod,
        nodes_culled_occlusion: info.occlusion.culled,
        occlusion_queries: info.occlusion.queries,
        occlusion_node_tests: info.occlusion.node_tests,
        occlusion_nodes_hidden: info.occlusion.nodes_hidden,
        culling_box_tests_ms: ms(info.times.cull_box_tests),
        culling_triangle_tests_ms: ms(info.times.cull_triangle_tests),
        culling_readback_ms: ms(info.times.cull_readback),
        culling_ms: ms(info.times.cull),
        resident_mb: st.resident_bytes as f64 / 1e6,
        gpu_resident_mb: info.gpu.resident_bytes as f64 / 1e6,
        disk_read_mb: st.bytes_read as f64 / 1e6,
        pages_requested: st.pages_requested,
        pages_loaded: st.pages_loaded,
        pages_evicted: st.pages_evicted,
        stalls_avoided: st.stalls_avoided,
        groups_failed: info.select.groups_failed,
        shadow: (info.shadow.layers > 0).then(|| shadow_record(&info.shadow)),
        ..Default::default()
    }
}

/// The shadow stage's figures of a frame (set sizes as the thesis reports them, stage times).
fn shadow_record(s: &tw_frame::ShadowInfo) -> tw_report::ShadowRecord {
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    tw_report::ShadowRecord {
        layers: s.layers,
        layers_reused: s.layers_reused,
        light_clusters: s.sets.light_cut,
        light_triangles: s.light_triangles,
        light_drawn_triangles: s.light_drawn_triangles,
        light_visible_clusters: s.sets.light_visible,
        caster_clusters: s.sets.casters,
        caster_triangles: s.caster_triangles,
        lit_triangles: s.sets.triangles_lit,
        shadowed_triangles: s.sets.triangles_shadowed,
        partial_triangles: s.sets.triangles_partial,
        partial_clusters: s.sets.receivers_partial,
        receiver_clusters: s.sets.receivers_lit + s.sets.receivers_shadowed + s.sets.receivers_partial,
        total_ms: ms(s.total),
        select_ms: ms(s.select),
        draw_ms: ms(s.draw),
        readback_ms: ms(s.readback),
        classify_ms: ms(s.classify),
    }
}

/// How a report names a light.
fn light_name(light: &tw_runtime::Light) -> String {
    match light {
        tw_runtime::Light::Sun { towards } => {
            format!("sun towards ({:.2}, {:.2}, {:.2})", towards.x, towards.y, towards.z)
        }
        tw_runtime::Light::Point { position } => {
            format!("point light at ({:.1}, {:.1}, {:.1}) scene", position.x, position.y, position.z)
        }
    }
}

/// Ratios between the runs of one report (measured in the same process on the same frames):
/// each strategy against the first run and against the reference, and the fidelity figures.
fn print_comparison(report: &BenchReport) {
    let Some(first) = report.runs.first() else { return };
    for run in &report.runs[1..] {
        if run.name == "reference" {
            // The reference ran on every K-th frame only: compare the same frames.
            let frames: std::collections::HashSet<u32> = run.frames.iter().map(|f| f.frame).collect();
            let same: Vec<f64> =
                first.frames.iter().filter(|f| frames.contains(&f.frame)).map(|f| f.frame_ms).collect();
            if let Some(m) = tw_report::stats::median(&same) {
                outln!(
                    "{:>10}: {} is {:.1}x faster than the reference on the same {} frames",
                    "speed-up",
                    first.name,
                    run.summary.median_ms / m.max(1e-9),
                    same.len()
                );
            }
        } else {
            outln!(
                "{:>10}: {} is {:.2}x the speed of {} (median frame time)",
                "ratio",
                run.name,
                first.summary.median_ms / run.summary.median_ms.max(1e-9),
                first.name
            );
        }
    }
    for shadowed in report.runs.iter().filter(|r| r.name.contains("+shadows")) {
        let plain = shadowed.name.replacen("+shadows", "", 1);
        if let Some(run) = report.runs.iter().find(|r| r.name == plain) {
            outln!(
                "{:>10}: {} runs at {:.2}x the frame rate of {} (median frame time, same frames)",
                "shadows",
                shadowed.name,
                run.summary.median_ms / shadowed.summary.median_ms.max(1e-9),
                run.name
            );
        }
    }
    for run in report.runs.iter().filter(|r| r.name != "reference") {
        let psnr: Vec<f64> = run.frames.iter().filter_map(|f| f.psnr_db).collect();
        if let (Some(med), Some(min)) =
            (tw_report::stats::median(&psnr), psnr.iter().cloned().reduce(f64::min))
        {
            outln!(
                "{:>10}: {}: PSNR against the reference: median {med:.1} dB, worst {min:.1} dB ({} frames)",
                "fidelity",
                run.name,
                psnr.len()
            );
        }
        print_supersampled(run);
        if let Some(e) = run.summary.median_culling_efficiency {
            let of_cut = run.summary.median_cut_efficiency.map_or(String::new(), |c| {
                format!(" (/ visible triangles of the frame's own LOD cut: median {c:.1})")
            });
            outln!(
                "{:>10}: {}: triangles drawn / exact visible triangles: median {e:.1}{of_cut}",
                "culling",
                run.name
            );
        }
        let s = &run.summary;
        if let (Some(ratio), Some(needed)) = (s.median_lod_efficiency, s.median_needed_triangles) {
            outln!(
                "{:>10}: {}: LOD cut median {} triangles, a screen needs ~{} at ε = {} px \
                 (2 · covered px ÷ ε²): cut ÷ needed median {ratio:.2}",
                "lod",
                run.name,
                fmt_count(s.median_cut_triangles as u64),
                fmt_count(needed as u64),
                report.meta.error_px
            );
        }
    }
}

fn print_run(run: &Run) {
    let s = &run.summary;
    outln!(
        "{:>10}: {} frames, median {:.1} ms ({:.1} fps), p99 {:.1} ms, median {} triangles, peak RSS {}",
        run.name,
        s.frames,
        s.median_ms,
        s.median_fps,
        s.p99_ms,
        fmt_count(s.median_triangles as u64),
        s.peak_rss_mb.map(|m| crate::units::fmt_bytes((m * 1e6) as u64)).unwrap_or_else(|| "?".into())
    );
    let node_tests: u64 = run.frames.iter().map(|f| f.occlusion_node_tests).sum();
    if node_tests > 0 {
        let hidden: u64 = run.frames.iter().map(|f| f.occlusion_nodes_hidden).sum();
        outln!(
            "{:>10}: {}: {} node boxes tested before the clusters, {} of them hidden (each culls its subtree)",
            "nodes", run.name, node_tests, hidden
        );
    }
    print_shadows(run);
    print_popping(run);
}

/// `--reference-samples`: the ground truth of one compared frame, its full-detail reference
/// supersampled (PNG-compressed, like the 1-sample references), and the brute-force frame's
/// PSNR against it.
struct Truth {
    png: Vec<u8>,
    brute_force_psnr_db: f64,
}

impl Truth {
    /// The truth of `camera`, whose 1-sample full-detail reference (at the run's samples) is
    /// `brute_force`.
    fn of(walk: &mut Walkthrough, camera: &Camera, brute_force: &Image, samples: u32) -> Result<Truth> {
        let truth = walk.reference_supersampled(camera, samples)?;
        Ok(Truth { brute_force_psnr_db: brute_force.psnr(&truth)?.min(99.0), png: truth.png_bytes()? })
    }

    /// Sets `rec`'s figures against the truth for its frame's `image`: the frame's PSNR, the
    /// brute-force frame's, and their difference (both capped at 99 dB as `psnr_db` is).
    fn record(&self, rec: &mut FrameRecord, image: &Image) -> Result<()> {
        let truth = Image::from_png_bytes(&self.png)?;
        let lod = image.psnr(&truth)?.min(99.0);
        rec.supersampled_psnr_db = Some(lod);
        rec.brute_force_psnr_db = Some(self.brute_force_psnr_db);
        rec.psnr_gap_db = Some(lod - self.brute_force_psnr_db);
        Ok(())
    }
}

/// `--reference-samples`: a run's PSNR against the supersampled references, its brute-force
/// counterpart's, and the difference (median, and the worst frame's).
fn print_supersampled(run: &Run) {
    let gaps: Vec<(u32, f64)> = run.frames.iter().filter_map(|f| Some((f.frame, f.psnr_gap_db?))).collect();
    let Some(&(worst_frame, worst)) = gaps.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else { return };
    let median = |v: Vec<f64>| tw_report::stats::median(&v).unwrap_or(f64::NAN);
    outln!(
        "{:>10}: {}: PSNR against the supersampled reference: median {:.2} dB (brute force {:.2} dB); \
         LOD − brute force: median {:.2} dB, worst {worst:.2} dB (frame {worst_frame}), {} of {} frames within 0.5 dB",
        "truth",
        run.name,
        median(run.frames.iter().filter_map(|f| f.supersampled_psnr_db).collect()),
        median(run.frames.iter().filter_map(|f| f.brute_force_psnr_db).collect()),
        median(gaps.iter().map(|g| g.1).collect()),
        gaps.iter().filter(|g| g.1 >= -0.5).count(),
        gaps.len()
    );
}

/// `--popping`: the LOD-only image change of a run's frames.
fn print_popping(run: &Run) {
    let changed: Vec<f64> = run.frames.iter().filter_map(|f| f.popping_changed_pixels).collect();
    if changed.is_empty() {
        return;
    }
    let psnr: Vec<f64> = run.frames.iter().filter_map(|f| f.popping_psnr_db).collect();
    let worst_changed = changed.iter().cloned().fold(0.0, f64::max);
    outln!(
        "{:>10}: {}: pixels the LOD alone changes: median {:.3} %, worst {:.3} %; PSNR of the change: median {}, \
         worst {} ({} of {} frames changed)",
        "popping",
        run.name,
        100.0 * tw_report::stats::median(&changed).unwrap_or(0.0),
        100.0 * worst_changed,
        tw_report::stats::median(&psnr).map_or("-".into(), |p| format!("{p:.1} dB")),
        psnr.iter().cloned().reduce(f64::min).map_or("-".into(), |p| format!("{p:.1} dB")),
        psnr.len(),
        changed.len()
    );
}

/// `--light`: the shadow stage's medians (set sizes and times) of a run.
fn print_shadows(run: &Run) {
    let shadows: Vec<&tw_report::ShadowRecord> =
        run.frames.iter().filter_map(|f| f.shadow.as_ref()).collect();
    if shadows.is_empty() {
        return;
    }
    let med = |f: &dyn Fn(&tw_report::ShadowRecord) -> f64| {
        tw_report::stats::median(&shadows.iter().map(|s| f(s)).collect::<Vec<f64>>()).unwrap_or(0.0)
    };
    let sum = |f: &dyn Fn(&tw_report::ShadowRecord) -> u32| shadows.iter().map(|s| f(s) as f64).sum::<f64>();
    let reused = 100.0 * sum(&|s| s.layers_reused) / sum(&|s| s.layers).max(1.0);
    let mean = shadows.iter().map(|s| s.total_ms).sum::<f64>() / shadows.len() as f64;
    outln!(
        "{:>10}: {}: median {:.1} ms, mean {:.1} (select {:.1}, map {:.1}, read-back {:.1}, classify {:.1}); {:.0} % of \
         the layers reused from an earlier frame; light-view set {} triangles ({} drawn) in {:.0} layers, {:.0} of {:.0} \
         clusters seen by the light, casters {} triangles; receivers lit {} / shadowed {} / partly {} triangles",
        "shadows",
        run.name,
        med(&|s| s.total_ms),
        mean,
        med(&|s| s.select_ms),
        med(&|s| s.draw_ms),
        med(&|s| s.readback_ms),
        med(&|s| s.classify_ms),
        reused,
        fmt_count(med(&|s| s.light_triangles as f64) as u64),
        fmt_count(med(&|s| s.light_drawn_triangles as f64) as u64),
        med(&|s| s.layers as f64),
        med(&|s| s.light_visible_clusters as f64),
        med(&|s| s.light_clusters as f64),
        fmt_count(med(&|s| s.caster_triangles as f64) as u64),
        fmt_count(med(&|s| s.lit_triangles as f64) as u64),
        fmt_count(med(&|s| s.shadowed_triangles as f64) as u64),
        fmt_count(med(&|s| s.partial_triangles as f64) as u64),
    );
}

/// Up to `n` frames spread evenly over `len`.
fn image_frames(len: usize, n: usize) -> Vec<usize> {
    if n == 0 || len == 0 {
        return Vec::new();
    }
    let n = n.min(len);
    (0..n).map(|k| k * (len - 1) / (n - 1).max(1)).collect()
}

/// The resident set now and its peak so far (VmRSS, VmHWM), for the memory traces.
fn memory_now() -> String {
    let mb = |b: Option<u64>| b.map_or("?".to_string(), crate::units::fmt_bytes);
    format!("RSS {}, peak {}", mb(tw_report::rss_bytes()), mb(tw_report::peak_rss_bytes()))
}

/// The machine, for the report's header: CPU model (where /proc/cpuinfo names it), cores this
/// process may use, memory (MemTotal, GiB as the kernel counts it), OS.
fn machine() -> String {
    let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let field = |file: &str, key: &str| -> Option<String> {
        let text = std::fs::read_to_string(file).ok()?;
        let line = text.lines().find(|l| l.split(':').next().is_some_and(|k| k.trim() == key))?;
        Some(line.split_once(':')?.1.trim().to_string())
    };
    let cpu = field("/proc/cpuinfo", "model name").map(|m| format!("{m}, ")).unwrap_or_default();
    let mem = field("/proc/meminfo", "MemTotal")
        .and_then(|v| v.split_whitespace().next()?.parse::<u64>().ok())
        .map(|kb| format!(", {:.1} GiB RAM", kb as f64 / 1048576.0))
        .unwrap_or_default();
    format!("{cpu}{cores} cores{mem}, {}", std::env::consts::OS)
}
