//! Opening a model directly (`terawalk render model.ply`: built once into the cache, reused,
//! rebuilt when the file changes, the cache bounded) and rendering image sequences of a camera
//! path (`--frames-dir`, `--video` through ffmpeg). The cache is always a temporary folder
//! (`TERAWALK_CACHE`), never the user's. Rendering runs on whatever adapter wgpu finds (Mesa's
//! CPU Vulkan driver here); without one the rendering checks are skipped unless
//! `TERAWALK_REQUIRE_GPU=1`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::{Duration, SystemTime};

mod common;

use common::{no_gpu, stderr, stdout, terawalk};

/// The program with `args` in `dir`, its build cache in `cache`.
fn terawalk_cached(args: &[&str], dir: &Path, cache: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(args)
        .current_dir(dir)
        .env("TERAWALK_CACHE", cache)
        .output()
        .expect("runs")
}

/// A 30k-triangle plant, its store and a 6-frame camera path through it, made once.
fn plant() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let cache = d.join("cache");
        for args in [
            &["generate", "plant", "--triangles", "30000", "-o", "p.ply"][..],
            &["-q", "build", "p.ply", "-o", "p.tw", "--memory", "256M", "--threads", "2"],
            &["path", "p.tw", "-o", "path.json", "--frames", "6"],
        ] {
            let o = terawalk_cached(args, d, &cache);
            assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        }
        dir
    })
    .path()
}

/// The stores in a cache folder, and no temporary files beside them.
fn cached_stores(cache: &Path) -> Vec<PathBuf> {
    let mut stores = Vec::new();
    for e in std::fs::read_dir(cache).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.starts_with('.') && !name.ends_with(".tmp"), "a temporary file stayed: {name}");
        if name.ends_with(".tw") {
            stores.push(cache.join(name));
        }
    }
    stores.sort();
    stores
}

fn png_size(path: &Path) -> (u32, u32) {
    let png = std::fs::read(path).unwrap();
    assert_eq!(&png[1..4], b"PNG", "{}", path.display());
    let be = |i: usize| u32::from_be_bytes(png[i..i + 4].try_into().unwrap());
    (be(16), be(20))
}

#[test]
fn a_model_is_built_once_reused_rebuilt_when_touched_and_the_cache_is_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let (d, cache) = (dir.path(), dir.path().join("cache"));
    let o = terawalk_cached(&["generate", "plant", "--triangles", "30000", "-o", "m.ply"], d, &cache);
    assert!(o.status.success(), "{}", stderr(&o));
    let render = |out: &str, extra: &[&str]| {
        let mut args = vec!["render", "m.ply", "-o", out, "--size", "64x36"];
        args.extend(extra);
        terawalk_cached(&args, d, &cache)
    };

    let o = render("a.png", &[]);
    if no_gpu(&o) {
        return;
    }
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("building m.ply into the cache"), "{}", stdout(&o));
    assert_eq!(png_size(&d.join("a.png")), (64, 36));
    let first = cached_stores(&cache);
    assert_eq!(first.len(), 1, "{first:?}");

    let o = render("b.png", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains(&format!("using cached store {}", first[0].display())), "{out}");
    assert!(!out.contains("building"), "{out}");
    assert_eq!(cached_stores(&cache), first);
    // The cached store's modification time records its use (the eviction's order).
    let used = std::fs::metadata(&first[0]).unwrap().modified().unwrap();
    assert!(used.elapsed().unwrap_or_default() < Duration::from_secs(60));

    // A touched model is another model: built again, into a store of its own.
    let later = SystemTime::now() + Duration::from_secs(5);
    std::fs::File::options().write(true).open(d.join("m.ply")).unwrap().set_modified(later).unwrap();
    let o = render("c.png", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("building m.ply into the cache"), "{}", stdout(&o));
    let both = cached_stores(&cache);
    assert_eq!(both.len(), 2, "{both:?}");

    // A cache bounded below two stores keeps the one in use and removes the other.
    let o = render("d.png", &["--cache-size", "1K"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("using cached store") && out.contains("removed cached store"), "{out}");
    let left = cached_stores(&cache);
    assert_eq!(left.len(), 1);
    assert_ne!(left, first, "the store of the file as it was is the one removed");
}

