//! Preset and named viewpoints. [`Preset`]: the six axis views and an isometric one, framing the
//! model's bounds (the eye on the axis through the bounds' centre, far enough that the bounding
//! sphere fills the field of view). [`Viewpoints`]: cameras saved under a name in a JSON file
//! next to the store ([`views_file`]), in the store's input coordinates (the grid origin added
//! back, as `--camera` and path files use), so that the file stays meaningful outside the
//! viewer and across rebuilds of the store with another grid origin.
//!
//! ```json
//! {"format":"terawalk-views","version":1,
//!  "views":[{"name":"entrance","eye":[1,2,3],"target":[1,3,3],"fovy":60},
//!           {"name":"plan","eye":[5,5,90],"target":[5,5,0],"fovy":60,"ortho_height":42}]}
//! ```
//!
//! A view with `ortho_height` (input units, > 0) is orthographic with a view that high (its
//! `fovy` is the perspective that O returns to); files without it, as every file written before
//! the orthographic camera, hold perspective views — except the views the viewer's former O
//! saved: a 1° perspective from far away, stored as `fovy` 1 and read back as the orthographic
//! view they stood for ([`OLD_ORTHO_FOVY_DEG`], [`Viewpoint::camera`]).

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use tw_runtime::camera::DEFAULT_FOVY_DEG;
use tw_runtime::{Camera, Projection};

use crate::controller::clip_planes;

/// The former orthographic view (before the true projection: a 1° perspective from 66 times
/// further away, `fovy` saved as 1): a view without `ortho_height` whose `fovy` is at most this
/// (the former viewer's own test, 1° + 1 %) is read as orthographic.
pub const OLD_ORTHO_FOVY_DEG: f64 = 1.01;

/// The `format` field of a viewpoints file.
pub const VIEWS_FORMAT: &str = "terawalk-views";
pub const VIEWS_VERSION: u64 = 1;

/// A view along an axis of the scene, or the isometric one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    PosX,
    NegX,
    PosY,
    NegY,
    PosZ,
    NegZ,
    Iso,
}

impl Preset {
    pub const ALL: [Preset; 7] =
        [Preset::PosX, Preset::NegX, Preset::PosY, Preset::NegY, Preset::PosZ, Preset::NegZ, Preset::Iso];

    /// The side the eye is on: `+x` looks from +X towards −X.
    pub fn name(self) -> &'static str {
        match self {
            Preset::PosX => "+x",
            Preset::NegX => "-x",
            Preset::PosY => "+y",
            Preset::NegY => "-y",
            Preset::PosZ => "+z",
            Preset::NegZ => "-z",
            Preset::Iso => "iso",
        }
    }

    pub fn parse(s: &str) -> Option<Preset> {
        let s = s.to_ascii_lowercase();
        Preset::ALL.into_iter().find(|p| p.name() == s || (s.len() == 1 && p.name() == format!("+{s}")))
    }

    /// Unit direction from the model's centre to the eye, for the scene's `up` axis (the
    /// isometric view comes from above, in front and to the right: +a −b +up for the other
    /// two axes a, b in x y z order).
    pub fn direction(self, up: Vec3) -> Vec3 {
        match self {
            Preset::PosX => Vec3::X,
            Preset::NegX => -Vec3::X,
            Preset::PosY => Vec3::Y,
            Preset::NegY => -Vec3::Y,
            Preset::PosZ => Vec3::Z,
            Preset::NegZ => -Vec3::Z,
            Preset::Iso => {
                let up = up.normalize_or(Vec3::Z);
                let others: Vec<Vec3> =
                    [Vec3::X, Vec3::Y, Vec3::Z].into_iter().filter(|a| a.dot(up).abs() < 0.5).collect();
                match others.as_slice() {
                    [a, b] => (*a - *b + up).normalize(),
                    _ => Vec3::ONE.normalize(),
                }
            }
        }
    }

    /// The camera of this view of `bounds` (scene space) with vertical field of view `fovy`,
    /// or, when `orthographic`, from the same eye with a view as high as the perspective one is
    /// at the model's centre: the model keeps its apparent size.
    pub fn camera(self, bounds: (Vec3, Vec3), up: Vec3, fovy: f32, orthographic: bool) -> Camera {
        let (lo, hi) = bounds;
        let centre = (lo + hi) * 0.5;
        let radius = ((hi - lo).length() * 0.5).max(1e-3);
        let half = (fovy.clamp(0.1, 3.0) * 0.5).sin();
        let dir = self.direction(up);
        let eye = centre + dir * (radius / half * 1.05);
        // Along the up axis the camera's up is another axis (the controller keeps the scene's).
        let cam_up = if dir.dot(up).abs() > 0.99 { up.any_orthonormal_vector() } else { up };
        let (near, far) = clip_planes(eye, bounds);
        let camera = Camera {
            eye,
            target: centre,
            up: cam_up,
            projection: Projection::Perspective { fovy },
            near,
            far,
        };
        if orthographic {
            let height = camera.view_height_at((centre - eye).length() as f64) as f32;
            Camera { projection: Projection::Orthographic { height }, ..camera }
        } else {
            camera
        }
    }
}

