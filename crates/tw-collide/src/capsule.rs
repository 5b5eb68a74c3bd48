//! A walker's vertical capsule moved through triangles: collide and slide, step up onto ledges,
//! land on the ground (the viewer's walk mode; docs/DESIGN.md "Where the new capabilities go").
//!
//! The capsule is the set of points within `radius` of its core segment, from `feet + radius·up`
//! to `feet + (height − radius)·up`; its distance to a triangle is the core's
//! ([`crate::closest::segment_triangle`], exact). A move:
//!
//! 1. **Horizontal** part, by *sub-stepped depenetration*: the motion is cut into sub-steps of at
//!    most an eighth of the radius ([`SUBSTEP`]); after each, the capsule is pushed out of the
//!    deepest triangle it penetrates, a bounded number of times ([`MAX_ITERATIONS`]). A contact
//!    whose normal is walkable (a floor, a gentle slope, a low edge under the rounded bottom)
//!    pushes straight up; any other (a wall, a riser, a steep slope) pushes along its normal
//!    without its upward part, so walls are slid along (the push removes the motion's normal
//!    component) and never climbed. A sub-step that cannot be resolved is undone and the move
//!    stops there (a corner).
//! 2. **Step up** when the horizontal part was blocked: up, the horizontal part again, down by
//!    what was risen; kept if a probe a radius ahead found a ledge to stand on and the landing
//!    went further and stands on walkable ground. The rounded bottom rides over edges up to
//!    `radius × (1 − cos 50°)` by itself, so the lift is the step height less that: stairs up
//!    to the step height are climbed, higher risers block.
//! 3. **Vertical** part (the caller's gravity or climb): sub-stepped the same way; touching
//!    walkable ground is reported ([`Moved::grounded`]) so that the caller stops falling.
//!
//! **No tunnelling.** Every translation of the capsule — a sub-step or a push — is shorter than
//! the core's distance to every triangle at its start: a sub-step is at most `radius / 8` and
//! starts from a non-penetrating position (distance ≥ radius − tolerance), a push is capped at
//! 0.9 × the nearest distance. The distance changes by at most the length of a translation, so
//! the core never touches a triangle during a move, however thin the wall and however long the
//! move: it cannot reach the other side. A move that starts penetrating (the walker was put
//! inside geometry) is first pushed out without that cap; if that fails it moves freely, so a
//! walker placed inside a wall can walk out of it.

use glam::{DVec3, Vec3};

use crate::closest::segment_triangle;
use crate::Aabb;

/// A triangle in scene space.
pub type Triangle = [[f32; 3]; 3];

/// Pushes per sub-step at most (a sub-step still penetrating after them is undone).
pub const MAX_ITERATIONS: usize = 8;
/// Sub-steps per part of a move at most; motion beyond `MAX_SUBSTEPS × SUBSTEP × radius` is dropped
/// (a frame's walk is a few centimetres; this bounds the work of a teleport).
pub const MAX_SUBSTEPS: usize = 256;
/// Sub-steps are at most this fraction of the radius: short enough that no translation reaches
/// a triangle (no tunnelling needs at most ½), and that a contact is judged walkable or not from
/// a position close to that of first contact: with ½, a sub-step into the top edge of a riser
/// taller than a step went deep enough to see the edge under the feet.
pub const SUBSTEP: f64 = 0.125;
/// Cosine of the steepest walkable slope (50°).
pub const WALKABLE_COS: f32 = 0.642_787_6;

/// Penetration tolerated, as a fraction of the radius (distances are computed in f64 from f32
/// positions).
const TOLERANCE: f64 = 1e-4;
/// The gap a push leaves, as a fraction of the radius; contacts within twice this count as
/// touching (so that a walker resting on the floor stays grounded).
const SKIN: f64 = 1e-3;

/// A vertical capsule: the walker's body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capsule {
    pub radius: f32,
    /// Feet to the top of the head (at least `2 × radius`).
    pub height: f32,
    /// The highest ledge stepped up onto.
    pub step_height: f32,
    /// Unit up axis.
    pub up: Vec3,
}

