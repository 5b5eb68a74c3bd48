//! The plan of the assembly (how many boards and cabinets, how many triangles each) and the
//! layout of one cabinet's structure and of one board.
//!
//! Everything is derived from `(seed, index, budget)` alone, each random choice from a stream of
//! its own ([`stream`]), so a cabinet or a board can be laid out at any time and in any order with
//! the same result. Millimetres, x along the cabinet row, y from the cabinet front to its back
//! (the aisle lies beyond the back, at larger y), z up, the floor at z = 0.

use tw_core::Rng;

use super::super::shapes::{Frame, V3};
use super::parts::{turned, Detail, Part, Placed, Sheet, MAX_LEVEL, MIN_HARNESS};
use super::AssemblyParams;

/// Cabinet width (x), depth (y) and height (z).
pub(crate) const CAB_W: f64 = 600.0;
pub(crate) const CAB_D: f64 = 800.0;
pub(crate) const CAB_H: f64 = 2000.0;
/// Cabinet grid pitch along y: the cabinet and a 600 mm aisle with a floor grating.
pub(crate) const PITCH_Y: f64 = 1400.0;
/// Highest point of the scene: the cable tray on the roof.
pub(crate) const TOP: f64 = 2100.0;
/// Lowest point: the bottom of the aisle grating's bearing bars.
pub(crate) const BOTTOM: f64 = -30.0;

/// Card cages per cabinet and board slots per cage.
pub(crate) const CAGES: u32 = 6;
pub(crate) const SLOTS: u32 = 20;
pub(crate) const BOARDS_PER_CABINET: u32 = CAGES * SLOTS;
/// A 6U Eurocard: 233.35 × 160 mm, 1.6 mm thick.
pub(crate) const BOARD_L: f64 = 233.35;
pub(crate) const BOARD_W: f64 = 160.0;
pub(crate) const BOARD_T: f64 = 1.6;
/// Slot pitch (so components up to about 18 mm high fit between boards).
const SLOT_PITCH: f64 = 22.5;
const CAGE_PITCH: f64 = 290.0;
const CAGE_H: f64 = 266.7;
const FIRST_CAGE: f64 = 200.0;
/// The board front edge is this far behind the cabinet front.
const BOARD_Y: f64 = 30.0;
/// Front face of the backplane.
const BACKPLANE_Y: f64 = 273.4;

/// Triangles per board at 10^7 triangles (a fully populated board at the lowest detail levels);
/// grows as N^(1/5), so that both the number of boards and their detail grow with N.
const REF_BOARD: f64 = 90_000.0;
const REF_TRIANGLES: f64 = 1e7;
/// No board is planned with fewer triangles (a sparse board rather than many empty ones).
const MIN_BOARD: f64 = 4_000.0;
/// Most of the triangles the cabinet structures (and the machinery) may take.
const STRUCTURE_SHARE: f64 = 0.15;
/// Highest structure level (see [`cabinet_parts`]).
pub(crate) const MAX_STRUCTURE: u32 = 6;

const TAG_BOARD: u64 = 1;
const TAG_BOTTOM: u64 = 2;

/// The random stream of one thing: `tag` says what, `index` which one.
pub(crate) fn stream(tag: u64, index: u64) -> u64 {
    (tag << 40) | (index & 0xff_ffff_ffff)
}

/// How the triangles are spread over cabinets and boards.
#[derive(Clone, Debug)]
pub(crate) struct Plan {
    /// Triangles generated: the request rounded down to even (closed meshes are even).
    pub triangles: u64,
    pub seed: u64,
    pub boards: u32,
    pub cabinets: u32,
    pub cols: u32,
    pub rows: u32,
    /// Structure level of every cabinet (0..=[`MAX_STRUCTURE`]).
    pub structure_level: u32,
    /// Triangles of all cabinet structures together.
    pub structure: u64,
}

