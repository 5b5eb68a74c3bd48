//! The walk grid: steps 1–4 of the [module documentation](super): the coarse cut of the LOD
//! DAG, conservatively voxelized into bit columns (Recast's `rasterizeTri`: each triangle
//! clipped to every column it overlaps), the open spans of each column, the exterior flood fill
//! and the walkable spans eroded by the agent radius, with their links (Mononen, *Recast
//! Navigation*).

use std::sync::atomic::{AtomicU64, Ordering as AtomicOrdering};

use rayon::prelude::*;
use tw_store::Store;

use super::PathGenError;

/// Parameters of the voxel analysis, in scene units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WalkParams {
    pub eye_height: f64,
    pub voxel_size: f64,
    pub max_voxels: u64,
}

/// A free interval `[lo, hi)` of voxel levels in one column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Span {
    lo: u16,
    hi: u16,
}

/// The voxelized scene and its walkable spans (steps 1–4 of the module documentation).
#[derive(Debug)]
pub struct WalkGrid {
    /// Scene axes of grid i, j (horizontal) and k (up).
    axes: [usize; 3],
    /// Scene-space position of the grid's corner, per grid axis (i, j, k).
    lo: [f64; 3],
    pub(super) v: f64,
    pub(super) nx: usize,
    ny: usize,
    nz: usize,
    wpc: usize,
    bits: Vec<u64>,
    col_start: Vec<u32>,
    spans: Vec<Span>,
    exterior: Vec<bool>,
    /// Node index of each walkable span (u32::MAX when not walkable).
    node_of: Vec<u32>,
    pub(super) nodes: Vec<Node>,
    /// Eye height, head clearance, step and agent radius in voxels.
    body: u16,
    step: u16,
    radius: usize,
    pub(super) eye: f64,
    pub(super) windowed: bool,
    pub(super) pages_read: u64,
    pub(super) pages_failed: u64,
    pub(super) triangles: u64,
}

/// A walkable span and its links.
#[derive(Clone, Copy, Debug)]
pub(super) struct Node {
    pub(super) col: u32,
    span: u32,
    /// Something above within three eye heights (inside a building).
    pub(super) covered: bool,
    /// Neighbour nodes in the 8 directions (u32::MAX: none).
    pub(super) nb: [u32; 8],
}

/// No node (an unlinked direction, a span that is not walkable).
pub(super) const NONE: u32 = u32::MAX;
const DIRS: [(i32, i32); 8] = [(1, 0), (0, 1), (-1, 0), (0, -1), (1, 1), (-1, 1), (-1, -1), (1, -1)];

