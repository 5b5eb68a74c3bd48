//! What a benchmark is asked to do: a plain options struct (no command-line parsing), checked
//! before anything is opened.

use std::path::PathBuf;

use anyhow::{bail, Result};
use tw_core::color::ColorMode;
use tw_frame::shadow::ShadowOptions;
use tw_frame::{Occlusion, Pipeline, ShadowSettings};
use tw_runtime::{Camera, InputLight};

/// A benchmark's settings (`terawalk bench`'s flags, whose names its errors use).
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// The store measured, named in the report.
    pub store: PathBuf,
    /// The camera path; `None`: one generated as `terawalk path` does.
    pub path: Option<PathBuf>,
    /// Only the first N frames of the path (or a generated path of N frames).
    pub frames: Option<usize>,
    /// The report's folder (index.html, report.json).
    pub out: PathBuf,
    /// Image size, width and height.
    pub size: (u32, u32),
    /// Samples per pixel; `None`: the device's default ([`tw_gpu::Renderer::default_samples`]).
    pub samples: Option<u32>,
    /// Pixel error threshold τ of the LOD cut.
    pub error: f32,
    /// Page cache budget, bytes.
    pub memory: u64,
    /// One run per strategy, in this order; `None`: the fastest conservative one on the device
    /// ([`Occlusion::fastest_for`]).
    pub occlusion: Vec<Option<Occlusion>>,
    /// How each strategy's frames run (`--pipeline`): one run per strategy and pipeline, in
    /// this order within each strategy.
    pub pipelines: Vec<Pipeline>,
    /// The main run is the reference itself (full detail, no culling).
    pub reference: bool,
    /// The reference every K-th frame: PSNR, differing pixels, speed-up on the same frames.
    pub compare: Option<usize>,
    /// With `compare`: the compared frames' references also supersampled, N samples per pixel
    /// (1: none).
    pub reference_samples: u32,
    /// Exact visible sets on the compared frames (every 10th without `compare`).
    pub exact: bool,
    /// Load every page a frame needs before drawing it.
    pub wait: bool,
    /// Streaming: raise τ while the cut's pages would not fit `memory` (`tw_runtime::fit`).
    pub fit_memory: bool,
    /// `queries`' visible-pixel cut-off.
    pub visible_pixels: u32,
    /// `hzb` without its per-triangle tests.
    pub whole_clusters: bool,
    /// Section planes and box in input coordinates (`--section`, `--section-box`): every run
    /// culls and clips by them (tw_runtime::section).
    pub section_planes: Vec<tw_runtime::SectionPlane>,
    pub section_box: Option<tw_runtime::SectionBox>,
    /// GPU budget of the resident cluster pool, bytes.
    pub gpu_memory: u64,
    /// Frames at the first camera before each run.
    pub warmup: usize,
    /// Frames embedded in the report as pictures.
    pub images: usize,
    /// How triangles are coloured.
    pub color: ColorMode,
    /// The cull server's address (host:port) when the frames cull there; the caller supplies
    /// the transport (see [`crate::RemoteCulling`]).
    pub cull_server: Option<String>,
    /// The CPU ray tracer instead of the rasterizer (one run).
    pub ray_traced: bool,
    /// With `ray_traced`: a flashlight with hard shadows.
    pub flashlight: bool,
    /// The LOD-only image change of every frame.
    pub popping: bool,
    /// How LOD switches are drawn (`--transition`; [`tw_frame::transition`]).
    pub transition: tw_frame::Transition,
    /// Shadows of one light: every strategy runs with them and without.
    pub shadows: Option<ShadowRequest>,
    /// The program, for the report's header.
    pub program: Program,
}

/// The program that measures, recorded in the report so that a figure can be traced to the
/// code and the command behind it.
#[derive(Clone, Debug, Default)]
pub struct Program {
    pub command_line: String,
    pub version: String,
    pub commit: String,
}

