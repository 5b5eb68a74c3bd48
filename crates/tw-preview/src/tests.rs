//! Tests of the preview rasterizer through its public interface.

use super::*;
use tw_core::{Aabb, Rng};

const RED: Rgba8 = Rgba8([255, 0, 0, 255]);
const BLUE: Rgba8 = Rgba8([0, 0, 255, 255]);

/// 100 × 100, eye at z = 10 looking at the origin, 90°: the square |x|, |y| ≤ 10 in z = 0
/// fills the image exactly (x = −10 → column 0, y = 10 → row 0).
fn front_camera(offset: [f64; 3]) -> Camera {
    Camera {
        eye: [offset[0], offset[1], offset[2] + 10.0],
        target: offset,
        up: [0.0, 1.0, 0.0],
        fovy_deg: 90.0,
        ortho_height: None,
    }
}

fn covered(p: &Preview) -> usize {
    p.depth().iter().filter(|&&d| d > 0.0).count()
}

fn pixel(p: &Preview, i: usize, j: usize) -> [u8; 4] {
    let o = (j * p.width() as usize + i) * 4;
    p.image()[o..o + 4].try_into().unwrap()
}

fn tri(p: [[f64; 3]; 3], object: u32) -> Triangle {
    Triangle::new(p, object)
}

#[test]
fn single_triangle_covers_expected_pixels() {
    for offset in [[0.0; 3], [1e7, -3e6, 2e5]] {
        let mut p = Preview::new(100, 100, front_camera(offset)).unwrap();
        let o = |x: f64, y: f64| [offset[0] + x, offset[1] + y, offset[2]];
        p.object(0, &ObjectInfo { name: String::new(), color: Some(RED) }).unwrap();
        // Screen (50,50) (100,50) (50,0): centres with i ≥ 50, j ≤ 49 and i − j ≤ 49; the
        // hypotenuse x − y = 50 is a right edge, so centres on it (i − j = 50) are not drawn.
        p.triangle(&tri([o(0.0, 0.0), o(10.0, 0.0), o(0.0, 10.0)], 0)).unwrap();
        assert_eq!(covered(&p), 1225, "offset {offset:?}");
        for (i, j) in [(50, 49), (60, 30), (98, 49), (50, 1)] {
            assert!(p.depth()[j * 100 + i] > 0.0, "{i},{j} should be drawn");
            assert!((p.depth()[j * 100 + i] - 0.1).abs() < 1e-6);
        }
        for (i, j) in [(49, 30), (60, 50), (99, 0), (80, 29), (50, 0), (60, 10)] {
            assert_eq!(p.depth()[j * 100 + i], 0.0, "{i},{j} should be sky");
        }
        let c = pixel(&p, 60, 30);
        assert!(c[0] > 100 && c[1] == 0 && c[2] == 0, "{c:?}");
        assert_eq!(
            p.stats(),
            PreviewStats { triangles: 1, culled: 0, clipped: 0, fragments: 1225, pixels: 1225 }
        );
    }
}

#[test]
fn near_plane_crossing_triangle_draws() {
    // Eye at the origin looking down −z; a floor triangle at y = −1 that reaches behind the eye.
    let cam = Camera {
        eye: [0.0; 3],
        target: [0.0, 0.0, -1.0],
        up: [0.0, 1.0, 0.0],
        fovy_deg: 90.0,
        ortho_height: None,
    };
    let mut p = Preview::new(64, 64, cam).unwrap();
    p.object(0, &ObjectInfo::default()).unwrap();
    p.triangle(&tri([[-10.0, -1.0, -10.0], [10.0, -1.0, -10.0], [0.0, -1.0, 5.0]], 0)).unwrap();
    let s = p.stats();
    assert_eq!((s.clipped, s.culled), (1, 0));
    assert!(s.pixels > 200, "{s:?}");
    // A floor below the eye shows only below the horizon.
    for j in 0..32 {
        assert!((0..64).all(|i| p.depth()[j * 64 + i] == 0.0), "row {j}");
    }
    assert!(p.depth().iter().all(|d| d.is_finite() && *d >= 0.0));
    // The nearest row of the floor is the bottom row.
    assert!((0..64).any(|i| p.depth()[63 * 64 + i] > 0.0));
    // Through the eye itself, and entirely behind: no panic; the latter draws nothing.
    p.triangle(&tri([[0.0, 0.0, 0.0], [1.0, 0.0, -1.0], [0.0, 1.0, -1.0]], 0)).unwrap();
    let before = p.stats().pixels;
    p.triangle(&tri([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 2.0]], 0)).unwrap();
    assert_eq!(p.stats().pixels, before);
    assert_eq!(p.stats().culled, 1);
}

