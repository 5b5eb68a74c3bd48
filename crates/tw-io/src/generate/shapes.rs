//! Primitive meshes for the plant generator, written straight into indexed chunks.
//!
//! [`Emitter`] owns one reusable chunk (positions and local `u32` indices) and hands it to the
//! sink when it fills up or when the object changes, so generation allocates nothing per
//! triangle. Every primitive is built from rings of points on precomputed unit circles
//! ([`Emitter::trig`]), transformed by a [`Frame`].
//!
//! An emitter made with [`Emitter::counting`] has no sink: primitives only add their triangle
//! count and return. Parts are counted this way before they are placed, so that the plan knows the
//! exact triangle count of every part without a second set of formulas to keep in step.
//!
//! Invariant: every primitive emits only non-degenerate triangles as long as its sizes are
//! positive (radii, lengths, thicknesses > 0) and, for a torus, the tube radius is below the ring
//! radius. Callers assert these in debug builds.

use tw_core::Rgba8;

use crate::{ImportError, MeshChunk, ObjectId, ObjectInfo, TriangleSink};

pub(crate) type V3 = [f64; 3];

#[inline]
pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
#[inline]
pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub(crate) fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
#[inline]
pub(crate) fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
#[inline]
pub(crate) fn length(a: V3) -> f64 {
    dot(a, a).sqrt()
}
#[inline]
pub(crate) fn normalize(a: V3) -> V3 {
    scale(a, 1.0 / length(a))
}

/// Rotates `v` about the unit `axis` by the angle whose cosine and sine are `c` and `s`
/// (Rodrigues' formula).
#[inline]
pub(crate) fn rotate(v: V3, axis: V3, c: f64, s: f64) -> V3 {
    let k = cross(axis, v);
    let d = dot(axis, v) * (1.0 - c);
    [v[0] * c + k[0] * s + axis[0] * d, v[1] * c + k[1] * s + axis[1] * d, v[2] * c + k[2] * s + axis[2] * d]
}

/// A right-handed orthonormal frame: local `(x, y, z)` is `o + x·self.x + y·self.y + z·self.z`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Frame {
    pub o: V3,
    pub x: V3,
    pub y: V3,
    pub z: V3,
}

impl Frame {
    /// World axes at `o`.
    pub fn at(o: V3) -> Frame {
        Frame { o, x: [1.0, 0.0, 0.0], y: [0.0, 1.0, 0.0], z: [0.0, 0.0, 1.0] }
    }

    /// World axes at `o`, turned by `quarter` quarter turns about +z.
    pub fn turned(o: V3, quarter: u32) -> Frame {
        let (x, y) = match quarter % 4 {
            0 => ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            1 => ([0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]),
            2 => ([-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]),
            _ => ([0.0, -1.0, 0.0], [1.0, 0.0, 0.0]),
        };
        Frame { o, x, y, z: [0.0, 0.0, 1.0] }
    }

    /// A frame at `o` whose z axis is the unit vector `dir`.
    pub fn axis(o: V3, dir: V3) -> Frame {
        let a = if dir[2].abs() < 0.9 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] };
        let x = normalize(cross(a, dir));
        let y = cross(dir, x);
        Frame { o, x, y, z: dir }
    }

    /// The world position of local `(x, y, z)`.
    #[inline]
    pub fn p(&self, x: f64, y: f64, z: f64) -> V3 {
        [
            self.o[0] + x * self.x[0] + y * self.y[0] + z * self.z[0],
            self.o[1] + x * self.x[1] + y * self.y[1] + z * self.z[1],
            self.o[2] + x * self.x[2] + y * self.y[2] + z * self.z[2],
        ]
    }

    /// The same axes with the origin moved to local `(x, y, z)`.
    pub fn moved(&self, x: f64, y: f64, z: f64) -> Frame {
        Frame { o: self.p(x, y, z), ..*self }
    }

    /// The same origin with the z axis along the old x axis (axes permuted cyclically).
    pub fn z_along_x(&self) -> Frame {
        Frame { o: self.o, x: self.y, y: self.z, z: self.x }
    }

    /// The same origin upside down (z and y negated), still right-handed.
    pub fn flipped(&self) -> Frame {
        Frame { o: self.o, x: self.x, y: scale(self.y, -1.0), z: scale(self.z, -1.0) }
    }
}

