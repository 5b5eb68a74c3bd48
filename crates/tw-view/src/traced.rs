//! The viewer's ray-traced mode (`view --renderer rt`): a [`TracedWalkthrough`] over the store
//! (the rasterizer's select-and-stream step, the same memory budget shared by the decoded pages
//! and the cluster BVHs) traces each frame on every core, and while the camera and the settings
//! stay the same each new frame adds one sample per pixel to the image shown
//! ([`crate::accumulate`]; Wald, Dietrich & Slusallek 2004: no antialiasing while moving,
//! supersampling added progressively when the camera stops).
//!
//! The accumulation starts again at one sample (the pixel centre) when anything the image
//! depends on changes: the camera, the pixel error, frustum culling, the colouring, the
//! flashlight, the shadows' light, the size, the highlighted object — and the traced cut
//! itself, which changes while streamed pages replace their coarser stand-ins (mixing samples
//! of two cuts would blur the refinement into a ghost).
//!
//! Shadows: the light the rasterizer's shadow maps use ([`crate::settings::ShadowControls`])
//! goes to tw-rt's shadow rays ([`TraceSettings::light`]), so switching renderers (G) keeps the
//! shadows; the traced cut then also holds the casters outside the view (tw-frame's traced
//! walkthrough), and the shadow-map options (size, cascades, cross-culling) do not apply.
//!
//! What the rasterized mode does on top of drawing is not all here: hidden and isolated objects
//! are still traced (a ray cannot skip a triangle of a hidden object without a per-triangle
//! mask in the tracer), and the cut is always selected from the drawing camera (no LOD freeze,
//! no separate culling camera in the debug view). Picking works: it casts its own rays into the
//! traced cut ([`crate::scene::Scene::pick_triangle`]).

use std::sync::Arc;

use tw_frame::traced::TracedWalkthrough;
use tw_frame::FrameSettings;
use tw_rt::scene::TraceSettings;
use tw_runtime::{Camera, Light, Selection, StreamOptions, Streamer};
use tw_store::Store;

use crate::accumulate::{sample_position, Accumulator, MAX_SAMPLES};
use crate::error::ViewError;
use crate::settings::{Coloring, Settings};

/// What the accumulated samples were traced from.
#[derive(Clone, Debug, PartialEq)]
struct TraceKey {
    camera: Camera,
    tau: f32,
    frustum: bool,
    coloring: Coloring,
    flashlight: bool,
    light: Option<Light>,
    size: [u32; 2],
    highlight: Option<u32>,
    /// A new section starts a new mean.
    section: tw_runtime::Section,
}

/// What one [`TracedScene::frame`] did.
#[derive(Clone, Debug)]
pub struct Traced {
    /// The frame's figures in the rasterizer's terms (BVH builds as `upload`, tracing and
    /// shading as `render`).
    pub info: tw_frame::FrameInfo,
    /// Samples per pixel in [`TracedScene::image`].
    pub samples: u32,
    /// Whether the image changed (a sample was added or the mean started again).
    pub changed: bool,
    /// Tinting and adding the sample to the mean.
    pub mean_ms: f32,
}

/// The ray-traced mode's state: the walkthrough and the running mean of its samples.
pub struct TracedScene {
    walk: TracedWalkthrough,
    size: [u32; 2],
    mean: Accumulator,
    key: Option<TraceKey>,
    /// The sample position of the next trace ([`sample_position`]).
    next: u32,
}

impl TracedScene {
    /// A ray-traced view of `store` at `size` pixels whose pages and BVHs keep within
    /// `memory_budget` bytes (tw-rt's split of it).
    pub fn new(store: Arc<Store>, size: [u32; 2], memory_budget: u64) -> Result<TracedScene, ViewError> {
        let options = StreamOptions { budget_bytes: memory_budget, ..Default::default() };
        let walk = TracedWalkthrough::new(store, (size[0], size[1]), options, TraceSettings::default())?;
        Ok(TracedScene { walk, size, mean: Accumulator::default(), key: None, next: 0 })
    }

