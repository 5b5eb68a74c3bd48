use super::assign::*;
use super::cell_stats::*;
use super::cluster::*;
use super::geometry::*;
use super::partition1::*;
use super::partition2::*;
use super::pieces::*;
use super::samples::*;
use super::scan::*;
use super::*;
use crate::ingest::tests::{ingest_list, ingest_plant};

use crate::ingest::tests::ListObject as Obj;

#[test]
fn samples_taken_by_ingest_equal_pass_a_over_the_file() {
    let dir = tempfile::tempdir().unwrap();
    for p in [
        RedefineParams::default(),
        // A budget small enough that ingest's global stride doubles several times.
        RedefineParams { max_samples: 5000, min_samples_per_object: 8, ..Default::default() },
    ] {
        let rule = p.sample_rule();
        let src =
            tw_io::generate::PlantSource::new(tw_io::generate::PlantParams { triangles: 300_000, seed: 5 })
                .unwrap();
        let scene = tw_io::Scene::from_sources(vec![Box::new(src)]);
        let sampler = crate::sampling::OnlineSampler::new(rule, 1 << 30);
        let ing = crate::ingest::ingest_in(scene, dir.path(), None, Some(sampler), &mut |_| {}).unwrap();
        assert!(ing.samples.lock().unwrap().is_some(), "the plant's objects are contiguous");
        let online = sample_objects(&ing, &p).unwrap();
        // Taken once: a second redefinition reads the file.
        assert!(ing.samples.lock().unwrap().is_none());
        let file = sample_objects(&ing, &p).unwrap();
        assert!(online.points.len() as u64 >= p.max_samples.min(1000));
        assert_eq!(online.stride, file.stride);
        assert_eq!(online.start, file.start);
        let bits = |s: &Samples| s.points.iter().map(|c| c.map(f32::to_bits)).collect::<Vec<_>>();
        assert!(bits(&online) == bits(&file));
    }
}

/// The binned lookup of a part route gives the group a binary search over all the starts
/// gives, for every index of the span and past it, whatever the spacing of the starts.
#[test]
fn part_routes_find_the_group_of_every_index_like_a_search() {
    let cases: [(u64, u64, Vec<u64>); 6] = [
        (100, 1000, vec![1, 2, 3, 512, 513, 900, 999]),
        (0, 5000, (1..40).map(|k| k * k * 3).collect()),
        (7, 7, vec![]),
        (50, 60, vec![]),
        (0, 4096, vec![1024]),
        (1 << 40, (1 << 40) + 3000, (1..3000).step_by(7).collect()),
    ];
    for (start, end, starts) in cases {
        let route = PartRoute::new(9, start..end, starts.clone());
        assert!(route.bins.len() <= 2 * (starts.len() + 2), "O(groups) bins");
        for index in start.saturating_sub(3)..end + 600 {
            let rel = index.saturating_sub(start);
            let expected = 9 + starts.partition_point(|&s| s <= rel) as u32;
            assert_eq!(route.piece(index), expected, "index {index} of {start}..{end}");
        }
    }
}

#[test]
fn spans_to_read_are_sorted_joined_across_small_gaps_and_skip_empty_objects() {
    let g = SPAN_GAP;
    let span = [5 * g..6 * g, 0..0, 10..20, 20 + g..30 + g, 4 * g..4 * g + 1, 7..7];
    // Objects 2 and 3 are one gap apart (joined); 4 and 0 are more than a gap from 3 but
    // within one of each other; 1 and 5 have no triangle.
    let span = |o: u32| span[o as usize].clone();
    assert_eq!(joined_spans(&[0, 1, 2, 3, 4, 5], span), vec![10..30 + g, 4 * g..6 * g]);
    assert_eq!(joined_spans(&[3], span), vec![20 + g..30 + g]);
    assert!(joined_spans(&[1, 5], span).is_empty());
}

/// A strip of `n` triangles along x from `x0` to `x0 + len`, at (y, z).
fn strip(name: &str, n: usize, x0: f64, len: f64, y: f64, z: f64) -> Obj {
    let dx = len / n as f64;
    let tris = (0..n)
        .map(|i| {
            let x = x0 + i as f64 * dx;
            [[x, y, z], [x + dx, y, z], [x, y + 0.5, z + 0.5]]
        })
        .collect();
    (name.into(), None, tris)
}

