//! CULLIDE, S-CULLIDE and FAR (Govindaraju 2004 thesis, ch. 5): the potentially colliding set
//! (PCS) computed with full-visibility queries on the GPU (`tw_gpu::visibility`), then
//! sweep-and-prune and exact triangle tests on the CPU.
//!
//! Lemma 1 of the thesis: an element fully visible against a set of others (strictly in front of
//! them at every pixel it covers, in some orthographic view) does not collide with them. The
//! two-pass test draws the elements in order 1..n, querying each before writing its depth (pass
//! 1: each against those before it), then in reverse order (pass 2: against those after it); an
//! element fully visible in both passes collides with nothing and leaves the PCS. This runs in
//! orthographic views along x, y and z, repeated while elements leave (at most
//! [`Options::iterations`] rounds), at each granularity ([`Granularity`]): the objects' boxes,
//! then groups of adjacent triangles ([`Options::groups`]: k, then single triangles). Objects
//! and groups are drawn and queried as their bounding boxes (the thesis' "boxes first"):
//! containing what they stand for, boxes keep the test conservative and cost 12 triangles
//! however many they hold; single triangles are drawn as themselves (CULLIDE) or fattened
//! (FAR). Within one object all elements are queried first and then all drawn, so an object
//! never blocks itself. The surviving triangles' boxes go through sweep-and-prune
//! ([`crate::sap`]) and the pairs through the exact test ([`crate::reference::exact_pairs`]).
//!
//! - [`Method::Cullide`]: the triangles as they are. It can miss collisions: a triangle seen
//!   edge-on covers no pixel centre, contacts fall between samples, depths round.
//! - [`Method::Far`]: every triangle replaced by its fattened oriented box ([`crate::fatten`],
//!   p = max(2dX, 2dY, 2dZ) from the scene's extent and the resolution), objects' boxes grown by
//!   the same radius: nothing is missed at any resolution (Theorem 1), at the cost of fill.
//! - Self-collision (objects with [`crate::Object::self_collide`]): under `Cullide`, S-CULLIDE —
//!   every triangle of the object is an element of its own and the test is strict (`Greater`),
//!   so neighbours that only touch do not block each other. Fattened neighbours always overlap
//!   (the thesis: FAR does not apply directly to self-collision), so under `Far` the
//!   self-collisions come from the exact BVH reference, which keeps FAR's result exact.
//! - [`Method::Reference`]: the CPU reference alone ([`crate::reference::all_pairs`]).

use std::time::Instant;

use glam::Mat4;
use tw_gpu::visibility::{DepthTest, Faces, VisOp, Visibility};

use crate::fatten::{oriented_box, BOX_TRIANGLES};
use crate::reference::{all_pairs_within, exact_pairs};
use crate::sap::overlapping_pairs;
use crate::{Aabb, Object, Pair, TriRef};

/// How the colliding pairs are found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    Reference,
    Cullide,
    Far,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Reference => "reference",
            Method::Cullide => "cullide",
            Method::Far => "far",
        }
    }
}

/// The settings of a [`Collider`].
#[derive(Clone, Debug)]
pub struct Options {
    pub method: Method,
    /// The side of the square viewport of the queries, in pixels (at least 8).
    pub resolution: u32,
    /// The sub-object stages after the object boxes: triangles per sub-object (k, adjacent in
    /// the object's triangle order), from coarse to fine. The thesis' pipeline is `[k, 1]`: k
    /// triangles, then single triangles. Ending at a k > 1 hands whole groups to
    /// sweep-and-prune, trading queries for exact tests.
    pub groups: Vec<usize>,
    /// Rounds of the x, y, z views per granularity at most (the thesis: about 2 to stabilise).
    pub iterations: usize,
    /// Report the pairs within this distance instead of the overlapping ones (FAR's
    /// within-distance variant: everything fattened by a further D/2; `Far` and `Reference`).
    pub within: f32,
    /// Run a pass's queries in batches of a few draws where the device allows it
    /// (`tw_gpu::visibility`; the same answers), instead of one occlusion query a draw.
    pub batched: bool,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            method: Method::Far,
            resolution: 512,
            groups: vec![32, 1],
            iterations: 2,
            within: 0.0,
            batched: true,
        }
    }
}

