//! Automatic camera paths for `terawalk path`: an interior walk at eye height through the
//! walkable space of a store, a fly-over above it, joined smoothly, or a fly-around when the
//! model has no walkable space (a scanned statue). Plain data in ([`Store`], [`PathOptions`]),
//! a [`CameraPath`] out; pure CPU, deterministic for a seed.
//!
//! The walk follows Recast's navigation-mesh pipeline (Mononen, *Recast Navigation*: solid
//! heightfield → open spans → walkable filter → agent-radius erosion → regions), on voxels:
//!
//! 1. **Coarse geometry.** The object-space cut of the LOD DAG at `t` = half a voxel (the render
//!    rule of docs/FORMAT.md with an object-space threshold: a cluster is used when
//!    `self_error ≤ t < group.error`), so only coarse pages are decoded, one at a time.
//!    The voxel size is eye height / 8, grown (or the voxelized window shrunk around the scene's
//!    centre) until the grid fits [`PathOptions::max_voxels`]: work and memory are bounded
//!    whatever the store's size.
//! 2. **Conservative voxelization** (Recast's `rasterizeTri`): each triangle is clipped to every
//!    voxel column it overlaps and the column's voxels from the clipped polygon's lowest to
//!    highest point are marked. Columns are bitsets along the up axis.
//! 3. **Open spans**: the free intervals of each column. A flood fill from the grid's padded
//!    border over spans that overlap in 4-neighbour columns finds the *exterior* free space;
//!    free space enclosed by geometry (inside tanks, pipes, a closed statue) counts as solid.
//! 4. **Walkable**: an exterior span with a floor (an occupied voxel below) and room for the eye
//!    height plus 5 %; *eroded* by the agent radius (0.12 eye heights, at least a voxel: a
//!    camera, not a person, so 1 m doors stay open): above step height (a quarter of the eye
//!    height), the body's cylinder must be free in the neighbouring columns too. Walkable spans of 8-neighbour
//!    columns connect when their floors differ by at most a step and their free intervals
//!    overlap by the body height (diagonals also need both orthogonal moves), so stairs work.
//! 5. **Region**: the largest connected region of *covered* walkable spans (something above within
//!    three eye heights: inside buildings, not under a pipe rack); if there is none of useful size, the largest walkable
//!    region in the open; if neither, no walk (the fly-around fallback says why).
//! 6. **Route**: waypoints by farthest-point sampling over graph distances (seeded start),
//!    connected by A* shortest paths whose edge costs grow near the region's border (so walks
//!    keep to the middle of corridors), until the route is as long as the walk needs.
//! 7. **Smoothing**: the route is resampled, Gaussian-smoothed (position and height, so stairs
//!    become ramps), checked against the voxels (a smoothed point that leaves walkable space
//!    halves the smoothing), then resampled at constant walking speed. The look direction
//!    follows the path 1.5 s ahead, smoothed over half a second and limited to 90°/s (a
//!    reversal at a waypoint becomes a two-second turn), with a slow seeded pitch sway.
//!
//! The fly part is one orbit around the scene's centre at about the distance that frames its
//! bounding sphere, elevation 25–45° and distance varying slowly, never below the model's top;
//! after a walk, a Hermite curve rises from the walk's last camera (same velocity) to the orbit
//! (same velocity) over a third of the fly frames, turning the view to the centre by yaw and
//! pitch. (The rise goes through whatever is above the walk: the renderer's near plane cuts
//! the roof for a few frames.)
//!
//! Bounds: the grid holds at most [`PathOptions::max_voxels`] bits (32 MiB by default) plus
//! per-column spans; pages are decoded one at a time per thread; a scene too large for fine
//! voxels is voxelized in a window around its centre (the walk stays in it) and, failing
//! that, with coarser voxels, down to a third of the eye height, below which there is no walk.
//!
//! The approach part ([`PathPart::Approach`]) is separate: from `render`'s overview of the whole
//! model to a close oblique view of its top, the distance shrinking geometrically to an eighth;
//! it needs no walkable space, so nothing is voxelized (see `approach`).
//!
//! Frames are perspective unless [`PathOptions::ortho`] asks for orthographic ones: a fixed
//! view height, or [`OrthoHeight::Framed`], which keeps the sizes the perspective path shows
//! (`orthographic_frames`).
//!
//! Files: `voxels` (steps 1–4: [`WalkGrid`]), `route` (steps 5–7: the region, the route and its
//! smoothing), `cameras` (the look direction, the fly-over, the rise between them and the
//! frames) and `approach`; this file has the options, the report and [`generate_path`], which
//! joins them.

