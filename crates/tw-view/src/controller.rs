//! Camera controllers (fly, walk, orbit) as plain data: [`Controller::update`] takes the frame
//! time and an [`Input`] (keys held, mouse motion, scroll) and moves the camera; no window is
//! involved, so the motion is unit-tested.
//!
//! - **Fly**: WASD (and Q/E down/up) along the view, mouse look (yaw about the scene's up axis,
//!   pitch clamped short of the poles), speed scaled by the scroll wheel (through an
//!   orthographic camera the wheel zooms instead), starting at a fraction
//!   of the model's size; velocity is smoothed (exponential approach), so motion starts and stops
//!   softly.
//! - **Walk**: as fly but horizontal, at walking speed, falling under gravity along the up axis.
//!   With a [`Collide`] (the viewer's: the walker's capsule against the resident geometry,
//!   `tw_collide::capsule`) the feet, `eye_height` below the eye, are moved by the frame's
//!   motion through it: walls stop and are slid along, steps are climbed, the fall stops on
//!   the ground it reports. Without one ("fly through", or no geometry at hand) the eye is held
//!   at `eye_height` above the ground below it (the caller finds it by casting a ray down,
//!   [`Input::ground`]), and walls are walked through. Either way the floor is at least the
//!   bottom of the model's bounds. Eye height (1.7 m), walking speed (1.4 m/s) and gravity
//!   (9.81 m/s²) are human-scale lengths converted with the store's units
//!   ([`tw_store::units`], the definitions `terawalk path` uses too): a millimetre model is
//!   walked 1700 units above its deck.
//! - **Orbit**: around a pivot (a clicked point): mouse drag turns, scroll and W/S change the
//!   distance (smoothed), A/D turn.
//!
//! Any mode may look through an orthographic camera ([`Controller::set_orthographic`]): the eye
//! and its motion stay, the projection has a view height instead of the field of view. In orbit
//! mode zooming scales the view height with the distance, so the zoom still shows; in fly and
//! walk mode the wheel scales the view height (moving along the view changes nothing on screen
//! there) and leaves the speed alone.

use glam::Vec3;
use tw_runtime::camera::DEFAULT_FOVY_DEG;
use tw_runtime::{Camera, Projection};
use tw_store::units::{EYE_HEIGHT_M, GRAVITY_M_S2, WALK_SPEED_M_S};

/// Camera mode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    #[default]
    Fly,
    Walk,
    Orbit,
}

impl Mode {
    pub fn name(self) -> &'static str {
        match self {
            Mode::Fly => "fly",
            Mode::Walk => "walk",
            Mode::Orbit => "orbit",
        }
    }
}

/// One frame's input, already reduced to axes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Input {
    /// +1 forward (W), −1 back (S).
    pub forward: f32,
    /// +1 right (D), −1 left (A).
    pub right: f32,
    /// +1 up (E), −1 down (Q).
    pub up: f32,
    /// Shift: four times faster.
    pub fast: bool,
    /// Mouse motion while looking, pixels (x right, y down).
    pub look: [f32; 2],
    /// Scroll wheel steps (positive = away from the user / up).
    pub scroll: f32,
    /// Height (along up) of the ground below the eye, if a ray down hit something.
    pub ground: Option<f32>,
}

/// Where a walker's move ended ([`Collide::walk`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Walked {
    pub feet: Vec3,
    /// Standing on walkable ground: the fall stops.
    pub grounded: bool,
}

/// Moves a walker's feet through the scene: the walk mode's collision, supplied by the caller so
/// that the controller stays free of windows and geometry.
pub trait Collide {
    /// The feet at `feet` moved by `motion` (scene units; gravity's part along −up included).
    fn walk(&mut self, feet: Vec3, motion: Vec3) -> Walked;
}