/// Errors of the collision pipeline.
#[derive(Debug, thiserror::Error)]
pub enum CollideError {
    #[error("collision queries: {0}")]
    Gpu(#[from] tw_gpu::GpuError),
    #[error("the query resolution {0} is too small: at least 8 pixels")]
    Resolution(u32),
    #[error("distance {0}: within-distance queries need a finite distance ≥ 0, and FAR or the reference")]
    Within(f32),
    #[error("{path}: {message}")]
    Model { path: String, message: String },
    #[error(transparent)]
    Import(#[from] tw_io::ImportError),
}

/// The elements at one granularity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Granularity {
    /// Each object's box.
    Boxes,
    /// Groups of this many triangles (1: single triangles).
    Groups(usize),
}

/// What one step found and cost.
#[derive(Clone, Debug, Default)]
pub struct StepStats {
    /// The colliding triangle pairs found, sorted.
    pub pairs: Vec<Pair>,
    /// Objects left in the PCS after the box stage, and triangles after each sub-object stage
    /// (the last: the triangles sweep-and-prune gets).
    pub pcs_objects: usize,
    pub pcs_stages: Vec<usize>,
    pub pcs_triangles: usize,
    /// Triangles left by S-CULLIDE (self-collision).
    pub pcs_self_triangles: usize,
    /// Pairs given to the exact test.
    pub candidates: usize,
    /// Occlusion queries issued.
    pub queries: usize,
    /// Milliseconds in the GPU passes (including building their geometry) and in the CPU stages.
    pub gpu_ms: f64,
    pub cpu_ms: f64,
    pub total_ms: f64,
}

/// Finds the colliding pairs of a scene, one step at a time.
pub struct Collider {
    options: Options,
    vis: Option<Visibility>,
}

/// Elements of one granularity: ranges of vertices, grouped by the unit that is queried then
/// drawn as a whole (an object, or a single triangle for S-CULLIDE).
struct Elements {
    vertices: Vec<[f32; 3]>,
    /// Vertex range and (object, triangles) of every element.
    ranges: Vec<std::ops::Range<u32>>,
    members: Vec<(u32, Vec<u32>)>,
    /// Element ranges of each unit, in drawing order.
    units: Vec<std::ops::Range<usize>>,
    alive: Vec<bool>,
}

impl Collider {
    /// A collider; `Cullide` and `Far` open the GPU (an error when there is none).
    pub fn new(options: Options) -> Result<Collider, CollideError> {
        if options.resolution < 8 {
            return Err(CollideError::Resolution(options.resolution));
        }
        let within = options.within;
        if !(within == 0.0 || within > 0.0 && within.is_finite() && options.method != Method::Cullide) {
            return Err(CollideError::Within(within));
        }
        let vis = match options.method {
            Method::Reference => None,
            _ => {
                let mut vis = Visibility::new_headless(options.resolution)?;
                vis.set_batched(options.batched);
                Some(vis)
            }
        };
        Ok(Collider { options, vis })
    }

    pub fn options(&self) -> &Options {
        &self.options
    }

    /// The GPU adapter's name, when one is used.
    pub fn adapter(&self) -> Option<String> {
        self.vis.as_ref().map(|v| format!("{} ({:?})", v.adapter().name, v.adapter().backend))
    }

    /// Whether the queries run in batches (`Some(false)`: one occlusion query a draw; `None`:
    /// no GPU).
    pub fn batched(&self) -> Option<bool> {
        self.vis.as_ref().map(Visibility::batched)
    }

    /// The colliding pairs of `objects` in this step. Objects with a vertex index out of range
    /// or a position that is not finite are refused.
    pub fn step(&mut self, objects: &[Object]) -> Result<StepStats, CollideError> {
        check(objects)?;
        let start = Instant::now();
        let mut stats = StepStats::default();
        match self.options.method {
            Method::Reference => stats.pairs = all_pairs_within(objects, self.options.within),
            Method::Cullide | Method::Far => self.cull(objects, &mut stats)?,
        }
        stats.total_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(stats)
    }

