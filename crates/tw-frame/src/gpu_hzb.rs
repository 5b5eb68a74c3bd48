//! The `gpu-hzb` strategy ([`crate::Occlusion::GpuHzb`]; docs/DESIGN.md, D6): the two passes of
//! [`crate::occlude`] with the hierarchical Z-buffer (Greene et al. 1993) built, and the
//! candidates tested, in compute shaders that write the second pass's indirect draws — the
//! two-pass GPU culling of modern GPU-driven renderers. The GPU side is
//! [`tw_gpu::gpu_cull`]; this module only splits the cut, passes the boxes and keeps the
//! history:
//!
//! 1. occluders (visible last frame, from this frame's cut) are drawn, as in every strategy;
//! 2. [`Renderer::draw_gpu_culled`]: HZB of their depth → cull of the candidates (the CPU
//!    test's rules, [`tw_runtime::Hzb::test_box`]) → indirect draw of the visible ones → HZB of
//!    the final depth → test of the occluders, in one submission;
//! 3. the flags read back make the history: the candidates drawn plus the occluders the final
//!    depth still shows.
//!
//! `cull_time` is the GPU time of the compute passes (timestamp queries) where the device has
//! them, else the CPU time of recording them.

use std::collections::HashMap;

use glam::Vec3;
use tw_gpu::{Renderer, Target};
use tw_runtime::frustum::grid_box;
use tw_runtime::{Camera, ClusterRef, HzbResult};
use tw_store::PageCluster;

use crate::occlude::{Culled, OcclusionState, OcclusionStats};
use crate::FrameError;

/// A box for a cluster without bounds: never culled (its corners are not finite).
const UNKNOWN_BOX: (Vec3, Vec3) = (Vec3::splat(f32::MIN), Vec3::splat(f32::MAX));

/// Draws the frame's cut `clusters` with GPU HZB culling (after `begin_frame`).
pub(crate) fn draw_gpu_hzb(
    state: &mut OcclusionState,
    renderer: &mut Renderer,
    grid_step: f64,
    camera: &Camera,
    clusters: &[(ClusterRef, &PageCluster)],
    bounds: impl Fn(&ClusterRef) -> Option<([u32; 3], [u32; 3])>,
) -> Result<Culled, FrameError> {
    renderer.gpu_cull_supported()?;
    let refs: Vec<ClusterRef> = clusters.iter().map(|c| c.0).collect();
    let split = state.history.split(&refs);
    let by_key: HashMap<(u32, u32), &PageCluster> =
        clusters.iter().map(|(k, c)| ((k.page, k.index_in_page), *c)).collect();
    let decoded = |list: &[ClusterRef]| -> Vec<(ClusterRef, &PageCluster)> {
        list.iter().filter_map(|k| by_key.get(&(k.page, k.index_in_page)).map(|c| (*k, *c))).collect()
    };
    let cluster_box =
        |k: &ClusterRef| bounds(k).map(|(lo, hi)| grid_box(lo, hi, grid_step)).unwrap_or(UNKNOWN_BOX);

    renderer.draw(Target::Own, camera, grid_step, &decoded(&split.occluders), true)?;
    let candidates = decoded(&split.candidates);
    let boxes: Vec<(Vec3, Vec3)> = candidates.iter().map(|(k, _)| cluster_box(k)).collect();
    let occluder_boxes: Vec<(Vec3, Vec3)> = split.occluders.iter().map(cluster_box).collect();
    let result = renderer.draw_gpu_culled(camera, grid_step, &candidates, &boxes, &occluder_boxes)?;

    let mut stats = OcclusionStats {
        occluders: split.occluders.len() as u64,
        tested: candidates.len() as u64,
        ..Default::default()
    };
    let (mut visible, mut occluded) = (Vec::new(), Vec::new());
    for ((k, _), r) in candidates.iter().zip(&result.candidates) {
        match r {
            HzbResult::Visible => visible.push(*k),
            HzbResult::Occluded => occluded.push(*k),
            HzbResult::NoPixels => stats.no_pixels += 1,
        }
    }
    stats.culled = occluded.len() as u64;
    let still_visible: Vec<ClusterRef> = split
        .occluders
        .iter()
        .zip(&result.occluders)
        .filter(|(_, r)| **r == HzbResult::Visible)
        .map(|(k, _)| *k)
        .collect();
    state.history.update(&still_visible, &visible);
    let cull_time = result.gpu_time.unwrap_or(result.encode_time);
    let mut drawn = split.occluders;
    drawn.extend_from_slice(&visible);
    Ok(Culled { stats, cull_time, drawn, occluded, ..Default::default() })
}
