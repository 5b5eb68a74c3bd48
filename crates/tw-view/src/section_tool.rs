//! The viewer's section tool (issue 35): up to six section planes and a section box, edited
//! by keys, the HUD's "Section" panel ([`crate::section_ui`]) and `--script` steps
//! ([`SectionStep`]), and handed to every frame as a [`tw_runtime::Section`] (the selection
//! culls by it, the renderer clips by it, the pick looks through what it removes).
//!
//! Everything here is in scene space (input coordinates minus the store's grid origin); the
//! scene's box ([`SceneBox`]) is the unit the fractions of the script steps and the sliders
//! measure in.

use glam::{DVec3, Vec3};
use tw_runtime::{Section, SectionPlane, MAX_SECTION_PLANES};

/// The scene's box in scene space: what fractions and slider ranges refer to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneBox {
    pub min: Vec3,
    pub max: Vec3,
}

impl SceneBox {
    /// The point at fractions `f` of the box on each axis.
    pub fn at(&self, f: [f32; 3]) -> Vec3 {
        self.min + (self.max - self.min) * Vec3::from_array(f)
    }

    /// The length of the box's diagonal: the moving keys' unit.
    pub fn diagonal(&self) -> f32 {
        (self.max - self.min).length()
    }
}

/// The section being edited: planes keeping `normal·p ≥ offset` (scene space), an optional
/// box, and whether it is on (K toggles it without forgetting it).
#[derive(Clone, Debug, PartialEq)]
pub struct SectionTool {
    pub planes: Vec<SectionPlane>,
    pub boxed: Option<(Vec3, Vec3)>,
    pub enabled: bool,
}

impl Default for SectionTool {
    fn default() -> Self {
        SectionTool { planes: Vec::new(), boxed: None, enabled: true }
    }
}

/// What a `--script` section step does (script.rs `Step::Section`).
#[derive(Clone, Debug, PartialEq)]
pub enum SectionStep {
    /// `section-plane x|y|z F`: a plane across an axis at fraction `F` of the scene box,
    /// keeping the side towards +axis.
    Axis(usize, f32),
    /// `section-plane picked`: a plane through the picked point along its surface normal,
    /// removing the side the eye is on.
    Picked,
    /// `section-flip I`: plane I (from 1) keeps its other side.
    Flip(usize),
    /// `section-move I F`: moves plane I along its normal by `F` × the scene's diagonal.
    Move(usize, f32),
    /// `section-remove I`.
    Remove(usize),
    /// `section-box X0 Y0 Z0 X1 Y1 Z1`: a box at those fractions of the scene box.
    Box([f32; 3], [f32; 3]),
    /// `section-box picked`: the picked object's box.
    BoxPicked,
    /// `section-toggle`: all on or off.
    Toggle,
    /// `section-clear`: no plane, no box.
    Clear,
}

// Steps are parsed with finite numbers only (parse_step), so equality is an equivalence.
impl Eq for SectionStep {}

impl SectionTool {
    /// The section a frame uses: empty while off.
    pub fn section(&self) -> Section {
        if !self.enabled {
            return Section::default();
        }
        let boxed = self.boxed.map(|(lo, hi)| tw_runtime::SectionBox {
            min: lo.as_dvec3().to_array(),
            max: hi.as_dvec3().to_array(),
        });
        // Every edit keeps the tool valid (≤ 6 planes, unit normals, min ≤ max).
        Section::new(&self.planes, boxed).unwrap_or_default()
    }

    /// The tool holding `section` (a scene-space section, as `view --section` gives).
    pub fn from_section(section: &Section) -> SectionTool {
        let planes = section
            .planes()
            .iter()
            .map(|p| SectionPlane { normal: p.truncate().as_dvec3().to_array(), offset: -p.w as f64 })
            .collect();
        SectionTool { planes, boxed: section.section_box(), enabled: true }
    }

    /// Adds the plane `normal·p ≥ normal·point` (`normal` made unit length). An error when six
    /// are there already or the normal is zero.
    pub fn add_plane(&mut self, normal: Vec3, point: Vec3) -> Result<usize, String> {
        if self.planes.len() >= MAX_SECTION_PLANES {
            return Err(format!("at most {MAX_SECTION_PLANES} section planes: remove one first"));
        }
        let n = normal.as_dvec3().normalize_or_zero();
        if n == DVec3::ZERO {
            return Err("the plane's normal is zero".into());
        }
        self.planes.push(SectionPlane { normal: n.to_array(), offset: n.dot(point.as_dvec3()) });
        self.enabled = true;
        Ok(self.planes.len())
    }

