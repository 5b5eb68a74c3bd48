//! Plant parts: every kind of thing the generator places, from 2 cm bolts to storage tanks.
//!
//! A part is a plain description (an [`Item`]: position, sizes, tessellation) with no randomness
//! left in it, so that counting it ([`Item::triangles`], a dry run through a counting
//! [`Emitter`]) and emitting it give the same triangles. Each part announces its own objects: a
//! flange and each of its bolts are separate objects, as in a CAD export.
//!
//! Sizes are in metres, z up. Tessellation comes from a [`Detail`] level chosen by the plan.

use tw_core::Rgba8;

use super::shapes::{add, cross, length, normalize, scale, sub, Emitter, Frame, V3};

/// Object colours.
pub(crate) mod color {
    use tw_core::Rgba8;
    pub const CONCRETE: Rgba8 = Rgba8::rgb(168, 166, 160);
    pub const GROUND: Rgba8 = Rgba8::rgb(96, 98, 92);
    pub const STEEL: Rgba8 = Rgba8::rgb(88, 104, 122);
    pub const GRATING: Rgba8 = Rgba8::rgb(80, 82, 86);
    pub const YELLOW: Rgba8 = Rgba8::rgb(232, 188, 32);
    pub const SILVER: Rgba8 = Rgba8::rgb(200, 202, 208);
    pub const PUMP: Rgba8 = Rgba8::rgb(40, 86, 170);
    pub const EXCHANGER: Rgba8 = Rgba8::rgb(70, 130, 96);
    pub const VALVE: Rgba8 = Rgba8::rgb(190, 40, 30);
    pub const FLANGE: Rgba8 = Rgba8::rgb(112, 112, 118);
    pub const BOLT: Rgba8 = Rgba8::rgb(64, 64, 70);
    pub const CABINET: Rgba8 = Rgba8::rgb(214, 206, 180);
    pub const PIPE: Rgba8 = Rgba8::rgb(56, 142, 72);
}

/// The highest detail level.
pub(crate) const MAX_LEVEL: u32 = 48;

/// Tessellation and clutter for one detail level; every count grows with the level, so the
/// triangle count of a building is monotone in it (the plan searches over it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Detail {
    pub level: u32,
    /// Sides of vessels, domes and big cylinders (6..=48).
    pub sides: u32,
    /// Rings of domes and other doubly curved surfaces (1..=8).
    pub rings: u32,
    /// Sides of rails, rungs, stems and small pipes (6..=16).
    pub small: u32,
    /// Sides of bolt shanks (6..=16).
    pub bolt: u32,
    /// Small valves on a manifold beside each piece of equipment (0..=27).
    pub satellites: u32,
    /// 0: box columns and beams, slabs only; 1: I-beams, grating floors, windows; 2: column base
    /// plates with anchor bolts; 3: bolted beam connections.
    pub structure: u32,
    /// Bar pitch of grating floors, metres.
    pub pitch: f64,
}

impl Detail {
    pub fn new(level: u32) -> Detail {
        let l = level.min(MAX_LEVEL);
        let t = l.min(21);
        Detail {
            level: l,
            sides: 6 + 2 * t,
            rings: 1 + t / 3,
            small: 6 + 2 * (l / 4).min(5),
            bolt: 6 + 2 * (l / 4).min(5),
            satellites: l.saturating_sub(21),
            structure: (l / 2).min(3),
            pitch: (0.3 / (1.0 + l as f64 / 3.0)).max(0.03),
        }
    }
}

/// Where a pipe can connect to a part: the top of its nozzle flange, and the nozzle radius.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Nozzle {
    pub top: V3,
    pub radius: f64,
}

/// One placed part.
#[derive(Clone, Debug)]
pub(crate) enum Item {
    Ground { min: V3, max: V3 },
    Wall(Wall),
    Slab(Slab),
    Grating(Grating),
    Column(Column),
    Beams(Beams),
    Stair(Stair),
    Railing(Railing),
    Vessel(Vessel),
    Pump(Pump),
    Exchanger(Exchanger),
    Valve(Valve),
    Cabinet(Cabinet),
    Platform(Platform),
    Manifold(Manifold),
    StorageTank(StorageTank),
    Stack(Stack),
    RackFrame(RackFrame),
}

impl Item {
    pub fn emit(&self, e: &mut Emitter<'_>) {
        match self {
            Item::Ground { min, max } => {
                e.begin("ground", color::GROUND);
                e.cuboid(&Frame::at([0.0; 3]), *min, *max);
            }
            Item::Wall(w) => w.emit(e),
            Item::Slab(s) => s.emit(e),
            Item::Grating(g) => g.emit(e),
            Item::Column(c) => c.emit(e),
            Item::Beams(b) => b.emit(e),
            Item::Stair(s) => s.emit(e),
            Item::Railing(r) => r.emit(e),
            Item::Vessel(v) => v.emit(e),
            Item::Pump(p) => p.emit(e),
            Item::Exchanger(x) => x.emit(e),
            Item::Valve(v) => v.emit(e),
            Item::Cabinet(c) => c.emit(e),
            Item::Platform(p) => p.emit(e),
            Item::Manifold(m) => m.emit(e),
            Item::StorageTank(t) => t.emit(e),
            Item::Stack(s) => s.emit(e),
            Item::RackFrame(r) => r.emit(e),
        }
    }

    /// Exact triangle count (a dry run).
    pub fn triangles(&self) -> u64 {
        let mut c = Emitter::counting();
        self.emit(&mut c);
        c.triangles()
    }
}

