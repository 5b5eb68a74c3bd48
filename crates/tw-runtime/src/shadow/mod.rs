//! Shadows of one light over a frame (Govindaraju's thesis ch. 4): the shadow-map layers that
//! both the rasterizer and the CPU's cross-culling read, and the one rule that says whether the
//! light reaches a point.
//!
//! **The lookup rule** ([`Shadows::lit`]), followed exactly by tw-gpu's draw.wgsl and by the
//! cross-culling classification here, so that classifying a receiver as fully lit or fully
//! shadowed never changes the image:
//! 1. the layer of a point `p` is the first layer `i` whose eye-depth range `split` holds
//!    `(p − eye) · view_direction` and whose light clip space holds `p` (x, y in −1..=1, depth in
//!    0..=1, w > 0); a point in no layer is lit;
//! 2. in that layer, with `(x, y, d)` its light clip position, the texel is
//!    `(⌊(x + 1) / 2 · size⌋, ⌊(1 − y) / 2 · size⌋)` clamped to the map, and `p` is lit when
//!    `d ≤ map[texel] + bias` (depth 0 nearest the light; the map cleared to 1).
//!
//! Sun: up to four orthographic cascades split along the eye's depth. Point light: the faces of a
//! cube around the light, 90° perspective frusta, every split `0..f32::MAX` (WGSL may assume
//! finite values, so an open end is the largest finite float).
//!
//! Submodules, one algorithm each: [`fit`] fits the layers to the eye's receivers, [`reuse`]
//! keeps last frame's layers where they still serve, [`clip`] cuts a box to what a layer can
//! hold, [`depth`] keeps a read-back layer as min/max pyramids, [`classify`] cross-culls
//! receivers and casters against them, [`subobjects`] refines partly shadowed receivers to
//! runs of a few triangles, [`light_lod`] measures errors in the light's texels (the LOD policy
//! "the finer of both"). The light's view of a layer (the
//! eye's LOD cut culled by the layer's frustum) is [`crate::Selector::select_light`] and
//! [`crate::Streamer::select_light`].

use glam::{Mat4, Vec3, Vec4};

use crate::camera::Camera;
use crate::light::Light;

pub mod classify;
pub mod clip;
pub mod depth;
pub mod fit;
pub mod light_lod;
pub mod reuse;
pub mod subobjects;

pub use classify::{casters, classify_receivers, light_visible, ShadowSetStats};
pub use depth::LightDepth;
pub use fit::{fit_layers, refit_layers, texel_size, ShadowOptions};
pub use light_lod::LightLod;
pub use reuse::lod_within_bias;
pub use subobjects::{classify_subobjects, classify_subobjects_cut, TriangleClasses, SUBOBJECT_TRIANGLES};

/// What cross-culling decided about a receiver (a cluster of the eye's cut).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ShadowClass {
    /// Every point is lit: drawn without shadow lookups.
    Lit,
    /// No point is lit: drawn without the light's term and without lookups.
    Shadowed,
    /// Some points may be lit and some not: drawn with a lookup per fragment.
    #[default]
    Partial,
}

/// One shadow-map layer: a sun cascade or a point light's cube face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowLayer {
    /// Scene space to the light's clip space (depth 0..1, 0 nearest the light).
    pub view_proj: Mat4,
    /// The eye depths `[from, to)` this layer serves (rule 1).
    pub split: [f32; 2],
}

/// The shadows of a frame: the light, its layers (all `size`×`size` texels) and the bias.
#[derive(Clone, Debug, PartialEq)]
pub struct Shadows {
    pub light: Light,
    pub layers: Vec<ShadowLayer>,
    /// Texels per side of each layer.
    pub size: u32,
    /// Added to the map's depth before comparing (rule 2), in the layers' depth units.
    pub bias: f32,
}

impl Shadows {
    /// Rule 1: the layer of `p` seen by `eye`, and `p`'s light clip position in it.
    pub fn layer_of(&self, eye: &Camera, p: Vec3) -> Option<(usize, Vec3)> {
        let depth = (p - eye.eye).dot(eye.direction());
        self.layers.iter().enumerate().find_map(|(i, layer)| {
            if !(depth >= layer.split[0] && depth < layer.split[1]) {
                return None;
            }
            let c = layer.view_proj * Vec4::new(p.x, p.y, p.z, 1.0);
            if c.w <= 0.0 {
                return None;
            }
            let n = c.truncate() / c.w;
            let inside = n.x.abs() <= 1.0 && n.y.abs() <= 1.0 && (0.0..=1.0).contains(&n.z);
            inside.then_some((i, n))
        })
    }

    /// Rule 2: the texel of light clip position `n` in a layer.
    pub fn texel(&self, n: Vec3) -> (u32, u32) {
        let s = self.size as f32;
        let x = (((n.x + 1.0) * 0.5 * s).floor()).clamp(0.0, s - 1.0);
        let y = (((1.0 - n.y) * 0.5 * s).floor()).clamp(0.0, s - 1.0);
        (x as u32, y as u32)
    }

    /// The lookup rule: whether the light reaches `p`, with `map(layer, x, y)` the depth stored
    /// in texel `(x, y)` of `layer`.
    pub fn lit(&self, eye: &Camera, p: Vec3, map: impl Fn(usize, u32, u32) -> f32) -> bool {
        match self.layer_of(eye, p) {
            None => true,
            Some((layer, n)) => {
                let (x, y) = self.texel(n);
                n.z <= map(layer, x, y) + self.bias
            }
        }
    }
}
