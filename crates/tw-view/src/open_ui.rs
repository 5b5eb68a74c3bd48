//! The opening UI, in egui: the "Open…" button, the open dialog ([`crate::browser`]), the
//! build's progress window, the error window of an open that failed, and the "drop to open"
//! overlay while a file is dragged over the window. It only draws and reports what the user
//! asked for ([`OpenAction`]); the app carries it out.

use std::path::PathBuf;

use egui::{Align2, Color32, RichText};

use crate::browser::Submit;
use crate::opening::{JobView, Opening};

/// What the user asked for in the opening UI.
#[derive(Clone, Debug, PartialEq)]
pub enum OpenAction {
    /// Show the open dialog (the "Open…" button).
    ShowDialog,
    Open(PathBuf),
    /// Stop waiting for the running open.
    Cancel,
}

/// Draws the opening UI over the viewer's; returns what was asked for.
pub fn draw(ctx: &egui::Context, opening: &mut Opening) -> Vec<OpenAction> {
    let mut actions = Vec::new();
    open_button(ctx, opening, &mut actions);
    if let Some(job) = opening.job_view() {
        progress_window(ctx, &job, &mut actions);
    }
    failure_window(ctx, opening);
    dialog(ctx, opening, &mut actions);
    drop_overlay(ctx, opening);
    actions
}

/// "Open…" at the window's bottom left.
fn open_button(ctx: &egui::Context, opening: &Opening, actions: &mut Vec<OpenAction>) {
    egui::Area::new(egui::Id::unique("terawalk open button")).anchor(Align2::LEFT_BOTTOM, [8.0, -8.0]).show(
        ctx,
        |ui| {
            let b = ui.add_enabled(!opening.busy(), egui::Button::new("Open… (Ctrl+O)"));
            if b.clicked() {
                actions.push(OpenAction::ShowDialog);
            }
        },
    );
}

/// The running open: file, phase, bar, elapsed time and the phase's ETA, and Cancel.
fn progress_window(ctx: &egui::Context, job: &JobView, actions: &mut Vec<OpenAction>) {
    let name = job.file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    egui::Window::new(format!("Opening {name}"))
        .collapsible(false)
        .resizable(false)
        .anchor(Align2::CENTER_CENTER, [0.0, 0.0])
        .show(ctx, |ui| {
            ui.label(job.file.display().to_string());
            let p = &job.progress;
            let phase = if p.phase.is_empty() { "starting" } else { p.phase.as_str() };
            ui.label(format!("phase: {phase}"));
            let fraction = if p.total > 0 { (p.done as f32 / p.total as f32).min(1.0) } else { 0.0 };
            let text = match (p.total, p.unit.as_str()) {
                (0, _) => "…".to_string(),
                (t, "bytes") => format!("{} of {} MB", p.done >> 20, t >> 20),
                (t, u) => format!("{} of {t} {u}", p.done),
            };
            ui.add(egui::ProgressBar::new(fraction).text(text).desired_width(320.0).animate(p.total == 0));
            let eta = job.phase_eta.map(|e| format!(", phase ETA {:.0} s", e.as_secs_f64())).unwrap_or_default();
            ui.label(format!("elapsed {:.1} s{eta}", job.elapsed.as_secs_f64()));
            if ui.button("Cancel").clicked() {
                actions.push(OpenAction::Cancel);
            }
            ui.small("A build cannot be stopped halfway: Cancel stops waiting (the scene shown stays), and the build ends in the background into the cache.");
        });
}

/// The last open's error, until dismissed (the scene shown is the one before).
fn failure_window(ctx: &egui::Context, opening: &mut Opening) {
    let Some(f) = &opening.failure else { return };
    let mut dismissed = false;
    egui::Window::new("Cannot open")
        .collapsible(false)
        .resizable(false)
        .anchor(Align2::CENTER_TOP, [0.0, 40.0])
        .show(ctx, |ui| {
            ui.strong(f.path.display().to_string());
            ui.colored_label(Color32::from_rgb(255, 110, 100), f.error.as_str());
            ui.label("The scene shown (if any) is the one before.");
            dismissed = ui.button("OK").clicked();
        });
    if dismissed {
        opening.failure = None;
    }
}

/// The open dialog: the folder, its parent, the folders and openable files, and the path field.
fn dialog(ctx: &egui::Context, opening: &mut Opening, actions: &mut Vec<OpenAction>) {
    let accepts = opening.opener().clone();
    let accepts = |p: &std::path::Path| accepts.accepts(p);
    let Some(b) = opening.browser.as_mut() else { return };
    let mut open = true;
    let mut submit = None;
    egui::Window::new("Open")
        .open(&mut open)
        .collapsible(false)
        .default_size([420.0, 360.0])
        .anchor(Align2::CENTER_CENTER, [0.0, 0.0])
        .show(ctx, |ui| {
            ui.horizontal(|ui| {
                if ui.button("Parent folder").clicked() {
                    b.parent(&accepts);
                }
                ui.monospace(b.dir.display().to_string());
            });
            if let Some(e) = &b.error {
                ui.colored_label(Color32::from_rgb(255, 110, 100), e.as_str());
            }
            ui.separator();
            let mut clicked = None;
            egui::ScrollArea::vertical().max_height(240.0).show(ui, |ui| {
                for e in &b.entries {
                    let label = if e.is_dir {
                        RichText::new(format!("📁 {}/", e.name)).strong()
                    } else {
                        RichText::new(format!("{}  ({} kB)", e.name, e.bytes.div_ceil(1024)))
                    };
                    let r = ui.selectable_label(b.path_text == e.name, label);
                    if r.double_clicked() {
                        clicked = Some((e.path.clone(), true));
                    } else if r.clicked() {
                        clicked = Some((e.path.clone(), false));
                    }
                }
            });
            if let Some((path, activate)) = clicked {
                if activate {
                    submit = Some(b.activate(&path, &accepts));
                } else {
                    b.path_text =
                        path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
                }
            }
            ui.separator();
            ui.horizontal(|ui| {
                let field = ui.add(egui::TextEdit::singleline(&mut b.path_text).hint_text("file or folder"));
                let enter = field.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
                if ui.button("Open").clicked() || enter {
                    submit = Some(b.submit(&accepts));
                }
            });
        });
    match submit {
        Some(Submit::Open(p)) => actions.push(OpenAction::Open(p)),
        Some(Submit::Missing(m)) => b.error = Some(m),
        Some(Submit::Entered) | None => {}
    }
    if !open {
        opening.browser = None;
    }
}

/// A file dragged over the window: the whole window says it will be opened.
fn drop_overlay(ctx: &egui::Context, opening: &Opening) {
    let Some(p) = &opening.hovered else { return };
    let rect = ctx.content_rect();
    let painter = ctx.layer_painter(egui::LayerId::new(egui::Order::Foreground, egui::Id::unique("drop")));
    painter.rect_filled(rect, 0.0, Color32::from_black_alpha(150));
    let name = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    painter.text(
        rect.center(),
        Align2::CENTER_CENTER,
        format!("drop to open {name}"),
        egui::FontId::proportional(24.0),
        Color32::WHITE,
    );
}
