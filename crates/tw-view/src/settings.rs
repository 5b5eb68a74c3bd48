//! The viewer's controls as plain data: one [`Settings`] value holds every technique switch the
//! UI exposes (pixel error, occlusion strategy, frustum culling, LOD freeze, memory budget,
//! debug colourings, third-person debug view, shadows). The scene ([`crate::scene`]) reads it
//! each frame; the UI ([`crate::ui`]) edits it. Nothing here touches a window or the GPU.
//!
//! **Shadows** ([`ShadowControls`]) keep the light as the user handles it: the sun as azimuth and
//! elevation in degrees around the store's up axis (the `--light sun:AZ,EL` convention, so the
//! keys and sliders turn it in steps a person can follow), or a point light at a scene-space
//! position. The scene-space [`Light`] is built from them each frame through
//! [`InputLight::to_scene`], the same conversion the command line uses.

use glam::Vec3;
use tw_frame::shadow::ShadowOptions;
use tw_frame::{ShadowLod, ShadowSettings};
use tw_runtime::{Camera, InputLight, Light, Projection};
use tw_store::Header;

pub use tw_frame::Occlusion;

/// How triangles are coloured (mirrors [`tw_gpu::ColorMode`], with names for the UI).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Coloring {
    #[default]
    Material,
    Level,
    Cluster,
    Object,
    /// The light's shadow mask (white lit, black blocked, grey facing away).
    Shadow,
}

impl Coloring {
    pub const ALL: [Coloring; 5] =
        [Coloring::Material, Coloring::Level, Coloring::Cluster, Coloring::Object, Coloring::Shadow];

    pub fn name(self) -> &'static str {
        match self {
            Coloring::Material => "material",
            Coloring::Level => "LOD level",
            Coloring::Cluster => "cluster",
            Coloring::Object => "object",
            Coloring::Shadow => "shadow mask",
        }
    }

    pub fn to_gpu(self) -> tw_gpu::ColorMode {
        match self {
            Coloring::Material => tw_gpu::ColorMode::Material,
            Coloring::Level => tw_gpu::ColorMode::Level,
            Coloring::Cluster => tw_gpu::ColorMode::Cluster,
            Coloring::Object => tw_gpu::ColorMode::Object,
            Coloring::Shadow => tw_gpu::ColorMode::Shadow,
        }
    }
}

/// Which renderer draws the scene (`view --renderer`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum RendererKind {
    /// tw-gpu on the window's device (every technique of the viewer).
    #[default]
    Raster,
    /// tw-rt on every core: the same LOD cut ray traced, with progressive supersampling while
    /// the camera stands still ([`crate::traced`]).
    Rt,
}

impl RendererKind {
    pub const ALL: [RendererKind; 2] = [RendererKind::Raster, RendererKind::Rt];

    pub fn name(self) -> &'static str {
        match self {
            RendererKind::Raster => "raster",
            RendererKind::Rt => "rt",
        }
    }
}

/// Which light casts the shadows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum LightKind {
    /// Parallel light from [`ShadowControls::azimuth_deg`] / [`ShadowControls::elevation_deg`].
    #[default]
    Sun,
    /// A point light at [`ShadowControls::point`].
    Point,
}

/// Degrees the sun turns per press of `[` / `]` (azimuth) or Shift+`[` / `]` (elevation).
pub const SUN_STEP_DEG: f32 = 5.0;
/// The lowest sun the controls allow: `--light sun:AZ,EL` needs an elevation in (0, 90], and a
/// sun grazing the horizon casts shadows longer than any map can hold.
pub const MIN_ELEVATION_DEG: f32 = 1.0;
/// The highest sun: straight above (along the up axis).
pub const MAX_ELEVATION_DEG: f32 = 90.0;
/// Shadow-map sizes (texels per side) the UI offers; the command line takes any in 64..=8192.
pub const MAP_SIZES: [u32; 6] = [256, 512, 1024, 2048, 4096, 8192];
/// Sun cascades the UI offers (as `--cascades`).
pub const CASCADE_RANGE: std::ops::RangeInclusive<u32> = 1..=4;

