//! The approach part (`terawalk path --part approach`): from the overview of the whole model to
//! a close oblique view of it, for benchmarks of level of detail on assemblies, where the cut
//! must refine steadily as the camera closes in (the same file plays in terawalk and in a peer
//! viewer).
//!
//! 1. **Overview.** The first frame is the camera `terawalk render` uses when no `--camera` is
//!    given (`default_camera` in crates/terawalk/src/commands/render.rs): the bounds seen from
//!    the preset `iso` direction (`preset_direction` in crates/terawalk/src/commands/preview.rs,
//!    axes permuted so that its Z is the store's up axis), the eye moved along that direction
//!    until the eight corners of the bounds fit the view with a 5 % margin
//!    (`Camera::frame_bounds` in crates/tw-preview/src/camera.rs), for the path's field of view
//!    and a 16:9 image (`render`'s and `bench`'s default size). That crate sits above this one,
//!    so the framing is computed here again; with `--fovy 40` (the preview's framing field of
//!    view) the first frame is exactly `render`'s default camera.
//! 2. **Point of interest.** The top of the model above its centre, so the close view looks at
//!    geometry, not into the empty middle of the bounds: of the boxes of the leaves (cells) of
//!    the store's spatial hierarchy whose footprint holds the centre, the highest top (a tall
//!    part elsewhere, a chimney beside a hall, does not lift it); when none holds it, the top of
//!    the nearest one at its point nearest the centre. Read from the index only (no page);
//!    with one cell it is the centre of the bounds' top face.
//! 3. **Curve.** With `s` = smoothstep of the frame's time (eased at both ends), the camera looks
//!    at the point between the bounds' centre and the point of interest at `s`, from a distance
//!    that shrinks geometrically from the overview's to an eighth of it (`d = d₀ · 8^−s`: a
//!    constant zoom rate, which feels natural), along a direction that turns 30° about the up
//!    axis and rises from the iso elevation to 35°, so the eye spirals in on a smooth curve and
//!    sees the model from a changing side (parallax for occlusion culling).
//!
//! No randomness: the same store, frame count and field of view give the same path.

use glam::DVec3;
use tw_store::Store;

use super::cameras::{from_yaw_pitch, yaw_pitch};
use super::route::{dist3, lerp3};
use super::PathGenError;
use crate::path::PathFrame;

/// The segment name of every frame of the approach.
pub(super) const SEGMENT: &str = "approach";
/// The close view's distance as a share of the overview's.
pub(super) const ZOOM: f64 = 1.0 / 8.0;
/// How far the view direction turns about the up axis over the approach, degrees.
const YAW_TURN_DEG: f64 = 30.0;
/// Elevation of the close view above the horizontal, degrees.
const END_ELEVATION_DEG: f64 = 35.0;
/// Width / height of the image the overview is framed for (1280 × 720, the default size of
/// `render` and `bench`).
const OVERVIEW_ASPECT: f64 = 16.0 / 9.0;
/// Share of the view the framed corners may fill (the preview's margin).
const FRAME_MARGIN: f64 = 0.95;
/// The `iso` preset's direction from the model towards the eye, in a Z-up frame.
const ISO_DIRECTION: [f64; 3] = [-0.55, -0.75, 0.55];

/// The approach and what it did.
pub(super) struct Approach {
    pub(super) frames: Vec<PathFrame>,
    /// Distance from the eye to the looked-at point in the first and the last frame.
    pub(super) start_distance: f64,
    pub(super) end_distance: f64,
}

/// `count` frames (≥ 2) of the approach to `store`'s model, with vertical field of view `fovy`
/// (degrees); an error when the store has no bounds to frame.
pub(super) fn approach(store: &Store, count: usize, fovy: f64) -> Result<Approach, PathGenError> {
    let h = store.header();
    let (lo, hi) = (h.bounds_min, h.bounds_max);
    if !(lo.iter().chain(&hi).all(|v| v.is_finite()) && (0..3).all(|a| lo[a] <= hi[a])) {
        return Err(PathGenError::Options(format!(
            "the store's bounds ({lo:?} to {hi:?}) hold no geometry: nothing to approach"
        )));
    }
    let up = h.up_axis.min(2) as usize;
    let dir0 = iso_direction(up);
    let centre = lerp3(lo, hi, 0.5);
    let d0 = overview_distance(lo, hi, dir0, up, fovy);
    let poi = point_of_interest(store, up);
    let (yaw0, pitch0) = yaw_pitch(dir0, up);
    let pitch1 = END_ELEVATION_DEG.to_radians().max(pitch0);
    let mut upv = [0.0; 3];
    upv[up] = 1.0;
    let frames = (0..count)
        .map(|i| {
            let t = i as f64 / (count.max(2) - 1) as f64;
            let s = t * t * (3.0 - 2.0 * t);
            let target = lerp3(centre, poi, s);
            let dir = if i == 0 {
                dir0
            } else {
                from_yaw_pitch(yaw0 + YAW_TURN_DEG.to_radians() * s, pitch0 + (pitch1 - pitch0) * s, up)
            };
            let d = d0 * ZOOM.powf(s);
            PathFrame {
                eye: [0, 1, 2].map(|a| target[a] + dir[a] * d),
                target,
                up: upv,
                fovy,
                // Perspective; `--ortho` makes it orthographic afterwards (`orthographic_frames`).
                ortho_height: None,
                segment: SEGMENT.to_string(),
            }
        })
        .collect::<Vec<_>>();
    // As measured on the frames (what a reader of the file sees), not as planned.
    let distance = |f: Option<&PathFrame>| f.map_or(d0, |f| dist3(f.eye, f.target));
    let (start_distance, end_distance) = (distance(frames.first()), distance(frames.last()));
    Ok(Approach { frames, start_distance, end_distance })
}

