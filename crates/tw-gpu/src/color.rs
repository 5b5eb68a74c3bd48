//! Colours: where a triangle's colour comes from ([`ColorMode`]) and the CPU versions of the
//! debug palettes that draw.wgsl computes on the GPU (the object hash and the LOD-level palette,
//! defined in `tw_core::color` so that the ray tracer colours the same way).

pub use tw_core::color::{hash_color, level_color, ColorMode, BACKGROUND, DEFAULT_COLOR};

/// The shader's code for `mode` (draw.wgsl `base_color`).
pub(crate) fn mode_code(mode: ColorMode) -> u32 {
    match mode {
        ColorMode::Material => 0,
        ColorMode::Object => 1,
        ColorMode::Level => 2,
        ColorMode::Cluster => 3,
        ColorMode::Shadow => 4,
    }
}

/// Packs an sRGB colour the way draw.wgsl's `unpack_srgb` reads it.
pub(crate) fn pack(c: [u8; 4]) -> u32 {
    u32::from_le_bytes(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_is_little_endian_rgba() {
        assert_eq!(pack([1, 2, 3, 4]), 0x0403_0201);
    }
}
