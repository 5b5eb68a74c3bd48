//! The hierarchical Z-buffer (HZB) and its conservative box test, on the CPU, as GigaWalk's
//! scene-traversal stage uses it (Baxter et al. 2002, §4 "STC": build the depth pyramid from the
//! occluders' Z-buffer, then test each node's screen-space bounding rectangle against it; Greene
//! et al. 1993 for the pyramid).
//!
//! Depth is **reverse-Z** as the renderer draws it (tw-gpu; [`crate::Camera::projection_reverse_z`]):
//! 1 at the near plane, 0 at the far plane and on the cleared background, so *larger is nearer*.
//! Each pyramid texel holds the *farthest* (smallest) depth of the pixels it covers: level 0 is the
//! depth buffer itself, each next level halves the size, rounding up; a texel covers the
//! (existing) texels `2x..=2x+1 × 2y..=2y+1` of the level below, so at level `k` it covers the
//! pixels `x·2ᵏ..(x+1)·2ᵏ` (clipped to the image).
//!
//! [`Hzb::test_box`] projects the 8 corners of a scene-space box; its screen rectangle is their
//! bounding rectangle (the box projects inside the hull of its corners when all lie in front of
//! the eye) and its nearest depth is the largest corner depth (depth is monotone in view-space
//! distance, which is linear over the box, so its extreme is at a corner). The rectangle is
//! reduced to the pixels whose *centres* it contains — the only ones rasterization can write —
//! after widening it by [`RECT_SLACK_PX`] against rounding and the rasterizer's vertex snapping.
//! The box is occluded when its nearest depth is strictly farther than the occluder depth at every
//! one of those pixels, with a relative margin ([`DEPTH_MARGIN`]) in the box's favour. The test
//! starts at the level where the rectangle spans at most 2×2 texels (4 reads prove most boxes
//! occluded) and refines each texel that does not prove it into its children that meet the
//! rectangle, down to single pixels where needed, stopping at the first pixel that could show
//! the box — the exact answer for the rectangle, where a single coarse level would call visible
//! every box whose 2×2 texels reach past an occluder's silhouette. A box
//! with a corner behind the eye or in front of the near plane is reported visible.
//!
//! The test is therefore conservative: it never reports a box occluded if any point inside it
//! would pass the depth test at a pixel centre, for the same camera and resolution as the depth
//! buffer. With multisampling a pixel is its samples ([`Hzb::with_samples`], e.g. [`SAMPLES_4X`])
//! and the depth buffer holds each pixel's farthest sample: "centre" above then reads "any sample
//! position", a rectangle is widened by the samples' spread around the centre, and the test is
//! conservative for every sample. (Conservative *relative to the occluders drawn*: GigaWalk's argument that the result
//! equals no culling needs the occluders to be drawn at the same LOD cut as the frame, which is
//! the caller's job.)

use glam::{Mat4, Vec3, Vec4};

/// Pixels by which a projected rectangle is widened on every side before it is reduced to pixel
/// centres: covers f32 rounding of the projection and the rasterizer's sub-pixel snapping
/// (≥ 1/256 px on every GPU and on lavapipe/llvmpipe).
pub const RECT_SLACK_PX: f32 = 1.0 / 32.0;

/// The one sample of a pixel without multisampling: its centre (x, y from the pixel's top-left
/// corner).
pub const PIXEL_CENTRE: [[f32; 2]; 1] = [[0.5, 0.5]];

/// WebGPU's standard 4× multisample positions (x, y from the pixel's top-left corner), which
/// Vulkan's standard sample locations, lavapipe and llvmpipe share.
pub const SAMPLES_4X: [[f32; 2]; 4] = [[0.375, 0.125], [0.875, 0.375], [0.125, 0.625], [0.625, 0.875]];

/// The sample positions of a pixel rendered with `count` samples (1 or 4), `None` for other
/// counts.
pub fn sample_positions(count: u32) -> Option<&'static [[f32; 2]]> {
    match count {
        1 => Some(&PIXEL_CENTRE),
        4 => Some(&SAMPLES_4X),
        _ => None,
    }
}

/// How far `samples` reach from the pixel centre along either axis (pixels).
pub fn sample_spread(samples: &[[f32; 2]]) -> f32 {
    samples.iter().flat_map(|p| p.map(|c| (c - 0.5).abs())).fold(0.0, f32::max)
}

/// Relative depth margin in the box's favour: a box is occluded only when its nearest depth is
/// below `occluder_depth × (1 − DEPTH_MARGIN)`.
pub const DEPTH_MARGIN: f32 = 1e-5;

