//! The thesis' collision scenes (Govindaraju 2004, ch. 5, the results section) with generated
//! motion: a [`Scene`] yields every step's deformed geometry ([`Scene::step`]), deterministic from
//! the step number.
//!
//! - `cylinders`: 100 deforming open cylinders × 200 triangles (the thesis' Env 1): a 10 × 10
//!   grid, leaning, swaying and breathing.
//! - `tori`: 6 tori × 20 K triangles (Env 2): a chain of interlocked tori, sliding and wobbling.
//! - `breaking`: the bunny falls through the dragon, creating pieces (Env 3 and the breaking
//!   scene): the dragon cut into up to 27 pieces that fly apart as the bunny passes.
//! - `cloth`: a cloth of 20 K triangles on a sphere (S-CULLIDE's scene): a 101 × 101 grid
//!   draped over a sphere, its skirt folding into loops through itself.
//! - `bunnies`: two interpenetrating bunnies (FAR's accuracy scene), passing through each other.
//!
//! `scale` (0 < scale ≤ 1) shrinks the triangle counts for tests. The dragon
//! (`data/dragon_vrip.ply.gz`) and the bunny (`data/bunny.obj`, 3,674 triangles) are read with
//! `tw-io` (scripts/fetch-data.sh fetches them); the dragon is reduced by vertex clustering to
//! the scene's size, the bunny refined by midpoint subdivision towards it.

use std::collections::HashMap;
use std::f32::consts::TAU;
use std::path::{Path, PathBuf};

use crate::cullide::CollideError;
use crate::{Aabb, Object};

/// Which scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneKind {
    Cylinders,
    Tori,
    Breaking,
    Cloth,
    Bunnies,
}

impl SceneKind {
    pub const ALL: [SceneKind; 5] =
        [SceneKind::Cylinders, SceneKind::Tori, SceneKind::Breaking, SceneKind::Cloth, SceneKind::Bunnies];