/// Radians of turn per pixel of mouse motion.
pub const LOOK_SENSITIVITY: f32 = 0.004;
/// Pitch limit (radians): just short of straight up/down.
pub const MAX_PITCH: f32 = 1.54;
/// Velocity smoothing rate (1/s): higher is snappier.
pub const SMOOTHING: f32 = 10.0;
/// One wheel step of zoom: orbit distance or orthographic view height × this (in: up/away).
pub const ZOOM_STEP: f32 = 0.85;

/// What a controller needs of the scene: its bounds and up axis (scene space) and the size of
/// its unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneFrame {
    pub bounds: (Vec3, Vec3),
    /// The up axis (need not be unit length).
    pub up: Vec3,
    /// Metres per scene unit (the store's units; 1 when it records none).
    pub metres_per_unit: f32,
}

/// The camera state and its controller; see the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct Controller {
    pub mode: Mode,
    pub eye: Vec3,
    /// Angle about `up` from `e1` towards `e2`.
    pub yaw: f32,
    /// Angle above the horizontal plane.
    pub pitch: f32,
    /// Unit scene up axis and two unit horizontal axes (right-handed: e1 × e2 = up).
    pub up: Vec3,
    e1: Vec3,
    e2: Vec3,
    /// The perspective field of view (radians); also the one an orthographic view returns to.
    pub fovy: f32,
    /// `Some(height)`: the camera is orthographic, its view `height` scene units high.
    pub ortho_height: Option<f32>,
    /// Fly speed, scene units per second (a fraction of the model's size).
    pub speed: f32,
    /// Walk speed, scene units per second (1.4 m/s in the store's units).
    pub walk_speed: f32,
    /// Diagonal of the model's bounds (scales speeds and limits).
    pub scene_size: f32,
    /// Scene bounds (for clip planes and the default floor).
    pub bounds: (Vec3, Vec3),
    velocity: Vec3,
    /// Walk mode's eye height above the ground, scene units (1.7 m in the store's units).
    pub eye_height: f32,
    /// Walk mode's gravity, scene units per second squared (9.81 m/s²).
    pub gravity: f32,
    vertical_speed: f32,
    pub pivot: Vec3,
    pub distance: f32,
    target_distance: f32,
}

impl Controller {
    /// A controller at `camera` for the scene `frame`.
    pub fn new(camera: &Camera, frame: &SceneFrame) -> Controller {
        let SceneFrame { bounds, up, metres_per_unit } = *frame;
        let unit = if metres_per_unit.is_finite() && metres_per_unit > 0.0 { metres_per_unit } else { 1.0 };
        let up = up.normalize_or(Vec3::Z);
        let e1 = if up.dot(Vec3::X).abs() < 0.9 { Vec3::X } else { Vec3::Y };
        let e1 = (e1 - up * e1.dot(up)).normalize();
        let e2 = up.cross(e1);
        let scene_size = (bounds.1 - bounds.0).length().max(1e-6);
        let mut c = Controller {
            mode: Mode::Fly,
            eye: camera.eye,
            yaw: 0.0,
            pitch: 0.0,
            up,
            e1,
            e2,
            fovy: match camera.projection {
                Projection::Perspective { fovy } => fovy,
                Projection::Orthographic { .. } => DEFAULT_FOVY_DEG.to_radians() as f32,
            },
            ortho_height: match camera.projection {
                Projection::Perspective { .. } => None,
                Projection::Orthographic { height } => Some(height),
            },
            speed: scene_size * 0.05,
            walk_speed: (WALK_SPEED_M_S / unit as f64) as f32,
            scene_size,
            bounds,
            velocity: Vec3::ZERO,
            eye_height: (EYE_HEIGHT_M / unit as f64) as f32,
            gravity: (GRAVITY_M_S2 / unit as f64) as f32,
            vertical_speed: 0.0,
            pivot: camera.target,
            distance: (camera.target - camera.eye).length(),
            target_distance: (camera.target - camera.eye).length(),
        };
        c.look_at(camera.target);
        c
    }

