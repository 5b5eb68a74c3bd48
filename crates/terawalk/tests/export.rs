//! `terawalk export` end to end on a generated 30k-triangle plant: the GLB of a cut and of a
//! region read back through tw-io's glTF importer; the 3D Tiles tileset's structure and its
//! rendering in CesiumJS (headless Chromium, through scripts/check-tiles-cesium.sh: skipped with
//! a note when Chromium, node or the npm packages are missing, unless
//! `TERAWALK_REQUIRE_CESIUM=1`, as in CI); usage errors.

use std::path::{Path, PathBuf};
use std::process::Command;
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

/// scripts/check-tiles-cesium.sh.
fn cesium_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/check-tiles-cesium.sh")
}

/// Whether the CesiumJS check can run here (the script's `--check-setup`, which installs
/// nothing); else the test is skipped with what is missing named, or fails when CesiumJS is
/// required.
fn have_cesium() -> bool {
    let missing = match Command::new("bash").arg(cesium_script()).arg("--check-setup").output() {
        Ok(o) if o.status.success() => return true,
        Ok(o) => stderr(&o),
        Err(e) => format!("bash: {e}"),
    };
    let install = "scripts/check-tiles-cesium.sh --install";
    assert_ne!(
        std::env::var("TERAWALK_REQUIRE_CESIUM").as_deref(),
        Ok("1"),
        "the CesiumJS check cannot run (install with `{install}`):\n{missing}"
    );
    eprintln!("SKIPPED: the CesiumJS check cannot run (install with `{install}`):\n{missing}");
    false
}

/// Where a screenshot shows the model: the pixels that are not the white background.
#[derive(Debug)]
struct Silhouette {
    /// Model pixels over all pixels.
    fraction: f64,
    /// The model pixels' mean position, as fractions of the width and the height (0 = left, top).
    centroid: [f64; 2],
    /// The widest row's span (first to last model pixel), over the image's width.
    widest: f64,
    /// Where the widest row lies between the silhouette's top (0) and bottom (1) rows.
    widest_at: f64,
    /// The widest span among the silhouette's top 15 % of rows, over the image's width.
    top_width: f64,
}

impl Silhouette {
    /// `model` holds `width × height` flags, row by row from the top.
    fn of(model: &[bool], width: usize, height: usize) -> Silhouette {
        let (mut count, mut sum) = (0usize, [0.0f64; 2]);
        // Each row's span of model pixels (first, last), if it has any.
        let mut spans = vec![None; height];
        for (y, row) in model.chunks_exact(width).enumerate() {
            for (x, _) in row.iter().enumerate().filter(|(_, m)| **m) {
                count += 1;
                sum[0] += x as f64;
                sum[1] += y as f64;
                let span: &mut Option<(usize, usize)> = &mut spans[y];
                *span = Some(span.map_or((x, x), |(a, _)| (a, x)));
            }
        }
        let width_of = |y: usize| spans[y].map_or(0, |(a, b)| b + 1 - a);
        let rows: Vec<usize> = (0..height).filter(|&y| spans[y].is_some()).collect();
        let (top, bottom) = (rows.first().copied().unwrap_or(0), rows.last().copied().unwrap_or(0));
        let widest_y = (top..=bottom).max_by_key(|&y| width_of(y)).unwrap_or(0);
        let band_end = top + (bottom - top) * 15 / 100;
        let n = count.max(1) as f64;
        Silhouette {
            fraction: count as f64 / (width * height).max(1) as f64,
            centroid: [sum[0] / n / width as f64, sum[1] / n / height as f64],
            widest: width_of(widest_y) as f64 / width as f64,
            widest_at: (widest_y - top) as f64 / (bottom - top).max(1) as f64,
            top_width: (top..=band_end).map(width_of).max().unwrap_or(0) as f64 / width as f64,
        }
    }

    /// Reads a PNG screenshot (8-bit RGB or RGBA); a pixel darker than 235 in any channel is
    /// the model's (the background is white; the model is grey, shaded, its edges antialiased).
    fn of_png(path: &Path) -> Silhouette {
        let (w, h) = png_size(path);
        let model: Vec<bool> = image_rgb(path).iter().map(|p| p.iter().any(|&c| c < 235)).collect();
        Silhouette::of(&model, w, h)
    }

    /// Whether this is the plant as the script's camera sees it upright: a ground slab seen from
    /// above (the widest rows in the lower half), a chimney rising from it (narrow top rows),
    /// about in the middle, neither a speck nor filling the view.
    fn looks_like_upright_plant(&self) -> bool {
        (0.05..0.6).contains(&self.fraction)
            && (0.3..0.7).contains(&self.centroid[0])
            && (0.3..0.9).contains(&self.centroid[1])
            && self.widest > 0.3
            && self.widest_at > 0.5
            && self.top_width < 0.25 * self.widest
    }
}

/// A PNG's width and height.
fn png_size(path: &Path) -> (usize, usize) {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let info = png::Decoder::new(file).read_info().unwrap().info().clone();
    (info.width as usize, info.height as usize)
}