impl WalkGrid {
    /// Voxelizes `store` (the coarse cut, see the module documentation) and finds its walkable
    /// spans. `progress(done, total)` is called as pages are read.
    pub fn build(
        store: &Store,
        params: &WalkParams,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<WalkGrid, PathGenError> {
        let h = store.header();
        let eye = params.eye_height;
        if !(eye.is_finite() && eye > 0.0) {
            return Err(PathGenError::Options(format!("eye height must be > 0, got {eye}")));
        }
        let v = params.voxel_size;
        if !(v.is_finite() && v > 0.0) {
            return Err(PathGenError::Options(format!("voxel size must be > 0, got {v}")));
        }
        let up = h.up_axis.min(2) as usize;
        let axes = [(up + 1) % 3, (up + 2) % 3, up];
        let smin: Vec<f64> = (0..3).map(|a| h.bounds_min[a] - h.grid_origin[a]).collect();
        let smax: Vec<f64> = (0..3).map(|a| h.bounds_max[a] - h.grid_origin[a]).collect();
        let wlo = [smin[axes[0]], smin[axes[1]], smin[axes[2]]];
        let whi = [smax[axes[0]], smax[axes[1]], smax[axes[2]]];
        let mut g = WalkGrid::fit(axes, (wlo, whi), eye, v, params.max_voxels);
        g.voxelize(store, progress);
        g.find_spans();
        g.flood_exterior();
        g.find_walkable();
        Ok(g)
    }

    /// An empty grid over the scene window `(wlo, whi)` (scene space, per grid axis) with
    /// voxels of `v` or coarser: the window is shrunk horizontally around its centre (while
    /// wider than 40 eye heights), else the voxels grown by a quarter, until the grid holds at
    /// most `max_voxels` bits.
    fn fit(
        axes: [usize; 3],
        (mut wlo, mut whi): ([f64; 3], [f64; 3]),
        eye: f64,
        mut v: f64,
        max_voxels: u64,
    ) -> WalkGrid {
        let max_voxels = max_voxels.max(1 << 12);
        let mut windowed = false;
        let (nx, ny, nz, wpc, radius, body, step, pad) = loop {
            // Body: the eye height and 5 % above; step: a quarter of it; agent radius: 0.12 of it
            // (0.2 m for a 1.7 m eye: a camera, not a person, so doors of 1 m stay passable).
            let body = ((eye * 1.05) / v).ceil().max(3.0);
            let step = ((eye * 0.25) / v).floor().max(1.0);
            let radius = ((eye * 0.12) / v).round().max(1.0) as usize;
            let pad = radius + 2;
            let n = |a: usize| ((whi[a] - wlo[a]) / v).ceil().max(1.0) + 2.0 * pad as f64;
            let (fx, fy) = (n(0), n(1));
            // Grid sizes are f64 here so that huge scenes cannot overflow before the cap test.
            let fz = ((whi[2] - wlo[2]) / v).ceil().max(1.0) + body + 3.0;
            let wpc = (fz / 64.0).ceil();
            let total = fx * fy * wpc * 64.0;
            if fz < 65000.0 && body < 60000.0 && total <= max_voxels as f64 && fx * fy <= (1u64 << 26) as f64
            {
                break (
                    fx as usize,
                    fy as usize,
                    fz as usize,
                    wpc as usize,
                    radius,
                    body as u16,
                    step as u16,
                    pad,
                );
            }
            // Prefer a window of at least 40 eye heights at the fine voxel size.
            let wide = (0..2).any(|a| whi[a] - wlo[a] > 40.0 * eye);
            if wide && fz < 65000.0 {
                windowed = true;
                for a in 0..2 {
                    let c = 0.5 * (wlo[a] + whi[a]);
                    let half = 0.5 * (whi[a] - wlo[a]) * 0.85;
                    let half = half.max(20.0 * eye).min(0.5 * (whi[a] - wlo[a]));
                    wlo[a] = c - half;
                    whi[a] = c + half;
                }
            } else {
                v *= 1.25;
            }
        };
        let lo = [wlo[0] - pad as f64 * v, wlo[1] - pad as f64 * v, wlo[2] - v];
        WalkGrid {
            axes,
            lo,
            v,
            nx,
            ny,
            nz,
            wpc,
            bits: Vec::new(),
            col_start: Vec::new(),
            spans: Vec::new(),
            exterior: Vec::new(),
            node_of: Vec::new(),
            nodes: Vec::new(),
            body,
            step,
            radius,
            eye,
            windowed,
            pages_read: 0,
            pages_failed: 0,
            triangles: 0,
        }
    }

    pub fn voxel_size(&self) -> f64 {
        self.v
    }

    pub fn dims(&self) -> [usize; 3] {
        [self.nx, self.ny, self.nz]
    }

    pub fn walkable_spans(&self) -> usize {
        self.nodes.len()
    }

    /// Grid coordinates (continuous, in voxels) of a scene-space point.
    fn to_grid(&self, p: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|a| (p[self.axes[a]] - self.lo[a]) / self.v)
    }

    fn to_scene(&self, q: [f64; 3]) -> [f64; 3] {
        let mut p = [0.0; 3];
        for a in 0..3 {
            p[self.axes[a]] = self.lo[a] + q[a] * self.v;
        }
        p
    }

    fn cell(&self, p: [f64; 3]) -> Option<(usize, usize, usize)> {
        let q = self.to_grid(p);
        if q.iter().any(|x| !x.is_finite() || *x < 0.0) {
            return None;
        }
        let (i, j, k) = (q[0] as usize, q[1] as usize, q[2] as usize);
        (i < self.nx && j < self.ny && k < self.nz).then_some((i, j, k))
    }

