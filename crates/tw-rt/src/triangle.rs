//! Watertight ray/triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection") and the leaf layout it reads.
//!
//! The ray is turned into a shear-and-permute transform that maps its direction onto +z; the
//! triangle's vertices, taken relative to the ray origin and transformed, are tested with 2D
//! edge functions. A shared edge gives exactly opposite edge values in its two triangles (the
//! products are the same numbers), so no ray slips between triangles that share an edge or a
//! vertex. Edge values of exactly 0 are recomputed in f64 (section 4 of the paper) so that the
//! sign of a ray through a vertex is decided consistently.
//!
//! [`lanes`] runs the test on `L` independent lanes; the same code serves one ray against the 4
//! triangles of a [`TriGroup`] (`L = 4`), 8 rays of a packet against one triangle (`L = 8`) and
//! the scalar reference (`L = 1`), so all paths return bit-identical results.

use glam::Vec3;

use crate::aabb::{max, min};
use crate::ray::Ray;

/// Triangles per leaf group.
pub(crate) const GROUP: usize = 4;

/// The shear-and-permute transform of one ray (section 3 of the paper).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Shear {
    /// Axes `kx, ky, kz`: `kz` the largest direction component; `kx, ky` swapped when
    /// `dir[kz] < 0` to keep the winding.
    pub k: [usize; 3],
    /// `Sx = dx/dz`, `Sy = dy/dz`, `Sz = 1/dz` (in the permuted axes).
    pub s: [f32; 3],
}

impl Shear {
    pub fn new(dir: Vec3) -> Shear {
        let d = dir.to_array();
        let [kx, ky, kz] = Shear::axes(d);
        Shear { k: [kx, ky, kz], s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]] }
    }

    /// The axis of the largest direction component (ties go to the lower axis).
    #[inline(always)]
    pub fn major_axis(d: [f32; 3]) -> usize {
        let a = d.map(f32::abs);
        if a[0] >= a[1] && a[0] >= a[2] {
            0
        } else if a[1] >= a[2] {
            1
        } else {
            2
        }
    }

    /// The permutation `[kx, ky, kz]` for direction `d`: `kz` the major axis, `kx, ky` the
    /// next two, swapped when `d[kz]` is negative (paper, section 3).
    #[inline(always)]
    pub fn axes(d: [f32; 3]) -> [usize; 3] {
        let kz = Shear::major_axis(d);
        let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d[kz] < 0.0 {
            [ky, kx, kz]
        } else {
            [kx, ky, kz]
        }
    }
}

/// Results of [`lanes`]: a hit mask and, for the hit lanes, `t` and barycentrics.
pub(crate) struct LaneHits<const L: usize> {
    pub mask: u32,
    pub t: [f32; L],
    pub u: [f32; L],
    pub v: [f32; L],
}

/// The watertight test on `L` lanes. `a, b, c` are the vertices minus the ray origin, already
/// permuted to `(kx, ky, kz)`; `s` the shear per lane. A lane hits when `t` lies in
/// `[t_min, t_max)`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn lanes<const L: usize>(
    a: &[[f32; L]; 3],
    b: &[[f32; L]; 3],
    c: &[[f32; L]; 3],
    s: &[[f32; L]; 3],
    t_min: &[f32; L],
    t_max: &[f32; L],
) -> LaneHits<L> {
    let mut e = [[0.0f32; L]; 3];
    let mut any_zero = false;
    for i in 0..L {
        let ax = a[0][i] - s[0][i] * a[2][i];
        let ay = a[1][i] - s[1][i] * a[2][i];
        let bx = b[0][i] - s[0][i] * b[2][i];
        let by = b[1][i] - s[1][i] * b[2][i];
        let cx = c[0][i] - s[0][i] * c[2][i];
        let cy = c[1][i] - s[1][i] * c[2][i];
        e[0][i] = cx * by - cy * bx;
        e[1][i] = ax * cy - ay * cx;
        e[2][i] = bx * ay - by * ax;
        any_zero |= (e[0][i] == 0.0) | (e[1][i] == 0.0) | (e[2][i] == 0.0);
    }
    if any_zero {
        refine_zero_edges(a, b, c, s, &mut e);
    }
    let mut out = LaneHits { mask: 0, t: [0.0; L], u: [0.0; L], v: [0.0; L] };
    // Most lanes miss on the edge signs alone: decide those first and skip the division.
    let mut inside = [false; L];
    for i in 0..L {
        // Inside when no edge value is negative or none is positive (zeros count as both).
        let (u, v, w) = (e[0][i], e[1][i], e[2][i]);
        let lo = min(u, min(v, w));
        let hi = max(u, max(v, w));
        inside[i] = ((lo >= 0.0) | (hi <= 0.0)) & (u + v + w != 0.0);
    }
    if !inside.iter().fold(false, |a, &b| a | b) {
        return out;
    }
    let mut hit = [false; L];
    for i in 0..L {
        let (u, v, w) = (e[0][i], e[1][i], e[2][i]);
        let det = u + v + w;
        let az = s[2][i] * a[2][i];
        let bz = s[2][i] * b[2][i];
        let cz = s[2][i] * c[2][i];
        let tt = u * az + v * bz + w * cz;
        let rcp = 1.0 / det;
        let t = tt * rcp;
        out.t[i] = t;
        out.u[i] = v * rcp;
        out.v[i] = w * rcp;
        hit[i] = inside[i] & (t >= t_min[i]) & (t < t_max[i]);
    }
    for (i, h) in hit.iter().enumerate() {
        out.mask |= (*h as u32) << i;
    }
    out
}

