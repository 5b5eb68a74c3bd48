//! Correctness of the ray tracing core against brute force: boxes, triangles, watertightness,
//! BVH structure, and every traversal path (single, packet; AVX2 and portable).

use glam::Vec3;
use tw_core::rng::Rng;
use tw_rt::{
    intersect_triangle, trace_image_with, Aabb, BuildOptions, Bvh, Camera, Hit, MeshError, Ray, Simd,
    SpatialSplits, TraceMode, TriangleBvh,
};

/// Test randomness from the shared generator, as `f32`s and vectors.
trait TestRng {
    /// Uniform in [lo, hi).
    fn f(&mut self, lo: f32, hi: f32) -> f32;
    /// Each coordinate uniform in [lo, hi).
    fn v(&mut self, lo: f32, hi: f32) -> Vec3;
    /// A uniformly distributed unit direction (by rejection from the cube).
    fn dir(&mut self) -> Vec3;
}

impl TestRng for Rng {
    fn f(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32 * (hi - lo)
    }
    fn v(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.f(lo, hi), self.f(lo, hi), self.f(lo, hi))
    }
    fn dir(&mut self) -> Vec3 {
        loop {
            let d = self.v(-1.0, 1.0);
            if d.length_squared() > 0.01 && d.length_squared() <= 1.0 {
                return d.normalize();
            }
        }
    }
}

/// Random soup of small triangles in the cube [-1, 1]^3.
fn soup(rng: &mut Rng, n: usize) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    for i in 0..n as u32 {
        let c = rng.v(-1.0, 1.0);
        for _ in 0..3 {
            pos.push((c + rng.v(-0.15, 0.15)).to_array());
        }
        tris.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    (pos, tris)
}

fn corners(pos: &[[f32; 3]], t: &[u32; 3]) -> [Vec3; 3] {
    t.map(|i| Vec3::from(pos[i as usize]))
}

/// The nearest hit over all triangles, with the same triangle test as the BVH.
fn brute(pos: &[[f32; 3]], tris: &[[u32; 3]], ray: &Ray) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for (i, t) in tris.iter().enumerate() {
        let mut r = *ray;
        if let Some(b) = best {
            r.t_max = b.t;
        }
        if let Some((t, u, v)) = intersect_triangle(&r, corners(pos, t)) {
            best = Some(Hit { t, prim: i as u32, u, v });
        }
    }
    best
}

/// Same nearest `t`; the same primitive unless another one is hit at exactly that `t`.
fn assert_same(
    pos: &[[f32; 3]],
    tris: &[[u32; 3]],
    ray: &Ray,
    got: Option<Hit>,
    want: Option<Hit>,
    what: &str,
) {
    match (got, want) {
        (None, None) => {}
        (Some(g), Some(w)) => {
            assert_eq!(g.t, w.t, "{what}: t differs for {ray:?}");
            if g.prim != w.prim {
                let tie = intersect_triangle(ray, corners(pos, &tris[g.prim as usize])).map(|h| h.0);
                assert_eq!(tie, Some(w.t), "{what}: prim {} instead of {} for {ray:?}", g.prim, w.prim);
            } else {
                assert_eq!((g.u, g.v), (w.u, w.v), "{what}: barycentrics differ");
            }
        }
        _ => panic!("{what}: got {got:?}, brute force {want:?} for {ray:?}"),
    }
}

const PATHS: [Simd; 2] = [Simd::Avx2, Simd::Portable];

#[test]
fn ray_box_agrees_with_f64_slabs() {
    let mut rng = Rng::new(7);
    for _ in 0..20_000 {
        let b = Aabb::from_points(&[rng.v(-1.0, 1.0), rng.v(-1.0, 1.0)]);
        let mut dir = rng.dir();
        // Zero components (both signs) are the robustness cases.
        for a in 0..3 {
            match rng.next_u64() % 8 {
                0 => dir[a] = 0.0,
                1 => dir[a] = -0.0,
                _ => {}
            }
        }
        if dir == Vec3::ZERO {
            continue;
        }
        let ray = Ray::new(rng.v(-2.0, 2.0), dir);
        let (mut lo, mut hi) = (0.0f64, f64::INFINITY);
        for a in 0..3 {
            let (o, d) = (ray.origin[a] as f64, ray.dir[a] as f64);
            let (bmin, bmax) = (b.min[a] as f64, b.max[a] as f64);
            if d == 0.0 {
                if o < bmin || o > bmax {
                    hi = -1.0;
                }
            } else {
                let (t0, t1) = ((bmin - o) / d, (bmax - o) / d);
                lo = lo.max(t0.min(t1));
                hi = hi.min(t0.max(t1));
            }
        }
        let got = b.intersect(&ray);
        if hi - lo > 1e-5 {
            assert!(got.is_some(), "missed {b:?} {ray:?} ({lo}, {hi})");
        } else if lo - hi > 1e-5 {
            assert!(got.is_none(), "false hit {b:?} {ray:?}");
        }
    }
}

