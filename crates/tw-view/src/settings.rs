//! The viewer's controls as plain data: one [`Settings`] value holds every technique switch the
//! UI exposes (pixel error, occlusion strategy, frustum culling, LOD freeze, memory budget,
//! debug colourings, third-person debug view). The scene ([`crate::scene`]) reads it each frame;
//! the UI ([`crate::ui`]) edits it. Nothing here touches a window or the GPU.

/// Occlusion culling strategy (DESIGN decision 6), run by tw-frame's two-pass strategies
/// ([`tw_frame::Occlusion`]) exactly as `terawalk bench` runs them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum OcclusionStrategy {
    /// No occlusion culling: the frustum-culled LOD cut is drawn as it is.
    #[default]
    None,
    /// GigaWalk's CPU hierarchical Z-buffer of last frame's visible set.
    Hzb,
    /// Hardware occlusion queries of the candidates' boxes (Yoon et al. 2003).
    Queries,
    /// A hierarchical Z-buffer built and tested in compute shaders, feeding indirect draws.
    GpuHzb,
}

impl OcclusionStrategy {
    pub const ALL: [OcclusionStrategy; 4] = [
        OcclusionStrategy::None,
        OcclusionStrategy::Hzb,
        OcclusionStrategy::Queries,
        OcclusionStrategy::GpuHzb,
    ];

    /// The name `--occlusion` takes.
    pub fn name(self) -> &'static str {
        self.to_frame().name()
    }

    /// Whether the viewer can run this strategy (all of them now).
    pub fn available(self) -> bool {
        true
    }

    pub fn parse(s: &str) -> Option<OcclusionStrategy> {
        OcclusionStrategy::ALL.into_iter().find(|o| o.name() == s)
    }

    /// The frame pipeline's strategy.
    pub fn to_frame(self) -> tw_frame::Occlusion {
        match self {
            OcclusionStrategy::None => tw_frame::Occlusion::None,
            OcclusionStrategy::Hzb => tw_frame::Occlusion::Hzb,
            OcclusionStrategy::Queries => tw_frame::Occlusion::Queries,
            OcclusionStrategy::GpuHzb => tw_frame::Occlusion::GpuHzb,
        }
    }
}

/// How triangles are coloured (mirrors [`tw_gpu::ColorMode`], with names for the UI).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Coloring {
    #[default]
    Material,
    Level,
    Cluster,
    Object,
}

impl Coloring {
    pub const ALL: [Coloring; 4] = [Coloring::Material, Coloring::Level, Coloring::Cluster, Coloring::Object];

    pub fn name(self) -> &'static str {
        match self {
            Coloring::Material => "material",
            Coloring::Level => "LOD level",
            Coloring::Cluster => "cluster",
            Coloring::Object => "object",
        }
    }

    pub fn to_gpu(self) -> tw_gpu::ColorMode {
        match self {
            Coloring::Material => tw_gpu::ColorMode::Material,
            Coloring::Level => tw_gpu::ColorMode::Level,
            Coloring::Cluster => tw_gpu::ColorMode::Cluster,
            Coloring::Object => tw_gpu::ColorMode::Object,
        }
    }
}

/// Every control of the viewer.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Pixel error threshold τ (DESIGN decision 3).
    pub pixel_error: f32,
    pub occlusion: OcclusionStrategy,
    pub frustum_culling: bool,
    /// Keep the current LOD cut (selection) while the camera moves.
    pub lod_freeze: bool,
    /// Decoded page cache budget, bytes.
    pub memory_budget: u64,
    /// GPU memory budget for resident cluster geometry, bytes (tw-gpu's pool).
    pub gpu_budget: u64,
    pub coloring: Coloring,
    /// Third-person debug view: culling from the frozen camera, drawing from a second one.
    pub debug_view: bool,
    /// Draw the boxes of visible / occluded nodes (in the debug view).
    pub show_boxes: bool,
    /// Scene resolution as a fraction of the window (CPU rasterizers like 0.5).
    pub render_scale: f32,
    pub show_hud: bool,
    pub show_controls: bool,
    pub show_help: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            pixel_error: 1.0,
            occlusion: OcclusionStrategy::None,
            frustum_culling: true,
            lod_freeze: false,
            memory_budget: 1 << 30,
            gpu_budget: tw_gpu::DEFAULT_GPU_BUDGET,
            coloring: Coloring::Material,
            debug_view: false,
            show_boxes: true,
            render_scale: 1.0,
            show_hud: true,
            show_controls: true,
            show_help: false,
        }
    }
}

/// Range of the pixel error slider.
pub const PIXEL_ERROR_RANGE: std::ops::RangeInclusive<f32> = 0.0..=64.0;
/// Range of the memory budget slider (bytes).
pub const MEMORY_RANGE: std::ops::RangeInclusive<u64> = (16 << 20)..=(64 << 30);
/// Range of the GPU memory budget slider (bytes).
pub const GPU_MEMORY_RANGE: std::ops::RangeInclusive<u64> = tw_gpu::MIN_BUDGET..=(16 << 30);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn occlusion_names_round_trip() {
        for o in OcclusionStrategy::ALL {
            assert_eq!(OcclusionStrategy::parse(o.name()), Some(o));
        }
        assert_eq!(OcclusionStrategy::parse("bogus"), None);
        assert!(OcclusionStrategy::ALL.iter().all(|o| o.available()));
        assert_eq!(OcclusionStrategy::Queries.to_frame(), tw_frame::Occlusion::Queries);
        assert_eq!(OcclusionStrategy::parse("gpu-hzb"), Some(OcclusionStrategy::GpuHzb));
    }

    #[test]
    fn defaults_are_sensible() {
        let s = Settings::default();
        assert_eq!(s.pixel_error, 1.0);
        assert!(s.frustum_culling && !s.lod_freeze && !s.debug_view);
        assert!(MEMORY_RANGE.contains(&s.memory_budget));
        assert!(GPU_MEMORY_RANGE.contains(&s.gpu_budget));
        assert_eq!(Coloring::Level.to_gpu(), tw_gpu::ColorMode::Level);
    }
}