/// Most sides any ring may have (pipes, caps and domes stay far below it).
pub(crate) const MAX_SIDES: u32 = 256;

/// Vertices per chunk before it is handed to the sink.
const CHUNK_VERTICES: usize = 1 << 15;

/// Progress is reported about this often, in triangles.
const PROGRESS_STEP: u64 = 100_000;

/// Triangles of an I-beam prism (12-point profile: 24 side triangles, 6 per end cap).
pub(crate) const IBEAM_TRIS: u64 = 36;

/// Writes primitives into indexed chunks for a sink, or only counts them.
pub(crate) struct Emitter<'a> {
    sink: Option<&'a mut dyn TriangleSink>,
    positions: Vec<V3>,
    indices: Vec<u32>,
    scratch: Vec<V3>,
    object: ObjectId,
    objects: u32,
    triangles: u64,
    vertices: u64,
    next_progress: u64,
    error: Option<ImportError>,
    /// `trig[s]` holds `(cos, sin)` of the `s` corners of a regular polygon, for 3 ≤ s ≤ MAX_SIDES.
    trig: Vec<Vec<(f64, f64)>>,
    strip_sides: u32,
    strip_prev: Option<u32>,
}

impl<'a> Emitter<'a> {
    /// An emitter that streams into `sink`.
    pub fn new(sink: &'a mut dyn TriangleSink) -> Emitter<'a> {
        let trig = (0..=MAX_SIDES)
            .map(|s| {
                if s < 3 {
                    return Vec::new();
                }
                (0..s)
                    .map(|i| {
                        let a = std::f64::consts::TAU * i as f64 / s as f64;
                        (a.cos(), a.sin())
                    })
                    .collect()
            })
            .collect();
        Emitter {
            sink: Some(sink),
            positions: Vec::with_capacity(CHUNK_VERTICES),
            indices: Vec::with_capacity(CHUNK_VERTICES * 4),
            scratch: Vec::new(),
            object: 0,
            objects: 0,
            triangles: 0,
            vertices: 0,
            next_progress: PROGRESS_STEP,
            error: None,
            trig,
            strip_sides: 0,
            strip_prev: None,
        }
    }

    /// An emitter that only counts triangles and objects (allocates nothing).
    pub fn counting() -> Emitter<'static> {
        Emitter {
            sink: None,
            positions: Vec::new(),
            indices: Vec::new(),
            scratch: Vec::new(),
            object: 0,
            objects: 0,
            triangles: 0,
            vertices: 0,
            next_progress: u64::MAX,
            error: None,
            trig: Vec::new(),
            strip_sides: 0,
            strip_prev: None,
        }
    }

    #[inline]
    fn counts_only(&self) -> bool {
        self.sink.is_none()
    }

    /// Triangles emitted so far (including those still in the chunk).
    pub fn triangles(&self) -> u64 {
        self.triangles
    }

    /// Objects announced so far.
    pub fn objects(&self) -> u32 {
        self.objects
    }

    /// Vertices written so far.
    pub fn vertices(&self) -> u64 {
        self.vertices
    }

    /// True once the sink has refused something; later output is dropped.
    pub fn failed(&self) -> bool {
        self.error.is_some()
    }