/// What the light keys ask for. Turning the sun or placing a point light also turns shadows
/// on: without them the light is the fixed sun of the unshadowed shading, and the key would
/// seem to do nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKey {
    /// J: shadows on / off.
    Toggle,
    /// `[` / `]` (azimuth) and Shift+`[` / `]` (elevation): the sun turned by these degrees.
    TurnSun { azimuth_deg: f32, elevation_deg: f32 },
    /// U: a point light at this eye position (scene space); pressed while a point light casts
    /// shadows, back to the sun.
    PointAtEye(Vec3),
}

/// The shadow controls (J, `[` `]`, U and the HUD's "Shadows" section): whether a light casts
/// shadows, which light, and the shadow stage's options.
#[derive(Clone, Debug, PartialEq)]
pub struct ShadowControls {
    /// Shadows drawn (off: the unshadowed shading of the fixed sun).
    pub enabled: bool,
    pub kind: LightKind,
    /// The sun's azimuth in degrees in [0, 360), measured around the store's up axis from the
    /// next axis (x → y for z-up, y → z for x-up, z → x for y-up), as `--light sun:AZ,EL`.
    pub azimuth_deg: f32,
    /// The sun's elevation above the horizon in degrees, in
    /// [[`MIN_ELEVATION_DEG`], [`MAX_ELEVATION_DEG`]].
    pub elevation_deg: f32,
    /// The point light's position in scene space (U puts it at the eye).
    pub point: Vec3,
    /// Classify receivers against the light's depth so that only partly shadowed ones look the
    /// map up (the image is the same either way).
    pub cross_culling: bool,
    /// The level of detail of both views: the eye's, or the finer of the eye's and the light's.
    pub lod: ShadowLod,
    /// Shadow-map layer size in texels per side, sun cascades, depth bias in texels.
    pub map_size: u32,
    pub cascades: u32,
    pub bias_texels: f32,
}

impl Default for ShadowControls {
    /// Off, lit by the shading's own sun for a z-up store ([`ShadowControls::for_up_axis`] gives
    /// it for the others), with the command line's default map options.
    fn default() -> Self {
        ShadowControls::for_up_axis(2)
    }
}

impl ShadowControls {
    /// Off, with the sun of the unshadowed shading ([`Light::default_sun`]) for a store whose up
    /// axis is `up_axis` (0 x, 1 y, 2 z), so that turning shadows on changes only where the
    /// light is blocked.
    pub fn for_up_axis(up_axis: u8) -> ShadowControls {
        let o = ShadowOptions::default();
        let (azimuth_deg, elevation_deg) = sun_angles(default_sun_direction(up_axis), up_axis);
        ShadowControls {
            enabled: false,
            kind: LightKind::Sun,
            azimuth_deg,
            elevation_deg,
            point: Vec3::ZERO,
            cross_culling: true,
            lod: ShadowLod::Eye,
            map_size: o.size,
            cascades: o.cascades,
            bias_texels: o.bias_texels,
        }
    }

    /// The controls for a frame's shadow settings (`view --light …`), `enabled` or not, on a
    /// store whose up axis is `up_axis`. A point light keeps the default sun to return to.
    pub fn from_settings(s: &ShadowSettings, enabled: bool, up_axis: u8) -> ShadowControls {
        let mut c = ShadowControls::for_up_axis(up_axis);
        c.enabled = enabled;
        match s.light {
            Light::Sun { towards } => (c.azimuth_deg, c.elevation_deg) = sun_angles(towards, up_axis),
            Light::Point { position } => {
                c.kind = LightKind::Point;
                c.point = position;
            }
        }
        c.cross_culling = s.cross_culling;
        c.lod = s.lod;
        c.map_size = s.options.size;
        c.cascades = s.options.cascades;
        c.bias_texels = s.options.bias_texels;
        c
    }

