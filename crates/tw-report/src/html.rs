//! The report page: one self-contained HTML file (inline CSS and SVG, images as PNG data URIs;
//! no scripts, nothing fetched). Sections: the run's metadata, a summary table (medians, p95,
//! p99, fps, speed-up of each run against the first, memory, fidelity), a plot per per-frame
//! series (see [`crate::svg`]), and the embedded frames.

use std::fmt::Write;

use crate::svg::{escape, plot, plotted, plotted_runs, Series, PALETTE, SERIES};
use crate::{BenchReport, ReportImage, Run, RunKind, RunMeta};

const STYLE: &str = "\
:root{--fg:#1f2933;--muted:#616e7c;--line:#d9e2ec;--bg:#f5f7fa}\
*{box-sizing:border-box}\
.damaged{border-left:4px solid #c62828;background:#fdecea;padding:0 12px}\
body{margin:0;font:14px/1.45 system-ui,-apple-system,'Segoe UI',Roboto,Helvetica,Arial,sans-serif;color:var(--fg);background:var(--bg)}\
header{background:#102a43;color:#f0f4f8;padding:20px 32px}\
header h1{margin:0 0 4px;font-size:22px;font-weight:600}\
header p{margin:0;color:#bcccdc}\
main{max-width:1620px;margin:0 auto;padding:20px 32px 40px}\
section{background:#fff;border:1px solid var(--line);border-radius:6px;padding:16px 20px;margin:0 0 20px}\
h2{font-size:16px;margin:0 0 12px;font-weight:600}\
table{border-collapse:collapse;width:100%;font-variant-numeric:tabular-nums}\
.wide{overflow-x:auto;max-width:100%}\
table.summary th{white-space:normal;min-width:64px;max-width:110px;vertical-align:bottom}\
table.summary td:first-child,table.summary th:first-child{position:sticky;left:0;background:#fff}\
th,td{padding:5px 10px;border-bottom:1px solid var(--line);text-align:right;white-space:nowrap}\
th{font-weight:600;color:var(--muted);font-size:12px;text-transform:uppercase;letter-spacing:.03em}\
td:first-child,th:first-child{text-align:left}\
table.meta td{text-align:left;white-space:normal}table.meta td:first-child{color:var(--muted);width:180px}\
code{font:12px ui-monospace,SFMono-Regular,Menlo,Consolas,monospace;background:var(--bg);padding:1px 4px;border-radius:3px}\
.swatch{display:inline-block;width:10px;height:10px;border-radius:2px;margin-right:6px;vertical-align:middle}\
.plots{display:grid;grid-template-columns:repeat(auto-fill,minmax(560px,1fr));gap:14px}\
svg.plot{width:100%;height:auto;border:1px solid var(--line);border-radius:4px}\
svg .grid{stroke:#e4e7eb;stroke-width:1}svg .axis{stroke:#9aa5b1;stroke-width:1}\
svg .tick{font-size:11px;fill:#616e7c}svg .axislabel{font-size:11px;fill:#616e7c}\
svg .ptitle{font-size:13px;font-weight:600;fill:#1f2933}svg .legend{font-size:11px;fill:#3e4c59}\
svg .seg{font-size:10px;fill:#9aa5b1}\
.frames{display:grid;grid-template-columns:repeat(auto-fill,minmax(360px,1fr));gap:14px}\
figure{margin:0}figure img{width:100%;height:auto;border:1px solid var(--line);border-radius:4px;background:#000}\
figcaption{color:var(--muted);font-size:12px;margin-top:4px}\
.note{color:var(--muted);font-size:12px;margin:8px 0 0}\
footer{color:var(--muted);font-size:12px;text-align:center;padding:0 0 24px}";

/// The page for `report` with `images` embedded (PNG bytes, checked by the caller): the
/// document head, then each section in reading order.
pub fn page(report: &BenchReport, images: &[ReportImage]) -> String {
    let mut h = String::with_capacity(64 << 10);
    let title = title(&report.meta);
    head(&mut h, &title);
    header(&mut h, report, &title);
    damaged_section(&mut h, report);
    run_section(&mut h, &report.meta);
    summary_section(&mut h, report);
    plots_section(&mut h, report);
    frames_section(&mut h, images);
    footer(&mut h);
    h
}

