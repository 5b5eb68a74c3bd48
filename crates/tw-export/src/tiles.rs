//! The store's LOD hierarchy as an OGC 3D Tiles 1.1 tileset: `tileset.json` and one GLB per
//! tile under `tiles/`, refinement REPLACE.
//!
//! # Tiles
//!
//! A tile is a pair (skeleton node `N`, object-space error `ε`); its content is the cut of the
//! cluster DAG below `N` at `ε` ([`crate::cut::object_space_cut`]: complete and crack-free for
//! any `ε`), and its `geometricError` is that cut's own error `e`, the largest `self_error` of
//! its clusters (errors are measured from full detail, so this is what is lost by drawing the
//! tile instead of its children). The root tile is (root node, +∞): the coarsest clusters.
//! A tile with `e > 0` is refined at the largest `ε' = e / 2^k` (k ≥ 1) whose cut has at least
//! [`GROWTH`] times the tile's triangles, or is full detail (`refine_threshold`):
//!
//! - into (`N`, `ε'`) — the same region, finer — while `N` still has clusters of its own in
//!   that cut (its HLOD levels), or when `N` is a cell, or when its subtree holds at most
//!   [`TilesOptions::tile_triangles`] full-detail triangles;
//! - otherwise into (`C`, `ε'`) for each child `C` of `N` whose cut is not empty: `N`'s own
//!   clusters are all replaced at `ε'`, so the children's cuts together are `N`'s.
//!
//! A tile with `e = 0` is full detail: a leaf. Each refinement at least halves the error, so
//! errors strictly decrease from the root to the leaves; and each at least doubles the
//! triangles, so a chain of tiles over one region is as long as the number of LOD levels at
//! most (usually less: levels whose errors are close are skipped), and all tiles over one region
//! together hold at most about twice its full-detail triangles. (Halving the error alone made
//! the 30k plant a chain of 14 tiles holding 6 times its triangles, most of them near full
//! detail.)
//!
//! **Tile count.** Small subtrees are merged: a node whose subtree holds at most
//! `tile_triangles` full-detail triangles is never split into its children, so every tile's
//! content is either at most about that many triangles at full detail or one node's HLOD level,
//! and the tile count is about (nodes above that size + their merged subtrees) × LOD levels
//! rather than nodes × levels.
//!
//! # Frames and units
//!
//! Content is the same y-up GLB as [`crate::glb`], positions in input coordinates, with the
//! root node also scaling to metres when the store records known units (`geometricError` is in
//! metres in 3D Tiles; a tile `transform` with a scale would also scale the error in some
//! clients, so the scale stays in the content). A 3D Tiles client turns glTF content from y-up
//! to z-up, so the bounding volumes (boxes, from the nodes' grid boxes, which contain their
//! subtrees' vertices and their children's boxes) are given in that z-up frame
//! ([`crate::frame::to_tileset`]): the store's up axis is the tileset's +Z and the model stands
//! upright. Without units the scene's units are taken as metres.

use std::io::Write;
use std::path::{Path, PathBuf};

use serde_json::{json, Value};
use tw_io::write::{AtomicFile, GlbWriter, SceneWriter};
use tw_runtime::PageCache;
use tw_store::Store;

use crate::cut::{object_space_cut, Cut, Hierarchy};
use crate::emit::emit_clusters;
use crate::error::ExportError;
use crate::frame::{box_to_tileset, grid_to_input};

/// A child tile holds at least this many times the triangles of its parent (over the same
/// region) unless it is full detail (module documentation).
pub const GROWTH: f64 = 2.0;

/// How the tileset is cut into tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TilesOptions {
    /// Subtrees with at most this many full-detail triangles are not split spatially (module
    /// documentation, "Tile count").
    pub tile_triangles: u64,
}

impl Default for TilesOptions {
    fn default() -> Self {
        TilesOptions { tile_triangles: 64_000 }
    }
}

/// What [`export_tiles`] wrote.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TilesSummary {
    pub tiles: usize,
    /// Triangles over all tiles' content (each level counted).
    pub triangles: u64,
    /// Most triangles in one tile.
    pub max_tile_triangles: u64,
    /// Tiles from the root to the deepest leaf.
    pub depth: usize,
    /// Bytes of all files written.
    pub bytes: u64,
    /// The root tile's geometric error (metres).
    pub root_error: f64,
}

/// One tile, as `tileset.json` describes it.
struct Tile {
    uri: String,
    /// Geometric error in metres.
    error: f64,
    /// Bounding box in the tileset frame.
    min: [f64; 3],
    max: [f64; 3],
    children: Vec<usize>,
    depth: usize,
}

/// A tile to make: node, error threshold, parent tile.
struct Pending {
    parent: Option<usize>,
    node: u32,
    eps: f32,
}

