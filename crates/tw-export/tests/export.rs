//! End to end over a store built from a generated plant: the GLB of a cut and of a region read
//! back through tw-io's glTF importer, and the tileset's structure.

use std::path::Path;

use tw_export::cut::Region;
use tw_export::{export_glb, export_tiles, GlbSelection, TilesOptions};
use tw_io::format::{open_source, ImportOptions};
use tw_io::{ImportError, ObjectId, ObjectInfo, Triangle, TriangleSink};
use tw_runtime::{Camera, PageCache};
use tw_store::Store;

/// A 30k-triangle plant (seed 1) built with this up axis and these units, once per process
/// for each (tw-testkit).
fn build_plant(up: u8, units: &str) -> &'static tw_testkit::Built {
    let options = tw_build::BuildOptions {
        memory: 256 << 20,
        up: tw_io::up::UpRequest::Axis(up),
        units: units.into(),
        ..Default::default()
    };
    tw_testkit::plant(30_000, 1, options)
}

/// The plant as generated (z-up, no units), built once for all tests.
fn plant() -> &'static Path {
    build_plant(2, "").path()
}

/// What the importer reads back: triangles, their bounds, object names.
#[derive(Default)]
struct ReadBack {
    triangles: u64,
    min: [f64; 3],
    max: [f64; 3],
    names: Vec<String>,
}

impl TriangleSink for ReadBack {
    fn object(&mut self, _: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        self.names.push(info.name.clone());
        Ok(())
    }
    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        if self.triangles == 0 {
            self.min = [f64::INFINITY; 3];
            self.max = [f64::NEG_INFINITY; 3];
        }
        self.triangles += 1;
        for p in t.positions {
            for (a, v) in p.into_iter().enumerate() {
                self.min[a] = self.min[a].min(v);
                self.max[a] = self.max[a].max(v);
            }
        }
        Ok(())
    }
}

fn read_back(path: &Path) -> ReadBack {
    let mut r = ReadBack::default();
    open_source(path, &ImportOptions::default()).unwrap().stream(&mut r).unwrap();
    r
}

/// The plant is z-up: glTF's importer gives (x, y, z) back as (x, z, −y).
fn z_up_to_y_up(min: [f64; 3], max: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    ([min[0], min[2], -max[1]], [max[0], max[2], -min[1]])
}

fn assert_close(got: [f64; 3], want: [f64; 3], tol: f64, what: &str) {
    for a in 0..3 {
        assert!((got[a] - want[a]).abs() <= tol, "{what}: {got:?} vs {want:?}");
    }
}

/// A camera that sees the whole plant from outside, obliquely.
fn overview(store: &Store) -> Camera {
    let h = store.header();
    let c: Vec<f64> = (0..3).map(|a| (h.bounds_min[a] + h.bounds_max[a]) / 2.0).collect();
    let d = (0..3).map(|a| (h.bounds_max[a] - h.bounds_min[a]).powi(2)).sum::<f64>().sqrt();
    let eye = [c[0] + 1.5 * d, c[1] + 1.5 * d, c[2] + 1.5 * d];
    Camera::from_input_coordinates(eye, [c[0], c[1], c[2]], [0.0, 0.0, 1.0], 60.0, h).unwrap()
}

#[test]
fn cut_at_zero_pixel_error_is_every_input_triangle() {
    let store = Store::open(plant()).unwrap();
    let cache = PageCache::new(&store, 64 << 20);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cut.glb");
    let selection = GlbSelection::Camera { camera: overview(&store), tau: 0.0, viewport: [1280, 720] };
    let e = export_glb(&store, &cache, &selection, &out).unwrap();
    let h = store.header();
    assert_eq!(e.file.triangles, h.input_triangles);
    let r = read_back(&out);
    assert_eq!(r.triangles, h.input_triangles);
    let (min, max) = z_up_to_y_up(h.bounds_min, h.bounds_max);
    // Positions are grid points, within half a step of the input (and f32 in the file).
    let tol = h.grid_step + 1e-4 * (max[0] - min[0]).abs().max(1.0);
    assert_close(r.min, min, tol, "min");
    assert_close(r.max, max, tol, "max");
    // Objects keep their names from the store's object table.
    let names: Vec<&str> = store.objects().iter().map(|o| o.name.as_str()).collect();
    assert!(r.names.iter().all(|n| names.contains(&n.as_str())), "{:?}", &r.names[..3]);
}

