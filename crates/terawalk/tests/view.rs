//! `terawalk view` end to end. Errors (missing or corrupt store, bad path file) must give a
//! clear message and exit code 1 before any window opens. The scripted run starts the viewer
//! under Xvfb (Debian `xvfb`, `xauth`) on Mesa's CPU drivers, plays a short camera path with
//! `--exit-after`, saves a screenshot and checks that it shows the model. It is skipped only
//! when `xvfb-run` is missing and `TERAWALK_REQUIRE_GPU` is unset; with
//! `TERAWALK_REQUIRE_GPU=1` (CI) a missing Xvfb, display or adapter fails the test.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

// The shared helpers (only the wound cubes are used here).
#[allow(dead_code)]
mod common;

fn terawalk(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_terawalk")).args(args).current_dir(dir).output().expect("runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn require_gpu() -> bool {
    std::env::var("TERAWALK_REQUIRE_GPU").is_ok_and(|v| !v.is_empty() && v != "0")
}

fn which(exe: &str) -> Option<PathBuf> {
    std::env::var_os("PATH")?.to_str()?.split(':').map(|d| Path::new(d).join(exe)).find(|p| p.is_file())
}

/// A small store built once through the CLI (generate + build).
fn store() -> &'static Path {
    static STORE: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &STORE
        .get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let o = terawalk(&["generate", "plant", "--triangles", "30k", "-o", "p.ply"], dir.path());
            assert!(o.status.success(), "{}", text(&o.stderr));
            let o = terawalk(
                &["-q", "build", "p.ply", "-o", "p.tw", "--memory", "256M", "--threads", "1"],
                dir.path(),
            );
            assert!(o.status.success(), "{}", text(&o.stderr));
            let p = dir.path().join("p.tw");
            (dir, p)
        })
        .1
}

fn assert_clean_error(o: &Output, needle: &str) {
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "stderr: {err}");
    assert!(err.contains(needle), "stderr lacks {needle:?}: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn view_help_has_examples() {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["view", "--help"], dir.path());
    assert!(o.status.success());
    let out = text(&o.stdout);
    assert!(out.contains("Examples:") && out.contains("--exit-after") && out.contains("F12"), "{out}");
}

#[test]
fn a_missing_store_is_a_clear_error_before_any_window() {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["view", "nowhere.tw"], dir.path());
    assert_clean_error(&o, "cannot open the store: nowhere.tw");
}

#[test]
fn a_corrupt_store_is_a_clear_error_before_any_window() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.tw"), vec![0x5au8; 4096]).unwrap();
    let o = terawalk(&["view", "bad.tw"], dir.path());
    assert_clean_error(&o, "cannot open the store: bad.tw");
    // A truncated real store.
    let bytes = std::fs::read(store()).unwrap();
    std::fs::write(dir.path().join("cut.tw"), &bytes[..bytes.len() / 3]).unwrap();
    let o = terawalk(&["view", "cut.tw"], dir.path());
    assert_clean_error(&o, "cannot open the store: cut.tw");
}

#[test]
fn a_bad_path_file_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("p.json"), "{\"format\":\"terawalk-path\"").unwrap();
    let s = store().to_str().unwrap();
    let o = terawalk(&["view", s, "--path", "p.json", "--exit-after", "2"], dir.path());
    assert_clean_error(&o, "p.json");
    let o = terawalk(&["view", s, "--screenshot", "x.png"], dir.path());
    assert_clean_error(&o, "--exit-after");
}

/// A path of `n` frames circling the model's centre, from the store's bounds.
fn circle_path(store: &Path, n: usize) -> String {
    let st = tw_store::Store::open(store).unwrap();
    let h = st.header();
    let c: Vec<f64> = (0..3).map(|i| (h.bounds_min[i] + h.bounds_max[i]) / 2.0).collect();
    let r = (0..3).map(|i| (h.bounds_max[i] - h.bounds_min[i]).powi(2)).sum::<f64>().sqrt() * 0.8;
    let frames: Vec<String> = (0..n)
        .map(|i| {
            let a = 0.6 + i as f64 * 0.05;
            format!(
                "{{\"eye\":[{},{},{}],\"target\":[{},{},{}],\"up\":[0,0,1],\"fovy\":60,\"segment\":\"test\"}}",
                c[0] + r * a.cos(),
                c[1] + r * a.sin(),
                c[2] + r * 0.5,
                c[0],
                c[1],
                c[2]
            )
        })
        .collect();
    format!("{{\"format\":\"terawalk-path\",\"version\":1,\"fps\":30,\"frames\":[{}]}}", frames.join(","))
}

/// Runs `cmd` with a time limit; None when it was killed.
fn run_with_timeout(mut cmd: Command, limit: Duration) -> Option<Output> {
    let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("spawns");
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return Some(child.wait_with_output().unwrap());
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let o = child.wait_with_output().unwrap();
            eprintln!("killed after {limit:?}; stderr: {}", text(&o.stderr));
            return None;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Pixels that are not the background, and distinct colours among them.
fn coverage(png_file: &Path) -> (f64, usize) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(png_file).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    let px = &buf[..info.buffer_size()];
    let bg = [205u8, 218, 235];
    let mut colours = std::collections::HashSet::new();
    let mut covered = 0usize;
    for p in px.chunks_exact(4) {
        if p[..3] != bg {
            covered += 1;
            colours.insert([p[0] >> 3, p[1] >> 3, p[2] >> 3]);
        }
    }
    (covered as f64 / (px.len() / 4) as f64, colours.len())
}

fn scripted_run(backend: &str) {
    scripted_run_with(backend, &[], true);
}

/// The run's folder, or None when it was skipped.
fn scripted_run_with(backend: &str, extra: &[&str], check_image: bool) -> Option<tempfile::TempDir> {
    scripted_run_on(store(), backend, extra, check_image).map(|(dir, _)| dir)
}

/// [`scripted_run_with`] on any store; also returns the viewer's stderr.
fn scripted_run_on(
    store_file: &Path,
    backend: &str,
    extra: &[&str],
    check_image: bool,
) -> Option<(tempfile::TempDir, String)> {
    run_under_xvfb(store_file, backend, &["--exit-after", "8"], "8 frames", extra, check_image)
}