    /// Turns the view towards `target` (keeps the eye).
    pub fn look_at(&mut self, target: Vec3) {
        let d = (target - self.eye).normalize_or(self.e1);
        self.pitch = d.dot(self.up).clamp(-1.0, 1.0).asin().clamp(-MAX_PITCH, MAX_PITCH);
        self.yaw = d.dot(self.e2).atan2(d.dot(self.e1));
    }

    /// Unit view direction.
    pub fn forward(&self) -> Vec3 {
        let h = self.e1 * self.yaw.cos() + self.e2 * self.yaw.sin();
        h * self.pitch.cos() + self.up * self.pitch.sin()
    }

    /// Unit horizontal direction of view.
    pub fn forward_horizontal(&self) -> Vec3 {
        self.e1 * self.yaw.cos() + self.e2 * self.yaw.sin()
    }

    /// Unit right direction (horizontal).
    pub fn right(&self) -> Vec3 {
        self.forward_horizontal().cross(self.up).normalize()
    }

    /// Switches mode. Into orbit: the pivot is `pivot` if given, else the point `distance`
    /// ahead; into walk: falling starts from rest.
    pub fn set_mode(&mut self, mode: Mode, pivot: Option<Vec3>) {
        if mode == Mode::Orbit {
            let p = pivot.unwrap_or(self.eye + self.forward() * (self.scene_size * 0.25));
            self.set_pivot(p);
        }
        if mode == Mode::Walk {
            // Walkers look ahead, not down.
            self.pitch = 0.0;
        }
        self.vertical_speed = 0.0;
        self.velocity = Vec3::ZERO;
        self.mode = mode;
    }

    /// Orbit around `p` from the current eye.
    pub fn set_pivot(&mut self, p: Vec3) {
        self.pivot = p;
        self.distance = (p - self.eye).length().max(self.scene_size * 1e-4);
        self.target_distance = self.distance;
        self.look_at(p);
    }

    /// Advances by `dt` seconds (walk mode without collision).
    pub fn update(&mut self, dt: f32, input: &Input) {
        self.update_with(dt, input, None);
    }

    /// Advances by `dt` seconds; in walk mode the feet move through `collide` when given.
    pub fn update_with(&mut self, dt: f32, input: &Input, collide: Option<&mut dyn Collide>) {
        let dt = dt.clamp(0.0, 0.25);
        let [dx, dy] = input.look;
        self.yaw -= dx * LOOK_SENSITIVITY;
        self.pitch = (self.pitch - dy * LOOK_SENSITIVITY).clamp(-MAX_PITCH, MAX_PITCH);
        let blend = 1.0 - (-SMOOTHING * dt).exp();
        let boost = if input.fast { 4.0 } else { 1.0 };
        match self.mode {
            Mode::Fly | Mode::Walk => {
                let (lo, hi) = (self.scene_size * 1e-5, self.scene_size * 10.0);
                let speed = if self.mode == Mode::Walk { &mut self.walk_speed } else { &mut self.speed };
                if let (Some(h), true) = (&mut self.ortho_height, input.scroll != 0.0) {
                    // Orthographic: the wheel zooms (the view height, by orbit zoom's step), as
                    // moving closer does not; the speed stays.
                    *h = (*h * ZOOM_STEP.powf(input.scroll)).clamp(lo.min(*h), hi.max(*h));
                } else if input.scroll != 0.0 {
                    // Within a range scaled to the model; a walking speed already outside it (a
                    // model far smaller or larger than a person) may only move back towards it.
                    *speed = (*speed * 1.2f32.powf(input.scroll)).clamp(lo.min(*speed), hi.max(*speed));
                }
                let speed = *speed;
                let (fwd, vert) = if self.mode == Mode::Fly {
                    (self.forward(), input.up)
                } else {
                    (self.forward_horizontal(), 0.0)
                };
                let wish = (fwd * input.forward + self.right() * input.right + self.up * vert)
                    .clamp_length_max(1.0)
                    * speed
                    * boost;
                self.velocity += (wish - self.velocity) * blend;
                match (self.mode, collide) {
                    (Mode::Walk, Some(c)) => self.walk_through(dt, c),
                    (Mode::Walk, None) => {
                        self.eye += self.velocity * dt;
                        self.apply_gravity(dt, input.ground);
                    }
                    _ => self.eye += self.velocity * dt,
                }
            }
            Mode::Orbit => {
                self.yaw -= input.right * 1.5 * dt;
                if input.scroll != 0.0 || input.forward != 0.0 {
                    let steps = input.scroll + input.forward * dt * 4.0 * boost;
                    self.target_distance = (self.target_distance * ZOOM_STEP.powf(steps))
                        .clamp(self.scene_size * 1e-4, self.scene_size * 10.0);
                }
                let before = self.distance;
                self.distance += (self.target_distance - self.distance) * blend;
                if let Some(h) = &mut self.ortho_height {
                    // Zooming an orthographic view: its height follows the distance.
                    if before > 0.0 && self.distance > 0.0 {
                        *h *= self.distance / before;
                    }
                }
                self.eye = self.pivot - self.forward() * self.distance;
            }
        }
    }

