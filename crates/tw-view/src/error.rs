//! Errors of the viewer library.

/// What can stop the viewer.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("cannot open a window: {0} (is DISPLAY set? under no display, run with xvfb-run)")]
    Window(String),
    #[error(
        "no GPU adapter can draw to the window: {0}; install mesa-vulkan-drivers or set WGPU_BACKEND=gl"
    )]
    Adapter(String),
    #[error("GPU: {0}")]
    Gpu(String),
    #[error(transparent)]
    Renderer(#[from] tw_gpu::GpuError),
    #[error(transparent)]
    Runtime(#[from] tw_runtime::RuntimeError),
    #[error(transparent)]
    Frame(#[from] tw_frame::FrameError),
    #[error("no frame was drawn before exit: {0}")]
    NoFrame(String),
}