/// The page's title: the store's path, "report" for a report without one.
fn title(m: &RunMeta) -> String {
    format!("terawalk bench — {}", if m.store.is_empty() { "report" } else { &m.store })
}

/// The document up to `<body>`: the title and the inline style sheet.
fn head(h: &mut String, title: &str) {
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width,initial-scale=1\">\
         <title>{}</title><style>{STYLE}</style></head><body>",
        escape(title)
    );
}

/// The banner (title, [`header_input`], [`header_run`]), and the opening of `<main>` that
/// [`footer`] closes.
fn header(h: &mut String, report: &BenchReport, title: &str) {
    let _ = write!(
        h,
        "<header><h1>{}</h1><p>{}</p><p>{}</p></header><main>",
        escape(title),
        escape(&header_input(&report.meta)),
        escape(&header_run(report))
    );
}

/// The pages that failed their checksum or decoding, first on the page because every figure
/// below them is suspect (nothing when the store was whole). Lists at most 20 of them.
fn damaged_section(h: &mut String, report: &BenchReport) {
    if report.damaged_pages.is_empty() {
        return;
    }
    let pages: Vec<String> = report.damaged_pages.iter().take(20).map(|d| d.page.to_string()).collect();
    let more = report.damaged_pages.len().saturating_sub(pages.len());
    let _ = write!(
        h,
        "<section class=\"damaged\"><h2>Damaged store</h2><p>{} page(s) failed their checksum or \
         decoding (pages {}{}): their geometry was drawn from coarser levels where the store has \
         them and is missing otherwise. These frames are not the store's true images; \
         <code>terawalk info STORE --verify</code> checks the whole store.</p><ul>",
        report.damaged_pages.len(),
        pages.join(", "),
        if more > 0 { format!(" and {more} more") } else { String::new() }
    );
    for d in report.damaged_pages.iter().take(20) {
        let _ = write!(h, "<li>page {}: {}</li>", d.page, escape(&d.error));
    }
    h.push_str("</ul></section>");
}

/// The run's metadata as a two-column table; a field the report did not record (empty or
/// zero) has no row.
fn run_section(h: &mut String, m: &RunMeta) {
    h.push_str("<section><h2>Run</h2><table class=\"meta\">");
    meta_row(h, "Store", escape(&m.store));
    meta_row(h, "Store size", if m.store_bytes == 0 { String::new() } else { bytes(m.store_bytes) });
    meta_row(
        h,
        "Input triangles",
        if m.input_triangles == 0 { String::new() } else { thousands(m.input_triangles) },
    );
    meta_row(h, "terawalk", escape(&build(m)));
    meta_row(h, "Camera path", escape(&m.path));
    meta_row(
        h,
        "Command",
        if m.command_line.is_empty() {
            String::new()
        } else {
            format!("<code>{}</code>", escape(&m.command_line))
        },
    );
    meta_row(h, "Adapter", escape(&m.adapter));
    meta_row(
        h,
        "Image size",
        if m.size == [0, 0] { String::new() } else { format!("{} × {} px", m.size[0], m.size[1]) },
    );
    meta_row(h, "Pixel error ε", format!("{} px", m.error_px));
    meta_row(
        h,
        "Memory budget",
        if m.memory_budget_bytes == 0 {
            String::new()
        } else {
            format!("{:.0} MB", m.memory_budget_bytes as f64 / 1e6)
        },
    );
    meta_row(h, "Date", escape(&m.date));
    meta_row(h, "Machine", escape(&m.machine));
    for (k, v) in &m.extra {
        meta_row(h, k, escape(v));
    }
    h.push_str("</table></section>");
}

/// One row of the metadata table: `k` as text, `v` as HTML (escaped by the caller); none
/// when `v` is empty.
fn meta_row(h: &mut String, k: &str, v: String) {
    if !v.is_empty() {
        let _ = write!(h, "<tr><td>{}</td><td>{v}</td></tr>", escape(k));
    }
}

