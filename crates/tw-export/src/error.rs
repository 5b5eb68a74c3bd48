//! Errors of an export: each names the file (store or output) it is about.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Writing an output file (the GLB writer's errors name the file).
    #[error(transparent)]
    Write(#[from] tw_io::ImportError),
    /// A page of the store could not be read or decoded.
    #[error("{store}: {source}")]
    Store { store: PathBuf, source: tw_runtime::RuntimeError },
    /// Creating a directory or writing `tileset.json`.
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    /// Options that cannot describe an export (an empty region, a bad camera).
    #[error("{0}")]
    Invalid(String),
}
