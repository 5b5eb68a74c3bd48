//! Keeping last frame's shadow-map layers where they still serve: the scene and the light stand
//! still while the eye walks, so a layer drawn last frame is still a correct shadow map of the
//! light — for its own matrix. It can serve this frame's cascade when
//! 1. the light, the map size, the bias and the number of layers are the same (the fit keeps
//!    the bias put as the eye moves, src/shadow/fit.rs "Stable from frame to frame");
//! 2. the layer's light clip space holds the whole box this frame's fit gave the cascade (its
//!    window and depth range: every receiver point the cascade serves, and every caster between
//!    them and the light, since both layers start at the scene's side nearest the light), and
//! 3. its texels are at most [`MAX_COARSENING`] times wider than this frame's fit asks for.
//!
//! Then the cascade takes the old layer's matrix and keeps its own split, and the lookup rule
//! ([`super::Shadows::lit`]) gives what it gave last frame for every point of the split. A point
//! light's faces depend only on the light and the scene, so they serve while they are equal.
//! Whether the casters drawn into the layer still match the eye's level of detail is the
//! caller's check ([`lod_within_bias`]): the layer holds last frame's light-view set.

use glam::{Mat4, Vec3, Vec4};

use crate::light::Light;
use crate::shadow::fit::texel_size;
use crate::shadow::Shadows;

/// How much wider than this frame's fit asks a reused layer's texels may be: √2, two steps of
/// the fit's 2^¼ quantization of the window side.
pub const MAX_COARSENING: f32 = std::f32::consts::SQRT_2;

/// Slack of the containment test in light clip units (a hair of rounding of the matrices).
const CLIP_SLACK: f32 = 1e-5;

/// Of the depth bias, the share the level of detail of a reused layer's casters may take: their
/// surfaces may be this far from this frame's (in scene units, `LOD_SHARE · bias_texels`
/// texels) before the layer is drawn again. The rest of the bias is left for the slope it is
/// there for (src/shadow/fit.rs "Bias").
pub const LOD_SHARE: f32 = 0.25;

/// Where `current`'s layers can take `previous`'s (module documentation): per layer, whether it
/// did; those layers now hold `previous`'s matrices. `needs`: per sun cascade, the scene-space
/// corners of the box it must hold (empty for a point light's faces, which serve while equal).
/// Nothing is reused across a change of light, size, bias or layer count.
pub(crate) fn reuse_layers(current: &mut Shadows, needs: &[[Vec3; 8]], previous: &Shadows) -> Vec<bool> {
    let comparable = current.light == previous.light
        && current.size == previous.size
        && current.bias == previous.bias
        && current.layers.len() == previous.layers.len();
    if !comparable {
        return vec![false; current.layers.len()];
    }
    (0..current.layers.len())
        .map(|i| {
            let (old, new) = (previous.layers[i].view_proj, current.layers[i].view_proj);
            let serves = old == new
                || needs.get(i).is_some_and(|need| {
                    coarsening(previous, current, i) <= MAX_COARSENING && holds(&old, need)
                });
            if serves {
                current.layers[i].view_proj = old;
            }
            serves
        })
        .collect()
}

/// How many times wider layer `i`'s texels are in `previous` than in `current`.
fn coarsening(previous: &Shadows, current: &Shadows, i: usize) -> f32 {
    match (texel_size(previous, i), texel_size(current, i)) {
        (Some(old), Some(new)) if new > 0.0 => old / new,
        _ => f32::INFINITY,
    }
}

/// Whether the light clip space of `layer` (x, y in −1..=1, depth in 0..=1) holds the scene
/// points `points`: for a box's corners under a parallel projection, the whole box.
fn holds(layer: &Mat4, points: &[Vec3; 8]) -> bool {
    points.iter().all(|&p| {
        let c = *layer * Vec4::new(p.x, p.y, p.z, 1.0);
        if c.w.is_nan() || c.w <= 0.0 {
            return false;
        }
        let n = c.truncate() / c.w;
        // Near the light the box ends at the scene's side nearest it, where both layers start
        // (a hair of rounding either way); elsewhere it must be inside by the slack.
        n.x.abs() <= 1.0 - CLIP_SLACK
            && n.y.abs() <= 1.0 - CLIP_SLACK
            && (-CLIP_SLACK..=1.0 - CLIP_SLACK).contains(&n.z)
    })
}

