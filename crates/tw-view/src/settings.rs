//! The viewer's controls as plain data: one [`Settings`] value holds every technique switch the
//! UI exposes (pixel error, occlusion strategy, frustum culling, LOD freeze, memory budget,
//! debug colourings, third-person debug view). The scene ([`crate::scene`]) reads it each frame;
//! the UI ([`crate::ui`]) edits it. Nothing here touches a window or the GPU.

pub use tw_frame::Occlusion;

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

/// Which renderer draws the scene (`view --renderer`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum RendererKind {
    /// tw-gpu on the window's device (every technique of the viewer).
    #[default]
    Raster,
    /// tw-rt on every core: the same LOD cut ray traced, with progressive supersampling while
    /// the camera stands still ([`crate::traced`]).
    Rt,
}

impl RendererKind {
    pub const ALL: [RendererKind; 2] = [RendererKind::Raster, RendererKind::Rt];

    pub fn name(self) -> &'static str {
        match self {
            RendererKind::Raster => "raster",
            RendererKind::Rt => "rt",
        }
    }
}

/// Every control of the viewer.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Pixel error threshold τ (docs/DESIGN.md, D3).
    pub pixel_error: f32,
    /// The occlusion culling strategy (tw-frame's, as `terawalk bench` runs them).
    pub occlusion: Occlusion,
    pub frustum_culling: bool,
    /// Keep the current LOD cut (selection) while the camera moves.
    pub lod_freeze: bool,
    /// Decoded page cache budget, bytes.
    pub memory_budget: u64,
    /// GPU memory budget for resident cluster geometry, bytes (tw-gpu's pool).
    pub gpu_budget: u64,
    pub coloring: Coloring,
    /// The renderer, and (ray traced only) the flashlight: a light above and beside the eye with
    /// hard shadows instead of the headlight.
    pub renderer: RendererKind,
    pub flashlight: bool,
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
            occlusion: Occlusion::None,
            frustum_culling: true,
            lod_freeze: false,
            memory_budget: 1 << 30,
            gpu_budget: tw_gpu::DEFAULT_GPU_BUDGET,
            coloring: Coloring::Material,
            renderer: RendererKind::Raster,
            flashlight: false,
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
        for o in Occlusion::ALL {
            assert_eq!(Occlusion::parse(o.name()), Some(o));
        }
        assert_eq!(Occlusion::parse("bogus"), None);
        assert_eq!(Occlusion::parse("gpu-hzb"), Some(Occlusion::GpuHzb));
        assert_eq!(Occlusion::fastest_conservative(wgpu::DeviceType::Cpu, true), Occlusion::Hzb);
        assert_eq!(Occlusion::fastest_conservative(wgpu::DeviceType::DiscreteGpu, true), Occlusion::GpuHzb);
        assert_eq!(Occlusion::fastest_conservative(wgpu::DeviceType::IntegratedGpu, false), Occlusion::Hzb);
    }

    #[test]
    fn defaults_are_sensible() {
        let s = Settings::default();
        assert_eq!(s.pixel_error, 1.0);
        assert!(s.frustum_culling && !s.lod_freeze && !s.debug_view);
        assert!(MEMORY_RANGE.contains(&s.memory_budget));
        assert!(GPU_MEMORY_RANGE.contains(&s.gpu_budget));
        assert_eq!(Coloring::Level.to_gpu(), tw_gpu::ColorMode::Level);
        assert!(s.renderer == RendererKind::Raster && !s.flashlight);
        assert_eq!(RendererKind::ALL.map(RendererKind::name), ["raster", "rt"]);
    }
}
