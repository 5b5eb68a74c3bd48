use std::collections::HashMap;

use super::layout::{count, Board, Plan, BOARDS_PER_CABINET, MAX_STRUCTURE};
use super::parts::{Detail, MAX_LEVEL};
use super::*;
use crate::{MeshChunk, ObjectId, ObjectInfo, Scene, SceneStats, Triangle};

fn params(triangles: u64, seed: u64) -> AssemblyParams {
    AssemblyParams { triangles, seed, objects: AssemblyObjects::PerPart }
}

fn one(triangles: u64, seed: u64) -> AssemblyParams {
    AssemblyParams { objects: AssemblyObjects::One, ..params(triangles, seed) }
}

/// Per object: name, triangles, bounds. Also a hash of the geometry, the largest chunk and,
/// when `edges` is set, the closedness of every object (checked when the next one begins).
#[derive(Default)]
struct Record {
    triangles: u64,
    objects: Vec<(String, u64, Aabb)>,
    colors: usize,
    /// Hash of every triangle's positions, in order, ignoring objects.
    hash: u64,
    largest_chunk: usize,
    edges: Option<HashMap<(u64, u64), u32>>,
    vertex_base: u64,
    open_objects: Vec<String>,
}

impl Record {
    fn new(check_edges: bool) -> Record {
        Record { hash: 0xcbf2_9ce4_8422_2325, edges: check_edges.then(HashMap::new), ..Default::default() }
    }

    /// Every directed edge of the object must appear exactly once and its reverse exactly once:
    /// each undirected edge is used by two triangles, consistently wound.
    fn check_closed(&mut self) {
        let Some(edges) = self.edges.as_mut() else { return };
        let closed = edges.iter().all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1));
        if !closed && !edges.is_empty() {
            self.open_objects.push(self.objects.last().map(|o| o.0.clone()).unwrap_or_default());
        }
        edges.clear();
    }
}

impl TriangleSink for Record {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        assert_eq!(id as usize, self.objects.len(), "objects are numbered densely");
        self.check_closed();
        self.colors += info.color.is_some() as usize;
        self.objects.push((info.name.clone(), 0, Aabb::EMPTY));
        Ok(())
    }
    fn triangle(&mut self, _t: &Triangle) -> Result<(), ImportError> {
        unreachable!("the generator emits chunks")
    }
    fn mesh(&mut self, c: &MeshChunk<'_>) -> Result<(), ImportError> {
        let n = c.indices.len() as u64 / 3;
        self.triangles += n;
        self.largest_chunk = self.largest_chunk.max(c.positions.len());
        for &i in c.indices {
            for v in c.positions[i as usize] {
                self.hash = (self.hash ^ v.to_bits()).wrapping_mul(0x100_0000_01b3);
            }
            self.objects[c.object as usize].2.grow(c.positions[i as usize]);
        }
        self.objects[c.object as usize].1 += n;
        if let Some(edges) = self.edges.as_mut() {
            for t in c.indices.chunks_exact(3) {
                for k in 0..3 {
                    let (a, b) = (t[k] as u64 + self.vertex_base, t[(k + 1) % 3] as u64 + self.vertex_base);
                    *edges.entry((a, b)).or_insert(0) += 1;
                }
            }
        }
        self.vertex_base += c.positions.len() as u64;
        Ok(())
    }
}

fn record_with(p: AssemblyParams, check_edges: bool) -> Record {
    let mut r = Record::new(check_edges);
    let s = Box::new(AssemblySource::new(p).unwrap()).stream(&mut r).unwrap();
    r.check_closed();
    assert_eq!(s.objects as usize, r.objects.len());
    r
}

fn record(p: AssemblyParams) -> Record {
    record_with(p, false)
}

#[test]
fn the_closedness_check_finds_an_open_part() {
    let mut r = Record::new(true);
    let mut e = Emitter::new(&mut r);
    let f = crate::generate::shapes::Frame::at([0.0; 3]);
    e.begin("closed", Rgba8::GREY);
    e.cylinder(&f, 1.0, 0.0, 1.0, 8, true, true);
    e.begin("open", Rgba8::GREY);
    e.cylinder(&f, 1.0, 0.0, 1.0, 8, true, false);
    e.finish().unwrap();
    r.check_closed();
    assert_eq!(r.open_objects, ["open"]);
}