/// A small cube-ish object of 12 triangles at `c` with half size `h`.
fn cube(name: &str, c: [f64; 3], h: f64) -> Obj {
    let v = |i: u32| {
        [
            c[0] + if i & 1 > 0 { h } else { -h },
            c[1] + if i & 2 > 0 { h } else { -h },
            c[2] + if i & 4 > 0 { h } else { -h },
        ]
    };
    let faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    let mut tris = Vec::new();
    for f in faces {
        tris.push([v(f[0]), v(f[1]), v(f[2])]);
        tris.push([v(f[0]), v(f[2]), v(f[3])]);
    }
    (name.into(), None, tris)
}

fn cells_of(ing: &Ingested, r: &Redefined) -> Vec<u32> {
    let mut v = Vec::new();
    ing.work
        .scan(|first, tris| {
            v.extend(tris.iter().enumerate().map(|(k, t)| r.cell_of(t, first + k as u64)));
            Ok(())
        })
        .unwrap();
    v
}

#[test]
fn partition_one_splits_a_long_object_into_pieces_under_thresholds() {
    let dir = tempfile::tempdir().unwrap();
    // A 100 m pipe of 20 000 triangles beside a 1 m cube (so the scene is the pipe).
    let ing = ingest_list(
        dir.path(),
        vec![strip("pipe", 20_000, 0.0, 100.0, 0.0, 0.0), cube("c", [50.0, 20.0, 0.0], 0.5)],
    );
    // No clustering, no partition-II: the pieces are the cells.
    let params = RedefineParams {
        neighbours: 0,
        t2: u64::MAX / 2,
        max_cell_triangles: u64::MAX / 2,
        ..Default::default()
    };
    let r = redefine(&ing, &params).unwrap();
    assert_eq!(r.report.objects, 2);
    assert_eq!(r.report.split_objects, 1);
    assert!(r.report.pieces >= 10, "{:?}", r.report);
    assert_eq!(r.report.cells, r.report.pieces);
    let scale = Scale::new(&ing, &params);
    let total: u64 = r.cells.iter().map(|c| c.triangles).sum();
    assert_eq!(total, 20_012);
    for c in &r.cells {
        let ext = scale.grid_ext(&c.bounds);
        // Each piece is short enough (up to a triangle's width) or small enough.
        assert!(
            c.triangles <= params.t1 * 2 || diag(ext) <= scale.s1 * 1.2,
            "piece of {} triangles, diagonal {}",
            c.triangles,
            diag(ext)
        );
    }
    // Pieces of the pipe are contiguous intervals of x: balanced medians give equal counts.
    let pipe: Vec<u64> = r.cells.iter().map(|c| c.triangles).filter(|&t| t > 12).collect();
    let (min, max) = (pipe.iter().min().unwrap(), pipe.iter().max().unwrap());
    assert!(max - min <= max / 4, "unbalanced pieces {pipe:?}");
}

#[test]
fn compact_objects_are_not_split() {
    let dir = tempfile::tempdir().unwrap();
    let mut objs = vec![cube("a", [0.0; 3], 1.0), cube("b", [100.0, 100.0, 100.0], 1.0)];
    // 2000 triangles, but a 1 m square patch: fine for partition-I.
    let patch: Vec<[[f64; 3]; 3]> = (0..2000)
        .map(|i| {
            let x = (i % 40) as f64 * 0.025;
            let y = (i / 40) as f64 * 0.02;
            [[x, y, 0.0], [x + 0.025, y, 0.0], [x, y + 0.02, 0.0]]
        })
        .collect();
    objs.push(("patch".into(), None, patch));
    let ing = ingest_list(dir.path(), objs);
    let params = RedefineParams { neighbours: 0, ..Default::default() };
    let r = redefine(&ing, &params).unwrap();
    assert_eq!(r.report.split_objects, 0);
    assert_eq!(r.report.pieces, 3);
}