/// The viewpoints file of a store: `scene.tw` → `scene.tw.views.json`, next to it.
pub fn views_file(store: &Path) -> PathBuf {
    let mut name = store.file_name().map(|n| n.to_os_string()).unwrap_or_else(|| "scene".into());
    name.push(".views.json");
    store.with_file_name(name)
}

/// A named camera in the store's input coordinates; `fovy` in degrees; `ortho_height` (input
/// units) for an orthographic view.
#[derive(Clone, Debug, PartialEq)]
pub struct Viewpoint {
    pub name: String,
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub fovy: f64,
    pub ortho_height: Option<f64>,
}

impl Viewpoint {
    /// `camera` (scene space) under `name`; `origin` is the store's grid origin; `fovy`
    /// (radians) the perspective an orthographic camera returns to.
    pub fn from_camera(name: &str, camera: &Camera, fovy: f32, origin: [f64; 3]) -> Viewpoint {
        let o = DVec3::from_array(origin);
        let (fovy, ortho_height) = match camera.projection {
            Projection::Perspective { fovy } => (fovy, None),
            Projection::Orthographic { height } => (fovy, Some(height as f64)),
        };
        Viewpoint {
            name: name.to_string(),
            eye: (camera.eye.as_dvec3() + o).to_array(),
            target: (camera.target.as_dvec3() + o).to_array(),
            fovy: (fovy as f64).to_degrees(),
            ortho_height,
        }
    }

    /// The perspective field of view (radians) of the view, or the one its orthographic view
    /// returns to (for a former orthographic view, [`DEFAULT_FOVY_DEG`]).
    pub fn fovy_radians(&self) -> f32 {
        let degrees = if self.is_old_orthographic() { DEFAULT_FOVY_DEG } else { self.fovy };
        (degrees.to_radians() as f32).clamp(0.01, 3.1)
    }

    /// Whether this is a view the former O saved ([`OLD_ORTHO_FOVY_DEG`]).
    pub fn is_old_orthographic(&self) -> bool {
        self.ortho_height.is_none() && self.fovy <= OLD_ORTHO_FOVY_DEG
    }

    /// The scene-space camera (clip planes seeing all of `bounds`, the scene's `up`).
    ///
    /// A former orthographic view ([`is_old_orthographic`](Self::is_old_orthographic)) becomes
    /// the orthographic camera that view stood for: as high as its narrow view was at the depth
    /// of the bounds' centre, the eye brought forward along the view to where the former O had
    /// moved it back from (a [`DEFAULT_FOVY_DEG`] view showing that depth at the same size, as
    /// O in the viewer now leaves the eye); a view looking away from the centre stays as saved.
    pub fn camera(&self, origin: [f64; 3], bounds: (Vec3, Vec3), up: Vec3) -> Camera {
        let o = DVec3::from_array(origin);
        let mut eye = (DVec3::from_array(self.eye) - o).as_vec3();
        let mut target = (DVec3::from_array(self.target) - o).as_vec3();
        let mut projection = match self.ortho_height {
            Some(h) => Projection::Orthographic { height: h as f32 },
            None => Projection::Perspective { fovy: (self.fovy.to_radians() as f32).clamp(0.01, 3.1) },
        };
        if self.is_old_orthographic() {
            let forward = (target - eye).normalize_or_zero();
            let depth = ((bounds.0 + bounds.1) * 0.5 - eye).dot(forward) as f64;
            if depth > 0.0 {
                let narrow = (self.fovy.to_radians() * 0.5).tan();
                let back = depth * narrow / (DEFAULT_FOVY_DEG.to_radians() * 0.5).tan();
                let reach = (target - eye).length();
                eye += forward * (depth - back) as f32;
                target = eye + forward * reach;
                projection = Projection::Orthographic { height: (2.0 * depth * narrow) as f32 };
            }
        }
        let (near, far) = clip_planes(eye, bounds);
        Camera { eye, target, up, projection, near, far }
    }
}

