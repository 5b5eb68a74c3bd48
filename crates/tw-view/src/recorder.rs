//! Path recording and playback in the format `terawalk path` writes and `bench` reads
//! ([`tw_runtime::CameraPath`]: one camera per frame, input coordinates). Plain data:
//! [`Recorder`] turns scene cameras into path frames (adding the store's grid origin back),
//! [`Player`] turns a path into scene cameras, either one per rendered frame (scripted runs,
//! deterministic) or by elapsed time at the path's fps (interactive playback).

use glam::DVec3;
use tw_runtime::camera::DEFAULT_FOVY_DEG;
use tw_runtime::{Camera, CameraPath, PathFrame, Projection, RuntimeError};
use tw_store::Header;

/// The scene camera as a path frame in input coordinates (an orthographic camera keeps
/// [`DEFAULT_FOVY_DEG`] as its frame's field of view).
pub fn to_frame(camera: &Camera, header: &Header, segment: &str) -> PathFrame {
    let origin = DVec3::from_array(header.grid_origin);
    let eye = camera.eye.as_dvec3() + origin;
    let target = camera.target.as_dvec3() + origin;
    let (fovy, ortho_height) = match camera.projection {
        Projection::Perspective { fovy } => ((fovy as f64).to_degrees().clamp(1.0, 179.0), None),
        Projection::Orthographic { height } => (DEFAULT_FOVY_DEG, Some(height as f64)),
    };
    PathFrame {
        eye: eye.to_array(),
        target: target.to_array(),
        up: camera.up.as_dvec3().to_array(),
        fovy,
        ortho_height,
        segment: segment.to_string(),
    }
}

/// Collects one frame per rendered frame.
#[derive(Clone, Debug, Default)]
pub struct Recorder {
    frames: Vec<PathFrame>,
    seconds: f64,
}

impl Recorder {
    pub fn push(&mut self, camera: &Camera, header: &Header, dt: f64) {
        self.frames.push(to_frame(camera, header, "recorded"));
        self.seconds += dt.max(0.0);
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The recording as a path; its fps is the mean frame rate of the recording (30 if unknown).
    pub fn finish(self) -> CameraPath {
        let fps = if self.seconds > 0.0 { self.frames.len() as f64 / self.seconds } else { 30.0 };
        CameraPath::new(fps.clamp(1.0, 1000.0), self.frames)
    }
}

/// Plays a path back as scene cameras.
#[derive(Clone, Debug)]
pub struct Player {
    cameras: Vec<Camera>,
    fps: f64,
    frame: usize,
    time: f64,
}

impl Player {
    /// Converts every frame for `header`'s store; errors name the frame.
    pub fn new(path: &CameraPath, header: &Header) -> Result<Player, RuntimeError> {
        let cameras = path
            .frames
            .iter()
            .enumerate()
            .map(|(i, f)| {
                f.to_scene(header).map_err(|e| RuntimeError::Camera(format!("path frame {i}: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Player { cameras, fps: path.fps, frame: 0, time: 0.0 })
    }

    pub fn len(&self) -> usize {
        self.cameras.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cameras.is_empty()
    }

    /// Index of the current frame.
    pub fn position(&self) -> usize {
        self.frame
    }

    pub fn first(&self) -> Option<&Camera> {
        self.cameras.first()
    }

    /// The current frame, then moves one frame on; `None` after the last.
    pub fn step(&mut self) -> Option<Camera> {
        let c = self.cameras.get(self.frame).copied();
        if c.is_some() {
            self.frame += 1;
        }
        c
    }

    /// Advances `dt` seconds at the path's fps and returns that frame; `None` after the end.
    pub fn advance(&mut self, dt: f64) -> Option<Camera> {
        self.time += dt.max(0.0);
        self.frame = (self.time * self.fps) as usize;
        self.cameras.get(self.frame).copied()
    }

    pub fn rewind(&mut self) {
        self.frame = 0;
        self.time = 0.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn header() -> Header {
        let mut h: Header = base_header();
        h.grid_origin = [100.0, 200.0, 300.0];
        h
    }

    fn base_header() -> Header {
        Header::empty([100.0, 200.0, 300.0], [110.0, 210.0, 310.0], [0.0; 3], 0.01)
    }

    #[test]
    fn record_then_play_round_trips_through_a_file() {
        let h = header();
        let mut rec = Recorder::default();
        // The last one orthographic.
        let cams: Vec<Camera> = (0..5)
            .map(|i| {
                let projection = if i == 4 {
                    Projection::Orthographic { height: 7.5 }
                } else {
                    Projection::Perspective { fovy: 1.0 }
                };
                Camera::with_projection(
                    Vec3::new(i as f32, 1.0, 2.0),
                    Vec3::new(i as f32 + 1.0, 1.0, 2.0),
                    Vec3::Z,
                    projection,
                    0.01,
                    50.0,
                )
                .unwrap()
            })
            .collect();
        for c in &cams {
            rec.push(c, &h, 0.02);
        }
        let path = rec.finish();
        assert!((path.fps - 50.0).abs() < 1e-6);
        assert_eq!(path.frames[0].eye, [100.0, 201.0, 302.0]);
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("rec.json");
        path.save(&file).unwrap();
        let loaded = CameraPath::load(&file).unwrap();
        let mut p = Player::new(&loaded, &h).unwrap();
        assert_eq!(p.len(), 5);
        for c in &cams {
            let got = p.step().unwrap();
            assert!((got.eye - c.eye).length() < 1e-4 && (got.target - c.target).length() < 1e-4);
            match (got.projection, c.projection) {
                (Projection::Perspective { fovy: a }, Projection::Perspective { fovy: b }) => {
                    assert!((a - b).abs() < 1e-5)
                }
                (a, b) => assert_eq!(a, b),
            }
        }
        assert!(p.step().is_none());
        p.rewind();
        assert_eq!(p.advance(0.05).unwrap().eye, p.cameras[2].eye);
        assert!(p.advance(10.0).is_none());
    }
}
