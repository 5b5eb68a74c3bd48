//! Colours as importers and the store carry them, and the palettes renderers colour by (the
//! rasterizer's draw.wgsl and the ray tracer use the same ones).

/// An sRGB colour with straight alpha, 8 bits per channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct Rgba8(pub [u8; 4]);

impl Rgba8 {
    pub const WHITE: Rgba8 = Rgba8([255, 255, 255, 255]);
    pub const GREY: Rgba8 = Rgba8([180, 180, 180, 255]);

    pub const fn rgb(r: u8, g: u8, b: u8) -> Rgba8 {
        Rgba8([r, g, b, 255])
    }

    /// From linear-ish floats in 0..=1 (values are clamped; NaN maps to 0).
    pub fn from_f32(c: [f32; 4]) -> Rgba8 {
        let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
        Rgba8([q(c[0]), q(c[1]), q(c[2]), q(c[3])])
    }

    pub fn to_f32(self) -> [f32; 4] {
        self.0.map(|v| v as f32 / 255.0)
    }
}

/// Where a triangle's colour comes from (both renderers: tw-gpu's draw.wgsl, tw-rt).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ColorMode {
    /// The object's colour from the store's object table, [`DEFAULT_COLOR`] without one.
    #[default]
    Material,
    /// A colour from a hash of the object id.
    Object,
    /// A colour per LOD level (0 = full resolution).
    Level,
    /// A colour from a hash of the cluster: [`cluster_color`].
    Cluster,
    /// The shadow mask of the light (`--light`): [`SHADOW_LIT`] where the light reaches the
    /// surface, [`SHADOW_BLOCKED`] where something blocks it, [`SHADOW_AWAY`] where the surface
    /// faces away from it — flat, unshaded, so that two renderers' shadows compare pixel by pixel.
    Shadow,
}

/// [`ColorMode::Shadow`]: a surface the light reaches (sRGB).
pub const SHADOW_LIT: [u8; 4] = [255, 255, 255, 255];
/// [`ColorMode::Shadow`]: a surface facing the light whose light is blocked (sRGB).
pub const SHADOW_BLOCKED: [u8; 4] = [0, 0, 0, 255];
/// [`ColorMode::Shadow`]: a surface facing away from the light (sRGB).
pub const SHADOW_AWAY: [u8; 4] = [128, 128, 128, 255];

/// The flat colour of the back faces a section reveals (sRGB; tw-gpu draw.wgsl `fs_main`): the
/// inside of a cut solid reads as a cut, not as more surface.
pub const SECTION: [u8; 4] = [200, 30, 60, 255];

/// The picked object's tint (sRGB): its colour, in every colour mode, is drawn half-way to this
/// orange ([`highlight`]).
pub const HIGHLIGHT: [u8; 4] = [255, 140, 0, 255];

/// `color` blended half-way to [`HIGHLIGHT`] (sRGB, per channel): how the rasterizer's shader
/// and the ray tracer's picture tint the picked object.
pub fn highlight(color: [u8; 4]) -> [u8; 4] {
    std::array::from_fn(|i| ((color[i] as u16 + HIGHLIGHT[i] as u16) / 2) as u8)
}

/// Colour of objects without one in the store (sRGB).
pub const DEFAULT_COLOR: [u8; 4] = [180, 180, 180, 255];

/// Background (sRGB) that tw-gpu's `Image::save_png` puts where nothing was drawn.
pub const BACKGROUND: [u8; 3] = [205, 218, 235];

/// A distinct, fairly saturated sRGB colour for an id (MurmurHash3's finaliser, then HSV; tw-gpu's
/// draw.wgsl computes the same in f32).
pub fn hash_color(id: u32) -> [u8; 4] {
    let [r, g, b] = hash_color_f64(id).map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
    [r, g, b, 255]
}

/// [`hash_color`] before quantization, channels in 0..=1 (tw-preview shades with it).
pub fn hash_color_f64(id: u32) -> [f64; 3] {
    let mut h = id.wrapping_add(0x9e37_79b9);
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^= h >> 16;
    let hue = (h & 0xffff) as f64 / 65536.0 * 6.0;
    let sat = 0.45 + 0.35 * ((h >> 16) & 0xff) as f64 / 255.0;
    let val = 0.75 + 0.25 * (h >> 24) as f64 / 255.0;
    let f = hue.fract();
    let (p, q, t) = (val * (1.0 - sat), val * (1.0 - sat * f), val * (1.0 - sat * (1.0 - f)));
    match hue as u32 {
        0 => [val, t, p],
        1 => [q, val, p],
        2 => [p, val, t],
        3 => [p, q, val],
        4 => [t, p, val],
        _ => [val, p, q],
    }
}

/// The colour of LOD level `level`: full resolution green, then yellow, orange, red, magenta,
/// blue, cyan, repeating.
pub fn level_color(level: u8) -> [u8; 4] {
    const PALETTE: [[u8; 4]; 8] = [
        [80, 200, 90, 255],
        [220, 210, 70, 255],
        [240, 150, 50, 255],
        [225, 70, 60, 255],
        [200, 80, 200, 255],
        [90, 110, 230, 255],
        [70, 200, 220, 255],
        [240, 240, 240, 255],
    ];
    PALETTE[level as usize % PALETTE.len()]
}

/// The colour of cluster `index_in_page` of page `page` (draw.wgsl hashes the same key).
pub fn cluster_color(page: u32, index_in_page: u32) -> [u8; 4] {
    hash_color(page.wrapping_mul(0x9e37_79b9) ^ index_in_page)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float_round_trip_and_clamping() {
        assert_eq!(Rgba8::from_f32([0.0, 1.0, 2.0, f32::NAN]), Rgba8([0, 255, 255, 0]));
        let c = Rgba8([12, 34, 56, 78]);
        assert_eq!(Rgba8::from_f32(c.to_f32()), c);
    }

    #[test]
    fn hash_colors_differ_between_ids() {
        let colors: std::collections::HashSet<_> = (0..64).map(hash_color).collect();
        assert!(colors.len() > 50);
    }

    #[test]
    fn level_colors_cycle() {
        assert_ne!(level_color(0), level_color(1));
        assert_eq!(level_color(0), level_color(8));
    }
}

/// The sRGB transfer function's decoding (IEC 61966-2-1), per encoded byte: linear light 0..1.
/// One table for every place that averages colours in linear light (the supersampled reference,
/// the viewer's progressive ray tracing).
pub fn srgb_decode_table() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|b| {
            let c = b as f64 / 255.0;
            let l = if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) };
            l as f32
        })
    })
}

/// The sRGB transfer function's encoding: linear light (clamped to 0..1) → the byte, rounded to
/// nearest; every byte survives [`srgb_decode_table`] and back.
pub fn srgb_encode(l: f32) -> u8 {
    let l = l.clamp(0.0, 1.0) as f64;
    let c = if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
    (c * 255.0).round().clamp(0.0, 255.0) as u8
}

#[cfg(test)]
mod srgb_tests {
    use super::*;

    #[test]
    fn every_byte_survives_decoding_and_encoding() {
        let decode = srgb_decode_table();
        for b in 0..=255u8 {
            assert_eq!(srgb_encode(decode[b as usize]), b);
        }
        assert_eq!((srgb_encode(0.0), srgb_encode(1.0), srgb_encode(0.5)), (0, 255, 188));
    }
}
