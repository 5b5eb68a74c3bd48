//! The measured runs: one per occlusion strategy (with `shadows`, each with and without them),
//! all in one process so that their ratios are measured under the same conditions, each over
//! the whole path after `warmup` frames at the first camera.

use anyhow::Result;
use tw_frame::traced::TracedWalkthrough;
use tw_frame::{FrameInfo, FrameSettings, Occlusion, Pipeline, ShadowSettings, Walkthrough};
use tw_gpu::Image;
use tw_report::{FrameRecord, ReportImage, Run};
use tw_runtime::Camera;

use crate::path::Frames;
use crate::record::{light_name, record};
use crate::references::References;
use crate::traced::ColdStart;
use crate::{BenchOptions, Observer, RemoteCulling};

/// One run to measure: a strategy, with or without shadows, through a pipeline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plan {
    pub occlusion: Occlusion,
    pub shadowed: bool,
    pub pipeline: Pipeline,
}

/// The runs, in order: each strategy with shadows, then without, when there is a light (their
/// ratio is the shadows' cost, measured in the same process on the same frames); the ray
/// tracer's one run casts shadow rays when there is a light (it has no strategies to compare).
/// Each of those through every pipeline in turn (shadows and the ray tracer only serial:
/// [`BenchOptions::validate`](crate::BenchOptions::validate) refuses the others).
pub fn plans(strategies: &[Occlusion], shadows: bool, traced: bool, pipelines: &[Pipeline]) -> Vec<Plan> {
    let both: &[bool] = match (shadows, traced) {
        (true, false) => &[true, false],
        (true, true) => &[true],
        (false, _) => &[false],
    };
    strategies
        .iter()
        .flat_map(|&occlusion| {
            both.iter().flat_map(move |&shadowed| {
                pipelines.iter().map(move |&pipeline| Plan { occlusion, shadowed, pipeline })
            })
        })
        .collect()
}

/// Run `index`'s name. A strategy given again (`--occlusion none,queries,none`: does memory
/// come back down?) is a run of its own, "none #2": the report's runs have distinct names.
pub fn name(plans: &[Plan], index: usize, reference: bool, traced: bool) -> String {
    let plan = plans[index];
    let repeat = plans[..index].iter().filter(|&&p| p == plan).count();
    let mut base = if plan.shadowed {
        format!("{}+shadows", plan.occlusion.name())
    } else {
        plan.occlusion.name().to_string()
    };
    if plan.pipeline != Pipeline::Serial {
        base = format!("{base} {}", plan.pipeline.name());
    }
    match (reference, repeat) {
        _ if traced => "rt".to_string(),
        (true, _) => "reference".to_string(),
        (false, 0) => base,
        (false, k) => format!("{base} #{}", k + 1),
    }
}

/// What the runs draw with, and what they collect on the way.
pub struct Runner<'a> {
    pub options: &'a BenchOptions,
    pub walk: Walkthrough,
    /// `ray_traced`: the ray tracer's walkthrough and its cold start.
    pub traced: Option<(TracedWalkthrough, ColdStart)>,
    pub remote: Option<Box<dyn RemoteCulling>>,
    pub frames: &'a Frames,
    pub references: &'a References,
    pub shadows: Option<ShadowSettings>,
    /// The section every run culls and clips by (scene space).
    pub section: tw_runtime::Section,
    /// The frames of the first run embedded in the report as pictures.
    pub image_frames: Vec<usize>,
    pub images: Vec<ReportImage>,
    /// `cull_server`: every run's network figures, for the report's header.
    pub net_lines: Vec<(String, String)>,
}