#[test]
fn clustering_merges_nearby_small_objects_but_not_far_apart_ones() {
    let dir = tempfile::tempdir().unwrap();
    let mut objs = Vec::new();
    // Two groups of 50 bolts, 1 000 m apart; inside a group the bolts are 0.5 m apart.
    for g in 0..2 {
        for i in 0..50 {
            let c = [g as f64 * 1000.0 + (i % 10) as f64 * 0.5, (i / 10) as f64 * 0.5, 0.0];
            objs.push(cube(&format!("bolt {g} {i}"), c, 0.1));
        }
    }
    let ing = ingest_list(dir.path(), objs);
    // The scene box is 1005 × 2.2 × 1 m (the floor on extents), a group 4.7 × 2.2 × 1 m:
    // V must allow 1 % of the scene volume.
    let r = redefine(&ing, &RedefineParams { v: 0.01, ..Default::default() }).unwrap();
    assert_eq!(r.report.pieces, 100);
    assert_eq!(r.report.clusters, 2, "{:?}", r.report);
    assert_eq!(r.report.cells, 2);
    let cells = cells_of(&ing, &r);
    // Each group is one cell, and the groups differ.
    assert!(cells[..600].iter().all(|&c| c == cells[0]));
    assert!(cells[600..].iter().all(|&c| c == cells[600]));
    assert_ne!(cells[0], cells[600]);
}

#[test]
fn clustering_respects_the_volume_limit() {
    let dir = tempfile::tempdir().unwrap();
    // A row of 40 touching boxes 1 m wide in a 40 × 40 × 40 m scene (volume 64 000 m³);
    // with V = 10⁻³ of it (64 m³) a cluster spans at most 64 / (1 × 1 × 1) m along the row...
    let mut objs: Vec<Obj> =
        (0..40).map(|i| cube(&format!("b{i}"), [i as f64 + 0.5, 0.5, 0.5], 0.5)).collect();
    objs.push(cube("far corner", [39.5, 39.5, 39.5], 0.5));
    let ing = ingest_list(dir.path(), objs);
    let unlimited = redefine(&ing, &RedefineParams { v: 1.0, ..Default::default() }).unwrap();
    assert_eq!(unlimited.report.clusters, 2, "{:?}", unlimited.report);
    // ... and with V = 1.5e-4 (9.6 m³) at most 9 boxes of 1 m³.
    let params = RedefineParams { v: 1.5e-4, min_cell_triangles: 0, ..Default::default() };
    let limited = redefine(&ing, &params).unwrap();
    assert!(limited.report.clusters >= 5, "{:?}", limited.report);
    let scale = Scale::new(&ing, &params);
    for c in &limited.cells {
        assert!(scale.volume(&c.bounds) <= scale.v * 1.01, "cell volume {}", scale.volume(&c.bounds));
    }
    // The small-cluster post-pass may go up to 2 V.
    let relaxed = redefine(&ing, &RedefineParams { min_cell_triangles: 1000, ..params }).unwrap();
    assert!(relaxed.report.clusters < limited.report.clusters, "{:?}", relaxed.report);
    for c in &relaxed.cells {
        assert!(scale.volume(&c.bounds) <= 2.0 * scale.v * 1.01, "cell volume {}", scale.volume(&c.bounds));
    }
}

#[test]
fn partition_two_splits_large_uneven_clusters() {
    let dir = tempfile::tempdir().unwrap();
    // 60 touching slabs of 1000 triangles along x: one cluster of 60 000 triangles, 60 m
    // long and 1 m wide: partition-II must cut it into compact cells of ≤ t2-ish triangles.
    let objs: Vec<Obj> = (0..60).map(|i| strip(&format!("s{i}"), 1000, i as f64, 1.0, 0.0, 0.0)).collect();
    let ing = ingest_list(dir.path(), objs);
    let params = RedefineParams { v: 1.0, d: 0.05, ..Default::default() };
    let no_p2 = RedefineParams { t2: u64::MAX / 2, r2: 1e9, s2: 1e9, ..params.clone() };
    let r0 = redefine(&ing, &no_p2).unwrap();
    assert_eq!(r0.report.clusters, 1, "{:?}", r0.report);
    assert_eq!(r0.report.cells, 1);
    let r = redefine(&ing, &params).unwrap();
    assert_eq!(r.report.clusters, 1);
    assert_eq!(r.report.split_clusters, 1);
    assert!(r.report.cells >= 6, "{:?}", r.report);
    assert!(r.report.max_cell_triangles <= 10_000, "{:?}", r.report);
    assert_eq!(r.cells.iter().map(|c| c.triangles).sum::<u64>(), 60_000);
}

