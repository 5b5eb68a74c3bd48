//! How a frame switches LOD (`--transition`, docs/RUNTIME.md "Transitions"): at once (`pop`),
//! or by a screen-door cross-fade of the old and the new clusters over a few frames (`dither`).
//!
//! A cluster-DAG cut switches whole groups at once when their error crosses τ: the image jumps
//! (popping; [`crate::popping`] measures it). With `dither:N`, a cluster that entered the cut at
//! frame f and one that left it at frame f are both drawn for N frames, with complementary
//! screen-door masks ([`tw_gpu::dither`]): at frame k the entering one keeps the pixels ranked
//! below t = (k − f + 1) / (N + 1), the leaving one the rest. Both halves of a switch entered or
//! left at the same frame, so they share t and every pixel sees one of them: the frame is
//! everywhere one whole, consistent cut — no crack, no z-fight, no doubled surface. After N
//! frames the old cluster is gone and the new one whole.
//!
//! Rules ([`Fades::advance`]):
//! - a cluster's state follows its membership of the cut: one that joins the cut enters
//!   (fading in) from that frame, one that leaves it leaves (fading out) from that frame;
//! - but the frustum is not the LOD: a cluster that joins the cut because it came into view
//!   (its box was outside the previous frame's frustum) has nothing to fade from and is drawn
//!   whole at once, and one that leaves the cut out of view (its box outside this frame's
//!   frustum) is dropped at once;
//! - **flipping back mid-fade**: a cluster that rejoins the cut while still fading out enters
//!   anew from the current frame (its fade-out is forgotten), and one that leaves while still
//!   fading in leaves from the current frame. Every cluster that joins the cut at frame f
//!   replaces clusters that left it at f, and those restart at f too, so each pixel of the
//!   cut's surface is always drawn by one of them: never a hole, at worst an old and a new
//!   level both drawn (a chain of switches within one fade), where the depth test picks one.
//!   The price is a jump where a switch reverses: the cluster that flips goes from its partial
//!   coverage to its new side's. Turning the flipping cluster round instead (keeping its mask
//!   and stepping its threshold back) makes a reversal smooth but opens holes where switches
//!   chain (the newest level starts from the bottom of the ranks while the one it replaces
//!   steps back from the middle): on the 10^7 fly-over the worst frame changed 1.60 % of its
//!   pixels that way against 0.54 % restarting (docs/benchmarks-log.md, session 39);
//! - a leaving cluster whose page is no longer resident is not drawn: it pops
//!   ([`crate::Walkthrough::draw_frame`]);
//! - the first frame after a [`reset`](Fades::reset) (a new walk, a teleport) fades nothing.
//!
//! Where fading clusters are drawn: every eye pass of the frame (the occluders' depth, the
//! occlusion tests' candidates — both halves are tested — the second pass, the colour) with the
//! same masks, so a dithered depth only has holes where nothing of the two halves is drawn:
//! the HZB built from it is still conservative, and `hzb` draws pixel for pixel what `none`
//! draws. Shadow casters are the light's own selection, not the eye's cut: they switch at once.
//! The ray tracer (`--ray-traced`) and the parallel pipelines other than `serial` switch at once.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use glam::Mat4;
use tw_gpu::dither::{fade_word, Fade};
use tw_runtime::{Camera, ClusterRef, Containment, Frustum, ResidentPage};

use crate::Walkthrough;

/// The most frames a cross-fade may last (`dither:N`).
pub const MAX_FADE_FRAMES: u32 = 64;

/// The cross-fade's length when `dither` names none.
pub const DEFAULT_FADE_FRAMES: u32 = 8;

/// How LOD switches are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Transition {
    /// At once: each frame draws its cut alone.
    #[default]
    Pop,
    /// A screen-door cross-fade over `frames` frames (1..=[`MAX_FADE_FRAMES`]).
    Dither { frames: u32 },
}

impl Transition {
    /// `pop`, `dither` or `dither:N` (N in 1..=[`MAX_FADE_FRAMES`]); the error names the flag.
    pub fn parse(text: &str) -> Result<Transition, String> {
        let text = text.trim();
        match text.split_once(':') {
            None if text == "pop" => Ok(Transition::Pop),
            None if text == "dither" => Ok(Transition::Dither { frames: DEFAULT_FADE_FRAMES }),
            Some(("dither", n)) => match n.trim().parse::<u32>() {
                Ok(frames) if (1..=MAX_FADE_FRAMES).contains(&frames) => Ok(Transition::Dither { frames }),
                _ => Err(format!(
                    "--transition {text}: the cross-fade's length must be a whole number of frames from 1 to {MAX_FADE_FRAMES}"
                )),
            },
            _ => Err(format!("--transition {text}: expected pop, dither or dither:N (N frames, 1 to {MAX_FADE_FRAMES})")),
        }
    }

    /// As `--transition` spells it.
    pub fn name(self) -> String {
        match self {
            Transition::Pop => "pop".into(),
            Transition::Dither { frames } => format!("dither:{frames}"),
        }
    }
}

