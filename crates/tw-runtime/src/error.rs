//! Errors of the runtime: camera descriptions that make no sense, and pages that cannot be used.

use tw_store::StoreError;

/// Everything that can go wrong in the per-frame runtime.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    /// A camera string (`"x,y,z;x,y,z;x,y,z;fovy"`) could not be parsed.
    #[error("camera {input:?}: {msg}")]
    CameraParse { input: String, msg: String },
    /// A light string (`sun`, `sun:AZ,EL`, `point:X,Y,Z`) could not be parsed.
    #[error("light {input:?}: {msg}")]
    LightParse { input: String, msg: String },
    /// A camera whose parameters cannot give a view (eye = target, up parallel to the view
    /// direction, field of view or clip planes out of range, non-finite values).
    #[error("invalid camera: {0}")]
    Camera(String),
    /// A page failed its checksum or could not be decoded (the store names file, page and byte).
    #[error(transparent)]
    Page(#[from] StoreError),
    /// A page that failed before: the cache remembers failures instead of decoding again.
    #[error("page {page} failed to load earlier: {msg}")]
    PageFailed { page: u32, msg: String },
    /// The page loader threads could not be started.
    #[error("page loader: {0}")]
    Loader(String),
    /// Shadow settings out of range, or a light depth map that does not match its layer.
    #[error("shadows: {0}")]
    Shadow(String),
    /// A camera path file that cannot be read, parsed or written.
    #[error("camera path {}: {msg}", path.display())]
    Path { path: std::path::PathBuf, msg: String },
}
