//! Comparing two renderers' shadows pixel by pixel: two images in
//! [`ColorMode::Shadow`](tw_core::color::ColorMode::Shadow) — the ray tracer's (the reference:
//! a shadow ray per pixel) and the rasterizer's (shadow maps) — agree where both call a pixel
//! lit, or both blocked.
//!
//! Shadow maps are exact only up to their texels: near a shadow's edge a map of finite
//! resolution may decide either way, which is the method's known error, not a fault. So the
//! comparison leaves out the reference's pixels within `edge_px` (Chebyshev distance) of a pixel
//! of the other class (lit next to blocked) and counts them apart. Pixels the reference shows as
//! facing away from the light or as background have no shadow to compare: they are counted, not
//! compared. Where the reference is lit or blocked but the test image shows something else
//! (facing away, background, a blended colour), the pixel is compared and disagrees.

use tw_core::color::{SHADOW_AWAY, SHADOW_BLOCKED, SHADOW_LIT};

/// What a pixel of a shadow mask shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaskClass {
    /// [`SHADOW_LIT`].
    Lit,
    /// [`SHADOW_BLOCKED`].
    Blocked,
    /// [`SHADOW_AWAY`].
    Away,
    /// No geometry (alpha 0).
    Background,
    /// Any other colour (a blend at a silhouette, another colour mode).
    Other,
}

impl MaskClass {
    /// The class of one RGBA8 pixel.
    pub fn of(pixel: [u8; 4]) -> MaskClass {
        match pixel {
            [_, _, _, 0] => MaskClass::Background,
            p if p == SHADOW_LIT => MaskClass::Lit,
            p if p == SHADOW_BLOCKED => MaskClass::Blocked,
            p if p == SHADOW_AWAY => MaskClass::Away,
            _ => MaskClass::Other,
        }
    }
}

/// How two shadow masks agree ([`compare_shadow_masks`]). Every pixel is counted once in
/// `compared`, `excluded_edge`, `away`, `background` or `other`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MaskAgreement {
    /// Reference pixels lit or blocked, away from shadow edges.
    pub compared: u64,
    /// Of `compared`, those the test image classes the same.
    pub agree: u64,
    /// Of `compared`, lit in the reference and blocked in the test image (e.g. shadow acne).
    pub lit_as_blocked: u64,
    /// Of `compared`, blocked in the reference and lit in the test image (light leaks).
    pub blocked_as_lit: u64,
    /// Of `compared`, lit or blocked in the reference but neither in the test image.
    pub not_a_shadow: u64,
    /// Reference pixels lit or blocked within `edge_px` of the other class: not compared.
    pub excluded_edge: u64,
    /// Reference pixels facing away from the light, background or other colours: not compared.
    pub away: u64,
    pub background: u64,
    pub other: u64,
}

impl MaskAgreement {
    /// `agree / compared` (1 when nothing was compared).
    pub fn ratio(&self) -> f64 {
        if self.compared == 0 {
            1.0
        } else {
            self.agree as f64 / self.compared as f64
        }
    }
}

/// Why two masks could not be compared.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum MaskError {
    #[error(
        "shadow mask {which}: {len} bytes, expected {width}x{height} RGBA8 pixels ({} bytes)",
        *width as u64 * *height as u64 * 4
    )]
    Size { which: &'static str, len: usize, width: u32, height: u32 },
}

