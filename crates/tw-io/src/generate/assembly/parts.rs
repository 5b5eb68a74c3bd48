//! Assembly parts: every kind of thing the assembly generator places, from 12-triangle SMD
//! capacitors to backplane connectors and valves.
//!
//! A [`Part`] is a plain description (sizes, counts, no randomness) placed by a [`Frame`]: the
//! origin at the centre of its footprint on the surface it is mounted on, local z out of that
//! surface, millimetres. Its tessellation comes from a [`Detail`] level, so the same placed part
//! can be counted at several levels ([`Part::triangles`], a dry run through a counting
//! [`Emitter`]) before one is chosen, and counting and emitting always agree.
//!
//! Every part is built only from closed primitives of [`Emitter`] (boxes, capped cylinders and
//! frusta, tori, ring plates), each with vertices of its own, so every part is a closed mesh:
//! each edge is used by exactly two of the part's triangles. Closed triangle meshes have an even
//! number of triangles (3·F = 2·E), so every part's count is even.

use tw_core::Rgba8;

use super::super::shapes::{Emitter, Frame, V3};

/// Object colours.
pub(crate) mod color {
    use tw_core::Rgba8;
    pub const PCB: Rgba8 = Rgba8::rgb(22, 110, 52);
    pub const BACKPLANE: Rgba8 = Rgba8::rgb(30, 70, 130);
    pub const BLACK: Rgba8 = Rgba8::rgb(30, 30, 34);
    pub const CERAMIC: Rgba8 = Rgba8::rgb(190, 160, 110);
    pub const RESISTOR: Rgba8 = Rgba8::rgb(40, 40, 44);
    pub const ALUMINIUM: Rgba8 = Rgba8::rgb(190, 194, 200);
    pub const ELECTROLYTIC: Rgba8 = Rgba8::rgb(40, 60, 140);
    pub const CONNECTOR: Rgba8 = Rgba8::rgb(230, 230, 220);
    pub const HEADER: Rgba8 = Rgba8::rgb(20, 20, 24);
    pub const LED: Rgba8 = Rgba8::rgb(220, 40, 30);
    pub const COPPER: Rgba8 = Rgba8::rgb(184, 115, 51);
    pub const STEEL: Rgba8 = Rgba8::rgb(150, 152, 158);
    pub const ZINC: Rgba8 = Rgba8::rgb(200, 200, 190);
    pub const SHEET: Rgba8 = Rgba8::rgb(205, 208, 212);
    pub const FRAME: Rgba8 = Rgba8::rgb(60, 62, 68);
    pub const GRATING: Rgba8 = Rgba8::rgb(110, 112, 116);
    pub const TRAY: Rgba8 = Rgba8::rgb(170, 172, 160);
    pub const VALVE: Rgba8 = Rgba8::rgb(190, 40, 30);
    pub const PIPE: Rgba8 = Rgba8::rgb(56, 142, 72);
    pub const WIRE: Rgba8 = Rgba8::rgb(230, 180, 30);
}

/// The highest detail level.
pub(crate) const MAX_LEVEL: u32 = 24;

/// Smallest closed tube [`Emitter::cylinder`] makes (3 sides, both ends capped).
const MIN_TUBE: u64 = 8;
/// Triangles of a cable tie (a 3 × 3 torus), the one closed shape with a count ≡ 2 (mod 4)
/// used by the harness.
const TIE: u64 = 18;
/// Most sides of one harness wire (a wire of `s` sides has `4s − 4` triangles).
const WIRE_SIDES: u64 = 32;
/// The fewest triangles a [`Part::Harness`] can take: a tie plus the smallest wire.
pub(crate) const MIN_HARNESS: u64 = TIE + MIN_TUBE;

/// Tessellation for one detail level. Every count grows with the level, so a board's triangle
/// count is monotone in it (the board layout searches over it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Detail {
    pub level: u32,
    /// Sides of round bodies: capacitor cans, screw heads, fans, valves (6..=30).
    pub round: u32,
    /// Sides of connector and header pins (4..=16).
    pub pin: u32,
    /// Sides of BGA balls (4..=24).
    pub ball: u32,
    /// Chip resistors get separate terminations (3 boxes instead of 1).
    pub terminations: bool,
    /// Chip capacitors get separate terminations too.
    pub cap_terminations: bool,
    /// Gull-wing legs of three boxes (shoulder, drop, foot) instead of one.
    pub gull: bool,
}

