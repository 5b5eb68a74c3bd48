//! Report writing end to end: JSON round trip, the page's plots and images, summary statistics
//! on known inputs, atomic writes.

use tw_report::{svg, write_report, BenchReport, FrameRecord, ReportImage, Run, RunKind, RunMeta, Summary};

/// A 1×1 PNG.
const PNG: [u8; 70] = [
    137, 80, 78, 71, 13, 10, 26, 10, 0, 0, 0, 13, 73, 72, 68, 82, 0, 0, 0, 1, 0, 0, 0, 1, 8, 6, 0, 0, 0, 31,
    21, 196, 137, 0, 0, 0, 13, 73, 68, 65, 84, 120, 218, 99, 100, 248, 207, 80, 15, 0, 3, 134, 1, 128, 90,
    52, 125, 107, 0, 0, 0, 0, 73, 69, 78, 68, 174, 66, 96, 130,
];

fn frames(n: u32, scale: f64, compare: bool) -> Vec<FrameRecord> {
    (0..n)
        .map(|i| FrameRecord {
            frame: i,
            segment: if i < n / 2 { "walk".into() } else { "fly".into() },
            frame_ms: scale * (10.0 + (i % 7) as f64),
            select_ms: 1.0 + (i % 3) as f64 * 0.1,
            render_ms: scale * 8.0,
            triangles: 100_000 + i as u64 * 1000,
            clusters: 800 + i as u64,
            nodes_visited: 5000,
            nodes_culled_frustum: 1200,
            nodes_culled_occlusion: if scale < 1.0 { 900 } else { 0 },
            resident_mb: 50.0 + i as f64 * 0.1,
            disk_read_mb: if i == 0 { 30.0 } else { 0.2 },
            pages_loaded: if i == 0 { 40 } else { 1 },
            psnr_db: compare.then_some(42.0 + (i % 5) as f64),
            differing_pixels: compare.then_some(0.001),
            ..Default::default()
        })
        .collect()
}

fn report() -> BenchReport {
    let meta = RunMeta {
        store: "plant <10M>.tw".into(),
        command_line: "terawalk bench plant.tw --path walk.json --occlusion none,hzb".into(),
        adapter: "llvmpipe (LLVM 19), Gl".into(),
        size: [1280, 720],
        error_px: 1.0,
        memory_budget_bytes: 1 << 30,
        date: "2026-12-01T18:00:00Z".into(),
        machine: "2 cores, 8 GB".into(),
        path: "walk.json".into(),
        store_bytes: 52_000_000,
        input_triangles: 10_000_000,
        version: "0.1.0".into(),
        commit: "15a11bb".into(),
        extra: vec![("seed".into(), "1".into())],
    };
    BenchReport::new(
        meta,
        vec![
            Run::new("none", "no occlusion culling", frames(120, 1.0, false), Some(300_000_000)),
            Run::new("hzb", "CPU hierarchical Z-buffer", frames(120, 0.5, true), Some(310_000_000)),
            // The full-detail renderings of every 10th frame (`--compare 10`).
            Run::new("reference", "full detail", frames(120, 400.0, false), None)
                .with_kind(RunKind::Reference),
        ],
    )
}

fn images() -> Vec<ReportImage> {
    vec![
        ReportImage { caption: "frame 0 (walk)".into(), png: PNG.to_vec() },
        ReportImage { caption: "frame 90 (fly)".into(), png: PNG.to_vec() },
    ]
}

#[test]
fn json_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let r = report();
    let files = write_report(dir.path(), &r, &images()).unwrap();
    let back = BenchReport::from_json(&std::fs::read_to_string(&files.json).unwrap()).unwrap();
    assert_eq!(back, r);
    assert!(BenchReport::from_json("{\"format\":\"x\"").unwrap_err().to_string().contains("line 1"));
}