#[test]
fn ray_box_on_faces_with_zero_directions() {
    let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
    for z in [0.0f32, -0.0] {
        // Origins on the box's faces, moving parallel to them: touching counts as a hit.
        assert!(b.intersect(&Ray::new(Vec3::new(0.0, 0.5, -1.0), Vec3::new(z, z, 1.0))).is_some());
        assert!(b.intersect(&Ray::new(Vec3::new(1.0, 0.5, -1.0), Vec3::new(z, z, 1.0))).is_some());
        assert!(b.intersect(&Ray::new(Vec3::new(1.0, 1.0, 2.0), Vec3::new(z, z, -1.0))).is_some());
        assert!(b.intersect(&Ray::new(Vec3::new(1.0001, 0.5, -1.0), Vec3::new(z, z, 1.0))).is_none());
        assert!(b.intersect(&Ray::new(Vec3::new(0.5, -0.0001, -1.0), Vec3::new(z, z, 1.0))).is_none());
    }
}

#[test]
fn ray_triangle_agrees_with_f64_reference() {
    let mut rng = Rng::new(11);
    let mut hits = 0;
    for _ in 0..20_000 {
        let p = [rng.v(-1.0, 1.0), rng.v(-1.0, 1.0), rng.v(-1.0, 1.0)];
        let o = rng.v(-3.0, 3.0);
        let ray = Ray::new(o, (p[0] + p[1] + p[2]) / 3.0 + rng.v(-0.5, 0.5) - o);
        // f64 Moller-Trumbore with the barycentrics, to classify clear hits and clear misses.
        let d = ray.dir.as_dvec3();
        let (p0, p1, p2) = (p[0].as_dvec3(), p[1].as_dvec3(), p[2].as_dvec3());
        let (e1, e2) = (p1 - p0, p2 - p0);
        let h = d.cross(e2);
        let det = e1.dot(h);
        if det.abs() < 1e-9 {
            continue;
        }
        let s = ray.origin.as_dvec3() - p0;
        let u = s.dot(h) / det;
        let q = s.cross(e1);
        let v = d.dot(q) / det;
        let t = e2.dot(q) / det;
        let margin = u.min(v).min(1.0 - u - v);
        let got = intersect_triangle(&ray, p);
        if margin > 1e-4 && t > 1e-4 {
            let (gt, gu, gv) = got.unwrap_or_else(|| panic!("missed {p:?} {ray:?}"));
            assert!((gt as f64 - t).abs() < 1e-3 * t.max(1.0), "t {gt} vs {t}");
            assert!((gu as f64 - u).abs() < 1e-3 && (gv as f64 - v).abs() < 1e-3, "uv {gu},{gv} vs {u},{v}");
            hits += 1;
        } else if margin < -1e-4 || t < -1e-4 {
            assert!(got.is_none(), "false hit {p:?} {ray:?}");
        }
    }
    assert!(hits > 1000, "too few hits to mean anything: {hits}");
}

/// A closed cube surface of `n x n` quads per face (two triangles each), sharing vertices.
fn subdivided_cube(n: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut pos = Vec::new();
    let mut index = std::collections::HashMap::new();
    let mut vertex = |p: [i32; 3], pos: &mut Vec<[f32; 3]>| {
        *index.entry(p).or_insert_with(|| {
            pos.push(p.map(|c| c as f32 / n as f32 * 2.0 - 1.0));
            pos.len() as u32 - 1
        })
    };
    let mut tris = Vec::new();
    let n = n as i32;
    for axis in 0..3 {
        for side in [0, n] {
            for i in 0..n {
                for j in 0..n {
                    let at = |a: i32, b: i32| {
                        let mut p = [0; 3];
                        p[axis] = side;
                        p[(axis + 1) % 3] = a;
                        p[(axis + 2) % 3] = b;
                        p
                    };
                    let q =
                        [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)].map(|p| vertex(p, &mut pos));
                    tris.push([q[0], q[1], q[2]]);
                    tris.push([q[0], q[2], q[3]]);
                }
            }
        }
    }
    (pos, tris)
}

