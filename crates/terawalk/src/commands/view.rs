//! `terawalk view`: the interactive viewer (tw-view). Everything that can be wrong with the
//! user's input — a missing or corrupt store, a bad camera or path file, a bad option — is
//! checked here and reported with a clear message and exit code 1 before any window opens.
//!
//! With no file the window opens empty, with the open dialog; with a model the cache lacks it
//! opens at once and builds the model in the background, showing the build's progress (the
//! viewer's opener, the one the open dialog uses), unless an option needs the store before the
//! window (`--camera`, `--path`, `--light`, `--section`, `--section-box`: given in the model's
//! coordinates) or `--exit-after` counts frames from the start:
//! then it is built first, with the terminal's progress, as `render` does. A model whose file
//! is missing is an error before the window. `--up`, `--units` and the cache options apply to
//! every build, the first and those the open dialog starts.

use std::path::Path;

use anyhow::{Context, Result};
use tw_runtime::{CameraPath, InputCamera};
use tw_view::settings::ShadowControls;
use tw_view::{Coloring, Occlusion, RendererKind, Scene, Settings, ViewOptions};

use crate::cli::{CameraModeArg, OcclusionChoice, RenderColoring, RendererChoice, ViewArgs};
use crate::commands::render::{default_camera, up_axis};

pub fn run(args: ViewArgs, quiet: bool) -> Result<()> {
    check_args(&args)?;
    let scripted = args.exit_after.is_some() || args.script.is_some();
    let script = match &args.script {
        Some(p) => Some(tw_view::script::Script::load(p)?),
        None => None,
    };
    let report = match start(&args)? {
        Start::Empty => tw_view::run_empty(empty_options(&args, script, None)?, None)?,
        Start::Build(model) => tw_view::run_empty(empty_options(&args, script, Some(model))?, Some(model))?,
        Start::Store(file) => run_on_store(&args, file, script, quiet)?,
    };
    print_report(&report, scripted);
    Ok(())
}

/// What the window starts with.
enum Start<'a> {
    /// No file: the open dialog.
    Empty,
    /// A model the cache lacks: built in the background, in the viewer's progress window.
    Build(&'a Path),
    /// A store, or a model built first (its cached store, or built with the terminal's progress
    /// when an option needs the store before the window opens).
    Store(&'a Path),
}

/// No file: an empty window (options that need a scene are refused); a model the cache lacks,
/// with no option that reads its store before the window opens (`--camera`, `--path`,
/// `--light`, the section's) and no `--exit-after`: its build in the window; else the store.
fn start(args: &ViewArgs) -> Result<Start<'_>> {
    let needs_store = [
        (args.camera.is_some(), "--camera"),
        (args.path.is_some(), "--path"),
        (args.shadows.light.is_some(), "--light"),
        (!args.section.planes.is_empty(), "--section"),
        (args.section.section_box.is_some(), "--section-box"),
    ];
    let Some(file) = args.store.as_deref() else {
        if let Some((_, name)) = needs_store.iter().find(|(given, _)| *given) {
            anyhow::bail!("{name} needs a FILE to view (it is read in the scene's coordinates): terawalk view FILE {name} …");
        }
        return Ok(Start::Empty);
    };
    // `--exit-after N` counts frames from the start, and cannot wait for a build as a
    // script's `wait-open` does: the store is built first.
    let in_window =
        file.exists() && !needs_store.iter().any(|(given, _)| *given) && args.exit_after.is_none();
    if in_window && crate::commands::open::needs_build(file, args.up, &args.open)? {
        Ok(Start::Build(file))
    } else {
        Ok(Start::Store(file))
    }
}

/// The viewer over the store `file` (a model: its cached store, built first when missing).
fn run_on_store(
    args: &ViewArgs,
    file: &Path,
    script: Option<tw_view::script::Script>,
    quiet: bool,
) -> Result<tw_view::ViewReport> {
    let (_, store) = crate::commands::open::open(file, args.up, &args.open, quiet)?;
    let path = match &args.path {
        Some(p) => Some(CameraPath::load(p)?),
        None => None,
    };
    let header = store.header();
    let camera = start_camera(args, header, path.as_ref())?;
    let shadows = shadow_controls(args, header, &camera)?;
    let section = tw_view::section_tool::SectionTool::from_section(&args.section.section(header)?);
    let mut scene = Scene::new(store, args.memory);
    scene.set_fit_memory(args.fit_memory)?;
    if let Some(axis) = args.up {
        scene.set_up_axis(axis);
    }
    let mut options = ViewOptions { path, ..view_options(args, camera, shadows, script, Some(file)) };
    options.settings.section = section;
    Ok(tw_view::run(scene, options)?)
}

