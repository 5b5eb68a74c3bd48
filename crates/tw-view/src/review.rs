//! Design-review state as plain data: which objects are drawn ([`ObjectFilter`]: hide, isolate,
//! show all), the picked object ([`Picked`]) and the point-to-point measurement ([`Measure`]).
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
}
