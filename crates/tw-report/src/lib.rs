//! Benchmark reports (docs/DESIGN.md "Conventions": reports are self-contained HTML with inline SVG
//! plots, no network, plus JSON with every figure). Plain data in, files out:
//!
//! - [`BenchReport`]: run metadata, and one or more [`Run`]s (the measured run and comparison
//!   runs such as "reference", "none", "hzb", "queries"), each a named series of per-frame
//!   [`FrameRecord`]s with its [`Summary`];
//! - [`write_report`] writes `report.json` and `index.html` into a folder, atomically;
//! - [`stats`]: median and percentiles; [`svg`]: the line plots; [`html`]: the page;
//! - [`lod`]: the LOD efficiency model (the cut's triangles against those a screen needs at ε).
//!
//! Memory figures come from [`tw_core::mem`] (VmHWM / VmRSS), re-exported here as
//! [`peak_rss_bytes`] and [`rss_bytes`].
//!
//! ```no_run
//! use tw_report::{BenchReport, FrameRecord, ReportImage, Run, RunMeta};
//! let frames = vec![FrameRecord { frame: 0, frame_ms: 16.0, ..Default::default() }];
//! let run = Run::new("hzb", "occlusion culling with a CPU hierarchical Z-buffer", frames, tw_report::peak_rss_bytes());
//! let report = BenchReport::new(RunMeta { store: "plant.tw".into(), ..Default::default() }, vec![run]);
//! tw_report::write_report("bench-out".as_ref(), &report, &[])?;
//! # Ok::<(), tw_report::ReportError>(())
//! ```

pub mod html;
pub mod lod;
pub mod stats;
pub mod svg;
mod write;

use serde::{Deserialize, Serialize};

pub use tw_core::mem::{peak_rss_bytes, rss_bytes};
pub use write::{write_report, ReportFiles};

/// The `format` field of every `report.json`.
pub const REPORT_FORMAT: &str = "terawalk-bench-report";
/// The version this crate writes.
pub const REPORT_VERSION: u32 = 1;

/// What was measured, where and how.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunMeta {
    /// The store file.
    pub store: String,
    /// The command line that produced the report.
    pub command_line: String,
    /// The wgpu adapter ("llvmpipe (LLVM 19, 256 bits), Gl").
    pub adapter: String,
    /// Image size in pixels, width × height.
    pub size: [u32; 2],
    /// Pixel error threshold ε (τ) of the LOD cut.
    pub error_px: f64,
    /// Memory budget given with `--memory`, bytes.
    pub memory_budget_bytes: u64,
    /// When the run started, RFC 3339 UTC (see [`utc_now`]).
    pub date: String,
    /// The machine (CPU, cores, memory, OS).
    pub machine: String,
    /// The camera path file, if any.
    #[serde(default)]
    pub path: String,
    /// Size of the store file, bytes (0: not recorded, as in reports written before it was).
    #[serde(default)]
    pub store_bytes: u64,
    /// Triangles of the model the store was built from (the store header's input count; 0: not
    /// recorded).
    #[serde(default)]
    pub input_triangles: u64,
    /// The terawalk version that measured the run ("" in older reports).
    #[serde(default)]
    pub version: String,
    /// The git commit terawalk was built from (short hash, "unknown" for a build outside a git
    /// checkout; "" in older reports): with the version, what a figure can be traced back to.
    #[serde(default)]
    pub commit: String,
    /// Anything else worth keeping (key → value), shown in the page's header table.
    #[serde(default)]
    pub extra: Vec<(String, String)>,
}