/// What a move did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Moved {
    /// Where the feet ended.
    pub feet: Vec3,
    /// The vertical part touched walkable ground (or a step was climbed).
    pub grounded: bool,
    /// The horizontal part was stopped or deflected (a wall).
    pub blocked: bool,
    /// The horizontal part stepped up onto a ledge.
    pub stepped: bool,
    /// Triangle distance tests made (for timing reports).
    pub tests: u64,
}

/// What one part of a move met.
#[derive(Clone, Copy, Debug, Default)]
struct Met {
    ground: bool,
    blocked: bool,
}

impl Capsule {
    /// A capsule of `radius` and `height` (raised to `2 × radius`) stepping up to `step_height`,
    /// standing along `up` (normalized; +z when zero).
    pub fn new(radius: f32, height: f32, step_height: f32, up: Vec3) -> Capsule {
        let radius = radius.abs().max(f32::MIN_POSITIVE);
        Capsule {
            radius,
            height: height.max(2.0 * radius),
            step_height: step_height.max(0.0),
            up: up.normalize_or(Vec3::Z),
        }
    }

    /// A walker's body in a store whose unit is `metres_per_unit` metres (non-finite or not
    /// positive: metres): radius, height (eye height and head) and step of [`tw_store::units`].
    pub fn walker(metres_per_unit: f64, up: Vec3) -> Capsule {
        use tw_store::units::{EYE_HEIGHT_M, HEAD_ABOVE_EYE_M, STEP_HEIGHT_M, WALKER_RADIUS_M};
        let unit = if metres_per_unit.is_finite() && metres_per_unit > 0.0 { metres_per_unit } else { 1.0 };
        let len = |m: f64| (m / unit) as f32;
        Capsule::new(len(WALKER_RADIUS_M), len(EYE_HEIGHT_M + HEAD_ABOVE_EYE_M), len(STEP_HEIGHT_M), up)
    }

    /// The core segment of the capsule standing at `feet`.
    pub fn core(&self, feet: DVec3) -> (DVec3, DVec3) {
        let up = self.up.as_dvec3();
        let r = self.radius as f64;
        (feet + up * r, feet + up * (self.height as f64 - r))
    }

    /// The box holding every triangle a move of `motion` from `feet` can touch: the capsule's
    /// box over the move (step-up included), grown by a radius for the step-up's probe and one
    /// for the pushes. Triangles outside it need not be given to [`move_by`](Self::move_by).
    pub fn reach(&self, feet: Vec3, motion: Vec3) -> Aabb {
        let up = self.up * self.step_height;
        let r = 3.0 * self.radius;
        let mut b = Aabb::EMPTY;
        for p in [feet, feet + motion, feet + up, feet + up + motion] {
            b = b.include(p.to_array()).include((p + self.up * self.height).to_array());
        }
        b.grow(r)
    }

    /// The clearance of the capsule at `feet`: the core's distance to the nearest triangle minus
    /// the radius (negative: penetrating), `f64::INFINITY` without triangles.
    pub fn clearance(&self, feet: Vec3, triangles: &[Triangle]) -> f64 {
        let (p, q) = self.core(feet.as_dvec3());
        triangles
            .iter()
            .map(|t| {
                let (s, x) = segment_triangle(p, q, &t.map(|v| Vec3::from_array(v).as_dvec3()));
                s.distance(x)
            })
            .fold(f64::INFINITY, f64::min)
            - self.radius as f64
    }

    /// Moves the capsule standing at `feet` by `motion` through `triangles` (see the module
    /// documentation). `scratch` is reused between calls (the triangles within reach).
    pub fn move_by(
        &self,
        feet: Vec3,
        motion: Vec3,
        triangles: &[Triangle],
        scratch: &mut Vec<Candidate>,
    ) -> Moved {
        scratch.clear();
        let reach = self.reach(feet, motion);
        for t in triangles {
            let b = Aabb::of_triangle(t);
            if b.overlaps(&reach) {
                let tri = t.map(|v| Vec3::from_array(v).as_dvec3());
                scratch.push(Candidate {
                    tri,
                    lo: DVec3::from_array(b.lo.map(f64::from)),
                    hi: DVec3::from_array(b.hi.map(f64::from)),
                });
            }
        }
        let mut w =
            Walker { capsule: self, up: self.up.as_dvec3(), r: self.radius as f64, tris: scratch, tests: 0 };
        let up = w.up;
        let start = feet.as_dvec3();
        let m = motion.as_dvec3();
        let vertical = up * m.dot(up);
        let horizontal = m - vertical;
        let start = match w.unstick(start) {
            Some(p) => p,
            // Inside geometry that cannot be left by pushing: move freely until out.
            None => return Moved { feet: (start + m).as_vec3(), tests: w.tests, ..Default::default() },
        };
        let (mut pos, met) = w.slide(start, horizontal, true, false);
        let mut moved = Moved { blocked: met.blocked, ..Default::default() };
        if met.blocked && self.step_height > 0.0 && horizontal != DVec3::ZERO {
            if let Some(p) = w.step_up(start, horizontal, pos) {
                pos = p;
                moved.stepped = true;
            }
        }
        let (end, met) = w.slide(pos, vertical, false, true);
        moved.feet = end.as_vec3();
        moved.grounded = moved.stepped || (met.ground && vertical.dot(up) <= 0.0);
        moved.tests = w.tests;
        moved
    }
}

