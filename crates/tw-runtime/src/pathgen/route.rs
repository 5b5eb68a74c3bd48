//! The walk's route: steps 5–7 of the [module documentation](super): the region to walk
//! through, waypoints by farthest-point sampling over graph distances joined by A* shortest
//! paths that keep to the middle of corridors, and the resampling and Gaussian smoothing that
//! turn the route into eye positions at walking speed.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use tw_core::Rng;

use super::voxels::{WalkGrid, NONE};
use super::{format_length, RegionKind};

#[derive(Copy, Clone, PartialEq)]
struct Open {
    f: f64,
    n: u32,
}
impl Eq for Open {}
impl Ord for Open {
    fn cmp(&self, o: &Self) -> Ordering {
        o.f.partial_cmp(&self.f).unwrap_or(Ordering::Equal).then_with(|| o.n.cmp(&self.n))
    }
}
impl PartialOrd for Open {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// A connected set of walkable spans, with each span's distance to the set's border.
pub(super) struct Region<'a> {
    g: &'a WalkGrid,
    /// Nodes of the region, and the local index of each grid node (NONE outside).
    pub(super) nodes: Vec<u32>,
    local: Vec<u32>,
    /// Hops to the region's border, per local node.
    clearance: Vec<u16>,
}

impl<'a> Region<'a> {
    pub(super) fn new(g: &'a WalkGrid, comp: &[u32], c: u32) -> Region<'a> {
        let nodes: Vec<u32> = (0..g.nodes.len() as u32).filter(|&n| comp[n as usize] == c).collect();
        let mut local = vec![NONE; g.nodes.len()];
        for (l, &n) in nodes.iter().enumerate() {
            local[n as usize] = l as u32;
        }
        let mut clearance = vec![u16::MAX; nodes.len()];
        let mut queue = std::collections::VecDeque::new();
        for (l, &n) in nodes.iter().enumerate() {
            if g.nodes[n as usize].nb.iter().any(|&m| m == NONE || local[m as usize] == NONE) {
                clearance[l] = 0;
                queue.push_back(l as u32);
            }
        }
        while let Some(l) = queue.pop_front() {
            let d = clearance[l as usize];
            for &m in &g.nodes[nodes[l as usize] as usize].nb[..4] {
                if m == NONE {
                    continue;
                }
                let lm = local[m as usize];
                if lm != NONE && clearance[lm as usize] == u16::MAX {
                    clearance[lm as usize] = d.saturating_add(1);
                    queue.push_back(lm);
                }
            }
        }
        Region { g, nodes, local, clearance }
    }

    fn neighbours(&self, l: u32) -> impl Iterator<Item = (u32, f64)> + '_ {
        let node = &self.g.nodes[self.nodes[l as usize] as usize];
        node.nb.iter().enumerate().filter_map(move |(d, &m)| {
            if m == NONE {
                return None;
            }
            let lm = self.local[m as usize];
            (lm != NONE).then_some((lm, if d < 4 { 1.0 } else { std::f64::consts::SQRT_2 }))
        })
    }

    /// Unweighted hop distances from `src` (multi-source, `dist` updated with the minimum).
    fn bfs_min(&self, src: u32, dist: &mut [u32]) {
        let mut seen = vec![u32::MAX; self.nodes.len()];
        let mut queue = std::collections::VecDeque::from([src]);
        seen[src as usize] = 0;
        while let Some(l) = queue.pop_front() {
            let d = seen[l as usize];
            dist[l as usize] = dist[l as usize].min(d);
            for (m, _) in self.neighbours(l) {
                if seen[m as usize] == u32::MAX {
                    seen[m as usize] = d + 1;
                    queue.push_back(m);
                }
            }
        }
    }

