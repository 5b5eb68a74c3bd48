//! Opening a file that must be a regular file (a model, a store, a glTF buffer).
//!
//! Why: readers size their work and their reads from the file's length and seek or read at
//! offsets. A FIFO has no length and blocks `open` until a writer appears (a hang), a character
//! device such as `/dev/zero` reports length 0 and never ends (a read "to the end" fills memory),
//! and neither can seek ("Illegal seek"). So these are refused up front with a message that
//! names the path and what it is, before anything is opened.
//!
//! [`open_regular`] looks at the path first (so a FIFO is never opened for reading, which would
//! block), then opens it without blocking and checks the opened file again, so that a path
//! replaced in between is still refused.

use std::fs::{File, Metadata, OpenOptions};
use std::io;
use std::path::Path;

/// What kind of file `meta` describes, in words, when it is not a regular file (`None` for a
/// regular file).
pub fn not_regular(meta: &Metadata) -> Option<&'static str> {
    let t = meta.file_type();
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a directory");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_char_device() {
            return Some("a character device");
        }
        if t.is_block_device() {
            return Some("a block device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("not a regular file")
}

/// The error for a path that is `kind` (from [`not_regular`]): kind `InvalidInput`, message
/// "is a FIFO (named pipe), not a regular file; copy it to a file first" (the caller names the
/// path, as for every I/O error). A directory gets no advice: it holds no stream to copy.
pub fn not_regular_error(kind: &str) -> io::Error {
    let message = match kind {
        "a directory" => format!("is {kind}, not a regular file"),
        "not a regular file" => format!("is {kind}; copy it to a file first"),
        _ => format!("is {kind}, not a regular file; copy it to a file first"),
    };
    io::Error::new(io::ErrorKind::InvalidInput, message)
}

/// Fails with [`not_regular_error`] unless `path` (following symbolic links) is a regular file.
pub fn check_regular(path: &Path) -> io::Result<Metadata> {
    let meta = std::fs::metadata(path)?;
    match not_regular(&meta) {
        None => Ok(meta),
        Some(kind) => Err(not_regular_error(kind)),
    }
}

/// Opens `path` for reading if it is a regular file; returns the file and its metadata (taken
/// from the open file). See the module documentation.
pub fn open_regular(path: &Path) -> io::Result<(File, Metadata)> {
    check_regular(path)?;
    let mut options = OpenOptions::new();
    options.read(true);
    #[cfg(target_os = "linux")]
    {
        // Should the path have become a FIFO since the check, opening it must not block.
        // O_NONBLOCK does not change reads of a regular file.
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    if let Some(kind) = not_regular(&meta) {
        return Err(not_regular_error(kind));
    }
    Ok((file, meta))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_files_open_and_others_are_named() {
        let dir = std::env::temp_dir().join(format!("tw-core-regular-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("a.bin");
        std::fs::write(&file, b"abc").unwrap();
        let (_, meta) = open_regular(&file).unwrap();
        assert_eq!(meta.len(), 3);

        let e = open_regular(&dir).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert_eq!(e.to_string(), "is a directory, not a regular file");
        #[cfg(unix)]
        {
            let e = open_regular(Path::new("/dev/null")).unwrap_err();
            assert!(e.to_string().contains("character device"), "{e}");
            let fifo = dir.join("pipe");
            let made = std::process::Command::new("mkfifo").arg(&fifo).status();
            if made.is_ok_and(|s| s.success()) {
                // Would block forever if the FIFO were opened for reading.
                let e = open_regular(&fifo).unwrap_err();
                assert!(e.to_string().contains("FIFO"), "{e}");
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