mod approach;
mod cameras;
mod route;
mod voxels;

use tw_core::Rng;
use tw_store::units::{EYE_HEIGHT_M, WALK_SPEED_M_S};
use tw_store::{Store, StoreError};

use crate::path::{CameraPath, PathFrame};
use cameras::View;
use route::{polyline_length, Region};
pub use voxels::{WalkGrid, WalkParams};

/// Which parts the path has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathPart {
    Walk,
    Fly,
    Both,
    /// From the overview of the whole model to a close oblique view (no walk, no fly-over).
    Approach,
}

/// The view height of orthographic path frames ([`PathOptions::ortho`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OrthoHeight {
    /// Every frame this many input units high.
    Fixed(f64),
    /// Each frame as high as the perspective view of [`PathOptions::fovy_deg`] is at the
    /// distance from its eye to what it shows: the approach's target (so the approach still
    /// closes in, its view shrinking to an eighth), the model's centre for the walk and the
    /// fly-over (the orbit looks at it; along a walk the height changes smoothly, the model
    /// shown at the size the fly-over shows it, and the rise joins the two without a jump).
    Framed,
}

/// What to generate. Lengths are in scene (input) units; `None` picks a default from the
/// store's units (metres when it has none).
#[derive(Clone, Debug, PartialEq)]
pub struct PathOptions {
    /// Frames in all (≥ 2).
    pub frames: usize,
    /// Frame rate the path is made for (> 0).
    pub fps: f64,
    pub part: PathPart,
    /// Share of the frames that walk when `part` is [`PathPart::Both`] (0..1, exclusive).
    pub walk_share: f64,
    /// Eye height above the floor; default 1.7 m in the store's units.
    pub eye_height: Option<f64>,
    /// Walking speed, units per second; default 1.4 m/s in the store's units.
    pub speed: Option<f64>,
    /// Vertical field of view, degrees (1..=179).
    pub fovy_deg: f64,
    /// `Some`: orthographic frames of this view height (the eyes and view directions are the
    /// same as without it); `None`: perspective.
    pub ortho: Option<OrthoHeight>,
    pub seed: u64,
    /// Voxel edge; default eye height / 8.
    pub voxel_size: Option<f64>,
    /// Most voxels in the occupancy grid (bounds its memory: one bit each).
    pub max_voxels: u64,
}

impl Default for PathOptions {
    fn default() -> Self {
        PathOptions {
            frames: 600,
            fps: 30.0,
            part: PathPart::Both,
            walk_share: 0.6,
            eye_height: None,
            speed: None,
            fovy_deg: 60.0,
            ortho: None,
            seed: 1,
            voxel_size: None,
            max_voxels: 1 << 28,
        }
    }
}

/// Errors of path generation: bad options (the store's errors are reported per page and do not
/// stop it).
#[derive(Debug, thiserror::Error)]
pub enum PathGenError {
    #[error("{0}")]
    Options(String),
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// The kind of region the walk went through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RegionKind {
    /// Covered walkable space (inside buildings).
    Interior,
    /// Walkable space in the open (no covered region of useful size).
    Outdoor,
}

/// What [`generate_path`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct PathReport {
    pub walk_frames: usize,
    pub fly_frames: usize,
    /// Length travelled by the eye, scene units.
    pub walk_length: f64,
    pub fly_length: f64,
    pub eye_height: f64,
    pub speed: f64,
    /// Why there is no walk although one was asked for (the path is a fly-around instead).
    pub fallback: Option<String>,
    /// The walk's region, when there is a walk.
    pub region: Option<RegionKind>,
    /// Walkable spans in the chosen region, and in all.
    pub region_spans: usize,
    pub walkable_spans: usize,
    pub voxel_size: f64,
    /// Grid dimensions (horizontal, horizontal, up).
    pub grid: [usize; 3],
    /// True when only a window around the centre was voxelized (the scene is too large).
    pub windowed: bool,
    pub pages_read: u64,
    pub pages_failed: u64,
    pub triangles_voxelized: u64,
    /// Waypoints the route visited.
    pub waypoints: usize,
    pub approach_frames: usize,
    pub approach_length: f64,
    /// Distance from the eye to the looked-at point in the approach's first and last frame.
    pub approach_distances: (f64, f64),
}