    /// A plane across `axis` (0, 1, 2) at fraction `f` of `scene`, keeping the +axis side.
    pub fn add_axis_plane(&mut self, axis: usize, f: f32, scene: &SceneBox) -> Result<usize, String> {
        let mut n = Vec3::ZERO;
        n[axis.min(2)] = 1.0;
        self.add_plane(n, scene.at([f; 3]))
    }

    /// A plane through `point` on a surface of normal `normal`, seen from `eye`: the side the
    /// eye is on is removed, and the plane is pushed a thousandth of `scale` past the surface
    /// so that the picked surface itself goes and what is behind it shows.
    pub fn add_picked_plane(
        &mut self,
        point: Vec3,
        normal: Vec3,
        eye: Vec3,
        scale: f32,
    ) -> Result<usize, String> {
        let n = if normal.dot(eye - point) > 0.0 { -normal } else { normal };
        let n = n.normalize_or_zero();
        self.add_plane(n, point + n * (1e-3 * scale))
    }

    /// Plane `i` (from 0), or an error naming the planes there are.
    fn plane_mut(&mut self, i: usize) -> Result<&mut SectionPlane, String> {
        let count = self.planes.len();
        self.planes.get_mut(i).ok_or_else(|| format!("no section plane {} (there are {count})", i + 1))
    }

    /// Plane `i` keeps its other side.
    pub fn flip(&mut self, i: usize) -> Result<(), String> {
        let p = self.plane_mut(i)?;
        p.normal = p.normal.map(|v| -v);
        p.offset = -p.offset;
        Ok(())
    }

    /// Moves plane `i` by `distance` along its normal (positive: removes more).
    pub fn move_plane(&mut self, i: usize, distance: f32) -> Result<(), String> {
        self.plane_mut(i)?.offset += distance as f64;
        Ok(())
    }

    /// Removes plane `i`.
    pub fn remove(&mut self, i: usize) -> Result<(), String> {
        self.plane_mut(i)?;
        self.planes.remove(i);
        Ok(())
    }

    /// Sets the box `lo..hi` (corners sorted per axis).
    pub fn set_box(&mut self, lo: Vec3, hi: Vec3) {
        self.boxed = Some((lo.min(hi), lo.max(hi)));
        self.enabled = true;
    }

    /// No plane, no box.
    pub fn clear(&mut self) {
        self.planes.clear();
        self.boxed = None;
    }

    /// One line for the HUD and the messages: what the section holds.
    pub fn summary(&self) -> String {
        let state = if self.enabled { "" } else { " (off)" };
        let boxed = if self.boxed.is_some() { " and a box" } else { "" };
        format!("{} plane(s){boxed}{state}", self.planes.len())
    }
}

