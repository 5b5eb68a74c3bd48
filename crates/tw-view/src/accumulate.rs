//! Progressive supersampling for the ray-traced mode (Wald, Dietrich & Slusallek 2004: "no
//! antialiasing while moving; supersampling added progressively when the camera stops"): while
//! nothing changes, each frame traces one more sample per pixel at a new position inside the
//! pixel ([`sample_position`]: the centre first, then the Halton(2, 3) sequence) and the
//! viewer shows the running mean ([`Accumulator`]), up to [`MAX_SAMPLES`].
//!
//! **Averaging in linear light.** A pixel's colour is the mean radiance over its area, and
//! radiance adds linearly; the traced bytes are sRGB-encoded, so they are decoded to linear
//! light before they are summed and encoded again for display. Averaging the encoded bytes
//! instead would darken every edge between a bright and a dark surface (the mean of black and
//! white would show as sRGB 128, i.e. 22 % of white's light, instead of sRGB 188, i.e. 50 %).
//!
//! **Coverage.** A sample that hits nothing is transparent (alpha 0, as in the rasterizer's
//! images). The mean keeps that convention: alpha is the share of samples that hit geometry
//! and the colour is the linear mean of those samples, premultiplied by that share in the
//! stored sRGB bytes — the form [`tw_gpu::Image::opaque`] composites over the background
//! (`p + (1 − α)·background`), so a supersampled silhouette against the empty background blends
//! the way the rasterizer's multisampled edges do.

use std::sync::OnceLock;

/// The most samples per pixel: beyond 64 the mean moves by less than 1/64 of a sample's
/// difference from it, well under one sRGB step on most pixels.
pub const MAX_SAMPLES: u32 = 64;

/// Where sample `k` (0-based) passes through its pixel, in `[0, 1)²` from the pixel's top-left
/// corner: the centre for the first sample (what the rasterizer samples, so a still frame
/// starts as the moving frames look), then point `k` of the Halton(2, 3) sequence, which fills
/// the pixel evenly however many samples have been taken.
pub fn sample_position(k: u32) -> [f32; 2] {
    if k == 0 {
        [0.5, 0.5]
    } else {
        [radical_inverse(2, k), radical_inverse(3, k)]
    }
}

/// `i`'s digits in `base` mirrored around the radix point (van der Corput).
fn radical_inverse(base: u32, mut i: u32) -> f32 {
    let inv = 1.0 / base as f64;
    let (mut scale, mut value) = (inv, 0.0f64);
    while i > 0 {
        value += (i % base) as f64 * scale;
        i /= base;
        scale *= inv;
    }
    value as f32
}

/// The sRGB decoding, per byte (tw-core's).
fn decode_table() -> &'static [f32; 256] {
    tw_core::color::srgb_decode_table()
}

/// Steps of [`encode`]'s table: fine enough that every byte survives decoding and encoding
/// (the darkest step of the encoding, bytes 0 to 1, spans ~20 of them).
const ENCODE_STEPS: usize = 1 << 16;

/// Linear light in `[0, 1]` to an sRGB byte (a table: a `powf` per channel and pixel would
/// cost more than the rest of the mean).
fn encode(l: f32) -> u8 {
    static TABLE: OnceLock<Vec<u8>> = OnceLock::new();
    let table = TABLE.get_or_init(|| {
        (0..ENCODE_STEPS).map(|i| tw_core::color::srgb_encode(i as f32 / (ENCODE_STEPS - 1) as f32)).collect()
    });
    let i = (l.clamp(0.0, 1.0) * (ENCODE_STEPS - 1) as f32).round() as usize;
    table[i.min(ENCODE_STEPS - 1)]
}

/// The running mean of sample images of one size (RGBA, sRGB, rows from the top, alpha 0 where
/// nothing was hit); see the module documentation.
#[derive(Clone, Debug, Default)]
pub struct Accumulator {
    width: u32,
    height: u32,
    samples: u32,
    /// Per pixel: the linear RGB summed over the samples that hit geometry, and their count.
    sums: Vec<[f32; 4]>,
    /// The mean, as shown.
    mean: Vec<u8>,
}

impl Accumulator {
    /// Samples in the mean (0 after [`reset`](Self::reset)).
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Forgets every sample: the next one starts a new mean.
    pub fn reset(&mut self) {
        self.samples = 0;
    }

    /// The mean so far (empty before the first sample).
    pub fn mean(&self) -> &[u8] {
        if self.samples == 0 {
            &[]
        } else {
            &self.mean
        }
    }

    /// Adds one `width × height` sample image and returns the new mean; a size other than the
    /// samples' so far starts a new mean. `None` (nothing added) when `rgba` does not hold
    /// `width × height` pixels.
    pub fn add(&mut self, width: u32, height: u32, rgba: &[u8]) -> Option<&[u8]> {
        let pixels = width as usize * height as usize;
        if rgba.len() != pixels * 4 {
            return None;
        }
        if (width, height) != (self.width, self.height) || self.samples == 0 {
            self.width = width;
            self.height = height;
            self.samples = 0;
            self.sums.clear();
            self.sums.resize(pixels, [0.0; 4]);
            self.mean.resize(pixels * 4, 0);
        }
        self.samples += 1;
        let n = self.samples;
        let decode = decode_table();
        for ((sum, out), p) in
            self.sums.iter_mut().zip(self.mean.chunks_exact_mut(4)).zip(rgba.chunks_exact(4))
        {
            if p[3] != 0 {
                for c in 0..3 {
                    sum[c] += decode[p[c] as usize];
                }
                sum[3] += 1.0;
            }
            resolve(sum, n, out);
        }
        Some(&self.mean)
    }
}

