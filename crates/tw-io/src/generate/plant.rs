//! The site plan (how many blocks, how many triangles each) and the layout of one block: its
//! building (walls, floors, steel, stairs), the equipment in its rooms and its yard.
//!
//! Everything here is derived from `(seed, block index, block budget)` alone, each random choice
//! from its own stream ([`stream`]), so a block's layout can be recomputed at any time: the
//! building pass and the piping pass both call [`Layout::new`] and get the same answer.

use tw_core::Rng;

use super::parts::{
    color, Beams, Cabinet, Column, Detail, Exchanger, Grating, Item, Manifold, Nozzle, Platform, Pump,
    RackFrame, Railing, Slab, Stack, Stair, StorageTank, Valve, Vessel, Wall, BEAM_DEPTH, MAX_LEVEL,
};
use super::shapes::{Frame, V3};
use super::PlantParams;

/// Side of one block of the site grid (building, yard, road and pipe rack).
pub(crate) const PITCH: f64 = 80.0;
/// Floor-to-floor height.
pub(crate) const STOREY: f64 = 4.5;
/// Structural grid spacing.
pub(crate) const BAY: f64 = 6.0;
/// Thickness of floor slabs; the roof is 0.3 m.
pub(crate) const SLAB: f64 = 0.25;
const ROOF: f64 = 0.3;
/// Exterior wall thickness.
pub(crate) const WALL: f64 = 0.3;
/// Half the corridor width (between the corridor walls' inner faces).
pub(crate) const CORRIDOR: f64 = 1.5;
/// Share of the triangles the piping network is planned to take (it also absorbs what the
/// buildings leave unused, so it ends up a little above this).
pub(crate) const PIPE_SHARE: f64 = 0.22;
/// Top of the pipe rack beams along each block's south road.
pub(crate) const RACK_TOP: f64 = 7.0;
/// Height at which headers and yard pipes cross above the rack.
pub(crate) const CROSSING_Z: f64 = 10.0;
/// Height of the chimney in block 0.
pub(crate) const STACK_HEIGHT: f64 = 55.0;

/// At this many triangles the site has [`REF_BLOCKS`] blocks.
const REF_TRIANGLES: f64 = 1e7;
const REF_BLOCKS: f64 = 16.0;
/// Fraction of the room slots the detail search plans to fill.
const TARGET_FILL: f64 = 0.85;

const TAG_SHAPE: u64 = 1;
const TAG_STRUCT: u64 = 2;
const TAG_YARD: u64 = 3;
const TAG_SLOT: u64 = 4;
const TAG_SAMPLE: u64 = 5;
pub(crate) const TAG_RACK: u64 = 6;
pub(crate) const TAG_VIEW: u64 = 7;

/// The random stream of one thing: `tag` says what, `index` which one, within block `block`.
pub(crate) fn stream(block: u64, tag: u64, index: u64) -> u64 {
    (block << 32) | (tag << 24) | (index & 0xff_ffff)
}

/// Tessellation and route counts of the piping network, from the triangles per block.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PipeDetail {
    pub sides: u32,
    pub elbow: u32,
    /// Headers per storey (1..=3).
    pub headers: u32,
    /// Pipes on the rack (2..=8).
    pub rack: u32,
}

/// How the triangles are spread over the site.
#[derive(Clone, Debug)]
pub(crate) struct SitePlan {
    pub triangles: u64,
    pub seed: u64,
    pub blocks: u32,
    pub cols: u32,
    pub rows: u32,
    /// Triangles planned for everything but the piping network.
    pub nonpipe: u64,
    pub pipe: PipeDetail,
}

