//! End-to-end tests of automatic paths (`tw_runtime::pathgen`) on stores built with tw-build: the
//! walk through a generated plant stays at eye height in free space above a floor and moves
//! smoothly; paths are deterministic for a seed; a model with nothing to walk on gets a
//! fly-around; bad options are clear errors; orthographic paths keep the cameras.

use std::path::{Path, PathBuf};

use tw_io::{ImportError, ObjectInfo, SourceSummary, Triangle, TriangleSink, TriangleSource};
use tw_runtime::pathgen::{
    generate_path, OrthoHeight, PathOptions, PathPart, RegionKind, WalkGrid, WalkParams,
};
use tw_store::Store;

/// How every store of these tests is built.
fn build_options() -> tw_build::BuildOptions {
    tw_build::BuildOptions { memory: 256 << 20, ..Default::default() }
}

/// The 50 k-triangle plant (seed 1), built once per process (tw-testkit).
fn plant_path() -> &'static Path {
    tw_testkit::plant(50_000, 1, build_options()).path()
}

/// One closed icosphere (a stand-in for a scanned statue).
struct Sphere([f64; 3], f64);

impl TriangleSource for Sphere {
    fn name(&self) -> String {
        "sphere".into()
    }
    fn progress_total(&self) -> Option<u64> {
        None
    }
    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        sink.object(0, &ObjectInfo::default())?;
        let (v, f) = tw_io::generate::icosphere(self.0, self.1, 4);
        for t in f {
            sink.triangle(&Triangle::new(t.map(|i| v[i as usize]), 0))?;
        }
        Ok(SourceSummary { objects: 1, ..Default::default() })
    }
}

fn sphere_path(r: f64) -> PathBuf {
    // Once per radius, as the tests call it with a small and a large one.
    tw_testkit::once(format!("tw-runtime pathgen sphere {r}"), || {
        tw_testkit::build(Box::new(Sphere([3.0, -2.0, 1.0], r)), &build_options())
    })
    .path
    .clone()
}

const VOXEL: f64 = 0.3;

fn options(frames: usize, seed: u64) -> PathOptions {
    PathOptions { frames, seed, voxel_size: Some(VOXEL), ..Default::default() }
}

fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot: f64 = (0..3).map(|i| a[i] * b[i]).sum();
    let n = |v: [f64; 3]| (0..3).map(|i| v[i] * v[i]).sum::<f64>().sqrt();
    (dot / (n(a) * n(b))).clamp(-1.0, 1.0).acos().to_degrees()
}

fn dir(f: &tw_runtime::PathFrame) -> [f64; 3] {
    [0, 1, 2].map(|i| f.target[i] - f.eye[i])
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
}

#[test]
fn plant_walk_is_at_eye_height_in_free_space_and_smooth() {
    let store = Store::open(plant_path()).unwrap();
    let h = store.header().clone();
    let g = generate_path(&store, &options(300, 3), &mut |_, _, _| {}).unwrap();
    let r = &g.report;
    assert_eq!(r.fallback, None, "{r:?}");
    assert_eq!(r.region, Some(RegionKind::Interior), "{r:?}");
    assert_eq!((r.walk_frames, r.fly_frames), (180, 120));
    assert_eq!(g.path.frames.len(), 300);
    g.path.validate().unwrap();
    let grid = WalkGrid::build(
        &store,
        &WalkParams { eye_height: 1.7, voxel_size: VOXEL, max_voxels: PathOptions::default().max_voxels },
        &mut |_, _| {},
    )
    .unwrap();
    let walk: Vec<_> = g.path.frames.iter().filter(|f| f.segment == "walk").collect();
    assert_eq!(walk.len(), 180);
    let step = r.speed / g.path.fps;
    for (i, f) in walk.iter().enumerate() {
        for a in 0..3 {
            assert!(f.eye[a] >= h.bounds_min[a] && f.eye[a] <= h.bounds_max[a], "frame {i} outside {f:?}");
        }
        let s = [0, 1, 2].map(|a| f.eye[a] - h.grid_origin[a]);
        assert!(!grid.is_occupied(s), "frame {i}: eye in an occupied voxel {f:?}");
        let floor = grid.floor_below(s).unwrap_or_else(|| panic!("frame {i}: no floor below {f:?}"));
        let above = s[2] - floor;
        assert!((above - 1.7).abs() <= 2.5 * VOXEL, "frame {i}: eye {above} above the floor");
        assert_eq!(f.up, [0.0, 0.0, 1.0]);
    }
    for (i, w) in walk.windows(2).enumerate() {
        let d = dist(w[0].eye, w[1].eye);
        assert!(d <= step * 1.05, "frame {i}: moved {d}, walking step {step}");
        let turn = angle(dir(w[0]), dir(w[1]));
        assert!(turn <= 3.5, "frame {i}: turned {turn}° in one frame");
    }
    let length: f64 = walk.windows(2).map(|w| dist(w[0].eye, w[1].eye)).sum();
    assert!(length > 0.8 * step * 179.0, "walk of {length}");
    // The fly part: no jumps, ends above the model looking at it.
    let all = &g.path.frames;
    let fly_steps: Vec<f64> = all[179..].windows(2).map(|w| dist(w[0].eye, w[1].eye)).collect();
    let orbit_max = fly_steps[fly_steps.len() - 60..].iter().cloned().fold(0.0, f64::max);
    assert!(fly_steps.iter().all(|&d| d <= 2.0 * orbit_max), "{fly_steps:?}");
    for f in &all[all.len() - 60..] {
        assert!(f.eye[2] > h.bounds_max[2], "orbit above the model: {f:?}");
    }
    for w in all.windows(2) {
        assert!(angle(dir(&w[0]), dir(&w[1])) <= 10.0, "{w:?}");
    }
}