/// A hexagon-head bolt standing on a surface: `frame` at the surface, z out of it; `a` is the
/// width across flats (1.2–2.2 cm). The head is 0.4·a high and the shank reaches 0.8·a into the
/// surface: 20 + 3·sides − 2 triangles (36 to 66), one object.
pub(crate) fn bolt(e: &mut Emitter<'_>, f: &Frame, a: f64, sides: u32) {
    e.begin("bolt", color::BOLT);
    bolt_shape(e, f, a, sides);
}

/// The geometry of [`bolt`] without announcing an object.
fn bolt_shape(e: &mut Emitter<'_>, f: &Frame, a: f64, sides: u32) {
    e.cylinder(f, a / 3f64.sqrt(), 0.0, 0.4 * a, 6, true, true);
    e.cylinder(f, 0.28 * a, -0.8 * a, 0.0, sides, true, false);
}

/// A flange (ring plate) with a circle of bolts on its outer face.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Flange {
    /// Origin at the centre of the face against the pipe, z along the pipe, out of the joint.
    pub frame: Frame,
    pub r_in: f64,
    pub r_out: f64,
    pub thick: f64,
    pub sides: u32,
    pub bolts: u32,
    pub bolt_sides: u32,
    /// The flange is an object of its own (else it belongs to the object being emitted).
    pub own_object: bool,
    /// Each bolt is an object of its own (else the bolts belong to the flange's object).
    pub separate_bolts: bool,
}

impl Flange {
    pub fn new(frame: Frame, r_pipe: f64, d: &Detail, bolts: u32) -> Flange {
        let w = (0.7 * r_pipe).max(0.02);
        Flange {
            frame,
            r_in: r_pipe,
            r_out: r_pipe + w,
            thick: (0.3 * w).max(0.01),
            sides: (d.sides / 2).max(8),
            bolts: bolts.min(4 + d.level / 4),
            bolt_sides: d.bolt,
            own_object: true,
            separate_bolts: true,
        }
    }

    /// The same flange with its bolts in its own object.
    pub fn with_bolts_merged(self) -> Flange {
        Flange { separate_bolts: false, ..self }
    }

    /// The same flange, bolts included, in the object of the part it belongs to.
    pub fn inline(self) -> Flange {
        Flange { separate_bolts: false, own_object: false, ..self }
    }

    pub fn emit(&self, e: &mut Emitter<'_>) {
        if self.own_object {
            e.begin("flange", color::FLANGE);
        }
        e.ring_plate(&self.frame, self.r_in, self.r_out, 0.0, self.thick, self.sides);
        let w = self.r_out - self.r_in;
        let a = (0.5 * w).clamp(0.012, 0.022);
        let rb = self.r_in + 0.5 * w;
        for j in 0..self.bolts {
            let t = std::f64::consts::TAU * (j as f64 + 0.5) / self.bolts as f64;
            let f = self.frame.moved(rb * t.cos(), rb * t.sin(), self.thick);
            if self.separate_bolts {
                bolt(e, &f, a, self.bolt_sides);
            } else {
                bolt_shape(e, &f, a, self.bolt_sides);
            }
        }
    }

    /// The centre of the outer face.
    pub fn top(&self) -> V3 {
        self.frame.p(0.0, 0.0, self.thick)
    }
}

/// A straight wall with rectangular openings, built from solid blocks around them.
#[derive(Clone, Debug)]
pub(crate) struct Wall {
    /// Origin at the wall's start, bottom, outer face; x along the wall, y through it, z up.
    pub frame: Frame,
    pub len: f64,
    pub height: f64,
    pub thick: f64,
    /// `[x0, x1, z0, z1]`, sorted by x, disjoint, inside the wall.
    pub openings: Vec<[f64; 4]>,
    pub name: &'static str,
    pub color: Rgba8,
}

impl Wall {
    fn emit(&self, e: &mut Emitter<'_>) {
        e.begin(self.name, self.color);
        let (t, h) = (self.thick, self.height);
        let mut x = 0.0;
        for o in &self.openings {
            if o[0] - x > 1e-3 {
                e.cuboid(&self.frame, [x, 0.0, 0.0], [o[0], t, h]);
            }
            if o[2] > 1e-3 {
                e.cuboid(&self.frame, [o[0], 0.0, 0.0], [o[1], t, o[2]]);
            }
            if h - o[3] > 1e-3 {
                e.cuboid(&self.frame, [o[0], 0.0, o[3]], [o[1], t, h]);
            }
            x = o[1];
        }
        if self.len - x > 1e-3 {
            e.cuboid(&self.frame, [x, 0.0, 0.0], [self.len, t, h]);
        }
    }
}

/// Parts of the rectangle `r` = `[x0, x1, y0, y1]` outside the hole `h` (up to four).
fn around_hole(r: [f64; 4], hole: Option<[f64; 4]>, mut f: impl FnMut([f64; 4])) {
    let Some(h) = hole else {
        f(r);
        return;
    };
    let keep = |q: [f64; 4]| q[1] - q[0] > 1e-3 && q[3] - q[2] > 1e-3;
    for q in [
        [r[0], h[0], r[2], r[3]],
        [h[1], r[1], r[2], r[3]],
        [h[0], h[1], r[2], h[2]],
        [h[0], h[1], h[3], r[3]],
    ] {
        if keep(q) {
            f(q);
        }
    }
}