/// Parses a section step of a script (`cmd` starts with `section`), or says what is wrong.
pub fn parse_step(cmd: &str, args: &[&str]) -> Result<SectionStep, String> {
    let num =
        |s: &str| s.parse::<f32>().ok().filter(|v| v.is_finite()).ok_or(format!("`{s}` is not a number"));
    let index = |s: &str| {
        s.parse::<usize>()
            .ok()
            .filter(|&i| (1..=MAX_SECTION_PLANES).contains(&i))
            .map(|i| i - 1)
            .ok_or(format!("`{s}` is not a section plane number (1..={MAX_SECTION_PLANES})"))
    };
    let want = |n: usize| {
        (args.len() == n).then_some(()).ok_or(format!("`{cmd}` takes {n} argument(s), found {}", args.len()))
    };
    Ok(match (cmd, args) {
        ("section-plane", ["picked"]) => SectionStep::Picked,
        ("section-plane", [axis, f]) => {
            let a = ["x", "y", "z"]
                .iter()
                .position(|x| x.eq_ignore_ascii_case(axis))
                .ok_or(format!("`{axis}` is not an axis (x, y, z, or `picked`)"))?;
            SectionStep::Axis(a, num(f)?)
        }
        ("section-plane", _) => return Err("`section-plane` takes `x|y|z FRACTION` or `picked`".into()),
        ("section-flip", _) => {
            want(1)?;
            SectionStep::Flip(index(args[0])?)
        }
        ("section-move", _) => {
            want(2)?;
            SectionStep::Move(index(args[0])?, num(args[1])?)
        }
        ("section-remove", _) => {
            want(1)?;
            SectionStep::Remove(index(args[0])?)
        }
        ("section-box", ["picked"]) => SectionStep::BoxPicked,
        ("section-box", _) => {
            want(6)?;
            let v: Vec<f32> = args.iter().map(|a| num(a)).collect::<Result<_, _>>()?;
            SectionStep::Box([v[0], v[1], v[2]], [v[3], v[4], v[5]])
        }
        ("section-toggle", _) => {
            want(0)?;
            SectionStep::Toggle
        }
        ("section-clear", _) => {
            want(0)?;
            SectionStep::Clear
        }
        _ => {
            return Err(format!(
                "unknown step `{cmd}` (section-plane, section-flip, section-move, section-remove, \
                 section-box, section-toggle, section-clear)"
            ))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit() -> SceneBox {
        SceneBox { min: Vec3::ZERO, max: Vec3::splat(10.0) }
    }

    #[test]
    fn planes_are_added_flipped_moved_and_removed() {
        let mut t = SectionTool::default();
        t.add_axis_plane(0, 0.5, &unit()).unwrap();
        let s = t.section();
        assert!(s.keeps(Vec3::new(6.0, 1.0, 1.0)) && !s.keeps(Vec3::new(4.0, 1.0, 1.0)));
        t.flip(0).unwrap();
        assert!(t.section().keeps(Vec3::new(4.0, 1.0, 1.0)));
        t.move_plane(0, 2.0).unwrap(); // keeps x ≤ 3 now
        assert!(!t.section().keeps(Vec3::new(4.0, 1.0, 1.0)));
        assert!(t.flip(3).unwrap_err().contains("no section plane 4"));
        for _ in 0..5 {
            t.add_axis_plane(2, 0.1, &unit()).unwrap();
        }
        assert!(t.add_axis_plane(2, 0.1, &unit()).unwrap_err().contains("at most 6"));
        t.remove(0).unwrap();
        assert_eq!(t.planes.len(), 5);
        t.enabled = false;
        assert!(t.section().is_empty());
        t.clear();
        assert_eq!(t.summary(), "0 plane(s) (off)");
    }

    #[test]
    fn a_picked_plane_removes_the_eyes_side_and_the_surface() {
        let mut t = SectionTool::default();
        // A wall at x = 5 seen from x = 0: the wall and everything before it go.
        t.add_picked_plane(Vec3::new(5.0, 1.0, 1.0), Vec3::X, Vec3::ZERO, 10.0).unwrap();
        let s = t.section();
        assert!(!s.keeps(Vec3::new(5.0, 1.0, 1.0)) && !s.keeps(Vec3::new(2.0, 1.0, 1.0)));
        assert!(s.keeps(Vec3::new(5.5, 1.0, 1.0)));
        let back = SectionTool::from_section(&s);
        assert_eq!(back.section(), s);
    }

    #[test]
    fn script_steps_parse_and_refuse_bad_input() {
        assert_eq!(parse_step("section-plane", &["y", "0.25"]), Ok(SectionStep::Axis(1, 0.25)));
        assert_eq!(parse_step("section-plane", &["picked"]), Ok(SectionStep::Picked));
        assert_eq!(parse_step("section-flip", &["2"]), Ok(SectionStep::Flip(1)));
        assert_eq!(parse_step("section-move", &["1", "-0.1"]), Ok(SectionStep::Move(0, -0.1)));
        assert_eq!(
            parse_step("section-box", &["0", "0", "0", "0.5", "0.5", "1"]),
            Ok(SectionStep::Box([0.0; 3], [0.5, 0.5, 1.0]))
        );
        assert_eq!(parse_step("section-clear", &[]), Ok(SectionStep::Clear));
        assert!(parse_step("section-plane", &["w", "0.5"]).unwrap_err().contains("not an axis"));
        assert!(parse_step("section-flip", &["7"]).unwrap_err().contains("1..=6"));
        assert!(parse_step("section-box", &["0", "0"]).unwrap_err().contains("6 argument"));
        assert!(parse_step("section-move", &["1", "nan"]).is_err());
        assert!(parse_step("sections", &[]).unwrap_err().contains("unknown step"));
    }
}