    fn bit(&self, col: usize, k: usize) -> bool {
        self.bits[col * self.wpc + k / 64] >> (k % 64) & 1 == 1
    }

    /// Whether the voxel holding scene-space point `p` holds geometry. Points outside the
    /// voxelized window are reported as not occupied.
    pub fn is_occupied(&self, p: [f64; 3]) -> bool {
        self.cell(p).is_some_and(|(i, j, k)| self.bit(j * self.nx + i, k))
    }

    /// When `p` lies in exterior free space with a floor below, the scene-space height (along
    /// the up axis) of the top of that floor.
    pub fn floor_below(&self, p: [f64; 3]) -> Option<f64> {
        let (i, j, k) = self.cell(p)?;
        let col = j * self.nx + i;
        let s = self.span_at(col, k)?;
        let span = self.spans[s];
        (self.exterior[s] && span.lo >= 1).then(|| self.lo[2] + span.lo as f64 * self.v)
    }

    fn span_at(&self, col: usize, k: usize) -> Option<usize> {
        let r = self.col_start[col] as usize..self.col_start[col + 1] as usize;
        r.into_iter().find(|&s| (self.spans[s].lo as usize) <= k && k < self.spans[s].hi as usize)
    }

    fn voxelize(&mut self, store: &Store, progress: &mut dyn FnMut(u64, u64)) {
        let this: &WalkGrid = self;
        let t = (self.v * 0.5) as f32;
        let groups = store.groups();
        let step = store.header().grid_step;
        // Window in scene space, for the group sphere test.
        let glo = this.to_scene([0.0; 3]);
        let ghi = this.to_scene([this.nx as f64, this.ny as f64, this.nz as f64]);
        let wanted: Vec<bool> = groups
            .iter()
            .map(|g| {
                if g.error.is_nan() || g.error <= t {
                    return false; // replaced by coarser clusters
                }
                let mut d2 = 0.0;
                for a in 0..3 {
                    let c = g.sphere[a] as f64;
                    let d = (glo[a] - c).max(c - ghi[a]).max(0.0);
                    d2 += d * d;
                }
                d2 <= (g.sphere[3] as f64).powi(2) * 1.0001 + 1e-9
            })
            .collect();
        let mut pages: Vec<u32> =
            groups.iter().zip(&wanted).filter(|(_, &w)| w).map(|(g, _)| g.page).collect();
        pages.sort_unstable();
        pages.dedup();
        let atoms: Vec<AtomicU64> = (0..this.nx * this.ny * this.wpc).map(|_| AtomicU64::new(0)).collect();
        let total = pages.len() as u64;
        let mut done = 0u64;
        progress(0, total);
        let failed = AtomicU64::new(0);
        let tris = AtomicU64::new(0);
        for chunk in pages.chunks(32) {
            chunk.par_iter().for_each(|&p| match store.page(p) {
                Ok(clusters) => {
                    let mut n = 0u64;
                    let mut buf = Clip::default();
                    for c in &clusters {
                        if !wanted.get(c.group as usize).copied().unwrap_or(false) || c.self_error > t {
                            continue;
                        }
                        for tri in c.indices.chunks_exact(3) {
                            let mut q = [[0f64; 3]; 3];
                            let mut ok = true;
                            for (slot, &li) in q.iter_mut().zip(tri) {
                                let Some(pos) = c.positions.get(li as usize) else {
                                    ok = false;
                                    break;
                                };
                                let s = [0, 1, 2].map(|a| pos[a] as f64 * step);
                                *slot = this.to_grid(s);
                            }
                            if ok {
                                this.rasterize(&q, &atoms, &mut buf);
                                n += 1;
                            }
                        }
                    }
                    tris.fetch_add(n, AtomicOrdering::Relaxed);
                }
                Err(e) => {
                    tracing::warn!("path: page {p} skipped: {e}");
                    failed.fetch_add(1, AtomicOrdering::Relaxed);
                }
            });
            done += chunk.len() as u64;
            progress(done, total);
        }
        self.bits = atoms.into_iter().map(AtomicU64::into_inner).collect();
        self.pages_read = total;
        self.pages_failed = failed.into_inner();
        self.triangles = tris.into_inner();
    }