/// Every way to build a triangle BVH: object splits only, the default, and spatial splits with
/// a budget large enough that many triangles are split.
const BUILDS: [Option<SpatialSplits>; 3] = [
    None,
    Some(SpatialSplits { budget: 0.2, min_overlap: 1e-5 }),
    Some(SpatialSplits { budget: 4.0, min_overlap: 0.0 }),
];

/// How many triangle references beyond one per triangle the tree holds.
fn duplicates(bvh: &TriangleBvh, triangles: usize) -> usize {
    bvh.bvh().prim_indices().len() - triangles
}

#[test]
fn closed_cube_is_watertight_at_edges_and_vertices() {
    let (pos, tris) = subdivided_cube(7);
    for build in BUILDS {
        let bvh = TriangleBvh::build_with(&pos, &tris, build).unwrap();
        bvh.validate(&pos, &tris).unwrap();
        assert_watertight(&bvh, &pos, &tris, |rng| rng.v(-0.9, 0.9));
    }
}

/// A long closed cylinder (length 50, radius 1, off the axes) of long thin triangles whose
/// boxes all overlap: spatial splits cut them into many leaves, and the parts must still close
/// the surface.
#[test]
fn split_long_cylinder_is_watertight() {
    let (segments, length) = (24u32, 50.0f32);
    let turn = glam::Quat::from_euler(glam::EulerRot::XYZ, 0.3, 0.5, 0.7);
    let at = |x: f32, angle: f32| turn * Vec3::new(x, angle.cos(), angle.sin());
    let mut pos = Vec::new();
    for end in [0.0, length] {
        for k in 0..segments {
            pos.push(at(end, k as f32 / segments as f32 * std::f32::consts::TAU).to_array());
        }
    }
    pos.push((turn * Vec3::ZERO).to_array());
    pos.push((turn * Vec3::new(length, 0.0, 0.0)).to_array());
    let (c0, c1) = (2 * segments, 2 * segments + 1);
    let mut tris = Vec::new();
    for k in 0..segments {
        let (a, b) = (k, (k + 1) % segments);
        tris.push([a, b, segments + b]);
        tris.push([a, segments + b, segments + a]);
        tris.push([c0, b, a]);
        tris.push([c1, segments + a, segments + b]);
    }
    for build in BUILDS {
        let bvh = TriangleBvh::build_with(&pos, &tris, build).unwrap();
        bvh.validate(&pos, &tris).unwrap();
        if build.is_some_and(|b| b.budget > 1.0) {
            assert!(duplicates(&bvh, tris.len()) > 0, "{build:?}: no triangle was split");
        }
        assert_watertight(&bvh, &pos, &tris, |rng| {
            turn * Vec3::new(rng.f(0.02, 0.98) * length, rng.f(-0.6, 0.6), rng.f(-0.6, 0.6))
        });
    }
}

/// Rays from inside and outside a closed mesh through every vertex and edge midpoint hit it on
/// every traversal path.
/// `inside` makes a random point inside the mesh.
fn assert_watertight(
    bvh: &TriangleBvh,
    pos: &[[f32; 3]],
    tris: &[[u32; 3]],
    inside: impl Fn(&mut Rng) -> Vec3,
) {
    let mut rng = Rng::new(3);
    let mut rays = Vec::new();
    // Rays from inside and outside through every vertex and every edge midpoint.
    for t in tris {
        let c = corners(pos, t);
        for k in 0..3 {
            for target in [c[k], (c[k] + c[(k + 1) % 3]) * 0.5] {
                let inside = inside(&mut rng);
                rays.push(Ray::new(inside, target - inside));
                // From outside, on the line from an interior point through the target: the
                // ray enters the cube exactly there.
                let outside = target + (target - inside) * 2.0;
                rays.push(Ray::new(outside, inside - outside));
            }
        }
    }
    for simd in PATHS {
        let mut packet = vec![None; rays.len()];
        bvh.intersect_packet_simd(&rays, &mut packet, simd);
        for (ray, p) in rays.iter().zip(&packet) {
            assert!(brute(pos, tris, ray).is_some(), "brute force slipped through {ray:?}");
            assert!(bvh.intersect_simd(ray, simd).is_some(), "{simd:?} slipped through {ray:?}");
            assert!(p.is_some(), "{simd:?} packet slipped through {ray:?}");
            assert!(bvh.occluded_simd(ray, simd));
        }
    }
}

