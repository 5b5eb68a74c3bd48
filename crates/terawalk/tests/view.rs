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
    // One Xvfb at a time: `xvfb-run -a` picks a free display number racily.
    static XVFB: std::sync::Mutex<()> = std::sync::Mutex::new(());
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
    // renderer's own target and copied into the window's texture.
    scripted_run_with("vulkan", &["--occlusion", "hzb"], true);
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