/// Compares the `width`×`height` RGBA8 shadow masks `reference` and `test` (rows from the top,
/// as [`tw_gpu::Image::rgba`] and `tw_rt::scene::TracedFrame::rgba` hold them), leaving out the
/// reference's pixels within `edge_px` of a lit/blocked boundary (module documentation).
pub fn compare_shadow_masks(
    reference: &[u8],
    test: &[u8],
    width: u32,
    height: u32,
    edge_px: u32,
) -> Result<MaskAgreement, MaskError> {
    let reference = classes(reference, "reference", width, height)?;
    let test = classes(test, "test", width, height)?;
    let (w, h) = (width as usize, height as usize);
    let near_lit = dilate(&reference.iter().map(|&c| c == MaskClass::Lit).collect::<Vec<_>>(), w, h, edge_px);
    let near_blocked =
        dilate(&reference.iter().map(|&c| c == MaskClass::Blocked).collect::<Vec<_>>(), w, h, edge_px);
    let mut a = MaskAgreement::default();
    for (i, (&r, &t)) in reference.iter().zip(&test).enumerate() {
        let edge = match r {
            MaskClass::Lit => near_blocked[i],
            MaskClass::Blocked => near_lit[i],
            MaskClass::Away => {
                a.away += 1;
                continue;
            }
            MaskClass::Background => {
                a.background += 1;
                continue;
            }
            MaskClass::Other => {
                a.other += 1;
                continue;
            }
        };
        if edge {
            a.excluded_edge += 1;
            continue;
        }
        a.compared += 1;
        match (r, t) {
            _ if r == t => a.agree += 1,
            (MaskClass::Lit, MaskClass::Blocked) => a.lit_as_blocked += 1,
            (MaskClass::Blocked, MaskClass::Lit) => a.blocked_as_lit += 1,
            _ => a.not_a_shadow += 1,
        }
    }
    Ok(a)
}

/// [`compare_shadow_masks`] on two images (the rasterizer's read-back, or a traced frame's
/// pixels wrapped as one); images of different sizes are an error.
pub fn compare_shadow_images(
    reference: &tw_gpu::Image,
    test: &tw_gpu::Image,
    edge_px: u32,
) -> Result<MaskAgreement, MaskError> {
    if (test.width, test.height) != (reference.width, reference.height) {
        return Err(MaskError::Size {
            which: "test",
            len: test.rgba.len(),
            width: reference.width,
            height: reference.height,
        });
    }
    compare_shadow_masks(&reference.rgba, &test.rgba, reference.width, reference.height, edge_px)
}

/// The class of every pixel of `rgba`, checked to be `width`×`height` pixels.
fn classes(rgba: &[u8], which: &'static str, width: u32, height: u32) -> Result<Vec<MaskClass>, MaskError> {
    let pixels = width as u64 * height as u64;
    if rgba.len() as u64 != pixels * 4 {
        return Err(MaskError::Size { which, len: rgba.len(), width, height });
    }
    Ok(rgba.chunks_exact(4).map(|p| MaskClass::of([p[0], p[1], p[2], p[3]])).collect())
}

/// `set` (row-major, `w`×`h`) grown by `r` pixels in every direction (a square window: the
/// pixels within Chebyshev distance `r` of a set pixel), as two separable passes of window
/// counts over prefix sums, linear in the pixels whatever `r`.
fn dilate(set: &[bool], w: usize, h: usize, r: u32) -> Vec<bool> {
    let r = r as usize;
    let rows: Vec<bool> = set.chunks(w.max(1)).flat_map(|row| window_any(row, r)).collect();
    let mut out = vec![false; rows.len()];
    let mut column = vec![false; h];
    for x in 0..w {
        for (y, c) in column.iter_mut().enumerate() {
            *c = rows[y * w + x];
        }
        for (y, v) in window_any(&column, r).into_iter().enumerate() {
            out[y * w + x] = v;
        }
    }
    out
}