    /// Walk mode with collision: the frame's horizontal motion and fall move the feet through
    /// `collide`; standing on ground stops the fall. The bottom of the model's bounds is a floor.
    fn walk_through(&mut self, dt: f32, collide: &mut dyn Collide) {
        self.vertical_speed -= self.gravity * dt;
        let motion = self.velocity * dt + self.up * (self.vertical_speed * dt);
        let feet = self.eye - self.up * self.eye_height;
        let walked = collide.walk(feet, motion);
        self.eye = walked.feet + self.up * self.eye_height;
        if walked.grounded && self.vertical_speed < 0.0 {
            self.vertical_speed = 0.0;
        }
        let floor = self.bounds.0.dot(self.up).min(self.bounds.1.dot(self.up)) + self.eye_height;
        let h = self.eye.dot(self.up);
        if h < floor {
            self.eye += self.up * (floor - h);
            self.vertical_speed = 0.0;
        }
    }

    /// Walk mode: hold the eye `eye_height` above the ground, falling at g towards it.
    fn apply_gravity(&mut self, dt: f32, ground: Option<f32>) {
        let floor = ground.unwrap_or_else(|| self.bounds.0.dot(self.up).min(self.bounds.1.dot(self.up)));
        let want = floor + self.eye_height;
        let h = self.eye.dot(self.up);
        if h > want {
            self.vertical_speed -= self.gravity * dt;
            let new_h = (h + self.vertical_speed * dt).max(want);
            self.eye += self.up * (new_h - h);
            if new_h <= want {
                self.vertical_speed = 0.0;
            }
        } else {
            // Steps up onto higher ground at once.
            self.eye += self.up * (want - h);
            self.vertical_speed = 0.0;
        }
    }

    /// Switches to the orthographic camera (`on`) or back to perspective, keeping what is
    /// `focus` units ahead at its size on screen: the orthographic view is as high as the
    /// perspective one is at that depth ([`Camera::view_height_at`]). The eye does not move.
    pub fn set_orthographic(&mut self, on: bool, focus: f32) {
        if !on {
            self.ortho_height = None;
            return;
        }
        let focus = if focus.is_finite() && focus > 0.0 { focus } else { self.scene_size * 0.5 };
        let perspective = Camera { projection: Projection::Perspective { fovy: self.fovy }, ..self.camera() };
        self.ortho_height = Some(perspective.view_height_at(focus as f64) as f32);
    }

    /// The speed of the current mode (walk or fly), scene units per second.
    pub fn active_speed(&self) -> f32 {
        if self.mode == Mode::Walk {
            self.walk_speed
        } else {
            self.speed
        }
    }

