//! The app's side of the section tool ([`crate::section_tool`]): its keys, and the steps the
//! keys, the HUD's "Section" panel and `--script` ask for, carried out on the viewer's state
//! (the picked surface, the picked object's box, the eye).

use glam::Vec3;
use winit::keyboard::KeyCode;

use super::App;
use crate::section_tool::{SceneBox, SectionStep};

/// How far `,` and `.` move the last plane: a hundredth of the scene's diagonal.
const MOVE_STEP: f32 = 0.01;

impl App {
    /// The scene's box in scene space (what the steps' fractions refer to).
    pub(super) fn scene_box(&self) -> SceneBox {
        let (min, max) = self.scene.bounds();
        SceneBox { min, max }
    }

    /// The section keys: X a plane through the picked surface (Shift+X removes the last one),
    /// V flips the last plane, `,` / `.` move it, B a box around the picked object or the whole
    /// scene (Shift+B removes the box), K all on / off (Shift+K clears all). Whether `code` was
    /// one of them.
    pub(super) fn section_key(&mut self, code: KeyCode, shift: bool) -> bool {
        let last = self.settings.section.planes.len().saturating_sub(1);
        let step = match (code, shift) {
            (KeyCode::KeyX, false) => SectionStep::Picked,
            (KeyCode::KeyX, true) => SectionStep::Remove(last),
            (KeyCode::KeyV, _) => SectionStep::Flip(last),
            (KeyCode::Comma, _) => SectionStep::Move(last, -MOVE_STEP),
            (KeyCode::Period, _) => SectionStep::Move(last, MOVE_STEP),
            (KeyCode::KeyB, false) if self.picked.is_some() => SectionStep::BoxPicked,
            (KeyCode::KeyB, false) => SectionStep::Box([0.0; 3], [1.0; 3]),
            (KeyCode::KeyB, true) => {
                self.settings.section.boxed = None;
                self.say(format!("section: box removed; {}", self.settings.section.summary()));
                return true;
            }
            (KeyCode::KeyK, false) => SectionStep::Toggle,
            (KeyCode::KeyK, true) => SectionStep::Clear,
            _ => return false,
        };
        self.section_step(step);
        true
    }

    /// Carries out one section step and says what it did (or why not).
    pub(super) fn section_step(&mut self, step: SectionStep) {
        let said = self.apply_section_step(step);
        let summary = self.settings.section.summary();
        match said {
            Ok(what) => self.say(format!("section: {what}; {summary}")),
            Err(e) => self.say(format!("section: {e}")),
        }
    }

    fn apply_section_step(&mut self, step: SectionStep) -> Result<String, String> {
        let scene = self.scene_box();
        let tool = &mut self.settings.section;
        let plane = |i: usize| i + 1;
        Ok(match step {
            SectionStep::Axis(axis, f) => {
                let i = tool.add_axis_plane(axis, f, &scene)?;
                format!("plane {i} across {} at {f}", ["x", "y", "z"][axis.min(2)])
            }
            SectionStep::Picked => {
                let (point, normal) =
                    self.section_pick.ok_or("click a surface first (the plane goes through it)")?;
                let eye = self.controller.camera().eye;
                let i = self.settings.section.add_picked_plane(point, normal, eye, scene.diagonal())?;
                format!("plane {i} through the picked point")
            }
            SectionStep::Flip(i) => tool.flip(i).map(|_| format!("plane {} flipped", plane(i)))?,
            SectionStep::Move(i, f) => {
                tool.move_plane(i, f * scene.diagonal()).map(|_| format!("plane {} moved", plane(i)))?
            }
            SectionStep::Remove(i) => tool.remove(i).map(|_| format!("plane {} removed", plane(i)))?,
            SectionStep::Box(lo, hi) => {
                tool.set_box(scene.at(lo), scene.at(hi));
                "box set".into()
            }
            SectionStep::BoxPicked => {
                let id = self.picked.as_ref().ok_or("pick an object first")?.object;
                let (lo, hi) = self.scene.object_box(id).ok_or("the picked object is not in the cut")?;
                // A little margin, so that the object's own faces on the box are kept.
                let pad = Vec3::splat(1e-3 * scene.diagonal());
                self.settings.section.set_box(lo - pad, hi + pad);
                format!("box around object {id}")
            }
            SectionStep::Toggle => {
                tool.enabled = !tool.enabled;
                (if tool.enabled { "on" } else { "off" }).into()
            }
            SectionStep::Clear => {
                tool.clear();
                "cleared".into()
            }
        })
    }
}
