//! The crate's error type (docs/DESIGN.md "Conventions": `thiserror` in libraries, no panics on
//! bad data).

use std::path::PathBuf;

/// Errors of this crate.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter for backends {backends}: {reason}; install mesa-vulkan-drivers or set \
         WGPU_BACKEND=gl"
    )]
    NoAdapter { backends: String, reason: String },
    #[error(
        "{adapter} cannot run terawalk's shaders: it lacks {missing}; use another backend \
         (WGPU_BACKEND=vulkan)"
    )]
    Unusable { adapter: String, missing: String },
    #[error("cannot create a device on {adapter}: {source}")]
    Device {
        adapter: String,
        #[source]
        source: wgpu::RequestDeviceError,
    },
    #[error("image size {width}×{height} is invalid: each side must be 1 to {max} pixels")]
    Size { width: u32, height: u32, max: u32 },
    #[error("images of different sizes cannot be compared: {}×{} and {}×{}", a.0, a.1, b.0, b.1)]
    ImageMismatch { a: (u32, u32), b: (u32, u32) },
    #[error("{what} needs the renderer's own target; it was last drawn into a caller's view")]
    NotOwnTarget { what: &'static str },
    #[error("{what} needs {missing}, which {adapter} does not have; choose another strategy")]
    Unsupported { what: &'static str, missing: &'static str, adapter: String },
    #[error("shadows: {0}")]
    Shadow(String),
    #[error("the frame does not fit the GPU budget of {budget} bytes in one pass")]
    OverBudget { budget: u64 },
    #[error("GPU error: {0}")]
    Gpu(String),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: PNG encoding failed: {source}", path.display())]
    Png {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
}