    /// Turns the sun by `azimuth` degrees around the up axis (wrapping) and raises it by
    /// `elevation` degrees (clamped to [[`MIN_ELEVATION_DEG`], [`MAX_ELEVATION_DEG`]]); the sun
    /// becomes the light.
    pub fn turn_sun(&mut self, azimuth: f32, elevation: f32) {
        self.kind = LightKind::Sun;
        self.azimuth_deg = wrap_degrees(self.azimuth_deg + azimuth);
        self.elevation_deg = clamp_elevation(self.elevation_deg + elevation);
    }

    /// Carries out a light key (see [`LightKey`]).
    pub fn press(&mut self, key: LightKey) {
        match key {
            LightKey::Toggle => self.enabled = !self.enabled,
            LightKey::TurnSun { azimuth_deg, elevation_deg } => {
                self.turn_sun(azimuth_deg, elevation_deg);
                self.enabled = true;
            }
            LightKey::PointAtEye(_) if self.enabled && self.kind == LightKind::Point => {
                self.kind = LightKind::Sun;
            }
            LightKey::PointAtEye(eye) => {
                self.kind = LightKind::Point;
                self.point = eye;
                self.enabled = true;
            }
        }
    }

    /// The light in scene space for a store with `header` whose up axis is `up_axis`, through
    /// [`InputLight::to_scene`] (the `--light` conversion); `camera` is what it asks for.
    pub fn light(&self, header: &Header, up_axis: u8, camera: &Camera) -> Light {
        match self.kind {
            LightKind::Sun => InputLight::Sun {
                azimuth_deg: wrap_degrees(self.azimuth_deg) as f64,
                elevation_deg: clamp_elevation(self.elevation_deg) as f64,
            }
            .to_scene(header, up_axis, camera),
            LightKind::Point => Light::Point { position: self.point },
        }
    }

    /// Map size, cascades and bias as the frame takes them.
    pub fn options(&self) -> ShadowOptions {
        ShadowOptions { size: self.map_size, cascades: self.cascades, bias_texels: self.bias_texels }
    }

    /// The frame's shadow settings (see [`light`](Self::light)); `None` while shadows are off.
    pub fn frame_settings(&self, header: &Header, up_axis: u8, camera: &Camera) -> Option<ShadowSettings> {
        self.enabled.then(|| ShadowSettings {
            light: self.light(header, up_axis, camera),
            options: self.options(),
            cross_culling: self.cross_culling,
            lod: self.lod,
        })
    }
}

/// `(azimuth, elevation)` in degrees of the sun direction `towards` for up axis `up_axis`: the
/// inverse of [`InputLight::to_scene`]'s `sun:AZ,EL`, the elevation clamped to the controls'
/// range (a sun below the horizon is taken as barely above it).
pub fn sun_angles(towards: Vec3, up_axis: u8) -> (f32, f32) {
    let up = up_axis.min(2) as usize;
    let (a0, a1) = ((up + 1) % 3, (up + 2) % 3);
    let mut unit_up = [0.0f32; 3];
    unit_up[up] = 1.0;
    let d = towards.normalize_or(Vec3::from_array(unit_up)).to_array();
    let elevation = d[up].clamp(-1.0, 1.0).asin().to_degrees();
    let azimuth = d[a1].atan2(d[a0]).to_degrees();
    (wrap_degrees(azimuth), clamp_elevation(elevation))
}

/// The unshadowed shading's sun ([`Camera::sun_direction`]) for up axis `up_axis`: it depends
/// only on the camera's up, which the viewer keeps on the store's up axis.
fn default_sun_direction(up_axis: u8) -> Vec3 {
    let axis = up_axis.min(2) as usize;
    let (up, ahead) = ([Vec3::X, Vec3::Y, Vec3::Z][axis], [Vec3::Y, Vec3::Z, Vec3::X][axis]);
    let camera = Camera {
        eye: Vec3::ZERO,
        target: ahead,
        up,
        projection: Projection::Perspective { fovy: 1.0 },
        near: 0.1,
        far: 1.0,
    };
    camera.sun_direction()
}

