//! Which input axis is up: what `--up` asks for ([`UpRequest`]), the formats' conventions
//! ([`format_default`]: glTF 2.0 says +Y is up; PLY, OBJ and STL say nothing, so z, the
//! convention of CAD and scanning, stays their default), and the `--up auto` estimate
//! ([`UpVotes`]) for the formats without a convention.
//!
//! The store records the chosen axis; the geometry is never rotated (the viewer's camera and
//! walk mode follow the recorded axis, and `view`/`render --up` may override it at run time).
//!
//! # The estimate
//!
//! Massive walkthrough models (plants, ships, buildings) are built on horizontal surfaces:
//! floors, decks, gratings, roofs, ceilings, slabs. So the statistic is the triangle area whose
//! normal lies within [`FACING_COS`] (about 26°) of each axis: the up axis collects floors and
//! ceilings, while walls split between the two horizontal axes. It is robust enough because it
//! is
//! - area-weighted: a finely tessellated pipe or bolt does not outvote a coarse deck plate, and
//!   the same surface votes the same however it is meshed;
//! - limited to near-axis-aligned faces: curved and sloped surfaces (pipes, hulls, terrain
//!   slopes) do not vote at all, rather than adding noise to every axis;
//! - a ratio between the best and the second axis, not a threshold on absolute area, so it
//!   holds at any scale and unit.
//!
//! The thinnest extent of the bounds (boards, floor plans, sites and ships are much wider than
//! tall) is the second opinion: it confirms or vetoes, but never decides alone, since a tower or
//! a standing panel is thinnest along a horizontal axis.
//!
//! The estimate abstains, and the format's default stands, when the evidence is weak or
//! conflicting: no axis-facing area at all (a sphere, an organic scan), the best axis less than
//! [`MIN_RATIO`] times the second (a cube, a room scanned from inside), axis-facing area under
//! [`MIN_FACING_SHARE`] of the total, or a clearly thinnest axis that is not the one the area
//! picked. It costs one cross product per triangle, taken while the build streams the inputs.

use std::fmt;

use crate::format::Format;

/// A face votes for an axis when its unit normal's component along it is at least this
/// (cos 26°): floors modelled slightly off level still count, 45° slopes do not.
pub const FACING_COS: f64 = 0.9;
/// The best axis must collect at least this many times the area of the second.
pub const MIN_RATIO: f64 = 2.0;
/// Axis-facing area (all three axes) must be at least this share of the total area.
pub const MIN_FACING_SHARE: f64 = 0.2;
/// An axis is clearly the thinnest when its extent is at most this share of the next one's.
pub const THIN_SHARE: f64 = 0.5;

/// Axis names, by index (0 x, 1 y, 2 z).
pub const AXIS_NAMES: [&str; 3] = ["x", "y", "z"];

/// Parses an axis name (`x`, `y` or `z`, any case) to its index.
pub fn parse_axis(s: &str) -> Result<u8, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "x" => Ok(0),
        "y" => Ok(1),
        "z" => Ok(2),
        other => Err(format!("unknown up axis {other:?}: expected x, y or z")),
    }
}

/// What the user asked for as the up axis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UpRequest {
    /// This axis (0 x, 1 y, 2 z), whatever the inputs.
    Axis(u8),
    /// The inputs' format convention ([`format_default`]).
    #[default]
    FormatDefault,
    /// Estimated from the triangles ([`UpVotes`]), the format default when it abstains.
    Auto,
}

impl UpRequest {
    /// Parses `x`, `y`, `z` or `auto`.
    pub fn parse(s: &str) -> Result<UpRequest, String> {
        if s.trim().eq_ignore_ascii_case("auto") {
            return Ok(UpRequest::Auto);
        }
        parse_axis(s)
            .map(UpRequest::Axis)
            .map_err(|_| format!("unknown up axis {s:?}: expected x, y, z or auto"))
    }
}

impl fmt::Display for UpRequest {
    /// As `--up` takes it (`default` for the format convention), for the stored build options.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            UpRequest::Axis(a) => f.write_str(AXIS_NAMES[(*a).min(2) as usize]),
            UpRequest::FormatDefault => f.write_str("default"),
            UpRequest::Auto => f.write_str("auto"),
        }
    }
}

/// The axis chosen and why, for the build's output (`up: y (glTF convention)`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UpChoice {
    /// 0 x, 1 y, 2 z.
    pub axis: u8,
    pub reason: String,
}

impl Default for UpChoice {
    /// z, the default of the formats without a convention.
    fn default() -> Self {
        UpChoice { axis: 2, reason: "default".into() }
    }
}

impl fmt::Display for UpChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", AXIS_NAMES[self.axis.min(2) as usize], self.reason)
    }
}