    /// Hands the last chunk over and returns the first error the sink reported, if any.
    pub fn finish(&mut self) -> Result<(), ImportError> {
        self.flush();
        match self.error.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// Announces a new object; the following primitives belong to it.
    pub fn begin(&mut self, name: impl std::fmt::Display, color: Rgba8) {
        self.flush();
        self.object = self.objects;
        self.objects += 1;
        self.strip_prev = None;
        if self.error.is_some() {
            return;
        }
        if let Some(sink) = self.sink.as_mut() {
            let info = ObjectInfo { name: name.to_string(), color: Some(color) };
            if let Err(e) = sink.object(self.object, &info) {
                self.error = Some(e);
            }
        }
    }

    fn flush(&mut self) {
        if let Some(sink) = self.sink.as_mut() {
            if !self.indices.is_empty() && self.error.is_none() {
                let chunk =
                    MeshChunk { object: self.object, positions: &self.positions, indices: &self.indices };
                if let Err(e) = sink.mesh(&chunk) {
                    self.error = Some(e);
                }
            }
            if self.triangles >= self.next_progress && self.error.is_none() {
                sink.progress(self.triangles);
                self.next_progress = self.triangles + PROGRESS_STEP;
            }
        }
        self.positions.clear();
        self.indices.clear();
    }

    /// Makes room for `n` more vertices in the chunk and returns the index the first will get.
    #[inline]
    fn reserve(&mut self, n: usize) -> u32 {
        debug_assert!(n <= CHUNK_VERTICES);
        if self.positions.len() + n > CHUNK_VERTICES {
            self.flush();
            self.strip_prev = None;
        }
        self.vertices += n as u64;
        self.positions.len() as u32
    }

    #[inline]
    fn tri(&mut self, base: u32, a: u32, b: u32, c: u32) {
        self.indices.extend_from_slice(&[base + a, base + b, base + c]);
    }

    #[inline]
    fn quad(&mut self, base: u32, a: u32, b: u32, c: u32, d: u32) {
        self.indices.extend_from_slice(&[base + a, base + b, base + c, base + a, base + c, base + d]);
    }

    /// A box spanning local `min..max` in `f` (12 triangles). Requires `min < max` on every axis.
    pub fn cuboid(&mut self, f: &Frame, min: V3, max: V3) {
        debug_assert!((0..3).all(|i| max[i] - min[i] > 1e-6), "flat box {min:?} {max:?}");
        self.triangles += 12;
        if self.counts_only() {
            return;
        }
        let base = self.reserve(8);
        for i in 0..8 {
            let x = if i & 1 != 0 { max[0] } else { min[0] };
            let y = if i & 2 != 0 { max[1] } else { min[1] };
            let z = if i & 4 != 0 { max[2] } else { min[2] };
            self.positions.push(f.p(x, y, z));
        }
        for q in [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]] {
            self.quad(base, q[0], q[1], q[2], q[3]);
        }
    }

    /// A frustum along local z from `z0` (radius `r0`) to `z1` (radius `r1`) with `sides` sides:
    /// `2·sides` triangles plus `sides − 2` per closed end.
    #[allow(clippy::too_many_arguments)]
    pub fn frustum(
        &mut self,
        f: &Frame,
        r0: f64,
        r1: f64,
        z0: f64,
        z1: f64,
        sides: u32,
        cap0: bool,
        cap1: bool,
    ) {
        debug_assert!(r0 > 0.0 && r1 > 0.0 && z1 - z0 > 1e-6 && (3..=MAX_SIDES).contains(&sides));
        let s = sides;
        self.triangles += 2 * s as u64 + (cap0 as u64 + cap1 as u64) * (s as u64 - 2);
        if self.counts_only() {
            return;
        }
        let base = self.reserve(2 * s as usize);
        for (r, z) in [(r0, z0), (r1, z1)] {
            for &(c, sn) in &self.trig[s as usize] {
                self.positions.push(f.p(r * c, r * sn, z));
            }
        }
        for i in 0..s {
            let j = (i + 1) % s;
            self.quad(base, i, j, s + j, s + i);
        }
        if cap0 {
            for i in 1..s - 1 {
                self.tri(base, 0, i + 1, i);
            }
        }
        if cap1 {
            for i in 1..s - 1 {
                self.tri(base, s, s + i, s + i + 1);
            }
        }
    }

    /// A cylinder along local z (see [`Emitter::frustum`]).
    #[allow(clippy::too_many_arguments)]
    pub fn cylinder(&mut self, f: &Frame, r: f64, z0: f64, z1: f64, sides: u32, cap0: bool, cap1: bool) {
        self.frustum(f, r, r, z0, z1, sides, cap0, cap1);
    }

    /// A cylinder of radius `r` from point `a` to point `b`.
    #[allow(clippy::too_many_arguments)]
    pub fn rod(&mut self, a: V3, b: V3, r: f64, sides: u32, cap0: bool, cap1: bool) {
        let d = sub(b, a);
        let len = length(d);
        if self.counts_only() {
            self.frustum(&Frame::at(a), r, r, 0.0, 1.0, sides, cap0, cap1);
            return;
        }
        let f = Frame::axis(a, scale(d, 1.0 / len));
        self.frustum(&f, r, r, 0.0, len, sides, cap0, cap1);
    }