    fn cull(&mut self, objects: &[Object], stats: &mut StepStats) -> Result<(), CollideError> {
        let far = self.options.method == Method::Far;
        let bounds = objects.iter().map(Object::bounds).fold(Aabb::EMPTY, |a, b| a.union(&b));
        if objects.is_empty() || bounds.lo[0] > bounds.hi[0] {
            return Ok(());
        }
        let within = self.options.within;
        let views = Views::new(&bounds, self.options.resolution, far, within);
        let gpu_start = Instant::now();
        // Between objects: boxes, then sub-objects, then triangles.
        let mut live: Vec<u32> = (0..objects.len() as u32).collect();
        let mut triangles: Vec<(u32, Vec<u32>)> = Vec::new();
        if objects.len() > 1 {
            let boxes = self.prune(objects, &views, Granularity::Boxes, &whole(objects, &live), stats)?;
            live = partnered(objects, &boxes, views.radius);
            stats.pcs_objects = live.len();
            triangles = whole(objects, &live);
            for k in self.options.groups.clone() {
                triangles = self.prune(objects, &views, Granularity::Groups(k), &triangles, stats)?;
                stats.pcs_stages.push(triangles.iter().map(|(_, t)| t.len()).sum());
            }
        }
        // Within self-colliding objects: S-CULLIDE (CULLIDE) or nothing to cull (FAR).
        let mut self_sets: Vec<(u32, Vec<u32>)> = Vec::new();
        for (i, o) in objects.iter().enumerate().filter(|(_, o)| o.self_collide) {
            if !far {
                let all = vec![(i as u32, (0..o.triangles.len() as u32).collect::<Vec<u32>>())];
                let left = self.prune_self(objects, &views, &all, stats)?;
                stats.pcs_self_triangles += left.iter().map(|(_, t)| t.len()).sum::<usize>();
                self_sets.extend(left);
            }
        }
        stats.gpu_ms = gpu_start.elapsed().as_secs_f64() * 1e3;
        let cpu_start = Instant::now();
        stats.pcs_triangles = triangles.iter().map(|(_, t)| t.len()).sum();
        let mut candidates = candidate_pairs(objects, &triangles, false, within);
        candidates.extend(candidate_pairs(objects, &self_sets, true, within));
        stats.candidates = candidates.len();
        let mut pairs = exact_pairs(objects, &candidates, within);
        if far {
            pairs.extend(self_pairs_exactly(objects, within));
            pairs.sort_unstable();
        }
        stats.pairs = pairs;
        stats.cpu_ms = cpu_start.elapsed().as_secs_f64() * 1e3;
        Ok(())
    }

    /// The elements of `sets` (object, triangles) at `level` that stay in the PCS, as the
    /// (object, triangles) they cover.
    fn prune(
        &mut self,
        objects: &[Object],
        views: &Views,
        level: Granularity,
        sets: &[(u32, Vec<u32>)],
        stats: &mut StepStats,
    ) -> Result<Vec<(u32, Vec<u32>)>, CollideError> {
        let far = self.options.method == Method::Far;
        let mut el = Elements::new(objects, sets, level, far.then_some(views.radius));
        // FAR's elements are closed boxes wound outward (and the views keep orientation): the
        // queries need only their far faces, the draws their near ones.
        let faces = if far { Faces::Split } else { Faces::Both };
        self.passes(&mut el, views, DepthTest::Inclusive, faces, stats)?;
        Ok(el.survivors())
    }

    /// S-CULLIDE: every triangle its own unit, strict test.
    fn prune_self(
        &mut self,
        objects: &[Object],
        views: &Views,
        sets: &[(u32, Vec<u32>)],
        stats: &mut StepStats,
    ) -> Result<Vec<(u32, Vec<u32>)>, CollideError> {
        let mut el = Elements::new(objects, sets, Granularity::Groups(1), None);
        el.units = (0..el.ranges.len()).map(|e| e..e + 1).collect();
        self.passes(&mut el, views, DepthTest::Strict, Faces::Both, stats)?;
        Ok(el.survivors())
    }

