//! The piping network: one object of swept tubes with bent elbows, routed through every block,
//! emitted after all buildings so that its triangles stay contiguous.
//!
//! Routes per block (all Manhattan polylines, see [`runs`]):
//! 1. rack pipes along the south road, lying on the rack beams; they line up from block to block,
//!    so each row of blocks has continuous pipes across the whole site;
//! 2. headers, one per storey and header slot, rising from the rack outside the east wall at the
//!    crossing height, entering the building and running west under the corridor ceiling;
//! 3. pipes from the rack to the roof nozzle of each yard storage tank;
//! 4. branches from a header down to the top flange of every piece of equipment with a nozzle.
//!
//! The block's share of triangles is then met exactly ([`emit`]): the tessellation is chosen
//! (dropping branches or coarsening only when the share is too small), every straight stretch
//! gets extra rings in proportion to its length, and the last few triangles (fewer than one ring
//! of quads) become a blind end cap of exactly that many triangles.

use tw_core::Rng;

use super::plant::{stream, Layout, SitePlan, CROSSING_Z, PITCH, RACK_TOP, STOREY, TAG_RACK};
use super::shapes::{add, cross, dot, length, normalize, rotate, scale, sub, Emitter, Frame, V3};

/// One pipe: a polyline whose consecutive segments are perpendicular, and a radius.
#[derive(Clone, Debug)]
pub(crate) struct Run {
    pub points: Vec<V3>,
    pub r: f64,
}

/// Height of header `i` under the ceiling of storey `k`.
fn header_z(k: u32, i: u32) -> f64 {
    (k + 1) as f64 * STOREY - 0.75 - 0.35 * i as f64
}

/// The routes of block `lay`, in order: rack, headers, yard, branches (branches are dropped
/// first when the share is small).
pub(crate) fn runs(site: &SitePlan, lay: &Layout) -> (Vec<Run>, usize) {
    let sh = &lay.shape;
    let o = sh.origin;
    let mut out = Vec::new();
    let row = (sh.block / site.cols) as u64;
    for i in 0..site.pipe.rack {
        let r = Rng::with_stream(site.seed, stream(row, TAG_RACK, i as u64)).range_f64(0.08, 0.22);
        let y = o[1] + 2.2 + 0.65 * i as f64;
        let z = RACK_TOP + r;
        out.push(Run { points: vec![[o[0], y, z], [o[0] + PITCH, y, z]], r });
    }
    // Headers: risers ordered by how far they climb from the crossing height, so that no header
    // running west at its height meets a riser nearer the wall.
    let h = site.pipe.headers;
    let mut hs: Vec<(u32, u32)> = (0..lay.storeys).flat_map(|k| (0..h).map(move |i| (k, i))).collect();
    hs.sort_by(|a, b| {
        let da = (header_z(a.0, a.1) - CROSSING_Z).abs();
        let db = (header_z(b.0, b.1) - CROSSING_Z).abs();
        da.total_cmp(&db)
    });
    let east = sh.bx + sh.w + 1.0;
    let yc = sh.yc();
    for (q, &(k, i)) in hs.iter().enumerate() {
        let x = east + 0.3 * q as f64;
        let y = yc + 0.3 + 0.35 * i as f64;
        let z = header_z(k, i);
        out.push(Run {
            points: vec![[x, o[1] + 4.0, CROSSING_Z], [x, y, CROSSING_Z], [x, y, z], [sh.bx + 6.5, y, z]],
            r: 0.09,
        });
    }
    // Yard tanks: up from the rack east of the headers, west above every tank, down onto the roof.
    let high = lay.tanks.iter().map(|t| t.top[2]).fold(CROSSING_Z + 0.2, f64::max) + 0.8;
    for (j, t) in lay.tanks.iter().enumerate() {
        let x = east + 0.3 * hs.len() as f64 + 0.5 + 0.4 * j as f64;
        let z = high + 0.5 * j as f64;
        let [tx, ty, tz] = t.top;
        out.push(Run {
            points: vec![
                [x, o[1] + 4.0, CROSSING_Z],
                [x, ty, CROSSING_Z],
                [x, ty, z],
                [tx, ty, z],
                [tx, ty, tz],
            ],
            r: t.radius,
        });
    }
    let fixed = out.len();
    for n in &lay.nozzles {
        if n.bay == 0 {
            continue; // the headers stop short of the stair bay
        }
        let i = n.row % h;
        let (y, z) = (yc + 0.3 + 0.35 * i as f64, header_z(n.storey, i));
        let [x, ny, top] = n.nozzle.top;
        if z - top < 0.3 {
            continue;
        }
        out.push(Run { points: vec![[x, y, z], [x, ny, z], [x, ny, top]], r: n.nozzle.radius });
    }
    debug_assert!(out.iter().all(|r| r.points.windows(2).all(|w| length(sub(w[1], w[0])) > 2.2 * r.r)));
    debug_assert!(out
        .iter()
        .all(|r| r.points.iter().all(|p| p[0] > o[0] - 1e-9 && p[0] < o[0] + PITCH + 1e-9)));
    (out, fixed)
}