/// `deg` in [0, 360) (a non-finite angle becomes 0).
fn wrap_degrees(deg: f32) -> f32 {
    if !deg.is_finite() {
        return 0.0;
    }
    let w = deg.rem_euclid(360.0);
    // rem_euclid of a tiny negative angle rounds up to 360; -0 prints as "-0".
    if w >= 360.0 {
        0.0
    } else {
        w + 0.0
    }
}

/// `deg` within [[`MIN_ELEVATION_DEG`], [`MAX_ELEVATION_DEG`]] (a non-finite one: straight up).
fn clamp_elevation(deg: f32) -> f32 {
    if deg.is_finite() {
        deg.clamp(MIN_ELEVATION_DEG, MAX_ELEVATION_DEG)
    } else {
        MAX_ELEVATION_DEG
    }
}

/// Every control of the viewer.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Pixel error threshold τ (docs/DESIGN.md, D3).
    pub pixel_error: f32,
    /// The occlusion culling strategy (tw-frame's, as `terawalk bench` runs them).
    pub occlusion: Occlusion,
    /// How LOD switches are drawn (`view --transition`; tw_frame::transition).
    pub transition: tw_frame::Transition,
    pub frustum_culling: bool,
    /// Keep the current LOD cut (selection) while the camera moves.
    pub lod_freeze: bool,
    /// Decoded page cache budget, bytes.
    pub memory_budget: u64,
    /// GPU memory budget for resident cluster geometry, bytes (tw-gpu's pool).
    pub gpu_budget: u64,
    pub coloring: Coloring,
    /// The renderer, and (ray traced only) the flashlight: a light above and beside the eye with
    /// hard shadows instead of the headlight.
    pub renderer: RendererKind,
    pub flashlight: bool,
    /// Third-person debug view: culling from the frozen camera, drawing from a second one.
    pub debug_view: bool,
    /// Draw the boxes of visible / occluded nodes (in the debug view).
    pub show_boxes: bool,
    /// Scene resolution as a fraction of the window (CPU rasterizers like 0.5).
    pub render_scale: f32,
    pub show_hud: bool,
    pub show_controls: bool,
    pub show_help: bool,
    /// Shadows of one light (J, `[` `]`, U; `view --light`).
    pub shadows: ShadowControls,
    /// Section planes and box (crate::section_tool): culled and clipped in every frame.
    pub section: crate::section_tool::SectionTool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            pixel_error: 1.0,
            occlusion: Occlusion::None,
            transition: tw_frame::Transition::Pop,
            frustum_culling: true,
            lod_freeze: false,
            memory_budget: 1 << 30,
            gpu_budget: tw_gpu::DEFAULT_GPU_BUDGET,
            coloring: Coloring::Material,
            renderer: RendererKind::Raster,
            flashlight: false,
            debug_view: false,
            show_boxes: true,
            render_scale: 1.0,
            show_hud: true,
            show_controls: true,
            show_help: false,
            shadows: ShadowControls::default(),
            section: Default::default(),
        }
    }
}