impl SitePlan {
    pub fn new(p: &PlantParams) -> SitePlan {
        let n = p.triangles as f64;
        let blocks = (REF_BLOCKS * (n / REF_TRIANGLES).powf(2.0 / 3.0)).round().max(1.0) as u32;
        let cols = (blocks as f64).sqrt().ceil() as u32;
        let rows = blocks.div_ceil(cols);
        let nonpipe = p.triangles - (n * PIPE_SHARE).round() as u64;
        // Triangles per block relative to the reference plant: grows as N^(1/3).
        let d = n / blocks as f64 / (REF_TRIANGLES / REF_BLOCKS);
        let pipe = PipeDetail {
            sides: (6.0 + 6.0 * d).round().clamp(6.0, 24.0) as u32,
            elbow: (1.0 + 3.0 * d).round().clamp(1.0, 8.0) as u32,
            headers: (1.0 + 2.0 * d).round().clamp(1.0, 3.0) as u32,
            rack: (2.0 + 3.0 * d).round().clamp(2.0, 8.0) as u32,
        };
        SitePlan { triangles: p.triangles, seed: p.seed, blocks, cols, rows, nonpipe, pipe }
    }

    /// South-west corner of block `b`.
    pub fn origin(&self, b: u32) -> V3 {
        [(b % self.cols) as f64 * PITCH, (b / self.cols) as f64 * PITCH, 0.0]
    }

    /// Triangles block `b` may use for its building, equipment and yard.
    pub fn block_budget(&self, b: u32) -> u64 {
        let blocks = self.blocks as u64;
        self.nonpipe / blocks + ((b as u64) < self.nonpipe % blocks) as u64
    }
}

/// The random shape of a block's building, before the budget decides how much of it is built.
#[derive(Clone, Debug)]
pub(crate) struct BlockShape {
    pub block: u32,
    pub origin: V3,
    /// South-west corner of the building.
    pub bx: f64,
    pub by: f64,
    pub w: f64,
    pub d: f64,
    /// Bays along x and y (`ny` odd: the corridor runs along the middle bay).
    pub nx: u32,
    pub ny: u32,
    pub storeys: u32,
    pub kind: &'static str,
    /// Bit k set: floor k is a grating floor.
    pub gratings: u32,
}

const KINDS: [&str; 5] =
    ["boiler house", "turbine hall", "pump house", "switchgear building", "water treatment"];

impl BlockShape {
    pub fn new(site: &SitePlan, b: u32) -> BlockShape {
        let mut rng = Rng::with_stream(site.seed, stream(b as u64, TAG_SHAPE, 0));
        let origin = site.origin(b);
        let nx = rng.range_u32(6, 11);
        let ny = *rng.pick(&[5, 7]);
        let storeys = rng.range_u32(2, 6);
        let w = nx as f64 * BAY;
        let slack = (70.0 - w - 10.0).max(0.0);
        let bx = origin[0] + 10.0 + (rng.f64() * slack / 2.0).floor() * 2.0;
        let by = origin[1] + 12.0;
        let kind = *rng.pick(&KINDS);
        let mut gratings = 0;
        for k in 1..storeys {
            if rng.chance(0.35) {
                gratings |= 1 << k;
            }
        }
        BlockShape { block: b, origin, bx, by, w, d: ny as f64 * BAY, nx, ny, storeys, kind, gratings }
    }

    /// The corridor's centre line.
    pub fn yc(&self) -> f64 {
        self.by + (self.ny / 2) as f64 * BAY + BAY / 2.0
    }

    /// The stair lane of flight `k`: `[y0, y1]` (lane A south of the centre line for even
    /// flights, lane B north of it for odd ones).
    pub fn lane(&self, k: u32) -> [f64; 2] {
        let yc = self.yc();
        if k & 1 == 0 {
            [yc - 1.45, yc - 0.35]
        } else {
            [yc + 0.35, yc + 1.45]
        }
    }

    fn grating(&self, k: u32) -> bool {
        self.gratings & (1 << k) != 0
    }

