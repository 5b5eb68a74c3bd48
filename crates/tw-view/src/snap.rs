//! Snapping a measurement point on a picked triangle, plain data: to the nearest corner whose
//! projection lies within a pixel radius of the click, else to the nearest point of one of the
//! triangle's edges within that radius, else the surface point itself ([`snap_point`]). The
//! decision is taken on the screen, so the tolerance does not depend on the distance; the point
//! returned lies exactly on the vertex or edge (interpolated between the edge's corners,
//! perspective-correct), so that measuring between two edges gives the model's distance.

use glam::{Mat4, Vec2, Vec3};

/// What a measurement point snapped to (the HUD says it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Snap {
    Vertex,
    Edge,
    Surface,
}

impl Snap {
    pub fn name(self) -> &'static str {
        match self {
            Snap::Vertex => "vertex",
            Snap::Edge => "edge",
            Snap::Surface => "surface",
        }
    }

    /// The end of a measurement message: ", snapped to a vertex", ", snapped to an edge",
    /// ", on the surface".
    pub fn phrase(self) -> &'static str {
        match self {
            Snap::Vertex => ", snapped to a vertex",
            Snap::Edge => ", snapped to an edge",
            Snap::Surface => ", on the surface",
        }
    }
}

/// A `w` × `h` viewport seen through `view_projection`: scene points to window pixels (y down).
#[derive(Clone, Copy, Debug)]
pub struct Screen {
    pub view_projection: Mat4,
    pub w: f32,
    pub h: f32,
}

impl Screen {
    /// The pixel of `p` and its clip-space w, `None` behind the eye.
    fn project(&self, p: Vec3) -> Option<(Vec2, f32)> {
        let c = self.view_projection * p.extend(1.0);
        (c.w > 0.0).then(|| {
            let px = Vec2::new((c.x / c.w * 0.5 + 0.5) * self.w, (0.5 - c.y / c.w * 0.5) * self.h);
            (px, c.w)
        })
    }
}

/// Snaps `point` (on the triangle `corners`) to a corner within `max_px` pixels, else to the
/// nearest edge point within `max_px`, else keeps it (see the module doc).
pub fn snap_point(point: Vec3, corners: &[Vec3; 3], screen: &Screen, max_px: f32) -> (Vec3, Snap) {
    let Some((at, _)) = screen.project(point) else { return (point, Snap::Surface) };
    if let Some(v) = nearest_vertex(at, corners, screen, max_px) {
        return (v, Snap::Vertex);
    }
    match nearest_edge_point(at, corners, screen, max_px) {
        Some(e) => (e, Snap::Edge),
        None => (point, Snap::Surface),
    }
}

/// The corner whose pixel is nearest `at`, within `max_px`.
fn nearest_vertex(at: Vec2, corners: &[Vec3; 3], screen: &Screen, max_px: f32) -> Option<Vec3> {
    corners
        .iter()
        .filter_map(|&c| screen.project(c).map(|(px, _)| (c, px.distance(at))))
        .filter(|(_, d)| d.is_finite() && *d <= max_px)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(c, _)| c)
}

/// The point of the triangle's edges whose pixel is nearest `at`, within `max_px`.
fn nearest_edge_point(at: Vec2, corners: &[Vec3; 3], screen: &Screen, max_px: f32) -> Option<Vec3> {
    (0..3)
        .filter_map(|i| closest_on_edge(at, corners[i], corners[(i + 1) % 3], screen))
        .filter(|(_, d)| d.is_finite() && *d <= max_px)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(p, _)| p)
}