    pub fn name(self) -> &'static str {
        match self {
            SceneKind::Cylinders => "cylinders",
            SceneKind::Tori => "tori",
            SceneKind::Breaking => "breaking",
            SceneKind::Cloth => "cloth",
            SceneKind::Bunnies => "bunnies",
        }
    }

    pub fn from_name(name: &str) -> Option<SceneKind> {
        SceneKind::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// How a scene is made.
#[derive(Clone, Debug)]
pub struct SceneOptions {
    /// Triangle counts relative to the thesis' (0 < scale ≤ 1).
    pub scale: f32,
    /// Where `dragon_vrip.ply.gz` and `bunny.obj` are.
    pub data_dir: PathBuf,
}

impl Default for SceneOptions {
    fn default() -> SceneOptions {
        SceneOptions { scale: 1.0, data_dir: PathBuf::from("data") }
    }
}

/// A scene: its fixed meshes, moved and deformed per step.
pub struct Scene {
    kind: SceneKind,
    scale: f32,
    /// Meshes at rest: the scene's objects (cylinders and tori are made per step).
    rest: Vec<Object>,
}

/// The thesis' sizes.
const DRAGON_TRIANGLES: f32 = 250_000.0;
const BUNNY_TRIANGLES: f32 = 35_000.0;
const BIG_BUNNY_TRIANGLES: f32 = 68_000.0;
/// Pieces per axis the dragon is cut into.
const PIECES: usize = 3;

impl Scene {
    pub fn new(kind: SceneKind, options: &SceneOptions) -> Result<Scene, CollideError> {
        if !(options.scale > 0.0 && options.scale <= 1.0) {
            return Err(CollideError::Model {
                path: "--scale".into(),
                message: format!("{} is not in (0, 1]", options.scale),
            });
        }
        let s = options.scale;
        let rest = match kind {
            SceneKind::Cylinders | SceneKind::Tori | SceneKind::Cloth => Vec::new(),
            SceneKind::Breaking => {
                let dragon = load(&options.data_dir.join("dragon_vrip.ply.gz"))?;
                let dragon = normalize(&cluster_to(&dragon, DRAGON_TRIANGLES * s), 2.0);
                let bunny = normalize(
                    &subdivide_to(load(&options.data_dir.join("bunny.obj"))?, BUNNY_TRIANGLES * s),
                    0.8,
                );
                let mut objects = vec![bunny];
                objects.extend(pieces(&dragon, PIECES));
                objects
            }
            SceneKind::Bunnies => {
                let bunny = normalize(
                    &subdivide_to(load(&options.data_dir.join("bunny.obj"))?, BIG_BUNNY_TRIANGLES * s),
                    1.0,
                );
                vec![bunny.clone(), bunny]
            }
        };
        Ok(Scene { kind, scale: s, rest })
    }

    pub fn kind(&self) -> SceneKind {
        self.kind
    }

    /// The objects at step `t`.
    pub fn step(&self, t: usize) -> Vec<Object> {
        let t = t as f32;
        match self.kind {
            SceneKind::Cylinders => cylinders(self.scale, t),
            SceneKind::Tori => tori(self.scale, t),
            SceneKind::Cloth => cloth(self.scale, t),
            SceneKind::Breaking => breaking(&self.rest, t),
            SceneKind::Bunnies => bunnies(&self.rest, t),
        }
    }
}

/// Random triangles for tests: `objects` objects of `triangles` triangles each (sides up to
/// `size`) in the unit cube, from `seed`. Object `k` keeps its triangles near a centre of its
/// own, so objects overlap some of their neighbours.
pub fn random_soup(objects: usize, triangles: usize, size: f32, seed: u64) -> Vec<Object> {
    let mut n = seed.wrapping_mul(1_000_003);
    let mut next = || {
        n += 1;
        hash01(n, seed)
    };
    (0..objects)
        .map(|_| {
            let centre = [next(), next(), next()];
            let mut o = Object::default();
            for t in 0..triangles as u32 {
                let a: [f32; 3] = std::array::from_fn(|i| centre[i] + (next() - 0.5) * 0.3);
                for _ in 0..3 {
                    o.positions.push(std::array::from_fn(|i| a[i] + (next() - 0.5) * size));
                }
                o.triangles.push([3 * t, 3 * t + 1, 3 * t + 2]);
            }
            o
        })
        .collect()
}

/// A deterministic value in [0, 1) for `(i, salt)` (splitmix64).
fn hash01(i: u64, salt: u64) -> f32 {
    let mut z = i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ salt.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 24) as f32
}

/// A grid mesh of `rows` × `cols` vertices from `f(row, col)`, closed around the columns when
/// `wrap_cols` (and the rows when `wrap_rows`).
fn grid(
    rows: usize,
    cols: usize,
    wrap_rows: bool,
    wrap_cols: bool,
    f: impl Fn(usize, usize) -> [f32; 3],
) -> Object {
    let mut positions = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            positions.push(f(r, c));
        }
    }
    let id = |r: usize, c: usize| ((r % rows) * cols + c % cols) as u32;
    let (rr, cc) = (if wrap_rows { rows } else { rows - 1 }, if wrap_cols { cols } else { cols - 1 });
    let mut triangles = Vec::with_capacity(rr * cc * 2);
    for r in 0..rr {
        for c in 0..cc {
            let (a, b, d, e) = (id(r, c), id(r, c + 1), id(r + 1, c), id(r + 1, c + 1));
            triangles.push([a, b, e]);
            triangles.push([a, e, d]);
        }
    }
    Object { positions, triangles, self_collide: false }
}

