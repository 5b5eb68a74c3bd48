//! Process memory figures from /proc (Linux): the peak resident set (VmHWM) that every memory
//! budget in terawalk is checked against, and the current resident set.

/// Peak resident set size in bytes (VmHWM), or `None` where /proc is unavailable.
pub fn peak_rss_bytes() -> Option<u64> {
    status_field("VmHWM:")
}

/// Current resident set size in bytes (VmRSS), or `None` where /proc is unavailable.
pub fn rss_bytes() -> Option<u64> {
    status_field("VmRSS:")
}

fn status_field(key: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    let kb: u64 = line[key.len()..].trim().trim_end_matches("kB").trim().parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    #[test]
    #[cfg(target_os = "linux")]
    fn peak_is_at_least_current() {
        // Current first: other test threads may grow the process between the two reads.
        let now = super::rss_bytes().unwrap();
        let peak = super::peak_rss_bytes().unwrap();
        assert!(peak >= now && now > 0);
    }
}