    /// A* from `a` to `b`; edge cost = length × (1 + 2 / (1 + clearance)²).
    fn shortest(&self, a: u32, b: u32) -> Option<Vec<u32>> {
        let pos = |l: u32| {
            let col = self.g.nodes[self.nodes[l as usize] as usize].col as usize;
            ((col % self.g.nx) as f64, (col / self.g.nx) as f64)
        };
        let (bx, by) = pos(b);
        let hfun = |l: u32| {
            let (x, y) = pos(l);
            ((x - bx).powi(2) + (y - by).powi(2)).sqrt()
        };
        let n = self.nodes.len();
        let mut gcost = vec![f64::INFINITY; n];
        let mut prev = vec![NONE; n];
        let mut heap = BinaryHeap::new();
        gcost[a as usize] = 0.0;
        heap.push(Open { f: hfun(a), n: a });
        while let Some(Open { f: _, n: l }) = heap.pop() {
            if l == b {
                let mut out = vec![b];
                let mut c = b;
                while c != a {
                    c = prev[c as usize];
                    out.push(c);
                }
                out.reverse();
                return Some(out);
            }
            let gl = gcost[l as usize];
            for (m, len) in self.neighbours(l) {
                let c = self.clearance[m as usize] as f64;
                let cost = gl + len * (1.0 + 2.0 / (1.0 + c).powi(2));
                if cost < gcost[m as usize] {
                    gcost[m as usize] = cost;
                    prev[m as usize] = l;
                    heap.push(Open { f: cost + hfun(m), n: m });
                }
            }
        }
        None
    }
}

/// A route through the region at least `length` long (when the region allows): eye positions
/// of the visited nodes, and the waypoints used.
pub(super) fn route(region: &Region, rng: &mut Rng, length: f64) -> (Vec<[f64; 3]>, usize) {
    let n = region.nodes.len();
    let start = rng.range_u32(0, n as u32);
    let mut dist = vec![u32::MAX; n];
    region.bfs_min(start, &mut dist);
    let mut points: Vec<[f64; 3]> = vec![region.g.eye_at(region.nodes[start as usize])];
    let mut total = 0.0;
    let mut cur = start;
    let mut waypoints = 1;
    for _ in 0..256 {
        if total >= length {
            break;
        }
        // Farthest point from all waypoints so far (ties: lowest index).
        let (next, d) =
            dist.iter().enumerate().fold((0usize, 0u32), |b, (i, &d)| if d > b.1 { (i, d) } else { b });
        if d == 0 {
            break;
        }
        let next = next as u32;
        region.bfs_min(next, &mut dist);
        let Some(leg) = region.shortest(cur, next) else { continue };
        for &l in &leg[1..] {
            let p = region.g.eye_at(region.nodes[l as usize]);
            total += dist3(*points.last().unwrap_or(&p), p);
            points.push(p);
        }
        cur = next;
        waypoints += 1;
    }
    (points, waypoints)
}

/// Step 5: the region to walk through, as (component of each node, the chosen component, its
/// kind): the largest covered region when it has a useful size (20 eye heights² of floor),
/// else the largest region in the open when it has 100; else why there is none.
pub(super) fn choose_region(g: &WalkGrid) -> Result<(Vec<u32>, usize, RegionKind), String> {
    let area = |n: usize| n as f64 * g.v * g.v;
    let min_interior = 20.0 * g.eye * g.eye;
    let min_outdoor = 100.0 * g.eye * g.eye;
    let (comp_c, sizes_c) = g.components(|n| n.covered);
    let best_c = (0..sizes_c.len()).max_by_key(|&c| (sizes_c[c], std::cmp::Reverse(c)));
    Ok(match best_c {
        Some(c) if area(sizes_c[c]) >= min_interior => (comp_c, c, RegionKind::Interior),
        _ => {
            let (comp_a, sizes_a) = g.components(|_| true);
            match (0..sizes_a.len()).max_by_key(|&c| (sizes_a[c], std::cmp::Reverse(c))) {
                Some(c) if area(sizes_a[c]) >= min_outdoor => (comp_a, c, RegionKind::Outdoor),
                Some(c) => {
                    return Err(format!(
                        "no walkable space: the largest walkable region has {} square units of \
                         floor, less than the {} (100 eye heights squared) a walk in the open needs",
                        format_length(area(sizes_a[c])),
                        format_length(min_outdoor)
                    ))
                }
                None => return Err("no walkable space".into()),
            }
        }
    })
}

