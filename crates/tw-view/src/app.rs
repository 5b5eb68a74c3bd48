//! The viewer's event loop (winit 0.30 `ApplicationHandler`): it opens the window, routes input
//! to egui first and to the camera controller when egui does not want it, and on each redraw
//! moves the camera (or plays the path), lets [`crate::scene::Scene`] select and draw, builds the
//! debug view's lines, runs the UI and presents. It redraws continuously only while something
//! moves (keys held, smoothing, playback, recording, a scripted run); otherwise it waits for
//! events, so an idle viewer costs nothing. Minimising (zero size) skips frames; closing or Esc
//! (with nothing picked or measured) ends the loop; errors end it and are returned from
//! [`crate::run`].
//!
//! Design review: a left click (press and release without dragging) picks the object under the
//! cursor ([`crate::pick::pick_triangle`]) and tints it, or, while measuring (M), adds a
//! measurement point snapped to a vertex, else an edge, within [`SNAP_PX`] pixels
//! ([`crate::snap`]), or with Shift+M from the plane of the first click's face
//! ([`crate::review::PlaneMeasure`]); Shift+T opens the model tree ([`crate::tree_panel`]),
//! whose rows select objects as a click does (the handlers are in [`review`]); H / I / Shift+H hide,
//! isolate, show all ([`crate::review::ObjectFilter`], which the scene honours when drawing and
//! picking); 4…9, 0 are the preset views (orthographic while the view is), O switches between
//! the perspective and a true orthographic camera (`tw_runtime::Projection`) that keeps what
//! is ahead at its size ([`Controller::set_orthographic`]; the wheel, in orbit mode the zoom,
//! changes its view height), F11 fullscreen (the window covers the monitor itself where no
//! window manager answers, [`crate::fullscreen`]), and named viewpoints are saved next to the store
//! ([`crate::viewpoints`]).
//!
//! Opening another file (Ctrl+O's dialog, a file dropped on the window, the script's `open` and
//! `drop`): [`switch`] starts it in the background and swaps the new scene in when it is ready.
//! With no scene at the start (`terawalk view` with no file), [`empty`] runs the window until
//! the first open ends, then hands it to [`App`].
//!
//! Ray tracing: G switches the renderer (raster / rt, [`crate::traced`]) and T the ray
//! tracer's flashlight; while the camera stands still the ray-traced image gathers samples, and
//! the scene asks for frames until it has them all ([`Scene::wants_redraw`]).
//!
//! Shadows of one light ([`crate::settings::ShadowControls`]): J turns them on and off; `[` and
//! `]` turn the sun around the up axis and Shift+`[` / `]` lower and raise it (held, they keep
//! turning: key repeats count), U leaves a point light at the eye (again: back to the sun). Each
//! says the light in the message line; the HUD's "shadows" line and the controls' "Shadows"
//! section show the last shadow stage's figures.

mod section;

use std::collections::HashSet;
use std::sync::Arc;
use std::time::Instant;

use tw_runtime::{Camera, StreamStats};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::collision::WalkCollision;
use crate::controller::{Controller, Input, Mode};
use crate::debug_view;
use crate::error::ViewError;
use crate::fullscreen::Fullscreen;
use crate::gfx::Gfx;
use crate::hud::{FrameTimes, HudFrame, Throughput};
use crate::model_tree::ModelTree;
use crate::pick::{camera_ray, Ray};
use crate::recorder::{Player, Recorder};
use crate::review::{Measure, MeasureKind, ObjectFilter, Picked, PlaneMeasure};
use crate::scene::{FrameInfo, Scene};
use crate::script::{ScriptRunner, Step};
use crate::settings::{Coloring, LightKey, LightKind, RendererKind, Settings, SUN_STEP_DEG};
use crate::snap::Snap;
use crate::tree_panel::{self, TreePanel};
use crate::ui::{self, Action, Line};
use crate::viewpoints::{Preset, Viewpoint, Viewpoints};
use crate::ViewOptions;

mod empty;
mod review;
mod switch;
mod window;

pub(crate) use empty::Viewer;

/// The most node boxes the debug view draws.
const MAX_BOXES: usize = 4000;

/// A measurement point snaps to a vertex, else an edge, of the picked triangle this close, in
/// window pixels.
pub const SNAP_PX: f32 = 8.0;

/// A left button released this close to where it went down is a click (pick), not a drag.
const CLICK_PX: f32 = 4.0;

/// The colour of the measurement's line and points (RGBA).
const MEASURE_COLOR: [u8; 4] = [255, 220, 40, 255];

/// What the last drawn frame was drawn from (culling and drawing cameras, settings, size in
/// pixels, the objects shown, the highlighted object): the scene is drawn again when it changes.
type DrawnKey = (Camera, Camera, Settings, [u32; 2], ObjectFilter, Option<u32>);

/// The window and what draws into it (made when the event loop resumes).
struct WindowState {
    window: Arc<Window>,
    gfx: Gfx,
    egui: egui_winit::State,
    /// The scene texture registered with egui-wgpu, and the target generation it shows.
    scene_tex: Option<(egui::TextureId, u64)>,
}

pub(crate) struct App {
    options: ViewOptions,
    scene: Scene,
    settings: Settings,
    win: Option<WindowState>,
    controller: Controller,
    /// Walk mode's collision (N: fly through).
    walker: WalkCollision,
    start_camera: Camera,
    frozen: Option<Camera>,
    player: Option<Player>,
    playing: bool,
    recorder: Option<Recorder>,
    keys: HashSet<KeyCode>,
    look: [f32; 2],
    scroll: f32,
    dragging: bool,
    cursor: Option<[f32; 2]>,
    last_time: Instant,
    /// The last frame asked for no next one (the loop then waited for events).
    idle: bool,
    started: Instant,
    times: FrameTimes,
    disk: Throughput,
    frames: u64,
    drawn_key: Option<DrawnKey>,
    message: Option<(String, Instant)>,
    /// A window screenshot (UI included) to take at the next present.
    window_shot: Option<std::path::PathBuf>,
    /// The `--script` being run.
    script: Option<ScriptRunner>,
    /// Minimised (by a script step, or a zero-size window): frames are skipped.
    minimized: bool,
    /// Design review: the objects drawn, the picked object and what the HUD says of it, the
    /// measurement and whether clicks measure (M).
    filter: ObjectFilter,
    picked: Option<Picked>,
    pick_lines: Vec<(String, String)>,
    measure: Measure,
    measuring: bool,
    /// What the last measurement point snapped to.
    snap: Option<Snap>,
    /// Whether clicks measure between points (M) or from a plane (Shift+M), and the latter.
    measure_kind: MeasureKind,
    plane: PlaneMeasure,
    /// The model tree (Shift+T), made from the object table when first opened, and its window.
    tree: Option<ModelTree>,
    tree_panel: TreePanel,
    /// Where the left button went down (its release near there is a click).
    press_at: Option<[f32; 2]>,
    /// The store's named viewpoints, read at first use.
    viewpoints: Option<Viewpoints>,
    /// F11's fullscreen while on.
    fullscreen: Option<Fullscreen>,
    /// Opening another file (dialog, drag and drop: [`crate::opening`]), and the file shown.
    opening: crate::opening::Opening,
    opened_file: std::path::PathBuf,
    /// The last clicked surface: point and unit normal (a section plane goes through it).
    section_pick: Option<(glam::Vec3, glam::Vec3)>,
    pub(crate) error: Option<ViewError>,
    pub(crate) report: crate::ViewReport,
}