#[test]
fn huge_triangle_through_the_view_is_clipped_to_the_guard_band() {
    let mut p = Preview::new(100, 100, front_camera([0.0; 3])).unwrap();
    p.object(0, &ObjectInfo::default()).unwrap();
    p.triangle(&tri([[-1e9, -1e9, 0.0], [1e9, -1e9, 0.0], [0.0, 1e9, 0.0]], 0)).unwrap();
    assert_eq!(covered(&p), 100 * 100);
    assert_eq!(p.stats().clipped, 1);
}

#[test]
fn nearer_triangle_hides_farther_in_either_order() {
    let render = |order: [usize; 2]| {
        let mut p = Preview::new(100, 100, front_camera([0.0; 3])).unwrap();
        p.object(0, &ObjectInfo { name: "far".into(), color: Some(RED) }).unwrap();
        p.object(1, &ObjectInfo { name: "near".into(), color: Some(BLUE) }).unwrap();
        let tris = [
            tri([[-8.0, -8.0, 0.0], [8.0, -8.0, 0.0], [0.0, 8.0, 0.0]], 0),
            tri([[-6.0, -6.0, 1.0], [6.0, -6.0, 1.0], [0.0, 6.0, 1.0]], 1),
        ];
        for k in order {
            p.triangle(&tris[k]).unwrap();
        }
        p
    };
    let a = render([0, 1]);
    let b = render([1, 0]);
    assert_eq!(a.image(), b.image());
    assert_eq!(a.depth(), b.depth());
    let c = pixel(&a, 50, 50);
    assert!(c[2] > 100 && c[0] == 0, "centre should be the near blue triangle: {c:?}");
    let c = pixel(&a, 50, 85); // below the near one, inside the far one
    assert!(c[0] > 100 && c[2] == 0, "{c:?}");
}

fn random_scene(sink: &mut dyn TriangleSink, n: usize) {
    let mut rng = Rng::new(11);
    for o in 0..8 {
        sink.object(o, &ObjectInfo::default()).unwrap();
    }
    for _ in 0..n {
        let c = [rng.range_f64(-1.0, 1.0), rng.range_f64(-1.0, 1.0), rng.range_f64(-1.0, 1.0)];
        let mut v = || [0, 1, 2].map(|i| c[i] + rng.range_f64(-0.2, 0.2));
        let t = tri([v(), v(), v()], rng.range_u32(0, 8));
        sink.triangle(&t).unwrap();
    }
}

#[test]
fn image_is_deterministic() {
    let cam = Camera::look_at_bounds(&Aabb::from_points(&[[-1.0; 3], [1.0; 3]]), [1.0, -2.0, 1.5]);
    let render = |mode| {
        let mut p = Preview::new(120, 90, cam).unwrap().with_color_mode(mode);
        random_scene(&mut p, 3000);
        p
    };
    let a = render(ColorMode::Object);
    assert_eq!(a.image(), render(ColorMode::Object).image());
    let h = render(ColorMode::HashObject);
    assert_eq!(h.image(), render(ColorMode::HashObject).image());
    assert_eq!(a.depth(), h.depth());
    assert_ne!(a.image(), h.image());
    // Hash colours tell objects apart.
    let colors: std::collections::HashSet<[u8; 3]> =
        (0..8).map(|o| hash_color(o).map(|v| (v * 255.0) as u8)).collect();
    assert_eq!(colors.len(), 8);
}