impl Plan {
    pub fn new(p: &AssemblyParams) -> Plan {
        let triangles = p.triangles & !1;
        let n = triangles as f64;
        let per_board = (REF_BOARD * (n / REF_TRIANGLES).powf(0.2)).max(MIN_BOARD);
        let boards = (n / per_board).round().max(1.0) as u32;
        let cabinets = boards.div_ceil(BOARDS_PER_CABINET);
        let cols = (cabinets as f64).sqrt().ceil() as u32;
        let rows = cabinets.div_ceil(cols);
        let mut plan =
            Plan { triangles, seed: p.seed, boards, cabinets, cols, rows, structure_level: 0, structure: 0 };
        let total = |plan: &Plan, level: u32| -> u64 {
            (0..plan.cabinets).map(|c| count(&cabinet_parts(plan, c, level), &structure_detail(level))).sum()
        };
        let cap = (STRUCTURE_SHARE * n) as u64;
        let level = (0..=MAX_STRUCTURE).rev().find(|&l| total(&plan, l) <= cap).unwrap_or(0);
        plan.structure_level = level;
        plan.structure = total(&plan, level);
        plan
    }

    /// South-west (front-left) floor corner of cabinet `c`.
    pub fn cabinet_origin(&self, c: u32) -> V3 {
        [(c % self.cols) as f64 * CAB_W, (c / self.cols) as f64 * PITCH_Y, 0.0]
    }

    /// The boards of cabinet `c`.
    pub fn cabinet_boards(&self, c: u32) -> std::ops::Range<u32> {
        let first = c * BOARDS_PER_CABINET;
        first..(first + BOARDS_PER_CABINET).min(self.boards)
    }

    /// Triangles board `b` takes (even; all boards sum to what the structures leave).
    pub fn board_budget(&self, b: u32) -> u64 {
        let half = (self.triangles - self.structure) / 2;
        let boards = self.boards as u64;
        2 * (half / boards + ((b as u64) < half % boards) as u64)
    }

    /// The frame of board `b`: origin at its front-bottom corner on the cabinet front side, x
    /// towards the back, y up, z (the component side) along +x of the cabinet.
    pub fn board_frame(&self, b: u32) -> Frame {
        let c = b / BOARDS_PER_CABINET;
        let k = b % BOARDS_PER_CABINET;
        let (cage, slot) = (k / SLOTS, k % SLOTS);
        let o = self.cabinet_origin(c);
        Frame {
            o: [o[0] + slot_x(slot), o[1] + BOARD_Y, cage_z(cage) + 50.0],
            x: [0.0, 1.0, 0.0],
            y: [0.0, 0.0, 1.0],
            z: [1.0, 0.0, 0.0],
        }
    }
}

fn slot_x(slot: u32) -> f64 {
    65.0 + SLOT_PITCH * slot as f64
}

fn cage_z(cage: u32) -> f64 {
    FIRST_CAGE + CAGE_PITCH * cage as f64
}

/// The tessellation of the cabinet structures at structure level `level`.
pub(crate) fn structure_detail(level: u32) -> Detail {
    Detail::new(4 * level)
}

/// Exact triangles of `parts` at detail `d`.
pub(crate) fn count(parts: &[Placed], d: &Detail) -> u64 {
    parts.iter().map(|p| p.triangles(d)).sum()
}

/// A frame at `o` whose z axis is `z` and x axis `x` (unit, perpendicular).
fn frame(o: V3, x: V3, z: V3) -> Frame {
    let y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]];
    Frame { o, x, y, z }
}

const PX: V3 = [1.0, 0.0, 0.0];
const NX: V3 = [-1.0, 0.0, 0.0];
const PY: V3 = [0.0, 1.0, 0.0];
const NY: V3 = [0.0, -1.0, 0.0];
const PZ: V3 = [0.0, 0.0, 1.0];

