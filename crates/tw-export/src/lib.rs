//! Getting a scene back out of a store (`terawalk export`):
//!
//! - [`glb`]: one GLB file holding either the LOD cut that `render` draws for a camera at a
//!   pixel error (the same [`tw_runtime::Selector`]), or the full-detail triangles inside a box;
//! - [`tiles`]: the store's LOD hierarchy as an OGC 3D Tiles 1.1 tileset (`tileset.json` and
//!   one GLB per tile, refinement REPLACE).
//!
//! Both are built from two parts: [`cut`] chooses clusters (a cut of the cluster DAG, by
//! camera or by object-space error) and [`emit`] streams chosen clusters' triangles into
//! tw-io's GLB writer, page by page through a [`tw_runtime::PageCache`] with a memory budget.
//! Nothing holds more than the list of chosen clusters; the triangles go to the writer, which
//! spills them to disk. [`frame`] holds the coordinate conventions (store up axis, glTF's +Y,
//! 3D Tiles' +Z).

pub mod cut;
pub mod emit;
pub mod error;
pub mod frame;
pub mod glb;
pub mod tiles;

pub use error::ExportError;
pub use glb::{export_glb, GlbExport, GlbSelection};
pub use tiles::{export_tiles, TilesOptions, TilesSummary};
