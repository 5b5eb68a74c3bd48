//! Design-review state as plain data: which objects are drawn ([`ObjectFilter`]: hide, isolate,
//! show all), the picked object ([`Picked`]), the point-to-point measurement ([`Measure`]) and
//! the point-to-plane one ([`PlaneMeasure`]).
//! The scene reads the filter when it draws (a triangle mask per cluster, see
//! [`ObjectFilter::mask`]); nothing here touches a window or the GPU.

use std::collections::BTreeSet;

use glam::Vec3;
use tw_runtime::triangle_test::TriangleMask;

/// Which objects are drawn: all but the hidden ones, or only the isolated one.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ObjectFilter {
    hidden: BTreeSet<u32>,
    isolated: Option<u32>,
}

impl ObjectFilter {
    /// Whether every object is drawn (the scene then draws as without a filter).
    pub fn is_all(&self) -> bool {
        self.hidden.is_empty() && self.isolated.is_none()
    }

    /// Whether object `id` is drawn.
    pub fn shows(&self, id: u32) -> bool {
        match self.isolated {
            Some(i) => i == id,
            None => !self.hidden.contains(&id),
        }
    }

    /// Hides `id`. Within an isolation, hiding another object changes nothing (it is not drawn);
    /// hiding the isolated one ends the isolation: everything but it is drawn.
    pub fn hide(&mut self, id: u32) {
        match self.isolated {
            Some(i) if i != id => {}
            _ => {
                self.isolated = None;
                self.hidden.insert(id);
            }
        }
    }

    /// Draws `id` alone.
    pub fn isolate(&mut self, id: u32) {
        self.hidden.clear();
        self.isolated = Some(id);
    }

    pub fn show_all(&mut self) {
        self.hidden.clear();
        self.isolated = None;
    }

    /// Objects hidden (0 while isolating).
    pub fn hidden_count(&self) -> usize {
        self.hidden.len()
    }

    pub fn isolated(&self) -> Option<u32> {
        self.isolated
    }

    /// The triangles of a cluster to draw, from its per-triangle object ids (bit `t` for
    /// triangle `t`, as `tw_gpu::Renderer::draw_masked` reads it; clusters have at most 128).
    pub fn mask(&self, objects: &[u32]) -> TriangleMask {
        objects
            .iter()
            .take(128)
            .enumerate()
            .filter(|(_, &o)| self.shows(o))
            .fold(0, |m, (t, _)| m | (1u128 << t))
    }
}

/// The picked object and point (scene space).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Picked {
    pub object: u32,
    pub point: Vec3,
}

/// A point-to-point measurement: the first click sets `a`, the second `b`; a third starts a new
/// one.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Measure {
    pub a: Option<Vec3>,
    pub b: Option<Vec3>,
}

impl Measure {
    /// Adds a picked point: the second end, or the first of a new measurement.
    pub fn add(&mut self, p: Vec3) {
        match (self.a, self.b) {
            (Some(_), None) => self.b = Some(p),
            _ => *self = Measure { a: Some(p), b: None },
        }
    }

    /// The distance between both ends, once both are set (scene units = the store's units).
    pub fn distance(&self) -> Option<f32> {
        Some(self.a?.distance(self.b?))
    }

    pub fn is_empty(&self) -> bool {
        self.a.is_none()
    }
}

/// What measuring clicks measure.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MeasureKind {
    /// Two points, the distance between them (M).
    #[default]
    Point,
    /// A plane, then points: the perpendicular distance from each (Shift+M).
    Plane,
}

impl MeasureKind {
    pub fn parse(s: &str) -> Option<MeasureKind> {
        match s.to_ascii_lowercase().as_str() {
            "point" | "points" => Some(MeasureKind::Point),
            "plane" => Some(MeasureKind::Plane),
            _ => None,
        }
    }
}

/// A plane through `origin` with the unit `normal`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub origin: Vec3,
    pub normal: Vec3,
}

impl Plane {
    /// The plane of triangle `corners` through `origin` (the snapped click, which lies in it);
    /// `None` for a degenerate triangle (no normal).
    pub fn of_triangle(origin: Vec3, corners: &[Vec3; 3]) -> Option<Plane> {
        let [a, b, c] = corners.map(|p| p.as_dvec3());
        // In f64: thin triangles far from the origin lose their normal's digits in f32.
        let n = (b - a).cross(c - a);
        let len = n.length();
        (len > 0.0 && len.is_finite()).then(|| Plane { origin, normal: (n / len).as_vec3() })
    }

    /// The distance of `p` from the plane along the normal (positive on the normal's side).
    pub fn signed_distance(&self, p: Vec3) -> f32 {
        (p - self.origin).as_dvec3().dot(self.normal.as_dvec3()) as f32
    }

    /// The point of the plane nearest `p` (the foot of the perpendicular).
    pub fn foot(&self, p: Vec3) -> Vec3 {
        p - self.normal * self.signed_distance(p)
    }
}

