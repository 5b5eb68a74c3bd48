//! The egui user interface: the scene image in the background layer with the debug view's
//! lines over it, the HUD window (figures and the frame-time graph), the controls window (every
//! technique's switch, camera mode, recording and playback, and the "Shadows" section: the
//! light and the shadow stage's figures) and the F1 help overlay. It edits
//! [`Settings`] in place and returns the buttons pressed as [`Action`]s for the app to carry out.

use egui::{Color32, Pos2, Rect, Stroke};

use crate::controller::Mode;
use crate::hud::{FrameTimes, HudFrame};
use crate::settings::{
    Coloring, LightKind, Occlusion, RendererKind, Settings, ShadowControls, CASCADE_RANGE, GPU_MEMORY_RANGE,
    MAP_SIZES, MAX_ELEVATION_DEG, MEMORY_RANGE, MIN_ELEVATION_DEG, PIXEL_ERROR_RANGE,
};
use crate::viewpoints::Preset;

/// A button or key the app acts on.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Action {
    Screenshot,
    ToggleRecording,
    TogglePlayback,
    SetMode(Mode),
    ToggleDebugView,
    ResetView,
    /// Hide / isolate the picked object, show every object again.
    Hide,
    Isolate,
    ShowAll,
    /// Clicks measure (or pick) from now on.
    ToggleMeasure,
    View(Preset),
    /// The orthographic view and back.
    ToggleOrtho,
    /// Save the camera as / go to a named viewpoint.
    SaveView(String),
    LoadView(String),
    ToggleFullscreen,
    /// Raster ↔ ray traced, and the ray tracer's flashlight.
    ToggleRenderer,
    ToggleFlashlight,
    /// J: shadows on / off.
    ToggleShadows,
    /// U: a point light at the eye, or (a point light casting shadows) back to the sun.
    TogglePointLight,
    /// The point light moved to the eye.
    MovePointLight,
    /// Shift+M: clicks measure from a plane (the first click's face) from now on.
    TogglePlaneMeasure,
    /// Shift+T: the model tree's window.
    ToggleTree,
    /// A model tree row: select (pick) this object.
    SelectObject(u32),
    /// Move the camera to see the picked object's box.
    FramePicked,
    /// A section step (the "Section" panel's buttons; crate::section_tool).
    Section(crate::section_tool::SectionStep),
}

/// A 2D line in window points with its colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line {
    pub a: [f32; 2],
    pub b: [f32; 2],
    pub color: [u8; 4],
}

/// What the UI shows besides the settings.
pub struct View<'a> {
    pub hud: &'a HudFrame,
    pub times: &'a FrameTimes,
    pub mode: Mode,
    /// Frames recorded so far, while recording.
    pub recording: Option<usize>,
    /// (frame, frames) while a path plays.
    pub playing: Option<(usize, usize)>,
    /// Whether a path is loaded (playback possible).
    pub has_path: bool,
    pub message: Option<&'a str>,
    /// The scene image and its size in pixels.
    pub scene: Option<egui::TextureId>,
    pub lines: &'a [Line],
    /// The design-review lines of the HUD (pick, hidden objects, measurement).
    pub review: &'a [(String, String)],
    pub measuring: bool,
    /// Measuring from a plane (Shift+M) rather than between points.
    pub measuring_plane: bool,
    /// The store's named viewpoints.
    pub viewpoints: &'a [String],
    /// The scene's box (the "Section" panel's slider ranges).
    pub scene_box: crate::section_tool::SceneBox,
}