#[test]
fn coarser_pixel_error_exports_fewer_triangles() {
    let store = Store::open(plant()).unwrap();
    let cache = PageCache::new(&store, 64 << 20);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cut.glb");
    let selection = GlbSelection::Camera { camera: overview(&store), tau: 8.0, viewport: [1280, 720] };
    let e = export_glb(&store, &cache, &selection, &out).unwrap();
    assert!(e.file.triangles > 0 && e.file.triangles < store.header().input_triangles, "{e:?}");
    assert_eq!(read_back(&out).triangles, e.file.triangles);
    let bad = GlbSelection::Camera { camera: overview(&store), tau: f32::NAN, viewport: [1280, 720] };
    assert!(export_glb(&store, &cache, &bad, &out).is_err());
}

#[test]
fn region_exports_only_the_full_detail_triangles_inside_it() {
    let store = Store::open(plant()).unwrap();
    let cache = PageCache::new(&store, 64 << 20);
    let h = store.header();
    let dir = tempfile::tempdir().unwrap();
    // The whole bounds: everything.
    let all = Region { min: h.bounds_min, max: h.bounds_max };
    let out = dir.path().join("all.glb");
    let e = export_glb(&store, &cache, &GlbSelection::Region(all), &out).unwrap();
    assert_eq!(e.file.triangles, h.input_triangles);
    // The lower-x, lower-y quarter: some triangles, all inside.
    let mid = |a: usize| (h.bounds_min[a] + h.bounds_max[a]) / 2.0;
    let quarter = Region { min: h.bounds_min, max: [mid(0), mid(1), h.bounds_max[2]] };
    let out = dir.path().join("quarter.glb");
    let e = export_glb(&store, &cache, &GlbSelection::Region(quarter), &out).unwrap();
    assert!(e.file.triangles > 0 && e.file.triangles < h.input_triangles, "{e:?}");
    assert!(e.outside > 0, "{e:?}");
    let r = read_back(&out);
    assert_eq!(r.triangles, e.file.triangles);
    let (min, max) = z_up_to_y_up(quarter.min, quarter.max);
    let tol = 1e-6 * (h.bounds_max[0] - h.bounds_min[0]).abs().max(1.0);
    for a in 0..3 {
        assert!(
            r.min[a] >= min[a] - tol && r.max[a] <= max[a] + tol,
            "{:?}..{:?} in {min:?}..{max:?}",
            r.min,
            r.max
        );
    }
    // A region away from the model: a valid file without triangles.
    let far = Region { min: [1e6; 3], max: [1e6 + 1.0; 3] };
    let e = export_glb(&store, &cache, &GlbSelection::Region(far), &dir.path().join("none.glb")).unwrap();
    assert_eq!(e.file.triangles, 0);
}

#[test]
fn region_parse_errors_say_what_is_wrong() {
    assert_eq!(Region::parse("0,0,0,1,2,3").unwrap(), Region { min: [0.0; 3], max: [1.0, 2.0, 3.0] });
    for (bad, why) in [
        ("0,0,0,1,2", "5 numbers"),
        ("0,0,0,1,2,x", "expected minx"),
        ("2,0,0,1,1,1", "above"),
        ("0,0,0,1,1,inf", "finite"),
    ] {
        let e = Region::parse(bad).unwrap_err().to_string();
        assert!(e.contains(why) && e.contains(bad), "{bad}: {e}");
    }
}