    /// Marks the voxels a triangle (in grid coordinates) overlaps: clipped per column, from the
    /// lowest to the highest point of the clipped polygon (Recast's `rasterizeTri`).
    fn rasterize(&self, q: &[[f64; 3]; 3], atoms: &[AtomicU64], buf: &mut Clip) {
        let (nx, ny, nz) = (self.nx as f64, self.ny as f64, self.nz as f64);
        let mn = |a: usize| q[0][a].min(q[1][a]).min(q[2][a]);
        let mx = |a: usize| q[0][a].max(q[1][a]).max(q[2][a]);
        if !(mn(0) < nx && mx(0) >= 0.0 && mn(1) < ny && mx(1) >= 0.0 && mn(2) < nz && mx(2) >= 0.0) {
            return;
        }
        if q.iter().flatten().any(|x| !x.is_finite()) {
            return;
        }
        let j0 = mn(1).max(0.0) as usize;
        let j1 = (mx(1).min(ny - 1.0)) as usize;
        buf.tri.clear();
        buf.tri.extend_from_slice(q);
        for j in j0..=j1 {
            clip_axis(&buf.tri, 1, j as f64, j as f64 + 1.0, &mut buf.row);
            if buf.row.is_empty() {
                continue;
            }
            let rmin = buf.row.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
            let rmax = buf.row.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
            let i0 = rmin.max(0.0) as usize;
            let i1 = rmax.min(nx - 1.0) as usize;
            for i in i0..=i1 {
                clip_axis(&buf.row, 0, i as f64, i as f64 + 1.0, &mut buf.cell);
                if buf.cell.is_empty() {
                    continue;
                }
                let zmin = buf.cell.iter().map(|p| p[2]).fold(f64::INFINITY, f64::min);
                let zmax = buf.cell.iter().map(|p| p[2]).fold(f64::NEG_INFINITY, f64::max);
                if zmax < 0.0 || zmin >= nz {
                    continue;
                }
                let k0 = zmin.max(0.0) as usize;
                let k1 = (zmax.min(nz - 1.0)) as usize;
                let base = (j * self.nx + i) * self.wpc;
                let mut k = k0;
                while k <= k1 {
                    let w = k / 64;
                    let end = (k1 + 1).min((w + 1) * 64);
                    let bits = end - k;
                    let mask = if bits == 64 { u64::MAX } else { ((1u64 << bits) - 1) << (k % 64) };
                    atoms[base + w].fetch_or(mask, AtomicOrdering::Relaxed);
                    k = end;
                }
            }
        }
    }

    /// The free intervals of every column.
    fn find_spans(&mut self) {
        let ncols = self.nx * self.ny;
        let mut col_start = Vec::with_capacity(ncols + 1);
        let mut spans = Vec::new();
        for col in 0..ncols {
            col_start.push(spans.len() as u32);
            let words = &self.bits[col * self.wpc..(col + 1) * self.wpc];
            let mut k = 0usize;
            let mut start: Option<usize> = None;
            while k < self.nz {
                let w = words[k / 64];
                if k.is_multiple_of(64) && (w == 0 || w == u64::MAX) && k + 64 <= self.nz {
                    if w == 0 {
                        start.get_or_insert(k);
                    } else if let Some(s) = start.take() {
                        spans.push(Span { lo: s as u16, hi: k as u16 });
                    }
                    k += 64;
                    continue;
                }
                if w >> (k % 64) & 1 == 1 {
                    if let Some(s) = start.take() {
                        spans.push(Span { lo: s as u16, hi: k as u16 });
                    }
                } else {
                    start.get_or_insert(k);
                }
                k += 1;
            }
            if let Some(s) = start {
                spans.push(Span { lo: s as u16, hi: self.nz as u16 });
            }
        }
        col_start.push(spans.len() as u32);
        self.col_start = col_start;
        self.spans = spans;
    }

    fn col_spans(&self, col: usize) -> std::ops::Range<usize> {
        self.col_start[col] as usize..self.col_start[col + 1] as usize
    }

    fn neighbour_col(&self, col: usize, d: (i32, i32)) -> Option<usize> {
        let (i, j) = ((col % self.nx) as i64 + d.0 as i64, (col / self.nx) as i64 + d.1 as i64);
        (i >= 0 && j >= 0 && (i as usize) < self.nx && (j as usize) < self.ny)
            .then(|| j as usize * self.nx + i as usize)
    }