impl Detail {
    pub fn new(level: u32) -> Detail {
        let l = level.min(MAX_LEVEL);
        Detail {
            level: l,
            round: 6 + l,
            pin: 4 + l / 2,
            ball: 4 + 5 * l / 6,
            terminations: l >= 1,
            cap_terminations: l >= 12,
            gull: l >= 3,
        }
    }
}

/// One kind of part with its sizes (millimetres).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Part {
    /// A bare circuit board `l × w`, `t` thick, from its corner (frame origin) up.
    Board { l: f64, w: f64, t: f64, backplane: bool },
    /// An SMD chip resistor or capacitor `l × w × h`: one box of 12 triangles, or a body and two
    /// terminations (resistors from level 1, capacitors from level 12).
    Chip { l: f64, w: f64, h: f64, resistor: bool },
    /// A SOT-23-like transistor: body and `legs` gull-wing legs on its two long sides.
    Sot { l: f64, w: f64, h: f64, legs: u32 },
    /// A leaded IC (SOIC with `quad == false`, QFP with legs on all four sides).
    LeadedIc { l: f64, w: f64, h: f64, per_side: u32, pitch: f64, quad: bool },
    /// A ball-grid array: substrate and mould cap `size` square on `n × n` balls.
    Bga { size: f64, h: f64, n: u32, pitch: f64 },
    /// An electrolytic capacitor can of radius `r`, height `h` on a plastic base.
    Electrolytic { r: f64, h: f64 },
    /// A pin header: `rows × pins` square pins through a plastic strip.
    Header { pins: u32, rows: u32 },
    /// A connector: housing `l × w × h` with `rows × per_row` round pins and a shroud.
    Connector { l: f64, w: f64, h: f64, rows: u32, per_row: u32 },
    /// A finned heatsink `l × w` on its base, `fins` fins, `h` high.
    Heatsink { l: f64, w: f64, h: f64, fins: u32 },
    /// A quartz crystal (HC-49 style: a box between two half-round ends).
    Crystal { l: f64, w: f64, h: f64 },
    /// A through-hole LED: body and collar.
    Led { r: f64, h: f64 },
    /// A toroidal choke on a base plate.
    Toroid { r: f64, tube: f64 },
    /// A screw: head of radius `head` (height `0.6·head`) on a shank of radius `r` reaching
    /// `len` into the surface.
    Screw { r: f64, head: f64, len: f64 },
    /// A flat washer.
    Washer { r_in: f64, r_out: f64, t: f64 },
    /// A hex nut `a` across corners, `h` high, with a hexagonal hole.
    Nut { a: f64, h: f64 },
    /// A hex standoff `a` across corners, `h` high.
    Standoff { a: f64, h: f64 },
    /// A sheet-metal or plastic box `min..max` (panels, posts, rails, guides, brackets).
    Sheet { min: V3, max: V3, kind: Sheet },
    /// A front-panel handle: two posts and a grip bar, `span` apart.
    Handle { span: f64, r: f64, h: f64 },
    /// A grating `l × w` of bars `pitch` apart (bearing bars along x, cross bars every 4).
    Grating { l: f64, w: f64, pitch: f64 },
    /// A ladder cable tray `l` long (along x), `w` wide, rungs every `pitch`.
    Tray { l: f64, w: f64, h: f64, pitch: f64 },
    /// An axial fan `size` square: frame bars, hub and `blades` blades.
    Fan { size: f64, depth: f64, blades: u32 },
    /// A straight pipe along local z of radius `r`, `len` long.
    Pipe { r: f64, len: f64 },
    /// A flange (ring plate) on a pipe of radius `r`, along local z.
    Flange { r: f64, r_out: f64, t: f64 },
    /// A hex bolt along local z: head above the surface, shank `len` into it.
    Bolt { a: f64, len: f64 },
    /// A gate valve on a pipe of radius `r` (pipe along local x): body, bonnet, stem and hand wheel.
    Valve { r: f64 },
    /// A wire harness along local x, `len` long, of exactly `triangles` triangles (even, at least
    /// [`MIN_HARNESS`]): wires of up to 32 sides and a cable tie when the count needs one.
    Harness { len: f64, triangles: u64 },
}