/// A concrete slab, world axis-aligned, with an optional rectangular hole (a stairwell).
#[derive(Clone, Debug)]
pub(crate) struct Slab {
    /// `[x0, x1, y0, y1]`.
    pub rect: [f64; 4],
    pub z0: f64,
    pub z1: f64,
    pub hole: Option<[f64; 4]>,
    pub name: &'static str,
}

impl Slab {
    fn emit(&self, e: &mut Emitter<'_>) {
        e.begin(self.name, color::CONCRETE);
        let f = Frame::at([0.0; 3]);
        around_hole(self.rect, self.hole, |q| e.cuboid(&f, [q[0], q[2], self.z0], [q[1], q[3], self.z1]));
    }
}

/// A grating floor: bearing bars along x every `pitch`, cross bars along y every 4·pitch, top
/// flush at `z`; bars stop at the hole.
#[derive(Clone, Debug)]
pub(crate) struct Grating {
    pub rect: [f64; 4],
    pub z: f64,
    pub hole: Option<[f64; 4]>,
    pub pitch: f64,
}

impl Grating {
    fn emit(&self, e: &mut Emitter<'_>) {
        e.begin("grating", color::GRATING);
        let f = Frame::at([0.0; 3]);
        let [x0, x1, y0, y1] = self.rect;
        let (p, z) = (self.pitch, self.z);
        let hole = self.hole.unwrap_or([0.0, 0.0, f64::NAN, f64::NAN]);
        let mut y = y0 + 0.5 * p;
        while y < y1 - 0.003 {
            let span =
                if y > hole[2] && y < hole[3] { [(x0, hole[0]), (hole[1], x1)] } else { [(x0, x1); 2] };
            for (k, &(a, b)) in span.iter().enumerate() {
                if b - a > 0.01 && (k == 0 || span[0] != span[1]) {
                    e.cuboid(&f, [a, y - 0.0025, z - 0.03], [b, y + 0.0025, z]);
                }
            }
            y += p;
        }
        let q = 4.0 * p;
        let mut x = x0 + 0.5 * q;
        while x < x1 - 0.003 {
            let span =
                if x > hole[0] && x < hole[1] { [(y0, hole[2]), (hole[3], y1)] } else { [(y0, y1); 2] };
            for (k, &(a, b)) in span.iter().enumerate() {
                if b - a > 0.01 && (k == 0 || span[0] != span[1]) {
                    e.cuboid(&f, [x - 0.003, a, z - 0.012], [x + 0.003, b, z]);
                }
            }
            x += q;
        }
    }
}

/// A full-height column; optional base plate with four anchor bolts and bolted connections.
#[derive(Clone, Debug)]
pub(crate) struct Column {
    pub base: V3,
    pub height: f64,
    pub ibeam: bool,
    pub base_plate: bool,
    /// Heights (above the base) of bolted beam connections, two bolts each.
    pub bolt_levels: Vec<f64>,
    pub bolt_sides: u32,
}

impl Column {
    fn emit(&self, e: &mut Emitter<'_>) {
        let f = Frame::at(self.base);
        e.begin("column", color::STEEL);
        if self.ibeam {
            e.ibeam(&f, 0.3, 0.3, 0.02, 0.012, 0.0, self.height);
        } else {
            e.cuboid(&f, [-0.15, -0.15, 0.0], [0.15, 0.15, self.height]);
        }
        if self.base_plate {
            e.begin("base plate", color::STEEL);
            e.cuboid(&f, [-0.25, -0.25, 0.0], [0.25, 0.25, 0.03]);
            for (x, y) in [(-0.19, -0.19), (0.19, -0.19), (0.19, 0.19), (-0.19, 0.19)] {
                e.begin("anchor bolt", color::BOLT);
                let g = f.moved(x, y, 0.03);
                e.cylinder(&g, 0.006, -0.005, 0.022, self.bolt_sides, false, true);
                e.ring_plate(&g, 0.006, 0.0115, 0.0, 0.011, 6);
            }
        }
        if !self.bolt_levels.is_empty() {
            e.begin("column connections", color::STEEL);
        }
        for &z in &self.bolt_levels {
            for y in [-0.07, 0.07] {
                let g = Frame::axis(f.p(0.15, y, z), [1.0, 0.0, 0.0]);
                bolt_shape(e, &g, 0.02, self.bolt_sides);
            }
        }
    }
}

/// The beams under one floor: one object, an I-beam (or a box) per grid line.
#[derive(Clone, Debug)]
pub(crate) struct Beams {
    /// Height of the beams' top face.
    pub top: f64,
    /// `(y, x0, x1)`: beams along x.
    pub along_x: Vec<(f64, f64, f64)>,
    /// `(x, y0, y1)`: beams along y.
    pub along_y: Vec<(f64, f64, f64)>,
    pub ibeam: bool,
}

/// Depth of floor beams.
pub(crate) const BEAM_DEPTH: f64 = 0.35;

fn beam_between(e: &mut Emitter<'_>, f: &Frame, len: f64, ibeam: bool) {
    if ibeam {
        e.ibeam(f, 0.18, BEAM_DEPTH, 0.015, 0.009, 0.0, len);
    } else {
        e.cuboid(f, [-0.09, -BEAM_DEPTH / 2.0, 0.0], [0.09, BEAM_DEPTH / 2.0, len]);
    }
}