/// The outcome of one [`Hzb::test_box`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HzbResult {
    /// Some pixel centre inside the rectangle could show the box (or the test cannot tell: the
    /// box crosses the near plane).
    Visible,
    /// Every pixel the box could cover holds nearer geometry.
    Occluded,
    /// The box covers no pixel centre of the image (outside the viewport, or thinner than a
    /// pixel between centres): nothing of it can be drawn at this resolution.
    NoPixels,
}

/// One level of the pyramid: `width × height` farthest depths, rows from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct HzbLevel {
    pub width: u32,
    pub height: u32,
    pub depth: Vec<f32>,
}

/// A farthest-depth pyramid over a reverse-Z depth buffer; see the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct Hzb {
    pub levels: Vec<HzbLevel>,
    /// The sample positions of a pixel ([`PIXEL_CENTRE`] unless [`Hzb::with_samples`]).
    samples: Vec<[f32; 2]>,
    /// How far the samples reach from the pixel centre along either axis (0 for the centre).
    spread: f32,
}

/// Errors of [`Hzb::build`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum HzbError {
    #[error("depth buffer of {len} values does not match {width}×{height}")]
    SizeMismatch { width: u32, height: u32, len: usize },
    #[error("depth buffer must not be empty")]
    Empty,
}

/// The next pyramid level of `last`: each texel the farthest (smallest reverse-Z) of its 2×2
/// block, sizes rounding up (an odd last row or column is its own pair). Rows in parallel for
/// the large levels: at 1280×720 the build was ~2.5 ms of a ~50 ms `hzb` frame on 2 cores,
/// during which the rasterizer's threads are idle (the frame waits for this pyramid).
fn reduce(last: &HzbLevel) -> HzbLevel {
    use rayon::prelude::*;
    let (w, h) = (last.width.div_ceil(2), last.height.div_ceil(2));
    let mut depth = vec![0f32; w as usize * h as usize];
    let src_w = last.width as usize;
    let row = |(y, out): (usize, &mut [f32])| {
        let y0 = 2 * y;
        let y1 = (2 * y + 1).min(last.height as usize - 1);
        let (r0, r1) = (&last.depth[y0 * src_w..][..src_w], &last.depth[y1 * src_w..][..src_w]);
        for (x, d) in out.iter_mut().enumerate() {
            let x0 = 2 * x;
            let x1 = (2 * x + 1).min(src_w - 1);
            *d = r0[x0].min(r0[x1]).min(r1[x0]).min(r1[x1]);
        }
    };
    if depth.len() >= 1 << 16 {
        depth.par_chunks_mut(w as usize).enumerate().for_each(row);
    } else {
        depth.chunks_mut(w as usize).enumerate().for_each(row);
    }
    HzbLevel { width: w, height: h, depth }
}

impl Hzb {
    /// Builds the pyramid from a reverse-Z depth buffer (`width × height`, rows from the top).
    /// Non-finite depths are treated as far (0), so they never occlude.
    pub fn build(depth: &[f32], width: u32, height: u32) -> Result<Hzb, HzbError> {
        if width == 0 || height == 0 {
            return Err(HzbError::Empty);
        }
        if depth.len() as u64 != width as u64 * height as u64 {
            return Err(HzbError::SizeMismatch { width, height, len: depth.len() });
        }
        let base: Vec<f32> = depth.iter().map(|&d| if d.is_finite() { d } else { 0.0 }).collect();
        let mut levels = vec![HzbLevel { width, height, depth: base }];
        while let Some(last) = levels.last() {
            if last.width == 1 && last.height == 1 {
                break;
            }
            levels.push(reduce(last));
        }
        Ok(Hzb::from_levels(levels))
    }

    /// A pyramid of given levels (level 0 the depth buffer, each next one as [`Hzb::build`]
    /// reduces it), sampled at pixel centres.
    pub fn from_levels(levels: Vec<HzbLevel>) -> Hzb {
        Hzb { levels, samples: PIXEL_CENTRE.to_vec(), spread: 0.0 }
    }

    /// The pyramid of a multisampled frame: the depth buffer holds each pixel's farthest
    /// sample, and primitives cover a pixel where they cover one of the `samples` positions
    /// (x, y in 0..1 from its top-left corner; e.g. [`SAMPLES_4X`]). An empty list means the
    /// centre.
    pub fn with_samples(mut self, samples: &[[f32; 2]]) -> Hzb {
        self.samples = if samples.is_empty() { PIXEL_CENTRE.to_vec() } else { samples.to_vec() };
        self.spread = sample_spread(&self.samples);
        self
    }