/// The summary table's optional columns: each is shown when some run has its figure.
struct Columns {
    rss: bool,
    psnr: bool,
    gap: bool,
    efficiency: bool,
    lod: bool,
}

impl Columns {
    fn of(runs: &[Run]) -> Columns {
        Columns {
            rss: runs.iter().any(|r| r.summary.peak_rss_mb.is_some()),
            psnr: runs.iter().any(|r| r.summary.min_psnr_db.is_some()),
            gap: runs.iter().any(|r| r.summary.min_psnr_gap_db.is_some()),
            efficiency: runs.iter().any(|r| r.summary.median_culling_efficiency.is_some()),
            lod: runs.iter().any(|r| r.summary.median_lod_efficiency.is_some()),
        }
    }
}

/// The summary: one row of figures per run (speed-up against the first run), then the notes
/// that say how they were computed.
fn summary_section(h: &mut String, report: &BenchReport) {
    let columns = Columns::of(&report.runs);
    let first = report.runs.first();
    let base = first.map(|r| r.summary.median_ms).unwrap_or(0.0);
    let base_name = first.map(|r| r.name.as_str()).unwrap_or("");
    h.push_str("<section><h2>Summary</h2><div class=\"wide\"><table class=\"summary\">");
    summary_heading(h, base_name, &columns);
    for (i, r) in report.runs.iter().enumerate() {
        summary_row(h, i, r, base, &columns);
    }
    h.push_str("</table></div>");
    summary_notes(h, &report.runs, &columns);
    h.push_str("</section>");
}

/// The summary table's heading row.
fn summary_heading(h: &mut String, base_name: &str, columns: &Columns) {
    h.push_str(
        "<tr><th>Run</th><th>Frames</th><th>Median ms</th><th>p95 ms</th>\
                <th>p99 ms</th><th>Max ms</th><th>Mean fps</th>",
    );
    let _ = write!(h, "<th>Speed-up vs {}</th>", escape(base_name));
    h.push_str("<th>Median triangles</th><th>Median select ms</th><th>Median culling ms</th><th>Max resident MB</th><th>Disk MB</th>");
    if columns.rss {
        h.push_str("<th>Peak RSS MB</th>");
    }
    if columns.psnr {
        h.push_str("<th>Min PSNR dB</th>");
    }
    if columns.gap {
        h.push_str("<th>LOD − brute force dB, median (supersampled reference)</th><th>Worst frame's</th>");
    }
    if columns.efficiency {
        h.push_str("<th>Culling efficiency</th><th>Of the cut</th>");
    }
    if columns.lod {
        h.push_str("<th>Median cut triangles</th><th>Median needed at ε</th><th>LOD efficiency</th>");
    }
    h.push_str("</tr>");
}

/// The summary row of run `r`, the `i`-th (its colour); `base` is the first run's median frame
/// time, which the speed-up divides.
fn summary_row(h: &mut String, i: usize, r: &Run, base: f64, columns: &Columns) {
    let s = &r.summary;
    let speedup =
        if s.median_ms > 0.0 && base > 0.0 { format!("{:.2}×", base / s.median_ms) } else { "–".into() };
    let _ = write!(
        h,
        "<tr><td><span class=\"swatch\" style=\"background:{}\"></span>{}</td><td>{}</td><td>{:.2}</td>\
         <td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.1}</td><td>{speedup}</td><td>{:.0}</td><td>{:.2}</td>\
         <td>{:.2}</td><td>{:.1}</td><td>{:.1}</td>",
        PALETTE[i % PALETTE.len()],
        escape(&r.name),
        s.frames,
        s.median_ms,
        s.p95_ms,
        s.p99_ms,
        s.max_ms,
        s.mean_fps,
        s.median_triangles,
        s.median_select_ms,
        s.median_culling_ms,
        s.max_resident_mb,
        s.total_disk_read_mb
    );
    if columns.rss {
        let _ = write!(h, "<td>{}</td>", optional(s.peak_rss_mb, 1));
    }
    if columns.psnr {
        let _ = write!(h, "<td>{}</td>", optional(s.min_psnr_db, 2));
    }
    if columns.gap {
        let _ = write!(
            h,
            "<td>{}</td><td>{}</td>",
            optional(s.median_psnr_gap_db, 2),
            optional(s.min_psnr_gap_db, 2)
        );
    }
    if columns.efficiency {
        let _ = write!(h, "<td>{}</td>", optional(s.median_culling_efficiency, 3));
        let _ = write!(h, "<td>{}</td>", optional(s.median_cut_efficiency, 3));
    }
    if columns.lod {
        let _ = write!(
            h,
            "<td>{:.0}</td><td>{}</td><td>{}</td>",
            s.median_cut_triangles,
            optional(s.median_needed_triangles, 0),
            optional(s.median_lod_efficiency, 2)
        );
    }
    h.push_str("</tr>");
}