impl Beams {
    fn emit(&self, e: &mut Emitter<'_>) {
        e.begin("floor beams", color::STEEL);
        let zc = self.top - BEAM_DEPTH / 2.0;
        for &(y, x0, x1) in &self.along_x {
            let f = Frame { o: [x0, y, zc], x: [0.0, 1.0, 0.0], y: [0.0, 0.0, 1.0], z: [1.0, 0.0, 0.0] };
            beam_between(e, &f, x1 - x0, self.ibeam);
        }
        for &(x, y0, y1) in &self.along_y {
            let f = Frame { o: [x, y0, zc], x: [-1.0, 0.0, 0.0], y: [0.0, 0.0, 1.0], z: [0.0, 1.0, 0.0] };
            beam_between(e, &f, y1 - y0, self.ibeam);
        }
    }
}

/// A straight steel stair flight: `frame` at the foot of the flight on its centre line, x up the
/// flight, z up.
#[derive(Clone, Debug)]
pub(crate) struct Stair {
    pub frame: Frame,
    pub run: f64,
    pub rise: f64,
    pub width: f64,
    pub steps: u32,
}

impl Stair {
    fn emit(&self, e: &mut Emitter<'_>) {
        e.begin("stair", color::STEEL);
        let f = &self.frame;
        let n = self.steps as f64;
        let (t, r, w) = (self.run / n, self.rise / n, self.width / 2.0);
        for i in 0..self.steps {
            let top = (i + 1) as f64 * r;
            e.cuboid(f, [i as f64 * t, -w, top - 0.04], [(i + 1) as f64 * t, w, top]);
        }
        for y in [-w - 0.01, w + 0.01] {
            let a = f.p(0.0, y, 0.0);
            let b = f.p(self.run, y, self.rise);
            let d = sub(b, a);
            let g = Frame::axis(a, normalize(d));
            e.cuboid(&g, [-0.006, -0.12, 0.0], [0.006, 0.12, length(d)]);
        }
    }
}

/// A railing along a path of walking-level points: posts, top and knee rails, and toe boards on
/// level stretches.
#[derive(Clone, Debug)]
pub(crate) struct Railing {
    pub points: Vec<V3>,
    pub sides: u32,
}

impl Railing {
    fn emit(&self, e: &mut Emitter<'_>) {
        e.begin("railing", color::YELLOW);
        let up = |p: V3, h: f64| add(p, [0.0, 0.0, h]);
        for (k, w) in self.points.windows(2).enumerate() {
            let (a, b) = (w[0], w[1]);
            let d = sub(b, a);
            let len = length(d);
            let posts = (len / 1.6).ceil().max(1.0) as u32;
            let first = if k == 0 { 0 } else { 1 };
            for j in first..=posts {
                let p = add(a, scale(d, j as f64 / posts as f64));
                e.cylinder(&Frame::at(p), 0.02, 0.0, 1.05, self.sides, false, true);
            }
            e.rod(up(a, 1.0), up(b, 1.0), 0.02, self.sides, false, false);
            e.rod(up(a, 0.5), up(b, 0.5), 0.015, self.sides, false, false);
            if d[2].abs() < 1e-9 {
                let g = Frame::axis(a, scale(d, 1.0 / len));
                e.cuboid(&g, [-0.005, 0.0, 0.0], [0.005, 0.1, len]);
            }
        }
    }
}

/// A fixed ladder: `base` is the foot between the rails, `out` the horizontal unit vector towards
/// the climber.
#[derive(Clone, Debug)]
pub(crate) struct Ladder {
    pub base: V3,
    pub out: V3,
    pub height: f64,
    pub sides: u32,
}

impl Ladder {
    fn emit(&self, e: &mut Emitter<'_>) {
        e.begin("ladder", color::YELLOW);
        let z = [0.0, 0.0, 1.0];
        let f = Frame { o: self.base, x: cross(self.out, z), y: self.out, z };
        let top = self.height + 1.0;
        e.cuboid(&f, [-0.231, 0.0, 0.0], [-0.219, 0.06, top]);
        e.cuboid(&f, [0.219, 0.0, 0.0], [0.231, 0.06, top]);
        let rungs = (self.height / 0.3).floor() as u32;
        for i in 1..=rungs {
            let h = i as f64 * 0.3;
            e.rod(f.p(-0.219, 0.03, h), f.p(0.219, 0.03, h), 0.012, self.sides, false, false);
        }
    }
}

/// A vertical pressure vessel on four legs, with a nozzle and flange on top.
#[derive(Clone, Debug)]
pub(crate) struct Vessel {
    pub frame: Frame,
    pub r: f64,
    pub shell: f64,
    pub sides: u32,
    pub rings: u32,
    pub flange: Flange,
}

impl Vessel {
    pub fn new(frame: Frame, r: f64, shell: f64, noz_r: f64, d: &Detail) -> Vessel {
        let top = 0.35 + 0.3 * r + shell + 0.35 * r + 0.15;
        let flange = Flange::new(frame.moved(0.0, 0.0, top), noz_r, d, 4 + 2 * (d.level / 8).min(4));
        Vessel { frame, r, shell, sides: d.sides, rings: d.rings, flange }
    }

    fn emit(&self, e: &mut Emitter<'_>) {
        let (f, r) = (&self.frame, self.r);
        e.begin("vessel", color::SILVER);
        let z0 = 0.35 + 0.3 * r;
        let z1 = z0 + self.shell;
        let l = 0.6 * r;
        for (x, y) in [(-l, -l), (l, -l), (l, l), (-l, l)] {
            e.cuboid(f, [x - 0.04, y - 0.04, 0.0], [x + 0.04, y + 0.04, z0]);
        }
        e.dome(&f.moved(0.0, 0.0, z0).flipped(), r, 0.0, 0.3 * r, self.sides, self.rings);
        e.cylinder(f, r, z0, z1, self.sides, false, false);
        e.dome(f, r, z1, 0.35 * r, self.sides, self.rings);
        let top = self.flange.frame.o[2] - f.o[2];
        e.cylinder(f, self.flange.r_in, z1 + 0.3 * r, top, self.sides.min(24), false, false);
        self.flange.emit(e);
    }
}

