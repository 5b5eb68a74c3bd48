//! Wald's 18-direction proxies (Wald, Dietrich & Slusallek 2004, §5.2 "Hybrid
//! volumetric/lightfield-like proxies"):
//! what a ray that reaches missing geometry is shaded from. A proxy stands for a region seen
//! from outside and keeps, per direction of the incoming ray, the averaged diffuse colour and the
//! averaged normal of the surface first seen from that direction; the hit position is ignored
//! (the paper assumes proxies project below a pixel), so a large proxy looks like a coloured box.
//!
//! - **Directions**: the 18 vertices of a once-subdivided octahedron, the 6 axes and the 12
//!   directions of the `(±1, ±1, 0)` kind ([`directions`]).
//! - **Lookup** ([`weights`]): the octant from the direction's sign bits, then the sub-triangle
//!   of that octant's face (one of four) holding the direction's central projection onto the
//!   face, and its barycentric coordinates there: the three nearest directions with weights
//!   `≥ 0` summing to 1, exact at the 18 directions and continuous everywhere (the paper's
//!   "spherical triangle that contains this direction", with barycentrics taken on the flat
//!   face, which the central projection maps onto the spherical triangle).
//! - **Storage** ([`Proxy`], 80 bytes as in the paper): per direction an RGB565 colour and a
//!   16-bit octahedral normal (two 8-bit coordinates in `1..=255`; the code 0 marks a direction
//!   from which the region showed no surface), a float area (the region's surface area, the
//!   paper's loading priority) and a u32 id.
//! - **Generation** ([`generate`]): rays shot at the region from outside along Halton
//!   directions (bases 2, 3) through Halton points of the disc that covers the region's box
//!   (bases 5, 7); only each ray's first hit counts, so hidden geometry does not tint the proxy
//!   (the paper's yellow cables behind a green panel). A ray is splatted onto its three
//!   directions with its lookup weights; colours are averaged in linear light (the shader's
//!   `pow(c, 2.2)`), normals (turned towards the ray's origin) summed and normalised — which
//!   over-brightens the edges of a box, as the paper notes (§5.2).
//! - **Shading** ([`Proxy::sample`]): colour and normal interpolated over the directions that
//!   saw a surface; lighting is applied at render time by the caller.

use glam::Vec3;

use crate::{MeshError, Ray, TriangleBvh};

/// Directions a proxy keeps.
pub const DIRECTIONS: usize = 18;

/// The rays [`generate`] shoots by default: the paper's "~10K".
pub const DEFAULT_RAYS: u32 = 10_000;

/// The most rays [`generate`] accepts for one proxy.
pub const MAX_RAYS: u32 = 1 << 20;

/// Index of the axis direction `axis` (0 x, 1 y, 2 z) with sign `negative`.
fn axis_index(axis: usize, negative: bool) -> usize {
    2 * axis + negative as usize
}

/// Index of the edge direction between axes `a < b` (0: xy, 1: yz, 2: xz) with the signs of
/// those two components.
fn edge_index(edge: usize, negative_a: bool, negative_b: bool) -> usize {
    6 + 4 * edge + negative_a as usize + 2 * negative_b as usize
}

/// The 18 unit directions: `0..6` the axes (+x, −x, +y, −y, +z, −z), `6..18` the edges of
/// the octahedron's faces: xy, yz and xz, each with signs (+,+), (−,+), (+,−), (−,−).
pub fn directions() -> [Vec3; DIRECTIONS] {
    let mut d = [Vec3::ZERO; DIRECTIONS];
    for axis in 0..3 {
        for negative in [false, true] {
            let mut v = Vec3::ZERO;
            v[axis] = if negative { -1.0 } else { 1.0 };
            d[axis_index(axis, negative)] = v;
        }
    }
    let h = std::f32::consts::FRAC_1_SQRT_2;
    for (edge, (a, b)) in EDGES.iter().enumerate() {
        for (na, nb) in [(false, false), (true, false), (false, true), (true, true)] {
            let mut v = Vec3::ZERO;
            v[*a] = if na { -h } else { h };
            v[*b] = if nb { -h } else { h };
            d[edge_index(edge, na, nb)] = v;
        }
    }
    d
}

