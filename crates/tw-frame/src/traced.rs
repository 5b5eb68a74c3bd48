//! Ray-traced frames (`--renderer rt`; docs/DESIGN.md D8): the same select-and-stream step as
//! [`Walkthrough`](crate::Walkthrough) — the LOD cut at the frame's pixel error, pages streamed
//! by priority with resident ancestors standing in for missing ones — then tw-rt traces the cut
//! on every core instead of wgpu drawing it. There is no occlusion culling step: the rays find
//! the visible surface themselves, and a ray never touches a page that is not resident.
//!
//! **Shadows** (a light in [`TraceSettings::light`] or [`FrameSettings::shadows`]): shadow rays
//! must meet every cluster that can cast into the view, also those outside the eye's frustum.
//! The cut is then selected without frustum culling — at the eye's LOD, the thesis' LOD
//! consistency the rasterizer's light views follow too, under the same page budget — and cut
//! down to the clusters in the light's sweep of the eye's frustum
//! ([`tw_rt::scene::casters::CasterVolume`]), which holds the eye's own. Primary rays, limited by
//! the clip planes, see exactly what the frustum-culled cut shows, since frustum culling only
//! removes clusters.

use std::sync::Arc;
use std::time::Instant;

use tw_gpu::Image;
use tw_rt::scene::casters::CasterVolume;
use tw_rt::scene::{StoreTracer, TraceSettings, TraceStats, TracedFrame};
use tw_runtime::{Camera, SelectionPages, StreamOptions, Streamer};
use tw_store::Store;

use crate::{select_and_stream, FrameError, FrameInfo, FrameSettings, FrameTimes, Streamed};

/// A store walked through with the ray tracer: a [`Streamer`] and a [`StoreTracer`].
pub struct TracedWalkthrough {
    streamer: Streamer,
    tracer: StoreTracer,
    size: (u32, u32),
    selection: tw_runtime::Selection,
    pub trace: TraceSettings,
}

impl TracedWalkthrough {
    /// Prepares `store` for ray-traced frames of `size`: `stream.budget_bytes` is shared by the
    /// decoded pages and the cluster BVHs ([`StoreTracer::budget_split`]); root pages are loaded
    /// now and stay resident.
    pub fn new(
        store: Arc<Store>,
        size: (u32, u32),
        mut stream: StreamOptions,
        trace: TraceSettings,
    ) -> Result<TracedWalkthrough, FrameError> {
        let (pages, bvhs) = StoreTracer::budget_split(stream.budget_bytes);
        stream.budget_bytes = pages;
        let tracer = StoreTracer::new(&store, bvhs);
        let streamer = Streamer::new(store, stream)?;
        Ok(TracedWalkthrough { streamer, tracer, size, selection: Default::default(), trace })
    }

    pub fn streamer(&self) -> &Streamer {
        &self.streamer
    }

    pub fn tracer(&self) -> &StoreTracer {
        &self.tracer
    }

    /// The tracer, e.g. to make it build the cluster BVHs of a store that stores them
    /// ([`StoreTracer::use_stored_bvhs`]).
    pub fn tracer_mut(&mut self) -> &mut StoreTracer {
        &mut self.tracer
    }

    /// The last frame's LOD cut (what it traced, with a light the casters outside the view
    /// too; the viewer picks among these clusters: `TracedFrame::clusters` indexes it).
    pub fn selection(&self) -> &tw_runtime::Selection {
        &self.selection
    }

    /// Traces the next frames at `size` (a resized window), keeping the resident pages and the
    /// cluster BVHs.
    pub fn set_size(&mut self, size: (u32, u32)) {
        self.size = size;
    }

    /// Forgets frame-to-frame state (camera history for prefetching).
    pub fn reset(&mut self) {
        self.streamer.reset_history();
    }

    /// Traces one frame of `camera` (`settings.occlusion` is ignored: rays need none) and
    /// returns its image, statistics in the rasterizer's terms (BVH builds as `upload`, tracing
    /// and shading as `render`) and the ray tracer's own, and the per-pixel hits. The light of
    /// `settings.shadows`, if any, is traced (else [`TraceSettings::light`]'s); the cut then
    /// holds the casters outside the view too (module documentation).
    pub fn frame(
        &mut self,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<(Image, FrameInfo, TracedFrame), FrameError> {
        let start = Instant::now();
        let trace = TraceSettings {
            light: settings.shadows.map(|s| s.light).or(self.trace.light),
            section: settings.section,
            ..self.trace
        };
        let select_settings =
            FrameSettings { frustum_culling: settings.frustum_culling && trace.light.is_none(), ..*settings };
        let Streamed { pages, stats: stream, times: stream_times } =
            select_and_stream(&mut self.streamer, &mut self.selection, camera, &select_settings, self.size);
        if let (Some(light), true) = (trace.light, settings.frustum_culling) {
            let aspect = self.size.0 as f32 / self.size.1.max(1) as f32;
            let volume = CasterVolume::new(camera, aspect, &light);
            volume.keep_casters(&mut self.selection, &pages, self.streamer.store().header().grid_step);
        }
        let select = start.elapsed();
        let held = SelectionPages::from_resident(&pages, &self.selection.clusters);
        let mut traced = self.tracer.trace(&held, camera, self.size, &trace);
        let t: TraceStats = traced.stats;
        let info = FrameInfo {
            times: FrameTimes {
                upload: t.blas.build_time + t.tlas_time,
                render: t.trace_time + t.shade_time,
                total: start.elapsed(),
                ..crate::selection_times(select, stream_times)
            },
            select: self.selection.stats,
            stream,
            cut_triangles: t.triangles,
            triangles: t.triangles,
            masked_triangles: t.triangles,
            clusters: t.clusters as u64,
            ..Default::default()
        };
        let image =
            Image { width: traced.width, height: traced.height, rgba: std::mem::take(&mut traced.rgba) };
        Ok((image, info, traced))
    }
}
