//! Camera paths: one camera per frame, in input coordinates, as JSON. `terawalk path` writes
//! them, `terawalk bench` renders them, the viewer records and plays them back (one format for
//! all three).
//!
//! ```json
//! {
//!   "format": "terawalk-path",
//!   "version": 1,
//!   "fps": 30.0,
//!   "frames": [
//!     { "eye": [10.0, 5.0, 1.7], "target": [40.0, 5.0, 1.7], "up": [0.0, 0.0, 1.0],
//!       "fovy": 60.0, "segment": "walk" }
//!   ]
//! }
//! ```
//!
//! `eye`, `target` and `up` are in the units and axes of the input files (as `--camera`
//! takes them), `fovy` is the vertical field of view in degrees (1..=179), the optional
//! `ortho_height` (> 0, input units) makes the frame orthographic with a view that high (its
//! `fovy` is then the perspective the viewer's O key returns to; frames without it, as every file
//! written before orthographic cameras, are perspective), `segment` names the
//! part of the path a frame belongs to (`"walk"`, `"fly"`, `"recorded"`, …; free text, used to
//! split reports). [`CameraPath::load`] checks every frame and names the file and frame of the
//! first bad one; [`CameraPath::save`] writes atomically (a temporary file renamed into place).

use std::io::Write;
use std::path::Path;

use serde::{Deserialize, Serialize};
use tw_store::Header;

use crate::camera::{Camera, InputCamera};
use crate::error::RuntimeError;

/// The `format` field of every path file.
pub const PATH_FORMAT: &str = "terawalk-path";
/// The version this crate reads and writes.
pub const PATH_VERSION: u32 = 1;
/// The most frames a path file may hold (a day at 100 fps is 8.6 M).
pub const MAX_FRAMES: usize = 10_000_000;

/// One frame's camera, in input coordinates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PathFrame {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
    /// Vertical field of view, degrees.
    pub fovy: f64,
    /// Orthographic view height (input units); absent: a perspective frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ortho_height: Option<f64>,
    /// Which part of the path this frame belongs to ("walk", "fly", "recorded", …).
    #[serde(default)]
    pub segment: String,
}

impl PathFrame {
    /// The frame as an [`InputCamera`] (not yet checked; see [`CameraPath::validate`]).
    pub fn input_camera(&self) -> InputCamera {
        InputCamera {
            eye: self.eye,
            target: self.target,
            up: self.up,
            fovy_deg: self.fovy,
            ortho_height: self.ortho_height,
        }
    }

    /// The frame's scene-space camera for `header`'s store.
    pub fn to_scene(&self, header: &Header) -> Result<Camera, RuntimeError> {
        self.input_camera().to_scene(header)
    }

    /// A frame from an input camera.
    pub fn from_input_camera(camera: &InputCamera, segment: &str) -> PathFrame {
        PathFrame {
            eye: camera.eye,
            target: camera.target,
            up: camera.up,
            fovy: camera.fovy_deg,
            ortho_height: camera.ortho_height,
            segment: segment.to_string(),
        }
    }
}

/// A camera path: frames played at `fps`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraPath {
    pub format: String,
    pub version: u32,
    /// Frames per second the path was made for (playback speed; > 0).
    pub fps: f64,
    pub frames: Vec<PathFrame>,
}

impl CameraPath {
    /// A path of `frames` at `fps`.
    pub fn new(fps: f64, frames: Vec<PathFrame>) -> CameraPath {
        CameraPath { format: PATH_FORMAT.to_string(), version: PATH_VERSION, fps, frames }
    }

    /// Duration in seconds at the path's own frame rate.
    pub fn duration_s(&self) -> f64 {
        self.frames.len() as f64 / self.fps
    }

    /// Checks the header fields and every frame: finite values, eye ≠ target, up not zero and
    /// not parallel to the view direction, 1 ≤ fovy ≤ 179, an orthographic height finite and
    /// > 0. Errors name the frame.
    pub fn validate(&self) -> Result<(), String> {
        if self.format != PATH_FORMAT {
            return Err(format!("\"format\" is {:?}, expected {PATH_FORMAT:?}", self.format));
        }
        if self.version != PATH_VERSION {
            return Err(format!(
                "path version {} is not supported (this terawalk reads version {PATH_VERSION})",
                self.version
            ));
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(format!("\"fps\" must be a positive number, got {}", self.fps));
        }
        if self.frames.is_empty() {
            return Err("the path has no frames".into());
        }
        if self.frames.len() > MAX_FRAMES {
            return Err(format!("{} frames is more than the {MAX_FRAMES} allowed", self.frames.len()));
        }
        for (i, f) in self.frames.iter().enumerate() {
            check_frame(f).map_err(|m| format!("frame {i}: {m}"))?;
        }
        Ok(())
    }

