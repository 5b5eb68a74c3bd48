//! `--light` end to end: `render` draws the shadows of a sun with both renderers (the point
//! light is checked in tw-gpu and tw-frame), and their shadow masks agree away from the shadow
//! edges; `bench --light` measures every strategy with and without shadows in one process; bad
//! lights and shadow options are refused with a message naming them.

use std::path::Path;
use std::process::Output;

use tw_gpu::Image;

mod common;

use common::{stderr, stdout, terawalk};

#[test]
fn render_and_bench_draw_shadows_that_the_ray_tracer_confirms() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    build_plant(d);
    bad_lights_are_refused(d);
    if !raster_shadows_agree_with_the_ray_tracer(d) {
        return;
    }
    shadows_darken_the_shaded_image(d);
    bench_measures_every_strategy_with_shadows(d);
    traced_bench_casts_shadow_rays(d);
}

/// Runs `terawalk args` in `d` and checks that it succeeded (else fails with its stderr).
fn run_ok(args: &[&str], d: &Path) -> Output {
    let o = terawalk(args, d);
    assert!(o.status.success(), "{}", stderr(&o));
    o
}

/// `p.tw` in `d`: a generated plant of 30k triangles, built.
fn build_plant(d: &Path) {
    run_ok(&["generate", "plant", "--triangles", "30k", "-o", "p.ply"], d);
    run_ok(&["build", "p.ply", "-o", "p.tw", "--memory", "256M", "--threads", "2"], d);
}

/// A bad light, bad shadow options, and shadow options without a light: refused, with a
/// message naming what is wrong.
fn bad_lights_are_refused(d: &Path) {
    for (bad, what) in [
        (vec!["--light", "lamp"], "light"),
        (vec!["--light", "sun:10,95"], "elevation"),
        (vec!["--light", "sun", "--shadow-map", "10"], "shadow map size"),
        (vec!["--light", "sun", "--cascades", "9"], "cascades"),
        (vec!["--shadow-map", "512"], "--light"),
        (vec!["--light", "sun", "--shadow-lod", "coarse"], "eye or finer"),
        (vec!["--shadow-lod", "finer"], "--light"),
    ] {
        let mut args = vec!["render", "p.tw", "-o", "x.png", "--size", "64x64"];
        args.extend(bad.iter().copied());
        let o = terawalk(&args, d);
        assert!(!o.status.success(), "{args:?} was accepted");
        assert!(stderr(&o).contains(what), "{args:?}: {}", stderr(&o));
    }
}

/// The shadow masks of a sun (`--color shadow`) by the ray tracer and by the rasterizer: both
/// have shadows, and they agree away from the shadow edges. False where there is no GPU
/// adapter and none is required (the rest of the test needs one).
fn raster_shadows_agree_with_the_ray_tracer(d: &Path) -> bool {
    let mask = ["--size", "320x200", "--light", "sun:30,40", "--color", "shadow"];
    run_ok(&[&["render", "p.tw", "-o", "rt.png", "--renderer", "rt"][..], &mask].concat(), d);
    let o = terawalk(&[&["render", "p.tw", "-o", "raster.png"][..], &mask].concat(), d);
    if !o.status.success()
        && stderr(&o).contains("no GPU adapter")
        && std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1")
    {
        eprintln!(
            "SKIPPED the rasterized shadows: {} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)",
            stderr(&o)
        );
        return false;
    }
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("shadows:") && out.contains("layers") && out.contains("receivers"), "{out}");
    let (rt, raster) = (image(d, "rt.png"), image(d, "raster.png"));
    let blocked = |i: &Image| i.rgba.chunks(4).filter(|p| p[3] == 255 && p[..3] == [0, 0, 0]).count();
    assert!(
        blocked(&rt) > 500 && blocked(&raster) > 500,
        "no shadow: {} / {}",
        blocked(&rt),
        blocked(&raster)
    );
    let agreement = tw_frame::mask::compare_shadow_images(&rt, &raster, 2).unwrap();
    assert!(agreement.ratio() >= 0.99, "{agreement:?}");
    // The finer of both LODs: at least the eye's triangles, and shadows the ray tracer confirms
    // (at full detail: the finer cut is not the ray tracer's own eye-LOD cut).
    let o = run_ok(&[&["render", "p.tw", "-o", "finer.png", "--shadow-lod", "finer"][..], &mask].concat(), d);
    run_ok(
        &[&["render", "p.tw", "-o", "rt0.png", "--renderer", "rt", "--error", "0"][..], &mask].concat(),
        d,
    );
    let (finer, rt0) = (image(d, "finer.png"), image(d, "rt0.png"));
    let eye_full = tw_frame::mask::compare_shadow_images(&rt0, &raster, 2).unwrap();
    let finer_full = tw_frame::mask::compare_shadow_images(&rt0, &finer, 2).unwrap();
    assert!(finer_full.ratio() >= 0.99, "finer LOD: {finer_full:?}");
    assert!(finer_full.agree >= eye_full.agree, "finer {finer_full:?}\neye {eye_full:?}");
    assert!(triangles_drawn(&stdout(&o)) >= triangles_drawn(&out), "{}\n{out}", stdout(&o));
    true
}

