//! Colours as importers and the store carry them.

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float_round_trip_and_clamping() {
        assert_eq!(Rgba8::from_f32([0.0, 1.0, 2.0, f32::NAN]), Rgba8([0, 255, 255, 0]));
        let c = Rgba8([12, 34, 56, 78]);
        assert_eq!(Rgba8::from_f32(c.to_f32()), c);
    }
}