    /// Reads and validates a path file.
    pub fn load(path: &Path) -> Result<CameraPath, RuntimeError> {
        let err = |msg: String| RuntimeError::Path { path: path.to_path_buf(), msg };
        let file = std::fs::File::open(path).map_err(|e| err(format!("cannot open: {e}")))?;
        let len = file.metadata().map(|m| m.len()).unwrap_or(0);
        // About 200 bytes a frame: refuse files that could not be a path before parsing them.
        if len > MAX_FRAMES as u64 * 1024 {
            return Err(err(format!("{len} bytes is too large for a camera path")));
        }
        CameraPath::parse(std::io::BufReader::new(file)).map_err(err)
    }

    /// Reads and validates a path from `reader` (what [`CameraPath::load`] does after opening
    /// the file; also the entry point of the `path` fuzz target). The message names the line
    /// and column of a syntax error, or the first bad frame.
    pub fn parse(reader: impl std::io::Read) -> Result<CameraPath, String> {
        let p: CameraPath = serde_json::from_reader(reader).map_err(|e| {
            if e.is_io() {
                format!("cannot read: {e}")
            } else {
                format!("line {}, column {}: {e}", e.line(), e.column())
            }
        })?;
        p.validate()?;
        Ok(p)
    }

    /// Writes the path as pretty JSON, atomically (temporary file in the same folder, renamed).
    pub fn save(&self, path: &Path) -> Result<(), RuntimeError> {
        let err = |msg: String| RuntimeError::Path { path: path.to_path_buf(), msg };
        self.validate().map_err(|m| err(format!("not written: {m}")))?;
        tw_core::output::check_replaceable(path).map_err(|e| err(e.to_string()))?;
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let builder = tempfile::Builder::new();
        // The usual permissions of a new file (0666 less the umask), not a temporary file's 0600.
        #[cfg(unix)]
        let builder = {
            use std::os::unix::fs::PermissionsExt;
            let mut builder = builder;
            builder.permissions(std::fs::Permissions::from_mode(0o666));
            builder
        };
        let mut tmp = builder
            .tempfile_in(dir)
            .map_err(|e| err(format!("cannot create a temporary file in {}: {e}", dir.display())))?;
        let mut w = std::io::BufWriter::new(tmp.as_file_mut());
        serde_json::to_writer_pretty(&mut w, self).map_err(|e| err(format!("cannot write: {e}")))?;
        w.write_all(b"\n").and_then(|_| w.flush()).map_err(|e| err(format!("cannot write: {e}")))?;
        drop(w);
        tmp.as_file().sync_all().map_err(|e| err(format!("cannot write: {e}")))?;
        tmp.persist(path).map_err(|e| err(format!("cannot rename into place: {}", e.error)))?;
        Ok(())
    }
}