/// One frame's figures. Times in milliseconds, memory and I/O in MB (10^6 bytes).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    pub frame: u32,
    /// The camera path's segment ("walk", "fly", …).
    #[serde(default)]
    pub segment: String,
    /// From camera update to image complete; through a parallel pipeline (`--pipeline`), the
    /// interval since the frame before was complete (the pipeline's throughput).
    pub frame_ms: f64,
    /// Through a parallel pipeline: from the camera going in to its image complete (the
    /// end-to-end latency, which the pipeline's stages add up to).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency_ms: Option<f64>,
    pub select_ms: f64,
    /// Of `select_ms`: the frame's own cut, and the prefetch views' selections.
    #[serde(default)]
    pub cut_ms: f64,
    #[serde(default)]
    pub prefetch_ms: f64,
    /// The same as `culling_ms` (occlusion culling; frustum culling is part of `select_ms`):
    /// kept so that reports of format version 1 still read. Not plotted.
    pub cull_ms: f64,
    pub upload_ms: f64,
    pub render_ms: f64,
    pub triangles: u64,
    /// Of `triangles`, those that passed the per-triangle occlusion tests (`hzb`): the rest
    /// are gaps between runs of visible triangles that are drawn to save draw calls.
    #[serde(default)]
    pub masked_triangles: u64,
    /// Triangles of the frame's LOD cut within the frustum, before occlusion culling (0 in
    /// reports written before it was recorded).
    #[serde(default)]
    pub cut_triangles: u64,
    pub clusters: u64,
    pub nodes_visited: u64,
    pub nodes_culled_frustum: u64,
    pub nodes_culled_lod: u64,
    pub nodes_culled_occlusion: u64,
    pub occlusion_queries: u64,
    /// Skeleton node boxes tested before the clusters (`queries`, `hzb`; a hidden one culls
    /// the clusters under it), and of those found hidden.
    #[serde(default)]
    pub occlusion_node_tests: u64,
    #[serde(default)]
    pub occlusion_nodes_hidden: u64,
    /// Of `culling_ms`, `hzb` only: the box tests (nodes, groups, clusters) and the triangle
    /// tests.
    #[serde(default)]
    pub culling_box_tests_ms: f64,
    #[serde(default)]
    pub culling_triangle_tests_ms: f64,
    /// Of `culling_ms`, `hzb` only: the depth read-back, which waits for the first pass to be
    /// drawn (on a CPU driver that is rasterization): `culling_ms` less this is the culling's
    /// own CPU time.
    #[serde(default)]
    pub culling_readback_ms: f64,
    /// Time spent in occlusion culling (queries, HZB build and tests).
    pub culling_ms: f64,
    /// Decoded pages resident in memory.
    pub resident_mb: f64,
    pub gpu_resident_mb: f64,
    /// Read from the store file this frame.
    pub disk_read_mb: f64,
    pub pages_requested: u64,
    pub pages_loaded: u64,
    pub pages_evicted: u64,
    /// Groups drawn from a coarser resident ancestor instead of waiting for a page.
    pub stalls_avoided: u64,
    /// The factor τ was raised by so that the cut's pages fit the cache (1: as asked; 0: the
    /// frame waited for its pages, `--wait`, where τ is never raised).
    #[serde(default)]
    pub tau_scale: f64,
    /// Groups whose page failed (checksum, decoding): drawn from a coarser ancestor where the
    /// store has one ([`BenchReport::damaged_pages`]).
    #[serde(default)]
    pub groups_failed: u64,
    /// `--compare`: PSNR against the reference image, dB (∞ for identical images is stored as
    /// `None` with `differing_pixels = 0`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psnr_db: Option<f64>,
    /// `--compare`: share of pixels that differ from the reference (0..1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub differing_pixels: Option<f64>,
    /// `--compare` with `--reference-samples N` (N > 1): PSNR (dB, capped at 99) of the frame
    /// against the full-detail reference supersampled with N samples per pixel (the ground
    /// truth, tw-frame's `supersample`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supersampled_psnr_db: Option<f64>,
    /// `--reference-samples N`: PSNR (dB, capped at 99) of the brute-force frame (full detail,
    /// no culling, at the run's samples per pixel: the `--compare` reference) against the same
    /// supersampled reference: the best a frame at these samples can do.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub brute_force_psnr_db: Option<f64>,
    /// `--reference-samples N`: `supersampled_psnr_db − brute_force_psnr_db`, dB: what the
    /// LOD cut and the culling lose against brute force (negative: worse than brute force).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psnr_gap_db: Option<f64>,
    /// `--exact`: triangles and objects visible in the item buffer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exact_visible_triangles: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exact_visible_objects: Option<u64>,
    /// `--exact`: triangles drawn ÷ exact visible triangles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub culling_efficiency: Option<f64>,
    /// `--exact`: triangles of the frame's own LOD cut visible in its item buffer (no
    /// occlusion culling), and triangles drawn ÷ those: the culling's own excess, without the
    /// LOD's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cut_visible_triangles: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cut_efficiency: Option<f64>,
    /// `--exact`: `masked_triangles` ÷ exact visible triangles (the efficiency of the tests
    /// themselves, without the bridged gaps).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_efficiency: Option<f64>,
    /// Pixels of the frame's image that show the model (not background).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covered_pixels: Option<u64>,
    /// Triangles a screen can use over `covered_pixels` at the run's ε ([`lod::needed_triangles`]);
    /// `None` at ε = 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub needed_triangles: Option<u64>,
    /// LOD efficiency: `cut_triangles ÷ needed_triangles` ([`lod::lod_efficiency`]); `None` where
    /// nothing is needed (no pixel covered, or ε = 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lod_efficiency: Option<f64>,
    /// `--popping`: share of the pixels (0..1) that differ between the frame's camera drawn with
    /// the previous frame's cut and with its own (the LOD's own image change; 0 on the first
    /// frame), and their PSNR in dB (`None` where nothing differs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub popping_changed_pixels: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub popping_psnr_db: Option<f64>,
    /// `--light`: the shadow stage's set sizes and times.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shadow: Option<ShadowRecord>,
}

