//! `terawalk bench`: glue around tw-bench, the benchmark method (the runs per strategy, the
//! references, exact visibility, the records and the report). Here: the flags become its
//! options, the store is opened, the cull server is reached through tw-net's client, and its
//! account is printed (progress bars, each run's summary, the comparison, damaged pages).

mod summary;

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Result;
use indicatif::ProgressBar;
use tw_bench::{Bench, BenchOptions, Program};
use tw_frame::{FrameInfo, FrameSettings, Walkthrough};
use tw_gpu::Image;
use tw_report::{BenchReport, Run, RunKind};
use tw_runtime::Camera;
use tw_store::Store;

use crate::cli::{BenchArgs, OcclusionChoice, RendererChoice, SamplesChoice};
use crate::commands::cull_client::RemoteCulling;

/// What `run` measured, for callers such as `demo`.
pub struct BenchOutcome {
    pub html: PathBuf,
}

pub fn run(args: BenchArgs) -> Result<BenchOutcome> {
    let bench = Bench::new(options(&args))?;
    let store = crate::commands::open_store(&args.store)?;
    let wait = Duration::from_millis(args.cull_timeout_ms);
    let start_remote = |store: &Store| -> Box<dyn tw_bench::RemoteCulling> {
        let addr = args.cull_server.as_deref().unwrap_or_default();
        Box::new(RemoteCulling::start(addr, store, wait))
    };
    let outcome = bench.run(store, Some(&start_remote), &mut Printer { bar: None })?;
    outln!(
        "report: {} (open it in a browser), figures in {}",
        outcome.html.display(),
        outcome.json.display()
    );
    crate::commands::damage::check(&args.store, &outcome.failed_pages, args.allow_damaged)?;
    Ok(BenchOutcome { html: outcome.html })
}

/// The method's options from the flags.
fn options(args: &BenchArgs) -> BenchOptions {
    BenchOptions {
        store: args.store.clone(),
        path: args.path.clone(),
        frames: args.frames,
        out: args.out.clone(),
        size: args.frame.size,
        samples: match args.frame.samples {
            SamplesChoice::Auto => None,
            SamplesChoice::Is(n) => Some(n),
        },
        error: args.error,
        memory: args.memory,
        occlusion: args
            .occlusion
            .iter()
            .map(|o| match o {
                OcclusionChoice::Auto => None,
                OcclusionChoice::Is(o) => Some(*o),
            })
            .collect(),
        pipelines: args.pipeline.clone(),
        reference: args.reference,
        compare: args.compare,
        reference_samples: args.reference_samples,
        exact: args.exact,
        wait: args.wait,
        fit_memory: args.fit_memory,
        visible_pixels: args.visible_pixels,
        whole_clusters: args.whole_clusters,
        section_planes: args.section.planes.clone(),
        section_box: args.section.section_box,
        gpu_memory: args.gpu_memory,
        warmup: args.warmup,
        images: args.images,
        color: args.color.mode(),
        cull_server: args.cull_server.clone(),
        ray_traced: args.renderer == RendererChoice::Rt,
        flashlight: args.flashlight,
        popping: args.popping,
        transition: args.frame.transition,
        shadows: args.shadows.request(),
        program: Program {
            command_line: std::env::args().collect::<Vec<_>>().join(" "),
            version: env!("CARGO_PKG_VERSION").into(),
            // Set by build.rs: the short hash of the commit built (with "-dirty" when the
            // tracked sources differed from it), or "unknown".
            commit: env!("TERAWALK_COMMIT").into(),
        },
    }
}

/// Prints the benchmark's account: lines and summaries on standard output, progress bars on
/// standard error (when it is a terminal), memory traces in the log (`-v`, `-vv`).
struct Printer {
    bar: Option<ProgressBar>,
}

impl tw_bench::Observer for Printer {
    fn line(&mut self, text: &str) {
        outln!("{text}");
    }

    fn phase(&mut self, name: &str, total: u64) {
        self.bar = Some(crate::progress::count(total, name.to_string()));
    }

    fn frame_done(&mut self, name: &str, frame: usize, measured: bool) {
        if measured && tracing::enabled!(tracing::Level::DEBUG) {
            tracing::debug!("{name} frame {frame}: {}", summary::memory_now());
        }
        if let Some(bar) = &self.bar {
            bar.inc(1);
        }
    }

    fn end_phase(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }

    fn run_done(&mut self, run: &Run, network: &[(String, String)]) {
        summary::print_run(run);
        for (key, value) in network {
            outln!("{:>10}: {key}: {value}", "network");
        }
        if run.kind != RunKind::Reference {
            tracing::info!("after {}: {}", run.name, summary::memory_now());
        }
    }

    fn report_done(&mut self, report: &BenchReport) {
        summary::print_comparison(report);
    }
}

/// `--cull-server`'s frames for the method, through tw-net's client.
impl tw_bench::RemoteCulling for RemoteCulling {
    fn frame(
        &mut self,
        walk: &mut Walkthrough,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<(Image, FrameInfo)> {
        RemoteCulling::frame(self, walk, camera, settings)
    }

    fn take_lines(&mut self, run: &str) -> Vec<(String, String)> {
        self.take_totals().lines(run)
    }
}