/// Keyboard help (F1).
pub const HELP: &[(&str, &str)] = &[
    ("W A S D", "move (fly, walk); orbit: W/S zoom, A/D turn"),
    ("Q / E", "down / up (fly)"),
    ("Shift", "four times faster"),
    ("left drag", "look around (orbit: turn around the pivot)"),
    ("right click", "orbit around the clicked point"),
    ("left click", "pick an object: name, id, triangles, box, point (tinted orange)"),
    ("H / I", "hide / isolate the picked object"),
    ("Shift+T", "model tree: search object names, select, hide / isolate / frame"),
    ("Shift+H", "show every object again"),
    ("M", "measure: click two points (snaps to a vertex, else an edge, within 8 px)"),
    ("Shift+M", "measure to a plane: click a face for the plane, then points (perpendicular distance)"),
    ("4 5 / 6 7 / 8 9", "views from +X −X / +Y −Y / +Z −Z"),
    ("0", "isometric view"),
    ("O", "orthographic / perspective view (orbit zoom: view height)"),
    ("F11", "fullscreen"),
    ("Ctrl+O / drop a file", "open a store or a model (built into the cache in the background)"),
    ("scroll wheel", "speed (fly, walk); distance (orbit); zoom in orthographic views"),
    ("1 / 2 / 3", "fly / walk / orbit"),
    ("N", "walk: fly through walls / collide with them (the HUD shows the collision's time)"),
    ("F", "debug view: freeze the culling camera, move a second one out"),
    ("L", "freeze the LOD cut"),
    ("C", "next debug colouring"),
    ("G", "renderer: raster / rt (CPU ray tracer; supersamples while the camera stands still)"),
    ("T", "rt: flashlight with hard shadows / headlight"),
    ("J", "shadows of one light on / off (shadow maps; rt: shadow rays)"),
    ("[ / ]", "turn the sun around the up axis, 5° a press (turns shadows on)"),
    ("Shift+[ / ]", "lower / raise the sun, 5° a press (1° to 90°)"),
    ("U", "point light at the eye, left there (walk away to see its shadows) / back to the sun"),
    ("", "rt: hide, isolate, LOD freeze and the debug view's culling camera act in raster only"),
    ("R", "start / stop recording a path"),
    ("P", "play / stop the loaded path"),
    ("Tab", "hide / show the panels"),
    ("Home", "back to the starting view"),
    ("F12", "screenshot of the 3D view (PNG); Shift+F12 the whole window"),
    ("F1", "this help"),
    ("X / Shift+X", "section plane through the picked surface (removes the eye's side) / remove the last"),
    ("V", "flip the last section plane"),
    (", / .", "move the last section plane back / forward"),
    ("B / Shift+B", "section box around the picked object (the scene when none) / no box"),
    ("K / Shift+K", "section on / off; clear every plane and the box (the Section panel has sliders)"),
    (
        "Esc",
        "close the open dialog or its error; clear the pick and the measurement; quit when there is none",
    ),
];

/// Builds this frame's UI.
pub fn draw(ctx: &egui::Context, settings: &mut Settings, view: &View) -> Vec<Action> {
    let mut actions = Vec::new();
    let screen = ctx.content_rect();
    let bg = ctx.layer_painter(egui::LayerId::background());
    if let Some(tex) = view.scene {
        bg.image(tex, screen, Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)), Color32::WHITE);
    }
    for l in view.lines {
        let [r, g, b, a] = l.color;
        bg.line_segment(
            [
                Pos2::new(l.a[0], l.a[1]) + screen.min.to_vec2(),
                Pos2::new(l.b[0], l.b[1]) + screen.min.to_vec2(),
            ],
            Stroke::new(1.0, Color32::from_rgba_unmultiplied(r, g, b, a)),
        );
    }
    if settings.show_hud {
        egui::Window::new("HUD").default_pos([8.0, 8.0]).resizable(false).show(ctx, |ui| hud(ui, view));
    }
    if settings.show_controls {
        egui::Window::new("Controls")
            .default_pos([screen.max.x - 290.0, 8.0])
            .default_width(270.0)
            .show(ctx, |ui| controls(ui, settings, view, &mut actions));
    }
    if settings.show_help {
        egui::Window::new("Keys (F1)")
            .collapsible(false)
            .anchor(egui::Align2::CENTER_CENTER, [0.0, 0.0])
            .show(ctx, |ui| {
                egui::Grid::new("help").striped(true).show(ui, |ui| {
                    for (k, what) in HELP {
                        ui.strong(*k);
                        ui.label(*what);
                        ui.end_row();
                    }
                });
            });
    }
    if let Some(m) = view.message {
        // An area per message: a kept one keeps the width of the first message it showed, and
        // longer ones then wrap into a narrow column over the middle of the scene.
        egui::Area::new(egui::Id::unique(("terawalk message", m)))
            .anchor(egui::Align2::CENTER_BOTTOM, [0.0, -12.0])
            .default_width((screen.width() - 24.0).max(100.0))
            .show(ctx, |ui| {
                ui.set_max_width((screen.width() - 24.0).max(100.0));
                egui::Frame::popup(ui.style()).show(ui, |ui| ui.label(m));
            });
    }
    actions
}

