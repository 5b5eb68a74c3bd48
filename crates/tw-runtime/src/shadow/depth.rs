//! A read-back shadow-map layer as a min and a max pyramid, for cross-culling's rectangle
//! questions ("is every texel of this footprint at least d?", "is some texel above d?") in a
//! few reads instead of one per texel: the idea of the hierarchical Z-buffer (src/hzb.rs; Greene
//! et al. 1993) with both extremes kept, since a receiver is proven lit by the map's *nearest*
//! depth over its footprint and proven shadowed by its *farthest*.
//!
//! Level 0 is the map (`size × size`, row 0 at the top, depth 0 nearest the light, 1.0 where
//! nothing was drawn). Each next level halves the size, rounding up; a texel covers the existing
//! texels `2x..=2x+1 × 2y..=2y+1` below it and holds their minimum and maximum. A non-finite
//! depth (which a depth buffer never holds) is kept as −∞ in the min and +∞ in the max, so it
//! can prove nothing either way.

use crate::error::RuntimeError;

/// One level: `width × height` minima and maxima, rows from the top.
#[derive(Clone, Debug, PartialEq)]
struct Level {
    width: u32,
    height: u32,
    min: Vec<f32>,
    max: Vec<f32>,
}

/// A min/max pyramid over a grid of values (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct MinMaxPyramid {
    levels: Vec<Level>,
}

/// The next level of `last`: each texel the min and max of its 2×2 block.
/// Rows in parallel for the large levels (a 2048² layer is 4 M texels).
fn reduce(last: &Level) -> Level {
    use rayon::prelude::*;
    let (w, h) = (last.width.div_ceil(2), last.height.div_ceil(2));
    let (sw, sh) = (last.width as usize, last.height as usize);
    let mut min = vec![0f32; w as usize * h as usize];
    let mut max = vec![0f32; w as usize * h as usize];
    let row = |(y, (mins, maxs)): (usize, (&mut [f32], &mut [f32]))| {
        let (y0, y1) = (2 * y, (2 * y + 1).min(sh - 1));
        for x in 0..w as usize {
            let (x0, x1) = (2 * x, (2 * x + 1).min(sw - 1));
            let idx = [y0 * sw + x0, y0 * sw + x1, y1 * sw + x0, y1 * sw + x1];
            mins[x] = idx.iter().map(|&i| last.min[i]).fold(f32::INFINITY, f32::min);
            maxs[x] = idx.iter().map(|&i| last.max[i]).fold(f32::NEG_INFINITY, f32::max);
        }
    };
    let rows = min.chunks_mut(w as usize).zip(max.chunks_mut(w as usize));
    if w as usize * h as usize >= 1 << 16 {
        rows.collect::<Vec<_>>().into_par_iter().enumerate().for_each(row);
    } else {
        rows.enumerate().for_each(row);
    }
    Level { width: w, height: h, min, max }
}

impl MinMaxPyramid {
    /// The pyramid of `values` (`width × height`, rows from the top; both sizes > 0 and
    /// `values.len() == width × height`, which the callers check).
    fn build(values: &[f32], width: u32, height: u32) -> MinMaxPyramid {
        let base = Level {
            width,
            height,
            min: values.iter().map(|&v| if v.is_finite() { v } else { f32::NEG_INFINITY }).collect(),
            max: values.iter().map(|&v| if v.is_finite() { v } else { f32::INFINITY }).collect(),
        };
        let mut levels = vec![base];
        while let Some(last) = levels.last() {
            if last.width == 1 && last.height == 1 {
                break;
            }
            levels.push(reduce(last));
        }
        MinMaxPyramid { levels }
    }

    /// A pyramid over a grid whose values were accumulated elsewhere (the casters' grid of
    /// receiver depths); `None` when the sizes do not match.
    pub fn from_grid(values: &[f32], width: u32, height: u32) -> Option<MinMaxPyramid> {
        (width > 0 && height > 0 && values.len() as u64 == width as u64 * height as u64)
            .then(|| MinMaxPyramid::build(values, width, height))
    }