    /// The sample positions within a pixel (see [`Hzb::with_samples`]).
    pub fn samples(&self) -> &[[f32; 2]] {
        &self.samples
    }

    /// The occluder depth at pixel (`x`, `y`) of level 0 (the depth buffer); `x`, `y` must be
    /// inside the image.
    pub fn pixel_depth(&self, x: u32, y: u32) -> f32 {
        let level = &self.levels[0];
        level.depth[(y * level.width + x) as usize]
    }

    /// Whether a primitive whose depth at pixel (`x`, `y`)'s centre is at most `nearest` can
    /// show there: the occluder depth is not above it (with the relative [`DEPTH_MARGIN`], as
    /// every test here). `x`, `y` must be inside the image.
    pub fn pixel_shows(&self, x: u32, y: u32, nearest: f64) -> bool {
        self.pixel_depth(x, y) as f64 * (1.0 - DEPTH_MARGIN as f64) <= nearest
    }

    /// Width and height of the depth buffer (level 0).
    pub fn size(&self) -> (u32, u32) {
        (self.levels[0].width, self.levels[0].height)
    }

    /// Tests the scene-space box `min..=max` seen through `view_proj` (a reverse-Z
    /// view-projection, the one the depth buffer was drawn with).
    pub fn test_box(&self, view_proj: &Mat4, min: Vec3, max: Vec3) -> HzbResult {
        match self.project_box(view_proj, min, max) {
            Some((x_lo, y_lo, x_hi, y_hi, nearest)) => self.test_rect(x_lo, y_lo, x_hi, y_hi, nearest),
            None => HzbResult::Visible,
        }
    }

    /// [`test_box`](Self::test_box) at one pyramid level only, without refining: the level
    /// where the rectangle spans at most 2×2 texels decides (GigaWalk's test, and what the GPU
    /// culling shader computes). Never calls occluded a box `test_box` calls visible.
    pub fn test_box_single_level(&self, view_proj: &Mat4, min: Vec3, max: Vec3) -> HzbResult {
        let Some((x_lo, y_lo, x_hi, y_hi, nearest)) = self.project_box(view_proj, min, max) else {
            return HzbResult::Visible;
        };
        let Some([x0, y0, x1, y1]) = self.pixel_rect(x_lo, y_lo, x_hi, y_hi) else {
            return HzbResult::NoPixels;
        };
        let k = self.start_level([x0, y0, x1, y1]);
        let level = &self.levels[k];
        let bound = nearest / (1.0 - DEPTH_MARGIN);
        let occluded = ((y0 >> k)..=(y1 >> k)).all(|ty| {
            ((x0 >> k)..=(x1 >> k)).all(|tx| level.depth[(ty * level.width + tx) as usize] > bound)
        });
        if occluded {
            HzbResult::Occluded
        } else {
            HzbResult::Visible
        }
    }

    /// The screen rectangle (pixel units) and nearest depth of a box's corners; `None` when a
    /// corner is behind the eye, at or before the near plane, or not finite.
    fn project_box(&self, view_proj: &Mat4, min: Vec3, max: Vec3) -> Option<(f32, f32, f32, f32, f32)> {
        let (w, h) = self.size();
        let (mut x_lo, mut y_lo) = (f32::INFINITY, f32::INFINITY);
        let (mut x_hi, mut y_hi) = (f32::NEG_INFINITY, f32::NEG_INFINITY);
        let mut nearest = 0f32;
        for i in 0..8 {
            let p = Vec3::new(
                if i & 1 == 0 { min.x } else { max.x },
                if i & 2 == 0 { min.y } else { max.y },
                if i & 4 == 0 { min.z } else { max.z },
            );
            let c: Vec4 = *view_proj * p.extend(1.0);
            if !c.is_finite() || c.w <= 0.0 {
                return None; // behind the eye, or degenerate
            }
            let depth = c.z / c.w;
            if depth >= 1.0 {
                return None; // at or before the near plane
            }
            nearest = nearest.max(depth);
            let sx = (c.x / c.w * 0.5 + 0.5) * w as f32;
            let sy = (0.5 - c.y / c.w * 0.5) * h as f32;
            x_lo = x_lo.min(sx);
            x_hi = x_hi.max(sx);
            y_lo = y_lo.min(sy);
            y_hi = y_hi.max(sy);
        }
        Some((x_lo, y_lo, x_hi, y_hi, nearest))
    }

