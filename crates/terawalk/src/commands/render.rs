//! `terawalk render`: frames of a store, headless (tw-runtime selects the LOD cut with frustum
//! culling; tw-gpu draws it and reads it back, or with `--renderer rt` tw-rt ray traces it): one
//! frame written as PNG, or every frame of a camera path as numbered PNGs and/or a video
//! (ffmpeg, `commands::video`). A model file is opened through the build cache
//! (`commands::open`).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use indicatif::ProgressBar;
use tw_core::Aabb;
use tw_frame::traced::TracedWalkthrough;
use tw_frame::{FrameSettings, ShadowInfo, Walkthrough};
use tw_gpu::{Image, Renderer};
use tw_rt::scene::{StoreTracer, TraceSettings, TraceStats};
use tw_runtime::{
    Camera, CameraPath, InputCamera, PageCache, SelectOptions, Selection, SelectionPages, Selector,
    StreamOptions,
};
use tw_store::{Header, Store};

use crate::cli::{RenderArgs, RendererChoice, ShadowArgs, View};
use crate::commands::preview::preset_direction;
use crate::commands::{open, video};
use crate::progress;
use crate::units::{fmt_bytes, fmt_count};

/// The up axis the camera uses: `--up` when given (overriding the store's at run time, no
/// rebuild), else the one the store records.
pub fn up_axis(header: &Header, over: Option<u8>) -> usize {
    over.unwrap_or(header.up_axis).min(2) as usize
}

/// The default camera: the store's bounds framed from the `--view iso` direction of `preview`,
/// upright along `up` (see [`up_axis`]).
pub fn default_camera(header: &Header, size: (u32, u32), up: usize) -> Result<Camera> {
    let bounds = Aabb { min: header.bounds_min, max: header.bounds_max };
    let (dir, up) = preset_direction(View::Iso, up);
    let c = tw_preview::Camera::frame_bounds(&bounds, dir, up, size.0 as f64 / size.1 as f64);
    Ok(Camera::from_input_coordinates(c.eye, c.target, c.up, c.fovy_deg, header)?)
}

pub fn run(args: RenderArgs, quiet: bool) -> Result<()> {
    if !(args.error.is_finite() && args.error >= 0.0) {
        anyhow::bail!("--error must be a finite number ≥ 0, got {}", args.error);
    }
    if let Some(fps) = args.fps.filter(|f| !(f.is_finite() && *f > 0.0)) {
        anyhow::bail!("--fps must be a number > 0, got {fps}");
    }
    if args.frames == Some(0) {
        anyhow::bail!("--frames N needs N ≥ 1");
    }
    let inputs: Vec<&Path> =
        [Some(args.store.as_path()), args.path.as_deref()].into_iter().flatten().collect();
    for out in [&args.output, &args.video].into_iter().flatten() {
        tw_core::output::check_output(out, &inputs)?;
    }
    // Before a model is built: a missing ffmpeg is known at once.
    let ffmpeg = args.video.as_ref().map(|_| video::find_ffmpeg()).transpose()?;
    let path = args.path.as_deref().map(CameraPath::load).transpose()?;
    let (store_path, store) = open::open(&args.store, args.up, &args.open, quiet)?;
    let store = Arc::new(store);
    let mut frame = FrameRenderer::new(&store, &args)?;
    match (&path, &args.output) {
        (Some(p), _) => render_sequence(&mut frame, p, &args, ffmpeg.as_deref(), quiet)?,
        (None, Some(output)) => render_one(&mut frame, output, &args)?,
        (None, None) => anyhow::bail!("give -o FILE.png, or --path with --frames-dir or --video"),
    }
    let failed = match &frame.backend {
        Backend::Shadowed(walk, _) => walk.streamer().cache().failed_pages(),
        Backend::TracedShadowed(traced, _) => traced.streamer().cache().failed_pages(),
        _ => frame.cache.failed_pages(),
    };
    crate::commands::damage::check(&store_path, &failed, args.allow_damaged)
}