    /// Traces one frame from `camera` at `size` (one more sample of the image while nothing
    /// changed, until [`MAX_SAMPLES`]; then only the cut is selected again, to see whether
    /// streamed pages changed it), tinting `highlight`'s pixels; `light`, if any, casts shadows
    /// (shadow rays).
    pub fn frame(
        &mut self,
        camera: &Camera,
        settings: &Settings,
        light: Option<Light>,
        size: [u32; 2],
        highlight: Option<u32>,
    ) -> Result<Traced, ViewError> {
        let key = TraceKey {
            camera: *camera,
            tau: settings.pixel_error,
            frustum: settings.frustum_culling,
            coloring: settings.coloring,
            flashlight: settings.flashlight,
            light,
            size,
            highlight,
            section: settings.section.section(),
        };
        if self.key.as_ref() != Some(&key) {
            self.mean.reset();
            self.next = 0;
            self.key = Some(key);
        }
        if size != self.size {
            self.walk.set_size((size[0], size[1]));
            self.size = size;
        }
        let complete = self.mean.samples() >= MAX_SAMPLES;
        let position = if complete { 0 } else { self.next };
        self.walk.trace = TraceSettings {
            coloring: settings.coloring.to_gpu(),
            flashlight: settings.flashlight,
            subpixel: sample_position(position),
            light,
            section: Default::default(),
        };
        let fs = FrameSettings {
            tau: settings.pixel_error,
            frustum_culling: settings.frustum_culling,
            wait_for_pages: false,
            section: settings.section.section(),
            ..Default::default()
        };
        let (mut image, info, traced) = self.walk.frame(camera, &fs)?;
        if traced.stats.tlas_rebuilt {
            // A new cut: its samples start a new mean (this one, wherever it lies, is the first).
            self.mean.reset();
        } else if complete {
            return Ok(Traced { info, samples: self.mean.samples(), changed: false, mean_ms: 0.0 });
        }
        let start = std::time::Instant::now();
        tint(&mut image.rgba, &traced.objects, highlight);
        self.mean.add(image.width, image.height, &image.rgba).ok_or_else(|| {
            ViewError::NoFrame(format!(
                "the ray tracer returned {} bytes for a {}x{} image",
                image.rgba.len(),
                image.width,
                image.height
            ))
        })?;
        self.next = position + 1;
        let mean_ms = start.elapsed().as_secs_f32() * 1e3;
        Ok(Traced { info, samples: self.mean.samples(), changed: true, mean_ms })
    }

    /// The image shown: the mean of the samples so far (RGBA, sRGB, premultiplied coverage).
    pub fn image(&self) -> &[u8] {
        self.mean.mean()
    }

    /// Samples per pixel in [`image`](Self::image).
    pub fn samples(&self) -> u32 {
        self.mean.samples()
    }

    /// Whether more samples would refine the image.
    pub fn refining(&self) -> bool {
        self.mean.samples() < MAX_SAMPLES
    }

    /// The last frame's cut.
    pub fn selection(&self) -> &Selection {
        self.walk.selection()
    }

    pub fn streamer(&self) -> &Streamer {
        self.walk.streamer()
    }
}

/// Tints the pixels that show `object` half-way to `tw_core::color::HIGHLIGHT` (the rasterizer
/// tints the object's colour before shading; here the shaded colour is tinted, which keeps the
/// shading).
fn tint(rgba: &mut [u8], objects: &[u32], object: Option<u32>) {
    let Some(h) = object else { return };
    for (p, _) in rgba.chunks_exact_mut(4).zip(objects).filter(|(p, &o)| o == h && p[3] != 0) {
        let tinted = tw_core::color::highlight([p[0], p[1], p[2], 255]);
        p[..3].copy_from_slice(&tinted[..3]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_highlighted_objects_pixels_are_tinted() {
        let mut rgba = vec![100, 100, 100, 255, 100, 100, 100, 255, 0, 0, 0, 0];
        let objects = [3, 4, 3];
        tint(&mut rgba, &objects, None);
        assert_eq!(rgba[..4], [100, 100, 100, 255]);
        tint(&mut rgba, &objects, Some(3));
        assert_eq!(rgba, [177, 120, 50, 255, 100, 100, 100, 255, 0, 0, 0, 0]);
    }
}
