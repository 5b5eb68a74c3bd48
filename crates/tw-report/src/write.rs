//! Writing a report folder atomically: everything is checked and rendered in memory first, then
//! each file is written to a temporary file in the folder, flushed to disk and renamed into
//! place, so a failure leaves no half-written `report.json` or `index.html` (and no temporary
//! file) behind.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::{BenchReport, ReportError, ReportImage};

/// The files [`write_report`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct ReportFiles {
    pub json: PathBuf,
    pub html: PathBuf,
}

impl ReportFiles {
    /// The files a report in folder `dir` consists of (for checking them before a run).
    pub fn in_folder(dir: &Path) -> ReportFiles {
        ReportFiles { json: dir.join("report.json"), html: dir.join("index.html") }
    }

    /// Every file, in the order they are written.
    pub fn all(&self) -> [PathBuf; 2] {
        [self.json.clone(), self.html.clone()]
    }
}

const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];

/// Writes `dir/report.json` (every figure) and `dir/index.html` (the page, `images` embedded),
/// creating `dir` if needed. Checks the report ([`BenchReport::validate`]) and that each image
/// is PNG data before writing anything.
pub fn write_report(
    dir: &Path,
    report: &BenchReport,
    images: &[ReportImage],
) -> Result<ReportFiles, ReportError> {
    report.validate()?;
    for (i, im) in images.iter().enumerate() {
        if !im.png.starts_with(&PNG_SIGNATURE) {
            return Err(ReportError::Invalid(format!("image {i} ({:?}) is not PNG data", im.caption)));
        }
    }
    let mut json = serde_json::to_string_pretty(report)
        .map_err(|e| ReportError::Invalid(format!("cannot encode: {e}")))?;
    json.push('\n');
    let html = crate::html::page(report, images);
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let files = ReportFiles::in_folder(dir);
    atomic_write(&files.json, json.as_bytes())?;
    atomic_write(&files.html, html.as_bytes())?;
    Ok(files)
}

fn io(path: &Path, e: impl std::fmt::Display) -> ReportError {
    ReportError::Io { path: path.to_path_buf(), msg: e.to_string() }
}

/// Temporary file in the same folder, fsync, rename.
fn atomic_write(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    tw_core::output::check_replaceable(path).map_err(|e| io(path, e))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".tw-report-");
    // The usual permissions of a new file (0666 less the umask), not a temporary file's 0600.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp =
        builder.tempfile_in(dir).map_err(|e| io(dir, format!("cannot create a temporary file: {e}")))?;
    tmp.write_all(bytes)
        .and_then(|_| tmp.as_file().sync_all())
        .map_err(|e| io(path, format!("cannot write: {e}")))?;
    tmp.persist(path).map_err(|e| io(path, format!("cannot rename into place: {}", e.error)))?;
    Ok(())
}
