//! Section planes and a section box: the part of the scene a design review cuts away to see
//! inside (issue 35). One definition shared by the selection, which culls what lies entirely
//! on a removed side like a frustum miss ([`crate::select`]), the renderer, which clips per
//! fragment (tw-gpu, common.wgsl `section_keeps`), the CPU pick and the command line.
//!
//! A section keeps the points `p` with `n·p ≥ d` for each of its planes (at most
//! [`MAX_SECTION_PLANES`]) and, when it has a box, the points inside the box: the intersection
//! of those half-spaces. The planes are stored as `(n, −d)`, so a point is kept when
//! `n·p + w ≥ 0` for all of them — the convention of [`crate::Frustum`]'s planes, and the same
//! conservative box test ([`Section::removes_box`] never removes a box that reaches into the
//! kept part).
//!
//! Coordinates: the runtime works in scene space (input coordinates minus the store's grid
//! origin, [`crate::camera`]); the command line and the viewer give input coordinates,
//! converted once by [`Section::to_scene`].

use glam::{DVec3, Vec3, Vec4};

/// The most planes a section has (the "up to 6 section planes").
pub const MAX_SECTION_PLANES: usize = 6;

/// One section plane: keeps the points `p` with `normal·p ≥ offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SectionPlane {
    pub normal: [f64; 3],
    pub offset: f64,
}

/// An axis-aligned section box: keeps its inside, `min ≤ p ≤ max`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SectionBox {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl SectionBox {
    /// Parses `"X0,Y0,Z0;X1,Y1,Z1"` (the command line's `--section-box`): the box's two
    /// corners, `min ≤ max` on every axis.
    pub fn parse(s: &str) -> Result<SectionBox, String> {
        let what = "a section box \"X0,Y0,Z0;X1,Y1,Z1\"";
        let Some((a, b)) = s.split_once(';') else {
            return Err(format!("{what} needs two corners separated by ';', got {s:?}"));
        };
        let (lo, hi) = (numbers(a, 3, what)?, numbers(b, 3, what)?);
        let boxed = SectionBox { min: [lo[0], lo[1], lo[2]], max: [hi[0], hi[1], hi[2]] };
        Section::new(&[], Some(boxed)).map_err(|e| format!("{s:?}: {e}"))?;
        Ok(boxed)
    }
}

/// Why a section was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SectionError {
    #[error("at most {MAX_SECTION_PLANES} section planes, got {0}")]
    TooManyPlanes(usize),
    #[error("section plane {index}: {what}")]
    BadPlane { index: usize, what: String },
    #[error("section box: {0}")]
    BadBox(String),
}

/// A validated section (see the module documentation). The default keeps everything.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Section {
    /// `(n, −d)` with `|n| = 1`; the first `count` are used.
    planes: [Vec4; MAX_SECTION_PLANES],
    count: u8,
    /// The box, `(min, max)`.
    boxed: Option<(Vec3, Vec3)>,
}

/// The numbers of `s`, separated by commas: exactly `n` finite ones, or an error naming `what`.
fn numbers(s: &str, n: usize, what: &str) -> Result<Vec<f64>, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != n {
        return Err(format!("{what} needs {n} numbers separated by commas, got {s:?}"));
    }
    parts
        .iter()
        .map(|p| match p.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("{what}: {p:?} is not a finite number (in {s:?})")),
        })
        .collect()
}

impl SectionPlane {
    /// Parses `"NX,NY,NZ,D"` (the command line's `--section`): keeps `n·p ≥ D`.
    pub fn parse(s: &str) -> Result<SectionPlane, String> {
        let v = numbers(s, 4, "a section plane \"NX,NY,NZ,D\"")?;
        let plane = SectionPlane { normal: [v[0], v[1], v[2]], offset: v[3] };
        plane.checked(0).map_err(|_| format!("section plane {s:?}: the normal must not be zero"))?;
        Ok(plane)
    }