/// Open cylinders of 10 × 10 × 2 triangles on a grid 1 apart, radius 0.3 breathing by a
/// quarter, length 2, each leaning its own way (up to 0.6 rad) and swaying by 0.35 rad more:
/// neighbours touch now and then.
fn cylinders(scale: f32, t: f32) -> Vec<Object> {
    let n = ((100.0 * scale).round() as usize).max(4);
    let side = (n as f32).sqrt().ceil() as usize;
    (0..n)
        .map(|i| {
            let (gx, gy) = ((i % side) as f32, (i / side) as f32);
            let phase = hash01(i as u64, 1) * TAU;
            let dir = hash01(i as u64, 2) * TAU;
            let tilt = 0.6 * hash01(i as u64, 6) + 0.35 * (0.2 * t + phase).sin();
            let (ts, tc) = tilt.sin_cos();
            let (ds, dc) = dir.sin_cos();
            // The axis, and two unit vectors across it.
            let axis = [ts * dc, ts * ds, tc];
            let across = [tc * dc, tc * ds, -ts];
            let side_v = [-ds, dc, 0.0];
            grid(11, 10, false, true, |r, c| {
                let h = r as f32 / 10.0 * 2.0 - 1.0;
                let radius = 0.3 * (1.0 + 0.25 * (0.3 * t + 3.0 * h + phase).sin());
                let a = c as f32 / 10.0 * TAU;
                let (x, y) = (radius * a.cos(), radius * a.sin());
                [
                    gx + axis[0] * h + across[0] * x + side_v[0] * y,
                    gy + axis[1] * h + across[1] * x + side_v[1] * y,
                    axis[2] * h + across[2] * x + side_v[2] * y,
                ]
            })
        })
        .collect()
}

/// A chain of 6 tori (major radius 1, minor 0.25, 200 × 50 × 2 triangles at scale 1), links in
/// alternate planes 1.6 apart, sliding along the chain and wobbling.
fn tori(scale: f32, t: f32) -> Vec<Object> {
    let major = ((200.0 * scale.sqrt()).round() as usize).max(8);
    let minor = ((50.0 * scale.sqrt()).round() as usize).max(4);
    (0..6)
        .map(|i| {
            let phase = hash01(i as u64, 3) * TAU;
            let cx = i as f32 * 1.6 + 0.35 * (0.25 * t + phase).sin();
            let spin = 0.1 * t + phase;
            grid(major, minor, true, true, |r, c| {
                let u = r as f32 / major as f32 * TAU;
                let v = c as f32 / minor as f32 * TAU;
                let rr = 0.25 * (1.0 + 0.15 * (3.0 * u + 0.4 * t).sin());
                let (x, y, z) =
                    ((1.0 + rr * v.cos()) * u.cos(), (1.0 + rr * v.cos()) * u.sin(), rr * v.sin());
                // Even links lie in the xy plane, odd ones in xz; all turn about the chain (x).
                let (y, z) = if i % 2 == 0 { (y, z) } else { (z, y) };
                let (s, k) = spin.sin_cos();
                [cx + x, y * k - z * s, y * s + z * k]
            })
        })
        .collect()
}

/// A cloth of 101 × 101 vertices (at scale 1) over a unit sphere: the part over the sphere
/// rests on it (dipping in and out by 0.02), the skirt hangs in loops (a prolate trochoid that
/// grows over the first 20 steps), which fold the cloth through itself.
fn cloth(scale: f32, t: f32) -> Vec<Object> {
    let n = ((101.0 * scale.sqrt()).round() as usize).max(8);
    let half = 1.6;
    let grow = (t / 20.0).min(1.0);
    let mut c = grid(n, n, false, false, |r, col| {
        let x = -half + 2.0 * half * col as f32 / (n - 1) as f32;
        let z = -half + 2.0 * half * r as f32 / (n - 1) as f32;
        let d = (x * x + z * z).sqrt();
        let rim = 0.95f32;
        if d <= rim {
            let dip = 0.02 * (5.0 * x + 0.2 * t).sin() * (5.0 * z).sin();
            let y = (1.0 - d * d).max(0.0).sqrt() + 0.01 + dip;
            [x, y, z]
        } else {
            let s = d - rim;
            let (b, w) = (0.08 * grow, 20.0);
            let y_rim = (1.0 - rim * rim).sqrt() + 0.01;
            let radial = rim + 0.25 * s + b * (w * s).sin() * 1.5;
            let y = y_rim - s - b * (w * s).cos() + b;
            [x / d * radial, y, z / d * radial]
        }
    });
    c.self_collide = true;
    let sphere = grid(40, 60, false, true, |r, col| {
        let th = r as f32 / 39.0 * std::f32::consts::PI;
        let ph = col as f32 / 60.0 * TAU;
        [th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()]
    });
    vec![c, sphere]
}

