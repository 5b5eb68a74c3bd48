//! The cameras: step 7's look direction of the walk, the fly-over orbit, the Hermite rise from
//! the walk's end to the orbit, and the [`PathFrame`] each camera becomes (see the
//! [module documentation](super)).

use tw_core::Rng;
use tw_store::Store;

use super::route::{dist3, gaussian, lerp3};
use super::WalkEnd;
use crate::path::PathFrame;

/// How every camera of the path is set up: the scene's up axis, the offset from scene space to
/// the store's coordinates, and the vertical field of view (degrees).
pub(super) struct View {
    pub(super) up: usize,
    pub(super) origin: [f64; 3],
    pub(super) fovy: f64,
}

impl View {
    /// A frame looking from `eye` along `dir` (pitch limited to ±80° so `up` never lines up).
    pub(super) fn frame(&self, eye: [f64; 3], dir: [f64; 3], segment: &str) -> PathFrame {
        frame(eye, dir, self.up, self.origin, self.fovy, segment)
    }
}

/// [`View::frame`] with the view's parts spelled out.
fn frame(
    eye: [f64; 3],
    dir: [f64; 3],
    up_axis: usize,
    origin: [f64; 3],
    fovy: f64,
    segment: &str,
) -> PathFrame {
    let h = [(up_axis + 1) % 3, (up_axis + 2) % 3];
    let horiz = (dir[h[0]].powi(2) + dir[h[1]].powi(2)).sqrt();
    let mut d = dir;
    let max_tan = 80f64.to_radians().tan();
    if horiz < 1e-9 {
        d[h[0]] = 1.0;
        d[h[1]] = 0.0;
        d[up_axis] = dir[up_axis].signum() * max_tan;
    } else if d[up_axis].abs() > horiz * max_tan {
        d[up_axis] = d[up_axis].signum() * horiz * max_tan;
    }
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-300);
    let mut up = [0.0; 3];
    up[up_axis] = 1.0;
    let dist = 10.0;
    PathFrame {
        eye: [0, 1, 2].map(|a| eye[a] + origin[a]),
        target: [0, 1, 2].map(|a| eye[a] + origin[a] + d[a] / len * dist),
        up,
        fovy,
        // Perspective; `--ortho` makes it orthographic afterwards (`orthographic_frames`).
        ortho_height: None,
        segment: segment.to_string(),
    }
}

/// Scene centre and bounding radius (scene space).
fn scene_sphere(store: &Store) -> ([f64; 3], f64) {
    let h = store.header();
    let lo: [f64; 3] = [0, 1, 2].map(|a| h.bounds_min[a] - h.grid_origin[a]);
    let hi: [f64; 3] = [0, 1, 2].map(|a| h.bounds_max[a] - h.grid_origin[a]);
    let c = lerp3(lo, hi, 0.5);
    let r = 0.5 * dist3(lo, hi);
    (c, r.max(h.grid_step * 16.0).max(1e-6))
}

/// Orbit state of the fly part.
struct Orbit {
    centre: [f64; 3],
    dist: f64,
    theta0: f64,
    sense: f64,
    phase: f64,
    up: usize,
    /// The eye never goes below this (the model's top plus a margin).
    min_height: f64,
}

impl Orbit {
    fn eye(&self, u: f64) -> [f64; 3] {
        let theta = self.theta0 + self.sense * std::f64::consts::TAU * u;
        let elev = (35.0 + 10.0 * (std::f64::consts::TAU * u + self.phase).sin()).to_radians();
        let d = self.dist * (0.9 + 0.1 * (std::f64::consts::TAU * 2.0 * u + self.phase).cos());
        let h = [(self.up + 1) % 3, (self.up + 2) % 3];
        let mut p = self.centre;
        p[h[0]] += d * elev.cos() * theta.cos();
        p[h[1]] += d * elev.cos() * theta.sin();
        p[self.up] = (p[self.up] + d * elev.sin()).max(self.min_height);
        p
    }