#[test]
fn page_has_one_plot_per_series_and_the_images() {
    let dir = tempfile::tempdir().unwrap();
    let r = report();
    let files = write_report(dir.path(), &r, &images()).unwrap();
    let html = std::fs::read_to_string(&files.html).unwrap();
    let shown = svg::plotted(&r.runs);
    assert_eq!(html.matches("<svg").count(), shown.len());
    for s in &shown {
        assert_eq!(html.matches(&format!("data-series=\"{}\"", s.key)).count(), 1, "{}", s.key);
    }
    // Non-zero series are shown, all-zero ones are listed instead.
    for key in ["frame_ms", "triangles", "nodes_culled_occlusion", "psnr_db", "disk_read_mb"] {
        assert!(shown.iter().any(|s| s.key == key), "{key}");
    }
    assert!(!shown.iter().any(|s| s.key == "occlusion_queries"));
    assert!(html.contains("Occlusion queries"));
    assert_eq!(html.matches("src=\"data:image/png;base64,").count(), 2);
    assert!(html.contains("frame 90 (fly)"));
    // Self-contained: nothing fetched, no scripts; text escaped.
    assert_eq!(html.matches("http").count(), html.matches("http://www.w3.org/2000/svg").count());
    assert!(!html.contains("<script"));
    assert!(html.contains("plant &lt;10M&gt;.tw"));
    // Speed-up of hzb against none: frame times are halved.
    assert!(html.contains("2.00×"), "speed-up column");
    assert!(html.contains("#4e79a7") && html.contains("#f28e2b"), "one colour per run");
}

#[test]
fn summary_statistics_on_known_inputs() {
    let f: Vec<FrameRecord> = (1..=100)
        .map(|i| FrameRecord { frame: i, frame_ms: i as f64, triangles: 10, ..Default::default() })
        .collect();
    let s = Summary::of(&f, Some(2_000_000));
    assert_eq!(s.frames, 100);
    assert!((s.median_ms - 50.5).abs() < 1e-12);
    assert!((s.p95_ms - 95.05).abs() < 1e-9);
    assert!((s.p99_ms - 99.01).abs() < 1e-9);
    assert!((s.mean_ms - 50.5).abs() < 1e-12);
    assert_eq!(s.max_ms, 100.0);
    assert!((s.mean_fps - 1000.0 / 50.5).abs() < 1e-9);
    assert_eq!(s.median_triangles, 10.0);
    assert_eq!(s.peak_rss_mb, Some(2.0));
    assert_eq!(s.min_psnr_db, None);
    let empty = Summary::of(&[], None);
    assert_eq!((empty.frames, empty.median_ms, empty.mean_fps), (0, 0.0, 0.0));
}

#[test]
fn failed_writes_leave_no_partial_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    // Not PNG data: refused before anything is written.
    let bad = vec![ReportImage { caption: "x".into(), png: b"GIF89a".to_vec() }];
    let e = write_report(&out, &report(), &bad).unwrap_err().to_string();
    assert!(e.contains("not PNG"), "{e}");
    assert!(!out.exists());
    // A value JSON cannot carry.
    let mut r = report();
    r.runs[1].frames[3].frame_ms = f64::NAN;
    let e = write_report(&out, &r, &[]).unwrap_err().to_string();
    assert!(e.contains("frame 3") && e.contains("frame_ms"), "{e}");
    assert!(!out.exists());
    // The page's place is taken by a folder: the rename fails, no temporary file is left.
    std::fs::create_dir_all(out.join("index.html")).unwrap();
    let e = write_report(&out, &report(), &[]).unwrap_err().to_string();
    assert!(e.contains("index.html"), "{e}");
    let left: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".tw-report-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    // Writing again over an existing report replaces it whole.
    std::fs::remove_dir(out.join("index.html")).unwrap();
    write_report(&out, &report(), &images()).unwrap();
    let mut r = report();
    r.runs.truncate(1);
    write_report(&out, &r, &[]).unwrap();
    let back = BenchReport::from_json(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(back.runs.len(), 1);
}

#[test]
fn invalid_reports_are_refused() {
    let mut r = report();
    r.runs[1].name = "none".into();
    assert!(r.validate().unwrap_err().to_string().contains("two runs"));
    let r = BenchReport::new(RunMeta::default(), vec![]);
    assert!(r.validate().unwrap_err().to_string().contains("no runs"));
}

