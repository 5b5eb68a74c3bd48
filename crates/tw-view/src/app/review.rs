//! Design review in the viewer: picking (a click, or a row of the model tree), measuring point
//! to point and point to plane with snapping ([`crate::snap`]), hiding and isolating the picked
//! object, and the model tree's window and steps ([`crate::model_tree`], [`crate::tree_panel`]).
//! The review's state lives in [`App`]; this module is its handlers.

use std::time::Instant;

use tw_runtime::Camera;

use crate::debug_view;
use crate::measure_draw;
use crate::model_tree::ModelTree;
use crate::pick::{camera_ray, TriangleHit};
use crate::review::{format_distance, Measure, MeasureKind, Picked, PlaneMeasure};
use crate::script::{TreeStep, TreeTarget};
use crate::snap::{snap_point, Screen, Snap};
use crate::ui::{Action, Line};
use crate::viewpoints::Preset;

use super::{App, MEASURE_COLOR, SNAP_PX};

impl App {
    /// Opens (making it at first use) or closes the model tree's window.
    pub(super) fn open_tree(&mut self, open: bool) {
        self.tree_panel.open = open;
        if open && self.tree.is_none() {
            let start = Instant::now();
            let names = self.scene.store().objects().iter().map(|o| o.name.clone()).collect();
            let tree = ModelTree::new(names);
            let ms = start.elapsed().as_secs_f64() * 1e3;
            self.say(format!("model tree: {} objects, made in {ms:.1} ms", tree.objects()));
            self.tree = Some(tree);
        }
        if let Some(p) = self.picked {
            self.follow_in_tree(p.object);
        }
    }

    /// Shows `object`'s row in the open model tree (opening its groups, scrolling to it).
    pub(super) fn follow_in_tree(&mut self, object: u32) {
        let Some(tree) = self.tree.as_mut().filter(|_| self.tree_panel.open) else { return };
        if !tree.is_searching() {
            tree.reveal(object);
        }
        self.tree_panel.scroll_to = tree.row_of(object);
    }

    /// Moves the camera to see the picked object's box (isometric, as the `0` view of it).
    pub(super) fn frame_picked(&mut self) {
        let Some(p) = self.picked else {
            self.say("nothing picked to frame (click an object or a tree row first)".into());
            return;
        };
        let Some(bbox) = self.scene.object_box(p.object) else {
            self.say(format!("{} has no resident geometry to frame", self.object_name(p.object)));
            return;
        };
        let ortho = self.controller.ortho_height.is_some();
        let mut cam = Preset::Iso.camera(bbox, self.scene.up(), self.controller.fovy, ortho);
        // The rest of the scene stays drawn behind the object.
        let (lo, hi) = self.scene.bounds();
        cam.far = cam.far.max((cam.eye - (lo + hi) * 0.5).length() + (hi - lo).length());
        self.go_to(&cam);
        self.say(format!("framed {}", self.object_name(p.object)));
    }

    /// A model tree step of a script: as the window's search box, rows and buttons.
    pub(super) fn tree_step(&mut self, step: TreeStep) {
        if !matches!(step, TreeStep::Toggle) && !self.tree_panel.open {
            self.open_tree(true);
        }
        match step {
            TreeStep::Toggle => self.act(Action::ToggleTree),
            TreeStep::Search(q) => {
                let Some(tree) = self.tree.as_mut() else { return };
                let start = Instant::now();
                tree.set_query(&q);
                let ms = start.elapsed().as_secs_f64() * 1e3;
                let (n, all, searching) = (tree.rows().len(), tree.objects(), tree.is_searching());
                self.say(match searching {
                    true => format!("model tree: {n} of {all} objects match `{q}` ({ms:.1} ms)"),
                    false => format!("model tree: all {all} objects, {n} rows shown"),
                });
            }
            TreeStep::Select(target) => match self.tree_target(&target) {
                Ok(id) => self.act(Action::SelectObject(id)),
                Err(e) => self.say(format!("model tree: {e}")),
            },
            TreeStep::Hide => self.act(Action::Hide),
            TreeStep::Isolate => self.act(Action::Isolate),
            TreeStep::ShowAll => self.act(Action::ShowAll),
            TreeStep::Frame => self.act(Action::FramePicked),
        }
    }

    /// The object a `tree-select` names: by name, id or row shown.
    pub(super) fn tree_target(&self, target: &TreeTarget) -> Result<u32, String> {
        let tree = self.tree.as_ref().ok_or("no model tree")?;
        match target {
            TreeTarget::Name(n) => tree.find(n).ok_or_else(|| format!("no object named `{n}`")),
            TreeTarget::Id(id) if (*id as usize) < tree.objects() => Ok(*id),
            TreeTarget::Id(id) => Err(format!("no object #{id} ({} objects)", tree.objects())),
            TreeTarget::Row(r) => tree
                .rows()
                .get(r.wrapping_sub(1))
                .and_then(|&n| tree.node(n).object)
                .ok_or_else(|| format!("row {r} is not an object ({} rows shown)", tree.rows().len())),
        }
    }