#[test]
fn rejects_sizes_out_of_range() {
    assert!(AssemblySource::new(params(9_999, 1)).is_err());
    assert!(AssemblySource::new(params(MAX_ASSEMBLY_TRIANGLES + 1, 1)).is_err());
    let e = AssemblySource::new(params(0, 1)).unwrap_err();
    assert!(e.to_string().contains("0 triangles requested"), "{e}");
    assert!(AssemblySource::new(params(MIN_ASSEMBLY_TRIANGLES, 1)).is_ok());
    assert!(AssemblySource::new(params(MAX_ASSEMBLY_TRIANGLES, 1)).is_ok());
}

#[test]
fn name_and_progress_total_round_down_to_even() {
    let s = AssemblySource::new(params(123_457, 9)).unwrap();
    assert_eq!(s.name(), "generated assembly (123457 triangles, seed 9)");
    assert_eq!(s.progress_total(), Some(123_456));
    let s = AssemblySource::new(one(20_000, 2)).unwrap();
    assert_eq!(s.name(), "generated assembly (20000 triangles, seed 2, one object)");
}

#[test]
fn triangle_count_is_exact_for_even_n_and_one_less_for_odd_n() {
    for n in [10_000, 10_001, 33_334, 250_001, 1_000_000] {
        let r = record(params(n, 3));
        assert_eq!(r.triangles, n & !1, "N = {n}");
        assert!(r.objects.iter().all(|o| o.1 > 0), "N = {n}: an object without triangles");
    }
}

#[test]
fn every_board_uses_its_budget_exactly_with_a_small_harness() {
    for n in [10_000, 1_000_000, 10_000_000] {
        let plan = Plan::new(&params(n, 5));
        for b in [0, plan.boards / 2, plan.boards - 1] {
            let board = Board::new(&plan, b);
            let budget = plan.board_budget(b);
            let sum: u64 = board.parts.iter().map(|(p, d)| p.triangles(d)).sum();
            assert_eq!(sum, budget, "N {n} board {b}");
            let (last, d) = board.parts.last().unwrap();
            let harness = last.triangles(d);
            assert!(
                harness <= 200 || (harness as f64) < 0.02 * budget as f64,
                "N {n} board {b}: harness {harness}"
            );
        }
        let boards: u64 = (0..plan.boards).map(|b| plan.board_budget(b)).sum();
        assert_eq!(boards + plan.structure, plan.triangles);
    }
}

#[test]
fn same_seed_same_assembly_different_seed_different_assembly() {
    let a = record(params(200_000, 1));
    let b = record(params(200_000, 1));
    let c = record(params(200_000, 2));
    assert_eq!(a.hash, b.hash);
    assert_eq!(a.objects, b.objects);
    assert_ne!(a.hash, c.hash);
}

#[test]
fn every_part_is_closed_and_consistently_wound() {
    for n in [10_000, 300_000] {
        let r = record_with(params(n, 4), true);
        assert!(
            r.open_objects.is_empty(),
            "N {n}: open parts {:?}",
            &r.open_objects[..r.open_objects.len().min(10)]
        );
        assert!(r.objects.iter().all(|o| o.1 % 2 == 0));
    }
    // Every part kind at the highest detail too (the largest boards of a 10^9 assembly).
    let plan = Plan::new(&params(MAX_ASSEMBLY_TRIANGLES, 1));
    let board = Board::new(&plan, 7);
    assert!(board.level > 0);
    let mut r = Record::new(true);
    let mut e = Emitter::new(&mut r);
    let cabinet = cabinet_parts(&plan, 0, MAX_STRUCTURE);
    for p in board.parts.iter().map(|(p, _)| p).chain(&cabinet) {
        e.begin(p.part.prefix(), p.part.color());
        p.part.emit(&mut e, &p.frame, &Detail::new(MAX_LEVEL));
    }
    e.finish().unwrap();
    r.check_closed();
    assert!(r.open_objects.is_empty(), "{:?}", r.open_objects);
}

