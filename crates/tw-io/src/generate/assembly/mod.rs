//! The procedural CAD assembly: electronics cabinets full of populated circuit boards, in
//! millimetres, at any size from 10^4 to 10^9 triangles.
//!
//! Real CAD exports of PCB assemblies and machinery are tens of thousands of small closed parts
//! (50–5,000 triangles each, many of them tiny: pins, screws, SMD resistors and capacitors of
//! 12 triangles) packed densely on boards and in racks, often written as one object with no ids.
//! That is what this scene is, and why it is hard where the power plant is easy: there are no
//! large connected surfaces to simplify, only a dust of disjoint closed parts a few millimetres
//! across, so a level of detail that merges or drops small parts changes the silhouette of a
//! whole board, and with `One` object there are no part boundaries to lean on.
//!
//! # Layout
//!
//! A grid of cabinets (600 × 800 × 2000 mm, x along the row, y from the cabinet front to the
//! back, z up, the floor at z = 0), each followed along y by a 600 mm aisle. A cabinet holds up to
//! six card cages of twenty 6U boards (233.35 × 160 × 1.6 mm, 22.5 mm apart, standing on edge,
//! component side towards +x). Its structure (`layout::cabinet_parts`): plinth, posts, side,
//! back and roof panels, cage plates and rails; at higher structure levels card guides and a
//! backplane per cage, a backplane connector per board with standoffs and screws, mounting rails
//! with screws and washers, a fan tray with fans, a ladder cable tray on the roof, and in the
//! aisle a floor grating and a cooling water line (pipes on supports, a valve between two
//! flanges with bolts and nuts).
//!
//! A board (`layout::Board`): the bare board, a front panel with handle, screws, washers and
//! LEDs, a 160-pin rear connector, four mounting screws with washers and nuts, then rows of
//! components packed over the top side: rows of SMD resistors and capacitors (12 or 36
//! triangles) and SOT transistors; rows of SOICs, small QFPs, electrolytic capacitors, pin
//! headers, crystals and chokes; rows of BGAs (up to 27 × 27 balls, some under a heatsink), large
//! QFPs, connectors, big capacitors and heatsinks. The bottom side holds a grid of 0402 and
//! 0603 capacitors and resistors. Every part is a closed mesh built from closed primitives
//! (`parts.rs`), and parts share no vertices.
//!
//! # How N maps to the assembly
//!
//! 1. The count generated is N rounded down to even: a closed triangle mesh has an even number
//!    of triangles (each edge is shared by two triangles, so 3·F = 2·E), and every part is
//!    closed. So the total is exactly N for even N and N − 1 for odd N.
//! 2. Boards: `B = round(N / b)` with `b = max(4000, 90000 · (N / 10^7)^(1/5))` triangles per
//!    board, filling cabinets of 120 boards in order on a near-square grid (`layout::Plan`):
//!    1 board at 10^4, 18 in one cabinet at 10^6, 111 in one cabinet (0.6 × 1.4 m with its
//!    aisle) at 10^7, 701 in 6 cabinets (1.8 × 2.8 m) at 10^8, 4,423 in 37 cabinets
//!    (4.2 × 8.4 m) at 10^9. Both the number of boards and their detail grow with N: a fully
//!    populated board (about 1,500 parts) is about 67 k triangles at detail level 0 and 300 k at
//!    level 24; boards are at level 0–1 at 10^7 and about 11 at 10^9.
//! 3. The cabinet structures take at most 15 % of N: the highest structure level (0–6) whose
//!    exact count (a dry run) fits. The boards share the rest evenly, each an exact even budget.
//! 4. A board uses its budget exactly (`layout::Board`): all its parts at the highest detail
//!    level (0–24: sides of round parts, pins and BGA balls, terminations, gull-wing legs) whose
//!    exact count fits, the parts that gain most one level finer while the budget allows, then a
//!    wire harness of closed wires (and a cable tie when the count is 2 mod 4) of exactly the
//!    remaining triangles (at least 26, a few dozen as a rule). Below about 5·10^6 triangles even
//!    level 0 does not fit: small parts are placed first (up to 60 % of the budget), then the
//!    others in board order where they fit, and the rest are left unplaced.
//!
//! The result at 10^6: about 30 k parts; at 10^7: about 190 k; at 10^9: about 7.6 M. Passives
//! dominate as they do on real boards: the median part is a 12-triangle chip, the 90th
//! percentile 36–48 triangles, the 99th 400–700, the largest about 10 k (a BGA of 23 × 23 balls).
//!
//! # Objects
//!
//! [`AssemblyObjects::PerPart`] writes one object per part, named by a designator (`R123`,
//! `C45`, `U7`, `J2`, `S4`, `MP12`, …; numbered per board and per cabinet, so the names repeat
//! across boards as they do in CAD) with a colour per kind; [`AssemblyObjects::One`] writes the
//! same triangles as a single object, like a PLY export of a whole assembly.
//!
//! # Streaming and determinism
//!
//! Generation keeps one cabinet's structure or one board's layout (a few thousand part
//! descriptions) and one mesh chunk in memory, whatever N is. Every random choice comes from a
//! [`tw_core::Rng`] stream of its own (board or cabinet, and what), so the assembly depends only
//! on `(triangles, seed)`; the object mode changes only how the triangles are grouped.

mod layout;
mod parts;