/// One pixel of the mean of `n` samples from its sums (see the module documentation).
fn resolve(sum: &[f32; 4], n: u32, out: &mut [u8]) {
    let hits = sum[3];
    if hits == 0.0 {
        out.copy_from_slice(&[0; 4]);
        return;
    }
    let coverage = hits / n as f32;
    for c in 0..3 {
        let straight = encode(sum[c] / hits) as f32;
        out[c] = (straight * coverage).round() as u8;
    }
    out[3] = (255.0 * coverage).round() as u8;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_sample_is_the_centre_then_halton_2_3() {
        assert_eq!(sample_position(0), [0.5, 0.5]);
        assert_eq!(sample_position(1), [0.5, 1.0 / 3.0]);
        assert_eq!(sample_position(2), [0.25, 2.0 / 3.0]);
        assert_eq!(sample_position(3), [0.75, 1.0 / 9.0]);
        let all: Vec<[f32; 2]> = (0..MAX_SAMPLES).map(sample_position).collect();
        assert!(all.iter().flatten().all(|v| (0.0..1.0).contains(v)));
        // Distinct positions, spread over the pixel: every quarter of it gets a fair share.
        for (i, a) in all.iter().enumerate() {
            assert!(all[i + 1..].iter().all(|b| a != b), "{a:?} repeats");
        }
        for q in 0..4 {
            let (x0, y0) = ((q % 2) as f32 * 0.5, (q / 2) as f32 * 0.5);
            let n = all
                .iter()
                .filter(|p| (x0..x0 + 0.5).contains(&p[0]) && (y0..y0 + 0.5).contains(&p[1]))
                .count();
            assert!((12..=20).contains(&n), "quarter {q}: {n} of {MAX_SAMPLES}");
        }
    }

    #[test]
    fn every_byte_survives_decoding_and_encoding() {
        let d = decode_table();
        for b in 0..=255u8 {
            assert_eq!(encode(d[b as usize]), b);
        }
    }

    #[test]
    fn one_sample_is_shown_as_traced() {
        let img: Vec<u8> = (0..4 * 6).map(|i| if i % 4 == 3 { 255 } else { (i * 37 % 256) as u8 }).collect();
        let mut a = Accumulator::default();
        assert_eq!(a.add(3, 2, &img), Some(&img[..]));
        assert_eq!(a.samples(), 1);
        // Transparent pixels stay transparent black.
        let mut empty = img.clone();
        empty[..4].copy_from_slice(&[0; 4]);
        a.reset();
        assert_eq!(&a.add(3, 2, &empty).unwrap()[..4], &[0, 0, 0, 0]);
    }

    #[test]
    fn the_mean_is_taken_in_linear_light() {
        let mut a = Accumulator::default();
        a.add(1, 1, &[0, 0, 0, 255]);
        // Black and white average to half the light: sRGB 188, not 128.
        assert_eq!(a.add(1, 1, &[255, 255, 255, 255]), Some(&[188u8, 188, 188, 255][..]));
        assert_eq!(a.samples(), 2);
        // Equal samples leave the mean as it is, however many.
        let mut a = Accumulator::default();
        for _ in 0..MAX_SAMPLES {
            a.add(1, 1, &[200, 100, 30, 255]);
        }
        assert_eq!(a.mean(), &[200, 100, 30, 255]);
    }

    #[test]
    fn partial_coverage_is_premultiplied_alpha() {
        // One sample of four hits a white surface: a quarter covered, white at a quarter.
        let mut a = Accumulator::default();
        for hit in [true, false, false, false] {
            a.add(1, 1, if hit { &[255, 255, 255, 255] } else { &[0, 0, 0, 0] });
        }
        assert_eq!(a.mean(), &[64, 64, 64, 64]);
        // Composited over the background, that is a quarter of the way from it to white.
        let img = tw_gpu::Image { width: 1, height: 1, rgba: a.mean().to_vec() };
        let bg = tw_gpu::BACKGROUND;
        let o = img.opaque();
        for c in 0..3 {
            let want = bg[c] as f32 + (255.0 - bg[c] as f32) * 0.25;
            assert!((o[c] as f32 - want).abs() <= 1.0, "{o:?}");
        }
    }

    #[test]
    fn a_new_size_or_reset_starts_again_and_bad_input_is_refused() {
        let mut a = Accumulator::default();
        a.add(1, 1, &[10, 10, 10, 255]);
        a.add(1, 1, &[250, 250, 250, 255]);
        assert_eq!(a.samples(), 2);
        assert_eq!(a.add(2, 1, &[9, 9, 9, 255, 9, 9, 9, 255]), Some(&[9u8, 9, 9, 255, 9, 9, 9, 255][..]));
        assert_eq!(a.samples(), 1);
        assert_eq!(a.add(2, 2, &[0; 4]), None, "too few pixels");
        assert_eq!(a.samples(), 1);
        a.reset();
        assert_eq!(a.mean(), &[] as &[u8]);
        assert_eq!(a.add(1, 1, &[7, 7, 7, 255]), Some(&[7u8, 7, 7, 255][..]));
    }
}