/// The clusters fading in and out, frame to frame (see the module documentation).
#[derive(Clone, Debug, Default)]
pub struct Fades {
    /// Frames advanced since the reset.
    frame: u64,
    /// The previous frame's cut.
    previous: HashSet<ClusterRef>,
    /// Clusters of the cut that entered it at the given frame, less than a fade ago.
    entering: HashMap<ClusterRef, u64>,
    /// Clusters out of the cut that left it at the given frame, less than a fade ago.
    leaving: HashMap<ClusterRef, u64>,
}

impl Fades {
    /// Forgets every fade: the next frame fades nothing.
    pub fn reset(&mut self) {
        *self = Fades::default();
    }

    /// The next frame, whose cut is `cut`, with fades of `frames` frames: clusters that joined
    /// the cut since the previous frame enter where `was_seen` (the previous frame could show
    /// them), those that left it leave where `is_seen` (this frame can show them), the others
    /// switch at once; fades as old as `frames` end.
    pub fn advance(
        &mut self,
        cut: &[ClusterRef],
        frames: u32,
        was_seen: impl Fn(&ClusterRef) -> bool,
        is_seen: impl Fn(&ClusterRef) -> bool,
    ) {
        self.frame += 1;
        let now: HashSet<ClusterRef> = cut.iter().copied().collect();
        if !self.previous.is_empty() {
            for c in now.difference(&self.previous) {
                self.leaving.remove(c);
                if was_seen(c) {
                    self.entering.insert(*c, self.frame);
                }
            }
            for c in self.previous.difference(&now) {
                self.entering.remove(c);
                if is_seen(c) {
                    self.leaving.insert(*c, self.frame);
                }
            }
        }
        let frame = self.frame;
        let live = |start: &mut u64| frame - *start < frames as u64;
        self.entering.retain(|_, s| live(s));
        self.leaving.retain(|_, s| live(s));
        self.previous = now;
    }

    /// The clusters fading out (not in the cut, still drawn), in order.
    pub fn leaving(&self) -> Vec<ClusterRef> {
        let mut v: Vec<ClusterRef> = self.leaving.keys().copied().collect();
        v.sort_unstable();
        v
    }

    /// Whether nothing fades.
    pub fn is_empty(&self) -> bool {
        self.entering.is_empty() && self.leaving.is_empty()
    }

    /// The fade word of every fading cluster at this frame, with fades of `frames` frames
    /// (t = (frame − start + 1) / (frames + 1)).
    pub fn words(&self, frames: u32) -> Vec<(ClusterRef, u32)> {
        let t = |start: u64| (self.frame - start + 1) as f32 / (frames + 1) as f32;
        let entering = self.entering.iter().map(|(c, s)| (*c, fade_word(Fade::Entering, t(*s))));
        let leaving = self.leaving.iter().map(|(c, s)| (*c, fade_word(Fade::Leaving, t(*s))));
        entering.chain(leaving).collect()
    }
}

/// What a frame drew: its cut and the clusters fading out that were drawn with it, and the fade
/// word of each fading cluster. `bench --popping` draws a frame's camera with the previous
/// frame's state and with its own ([`crate::Walkthrough::lod_change`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DrawnState {
    pub clusters: Vec<ClusterRef>,
    pub fades: Vec<(ClusterRef, u32)>,
    /// Triangles of the cut (the fading-out clusters not counted).
    pub triangles: u64,
    /// The view-projection of the frame's camera (what it could show; `None` before a frame).
    pub view_proj: Option<Mat4>,
}

impl Walkthrough {
    /// A frame's fades under `transition`, its cut just selected: advances them, sets their
    /// words on the renderer and notes which fading-out clusters the frame draws — those whose
    /// page is among the frame's `pages` or still in the cache (the others pop). Returns
    /// `pages` with the pages of those clusters added (sorted by page).
    pub(crate) fn fade(
        &mut self,
        camera: &Camera,
        transition: Transition,
        mut pages: Vec<(u32, Arc<ResidentPage>)>,
    ) -> Vec<(u32, Arc<ResidentPage>)> {
        let (w, h) = self.renderer.size();
        let view_proj = camera.view_projection(w as f32 / h.max(1) as f32);
        let before = self.view.replace(view_proj);
        let frames = match transition {
            Transition::Pop => {
                self.fades.reset();
                self.faded = Default::default();
                self.renderer.set_fades([]);
                return pages;
            }
            Transition::Dither { frames } => frames,
        };
        let cache = self.streamer.cache();
        let grid_step = self.streamer.store().header().grid_step;
        // Each frustum once a frame, not once a cluster.
        let (was, is) =
            (before.map(|m| Frustum::from_view_projection(&m)), Frustum::from_view_projection(&view_proj));
        let seen_by = |frustum: Option<&Frustum>, c: &ClusterRef| {
            let Some(frustum) = frustum else { return true };
            let bounds = match pages.binary_search_by_key(&c.page, |(p, _)| *p) {
                Ok(i) => pages[i].1.bounds.get(c.index_in_page as usize).copied(),
                Err(_) => cache.try_get(c.page).and_then(|p| p.bounds.get(c.index_in_page as usize).copied()),
            };
            bounds.is_none_or(|(min, max)| frustum.test_grid_box(min, max, grid_step) != Containment::Outside)
        };
        self.fades.advance(
            &self.selection.clusters,
            frames,
            |c| seen_by(was.as_ref(), c),
            |c| seen_by(Some(&is), c),
        );
        let mut drawn = Vec::new();
        let mut gone = HashSet::new();
        for c in self.fades.leaving() {
            match pages.binary_search_by_key(&c.page, |(p, _)| *p) {
                Ok(_) => drawn.push(c),
                Err(at) => match cache.try_get(c.page) {
                    Some(page) => {
                        pages.insert(at, (c.page, page));
                        drawn.push(c);
                    }
                    None => {
                        gone.insert(c);
                    }
                },
            }
        }
        let words: Vec<(ClusterRef, u32)> =
            self.fades.words(frames).into_iter().filter(|(c, _)| !gone.contains(c)).collect();
        self.renderer.set_fades(words.iter().copied());
        self.faded = (drawn, words);
        pages
    }