    /// The two-pass test along x, y and z, repeated while elements leave.
    fn passes(
        &mut self,
        el: &mut Elements,
        views: &Views,
        test: DepthTest,
        faces: Faces,
        stats: &mut StepStats,
    ) -> Result<(), CollideError> {
        let Some(vis) = self.vis.as_mut() else { return Ok(()) };
        vis.set_faces(faces);
        if el.units.len() < 2 {
            // One unit: nothing to collide with.
            el.alive.iter_mut().for_each(|a| *a = false);
            return Ok(());
        }
        vis.upload(&el.vertices);
        for _ in 0..self.options.iterations.max(1) {
            let mut changed = false;
            for view in &views.matrices {
                let query: Vec<bool> = el.alive.clone();
                let first = el.run(vis, *view, &query, false, test)?;
                let second = el.run(vis, *view, &first, true, test)?;
                stats.queries += first.iter().chain(&query).filter(|&&q| q).count();
                for (e, visible) in second.iter().enumerate() {
                    if *visible && el.alive[e] {
                        el.alive[e] = false;
                        changed = true;
                    }
                }
            }
            if !changed {
                break;
            }
        }
        Ok(())
    }
}

/// Refuses objects that index past their positions or hold positions that are not finite.
fn check(objects: &[Object]) -> Result<(), CollideError> {
    for (i, o) in objects.iter().enumerate() {
        let bad = |message: String| CollideError::Model { path: format!("object {i}"), message };
        if let Some(v) = o.positions.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(bad(format!("vertex {v} is not finite: {:?}", o.positions[v])));
        }
        let n = o.positions.len() as u32;
        if let Some(t) = o.triangles.iter().position(|t| t.iter().any(|&v| v >= n)) {
            return Err(bad(format!("triangle {t} {:?} indexes past its {n} vertices", o.triangles[t])));
        }
    }
    Ok(())
}

/// Every triangle of each object in `live`.
fn whole(objects: &[Object], live: &[u32]) -> Vec<(u32, Vec<u32>)> {
    live.iter().map(|&o| (o, (0..objects[o as usize].triangles.len() as u32).collect())).collect()
}

/// The objects among `sets` whose box (grown by `radius`) overlaps another's: an object with no
/// partner collides with nothing (sweep-and-prune at the object level).
fn partnered(objects: &[Object], sets: &[(u32, Vec<u32>)], radius: f32) -> Vec<u32> {
    let boxes: Vec<Aabb> = sets.iter().map(|(o, _)| objects[*o as usize].bounds().grow(radius)).collect();
    let mut has = vec![false; sets.len()];
    for (i, j) in overlapping_pairs(&boxes, |_, _| true) {
        has[i] = true;
        has[j] = true;
    }
    sets.iter().zip(has).filter(|(_, h)| *h).map(|((o, _), _)| *o).collect()
}

/// Pairs of triangles of `sets` whose boxes overlap: of different objects, or (`within`) of
/// the same object.
fn candidate_pairs(
    objects: &[Object],
    sets: &[(u32, Vec<u32>)],
    within: bool,
    distance: f32,
) -> Vec<(TriRef, TriRef)> {
    let refs: Vec<TriRef> =
        sets.iter().flat_map(|(o, ts)| ts.iter().map(move |&t| TriRef { object: *o, triangle: t })).collect();
    let boxes: Vec<Aabb> =
        refs.iter().map(|r| Aabb::of_triangle(&objects[r.object as usize].triangle(r.triangle))).collect();
    let boxes: Vec<Aabb> = boxes.iter().map(|b| b.grow(distance / 2.0)).collect();
    overlapping_pairs(&boxes, |i, j| (refs[i].object == refs[j].object) == within)
        .into_iter()
        .map(|(i, j)| (refs[i], refs[j]))
        .collect()
}

/// The self-collisions of every self-colliding object, by the exact reference.
fn self_pairs_exactly(objects: &[Object], distance: f32) -> Vec<Pair> {
    let mut out = Vec::new();
    for (i, o) in objects.iter().enumerate().filter(|(_, o)| o.self_collide) {
        let one = [o.clone()];
        out.extend(all_pairs_within(&one, distance).into_iter().map(|p| {
            let fix = |r: TriRef| TriRef { object: i as u32, triangle: r.triangle };
            Pair(fix(p.0), fix(p.1))
        }));
    }
    out
}

impl Elements {
    /// The elements of `sets` at `level`, each unit one object; with `fatten`, every triangle
    /// replaced by its oriented box grown by that radius and every object box grown by it.
    fn new(
        objects: &[Object],
        sets: &[(u32, Vec<u32>)],
        level: Granularity,
        fatten: Option<f32>,
    ) -> Elements {
        let mut el = Elements {
            vertices: Vec::new(),
            ranges: Vec::new(),
            members: Vec::new(),
            units: Vec::new(),
            alive: Vec::new(),
        };
        for (o, tris) in sets {
            let object = &objects[*o as usize];
            let first = el.ranges.len();
            let chunk = match level {
                Granularity::Boxes => tris.len().max(1),
                Granularity::Groups(k) => k.max(1),
            };
            for members in tris.chunks(chunk) {
                let start = el.vertices.len() as u32;
                if members.len() > 1 {
                    // A box holds the group (and, grown, its fattened triangles): a box fully
                    // visible against boxes means its contents are fully visible against their
                    // contents (Lemma 1 on supersets), at 12 triangles a group.
                    let b = members
                        .iter()
                        .fold(Aabb::EMPTY, |b, &t| b.union(&Aabb::of_triangle(&object.triangle(t))))
                        .grow(fatten.unwrap_or(0.0));
                    push_box(&mut el.vertices, &box_corners(&b));
                } else {
                    for &t in members {
                        let tri = object.triangle(t);
                        match fatten {
                            Some(r) => push_box(&mut el.vertices, &oriented_box(&tri, r)),
                            None => el.vertices.extend_from_slice(&tri),
                        }
                    }
                }
                el.ranges.push(start..el.vertices.len() as u32);
                el.members.push((*o, members.to_vec()));
            }
            el.units.push(first..el.ranges.len());
        }
        el.alive = vec![true; el.ranges.len()];
        el
    }