#[test]
fn partition_two_caps_cells() {
    let dir = tempfile::tempdir().unwrap();
    // One compact object of 40 000 triangles (a 10 × 10 m patch): no uneven split applies,
    // but the cap of 8 192 does, through the object's samples.
    let patch: Vec<[[f64; 3]; 3]> = (0..40_000)
        .map(|i| {
            let x = (i % 200) as f64 * 0.05;
            let y = (i / 200) as f64 * 0.05;
            [[x, y, 0.0], [x + 0.05, y, 0.0], [x, y + 0.05, 0.0]]
        })
        .collect();
    let ing = ingest_list(dir.path(), vec![("patch".into(), None, patch)]);
    let params = RedefineParams { max_cell_triangles: 8192, ..Default::default() };
    let r = redefine(&ing, &params).unwrap();
    assert!(r.report.cells >= 5, "{:?}", r.report);
    assert!(r.report.max_cell_triangles <= 8192, "{:?}", r.report);
}

/// Every triangle's cell from a pass over the file agrees with the cells' counts and boxes.
fn check_cells(ing: &Ingested, r: &Redefined) {
    let mut count = vec![0u64; r.cells.len()];
    let mut boxes = vec![GridBox::EMPTY; r.cells.len()];
    let mut next = 0u64;
    ing.work
        .scan(|first, tris| {
            assert_eq!(first, next);
            next += tris.len() as u64;
            for (k, t) in tris.iter().enumerate() {
                let c = r.cell_of(t, first + k as u64) as usize;
                count[c] += 1;
                for v in t.p {
                    boxes[c].grow(ing.work.quantize(&ing.grid, v));
                }
            }
            Ok(())
        })
        .unwrap();
    assert_eq!(count, r.cells.iter().map(|c| c.triangles).collect::<Vec<_>>());
    assert_eq!(boxes, r.cells.iter().map(|c| c.bounds).collect::<Vec<_>>(), "exact boxes");
}

#[test]
fn coincident_triangles_are_cut_by_count_under_the_cap() {
    let dir = tempfile::tempdir().unwrap();
    let one = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let moved = |d: f64| one.map(|p| [p[0] + d, p[1], p[2]]);
    // Copies of one triangle (no plane between them), a second pile nearby, and a strip
    // that space splits as usual.
    let objs = vec![
        ("pile".into(), None, vec![one; 10_000]),
        ("strip".into(), None, strip("strip", 3000, 0.0, 30.0, 2.0, 0.0).2),
        ("pile2".into(), None, vec![moved(0.5); 2500]),
    ];
    let ing = ingest_list(dir.path(), objs);
    let params = RedefineParams { max_cell_triangles: 1000, ..Default::default() };
    let mut r = redefine(&ing, &params).unwrap();
    assert!(r.report.count_split_cells >= 1, "{:?}", r.report);
    assert!(r.report.max_cell_triangles <= 1000, "{:?}", r.report);
    assert!(r.cells.iter().all(|c| c.triangles <= 1000));
    assert!(r.report.cells >= 16, "{:?}", r.report);
    check_cells(&ing, &r);
    // The same again, and after the hierarchy renumbered the cells.
    let again = redefine(&ing, &params).unwrap();
    assert_eq!(again.cells, r.cells);
    assert_eq!(cells_of(&ing, &again), cells_of(&ing, &r));
    r.order_by_hierarchy();
    check_cells(&ing, &r);
}

#[test]
fn a_cap_of_one_triangle_gives_a_cell_per_triangle() {
    let dir = tempfile::tempdir().unwrap();
    let one = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let ing = ingest_list(dir.path(), vec![("pile".into(), None, vec![one; 50])]);
    let params = RedefineParams { max_cell_triangles: 1, ..Default::default() };
    let r = redefine(&ing, &params).unwrap();
    assert_eq!(r.cells.len(), 50, "{:?}", r.report);
    check_cells(&ing, &r);
}

#[test]
fn the_plant_needs_no_count_split() {
    // Inputs that space splits keep their cells (and their stores) as before.
    let dir = tempfile::tempdir().unwrap();
    let ing = ingest_plant(dir.path(), 200_000);
    let r = redefine(&ing, &RedefineParams::default()).unwrap();
    assert_eq!(r.report.count_split_cells, 0, "{:?}", r.report);
    assert!(r.assign.count_split.is_empty());
}

#[test]
fn every_triangle_gets_an_existing_cell_and_counts_match() {
    let dir = tempfile::tempdir().unwrap();
    let ing = ingest_plant(dir.path(), 200_000);
    let r = redefine(&ing, &RedefineParams::default()).unwrap();
    let cells = cells_of(&ing, &r);
    let mut count = vec![0u64; r.cells.len()];
    for &c in &cells {
        count[c as usize] += 1;
    }
    assert_eq!(count, r.cells.iter().map(|c| c.triangles).collect::<Vec<_>>());
    assert!(r.report.objects > r.report.clusters, "{:?}", r.report);
    assert!(r.report.pieces >= r.report.objects);
}