fn hud(ui: &mut egui::Ui, view: &View) {
    if view.hud.pages_failed > 0 {
        // Not one figure among many: the image lacks geometry, and the user must know.
        ui.colored_label(
            Color32::from_rgb(255, 90, 80),
            format!(
                "DAMAGED STORE: {} page(s) failed their checksum; their geometry is drawn coarser or missing",
                view.hud.pages_failed
            ),
        );
    }
    egui::Grid::new("hud").num_columns(2).show(ui, |ui| {
        for (k, v) in view.hud.lines() {
            ui.label(k);
            ui.monospace(v);
            ui.end_row();
        }
    });
    if !view.review.is_empty() {
        ui.separator();
        egui::Grid::new("review").num_columns(2).show(ui, |ui| {
            for (k, v) in view.review {
                ui.label(k);
                ui.monospace(v);
                ui.end_row();
            }
        });
    }
    ui.label("frame time (top = max(largest, 33 ms))");
    let (rect, _) = ui.allocate_exact_size(egui::vec2(240.0, 50.0), egui::Sense::hover());
    let p = ui.painter_at(rect);
    p.rect_filled(rect, 2.0, Color32::from_black_alpha(120));
    let pts: Vec<Pos2> = view
        .times
        .graph(rect.width(), rect.height())
        .into_iter()
        .map(|[x, y]| rect.min + egui::vec2(x, y))
        .collect();
    if pts.len() > 1 {
        p.add(egui::Shape::line(pts, Stroke::new(1.0, Color32::LIGHT_GREEN)));
    }
    if let Some(n) = view.recording {
        ui.colored_label(Color32::RED, format!("● recording, {n} frames"));
    }
    if let Some((i, n)) = view.playing {
        ui.colored_label(Color32::LIGHT_BLUE, format!("▶ playing frame {i} / {n}"));
    }
}