    fn checked(&self, index: usize) -> Result<(DVec3, f64), SectionError> {
        let bad = |what: &str| SectionError::BadPlane { index, what: what.into() };
        let n = DVec3::from_array(self.normal);
        if !n.is_finite() || !self.offset.is_finite() {
            return Err(bad("the normal and the offset must be finite numbers"));
        }
        let len = n.length();
        if len <= 1e-12 {
            return Err(bad("the normal must not be zero"));
        }
        Ok((n / len, self.offset / len))
    }
}

impl Section {
    /// A section of `planes` and an optional box, validated: at most [`MAX_SECTION_PLANES`]
    /// planes with finite, non-zero normals and finite offsets (normals are normalised, the
    /// offsets scaled with them), and a box with finite corners and `min ≤ max` on every axis.
    pub fn new(planes: &[SectionPlane], boxed: Option<SectionBox>) -> Result<Section, SectionError> {
        Section::with_origin(planes, boxed, [0.0; 3])
    }

    /// [`Section::new`] of planes and a box given in input coordinates, in the scene space of
    /// a store whose grid origin is `origin` (module documentation, "Coordinates").
    pub fn to_scene(
        planes: &[SectionPlane],
        boxed: Option<SectionBox>,
        origin: [f64; 3],
    ) -> Result<Section, SectionError> {
        Section::with_origin(planes, boxed, origin)
    }

    fn with_origin(
        planes: &[SectionPlane],
        boxed: Option<SectionBox>,
        origin: [f64; 3],
    ) -> Result<Section, SectionError> {
        if planes.len() > MAX_SECTION_PLANES {
            return Err(SectionError::TooManyPlanes(planes.len()));
        }
        let o = DVec3::from_array(origin);
        let mut out = Section::default();
        for (i, p) in planes.iter().enumerate() {
            let (n, d) = p.checked(i)?;
            // n·(s + o) ≥ d  ⇔  n·s ≥ d − n·o.
            out.planes[i] = n.as_vec3().extend(-(d - n.dot(o)) as f32);
        }
        out.count = planes.len() as u8;
        if let Some(b) = boxed {
            let (lo, hi) = (DVec3::from_array(b.min), DVec3::from_array(b.max));
            if !lo.is_finite() || !hi.is_finite() {
                return Err(SectionError::BadBox("the corners must be finite numbers".into()));
            }
            if lo.cmpgt(hi).any() {
                return Err(SectionError::BadBox(format!(
                    "min {:?} must not exceed max {:?} on any axis",
                    b.min, b.max
                )));
            }
            out.boxed = Some(((lo - o).as_vec3(), (hi - o).as_vec3()));
        }
        Ok(out)
    }

    /// Whether the section keeps everything (no plane, no box): the selection and the
    /// renderer then do no section work at all.
    pub fn is_empty(&self) -> bool {
        self.count == 0 && self.boxed.is_none()
    }

    /// The planes in use, `(n, −d)` in scene space.
    pub fn planes(&self) -> &[Vec4] {
        &self.planes[..self.count as usize]
    }

    /// The box in scene space, if any.
    pub fn section_box(&self) -> Option<(Vec3, Vec3)> {
        self.boxed
    }

    /// Every half-space of the section as a plane `(n, w)` keeping `n·p + w ≥ 0`: the planes,
    /// then the box's six faces, padded to twelve with planes that keep everything
    /// `(0, 0, 0, 1)`. The renderer's uniforms (tw-gpu common.wgsl): the shader tests all
    /// twelve arithmetically, with no branch on a uniform.
    pub fn clip_planes(&self) -> [Vec4; 12] {
        let mut out = [Vec4::W; 12];
        out[..self.count as usize].copy_from_slice(self.planes());
        if let Some((lo, hi)) = self.boxed {
            let faces = [
                Vec4::new(1.0, 0.0, 0.0, -lo.x),
                Vec4::new(0.0, 1.0, 0.0, -lo.y),
                Vec4::new(0.0, 0.0, 1.0, -lo.z),
                Vec4::new(-1.0, 0.0, 0.0, hi.x),
                Vec4::new(0.0, -1.0, 0.0, hi.y),
                Vec4::new(0.0, 0.0, -1.0, hi.z),
            ];
            out[MAX_SECTION_PLANES..].copy_from_slice(&faces);
        }
        out
    }