#[test]
fn lod_efficiency_is_recorded_summarised_and_shown() {
    let frames: Vec<FrameRecord> = (0..5u64)
        .map(|i| {
            let mut f = FrameRecord {
                frame: i as u32,
                frame_ms: 10.0,
                cut_triangles: 1000 * (i + 1),
                ..Default::default()
            };
            // ε = 2: two triangles per 4 covered pixels; frame 0 sees nothing (no ratio).
            f.set_coverage(if i == 0 { 0 } else { 2000 }, 2.0);
            f
        })
        .collect();
    assert_eq!(frames[0].needed_triangles, Some(0));
    assert_eq!(frames[0].lod_efficiency, None);
    assert_eq!((frames[1].covered_pixels, frames[1].needed_triangles), (Some(2000), Some(1000)));
    assert_eq!(frames[3].lod_efficiency, Some(4.0));
    let s = Summary::of(&frames, None);
    assert_eq!(s.median_cut_triangles, 3000.0);
    assert_eq!(s.median_needed_triangles, Some(1000.0));
    // Median of the ratios 2, 3, 4, 5 of the frames that cover pixels.
    assert_eq!(s.median_lod_efficiency, Some(3.5));

    let report = BenchReport::new(
        RunMeta { error_px: 2.0, ..Default::default() },
        vec![Run::new("none", "", frames, None)],
    );
    let dir = tempfile::tempdir().unwrap();
    let files = write_report(dir.path(), &report, &[]).unwrap();
    let html = std::fs::read_to_string(&files.html).unwrap();
    assert!(html.contains("<th>LOD efficiency</th>") && html.contains("<td>3.50</td>"), "summary column");
    for key in ["cut_triangles", "needed_triangles", "lod_efficiency", "covered_pixels"] {
        assert!(html.contains(&format!("data-series=\"{key}\"")), "{key}");
    }
    let back = BenchReport::from_json(&std::fs::read_to_string(&files.json).unwrap()).unwrap();
    assert_eq!(back, report);
}

#[test]
fn reports_without_lod_figures_still_read() {
    // A report written before the LOD figures: no cut_triangles, covered_pixels,
    // needed_triangles, lod_efficiency in its frames, no LOD medians in its summaries.
    let mut v = serde_json::to_value(report()).unwrap();
    for run in v["runs"].as_array_mut().unwrap() {
        for key in ["median_cut_triangles", "median_needed_triangles", "median_lod_efficiency"] {
            run["summary"].as_object_mut().unwrap().remove(key);
        }
        for f in run["frames"].as_array_mut().unwrap() {
            f.as_object_mut().unwrap().remove("cut_triangles");
        }
    }
    let text = serde_json::to_string(&v).unwrap();
    assert!(!text.contains("cut_triangles") && !text.contains("lod_efficiency"));
    let back = BenchReport::from_json(&text).unwrap();
    assert_eq!(back.runs[0].frames[0].cut_triangles, 0);
    assert_eq!(back.runs[0].frames[0].lod_efficiency, None);
    assert_eq!(back.runs[0].summary.median_lod_efficiency, None);
    // Its page has no LOD column.
    assert!(!tw_report::html::page(&back, &[]).contains("LOD efficiency</th>"));
}

#[test]
fn reports_without_run_kinds_or_build_figures_still_read() {
    // A report written before runs had a kind and the header its store size, input, version
    // and commit: every run is a walkthrough, the figures are empty.
    let mut v = serde_json::to_value(report()).unwrap();
    assert_eq!(v["runs"][2]["kind"], "reference");
    assert!(v["runs"][0].get("kind").is_none(), "walkthroughs are not marked");
    for key in ["store_bytes", "input_triangles", "version", "commit"] {
        v["meta"].as_object_mut().unwrap().remove(key);
    }
    v["runs"][2].as_object_mut().unwrap().remove("kind");
    let back = BenchReport::from_json(&serde_json::to_string(&v).unwrap()).unwrap();
    assert!(back.runs.iter().all(|r| r.kind == RunKind::Walkthrough));
    assert_eq!((back.meta.store_bytes, back.meta.input_triangles), (0, 0));
    assert!(back.meta.commit.is_empty());
    tw_report::html::page(&back, &[]);
}

/// Two walkthrough runs measured with `bench --popping`: the LOD-only change of every frame (0 on
/// the first), its PSNR only where something changed.
fn popping_runs() -> Vec<Run> {
    let run = |name: &str, scale: f64| {
        let frames = (0..30)
            .map(|i| {
                let changed = if i % 3 == 0 { 0.0 } else { scale * 0.001 * i as f64 };
                FrameRecord {
                    frame: i,
                    frame_ms: 10.0,
                    popping_changed_pixels: Some(changed),
                    popping_psnr_db: (changed > 0.0).then_some(50.0 - i as f64 * 0.1),
                    ..Default::default()
                }
            })
            .collect();
        Run::new(name, "", frames, None)
    };
    vec![run("none", 1.0), run("hzb", 2.0)]
}