/// The up axis a format's specification fixes, if any: glTF 2.0, section "Coordinate System
/// and Units": +Y is up.
pub fn format_convention(format: Format) -> Option<u8> {
    match format {
        Format::Gltf | Format::Glb => Some(1),
        Format::Obj | Format::Ply | Format::Stl => None,
    }
}

/// The up axis every input's format fixes, when all fix one and the same (glTF: y); `None`
/// when some input's format has no convention (or it is a generated source) or they disagree.
/// Then `--up auto` keeps it too: a mechanical part's largest flat faces need not face up,
/// while a glTF file that breaks the convention is rare and `--up` fixes it.
fn shared_convention(formats: &[Option<Format>]) -> Option<u8> {
    let first = formats.first().copied().flatten().and_then(format_convention)?;
    formats.iter().all(|f| f.and_then(format_convention) == Some(first)).then_some(first)
}

/// The default up axis of a scene whose inputs have `formats` (`None`: a generated source):
/// y when every input is glTF, else z (the inputs' formats have no convention, or they
/// disagree: the user must say).
pub fn format_default(formats: &[Option<Format>]) -> UpChoice {
    if let Some(axis) = shared_convention(formats) {
        return UpChoice { axis, reason: "glTF convention".into() };
    }
    let mut names: Vec<&str> = formats.iter().map(|f| f.map_or("generated input", |f| f.name())).collect();
    names.sort_unstable();
    names.dedup();
    let reason = if formats.iter().any(|f| f.and_then(format_convention).is_some()) {
        format!(
            "default for mixed inputs ({}): glTF is y-up, the others have no convention; \
             use --up to override",
            names.join(", ")
        )
    } else {
        format!("default for {}; use --up to override", names.join(" and "))
    };
    UpChoice { axis: 2, reason }
}

/// The `--up auto` statistic: triangle area facing each axis, accumulated one triangle at a
/// time in input order (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpVotes {
    /// Area of the faces whose normal is within [`FACING_COS`] of each axis.
    pub facing: [f64; 3],
    /// Area of all faces.
    pub total: f64,
}

/// What the estimate found: an axis, or why it abstains.
#[derive(Clone, Debug, PartialEq)]
pub enum UpEstimate {
    Axis { axis: u8, why: String },
    Abstain(String),
}

impl UpVotes {
    /// Adds one triangle (any origin: only edge vectors are used).
    #[inline]
    pub fn add(&mut self, p: [[f64; 3]; 3]) {
        let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
        let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
        let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if !(len.is_finite() && len > 0.0) {
            return;
        }
        let area = 0.5 * len;
        self.total += area;
        if let Some(axis) = (0..3).find(|&i| n[i].abs() >= FACING_COS * len) {
            self.facing[axis] += area;
        }
    }

    /// Adds the votes of another part of the scene.
    pub fn merge(&mut self, other: &UpVotes) {
        for (a, b) in self.facing.iter_mut().zip(other.facing) {
            *a += b;
        }
        self.total += other.total;
    }

    /// The estimate for a scene whose bounds are `min`..`max`: the axis most area faces, when
    /// it leads clearly and the thinnest extent does not point elsewhere; see the module
    /// documentation for when it abstains.
    pub fn estimate(&self, min: [f64; 3], max: [f64; 3]) -> UpEstimate {
        let share = |a: f64| if self.total > 0.0 { 100.0 * a / self.total } else { 0.0 };
        let facing_sum: f64 = self.facing.iter().sum();
        if !(self.total > 0.0 && facing_sum >= MIN_FACING_SHARE * self.total) {
            return UpEstimate::Abstain(format!(
                "only {:.0}% of the triangle area faces an axis",
                share(facing_sum)
            ));
        }
        let by_area = ranked(self.facing, true);
        let (best, second) = (by_area[0], by_area[1]);
        if self.facing[best] < MIN_RATIO * self.facing[second] {
            return UpEstimate::Abstain(format!(
                "no axis leads: {:.0}% of the area faces {}, {:.0}% {}",
                share(self.facing[best]),
                AXIS_NAMES[best],
                share(self.facing[second]),
                AXIS_NAMES[second]
            ));
        }
        let extent: [f64; 3] = std::array::from_fn(|i| (max[i] - min[i]).max(0.0));
        let by_extent = ranked(extent, false);
        let thinnest = by_extent[0];
        let clearly_thin = extent[thinnest] <= THIN_SHARE * extent[by_extent[1]];
        let area_why = format!(
            "{:.0}% of the triangle area faces {}, {:.0}% {}",
            share(self.facing[best]),
            AXIS_NAMES[best],
            share(self.facing[second]),
            AXIS_NAMES[second]
        );
        if clearly_thin && thinnest != best {
            return UpEstimate::Abstain(format!(
                "{area_why}, but the model is thinnest along {}",
                AXIS_NAMES[thinnest]
            ));
        }
        let why = if clearly_thin { format!("{area_why}; thinnest along it too") } else { area_why };
        UpEstimate::Axis { axis: best as u8, why }
    }
}