/// One frame's shadow stage (Govindaraju's thesis ch. 4 reports the same sets): the light-view
/// sets drawn into the shadow map, how cross-culling split the receivers (the eye's cut), and the
/// stage's times (ms; `total_ms` is part of `frame_ms`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ShadowRecord {
    /// Shadow-map layers (sun cascades or cube faces).
    pub layers: u32,
    /// Of `layers`, those kept from an earlier frame instead of drawn.
    #[serde(default)]
    pub layers_reused: u32,
    pub light_clusters: u64,
    pub light_triangles: u64,
    /// Of `light_triangles`, those drawn after occlusion culling from the light.
    #[serde(default)]
    pub light_drawn_triangles: u64,
    /// Of the light-view clusters, those the light sees (not hidden behind the map).
    pub light_visible_clusters: u64,
    /// Of those, the casters: in front of a partly shadowed receiver.
    pub caster_clusters: u64,
    pub caster_triangles: u64,
    pub receiver_clusters: u64,
    pub lit_triangles: u64,
    pub shadowed_triangles: u64,
    pub partial_triangles: u64,
    pub partial_clusters: u64,
    /// Of the partly shadowed receivers, those classified again by subobjects of a few
    /// triangles, and of their triangles those found lit and shadowed (drawn without lookups).
    #[serde(default)]
    pub refined_clusters: u64,
    #[serde(default)]
    pub refined_lit_triangles: u64,
    #[serde(default)]
    pub refined_shadowed_triangles: u64,
    pub total_ms: f64,
    pub select_ms: f64,
    pub draw_ms: f64,
    pub readback_ms: f64,
    pub classify_ms: f64,
}

impl FrameRecord {
    /// Sets the LOD efficiency figures of a frame whose image covers `covered_pixels` pixels,
    /// its cut drawn at pixel error `error_px` ([`lod`]).
    pub fn set_coverage(&mut self, covered_pixels: u64, error_px: f64) {
        self.covered_pixels = Some(covered_pixels);
        self.needed_triangles = lod::needed_triangles(covered_pixels, error_px);
        self.lod_efficiency = self.needed_triangles.and_then(|n| lod::lod_efficiency(self.cut_triangles, n));
    }
}

/// Summary statistics of one run's frames (percentiles interpolate linearly between ranks).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub frames: usize,
    pub median_ms: f64,
    pub p95_ms: f64,
    pub p99_ms: f64,
    pub mean_ms: f64,
    pub max_ms: f64,
    /// Frames ÷ total frame time.
    pub mean_fps: f64,
    /// 1000 ÷ median frame time.
    pub median_fps: f64,
    pub median_triangles: f64,
    pub median_select_ms: f64,
    pub median_culling_ms: f64,
    pub total_disk_read_mb: f64,
    pub max_resident_mb: f64,
    /// Peak resident set (VmHWM) of the process after the run, MB.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_rss_mb: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_psnr_db: Option<f64>,
    /// Median and lowest (the worst frame's) of the frames' `psnr_gap_db` (LOD − brute force
    /// against the supersampled reference, dB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_psnr_gap_db: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_psnr_gap_db: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_culling_efficiency: Option<f64>,
    /// Median of the frames' `cut_efficiency` (drawn ÷ visible of the frame's own cut).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_cut_efficiency: Option<f64>,
    /// Median of the frames' `cut_triangles`.
    #[serde(default)]
    pub median_cut_triangles: f64,
    /// Median of the frames' `needed_triangles` (where the model has a value).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_needed_triangles: Option<f64>,
    /// Median of the frames' `lod_efficiency` (cut ÷ needed, [`lod`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_lod_efficiency: Option<f64>,
}