    /// The pixels whose centres lie in the widened rectangle (inclusive bounds: x0, y0, x1,
    /// y1), `None` when there are none. The rectangle must be finite. With multisampling the
    /// rectangle is widened by the samples' spread as well: the pixels a sample of which may
    /// lie in it.
    pub fn pixel_rect(&self, x_lo: f32, y_lo: f32, x_hi: f32, y_hi: f32) -> Option<[u32; 4]> {
        let (w, h) = self.size();
        // Pixels whose centre lies in the widened rectangle: ceil(lo − ½) ..= floor(hi − ½).
        let slack = RECT_SLACK_PX + self.spread;
        let px0 = (x_lo - slack - 0.5).ceil().max(0.0);
        let py0 = (y_lo - slack - 0.5).ceil().max(0.0);
        let px1 = (x_hi + slack - 0.5).floor().min(w as f32 - 1.0);
        let py1 = (y_hi + slack - 0.5).floor().min(h as f32 - 1.0);
        if px0 > px1 || py0 > py1 {
            return None;
        }
        Some([px0 as u32, py0 as u32, px1 as u32, py1 as u32])
    }

    /// The finest level where the pixel rectangle spans at most 2×2 texels.
    fn start_level(&self, [x0, y0, x1, y1]: [u32; 4]) -> usize {
        let mut k = 0usize;
        while k + 1 < self.levels.len() && ((x1 >> k) - (x0 >> k) > 1 || (y1 >> k) - (y0 >> k) > 1) {
            k += 1;
        }
        k
    }

    /// Tests a screen rectangle (pixel units, x right, y down, pixel `i` spans `i..i+1` with its
    /// centre at `i + 0.5`) whose nearest reverse-Z depth is `nearest`.
    pub fn test_rect(&self, x_lo: f32, y_lo: f32, x_hi: f32, y_hi: f32, nearest: f32) -> HzbResult {
        if !(x_lo.is_finite() && y_lo.is_finite() && x_hi.is_finite() && y_hi.is_finite()) {
            return HzbResult::Visible;
        }
        match self.pixel_rect(x_lo, y_lo, x_hi, y_hi) {
            Some(rect) => self.test_pixels(rect, nearest),
            None => HzbResult::NoPixels,
        }
    }

    /// [`test_rect`](Self::test_rect) of the pixels `rect` (inclusive bounds, as
    /// [`pixel_rect`](Self::pixel_rect) gives them): `Occluded` or `Visible`.
    pub fn test_pixels(&self, rect: [u32; 4], nearest: f32) -> HzbResult {
        self.test_pixels_by(rect, nearest, |_| Some(nearest))
    }

    /// [`test_pixels`](Self::test_pixels) of a primitive whose depth and footprint vary over
    /// the rectangle: `nearest` is the nearest depth it has anywhere, and `bound(region)`, for a
    /// sub-rectangle of `rect` (inclusive pixel bounds), the nearest depth it can have at a
    /// pixel centre of the region that it may cover (at most `nearest`), or `None` when it can
    /// cover none of them. Every texel on the way down the pyramid that `nearest` does not
    /// settle is compared with its own region's bound (a region of one pixel at the bottom), so
    /// a triangle is tested against the pixels it covers, each with the depth it has there,
    /// rather than its whole rectangle against its nearest corner.
    pub fn test_pixels_by(
        &self,
        rect: [u32; 4],
        nearest: f32,
        bound: impl Fn([u32; 4]) -> Option<f32>,
    ) -> HzbResult {
        let [x0, y0, x1, y1] = rect;
        let k = self.start_level(rect);
        let nearest = nearest / (1.0 - DEPTH_MARGIN);
        for ty in (y0 >> k)..=(y1 >> k) {
            for tx in (x0 >> k)..=(x1 >> k) {
                if !self.texel_occludes(k, tx, ty, rect, nearest, &bound) {
                    return HzbResult::Visible;
                }
            }
        }
        HzbResult::Occluded
    }