    /// One pass in unit order (`reverse`: backwards): for each unit, a query of each of its
    /// elements marked in `query`, then a draw of all its live elements. Returns, per element,
    /// whether it was queried and fully visible.
    fn run(
        &self,
        vis: &mut Visibility,
        view: Mat4,
        query: &[bool],
        reverse: bool,
        test: DepthTest,
    ) -> Result<Vec<bool>, CollideError> {
        let mut ops = Vec::new();
        let mut queried = Vec::new();
        let order: Box<dyn Iterator<Item = &std::ops::Range<usize>>> =
            if reverse { Box::new(self.units.iter().rev()) } else { Box::new(self.units.iter()) };
        for unit in order {
            for e in unit.clone().filter(|&e| self.alive[e] && query[e]) {
                ops.push(VisOp::Query(self.ranges[e].clone()));
                queried.push(e);
            }
            // Live elements of a unit are drawn in as few draws as their ranges allow.
            let mut draw: Option<std::ops::Range<u32>> = None;
            for e in unit.clone().filter(|&e| self.alive[e]) {
                let r = self.ranges[e].clone();
                draw = match draw {
                    Some(d) if d.end == r.start => Some(d.start..r.end),
                    Some(d) => {
                        ops.push(VisOp::Draw(d));
                        Some(r)
                    }
                    None => Some(r),
                };
            }
            ops.extend(draw.map(VisOp::Draw));
        }
        let results = vis.run(view, &ops, test)?;
        let mut visible = vec![false; self.ranges.len()];
        for (e, r) in queried.into_iter().zip(results) {
            visible[e] = r == 0;
        }
        Ok(visible)
    }

    /// The (object, triangles) of the live elements, grouped by object.
    fn survivors(&self) -> Vec<(u32, Vec<u32>)> {
        let mut out: Vec<(u32, Vec<u32>)> = Vec::new();
        for ((o, tris), _) in self.members.iter().zip(&self.alive).filter(|(_, alive)| **alive) {
            match out.last_mut() {
                Some((last, v)) if last == o => v.extend_from_slice(tris),
                _ => out.push((*o, tris.clone())),
            }
        }
        out
    }
}

fn box_corners(b: &Aabb) -> [[f32; 3]; 8] {
    std::array::from_fn(|c| {
        [
            if c & 1 != 0 { b.hi[0] } else { b.lo[0] },
            if c & 2 != 0 { b.hi[1] } else { b.lo[1] },
            if c & 4 != 0 { b.hi[2] } else { b.lo[2] },
        ]
    })
}

fn push_box(out: &mut Vec<[f32; 3]>, corners: &[[f32; 3]; 8]) {
    for t in BOX_TRIANGLES {
        out.extend(t.map(|c| corners[c]));
    }
}

/// The orthographic views along x, y and z over the scene's box, and FAR's fattening radius.
pub struct Views {
    pub matrices: [Mat4; 3],
    /// 0 for CULLIDE.
    pub radius: f32,
}

/// Depth is mapped into [DEPTH_MARGIN, 1 − DEPTH_MARGIN]: nothing touches the near plane or the
/// cleared far value.
const DEPTH_MARGIN: f32 = 1.0 / 1024.0;

