//! Process memory figures: the peak resident set that every memory budget in terawalk is
//! checked against, and the current resident set. On Linux from /proc (VmHWM, VmRSS), on
//! Windows from the process's memory counters (peak and current working set: the same
//! measure, the process's pages held in physical memory).

/// Peak resident set size in bytes, or `None` where the system does not say.
pub fn peak_rss_bytes() -> Option<u64> {
    #[cfg(windows)]
    return windows::counters().map(|c| c.PeakWorkingSetSize as u64);
    #[cfg(not(windows))]
    status_field("VmHWM:")
}

/// Current resident set size in bytes, or `None` where the system does not say.
pub fn rss_bytes() -> Option<u64> {
    #[cfg(windows)]
    return windows::counters().map(|c| c.WorkingSetSize as u64);
    #[cfg(not(windows))]
    status_field("VmRSS:")
}

#[cfg(windows)]
mod windows {
    use windows_sys::Win32::System::ProcessStatus::{K32GetProcessMemoryInfo, PROCESS_MEMORY_COUNTERS};
    use windows_sys::Win32::System::Threading::GetCurrentProcess;

    /// The current process's memory counters (`K32GetProcessMemoryInfo`, kernel32 since Windows 7).
    pub(super) fn counters() -> Option<PROCESS_MEMORY_COUNTERS> {
        let size = std::mem::size_of::<PROCESS_MEMORY_COUNTERS>() as u32;
        // SAFETY: the structure is plain data (all zeros is a valid value), `cb` tells the call its
        // size, and the pseudo-handle of the current process needs no closing.
        unsafe {
            let mut counters: PROCESS_MEMORY_COUNTERS = std::mem::zeroed();
            counters.cb = size;
            (K32GetProcessMemoryInfo(GetCurrentProcess(), &mut counters, size) != 0).then_some(counters)
        }
    }
}

/// Makes every thread allocate from one heap (glibc: `M_ARENA_MAX` = 1); call it before the
/// process starts threads. glibc gives each thread that allocates concurrently an arena of its
/// own, up to 8 per core, and memory freed in an arena stays resident there for that arena's
/// next allocations. A process whose threads take turns at large working sets (the build's
/// phases and cell workers) then holds the sum of every arena's high-water mark: the 10^7
/// plant's build at `--memory 128M` peaked at 242 MB while its live heap never exceeded
/// ~100 MB, with 170–190 MB free inside the arenas (docs/benchmarks-log.md, "Build memory,
/// 2026-12-04"). With one arena the resident set follows the live heap (113 MB). The
/// renderer's process is alike: Mesa's CPU drivers allocate a full-detail reference frame's
/// batches from their own threads, and a 10^8 bench with reference frames at `--memory 512M`
/// peaked at 2,510 MB with glibc's arenas, 2,025 MB with two, 1,730 MB with one, frame times
/// unchanged within noise. Small allocations still go through each thread's lock-free cache.
/// Does nothing on other C libraries.
pub fn use_one_heap_arena() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets a parameter of the allocator; it is thread-safe.
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, 1);
    }
}

/// Gives the free pages inside the heap back to the system (glibc: `malloc_trim(0)`), so that
/// memory freed in the middle of the heap stops counting in the resident set. Costs a walk of
/// the heap's free lists; call it between large units of work. Does nothing on other C
/// libraries.
pub fn return_free_heap_pages() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only releases free memory of the allocator; it is thread-safe.
    unsafe {
        libc::malloc_trim(0);
    }
}

#[cfg(not(windows))]
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