/// A pump skid: motor, coupling guard, casing, suction and discharge nozzles with flanges.
#[derive(Clone, Debug)]
pub(crate) struct Pump {
    pub frame: Frame,
    pub sides: u32,
    pub suction: Flange,
    pub discharge: Flange,
}

impl Pump {
    pub fn new(frame: Frame, noz_r: f64, d: &Detail) -> Pump {
        let suction = Flange::new(frame.moved(0.85, 0.0, 0.45).z_along_x(), noz_r, d, 4).with_bolts_merged();
        let discharge = Flange::new(frame.moved(0.35, 0.0, 1.05), noz_r, d, 4);
        Pump { frame, sides: d.sides, suction, discharge }
    }

    fn emit(&self, e: &mut Emitter<'_>) {
        let f = &self.frame;
        let s = self.sides;
        let rn = self.discharge.r_in;
        e.begin("pump", color::PUMP);
        e.cuboid(f, [-1.0, -0.45, 0.0], [1.0, 0.45, 0.15]);
        e.cylinder(&f.moved(-0.9, 0.0, 0.45).z_along_x(), 0.25, 0.0, 0.8, s, true, true);
        e.cuboid(f, [-0.1, -0.12, 0.3], [0.15, 0.12, 0.6]);
        e.cylinder(&f.moved(0.15, 0.0, 0.45).z_along_x(), 0.3, 0.0, 0.4, s, true, true);
        e.cylinder(&f.moved(0.55, 0.0, 0.45).z_along_x(), rn, 0.0, 0.3, s.min(24), false, false);
        e.cylinder(&f.moved(0.35, 0.0, 0.45), rn, 0.25, 0.6, s.min(24), false, false);
        self.suction.emit(e);
        self.discharge.emit(e);
    }
}

/// A horizontal heat exchanger on two saddles, with a nozzle on top.
#[derive(Clone, Debug)]
pub(crate) struct Exchanger {
    pub frame: Frame,
    pub r: f64,
    pub len: f64,
    pub sides: u32,
    pub rings: u32,
    pub flange: Flange,
}

impl Exchanger {
    pub fn new(frame: Frame, r: f64, len: f64, noz_r: f64, d: &Detail) -> Exchanger {
        let flange = Flange::new(frame.moved(0.25 * len, 0.0, 0.5 + 2.0 * r), noz_r, d, 4);
        Exchanger { frame, r, len, sides: d.sides, rings: d.rings, flange }
    }

    fn emit(&self, e: &mut Emitter<'_>) {
        let (f, r, l) = (&self.frame, self.r, self.len);
        e.begin("heat exchanger", color::EXCHANGER);
        let zc = 0.3 + r;
        e.cylinder(&f.moved(-l / 2.0, 0.0, zc).z_along_x(), r, 0.0, l, self.sides, false, false);
        e.dome(&f.moved(l / 2.0, 0.0, zc).z_along_x(), r, 0.0, 0.5 * r, self.sides, self.rings);
        e.dome(&f.moved(-l / 2.0, 0.0, zc).z_along_x().flipped(), r, 0.0, 0.5 * r, self.sides, self.rings);
        for x in [-0.3 * l, 0.3 * l] {
            e.cuboid(f, [x - 0.08, -0.8 * r, 0.0], [x + 0.08, 0.8 * r, 0.3 + 0.5 * r]);
        }
        let top = self.flange.frame.o[2] - f.o[2];
        let g = f.moved(0.25 * l, 0.0, 0.0);
        e.cylinder(&g, self.flange.r_in, zc + 0.9 * r, top, self.sides.min(24), false, false);
        self.flange.emit(e);
    }
}

/// A hand valve on a pipe stub: spherical body, bonnet, stem, handwheel with spokes, a flange on
/// each side; optional supports down to the floor.
#[derive(Clone, Debug)]
pub(crate) struct Valve {
    /// Origin at the body centre, x along the pipe, z up.
    pub frame: Frame,
    pub rp: f64,
    pub stub: f64,
    /// Local z of the floor when the valve stands on supports.
    pub floor: Option<f64>,
    pub sides: u32,
    pub rings: u32,
    pub small: u32,
    pub flanges: [Flange; 2],
}

impl Valve {
    /// A valve whose flanges are objects of their own (`small == false`) or part of the valve
    /// object (small valves on a manifold). Bolts are never separate objects on valves: only
    /// equipment nozzles have those, which already makes plenty of 50-triangle objects.
    pub fn new(
        frame: Frame,
        rp: f64,
        stub: f64,
        floor: Option<f64>,
        d: &Detail,
        bolts: u32,
        small: bool,
    ) -> Valve {
        let xf = 1.8 * rp + 0.01;
        let style = |f: Flange| if small { f.inline() } else { f.with_bolts_merged() };
        let plus = style(Flange::new(frame.moved(xf, 0.0, 0.0).z_along_x(), rp, d, bolts));
        let minus = style(Flange::new(frame.moved(-xf, 0.0, 0.0).z_along_x().flipped(), rp, d, bolts));
        Valve {
            frame,
            rp,
            stub,
            floor,
            sides: d.sides.min(32),
            rings: d.rings,
            small: d.small,
            flanges: [plus, minus],
        }
    }

