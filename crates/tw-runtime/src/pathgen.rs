//! Automatic camera paths for `terawalk path`: an interior walk at eye height through the
//! walkable space of a store, a fly-over above it, joined smoothly, or a fly-around when the
//! model has no walkable space (a scanned statue). Plain data in ([`Store`], [`PathOptions`]),
//! a [`CameraPath`] out; pure CPU, deterministic for a seed.
//!
//! The walk follows Recast's navigation-mesh pipeline (Mononen, *Recast Navigation*: solid
//! heightfield → open spans → walkable filter → agent-radius erosion → regions), on voxels:
//!
//! 1. **Coarse geometry.** The object-space cut of the LOD DAG at `t` = half a voxel (the render
//!    rule of docs/FORMAT.md with an object-space threshold: a cluster is used when
//!    `self_error ≤ t < group.error`), so only coarse pages are decoded, one at a time.
//!    The voxel size is eye height / 8, grown (or the voxelized window shrunk around the scene's
//!    centre) until the grid fits [`PathOptions::max_voxels`]: work and memory are bounded
//!    whatever the store's size.
//! 2. **Conservative voxelization** (Recast's `rasterizeTri`): each triangle is clipped to every
//!    voxel column it overlaps and the column's voxels from the clipped polygon's lowest to
//!    highest point are marked. Columns are bitsets along the up axis.
//! 3. **Open spans**: the free intervals of each column. A flood fill from the grid's padded
//!    border over spans that overlap in 4-neighbour columns finds the *exterior* free space;
//!    free space enclosed by geometry (inside tanks, pipes, a closed statue) counts as solid.
//! 4. **Walkable**: an exterior span with a floor (an occupied voxel below) and room for the eye
//!    height plus 5 %; *eroded* by the agent radius (0.12 eye heights, at least a voxel: a
//!    camera, not a person, so 1 m doors stay open): above step height (a quarter of the eye
//!    height), the body's cylinder must be free in the neighbouring columns too. Walkable spans of 8-neighbour
//!    columns connect when their floors differ by at most a step and their free intervals
//!    overlap by the body height (diagonals also need both orthogonal moves), so stairs work.
//! 5. **Region**: the largest connected region of *covered* walkable spans (something above within
//!    three eye heights: inside buildings, not under a pipe rack); if there is none of useful size, the largest walkable
//!    region in the open; if neither, no walk (the fly-around fallback says why).
//! 6. **Route**: waypoints by farthest-point sampling over graph distances (seeded start),
//!    connected by A* shortest paths whose edge costs grow near the region's border (so walks
//!    keep to the middle of corridors), until the route is as long as the walk needs.
//! 7. **Smoothing**: the route is resampled, Gaussian-smoothed (position and height, so stairs
//!    become ramps), checked against the voxels (a smoothed point that leaves walkable space
//!    halves the smoothing), then resampled at constant walking speed. The look direction
//!    follows the path 1.5 s ahead, smoothed over half a second and limited to 90°/s (a
//!    reversal at a waypoint becomes a two-second turn), with a slow seeded pitch sway.
//!
//! The fly part is one orbit around the scene's centre at about the distance that frames its
//! bounding sphere, elevation 25–45° and distance varying slowly, never below the model's top;
//! after a walk, a Hermite curve rises from the walk's last camera (same velocity) to the orbit
//! (same velocity) over a third of the fly frames, turning the view to the centre by yaw and
//! pitch. (The rise goes through whatever is above the walk: the renderer's near plane cuts
//! the roof for a few frames.)
//!
//! Bounds: the grid holds at most [`PathOptions::max_voxels`] bits (32 MiB by default) plus
//! per-column spans; pages are decoded one at a time per thread; a scene too large for fine
//! voxels is voxelized in a window around its centre (the walk stays in it) and, failing
//! that, with coarser voxels, down to a third of the eye height, below which there is no walk.

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicU64, Ordering as AtomicOrdering};

use rayon::prelude::*;
use tw_core::Rng;
use tw_store::{Store, StoreError};

use crate::path::{CameraPath, PathFrame};

/// Which parts the path has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathPart {
    Walk,
    Fly,
    Both,
}