    /// Whether the camera is still moving (smoothing or falling): the viewer keeps redrawing.
    pub fn is_moving(&self) -> bool {
        self.velocity.length() > self.active_speed() * 1e-3
            || self.vertical_speed != 0.0
            || (self.mode == Mode::Orbit
                && (self.distance - self.target_distance).abs() > self.distance * 1e-4)
    }

    /// The scene camera: clip planes from the eye's distance to the farthest bounds corner
    /// (as [`Camera::from_input_coordinates`]); orthographic while
    /// [`ortho_height`](Self::ortho_height) is set.
    pub fn camera(&self) -> Camera {
        let (near, far) = clip_planes(self.eye, self.bounds);
        let projection = match self.ortho_height {
            Some(height) => Projection::Orthographic { height },
            None => Projection::Perspective { fovy: self.fovy },
        };
        Camera { eye: self.eye, target: self.eye + self.forward(), up: self.up, projection, near, far }
    }
}

/// Near and far planes seeing all of `bounds` from `eye`.
pub fn clip_planes(eye: Vec3, bounds: (Vec3, Vec3)) -> (f32, f32) {
    let (lo, hi) = bounds;
    let corner = (eye - lo).abs().max((eye - hi).abs()).length();
    let far = (corner * 1.01).max((hi - lo).length() * 1e-3).max(1e-3);
    (far * tw_runtime::camera::NEAR_FAR_RATIO, far)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A controller in a 20-unit cube of a store in `metres_per_unit`.
    fn ctl_in(metres_per_unit: f32) -> Controller {
        let cam =
            Camera::new(Vec3::new(0.0, -10.0, 2.0), Vec3::new(0.0, 0.0, 2.0), Vec3::Z, 1.0, 0.01, 100.0)
                .unwrap();
        let frame =
            SceneFrame { bounds: (Vec3::splat(-10.0), Vec3::splat(10.0)), up: Vec3::Z, metres_per_unit };
        Controller::new(&cam, &frame)
    }

    fn ctl() -> Controller {
        ctl_in(1.0)
    }

    #[test]
    fn walk_scale_follows_the_store_units() {
        // A millimetre store: 1.7 m above the deck is 1700 units, 9.81 m/s² is 9810 units/s².
        let mm = ctl_in(1e-3);
        assert!((mm.eye_height - 1700.0).abs() < 1e-2, "{}", mm.eye_height);
        assert!((mm.gravity - 9810.0).abs() < 1e-1, "{}", mm.gravity);
        assert!((mm.walk_speed - 1400.0).abs() < 1e-2, "{}", mm.walk_speed);
        let m = ctl_in(1.0);
        assert!((m.eye_height - 1.7).abs() < 1e-6 && (m.walk_speed - 1.4).abs() < 1e-6);
        // Fly speed stays a fraction of the model, whatever the units.
        assert_eq!(mm.speed, m.speed);
        // Nonsense units fall back to metres rather than a zero or infinite eye height.
        assert_eq!(ctl_in(0.0).eye_height, m.eye_height);
        assert_eq!(ctl_in(f32::NAN).eye_height, m.eye_height);
    }

    #[test]
    fn walking_uses_the_walk_speed_and_falls_at_g() {
        let mut c = ctl_in(1e-3);
        c.set_mode(Mode::Walk, None);
        let start = c.eye;
        let w = Input { forward: 1.0, ground: Some(-1e6), ..Default::default() };
        for _ in 0..200 {
            c.update(0.01, &w);
        }
        // Falling from rest for 2 s under 9810 units/s² drops ½ g t² ≈ 19 620 units.
        let fell = start.z - c.eye.z;
        assert!((fell - 0.5 * 9810.0 * 2.0 * 2.0).abs() < 0.02 * fell, "{fell}");
        // Settled at walking speed: the last frame moved 1400 units/s horizontally.
        let before = c.eye;
        c.update(0.01, &w);
        let step = (c.eye - before) * Vec3::new(1.0, 1.0, 0.0);
        assert!((step.length() / 0.01 - 1400.0).abs() < 5.0, "{step:?}");
    }

    #[test]
    fn starts_looking_at_the_target() {
        let c = ctl();
        assert!((c.forward() - Vec3::Y).length() < 1e-5, "{:?}", c.forward());
        let cam = c.camera();
        assert!(cam.validate().is_ok());
        assert!(cam.far > 20.0);
    }

    #[test]
    fn fly_moves_forward_smoothly_and_stops() {
        let mut c = ctl();
        let start = c.eye;
        let w = Input { forward: 1.0, ..Default::default() };
        c.update(0.016, &w);
        let first = (c.eye - start).length();
        for _ in 0..60 {
            c.update(0.016, &w);
        }
        let moved = c.eye - start;
        assert!(moved.y > 0.0 && moved.x.abs() < 1e-4, "{moved:?}");
        // Smooth: the first frame moves less than full speed would.
        assert!(first < c.speed * 0.016 * 0.5);
        for _ in 0..120 {
            c.update(0.016, &Input::default());
        }
        assert!(!c.is_moving());
    }

    #[test]
    fn scroll_changes_speed_and_look_turns() {
        let mut c = ctl();
        let s = c.speed;
        c.update(0.016, &Input { scroll: 2.0, ..Default::default() });
        assert!((c.speed / s - 1.44).abs() < 1e-3);
        // Mouse right turns right (yaw decreases: from +Y towards +X).
        c.update(0.016, &Input { look: [100.0, 0.0], ..Default::default() });
        assert!(c.forward().x > 0.3, "{:?}", c.forward());
        // Pitch is clamped.
        c.update(0.016, &Input { look: [0.0, -1e6], ..Default::default() });
        assert!(c.pitch <= MAX_PITCH && c.camera().validate().is_ok());
    }

    #[test]
    fn walk_falls_to_eye_height_above_the_ground() {
        let mut c = ctl();
        c.set_mode(Mode::Walk, None);
        for _ in 0..600 {
            c.update(0.016, &Input { ground: Some(1.0), ..Default::default() });
        }
        assert!((c.eye.z - (1.0 + c.eye_height)).abs() < 1e-4, "{:?}", c.eye);
        // Walking forward while looking up stays horizontal.
        c.pitch = 1.0;
        let z = c.eye.z;
        for _ in 0..30 {
            c.update(0.016, &Input { forward: 1.0, ground: Some(1.0), ..Default::default() });
        }
        assert!((c.eye.z - z).abs() < 1e-4);
        // Without a ground the floor is the bottom of the bounds.
        for _ in 0..600 {
            c.update(0.016, &Input::default());
        }
        assert!((c.eye.z - (-10.0 + c.eye_height)).abs() < 1e-3, "{:?}", c.eye);
    }

    /// A floor at z = 0 and a wall at y = 3, in the walker's terms (feet are what is moved).
    struct Room;
    impl Collide for Room {
        fn walk(&mut self, feet: Vec3, motion: Vec3) -> Walked {
            let mut f = feet + motion;
            f.y = f.y.min(3.0 - 0.2);
            let grounded = f.z <= 0.0;
            f.z = f.z.max(0.0);
            Walked { feet: f, grounded }
        }
    }

    #[test]
    fn walking_with_collision_moves_the_feet_through_it_and_lands() {
        let mut c = ctl();
        c.set_mode(Mode::Walk, None);
        // From 2 above the floor the eye falls to eye height above it and stays there.
        for _ in 0..200 {
            c.update_with(0.016, &Input::default(), Some(&mut Room));
        }
        assert!((c.eye.z - c.eye_height).abs() < 1e-4 && !c.is_moving(), "{:?}", c.eye);
        // Walking at the wall (+y): held a radius short of it, however long.
        for _ in 0..600 {
            c.update_with(0.016, &Input { forward: 1.0, fast: true, ..Default::default() }, Some(&mut Room));
        }
        assert!((c.eye.y - 2.8).abs() < 1e-4 && (c.eye.z - c.eye_height).abs() < 1e-4, "{:?}", c.eye);
        // Without collision (fly through) the wall is walked through.
        for _ in 0..100 {
            c.update(0.016, &Input { forward: 1.0, ground: Some(0.0), ..Default::default() });
        }
        assert!(c.eye.y > 3.0, "{:?}", c.eye);
    }

    #[test]
    fn orbit_keeps_the_distance_to_the_pivot() {
        let mut c = ctl();
        let p = Vec3::new(1.0, 2.0, 0.0);
        c.set_mode(Mode::Orbit, Some(p));
        let d = (c.eye - p).length();
        c.update(0.016, &Input { look: [50.0, 20.0], ..Default::default() });
        assert!(((c.eye - p).length() - d).abs() < 1e-3);
        assert!((c.camera().target - c.eye).normalize().dot((p - c.eye).normalize()) > 0.999);
        for _ in 0..100 {
            c.update(0.016, &Input { scroll: 1.0, ..Default::default() });
        }
        assert!((c.eye - p).length() < d);
    }

    #[test]
    fn the_orthographic_view_keeps_the_focus_framed_and_orbit_zoom_changes_its_height() {
        let mut c = ctl_in(1.0);
        let eye = c.eye;
        let before = c.camera().view_height_at(5.0);
        c.set_orthographic(true, 5.0);
        let cam = c.camera();
        assert!(cam.is_orthographic() && c.eye == eye, "the eye stays");
        assert!((cam.view_height_at(1e3) - before).abs() < before * 1e-5, "the focus changed size");
        c.set_orthographic(false, 5.0);
        assert_eq!(c.camera().projection, Projection::Perspective { fovy: 1.0 });
        // Orbit: zooming in shrinks the view with the distance.
        c.set_mode(Mode::Orbit, Some(eye + c.forward() * 5.0));
        c.set_orthographic(true, c.distance);
        let (h0, d0) = (c.ortho_height.unwrap(), c.distance);
        for _ in 0..200 {
            c.update(0.016, &Input { scroll: 1.0, ..Default::default() });
        }
        let (h1, d1) = (c.ortho_height.unwrap(), c.distance);
        assert!(h1 < h0 * 0.5, "zoomed in: {h0} to {h1}");
        assert!((h1 / d1 - h0 / d0).abs() < h0 / d0 * 1e-3, "the height follows the distance");
    }

    #[test]
    fn the_wheel_zooms_an_orthographic_view_in_fly_and_walk_mode_and_keeps_the_speed() {
        for mode in [Mode::Fly, Mode::Walk] {
            let mut c = ctl_in(1.0);
            c.set_mode(mode, None);
            c.set_orthographic(true, 5.0);
            let (h0, speed, walk, eye) = (c.ortho_height.unwrap(), c.speed, c.walk_speed, c.eye);
            c.update(0.016, &Input { scroll: 2.0, ..Default::default() });
            let h1 = c.ortho_height.unwrap();
            assert!((h1 / h0 - ZOOM_STEP * ZOOM_STEP).abs() < 1e-5, "{mode:?}: zoomed in {h0} to {h1}");
            assert_eq!((c.speed, c.walk_speed), (speed, walk), "{mode:?}: the speed stays");
            c.update(0.016, &Input { scroll: -2.0, ..Default::default() });
            assert!((c.ortho_height.unwrap() / h0 - 1.0).abs() < 1e-5, "{mode:?}: and back out");
            if mode == Mode::Fly {
                assert_eq!(c.eye, eye, "{mode:?}: zooming does not move the eye");
            }
            // Perspective again: the wheel is the speed once more.
            c.set_orthographic(false, 5.0);
            c.update(0.016, &Input { scroll: 1.0, ..Default::default() });
            let s = if mode == Mode::Walk { (c.walk_speed, walk) } else { (c.speed, speed) };
            assert!((s.0 / s.1 - 1.2).abs() < 1e-5, "{mode:?}: {s:?}");
        }
    }
}
