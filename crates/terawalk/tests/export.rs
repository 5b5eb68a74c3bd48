//! `terawalk export` end to end on a generated 30k-triangle plant: the GLB of a cut and of a
//! region read back through tw-io's glTF importer; the 3D Tiles tileset's structure; usage
//! errors.

use std::path::Path;
use std::sync::OnceLock;

mod common;

use common::{stderr, stdout, terawalk};
use tw_io::format::{open_source, ImportOptions};
use tw_io::{ImportError, ObjectId, ObjectInfo, Triangle, TriangleSink};

/// A folder with the plant `p.ply` (30,000 triangles, z-up) and its store `p.tw`, made once.
fn plant() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let o = terawalk(&["generate", "plant", "--triangles", "30000", "-o", "p.ply"], dir.path());
        assert!(o.status.success(), "{}", stderr(&o));
        let o = terawalk(&["build", "p.ply", "-o", "p.tw", "--memory", "256M"], dir.path());
        assert!(o.status.success(), "{}", stderr(&o));
        dir
    })
    .path()
}

/// Triangles and bounds as tw-io's importer reads them.
#[derive(Default)]
struct ReadBack {
    triangles: u64,
    min: [f64; 3],
    max: [f64; 3],
}

impl TriangleSink for ReadBack {
    fn object(&mut self, _: ObjectId, _: &ObjectInfo) -> Result<(), ImportError> {
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

/// The plant's bounds in the glTF's y-up frame: (x, y, z) → (x, z, −y).
fn y_up(min: [f64; 3], max: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    ([min[0], min[2], -max[1]], [max[0], max[2], -min[1]])
}

#[test]
fn cut_at_zero_error_has_every_input_triangle_within_the_bounds() {
    let d = plant();
    let o = terawalk(&["export", "p.tw", "-o", "full.glb", "--error", "0"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("30,000 triangles"), "{}", stdout(&o));
    let store = tw_store::Store::open(d.join("p.tw")).unwrap();
    let h = store.header();
    let r = read_back(&d.join("full.glb"));
    assert_eq!(r.triangles, 30_000);
    let (min, max) = y_up(h.bounds_min, h.bounds_max);
    let tol = 1e-4;
    for a in 0..3 {
        assert!(
            (r.min[a] - min[a]).abs() < tol && (r.max[a] - max[a]).abs() < tol,
            "{:?}..{:?}",
            r.min,
            r.max
        );
    }
    // The default pixel error gives a coarser cut of the same scene.
    let o = terawalk(&["export", "p.tw", "-o", "cut.glb"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let cut = read_back(&d.join("cut.glb"));
    assert!(cut.triangles > 0 && cut.triangles < 30_000, "{}", cut.triangles);
    // A camera given as just "eye;target" (up: the store's axis), looking at a corner.
    let o = terawalk(&["export", "p.tw", "-o", "corner.glb", "--camera", "-20,-20,10;10,10,0"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let corner = read_back(&d.join("corner.glb"));
    assert!(corner.triangles > 0 && corner.triangles < 30_000, "{}", corner.triangles);
}

#[test]
fn region_keeps_only_the_triangles_inside_it() {
    let d = plant();
    let region = [0.0, 0.0, -1.0, 20.0, 20.0, 5.0];
    let arg = region.map(|v| v.to_string()).join(",");
    let o = terawalk(&["export", "p.tw", "-o", "r.glb", "--region", &arg], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = read_back(&d.join("r.glb"));
    assert!(r.triangles > 0 && r.triangles < 30_000, "{}", r.triangles);
    let (min, max) = y_up([region[0], region[1], region[2]], [region[3], region[4], region[5]]);
    for a in 0..3 {
        assert!(r.min[a] >= min[a] - 1e-4 && r.max[a] <= max[a] + 1e-4, "{:?}..{:?}", r.min, r.max);
    }
}

/// Checks one tile and its subtree: content exists, errors decrease, boxes nest. Returns the
/// number of tiles.
fn check_tile(dir: &Path, tile: &serde_json::Value, parent: Option<(f64, &[f64])>) -> usize {
    let error = tile["geometricError"].as_f64().unwrap();
    let b: Vec<f64> =
        tile["boundingVolume"]["box"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(b.len(), 12);
    let uri = tile["content"]["uri"].as_str().unwrap();
    assert!(dir.join(uri).is_file(), "{uri}");
    if let Some((parent_error, pb)) = parent {
        assert!(error < parent_error, "{error} !< {parent_error}");
        for a in 0..3 {
            let (c, h, pc, ph) = (b[a], b[3 + 4 * a], pb[a], pb[3 + 4 * a]);
            assert!(c - h >= pc - ph - 1e-9 && c + h <= pc + ph + 1e-9, "{b:?} not in {pb:?}");
        }
    }
    let children = tile.get("children").and_then(|c| c.as_array());
    1 + children.into_iter().flatten().map(|c| check_tile(dir, c, Some((error, &b)))).sum::<usize>()
}

#[test]
fn tileset_parses_and_nests() {
    let d = plant();
    let o = terawalk(&["export", "p.tw", "--tiles", "tiles", "--tile-triangles", "2k"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("tiles/tileset.json")).unwrap()).unwrap();
    assert_eq!(json["asset"]["version"], "1.1");
    assert_eq!(json["root"]["refine"], "REPLACE");
    let tiles = check_tile(&d.join("tiles"), &json["root"], None);
    assert!(tiles > 10, "{tiles}");
    assert!(stdout(&o).contains(&format!("{tiles} tiles")), "{}", stdout(&o));
    // The root's content is the coarsest level: upright (y-up GLB) and much smaller.
    let root = read_back(&d.join("tiles").join(json["root"]["content"]["uri"].as_str().unwrap()));
    assert!(root.triangles > 0 && root.triangles < 10_000, "{}", root.triangles);
}

#[test]
fn usage_errors_are_clear() {
    let d = plant();
    for (args, code, says) in [
        (&["export", "p.tw"][..], 2, "--output"),
        (&["export", "p.tw", "-o", "a.glb", "--tiles", "t"][..], 2, "cannot be used with"),
        (
            &["export", "p.tw", "-o", "a.glb", "--region", "0,0,0,1,1", "--camera", "0,0,0;1,1,1;0,0,1;60"][..],
            2,
            "cannot be used with",
        ),
        (
            &["export", "p.tw", "-o", "a.glb", "--region", "0,0,0,1,1"][..],
            1,
            "region \"0,0,0,1,1\": 5 numbers",
        ),
        (&["export", "p.tw", "-o", "a.glb", "--error=-1"][..], 1, "--error"),
        (&["export", "p.tw", "-o", "a.ply"][..], 1, "a.ply"),
        (&["export", "p.ply", "-o", "a.glb"][..], 1, "terawalk build p.ply"),
    ] {
        let o = terawalk(args, d);
        assert_eq!(o.status.code(), Some(code), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{args:?}: {}", stderr(&o));
    }
    assert!(!d.join("a.glb").exists());
}