impl App {
    pub(crate) fn new(scene: Scene, options: ViewOptions) -> Result<App, ViewError> {
        let player = match &options.path {
            Some(p) => Some(Player::new(p, scene.header())?),
            None => None,
        };
        let mut controller = Controller::new(&options.camera, &scene.scene_frame());
        controller.set_mode(options.mode, None);
        let walker = WalkCollision::new(&scene);
        let mut settings = options.settings.clone();
        settings.memory_budget = scene.memory_budget();
        let start_debug = settings.debug_view;
        settings.debug_view = false;
        let scripted = options.exit_after.is_some() || options.script.is_some();
        let playing = player.is_some() && (options.play || scripted);
        let script = options.script.clone().map(ScriptRunner::new);
        let opening = crate::opening::Opening::new(options.opener.clone());
        let opened_file = options.file.clone();
        let mut app = App {
            start_camera: options.camera,
            controller,
            walker,
            settings,
            player,
            playing,
            scene,
            options,
            win: None,
            frozen: None,
            recorder: None,
            keys: HashSet::new(),
            look: [0.0; 2],
            scroll: 0.0,
            dragging: false,
            cursor: None,
            last_time: Instant::now(),
            idle: true,
            started: Instant::now(),
            times: FrameTimes::default(),
            disk: Throughput::default(),
            frames: 0,
            drawn_key: None,
            message: None,
            window_shot: None,
            script,
            minimized: false,
            filter: ObjectFilter::default(),
            picked: None,
            pick_lines: Vec::new(),
            measure: Measure::default(),
            measuring: false,
            snap: None,
            measure_kind: MeasureKind::Point,
            plane: PlaneMeasure::default(),
            tree: None,
            tree_panel: TreePanel::default(),
            press_at: None,
            viewpoints: None,
            fullscreen: None,
            opening,
            opened_file,
            section_pick: None,
            error: None,
            report: Default::default(),
        };
        if start_debug {
            app.act(Action::ToggleDebugView);
        }
        if app.options.record.is_some() {
            app.recorder = Some(Recorder::default());
        }
        Ok(app)
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: ViewError) {
        tracing::error!("{e}");
        if self.error.is_none() {
            self.error = Some(e);
        }
        event_loop.exit();
    }

    fn say(&mut self, m: String) {
        tracing::info!("{m}");
        self.message = Some((m, Instant::now()));
    }

    fn open_window(&mut self, event_loop: &ActiveEventLoop) -> Result<(), ViewError> {
        self.win = Some(WindowState::open(event_loop, self.options.size, &self.options.title)?);
        self.attach_scene()
    }

    /// The scene onto the window's device (one device for the window, egui and the scene), and
    /// `--occlusion auto`'s choice on it.
    fn attach_scene(&mut self) -> Result<(), ViewError> {
        let gfx = &self.win.as_ref().expect("the window is open").gfx;
        self.scene.attach(
            gfx.device.clone(),
            gfx.queue.clone(),
            gfx.adapter.get_info(),
            gfx.adapter.get_downlevel_capabilities(),
        )?;
        if self.options.occlusion_auto {
            if let Some(o) = self.scene.fastest_occlusion() {
                self.settings.occlusion = o;
                tracing::info!("occlusion culling: {} (the fastest conservative strategy here)", o.name());
            }
        }
        Ok(())
    }

    /// Whether the next frame must follow at once.
    fn animating(&self) -> bool {
        self.options.exit_after.is_some()
            || self.script.is_some()
            || self.fullscreen.as_ref().is_some_and(Fullscreen::pending)
            || self.playing
            || self.recorder.is_some()
            || self.dragging
            || self.controller.is_moving()
            || self.scene.wants_redraw()
            || self.keys.iter().any(|k| {
                matches!(
                    k,
                    KeyCode::KeyW
                        | KeyCode::KeyA
                        | KeyCode::KeyS
                        | KeyCode::KeyD
                        | KeyCode::KeyQ
                        | KeyCode::KeyE
                        | KeyCode::ArrowUp
                        | KeyCode::ArrowDown
                        | KeyCode::ArrowLeft
                        | KeyCode::ArrowRight
                )
            })
    }

    fn input(&mut self, ground: Option<f32>) -> Input {
        let axis = |p: &[KeyCode], n: &[KeyCode], keys: &HashSet<KeyCode>| {
            (p.iter().any(|k| keys.contains(k)) as i32 - n.iter().any(|k| keys.contains(k)) as i32) as f32
        };
        let input = Input {
            forward: axis(
                &[KeyCode::KeyW, KeyCode::ArrowUp],
                &[KeyCode::KeyS, KeyCode::ArrowDown],
                &self.keys,
            ),
            right: axis(
                &[KeyCode::KeyD, KeyCode::ArrowRight],
                &[KeyCode::KeyA, KeyCode::ArrowLeft],
                &self.keys,
            ),
            up: axis(&[KeyCode::KeyE, KeyCode::PageUp], &[KeyCode::KeyQ, KeyCode::PageDown], &self.keys),
            fast: self.keys.contains(&KeyCode::ShiftLeft) || self.keys.contains(&KeyCode::ShiftRight),
            look: self.look,
            scroll: self.scroll,
            ground,
        };
        self.look = [0.0; 2];
        self.scroll = 0.0;
        input
    }

