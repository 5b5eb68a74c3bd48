//! Bounds on the disk a process fills with working data, checked before each write.
//!
//! A build writes working files several times the size of its input (and an input that is
//! compressed may be a thousand times smaller than its triangles). Without a bound, a small
//! `.gz` fills the disk: the build then fails on ENOSPC deep inside a phase, and the machine's
//! other programs fail with it. So every write of [`crate::direct_io::DirectWriter`] (the
//! build's working files and the store it writes) and every vertex block an importer spills
//! first asks [`check`]:
//!
//! - **Free space**: the write must leave at least [`Limits::keep_free`] bytes free on the file
//!   system it goes to (`fstatvfs`, one call per buffer of a megabyte or so).
//! - **A cap** ([`Limits::max_written`], `terawalk build --temp-space`): the bytes written by
//!   this process's direct writers, over their whole life, stay under it. Files deleted on the
//!   way are not subtracted, so the cap is a conservative bound on the disk in use.
//!
//! The limits are process-wide (one build per process, as the command-line program runs it);
//! a library that runs several builds at once sets them to what all of them may use together.

use std::fs::File;
use std::io;
use std::sync::atomic::{AtomicU64, Ordering};

/// What [`check`] enforces ([`set_limits`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Bytes every write must leave free on its file system.
    pub keep_free: u64,
    /// Most bytes the process's direct writers may write in all (`u64::MAX`: no cap).
    pub max_written: u64,
}

impl Default for Limits {
    /// No cap; 256 MiB kept free.
    fn default() -> Limits {
        Limits { keep_free: 256 << 20, max_written: u64::MAX }
    }
}

static KEEP_FREE: AtomicU64 = AtomicU64::new(256 << 20);
static MAX_WRITTEN: AtomicU64 = AtomicU64::new(u64::MAX);
static WRITTEN: AtomicU64 = AtomicU64::new(0);

/// Sets the limits for every later write of the process.
pub fn set_limits(limits: Limits) {
    KEEP_FREE.store(limits.keep_free, Ordering::Relaxed);
    MAX_WRITTEN.store(limits.max_written, Ordering::Relaxed);
}

/// Bytes the process's direct writers have written so far.
pub fn written() -> u64 {
    WRITTEN.load(Ordering::Relaxed)
}

/// Checks that `bytes` more may be written to `file`, and counts them. The error is of kind
/// [`io::ErrorKind::StorageFull`] and says which limit, so that it reads as the disk-full
/// error it prevents.
pub fn check(file: &File, bytes: u64) -> io::Result<()> {
    let before = WRITTEN.fetch_add(bytes, Ordering::Relaxed);
    let limits = Limits {
        keep_free: KEEP_FREE.load(Ordering::Relaxed),
        max_written: MAX_WRITTEN.load(Ordering::Relaxed),
    };
    judge(limits, before, || free_bytes(file), bytes)
}

/// [`check`]'s decision: `bytes` more after `before` written, with `free` bytes free.
fn judge(limits: Limits, before: u64, free: impl FnOnce() -> Option<u64>, bytes: u64) -> io::Result<()> {
    if before.saturating_add(bytes) > limits.max_written {
        return Err(io::Error::new(
            io::ErrorKind::StorageFull,
            format!(
                "the temporary-space limit is reached: {:.1} MB of working data written, the \
                 limit is {:.1} MB (--temp-space)",
                before as f64 / 1e6,
                limits.max_written as f64 / 1e6
            ),
        ));
    }
    if let Some(free) = free() {
        if free < bytes.saturating_add(limits.keep_free) {
            return Err(io::Error::new(
                io::ErrorKind::StorageFull,
                format!(
                    "no space left on the device (ENOSPC) for working data: {:.1} MB free, and \
                     {:.1} MB must stay free for the rest of the system; free space, or put \
                     working files on a larger disk (--work-dir)",
                    free as f64 / 1e6,
                    limits.keep_free as f64 / 1e6
                ),
            ));
        }
    }
    Ok(())
}

/// Free bytes for unprivileged users on `file`'s file system, where the platform tells.
#[cfg(target_os = "linux")]
fn free_bytes(file: &File) -> Option<u64> {
    use std::os::fd::AsRawFd;
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `st` is a valid out-pointer and the descriptor is open for the call's duration.
    let r = unsafe { libc::fstatvfs(file.as_raw_fd(), &mut st) };
    (r == 0).then(|| st.f_bavail as u64 * st.f_frsize as u64)
}

#[cfg(not(target_os = "linux"))]
fn free_bytes(_: &File) -> Option<u64> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn free_space_and_the_cap_are_checked_before_a_write() {
        let l = Limits { keep_free: 1000, max_written: 10_000 };
        judge(l, 0, || Some(5000), 4000).unwrap();
        // Would leave less than `keep_free`: refused as disk full, naming ENOSPC.
        let e = judge(l, 0, || Some(5000), 4001).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::StorageFull);
        assert!(e.to_string().contains("ENOSPC"), "{e}");
        // Past the cap, whatever the free space.
        judge(l, 6000, || None, 4000).unwrap();
        let e = judge(l, 6001, || None, 4000).unwrap_err();
        assert!(e.to_string().contains("--temp-space"), "{e}");
    }

    #[test]
    fn a_write_is_counted_and_the_free_space_read() {
        let dir = tempfile::tempdir().unwrap();
        let f = File::create(dir.path().join("w")).unwrap();
        let before = written();
        check(&f, 4096).unwrap();
        assert!(written() >= before + 4096);
        #[cfg(target_os = "linux")]
        assert!(free_bytes(&f).is_some_and(|b| b > 0));
    }
}
