//! The model tree's egui window (Shift+T): a search box, the hide / isolate / show all / frame
//! buttons (they act on the selected object, which is the picked one), and the rows of
//! [`ModelTree`] in a virtualised list (`ScrollArea::show_rows`: only the rows on screen are
//! laid out, whatever the number of objects). A click on a row selects its object as a pick in
//! the scene would; the `+` / `-` before a group (or its name) opens or closes it.

use std::time::Instant;

use crate::hud::count;
use crate::model_tree::ModelTree;
use crate::ui::Action;

/// The window's state besides the tree: open or not, a row to scroll to, the time the panel
/// took (for the cost figure the viewer logs when it ends).
#[derive(Clone, Debug, Default)]
pub struct TreePanel {
    pub open: bool,
    /// Scroll so that this row shows (after a pick or a scripted selection).
    pub scroll_to: Option<usize>,
    pub frames: u64,
    pub total_ms: f64,
    pub max_ms: f64,
}

impl TreePanel {
    /// Mean and largest time of the panel per frame drawn, in ms.
    pub fn cost(&self) -> Option<(f64, f64)> {
        (self.frames > 0).then(|| (self.total_ms / self.frames as f64, self.max_ms))
    }
}

/// Draws the window when open; returns the actions asked for (select, hide…).
pub fn draw(
    ctx: &egui::Context,
    panel: &mut TreePanel,
    tree: &mut ModelTree,
    selected: Option<u32>,
) -> Vec<Action> {
    let mut actions = Vec::new();
    if !panel.open {
        return actions;
    }
    let start = Instant::now();
    let mut open = true;
    let scroll_to = panel.scroll_to.take();
    egui::Window::new("Model tree (Shift+T)")
        .open(&mut open)
        .default_pos([8.0, 200.0])
        .default_size([280.0, 320.0])
        .show(ctx, |ui| {
            header(ui, tree, selected, &mut actions);
            ui.separator();
            rows(ui, tree, selected, scroll_to, &mut actions);
        });
    if !open {
        actions.push(Action::ToggleTree);
    }
    let ms = start.elapsed().as_secs_f64() * 1e3;
    panel.frames += 1;
    panel.total_ms += ms;
    panel.max_ms = panel.max_ms.max(ms);
    actions
}

/// The search box, the count of rows and the buttons.
fn header(ui: &mut egui::Ui, tree: &mut ModelTree, selected: Option<u32>, actions: &mut Vec<Action>) {
    let mut query = tree.query().to_string();
    let edit = egui::TextEdit::singleline(&mut query).hint_text("search names").desired_width(f32::INFINITY);
    if ui.add(edit).changed() {
        tree.set_query(&query);
    }
    let shown = if tree.is_searching() {
        format!("{} of {} objects match", count(tree.rows().len() as u64), count(tree.objects() as u64))
    } else {
        format!("{} objects", count(tree.objects() as u64))
    };
    ui.label(shown);
    ui.horizontal(|ui| {
        for (label, a) in
            [("hide", Action::Hide), ("isolate", Action::Isolate), ("frame", Action::FramePicked)]
        {
            if ui.add_enabled(selected.is_some(), egui::Button::new(label)).clicked() {
                actions.push(a);
            }
        }
        if ui.button("show all").clicked() {
            actions.push(Action::ShowAll);
        }
    });
}

/// The rows on screen, out of all of them.
fn rows(
    ui: &mut egui::Ui,
    tree: &mut ModelTree,
    selected: Option<u32>,
    scroll_to: Option<usize>,
    actions: &mut Vec<Action>,
) {
    let row_h = ui.spacing().interact_size.y;
    let mut area = egui::ScrollArea::vertical().auto_shrink([false, false]);
    if let Some(r) = scroll_to {
        area = area.vertical_scroll_offset((r as f32 - 3.0).max(0.0) * (row_h + ui.spacing().item_spacing.y));
    }
    let mut toggled = None;
    area.show_rows(ui, row_h, tree.rows().len(), |ui, range| {
        for &n in &tree.rows()[range] {
            let node = tree.node(n);
            ui.horizontal(|ui| {
                ui.set_height(row_h);
                if !tree.is_searching() {
                    ui.add_space(node.depth as f32 * 12.0);
                    if node.children.is_empty() {
                        ui.add_space(ui.spacing().icon_width);
                    } else if ui.small_button(if tree.is_expanded(n) { "-" } else { "+" }).clicked() {
                        toggled = Some(n);
                    }
                }
                let label = match (tree.is_searching(), node.object) {
                    (true, Some(o)) => tree.name(o).unwrap_or_default().to_string(),
                    _ => node.label.clone(),
                };
                let label = match node.object {
                    Some(o) => format!("{label}  #{o}"),
                    None => label,
                };
                let response = ui.selectable_label(node.object.is_some() && node.object == selected, label);
                if response.clicked() {
                    match node.object {
                        Some(o) => actions.push(Action::SelectObject(o)),
                        None => toggled = Some(n),
                    }
                }
            });
        }
    });
    if let Some(n) = toggled {
        tree.toggle(n);
    }
}