#[test]
fn paths_are_deterministic_for_a_seed() {
    let store = Store::open(plant_path()).unwrap();
    let a = generate_path(&store, &options(120, 5), &mut |_, _, _| {}).unwrap();
    let b = generate_path(&store, &options(120, 5), &mut |_, _, _| {}).unwrap();
    assert_eq!(a.path, b.path);
    let c = generate_path(&store, &options(120, 6), &mut |_, _, _| {}).unwrap();
    assert_ne!(a.path, c.path);
    let w = generate_path(&store, &PathOptions { part: PathPart::Walk, ..options(50, 5) }, &mut |_, _, _| {})
        .unwrap();
    assert!(w.path.frames.iter().all(|f| f.segment == "walk"));
    let f = generate_path(&store, &PathOptions { part: PathPart::Fly, ..options(50, 5) }, &mut |_, _, _| {})
        .unwrap();
    assert!(f.path.frames.iter().all(|f| f.segment == "fly"));
    assert_eq!(f.report.pages_read, 0, "a fly-over reads no pages");
}

#[test]
fn statues_get_a_fly_around() {
    for (r, why) in [(1.0, "across"), (6.0, "no walkable space")] {
        let store = Store::open(sphere_path(r)).unwrap();
        let g = generate_path(&store, &options(60, 1), &mut |_, _, _| {}).unwrap();
        let msg = g.report.fallback.clone().unwrap_or_default();
        assert!(msg.contains(why), "radius {r}: {:?}", g.report);
        assert_eq!((g.report.walk_frames, g.report.fly_frames), (0, 60));
        g.path.validate().unwrap();
        for f in &g.path.frames {
            assert_eq!(f.segment, "fly");
            let to_centre = [3.0 - f.eye[0], -2.0 - f.eye[1], 1.0 - f.eye[2]];
            assert!(angle(dir(f), to_centre) < 1.0, "looks at the centre");
            assert!(dist(f.eye, [3.0, -2.0, 1.0]) > 1.5 * r, "outside the model");
        }
    }
}

#[test]
fn bad_options_are_clear_errors() {
    let store = Store::open(sphere_path(1.0)).unwrap();
    let d = PathOptions::default();
    for (o, what) in [
        (PathOptions { frames: 1, ..d.clone() }, "frames"),
        (PathOptions { fps: 0.0, ..d.clone() }, "fps"),
        (PathOptions { walk_share: 1.5, ..d.clone() }, "walk share"),
        (PathOptions { eye_height: Some(-1.0), ..d.clone() }, "eye height"),
        (PathOptions { speed: Some(f64::NAN), ..d.clone() }, "speed"),
        (PathOptions { voxel_size: Some(5.0), ..d.clone() }, "voxel size"),
        (PathOptions { fovy_deg: 0.0, ..d.clone() }, "field of view"),
        (PathOptions { ortho: Some(OrthoHeight::Fixed(0.0)), ..d.clone() }, "orthographic view height"),
    ] {
        let e = generate_path(&store, &o, &mut |_, _, _| {}).unwrap_err().to_string();
        assert!(e.contains(what), "{what}: {e}");
    }
}

/// `ortho`: the same path (eyes, targets), orthographic; `Framed` as high as the perspective view
/// at the distance to the model's centre on the walk and the fly-over, changing smoothly from
/// the walk through the rise into the orbit; `Fixed` the given height on every frame.
#[test]
fn orthographic_walks_and_fly_overs_keep_the_path() {
    let store = Store::open(plant_path()).unwrap();
    let perspective = generate_path(&store, &options(120, 5), &mut |_, _, _| {}).unwrap();
    let with = |ortho| PathOptions { ortho: Some(ortho), ..options(120, 5) };
    let framed = generate_path(&store, &with(OrthoHeight::Framed), &mut |_, _, _| {}).unwrap();
    framed.path.validate().unwrap();
    assert!(perspective.report.walk_frames > 0 && perspective.report.fly_frames > 0);
    let h = store.header();
    let centre: [f64; 3] = std::array::from_fn(|a| 0.5 * (h.bounds_min[a] + h.bounds_max[a]));
    let tan = (30f64).to_radians().tan();
    let mut heights = Vec::new();
    let mut eyes = Vec::new();
    for (p, o) in perspective.path.frames.iter().zip(&framed.path.frames) {
        assert_eq!((p.eye, p.target, &p.segment), (o.eye, o.target, &o.segment));
        assert_eq!(p.ortho_height, None);
        let want = 2.0 * tan * dist(o.eye, centre);
        let got = o.ortho_height.unwrap();
        assert!((got - want).abs() < 1e-9 * want, "{o:?}");
        heights.push(got);
        eyes.push(o.eye);
    }
    // No jump where the walk ends or the orbit starts: the height changes no faster than the
    // eye moves (2 tan(fovy / 2) per unit).
    for i in 1..heights.len() {
        let step = 2.0 * tan * dist(eyes[i - 1], eyes[i]);
        assert!((heights[i] - heights[i - 1]).abs() <= step * (1.0 + 1e-9) + 1e-9, "frame {i}: {heights:?}");
    }
    let fixed = generate_path(&store, &with(OrthoHeight::Fixed(25.0)), &mut |_, _, _| {}).unwrap();
    assert!(fixed.path.frames.iter().all(|f| f.ortho_height == Some(25.0)));
    assert!(fixed.path.frames[3].to_scene(h).unwrap().is_orthographic());
}