/// The structure of cabinet `c` at structure level `level` (each level adds to the one below):
/// 0: plinth, posts, side panels, roof, back panel, cage plates and rails of the cages in use;
/// 1: card guides for every slot, a backplane per cage; 2: backplane connectors for every board,
/// backplane standoffs and screws, front mounting rails with cage screws and washers; 3: a fan
/// tray with three fans, a cable tray on the roof; 4: the aisle floor grating and a cooling water
/// line (pipes, supports, a valve between two flanges, bolts and nuts); 5–6: a finer grating and
/// more bolts.
pub(crate) fn cabinet_parts(plan: &Plan, c: u32, level: u32) -> Vec<Placed> {
    let o = plan.cabinet_origin(c);
    let boards = plan.cabinet_boards(c);
    let cages = (boards.end - boards.start).div_ceil(SLOTS);
    let mut out = Vec::new();
    frame_and_panels(&mut out, o);
    for k in 0..cages {
        cage(&mut out, o, k, level);
    }
    if level >= 1 {
        for k in 0..cages {
            // x along the row, y up, z (the thickness) towards the cabinet front.
            let f = frame([o[0] + 52.0, o[1] + BACKPLANE_Y + 1.6, cage_z(k) + 20.0], PX, NY);
            out.push(Placed { part: Part::Board { l: 496.0, w: 226.7, t: 1.6, backplane: true }, frame: f });
        }
    }
    if level >= 2 {
        backplane_connectors(&mut out, o, boards);
        backplane_fixings(&mut out, o, cages);
        front_rails(&mut out, o, cages);
    }
    if level >= 3 {
        fans_and_cable_tray(&mut out, o);
    }
    if level >= 4 {
        let pitch = 40.0 / (level - 3) as f64;
        out.push(Placed {
            part: Part::Grating { l: CAB_W, w: PITCH_Y - CAB_D, pitch },
            frame: cabinet_at(o, 0.0, CAB_D, 0.0),
        });
        machinery(&mut out, [o[0], o[1] + CAB_D + 60.0, 60.0], 4 + 2 * (level - 4));
    }
    out
}

/// The frame at `(x, y, z)` in the cabinet whose origin is `o`.
fn cabinet_at(o: V3, x: f64, y: f64, z: f64) -> Frame {
    Frame::at([o[0] + x, o[1] + y, o[2] + z])
}

/// A sheet part from `min` to `max` in the cabinet's frame.
fn sheet(out: &mut Vec<Placed>, o: V3, min: V3, max: V3, kind: Sheet) {
    out.push(Placed { part: Part::Sheet { min, max, kind }, frame: cabinet_at(o, 0.0, 0.0, 0.0) })
}

/// Level 0's cabinet: plinth, four posts, side panels, roof and back panel.
fn frame_and_panels(out: &mut Vec<Placed>, o: V3) {
    sheet(out, o, [0.0, 0.0, 0.0], [CAB_W, CAB_D, 100.0], Sheet::Frame);
    for (x, y) in [(0.0, 0.0), (CAB_W - 40.0, 0.0), (0.0, CAB_D - 40.0), (CAB_W - 40.0, CAB_D - 40.0)] {
        sheet(out, o, [x, y, 100.0], [x + 40.0, y + 40.0, CAB_H], Sheet::Frame);
    }
    for x in [0.0, CAB_W - 1.5] {
        sheet(out, o, [x, 40.0, 100.0], [x + 1.5, CAB_D - 40.0, CAB_H], Sheet::Panel);
    }
    sheet(out, o, [0.0, 0.0, CAB_H], [CAB_W, CAB_D, CAB_H + 2.0], Sheet::Panel);
    sheet(out, o, [40.0, CAB_D - 1.5, 100.0], [CAB_W - 40.0, CAB_D, CAB_H], Sheet::Panel);
}

/// Cage `k`: its side plates and rails (level 0) and, from level 1, two card guides per slot.
fn cage(out: &mut Vec<Placed>, o: V3, k: u32, level: u32) {
    let z0 = cage_z(k);
    for x in [50.0, 548.0] {
        sheet(out, o, [x, 25.0, z0], [x + 2.0, BACKPLANE_Y + 2.0, z0 + CAGE_H], Sheet::Guide);
    }
    for z in [z0, z0 + CAGE_H - 5.0] {
        sheet(out, o, [52.0, 25.0, z], [548.0, 40.0, z + 5.0], Sheet::Frame);
    }
    if level >= 1 {
        for j in 0..SLOTS {
            let x = slot_x(j);
            for z in [z0 + 44.0, z0 + 50.0 + BOARD_W] {
                sheet(out, o, [x - 1.5, 40.0, z], [x + BOARD_T + 1.5, 262.0, z + 6.0], Sheet::Guide);
            }
        }
    }
}