/// One Xvfb at a time: `xvfb-run -a` picks a free display number racily.
static XVFB: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Runs the viewer under Xvfb on the circle path until `stop` says (`--exit-after N` or
/// `--script FILE`, relative to the run's folder, where `script` is written first), checks that
/// stdout reports `frames` and that the `--screenshot` shows the model (`check_image`).
fn run_under_xvfb(
    store_file: &Path,
    backend: &str,
    stop: &[&str],
    frames: &str,
    extra: &[&str],
    check_image: bool,
) -> Option<(tempfile::TempDir, String)> {
    let _one = XVFB.lock().unwrap_or_else(|e| e.into_inner());
    let Some(xvfb_run) = which("xvfb-run") else {
        assert!(
            !require_gpu(),
            "TERAWALK_REQUIRE_GPU is set but xvfb-run is missing (apt-get install xvfb xauth)"
        );
        eprintln!("skipped: xvfb-run not found (apt-get install xvfb xauth)");
        return None;
    };
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("path.json"), circle_path(store_file, 6)).unwrap();
    let shot = dir.path().join("shot.png");
    let mut cmd = Command::new(xvfb_run);
    cmd.args(["-a", "-s", "-screen 0 1024x768x24", env!("CARGO_BIN_EXE_terawalk"), "view"])
        .arg(store_file)
        .args(["--path", "path.json", "--size", "480x320", "--screenshot"])
        .arg(&shot)
        .args(stop)
        .args(extra)
        .current_dir(dir.path())
        .env("WGPU_BACKEND", backend)
        .env("TERAWALK_LOG", "info,wgpu_hal=off,wgpu_core=warn,naga=warn");
    let lvp = Path::new("/usr/share/vulkan/icd.d/lvp_icd.x86_64.json");
    if backend == "vulkan" && std::env::var_os("VK_ICD_FILENAMES").is_none() && lvp.exists() {
        cmd.env("VK_ICD_FILENAMES", lvp);
    }
    let o = run_with_timeout(cmd, Duration::from_secs(240)).expect("the viewer did not exit in time");
    let err = text(&o.stderr);
    if !o.status.success() {
        let no_device = err.contains("no GPU adapter") || err.contains("cannot open a window");
        assert!(no_device && !require_gpu(), "view failed ({backend}): {err}");
        eprintln!("skipped ({backend}): no display or adapter: {err}");
        return None;
    }
    assert!(!err.contains("panicked"), "{err}");
    assert!(text(&o.stdout).contains(frames), "{}", text(&o.stdout));
    if !check_image {
        return Some((dir, err));
    }
    let (covered, colours) = coverage(&shot);
    eprintln!("{backend} {extra:?}: {:.1} % covered, {colours} colours", covered * 100.0);
    assert!(covered > 0.05, "the screenshot shows almost nothing ({:.2} %)", covered * 100.0);
    assert!(colours >= 8, "the screenshot has only {colours} colours");
    Some((dir, err))
}

#[test]
fn scripted_path_under_xvfb_shows_the_model_vulkan() {
    scripted_run("vulkan");
}

#[test]
fn scripted_path_under_xvfb_shows_the_model_gl() {
    scripted_run("gl");
}

#[test]
fn walk_orbit_and_debug_view_run_under_xvfb() {
    // The path drives the first frames; the modes and the debug view must not fail or panic.
    // --record records every frame and saves at exit, in the format --path reads.
    if let Some(dir) =
        scripted_run_with("vulkan", &["--mode", "walk", "--color", "level", "--record", "rec.json"], false)
    {
        let rec = tw_runtime::CameraPath::load(&dir.path().join("rec.json")).expect("recorded path");
        assert_eq!(rec.frames.len(), 8);
        assert_eq!(rec.frames[0].segment, "recorded");
    }
    if let Some(dir) = scripted_run_with(
        "vulkan",
        &["--mode", "orbit", "--debug-view", "--screenshot-window", "win.png"],
        true,
    ) {
        // The HUD and panels (text) over the model and its debug lines: many colours.
        let (covered, colours) = coverage(&dir.path().join("win.png"));
        assert!(covered > 0.05 && colours >= 20, "window screenshot: {covered} covered, {colours} colours");
    }
}

#[test]
fn occlusion_culling_under_xvfb_shows_the_model() {
    // hzb reads the own depth back and queries test against it: the frame is drawn into the
    // renderer's own target and copied into the window's texture. With the cut kept at the
    // asked-for τ whatever the cache holds (`--fit-memory off`).
    scripted_run_with("vulkan", &["--occlusion", "hzb", "--fit-memory", "off"], true);
    // Queries in the third-person debug view (occluded node boxes in yellow).
    if let Some(dir) = scripted_run_with(
        "vulkan",
        &["--occlusion", "queries", "--debug-view", "--screenshot-window", "win.png"],
        true,
    ) {
        let (covered, colours) = coverage(&dir.path().join("win.png"));
        assert!(covered > 0.05 && colours >= 20, "window screenshot: {covered} covered, {colours} colours");
    }
}

#[test]
fn a_corrupt_page_does_not_stop_the_viewer() {
    // One finest-level page's bytes are damaged after the store was written: the store opens
    // (the page table is intact), the page fails its checksum when streamed, is logged, and its
    // groups are drawn by their ancestors.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("damaged.tw");
    std::fs::copy(store(), &file).unwrap();
    let page = {
        let st = tw_store::Store::open(&file).unwrap();
        let pages = st.pages();
        let p = pages
            .iter()
            .filter(|p| !p.is_root() && p.compressed_len > 16)
            .min_by_key(|p| p.level_min)
            .copied()
            .expect("a non-root page");
        (p.offset, p.compressed_len)
    };
    let mut bytes = std::fs::read(&file).unwrap();
    for b in &mut bytes[(page.0 + page.1 as u64 / 4) as usize..][..8] {
        *b ^= 0xa5;
    }
    std::fs::write(&file, &bytes).unwrap();
    if let Some((_, err)) = scripted_run_on(&file, "vulkan", &["--error", "0"], true) {
        assert!(err.contains("failed to load"), "the damaged page was not reported: {err}");
    }
}

/// The size of a PNG file (its IHDR).
fn png_size(file: &Path) -> (u32, u32) {
    let bytes = std::fs::read(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (be(16), be(20))
}

#[test]
fn a_script_drives_keys_resizes_and_minimising() {
    // Keys held and pressed, mouse look, two resizes and a minimise/restore in one session:
    // the scene follows the window's size, minimised frames are skipped without an error, and
    // the last frame after restoring shows the model at the new size.
    let script = "wait 2\nhold W 3\nlook 40 -10\npress C\nresize 320x200\nwait 4\nscreenshot small.png\n\
                  minimize\nwait 3\nrestore\nresize 400x300\nwait 4\n";
    let frames = tw_view::script::Script::parse(script, Path::new("s")).unwrap().frames();
    assert_eq!(frames, 17);
    for backend in ["vulkan", "gl"] {
        let dir = tempfile::tempdir().unwrap();
        let script_file = dir.path().join("script.txt");
        std::fs::write(&script_file, script).unwrap();
        let stop = ["--script", script_file.to_str().unwrap()];
        let Some((run, _)) = run_under_xvfb(store(), backend, &stop, "17 frames (3 minimised)", &[], true)
        else {
            continue;
        };
        assert_eq!(png_size(&run.path().join("small.png")), (320, 200), "{backend}: after the first resize");
        assert_eq!(png_size(&run.path().join("shot.png")), (400, 300), "{backend}: after restoring");
    }
}

#[test]
fn a_bad_script_is_a_clear_error_before_any_window() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.txt"), "wait 2\nhold W\n").unwrap();
    let s = store().to_str().unwrap();
    let o = terawalk(&["view", s, "--script", "s.txt"], dir.path());
    assert_clean_error(&o, "s.txt:2: `hold` takes 2 argument(s), found 1");
    let o = terawalk(&["view", s, "--script", "missing.txt"], dir.path());
    assert_clean_error(&o, "missing.txt");
    let o = terawalk(&["view", s, "--script", "s.txt", "--exit-after", "3"], dir.path());
    assert_clean_error(&o, "give one of them");
}