    /// Height of the top of the beams under floor `k` (the roof when `k == storeys`).
    fn beam_top(&self, k: u32, storeys: u32, d: &Detail) -> f64 {
        let z = k as f64 * STOREY;
        if k == storeys {
            z - ROOF
        } else if d.structure >= 1 && self.grating(k) {
            z - 0.03
        } else {
            z - SLAB
        }
    }
}

/// A room slot: a 3 × 3 m square that may hold one piece of equipment.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Slot {
    pub centre: V3,
    pub storey: u32,
    /// Bay index along x (bay 0 holds the stair; no branch pipes reach it).
    pub bay: u32,
    /// Row of slots counted from the building's south wall.
    pub row: u32,
}

/// A nozzle in a room, with the slot it belongs to.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SlotNozzle {
    pub nozzle: Nozzle,
    pub storey: u32,
    pub bay: u32,
    pub row: u32,
}

/// Everything in one block, small enough to hold (a few thousand part descriptions at most).
pub(crate) struct Layout {
    pub shape: BlockShape,
    /// Storeys actually built (fewer than the shape's when the budget is small).
    pub storeys: u32,
    /// The detail level chosen (for tests and debugging).
    #[allow(dead_code)]
    pub detail: Detail,
    pub items: Vec<Item>,
    pub nozzles: Vec<SlotNozzle>,
    /// Roof nozzles of the yard's storage tanks.
    pub tanks: Vec<Nozzle>,
    /// Triangles of all items (for tests and debugging).
    #[allow(dead_code)]
    pub triangles: u64,
}