    /// Starts the orbit above the walk's end `we`, turning the way the walk was heading (`wv`).
    fn start_above(&mut self, we: [f64; 3], wv: [f64; 3]) {
        let hz = [(self.up + 1) % 3, (self.up + 2) % 3];
        let centre = self.centre;
        self.theta0 = (we[hz[1]] - centre[hz[1]]).atan2(we[hz[0]] - centre[hz[0]]);
        let rx = we[hz[0]] - centre[hz[0]];
        let ry = we[hz[1]] - centre[hz[1]];
        let cross = rx * wv[hz[1]] - ry * wv[hz[0]];
        self.sense = if cross < 0.0 { -1.0 } else { 1.0 };
    }
}

/// The fly part: `count` frames of one orbit around the scene's centre at about the distance
/// that frames its bounding sphere; after a walk (its end, and its last frame) the first third
/// of them rise from the walk to the orbit ([`rise`]).
pub(super) fn fly_over(
    store: &Store,
    count: usize,
    after_walk: Option<(WalkEnd, Option<&PathFrame>)>,
    view: &View,
    rng: &mut Rng,
) -> Vec<PathFrame> {
    let h = store.header();
    let up = view.up;
    let (centre, radius) = scene_sphere(store);
    let half_fov = (view.fovy.min(100.0) / 2.0).to_radians();
    let mut orbit = Orbit {
        centre,
        // The bounding sphere fits the view at `radius / sin(fov / 2)`; sites are flatter than
        // their sphere, so come a little closer.
        dist: radius / half_fov.sin() * 0.8,
        theta0: rng.range_f64(0.0, std::f64::consts::TAU),
        sense: 1.0,
        phase: rng.range_f64(0.0, std::f64::consts::TAU),
        up,
        min_height: h.bounds_max[up] - h.grid_origin[up] + 0.1 * radius,
    };
    let mut fly: Vec<PathFrame> = Vec::with_capacity(count);
    if count == 0 {
        return fly;
    }
    let transition = if after_walk.is_some() { (count / 3).max(1).min(count) } else { 0 };
    let orbit_frames = count - transition;
    if let Some(((we, wv), _)) = after_walk {
        orbit.start_above(we, wv);
    }
    let du = 1.0 / (orbit_frames.max(2) - 1) as f64;
    let orbit_at = |i: usize| orbit.eye(i as f64 * du);
    if let Some((end, last)) = after_walk {
        let wdir = last.map(|f| [0, 1, 2].map(|c| f.target[c] - f.eye[c])).unwrap_or([1.0, 0.0, 0.0]);
        fly.extend(rise(end, wdir, (orbit_at(0), orbit_at(1)), transition, centre, view));
    }
    for i in 0..orbit_frames {
        let p = orbit_at(i);
        fly.push(view.frame(p, sub(centre, p), "fly"));
    }
    fly
}

/// The rise from the walk's end (eye and velocity per frame, looking along `wdir`) to the
/// orbit's first two eyes: `frames` frames on a Hermite curve whose velocities match both, the
/// view turning from the walk's direction to `centre` by yaw and pitch.
fn rise(
    (we, wv): WalkEnd,
    wdir: [f64; 3],
    (o0, o1): ([f64; 3], [f64; 3]),
    frames: usize,
    centre: [f64; 3],
    view: &View,
) -> Vec<PathFrame> {
    let up = view.up;
    let n = frames as f64 + 1.0;
    // Hermite from the walk's end to the orbit's start, velocities matched per frame.
    let t0 = wv.map(|c| c * n);
    let t1 = [0, 1, 2].map(|c| (o1[c] - o0[c]) * n);
    let mut out = Vec::with_capacity(frames);
    for k in 1..=frames {
        let u = k as f64 / n;
        let (u2, u3) = (u * u, u * u * u);
        let (h00, h10, h01, h11) =
            (2.0 * u3 - 3.0 * u2 + 1.0, u3 - 2.0 * u2 + u, -2.0 * u3 + 3.0 * u2, u3 - u2);
        let p = [0, 1, 2].map(|c| h00 * we[c] + h10 * t0[c] + h01 * o0[c] + h11 * t1[c]);
        // Turn the view from the walk's to the centre by yaw and pitch (the shorter way
        // round), with a smoothstep: no fast swing even when the two are opposite.
        let s = u2 * (3.0 - 2.0 * u);
        let (y0, p0) = yaw_pitch(wdir, up);
        let (y1, p1) = yaw_pitch(sub(centre, p), up);
        let mut dy = y1 - y0;
        while dy > std::f64::consts::PI {
            dy -= std::f64::consts::TAU;
        }
        while dy < -std::f64::consts::PI {
            dy += std::f64::consts::TAU;
        }
        let d = from_yaw_pitch(y0 + dy * s, p0 + (p1 - p0) * s, up);
        out.push(view.frame(p, d, "fly"));
    }
    out
}