/// What to generate. Lengths are in scene (input) units; `None` picks a default from the
/// store's units (metres when it has none).
#[derive(Clone, Debug, PartialEq)]
pub struct PathOptions {
    /// Frames in all (≥ 2).
    pub frames: usize,
    /// Frame rate the path is made for (> 0).
    pub fps: f64,
    pub part: PathPart,
    /// Share of the frames that walk when `part` is [`PathPart::Both`] (0..1, exclusive).
    pub walk_share: f64,
    /// Eye height above the floor; default 1.7 m in the store's units.
    pub eye_height: Option<f64>,
    /// Walking speed, units per second; default 1.4 m/s in the store's units.
    pub speed: Option<f64>,
    /// Vertical field of view, degrees (1..=179).
    pub fovy_deg: f64,
    pub seed: u64,
    /// Voxel edge; default eye height / 8.
    pub voxel_size: Option<f64>,
    /// Most voxels in the occupancy grid (bounds its memory: one bit each).
    pub max_voxels: u64,
}

impl Default for PathOptions {
    fn default() -> Self {
        PathOptions {
            frames: 600,
            fps: 30.0,
            part: PathPart::Both,
            walk_share: 0.6,
            eye_height: None,
            speed: None,
            fovy_deg: 60.0,
            seed: 1,
            voxel_size: None,
            max_voxels: 1 << 28,
        }
    }
}

/// Errors of path generation: bad options (the store's errors are reported per page and do not
/// stop it).
#[derive(Debug, thiserror::Error)]
pub enum PathGenError {
    #[error("{0}")]
    Options(String),
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// The kind of region the walk went through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RegionKind {
    /// Covered walkable space (inside buildings).
    Interior,
    /// Walkable space in the open (no covered region of useful size).
    Outdoor,
}

/// What [`generate_path`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct PathReport {
    pub walk_frames: usize,
    pub fly_frames: usize,
    /// Length travelled by the eye, scene units.
    pub walk_length: f64,
    pub fly_length: f64,
    pub eye_height: f64,
    pub speed: f64,
    /// Why there is no walk although one was asked for (the path is a fly-around instead).
    pub fallback: Option<String>,
    /// The walk's region, when there is a walk.
    pub region: Option<RegionKind>,
    /// Walkable spans in the chosen region, and in all.
    pub region_spans: usize,
    pub walkable_spans: usize,
    pub voxel_size: f64,
    /// Grid dimensions (horizontal, horizontal, up).
    pub grid: [usize; 3],
    /// True when only a window around the centre was voxelized (the scene is too large).
    pub windowed: bool,
    pub pages_read: u64,
    pub pages_failed: u64,
    pub triangles_voxelized: u64,
    /// Waypoints the route visited.
    pub waypoints: usize,
}

/// The path and how it was made.
#[derive(Clone, Debug)]
pub struct GeneratedPath {
    pub path: CameraPath,
    pub report: PathReport,
}

/// Metres per unit for a store's units string (`""` is taken as metres).
pub fn metres_per_unit(units: &str) -> Option<f64> {
    Some(match units.trim().to_ascii_lowercase().as_str() {
        "" | "m" | "meter" | "metre" | "meters" | "metres" => 1.0,
        "mm" | "millimeter" | "millimetre" | "millimeters" | "millimetres" => 1e-3,
        "cm" | "centimeter" | "centimetre" | "centimeters" | "centimetres" => 1e-2,
        "dm" => 0.1,
        "km" => 1e3,
        "in" | "inch" | "inches" => 0.0254,
        "ft" | "foot" | "feet" => 0.3048,
        "yd" | "yard" | "yards" => 0.9144,
        _ => return None,
    })
}

/// A length for messages: three significant digits at any scale (`16.8`, `0.00212`, `1520`).
pub fn format_length(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let digits = (2 - x.abs().log10().floor() as i64).clamp(0, 15) as usize;
    format!("{x:.digits$}")
}

// ---------------------------------------------------------------------------------------------
// Voxel grid
// ---------------------------------------------------------------------------------------------

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
    v: f64,
    nx: usize,
    ny: usize,
    nz: usize,
    wpc: usize,
    bits: Vec<u64>,
    col_start: Vec<u32>,
    spans: Vec<Span>,
    exterior: Vec<bool>,
    /// Node index of each walkable span (u32::MAX when not walkable).
    node_of: Vec<u32>,
    nodes: Vec<Node>,
    /// Eye height, head clearance, step and agent radius in voxels.
    body: u16,
    step: u16,
    radius: usize,
    eye: f64,
    pub windowed: bool,
    pub pages_read: u64,
    pub pages_failed: u64,
    pub triangles: u64,
}

