//! Walk mode's collision ([`crate::controller::Collide`]): the walker's capsule
//! (`tw_collide::capsule`, sized by the store's units) moved through the triangles within its
//! reach, gathered each frame from the resident pages (`tw_collide::nearby`: the full-detail
//! clusters around the walker and the frame's cut there). "Fly through" switches it off.
//! The time a frame spends here is kept for the HUD.

use std::time::Instant;

use glam::Vec3;
use tw_collide::capsule::{Candidate, Capsule};
use tw_collide::nearby::Nearby;

use crate::controller::{Collide, Walked};
use crate::scene::Scene;

/// The walker's body and its buffers, kept between frames.
pub struct WalkCollision {
    pub capsule: Capsule,
    /// Walls are passed through (the ground still holds the walker, found by a ray).
    pub fly_through: bool,
    nearby: Nearby,
    scratch: Vec<Candidate>,
    /// The last frame's collision: milliseconds, triangles within reach, and clusters within
    /// reach whose page was not resident.
    pub last_ms: f32,
    pub last_triangles: usize,
    pub last_missing: u64,
}

impl WalkCollision {
    /// The walker of `scene` (its units and up axis).
    pub fn new(scene: &Scene) -> WalkCollision {
        let frame = scene.scene_frame();
        WalkCollision {
            capsule: Capsule::walker(frame.metres_per_unit as f64, frame.up),
            fly_through: false,
            nearby: Nearby::default(),
            scratch: Vec::new(),
            last_ms: 0.0,
            last_triangles: 0,
            last_missing: 0,
        }
    }

    /// The collision to give the controller this frame, `None` when flying through or before
    /// the scene has a cut to collide with.
    pub fn collider<'a>(&'a mut self, scene: &'a Scene) -> Option<SceneCollider<'a>> {
        (!self.fly_through && scene.selection().is_some()).then_some(SceneCollider { walk: self, scene })
    }

    /// What the HUD says of it.
    pub fn status(&self) -> String {
        if self.fly_through {
            "fly through (N: collide)".into()
        } else {
            format!(
                "collision {:.2} ms, {} triangles near{}",
                self.last_ms,
                self.last_triangles,
                if self.last_missing > 0 {
                    format!(", {} clusters not loaded", self.last_missing)
                } else {
                    String::new()
                }
            )
        }
    }
}

/// [`WalkCollision`] against one frame's scene.
pub struct SceneCollider<'a> {
    walk: &'a mut WalkCollision,
    scene: &'a Scene,
}

impl Collide for SceneCollider<'_> {
    fn walk(&mut self, feet: Vec3, motion: Vec3) -> Walked {
        let start = Instant::now();
        let w = &mut *self.walk;
        let reach = w.capsule.reach(feet, motion);
        self.scene.gather_nearby(&reach, &mut w.nearby);
        let moved = w.capsule.move_by(feet, motion, &w.nearby.triangles, &mut w.scratch);
        w.last_ms = start.elapsed().as_secs_f32() * 1e3;
        w.last_triangles = w.nearby.triangles.len();
        w.last_missing = w.nearby.missing;
        tracing::debug!(
            ms = w.last_ms,
            triangles = w.last_triangles,
            missing = w.last_missing,
            tests = moved.tests,
            "walk collision"
        );
        Walked { feet: moved.feet, grounded: moved.grounded }
    }
}
