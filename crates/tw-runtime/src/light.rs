//! The light that casts shadows: a sun (parallel light from a direction) or a point light, in
//! scene space, and the command-line form (`--light`) in input coordinates.
//!
//! Both renderers shade with it the same way (tw-gpu's draw.wgsl and tw-rt): the light's term of
//! the flat shading is `0.35 · max(n · l, 0)`, with `l` the unit direction from the surface
//! towards the light, times 1 where the light reaches the surface and 0 in its shadow. Without
//! `--light` the renderers keep the fixed, unshadowed sun of [`Camera::sun_direction`].

use std::str::FromStr;

use glam::{DVec3, Vec3};
use tw_store::Header;

use crate::camera::Camera;
use crate::error::RuntimeError;

/// A shadow-casting light in scene space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Parallel light (the sun): `towards` is the unit direction from the scene towards it.
    Sun { towards: Vec3 },
    /// A point light at `position` (radiating in every direction).
    Point { position: Vec3 },
}

impl Light {
    /// The sun of the unshadowed shading ([`Camera::sun_direction`]): the light `--light sun`
    /// gives, so that turning shadows on changes only where the light is blocked.
    pub fn default_sun(camera: &Camera) -> Light {
        Light::Sun { towards: camera.sun_direction() }
    }

    /// Unit direction from `p` towards the light (for a point light at `p` itself: the camera's
    /// conventional up, +Z).
    pub fn towards_from(&self, p: Vec3) -> Vec3 {
        match *self {
            Light::Sun { towards } => towards,
            Light::Point { position } => (position - p).normalize_or(Vec3::Z),
        }
    }

    /// How far a shadow ray from `p` must reach to meet the light (`f32::INFINITY` for the sun).
    pub fn distance_from(&self, p: Vec3) -> f32 {
        match *self {
            Light::Sun { .. } => f32::INFINITY,
            Light::Point { position } => (position - p).length(),
        }
    }
}

/// A light as the user gives it (`--light`), in input coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InputLight {
    /// `sun`: the default sun direction of the shading ([`Light::default_sun`]).
    DefaultSun,
    /// `sun:AZ,EL`: azimuth in degrees, measured around the store's up axis from the next axis
    /// (x → y for z-up, y → z for x-up, z → x for y-up), and elevation above the horizon in
    /// degrees (0 < EL ≤ 90).
    Sun { azimuth_deg: f64, elevation_deg: f64 },
    /// `point:X,Y,Z`: a point light at input coordinates X, Y, Z.
    Point { position: [f64; 3] },
}

impl InputLight {
    /// Parses `sun`, `sun:AZ,EL` or `point:X,Y,Z` (whitespace around numbers allowed).
    pub fn parse(s: &str) -> Result<InputLight, RuntimeError> {
        let err = |msg: String| RuntimeError::LightParse { input: s.to_string(), msg };
        let (kind, args) = match s.trim().split_once(':') {
            Some((k, a)) => (k.trim(), Some(a)),
            None => (s.trim(), None),
        };
        let numbers = |a: &str, n: usize, what: &str| -> Result<Vec<f64>, RuntimeError> {
            let v: Vec<f64> = a
                .split(',')
                .map(|c| {
                    let x: f64 =
                        c.trim().parse().map_err(|_| err(format!("bad number {:?} in {what}", c.trim())))?;
                    if x.is_finite() {
                        Ok(x)
                    } else {
                        Err(err(format!("{what} must be finite, got {:?}", c.trim())))
                    }
                })
                .collect::<Result<_, _>>()?;
            if v.len() != n {
                return Err(err(format!("{what} needs {n} numbers separated by commas, got {}", v.len())));
            }
            Ok(v)
        };
        match (kind, args) {
            ("sun", None) => Ok(InputLight::DefaultSun),
            ("sun", Some(a)) => {
                let v = numbers(a, 2, "sun:AZIMUTH,ELEVATION")?;
                if !(v[1] > 0.0 && v[1] <= 90.0) {
                    return Err(err(format!("sun elevation must be in (0, 90] degrees, got {}", v[1])));
                }
                Ok(InputLight::Sun { azimuth_deg: v[0], elevation_deg: v[1] })
            }
            ("point", Some(a)) => {
                let v = numbers(a, 3, "point:X,Y,Z")?;
                Ok(InputLight::Point { position: [v[0], v[1], v[2]] })
            }
            ("point", None) => Err(err("a point light needs its position: point:X,Y,Z".into())),
            _ => Err(err(format!("expected sun, sun:AZIMUTH,ELEVATION or point:X,Y,Z, got {kind:?}"))),
        }
    }

