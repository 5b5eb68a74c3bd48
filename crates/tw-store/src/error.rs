//! Errors of the store reader, writer and page codec.

use std::path::PathBuf;

use crate::format::FORMAT_VERSION;

/// Everything that can go wrong opening, reading, verifying or writing a store.
///
/// Every variant that comes from file contents names the file and the byte offset (absolute, in
/// the file) where the problem was found; page errors also name the page.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// An operating-system error on the store file.
    #[error("{}: {source}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file does not start with the store magic `TERAWALK`.
    #[error("{}: not a terawalk store (the file does not start with \"TERAWALK\")", .path.display())]
    NotAStore { path: PathBuf },
    /// The file is a store of another format version.
    #[error("{}: {}", .path.display(), version_advice(*.found))]
    Version { path: PathBuf, found: u32 },
    /// The file ends before the data its header describes.
    #[error(
        "{}: truncated store: {what} needs {needed} bytes but the file has {len} (incomplete copy or \
         interrupted write?)",
        .path.display()
    )]
    Truncated { path: PathBuf, what: String, needed: u64, len: u64 },
    /// A header or table field is invalid (includes checksum mismatches).
    #[error("{}: corrupt store at byte {offset}: {msg}", .path.display())]
    Corrupt { path: PathBuf, offset: u64, msg: String },
    /// A page failed its checksum or could not be decoded.
    #[error("{}: corrupt page {page} at byte {offset}: {msg}", .path.display())]
    Page { path: PathBuf, page: u32, offset: u64, msg: String },
    /// A structural invariant found by [`Store::verify`](crate::Store::verify) does not hold.
    #[error("{}: invalid store: {msg}", .path.display())]
    Invariant { path: PathBuf, msg: String },
    /// The writer was given data that cannot be stored (a bug in the caller).
    #[error("cannot write store: {0}")]
    Invalid(String),
}

/// What to do with a store of format version `found` (≠ [`FORMAT_VERSION`]).
fn version_advice(found: u32) -> String {
    if found < FORMAT_VERSION {
        format!(
            "was written by an older terawalk (store format {found}); rebuild it with `terawalk build` \
             (this terawalk reads store format {FORMAT_VERSION})"
        )
    } else {
        format!(
            "was written by a newer terawalk (store format {found}; this terawalk reads store format \
             {FORMAT_VERSION}); rebuild it with this terawalk's `terawalk build`, or update terawalk"
        )
    }
}

/// A page that could not be decoded: `offset` is relative to the start of the page's bytes.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("page byte {offset}: {msg}")]
pub struct CodecError {
    pub offset: usize,
    pub msg: String,
}

impl CodecError {
    pub(crate) fn new(offset: usize, msg: impl Into<String>) -> CodecError {
        CodecError { offset, msg: msg.into() }
    }
}
