//! STL importer (being written).

use crate::error::ImportError;
use crate::format::ImportOptions;
use crate::input::Input;
use crate::TriangleSource;

/// Opens an STL file for streaming.
pub fn open(input: Input, _options: &ImportOptions) -> Result<Box<dyn TriangleSource>, ImportError> {
    Err(ImportError::unsupported(&input.path, "STL import is not implemented yet"))
}