/// Checks a tile and its subtree; returns (tiles, leaf triangles are not counted here).
fn check_tile(dir: &Path, tile: &serde_json::Value, parent: Option<(f64, &[f64])>) -> usize {
    let error = tile["geometricError"].as_f64().unwrap();
    let b: Vec<f64> =
        tile["boundingVolume"]["box"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(b.len(), 12);
    assert_eq!(tile["refine"], "REPLACE");
    let uri = tile["content"]["uri"].as_str().unwrap();
    assert!(dir.join(uri).is_file(), "{uri}");
    if let Some((pe, pb)) = parent {
        assert!(error < pe, "child error {error} not below its parent's {pe}");
        // Axis-aligned boxes: centre ± half sizes on the diagonal.
        for a in 0..3 {
            let (c, h) = (b[a], b[3 + 4 * a]);
            let (pc, ph) = (pb[a], pb[3 + 4 * a]);
            let tol = 1e-9 * (1.0 + pc.abs() + ph);
            assert!(
                c - h >= pc - ph - tol && c + h <= pc + ph + tol,
                "axis {a}: child box {b:?} outside {pb:?}"
            );
        }
    }
    let mut n = 1;
    if let Some(children) = tile.get("children").and_then(|c| c.as_array()) {
        assert!(error > 0.0);
        for c in children {
            n += check_tile(dir, c, Some((error, &b)));
        }
    } else {
        assert_eq!(error, 0.0, "a leaf is full detail");
    }
    n
}

#[test]
fn tileset_is_well_formed_and_refines_to_full_detail() {
    let store = Store::open(plant()).unwrap();
    let cache = PageCache::new(&store, 64 << 20);
    for tile_triangles in [64_000, 2_000] {
        let dir = tempfile::tempdir().unwrap();
        let s = export_tiles(&store, &cache, dir.path(), &TilesOptions { tile_triangles }).unwrap();
        let text = std::fs::read_to_string(dir.path().join("tileset.json")).unwrap();
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(json["asset"]["version"], "1.1");
        assert!(json["geometricError"].as_f64().unwrap() >= json["root"]["geometricError"].as_f64().unwrap());
        let n = check_tile(dir.path(), &json["root"], None);
        assert_eq!(n, s.tiles);
        let files = std::fs::read_dir(dir.path().join("tiles")).unwrap().count();
        assert_eq!(files, s.tiles, "one file per tile, no temporaries");
        // The root tile is the coarsest cut: far fewer triangles than the input.
        let root = read_back(&dir.path().join(json["root"]["content"]["uri"].as_str().unwrap()));
        assert!(
            root.triangles > 0 && root.triangles < store.header().input_triangles / 2,
            "{}",
            root.triangles
        );
        eprintln!("tile_triangles {tile_triangles}: {s:?}");
        if tile_triangles == 2_000 {
            assert!(s.depth >= 3, "{s:?}");
        }
    }
}

/// A store recorded as y-up is already glTF's frame: the GLB comes back as stored, and the
/// tileset's boxes turn its +Y to +Z.
#[test]
fn a_y_up_store_exports_unturned_and_stands_up_in_the_tileset() {
    let built = build_plant(1, "");
    let store = Store::open(&built.path).unwrap();
    let cache = PageCache::new(&store, 64 << 20);
    let h = store.header();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("all.glb");
    let all = Region { min: h.bounds_min, max: h.bounds_max };
    export_glb(&store, &cache, &GlbSelection::Region(all), &out).unwrap();
    let r = read_back(&out);
    assert_eq!(r.triangles, h.input_triangles);
    assert_close(r.min, h.bounds_min, 1e-4, "min");
    assert_close(r.max, h.bounds_max, 1e-4, "max");
    export_tiles(&store, &cache, dir.path(), &TilesOptions::default()).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("tileset.json")).unwrap()).unwrap();
    let b: Vec<f64> = json["root"]["boundingVolume"]["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    // Tileset z = store y: centre and half height along z are those of the store's y extent.
    let (lo, hi) = (h.bounds_min[1], h.bounds_max[1]);
    assert!((b[2] - (lo + hi) / 2.0).abs() < 1e-3 && (b[11] - (hi - lo) / 2.0).abs() < 1e-3, "{b:?}");
}

/// A store in millimetres: the tileset's errors and boxes are in metres, and its content is
/// scaled to metres by the GLB's root node.
#[test]
fn tileset_of_a_millimetre_store_is_in_metres() {
    let built = build_plant(2, "mm");
    let store = Store::open(&built.path).unwrap();
    let cache = PageCache::new(&store, 64 << 20);
    let unitless = Store::open(plant()).unwrap();
    let dir_mm = tempfile::tempdir().unwrap();
    let dir_1 = tempfile::tempdir().unwrap();
    let mm = export_tiles(&store, &cache, dir_mm.path(), &TilesOptions::default()).unwrap();
    let one =
        export_tiles(&unitless, &PageCache::new(&unitless, 64 << 20), dir_1.path(), &TilesOptions::default())
            .unwrap();
    assert_eq!(mm.tiles, one.tiles);
    assert!(
        (mm.root_error - one.root_error / 1000.0).abs() < 1e-9 * one.root_error.max(1.0),
        "{mm:?} {one:?}"
    );
    let read = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("tileset.json")).unwrap()).unwrap()
    };
    let (a, b) = (read(dir_mm.path()), read(dir_1.path()));
    let half = |j: &serde_json::Value| j["root"]["boundingVolume"]["box"][3].as_f64().unwrap();
    assert!((half(&a) - half(&b) / 1000.0).abs() < 1e-9 * half(&b), "{} {}", half(&a), half(&b));
    let root = read_back(&dir_mm.path().join(a["root"]["content"]["uri"].as_str().unwrap()));
    let size = root.max[0] - root.min[0];
    assert!(size > 0.0 && size < 0.1, "content in metres: {size}");
}
