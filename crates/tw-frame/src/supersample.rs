//! The supersampled ground-truth reference (`bench --reference-samples N`).
//!
//! A 1-sample frame is aliased: a full-detail frame and a LOD frame alias differently, and the
//! PSNR between them mixes the LOD's error with two different aliasing patterns. Against a
//! reference with many samples per pixel, both the LOD frame and the brute-force full-detail
//! frame at the run's samples can be measured, and their difference is the LOD's own share.
//!
//! CPU drivers offer at most 4× MSAA ([`tw_gpu::SUPPORTED_SAMPLES`]), so the reference is an
//! ordered-grid supersample instead: the full-detail scene drawn once into an s·width × s·height
//! target (one sample a pixel), then box-filtered down by s × s. One draw of the full-detail
//! scene, rather than N sub-pixel-jittered draws, matters at 10^8 triangles, where one draw
//! takes tens of seconds on lavapipe. When s·width or s·height exceeds the device's largest
//! texture, [`Walkthrough::reference_supersampled`] fails with an error naming both sizes
//! (fewer samples or a smaller `--size` fits); it does not fall back to jittered draws.
//!
//! The renderer's colour bytes are sRGB-encoded (`Rgba8Unorm` written by the shader,
//! tw-gpu's `COLOR_FORMAT`), so each sub-pixel is composited over the background as
//! [`Image::opaque`] does, decoded to linear light, averaged, and encoded back: averaging
//! encoded bytes would darken every edge between a light and a dark surface.

use tw_core::color::{srgb_decode_table, srgb_encode};
use tw_gpu::{wgpu, GpuError, Image, Renderer, Target, BACKGROUND};
use tw_runtime::Camera;

use crate::{FrameError, Walkthrough};

/// The `--reference-samples` counts: 1 (no supersampling) and the squares s² of s = 2, 4, 8.
pub const REFERENCE_SAMPLES: [u32; 4] = [1, 4, 16, 64];

/// The side s of the s × s grid of `samples` per pixel, `None` for a count not in
/// [`REFERENCE_SAMPLES`].
pub fn grid_side(samples: u32) -> Option<u32> {
    REFERENCE_SAMPLES.contains(&samples).then(|| (samples as f64).sqrt().round() as u32)
}

/// The grid side s of `samples` per pixel for `renderer`'s frames, or an error when `samples` is
/// not one of [`REFERENCE_SAMPLES`] or the s·width × s·height target exceeds the device's
/// largest texture: for callers to check before rendering anything.
pub fn check_grid(renderer: &Renderer, samples: u32) -> Result<u32, GpuError> {
    let side = grid_side(samples).ok_or_else(|| {
        GpuError::Gpu(format!(
            "{samples} reference samples per pixel: expected one of {REFERENCE_SAMPLES:?} (s × s grids)"
        ))
    })?;
    let (w, h) = renderer.size();
    let size = (w as u64 * side as u64, h as u64 * side as u64);
    let max = renderer.device().0.limits().max_texture_dimension_2d;
    if size.0 > max as u64 || size.1 > max as u64 {
        return Err(GpuError::Gpu(format!(
            "a {samples}-sample reference of a {w}×{h} frame needs a {}×{} target, over this \
             device's largest texture ({max}×{max}): use fewer reference samples or a smaller size",
            size.0, size.1
        )));
    }
    Ok(side)
}

/// Readback strips of the large target hold at most this many bytes (padded rows).
const STRIP_BYTES: u64 = 32 << 20;

/// `image` (side·w × side·h) box-filtered down to w × h in linear light: each output pixel is
/// the mean of its side × side sub-pixels, each composited over the background first. The
/// result is opaque (alpha 255), as a PSNR compares images ([`Image::psnr`]).
pub fn box_filter(image: &Image, side: u32) -> Result<Image, GpuError> {
    let (w, h) = (image.width, image.height);
    let n = w as usize * h as usize * 4;
    if side == 0 || w % side != 0 || h % side != 0 || image.rgba.len() != n {
        return Err(GpuError::Gpu(format!(
            "cannot box-filter a {w}×{h} image ({} bytes) by {side} × {side}: sides must be \
             multiples of {side} and the image {n} bytes",
            image.rgba.len()
        )));
    }
    let mut out = Vec::with_capacity(n / (side * side) as usize);
    filter_rows(&image.rgba, w, side, &mut out);
    Ok(Image { width: w / side, height: h / side, rgba: out })
}

