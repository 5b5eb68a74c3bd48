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
//!
//! Where the handlers are: this file holds the window's events, the frame and its parts;
//! [`controls`] the keys and toggles, [`steps`] the script's steps, [`views`] camera moves,
//! viewpoints, recording and screenshots, [`review`] picking, measuring and the model tree,
//! [`section`] the section planes, [`switch`] opening another file, [`empty`] the window with
//! no scene.

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
use crate::pick::Ray;
use crate::recorder::{Player, Recorder};
use crate::review::{Measure, MeasureKind, ObjectFilter, Picked, PlaneMeasure};
use crate::scene::{FrameInfo, Scene};
use crate::script::ScriptRunner;
use crate::settings::{LightKey, RendererKind, Settings};
use crate::snap::Snap;
use crate::tree_panel::{self, TreePanel};
use crate::ui::{self, Action, Line};
use crate::viewpoints::Viewpoints;
use crate::ViewOptions;

mod controls;
mod empty;
mod review;
mod steps;
mod switch;
mod views;
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