impl Layout {
    /// The layout of block `b`, using at most its budget of triangles.
    pub fn new(site: &SitePlan, b: u32) -> Layout {
        let shape = BlockShape::new(site, b);
        let budget = site.block_budget(b);
        let fixed = |s: u32, d: &Detail| -> u64 {
            let (items, _) = fixed_items(site, &shape, s, d);
            items.iter().map(Item::triangles).sum()
        };
        let per_slot = |d: &Detail| expected_slot_triangles(site, b, d);
        let slot_count = |s: u32| slots(&shape, s).len() as f64;

        // Storeys: as many as the shape asks for while the building at the lowest detail leaves
        // room for some equipment.
        let d0 = Detail::new(0);
        let mut storeys = 1;
        for s in (1..=shape.storeys).rev() {
            if (fixed(s, &d0) as f64 + 0.3 * slot_count(s) * per_slot(&d0)) <= budget as f64 {
                storeys = s;
                break;
            }
        }
        // Detail: the highest level whose expected total fits at the target fill; then a share
        // of the slots one level higher, to use the budget closely despite the steps between
        // levels.
        let fits = |l: u32| {
            let d = Detail::new(l);
            fixed(storeys, &d) as f64 + TARGET_FILL * slot_count(storeys) * per_slot(&d) <= budget as f64
        };
        let (mut lo, mut hi) = (0, MAX_LEVEL);
        if fits(hi) {
            lo = hi;
        } else {
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                if fits(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
        }
        let detail = Detail::new(lo);
        let higher = Detail::new((lo + 1).min(MAX_LEVEL));

        let (fixed_list, tanks) = fixed_items(site, &shape, storeys, &detail);
        let mut items = Vec::with_capacity(fixed_list.len() + 256);
        let mut used = 0;
        for item in fixed_list {
            let n = item.triangles();
            if used + n <= budget {
                used += n;
                items.push(item);
            }
        }
        let room = slots(&shape, storeys);
        let avail = budget.saturating_sub(used) as f64 / room.len().max(1) as f64;
        let (e0, e1) = (per_slot(&detail), per_slot(&higher));
        let (fill, up) = if avail < TARGET_FILL * e0 || lo == MAX_LEVEL || e1 <= e0 {
            ((avail / e0).clamp(0.0, 1.0), 0.0)
        } else {
            (TARGET_FILL, ((avail / TARGET_FILL - e0) / (e1 - e0)).clamp(0.0, 1.0))
        };
        let mut nozzles = Vec::new();
        for (q, slot) in room.iter().enumerate() {
            let mut rng = Rng::with_stream(site.seed, stream(b as u64, TAG_SLOT, q as u64));
            let place = rng.chance(fill);
            let d = if rng.chance(up) { &higher } else { &detail };
            let (item, nozzle) = slot_item(Frame::at(slot.centre), d, &mut rng);
            if !place {
                continue;
            }
            let manifold = Manifold::new(Frame::at(slot.centre), d.satellites, rng.range_f64(0.02, 0.035), d);
            let manifold = Item::Manifold(manifold);
            let n = item.triangles() + manifold.triangles();
            if used + n > budget {
                continue;
            }
            used += n;
            items.push(item);
            items.push(manifold);
            if let Some(nozzle) = nozzle {
                nozzles.push(SlotNozzle { nozzle, storey: slot.storey, bay: slot.bay, row: slot.row });
            }
        }
        Layout { shape, storeys, detail, items, nozzles, tanks, triangles: used }
    }
}

/// Triangles an occupied slot is expected to take at detail `d` (equipment mix plus manifold).
fn expected_slot_triangles(site: &SitePlan, b: u32, d: &Detail) -> f64 {
    const SAMPLES: u64 = 24;
    let mut total = 0;
    for k in 0..SAMPLES {
        let mut rng = Rng::with_stream(site.seed, stream(b as u64, TAG_SAMPLE, k));
        total += slot_item(Frame::at([0.0; 3]), d, &mut rng).0.triangles();
    }
    let manifold = Item::Manifold(Manifold::new(Frame::at([0.0; 3]), d.satellites, 0.03, d));
    total as f64 / SAMPLES as f64 + manifold.triangles() as f64
}

/// One random piece of equipment for a slot whose floor centre is `f`, and its nozzle if it has
/// one. Every random number is drawn whatever the kind, in the same order.
fn slot_item(f: Frame, d: &Detail, rng: &mut Rng) -> (Item, Option<Nozzle>) {
    let pick = rng.f64();
    let quarter = rng.range_u32(0, 4);
    let (a, b, c) = (rng.f64(), rng.f64(), rng.f64());
    let g = Frame::turned(f.o, quarter);
    let noz_r = 0.04 + 0.04 * c;
    let nozzle = |fl: &super::parts::Flange| Some(Nozzle { top: fl.top(), radius: fl.r_in });
    match pick {
        p if p < 0.22 => {
            let r = 0.5 + 0.55 * a;
            let max_shell = 2.3 - (0.5 + 0.65 * r) - 0.05;
            let v = Vessel::new(g, r, 0.8 + (max_shell - 0.8) * b, noz_r, d);
            let n = nozzle(&v.flange);
            (Item::Vessel(v), n)
        }
        p if p < 0.40 => {
            let pump = Pump::new(g, 0.04 + 0.03 * c, d);
            let n = nozzle(&pump.discharge);
            (Item::Pump(pump), n)
        }
        p if p < 0.55 => {
            let x = Exchanger::new(Frame::turned(f.o, quarter % 2), 0.35 + 0.2 * a, 1.0 + 0.4 * b, noz_r, d);
            let n = nozzle(&x.flange);
            (Item::Exchanger(x), n)
        }
        p if p < 0.70 => {
            let v = Valve::new(
                Frame::turned(f.o, quarter % 2).moved(0.0, 0.0, 0.6),
                0.06 + 0.06 * a,
                0.9,
                Some(-0.6),
                d,
                8,
                false,
            );
            (Item::Valve(v), None)
        }
        p if p < 0.82 => (Item::Cabinet(Cabinet { frame: g, count: 1 + (a < 0.5) as u32 }), None),
        _ => (Item::Platform(Platform::new(g, 2.0, d)), None),
    }
}

/// The room slots of the first `storeys` storeys.
pub(crate) fn slots(sh: &BlockShape, storeys: u32) -> Vec<Slot> {
    let jc = sh.ny / 2;
    let door_bay = sh.nx / 2;
    let mut out = Vec::new();
    for k in 0..storeys {
        for i in 0..sh.nx {
            for j in (0..sh.ny).filter(|&j| j != jc) {
                for sy in 0..2 {
                    if k == 0 && j == 0 && sy == 0 && i == door_bay {
                        continue; // keep the ground-floor door free
                    }
                    for sx in 0..2 {
                        let row = 2 * j + sy;
                        let dx = ((row % 4) as f64 - 1.5) * 0.12;
                        let x = sh.bx + i as f64 * BAY + 1.5 + 3.0 * sx as f64 + dx;
                        let y = sh.by + j as f64 * BAY + 1.5 + 3.0 * sy as f64;
                        out.push(Slot { centre: [x, y, k as f64 * STOREY], storey: k, bay: i, row });
                    }
                }
            }
        }
    }
    out
}

/// Clamps a grid-line offset so that columns and beams stay inside the walls.
fn inset(v: f64, len: f64) -> f64 {
    v.clamp(0.45, len - 0.45)
}

/// The ground, rack, building structure and yard of a block at `storeys` storeys and detail `d`,
/// and the yard tanks' roof nozzles.
fn fixed_items(site: &SitePlan, sh: &BlockShape, storeys: u32, d: &Detail) -> (Vec<Item>, Vec<Nozzle>) {
    let mut items = Vec::new();
    let ibeam = d.structure >= 1;
    ground_and_rack(&mut items, sh, ibeam);
    let mut rng = Rng::with_stream(site.seed, stream(sh.block as u64, TAG_STRUCT, 0));
    for k in 0..storeys {
        let h = STOREY - if k + 1 == storeys { ROOF } else { SLAB };
        let mut walls = Walls { items: &mut items, height: h, z0: k as f64 * STOREY };
        exterior_walls(&mut walls, &mut rng, sh, k, ibeam);
        interior_walls(&mut walls, &mut rng, sh);
    }
    floors_and_roof(&mut items, sh, storeys, d, ibeam);
    steel(&mut items, sh, storeys, d, ibeam);
    stairs(&mut items, sh, storeys, d);
    let tanks = yard(&mut items, site, sh, d);
    (items, tanks)
}

/// The block's ground, the pipe rack's frames along its south edge, and the building's ground
/// slab.
fn ground_and_rack(items: &mut Vec<Item>, sh: &BlockShape, ibeam: bool) {
    let o = sh.origin;
    items.push(Item::Ground { min: [o[0], o[1], -0.5], max: [o[0] + PITCH, o[1] + PITCH, -0.05] });
    for j in 0..13 {
        items.push(Item::RackFrame(RackFrame {
            x: o[0] + 3.0 + BAY * j as f64,
            y0: o[1] + 1.5,
            y1: o[1] + 7.5,
            ground: -0.05,
            top: RACK_TOP,
            ibeam,
        }));
    }
    items.push(Item::Slab(Slab {
        rect: [sh.bx, sh.bx + sh.w, sh.by, sh.by + sh.d],
        z0: -0.3,
        z1: 0.0,
        hole: None,
        name: "ground slab",
    }));
}

/// The walls of one storey as they are made: concrete, `height` high, standing at `z0`.
struct Walls<'a> {
    items: &'a mut Vec<Item>,
    height: f64,
    z0: f64,
}