/// Appends the filtered rows of `rows` (whole rows of `width` RGBA pixels, a multiple of `side`
/// of them) to `out`: `width / side` pixels for every `side` rows.
fn filter_rows(rows: &[u8], width: u32, side: u32, out: &mut Vec<u8>) {
    let (width, side) = (width as usize, side as usize);
    let decode = srgb_decode_table();
    let row_bytes = width * 4;
    let count = (side * side) as f32;
    let mut sums = vec![[0f32; 3]; width / side];
    for band in rows.chunks_exact(row_bytes * side) {
        sums.iter_mut().for_each(|s| *s = [0.0; 3]);
        for row in band.chunks_exact(row_bytes) {
            for (x, p) in row.chunks_exact(4).enumerate() {
                let sum = &mut sums[x / side];
                for (c, s) in sum.iter_mut().enumerate() {
                    *s += decode[over_background(p, c) as usize];
                }
            }
        }
        for s in &sums {
            out.extend(s.map(|v| srgb_encode(v / count)));
            out.push(255);
        }
    }
}

/// Channel `c` of the premultiplied pixel `p` composited over [`BACKGROUND`], encoded (the
/// same arithmetic as [`Image::opaque`], so that a 1 × 1 grid gives that image exactly).
fn over_background(p: &[u8], c: usize) -> u8 {
    let rest = 255 - p[3] as u32;
    (p[c] as u32 + (rest * BACKGROUND[c] as u32 + 127) / 255).min(255) as u8
}

impl Walkthrough {
    /// The full-detail reference of `camera` ([`reference`](Self::reference): every
    /// full-resolution cluster, no culling) supersampled with `samples` per pixel (one of
    /// [`REFERENCE_SAMPLES`]) on an ordered s × s grid: drawn at one sample a pixel into an
    /// s·width × s·height target, then [`box_filter`]ed in linear light, read back in strips.
    /// The renderer's samples per pixel are restored afterwards, whatever happens.
    pub fn reference_supersampled(&mut self, camera: &Camera, samples: u32) -> Result<Image, FrameError> {
        let side = check_grid(&self.renderer, samples)?;
        let (w, h) = self.renderer.size();
        let size = (w * side, h * side);
        let previous = self.renderer.samples();
        self.renderer.set_samples(1)?;
        let result = self.draw_supersampled(camera, size, side);
        self.renderer.set_samples(previous)?;
        result
    }