/// The axes of each edge direction, in the order of [`directions`].
const EDGES: [(usize, usize); 3] = [(0, 1), (1, 2), (0, 2)];

/// The three directions around `dir` and their barycentric weights (`≥ 0`, summing to 1; see
/// the module documentation). `dir` need not be unit length; a zero or non-finite direction
/// gets +z.
pub fn weights(dir: Vec3) -> [(usize, f32); 3] {
    let a = dir.abs();
    let sum = a.x + a.y + a.z;
    if !sum.is_finite() || sum <= 0.0 {
        return [(axis_index(2, false), 1.0), (axis_index(0, false), 0.0), (axis_index(1, false), 0.0)];
    }
    // Barycentrics of the central projection on the octant's face (x, y, z corners).
    let b = [a.x / sum, a.y / sum, a.z / sum];
    let neg = [dir.x < 0.0, dir.y < 0.0, dir.z < 0.0];
    let axis = |k: usize| axis_index(k, neg[k]);
    let edge = |e: usize| {
        let (i, j) = EDGES[e];
        edge_index(e, neg[i], neg[j])
    };
    // The edge between axes i and j, by the axis pair.
    let edge_of = |i: usize, j: usize| match (i.min(j), i.max(j)) {
        (0, 1) => edge(0),
        (1, 2) => edge(1),
        _ => edge(2),
    };
    for k in 0..3 {
        if b[k] >= 0.5 {
            // The corner sub-triangle of axis k: (axis k, edge k–i, edge k–j).
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            return [(axis(k), 2.0 * b[k] - 1.0), (edge_of(k, i), 2.0 * b[i]), (edge_of(k, j), 2.0 * b[j])];
        }
    }
    // The middle sub-triangle: each edge's weight falls to 0 at the opposite axis's corner.
    [(edge(0), 1.0 - 2.0 * b[2]), (edge(1), 1.0 - 2.0 * b[0]), (edge(2), 1.0 - 2.0 * b[1])]
}

/// One proxy: what a region looks like from each of the 18 directions (module documentation).
/// 80 bytes, as in the paper.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Proxy {
    /// Per direction `[RGB565 colour, octahedral normal]`; a normal code of 0: no surface.
    pub samples: [[u16; 2]; DIRECTIONS],
    /// Surface area of the region's triangles (scene units²; the paper's loading priority).
    pub area: f32,
    /// What the proxy stands for (the caller's id: a group of the store).
    pub id: u32,
}

/// A proxy's look from one direction, decoded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProxySample {
    /// sRGB colour.
    pub color: [u8; 3],
    /// Unit normal, facing where the ray came from.
    pub normal: Vec3,
}

impl Proxy {
    /// The look from direction `k` of [`directions`], if a surface was seen from there.
    pub fn direction(&self, k: usize) -> Option<ProxySample> {
        let [color, normal] = self.samples[k];
        Some(ProxySample { color: rgb565_decode(color), normal: normal_decode(normal)? })
    }

    /// The look along a ray of direction `dir`: colour and normal interpolated over the
    /// ray's three directions that saw a surface ([`weights`], renormalised); `None` when none
    /// of them did.
    pub fn sample(&self, dir: Vec3) -> Option<ProxySample> {
        let (mut color, mut normal, mut total) = ([0.0f32; 3], Vec3::ZERO, 0.0f32);
        for (k, w) in weights(dir) {
            if w <= 0.0 {
                continue;
            }
            if let Some(s) = self.direction(k) {
                for c in 0..3 {
                    color[c] += w * s.color[c] as f32;
                }
                normal += w * s.normal;
                total += w;
            }
        }
        if total <= 0.0 {
            return None;
        }
        let color = color.map(|c| (c / total).round().clamp(0.0, 255.0) as u8);
        Some(ProxySample { color, normal: normal.normalize_or(-dir.normalize_or(Vec3::Z)) })
    }
}

