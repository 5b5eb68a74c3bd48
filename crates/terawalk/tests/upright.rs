//! Real models open upright with `render FILE` alone (built through the cache, as `view FILE`
//! does): a real IFC building, Y-up glTF 2.0 and COLLADA models, a Z-up COLLADA scene and an FBX
//! model, all from Debian's `assimp-testmodels` (`/usr/share/assimp/models`). Each test checks
//! the store the cache built (its up axis and the model's extent along it, plausible for the
//! object) and that the picture shows the model. A missing package or converter skips the test
//! with a note, unless `TERAWALK_REQUIRE_CONVERTERS=1` (CI, which installs them); a missing GPU
//! adapter skips the picture check only, unless `TERAWALK_REQUIRE_GPU=1`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::Instant;

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Where Debian's `assimp-testmodels` puts its models.
const MODELS: &str = "/usr/share/assimp/models";

fn required() -> bool {
    std::env::var("TERAWALK_REQUIRE_CONVERTERS").as_deref() == Ok("1")
}

/// Whether `check` (a shell command) succeeds; else the test is skipped with `install` named,
/// or fails when the converters are required.
fn have(check: &str, install: &str) -> bool {
    let ok = Command::new("sh").args(["-c", check]).stdout(Stdio::null()).stderr(Stdio::null()).status();
    if ok.is_ok_and(|s| s.success()) {
        return true;
    }
    assert!(!required(), "`{check}` failed: install with `{install}`");
    eprintln!("SKIPPED: `{check}` failed (install with `{install}`)");
    false
}

/// The test model `name` (relative to [`MODELS`]), or `None` (the test is skipped with a note)
/// when the package is not installed; a failure when the converters are required.
fn model(name: &str) -> Option<PathBuf> {
    let path = Path::new(MODELS).join(name);
    if path.is_file() {
        return Some(path);
    }
    assert!(!required(), "{} is missing: install with `apt install assimp-testmodels`", path.display());
    eprintln!("SKIPPED: {} is missing (install with `apt install assimp-testmodels`)", path.display());
    None
}

/// What opening a model gave: the store the cache built and the picture, when one was drawn.
struct Opened {
    store: tw_store::Store,
    png: Option<PathBuf>,
    _dir: tempfile::TempDir,
}

/// `terawalk render MODEL -o shot.png --size 320x240` with a fresh cache: the model is built into
/// the cache exactly as `view MODEL` builds it.
fn open(model: &Path) -> Opened {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let start = Instant::now();
    let model_arg = model.to_str().unwrap();
    let o: Output = Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(["render", model_arg, "-o", "shot.png", "--size", "320x240"])
        .current_dir(dir.path())
        .env("TERAWALK_CACHE", &cache)
        .output()
        .expect("runs");
    eprintln!("{}: {:.1} s", model.display(), start.elapsed().as_secs_f64());
    let no_gpu = !o.status.success() && stderr(&o).contains("no GPU adapter");
    assert!(o.status.success() || no_gpu, "{}{}", stdout(&o), stderr(&o));
    assert!(stdout(&o).contains("into the cache"), "built through the cache: {}", stdout(&o));
    let stores: Vec<PathBuf> = std::fs::read_dir(&cache)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "tw"))
        .collect();
    assert_eq!(stores.len(), 1, "{stores:?}");
    let store = tw_store::Store::open(&stores[0]).unwrap();
    let png = if no_gpu {
        assert_ne!(std::env::var("TERAWALK_REQUIRE_GPU").as_deref(), Ok("1"), "{}", stderr(&o));
        eprintln!("SKIPPED the picture: {} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)", stderr(&o));
        None
    } else {
        Some(dir.path().join("shot.png"))
    };
    Opened { store, png, _dir: dir }
}

/// The model's extent along x, y and z.
fn extent(store: &tw_store::Store) -> [f64; 3] {
    let h = store.header();
    [0, 1, 2].map(|i| h.bounds_max[i] - h.bounds_min[i])
}

/// The extent along the store's up axis and the two horizontal extents, smaller first.
fn up_and_horizontal(store: &tw_store::Store) -> (f64, [f64; 2]) {
    let e = extent(store);
    let up = store.header().up_axis as usize;
    let mut h = [e[(up + 1) % 3], e[(up + 2) % 3]];
    h.sort_by(f64::total_cmp);
    (e[up], h)
}