/// The options of a window that starts with no scene (`model`: the file being built for it).
/// The camera and the shadows are the opened scene's own (its iso view, shadows off): only
/// the field of view of this camera counts.
fn empty_options(
    args: &ViewArgs,
    script: Option<tw_view::script::Script>,
    model: Option<&Path>,
) -> Result<ViewOptions> {
    let camera = tw_runtime::Camera::new(
        glam::Vec3::new(0.0, -1.0, 0.0),
        glam::Vec3::ZERO,
        glam::Vec3::Z,
        tw_preview::camera::FRAMING_FOVY_DEG.to_radians() as f32,
        1e-3,
        10.0,
    )?;
    Ok(view_options(args, camera, ShadowControls::for_up_axis(2), script, model))
}

/// The viewer's options from the command's (`file`: the file named, shown in the title).
fn view_options(
    args: &ViewArgs,
    camera: tw_runtime::Camera,
    shadows: ShadowControls,
    script: Option<tw_view::script::Script>,
    file: Option<&Path>,
) -> ViewOptions {
    let occlusion = match args.occlusion {
        OcclusionChoice::Auto => Occlusion::None,
        OcclusionChoice::Is(o) => o,
    };
    let file = file.map(Path::to_path_buf).unwrap_or_default();
    ViewOptions {
        camera,
        path: None,
        play: args.play,
        exit_after: args.exit_after,
        script,
        screenshot: args.screenshot.clone(),
        window_screenshot: args.screenshot_window.clone(),
        record: args.record.clone(),
        output_dir: args.output_dir.clone(),
        size: args.size,
        title: file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
        mode: match args.mode {
            CameraModeArg::Fly => tw_view::controller::Mode::Fly,
            CameraModeArg::Walk => tw_view::controller::Mode::Walk,
            CameraModeArg::Orbit => tw_view::controller::Mode::Orbit,
        },
        settings: settings(args, occlusion, shadows),
        occlusion_auto: args.occlusion == OcclusionChoice::Auto,
        file,
        opener: Some(opener(args.up, &args.open)),
        fit_memory: args.fit_memory,
    }
}

/// Refuses options that cannot work together, and outputs that would overwrite an input,
/// before anything is read.
fn check_args(args: &ViewArgs) -> Result<()> {
    let inputs: Vec<&std::path::Path> =
        [args.store.as_deref(), args.path.as_deref(), args.script.as_deref()].into_iter().flatten().collect();
    for out in [&args.screenshot, &args.screenshot_window, &args.record].into_iter().flatten() {
        tw_core::output::check_output(out, &inputs)?;
    }
    if !(args.error.is_finite() && args.error >= 0.0) {
        anyhow::bail!("--error must be a finite number ≥ 0, got {}", args.error);
    }
    if !(0.1..=1.0).contains(&args.render_scale) {
        anyhow::bail!("--render-scale must be in 0.1..=1, got {}", args.render_scale);
    }
    if args.flashlight && args.renderer != RendererChoice::Rt {
        anyhow::bail!("--flashlight needs --renderer rt (shadows are ray traced)");
    }
    let scripted = args.exit_after.is_some() || args.script.is_some();
    if (args.screenshot.is_some() || args.screenshot_window.is_some()) && !scripted {
        anyhow::bail!(
            "--screenshot needs --exit-after N or --script FILE (press F12 for screenshots while viewing)"
        );
    }
    if args.play && args.path.is_none() {
        anyhow::bail!("--play needs --path FILE");
    }
    if args.exit_after.is_some() && args.script.is_some() {
        anyhow::bail!("--exit-after and --script both say when to stop: give one of them");
    }
    Ok(())
}

/// The camera to start from: `--camera`, else the path's first frame, else the default view
/// of the store. Every frame of the path is checked here, so that a bad one is an error before
/// the window opens.
fn start_camera(
    args: &ViewArgs,
    header: &tw_store::Header,
    path: Option<&CameraPath>,
) -> Result<tw_runtime::Camera> {
    let camera = match (&args.camera, path) {
        (Some(s), _) => InputCamera::parse(s)?.to_scene(header)?,
        (None, Some(p)) => p.frames[0]
            .to_scene(header)
            .with_context(|| format!("first frame of {}", args.path.as_ref().expect("path").display()))?,
        (None, None) => default_camera(header, args.size, up_axis(header, args.up))?,
    };
    if let Some(p) = path {
        for (i, f) in p.frames.iter().enumerate() {
            f.to_scene(header).with_context(|| format!("path frame {i}"))?;
        }
    }
    Ok(camera)
}