/// Axis indices ordered by `v`, largest first when `descending`; ties keep the lower index
/// first (x before y before z), so equal evidence ranks the same on every run.
fn ranked(v: [f64; 3], descending: bool) -> [usize; 3] {
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&a, &b| {
        let o = v[a].total_cmp(&v[b]);
        if descending {
            o.reverse()
        } else {
            o
        }
    });
    idx
}

/// Resolves `request` for a scene of `formats`: an explicit axis as given; otherwise the
/// format default, replaced under `Auto` by the estimate from `votes` over bounds `min`..`max`
/// unless the formats have a convention or the estimate abstains (`votes` is only looked at
/// then).
pub fn resolve(
    request: UpRequest,
    formats: &[Option<Format>],
    votes: &UpVotes,
    min: [f64; 3],
    max: [f64; 3],
) -> UpChoice {
    match request {
        UpRequest::Axis(axis) => UpChoice { axis: axis.min(2), reason: "--up".into() },
        UpRequest::FormatDefault => format_default(formats),
        UpRequest::Auto if shared_convention(formats).is_some() => {
            let d = format_default(formats);
            UpChoice {
                axis: d.axis,
                reason: format!("{}; auto estimates only formats without one", d.reason),
            }
        }
        UpRequest::Auto => match votes.estimate(min, max) {
            UpEstimate::Axis { axis, why } => UpChoice { axis, reason: format!("auto: {why}") },
            UpEstimate::Abstain(why) => {
                let d = format_default(formats);
                UpChoice { axis: d.axis, reason: format!("auto abstained: {why}; {}", d.reason) }
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles of a w × h rectangle facing `axis`, at height `at` along it, offset by
    /// `shift` on the other two axes.
    fn quad(votes: &mut UpVotes, axis: usize, at: f64, w: f64, h: f64, shift: f64) {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let pt = |a: f64, b: f64| {
            let mut p = [0.0; 3];
            p[axis] = at;
            p[u] = shift + a;
            p[v] = shift + b;
            p
        };
        votes.add([pt(0.0, 0.0), pt(w, 0.0), pt(w, h)]);
        votes.add([pt(0.0, 0.0), pt(w, h), pt(0.0, h)]);
    }

    /// A building with `up` as its up axis: `floors` slabs of 20 × 20, each storey's four
    /// walls 20 wide and 3 high (facing the two horizontal axes), bounds 20 × 20 × 3·floors.
    fn building(up: usize, floors: usize) -> (UpVotes, [f64; 3], [f64; 3]) {
        let mut v = UpVotes::default();
        let (a, b) = ((up + 1) % 3, (up + 2) % 3);
        for f in 0..floors {
            quad(&mut v, up, 3.0 * f as f64, 20.0, 20.0, 0.0);
            for (axis, at) in [(a, 0.0), (a, 20.0), (b, 0.0), (b, 20.0)] {
                // A wall facing `axis`: 20 along the other horizontal axis, 3 along up.
                let mut w = UpVotes::default();
                quad(&mut w, axis, at, 20.0, 3.0, 0.0);
                v.merge(&w);
            }
        }
        let mut max = [20.0; 3];
        max[up] = 3.0 * floors as f64;
        (v, [0.0; 3], max)
    }

    #[test]
    fn floors_outvote_walls_on_every_axis() {
        for up in 0..3 {
            let (v, min, max) = building(up, 5);
            match v.estimate(min, max) {
                UpEstimate::Axis { axis, .. } => assert_eq!(axis as usize, up),
                e => panic!("up {up}: {e:?}"),
            }
        }
    }

    #[test]
    fn a_tall_tower_is_not_fooled_by_its_thin_footprint() {
        // 20 × 20 × 90: thinnest is not clear (20 vs 20), the floors decide.
        let (v, min, max) = building(1, 30);
        assert!(matches!(v.estimate(min, max), UpEstimate::Axis { axis: 1, .. }));
    }

    #[test]
    fn tessellation_density_does_not_change_the_vote() {
        // A 10 × 10 deck facing z as 2 triangles, and as 20 000 (a 100 × 100 grid of quads),
        // against 120 units of wall area facing x as 2 big triangles.
        let mut coarse = UpVotes::default();
        quad(&mut coarse, 2, 0.0, 10.0, 10.0, 0.0);
        let mut fine = UpVotes::default();
        for _ in 0..10_000 {
            quad(&mut fine, 2, 0.0, 0.1, 0.1, 0.0);
        }
        assert!((coarse.facing[2] - fine.facing[2]).abs() < 1e-6 * coarse.facing[2]);
        for v in [&mut coarse, &mut fine] {
            quad(v, 0, 0.0, 10.0, 4.0, 0.0);
        }
        for v in [coarse, fine] {
            assert!(matches!(v.estimate([0.0; 3], [10.0, 10.0, 4.0]), UpEstimate::Axis { axis: 2, .. }));
        }
    }

    #[test]
    fn abstains_on_a_cube_a_sphere_and_conflicting_thinness() {
        let mut cube = UpVotes::default();
        for axis in 0..3 {
            quad(&mut cube, axis, 0.0, 1.0, 1.0, 0.0);
            quad(&mut cube, axis, 1.0, 1.0, 1.0, 0.0);
        }
        assert!(matches!(cube.estimate([0.0; 3], [1.0; 3]), UpEstimate::Abstain(_)));

        // An octahedron: every face at 54.7° from every axis, none votes.
        let mut sphere = UpVotes::default();
        for sx in [-1.0, 1.0] {
            for sy in [-1.0, 1.0] {
                for sz in [-1.0, 1.0] {
                    sphere.add([[sx, 0.0, 0.0], [0.0, sy, 0.0], [0.0, 0.0, sz]]);
                }
            }
        }
        assert!(matches!(sphere.estimate([-1.0; 3], [1.0; 3]), UpEstimate::Abstain(_)));

        // Floors facing z, but the bounds are thinnest along x: abstain.
        let (v, min, _) = building(2, 3);
        assert!(matches!(v.estimate(min, [2.0, 20.0, 9.0]), UpEstimate::Abstain(_)));

        assert!(matches!(UpVotes::default().estimate([0.0; 3], [1.0; 3]), UpEstimate::Abstain(_)));
    }

    #[test]
    fn degenerate_and_non_finite_triangles_do_not_vote() {
        let mut v = UpVotes::default();
        v.add([[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        v.add([[f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert_eq!(v, UpVotes::default());
    }

    #[test]
    fn format_defaults() {
        let d = format_default(&[Some(Format::Glb), Some(Format::Gltf)]);
        assert_eq!(d.to_string(), "y (glTF convention)");
        let d = format_default(&[Some(Format::Ply)]);
        assert_eq!(d.to_string(), "z (default for PLY; use --up to override)");
        let d = format_default(&[Some(Format::Obj), Some(Format::Stl), Some(Format::Obj)]);
        assert_eq!(d.axis, 2);
        assert_eq!(d.reason, "default for OBJ and STL; use --up to override");
        let d = format_default(&[Some(Format::Glb), Some(Format::Ply)]);
        assert_eq!(d.axis, 2);
        assert!(d.reason.contains("mixed"), "{}", d.reason);
        assert_eq!(format_default(&[None]).axis, 2);
    }

    #[test]
    fn resolve_falls_back_to_the_format_default_when_auto_abstains() {
        let ply = [Some(Format::Ply)];
        let none = UpVotes::default();
        let r = resolve(UpRequest::Auto, &ply, &none, [0.0; 3], [1.0; 3]);
        assert_eq!(r.axis, 2);
        assert!(
            r.reason.starts_with("auto abstained") && r.reason.contains("default for PLY"),
            "{}",
            r.reason
        );
        let (v, min, max) = building(0, 4);
        let r = resolve(UpRequest::Auto, &ply, &v, min, max);
        assert_eq!(r.axis, 0, "{}", r.reason);
        assert!(r.reason.starts_with("auto: "), "{}", r.reason);
        // glTF has a convention: auto keeps it, whatever the triangles say.
        let glb = [Some(Format::Glb)];
        let r = resolve(UpRequest::Auto, &glb, &v, min, max);
        assert_eq!(r.to_string(), "y (glTF convention; auto estimates only formats without one)");
        // Mixed inputs have no single convention: auto decides.
        assert_eq!(resolve(UpRequest::Auto, &[Some(Format::Glb), Some(Format::Obj)], &v, min, max).axis, 0);
        assert_eq!(resolve(UpRequest::Axis(2), &glb, &v, min, max).to_string(), "z (--up)");
        assert_eq!(resolve(UpRequest::FormatDefault, &glb, &v, min, max).axis, 1);
        assert_eq!(resolve(UpRequest::FormatDefault, &ply, &v, min, max).axis, 2);
    }

    #[test]
    fn parses_requests() {
        assert_eq!(UpRequest::parse("Y"), Ok(UpRequest::Axis(1)));
        assert_eq!(UpRequest::parse("auto"), Ok(UpRequest::Auto));
        assert!(UpRequest::parse("w").unwrap_err().contains("x, y, z or auto"));
        assert_eq!(parse_axis("z"), Ok(2));
        assert!(parse_axis("auto").is_err());
    }
}
