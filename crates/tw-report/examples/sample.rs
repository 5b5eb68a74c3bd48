//! Writes a sample report with synthetic figures (three occlusion strategies, a walk then a
//! fly-over) to the folder given as the first argument (default `sample-report`), to look at
//! the page: `cargo run -p tw-report --example sample -- /tmp/report && xdg-open /tmp/report/index.html`.

use tw_report::{BenchReport, FrameRecord, Run, RunMeta};

fn frames(n: u32, cost: f64, culls: bool) -> Vec<FrameRecord> {
    (0..n)
        .map(|i| {
            let walk = i < n * 3 / 5;
            let t = i as f64 / n as f64;
            let tris = if walk { 2.0e6 + 8.0e5 * (t * 17.0).sin() } else { 6.0e5 + 2.0e5 * (t * 9.0).cos() };
            let drawn = if culls && walk { tris * 0.25 } else { tris };
            let frame_ms = 4.0 + drawn / 1.5e5 * cost + if i % 97 == 13 { 12.0 } else { 0.0 };
            FrameRecord {
                frame: i,
                segment: if walk { "walk" } else { "fly" }.into(),
                frame_ms,
                select_ms: 1.2 + 0.3 * (t * 31.0).sin().abs(),
                cull_ms: 0.4,
                culling_ms: if culls { 1.5 } else { 0.0 },
                upload_ms: 0.8,
                render_ms: frame_ms - 3.0,
                triangles: drawn as u64,
                clusters: (drawn / 110.0) as u64,
                nodes_visited: 9000,
                nodes_culled_frustum: 3000,
                nodes_culled_lod: 2500,
                nodes_culled_occlusion: if culls && walk { 2400 } else { 0 },
                resident_mb: 120.0 + 200.0 * t,
                disk_read_mb: if i % 20 == 0 { 6.0 } else { 0.3 },
                pages_loaded: if i % 20 == 0 { 90 } else { 4 },
                pages_requested: if i % 20 == 0 { 120 } else { 6 },
                psnr_db: Some(48.0 + 3.0 * (t * 5.0).sin()),
                differing_pixels: Some(0.002),
                ..Default::default()
            }
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args().nth(1).unwrap_or_else(|| "sample-report".into());
    let meta = RunMeta {
        store: "plant-10M.tw".into(),
        command_line: "terawalk bench plant-10M.tw --path path.json --occlusion none,hzb,queries".into(),
        adapter: "llvmpipe (LLVM 19.1, 256 bits), Vulkan".into(),
        size: [1280, 720],
        error_px: 1.0,
        memory_budget_bytes: 1 << 30,
        date: tw_report::utc_now(),
        machine: "sample data".into(),
        path: "path.json".into(),
        store_bytes: 412_000_000,
        input_triangles: 10_000_000,
        version: env!("CARGO_PKG_VERSION").into(),
        commit: "sample".into(),
        extra: vec![],
    };
    let report = BenchReport::new(
        meta,
        vec![
            Run::new("none", "no occlusion culling", frames(600, 1.0, false), Some(900_000_000)),
            Run::new(
                "hzb",
                "CPU hierarchical Z-buffer (GigaWalk)",
                frames(600, 1.0, true),
                Some(910_000_000),
            ),
            Run::new("queries", "hardware occlusion queries", frames(600, 1.15, true), Some(905_000_000)),
        ],
    );
    let files = tw_report::write_report(dir.as_ref(), &report, &[])?;
    println!("wrote {} and {}", files.json.display(), files.html.display());
    Ok(())
}