use tw_core::{Aabb, Rgba8};

use super::shapes::Emitter;
use crate::{ImportError, SourceSummary, TriangleSink, TriangleSource};
use layout::{cabinet_parts, structure_detail, Board, Plan, BOTTOM, CAB_W, PITCH_Y, TOP};
use parts::{Detail, Placed};

/// The smallest assembly [`AssemblySource::new`] accepts.
pub const MIN_ASSEMBLY_TRIANGLES: u64 = 10_000;
/// The largest assembly [`AssemblySource::new`] accepts.
pub const MAX_ASSEMBLY_TRIANGLES: u64 = 1_000_000_000;

/// How the parts are grouped into objects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum AssemblyObjects {
    /// One object per part, named by its designator, with a colour per kind.
    #[default]
    PerPart,
    /// Everything in a single object (a whole-assembly export without ids).
    One,
}

/// What to generate: the number of triangles (rounded down to even), the seed and the
/// grouping into objects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct AssemblyParams {
    pub triangles: u64,
    pub seed: u64,
    pub objects: AssemblyObjects,
}

/// A [`TriangleSource`] that generates the assembly as it streams.
#[derive(Clone, Debug)]
pub struct AssemblySource {
    params: AssemblyParams,
}

impl AssemblySource {
    /// Checks the parameters: `triangles` must be within
    /// [`MIN_ASSEMBLY_TRIANGLES`]`..=`[`MAX_ASSEMBLY_TRIANGLES`].
    pub fn new(params: AssemblyParams) -> Result<AssemblySource, ImportError> {
        let range = MIN_ASSEMBLY_TRIANGLES..=MAX_ASSEMBLY_TRIANGLES;
        super::check_triangles("generated assembly", params.triangles, range)?;
        Ok(AssemblySource { params })
    }

    pub fn params(&self) -> AssemblyParams {
        self.params
    }

    /// The number of triangles the stream will have: the request rounded down to even.
    pub fn triangles(&self) -> u64 {
        self.params.triangles & !1
    }
}

/// The colour of the single object in [`AssemblyObjects::One`] mode.
const ONE_COLOR: Rgba8 = Rgba8::rgb(120, 140, 120);

/// A part's object name: its designator prefix and number (no allocation until the sink asks).
struct Designator(&'static str, u32);

impl std::fmt::Display for Designator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}{}", self.0, self.1)
    }
}

/// Writes parts, one object each when `per_part`, numbering designators per prefix from 1.
struct PartWriter {
    per_part: bool,
    numbers: Vec<(&'static str, u32)>,
}

impl PartWriter {
    /// Starts a new numbering (a new board or cabinet).
    fn restart(&mut self) {
        self.numbers.clear();
    }

    fn write<'p>(&mut self, e: &mut Emitter<'_>, parts: impl IntoIterator<Item = (&'p Placed, &'p Detail)>) {
        for (p, d) in parts {
            if self.per_part {
                let prefix = p.part.prefix();
                let n = match self.numbers.iter_mut().find(|(k, _)| *k == prefix) {
                    Some((_, n)) => {
                        *n += 1;
                        *n
                    }
                    None => {
                        self.numbers.push((prefix, 1));
                        1
                    }
                };
                e.begin(Designator(prefix, n), p.part.color());
            }
            p.part.emit(e, &p.frame, d);
        }
    }
}

impl TriangleSource for AssemblySource {
    fn name(&self) -> String {
        let mode = match self.params.objects {
            AssemblyObjects::PerPart => "",
            AssemblyObjects::One => ", one object",
        };
        format!("generated assembly ({} triangles, seed {}{mode})", self.params.triangles, self.params.seed)
    }

    fn progress_total(&self) -> Option<u64> {
        Some(self.triangles())
    }

    /// Streams every cabinet's structure followed by its boards: exactly `triangles` rounded
    /// down to even, every part closed, none of the triangles degenerate.
    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        let plan = Plan::new(&self.params);
        let per_part = self.params.objects == AssemblyObjects::PerPart;
        let mut e = Emitter::new(sink);
        if !per_part {
            e.begin("assembly", ONE_COLOR);
        }
        let mut w = PartWriter { per_part, numbers: Vec::new() };
        let structure = structure_detail(plan.structure_level);
        for c in 0..plan.cabinets {
            w.restart();
            let cabinet = cabinet_parts(&plan, c, plan.structure_level);
            w.write(&mut e, cabinet.iter().map(|p| (p, &structure)));
            for b in plan.cabinet_boards(c) {
                let board = Board::new(&plan, b);
                w.restart();
                w.write(&mut e, board.parts.iter().map(|(p, d)| (p, d)));
                if e.failed() {
                    break;
                }
            }
            if e.failed() {
                break;
            }
        }
        e.finish()?;
        debug_assert_eq!(e.triangles(), plan.triangles);
        Ok(SourceSummary { objects: e.objects(), vertices: e.vertices(), bytes: 0 })
    }
}

/// The assembly's bounds in millimetres, computed without generating: every generated
/// triangle lies inside.
pub fn assembly_bounds(params: &AssemblyParams) -> Aabb {
    let plan = Plan::new(params);
    Aabb { min: [0.0, 0.0, BOTTOM], max: [plan.cols as f64 * CAB_W, plan.rows as f64 * PITCH_Y, TOP] }
}

#[cfg(test)]
mod tests;