#[test]
fn validate_accepts_random_and_degenerate_inputs() {
    let mut rng = Rng::new(5);
    let random: Vec<Aabb> = (0..5000)
        .map(|_| {
            let c = rng.v(-10.0, 10.0);
            Aabb::new(c, c + rng.v(0.0, 1.0))
        })
        .collect();
    let same = vec![Aabb::new(Vec3::ONE, Vec3::splat(2.0)); 1000];
    let flat: Vec<Aabb> = (0..1000)
        .map(|_| {
            let c = rng.v(-1.0, 1.0) * Vec3::new(1.0, 1.0, 0.0);
            Aabb::new(c, c + Vec3::new(0.1, 0.1, 0.0))
        })
        .collect();
    let points: Vec<Aabb> =
        (0..1000).map(|i| Aabb::new(Vec3::splat(i as f32), Vec3::splat(i as f32))).collect();
    // Exponentially spaced boxes push SAH towards deep trees; the depth bound must hold.
    let skewed: Vec<Aabb> =
        (0..3000).map(|i| Aabb::new(Vec3::splat(1.01f32.powi(i)), Vec3::splat(1.01f32.powi(i)))).collect();
    let with_empty: Vec<Aabb> = (0..100).map(|i| if i % 3 == 0 { Aabb::EMPTY } else { random[i] }).collect();
    let one = vec![random[0]];
    for (name, boxes) in [
        ("random", &random),
        ("identical", &same),
        ("flat", &flat),
        ("points", &points),
        ("skewed", &skewed),
        ("with empty", &with_empty),
        ("one", &one),
        ("none", &Vec::new()),
    ] {
        for max_leaf_size in [1, 4, 16] {
            let bvh = Bvh::build_with(boxes, &BuildOptions { max_leaf_size, ..BuildOptions::default() });
            bvh.validate(boxes).unwrap_or_else(|e| panic!("{name}, leaves of {max_leaf_size}: {e}"));
            assert_eq!(bvh.prim_indices().len(), boxes.len());
        }
    }
}

#[test]
fn validate_rejects_a_tree_built_for_other_boxes() {
    let boxes: Vec<Aabb> =
        (0..100).map(|i| Aabb::new(Vec3::splat(i as f32), Vec3::splat(i as f32 + 1.0))).collect();
    let bvh = Bvh::build(&boxes);
    let mut moved = boxes.clone();
    moved[42].max.x += 1000.0;
    assert!(bvh.validate(&moved).is_err());
    assert!(bvh.validate(&boxes[..99]).is_err());
}

/// Random rays: from outside the soup towards it, and from inside in random directions.
fn random_rays(rng: &mut Rng, n: usize) -> Vec<Ray> {
    (0..n)
        .map(|i| {
            if i % 2 == 0 {
                let o = rng.dir() * 3.0;
                Ray::new(o, rng.v(-1.0, 1.0) - o)
            } else {
                let mut r = Ray::new(rng.v(-1.0, 1.0), rng.dir());
                r.t_max = rng.f(0.1, 5.0);
                r
            }
        })
        .collect()
}

/// Coherent packets: 8 rays from one eye through a small 4x2 grid of directions.
fn coherent_rays(rng: &mut Rng, packets: usize) -> Vec<Ray> {
    let mut rays = Vec::new();
    for _ in 0..packets {
        let eye = rng.dir() * 3.0;
        let cam = Camera::look_at(eye, rng.v(-0.5, 0.5), Vec3::Z, 0.8, 1.5);
        let (x0, y0) = ((rng.next_u64() % 60) as u32, (rng.next_u64() % 40) as u32);
        for k in 0..8 {
            rays.push(cam.pixel_ray(x0 + k % 4, y0 + k / 4, 64, 48));
        }
    }
    rays
}