    /// The scene-space light for a store whose up axis is `up_axis` (0 x, 1 y, 2 z; the
    /// store header's or `--up`), seen by `camera` (for [`InputLight::DefaultSun`]).
    pub fn to_scene(&self, header: &Header, up_axis: u8, camera: &Camera) -> Light {
        match *self {
            InputLight::DefaultSun => Light::default_sun(camera),
            InputLight::Sun { azimuth_deg, elevation_deg } => {
                let up = up_axis.min(2) as usize;
                let (a0, a1) = ((up + 1) % 3, (up + 2) % 3);
                let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
                let mut d = [0f64; 3];
                d[a0] = el.cos() * az.cos();
                d[a1] = el.cos() * az.sin();
                d[up] = el.sin();
                Light::Sun { towards: DVec3::from_array(d).normalize().as_vec3() }
            }
            InputLight::Point { position } => Light::Point {
                position: (DVec3::from_array(position) - DVec3::from_array(header.grid_origin)).as_vec3(),
            },
        }
    }
}

impl FromStr for InputLight {
    type Err = RuntimeError;
    fn from_str(s: &str) -> Result<InputLight, RuntimeError> {
        InputLight::parse(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera::new(Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::Z, 1.0, 0.1, 100.0).unwrap()
    }

    #[test]
    fn parses_the_three_forms() {
        assert_eq!(InputLight::parse("sun").unwrap(), InputLight::DefaultSun);
        assert_eq!(
            InputLight::parse(" sun: 30 , 45 ").unwrap(),
            InputLight::Sun { azimuth_deg: 30.0, elevation_deg: 45.0 }
        );
        assert_eq!(
            InputLight::parse("point:1,2.5,-3").unwrap(),
            InputLight::Point { position: [1.0, 2.5, -3.0] }
        );
    }

    #[test]
    fn rejects_bad_lights_with_a_message() {
        for bad in
            ["", "lamp", "point", "point:1,2", "sun:10", "sun:10,0", "sun:10,91", "sun:a,10", "point:1,2,inf"]
        {
            let e = InputLight::parse(bad).unwrap_err().to_string();
            assert!(e.contains("light"), "{bad:?}: {e}");
        }
    }

    #[test]
    fn sun_angles_follow_the_up_axis() {
        let header = Header::empty([0.0; 3], [1.0; 3], [0.0; 3], 1.0);
        let high = InputLight::Sun { azimuth_deg: 0.0, elevation_deg: 90.0 };
        for (axis, up) in [(0u8, Vec3::X), (1, Vec3::Y), (2, Vec3::Z)] {
            let Light::Sun { towards } = high.to_scene(&header, axis, &camera()) else { panic!() };
            assert!((towards - up).length() < 1e-6, "{axis}: {towards}");
        }
        let east = InputLight::Sun { azimuth_deg: 90.0, elevation_deg: 30.0 };
        let Light::Sun { towards } = east.to_scene(&header, 2, &camera()) else { panic!() };
        assert!((towards - Vec3::new(0.0, 30f32.to_radians().cos(), 0.5)).length() < 1e-5, "{towards}");
    }

    #[test]
    fn point_lights_are_rebased_and_default_sun_is_the_shading_sun() {
        let header = Header::empty([0.0; 3], [10.0; 3], [5.0, 0.0, 0.0], 1.0);
        let p = InputLight::Point { position: [6.0, 1.0, 2.0] }.to_scene(&header, 2, &camera());
        assert_eq!(p, Light::Point { position: Vec3::new(1.0, 1.0, 2.0) });
        assert!((p.towards_from(Vec3::new(1.0, 1.0, 0.0)) - Vec3::Z).length() < 1e-6);
        assert_eq!(p.distance_from(Vec3::new(1.0, 1.0, 0.0)), 2.0);
        let sun = InputLight::DefaultSun.to_scene(&header, 2, &camera());
        assert_eq!(sun, Light::Sun { towards: camera().sun_direction() });
        assert_eq!(sun.distance_from(Vec3::ZERO), f32::INFINITY);
    }
}