    /// Whether point `p` (scene space) is kept.
    pub fn keeps(&self, p: Vec3) -> bool {
        self.planes().iter().all(|pl| pl.truncate().dot(p) + pl.w >= 0.0)
            && self.boxed.is_none_or(|(lo, hi)| p.cmpge(lo).all() && p.cmple(hi).all())
    }

    /// Whether the box `min..=max` (scene space) lies entirely on a removed side: beyond one
    /// plane (its corner farthest along the normal is removed), or disjoint from the section
    /// box. Conservative: never true for a box that has a kept point.
    pub fn removes_box(&self, min: Vec3, max: Vec3) -> bool {
        let beyond_plane = self.planes().iter().any(|pl| {
            let n = pl.truncate();
            let far = Vec3::select(n.cmpge(Vec3::ZERO), max, min);
            n.dot(far) + pl.w < 0.0
        });
        beyond_plane || self.boxed.is_some_and(|(lo, hi)| max.cmplt(lo).any() || min.cmpgt(hi).any())
    }

    /// Whether the sphere at `center` with `radius` (scene space) lies entirely on a removed
    /// side (as [`Section::removes_box`], for the sphere's bounding box against the section
    /// box).
    pub fn removes_sphere(&self, center: Vec3, radius: f32) -> bool {
        let beyond_plane = self.planes().iter().any(|pl| pl.truncate().dot(center) + pl.w < -radius);
        let r = Vec3::splat(radius);
        beyond_plane
            || self.boxed.is_some_and(|(lo, hi)| (center + r).cmplt(lo).any() || (center - r).cmpgt(hi).any())
    }

