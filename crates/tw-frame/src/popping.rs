//! Popping: the image change a frame's LOD cut causes on its own (`bench --popping`).
//!
//! Along a camera path, a cluster-DAG cut switches whole groups at once when their error crosses
//! τ, and the image jumps there (Yoon et al. 2003 §1 call it popping; Govindaraju's thesis lists
//! it among the limits of static LODs). The camera moves too, so two consecutive frames differ for
//! both reasons; to separate them, the frame's camera draws both the previous frame's drawn state
//! and its own, with the same renderer state and without occlusion culling: whatever differs
//! between the two images is the LOD's doing alone. The drawn state is the cut plus, with a
//! cross-fade (`--transition dither`, [`crate::transition`]), the clusters fading in and out at
//! their masks. A still camera keeps its cut, so its change is 0.
//!
//! The frustum is not the LOD: clusters that joined the cut because they came into view (their
//! box outside the previous frame's frustum, so no part of them could show in that frame) are
//! added to the previous state too: otherwise the previous cut, drawn from the new camera, would
//! leave the newly seen border empty, and a turning camera would count as popping (on the 10^7
//! fly-over this was most of the change measured: docs/benchmarks-log.md, session 39).

use std::collections::HashSet;
use tw_gpu::{GpuError, Image};

use tw_runtime::{Camera, ClusterRef, Containment, Frustum, Selection};

use crate::{DrawnState, FrameError, Walkthrough};

/// The LOD-only change of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodChange {
    /// Share of the pixels that differ between the two cuts' images (0..1).
    pub changed_pixels: f64,
    /// PSNR of the frame's own cut against the previous cut, dB; `None` when the images are
    /// identical.
    pub psnr_db: Option<f64>,
    /// Triangles of the previous and of the frame's own cut.
    pub triangles_before: u64,
    pub triangles_now: u64,
}

impl LodChange {
    /// The change between two images of the same camera.
    fn between(before: &Image, now: &Image, triangles: (u64, u64)) -> Result<LodChange, GpuError> {
        let changed = now.differing_share(before)?;
        let psnr = if changed > 0.0 { Some(now.psnr(before)?) } else { None };
        Ok(LodChange {
            changed_pixels: changed,
            psnr_db: psnr,
            triangles_before: triangles.0,
            triangles_now: triangles.1,
        })
    }
}

impl Walkthrough {
    /// The LOD-only change at `camera` between `previous` (what the frame before drew,
    /// [`Walkthrough::drawn_state`]) and what the frame just drawn drew: both drawn with their
    /// fades, unshadowed, without occlusion culling, pages loaded as needed. Leaves the
    /// renderer's own target holding the frame's own state.
    pub fn lod_change(&mut self, camera: &Camera, previous: &DrawnState) -> Result<LodChange, FrameError> {
        let now = self.drawn_state();
        let previous = self.with_clusters_come_into_view(previous, &now);
        crate::shadow::clear(&mut self.renderer);
        let before = self.render_state(camera, &previous);
        let after = before.and_then(|b| Ok((b, self.render_state(camera, &now)?)));
        self.renderer.set_fades([]);
        let (before, after) = after?;
        let triangles = (previous.triangles, now.triangles);
        Ok(LodChange::between(&before, &after, triangles)?)
    }

    /// `previous` with the clusters of `now` that its frame could not show (their boxes outside
    /// its frustum) and that it did not draw.
    fn with_clusters_come_into_view(&self, previous: &DrawnState, now: &DrawnState) -> DrawnState {
        let mut state = previous.clone();
        let Some(view_proj) = previous.view_proj else { return state };
        let frustum = Frustum::from_view_projection(&view_proj);
        let (store, cache) = (self.streamer.store(), self.streamer.cache());
        let grid_step = store.header().grid_step;
        let drawn: HashSet<&ClusterRef> = previous.clusters.iter().collect();
        let unseen = |c: &ClusterRef| match cache.get(store, c.page) {
            Ok(page) => page.bounds.get(c.index_in_page as usize).is_some_and(|(min, max)| {
                frustum.test_grid_box(*min, *max, grid_step) == Containment::Outside
            }),
            Err(_) => false,
        };
        state.clusters.extend(now.clusters.iter().filter(|c| !drawn.contains(c) && unseen(c)));
        state
    }

    /// `state` drawn whole from `camera` (its fading clusters with their masks).
    fn render_state(&mut self, camera: &Camera, state: &DrawnState) -> Result<Image, FrameError> {
        let store = self.streamer.store().clone();
        let cache = self.streamer.cache().clone();
        self.renderer.set_fades(state.fades.iter().copied());
        let selection = Selection { clusters: state.clusters.clone(), ..Default::default() };
        Ok(self.renderer.render_selection(&store, &cache, camera, &selection)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(pixels: &[[u8; 4]]) -> Image {
        Image { width: pixels.len() as u32, height: 1, rgba: pixels.iter().flatten().copied().collect() }
    }

    #[test]
    fn identical_images_change_nothing() {
        let a = image(&[[10, 20, 30, 255], [0, 0, 0, 0]]);
        let c = LodChange::between(&a, &a, (5, 5)).unwrap();
        assert_eq!(c.changed_pixels, 0.0);
        assert_eq!(c.psnr_db, None);
    }

    #[test]
    fn a_changed_pixel_is_counted_with_its_psnr() {
        let a = image(&[[10, 20, 30, 255], [0, 0, 0, 255], [1, 1, 1, 255], [9, 9, 9, 255]]);
        let b = image(&[[10, 20, 30, 255], [255, 255, 255, 255], [1, 1, 1, 255], [9, 9, 9, 255]]);
        let c = LodChange::between(&a, &b, (4, 6)).unwrap();
        assert_eq!(c.changed_pixels, 0.25);
        assert!(c.psnr_db.is_some_and(|p| p.is_finite() && p > 0.0 && p < 20.0), "{c:?}");
        assert_eq!((c.triangles_before, c.triangles_now), (4, 6));
    }
}