/// `--light`: a light and its shadow maps, turned into a frame's settings once the store and
/// the first camera are known. The one place the flags become [`ShadowSettings`], for `bench`
/// and for `render` and `view` alike, so that they check and name the flags the same way.
#[derive(Clone, Debug)]
pub struct ShadowRequest {
    pub light: InputLight,
    pub options: ShadowOptions,
    pub cross_culling: bool,
    /// `--shadow-lod`.
    pub lod: tw_frame::ShadowLod,
}

impl ShadowRequest {
    /// The frames' shadow settings on a store with `header`, its light placed for `camera`
    /// with `up_axis` up (the store's, or another that the command was given). Errors name
    /// the flags.
    pub fn settings(
        &self,
        header: &tw_store::Header,
        up_axis: u8,
        camera: &Camera,
    ) -> Result<ShadowSettings> {
        self.options.validate().map_err(|e| anyhow::anyhow!("--shadow-map/--cascades/--shadow-bias: {e}"))?;
        Ok(ShadowSettings {
            light: self.light.to_scene(header, up_axis, camera),
            options: self.options,
            cross_culling: self.cross_culling,
            lod: self.lod,
        })
    }
}

impl BenchOptions {
    /// Refuses combinations that would measure the wrong thing, and a report that would
    /// overwrite an input: before the store is opened.
    pub fn validate(&self) -> Result<()> {
        if !(self.error.is_finite() && self.error >= 0.0) {
            bail!("--error must be a finite number ≥ 0, got {}", self.error);
        }
        if self.compare == Some(0) {
            bail!("--compare K needs K ≥ 1 (every K-th frame)");
        }
        if self.shadows.is_some() && (self.reference || self.compare.is_some() || self.exact) {
            // The references are unshadowed full-detail frames: a PSNR against them would
            // measure the shadows, not the culling. The shadows' own check is the ray-traced
            // mask (tw-frame's `shadow_check` example).
            bail!("--light cannot be combined with --reference, --compare or --exact");
        }
        if self.shadows.is_some() && self.cull_server.is_some() {
            bail!("--light cannot be combined with --cull-server (the server culls the eye's view only)");
        }
        self.validate_pipelines()?;
        let inputs: Vec<&std::path::Path> =
            [Some(self.store.as_path()), self.path.as_deref()].into_iter().flatten().collect();
        for file in tw_report::ReportFiles::in_folder(&self.out).all() {
            tw_core::output::check_output(&file, &inputs)?;
        }
        Ok(())
    }

    /// Refuses parallel pipelines where a run draws something else than culled frames of the
    /// rasterizer, and strategies a pipeline cannot cull with.
    fn validate_pipelines(&self) -> Result<()> {
        if self.pipelines.is_empty() {
            bail!("--pipeline needs at least one of serial, gigawalk, switch");
        }
        let Some(parallel) = self.pipelines.iter().find(|p| **p != Pipeline::Serial) else {
            return Ok(());
        };
        let conflicts = [
            (self.reference, "--reference"),
            (self.ray_traced, "--renderer rt"),
            (self.popping, "--popping"),
            (self.shadows.is_some(), "--light"),
            (self.cull_server.is_some(), "--cull-server"),
        ];
        if let Some((_, flag)) = conflicts.iter().find(|(on, _)| *on) {
            bail!("--pipeline {} cannot be combined with {flag} (use --pipeline serial)", parallel.name());
        }
        for p in &self.pipelines {
            for o in self.occlusion.iter().flatten() {
                p.supports(*o).map_err(|e| anyhow::anyhow!(e))?;
            }
        }
        Ok(())
    }

    /// Every K-th frame gets a reference (and exact visibility): `compare`, or every 10th
    /// with `exact` alone.
    pub(crate) fn compared_every(&self) -> Option<usize> {
        self.compare.or(if self.exact { Some(10) } else { None })
    }
}