/// RGB565 of an sRGB colour (rounded).
pub fn rgb565_encode(c: [u8; 3]) -> u16 {
    let q = |v: u8, max: u32| ((v as u32 * max + 127) / 255) as u16;
    (q(c[0], 31) << 11) | (q(c[1], 63) << 5) | q(c[2], 31)
}

/// The sRGB colour of an RGB565 code.
pub fn rgb565_decode(c: u16) -> [u8; 3] {
    let e = |v: u16, max: u32| ((v as u32 * 255 + max / 2) / max) as u8;
    [e(c >> 11, 31), e((c >> 5) & 63, 63), e(c & 31, 31)]
}

/// A unit normal in 16 bits: its octahedral map (Meyer et al. 2010, "On floating-point normal
/// vectors") quantised to 255 levels per coordinate, stored as `1..=255` so that 0 stays free
/// for "no surface". A zero vector encodes as +z.
pub fn normal_encode(n: Vec3) -> u16 {
    let n = n.normalize_or(Vec3::Z);
    let s = n.x.abs() + n.y.abs() + n.z.abs();
    let (mut u, mut v) = (n.x / s, n.y / s);
    if n.z < 0.0 {
        let (pu, pv) = (u, v);
        u = (1.0 - pv.abs()) * sign(pu);
        v = (1.0 - pu.abs()) * sign(pv);
    }
    let q = |x: f32| ((x.clamp(-1.0, 1.0) * 0.5 + 0.5) * 254.0).round() as u16 + 1;
    (q(u) << 8) | q(v)
}

/// The unit normal of a [`normal_encode`] code; `None` for 0 ("no surface") and for a code
/// with a zero byte.
pub fn normal_decode(code: u16) -> Option<Vec3> {
    let (qu, qv) = (code >> 8, code & 0xff);
    if qu == 0 || qv == 0 {
        return None;
    }
    let d = |q: u16| (q - 1) as f32 / 254.0 * 2.0 - 1.0;
    let (u, v) = (d(qu), d(qv));
    let z = 1.0 - u.abs() - v.abs();
    let (x, y) = if z < 0.0 { ((1.0 - v.abs()) * sign(u), (1.0 - u.abs()) * sign(v)) } else { (u, v) };
    Some(Vec3::new(x, y, z).normalize())
}

fn sign(x: f32) -> f32 {
    if x < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// The radical inverse of `i` in base `base` (the Halton sequence's `i`-th value).
fn halton(mut i: u32, base: u32) -> f32 {
    let (mut f, mut r) = (1.0f64, 0.0f64);
    while i > 0 {
        f /= base as f64;
        r += f * (i % base) as f64;
        i /= base;
    }
    r as f32
}

/// The geometry a proxy is generated from: triangles over `positions` with an sRGB colour per
/// triangle.
pub struct ProxyInput<'a> {
    pub positions: &'a [[f32; 3]],
    pub triangles: &'a [[u32; 3]],
    pub colors: &'a [[u8; 3]],
}

/// Why [`generate`] refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ProxyError {
    #[error("proxy rays: {0} is out of range (1..={MAX_RAYS})")]
    Rays(u32),
    #[error("proxy input: {colors} colours for {triangles} triangles")]
    Colors { triangles: usize, colors: usize },
    #[error("proxy input: {0}")]
    Mesh(#[from] MeshError),
}

/// Sums of what one direction saw while generating.
#[derive(Clone, Copy, Default)]
struct Accumulator {
    weight: f32,
    color: [f32; 3],
    normal: Vec3,
}