/// The headless renderer, page cache and LOD selector of a store, reused from frame to frame.
struct FrameRenderer<'s> {
    store: &'s Store,
    backend: Backend,
    size: (u32, u32),
    cache: PageCache,
    selector: Selector,
    options: SelectOptions,
    /// `--up`, for `--light sun:AZ,EL`.
    up: Option<u8>,
    /// `--transition`: with a cross-fade, frames go through the frame pipeline.
    transition: tw_frame::Transition,
}

/// What draws the cut: the rasterizer or the ray tracer (`--renderer`); with `--light` the
/// rasterizer draws through the frame pipeline (tw-frame), whose shadow stage draws the shadow
/// map from the light-view sets.
enum Backend {
    Raster(Box<Renderer>),
    Shadowed(Box<Walkthrough>, ShadowArgs),
    /// The ray tracer with `--light`: the traced frame pipeline, whose cut also holds the
    /// casters outside the eye's frustum.
    TracedShadowed(Box<TracedWalkthrough>, ShadowArgs),
    Rt(Box<StoreTracer>, TraceSettings),
}

/// One rendered frame and what it took.
struct Frame {
    image: Image,
    selection: Selection,
    select_time: Duration,
    /// The ray tracer's figures (`--renderer rt`).
    traced: Option<TraceStats>,
    /// The shadow stage's figures (`--light`, rasterized).
    shadow: Option<ShadowInfo>,
}

impl<'s> FrameRenderer<'s> {
    fn new(store: &'s Arc<Store>, args: &RenderArgs) -> Result<Self> {
        let section = args.section.section(store.header())?;
        let faded = args.frame.transition != tw_frame::Transition::Pop;
        if faded && args.renderer == RendererChoice::Rt {
            anyhow::bail!(
                "--transition {} needs the rasterizer: the ray tracer switches LOD at once (use --transition pop)",
                args.frame.transition.name()
            );
        }
        let backend = match args.renderer {
            // A cross-fade needs the frame pipeline's state from frame to frame.
            RendererChoice::Raster if args.shadows.light.is_some() || faded => {
                let mut renderer = Renderer::new_headless(args.frame.size.0, args.frame.size.1)?;
                outln!("adapter: {}", renderer.adapter_summary());
                renderer.set_samples(args.frame.samples.resolve(&renderer))?;
                renderer.set_color_mode(args.color.mode());
                let stream = StreamOptions { budget_bytes: args.memory, ..Default::default() };
                let walk = Walkthrough::new(store.clone(), renderer, stream)?;
                Backend::Shadowed(Box::new(walk), args.shadows.clone())
            }
            RendererChoice::Raster => {
                let mut renderer = Renderer::new_headless(args.frame.size.0, args.frame.size.1)?;
                outln!("adapter: {}", renderer.adapter_summary());
                renderer.set_samples(args.frame.samples.resolve(&renderer))?;
                renderer.set_store_colors(store);
                renderer.set_color_mode(args.color.mode());
                renderer.set_section(&section);
                Backend::Raster(Box::new(renderer))
            }
            RendererChoice::Rt if args.shadows.light.is_some() => {
                outln!("renderer: CPU ray tracer, {} threads", StoreTracer::threads());
                let trace = TraceSettings {
                    coloring: args.color.mode(),
                    flashlight: args.flashlight,
                    ..Default::default()
                };
                let stream = StreamOptions { budget_bytes: args.memory, ..Default::default() };
                let traced = TracedWalkthrough::new(store.clone(), args.frame.size, stream, trace)?;
                Backend::TracedShadowed(Box::new(traced), args.shadows.clone())
            }
            RendererChoice::Rt => {
                outln!("renderer: CPU ray tracer, {} threads", StoreTracer::threads());
                let settings = TraceSettings {
                    coloring: args.color.mode(),
                    flashlight: args.flashlight,
                    section,
                    ..Default::default()
                };
                let (_, bvhs) = StoreTracer::budget_split(args.memory);
                Backend::Rt(Box::new(StoreTracer::new(store, bvhs)), settings)
            }
        };
        if args.flashlight && args.renderer != RendererChoice::Rt {
            anyhow::bail!("--flashlight needs --renderer rt (shadows are ray traced)");
        }
        // The ray tracer's cluster BVHs share --memory with the decoded pages.
        let pages = match args.renderer {
            RendererChoice::Raster => args.memory,
            RendererChoice::Rt => StoreTracer::budget_split(args.memory).0,
        };
        // The frame pipeline has a page cache of its own: this one holds the root pages only.
        let pages =
            if matches!(backend, Backend::Shadowed(..) | Backend::TracedShadowed(..)) { 1 } else { pages };
        let cache = PageCache::new(store, pages);
        cache.load_root_pages(store);
        let selector = Selector::new(store);
        let options = SelectOptions {
            tau: args.error,
            viewport: [args.frame.size.0, args.frame.size.1],
            frustum_culling: true,
            section,
            ..Default::default()
        };
        let transition = args.frame.transition;
        Ok(FrameRenderer {
            store,
            backend,
            size: args.frame.size,
            cache,
            selector,
            options,
            up: args.up,
            transition,
        })
    }

