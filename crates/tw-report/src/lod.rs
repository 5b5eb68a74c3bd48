//! LOD efficiency: the triangles of a frame's LOD cut against a model of the triangles the
//! screen can use at the cut's pixel error ε.
//!
//! The model. A cut at error ε may replace any geometry by a coarser version whose deviation
//! projects to at most ε pixels (docs/DESIGN.md, D3). A triangle whose edges all project
//! shorter than ε pixels can be collapsed to a point without moving the surface by more than
//! ε, so a cut that spends its error budget fully keeps no such triangle: every visible one
//! spans at least about ε pixels, an area of at least about ε²/2 pixels (a right triangle
//! with legs of ε pixels; an equilateral one, √3/4·ε² ≈ 0.43·ε², is much the same). The
//! pixels the model covers therefore hold at most
//!
//! ```text
//! needed = covered_pixels / (k · ε²),   k = 1/2   (= 2 · covered_pixels / ε²)
//! ```
//!
//! triangles. This is deliberately an upper bound, not an estimate: flat or gently curved
//! surfaces need far larger triangles (a chord of length ℓ on a radius R deviates by ℓ²/8R),
//! so real needs are lower and `cut ÷ needed` under-states the excess. A ratio above 1 is
//! certainly more than the screen can show at ε; a ratio at or below 1 is not proof of a
//! good cut. The cut's triangles include those hidden behind the visible surface (the cut
//! is chosen by error, not by visibility), so the ratio also grows with depth complexity,
//! which occlusion culling, not the LOD, is there to remove.

/// Pixels one triangle covers at the model's density, in units of ε² (k in the module
/// documentation): a triangle with ε-pixel legs covers ε²/2 pixels.
pub const PIXELS_PER_TRIANGLE_PER_EPSILON_SQUARED: f64 = 0.5;

/// The triangles a screen can use at pixel error `error_px` over `covered_pixels` pixels:
/// `covered_pixels / (k·ε²)`, rounded up. `None` for ε = 0 (full detail: no finite model) or
/// an ε that is not a finite positive number; saturates at `u64::MAX` for a tiny ε.
pub fn needed_triangles(covered_pixels: u64, error_px: f64) -> Option<u64> {
    if !(error_px.is_finite() && error_px > 0.0) {
        return None;
    }
    let area = PIXELS_PER_TRIANGLE_PER_EPSILON_SQUARED * error_px * error_px;
    // `as` saturates: an ε so small that the count overflows gives u64::MAX.
    Some((covered_pixels as f64 / area).ceil() as u64)
}

/// LOD efficiency: the cut's triangles ÷ the triangles needed. `None` when nothing is needed
/// (the frame covers no pixel): no finite ratio.
pub fn lod_efficiency(cut_triangles: u64, needed_triangles: u64) -> Option<f64> {
    (needed_triangles > 0).then(|| cut_triangles as f64 / needed_triangles as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn needed_is_two_triangles_per_epsilon_squared_of_coverage() {
        // ε = 1: two triangles a pixel, a 1280×720 screen full of model: 1,843,200.
        assert_eq!(needed_triangles(1280 * 720, 1.0), Some(1_843_200));
        // ε = 2: a quarter of that.
        assert_eq!(needed_triangles(1280 * 720, 2.0), Some(460_800));
        // Rounded up: one covered pixel at ε = 4 (8 pixels a triangle) still needs one.
        assert_eq!(needed_triangles(1, 4.0), Some(1));
        assert_eq!(needed_triangles(0, 1.0), Some(0));
    }

    #[test]
    fn no_model_without_a_positive_finite_error() {
        assert_eq!(needed_triangles(1000, 0.0), None);
        assert_eq!(needed_triangles(1000, -1.0), None);
        assert_eq!(needed_triangles(1000, f64::NAN), None);
        assert_eq!(needed_triangles(1000, f64::INFINITY), None);
        assert_eq!(needed_triangles(1000, 1e-300), Some(u64::MAX));
    }

    #[test]
    fn efficiency_is_cut_over_needed() {
        assert_eq!(lod_efficiency(3_600_000, 400_000), Some(9.0));
        assert_eq!(lod_efficiency(100, 400), Some(0.25));
        assert_eq!(lod_efficiency(100, 0), None);
    }
}