#[test]
fn bvh_matches_brute_force_single_and_packet() {
    let mut rng = Rng::new(9);
    let (pos, tris) = soup(&mut rng, 1500);
    let mut rays = random_rays(&mut rng, 600);
    rays.extend(coherent_rays(&mut rng, 60));
    // A ragged tail: the last packet is partial.
    rays.truncate(rays.len() - 3);
    for build in BUILDS {
        let bvh = TriangleBvh::build_with(&pos, &tris, build).unwrap();
        bvh.bvh()
            .validate(&tris.iter().map(|t| Aabb::from_points(&corners(&pos, t))).collect::<Vec<_>>())
            .unwrap();
        bvh.validate(&pos, &tris).unwrap();
        assert_matches_brute_force(&bvh, &pos, &tris, &rays);
    }
}

/// A soup of long slivers across small triangles, the case spatial splits are for: every path
/// must still find the brute-force hits.
#[test]
fn split_slivers_match_brute_force() {
    let mut rng = Rng::new(23);
    let (mut pos, mut tris) = soup(&mut rng, 800);
    for _ in 0..200 {
        let (a, b) = (rng.v(-1.0, 1.0), rng.v(-1.0, 1.0));
        let base = pos.len() as u32;
        pos.extend([a, b, b + rng.v(-0.02, 0.02)].map(|p| p.to_array()));
        tris.push([base, base + 1, base + 2]);
    }
    let mut rays = random_rays(&mut rng, 800);
    rays.extend(coherent_rays(&mut rng, 80));
    for build in BUILDS {
        let bvh = TriangleBvh::build_with(&pos, &tris, build).unwrap();
        bvh.validate(&pos, &tris).unwrap();
        if build.is_some() {
            assert!(duplicates(&bvh, tris.len()) > 0, "{build:?}: no sliver was split");
        }
        assert_matches_brute_force(&bvh, &pos, &tris, &rays);
    }
}

fn assert_matches_brute_force(bvh: &TriangleBvh, pos: &[[f32; 3]], tris: &[[u32; 3]], rays: &[Ray]) {
    for simd in PATHS {
        let mut packet = vec![None; rays.len()];
        bvh.intersect_packet_simd(rays, &mut packet, simd);
        for (ray, p) in rays.iter().zip(&packet) {
            let want = brute(pos, tris, ray);
            assert_same(pos, tris, ray, bvh.intersect_simd(ray, simd), want, &format!("{simd:?} single"));
            assert_same(pos, tris, ray, *p, want, &format!("{simd:?} packet"));
            assert_eq!(bvh.occluded_simd(ray, simd), want.is_some(), "{simd:?} occluded {ray:?}");
        }
    }
}

/// Packets whose rays start at different points (parallel rays of an orthographic view, and
/// a fan of shadow-like rays from points on a segment) take the packet path without the
/// shared-origin shortcut.
#[test]
fn packets_with_distinct_origins_match_brute_force() {
    let mut rng = Rng::new(17);
    let (pos, tris) = soup(&mut rng, 1200);
    let bvh = TriangleBvh::build(&pos, &tris).unwrap();
    let mut rays = Vec::new();
    for _ in 0..80 {
        let dir = Vec3::new(rng.f(0.2, 1.0), rng.f(0.2, 1.0), rng.f(0.2, 1.0)).normalize();
        let base = rng.v(-1.0, 1.0) - dir * 3.0;
        let (du, dv) = (dir.any_orthonormal_vector(), dir.cross(dir.any_orthonormal_vector()));
        for k in 0..8 {
            let o = base + du * (k % 4) as f32 * 0.02 + dv * (k / 4) as f32 * 0.02;
            rays.push(Ray::new(o, dir + rng.v(-0.01, 0.01)));
        }
    }
    for simd in PATHS {
        let mut packet = vec![None; rays.len()];
        bvh.intersect_packet_simd(&rays, &mut packet, simd);
        for (ray, p) in rays.iter().zip(&packet) {
            assert_same(&pos, &tris, ray, *p, brute(&pos, &tris, ray), &format!("{simd:?} packet"));
        }
    }
    assert!(packet_hits(&bvh, &rays) > 50, "the rays should hit the soup");
}

fn packet_hits(bvh: &TriangleBvh, rays: &[Ray]) -> usize {
    let mut hits = vec![None; rays.len()];
    bvh.intersect_packet(rays, &mut hits);
    hits.iter().filter(|h| h.is_some()).count()
}