fn controls(ui: &mut egui::Ui, s: &mut Settings, view: &View, actions: &mut Vec<Action>) {
    ui.horizontal(|ui| {
        ui.label("camera");
        for m in [Mode::Fly, Mode::Walk, Mode::Orbit] {
            if ui.selectable_label(view.mode == m, m.name()).clicked() {
                actions.push(Action::SetMode(m));
            }
        }
    });
    ui.horizontal(|ui| {
        ui.label("renderer (G)");
        for r in RendererKind::ALL {
            ui.selectable_value(&mut s.renderer, r, r.name());
        }
        ui.add_enabled(
            s.renderer == RendererKind::Rt,
            egui::Checkbox::new(&mut s.flashlight, "flashlight (T)"),
        );
    });
    ui.add(egui::Slider::new(&mut s.pixel_error, PIXEL_ERROR_RANGE).logarithmic(true).text("pixel error"));
    egui::ComboBox::from_label("occlusion").selected_text(s.occlusion.name()).show_ui(ui, |ui| {
        for o in Occlusion::ALL {
            ui.selectable_value(&mut s.occlusion, o, o.name()).on_hover_text(o.description());
        }
    });
    ui.checkbox(&mut s.frustum_culling, "frustum culling");
    ui.checkbox(&mut s.lod_freeze, "freeze LOD cut (L)");
    let mut mib = (s.memory_budget >> 20).max(1);
    let (lo, hi) = (*MEMORY_RANGE.start() >> 20, *MEMORY_RANGE.end() >> 20);
    if ui.add(egui::Slider::new(&mut mib, lo..=hi).logarithmic(true).text("memory MiB")).changed() {
        s.memory_budget = mib << 20;
    }
    let mut gpu_mib = (s.gpu_budget >> 20).max(1);
    let (lo, hi) = ((*GPU_MEMORY_RANGE.start() >> 20).max(1), *GPU_MEMORY_RANGE.end() >> 20);
    if ui.add(egui::Slider::new(&mut gpu_mib, lo..=hi).logarithmic(true).text("GPU memory MiB")).changed() {
        s.gpu_budget = gpu_mib << 20;
    }
    egui::ComboBox::from_label("colour").selected_text(s.coloring.name()).show_ui(ui, |ui| {
        for c in Coloring::ALL {
            ui.selectable_value(&mut s.coloring, c, c.name());
        }
    });
    ui.add(egui::Slider::new(&mut s.render_scale, 0.25..=1.0).text("render scale"));
    egui::CollapsingHeader::new("Shadows (J)")
        .default_open(s.shadows.enabled)
        .show(ui, |ui| shadows(ui, &mut s.shadows, s.renderer, view, actions));
    egui::CollapsingHeader::new("Section (K)")
        .default_open(!s.section.planes.is_empty() || s.section.boxed.is_some())
        .show(ui, |ui| crate::section_ui::panel(ui, &mut s.section, view.scene_box, actions));
    ui.separator();
    let mut debug = s.debug_view;
    if ui.checkbox(&mut debug, "third-person debug view (F)").changed() {
        actions.push(Action::ToggleDebugView);
    }
    ui.checkbox(&mut s.show_boxes, "node boxes (pink visible, yellow occluded)");
    ui.separator();
    ui.horizontal(|ui| {
        let rec = if view.recording.is_some() { "stop recording" } else { "record (R)" };
        if ui.button(rec).clicked() {
            actions.push(Action::ToggleRecording);
        }
        let play = if view.playing.is_some() { "stop" } else { "play (P)" };
        if ui.add_enabled(view.has_path || view.playing.is_some(), egui::Button::new(play)).clicked() {
            actions.push(Action::TogglePlayback);
        }
    });
    ui.horizontal(|ui| {
        if ui.button("screenshot (F12)").clicked() {
            actions.push(Action::Screenshot);
        }
        if ui.button("reset view").clicked() {
            actions.push(Action::ResetView);
        }
        if ui.button("help (F1)").clicked() {
            s.show_help = !s.show_help;
        }
    });
    ui.separator();
    review(ui, view, actions);
}

