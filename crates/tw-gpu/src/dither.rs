//! Screen-door cross-fades of LOD switches (`--transition dither`, docs/RUNTIME.md
//! "Transitions"): while a group switches level, the clusters that left the cut and those that
//! entered are both drawn for a few frames, each keeping a complementary part of the pixels
//! (screen-door transparency: Mulder, Groen & van Wijk, "Pixel masks for screen-door
//! transparency", IEEE Visualization 1998, §2), so the switch is spread over those frames.
//!
//! A cluster's **fade word** (its slot record's `fade`, common.wgsl `Slot`) says which part it
//! keeps: 0 every pixel; otherwise bits 30–31 the side ([`Fade::Entering`] or
//! [`Fade::Leaving`]) and bits 0–15 the threshold t (0..=65536 for 0..=1, [`T_ONE`]). A pixel's
//! rank h is its cell of an 8 × 8 ordered dither matrix (Bayer, "An optimum method for
//! two-level rendition of continuous-tone pictures", ICC 1973), fixed on the screen: an
//! entering cluster keeps the pixels with h < t, a leaving one those with h ≥ t. Both halves of
//! one switch carry the same t, so every pixel sees exactly one of them: no crack, no doubled
//! surface. The shaders' test is common.wgsl `dither_keeps`; [`keeps`] is the same arithmetic.

/// t = 1 in a fade word's threshold bits.
pub const T_ONE: u32 = 1 << 16;

/// Which half of a switch a cluster is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Fade {
    /// Entered the cut: keeps the pixels whose rank is below t (more of them as t grows).
    Entering,
    /// Left the cut: keeps the pixels whose rank is at or above t.
    Leaving,
}

/// The fade word of `side` at threshold `t` (clamped to 0..=1).
pub fn fade_word(side: Fade, t: f32) -> u32 {
    let t = (t.clamp(0.0, 1.0) * T_ONE as f32).round() as u32;
    let side = match side {
        Fade::Entering => 1u32,
        Fade::Leaving => 2,
    };
    (side << 30) | t.min(T_ONE)
}

/// The rank of pixel (x, y) in the 8 × 8 Bayer matrix, 0..64: each bit pair of the coordinates
/// picks a cell of the 2 × 2 matrix [[0, 2], [3, 1]], the lowest bits weighing most, so that
/// consecutive ranks are spread over the tile.
pub fn bayer8(x: u32, y: u32) -> u32 {
    let mut rank = 0;
    for bit in 0..3 {
        let (bx, by) = ((x >> bit) & 1, (y >> bit) & 1);
        rank = rank * 4 + (((bx ^ by) << 1) | by);
    }
    rank
}

/// The rank of pixel (x, y) on the threshold's scale: the centre of its cell, (rank + ½) / 64.
pub fn pixel_rank(x: u32, y: u32) -> u32 {
    bayer8(x & 7, y & 7) * (T_ONE / 64) + T_ONE / 128
}

/// Whether a cluster with fade word `word` draws pixel (x, y) (common.wgsl `dither_keeps`).
pub fn keeps(x: u32, y: u32, word: u32) -> bool {
    let t = word & 0x1_ffff;
    let h = pixel_rank(x, y);
    match word >> 30 {
        1 => h < t,
        2 => h >= t,
        _ => true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_matrix_holds_each_rank_once() {
        let mut seen = [false; 64];
        for y in 0..8 {
            for x in 0..8 {
                let r = bayer8(x, y) as usize;
                assert!(!seen[r], "rank {r} twice");
                seen[r] = true;
            }
        }
        // The 2 × 2 matrix at the coarsest level: ranks 0..4 are spread over the tile.
        assert_eq!(bayer8(0, 0), 0);
        assert_eq!(bayer8(1, 1), 16);
    }

    #[test]
    fn both_halves_of_a_switch_cover_every_pixel_once() {
        for k in 0..=9 {
            let t = k as f32 / 9.0;
            let (a, b) = (fade_word(Fade::Entering, t), fade_word(Fade::Leaving, t));
            let mut entering = 0;
            for y in 0..16 {
                for x in 0..16 {
                    assert_ne!(keeps(x, y, a), keeps(x, y, b), "pixel ({x}, {y}) at t = {t}");
                    entering += keeps(x, y, a) as u32;
                }
            }
            // The share kept follows t within one cell of the 64.
            let share = entering as f32 / 256.0;
            assert!((share - t).abs() <= 1.0 / 64.0, "t = {t}: share {share}");
        }
    }

    #[test]
    fn the_ends_keep_all_or_nothing_and_zero_keeps_all() {
        for (x, y) in [(0, 0), (7, 7), (3, 5), (100, 37)] {
            assert!(keeps(x, y, 0));
            assert!(keeps(x, y, fade_word(Fade::Entering, 1.0)));
            assert!(!keeps(x, y, fade_word(Fade::Leaving, 1.0)));
            assert!(!keeps(x, y, fade_word(Fade::Entering, 0.0)));
            assert!(keeps(x, y, fade_word(Fade::Leaving, 0.0)));
        }
    }
}