/// A triangle within reach of a move, in f64 with its box.
#[derive(Clone, Copy, Debug)]
pub struct Candidate {
    tri: [DVec3; 3],
    lo: DVec3,
    hi: DVec3,
}

/// The nearest triangle to a core segment.
struct Nearest {
    distance: f64,
    /// Unit direction from the triangle to the core.
    normal: DVec3,
    /// The contact holds the walker up (pushed out upwards).
    walkable: bool,
    /// Some walkable contact is touching.
    ground: bool,
}

/// One move's state.
struct Walker<'a> {
    capsule: &'a Capsule,
    up: DVec3,
    r: f64,
    tris: &'a [Candidate],
    tests: u64,
}

impl Walker<'_> {
    /// Whether a contact of normal `normal` (triangle to core) with a triangle of face normal
    /// `face` holds the walker up. Moving sideways only the contact counts (a riser's top edge
    /// under the rounded bottom would otherwise be climbed whatever its height); landing, the
    /// edge of a walkable face under the feet holds too (standing on a step's nosing). The
    /// contact normal is that of a position at most a sub-step into the triangle
    /// ([`SUBSTEP`]), close to the one of first contact.
    fn walkable(&self, normal: DVec3, face: DVec3, landing: bool) -> bool {
        let s = normal.dot(self.up);
        s >= WALKABLE_COS as f64 || (landing && s > 0.0 && face.dot(self.up).abs() >= WALKABLE_COS as f64)
    }

    /// The nearest triangle to the capsule at `feet` (boxes farther than the radius and the skin
    /// are skipped: they neither penetrate nor touch). Of triangles equally near (an edge two
    /// faces share), a walkable one is taken, so that a step's nosing holds up what its riser
    /// would push aside.
    fn nearest(&mut self, feet: DVec3, landing: bool) -> Nearest {
        let (p, q) = self.capsule.core(feet);
        let reach = self.r * (1.0 + 4.0 * SKIN);
        let (lo, hi) = (p.min(q) - DVec3::splat(reach), p.max(q) + DVec3::splat(reach));
        let mut best = Nearest { distance: f64::INFINITY, normal: self.up, walkable: false, ground: false };
        let touch = self.r * (1.0 + 2.0 * SKIN);
        let tie = self.r * 1e-7;
        for c in self.tris {
            if c.lo.cmpgt(hi).any() || c.hi.cmplt(lo).any() {
                continue;
            }
            self.tests += 1;
            let (s, x) = segment_triangle(p, q, &c.tri);
            let d = s.distance(x);
            let face = face_normal(&c.tri, (p + q) * 0.5, self.up);
            let normal = if d > self.r * 1e-9 { (s - x) / d } else { face };
            let walkable = self.walkable(normal, face, landing);
            if d < touch && walkable {
                best.ground = true;
            }
            if d < best.distance - tie || (d < best.distance + tie && walkable && !best.walkable) {
                best.distance = best.distance.min(d);
                best.normal = normal;
                best.walkable = walkable;
            }
        }
        best
    }

    /// Pushes the capsule at `feet` out of the triangles it penetrates, each push at most
    /// `cap × ` the nearest distance (`None`: uncapped). `None` when still penetrating after
    /// [`MAX_ITERATIONS`] pushes.
    fn resolve(&mut self, mut feet: DVec3, cap: Option<f64>, landing: bool, met: &mut Met) -> Option<DVec3> {
        for _ in 0..=MAX_ITERATIONS {
            let n = self.nearest(feet, landing);
            met.ground |= n.ground;
            if n.distance >= self.r * (1.0 - TOLERANCE) {
                return Some(feet);
            }
            let need = self.r * (1.0 + SKIN) - n.distance;
            let s = n.normal.dot(self.up);
            let (dir, length) = if n.walkable {
                (self.up, need / s.max(1e-3))
            } else {
                met.blocked = true;
                // No upward part: walls and risers are slid along, never climbed.
                let h = if s > 0.0 { (n.normal - self.up * s).normalize_or(n.normal) } else { n.normal };
                (h, need / n.normal.dot(h).max(1e-3))
            };
            let length = cap.map_or(length, |c| length.min(c * n.distance));
            feet += dir * length;
        }
        None
    }

    /// Frees a capsule that starts penetrating (uncapped pushes); `None` when it cannot be.
    fn unstick(&mut self, feet: DVec3) -> Option<DVec3> {
        self.resolve(feet, None, false, &mut Met::default())
    }

    /// Moves by `motion` in sub-steps of at most [`SUBSTEP`] radii, resolving after each; stops at
    /// a sub-step that cannot be resolved. `horizontal`: a stop or a deflection counts as
    /// blocked; `nosings`: moving down, the edge of a walkable face under the feet holds
    /// ([`Walker::walkable`]).
    fn slide(&mut self, feet: DVec3, motion: DVec3, horizontal: bool, nosings: bool) -> (DVec3, Met) {
        let mut met = Met::default();
        let len = motion.length();
        let n = ((len / (SUBSTEP * self.r)).ceil() as usize).clamp(1, MAX_SUBSTEPS);
        let step = motion / n as f64;
        let landing = nosings && motion.dot(self.up) < 0.0;
        let mut pos = feet;
        for _ in 0..n {
            match self.resolve(pos + step, Some(0.9), landing, &mut met) {
                Some(p) => pos = p,
                None => {
                    met.blocked = true;
                    break;
                }
            }
        }
        if len == 0.0 {
            // Nothing to move: still report the ground under the feet.
            met.ground |= self.nearest(pos, true).ground;
        }
        if horizontal {
            let done = (pos - feet).dot(motion) / len.max(f64::MIN_POSITIVE);
            met.blocked |= len > 0.0 && done < len * 0.999;
        }
        (pos, met)
    }

    /// Up by the step height, `horizontal` again, back down by what was risen: the landing when
    /// a probe a radius ahead finds a ledge, and it got further along `horizontal` than `plain`
    /// did and stands on walkable ground.
    fn step_up(&mut self, start: DVec3, horizontal: DVec3, plain: DVec3) -> Option<DVec3> {
        // The rounded bottom climbs by itself edges up to `r (1 − cos θ)` above the feet (θ the
        // steepest walkable slope): lifted by that much less, the highest step is the step height.
        let lift = self.capsule.step_height as f64 - self.r * (1.0 - WALKABLE_COS as f64);
        if lift <= 0.0 {
            return None;
        }
        let (lifted, _) = self.slide(start, self.up * lift, false, false);
        let rise = (lifted - start).dot(self.up);
        if rise <= 0.0 {
            return None;
        }
        // Probe a radius ahead (a frame's motion is far less): only ground that holds the walker
        // up by itself (no nosing) is a ledge to step onto, not the top edge of a high riser
        // that the lifted rounded bottom rests against.
        let probe = horizontal.normalize_or_zero() * horizontal.length().max(self.r);
        let (ahead, _) = self.slide(lifted, probe, true, false);
        let (probed, met) = self.slide(ahead, -self.up * rise, false, false);
        let along = |p: DVec3| (p - start).dot(horizontal) / horizontal.length();
        // Pushed back off a riser's edge it lands on the floor it started from: no ledge.
        if !met.ground || along(probed) < along(plain) + 0.5 * self.r {
            return None;
        }
        let (ahead, _) = self.slide(lifted, horizontal, true, false);
        let (landed, met) = self.slide(ahead, -self.up * rise, false, true);
        (met.ground && along(landed) > along(plain) + self.r * 1e-3).then_some(landed)
    }
}