/// Writes the tileset of `store` into the directory `dir` (created if missing): `tileset.json`
/// and `tiles/<n>.glb`. Pages come through `cache`.
pub fn export_tiles(
    store: &Store,
    cache: &PageCache,
    dir: &Path,
    options: &TilesOptions,
) -> Result<TilesSummary, ExportError> {
    let tiles_dir = dir.join("tiles");
    std::fs::create_dir_all(&tiles_dir)
        .map_err(|e| ExportError::Io { path: tiles_dir.clone(), source: e })?;
    let hierarchy = Hierarchy::new(store);
    let scale = store.metres_per_unit().unwrap_or(1.0);
    let mut tiles: Vec<Tile> = Vec::new();
    let mut summary = TilesSummary::default();
    let mut stack = vec![Pending { parent: None, node: 0, eps: f32::INFINITY }];
    while let Some(p) = stack.pop() {
        let cut = object_space_cut(store, cache, &hierarchy, p.node, p.eps, None)?;
        if p.parent.is_some() && !cut.own && splits(store, &hierarchy, p.node, options) {
            // The node's own levels are all replaced here: its children's cuts are its cut.
            let n = &store.nodes()[p.node as usize];
            for c in (n.first_child..n.first_child + n.child_count).rev() {
                stack.push(Pending { parent: p.parent, node: c, eps: p.eps });
            }
            continue;
        }
        if p.parent.is_some() && cut.clusters.is_empty() {
            continue;
        }
        let id = tiles.len();
        let uri = format!("tiles/{id}.glb");
        summary.bytes += write_content(store, cache, &cut, scale, &dir.join(&uri))?;
        summary.triangles += cut.triangles;
        summary.max_tile_triangles = summary.max_tile_triangles.max(cut.triangles);
        let (min, max) = node_box(store, p.node, scale);
        let depth = p.parent.map_or(1, |q| tiles[q].depth + 1);
        summary.depth = summary.depth.max(depth);
        tiles.push(Tile { uri, error: cut.error as f64 * scale, min, max, children: Vec::new(), depth });
        if let Some(q) = p.parent {
            tiles[q].children.push(id);
        }
        if cut.error > 0.0 && !cut.clusters.is_empty() {
            let eps = refine_threshold(store, cache, &hierarchy, p.node, &cut)?;
            stack.push(Pending { parent: Some(id), node: p.node, eps });
        }
    }
    summary.tiles = tiles.len();
    summary.root_error = tiles.first().map_or(0.0, |t| t.error);
    summary.bytes += write_tileset(&tiles, &dir.join("tileset.json"))?;
    Ok(summary)
}

/// The threshold of the tiles that refine `cut` (the cut of `node` at some threshold, with error
/// `e > 0`): the largest `e / 2^k`, k ≥ 1, whose cut has at least [`GROWTH`] times the
/// triangles or is full detail. Each try at least halves the error, so this ends (a cut's error
/// is below its threshold, and full detail has error 0).
fn refine_threshold(
    store: &Store,
    cache: &PageCache,
    hierarchy: &Hierarchy,
    node: u32,
    cut: &Cut,
) -> Result<f32, ExportError> {
    let mut eps = cut.error / 2.0;
    loop {
        let finer = object_space_cut(store, cache, hierarchy, node, eps, None)?;
        if finer.error <= 0.0 || finer.triangles as f64 >= GROWTH * cut.triangles as f64 {
            return Ok(eps);
        }
        eps = finer.error / 2.0;
    }
}

/// Whether a tile of `node` is refined into its children's tiles rather than a finer tile of
/// the same node (once the node's own clusters are all replaced).
fn splits(store: &Store, hierarchy: &Hierarchy, node: u32, options: &TilesOptions) -> bool {
    let n = &store.nodes()[node as usize];
    n.child_count > 0 && hierarchy.subtree_triangles[node as usize] > options.tile_triangles
}

/// The node's grid box in the tileset frame.
fn node_box(store: &Store, node: u32, scale: f64) -> ([f64; 3], [f64; 3]) {
    let n = &store.nodes()[node as usize];
    let h = store.header();
    box_to_tileset(h.up_axis, scale, grid_to_input(h, n.min), grid_to_input(h, n.max))
}

/// Writes one tile's content; returns its size in bytes.
fn write_content(
    store: &Store,
    cache: &PageCache,
    cut: &Cut,
    scale: f64,
    path: &Path,
) -> Result<u64, ExportError> {
    let mut writer = GlbWriter::create(path)?;
    writer.set_up_axis(store.header().up_axis)?;
    writer.set_scale(scale)?;
    let mut writer: Box<dyn SceneWriter> = Box::new(writer);
    emit_clusters(store, cache, &cut.clusters, None, &mut *writer)?;
    Ok(writer.finish()?.bytes)
}

/// The JSON of tile `id` and its subtree.
fn tile_json(tiles: &[Tile], id: usize) -> Value {
    let t = &tiles[id];
    let c: Vec<f64> = (0..3).map(|a| (t.min[a] + t.max[a]) / 2.0).collect();
    let h: Vec<f64> = (0..3).map(|a| (t.max[a] - t.min[a]) / 2.0).collect();
    let mut v = json!({
        "boundingVolume": { "box": [c[0], c[1], c[2], h[0], 0, 0, 0, h[1], 0, 0, 0, h[2]] },
        "geometricError": t.error,
        "refine": "REPLACE",
        "content": { "uri": t.uri },
    });
    if !t.children.is_empty() {
        v["children"] = Value::Array(t.children.iter().map(|&c| tile_json(tiles, c)).collect());
    }
    v
}

/// Writes `tileset.json` atomically; returns its size. The tileset's own geometric error (what
/// showing nothing costs) is the root box's diagonal, at least twice the root tile's error.
fn write_tileset(tiles: &[Tile], path: &Path) -> Result<u64, ExportError> {
    let root = match tiles.first() {
        Some(_) => tile_json(tiles, 0),
        None => return Err(ExportError::Invalid(format!("{}: no tiles to write", path.display()))),
    };
    let t = &tiles[0];
    let diagonal = (0..3).map(|a| (t.max[a] - t.min[a]).powi(2)).sum::<f64>().sqrt();
    let tileset = json!({
        "asset": { "version": "1.1", "generator": "terawalk export" },
        "geometricError": diagonal.max(2.0 * t.error),
        "root": root,
    });
    let err = |e: std::io::Error| ExportError::Io { path: PathBuf::from(path), source: e };
    let mut file = AtomicFile::create(path)?;
    serde_json::to_writer_pretty(&mut file, &tileset).map_err(|e| err(e.into()))?;
    file.write_all(b"\n").map_err(err)?;
    Ok(file.commit()?)
}
