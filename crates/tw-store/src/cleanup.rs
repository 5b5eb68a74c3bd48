//! Temporary paths to remove when the process is interrupted.
//!
//! A store is written to a temporary file next to its destination and renamed over it when
//! complete, and a build keeps its working files in a temporary directory; both are removed
//! when their owners are dropped. A signal (Ctrl-C, `kill`) ends the process without running
//! destructors, so the owners also register their paths here, and the program's signal handler
//! calls [`remove_registered`] before it exits: an interrupted build leaves neither a store nor
//! gigabytes of working files behind.

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
        let r = if p.is_dir() { std::fs::remove_dir_all(&p) } else { std::fs::remove_file(&p) };
        removed += r.is_ok() as usize;
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

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