#[test]
fn mesh_chunks_draw_like_their_triangles() {
    let positions = [[-5.0, -5.0, 0.0], [5.0, -5.0, 0.0], [5.0, 5.0, 1.0], [-5.0, 5.0, 0.0]];
    let indices = [0u32, 1, 2, 0, 2, 3];
    let mut a = Preview::new(100, 100, front_camera([0.0; 3])).unwrap();
    a.object(0, &ObjectInfo { name: String::new(), color: Some(RED) }).unwrap();
    a.mesh(&MeshChunk { object: 0, positions: &positions, indices: &indices }).unwrap();
    let mut b = Preview::new(100, 100, front_camera([0.0; 3])).unwrap();
    b.object(0, &ObjectInfo { name: String::new(), color: Some(RED) }).unwrap();
    for t in indices.chunks_exact(3) {
        b.triangle(&tri([positions[t[0] as usize], positions[t[1] as usize], positions[t[2] as usize]], 0))
            .unwrap();
    }
    assert_eq!(a.image(), b.image());
    assert!(covered(&a) > 2000);
    let e = a.mesh(&MeshChunk { object: 0, positions: &positions, indices: &[0, 1, 4] }).unwrap_err();
    assert!(e.to_string().contains("out of range"), "{e}");
}

#[test]
fn non_finite_triangles_are_skipped() {
    let mut p = Preview::new(10, 10, front_camera([0.0; 3])).unwrap();
    p.triangle(&tri([[f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], 0)).unwrap();
    p.triangle(&tri([[f64::INFINITY, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], 0)).unwrap();
    assert_eq!(covered(&p), 0);
    assert_eq!(p.stats().culled, 2);
}

#[test]
fn vertex_colours_and_unannounced_objects() {
    let mut p = Preview::new(100, 100, front_camera([0.0; 3])).unwrap();
    // Unannounced object: grey. Vertex colours: their average.
    p.triangle(&tri([[-9.0, -9.0, 0.0], [-1.0, -9.0, 0.0], [-9.0, -1.0, 0.0]], 5)).unwrap();
    let mut t = tri([[1.0, 1.0, 0.0], [9.0, 1.0, 0.0], [1.0, 9.0, 0.0]], 5);
    t.colors = Some([BLUE; 3]);
    p.triangle(&t).unwrap();
    let grey = pixel(&p, 15, 85);
    assert!(grey[0] == grey[1] && grey[1] == grey[2] && grey[0] > 50, "{grey:?}");
    let blue = pixel(&p, 60, 40);
    assert!(blue[2] > 100 && blue[0] == 0, "{blue:?}");
}

#[test]
fn sky_is_a_gradient() {
    let p = Preview::new(40, 60, front_camera([0.0; 3])).unwrap();
    // Camera looks along −z with y up: horizontal view, horizon at mid-height.
    let top = pixel(&p, 20, 0);
    let above = pixel(&p, 20, 29);
    let below = pixel(&p, 20, 30);
    let bottom = pixel(&p, 20, 59);
    assert!(top[2] > top[0] && top != above, "{top:?} {above:?}");
    assert!(bottom[0] < below[0] && bottom[2] < below[2], "darker towards the nadir: {below:?} {bottom:?}");
    assert!(p.image().chunks_exact(4).all(|c| c[3] == 255));
    assert_eq!(covered(&p), 0);
}

#[test]
fn look_at_bounds_frames_the_box() {
    let b = Aabb::from_points(&[[10.0, 20.0, 30.0], [14.0, 21.0, 38.0]]);
    for dir in [[1.0, 1.0, 1.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-3.0, 0.5, -0.2]] {
        let p = Preview::new(200, 200, Camera::look_at_bounds(&b, dir)).unwrap();
        let c = p.project(b.center()).unwrap();
        assert!((c[0] - 100.0).abs() < 1e-6 && (c[1] - 100.0).abs() < 1e-6, "{c:?}");
        for k in 0..8 {
            let corner = [0, 1, 2].map(|i| if k >> i & 1 == 1 { b.max[i] } else { b.min[i] });
            let s = p.project(corner).unwrap();
            assert!(s.iter().all(|&v| (0.0..=200.0).contains(&v)), "{dir:?} {corner:?} -> {s:?}");
        }
    }
}

#[test]
fn frame_bounds_fits_the_corners_tightly() {
    let b = Aabb::from_points(&[[0.0, 0.0, 0.0], [300.0, 200.0, 40.0]]);
    let (w, h) = (320u32, 180u32);
    let cam = Camera::frame_bounds(&b, [-0.55, -0.75, 0.55], [0.0, 0.0, 1.0], w as f64 / h as f64);
    let p = Preview::new(w, h, cam).unwrap();
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for k in 0..8 {
        let corner = [0, 1, 2].map(|i| if k >> i & 1 == 1 { b.max[i] } else { b.min[i] });
        let s = p.project(corner).unwrap();
        assert!(s[0] >= 0.0 && s[0] <= w as f64 && s[1] >= 0.0 && s[1] <= h as f64, "{corner:?} -> {s:?}");
        for i in 0..2 {
            lo[i] = lo[i].min(s[i]);
            hi[i] = hi[i].max(s[i]);
        }
    }
    // Tight: one corner touches the margin, so with the target at the box centre (perspective
    // makes the projection lopsided) the box spans well over half the image along one axis.
    let span = ((hi[0] - lo[0]) / w as f64).max((hi[1] - lo[1]) / h as f64);
    assert!(span > 0.65, "span {span}");
    assert!(cam.target_distance() < Camera::look_at_bounds(&b, [-0.55, -0.75, 0.55]).target_distance());
}

#[test]
fn invalid_sizes_are_errors() {
    for (w, h) in [(0, 10), (10, 0), (MAX_SIDE + 1, 1)] {
        let e = Preview::new(w, h, Camera::default()).err().unwrap();
        assert!(matches!(e, PreviewError::Size { .. }), "{e}");
    }
}

#[test]
fn png_is_written_atomically_and_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.png");
    std::fs::write(&path, b"old").unwrap();
    let mut p = Preview::new(32, 24, front_camera([0.0; 3])).unwrap();
    p.triangle(&tri([[-9.0, -9.0, 0.0], [9.0, -9.0, 0.0], [0.0, 9.0, 0.0]], 0)).unwrap();
    p.write_png(&path).unwrap();
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names, ["p.png"]);
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height, info.color_type), (32, 24, png::ColorType::Rgba));
    assert_eq!(&buf[..info.buffer_size()], p.image());
    // A missing directory: an error naming the path, nothing written.
    let bad = dir.path().join("missing/p.png");
    let e = p.write_png(&bad).unwrap_err();
    assert!(e.to_string().contains("missing/p.png"), "{e}");
}