    /// Free space connected to the grid's border (6-connected through overlapping spans).
    fn flood_exterior(&mut self) {
        let mut ext = vec![false; self.spans.len()];
        let mut stack = Vec::new();
        for col in 0..self.nx * self.ny {
            let (i, j) = (col % self.nx, col / self.nx);
            let border = i == 0 || j == 0 || i + 1 == self.nx || j + 1 == self.ny;
            for s in self.col_spans(col) {
                let sp = self.spans[s];
                if border || sp.lo == 0 || sp.hi as usize == self.nz {
                    ext[s] = true;
                    stack.push((col as u32, s as u32));
                }
            }
        }
        while let Some((col, s)) = stack.pop() {
            let sp = self.spans[s as usize];
            for d in &DIRS[..4] {
                let Some(nc) = self.neighbour_col(col as usize, *d) else { continue };
                for t in self.col_spans(nc) {
                    let o = self.spans[t];
                    if !ext[t] && o.lo.max(sp.lo) < o.hi.min(sp.hi) {
                        ext[t] = true;
                        stack.push((nc as u32, t as u32));
                    }
                }
            }
        }
        self.exterior = ext;
    }

    /// Whether column `col` has exterior free space over levels `[a, b)`.
    fn free_over(&self, col: usize, a: u16, b: u16) -> bool {
        self.col_spans(col).any(|s| self.exterior[s] && self.spans[s].lo <= a && self.spans[s].hi >= b)
    }

    fn find_walkable(&mut self) {
        let r = self.radius as i32;
        let mut node_of = vec![NONE; self.spans.len()];
        let mut nodes = Vec::new();
        // A ceiling within three eye heights (5.1 m: storeys, not the sky under a pipe rack).
        let cover_max = ((3.0 * self.eye) / self.v).ceil() as usize;
        for col in 0..self.nx * self.ny {
            'span: for s in self.col_spans(col) {
                let sp = self.spans[s];
                if !self.exterior[s] || sp.lo == 0 || sp.hi - sp.lo < self.body {
                    continue;
                }
                // Agent radius: above step height the body's cylinder is free around.
                let (a, b) = (sp.lo + self.step + 1, sp.lo + self.body);
                for dj in -r..=r {
                    for di in -r..=r {
                        if (di * di + dj * dj) as f64 > (r as f64 + 0.5).powi(2) || (di, dj) == (0, 0) {
                            continue;
                        }
                        match self.neighbour_col(col, (di, dj)) {
                            Some(nc) if a >= b || self.free_over(nc, a, b) => {}
                            _ => continue 'span,
                        }
                    }
                }
                let covered = (sp.hi as usize) < self.nz && ((sp.hi - sp.lo) as usize) <= cover_max;
                node_of[s] = nodes.len() as u32;
                nodes.push(Node { col: col as u32, span: s as u32, covered, nb: [NONE; 8] });
            }
        }
        // Links: floors within a step, free intervals overlapping by the body height.
        for node in nodes.iter_mut() {
            let (col, sp) = (node.col as usize, self.spans[node.span as usize]);
            let mut nb = [NONE; 8];
            for (d, dir) in DIRS.iter().enumerate() {
                let Some(nc) = self.neighbour_col(col, *dir) else { continue };
                for t in self.col_spans(nc) {
                    let o = self.spans[t];
                    if node_of[t] != NONE
                        && o.lo.abs_diff(sp.lo) <= self.step
                        && o.hi.min(sp.hi).saturating_sub(o.lo.max(sp.lo)) >= self.body
                    {
                        nb[d] = node_of[t];
                        break;
                    }
                }
            }
            // Diagonal moves need both orthogonal moves (no cutting corners).
            for d in 4..8 {
                let (a, b) = (d - 4, (d - 3) % 4);
                if nb[a] == NONE || nb[b] == NONE {
                    nb[d] = NONE;
                }
            }
            node.nb = nb;
        }
        self.node_of = node_of;
        self.nodes = nodes;
    }

    /// Scene-space eye position above node `n`.
    pub(super) fn eye_at(&self, n: u32) -> [f64; 3] {
        let node = self.nodes[n as usize];
        let col = node.col as usize;
        let sp = self.spans[node.span as usize];
        self.to_scene([
            (col % self.nx) as f64 + 0.5,
            (col / self.nx) as f64 + 0.5,
            sp.lo as f64 + self.eye / self.v,
        ])
    }

    /// Connected components among nodes passing `filter`: (component of each node, sizes).
    pub(super) fn components(&self, filter: impl Fn(&Node) -> bool) -> (Vec<u32>, Vec<usize>) {
        let mut comp = vec![NONE; self.nodes.len()];
        let mut sizes = Vec::new();
        let mut stack = Vec::new();
        for start in 0..self.nodes.len() {
            if comp[start] != NONE || !filter(&self.nodes[start]) {
                continue;
            }
            let c = sizes.len() as u32;
            let mut size = 0;
            comp[start] = c;
            stack.push(start as u32);
            while let Some(n) = stack.pop() {
                size += 1;
                for &m in &self.nodes[n as usize].nb {
                    if m != NONE && comp[m as usize] == NONE && filter(&self.nodes[m as usize]) {
                        comp[m as usize] = c;
                        stack.push(m);
                    }
                }
            }
            sizes.push(size);
        }
        (comp, sizes)
    }

    /// Checks that a walk eye lies in free exterior space with a floor about one eye height
    /// below (within a step and a voxel).
    pub(super) fn eye_ok(&self, p: [f64; 3]) -> bool {
        match self.floor_below(p) {
            Some(f) => {
                let hgt = p[self.axes[2]] - f;
                (hgt - self.eye).abs() <= (self.step as f64 + 1.0) * self.v
            }
            None => false,
        }
    }
}