impl Walls<'_> {
    fn push(&mut self, frame: Frame, len: f64, thick: f64, openings: Vec<[f64; 4]>, name: &'static str) {
        self.items.push(Item::Wall(Wall {
            frame,
            len,
            height: self.height,
            thick,
            openings,
            name,
            color: color::CONCRETE,
        }));
    }
}

/// A wall's frame along y (its length along the scene's y) at `o`.
fn along_y(o: V3) -> Frame {
    Frame { o, x: [0.0, 1.0, 0.0], y: [-1.0, 0.0, 0.0], z: [0.0, 0.0, 1.0] }
}

/// Window openings in a wall of `bays` bays: each bay but `skip` by chance (when the detail
/// has windows at all; the draws are made either way, so the scene's other random choices do
/// not depend on the detail), shifted back by `shift` (the wall's start).
fn windows(rng: &mut Rng, bays: u32, skip: Option<u32>, shift: f64, ibeam: bool) -> Vec<[f64; 4]> {
    (0..bays)
        .filter(|&i| Some(i) != skip)
        .filter(|_| rng.chance(0.7))
        .filter(|_| ibeam)
        .map(|i| [i as f64 * BAY + 2.0 - shift, i as f64 * BAY + 4.0 - shift, 1.0, 2.2])
        .collect()
}

