//! glTF importer (being written).

use crate::error::ImportError;
use crate::format::{Format, ImportOptions};
use crate::input::Input;
use crate::TriangleSource;

/// Opens a glTF or GLB file for streaming.
pub fn open(
    input: Input,
    _format: Format,
    _options: &ImportOptions,
) -> Result<Box<dyn TriangleSource>, ImportError> {
    Err(ImportError::unsupported(&input.path, "glTF import is not implemented yet"))
}