/// The shadow controls (J, `[` `]`, U) and the last frame's shadow figures.
fn shadows(
    ui: &mut egui::Ui,
    s: &mut ShadowControls,
    renderer: RendererKind,
    view: &View,
    actions: &mut Vec<Action>,
) {
    let mut enabled = s.enabled;
    if ui.checkbox(&mut enabled, "shadows (J)").changed() {
        actions.push(Action::ToggleShadows);
    }
    ui.horizontal(|ui| {
        ui.label("light");
        if ui.selectable_label(s.kind == LightKind::Sun, "sun").clicked() {
            s.kind = LightKind::Sun;
        }
        let point = ui.selectable_label(s.kind == LightKind::Point, "point at the eye (U)");
        if point.clicked() && s.kind == LightKind::Sun {
            actions.push(Action::TogglePointLight);
        }
        if s.kind == LightKind::Point && ui.small_button("move to the eye").clicked() {
            actions.push(Action::MovePointLight);
        }
    });
    match s.kind {
        LightKind::Sun => {
            ui.add(egui::Slider::new(&mut s.azimuth_deg, 0.0..=360.0).suffix("°").text("sun azimuth ([ ])"));
            ui.add(
                egui::Slider::new(&mut s.elevation_deg, MIN_ELEVATION_DEG..=MAX_ELEVATION_DEG)
                    .suffix("°")
                    .text("sun elevation (Shift+[ ])"),
            );
        }
        LightKind::Point => {
            ui.label(&view.hud.light);
        }
    }
    if renderer == RendererKind::Rt {
        ui.label("ray traced: shadow rays (the map options apply to the rasterizer)");
    }
    ui.checkbox(&mut s.cross_culling, "cross-culling (lit / shadowed receivers skip the map)");
    let mut finer = s.lod == tw_frame::ShadowLod::Finer;
    if ui.checkbox(&mut finer, "finer of eye and light LOD (else the eye's)").changed() {
        s.lod = if finer { tw_frame::ShadowLod::Finer } else { tw_frame::ShadowLod::Eye };
    }
    ui.horizontal(|ui| {
        egui::ComboBox::from_label("map texels").selected_text(s.map_size.to_string()).show_ui(ui, |ui| {
            for n in MAP_SIZES {
                ui.selectable_value(&mut s.map_size, n, n.to_string());
            }
        });
        ui.add_enabled(
            s.kind == LightKind::Sun,
            egui::Slider::new(&mut s.cascades, CASCADE_RANGE).text("cascades"),
        );
    });
    let lines = view.hud.shadow_lines();
    if !lines.is_empty() {
        egui::Grid::new("shadow figures").num_columns(2).show(ui, |ui| {
            for (k, v) in lines {
                ui.label(k);
                ui.monospace(v);
                ui.end_row();
            }
        });
    }
}

/// The design-review controls: hide / isolate / show all, measuring, preset and named views.
fn review(ui: &mut egui::Ui, view: &View, actions: &mut Vec<Action>) {
    ui.horizontal(|ui| {
        for (label, a) in
            [("hide (H)", Action::Hide), ("isolate (I)", Action::Isolate), ("show all", Action::ShowAll)]
        {
            if ui.button(label).clicked() {
                actions.push(a);
            }
        }
        if ui.selectable_label(view.measuring && !view.measuring_plane, "measure (M)").clicked() {
            actions.push(Action::ToggleMeasure);
        }
        if ui.selectable_label(view.measuring_plane, "to plane (Shift+M)").clicked() {
            actions.push(Action::TogglePlaneMeasure);
        }
        if ui.button("tree (Shift+T)").clicked() {
            actions.push(Action::ToggleTree);
        }
    });
    ui.horizontal(|ui| {
        ui.label("view");
        for p in Preset::ALL {
            if ui.small_button(p.name()).clicked() {
                actions.push(Action::View(p));
            }
        }
        if ui.small_button("ortho (O)").clicked() {
            actions.push(Action::ToggleOrtho);
        }
    });
    ui.horizontal(|ui| {
        let id = egui::Id::unique("terawalk viewpoint name");
        let mut name = ui.data_mut(|d| d.get_temp::<String>(id)).unwrap_or_default();
        ui.add(egui::TextEdit::singleline(&mut name).desired_width(110.0).hint_text("viewpoint name"));
        let trimmed = name.trim().to_string();
        if ui.add_enabled(!trimmed.is_empty(), egui::Button::new("save view")).clicked() {
            actions.push(Action::SaveView(trimmed));
        }
        ui.data_mut(|d| d.insert_temp(id, name));
    });
    if !view.viewpoints.is_empty() {
        ui.horizontal_wrapped(|ui| {
            ui.label("go to");
            for v in view.viewpoints {
                if ui.small_button(v).clicked() {
                    actions.push(Action::LoadView(v.clone()));
                }
            }
        });
    }
}