/// Range of the pixel error slider.
pub const PIXEL_ERROR_RANGE: std::ops::RangeInclusive<f32> = 0.0..=64.0;
/// Range of the memory budget slider (bytes).
pub const MEMORY_RANGE: std::ops::RangeInclusive<u64> = (16 << 20)..=(64 << 30);
/// Range of the GPU memory budget slider (bytes).
pub const GPU_MEMORY_RANGE: std::ops::RangeInclusive<u64> = tw_gpu::MIN_BUDGET..=(16 << 30);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn occlusion_names_round_trip() {
        for o in Occlusion::ALL {
            assert_eq!(Occlusion::parse(o.name()), Some(o));
        }
        assert_eq!(Occlusion::parse("bogus"), None);
        assert_eq!(Occlusion::parse("gpu-hzb"), Some(Occlusion::GpuHzb));
        assert_eq!(Occlusion::fastest_conservative(wgpu::DeviceType::Cpu, true), Occlusion::Hzb);
        assert_eq!(Occlusion::fastest_conservative(wgpu::DeviceType::DiscreteGpu, true), Occlusion::GpuHzb);
        assert_eq!(Occlusion::fastest_conservative(wgpu::DeviceType::IntegratedGpu, false), Occlusion::Hzb);
    }

    #[test]
    fn defaults_are_sensible() {
        let s = Settings::default();
        assert_eq!(s.pixel_error, 1.0);
        assert!(s.frustum_culling && !s.lod_freeze && !s.debug_view);
        assert!(MEMORY_RANGE.contains(&s.memory_budget));
        assert!(GPU_MEMORY_RANGE.contains(&s.gpu_budget));
        assert_eq!(Coloring::Level.to_gpu(), tw_gpu::ColorMode::Level);
        assert!(s.renderer == RendererKind::Raster && !s.flashlight);
        assert_eq!(RendererKind::ALL.map(RendererKind::name), ["raster", "rt"]);
        let sh = &s.shadows;
        assert!(!sh.enabled && sh.kind == LightKind::Sun && sh.cross_culling);
        assert_eq!(sh.options(), ShadowOptions::default());
        assert!(MAP_SIZES.contains(&sh.map_size) && CASCADE_RANGE.contains(&sh.cascades));
    }

    fn header() -> Header {
        Header::empty([0.0; 3], [10.0; 3], [2.0, 0.0, 0.0], 1.0)
    }

    fn camera(up: Vec3) -> Camera {
        Camera {
            eye: Vec3::ZERO,
            target: Vec3::ONE,
            up,
            projection: Projection::Perspective { fovy: 1.0 },
            near: 0.1,
            far: 100.0,
        }
    }

    fn sun(light: Light) -> Vec3 {
        match light {
            Light::Sun { towards } => towards,
            Light::Point { position } => panic!("a point light at {position}"),
        }
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn the_default_light_is_the_shadings_sun_for_each_up_axis() {
        for (axis, up) in [(0u8, Vec3::X), (1, Vec3::Y), (2, Vec3::Z)] {
            let c = ShadowControls::for_up_axis(axis);
            let light = sun(c.light(&header(), axis, &camera(up)));
            let shading = camera(up).sun_direction();
            assert!(close(light, shading), "axis {axis}: {light} vs {shading}");
            assert!(light.dot(up) > 0.5, "axis {axis}: the sun is high");
        }
    }

    #[test]
    fn sun_angles_point_where_expected_for_each_up_axis() {
        let h = 45f32.to_radians().sin();
        // Azimuth 0 lies along the axis after the up axis, 90 along the one after that.
        for (axis, up, a0, a1) in
            [(0u8, Vec3::X, Vec3::Y, Vec3::Z), (1, Vec3::Y, Vec3::Z, Vec3::X), (2, Vec3::Z, Vec3::X, Vec3::Y)]
        {
            let mut c = ShadowControls::for_up_axis(axis);
            (c.azimuth_deg, c.elevation_deg) = (0.0, 45.0);
            assert!(close(sun(c.light(&header(), axis, &camera(up))), (a0 + up) * h), "axis {axis}");
            c.azimuth_deg = 90.0;
            assert!(close(sun(c.light(&header(), axis, &camera(up))), (a1 + up) * h), "axis {axis}");
            c.elevation_deg = 90.0;
            assert!(close(sun(c.light(&header(), axis, &camera(up))), up), "axis {axis}");
            // And back: the angles of a direction.
            let (az, el) = sun_angles((a1 + up) * h, axis);
            assert!((az - 90.0).abs() < 1e-3 && (el - 45.0).abs() < 1e-3, "axis {axis}: {az} {el}");
        }
    }

    #[test]
    fn sun_keys_turn_within_bounds() {
        let mut c = ShadowControls::default();
        (c.azimuth_deg, c.elevation_deg) = (2.0, 80.0);
        c.press(LightKey::TurnSun { azimuth_deg: -SUN_STEP_DEG, elevation_deg: 0.0 });
        assert!(c.enabled, "turning the sun shows its shadows");
        assert_eq!((c.azimuth_deg, c.elevation_deg), (357.0, 80.0));
        c.press(LightKey::TurnSun { azimuth_deg: SUN_STEP_DEG, elevation_deg: 0.0 });
        assert_eq!(c.azimuth_deg, 2.0);
        for _ in 0..5 {
            c.press(LightKey::TurnSun { azimuth_deg: 0.0, elevation_deg: SUN_STEP_DEG });
        }
        assert_eq!(c.elevation_deg, MAX_ELEVATION_DEG);
        for _ in 0..40 {
            c.press(LightKey::TurnSun { azimuth_deg: 0.0, elevation_deg: -SUN_STEP_DEG });
        }
        assert_eq!(c.elevation_deg, MIN_ELEVATION_DEG);
        for _ in 0..100 {
            c.press(LightKey::TurnSun { azimuth_deg: SUN_STEP_DEG * 7.0, elevation_deg: 0.0 });
            assert!((0.0..360.0).contains(&c.azimuth_deg), "{}", c.azimuth_deg);
        }
        c.turn_sun(f32::NAN, f32::INFINITY);
        assert_eq!((c.azimuth_deg, c.elevation_deg), (0.0, MAX_ELEVATION_DEG));
        assert_eq!(sun_angles(Vec3::new(0.0, 0.0, -1.0), 2).1, MIN_ELEVATION_DEG);
    }

    #[test]
    fn light_keys_toggle_shadows_and_the_point_light() {
        let mut c = ShadowControls::default();
        let eye = Vec3::new(1.0, 2.0, 3.0);
        assert!(c.frame_settings(&header(), 2, &camera(Vec3::Z)).is_none(), "off by default");
        c.press(LightKey::Toggle);
        let on = c.frame_settings(&header(), 2, &camera(Vec3::Z)).expect("on");
        assert!(on.cross_culling && on.options == c.options());
        c.press(LightKey::Toggle);
        assert!(!c.enabled);
        // U: a point light at the eye (shadows on), stays in scene space …
        c.press(LightKey::PointAtEye(eye));
        assert!(c.enabled && c.kind == LightKind::Point);
        let s = c.frame_settings(&header(), 2, &camera(Vec3::Z)).expect("on");
        assert_eq!(s.light, Light::Point { position: eye });
        // … and again: back to the sun, which kept its angles.
        let angles = (c.azimuth_deg, c.elevation_deg);
        c.press(LightKey::PointAtEye(Vec3::ZERO));
        assert!(c.enabled && c.kind == LightKind::Sun && (c.azimuth_deg, c.elevation_deg) == angles);
        assert_eq!(c.point, eye);
        // With shadows off, U places the light anew and turns them on.
        c.press(LightKey::Toggle);
        c.kind = LightKind::Point;
        c.press(LightKey::PointAtEye(Vec3::ONE));
        assert!(c.enabled && c.kind == LightKind::Point && c.point == Vec3::ONE);
    }

    #[test]
    fn controls_start_from_the_command_lines_settings() {
        let options = ShadowOptions { size: 1024, cascades: 2, bias_texels: 3.0 };
        for (axis, up) in [(0u8, Vec3::X), (1, Vec3::Y), (2, Vec3::Z)] {
            let towards = (up * 2.0 + Vec3::ONE).normalize();
            let given = ShadowSettings {
                light: Light::Sun { towards },
                options,
                cross_culling: false,
                lod: ShadowLod::Finer,
            };
            let c = ShadowControls::from_settings(&given, true, axis);
            let back = c.frame_settings(&header(), axis, &camera(up)).expect("enabled");
            assert!(close(sun(back.light), towards), "axis {axis}: {:?}", back.light);
            assert_eq!((back.options, back.cross_culling, back.lod), (options, false, ShadowLod::Finer));
        }
        let point = Light::Point { position: Vec3::new(-4.0, 5.0, 6.0) };
        let given = ShadowSettings { light: point, options, cross_culling: true, lod: ShadowLod::Eye };
        let c = ShadowControls::from_settings(&given, false, 2);
        assert!(!c.enabled && c.kind == LightKind::Point);
        assert_eq!(c.light(&header(), 2, &camera(Vec3::Z)), point);
    }
}