/// A viewpoints file that cannot be read or written, with its path (and line and column).
#[derive(Debug, thiserror::Error)]
pub enum ViewpointError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: {msg}")]
    Format { path: PathBuf, msg: String },
}

/// The named viewpoints of a store, in the order they were first saved.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Viewpoints {
    pub views: Vec<Viewpoint>,
}

impl Viewpoints {
    /// Reads `path`; a missing file is an empty list (nothing saved yet).
    pub fn load(path: &Path) -> Result<Viewpoints, ViewpointError> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Viewpoints::default()),
            Err(source) => return Err(ViewpointError::Io { path: path.to_path_buf(), source }),
        };
        Viewpoints::parse(&text, path)
    }

    /// Parses a file's `text`; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Viewpoints, ViewpointError> {
        let err = |msg: String| ViewpointError::Format { path: path.to_path_buf(), msg };
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| err(e.to_string()))?;
        if v.get("format").and_then(|f| f.as_str()) != Some(VIEWS_FORMAT) {
            return Err(err(format!("not a viewpoints file (\"format\" is not \"{VIEWS_FORMAT}\")")));
        }
        match v.get("version").and_then(|f| f.as_u64()) {
            Some(VIEWS_VERSION) => {}
            other => {
                return Err(err(format!("unsupported version {other:?} (this viewer reads {VIEWS_VERSION})")))
            }
        }
        let list =
            v.get("views").and_then(|l| l.as_array()).ok_or_else(|| err("no \"views\" list".into()))?;
        let mut views = Vec::with_capacity(list.len());
        for (i, item) in list.iter().enumerate() {
            let at = |field: &str| format!("views[{i}].{field}");
            let point = |field: &str| -> Result<[f64; 3], ViewpointError> {
                let a = item.get(field).and_then(|p| p.as_array()).filter(|a| a.len() == 3);
                let p: Option<Vec<f64>> =
                    a.map(|a| a.iter().filter_map(|x| x.as_f64()).filter(|x| x.is_finite()).collect());
                p.filter(|p| p.len() == 3)
                    .map(|p| [p[0], p[1], p[2]])
                    .ok_or_else(|| err(format!("{} is not three finite numbers", at(field))))
            };
            let name = item
                .get("name")
                .and_then(|n| n.as_str())
                .filter(|n| !n.is_empty())
                .ok_or_else(|| err(format!("{} is not a name", at("name"))))?;
            let fovy = item
                .get("fovy")
                .and_then(|f| f.as_f64())
                .filter(|f| *f > 0.0 && *f < 180.0)
                .ok_or_else(|| err(format!("{} is not an angle in (0, 180) degrees", at("fovy"))))?;
            let ortho_height = match item.get("ortho_height") {
                None | Some(serde_json::Value::Null) => None,
                Some(h) => Some(
                    h.as_f64()
                        .filter(|h| *h > 0.0 && h.is_finite())
                        .ok_or_else(|| err(format!("{} is not a positive height", at("ortho_height"))))?,
                ),
            };
            let (eye, target) = (point("eye")?, point("target")?);
            if eye == target {
                return Err(err(format!("{}: the eye is the target", at("name"))));
            }
            views.push(Viewpoint { name: name.to_string(), eye, target, fovy, ortho_height });
        }
        Ok(Viewpoints { views })
    }

    /// Writes the list to `path` (whole, through a temporary file next to it).
    pub fn save(&self, path: &Path) -> Result<(), ViewpointError> {
        let views: Vec<serde_json::Value> = self
            .views
            .iter()
            .map(|v| {
                let mut j =
                    serde_json::json!({"name": v.name, "eye": v.eye, "target": v.target, "fovy": v.fovy});
                if let Some(h) = v.ortho_height {
                    j["ortho_height"] = serde_json::json!(h);
                }
                j
            })
            .collect();
        let doc = serde_json::json!({"format": VIEWS_FORMAT, "version": VIEWS_VERSION, "views": views});
        let text = serde_json::to_string_pretty(&doc).unwrap_or_default();
        let io = |source| ViewpointError::Io { path: path.to_path_buf(), source };
        let tmp = path.with_extension("json.tmp");
        std::fs::write(&tmp, text + "\n").map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
    }

    /// Adds `v`, replacing a viewpoint of the same name.
    pub fn set(&mut self, v: Viewpoint) {
        match self.views.iter_mut().find(|w| w.name == v.name) {
            Some(w) => *w = v,
            None => self.views.push(v),
        }
    }

    pub fn get(&self, name: &str) -> Option<&Viewpoint> {
        self.views.iter().find(|v| v.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_frame_the_bounds_from_their_side() {
        let bounds = (Vec3::ZERO, Vec3::new(4.0, 1.0, 1.0));
        let centre = Vec3::new(2.0, 0.5, 0.5);
        for p in Preset::ALL {
            let c = p.camera(bounds, Vec3::Z, 1.0, false);
            assert_eq!(c.target, centre, "{}", p.name());
            assert!(c.validate().is_ok(), "{}", p.name());
            // Outside the bounding sphere, on the preset's side.
            let d = c.eye - centre;
            assert!(d.length() > (bounds.1 - bounds.0).length() * 0.5, "{}", p.name());
            assert!(d.normalize().dot(p.direction(Vec3::Z)) > 0.999, "{}", p.name());
            assert_eq!(Preset::parse(p.name()), Some(p));
        }
        assert!(Preset::PosX.camera(bounds, Vec3::Z, 1.0, false).eye.x > 4.0);
        assert_eq!(Preset::parse("X"), Some(Preset::PosX));
        assert_eq!(Preset::parse("front"), None);
        assert!(Preset::Iso.direction(Vec3::Z).z > 0.0 && Preset::Iso.direction(Vec3::Y).y > 0.0);
    }

    #[test]
    fn viewpoints_round_trip_through_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let store = dir.path().join("plant.tw");
        let file = views_file(&store);
        assert_eq!(file, dir.path().join("plant.tw.views.json"));
        assert_eq!(Viewpoints::load(&file).unwrap(), Viewpoints::default(), "no file: no views");
        let origin = [1000.0, -20.0, 3.5];
        let cam =
            Camera::new(Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0, 5.0, 3.0), Vec3::Z, 1.0, 0.1, 50.0).unwrap();
        let mut views = Viewpoints::default();
        views.set(Viewpoint::from_camera("door", &cam, 1.0, origin));
        views.set(Viewpoint::from_camera(
            "top",
            &Preset::PosZ.camera((Vec3::ZERO, Vec3::ONE), Vec3::Z, 1.0, false),
            1.0,
            origin,
        ));
        let plan = Preset::PosZ.camera((Vec3::ZERO, Vec3::ONE), Vec3::Z, 1.0, true);
        views.set(Viewpoint::from_camera("plan", &plan, 0.7, origin));
        views.set(Viewpoint::from_camera("door", &cam, 1.0, origin));
        assert_eq!(views.views.len(), 3, "same name replaces");
        views.save(&file).unwrap();
        let back = Viewpoints::load(&file).unwrap();
        // serde_json reads floats to within an ulp (no `float_roundtrip`).
        assert_eq!(back.views[..2], views.views[..2]);
        let (a, b) = (back.views[2].ortho_height.unwrap(), views.views[2].ortho_height.unwrap());
        assert!((a - b).abs() < 1e-12 && back.views[2].eye == views.views[2].eye);
        assert_eq!(back.get("door").unwrap().eye, [1001.0, -18.0, 6.5]);
        let bounds = (Vec3::ZERO, Vec3::splat(10.0));
        let again = back.get("door").unwrap().camera(origin, bounds, Vec3::Z);
        assert!((again.eye - cam.eye).length() < 1e-5 && (again.target - cam.target).length() < 1e-5);
        assert_eq!(again.projection, cam.projection);
        let plan = back.get("plan").unwrap();
        assert!((plan.fovy_radians() - 0.7).abs() < 1e-6, "the perspective to return to");
        let plan = plan.camera(origin, bounds, Vec3::Z);
        let top = back.get("top").unwrap().camera(origin, bounds, Vec3::Z);
        let Projection::Orthographic { height } = plan.projection else { panic!("{plan:?}") };
        let d = (top.target - top.eye).length() as f64;
        assert!((height as f64 - top.view_height_at(d)).abs() < 1e-5, "as high as the perspective view");
    }

    /// A view the former O saved (a 1° perspective 66 times further back, `fovy` 1, no
    /// `ortho_height`) is read as orthographic: the model's centre as large as the narrow view
    /// showed it, the eye where O had taken it from, O returning to a 60° perspective that
    /// frames it alike. A 2° view is an ordinary telephoto view.
    #[test]
    fn former_orthographic_viewpoints_load_as_orthographic() {
        let bounds = (Vec3::splat(-5.0), Vec3::splat(5.0));
        let origin = [100.0, 200.0, 0.0];
        // The former O from 20 units in front of the centre, looking along +y: 66x further.
        let scale = (30f64.to_radians().tan() / 0.5f64.to_radians().tan()) as f32;
        let eye = Vec3::new(0.0, -20.0 * scale, 0.0);
        let old = |fovy: f64| Viewpoint {
            name: "old".into(),
            eye: [eye.x as f64 + 100.0, eye.y as f64 + 200.0, 0.0],
            target: [100.0, eye.y as f64 + 201.0, 0.0],
            fovy,
            ortho_height: None,
        };
        let v = old(1.0);
        assert!(v.is_old_orthographic());
        let cam = v.camera(origin, bounds, Vec3::Z);
        let Projection::Orthographic { height } = cam.projection else { panic!("{cam:?}") };
        let narrow_height = 2.0 * (-eye.y) * 0.5f32.to_radians().tan();
        assert!((height - narrow_height).abs() < 1e-3 * height, "{height} against {narrow_height}");
        assert!((cam.eye - Vec3::new(0.0, -20.0, 0.0)).length() < 1e-2, "the eye back in front: {}", cam.eye);
        assert!((cam.direction() - Vec3::Y).length() < 1e-6);
        assert!((v.fovy_radians() - 60f32.to_radians()).abs() < 1e-6);
        let back = Camera { projection: Projection::Perspective { fovy: v.fovy_radians() }, ..cam };
        assert!(
            (back.view_height_at(20.0) - height as f64).abs() < 1e-3 * height as f64,
            "O frames it alike"
        );
        // Saved again, it is an orthographic view of today's kind.
        let again = Viewpoint::from_camera("old", &cam, v.fovy_radians(), origin);
        assert!(!again.is_old_orthographic() && again.ortho_height.is_some());
        // A narrow view of another kind stays perspective.
        let tele = old(2.0);
        assert!(!tele.is_old_orthographic());
        assert_eq!(
            tele.camera(origin, bounds, Vec3::Z).projection,
            Projection::Perspective { fovy: 2f32.to_radians() }
        );
    }

    /// The preset views keep the model's apparent size in orthographic: the view's height at
    /// the model's centre is the same in both projections.
    #[test]
    fn orthographic_presets_frame_the_model_as_the_perspective_ones() {
        let bounds = (Vec3::new(-1.0, 0.0, 2.0), Vec3::new(3.0, 5.0, 4.0));
        for p in Preset::ALL {
            let persp = p.camera(bounds, Vec3::Z, 0.8, false);
            let ortho = p.camera(bounds, Vec3::Z, 0.8, true);
            assert_eq!((ortho.eye, ortho.target), (persp.eye, persp.target));
            assert!(ortho.is_orthographic() && !persp.is_orthographic());
            let d = (persp.target - persp.eye).length() as f64;
            let (a, b) = (persp.view_height_at(d), ortho.view_height_at(d));
            assert!((a - b).abs() < b * 1e-6, "{}: {a} against {b}", p.name());
        }
    }

    #[test]
    fn bad_files_name_the_file_and_the_field() {
        let p = Path::new("v.json");
        for (text, needle) in [
            ("{", "v.json: EOF while parsing"),
            ("{\"format\":\"x\",\"version\":1,\"views\":[]}", "not a viewpoints file"),
            ("{\"format\":\"terawalk-views\",\"version\":9,\"views\":[]}", "unsupported version"),
            (
                "{\"format\":\"terawalk-views\",\"version\":1,\"views\":[{\"name\":\"a\",\"eye\":[0,0],\
                 \"target\":[1,1,1],\"fovy\":60}]}",
                "views[0].eye is not three finite numbers",
            ),
            (
                "{\"format\":\"terawalk-views\",\"version\":1,\"views\":[{\"name\":\"a\",\"eye\":[0,0,0],\
                 \"target\":[1,1,1],\"fovy\":0}]}",
                "views[0].fovy",
            ),
            (
                "{\"format\":\"terawalk-views\",\"version\":1,\"views\":[{\"name\":\"a\",\"eye\":[0,0,0],\
                 \"target\":[1,1,1],\"fovy\":60,\"ortho_height\":-2}]}",
                "views[0].ortho_height",
            ),
        ] {
            let e = Viewpoints::parse(text, p).unwrap_err().to_string();
            assert!(e.starts_with("v.json: ") && e.contains(needle), "{e}");
        }
    }
}