/// Step 2 of the module documentation: the top of the leaf boxes above the bounds' centre
/// (input coordinates).
pub(super) fn point_of_interest(store: &Store, up: usize) -> [f64; 3] {
    let h = store.header();
    let (lo, hi) = (h.bounds_min, h.bounds_max);
    let centre = lerp3(lo, hi, 0.5);
    let hz = [(up + 1) % 3, (up + 2) % 3];
    // (horizontal distance from the centre, top, nearest point) of the best leaf so far.
    let mut best: Option<(f64, f64, [f64; 3])> = None;
    for node in store.nodes().iter().filter(|n| n.child_count == 0) {
        let to_input = |g: [u32; 3]| {
            [0, 1, 2].map(|a| (h.grid_origin[a] + g[a] as f64 * h.grid_step).clamp(lo[a], hi[a]))
        };
        let (bmin, bmax) = (to_input(node.min), to_input(node.max));
        let mut p = centre;
        for a in hz {
            p[a] = centre[a].clamp(bmin[a], bmax[a]);
        }
        let off = (p[hz[0]] - centre[hz[0]]).hypot(p[hz[1]] - centre[hz[1]]);
        let better = match best {
            None => true,
            Some((o, top, _)) => off < o || (off == o && bmax[up] > top),
        };
        if better && off.is_finite() && bmax[up].is_finite() {
            p[up] = bmax[up];
            best = Some((off, bmax[up], p));
        }
    }
    best.map_or_else(
        || {
            let mut top = centre;
            top[up] = hi[up];
            top
        },
        |(_, _, p)| p,
    )
}

/// The `iso` preset's unit direction from the model towards the eye, its Z made the `up` axis
/// (the permutation of `preset_direction` in crates/terawalk/src/commands/preview.rs).
pub(super) fn iso_direction(up: usize) -> [f64; 3] {
    let v = ISO_DIRECTION;
    let d = match up {
        0 => [v[2], v[0], v[1]],
        1 => [v[0], v[2], -v[1]],
        _ => v,
    };
    let len = dist3(d, [0.0; 3]);
    d.map(|c| c / len)
}

/// Distance from the bounds' centre along `dir` (unit, towards the eye) at which the eight
/// corners of `lo..hi` fit a `fovy`-degree view of a 16:9 image with a 5 % margin (step 1 of
/// the module documentation); the bounding sphere's distance when the corners give none (a
/// box of one point).
fn overview_distance(lo: [f64; 3], hi: [f64; 3], dir: [f64; 3], up: usize, fovy: f64) -> f64 {
    let half = (fovy.clamp(1.0, 170.0) * 0.5).to_radians();
    let radius = 0.5 * dist3(lo, hi);
    let sphere = if radius > 0.0 { radius } else { 1.0 } / half.sin() * 1.02;
    // The view basis: forward (towards the centre), up made orthogonal to it, right = f × u.
    let forward = -DVec3::from(dir);
    let mut upv = DVec3::ZERO;
    upv[up] = 1.0;
    let u = normalized(upv - forward * upv.dot(forward));
    let right = forward.cross(u);
    let tan_y = half.tan() * FRAME_MARGIN;
    let tan_x = tan_y * OVERVIEW_ASPECT;
    let centre = DVec3::from(lerp3(lo, hi, 0.5));
    let mut distance: f64 = 0.0;
    for i in 0..8 {
        let corner = [0, 1, 2].map(|a| if i & (1 << a) == 0 { lo[a] } else { hi[a] });
        let c = DVec3::from(corner) - centre;
        // The eye is at centre − forward · d; the corner's depth is d + c · forward.
        let need_x = c.dot(right).abs() / tan_x - c.dot(forward);
        let need_y = c.dot(u).abs() / tan_y - c.dot(forward);
        distance = distance.max(need_x).max(need_y);
    }
    if distance.is_finite() && distance > 0.0 {
        distance
    } else {
        sphere
    }
}

