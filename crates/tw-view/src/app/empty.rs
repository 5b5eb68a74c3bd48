//! The viewer before a scene is opened (`terawalk view` with no file, or with a model the cache
//! lacks, built in the background): the window shows its plain background, a hint, the open
//! dialog (or the build's progress window) and the message line, and does nothing that needs a
//! scene — there is no camera to move, nothing to pick, draw, record or screenshot. When an
//! open finishes, [`Viewer`] turns into the full viewer ([`App`]) on the same window, with the
//! script, the frame count and the opening state carried over, and the camera at the new
//! scene's start view (as [`super::switch`] does for a scene replacing another).
//!
//! Keeping this state apart (rather than an optional scene inside [`App`]) leaves every
//! scene-dependent path of the viewer as it is: none of them can run without a scene.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

use egui::{Align2, Color32, FontId};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::WindowId;

use super::{App, WindowState};
use crate::error::ViewError;
use crate::open_ui::OpenAction;
use crate::opening::{Opened, Opening};
use crate::scene::Scene;
use crate::script::{ScriptRunner, Step};
use crate::{ViewOptions, ViewReport};

/// What the empty window says.
pub const HINT: &str = "Open a model or store: Ctrl+O, or drop a file here";

/// The viewer's event loop handler: without a scene until one is opened, then the full viewer.
pub(crate) enum Viewer {
    Empty(Box<Empty>),
    Scene(Box<App>),
}

impl Viewer {
    /// The viewer over `scene`.
    pub(crate) fn with_scene(scene: Scene, options: ViewOptions) -> Result<Viewer, ViewError> {
        Ok(Viewer::Scene(Box::new(App::new(scene, options)?)))
    }

    /// The viewer with no scene: opening `open` at once in the background, else showing the
    /// open dialog.
    pub(crate) fn empty(options: ViewOptions, open: Option<&Path>) -> Viewer {
        Viewer::Empty(Box::new(Empty::new(options, open)))
    }

    /// At exit: a recording in progress is saved.
    pub(crate) fn finish(&mut self) {
        if let Viewer::Scene(app) = self {
            app.finish();
        }
    }

    /// The session's report, or its first error.
    pub(crate) fn result(&mut self) -> Result<ViewReport, ViewError> {
        let (error, report) = match self {
            Viewer::Empty(e) => (e.error.take(), &e.report),
            Viewer::Scene(a) => (a.error.take(), &a.report),
        };
        match error {
            Some(e) => Err(e),
            None => Ok(report.clone()),
        }
    }

    /// The scene just opened in place of the empty window.
    fn open_scene(&mut self, event_loop: &ActiveEventLoop, opened: Opened) {
        let Viewer::Empty(e) = self else { return };
        match App::from_empty(e, opened) {
            Ok(app) => {
                app.request_redraw();
                *self = Viewer::Scene(Box::new(app));
            }
            Err(err) => {
                tracing::error!("{err}");
                e.error = Some(err);
                event_loop.exit();
            }
        }
    }
}

impl ApplicationHandler for Viewer {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        match self {
            Viewer::Empty(e) => e.resumed(event_loop),
            Viewer::Scene(a) => a.resumed(event_loop),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, id: WindowId, event: WindowEvent) {
        let opened = match self {
            Viewer::Empty(e) => e.window_event(event_loop, event),
            Viewer::Scene(a) => {
                a.window_event(event_loop, id, event);
                None
            }
        };
        if let Some(o) = opened {
            self.open_scene(event_loop, o);
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        match self {
            Viewer::Empty(e) => e.about_to_wait(event_loop),
            Viewer::Scene(a) => a.about_to_wait(event_loop),
        }
    }
}

/// The window with no scene (see the module documentation).
pub(crate) struct Empty {
    options: ViewOptions,
    win: Option<WindowState>,
    opening: Opening,
    script: Option<ScriptRunner>,
    /// The keys held (Ctrl+O, Shift+F12).
    keys: HashSet<KeyCode>,
    message: Option<(String, Instant)>,
    window_shot: Option<PathBuf>,
    frames: u64,
    last_frame: Instant,
    error: Option<ViewError>,
    report: ViewReport,
}

impl Empty {
    fn new(options: ViewOptions, open: Option<&Path>) -> Empty {
        let mut e = Empty {
            opening: Opening::new(options.opener.clone()),
            script: options.script.clone().map(ScriptRunner::new),
            options,
            win: None,
            keys: HashSet::new(),
            message: None,
            window_shot: None,
            frames: 0,
            last_frame: Instant::now(),
            error: None,
            report: ViewReport::default(),
        };
        match open {
            Some(p) => e.open_file(p),
            None => e.show_open_dialog(),
        }
        e
    }

