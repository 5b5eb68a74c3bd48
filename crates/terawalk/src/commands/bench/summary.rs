//! `terawalk bench`'s summary on standard output: each run's line when it is complete, then the
//! ratios between the runs and the fidelity figures (tw-bench measures; this says it).

use tw_report::{BenchReport, Run};

use crate::units::fmt_count;

/// Ratios between the runs of one report (measured in the same process on the same frames):
/// each strategy against the first run and against the reference, and the fidelity figures.
pub fn print_comparison(report: &BenchReport) {
    let Some(first) = report.runs.first() else { return };
    print_ratios(first, &report.runs[1..]);
    print_shadow_ratios(report);
    for run in report.runs.iter().filter(|r| r.name != "reference") {
        print_fidelity(run, report.meta.error_px);
    }
}

/// Each run's speed against the first run's, and the first run's against the reference's on
/// the reference's frames.
fn print_ratios(first: &Run, others: &[Run]) {
    for run in others {
        if run.name == "reference" {
            // The reference ran on every K-th frame only: compare the same frames.
            let frames: std::collections::HashSet<u32> = run.frames.iter().map(|f| f.frame).collect();
            let same: Vec<f64> =
                first.frames.iter().filter(|f| frames.contains(&f.frame)).map(|f| f.frame_ms).collect();
            if let Some(m) = tw_report::stats::median(&same) {
                outln!(
                    "{:>10}: {} is {:.1}x faster than the reference on the same {} frames",
                    "speed-up",
                    first.name,
                    run.summary.median_ms / m.max(1e-9),
                    same.len()
                );
            }
        } else {
            outln!(
                "{:>10}: {} is {:.2}x the speed of {} (median frame time)",
                "ratio",
                run.name,
                first.summary.median_ms / run.summary.median_ms.max(1e-9),
                first.name
            );
        }
    }
}

/// `--light`: each shadowed run's frame rate against the same strategy's unshadowed run.
fn print_shadow_ratios(report: &BenchReport) {
    for shadowed in report.runs.iter().filter(|r| r.name.contains("+shadows")) {
        let plain = shadowed.name.replacen("+shadows", "", 1);
        if let Some(run) = report.runs.iter().find(|r| r.name == plain) {
            outln!(
                "{:>10}: {} runs at {:.2}x the frame rate of {} (median frame time, same frames)",
                "shadows",
                shadowed.name,
                run.summary.median_ms / shadowed.summary.median_ms.max(1e-9),
                run.name
            );
        }
    }
}

/// A run's fidelity and efficiency: PSNR against the references, the supersampled truth,
/// culling efficiency against the exact visible set, and the LOD cut against what the screen
/// needs at `error_px`.
fn print_fidelity(run: &Run, error_px: f64) {
    let psnr: Vec<f64> = run.frames.iter().filter_map(|f| f.psnr_db).collect();
    if let (Some(med), Some(min)) = (tw_report::stats::median(&psnr), psnr.iter().cloned().reduce(f64::min)) {
        outln!(
            "{:>10}: {}: PSNR against the reference: median {med:.1} dB, worst {min:.1} dB ({} frames)",
            "fidelity",
            run.name,
            psnr.len()
        );
    }
    print_supersampled(run);
    if let Some(e) = run.summary.median_culling_efficiency {
        let of_cut = run.summary.median_cut_efficiency.map_or(String::new(), |c| {
            format!(" (/ visible triangles of the frame's own LOD cut: median {c:.1})")
        });
        outln!(
            "{:>10}: {}: triangles drawn / exact visible triangles: median {e:.1}{of_cut}",
            "culling",
            run.name
        );
    }
    let s = &run.summary;
    if let (Some(ratio), Some(needed)) = (s.median_lod_efficiency, s.median_needed_triangles) {
        outln!(
            "{:>10}: {}: LOD cut median {} triangles, a screen needs ~{} at ε = {} px \
             (2 · covered px ÷ ε²): cut ÷ needed median {ratio:.2}",
            "lod",
            run.name,
            fmt_count(s.median_cut_triangles as u64),
            fmt_count(needed as u64),
            error_px
        );
    }
}

/// A run's summary line: frame times, triangles, peak memory, then its node tests, shadows and
/// popping where it has them.
pub fn print_run(run: &Run) {
    let s = &run.summary;
    outln!(
        "{:>10}: {} frames, median {:.1} ms ({:.1} fps), p99 {:.1} ms, median {} triangles, peak RSS {}",
        run.name,
        s.frames,
        s.median_ms,
        s.median_fps,
        s.p99_ms,
        fmt_count(s.median_triangles as u64),
        s.peak_rss_mb.map(|m| crate::units::fmt_bytes((m * 1e6) as u64)).unwrap_or_else(|| "?".into())
    );
    let node_tests: u64 = run.frames.iter().map(|f| f.occlusion_node_tests).sum();
    if node_tests > 0 {
        let hidden: u64 = run.frames.iter().map(|f| f.occlusion_nodes_hidden).sum();
        outln!(
            "{:>10}: {}: {} node boxes tested before the clusters, {} of them hidden (each culls its subtree)",
            "nodes", run.name, node_tests, hidden
        );
    }
    print_latency(run);
    print_shadows(run);
    print_popping(run);
}