    /// A half-ellipsoid cap standing on the circle of radius `r` at local `z0`, rising `h` along
    /// +z: `2·sides·(rings − 1) + sides` triangles. Use a [`Frame::flipped`] frame for a cap that
    /// points down.
    #[allow(clippy::too_many_arguments)]
    pub fn dome(&mut self, f: &Frame, r: f64, z0: f64, h: f64, sides: u32, rings: u32) {
        debug_assert!(r > 0.0 && h > 0.0 && rings >= 1 && (3..=MAX_SIDES).contains(&sides));
        let s = sides;
        self.triangles += 2 * s as u64 * (rings as u64 - 1) + s as u64;
        if self.counts_only() {
            return;
        }
        let base = self.reserve((s * rings + 1) as usize);
        for k in 0..rings {
            let phi = std::f64::consts::FRAC_PI_2 * k as f64 / rings as f64;
            let (rr, z) = (r * phi.cos(), z0 + h * phi.sin());
            for &(c, sn) in &self.trig[s as usize] {
                self.positions.push(f.p(rr * c, rr * sn, z));
            }
        }
        self.positions.push(f.p(0.0, 0.0, z0 + h));
        for k in 0..rings - 1 {
            for i in 0..s {
                let j = (i + 1) % s;
                self.quad(base, k * s + i, k * s + j, (k + 1) * s + j, (k + 1) * s + i);
            }
        }
        let top = (rings - 1) * s;
        for i in 0..s {
            self.tri(base, top + i, top + (i + 1) % s, rings * s);
        }
    }

    /// A torus about local z: ring radius `big`, tube radius `small < big`; `2·a·b` triangles.
    pub fn torus(&mut self, f: &Frame, big: f64, small: f64, a: u32, b: u32) {
        debug_assert!(small > 0.0 && big > small * 1.2 && a >= 3 && b >= 3);
        self.triangles += 2 * a as u64 * b as u64;
        if self.counts_only() {
            return;
        }
        let base = self.reserve((a * b) as usize);
        for i in 0..a as usize {
            let (ct, st) = self.trig[a as usize][i];
            for j in 0..b as usize {
                let (cp, sp) = self.trig[b as usize][j];
                let rr = big + small * cp;
                self.positions.push(f.p(rr * ct, rr * st, small * sp));
            }
        }
        for i in 0..a {
            let i1 = (i + 1) % a;
            for j in 0..b {
                let j1 = (j + 1) % b;
                self.quad(base, i * b + j, i1 * b + j, i1 * b + j1, i * b + j1);
            }
        }
    }

    /// A flat round plate in local plane z = `z`: a polygon of `k + 2` corners, `k` triangles
    /// (any `k ≥ 1`), facing +z when `up`, −z otherwise.
    pub fn disc(&mut self, f: &Frame, r: f64, z: f64, k: u32, up: bool) {
        debug_assert!(r > 0.0 && k >= 1 && k + 2 <= MAX_SIDES);
        self.triangles += k as u64;
        if self.counts_only() {
            return;
        }
        let n = k + 2;
        let base = self.reserve(n as usize);
        for &(c, sn) in &self.trig[n as usize] {
            self.positions.push(f.p(r * c, r * sn, z));
        }
        for i in 1..=k {
            if up {
                self.tri(base, 0, i, i + 1);
            } else {
                self.tri(base, 0, i + 1, i);
            }
        }
    }

    /// A flat ring (a flange) around local z from `z0` to `z1`, radii `r_in < r_out`: `8·sides`
    /// triangles.
    #[allow(clippy::too_many_arguments)]
    pub fn ring_plate(&mut self, f: &Frame, r_in: f64, r_out: f64, z0: f64, z1: f64, sides: u32) {
        debug_assert!(r_in > 0.0 && r_out > r_in && z1 > z0 && (3..=MAX_SIDES).contains(&sides));
        let s = sides;
        self.triangles += 8 * s as u64;
        if self.counts_only() {
            return;
        }
        let base = self.reserve(4 * s as usize);
        for (r, z) in [(r_out, z0), (r_out, z1), (r_in, z0), (r_in, z1)] {
            for &(c, sn) in &self.trig[s as usize] {
                self.positions.push(f.p(r * c, r * sn, z));
            }
        }
        let (ob, ot, ib, it) = (0, s, 2 * s, 3 * s);
        for i in 0..s {
            let j = (i + 1) % s;
            self.quad(base, ob + i, ob + j, ot + j, ot + i);
            self.quad(base, ib + i, it + i, it + j, ib + j);
            self.quad(base, it + i, ot + i, ot + j, it + j);
            self.quad(base, ib + i, ib + j, ob + j, ob + i);
        }
    }