    fn say(&mut self, m: String) {
        tracing::info!("{m}");
        self.message = Some((m, Instant::now()));
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: ViewError) {
        tracing::error!("{e}");
        self.error.get_or_insert(e);
        event_loop.exit();
    }

    fn request_redraw(&self) {
        if let Some(w) = &self.win {
            w.window.request_redraw();
        }
    }

    fn open_file(&mut self, path: &Path) {
        match self.opening.start(path) {
            Ok(()) => self.say(format!("opening {}", path.display())),
            Err(e) => self.say(e),
        }
        self.request_redraw();
    }

    /// The open dialog over the working folder (or the folder of the file being opened).
    fn show_open_dialog(&mut self) {
        if self.opening.browser.is_some() {
            return;
        }
        let file = &self.options.file;
        let dir = file.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let opener = self.opening.opener().clone();
        self.opening.browser = Some(crate::browser::FileBrowser::new(dir, &|p: &Path| opener.accepts(p)));
        self.request_redraw();
    }

    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.win.is_none() {
            let title = if self.options.title.is_empty() { "no scene" } else { &self.options.title };
            match WindowState::open(event_loop, self.options.size, title) {
                Ok(w) => self.win = Some(w),
                Err(e) => return self.fail(event_loop, e),
            }
        }
        self.request_redraw();
    }