/// A figure a run may lack, with `digits` decimals; "–" when it has none.
fn optional(v: Option<f64>, digits: usize) -> String {
    v.map(|x| format!("{x:.digits$}")).unwrap_or_else(|| "–".into())
}

/// Under the summary table: the runs' descriptions, and what the percentiles, the speed-up
/// and the efficiencies mean.
fn summary_notes(h: &mut String, runs: &[Run], columns: &Columns) {
    let described: Vec<String> = runs
        .iter()
        .filter(|r| !r.description.is_empty())
        .map(|r| format!("<b>{}</b>: {}", escape(&r.name), escape(&r.description)))
        .collect();
    if !described.is_empty() {
        let _ = write!(h, "<p class=\"note\">{}</p>", described.join(" · "));
    }
    h.push_str(
        "<p class=\"note\">Percentiles interpolate linearly between ranks. Speed-up is the first run's median \
         frame time divided by each run's, measured in the same session. Culling efficiency: triangles drawn ÷ \
         triangles visible at full detail (item buffer); of the cut: ÷ triangles of the frame's own LOD cut \
         visible in its item buffer (the culling's excess alone).</p>",
    );
    if columns.lod {
        h.push_str(
            "<p class=\"note\">LOD efficiency: triangles of the LOD cut (before occlusion culling) ÷ the \
             triangles a screen can use at ε, modelled as 2 · covered pixels ÷ ε² (a triangle of ε-pixel \
             legs covers ε²/2 pixels, and a cut at error ε need keep no smaller one). The model is an upper \
             bound, so the ratio under-states the excess; it also counts triangles hidden behind the \
             visible surface. Median of the per-frame ratios.</p>",
        );
    }
}

/// A plot per series worth one ([`plotted`]), then notes on what is not plotted: the
/// reference renderings, and the series that are zero throughout.
fn plots_section(h: &mut String, report: &BenchReport) {
    let shown = plotted(&report.runs);
    h.push_str("<section><h2>Per frame</h2><div class=\"plots\">");
    for s in &shown {
        h.push_str(&plot(s, &report.runs));
    }
    h.push_str("</div>");
    references_note(h, &report.runs);
    zero_series_note(h, &report.runs, &shown);
    h.push_str("</section>");
}

/// Names the reference runs the plots leave out ([`plotted_runs`] says why).
fn references_note(h: &mut String, runs: &[Run]) {
    let references: Vec<String> = runs
        .iter()
        .filter(|r| r.kind == RunKind::Reference)
        .map(|r| format!("<b>{}</b>", escape(&r.name)))
        .collect();
    if !references.is_empty() {
        let _ = write!(
            h,
            "<p class=\"note\">Not plotted: {} (full-detail reference renderings of the compared \
             frames, not walkthrough frames; their figures are in the summary table).</p>",
            references.join(", ")
        );
    }
}