/// Generates the proxy of `input` (id `id`) from `rays` Halton rays shot from outside the box
/// of its triangles (module documentation). Deterministic: the same input gives the same proxy.
pub fn generate(input: &ProxyInput, rays: u32, id: u32) -> Result<Proxy, ProxyError> {
    if !(1..=MAX_RAYS).contains(&rays) {
        return Err(ProxyError::Rays(rays));
    }
    if input.colors.len() != input.triangles.len() {
        return Err(ProxyError::Colors { triangles: input.triangles.len(), colors: input.colors.len() });
    }
    let mut proxy = Proxy { samples: [[0, 0]; DIRECTIONS], area: area(input), id };
    let Some((centre, radius)) = bounding_sphere(input) else { return Ok(proxy) };
    let bvh = TriangleBvh::build(input.positions, input.triangles)?;
    let mut sums = [Accumulator::default(); DIRECTIONS];
    for i in 0..rays {
        let ray = halton_ray(i + 1, centre, radius);
        let Some(hit) = bvh.intersect(&ray) else { continue };
        let [a, b, c] = input.triangles[hit.prim as usize].map(|v| Vec3::from(input.positions[v as usize]));
        let n = (b - a).cross(c - a).normalize_or_zero();
        let n = if n.dot(ray.dir) > 0.0 { -n } else { n };
        let linear = input.colors[hit.prim as usize].map(|c| (c as f32 / 255.0).powf(2.2));
        for (k, w) in weights(ray.dir) {
            let s = &mut sums[k];
            s.weight += w;
            for j in 0..3 {
                s.color[j] += w * linear[j];
            }
            s.normal += w * n;
        }
    }
    for (k, s) in sums.iter().enumerate() {
        if s.weight > 0.0 && s.normal.length_squared() > 0.0 {
            let color =
                s.color.map(|c| ((c / s.weight).powf(1.0 / 2.2) * 255.0).round().clamp(0.0, 255.0) as u8);
            proxy.samples[k] = [rgb565_encode(color), normal_encode(s.normal)];
        }
    }
    Ok(proxy)
}

/// Ray `i` (from 1) of [`generate`]: a Halton direction, aimed through a Halton point of the
/// disc of radius `radius` around `centre` perpendicular to it, starting outside the sphere.
fn halton_ray(i: u32, centre: Vec3, radius: f32) -> Ray {
    let (u, v) = (halton(i, 2), halton(i, 3));
    let z = 1.0 - 2.0 * u;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * v;
    let dir = Vec3::new(r * phi.cos(), r * phi.sin(), z);
    let (e1, e2) = dir.any_orthonormal_pair();
    let (s, t) = (halton(i, 5), halton(i, 7));
    let (rr, theta) = (radius * s.sqrt(), std::f32::consts::TAU * t);
    let origin = centre - 2.0 * radius * dir + rr * (theta.cos() * e1 + theta.sin() * e2);
    Ray::new(origin, dir)
}

