//! One GLB of a store: the LOD cut `render` draws for a camera, or the full-detail triangles in
//! a region.
//!
//! The file is tw-io's GLB ([`tw_io::write::GlbWriter`]): one node and mesh per object (named
//! after the store's object table, coloured by its colours), positions in input coordinates and
//! units, and a root node that turns the store's recorded up axis to glTF's +Y.

use std::path::Path;

use tw_io::write::{GlbWriter, SceneWriter, WriteSummary};
use tw_runtime::{Camera, PageCache};
use tw_store::Store;

use crate::cut::{camera_cut, object_space_cut, render_options, Hierarchy, Region};
use crate::emit::emit_clusters;
use crate::error::ExportError;

/// Which triangles go into the file.
#[derive(Clone, Debug)]
pub enum GlbSelection {
    /// The cut `render` draws for this camera at pixel error `tau` in a viewport of this size.
    Camera { camera: Camera, tau: f32, viewport: [u32; 2] },
    /// The full-detail triangles whose three vertices lie in this box (input coordinates).
    Region(Region),
}

/// What [`export_glb`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct GlbExport {
    pub file: WriteSummary,
    /// Clusters of the cut.
    pub clusters: u64,
    /// Triangles of the cut's clusters left out because they reach outside the region.
    pub outside: u64,
}

/// Writes the selected triangles of `store` to `output` (named `.glb`), reading pages through
/// `cache`. The file appears only when complete.
pub fn export_glb(
    store: &Store,
    cache: &PageCache,
    selection: &GlbSelection,
    output: &Path,
) -> Result<GlbExport, ExportError> {
    let is_glb = output.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    if !is_glb {
        return Err(ExportError::Invalid(format!(
            "{}: export writes binary glTF: name the output .glb",
            output.display()
        )));
    }
    let (cut, region) = match selection {
        GlbSelection::Camera { camera, tau, viewport } => {
            if !(tau.is_finite() && *tau >= 0.0) {
                return Err(ExportError::Invalid(format!("pixel error must be finite and ≥ 0, got {tau}")));
            }
            (camera_cut(store, cache, camera, &render_options(*tau, *viewport)), None)
        }
        GlbSelection::Region(r) => {
            (object_space_cut(store, cache, &Hierarchy::new(store), 0, 0.0, Some(r))?, Some(r))
        }
    };
    let mut writer = GlbWriter::create(output)?;
    writer.set_up_axis(store.header().up_axis)?;
    let mut writer: Box<dyn SceneWriter> = Box::new(writer);
    let emitted = emit_clusters(store, cache, &cut.clusters, region, &mut *writer)?;
    let file = writer.finish()?;
    Ok(GlbExport { file, clusters: cut.clusters.len() as u64, outside: emitted.outside })
}