    /// M / Shift+M: measuring of `kind` on (from a new measurement), or off when it was on.
    pub(super) fn toggle_measure(&mut self, kind: MeasureKind) {
        let on = !(self.measuring && self.measure_kind == kind);
        self.set_measure(on.then_some(kind));
    }

    /// Measuring of a kind from a new measurement, or off (`None`).
    pub(super) fn set_measure(&mut self, kind: Option<MeasureKind>) {
        self.measuring = kind.is_some();
        self.measure_kind = kind.unwrap_or_default();
        self.clear_measure();
        self.say(
            match kind {
                Some(MeasureKind::Point) => "measure: click two points (Esc clears)",
                Some(MeasureKind::Plane) => {
                    "measure to a plane: click a face for the plane, then points (Esc clears)"
                }
                None => "measure off",
            }
            .into(),
        );
    }

    /// Forgets both measurements and the last snap.
    pub(super) fn clear_measure(&mut self) {
        self.measure = Measure::default();
        self.plane = PlaneMeasure::default();
        self.snap = None;
    }

    /// Hides the picked object (and forgets the pick).
    pub(super) fn hide_picked(&mut self) {
        match self.picked.take() {
            Some(p) => {
                self.pick_lines.clear();
                self.filter.hide(p.object);
                let note = self.raster_only_note();
                self.say(format!("hidden: {} (Shift+H shows all){note}", self.object_name(p.object)));
            }
            None => self.say("nothing picked to hide (click an object first)".into()),
        }
    }

    /// Shows the picked object alone.
    pub(super) fn isolate_picked(&mut self) {
        match self.picked {
            Some(p) => {
                self.filter.isolate(p.object);
                let note = self.raster_only_note();
                self.say(format!("isolated: {} (Shift+H shows all){note}", self.object_name(p.object)));
            }
            None => self.say("nothing picked to isolate (click an object first)".into()),
        }
    }

    pub(super) fn object_name(&self, id: u32) -> String {
        match self.scene.store().objects().get(id as usize) {
            Some(o) => format!("`{}` (object {id})", o.name),
            None => format!("object {id}"),
        }
    }

    /// Left click at the cursor: picks the object there, or adds a measurement point.
    pub(super) fn click(&mut self) {
        let (Some([x, y]), Some(w)) = (self.cursor, &self.win) else { return };
        let size = w.window.inner_size();
        let (vw, vh) = (size.width as f32, size.height as f32);
        let cam = self.controller.camera();
        let ray = camera_ray(&cam, x, y, vw, vh);
        let Some(hit) = self.scene.pick_triangle(&ray, cam.far) else {
            if !self.measuring {
                self.picked = None;
                self.pick_lines.clear();
            }
            self.say(format!("nothing under the cursor at ({x:.0}, {y:.0})"));
            return;
        };
        let point = ray.at(hit.t);
        let [a, b, c] = hit.corners;
        self.section_pick = Some((point, (b - a).cross(c - a).normalize_or(-ray.dir)));
        if self.measuring {
            let screen = Screen { view_projection: cam.view_projection(vw / vh.max(1.0)), w: vw, h: vh };
            self.measure_click(point, &hit, &screen);
        } else {
            self.pick_object(hit.object, Some(point));
        }
    }

    /// Picks object `id` (a click at `point`, or a row of the model tree): tints it and fills
    /// the HUD's pick lines (name, id, triangles, point, box).
    pub(super) fn pick_object(&mut self, id: u32, point: Option<glam::Vec3>) {
        let units = tw_store::units::unit_suffix(self.scene.units()).to_string();
        let obj = self.scene.store().objects().get(id as usize);
        let name = obj.map_or_else(|| "(not in the object table)".to_string(), |o| o.name.clone());
        let triangles = obj.map_or(0, |o| o.triangles);
        let bbox = self.scene.object_box(id);
        let centre = bbox.map(|(lo, hi)| (lo + hi) * 0.5);
        self.picked = Some(Picked { object: id, point: point.or(centre).unwrap_or_default() });
        self.pick_lines = vec![
            ("picked".into(), format!("{name} (id {id})")),
            ("triangles".into(), crate::hud::count(triangles)),
        ];
        if let Some(p) = point {
            self.pick_lines.push(("point".into(), format!("{} {units}", self.position_text(p))));
        }
        if let Some((lo, hi)) = bbox {
            self.pick_lines.push(("box min".into(), format!("{} {units}", self.position_text(lo))));
            self.pick_lines.push(("box max".into(), format!("{} {units}", self.position_text(hi))));
        }
        let at = point.map(|p| format!(", at {} {units}", self.position_text(p))).unwrap_or_default();
        let bbox_text = bbox
            .map(|(lo, hi)| format!(", box {} – {}", self.position_text(lo), self.position_text(hi)))
            .unwrap_or_default();
        self.say(format!("picked `{name}` (id {id}): {triangles} triangles{at}{bbox_text}"));
        self.follow_in_tree(id);
    }

