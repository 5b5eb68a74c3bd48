//! The procedural power plant: a deterministic stand-in for the UNC Power Plant (12.7 M
//! triangles, ~1,200 objects, one pipe object of more than 6 M triangles next to 20-triangle
//! bolts) and the Double Eagle tanker (82 M triangles, 127 K objects), at any size from 10^4 to
//! 10^10 triangles.
//!
//! The models are hard for the same reasons the real ones are: objects of wildly different sizes
//! (2 cm bolts and anchor bolts of 36–94 triangles; one piping network of 22–26 % of all
//! triangles spanning the whole site; about one object per 250 triangles at 10^7 and per 700 at
//! 10^9), high depth complexity (closed multi-storey buildings with corridors, rooms, slabs and
//! grating floors above each other: from a corridor under 1 % of the objects are visible), and a
//! large extent with small details (a 320 m site at 10^7 triangles holding 1 cm features).
//!
//! # Layout
//!
//! The site is a grid of 80 × 80 m blocks (`plant::PITCH`), x east, y north, z up, metres, the
//! ground at z = 0. Each block holds, from south to north:
//! - a road with a **pipe rack**: steel portals every 6 m carrying the rack pipes, which line up
//!   with the next block's so that every row of blocks has pipes across the whole site;
//! - a **building** of 36–60 × 30–42 m on a 6 m structural grid, 2–5 storeys of 4.5 m: concrete
//!   exterior walls with a truck door, a corridor door and windows; a 3 m corridor along x with
//!   door-pierced walls and rooms on both sides, some split by partition walls; floors that are
//!   concrete slabs or steel gratings (bars every 3–30 cm); I-beam columns and floor beams, with
//!   base plates, anchor bolts and bolted connections at higher detail; switchback stairs at the
//!   corridor's west end with railings; a roof slab. The rooms are cut into 3 × 3 m slots; each
//!   holds, with a probability the budget sets, one piece of equipment (a vessel on legs, a pump
//!   skid, a heat exchanger, a hand valve on supports, electrical cabinets, a platform with
//!   grating, railing and ladder) plus, at high detail, a manifold of small valves. Nozzles carry
//!   flanges with a separate object per bolt;
//! - a **yard** with storage tanks (ladder, roof railing, roof nozzle); block 0 also has a 55 m
//!   chimney.
//!
//! One **piping network** object, emitted last, runs through everything (see `pipes.rs`): rack
//! pipes, headers from the rack into every storey's corridor ceiling, pipes up onto every storage
//! tank and a branch down to every piece of equipment with a nozzle; bent elbows at every corner.
//!
//! # How N maps to the plant
//!
//! 1. Blocks: `B = max(1, round(16 · (N / 10^7)^(2/3)))` on a near-square grid
//!    (`plant::SitePlan`): 1 block at 10^4–10^5, 3 at 10^6, 16 (a 320 m site) at 10^7, 74 at
//!    10^8, ~345 (a 1.5 km site) at 10^9. The extent grows as N^(1/3) and so does the density,
//!    since each block gets `N / B ∝ N^(1/3)` triangles.
//! 2. Each block gets `0.78 · N / B` triangles for its building, equipment and yard. The block
//!    layout (`plant::Layout::new`) first drops storeys while even the coarsest building would
//!    not leave room for equipment, then picks the highest detail level (0–48: cylinder sides
//!    6–48, dome rings, bolt sides, grating pitch, structural detail, then 0–27 small valves per
//!    slot) whose building plus expected equipment fits, then the fill probability of the slots,
//!    and places parts while they fit. Every part's exact triangle count is known before it is
//!    placed (a dry run), so a block never exceeds its budget.
//! 3. The piping network takes the rest, `N − (triangles of all blocks)`, spread evenly over the
//!    blocks; each block's share is met exactly by the tessellation of its pipes, extra rings on
//!    straight stretches and a blind end cap of the last few triangles. The total is therefore
//!    exactly N.
//!
//! # Streaming and determinism
//!
//! Generation keeps one block's layout (a few thousand part descriptions) and one mesh chunk in
//! memory, whatever N is: the blocks are generated one by one, then generated again (layout only)
//! for the piping pass. Every random choice comes from a [`tw_core::Rng`] stream of its own
//! (block, what, which), so the plant depends only on `(triangles, seed)`.