    /// The LOD cut for `camera`, drawn and read back.
    fn draw(&mut self, camera: &Camera) -> Result<Frame> {
        let header = self.store.header();
        let up = up_axis(header, self.up) as u8;
        let select = |selector: &Selector, cache: &PageCache| {
            let t = Instant::now();
            let selection = selector.select(self.store, cache, camera, &self.options);
            (selection, t.elapsed())
        };
        Ok(match &mut self.backend {
            Backend::Raster(renderer) => {
                let (selection, select_time) = select(&self.selector, &self.cache);
                let image = renderer.render_selection(self.store, &self.cache, camera, &selection)?;
                Frame { image, selection, select_time, traced: None, shadow: None }
            }
            Backend::Rt(tracer, settings) => {
                let (selection, select_time) = select(&self.selector, &self.cache);
                let pages = SelectionPages::resolve(self.store, &self.cache, &selection.clusters);
                let frame = tracer.trace(&pages, camera, self.size, settings);
                let image = Image { width: frame.width, height: frame.height, rgba: frame.rgba };
                Frame { image, selection, select_time, traced: Some(frame.stats), shadow: None }
            }
            Backend::Shadowed(walk, shadows) => {
                let settings = FrameSettings {
                    transition: self.transition,
                    ..frame_settings(&self.options, shadows.settings(header, up, camera)?)
                };
                let (image, info) = walk.frame(camera, &settings)?;
                let selection = walk.selection().clone();
                Frame {
                    image,
                    selection,
                    select_time: info.times.select,
                    traced: None,
                    shadow: Some(info.shadow),
                }
            }
            Backend::TracedShadowed(traced, shadows) => {
                let settings = frame_settings(&self.options, shadows.settings(header, up, camera)?);
                let (image, info, frame) = traced.frame(camera, &settings)?;
                let selection = traced.selection().clone();
                Frame {
                    image,
                    selection,
                    select_time: info.times.select,
                    traced: Some(frame.stats),
                    shadow: None,
                }
            }
        })
    }
}

/// The frame pipeline's settings of `render` with `--light`: the cut at `--error`, every page
/// loaded first, no occlusion culling (as the direct draws), with `shadows`.
fn frame_settings(options: &SelectOptions, shadows: Option<tw_frame::ShadowSettings>) -> FrameSettings {
    FrameSettings {
        tau: options.tau,
        wait_for_pages: true,
        shadows,
        section: options.section,
        ..Default::default()
    }
}