/// Recomputes in f64 the lanes whose f32 edge values came out exactly 0 (paper, section 4).
#[cold]
#[inline(never)]
fn refine_zero_edges<const L: usize>(
    a: &[[f32; L]; 3],
    b: &[[f32; L]; 3],
    c: &[[f32; L]; 3],
    s: &[[f32; L]; 3],
    e: &mut [[f32; L]; 3],
) {
    for i in 0..L {
        if e[0][i] != 0.0 && e[1][i] != 0.0 && e[2][i] != 0.0 {
            continue;
        }
        let ax = a[0][i] - s[0][i] * a[2][i];
        let ay = a[1][i] - s[1][i] * a[2][i];
        let bx = b[0][i] - s[0][i] * b[2][i];
        let by = b[1][i] - s[1][i] * b[2][i];
        let cx = c[0][i] - s[0][i] * c[2][i];
        let cy = c[1][i] - s[1][i] * c[2][i];
        let d = |p: f32, q: f32, r: f32, t: f32| (p as f64 * q as f64 - r as f64 * t as f64) as f32;
        e[0][i] = d(cx, by, cy, bx);
        e[1][i] = d(ax, cy, ay, cx);
        e[2][i] = d(bx, ay, by, ax);
    }
}

/// One ray against one triangle: `(t, u, v)` when it hits within `[ray.t_min, ray.t_max)`.
/// The reference the BVH paths must agree with.
pub fn intersect_triangle(ray: &Ray, p: [Vec3; 3]) -> Option<(f32, f32, f32)> {
    let sh = Shear::new(ray.dir);
    let rel = |q: Vec3| {
        let d = (q - ray.origin).to_array();
        [[d[sh.k[0]]], [d[sh.k[1]]], [d[sh.k[2]]]]
    };
    let s = sh.s.map(|x| [x]);
    let h = lanes::<1>(&rel(p[0]), &rel(p[1]), &rel(p[2]), &s, &[ray.t_min], &[ray.t_max]);
    (h.mask != 0).then_some((h.t[0], h.u[0], h.v[0]))
}

/// Up to four triangles of a leaf in structure-of-arrays order: `v[vertex][axis][lane]`.
/// Unused lanes repeat the last triangle (same `prim`: a duplicate never wins a tie, and
/// [`TriGroup::count`] finds the end from the repeat), which keeps the group at 160 bytes
/// (2.5 cache lines) with no count field.
#[derive(Clone, Debug)]
#[repr(C, align(32))]
pub(crate) struct TriGroup {
    pub v: [[[f32; GROUP]; 3]; 3],
    pub prim: [u32; GROUP],
}

impl TriGroup {
    /// Triangles in use (1 to 4): lanes up to the first repeat of the previous lane's `prim`.
    #[inline(always)]
    pub fn count(&self) -> usize {
        1 + (1..GROUP).take_while(|&i| self.prim[i] != self.prim[i - 1]).count()
    }

    pub fn new(tris: &[([Vec3; 3], u32)]) -> TriGroup {
        let mut g = TriGroup { v: [[[0.0; GROUP]; 3]; 3], prim: [0; GROUP] };
        for lane in 0..GROUP {
            let (p, prim) = tris[lane.min(tris.len() - 1)];
            for (vert, q) in p.iter().enumerate() {
                for axis in 0..3 {
                    g.v[vert][axis][lane] = q[axis];
                }
            }
            g.prim[lane] = prim;
        }
        g
    }

    /// The nearest of the group's triangles along a ray in `[t_min, t_max)`:
    /// `(lane, t, u, v)`.
    #[inline(always)]
    pub fn intersect(
        &self,
        origin: &[f32; 3],
        sh: &Shear,
        t_min: f32,
        t_max: f32,
    ) -> Option<(usize, f32, f32, f32)> {
        let rel = |vert: usize| {
            let mut r = [[0.0f32; GROUP]; 3];
            for (j, &axis) in sh.k.iter().enumerate() {
                for lane in 0..GROUP {
                    r[j][lane] = self.v[vert][axis][lane] - origin[axis];
                }
            }
            r
        };
        let s = sh.s.map(|x| [x; GROUP]);
        let h = lanes::<GROUP>(&rel(0), &rel(1), &rel(2), &s, &[t_min; GROUP], &[t_max; GROUP]);
        if h.mask == 0 {
            return None;
        }
        let mut best = h.mask.trailing_zeros() as usize;
        let mut m = h.mask & (h.mask - 1);
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            if h.t[i] < h.t[best] {
                best = i;
            }
        }
        Some((best, h.t[best], h.u[best], h.v[best]))
    }

    /// True when any triangle of the group is hit in `[t_min, t_max)`.
    #[inline(always)]
    pub fn occluded(&self, origin: &[f32; 3], sh: &Shear, t_min: f32, t_max: f32) -> bool {
        self.intersect(origin, sh, t_min, t_max).is_some()
    }
}