/// The bunny (object 0) falls through the dragon's pieces; a piece flies outward and down from
/// the moment the bunny's centre passes its top.
fn breaking(rest: &[Object], t: f32) -> Vec<Object> {
    let Some((bunny, pieces)) = rest.split_first() else { return Vec::new() };
    let dragon = pieces.iter().map(Object::bounds).fold(Aabb::EMPTY, |a, b| a.union(&b));
    let dc = dragon.center();
    let bb = bunny.bounds();
    let speed = 0.05;
    let drop = dragon.hi[1] + (bb.hi[1] - bb.lo[1]) * 0.5 - speed * t;
    let mut out = vec![moved(bunny, [dc[0], drop, dc[2]])];
    for (k, p) in pieces.iter().enumerate() {
        let pb = p.bounds();
        let pc = pb.center();
        let hit = (dragon.hi[1] + (bb.hi[1] - bb.lo[1]) * 0.5 - pb.hi[1]) / speed;
        let dt = (t - hit).max(0.0);
        let out_dir = [
            pc[0] - dc[0] + 0.1 * (hash01(k as u64, 4) - 0.5),
            pc[2] - dc[2] + 0.1 * (hash01(k as u64, 5) - 0.5),
        ];
        let len = (out_dir[0] * out_dir[0] + out_dir[1] * out_dir[1]).sqrt().max(1e-3);
        let v = 0.03;
        let off = [out_dir[0] / len * v * dt, -0.5 * 0.002 * dt * dt, out_dir[1] / len * v * dt];
        out.push(moved(p, [pc[0] + off[0], pc[1] + off[1], pc[2] + off[2]]));
    }
    out
}

/// Two bunnies passing through each other along x, the second turned a quarter about y.
fn bunnies(rest: &[Object], t: f32) -> Vec<Object> {
    let Some(bunny) = rest.first() else { return Vec::new() };
    let x = 0.6 - 0.02 * t;
    let turned =
        Object { positions: bunny.positions.iter().map(|p| [p[2], p[1], -p[0]]).collect(), ..bunny.clone() };
    vec![moved(bunny, [-0.2, 0.0, 0.0]), moved(&turned, [x, 0.05, 0.0])]
}

/// `o` with its box centred at `to`.
fn moved(o: &Object, to: [f32; 3]) -> Object {
    let c = o.bounds().center();
    Object {
        positions: o
            .positions
            .iter()
            .map(|p| [p[0] - c[0] + to[0], p[1] - c[1] + to[1], p[2] - c[2] + to[2]])
            .collect(),
        ..o.clone()
    }
}

/// `o` scaled so that its longest side is `size`, centred at the origin.
fn normalize(o: &Object, size: f32) -> Object {
    let b = o.bounds();
    let e = b.extent();
    let k = size / e[0].max(e[1]).max(e[2]).max(f32::MIN_POSITIVE);
    let c = b.center();
    Object {
        positions: o
            .positions
            .iter()
            .map(|p| [(p[0] - c[0]) * k, (p[1] - c[1]) * k, (p[2] - c[2]) * k])
            .collect(),
        ..o.clone()
    }
}

/// Reads a model with `tw-io` into one indexed mesh, welding equal positions.
pub fn load(path: &Path) -> Result<Object, CollideError> {
    if !path.is_file() {
        return Err(CollideError::Model {
            path: path.display().to_string(),
            message: "not found; run scripts/fetch-data.sh".into(),
        });
    }
    let scene = tw_io::Scene::open(&[path], tw_io::SceneOptions::default())?;
    let mut sink = Welder::default();
    scene.stream(&mut sink)?;
    if sink.object.triangles.is_empty() {
        return Err(CollideError::Model { path: path.display().to_string(), message: "no triangles".into() });
    }
    Ok(sink.object)
}

/// A `tw-io` sink that welds triangles into one mesh.
#[derive(Default)]
struct Welder {
    object: Object,
    index: HashMap<[u32; 3], u32>,
}

impl tw_io::TriangleSink for Welder {
    fn object(&mut self, _: tw_io::ObjectId, _: &tw_io::ObjectInfo) -> Result<(), tw_io::ImportError> {
        Ok(())
    }

