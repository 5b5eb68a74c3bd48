//! The benchmark method of `terawalk bench`: renders a camera path headless through the frame
//! pipeline (tw-frame) and writes a self-contained report (tw-report: index.html with SVG
//! plots, report.json with every figure). The program parses flags and prints; the method,
//! what is run and measured, lives here (docs/DESIGN.md, "Measuring").
//!
//! Runs, all in one process so that their ratios are measured under the same conditions:
//! - one run per `occlusion` strategy, each over the whole path after `warmup` frames at the
//!   first camera (`runs.rs`);
//! - `reference`: the main run is the reference itself (full detail, no culling);
//! - `compare: K`: every K-th frame is also rendered as the reference (once, before the runs,
//!   so that its full-detail draws do not empty the caches in the middle of one:
//!   `references.rs`); every run's records of those frames get PSNR and the share of differing
//!   pixels, and a "reference" run holds the reference frame times (same frames), so the
//!   speed-up is a ratio of the same frames;
//! - `reference_samples: N` (with `compare`): the compared frames' references are also
//!   rendered supersampled, N samples per pixel (tw-frame's `supersample`), and every run's
//!   compared frames get their PSNR against it beside the brute-force frame's (the 1-sample
//!   reference above, at the run's samples) and the difference: what the LOD loses, apart from
//!   the aliasing both share;
//! - `exact`: on the same frames, the item buffer at full detail gives the exact visible
//!   objects and triangles, and every run's culling efficiency (drawn ÷ exact visible).
//!
//! Every frame also gets its LOD efficiency (tw_report::lod): the cut's triangles against the
//! triangles a screen can use at ε over the pixels the model covers. The coverage is counted on
//! the colour image the frame reads back anyway (alpha ≠ 0 where geometry was drawn), after the
//! frame's clock has stopped: no extra readback, and the count is not in the frame time.
//!
//! Errors are `anyhow` errors: they are only ever reported to a person, as the chain of what
//! failed and why, and they name `terawalk bench`'s flags.

mod meta;
mod observe;
mod options;
mod path;
mod record;
mod references;
mod runs;
mod traced;

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Result;
use tw_frame::{Occlusion, Walkthrough};
use tw_gpu::Renderer;
use tw_report::{BenchReport, DamagedPage, FrameRecord, Run, RunKind};
use tw_runtime::StreamOptions;
use tw_store::Store;

pub use observe::{Observer, RemoteCulling, Silent, StartRemote};
pub use options::{BenchOptions, Program, ShadowRequest};

use meta::Measured;
use path::Frames;
use references::References;
use runs::Runner;

/// What a benchmark produced.
pub struct Outcome {
    /// The report's files.
    pub html: PathBuf,
    pub json: PathBuf,
    /// Store pages that failed their checksum or decoding while the frames drew (page, error):
    /// the report lists them; the caller decides whether that fails it.
    pub failed_pages: Vec<(u32, String)>,
}

/// A benchmark whose options were checked ([`Bench::new`]), ready to run on its store.
pub struct Bench {
    options: BenchOptions,
}

impl Bench {
    /// Checks `options` (see [`BenchOptions::validate`]) before anything is opened.
    pub fn new(options: BenchOptions) -> Result<Bench> {
        options.validate()?;
        Ok(Bench { options })
    }

    /// Runs the benchmark on `store` (the store `options.store` names) and writes the report:
    /// the path, the walkthrough, the references, the runs, the report. With `cull_server`,
    /// `start_remote` connects the frames to it.
    pub fn run(
        &self,
        store: Store,
        start_remote: Option<StartRemote<'_>>,
        observer: &mut dyn Observer,
    ) -> Result<Outcome> {
        let o = &self.options;
        let store_bytes = std::fs::metadata(&o.store).map(|m| m.len()).unwrap_or(0);
        let input_triangles = store.header().input_triangles;
        let frames = Frames::of(o, &store, observer)?;
        let (mut walk, adapter, samples) = self.walkthrough(store, observer)?;
        let traced = if o.ray_traced {
            Some(traced::traced_walkthrough(o, walk.store().clone(), &frames.cameras[0], observer)?)
        } else {
            None
        };
        let strategies = self.strategies(&walk, traced.is_some());
        let header = walk.store().header().clone();
        let shadows = o
            .shadows
            .as_ref()
            .map(|s| s.settings(&header, header.up_axis, &frames.cameras[0]))
            .transpose()?;
        let remote = match (&o.cull_server, start_remote) {
            (Some(_), Some(start)) => Some(start(walk.store().as_ref())),
            (Some(addr), None) => anyhow::bail!("cull server {addr}: no way to reach it was given"),
            (None, _) => None,
        };
        let section = tw_runtime::Section::to_scene(&o.section_planes, o.section_box, header.grid_origin)?;
        let mut references = References::make(o, &mut walk, &frames, observer)?;
        let reference_records = std::mem::take(&mut references.records);
        let runner = Runner {
            options: o,
            walk,
            traced,
            remote,
            frames: &frames,
            references: &references,
            shadows,
            section,
            image_frames: meta::image_frames(frames.cameras.len(), o.images),
            images: Vec::new(),
            net_lines: Vec::new(),
        };
        let measured = Measured {
            adapter,
            samples,
            frames: frames.cameras.len(),
            store_bytes,
            input_triangles,
            net_lines: Vec::new(),
        };
        self.runs_and_report(runner, strategies, reference_records, measured, observer)
    }