/// Storey `k`'s exterior walls: a truck door south and a door at the corridor's east end on the
/// ground floor, windows above.
fn exterior_walls(walls: &mut Walls, rng: &mut Rng, sh: &BlockShape, k: u32, ibeam: bool) {
    let (bx, by, w, dd, z0) = (sh.bx, sh.by, sh.w, sh.d, walls.z0);
    let south = if k == 0 {
        let c = (sh.nx / 2) as f64 * BAY;
        vec![[c + 1.5, c + 4.5, 0.0, 3.5]]
    } else {
        windows(rng, sh.nx, None, 0.0, ibeam)
    };
    walls.push(Frame::at([bx, by, z0]), w, WALL, south, sh.kind);
    let north = if k == 0 { Vec::new() } else { windows(rng, sh.nx, None, 0.0, ibeam) };
    walls.push(Frame::at([bx, by + dd - WALL, z0]), w, WALL, north, sh.kind);
    let west = if k == 0 { Vec::new() } else { windows(rng, sh.ny, Some(sh.ny / 2), WALL, ibeam) };
    walls.push(along_y([bx + WALL, by + WALL, z0]), dd - 2.0 * WALL, WALL, west, sh.kind);
    let east = if k == 0 {
        let y = sh.yc() - by - WALL;
        vec![[y - 0.6, y + 0.6, 0.0, 2.2]]
    } else {
        windows(rng, sh.ny, None, WALL, ibeam)
    };
    walls.push(along_y([bx + w, by + WALL, z0]), dd - 2.0 * WALL, WALL, east, sh.kind);
}

/// A storey's interior walls: the corridor walls with a door into every room bay but the stair
/// bay, and cross walls between some room bays, each with a door.
fn interior_walls(walls: &mut Walls, rng: &mut Rng, sh: &BlockShape) {
    let (bx, by, w, dd, z0) = (sh.bx, sh.by, sh.w, sh.d, walls.z0);
    let (yc, jc) = (sh.yc(), sh.ny / 2);
    let doors: Vec<[f64; 4]> =
        (1..sh.nx).map(|i| [i as f64 * BAY + 2.5 - WALL, i as f64 * BAY + 3.5 - WALL, 0.0, 2.2]).collect();
    let corridor_wall = Frame::at([bx + WALL, yc - CORRIDOR - 0.15, z0]);
    walls.push(corridor_wall, w - 2.0 * WALL, 0.15, doors.clone(), "corridor wall");
    walls.push(Frame::at([bx + WALL, yc + CORRIDOR, z0]), w - 2.0 * WALL, 0.15, doors, "corridor wall");
    for i in 1..sh.nx {
        let x = bx + i as f64 * BAY + 0.075;
        for (y0, y1, bays) in
            [(by + WALL, yc - CORRIDOR - 0.15, 0..jc), (yc + CORRIDOR + 0.15, by + dd - WALL, jc + 1..sh.ny)]
        {
            let build = rng.chance(0.45);
            let j = bays.start + rng.range_u32(0, bays.end - bays.start);
            if build {
                let door = by + j as f64 * BAY + 2.5 - y0;
                let opening = vec![[door, door + 1.0, 0.0, 2.2]];
                walls.push(along_y([x, y0, z0]), y1 - y0, 0.15, opening, "partition wall");
            }
        }
    }
}