    /// Carries out a UI or key action.
    fn act(&mut self, a: Action) {
        match a {
            Action::Screenshot => {
                let p = self.timestamped("terawalk", "png");
                self.screenshot(&p);
            }
            Action::ToggleRecording => self.toggle_recording(),
            Action::TogglePlayback => self.toggle_playback(),
            Action::SetMode(m) => self.controller.set_mode(m, None),
            Action::ToggleDebugView => self.toggle_debug_view(),
            Action::ResetView => {
                self.frozen = None;
                self.settings.debug_view = false;
                self.controller = Controller::new(&self.start_camera, &self.scene.scene_frame());
            }
            Action::Hide => self.hide_picked(),
            Action::Isolate => self.isolate_picked(),
            Action::ShowAll => {
                self.filter.show_all();
                self.say("showing every object".into());
            }
            Action::ToggleMeasure => self.toggle_measure(MeasureKind::Point),
            Action::View(p) => {
                let ortho = self.controller.ortho_height.is_some();
                let cam = p.camera(self.scene.bounds(), self.scene.up(), self.controller.fovy, ortho);
                self.go_to(&cam);
                self.say(format!("view {}", p.name()));
            }
            Action::SaveView(name) => self.save_view(&name),
            Action::LoadView(name) => self.load_view(&name),
            Action::ToggleOrtho => self.toggle_ortho(),
            Action::ToggleRenderer => self.toggle_renderer(),
            Action::ToggleFlashlight => self.toggle_flashlight(),
            Action::ToggleShadows => self.light_key(LightKey::Toggle),
            Action::TogglePointLight => self.light_key(LightKey::PointAtEye(self.controller.eye)),
            Action::MovePointLight => {
                self.settings.shadows.point = self.controller.eye;
                self.say(format!("shadows: {}", self.light_text()));
            }
            Action::ToggleFullscreen => self.toggle_fullscreen(),
            Action::TogglePlaneMeasure => self.toggle_measure(MeasureKind::Plane),
            Action::ToggleTree => {
                let open = !self.tree_panel.open;
                self.open_tree(open);
            }
            Action::SelectObject(id) => self.pick_object(id, None),
            Action::FramePicked => self.frame_picked(),
            Action::Section(s) => self.section_step(s),
        }
    }

    /// F11: borderless fullscreen on the window's monitor, or back; without a window manager
    /// to answer, the window covers the monitor itself ([`crate::fullscreen`]).
    fn toggle_fullscreen(&mut self) {
        let Some(window) = self.win.as_ref().map(|w| w.window.clone()) else { return };
        match self.fullscreen.take() {
            Some(f) => {
                f.leave(&window);
                self.say("fullscreen off".into());
            }
            None => {
                self.fullscreen = Fullscreen::enter(&window, self.frames);
                let what =
                    if self.fullscreen.is_some() { "fullscreen" } else { "fullscreen: no monitor to fill" };
                self.say(what.into());
                window.request_redraw();
            }
        }
    }

    /// Once a frame while fullscreen was asked for: the fallback when no window manager
    /// answered.
    fn check_fullscreen(&mut self) {
        let scripted = self.options.exit_after.is_some() || self.script.is_some();
        let (Some(f), Some(w)) = (self.fullscreen.as_mut(), self.win.as_ref()) else { return };
        if f.check(&w.window, self.frames, scripted) {
            self.say("fullscreen: no window manager answered; the window covers the monitor".into());
        }
    }

    /// Stops the recorded path playing, or plays it from its start.
    fn toggle_playback(&mut self) {
        if self.playing {
            self.playing = false;
        } else if let Some(p) = self.player.as_mut() {
            p.rewind();
            self.playing = true;
        }
    }

    /// The debug view on: the camera frozen where it is (the cut is still selected and culled
    /// from it) and a third-person camera behind it, in the same mode; off: back to the frozen
    /// camera.
    fn toggle_debug_view(&mut self) {
        if let Some(f) = self.frozen.take() {
            self.settings.debug_view = false;
            self.controller = Controller::new(&f, &self.scene.scene_frame());
        } else {
            let f = self.controller.camera();
            self.frozen = Some(f);
            self.settings.debug_view = true;
            let mode = self.controller.mode;
            let third = debug_view::third_person(&f, self.controller.scene_size);
            self.controller = Controller::new(&third, &self.scene.scene_frame());
            if mode == Mode::Orbit {
                self.controller.set_mode(Mode::Orbit, Some(f.eye));
            }
        }
    }

    /// Switches between the rasterizer and the ray tracer.
    fn toggle_renderer(&mut self) {
        let r = match self.settings.renderer {
            RendererKind::Raster => RendererKind::Rt,
            RendererKind::Rt => RendererKind::Raster,
        };
        self.settings.renderer = r;
        self.say(format!("renderer: {}", r.name()));
    }

    /// The flashlight on or off (it lights the ray-traced image only, which the message says).
    fn toggle_flashlight(&mut self) {
        self.settings.flashlight = !self.settings.flashlight;
        let state = if self.settings.flashlight { "on" } else { "off" };
        let note = match self.settings.renderer {
            RendererKind::Rt => "",
            RendererKind::Raster => " (it lights the ray-traced image: G switches to rt)",
        };
        self.say(format!("flashlight {state}{note}"));
    }

    /// Carries out a light key and says what the light is now.
    fn light_key(&mut self, key: LightKey) {
        self.settings.shadows.press(key);
        // A frozen cut is drawn again without the shadow stage: its maps stay the last
        // selected frame's.
        let frozen = self.settings.lod_freeze && self.settings.renderer == RendererKind::Raster;
        let note =
            if frozen { "; the LOD cut is frozen: the shadows follow when L unfreezes it" } else { "" };
        let m = if self.settings.shadows.enabled {
            let keys = match self.settings.shadows.kind {
                LightKind::Sun => "[ ] turn, Shift+[ ] raise, U point light",
                LightKind::Point => "U back to the sun",
            };
            format!("shadows: {} ({keys}, J off){note}", self.light_text())
        } else {
            format!("shadows off (J on){note}")
        };
        self.say(m);
    }

    /// The light in words: the sun's angles, or the point light's position in input
    /// coordinates and the store's units.
    fn light_text(&self) -> String {
        let s = &self.settings.shadows;
        match s.kind {
            LightKind::Sun => {
                format!("sun at azimuth {:.0}°, elevation {:.0}°", s.azimuth_deg, s.elevation_deg)
            }
            LightKind::Point => {
                let [x, y, z] = self.scene.input_position(s.point).map(tw_runtime::pathgen::format_length);
                let units = tw_store::units::unit_suffix(self.scene.units());
                format!("point light at ({x}, {y}, {z}) {units}")
            }
        }
    }