    fn emit(&self, e: &mut Emitter<'_>) {
        let (f, rp) = (&self.frame, self.rp);
        let rb = 1.8 * rp;
        e.begin("valve", color::VALVE);
        e.cylinder(
            &f.moved(-self.stub, 0.0, 0.0).z_along_x(),
            rp,
            0.0,
            2.0 * self.stub,
            self.sides,
            false,
            false,
        );
        e.dome(f, rb, 0.0, rb, self.sides, self.rings);
        e.dome(&f.flipped(), rb, 0.0, rb, self.sides, self.rings);
        let bonnet = rb + 0.6 * rp;
        e.cylinder(f, 0.45 * rb, 0.8 * rb, bonnet, self.small, false, true);
        let stem_r = (0.15 * rp).max(0.004);
        let wheel = bonnet + 0.8 * rp;
        e.cylinder(f, stem_r, bonnet, wheel + 0.01, self.small, false, true);
        let big = 2.2 * rp;
        let g = f.moved(0.0, 0.0, wheel);
        e.torus(&g, big, 0.12 * big, self.small * 2, self.small.min(8));
        for k in 0..3 {
            let t = std::f64::consts::TAU * k as f64 / 3.0;
            e.rod(g.o, g.p(big * t.cos(), big * t.sin(), 0.0), 0.06 * big, self.small.min(8), false, false);
        }
        if let Some(fl) = self.floor {
            for x in [-0.7 * self.stub, 0.7 * self.stub] {
                e.cuboid(f, [x - 0.05, -0.05, fl], [x + 0.05, 0.05, -rp]);
            }
        }
        for fl in &self.flanges {
            fl.emit(e);
        }
    }
}

/// A row of electrical cabinets on a plinth.
#[derive(Clone, Debug)]
pub(crate) struct Cabinet {
    pub frame: Frame,
    pub count: u32,
}

impl Cabinet {
    fn emit(&self, e: &mut Emitter<'_>) {
        let f = &self.frame;
        e.begin("cabinet", color::CABINET);
        let x0 = -0.4 * self.count as f64;
        for i in 0..self.count {
            let x = x0 + 0.8 * i as f64;
            e.cuboid(f, [x + 0.01, -0.3, 0.0], [x + 0.79, 0.3, 0.1]);
            e.cuboid(f, [x, -0.3, 0.1], [x + 0.8, 0.3, 2.1]);
            e.cuboid(f, [x + 0.65, -0.33, 1.0], [x + 0.68, -0.3, 1.2]);
            e.cuboid(f, [x + 0.2, -0.15, 2.1], [x + 0.6, 0.15, 2.2]);
        }
    }
}

/// A small steel platform on four posts: grating deck, railing on three sides, ladder on the
/// fourth.
#[derive(Clone, Debug)]
pub(crate) struct Platform {
    pub frame: Frame,
    pub height: f64,
    pub deck: Grating,
    pub railing: Railing,
    pub ladder: Ladder,
}

impl Platform {
    pub fn new(frame: Frame, height: f64, d: &Detail) -> Platform {
        let (a, b) = (frame.p(-1.0, -1.0, height), frame.p(1.0, 1.0, height));
        let rect = [a[0].min(b[0]), a[0].max(b[0]), a[1].min(b[1]), a[1].max(b[1])];
        let deck = Grating { rect, z: a[2], hole: None, pitch: d.pitch };
        let h = |x, y| frame.p(x, y, height);
        let railing =
            Railing { points: vec![h(-1.0, 1.0), h(1.0, 1.0), h(1.0, -1.0), h(-1.0, -1.0)], sides: d.small };
        let ladder =
            Ladder { base: frame.p(-1.0, 0.0, 0.0), out: scale(frame.x, -1.0), height, sides: d.small };
        Platform { frame, height, deck, railing, ladder }
    }

    fn emit(&self, e: &mut Emitter<'_>) {
        let (f, h) = (&self.frame, self.height);
        e.begin("platform", color::STEEL);
        for (x, y) in [(-0.95, -0.95), (0.95, -0.95), (0.95, 0.95), (-0.95, 0.95)] {
            e.cuboid(f, [x - 0.04, y - 0.04, 0.0], [x + 0.04, y + 0.04, h - 0.03]);
        }
        e.cuboid(f, [-1.0, -1.0, h - 0.15], [1.0, -0.92, h - 0.03]);
        e.cuboid(f, [-1.0, 0.92, h - 0.15], [1.0, 1.0, h - 0.03]);
        e.cuboid(f, [-1.0, -0.92, h - 0.15], [-0.92, 0.92, h - 0.03]);
        e.cuboid(f, [0.92, -0.92, h - 0.15], [1.0, 0.92, h - 0.03]);
        self.deck.emit(e);
        self.railing.emit(e);
        self.ladder.emit(e);
    }
}

/// A row of posts along one edge of a slot carrying small valves, six per post.
#[derive(Clone, Debug)]
pub(crate) struct Manifold {
    pub frame: Frame,
    pub valves: Vec<Valve>,
}

/// Valves per manifold post.
const VALVES_PER_POST: u32 = 6;

impl Manifold {
    pub fn new(frame: Frame, count: u32, rp: f64, d: &Detail) -> Manifold {
        let valves = (0..count)
            .map(|j| {
                let (p, q) = (j / VALVES_PER_POST, j % VALVES_PER_POST);
                let g = frame.moved(-1.0 + 0.4 * p as f64, 1.2, 0.3 + 0.28 * q as f64);
                Valve::new(g, rp, 0.13, None, d, 4, true)
            })
            .collect();
        Manifold { frame, valves }
    }