    /// Width and height of level 0.
    pub fn size(&self) -> (u32, u32) {
        (self.levels[0].width, self.levels[0].height)
    }

    /// Whether some texel of `rect` (inclusive level-0 bounds `[x0, y0, x1, y1]`, clamped to the
    /// grid) may satisfy a condition, where `may(min, max)` tells whether a block whose values
    /// span `min..=max` may hold such a texel (at a single texel `min == max` is its value, so
    /// `may` decides it exactly). Starts at the level where the rectangle spans at most 2×2
    /// texels and refines only the blocks `may` cannot rule out: the exact answer for the
    /// rectangle, usually in a handful of reads.
    pub fn any(&self, rect: [u32; 4], may: impl Fn(f32, f32) -> bool) -> bool {
        self.any_in(rect, usize::MAX, |min, max, _| may(min, max))
    }

    /// [`any`](Self::any) with the block's extent: `may(min, max, block)` also gets the level-0
    /// texels `[x0, y0, x1, y1]` (inclusive) that the block covers within `rect`, so that what is
    /// compared with the block's values can itself depend on where the block lies (a receiver's
    /// depth bound over just that part of its footprint). After `budget` blocks read without an
    /// answer it gives up and answers `true` ("may"): a bound on the cost of one question, for
    /// callers to whom `true` is the safe answer.
    pub fn any_in(&self, rect: [u32; 4], budget: usize, may: impl Fn(f32, f32, [u32; 4]) -> bool) -> bool {
        let (w, h) = self.size();
        let [x0, y0] = [rect[0].min(w - 1), rect[1].min(h - 1)];
        let [x1, y1] = [rect[2].min(w - 1), rect[3].min(h - 1)];
        if x0 > x1 || y0 > y1 {
            return false;
        }
        let mut k = 0usize;
        while k + 1 < self.levels.len() && ((x1 >> k) - (x0 >> k) > 1 || (y1 >> k) - (y0 >> k) > 1) {
            k += 1;
        }
        let mut stack: Vec<(usize, u32, u32)> = Vec::with_capacity(32);
        for ty in (y0 >> k)..=(y1 >> k) {
            for tx in (x0 >> k)..=(x1 >> k) {
                stack.push((k, tx, ty));
            }
        }
        let mut reads = 0usize;
        while let Some((k, tx, ty)) = stack.pop() {
            reads += 1;
            if reads > budget {
                return true;
            }
            let level = &self.levels[k];
            let i = (ty * level.width + tx) as usize;
            let block = [
                (tx << k).max(x0),
                (ty << k).max(y0),
                ((tx + 1) << k).min(x1 + 1) - 1,
                ((ty + 1) << k).min(y1 + 1) - 1,
            ];
            if !may(level.min[i], level.max[i], block) {
                continue;
            }
            if k == 0 {
                return true;
            }
            let below = &self.levels[k - 1];
            let s = k - 1;
            let (cx0, cx1) = ((2 * tx).max(x0 >> s), (2 * tx + 1).min(x1 >> s).min(below.width - 1));
            let (cy0, cy1) = ((2 * ty).max(y0 >> s), (2 * ty + 1).min(y1 >> s).min(below.height - 1));
            for cy in cy0..=cy1 {
                for cx in cx0..=cx1 {
                    stack.push((s, cx, cy));
                }
            }
        }
        false
    }

    /// The value at level-0 texel (`x`, `y`) (the min kept: the value itself when finite).
    pub fn value(&self, x: u32, y: u32) -> f32 {
        let l = &self.levels[0];
        l.min[(y * l.width + x) as usize]
    }
}

/// One read-back shadow-map layer and its pyramids (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct LightDepth {
    size: u32,
    pyramid: MinMaxPyramid,
}