/// What a [`Part::Sheet`] is, for its designator and colour.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Sheet {
    /// Cabinet posts, rails and frame members.
    Frame,
    /// Cabinet panels and board front panels.
    Panel,
    /// Card guides and cage plates.
    Guide,
}

/// A part and where it goes.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Placed {
    pub part: Part,
    pub frame: Frame,
}

impl Placed {
    /// Exact triangle count at detail `d` (a dry run).
    pub fn triangles(&self, d: &Detail) -> u64 {
        let mut c = Emitter::counting();
        self.part.emit(&mut c, &self.frame, d);
        c.triangles()
    }
}

/// `f` turned by `quarter` quarter turns about its own z axis.
pub(crate) fn turned(f: &Frame, quarter: u32) -> Frame {
    let (x, y) = match quarter % 4 {
        0 => (f.x, f.y),
        1 => (f.y, neg(f.x)),
        2 => (neg(f.x), neg(f.y)),
        _ => (neg(f.y), f.x),
    };
    Frame { o: f.o, x, y, z: f.z }
}

/// `f` turned by `angle` radians about its own z axis.
fn rotated(f: &Frame, angle: f64) -> Frame {
    let (s, c) = angle.sin_cos();
    let mix = |a: V3, b: V3, ka: f64, kb: f64| {
        [ka * a[0] + kb * b[0], ka * a[1] + kb * b[1], ka * a[2] + kb * b[2]]
    };
    Frame { o: f.o, x: mix(f.x, f.y, c, s), y: mix(f.x, f.y, -s, c), z: f.z }
}

fn neg(v: V3) -> V3 {
    [-v[0], -v[1], -v[2]]
}

/// A closed cylinder along local z.
fn tube(e: &mut Emitter<'_>, f: &Frame, r: f64, z0: f64, z1: f64, sides: u32) {
    e.cylinder(f, r, z0, z1, sides, true, true);
}

/// A gull-wing leg leaving a body's side at local `(x, y)` outwards along +y of `f` (turned so),
/// reaching `reach` beyond the side; the body is `h` high.
#[allow(clippy::too_many_arguments)]
fn gull_leg(e: &mut Emitter<'_>, f: &Frame, x: f64, y: f64, w: f64, reach: f64, h: f64, d: &Detail) {
    let t = 0.15_f64.min(h / 4.0);
    let zs = (h / 2.0).max(2.0 * t);
    if d.gull {
        e.cuboid(f, [x - w / 2.0, y, zs - t], [x + w / 2.0, y + reach * 0.4, zs]);
        e.cuboid(f, [x - w / 2.0, y + reach * 0.4, t], [x + w / 2.0, y + reach * 0.4 + t, zs]);
        e.cuboid(f, [x - w / 2.0, y + reach * 0.4, 0.0], [x + w / 2.0, y + reach, t]);
    } else {
        e.cuboid(f, [x - w / 2.0, y, 0.0], [x + w / 2.0, y + reach, t]);
    }
}