/// Three named unit cubes side by side along x (`left` [0, 1], `middle` [1.5, 2.5], `right`
/// [3, 4]; y and z in [0, 1]), built through the CLI in metres: a model whose objects and
/// points are known, for the design-review tools.
fn cubes_store() -> &'static Path {
    static STORE: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &STORE
        .get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let mut obj = String::new();
            for (k, (name, x0)) in [("left", 0.0), ("middle", 1.5), ("right", 3.0)].into_iter().enumerate() {
                obj += &format!("o {name}\n");
                // Vertex i: x bit 2, y bit 1, z bit 0.
                for i in 0..8 {
                    obj += &format!("v {} {} {}\n", x0 + (i >> 2) as f64, (i >> 1) & 1, i & 1);
                }
                let v = |x: usize, y: usize, z: usize| k * 8 + x * 4 + y * 2 + z + 1;
                for a in 0..2 {
                    for q in [
                        [v(a, 0, 0), v(a, 1, 0), v(a, 1, 1), v(a, 0, 1)],
                        [v(0, a, 0), v(1, a, 0), v(1, a, 1), v(0, a, 1)],
                        [v(0, 0, a), v(1, 0, a), v(1, 1, a), v(0, 1, a)],
                    ] {
                        obj += &format!("f {} {} {}\nf {} {} {}\n", q[0], q[1], q[2], q[0], q[2], q[3]);
                    }
                }
            }
            std::fs::write(dir.path().join("cubes.obj"), obj).unwrap();
            let o = terawalk(
                &["-q", "build", "cubes.obj", "-o", "cubes.tw", "--units", "m", "--threads", "1"],
                dir.path(),
            );
            assert!(o.status.success(), "{}", text(&o.stderr));
            let p = dir.path().join("cubes.tw");
            (dir, p)
        })
        .1
}

/// Runs `script` in the viewer under Xvfb (Vulkan) over a copy of `store_file` in the run's
/// folder (its viewpoints file is written there), without a path; returns the folder and
/// stderr (the viewer's messages), or None when skipped as [`run_under_xvfb`] skips.
fn review_session(store_file: &Path, script: &str) -> Option<(tempfile::TempDir, String)> {
    script_session(store_file, script, &[]).map(|(dir, _, err)| (dir, err))
}

/// [`review_session`] with more options; returns the folder, stdout and stderr.
fn script_session(
    store_file: &Path,
    script: &str,
    extra: &[&str],
) -> Option<(tempfile::TempDir, String, String)> {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(store_file, dir.path().join("m.tw")).unwrap();
    let args: Vec<&str> = ["m.tw"].into_iter().chain(extra.iter().copied()).collect();
    xvfb_view(dir, script, &args)
}

/// Runs `terawalk view ARGS --script` under Xvfb (Vulkan) in `dir`, with `script`; returns the
/// folder, stdout and stderr, or None when skipped as [`run_under_xvfb`] skips.
fn xvfb_view(
    dir: tempfile::TempDir,
    script: &str,
    extra: &[&str],
) -> Option<(tempfile::TempDir, String, String)> {
    let _one = XVFB.lock().unwrap_or_else(|e| e.into_inner());
    let Some(xvfb_run) = which("xvfb-run") else {
        assert!(!require_gpu(), "TERAWALK_REQUIRE_GPU is set but xvfb-run is missing");
        eprintln!("skipped: xvfb-run not found (apt-get install xvfb xauth)");
        return None;
    };
    std::fs::write(dir.path().join("script.txt"), script).unwrap();
    let mut cmd = Command::new(xvfb_run);
    cmd.args(["-a", "-s", "-screen 0 1024x768x24", env!("CARGO_BIN_EXE_terawalk"), "view"])
        .args(["--size", "480x320", "--script", "script.txt"])
        .args(extra)
        .current_dir(dir.path())
        .env("WGPU_BACKEND", "vulkan")
        .env("TERAWALK_LOG", "info,wgpu_hal=off,wgpu_core=warn,naga=warn");
    let lvp = Path::new("/usr/share/vulkan/icd.d/lvp_icd.x86_64.json");
    if std::env::var_os("VK_ICD_FILENAMES").is_none() && lvp.exists() {
        cmd.env("VK_ICD_FILENAMES", lvp);
    }
    let o = run_with_timeout(cmd, Duration::from_secs(240)).expect("the viewer did not exit in time");
    let err = text(&o.stderr);
    if !o.status.success() {
        let no_device = err.contains("no GPU adapter") || err.contains("cannot open a window");
        assert!(no_device && !require_gpu(), "view failed: {err}");
        eprintln!("skipped: no display or adapter: {err}");
        return None;
    }
    assert!(!err.contains("panicked"), "{err}");
    Some((dir, text(&o.stdout), err))
}

/// A PNG's RGBA pixels and width.
fn rgba(png_file: &Path) -> (Vec<u8>, usize) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(png_file).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    (buf, info.width as usize)
}

/// Pixels that are not the background in the columns `x0..x1`.
fn covered_in_columns(png_file: &Path, x0: usize, x1: usize) -> usize {
    let (px, w) = rgba(png_file);
    px.chunks_exact(4)
        .enumerate()
        .filter(|(i, p)| (x0..x1).contains(&(i % w)) && p[..3] != [205, 218, 235])
        .count()
}

/// The text after `needle` in the viewer's messages, up to the end of its line.
fn message_after<'a>(err: &'a str, needle: &str) -> &'a str {
    let at = err.find(needle).unwrap_or_else(|| panic!("no {needle:?} in: {err}")) + needle.len();
    err[at..].lines().next().unwrap_or_default()
}