/// The viewer's settings at the start, from the options.
fn settings(args: &ViewArgs, occlusion: Occlusion, shadows: ShadowControls) -> Settings {
    Settings {
        pixel_error: args.error,
        occlusion,
        transition: args.transition,
        frustum_culling: !args.no_frustum,
        memory_budget: args.memory,
        coloring: match args.color.color {
            RenderColoring::Material => Coloring::Material,
            RenderColoring::Object => Coloring::Object,
            RenderColoring::Level => Coloring::Level,
            RenderColoring::Cluster => Coloring::Cluster,
            RenderColoring::Shadow => Coloring::Shadow,
        },
        render_scale: args.render_scale,
        debug_view: args.debug_view,
        renderer: match args.renderer {
            RendererChoice::Raster => RendererKind::Raster,
            RendererChoice::Rt => RendererKind::Rt,
        },
        flashlight: args.flashlight,
        shadows,
        ..Settings::default()
    }
}

/// What a run wrote and, for a scripted run, what its last frame drew.
fn print_report(report: &tw_view::ViewReport, scripted: bool) {
    if let Some(s) = &report.screenshot {
        outln!("wrote {}", s.display());
    }
    if scripted {
        outln!(
            "{} frames ({} minimised), {} triangles in the last, window {}x{}",
            report.frames,
            report.minimized_frames,
            report.last_triangles,
            report.last_size[0],
            report.last_size[1]
        );
        if report.samples > 0 {
            outln!("ray traced: {} samples per pixel in the last frame", report.samples);
        }
    }
}

/// The viewer's shadow controls at the start: `--light` and its options turn shadows on with
/// that light; without it they start off, ready to be turned on (J) with the shading's own sun
/// ([`tw_runtime::Light::default_sun`]).
fn shadow_controls(
    args: &ViewArgs,
    header: &tw_store::Header,
    camera: &tw_runtime::Camera,
) -> Result<ShadowControls> {
    let up = up_axis(header, args.up) as u8;
    Ok(match args.shadows.settings(header, up, camera)? {
        Some(s) => ShadowControls::from_settings(&s, true, up),
        // The shading's sun depends only on the camera's up, which the viewer keeps on the
        // store's up axis (or --up's).
        None => ShadowControls::for_up_axis(up),
    })
}

/// How the viewer opens files (the open dialog, drag and drop): a model is built into the same
/// cache and with the same options (`--up`, `--units`, `--cache-dir`, …) as the file named on
/// the command line, reporting to the viewer's progress window; the dialog lists stores and
/// the model files `build` reads.
fn opener(up: Option<u8>, open: &crate::cli::OpenArgs) -> tw_view::opening::Opener {
    let open = open.clone();
    let build = move |input: &std::path::Path, report: &dyn Fn(tw_view::opening::Progress)| {
        let mut progress = WindowProgress { report, phase: tw_view::opening::Progress::default() };
        crate::commands::open::store_for(input, up, &open, &mut progress).map_err(|e| format!("{e:#}"))
    };
    let accepts = |p: &std::path::Path| tw_view::opening::is_store(p) || crate::commands::open::is_model(p);
    tw_view::opening::Opener::new(std::sync::Arc::new(build), std::sync::Arc::new(accepts))
}

/// A build's progress, handed to the viewer's progress window.
struct WindowProgress<'a> {
    report: &'a dyn Fn(tw_view::opening::Progress),
    phase: tw_view::opening::Progress,
}

impl tw_build::BuildProgress for WindowProgress<'_> {
    fn phase(&mut self, name: &str, total: u64, unit: &str) {
        self.phase = tw_view::opening::Progress { phase: name.into(), done: 0, total, unit: unit.into() };
        (self.report)(self.phase.clone());
    }
    fn advance(&mut self, done: u64) {
        self.phase.done = done;
        self.phase.total = self.phase.total.max(done);
        (self.report)(self.phase.clone());
    }
    fn end_phase(&mut self) {}
}
