//! A cut that fits the page cache (docs/DESIGN.md, D4): when the pages a streamed frame's cut
//! draws from and asks for would not fit the cache's budget, the pixel error threshold is raised
//! for the next frames until they do, and lowered back toward the asked-for τ when there is room.
//!
//! **Why.** A cut whose pages exceed the budget thrashes: the loads a frame asks for evict pages
//! the same cut draws, which the next frame asks for again. The 10^9-triangle plant walked at
//! `--memory 1G` loaded and evicted ~1,400 pages a frame and ran at 1.8 fps (BENCHMARKS.md,
//! "Build as a plan of jobs, and 10^9 triangles"), and the availability rule drew random groups
//! from coarse ancestors. A uniformly coarser cut that fits looks better and streams nothing once
//! settled. Nanite's streaming pool does the same when it is overcommitted (it lowers the
//! quality until the requests fit).
//!
//! **The controller.** After each frame, `fill` = (the decoded bytes of the pages the frame
//! used — drawn from, or looked up on the way down to the cut — and the pinned root pages, +
//! the decoded sizes the store records for the pages it asked for) ÷ the budget
//! ([`crate::PageCache::frame_bytes`]; pages the loaders brought in during the frame count too). A cut's
//! bytes fall about as τ⁻² (a surface's triangles at pixel error τ), so above [`HIGH`] the scale
//! of τ is multiplied by `√(fill / TARGET)` (at least [`MIN_STEP`], at most [`MAX_RISE`] a
//! frame); below [`LOW`], in a frame that asked for no page, it is divided by at most
//! [`MAX_FALL`] a frame, never below 1. The band between keeps a settled cut from oscillating,
//! and the slow fall keeps a frame from asking for much more than the last one held. A frame
//! that still asks for pages never lowers τ: its fill counts only the frontier it asks for, not
//! the pages the cut will need below it — and when loads evict pages the cut draws from, the
//! next cut falls back to coarse ancestors and looks small (measured on a plant of small
//! pages: cuts alternating between the root pages and 20 times more, the scale rising and
//! falling with them). Only [`crate::Streamer::frame`] and the light views of the
//! same frame use the raised τ: the waiting mode ([`crate::Streamer::select_blocking`]: `bench
//! --wait`, `render`, the references) is the render rule's exact cut at the asked-for τ.

/// Above this share of the budget the next frame's τ rises. A cut within the budget does not
/// thrash (loads evict the pages outside the frame first, and prefetched pages only those), so
/// the margin is only for the next frames' movement: at 0.85 the 10^8 fly-over at
/// `--memory 512M`, which streams nothing once settled, was coarsened by ×1.2–1.3 for nothing.
pub const HIGH: f64 = 0.95;
/// The share a rise aims at.
pub const TARGET: f64 = 0.85;
/// Below this share τ falls back toward the asked-for one.
pub const LOW: f64 = 0.6;
/// The smallest rise, so that a fill just above [`HIGH`] still moves.
pub const MIN_STEP: f64 = 1.02;
/// The largest rise in one frame.
pub const MAX_RISE: f64 = 2.0;
/// The largest fall in one frame.
pub const MAX_FALL: f64 = 1.05;
/// The largest scale: beyond it the cut is the root pages' anyway.
pub const MAX_SCALE: f64 = 4096.0;

/// The scale of τ that keeps a streamed cut within the cache (module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CacheFit {
    scale: f64,
}

impl Default for CacheFit {
    fn default() -> Self {
        CacheFit { scale: 1.0 }
    }
}

impl CacheFit {
    /// The factor τ is multiplied by (≥ 1).
    pub fn scale(&self) -> f32 {
        self.scale as f32
    }

    /// The τ to select with when `tau` was asked for.
    pub fn tau(&self, tau: f32) -> f32 {
        (tau as f64 * self.scale) as f32
    }

    /// Updates the scale from a frame whose cut needed `need` bytes of a `budget` and
    /// `asked` for missing pages or not.
    pub fn update(&mut self, need: u64, budget: u64, asked: bool) {
        let fill = need as f64 / budget.max(1) as f64;
        if fill > HIGH {
            let step = (fill / TARGET).sqrt().clamp(MIN_STEP, MAX_RISE);
            self.scale = (self.scale * step).min(MAX_SCALE);
        } else if fill < LOW && !asked && self.scale > 1.0 {
            let step = (TARGET / fill.max(1e-9)).sqrt().min(MAX_FALL);
            self.scale = (self.scale / step).max(1.0);
        }
    }

    /// Back to the asked-for τ (a new budget, a teleport).
    pub fn reset(&mut self) {
        self.scale = 1.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene whose cut needs `bytes_at_1 / scale²` bytes.
    fn settle(bytes_at_1: f64, budget: u64, frames: usize) -> Vec<f32> {
        let mut fit = CacheFit::default();
        (0..frames)
            .map(|_| {
                let need = bytes_at_1 / fit.scale.powi(2);
                fit.update(need as u64, budget, false);
                fit.scale()
            })
            .collect()
    }

    #[test]
    fn a_cut_that_fits_keeps_the_asked_for_tau() {
        assert!(settle(800.0, 1000, 50).iter().all(|&s| s == 1.0));
    }

    #[test]
    fn a_cut_that_does_not_fit_settles_inside_the_band_without_oscillating() {
        let scales = settle(4000.0, 1000, 60);
        let last = *scales.last().unwrap() as f64;
        let fill = 4000.0 / last.powi(2) / 1000.0;
        assert!((LOW..=HIGH).contains(&fill), "fill {fill}, scales {scales:?}");
        // Settled within a few frames and constant after.
        assert!(scales[10..].iter().all(|&s| s == scales[10]), "{scales:?}");
    }

    #[test]
    fn room_brings_tau_back_slowly_and_never_below_the_asked_for_one() {
        let mut fit = CacheFit::default();
        fit.update(100_000, 1000, true);
        let raised = fit.scale();
        assert!(raised > 1.5);
        // A frame still asking for pages does not know what its cut needs: no fall.
        fit.update(0, 1000, true);
        assert_eq!(fit.scale(), raised);
        fit.update(0, 1000, false);
        assert!(fit.scale() >= raised / MAX_FALL as f32 - 1e-6);
        for _ in 0..200 {
            fit.update(0, 1000, false);
        }
        assert_eq!(fit.scale(), 1.0);
        assert_eq!(fit.tau(2.0), 2.0);
    }

    #[test]
    fn an_impossible_budget_stops_at_the_largest_scale() {
        let mut fit = CacheFit::default();
        for _ in 0..100 {
            fit.update(u64::MAX, 1, true);
        }
        assert_eq!(fit.scale() as f64, MAX_SCALE);
    }
}