mod assembly;
mod parts;
mod pipes;
mod plant;
mod shapes;

#[cfg(test)]
mod preview;

/// A sink that counts triangles (`.0`) and objects (`.1`): the generators' speed reports.
#[cfg(test)]
#[derive(Default)]
pub(crate) struct Count(pub u64, pub u64);

#[cfg(test)]
impl TriangleSink for Count {
    fn object(&mut self, _: crate::ObjectId, _: &crate::ObjectInfo) -> Result<(), ImportError> {
        self.1 += 1;
        Ok(())
    }
    fn triangle(&mut self, _: &crate::Triangle) -> Result<(), ImportError> {
        self.0 += 1;
        Ok(())
    }
    fn mesh(&mut self, c: &crate::MeshChunk<'_>) -> Result<(), ImportError> {
        self.0 += c.indices.len() as u64 / 3;
        Ok(())
    }
}

use tw_core::{Aabb, Rng};

pub use assembly::{
    assembly_bounds, AssemblyObjects, AssemblyParams, AssemblySource, MAX_ASSEMBLY_TRIANGLES,
    MIN_ASSEMBLY_TRIANGLES,
};

use crate::{ImportError, SourceSummary, TriangleSink, TriangleSource};
use parts::color;
use plant::{Layout, SitePlan, BAY, PITCH, STACK_HEIGHT, STOREY, TAG_VIEW};
use shapes::Emitter;

/// The smallest plant [`PlantSource::new`] accepts.
pub const MIN_TRIANGLES: u64 = 10_000;
/// The largest plant [`PlantSource::new`] accepts.
pub const MAX_TRIANGLES: u64 = 10_000_000_000;

/// What to generate: the exact number of triangles and the seed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PlantParams {
    pub triangles: u64,
    pub seed: u64,
}

/// A [`TriangleSource`] that generates the plant as it streams.
#[derive(Clone, Debug)]
pub struct PlantSource {
    params: PlantParams,
}

impl PlantSource {
    /// Checks the parameters: `triangles` must be within
    /// [`MIN_TRIANGLES`]`..=`[`MAX_TRIANGLES`].
    pub fn new(params: PlantParams) -> Result<PlantSource, ImportError> {
        check_triangles("generated plant", params.triangles, MIN_TRIANGLES..=MAX_TRIANGLES)?;
        Ok(PlantSource { params })
    }

    pub fn params(&self) -> PlantParams {
        self.params
    }
}

impl TriangleSource for PlantSource {
    fn name(&self) -> String {
        format!("generated plant ({} triangles, seed {})", self.params.triangles, self.params.seed)
    }

    fn progress_total(&self) -> Option<u64> {
        Some(self.params.triangles)
    }

    /// Streams every block's building, equipment and yard, then the piping network (the last
    /// object), exactly `triangles` triangles in all, none of them degenerate.
    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        let site = SitePlan::new(&self.params);
        let mut e = Emitter::new(sink);
        for b in 0..site.blocks {
            let lay = Layout::new(&site, b);
            for item in &lay.items {
                item.emit(&mut e);
                if e.failed() {
                    return e.finish().map(|_| SourceSummary::default());
                }
            }
        }
        let mut left = site.triangles - e.triangles();
        e.begin("piping network", color::PIPE);
        for b in 0..site.blocks {
            let lay = Layout::new(&site, b);
            let (runs, fixed) = pipes::runs(&site, &lay);
            let share = left / (site.blocks - b) as u64;
            pipes::emit(&mut e, lay.shape.origin, &runs, fixed, share, site.pipe.sides, site.pipe.elbow);
            left -= share;
            if e.failed() {
                break;
            }
        }
        e.finish()?;
        debug_assert_eq!(e.triangles(), site.triangles);
        Ok(SourceSummary { objects: e.objects(), vertices: e.vertices(), bytes: 0 })
    }
}