impl Part {
    /// The designator prefix of the part (its object name is this plus a number).
    pub fn prefix(&self) -> &'static str {
        match self {
            Part::Board { backplane: false, .. } => "PCB",
            Part::Board { backplane: true, .. } => "BP",
            Part::Chip { resistor: true, .. } => "R",
            Part::Chip { resistor: false, .. } | Part::Electrolytic { .. } => "C",
            Part::Sot { .. } => "Q",
            Part::LeadedIc { .. } | Part::Bga { .. } => "U",
            Part::Header { .. } | Part::Connector { .. } => "J",
            Part::Heatsink { .. } => "HS",
            Part::Crystal { .. } => "Y",
            Part::Led { .. } => "D",
            Part::Toroid { .. } => "L",
            Part::Screw { .. } => "S",
            Part::Washer { .. } => "WA",
            Part::Nut { .. } => "N",
            Part::Standoff { .. } => "ST",
            Part::Sheet { .. } | Part::Handle { .. } | Part::Fan { .. } => "MP",
            Part::Grating { .. } => "GR",
            Part::Tray { .. } => "CT",
            Part::Pipe { .. } => "P",
            Part::Flange { .. } => "FL",
            Part::Bolt { .. } => "B",
            Part::Valve { .. } => "V",
            Part::Harness { .. } => "W",
        }
    }

    pub fn color(&self) -> Rgba8 {
        match self {
            Part::Board { backplane: false, .. } => color::PCB,
            Part::Board { backplane: true, .. } => color::BACKPLANE,
            Part::Chip { resistor: true, .. } => color::RESISTOR,
            Part::Chip { resistor: false, .. } => color::CERAMIC,
            Part::Sot { .. } | Part::LeadedIc { .. } | Part::Bga { .. } | Part::Crystal { .. } => {
                color::BLACK
            }
            Part::Header { .. } => color::HEADER,
            Part::Electrolytic { .. } => color::ELECTROLYTIC,
            Part::Connector { .. } => color::CONNECTOR,
            Part::Heatsink { .. } => color::ALUMINIUM,
            Part::Led { .. } => color::LED,
            Part::Toroid { .. } => color::COPPER,
            Part::Screw { .. } | Part::Nut { .. } | Part::Washer { .. } | Part::Bolt { .. } => color::ZINC,
            Part::Standoff { .. } => color::COPPER,
            Part::Sheet { kind: Sheet::Frame, .. } | Part::Handle { .. } | Part::Fan { .. } => color::FRAME,
            Part::Sheet { kind: Sheet::Panel, .. } => color::SHEET,
            Part::Sheet { kind: Sheet::Guide, .. } => color::STEEL,
            Part::Grating { .. } => color::GRATING,
            Part::Tray { .. } => color::TRAY,
            Part::Pipe { .. } | Part::Flange { .. } => color::PIPE,
            Part::Valve { .. } => color::VALVE,
            Part::Harness { .. } => color::WIRE,
        }
    }

    /// Writes the part's geometry (no object is announced) in frame `f` at detail `d`.
    pub fn emit(&self, e: &mut Emitter<'_>, f: &Frame, d: &Detail) {
        match *self {
            Part::Board { l, w, t, .. } => e.cuboid(f, [0.0, 0.0, 0.0], [l, w, t]),
            Part::Chip { l, w, h, resistor } => chip(e, f, d, [l, w, h], resistor),
            Part::Sot { l, w, h, legs } => sot(e, f, d, [l, w, h], legs),
            Part::LeadedIc { l, w, h, per_side, pitch, quad } => {
                leaded_ic(e, f, d, [l, w, h], per_side, pitch, quad)
            }
            Part::Bga { size, h, n, pitch } => bga(e, f, d, size, h, n, pitch),
            Part::Electrolytic { r, h } => {
                let b = 2.0 * r + 0.6;
                e.cuboid(f, [-b / 2.0, -b / 2.0, 0.0], [b / 2.0, b / 2.0, 0.5]);
                tube(e, f, r, 0.5, h - 0.3, d.round);
                e.frustum(f, r, 0.9 * r, h - 0.3, h, d.round, true, true);
            }
            Part::Header { pins, rows } => header(e, f, d, pins, rows),
            Part::Connector { l, w, h, rows, per_row } => connector(e, f, d, [l, w, h], rows, per_row),
            Part::Heatsink { l, w, h, fins } => heatsink(e, f, [l, w, h], fins),
            Part::Crystal { l, w, h } => {
                let r = w / 2.0;
                e.cuboid(f, [-l / 2.0 + r, -w / 2.0, 0.0], [l / 2.0 - r, w / 2.0, h]);
                for x in [-l / 2.0 + r, l / 2.0 - r] {
                    tube(e, &f.moved(x, 0.0, 0.0), r, 0.0, h, (d.round / 2).max(4));
                }
            }
            Part::Led { r, h } => {
                tube(e, f, 1.15 * r, 0.0, 1.0, d.round);
                e.frustum(f, r, 0.55 * r, 1.0, h, d.round, true, true);
                for x in [-0.4 * r, 0.4 * r] {
                    tube(e, &f.moved(x, 0.0, 0.0), 0.25, -3.0, 0.2, 4);
                }
            }
            Part::Toroid { r, tube: t } => {
                e.cuboid(f, [-r - t, -r - t, 0.0], [r + t, r + t, 0.8]);
                let a = 2 * d.round;
                let b = (d.round / 2).max(3);
                e.torus(&f.moved(0.0, 0.0, 0.8 + t), r, t, a, b);
            }
            Part::Screw { r, head, len } => {
                tube(e, f, head, 0.0, 0.6 * head, d.round);
                tube(e, f, r, -len, 0.0, (d.round / 2).max(6));
            }
            Part::Washer { r_in, r_out, t } => e.ring_plate(f, r_in, r_out, 0.0, t, d.round),
            Part::Nut { a, h } => e.ring_plate(f, 0.45 * a, a / 2.0, 0.0, h, 6),
            Part::Standoff { a, h } => tube(e, f, a / 2.0, 0.0, h, 6),
            Part::Sheet { min, max, .. } => e.cuboid(f, min, max),
            Part::Handle { span, r, h } => {
                for x in [-span / 2.0, span / 2.0] {
                    tube(e, &f.moved(x, 0.0, 0.0), r, 0.0, h, (d.round / 2).max(4));
                }
                let bar = f.moved(-span / 2.0 - r, 0.0, h + r).z_along_x();
                tube(e, &bar, r, 0.0, span + 2.0 * r, (d.round / 2).max(4));
            }
            Part::Grating { l, w, pitch } => grating(e, f, l, w, pitch),
            Part::Tray { l, w, h, pitch } => tray(e, f, [l, w, h], pitch),
            Part::Fan { size, depth, blades } => fan(e, f, d, size, depth, blades),
            Part::Pipe { r, len } => tube(e, f, r, 0.0, len, 2 * d.round),
            Part::Flange { r, r_out, t } => e.ring_plate(f, r, r_out, 0.0, t, 2 * d.round),
            Part::Bolt { a, len } => {
                tube(e, f, a / 2.0, 0.0, 0.6 * a, 6);
                tube(e, f, 0.28 * a, -len, 0.0, (d.round / 2).max(6));
            }
            Part::Valve { r } => {
                let g = f.z_along_x();
                tube(e, &g, 1.4 * r, -1.5 * r, 1.5 * r, 2 * d.round);
                tube(e, f, 1.0 * r, 1.2 * r, 3.0 * r, d.round);
                tube(e, f, 0.15 * r, 3.0 * r, 5.0 * r, (d.round / 2).max(6));
                e.torus(&f.moved(0.0, 0.0, 5.0 * r), 1.2 * r, 0.12 * r, 2 * d.round, (d.round / 2).max(4));
            }
            Part::Harness { len, triangles } => harness(e, f, len, triangles),
        }
    }
}

