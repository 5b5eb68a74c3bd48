//! `--light` end to end: `render` draws the shadows of a sun and of a point light with both
//! renderers, and their shadow masks agree away from the shadow edges; `bench --light` measures
//! every strategy with and without shadows in one process; bad lights and shadow options are
//! refused with a message naming them.

use tw_gpu::Image;

mod common;

use common::{stderr, stdout, terawalk};

#[test]
fn render_and_bench_draw_shadows_that_the_ray_tracer_confirms() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = terawalk(&["generate", "plant", "--triangles", "30k", "-o", "p.ply"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["build", "p.ply", "-o", "p.tw", "--memory", "256M", "--threads", "2"], d);
    assert!(o.status.success(), "{}", stderr(&o));

    for (bad, what) in [
        (vec!["--light", "lamp"], "light"),
        (vec!["--light", "sun:10,95"], "elevation"),
        (vec!["--light", "sun", "--shadow-map", "10"], "shadow map size"),
        (vec!["--light", "sun", "--cascades", "9"], "cascades"),
        (vec!["--shadow-map", "512"], "--light"),
    ] {
        let mut args = vec!["render", "p.tw", "-o", "x.png", "--size", "64x64"];
        args.extend(bad.iter().copied());
        let o = terawalk(&args, d);
        assert!(!o.status.success(), "{args:?} was accepted");
        assert!(stderr(&o).contains(what), "{args:?}: {}", stderr(&o));
    }

    let o = terawalk(
        &[
            "render",
            "p.tw",
            "-o",
            "rt.png",
            "--size",
            "320x200",
            "--renderer",
            "rt",
            "--light",
            "sun:30,40",
            "--color",
            "shadow",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(
        &[
            "render",
            "p.tw",
            "-o",
            "raster.png",
            "--size",
            "320x200",
            "--light",
            "sun:30,40",
            "--color",
            "shadow",
        ],
        d,
    );
    if !o.status.success()
        && stderr(&o).contains("no GPU adapter")
        && std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1")
    {
        eprintln!(
            "SKIPPED the rasterized shadows: {} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)",
            stderr(&o)
        );
        return;
    }
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("shadows:") && out.contains("layers") && out.contains("receivers"), "{out}");
    let image = |name: &str| Image::from_png_bytes(&std::fs::read(d.join(name)).unwrap()).unwrap();
    let (rt, raster) = (image("rt.png"), image("raster.png"));
    let blocked = |i: &Image| i.rgba.chunks(4).filter(|p| p[3] == 255 && p[..3] == [0, 0, 0]).count();
    assert!(
        blocked(&rt) > 500 && blocked(&raster) > 500,
        "no shadow: {} / {}",
        blocked(&rt),
        blocked(&raster)
    );
    let agreement = tw_frame::mask::compare_shadow_images(&rt, &raster, 2).unwrap();
    assert!(agreement.ratio() >= 0.99, "{agreement:?}");

    // The shaded image: darker where the mask is blocked, the same elsewhere.
    let o = terawalk(&["render", "p.tw", "-o", "plain.png", "--size", "320x200"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["render", "p.tw", "-o", "sun.png", "--size", "320x200", "--light", "sun"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let (plain, sun) = (image("plain.png"), image("sun.png"));
    assert!(sun.differing_pixels(&plain).unwrap() > 0, "the default sun's shadows changed nothing");

    let o = terawalk(
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
    assert!(o.status.success(), "{}", stderr(&o));
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

    // The ray tracer's bench run casts shadow rays of the light (one run, no strategies).
    let o = terawalk(
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
    assert!(o.status.success(), "{}", stderr(&o));
    let report = std::fs::read_to_string(d.join("rt/report.json")).unwrap();
    assert!(report.contains("shadow rays of the sun"), "the traced run ignored the light");
}