    /// Said with hide and isolate while ray tracing, which traces every object.
    fn raster_only_note(&self) -> &'static str {
        match self.settings.renderer {
            RendererKind::Raster => "",
            RendererKind::Rt => "; the ray tracer still shows it (G: raster)",
        }
    }

    /// O: the orthographic view and back, keeping what is ahead framed (the orbit pivot, else
    /// the surface under the centre of the view, else the model's centre).
    fn toggle_ortho(&mut self) {
        if self.controller.mode == Mode::Walk && self.controller.ortho_height.is_none() {
            self.say("orthographic view: not in walk mode (1 fly, 3 orbit)".into());
            return;
        }
        let c = &self.controller;
        let focus = if c.mode == Mode::Orbit {
            c.distance
        } else {
            let ray = Ray { origin: c.eye, dir: c.forward() };
            let (lo, hi) = self.scene.bounds();
            let to_centre = ((lo + hi) * 0.5 - c.eye).dot(c.forward()).max(c.scene_size * 0.01);
            self.scene.pick(&ray, f32::MAX).unwrap_or(to_centre)
        };
        if self.controller.ortho_height.is_none() {
            self.controller.set_orthographic(true, focus);
            self.say("orthographic view (O: perspective)".into());
        } else {
            self.controller.set_orthographic(false, focus);
            self.say("perspective view".into());
        }
    }

    /// Moves the camera to `cam`, keeping the mode and speeds (orbit: around `cam`'s target).
    fn go_to(&mut self, cam: &Camera) {
        self.frozen = None;
        self.settings.debug_view = false;
        self.playing = false;
        let old = &self.controller;
        let mut k = Controller::new(cam, &self.scene.scene_frame());
        k.speed = old.speed;
        k.walk_speed = old.walk_speed;
        if cam.is_orthographic() {
            // The perspective to return to (O) stays the viewer's.
            k.fovy = old.fovy;
        }
        match old.mode {
            Mode::Orbit => k.set_mode(Mode::Orbit, Some(cam.target)),
            m => k.mode = m,
        }
        self.controller = k;
    }

    /// The viewpoints, read from the store's file at first use (a bad file is reported and
    /// left alone: saving then starts a new list only after the user is told).
    fn viewpoints(&mut self) -> Result<&mut Viewpoints, String> {
        if self.viewpoints.is_none() {
            let file = self.scene.views_file().to_path_buf();
            self.viewpoints = Some(Viewpoints::load(&file).map_err(|e| e.to_string())?);
        }
        Ok(self.viewpoints.as_mut().expect("loaded above"))
    }

    /// Saves the camera as viewpoint `name` in the store's viewpoints file.
    fn save_view(&mut self, name: &str) {
        let c = &self.controller;
        let mut cam = c.camera();
        if c.mode == Mode::Orbit {
            cam.target = c.pivot;
        }
        let v = Viewpoint::from_camera(name, &cam, c.fovy, self.scene.header().grid_origin);
        let file = self.scene.views_file().to_path_buf();
        let result = self.viewpoints().and_then(|list| {
            list.set(v);
            list.save(&file).map_err(|e| e.to_string())
        });
        match result {
            Ok(()) => {
                self.say(format!("viewpoint `{name}` saved to {}: {}", file.display(), camera_text(&cam)))
            }
            Err(e) => self.say(format!("viewpoint `{name}` not saved: {e}")),
        }
    }

    /// Goes to the saved viewpoint `name`.
    fn load_view(&mut self, name: &str) {
        let origin = self.scene.header().grid_origin;
        let (bounds, up) = (self.scene.bounds(), self.scene.up());
        let cam = match self.viewpoints() {
            Ok(list) => list.get(name).map(|v| (v.camera(origin, bounds, up), v.fovy_radians())),
            Err(e) => {
                self.say(format!("viewpoint `{name}` not loaded: {e}"));
                return;
            }
        };
        match cam {
            Some((cam, fovy)) => {
                // A viewpoint saved in the orthographic view is one again; O returns to its
                // perspective.
                self.go_to(&cam);
                self.controller.fovy = fovy;
                let now = self.controller.camera();
                self.say(format!("viewpoint `{name}` restored: {}", camera_text(&now)));
            }
            None => self.say(format!("no viewpoint `{name}` in {}", self.scene.views_file().display())),
        }
    }

    /// The saved viewpoints' names (none when the file cannot be read).
    fn viewpoint_names(&mut self) -> Vec<String> {
        self.viewpoints().map(|l| l.views.iter().map(|v| v.name.clone()).collect()).unwrap_or_default()
    }

    /// `output_dir/PREFIX-<unix seconds>-<frame>.EXT`.
    fn timestamped(&self, prefix: &str, ext: &str) -> std::path::PathBuf {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        self.options.output_dir.join(format!("{prefix}-{secs}-{}.{ext}", self.frames))
    }

    /// R: starts recording, or saves the recording (`--record` or a timestamped file).
    fn toggle_recording(&mut self) {
        match self.recorder.take() {
            None => {
                self.recorder = Some(Recorder::default());
                self.say("recording the camera path (R to stop)".into());
            }
            Some(r) if r.is_empty() => self.say("nothing recorded".into()),
            Some(r) => {
                let path = r.finish();
                let file =
                    self.options.record.clone().unwrap_or_else(|| self.timestamped("terawalk-path", "json"));
                match path.save(&file) {
                    Ok(()) => {
                        self.say(format!("saved {} frames to {}", path.frames.len(), file.display()));
                        if let Ok(p) = Player::new(&path, self.scene.header()) {
                            self.player = Some(p);
                        }
                    }
                    Err(e) => self.say(format!("recording not saved: {e}")),
                }
            }
        }
    }

    /// At exit: a recording in progress is saved.
    pub(crate) fn finish(&mut self) {
        if let (Some((mean, max)), Some(tree)) = (self.tree_panel.cost(), &self.tree) {
            tracing::info!(
                "model tree: {} objects, {} rows shown at the end; the window took {mean:.3} ms per frame \
                 on average, {max:.3} ms at most, over {} frames",
                tree.objects(),
                tree.rows().len(),
                self.tree_panel.frames
            );
        }
        if self.recorder.is_some() {
            self.toggle_recording();
            if let Some((m, _)) = &self.message {
                eprintln!("{m}");
            }
        }
    }

    fn screenshot(&mut self, path: &std::path::Path) {
        match self.scene.read_image().and_then(|img| Ok(img.save_png(path)?)) {
            Ok(()) => {
                self.report.screenshot = Some(path.to_path_buf());
                self.say(format!("screenshot {}", path.display()));
            }
            Err(e) => self.say(format!("screenshot failed: {e}")),
        }
    }

    fn key(&mut self, code: KeyCode, pressed: bool, repeat: bool, event_loop: &ActiveEventLoop) {
        if !pressed {
            self.keys.remove(&code);
            return;
        }
        self.keys.insert(code);
        let shift = self.keys.contains(&KeyCode::ShiftLeft) || self.keys.contains(&KeyCode::ShiftRight);
        let ctrl = self.keys.contains(&KeyCode::ControlLeft) || self.keys.contains(&KeyCode::ControlRight);
        // The sun keys repeat while held: the shadows sweep as the sun turns.
        if let KeyCode::BracketLeft | KeyCode::BracketRight = code {
            let step = if code == KeyCode::BracketLeft { -SUN_STEP_DEG } else { SUN_STEP_DEG };
            let (azimuth_deg, elevation_deg) = if shift { (0.0, step) } else { (step, 0.0) };
            self.light_key(LightKey::TurnSun { azimuth_deg, elevation_deg });
            return;
        }
        if repeat {
            return;
        }
        match code {
            _ if self.section_key(code, shift) => {}
            KeyCode::Escape if self.opening.browser.is_some() || self.opening.failure.is_some() => {
                self.opening.browser = None;
                self.opening.failure = None;
                self.say("closed the open dialog (Esc again quits)".into());
            }
            KeyCode::Escape if self.measuring || self.picked.is_some() => {
                self.measuring = false;
                self.clear_measure();
                self.picked = None;
                self.pick_lines.clear();
                self.say("cleared the pick and the measurement (Esc again quits)".into());
            }
            KeyCode::Escape => event_loop.exit(),
            KeyCode::KeyH if shift => self.act(Action::ShowAll),
            KeyCode::KeyH => self.act(Action::Hide),
            KeyCode::KeyI => self.act(Action::Isolate),
            KeyCode::KeyM if shift => self.act(Action::TogglePlaneMeasure),
            KeyCode::KeyM => self.act(Action::ToggleMeasure),
            KeyCode::KeyN => {
                self.walker.fly_through = !self.walker.fly_through;
                let m = if self.walker.fly_through {
                    "walk: fly through walls"
                } else {
                    "walk: walls stop the walker"
                };
                self.say(m.into());
            }
            KeyCode::KeyO if ctrl => self.show_open_dialog(),
            KeyCode::KeyO => self.act(Action::ToggleOrtho),
            KeyCode::F11 => self.act(Action::ToggleFullscreen),
            KeyCode::Digit4 => self.act(Action::View(Preset::PosX)),
            KeyCode::Digit5 => self.act(Action::View(Preset::NegX)),
            KeyCode::Digit6 => self.act(Action::View(Preset::PosY)),
            KeyCode::Digit7 => self.act(Action::View(Preset::NegY)),
            KeyCode::Digit8 => self.act(Action::View(Preset::PosZ)),
            KeyCode::Digit9 => self.act(Action::View(Preset::NegZ)),
            KeyCode::Digit0 => self.act(Action::View(Preset::Iso)),
            KeyCode::F1 => self.settings.show_help = !self.settings.show_help,
            KeyCode::F12
                if self.keys.contains(&KeyCode::ShiftLeft) || self.keys.contains(&KeyCode::ShiftRight) =>
            {
                self.window_shot = Some(self.timestamped("terawalk-window", "png"));
            }
            KeyCode::F12 => self.act(Action::Screenshot),
            KeyCode::Digit1 => self.act(Action::SetMode(Mode::Fly)),
            KeyCode::Digit2 => self.act(Action::SetMode(Mode::Walk)),
            KeyCode::Digit3 => self.act(Action::SetMode(Mode::Orbit)),
            KeyCode::KeyF => self.act(Action::ToggleDebugView),
            KeyCode::KeyL => self.settings.lod_freeze = !self.settings.lod_freeze,
            KeyCode::KeyR => self.act(Action::ToggleRecording),
            KeyCode::KeyG => self.act(Action::ToggleRenderer),
            KeyCode::KeyT if shift => self.act(Action::ToggleTree),
            KeyCode::KeyT => self.act(Action::ToggleFlashlight),
            KeyCode::KeyJ => self.act(Action::ToggleShadows),
            KeyCode::KeyU => self.act(Action::TogglePointLight),
            KeyCode::KeyP => self.act(Action::TogglePlayback),
            KeyCode::Home => self.act(Action::ResetView),
            KeyCode::Tab => {
                let show = !(self.settings.show_hud || self.settings.show_controls);
                self.settings.show_hud = show;
                self.settings.show_controls = show;
            }
            KeyCode::KeyC => {
                let i = Coloring::ALL.iter().position(|c| *c == self.settings.coloring).unwrap_or(0);
                self.settings.coloring = Coloring::ALL[(i + 1) % Coloring::ALL.len()];
            }
            _ => {}
        }
    }

    /// Right click: orbit around the point under the cursor.
    fn pick_pivot(&mut self) {
        let (Some([x, y]), Some(w)) = (self.cursor, &self.win) else { return };
        let size = w.window.inner_size();
        let cam = self.controller.camera();
        let ray = camera_ray(&cam, x, y, size.width as f32, size.height as f32);
        match self.scene.pick(&ray, cam.far) {
            Some(t) => {
                self.controller.set_mode(Mode::Orbit, Some(ray.at(t)));
                self.say(format!("orbiting around the point {:.2} away", t));
            }
            None => self.say("nothing under the cursor to orbit around".into()),
        }
    }

    /// Applies the script's steps for this frame (keys, look, resizes, minimising,
    /// screenshots); returns whether this frame is the script's last.
    fn script_steps(&mut self, event_loop: &ActiveEventLoop) -> bool {
        let Some(runner) = self.script.as_mut() else { return false };
        if !self.opening.busy() {
            runner.open_finished();
        }
        let steps = runner.next_frame();
        if let Some(k) = steps.release {
            self.key(k, false, false, event_loop);
        }
        if let Some(k) = steps.hold {
            self.key(k, true, false, event_loop);
        }
        for step in steps.instant {
            match step {
                Step::Press(k) => {
                    self.key(k, true, false, event_loop);
                    self.key(k, false, false, event_loop);
                }
                Step::PressShifted(k) => {
                    let held = self.keys.contains(&KeyCode::ShiftLeft);
                    self.key(KeyCode::ShiftLeft, true, false, event_loop);
                    self.key(k, true, false, event_loop);
                    self.key(k, false, false, event_loop);
                    if !held {
                        self.key(KeyCode::ShiftLeft, false, false, event_loop);
                    }
                }
                Step::Click(x, y) => {
                    self.cursor = Some([x, y]);
                    self.click();
                }
                Step::View(p) => self.act(Action::View(p)),
                Step::SaveView(name) => self.save_view(&name),
                Step::LoadView(name) => self.load_view(&name),
                Step::Look(dx, dy) => {
                    self.look[0] += dx;
                    self.look[1] += dy;
                }
                Step::Scroll(lines) => self.scroll += lines,
                Step::Resize(width, height) => {
                    if let Some(w) = self.win.as_mut() {
                        // Applied now when the window system grants it at once, else when its
                        // Resized event comes.
                        if let Some(s) =
                            w.window.request_inner_size(winit::dpi::PhysicalSize::new(width, height))
                        {
                            w.gfx.resize(s.width, s.height);
                        }
                    }
                    self.say(format!("script: resize to {width}×{height}"));
                }
                Step::Minimize => {
                    if let Some(w) = self.win.as_mut() {
                        w.window.set_minimized(true);
                        // The zero-size path, whatever the window system does with the request.
                        w.gfx.resize(0, 0);
                    }
                    self.minimized = true;
                }
                Step::Restore => {
                    if let Some(w) = self.win.as_mut() {
                        w.window.set_minimized(false);
                        let s = w.window.inner_size();
                        w.gfx.resize(s.width, s.height);
                    }
                    self.minimized = false;
                }
                // The scene as the last frame drew it (before this frame's steps act).
                Step::Screenshot(p) => self.screenshot(&p),
                Step::WindowScreenshot(p) => self.window_shot = Some(p),
                Step::PressCtrl(k) => {
                    self.key(KeyCode::ControlLeft, true, false, event_loop);
                    self.key(k, true, false, event_loop);
                    self.key(k, false, false, event_loop);
                    self.key(KeyCode::ControlLeft, false, false, event_loop);
                }
                Step::Open(p) => self.open_file(&p),
                Step::Drop(p) => self.dropped(p),
                Step::Measure(kind) => self.set_measure(kind),
                Step::Tree(t) => self.tree_step(t),
                Step::Section(s) => self.section_step(s),
                Step::Wait(_) | Step::Hold(..) | Step::WaitOpen(_) => {
                    unreachable!("frame steps are not instant")
                }
            }
        }
        steps.last
    }

    /// One frame, in named steps: the script's steps, the camera, the scene, the lines over it,
    /// the HUD and UI, the present, then the count of frames (a scripted run may end here) and
    /// whether the next frame must follow at once.
    fn redraw(&mut self, event_loop: &ActiveEventLoop) -> Result<(), ViewError> {
        let dt = self.frame_time();
        self.finish_open()?;
        // The script's steps first: a resize it asks for may apply at once.
        let last_step = self.script_steps(event_loop);
        self.check_fullscreen();
        let Some(size) = self.win.as_ref().map(|w| w.window.inner_size()) else { return Ok(()) };
        if self.minimized || size.width == 0 || size.height == 0 {
            self.skip_frame(event_loop, last_step);
            return Ok(());
        }

        let draw = self.move_camera(dt);
        let cull = self.frozen.unwrap_or(draw);
        let px = self.draw_scene(cull, draw, size, dt)?;
        let info = self.scene.last_frame();
        let ss = self.scene.stream_stats();
        self.disk.push(self.started.elapsed().as_secs_f64(), self.scene.bytes_read());

        let review = self.review_lines();
        let viewpoint_names = self.viewpoint_names();
        let lines = self.overlay_lines(&draw, px, size);
        self.update_scene_texture();
        let hud = self.hud_frame(&info, &ss);
        let (out, actions, opens) = self.run_ui(&hud, &lines, &review, &viewpoint_names);
        let repaint_now = self.present(out)?;
        for a in actions {
            self.act(a);
        }
        for a in opens {
            self.open_action(a);
        }

        if self.count_frame(event_loop, size, info.triangles, last_step)? {
            return Ok(());
        }
        self.idle = !self.animating();
        if repaint_now || self.animating() {
            if let Some(w) = &self.win {
                w.window.request_redraw();
            }
        }
        Ok(())
    }

    /// The seconds since the last frame, the time the camera moves by.
    fn frame_time(&mut self) -> f32 {
        let now = Instant::now();
        let mut dt = (now - self.last_time).as_secs_f32();
        self.last_time = now;
        if self.idle {
            // After waiting for events, the time since the last frame is not motion time.
            dt = dt.min(1.0 / 60.0);
        }
        dt
    }

    /// A frame while minimised: nothing to draw, but a script goes on counting frames (and
    /// ends on its last step).
    fn skip_frame(&mut self, event_loop: &ActiveEventLoop, last_step: bool) {
        if self.script.is_some() {
            self.frames += 1;
            self.report.frames = self.frames;
            self.report.minimized_frames += 1;
            if last_step {
                event_loop.exit();
            } else if let Some(w) = &self.win {
                w.window.request_redraw();
            }
        }
    }

    /// Moves the camera by `dt` seconds, along the path while one plays, else by the
    /// controller; records it while recording. Returns the camera to draw from.
    fn move_camera(&mut self, dt: f32) -> Camera {
        let draw = match self.play_path(dt) {
            Some(c) => {
                // The controller takes over from the path's camera when the path ends or stops.
                self.controller = {
                    let mut k = Controller::new(&c, &self.scene.scene_frame());
                    k.mode = self.controller.mode;
                    k.speed = self.controller.speed;
                    k.walk_speed = self.controller.walk_speed;
                    k
                };
                c
            }
            None => {
                // Colliding, the capsule finds the ground itself.
                let colliding = self.controller.mode == Mode::Walk
                    && !self.walker.fly_through
                    && self.scene.selection().is_some();
                let ground = if colliding { None } else { self.ground_below() };
                let input = self.input(ground);
                match self.walker.collider(&self.scene).filter(|_| colliding).as_mut() {
                    Some(c) => self.controller.update_with(dt, &input, Some(c)),
                    None => self.controller.update(dt, &input),
                }
                self.controller.camera()
            }
        };
        if let Some(r) = self.recorder.as_mut() {
            r.push(&draw, self.scene.header(), dt as f64);
        }
        draw
    }

    /// The path's next camera while a path plays: frame by frame in scripted runs (so that they
    /// are reproducible), else in real time. Playing stops at the path's end.
    fn play_path(&mut self, dt: f32) -> Option<Camera> {
        if !self.playing {
            return None;
        }
        let scripted = self.options.exit_after.is_some() || self.script.is_some();
        let p = self.player.as_mut().expect("playing needs a path");
        let camera = if scripted { p.step() } else { p.advance(dt as f64) };
        if camera.is_none() {
            self.playing = false;
            self.say("path finished".into());
        }
        camera
    }

    /// In walk mode, the height (along up) of the ground below the eye, found by casting a ray
    /// down ([`Input::ground`]); `None` in other modes or when the ray hits nothing.
    fn ground_below(&self) -> Option<f32> {
        if self.controller.mode != Mode::Walk {
            return None;
        }
        let c = &self.controller;
        let ray = Ray { origin: c.eye, dir: -c.up };
        self.scene.pick(&ray, c.scene_size).map(|t| c.eye.dot(c.up) - t)
    }

    /// Selects and draws the scene at the render scale when anything changed since the frame
    /// last drawn; returns the size of the scene image in pixels.
    fn draw_scene(
        &mut self,
        cull: Camera,
        draw: Camera,
        size: PhysicalSize<u32>,
        dt: f32,
    ) -> Result<[u32; 2], ViewError> {
        let scale = self.settings.render_scale.clamp(0.1, 1.0);
        let px = [((size.width as f32 * scale) as u32).max(1), ((size.height as f32 * scale) as u32).max(1)];
        if self.settings.memory_budget != self.scene.memory_budget() {
            self.scene.set_memory_budget(self.settings.memory_budget)?;
            self.drawn_key = None;
        }
        self.scene.set_filter(&self.filter);
        self.scene.set_highlight(self.picked.map(|p| p.object));
        let key = (cull, draw, self.settings.clone(), px, self.filter.clone(), self.picked.map(|p| p.object));
        // Drawn again while the last frame is not final (pages arriving, occlusion settling).
        let rendered = self.drawn_key.as_ref() != Some(&key) || self.scene.wants_redraw();
        if rendered {
            self.scene.frame(&cull, &draw, &self.settings, px)?;
            self.drawn_key = Some(key);
            self.times.push(dt);
        }
        Ok(px)
    }

    /// The lines drawn over the scene, in window points: the debug view's and the measurement's.
    fn overlay_lines(&self, draw: &Camera, px: [u32; 2], size: PhysicalSize<u32>) -> Vec<Line> {
        let w = self.win.as_ref().expect("redraw checked the window");
        let ppp = egui_winit::pixels_per_point(w.egui.egui_ctx(), &w.window);
        let view_size = [size.width as f32 / ppp, size.height as f32 / ppp];
        let mut lines = Vec::new();
        self.debug_view_lines(draw, px, view_size, &mut lines);
        self.measure_lines(draw, view_size, &mut lines);
        lines
    }

    /// In the debug view (the culling camera frozen): the frozen frustum, and the node boxes
    /// drawn and occluded when they are shown, as seen from the drawing camera.
    fn debug_view_lines(&self, draw: &Camera, px: [u32; 2], view_size: [f32; 2], lines: &mut Vec<Line>) {
        let Some(f) = &self.frozen else { return };
        let vp = draw.view_projection(view_size[0] / view_size[1]);
        let aspect = px[0] as f32 / px[1] as f32;
        let corners = debug_view::frustum_corners(f, aspect, Some(self.controller.scene_size * 0.5));
        let mut add = |segs: &[debug_view::Segment], color| {
            for s in segs {
                if let Some((a, b)) = debug_view::project_segment(&vp, *s, view_size) {
                    lines.push(Line { a, b, color });
                }
            }
        };
        add(&debug_view::frustum_edges(&corners), debug_view::FRUSTUM_COLOR);
        if self.settings.show_boxes {
            for (lo, hi) in self.scene.visible_node_boxes(MAX_BOXES) {
                add(&debug_view::box_edges(lo, hi), debug_view::VISIBLE_COLOR);
            }
            for (lo, hi) in self.scene.occluded_node_boxes(MAX_BOXES) {
                add(&debug_view::box_edges(lo, hi), debug_view::OCCLUDED_COLOR);
            }
        }
    }

    /// Registers the scene texture with egui-wgpu, again when the scene made it anew (a new
    /// generation), so that the UI shows the image just drawn.
    fn update_scene_texture(&mut self) {
        let w = self.win.as_mut().expect("redraw checked the window");
        if let Some((view, _, generation)) = self.scene.target() {
            match w.scene_tex {
                Some((_, g)) if g == generation => {}
                Some((id, _)) => {
                    w.gfx.egui.update_egui_texture_from_wgpu_texture(
                        &w.gfx.device,
                        view,
                        wgpu::FilterMode::Linear,
                        id,
                    );
                    w.scene_tex = Some((id, generation));
                }
                None => {
                    let id =
                        w.gfx.egui.register_native_texture(&w.gfx.device, view, wgpu::FilterMode::Linear);
                    w.scene_tex = Some((id, generation));
                }
            }
        }
    }

    /// What the HUD shows of this frame.
    fn hud_frame(&self, info: &FrameInfo, ss: &StreamStats) -> HudFrame {
        let w = self.win.as_ref().expect("redraw checked the window");
        let st = &info.stats;
        HudFrame {
            fps: self.times.fps(),
            frame_ms: self.times.times().last().unwrap_or(0.0) * 1e3,
            select_ms: info.select_ms,
            render_ms: info.render_ms,
            triangles: info.triangles,
            clusters: info.clusters,
            nodes_visible: st.nodes_visited.saturating_sub(st.nodes_culled_frustum + st.nodes_culled_lod),
            nodes_frustum_culled: st.nodes_culled_frustum,
            nodes_lod_culled: st.nodes_culled_lod,
            // Rays find the visible surface themselves: no occlusion culling when ray tracing.
            occlusion: match self.settings.renderer {
                RendererKind::Raster => self.settings.occlusion.name().to_string(),
                RendererKind::Rt => String::new(),
            },
            occlusion_tested: info.occlusion.tested,
            occlusion_culled: info.occlusion.culled,
            cull_ms: info.cull_ms,
            resident_bytes: ss.resident_bytes,
            memory_budget: self.scene.memory_budget(),
            tau_scale: ss.tau_scale,
            gpu_bytes: self.scene.gpu_bytes(),
            gpu_budget: self.scene.gpu_budget(),
            pages_loading: self.scene.pages_loading(),
            pages_failed: ss.failed_pages,
            disk_bytes_per_s: self.disk.per_second(),
            position: self.scene.input_position(self.controller.eye),
            speed: self.controller.active_speed() as f64,
            units: self.scene.units().to_string(),
            mode: format!(
                "{}{}{}{}{}",
                self.controller.mode.name(),
                if self.frozen.is_some() { ", debug view" } else { "" },
                if self.controller.ortho_height.is_some() { ", orthographic" } else { "" },
                if self.settings.lod_freeze { ", LOD frozen" } else { "" },
                if self.controller.mode == Mode::Walk {
                    format!(", {}", self.walker.status())
                } else {
                    String::new()
                }
            ),
            adapter: {
                let i = w.gfx.adapter.get_info();
                format!("{} ({:?})", i.name.split(" (").next().unwrap_or(&i.name), i.backend)
            },
            renderer: match self.settings.renderer {
                RendererKind::Raster => "raster".into(),
                RendererKind::Rt => format!(
                    "rt (CPU, {} threads), {}",
                    tw_rt::scene::StoreTracer::threads(),
                    if self.settings.flashlight { "flashlight (T)" } else { "headlight (T: flashlight)" }
                ),
            },
            samples: info.samples,
            max_samples: match self.settings.renderer {
                RendererKind::Raster => 0,
                RendererKind::Rt => crate::accumulate::MAX_SAMPLES,
            },
            light: if self.settings.shadows.enabled { self.light_text() } else { String::new() },
            shadow: (self.settings.renderer == RendererKind::Raster).then_some(info.shadow),
            cross_culling: self.settings.shadows.cross_culling,
        }
    }

    /// Runs the UI (HUD, panels, the scene image and the lines over it); returns egui's output
    /// and the actions the user asked for (applied after the present).
    fn run_ui(
        &mut self,
        hud: &HudFrame,
        lines: &[Line],
        review: &[(String, String)],
        viewpoints: &[String],
    ) -> (egui::FullOutput, Vec<Action>, Vec<crate::open_ui::OpenAction>) {
        if self.message.as_ref().is_some_and(|(_, t)| t.elapsed().as_secs_f32() > 4.0) {
            self.message = None;
        }
        let scene_box = self.scene_box();
        let w = self.win.as_mut().expect("redraw checked the window");
        let raw = w.egui.take_egui_input(&w.window);
        let view = ui::View {
            hud,
            times: &self.times,
            mode: self.controller.mode,
            recording: self.recorder.as_ref().map(|r| r.len()),
            playing: self.playing.then(|| {
                let p = self.player.as_ref().expect("playing");
                (p.position(), p.len())
            }),
            has_path: self.player.is_some(),
            message: self.message.as_ref().map(|(m, _)| m.as_str()),
            scene: w.scene_tex.map(|(id, _)| id),
            lines,
            review,
            measuring: self.measuring,
            measuring_plane: self.measuring && self.measure_kind == MeasureKind::Plane,
            viewpoints,
            scene_box,
        };
        let (mut actions, mut opens) = (Vec::new(), Vec::new());
        let (settings, opening) = (&mut self.settings, &mut self.opening);
        let (panel, tree) = (&mut self.tree_panel, &mut self.tree);
        let selected = self.picked.map(|p| p.object);
        let out = w.egui.egui_ctx().run_pass(raw, |ctx| {
            actions = ui::draw(ctx, settings, &view);
            if let Some(tree) = tree.as_mut() {
                actions.extend(tree_panel::draw(ctx, panel, tree, selected));
            }
            opens = crate::open_ui::draw(ctx, opening);
        });
        (out, actions, opens)
    }

    /// Presents the UI's output, taking the window screenshot when one is due; returns whether
    /// egui asks to be repainted at once.
    fn present(&mut self, out: egui::FullOutput) -> Result<bool, ViewError> {
        let w = self.win.as_mut().expect("redraw checked the window");
        let (repaint, said) = w.present_ui(out, self.window_shot.take())?;
        if let Some(m) = said {
            self.say(m);
        }
        Ok(repaint)
    }

    /// Counts the frame. Scripted runs stop after N frames (or at the script's last step) with
    /// a screenshot, the window's taken at frame N-1; returns whether the run ended here.
    fn count_frame(
        &mut self,
        event_loop: &ActiveEventLoop,
        size: PhysicalSize<u32>,
        triangles: u64,
        last_step: bool,
    ) -> Result<bool, ViewError> {
        self.frames += 1;
        if let (Some(n), Some(p)) = (self.options.exit_after, &self.options.window_screenshot) {
            if self.frames + 1 == n {
                self.window_shot = Some(p.clone());
            }
        }
        self.report.frames = self.frames;
        self.report.last_size = [size.width, size.height];
        if let Some(n) = self.options.exit_after.or(last_step.then_some(self.frames)) {
            if self.frames >= n {
                if let Some(p) = self.options.screenshot.clone() {
                    self.screenshot(&p);
                    if self.report.screenshot.is_none() {
                        return Err(ViewError::NoFrame(format!("cannot write {}", p.display())));
                    }
                }
                self.report.last_triangles = triangles;
                self.report.samples = self.scene.last_frame().samples;
                event_loop.exit();
                return Ok(true);
            }
        }
        Ok(false)
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.win.is_none() {
            if let Err(e) = self.open_window(event_loop) {
                self.fail(event_loop, e);
                return;
            }
        }
        if let Some(w) = &self.win {
            w.window.request_redraw();
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(w) = self.win.as_mut() else { return };
        let response = w.egui.on_window_event(&w.window, &event);
        if response.repaint {
            w.window.request_redraw();
        }
        let egui_pointer =
            w.egui.egui_ctx().egui_wants_pointer_input() || w.egui.egui_ctx().is_pointer_over_egui();
        let egui_keys = w.egui.egui_ctx().egui_wants_keyboard_input();
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                w.gfx.resize(size.width, size.height);
                w.window.request_redraw();
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw(event_loop) {
                    self.fail(event_loop, e);
                }
            }
            WindowEvent::KeyboardInput { event, .. } => {
                if let PhysicalKey::Code(code) = event.physical_key {
                    let pressed = event.state == ElementState::Pressed;
                    if !pressed || !egui_keys {
                        self.key(code, pressed, event.repeat, event_loop);
                    }
                }
                if let Some(w) = &self.win {
                    w.window.request_redraw();
                }
            }
            WindowEvent::MouseInput { state, button, .. } => {
                let pressed = state == ElementState::Pressed;
                match button {
                    MouseButton::Left if !pressed => {
                        self.dragging = false;
                        // Released where it went down: a click, not a drag.
                        let near = |a: [f32; 2], b: [f32; 2]| (a[0] - b[0]).hypot(a[1] - b[1]) <= CLICK_PX;
                        if let (Some(a), Some(b)) = (self.press_at.take(), self.cursor) {
                            if near(a, b) && !egui_pointer {
                                self.click();
                            }
                        }
                    }
                    MouseButton::Left if !egui_pointer => {
                        self.dragging = true;
                        self.press_at = self.cursor;
                    }
                    MouseButton::Right if pressed && !egui_pointer => self.pick_pivot(),
                    _ => {}
                }
                if let Some(w) = &self.win {
                    w.window.request_redraw();
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                let p = [position.x as f32, position.y as f32];
                if let (true, Some(last)) = (self.dragging, self.cursor) {
                    self.look[0] += p[0] - last[0];
                    self.look[1] += p[1] - last[1];
                    w.window.request_redraw();
                }
                self.cursor = Some(p);
            }
            WindowEvent::CursorLeft { .. } => self.cursor = None,
            WindowEvent::MouseWheel { delta, .. } if !egui_pointer => {
                self.scroll += match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                w.window.request_redraw();
            }
            WindowEvent::Focused(false) => self.keys.clear(),
            WindowEvent::HoveredFile(path) => {
                self.opening.hovered = Some(path);
                w.window.request_redraw();
            }
            WindowEvent::HoveredFileCancelled => {
                self.opening.hovered = None;
                w.window.request_redraw();
            }
            WindowEvent::DroppedFile(path) => self.dropped(path),
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        event_loop.set_control_flow(ControlFlow::Wait);
        if self.opening.busy() {
            // The progress window, ten times a second, while an open runs (and its end).
            let next = self.last_time + std::time::Duration::from_millis(100);
            if Instant::now() >= next {
                self.request_redraw();
            } else {
                event_loop.set_control_flow(ControlFlow::WaitUntil(next));
            }
        }
        if self.animating() {
            if let Some(w) = &self.win {
                w.window.request_redraw();
            }
        }
    }
}

/// A camera for messages: eye and view direction, scene space.
fn camera_text(c: &Camera) -> String {
    let d = c.direction();
    format!(
        "eye ({:.4}, {:.4}, {:.4}) looking ({:.4}, {:.4}, {:.4})",
        c.eye.x, c.eye.y, c.eye.z, d.x, d.y, d.z
    )
}