/// For each position of `line`, whether any position within `r` of it is set.
fn window_any(line: &[bool], r: usize) -> Vec<bool> {
    let mut prefix = Vec::with_capacity(line.len() + 1);
    prefix.push(0u32);
    for &v in line {
        prefix.push(prefix.last().copied().unwrap_or(0) + v as u32);
    }
    (0..line.len()).map(|i| prefix[(i + r + 1).min(line.len())] > prefix[i.saturating_sub(r)]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const BG: [u8; 4] = [0, 0, 0, 0];

    /// A `w`×`h` mask from a function of the pixel.
    fn mask(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 4]) -> Vec<u8> {
        let f = &f;
        (0..h).flat_map(|y| (0..w).flat_map(move |x| f(x, y))).collect()
    }

    /// A lit floor with a blocked square `[10, 20)²`, away pixels in the last rows and
    /// background in the last columns.
    fn scene(x: u32, y: u32) -> [u8; 4] {
        if x >= 36 {
            BG
        } else if y >= 36 {
            SHADOW_AWAY
        } else if (10..20).contains(&x) && (10..20).contains(&y) {
            SHADOW_BLOCKED
        } else {
            SHADOW_LIT
        }
    }

    #[test]
    fn identical_masks_agree_everywhere_but_edges_are_set_apart() {
        let m = mask(40, 40, scene);
        let a = compare_shadow_masks(&m, &m, 40, 40, 0).unwrap();
        assert_eq!(a.compared, 36 * 36);
        assert_eq!((a.agree, a.ratio()), (36 * 36, 1.0));
        assert_eq!((a.away, a.background, a.excluded_edge), (4 * 36, 4 * 40, 0));
        // Within two pixels of the square's border: the 14x14 band from 8 to 22 less the
        // blocked core from 12 to 18.
        let a = compare_shadow_masks(&m, &m, 40, 40, 2).unwrap();
        assert_eq!(a.excluded_edge, 14 * 14 - 6 * 6);
        assert_eq!(a.compared + a.excluded_edge + a.away + a.background + a.other, 40 * 40);
    }

    #[test]
    fn errors_are_counted_by_kind_and_edges_forgive_a_shifted_shadow() {
        let reference = mask(40, 40, scene);
        // The test's shadow is one pixel to the right, and a speck of acne sits in the open.
        let test = mask(40, 40, |x, y| match (x, y) {
            (30, 5) => SHADOW_BLOCKED,
            (3, 3) => BG,
            _ if x >= 1 => scene(x - 1, y),
            _ => scene(x, y),
        });
        let a = compare_shadow_masks(&reference, &test, 40, 40, 0).unwrap();
        // Column 10 is blocked in the reference and lit in the test; column 20 the reverse.
        assert_eq!(a.blocked_as_lit, 10);
        assert_eq!(a.lit_as_blocked, 10 + 1);
        assert_eq!(a.not_a_shadow, 1);
        // Past the x = 36 background border the shift shows lit pixels where the reference has
        // background: not compared. At the away rows' border the same: not compared.
        assert_eq!(a.agree, a.compared - 22);
        let forgiving = compare_shadow_masks(&reference, &test, 40, 40, 1).unwrap();
        assert_eq!((forgiving.blocked_as_lit, forgiving.lit_as_blocked, forgiving.not_a_shadow), (0, 1, 1));
    }

    #[test]
    fn other_colours_and_blends_are_classed_apart() {
        assert_eq!(MaskClass::of([200, 10, 10, 255]), MaskClass::Other);
        assert_eq!(MaskClass::of([255, 255, 255, 0]), MaskClass::Background);
        let reference = mask(4, 1, |x, _| [SHADOW_LIT, [9, 9, 9, 255], SHADOW_AWAY, BG][x as usize]);
        let test = mask(4, 1, |x, _| [[128, 128, 128, 255], SHADOW_LIT, SHADOW_LIT, SHADOW_LIT][x as usize]);
        let a = compare_shadow_masks(&reference, &test, 4, 1, 3).unwrap();
        let want = MaskAgreement {
            compared: 1,
            not_a_shadow: 1,
            other: 1,
            away: 1,
            background: 1,
            ..Default::default()
        };
        assert_eq!(a, want);
        assert_eq!(a.ratio(), 0.0);
    }

    #[test]
    fn masks_of_the_wrong_size_are_an_error_not_a_panic() {
        let m = mask(4, 4, scene);
        let e = compare_shadow_masks(&m, &m[..60], 4, 4, 1).unwrap_err();
        assert_eq!(e, MaskError::Size { which: "test", len: 60, width: 4, height: 4 });
        assert!(e.to_string().contains("64 bytes"), "{e}");
        assert!(compare_shadow_masks(&m, &m, 8, 2, 1).is_ok(), "same byte count, other shape: allowed");
        assert!(compare_shadow_masks(&m, &m, 3, 4, 1).is_err());
        let image = |w: u32, h: u32| tw_gpu::Image { width: w, height: h, rgba: mask(w, h, scene) };
        assert!(compare_shadow_images(&image(4, 4), &image(4, 4), 1).is_ok());
        assert!(compare_shadow_images(&image(4, 4), &image(2, 8), 1).is_err());
        assert_eq!(compare_shadow_masks(&[], &[], 0, 0, 5).unwrap(), MaskAgreement::default());
    }
}