/// Emits runs into the current object (the piping network) using exactly `budget` triangles.
/// `fixed` runs come first and are kept as long as possible.
#[allow(clippy::too_many_arguments)]
pub(crate) fn emit(
    e: &mut Emitter<'_>,
    origin: V3,
    runs: &[Run],
    fixed: usize,
    budget: u64,
    sides: u32,
    elbow: u32,
) {
    // Prefix sums of segments and corners, so that the cost of the first n runs is O(1).
    let mut segs = vec![0u64; runs.len() + 1];
    let mut corners = vec![0u64; runs.len() + 1];
    for (k, r) in runs.iter().enumerate() {
        segs[k + 1] = segs[k] + (r.points.len() - 1) as u64;
        corners[k + 1] = corners[k] + (r.points.len() - 2) as u64;
    }
    let cost = |n: usize, s: u32, el: u32| 2 * s as u64 * (segs[n] + el as u64 * corners[n]);
    let (mut n, mut s, mut el) = (runs.len(), sides, elbow);
    while cost(n, s, el) > budget && n > fixed {
        n -= 1;
    }
    while cost(n, s, el) > budget && (el > 1 || s > 6) {
        if el > 1 {
            el -= 1;
        } else {
            s -= 1;
        }
    }
    while cost(n, s, el) > budget && n > 0 {
        n -= 1;
    }
    let base = cost(n, s, el);
    let ring = 2 * s as u64;
    let extra = if n > 0 { (budget - base) / ring } else { 0 };
    let rest = budget - base - extra * ring;
    let runs = &runs[..n];

    // Extra rings go to straight stretches in proportion to their length (whole millimetres, so
    // that the shares add up exactly).
    let mm = |r: &Run, i: usize| -> u64 {
        let (rb0, rb1) = (bend(r, i), bend(r, i + 1));
        let len = length(sub(r.points[i + 1], r.points[i])) - rb0 - rb1;
        ((len * 1000.0).round() as u64).max(1)
    };
    let total_mm: u64 = runs.iter().map(|r| (0..r.points.len() - 1).map(|i| mm(r, i)).sum::<u64>()).sum();
    let mut acc = 0u64;
    let mut given = 0u64;
    for r in runs {
        emit_run(e, r, s, el, |i| {
            acc += mm(r, i);
            let upto = (extra as u128 * acc as u128 / total_mm as u128) as u64;
            let k = upto - given;
            given = upto;
            k
        });
    }
    debug_assert_eq!(given, extra);
    if rest > 0 {
        // A blind cap on the last pipe's open end, or a lone plate when no pipe fits at all.
        let f = match runs.last() {
            Some(r) => {
                let p = &r.points;
                let d = normalize(sub(p[p.len() - 1], p[p.len() - 2]));
                Frame::axis(p[p.len() - 1], d)
            }
            None => Frame::at(add(origin, [1.0, 1.0, RACK_TOP])),
        };
        let r = runs.last().map_or(0.1, |r| r.r);
        // Set a little into the pipe: at its very end the cap would lie in the plane of the
        // nozzle flange's face there, and two coplanar faces show whichever is drawn first.
        let z = if runs.is_empty() { 0.0 } else { -0.05 * r };
        e.disc(&f, r, z, rest as u32, true);
    }
}

/// Bend radius at corner `i` of a run (zero at the ends).
fn bend(r: &Run, i: usize) -> f64 {
    let p = &r.points;
    if i == 0 || i + 1 >= p.len() {
        return 0.0;
    }
    let a = length(sub(p[i], p[i - 1]));
    let b = length(sub(p[i + 1], p[i]));
    (1.5 * r.r).min(0.45 * a.min(b))
}

/// Sweeps one run: straight stretches of `1 + extra(i)` bands, elbows of `el` bands, the ring
/// frame carried around each bend by rotation so the tube never twists.
fn emit_run(e: &mut Emitter<'_>, r: &Run, s: u32, el: u32, mut extra: impl FnMut(usize) -> u64) {
    let p = &r.points;
    let d0 = normalize(sub(p[1], p[0]));
    let f = Frame::axis(p[0], d0);
    let (mut u, mut v) = (f.x, f.y);
    e.strip_begin(s);
    e.strip_ring(p[0], u, v, r.r);
    for i in 0..p.len() - 1 {
        let d = normalize(sub(p[i + 1], p[i]));
        let a = add(p[i], scale(d, bend(r, i)));
        let rb = bend(r, i + 1);
        let b = sub(p[i + 1], scale(d, rb));
        let bands = 1 + extra(i);
        for j in 1..=bands {
            let t = j as f64 / bands as f64;
            e.strip_ring(add(a, scale(sub(b, a), t)), u, v, r.r);
        }
        if i + 2 < p.len() {
            let d1 = normalize(sub(p[i + 2], p[i + 1]));
            debug_assert!(dot(d, d1).abs() < 1e-9, "route corners must be square");
            let axis = cross(d, d1);
            let c = add(b, scale(d1, rb));
            let rel = sub(b, c);
            for j in 1..=el {
                let th = std::f64::consts::FRAC_PI_2 * j as f64 / el as f64;
                let (co, si) = (th.cos(), th.sin());
                e.strip_ring(
                    add(c, rotate(rel, axis, co, si)),
                    rotate(u, axis, co, si),
                    rotate(v, axis, co, si),
                    r.r,
                );
            }
            u = rotate(u, axis, 0.0, 1.0);
            v = rotate(v, axis, 0.0, 1.0);
        }
    }
}