/// The cut's triangles `render` reports ("… N triangles …" on its first line that has them).
fn triangles_drawn(out: &str) -> u64 {
    let line =
        out.lines().find(|l| l.contains("triangles")).unwrap_or_else(|| panic!("no triangles in {out}"));
    let words: Vec<&str> = line.split_whitespace().collect();
    let i = words.iter().position(|w| w.starts_with("triangles")).expect("a count before 'triangles'");
    words[..i].last().and_then(|w| w.replace([',', '\u{202f}'], "").parse().ok()).unwrap_or(0)
}

/// The PNG `name` in `d`.
fn image(d: &Path, name: &str) -> Image {
    Image::from_png_bytes(&std::fs::read(d.join(name)).unwrap()).unwrap()
}

/// The shaded image with the default sun's shadows differs from the one without.
fn shadows_darken_the_shaded_image(d: &Path) {
    run_ok(&["render", "p.tw", "-o", "plain.png", "--size", "320x200"], d);
    run_ok(&["render", "p.tw", "-o", "sun.png", "--size", "320x200", "--light", "sun"], d);
    let (plain, sun) = (image(d, "plain.png"), image(d, "sun.png"));
    assert!(sun.differing_pixels(&plain).unwrap() > 0, "the default sun's shadows changed nothing");
}

/// `bench --light` runs a strategy with shadows beside the one without, compares their frame
/// rates, prints the light-view set, and puts the shadow figures in the report.
fn bench_measures_every_strategy_with_shadows(d: &Path) {
    let o = run_ok(
        &[
            "bench",
            "p.tw",
            "--frames",
            "6",
            "--warmup",
            "1",
            "--occlusion",
            "hzb",
            "--light",
            "sun",
            "--out",
            "r",
            "--size",
            "320x200",
        ],
        d,
    );
    let out = stdout(&o);
    assert!(
        out.contains("hzb+shadows")
            && out.contains("the frame rate of hzb")
            && out.contains("light-view set"),
        "{out}"
    );
    let report = std::fs::read_to_string(d.join("r/report.json")).unwrap();
    assert!(
        report.contains("\"shadow\"") && report.contains("caster_triangles"),
        "no shadow figures in the report"
    );
}

/// The ray tracer's bench run casts shadow rays of the light (one run, no strategies).
fn traced_bench_casts_shadow_rays(d: &Path) {
    run_ok(
        &[
            "bench",
            "p.tw",
            "--frames",
            "3",
            "--warmup",
            "0",
            "--renderer",
            "rt",
            "--light",
            "sun",
            "--out",
            "rt",
            "--size",
            "160x100",
        ],
        d,
    );
    let report = std::fs::read_to_string(d.join("rt/report.json")).unwrap();
    assert!(report.contains("shadow rays of the sun"), "the traced run ignored the light");
}