/// A chip resistor or capacitor: a body, with its two end terminations at details that show them.
fn chip(e: &mut Emitter<'_>, f: &Frame, d: &Detail, [l, w, h]: [f64; 3], resistor: bool) {
    if (resistor && d.terminations) || (!resistor && d.cap_terminations) {
        let c = 0.2 * l;
        e.cuboid(f, [-l / 2.0 + c, -w / 2.0, 0.02], [l / 2.0 - c, w / 2.0, h - 0.02]);
        e.cuboid(f, [-l / 2.0, -w / 2.0, 0.0], [-l / 2.0 + c, w / 2.0, h]);
        e.cuboid(f, [l / 2.0 - c, -w / 2.0, 0.0], [l / 2.0, w / 2.0, h]);
    } else {
        e.cuboid(f, [-l / 2.0, -w / 2.0, 0.0], [l / 2.0, w / 2.0, h]);
    }
}

/// A small-outline transistor: a body and its gull-wing legs, split between two sides.
fn sot(e: &mut Emitter<'_>, f: &Frame, d: &Detail, [l, w, h]: [f64; 3], legs: u32) {
    e.cuboid(f, [-l / 2.0, -w / 2.0, 0.1], [l / 2.0, w / 2.0, h]);
    let (south, north) = (legs / 2, legs - legs / 2);
    for (n, side) in [(south, 2), (north, 0)] {
        let g = turned(f, side);
        for i in 0..n {
            let x = (i as f64 + 0.5 - n as f64 / 2.0) * l / n as f64;
            gull_leg(e, &g, x, w / 2.0, 0.4, 0.6, h, d);
        }
    }
}