/// `a` scaled to unit length (`a` is never zero here: the iso direction is never vertical).
/// Divides by the length, as the paths were always made, rather than multiplying by its
/// reciprocal (`DVec3::normalize`), which can differ in the last bit.
fn normalized(a: DVec3) -> DVec3 {
    a / a.length()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::path::CameraPath;
    use crate::pathgen::{generate_path, PathOptions, PathPart};

    /// A small generated plant built into a store with `up` as its up axis.
    fn plant_store(up: u8) -> (tempfile::TempDir, Store) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plant.tw");
        let params = tw_io::generate::PlantParams { triangles: 10_000, seed: 3 };
        let src = tw_io::generate::PlantSource::new(params).unwrap();
        let scene = tw_io::Scene::from_sources(vec![Box::new(src)]);
        let options = tw_build::BuildOptions {
            memory: 128 << 20,
            up: tw_io::up::UpRequest::Axis(up),
            ..Default::default()
        };
        tw_build::build(scene, &path, &options, &mut tw_build::NoProgress).unwrap();
        let store = Store::open(&path).unwrap();
        (dir, store)
    }

    fn approach_of(store: &Store, frames: usize, seed: u64) -> crate::pathgen::GeneratedPath {
        let options = PathOptions { frames, seed, part: PathPart::Approach, ..Default::default() };
        generate_path(store, &options, &mut |_, _, _| {}).unwrap()
    }

    /// The first frame looks at the bounds' centre from the iso direction, and the bounds'
    /// corners just fit a 16:9 view with the margin (at least one on its edge, none outside).
    fn assert_overview(store: &Store, f: &PathFrame) {
        let h = store.header();
        let up = h.up_axis as usize;
        let centre = lerp3(h.bounds_min, h.bounds_max, 0.5);
        assert!(dist3(f.target, centre) < 1e-9 * dist3(f.eye, centre), "{f:?}");
        let d = dist3(f.eye, f.target);
        let eye = DVec3::from(f.eye);
        let to_eye = (eye - DVec3::from(f.target)) / d;
        assert!(dist3(to_eye.to_array(), iso_direction(up)) < 1e-12, "{to_eye:?}");
        assert!(to_eye[up] > 0.0, "the overview looks down: {to_eye:?}");
        let forward = -to_eye;
        let fup = DVec3::from(f.up);
        let u = normalized(fup - forward * fup.dot(forward));
        let right = forward.cross(u);
        let tan_y = (f.fovy.to_radians() / 2.0).tan() * FRAME_MARGIN;
        let mut fill: f64 = 0.0;
        for i in 0..8 {
            let corner = [0, 1, 2].map(|a| if i & (1 << a) == 0 { h.bounds_min[a] } else { h.bounds_max[a] });
            let c = DVec3::from(corner) - eye;
            let depth = c.dot(forward);
            assert!(depth > 0.0, "corner {i} behind the eye");
            fill = fill
                .max(c.dot(u).abs() / depth / tan_y)
                .max(c.dot(right).abs() / depth / (tan_y * 16.0 / 9.0));
        }
        assert!((fill - 1.0).abs() < 1e-9, "the corners fill {fill} of the margin");
    }

    #[test]
    fn approach_starts_at_the_overview_and_closes_in_to_an_eighth() {
        for up in [2u8, 1] {
            let (_dir, store) = plant_store(up);
            let g = approach_of(&store, 120, 1);
            let frames = &g.path.frames;
            assert_eq!(frames.len(), 120);
            assert_eq!((g.report.approach_frames, g.report.walk_frames, g.report.fly_frames), (120, 0, 0));
            g.path.validate().unwrap();
            assert!(frames.iter().all(|f| f.segment == SEGMENT));
            assert_overview(&store, &frames[0]);
            let h = store.header();
            let up = up as usize;
            // The distance to the looked-at point shrinks at every frame, to an eighth.
            let d: Vec<f64> = frames.iter().map(|f| dist3(f.eye, f.target)).collect();
            assert!(d.windows(2).all(|w| w[1] < w[0]), "{d:?}");
            assert!((d[119] / d[0] - ZOOM).abs() < 1e-9, "{} / {}", d[119], d[0]);
            assert_eq!(g.report.approach_distances, (d[0], d[119]));
            // The close view looks down at the point of interest, obliquely.
            let last = &frames[119];
            let poi = point_of_interest(&store, up);
            assert!(dist3(last.target, poi) < 1e-9 * d[0], "{last:?}");
            assert!(frames.iter().all(|f| f.eye[up] > h.bounds_min[up]));
            let rise = (last.eye[up] - poi[up]) / d[119];
            assert!((rise - END_ELEVATION_DEG.to_radians().sin()).abs() < 1e-9, "{rise}");
            // Smooth: eased at both ends (slow steps there), no jumps in between.
            let steps: Vec<f64> = frames.windows(2).map(|w| dist3(w[0].eye, w[1].eye)).collect();
            let max = steps.iter().cloned().fold(0.0, f64::max);
            assert!(steps[0] < 0.05 * max && steps[118] < 0.05 * max, "{steps:?}");
            assert!(steps.windows(2).all(|w| (w[1] - w[0]).abs() < 0.1 * max), "{steps:?}");
            assert!((g.report.approach_length - steps.iter().sum::<f64>()).abs() < 1e-9 * d[0]);
        }
    }

    /// `--ortho auto` on the approach: the same eyes and targets, each frame as high as the
    /// perspective view at its target (so the view shrinks to an eighth); `--ortho 40`: 40 high.
    #[test]
    fn orthographic_approaches_keep_the_cameras_and_frame_the_target() {
        use crate::pathgen::OrthoHeight;
        let (_dir, store) = plant_store(2);
        let perspective = approach_of(&store, 60, 1);
        assert!(perspective.path.frames.iter().all(|f| f.ortho_height.is_none()));
        let ortho = |ortho| {
            let options = PathOptions {
                frames: 60,
                seed: 1,
                part: PathPart::Approach,
                ortho: Some(ortho),
                ..Default::default()
            };
            generate_path(&store, &options, &mut |_, _, _| {}).unwrap()
        };
        let framed = ortho(OrthoHeight::Framed);
        framed.path.validate().unwrap();
        let tan = (30f64).to_radians().tan();
        for (p, o) in perspective.path.frames.iter().zip(&framed.path.frames) {
            assert_eq!((p.eye, p.target, p.up, p.fovy), (o.eye, o.target, o.up, o.fovy));
            let want = 2.0 * tan * dist3(p.eye, p.target);
            assert!((o.ortho_height.unwrap() - want).abs() < 1e-9 * want, "{o:?}");
        }
        let h: Vec<f64> = framed.path.frames.iter().map(|f| f.ortho_height.unwrap()).collect();
        assert!((h[59] / h[0] - ZOOM).abs() < 1e-9, "{} / {}", h[59], h[0]);
        // The camera the viewer, render and bench get from the file is orthographic.
        let cam = framed.path.frames[0].to_scene(store.header()).unwrap();
        assert_eq!(cam.projection, crate::Projection::Orthographic { height: h[0] as f32 });
        let fixed = ortho(OrthoHeight::Fixed(40.0));
        assert!(fixed.path.frames.iter().all(|f| f.ortho_height == Some(40.0)));
    }

    #[test]
    fn the_point_of_interest_is_the_roof_at_the_centre_not_the_chimney() {
        let (_dir, store) = plant_store(2);
        let h = store.header();
        let poi = point_of_interest(&store, 2);
        let centre = lerp3(h.bounds_min, h.bounds_max, 0.5);
        assert_eq!((poi[0], poi[1]), (centre[0], centre[1]));
        // The plant's hall stands at the centre and its chimney, the tallest part, beside it:
        // the close view looks at the hall's roof, well below the top of the bounds.
        assert!(
            poi[2] > h.bounds_min[2] && poi[2] < h.bounds_max[2] - 0.25 * (h.bounds_max[2] - h.bounds_min[2])
        );
        // On a leaf box's top.
        let on_top = store.nodes().iter().filter(|n| n.child_count == 0).any(|n| {
            let top = h.grid_origin[2] + n.max[2] as f64 * h.grid_step;
            (top.min(h.bounds_max[2]) - poi[2]).abs() < 1e-9
        });
        assert!(on_top, "{poi:?}");
    }

    #[test]
    fn approach_is_deterministic_and_reads_no_pages() {
        let (_dir, store) = plant_store(2);
        let a = approach_of(&store, 30, 1);
        let b = approach_of(&store, 30, 9);
        assert_eq!(a.path, b.path);
        assert_eq!(a.report.pages_read, 0);
        let json = serde_json::to_string(&a.path).unwrap();
        let back = CameraPath::parse(json.as_bytes()).unwrap();
        assert_eq!(back.frames.len(), 30);
        // Two frames: the overview and the close view.
        let two = approach_of(&store, 2, 1);
        assert_eq!(two.path.frames[0], a.path.frames[0]);
        let (d0, d1) = two.report.approach_distances;
        assert!((d1 / d0 - ZOOM).abs() < 1e-9);
    }
}
