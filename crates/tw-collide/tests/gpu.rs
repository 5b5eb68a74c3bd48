//! CULLIDE, S-CULLIDE and FAR on the GPU against the exact reference. Run with a Vulkan device
//! (lavapipe: `VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json`); without an adapter
//! a test is skipped with a note, unless `TERAWALK_REQUIRE_GPU=1`, where it fails.

use tw_collide::cullide::{CollideError, Options};
use tw_collide::scenes::random_soup;
use tw_collide::{all_pairs, Collider, Method, Object, Scene, SceneKind, SceneOptions};

fn collider(method: Method, resolution: u32) -> Option<Collider> {
    match Collider::new(Options { method, resolution, ..Default::default() }) {
        Ok(c) => Some(c),
        Err(CollideError::Gpu(e @ tw_gpu::GpuError::NoAdapter { .. }))
            if std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1") =>
        {
            eprintln!("SKIPPED: {e} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)");
            None
        }
        Err(e) => panic!("{e}"),
    }
}

fn object(triangles: &[[[f32; 3]; 3]]) -> Object {
    Object {
        positions: triangles.iter().flatten().copied().collect(),
        triangles: (0..triangles.len() as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect(),
        self_collide: false,
    }
}

#[test]
fn fully_visible_objects_leave_the_pcs() {
    let Some(mut c) = collider(Method::Cullide, 64) else { return };
    // Two parallel squares, one above the other: each is fully visible against the other in the
    // view along z (Lemma 1), so nothing reaches the exact tests.
    let square = |z: f32| {
        object(&[
            [[0.0, 0.0, z], [1.0, 0.0, z], [1.0, 1.0, z]],
            [[0.0, 0.0, z], [1.0, 1.0, z], [0.0, 1.0, z]],
        ])
    };
    let s = c.step(&[square(0.0), square(0.5)]).unwrap();
    assert!(s.pairs.is_empty());
    assert_eq!(s.pcs_triangles, 0, "{s:?}");
    assert_eq!(s.candidates, 0);
    assert!(s.queries > 0);
}

#[test]
fn fattening_keeps_a_touching_pair_at_low_resolution() {
    // A vertical triangle whose lower edge lies on a diagonal of the base: they touch along a
    // line no thicker than nothing, which an 8 × 8 viewport cannot sample.
    let base = object(&[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]]);
    let fin = object(&[[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, 1.0]]]);
    let scene = [base, fin];
    let reference = all_pairs(&scene);
    assert_eq!(reference.len(), 1);
    let Some(mut far) = collider(Method::Far, 8) else { return };
    assert_eq!(far.step(&scene).unwrap().pairs, reference);
}

#[test]
fn far_equals_the_reference_on_random_scenes() {
    for resolution in [8, 32, 128] {
        let Some(mut far) = collider(Method::Far, resolution) else { return };
        for seed in 0..3 {
            let scene = random_soup(12, 60, 0.12, seed);
            let want = all_pairs(&scene);
            assert!(!want.is_empty());
            let got = far.step(&scene).unwrap();
            assert_eq!(got.pairs, want, "resolution {resolution}, seed {seed}");
        }
    }
}

#[test]
fn cullide_pairs_are_a_subset_of_the_reference() {
    // At 64² CULLIDE misses every contact of these small triangles (they cross between pixel
    // centres); at 256² it finds some.
    let Some(mut c) = collider(Method::Cullide, 256) else { return };
    let mut found = 0;
    for seed in 0..3 {
        let scene = random_soup(12, 60, 0.12, seed);
        let want = all_pairs(&scene);
        let got = c.step(&scene).unwrap();
        assert!(got.pairs.iter().all(|p| want.binary_search(p).is_ok()), "seed {seed}");
        assert!(got.pcs_triangles < tw_collide::triangle_count(&scene));
        found += got.pairs.len();
    }
    assert!(found > 0);
}

#[test]
fn s_cullide_and_far_on_the_cloth() {
    let scene = Scene::new(SceneKind::Cloth, &SceneOptions { scale: 0.1, ..Default::default() }).unwrap();
    let objects = scene.step(30);
    let want = all_pairs(&objects);
    assert!(want.iter().any(|p| p.0.object == 0 && p.1.object == 0), "the cloth should fold through itself");
    let Some(mut c) = collider(Method::Cullide, 256) else { return };
    let got = c.step(&objects).unwrap();
    assert!(got.pairs.iter().all(|p| want.binary_search(p).is_ok()));
    assert!(got.pcs_self_triangles < objects[0].triangles.len(), "{got:?}");
    let Some(mut far) = collider(Method::Far, 64) else { return };
    assert_eq!(far.step(&objects).unwrap().pairs, want);
}

#[test]
fn far_equals_the_reference_on_the_generated_scenes() {
    let Some(mut far) = collider(Method::Far, 128) else { return };
    let opts = SceneOptions { scale: 0.05, ..Default::default() };
    for kind in [SceneKind::Cylinders, SceneKind::Tori, SceneKind::Cloth] {
        let scene = Scene::new(kind, &opts).unwrap();
        for t in [6, 25] {
            let objects = scene.step(t);
            assert_eq!(far.step(&objects).unwrap().pairs, all_pairs(&objects), "{kind:?} step {t}");
        }
    }
}

#[test]
fn far_within_distance_equals_the_reference() {
    let Some(_) = collider(Method::Far, 8) else { return };
    for (resolution, distance) in [(16, 0.02), (128, 0.05)] {
        let options = Options { method: Method::Far, resolution, within: distance, ..Default::default() };
        let mut far = Collider::new(options).unwrap();
        let scene = random_soup(10, 40, 0.1, 5);
        let want = tw_collide::reference::all_pairs_within(&scene, distance);
        assert!(want.len() > all_pairs(&scene).len());
        assert_eq!(far.step(&scene).unwrap().pairs, want, "resolution {resolution}, distance {distance}");
    }
    let cullide = Options { method: Method::Cullide, within: 0.1, ..Default::default() };
    assert!(matches!(Collider::new(cullide), Err(CollideError::Within(_))));
}
