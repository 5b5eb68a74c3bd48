//! terawalk's GPU renderer (wgpu 30): draws the clusters a [`tw_runtime::Selector`] chose for a
//! frame (docs/DESIGN.md "Data flow"; D5), headless
//! into its own offscreen target (for `terawalk render`, `bench`, tests) or into a caller's
//! texture view (the viewer's surface or egui texture), with the measurements of
//! docs/DESIGN.md "Measuring" (item buffer, image comparison) and the GPU side of the occlusion
//! strategies of D6 (two-pass drawing with depth readback for `hzb`).
//!
//! Modules, one concern each:
//! - `renderer`: the [`Renderer`] itself, by concern: opening it (adapter, device), its
//!   targets (colour, depth, item buffer, multisampled; resize and readback) and the draw
//!   passes.
//! - [`pool`]: clusters resident on the GPU in one pooled, indexed buffer under a byte budget,
//!   LRU eviction; only clusters not yet resident are uploaded each frame.
//! - [`draw`]: pipelines and batched draws (`multi_draw_indexed_indirect` or a `draw_indexed`
//!   loop, [`DrawMode`]); shading in draw.wgsl (headlight + fixed sun, [`ColorMode`]).
//! - [`ids`]: the item buffer and the exact visible sets.
//! - [`depth`]: reverse-Z depth readback for the CPU HZB.
//! - [`query`]: hardware occlusion queries of boxes against the frame's depth.
//! - [`visibility`]: full-visibility queries of triangles in a given order (CULLIDE's passes,
//!   for `tw-collide`).
//! - [`gpu_cull`]: the GPU hierarchical Z-buffer built in compute shaders, the cull of
//!   candidate boxes against it feeding indirect draws in the same frame (`gpu-hzb`).
//! - [`shadow`]: shadow maps (a depth array drawn from the light through the pool) and the
//!   shading with shadows, following `tw_runtime::shadow`'s lookup rule exactly.
//! - [`msaa`]: 4× multisampling of the shaded passes, with the farthest-sample depth resolve
//!   the occlusion strategies read.
//! - [`image`]: RGBA images, PNG, PSNR and pixel differences.
//! - `readback`, [`color`], [`error`].
//!
//! A frame: [`Renderer::begin_frame`], then one or more [`Renderer::draw`] calls (the first
//! clears, later ones draw on top — the two passes of an occlusion-culled frame), then
//! [`Renderer::read_color`] / [`Renderer::read_depth`]. [`Renderer::render_clusters`] and
//! [`Renderer::render_selection`] do the whole single-pass frame and return an [`Image`];
//! [`Renderer::render_to_view`] draws into a caller's view and does not wait.
//!
//! Shadows ([`shadow`]): [`Renderer::set_shadow_map`] once; in a frame, after `begin_frame`,
//! [`Renderer::draw_shadow_map`] for each layer, [`Renderer::set_shadows`] (and the
//! cross-culling classes, [`Renderer::set_shadow_classes`]), then the shaded draws as above.
//! [`Renderer::set_shadows`]`(None)` returns to the unshadowed shading.
//!
//! Depth is reverse-Z ([`tw_runtime::Camera::projection_reverse_z`], `Greater`, clear 0).
//! Images: RGBA8 sRGB, rows from the top; alpha 255 where geometry was drawn, 0 elsewhere.
//!
//! What each backend gives (Mesa 22.3.6, tested by tests/frame.rs):
//!
//! | | Vulkan (lavapipe) | GL (llvmpipe) |
//! |---|---|---|
//! | batched draws | `multi_draw_indexed_indirect` | the same (wgpu loops over `glDrawElementsIndirect`); [`Renderer::from_device`] on GL needs [`Renderer::set_downlevel`] to use it |
//! | triangle ids in the item buffer | yes (`PRIMITIVE_INDEX`) | yes |
//! | depth readback | compute copy | compute copy |
//! | occlusion queries | sample counts | 0/1 |
//! | GPU HZB cull ([`gpu_cull`]) | compacted, `multi_draw_indexed_indirect_count` | in place (culled draws get 0 instances); needs GL 4.3 compute, known after [`Renderer::set_downlevel`] |
//! | 4× multisampling ([`Renderer::set_samples`]) | yes | refused (llvmpipe resolved to nothing) |
//! | shadow maps ([`shadow`]) | yes; layers read back by copy | yes; one spare layer where GL would not make the map a 2D array, layers read back by a compute copy |
//! | reuse of evicted pool ranges | ordered by wgpu | the renderer waits for earlier GPU work first (see `draw_pass`) |

pub mod color;
pub mod depth;
pub mod dither;
pub mod draw;
pub mod error;
pub mod gpu_cull;
pub mod headless;
pub mod ids;
pub mod image;
pub mod msaa;
pub mod pool;
pub mod query;
mod readback;
mod renderer;
pub mod shadow;
pub mod visibility;
mod visibility_batch;

pub use wgpu;

use tw_runtime::ClusterRef;

pub use color::{hash_color, level_color, ColorMode, BACKGROUND, DEFAULT_COLOR};
pub use depth::DepthImage;
pub use draw::DrawMode;
pub use error::GpuError;
pub use gpu_cull::GpuCullResult;
pub use ids::{ClusterVisibility, Item, ItemBuffer, VisibleSet};
pub use image::Image;
pub use msaa::SUPPORTED_SAMPLES;
pub use pool::{PoolStats, MIN_BUDGET};
pub use readback::map_read;
pub use renderer::{FrameStats, Renderer, Target, MAX_RUNS};
pub use shadow::MAX_SHADOW_LAYERS;
pub use tw_runtime::SelectionPages;

/// Identifies a cluster: its page, index in the page and group (as selected). The pool keys
/// clusters by (page, index in page).
pub type ClusterKey = ClusterRef;

/// The largest image side accepted.
pub const MAX_SIDE: u32 = 16384;

/// The default GPU-memory budget for resident cluster geometry (bytes).
pub const DEFAULT_GPU_BUDGET: u64 = 512 << 20;

/// The own colour target's format. Its bytes are sRGB-encoded, but by the vertex stage
/// (`srgb_encode` in draw.wgsl: colours are flat per triangle) rather than by the rasterizer on
/// every fragment write, which on llvmpipe cost a quarter of an interior frame (10^8 walk,
/// `stage_times`: 47.5 → 35.7 ms). Copies into an `Rgba8UnormSrgb` texture keep the meaning.
pub(crate) const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// Absolute rounding of a depth written on GL: wgpu's GL backend maps clip z to GL's −1..1
/// range in the vertex shader (z' = 2z − w) and the window transform maps it back, which leaves
/// a few ulps of 1.0 on every depth. (The identical-image test on llvmpipe failed by 4 pixels
/// when the triangle tests left it out.)
pub const GL_DEPTH_ROUNDING: f32 = 4.0 * f32::EPSILON;