#[test]
fn frames_dir_gets_one_png_per_frame_of_the_path() {
    let d = plant();
    let out = tempfile::tempdir().unwrap();
    let frames = out.path().join("frames");
    let o = terawalk_cached(
        &[
            "render",
            "p.tw",
            "--path",
            "path.json",
            "--frames-dir",
            frames.to_str().unwrap(),
            "--size",
            "64x36",
        ],
        d,
        &out.path().join("cache"),
    );
    if no_gpu(&o) {
        return;
    }
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("rendered 6 frames (64x36"), "{}", stdout(&o));
    let mut names: Vec<String> = std::fs::read_dir(&frames)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let expected: Vec<String> = (0..6).map(|i| format!("frame-{i:05}.png")).collect();
    assert_eq!(names, expected);
    for n in &names {
        assert_eq!(png_size(&frames.join(n)), (64, 36));
    }
    // --frames N renders the first N only.
    let few = out.path().join("few");
    let o = terawalk_cached(
        &[
            "render",
            "p.tw",
            "--path",
            "path.json",
            "--frames-dir",
            few.to_str().unwrap(),
            "--size",
            "64x36",
            "--frames",
            "2",
        ],
        d,
        &out.path().join("cache"),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read_dir(&few).unwrap().count(), 2);
}

#[test]
fn video_without_ffmpeg_says_how_to_install_it_and_writes_nothing() {
    let d = plant();
    let out = tempfile::tempdir().unwrap();
    let empty = tempfile::tempdir().unwrap();
    let video = out.path().join("walk.mp4");
    let o = Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args([
            "render",
            "p.tw",
            "--path",
            "path.json",
            "--video",
            video.to_str().unwrap(),
            "--size",
            "64x36",
        ])
        .current_dir(d)
        .env("PATH", empty.path())
        .env("TERAWALK_CACHE", out.path().join("cache"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("ffmpeg, which is not on PATH"), "{}", stderr(&o));
    assert!(stderr(&o).contains("sudo apt install ffmpeg"), "{}", stderr(&o));
    assert_eq!(std::fs::read_dir(out.path()).unwrap().count(), 0, "nothing written");
    // Usage: a path needs somewhere to go, and -o is one frame.
    let o = terawalk(&["render", "p.tw", "--path", "path.json"], d);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = terawalk(&["render", "p.tw", "--path", "path.json", "-o", "x.png", "--frames-dir", "f"], d);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = terawalk(
        &["render", "p.tw", "--path", "path.json", "--frames-dir", "f", "--camera", "0,0,0;1,0,0;0,0,1;60"],
        d,
    );
    assert_eq!(o.status.code(), Some(2), "the path gives the cameras: {}", stderr(&o));
    for (bad, needle) in [(["--fps", "0"], "--fps must be"), (["--frames", "0"], "--frames N needs")] {
        let mut args = vec!["render", "p.tw", "--path", "path.json", "--video", "v.mp4"];
        args.extend(bad);
        let o = terawalk(&args, d);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(stderr(&o).contains(needle), "{}", stderr(&o));
    }
    assert!(!d.join("f").exists() && !d.join("v.mp4").exists());
}

/// The frames reach ffmpeg as raw RGBA on its standard input, the video appears under its name
/// once ffmpeg succeeded: checked with a stand-in `ffmpeg` that stores what it reads.
#[cfg(unix)]
#[test]
fn video_pipes_raw_frames_into_ffmpeg() {
    use std::os::unix::fs::PermissionsExt;
    let d = plant();
    let out = tempfile::tempdir().unwrap();
    let bin = out.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let fake = bin.join("ffmpeg");
    std::fs::write(
        &fake,
        "#!/bin/sh\nfor a; do last=$a; done\nprintf '%s\\n' \"$@\" > \"$(dirname \"$last\")/args.txt\"\ncat > \"$last\"\n",
    )
    .unwrap();
    std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
    let path = std::env::join_paths(
        std::iter::once(bin.clone())
            .chain(std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default())),
    )
    .unwrap();
    let video = out.path().join("walk.mp4");
    let o = Command::new(env!("CARGO_BIN_EXE_terawalk"))
        .args(["render", "p.tw", "--path", "path.json", "--video", video.to_str().unwrap()])
        .args(["--size", "64x36", "--fps", "24", "--frames", "3"])
        .current_dir(d)
        .env("PATH", path)
        .env("TERAWALK_CACHE", out.path().join("cache"))
        .output()
        .unwrap();
    if no_gpu(&o) {
        return;
    }
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("walk.mp4 (3 frames at 24 fps"), "{}", stdout(&o));
    assert_eq!(std::fs::metadata(&video).unwrap().len(), 3 * 64 * 36 * 4);
    let args = std::fs::read_to_string(out.path().join("args.txt")).unwrap();
    assert!(args.contains("rawvideo\n") && args.contains("64x36\n") && args.contains("24\n"), "{args}");
    let partial: Vec<_> = std::fs::read_dir(out.path())
        .unwrap()
        .filter(|e| e.as_ref().unwrap().file_name().to_string_lossy().contains("partial"))
        .collect();
    assert!(partial.is_empty(), "{partial:?}");
}