    /// The rasterizer's walkthrough of `store` at the options' size, samples, budgets and
    /// colours; the adapter's summary and the samples per pixel it draws.
    fn walkthrough(&self, store: Store, observer: &mut dyn Observer) -> Result<(Walkthrough, String, u32)> {
        let o = &self.options;
        let mut renderer = Renderer::new_headless(o.size.0, o.size.1)?;
        renderer.set_gpu_budget(o.gpu_memory);
        if renderer.gpu_budget() + (64 << 10) < o.gpu_memory {
            observer.line(&format!(
                "note: GPU budget {} MiB, the most one buffer can hold on this device (asked for {} MiB)",
                renderer.gpu_budget() >> 20,
                o.gpu_memory >> 20
            ));
        }
        let adapter = renderer.adapter_summary();
        observer.line(&format!("adapter: {adapter}"));
        let samples = o.samples.unwrap_or_else(|| renderer.default_samples());
        renderer.set_samples(samples)?;
        if o.reference_samples > 1 {
            // Before any frame: a supersampled target the device cannot hold fails now, not
            // after the first reference.
            tw_frame::supersample::check_grid(&renderer, o.reference_samples)?;
        }
        let stream = StreamOptions { budget_bytes: o.memory, fit_budget: o.fit_memory, ..Default::default() };
        let mut walk = Walkthrough::new(Arc::new(store), renderer, stream)?;
        walk.set_color_mode(o.color);
        Ok((walk, adapter, samples))
    }

    /// The strategies to run: none for the reference and the ray tracer, else those asked for
    /// (`None`: the fastest conservative one on this device that every `--pipeline` asked for
    /// can cull with: `hzb` where that is `gpu-hzb` and a pipeline cannot run it).
    fn strategies(&self, walk: &Walkthrough, traced: bool) -> Vec<Occlusion> {
        if self.options.reference || traced {
            return vec![Occlusion::None];
        }
        let fastest = || {
            let device = Occlusion::fastest_for(walk.renderer());
            let all_run = self.options.pipelines.iter().all(|p| p.supports(device).is_ok());
            if all_run {
                device
            } else {
                Occlusion::Hzb
            }
        };
        self.options.occlusion.iter().map(|o| o.unwrap_or_else(fastest)).collect()
    }

    /// Measures every run, then the references' own run, and writes the report.
    fn runs_and_report(
        &self,
        mut runner: Runner<'_>,
        strategies: Vec<Occlusion>,
        reference_records: Vec<FrameRecord>,
        mut measured: Measured,
        observer: &mut dyn Observer,
    ) -> Result<Outcome> {
        let o = &self.options;
        let traced = runner.traced.is_some();
        let plans = runs::plans(&strategies, runner.shadows.is_some(), traced, &o.pipelines);
        let mut runs = Vec::new();
        for (index, &plan) in plans.iter().enumerate() {
            let name = runs::name(&plans, index, o.reference, traced);
            runs.push(runner.measure(index, plan, name, observer)?);
        }
        if !reference_records.is_empty() {
            // Reference renderings, not walkthrough frames: in the summary (the speed-up
            // against the reference is a ratio of the same frames), out of the per-frame
            // plots, where one full-detail frame of seconds would flatten the walkthroughs'
            // milliseconds.
            let run = Run::new(
                "reference",
                "full detail, no culling, on the compared frames",
                reference_records,
                tw_report::peak_rss_bytes(),
            )
            .with_kind(RunKind::Reference);
            observer.run_done(&run, &[]);
            runs.push(run);
        }
        measured.net_lines = std::mem::take(&mut runner.net_lines);
        let mut report = BenchReport::new(meta::meta(o, measured), runs);
        let failed = runner.walk.streamer().cache().failed_pages();
        report.damaged_pages =
            failed.iter().map(|(page, error)| DamagedPage { page: *page, error: error.clone() }).collect();
        observer.report_done(&report);
        let files = tw_report::write_report(&o.out, &report, &runner.images)?;
        Ok(Outcome { html: files.html, json: files.json, failed_pages: failed })
    }
}