/// Level 2: a backplane connector for every board of the cabinet.
fn backplane_connectors(out: &mut Vec<Placed>, o: V3, boards: std::ops::Range<u32>) {
    for b in boards {
        let k = b % BOARDS_PER_CABINET;
        let (z0, x) = (cage_z(k / SLOTS), slot_x(k % SLOTS) + BOARD_T / 2.0);
        let f = frame([o[0] + x, o[1] + BACKPLANE_Y, z0 + 50.0 + 80.0], PZ, NY);
        let part = Part::Connector { l: 140.0, w: 8.0, h: 10.0, rows: 4, per_row: 40 };
        out.push(Placed { part, frame: f });
    }
}

/// Level 2: each backplane's standoffs behind it and screws through it, six per cage.
fn backplane_fixings(out: &mut Vec<Placed>, o: V3, cages: u32) {
    for k in 0..cages {
        let z0 = cage_z(k);
        for x in [80.0, 300.0, 520.0] {
            for z in [z0 + 30.0, z0 + 236.0] {
                let back = frame([o[0] + x, o[1] + BACKPLANE_Y + 1.6, o[2] + z], PX, PY);
                out.push(Placed { part: Part::Standoff { a: 6.0, h: 10.0 }, frame: back });
                let front = frame([o[0] + x, o[1] + BACKPLANE_Y, o[2] + z], PX, NY);
                out.push(Placed { part: Part::Screw { r: 1.5, head: 2.75, len: 8.0 }, frame: front });
            }
        }
    }
}

/// Level 2: the front mounting rails, and each cage's four screws with washers into them.
fn front_rails(out: &mut Vec<Placed>, o: V3, cages: u32) {
    for x in [40.0, CAB_W - 60.0] {
        sheet(out, o, [x, 20.0, 100.0], [x + 20.0, 25.0, CAB_H], Sheet::Frame);
    }
    for k in 0..cages {
        for x in [50.0, CAB_W - 50.0] {
            for z in [cage_z(k) + 20.0, cage_z(k) + CAGE_H - 20.0] {
                let f = frame([o[0] + x, o[1] + 20.0, o[2] + z], PX, NY);
                out.push(Placed { part: Part::Washer { r_in: 3.2, r_out: 6.0, t: 0.8 }, frame: f });
                let f = f.moved(0.0, 0.0, 0.8);
                out.push(Placed { part: Part::Screw { r: 2.5, head: 5.0, len: 12.0 }, frame: f });
            }
        }
    }
}

/// Level 3: the fan tray with three fans, and the cable tray on the roof.
fn fans_and_cable_tray(out: &mut Vec<Placed>, o: V3) {
    sheet(out, o, [40.0, 40.0, 100.0], [CAB_W - 40.0, 300.0, 108.0], Sheet::Panel);
    for x in [150.0, 300.0, 450.0] {
        out.push(Placed {
            part: Part::Fan { size: 120.0, depth: 25.0, blades: 7 },
            frame: cabinet_at(o, x, 170.0, 110.0),
        });
    }
    out.push(Placed {
        part: Part::Tray { l: CAB_W, w: 200.0, h: 60.0, pitch: 100.0 },
        frame: cabinet_at(o, 0.0, 300.0, CAB_H + 2.0),
    });
}

/// A cooling water line along x at `p` (the pipe's start, on its axis): two pipes, two supports,
/// a valve between two flanges, `bolts` bolts and nuts through each flange.
fn machinery(out: &mut Vec<Placed>, p: V3, bolts: u32) {
    let r = 25.0;
    let along = |x: f64| frame([p[0] + x, p[1], p[2]], PY, PX);
    out.push(Placed { part: Part::Pipe { r, len: 250.0 }, frame: along(0.0) });
    out.push(Placed { part: Part::Pipe { r, len: 250.0 }, frame: along(350.0) });
    for x in [120.0, 480.0] {
        let part =
            Part::Sheet { min: [x - 20.0, -30.0, 0.0], max: [x + 20.0, 30.0, p[2] - r], kind: Sheet::Frame };
        out.push(Placed { part, frame: Frame::at([p[0], p[1], 0.0]) });
    }
    let (t, r_out, rb) = (12.5, 50.0, 37.5);
    let valve = frame([p[0] + 300.0, p[1], p[2]], PX, PZ);
    out.push(Placed { part: Part::Valve { r }, frame: valve });
    for (x, dir) in [(250.0, PX), (350.0, NX)] {
        let f = frame([p[0] + x, p[1], p[2]], if dir[0] > 0.0 { PY } else { [0.0, -1.0, 0.0] }, dir);
        out.push(Placed { part: Part::Flange { r, r_out, t }, frame: f });
        for j in 0..bolts {
            let a = std::f64::consts::TAU * (j as f64 + 0.5) / bolts as f64;
            let (cy, cz) = (rb * a.cos(), rb * a.sin());
            // Head on the pipe side of the flange, nut on the valve side.
            let head = frame(f.p(cy, cz, 0.0), f.x, [-dir[0], -dir[1], -dir[2]]);
            out.push(Placed { part: Part::Bolt { a: 10.0, len: t + 8.0 }, frame: head });
            out.push(Placed { part: Part::Nut { a: 11.0, h: 6.0 }, frame: f.moved(cy, cz, t) });
        }
    }
}

