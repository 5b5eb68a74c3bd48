//! `terawalk view`: the interactive viewer (tw-view). Everything that can be wrong with the
//! user's input — a missing or corrupt store, a bad camera or path file, a bad option — is
//! checked here and reported with a clear message and exit code 1 before any window opens.

use anyhow::{Context, Result};
use tw_runtime::{CameraPath, InputCamera};
use tw_view::settings::ShadowControls;
use tw_view::{Coloring, Occlusion, RendererKind, Scene, Settings, ViewOptions};

use crate::cli::{CameraModeArg, OcclusionChoice, RenderColoring, RendererChoice, ViewArgs};
use crate::commands::render::{default_camera, up_axis};

pub fn run(args: ViewArgs, quiet: bool) -> Result<()> {
    check_args(&args)?;
    let occlusion = match args.occlusion {
        OcclusionChoice::Auto => Occlusion::None,
        OcclusionChoice::Is(o) => o,
    };
    let scripted = args.exit_after.is_some() || args.script.is_some();
    let script = match &args.script {
        Some(p) => Some(tw_view::script::Script::load(p)?),
        None => None,
    };
    let (_, store) = crate::commands::open::open(&args.store, args.up, &args.open, quiet)?;
    let path = match &args.path {
        Some(p) => Some(CameraPath::load(p)?),
        None => None,
    };
    if args.play && path.is_none() {
        anyhow::bail!("--play needs --path FILE");
    }
    let header = store.header();
    let camera = start_camera(&args, header, path.as_ref())?;
    let shadows = shadow_controls(&args, header, &camera)?;
    let mut settings = settings(&args, occlusion, shadows);
    settings.section = tw_view::section_tool::SectionTool::from_section(&args.section.section(header)?);
    let title = args.store.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut scene = Scene::new(store, args.memory);
    scene.set_fit_memory(args.fit_memory)?;
    if let Some(axis) = args.up {
        scene.set_up_axis(axis);
    }
    let options = ViewOptions {
        camera,
        path,
        play: args.play,
        exit_after: args.exit_after,
        script,
        screenshot: args.screenshot.clone(),
        window_screenshot: args.screenshot_window.clone(),
        record: args.record.clone(),
        output_dir: args.output_dir.clone(),
        size: args.size,
        title,
        mode: match args.mode {
            CameraModeArg::Fly => tw_view::controller::Mode::Fly,
            CameraModeArg::Walk => tw_view::controller::Mode::Walk,
            CameraModeArg::Orbit => tw_view::controller::Mode::Orbit,
        },
        settings,
        occlusion_auto: args.occlusion == OcclusionChoice::Auto,
        file: args.store.clone(),
        opener: Some(opener(args.up, &args.open)),
    };
    let report = tw_view::run(scene, options)?;
    print_report(&report, scripted);
    Ok(())
}

/// Refuses options that cannot work together, and outputs that would overwrite an input,
/// before anything is read.
fn check_args(args: &ViewArgs) -> Result<()> {
    let inputs: Vec<&std::path::Path> =
        [Some(args.store.as_path()), args.path.as_deref(), args.script.as_deref()]
            .into_iter()
            .flatten()
            .collect();
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