/// Whether a reused layer's casters, drawn at last frame's level of detail, are close enough to
/// this frame's: `moved` is the largest simplification error (scene units) of the clusters that
/// left the layer's light-view set plus that of the clusters that entered it — the two surfaces
/// are at most that far apart — and `at` a point among them (for a point light, whose texels
/// widen with distance, the nearest one to the light). It must stay within [`LOD_SHARE`] of the
/// bias, `bias_texels` texels' worth of scene units at `at`.
pub fn lod_within_bias(shadows: &Shadows, layer: usize, bias_texels: f32, moved: f32, at: Vec3) -> bool {
    if moved <= 0.0 {
        return true;
    }
    let Some(texel) = texel_size(shadows, layer) else { return false };
    let texel = match shadows.light {
        Light::Sun { .. } => texel,
        Light::Point { position } => texel * (at - position).length(),
    };
    moved <= LOD_SHARE * bias_texels * texel
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::shadow::fit::refit_layers;
    use crate::shadow::fit::tests::{receivers, scene};
    use crate::shadow::{fit_layers, ShadowOptions};

    fn eye(x: f32) -> Camera {
        Camera::new(Vec3::new(x, -30.0, 2.0), Vec3::new(x, 0.0, 1.5), Vec3::Z, 1.0, 0.1, 500.0).unwrap()
    }

    /// Whether the eye sees `p` (the points the layers must serve).
    fn in_view(eye: &Camera, p: Vec3) -> bool {
        let c = eye.view_projection(1.6) * p.extend(1.0);
        c.w > 0.0 && {
            let n = c.truncate() / c.w;
            n.x.abs() <= 1.0 && n.y.abs() <= 1.0 && (0.0..=1.0).contains(&n.z)
        }
    }

    const OPTIONS: ShadowOptions = ShadowOptions { size: 1024, cascades: 3, bias_texels: 1.5 };

    fn fit(light: &Light, x: f32) -> Shadows {
        fit_layers(light, &eye(x), 1.6, &receivers(), scene(), &OPTIONS)
    }

    fn refit(light: &Light, x: f32, previous: &Shadows) -> (Shadows, Vec<bool>) {
        refit_layers(light, &eye(x), 1.6, &receivers(), scene(), &OPTIONS, previous)
    }

    #[test]
    fn a_small_step_of_the_eye_reuses_layers_and_keeps_every_receiver_in_its_layer() {
        let sun = Light::Sun { towards: Vec3::new(0.3, 0.2, 0.9).normalize() };
        let previous = fit(&sun, 0.0);
        let tight = fit(&sun, 0.05);
        let (current, reused) = refit(&sun, 0.05, &previous);
        assert!(reused.iter().all(|&r| r), "a 5 cm step redrew a layer: {reused:?}");
        for (i, &r) in reused.iter().enumerate() {
            assert_eq!(current.layers[i].split, tight.layers[i].split, "splits are this frame's");
            let expected = if r { previous.layers[i].view_proj } else { tight.layers[i].view_proj };
            assert_eq!(current.layers[i].view_proj, expected);
        }
        // Every receiver point the fit covered is in the same layer after the reuse.
        let mut checked = 0;
        for &(lo, hi) in &receivers() {
            for p in [lo, hi, (lo + hi) * 0.5].into_iter().filter(|&p| in_view(&eye(0.05), p)) {
                // A reused layer is wider: it may hold points the fit left out, never fewer.
                let (a, b) = (tight.layer_of(&eye(0.05), p), current.layer_of(&eye(0.05), p));
                if let Some((layer, _)) = a {
                    assert_eq!(Some(layer), b.map(|x| x.0), "{p}");
                    checked += 1;
                }
            }
        }
        assert!(checked > 50, "{checked}");
    }

    #[test]
    fn a_long_step_or_another_light_redraws() {
        let sun = Light::Sun { towards: Vec3::new(0.3, 0.2, 0.9).normalize() };
        let previous = fit(&sun, 0.0);
        let tight = fit(&sun, 15.0);
        let (current, reused) = refit(&sun, 15.0, &previous);
        assert!(!reused[0], "the cascade nearest the eye moved 15 m: {reused:?}");
        for &(lo, hi) in &receivers() {
            for p in [lo, hi].into_iter().filter(|&p| in_view(&eye(15.0), p)) {
                let (a, b) = (tight.layer_of(&eye(15.0), p), current.layer_of(&eye(15.0), p));
                if let Some((layer, _)) = a {
                    assert_eq!(Some(layer), b.map(|x| x.0), "{p}");
                }
            }
        }
        let other = Light::Sun { towards: Vec3::new(0.31, 0.2, 0.9).normalize() };
        assert!(refit(&other, 0.0, &previous).1.iter().all(|&r| !r));
    }

    #[test]
    fn point_light_faces_serve_while_equal() {
        let lamp = Light::Point { position: Vec3::new(1.0, 2.0, 6.0) };
        let previous = fit(&lamp, 0.0);
        assert!(refit(&lamp, 0.0, &previous).1.iter().all(|&r| r));
        let moved = Light::Point { position: Vec3::new(1.0, 2.5, 6.0) };
        assert!(refit(&moved, 0.0, &previous).1.iter().all(|&r| !r));
    }

    #[test]
    fn a_layer_holds_only_points_inside_its_clip_box() {
        let layer = Mat4::from_scale(Vec3::new(0.5, 0.5, 0.1));
        let inside = [Vec3::new(1.0, 1.0, 1.0); 8];
        assert!(holds(&layer, &inside));
        let mut outside = inside;
        outside[3] = Vec3::new(2.5, 0.0, 1.0);
        assert!(!holds(&layer, &outside));
        outside[3] = Vec3::new(0.0, 0.0, 11.0);
        assert!(!holds(&layer, &outside));
    }

    #[test]
    fn lod_slack_is_a_share_of_the_bias() {
        let sun = Light::Sun { towards: Vec3::Z };
        let s = fit(&sun, 0.0);
        let texel = texel_size(&s, 0).unwrap();
        assert!(lod_within_bias(&s, 0, 1.5, 0.0, Vec3::ZERO));
        assert!(lod_within_bias(&s, 0, 1.5, 0.9 * LOD_SHARE * 1.5 * texel, Vec3::ZERO));
        assert!(!lod_within_bias(&s, 0, 1.5, 1.1 * LOD_SHARE * 1.5 * texel, Vec3::ZERO));
    }
}