    fn emit(&self, e: &mut Emitter<'_>) {
        if self.valves.is_empty() {
            return;
        }
        e.begin("manifold", color::STEEL);
        let posts = (self.valves.len() as u32).div_ceil(VALVES_PER_POST);
        for p in 0..posts {
            let x = -1.0 + 0.4 * p as f64;
            e.cuboid(&self.frame, [x - 0.03, 1.3, 0.0], [x + 0.03, 1.36, 1.9]);
            e.cuboid(&self.frame, [x - 0.02, 1.2, 0.25], [x + 0.02, 1.3, 0.29]);
        }
        for v in &self.valves {
            v.emit(e);
        }
    }
}

/// A large outdoor storage tank: flat bottom, shallow roof, roof nozzle, ladder and roof railing.
#[derive(Clone, Debug)]
pub(crate) struct StorageTank {
    pub frame: Frame,
    pub r: f64,
    pub h: f64,
    pub sides: u32,
    pub rings: u32,
    pub small: u32,
    pub flange: Flange,
    pub ladder: Ladder,
}

impl StorageTank {
    pub fn new(frame: Frame, r: f64, h: f64, d: &Detail) -> StorageTank {
        let flange = Flange::new(frame.moved(0.0, 0.0, h + 0.15 * r + 0.3), 0.1, d, 8);
        let ladder =
            Ladder { base: frame.p(0.0, -r - 0.25, 0.0), out: [0.0, -1.0, 0.0], height: h, sides: d.small };
        StorageTank { frame, r, h, sides: d.sides.max(12), rings: d.rings, small: d.small, flange, ladder }
    }

    pub fn nozzle(&self) -> Nozzle {
        Nozzle { top: self.flange.top(), radius: self.flange.r_in }
    }

    fn emit(&self, e: &mut Emitter<'_>) {
        let (f, r, h) = (&self.frame, self.r, self.h);
        e.begin("storage tank", color::SILVER);
        e.cylinder(f, r, 0.0, h, self.sides, true, false);
        e.dome(f, r, h, 0.15 * r, self.sides, self.rings);
        let top = self.flange.frame.o[2] - f.o[2];
        e.cylinder(f, self.flange.r_in, h + 0.15 * r - 0.05, top, self.small, false, false);
        self.flange.emit(e);
        self.ladder.emit(e);
        e.begin("railing", color::YELLOW);
        let rr = r - 0.15;
        let posts = ((std::f64::consts::TAU * rr / 2.0).ceil() as u32).max(6);
        for j in 0..posts {
            let t = std::f64::consts::TAU * j as f64 / posts as f64;
            e.cylinder(&f.moved(rr * t.cos(), rr * t.sin(), h), 0.025, 0.0, 1.05, self.small, false, true);
        }
        for z in [h + 0.5, h + 1.0] {
            e.torus(&f.moved(0.0, 0.0, z), rr, 0.025, self.sides, self.small.min(8));
        }
    }
}

/// A chimney with two gallery rings and a ladder.
#[derive(Clone, Debug)]
pub(crate) struct Stack {
    pub frame: Frame,
    pub r: f64,
    pub h: f64,
    pub sides: u32,
    pub ladder: Ladder,
}

impl Stack {
    pub fn new(frame: Frame, r: f64, h: f64, d: &Detail) -> Stack {
        let ladder =
            Ladder { base: frame.p(0.0, -r - 0.25, 0.0), out: [0.0, -1.0, 0.0], height: h, sides: d.small };
        Stack { frame, r, h, sides: d.sides.max(16), ladder }
    }

    fn emit(&self, e: &mut Emitter<'_>) {
        let (f, r, h) = (&self.frame, self.r, self.h);
        e.begin("stack", color::CONCRETE);
        e.cylinder(f, r, 0.0, h, self.sides, false, false);
        e.torus(&f.moved(0.0, 0.0, h), r, 0.15, self.sides, 6);
        for z in [0.35 * h, 0.7 * h] {
            e.ring_plate(&f.moved(0.0, 0.0, z), r, r + 1.2, 0.0, 0.08, self.sides);
        }
        self.ladder.emit(e);
    }
}

/// One portal of the pipe rack: two columns and a cross beam whose top is at `top`.
#[derive(Clone, Debug)]
pub(crate) struct RackFrame {
    pub x: f64,
    pub y0: f64,
    pub y1: f64,
    pub ground: f64,
    pub top: f64,
    pub ibeam: bool,
}

impl RackFrame {
    fn emit(&self, e: &mut Emitter<'_>) {
        e.begin("pipe rack", color::STEEL);
        let col_top = self.top - BEAM_DEPTH;
        for y in [self.y0, self.y1] {
            let f = Frame::at([self.x, y, self.ground]);
            if self.ibeam {
                e.ibeam(&f, 0.25, 0.25, 0.015, 0.01, 0.0, col_top - self.ground);
            } else {
                e.cuboid(&f, [-0.125, -0.125, 0.0], [0.125, 0.125, col_top - self.ground]);
            }
        }
        let zc = self.top - BEAM_DEPTH / 2.0;
        let f = Frame {
            o: [self.x, self.y0 - 0.3, zc],
            x: [-1.0, 0.0, 0.0],
            y: [0.0, 0.0, 1.0],
            z: [0.0, 1.0, 0.0],
        };
        beam_between(e, &f, self.y1 - self.y0 + 0.6, self.ibeam);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ImportError, ObjectId, ObjectInfo, Triangle, TriangleSink};

