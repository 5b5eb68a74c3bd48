//! Progress bars for long work (indicatif): drawn on stderr when it is a terminal, hidden
//! otherwise (CI logs, pipes), so that output stays clean.
//!
//! Work of unknown size (a build phase that counts nothing, a stream without a length) gets a
//! spinner with the elapsed time instead of a bar: a bar of `0/0` is full from the start and
//! says "done" while the work has only begun.

use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar counting bytes towards `total`; a spinner with the bytes so far when `total` is 0
/// (unknown).
pub fn bytes(total: u64, prefix: impl Into<String>) -> ProgressBar {
    match total {
        0 => spinner(prefix, "{prefix:>12.cyan.bold} {spinner} {elapsed} {bytes} {bytes_per_sec} {msg}"),
        _ => bar(
            total,
            prefix,
            "{prefix:>12.cyan.bold} [{bar:30}] {bytes}/{total_bytes} {bytes_per_sec} eta {eta} {msg}",
        ),
    }
}

/// A bar counting items (triangles) towards `total`; a spinner with the count so far when
/// `total` is 0 (unknown).
pub fn count(total: u64, prefix: impl Into<String>) -> ProgressBar {
    match total {
        0 => spinner(prefix, "{prefix:>12.cyan.bold} {spinner} {elapsed} {human_pos} {per_sec} {msg}"),
        _ => bar(
            total,
            prefix,
            "{prefix:>12.cyan.bold} [{bar:30}] {human_pos}/{human_len} {per_sec} eta {eta} {msg}",
        ),
    }
}

/// A spinner with the elapsed time only, for work that counts nothing.
pub fn elapsed(prefix: impl Into<String>) -> ProgressBar {
    spinner(prefix, "{prefix:>12.cyan.bold} {spinner} {elapsed} {msg}")
}

fn bar(total: u64, prefix: impl Into<String>, template: &str) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr_with_hz(5));
    pb.set_style(ProgressStyle::with_template(template).expect("valid template").progress_chars("=> "));
    start(pb, prefix)
}

fn spinner(prefix: impl Into<String>, template: &str) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr_with_hz(5));
    pb.set_style(ProgressStyle::with_template(template).expect("valid template"));
    start(pb, prefix)
}

fn start(pb: ProgressBar, prefix: impl Into<String>) -> ProgressBar {
    pb.set_prefix(prefix.into());
    pb.enable_steady_tick(Duration::from_millis(200));
    pb
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_totals_get_a_spinner_not_a_full_bar() {
        for pb in [count(0, "redefine"), bytes(0, "ingest"), elapsed("write")] {
            assert_eq!(pb.length(), None, "{}", pb.prefix());
            pb.finish_and_clear();
        }
        for pb in [count(10, "lod"), bytes(10, "reading")] {
            assert_eq!(pb.length(), Some(10));
            pb.finish_and_clear();
        }
    }
}