/// Speed: `cargo test --release -p tw-preview bench -- --ignored --nocapture`.
#[test]
#[ignore = "benchmark"]
fn bench_raster_speed() {
    let cam = Camera::look_at_bounds(&Aabb::from_points(&[[-1.0; 3], [1.0; 3]]), [1.0, -2.0, 1.5]);
    for (label, size, n) in
        [("tiny", 0.004, 4_000_000usize), ("small", 0.015, 2_000_000), ("medium", 0.05, 1_000_000)]
    {
        let mut rng = Rng::new(5);
        let mut tris = Vec::with_capacity(n);
        for _ in 0..n {
            let c = [rng.range_f64(-1.0, 1.0), rng.range_f64(-1.0, 1.0), rng.range_f64(-1.0, 1.0)];
            let mut v = || [0, 1, 2].map(|i| c[i] + rng.range_f64(-size, size));
            tris.push(tri([v(), v(), v()], 0));
        }
        let mut p = Preview::new(1024, 768, cam).unwrap();
        p.object(0, &ObjectInfo::default()).unwrap();
        let start = std::time::Instant::now();
        for t in &tris {
            p.triangle(t).unwrap();
        }
        let secs = start.elapsed().as_secs_f64();
        let s = p.stats();
        println!(
            "{label}: {n} triangles in {secs:.3} s = {:.2} M triangles/s, {:.1} px/triangle, {:.0}% culled",
            n as f64 / secs / 1e6,
            s.fragments as f64 / n as f64,
            s.culled as f64 / n as f64 * 100.0
        );
    }
    // An indexed grid, 1000 × 1000 quads (2 M triangles) filling the view.
    let m = 1000u32;
    let positions: Vec<[f64; 3]> = (0..=m)
        .flat_map(|y| {
            (0..=m).map(move |x| [x as f64 / m as f64 * 2.0 - 1.0, y as f64 / m as f64 * 2.0 - 1.0, 0.0])
        })
        .collect();
    let mut indices = Vec::new();
    for y in 0..m {
        for x in 0..m {
            let i = y * (m + 1) + x;
            indices.extend_from_slice(&[i, i + 1, i + m + 2, i, i + m + 2, i + m + 1]);
        }
    }
    let mut p = Preview::new(1024, 768, cam).unwrap();
    p.object(0, &ObjectInfo::default()).unwrap();
    let start = std::time::Instant::now();
    p.mesh(&MeshChunk { object: 0, positions: &positions, indices: &indices }).unwrap();
    let secs = start.elapsed().as_secs_f64();
    println!(
        "indexed grid: {} triangles in {secs:.3} s = {:.2} M triangles/s",
        indices.len() / 3,
        indices.len() as f64 / 3.0 / secs / 1e6
    );
}

