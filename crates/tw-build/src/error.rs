//! Build errors: every one names the file it concerns (an input, a working file, the output)
//! or the limit that was exceeded.

use std::path::PathBuf;

use tw_io::ImportError;

#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// Reading an input failed (bad syntax, truncated data, unreadable file).
    #[error(transparent)]
    Import(#[from] ImportError),
    /// The operating system failed on a working or output file (disk full, permissions).
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The inputs hold no (non-degenerate) triangle.
    #[error("the inputs hold no triangles")]
    Empty,
    /// A size or memory limit cannot be met (a cell larger than the memory budget, coordinates
    /// too far apart for the working format, too many objects).
    #[error("{0}")]
    Limit(String),
    /// A build parameter is out of range.
    #[error("invalid parameter: {0}")]
    Param(String),
    /// Writing the store failed.
    #[error(transparent)]
    Store(#[from] tw_store::StoreError),
    /// A working file does not hold what this build wrote into it (changed on disk meanwhile).
    #[error("{}: working file is corrupt: {message}", path.display())]
    Corrupt { path: PathBuf, message: String },
    /// A helper thread or job of the build failed where it never should (a bug).
    #[error("internal error (a bug of terawalk, please report it): {0}")]
    Internal(String),
}

impl BuildError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> BuildError {
        BuildError::Io { path: path.into(), source }
    }

    pub fn store(e: tw_store::StoreError) -> BuildError {
        BuildError::Store(e)
    }
}
