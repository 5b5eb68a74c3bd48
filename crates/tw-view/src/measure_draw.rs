//! What the measurements draw over the scene, plain data: the point-to-plane measurement's
//! plane as a square outline around its point ([`plane_outline`]) and the small crosses that
//! mark measured points on the screen ([`crosses`]).

use glam::Vec3;

use crate::review::Plane;
use crate::ui::Line;

/// Half the arm of a point's cross, in window points.
const CROSS: f32 = 5.0;

/// The four sides of a square of side `size` in `plane`, centred on its point: shows where the
/// plane lies and how it is tilted.
pub fn plane_outline(plane: &Plane, size: f32) -> Vec<(Vec3, Vec3)> {
    let (u, v) = plane.normal.any_orthonormal_pair();
    let h = size * 0.5;
    let c = [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(a, b)| plane.origin + u * a + v * b);
    (0..4).map(|i| (c[i], c[(i + 1) % 4])).collect()
}

/// A cross (a horizontal and a vertical stroke) on each of `points` (window points).
pub fn crosses(points: &[[f32; 2]], color: [u8; 4]) -> Vec<Line> {
    points
        .iter()
        .flat_map(|p| {
            [(CROSS, 0.0), (0.0, CROSS)].map(|(dx, dy)| Line {
                a: [p[0] - dx, p[1] - dy],
                b: [p[0] + dx, p[1] + dy],
                color,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_outline_lies_in_the_plane_around_its_point() {
        let plane = Plane { origin: Vec3::new(4.0, 0.5, 0.5), normal: Vec3::X };
        let sides = plane_outline(&plane, 2.0);
        assert_eq!(sides.len(), 4);
        for (a, b) in &sides {
            assert!((plane.signed_distance(*a)).abs() < 1e-6 && (a.distance(*b) - 2.0).abs() < 1e-5);
            assert!((a.distance(plane.origin) - 2f32.sqrt()).abs() < 1e-5);
        }
        assert_eq!(sides[3].1, sides[0].0, "closed");
    }

    #[test]
    fn a_cross_per_point() {
        let l = crosses(&[[10.0, 20.0]], [1, 2, 3, 4]);
        assert_eq!(l.len(), 2);
        assert_eq!((l[0].a, l[0].b), ([5.0, 20.0], [15.0, 20.0]));
        assert_eq!((l[1].a, l[1].b), ([10.0, 15.0], [10.0, 25.0]));
    }
}