    /// Whether a cross-fade is in progress: a still camera's next frames still change.
    pub fn fading(&self) -> bool {
        !self.fades.is_empty()
    }

    /// What the last frame drew ([`Walkthrough::draw_frame`]): its cut, the clusters fading
    /// out that it drew too, and the fade words.
    pub fn drawn_state(&self) -> DrawnState {
        let mut clusters = self.selection.clusters.clone();
        clusters.extend_from_slice(&self.faded.0);
        let triangles = self.selection.triangles;
        DrawnState { clusters, fades: self.faded.1.clone(), triangles, view_proj: self.view }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(i: u32) -> ClusterRef {
        ClusterRef { page: i, index_in_page: 0, group: 0 }
    }

    fn seen(_: &ClusterRef) -> bool {
        true
    }

    #[test]
    fn clusters_coming_into_view_or_leaving_it_switch_at_once() {
        let mut f = Fades::default();
        f.advance(&[c(1), c(2)], 8, seen, seen);
        // 3 came into view (the previous frame could not show it), 2 went out of view.
        let out_of_view = |x: &ClusterRef| *x != c(3) && *x != c(2);
        f.advance(&[c(1), c(3)], 8, out_of_view, out_of_view);
        assert!(f.is_empty(), "{f:?}");
    }

    #[test]
    fn flags_parse_and_bad_lengths_are_refused() {
        assert_eq!(Transition::parse("pop"), Ok(Transition::Pop));
        assert_eq!(Transition::parse("dither"), Ok(Transition::Dither { frames: DEFAULT_FADE_FRAMES }));
        assert_eq!(Transition::parse("dither:3"), Ok(Transition::Dither { frames: 3 }));
        for bad in ["dither:0", "dither:65", "dither:x", "fade", "dither:", "pop:2"] {
            let e = Transition::parse(bad).unwrap_err();
            assert!(e.contains("--transition"), "{bad}: {e}");
        }
        assert_eq!(
            Transition::parse(&Transition::Dither { frames: 5 }.name()),
            Ok(Transition::Dither { frames: 5 })
        );
    }

    #[test]
    fn a_switch_fades_for_n_frames_with_both_halves_at_one_t() {
        let mut f = Fades::default();
        f.advance(&[c(1), c(2)], 3, seen, seen);
        assert!(f.is_empty(), "the first frame fades nothing");
        // 2 is replaced by its parent 9.
        f.advance(&[c(1), c(9)], 3, seen, seen);
        assert_eq!(f.leaving(), vec![c(2)]);
        for k in 1..=3u32 {
            let words: HashMap<ClusterRef, u32> = f.words(3).into_iter().collect();
            let t = k as f32 / 4.0;
            assert_eq!(words[&c(9)], fade_word(Fade::Entering, t), "frame {k}");
            assert_eq!(words[&c(2)], fade_word(Fade::Leaving, t), "frame {k}");
            assert!(!words.contains_key(&c(1)));
            f.advance(&[c(1), c(9)], 3, seen, seen);
        }
        assert!(f.is_empty(), "after 3 frames the fade is over");
    }

    #[test]
    fn a_switch_reversed_mid_fade_restarts_both_halves_together() {
        let mut f = Fades::default();
        f.advance(&[c(2)], 8, seen, seen);
        f.advance(&[c(9)], 8, seen, seen);
        f.advance(&[c(9)], 8, seen, seen);
        f.advance(&[c(2)], 8, seen, seen);
        let words: HashMap<ClusterRef, u32> = f.words(8).into_iter().collect();
        let t = 1.0 / 9.0;
        assert_eq!(words[&c(2)], fade_word(Fade::Entering, t));
        assert_eq!(words[&c(9)], fade_word(Fade::Leaving, t));
        assert_eq!(f.leaving(), vec![c(9)]);
    }

    #[test]
    fn a_still_cut_fades_nothing() {
        let mut f = Fades::default();
        for _ in 0..5 {
            f.advance(&[c(1), c(2), c(3)], 8, seen, seen);
            assert!(f.is_empty());
        }
    }
}
