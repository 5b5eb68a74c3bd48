//! The script's steps of a frame (`--script`, [`crate::script`]): keys, looks, resizes,
//! minimising, screenshots, opening files and the review steps, applied before the frame.

use winit::event_loop::ActiveEventLoop;
use winit::keyboard::KeyCode;

use crate::script::Step;
use crate::ui::Action;

use super::App;

impl App {
    /// Applies the script's steps for this frame (keys, look, resizes, minimising,
    /// screenshots); returns whether this frame is the script's last.
    pub(super) fn script_steps(&mut self, event_loop: &ActiveEventLoop) -> bool {
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
}
