//! Import errors: every one names the file and, where it applies, the line or byte offset.

use std::fmt;
use std::path::PathBuf;

use tw_core::printable::escape_controls;

/// Where in a file something went wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Position {
    /// A 1-based line of a text file.
    Line(u64),
    /// A byte offset from the start of the (decompressed) file.
    Byte(u64),
    /// The whole file (empty file, unknown format).
    File,
}

impl fmt::Display for Position {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Position::Line(l) => write!(f, "line {l}"),
            Position::Byte(b) => write!(f, "byte {b}"),
            Position::File => Ok(()),
        }
    }
}

/// Messages quote file content (keywords, names, URIs) and paths that may come from files (a
/// glTF buffer's, an OBJ's material library): both are shown through
/// [`escape_controls`], so control characters in them (ESC, BEL...) are printed as `\x1b` and
/// never act on the terminal the message is written to.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file's contents are wrong: bad syntax, out-of-range index, truncated data, NaN.
    #[error("{}: {}", location(path, *position), escape_controls(message))]
    Parse { path: PathBuf, position: Position, message: String },
    /// The operating system failed us (missing file, permission, disk full, bad gzip stream).
    #[error("{}: {}", location(path, *position), escape_controls(&source.to_string()))]
    Io {
        path: PathBuf,
        position: Position,
        #[source]
        source: std::io::Error,
    },
    /// The file is valid but uses something terawalk does not read.
    #[error("{}: unsupported: {}", escape_controls(&path.display().to_string()), escape_controls(message))]
    Unsupported { path: PathBuf, message: String },
    /// A sink refused a triangle (a writer's disk filled, a limit was reached).
    #[error("{}", escape_controls(.0))]
    Sink(String),
}

fn location(path: &std::path::Path, position: Position) -> String {
    let path = escape_controls(&path.display().to_string()).into_owned();
    match position {
        Position::File => path,
        p => format!("{path}: {p}"),
    }
}

impl ImportError {
    pub fn parse(path: impl Into<PathBuf>, position: Position, message: impl Into<String>) -> Self {
        ImportError::Parse { path: path.into(), position, message: message.into() }
    }

    pub fn io(path: impl Into<PathBuf>, position: Position, source: std::io::Error) -> Self {
        ImportError::Io { path: path.into(), position, source }
    }

    pub fn unsupported(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        ImportError::Unsupported { path: path.into(), message: message.into() }
    }

    /// The position the error names, if any.
    pub fn position(&self) -> Option<Position> {
        match self {
            ImportError::Parse { position, .. } | ImportError::Io { position, .. } => Some(*position),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_file_and_position() {
        let e = ImportError::parse("a.obj", Position::Line(12), "face index 0 is invalid");
        assert_eq!(e.to_string(), "a.obj: line 12: face index 0 is invalid");
        let e = ImportError::parse("b.ply", Position::Byte(77), "truncated");
        assert_eq!(e.to_string(), "b.ply: byte 77: truncated");
        let e = ImportError::parse("c.stl", Position::File, "empty file");
        assert_eq!(e.to_string(), "c.stl: empty file");
    }

    /// Regression: raw ESC and BEL bytes of an input file were echoed into error messages,
    /// where a terminal acts on them. They are shown escaped, in messages and paths alike.
    #[test]
    fn control_characters_from_files_are_escaped() {
        let e = ImportError::parse("a.obj", Position::Line(3), "unknown keyword \"\x1b]0;pwned\x07\x1b[2J\"");
        assert_eq!(e.to_string(), "a.obj: line 3: unknown keyword \"\\x1b]0;pwned\\x07\\x1b[2J\"");
        let e = ImportError::unsupported("b\x1b[31m.gltf", "extension \"\x7f\u{9b}\"");
        assert_eq!(e.to_string(), "b\\x1b[31m.gltf: unsupported: extension \"\\x7f\\u{9b}\"");
        let e = ImportError::io("c\x07.ply", Position::Byte(4), std::io::Error::other("boom"));
        assert_eq!(e.to_string(), "c\\x07.ply: byte 4: boom");
    }
}