/// A point-to-plane measurement: the first click sets the plane (the picked triangle's, through
/// the snapped point), each later one the point measured from it; Esc or the mode's key again
/// starts over.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlaneMeasure {
    pub plane: Option<Plane>,
    pub point: Option<Vec3>,
}

impl PlaneMeasure {
    /// Adds a click at `p` on the triangle `corners`: the plane when there is none yet, else the
    /// point measured. Returns false when the first click's triangle has no plane (degenerate).
    pub fn add(&mut self, p: Vec3, corners: &[Vec3; 3]) -> bool {
        if self.plane.is_some() {
            self.point = Some(p);
            return true;
        }
        self.plane = Plane::of_triangle(p, corners);
        self.plane.is_some()
    }

    /// The perpendicular distance of the point from the plane, and the foot, once both are set.
    pub fn distance(&self) -> Option<(f32, Vec3)> {
        let (plane, p) = (self.plane?, self.point?);
        Some((plane.signed_distance(p).abs(), plane.foot(p)))
    }
}

/// A length for the HUD and messages: four decimals up to a million units (a measurement is
/// read for its digits; millimetre models have large numbers), scientific notation beyond.
pub fn format_distance(d: f64) -> String {
    if d.abs() < 1e6 {
        format!("{d:.4}")
    } else {
        format!("{d:.4e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hide_isolate_and_show_all() {
        let mut f = ObjectFilter::default();
        assert!(f.is_all() && f.shows(3));
        f.hide(3);
        assert!(!f.shows(3) && f.shows(4) && !f.is_all());
        f.isolate(4);
        assert!(f.shows(4) && !f.shows(3) && !f.shows(5));
        f.hide(4);
        assert!(!f.shows(4) && f.shows(5) && f.isolated().is_none(), "hiding the isolated one");
        f.show_all();
        assert!(f.is_all() && f.shows(4));
    }

    #[test]
    fn masks_keep_the_shown_triangles() {
        let mut f = ObjectFilter::default();
        assert_eq!(f.mask(&[1, 2, 1]), 0b111);
        f.hide(1);
        assert_eq!(f.mask(&[1, 2, 1]), 0b010);
        f.isolate(1);
        assert_eq!(f.mask(&[1, 2, 1]), 0b101);
        assert_eq!(f.mask(&[1; 128]), u128::MAX);
    }

    #[test]
    fn measuring_takes_two_points_then_starts_again() {
        let mut m = Measure::default();
        assert!(m.is_empty() && m.distance().is_none());
        m.add(Vec3::ZERO);
        assert_eq!(m.distance(), None);
        m.add(Vec3::new(3.0, 4.0, 0.0));
        assert_eq!(m.distance(), Some(5.0));
        m.add(Vec3::ONE);
        assert_eq!((m.a, m.b), (Some(Vec3::ONE), None));
        assert_eq!(format_distance(2.06156), "2.0616");
        assert_eq!(format_distance(2.5e7), "2.5000e7");
    }

    #[test]
    fn plane_measure_gives_the_perpendicular_distance_and_foot() {
        let mut m = PlaneMeasure::default();
        assert_eq!(m.distance(), None);
        // The plane x = 4 (a face of a cube), through a click on it.
        let face = [Vec3::new(4.0, 0.0, 0.0), Vec3::new(4.0, 1.0, 0.0), Vec3::new(4.0, 1.0, 1.0)];
        assert!(m.add(Vec3::new(4.0, 0.5, 0.5), &face));
        assert_eq!(m.distance(), None, "only the plane so far");
        let far = [Vec3::ZERO; 3];
        assert!(m.add(Vec3::new(1.5, 0.0, 0.25), &far), "later clicks need no plane of their own");
        let (d, foot) = m.distance().unwrap();
        assert_eq!(d, 2.5);
        assert_eq!(foot, Vec3::new(4.0, 0.0, 0.25));
        // Each next click measures from the same plane.
        m.add(Vec3::new(7.0, 3.0, 3.0), &far);
        assert_eq!(m.distance().unwrap().0, 3.0);
    }

    #[test]
    fn a_tilted_plane_and_a_degenerate_triangle() {
        let p = Plane::of_triangle(Vec3::ZERO, &[Vec3::ZERO, Vec3::X, Vec3::new(0.0, 1.0, 1.0)]).unwrap();
        // Normal (0, -1, 1)/√2: the point (0, 0, 2) is √2 above, its foot (0, 1, 1).
        assert!((p.signed_distance(Vec3::new(0.0, 0.0, 2.0)) - 2f32.sqrt()).abs() < 1e-6);
        assert!((p.foot(Vec3::new(0.0, 0.0, 2.0)) - Vec3::new(0.0, 1.0, 1.0)).length() < 1e-6);
        let mut m = PlaneMeasure::default();
        assert!(!m.add(Vec3::X, &[Vec3::ZERO, Vec3::X, Vec3::new(2.0, 0.0, 0.0)]));
        assert_eq!(m.plane, None);
        assert_eq!(MeasureKind::parse("Plane"), Some(MeasureKind::Plane));
        assert_eq!(MeasureKind::parse("line"), None);
    }
}