/// Names the series that have values but no plot (`shown` lacks them): zero everywhere, so
/// that a missing plot reads as "measured, nothing happened" rather than "not measured".
fn zero_series_note(h: &mut String, runs: &[Run], shown: &[&Series]) {
    let zero: Vec<&str> = SERIES
        .iter()
        .filter(|s| !shown.iter().any(|p| p.key == s.key))
        .filter(|s| plotted_runs(runs).any(|(_, r)| r.frames.iter().any(|f| (s.value)(f).is_some())))
        .map(|s| s.title)
        .collect();
    if !zero.is_empty() {
        let _ = write!(
            h,
            "<p class=\"note\">Zero in every frame of every run: {}.</p>",
            escape(&zero.join(", "))
        );
    }
}

/// The embedded frames with their captions (nothing without images).
fn frames_section(h: &mut String, images: &[ReportImage]) {
    if images.is_empty() {
        return;
    }
    h.push_str("<section><h2>Frames</h2><div class=\"frames\">");
    for im in images {
        let _ = write!(
            h,
            "<figure><img alt=\"{c}\" src=\"data:image/png;base64,{}\"><figcaption>{c}</figcaption></figure>",
            base64(&im.png),
            c = escape(&im.caption)
        );
    }
    h.push_str("</div></section>");
}

/// Closes `<main>` (opened by [`header`]) and the document.
fn footer(h: &mut String) {
    let _ = writeln!(
        h,
        "</main><footer>terawalk {} · every figure is also in report.json</footer></body></html>",
        env!("CARGO_PKG_VERSION")
    );
}

/// The header's first line, under the store's path in the title: the store's size and the
/// input's triangles ("size not recorded" for a report without them).
fn header_input(m: &RunMeta) -> String {
    let mut parts = Vec::new();
    if m.store_bytes > 0 {
        parts.push(format!("store {}", bytes(m.store_bytes)));
    }
    if m.input_triangles > 0 {
        parts.push(format!("{} input triangles", thousands(m.input_triangles)));
    }
    if parts.is_empty() {
        return "store size and input not recorded".into();
    }
    parts.join(" · ")
}

/// The header's second line: when, with what and where (date, runs and frames, terawalk's
/// version and commit, the machine, the adapter), the fields a report lacks left out.
fn header_run(report: &BenchReport) -> String {
    let m = &report.meta;
    let frames = report.runs.first().map(|r| r.frames.len()).unwrap_or(0);
    [
        m.date.clone(),
        format!("{} runs · {frames} frames", report.runs.len()),
        build(m),
        m.machine.clone(),
        m.adapter.clone(),
    ]
    .into_iter()
    .filter(|p| !p.is_empty())
    .collect::<Vec<_>>()
    .join(" · ")
}

/// "terawalk 0.1.0, commit 1a2b3c4" from what the report recorded ("" if nothing).
fn build(m: &RunMeta) -> String {
    match (m.version.is_empty(), m.commit.is_empty()) {
        (true, true) => String::new(),
        (false, true) => format!("terawalk {}", m.version),
        (true, false) => format!("terawalk, commit {}", m.commit),
        (false, false) => format!("terawalk {}, commit {}", m.version, m.commit),
    }
}

/// A file size in decimal units, as the rest of the report counts MB (10^6 bytes).
fn bytes(b: u64) -> String {
    let b = b as f64;
    match b {
        _ if b >= 1e12 => format!("{:.2} TB", b / 1e12),
        _ if b >= 1e9 => format!("{:.2} GB", b / 1e9),
        _ if b >= 1e6 => format!("{:.1} MB", b / 1e6),
        _ if b >= 1e3 => format!("{:.1} kB", b / 1e3),
        _ => format!("{b} bytes"),
    }
}

/// `n` with thousands separated by commas (one definition: `tw_core::digits`).
fn thousands(n: u64) -> String {
    tw_core::digits::thousands(n)
}

/// Standard base64 with padding (RFC 4648).
pub fn base64(data: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut o = String::with_capacity(data.len().div_ceil(3) * 4);
    for c in data.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        o.push(A[(n >> 18) as usize & 63] as char);
        o.push(A[(n >> 12) as usize & 63] as char);
        o.push(if c.len() > 1 { A[(n >> 6) as usize & 63] as char } else { '=' });
        o.push(if c.len() > 2 { A[n as usize & 63] as char } else { '=' });
    }
    o
}