/// The path and how it was made.
#[derive(Clone, Debug)]
pub struct GeneratedPath {
    pub path: CameraPath,
    pub report: PathReport,
}

/// Metres per unit for a store's units string: the one definition is in tw-store, shared
/// with the viewer's walk mode.
pub use tw_store::units::metres_per_unit;

/// A length for messages: three significant digits at any scale (`16.8`, `0.00212`, `1520`).
pub fn format_length(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let digits = (2 - x.abs().log10().floor() as i64).clamp(0, 15) as usize;
    format!("{x:.digits$}")
}

/// Generates the path (see the module documentation). `progress(stage, done, total)` reports
/// the slow step (reading pages: stage "voxelize").
pub fn generate_path(
    store: &Store,
    options: &PathOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<GeneratedPath, PathGenError> {
    check_options(options)?;
    let (eye, speed) = eye_and_speed(store, options)?;
    let h = store.header();
    let view = View { up: h.up_axis.min(2) as usize, origin: h.grid_origin, fovy: options.fovy_deg };
    let mut rng = Rng::with_stream(options.seed, 0x7061_7468);
    let mut report = PathReport::new(eye, speed);
    if options.part == PathPart::Approach {
        return approach_part(store, options, report);
    }

    // The walk (steps 1–7 of the module documentation), or why there is none.
    let mut walk: Vec<PathFrame> = Vec::new();
    let mut walk_end: Option<WalkEnd> = None;
    let walk_frames = walk_frame_count(options);
    if walk_frames > 0 {
        let spec = WalkSpec { frames: walk_frames, fps: options.fps, eye, speed };
        match walk_part(store, options, &spec, &view, &mut rng, &mut report, progress)? {
            Ok((frames, end)) => {
                walk = frames;
                walk_end = Some(end);
            }
            Err(why) => report.fallback = Some(why),
        }
    }

    // The fly part: the rest of the frames (all of them after a fallback).
    let after_walk = walk_end.map(|end| (end, walk.last()));
    let fly = cameras::fly_over(store, options.frames - walk.len(), after_walk, &view, &mut rng);
    report.fly_frames = fly.len();
    report.fly_length = fly.windows(2).map(|w| route::dist3(w[0].eye, w[1].eye)).sum::<f64>()
        + match (walk.last(), fly.first()) {
            (Some(a), Some(b)) => route::dist3(a.eye, b.eye),
            _ => 0.0,
        };
    report.walk_frames = walk.len();
    walk.extend(fly);
    orthographic_frames(store, options, &mut walk);
    Ok(GeneratedPath { path: CameraPath::new(options.fps, walk), report })
}

/// The approach (see `approach`): all the frames, recorded in `report`.
fn approach_part(
    store: &Store,
    options: &PathOptions,
    mut report: PathReport,
) -> Result<GeneratedPath, PathGenError> {
    let mut a = approach::approach(store, options.frames, options.fovy_deg)?;
    orthographic_frames(store, options, &mut a.frames);
    report.approach_frames = a.frames.len();
    report.approach_length = a.frames.windows(2).map(|w| route::dist3(w[0].eye, w[1].eye)).sum();
    report.approach_distances = (a.start_distance, a.end_distance);
    Ok(GeneratedPath { path: CameraPath::new(options.fps, a.frames), report })
}

/// Makes `frames` orthographic as [`PathOptions::ortho`] says (nothing for `None`): the view
/// height of [`OrthoHeight`] on every frame, its eye, target and field of view kept.
fn orthographic_frames(store: &Store, options: &PathOptions, frames: &mut [PathFrame]) {
    let Some(ortho) = options.ortho else { return };
    let h = store.header();
    let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (h.bounds_min[a] + h.bounds_max[a]));
    let tan = (options.fovy_deg.to_radians() * 0.5).tan();
    for f in frames {
        f.ortho_height = Some(match ortho {
            OrthoHeight::Fixed(height) => height,
            OrthoHeight::Framed => {
                let looked_at = if f.segment == approach::SEGMENT { f.target } else { centre };
                // At least a grid step, however close the eye (a view of no height is refused).
                (2.0 * tan * route::dist3(f.eye, looked_at)).max(h.grid_step)
            }
        });
    }
}