/// A generator's size check: `triangles` within `range`, else an error naming the generator.
pub(crate) fn check_triangles(
    what: &str,
    triangles: u64,
    range: std::ops::RangeInclusive<u64>,
) -> Result<(), ImportError> {
    if range.contains(&triangles) {
        return Ok(());
    }
    let (min, max) = range.into_inner();
    Err(ImportError::unsupported(
        what,
        format!("{triangles} triangles requested; the generator makes {min} to {max}"),
    ))
}

/// The site's bounds, computed without generating: every generated triangle lies inside.
pub fn plant_bounds(params: &PlantParams) -> Aabb {
    let site = SitePlan::new(params);
    Aabb {
        min: [0.0, 0.0, -0.5],
        max: [site.cols as f64 * PITCH, site.rows as f64 * PITCH, STACK_HEIGHT + 2.0],
    }
}

/// `count` viewpoints inside buildings, as `(eye, target)` pairs: eyes 1.7 m above a floor in a
/// corridor, looking 10 m along it. Spread over the blocks (block `i mod B` for the i-th) and
/// deterministic for the parameters.
pub fn interior_viewpoints(params: &PlantParams, count: usize) -> Vec<([f64; 3], [f64; 3])> {
    let site = SitePlan::new(params);
    let mut out = Vec::with_capacity(count.min(1 << 16));
    let mut cached: Option<Layout> = None;
    for i in 0..count {
        let b = (i % site.blocks as usize) as u32;
        if cached.as_ref().is_none_or(|l| l.shape.block != b) {
            cached = Some(Layout::new(&site, b));
        }
        let Some(lay) = cached.as_ref() else { continue };
        let sh = &lay.shape;
        let mut rng = Rng::with_stream(site.seed, plant::stream(b as u64, TAG_VIEW, i as u64));
        let k = rng.range_u32(0, lay.storeys);
        // East of the stair bay, in the corridor's north half (clear of the stair lanes).
        let x = rng.range_f64(sh.bx + BAY + 1.0, sh.bx + sh.w - 2.0);
        let y = sh.yc() + 0.6;
        let z = k as f64 * STOREY + 1.7;
        let dir = if rng.chance(0.5) { 1.0 } else { -1.0 };
        out.push(([x, y, z], [x + 10.0 * dir, y, z]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{MeshChunk, ObjectId, ObjectInfo, Scene, SceneStats, Triangle};

    fn params(triangles: u64, seed: u64) -> PlantParams {
        PlantParams { triangles, seed }
    }

    /// Counts triangles per object and records names, colours, bounds and progress.
    #[derive(Default)]
    struct Record {
        triangles: u64,
        objects: Vec<(String, u64, Aabb)>,
        colors: usize,
        progress: Vec<u64>,
        hash: u64,
    }

    impl Record {
        fn mix(&mut self, v: u64) {
            self.hash = (self.hash ^ v).wrapping_mul(0x100_0000_01b3);
        }
    }

    impl TriangleSink for Record {
        fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
            assert_eq!(id as usize, self.objects.len(), "objects are numbered densely");
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
            self.mix(c.object as u64);
            for &i in c.indices {
                let p = c.positions[i as usize];
                for v in p {
                    self.mix(v.to_bits());
                }
                self.objects[c.object as usize].2.grow(p);
            }
            self.objects[c.object as usize].1 += n;
            Ok(())
        }
        fn progress(&mut self, done: u64) {
            self.progress.push(done);
        }
    }

    fn record(p: PlantParams) -> Record {
        let mut r = Record { hash: 0xcbf2_9ce4_8422_2325, ..Default::default() };
        let s = Box::new(PlantSource::new(p).unwrap()).stream(&mut r).unwrap();
        assert_eq!(s.objects as usize, r.objects.len());
        r
    }

    #[test]
    fn rejects_sizes_out_of_range() {
        assert!(PlantSource::new(params(9_999, 1)).is_err());
        assert!(PlantSource::new(params(MAX_TRIANGLES + 1, 1)).is_err());
        let e = PlantSource::new(params(0, 1)).unwrap_err();
        assert!(e.to_string().contains("0 triangles requested"), "{e}");
        assert!(PlantSource::new(params(MIN_TRIANGLES, 1)).is_ok());
        assert!(PlantSource::new(params(MAX_TRIANGLES, 1)).is_ok());
    }

    #[test]
    fn name_and_progress_total() {
        let s = PlantSource::new(params(123_456, 9)).unwrap();
        assert_eq!(s.name(), "generated plant (123456 triangles, seed 9)");
        assert_eq!(s.progress_total(), Some(123_456));
    }

    #[test]
    fn triangle_count_is_exact() {
        for n in [10_000, 10_001, 100_000, 1_000_000, 3_000_000] {
            let r = record(params(n, 3));
            assert_eq!(r.triangles, n, "N = {n}");
        }
    }

    #[test]
    fn every_object_has_triangles() {
        // An object announced without geometry would be lost by formats that name objects only
        // where their faces are (OBJ), and is noise everywhere else.
        for n in [10_000, 20_000, 100_000, 1_000_000] {
            let r = record(params(n, 1));
            let empty = r.objects.iter().filter(|o| o.1 == 0).count();
            assert_eq!(empty, 0, "N = {n}: {empty} of {} objects are empty", r.objects.len());
        }
    }

    #[test]
    fn same_seed_same_plant_different_seed_different_plant() {
        let a = record(params(100_000, 1));
        let b = record(params(100_000, 1));
        let c = record(params(100_000, 2));
        assert_eq!(a.hash, b.hash);
        assert_eq!(a.objects.len(), b.objects.len());
        assert_ne!(a.hash, c.hash);
    }

    #[test]
    fn no_degenerate_triangles_through_a_scene() {
        let src = PlantSource::new(params(1_000_000, 5)).unwrap();
        let mut stats = SceneStats::default();
        let summary = Scene::from_sources(vec![Box::new(src)]).stream(&mut stats).unwrap();
        assert_eq!(summary.degenerate, 0);
        assert_eq!(summary.triangles, 1_000_000);
        assert_eq!(stats.triangles, 1_000_000);
        let bounds = plant_bounds(&params(1_000_000, 5));
        for i in 0..3 {
            assert!(
                stats.bounds.min[i] >= bounds.min[i] && stats.bounds.max[i] <= bounds.max[i],
                "{stats:?}"
            );
        }
    }

    #[test]
    fn object_sizes_span_five_orders_of_magnitude() {
        let r = record(params(1_000_000, 11));
        let n = r.triangles as f64;
        let smallest = r.objects.iter().map(|o| o.1).min().unwrap();
        assert!(smallest < 100, "{smallest}");
        let (name, pipe, _) = r.objects.last().unwrap();
        assert_eq!(name, "piping network");
        let share = *pipe as f64 / n;
        assert!((0.15..0.35).contains(&share), "pipe share {share}");
        let bolts = r.objects.iter().filter(|o| o.0 == "bolt").count();
        assert!(bolts > 100, "{bolts} bolts");
        assert_eq!(r.colors, r.objects.len());
        assert!(r.objects.iter().all(|o| o.1 > 0), "every object has triangles");
    }

    #[test]
    fn bolts_are_one_to_three_centimetres() {
        let r = record(params(300_000, 4));
        let mut seen = 0;
        for (name, n, b) in r.objects.iter().filter(|o| o.0.contains("bolt")) {
            let size = b.extent().into_iter().fold(0.0, f64::max);
            assert!((0.01..=0.03).contains(&size), "{name}: {size} m");
            assert!((20..=100).contains(n), "{name}: {n} triangles");
            seen += 1;
        }
        assert!(seen > 0);
    }

    #[test]
    fn more_triangles_more_objects_and_a_larger_site() {
        let small = record(params(100_000, 1));
        let large = record(params(3_000_000, 1));
        assert!(
            large.objects.len() > 3 * small.objects.len(),
            "{} vs {}",
            large.objects.len(),
            small.objects.len()
        );
        let (a, b) = (plant_bounds(&params(100_000, 1)), plant_bounds(&params(3_000_000, 1)));
        assert!(b.extent()[0] > a.extent()[0]);
        assert!(plant_bounds(&params(1_000_000_000, 1)).extent()[0] >= 1000.0);
    }

    #[test]
    fn progress_is_reported_about_every_100k_triangles() {
        let r = record(params(1_000_000, 1));
        assert!(r.progress.len() >= 8, "{:?}", r.progress);
        assert!(r.progress.windows(2).all(|w| w[0] < w[1] && w[1] - w[0] < 250_000), "{:?}", r.progress);
        assert!(*r.progress.last().unwrap() <= 1_000_000);
    }

    #[test]
    fn huge_plants_have_small_block_plans_that_use_their_budget() {
        for n in [1_000_000_000, MAX_TRIANGLES] {
            let site = SitePlan::new(&params(n, 1));
            for b in [0, site.blocks / 2, site.blocks - 1] {
                let lay = Layout::new(&site, b);
                assert!(lay.items.len() < 5_000, "{} items", lay.items.len());
                let budget = site.block_budget(b) as f64;
                assert!(
                    lay.triangles as f64 > 0.8 * budget,
                    "N {n} block {b}: {} of {budget}",
                    lay.triangles
                );
                assert!(lay.triangles as f64 <= budget);
                assert!(lay.detail.level > 20, "level {}", lay.detail.level);
            }
        }
    }

    #[test]
    fn viewpoints_are_in_corridors_at_eye_height() {
        let p = params(3_000_000, 8);
        let site = SitePlan::new(&p);
        let views = interior_viewpoints(&p, 20);
        assert_eq!(views.len(), 20);
        assert_eq!(views, interior_viewpoints(&p, 20));
        for (i, (eye, target)) in views.iter().enumerate() {
            let lay = Layout::new(&site, (i % site.blocks as usize) as u32);
            let sh = &lay.shape;
            assert!(eye[0] > sh.bx + BAY && eye[0] < sh.bx + sh.w, "{eye:?}");
            assert!((eye[1] - sh.yc()).abs() < plant::CORRIDOR);
            let floor = eye[2] - 1.7;
            assert!((floor / STOREY - (floor / STOREY).round()).abs() < 1e-9);
            assert!(floor / STOREY < lay.storeys as f64);
            assert_eq!(eye[2], target[2]);
            assert!((target[0] - eye[0]).abs() == 10.0);
        }
    }

    /// Generation speed into a counting sink, for the record (run in release):
    /// `cargo test -p tw-io --release generate::tests::speed -- --ignored --nocapture`
    /// (also streams 10^8 triangles through a [`Scene`] and checks that none is degenerate).
    #[test]
    #[ignore]
    fn speed_100m_triangles() {
        for n in [10_000_000u64, 100_000_000, 1_000_000_000] {
            let mut c = Count::default();
            let t = std::time::Instant::now();
            Box::new(PlantSource::new(params(n, 1)).unwrap()).stream(&mut c).unwrap();
            let s = t.elapsed().as_secs_f64();
            println!(
                "N = {n}: {} triangles, {} objects, {s:.2} s, {:.1} M triangles/s",
                c.0,
                c.1,
                c.0 as f64 / s / 1e6
            );
            assert_eq!(c.0, n);
        }
        let src = PlantSource::new(params(100_000_000, 2)).unwrap();
        let mut stats = SceneStats::default();
        let summary = Scene::from_sources(vec![Box::new(src)]).stream(&mut stats).unwrap();
        println!("through a Scene: {summary:?}, bounds {:?}", stats.bounds);
        assert_eq!(summary.degenerate, 0);
        assert_eq!(summary.triangles, 100_000_000);
    }
}

/// Diagnostics: per-N counts, object kinds and shares.
/// `cargo test -p tw-io --release generate::report -- --ignored --nocapture`
#[cfg(test)]
mod report {
    use super::*;
    use crate::{MeshChunk, ObjectId, ObjectInfo, Triangle};

    #[derive(Default)]
    struct Per(Vec<(String, u64)>, u64);
    impl TriangleSink for Per {
        fn object(&mut self, _: ObjectId, i: &ObjectInfo) -> Result<(), ImportError> {
            self.0.push((i.name.clone(), 0));
            Ok(())
        }
        fn triangle(&mut self, _: &Triangle) -> Result<(), ImportError> {
            Ok(())
        }
        fn mesh(&mut self, c: &MeshChunk<'_>) -> Result<(), ImportError> {
            let n = c.indices.len() as u64 / 3;
            self.0[c.object as usize].1 += n;
            self.1 += n;
            Ok(())
        }
    }

    #[test]
    #[ignore]
    fn print_report() {
        for n in [10_000u64, 100_000, 1_000_000, 3_000_000, 10_000_000] {
            let p = PlantParams { triangles: n, seed: 1 };
            let site = SitePlan::new(&p);
            let lay = Layout::new(&site, 0);
            let mut s = Per::default();
            Box::new(PlantSource::new(p).unwrap()).stream(&mut s).unwrap();
            let largest = s.0.iter().map(|o| o.1).max().unwrap();
            let smallest = s.0.iter().map(|o| o.1).min().unwrap();
            let mut kinds: std::collections::BTreeMap<String, (u64, u64)> = Default::default();
            for (name, t) in &s.0 {
                let e = kinds.entry(name.clone()).or_default();
                e.0 += 1;
                e.1 += t;
            }
            println!(
                "N={n} tris={} blocks={} level0={} storeys0={}/{} objects={} largest={:.1}% smallest={} pipe={:?} extent={:?}",
                s.1,
                site.blocks,
                lay.detail.level,
                lay.storeys,
                lay.shape.storeys,
                s.0.len(),
                100.0 * largest as f64 / n as f64,
                smallest,
                site.pipe,
                plant_bounds(&p).extent()
            );
            for (k, (c, t)) in kinds {
                println!("    {k:20} {c:8} objects {:6.2}%", 100.0 * t as f64 / n as f64);
            }
        }
    }
}

/// A geodesic sphere: the icosahedron subdivided `subdivisions` times (each triangle into four,
/// midpoints pushed onto the sphere), `20 × 4^subdivisions` triangles, closed and manifold,
/// consistently wound outwards. Vertices are numbered in order of creation, so the mesh is the
/// same on every platform. The shared test geometry of the build and runtime tests.
pub fn icosphere(center: [f64; 3], radius: f64, subdivisions: u32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let norm = |p: [f64; 3]| {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        p.map(|x| x / l)
    };
    v.iter_mut().for_each(|p| *p = norm(*p));
    for _ in 0..subdivisions {
        let mut mid: std::collections::BTreeMap<(u32, u32), u32> = std::collections::BTreeMap::new();
        let mut nf = Vec::with_capacity(f.len() * 4);
        for tri in &f {
            let mut m = [0u32; 3];
            for e in 0..3 {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                m[e] = *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let (pa, pb) = (v[a as usize], v[b as usize]);
                    v.push(norm([(pa[0] + pb[0]) / 2.0, (pa[1] + pb[1]) / 2.0, (pa[2] + pb[2]) / 2.0]));
                    v.len() as u32 - 1
                });
            }
            nf.push([tri[0], m[0], m[2]]);
            nf.push([tri[1], m[1], m[0]]);
            nf.push([tri[2], m[2], m[1]]);
            nf.push(m);
        }
        f = nf;
    }
    let positions = v.iter().map(|p| std::array::from_fn(|i| center[i] + p[i] * radius)).collect();
    (positions, f)
}
