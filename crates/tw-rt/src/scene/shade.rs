//! Shading a hit the way the rasterizer shades a triangle (tw-gpu's draw.wgsl `vs_shade`): flat
//! colour per triangle from its base colour, a headlight along the view direction and a fixed
//! sun, both sides lit; the result encoded to sRGB. The same formula on both sides is what lets
//! a ray-traced frame be compared with a rasterized one pixel by pixel (PSNR).
//!
//! With a shadow-casting light (`tw_runtime::Light`) the sun's term takes the light's direction
//! at the point and is multiplied by its visibility (1 lit, 0 blocked: a shadow ray,
//! [`super::shadow`]); nothing else changes. [`ColorMode::Shadow`] shows that decision as a flat
//! mask instead of a colour.

use glam::Vec3;
use tw_core::color::{
    cluster_color, hash_color, level_color, ColorMode, DEFAULT_COLOR, SHADOW_AWAY, SHADOW_BLOCKED, SHADOW_LIT,
};
use tw_runtime::ClusterRef;
use tw_store::PageCluster;

/// The lights and colours of one frame.
#[derive(Clone, Debug)]
pub struct Shader<'a> {
    pub mode: ColorMode,
    /// sRGB colour per object (the store's object table).
    pub object_colors: &'a [Option<[u8; 4]>],
    pub eye: Vec3,
    /// An orthographic view: the viewer is towards `headlight` from every point
    /// (`Camera::to_viewer`), not at `eye`.
    pub orthographic: bool,
    /// Unit direction towards the eye (`Camera::headlight`).
    pub headlight: Vec3,
    /// Unit direction towards the sun (`Camera::sun_direction`).
    pub sun: Vec3,
}

impl Shader<'_> {
    /// The unit normal of the triangle with scene-space `corners`, turned towards the viewer
    /// (as `tw_runtime::Camera::to_viewer`): both sides are lit, as inputs are not consistently
    /// wound (a degenerate triangle faces the viewer).
    pub fn normal(&self, corners: [Vec3; 3]) -> Vec3 {
        let [p0, p1, p2] = corners;
        let to_eye = if self.orthographic { self.headlight } else { (self.eye - p0).normalize_or_zero() };
        let n = (p1 - p0).cross(p2 - p0).normalize_or(to_eye);
        if n.dot(to_eye) < 0.0 {
            -n
        } else {
            n
        }
    }

    /// The sRGB colour of triangle `triangle` of `cluster` (selected as `key`) with normal `n`
    /// ([`Shader::normal`]). `headlight`: how much of the flashlight reaches the point (1 lit,
    /// 0 in shadow) and the direction towards it, replacing the headlight; `sun`: the same for
    /// the shadow-casting light, replacing the fixed sun.
    pub fn shade(
        &self,
        key: ClusterRef,
        cluster: &PageCluster,
        triangle: usize,
        n: Vec3,
        headlight: Option<(f32, Vec3)>,
        sun: Option<(f32, Vec3)>,
    ) -> [u8; 4] {
        let head = match headlight {
            None => n.dot(self.headlight).abs(),
            Some((lit, towards_light)) => lit * n.dot(towards_light).abs(),
        };
        let (visible, facing) = match sun {
            None => (1.0, n.dot(self.sun).max(0.0)),
            Some((lit, towards_light)) => (lit, n.dot(towards_light).max(0.0)),
        };
        if self.mode == ColorMode::Shadow {
            return match (facing > 0.0, visible > 0.0) {
                (false, _) => SHADOW_AWAY,
                (true, true) => SHADOW_LIT,
                (true, false) => SHADOW_BLOCKED,
            };
        }
        let object = cluster.objects.get(triangle).copied().unwrap_or(u32::MAX);
        let base = self.base_color(key, cluster, object);
        // `facing * 1.0` is exact: an unshadowed frame is bit-identical to one without a light.
        let light = 0.18 + 0.62 * head + 0.35 * (facing * visible);
        let rgb = base.map(|c| srgb_encode((srgb_decode(c) * light).min(1.0)));
        [rgb[0], rgb[1], rgb[2], 255]
    }

    /// The sRGB colour of a surface of sRGB colour `base` and unit normal `n` under the
    /// headlight and the fixed sun (no flashlight, no shadows): how a proxy is lit
    /// ([`crate::proxy`]), with [`Shader::shade`]'s formula.
    pub fn shade_color(&self, base: [u8; 3], n: Vec3) -> [u8; 4] {
        let light = 0.18 + 0.62 * n.dot(self.headlight).abs() + 0.35 * n.dot(self.sun).max(0.0);
        let rgb = base.map(|c| srgb_encode((srgb_decode(c) * light).min(1.0)));
        [rgb[0], rgb[1], rgb[2], 255]
    }

    fn base_color(&self, key: ClusterRef, cluster: &PageCluster, object: u32) -> [u8; 3] {
        let c = match self.mode {
            ColorMode::Material => {
                self.object_colors.get(object as usize).copied().flatten().unwrap_or(DEFAULT_COLOR)
            }
            ColorMode::Object => hash_color(object),
            ColorMode::Level => level_color(cluster.level),
            ColorMode::Cluster => cluster_color(key.page, key.index_in_page),
            ColorMode::Shadow => SHADOW_LIT,
        };
        [c[0], c[1], c[2]]
    }
}

/// draw.wgsl's decode: `pow(c, 2.2)`.
fn srgb_decode(c: u8) -> f32 {
    (c as f32 / 255.0).powf(2.2)
}

/// draw.wgsl's `srgb_encode`, then the unorm8 store's rounding.
fn srgb_encode(c: f32) -> u8 {
    let v = if c <= 0.003_130_8 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}