    /// Where the ray `origin + t·dir` is kept: the interval `[t0, t1]` of `t` (possibly empty,
    /// `t0 > t1`) inside every half-space. The CPU pick and the ray tracer take the first hit
    /// in it, so a surface on a removed side is looked through.
    pub fn ray_interval(&self, origin: Vec3, dir: Vec3) -> (f32, f32) {
        let (mut t0, mut t1) = (f32::NEG_INFINITY, f32::INFINITY);
        for pl in self.clip_planes() {
            let n = pl.truncate();
            let (dn, s) = (n.dot(dir), n.dot(origin) + pl.w);
            if dn.abs() < 1e-30 {
                if s < 0.0 {
                    return (1.0, 0.0);
                }
            } else if dn > 0.0 {
                t0 = t0.max(-s / dn);
            } else {
                t1 = t1.min(-s / dn);
            }
        }
        (t0, t1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(n: [f64; 3], d: f64) -> SectionPlane {
        SectionPlane { normal: n, offset: d }
    }

    #[test]
    fn validates_its_input() {
        let seven = vec![plane([1.0, 0.0, 0.0], 0.0); 7];
        assert_eq!(Section::new(&seven, None), Err(SectionError::TooManyPlanes(7)));
        assert!(matches!(
            Section::new(&[plane([0.0; 3], 1.0)], None),
            Err(SectionError::BadPlane { index: 0, .. })
        ));
        assert!(matches!(
            Section::new(&[plane([1.0, 0.0, 0.0], 0.0), plane([f64::NAN, 0.0, 1.0], 0.0)], None),
            Err(SectionError::BadPlane { index: 1, .. })
        ));
        let inverted = SectionBox { min: [0.0, 2.0, 0.0], max: [1.0, 1.0, 1.0] };
        assert!(matches!(Section::new(&[], Some(inverted)), Err(SectionError::BadBox(_))));
        let inf = SectionBox { min: [0.0; 3], max: [f64::INFINITY, 1.0, 1.0] };
        assert!(matches!(Section::new(&[], Some(inf)), Err(SectionError::BadBox(_))));
        assert!(Section::new(&[], None).unwrap().is_empty());
    }

    #[test]
    fn parses_the_command_line_forms() {
        assert_eq!(SectionPlane::parse("-1, 0,0,-2.5"), Ok(plane([-1.0, 0.0, 0.0], -2.5)));
        assert!(SectionPlane::parse("0,0,0,1").unwrap_err().contains("zero"));
        assert!(SectionPlane::parse("1,0,1").unwrap_err().contains("4 numbers"));
        assert!(SectionPlane::parse("1,0,x,1").unwrap_err().contains("\"x\""));
        assert!(SectionPlane::parse("inf,0,0,1").is_err());
        let b = SectionBox::parse("-1,-2,-3;4,5,6").unwrap();
        assert_eq!((b.min, b.max), ([-1.0, -2.0, -3.0], [4.0, 5.0, 6.0]));
        assert!(SectionBox::parse("1,2,3").unwrap_err().contains("';'"));
        assert!(SectionBox::parse("1,0,0;0,1,1").unwrap_err().contains("must not exceed"));
    }

    #[test]
    fn keeps_the_positive_side_and_the_box_inside() {
        // 2x ≥ 4 is x ≥ 2 after normalising.
        let s = Section::new(&[plane([2.0, 0.0, 0.0], 4.0)], None).unwrap();
        assert!(s.keeps(Vec3::new(2.5, 0.0, 0.0)));
        assert!(!s.keeps(Vec3::new(1.5, 9.0, 0.0)));
        assert!(s.removes_box(Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.9, 5.0, 5.0)));
        assert!(!s.removes_box(Vec3::new(0.0, 0.0, 0.0), Vec3::new(2.1, 5.0, 5.0)));
        assert!(s.removes_sphere(Vec3::ZERO, 1.9));
        assert!(!s.removes_sphere(Vec3::ZERO, 2.1));
        let b = Section::new(&[], Some(SectionBox { min: [0.0; 3], max: [1.0; 3] })).unwrap();
        assert!(b.keeps(Vec3::splat(0.5)));
        assert!(!b.keeps(Vec3::new(0.5, 1.5, 0.5)));
        assert!(b.removes_box(Vec3::new(1.1, 0.0, 0.0), Vec3::new(2.0, 1.0, 1.0)));
        assert!(!b.removes_box(Vec3::new(0.9, 0.0, 0.0), Vec3::new(2.0, 1.0, 1.0)));
    }

    #[test]
    fn input_coordinates_move_with_the_origin() {
        let origin = [10.0, 0.0, 0.0];
        let s = Section::to_scene(
            &[plane([1.0, 0.0, 0.0], 12.0)],
            Some(SectionBox { min: [10.0, 0.0, 0.0], max: [20.0, 1.0, 1.0] }),
            origin,
        )
        .unwrap();
        // Input x = 12.5 is scene x = 2.5.
        assert!(s.keeps(Vec3::new(2.5, 0.5, 0.5)));
        assert!(!s.keeps(Vec3::new(1.5, 0.5, 0.5)));
        assert!(!s.keeps(Vec3::new(10.5, 0.5, 0.5)));
    }

    #[test]
    fn clip_planes_agree_with_keeps_and_the_ray_interval() {
        let s =
            Section::new(&[plane([0.0, 0.0, 1.0], 0.25)], Some(SectionBox { min: [-1.0; 3], max: [1.0; 3] }))
                .unwrap();
        let planes = s.clip_planes();
        for p in [Vec3::new(0.0, 0.0, 0.5), Vec3::new(0.0, 0.0, 0.0), Vec3::new(2.0, 0.0, 0.5)] {
            let by_planes = planes.iter().all(|pl| pl.truncate().dot(p) + pl.w >= 0.0);
            assert_eq!(by_planes, s.keeps(p), "{p}");
        }
        let (t0, t1) = s.ray_interval(Vec3::new(0.0, 0.0, -5.0), Vec3::Z);
        assert!((t0 - 5.25).abs() < 1e-5 && (t1 - 6.0).abs() < 1e-5, "{t0} {t1}");
        let (t0, t1) = s.ray_interval(Vec3::new(5.0, 0.0, 0.5), Vec3::Y);
        assert!(t0 > t1);
        assert_eq!(Section::default().ray_interval(Vec3::ZERO, Vec3::X), (f32::NEG_INFINITY, f32::INFINITY));
    }
}