    /// Routes an event to egui and handles what concerns the empty window; returns the scene
    /// when an open finished at this redraw.
    fn window_event(&mut self, event_loop: &ActiveEventLoop, event: WindowEvent) -> Option<Opened> {
        let w = self.win.as_mut()?;
        let response = w.egui.on_window_event(&w.window, &event);
        if response.repaint {
            w.window.request_redraw();
        }
        let egui_keys = w.egui.egui_ctx().egui_wants_keyboard_input();
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                w.gfx.resize(size.width, size.height);
                w.window.request_redraw();
            }
            WindowEvent::RedrawRequested => match self.redraw(event_loop) {
                Ok(opened) => return opened,
                Err(e) => self.fail(event_loop, e),
            },
            WindowEvent::KeyboardInput { event, .. } => {
                if let PhysicalKey::Code(code) = event.physical_key {
                    let pressed = event.state == ElementState::Pressed;
                    if !pressed || !egui_keys {
                        self.key(code, pressed, event_loop);
                    }
                }
                self.request_redraw();
            }
            WindowEvent::HoveredFile(path) => {
                self.opening.hovered = Some(path);
                w.window.request_redraw();
            }
            WindowEvent::HoveredFileCancelled => {
                self.opening.hovered = None;
                w.window.request_redraw();
            }
            WindowEvent::DroppedFile(path) => {
                self.opening.hovered = None;
                self.open_file(&path);
            }
            _ => {}
        }
        None
    }

    /// The keys of the empty window: Ctrl+O the dialog, Esc closes it (or its error window),
    /// else quits, Shift+F12 the window screenshot; F12 says there is no scene to take, and the
    /// others need a scene.
    fn key(&mut self, code: KeyCode, pressed: bool, event_loop: &ActiveEventLoop) {
        if !pressed {
            self.keys.remove(&code);
            return;
        }
        self.keys.insert(code);
        let ctrl = self.keys.contains(&KeyCode::ControlLeft) || self.keys.contains(&KeyCode::ControlRight);
        match code {
            KeyCode::KeyO if ctrl => self.show_open_dialog(),
            KeyCode::Escape if self.opening.browser.is_some() || self.opening.failure.is_some() => {
                self.opening.browser = None;
                self.opening.failure = None;
                self.say("closed the open dialog (Esc again quits)".into());
            }
            KeyCode::Escape => event_loop.exit(),
            KeyCode::F12
                if self.keys.contains(&KeyCode::ShiftLeft) || self.keys.contains(&KeyCode::ShiftRight) =>
            {
                let secs = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map(|d| d.as_secs())
                    .unwrap_or(0);
                let name = format!("terawalk-window-{secs}-{}.png", self.frames);
                self.window_shot = Some(self.options.output_dir.join(name));
            }
            KeyCode::F12 => self.say("screenshot: no scene yet (open a model or store first)".into()),
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        event_loop.set_control_flow(ControlFlow::Wait);
        let scripted = self.options.exit_after.is_some() || self.script.is_some();
        if scripted {
            self.request_redraw();
        } else if self.opening.busy() {
            // The progress window, ten times a second, while an open runs (and its end).
            let next = self.last_frame + std::time::Duration::from_millis(100);
            if Instant::now() >= next {
                self.request_redraw();
            } else {
                event_loop.set_control_flow(ControlFlow::WaitUntil(next));
            }
        }
    }

    /// One frame: a finished open ends the empty window (returned); else the script's steps,
    /// the UI, the present and the count of frames (a scripted run may end here).
    fn redraw(&mut self, event_loop: &ActiveEventLoop) -> Result<Option<Opened>, ViewError> {
        self.last_frame = Instant::now();
        match self.opening.poll() {
            Some(Ok(opened)) => return Ok(Some(opened)),
            Some(Err(f)) => {
                tracing::warn!("cannot open {}: {}", f.path.display(), f.error);
                self.say(format!("cannot open {}: {}", f.path.display(), f.error));
            }
            None => {}
        }
        let last_step = self.script_steps(event_loop);
        let Some(size) = self.win.as_ref().map(|w| w.window.inner_size()) else { return Ok(None) };
        if size.width > 0 && size.height > 0 {
            let (out, opens) = self.run_ui();
            let w = self.win.as_mut().expect("checked above");
            let (repaint, said) = w.present_ui(out, self.window_shot.take())?;
            if let Some(m) = said {
                self.say(m);
            }
            for a in opens {
                self.open_action(a);
            }
            if repaint {
                self.request_redraw();
            }
        }
        self.count_frame(event_loop, size, last_step)?;
        Ok(None)
    }

    /// The hint, the message line and the opening UI (dialog, progress, errors) over the
    /// window's plain background.
    fn run_ui(&mut self) -> (egui::FullOutput, Vec<OpenAction>) {
        if self.message.as_ref().is_some_and(|(_, t)| t.elapsed().as_secs_f32() > 4.0) {
            self.message = None;
        }
        let w = self.win.as_mut().expect("redraw checked the window");
        let raw = w.egui.take_egui_input(&w.window);
        let (opening, message) = (&mut self.opening, self.message.as_ref().map(|(m, _)| m.as_str()));
        let mut opens = Vec::new();
        let out = w.egui.egui_ctx().run_pass(raw, |ctx| {
            hint(ctx);
            if let Some(m) = message {
                egui::Area::new(egui::Id::unique("terawalk message"))
                    .anchor(Align2::CENTER_BOTTOM, [0.0, -12.0])
                    .show(ctx, |ui| {
                        egui::Frame::popup(ui.style()).show(ui, |ui| ui.label(m));
                    });
            }
            opens = crate::open_ui::draw(ctx, opening);
        });
        (out, opens)
    }

    fn open_action(&mut self, a: OpenAction) {
        match a {
            OpenAction::ShowDialog => self.show_open_dialog(),
            OpenAction::Open(p) => self.open_file(&p),
            OpenAction::Cancel => {
                if let Some(p) = self.opening.cancel() {
                    self.say(format!("stopped waiting for {} (a build goes on into the cache)", p.display()));
                }
            }
        }
    }

    /// The script's steps for this frame: those that open files, press keys, resize or take
    /// a window screenshot act; those that need a scene are said to do nothing. Returns
    /// whether this frame is the script's last.
    fn script_steps(&mut self, event_loop: &ActiveEventLoop) -> bool {
        let Some(runner) = self.script.as_mut() else { return false };
        if !self.opening.busy() {
            runner.open_finished();
        }
        let steps = runner.next_frame();
        for step in steps.instant {
            match step {
                Step::Press(k) => self.press(&[k], event_loop),
                Step::PressShifted(k) => self.press(&[KeyCode::ShiftLeft, k], event_loop),
                Step::PressCtrl(k) => self.press(&[KeyCode::ControlLeft, k], event_loop),
                Step::Open(p) => self.open_file(&p),
                Step::Drop(p) => self.open_file(&p),
                Step::WindowScreenshot(p) => self.window_shot = Some(p),
                Step::Resize(width, height) => {
                    if let Some(w) = self.win.as_mut() {
                        if let Some(s) =
                            w.window.request_inner_size(winit::dpi::PhysicalSize::new(width, height))
                        {
                            w.gfx.resize(s.width, s.height);
                        }
                    }
                }
                Step::Screenshot(p) => {
                    let m = format!("screenshot {}: no scene yet (open a model or store first)", p.display());
                    tracing::warn!("{m}");
                    self.message = Some((m, Instant::now()));
                }
                Step::Wait(_) | Step::Hold(..) | Step::WaitOpen(_) => {
                    unreachable!("frame steps are not instant")
                }
                other => self.say(format!("script: {other:?} needs a scene (none is open yet)")),
            }
        }
        steps.last
    }

    /// Presses `keys` in order and releases them in reverse (a key with its modifiers).
    fn press(&mut self, keys: &[KeyCode], event_loop: &ActiveEventLoop) {
        for k in keys {
            self.key(*k, true, event_loop);
        }
        for k in keys.iter().rev() {
            self.key(*k, false, event_loop);
        }
    }

    /// Counts the frame; a scripted run ends after N frames or at its last step (a
    /// `--screenshot` asked for is then an error: there is no scene to take it of).
    fn count_frame(
        &mut self,
        event_loop: &ActiveEventLoop,
        size: winit::dpi::PhysicalSize<u32>,
        last_step: bool,
    ) -> Result<(), ViewError> {
        self.frames += 1;
        if let (Some(n), Some(p)) = (self.options.exit_after, &self.options.window_screenshot) {
            if self.frames + 1 == n {
                self.window_shot = Some(p.clone());
            }
        }
        self.report.frames = self.frames;
        self.report.last_size = [size.width, size.height];
        let Some(n) = self.options.exit_after.or(last_step.then_some(self.frames)) else { return Ok(()) };
        if self.frames < n {
            return Ok(());
        }
        event_loop.exit();
        match &self.options.screenshot {
            Some(p) => Err(ViewError::NoFrame(format!(
                "no scene was opened: nothing to write to {} (open a model or store first)",
                p.display()
            ))),
            None => Ok(()),
        }
    }
}

