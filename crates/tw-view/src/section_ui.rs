//! The HUD's "Section" panel: the section tool's planes (each with a slider that moves it
//! across the scene, flip and remove), the box (six sliders), and buttons that add planes and
//! boxes. The sliders edit the [`SectionTool`] in place; the buttons that need the app's state
//! (the pick, the eye) are returned as [`Action::Section`] steps.

use crate::section_tool::{SceneBox, SectionStep, SectionTool};
use crate::ui::Action;

/// The panel's content.
pub fn panel(ui: &mut egui::Ui, tool: &mut SectionTool, scene: SceneBox, actions: &mut Vec<Action>) {
    let mut step = |s: SectionStep| actions.push(Action::Section(s));
    ui.checkbox(&mut tool.enabled, "section on (K; Shift+K clears)");
    ui.horizontal(|ui| {
        for (axis, name) in ["+X", "+Y", "+Z"].iter().enumerate() {
            if ui.button(format!("plane {name}")).clicked() {
                step(SectionStep::Axis(axis, 0.5));
            }
        }
        if ui.button("at pick (X)").clicked() {
            step(SectionStep::Picked);
        }
    });
    for i in 0..tool.planes.len() {
        plane_row(ui, tool, i, scene, &mut step);
    }
    ui.horizontal(|ui| {
        if ui.button("box: scene (B)").clicked() {
            step(SectionStep::Box([0.0; 3], [1.0; 3]));
        }
        if ui.button("box: picked").clicked() {
            step(SectionStep::BoxPicked);
        }
        if tool.boxed.is_some() && ui.button("no box").clicked() {
            tool.boxed = None;
        }
    });
    if let Some((lo, hi)) = &mut tool.boxed {
        box_sliders(ui, lo, hi, scene);
    }
}

/// Plane `i`: its slider (the offset over the range the scene box spans along the normal),
/// flip and remove.
fn plane_row(
    ui: &mut egui::Ui,
    tool: &mut SectionTool,
    i: usize,
    scene: SceneBox,
    step: &mut impl FnMut(SectionStep),
) {
    let p = &mut tool.planes[i];
    let n = glam::DVec3::from_array(p.normal);
    let corners = (0..8).map(|k| {
        let pick =
            |a: usize, bit: usize| if (k >> bit) & 1 == 1 { scene.max[a] } else { scene.min[a] } as f64;
        n.dot(glam::DVec3::new(pick(0, 0), pick(1, 1), pick(2, 2)))
    });
    let (lo, hi) = corners.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    ui.horizontal(|ui| {
        let label = format!("{} ({:.2}, {:.2}, {:.2})", i + 1, n.x, n.y, n.z);
        ui.add(egui::Slider::new(&mut p.offset, lo..=hi).text(label));
        if ui.small_button("flip").clicked() {
            step(SectionStep::Flip(i));
        }
        if ui.small_button("remove").clicked() {
            step(SectionStep::Remove(i));
        }
    });
}

/// The box's six sliders, each over the scene box's extent on its axis (min kept ≤ max).
fn box_sliders(ui: &mut egui::Ui, lo: &mut glam::Vec3, hi: &mut glam::Vec3, scene: SceneBox) {
    for (a, name) in ["x", "y", "z"].iter().enumerate() {
        let range = scene.min[a]..=scene.max[a];
        ui.add(egui::Slider::new(&mut lo[a], range.clone()).text(format!("box min {name}")));
        ui.add(egui::Slider::new(&mut hi[a], range).text(format!("box max {name}")));
        if lo[a] > hi[a] {
            std::mem::swap(&mut lo[a], &mut hi[a]);
        }
    }
}