    /// A measuring click on `hit` at `point`: snaps it and adds it to the measurement.
    pub(super) fn measure_click(&mut self, point: glam::Vec3, hit: &TriangleHit, screen: &Screen) {
        let (p, snap) = snap_point(point, &hit.corners, screen, SNAP_PX);
        self.snap = Some(snap);
        if self.measure_kind == MeasureKind::Plane {
            self.plane_click(p, hit, snap);
            return;
        }
        self.measure.add(p);
        let units = tw_store::units::unit_suffix(self.scene.units());
        let phrase = snap.phrase();
        let m = match (self.measure.a, self.measure.distance()) {
            (Some(a), Some(d)) => format!(
                "measure: distance {} {units} from {} to {}{phrase}",
                format_distance(d as f64),
                self.position_text(a),
                self.position_text(p)
            ),
            _ => format!("measure: first point {} {units}{phrase}", self.position_text(p)),
        };
        self.say(m);
    }

    /// A point-to-plane click at the snapped `p`: the plane (the hit triangle's) or a point
    /// measured from it.
    pub(super) fn plane_click(&mut self, p: glam::Vec3, hit: &TriangleHit, snap: Snap) {
        let units = tw_store::units::unit_suffix(self.scene.units());
        let phrase = snap.phrase();
        let had_plane = self.plane.plane.is_some();
        if !self.plane.add(p, &hit.corners) {
            self.say("measure: that triangle has no plane (degenerate); click another face".into());
            return;
        }
        let m = match (self.plane.plane, self.plane.distance()) {
            (_, Some((d, foot))) if had_plane => format!(
                "measure: distance to the plane {} {units} from {} to the foot {}{phrase}",
                format_distance(d as f64),
                self.position_text(p),
                self.position_text(foot)
            ),
            (Some(plane), _) => {
                // `+ 0.0`: no "-0.0000".
                let [x, y, z] = plane.normal.to_array().map(|v| format!("{:.4}", v + 0.0));
                format!(
                    "measure: plane through {} {units}, normal ({x}, {y}, {z}){phrase}",
                    self.position_text(plane.origin)
                )
            }
            _ => unreachable!("add returned true: the plane is set"),
        };
        self.say(m);
    }

    /// A scene point in the input's coordinates, `(x, y, z)`.
    pub(super) fn position_text(&self, p: glam::Vec3) -> String {
        let [x, y, z] = self.scene.input_position(p).map(format_distance);
        format!("({x}, {y}, {z})")
    }

    /// The HUD's design-review lines: the pick, the filter, the measurement.
    pub(super) fn review_lines(&self) -> Vec<(String, String)> {
        let mut out = self.pick_lines.clone();
        if let Some(i) = self.filter.isolated() {
            out.push(("isolated".into(), self.object_name(i)));
        } else if self.filter.hidden_count() > 0 {
            out.push(("hidden".into(), format!("{} object(s)", self.filter.hidden_count())));
        }
        if self.measuring && self.measure_kind == MeasureKind::Plane {
            let units = tw_store::units::unit_suffix(self.scene.units());
            let v = match (self.plane.plane, self.plane.distance()) {
                (_, Some((d, _))) => format!("{} {units} to the plane", format_distance(d as f64)),
                (None, _) => "click a face for the plane".into(),
                (Some(_), None) => "click a point".into(),
            };
            out.push(("measure".into(), v));
        } else if self.measuring {
            let units = tw_store::units::unit_suffix(self.scene.units());
            let v = match self.measure.distance() {
                Some(d) => format!("{} {units}", format_distance(d as f64)),
                None if self.measure.is_empty() => "click the first point".into(),
                None => "click the second point".into(),
            };
            out.push(("measure".into(), v));
            if let Some(snap) = self.snap {
                out.push(("snapped to".into(), snap.name().into()));
            }
        }
        out
    }

    /// The measurement: its points (small crosses) and the line between them, over the scene;
    /// to a plane, the plane's outline around its point and the perpendicular to its foot.
    pub(super) fn measure_lines(&self, draw: &Camera, view_size: [f32; 2], lines: &mut Vec<Line>) {
        let vp = draw.view_projection(view_size[0] / view_size[1]);
        let segments = match (self.measure_kind, self.plane.plane) {
            (MeasureKind::Plane, Some(plane)) => {
                let size = self.controller.scene_size * 0.05;
                let mut segs: Vec<_> =
                    measure_draw::plane_outline(&plane, size).into_iter().map(|s| (s, false)).collect();
                if let (Some(p), Some((_, foot))) = (self.plane.point, self.plane.distance()) {
                    segs.push(((p, foot), true));
                }
                segs
            }
            (MeasureKind::Point, _) => match self.measure.a {
                Some(a) => vec![((a, self.measure.b.unwrap_or(a)), true)],
                None => return,
            },
            (MeasureKind::Plane, None) => return,
        };
        for (s, ends) in segments {
            if let Some((pa, pb)) = debug_view::project_segment(&vp, s, view_size) {
                lines.push(Line { a: pa, b: pb, color: MEASURE_COLOR });
                if ends {
                    lines.extend(measure_draw::crosses(&[pa, pb], MEASURE_COLOR));
                }
            }
        }
    }
}
