//! The viewer's keys and toggles: the keyboard's dispatch ([`App::key`]), fullscreen,
//! playback, the debug view, the renderer and its flashlight, the light's keys, the
//! orthographic switch and the right click's pivot. The state they change lives in [`App`].

use winit::event_loop::ActiveEventLoop;
use winit::keyboard::KeyCode;

use crate::controller::{Controller, Mode};
use crate::debug_view;
use crate::fullscreen::Fullscreen;
use crate::pick::{camera_ray, Ray};
use crate::settings::{Coloring, LightKey, LightKind, RendererKind, SUN_STEP_DEG};
use crate::ui::Action;
use crate::viewpoints::Preset;

use super::App;

impl App {
    /// F11: borderless fullscreen on the window's monitor, or back; without a window manager
    /// to answer, the window covers the monitor itself ([`crate::fullscreen`]).
    pub(super) fn toggle_fullscreen(&mut self) {
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
    pub(super) fn check_fullscreen(&mut self) {
        let scripted = self.options.exit_after.is_some() || self.script.is_some();
        let (Some(f), Some(w)) = (self.fullscreen.as_mut(), self.win.as_ref()) else { return };
        if f.check(&w.window, self.frames, scripted) {
            self.say("fullscreen: no window manager answered; the window covers the monitor".into());
        }
    }

    /// Stops the recorded path playing, or plays it from its start.
    pub(super) fn toggle_playback(&mut self) {
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
    pub(super) fn toggle_debug_view(&mut self) {
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
    pub(super) fn toggle_renderer(&mut self) {
        let r = match self.settings.renderer {
            RendererKind::Raster => RendererKind::Rt,
            RendererKind::Rt => RendererKind::Raster,
        };
        self.settings.renderer = r;
        self.say(format!("renderer: {}", r.name()));
    }

    /// The flashlight on or off (it lights the ray-traced image only, which the message says).
    pub(super) fn toggle_flashlight(&mut self) {
        self.settings.flashlight = !self.settings.flashlight;
        let state = if self.settings.flashlight { "on" } else { "off" };
        let note = match self.settings.renderer {
            RendererKind::Rt => "",
            RendererKind::Raster => " (it lights the ray-traced image: G switches to rt)",
        };
        self.say(format!("flashlight {state}{note}"));
    }

    /// Carries out a light key and says what the light is now.
    pub(super) fn light_key(&mut self, key: LightKey) {
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
    pub(super) fn light_text(&self) -> String {
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
    pub(super) fn raster_only_note(&self) -> &'static str {
        match self.settings.renderer {
            RendererKind::Raster => "",
            RendererKind::Rt => "; the ray tracer still shows it (G: raster)",
        }
    }

    /// O: the orthographic view and back, keeping what is ahead framed (the orbit pivot, else
    /// the surface under the centre of the view, else the model's centre).
    pub(super) fn toggle_ortho(&mut self) {
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

    pub(super) fn key(&mut self, code: KeyCode, pressed: bool, repeat: bool, event_loop: &ActiveEventLoop) {
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
    pub(super) fn pick_pivot(&mut self) {
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
}