    /// Whether every pixel of `rect` (inclusive pixel bounds) under texel (`tx`, `ty`) of level
    /// `k` holds a depth above the primitive's there: true at once when the texel's farthest
    /// depth is above `nearest` (the primitive's nearest depth, margin included), or above its
    /// bound over the pixels the texel and `rect` share (with the relative [`DEPTH_MARGIN`]),
    /// or when the primitive covers none of those pixels; else its children of level `k − 1`
    /// that meet the rectangle are refined, down to the pixels. The recursion stops at the
    /// first pixel that could show the primitive, so a visible one costs one path down the
    /// pyramid, and an occluded one as many texels as its outline needs.
    fn texel_occludes<F: Fn([u32; 4]) -> Option<f32>>(
        &self,
        k: usize,
        tx: u32,
        ty: u32,
        rect: [u32; 4],
        nearest: f32,
        bound: &F,
    ) -> bool {
        let level = &self.levels[k];
        let farthest = level.depth[(ty * level.width + tx) as usize];
        if farthest > nearest {
            return true;
        }
        let [x0, y0, x1, y1] = rect;
        let region =
            [x0.max(tx << k), y0.max(ty << k), x1.min(((tx + 1) << k) - 1), y1.min(((ty + 1) << k) - 1)];
        match bound(region) {
            None => return true,
            Some(b) if farthest > b / (1.0 - DEPTH_MARGIN) => return true,
            Some(_) => {}
        }
        if k == 0 {
            return false;
        }
        let (c, below) = (k - 1, &self.levels[k - 1]);
        for cy in (2 * ty).max(y0 >> c)..=(2 * ty + 1).min(y1 >> c).min(below.height - 1) {
            for cx in (2 * tx).max(x0 >> c)..=(2 * tx + 1).min(x1 >> c).min(below.width - 1) {
                if !self.texel_occludes(c, cx, cy, rect, nearest, bound) {
                    return false;
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    const W: u32 = 64;
    const H: u32 = 48;

    /// A camera at the origin looking down +X, z up.
    fn camera() -> Camera {
        Camera::new(Vec3::ZERO, Vec3::X, Vec3::Z, 60f32.to_radians(), 0.1, 1000.0).unwrap()
    }

    fn view_proj(c: &Camera) -> Mat4 {
        c.projection_reverse_z(W as f32 / H as f32) * c.view()
    }

    /// Reverse-Z depth of a point at distance `x` straight ahead.
    fn depth_at(vp: &Mat4, x: f32) -> f32 {
        let c = *vp * Vec4::new(x, 0.0, 0.0, 1.0);
        c.z / c.w
    }

    /// A full-screen wall at distance `x`, with the pixel columns `gap` left open (background).
    fn wall(vp: &Mat4, x: f32, gap: std::ops::Range<u32>) -> Vec<f32> {
        let d = depth_at(vp, x);
        (0..W * H).map(|i| if gap.contains(&(i % W)) { 0.0 } else { d }).collect()
    }

    fn unit_box_at(x: f32) -> (Vec3, Vec3) {
        (Vec3::new(x - 0.5, -0.5, -0.5), Vec3::new(x + 0.5, 0.5, 0.5))
    }

    #[test]
    fn pyramid_keeps_the_farthest_depth_and_covers_odd_sizes() {
        let depth: Vec<f32> = (0..5 * 3).map(|i| 1.0 - i as f32 / 100.0).collect();
        let hzb = Hzb::build(&depth, 5, 3).unwrap();
        let sizes: Vec<(u32, u32)> = hzb.levels.iter().map(|l| (l.width, l.height)).collect();
        assert_eq!(sizes, vec![(5, 3), (3, 2), (2, 1), (1, 1)]);
        // Level 1 texel (2, 1) covers only pixel (4, 2): no neighbours beyond the edge.
        assert_eq!(hzb.levels[1].depth[3 + 2], depth[2 * 5 + 4]);
        // The top is the farthest (smallest) depth of all.
        assert_eq!(hzb.levels[3].depth[0], depth.iter().cloned().fold(f32::INFINITY, f32::min));
        for k in 1..hzb.levels.len() {
            let (lo, hi) = (&hzb.levels[k - 1], &hzb.levels[k]);
            for y in 0..lo.height {
                for x in 0..lo.width {
                    let parent = hi.depth[((y / 2) * hi.width + x / 2) as usize];
                    assert!(parent <= lo.depth[(y * lo.width + x) as usize]);
                }
            }
        }
    }

    /// Orthographic from the origin down +X, a view 4 high: a wall at 20 hides a box behind it
    /// wherever it is in the view, a box in front of it or through a gap is visible, and one
    /// the near plane cuts is visible without a test.
    #[test]
    fn orthographic_boxes_behind_a_wall_are_occluded() {
        let c = Camera::orthographic(Vec3::ZERO, Vec3::X, Vec3::Z, 4.0, 0.1, 1000.0).unwrap();
        let vp = view_proj(&c);
        let hzb = Hzb::build(&wall(&vp, 20.0, 0..8), W, H).unwrap();
        let shifted = |x: f32, dy: f32, dz: f32| {
            let (lo, hi) = unit_box_at(x);
            let d = Vec3::new(0.0, dy, dz);
            (lo * Vec3::new(1.0, 0.3, 0.3) + d, hi * Vec3::new(1.0, 0.3, 0.3) + d)
        };
        for (dy, dz) in [(0.0, 0.0), (-1.5, 1.2), (1.0, -1.2)] {
            let (lo, hi) = shifted(40.0, dy, dz);
            assert_eq!(hzb.test_box(&vp, lo, hi), HzbResult::Occluded, "behind, at {dy} {dz}");
            assert_eq!(hzb.test_box_single_level(&vp, lo, hi), HzbResult::Occluded);
            let (lo, hi) = shifted(10.0, dy, dz);
            assert_eq!(hzb.test_box(&vp, lo, hi), HzbResult::Visible, "in front, at {dy} {dz}");
        }
        // The gap: the 8 left pixel columns (+Y is left when looking down +X with Z up).
        let (lo, hi) = shifted(40.0, 2.4, 0.0);
        assert_eq!(hzb.test_box(&vp, lo, hi), HzbResult::Visible, "through the gap");
        let (lo, hi) = (Vec3::new(0.05, -0.2, -0.2), Vec3::new(30.0, 0.2, 0.2));
        assert_eq!(hzb.test_box(&vp, lo, hi), HzbResult::Visible, "cut by the near plane");
    }

    #[test]
    fn bad_sizes_are_errors() {
        assert_eq!(Hzb::build(&[], 0, 4), Err(HzbError::Empty));
        assert!(matches!(Hzb::build(&[0.0; 5], 2, 3), Err(HzbError::SizeMismatch { .. })));
    }

    #[test]
    fn a_wall_hides_a_box_behind_it() {
        let c = camera();
        let vp = view_proj(&c);
        let hzb = Hzb::build(&wall(&vp, 10.0, 0..0), W, H).unwrap();
        assert_eq!(hzb.test_box(&vp, unit_box_at(20.0).0, unit_box_at(20.0).1), HzbResult::Occluded);
        // In front of the wall, and straddling it: visible.
        assert_eq!(hzb.test_box(&vp, unit_box_at(5.0).0, unit_box_at(5.0).1), HzbResult::Visible);
        assert_eq!(hzb.test_box(&vp, unit_box_at(10.2).0, unit_box_at(10.2).1), HzbResult::Visible);
    }

    #[test]
    fn a_one_pixel_gap_shows_the_box() {
        let c = camera();
        let vp = view_proj(&c);
        // The box at distance 20 covers the central columns; open one of them.
        let (lo, hi) = unit_box_at(20.0);
        let center_col = W / 2;
        let hzb = Hzb::build(&wall(&vp, 10.0, center_col..center_col + 1), W, H).unwrap();
        assert_eq!(hzb.test_box(&vp, lo, hi), HzbResult::Visible);
        // A gap outside the box's rectangle does not.
        let hzb = Hzb::build(&wall(&vp, 10.0, 1..2), W, H).unwrap();
        assert_eq!(hzb.test_box(&vp, lo, hi), HzbResult::Occluded);
    }

    /// `test_pixels_by`: only the pixels the primitive covers count, each with its own bound;
    /// the walk asks for the bounds of regions inside the rectangle only.
    #[test]
    fn a_primitive_is_tested_by_its_own_pixels_and_depths() {
        let c = camera();
        let vp = view_proj(&c);
        let (wall_depth, far) = (depth_at(&vp, 10.0), depth_at(&vp, 20.0));
        // A one-pixel gap at column 40; the rectangle spans columns 30..=50, rows 10..=20.
        let hzb = Hzb::build(&wall(&vp, 10.0, 40..41), W, H).unwrap();
        let rect = [30, 10, 50, 20];
        let inside = |r: [u32; 4]| {
            assert!(
                r[0] >= 30 && r[1] >= 10 && r[2] <= 50 && r[3] <= 20 && r[0] <= r[2] && r[1] <= r[3],
                "{r:?}"
            );
        };
        // Covering the gap column, behind the wall: visible through the gap.
        let covers = |col: u32| {
            move |r: [u32; 4]| {
                inside(r);
                (r[0] <= col && col <= r[2]).then_some(far)
            }
        };
        assert_eq!(hzb.test_pixels_by(rect, far, covers(40)), HzbResult::Visible);
        // Covering only column 35 (wall there): hidden, though the rectangle holds the gap.
        assert_eq!(hzb.test_pixels_by(rect, far, covers(35)), HzbResult::Occluded);
        assert_eq!(hzb.test_pixels(rect, far), HzbResult::Visible);
        // Covering everything, nearer than the wall at column 35 only: visible there.
        let nearer_at_35 = |r: [u32; 4]| {
            inside(r);
            Some(if r[0] <= 35 && 35 <= r[2] { wall_depth * 1.01 } else { wall_depth * 0.99 })
        };
        let solid = Hzb::build(&wall(&vp, 10.0, 0..0), W, H).unwrap();
        assert_eq!(solid.test_pixels_by(rect, wall_depth * 1.01, nearer_at_35), HzbResult::Visible);
        assert_eq!(
            solid.test_pixels_by(rect, wall_depth * 0.99, |_| Some(wall_depth * 0.99)),
            HzbResult::Occluded
        );
        // Covering nothing.
        assert_eq!(hzb.test_pixels_by(rect, 1.0, |_| None), HzbResult::Occluded);
    }

    /// The refinement: a gap right beside the box's rectangle, inside the coarse texels that
    /// cover it, must not make the box visible; a gap one pixel inside its rectangle must.
    #[test]
    fn a_gap_next_to_the_rectangle_is_refined_away() {
        let c = camera();
        let vp = view_proj(&c);
        let (lo, hi) = (Vec3::new(17.5, -2.5, -2.5), Vec3::new(22.5, 2.5, 2.5));
        // The box's pixel columns: its rectangle from the corners' projections.
        let hzb = Hzb::build(&wall(&vp, 10.0, 0..0), W, H).unwrap();
        let cols: Vec<u32> = (0..W)
            .filter(|&x| {
                let gap = Hzb::build(&wall(&vp, 10.0, x..x + 1), W, H).unwrap();
                gap.test_box(&vp, lo, hi) == HzbResult::Visible
            })
            .collect();
        assert_eq!(hzb.test_box(&vp, lo, hi), HzbResult::Occluded);
        let (first, last) = (cols[0], *cols.last().unwrap());
        assert_eq!(cols.len() as u32, last - first + 1, "the columns that show it are contiguous: {cols:?}");
        // Those columns are exactly the ones the rectangle's pixel centres cover.
        let corners: Vec<f32> = (0..8)
            .map(|i| {
                let p = Vec3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                );
                let v = vp * p.extend(1.0);
                (v.x / v.w * 0.5 + 0.5) * W as f32
            })
            .collect();
        let x_lo = corners.iter().cloned().fold(f32::INFINITY, f32::min) - RECT_SLACK_PX;
        let x_hi = corners.iter().cloned().fold(f32::NEG_INFINITY, f32::max) + RECT_SLACK_PX;
        assert_eq!(first, (x_lo - 0.5).ceil() as u32);
        assert_eq!(last, (x_hi - 0.5).floor() as u32);
        // With a single coarse level, some gap beside the box shows it (a texel of the level
        // that decides holds a column of the box and the gap); the refined test does not.
        assert!(first >= 3 && last + 3 < W);
        let fooled = (first - 3..first).chain(last + 1..last + 4).filter(|&x| {
            let beside = Hzb::build(&wall(&vp, 10.0, x..x + 1), W, H).unwrap();
            assert_eq!(beside.test_box(&vp, lo, hi), HzbResult::Occluded);
            beside.test_box_single_level(&vp, lo, hi) == HzbResult::Visible
        });
        let fooled: Vec<u32> = fooled.collect();
        assert!(!fooled.is_empty(), "columns {first}..={last}");
    }

    /// `test_rect` equals the brute-force answer over the rectangle's pixels, on random depth
    /// buffers of odd sizes and random rectangles.
    #[test]
    fn rect_test_is_exact_over_the_pixels() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..300 {
            let (w, h) = (1 + (next() % 37) as u32, 1 + (next() % 29) as u32);
            // Blocky depth: regions of near and far, a few holes.
            let depth: Vec<f32> = (0..w * h).map(|_| [0.0, 0.3, 0.6, 0.9][(next() % 4) as usize]).collect();
            let hzb = Hzb::build(&depth, w, h).unwrap();
            for _ in 0..20 {
                let f = |n: u64, m: u32| (n % (m as u64 * 100)) as f32 / 100.0 - 1.0;
                let (a, b) = (f(next(), w + 2), f(next(), w + 2));
                let (c, d) = (f(next(), h + 2), f(next(), h + 2));
                let (x_lo, x_hi, y_lo, y_hi) = (a.min(b), a.max(b), c.min(d), c.max(d));
                let nearest = [0.1, 0.45, 0.75][(next() % 3) as usize];
                let (px0, px1) = ((x_lo - RECT_SLACK_PX - 0.5).ceil(), (x_hi + RECT_SLACK_PX - 0.5).floor());
                let (py0, py1) = ((y_lo - RECT_SLACK_PX - 0.5).ceil(), (y_hi + RECT_SLACK_PX - 0.5).floor());
                let (px0, py0) = (px0.max(0.0) as i64, py0.max(0.0) as i64);
                let (px1, py1) = (px1.min(w as f32 - 1.0) as i64, py1.min(h as f32 - 1.0) as i64);
                let expected = if px0 > px1 || py0 > py1 {
                    HzbResult::NoPixels
                } else if (py0..=py1).all(|y| {
                    (px0..=px1)
                        .all(|x| nearest < depth[(y as u32 * w + x as u32) as usize] * (1.0 - DEPTH_MARGIN))
                }) {
                    HzbResult::Occluded
                } else {
                    HzbResult::Visible
                };
                assert_eq!(
                    hzb.test_rect(x_lo, y_lo, x_hi, y_hi, nearest),
                    expected,
                    "{w}×{h}, rect ({x_lo}, {y_lo})..({x_hi}, {y_hi}), nearest {nearest}"
                );
            }
        }
    }

    #[test]
    fn a_background_pixel_never_occludes() {
        let c = camera();
        let vp = view_proj(&c);
        let hzb = Hzb::build(&vec![0.0; (W * H) as usize], W, H).unwrap();
        let (lo, hi) = (Vec3::new(899.0, -50.0, -50.0), Vec3::new(900.0, 50.0, 50.0));
        assert_eq!(hzb.test_box(&vp, lo, hi), HzbResult::Visible);
    }

    #[test]
    fn boxes_at_the_near_plane_or_behind_the_eye_are_visible() {
        let c = camera();
        let vp = view_proj(&c);
        let hzb = Hzb::build(&vec![1.0; (W * H) as usize], W, H).unwrap();
        // Crosses the near plane (0.1): reported visible even though the buffer is all "nearest".
        let b = (Vec3::new(0.05, -0.5, -0.5), Vec3::new(3.0, 0.5, 0.5));
        assert_eq!(hzb.test_box(&vp, b.0, b.1), HzbResult::Visible);
        // Contains the eye.
        assert_eq!(hzb.test_box(&vp, Vec3::splat(-1.0), Vec3::splat(1.0)), HzbResult::Visible);
        // Entirely behind the eye: the frustum culls it; the HZB does not guess.
        assert_eq!(hzb.test_box(&vp, unit_box_at(-5.0).0, unit_box_at(-5.0).1), HzbResult::Visible);
    }

    #[test]
    fn off_screen_and_sub_pixel_boxes_cover_no_pixels() {
        let c = camera();
        let vp = view_proj(&c);
        let hzb = Hzb::build(&vec![0.0; (W * H) as usize], W, H).unwrap();
        // Far to the left of the view.
        let b = (Vec3::new(10.0, 40.0, -0.5), Vec3::new(11.0, 41.0, 0.5));
        assert_eq!(hzb.test_box(&vp, b.0, b.1), HzbResult::NoPixels);
        // A rectangle between pixel centres.
        assert_eq!(hzb.test_rect(10.6, 10.6, 10.9, 10.9, 0.5), HzbResult::NoPixels);
        // The same rectangle reaching a centre within the slack is tested.
        assert_eq!(hzb.test_rect(10.6, 10.6, 11.49, 11.49, 0.5), HzbResult::Visible);
    }

    #[test]
    fn big_rectangles_read_a_coarse_level_and_stay_conservative() {
        // Random depth buffers: the pyramid answer must agree with a brute-force scan whenever it
        // says occluded.
        let mut rng = tw_core::Rng::new(7);
        for _ in 0..200 {
            let depth: Vec<f32> = (0..W * H).map(|_| 0.2 + 0.8 * rng.f64() as f32).collect();
            let hzb = Hzb::build(&depth, W, H).unwrap();
            let x0 = rng.f64() as f32 * W as f32;
            let y0 = rng.f64() as f32 * H as f32;
            let x1 = x0 + rng.f64() as f32 * 30.0;
            let y1 = y0 + rng.f64() as f32 * 30.0;
            let z = rng.f64() as f32 * 0.3;
            let brute = {
                let mut far = f32::INFINITY;
                for y in 0..H {
                    for x in 0..W {
                        let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
                        if cx >= x0 && cx <= x1 && cy >= y0 && cy <= y1 {
                            far = far.min(depth[(y * W + x) as usize]);
                        }
                    }
                }
                far
            };
            if hzb.test_rect(x0, y0, x1, y1, z) == HzbResult::Occluded {
                assert!(z < brute, "occluded at depth {z} but a pixel has {brute}");
            }
        }
    }
}