fn check_frame(f: &PathFrame) -> Result<(), String> {
    let finite = |v: [f64; 3]| v.iter().all(|x| x.is_finite());
    if !(finite(f.eye) && finite(f.target) && finite(f.up) && f.fovy.is_finite()) {
        return Err("eye, target, up and fovy must be finite numbers".into());
    }
    if !(1.0..=179.0).contains(&f.fovy) {
        return Err(format!("field of view must be 1..=179 degrees, got {}", f.fovy));
    }
    if let Some(h) = f.ortho_height {
        if !(h > 0.0 && h.is_finite()) {
            return Err(format!("orthographic height must be finite and > 0, got {h}"));
        }
    }
    let d = [f.target[0] - f.eye[0], f.target[1] - f.eye[1], f.target[2] - f.eye[2]];
    let cross =
        [d[1] * f.up[2] - d[2] * f.up[1], d[2] * f.up[0] - d[0] * f.up[2], d[0] * f.up[1] - d[1] * f.up[0]];
    let n2 = |v: [f64; 3]| v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if n2(d) == 0.0 {
        return Err("eye and target are the same point".into());
    }
    if n2(f.up) == 0.0 {
        return Err("up must not be zero".into());
    }
    if n2(cross) <= 1e-12 * n2(d) * n2(f.up) {
        return Err("up is parallel to the view direction".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(x: f64) -> PathFrame {
        PathFrame {
            eye: [x, 0.0, 1.7],
            target: [x + 1.0, 0.0, 1.7],
            up: [0.0, 0.0, 1.0],
            fovy: 60.0,
            ortho_height: None,
            segment: "walk".into(),
        }
    }

    #[test]
    fn save_then_load_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("p.json");
        let p = CameraPath::new(30.0, (0..5).map(|i| frame(i as f64 * 0.1)).collect());
        p.save(&file).unwrap();
        assert_eq!(CameraPath::load(&file).unwrap(), p);
        assert!((p.duration_s() - 5.0 / 30.0).abs() < 1e-12);
    }

    #[test]
    fn segment_is_optional() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("p.json");
        std::fs::write(
            &file,
            r#"{"format":"terawalk-path","version":1,"fps":24,"frames":[
                {"eye":[0,0,0],"target":[1,0,0],"up":[0,0,1],"fovy":50}]}"#,
        )
        .unwrap();
        let p = CameraPath::load(&file).unwrap();
        assert_eq!(p.frames[0].segment, "");
        assert_eq!(p.frames[0].ortho_height, None, "files without the field are perspective");
        assert_eq!(p.fps, 24.0);
    }

    fn load_err(text: &str) -> String {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("bad.json");
        std::fs::write(&file, text).unwrap();
        let e = CameraPath::load(&file).unwrap_err().to_string();
        assert!(e.contains("bad.json"), "{e}");
        e
    }

    #[test]
    fn bad_files_are_refused_with_their_position() {
        let e = load_err("{\"format\":\"terawalk-path\",\n\"version\":1,\"fps\":30,\"frames\":[}");
        assert!(e.contains("line 2"), "{e}");
        let e = load_err(r#"{"format":"other","version":1,"fps":30,"frames":[]}"#);
        assert!(e.contains("format"), "{e}");
        let e = load_err(r#"{"format":"terawalk-path","version":9,"fps":30,"frames":[]}"#);
        assert!(e.contains("version 9"), "{e}");
        let e = load_err(r#"{"format":"terawalk-path","version":1,"fps":0,"frames":[]}"#);
        assert!(e.contains("fps"), "{e}");
        let e = load_err(r#"{"format":"terawalk-path","version":1,"fps":30,"frames":[]}"#);
        assert!(e.contains("no frames"), "{e}");
        let e = load_err(
            r#"{"format":"terawalk-path","version":1,"fps":30,"frames":[
            {"eye":[0,0,0],"target":[1,0,0],"up":[0,0,1],"fovy":50},
            {"eye":[0,0,0],"target":[0,0,0],"up":[0,0,1],"fovy":50}]}"#,
        );
        assert!(e.contains("frame 1") && e.contains("same point"), "{e}");
        let e = load_err(
            r#"{"format":"terawalk-path","version":1,"fps":30,"frames":[
            {"eye":[0,0,0],"target":[0,0,5],"up":[0,0,1],"fovy":50}]}"#,
        );
        assert!(e.contains("parallel"), "{e}");
        let e = load_err(
            r#"{"format":"terawalk-path","version":1,"fps":30,"frames":[
            {"eye":[0,0,0],"target":[1,0,0],"up":[0,0,1],"fovy":180}]}"#,
        );
        assert!(e.contains("1..=179"), "{e}");
    }

    #[test]
    fn invalid_paths_are_not_written() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("p.json");
        let mut f = frame(0.0);
        f.target = f.eye;
        assert!(CameraPath::new(30.0, vec![f]).save(&file).is_err());
        assert!(!file.exists());
    }

    #[test]
    fn orthographic_frames_round_trip_and_perspective_ones_are_written_as_before() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("p.json");
        let ortho = PathFrame { ortho_height: Some(12.5), ..frame(0.0) };
        let p = CameraPath::new(30.0, vec![frame(0.0), ortho.clone()]);
        p.save(&file).unwrap();
        let text = std::fs::read_to_string(&file).unwrap();
        assert_eq!(text.matches("ortho_height").count(), 1, "only the orthographic frame: {text}");
        let back = CameraPath::load(&file).unwrap();
        assert_eq!(back, p);
        let h = tw_store::Header::empty([-10.0; 3], [10.0; 3], [0.0; 3], 0.01);
        let c = back.frames[1].to_scene(&h).unwrap();
        assert_eq!(c.projection, crate::camera::Projection::Orthographic { height: 12.5 });
        assert!(!back.frames[0].to_scene(&h).unwrap().is_orthographic());
        let bad = CameraPath::new(30.0, vec![PathFrame { ortho_height: Some(0.0), ..frame(0.0) }]);
        assert!(bad.validate().unwrap_err().contains("orthographic"));
    }
}