impl Runner<'_> {
    /// Measures run `index` of `plan` named `name`.
    pub fn measure(
        &mut self,
        index: usize,
        plan: Plan,
        name: String,
        observer: &mut dyn Observer,
    ) -> Result<Run> {
        let settings = self.settings(plan);
        let count = self.frames.cameras.len();
        observer.phase(&name, count as u64);
        let records = if plan.pipeline == Pipeline::Serial {
            self.warm_up(&settings)?;
            let mut records = Vec::with_capacity(count);
            for i in 0..count {
                records.push(self.measured_frame(index, &name, i, &settings, observer)?);
                observer.frame_done(&name, i, true);
            }
            records
        } else {
            self.measure_pipelined(index, plan.pipeline, &name, &settings, observer)?
        };
        observer.end_phase();
        let run = Run::new(name, self.description(plan), records, tw_report::peak_rss_bytes());
        let network = self.remote.as_mut().map(|r| r.take_lines(&run.name)).unwrap_or_default();
        observer.run_done(&run, &network);
        self.net_lines.extend(network);
        Ok(run)
    }

    /// The frames' settings of a run.
    fn settings(&self, plan: Plan) -> FrameSettings {
        let o = self.options;
        FrameSettings {
            tau: o.error,
            frustum_culling: true,
            occlusion: plan.occlusion,
            wait_for_pages: o.wait,
            visible_pixels: o.visible_pixels,
            triangle_culling: !o.whole_clusters,
            shadows: if plan.shadowed { self.shadows } else { None },
            section: self.section,
            transition: o.transition,
        }
    }

    /// A run through a parallel pipeline: `warmup` frames at the first camera, then the path,
    /// keeping every stage busy ([`Pipeline::depth`] frames in flight). A frame's time is the
    /// interval since the frame before came out (the pipeline's throughput); its latency, from
    /// its camera going in to its image read back, is recorded beside it.
    fn measure_pipelined(
        &mut self,
        index: usize,
        pipeline: Pipeline,
        name: &str,
        settings: &FrameSettings,
        observer: &mut dyn Observer,
    ) -> Result<Vec<FrameRecord>> {
        self.walk.reset();
        let Runner { options, walk, frames, references, image_frames, images, .. } = self;
        let frames: &Frames = frames;
        let warmup = options.warmup;
        let cameras: Vec<&Camera> =
            std::iter::repeat_n(&frames.cameras[0], warmup).chain(&frames.cameras).collect();
        walk.pipelined(pipeline, settings, |pipe| -> Result<Vec<FrameRecord>> {
            let mut records = Vec::with_capacity(frames.cameras.len());
            let (mut next, mut last) = (0, std::time::Instant::now());
            for k in 0..cameras.len() {
                while next < cameras.len() && pipe.in_flight() < pipeline.depth() as u64 {
                    pipe.submit(cameras[next])?;
                    next += 1;
                }
                let out = pipe.receive()?;
                let interval = last.elapsed();
                last = std::time::Instant::now();
                let Some(i) = k.checked_sub(warmup) else { continue };
                let (image, mut info) = (out.image, out.info);
                let latency = info.times.total;
                info.times.total = interval;
                let mut pictures = Pictures { index, name, frames: image_frames, images };
                let tau = settings.tau as f64;
                let mut rec =
                    framed_record(options, frames, references, &mut pictures, i, &image, &info, tau)?;
                rec.latency_ms = Some(latency.as_secs_f64() * 1e3);
                records.push(rec);
                observer.frame_done(name, i, true);
            }
            Ok(records)
        })?
    }

    /// A run's start: the caches emptied, then `warmup` frames at the first camera to fill
    /// them, whose network figures are not the run's.
    fn warm_up(&mut self, settings: &FrameSettings) -> Result<()> {
        self.walk.reset();
        if let Some((t, _)) = self.traced.as_mut() {
            t.reset();
        }
        let frames = self.frames;
        for _ in 0..self.options.warmup {
            self.frame(&frames.cameras[0], settings)?;
        }
        if let Some(r) = &mut self.remote {
            // Dropped: the warm-up frames' figures are not the run's.
            r.take_lines("");
        }
        Ok(())
    }

    /// Frame `i` of run `index` (`name`), measured and compared.
    fn measured_frame(
        &mut self,
        index: usize,
        name: &str,
        i: usize,
        settings: &FrameSettings,
        observer: &mut dyn Observer,
    ) -> Result<FrameRecord> {
        let o = self.options;
        let frames = self.frames;
        let camera = &frames.cameras[i];
        let previous = (o.popping && i > 0).then(|| self.walk.drawn_state());
        let (image, info) = self.frame(camera, settings)?;
        if let (0, Some((_, cold))) = (i, &self.traced) {
            if let Some(line) = cold.report(image.covered_pixels()) {
                observer.line(&line);
            }
        }
        // The reference draws full detail (τ = 0): no model of what it needs.
        let tau = if o.reference { 0.0 } else { settings.tau as f64 };
        let mut pictures = Pictures { index, name, frames: &self.image_frames, images: &mut self.images };
        let mut rec = framed_record(o, frames, self.references, &mut pictures, i, &image, &info, tau)?;
        if o.popping {
            self.popping(&mut rec, camera, previous)?;
        }
        Ok(rec)
    }

    /// `popping`: the pixels the LOD alone changes between the previous frame's cut and this
    /// one's, at this frame's camera (none on the first frame).
    fn popping(
        &mut self,
        rec: &mut FrameRecord,
        camera: &Camera,
        previous: Option<tw_frame::DrawnState>,
    ) -> Result<()> {
        let change = match &previous {
            Some(previous) => Some(self.walk.lod_change(camera, previous)?),
            None => None,
        };
        rec.popping_changed_pixels = Some(change.map_or(0.0, |c| c.changed_pixels));
        rec.popping_psnr_db = change.and_then(|c| c.psnr_db).map(|p| p.min(99.0));
        Ok(())
    }

    /// One frame: the reference, or ray traced, or through the remote culling, or culled here.
    fn frame(&mut self, camera: &Camera, settings: &FrameSettings) -> Result<(Image, FrameInfo)> {
        if let Some((t, _)) = self.traced.as_mut() {
            let (image, info, _) = t.frame(camera, settings)?;
            return Ok((image, info));
        }
        Ok(match self.remote.as_mut() {
            _ if self.options.reference => self.walk.reference(camera)?,
            Some(r) => r.frame(&mut self.walk, camera, settings)?,
            None => self.walk.frame(camera, settings)?,
        })
    }

    /// What a run is, for the report.
    fn description(&self, plan: Plan) -> String {
        let o = self.options;
        if let Some((t, _)) = &self.traced {
            let light = match (plan.shadowed, &self.shadows) {
                (true, Some(s)) => format!(", shadow rays of the {}", light_name(&s.light)),
                _ => String::new(),
            };
            format!(
                "ray traced on the CPU (tw-rt, {} threads{}{light}), LOD cut at {} px, frustum culling",
                tw_rt::scene::StoreTracer::threads(),
                if t.trace.flashlight { ", flashlight with hard shadows" } else { "" },
                o.error
            )
        } else if o.reference {
            "full detail, no culling (τ = 0, frustum and occlusion culling off)".to_string()
        } else {
            self.culled_description(plan)
        }
    }

    /// What a rasterized, culled run is: its strategy and its options.
    fn culled_description(&self, plan: Plan) -> String {
        let o = self.options;
        let cutoff = if plan.occlusion == Occlusion::Queries && o.visible_pixels > 0 {
            format!(", visible-pixel cut-off {} samples (approximate)", o.visible_pixels)
        } else if plan.occlusion == Occlusion::Hzb && o.whole_clusters {
            ", visible clusters drawn whole (no triangle tests)".to_string()
        } else {
            String::new()
        };
        let shadows = match (plan.shadowed, &self.shadows) {
            (true, Some(s)) => format!(
                ", shadows: {} ({} texels, cross-culling {}, {} LOD)",
                light_name(&s.light),
                s.options.size,
                if s.cross_culling { "on" } else { "off" },
                s.lod.name()
            ),
            _ => String::new(),
        };
        let pipeline = match plan.pipeline {
            Pipeline::Serial => String::new(),
            p => format!("; {} (frame time = throughput, latency recorded)", p.description()),
        };
        let transition = match o.transition {
            tw_frame::Transition::Pop => String::new(),
            t => format!(", LOD switches cross-faded ({})", t.name()),
        };
        format!(
            "LOD cut at {} px, frustum culling, occlusion culling: {}{cutoff}{shadows}{transition}{pipeline}",
            o.error,
            plan.occlusion.name()
        )
    }
}

/// Where a run's frames become the report's pictures: run `index` (only the first run's
/// frames are kept), named `name`, at the frames `frames`.
struct Pictures<'a> {
    index: usize,
    name: &'a str,
    frames: &'a [usize],
    images: &'a mut Vec<ReportImage>,
}

/// Frame `i`'s record from its image and figures: coverage at pixel error `tau`, the picture
/// when it is one, and (except for the reference run) the comparison with its reference.
#[allow(clippy::too_many_arguments)]
fn framed_record(
    options: &BenchOptions,
    frames: &Frames,
    references: &References,
    pictures: &mut Pictures<'_>,
    i: usize,
    image: &Image,
    info: &FrameInfo,
    tau: f64,
) -> Result<FrameRecord> {
    let segment = &frames.segments[i];
    let mut rec = record(i, segment, info);
    rec.set_coverage(image.covered_pixels() as u64, tau);
    if pictures.index == 0 && pictures.frames.contains(&i) {
        let caption = format!("{}, frame {i} ({segment})", pictures.name);
        pictures.images.push(ReportImage { caption, png: image.png_bytes()? });
    }
    if !options.reference {
        references.compare(&mut rec, i, image, info)?;
    }
    Ok(rec)
}
