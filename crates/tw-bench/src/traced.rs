//! The ray tracer's benchmark (`ray_traced`): its walkthrough, and how its first frames fare
//! after a cold start.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Result;
use tw_frame::traced::TracedWalkthrough;
use tw_frame::FrameSettings;
use tw_rt::scene::TraceSettings;
use tw_runtime::{Camera, StreamOptions};

use crate::{BenchOptions, Observer};

/// The first ray-traced frames after a cold start (a page cache holding the root pages only),
/// all of the first camera: when each was complete and how many pixels it covered, to tell when
/// the image became recognisable against the first measured (warm) frame of the same camera.
pub struct ColdStart {
    frames: Vec<(Duration, usize)>,
}

/// Frames [`ColdStart`] traces: the streamer loads a walk's first view within a few.
const COLD_FRAMES: usize = 8;

impl ColdStart {
    /// The line that compares the cold frames with the warm frame's `warm_covered` pixels.
    pub fn report(&self, warm_covered: usize) -> Option<String> {
        let share = |covered: usize| 100.0 * covered as f64 / warm_covered.max(1) as f64;
        let &(first, covered) = self.frames.first()?;
        let mut line = format!(
            "cold start: first ray-traced image after {:.0} ms covering {:.1} % of what the warm frame covers",
            first.as_secs_f64() * 1e3,
            share(covered)
        );
        match self.frames.iter().find(|&&(_, c)| share(c) >= 95.0) {
            Some((t, c)) => {
                line += &format!("; ≥ 95 % ({:.1} %) after {:.0} ms", share(*c), t.as_secs_f64() * 1e3)
            }
            None => line += &format!("; under 95 % for its first {} frames", self.frames.len()),
        }
        Some(line)
    }
}

/// The ray tracer's walkthrough, with its first frames timed from a cold start.
pub fn traced_walkthrough(
    options: &BenchOptions,
    store: Arc<tw_store::Store>,
    first: &Camera,
    observer: &mut dyn Observer,
) -> Result<(TracedWalkthrough, ColdStart)> {
    let start = Instant::now();
    let stream = StreamOptions { budget_bytes: options.memory, ..Default::default() };
    let trace =
        TraceSettings { coloring: options.color, flashlight: options.flashlight, ..Default::default() };
    let mut traced = TracedWalkthrough::new(store, options.size, stream, trace)?;
    let settings = FrameSettings { tau: options.error, wait_for_pages: options.wait, ..Default::default() };
    let mut cold = ColdStart { frames: Vec::with_capacity(COLD_FRAMES) };
    for _ in 0..COLD_FRAMES {
        let (image, ..) = traced.frame(first, &settings)?;
        cold.frames.push((start.elapsed(), image.covered_pixels()));
    }
    observer.line(&format!("renderer: CPU ray tracer, {} threads", tw_rt::scene::StoreTracer::threads()));
    Ok((traced, cold))
}