/// Floors above the ground: slabs or gratings with the stairwell of the flight below open and a
/// railing along it; then the roof.
fn floors_and_roof(items: &mut Vec<Item>, sh: &BlockShape, storeys: u32, d: &Detail, ibeam: bool) {
    let (bx, by, w, dd) = (sh.bx, sh.by, sh.w, sh.d);
    for k in 1..storeys {
        let z = k as f64 * STOREY;
        let lane = sh.lane(k - 1);
        let hole = Some([bx + 0.3, bx + 6.0, lane[0], lane[1]]);
        if ibeam && sh.grating(k) {
            let rect = [bx + WALL, bx + w - WALL, by + WALL, by + dd - WALL];
            items.push(Item::Grating(Grating { rect, z, hole, pitch: d.pitch }));
        } else {
            let rect = [bx, bx + w, by, by + dd];
            items.push(Item::Slab(Slab { rect, z0: z - SLAB, z1: z, hole, name: "floor slab" }));
        }
        let edge = if k % 2 == 1 { lane[1] } else { lane[0] };
        items.push(Item::Railing(Railing {
            points: vec![[bx + 0.35, edge, z], [bx + 6.0, edge, z]],
            sides: d.small,
        }));
    }
    let top = storeys as f64 * STOREY;
    items.push(Item::Slab(Slab {
        rect: [bx, bx + w, by, by + dd],
        z0: top - ROOF,
        z1: top,
        hole: None,
        name: "roof",
    }));
}

/// Steel: beams under every floor, full-height columns on the grid.
fn steel(items: &mut Vec<Item>, sh: &BlockShape, storeys: u32, d: &Detail, ibeam: bool) {
    let (bx, by, w, dd) = (sh.bx, sh.by, sh.w, sh.d);
    for k in 1..=storeys {
        let along_x =
            (0..=sh.ny).map(|j| (by + inset(j as f64 * BAY, dd), bx + WALL, bx + w - WALL)).collect();
        let along_y =
            (0..=sh.nx).map(|i| (bx + inset(i as f64 * BAY, w), by + WALL, by + dd - WALL)).collect();
        items.push(Item::Beams(Beams { top: sh.beam_top(k, storeys, d), along_x, along_y, ibeam }));
    }
    let top = storeys as f64 * STOREY;
    for i in 0..=sh.nx {
        for j in 0..=sh.ny {
            let bolt_levels = if d.structure >= 3 {
                (1..=storeys).map(|k| sh.beam_top(k, storeys, d) - BEAM_DEPTH / 2.0).collect()
            } else {
                Vec::new()
            };
            items.push(Item::Column(Column {
                base: [bx + inset(i as f64 * BAY, w), by + inset(j as f64 * BAY, dd), 0.0],
                height: top - ROOF,
                ibeam,
                base_plate: d.structure >= 2,
                bolt_levels,
                bolt_sides: d.bolt,
            }));
        }
    }
}

/// Stairs: flights alternate between the two lanes at the corridor's west end, each with a
/// railing.
fn stairs(items: &mut Vec<Item>, sh: &BlockShape, storeys: u32, d: &Detail) {
    let bx = sh.bx;
    for k in 0..storeys.saturating_sub(1) {
        let lane = sh.lane(k);
        let y = 0.5 * (lane[0] + lane[1]);
        let z = k as f64 * STOREY;
        let frame =
            if k % 2 == 0 { Frame::turned([bx + 0.4, y, z], 0) } else { Frame::turned([bx + 5.8, y, z], 2) };
        items.push(Item::Stair(Stair { frame, run: 5.4, rise: STOREY, width: 1.1, steps: 23 }));
        items.push(Item::Railing(Railing {
            points: vec![frame.p(0.0, 0.6, 0.0), frame.p(5.4, 0.6, STOREY)],
            sides: d.small,
        }));
    }
}