/// The point of segment `a b` whose projection is nearest the pixel `at`, and its distance in
/// pixels. The nearest point is found on the screen (parameter `s` along the projected
/// segment) and taken back to the segment with the perspective-correct parameter
/// `t = s·w_a / ((1 − s)·w_b + s·w_a)` (screen positions interpolate linearly in 1/w).
pub fn closest_on_edge(at: Vec2, a: Vec3, b: Vec3, screen: &Screen) -> Option<(Vec3, f32)> {
    let (pa, wa) = screen.project(a)?;
    let (pb, wb) = screen.project(b)?;
    let d = pb - pa;
    let len2 = d.length_squared();
    let s = if len2 > 0.0 { ((at - pa).dot(d) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let px = pa + d * s;
    let denom = (1.0 - s) * wb + s * wa;
    let t = if denom > 0.0 { (s * wa / denom).clamp(0.0, 1.0) } else { s };
    // The ends themselves, exactly (a lerp at 0 or 1 would round).
    let p = match t {
        0.0 => a,
        1.0 => b,
        _ => a.lerp(b, t),
    };
    Some((p, px.distance(at)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tw_runtime::Camera;

    /// Looking down −Z at the unit triangle from 5 units, 100 × 100 pixels, ~45° fov.
    fn screen(size: f32) -> Screen {
        let cam = Camera::new(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y, 0.8, 0.1, 100.0).unwrap();
        Screen { view_projection: cam.view_projection(1.0), w: size, h: size }
    }

    const TRI: [Vec3; 3] = [Vec3::ZERO, Vec3::X, Vec3::Y];

    #[test]
    fn a_corner_within_the_radius_wins() {
        // 0.02 units from (1, 0, 0): about 0.5 px at this distance.
        let (p, s) = snap_point(Vec3::new(0.98, 0.01, 0.0), &TRI, &screen(100.0), 6.0);
        assert_eq!((p, s), (Vec3::X, Snap::Vertex));
    }

    #[test]
    fn near_an_edge_the_point_moves_onto_it() {
        // Near the bottom edge (y = 0), far from its corners: onto the edge, x kept.
        let (p, s) = snap_point(Vec3::new(0.4, 0.02, 0.0), &TRI, &screen(100.0), 6.0);
        assert_eq!(s, Snap::Edge);
        assert_eq!(p.y, 0.0);
        assert!((p.x - 0.4).abs() < 1e-4, "{p}");
        // Near the hypotenuse: onto x + y = 1.
        let (p, s) = snap_point(Vec3::new(0.48, 0.48, 0.0), &TRI, &screen(100.0), 6.0);
        assert_eq!(s, Snap::Edge);
        assert!((p.x + p.y - 1.0).abs() < 1e-6 && (p.x - 0.5).abs() < 1e-4, "{p}");
    }

    #[test]
    fn far_from_corners_and_edges_it_stays_on_the_surface() {
        let mid = Vec3::new(0.3, 0.3, 0.0);
        assert_eq!(snap_point(mid, &TRI, &screen(100.0), 6.0), (mid, Snap::Surface));
        // The same small offset on a 10 000-pixel viewport is many pixels: not snapped.
        let near = Vec3::new(0.4, 0.02, 0.0);
        assert_eq!(snap_point(near, &TRI, &screen(1e4), 6.0), (near, Snap::Surface));
    }

    /// An edge receding from the eye: the nearest screen point maps back to the 3D point
    /// whose projection it is (perspective-correct), not to the screen parameter.
    #[test]
    fn edge_points_are_perspective_correct() {
        let cam = Camera::new(Vec3::new(0.0, -5.0, 1.0), Vec3::new(0.0, 0.0, 1.0), Vec3::Z, 0.8, 0.1, 100.0)
            .unwrap();
        let sc = Screen { view_projection: cam.view_projection(1.0), w: 400.0, h: 400.0 };
        let (a, b) = (Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 10.0, 0.0));
        let target = Vec3::new(1.0, 3.0, 0.0);
        let (at, _) = sc.project(target).unwrap();
        let (p, d) = closest_on_edge(at, a, b, &sc).unwrap();
        assert!(d < 1e-3 && (p - target).length() < 1e-4, "{p} at {d} px");
    }

    #[test]
    fn edge_ends_are_exact_and_a_point_edge_is_harmless() {
        let sc = screen(100.0);
        let (at, _) = sc.project(Vec3::new(-0.5, 0.0, 0.0)).unwrap();
        assert_eq!(closest_on_edge(at, Vec3::ZERO, Vec3::X, &sc).unwrap().0, Vec3::ZERO);
        let (p, d) = closest_on_edge(at, Vec3::X, Vec3::X, &sc).unwrap();
        assert!(p == Vec3::X && d > 0.0);
    }

    #[test]
    fn names_for_the_hud() {
        assert_eq!(Snap::Edge.name(), "edge");
        assert!(Snap::Vertex.phrase().ends_with("snapped to a vertex"));
    }
}