/// A pipelined run's latency: from a camera going in to its image, median and p99 (its frame
/// times above are the pipeline's throughput).
fn print_latency(run: &Run) {
    let latency: Vec<f64> = run.frames.iter().filter_map(|f| f.latency_ms).collect();
    if latency.is_empty() {
        return;
    }
    let median = tw_report::stats::median(&latency).unwrap_or(f64::NAN);
    let p99 = tw_report::stats::percentile(&latency, 99.0).unwrap_or(f64::NAN);
    // Frames leave a pipeline unevenly when stages finish together; frames over the run's
    // whole time is the throughput a median of intervals may hide.
    let total_ms: f64 = run.frames.iter().map(|f| f.frame_ms).sum();
    outln!(
        "{:>10}: {}: latency (camera in to image out) median {median:.1} ms, p99 {p99:.1} ms, {:.2} frames of its median frame time; throughput {:.1} fps (frames ÷ time)",
        "latency",
        run.name,
        median / run.summary.median_ms,
        run.frames.len() as f64 * 1e3 / total_ms
    );
}

/// `--reference-samples`: a run's PSNR against the supersampled references, its brute-force
/// counterpart's, and the difference (median, and the worst frame's).
fn print_supersampled(run: &Run) {
    let gaps: Vec<(u32, f64)> = run.frames.iter().filter_map(|f| Some((f.frame, f.psnr_gap_db?))).collect();
    let Some(&(worst_frame, worst)) = gaps.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else { return };
    let median = |v: Vec<f64>| tw_report::stats::median(&v).unwrap_or(f64::NAN);
    outln!(
        "{:>10}: {}: PSNR against the supersampled reference: median {:.2} dB (brute force {:.2} dB); \
         LOD − brute force: median {:.2} dB, worst {worst:.2} dB (frame {worst_frame}), {} of {} frames within 0.5 dB",
        "truth",
        run.name,
        median(run.frames.iter().filter_map(|f| f.supersampled_psnr_db).collect()),
        median(run.frames.iter().filter_map(|f| f.brute_force_psnr_db).collect()),
        median(gaps.iter().map(|g| g.1).collect()),
        gaps.iter().filter(|g| g.1 >= -0.5).count(),
        gaps.len()
    );
}

/// `--popping`: the LOD-only image change of a run's frames.
fn print_popping(run: &Run) {
    let changed: Vec<f64> = run.frames.iter().filter_map(|f| f.popping_changed_pixels).collect();
    if changed.is_empty() {
        return;
    }
    let psnr: Vec<f64> = run.frames.iter().filter_map(|f| f.popping_psnr_db).collect();
    let worst_changed = changed.iter().cloned().fold(0.0, f64::max);
    outln!(
        "{:>10}: {}: pixels the LOD alone changes: median {:.3} %, worst {:.3} %; PSNR of the change: median {}, \
         worst {} ({} of {} frames changed)",
        "popping",
        run.name,
        100.0 * tw_report::stats::median(&changed).unwrap_or(0.0),
        100.0 * worst_changed,
        tw_report::stats::median(&psnr).map_or("-".into(), |p| format!("{p:.1} dB")),
        psnr.iter().cloned().reduce(f64::min).map_or("-".into(), |p| format!("{p:.1} dB")),
        psnr.len(),
        changed.len()
    );
}

/// `--light`: the shadow stage's medians (set sizes and times) of a run.
fn print_shadows(run: &Run) {
    let shadows: Vec<&tw_report::ShadowRecord> =
        run.frames.iter().filter_map(|f| f.shadow.as_ref()).collect();
    if shadows.is_empty() {
        return;
    }
    let med = |f: &dyn Fn(&tw_report::ShadowRecord) -> f64| {
        tw_report::stats::median(&shadows.iter().map(|s| f(s)).collect::<Vec<f64>>()).unwrap_or(0.0)
    };
    let sum = |f: &dyn Fn(&tw_report::ShadowRecord) -> u32| shadows.iter().map(|s| f(s) as f64).sum::<f64>();
    let reused = 100.0 * sum(&|s| s.layers_reused) / sum(&|s| s.layers).max(1.0);
    let mean = shadows.iter().map(|s| s.total_ms).sum::<f64>() / shadows.len() as f64;
    outln!(
        "{:>10}: {}: median {:.1} ms, mean {:.1} (select {:.1}, map {:.1}, read-back {:.1}, classify {:.1}); {:.0} % of \
         the layers reused from an earlier frame; light-view set {} triangles ({} drawn) in {:.0} layers, {:.0} of {:.0} \
         clusters seen by the light, casters {} triangles; receivers lit {} / shadowed {} / partly {} triangles, of \
         which {} lit and {} shadowed by subobjects",
        "shadows",
        run.name,
        med(&|s| s.total_ms),
        mean,
        med(&|s| s.select_ms),
        med(&|s| s.draw_ms),
        med(&|s| s.readback_ms),
        med(&|s| s.classify_ms),
        reused,
        fmt_count(med(&|s| s.light_triangles as f64) as u64),
        fmt_count(med(&|s| s.light_drawn_triangles as f64) as u64),
        med(&|s| s.layers as f64),
        med(&|s| s.light_visible_clusters as f64),
        med(&|s| s.light_clusters as f64),
        fmt_count(med(&|s| s.caster_triangles as f64) as u64),
        fmt_count(med(&|s| s.lit_triangles as f64) as u64),
        fmt_count(med(&|s| s.shadowed_triangles as f64) as u64),
        fmt_count(med(&|s| s.partial_triangles as f64) as u64),
        fmt_count(med(&|s| s.refined_lit_triangles as f64) as u64),
        fmt_count(med(&|s| s.refined_shadowed_triangles as f64) as u64),
    );
}

/// The resident set now and its peak so far (VmRSS, VmHWM), for the memory traces.
pub fn memory_now() -> String {
    let mb = |b: Option<u64>| b.map_or("?".to_string(), crate::units::fmt_bytes);
    format!("RSS {}, peak {}", mb(tw_report::rss_bytes()), mb(tw_report::peak_rss_bytes()))
}
