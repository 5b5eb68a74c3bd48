//! Where the camera goes and what the viewer keeps of it: moving to a camera, named and
//! preset viewpoints, recording the walk and screenshots.

use tw_runtime::Camera;

use crate::controller::{Controller, Mode};
use crate::recorder::{Player, Recorder};
use crate::viewpoints::{Viewpoint, Viewpoints};

use super::{camera_text, App};

impl App {
    /// Moves the camera to `cam`, keeping the mode and speeds (orbit: around `cam`'s target).
    pub(super) fn go_to(&mut self, cam: &Camera) {
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
    pub(super) fn viewpoints(&mut self) -> Result<&mut Viewpoints, String> {
        if self.viewpoints.is_none() {
            let file = self.scene.views_file().to_path_buf();
            self.viewpoints = Some(Viewpoints::load(&file).map_err(|e| e.to_string())?);
        }
        Ok(self.viewpoints.as_mut().expect("loaded above"))
    }

    /// Saves the camera as viewpoint `name` in the store's viewpoints file.
    pub(super) fn save_view(&mut self, name: &str) {
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
    pub(super) fn load_view(&mut self, name: &str) {
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
    pub(super) fn viewpoint_names(&mut self) -> Vec<String> {
        self.viewpoints().map(|l| l.views.iter().map(|v| v.name.clone()).collect()).unwrap_or_default()
    }

    /// `output_dir/PREFIX-<unix seconds>-<frame>.EXT`.
    pub(super) fn timestamped(&self, prefix: &str, ext: &str) -> std::path::PathBuf {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        self.options.output_dir.join(format!("{prefix}-{secs}-{}.{ext}", self.frames))
    }

    /// R: starts recording, or saves the recording (`--record` or a timestamped file).
    pub(super) fn toggle_recording(&mut self) {
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

    pub(super) fn screenshot(&mut self, path: &std::path::Path) {
        match self.scene.read_image().and_then(|img| Ok(img.save_png(path)?)) {
            Ok(()) => {
                self.report.screenshot = Some(path.to_path_buf());
                self.say(format!("screenshot {}", path.display()));
            }
            Err(e) => self.say(format!("screenshot failed: {e}")),
        }
    }
}