/// Regression: 100,000 copies of one large triangle took 42.7 s, a full scan conversion per
/// copy. An exact repeat changes no pixel, so it is skipped: the image, the depths and the
/// statistics are those of drawing every copy, and 2,000 copies of a triangle covering most of a
/// 1000 × 1000 image (a billion fragments) take a moment, also unoptimized.
#[test]
fn exact_repeats_of_large_triangles_are_not_drawn_again() {
    let big = |object| tri([[-9.0, -9.0, 0.0], [9.5, -8.0, 0.5], [0.0, 9.7, -0.5]], object);
    // Nearer, over part of the big one.
    let near = tri([[-1.0, -1.0, 2.0], [1.0, -1.0, 2.0], [0.0, 1.0, 2.0]], 1);
    let render = |copies: usize| {
        let mut p = Preview::new(1000, 1000, front_camera([0.0; 3])).unwrap();
        p.object(0, &ObjectInfo { name: "a".into(), color: Some(RED) }).unwrap();
        p.object(1, &ObjectInfo { name: "b".into(), color: Some(BLUE) }).unwrap();
        p.triangle(&big(0)).unwrap();
        p.triangle(&near).unwrap();
        for k in 0..copies {
            // Another colour, and the small triangle again in between: still nothing to draw.
            p.triangle(&big(1)).unwrap();
            if k % 100 == 0 {
                p.triangle(&near).unwrap();
            }
        }
        p
    };
    let once = render(0);
    let start = std::time::Instant::now();
    let many = render(2000);
    let took = start.elapsed();
    assert!(once.image() == many.image() && once.depth() == many.depth());
    let (a, b) = (once.stats(), many.stats());
    let mut alone = Preview::new(1000, 1000, front_camera([0.0; 3])).unwrap();
    alone.triangle(&near).unwrap();
    let small = alone.stats().fragments;
    let big_fragments = a.fragments - small;
    assert_eq!(b.triangles, a.triangles + 2000 + 20);
    assert_eq!(b.pixels, a.pixels);
    assert_eq!(b.fragments, a.fragments + 2000 * big_fragments + 20 * small);
    assert!(big_fragments > 400_000, "{a:?}");
    assert!(took.as_secs_f64() < 5.0, "2,000 repeats took {took:?}");
}

/// [`front_camera`] made orthographic, `height` units high, its eye `back` units from z = 0.
fn ortho_camera(height: f64, back: f64) -> Camera {
    Camera { eye: [0.0, 0.0, back], ortho_height: Some(height), ..front_camera([0.0; 3]) }
}