#[derive(Default)]
struct Clip {
    tri: Vec<[f64; 3]>,
    row: Vec<[f64; 3]>,
    cell: Vec<[f64; 3]>,
}

/// Sutherland–Hodgman clipping of a convex polygon to `lo ≤ p[axis] ≤ hi` (inclusive, so
/// degenerate polygons such as vertical triangles seen from above are kept).
fn clip_axis(poly: &[[f64; 3]], axis: usize, lo: f64, hi: f64, out: &mut Vec<[f64; 3]>) {
    let mut tmp: Vec<[f64; 3]> = Vec::with_capacity(poly.len() + 2);
    clip_half(poly, axis, lo, true, &mut tmp);
    out.clear();
    clip_half(&tmp, axis, hi, false, out);
}

fn clip_half(poly: &[[f64; 3]], axis: usize, bound: f64, keep_above: bool, out: &mut Vec<[f64; 3]>) {
    out.clear();
    let inside = |p: &[f64; 3]| if keep_above { p[axis] >= bound } else { p[axis] <= bound };
    let n = poly.len();
    for idx in 0..n {
        let a = poly[idx];
        let b = poly[(idx + 1) % n];
        let (ia, ib) = (inside(&a), inside(&b));
        if ia {
            out.push(a);
        }
        if ia != ib {
            let t = (bound - a[axis]) / (b[axis] - a[axis]);
            let mut p = [0.0; 3];
            for c in 0..3 {
                p[c] = a[c] + (b[c] - a[c]) * t;
            }
            p[axis] = bound;
            out.push(p);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_keeps_the_part_inside() {
        let tri = [[0.0, 0.0, 0.0], [4.0, 0.0, 1.0], [0.0, 4.0, 2.0]];
        let mut out = Vec::new();
        clip_axis(&tri, 0, 1.0, 2.0, &mut out);
        assert!(out.iter().all(|p| (1.0..=2.0).contains(&p[0])));
        assert!(out.len() >= 3);
        clip_axis(&tri, 0, 5.0, 6.0, &mut out);
        assert!(out.is_empty());
        // A vertical triangle seen from above is a segment: still kept.
        let wall = [[0.0, 1.0, 0.0], [3.0, 1.0, 0.0], [0.0, 1.0, 3.0]];
        clip_axis(&wall, 1, 1.0, 2.0, &mut out);
        assert!(!out.is_empty());
    }
}
