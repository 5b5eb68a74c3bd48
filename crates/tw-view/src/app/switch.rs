//! Switching the scene at run time: the open dialog, drag and drop and the script's `open` /
//! `drop` steps start an open ([`crate::opening`]); when it finishes, the new store replaces the
//! scene, and everything that belonged to the old one is reset (streamer and GPU pool, filter,
//! pick, measurement, the model tree, viewpoints, path, debug view), the camera goes to the new
//! scene's start view (its iso preset) and the controller takes its units and up axis. A failed
//! open leaves the scene as it was and shows why (the error window, and the message line).

use std::path::{Path, PathBuf};

use super::App;
use crate::controller::Controller;
use crate::error::ViewError;
use crate::hud::Throughput;
use crate::open_ui::OpenAction;
use crate::opening::Opened;
use crate::review::{Measure, ObjectFilter};
use crate::scene::Scene;
use crate::settings::ShadowControls;
use crate::viewpoints::Preset;

impl App {
    /// Starts opening `path` in the background (the dialog's Enter, a drop, `open PATH`).
    pub(super) fn open_file(&mut self, path: &Path) {
        match self.opening.start(path) {
            Ok(()) => self.say(format!("opening {}", path.display())),
            Err(e) => self.say(e),
        }
        self.request_redraw();
    }

    /// A file dropped on the window (winit's `DroppedFile`, or `drop PATH`).
    pub(super) fn dropped(&mut self, path: PathBuf) {
        self.opening.hovered = None;
        self.open_file(&path);
    }

    /// Ctrl+O, "Open…": the dialog over the folder of the file shown.
    pub(super) fn show_open_dialog(&mut self) {
        if self.opening.browser.is_some() {
            return;
        }
        let shown = self.opened_file.clone();
        let dir = shown.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let opener = self.opening.opener().clone();
        self.opening.browser = Some(crate::browser::FileBrowser::new(dir, &|p: &Path| opener.accepts(p)));
        self.request_redraw();
    }

    /// Carries out what the opening UI asked for.
    pub(super) fn open_action(&mut self, a: OpenAction) {
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

    /// At the start of a frame: a finished open replaces the scene, or says why it could not.
    pub(super) fn finish_open(&mut self) -> Result<(), ViewError> {
        match self.opening.poll() {
            None => Ok(()),
            Some(Ok(opened)) => self.replace_scene(opened),
            Some(Err(f)) => {
                tracing::warn!("cannot open {}: {}", f.path.display(), f.error);
                self.say(format!("cannot open {}: {}", f.path.display(), f.error));
                Ok(())
            }
        }
    }

    /// The new store in place of the scene (see the module documentation).
    fn replace_scene(&mut self, opened: Opened) -> Result<(), ViewError> {
        let Some(w) = self.win.as_mut() else { return Ok(()) };
        let (mut scene, requested) = scene_for(opened, self.scene.memory_budget(), self.scene.fit_memory())?;
        scene.attach(
            w.gfx.device.clone(),
            w.gfx.queue.clone(),
            w.gfx.adapter.get_info(),
            w.gfx.adapter.get_downlevel_capabilities(),
        )?;
        // The new scene's texture generations start again: egui must take its texture anew.
        w.scene_tex = w.scene_tex.map(|(id, _)| (id, u64::MAX));
        if self.recorder.is_some() {
            // Saved in the old scene's coordinates, which it was recorded in.
            self.toggle_recording();
        }
        self.scene = scene;
        self.reset_for_new_scene();
        self.announce_opened(requested);
        Ok(())
    }

    /// The window's title and the message line name the file just opened, which the open
    /// dialog starts from next time.
    pub(super) fn announce_opened(&mut self, requested: PathBuf) {
        let name = requested.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if let Some(w) = &self.win {
            w.window.set_title(&format!("terawalk — {name}"));
        }
        let (tris, objects) = (self.scene.header().input_triangles, self.scene.store().objects().len());
        self.say(format!("opened {} ({tris} triangles, {objects} objects)", requested.display()));
        self.opened_file = requested;
    }

    /// Forgets what belonged to the old scene and starts the camera at the new one's view.
    pub(super) fn reset_for_new_scene(&mut self) {
        self.frozen = None;
        self.settings.debug_view = false;
        self.settings.shadows = ShadowControls::for_up_axis(self.scene.header().up_axis.min(2));
        self.player = None;
        self.playing = false;
        self.filter = ObjectFilter::default();
        self.picked = None;
        self.pick_lines.clear();
        self.measure = Measure::default();
        self.measuring = false;
        self.plane = crate::review::PlaneMeasure::default();
        self.snap = None;
        // The tree lists the old store's objects: made again from the new one when next opened.
        self.tree = None;
        self.tree_panel = crate::tree_panel::TreePanel::default();
        self.viewpoints = None;
        self.drawn_key = None;
        self.disk = Throughput::default();
        self.walker = crate::collision::WalkCollision::new(&self.scene);
        let fovy = self.controller.fovy;
        let cam = Preset::Iso.camera(self.scene.bounds(), self.scene.up(), fovy, false);
        let mode = self.controller.mode;
        self.start_camera = cam;
        self.controller = Controller::new(&cam, &self.scene.scene_frame());
        self.controller.set_mode(mode, None);
    }

    pub(super) fn request_redraw(&self) {
        if let Some(w) = &self.win {
            w.window.request_redraw();
        }
    }
}

/// The scene of an opened store with the viewer's memory options, and the file asked for.
pub(super) fn scene_for(
    opened: Opened,
    memory_budget: u64,
    fit_memory: bool,
) -> Result<(Scene, PathBuf), ViewError> {
    let Opened { requested, store } = opened;
    let built = store.path() != requested.as_path();
    let mut scene = Scene::new(store, memory_budget);
    scene.set_fit_memory(fit_memory)?;
    if built {
        // Viewpoints belong to the model, not to a cache entry that may be evicted.
        scene.set_views_file(crate::viewpoints::views_file(&requested));
    }
    Ok((scene, requested))
}
