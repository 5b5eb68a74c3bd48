//! Images read back from the GPU and their comparison (docs/DESIGN.md "Measuring": fidelity is PSNR
//! and the share of differing pixels against the full-detail, no-culling reference; conservative
//! culling means identical images).

use std::path::Path;

use crate::color::BACKGROUND;
use crate::error::GpuError;

/// An RGBA8 image read back from the GPU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// RGBA, 8 bits a channel (sRGB), rows from the top, `width × height × 4` bytes. Alpha is
    /// 255 where geometry was drawn, 0 elsewhere.
    pub rgba: Vec<u8>,
}

impl Image {
    /// Whether pixel `(x, y)` shows geometry.
    pub fn covered(&self, x: u32, y: u32) -> bool {
        if x >= self.width || y >= self.height {
            return false;
        }
        let i = (y as usize * self.width as usize + x as usize) * 4 + 3;
        self.rgba.get(i).is_some_and(|&a| a != 0)
    }

    /// Pixels that show geometry.
    pub fn covered_pixels(&self) -> usize {
        self.rgba.chunks_exact(4).filter(|p| p[3] != 0).count()
    }

    /// The image composited over [`BACKGROUND`], opaque. The renderer clears to transparent
    /// black, so a pixel is premultiplied by its coverage: 255 where geometry covers it, 0
    /// where nothing was drawn, in between on the edges of a multisampled frame ([`crate::msaa`]).
    pub fn opaque(&self) -> Vec<u8> {
        let mut out = self.rgba.clone();
        for p in out.chunks_exact_mut(4) {
            let rest = 255 - p[3] as u32;
            if rest > 0 {
                for c in 0..3 {
                    let v = p[c] as u32 + (rest * BACKGROUND[c] as u32 + 127) / 255;
                    p[c] = v.min(255) as u8;
                }
            }
            p[3] = 255;
        }
        out
    }

    fn check_same_size(&self, other: &Image) -> Result<(), GpuError> {
        let n = self.width as usize * self.height as usize * 4;
        if self.width != other.width
            || self.height != other.height
            || self.rgba.len() != n
            || other.rgba.len() != n
        {
            return Err(GpuError::ImageMismatch {
                a: (self.width, self.height),
                b: (other.width, other.height),
            });
        }
        Ok(())
    }

    /// Pixels whose RGBA differs from `other`'s (any channel, any amount).
    pub fn differing_pixels(&self, other: &Image) -> Result<usize, GpuError> {
        self.check_same_size(other)?;
        Ok(self.rgba.chunks_exact(4).zip(other.rgba.chunks_exact(4)).filter(|(a, b)| a != b).count())
    }

    /// Share (0..=1) of the pixels that differ from `other`'s.
    pub fn differing_share(&self, other: &Image) -> Result<f64, GpuError> {
        let n = self.differing_pixels(other)?;
        Ok(n as f64 / (self.width as f64 * self.height as f64))
    }

    /// Peak signal-to-noise ratio (dB) against `other`, over the R, G and B channels of the
    /// opaque images (background filled, [`Image::opaque`]), peak 255:
    /// `10 · log10(255² / MSE)`; `+∞` for identical images.
    pub fn psnr(&self, other: &Image) -> Result<f64, GpuError> {
        self.check_same_size(other)?;
        let (a, b) = (self.opaque(), other.opaque());
        let mut sum = 0f64;
        for (p, q) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
            for c in 0..3 {
                let d = p[c] as f64 - q[c] as f64;
                sum += d * d;
            }
        }
        let mse = sum / (self.width as f64 * self.height as f64 * 3.0);
        Ok(if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0 * 255.0 / mse).log10() })
    }

    /// The image encoded as an opaque 8-bit RGBA PNG (see [`Image::opaque`]), e.g. for a report.
    pub fn png_bytes(&self) -> Result<Vec<u8>, png::EncodingError> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.width, self.height);
            enc.set_color(png::ColorType::Rgba);
            enc.set_depth(png::BitDepth::Eight);
            enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
            let mut pw = enc.write_header()?;
            pw.write_image_data(&self.opaque())?;
            pw.finish()?;
        }
        Ok(out)
    }

    /// An image decoded from an 8-bit RGBA PNG such as [`png_bytes`](Self::png_bytes) writes
    /// (opaque); other PNG layouts are an error.
    pub fn from_png_bytes(bytes: &[u8]) -> Result<Image, GpuError> {
        let bad = |e: png::DecodingError| GpuError::Gpu(format!("decoding a PNG image: {e}"));
        // Frames up to the renderer's largest side (the default limit is 64 MiB).
        let limits = png::Limits { bytes: 1 << 30 };
        let decoder = png::Decoder::new_with_limits(std::io::Cursor::new(bytes), limits);
        let mut reader = decoder.read_info().map_err(bad)?;
        let info = reader.info();
        let (width, height) = (info.width, info.height);
        if (info.color_type, info.bit_depth) != (png::ColorType::Rgba, png::BitDepth::Eight) {
            return Err(GpuError::Gpu(format!(
                "expected an 8-bit RGBA PNG, got {:?} at {:?}",
                info.color_type, info.bit_depth
            )));
        }
        let mut rgba = vec![0u8; width as usize * height as usize * 4];
        reader.next_frame(&mut rgba).map_err(bad)?;
        Ok(Image { width, height, rgba })
    }

    /// The image as [`opaque`](Self::opaque) gives it, as an image.
    pub fn to_opaque(&self) -> Image {
        Image { width: self.width, height: self.height, rgba: self.opaque() }
    }

    /// Writes the image as [`png_bytes`](Self::png_bytes), atomically (a temporary file beside
    /// `path`, synced, renamed).
    pub fn save_png(&self, path: &Path) -> Result<(), GpuError> {
        let io = |source| GpuError::Io { path: path.to_path_buf(), source };
        tw_core::output::check_replaceable(path)
            .map_err(|e| io(std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string())))?;
        let bytes = self.png_bytes().map_err(|source| GpuError::Png { path: path.to_path_buf(), source })?;
        let mut tmp_name = path.file_name().unwrap_or_default().to_os_string();
        tmp_name.push(".tmp");
        let tmp = path.with_file_name(tmp_name);
        let result = (|| {
            let mut file = std::fs::File::create(&tmp).map_err(io)?;
            std::io::Write::write_all(&mut file, &bytes).map_err(io)?;
            file.sync_all().map_err(io)?;
            std::fs::rename(&tmp, path).map_err(io)
        })();
        if result.is_err() {
            let _ = std::fs::remove_file(&tmp);
        }
        result
    }
}
