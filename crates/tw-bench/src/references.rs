//! What every run is compared with, made once before the runs: the full-detail reference of
//! every K-th frame (PNG-compressed: 0.1–1 MB a frame instead of 3.7), its supersampled truth
//! (`reference_samples`), and the exact visible sets (`exact`). They depend on the camera only;
//! made before the runs, their full-detail draws do not empty the page cache and the GPU pool
//! in the middle of a measured run (the frames after a reference would start cold: a coarser
//! cut, a slower frame).

use std::collections::HashMap;
use std::time::{Duration, Instant};

use anyhow::Result;
use tw_frame::{ExactVisibility, FrameInfo, Walkthrough};
use tw_gpu::Image;
use tw_report::FrameRecord;
use tw_runtime::Camera;

use crate::path::Frames;
use crate::record::record;
use crate::{BenchOptions, Observer};

/// The references of the compared frames, by frame.
#[derive(Default)]
pub struct References {
    /// Every K-th frame's reference, or none without `compare`/`exact` (or with `reference`).
    pub every: Option<usize>,
    /// The reference renderings' own records (the "reference" run: times of the same frames).
    pub records: Vec<FrameRecord>,
    /// `compare`: the reference images, PNG.
    images: HashMap<usize, Vec<u8>>,
    /// `exact`: the visible sets at full detail and of the frame's own LOD cut.
    exacts: HashMap<usize, (ExactVisibility, ExactVisibility)>,
    /// `reference_samples`: the supersampled truths.
    truths: HashMap<usize, Truth>,
}

impl References {
    /// Renders the references `options` asks for, every K-th frame.
    pub fn make(
        options: &BenchOptions,
        walk: &mut Walkthrough,
        frames: &Frames,
        observer: &mut dyn Observer,
    ) -> Result<References> {
        let every = options.compared_every();
        let mut refs = References { every, ..Default::default() };
        let Some(k) = every.filter(|_| !options.reference) else { return Ok(refs) };
        let compared: Vec<usize> = (0..frames.cameras.len()).step_by(k).collect();
        observer.phase("reference", compared.len() as u64);
        let mut truth_time = Duration::ZERO;
        for &i in &compared {
            truth_time += refs.add(options, walk, frames, i)?;
            observer.frame_done("reference", i, false);
        }
        observer.end_phase();
        if !refs.truths.is_empty() {
            observer.line(&format!(
                "{:>10}: {} supersampled references ({} samples per pixel) in {:.1} s",
                "reference",
                refs.truths.len(),
                options.reference_samples,
                truth_time.as_secs_f64()
            ));
        }
        Ok(refs)
    }

    /// Frame `i`'s references; returns the time its supersampled truth took.
    fn add(
        &mut self,
        options: &BenchOptions,
        walk: &mut Walkthrough,
        frames: &Frames,
        i: usize,
    ) -> Result<Duration> {
        let camera = &frames.cameras[i];
        let (reference, info) = walk.reference(camera)?;
        self.records.push(record(i, &frames.segments[i], &info));
        let mut truth_time = Duration::ZERO;
        if options.compare.is_some() {
            if options.reference_samples > 1 {
                let start = Instant::now();
                self.truths.insert(i, Truth::of(walk, camera, &reference, options.reference_samples)?);
                truth_time = start.elapsed();
            }
            self.images.insert(i, reference.png_bytes()?);
        }
        if options.exact {
            let full = walk.exact_visibility(camera)?;
            self.exacts.insert(i, (full, walk.exact_visibility_of_cut(camera, options.error)?));
        }
        Ok(truth_time)
    }

    /// Sets a run's record `rec` of frame `i` (its `image`, its `info`) against the frame's
    /// references, if it has any.
    pub fn compare(&self, rec: &mut FrameRecord, i: usize, image: &Image, info: &FrameInfo) -> Result<()> {
        if self.every.is_none_or(|k| !i.is_multiple_of(k)) {
            return Ok(());
        }
        if let Some(png) = self.images.get(&i) {
            let (reference, image) = (Image::from_png_bytes(png)?, image.to_opaque());
            rec.psnr_db = Some(image.psnr(&reference)?.min(99.0));
            rec.differing_pixels = Some(image.differing_share(&reference)?);
        }
        if let Some(truth) = self.truths.get(&i) {
            truth.record(rec, image)?;
        }
        if let Some((exact, of_cut)) = self.exacts.get(&i) {
            rec.exact_visible_triangles = Some(exact.triangles);
            rec.exact_visible_objects = Some(exact.objects);
            rec.cut_visible_triangles = Some(of_cut.triangles);
            rec.cut_efficiency = Some(info.triangles as f64 / of_cut.triangles.max(1) as f64);
            rec.culling_efficiency = Some(info.triangles as f64 / exact.triangles.max(1) as f64);
            rec.test_efficiency = Some(info.masked_triangles as f64 / exact.triangles.max(1) as f64);
        }
        Ok(())
    }
}

/// `reference_samples`: the ground truth of one compared frame, its full-detail reference
/// supersampled (PNG-compressed, like the 1-sample references), and the brute-force frame's
/// PSNR against it.
struct Truth {
    png: Vec<u8>,
    brute_force_psnr_db: f64,
}

impl Truth {
    /// The truth of `camera`, whose 1-sample full-detail reference (at the run's samples) is
    /// `brute_force`.
    fn of(walk: &mut Walkthrough, camera: &Camera, brute_force: &Image, samples: u32) -> Result<Truth> {
        let truth = walk.reference_supersampled(camera, samples)?;
        Ok(Truth { brute_force_psnr_db: brute_force.psnr(&truth)?.min(99.0), png: truth.png_bytes()? })
    }

    /// Sets `rec`'s figures against the truth for its frame's `image`: the frame's PSNR, the
    /// brute-force frame's, and their difference (both capped at 99 dB as `psnr_db` is).
    fn record(&self, rec: &mut FrameRecord, image: &Image) -> Result<()> {
        let truth = Image::from_png_bytes(&self.png)?;
        let lod = image.psnr(&truth)?.min(99.0);
        rec.supersampled_psnr_db = Some(lod);
        rec.brute_force_psnr_db = Some(self.brute_force_psnr_db);
        rec.psnr_gap_db = Some(lod - self.brute_force_psnr_db);
        Ok(())
    }
}
