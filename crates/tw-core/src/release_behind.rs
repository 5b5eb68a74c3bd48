//! Gives back the disk blocks of a file that is read once, front to back, behind its reader:
//! `fallocate(FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE)` over what has been consumed.
//!
//! Why: the build's distribute pass turns the working file (40 bytes per triangle) into the
//! cells' bucket files (35 bytes per triangle; `crates/tw-build/src/cells.rs`). Without this both
//! are on disk in full at the end of the pass: 75 GB at 10^9 triangles. Releasing the working
//! file as it is read keeps the pair near the larger of the two.
//!
//! The file keeps its length (reads of a punched range give zeros), so nothing else about it
//! changes. Where the platform or file system cannot punch holes (not Linux, an old kernel, a
//! file system without the operation), the file is simply kept, as before: never an error.

use std::fs::{File, OpenOptions};
use std::io;
use std::path::Path;

/// Bytes consumed between two releases: large, so that a 40 GB file costs about 150 calls, and a
/// multiple of every file system's block size, so that each punch frees whole blocks.
pub const RELEASE_STEP: u64 = 256 << 20;

/// Releases a file's blocks behind a front-to-back reader, [`RELEASE_STEP`] at a time.
#[derive(Debug)]
pub struct ReleaseBehind {
    /// `None` once punching has failed or the file could not be opened for writing.
    file: Option<File>,
    /// Bytes from the start already released.
    released: u64,
    step: u64,
}

impl ReleaseBehind {
    /// Releases `path` behind its reader in steps of [`RELEASE_STEP`]. A file that cannot be
    /// opened for writing is kept ([`ReleaseBehind::keeps_file`]), not an error.
    pub fn open(path: &Path) -> ReleaseBehind {
        Self::with_step(path, RELEASE_STEP)
    }

    /// As [`ReleaseBehind::open`], with steps of `step` bytes (a multiple of the file system's
    /// block size: tests use small ones).
    pub fn with_step(path: &Path, step: u64) -> ReleaseBehind {
        let file = OpenOptions::new().write(true).open(path).ok();
        ReleaseBehind { file, released: 0, step: step.max(1) }
    }

    /// Bytes released so far.
    pub fn released(&self) -> u64 {
        self.released
    }

    /// Whether the file is being kept whole (it could not be opened for writing, or its file
    /// system or platform cannot punch holes): the caller may say so in its log.
    pub fn keeps_file(&self) -> bool {
        self.file.is_none()
    }

    /// The reader has consumed the file's first `bytes`: releases them, whole steps only (the
    /// reader's last partial step stays until the file is removed).
    pub fn consumed(&mut self, bytes: u64) {
        let Some(file) = &self.file else { return };
        let upto = bytes / self.step * self.step;
        if upto <= self.released {
            return;
        }
        match punch_hole(file, self.released, upto - self.released) {
            Ok(()) => self.released = upto,
            Err(_) => self.file = None,
        }
    }
}

/// Deallocates `len` bytes of `file` from `offset`, keeping its size; partial blocks at the ends
/// are zeroed, whole blocks freed.
#[cfg(target_os = "linux")]
pub fn punch_hole(file: &File, offset: u64, len: u64) -> io::Result<()> {
    use std::os::fd::AsRawFd;
    let (Ok(offset), Ok(len)) = (libc::off_t::try_from(offset), libc::off_t::try_from(len)) else {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, "range beyond the largest file offset"));
    };
    let mode = libc::FALLOC_FL_PUNCH_HOLE | libc::FALLOC_FL_KEEP_SIZE;
    // SAFETY: fallocate on a descriptor we own, with plain integer arguments; no memory is passed.
    #[allow(unsafe_code)]
    let r = unsafe { libc::fallocate(file.as_raw_fd(), mode, offset, len) };
    if r != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// Deallocates `len` bytes of `file` from `offset`: not supported on this platform.
#[cfg(not(target_os = "linux"))]
pub fn punch_hole(file: &File, offset: u64, len: u64) -> io::Result<()> {
    let _ = (file, offset, len);
    Err(io::Error::new(io::ErrorKind::Unsupported, "punching holes needs Linux"))
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;
    use std::io::{Read, Seek, SeekFrom, Write};
    use std::os::unix::fs::MetadataExt;

    const MIB: u64 = 1 << 20;

    /// A file of `mib` MiB whose every byte says where it is (so a misplaced read shows).
    fn numbered_file(dir: &Path, mib: u64) -> std::path::PathBuf {
        let path = dir.join("data");
        let mut f = File::create(&path).unwrap();
        let block: Vec<u8> = (0..MIB).map(|i| (i % 251) as u8).collect();
        for _ in 0..mib {
            f.write_all(&block).unwrap();
        }
        f.sync_all().unwrap();
        path
    }

    fn allocated(path: &Path) -> u64 {
        std::fs::metadata(path).unwrap().blocks() * 512
    }

    #[test]
    fn releases_whole_steps_behind_the_reader_and_keeps_the_rest() {
        let dir = tempfile::tempdir().unwrap();
        let path = numbered_file(dir.path(), 8);
        let before = allocated(&path);
        let mut r = ReleaseBehind::with_step(&path, MIB);
        r.consumed(MIB / 2); // less than a step: nothing yet
        assert_eq!(r.released(), 0);
        r.consumed(5 * MIB + 123);
        if r.keeps_file() {
            eprintln!("this file system cannot punch holes: the file is kept, as designed");
            assert_eq!(allocated(&path), before);
            return;
        }
        assert_eq!(r.released(), 5 * MIB);
        let after = allocated(&path);
        assert!(after + 5 * MIB <= before, "blocks {before} -> {after}: expected 5 MiB fewer");
        // The size is kept; the released part reads as zeros and the rest as written.
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 8 * MIB);
        let mut f = File::open(&path).unwrap();
        let mut head = vec![1u8; 4096];
        f.read_exact(&mut head).unwrap();
        assert!(head.iter().all(|&b| b == 0));
        f.seek(SeekFrom::Start(5 * MIB)).unwrap();
        let mut rest = Vec::new();
        f.read_to_end(&mut rest).unwrap();
        assert_eq!(rest.len() as u64, 3 * MIB);
        assert!(rest.iter().enumerate().all(|(i, &b)| b == (i as u64 % MIB % 251) as u8));
        // Consuming less than already released, or the same again, does nothing.
        r.consumed(2 * MIB);
        r.consumed(5 * MIB);
        assert_eq!(r.released(), 5 * MIB);
    }

    #[test]
    fn a_file_it_cannot_open_is_kept_without_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = ReleaseBehind::open(&dir.path().join("missing"));
        r.consumed(10 * RELEASE_STEP);
        assert_eq!(r.released(), 0);
    }
}