#[test]
fn pick_hide_isolate_and_measure_under_xvfb() {
    // From -y the three cubes stand side by side: `left` in columns ~90..180, `middle` around
    // the centre (~200..280), `right` ~300..390; the centre pixel's ray hits `middle`'s front
    // face at (2, 0, 0.5). From +x the centre pixel hits `right` at (4, 0.5, 0.5).
    let script = "view -y\nwait 8\nscreenshot front.png\nclick 240 160\nwait 3\nscreenshot picked.png\n\
                  press I\nwait 3\nscreenshot isolated.png\npress shift+H\nwait 3\nclick 240 160\n\
                  press H\nwait 3\nscreenshot hidden.png\npress shift+H\nwait 3\nscreenshot all.png\n\
                  press M\nclick 240 160\nview +x\nwait 8\nclick 240 160\nwait 1\n";
    let Some((dir, err)) = review_session(cubes_store(), script) else { return };
    let shot = |n: &str| dir.path().join(n);
    // The pick names the object, its triangles, the point and the box in metres.
    let picked = message_after(&err, "picked ");
    assert!(picked.starts_with("`middle` (id 1): 12 triangles, at (2.0000, 0.0000, 0.5000) m"), "{picked}");
    assert!(picked.contains("box (1.5000, 0.0000, 0.0000) – (2.5000, 1.0000, 1.0000)"), "{picked}");
    // Tinted orange: the centre pixel turns from grey to red > blue.
    let centre = |n: &str| {
        let (px, w) = rgba(&shot(n));
        let i = (160 * w + 240) * 4;
        [px[i] as i32, px[i + 1] as i32, px[i + 2] as i32]
    };
    let (grey, tinted) = (centre("front.png"), centre("picked.png"));
    assert!((grey[0] - grey[2]).abs() < 10 && tinted[0] > tinted[2] + 60, "{grey:?} → {tinted:?}");
    // Isolated: nothing but `middle` leaves the background; all three before and after.
    let (left, mid, right) = ((0, 190), (200, 280), (290, 480));
    for n in ["front.png", "all.png"] {
        for (x0, x1) in [left, mid, right] {
            assert!(covered_in_columns(&shot(n), x0, x1) > 1000, "{n}: columns {x0}..{x1} empty");
        }
    }
    let iso = shot("isolated.png");
    assert_eq!(covered_in_columns(&iso, left.0, left.1) + covered_in_columns(&iso, right.0, right.1), 0);
    assert!(covered_in_columns(&iso, mid.0, mid.1) > 1000);
    // Hidden: `middle` is gone, the others stay.
    let hidden = shot("hidden.png");
    assert_eq!(covered_in_columns(&hidden, mid.0 + 10, mid.1 - 10), 0);
    assert!(
        covered_in_columns(&hidden, left.0, left.1) > 1000
            && covered_in_columns(&hidden, right.0, right.1) > 1000
    );
    // Measured from (2, 0, 0.5) to (4, 0.5, 0.5): √4.25 m.
    let m = message_after(&err, "measure: distance ");
    let d: f64 = m.split_whitespace().next().and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("{m}"));
    assert!((d - 4.25f64.sqrt()).abs() < 1e-3 && m.contains(" m from (2.0000, 0.0000, 0.5000)"), "{m}");

    // Snapping: clicks 2 pixels inside the corners of `middle`'s front face (found in the
    // first session's picture) measure corner to corner, (2.5, 0, 1) to (1.5, 0, 0): √2 m.
    let (px, w) = rgba(&shot("front.png"));
    let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
    for (i, p) in px.chunks_exact(4).enumerate() {
        let (x, y) = (i % w, i / w);
        if (mid.0..mid.1).contains(&x) && p[..3] != [205, 218, 235] {
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
        }
    }
    let script = format!(
        "view -y\nwait 8\npress M\nclick {} {}\nclick {} {}\nwait 1\n",
        x1 - 2,
        y0 + 2,
        x0 + 2,
        y1 - 2
    );
    let Some((_, err)) = review_session(cubes_store(), &script) else { return };
    let m = message_after(&err, "measure: distance ");
    let d: f64 = m.split_whitespace().next().and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("{m}"));
    assert!((d - 2f64.sqrt()).abs() < 1e-4 && m.contains("(2.5000, 0.0000, 1.0000)"), "{m}");
    assert!(m.ends_with("snapped to a vertex"), "{m}");
}

/// Every text after `needle` in the viewer's messages, each up to the end of its line.
fn messages_after<'a>(err: &'a str, needle: &str) -> Vec<&'a str> {
    err.match_indices(needle)
        .map(|(at, _)| err[at + needle.len()..].lines().next().unwrap_or_default())
        .collect()
}

/// The first number of a message (a distance, a coordinate).
fn leading_number(m: &str) -> f64 {
    m.split_whitespace().next().and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("no number: {m}"))
}

/// The point `(x, y, z)` after "at " in a pick message.
fn picked_point(m: &str) -> [f64; 3] {
    let at = m.find("at (").unwrap_or_else(|| panic!("no point in {m}")) + 4;
    let v: Vec<f64> = m[at..].split(')').next().unwrap().split(", ").map(|v| v.parse().unwrap()).collect();
    [v[0], v[1], v[2]]
}

/// The covered box (x0, x1, y0, y1) of the pixels in columns `cols` of a screenshot.
fn covered_box(png_file: &Path, cols: (usize, usize)) -> (usize, usize, usize, usize) {
    let (px, w) = rgba(png_file);
    let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
    for (i, p) in px.chunks_exact(4).enumerate() {
        let (x, y) = (i % w, i / w);
        if (cols.0..cols.1).contains(&x) && p[..3] != [205, 218, 235] {
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
        }
    }
    (x0, x1, y0, y1)
}

/// Measurement-yellow pixels (the line's colour, `MEASURE_COLOR`) in row `y` ± 1 between
/// columns `x0..x1` of a window screenshot.
fn yellow_in_row(png_file: &Path, y: usize, x0: usize, x1: usize) -> usize {
    let (px, w) = rgba(png_file);
    px.chunks_exact(4)
        .enumerate()
        .filter(|(i, p)| {
            (y - 1..=y + 1).contains(&(i / w))
                && (x0..x1).contains(&(i % w))
                && p[0] > 200
                && p[1] > 170
                && p[2] < 120
        })
        .count()
}

#[test]
fn edge_snapping_and_point_to_plane_measuring_under_xvfb() {
    // `middle`'s front face from -y spans x 1.5..2.5 on y = 0 (found in a first picture). Clicks
    // 2 pixels inside its left and right edges on one row land on the surface about 0.05 m short
    // of each edge; measuring snaps them onto both edges: exactly 1 m. Then to a plane: the
    // first click (from +x, the centre: `right`'s face x = 4) sets the plane, a click near
    // `middle`'s left edge from -y is 2.5 m from it, the centre of `middle`'s face 2 m.
    let Some((dir, _)) = review_session(cubes_store(), "view -y\nwait 8\nscreenshot front.png\n") else {
        return;
    };
    let (x0, x1, y0, y1) = covered_box(&dir.path().join("front.png"), (200, 280));
    let (xl, xr, row) = (x0 + 2, x1 - 2, (y0 + y1) / 2);
    let script = format!(
        "view -y\nwait 8\nclick {xl} {row}\nclick {xr} {row}\npress M\nclick {xl} {row}\nclick {xr} {row}\n\
         press Tab\nwait 2\nscreenshot-window points.png\nwait 1\nmeasure plane\nview +x\nwait 8\n\
         click 240 160\nview -y\nwait 8\nclick 240 160\nclick {xl} {row}\nwait 2\nscreenshot-window plane.png\n\
         wait 1\n"
    );
    let Some((dir, err)) = review_session(cubes_store(), &script) else { return };
    // Unsnapped, the clicks are on the surface, inside the edges.
    let picks = messages_after(&err, "picked `middle` (id 1): 12 triangles, ");
    assert_eq!(picks.len(), 2, "{err}");
    let (l, r) = (picked_point(picks[0]), picked_point(picks[1]));
    assert!(l[0] > 1.5 + 1e-3 && r[0] < 2.5 - 1e-3 && r[0] - l[0] < 0.99, "surface {l:?} {r:?}");
    // Snapped onto both edges: 1 m to the model's precision (f32 on a 4 m scene).
    let m = message_after(&err, "measure: distance ");
    assert!(m.starts_with("1.0000 m from (1.5000, 0.0000, ") && m.ends_with("snapped to an edge"), "{m}");
    assert!(err.contains("measure: first point (1.5000, 0.0000, "), "{err}");
    // The line between them, yellow over the scene along the row.
    assert!(yellow_in_row(&dir.path().join("points.png"), row, xl + 5, xr - 5) > (xr - xl) / 2, "no line");
    // To the plane x = 4 through `right`'s face.
    let plane = message_after(&err, "measure: plane through ");
    assert!(plane.starts_with("(4.0000, ") && plane.contains("1.0000, 0.0000, 0.0000)"), "{plane}");
    let d = messages_after(&err, "measure: distance to the plane ");
    assert_eq!(d.len(), 2, "{err}");
    assert!((leading_number(d[0]) - 2.0).abs() < 1e-3 && d[0].contains("to the foot (4.0000, "), "{}", d[0]);
    assert!(
        d[1].starts_with("2.5000 m from (1.5000, 0.0000, ") && d[1].ends_with("snapped to an edge"),
        "{}",
        d[1]
    );
    // The perpendicular from `middle`'s edge to the plane runs along the row, to `right`.
    assert!(yellow_in_row(&dir.path().join("plane.png"), row, xl + 5, xr + 60) > 60, "no perpendicular");
}