/// One board's parts in emission order, each with the detail it is emitted at.
pub(crate) struct Board {
    pub parts: Vec<(Placed, Detail)>,
    /// The base detail level (some parts are one level finer).
    #[allow(dead_code)]
    pub level: u32,
    /// Parts planned (top and bottom side, before the budget) and how many were placed.
    #[allow(dead_code)]
    pub planned: usize,
    /// Triangles of all parts (the board's budget exactly).
    #[allow(dead_code)]
    pub triangles: u64,
}

impl Board {
    /// The layout of board `b` using exactly its budget. Its parts (top side, then the bottom
    /// side's chips) are emitted at the highest detail level whose exact count fits, and the
    /// parts with the largest gain one level finer while the budget allows (the same idea as the
    /// plant's share of slots one level higher), which leaves only a few triangles over. When
    /// even level 0 does not fit, some of the larger parts are left unplaced ([`keep_within`]).
    /// A wire harness takes exactly what is left (at least [`MIN_HARNESS`]).
    pub fn new(plan: &Plan, b: u32) -> Board {
        let f = plan.board_frame(b);
        let budget = plan.board_budget(b);
        let limit = budget.saturating_sub(MIN_HARNESS);
        let all = board_parts(plan.seed, b, &f);
        let planned = all.len();
        let fits = |l: u32| count(&all, &Detail::new(l)) <= limit;
        let level = if fits(MAX_LEVEL) {
            MAX_LEVEL
        } else if !fits(0) {
            0
        } else {
            let (mut lo, mut hi) = (0, MAX_LEVEL);
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                if fits(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        let (base, finer) = (Detail::new(level), Detail::new((level + 1).min(MAX_LEVEL)));
        let tris: Vec<u64> = all.iter().map(|p| p.triangles(&base)).collect();
        let keep = keep_within(&tris, limit);
        let total: u64 = tris.iter().zip(&keep).filter(|(_, &k)| k).map(|(n, _)| n).sum();
        let gain: Vec<u64> = all
            .iter()
            .zip(&tris)
            .zip(&keep)
            .map(|((p, &n), &k)| if k { p.triangles(&finer) - n } else { 0 })
            .collect();
        let mut order: Vec<usize> = (0..all.len()).collect();
        order.sort_by_key(|&i| std::cmp::Reverse(gain[i]));
        let mut slack = limit - total;
        let mut up = vec![false; all.len()];
        for i in order {
            if gain[i] > 0 && gain[i] <= slack {
                slack -= gain[i];
                up[i] = true;
            }
        }
        let used = limit - slack;
        let mut parts: Vec<(Placed, Detail)> = all
            .into_iter()
            .zip(keep.iter().zip(&up))
            .filter(|(_, (&k, _))| k)
            .map(|(p, (_, &u))| (p, if u { finer } else { base }))
            .collect();
        let harness = Part::Harness { len: BOARD_L - 16.0, triangles: budget - used };
        parts.push((Placed { part: harness, frame: f.moved(8.0, 3.0, BOARD_T) }, base));
        Board { parts, level, planned, triangles: budget }
    }
}

/// Parts of at most this many triangles (at the base level) are placed first when a board's
/// parts do not all fit.
const SMALL_PART: u64 = 200;
/// Share of a board's budget the small parts get first when its parts do not all fit.
const SMALL_SHARE: f64 = 0.6;

/// Which parts to place: all of them when their triangles `tris` fit in `limit`; else first the
/// small ones (up to [`SMALL_PART`], smallest first) within [`SMALL_SHARE`] of the limit, then
/// the others in board order wherever they still fit. A small budget thus keeps many of a
/// board's small parts and its first rows of ICs and connectors, rather than either only small
/// parts or only the first rows.
fn keep_within(tris: &[u64], limit: u64) -> Vec<bool> {
    if tris.iter().sum::<u64>() <= limit {
        return vec![true; tris.len()];
    }
    let mut small: Vec<usize> = (0..tris.len()).filter(|&i| tris[i] <= SMALL_PART).collect();
    small.sort_by_key(|&i| tris[i]);
    let mut keep = vec![false; tris.len()];
    let mut sum = 0;
    let first = (SMALL_SHARE * limit as f64) as u64;
    for i in small {
        if sum + tris[i] > first {
            break;
        }
        sum += tris[i];
        keep[i] = true;
    }
    for (i, &n) in tris.iter().enumerate() {
        if !keep[i] && sum + n <= limit {
            sum += n;
            keep[i] = true;
        }
    }
    keep
}

/// Every part a board can hold, in order: [`top_side`], then a grid of small capacitors and
/// resistors on the bottom side (decoupling under the ICs). Independent of the detail level.
fn board_parts(seed: u64, b: u32, f: &Frame) -> Vec<Placed> {
    let mut out = top_side(seed, b, f);
    let mut rng = Rng::with_stream(seed, stream(TAG_BOTTOM, b as u64));
    let (nx, ny) = (35, 36);
    let bottom = Frame { o: f.o, x: f.x, y: [-f.y[0], -f.y[1], -f.y[2]], z: [-f.z[0], -f.z[1], -f.z[2]] };
    for i in 0..nx * ny {
        let (ix, iy) = (i % nx, i / nx);
        let (x, y) = (26.0 + 5.4 * ix as f64, 10.0 + 4.0 * iy as f64);
        let resistor = rng.chance(0.2);
        let (l, w, h) = if rng.chance(0.7) { (1.0, 0.5, 0.5) } else { (1.6, 0.8, 0.8) };
        if rng.chance(0.15) {
            continue; // not every pad is populated
        }
        // The bottom frame's y runs the other way: board y is −y there.
        out.push(Placed { part: Part::Chip { l, w, h, resistor }, frame: bottom.moved(x, -y, 0.0) });
    }
    out
}

/// Placement rows on the board's top side.
#[derive(Clone, Copy, PartialEq)]
enum Row {
    Small,
    Medium,
    Large,
}

/// A sampled component: the part, its footprint along the board's x and y, its quarter turn
/// and what sits on top of it (a heatsink, at the given height).
struct Comp {
    part: Part,
    fx: f64,
    fy: f64,
    quarter: u32,
    on_top: Option<(Part, f64)>,
}

/// The board itself, its front panel hardware, the rear connector, four mounting screws and
/// the components packed in rows over the top side. Independent of the detail level.
fn top_side(seed: u64, b: u32, f: &Frame) -> Vec<Placed> {
    let mut rng = Rng::with_stream(seed, stream(TAG_BOARD, b as u64));
    let mut out = Vec::with_capacity(1024);
    let put = |out: &mut Vec<Placed>, part: Part, frame: Frame| out.push(Placed { part, frame });
    put(&mut out, Part::Board { l: BOARD_L, w: BOARD_W, t: BOARD_T, backplane: false }, *f);
    // Front panel (4HP wide, 6U high) and its hardware, facing the cabinet front (−x of f).
    let panel = Part::Sheet { min: [-2.5, -50.0, -5.0], max: [0.0, 212.0, 15.0], kind: Sheet::Panel };
    put(&mut out, panel, *f);
    let out_of = |y: f64, z: f64| {
        let o = f.p(-2.5, y, z);
        Frame { o, x: f.y, y: [-f.z[0], -f.z[1], -f.z[2]], z: [-f.x[0], -f.x[1], -f.x[2]] }
    };
    put(&mut out, Part::Handle { span: 60.0, r: 2.5, h: 15.0 }, out_of(20.0, 5.0));
    for y in [-40.0, 202.0] {
        put(&mut out, Part::Washer { r_in: 1.3, r_out: 3.0, t: 0.5 }, out_of(y, 5.0));
        put(&mut out, Part::Screw { r: 1.25, head: 2.75, len: 8.0 }, out_of(y, 5.0).moved(0.0, 0.0, 0.5));
    }
    for k in 0..3 {
        put(&mut out, Part::Led { r: 1.5, h: 5.0 }, out_of(120.0 + 8.0 * k as f64, 5.0));
    }
    // Rear (backplane) connector along the board's back edge.
    let rear = turned(&f.moved(BOARD_L - 4.0, 80.0, BOARD_T), 1);
    put(&mut out, Part::Connector { l: 140.0, w: 8.0, h: 10.0, rows: 4, per_row: 40 }, rear);
    // Mounting holes: washer and screw on top, nut below.
    for (x, y) in [(12.0, 12.0), (12.0, 150.0), (220.0, 12.0), (220.0, 150.0)] {
        let top = f.moved(x, y, BOARD_T);
        put(&mut out, Part::Washer { r_in: 1.6, r_out: 3.5, t: 0.5 }, top);
        put(&mut out, Part::Screw { r: 1.5, head: 2.75, len: 6.0 }, top.moved(0.0, 0.0, 0.5));
        let below = Frame {
            o: f.p(x, y, 0.0),
            x: f.x,
            y: [-f.y[0], -f.y[1], -f.y[2]],
            z: [-f.z[0], -f.z[1], -f.z[2]],
        };
        put(&mut out, Part::Nut { a: 6.4, h: 2.4 }, below);
    }
    // Component rows; the share of large rows differs from board to board.
    let large = rng.range_f64(0.08, 0.25);
    let (x0, x1, y1) = (24.0, 214.0, 156.0);
    let mut y = 8.0;
    loop {
        let p = rng.f64();
        let mut row = if p < large {
            Row::Large
        } else if p < large + 0.45 {
            Row::Medium
        } else {
            Row::Small
        };
        let mut h = match row {
            Row::Small => 3.0,
            Row::Medium => 10.0,
            Row::Large => rng.range_f64(16.0, 30.0),
        };
        if y + h > y1 {
            (row, h) = (Row::Small, 3.0);
            if y + h > y1 {
                break;
            }
        }
        let mut x = x0 + rng.range_f64(0.0, 1.0);
        loop {
            let c = sample(row, h, &mut rng);
            if x + c.fx > x1 {
                break;
            }
            let at = turned(&f.moved(x + c.fx / 2.0, y + h / 2.0, BOARD_T), c.quarter);
            if let Some((part, z)) = c.on_top {
                put(&mut out, c.part, at);
                put(&mut out, part, at.moved(0.0, 0.0, z));
            } else {
                put(&mut out, c.part, at);
            }
            let gap = match row {
                Row::Small => rng.range_f64(0.6, 1.2),
                Row::Medium => rng.range_f64(1.0, 2.5),
                Row::Large => rng.range_f64(1.5, 4.0),
            };
            x += c.fx + gap;
            debug_assert!(c.fy <= h + 1e-9);
        }
        y += h + 1.0;
    }
    out
}

/// One random component for a row of height `h` (its footprint across the row fits in `h`).
fn sample(row: Row, h: f64, rng: &mut Rng) -> Comp {
    let p = rng.f64();
    let flat = |part: Part, fx: f64, fy: f64, quarter: u32| Comp { part, fx, fy, quarter, on_top: None };
    match row {
        Row::Small => {
            if p < 0.85 {
                let resistor = p >= 0.45;
                let sizes: &[(f64, f64, f64)] = if resistor {
                    &[(1.0, 0.5, 0.35), (1.6, 0.8, 0.45), (2.0, 1.25, 0.5), (3.2, 1.6, 0.55)]
                } else {
                    &[(1.0, 0.5, 0.5), (1.6, 0.8, 0.8), (2.0, 1.25, 0.9)]
                };
                let (l, w, hh) = *rng.pick(sizes);
                let q = rng.range_u32(0, 4);
                let q = if l > h { q & 2 } else { q };
                let (fx, fy) = if q % 2 == 0 { (l, w) } else { (w, l) };
                flat(Part::Chip { l, w, h: hh, resistor }, fx, fy, q)
            } else {
                let legs = *rng.pick(&[3, 3, 3, 5, 6]);
                let q = 2 * rng.range_u32(0, 2);
                flat(Part::Sot { l: 2.9, w: 1.3, h: 1.0, legs }, 2.9, 2.5, q)
            }
        }
        Row::Medium => {
            let q = 2 * rng.range_u32(0, 2);
            if p < 0.40 {
                let per_side = rng.range_u32(4, 15);
                let w = if rng.chance(0.6) { 3.9 } else { 7.5 };
                let l = per_side as f64 * 1.27 + 0.6;
                let part =
                    Part::LeadedIc { l, w, h: rng.range_f64(1.5, 2.5), per_side, pitch: 1.27, quad: false };
                flat(part, l, w + 2.0, q)
            } else if p < 0.55 {
                let per_side = rng.range_u32(8, 15);
                let l = per_side as f64 * 0.5 + 1.0;
                let part = Part::LeadedIc { l, w: l, h: 1.2, per_side, pitch: 0.5, quad: true };
                flat(part, l + 2.0, l + 2.0, q)
            } else if p < 0.70 {
                let r = rng.range_f64(2.0, 4.5);
                flat(Part::Electrolytic { r, h: rng.range_f64(5.0, 12.0) }, 2.0 * r + 0.6, 2.0 * r + 0.6, 0)
            } else if p < 0.82 {
                let rows = rng.range_u32(1, 3);
                let pins = rng.range_u32(3, 21);
                flat(Part::Header { pins, rows }, pins as f64 * 2.54, rows as f64 * 2.54, 0)
            } else if p < 0.88 {
                flat(Part::Crystal { l: 11.0, w: 4.6, h: 3.5 }, 11.0, 4.6, 0)
            } else if p < 0.94 {
                flat(Part::Toroid { r: 3.0, tube: 1.0 }, 8.0, 8.0, 0)
            } else {
                flat(Part::Chip { l: 6.3, w: 3.2, h: 0.6, resistor: true }, 6.3, 3.2, q)
            }
        }
        Row::Large => {
            let q = rng.range_u32(0, 4);
            if p < 0.35 {
                let pitch = if rng.chance(0.5) { 0.8 } else { 1.0 };
                let most = (((h - 1.0) / pitch).floor() as u32).min(23);
                let n = rng.range_u32(10.min(most), most + 1);
                let size = n as f64 * pitch + pitch;
                let bh = rng.range_f64(1.2, 2.4);
                let part = Part::Bga { size, h: bh, n, pitch };
                let on_top = rng.chance(0.3).then(|| {
                    let fins = rng.range_u32(6, 17);
                    (
                        Part::Heatsink { l: size, w: size, h: rng.range_f64(8.0, 14.0), fins },
                        bh + 0.35 * pitch,
                    )
                });
                Comp { part, fx: size, fy: size, quarter: q, on_top }
            } else if p < 0.65 {
                let pitch = if rng.chance(0.5) { 0.5 } else { 0.65 };
                let most = (((h - 3.5) / pitch).floor() as u32).clamp(12, 52);
                let per_side = rng.range_u32(12, most + 1);
                let l = per_side as f64 * pitch + 1.5;
                let part = Part::LeadedIc { l, w: l, h: 1.4, per_side, pitch, quad: true };
                flat(part, l + 2.0, l + 2.0, q)
            } else if p < 0.80 {
                let l = rng.range_f64(20.0, 60.0);
                let w = rng.range_f64(6.0, h.min(14.0));
                let rows = rng.range_u32(2, 5);
                let per_row = ((l - 1.2) / 1.27).floor() as u32;
                flat(Part::Connector { l, w, h: rng.range_f64(6.0, 10.0), rows, per_row }, l, w, 2 * (q % 2))
            } else if p < 0.90 {
                let r = rng.range_f64(5.0, (h / 2.0 - 0.5).min(8.0));
                flat(Part::Electrolytic { r, h: rng.range_f64(10.0, 16.0) }, 2.0 * r + 0.6, 2.0 * r + 0.6, 0)
            } else {
                let l = rng.range_f64(15.0, 25.0);
                let w = 0.8 * h;
                flat(
                    Part::Heatsink { l, w, h: rng.range_f64(10.0, 15.0), fins: rng.range_u32(5, 13) },
                    l,
                    w,
                    0,
                )
            }
        }
    }
}