#[cfg(test)]
mod tests {
    use crate::{BenchReport, FrameRecord, Run, RunKind, RunMeta};

    fn report() -> BenchReport {
        let frames = |ms: f64| -> Vec<FrameRecord> {
            (0..4).map(|i| FrameRecord { frame: i, frame_ms: ms, ..Default::default() }).collect()
        };
        let meta = RunMeta {
            store: "plant.tw".into(),
            adapter: "llvmpipe (LLVM 19), Vulkan".into(),
            date: "2026-12-06T10:00:00Z".into(),
            machine: "AMD EPYC 7B13, 2 cores, 7.8 GiB RAM, linux".into(),
            store_bytes: 1_234_567_890,
            input_triangles: 12_345_678,
            version: "0.1.0".into(),
            commit: "15a11bb".into(),
            ..Default::default()
        };
        BenchReport::new(
            meta,
            vec![
                Run::new("hzb", "", frames(12.0), None),
                Run::new("reference", "", frames(10_000.0), None).with_kind(RunKind::Reference),
            ],
        )
    }

    /// The page's `<header>` element.
    fn header(page: &str) -> &str {
        let start = page.find("<header>").unwrap();
        &page[start..start + page[start..].find("</header>").unwrap()]
    }

    #[test]
    fn header_names_store_size_input_build_date_machine_and_adapter() {
        let page = super::page(&report(), &[]);
        let h = header(&page);
        for want in [
            "plant.tw",
            "store 1.23 GB",
            "12,345,678 input triangles",
            "terawalk 0.1.0, commit 15a11bb",
            "2026-12-06T10:00:00Z",
            "2 cores, 7.8 GiB RAM",
            "llvmpipe (LLVM 19), Vulkan",
        ] {
            assert!(h.contains(want), "header lacks {want:?}: {h}");
        }
        // A report written before these were recorded says so instead of showing zeros.
        let mut old = report();
        old.meta.store_bytes = 0;
        old.meta.input_triangles = 0;
        old.meta.commit.clear();
        let page = super::page(&old, &[]);
        let h = header(&page);
        assert!(h.contains("not recorded") && !h.contains("commit") && !h.contains(" 0 bytes"), "{h}");
    }

    #[test]
    fn sizes_and_counts_read_at_a_glance() {
        assert_eq!(super::bytes(512), "512 bytes");
        assert_eq!(super::bytes(2_500_000), "2.5 MB");
        assert_eq!(super::bytes(1_234_567_890), "1.23 GB");
        assert_eq!(super::thousands(0), "0");
        assert_eq!(super::thousands(999), "999");
        assert_eq!(super::thousands(1000), "1,000");
        assert_eq!(super::thousands(12_345_678), "12,345,678");
    }

    #[test]
    fn the_summary_table_scrolls_inside_its_section() {
        let page = super::page(&report(), &[]);
        assert!(page.contains("<div class=\"wide\"><table class=\"summary\">"), "{page}");
        assert!(super::STYLE.contains(".wide{overflow-x:auto"));
        // Long headings wrap instead of widening their columns; numbers do not.
        assert!(super::STYLE.contains("table.summary th{white-space:normal"));
        let table = &page[page.find("<table class=\"summary\">").unwrap()..];
        assert!(table.find("</table></div>").is_some());
    }

    #[test]
    fn reference_renderings_are_summarised_but_not_plotted() {
        let page = super::page(&report(), &[]);
        let summary =
            &page[page.find("<table class=\"summary\">").unwrap()..page.find("</table></div>").unwrap()];
        assert!(summary.contains("reference</td>"), "in the summary");
        assert!(page.contains("Not plotted: <b>reference</b>"));
        assert!(!page.contains("class=\"legend\">reference<"), "no plot shows it");
    }

    #[test]
    fn base64_matches_rfc4648() {
        for (i, o) in [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foobar", "Zm9vYmFy")] {
            assert_eq!(super::base64(i.as_bytes()), o);
        }
    }
}