/// `-o FILE`: one frame from `--camera` (or the default overview), with the figures of its cut.
fn render_one(frame: &mut FrameRenderer, output: &Path, args: &RenderArgs) -> Result<()> {
    let header = frame.store.header();
    let camera = match &args.camera {
        Some(s) => InputCamera::parse(s)?.to_scene(header)?,
        None => default_camera(header, args.frame.size, up_axis(header, args.up))?,
    };
    let Frame { image, selection, select_time, traced, shadow } = frame.draw(&camera)?;
    image.save_png(output)?;
    let cs = frame.cache.stats();
    outln!(
        "selection: {} clusters, {} triangles (τ = {} px) in {:.1} ms; {} pages touched, {} resident \
         ({}), {} culled by frustum",
        fmt_count(selection.stats.clusters_selected),
        fmt_count(selection.triangles),
        args.error,
        select_time.as_secs_f64() * 1e3,
        selection.stats.pages_touched,
        cs.resident_pages,
        fmt_bytes(cs.resident_bytes),
        fmt_count(selection.stats.nodes_culled_frustum + selection.stats.groups_culled_frustum),
    );
    if !frame.options.section.is_empty() {
        let s = &selection.stats;
        outln!(
            "section: culled {} nodes, {} groups, {} clusters",
            fmt_count(s.nodes_culled_section),
            fmt_count(s.groups_culled_section),
            fmt_count(s.clusters_culled_section),
        );
    }
    match (&frame.backend, traced) {
        (Backend::Raster(renderer), _) => print_raster_stats(renderer),
        (Backend::Shadowed(walk, _), _) => {
            print_raster_stats(walk.renderer());
            if let Some(s) = shadow {
                print_shadow_stats(&s);
            }
        }
        (Backend::Rt(tracer, _), Some(t)) => print_trace_stats(&t, tracer.bytes()),
        (Backend::TracedShadowed(traced, _), Some(t)) => print_trace_stats(&t, traced.tracer().bytes()),
        (Backend::Rt(..) | Backend::TracedShadowed(..), None) => {}
    }
    outln!("wrote {} ({}x{})", output.display(), args.frame.size.0, args.frame.size.1);
    Ok(())
}

/// What the shadow stage did (`--light`).
fn print_shadow_stats(s: &ShadowInfo) {
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    outln!(
        "shadows: {} layers in {:.1} ms (select {:.1}, map {:.1}, read-back {:.1}, classify {:.1}); light-view \
         set {} triangles ({} drawn; {} clusters, {} seen by the light), casters {} triangles; receivers: lit {}, \
         shadowed {}, partly {} triangles",
        s.layers,
        ms(s.total),
        ms(s.select),
        ms(s.draw),
        ms(s.readback),
        ms(s.classify),
        fmt_count(s.light_triangles),
        fmt_count(s.light_drawn_triangles),
        fmt_count(s.sets.light_cut),
        fmt_count(s.sets.light_visible),
        fmt_count(s.caster_triangles),
        fmt_count(s.sets.triangles_lit),
        fmt_count(s.sets.triangles_shadowed),
        fmt_count(s.sets.triangles_partial),
    );
}

/// What the rasterizer did for the last frame.
fn print_raster_stats(renderer: &Renderer) {
    let stats = renderer.stats();
    outln!(
        "render: {} triangles drawn, {} clusters; upload {:.1} ms, GPU + readback {:.1} ms",
        fmt_count(stats.triangles),
        fmt_count(stats.clusters),
        stats.upload.as_secs_f64() * 1e3,
        stats.render.as_secs_f64() * 1e3,
    );
    outln!(
        "GPU pool: {} clusters uploaded ({}), {} resident, {} batch(es), {} draw call(s) ({:?})",
        fmt_count(stats.pool.uploaded_clusters),
        fmt_bytes(stats.pool.uploaded_bytes),
        fmt_bytes(stats.pool.resident_bytes),
        stats.pool.batches,
        fmt_count(stats.draw_calls),
        renderer.draw_mode(),
    );
}