#[test]
fn model_tree_search_select_and_isolate_under_xvfb() {
    // A search for "IDD" finds `middle` alone; selecting its row tints it as a pick does, and
    // the tree's isolate leaves only its pixels. Then `right` by name (after show all).
    let script = "view -y\nwait 8\nscreenshot front.png\ntree-search IDD\ntree-select row=1\nwait 3\n\
                  screenshot selected.png\ntree-isolate\nwait 3\nscreenshot isolated.png\ntree-show-all\n\
                  tree-search\ntree-select RIGHT\ntree-frame\nwait 6\nscreenshot framed.png\n\
                  tree-select id=7\ntree-select row=9\nwait 1\n";
    let Some((dir, err)) = review_session(cubes_store(), script) else { return };
    let shot = |n: &str| dir.path().join(n);
    assert!(err.contains("model tree: 3 objects, made in "), "{err}");
    assert!(err.contains("model tree: 1 of 3 objects match `IDD` ("), "{err}");
    assert!(
        message_after(&err, "picked ").starts_with("`middle` (id 1): 12 triangles, box (1.5000, "),
        "{err}"
    );
    let colour = |n: &str, x: usize, y: usize| {
        let (px, w) = rgba(&shot(n));
        let i = (y * w + x) * 4;
        [px[i] as i32, px[i + 1] as i32, px[i + 2] as i32]
    };
    let tinted = |c: [i32; 3]| c[0] > c[2] + 60;
    // `middle` tinted, `left` and `right` not.
    assert!(tinted(colour("selected.png", 240, 160)), "{:?}", colour("selected.png", 240, 160));
    assert!(!tinted(colour("selected.png", 135, 160)) && !tinted(colour("selected.png", 345, 160)));
    assert!(!tinted(colour("front.png", 240, 160)));
    let (left, mid, right) = ((0, 190), (200, 280), (290, 480));
    let iso = shot("isolated.png");
    assert_eq!(covered_in_columns(&iso, left.0, left.1) + covered_in_columns(&iso, right.0, right.1), 0);
    assert!(covered_in_columns(&iso, mid.0, mid.1) > 1000);
    // `right` by name, framed: it fills the middle of the picture, tinted.
    assert!(err.contains("picked `right` (id 2)") && err.contains("framed `right` (object 2)"), "{err}");
    assert!(tinted(colour("framed.png", 240, 160)), "{:?}", colour("framed.png", 240, 160));
    assert!(coverage(&shot("framed.png")).0 > coverage(&shot("front.png")).0, "framing did not come closer");
    // Bad targets are said, not fatal.
    assert!(
        err.contains("model tree: no object id=7") || err.contains("model tree: no object #7 (3 objects)"),
        "{err}"
    );
    assert!(err.contains("model tree: row 9 is not an object (3 rows shown)"), "{err}");
}

#[test]
fn preset_views_viewpoints_and_ortho_under_xvfb() {
    // The +x view differs from the starting one; a viewpoint saved in the iso view and recalled
    // after moving elsewhere gives the same camera and the same picture, and its file is next to
    // the store; O toggles the orthographic view.
    let script = "wait 4\nscreenshot start.png\nview +x\nwait 6\nscreenshot x.png\nview iso\nwait 6\n\
                  save-view corner\nscreenshot saved.png\nview +z\nhold W 3\nwait 4\nscreenshot moved.png\n\
                  load-view corner\nwait 6\nscreenshot loaded.png\nload-view nowhere\nview -y\nwait 6\n\
                  screenshot perspective.png\npress O\nwait 6\nscreenshot ortho.png\npress O\nwait 6\n\
                  screenshot back.png\n";
    let Some((dir, err)) = review_session(cubes_store(), script) else { return };
    let img = |n: &str| tw_gpu::Image::from_png_bytes(&std::fs::read(dir.path().join(n)).unwrap()).unwrap();
    let share = |a: &str, b: &str| img(a).differing_share(&img(b)).unwrap();
    assert!(share("start.png", "x.png") > 0.02, "the +x view looks like the start");
    assert!(share("saved.png", "moved.png") > 0.02, "the camera did not move away");
    assert_eq!(share("saved.png", "loaded.png"), 0.0, "the viewpoint did not restore the picture");
    let saved = message_after(&err, "viewpoint `corner` saved to ");
    let loaded = message_after(&err, "viewpoint `corner` restored: ");
    assert!(saved.ends_with(loaded), "saved {saved} / loaded {loaded}");
    assert!(err.contains("no viewpoint `nowhere` in"), "{err}");
    let views = tw_view::viewpoints::Viewpoints::load(&dir.path().join("m.tw.views.json")).unwrap();
    assert_eq!(views.views.iter().map(|v| v.name.as_str()).collect::<Vec<_>>(), ["corner"]);
    // Orthographic from -y: the cubes' inner side faces (darker shades in perspective) vanish,
    // the front faces keep their place; O again returns to the perspective picture.
    let (_, perspective) = coverage(&dir.path().join("perspective.png"));
    let (_, ortho) = coverage(&dir.path().join("ortho.png"));
    assert!(perspective >= 2 && ortho < perspective, "colours: perspective {perspective}, ortho {ortho}");
    assert!(share("perspective.png", "ortho.png") < 0.05, "the orthographic view lost the framing");
    assert!(share("perspective.png", "back.png") < 0.005, "O twice did not return");
}

/// The wheel in an orthographic view (fly mode) zooms: three steps in make the cubes cover
/// more of the image, three out bring the picture back; the fly speed stays.
#[test]
fn the_wheel_zooms_an_orthographic_view_under_xvfb() {
    let script = "view -y\nwait 6\npress O\nwait 6\nscreenshot ortho.png\nscroll 3\nwait 6\n\
                  screenshot zoomed.png\nscroll -3\nwait 6\nscreenshot back.png\n";
    let Some((dir, err)) = review_session(cubes_store(), script) else { return };
    let covered = |n: &str| coverage(&dir.path().join(n)).0;
    let (ortho, zoomed) = (covered("ortho.png"), covered("zoomed.png"));
    assert!(zoomed > ortho * 1.5, "the wheel did not zoom in: {ortho} to {zoomed}: {err}");
    let img = |n: &str| tw_gpu::Image::from_png_bytes(&std::fs::read(dir.path().join(n)).unwrap()).unwrap();
    assert!(
        img("ortho.png").differing_share(&img("back.png")).unwrap() < 0.005,
        "zooming out did not return"
    );
}

