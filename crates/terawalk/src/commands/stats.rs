//! `terawalk stats`: stream inputs and report what they hold and how fast they read.

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use serde_json::json;
use tw_io::{Scene, SceneOptions, SceneStats, SceneSummary};

use crate::cli::StatsArgs;
use crate::progress;
use crate::units::{fmt_byte_rate, fmt_bytes, fmt_count, fmt_count_rate};

/// Figures for one file (or for the whole scene).
pub struct FileStats {
    pub summary: SceneSummary,
    pub stats: SceneStats,
    pub seconds: f64,
}

/// Streams one file into a [`SceneStats`], with a progress bar.
pub fn stream_file(path: &Path, options: &SceneOptions) -> Result<FileStats> {
    let start = Instant::now();
    let scene = Scene::open(&[path], options.clone())?;
    let total = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let name = path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
    let pb = progress::bytes(total, "reading");
    pb.set_message(name);
    let mut stats = SceneStats::default();
    let summary = scene.stream_with_progress(&mut stats, &mut |p| {
        if let Some(t) = p.total {
            pb.set_length(t);
        }
        pb.set_position(p.done)
    })?;
    pb.finish_and_clear();
    Ok(FileStats { summary, stats, seconds: start.elapsed().as_secs_f64() })
}

pub fn run(args: StatsArgs) -> Result<()> {
    let options = SceneOptions { import: args.import.options() };
    let mut rows = Vec::new();
    for path in &args.files {
        rows.push((path, stream_file(path, &options)?));
    }
    let total_tris: u64 = rows.iter().map(|(_, r)| r.summary.triangles).sum();
    let total_objects: u64 = rows.iter().map(|(_, r)| r.summary.objects as u64).sum();
    let total_bytes: u64 = rows.iter().map(|(_, r)| r.summary.bytes).sum();
    let total_secs: f64 = rows.iter().map(|(_, r)| r.seconds).sum();
    let bounds = rows.iter().fold(tw_core::Aabb::EMPTY, |b, (_, r)| b.union(&r.stats.bounds));
    let peak = tw_core::mem::peak_rss_bytes();

    if args.json {
        let files: Vec<_> = rows
            .iter()
            .map(|(p, r)| {
                json!({
                    "file": p.display().to_string(),
                    "triangles": r.summary.triangles,
                    "vertices": r.summary.vertices,
                    "objects": r.summary.objects,
                    "degenerate_dropped": r.summary.degenerate,
                    "bytes_read": r.summary.bytes,
                    "seconds": r.seconds,
                    "mb_per_s": r.summary.bytes as f64 / 1e6 / r.seconds.max(1e-9),
                    "bounds": { "min": r.stats.bounds.min, "max": r.stats.bounds.max },
                    "triangles_with_normals": r.stats.with_normals,
                    "triangles_with_colors": r.stats.with_colors,
                })
            })
            .collect();
        let out = json!({
            "files": files,
            "total": {
                "triangles": total_tris,
                "objects": total_objects,
                "bytes_read": total_bytes,
                "seconds": total_secs,
                "bounds": { "min": bounds.min, "max": bounds.max },
                "peak_rss_bytes": peak,
            }
        });
        outln!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }

    for (path, r) in &rows {
        let s = &r.summary;
        outln!("{}", path.display());
        outln!(
            "  {} triangles, {} vertices, {} objects, {} degenerate triangles dropped",
            fmt_count(s.triangles),
            fmt_count(s.vertices),
            fmt_count(s.objects as u64),
            fmt_count(s.degenerate)
        );
        let attrs = match (r.stats.with_normals > 0, r.stats.with_colors > 0) {
            (true, true) => "normals, colours",
            (true, false) => "normals",
            (false, true) => "colours",
            (false, false) => "positions only",
        };
        outln!("  attributes: {attrs}");
        print_bounds(&r.stats.bounds);
        outln!(
            "  read {} in {:.2} s: {}, {}",
            fmt_bytes(s.bytes),
            r.seconds,
            fmt_byte_rate(s.bytes, r.seconds),
            fmt_count_rate(s.triangles, r.seconds, "triangles")
        );
    }
    if rows.len() > 1 {
        outln!("total: {} files", rows.len());
        outln!(
            "  {} triangles, {} objects, {} read in {:.2} s",
            fmt_count(total_tris),
            fmt_count(total_objects),
            fmt_bytes(total_bytes),
            total_secs
        );
        print_bounds(&bounds);
    }
    if let Some(p) = peak {
        outln!("peak memory: {}", fmt_bytes(p));
    }
    Ok(())
}

fn print_bounds(b: &tw_core::Aabb) {
    if b.is_empty() {
        outln!("  bounds: empty");
        return;
    }
    let e = b.extent();
    outln!(
        "  bounds: ({:.4}, {:.4}, {:.4}) .. ({:.4}, {:.4}, {:.4}), size {:.4} x {:.4} x {:.4}",
        b.min[0],
        b.min[1],
        b.min[2],
        b.max[0],
        b.max[1],
        b.max[2],
        e[0],
        e[1],
        e[2]
    );
}