#[test]
fn popping_is_plotted_per_run_with_its_psnr_where_defined() {
    let runs = popping_runs();
    let shown = svg::plotted(&runs);
    for key in ["popping_changed_pixels", "popping_psnr_db"] {
        let series = shown.iter().find(|s| s.key == key).unwrap_or_else(|| panic!("{key} not plotted"));
        let plot = svg::plot(series, &runs);
        // One line per run, each in its own colour, with a legend naming it.
        assert_eq!(plot.matches("<polyline").count(), 2, "{key}: {plot}");
        assert!(plot.contains(svg::PALETTE[0]) && plot.contains(svg::PALETTE[1]), "{key}");
        assert!(plot.contains(">none<") && plot.contains(">hzb<"), "{key}: {plot}");
    }
    // The PSNR is left out of the unchanged frames (every third); the share is 0 there.
    let psnr = svg::SERIES.iter().find(|s| s.key == "popping_psnr_db").unwrap();
    let xs: Vec<f64> = svg::points(psnr, &runs[0]).iter().map(|p| p.0).collect();
    assert_eq!(xs.len(), 20);
    assert!(xs.iter().all(|&x| !(x as u32).is_multiple_of(3)), "{xs:?}");
    let share = svg::SERIES.iter().find(|s| s.key == "popping_changed_pixels").unwrap();
    assert_eq!(svg::points(share, &runs[1]).len(), 30);
    assert_eq!(svg::points(share, &runs[1])[5], (5.0, 0.01));
    // On the page, under its title.
    let mut r = report();
    r.runs = runs;
    let html = tw_report::html::page(&r, &[]);
    assert!(html.contains("data-series=\"popping_changed_pixels\""));
    assert!(html.contains("Popping: pixels the LOD alone changes"));
}

#[test]
fn supersampled_fidelity_is_summarised_shown_and_optional() {
    // Frames compared against a supersampled reference: the LOD frame, the brute-force frame,
    // and their difference.
    let frames: Vec<FrameRecord> = (0..5)
        .map(|i| {
            let (lod, brute) = (30.0 + i as f64, 30.5 + i as f64 + 0.1 * i as f64);
            FrameRecord {
                frame: 10 * i,
                frame_ms: 10.0,
                psnr_db: Some(40.0),
                supersampled_psnr_db: Some(lod),
                brute_force_psnr_db: Some(brute),
                psnr_gap_db: Some(lod - brute),
                ..Default::default()
            }
        })
        .collect();
    let s = Summary::of(&frames, None);
    assert!((s.median_psnr_gap_db.unwrap() - -0.7).abs() < 1e-9, "{s:?}");
    assert!((s.min_psnr_gap_db.unwrap() - -0.9).abs() < 1e-9, "{s:?}");
    let mut r = report();
    r.runs[1] = Run::new("hzb", "", frames, None);
    let dir = tempfile::tempdir().unwrap();
    let files = write_report(dir.path(), &r, &[]).unwrap();
    let json = std::fs::read_to_string(&files.json).unwrap();
    assert!(json.contains("\"supersampled_psnr_db\"") && json.contains("\"psnr_gap_db\""));
    assert_eq!(BenchReport::from_json(&json).unwrap(), r);
    let html = std::fs::read_to_string(&files.html).unwrap();
    assert!(html.contains("LOD − brute force dB") && html.contains("<td>-0.70</td><td>-0.90</td>"));
    for key in ["supersampled_psnr_db", "brute_force_psnr_db", "psnr_gap_db"] {
        assert!(html.contains(&format!("data-series=\"{key}\"")), "{key}");
    }
    // Reports written before these fields load, without them.
    let old =
        std::fs::read_to_string(write_report(dir.path().join("old").as_path(), &report(), &[]).unwrap().json)
            .unwrap();
    assert!(!old.contains("psnr_gap_db"));
    let back = BenchReport::from_json(&old).unwrap();
    assert!(back.runs.iter().all(|r| r.summary.median_psnr_gap_db.is_none()));
    assert!(back.runs.iter().flat_map(|r| &r.frames).all(|f| f.supersampled_psnr_db.is_none()));
}