/// Refuses options that cannot make a path: the frame count, frame rate, walk share, field of
/// view and orthographic height.
fn check_options(options: &PathOptions) -> Result<(), PathGenError> {
    let bad = |m: String| Err(PathGenError::Options(m));
    if options.frames < 2 || options.frames > crate::path::MAX_FRAMES {
        return bad(format!("frames must be 2..={}, got {}", crate::path::MAX_FRAMES, options.frames));
    }
    if !(options.fps.is_finite() && options.fps > 0.0 && options.fps <= 1000.0) {
        return bad(format!("fps must be in (0, 1000], got {}", options.fps));
    }
    if !(options.walk_share > 0.0 && options.walk_share < 1.0) {
        return bad(format!(
            "the walk share must be between 0 and 1 (exclusive), got {}",
            options.walk_share
        ));
    }
    if !(1.0..=179.0).contains(&options.fovy_deg) {
        return bad(format!("field of view must be 1..=179 degrees, got {}", options.fovy_deg));
    }
    if let Some(OrthoHeight::Fixed(height)) = options.ortho {
        if !(height.is_finite() && height > 0.0) {
            return bad(format!("the orthographic view height must be a positive number, got {height}"));
        }
    }
    Ok(())
}

/// The eye height and walking speed in the store's units (1.7 m and 1.4 m/s by default, the
/// speed scaled with a given eye height), checked together with the voxel size.
fn eye_and_speed(store: &Store, options: &PathOptions) -> Result<(f64, f64), PathGenError> {
    let bad = |m: String| Err(PathGenError::Options(m));
    let unit = metres_per_unit(store.units());
    let scale = 1.0 / unit.unwrap_or(1.0);
    let eye = options.eye_height.unwrap_or(EYE_HEIGHT_M * scale);
    if !(eye.is_finite() && eye > 0.0) {
        return bad(format!("eye height must be a positive number, got {eye}"));
    }
    let speed = options.speed.unwrap_or(WALK_SPEED_M_S * scale * eye / (EYE_HEIGHT_M * scale));
    if !(speed.is_finite() && speed > 0.0) {
        return bad(format!("speed must be a positive number, got {speed}"));
    }
    if let Some(v) = options.voxel_size {
        if !(v.is_finite() && v > 0.0 && v <= eye / 2.0) {
            return bad(format!(
                "voxel size must be > 0 and at most half the eye height ({}), got {v}",
                eye / 2.0
            ));
        }
    }
    Ok((eye, speed))
}

/// How many of the frames walk.
fn walk_frame_count(options: &PathOptions) -> usize {
    match options.part {
        PathPart::Walk => options.frames,
        PathPart::Fly | PathPart::Approach => 0,
        PathPart::Both => {
            ((options.frames as f64 * options.walk_share).round() as usize).clamp(1, options.frames - 1)
        }
    }
}

impl PathReport {
    /// The report before anything was generated.
    fn new(eye_height: f64, speed: f64) -> PathReport {
        PathReport {
            walk_frames: 0,
            fly_frames: 0,
            walk_length: 0.0,
            fly_length: 0.0,
            eye_height,
            speed,
            fallback: None,
            region: None,
            region_spans: 0,
            walkable_spans: 0,
            voxel_size: 0.0,
            grid: [0; 3],
            windowed: false,
            pages_read: 0,
            pages_failed: 0,
            triangles_voxelized: 0,
            waypoints: 0,
            approach_frames: 0,
            approach_length: 0.0,
            approach_distances: (0.0, 0.0),
        }
    }
}