/// Yard: the chimney (block 0) and storage tanks north of the building. Returns the tanks'
/// roof nozzles.
fn yard(items: &mut Vec<Item>, site: &SitePlan, sh: &BlockShape, d: &Detail) -> Vec<Nozzle> {
    let o = sh.origin;
    let mut tanks = Vec::new();
    let mut rng = Rng::with_stream(site.seed, stream(sh.block as u64, TAG_YARD, 0));
    let y_lo = sh.by + sh.d + 4.0;
    let y_hi = o[1] + PITCH - 1.0;
    let yt = 0.5 * (y_lo + y_hi);
    let r_max = ((y_hi - y_lo - 1.0) / 2.0).min(6.0);
    let mut x = o[0] + 4.0;
    if sh.block == 0 {
        items.push(Item::Stack(Stack::new(Frame::at([x + 4.0, yt, 0.0]), 2.6, STACK_HEIGHT, d)));
        x += 12.0;
    }
    for _ in 0..4 {
        let r = rng.range_f64(3.0, r_max.max(3.0 + 1e-9));
        let h = rng.range_f64(8.0, 14.0);
        if x + 2.0 * r > sh.bx + sh.w {
            break;
        }
        let t = StorageTank::new(Frame::at([x + r, yt, 0.0]), r, h, d);
        tanks.push(t.nozzle());
        items.push(Item::StorageTank(t));
        x += 2.0 * r + 3.0;
    }
    tanks
}

#[cfg(test)]
mod tests {
    use super::*;

    fn site(n: u64) -> SitePlan {
        SitePlan::new(&PlantParams { triangles: n, seed: 7 })
    }

    #[test]
    fn blocks_grow_as_n_to_the_two_thirds() {
        assert_eq!(site(10_000).blocks, 1);
        assert_eq!(site(10_000_000).blocks, 16);
        let b9 = site(1_000_000_000).blocks;
        assert!((300..400).contains(&b9), "{b9}");
    }

    #[test]
    fn block_budgets_sum_to_the_non_pipe_share() {
        let s = site(3_000_001);
        let total: u64 = (0..s.blocks).map(|b| s.block_budget(b)).sum();
        assert_eq!(total, s.nonpipe);
    }

    #[test]
    fn layouts_stay_within_budget_and_use_most_of_it() {
        for n in [10_000, 1_000_000, 50_000_000] {
            let s = site(n);
            for b in [0, s.blocks - 1] {
                let lay = Layout::new(&s, b);
                let budget = s.block_budget(b);
                let sum: u64 = lay.items.iter().map(Item::triangles).sum();
                assert_eq!(sum, lay.triangles);
                assert!(lay.triangles <= budget);
                assert!(
                    lay.triangles as f64 > 0.85 * budget as f64,
                    "n {n} block {b}: {} of {budget}",
                    lay.triangles
                );
            }
        }
    }

    #[test]
    fn a_layout_is_the_same_every_time() {
        let s = site(2_000_000);
        let a = Layout::new(&s, 1);
        let b = Layout::new(&s, 1);
        assert_eq!(a.triangles, b.triangles);
        assert_eq!(a.items.len(), b.items.len());
        assert_eq!(a.nozzles.len(), b.nozzles.len());
    }

    #[test]
    fn slots_avoid_the_corridor_and_stay_inside() {
        let s = site(1_000_000);
        let sh = BlockShape::new(&s, 0);
        for slot in slots(&sh, sh.storeys) {
            let [x, y, _] = slot.centre;
            assert!((y - sh.yc()).abs() > CORRIDOR + 1.5);
            assert!(x > sh.bx + 1.2 && x < sh.bx + sh.w - 1.2);
            assert!(y > sh.by + 1.2 && y < sh.by + sh.d - 1.2);
        }
    }
}