    /// Draws the full-detail scene into a new target of `size` and returns it box-filtered by
    /// `side`.
    fn draw_supersampled(
        &mut self,
        camera: &Camera,
        size: (u32, u32),
        side: u32,
    ) -> Result<Image, FrameError> {
        const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
        let texture = self.renderer.device().0.create_texture(&wgpu::TextureDescriptor {
            label: Some("supersampled reference"),
            size: wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let selection = self.full_detail(camera);
        let grid_step = self.streamer.store().header().grid_step;
        self.renderer.begin_frame();
        let target = Target::View { view: &view, format: FORMAT, size };
        let mut first = true;
        self.for_each_chunk(&selection, |renderer, clusters| {
            renderer.draw(target, camera, grid_step, clusters, first)?;
            first = false;
            Ok(())
        })?;
        if first {
            self.renderer.draw(target, camera, grid_step, &[], true)?;
        }
        Ok(read_filtered(&self.renderer, &texture, side)?)
    }
}

/// Reads `texture` (RGBA8) back in strips of whole `side`-row bands and box-filters each as it
/// arrives, so the full-size image is never held on the CPU.
fn read_filtered(renderer: &Renderer, texture: &wgpu::Texture, side: u32) -> Result<Image, GpuError> {
    let (device, queue) = renderer.device();
    let (width, height) = (texture.width(), texture.height());
    let row = width * 4;
    let pitch = row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let bands = (STRIP_BYTES / (pitch as u64 * side as u64)).max(1) as u32;
    let strip_rows = (bands * side).min(height);
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("supersampled reference readback"),
        size: pitch as u64 * strip_rows as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut out = Vec::with_capacity((width / side) as usize * (height / side) as usize * 4);
    let mut rows = Vec::with_capacity(row as usize * strip_rows as usize);
    let mut y = 0;
    while y < height {
        let n = strip_rows.min(height - y);
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                origin: wgpu::Origin3d { x: 0, y, z: 0 },
                ..texture.as_image_copy()
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(pitch),
                    rows_per_image: Some(n),
                },
            },
            wgpu::Extent3d { width, height: n, depth_or_array_layers: 1 },
        );
        queue.submit([encoder.finish()]);
        rows.clear();
        tw_gpu::map_read(device, &buffer, pitch as usize, n as usize, |r| {
            rows.extend_from_slice(&r[..row as usize])
        })?;
        filter_rows(&rows, width, side, &mut out);
        y += n;
    }
    Ok(Image { width: width / side, height: height / side, rgba: out })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(width: u32, height: u32, pixels: &[[u8; 4]]) -> Image {
        Image { width, height, rgba: pixels.iter().flatten().copied().collect() }
    }

    #[test]
    fn only_square_grids_are_accepted() {
        assert_eq!(REFERENCE_SAMPLES.map(grid_side), [Some(1), Some(2), Some(4), Some(8)]);
        for bad in [0, 2, 3, 8, 9, 25, 256] {
            assert_eq!(grid_side(bad), None, "{bad}");
        }
    }

    #[test]
    fn the_srgb_curve_round_trips_every_byte() {
        let decode = srgb_decode_table();
        for v in 0..=255u8 {
            assert_eq!(srgb_encode(decode[v as usize]), v);
        }
    }

    #[test]
    fn black_and_white_average_in_linear_light() {
        // Half the sub-pixels white, half black: linear 0.5, sRGB 0.7354 · 255 = 187.5 → 188,
        // not the 128 (or 127) of averaging the encoded bytes.
        let (b, w) = ([0, 0, 0, 255], [255, 255, 255, 255]);
        let out = box_filter(&image(2, 2, &[b, w, w, b]), 2).unwrap();
        assert_eq!((out.width, out.height), (1, 1));
        assert_eq!(out.rgba, vec![188, 188, 188, 255]);
    }

    #[test]
    fn each_output_pixel_averages_its_own_block() {
        // A 4×2 image, two 2×2 blocks: the left all one colour, the right with an uncovered
        // (transparent) sub-pixel that counts as the background.
        let (c, t) = ([200, 100, 50, 255], [0, 0, 0, 0]);
        let px = [c, c, c, c, c, c, c, t];
        let out = box_filter(&image(4, 2, &px), 2).unwrap();
        assert_eq!((out.width, out.height), (2, 1));
        assert_eq!(&out.rgba[..4], &[200, 100, 50, 255]);
        let decode = srgb_decode_table();
        for ch in 0..3 {
            let mean = (3.0 * decode[c[ch] as usize] + decode[BACKGROUND[ch] as usize]) / 4.0;
            assert_eq!(out.rgba[4 + ch], srgb_encode(mean), "channel {ch}");
        }
    }

    #[test]
    fn a_one_by_one_grid_is_the_opaque_image() {
        let px = [[10, 20, 30, 255], [0, 0, 0, 0], [255, 1, 128, 255], [7, 7, 7, 255]];
        let img = image(2, 2, &px);
        assert_eq!(box_filter(&img, 1).unwrap(), img.to_opaque());
    }

    #[test]
    fn sizes_that_do_not_divide_are_errors() {
        let img = image(3, 2, &[[0, 0, 0, 255]; 6]);
        let e = box_filter(&img, 2).unwrap_err().to_string();
        assert!(e.contains("3×2") && e.contains("multiples of 2"), "{e}");
        assert!(box_filter(&img, 0).is_err());
    }
}