/// What the walk is made for: its frame count and rate, the eye height and walking speed.
struct WalkSpec {
    frames: usize,
    fps: f64,
    eye: f64,
    speed: f64,
}

/// The last eye of a walk and its velocity per frame.
type WalkEnd = ([f64; 3], [f64; 3]);

/// Steps 1–4 and then the walk: the voxels of the scene (recorded in `report`), then
/// [`walk_path`] through them. The inner error is why there is no walk (the path becomes a
/// fly-around); the outer one, bad options.
fn walk_part(
    store: &Store,
    options: &PathOptions,
    spec: &WalkSpec,
    view: &View,
    rng: &mut Rng,
    report: &mut PathReport,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<Result<(Vec<PathFrame>, WalkEnd), String>, PathGenError> {
    let h = store.header();
    let eye = spec.eye;
    let horiz = [0, 1, 2]
        .into_iter()
        .filter(|&a| a != view.up)
        .map(|a| h.bounds_max[a] - h.bounds_min[a])
        .fold(0.0, f64::max);
    if horiz < 4.0 * eye {
        return Ok(Err(format!(
            "the scene is {} {u} across, less than 4 eye heights ({eye} {u}; units {units:?}): \
             nothing to walk through (give --eye-height in the model's units?)",
            format_length(horiz),
            u = if store.units().is_empty() { "units" } else { store.units() },
            units = store.units(),
        )));
    }
    let params = WalkParams {
        eye_height: eye,
        voxel_size: options.voxel_size.unwrap_or(eye / 8.0),
        max_voxels: options.max_voxels,
    };
    let g = WalkGrid::build(store, &params, &mut |d, t| progress("voxelize", d, t))?;
    tracing::debug!("path: voxels {:.3}, grid {:?}, {} walkable spans", g.v, g.dims(), g.nodes.len());
    report.voxel_size = g.v;
    report.grid = g.dims();
    report.windowed = g.windowed;
    report.pages_read = g.pages_read;
    report.pages_failed = g.pages_failed;
    report.triangles_voxelized = g.triangles;
    report.walkable_spans = g.nodes.len();
    Ok(walk_path(&g, spec, view, rng, report))
}

/// Steps 5–7: the walk frames through the grid's walkable spans, or why there are none. Also
/// returns the last eye and its per-frame velocity.
fn walk_path(
    g: &WalkGrid,
    spec: &WalkSpec,
    view: &View,
    rng: &mut Rng,
    report: &mut PathReport,
) -> Result<(Vec<PathFrame>, WalkEnd), String> {
    if g.v > g.eye / 3.0 {
        return Err(format!(
            "the voxel cap leaves voxels of {}, too coarse for an eye height of {} (raise --max-voxels)",
            format_length(g.v),
            g.eye
        ));
    }
    if g.nodes.is_empty() {
        return Err("no walkable space: no floor with room for the eye height was found".into());
    }
    let (comp, c, kind) = route::choose_region(g)?;
    let region = Region::new(g, &comp, c as u32);
    report.region = Some(kind);
    report.region_spans = region.nodes.len();
    let step = spec.speed / spec.fps;
    let length = step * (spec.frames.max(2) - 1) as f64;
    let (points, waypoints) = route::route(&region, rng, length);
    report.waypoints = waypoints;
    if points.len() < 2 || polyline_length(&points) <= 0.0 {
        return Err("no walkable space: the walkable region is a single spot".into());
    }
    let eyes = route::walk_eyes(g, &points, length, spec.frames);
    report.walk_length = polyline_length(&eyes);
    let heading = cameras::walk_headings(&eyes, spec.fps, view.up, g.v);
    let out = cameras::walk_frames(&eyes, &heading, spec.fps, view, rng);
    let n = eyes.len();
    let vel = if n >= 2 { cameras::sub(eyes[n - 1], eyes[n - 2]) } else { [0.0; 3] };
    Ok((out, (eyes[n - 1], vel)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_have_three_significant_digits() {
        assert_eq!(format_length(16.84), "16.8");
        assert_eq!(format_length(0.0021234), "0.00212");
        assert_eq!(format_length(1516.3), "1516");
        assert_eq!(format_length(0.0), "0");
    }
}