#[test]
fn one_object_mode_writes_the_same_triangles_as_one_object() {
    let parts = record(params(150_000, 6));
    let single = record(one(150_000, 6));
    assert_eq!(single.objects.len(), 1);
    assert_eq!(single.objects[0].0, "assembly");
    assert_eq!(single.triangles, 150_000);
    assert_eq!(single.hash, parts.hash);
    assert!(parts.objects.len() > 100);
}

#[test]
fn per_part_mode_writes_one_named_coloured_object_per_part() {
    let p = params(100_000, 8);
    let plan = Plan::new(&p);
    let mut parts = 0;
    for c in 0..plan.cabinets {
        parts += cabinet_parts(&plan, c, plan.structure_level).len();
        parts += plan.cabinet_boards(c).map(|b| Board::new(&plan, b).parts.len()).sum::<usize>();
    }
    let r = record(p);
    assert_eq!(r.objects.len(), parts);
    assert_eq!(r.colors, parts);
    let designator = |s: &str| {
        let digits = s.trim_start_matches(|c: char| c.is_ascii_uppercase());
        digits.len() < s.len() && !digits.is_empty() && digits.chars().all(|c| c.is_ascii_digit())
    };
    assert!(r.objects.iter().all(|o| designator(&o.0)), "{:?}", r.objects.iter().find(|o| !designator(&o.0)));
    for name in ["PCB1", "R1", "C1", "U1", "J1", "S1", "W1"] {
        assert!(r.objects.iter().any(|o| o.0 == name), "no {name}");
    }
}

#[test]
fn most_parts_are_tiny_some_are_medium_and_there_are_tens_of_thousands() {
    let r = record(params(1_000_000, 11));
    let mut sizes: Vec<u64> = r.objects.iter().map(|o| o.1).collect();
    sizes.sort_unstable();
    let median = sizes[sizes.len() / 2];
    assert!(median < 500, "median part {median} triangles");
    assert!(sizes.len() > 10_000, "{} parts", sizes.len());
    let medium = sizes.iter().filter(|&&n| (1_000..=5_000).contains(&n)).count();
    assert!(medium > 50, "{medium} parts of 1k-5k triangles");
    let largest = *sizes.last().unwrap();
    assert!((largest as f64) < 0.01 * r.triangles as f64, "largest part {largest}");
    let twelve = sizes.iter().filter(|&&n| n == 12).count();
    assert!(twelve > sizes.len() / 5, "{twelve} parts of 12 triangles");
    // Millimetre parts: most are 0.5–20 mm across.
    let mut extents: Vec<f64> =
        r.objects.iter().map(|o| o.2.extent().into_iter().fold(0.0, f64::max)).collect();
    extents.sort_by(f64::total_cmp);
    let med = extents[extents.len() / 2];
    assert!((0.5..20.0).contains(&med), "median part {med} mm");
}

#[test]
fn no_degenerate_triangles_and_inside_the_bounds() {
    let p = params(1_000_000, 5);
    let mut stats = SceneStats::default();
    let summary =
        Scene::from_sources(vec![Box::new(AssemblySource::new(p).unwrap())]).stream(&mut stats).unwrap();
    assert_eq!(summary.degenerate, 0);
    assert_eq!(summary.triangles, 1_000_000);
    let bounds = assembly_bounds(&p);
    for i in 0..3 {
        assert!(
            stats.bounds.min[i] >= bounds.min[i] && stats.bounds.max[i] <= bounds.max[i],
            "{stats:?} {bounds:?}"
        );
    }
}

#[test]
fn the_scene_grows_with_n_from_one_cabinet_to_metres() {
    let extent = |n: u64| assembly_bounds(&params(n, 1)).extent();
    let small = extent(10_000);
    assert!(small[0] <= 600.0 && small[1] <= 1400.0, "{small:?}");
    let mid = extent(10_000_000);
    assert!(mid[1] >= 500.0 && mid[1] <= 5000.0, "{mid:?}");
    let big = extent(MAX_ASSEMBLY_TRIANGLES);
    assert!(big[0] >= 3000.0 && big[1] <= 15_000.0, "{big:?}");
    let plan = Plan::new(&params(10_000_000, 1));
    assert!(plan.boards > 100, "{plan:?}");
    let plan = Plan::new(&params(MAX_ASSEMBLY_TRIANGLES, 1));
    assert!(plan.cabinets > 20, "{plan:?}");
}