    fn triangle(&mut self, t: &tw_io::Triangle) -> Result<(), tw_io::ImportError> {
        let ids = t.positions.map(|p| {
            let p = p.map(|v| v as f32);
            let next = self.object.positions.len() as u32;
            *self.index.entry(p.map(f32::to_bits)).or_insert_with(|| {
                self.object.positions.push(p);
                next
            })
        });
        if ids[0] != ids[1] && ids[1] != ids[2] && ids[0] != ids[2] {
            self.object.triangles.push(ids);
        }
        Ok(())
    }
}

/// `o` reduced towards `target` triangles by vertex clustering on a uniform grid (cells
/// averaged, collapsed and repeated triangles dropped); unchanged when already small enough.
fn cluster_to(o: &Object, target: f32) -> Object {
    let have = o.triangles.len() as f32;
    if have <= target {
        return o.clone();
    }
    // Triangle counts of a clustered surface go with the square of the grid's resolution.
    let mut res = 64.0f32;
    let mut out = cluster(o, res as usize);
    for _ in 0..3 {
        res *= (target / out.triangles.len().max(1) as f32).sqrt();
        out = cluster(o, res.clamp(4.0, 4096.0) as usize);
    }
    out
}

fn cluster(o: &Object, res: usize) -> Object {
    let b = o.bounds();
    let e = b.extent();
    let cell = e[0].max(e[1]).max(e[2]) / res as f32;
    let key = |p: [f32; 3]| -> [i32; 3] { std::array::from_fn(|i| ((p[i] - b.lo[i]) / cell) as i32) };
    let mut cells: HashMap<[i32; 3], u32> = HashMap::new();
    let mut sums: Vec<([f64; 3], u32)> = Vec::new();
    let remap: Vec<u32> = o
        .positions
        .iter()
        .map(|&p| {
            let id = *cells.entry(key(p)).or_insert_with(|| {
                sums.push(([0.0; 3], 0));
                sums.len() as u32 - 1
            });
            let s = &mut sums[id as usize];
            (0..3).for_each(|i| s.0[i] += p[i] as f64);
            s.1 += 1;
            id
        })
        .collect();
    let positions = sums.iter().map(|(s, n)| s.map(|v| (v / *n as f64) as f32)).collect();
    let mut seen = std::collections::HashSet::new();
    let triangles = o
        .triangles
        .iter()
        .map(|t| t.map(|v| remap[v as usize]))
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .filter(|t| {
            let mut k = *t;
            k.sort_unstable();
            seen.insert(k)
        })
        .collect();
    Object { positions, triangles, self_collide: o.self_collide }
}

/// `o` subdivided (each triangle into four at its edge midpoints) as often as brings its count
/// nearest to `target` (in ratio).
fn subdivide_to(mut o: Object, target: f32) -> Object {
    while (o.triangles.len() as f32 * 4.0 / target).ln().abs()
        < (o.triangles.len() as f32 / target).ln().abs()
    {
        o = subdivide(&o);
    }
    o
}

