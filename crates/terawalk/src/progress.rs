//! Progress bars for long work (indicatif): drawn on stderr when it is a terminal, hidden
//! otherwise (CI logs, pipes), so that output stays clean.

use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar counting bytes towards `total`.
pub fn bytes(total: u64, prefix: impl Into<String>) -> ProgressBar {
    bar(
        total,
        prefix,
        "{prefix:>12.cyan.bold} [{bar:30}] {bytes}/{total_bytes} {bytes_per_sec} eta {eta} {msg}",
    )
}

/// A bar counting items (triangles) towards `total`.
pub fn count(total: u64, prefix: impl Into<String>) -> ProgressBar {
    bar(total, prefix, "{prefix:>12.cyan.bold} [{bar:30}] {human_pos}/{human_len} {per_sec} eta {eta} {msg}")
}

fn bar(total: u64, prefix: impl Into<String>, template: &str) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr_with_hz(5));
    pb.set_style(ProgressStyle::with_template(template).expect("valid template").progress_chars("=> "));
    pb.set_prefix(prefix.into());
    pb.enable_steady_tick(Duration::from_millis(200));
    pb
}