#[test]
fn orthographic_views_project_in_parallel() {
    // A square |x|, |y| ≤ 10 fills a 20-unit-high orthographic view exactly, however far back
    // the eye is; 1/z is still the depth, and the shading does not change with the distance.
    let square = |z: f64, object: u32| {
        [
            tri([[-10.0, -10.0, z], [10.0, -10.0, z], [10.0, 10.0, z]], object),
            tri([[-10.0, -10.0, z], [10.0, 10.0, z], [-10.0, 10.0, z]], object),
        ]
    };
    let mut images = Vec::new();
    for back in [10.0, 1000.0] {
        let mut p = Preview::new(100, 100, ortho_camera(20.0, back)).unwrap();
        p.object(0, &ObjectInfo { name: String::new(), color: Some(RED) }).unwrap();
        for t in square(0.0, 0) {
            p.triangle(&t).unwrap();
        }
        assert_eq!(covered(&p), 100 * 100, "eye {back} back");
        assert!(p.depth().iter().all(|&d| (d as f64 - 1.0 / back).abs() < 1e-6 / back), "eye {back} back");
        assert_eq!(p.project([10.0, 10.0, 0.0]), Some([100.0, 0.0]));
        assert_eq!(p.project([-5.0, 0.0, -123.0]), Some([25.0, 50.0]), "depth does not move a point");
        images.push(p.image().to_vec());
    }
    assert!(images[0] == images[1], "the image changed with the eye's distance");

    // Equal squares at different depths cover the same pixels (in perspective the far one
    // would cover a quarter of the near one's); the nearer hides the farther in either order.
    for order in [[0usize, 1], [1, 0]] {
        let mut p = Preview::new(100, 100, ortho_camera(40.0, 100.0)).unwrap();
        p.object(1, &ObjectInfo { name: "near".into(), color: Some(BLUE) }).unwrap();
        p.object(2, &ObjectInfo { name: "far".into(), color: Some(RED) }).unwrap();
        let quads = [square(50.0, 1), square(-50.0, 2)];
        for k in order {
            for t in &quads[k] {
                p.triangle(t).unwrap();
            }
        }
        assert_eq!(covered(&p), 50 * 50);
        let c = pixel(&p, 50, 50);
        assert!(c[2] > 100 && c[0] == 0, "the near blue square shows: {c:?}");
        assert!((p.depth()[50 * 100 + 50] - 1.0 / 50.0).abs() < 1e-7);
        assert_eq!(pixel(&p, 24, 50), pixel(&p, 0, 0), "sky outside the squares");
    }
}

#[test]
fn orthographic_views_clip_at_the_near_plane_and_the_box_sides() {
    // A floor from behind the eye to far ahead, much wider than the view: clipped by the near
    // plane and the guard band, it covers the whole image (no gaps along the clipped edges).
    let cam = Camera {
        eye: [0.0; 3],
        target: [0.0, 0.0, -1.0],
        up: [0.0, 1.0, 0.0],
        fovy_deg: 60.0,
        ortho_height: Some(2.0),
    };
    let mut p = Preview::new(80, 60, cam).unwrap();
    p.object(0, &ObjectInfo::default()).unwrap();
    let (a, b) = (1e4, 1e4);
    // A plane tilted so that it is seen (x, y) over the whole view, crossing the eye plane.
    let z = |y: f64| -y * 0.5;
    p.triangle(&tri([[-a, -b, z(-b)], [a, -b, z(-b)], [a, b, z(b)]], 0)).unwrap();
    p.triangle(&tri([[-a, -b, z(-b)], [a, b, z(b)], [-a, b, z(b)]], 0)).unwrap();
    // In front of the eye: y > 0 (z < 0); the rows of y ≤ 0 are behind the near plane.
    let rows_drawn = (0..60).filter(|&j| p.depth()[j * 80 + 40] > 0.0).count();
    assert_eq!(rows_drawn, 30, "the upper half (in front of the eye) only");
    assert_eq!(covered(&p), 80 * 30);
    assert_eq!(p.stats().clipped, 2);
    // Outside the view box entirely: culled.
    p.triangle(&tri([[5.0, 5.0, -1.0], [6.0, 5.0, -1.0], [5.0, 6.0, -1.0]], 0)).unwrap();
    assert_eq!(p.stats().culled, 1);
}