fn subdivide(o: &Object) -> Object {
    let mut positions = o.positions.clone();
    let mut mids: HashMap<(u32, u32), u32> = HashMap::new();
    let mut mid = |a: u32, b: u32, positions: &mut Vec<[f32; 3]>| {
        *mids.entry((a.min(b), a.max(b))).or_insert_with(|| {
            let (p, q) = (positions[a as usize], positions[b as usize]);
            positions.push(std::array::from_fn(|i| 0.5 * (p[i] + q[i])));
            positions.len() as u32 - 1
        })
    };
    let mut triangles = Vec::with_capacity(o.triangles.len() * 4);
    for &[a, b, c] in &o.triangles {
        let (ab, bc, ca) = (mid(a, b, &mut positions), mid(b, c, &mut positions), mid(c, a, &mut positions));
        triangles.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    Object { positions, triangles, self_collide: o.self_collide }
}

/// `o` cut into up to `k`³ pieces by a grid over its box: a triangle goes to the cell that holds
/// its three vertices (cells half-open), and a triangle whose vertices lie in different cells is
/// dropped — the crack. So pieces never touch: had the triangles across a cut been kept, each
/// cut would be a seam of shared vertices between two objects, thousands of contacts.
fn pieces(o: &Object, k: usize) -> Vec<Object> {
    let b = o.bounds();
    let e = b.extent().map(|v| v.max(f32::MIN_POSITIVE));
    let cell = |p: [f32; 3]| -> usize {
        let c: [usize; 3] =
            std::array::from_fn(|i| (((p[i] - b.lo[i]) / e[i] * k as f32) as usize).min(k - 1));
        (c[2] * k + c[1]) * k + c[0]
    };
    let mut parts: Vec<Vec<[u32; 3]>> = vec![Vec::new(); k * k * k];
    for &t in &o.triangles {
        let cells = t.map(|v| cell(o.positions[v as usize]));
        if cells[0] == cells[1] && cells[1] == cells[2] {
            parts[cells[0]].push(t);
        }
    }
    parts
        .into_iter()
        .filter(|p| !p.is_empty())
        .map(|tris| {
            // Each piece keeps only its own vertices.
            let mut map = HashMap::new();
            let mut positions = Vec::new();
            let triangles = tris
                .iter()
                .map(|t| {
                    t.map(|v| {
                        *map.entry(v).or_insert_with(|| {
                            positions.push(o.positions[v as usize]);
                            positions.len() as u32 - 1
                        })
                    })
                })
                .collect();
            Object { positions, triangles, self_collide: false }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_scenes_have_the_thesis_sizes_at_scale_one() {
        let opts = SceneOptions::default();
        let count = |k| crate::triangle_count(&Scene::new(k, &opts).unwrap().step(0));
        assert_eq!(count(SceneKind::Cylinders), 100 * 200);
        assert_eq!(count(SceneKind::Tori), 6 * 200 * 50 * 2);
        let cloth = Scene::new(SceneKind::Cloth, &opts).unwrap().step(0);
        assert_eq!(cloth[0].triangles.len(), 100 * 100 * 2);
    }

    #[test]
    fn scenes_move_and_collide() {
        let opts = SceneOptions { scale: 0.2, ..Default::default() };
        for k in [SceneKind::Cylinders, SceneKind::Tori, SceneKind::Cloth] {
            let s = Scene::new(k, &opts).unwrap();
            let (a, b) = (s.step(0), s.step(30));
            assert_ne!(a[0].positions, b[0].positions, "{k:?} does not move");
            let hits: usize = (0..40).step_by(8).map(|t| crate::all_pairs(&s.step(t)).len()).sum();
            assert!(hits > 0, "{k:?} never collides");
        }
    }

    #[test]
    fn subdivision_and_clustering_reach_their_targets() {
        let o = grid(30, 30, false, false, |r, c| [r as f32, c as f32, ((r * c) as f32 * 0.1).sin()]);
        let have = o.triangles.len();
        assert_eq!(subdivide_to(o.clone(), have as f32 * 3.5).triangles.len(), have * 4);
        let small = cluster_to(&o, have as f32 / 4.0);
        assert!(small.triangles.len() < have / 2, "{}", small.triangles.len());
    }

    #[test]
    fn pieces_do_not_touch_along_their_cuts() {
        let sheet = grid(30, 30, false, false, |r, c| [r as f32 / 29.0, c as f32 / 29.0, 0.0]);
        let cut = pieces(&sheet, 3);
        assert_eq!(cut.len(), 9);
        assert!(crate::all_pairs(&cut).is_empty());
        // Only the triangles across the cuts are lost.
        let (have, kept) = (sheet.triangles.len(), cut.iter().map(|p| p.triangles.len()).sum::<usize>());
        assert!(kept < have && kept > have * 3 / 4, "{kept} of {have}");
    }

    #[test]
    fn a_missing_model_names_its_file() {
        let opts = SceneOptions { scale: 0.1, data_dir: PathBuf::from("/nonexistent") };
        let e = Scene::new(SceneKind::Bunnies, &opts).err().expect("no bunny there").to_string();
        assert!(e.contains("/nonexistent/bunny.obj"), "{e}");
    }
}