/// Step 7's look direction (yaw per frame) along the walk's `eyes` (voxel size `v`): a
/// look-ahead of about a second and a half of walking, smoothed over half a second, limited to
/// 90°/s (a reversal at a waypoint becomes a two-second turn), then smoothed a little again.
pub(super) fn walk_headings(eyes: &[[f64; 3]], fps: f64, up: usize, v: f64) -> Vec<[f64; 1]> {
    let frames = eyes.len();
    // Headings: a look-ahead of about a second and a half of walking, smoothed over half a second.
    let hz = [(up + 1) % 3, (up + 2) % 3];
    let ahead = ((1.5 * fps) as usize).max(1);
    let mut heading = Vec::with_capacity(frames);
    let mut last = 0.0f64;
    for i in 0..frames {
        let j = (i + ahead).min(frames - 1);
        let d = sub(eyes[j], eyes[i]);
        let a = if d[hz[0]].hypot(d[hz[1]]) > 1e-9 * v { d[hz[1]].atan2(d[hz[0]]) } else { last };
        // Unwrap.
        let mut a = a;
        if i > 0 {
            while a - last > std::f64::consts::PI {
                a -= std::f64::consts::TAU;
            }
            while a - last < -std::f64::consts::PI {
                a += std::f64::consts::TAU;
            }
        } else if d[hz[0]].hypot(d[hz[1]]) <= 1e-9 * v {
            a = 0.0;
        }
        heading.push([a]);
        last = a;
    }
    // Smoothed, then limited to 90°/s (a reversal at a waypoint becomes a two-second turn),
    // then smoothed a little again so the limiter leaves no kinks.
    let heading = gaussian(&heading, fps * 0.5);
    let max_turn = 90f64.to_radians() / fps;
    let mut limited = Vec::with_capacity(frames);
    for (i, a) in heading.iter().enumerate() {
        let a = if i == 0 {
            a[0]
        } else {
            let prev: f64 = limited[i - 1];
            prev + (a[0] - prev).clamp(-max_turn, max_turn)
        };
        limited.push(a);
    }
    gaussian(&limited.iter().map(|&a| [a]).collect::<Vec<_>>(), fps * 0.15)
}

/// The walk's frames: each eye looking along its heading, with a slow seeded pitch sway
/// (−4° ± 3° over seven seconds).
pub(super) fn walk_frames(
    eyes: &[[f64; 3]],
    heading: &[[f64; 1]],
    fps: f64,
    view: &View,
    rng: &mut Rng,
) -> Vec<PathFrame> {
    let phase = rng.range_f64(0.0, std::f64::consts::TAU);
    let mut out = Vec::with_capacity(eyes.len());
    for (i, &eye) in eyes.iter().enumerate() {
        let a = heading[i][0];
        let t = i as f64 / fps;
        let pitch = (-4.0 + 3.0 * (std::f64::consts::TAU * t / 7.0 + phase).sin()).to_radians();
        out.push(view.frame(eye, from_yaw_pitch(a, pitch, view.up), "walk"));
    }
    out
}

/// Yaw (about the up axis) and pitch of a direction.
pub(super) fn yaw_pitch(d: [f64; 3], up: usize) -> (f64, f64) {
    let h = [(up + 1) % 3, (up + 2) % 3];
    (d[h[1]].atan2(d[h[0]]), d[up].atan2(d[h[0]].hypot(d[h[1]])))
}

/// The unit direction of a yaw (about the up axis) and pitch.
pub(super) fn from_yaw_pitch(yaw: f64, pitch: f64, up: usize) -> [f64; 3] {
    let h = [(up + 1) % 3, (up + 2) % 3];
    let mut d = [0.0; 3];
    d[h[0]] = yaw.cos() * pitch.cos();
    d[h[1]] = yaw.sin() * pitch.cos();
    d[up] = pitch.sin();
    d
}

pub(super) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