#[test]
fn generation_streams_in_small_pieces_at_any_size() {
    // The plan and every board or cabinet layout are small whatever N is: nothing holds the
    // whole assembly. Chunks handed to the sink are bounded too.
    for n in [10_000_000, MAX_ASSEMBLY_TRIANGLES] {
        let plan = Plan::new(&params(n, 1));
        assert!(plan.structure_level <= MAX_STRUCTURE);
        let cabinet = cabinet_parts(&plan, 0, plan.structure_level);
        assert!(cabinet.len() < 5_000, "{} cabinet parts", cabinet.len());
        for b in [0, plan.boards - 1] {
            let board = Board::new(&plan, b);
            assert!(board.parts.len() < 10_000, "N {n} board {b}: {} parts", board.parts.len());
            assert_eq!(board.parts.len(), board.planned + 1, "N {n} board {b}: parts left out");
            if n == MAX_ASSEMBLY_TRIANGLES {
                assert!(board.level > 0, "N {n} board {b}: level 0");
            }
        }
        assert!(plan.boards as u64 <= plan.cabinets as u64 * BOARDS_PER_CABINET as u64);
    }
    let r = record(one(1_000_000, 2));
    assert!(r.largest_chunk <= 1 << 15, "{}", r.largest_chunk);
}

/// Generation speed into a counting sink, for the record (run in release):
/// `cargo test -p tw-io --release generate::assembly::tests::speed -- --ignored --nocapture`
#[test]
#[ignore]
fn speed_and_shape_report() {
    use crate::generate::Count;
    for n in [10_000u64, 1_000_000, 10_000_000, 100_000_000, 1_000_000_000] {
        let plan = Plan::new(&params(n, 1));
        let board = Board::new(&plan, 0);
        let mut c = Count::default();
        let t = std::time::Instant::now();
        Box::new(AssemblySource::new(params(n, 1)).unwrap()).stream(&mut c).unwrap();
        let s = t.elapsed().as_secs_f64();
        println!(
            "N = {n}: {} triangles, {} parts, {} boards, {} cabinets, structure level {} ({} triangles), \
             board 0: budget {}, level {}, {} of {} parts; full board at levels 0/1/8/16/24: {:?}; {:?} mm; \
             {s:.2} s, {:.1} M triangles/s",
            c.0,
            c.1,
            plan.boards,
            plan.cabinets,
            plan.structure_level,
            plan.structure,
            plan.board_budget(0),
            board.level,
            board.parts.len() - 1,
            board.planned,
            [0, 1, 8, 16, 24].map(|l| count(
                &board.parts.iter().map(|p| p.0.clone()).collect::<Vec<_>>(),
                &Detail::new(l)
            )),
            assembly_bounds(&params(n, 1)).extent(),
            c.0 as f64 / s / 1e6
        );
        assert_eq!(c.0, n);
        if n <= 10_000_000 {
            let r = record(params(n, 1));
            let mut sizes: Vec<u64> = r.objects.iter().map(|o| o.1).collect();
            sizes.sort_unstable();
            let at = |q: f64| sizes[((sizes.len() - 1) as f64 * q) as usize];
            let share = |lo: u64, hi: u64| {
                sizes.iter().filter(|&&t| (lo..hi).contains(&t)).count() as f64 / sizes.len() as f64
            };
            println!(
                "    part triangles: p10 {} p50 {} p75 {} p90 {} p99 {} max {}; <50: {:.0} %, 50-500: {:.0} %, \
                 500-1k: {:.1} %, 1k-5k: {:.1} %, >5k: {:.2} %",
                at(0.1),
                at(0.5),
                at(0.75),
                at(0.9),
                at(0.99),
                sizes[sizes.len() - 1],
                100.0 * share(0, 50),
                100.0 * share(50, 500),
                100.0 * share(500, 1000),
                100.0 * share(1000, 5000),
                100.0 * share(5000, u64::MAX)
            );
        }
    }
}