/// The hint, in the upper part of the window (the dialog takes its middle).
fn hint(ctx: &egui::Context) {
    let screen = ctx.content_rect();
    let painter = ctx.layer_painter(egui::LayerId::background());
    let at = egui::pos2(screen.center().x, screen.min.y + 20.0);
    painter.text(at, Align2::CENTER_CENTER, HINT, FontId::proportional(16.0), Color32::from_gray(40));
}

impl App {
    /// The full viewer over the store just opened, on the empty window's window, with its
    /// script, frame count, messages and opening state (see the module documentation).
    fn from_empty(e: &mut Empty, opened: Opened) -> Result<App, ViewError> {
        let (scene, requested) =
            super::switch::scene_for(opened, e.options.settings.memory_budget, e.options.fit_memory)?;
        // The script runs on from where it is, not from its start.
        let options = ViewOptions { script: None, file: requested.clone(), ..e.options.clone() };
        let mut app = App::new(scene, options)?;
        app.win = e.win.take();
        app.attach_scene()?;
        app.script = e.script.take();
        app.opening = std::mem::replace(&mut e.opening, Opening::new(None));
        app.window_shot = e.window_shot.take();
        app.frames = e.frames;
        app.report = std::mem::take(&mut e.report);
        app.last_time = e.last_frame;
        app.reset_for_new_scene();
        app.announce_opened(requested);
        Ok(app)
    }
}