/// A leaded IC (SOIC, QFP): a body with a pin-1 mark and gull-wing legs on two or four sides.
fn leaded_ic(
    e: &mut Emitter<'_>,
    f: &Frame,
    d: &Detail,
    [l, w, h]: [f64; 3],
    per_side: u32,
    pitch: f64,
    quad: bool,
) {
    e.cuboid(f, [-l / 2.0, -w / 2.0, 0.1], [l / 2.0, w / 2.0, h]);
    // Pin-1 mark: a shallow dimple standing proud of the top (kept closed).
    let r = 0.08 * w.min(l);
    tube(e, &f.moved(-l / 2.0 + 2.0 * r, -w / 2.0 + 2.0 * r, 0.0), r, h, h + 0.05, d.round.min(12));
    let sides: &[(u32, f64, f64)] =
        if quad { &[(0, w, l), (1, l, w), (2, w, l), (3, l, w)] } else { &[(0, w, l), (2, w, l)] };
    for &(q, across, along) in sides {
        let g = turned(f, q);
        for i in 0..per_side {
            let x = (i as f64 - (per_side as f64 - 1.0) / 2.0) * pitch;
            debug_assert!(x.abs() < along / 2.0);
            gull_leg(e, &g, x, across / 2.0, 0.45 * pitch, 1.0, h, d);
        }
    }
}

/// A ball grid array: the grid of solder balls, the substrate on them and the mould cap.
fn bga(e: &mut Emitter<'_>, f: &Frame, d: &Detail, size: f64, h: f64, n: u32, pitch: f64) {
    let zb = 0.35 * pitch;
    let rb = 0.3 * pitch;
    let half = (n as f64 - 1.0) / 2.0;
    for i in 0..n {
        for j in 0..n {
            let g = f.moved((i as f64 - half) * pitch, (j as f64 - half) * pitch, 0.0);
            tube(e, &g, rb, 0.0, zb, d.ball);
        }
    }
    e.cuboid(f, [-size / 2.0, -size / 2.0, zb], [size / 2.0, size / 2.0, zb + 0.4]);
    let m = 0.9 * size;
    e.cuboid(f, [-m / 2.0, -m / 2.0, zb + 0.4], [m / 2.0, m / 2.0, h]);
}

/// A pin header at 2.54 mm pitch: the plastic base and a pin through it per position.
fn header(e: &mut Emitter<'_>, f: &Frame, d: &Detail, pins: u32, rows: u32) {
    let p = 2.54;
    let (l, w) = (pins as f64 * p, rows as f64 * p);
    e.cuboid(f, [-l / 2.0, -w / 2.0, 0.0], [l / 2.0, w / 2.0, 2.5]);
    for i in 0..pins {
        for j in 0..rows {
            let x = (i as f64 + 0.5) * p - l / 2.0;
            let y = (j as f64 + 0.5) * p - w / 2.0;
            tube(e, &f.moved(x, y, 0.0), 0.36, -3.0, 8.5, d.pin);
        }
    }
}

/// A box connector: a floor, four walls and a contact pin per position.
fn connector(e: &mut Emitter<'_>, f: &Frame, d: &Detail, [l, w, h]: [f64; 3], rows: u32, per_row: u32) {
    let wall = 0.6;
    e.cuboid(f, [-l / 2.0, -w / 2.0, 0.0], [l / 2.0, w / 2.0, 0.4 * h]);
    for (y0, y1) in [(-w / 2.0, -w / 2.0 + wall), (w / 2.0 - wall, w / 2.0)] {
        e.cuboid(f, [-l / 2.0, y0, 0.4 * h], [l / 2.0, y1, h]);
    }
    for (x0, x1) in [(-l / 2.0, -l / 2.0 + wall), (l / 2.0 - wall, l / 2.0)] {
        e.cuboid(f, [x0, -w / 2.0 + wall, 0.4 * h], [x1, w / 2.0 - wall, h]);
    }
    let (px, py) = ((l - 2.0 * wall) / per_row as f64, (w - 2.0 * wall) / rows as f64);
    let r = 0.2 * px.min(py);
    for i in 0..per_row {
        for j in 0..rows {
            let x = -l / 2.0 + wall + (i as f64 + 0.5) * px;
            let y = -w / 2.0 + wall + (j as f64 + 0.5) * py;
            tube(e, &f.moved(x, y, 0.0), r, -2.5, 0.85 * h, d.pin);
        }
    }
}