/// F11 under Xvfb, where no window manager answers the fullscreen request: the viewer covers
/// the 1024×768 screen with its window itself, and F11 again restores the window's size.
#[test]
fn f11_fills_the_screen_without_a_window_manager_and_returns() {
    let script = "wait 4\nscreenshot windowed.png\npress F11\nwait 10\nscreenshot full.png\n\
                  press F11\nwait 10\nscreenshot back.png\n";
    let Some((dir, err)) = review_session(store(), script) else { return };
    let size = |n: &str| png_size(&dir.path().join(n));
    assert_eq!(size("windowed.png"), (480, 320), "{err}");
    assert_eq!(size("full.png"), (1024, 768), "F11 did not fill the screen: {err}");
    assert_eq!(size("back.png"), (480, 320), "F11 again did not restore the window: {err}");
    assert!(err.contains("no window manager answered"), "{err}");
    assert!(err.contains("fullscreen off"), "{err}");
}

#[test]
fn flashlight_needs_the_ray_tracer() {
    let dir = tempfile::tempdir().unwrap();
    let s = store().to_str().unwrap();
    let o = terawalk(&["view", s, "--flashlight", "--exit-after", "1"], dir.path());
    assert_clean_error(&o, "--flashlight needs --renderer rt");
}

#[test]
fn ray_traced_view_supersamples_while_the_camera_stands_still() {
    // `--renderer rt` with a still camera: the CPU ray tracer's image goes into the window's
    // scene texture (screenshots read it back) and each frame adds a sample per pixel; T turns
    // the flashlight on, which starts the mean again, and the samples then add up again.
    let script = "wait 3\nscreenshot first.png\npress T\nwait 12\n";
    let extra = ["--renderer", "rt", "--screenshot", "shot.png"];
    let Some((dir, out, err)) = script_session(store(), script, &extra) else { return };
    assert!(err.contains("flashlight on"), "T did not toggle the flashlight: {err}");
    let number = |line: &str| -> u32 {
        line.split_whitespace().next().and_then(|n| n.parse().ok()).unwrap_or_else(|| panic!("{out}"))
    };
    let frames = number(out.lines().find(|l| l.contains(" frames (")).unwrap_or_default());
    let samples = number(message_after(&out, "ray traced: "));
    // One a frame at most, and fewer than the frames (the flashlight started the mean again
    // after the third); more than one, unless pages kept changing the cut until the end.
    assert!(frames >= 15 && (2..=frames - 3).contains(&samples), "{samples} samples per pixel: {out}");
    for shot in ["first.png", "shot.png"] {
        let (covered, colours) = coverage(&dir.path().join(shot));
        assert!(covered > 0.05 && colours >= 8, "{shot}: {covered} covered, {colours} colours");
    }
}

#[test]
fn shadow_keys_turn_the_light_under_xvfb() {
    // `--light sun:30,45` starts with shadows on. `]` turns the sun by 5° around the up axis,
    // Shift+[ lowers it by 5°, J turns shadows off and on, U leaves a point light at the eye and
    // U again returns to the sun; G then traces the same light with shadow rays. Each key says
    // the light in the message line.
    let script = "wait 3\nscreenshot lit.png\npress ]\npress shift+[\nwait 2\npress J\nwait 2\npress J\n\
                  press U\nwait 2\nscreenshot point.png\npress U\npress G\nwait 3\n";
    let extra = ["--light", "sun:30,45", "--shadow-map", "512", "--screenshot", "shot.png"];
    let Some((dir, _, err)) = script_session(store(), script, &extra) else { return };
    for said in [
        "shadows: sun at azimuth 35°, elevation 45°",
        "shadows: sun at azimuth 35°, elevation 40°",
        "shadows off (J on)",
        "shadows: point light at (",
        "renderer: rt",
    ] {
        assert!(err.contains(said), "no {said:?} in: {err}");
    }
    assert!(message_after(&err, "shadows: point light at (").contains("U back to the sun"), "{err}");
    for shot in ["lit.png", "point.png", "shot.png"] {
        let (covered, colours) = coverage(&dir.path().join(shot));
        assert!(covered > 0.05 && colours >= 8, "{shot}: {covered} covered, {colours} colours");
    }
}

/// A slab as wide as [`cubes_store`]'s row of cubes (x 0..4, y 0..1, z 0..1, the same bounds):
/// from -y it also covers the gaps between the cubes. ASCII PLY, built by the viewer's opener.
fn slab_ply(path: &Path) {
    let mut ply = String::from(
        "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n\
         element face 12\nproperty list uchar int vertex_indices\nend_header\n",
    );
    // Vertex i: x bit 2 (0 or 4), y bit 1, z bit 0.
    for i in 0..8 {
        ply += &format!("{} {} {}\n", 4 * (i >> 2), (i >> 1) & 1, i & 1);
    }
    let v = |x: usize, y: usize, z: usize| x * 4 + y * 2 + z;
    for a in 0..2 {
        for q in [
            [v(a, 0, 0), v(a, 1, 0), v(a, 1, 1), v(a, 0, 1)],
            [v(0, a, 0), v(1, a, 0), v(1, a, 1), v(0, a, 1)],
            [v(0, 0, a), v(1, 0, a), v(1, 1, a), v(0, 1, a)],
        ] {
            ply += &format!("3 {} {} {}\n3 {} {} {}\n", q[0], q[1], q[2], q[0], q[2], q[3]);
        }
    }
    std::fs::write(path, ply).unwrap();
}