/// What the ray tracer did for the last frame.
fn print_trace_stats(t: &TraceStats, bytes: usize) {
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    outln!(
        "ray tracing: {} clusters, {} triangles; {} cluster BVHs made ({} from stored shapes) in {:.1} ms, \
         top level {:.1} ms; \
         {} rays in {:.1} ms ({:.1} M rays/s), shading {:.1} ms; BVHs hold {}",
        fmt_count(t.clusters as u64),
        fmt_count(t.triangles),
        fmt_count(t.blas.built as u64),
        fmt_count(t.blas.stored as u64),
        ms(t.blas.build_time),
        ms(t.tlas_time),
        fmt_count(t.rays),
        ms(t.trace_time),
        t.rays as f64 / t.trace_time.as_secs_f64().max(1e-9) / 1e6,
        ms(t.shade_time),
        fmt_bytes(bytes as u64),
    );
}

/// `DIR/frame-00042.png`: numbered from 0, five digits (more past 99,999 frames), so that the
/// names sort in frame order and ffmpeg's `frame-%05d.png` pattern reads them.
fn frame_file(dir: &Path, index: usize) -> PathBuf {
    dir.join(format!("frame-{index:05}.png"))
}

/// `--path`: every frame of the camera path (the first `--frames`), written as numbered PNGs
/// into `--frames-dir` and/or piped into ffmpeg for `--video`, with a progress bar and a summary.
/// Every camera is checked before the first frame is drawn.
fn render_sequence(
    frame: &mut FrameRenderer,
    path: &CameraPath,
    args: &RenderArgs,
    ffmpeg: Option<&Path>,
    quiet: bool,
) -> Result<()> {
    let header = frame.store.header();
    let file = args.path.as_deref().unwrap_or(Path::new("--path")).display();
    let count = args.frames.map_or(path.frames.len(), |n| n.min(path.frames.len()));
    if count == 0 {
        anyhow::bail!("the camera path {file} has no frames");
    }
    let cameras: Vec<Camera> = path.frames[..count]
        .iter()
        .enumerate()
        .map(|(i, f)| f.to_scene(header).with_context(|| format!("{file}: frame {i}")))
        .collect::<Result<_>>()?;
    if let Some(dir) = &args.frames_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let fps = args.fps.unwrap_or(path.fps);
    let mut encoder = match (ffmpeg, &args.video) {
        (Some(ffmpeg), Some(out)) => Some(video::Encoder::start(ffmpeg, args.frame.size, fps, out)?),
        _ => None,
    };
    let bar = if quiet { ProgressBar::hidden() } else { progress::count(count as u64, "render") };
    let start = Instant::now();
    let mut triangles = 0u64;
    for (i, camera) in cameras.iter().enumerate() {
        let f = frame.draw(camera).with_context(|| format!("{file}: frame {i}"))?;
        triangles += f.selection.triangles;
        if let Some(dir) = &args.frames_dir {
            f.image.save_png(&frame_file(dir, i))?;
        }
        if let Some(e) = encoder.as_mut() {
            e.frame(&f.image.opaque())?;
        }
        bar.set_position(i as u64 + 1);
    }
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    if let Some(e) = encoder {
        e.finish()?;
    }
    let (w, h) = args.frame.size;
    outln!(
        "rendered {count} frames ({w}x{h}, τ = {} px) in {secs:.1} s: {:.1} ms a frame, {} triangles a frame on average",
        args.error,
        secs * 1e3 / count as f64,
        fmt_count(triangles / count as u64)
    );
    if let Some(dir) = &args.frames_dir {
        outln!("wrote {} … {}", frame_file(dir, 0).display(), frame_file(dir, count - 1).display());
    }
    if let Some(out) = &args.video {
        outln!("wrote {} ({count} frames at {fps} fps, {:.1} s)", out.display(), count as f64 / fps);
    }
    Ok(())
}