impl Summary {
    /// The summary of `frames`; `peak_rss_bytes` from [`peak_rss_bytes`] after the run.
    pub fn of(frames: &[FrameRecord], peak_rss_bytes: Option<u64>) -> Summary {
        let ms: Vec<f64> = frames.iter().map(|f| f.frame_ms).collect();
        let total: f64 = ms.iter().sum();
        let med = |v: Vec<f64>| stats::median(&v).unwrap_or(0.0);
        let median_ms = med(ms.clone());
        let psnr: Vec<f64> = frames.iter().filter_map(|f| f.psnr_db).collect();
        let eff: Vec<f64> = frames.iter().filter_map(|f| f.culling_efficiency).collect();
        let gap: Vec<f64> = frames.iter().filter_map(|f| f.psnr_gap_db).collect();
        Summary {
            frames: frames.len(),
            median_ms,
            p95_ms: stats::percentile(&ms, 95.0).unwrap_or(0.0),
            p99_ms: stats::percentile(&ms, 99.0).unwrap_or(0.0),
            mean_ms: if ms.is_empty() { 0.0 } else { total / ms.len() as f64 },
            max_ms: ms.iter().cloned().fold(0.0, f64::max),
            mean_fps: if total > 0.0 { frames.len() as f64 * 1000.0 / total } else { 0.0 },
            median_fps: if median_ms > 0.0 { 1000.0 / median_ms } else { 0.0 },
            median_triangles: med(frames.iter().map(|f| f.triangles as f64).collect()),
            median_select_ms: med(frames.iter().map(|f| f.select_ms).collect()),
            median_culling_ms: med(frames.iter().map(|f| f.culling_ms).collect()),
            total_disk_read_mb: frames.iter().map(|f| f.disk_read_mb).sum(),
            max_resident_mb: frames.iter().map(|f| f.resident_mb).fold(0.0, f64::max),
            peak_rss_mb: peak_rss_bytes.map(|b| b as f64 / 1e6),
            min_psnr_db: psnr.iter().cloned().reduce(f64::min),
            median_psnr_gap_db: stats::median(&gap),
            min_psnr_gap_db: gap.iter().cloned().reduce(f64::min),
            median_culling_efficiency: stats::median(&eff),
            median_cut_efficiency: stats::median(
                &frames.iter().filter_map(|f| f.cut_efficiency).collect::<Vec<f64>>(),
            ),
            median_cut_triangles: med(frames.iter().map(|f| f.cut_triangles as f64).collect()),
            median_needed_triangles: stats::median(
                &frames.iter().filter_map(|f| f.needed_triangles.map(|n| n as f64)).collect::<Vec<f64>>(),
            ),
            median_lod_efficiency: stats::median(
                &frames.iter().filter_map(|f| f.lod_efficiency).collect::<Vec<f64>>(),
            ),
        }
    }
}

/// What a run's frames are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunKind {
    /// Frames of a walkthrough along the camera path: plotted per frame.
    #[default]
    Walkthrough,
    /// Full-detail reference renderings of some frames, made to compare the walkthroughs with
    /// (PSNR, speed-up): in the summary table, but not in the per-frame plots. They are no
    /// walkthrough frames, and one of them can take 100 to 1000 times a walkthrough frame (and
    /// draw as many times its triangles), which would flatten every plot it shares (see
    /// [`svg::plotted_runs`]).
    Reference,
}

impl RunKind {
    fn is_walkthrough(&self) -> bool {
        *self == RunKind::Walkthrough
    }
}

/// One measured run: a named series of frames (e.g. the occlusion strategy).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Run {
    /// Short name, used in legends ("hzb").
    pub name: String,
    /// What the run is ("occlusion culling with a CPU hierarchical Z-buffer").
    #[serde(default)]
    pub description: String,
    /// Walkthrough frames or reference renderings (older reports: walkthrough).
    #[serde(default, skip_serializing_if = "RunKind::is_walkthrough")]
    pub kind: RunKind,
    pub summary: Summary,
    pub frames: Vec<FrameRecord>,
}

