//! OBJ importer (being written).

use crate::error::ImportError;
use crate::format::ImportOptions;
use crate::input::Input;
use crate::TriangleSource;

/// Opens an OBJ file for streaming.
pub fn open(input: Input, _options: &ImportOptions) -> Result<Box<dyn TriangleSource>, ImportError> {
    Err(ImportError::unsupported(&input.path, "OBJ import is not implemented yet"))
}