/// The SAH counts primitives in blocks of the leaf's SIMD width: leaves tested as one 4-wide
/// group should be nearly full instead of holding 1.8 triangles on average.
#[test]
fn triangle_leaves_fill_their_groups() {
    let mut rng = Rng::new(19);
    let (pos, tris) = soup(&mut rng, 4000);
    let bvh = TriangleBvh::build(&pos, &tris).unwrap();
    let per_leaf = tris.len() as f64 / bvh.bvh().leaf_count() as f64;
    assert!(per_leaf > 3.0, "{per_leaf:.2} triangles per leaf");
    let boxes: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(&corners(&pos, t))).collect();
    let one = Bvh::build_with(&boxes, &BuildOptions { block_size: 1, ..BuildOptions::default() });
    assert!(one.leaf_count() > bvh.bvh().leaf_count(), "block size 1 splits further");
}

#[test]
fn generic_traverse_visits_what_brute_force_hits() {
    let mut rng = Rng::new(13);
    let (pos, tris) = soup(&mut rng, 800);
    let boxes: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(&corners(&pos, t))).collect();
    let bvh = Bvh::build_with(&boxes, &BuildOptions { max_leaf_size: 1, ..BuildOptions::default() });
    for ray in random_rays(&mut rng, 300) {
        let want = brute(&pos, &tris, &ray);
        let mut r = ray;
        let mut got: Option<Hit> = None;
        let any = bvh.traverse(&mut r, |prim, r| {
            match intersect_triangle(r, corners(&pos, &tris[prim as usize])) {
                Some((t, u, v)) => {
                    r.t_max = t;
                    got = Some(Hit { t, prim, u, v });
                    true
                }
                None => false,
            }
        });
        assert_eq!(any, want.is_some());
        assert_same(&pos, &tris, &ray, got, want, "traverse");
        let mut r = ray;
        let blocked = bvh.traverse_any(&mut r, |prim, r| {
            intersect_triangle(r, corners(&pos, &tris[prim as usize])).is_some()
        });
        assert_eq!(blocked, want.is_some());
    }
}

#[test]
fn trace_image_packets_equal_single_rays() {
    let (pos, tris) = subdivided_cube(5);
    let bvh = TriangleBvh::build(&pos, &tris).unwrap();
    let cam = Camera::look_at(Vec3::new(2.5, 1.7, 1.3), Vec3::ZERO, Vec3::Z, 0.9, 37.0 / 23.0);
    let (ids_p, depth_p) = trace_image_with(&bvh, &cam, 37, 23, TraceMode::Packet);
    let (ids_s, depth_s) = trace_image_with(&bvh, &cam, 37, 23, TraceMode::Single);
    assert_eq!(depth_p, depth_s);
    assert!(ids_p.iter().filter(|&&i| i != u32::MAX).count() > 100);
    for (i, (a, b)) in ids_p.iter().zip(&ids_s).enumerate() {
        if a != b {
            let ray = cam.pixel_ray(i as u32 % 37, i as u32 / 37, 37, 23);
            let t = intersect_triangle(&ray, corners(&pos, &tris[*a as usize])).map(|h| h.0);
            assert_eq!(t, Some(depth_s[i]), "pixel {i}: {a} vs {b} not a tie");
        }
    }
}

#[test]
fn empty_and_invalid_meshes() {
    let empty = TriangleBvh::build(&[], &[]).unwrap();
    let ray = Ray::new(Vec3::ZERO, Vec3::X);
    assert_eq!(empty.intersect(&ray), None);
    assert!(!empty.occluded(&ray));
    let mut hits = [Some(Hit { t: 0.0, prim: 0, u: 0.0, v: 0.0 })];
    empty.intersect_packet(&[ray], &mut hits);
    assert_eq!(hits, [None]);
    assert_eq!(
        TriangleBvh::build(&[[0.0; 3]; 3], &[[0, 1, 2], [0, 1, 3]]).unwrap_err(),
        MeshError::VertexOutOfRange { triangle: 1, vertex: 3, vertices: 3 }
    );
    // Degenerate and non-finite triangles are never hit.
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let bad = TriangleBvh::build(&pos, &[[0, 1, 2], [3, 1, 4]]).unwrap();
    assert_eq!(bad.intersect(&Ray::new(Vec3::new(0.5, 0.0, -1.0), Vec3::Z)), None);
}