impl Views {
    /// Views of `bounds` at `resolution`; with `fatten`, the FAR radius for its cells (from the
    /// box grown by the margin the fattened boxes need) and that margin.
    pub fn new(bounds: &Aabb, resolution: u32, fatten: bool, within: f32) -> Views {
        let ext = bounds.extent();
        let longest = ext[0].max(ext[1]).max(ext[2]).max(f32::MIN_POSITIVE);
        let res = resolution as f32;
        // FAR: p = max(2dX, 2dY, 2dZ) over all three views (every axis is a screen axis of two
        // of them; depth cells, 2^-24 of the extent, are far smaller), radius √3·p/2 plus the
        // bounds grown by twice the first radius, which holds for resolution ≥ 8.
        // The margin m must hold the corners of every fattened box, √3 × the radius from the
        // geometry, where the radius grows with the extent E + 2m the cells are taken from:
        // m ≥ √3 (√3 (E + 2m) / R + D/2), i.e. m ≥ (3E/R + √3 D/2) / (1 − 6/R), for R ≥ 8.
        let margin = if fatten {
            (3.0 * longest / res + 3f32.sqrt() * within / 2.0) / (1.0 - 6.0 / res) * 1.01
        } else {
            0.0
        } + longest * 1e-4;
        let grown = bounds.grow(margin);
        let gext = grown.extent().map(|e| e.max(longest * 1e-3));
        let radius =
            if fatten { fattening(gext[0].max(gext[1]).max(gext[2]), res) + within / 2.0 } else { 0.0 };
        let matrices = std::array::from_fn(|a| {
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            let mut rows = [[0.0f32; 4]; 4];
            rows[0][b] = 2.0 / gext[b];
            rows[0][3] = -1.0 - 2.0 * grown.lo[b] / gext[b];
            rows[1][c] = 2.0 / gext[c];
            rows[1][3] = -1.0 - 2.0 * grown.lo[c] / gext[c];
            let span = 1.0 - 2.0 * DEPTH_MARGIN;
            rows[2][a] = span / gext[a];
            rows[2][3] = DEPTH_MARGIN - span * grown.lo[a] / gext[a];
            rows[3][3] = 1.0;
            Mat4::from_cols_array_2d(&rows).transpose()
        });
        Views { matrices, radius }
    }
}

/// √3·p/2 with p = 2 × (extent / resolution).
fn fattening(extent: f32, resolution: f32) -> f32 {
    crate::fatten::radius([extent / resolution; 3], 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4;

    #[test]
    fn bad_objects_are_refused_with_their_position() {
        let mut c = Collider::new(Options { method: Method::Reference, ..Default::default() }).unwrap();
        let good =
            Object { positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], ..Default::default() };
        let mut past = good.clone();
        past.triangles = vec![[0, 1, 2], [0, 1, 3]];
        let e = c.step(&[good.clone(), past]).unwrap_err().to_string();
        assert!(e.contains("object 1") && e.contains("triangle 1"), "{e}");
        let mut nan = good.clone();
        nan.positions[2][1] = f32::NAN;
        let e = c.step(&[nan]).unwrap_err().to_string();
        assert!(e.contains("object 0") && e.contains("vertex 2"), "{e}");
        assert!(c.step(&[good]).unwrap().pairs.is_empty());
        assert!(Collider::new(Options { resolution: 4, ..Default::default() }).is_err());
    }

    #[test]
    fn views_map_the_box_inside_clip_space() {
        let b = Aabb { lo: [-1.0, 2.0, 10.0], hi: [3.0, 4.0, 11.0] };
        for (res, within) in [(8, 0.0), (64, 0.0), (8, 2.0), (512, 0.5)] {
            let v = Views::new(&b, res, true, within);
            assert!(v.radius > within / 2.0);
            // The farthest corner of a fattened box lies √3 radii from the geometry.
            for m in v.matrices {
                for c in box_corners(&b.grow(3f32.sqrt() * v.radius)) {
                    let p = m * Vec4::new(c[0], c[1], c[2], 1.0);
                    assert!(p.x.abs() <= 1.0 && p.y.abs() <= 1.0, "{res} {within} {p}");
                    assert!(p.z >= 0.0 && p.z <= 1.0, "{res} {within} {p}");
                }
            }
        }
        let v = Views::new(&b, 64, false, 0.0);
        assert_eq!(v.radius, 0.0);
        for m in v.matrices {
            for c in box_corners(&b) {
                let p = m * Vec4::new(c[0], c[1], c[2], 1.0);
                assert!(p.x.abs() < 1.0 && p.y.abs() < 1.0, "{p}");
                assert!(p.z > 0.0 && p.z < 1.0, "{p}");
            }
        }
    }
}
