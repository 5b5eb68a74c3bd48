//! Prefetching: the views whose pages the next frames will need (Manocha, "Interactive display
//! of complex environments", §5.5: once the current frame's objects are fetched, the I/O process
//! spends the rest of the frame prefetching objects for subsequent frames, using frame-to-frame
//! coherence).
//!
//! Two views beside the current one, both selected over the same residency snapshot and
//! requested at a lower priority than the frame's own pages ([`crate::stream::Streamer`]):
//!
//! 1. **Turning and approaching**: the current camera with a field of view enlarged by
//!    `fov_scale` (pages just outside the screen) and the threshold scaled by `tau_scale`
//!    (τ/2: the next finer level, needed as the viewer comes closer).
//! 2. **Moving**: the camera extrapolated `frames_ahead` frames from the last two frames'
//!    cameras (eye and target moved linearly), with the enlarged field of view. Skipped when
//!    the camera did not move or the extrapolation gives an invalid camera.

use crate::camera::Camera;
use crate::select::SelectOptions;

/// What to prefetch (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PrefetchOptions {
    pub enabled: bool,
    /// How far ahead the camera is extrapolated, in frames.
    pub frames_ahead: f32,
    /// Field of view scale of the prefetch views (clamped below 179°).
    pub fov_scale: f32,
    /// Threshold scale of the "next finer level" view.
    pub tau_scale: f32,
    /// Prefetch only when the frame requests at most this many pages of its own (the loaders
    /// are "idle enough").
    pub idle_below: usize,
    /// Select the prefetch views every this many frames (≥ 1); the frames between submit the
    /// last prefetch list again (less the pages that arrived). The views look `frames_ahead`
    /// frames ahead, so one selection serves the frames until then: frame-to-frame coherence
    /// instead of two extra traversals a frame.
    pub every: u32,
}

impl Default for PrefetchOptions {
    fn default() -> Self {
        PrefetchOptions {
            enabled: true,
            frames_ahead: 3.0,
            fov_scale: 1.2,
            tau_scale: 0.5,
            idle_below: 8,
            every: 3,
        }
    }
}

/// The cameras of the last two frames.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraHistory {
    previous: Option<Camera>,
    last: Option<Camera>,
}

impl CameraHistory {
    /// Records the camera of a frame.
    pub fn push(&mut self, camera: Camera) {
        self.previous = self.last.replace(camera);
    }

    /// Forgets the history (after a teleport, say).
    pub fn clear(&mut self) {
        *self = CameraHistory::default();
    }

    /// `current` extrapolated `frames` frames ahead from the last recorded camera: eye and
    /// target keep moving by `current − last` per frame. `None` when there is no history, the
    /// camera did not move, or the result is not a valid camera.
    pub fn extrapolate(&self, current: &Camera, frames: f32) -> Option<Camera> {
        let last = self.last?;
        let (de, dt) = (current.eye - last.eye, current.target - last.target);
        if de.length_squared() == 0.0 && dt.length_squared() == 0.0 {
            return None;
        }
        let c = Camera { eye: current.eye + de * frames, target: current.target + dt * frames, ..*current };
        c.validate().ok().map(|_| c)
    }

    /// The camera before the last one, if any.
    pub fn previous(&self) -> Option<Camera> {
        self.previous
    }
}

/// The prefetch views for a frame seen by `current` with `options` (see the module
/// documentation), given the cameras of the frames before it.
pub fn prefetch_views(
    current: &Camera,
    history: &CameraHistory,
    options: &SelectOptions,
    prefetch: &PrefetchOptions,
) -> Vec<(Camera, SelectOptions)> {
    if !prefetch.enabled {
        return Vec::new();
    }
    let widen = |c: &Camera| Camera { projection: c.projection.widened(prefetch.fov_scale), ..*c };
    let mut out = Vec::new();
    let wide = widen(current);
    if wide.validate().is_ok() {
        out.push((wide, SelectOptions { tau: options.tau * prefetch.tau_scale, ..*options }));
    }
    if let Some(ahead) = history.extrapolate(current, prefetch.frames_ahead) {
        let ahead = widen(&ahead);
        if ahead.validate().is_ok() {
            out.push((ahead, *options));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn cam(x: f32) -> Camera {
        Camera::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x + 1.0, 0.0, 0.0), Vec3::Z, 1.0, 0.01, 100.0).unwrap()
    }

    #[test]
    fn extrapolates_linearly_and_needs_motion() {
        let mut h = CameraHistory::default();
        assert!(h.extrapolate(&cam(0.0), 3.0).is_none(), "no history");
        h.push(cam(0.0));
        assert!(h.extrapolate(&cam(0.0), 3.0).is_none(), "no motion");
        let a = h.extrapolate(&cam(1.0), 3.0).unwrap();
        assert_eq!(a.eye, Vec3::new(4.0, 0.0, 0.0));
        assert_eq!(a.target, Vec3::new(5.0, 0.0, 0.0));
    }

    #[test]
    fn views_are_wider_and_finer() {
        let mut h = CameraHistory::default();
        let o = SelectOptions::default();
        let p = PrefetchOptions::default();
        let v = prefetch_views(&cam(0.0), &h, &o, &p);
        assert_eq!(v.len(), 1);
        assert_eq!(v[0].0.projection, crate::camera::Projection::Perspective { fovy: 1.2 });
        assert_eq!(v[0].1.tau, 0.5);
        h.push(cam(0.0));
        assert_eq!(prefetch_views(&cam(1.0), &h, &o, &p).len(), 2);
        assert!(prefetch_views(&cam(1.0), &h, &o, &PrefetchOptions { enabled: false, ..p }).is_empty());
    }
}