/// Switching the scene at run time: on the cubes, `open` a PLY model (built in the background
/// into `--cache-dir`), then `drop` another store, then `open` a broken file; each opened
/// scene is seen from -y, where the slab covers the gaps the cubes leave, and the broken file
/// leaves the cubes shown with the error said.
#[test]
fn open_and_drop_switch_the_scene_under_xvfb() {
    let (gap_a, gap_b) = ((184, 197), (284, 297));
    let script = "view -y\nwait 8\nscreenshot cubes.png\nscreenshot-window plain.png\nwait 1\npress ctrl+O\n\
                  wait 3\nscreenshot-window dialog.png\nwait 1\nopen slab.ply\nwait-open 2000\nview -y\nwait 8\n\
                  screenshot slab.png\ndrop other.tw\nwait-open 2000\nview -y\nwait 8\nscreenshot dropped.png\n\
                  open broken.ply\nwait-open 2000\nwait 4\nscreenshot-window error.png\nwait 2\n\
                  screenshot after.png\npress Escape\nwait 3\nscreenshot-window closed.png\nwait 2\n";
    let scratch = tempfile::tempdir().unwrap();
    // The session copies the store it starts on; the files it opens are made here and copied
    // in by the script's relative paths, from the session's folder.
    let cubes = cubes_store();
    slab_ply(&scratch.path().join("slab.ply"));
    std::fs::copy(cubes, scratch.path().join("other.tw")).unwrap();
    std::fs::write(scratch.path().join("broken.ply"), "ply\nformat ascii 1.0\nelement vertex 3\n").unwrap();
    let cache = scratch.path().join("cache");
    let extra = ["--cache-dir", cache.to_str().unwrap()];
    let script = script
        .replace("slab.ply", scratch.path().join("slab.ply").to_str().unwrap())
        .replace("other.tw", scratch.path().join("other.tw").to_str().unwrap())
        .replace("broken.ply", scratch.path().join("broken.ply").to_str().unwrap());
    let Some((dir, _, err)) = script_session(cubes, &script, &extra) else { return };
    let shot = |n: &str| dir.path().join(n);
    let gaps = |n: &str| {
        covered_in_columns(&shot(n), gap_a.0, gap_a.1) + covered_in_columns(&shot(n), gap_b.0, gap_b.1)
    };
    let whole = |n: &str| covered_in_columns(&shot(n), 0, 480);
    // The slab fills the gaps the cubes leave (at most the cubes' side faces show there).
    let (cubes_gaps, slab_gaps) = (gaps("cubes.png"), gaps("slab.png"));
    eprintln!("covered pixels in the gaps: cubes {cubes_gaps}, slab {slab_gaps}");
    assert!(
        slab_gaps > 2 * cubes_gaps + 500,
        "the opened slab is not shown: gaps {cubes_gaps} → {slab_gaps}: {err}"
    );
    assert!(err.contains("opened ") && err.contains("slab.ply (12 triangles, 1 objects)"), "{err}");
    let cached: Vec<_> = std::fs::read_dir(scratch.path().join("cache")).unwrap().flatten().collect();
    assert!(cached.iter().any(|e| e.file_name().to_string_lossy().starts_with("slab-")), "{cached:?}");
    // The dropped store is the cubes again: the picture returns to the first one's.
    assert_eq!(gaps("dropped.png"), cubes_gaps, "{err}");
    assert_eq!(whole("dropped.png"), whole("cubes.png"), "{err}");
    // Ctrl+O shows the open dialog over the window (the scene image stays the same).
    let img = |n: &str| tw_gpu::Image::from_png_bytes(&std::fs::read(shot(n)).unwrap()).unwrap();
    let dialog = img("plain.png").differing_share(&img("dialog.png")).unwrap();
    assert!(dialog > 0.05, "Ctrl+O showed no dialog ({dialog} of the window changed): {err}");
    // The broken file: said, and the cubes stay.
    let said = message_after(&err, "cannot open ");
    assert!(said.contains("broken.ply"), "{said}");
    assert_eq!(gaps("after.png"), cubes_gaps, "the scene changed after a failed open: {err}");
    // The error window: red text in the window's screenshot (the scene has none).
    let red = |n: &str| {
        let (px, _) = rgba(&shot(n));
        px.chunks_exact(4).filter(|p| p[0] > 200 && p[1] < 140 && p[2] < 130).count()
    };
    assert!(red("error.png") > 20, "no error window ({} red pixels): {err}", red("error.png"));
    // Esc closes it (and does not quit: the script ran to its end).
    assert_eq!(red("closed.png"), 0, "Esc did not close the error window: {err}");
    assert!(err.contains("closed the open dialog"), "{err}");
}

/// `view` with no file: the window shows the hint and the open dialog (Esc closes it and does
/// not quit); a screenshot step before any scene is said, not taken; `open` a store shows it,
/// and the script runs on to its end (exit 0).
#[test]
fn view_with_no_file_starts_with_the_open_dialog_under_xvfb() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(cubes_store(), dir.path().join("cubes.tw")).unwrap();
    // Without a scene frames are quick: egui's windows need some to fade in and out.
    let script = "wait 40\nscreenshot-window dialog.png\nwait 1\npress Escape\nwait 40\n\
                  screenshot-window hint.png\nwait 1\nscreenshot early.png\nclick 240 160\nview -y\npress F12\n\
                  press shift+F12\nwait 2\n\
                  open cubes.tw\nwait-open 2000\nview -y\nwait 8\nscreenshot cubes.png\n";
    let Some((dir, out, err)) = xvfb_view(dir, script, &[]) else { return };
    let shot = |n: &str| dir.path().join(n);
    let img = |n: &str| tw_gpu::Image::from_png_bytes(&std::fs::read(shot(n)).unwrap()).unwrap();
    // The dialog covers much of the window; closed, the plain background and the hint remain.
    let dialog = img("hint.png").differing_share(&img("dialog.png")).unwrap();
    assert!(dialog > 0.1, "no open dialog at the start ({dialog} of the window changed): {err}");
    let dark = |n: &str, y0: usize, y1: usize| {
        let (px, w) = rgba(&shot(n));
        px.chunks_exact(4).enumerate().filter(|(i, p)| (y0..y1).contains(&(i / w)) && p[0] < 120).count()
    };
    // The dialog is a dark window in the middle.
    let dialog_px = dark("dialog.png", 40, 260);
    assert!(dialog_px > 20000, "no open dialog at the start ({dialog_px} dark pixels): {err}");
    // The hint's dark text along the top; the rest is the background (and the Open… button).
    assert!(
        dark("hint.png", 0, 40) > 100,
        "no hint at the top ({} dark pixels): {err}",
        dark("hint.png", 0, 40)
    );
    assert_eq!(dark("hint.png", 40, 260), 0, "the empty window is not plain: {err}");
    assert!(err.contains("closed the open dialog"), "{err}");
    // Before any scene: the screenshot is said not to be taken, clicks and views do nothing.
    assert!(!shot("early.png").exists());
    assert!(message_after(&err, "screenshot early.png").contains("no scene yet"), "{err}");
    assert!(err.contains("needs a scene"), "{err}");
    assert!(err.contains("screenshot: no scene yet (open"), "F12: {err}");
    // Shift+F12, the whole window, works without a scene.
    let windows = std::fs::read_dir(dir.path()).unwrap().flatten();
    assert!(
        windows.into_iter().any(|e| e.file_name().to_string_lossy().starts_with("terawalk-window-")),
        "{err}"
    );
    // The store opened: the cubes show.
    assert!(err.contains("opened cubes.tw (36 triangles, 3 objects)"), "{err}");
    let covered = covered_in_columns(&shot("cubes.png"), 0, 480);
    assert!(covered > 5000, "the opened store is not shown ({covered} px): {err}");
    assert!(out.contains("frames"), "{out}");
}

/// `view MODEL` with a model the cache lacks: the window opens at once with the build's
/// progress, the model shows when the build ends (`wait-open`), and the cache holds its store;
/// a second run finds it there and opens it before the window.
#[test]
fn view_a_model_builds_it_in_the_window_under_xvfb() {
    let dir = tempfile::tempdir().unwrap();
    slab_ply(&dir.path().join("slab.ply"));
    let script = "screenshot-window start.png\nwait-open 2000\nview -y\nwait 8\nscreenshot slab.png\n";
    let Some((dir, _, err)) = xvfb_view(dir, script, &["slab.ply", "--cache-dir", "cache"]) else { return };
    assert!(err.contains("opening slab.ply"), "the build did not run in the window: {err}");
    assert!(err.contains("opened slab.ply (12 triangles, 1 objects)"), "{err}");
    // From -y the slab covers the whole row, gaps included.
    let covered = covered_in_columns(&dir.path().join("slab.png"), 0, 480);
    assert!(covered > 20000, "the model is not shown ({covered} px): {err}");
    let cached: Vec<_> = std::fs::read_dir(dir.path().join("cache")).unwrap().flatten().collect();
    assert!(cached.iter().any(|e| e.file_name().to_string_lossy().starts_with("slab-")), "{cached:?}");
    // Cached now: opened before the window, as a store.
    let script = "view -y\nwait 8\nscreenshot again.png\n";
    let dir = {
        let again = dir;
        let Some((again, out, err)) = xvfb_view(again, script, &["slab.ply", "--cache-dir", "cache"]) else {
            return;
        };
        assert!(out.contains("using cached store") || err.contains("using cached store"), "{out}{err}");
        assert!(!err.contains("opening slab.ply"), "{err}");
        again
    };
    assert_eq!(covered_in_columns(&dir.path().join("again.png"), 0, 480), covered);
}