/// With the real ffmpeg (Debian's, installed by `.ci/run`): the video holds every frame at the
/// asked size, odd sides padded to even ones for 4:2:0 chroma (checked with ffprobe). Skipped
/// without ffmpeg unless `TERAWALK_REQUIRE_CONVERTERS=1`, under which external tools must be there.
#[test]
fn video_encodes_every_frame_with_the_real_ffmpeg() {
    let require = std::env::var("TERAWALK_REQUIRE_CONVERTERS").as_deref() == Ok("1");
    let found = |name: &str| {
        std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default()).any(|d| d.join(name).is_file())
    };
    if !(found("ffmpeg") && found("ffprobe")) {
        assert!(
            !require,
            "TERAWALK_REQUIRE_CONVERTERS is set but ffmpeg is missing (apt-get install ffmpeg)"
        );
        eprintln!("SKIPPED: ffmpeg or ffprobe not found (apt-get install ffmpeg)");
        return;
    }
    let d = plant();
    let out = tempfile::tempdir().unwrap();
    for (name, size, padded) in [("walk.mp4", "64x36", "64,36"), ("odd.mkv", "63x35", "64,36")] {
        let video = out.path().join(name);
        let o = Command::new(env!("CARGO_BIN_EXE_terawalk"))
            .args(["render", "p.tw", "--path", "path.json", "--video", video.to_str().unwrap()])
            .args(["--size", size, "--fps", "12", "--frames", "5"])
            .current_dir(d)
            .env("TERAWALK_CACHE", out.path().join("cache"))
            .output()
            .unwrap();
        if no_gpu(&o) {
            return;
        }
        assert!(o.status.success(), "{}", stderr(&o));
        let probe = Command::new("ffprobe")
            .args(["-v", "error", "-select_streams", "v:0", "-count_frames"])
            .args(["-show_entries", "stream=width,height,nb_read_frames", "-of", "csv=p=0"])
            .arg(&video)
            .output()
            .unwrap();
        assert!(probe.status.success(), "{}", String::from_utf8_lossy(&probe.stderr));
        let fields = String::from_utf8_lossy(&probe.stdout).trim().to_string();
        assert_eq!(fields, format!("{padded},5"), "{name}: width, height, frames");
    }
}

/// `view` opens a model through the same cache: the first run builds, the second reuses (under
/// Xvfb on Mesa's drivers; skipped without `xvfb-run`, a display or an adapter unless
/// `TERAWALK_REQUIRE_GPU=1`).
#[test]
fn view_opens_a_model_through_the_cache() {
    let require = std::env::var("TERAWALK_REQUIRE_GPU").as_deref() == Ok("1");
    let xvfb_run = std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default())
        .map(|d| d.join("xvfb-run"))
        .find(|p| p.is_file());
    let Some(xvfb_run) = xvfb_run else {
        assert!(!require, "TERAWALK_REQUIRE_GPU is set but xvfb-run is missing (apt-get install xvfb xauth)");
        eprintln!("SKIPPED: xvfb-run not found (apt-get install xvfb xauth)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (d, cache) = (dir.path(), dir.path().join("cache"));
    let o = terawalk_cached(&["generate", "plant", "--triangles", "30000", "-o", "m.ply"], d, &cache);
    assert!(o.status.success(), "{}", stderr(&o));
    let view = |shot: &str| {
        Command::new(&xvfb_run)
            .args(["-a", "-s", "-screen 0 640x480x24", env!("CARGO_BIN_EXE_terawalk"), "view", "m.ply"])
            .args(["--size", "160x120", "--exit-after", "2", "--screenshot", shot])
            .current_dir(d)
            .env("TERAWALK_CACHE", &cache)
            .output()
            .expect("runs")
    };
    let o = view("first.png");
    if !o.status.success() {
        let err = stderr(&o);
        let no_device = err.contains("no GPU adapter") || err.contains("cannot open a window");
        assert!(no_device && !require, "view failed: {err}");
        eprintln!("SKIPPED: no display or adapter: {err}");
        return;
    }
    assert!(stdout(&o).contains("building m.ply into the cache"), "{}", stdout(&o));
    assert_eq!(png_size(&d.join("first.png")), (160, 120));
    let o = view("second.png");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("using cached store"), "{}", stdout(&o));
    assert_eq!(cached_stores(&cache).len(), 1);
}