    /// An I-beam along local z from `z0` to `z1`: flange width `b` (local x), depth `h`
    /// (local y), flange thickness `tf`, web thickness `tw`; [`IBEAM_TRIS`] triangles.
    #[allow(clippy::too_many_arguments)]
    pub fn ibeam(&mut self, f: &Frame, b: f64, h: f64, tf: f64, tw: f64, z0: f64, z1: f64) {
        debug_assert!(b > tw && h > 2.0 * tf && tw > 0.0 && tf > 0.0 && z1 > z0);
        self.triangles += IBEAM_TRIS;
        if self.counts_only() {
            return;
        }
        let (x, y, w) = (b / 2.0, h / 2.0, tw / 2.0);
        let profile = [
            (-x, -y),
            (x, -y),
            (x, -y + tf),
            (w, -y + tf),
            (w, y - tf),
            (x, y - tf),
            (x, y),
            (-x, y),
            (-x, y - tf),
            (-w, y - tf),
            (-w, -y + tf),
            (-x, -y + tf),
        ];
        let base = self.reserve(24);
        for z in [z0, z1] {
            for &(px, py) in &profile {
                self.positions.push(f.p(px, py, z));
            }
        }
        for i in 0..12 {
            let j = (i + 1) % 12;
            self.quad(base, i, j, 12 + j, 12 + i);
        }
        for q in [[0, 1, 2, 11], [10, 3, 4, 9], [8, 5, 6, 7]] {
            self.quad(base, 12 + q[0], 12 + q[1], 12 + q[2], 12 + q[3]);
            self.quad(base, q[0], q[3], q[2], q[1]);
        }
    }

    /// Starts a swept tube of `sides` sides: each later [`Emitter::strip_ring`] adds a ring and,
    /// from the second on, `2·sides` triangles joining it to the one before.
    pub fn strip_begin(&mut self, sides: u32) {
        debug_assert!((3..=MAX_SIDES).contains(&sides));
        self.strip_sides = sides;
        self.strip_prev = None;
    }

    /// Adds a ring of radius `r` around `c` in the plane of the unit vectors `u`, `v` (the tube
    /// runs along `u × v`).
    pub fn strip_ring(&mut self, c: V3, u: V3, v: V3, r: f64) {
        let s = self.strip_sides as usize;
        if self.counts_only() {
            if self.strip_prev.is_some() {
                self.triangles += 2 * s as u64;
            }
            self.strip_prev = Some(0);
            return;
        }
        if self.positions.len() + s > CHUNK_VERTICES {
            // Carry the previous ring into the next chunk so the tube stays joined.
            let prev = self.strip_prev;
            if let Some(p) = prev {
                self.scratch.clear();
                self.scratch.extend_from_slice(&self.positions[p as usize..p as usize + s]);
            }
            self.flush();
            self.strip_prev = None;
            if prev.is_some() {
                let p = self.reserve(s);
                self.positions.extend_from_slice(&self.scratch);
                self.strip_prev = Some(p);
            }
        }
        let prev = self.strip_prev;
        let base = self.reserve(s);
        for &(cs, sn) in &self.trig[s] {
            let (a, b) = (r * cs, r * sn);
            self.positions.push([
                c[0] + a * u[0] + b * v[0],
                c[1] + a * u[1] + b * v[1],
                c[2] + a * u[2] + b * v[2],
            ]);
        }
        if let Some(p) = prev {
            self.triangles += 2 * s as u64;
            let s = s as u32;
            for i in 0..s {
                let j = (i + 1) % s;
                self.indices.extend_from_slice(&[p + i, p + j, base + j, p + i, base + j, base + i]);
            }
        }
        self.strip_prev = Some(base);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Triangle, TriangleSink};