/// The centre and half diagonal of the box of the triangles' vertices; `None` without
/// triangles or for a box of no size.
fn bounding_sphere(input: &ProxyInput) -> Option<(Vec3, f32)> {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for t in input.triangles {
        for &v in t {
            let p = Vec3::from(*input.positions.get(v as usize)?);
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    let radius = 0.5 * (hi - lo).length();
    (radius > 0.0 && radius.is_finite()).then(|| (0.5 * (lo + hi), radius))
}

/// Total area of the triangles.
fn area(input: &ProxyInput) -> f32 {
    let p = |v: u32| input.positions.get(v as usize).map_or(Vec3::ZERO, |&p| Vec3::from(p));
    input.triangles.iter().map(|&[a, b, c]| 0.5 * (p(b) - p(a)).cross(p(c) - p(a)).length()).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn weight_vector(dir: Vec3) -> [f32; DIRECTIONS] {
        let mut w = [0.0; DIRECTIONS];
        for (k, x) in weights(dir) {
            w[k] += x;
        }
        w
    }

    #[test]
    fn a_proxy_is_80_bytes() {
        assert_eq!(std::mem::size_of::<Proxy>(), 80);
    }

    #[test]
    fn the_directions_are_distinct_unit_vectors() {
        let d = directions();
        for (i, a) in d.iter().enumerate() {
            assert!((a.length() - 1.0).abs() < 1e-6);
            for b in &d[i + 1..] {
                assert!(a.dot(*b) < 0.8, "{a} and {b}");
            }
        }
    }

    #[test]
    fn lookup_is_exact_at_the_18_directions() {
        for (k, d) in directions().iter().enumerate() {
            let w = weight_vector(*d);
            assert!((w[k] - 1.0).abs() < 1e-6, "direction {k}: {w:?}");
            assert!(w.iter().enumerate().all(|(j, &x)| j == k || x.abs() < 1e-6), "direction {k}: {w:?}");
        }
    }

    #[test]
    fn weights_are_non_negative_and_sum_to_one() {
        for i in 1..5000 {
            let d = halton_ray(i, Vec3::ZERO, 1.0).dir;
            let w = weights(d);
            assert!(w.iter().all(|&(_, x)| x >= -1e-6), "{d}: {w:?}");
            let sum: f32 = w.iter().map(|&(_, x)| x).sum();
            assert!((sum - 1.0).abs() < 1e-5, "{d}: {sum}");
            // The three directions are near `d`: within the octant's sub-triangle.
            let dirs = directions();
            assert!(w.iter().all(|&(k, x)| x < 1e-6 || dirs[k].dot(d) > 0.5), "{d}: {w:?}");
        }
    }

    #[test]
    fn lookup_is_continuous() {
        // Small steps across octant and sub-triangle borders change the weights by little.
        let dirs = directions();
        let eps = 1e-4;
        for i in 1..3000 {
            let d = halton_ray(i, Vec3::ZERO, 1.0).dir;
            // Also directions on the borders themselves, nudged both ways.
            let border =
                [d, dirs[(i % 18) as usize] + 0.3 * d, Vec3::new(d.x, 0.0, d.z), Vec3::new(d.x, d.x, d.z)];
            for b in border {
                let b = b.normalize();
                let step = b.any_orthonormal_vector() * eps;
                let (w0, w1) = (weight_vector(b - step), weight_vector(b + step));
                let change: f32 = w0.iter().zip(&w1).map(|(a, c)| (a - c).abs()).sum();
                assert!(change < 100.0 * eps, "{b}: {change}");
            }
        }
    }

    /// The 12 triangles of the box `[lo, hi]`.
    fn cube(lo: Vec3, hi: Vec3) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let p: Vec<[f32; 3]> = (0..8)
            .map(|i| {
                let pick = |bit: u32, a: f32, b: f32| if i & bit != 0 { b } else { a };
                [pick(1, lo.x, hi.x), pick(2, lo.y, hi.y), pick(4, lo.z, hi.z)]
            })
            .collect();
        let quads = [[0, 2, 6, 4], [1, 3, 7, 5], [0, 1, 5, 4], [2, 3, 7, 6], [0, 1, 3, 2], [4, 5, 7, 6]];
        let t = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        (p, t)
    }

    #[test]
    fn a_boxs_faces_give_the_normals_of_each_direction() {
        let (p, t) = cube(Vec3::splat(-1.0), Vec3::new(1.0, 2.0, 0.5));
        let colors = vec![[200, 100, 50]; t.len()];
        let proxy =
            generate(&ProxyInput { positions: &p, triangles: &t, colors: &colors }, DEFAULT_RAYS, 7).unwrap();
        assert_eq!(proxy.id, 7);
        let expected_area = 2.0 * (3.0 * 1.5 + 2.0 * 1.5 + 2.0 * 3.0);
        assert!((proxy.area - expected_area).abs() < 1e-4, "{}", proxy.area);
        for (k, d) in directions().iter().enumerate() {
            let s = proxy.direction(k).unwrap_or_else(|| panic!("direction {k} saw nothing"));
            assert_eq!(s.color, rgb565_decode(rgb565_encode([200, 100, 50])));
            if k < 6 {
                // Along an axis only the face turned towards the ray's origin is seen.
                assert!(s.normal.dot(-*d) > 0.999, "direction {k}: {}", s.normal);
            } else {
                // Between two axes both faces are seen: the averaged normal lies between them.
                let n = s.normal;
                assert!(n.dot(-*d) > 0.9, "direction {k}: {n}");
                assert!(d.x * n.x <= 0.0 && d.y * n.y <= 0.0 && d.z * n.z <= 0.0, "direction {k}: {n}");
            }
        }
    }

    #[test]
    fn hidden_geometry_does_not_tint_the_proxy() {
        // A green plane at z = 0 over [-2, 2]², a small yellow triangle under its middle.
        let (green, yellow) = ([0, 200, 0], [250, 220, 0]);
        let positions = vec![
            [-2.0, -2.0, 0.0],
            [2.0, -2.0, 0.0],
            [2.0, 2.0, 0.0],
            [-2.0, 2.0, 0.0],
            [-0.3, -0.3, -0.5],
            [0.3, -0.3, -0.5],
            [0.0, 0.3, -0.5],
        ];
        let down = axis_index(2, true);
        let plane_and_cable = ProxyInput {
            positions: &positions,
            triangles: &[[0, 1, 2], [0, 2, 3], [4, 5, 6]],
            colors: &[green, green, yellow],
        };
        let proxy = generate(&plane_and_cable, DEFAULT_RAYS, 0).unwrap();
        let seen = proxy.direction(down).unwrap();
        assert_eq!(seen.color, rgb565_decode(rgb565_encode(green)), "seen from above");
        assert!(seen.normal.z > 0.999);
        // From below the cable shows in front of the plane's underside: both count there.
        let up = proxy.direction(axis_index(2, false)).unwrap();
        assert!(up.color[0] > 0, "seen from below: {:?}", up.color);
        // The control: without the plane, the cable alone is yellow from above.
        let cable = ProxyInput { positions: &positions, triangles: &[[4, 5, 6]], colors: &[yellow] };
        let alone = generate(&cable, DEFAULT_RAYS, 0).unwrap().direction(down).unwrap();
        assert_eq!(alone.color, rgb565_decode(rgb565_encode(yellow)));
    }

    #[test]
    fn generation_is_deterministic_and_bounded() {
        let (p, t) = cube(Vec3::ZERO, Vec3::ONE);
        let colors = vec![[9, 9, 9]; t.len()];
        let input = ProxyInput { positions: &p, triangles: &t, colors: &colors };
        assert_eq!(generate(&input, 500, 1), generate(&input, 500, 1));
        assert_eq!(generate(&input, 0, 1), Err(ProxyError::Rays(0)));
        assert_eq!(generate(&input, MAX_RAYS + 1, 1), Err(ProxyError::Rays(MAX_RAYS + 1)));
        let wrong = ProxyInput { colors: &colors[1..], ..input };
        assert!(matches!(generate(&wrong, 10, 1), Err(ProxyError::Colors { .. })));
    }

    #[test]
    fn sampling_interpolates_and_skips_empty_directions() {
        let mut proxy = Proxy { samples: [[0, 0]; DIRECTIONS], area: 1.0, id: 0 };
        let (x, xy) = (axis_index(0, false), edge_index(0, false, false));
        proxy.samples[x] = [rgb565_encode([255, 0, 0]), normal_encode(-Vec3::X)];
        // Exactly on +x: that direction alone.
        assert_eq!(proxy.sample(Vec3::X).unwrap().color, [255, 0, 0]);
        // Between +x and the empty +xy: +x's look, renormalised.
        assert_eq!(proxy.sample(Vec3::new(1.0, 0.3, 0.0)).unwrap().color, [255, 0, 0]);
        proxy.samples[xy] = [rgb565_encode([0, 0, 255]), normal_encode(-Vec3::Y)];
        let mid = proxy.sample(Vec3::new(1.0, 0.5, 0.0)).unwrap();
        assert!(mid.color[0] > 0 && mid.color[2] > 0, "{:?}", mid.color);
        // Nothing seen around -x.
        assert_eq!(proxy.sample(-Vec3::X), None);
    }

    #[test]
    fn codes_round_trip_within_their_precision() {
        for i in 1..2000 {
            let n = halton_ray(i, Vec3::ZERO, 1.0).dir;
            let back = normal_decode(normal_encode(n)).unwrap();
            assert!(back.dot(n) > 0.9995, "{n} -> {back}");
        }
        assert_eq!(normal_decode(0), None);
        for c in [[0, 0, 0], [255, 255, 255], [12, 200, 99]] {
            let back = rgb565_decode(rgb565_encode(c));
            assert!(c.iter().zip(back).all(|(a, b)| (*a as i32 - b as i32).abs() <= 4), "{c:?} {back:?}");
        }
    }
}