/// A heatsink: a base plate and its fins across it.
fn heatsink(e: &mut Emitter<'_>, f: &Frame, [l, w, h]: [f64; 3], fins: u32) {
    e.cuboid(f, [-l / 2.0, -w / 2.0, 0.0], [l / 2.0, w / 2.0, 1.5]);
    let t = (0.4 * l / fins as f64).min(1.2);
    for i in 0..fins {
        let x = -l / 2.0 + (i as f64 + 0.5) * l / fins as f64;
        e.cuboid(f, [x - t / 2.0, -w / 2.0, 1.5], [x + t / 2.0, w / 2.0, h]);
    }
}

/// A floor grating: bearing bars at `pitch` and cross bars under them every fourth pitch.
fn grating(e: &mut Emitter<'_>, f: &Frame, l: f64, w: f64, pitch: f64) {
    let mut y = pitch / 2.0;
    while y < w {
        e.cuboid(f, [0.0, y - 1.5, -30.0], [l, y + 1.5, 0.0]);
        y += pitch;
    }
    let mut x = 2.0 * pitch;
    while x < l {
        e.cuboid(f, [x - 2.0, 0.0, -10.0], [x + 2.0, w, 0.0]);
        x += 4.0 * pitch;
    }
}

/// A ladder cable tray: two side rails and rungs at `pitch`.
fn tray(e: &mut Emitter<'_>, f: &Frame, [l, w, h]: [f64; 3], pitch: f64) {
    for y in [0.0, w - 2.0] {
        e.cuboid(f, [0.0, y, 0.0], [l, y + 2.0, h]);
    }
    let mut x = pitch / 2.0;
    while x < l {
        e.cuboid(f, [x - 10.0, 2.0, 0.0], [x + 10.0, w - 2.0, 2.0]);
        x += pitch;
    }
}

/// A fan: the square frame, the hub and its blades.
fn fan(e: &mut Emitter<'_>, f: &Frame, d: &Detail, size: f64, depth: f64, blades: u32) {
    let bar = 0.08 * size;
    let s2 = size / 2.0;
    e.cuboid(f, [-s2, -s2, 0.0], [s2, -s2 + bar, depth]);
    e.cuboid(f, [-s2, s2 - bar, 0.0], [s2, s2, depth]);
    e.cuboid(f, [-s2, -s2 + bar, 0.0], [-s2 + bar, s2 - bar, depth]);
    e.cuboid(f, [s2 - bar, -s2 + bar, 0.0], [s2, s2 - bar, depth]);
    let hub = 0.18 * size;
    tube(e, f, hub, 0.1 * depth, 0.9 * depth, d.round);
    for k in 0..blades {
        let g = rotated(f, std::f64::consts::TAU * k as f64 / blades as f64);
        e.cuboid(&g, [hub * 0.8, -0.09 * size, 0.35 * depth], [s2 - bar - 1.0, 0.09 * size, 0.45 * depth]);
    }
}

/// Wires along local x (each a closed tube of `4s − 4` triangles) and, when the count is
/// 2 mod 4, one cable tie: exactly `triangles` triangles for any even count from
/// [`MIN_HARNESS`] up (counts below it, or odd ones, are rounded down to what is possible).
fn harness(e: &mut Emitter<'_>, f: &Frame, len: f64, triangles: u64) {
    let mut left = triangles;
    if left % 4 == 2 && left >= MIN_HARNESS {
        let tie = f.moved(len / 2.0, 0.0, 1.0).z_along_x();
        e.torus(&tie, 1.6, 0.3, 3, 3);
        left -= TIE;
    }
    let most = 4 * WIRE_SIDES - 4;
    let mut i = 0u64;
    while left >= MIN_TUBE {
        let w = (if left <= most { left } else { most.min(left - MIN_TUBE) }) / 4 * 4;
        let sides = (w + 4) / 4;
        let (row, layer) = ((i % 3) as f64, (i / 3) as f64);
        let g = f.moved(0.0, (row - 1.0) * 0.9, 0.5 + layer * 0.9).z_along_x();
        tube(e, &g, 0.4, 0.0, len, sides as u32);
        left -= w;
        i += 1;
    }
}
