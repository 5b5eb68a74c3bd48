//! Checks on a path a command is about to write.
//!
//! Every writer of terawalk writes a temporary file beside its target and renames it over the
//! target when complete. A rename replaces whatever the target path names, so two mistakes would
//! lose data without any error: an output that is one of the command's inputs (`build in.ply -o
//! in.ply` replaced the model with the store), and an output that is not a regular file (a
//! rename over `/dev/null` replaces the device node; over a symbolic link, the link). The
//! commands call [`check_output`] before any work; the writers call [`check_replaceable`]
//! again just before they create their temporary file.

use std::fmt;
use std::path::{Path, PathBuf};

/// Why a path must not be written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OutputError {
    /// The output is the same file as an input (same device and inode: the same path, a hard
    /// link, or a symbolic link to it).
    IsInput { output: PathBuf, input: PathBuf },
    /// The output exists and is not a regular file (a directory, device, FIFO or socket).
    NotRegular { output: PathBuf, kind: &'static str },
}

impl fmt::Display for OutputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OutputError::IsInput { output, input } if output == input => write!(
                f,
                "{}: the output is also an input; writing it would destroy the input. Give \
                 another output path",
                output.display()
            ),
            OutputError::IsInput { output, input } => write!(
                f,
                "{}: the output is the same file as the input {} (a link to it); writing it would \
                 destroy the input. Give another output path",
                output.display(),
                input.display()
            ),
            OutputError::NotRegular { output, kind } => write!(
                f,
                "{}: exists and is a {kind}, not a regular file; the output replaces the file at \
                 its path, so give the path of a file to write",
                output.display()
            ),
        }
    }
}

impl std::error::Error for OutputError {}

/// Checks that `output` may be replaced: it is none of `inputs` (compared as files, through
/// links) and, if it exists, a regular file ([`check_replaceable`]). A path that does not
/// exist yet passes; an input that cannot be examined (it does not exist) is not compared.
pub fn check_output<P: AsRef<Path>>(output: &Path, inputs: &[P]) -> Result<(), OutputError> {
    check_replaceable(output)?;
    let Ok(out_meta) = std::fs::metadata(output) else { return Ok(()) };
    for input in inputs {
        let input = input.as_ref();
        if let Ok(in_meta) = std::fs::metadata(input) {
            if same_file(output, &out_meta, input, &in_meta) {
                return Err(OutputError::IsInput {
                    output: output.to_path_buf(),
                    input: input.to_path_buf(),
                });
            }
        }
    }
    Ok(())
}

/// Checks that the file at `output`, if any, is a regular file, following symbolic links (a
/// link to a regular file passes: the rename replaces the link, never what it points to, and
/// [`check_output`] has compared the target with the inputs).
pub fn check_replaceable(output: &Path) -> Result<(), OutputError> {
    match std::fs::metadata(output) {
        Ok(meta) if !meta.is_file() => {
            Err(OutputError::NotRegular { output: output.to_path_buf(), kind: kind_of(&meta) })
        }
        _ => Ok(()),
    }
}

/// A short name for what a non-regular file is, for messages.
fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    let ft = meta.file_type();
    if ft.is_dir() {
        return "directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_fifo() {
            return "FIFO";
        }
        if ft.is_char_device() {
            return "character device";
        }
        if ft.is_block_device() {
            return "block device";
        }
        if ft.is_socket() {
            return "socket";
        }
    }
    "special file"
}

#[cfg(unix)]
fn same_file(_: &Path, a: &std::fs::Metadata, _: &Path, b: &std::fs::Metadata) -> bool {
    use std::os::unix::fs::MetadataExt;
    a.dev() == b.dev() && a.ino() == b.ino()
}

#[cfg(not(unix))]
fn same_file(a: &Path, _: &std::fs::Metadata, b: &Path, _: &std::fs::Metadata) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_path_and_another_file_pass() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.ply");
        std::fs::write(&input, b"ply").unwrap();
        check_output(&dir.path().join("out.tw"), &[&input]).unwrap();
        let other = dir.path().join("old.tw");
        std::fs::write(&other, b"old").unwrap();
        check_output(&other, &[&input]).unwrap();
    }

    #[test]
    fn the_input_itself_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.ply");
        std::fs::write(&input, b"ply").unwrap();
        let e = check_output(&input, &[dir.path().join("a.obj"), input.clone()]).unwrap_err();
        assert!(matches!(e, OutputError::IsInput { .. }), "{e}");
        assert!(e.to_string().contains("would destroy the input"), "{e}");
        // Spelled differently: ./dir/../dir/in.ply.
        let spelled = dir.path().join(".").join("in.ply");
        assert!(check_output(&spelled, &[&input]).is_err());
    }

    #[cfg(unix)]
    #[test]
    fn links_to_the_input_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.ply");
        std::fs::write(&input, b"ply").unwrap();
        let hard = dir.path().join("hard.ply");
        std::fs::hard_link(&input, &hard).unwrap();
        let soft = dir.path().join("soft.ply");
        std::os::unix::fs::symlink(&input, &soft).unwrap();
        for out in [&hard, &soft] {
            let e = check_output(out, &[&input]).unwrap_err();
            assert!(e.to_string().contains("same file as the input"), "{e}");
        }
        // And the other way round: the input given through the link.
        assert!(check_output(&input, &[&soft]).is_err());
    }

    #[test]
    fn a_directory_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let e = check_output::<&Path>(dir.path(), &[]).unwrap_err();
        assert_eq!(e, OutputError::NotRegular { output: dir.path().to_path_buf(), kind: "directory" });
    }

    #[cfg(unix)]
    #[test]
    fn devices_and_fifos_are_refused() {
        let e = check_replaceable(Path::new("/dev/null")).unwrap_err();
        assert!(e.to_string().contains("character device"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().map(|s| s.success());
        if made.unwrap_or(false) {
            let e = check_replaceable(&fifo).unwrap_err();
            assert!(e.to_string().contains("FIFO"), "{e}");
        }
    }
}