/// Step 7's positions: the route `points` resampled densely and Gaussian-smoothed (position
/// and height) while the smoothed walk stays in walkable space, cut to `length` (or shorter
/// when the region is too small for it) and resampled at `frames` evenly spaced eyes.
pub(super) fn walk_eyes(g: &WalkGrid, points: &[[f64; 3]], length: f64, frames: usize) -> Vec<[f64; 3]> {
    // Dense resampling, then smoothing that stays in walkable space.
    let ds = g.v * 0.5;
    let dense_n = ((polyline_length(points) / ds).ceil() as usize + 1).clamp(2, 4_000_000);
    let dense = resample(points, dense_n);
    let mut sigma = 0.6 * g.eye / ds;
    let smooth = loop {
        let s = gaussian(&dense, sigma);
        if sigma < 0.5 || s.iter().all(|&p| g.eye_ok(p)) {
            break s;
        }
        sigma *= 0.5;
    };
    // Cut to the walk's length (or slow down when the region is too small for it).
    let total = polyline_length(&smooth);
    let used = total.min(length);
    let mut cut = Vec::new();
    let mut acc = 0.0;
    cut.push(smooth[0]);
    for w in smooth.windows(2) {
        let d = dist3(w[0], w[1]);
        if acc + d >= used {
            cut.push(lerp3(w[0], w[1], ((used - acc) / d.max(1e-300)).clamp(0.0, 1.0)));
            break;
        }
        acc += d;
        cut.push(w[1]);
    }
    resample(&cut, frames)
}

pub(super) fn dist3(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

pub(super) fn lerp3(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * t)
}

/// Resamples a polyline at `count` points evenly spaced by arc length.
pub(super) fn resample(points: &[[f64; 3]], count: usize) -> Vec<[f64; 3]> {
    if points.len() < 2 || count < 2 {
        return vec![points.first().copied().unwrap_or([0.0; 3]); count];
    }
    let mut cum = vec![0.0];
    for w in points.windows(2) {
        cum.push(cum.last().copied().unwrap_or(0.0) + dist3(w[0], w[1]));
    }
    let total = *cum.last().unwrap_or(&0.0);
    let mut out = Vec::with_capacity(count);
    let mut seg = 0;
    for i in 0..count {
        let s = total * i as f64 / (count - 1) as f64;
        while seg + 2 < cum.len() && cum[seg + 1] < s {
            seg += 1;
        }
        let len = cum[seg + 1] - cum[seg];
        let t = if len > 0.0 { ((s - cum[seg]) / len).clamp(0.0, 1.0) } else { 0.0 };
        out.push(lerp3(points[seg], points[seg + 1], t));
    }
    out
}

pub(super) fn polyline_length(points: &[[f64; 3]]) -> f64 {
    points.windows(2).map(|w| dist3(w[0], w[1])).sum()
}

/// Gaussian smoothing with standard deviation `sigma` samples (ends clamped).
pub(super) fn gaussian<const N: usize>(x: &[[f64; N]], sigma: f64) -> Vec<[f64; N]> {
    if sigma < 0.5 || x.len() < 3 {
        return x.to_vec();
    }
    let r = (3.0 * sigma).ceil() as i64;
    let w: Vec<f64> = (-r..=r).map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp()).collect();
    let n = x.len() as i64;
    (0..n)
        .map(|i| {
            let mut acc = [0.0; N];
            let mut ws = 0.0;
            for (k, &wk) in (-r..=r).zip(&w) {
                let p = x[(i + k).clamp(0, n - 1) as usize];
                for c in 0..N {
                    acc[c] += wk * p[c];
                }
                ws += wk;
            }
            acc.map(|a| a / ws)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resampling_is_even_and_keeps_the_ends() {
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 3.0, 0.0]];
        let r = resample(&p, 5);
        assert_eq!(r[0], p[0]);
        assert!(dist3(r[4], p[2]) < 1e-12);
        for w in r.windows(2) {
            assert!((dist3(w[0], w[1]) - 1.0).abs() < 0.3);
        }
    }

    #[test]
    fn gaussian_keeps_a_line_straight() {
        let p: Vec<[f64; 3]> = (0..50).map(|i| [i as f64, 2.0, 0.0]).collect();
        let s = gaussian(&p, 3.0);
        for (a, b) in p.iter().zip(&s).skip(10).take(30) {
            assert!(dist3(*a, *b) < 1e-9);
        }
    }
}
