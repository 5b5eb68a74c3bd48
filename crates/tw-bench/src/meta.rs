//! The report's header: what was measured, where, with which program and settings.

use tw_report::RunMeta;

use crate::BenchOptions;

/// What the header says beside the options: found while the benchmark ran.
pub struct Measured {
    pub adapter: String,
    pub samples: u32,
    pub frames: usize,
    pub store_bytes: u64,
    pub input_triangles: u64,
    /// `cull_server`: every run's network figures.
    pub net_lines: Vec<(String, String)>,
}

/// The report's header, dated now.
pub fn meta(options: &BenchOptions, measured: Measured) -> RunMeta {
    let o = options;
    RunMeta {
        store: o.store.display().to_string(),
        command_line: o.program.command_line.clone(),
        adapter: measured.adapter,
        size: [o.size.0, o.size.1],
        error_px: o.error as f64,
        memory_budget_bytes: o.memory,
        date: tw_report::utc_now(),
        machine: machine(),
        path: o.path.as_ref().map(|p| p.display().to_string()).unwrap_or_else(|| "generated".into()),
        store_bytes: measured.store_bytes,
        input_triangles: measured.input_triangles,
        version: o.program.version.clone(),
        commit: o.program.commit.clone(),
        extra: vec![
            ("frames".into(), measured.frames.to_string()),
            ("warmup".into(), o.warmup.to_string()),
            ("samples per pixel".into(), measured.samples.to_string()),
        ]
        .into_iter()
        .chain((o.reference_samples > 1).then(|| {
            ("reference samples per pixel".to_string(), format!("{} (supersampled)", o.reference_samples))
        }))
        .chain(o.cull_server.iter().map(|a| ("cull server".to_string(), a.clone())))
        .chain(measured.net_lines)
        .collect(),
    }
}

/// The machine, for the report's header: CPU model (where /proc/cpuinfo names it), cores this
/// process may use, memory (MemTotal, GiB as the kernel counts it), OS.
fn machine() -> String {
    let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let field = |file: &str, key: &str| -> Option<String> {
        let text = std::fs::read_to_string(file).ok()?;
        let line = text.lines().find(|l| l.split(':').next().is_some_and(|k| k.trim() == key))?;
        Some(line.split_once(':')?.1.trim().to_string())
    };
    let cpu = field("/proc/cpuinfo", "model name").map(|m| format!("{m}, ")).unwrap_or_default();
    let mem = field("/proc/meminfo", "MemTotal")
        .and_then(|v| v.split_whitespace().next()?.parse::<u64>().ok())
        .map(|kb| format!(", {:.1} GiB RAM", kb as f64 / 1048576.0))
        .unwrap_or_default();
    format!("{cpu}{cores} cores{mem}, {}", std::env::consts::OS)
}

/// Up to `n` frames spread evenly over `len`.
pub fn image_frames(len: usize, n: usize) -> Vec<usize> {
    if n == 0 || len == 0 {
        return Vec::new();
    }
    let n = n.min(len);
    (0..n).map(|k| k * (len - 1) / (n - 1).max(1)).collect()
}

#[cfg(test)]
mod tests {
    use super::image_frames;

    #[test]
    fn image_frames_spread_over_the_path() {
        assert_eq!(image_frames(10, 0), Vec::<usize>::new());
        assert_eq!(image_frames(0, 4), Vec::<usize>::new());
        assert_eq!(image_frames(1, 4), vec![0]);
        assert_eq!(image_frames(10, 4), vec![0, 3, 6, 9]);
        assert_eq!(image_frames(3, 4), vec![0, 1, 2]);
    }
}