#[derive(Clone, Copy, Debug)]
struct Node {
    col: u32,
    span: u32,
    covered: bool,
    /// Neighbour nodes in the 8 directions (u32::MAX: none).
    nb: [u32; 8],
}

const NONE: u32 = u32::MAX;
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
        let mut v = params.voxel_size;
        if !(v.is_finite() && v > 0.0) {
            return Err(PathGenError::Options(format!("voxel size must be > 0, got {v}")));
        }
        let up = h.up_axis.min(2) as usize;
        let axes = [(up + 1) % 3, (up + 2) % 3, up];
        let smin: Vec<f64> = (0..3).map(|a| h.bounds_min[a] - h.grid_origin[a]).collect();
        let smax: Vec<f64> = (0..3).map(|a| h.bounds_max[a] - h.grid_origin[a]).collect();
        // Window (per grid axis) to voxelize, shrunk horizontally if the grid would be too big.
        let mut wlo = [smin[axes[0]], smin[axes[1]], smin[axes[2]]];
        let mut whi = [smax[axes[0]], smax[axes[1]], smax[axes[2]]];
        let max_voxels = params.max_voxels.max(1 << 12);
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
        let mut g = WalkGrid {
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
        };
        g.voxelize(store, progress);
        g.find_spans();
        g.flood_exterior();
        g.find_walkable();
        Ok(g)
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
    fn eye_at(&self, n: u32) -> [f64; 3] {
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
    fn components(&self, filter: impl Fn(&Node) -> bool) -> (Vec<u32>, Vec<usize>) {
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
    fn eye_ok(&self, p: [f64; 3]) -> bool {
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

// ---------------------------------------------------------------------------------------------
// Route
// ---------------------------------------------------------------------------------------------

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

struct Region<'a> {
    g: &'a WalkGrid,
    /// Nodes of the region, and the local index of each grid node (NONE outside).
    nodes: Vec<u32>,
    local: Vec<u32>,
    /// Hops to the region's border, per local node.
    clearance: Vec<u16>,
}

impl<'a> Region<'a> {
    fn new(g: &'a WalkGrid, comp: &[u32], c: u32) -> Region<'a> {
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
fn route(region: &Region, rng: &mut Rng, length: f64) -> (Vec<[f64; 3]>, usize) {
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

fn dist3(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn lerp3(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * t)
}

/// Resamples a polyline at `count` points evenly spaced by arc length.
fn resample(points: &[[f64; 3]], count: usize) -> Vec<[f64; 3]> {
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

fn polyline_length(points: &[[f64; 3]]) -> f64 {
    points.windows(2).map(|w| dist3(w[0], w[1])).sum()
}

/// Gaussian smoothing with standard deviation `sigma` samples (ends clamped).
fn gaussian<const N: usize>(x: &[[f64; N]], sigma: f64) -> Vec<[f64; N]> {
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

// ---------------------------------------------------------------------------------------------
// Cameras
// ---------------------------------------------------------------------------------------------

/// A frame looking from `eye` along `dir` (pitch limited to ±80° so `up` never lines up).
fn frame(
    eye: [f64; 3],
    dir: [f64; 3],
    up_axis: usize,
    origin: [f64; 3],
    fovy: f64,
    segment: &str,
) -> PathFrame {
    let h = [(up_axis + 1) % 3, (up_axis + 2) % 3];
    let horiz = (dir[h[0]].powi(2) + dir[h[1]].powi(2)).sqrt();
    let mut d = dir;
    let max_tan = 80f64.to_radians().tan();
    if horiz < 1e-9 {
        d[h[0]] = 1.0;
        d[h[1]] = 0.0;
        d[up_axis] = dir[up_axis].signum() * max_tan;
    } else if d[up_axis].abs() > horiz * max_tan {
        d[up_axis] = d[up_axis].signum() * horiz * max_tan;
    }
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-300);
    let mut up = [0.0; 3];
    up[up_axis] = 1.0;
    let dist = 10.0;
    PathFrame {
        eye: [0, 1, 2].map(|a| eye[a] + origin[a]),
        target: [0, 1, 2].map(|a| eye[a] + origin[a] + d[a] / len * dist),
        up,
        fovy,
        segment: segment.to_string(),
    }
}

/// Scene centre and bounding radius (scene space).
fn scene_sphere(store: &Store) -> ([f64; 3], f64) {
    let h = store.header();
    let lo: [f64; 3] = [0, 1, 2].map(|a| h.bounds_min[a] - h.grid_origin[a]);
    let hi: [f64; 3] = [0, 1, 2].map(|a| h.bounds_max[a] - h.grid_origin[a]);
    let c = lerp3(lo, hi, 0.5);
    let r = 0.5 * dist3(lo, hi);
    (c, r.max(h.grid_step * 16.0).max(1e-6))
}

/// Orbit state of the fly part.
struct Orbit {
    centre: [f64; 3],
    dist: f64,
    theta0: f64,
    sense: f64,
    phase: f64,
    up: usize,
    /// The eye never goes below this (the model's top plus a margin).
    min_height: f64,
}

impl Orbit {
    fn eye(&self, u: f64) -> [f64; 3] {
        let theta = self.theta0 + self.sense * std::f64::consts::TAU * u;
        let elev = (35.0 + 10.0 * (std::f64::consts::TAU * u + self.phase).sin()).to_radians();
        let d = self.dist * (0.9 + 0.1 * (std::f64::consts::TAU * 2.0 * u + self.phase).cos());
        let h = [(self.up + 1) % 3, (self.up + 2) % 3];
        let mut p = self.centre;
        p[h[0]] += d * elev.cos() * theta.cos();
        p[h[1]] += d * elev.cos() * theta.sin();
        p[self.up] = (p[self.up] + d * elev.sin()).max(self.min_height);
        p
    }
}

/// Generates the path (see the module documentation). `progress(stage, done, total)` reports
/// the slow step (reading pages: stage "voxelize").
pub fn generate_path(
    store: &Store,
    options: &PathOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<GeneratedPath, PathGenError> {
    let bad = |m: String| Err(PathGenError::Options(m));
    if options.frames < 2 || options.frames > crate::path::MAX_FRAMES {
        return bad(format!("frames must be 2..={}, got {}", crate::path::MAX_FRAMES, options.frames));
    }
    if !(options.fps.is_finite() && options.fps > 0.0 && options.fps <= 1000.0) {
        return bad(format!("fps must be in (0, 1000], got {}", options.fps));
    }
    if !(options.walk_share > 0.0 && options.walk_share < 1.0) {
        return bad(format!(
            "the walk share must be between 0 and 1 (exclusive), got {}",
            options.walk_share
        ));
    }
    if !(1.0..=179.0).contains(&options.fovy_deg) {
        return bad(format!("field of view must be 1..=179 degrees, got {}", options.fovy_deg));
    }
    let h = store.header();
    let up = h.up_axis.min(2) as usize;
    let unit = metres_per_unit(store.units());
    let scale = 1.0 / unit.unwrap_or(1.0);
    let eye = options.eye_height.unwrap_or(1.7 * scale);
    if !(eye.is_finite() && eye > 0.0) {
        return bad(format!("eye height must be a positive number, got {eye}"));
    }
    let speed = options.speed.unwrap_or(1.4 * scale * eye / (1.7 * scale));
    if !(speed.is_finite() && speed > 0.0) {
        return bad(format!("speed must be a positive number, got {speed}"));
    }
    if let Some(v) = options.voxel_size {
        if !(v.is_finite() && v > 0.0 && v <= eye / 2.0) {
            return bad(format!(
                "voxel size must be > 0 and at most half the eye height ({}), got {v}",
                eye / 2.0
            ));
        }
    }
    let (walk_frames_wanted, _) = match options.part {
        PathPart::Walk => (options.frames, 0),
        PathPart::Fly => (0, options.frames),
        PathPart::Both => {
            let w =
                ((options.frames as f64 * options.walk_share).round() as usize).clamp(1, options.frames - 1);
            (w, options.frames - w)
        }
    };
    let origin = h.grid_origin;
    let fovy = options.fovy_deg;
    let mut rng = Rng::with_stream(options.seed, 0x7061_7468);
    let mut report = PathReport {
        walk_frames: 0,
        fly_frames: 0,
        walk_length: 0.0,
        fly_length: 0.0,
        eye_height: eye,
        speed,
        fallback: None,
        region: None,
        region_spans: 0,
        walkable_spans: 0,
        voxel_size: 0.0,
        grid: [0; 3],
        windowed: false,
        pages_read: 0,
        pages_failed: 0,
        triangles_voxelized: 0,
        waypoints: 0,
    };

    // The walk.
    let mut walk: Vec<PathFrame> = Vec::new();
    let mut walk_end: Option<([f64; 3], [f64; 3])> = None; // last eye, velocity per frame
    if walk_frames_wanted > 0 {
        let horiz = [0, 1, 2]
            .into_iter()
            .filter(|&a| a != up)
            .map(|a| h.bounds_max[a] - h.bounds_min[a])
            .fold(0.0, f64::max);
        if horiz < 4.0 * eye {
            report.fallback = Some(format!(
                "the scene is {} {u} across, less than 4 eye heights ({eye} {u}; units {units:?}): \
                 nothing to walk through (give --eye-height in the model's units?)",
                format_length(horiz),
                u = if store.units().is_empty() { "units" } else { store.units() },
                units = store.units(),
            ));
        } else {
            let params = WalkParams {
                eye_height: eye,
                voxel_size: options.voxel_size.unwrap_or(eye / 8.0),
                max_voxels: options.max_voxels,
            };
            let g = WalkGrid::build(store, &params, &mut |d, t| progress("voxelize", d, t))?;
            tracing::debug!("path: voxels {:.3}, grid {:?}, {} walkable spans", g.v, g.dims(), g.nodes.len());
            report.voxel_size = g.v;
            report.grid = g.dims();
            report.windowed = g.windowed;
            report.pages_read = g.pages_read;
            report.pages_failed = g.pages_failed;
            report.triangles_voxelized = g.triangles;
            report.walkable_spans = g.nodes.len();
            match walk_path(
                &g,
                &mut rng,
                walk_frames_wanted,
                options.fps,
                speed,
                up,
                origin,
                fovy,
                &mut report,
            ) {
                Ok((frames, end)) => {
                    walk = frames;
                    walk_end = Some(end);
                }
                Err(why) => report.fallback = Some(why),
            }
        }
    }

    // The fly part: the rest of the frames (all of them after a fallback).
    let fly_count = options.frames - walk.len();
    let (centre, radius) = scene_sphere(store);
    let half_fov = (fovy.min(100.0) / 2.0).to_radians();
    let mut orbit = Orbit {
        centre,
        // The bounding sphere fits the view at `radius / sin(fov / 2)`; sites are flatter than
        // their sphere, so come a little closer.
        dist: radius / half_fov.sin() * 0.8,
        theta0: rng.range_f64(0.0, std::f64::consts::TAU),
        sense: 1.0,
        phase: rng.range_f64(0.0, std::f64::consts::TAU),
        up,
        min_height: h.bounds_max[up] - h.grid_origin[up] + 0.1 * radius,
    };
    let mut fly: Vec<PathFrame> = Vec::with_capacity(fly_count);
    if fly_count > 0 {
        let hz = [(up + 1) % 3, (up + 2) % 3];
        let transition = if walk_end.is_some() { (fly_count / 3).max(1).min(fly_count) } else { 0 };
        let orbit_frames = fly_count - transition;
        if let Some((we, wv)) = walk_end {
            // Start the orbit above the walk's end, turning the way the walk was heading.
            orbit.theta0 = (we[hz[1]] - centre[hz[1]]).atan2(we[hz[0]] - centre[hz[0]]);
            let rx = we[hz[0]] - centre[hz[0]];
            let ry = we[hz[1]] - centre[hz[1]];
            let cross = rx * wv[hz[1]] - ry * wv[hz[0]];
            orbit.sense = if cross < 0.0 { -1.0 } else { 1.0 };
        }
        let du = 1.0 / (orbit_frames.max(2) - 1) as f64;
        let orbit_at = |i: usize| orbit.eye(i as f64 * du);
        if let Some((we, wv)) = walk_end {
            let o0 = orbit_at(0);
            let o1 = orbit_at(1);
            let n = transition as f64 + 1.0;
            // Hermite from the walk's end to the orbit's start, velocities matched per frame.
            let t0 = wv.map(|c| c * n);
            let t1 = [0, 1, 2].map(|c| (o1[c] - o0[c]) * n);
            let wdir =
                walk.last().map(|f| [0, 1, 2].map(|c| f.target[c] - f.eye[c])).unwrap_or([1.0, 0.0, 0.0]);
            for k in 1..=transition {
                let u = k as f64 / n;
                let (u2, u3) = (u * u, u * u * u);
                let (h00, h10, h01, h11) =
                    (2.0 * u3 - 3.0 * u2 + 1.0, u3 - 2.0 * u2 + u, -2.0 * u3 + 3.0 * u2, u3 - u2);
                let p = [0, 1, 2].map(|c| h00 * we[c] + h10 * t0[c] + h01 * o0[c] + h11 * t1[c]);
                // Turn the view from the walk's to the centre by yaw and pitch (the shorter way
                // round), with a smoothstep: no fast swing even when the two are opposite.
                let s = u2 * (3.0 - 2.0 * u);
                let (y0, p0) = yaw_pitch(wdir, up);
                let (y1, p1) = yaw_pitch(sub(centre, p), up);
                let mut dy = y1 - y0;
                while dy > std::f64::consts::PI {
                    dy -= std::f64::consts::TAU;
                }
                while dy < -std::f64::consts::PI {
                    dy += std::f64::consts::TAU;
                }
                let d = from_yaw_pitch(y0 + dy * s, p0 + (p1 - p0) * s, up);
                fly.push(frame(p, d, up, origin, fovy, "fly"));
            }
        }
        for i in 0..orbit_frames {
            let p = orbit_at(i);
            fly.push(frame(p, sub(centre, p), up, origin, fovy, "fly"));
        }
    }
    report.fly_frames = fly.len();
    report.fly_length = fly.windows(2).map(|w| dist3(w[0].eye, w[1].eye)).sum::<f64>()
        + match (walk.last(), fly.first()) {
            (Some(a), Some(b)) => dist3(a.eye, b.eye),
            _ => 0.0,
        };
    report.walk_frames = walk.len();
    walk.extend(fly);
    Ok(GeneratedPath { path: CameraPath::new(options.fps, walk), report })
}

/// Yaw (about the up axis) and pitch of a direction.
fn yaw_pitch(d: [f64; 3], up: usize) -> (f64, f64) {
    let h = [(up + 1) % 3, (up + 2) % 3];
    (d[h[1]].atan2(d[h[0]]), d[up].atan2(d[h[0]].hypot(d[h[1]])))
}

fn from_yaw_pitch(yaw: f64, pitch: f64, up: usize) -> [f64; 3] {
    let h = [(up + 1) % 3, (up + 2) % 3];
    let mut d = [0.0; 3];
    d[h[0]] = yaw.cos() * pitch.cos();
    d[h[1]] = yaw.sin() * pitch.cos();
    d[up] = pitch.sin();
    d
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// The last eye of a walk and its velocity per frame.
type WalkEnd = ([f64; 3], [f64; 3]);

/// The walk frames, or why there is none. Also returns the last eye and its per-frame velocity.
#[allow(clippy::too_many_arguments)]
fn walk_path(
    g: &WalkGrid,
    rng: &mut Rng,
    frames: usize,
    fps: f64,
    speed: f64,
    up: usize,
    origin: [f64; 3],
    fovy: f64,
    report: &mut PathReport,
) -> Result<(Vec<PathFrame>, WalkEnd), String> {
    if g.v > g.eye / 3.0 {
        return Err(format!(
            "the voxel cap leaves voxels of {}, too coarse for an eye height of {} (raise --max-voxels)",
            format_length(g.v),
            g.eye
        ));
    }
    if g.nodes.is_empty() {
        return Err("no walkable space: no floor with room for the eye height was found".into());
    }
    // Useful size: 20 eye heights² of floor for an interior, 100 in the open.
    let area = |n: usize| n as f64 * g.v * g.v;
    let min_interior = 20.0 * g.eye * g.eye;
    let min_outdoor = 100.0 * g.eye * g.eye;
    let (comp_c, sizes_c) = g.components(|n| n.covered);
    let best_c = (0..sizes_c.len()).max_by_key(|&c| (sizes_c[c], std::cmp::Reverse(c)));
    let (comp, c, kind) = match best_c {
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
    };
    let region = Region::new(g, &comp, c as u32);
    report.region = Some(kind);
    report.region_spans = region.nodes.len();
    let step = speed / fps;
    let length = step * (frames.max(2) - 1) as f64;
    let (points, waypoints) = route(&region, rng, length);
    report.waypoints = waypoints;
    if points.len() < 2 || polyline_length(&points) <= 0.0 {
        return Err("no walkable space: the walkable region is a single spot".into());
    }
    // Dense resampling, then smoothing that stays in walkable space.
    let ds = g.v * 0.5;
    let dense_n = ((polyline_length(&points) / ds).ceil() as usize + 1).clamp(2, 4_000_000);
    let dense = resample(&points, dense_n);
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
    let eyes = resample(&cut, frames);
    report.walk_length = polyline_length(&eyes);
    // Headings: a look-ahead of about a second and a half of walking, smoothed over half a second.
    let hz = [(up + 1) % 3, (up + 2) % 3];
    let ahead = ((1.5 * fps) as usize).max(1);
    let mut heading = Vec::with_capacity(frames);
    let mut last = 0.0f64;
    for i in 0..frames {
        let j = (i + ahead).min(frames - 1);
        let d = sub(eyes[j], eyes[i]);
        let a = if d[hz[0]].hypot(d[hz[1]]) > 1e-9 * g.v { d[hz[1]].atan2(d[hz[0]]) } else { last };
        // Unwrap.
        let mut a = a;
        if i > 0 {
            while a - last > std::f64::consts::PI {
                a -= std::f64::consts::TAU;
            }
            while a - last < -std::f64::consts::PI {
                a += std::f64::consts::TAU;
            }
        } else if d[hz[0]].hypot(d[hz[1]]) <= 1e-9 * g.v {
            a = 0.0;
        }
        heading.push([a]);
        last = a;
    }
    // Smoothed, then limited to 90°/s (a reversal at a waypoint becomes a two-second turn),
    // then smoothed a little again so the limiter leaves no kinks.
    let heading = gaussian(&heading, fps * 0.5);
    let max_turn = 90f64.to_radians() / fps;
    let mut limited = Vec::with_capacity(frames);
    for (i, a) in heading.iter().enumerate() {
        let a = if i == 0 {
            a[0]
        } else {
            let prev: f64 = limited[i - 1];
            prev + (a[0] - prev).clamp(-max_turn, max_turn)
        };
        limited.push(a);
    }
    let heading: Vec<[f64; 1]> = gaussian(&limited.iter().map(|&a| [a]).collect::<Vec<_>>(), fps * 0.15);
    let phase = rng.range_f64(0.0, std::f64::consts::TAU);
    let mut out = Vec::with_capacity(frames);
    for i in 0..frames {
        let a = heading[i][0];
        let t = i as f64 / fps;
        let pitch = (-4.0 + 3.0 * (std::f64::consts::TAU * t / 7.0 + phase).sin()).to_radians();
        out.push(frame(eyes[i], from_yaw_pitch(a, pitch, up), up, origin, fovy, "walk"));
    }
    let n = eyes.len();
    let vel = if n >= 2 { sub(eyes[n - 1], eyes[n - 2]) } else { [0.0; 3] };
    Ok((out, (eyes[n - 1], vel)))
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

    #[test]
    fn lengths_have_three_significant_digits() {
        assert_eq!(format_length(16.84), "16.8");
        assert_eq!(format_length(0.0021234), "0.00212");
        assert_eq!(format_length(1516.3), "1516");
        assert_eq!(format_length(0.0), "0");
    }

    #[test]
    fn units_scale_the_defaults() {
        assert_eq!(metres_per_unit(""), Some(1.0));
        assert_eq!(metres_per_unit("mm"), Some(1e-3));
        assert_eq!(metres_per_unit(" M "), Some(1.0));
        assert_eq!(metres_per_unit("parsec"), None);
    }
}