    #[derive(Default)]
    struct Check {
        triangles: u64,
        degenerate: u64,
        objects: Vec<(String, u64, tw_core::Aabb)>,
    }

    impl TriangleSink for Check {
        fn object(&mut self, _id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
            self.objects.push((info.name.clone(), 0, tw_core::Aabb::EMPTY));
            Ok(())
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.triangles += 1;
            self.degenerate += t.is_degenerate() as u64;
            let o = &mut self.objects[t.object as usize];
            o.1 += 1;
            for p in t.positions {
                o.2.grow(p);
            }
            Ok(())
        }
    }

    fn every_part(d: &Detail) -> Vec<Item> {
        let o = [1000.0, 2000.0, 4.5];
        let f = Frame::turned(o, 1);
        vec![
            Item::Vessel(Vessel::new(f, 0.8, 1.2, 0.06, d)),
            Item::Pump(Pump::new(f, 0.05, d)),
            Item::Exchanger(Exchanger::new(f, 0.45, 1.2, 0.05, d)),
            Item::Valve(Valve::new(f.moved(0.0, 0.0, 0.6), 0.1, 1.0, Some(-0.6), d, 8, false)),
            Item::Cabinet(Cabinet { frame: f, count: 2 }),
            Item::Platform(Platform::new(f, 2.0, d)),
            Item::Manifold(Manifold::new(f, d.satellites.max(7), 0.03, d)),
            Item::StorageTank(StorageTank::new(f, 5.0, 10.0, d)),
            Item::Stack(Stack::new(f, 2.6, 50.0, d)),
            Item::RackFrame(RackFrame {
                x: 3.0,
                y0: 1.5,
                y1: 7.5,
                ground: -0.05,
                top: 7.0,
                ibeam: d.structure > 0,
            }),
            Item::Column(Column {
                base: o,
                height: 9.0,
                ibeam: true,
                base_plate: true,
                bolt_levels: vec![4.0, 8.5],
                bolt_sides: d.bolt,
            }),
            Item::Grating(Grating {
                rect: [0.0, 6.0, 0.0, 3.0],
                z: 4.5,
                hole: Some([0.3, 2.0, 1.0, 2.0]),
                pitch: d.pitch,
            }),
            Item::Slab(Slab {
                rect: [0.0, 6.0, 0.0, 3.0],
                z0: 4.25,
                z1: 4.5,
                hole: Some([0.0, 2.0, 1.0, 2.0]),
                name: "slab",
            }),
            Item::Wall(Wall {
                frame: f,
                len: 12.0,
                height: 4.2,
                thick: 0.3,
                openings: vec![[0.0, 1.0, 0.0, 2.2], [3.0, 5.0, 1.0, 2.2], [9.0, 12.0, 0.0, 4.2]],
                name: "wall",
                color: color::CONCRETE,
            }),
            Item::Stair(Stair { frame: f, run: 5.4, rise: 4.5, width: 1.1, steps: 23 }),
        ]
    }

    #[test]
    fn parts_count_exactly_and_are_never_degenerate_at_every_detail() {
        for level in [0, 5, 21, MAX_LEVEL] {
            let d = Detail::new(level);
            let mut sink = Check::default();
            let mut e = Emitter::new(&mut sink);
            let mut expected = 0;
            for item in every_part(&d) {
                let n = item.triangles();
                let before = e.triangles();
                item.emit(&mut e);
                assert_eq!(e.triangles() - before, n, "level {level}: {item:?}");
                expected += n;
            }
            e.finish().unwrap();
            assert_eq!(sink.triangles, expected);
            assert_eq!(sink.degenerate, 0, "level {level}");
        }
    }

    #[test]
    fn bolts_are_one_to_three_centimetres_and_20_to_100_triangles() {
        for level in [0, MAX_LEVEL] {
            let d = Detail::new(level);
            let mut sink = Check::default();
            let mut e = Emitter::new(&mut sink);
            for item in every_part(&d) {
                item.emit(&mut e);
            }
            e.finish().unwrap();
            let bolts: Vec<_> = sink.objects.iter().filter(|o| o.0.contains("bolt")).collect();
            assert!(bolts.len() >= 16, "{} bolts", bolts.len());
            for (name, n, b) in bolts {
                let size = b.extent().into_iter().fold(0.0, f64::max);
                assert!((0.01..=0.03).contains(&size), "{name} is {size} m");
                assert!((20..=100).contains(n), "{name} has {n} triangles");
            }
        }
    }

    #[test]
    fn detail_grows_monotonically() {
        let count = |l| every_part(&Detail::new(l)).iter().map(Item::triangles).sum::<u64>();
        let mut last = 0;
        for l in 0..=MAX_LEVEL {
            let n = count(l);
            assert!(n >= last, "level {l}: {n} < {last}");
            last = n;
        }
    }

    #[test]
    fn walls_leave_their_openings_open() {
        let w = Wall {
            frame: Frame::at([0.0; 3]),
            len: 10.0,
            height: 4.0,
            thick: 0.3,
            openings: vec![[2.0, 3.0, 0.0, 2.2]],
            name: "wall",
            color: color::CONCRETE,
        };
        // Pier, lintel, pier: no sill below a door.
        assert_eq!(Item::Wall(w).triangles(), 36);
    }
}