impl LightDepth {
    /// The layer of `depth`: `size × size` depths, row 0 at the top, 1.0 where empty.
    pub fn new(depth: &[f32], size: u32) -> Result<LightDepth, RuntimeError> {
        if size == 0 {
            return Err(RuntimeError::Shadow("a light depth map must not be empty".into()));
        }
        if depth.len() as u64 != size as u64 * size as u64 {
            return Err(RuntimeError::Shadow(format!(
                "light depth map of {} values does not match {size}×{size} texels",
                depth.len()
            )));
        }
        Ok(LightDepth { size, pyramid: MinMaxPyramid::build(depth, size, size) })
    }

    /// Texels per side.
    pub fn size(&self) -> u32 {
        self.size
    }

    /// The depth stored at texel (`x`, `y`) (non-finite depths read as −∞).
    pub fn texel(&self, x: u32, y: u32) -> f32 {
        self.pyramid.value(x, y)
    }

    /// The min/max pyramid ([`MinMaxPyramid::any`] answers the rectangle questions).
    pub fn pyramid(&self) -> &MinMaxPyramid {
        &self.pyramid
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tw_core::rng::Rng;

    #[test]
    fn rectangle_questions_match_a_scan_of_the_texels() {
        let mut rng = Rng::new(0x1234_5678);
        for size in [1u32, 2, 5, 16, 37] {
            let map: Vec<f32> = (0..size * size).map(|_| rng.range_u32(0, 1000) as f32 / 1000.0).collect();
            let d = LightDepth::new(&map, size).unwrap();
            for _ in 0..300 {
                let (a, b) = (rng.range_u32(0, size), rng.range_u32(0, size));
                let (c, e) = (rng.range_u32(0, size), rng.range_u32(0, size));
                let rect = [a.min(b), c.min(e), a.max(b), c.max(e)];
                let t = rng.range_u32(0, 1000) as f32 / 1000.0;
                let scan_at = |f: &dyn Fn(u32, u32, f32) -> bool| {
                    (rect[1]..=rect[3])
                        .any(|y| (rect[0]..=rect[2]).any(|x| f(x, y, map[(y * size + x) as usize])))
                };
                let scan = |f: &dyn Fn(f32) -> bool| scan_at(&|_, _, v| f(v));
                assert_eq!(d.pyramid().any(rect, |mn, _| mn < t), scan(&|v| v < t), "{size} {rect:?} <{t}");
                assert_eq!(d.pyramid().any(rect, |_, mx| mx > t), scan(&|v| v > t), "{size} {rect:?} >{t}");
                // The blocks handed to the predicate lie in the rectangle and, at one texel,
                // are that texel.
                let inside = std::cell::Cell::new(true);
                let hit = d.pyramid().any_in(rect, usize::MAX, |mn, _, b| {
                    inside.set(
                        inside.get()
                            && b[0] >= rect[0]
                            && b[1] >= rect[1]
                            && b[2] <= rect[2]
                            && b[3] <= rect[3]
                            && b[0] <= b[2]
                            && b[1] <= b[3],
                    );
                    if b[0] == b[2] && b[1] == b[3] {
                        return map[(b[1] * size + b[0]) as usize] < t && b[0] % 2 == 0;
                    }
                    mn < t
                });
                assert!(inside.get(), "{size} {rect:?}");
                assert_eq!(hit, scan_at(&|x, _, v| v < t && x % 2 == 0), "{size} {rect:?} even <{t}");
            }
        }
    }

    #[test]
    fn bad_maps_are_errors_and_nan_proves_nothing() {
        assert!(LightDepth::new(&[1.0; 3], 2).unwrap_err().to_string().contains("2×2"));
        assert!(LightDepth::new(&[], 0).is_err());
        let d = LightDepth::new(&[f32::NAN, 0.5, 0.5, 0.5], 2).unwrap();
        assert!(d.pyramid().any([0, 0, 1, 1], |mn, _| mn < 0.0));
        assert!(d.pyramid().any([0, 0, 1, 1], |_, mx| mx > 1.0));
        assert!(!d.pyramid().any([1, 0, 1, 1], |_, mx| mx > 1.0));
    }
}
