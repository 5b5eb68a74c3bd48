//! The walker's capsule driven along a generated plant's walk path (`terawalk path`'s interior
//! walk), colliding with the cut a viewer at its eye would select (1280 × 720, τ = 1, frustum
//! culled) and the full-detail clusters within reach, never penetrates the full-detail geometry
//! near it — also while swerving into the walls beside the walkway, which the frustum culled
//! from the cut.

use std::sync::Arc;

use glam::Vec3;
use tw_collide::capsule::{Capsule, Triangle};
use tw_collide::nearby::Nearby;
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::{Camera, ClusterRef, PageCache, SelectOptions, Selector};
use tw_store::Store;

/// The 200 k-triangle plant (seed 3), built once per process (tw-testkit).
fn plant() -> Arc<Store> {
    let options = tw_build::BuildOptions { memory: 256 << 20, ..Default::default() };
    tw_testkit::plant(200_000, 3, options).store()
}

/// Every level-0 cluster of the store (the full-detail model).
fn full_detail(store: &Store) -> Vec<ClusterRef> {
    let mut out = Vec::new();
    for (g, group) in store.groups().iter().enumerate().filter(|(_, g)| g.level == 0) {
        for i in 0..group.cluster_count {
            out.push(ClusterRef {
                page: group.page,
                index_in_page: group.first_cluster + i,
                group: g as u32,
            });
        }
    }
    out
}

#[test]
fn the_capsule_along_a_plant_walk_never_penetrates_the_full_detail_geometry() {
    let store = plant();
    let options = PathOptions { frames: 240, part: PathPart::Walk, seed: 2, ..Default::default() };
    let path = generate_path(&store, &options, &mut |_, _, _| {}).unwrap().path;
    let cameras: Vec<Camera> = path.frames.iter().map(|f| f.to_scene(store.header()).unwrap()).collect();
    let up = [Vec3::X, Vec3::Y, Vec3::Z][store.header().up_axis.min(2) as usize];
    let unit = store.metres_per_unit().unwrap_or(1.0);
    let capsule = Capsule::walker(unit, up);
    let eye_height = (tw_store::units::EYE_HEIGHT_M / unit) as f32;
    let cache = PageCache::new(&store, 1 << 30);
    cache.load_root_pages(&store);
    let selector = Selector::new(&store);
    let select =
        SelectOptions { tau: 1.0, viewport: [1280, 720], frustum_culling: true, ..Default::default() };
    let full = full_detail(&store);
    let page = |p: u32| cache.get(&store, p).ok().map(|p: Arc<_>| p);
    let (mut near, mut truth) = (Nearby::default(), Nearby::default());
    let mut scratch = Vec::new();
    let mut feet = cameras[0].eye - up * eye_height;
    let (mut blocked, mut worst) = (0, f64::INFINITY);
    for (i, pair) in cameras.windows(2).enumerate() {
        let eye = feet + up * eye_height;
        let view = Camera { eye, target: eye + pair[1].direction(), ..pair[1] };
        let cut = selector.select(&store, &cache, &view, &select);
        // The path's horizontal motion, swerving left and right of it (into the walls beside
        // the walkway), and a frame's fall (as the viewer's gravity).
        let step = pair[1].eye - pair[0].eye;
        let along = step - up * step.dot(up);
        let side = along.cross(up) * if (i / 40) % 2 == 0 { 1.5 } else { -1.5 };
        let motion = along + side - up * (eye_height * 0.02);
        let reach = capsule.reach(feet, motion);
        near.gather(&store, &reach, &cut.clusters, page);
        let moved = capsule.move_by(feet, motion, &near.triangles, &mut scratch);
        blocked += moved.blocked as usize;
        feet = moved.feet;
        // Against the model itself, around where the capsule stands.
        truth.gather(&store, &capsule.reach(feet, Vec3::ZERO), &full, page);
        let clear = capsule.clearance(feet, &truth.triangles as &[Triangle]);
        worst = worst.min(clear);
        assert!(
            clear >= -(capsule.radius as f64) * 1e-3,
            "frame {i}: the capsule at {feet} penetrates the model by {} (radius {})",
            -clear,
            capsule.radius
        );
    }
    // The swerves met walls: the test exercised collisions, not only an open walkway.
    assert!(blocked > 0, "no frame was blocked");
    eprintln!(
        "{} frames, {blocked} blocked, worst clearance {worst:.4} (radius {}), ended {} from the path's end",
        cameras.len(),
        capsule.radius,
        (feet + up * eye_height - cameras.last().unwrap().eye).length()
    );
}