/// A PNG screenshot's pixels (8-bit RGB or RGBA), row by row, as RGB.
fn image_rgb(path: &Path) -> Vec<[u8; 3]> {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = match info.color_type {
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        other => panic!("{}: a {other:?} PNG", path.display()),
    };
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    let (w, h) = (info.width as usize, info.height as usize);
    buf.chunks_exact(info.line_size)
        .take(h)
        .flat_map(|row| row.chunks_exact(channels).take(w).map(|p| [p[0], p[1], p[2]]))
        .collect()
}

#[test]
fn silhouette_tells_an_upright_plant_from_a_flipped_or_empty_one() {
    // A 100×60 slab (rows 30..60, 80 wide) with a 6-wide chimney (rows 5..30) on its left.
    let (w, h) = (100, 60);
    let upright: Vec<bool> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            (y >= 30 && (10..90).contains(&x)) || (y >= 5 && (20..26).contains(&x))
        })
        .collect();
    let s = Silhouette::of(&upright, w, h);
    assert!(s.looks_like_upright_plant(), "{s:?}");
    assert!((s.widest - 0.8).abs() < 1e-9 && (s.top_width - 0.06).abs() < 1e-9, "{s:?}");
    // Upside down: the chimney hangs below the slab.
    let flipped: Vec<bool> = upright.chunks_exact(w).rev().flatten().copied().collect();
    let s = Silhouette::of(&flipped, w, h);
    assert!(!s.looks_like_upright_plant(), "{s:?}");
    // Nothing drawn, and everything drawn.
    for fill in [false, true] {
        let s = Silhouette::of(&vec![fill; w * h], w, h);
        assert!(!s.looks_like_upright_plant(), "{s:?}");
    }
}

/// The plant's tileset loads in CesiumJS down to its full-detail tiles, and the screenshot shows
/// it upright in the middle of the view.
#[test]
fn tileset_renders_in_cesium() {
    if !have_cesium() {
        return;
    }
    let d = plant();
    let o = terawalk(&["export", "p.tw", "--tiles", "cesium"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("cesium/tileset.json")).unwrap()).unwrap();
    let tiles = check_tile(&d.join("cesium"), &json["root"], None);
    // The script gives up by itself after TW_CESIUM_TIMEOUT (120 s unless set).
    let o = Command::new("bash")
        .arg(cesium_script())
        .args(["cesium", "cesium.png"])
        .current_dir(d)
        .output()
        .unwrap();
    let all = format!("{}{}", stdout(&o), stderr(&o));
    assert!(o.status.success(), "the CesiumJS check failed:\n{all}");
    let line = stdout(&o).lines().rev().find(|l| l.starts_with('{')).map(str::to_owned);
    let report: serde_json::Value = serde_json::from_str(&line.expect("a JSON report")).unwrap();
    assert_eq!(report["how"], "allTilesLoaded", "{all}");
    // The whole plant is in view: at the final screen-space error every tile is needed.
    assert_eq!(report["tiles"].as_u64(), Some(tiles as u64), "{all}");
    assert_eq!(report["finestError"].as_f64(), Some(0.0), "{all}");
    // At Cesium's default screen-space error (16 px) the geometric errors let it stop above the
    // full-detail leaves (the 1 m level projects to about 4 px from the script's camera).
    let coarse = report["coarseTiles"].as_u64().unwrap_or(0);
    assert!(coarse > 0 && coarse < tiles as u64, "{all}");
    assert_eq!(report["failed"].as_array().map(Vec::len), Some(0), "{all}");
    assert_eq!(report["pageErrors"].as_array().map(Vec::len), Some(0), "{all}");
    let s = Silhouette::of_png(&d.join("cesium.png"));
    eprintln!("{s:?}");
    assert!(s.looks_like_upright_plant(), "{s:?} in {}", d.join("cesium.png").display());
    // Lit, not flat-coloured: the tiles carry normals. Measured on a 20 k plant: 23 % of the
    // model's pixels lie more than 8 levels from its commonest grey; 1.2 % without normals
    // (only the antialiased edges).
    let shaded = shaded_fraction(&d.join("cesium.png"));
    assert!(shaded > 0.08, "{shaded} of the model's pixels shaded in {}", d.join("cesium.png").display());
}

/// Of a screenshot's model pixels (darker than 235 in a channel, as [`Silhouette::of_png`]
/// takes them), the fraction whose grey lies more than 8 levels from the commonest grey.
fn shaded_fraction(path: &Path) -> f64 {
    let image = image_rgb(path);
    let greys: Vec<u8> = image
        .iter()
        .filter(|p| p.iter().any(|&c| c < 235))
        .map(|p| ((p[0] as u32 + p[1] as u32 + p[2] as u32) / 3) as u8)
        .collect();
    let mut counts = [0usize; 256];
    for &g in &greys {
        counts[g as usize] += 1;
    }
    let commonest = (0..256).max_by_key(|&g| counts[g]).unwrap_or(0) as i32;
    let far = greys.iter().filter(|&&g| (g as i32 - commonest).abs() > 8).count();
    far as f64 / greys.len().max(1) as f64
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