/// Options that need a scene's coordinates are refused without a file, before any window.
#[test]
fn view_with_no_file_refuses_a_camera() {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["view", "--camera", "0,0,0;1,0,0;0,0,1;60"], dir.path());
    assert_clean_error(&o, "--camera needs a FILE to view");
    let o = terawalk(&["view", "--play"], dir.path());
    assert_clean_error(&o, "--play needs --path FILE");
}

/// `--screenshot` at the end of a run that opened no scene: a clear error (exit 1), no panic.
#[test]
fn a_screenshot_without_a_scene_is_a_clear_error() {
    let _one = XVFB.lock().unwrap_or_else(|e| e.into_inner());
    let Some(xvfb_run) = which("xvfb-run") else {
        assert!(!require_gpu(), "TERAWALK_REQUIRE_GPU is set but xvfb-run is missing");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("script.txt"), "wait 2\n").unwrap();
    let mut cmd = Command::new(xvfb_run);
    cmd.args(["-a", "-s", "-screen 0 1024x768x24", env!("CARGO_BIN_EXE_terawalk"), "view"])
        .args(["--size", "320x240", "--script", "script.txt", "--screenshot", "end.png"])
        .current_dir(dir.path())
        .env("WGPU_BACKEND", "vulkan");
    let lvp = Path::new("/usr/share/vulkan/icd.d/lvp_icd.x86_64.json");
    if std::env::var_os("VK_ICD_FILENAMES").is_none() && lvp.exists() {
        cmd.env("VK_ICD_FILENAMES", lvp);
    }
    let o = run_with_timeout(cmd, Duration::from_secs(120)).expect("the viewer did not exit in time");
    let err = text(&o.stderr);
    if err.contains("no GPU adapter") || err.contains("cannot open a window") {
        assert!(!require_gpu(), "{err}");
        return;
    }
    assert_clean_error(&o, "no scene was opened: nothing to write to end.png");
    assert!(!dir.path().join("end.png").exists());
}

/// Three unit cubes as in [`cubes_store`] (`left`, `middle`, `right` at x 0, 1.5, 3), wound
/// counter-clockwise seen from outside, as the section colour of back faces expects.
fn wound_cubes_store() -> &'static Path {
    static STORE: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &STORE
        .get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let obj = common::wound_cubes_obj(&[("left", 0.0), ("middle", 1.5), ("right", 3.0)]);
            std::fs::write(dir.path().join("cubes.obj"), obj).unwrap();
            let o = terawalk(&["-q", "build", "cubes.obj", "-o", "cubes.tw", "--units", "m"], dir.path());
            assert!(o.status.success(), "{}", text(&o.stderr));
            let p = dir.path().join("cubes.tw");
            (dir, p)
        })
        .1
}

#[test]
fn section_planes_and_box_under_xvfb() {
    // From -y: `left` in columns ~90..180, `middle` ~200..280, `right` ~300..390. The scene box
    // is x 0..4, so a plane at x fraction 0.5 is x = 2 (through `middle`) and a box to x
    // fraction 0.3 (x ≤ 1.2) holds `left` only.
    let script = "view -y\nwait 8\nscreenshot front.png\nsection-plane x 0.5\nwait 3\nscreenshot plane.png\n\
                  section-flip 1\nwait 3\nscreenshot flipped.png\nsection-move 1 0.1\nwait 3\n\
                  screenshot moved.png\nsection-toggle\nwait 3\nscreenshot off.png\nsection-toggle\n\
                  section-clear\nsection-box 0 0 0 0.3 1 1\nwait 3\nscreenshot box.png\nsection-clear\n\
                  wait 3\nclick 240 160\nsection-plane picked\nwait 3\nscreenshot picked.png\nsection-flip 3\n\
                  section-clear\npress Escape\nwait 3\nscreenshot cleared.png\n";
    let Some((dir, err)) = review_session(wound_cubes_store(), script) else { return };
    let shot = |n: &str| dir.path().join(n);
    let (px, w) = rgba(&shot("front.png"));
    let same_in = |n: &str, x0: usize, x1: usize| {
        let (q, _) = rgba(&shot(n));
        px.chunks_exact(4)
            .zip(q.chunks_exact(4))
            .enumerate()
            .all(|(i, (a, b))| !(x0..x1).contains(&(i % w)) || a == b)
    };
    let (left, right) = ((0, 190), (290, 480));
    for (x0, x1) in [left, (200, 280), right] {
        assert!(covered_in_columns(&shot("front.png"), x0, x1) > 1000, "columns {x0}..{x1} empty");
    }
    // x ≥ 2: `left` gone, `right` as before; flipped, x ≤ 2: the other way round.
    assert_eq!(covered_in_columns(&shot("plane.png"), left.0, left.1), 0);
    assert!(same_in("plane.png", right.0, right.1), "right changed under the plane");
    assert_eq!(covered_in_columns(&shot("flipped.png"), right.0, right.1), 0);
    assert!(same_in("flipped.png", left.0, left.1), "left changed under the flipped plane");
    // Moved by 0.1 × the diagonal (≈ 0.42 m) towards −x: x ≤ ~1.58 cuts most of `middle`.
    let moved = covered_in_columns(&shot("moved.png"), 200, 280);
    let flipped = covered_in_columns(&shot("flipped.png"), 200, 280);
    assert!(moved < flipped, "moving the plane removed nothing: {moved} vs {flipped}");
    // Off: the whole scene; the box keeps `left` only.
    assert!(same_in("off.png", 0, w), "the section toggled off still cuts");
    assert_eq!(covered_in_columns(&shot("box.png"), 200, 480), 0);
    assert!(same_in("box.png", left.0, left.1));
    // A plane through the picked front face of `middle` removes that face (and the eye's side
    // of every cube): the centre pixel shows `middle`'s inside, the back wall in the section
    // colour.
    assert!(message_after(&err, "section: ").starts_with("plane 1 across x at 0.5"), "{err}");
    assert!(err.contains("section: plane 1 through the picked point"), "{err}");
    let (q, _) = rgba(&shot("picked.png"));
    let i = (160 * w + 240) * 4;
    let centre = [q[i] as i32, q[i + 1] as i32, q[i + 2] as i32];
    assert!(
        (centre[0] - 200).abs() <= 2 && (centre[1] - 30).abs() <= 2 && (centre[2] - 60).abs() <= 2,
        "{centre:?}"
    );
    assert!(err.contains("section: no section plane 3 (there are 1)"), "{err}");
    assert!(same_in("cleared.png", 0, w), "cleared (and the pick's tint with Esc), the scene is whole again");
}