#[test]
fn plant_hierarchy_is_valid_and_renumbering_keeps_assignment() {
    let dir = tempfile::tempdir().unwrap();
    let ing = ingest_plant(dir.path(), 200_000);
    let mut r = redefine(&ing, &RedefineParams::default()).unwrap();
    let before = cells_of(&ing, &r);
    let old_cells = r.cells.clone();
    let h = r.order_by_hierarchy();
    let boxes: Vec<GridBox> = r.cells.iter().map(|c| c.bounds).collect();
    h.validate(&boxes).unwrap();
    assert_eq!(h.leaf_order(), (0..r.cells.len() as u32).collect::<Vec<_>>());
    let after = cells_of(&ing, &r);
    for (b, a) in before.iter().zip(&after) {
        assert_eq!(old_cells[*b as usize], r.cells[*a as usize]);
    }
}

#[test]
fn redefinition_is_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let ing = ingest_plant(dir.path(), 100_000);
    let a = redefine(&ing, &RedefineParams::default()).unwrap();
    let b = redefine(&ing, &RedefineParams::default()).unwrap();
    assert_eq!(a.cells, b.cells);
    assert_eq!(a.report, b.report);
    assert_eq!(cells_of(&ing, &a), cells_of(&ing, &b));
}

#[test]
fn bad_parameters_are_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let ing = ingest_list(dir.path(), vec![cube("a", [0.0; 3], 1.0)]);
    for p in [
        RedefineParams { s1: 0.0, ..Default::default() },
        RedefineParams { r2: f64::NAN, ..Default::default() },
        RedefineParams { t1: 0, ..Default::default() },
        RedefineParams { d: -1.0, ..Default::default() },
    ] {
        assert!(matches!(redefine(&ing, &p), Err(BuildError::Param(_))));
    }
}

#[test]
fn aspect_and_next_up_edge_cases() {
    assert_eq!(aspect([0.0; 3]), 1.0);
    assert_eq!(aspect([1.0, 0.0, 0.0]), f64::INFINITY);
    assert_eq!(aspect([4.0, 2.0, 0.0]), 2.0);
    for v in [0.0f32, 1.0, -1.0, 1e-30, -1e30, f32::MIN_POSITIVE] {
        let u = next_up(v);
        assert!(u > v && (u as f64 - v as f64) > 0.0);
        assert!(!(v < u && u < v), "no value between");
    }
    assert!(next_up(-f32::from_bits(1)) == 0.0 || next_up(-f32::from_bits(1)) == -0.0);
}

/// Passes A, B and C against the obvious serial loops over decoded triangles, on a plant
/// of several scan chunks, on pools of 1 and 3 threads: bit for bit the same samples, counts,
/// boxes and centres (the centroid sums must add in file order).
#[test]
fn parallel_passes_equal_the_serial_loops() {
    let dir = tempfile::tempdir().unwrap();
    let ing = crate::ingest::tests::ingest_plant(dir.path(), 150_000);
    assert!(ing.triangles > crate::ingest::SCAN_CHUNK as u64, "several chunks");
    for ((p, cuts), threads) in pass_presets().iter().flat_map(|p| [(p, 1), (p, 3)]) {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| check_passes_against_serial_loops(&ing, p, *cuts));
    }
}

/// The presets the passes are checked on, each with whether partition-II cuts pieces by plan.
/// The defaults split objects (partition-I); without partition-I and with small cells,
/// partition-II cuts whole large objects by plan (pass C reads them again).
fn pass_presets() -> [(RedefineParams, bool); 2] {
    [
        (RedefineParams::default(), false),
        (
            RedefineParams { s1: 10.0, r1: 1e9, max_cell_triangles: 4096, t2: 2000, ..Default::default() },
            true,
        ),
    ]
}