    /// Collects triangles and checks each one.
    #[derive(Default)]
    struct Check {
        triangles: u64,
        degenerate: u64,
        objects: u32,
    }

    impl TriangleSink for Check {
        fn object(&mut self, id: ObjectId, _info: &ObjectInfo) -> Result<(), ImportError> {
            assert_eq!(id, self.objects);
            self.objects += 1;
            Ok(())
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.triangles += 1;
            self.degenerate += t.is_degenerate() as u64;
            Ok(())
        }
    }

    fn every_primitive(e: &mut Emitter<'_>) {
        let f = Frame::axis([100.0, 200.0, 3.0], normalize([1.0, 2.0, 0.5]));
        e.begin("shapes", Rgba8::GREY);
        e.cuboid(&f, [0.0, 0.0, 0.0], [0.01, 0.02, 0.03]);
        e.frustum(&f, 0.2, 0.1, 0.0, 1.0, 7, true, true);
        e.cylinder(&f, 0.004, 0.0, 0.01, 16, true, false);
        e.rod([0.0; 3], [0.0, 0.0, 1.0], 0.01, 6, false, true);
        e.dome(&f, 1.0, 0.0, 0.3, 24, 5);
        e.dome(&f.flipped(), 1.0, 0.0, 0.3, 5, 1);
        e.torus(&f, 0.1, 0.01, 12, 6);
        for k in 1..6 {
            e.disc(&f, 0.1, 0.0, k, k % 2 == 0);
        }
        e.ring_plate(&f, 0.05, 0.1, 0.0, 0.02, 9);
        e.ibeam(&f, 0.3, 0.3, 0.02, 0.012, 0.0, 4.0);
        e.strip_begin(8);
        for i in 0..5 {
            e.strip_ring([i as f64, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], 0.1);
        }
    }

    #[test]
    fn primitives_count_exactly_and_are_never_degenerate() {
        let mut counter = Emitter::counting();
        every_primitive(&mut counter);
        let mut sink = Check::default();
        let mut e = Emitter::new(&mut sink);
        every_primitive(&mut e);
        let n = e.triangles();
        e.finish().unwrap();
        assert_eq!(n, counter.triangles());
        assert_eq!(sink.triangles, n);
        assert_eq!(sink.degenerate, 0);
        assert_eq!(sink.objects, 1);
        // 12 + 24 + 46 + 16 + 216 + 5 + 144 + 15 + 72 + 36 + 64
        assert_eq!(n, 650);
    }

    #[test]
    fn long_strips_stay_joined_across_chunks() {
        let mut sink = Check::default();
        let mut e = Emitter::new(&mut sink);
        e.begin("pipe", Rgba8::GREY);
        e.strip_begin(48);
        let rings = 3 * CHUNK_VERTICES / 48;
        for i in 0..rings {
            e.strip_ring([i as f64 * 0.01, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], 0.1);
        }
        e.finish().unwrap();
        assert_eq!(sink.triangles, 2 * 48 * (rings as u64 - 1));
        assert_eq!(sink.degenerate, 0);
    }

    #[test]
    fn outward_winding_of_a_box_and_a_cylinder() {
        struct Normals(Vec<(V3, V3)>);
        impl TriangleSink for Normals {
            fn object(&mut self, _: ObjectId, _: &ObjectInfo) -> Result<(), ImportError> {
                Ok(())
            }
            fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
                let [a, b, c] = t.positions;
                let n = cross(sub(b, a), sub(c, a));
                let centre = scale(add(add(a, b), c), 1.0 / 3.0);
                self.0.push((centre, n));
                Ok(())
            }
        }
        let mut sink = Normals(Vec::new());
        let mut e = Emitter::new(&mut sink);
        e.begin("b", Rgba8::GREY);
        e.cuboid(&Frame::at([0.0; 3]), [-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]);
        e.cylinder(&Frame::at([0.0; 3]), 1.0, -1.0, 1.0, 12, true, true);
        e.finish().unwrap();
        for (c, n) in sink.0 {
            assert!(dot(c, n) > 0.0, "inward face at {c:?}");
        }
    }
}
