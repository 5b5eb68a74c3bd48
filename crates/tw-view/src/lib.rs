//! terawalk's interactive viewer (`terawalk view scene.tw`): a winit window drawn with wgpu, a
//! UI in egui, and tw-frame's per-frame pipeline (camera → select and stream → occlude → draw,
//! the `bench` pipeline, never waiting for the disk) behind it.
//!
//! Modules, one concern each:
//! - [`settings`]: every control as plain data (pixel error, occlusion strategy, culling, LOD
//!   freeze, memory budget, colourings, debug view, shadows of one light and its keys);
//! - [`controller`]: fly / walk / orbit camera controllers (plain data, unit-tested);
//! - [`collision`]: walk mode's capsule against the resident geometry (`tw-collide`);
//! - [`hud`]: fps, frame-time graph, disk throughput and the HUD's figures;
//! - [`debug_view`]: the third-person debug view's geometry (frustum, node boxes, projection);
//! - [`pick`]: CPU ray casting for the orbit pivot, walk mode's ground, picking objects and
//!   measuring;
//! - [`model_tree`]: the objects as a tree (names with `/` paths) or a list, and its search;
//! - [`tree_panel`]: the model tree's window (virtualised rows);
//! - [`measure_draw`]: the measurements' lines over the scene (the plane's outline, crosses);
//! - [`snap`]: a measurement point snapped to the picked triangle's vertex or edge on the screen;
//! - [`review`]: design-review state: hidden / isolated objects, the picked object, the
//!   point-to-point and point-to-plane measurements;
//! - [`viewpoints`]: the axis and isometric preset views, named viewpoints saved next to the
//!   store;
//! - [`recorder`]: camera path recording and playback (the `path`/`bench` JSON format);
//! - [`scene`]: the store and its `tw_frame::Walkthrough` (streamer, renderer, occlusion
//!   culling), the scene texture egui shows;
//! - [`traced`]: the ray-traced mode (`--renderer rt`): `tw_frame`'s traced walkthrough and
//!   the running mean of its samples while the camera stands still;
//! - [`accumulate`]: progressive supersampling's sample positions and running mean;
//! - [`gfx`]: window surface, device and egui-wgpu;
//! - [`readback`]: textures to images (screenshots);
//! - [`ui`]: the egui panels;
//! - [`opening`], [`browser`], [`open_ui`]: opening another file at run time (in the
//!   background, with a progress window), the open dialog and drag and drop;
//! - [`script`]: scripted sessions (`--script`: keys, mouse look, clicks, resizes, minimising,
//!   preset and named views, screenshots, frame by frame);
//! - `app`: the winit event loop tying them together.
//!
//! [`run`] opens the window and returns when it is closed, after `exit_after` frames or the
//! last step of a `script`, or with the first error (no panics on user input).

pub mod accumulate;
pub mod browser;
pub mod collision;
pub mod controller;
pub mod debug_view;
pub mod error;
pub mod fullscreen;
pub mod gfx;
pub mod hud;
pub mod measure_draw;
pub mod model_tree;
pub mod open_ui;
pub mod opening;
pub mod pick;
pub mod readback;
pub mod recorder;
pub mod review;
pub mod scene;
pub mod script;
pub mod section_tool;
pub mod section_ui;
pub mod settings;
pub mod snap;
pub mod traced;
pub mod tree_panel;
pub mod ui;
pub mod viewpoints;

mod app;

use std::path::{Path, PathBuf};

pub use error::ViewError;
pub use scene::Scene;
pub use settings::{Coloring, Occlusion, RendererKind, Settings};
use tw_runtime::{Camera, CameraPath};

/// How to start the viewer.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// The starting camera (scene space). Without a scene at the start ([`run_empty`]) only
    /// its field of view counts: an opened scene starts at its isometric view.
    pub camera: Camera,
    /// A path to play (`--path`); with `play` or `exit_after` it plays at once.
    pub path: Option<CameraPath>,
    pub play: bool,
    /// Stop after this many frames (scripted runs: one path frame per rendered frame).
    pub exit_after: Option<u64>,
    /// Drive the session with a script and stop after its last step (one path frame per
    /// frame, as with `exit_after`).
    pub script: Option<script::Script>,
    /// Write the last frame here on exit (with `exit_after`).
    pub screenshot: Option<PathBuf>,
    /// Write the whole window (UI included) here just before exit (with `exit_after`).
    pub window_screenshot: Option<PathBuf>,
    /// Where a recording is saved (default: `output_dir/terawalk-path-<time>.json`); when
    /// given, recording starts at once and is saved at exit at the latest.
    pub record: Option<PathBuf>,
    /// Where F12 screenshots and recordings go.
    pub output_dir: PathBuf,
    /// Window size in pixels.
    pub size: (u32, u32),
    /// Shown in the title bar (the store's file name).
    pub title: String,
    /// Camera mode at the start (orbit: around the point ahead).
    pub mode: controller::Mode,
    /// `settings.debug_view` starts the third-person debug view from the starting camera.
    pub settings: Settings,
    /// Replace `settings.occlusion` by the fastest conservative strategy on the window's
    /// device once it is open (`--occlusion auto`).
    pub occlusion_auto: bool,
    /// The file the scene was opened from (the open dialog starts in its folder).
    pub file: PathBuf,
    /// How files opened in the viewer become stores (a model built into a cache); `None`:
    /// only stores are opened ([`opening::Opener::stores_only`]).
    pub opener: Option<opening::Opener>,
    /// Keep the resident geometry within the memory budget by coarsening (`--fit-memory`), for
    /// a scene opened after the start (the starting scene is set up by the caller).
    pub fit_memory: bool,
}

/// What a viewer session did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewReport {
    pub frames: u64,
    pub screenshot: Option<PathBuf>,
    pub last_triangles: u64,
    /// Frames skipped while minimised (scripted runs count them).
    pub minimized_frames: u64,
    /// The window size of the last frame drawn.
    pub last_size: [u32; 2],
    /// Ray traced: samples per pixel in the last frame's image (0 when rasterized).
    pub samples: u32,
}

/// Opens the window over `scene` and runs until it is closed (see the crate documentation).
pub fn run(scene: Scene, options: ViewOptions) -> Result<ViewReport, ViewError> {
    let event_loop = event_loop()?;
    let viewer = app::Viewer::with_scene(scene, options)?;
    run_viewer(event_loop, viewer)
}

/// Opens the window with no scene (`terawalk view` with no file): a hint and the open dialog,
/// or, with `open`, the progress window of that file's open in the background (a model being
/// built into the cache); the scene shows when the open ends. Until then only opening files,
/// the window screenshot and quitting do something (`app::empty`).
pub fn run_empty(options: ViewOptions, open: Option<&Path>) -> Result<ViewReport, ViewError> {
    let event_loop = event_loop()?;
    run_viewer(event_loop, app::Viewer::empty(options, open))
}

fn event_loop() -> Result<winit::event_loop::EventLoop<()>, ViewError> {
    winit::event_loop::EventLoop::new().map_err(|e| ViewError::Window(e.to_string()))
}

fn run_viewer(
    event_loop: winit::event_loop::EventLoop<()>,
    mut viewer: app::Viewer,
) -> Result<ViewReport, ViewError> {
    let result = event_loop.run_app(&mut viewer).map_err(|e| ViewError::Window(e.to_string()));
    viewer.finish();
    result?;
    viewer.result()
}