/// Runs passes A, B and C of one preset in the order `redefine` does, checking each against
/// its serial loop; `cuts` says the preset must have partition-II cut some pieces by plan.
fn check_passes_against_serial_loops(ing: &Ingested, p: &RedefineParams, cuts: bool) {
    let scale = Scale::new(ing, p);
    let mut samples = sample_objects(ing, p).unwrap();
    assert_pass_a_is_serial(ing, &samples);

    let mut assign = Assigner::default();
    let mut report = RedefineReport::default();
    let piece_object = partition_objects(ing, p, &scale, &mut samples, &mut assign, &mut report);
    let n = piece_object.len();
    assert!(cuts || report.split_objects > 0, "the plant has split objects");
    let pieces = piece_stats(ing, &assign, n).unwrap();
    assert_pass_b_is_serial(ing, &assign, n, &pieces);

    let clusters = cluster_pieces(p, &scale, &pieces, &mut report);
    let cells = partition_clusters(ing, p, &scale, &samples, &pieces, &clusters, &mut assign, &mut report);
    let cut = (0..n).filter(|&q| matches!(assign.piece_cell[q], Route::Plan(_))).count();
    assert!(!cuts || (cut > 0 && cut < n), "some pieces cut by a plan ({cut} of {n}), some whole");
    let stats = cell_stats(ing, &assign, &pieces, &piece_object, cells).unwrap();
    assert_pass_c_is_serial(ing, &assign, cells as usize, &stats);
}

/// Pass A, serially: every stride-th triangle of each sampled object, in file order.
fn assert_pass_a_is_serial(ing: &Ingested, samples: &Samples) {
    let mut seen = vec![0u64; ing.objects.len()];
    let mut expected = vec![[0f32; 3]; samples.points.len()];
    ing.work
        .scan(|_, tris| {
            for t in tris {
                let o = t.object as usize;
                let s = samples.stride[o];
                if s > 0 && seen[o].is_multiple_of(s) {
                    expected[samples.start[o] + (seen[o] / s) as usize] = t.centroid();
                }
                seen[o] += 1;
            }
            Ok(())
        })
        .unwrap();
    assert!(samples.points.iter().zip(&expected).all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits)));
}

/// Pass B, serially: each of the `n` pieces' count, box and centre (centroid sums added in
/// file order).
fn assert_pass_b_is_serial(ing: &Ingested, assign: &Assigner, n: usize, pieces: &Pieces) {
    let (mut count, mut sum, mut lo, mut hi) =
        (vec![0u64; n], vec![[0f64; 3]; n], vec![[f32::INFINITY; 3]; n], vec![[f32::NEG_INFINITY; 3]; n]);
    ing.work
        .scan(|first, tris| {
            for (k, t) in tris.iter().enumerate() {
                let q = assign.piece(t, first + k as u64) as usize;
                count[q] += 1;
                let c = t.centroid();
                for i in 0..3 {
                    sum[q][i] += c[i] as f64;
                    for v in t.p {
                        lo[q][i] = lo[q][i].min(v[i]);
                        hi[q][i] = hi[q][i].max(v[i]);
                    }
                }
            }
            Ok(())
        })
        .unwrap();
    assert_eq!(pieces.count, count);
    for q in 0..n {
        let c = count[q].max(1) as f64;
        let centre = sum[q].map(|s| (s / c) as f32);
        assert_eq!(pieces.centre[q].map(f32::to_bits), centre.map(f32::to_bits), "piece {q}");
        assert_eq!(pieces.bounds[q].min.map(f32::to_bits), lo[q].map(f32::to_bits));
        assert_eq!(pieces.bounds[q].max.map(f32::to_bits), hi[q].map(f32::to_bits));
    }
}

/// Pass C, serially: each of the `cells` cells' triangle count and, where it has triangles,
/// its grid box.
fn assert_pass_c_is_serial(ing: &Ingested, assign: &Assigner, cells: usize, stats: &[CellInfo]) {
    let mut tris_of = vec![0u64; cells];
    let mut box_of = vec![FBox::EMPTY; cells];
    ing.work
        .scan(|first, tris| {
            for (k, t) in tris.iter().enumerate() {
                let c = assign.cell(t, first + k as u64) as usize;
                tris_of[c] += 1;
                for v in t.p {
                    box_of[c].grow(v);
                }
            }
            Ok(())
        })
        .unwrap();
    assert_eq!(stats.iter().map(|c| c.triangles).collect::<Vec<_>>(), tris_of);
    for (c, info) in stats.iter().enumerate() {
        if tris_of[c] > 0 {
            assert_eq!(info.bounds, box_of[c].to_grid(&ing.work, &ing.grid), "cell {c}");
        }
    }
}