/// Checks the picture is 320×240 and shows the model: a fair share of its pixels differ from the
/// background (the corner pixel), and not all of them (the model is not in the camera's face).
fn assert_shows_the_model(png: &Option<PathBuf>) {
    let Some(png) = png else { return };
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(png).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (320, 240));
    let channels = info.color_type.samples();
    let pixels: Vec<&[u8]> = buf[..info.buffer_size()].chunks(channels).collect();
    let background = pixels[0];
    let differs = |p: &[u8]| p.iter().zip(background).take(3).any(|(a, b)| a.abs_diff(*b) > 24);
    let share = pixels.iter().filter(|p| differs(p)).count() as f64 / pixels.len() as f64;
    eprintln!("{}: {:.1}% of the pixels show the model", png.display(), share * 100.0);
    assert!((0.02..0.9).contains(&share), "{:.1}% of the pixels show the model", share * 100.0);
}

#[test]
fn the_fzk_house_ifc_opens_upright() {
    let Some(file) = model("IFC/AC14-FZK-Haus.ifc") else { return };
    if !have("${TERAWALK_PYTHON:-python3} -c 'import ifcopenshell.geom'", "pip install ifcopenshell") {
        return;
    }
    let opened = open(&file);
    let s = &opened.store;
    assert_eq!((s.header().up_axis, s.units()), (2, "m"), "IFC is z-up, in metres");
    // A one-family house with a pitched roof (7.3 m to the ridge from the basement slab) on a
    // terrain plate of 18 m × 16 m.
    let (height, [narrow, wide]) = up_and_horizontal(s);
    assert!((5.0..15.0).contains(&height), "height {height} m, {:?}", extent(s));
    assert!(narrow >= height && wide < 50.0, "footprint {narrow} × {wide} m, height {height} m");
    assert_shows_the_model(&opened.png);
}

#[test]
fn the_y_up_gltf_engine_opens_upright() {
    let Some(file) = model("glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb") else { return };
    let opened = open(&file);
    let s = &opened.store;
    assert_eq!(s.header().up_axis, 1, "glTF is y-up");
    // A flat-twin engine: its crankshaft and the two cylinders lie along x, the longest extent,
    // which must be horizontal; it is about as tall as it is deep.
    let e = extent(s);
    assert!(e[0] > 2.0 * e[1] && e[0] > 2.0 * e[2], "{e:?}");
    assert!((0.7..1.4).contains(&(e[1] / e[2])), "{e:?}");
    assert_shows_the_model(&opened.png);
}

#[test]
fn the_y_up_collada_duck_opens_upright() {
    if !have("assimp version", "apt install assimp-utils") {
        return;
    }
    let Some(file) = model("Collada/duck.dae") else { return };
    let opened = open(&file);
    let s = &opened.store;
    assert_eq!(s.header().up_axis, 1, "assimp writes glTF, which is y-up");
    // The duck sits on its belly: taller than it is wide (1.54 against 1.15), and above the
    // ground plane of its file.
    let (height, [narrow, _]) = up_and_horizontal(s);
    assert!(height > 1.2 * narrow, "height {height}, {:?}", extent(s));
    assert!(s.header().bounds_min[1] > 0.0, "{:?}", s.header().bounds_min);
    assert_shows_the_model(&opened.png);
}

#[test]
fn the_z_up_collada_teapots_open_upright() {
    if !have("assimp version", "apt install assimp-utils") {
        return;
    }
    let Some(file) = model("Collada/teapots.DAE") else { return };
    let opened = open(&file);
    let s = &opened.store;
    // The file is Z_UP; assimp turns it y-up for glTF. The three teapots stand on the ground
    // plane side by side: their bottom at height 0, much lower than the group is wide or deep.
    assert_eq!(s.header().up_axis, 1);
    let (height, [narrow, _]) = up_and_horizontal(s);
    assert!(s.header().bounds_min[1].abs() < 1e-3, "{:?}", s.header().bounds_min);
    assert!(height < 0.6 * narrow, "height {height}, {:?}", extent(s));
    assert_shows_the_model(&opened.png);
}

#[test]
fn the_fbx_spider_opens_upright() {
    if !have("assimp version", "apt install assimp-utils") {
        return;
    }
    let Some(file) = model("FBX/spider.fbx") else { return };
    let opened = open(&file);
    let s = &opened.store;
    assert_eq!(s.header().up_axis, 1, "assimp writes glTF, which is y-up");
    // A spider on its legs: much lower than it is long or wide.
    let (height, [narrow, _]) = up_and_horizontal(s);
    assert!(height < 0.7 * narrow, "height {height}, {:?}", extent(s));
    assert_shows_the_model(&opened.png);
}