/// The unit normal of `tri` on the side of `towards` (`up` for a degenerate triangle).
fn face_normal(tri: &[DVec3; 3], towards: DVec3, up: DVec3) -> DVec3 {
    let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize_or(up);
    if n.dot(towards - tri[0]) < 0.0 {
        -n
    } else {
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tw_core::rng::Rng;

    const R: f32 = 0.3;
    const TOL: f64 = R as f64 * 1e-3;

    fn body() -> Capsule {
        Capsule::new(R, 1.8, 0.35, Vec3::Z)
    }

    /// Two triangles of the quad `a b c d`.
    fn quad(a: [f32; 3], b: [f32; 3], c: [f32; 3], d: [f32; 3]) -> [Triangle; 2] {
        [[a, b, c], [a, c, d]]
    }

    fn floor(z: f32, half: f32) -> [Triangle; 2] {
        quad([-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z])
    }

    /// A vertical wall at `x` from `y0` to `y1` (zero thickness), 3 high.
    fn wall_x(x: f32, y0: f32, y1: f32) -> [Triangle; 2] {
        quad([x, y0, 0.0], [x, y1, 0.0], [x, y1, 3.0], [x, y0, 3.0])
    }

    fn wall_y(y: f32, x0: f32, x1: f32) -> [Triangle; 2] {
        quad([x0, y, 0.0], [x1, y, 0.0], [x1, y, 3.0], [x0, y, 3.0])
    }

    /// An axis-aligned box's faces (no bottom).
    fn block(lo: [f32; 3], hi: [f32; 3]) -> Vec<Triangle> {
        let [x0, y0, z0] = lo;
        let [x1, y1, z1] = hi;
        let mut v = Vec::new();
        v.extend(quad([x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]));
        v.extend(quad([x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]));
        v.extend(quad([x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]));
        v.extend(quad([x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]));
        v.extend(quad([x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]));
        v
    }

    /// Walks `frames` moves of `step` (plus a fall of 0.05) from `feet`, checking after each
    /// that nothing is penetrated; returns the end.
    fn walk(c: &Capsule, tris: &[Triangle], mut feet: Vec3, step: Vec3, frames: usize) -> Moved {
        let mut scratch = Vec::new();
        let mut last = Moved { feet, ..Default::default() };
        for i in 0..frames {
            last = c.move_by(feet, step - Vec3::Z * 0.05, tris, &mut scratch);
            feet = last.feet;
            let clear = c.clearance(feet, tris);
            assert!(clear >= -TOL, "frame {i}: penetrating by {} at {feet}", -clear);
        }
        last
    }

    #[test]
    fn a_wall_stops_the_capsule_at_its_radius_and_is_slid_along() {
        let c = body();
        let mut tris = floor(0.0, 20.0).to_vec();
        tris.extend(wall_x(1.0, -20.0, 20.0));
        let end = walk(&c, &tris, Vec3::new(0.0, 0.0, 0.01), Vec3::new(0.05, 0.0, 0.0), 60);
        assert!((end.feet.x - (1.0 - R)).abs() < 0.01, "{}", end.feet);
        assert!(end.blocked && end.grounded && end.feet.z.abs() < 0.01, "{end:?}");
        // Diagonally into it: slides along y at the full y speed, x held.
        let end2 = walk(&c, &tris, end.feet, Vec3::new(0.05, 0.05, 0.0), 20);
        assert!((end2.feet.x - (1.0 - R)).abs() < 0.01, "{}", end2.feet);
        assert!((end2.feet.y - end.feet.y - 1.0).abs() < 0.01, "slid {}", end2.feet.y - end.feet.y);
    }

    #[test]
    fn a_corner_holds_the_capsule_in() {
        let c = body();
        let mut tris = floor(0.0, 20.0).to_vec();
        tris.extend(wall_x(1.0, -20.0, 20.0));
        tris.extend(wall_y(1.0, -20.0, 20.0));
        let end = walk(&c, &tris, Vec3::new(0.0, 0.0, 0.01), Vec3::new(0.07, 0.05, 0.0), 80);
        assert!((end.feet.x - 0.7).abs() < 0.01 && (end.feet.y - 0.7).abs() < 0.01, "{}", end.feet);
        // An acute wedge (30°) opening towards -x: pushed into its tip, never out of it.
        let mut tris = floor(0.0, 20.0).to_vec();
        let (s, k) = (15f32.to_radians().sin(), 15f32.to_radians().cos());
        let tip = [2.0, 0.0];
        let a = [tip[0] - 10.0 * k, tip[1] + 10.0 * s];
        let b = [tip[0] - 10.0 * k, tip[1] - 10.0 * s];
        tris.extend(quad([a[0], a[1], 0.0], [tip[0], tip[1], 0.0], [tip[0], tip[1], 3.0], [a[0], a[1], 3.0]));
        tris.extend(quad([b[0], b[1], 0.0], [tip[0], tip[1], 0.0], [tip[0], tip[1], 3.0], [b[0], b[1], 3.0]));
        for dir in [Vec3::X, Vec3::new(1.0, 0.3, 0.0), Vec3::new(1.0, -0.3, 0.0)] {
            let end = walk(&c, &tris, Vec3::new(-3.0, 0.0, 0.01), dir.normalize() * 0.1, 80);
            // The wedge's inside: between its walls, left of the tip.
            let side = end.feet.y.abs() * k - (tip[0] - end.feet.x) * s;
            assert!(side < 0.0 && end.feet.x < tip[0], "escaped the wedge to {}", end.feet);
        }
    }

    #[test]
    fn a_thin_wall_stops_a_move_much_longer_than_the_radius() {
        let c = body();
        let mut tris = floor(0.0, 20.0).to_vec();
        tris.extend(wall_x(1.0, -20.0, 20.0));
        let mut scratch = Vec::new();
        for len in [0.61, 0.9, 2.0, 5.0, 15.0] {
            let m = c.move_by(Vec3::new(0.35, 0.0, 0.01), Vec3::new(len, 0.0, 0.0), &tris, &mut scratch);
            assert!(m.feet.x <= 1.0 - R + 0.01 && m.feet.x > 0.6, "len {len}: {}", m.feet);
            assert!(c.clearance(m.feet, &tris) >= -TOL);
        }
        // From right next to it, a single push-sized step.
        let m = c.move_by(Vec3::new(0.7, 0.0, 0.01), Vec3::new(0.31, 0.0, 0.0), &tris, &mut scratch);
        assert!(m.feet.x < 1.0, "{}", m.feet);
    }

    #[test]
    fn stairs_are_climbed_up_to_the_step_height_and_higher_risers_block() {
        let c = body();
        let stairs = |rise: f32| {
            let mut tris = floor(0.0, 20.0).to_vec();
            for i in 0..5 {
                let x = 1.0 + 0.4 * i as f32;
                tris.extend(block([x, -2.0, 0.0], [x + 0.4, 2.0, rise * (i + 1) as f32]));
            }
            tris
        };
        // Step height 0.35: risers up to it are climbed, to the top of the fifth step.
        for rise in [0.1, 0.2, 0.33] {
            let end = walk(&c, &stairs(rise), Vec3::new(0.0, 0.0, 0.01), Vec3::new(0.03, 0.0, 0.0), 95);
            assert!(
                (end.feet.z - 5.0 * rise).abs() < 0.02 && end.feet.x > 2.6,
                "rise {rise}: did not climb: {}",
                end.feet
            );
        }
        for rise in [0.4, 0.45, 1.0] {
            let end = walk(&c, &stairs(rise), Vec3::new(0.0, 0.0, 0.01), Vec3::new(0.03, 0.0, 0.0), 120);
            assert!(end.feet.z < 0.01 && end.feet.x < 1.0 - R + 0.01, "climbed a {rise} riser: {}", end.feet);
        }
    }

    #[test]
    fn walkable_slopes_are_walked_up_and_steep_ones_block() {
        let c = body();
        let ramp = |deg: f32| {
            let t = deg.to_radians().tan();
            let mut tris = floor(0.0, 20.0).to_vec();
            tris.extend(quad([1.0, -3.0, 0.0], [6.0, -3.0, 5.0 * t], [6.0, 3.0, 5.0 * t], [1.0, 3.0, 0.0]));
            tris
        };
        let gentle = ramp(25.0);
        let end = walk(&c, &gentle, Vec3::new(0.0, 0.0, 0.01), Vec3::new(0.03, 0.0, 0.0), 150);
        let expect = (end.feet.x - 1.0) * 25f32.to_radians().tan();
        assert!(
            end.feet.x > 3.5 && (end.feet.z - expect).abs() < 0.2,
            "{} (expected z ≈ {expect})",
            end.feet
        );
        // Standing still on it: no sliding down.
        let rest = walk(&c, &gentle, end.feet, Vec3::ZERO, 50);
        assert!((rest.feet - end.feet).length() < 0.01 && rest.grounded, "{} → {}", end.feet, rest.feet);
        let steep = ramp(70.0);
        let end = walk(&c, &steep, Vec3::new(0.0, 0.0, 0.01), Vec3::new(0.03, 0.0, 0.0), 100);
        assert!(end.feet.z < 0.4 && end.feet.x < 1.2, "climbed a 70° slope: {}", end.feet);
    }

    #[test]
    fn a_capsule_put_into_a_wall_is_pushed_out_and_walks_on() {
        let c = body();
        let tris = wall_y(0.0, -5.0, 5.0);
        let m = walk_free(&c, &tris, Vec3::new(1.0, 0.1, 0.5), Vec3::new(0.0, 0.1, 0.0), 20);
        assert!(m.y > 2.0 && c.clearance(m, &tris) >= -TOL, "stuck at {m}");
    }

    /// As [`walk`], without the check (the start penetrates).
    fn walk_free(c: &Capsule, tris: &[Triangle], mut feet: Vec3, step: Vec3, frames: usize) -> Vec3 {
        let mut scratch = Vec::new();
        for _ in 0..frames {
            feet = c.move_by(feet, step, tris, &mut scratch).feet;
        }
        feet
    }

    /// Uniform in [0, 1], from the project's generator.
    fn unit(rng: &mut Rng) -> f32 {
        rng.f64() as f32
    }

    #[test]
    fn random_walks_in_a_room_with_pillars_never_penetrate() {
        let c = body();
        for seed in 1..=6u64 {
            let mut rng = Rng::new(seed);
            let mut tris = floor(0.0, 6.0).to_vec();
            tris.extend(wall_x(-5.0, -5.0, 5.0));
            tris.extend(wall_x(5.0, -5.0, 5.0));
            tris.extend(wall_y(-5.0, -5.0, 5.0));
            tris.extend(wall_y(5.0, -5.0, 5.0));
            for _ in 0..12 {
                let (x, y) = (unit(&mut rng) * 8.0 - 4.0, unit(&mut rng) * 8.0 - 4.0);
                let (w, d) = (0.05 + unit(&mut rng) * 0.6, 0.05 + unit(&mut rng) * 0.6);
                // Some pillars are low (stepped onto), some are sheets of no thickness.
                let h = if unit(&mut rng) < 0.3 { 0.1 + unit(&mut rng) * 0.3 } else { 3.0 };
                let d = if unit(&mut rng) < 0.2 { 0.0 } else { d };
                tris.extend(block([x, y, 0.0], [x + w, y + d, h]));
            }
            let mut feet = Vec3::new(0.0, 0.0, 0.01);
            // Put it somewhere free.
            while c.clearance(feet, &tris) < 0.0 {
                feet = Vec3::new(unit(&mut rng) * 8.0 - 4.0, unit(&mut rng) * 8.0 - 4.0, 0.01);
            }
            let mut scratch = Vec::new();
            for i in 0..400 {
                let len = if unit(&mut rng) < 0.1 { unit(&mut rng) * 3.0 } else { unit(&mut rng) * 0.1 };
                let a = unit(&mut rng) * std::f32::consts::TAU;
                let m = Vec3::new(a.cos() * len, a.sin() * len, -0.05);
                let moved = c.move_by(feet, m, &tris, &mut scratch);
                let clear = c.clearance(moved.feet, &tris);
                assert!(clear >= -TOL, "seed {seed} move {i}: penetrating by {} at {}", -clear, moved.feet);
                let f = moved.feet;
                assert!(
                    f.x.abs() < 5.0 && f.y.abs() < 5.0 && f.z > -0.01,
                    "seed {seed} move {i}: left the room to {f}"
                );
                feet = f;
            }
        }
    }
}
