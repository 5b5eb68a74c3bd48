//! Temporary paths to remove when the process is interrupted.
//!
//! A store is written to a temporary file next to its destination and renamed over it when
//! complete, and a build keeps its working files in a temporary directory; both are removed
//! when their owners are dropped. A signal (Ctrl-C, `kill`) ends the process without running
//! destructors, so the owners also register their paths here, and the program's signal handler
//! calls [`remove_registered`] before it exits: an interrupted build leaves neither a store nor
//! gigabytes of working files behind.
//!
//! `SIGKILL`, a crash or a power cut runs no handler at all. So every temporary path is also
//! *locked* while its owner lives ([`lock`]: an advisory `flock` on the file, or on a `LOCK` file
//! inside a directory, released by the kernel when the process ends however it ends), and the
//! next build removes the temporary paths whose lock nobody holds ([`remove_stale`]): a killed
//! build's leftovers go at the next build into the same folder, and a build running beside it
//! keeps its own.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

static PATHS: Mutex<Vec<(u64, PathBuf)>> = Mutex::new(Vec::new());
static NEXT_ID: AtomicU64 = AtomicU64::new(0);

/// Keeps `path` registered until dropped.
#[derive(Debug)]
pub struct TempGuard {
    id: u64,
}

/// Registers `path` (a file or a directory) for [`remove_registered`].
pub fn register(path: &Path) -> TempGuard {
    let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
    PATHS.lock().unwrap_or_else(|e| e.into_inner()).push((id, path.to_path_buf()));
    TempGuard { id }
}

impl Drop for TempGuard {
    fn drop(&mut self) {
        PATHS.lock().unwrap_or_else(|e| e.into_inner()).retain(|(id, _)| *id != self.id);
    }
}

/// Removes every registered path that still exists (for a signal handler; errors are ignored)
/// and returns how many were removed.
pub fn remove_registered() -> usize {
    let paths = std::mem::take(&mut *PATHS.lock().unwrap_or_else(|e| e.into_inner()));
    let mut removed = 0;
    for (_, p) in paths {
        removed += remove_path(&p) as usize;
    }
    removed
}

/// Removes a file or a directory tree. The program's other threads run on while a signal
/// handler removes their working directory and may create a file in it meanwhile (the tree
/// then is not empty when its last directory goes): a few more tries catch those.
fn remove_path(p: &Path) -> bool {
    for _ in 0..20 {
        let r = if p.is_dir() { std::fs::remove_dir_all(p) } else { std::fs::remove_file(p) };
        if r.is_ok() {
            return true;
        }
        if std::fs::symlink_metadata(p).is_err() {
            return false; // gone, or never there
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    false
}

/// The lock file inside a temporary directory ([`lock_dir`]).
pub const DIR_LOCK: &str = "LOCK";

/// A directory younger than this without its lock file may be one whose owner is about to lock
/// it; older ones are leftovers (of a build killed between the two steps, or of a version that
/// did not lock).
const UNLOCKED_DIR_GRACE: std::time::Duration = std::time::Duration::from_secs(600);

/// Marks the temporary file open as `file` as in use for as long as `file` stays open.
pub fn lock(file: &File) -> std::io::Result<()> {
    file.lock()
}

/// Marks the temporary directory `dir` as in use for as long as the returned file stays open.
pub fn lock_dir(dir: &Path) -> std::io::Result<File> {
    let f = File::create(dir.join(DIR_LOCK))?;
    f.lock()?;
    Ok(f)
}

/// Removes the temporary files and directories in `dir` whose names start with one of
/// `prefixes` and that no live process holds ([`lock`], [`lock_dir`]); returns what was
/// removed. Anything it cannot examine or remove is left alone: this is housekeeping, and never
/// fails the caller.
pub fn remove_stale(dir: &Path, prefixes: &[&str]) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if !prefixes.iter().any(|p| name.starts_with(p)) {
            continue;
        }
        let path = entry.path();
        let Ok(meta) = std::fs::symlink_metadata(&path) else { continue };
        let gone = if meta.is_dir() {
            is_stale_dir(&path, &meta) && std::fs::remove_dir_all(&path).is_ok()
        } else if meta.is_file() {
            is_unlocked(&path) && std::fs::remove_file(&path).is_ok()
        } else {
            false
        };
        if gone {
            removed.push(path);
        }
    }
    removed.sort();
    removed
}

fn is_stale_dir(dir: &Path, meta: &std::fs::Metadata) -> bool {
    let lock = dir.join(DIR_LOCK);
    if lock.exists() {
        return is_unlocked(&lock);
    }
    meta.modified().ok().and_then(|m| m.elapsed().ok()).is_some_and(|age| age > UNLOCKED_DIR_GRACE)
}

/// Whether nobody holds `path`'s lock (taking it, and dropping it at once).
fn is_unlocked(path: &Path) -> bool {
    File::open(path).is_ok_and(|f| f.try_lock().is_ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stale_paths_go_and_held_ones_stay() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        // A killed build's leftovers: a store file and a working directory nobody locks.
        std::fs::write(d.join(".out.tw.tmpA"), b"x").unwrap();
        std::fs::create_dir(d.join(".terawalk-build-A")).unwrap();
        File::create(d.join(".terawalk-build-A").join(DIR_LOCK)).unwrap();
        std::fs::write(d.join(".terawalk-build-A/cells.work"), b"y").unwrap();
        // A live build's: locked.
        let live_file = File::create(d.join(".out.tw.tmpB")).unwrap();
        lock(&live_file).unwrap();
        std::fs::create_dir(d.join(".terawalk-build-B")).unwrap();
        let _live_dir = lock_dir(&d.join(".terawalk-build-B")).unwrap();
        // A directory just made, not locked yet: kept (its owner may be about to lock it).
        std::fs::create_dir(d.join(".terawalk-build-C")).unwrap();
        // Not ours.
        std::fs::write(d.join("out.tw"), b"z").unwrap();
        std::fs::write(d.join(".other.tmp"), b"z").unwrap();

        let removed = remove_stale(d, &[".out.tw.tmp", ".terawalk-build-"]);
        assert_eq!(removed, vec![d.join(".out.tw.tmpA"), d.join(".terawalk-build-A")]);
        for kept in [".out.tw.tmpB", ".terawalk-build-B", ".terawalk-build-C", "out.tw", ".other.tmp"] {
            assert!(d.join(kept).exists(), "{kept} was removed");
        }
        drop(live_file);
        assert_eq!(remove_stale(d, &[".out.tw.tmp"]), vec![d.join(".out.tw.tmpB")]);
    }

    #[test]
    fn registered_paths_are_removed_and_dropped_guards_forgotten() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b, c) = (dir.path().join("a"), dir.path().join("b"), dir.path().join("c"));
        std::fs::write(&a, b"x").unwrap();
        std::fs::create_dir_all(b.join("inner")).unwrap();
        std::fs::write(b.join("inner/f"), b"y").unwrap();
        std::fs::write(&c, b"z").unwrap();
        let (_ga, _gb) = (register(&a), register(&b));
        drop(register(&c));
        // Other tests of this binary may register paths concurrently; only ours are checked.
        remove_registered();
        assert!(!a.exists() && !b.exists(), "registered paths are removed");
        assert!(c.exists(), "a dropped guard's path is kept");
    }
}
