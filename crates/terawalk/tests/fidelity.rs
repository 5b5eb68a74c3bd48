//! `bench --compare K --reference-samples N`: honest fidelity against a supersampled reference
//! (tw-frame's `supersample`). On a small generated plant, lavapipe (GPU tests skip without an
//! adapter unless `TERAWALK_REQUIRE_GPU=1`, like the other bench tests).

mod common;

use common::{stderr, stdout, terawalk};

/// A built 30k-triangle plant in a temporary folder.
fn plant() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["generate", "plant", "--triangles", "30k", "-o", "p.ply"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["build", "p.ply", "-o", "p.tw", "--memory", "256M"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    dir
}

/// `bench` over 6 frames, every 2nd compared, pages loaded before each frame (the same cut
/// whatever the timing), with `extra` arguments; the report's JSON.
fn bench(dir: &std::path::Path, out: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec![
        "bench",
        "p.tw",
        "--frames",
        "6",
        "--compare",
        "2",
        "--size",
        "160x90",
        "--samples",
        "1",
        "--occlusion",
        "none",
        "--wait",
        "--out",
        out,
    ];
    args.extend_from_slice(extra);
    let o = terawalk(&args, dir);
    assert!(o.status.success(), "{}", stderr(&o));
    if extra.contains(&"16") {
        let s = stdout(&o);
        assert!(s.contains("LOD − brute force: median") && s.contains("within 0.5 dB"), "{s}");
    }
    serde_json::from_str(&std::fs::read_to_string(dir.join(out).join("report.json")).unwrap()).unwrap()
}

/// The compared frames of the run named `name`.
fn compared<'a>(report: &'a serde_json::Value, name: &str) -> Vec<&'a serde_json::Value> {
    let run = report["runs"].as_array().unwrap().iter().find(|r| r["name"] == name).unwrap();
    run["frames"].as_array().unwrap().iter().filter(|f| f.get("psnr_db").is_some()).collect()
}

#[test]
fn reference_samples_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    for bad in ["9", "2", "0", "x"] {
        let o = terawalk(&["bench", "p.tw", "--compare", "2", "--reference-samples", bad], dir.path());
        assert!(!o.status.success(), "{bad}");
        assert!(
            stderr(&o).contains("[1, 4, 16, 64]") && stderr(&o).contains("s × s"),
            "{bad}: {}",
            stderr(&o)
        );
    }
    // Nothing to compare without --compare.
    let o = terawalk(&["bench", "p.tw", "--reference-samples", "16"], dir.path());
    assert!(!o.status.success() && stderr(&o).contains("--compare"), "{}", stderr(&o));
    let o = terawalk(&["bench", "--help"], dir.path());
    assert!(stdout(&o).contains("--reference-samples 16"), "an example in the help");
}

#[test]
fn a_supersampled_reference_records_the_lod_and_the_brute_force_frame() {
    let dir = plant();
    let plain = bench(dir.path(), "one", &["--reference-samples", "1"]);
    let truth = bench(dir.path(), "sixteen", &["--reference-samples", "16"]);
    let (plain, truth) = (compared(&plain, "none"), compared(&truth, "none"));
    assert_eq!(plain.len(), 3);
    assert_eq!(truth.len(), 3);
    for (p, t) in plain.iter().zip(&truth) {
        // The 1-sample path is today's: the same PSNR against the same reference, no new fields.
        assert_eq!(p["psnr_db"], t["psnr_db"], "frame {}", p["frame"]);
        for key in ["supersampled_psnr_db", "brute_force_psnr_db", "psnr_gap_db"] {
            assert!(p.get(key).is_none(), "{key} at 1 sample: {p}");
        }
        // Against 16 samples: the brute-force frame is not the truth (finite PSNR), and the
        // difference is the LOD frame's PSNR minus the brute-force frame's.
        let get = |key: &str| t[key].as_f64().unwrap_or_else(|| panic!("{key}: {t}"));
        let (lod, brute, gap) = (get("supersampled_psnr_db"), get("brute_force_psnr_db"), get("psnr_gap_db"));
        assert!(brute > 10.0 && brute < 99.0, "{t}");
        assert!(lod > 10.0 && lod < 99.0, "{t}");
        assert!((gap - (lod - brute)).abs() < 1e-9, "{t}");
    }
    // A grid the device cannot hold (lavapipe's largest texture is 16384): a clear error before
    // any frame, no report.
    let big = [
        "bench",
        "p.tw",
        "--frames",
        "2",
        "--compare",
        "1",
        "--size",
        "4096x16",
        "--reference-samples",
        "64",
        "--out",
        "big",
    ];
    let o = terawalk(&big, dir.path());
    assert!(
        !o.status.success() && stderr(&o).contains("32768×128") && stderr(&o).contains("largest texture"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.path().join("big").exists());
    let html = std::fs::read_to_string(dir.path().join("sixteen/index.html")).unwrap();
    assert!(html.contains("data-series=\"psnr_gap_db\"") && html.contains("LOD − brute force dB"));
    assert!(html.contains("16 (supersampled)"), "the header names the reference's samples");
}

#[test]
fn popping_is_plotted_in_the_report() {
    let dir = plant();
    let args = [
        "bench",
        "p.tw",
        "--frames",
        "12",
        "--size",
        "160x90",
        "--occlusion",
        "none,hzb",
        "--wait",
        "--popping",
        "--out",
        "pop",
    ];
    let o = terawalk(&args, dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("pixels the LOD alone changes"), "{}", stdout(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("pop/report.json")).unwrap()).unwrap();
    let changed = |run: &serde_json::Value| -> f64 {
        run["frames"].as_array().unwrap().iter().map(|f| f["popping_changed_pixels"].as_f64().unwrap()).sum()
    };
    let html = std::fs::read_to_string(dir.path().join("pop/index.html")).unwrap();
    assert!(html.contains("Popping: pixels the LOD alone changes"));
    if json["runs"].as_array().unwrap().iter().any(|r| changed(r) > 0.0) {
        // One line per run (none, hzb) in the plot of the changed share.
        let plot = &html[html.find("data-series=\"popping_changed_pixels\"").expect("plotted")..];
        let plot = &plot[..plot.find("</svg>").unwrap()];
        assert_eq!(plot.matches("<polyline").count(), 2, "{plot}");
    }
}