impl Run {
    /// A run with its summary computed from `frames`.
    pub fn new(
        name: impl Into<String>,
        description: impl Into<String>,
        frames: Vec<FrameRecord>,
        peak_rss_bytes: Option<u64>,
    ) -> Run {
        let summary = Summary::of(&frames, peak_rss_bytes);
        Run {
            name: name.into(),
            description: description.into(),
            kind: RunKind::Walkthrough,
            summary,
            frames,
        }
    }

    /// The run, marked as `kind` (a walkthrough unless marked).
    pub fn with_kind(mut self, kind: RunKind) -> Run {
        self.kind = kind;
        self
    }
}

/// The whole report: metadata and runs (the first is the main run; the others compare with it).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BenchReport {
    pub format: String,
    pub version: u32,
    pub meta: RunMeta,
    pub runs: Vec<Run>,
    /// Pages of the store that failed their checksum or decoding during the runs: their
    /// geometry was drawn from coarser levels where the store had them, and is missing
    /// otherwise, so the frames are not the store's true images. Empty for a sound store.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub damaged_pages: Vec<DamagedPage>,
}

/// A page that could not be used ([`BenchReport::damaged_pages`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DamagedPage {
    pub page: u32,
    /// What failed (the store's error: file, page, byte).
    pub error: String,
}

impl BenchReport {
    pub fn new(meta: RunMeta, runs: Vec<Run>) -> BenchReport {
        BenchReport {
            format: REPORT_FORMAT.into(),
            version: REPORT_VERSION,
            meta,
            runs,
            damaged_pages: Vec::new(),
        }
    }

    /// Reads a `report.json`.
    pub fn from_json(text: &str) -> Result<BenchReport, ReportError> {
        let r: BenchReport = serde_json::from_str(text)
            .map_err(|e| ReportError::Invalid(format!("line {}, column {}: {e}", e.line(), e.column())))?;
        if r.format != REPORT_FORMAT {
            return Err(ReportError::Invalid(format!(
                "\"format\" is {:?}, expected {REPORT_FORMAT:?}",
                r.format
            )));
        }
        Ok(r)
    }

    /// Checks what JSON cannot carry or a page cannot show: every number finite, at least one
    /// run, distinct run names.
    pub fn validate(&self) -> Result<(), ReportError> {
        let bad = |m: String| Err(ReportError::Invalid(m));
        if self.runs.is_empty() {
            return bad("the report has no runs".into());
        }
        for (i, r) in self.runs.iter().enumerate() {
            if self.runs[..i].iter().any(|o| o.name == r.name) {
                return bad(format!("two runs are named {:?}", r.name));
            }
            for f in &r.frames {
                for s in svg::SERIES {
                    if let Some(v) = (s.value)(f) {
                        if !v.is_finite() {
                            return bad(format!("run {:?}, frame {}: {} is {v}", r.name, f.frame, s.key));
                        }
                    }
                }
            }
            let s = &r.summary;
            let all = [s.median_ms, s.p95_ms, s.p99_ms, s.mean_ms, s.max_ms, s.mean_fps, s.median_fps];
            if all.iter().any(|v| !v.is_finite()) {
                return bad(format!("run {:?}: summary figures must be finite", r.name));
            }
        }
        if !self.meta.error_px.is_finite() {
            return bad(format!("ε is {}", self.meta.error_px));
        }
        Ok(())
    }
}

/// A frame image embedded in the page (PNG bytes, as the renderer saves them).
#[derive(Clone, Debug, PartialEq)]
pub struct ReportImage {
    pub caption: String,
    pub png: Vec<u8>,
}

/// Errors of writing a report.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("report: {0}")]
    Invalid(String),
    #[error("report: {}: {msg}", path.display())]
    Io { path: std::path::PathBuf, msg: String },
}

/// The current time as RFC 3339 UTC (`2026-12-01T18:30:00Z`).
pub fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    rfc3339(secs)
}

/// `secs` since the Unix epoch as RFC 3339 UTC (Hinnant's days-to-civil algorithm).
pub fn rfc3339(secs: i64) -> String {
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + (m <= 2) as i64;
    format!("{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem % 3600 / 60, rem % 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_are_rfc3339() {
        assert_eq!(rfc3339(0), "1970-01-01T00:00:00Z");
        assert_eq!(rfc3339(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(rfc3339(1_796_146_200), "2026-12-01T17:30:00Z");
        assert!(utc_now().ends_with('Z'));
    }
}
